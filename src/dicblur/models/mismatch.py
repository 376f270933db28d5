"""Noise + blur-mismatch model (beyond the paper; paper-brief s. 10, docs/models.md).

With a sharp reference and a blurred current image the error of a subset has two parts:
the noise term of the match-score model evaluated at the blurred SSSIG, and a
deterministic, pattern-dependent shift of the SSD minimum that does not depend on noise:

    u_e(W, sigma)**2 = a (SSSIG(W) / sigma**2)**(-gamma) [(1 + d W**2)**2 + e W**4]
                       + u_0**2 + (b W)**2 + (c W**2 + c4 W**4)**2

Theory gives ``a = 2``, ``gamma = 1`` (eq. 2) and ``c`` from the static image
(:func:`~dicblur.models.blur_sensitivity`); ``c4`` is the next term of the expansion,
fitted only when the data ask for it (AIC). ``u_0`` (``floor``) is a noise-independent
floor of the matcher: the sub-pixel interpolation bias at the fractional shift of the
blurred image (W/2 for a linear trajectory; Schreier, Braasch & Sutton, Opt. Eng. 39(11), 2000,
doi:10.1117/1.1314593), about 1e-3 px with bicubic B-splines on 4 px speckles. With one
noise level it cannot be told from the noise term (both are flat in W at small W), so it is
fitted only with >= 2 noise levels (docs/models.md s. 4). ``d`` (``noise_blur2``, px**-2,
either sign) and ``e`` (``noise_blur``, px**-4, >= 0) are the growth of the noise term
with the blur mismatch: with a sharp reference the noise of the reference gradients meets
the mismatch residual ``(W**2 / 24) f''`` left at the fixed point, and its covariance with
the reference intensities' own noise is negative, O(W**2) relative; its variance and the
Hessian ``sum g_ref g_cur`` falling below ``sqrt(SSSIG_ref SSSIG(W))`` are O(W**4)
(docs/models.md s. 4, the complete noise term). The square keeps the factor positive.
They are separable from ``c`` only with >= 2 noise levels. ``b``
(``cross``, px/px) is the cross term of the blur mismatch with the interpolation's own
smoothing: the B-spline interpolant of the current image at its sub-pixel offset is
smoother than the sampled reference, an extra even mismatch ``m_i`` per subset that adds to
the blur's ``c_i W**2``; averaged over offsets, ``var(m_i + c_i W**2)`` gains
``2 cov(m_i, c_i) W**2``, a noise-free variance linear in ``W**2`` (docs/models.md s. 4).
Like the floor it is told from the noise term only with >= 2 noise levels. The noise
enters only through
``SSSIG / sigma**2``, so the model is invariant to scaling the image intensity. Without a
known noise level the noise term is ``k / SSSIG(W)`` with ``k = a sigma**2`` fitted.

This module is the model form and its fit (the ``mismatch`` kind of
:class:`~dicblur.models.BlurUncertaintyModel`); the predictions of ``c`` and of the
noise-free term from a static image are in :mod:`dicblur.models.mismatch_prediction`.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike
from scipy import optimize

from ..arrays import Float64Array, IndexArray
from ..checks import as_blur, as_positive, as_vector
from ..errors import FitError, InputError
from ._result import CIOptions, FitResult, make_result

__all__ = ["fit_mismatch", "mismatch_model", "mismatch_terms", "noise_growth"]


def mismatch_terms(
    blur: ArrayLike,
    sssig: ArrayLike,
    noise_sigma: ArrayLike | None,
    *,
    c: float,
    a: float = 2.0,
    gamma: float = 1.0,
    c4: float = 0.0,
    k: float | None = None,
    noise_blur: float = 0.0,
    cross: float = 0.0,
    noise_blur2: float = 0.0,
) -> tuple[Float64Array, Float64Array]:
    """The two variance terms of the noise + blur-mismatch model (docs/models.md eq. M1).

    This is the one implementation of the formula (``mismatch_model``, the fitted
    :class:`~dicblur.models.BlurUncertaintyModel` and the pattern-design surrogate call it):

        noise  = a (SSSIG / sigma**2)**(-gamma) [(1 + d W**2)**2 + e W**4]   (M2)
        blur2  = (b W)**2 + (c W**2 + c4 W**4)**2                     (M3)

    ``d = noise_blur2`` (px**-2, either sign) and ``e = noise_blur`` (px**-4) are the noise
    growth with the blur mismatch (:func:`noise_growth`).
    With ``noise_sigma=None`` the noise term is ``k / SSSIG`` times that growth (``k = a
    sigma**2``, GL**2, required). ``u_e**2 = noise + u_0**2 + blur2`` (M1); the floor
    ``u_0`` is added by the caller.

    Parameters
    ----------
    blur, sssig : array_like, shape (n,)
        W (px) and SSSIG(W) of the blurred image along the motion ((GL/px)**2).
    noise_sigma : float, array_like or None
        Noise std (GL).

    Returns
    -------
    noise, blur2 : ndarray, shape (n,)
        Variances, px**2.
    """
    w = np.asarray(blur, dtype=np.float64)
    s = np.asarray(sssig, dtype=np.float64)
    if noise_sigma is None:
        if k is None:
            raise InputError("k: give k (= a sigma**2, GL**2) when noise_sigma is None")
        noise = k / s
    else:
        sig = np.asarray(noise_sigma, dtype=np.float64)
        noise = a * (s / sig**2) ** (-gamma)
    noise = noise * noise_growth(w, noise_blur, noise_blur2)
    ub = c * w * w + c4 * w**4
    bw = cross * w
    return noise, bw * bw + ub * ub


def mismatch_model(
    blur: ArrayLike,
    sssig: ArrayLike,
    noise_sigma: ArrayLike | None,
    *,
    c: float,
    a: float = 2.0,
    gamma: float = 1.0,
    c4: float = 0.0,
    k: float | None = None,
    floor: float = 0.0,
    noise_blur: float = 0.0,
    cross: float = 0.0,
    noise_blur2: float = 0.0,
) -> Float64Array:
    """``sqrt(a (SSSIG/sigma**2)**(-gamma) [(1 + d W**2)**2 + e W**4] + floor**2
    + (b W)**2 + (c W**2 + c4 W**4)**2)`` (docs/models.md eq. M1, via
    :func:`mismatch_terms`).

    In px. With ``noise_sigma=None`` the noise term is ``k / SSSIG`` (``k`` required).
    ``floor`` (px) is the noise-independent matcher floor ``u_0``; ``noise_blur2`` (``d``,
    px**-2, either sign) and ``noise_blur`` (``e``, px**-4) the growth of the noise term
    with the blur mismatch (:func:`noise_growth`); ``cross`` (``b``, px/px) the
    mismatch-interpolation cross term.
    """
    noise, blur2 = mismatch_terms(
        blur,
        sssig,
        noise_sigma,
        c=c,
        a=a,
        gamma=gamma,
        c4=c4,
        k=k,
        noise_blur=noise_blur,
        cross=cross,
        noise_blur2=noise_blur2,
    )
    return np.sqrt(noise + floor * floor + blur2)


def noise_growth(blur: ArrayLike, noise_blur: float, noise_blur2: float = 0.0) -> Float64Array:
    """Growth factor of the noise term with the blur mismatch, ``(1 + d W**2)**2 + e W**4``
    (``d = noise_blur2`` px**-2, any sign: the negative covariance of the reference
    gradients' noise with its intensities' noise; ``e = noise_blur`` px**-4 >= 0). Positive
    for every ``W``; ``d = 0`` is the earlier ``1 + e W**4``. docs/models.md s. 4."""
    w2 = np.asarray(blur, dtype=np.float64) ** 2
    return np.asarray((1.0 + noise_blur2 * w2) ** 2 + noise_blur * w2 * w2)


def fit_mismatch(
    blur: ArrayLike,
    sssig: ArrayLike,
    u_e: ArrayLike,
    *,
    noise_sigma: ArrayLike | None = None,
    fit_gamma: bool | None = None,
    next_term: bool | Literal["auto"] = "auto",
    floor: bool | Literal["auto"] = "auto",
    noise_blur: bool | Literal["auto"] = "auto",
    cross: bool | Literal["auto"] = "auto",
    confidence: float = 0.95,
    ci: str = "covariance",
    n_boot: int = 500,
    seed: int | np.random.Generator | None = None,
) -> FitResult:
    """Fit the noise + blur-mismatch model by least squares on ``log u_e``.

    Parameters
    ----------
    blur, sssig, u_e : array_like, shape (n,)
        W (px), SSSIG of the blurred image along the motion ((GL/px)**2), u_e (px).
    noise_sigma : float or array_like, shape (n,), optional
        Noise std (GL). ``None``: the noise term is ``k / SSSIG``.
    fit_gamma : bool, optional
        Fit the noise exponent ``gamma``; default: only with >= 2 noise levels and neither
        ``floor`` nor ``cross`` (else fixed at the theoretical 1: noise-free terms are the
        physical reason a fitted ``gamma`` drops below 1, and they are barely separable
        from it with two levels).
    next_term : bool or "auto"
        Add ``c4 W**4`` to the mismatch term; ``"auto"`` keeps it when the Akaike
        information criterion drops by more than 2 and there are enough points.
    floor : bool or "auto"
        Fit the noise-independent floor ``u_0`` (px, name ``"floor"``). ``"auto"``: tried
        only with >= 2 noise levels (with one level it is confounded with ``a``) and kept
        when the AIC drops by more than 2. ``True`` with one level raises.
    noise_blur : bool or "auto"
        Fit ``d`` and ``e`` (names ``"noise_blur2"``, px**-2, and ``"noise_blur"``,
        px**-4) of the noise term's growth ``(1 + d W**2)**2 + e W**4``; same rules as
        ``floor``.
    cross : bool or "auto"
        Fit ``b`` (name ``"cross"``, px/px) of the noise-free term ``(b W)**2``, the
        cross term of the blur mismatch with the interpolation's smoothing; same rules as
        ``floor``.

    Returns
    -------
    FitResult
        ``names`` among ``("a" | "k", "gamma", "noise_blur2", "noise_blur", "floor",
        "cross", "c", "c4")``; ``fixed`` holds the rest.
    """
    w = as_vector(blur, "blur")
    s = as_positive(sssig, "sssig", w.size)
    u = as_positive(u_e, "u_e", w.size)
    as_blur(w, "blur", increasing=False)
    ci_options = CIOptions(confidence, ci, n_boot, seed)
    sig: Float64Array | None = None
    if noise_sigma is not None:
        sig = as_positive(
            np.broadcast_to(np.asarray(noise_sigma, dtype=np.float64), w.shape).copy(),
            "noise_sigma",
            w.size,
        )
    multi = sig is not None and np.unique(sig).size >= 2
    if next_term not in (True, False, "auto"):
        raise InputError(f"next_term={next_term!r}: use True, False or 'auto'")
    if floor not in (True, False, "auto"):
        raise InputError(f"floor={floor!r}: use True, False or 'auto'")
    if noise_blur not in (True, False, "auto"):
        raise InputError(f"noise_blur={noise_blur!r}: use True, False or 'auto'")
    if cross not in (True, False, "auto"):
        raise InputError(f"cross={cross!r}: use True, False or 'auto'")
    for opt, val in (("floor", floor), ("noise_blur", noise_blur), ("cross", cross)):
        if val is True and not multi:
            raise InputError(
                f"{opt}=True: needs data at >= 2 noise levels (with one level it cannot be "
                f"told from the other terms); add a noise level or use {opt}=False"
            )
    options = [False, True] if next_term == "auto" else [bool(next_term)]
    floors = ([False, True] if multi else [False]) if floor == "auto" else [bool(floor)]
    growths = ([False, True] if multi else [False]) if noise_blur == "auto" else [bool(noise_blur)]
    crosses = ([False, True] if multi else [False]) if cross == "auto" else [bool(cross)]
    results = []
    for with_cross in crosses:
        for with_growth in growths:
            for with_floor in floors:
                do_gamma = bool(
                    (multi and not (with_floor or with_cross))
                    if fit_gamma is None
                    else (fit_gamma and sig is not None)
                )
                for with_c4 in options:
                    names: list[str] = ["a" if sig is not None else "k"]
                    if do_gamma:
                        names.append("gamma")
                    if with_growth:  # the W**2 (either sign) and W**4 growth together
                        names += ["noise_blur2", "noise_blur"]
                    if with_floor:
                        names.append("floor")
                    if with_cross:
                        names.append("cross")
                    names.append("c")
                    if with_c4:
                        names.append("c4")
                    auto = (
                        (with_c4 and next_term == "auto")
                        or (with_floor and floor == "auto")
                        or (with_growth and noise_blur == "auto")
                        or (with_cross and cross == "auto")
                    )
                    if w.size - len(names) < (2 if auto else 1):
                        continue
                    results.append(
                        _fit_one(w, s, u, sig, tuple(names), ci_options, intervals=False)
                    )
    if not results:
        raise FitError(
            f"mismatch: {w.size} point(s) are too few for the noise + blur-mismatch model; "
            "give at least 3 blur levels"
        )

    def aic(r: FitResult) -> float:
        ssr = r.residual_std**2 * r.dof
        return r.n_points * math.log(max(ssr, 1e-300) / r.n_points) + 2 * len(r.names)

    # candidates in order of complexity; a richer one must lower the AIC by more than 2
    best = results[0]
    for r in results[1:]:
        if aic(r) < aic(best) - 2.0:
            best = r
    # intervals only for the chosen candidate (a degenerate one falls back to a bootstrap)
    return _fit_one(w, s, u, sig, best.names, ci_options)


def _fit_one(
    w: Float64Array,
    s: Float64Array,
    u: Float64Array,
    sig: Float64Array | None,
    names: tuple[str, ...],
    ci_options: CIOptions,
    *,
    intervals: bool = True,
) -> FitResult:
    def unpack(p: Float64Array) -> dict[str, float]:
        d = dict(zip(names, p, strict=True))
        d.setdefault("gamma", 1.0)
        d.setdefault("c4", 0.0)
        d.setdefault("floor", 0.0)
        d.setdefault("noise_blur", 0.0)
        d.setdefault("noise_blur2", 0.0)
        d.setdefault("cross", 0.0)
        return d

    def fit_once(
        idx: IndexArray, refit_from: Float64Array | None = None
    ) -> tuple[Float64Array, ...]:
        wi, si, ui = w[idx], s[idx], u[idx]
        sg = None if sig is None else sig[idx]
        q = si if sg is None else si / sg**2
        lo = np.argmin(wi)
        hi = np.argmax(wi)
        noise0 = float(ui[lo] ** 2 * q[lo])
        blur_part = ui[hi] ** 2 - noise0 / q[hi]
        c0 = math.sqrt(max(blur_part, 0.01 * ui[hi] ** 2)) / max(wi[hi] ** 2, 1e-12)
        floor0 = 0.3 * float(ui.min())
        if "floor" in names:  # start with part of the low-W variance on the floor
            noise0 *= 0.9
        start = {
            "a": noise0,
            "k": noise0,
            "gamma": 1.0,
            "c": c0,
            "c4": 0.0,
            "floor": floor0,
            "noise_blur": 1e-3,
            "noise_blur2": 0.0,
            "cross": 0.5 * c0,
        }
        p0 = np.array([start[n] for n in names])
        scl = np.where(p0 > 0, p0, 1e-3 * c0 if c0 > 0 else 1e-6)
        scl[[n == "noise_blur2" for n in names]] = 1e-2  # px**-2, starts at 0
        lower = np.array(
            [
                0.0
                if n in ("a", "k", "c", "floor", "noise_blur", "cross")
                else (0.05 if n == "gamma" else -np.inf)
                for n in names
            ]
        )
        upper = np.array([5.0 if n == "gamma" else np.inf for n in names])

        def resid(pn: Float64Array) -> Float64Array:
            d = unpack(pn * scl)
            m = mismatch_model(
                wi,
                si,
                sg,
                c=d["c"],
                a=d.get("a", 2.0),
                gamma=d["gamma"],
                c4=d["c4"],
                k=d.get("k"),
                floor=d["floor"],
                noise_blur=d["noise_blur"],
                cross=d["cross"],
                noise_blur2=d["noise_blur2"],
            )
            return np.log(np.maximum(m, 1e-300)) - np.log(ui)

        # a bootstrap refit (_result.FitOnce) starts at the fit to all points, to a
        # tolerance far below the bootstrap's Monte Carlo error, within a budget
        refit = refit_from is not None
        x0 = p0 if refit_from is None else np.clip(refit_from, lower, upper)
        tol = 1e-8 if refit else 1e-12
        r = optimize.least_squares(
            resid,
            x0 / scl,
            bounds=(lower / scl, upper / scl),
            method="trf",
            x_scale="jac",
            xtol=tol,
            ftol=tol,
            gtol=tol,
            max_nfev=150 if refit else 2000,
        )
        if not np.all(np.isfinite(r.fun)):
            raise FitError("mismatch: the fit produced non-finite residuals; check the data")
        if refit and r.status == 0:
            raise FitError("mismatch: a bootstrap refit did not converge within its budget")
        return r.x * scl, r.jac / scl, r.fun

    extra = {
        "noise_levels": [] if sig is None else [float(v) for v in np.unique(sig)],
        "noise_term": "k/SSSIG" if sig is None else "a*(SSSIG/sigma^2)^-gamma",
    }
    fixed = {} if "gamma" in names or sig is None else {"gamma": 1.0}
    return make_result(
        model="mismatch",
        names=names,
        fit_once=fit_once,
        n=w.size,
        data_space=np.log(u),
        blur=w,
        fixed=fixed,
        ci_options=ci_options,
        extra=extra,
        log_params=("a", "k"),
        nonneg=("c", "floor", "noise_blur", "cross"),
        intervals=intervals,
    )
