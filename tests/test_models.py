"""Tests of dicblur.models against closed forms and independent computations."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import optimize

import dicblur
from dicblur.errors import FitError, InputError
from dicblur.models import (
    BlurUncertaintyModel,
    PoissonGaussianCamera,
    blur_mismatch_curve,
    blur_sensitivity,
    combined_model,
    combined_pan_model,
    compare_models,
    edge_driven_range,
    fit_blur_model,
    fit_mismatch,
    fit_power_law,
    fit_sssig_decay,
    match_score_uncertainty,
    mbrf,
    mismatch_model,
    model_from_pattern,
    pan_uncertainty,
    parse_quantity,
    plan_exposure,
    predict_from_pattern,
    sssig_decay,
    taylor_model,
)

W = np.arange(0.0, 10.01, 0.5)
S0, BETA, ETA, ALPHA = 1.85e5, 0.022, 0.01, 0.5


def _powerlaw_data(seed: int, noise: float = 0.02, w: np.ndarray = W):
    rng = np.random.default_rng(seed)
    s = sssig_decay(w, S0, BETA) * np.exp(rng.normal(0, 0.01, w.size))
    u = ETA * s ** (-ALPHA) * np.exp(rng.normal(0, noise, w.size))
    return s, u


# ----------------------------------------------------------------------------- static


def test_static_models_closed_forms():
    s = np.array([1e4, 4e4])
    sig = np.array([[1.0], [2.0]])
    got = match_score_uncertainty(s, sig)
    assert got.shape == (2, 2)
    np.testing.assert_allclose(got, np.sqrt(2 * sig**2 / s), rtol=1e-14)
    np.testing.assert_allclose(
        pan_uncertainty([2.0, 4.0], 3.0, 21),
        math.sqrt(2) * 3.0 / (21 * np.array([2.0, 4.0])),
        rtol=1e-14,
    )


# ----------------------------------------------------------------------------- fits


def test_parameters_recovered_within_ci():
    s, u = _powerlaw_data(1)
    dec = fit_sssig_decay(W, s)
    for name, true in (("sssig0", S0), ("beta", BETA)):
        p = dec.parameter(name)
        assert p.low <= true <= p.high, (name, p)
    assert dec.r2 > 0.99
    pl = fit_power_law(s, u, blur=W)
    u_ref = ETA * pl.extra["sssig_ref"] ** (-ALPHA)  # u_e = u_ref (S / S_ref)^-alpha
    for name, true in (("u_ref", u_ref), ("alpha", ALPHA)):
        p = pl.parameter(name)
        assert p.low <= true <= p.high, (name, p)
    assert pl.extra["eta"] == pytest.approx(pl["u_ref"] * pl.extra["sssig_ref"] ** pl["alpha"])
    # mismatch model with known a = 2, c
    rng = np.random.default_rng(5)
    um = mismatch_model(W, s, 2.0, c=7e-4) * np.exp(rng.normal(0, 0.02, W.size))
    mm = fit_mismatch(W, s, um, noise_sigma=2.0, next_term=False)
    assert mm.names == ("a", "c") and mm.fixed == {"gamma": 1.0}
    for name, true in (("a", 2.0), ("c", 7e-4)):
        p = mm.parameter(name)
        assert p.low <= true <= p.high, (name, p)


def test_bootstrap_ci_contains_truth():
    s, u = _powerlaw_data(2)
    pl = fit_power_law(s, u, blur=W, ci="bootstrap", n_boot=300, seed=0)
    assert pl.ci_method == "bootstrap"
    assert pl.parameter("alpha").low <= ALPHA <= pl.parameter("alpha").high
    again = fit_power_law(s, u, blur=W, ci="bootstrap", n_boot=300, seed=0)
    assert again == pl  # same seed, same result


@pytest.mark.parametrize("which", ["power_law", "decay", "mismatch"])
def test_ci_coverage_roughly_nominal(which):
    hits = 0
    n = 120
    for seed in range(n):
        rng = np.random.default_rng(1000 + seed)
        w = np.arange(0.0, 8.01, 1.0)
        s = sssig_decay(w, S0, BETA)
        if which == "power_law":
            u = ETA * s ** (-ALPHA) * np.exp(rng.normal(0, 0.03, w.size))
            p = fit_power_law(s, u, blur=w).parameter("alpha")
            hits += p.low <= ALPHA <= p.high
        elif which == "decay":
            sn = s + rng.normal(0, 0.01 * S0, w.size)
            p = fit_sssig_decay(w, sn).parameter("beta")
            hits += p.low <= BETA <= p.high
        else:
            u = mismatch_model(w, s, 2.0, c=7e-4) * np.exp(rng.normal(0, 0.03, w.size))
            p = fit_mismatch(w, s, u, noise_sigma=2.0, next_term=False).parameter("c")
            hits += p.low <= 7e-4 <= p.high
    assert 0.88 <= hits / n <= 0.995, hits / n


def test_noise_exponents_fitted_with_several_levels():
    w = np.tile(np.arange(0.0, 8.01, 1.0), 3)
    sig = np.repeat([1.0, 2.0, 4.0], 9)
    s = sssig_decay(w, S0, BETA)
    rng = np.random.default_rng(3)
    # scale-consistent power law: u = eta_n (S / sigma^2)^-alpha
    alpha = 0.8
    u = 0.05 * (s / sig**2) ** (-alpha) * np.exp(rng.normal(0, 0.01, w.size))
    pl = fit_power_law(s, u, noise_sigma=sig, blur=w)
    assert pl.names == ("u_ref", "alpha", "kappa")
    k = pl.parameter("kappa")
    assert k.low <= 2 * alpha <= k.high
    um = mismatch_model(w, s, sig, c=5e-4, a=2.0, gamma=1.0) * np.exp(rng.normal(0, 0.01, w.size))
    mm = fit_mismatch(w, s, um, noise_sigma=sig, next_term=False)
    g = mm.parameter("gamma")
    assert mm.names == ("a", "gamma", "c") and g.low <= 1.0 <= g.high


def test_next_term_added_only_when_data_ask():
    w = np.arange(0.0, 12.01, 0.5)
    s = sssig_decay(w, S0, BETA)
    rng = np.random.default_rng(4)
    eps = np.exp(rng.normal(0, 0.01, w.size))
    plain = mismatch_model(w, s, 2.0, c=7e-4) * eps
    assert "c4" not in fit_mismatch(w, s, plain, noise_sigma=2.0).names
    curved = mismatch_model(w, s, 2.0, c=7e-4, c4=2e-5) * eps
    fit = fit_mismatch(w, s, curved, noise_sigma=2.0)
    assert "c4" in fit.names
    assert fit.parameter("c4").low <= 2e-5 <= fit.parameter("c4").high


def test_range_rule_on_contrast_driven_tail():
    w = np.arange(0.0, 10.01, 0.5)
    s = sssig_decay(w, S0, BETA)
    ratio = np.where(w <= 4.0, 1.0 + 0.004 * w, 1.0 + 0.15 * (w - 4.0) + 0.016)
    rng = np.random.default_rng(7)
    tail = np.where(w <= 4.0, 1.0, ratio**4)  # the law fails once contrast is lost
    u = ETA * s ** (-ALPHA) * tail * np.exp(rng.normal(0, 0.01, w.size))
    assert edge_driven_range(w, contrast_ratio=ratio) == (0.0, 4.0)
    model = fit_blur_model(w, s, u, contrast_ratio=ratio, default="power_law")
    assert model.fit_range == (0.0, 4.0)
    a = model.power_law.parameter("alpha")
    assert a.low <= ALPHA <= a.high
    # the same fit over all W is biased: the rule matters
    everything = fit_power_law(s, u, blur=w).parameter("alpha")
    assert not everything.low <= ALPHA <= everything.high
    # contrast from the two contrast columns gives the same range; override works
    m2 = fit_blur_model(w, s, u, contrast_ref=2.0, contrast=2.0 / ratio, default="power_law")
    assert m2.fit_range == (0.0, 4.0)
    m3 = fit_blur_model(w, s, u, contrast_ratio=ratio, fit_range=(0.0, 3.0))
    assert m3.fit_range == (0.0, 3.0) and m3.range_rule == "given"
    # too few qualifying levels: the smallest three are kept, with a warning
    with pytest.warns(UserWarning, match="only 1 blur level"):
        assert edge_driven_range(w, contrast_ratio=1.0 + w) == (0.0, 1.0)


def test_taylor_vs_exact_at_small_w():
    u0 = ETA * S0 ** (-ALPHA)
    w = np.array([0.05, 0.1, 0.2])
    exact = combined_model(w, ETA, ALPHA, S0, BETA)
    taylor = taylor_model(w, u0, ALPHA, BETA)
    # the remainder is fourth order: error / W^4 stays bounded and small
    err = np.abs(exact - taylor) / u0
    assert np.all(err <= 0.5 * ALPHA * (ALPHA + 1) * BETA**2 * w**4 * 1.01)
    # normalised curvature u''(0)/u(0) = 2 alpha beta = MBRF (central difference)
    h = 1e-3
    curv = (combined_model(h, ETA, ALPHA, S0, BETA) * 2 - 2 * u0) / h**2 / u0
    assert curv == pytest.approx(mbrf(ALPHA, BETA), rel=1e-5)
    # the paper's eq. 21 (1 + MBRF W^2) doubles the second-order term
    paper = u0 * (1 + mbrf(ALPHA, BETA) * w**2)
    assert np.all(np.abs(paper - exact) > 10 * np.abs(taylor - exact))


def test_pan_variant():
    mig0, n = 12.0, 21
    np.testing.assert_allclose(
        combined_pan_model(W, ETA, ALPHA, BETA, mig0=mig0, subset=n),
        combined_model(W, ETA, ALPHA, n**2 * mig0**2, BETA),
        rtol=1e-14,
    )


# ----------------------------------------------------------------------------- the model value


@pytest.fixture(scope="module")
def model() -> BlurUncertaintyModel:
    rng = np.random.default_rng(0)
    s = sssig_decay(W, S0, BETA) * np.exp(rng.normal(0, 0.01, W.size))
    u = mismatch_model(W, s, 2.0, c=7e-4) * np.exp(rng.normal(0, 0.02, W.size))
    return fit_blur_model(
        W,
        s,
        u,
        noise_sigma=2.0,
        subset=31,
        mean_level=120.0,
        c_static=6.8e-4,
        provenance={"pattern": "synthetic", "seed": (0, 1)},
    )


def test_model_value(model):
    assert model.default == "mismatch"  # the default, and the held-out comparison agrees
    assert model.comparison is not None and model.comparison["better"] == "mismatch"
    assert model.mbrf == pytest.approx(2 * model.alpha * model.beta)
    pred = model.predict([0.0, 2.0, 4.0, 8.0])
    truth = mismatch_model([0.0, 2.0, 4.0, 8.0], sssig_decay([0, 2, 4, 8.0], S0, BETA), 2.0, c=7e-4)
    assert np.all((pred.low <= truth) & (truth <= pred.high))
    np.testing.assert_allclose(pred.u_e**2, pred.u_noise**2 + pred.u_blur**2, rtol=1e-10)
    # at another noise the noise term scales with sigma (gamma = 1) and the blur term not
    p4 = model.predict([0.0, 8.0], 4.0)
    np.testing.assert_allclose(p4.u_noise, 2 * pred.u_noise[[0, 3]], rtol=1e-10)
    np.testing.assert_allclose(p4.u_blur, pred.u_blur[[0, 3]], rtol=1e-10)
    wmax = model.max_blur(0.01)
    assert model.predict([wmax]).u_e[0] == pytest.approx(0.01, rel=1e-9)
    text = model.report()
    for word in ("eq. 18", "MBRF", "alpha", "c predicted", "held-out", "synthetic"):
        assert word in text


def test_prediction_interval_coverage(model):
    # new measurements drawn like the fitted data fall in the 95 % interval ~95 % of the time
    rng = np.random.default_rng(9)
    w = np.arange(0.5, 10.01, 0.5)
    pred = model.predict(w)
    truth = mismatch_model(w, sssig_decay(w, S0, BETA), 2.0, c=7e-4)
    new = truth[None, :] * np.exp(rng.normal(0, 0.02, (200, w.size)))
    inside = np.mean((new >= pred.low) & (new <= pred.high))
    assert 0.88 <= inside <= 0.995


def test_json_round_trip_bit_exact(model, tmp_path):
    text = model.to_json()
    back = BlurUncertaintyModel.from_json(text)
    assert back == model
    assert back.to_json() == text
    assert back.mismatch.values == model.mismatch.values
    path = tmp_path / "m.json"
    model.to_json(str(path))
    assert BlurUncertaintyModel.from_json(str(path)) == model
    np.testing.assert_array_equal(back.predict(W).u_e, model.predict(W).u_e)
    with pytest.raises(InputError, match="schema"):
        BlurUncertaintyModel.from_json('{"a": 1}')


def test_compare_models_picks_the_generating_model():
    w = np.tile(np.arange(0.0, 10.01, 1.0), 3)
    sig = np.repeat([1.0, 2.0, 4.0], 11)
    s = sssig_decay(w, S0, BETA)
    rng = np.random.default_rng(11)
    eps = np.exp(rng.normal(0, 0.02, w.size))
    um = mismatch_model(w, s, sig, c=7e-4) * eps
    cm = compare_models(w, s, um, noise_sigma=sig)
    assert cm.better == "mismatch" and cm.holdout_noise == 4.0
    assert cm.rms_log_error["mismatch"] < 0.05 < cm.rms_log_error["power_law"]
    # one noise level (gamma fixed at 1): a power law with alpha = 1.5 is not a mismatch law
    one = sig == 2.0
    up = 0.05 * (s[one] / 4.0) ** (-1.5) * eps[one]
    cp = compare_models(w[one], s[one], up, noise_sigma=2.0)
    assert cp.better == "power_law" and cp.rms_log_error["power_law"] < 0.05


# ----------------------------------------------------------------------------- planning


def test_units():
    assert parse_quantity("120mm/s", "velocity") == pytest.approx(120.0)
    assert parse_quantity("0.12 m/s", "velocity") == pytest.approx(120.0)
    assert parse_quantity("800px/s", "velocity", scale=0.05) == pytest.approx(40.0)
    assert parse_quantity("1ms", "time") == pytest.approx(1e-3)
    assert parse_quantity("20px/mm", "scale") == pytest.approx(0.05)
    assert parse_quantity("0.05mm/px", "scale") == pytest.approx(0.05)
    assert parse_quantity("0.5um", "blur", scale=0.05) == pytest.approx(0.01)
    assert parse_quantity(3.0, "blur") == 3.0
    for bad, kind in (
        ("12 furlongs/s", "velocity"),
        ("fast", "velocity"),
        ("1mm", "time"),
        ("0.5um", "blur"),
    ):
        with pytest.raises(InputError):
            parse_quantity(bad, kind)  # type: ignore[arg-type]


def test_plan_fixed_noise(model):
    plan = plan_exposure(model, velocity="120mm/s", scale="0.05mm/px", target="0.01px")
    assert plan.velocity_px == pytest.approx(2400.0)
    assert plan.exposure == pytest.approx(model.max_blur(0.01) / 2400.0, rel=1e-12)
    assert plan.rule_of_thumb_exposure == pytest.approx(0.02 / 2400.0)
    assert "rule of thumb" in plan.summary()


def _noiseless(kind: str, beta: float) -> BlurUncertaintyModel:
    w = np.arange(0.0, 8.01, 1.0)
    s = sssig_decay(w, S0, beta)
    u = mismatch_model(w, s, 2.0, c=7e-4) if kind == "mismatch" else 0.02 * (s / 4.0) ** (-0.7)
    return fit_blur_model(w, s, u, noise_sigma=2.0, mean_level=100.0, default=kind, next_term=False)


def test_plan_power_law_with_camera_refused():
    # a camera moves the noise with the exposure; the one-level power law's noise
    # dependence (sigma^(2 alpha)) was never measured: refused, naming the model to use
    m = _noiseless("power_law", BETA)
    cam = PoissonGaussianCamera(full_well=1e12, read_noise=0.0, flux=1e5)
    with pytest.raises(InputError, match="mismatch"):
        plan_exposure(m, velocity=120.0, scale=0.05, camera=cam)
    assert m.beta == pytest.approx(BETA, rel=1e-8)


def test_plan_mismatch_closed_form():
    # beta = 0, read = 0: u^2 = A/t + B t^4, t* = (A / 4B)^(1/5), u*^2 = 5A / (4 t*)
    m = _noiseless("mismatch", 0.0)
    assert m.beta < 1e-9
    flux, v, sc = 2e5, 120.0, 0.05
    cam = PoissonGaussianCamera(full_well=1e12, read_noise=0.0, flux=flux)
    plan = plan_exposure(m, velocity=v, scale=sc, camera=cam, target=1.0)
    a_, c_ = m.mismatch["a"], m.mismatch["c"]
    big_a = a_ * 100.0**2 / (m.decay["sssig0"] * flux)
    big_b = c_**2 * (v / sc) ** 4
    t_star = (big_a / (4 * big_b)) ** 0.2
    assert plan.exposure == pytest.approx(t_star, rel=1e-5)
    assert plan.u_e == pytest.approx(math.sqrt(1.25 * big_a / t_star), rel=1e-6)
    # target window: both ends satisfy u = target
    assert plan.min_exposure < t_star < plan.max_exposure


def test_plan_with_read_noise_and_saturation(model):
    cam = PoissonGaussianCamera(full_well=2e4, read_noise=8.0, flux=1e6, peak_to_mean=2.0)
    plan = plan_exposure(model, velocity="120mm/s", scale="0.05mm/px", camera=cam)
    # brute-force check on a dense grid of exposures
    t = np.geomspace(1e-6, cam.saturation_exposure, 4000)
    u = [model.predict([ti * 2400.0], float(cam.noise_gl(ti, 120.0))).u_e[0] for ti in t[::20]]
    assert plan.u_e <= min(u) * (1 + 1e-6)
    assert plan.exposure <= cam.saturation_exposure


def test_camera_adapter_matches_camera_noise():
    # dicblur.Camera: variance = gain * signal + read^2 (GL); the adapter must agree
    cam = dicblur.Camera(read_noise=1.5, gain=0.02, full_well=None, bit_depth=None)
    level = 100.0
    frames = cam.capture(np.full((256, 256), level), seed=4)
    pg = PoissonGaussianCamera.from_camera(cam, nominal_exposure=2e-3, mean_level=level)
    expect = float(pg.noise_gl(2e-3, level))
    assert expect == pytest.approx(math.sqrt(0.02 * level + 1.5**2), rel=1e-12)
    assert frames.std() == pytest.approx(expect, rel=0.02)
    with pytest.raises(InputError, match="shot noise"):
        PoissonGaussianCamera.from_camera(
            dicblur.Camera(read_noise=1.0, bit_depth=None), nominal_exposure=1e-3, mean_level=level
        )


# ----------------------------------------------------------------------------- static c


def _fourier_eval(spec: np.ndarray, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """Exact band-limited (periodic) interpolation of an image at points (ys, xs)."""
    n0, n1 = spec.shape
    ky = np.fft.fftfreq(n0)
    kx = np.fft.fftfreq(n1)
    ey = np.exp(2j * np.pi * np.outer(ys, ky))  # (p, n0)
    ex = np.exp(2j * np.pi * np.outer(xs, kx))  # (p, n1)
    return np.real(np.einsum("pi,ij,pj->p", ey, spec, ex)) / (n0 * n1)


def _znssd_resid(g, ref):
    a = (g - g.mean()) / np.linalg.norm(g - g.mean())
    b = (ref - ref.mean()) / np.linalg.norm(ref - ref.mean())
    return a - b


# four 15 px subsets of a 48 px periodic image, with exact (spectral) derivatives: the static
# predictions checked against a band-limited brute force
EXACT = {
    "subset": 15,
    "points": np.array([[12, 12], [12, 34], [34, 20], [30, 34]]),
    "boundary": "periodic",
    "derivative": "spectral",
}


@pytest.mark.parametrize(
    ("shape", "motion", "criterion"),
    [
        ("translation", (0.0, 1.0), "ssd"),
        ("translation", (1.0, 1.0), "ssd"),
        ("affine", (0.0, 1.0), "ssd"),
        ("translation", (1.0, 1.0), "znssd"),
        ("affine", (0.0, 1.0), "znssd"),
    ],
)
def test_static_c_matches_brute_force_minimum(shape, motion, criterion):
    # exact (Fourier) interpolation in the brute force, so the static side uses the true
    # (spectral) derivatives; the spline-gradient default is checked against IC-GN in
    # tests/test_models_validation.py
    n = 48
    img = dicblur.speckle_pattern((n, n), speckle_size=5.0, softness=1.0, seed=3)
    wlen = 0.6
    d = np.array(motion) / np.hypot(*motion)
    ky = np.fft.fftfreq(n)[:, None]
    kx = np.fft.fftfreq(n)[None, :]
    # exact centred box blur of length W along d: sinc of the projected frequency
    spec_b = np.fft.fft2(img) * np.sinc(wlen * (d[0] * ky + d[1] * kx))
    h, centres = EXACT["subset"] // 2, EXACT["points"]
    bs = blur_sensitivity(img, motion=motion, shape=shape, criterion=criterion, **EXACT)
    oy, ox = np.meshgrid(np.arange(-h, h + 1.0), np.arange(-h, h + 1.0), indexing="ij")
    oy, ox = oy.ravel(), ox.ravel()
    for i, (r, c) in enumerate(centres):
        ref = img[r - h : r + h + 1, c - h : c + h + 1].ravel()

        def resid(p, r=r, c=c, ref=ref):
            if shape == "translation":
                xs, ys = c + ox + p[0], r + oy + p[1]
            else:
                xs = c + ox + p[0] + p[1] * ox + p[2] * oy
                ys = r + oy + p[3] + p[4] * ox + p[5] * oy
            g = _fourier_eval(spec_b, xs, ys)
            return g - ref if criterion == "ssd" else _znssd_resid(g, ref)

        p0 = np.zeros(2 if shape == "translation" else 6)
        sol = optimize.least_squares(resid, p0, xtol=1e-14, ftol=1e-14, gtol=1e-14).x
        u, v = (sol[0], sol[1]) if shape == "translation" else (sol[0], sol[3])
        along = d[1] * u + d[0] * v
        assert along == pytest.approx(bs.k[i] * wlen**2, rel=0.05, abs=0.03 * bs.c * wlen**2)


@pytest.mark.parametrize(
    ("shape", "motion", "wlen"),
    [
        ("translation", (0.0, 1.0), 3.0),
        ("affine", (1.0, 2.0), 3.0),
        ("translation", (1.0, 0.0), 5.0),
    ],
)
def test_mismatch_curve_matches_the_icgn_fixed_point_at_finite_blur(shape, motion, wlen):
    # W of the order of the speckle size, where c W**2 is off by 10-40 %. IC-GN stops where
    # sum J_f^T [f_hat - g_hat(W(x; p))] = 0 (J_f: reference gradients), which is not the
    # ZNSSD minimum once the images differ by more than a warp: solved here exactly, with
    # band-limited interpolation and true derivatives, by root finding
    n = 48
    img = dicblur.speckle_pattern((n, n), speckle_size=5.0, softness=1.0, seed=3)
    d = np.array(motion) / np.hypot(*motion)
    ky = np.fft.fftfreq(n)[:, None]
    kx = np.fft.fftfreq(n)[None, :]
    spec = np.fft.fft2(img)
    spec_b = spec * np.sinc(wlen * (d[0] * ky + d[1] * kx))
    fx = np.fft.ifft2(spec * 2j * np.pi * kx).real
    fy = np.fft.ifft2(spec * 2j * np.pi * ky).real
    h, centres = EXACT["subset"] // 2, EXACT["points"]
    curve = blur_mismatch_curve(img, [wlen], motion=motion, shape=shape, **EXACT)
    oy, ox = np.meshgrid(np.arange(-h, h + 1.0), np.arange(-h, h + 1.0), indexing="ij")
    oy, ox = oy.ravel(), ox.ravel()
    for i, (r, c) in enumerate(centres):
        sl = (slice(r - h, r + h + 1), slice(c - h, c + h + 1))
        ref = img[sl].ravel()
        gx, gy = fx[sl].ravel(), fy[sl].ravel()
        if shape == "translation":
            jac = np.stack([gx, gy], 1)
        else:
            jac = np.stack([gx, gx * ox, gx * oy, gy, gy * ox, gy * oy], 1)

        def stationarity(p, r=r, c=c, ref=ref, jac=jac):
            if shape == "translation":
                xs, ys = c + ox + p[0], r + oy + p[1]
            else:
                xs = c + ox + p[0] + p[1] * ox + p[2] * oy
                ys = r + oy + p[3] + p[4] * ox + p[5] * oy
            return jac.T @ _znssd_resid(_fourier_eval(spec_b, xs, ys), ref)

        p0 = np.zeros(jac.shape[1])
        sol = optimize.root(stationarity, p0, tol=1e-14)
        # MINPACK may stop at "xtol too small, no further improvement" with the root found
        # to rounding (seen on AMD EPYC / OpenBLAS): the residual decides
        f0 = np.abs(stationarity(p0)).max()
        assert sol.success or np.abs(sol.fun).max() < 1e-10 * f0
        u, v = (sol.x[0], sol.x[1]) if shape == "translation" else (sol.x[0], sol.x[3])
        along = d[1] * u + d[0] * v
        # linearised in the shift only: the error grows with the whole shift vector (which
        # can be 0.07 px across the motion), so it is bounded against the field's spread
        assert curve.shifts[0, i] == pytest.approx(along, rel=0.03, abs=0.02 * curve.u_blur[0])


# "central" is left out: its leading order uses the second difference for f_dd, while the
# curve blurs the image exactly
@pytest.mark.parametrize("derivative", ["bspline3", "bspline5", "spectral"])
@pytest.mark.parametrize(
    ("shape", "criterion"), [("translation", "znssd"), ("affine", "znssd"), ("affine", "ssd")]
)
def test_mismatch_curve_tends_to_leading_order(derivative, shape, criterion):
    img = dicblur.speckle_pattern((96, 96), speckle_size=4.0, seed=5)
    kw = dict(
        subset=21,
        step=15,
        motion=(1.0, 1.0),
        shape=shape,
        derivative=derivative,
        criterion=criterion,
    )
    bs = blur_sensitivity(img, **kw)
    w = np.array([0.0, 0.02, 0.04])
    curve = blur_mismatch_curve(img, w, **kw)
    assert curve.shifts.shape == (3, len(bs.k))
    assert np.all(curve.shifts[0] == 0.0)
    # xi(W) = k W^2 + O(W^4): the ratio converges to k linearly in W^2
    r1, r2 = curve.shifts[1] / w[1] ** 2, curve.shifts[2] / w[2] ** 2
    extrapolated = (4 * r1 - r2) / 3
    np.testing.assert_allclose(extrapolated, bs.k, rtol=1e-4, atol=1e-6 * bs.c)
    assert curve.u_blur[1] == pytest.approx(np.std(curve.shifts[1]))
    assert curve.mean[1] == pytest.approx(np.mean(curve.shifts[1]))
    assert curve.motion == pytest.approx((1 / math.sqrt(2), 1 / math.sqrt(2)))


def test_mismatch_curve_leaves_out_broken_down_subsets():
    # 3 px speckles blurred over 8 px: along x the texture of some subsets is gone and the
    # linearised shift runs away (IC-GN stops converging there too)
    img = dicblur.speckle_pattern((160, 160), speckle_size=3.0, softness=0.5, seed=7)
    kw = dict(subset=31, step=12, shape="affine", boundary="periodic")
    cv = blur_mismatch_curve(img, [1.0, 8.0], **kw)
    assert cv.valid_fraction[0] == 1.0
    assert 0.3 < cv.valid_fraction[1] < 1.0
    kept = np.isfinite(cv.shifts[1])
    assert cv.u_blur[1] == pytest.approx(np.std(cv.shifts[1][kept]))
    assert np.all(np.abs(cv.shifts[1][kept]) <= 1.0)
    every = blur_mismatch_curve(img, [1.0, 8.0], max_shift=1e9, **kw)
    assert every.valid_fraction[1] == 1.0
    assert every.u_blur[1] > cv.u_blur[1]
    np.testing.assert_array_equal(every.shifts[0], cv.shifts[0])


def test_blur_sensitivity_options_are_checked():
    img = dicblur.speckle_pattern((64, 64), speckle_size=4.0, seed=5)
    with pytest.raises(InputError, match="derivative='cubic'"):
        blur_sensitivity(img, subset=21, derivative="cubic")
    with pytest.raises(InputError, match="criterion='zncc'"):
        blur_sensitivity(img, subset=21, criterion="zncc")
    with pytest.raises(InputError, match="negative blur length"):
        blur_mismatch_curve(img, [1.0, -2.0], subset=21)
    with pytest.raises(InputError, match="boundary='wrap'"):
        blur_mismatch_curve(img, [1.0], subset=21, boundary="wrap")
    with pytest.raises(InputError, match="fewer than two subsets"):
        blur_mismatch_curve(np.full((64, 64), 9.0), [1.0], subset=21)


def test_blur_sensitivity_consistency(tmp_path, capsys):
    img = dicblur.speckle_pattern((128, 128), speckle_size=4.0, seed=2)
    bs = blur_sensitivity(img, subset=21)
    # `dicblur pattern metrics` shows the model's c beside the image metrics, on the same
    # subsets; the image metrics themselves hold no model quantity (metrics is below models)
    dicblur.save_image(tmp_path / "p.tif", img, bit_depth=16)
    from dicblur.cli import main

    assert main(["pattern", "metrics", str(tmp_path / "p.tif"), "--subset", "21", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["blur_sensitivity_c"] == pytest.approx(
        blur_sensitivity(dicblur.load_image(tmp_path / "p.tif"), subset=21).c, rel=1e-12
    )
    assert not hasattr(dicblur.pattern_metrics(img, subset=21), "blur_sensitivity_c")
    # intensity scaling does not change c; nor does the sign of the image
    assert blur_sensitivity(-img, subset=21).c == pytest.approx(bs.c, rel=1e-9)


def test_translation_form_reduces_to_the_1d_formula():
    # f = p(x) + q(y) with q symmetric about each subset centre: no f_x f_y coupling, so
    # k_i = -sum(f_x f_xx) / (24 sum(f_x^2)) (paper-brief s. 10), central differences
    rng = np.random.default_rng(0)
    n = 64
    p = np.convolve(np.tile(rng.normal(0, 50, n), 3), np.ones(5) / 5, mode="same")[n : 2 * n]
    q = 30 * np.cos(2 * np.pi * np.arange(n) / 16)
    img = p[None, :] + q[:, None]
    centres = np.array([[16, 20], [32, 31], [48, 45]])
    k = blur_sensitivity(
        img, subset=15, points=centres, derivative="central", boundary="periodic", criterion="ssd"
    ).k
    px = 0.5 * (np.roll(p, -1) - np.roll(p, 1))
    pxx = np.roll(p, -1) - 2 * p + np.roll(p, 1)
    for i, (_, c) in enumerate(centres):
        sl = slice(c - 7, c + 8)
        assert k[i] == pytest.approx(
            -np.sum(px[sl] * pxx[sl]) / (24 * np.sum(px[sl] ** 2)), rel=1e-9
        )


def test_intensity_scaling_invariance():
    img = dicblur.speckle_pattern((128, 128), speckle_size=4.0, seed=2)
    bs = blur_sensitivity(img, subset=21)
    # intensity scaling does not change c
    assert blur_sensitivity(3 * img + 7, subset=21).c == pytest.approx(bs.c, rel=1e-9)
    assert bs.u_blur(2.0) == pytest.approx(4 * bs.c)


# ----------------------------------------------------------------------------- bad input


def test_bad_input(model):
    s, u = _powerlaw_data(0)
    with pytest.raises(InputError, match="at least 3"):
        fit_blur_model(W[:2], s[:2], u[:2])
    bad = u.copy()
    bad[3] = np.nan
    with pytest.raises(InputError, match="NaN"):
        fit_blur_model(W, s, bad)
    with pytest.raises(InputError, match="<= 0"):
        fit_blur_model(W, -s, u)
    with pytest.raises(InputError, match="negative blur"):
        fit_blur_model(W - 1, s, u)
    with pytest.raises(InputError, match="strictly increasing"):
        fit_blur_model(W[::-1], s, u)
    with pytest.raises(InputError, match="values but blur has"):
        fit_blur_model(W, s[:-1], u)
    with pytest.raises(InputError, match="target"):
        model.max_blur(0.0)
    with pytest.raises(InputError, match="static uncertainty"):
        model.max_blur(1e-5)
    with pytest.raises(InputError, match="velocity"):
        plan_exposure(model, velocity="0mm/s", scale=0.05, target=0.01)
    with pytest.raises(InputError, match="target"):
        plan_exposure(model, velocity=120, scale=0.05, target=-1)
    with pytest.raises(InputError, match="target"):
        plan_exposure(model, velocity=120, scale=0.05)
    with pytest.raises(InputError, match="scale"):
        plan_exposure(model, velocity=120, scale=0, target=0.01)
    with pytest.raises(InputError, match="blur"):
        model.predict([-1.0])
    with pytest.raises(FitError, match="at least"):
        fit_sssig_decay(W[:2], s[:2])
    with pytest.raises(InputError, match="full_well"):
        PoissonGaussianCamera(full_well=0, read_noise=1, flux=1)


@pytest.mark.slow
def test_pattern_noise_variance_matches_monte_carlo_of_the_fixed_point():
    # noise of 2 GL in both images, W = 3 px: the exact IC-GN fixed point (root finding,
    # band-limited interpolation, true derivatives of the *noisy* reference) over 120
    # noise draws, against the linear sandwich formula
    n, sub, h, wlen, sigma = 48, 15, 7, 3.0, 2.0
    img = dicblur.speckle_pattern((n, n), speckle_size=5.0, softness=1.0, seed=3)
    kx = np.fft.fftfreq(n)[None, :]
    ky = np.fft.fftfreq(n)[:, None]
    blurred = np.fft.ifft2(np.fft.fft2(img) * np.sinc(wlen * kx)).real
    r, c = 24, 24
    pred = predict_from_pattern(
        img,
        [wlen],
        noise_sigma=sigma,
        subset=sub,
        points=[[r, c]] * 2,
        boundary="periodic",
        derivative="spectral",
    )
    oy, ox = np.meshgrid(np.arange(-h, h + 1.0), np.arange(-h, h + 1.0), indexing="ij")
    oy, ox = oy.ravel(), ox.ravel()
    sl = (slice(r - h, r + h + 1), slice(c - h, c + h + 1))
    rng = np.random.default_rng(11)
    us = []
    for _ in range(120):
        ref = img + rng.normal(0.0, sigma, img.shape)
        spec_g = np.fft.fft2(blurred + rng.normal(0.0, sigma, img.shape))
        spec_f = np.fft.fft2(ref)
        gx = np.fft.ifft2(spec_f * 2j * np.pi * kx).real[sl].ravel()
        gy = np.fft.ifft2(spec_f * 2j * np.pi * ky).real[sl].ravel()
        jac = np.stack([gx, gy], 1)
        f = ref[sl].ravel()

        def stationarity(p, jac=jac, f=f, spec_g=spec_g):
            return jac.T @ _znssd_resid(_fourier_eval(spec_g, c + ox + p[0], r + oy + p[1]), f)

        sol = optimize.root(stationarity, np.zeros(2), tol=1e-10)
        assert np.abs(sol.fun).max() < 1e-9 * np.abs(jac).sum()
        us.append(sol.x[0])
    # the two identical points share one subset: u_blur is 0, u_e is the noise term
    assert pred.u_blur[0] == pytest.approx(0.0, abs=1e-12)
    # 120 draws: the sample std is within +-20 % of the truth at ~3 sigma
    assert np.std(us) == pytest.approx(pred.u_noise[0], rel=0.2)


def test_model_from_pattern_follows_the_prediction_and_plans():
    img = dicblur.speckle_pattern((160, 160), speckle_size=4.0, seed=2)
    w = np.arange(0.0, 6.01, 0.5)
    pred = predict_from_pattern(img, w, noise_sigma=2.0, subset=21, step=10)
    assert np.all(np.diff(pred.u_e[2:]) > 0)  # the mismatch takes over
    np.testing.assert_allclose(pred.u_e, np.hypot(pred.u_noise, pred.u_blur))
    assert pred.sssig[0] == pytest.approx(dicblur.sssig(img, subset=21, step=10).mean(), rel=1e-9)
    model = model_from_pattern(img, noise_sigma=2.0, subset=21, step=10, blur=w)
    assert model.provenance["source"] == "static prediction"
    assert model.noise_sigma == 2.0
    np.testing.assert_allclose(model.predict(w).u_e, pred.u_e, rtol=0.1)
    # noise follows SSSIG / sigma**2: at 4 GL the static noise term doubles
    pred4 = predict_from_pattern(img, [0.0], noise_sigma=4.0, subset=21, step=10)
    assert model.predict([0.0], sigma=4.0).u_e[0] == pytest.approx(pred4.u_e[0], rel=0.1)
    plan = plan_exposure(model, velocity="100mm/s", scale="0.05mm/px", target="0.01px")
    assert plan.exposure > 0
    assert float(model.predict([plan.blur]).u_e[0]) == pytest.approx(0.01, rel=1e-3)
    with pytest.raises(InputError, match="noise_sigma"):
        predict_from_pattern(img, [1.0], noise_sigma=0.0, subset=21)
    with pytest.raises(InputError, match="at least 4"):
        model_from_pattern(img, noise_sigma=2.0, subset=21, blur=[0.0, 1.0, 2.0])


def test_interpolated_noise_covariance_matches_simulation():
    # white noise through the engine's own B-spline interpolant at a fractional offset:
    # the covariance the sub-pixel noise term uses (docs/models.md s. 4)
    from dicblur.models.derivatives import _interpolated_at
    from dicblur.models.derivatives import (
        interpolated_noise_covariance as _interpolated_noise_covariance,
    )

    rng = np.random.default_rng(5)
    noise = rng.standard_normal((64, 4096))
    for t, order in ((0.5, 3), (0.25, 3), (0.3, 5)):
        cov = _interpolated_noise_covariance(t, order, 5)
        assert np.allclose(cov, cov.T) and np.all(np.linalg.eigvalsh(cov) > 0)
        interp = _interpolated_at(noise, "periodic", 0.0, t, order)[0]
        # the interpolant at x + t of noise moved by t: a filtered copy of the same noise
        emp = [
            np.mean(interp[:, 8:-8] * interp[:, 8 + k : interp.shape[1] - 8 + k]) for k in range(4)
        ]
        np.testing.assert_allclose(emp, cov[0, :4], atol=0.01)
    assert np.allclose(_interpolated_noise_covariance(0.0, 3, 4), np.eye(4), atol=1e-12)


def test_subpixel_options_of_the_static_prediction():
    img = dicblur.speckle_pattern((96, 96), speckle_size=4.0, softness=0.5, seed=2)
    kw = dict(noise_sigma=2.0, subset=21, step=12, boundary="periodic")
    aligned = predict_from_pattern(img, [0.0, 1.0], **kw)
    half = predict_from_pattern(img, [0.0, 1.0], subpixel=0.5, **kw)
    avg = predict_from_pattern(img, [0.0, 1.0], subpixel="average", **kw)
    assert aligned.u_blur[0] == 0.0 and half.u_blur[0] > 0.0  # the interpolation floor
    # the interpolant filters the current image's noise most at half a pixel
    assert half.u_noise[0] < avg.u_noise[0] < aligned.u_noise[0]
    assert predict_from_pattern(img, [0.0], subpixel=0.0, **kw).u_e[0] == pytest.approx(
        aligned.u_e[0], rel=1e-9
    )
    for bad in (1.0, -0.1, "half", float("nan"), True):
        with pytest.raises(InputError, match="subpixel"):
            predict_from_pattern(img, [0.0], subpixel=bad, **kw)  # type: ignore[arg-type]
    with pytest.raises(InputError, match="subpixel"):
        blur_mismatch_curve(img, [1.0], subset=21, subpixel="average")  # type: ignore[arg-type]
