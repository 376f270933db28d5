"""The interactive planner page (issue #19): same numbers in the browser as in Python.

The page's script evaluates the model itself; these tests run that script in headless
Chromium on a grid of inputs and compare with ``BlurUncertaintyModel.predict`` and
``plan_exposure``. They skip when no Chromium is installed (``.ci/run`` installs it).
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from dicblur.models import (
    PoissonGaussianCamera,
    StaticTerms,
    fit_blur_model,
    mismatch_model,
    plan_exposure,
    sssig_decay,
    with_static_model,
)
from dicblur.report import find_browser
from dicblur.report.browser import evaluate_in_browser
from dicblur.report.planner import SIZE_BUDGET, PlannerDefaults, planner_html, write_planner

needs_browser = pytest.mark.skipif(
    find_browser() is None, reason="no Chromium on PATH; .ci/run installs it"
)

S0, BETA = 2.4e6, 0.03


def _model(levels=(2.0, 8.0), seed=1, floor=9e-4, breakdown=None):
    rng = np.random.default_rng(seed)
    w0 = np.arange(0.0, 6.01, 0.5)
    w = np.tile(w0, len(levels))
    sig = np.repeat(levels, w0.size)
    s = sssig_decay(w, S0, BETA)
    u = mismatch_model(w, s, sig, c=9e-4, a=1.4, floor=floor) * np.exp(
        rng.normal(0.0, 0.02, w.size)
    )
    extra = {}
    if breakdown is not None:  # DIC "fails" (< 90 % converged) from W = breakdown on
        extra["converged_fraction"] = np.where(w >= breakdown, 0.5, 1.0)
    return fit_blur_model(
        w,
        s * np.exp(rng.normal(0.0, 0.005, w.size)),
        u,
        noise_sigma=sig,
        subset=31,
        mean_level=120.0,
        provenance={"pattern": "synthetic.tif"},
        **extra,
    )


def synthetic_terms(breakdown=None, step=0.25, top=8.0):
    """A static-prediction table with the shapes of a real one: the noise variance grows
    as 1/SSSIG, the noise-free variance as (c W^2)^2 plus a sub-pixel bias that swings
    with the offset W/2 mod 1."""
    w = np.round(np.arange(0.0, top + 1e-9, step), 10)
    s = sssig_decay(w, S0, BETA)
    off = (w / 2) % 1.0
    return StaticTerms(
        blur=tuple(w),
        noise=tuple(1.6 / s),
        noise2=tuple(2e-3 / s * (1 + 0.1 * w**2) / s * S0 * 1e-4),
        mismatch=tuple((9e-4 * w**2) ** 2 + (1e-3 * np.sin(np.pi * off)) ** 2),
        valid_fraction=tuple(np.where(w >= (breakdown or np.inf), 0.5, 1.0)),
        breakdown_blur=breakdown,
    )


def _static_model(seed=11, breakdown=6.5):
    """A model whose default is the static kind, fitted to data the table describes."""
    terms = synthetic_terms(breakdown=breakdown)
    rng = np.random.default_rng(seed)
    w0 = np.arange(0.0, 6.01, 0.5)
    w = np.tile(w0, 2)
    sig = np.repeat([2.0, 8.0], w0.size)
    s = sssig_decay(w, S0, BETA)
    x = np.array(terms.blur)
    n1, n2, b2 = (np.interp(w, x, np.array(v)) for v in (terms.noise, terms.noise2, terms.mismatch))
    u = np.sqrt(0.95**2 * (sig**2 * n1 + sig**4 * n2) + 1.05**2 * b2)
    u = u * np.exp(rng.normal(0.0, 0.02, w.size))
    base = fit_blur_model(
        w,
        s,
        u,
        noise_sigma=sig,
        subset=31,
        mean_level=120.0,
        breakdown_blur=breakdown,
        breakdown_rule="static prediction",
    )
    return with_static_model(base, terms)


@pytest.fixture(scope="module")
def models():
    one = _model(levels=(2.0,), seed=3)
    broken = _model(seed=5, breakdown=4.5)
    assert broken.domain.breakdown_blur is not None
    st = _static_model()
    assert st.default == "static" and st.domain.breakdown_blur == 6.5
    return [_model(), one, broken, st]


def test_page_is_self_contained_and_small(models, tmp_path):
    path = write_planner(models, tmp_path / "planner.html")
    text = path.read_text()
    assert len(text.encode()) < SIZE_BUDGET
    assert not re.search(r"(src|href)=['\"]?(https?:)?//", text)  # no network, no CDN
    assert "dicblur-models" in text and "<svg" in text
    assert "@media print" in text
    assert list(tmp_path.iterdir()) == [path]  # atomic write leaves no temporary file


JS_PREDICT = """
var P = window.dicblurPlanner, out = [];
CASES.forEach(function (c) {
  var m = P.models[c.model];
  try {
    if (c.op === "predict") {
      var r = P.predict(m, [c.blur], c.sigma, c.kind);
      out.push({u_e: r.u_e[0], low: r.low[0], high: r.high[0],
                u_noise: r.u_noise.length ? r.u_noise[0] : null});
    } else {
      var q = {velocity: c.velocity, scale: c.scale, target: c.target, sigma: c.sigma,
               camera: c.camera, kind: c.kind, noise_level: null};
      var p = P.planExposure(m, q);
      out.push({exposure: p.exposure, u_e: p.u_e, max_exposure: p.max_exposure,
                min_exposure: p.min_exposure});
    }
  } catch (e) { out.push({error: String(e.message || e)}); }
});
var pre = document.createElement("pre");
pre.id = "dicblur-result";
pre.textContent = JSON.stringify(out);
document.body.appendChild(pre);
"""


def _plan_case(g: np.random.Generator, model: int, kind: str, *, camera: bool) -> dict:
    """A plan case at random velocity and target, with a fixed random noise or a random
    camera (drawn from ``g`` in that order)."""
    case = {
        "op": "plan",
        "model": model,
        "kind": kind,
        "velocity": float(g.uniform(20, 400)),
        "scale": 0.05,
        "target": float(g.uniform(0.004, 0.03)),
        "sigma": None if camera else float(g.uniform(1, 6)),
        "camera": None,
    }
    if camera:
        case["camera"] = {
            "full_well": float(g.uniform(1e4, 4e4)),
            "read_noise": float(g.uniform(1, 10)),
            "flux": float(10 ** g.uniform(6, 7.5)),
            "peak_to_mean": 2.0,
        }
    return case


def _cases(models):
    rng = np.random.default_rng(7)
    cases = []
    for _ in range(200):
        mi = int(rng.integers(0, len(models)))
        kind = str(rng.choice(["mismatch", "power_law"]))
        sigma = float(rng.uniform(0.5, 10))
        if kind == "power_law" and rng.uniform() < 0.7:
            # the power law predicts only at its fitted noise (model 0: 2..8 GL, model 1:
            # 2 GL); elsewhere both sides must refuse
            sigma = None if mi == 1 else float(rng.uniform(2.0, 8.0))
        cases.append(
            {
                "op": "predict",
                "model": mi,
                "kind": kind,
                "blur": float(rng.uniform(0, 9)),
                "sigma": sigma,
            }
        )
    for _ in range(30):
        cases.append(_plan_case(rng, int(rng.choice([0, 2])), "mismatch", camera=False))
    # the static kind (model 3, default static): predictions inside, between and beyond
    # the table's grid points and past the breakdown, fixed-noise and camera plans
    srng = np.random.default_rng(8)
    for _ in range(150):
        mi = int(srng.choice([3, 3, 3, 0]))  # model 0 has no static kind: both refuse
        cases.append(
            {
                "op": "predict",
                "model": mi,
                "kind": ["static", "static", "mismatch", None][int(srng.integers(0, 4))],
                "blur": float(srng.uniform(0, 9)),
                "sigma": float(srng.uniform(0.5, 10)),
            }
        )
    for _ in range(30):
        kind = str(srng.choice(["static", "static", "mismatch"]))
        cases.append(_plan_case(srng, 3, kind, camera=False))
    for _ in range(30):
        cases.append(_plan_case(srng, 3, "static", camera=True))
    for _ in range(40):
        mi = int(rng.choice([0, 2]))
        cases.append(_plan_case(rng, mi, str(rng.choice(["mismatch", "power_law"])), camera=True))
    return cases


def _python(models, c):
    m = models[c["model"]]
    try:
        if c["op"] == "predict":
            p = m.predict([c["blur"]], c["sigma"], model=c["kind"])
            return {"u_e": float(p.u_e[0]), "low": float(p.low[0]), "high": float(p.high[0])}
        cam = None if c["camera"] is None else PoissonGaussianCamera(**c["camera"])
        p = plan_exposure(
            m,
            velocity=c["velocity"],
            scale=c["scale"],
            target=c["target"],
            sigma=c["sigma"],
            camera=cam,
            which=c["kind"],
        )
        return {
            "exposure": p.exposure,
            "u_e": p.u_e,
            "max_exposure": p.max_exposure,
            "min_exposure": p.min_exposure,
        }
    except Exception as exc:  # the page must refuse the same inputs
        return {"error": str(exc)}


@needs_browser
def test_page_computes_what_python_computes(models):
    cases = _cases(models)
    assert len(cases) >= 200
    text = planner_html(models)
    got = json.loads(evaluate_in_browser(text, f"var CASES = {json.dumps(cases)};" + JS_PREDICT))
    assert len(got) == len(cases)
    n_checked = 0
    for c, js in zip(cases, got, strict=True):
        py = _python(models, c)
        assert ("error" in py) == ("error" in js), (c, py, js)
        if "error" in py:
            continue
        if py["u_e"] != py["u_e"]:  # NaN: no prediction beyond the breakdown W
            assert js["u_e"] is None, (c, py, js)  # JSON has no NaN: the page gives null
            n_checked += 1
            continue
        assert js["u_e"] == pytest.approx(py["u_e"], rel=1e-9, abs=0), (c, py, js)
        n_checked += 1
        if c["op"] == "predict":
            assert js["low"] == pytest.approx(py["low"], rel=1e-6)
            assert js["high"] == pytest.approx(py["high"], rel=1e-6)
        else:
            assert js["exposure"] == pytest.approx(py["exposure"], rel=1e-6), (c, py, js)
            for k in ("max_exposure", "min_exposure"):
                if py[k] is None:
                    assert js[k] is None
                else:
                    assert js[k] == pytest.approx(py[k], rel=1e-6)
    assert n_checked >= 200
    # the breakdown was exercised: predictions refused beyond it, plans capped at it
    assert any(c["model"] == 2 and c["op"] == "predict" and c["blur"] >= 4.5 for c in cases)
    # the static kind was evaluated (not only refused) in predictions and both plans
    ok_static = [
        c
        for c, js in zip(cases, got, strict=True)
        if c["model"] == 3 and c["kind"] in ("static", None) and "error" not in js
    ]
    assert sum(c["op"] == "predict" for c in ok_static) >= 80
    assert any(c["op"] == "plan" and c["camera"] is None for c in ok_static)
    assert sum(c["op"] == "plan" and c["camera"] is not None for c in ok_static) >= 20


SCRIPT_MOVE = """
function snap() {
  return {sentence: document.getElementById("sentence").textContent,
          curve: document.getElementById("plot").innerHTML,
          ue: document.getElementById("out-ue").textContent};
}
function set(id, v) {
  var el = document.getElementById(id);
  el.value = v;
  el.dispatchEvent(new Event("input", {bubbles: true}));
}
window.addEventListener("load", function () {
  var before = snap();
  set("velocity", "400mm/s");
  var mid = snap();
  set("sigma", "6");
  var after = snap();
  var pre = document.createElement("pre");
  pre.id = "dicblur-result";
  pre.textContent = JSON.stringify([before, mid, after]);
  document.body.appendChild(pre);
});
"""


@needs_browser
def test_moving_two_controls_changes_plot_and_sentence(models, tmp_path):
    text = planner_html(models, defaults=PlannerDefaults(velocity="120mm/s", target="0.01px"))
    before, mid, after = json.loads(evaluate_in_browser(text, SCRIPT_MOVE))
    assert before["sentence"].startswith("At 120 mm/s, expose at most")
    assert mid["sentence"].startswith("At 400 mm/s") and mid["curve"] != before["curve"]
    assert after["ue"] != mid["ue"] and after["curve"] != mid["curve"]
    # the sentence's exposure is the Python answer
    plan = plan_exposure(
        models[0], velocity="120mm/s", scale="0.05mm/px", target="0.01px", sigma=2.0
    )
    assert f"{plan.exposure * 1e3:.3g} ms" in before["sentence"]
    # screenshot as a test artefact
    from dicblur.report import check_in_browser

    page = tmp_path / "planner.html"
    page.write_text(text.replace("<body>", "<body data-images-ok='true'>"))
    shot = check_in_browser(page, screenshot=tmp_path / "planner.png", window=(1280, 800))
    assert shot.screenshot is not None and shot.screenshot.stat().st_size > 10_000


def test_cli_plan_writes_the_page(tmp_path, capsys):
    from dicblur.cli import main

    model_path = tmp_path / "model.json"
    _model().to_json(str(model_path))
    page = tmp_path / "planner.html"
    # the page alone: no velocity or scale needed
    assert main(["plan", str(model_path), "--html", str(page)]) == 0
    assert "wrote" in capsys.readouterr().out and page.stat().st_size > 10_000
    # with the other options: the plan is printed and they are the page's starting values
    assert (
        main(
            [
                "plan",
                str(model_path),
                "--velocity",
                "200mm/s",
                "--scale",
                "0.05mm/px",
                "--target",
                "0.02px",
                "--noise",
                "3",
                "--html",
                str(page),
            ]
        )
        == 0
    )
    assert "rule of thumb" in capsys.readouterr().out
    text = page.read_text()
    assert 'value="200mm/s"' in text and 'value="0.02px"' in text
    # bad output paths are refused before any work, with exit 2
    assert main(["plan", str(model_path), "--html", str(tmp_path / "no" / "p.html")]) == 2
    assert "--html" in capsys.readouterr().err
    assert main(["plan", str(model_path)]) == 2
    assert "--velocity" in capsys.readouterr().err


# ---------------------------------------------------------------- matcher modes (issue 18)
def _compensated_model():
    """The calibration of ``_model()`` with the blur-compensated matcher: no mismatch."""
    rng = np.random.default_rng(11)
    w0 = np.arange(0.0, 6.01, 0.5)
    w = np.tile(w0, 2)
    sig = np.repeat([2.0, 8.0], w0.size)
    s = sssig_decay(w, S0, BETA)
    u = mismatch_model(w, s, sig, c=0.0, a=1.4, floor=9e-4) * np.exp(rng.normal(0, 0.02, w.size))
    return fit_blur_model(
        w,
        s,
        u,
        noise_sigma=sig,
        subset=31,
        mean_level=120.0,
        provenance={"pattern": "synthetic.tif"},
        compensation="given",
        compare=False,
    )


JS_COMPARE = """
var P = window.dicblurPlanner, out = [];
CASES.forEach(function (q) {
  try {
    var r = P.comparePlans(P.models[0], P.models[1], q);
    out.push({u_e_ratio: r.u_e_ratio, exposure_ratio: r.exposure_ratio, sentence: r.sentence,
              base: r.baseline_compensation, comp: r.compensation});
  } catch (e) { out.push({error: String(e.message || e)}); }
});
var pre = document.createElement("pre");
pre.id = "dicblur-result";
pre.textContent = JSON.stringify(out);
document.body.appendChild(pre);
"""


@needs_browser
def test_page_compares_matcher_modes_as_python_does():
    from dicblur.models import compare_plans

    plain, comp = _model(), _compensated_model()
    rng = np.random.default_rng(5)
    cases = []
    for i in range(12):
        cam = {
            "full_well": float(rng.uniform(1e4, 4e4)),
            "read_noise": float(rng.uniform(1, 10)),
            "flux": float(10 ** rng.uniform(6, 7.5)),
            "peak_to_mean": 2.0,
        }
        cases.append(
            {
                "velocity": float(rng.uniform(20, 400)),
                "scale": 0.05,
                "target": None if i % 2 else float(rng.uniform(0.004, 0.02)),
                "sigma": float(rng.uniform(1, 6)) if i % 2 == 0 else None,
                "camera": None if i % 2 == 0 else cam,
                "kind": "mismatch",
                "noise_level": None,
            }
        )
    # the compensated model first: the plain one is still the baseline
    text = planner_html([comp, plain])
    got = json.loads(evaluate_in_browser(text, f"var CASES = {json.dumps(cases)};" + JS_COMPARE))
    for q, js in zip(cases, got, strict=True):
        cam = None if q["camera"] is None else PoissonGaussianCamera(**q["camera"])
        py = compare_plans(
            comp,
            plain,
            velocity=q["velocity"],
            scale=q["scale"],
            target=q["target"],
            sigma=q["sigma"],
            camera=cam,
            which="mismatch",
        )
        assert "error" not in js, (q, js)
        assert js["base"] == "none" and js["comp"] == "given"
        assert js["u_e_ratio"] == pytest.approx(py.u_e_ratio, rel=1e-6), (q, py, js)
        assert js["exposure_ratio"] == pytest.approx(py.exposure_ratio, rel=1e-6), (q, py, js)
        assert js["sentence"].startswith("With the blur-compensated matcher (blur given)")


SCRIPT_MODES = """
function snap() {
  return {sentence: document.getElementById("sentence").textContent,
          boxHidden: document.getElementById("compare-box").hidden,
          compare: document.getElementById("compare").value,
          gainHidden: document.getElementById("row-gain").hidden,
          gain: document.getElementById("out-gain").textContent,
          curve2: !!document.getElementById("curve2"),
          options: Array.prototype.map.call(document.getElementById("model").options,
                                            function (o) { return o.textContent; })};
}
window.addEventListener("load", function () {
  var both = snap();
  var el = document.getElementById("compare");
  el.value = "";
  el.dispatchEvent(new Event("change", {bubbles: true}));
  var one = snap();
  var pre = document.createElement("pre");
  pre.id = "dicblur-result";
  pre.textContent = JSON.stringify([both, one]);
  document.body.appendChild(pre);
});
"""


@needs_browser
def test_page_shows_both_matcher_modes_and_the_gain(models):
    plain, comp = _model(), _compensated_model()
    defaults = PlannerDefaults(full_well=2e4, read_noise=5, flux=4e6)
    page = planner_html([plain, comp], defaults=defaults)
    both, one = json.loads(evaluate_in_browser(page, SCRIPT_MODES))
    assert not both["boxHidden"] and both["compare"] == "1"
    assert both["curve2"] and not both["gainHidden"]
    assert "the blur-compensated matcher (blur given) the optimum exposure is" in both["sentence"]
    assert "blur-compensated matcher (blur given)" in both["options"][1]
    cam = PoissonGaussianCamera(full_well=2e4, read_noise=5, flux=4e6)
    from dicblur.models import compare_plans

    py = compare_plans(plain, comp, velocity="120mm/s", scale="0.05mm/px", camera=cam)
    assert f"u_e {py.u_e_ratio:.3g}x, exposure {py.exposure_ratio:.3g}x" in both["gain"]
    # switched off: one matcher, one curve, no gain
    assert not one["curve2"] and one["gainHidden"] and "With the" not in one["sentence"]
    # models of one matcher mode only: no selector
    (solo, _) = json.loads(evaluate_in_browser(planner_html(models), SCRIPT_MODES))
    assert solo["boxHidden"] and not solo["curve2"]
