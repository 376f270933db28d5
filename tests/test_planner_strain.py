"""The planner page's strain-uncertainty target (issue 28 item 4): the page's script gives
the exposures of :func:`dicblur.strain.plan.plan_strain`.

The agreement test runs the page's functions in headless Chromium when it is installed,
else in node (the planner's model and solver parts need no DOM); without either it skips.
"""

from __future__ import annotations

import json
import math
import shutil
import subprocess

import numpy as np
import pytest

from dicblur.models import fit_blur_model, mismatch_model, sssig_decay
from dicblur.report import find_browser
from dicblur.report.browser import evaluate_in_browser
from dicblur.report.planner import PlannerDefaults, planner_html, planner_payload
from dicblur.report.planner_js import PLANNER_JS
from dicblur.strain.plan import plan_strain

S0, BETA = 2.4e6, 0.03
NODE = shutil.which("node")
needs_js = pytest.mark.skipif(
    find_browser() is None and NODE is None,
    reason="neither Chromium nor node on PATH: the page's script cannot run here",
)


def _model(levels=(2.0, 8.0), seed=1, subset=21, breakdown=None):
    rng = np.random.default_rng(seed)
    w0 = np.arange(0.0, 6.01, 0.5)
    w = np.tile(w0, len(levels))
    sig = np.repeat(levels, w0.size)
    s = sssig_decay(w, S0, BETA)
    u = mismatch_model(w, s, sig, c=9e-4, a=1.4, floor=9e-4) * np.exp(rng.normal(0.0, 0.02, w.size))
    extra = {}
    if breakdown is not None:
        extra["converged_fraction"] = np.where(w >= breakdown, 0.5, 1.0)
    return fit_blur_model(
        w, s, u, noise_sigma=sig, subset=subset, mean_level=120.0, **extra
    )  # fmt: skip


@pytest.fixture(scope="module")
def models():
    return [_model(), _model(levels=(2.0,), seed=3), _model(seed=5, breakdown=4.5)]


def test_page_has_the_strain_controls_and_starting_values(models):
    text = planner_html(
        models[:1],
        defaults=PlannerDefaults(strain_target="100microstrain", vsg="61px", step=10),
    )
    for needle in ('id="target-unit"', 'id="strain-target"', 'id="vsg"', 'id="strain-step"',
                   'id="strain-subset"', 'id="tradeoff"', "planStrain"):  # fmt: skip
        assert needle in text, needle
    assert '<option value="strain" selected>' in text
    assert 'value="100microstrain"' in text and 'value="61px"' in text
    assert 'id="strain-subset" min="5" step="2" value="21"' in text  # the model's subset
    assert '<div id="strain-box">' in text  # shown: the page starts at the strain target
    # without a strain target the page starts at the displacement target, strain hidden
    plain = planner_html(models[:1])
    assert '<option value="px" selected>' in plain and '<div id="strain-box" hidden>' in plain


def test_cli_plan_strain_target_writes_the_page(models, tmp_path, capsys):
    from dicblur.cli import main

    path = tmp_path / "model.json"
    models[1].to_json(str(path))
    page = tmp_path / "planner.html"
    args = ["plan", str(path), "--target", "100microstrain", "--vsg", "41px"]
    assert main([*args, "--html", str(page)]) == 0  # the page alone: no velocity needed
    text = page.read_text()
    assert 'value="100microstrain"' in text and 'value="41px"' in text
    assert '<option value="strain" selected>' in text
    # with velocity and scale the text plan is printed too; a VSG in points becomes px
    more = ["--velocity", "200mm/s", "--scale", "0.05mm/px", "--noise", "2"]
    assert main([*args[:-1], "5", *more, "--html", str(page)]) == 0
    assert "longest exposure" in capsys.readouterr().out
    text = page.read_text()
    assert 'value="61px"' in text and 'value="200mm/s"' in text
    # bad output paths are refused before any work, with exit 2
    assert main([*args, "--html", str(tmp_path / "no" / "p.html")]) == 2
    assert "--html" in capsys.readouterr().err


JS_STRAIN = """
var P = window.dicblurPlanner, out = [];
CASES.forEach(function (c) {
  try {
    var m = MODELS[c.model];
    var q = {velocity: c.velocity, scale: c.scale, sigma: c.sigma, kind: c.kind, step: c.step,
             subset: null, target: P.parseStrain(c.target, "strain target"),
             window: P.windowFromVsg(c.vsg, c.step, m.subset, "VSG")};
    var p = P.planStrain(m, q);
    out.push({exposure: p.exposure, blur: p.blur, sigma_exx: p.sigma_exx, window: p.window,
              tradeoff_exposure: p.tradeoff_exposure.map(function (t) {
                return isFinite(t) ? t : null;
              }),
              tradeoff_sigma: p.tradeoff_sigma, curve: p.curve_u_e, notes: p.notes});
  } catch (e) {
    if (!(e instanceof P.UnitError)) throw e;
    out.push({error: String(e.message)});
  }
});
"""


def _run_js(payload, cases):
    """Run JS_STRAIN on ``cases`` in Chromium (the page) or node (the script alone)."""
    head = f"var CASES = {json.dumps(cases)};"
    if find_browser() is not None:
        script = (
            head
            + "var MODELS = window.dicblurPlanner.models;"
            + JS_STRAIN
            + (
                'var pre = document.createElement("pre"); pre.id = "dicblur-result";'
                "pre.textContent = JSON.stringify(out); document.body.appendChild(pre);"
            )
        )
        return json.loads(evaluate_in_browser(planner_html(payload), script))
    models = [planner_payload(m) for m in payload]
    js = (
        "var window = {};" + PLANNER_JS + head + f"var MODELS = {json.dumps(models)};"
        + JS_STRAIN + "console.log(JSON.stringify(out));"
    )  # fmt: skip
    run = subprocess.run([NODE, "-"], input=js, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    return json.loads(run.stdout)


def _cases():
    rng = np.random.default_rng(28)
    cases = []
    for i in range(40):
        mi = int(rng.integers(0, 3))
        kind = ["mismatch", "power_law", None][i % 3]
        sigma = float(rng.uniform(1.0, 8.0)) if mi != 1 else None
        if kind == "power_law" and mi != 1:
            sigma = float(rng.uniform(2.0, 8.0))
        cases.append(
            {
                "model": mi,
                "kind": kind,
                "velocity": float(rng.uniform(20, 400)),
                "scale": 0.05,
                "sigma": sigma,
                "step": int(rng.choice([5, 10, 15])),
                "vsg": str(int(rng.choice([3, 5, 7, 9]))),
                # 30 to 3,000 microstrain: some below the static uncertainty (refused)
                "target": f"{10 ** rng.uniform(1.5, 3.5):.6g}microstrain",
            }
        )
    # refused by both: below the static uncertainty, an even window, a displacement unit,
    # a VSG in px that is no (N - 1) x step + subset
    base = {**cases[0], "model": 0, "kind": "mismatch", "sigma": 2.0, "step": 10}
    for bad in ({"target": "1microstrain"}, {"vsg": "4"}, {"target": "0.01px"}, {"vsg": "45px"}):
        cases.append({**base, "vsg": "5", "target": "300microstrain", **bad})
    return cases


@needs_js
def test_page_plans_the_strain_target_as_python_does(models):
    cases = _cases()
    got = _run_js(models, cases)
    assert len(got) == len(cases)
    n_ok = n_err = 0
    for c, js in zip(cases, got, strict=True):
        try:
            py = plan_strain(
                models[c["model"]], velocity=c["velocity"], scale=c["scale"],
                target=c["target"], vsg=c["vsg"], step=c["step"], sigma=c["sigma"],
                which=c["kind"],
            )  # fmt: skip
        except Exception as exc:  # the page must refuse the same inputs
            assert "error" in js, (c, str(exc), js)
            n_err += 1
            continue
        assert "error" not in js, (c, js)
        n_ok += 1
        assert js["window"] == py.window
        assert js["exposure"] == pytest.approx(py.exposure, rel=1e-9), (c, py.exposure, js)
        assert js["sigma_exx"] == pytest.approx(py.sigma_exx, rel=1e-9)
        # JSON has no NaN (no prediction beyond the breakdown W): the page gives null
        for key, ref in (("curve", py.curve_sigma_exx), ("tradeoff_sigma", py.tradeoff_sigma)):
            vals = np.array([math.nan if v is None else v for v in js[key]])
            np.testing.assert_allclose(vals, ref, rtol=1e-9, equal_nan=True)
        for t_js, t_py in zip(js["tradeoff_exposure"], py.tradeoff_exposure, strict=True):
            if math.isnan(t_py):
                assert t_js is None
            else:
                assert t_js == pytest.approx(t_py, rel=1e-9)
        assert len(js["notes"]) == len(py.notes)
    # both answers and refusals were exercised, on the split and the power-law models
    assert n_ok >= 20 and n_err >= 4


SCRIPT_UI = """
function snap() {
  return {sentence: document.getElementById("sentence").textContent,
          message: document.getElementById("message").textContent,
          rows: document.getElementById("tradeoff-body").rows.length,
          hidden: document.getElementById("tradeoff").hidden,
          curve: !!document.getElementById("curve"),
          ue: document.getElementById("out-ue").textContent};
}
window.addEventListener("load", function () {
  var strain = snap();
  var el = document.getElementById("target-unit");
  el.value = "px";
  el.dispatchEvent(new Event("change", {bubbles: true}));
  var px = snap();
  var pre = document.createElement("pre");
  pre.id = "dicblur-result";
  pre.textContent = JSON.stringify([strain, px]);
  document.body.appendChild(pre);
});
"""


@pytest.mark.skipif(find_browser() is None, reason="no Chromium on PATH; .ci/run installs it")
def test_page_starts_at_the_strain_target_and_shows_the_tradeoff(models):
    d = PlannerDefaults(velocity="120mm/s", noise=2.0, strain_target="100microstrain", vsg="61px")
    strain, px = json.loads(evaluate_in_browser(planner_html(models[:1], defaults=d), SCRIPT_UI))
    assert strain["message"] == "" and strain["curve"] and not strain["hidden"]
    assert strain["rows"] == 7  # VSG 3..15 points
    py = plan_strain(
        models[0], velocity="120mm/s", scale="0.05mm/px", target="100microstrain",
        vsg="61px", step=10, sigma=2.0,
    )  # fmt: skip
    assert strain["sentence"].startswith("At 120 mm/s, expose at most")
    assert f"{py.exposure * 1e6:.3g} \u00b5s" in strain["sentence"], (py.exposure, strain)
    assert "at VSG 61 px" in strain["sentence"]
    assert " px; sigma_exx " in strain["ue"]  # at the chosen exposure (1 ms)
    # back to a displacement target: the px plan, the trade-off hidden
    assert px["hidden"] and px["sentence"].endswith("for 0.01 px.")
