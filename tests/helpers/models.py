"""Synthetic data of known parameters for the model tests and benchmarks.

``benchmarks/bench_coverage.py`` and ``benchmarks/bench_trust.py`` import this module too
(through ``_harness.use_tests_dir``), so a test and its benchmark measure one computation.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from dicblur.models import (
    StaticTerms,
    fit_mismatch,
    fit_power_law,
    fit_sssig_decay,
    fit_static_scales,
    mismatch_model,
    sssig_decay,
)

# SSSIG at W = 0 (GL^2) and its decay rate (1/px^2) of the synthetic patterns
S0, BETA = 2.4e6, 0.03

COVERAGE_MODELS = ("power_law", "decay", "mismatch", "mismatch_cross", "static")


def static_table(breakdown: float | None = None, top: float = 8.0) -> StaticTerms:
    """A static-prediction table with the shapes of a real one: noise terms falling with
    SSSIG, a mismatch term growing as W^4 with a ripple of period 2 px, on a 0.25 px grid
    from 0 to ``top`` px; half the points valid from ``breakdown`` px on."""
    w = np.round(np.arange(0.0, top + 1e-9, 0.25), 10)
    s = sssig_decay(w, S0, BETA)
    off = (w / 2) % 1.0
    return StaticTerms(
        blur=tuple(w),
        noise=tuple(1.6 / s),
        noise2=tuple(2e-10 * (1 + 0.1 * w**2) * S0 / s**2),
        mismatch=tuple((9e-4 * w**2) ** 2 + (1e-3 * np.sin(np.pi * off)) ** 2),
        valid_fraction=tuple(np.where(w >= (breakdown or np.inf), 0.5, 1.0)),
        breakdown_blur=breakdown,
    )


def static_truth(
    terms: StaticTerms, w: np.ndarray, sig: np.ndarray, kn: float = 0.95, kb: float = 1.05
) -> np.ndarray:
    """u_e (px) of the static kind with scales ``kn`` (noise) and ``kb`` (blur mismatch) at
    blur ``w`` (px) and noise ``sig`` (GL)."""
    x = np.array(terms.blur)
    n1, n2, b2 = (np.interp(w, x, np.array(v)) for v in (terms.noise, terms.noise2, terms.mismatch))
    return np.sqrt(kn**2 * (sig**2 * n1 + sig**4 * n2) + kb**2 * b2)


def two_noise_sweep() -> tuple[np.ndarray, np.ndarray]:
    """Blur 0..6 px by 0.5 px at 2 and 8 GL: (W, sigma), each of shape (26,)."""
    w1 = np.arange(0.0, 6.01, 0.5)
    return np.tile(w1, 2), np.repeat([2.0, 8.0], w1.size)


def coverage_case(which: str, rng: np.random.Generator) -> tuple[dict[str, float], Any]:
    """One data set with known parameters for model ``which`` (docs/models.md s. 5) and its
    fit: ``(truth, fit)``, truth naming the parameters whose intervals are checked."""
    if which == "static":
        terms = static_table()
        w, sig = two_noise_sweep()
        u = static_truth(terms, w, sig) * np.exp(rng.normal(0, 0.05, w.size))
        return {"k_noise": 0.95, "k_blur": 1.05}, fit_static_scales(terms, w, sig, u)
    if which == "power_law":
        w = np.arange(0.0, 3.01, 0.25)
        s = sssig_decay(w, S0, BETA) * np.exp(rng.normal(0, 0.01, w.size))
        truth = {"u_ref": 2e-3, "alpha": 2.7}
        u = 2e-3 * (s / S0) ** -2.7 * np.exp(rng.normal(0, 0.05, w.size))
        return truth, fit_power_law(s, u, blur=w, sssig_ref=S0)
    if which == "decay":
        w = np.arange(0.0, 8.01, 0.5)
        s = sssig_decay(w, S0, BETA) + rng.normal(0, 0.02 * S0, w.size)
        return {"sssig0": S0, "beta": BETA}, fit_sssig_decay(w, s)
    if which == "mismatch":
        w = np.arange(0.0, 6.01, 0.5)
        s = sssig_decay(w, S0, BETA)
        truth = {"a": 2.0, "c": 3e-4}
        u = mismatch_model(w, s, 2.0, **truth) * np.exp(rng.normal(0, 0.05, w.size))
        return truth, fit_mismatch(
            w, s, u, noise_sigma=2.0, next_term=False, floor=False, noise_blur=False, cross=False
        )
    if which != "mismatch_cross":
        raise ValueError(f"unknown model {which!r}; one of {COVERAGE_MODELS}")
    w, sig = two_noise_sweep()
    s = sssig_decay(w, S0, BETA)
    truth = {"a": 1.4, "floor": 1e-3, "cross": 1e-3, "c": 3e-4}
    u = mismatch_model(w, s, sig, **truth) * np.exp(rng.normal(0, 0.05, w.size))
    return truth, fit_mismatch(
        w, s, u, noise_sigma=sig, next_term=False, floor=True, noise_blur=False, cross=True
    )


def interval_coverage(which: str, n: int, *, first_seed: int) -> dict[str, dict]:
    """Fraction of ``n`` data sets (seeds ``first_seed`` ...) whose interval holds the true
    value, per parameter (``"coverage"``), and how many intervals each method gave
    (``"ci_methods"``)."""
    hits: dict[str, int] = {}
    methods: dict[str, int] = {}
    for seed in range(n):
        truth, fit = coverage_case(which, np.random.default_rng(first_seed + seed))
        methods[fit.ci_method] = methods.get(fit.ci_method, 0) + 1
        for name, value in truth.items():
            p = fit.parameter(name)
            hits[name] = hits.get(name, 0) + int(p.low <= value <= p.high)
    return {"coverage": {k: v / n for k, v in hits.items()}, "ci_methods": methods}


def simulated_u_e(
    folder: Path, tag: str, *, noise: float, blur: float, size: int, reps: int
) -> np.ndarray:
    """u_e (px) of each repetition of a direct simulation (a campaign on the calibration's
    pattern, paper4 seed 1, subset 21) at ``noise`` GL and ``blur`` px; the store is
    ``folder/<tag>.zarr``."""
    from dicblur.campaign import open_results, run_campaign
    from dicblur.campaign.calibrate import calibration_spec

    spec = calibration_spec(
        "paper4",
        noise=noise,
        subset=21,
        size=(size, size),
        blur=[float(blur)],
        repetitions=reps,
        seed=1,
    )
    run_campaign(spec, folder / f"{tag}.zarr", serial=True)
    return open_results(folder / f"{tag}.zarr")["u_e"].values.ravel()


def noise_variance_terms(
    image: np.ndarray,
    blur: list[float],
    points: np.ndarray,
    subset: int,
    *,
    boundary: str = "periodic",
    complete: bool = False,
) -> np.ndarray:
    """The static prediction's noise variances per GL^2 of noise for a translation subset
    blurred along the columns (``shifts_and_variance``'s second output, bspline3, ZNSSD, no
    shift limit): ``complete=False`` is the earlier first-order formula (reference
    intensities only) that the complete noise term (issue 14, item 4) replaced."""
    from dicblur.models.sensitivity import shifts_and_variance
    from dicblur.models.subset_algebra import SubsetMatcher

    var = shifts_and_variance(
        image,
        blur,
        points,
        subset,
        SubsetMatcher((0.0, 1.0), "translation", "bspline3", boundary),
        criterion="znssd",
        max_shift=np.inf,
        chunk=256,
        variance=True,
        complete=complete,
    )[1]
    assert var is not None
    return var


def subset_centres(n: int, subset: int, step: int) -> np.ndarray:
    """Centres (row, col) of the subsets that fit in an n x n image with a one-pixel
    margin, every ``step`` px: shape (n_points, 2)."""
    h = subset // 2
    return np.array(
        [[r, c] for r in range(h + 1, n - h - 1, step) for c in range(h + 1, n - h - 1, step)]
    )


def bruteforce_ssd_u_e(
    image: np.ndarray, blurs: np.ndarray, points: np.ndarray, subset: int
) -> list[float]:
    """u_e (px) at each blur W independent of the DIC code: the SSD minimum of each subset
    of ``image`` against the image blurred by a centred box of W px along the columns, with
    exact (Fourier) blur and shift and a least-squares search; the std over ``points`` of
    the column shift found."""
    from scipy import optimize

    h = subset // 2
    spec = np.fft.fft2(image)
    ky = np.fft.fftfreq(image.shape[0])[:, None]
    kx = np.fft.fftfreq(image.shape[1])[None, :]
    u_e = []
    for wl in blurs:
        blurred = spec * np.sinc(wl * kx)
        xs = []
        for r, c in points:
            sl = (slice(r - h, r + h + 1), slice(c - h, c + h + 1))
            ref = image[sl]

            def resid(p, sl=sl, ref=ref, blurred=blurred):
                shift = np.exp(2j * np.pi * (kx * p[0] + ky * p[1]))
                return (np.fft.ifft2(blurred * shift).real[sl] - ref).ravel()

            xs.append(optimize.least_squares(resid, [0.0, 0.0], xtol=1e-10).x[0])
        u_e.append(float(np.std(xs)))
    return u_e


def noisy_dic_scatter(
    reference: np.ndarray,
    current: np.ndarray,
    *,
    sigma: float,
    reps: int,
    rng: np.random.Generator,
    shape: str,
) -> list[float]:
    """Std over the converged points of the column displacement IC-GN measures (subset 21,
    step 10) between ``reference`` and ``current``, each with fresh Gaussian noise of
    ``sigma`` GL, for each of ``reps`` repetitions (px)."""
    import dicblur

    u_e = []
    for _ in range(reps):
        res = dicblur.correlate(
            reference + rng.normal(0, sigma, reference.shape),
            current + rng.normal(0, sigma, reference.shape),
            subset=21,
            step=10,
            shape=shape,
        )
        u_e.append(float(np.std(res.u[res.converged])))
    return u_e
