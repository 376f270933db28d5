"""SSD correlation of the sharp and the blurred pulse train (paper Section V-A, eq. 12-16).

``chi2(xi, w) = sum over N periods of [p_b(x - xi, w) - p_o(x)]^2`` (paper eq. 12), with
``p_o`` the reference (sharp: ``w_ref = 0`` in the continuous analysis, ``w_ref = 1`` for a
pixel-integrated image) and ``p_b`` the blurred signal.

Regime (a), continuous, ``w_ref = 0`` (our derivation; the seed's eq. 13 is garbled): each
edge contributes ``a^2 (w/12 + xi^2/w)`` for ``|xi| <= w/2`` and ``a^2 (|xi| - w/6)``
beyond, so per period ``chi2 = a^2 (w/6 + 2 xi^2 / w)`` near the minimum.

Uncertainty predictions (std of the minimiser, px), all for noise of std ``sigma`` in both
signals, ``S_b = SSSIG`` of the blurred signal, ``S_o`` of the reference and
``C = sum p_b' p_o'`` their cross-gradient (closed forms in :func:`gradient_sums`):

- first-principles (match score with the blurred SSSIG, noise-free shifted model):
  ``sqrt(2 sigma^2 / S_b)``, ``= sigma sqrt(w / N) / a`` in regime (a);
- interpolated-noise linearisation (the shifted signal carries its noise):
  ``sqrt(sigma^2 (S_o + S_b)) / |C|``, ``= sigma sqrt(w (w + 1) / (2 N)) / a`` in
  regime (a) with ``w_ref = 1``: it grows linearly for ``w >> 1``;
- the paper's linear reading of its eq. 16, anchored at w = 1 on the match score:
  ``sigma w / (a sqrt(N))``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from scipy import optimize

from ..arrays import Float64Array
from ..checks import check_positive
from .signal import PulseTrain, as_widths, check_width, edge_length

__all__ = [
    "chi2_continuous",
    "chi2_regime_a",
    "chi2_sampled",
    "gradient_sums",
    "min_chi2",
    "predict_first_principles",
    "predict_interpolated_noise",
    "predict_paper_linear",
]


def chi2_regime_a(
    xi: ArrayLike, w: ArrayLike, *, a: float = 1.0, n_periods: float = 1.0
) -> Float64Array:
    """Regime-(a) analytic SSD, continuous, sharp reference (``w_ref = 0``).

    ``N a^2 (w/6 + 2 xi^2 / w)`` for ``|xi| <= w/2`` and ``2 N a^2 (|xi| - w/6)`` beyond
    (valid while the shifted ramps stay inside their pulse and gap: ``w/2 + |xi| <=
    min(dp, g) - w/2``). Units: grey levels^2 x px.
    """
    x = np.abs(np.asarray(xi, dtype=np.float64))
    wa = as_widths(w)
    inner = wa / 12 + x**2 / wa
    outer = x - wa / 6
    return 2 * n_periods * a**2 * np.where(x <= wa / 2, inner, outer)


def _piecewise_integral(f, breaks: Float64Array, lo: float, hi: float) -> float:
    """Exact integral over [lo, hi] of ``f``, polynomial of degree <= 3 between ``breaks``.

    Two-point Gauss-Legendre on each piece: exact for cubics and never evaluates ``f`` at a
    kink or jump (the sharp reference jumps at its edges).
    """
    pts = np.unique(np.concatenate([[lo, hi], breaks[(breaks > lo) & (breaks < hi)]]))
    a, b = pts[:-1], pts[1:]
    mid, half = (a + b) / 2, (b - a) / 2
    r = half / np.sqrt(3.0)
    return float(np.sum(half * (f(mid - r) + f(mid + r))))


def chi2_continuous(
    train: PulseTrain, xi: ArrayLike, w: float, *, w_ref: float = 0.0, n_periods: float = 1.0
) -> Float64Array:
    """SSD ``integral of [p_b(x - xi, w) - p_b(x, w_ref)]^2`` over ``n_periods`` periods.

    Exact for continuous x: the integrand is piecewise quadratic, integrated by the two-point
    Gauss-Legendre rule between its kinks and jumps. ``w_ref = 0`` is the paper's sharp
    reference.
    """
    w = check_width(w)
    w_ref = check_width(w_ref, "w_ref")
    n_periods = check_positive(n_periods, "n_periods")
    xis = np.atleast_1d(np.asarray(xi, dtype=np.float64))
    out = np.empty(xis.shape)
    du = train.du
    for i, s in enumerate(xis):
        kb = np.mod(train.breakpoints(w) + s, du)
        kr = train.breakpoints(w_ref)
        breaks = np.concatenate([kb, kr, kb + du, kr + du])

        def f(x, s=s):
            return (train.blurred(x - s, w) - train.blurred(x, w_ref)) ** 2

        out[i] = n_periods * _piecewise_integral(f, breaks, 0.0, du)
    return out.reshape(np.shape(xi)) if np.ndim(xi) else out


def chi2_sampled(
    train: PulseTrain, xi: ArrayLike, w: float, *, w_ref: float = 1.0, n_periods: int = 1
) -> Float64Array:
    """SSD summed over pixel centres ``x = 0 .. N du - 1`` (the pixel-level version)."""
    n = round(train.du * n_periods)
    x = np.arange(n, dtype=np.float64)
    ref = train.blurred(x, w_ref)
    xis = np.atleast_1d(np.asarray(xi, dtype=np.float64))
    out = np.array([np.sum((train.blurred(x - s, w) - ref) ** 2) for s in xis])
    return out.reshape(np.shape(xi)) if np.ndim(xi) else out


def min_chi2(
    train: PulseTrain, w: ArrayLike, *, w_ref: float = 0.0, n_periods: float = 1.0
) -> tuple[Float64Array, Float64Array]:
    """Minimum over xi (|xi| <= du/2) of the continuous SSD, and its minimiser (paper Fig. 5).

    A grid search (0.1 px) is refined by bounded Brent minimisation.

    Returns
    -------
    value, xi_min : ndarray, shape of ``w``
    """
    wa = np.atleast_1d(as_widths(w))
    vals = np.empty(wa.shape)
    locs = np.empty(wa.shape)
    grid = np.arange(-train.du / 2, train.du / 2 + 1e-9, 0.1)
    for i, wi in enumerate(wa):
        c = chi2_continuous(train, grid, float(wi), w_ref=w_ref, n_periods=n_periods)
        j = int(np.argmin(c))
        lo, hi = grid[max(j - 1, 0)], grid[min(j + 1, grid.size - 1)]
        res = optimize.minimize_scalar(
            lambda s, wi=wi: float(
                chi2_continuous(train, [s], float(wi), w_ref=w_ref, n_periods=n_periods)[0]
            ),
            bounds=(lo, hi),
            method="bounded",
            options={"xatol": 1e-10},
        )
        best = min((float(res.fun), float(res.x)), (float(c[j]), float(grid[j])))
        vals[i], locs[i] = best
    return vals, locs


def gradient_sums(
    train: PulseTrain, w: ArrayLike, *, w_ref: float = 1.0, n_periods: float = 1.0
) -> tuple[Float64Array, Float64Array, Float64Array]:
    """Closed-form ``S_o``, ``S_b`` and the cross-gradient ``C`` over N periods (continuous).

    With ``R(s) = a^2 (dp - m(s))`` the pulse autocorrelation per period,
    ``S_b = 2 a^2 m(w) / w^2`` and
    ``C = integral p_b'(x, w) p_b'(x, w_ref) dx = 2 a^2 [m((w + w_ref)/2) - m(|w - w_ref|/2)]
    / (w w_ref)`` (per period; ``w_ref > 0``). ``C`` is the curvature of the noise-free
    cross-correlation at zero shift: it vanishes once the blurred ramps no longer cover the
    reference edges (``w >= 2 min(dp, g) + w_ref``), where the SSD minimum turns flat.

    Returns
    -------
    s_ref, s_blur, cross : ndarray, shape of ``w``, (grey levels / px)^2
    """
    wa = as_widths(w)
    w_ref = check_positive(w_ref, "w_ref")
    a2 = train.a**2
    s_b = 2 * n_periods * a2 * edge_length(train, wa) / wa**2
    s_o = 2 * n_periods * a2 * edge_length(train, np.asarray(w_ref)) / w_ref**2
    cross = (2 * n_periods * a2 / (wa * w_ref)) * (
        edge_length(train, (wa + w_ref) / 2) - edge_length(train, np.abs(wa - w_ref) / 2)
    )
    return np.broadcast_to(s_o, wa.shape).astype(float), s_b, cross


def predict_first_principles(
    train: PulseTrain, w: ArrayLike, *, sigma: float, n_periods: float
) -> Float64Array:
    """``sqrt(2 sigma^2 / S_b)`` px: match score with the blurred SSSIG (brief section 6)."""
    sigma = check_positive(sigma, "sigma")
    _, s_b, _ = gradient_sums(train, w, n_periods=n_periods)
    with np.errstate(divide="ignore"):
        return np.where(s_b > 0, np.sqrt(2 * sigma**2 / np.where(s_b > 0, s_b, 1)), np.inf)


def predict_interpolated_noise(
    train: PulseTrain, w: ArrayLike, *, sigma: float, n_periods: float, w_ref: float = 1.0
) -> Float64Array:
    """``sigma sqrt(S_o + S_b) / |C|`` px: linearised minimiser when the shifted signal is
    interpolated together with its noise (exact Fourier shift). ``inf`` where ``C = 0``."""
    sigma = check_positive(sigma, "sigma")
    s_o, s_b, c = gradient_sums(train, w, w_ref=w_ref, n_periods=n_periods)
    ok = np.abs(c) > 1e-12 * s_o
    return np.where(ok, sigma * np.sqrt(s_o + s_b) / np.where(ok, np.abs(c), 1), np.inf)


def predict_paper_linear(
    train: PulseTrain, w: ArrayLike, *, sigma: float, n_periods: float
) -> Float64Array:
    """The paper's linear reading of eq. 16, ``u_e ~ w``, anchored at w = 1 on the match
    score ``sigma / (a sqrt(N))``: ``sigma w / (a sqrt(N))`` px."""
    sigma = check_positive(sigma, "sigma")
    n_periods = check_positive(n_periods, "n_periods")
    wa = as_widths(w)
    return sigma * wa / (train.a * np.sqrt(n_periods))
