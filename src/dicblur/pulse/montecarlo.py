"""Monte Carlo of the 1-D pulse correlation under noise (paper Section V-B), vectorised.

For every blur width w and trial, a reference ``s_o = p_b(k, w_ref) + tau_o`` and a
current ``s_b = p_b(k - u, w) + tau_b`` (pixels ``k = 0 .. N du - 1``, periodic, Gaussian
noise of std sigma in both) are correlated; the displacement is the global minimiser of the
SSD over ``|xi| <= du / 2`` (one period: larger shifts alias). Sign convention: the
estimate equals the imposed displacement ``u`` of the current signal (the paper's xi of
eq. 12 is ``-u``).

How the shifted signal is interpolated (``interpolation``):

``"fourier"`` (default)
    Exact band-limited shift of the periodic sampled signal, noise included
    (``g(k + xi)`` has DFT ``G_q exp(2 pi i q xi / L)``; the Nyquist term of an even length
    is the real ``cos(pi (k + xi))`` component). The SSD is then a trigonometric polynomial:
    integer lags from one FFT cross-correlation, then safeguarded Newton iterations on the
    analytic first and second derivatives inside ``[j - 1, j + 1]`` around the best lag
    ``j``, started from a parabola through the three integer values (numba kernel).
``"linear"``
    Linear interpolation of the noisy samples: the SSD is quadratic on each unit interval,
    minimised exactly on every interval (FFT cross-correlations give all coefficients).
``"analytic"``
    The shifted signal's noise-free closed form is moved (an oracle interpolator) while its
    noise stays on the pixels. The SSD is piecewise quadratic between known kinks and is
    minimised exactly on every piece. This is the idealisation behind the first-principles
    ``sqrt(2 sigma^2 / SSSIG_b)`` prediction.

``"bspline"``
    An IC-GN-style matcher as in the 2-D engine: the moved signal is read through its
    periodic cubic B-spline interpolant (noise included) and the fixed signal's gradient
    is the derivative of its own B-spline interpolant at the pixels. The estimate is the
    root of the IC-GN fixed-point equation ``sum D f (g(k + xi) - f(k)) = 0`` near the best
    integer lag (Newton on the interpolant's exact derivative).
``"keys"``
    The same with Keys' cubic convolution (a = -1/2) as the interpolant and central
    differences as the gradient (a common DIC configuration).

``shifted`` says which signal is moved: ``"blurred"`` (paper eq. 12) or ``"reference"``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numba
import numpy as np
import xarray as xr
from numpy.typing import ArrayLike, NDArray

from ..arrays import Float64Array, IndexArray, UInt8Array
from ..checks import as_whole, check_choice, check_finite_number, check_positive, describe
from ..errors import InputError
from ..patterns import SeedLike
from .correlation import (
    gradient_sums,
    predict_first_principles,
    predict_interpolated_noise,
    predict_paper_linear,
)
from .signal import PulseTrain, edge_length, regime

__all__ = [
    "PAPER_TRAIN",
    "PAPER_WIDTHS",
    "MonteCarloSettings",
    "derivative_multiplier",
    "estimate_shift",
    "simulate",
]

Interpolation = Literal["fourier", "linear", "analytic", "bspline", "keys"]
#: Correlators of the IC-GN type (reference-gradient fixed point)
_ICGN_KINDS = ("bspline", "keys")
Shifted = Literal["blurred", "reference"]

#: The paper's Monte Carlo signal (Section V-B): a = 1, dp = 6, du = 22.
PAPER_TRAIN = PulseTrain(a=1.0, dp=6.0, du=22.0)
#: The paper's blur widths, w = 1..27 px.
PAPER_WIDTHS = tuple(float(w) for w in range(1, 28))

_Z95 = 1.959963984540054


@dataclass(frozen=True)
class MonteCarloSettings:
    """Inputs of :func:`simulate`, recorded in the dataset attributes."""

    train: PulseTrain
    widths: tuple[float, ...]
    sigma: float
    n_periods: int
    trials: int
    seed: int | None
    displacement: float
    interpolation: str
    shifted: str
    w_ref: float


# --------------------------------------------------------------------------------------
# Fourier estimator
# --------------------------------------------------------------------------------------
@numba.njit(cache=True, parallel=True)
def _newton_fourier(h, gn, fn, length, start, lo, hi, tol, max_iter):  # pragma: no cover
    # J(x) = const - (4/L) sum_q Re(H_q e^{i w_q x}) + (1/L)(G_N cos(pi x) - F_N)^2,
    # w_q = 2 pi q / L, q = 1 .. Q (H excludes q = 0 and the Nyquist bin).
    ntr, nq = h.shape
    out = np.empty(ntr)
    status = np.zeros(ntr, dtype=np.uint8)
    w1 = 2.0 * math.pi / length
    for t in numba.prange(ntr):
        x = start[t]
        st = 1
        for _ in range(max_iter):
            z1r = math.cos(w1 * x)
            z1i = math.sin(w1 * x)
            zr = z1r
            zi = z1i
            d1 = 0.0
            d2 = 0.0
            for q in range(nq):
                wq = w1 * (q + 1)
                hr = h[t, q].real
                hi_ = h[t, q].imag
                pr = hr * zr - hi_ * zi
                pi_ = hr * zi + hi_ * zr
                d1 += wq * pi_
                d2 += wq * wq * pr
                zr, zi = zr * z1r - zi * z1i, zr * z1i + zi * z1r
            d1 *= 4.0 / length
            d2 *= 4.0 / length
            if gn[t] != 0.0:
                c = math.cos(math.pi * x)
                s = math.sin(math.pi * x)
                r = gn[t] * c - fn[t]
                d1 += -2.0 * math.pi * r * gn[t] * s / length
                d2 += 2.0 * math.pi**2 * (gn[t] ** 2 * s * s - r * gn[t] * c) / length
            if d2 > 0.0:
                step = -d1 / d2
                if step > 0.5:
                    step = 0.5
                elif step < -0.5:
                    step = -0.5
            else:
                step = -0.05 if d1 > 0 else 0.05
            xn = x + step
            if xn < lo[t]:
                xn = lo[t]
            elif xn > hi[t]:
                xn = hi[t]
            done = abs(xn - x) < tol
            x = xn
            if done:
                st = 0
                break
        if st == 0 and (x <= lo[t] or x >= hi[t]):
            st = 2
        out[t] = x
        status[t] = st
    return out, status


def _lag_window(length: int, du: float) -> IndexArray:
    half = math.floor(du / 2 + 1e-9)
    return np.arange(-half, half + 1)


def _fourier_shift_estimate(
    moving: Float64Array, fixed: Float64Array, du: float, tol: float = 1e-11
) -> tuple[Float64Array, UInt8Array]:
    length = moving.shape[-1]
    return _fourier_estimate_from_spectra(
        np.fft.rfft(moving, axis=-1), np.fft.rfft(fixed, axis=-1), length, du, tol
    )


def _fourier_estimate_from_spectra(
    gm: NDArray[np.complex128],
    fm: NDArray[np.complex128],
    length: int,
    du: float,
    tol: float = 1e-11,
) -> tuple[Float64Array, UInt8Array]:
    """Fourier-shift SSD minimiser from the rFFTs of the moving and fixed signals."""
    cross = gm * np.conj(fm)
    corr = np.fft.irfft(cross, length, axis=-1)  # corr[j] = sum_k g(k + j) f(k)
    lags = _lag_window(length, du)
    c = corr[:, lags % length]
    jbest = np.argmax(c, axis=-1)
    jbest = np.clip(jbest, 1, lags.size - 2) if lags.size >= 3 else jbest
    rows = np.arange(c.shape[0])
    cm, c0, cp = c[rows, jbest - 1], c[rows, jbest], c[rows, jbest + 1]
    den = cm - 2 * c0 + cp
    with np.errstate(divide="ignore", invalid="ignore"):
        delta = np.where(den < 0, 0.5 * (cm - cp) / den, 0.0)
    delta = np.clip(np.nan_to_num(delta), -0.5, 0.5)
    centre = lags[jbest].astype(np.float64)
    even = length % 2 == 0
    nq = length // 2 - (1 if even else 0)
    h = np.ascontiguousarray(cross[:, 1 : nq + 1])
    gn = gm[:, -1].real.copy() if even else np.zeros(c.shape[0])
    fn = fm[:, -1].real.copy() if even else np.zeros(c.shape[0])
    return _newton_fourier(
        h, gn, fn, float(length), centre + delta, centre - 1.0, centre + 1.0, tol, 60
    )


def _white_noise_spectrum(
    rng: np.random.Generator, trials: int, length: int, sigma: float
) -> NDArray[np.complex128]:
    """rFFT of ``trials`` realisations of white Gaussian noise (std ``sigma``, ``length``
    samples), drawn directly in the Fourier domain.

    The DFT is orthogonal up to ``sqrt(L)``, so the rFFT of white Gaussian noise is, exactly in
    distribution, independent Gaussians: ``N(0, L sigma^2)`` for the real DC (and Nyquist, L
    even) bins and ``N(0, L sigma^2 / 2)`` for the real and imaginary parts of the others. This
    uses the same L normal draws per signal as real-space noise and saves one FFT. Draws are
    float32 (faster; their 2^-24 rounding is irrelevant at any noise level).
    """
    z = rng.standard_normal((trials, length), dtype=np.float32)
    nf = length // 2 + 1
    out = np.empty((trials, nf), dtype=np.complex128)
    full = sigma * math.sqrt(length)
    half = sigma * math.sqrt(length / 2)
    out[:, 0] = full * z[:, 0]
    if length % 2 == 0:
        inner = nf - 2
        out[:, -1] = full * z[:, -1]
    else:
        inner = nf - 1
    out.real[:, 1 : 1 + inner] = half * z[:, 1 : 1 + inner]
    out.imag[:, 1 : 1 + inner] = half * z[:, 1 + inner : 1 + 2 * inner]
    return out


# --------------------------------------------------------------------------------------
# Linear-interpolation estimator
# --------------------------------------------------------------------------------------
def _linear_shift_estimate(
    moving: Float64Array, fixed: Float64Array, du: float
) -> tuple[Float64Array, UInt8Array]:
    length = moving.shape[-1]
    gm = np.fft.rfft(moving, axis=-1)
    corr = np.fft.irfft(gm * np.conj(np.fft.rfft(fixed, axis=-1)), length, axis=-1)
    lags = _lag_window(length, du)[:-1]  # intervals [j, j + 1]
    cj = corr[:, lags % length]
    cj1 = corr[:, (lags + 1) % length]
    eg = np.sum(moving**2, axis=-1)[:, None]
    ef = np.sum(fixed**2, axis=-1)[:, None]
    r1 = np.sum(moving * np.roll(moving, -1, axis=-1), axis=-1)[:, None]
    c0 = eg + ef - 2 * cj
    c1 = r1 - eg - cj1 + cj
    c2 = 2 * eg - 2 * r1
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(c2 > 0, -c1 / c2, 0.0)
    t = np.clip(t, 0.0, 1.0)
    val = c0 + 2 * t * c1 + t**2 * c2
    k = np.argmin(val, axis=-1)
    rows = np.arange(val.shape[0])
    return lags[k] + t[rows, k], np.zeros(val.shape[0], dtype=np.uint8)


# --------------------------------------------------------------------------------------
# Analytic (oracle) estimator: noise-free closed form moved, noise fixed on the pixels
# --------------------------------------------------------------------------------------
def _analytic_shift_estimate(
    train: PulseTrain, model_w: float, model_shift: float, data: Float64Array
) -> tuple[Float64Array, UInt8Array]:
    length = data.shape[-1]
    half = math.floor(train.du / 2 + 1e-9)
    k = np.arange(length, dtype=np.float64)
    frac = np.unique(np.mod(train.breakpoints(model_w) + model_shift, 1.0))
    ints = np.arange(-half - 1, half + 2)
    kinks = np.unique((ints[:, None] + frac[None, :]).ravel())
    kinks = np.unique(np.concatenate([[-half, half], kinks[(kinks > -half) & (kinks < half)]]))
    lo, hi = kinks[:-1], kinks[1:]
    mid = (lo + hi) / 2
    x = k[None, :] + mid[:, None] - model_shift
    gval = train.blurred(x, model_w)  # (P, L)
    slope = train.blurred_gradient(x, model_w)
    a = np.sum(slope**2, axis=-1)
    b = 2 * np.sum(slope * gval, axis=-1)[None, :] - 2 * data @ slope.T
    c = np.sum(gval**2, axis=-1)[None, :] - 2 * data @ gval.T + np.sum(data**2, axis=-1)[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.where(a > 0, -b / (2 * a), 0.0)
    d = np.clip(d, (lo - mid)[None, :], (hi - mid)[None, :])
    val = a * d**2 + b * d + c
    j = np.argmin(val, axis=-1)
    rows = np.arange(val.shape[0])
    return mid[j] + d[rows, j], np.zeros(val.shape[0], dtype=np.uint8)


# --------------------------------------------------------------------------------------
# IC-GN-type estimators: B-spline (engine-like) and Keys + central differences
# --------------------------------------------------------------------------------------
def derivative_multiplier(length: int, kind: str) -> NDArray[np.complex128]:
    """Fourier multiplier (rFFT bins) of the correlator's derivative D of a periodic signal.

    ``"fourier"``: the spectral derivative ``i q`` (Nyquist 0); ``"bspline"``: the
    derivative of the cubic B-spline interpolant at the pixels, ``i sin q / ((4 + 2 cos q)
    / 6)``; ``"keys"``: central differences ``i sin q`` (also the derivative of Keys'
    interpolant at the pixels).
    """
    q = 2 * math.pi * np.arange(length // 2 + 1) / length
    out: NDArray[np.complex128]
    if kind == "bspline":
        out = (1j * np.sin(q) * 6.0 / (4.0 + 2.0 * np.cos(q))).astype(np.complex128)
    elif kind == "keys":
        out = (1j * np.sin(q)).astype(np.complex128)
    else:
        out = (1j * q).astype(np.complex128)
        if length % 2 == 0:
            out[-1] = 0.0
    return out


def _taps(t: Float64Array, kind: str) -> tuple[Float64Array, Float64Array]:
    """Weights (4, n) of taps -1..2 around ``floor(x)`` and of their derivative in ``t``."""
    if kind == "bspline":
        u = 1.0 - t
        w = np.stack(
            [
                u**3 / 6,
                (3 * t**3 - 6 * t**2 + 4) / 6,
                (-3 * t**3 + 3 * t**2 + 3 * t + 1) / 6,
                t**3 / 6,
            ]
        )
        dw = np.stack([-(u**2) / 2, (3 * t**2 - 4 * t) / 2, (-3 * t**2 + 2 * t + 1) / 2, t**2 / 2])
        return w, dw
    x = np.stack([t + 1.0, t, t - 1.0, t - 2.0])  # distance to each tap
    ax = np.abs(x)
    inner = ax <= 1.0
    w = np.where(
        inner,
        1.5 * ax**3 - 2.5 * ax**2 + 1.0,
        np.where(ax < 2.0, -0.5 * ax**3 + 2.5 * ax**2 - 4.0 * ax + 2.0, 0.0),
    )
    dw = np.where(
        inner,
        4.5 * x * ax - 5.0 * x,
        np.where(ax < 2.0, -1.5 * x * ax + 5.0 * x - 4.0 * np.sign(x), 0.0),
    )
    return w, dw


def _icgn_shift_estimate(
    moving: Float64Array,
    fixed: Float64Array,
    du: float,
    kind: str,
    tol: float = 1e-11,
    max_iter: int = 60,
) -> tuple[Float64Array, UInt8Array]:
    """Root of ``F(xi) = sum_k D f(k) [g(k + xi) - f(k)]`` (IC-GN's fixed point for a
    translation) with ``g`` the moved signal read through the ``kind`` interpolant."""
    n, length = moving.shape
    q = 2 * math.pi * np.arange(length // 2 + 1) / length
    fm, ff = np.fft.rfft(moving, axis=-1), np.fft.rfft(fixed, axis=-1)
    df = np.fft.irfft(derivative_multiplier(length, kind) * ff, length, axis=-1)
    # the interpolant's coefficients: B-spline prefilter, or the samples themselves
    coef = (
        np.fft.irfft(fm / ((4.0 + 2.0 * np.cos(q)) / 6.0), length, axis=-1)
        if kind == "bspline"
        else moving
    )
    corr = np.fft.irfft(fm * np.conj(ff), length, axis=-1)
    lags = _lag_window(length, du)
    xi = lags[np.argmax(corr[:, lags % length], axis=-1)].astype(np.float64)
    # taps -1..2 of every pixel as contiguous windows of the circularly extended
    # coefficients: window s of row r is coef[r, (s + k) mod L], k = 0..L-1
    windows = np.lib.stride_tricks.sliding_window_view(
        np.concatenate([coef, coef, coef[:, :4]], axis=-1), length, axis=-1
    )
    status = np.ones(n, dtype=np.uint8)
    # Newton on the rows still running only: a few slow trials (near w = 2 min(dp, g), where
    # C vanishes) used to keep the whole (trials, L) arrays in the loop for 60 iterations.
    # Each row's arithmetic is the same as on the full arrays (bit-identical estimates).
    idx = np.arange(n)
    for _ in range(max_iter):
        x = xi[idx]
        i0 = np.floor(x)
        t = x - i0
        w, dw = _taps(t, kind)
        m = idx.size
        val = np.zeros((m, length))
        der = np.zeros((m, length))
        first = (i0.astype(np.intp) - 1) % length
        for j in range(4):
            c = windows[idx, first + j]
            val += w[j][:, None] * c
            der += dw[j][:, None] * c
        d_act = df[idx]
        f_val = np.sum(d_act * (val - fixed[idx]), axis=-1)
        f_der = np.sum(d_act * der, axis=-1)
        with np.errstate(divide="ignore", invalid="ignore"):
            step = np.where(f_der != 0, f_val / f_der, 0.0)
        step = np.clip(np.nan_to_num(step), -1.0, 1.0)
        xi[idx] = x - step
        done = np.abs(step) < tol
        status[idx[done]] = 0
        idx = idx[~done]
        if not idx.size:
            break
    status[np.abs(xi) > du / 2] = 2
    return xi, status


def estimate_shift(
    reference: ArrayLike,
    current: ArrayLike,
    *,
    period: float,
    interpolation: Interpolation = "fourier",
    shifted: Shifted = "blurred",
) -> tuple[Float64Array, UInt8Array]:
    """Displacement of ``current`` relative to ``reference`` (px), minimising the SSD.

    Parameters
    ----------
    reference, current : array_like, shape (n,) or (trials, n)
        Periodic 1-D signals (grey levels) sampled at pixel centres.
    period : float
        Search half-range is ``period / 2`` px around zero (shifts beyond alias).
    interpolation : {"fourier", "linear", "bspline", "keys"}
        How the shifted signal is interpolated (module docstring). ``"analytic"`` needs the
        closed form and is available through :func:`simulate` only.
    shifted : {"blurred", "reference"}
        Which signal is moved: ``current`` (paper eq. 12) or ``reference``.

    Returns
    -------
    u : ndarray, shape (trials,)
        Estimated displacement (px) such that ``current(x) ~ reference(x - u)``.
    status : ndarray of uint8, shape (trials,)
        0 converged; 1 Newton iteration limit; 2 minimiser on the search-bracket edge.
    """
    ref = np.atleast_2d(np.asarray(reference, dtype=np.float64))
    cur = np.atleast_2d(np.asarray(current, dtype=np.float64))
    if ref.shape[-1] != cur.shape[-1] or ref.shape[-1] < 3:
        raise InputError(
            f"reference={describe(ref)}, current={describe(cur)}: the signals must have the "
            "same length (>= 3 samples)"
        )
    if not (np.all(np.isfinite(ref)) and np.all(np.isfinite(cur))):
        raise InputError("reference/current: NaN or infinite samples; remove them first")
    ref, cur = np.broadcast_arrays(ref, cur)
    period = check_positive(period, "period")
    check_choice(interpolation, "interpolation", ("fourier", "linear", *_ICGN_KINDS))
    check_choice(shifted, "shifted", ("blurred", "reference"))

    def fn(m: Float64Array, f: Float64Array, du: float) -> tuple[Float64Array, UInt8Array]:
        if interpolation in _ICGN_KINDS:
            return _icgn_shift_estimate(m, f, du, interpolation)
        if interpolation == "fourier":
            return _fourier_shift_estimate(m, f, du)
        return _linear_shift_estimate(m, f, du)

    if shifted == "blurred":
        u, st = fn(np.ascontiguousarray(cur), np.ascontiguousarray(ref), period)
        return u, st
    u, st = fn(np.ascontiguousarray(ref), np.ascontiguousarray(cur), period)
    return -u, st


# --------------------------------------------------------------------------------------
# Monte Carlo driver
# --------------------------------------------------------------------------------------
def _std_ci(x: Float64Array) -> tuple[float, float, float]:
    """Sample std and a 95% CI valid for non-Gaussian samples (delta method with the
    fourth central moment: ``var(s) ~ (m4 - s^4) / (4 n s^2)``)."""
    n = x.size
    s = float(np.std(x, ddof=1))
    if n < 4 or s == 0:
        return s, s, s
    m4 = float(np.mean((x - x.mean()) ** 4))
    se = math.sqrt(max(m4 - s**4, 0.0) / (4 * n * s**2))
    return s, max(s - _Z95 * se, 0.0), s + _Z95 * se


def _pixel_linearised(
    train: PulseTrain,
    w: float,
    w_ref: float,
    sigma: float,
    length: int,
    displacement: float,
    kind: str = "fourier",
) -> tuple[float, float, float, float]:
    """Pixel-level ``sigma sqrt(S_o + S_b) / |C|`` with the correlator's own derivative D
    (``S = sum (D p)^2``, ``C = sum D p_o D p_b``) and the second-order noise term
    ``sigma^4 ||D||_F^2``. It holds for every correlator whose D is antisymmetric and whose
    interpolant reproduces the samples and has derivative D at the pixels (spectral, cubic
    B-spline with its own derivative, Keys with central differences)."""
    po = train.sample(length, w_ref)
    pb = train.sample(length, w, shift=displacement)
    mult = derivative_multiplier(length, kind if kind in _ICGN_KINDS else "fourier")
    do = np.fft.irfft(mult * np.fft.rfft(po), length)
    db = np.fft.irfft(mult * np.fft.rfft(pb), length)
    s_o, s_b, c = float(np.sum(do**2)), float(np.sum(db**2)), float(np.sum(do * db))
    # ||D||_F^2 of the circulant operator: the sum of |multiplier|^2 over all L bins
    full = np.abs(mult) ** 2
    dnorm = float(2 * np.sum(full[1:]) - (full[-1] if length % 2 == 0 else 0.0))
    var = sigma**2 * (s_o + s_b) + sigma**4 * dnorm
    pred = math.sqrt(var) / abs(c) if abs(c) > 1e-12 * max(s_o, 1e-300) else math.inf
    return s_o, s_b, c, pred


def simulate(
    train: PulseTrain = PAPER_TRAIN,
    *,
    widths: ArrayLike = PAPER_WIDTHS,
    sigma: float = 0.05,
    n_periods: int = 10,
    trials: int = 10_000,
    seed: SeedLike = 1,
    displacement: float = 0.0,
    interpolation: Interpolation = "fourier",
    shifted: Shifted = "blurred",
    w_ref: float = 1.0,
    outlier_threshold: float = 1.0,
    keep_samples: bool = False,
) -> xr.Dataset:
    """Monte Carlo of the displacement uncertainty u_e(w) of the pulse correlation.

    Parameters
    ----------
    train : PulseTrain
        Signal (default the paper's a = 1, dp = 6, du = 22).
    widths : array_like of float
        Blur widths w = 1 + W, px (default 1..27).
    sigma : float
        Noise std (grey levels) added independently to both signals (>= 0).
    n_periods : int
        Periods in the correlated signal (the paper's subset size N); length ``N du`` px.
    trials : int
        Noise realisations per width.
    seed : int, SeedSequence or None
        Seed; each width draws from its own child stream, so results do not depend on the
        order in which widths are run.
    displacement : float
        Imposed displacement of the current signal, px (paper: 0).
    interpolation : {"fourier", "linear", "analytic"}
    shifted : {"blurred", "reference"}
    w_ref : float
        Box width of the reference, px (1 = pixel-integrated, sharp).
    outlier_threshold : float
        An estimate with ``|u - displacement|`` above this (px) counts as a gross error.
    keep_samples : bool
        Also return every estimate (variable ``u``, dims (w, trial)).

    Returns
    -------
    xarray.Dataset
        Dimension ``w`` (px). Variables (px unless stated): ``u_e`` (std of the estimates),
        ``u_e_ci_low``/``u_e_ci_high`` (95%), ``mean``, ``mean_ci_low``/``mean_ci_high``,
        ``bias`` (mean - displacement), ``median``, ``u_e_robust`` (1.4826 MAD),
        ``outlier_fraction``, ``converged_fraction``, ``regime`` (str), ``m`` (px),
        ``sssig_blur``, ``sssig_ref``, ``cross_gradient`` (closed forms,
        (grey levels/px)^2), ``u_first_principles``, ``u_interpolated_noise``,
        ``u_paper_linear`` (predictions), ``u_pixel_linearised`` (spectral, pixel-level
        version of the interpolated-noise prediction, meaningful for ``"fourier"``).
        Attributes record every input, the seed and the package version.
    """
    wa = np.atleast_1d(np.asarray(widths, dtype=np.float64))
    if wa.ndim != 1 or wa.size == 0 or not np.all(np.isfinite(wa)) or np.any(wa <= 0):
        raise InputError(f"widths={describe(widths)}: expected a 1-D list of widths > 0 px")
    sigma = check_finite_number(sigma, "sigma")
    if sigma < 0:
        raise InputError(f"sigma={sigma!r}: the noise std must be >= 0 grey levels")
    if not isinstance(n_periods, int | np.integer) or n_periods < 1:
        raise InputError(f"n_periods={describe(n_periods)}: expected an int >= 1 (e.g. 10)")
    if not isinstance(trials, int | np.integer) or trials < 2:
        raise InputError(f"trials={describe(trials)}: expected an int >= 2 (default 10000)")
    displacement = check_finite_number(displacement, "displacement")
    check_choice(interpolation, "interpolation", ("fourier", "linear", "analytic", *_ICGN_KINDS))
    check_choice(shifted, "shifted", ("blurred", "reference"))
    w_ref = check_positive(w_ref, "w_ref")
    outlier_threshold = check_positive(outlier_threshold, "outlier_threshold")
    length = as_whole(
        train.du * n_periods,
        f"du={train.du!r}, n_periods={n_periods}: the signal must hold a whole number of "
        "pixels (du * n_periods integer) to be periodic",
    )
    if isinstance(seed, np.random.Generator):
        raise InputError(
            "seed=Generator: pass an int or SeedSequence (one child stream per width keeps "
            "results independent of the order of widths)"
        )
    ss = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    children = ss.spawn(wa.size)

    from .._version import __version__

    ref_clean = train.sample(length, w_ref)
    names = (
        "u_e",
        "u_e_ci_low",
        "u_e_ci_high",
        "mean",
        "mean_ci_low",
        "mean_ci_high",
        "median",
        "u_e_robust",
        "outlier_fraction",
        "converged_fraction",
    )
    stats = {k: np.empty(wa.size) for k in names}
    pix = np.empty((4, wa.size))
    samples = np.empty((wa.size, trials)) if keep_samples else None
    for i, w in enumerate(wa):
        rng = np.random.default_rng(children[i])
        cur_clean = train.sample(length, float(w), shift=displacement)
        if interpolation == "fourier":
            # noise drawn as spectra (same distribution as real-space white noise)
            spec_o = np.fft.rfft(ref_clean) + _white_noise_spectrum(rng, trials, length, sigma)
            spec_b = np.fft.rfft(cur_clean) + _white_noise_spectrum(rng, trials, length, sigma)
            if shifted == "blurred":
                u, st = _fourier_estimate_from_spectra(spec_b, spec_o, length, train.du)
            else:
                u, st = _fourier_estimate_from_spectra(spec_o, spec_b, length, train.du)
                u = -u
            del spec_o, spec_b
        else:
            tau_o = sigma * rng.standard_normal((trials, length))
            tau_b = sigma * rng.standard_normal((trials, length))
        if interpolation == "analytic":
            if shifted == "blurred":
                u, st = _analytic_shift_estimate(
                    train, float(w), displacement, ref_clean + tau_o - tau_b
                )
            else:
                u, st = _analytic_shift_estimate(train, w_ref, 0.0, cur_clean + tau_b - tau_o)
                u = -u
        elif interpolation in ("linear", *_ICGN_KINDS):
            u, st = estimate_shift(
                ref_clean + tau_o,
                cur_clean + tau_b,
                period=train.du,
                interpolation=interpolation,
                shifted=shifted,
            )
        if samples is not None:
            samples[i] = u
        err = u - displacement
        s, lo, hi = _std_ci(u)
        mean = float(u.mean())
        half = _Z95 * s / math.sqrt(trials)
        med = float(np.median(u))
        for k, v in zip(
            names,
            (
                s,
                lo,
                hi,
                mean,
                mean - half,
                mean + half,
                med,
                1.482602218505602 * float(np.median(np.abs(u - med))),
                float(np.mean(np.abs(err) > outlier_threshold)),
                float(np.mean(st == 0)),
            ),
            strict=True,
        ):
            stats[k][i] = v
        pix[:, i] = _pixel_linearised(
            train, float(w), w_ref, max(sigma, 0.0), length, displacement, interpolation
        )

    s_o, s_b, cross = gradient_sums(train, wa, w_ref=w_ref, n_periods=n_periods)
    sig = max(sigma, 1e-300)
    data_vars: dict[str, tuple] = {k: ("w", v) for k, v in stats.items()}
    data_vars["bias"] = ("w", stats["mean"] - displacement)
    data_vars.update(
        {
            "regime": ("w", np.array([regime(train, float(w)) for w in wa])),
            "m": ("w", edge_length(train, wa)),
            "sssig_blur": ("w", s_b),
            "sssig_ref": ("w", s_o),
            "cross_gradient": ("w", cross),
            "u_first_principles": (
                "w",
                predict_first_principles(train, wa, sigma=sig, n_periods=n_periods),
            ),
            "u_interpolated_noise": (
                "w",
                predict_interpolated_noise(train, wa, sigma=sig, n_periods=n_periods, w_ref=w_ref),
            ),
            "u_paper_linear": (
                "w",
                predict_paper_linear(train, wa, sigma=sig, n_periods=n_periods),
            ),
            "u_pixel_linearised": ("w", pix[3]),  # with this correlator's own D
            "sssig_blur_spectral": ("w", pix[1]),
            "sssig_ref_spectral": ("w", pix[0]),
            "cross_gradient_spectral": ("w", pix[2]),
        }
    )
    if samples is not None:
        data_vars["u"] = (("w", "trial"), samples)
    ds = xr.Dataset(
        data_vars, coords={"w": ("w", wa, {"units": "px", "long_name": "box width w = 1 + W"})}
    )
    for name in ds.data_vars:
        if str(name).startswith(("u", "mean", "median", "bias", "m")):
            ds[name].attrs["units"] = "px"
    ds.attrs.update(
        {
            "title": "1-D periodic-pulse Monte Carlo (Lavatelli & Zappa 2017, Section V-B)",
            "a": train.a,
            "dp": train.dp,
            "du": train.du,
            "x0": train.x0,
            "sigma": sigma,
            "n_periods": int(n_periods),
            "trials": int(trials),
            "seed": "None"
            if seed is None
            else str(seed if not isinstance(seed, np.random.SeedSequence) else seed.entropy),
            "displacement": displacement,
            "interpolation": interpolation,
            "shifted": shifted,
            "w_ref": w_ref,
            "outlier_threshold": outlier_threshold,
            "dicblur_version": __version__,
        }
    )
    return ds
