"""Exposure planning with a noise-independent floor (issue 6, brute-force agreement).

Closed forms and independent computations: the floor recovered from two noise levels,
the bias a one-level calibration puts on the noise term (algebra), the optimum of
u^2 = A/t + f^2 + B t^4, and the gradient-weighted match-score noise term against a Monte
Carlo of a least-squares translation estimate with Poisson-Gaussian captures.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import dicblur
from dicblur.errors import InputError
from dicblur.models import (
    PoissonGaussianCamera,
    fit_blur_model,
    fit_mismatch,
    gradient_weighted_level,
    mismatch_model,
    plan_exposure,
    sssig_decay,
)

S0, BETA = 2.4e6, 0.03
A_TRUE, FLOOR, C_TRUE = 1.4, 9e-4, 9e-4
W = np.arange(0.0, 6.01, 0.5)


def _two_level_data(seed: int, noise: float = 0.01):
    rng = np.random.default_rng(seed)
    w = np.tile(W, 2)
    sig = np.repeat([2.0, 8.0], W.size)
    s = sssig_decay(w, S0, BETA)
    u = mismatch_model(w, s, sig, c=C_TRUE, a=A_TRUE, floor=FLOOR)
    return w, s, sig, u * np.exp(rng.normal(0.0, noise, w.size))


def test_floor_recovered_from_two_noise_levels():
    w, s, sig, u = _two_level_data(1)
    fit = fit_mismatch(w, s, u, noise_sigma=sig, next_term=False, floor=True)
    assert fit.names == ("a", "floor", "c")
    assert fit.fixed == {"gamma": 1.0}
    for name, true in (("a", A_TRUE), ("floor", FLOOR), ("c", C_TRUE)):
        p = fit.parameter(name)
        assert p.low <= true <= p.high, (name, p)
    # with two levels a fitted gamma < 1 mimics the floor (AIC cannot choose), so "auto"
    # keeps the gamma model; three levels over a wider range separate them
    assert fit_mismatch(w, s, u, noise_sigma=sig, next_term=False).names == ("a", "gamma", "c")
    w3 = np.tile(W, 3)
    sig3 = np.repeat([1.0, 4.0, 16.0], W.size)
    s3 = sssig_decay(w3, S0, BETA)
    u3 = mismatch_model(w3, s3, sig3, c=C_TRUE, a=A_TRUE, floor=FLOOR) * np.exp(
        np.random.default_rng(1).normal(0.0, 0.01, w3.size)
    )
    auto = fit_mismatch(w3, s3, u3, noise_sigma=sig3, next_term=False)
    assert auto.names == ("a", "floor", "c")
    assert auto.parameter("floor").low <= FLOOR <= auto.parameter("floor").high
    # data without a floor keep the gamma model
    plain = mismatch_model(w3, s3, sig3, c=C_TRUE, a=A_TRUE) * np.exp(
        np.random.default_rng(2).normal(0.0, 0.01, w3.size)
    )
    assert fit_mismatch(w3, s3, plain, noise_sigma=sig3, next_term=False).names == (
        "a",
        "gamma",
        "c",
    )


def test_noise_growth_recovered_from_two_noise_levels():
    # the noise term grows as (1 + e W^4): separable from c only through the two levels
    w, s, sig, _ = _two_level_data(0)
    e = 2e-3
    rng = np.random.default_rng(6)
    u = mismatch_model(w, s, sig, c=C_TRUE, a=A_TRUE, floor=FLOOR, noise_blur=e) * np.exp(
        rng.normal(0.0, 0.01, w.size)
    )
    fit = fit_mismatch(w, s, u, noise_sigma=sig, next_term=False, floor=True)
    # "auto" kept the growth (its W**2 and W**4 parts: data made with d = 0)
    assert fit.names == ("a", "noise_blur2", "noise_blur", "floor", "c")
    for name, true in (("c", C_TRUE), ("a", A_TRUE), ("noise_blur2", 0.0)):
        p = fit.parameter(name)
        assert p.low <= true <= p.high, (name, p)
    # e over repeated seeds: roughly nominal coverage of its 95 % interval, small bias
    hits, vals = [], []
    for seed in range(30):
        ui = mismatch_model(w, s, sig, c=C_TRUE, a=A_TRUE, floor=FLOOR, noise_blur=e) * np.exp(
            np.random.default_rng(100 + seed).normal(0.0, 0.01, w.size)
        )
        pe = fit_mismatch(
            w, s, ui, noise_sigma=sig, next_term=False, floor=True, noise_blur=True
        ).parameter("noise_blur")
        hits.append(pe.low <= e <= pe.high)
        vals.append(pe.value)
    assert np.mean(hits) >= 0.8
    assert np.mean(vals) == pytest.approx(e, rel=0.08)
    # without it, c absorbs the growth of the 8 GL points and comes out high
    plain = fit_mismatch(w, s, u, noise_sigma=sig, next_term=False, floor=True, noise_blur=False)
    assert plain["c"] > fit.parameter("c").high
    with pytest.raises(InputError, match="noise_blur=True"):
        fit_mismatch(W, sssig_decay(W, S0, BETA), u[: W.size], noise_sigma=2.0, noise_blur=True)


def test_floor_needs_two_noise_levels():
    s = sssig_decay(W, S0, BETA)
    u = mismatch_model(W, s, 2.0, c=C_TRUE, a=A_TRUE, floor=FLOOR)
    assert "floor" not in fit_mismatch(W, s, u, noise_sigma=2.0).names
    with pytest.raises(InputError, match="floor=True"):
        fit_mismatch(W, s, u, noise_sigma=2.0, floor=True)
    with pytest.raises(InputError, match="floor="):
        fit_mismatch(W, s, u, noise_sigma=2.0, floor="yes")  # type: ignore[arg-type]


def test_one_level_calibration_absorbs_the_floor_into_a():
    # noise-dominated points at one level: a_fit sigma^2 / S ~= a sigma^2 / S + f^2, so
    # a_fit ~= a + f^2 S / sigma^2 (algebra); extrapolated to 6x the noise, the one-level
    # model over-predicts the noise term by sqrt(a_fit / a), the two-level model does not
    w = np.arange(0.0, 1.51, 0.25)  # blur term negligible here
    s = sssig_decay(w, S0, BETA)
    u = mismatch_model(w, s, 2.0, c=C_TRUE, a=A_TRUE, floor=FLOOR)
    one = fit_mismatch(w, s, u, noise_sigma=2.0, next_term=False)
    expect = A_TRUE + FLOOR**2 * float(np.mean(s)) / 4.0
    assert one["a"] == pytest.approx(expect, rel=0.05)
    assert one["a"] > 1.3 * A_TRUE
    w2, s2, sig2, u2 = _two_level_data(3, noise=0.0)
    two = fit_mismatch(w2, s2, u2, noise_sigma=sig2, next_term=False, floor=True)
    assert two["a"] == pytest.approx(A_TRUE, rel=1e-4)
    assert two["floor"] == pytest.approx(FLOOR, rel=1e-4)


def _closed_form_model():
    # beta = 0 so that SSSIG is flat: u^2 = a sigma^2 / S0 + f^2 + c^2 W^4
    w, _, sig, _ = _two_level_data(0)
    s = np.full(w.size, S0)
    u = mismatch_model(w, s, sig, c=C_TRUE, a=A_TRUE, floor=FLOOR)
    return fit_blur_model(
        w, s, u, noise_sigma=sig, mean_level=100.0, default="mismatch", floor=True, compare=False
    )


def test_plan_with_floor_closed_form():
    # shot-noise limit: sigma^2(t) = L^2 / (flux t), so u^2 = A/t + f^2 + B t^4 with
    # A = a L^2 / (S0 flux), B = c^2 k^4; d/dt = 0 gives t* = (A / 4B)^(1/5) (the floor does
    # not move the optimum) and u*^2 = 5A / (4 t*) + f^2
    m = _closed_form_model()
    assert m.mismatch is not None and "floor" in m.mismatch.names
    flux, v, sc = 2e5, 120.0, 0.05
    cam = PoissonGaussianCamera(full_well=1e12, read_noise=0.0, flux=flux)
    plan = plan_exposure(m, velocity=v, scale=sc, camera=cam)
    big_a = A_TRUE * 100.0**2 / (S0 * flux)
    big_b = C_TRUE**2 * (v / sc) ** 4
    t_star = (big_a / (4 * big_b)) ** 0.2
    assert plan.exposure == pytest.approx(t_star, rel=1e-4)
    assert plan.u_e == pytest.approx(math.sqrt(1.25 * big_a / t_star + FLOOR**2), rel=1e-4)
    pred = m.predict([2.0], 3.0)
    assert pred.u_floor == pytest.approx(FLOOR, rel=1e-4)
    np.testing.assert_allclose(pred.u_e**2, pred.u_noise**2 + FLOOR**2 + pred.u_blur**2, rtol=1e-6)
    assert not any("from one calibration noise level" in n for n in plan.notes)


def test_plan_warns_when_one_level_is_extrapolated():
    s = sssig_decay(W, S0, BETA)
    u = mismatch_model(W, s, 2.0, c=C_TRUE, a=A_TRUE)
    m = fit_blur_model(
        W, s, u, noise_sigma=2.0, mean_level=100.0, default="mismatch", compare=False
    )
    # dim light: the optimum is at a noise far above the 2 GL of the calibration
    cam = PoissonGaussianCamera(full_well=1e12, read_noise=5.0, flux=2e5)
    plan = plan_exposure(m, velocity=120.0, scale=0.05, camera=cam)
    assert cam.noise_gl(plan.exposure, 100.0) > 4.0
    assert any("extrapolated from one calibration noise level" in n for n in plan.notes)


def test_gradient_weighted_noise_against_monte_carlo():
    # Signal-dependent noise: the linearised least-squares translation between two captures
    # has var(u) = sum g^2 (var_ref + var_cur) / (sum g^2)^2, var = gain I + read^2; i.e.
    # eq. 2 (2 sigma^2 / SSSIG) with sigma from the camera at the gradient-weighted level.
    # Checked against a Monte Carlo of dicblur.Camera captures (Poisson + Gaussian) on
    # bright blobs on a dark background, where the mean level is the wrong one.
    yy, xx = np.mgrid[0:32, 0:32].astype(np.float64)
    img = np.full((32, 32), 10.0)
    for cy, cx in ((8, 9), (22, 12), (14, 24), (25, 26)):
        img += 190.0 * np.exp(-((yy - cy) ** 2 + (xx - cx) ** 2) / (2 * 2.5**2))
    level = gradient_weighted_level(img)
    g = np.zeros_like(img)
    g[1:-1, 1:-1] = 0.5 * (img[1:-1, 2:] - img[1:-1, :-2])
    assert level == pytest.approx(float(np.sum(g**2 * img) / np.sum(g**2)), rel=1e-12)
    assert level > 1.5 * img.mean()
    cam = dicblur.Camera(read_noise=1.0, gain=0.5, full_well=None, bit_depth=None)
    pg = PoissonGaussianCamera.from_camera(cam, nominal_exposure=1e-3, mean_level=img.mean())
    sig_eff = float(pg.noise_gl(1e-3, img.mean(), level))
    sig_mean = float(pg.noise_gl(1e-3, img.mean()))
    predicted = math.sqrt(2 * sig_eff**2 / np.sum(g**2))
    rng = np.random.default_rng(11)
    reps = 3000
    u = np.array(
        [np.sum(g * (cam.capture(img, rng=rng) - cam.capture(img, rng=rng))) for _ in range(reps)]
    ) / np.sum(g**2)
    # the std of a std estimate is ~ 1/sqrt(2 reps) = 1.3 %; allow about 3.5 of them
    assert np.std(u) == pytest.approx(predicted, rel=0.045)
    assert math.sqrt(2 * sig_mean**2 / np.sum(g**2)) < 0.85 * np.std(u)
    # the planner takes it as noise_level: more shot noise, so a longer optimal exposure
    m = _closed_form_model()
    cam2 = PoissonGaussianCamera(full_well=1e12, read_noise=3.0, flux=2e5)
    base = plan_exposure(m, velocity=120.0, scale=0.05, camera=cam2)
    brighter = plan_exposure(m, velocity=120.0, scale=0.05, camera=cam2, noise_level=200.0)
    assert brighter.exposure > base.exposure
    with pytest.raises(InputError, match="noise_level"):
        plan_exposure(m, velocity=120.0, scale=0.05, camera=cam2, noise_level=-1.0)
    with pytest.raises(InputError, match="motion"):
        gradient_weighted_level(img, motion=(0.0, 0.0))


def test_cross_term_recovered_and_planned():
    # noise-free variance (b W)^2: the mismatch x interpolation cross term (docs/models.md
    # s. 4); with two noise levels it is told from the noise term, and leaving it out
    # moves a camera plan by several per cent
    b_true = 9e-4
    w = np.tile(W, 2)
    sig = np.repeat([2.0, 8.0], W.size)
    s = sssig_decay(w, S0, BETA)
    exact = mismatch_model(w, s, sig, c=C_TRUE, a=A_TRUE, floor=FLOOR, cross=b_true)
    assert np.allclose(
        exact**2 - mismatch_model(w, s, sig, c=C_TRUE, a=A_TRUE, floor=FLOOR) ** 2,
        (b_true * w) ** 2,
    )
    hits = []
    for seed in range(20):
        u = exact * np.exp(np.random.default_rng(300 + seed).normal(0.0, 0.01, w.size))
        fit = fit_mismatch(w, s, u, noise_sigma=sig, next_term=False, noise_blur=False)
        assert fit.names == ("a", "floor", "cross", "c")  # "auto" keeps floor and cross
        hits.append(
            all(
                fit.parameter(n).low <= t <= fit.parameter(n).high
                for n, t in (("a", A_TRUE), ("floor", FLOOR), ("cross", b_true), ("c", C_TRUE))
            )
        )
    assert np.mean(hits) >= 0.75
    cam = PoissonGaussianCamera.from_camera(
        dicblur.Camera(read_noise=2.0, gain=0.05, full_well=None, bit_depth=None),
        nominal_exposure=1e-3,
        mean_level=127.5,
    )

    def planned(u: np.ndarray, **kw: object) -> float:
        m = fit_blur_model(
            w,
            s,
            u,
            noise_sigma=sig,
            mean_level=127.5,
            default="mismatch",
            compare=False,
            noise_blur=False,
            **kw,
        )  # type: ignore[arg-type]
        return plan_exposure(m, velocity=100.0, scale=0.05, camera=cam).exposure

    t_true = planned(exact, floor=True, cross=True)  # exact data: the true model's plan
    u = exact * np.exp(np.random.default_rng(7).normal(0.0, 0.01, w.size))
    assert planned(u) == pytest.approx(t_true, rel=0.01)
    assert planned(u, cross=False) > 1.02 * t_true  # the floor model bends: plan too long
    with pytest.raises(InputError, match="cross=True"):
        fit_mismatch(W, sssig_decay(W, S0, BETA), exact[: W.size], noise_sigma=2.0, cross=True)
    with pytest.raises(InputError, match="cross="):
        fit_mismatch(w, s, exact, noise_sigma=sig, cross="yes")  # type: ignore[arg-type]
