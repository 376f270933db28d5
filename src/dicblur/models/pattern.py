"""Predict u_e(W) of a pattern from its static image alone: no simulation, no DIC run.

Both terms of the noise + blur-mismatch model (docs/models.md s. 4) come from the sharp
image and its exact box blur, subset by subset, for the ZNSSD IC-GN matcher:

- the mismatch shift ``xi_i(W)``: where IC-GN stops against the blurred image
  (:func:`~dicblur.models.blur_mismatch_curve`);
- the noise variance ``var_i(W)``: the response of that fixed point to independent
  Gaussian noise of std ``sigma`` in both images (the sandwich formula of
  :func:`dicblur.models.sensitivity.subset_noise_variance`, with the reference's noise
  through its intensities and its gradients, plus the two noises' second-order
  interaction; at W = 0 the match-score bound, eq. 2). Against a Monte Carlo of the
  engine: within 3 % at W = 0..8 px (BENCHMARKS.md).
- a breakdown test: the IC-GN contraction of each subset; ``breakdown_blur`` is where
  the prediction stops describing DIC.

The field statistic DIC reports, the std of the displacement over POIs, then has
expectation ``u_e(W)**2 = mean_i var_i(W) + var_i(xi_i(W))``. On generated patterns of 3
and 6 px speckles with noise 2 GL, noisy IC-GN lands within 5 % of it for W = 0..6 px
(BENCHMARKS.md). :func:`model_from_pattern` turns the prediction into a
:class:`~dicblur.models.BlurUncertaintyModel`, so ``predict``, ``max_blur`` and
``plan_exposure`` work before any campaign.
"""

from __future__ import annotations

import functools
import hashlib
import math
import warnings
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from ..arrays import Float64Array, IndexArray
from ..checks import as_blur, check_positive, check_subpixel
from ..errors import InputError
from ..metrics import directional_sssig
from ..threads import each
from .derivatives import Boundary, Derivative, box_blurred, image_spectrum, unit_direction
from .mismatch_prediction import subset_inputs
from .model import BlurUncertaintyModel
from .reference_terms import ReferenceTerms
from .scaled import StaticTerms
from .sensitivity import shifts_and_variance
from .subset_algebra import Shape, SubsetMatcher

if TYPE_CHECKING:
    from ..dic.settings import MatcherSettings

__all__ = ["PatternPrediction", "model_from_pattern", "predict_from_pattern", "static_terms"]


@dataclass(frozen=True)
class PatternPrediction:
    """Uncertainty of a pattern predicted from its static image (see predict_from_pattern).

    Attributes
    ----------
    blur : ndarray, shape (m,)
        Blur lengths W (px).
    u_e : ndarray, shape (m,)
        Predicted random error along the motion (px): ``sqrt(u_noise**2 + u_blur**2)``.
    u_noise : ndarray, shape (m,)
        Noise term ``sqrt(mean_i var_i)`` (px).
    u_blur : ndarray, shape (m,)
        Noise-free term ``std_i(xi_i)`` (px): the blur mismatch and, with ``subpixel``, the
        interpolation bias (mean square over the offsets).
    sssig : ndarray, shape (m,)
        Mean subset SSSIG of the blurred image along the motion ((GL/px)**2, central
        differences, as :func:`dicblur.sssig` and the campaigns compute it); NaN when
        not asked for (``predict_from_pattern(..., sssig=False)``).
    valid_fraction : ndarray, shape (m,)
        Fraction of the subsets in the statistics (the rest break down: no texture left
        along the motion).
    noise_sigma : float
        Noise std (GL) in each image.
    subset : int
    shape : str
    motion : tuple of float
        Unit motion direction (dy, dx).
    u_noise_reference, u_noise_current, u_noise_interaction : ndarray, shape (m,)
        The shares of ``u_noise`` (px; their squares add up to ``u_noise**2``): the
        reference image's noise alone and the current image's alone (first order, each
        ``~ sigma``), and the interaction of the two (the reference-gradient noise against
        the current noise, second order, ``~ sigma**2``; a few per cent of the variance at
        8 GL on soft patterns).
    breakdown_blur : float or None
        The smallest W (px) of ``blur`` at which fewer than 90 % of the subsets hold (the
        campaigns' DIC breakdown rule; a subset breaks down when its IC-GN contraction
        falls below ``min_contraction`` or its shift exceeds ``max_shift``): the prediction
        describes DIC only below it; at and beyond it the terms come from the surviving
        subsets (``nan`` where fewer than two survive). ``None``: no breakdown in ``blur``.
    """

    blur: Float64Array
    u_e: Float64Array
    u_noise: Float64Array
    u_blur: Float64Array
    sssig: Float64Array
    valid_fraction: Float64Array
    noise_sigma: float
    subset: int
    shape: str
    motion: tuple[float, float]
    u_noise_reference: Float64Array | None = None
    u_noise_current: Float64Array | None = None
    u_noise_interaction: Float64Array | None = None
    breakdown_blur: float | None = None


BREAKDOWN_FRACTION = 0.9  # as the campaigns: DIC broken down below 90 % of the subsets
MIN_CONTRACTION = 0.1  # default breakdown test of a subset (predict_from_pattern)
DEGENERATE = 0.02  # contraction below which a subset's fixed point is left out
N_OFFSETS = 8  # sub-pixel positions averaged by subpixel="average" (midpoint rule)
NOISE_FACTORS = (0.5, 1.0, 2.0)  # noise levels (times sigma) a prediction is fitted on


def model_blur(blur: ArrayLike | None, *, below: int | None = None) -> Float64Array:
    """Blur lengths (px) a model of a static prediction is fitted on: ``blur``, or by
    default W = 0..8 px in steps of 0.5 (those shorter than ``below`` px, when given);
    at least 4 distinct values."""
    w = as_blur(np.arange(0.0, 8.01, 0.5) if blur is None else blur, "blur", increasing=True)
    if blur is None and below is not None:
        w = w[w < below]
    if np.unique(w).size < 4:
        raise InputError(
            f"blur: {np.unique(w).size} distinct lengths; give at least 4 (e.g. W = 0, 1, 2, 4 px)"
        )
    return w


def fit_prediction(
    image: Float64Array,
    blur: Float64Array,
    sssig: Float64Array,
    u_e: list[Float64Array],
    *,
    noise_sigma: float,
    subset: int,
    shape: str,
    provenance: dict[str, Any],
    **options: Any,
) -> BlurUncertaintyModel:
    """A :class:`BlurUncertaintyModel` fitted to a static prediction like campaign data.

    ``u_e[j]`` (px, over ``blur``) is predicted at the noise ``NOISE_FACTORS[j] *
    noise_sigma``; the mismatch model is fitted on all of them
    (:func:`~dicblur.models.fit_blur_model`, ``options`` passed on) and the model's own
    noise is made ``noise_sigma``. The pattern is named from ``provenance``
    (:func:`pattern_name`) and hashed from ``image``.
    """
    from .fit import fit_blur_model

    levels = tuple(f * noise_sigma for f in NOISE_FACTORS)
    model = fit_blur_model(
        np.concatenate([blur] * len(levels)),
        np.concatenate([sssig] * len(levels)),
        np.concatenate(u_e),
        noise_sigma=np.repeat(levels, blur.size),
        subset=subset,
        mean_level=float(image.mean()),
        default="mismatch",
        provenance=provenance,
        compare=False,
        shape=str(shape),
        pattern=pattern_name(provenance),
        pattern_sha256=hashlib.sha256(image.tobytes()).hexdigest(),
        **options,
    )
    # fitted on three noise levels: make the model's own noise the one asked for
    return replace(model, noise_sigma=noise_sigma)


def _offsets(subpixel: float | str | None) -> list[float | None]:
    """The sub-pixel offsets a prediction averages over (``[None]``: no interpolation)."""
    if subpixel is None:
        return [None]
    if isinstance(subpixel, str):
        if subpixel != "average":
            raise InputError(
                f"subpixel={subpixel!r}: use None, 'average' or an offset in [0, 1) px"
            )
        return [(k + 0.5) / N_OFFSETS for k in range(N_OFFSETS)]
    return [check_subpixel(subpixel)]


def _terms(
    img: Float64Array,
    w: Float64Array,
    pts: IndexArray,
    subset: int,
    matcher: SubsetMatcher,
    max_shift: float,
    subpixel: float | str | None = None,
    min_contraction: float = 0.0,
    sssig: bool = True,
    reference: ReferenceTerms | None = None,
) -> tuple[Float64Array, Float64Array, Float64Array, Float64Array]:
    """Per W: mean noise variance (shape (3, m): the reference and the current image's
    shares per GL**2, their interaction per GL**4), mismatch variance, SSSIG, valid
    fraction (subsets with a shift <= ``max_shift`` and an IC-GN contraction >=
    ``min_contraction``; averaged over the sub-pixel offsets of ``subpixel``). The terms
    leave out only the degenerate subsets (contraction < ``DEGENERATE``); ``nan`` where
    fewer than two subsets remain. ``reference``: the reference's terms kept across the
    offsets and calls (a new one per call by default; the same numbers either way)."""
    if len(pts) < 2:  # not a texture problem: the grid holds too few subsets
        raise InputError(
            f"subset={subset}: {len(pts)} subset(s) of {subset} px fit in the "
            f"{img.shape[0]}x{img.shape[1]} px image, and the prediction averages over at "
            "least two; use a smaller subset (or step) or a larger image"
        )
    offs = _offsets(subpixel)
    ref = ReferenceTerms() if reference is None else reference
    lams = np.empty((len(offs), len(w), len(pts)))
    # degenerate fixed points (contraction below DEGENERATE) are left out, as DIC's
    # non-converged points; the breakdown counts those below min_contraction
    runs = [
        shifts_and_variance(
            img,
            w,
            pts,
            subset,
            matcher,
            criterion="znssd",
            max_shift=max_shift,
            chunk=256,
            variance=True,
            offset=o,
            min_contraction=min(DEGENERATE, min_contraction),
            contraction_out=lams[i],
            reference=ref,
        )
        for i, o in enumerate(offs)
    ]
    xis = np.stack([r[0] for r in runs])
    parts = np.stack([r[1] for r in runs if r[1] is not None])  # (offsets, 3, m, n)
    variances = parts.sum(axis=1)
    # a subset enters the statistics only where it holds at every offset
    ok = (np.isfinite(xis) & np.isfinite(variances)).all(axis=0)
    count = ok.sum(axis=1)
    if count[np.argmin(w)] < 2:  # larger W may break down (nan there, flagged)
        j = int(np.argmin(w))
        raise InputError(
            f"image: fewer than two subsets keep an intensity gradient at W = {w[j]:g} px "
            "(flat, or erased by the blur); no prediction there (use a textured image, a "
            "larger area or shorter blur lengths)"
        )
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-nan beyond the breakdown
        # reference and current shares, each averaged over the subsets and offsets
        mean_var = np.nanmean(np.where(ok[None], np.moveaxis(parts, 1, 0), np.nan), axis=3).mean(
            axis=1
        )
        mis_var = np.nanvar(np.where(ok, xis, np.nan), axis=2).mean(axis=0)
    dy, dx = unit_direction(matcher.motion)
    angle = math.degrees(math.atan2(dy, dx))
    held = ok & ((lams >= min_contraction).all(axis=0) if min_contraction > 0 else True)
    frac = held.sum(axis=1) / xis.shape[2]
    if not sssig:
        return mean_var, mis_var, np.full(len(w), np.nan), frac
    # SSSIG along the motion as dicblur.sssig and the campaigns compute it (one forward
    # FFT of the image for all the blur lengths)
    spec = image_spectrum(img, matcher.boundary) if np.any(w != 0) else None
    s = np.array(
        [
            float(
                directional_sssig(
                    img if wl == 0 else box_blurred(img, matcher.boundary, dy, dx, float(wl), spec),
                    pts,
                    subset=subset,
                    angle=angle,
                ).mean()
            )
            for wl in w
        ]
    )
    return mean_var, mis_var, s, frac


def predict_from_pattern(
    image: ArrayLike,
    blur: ArrayLike,
    *,
    noise_sigma: float,
    subset: int | None = None,
    step: int | None = None,
    points: ArrayLike | None = None,
    motion: tuple[float, float] = (0.0, 1.0),
    shape: Shape = "translation",
    derivative: Derivative = "bspline3",
    boundary: Boundary = "reflect",
    max_shift: float = 1.0,
    subpixel: float | str | None = None,
    min_contraction: float = 0.1,
    settings: MatcherSettings | None = None,
    sssig: bool = True,
) -> PatternPrediction:
    """Predict the DIC random error u_e(W) of a pattern from its static image alone.

    Parameters
    ----------
    image : array_like, shape (rows, cols)
        Sharp reference image (grey levels), e.g. a camera image of the specimen at rest.
    blur : array_like, shape (m,)
        Blur lengths W (px, >= 0) of linear motion along ``motion``.
    noise_sigma : float
        Gaussian noise std (GL) in each image (reference and blurred current).
    subset : int
        Odd subset size (px); required unless ``settings`` gives it.
    step, points
        Subset grid step (px, default ``subset``) or explicit (n, 2) (row, col) centres.
    motion : (dy, dx)
        Motion direction (only the direction matters).
    shape : {"translation", "affine"}
        Shape function of the IC-GN matcher.
    derivative, boundary, max_shift
        As for :func:`~dicblur.models.blur_mismatch_curve` (defaults: the DIC engine's
        cubic spline, mirror extension for camera images, breakdown beyond 1 px).
    subpixel : {None, "average"} or float
        Sub-pixel position of the moving target along the motion. ``None`` (default):
        exactly aligned, no interpolation error. A float in [0, 1) px: the blurred image
        is matched through the B-spline interpolant at that offset, so ``u_blur`` carries
        the matcher's interpolation bias (the floor and the cross term of the mismatch
        model). ``"average"``: the mean over 8 offsets, for a target at an arbitrary
        position (what a real test sees); about 5x the cost of the aligned prediction.
    min_contraction : float
        Breakdown test: a subset whose IC-GN contraction (the smallest eigenvalue of
        ``(sigma_f / sigma_g) H^-1 A``, 1 for a warped copy) is below it has broken down,
        and ``breakdown_blur`` is the first W where more than 10 % have. As it nears 0 the
        blur has nearly erased (beyond 0: reversed) the subset's gradients along the
        motion, the noise response grows as its inverse and IC-GN stalls. The terms keep
        such subsets (DIC does, while they converge) but leave out the degenerate ones,
        contraction < 0.02, which made the predicted noise term spike (to ~5 px on 2 px
        speckles at W = 8.5 px). ``0`` switches both off.
    settings : dicblur.dic.MatcherSettings, optional
        The matcher's settings in one record (as the Correlator and the campaigns take
        them): its ``subset`` and ``step`` (unless given here), ``shape`` and
        ``interpolation`` (for ``derivative``) are used.
    sssig : bool
        Compute the SSSIG of the blurred image (default); ``False``: leave it NaN (a
        caller that needs only the error terms: one blurred image less per W).

    Returns
    -------
    PatternPrediction

    Notes
    -----
    Without ``subpixel`` the prediction leaves out DIC's interpolation bias (below the
    noise term in noisy data, but the floor of noise-free or low-noise data) and takes the
    current image's noise as sampled; with it, both come through the interpolant at the
    offset (docs/models.md s. 4). It assumes
    Gaussian noise of the same std in both images (for a Poisson-Gaussian camera give the
    noise at the mean level, or use :func:`model_from_pattern` with ``plan_exposure``).
    """
    if settings is not None:
        subset = settings.subset if subset is None else subset
        step = settings.step if step is None and points is None else step
        shape = settings.shape
        derivative = settings.interpolation
    if subset is None:
        raise InputError("subset=None: give the odd subset size (px) or settings")
    img, subset, pts = subset_inputs(image, subset, step, points, boundary)
    sigma = check_positive(noise_sigma, "noise_sigma")
    max_shift = check_positive(max_shift, "max_shift")
    lam_min = check_positive(min_contraction, "min_contraction", allow_zero=True)
    w = as_blur(blur, "blur", increasing=False)
    matcher = SubsetMatcher(motion, shape, derivative, boundary)
    mean_var, mis_var, s, frac = _terms(
        img, w, pts, subset, matcher, max_shift, subpixel, lam_min, sssig=sssig
    )
    broken = frac < BREAKDOWN_FRACTION
    breakdown = float(w[broken].min()) if broken.any() else None
    u_noise = np.sqrt(sigma**2 * (mean_var[0] + mean_var[1]) + sigma**4 * mean_var[2])
    u_blur = np.sqrt(mis_var)
    return PatternPrediction(
        blur=w,
        u_e=np.hypot(u_noise, u_blur),
        u_noise=u_noise,
        u_blur=u_blur,
        sssig=s,
        valid_fraction=frac,
        noise_sigma=sigma,
        subset=subset,
        shape=str(shape),
        motion=unit_direction(motion),
        u_noise_reference=sigma * np.sqrt(mean_var[0]),
        u_noise_current=sigma * np.sqrt(mean_var[1]),
        u_noise_interaction=sigma**2 * np.sqrt(mean_var[2]),
        breakdown_blur=breakdown,
    )


def model_from_pattern(
    image: ArrayLike,
    *,
    noise_sigma: float,
    subset: int,
    blur: ArrayLike | None = None,
    step: int | None = None,
    points: ArrayLike | None = None,
    motion: tuple[float, float] = (0.0, 1.0),
    shape: Shape = "translation",
    boundary: Boundary = "reflect",
    provenance: dict[str, Any] | None = None,
    subpixel: float | str | None = None,
) -> BlurUncertaintyModel:
    """A :class:`BlurUncertaintyModel` fitted to the static prediction of a pattern.

    The prediction (:func:`predict_from_pattern`) at noise ``sigma/2``, ``sigma`` and
    ``2 sigma`` over ``blur`` (default W = 0..8 px in steps of 0.5) is fitted like
    campaign data (:func:`~dicblur.models.fit_blur_model`, mismatch model with its next
    term), so ``predict``, ``max_blur`` and ``plan_exposure`` work before any simulation.
    The intervals describe how well the model form follows the prediction, not the
    prediction's own error (within 5-10 % of IC-GN, BENCHMARKS.md); ``provenance`` records
    ``source = "static prediction"``.

    Parameters
    ----------
    image : array_like, shape (rows, cols)
        Sharp reference image, grey levels.
    noise_sigma : float
        Noise std (GL) of the images the model is for (its reference noise).
    subset : int
        Odd subset size (px).
    blur : array_like, optional
        Blur lengths (px) to predict and fit; at least 4 distinct values.
    step, points, motion, shape, boundary
        As for :func:`predict_from_pattern`.
    provenance : dict, optional
        Extra JSON-ready fields for the model's provenance.
    subpixel : {None, "average"} or float
        As for :func:`predict_from_pattern`; with an offset or ``"average"`` the
        prediction carries the interpolation bias and the model is fitted with its floor
        and cross term on ``"auto"``.

    Returns
    -------
    BlurUncertaintyModel
    """
    img, subset, pts = subset_inputs(image, subset, step, points, boundary)
    sigma = check_positive(noise_sigma, "noise_sigma")
    w = model_blur(blur)
    matcher = SubsetMatcher(motion, shape, "bspline3", boundary)
    mean_var, mis_var, s, frac = _terms(
        img, w, pts, subset, matcher, 1.0, subpixel, MIN_CONTRACTION
    )
    # below the first breakdown only (as the campaigns' rule: >= 90 % of the subsets)
    keep = frac >= BREAKDOWN_FRACTION
    keep &= w < (w[~keep].min() if (~keep).any() else np.inf)
    if keep.sum() < 4:
        raise InputError(
            f"blur: only {int(keep.sum())} blur lengths keep >= 90 % of the subsets; the "
            "pattern's texture is erased along the motion beyond W = "
            f"{w[keep][-1] if keep.any() else 0:g} px (give shorter blur lengths)"
        )
    var1 = mean_var[0] + mean_var[1]
    u_e = [
        np.sqrt(lv**2 * var1[keep] + lv**4 * mean_var[2][keep] + mis_var[keep])
        for lv in (f * sigma for f in NOISE_FACTORS)
    ]
    prov: dict[str, Any] = {
        "source": "static prediction",
        "subset": subset,
        "subpixel": subpixel,
        "shape": str(shape),
        "motion": [float(motion[0]), float(motion[1])],
        "n_subsets": len(pts),
        "image_shape": list(img.shape),
    }
    prov.update(provenance or {})
    # validity domain: the static prediction's own breakdown test ends it
    broken = np.nonzero(~keep)[0]
    w_break = float(w[broken[0]]) if broken.size else None
    return fit_prediction(
        img,
        w[keep],
        s[keep],
        u_e,
        noise_sigma=sigma,
        subset=subset,
        shape=str(shape),
        provenance=prov,
        next_term=True,
        breakdown_blur=w_break,
        breakdown_rule="static prediction: < 90 % of the subsets keep a shift below 1 px"
        if w_break is not None
        else None,
    )


def static_terms(
    image: ArrayLike,
    blur: ArrayLike,
    *,
    subset: int,
    step: int | None = None,
    points: ArrayLike | None = None,
    motion: tuple[float, float] = (0.0, 1.0),
    shape: Shape = "translation",
    boundary: Boundary = "reflect",
    max_shift: float = 1.0,
    min_contraction: float = MIN_CONTRACTION,
    extend_to: float | None = None,
    threads: int = 1,
) -> StaticTerms:
    """The static prediction's terms on a W grid, for the ``static`` model kind.

    Each W is predicted at the campaigns' sub-pixel offset ``W/2 mod 1`` px (a linear
    trajectory centres the blurred target at half its path), as
    :func:`predict_from_pattern` with ``subpixel`` set per W. The grid is ``blur`` with
    W = 0 added and, with ``extend_to``, continued in the grid's own step beyond its
    largest W up to ``extend_to`` (the static prediction needs no measurement there), up
    to the static prediction's breakdown W (included where its terms are finite); beyond
    it DIC is not described.

    Parameters
    ----------
    image : array_like, shape (rows, cols)
        Sharp reference image (grey levels).
    blur : array_like, shape (m,)
        Blur lengths W (px) of the calibration.
    subset, step, points, motion, shape, boundary, max_shift, min_contraction
        As for :func:`predict_from_pattern`.
    extend_to : float, optional
        Largest W (px) of the grid's extension (none by default).
    threads : int
        Threads sharing the grid's sub-pixel offsets (numpy releases the GIL; the same
        table on any number).

    Returns
    -------
    StaticTerms
        Per W: noise variance per GL**2 and per GL**4, noise-free variance (px**2), the
        fraction of subsets that hold, and the breakdown W.
    """
    img, subset, pts = subset_inputs(image, subset, step, points, boundary)
    max_shift = check_positive(max_shift, "max_shift")
    lam_min = check_positive(min_contraction, "min_contraction", allow_zero=True)
    w = np.unique(np.concatenate([[0.0], as_blur(blur, "blur", increasing=False)]))
    if extend_to is not None and w.size >= 2 and extend_to > w[-1]:
        dw = float(np.median(np.diff(w)))
        more = w[-1] + dw * np.arange(1, math.floor((extend_to - w[-1]) / dw + 1e-9) + 1)
        w = np.concatenate([w, np.round(more, 10)])
    offs = np.round((w / 2.0) % 1.0, 12) % 1.0
    n1, n2, b2, frac = (np.full(w.size, np.nan) for _ in range(4))
    # the reference's terms once for every W and offset (bit-identical, a third less work)
    ref = ReferenceTerms()
    matcher = SubsetMatcher(motion, shape, "bspline3", boundary)

    # in chunks of increasing W: nothing is computed beyond the first breakdown's chunk
    # (8 W: every offset W/2 mod 1 of a 0.25 px grid once; the W beyond the breakdown are
    # dropped below, so a shorter chunk gives the same table with less work past it)
    def one(sel: IndexArray, first: bool) -> None:
        try:
            mean_var, mis_var, _, fr = _terms(
                img,
                w[sel],
                pts,
                subset,
                matcher,
                max_shift,
                float(offs[sel[0]]),
                lam_min,
                sssig=False,  # the table has no SSSIG: one blurred image less per W
                reference=ref,
            )
        except InputError:
            if first:
                raise
            frac[sel] = 0.0  # the texture is gone along the motion: broken down
            return
        n1[sel] = mean_var[0] + mean_var[1]
        n2[sel] = mean_var[2]
        b2[sel] = mis_var
        frac[sel] = fr

    start = 0
    while start < w.size:
        chunk = np.arange(start, min(start + 8, w.size))
        # one group per offset, each writing its own W: the same table on any threads
        groups = [chunk[offs[chunk] == off] for off in np.unique(offs[chunk])]
        each(functools.partial(one, first=start == 0), groups, threads)
        if (frac[chunk] < BREAKDOWN_FRACTION).any():
            break
        start += chunk.size
    done = np.isfinite(frac)
    w, n1, n2, b2, frac = w[done], n1[done], n2[done], b2[done], frac[done]
    broken = np.nonzero(frac < BREAKDOWN_FRACTION)[0]
    breakdown = float(w[broken[0]]) if broken.size else None
    last = broken[0] if broken.size else w.size - 1
    finite = np.isfinite(n1) & np.isfinite(n2) & np.isfinite(b2)
    if not finite[last]:
        last -= 1
    if not finite[: last + 1].all() or last < 1:
        raise InputError(
            "image: the static prediction has no finite terms over the W grid below its "
            "breakdown; use a textured image or shorter blur lengths"
        )
    keep = slice(0, last + 1)
    return StaticTerms(
        blur=tuple(map(float, w[keep])),
        noise=tuple(map(float, n1[keep])),
        noise2=tuple(map(float, np.maximum(n2[keep], 0.0))),
        mismatch=tuple(map(float, b2[keep])),
        valid_fraction=tuple(map(float, frac[keep])),
        breakdown_blur=breakdown,
    )


def pattern_name(provenance: dict[str, Any]) -> str | None:
    """Pattern name for the validity domain: ``provenance["pattern"]`` or the stem of
    ``provenance["image"]`` (a path)."""
    if isinstance(provenance.get("pattern"), str):
        return str(provenance["pattern"])
    if isinstance(provenance.get("image"), str):
        return Path(provenance["image"]).stem or None
    return None
