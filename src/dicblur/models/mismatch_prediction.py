"""The blur-mismatch term predicted from a static image (no DIC run, no fit).

With a sharp reference and a blurred current image, IC-GN stops at a pattern-dependent
shift ``xi_i(W)`` of each subset; its spread over the subsets is the noise-free term of
the noise + blur-mismatch model (:mod:`dicblur.models.mismatch`, docs/models.md s. 4).
Two predictions of it from the sharp image alone:

- :func:`blur_sensitivity`: the leading order ``u_blur ~= c W**2``, the model's ``c``
  (paper-brief s. 10);
- :func:`blur_mismatch_curve`: ``u_blur(W)`` at every order of the blur, the matcher's
  fixed point against the exactly box-blurred image.

The subset-level formulas are in :mod:`dicblur.models.sensitivity`; the noise term is
added by :func:`~dicblur.models.predict_from_pattern` (:mod:`dicblur.models.pattern`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..arrays import Float64Array, IndexArray
from ..checks import as_blur, as_image, check_odd_subset, check_positive, check_subpixel
from ..errors import InputError
from ..metrics import resolve_points
from .derivatives import Boundary, Derivative, unit_direction
from .sensitivity import subset_blur_coefficients, subset_blur_shifts
from .subset_algebra import Criterion, Shape, SubsetMatcher

__all__ = [
    "BlurMismatchCurve",
    "BlurSensitivity",
    "blur_mismatch_curve",
    "blur_sensitivity",
    "subset_inputs",
]


def subset_inputs(
    image: ArrayLike,
    subset: int,
    step: int | None,
    points: ArrayLike | None,
    boundary: str = "reflect",
) -> tuple[Float64Array, int, IndexArray]:
    """Checked image, subset size and subset centres (row, col) of the static predictions."""
    img = as_image(image, "image", min_size=5)
    subset = check_odd_subset(subset)
    if boundary not in ("reflect", "periodic"):
        raise InputError(f"boundary={boundary!r}: choose 'reflect' or 'periodic'")
    return img, subset, resolve_points(img.shape, subset, step, points)


@dataclass(frozen=True)
class BlurSensitivity:
    """Predicted blur sensitivity of a pattern (from the static image alone).

    Attributes
    ----------
    c : float
        Field statistic ``std_i(k_i)`` (px / px**2): ``u_blur(W) ~= c W**2``.
    mean : float
        ``mean_i(k_i)``: a common shift, which DIC sees as a rigid offset (~0).
    k : ndarray, shape (n,)
        Per-subset coefficients ``xi_i / W**2`` along the motion (NaN: no gradient).
    centres : ndarray of int, shape (n, 2)
        Subset centres (row, col).
    subset : int
    motion : tuple of float
        Unit motion direction (dy, dx).
    shape : str
        ``"translation"`` or ``"affine"``.
    """

    c: float
    mean: float
    k: Float64Array
    centres: IndexArray
    subset: int
    motion: tuple[float, float]
    shape: str

    def u_blur(self, blur: ArrayLike) -> Float64Array:
        """Predicted mismatch uncertainty ``c W**2`` (px) at blur lengths ``blur`` (px)."""
        w = np.asarray(blur, dtype=np.float64)
        return self.c * w * w


def blur_sensitivity(
    image: ArrayLike,
    *,
    subset: int,
    step: int | None = None,
    points: ArrayLike | None = None,
    motion: tuple[float, float] = (0.0, 1.0),
    shape: Shape = "translation",
    derivative: Derivative = "bspline3",
    boundary: Boundary = "reflect",
    criterion: Criterion = "znssd",
) -> BlurSensitivity:
    """Predict the blur-mismatch coefficient ``c`` of a pattern from the static image.

    Per subset ``i``, ``k_i = -(1/24) e_d . [(J^T P J)^-1 J^T P f_dd]_centre`` with ``J`` the
    steepest-descent images of the shape function (built from the matcher's spline
    gradients), ``P`` the ZNSSD projection off the intensity offset and scale, and ``f_dd``
    the second derivative along the motion (docs/models.md derives both the translation and
    the affine form). For motion along x, SSD, spectral derivatives and a translation shape
    without gradient coupling this is ``-sum(f_x f_xx) / (24 sum(f_x**2))`` (paper-brief
    s. 10). The leading order holds while ``W`` is below about the speckle size;
    :func:`blur_mismatch_curve` keeps every order.

    Parameters
    ----------
    image : array_like, shape (rows, cols)
        Sharp reference image, grey levels.
    subset : int
        Odd subset size, px.
    step : int, optional
        Subset grid step (px, default ``subset``); or give ``points`` (n, 2) (row, col).
    motion : (dy, dx)
        Motion direction (px; only the direction matters).
    shape : {"translation", "affine"}
        Shape function of the DIC matcher.
    derivative : {"bspline3", "bspline5", "spectral", "central"}
        Gradient operator of the matcher: the derivative of its cubic (default, the DIC
        engine's ``interpolation="bspline3"``) or quintic B-spline, true (spectral)
        derivatives, or central differences. The blur term itself is always the image's.
    boundary : {"reflect", "periodic"}
        Image extension for spectral derivatives (periodic for tiling synthetic patterns).
    criterion : {"znssd", "ssd"}
        Matching criterion (the engine's ZNSSD by default).

    Returns
    -------
    BlurSensitivity
    """
    img, subset, pts = subset_inputs(image, subset, step, points, boundary)
    matcher = SubsetMatcher(motion, shape, derivative, boundary)
    k = subset_blur_coefficients(img, pts, subset, matcher, criterion=criterion)
    good = k[np.isfinite(k)]
    if good.size < 2:
        raise InputError(
            "image: fewer than two subsets have an intensity gradient; the blur sensitivity "
            "is undefined (use a textured image or a larger area)"
        )
    if float(good.std()) <= 1e-9 * float(np.max(np.abs(good))):
        # c is the spread of the subsets' responses: zero means no random texture, not a
        # pattern immune to blur
        raise InputError(
            f"image: all {good.size} subsets respond identically to blur (c = 0); the image "
            "has no random texture (flat, or periodic with the subset grid); use a speckle "
            "image"
        )
    return BlurSensitivity(
        c=float(good.std()),
        mean=float(good.mean()),
        k=k,
        centres=pts,
        subset=subset,
        motion=unit_direction(motion),
        shape=str(shape),
    )


@dataclass(frozen=True)
class BlurMismatchCurve:
    """Predicted blur-mismatch error at finite blur lengths (static image, every order in W).

    Attributes
    ----------
    blur : ndarray, shape (m,)
        Blur lengths W (px).
    u_blur : ndarray, shape (m,)
        Field statistic ``std_i(xi_i(W))`` (px): the noise-free part of u_e.
    mean : ndarray, shape (m,)
        ``mean_i(xi_i(W))`` (px): a common shift, which DIC sees as a rigid offset.
    valid_fraction : ndarray, shape (m,)
        Fraction of the subsets in the statistics at each W (the others have no gradient
        or break down, as non-converged DIC points would).
    shifts : ndarray, shape (m, n)
        Per-subset shift ``xi_i(W)`` along the motion (px; NaN: no gradient or breakdown).
    centres : ndarray of int, shape (n, 2)
        Subset centres (row, col).
    subset : int
    motion : tuple of float
        Unit motion direction (dy, dx).
    shape : str
        ``"translation"`` or ``"affine"``.
    """

    blur: Float64Array
    u_blur: Float64Array
    mean: Float64Array
    valid_fraction: Float64Array
    shifts: Float64Array
    centres: IndexArray
    subset: int
    motion: tuple[float, float]
    shape: str


def blur_mismatch_curve(
    image: ArrayLike,
    blur: ArrayLike,
    *,
    subset: int,
    step: int | None = None,
    points: ArrayLike | None = None,
    motion: tuple[float, float] = (0.0, 1.0),
    shape: Shape = "translation",
    derivative: Derivative = "bspline3",
    boundary: Boundary = "reflect",
    criterion: Criterion = "znssd",
    max_shift: float = 1.0,
    subpixel: float | None = None,
) -> BlurMismatchCurve:
    """Predict the blur-mismatch error ``u_blur(W)`` of a pattern at finite ``W``.

    Where :func:`blur_sensitivity` gives the leading order ``c W**2``, this keeps every
    order of the blur: for each subset the matcher's fixed point against the exactly
    (spectrally) box-blurred image, linearised in the shift only (docs/models.md s. 4).
    It needs no DIC run and no noise; noise-free IC-GN agrees within a few per cent up to
    W of about the speckle size and beyond (BENCHMARKS.md, models section).

    Parameters
    ----------
    image : array_like, shape (rows, cols)
        Sharp reference image, grey levels.
    blur : array_like, shape (m,)
        Blur lengths W (px, >= 0, any order).
    subset, step, points, motion, shape, derivative, boundary, criterion
        As for :func:`blur_sensitivity`.
    max_shift : float
        Breakdown threshold (px): subsets whose linearised shift is longer are left out
        of the statistics at that W (``valid_fraction`` says how many remain).
    subpixel : float, optional
        Sub-pixel position (px along the motion, e.g. 0.5) of the moving target: the
        blurred image is matched through the B-spline interpolant, so ``u_blur`` also
        carries the matcher's interpolation bias there (the floor ``u_0`` and the cross
        term ``b W`` of the mismatch model; docs/models.md s. 4). Noise-free IC-GN agrees
        within 1-2.5 % in variance at W = 0..2 px (BENCHMARKS.md). Default: exactly
        aligned, the blur mismatch alone.

    Returns
    -------
    BlurMismatchCurve
    """
    img, subset, pts = subset_inputs(image, subset, step, points, boundary)
    w = as_blur(blur, "blur", increasing=False)
    max_shift = check_positive(max_shift, "max_shift")
    offset = None if subpixel is None else check_subpixel(subpixel)
    matcher = SubsetMatcher(motion, shape, derivative, boundary)
    xi = subset_blur_shifts(
        img, w, pts, subset, matcher, criterion=criterion, max_shift=max_shift, offset=offset
    )
    good = np.isfinite(xi)
    count = good.sum(axis=1)
    if np.any(count < 2):
        j = int(np.argmax(count < 2))
        raise InputError(
            f"image: fewer than two subsets have an intensity gradient at W = {w[j]:g} px "
            "(flat, or erased by the blur); the blur mismatch is undefined there (use a "
            "textured image, a larger area or shorter blur lengths)"
        )
    with np.errstate(invalid="ignore"):
        u_blur = np.nanstd(xi, axis=1)
        mean = np.nanmean(xi, axis=1)
    return BlurMismatchCurve(
        blur=w,
        u_blur=u_blur,
        mean=mean,
        valid_fraction=count / xi.shape[1],
        shifts=xi,
        centres=pts,
        subset=subset,
        motion=unit_direction(motion),
        shape=str(shape),
    )
