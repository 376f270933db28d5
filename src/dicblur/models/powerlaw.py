"""Power-law model of the paper (eq. 17) with an explicit, scale-consistent noise term.

``u_e = eta / SSSIG**alpha`` (eq. 17) is a straight line in log-log. The paper's ``eta``
mixes the noise level and the blur sensitivity, and at ``alpha != 1/2`` the law is not
invariant to scaling the image intensity (ZNSSD DIC is). We therefore write it as

    u_e = eta_n (SSSIG / sigma**2)**(-alpha),   i.e.  eta = eta_n sigma**(2 alpha),

which depends on the image only through the scale-free ratio ``SSSIG / sigma**2``. With
one noise level this is the paper's law (``eta`` at that level; a prediction at another
noise level is refused: the law's noise dependence was never measured). With several noise
levels the exponent is fitted: ``u_e ∝ (sigma / sigma_ref)**kappa SSSIG**(-alpha)`` with
``sigma_ref`` the geometric mean of the levels; scale consistency is the testable statement
``kappa = 2 alpha``.

Parameters with plain units
---------------------------
``eta`` has the units px (GL/px)**(2 alpha), which depend on the fitted ``alpha``; its value
runs over decades (1e2..1e26 on the study's patterns) and its Gaussian interval is
degenerate (``log eta`` and ``alpha`` are almost perfectly correlated because ``log SSSIG``
is far from zero). The fit is therefore parameterised around a reference SSSIG:

    u_e = u_ref (SSSIG / SSSIG_ref)**(-alpha),      eta = u_ref SSSIG_ref**alpha,

``u_ref`` in px (the power law's u_e at ``SSSIG_ref``; :func:`dicblur.fit_blur_model` sets
``SSSIG_ref = SSSIG_0`` of the eq. 18 fit, so ``u_ref`` is its static u_e(0)), ``alpha``
dimensionless. ``eta`` is still available (``FitResult.extra["eta"]``,
``BlurUncertaintyModel.eta``), derived.

Fit range
---------
The law holds in the edge-driven regime (paper Section V, regime (a): edges soften, the
contrast is kept); its error grows with the contrast ratio static / blurred (paper Fig. 8).
:func:`edge_driven_range` picks the fit range automatically:

1. with contrast data: the blur levels from the smallest W up to (not including) the first
   W whose contrast ratio ``C_ref / C(W)`` exceeds ``1 + tolerance`` (default 5 % loss);
2. without contrast data: the W with ``beta W**2 <= 1`` from a fit of eq. 18 (SSSIG has at
   most halved), the point where eq. 18 leaves its edge-softening start;
3. at least ``min_points`` blur levels are always kept (the smallest ones), with a warning.

``fit_range=(W_lo, W_hi)`` overrides the rule.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
from numpy.typing import ArrayLike

from ..arrays import Float64Array, IndexArray
from ..checks import as_blur, as_positive, as_vector
from ..errors import InputError
from ._result import CIOptions, FitResult, make_result

__all__ = ["edge_driven_range", "fit_power_law", "power_law"]


def power_law(sssig: ArrayLike, eta: float, alpha: float) -> Float64Array:
    """``eta / SSSIG**alpha`` (eq. 17), px."""
    return eta * np.asarray(sssig, dtype=np.float64) ** (-alpha)


def edge_driven_range(
    blur: ArrayLike,
    *,
    contrast_ratio: ArrayLike | None = None,
    sssig: ArrayLike | None = None,
    tolerance: float = 0.05,
    min_points: int = 3,
) -> tuple[float, float]:
    """Automatic fit range ``(W_lo, W_hi)`` (px) of the power law (module docstring rule).

    Parameters
    ----------
    blur : array_like, shape (n,)
        Blur lengths W (px); repeated W (several noise levels) are grouped.
    contrast_ratio : array_like, shape (n,), optional
        Static contrast / blurred contrast (>= 1 in theory) of each point.
    sssig : array_like, shape (n,), optional
        SSSIG of each point, used by rule 2 when no contrast ratio is given.
    tolerance : float
        Allowed relative contrast loss of the edge-driven regime.
    min_points : int
        Minimum number of distinct blur levels kept.
    """
    w = as_blur(blur, "blur", increasing=False)
    levels = np.unique(w)
    if not (isinstance(tolerance, float | int) and tolerance > 0):
        raise InputError(f"range_tolerance={tolerance!r}: must be > 0, e.g. 0.05 (5 % loss)")
    if levels.size < min_points:
        raise InputError(
            f"blur: {levels.size} distinct blur level(s); the power law needs at least {min_points}"
        )
    if contrast_ratio is not None:
        r = as_positive(contrast_ratio, "contrast_ratio", w.size)
        per_level = np.array([r[w == lv].mean() for lv in levels])
        ok = per_level <= 1.0 + tolerance
    elif sssig is not None:
        from .decay import fit_sssig_decay

        s = as_positive(sssig, "sssig", w.size)
        beta = fit_sssig_decay(w, s)["beta"]
        ok = beta * levels**2 <= 1.0
    else:
        return float(levels[0]), float(levels[-1])
    n_ok = int(np.argmin(ok)) if not ok.all() else levels.size
    if n_ok < min_points:
        warnings.warn(
            f"edge-driven range: only {n_ok} blur level(s) pass the rule; using the "
            f"{min_points} smallest (W <= {levels[min_points - 1]:g} px). Pass fit_range to "
            "choose it yourself.",
            stacklevel=2,
        )
        n_ok = min_points
    return float(levels[0]), float(levels[n_ok - 1])


def fit_power_law(
    sssig: ArrayLike,
    u_e: ArrayLike,
    *,
    noise_sigma: ArrayLike | None = None,
    blur: ArrayLike | None = None,
    sssig_ref: float | None = None,
    fit_noise_exponent: bool | None = None,
    confidence: float = 0.95,
    ci: str = "covariance",
    n_boot: int = 500,
    seed: int | np.random.Generator | None = None,
) -> FitResult:
    """Fit ``log u_e = log u_ref - alpha log(SSSIG / SSSIG_ref) [+ kappa log(sigma /
    sigma_ref)]`` (eq. 17 around a reference SSSIG; module docstring).

    Ordinary least squares in log-log space (so CIs from the covariance are exact under
    Gaussian log residuals). Pass only the points of the fit range.

    Parameters
    ----------
    sssig, u_e : array_like, shape (n,)
        SSSIG ((GL/px)**2) and measured uncertainty (px), > 0.
    noise_sigma : float or array_like, shape (n,), optional
        Noise std (GL) of each point. One level: stored as the reference (predictions at
        other levels are refused by the model). Several: ``kappa`` fitted unless
        ``fit_noise_exponent=False`` (then ``kappa = 2 alpha``).
    blur : array_like, shape (n,), optional
        W of each point (px), recorded as the fit range.
    sssig_ref : float, optional
        Reference SSSIG ((GL/px)**2) of ``u_ref``; default the largest SSSIG of the data
        (:func:`dicblur.fit_blur_model` passes ``SSSIG_0`` of the eq. 18 fit).

    Returns
    -------
    FitResult
        ``names = ("u_ref", "alpha"[, "kappa"])`` (px, 1, 1); ``extra`` holds
        ``sssig_ref``, ``sigma_ref`` (GL or None) and the derived paper ``eta``.
    """
    s = as_positive(sssig, "sssig", len(np.atleast_1d(np.asarray(sssig))))
    u = as_positive(u_e, "u_e", s.size)
    w = np.zeros(s.size) if blur is None else as_vector(blur, "blur", s.size)
    ci_options = CIOptions(confidence, ci, n_boot, seed)
    s_ref = float(s.max()) if sssig_ref is None else float(sssig_ref)
    if not (math.isfinite(s_ref) and s_ref > 0):
        raise InputError(f"sssig_ref={sssig_ref!r}: must be a finite SSSIG > 0 ((GL/px)^2)")
    sig: Float64Array | None = None
    if noise_sigma is not None:
        sig = np.broadcast_to(np.asarray(noise_sigma, dtype=np.float64), s.shape).copy()
        sig = as_positive(sig, "noise_sigma", s.size)
    levels = np.unique(sig) if sig is not None else np.array([])
    multi = levels.size >= 2
    fit_kappa = multi if fit_noise_exponent is None else bool(fit_noise_exponent and multi)
    sigma_ref = (
        float(np.exp(np.mean(np.log(levels))))
        if multi
        else (float(levels[0]) if levels.size else None)
    )
    x = np.log(s / s_ref)
    y = np.log(u)
    z = np.log(sig / sigma_ref) if (sig is not None and sigma_ref is not None) else np.zeros_like(x)
    names: tuple[str, ...] = ("u_ref", "alpha", "kappa") if fit_kappa else ("u_ref", "alpha")

    def fit_once(
        idx: IndexArray, refit_from: Float64Array | None = None
    ) -> tuple[Float64Array, ...]:
        # refit_from (a bootstrap refit) unused: a linear least-squares fit
        cols = [np.ones(idx.size), -x[idx]] + ([z[idx]] if fit_kappa else [])
        a = np.stack(cols, axis=1)
        if not fit_kappa and multi:
            # kappa fixed at 2 alpha: regress on log(SSSIG / sigma^2) relative to sigma_ref
            a[:, 1] = -(x[idx] - 2.0 * z[idx])
        coef, *_ = np.linalg.lstsq(a, y[idx], rcond=None)
        u_ref = math.exp(coef[0])
        vals = np.array([u_ref, *coef[1:]])
        res = a @ coef - y[idx]
        jac = a.copy()
        jac[:, 0] = 1.0 / u_ref
        return vals, jac, res

    extra = {
        "sigma_ref": sigma_ref,
        "sssig_ref": s_ref,
        "noise_levels": [float(v) for v in levels],
        "kappa_rule": "fitted" if fit_kappa else "2*alpha",
    }
    res = make_result(
        model="power_law",
        names=names,
        fit_once=fit_once,
        n=s.size,
        data_space=y,
        blur=w,
        fixed={},
        ci_options=ci_options,
        extra=extra,
        log_params=("u_ref", "a", "k"),
    )
    eta = res["u_ref"] * s_ref ** res["alpha"]
    from dataclasses import replace

    return replace(res, extra={**res.extra, "eta": float(eta)})
