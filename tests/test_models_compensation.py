"""Models of the blur-compensated matcher (issue 18): the matcher mode recorded in a model,
calibrate sweeping with compensation, predict and plan stating the mode, and a plan with
compensation set against one without."""

from __future__ import annotations

import functools
import json
import math
from dataclasses import replace

import numpy as np
import pytest

import dicblur
from dicblur.campaign.calibrate import calibrate, calibration_spec
from dicblur.cli import main
from dicblur.errors import InputError
from dicblur.models import (
    BlurUncertaintyModel,
    PoissonGaussianCamera,
    compare_plans,
    fit_blur_model,
    mismatch_model,
    plan_exposure,
    predict_compensated,
    sssig_decay,
)

S0, BETA = 2.4e6, 0.03


@functools.cache  # frozen values: each calibration is fitted once
def _model(compensation="none", *, c=9e-4, seed=1):
    """A two-level calibration of a synthetic pattern; ``c = 0`` for the compensated one."""
    rng = np.random.default_rng(seed)
    w0 = np.arange(0.0, 8.01, 0.5)
    w = np.tile(w0, 2)
    sig = np.repeat([2.0, 8.0], w0.size)
    s = sssig_decay(w, S0, BETA)
    u = mismatch_model(w, s, sig, c=c, a=1.4, floor=9e-4) * np.exp(rng.normal(0, 0.02, w.size))
    return fit_blur_model(
        w,
        s,
        u,
        noise_sigma=sig,
        subset=31,
        mean_level=120.0,
        shape="translation",
        pattern="p.tif",
        pattern_sha256="abc",
        compensation=compensation,
        compare=False,
    )


# ---------------------------------------------------------------- the recorded mode
def test_model_records_its_matcher_mode_and_old_files_load_as_plain(tmp_path):
    comp = _model("given", c=0.0)
    assert comp.compensation == "given" and comp.domain.compensation == "given"
    assert "blur-compensated" in comp.matcher and "blur-compensated" in comp.report()
    back = BlurUncertaintyModel.from_json(comp.to_json())
    assert back == comp and back.compensation == "given"
    assert comp.predict([2.0], 2.0).compensation == "given"
    # the compensated matcher refuses blur not shorter than the subset: no prediction there
    assert comp.domain.breakdown_blur == 31.0
    assert np.isnan(comp.predict([31.0], 2.0).u_e[0])
    # a file written before the mode was recorded is the plain matcher
    d = json.loads(_model().to_json())
    d["domain"].pop("compensation")
    old = BlurUncertaintyModel.from_json(json.dumps(d))
    assert old.compensation == "none" and old.matcher == "plain matcher"
    d["domain"]["compensation"] = "sharpen"
    with pytest.raises(InputError, match=r"domain\.compensation"):
        BlurUncertaintyModel.from_json(json.dumps(d))
    with pytest.raises(InputError, match="compensation"):
        _model("sharpen")


def test_fitted_form_expresses_the_compensated_matcher():
    """Fitted on the compensated static prediction: the mismatch term is ~0 and the noise
    term (blurred reference's gradients) carries u_e within a few per cent."""
    img = dicblur.speckle_pattern((128, 128), speckle_size=4, seed=2)
    w = np.arange(0.0, 10.01, 1.0)
    cols = []
    for s in (2.0, 8.0):
        p = predict_compensated(img, w, noise_sigma=s, subset=31, step=8)
        cols.append((np.full(w.size, s), p.sssig, p.u_e))
    sig, ss, u = (np.concatenate(x) for x in zip(*cols, strict=True))
    ww = np.tile(w, 2)
    m = fit_blur_model(ww, ss, u, noise_sigma=sig, subset=31, compensation="given")
    pred = np.array([m.predict([wi], si).u_e[0] for wi, si in zip(ww, sig, strict=True)])
    assert np.max(np.abs(pred / u - 1)) < 0.08
    at8 = m.predict([8.0], 2.0)
    # the blur-mismatch term carries < 5 % of the variance (plain: ~99 % at W = 8 px)
    assert at8.u_blur[0] ** 2 < 0.05 * at8.u_noise[0] ** 2
    assert m.c < 1e-4  # plain calibrations of 4 px speckle: c ~ 1e-3 px/px^2


# ---------------------------------------------------------------- calibrate
def test_calibration_spec_sweeps_with_compensation():
    plain = calibration_spec("speckle", size=(128, 128))
    assert plain.compensation == "none"
    # the default spec (and its hash) is what it was before the option
    assert plain.content_hash() == calibration_spec("speckle", size=(128, 128)).content_hash()
    assert "compensation" not in plain.to_dict()["dic"]
    for mode in ("given", "estimate", "deblur"):
        assert calibration_spec("speckle", size=(128, 128), compensation=mode).compensation == mode
    with pytest.raises(InputError, match="compensation='sharpen'"):
        calibration_spec("speckle", compensation="sharpen")


@pytest.mark.filterwarnings("ignore:edge-driven range")
def test_calibrate_with_compensation_writes_a_compensated_model(tmp_path):
    """A compensated sweep on a periodic (generated) pattern: the model is compensated,
    and at low noise u_e stays at the interpolation floor (before the periodic margin, the
    blurred reference's mirror boundary put 0.07 px errors on the border subsets)."""
    kw = {"noise": 0.05, "subset": 31, "step": 12, "size": (128, 128), "serial": True}
    res = calibrate(
        "speckle", tmp_path / "given", blur=[0.0, 2.0, 4.0, 8.0], compensation="given", **kw
    )
    assert res is not None
    # W = 0 with the blur given is the plain matcher, bit for bit (same seeds)
    plain = calibrate("speckle", tmp_path / "plain", blur=[0.0, 1.0, 2.0], **kw)
    assert plain is not None
    u0 = float(res.curves["u_e"].sel(blur=0.0).values.ravel()[0])
    assert u0 == float(plain.curves["u_e"].sel(blur=0.0).values.ravel()[0])
    # dicblur fit on the campaign store takes the matcher from the store's spec
    out = tmp_path / "refit.json"
    assert main(["fit", str(res.results_path), "-o", str(out)]) == 0
    assert BlurUncertaintyModel.from_json(str(out)).compensation == "given"
    assert main(["fit", str(plain.results_path), "-o", str(out)]) == 0
    assert BlurUncertaintyModel.from_json(str(out)).compensation == "none"
    m = BlurUncertaintyModel.from_json(str(res.model_path))
    assert m.compensation == "given" and m.provenance["compensation"] == "given"
    # the static kind scales the plain matcher's terms: a compensated model has none
    assert m.static is None and m.default != "static"
    assert BlurUncertaintyModel.from_json(str(plain.model_path)).default == "static"
    u = np.asarray(res.curves["u_e"].values).ravel()
    # measured: 0.52e-3 px at W = 8 px (without the margin 2.7e-3; plain matcher ~0.05 px)
    assert np.all(u < 1e-3), u


def test_calibrate_cli_refuses_an_unknown_mode(tmp_path, capsys):
    code = main(["calibrate", "speckle", "-o", str(tmp_path / "c"), "--compensation", "on"])
    assert code == 2
    assert "--compensation='on'" in capsys.readouterr().err


# ---------------------------------------------------------------- predict and plan
def test_predict_prints_the_matcher(tmp_path, capsys):
    path = tmp_path / "comp.json"
    _model("given", c=0.0).to_json(str(path))
    assert main(["predict", str(path), "--blur", "2", "--noise", "2"]) == 0
    out = capsys.readouterr().out
    assert "matcher: blur-compensated matcher (blur given)" in out
    assert main(["predict", str(path), "--blur", "2", "--noise", "2", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["compensation"] == "given"


def test_compare_plans_states_the_gain_at_the_optimum():
    plain, comp = _model(), _model("given", c=0.0)
    cam = PoissonGaussianCamera(full_well=2e4, read_noise=5, flux=4e6)
    kw = {"velocity": "120mm/s", "scale": "0.05mm/px", "camera": cam}
    # either order: the plain model is the baseline
    for a, b in ((plain, comp), (comp, plain)):
        res = compare_plans(a, b, **kw)
        assert res.baseline_compensation == "none" and res.compensation == "given"
        p0, p1 = plan_exposure(plain, **kw), plan_exposure(comp, **kw)
        assert res.baseline.exposure == p0.exposure and res.compensated.exposure == p1.exposure
        assert res.u_e_ratio == pytest.approx(p1.u_e / p0.u_e, rel=1e-12)
        assert res.exposure_ratio == pytest.approx(p1.exposure / p0.exposure, rel=1e-12)
    # no mismatch term: longer exposure, more light, lower u_e
    assert res.exposure_ratio > 1.5 and res.u_e_ratio < 0.9
    assert f"{res.exposure_ratio:.3g}x as long" in res.sentence
    assert f"{1 / res.u_e_ratio:.3g}x lower" in res.sentence
    d = res.to_dict()
    assert d["u_e_ratio"] == res.u_e_ratio and d["compensated"]["compensation"] == "given"
    assert "blur-compensated" in res.summary() and "plain matcher" in res.summary()
    # fixed noise and a target: the target holds to a longer exposure
    fixed = compare_plans(
        plain, comp, velocity="120mm/s", scale="0.05mm/px", target="0.005px", sigma=2.0
    )
    assert fixed.exposure_ratio > 1 and math.isclose(fixed.u_e_ratio, 1.0, rel_tol=1e-6)


def test_compare_plans_refuses_different_calibrations():
    plain = _model()
    with pytest.raises(InputError, match="both models use the plain matcher"):
        compare_plans(plain, _model(seed=2), velocity=100, scale=0.05, target=0.01, sigma=2.0)
    comp = _model("given", c=0.0)
    for kw, what in (
        ({"subset": 41}, "subset"),
        ({"pattern": "q.tif"}, "pattern"),
        ({"pattern_sha256": "def"}, "pattern hash"),
        ({"shape": "affine"}, "shape"),
    ):
        other = replace(comp, domain=replace(comp.domain, **kw))
        with pytest.raises(InputError, match=what):
            compare_plans(plain, other, velocity=100, scale=0.05, target=0.01, sigma=2.0)


def test_cli_plan_compare(tmp_path, capsys):
    a, b = tmp_path / "plain.json", tmp_path / "comp.json"
    _model().to_json(str(a))
    _model("given", c=0.0).to_json(str(b))
    args = ["--velocity", "120mm/s", "--scale", "0.05mm/px", "--full-well", "20000"]
    args += ["--read-noise", "5", "--flux", "4e6"]
    png = tmp_path / "plan.png"
    assert main(["plan", str(a), "--compare", str(b), *args, "--plot", str(png)]) == 0
    assert png.stat().st_size > 10_000  # both matchers' curves
    out = capsys.readouterr().out
    assert "plain matcher:" in out and "blur-compensated matcher (blur given):" in out
    assert "the optimum exposure is" in out and "x lower" in out
    assert main(["plan", str(a), "--compare", str(b), *args, "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["exposure_ratio"] > 1 and d["u_e_ratio"] < 1 and d["sentence"]
    c = tmp_path / "other.json"
    comp = _model("given", c=0.0)
    replace(comp, domain=replace(comp.domain, subset=41)).to_json(str(c))
    assert main(["plan", str(a), "--compare", str(c), *args]) == 2
    err = capsys.readouterr().err
    assert "--compare: calibrated with subset 41, MODEL with 31" in err
    assert main(["plan", str(a), "--compare", str(a), *args]) == 2
    assert "both models use the plain matcher" in capsys.readouterr().err


def test_pattern_predict_writes_a_compensated_model_to_plan_against(tmp_path, capsys):
    """Before any campaign: the static predictions of both matchers as models, and the
    plan with compensation set against the one without."""
    path = tmp_path / "pat.tif"
    dicblur.save_image(path, dicblur.speckle_pattern((128, 128), speckle_size=4, seed=3))
    plain, comp = tmp_path / "plain.json", tmp_path / "comp.json"
    common = ["pattern", "predict", str(path), "--noise", "2", "--subset", "31", "--step", "8"]
    assert main([*common, "-o", str(plain)]) == 0
    assert main([*common, "--compensation", "given", "-o", str(comp)]) == 0
    capsys.readouterr()
    p, m = (BlurUncertaintyModel.from_json(str(x)) for x in (plain, comp))
    assert m.compensation == "given" and p.compensation == "none"
    assert m.c < 0.1 * p.c  # the mismatch term is gone
    assert m.domain.pattern_sha256 == p.domain.pattern_sha256 is not None
    assert m.domain.pattern == p.domain.pattern == "pat"
    args = ["--velocity", "120mm/s", "--scale", "0.05mm/px", "--full-well", "20000"]
    assert (
        main(
            [
                "plan",
                str(plain),
                "--compare",
                str(comp),
                *args,
                "--read-noise",
                "5",
                "--flux",
                "4e6",
                "--json",
            ]
        )
        == 0
    )
    d = json.loads(capsys.readouterr().out)
    assert d["exposure_ratio"] > 1 and d["u_e_ratio"] < 1


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore:edge-driven range")
def test_calibrate_with_the_blur_estimated(tmp_path):
    """dic.compensation = "estimate": the length estimated along the task's angle gives
    the u_e of the given blur (measured: within 2 % at W = 0..8 px; 8-30 s)."""
    kw = {"noise": 2.0, "subset": 31, "step": 12, "size": (128, 128), "serial": True}
    runs = {
        mode: calibrate(
            "speckle", tmp_path / mode, blur=[0.0, 2.0, 4.0, 8.0], compensation=mode, **kw
        )
        for mode in ("given", "estimate")
    }
    assert runs["estimate"].model.compensation == "estimate"
    u = {m: np.asarray(r.curves["u_e"].values).ravel() for m, r in runs.items()}
    np.testing.assert_allclose(u["estimate"], u["given"], rtol=0.1)
