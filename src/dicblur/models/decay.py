"""SSSIG decay under blur (paper eq. 18) and the combined power-law models (eqs. 19-22).

- ``SSSIG(W) = SSSIG_0 / (beta W**2 + 1)`` (eq. 18), ``beta`` the pattern degradation
  factor (1/px**2), fitted by nonlinear least squares on SSSIG itself; R^2 is reported in
  that linear space, as the paper does (its Fig. 9).
- ``u_e(W) = eta (SSSIG_0 / (beta W**2 + 1))**(-alpha)`` (eq. 19); with Pan's
  ``SSSIG_0 ~= N**2 MIG_0**2`` (eq. 20).
- ``MBRF = 2 alpha beta`` (eq. 22, the normalised curvature ``u_e''(0) / u_e(0)``), and the
  second-order expansion ``u_e(W) ~= u_e(0) (1 + alpha beta W**2)``: the paper's eq. 21
  writes ``1 + MBRF W**2``, which drops the 1/2 of the Taylor term (paper-brief s. 7).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from scipy import optimize

from ..arrays import Float64Array, IndexArray
from ..checks import as_blur, as_positive
from ..errors import FitError
from ._result import CIOptions, FitResult, make_result

__all__ = [
    "combined_model",
    "combined_pan_model",
    "fit_sssig_decay",
    "mbrf",
    "sssig_decay",
    "taylor_model",
]


def sssig_decay(blur: ArrayLike, sssig0: float, beta: float) -> Float64Array:
    """``SSSIG_0 / (beta W**2 + 1)`` (eq. 18); ``blur`` W in px, ``beta`` in 1/px**2."""
    w = np.asarray(blur, dtype=np.float64)
    return sssig0 / (beta * w * w + 1.0)


def combined_model(
    blur: ArrayLike, eta: float, alpha: float, sssig0: float, beta: float
) -> Float64Array:
    """``u_e(W) = eta (SSSIG_0 / (beta W**2 + 1))**(-alpha)`` (eq. 19), px."""
    return eta * sssig_decay(blur, sssig0, beta) ** (-alpha)


def combined_pan_model(
    blur: ArrayLike, eta: float, alpha: float, beta: float, *, mig0: float, subset: int
) -> Float64Array:
    """Eq. 20: eq. 19 with Pan's ``SSSIG_0 ~= N**2 MIG_0**2`` (``subset`` N px, MIG GL/px)."""
    return combined_model(blur, eta, alpha, float(subset) ** 2 * mig0**2, beta)


def mbrf(alpha: float, beta: float) -> float:
    """Motion blur rejection factor ``2 alpha beta`` (1/px**2), as the paper defines it."""
    return 2.0 * alpha * beta


def taylor_model(blur: ArrayLike, u0: float, alpha: float, beta: float) -> Float64Array:
    """Second-order expansion of eq. 19: ``u_e(0) (1 + alpha beta W**2)`` (= 1 + MBRF W^2/2)."""
    w = np.asarray(blur, dtype=np.float64)
    return u0 * (1.0 + alpha * beta * w * w)


def fit_sssig_decay(
    blur: ArrayLike,
    sssig: ArrayLike,
    *,
    confidence: float = 0.95,
    ci: str = "covariance",
    n_boot: int = 500,
    seed: int | np.random.Generator | None = None,
) -> FitResult:
    """Fit eq. 18 to SSSIG(W) by nonlinear least squares (``SSSIG_0``, ``beta >= 0``).

    Parameters
    ----------
    blur : array_like, shape (n,)
        Blur lengths W (px), >= 0.
    sssig : array_like, shape (n,)
        Mean subset SSSIG along the motion of the blurred images, (GL/px)**2.

    Returns
    -------
    FitResult
        ``names = ("sssig0", "beta")``; ``r2`` on SSSIG (linear), as in the paper's Fig. 9.
    """
    w = as_blur(blur, "blur", increasing=False)
    s = as_positive(sssig, "sssig", len(w))
    ci_options = CIOptions(confidence, ci, n_boot, seed)

    def fit_once(
        idx: IndexArray, refit_from: Float64Array | None = None
    ) -> tuple[Float64Array, ...]:
        # refit_from (a bootstrap refit) unused: a smooth, bounded fit from its linear start
        wi, si = w[idx], s[idx]
        # Start from the linear form 1/S = 1/S0 + (beta/S0) W^2.
        a, b = np.polyfit(wi * wi, 1.0 / si, 1) if np.ptp(wi) > 0 else (0.0, 1.0 / si.mean())
        s0 = 1.0 / b if b > 0 else float(si.max())
        beta0 = max(a * s0, 0.0)
        scale = float(si.max())

        def resid(p: Float64Array) -> Float64Array:
            return (sssig_decay(wi, p[0] * scale, p[1]) - si) / scale

        r = optimize.least_squares(
            resid,
            [s0 / scale, beta0],
            bounds=([0, 0], [np.inf, np.inf]),
            method="trf",
            xtol=1e-14,
            ftol=1e-14,
            gtol=1e-14,
        )
        if not r.success:  # pragma: no cover - the problem is smooth and bounded
            raise FitError(f"sssig_decay: the least-squares fit failed ({r.message})")
        vals = np.array([r.x[0] * scale, r.x[1]])
        jac = r.jac * np.array([1.0 / scale, 1.0]) * scale
        return vals, jac, r.fun * scale

    return make_result(
        model="sssig_decay",
        names=("sssig0", "beta"),
        fit_once=fit_once,
        n=len(w),
        data_space=s,
        blur=w,
        fixed={},
        ci_options=ci_options,
    )
