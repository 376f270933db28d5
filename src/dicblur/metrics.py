"""Speckle-pattern metrics (Lavatelli & Zappa 2017, eqs. 1-5).

Conventions
-----------
Images are 2-D arrays indexed ``(row, col)``; ``x`` runs along columns, ``y`` along rows.
Gradients are in grey levels per px. The default gradient is the central difference
``(f[i+1] - f[i-1]) / 2`` (as :func:`numpy.gradient` in the interior); ``"sobel"`` uses the
3x3 Sobel operator divided by 8 (so that it is a derivative in grey levels per px).
Both are defined on interior pixels only: subsets and whole-image statistics never use a
one-sided border difference.

References
----------
Pan B. et al., "Study on subset size selection in digital image correlation for speckle
patterns", Opt. Express 16 (2008) 7037, doi:10.1364/OE.16.007037 (SSSIG, eq. 2).
Pan B. et al., "Mean intensity gradient: An effective global parameter for quality
assessment of the speckle patterns used in DIC", Opt. Lasers Eng. 48 (2010) 469,
doi:10.1016/j.optlaseng.2009.08.010 (MIG, eqs. 4-5).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike
from scipy import ndimage

from .arrays import Float64Array, IndexArray
from .checks import (
    as_image,
    check_choice,
    check_odd_subset,
    check_positive,
    check_subset_fits,
    check_textured,
    describe,
)
from .errors import InputError

__all__ = [
    "PatternMetrics",
    "box_sssig",
    "directional_sssig",
    "estimate_noise",
    "gradient_variance",
    "image_gradients",
    "match_score_sigma",
    "michelson_contrast",
    "mig",
    "pan_sigma",
    "pattern_metrics",
    "resolve_points",
    "rms_contrast",
    "speckle_size",
    "sssig",
    "subset_centres",
]

Gradient = Literal["central", "sobel"]
_GRADIENTS = ("central", "sobel")


def image_gradients(
    image: ArrayLike, *, gradient: Gradient = "central"
) -> tuple[Float64Array, Float64Array]:
    """Intensity gradients ``(df/dy, df/dx)`` (grey levels / px), in (row, col) order.

    Parameters
    ----------
    image : array_like, shape (rows, cols)
    gradient : {"central", "sobel"}
        Central difference ``(f[i+1] - f[i-1]) / 2`` or Sobel / 8.

    Returns
    -------
    gy, gx : ndarray, shape (rows, cols)
        Derivatives along rows (y) and columns (x). Border pixels (first and last row and
        column) are set to 0: they have no central difference.
    """
    img = as_image(image, "image", min_size=3)
    check_choice(gradient, "gradient", _GRADIENTS)
    gy = np.zeros_like(img)
    gx = np.zeros_like(img)
    if gradient == "central":
        gy[1:-1, :] = 0.5 * (img[2:, :] - img[:-2, :])
        gx[:, 1:-1] = 0.5 * (img[:, 2:] - img[:, :-2])
    else:
        gy = ndimage.sobel(img, axis=0, mode="nearest") / 8.0
        gx = ndimage.sobel(img, axis=1, mode="nearest") / 8.0
    for g in (gy, gx):
        g[0, :] = g[-1, :] = 0.0
        g[:, 0] = g[:, -1] = 0.0
    return gy, gx


def subset_centres(shape: tuple[int, int], *, subset: int, step: int) -> IndexArray:
    """Centres ``(row, col)`` of a regular grid of square subsets inside an image.

    The first centre is at ``(h + 1, h + 1)`` with ``h = subset // 2`` (so that every
    subset pixel has a central-difference gradient), then every ``step`` px while the
    subset stays one pixel away from the border.

    Returns
    -------
    ndarray of int, shape (n, 2)
        Row-major list of (row, col) centres.
    """
    subset = check_odd_subset(subset)
    if isinstance(step, bool) or not isinstance(step, int | np.integer) or step < 1:
        raise InputError(f"step={describe(step)}: must be a positive integer (px)")
    h = subset // 2
    rows, cols = shape
    r = np.arange(h + 1, rows - h - 1, int(step))
    c = np.arange(h + 1, cols - h - 1, int(step))
    if r.size == 0 or c.size == 0:
        check_subset_fits(subset, (rows, cols))
    rr, cc = np.meshgrid(r, c, indexing="ij")
    return np.stack([rr.ravel(), cc.ravel()], axis=1)


def _box_sums(values: Float64Array, centres: IndexArray, subset: int) -> Float64Array:
    """Sum of ``values`` over each square subset (summed-area table, O(1) per subset)."""
    sat = np.zeros((values.shape[0] + 1, values.shape[1] + 1))
    sat[1:, 1:] = values.cumsum(axis=0).cumsum(axis=1)
    h = subset // 2
    r0 = centres[:, 0] - h
    c0 = centres[:, 1] - h
    r1 = centres[:, 0] + h + 1
    c1 = centres[:, 1] + h + 1
    return sat[r1, c1] - sat[r0, c1] - sat[r1, c0] + sat[r0, c0]


def resolve_points(
    shape: tuple[int, int], subset: int, step: int | None, points: ArrayLike | None
) -> IndexArray:
    """Subset centres ``(row, col)``, shape (n, 2): the grid of ``step`` px (default
    ``subset``, see :func:`subset_centres`) or the given ``points``, each checked to keep
    its subset one pixel inside an image of ``shape``."""
    if points is not None and step is not None:
        raise InputError("step and points: give one of them, not both")
    if points is None:
        return subset_centres(shape, subset=subset, step=subset if step is None else step)
    pts = np.asarray(points)
    if pts.ndim == 1 and pts.size == 2:
        pts = pts[None, :]
    if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] == 0:
        raise InputError(f"points={describe(pts)}: expected an (n, 2) array of (row, col)")
    if not np.all(np.isfinite(pts)) or not np.all(pts == np.round(pts)):
        raise InputError("points: subset centres must be integer (row, col) pixel positions")
    pts = pts.astype(np.intp)
    h = subset // 2
    rows, cols = shape
    inside = (
        (pts[:, 0] - h >= 1)
        & (pts[:, 0] + h <= rows - 2)
        & (pts[:, 1] - h >= 1)
        & (pts[:, 1] + h <= cols - 2)
    )
    if not inside.all():
        bad = pts[~inside][0]
        raise InputError(
            f"points: the subset of size {subset} centred at (row, col) = "
            f"({bad[0]}, {bad[1]}) leaves the image interior ({rows}x{cols}, 1-px border)"
        )
    return pts


def sssig(
    image: ArrayLike,
    *,
    subset: int,
    step: int | None = None,
    points: ArrayLike | None = None,
    direction: Literal["x", "y"] = "x",
    gradient: Gradient = "central",
) -> Float64Array:
    """Sum of square of subset intensity gradients (SSSIG), paper eq. 1 / Pan et al. 2008.

    ``SSSIG_x = sum over the subset of (df/dx)**2``, in grey levels**2 / px**2 summed over
    ``subset**2`` pixels. Motion along x is governed by ``SSSIG_x``.

    Parameters
    ----------
    image : array_like, shape (rows, cols)
    subset : int
        Odd subset size (px).
    step : int, optional
        Grid spacing of subset centres (px), see :func:`subset_centres`. Default: ``subset``
        (non-overlapping subsets).
    points : array_like of int, shape (n, 2), optional
        Explicit (row, col) centres instead of a grid.
    direction : {"x", "y"}
        Derivative along columns (x) or rows (y).
    gradient : {"central", "sobel"}
        Gradient operator; the default is the central difference.

    Returns
    -------
    ndarray of float64, shape (n,)
        SSSIG of each subset, in the order of the centres.
    """
    img = as_image(image, "image", min_size=3)
    subset = check_odd_subset(subset)
    check_subset_fits(subset, img.shape)
    check_choice(direction, "direction", ("x", "y"))
    gy, gx = image_gradients(img, gradient=gradient)
    g = gx if direction == "x" else gy
    pts = resolve_points(img.shape, subset, step, points)
    return _box_sums(g * g, pts, subset)


def mig(image: ArrayLike, *, gradient: Gradient = "central") -> float:
    """Mean intensity gradient (paper eq. 4, Pan et al. 2010), grey levels / px.

    ``MIG = mean over interior pixels of sqrt(fx**2 + fy**2)``.
    """
    gy, gx = image_gradients(image, gradient=gradient)
    mag = np.hypot(gx[1:-1, 1:-1], gy[1:-1, 1:-1])
    return float(mag.mean())


def gradient_variance(
    image: ArrayLike,
    *,
    direction: Literal["x", "y"] | None = None,
    gradient: Gradient = "central",
) -> float:
    """Variance of the intensity gradient over interior pixels ((grey levels / px)**2).

    With ``direction=None``, the variance of the gradient magnitude
    ``mean(|grad f|**2) - MIG**2``: Pan's approximation ``SSSIG ~= N**2 MIG**2`` is exact
    only when it is 0. With ``"x"`` or ``"y"``, the variance of that directional derivative
    (the quantity of the 1-D analysis, paper Section V).
    """
    gy, gx = image_gradients(image, gradient=gradient)
    gy, gx = gy[1:-1, 1:-1], gx[1:-1, 1:-1]
    if direction is None:
        return float(np.var(np.hypot(gx, gy)))
    check_choice(direction, "direction", ("x", "y"))
    return float(np.var(gx if direction == "x" else gy))


def _half_width(profile: Float64Array) -> float:
    """First lag at which a decreasing profile (profile[0] == 1) crosses 1/2, interpolated."""
    below = np.nonzero(profile <= 0.5)[0]
    if below.size == 0:
        return math.nan
    k = int(below[0])
    a, b = profile[k - 1], profile[k]
    return (k - 1) + (a - 0.5) / (a - b)


def speckle_size(image: ArrayLike) -> float:
    """Mean speckle diameter (px) from the autocorrelation.

    Definition: ``D = 2 r_half`` where ``r_half`` is the lag at which the normalised
    autocovariance (mean removed, divided by the variance) falls to 1/2, linearly
    interpolated between integer lags and averaged over the row and column axes. The
    autocovariance is estimated without wrap-around (zero padding, each lag divided by its
    number of overlapping pixels). For a thresholded pattern with black fraction 1/2 this
    is the width at half height of the autocorrelation peak; for isolated hard disks of
    diameter d it gives about 0.81 d.

    Raises
    ------
    InputError
        If the image is constant or its autocorrelation never falls to 1/2 (speckles
        larger than half the image).
    """
    img = as_image(image, "image", min_size=4)
    f = img - img.mean()
    var = float(np.mean(f * f))
    if var <= 0:
        raise InputError(f"image={describe(img)}: constant image, no speckle to measure")
    rows, cols = f.shape
    spec = np.fft.rfft2(f, s=(2 * rows, 2 * cols))
    acf = np.fft.irfft2(spec * np.conj(spec), s=(2 * rows, 2 * cols))
    along_rows = acf[: rows // 2, 0] / (rows - np.arange(rows // 2)) / cols
    along_cols = acf[0, : cols // 2] / (cols - np.arange(cols // 2)) / rows
    r_y = _half_width(along_rows / var)
    r_x = _half_width(along_cols / var)
    if not (math.isfinite(r_x) and math.isfinite(r_y)):
        raise InputError(
            f"image={describe(img)}: the autocorrelation does not fall to 1/2 within half the "
            "image; speckles are too large for this image size"
        )
    return float(r_x + r_y)


def michelson_contrast(image: ArrayLike, *, percentile: float = 0.5) -> float:
    """Michelson contrast ``(I_hi - I_lo) / (I_hi + I_lo)``.

    ``I_lo`` and ``I_hi`` are the ``percentile`` and ``100 - percentile`` percentiles of the
    grey levels (default 0.5 %: robust to a few noisy pixels); ``percentile=0`` uses the
    plain minimum and maximum.
    """
    img = as_image(image, "image", min_size=1)
    p = float(percentile)
    if not 0.0 <= p < 50.0:
        raise InputError(f"percentile={percentile!r}: must be in [0, 50)")
    lo, hi = np.percentile(img, [p, 100.0 - p])
    if hi + lo <= 0:
        raise InputError("image: Michelson contrast is undefined when I_hi + I_lo <= 0")
    return float((hi - lo) / (hi + lo))


def rms_contrast(image: ArrayLike) -> float:
    """RMS contrast: standard deviation of the grey levels divided by their mean."""
    img = as_image(image, "image", min_size=1)
    m = float(img.mean())
    if m <= 0:
        raise InputError("image: RMS contrast is undefined for a non-positive mean level")
    return float(img.std() / m)


def match_score_sigma(sssig_values: ArrayLike, noise_sigma: float) -> Float64Array:
    """Static random error of the match-score model (paper eq. 2), px.

    ``u_e = sqrt(2 sigma**2 / SSSIG)`` for Gaussian noise of std ``noise_sigma`` (grey
    levels) in both images. Vectorised over ``sssig_values``; 0 SSSIG gives ``inf``.

    Examples
    --------
    >>> match_score_sigma([8.0, 32.0, 0.0], 2.0).tolist()
    [1.0, 0.5, inf]
    """
    s = np.asarray(sssig_values, dtype=np.float64)
    sigma = check_positive(noise_sigma, "noise_sigma", allow_zero=True)
    if np.any(s < 0) or not np.all(np.isfinite(s)):
        raise InputError("sssig_values: must be finite and >= 0")
    with np.errstate(divide="ignore"):
        return np.sqrt(2.0 * sigma**2 / s)


def pan_sigma(mig_value: ArrayLike, noise_sigma: float, subset: int) -> Float64Array:
    """Pan's MIG-based estimate of the random error (paper eq. 5), px.

    ``u_e ~= sqrt(2) sigma / (N MIG)``, from ``SSSIG ~= N**2 MIG**2`` (N = subset size).
    """
    m = np.asarray(mig_value, dtype=np.float64)
    sigma = check_positive(noise_sigma, "noise_sigma", allow_zero=True)
    n = check_odd_subset(subset)
    if np.any(m <= 0) or not np.all(np.isfinite(m)):
        raise InputError("mig_value: must be finite and > 0")
    return np.asarray(math.sqrt(2.0) * sigma / (n * m))


def estimate_noise(image_a: ArrayLike, image_b: ArrayLike) -> float:
    """Noise standard deviation (grey levels) from two images of the same static scene.

    With independent noise of equal std ``sigma`` in both images, ``a - b`` has std
    ``sqrt(2) sigma``; a global offset between the two (flicker) is removed first.
    """
    a = as_image(image_a, "image_a")
    b = as_image(image_b, "image_b")
    if a.shape != b.shape:
        raise InputError(
            f"image_b: shape {b.shape} differs from image_a {a.shape}; "
            "both images must show the same field of view"
        )
    d = a - b
    return float(np.std(d - d.mean()) / math.sqrt(2.0))


@dataclass(frozen=True)
class PatternMetrics:
    """Scalar metrics of a speckle pattern (see :func:`pattern_metrics`).

    Gradients in grey levels / px, SSSIG in (grey levels / px)**2 summed over a subset,
    sizes in px, predictions in px. Prediction fields are ``None`` without a noise level.
    Image measurements only: the blur sensitivity ``c`` of the pattern is a model quantity
    (it needs the matcher's interpolant), :func:`dicblur.models.blur_sensitivity`.
    """

    shape: tuple[int, int]
    subset: int
    n_subsets: int
    mean_level: float
    michelson_contrast: float
    rms_contrast: float
    mig: float
    gradient_variance: float
    speckle_size: float
    sssig_x_mean: float
    sssig_x_std: float
    sssig_y_mean: float
    sssig_y_std: float
    pan_sssig: float
    noise_sigma: float | None = None
    match_score_x_mean: float | None = None
    match_score_x_std: float | None = None
    match_score_y_mean: float | None = None
    pan_u: float | None = None
    pan_over_match_score: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict of every field."""
        d = asdict(self)
        d["shape"] = list(self.shape)
        return d


def pattern_metrics(
    image: ArrayLike,
    *,
    subset: int,
    noise_sigma: float | None = None,
    step: int | None = None,
    gradient: Gradient = "central",
) -> PatternMetrics:
    """All pattern metrics of an image as one value.

    Parameters
    ----------
    image : array_like, shape (rows, cols)
        Grey levels.
    subset : int
        Odd subset size (px) for SSSIG and the static predictions.
    noise_sigma : float, optional
        Image noise std (grey levels). When given, the match-score prediction (eq. 2, per
        subset, mean and spread over subsets) and Pan's (eq. 5) are added, with their ratio:
        the paper's Fig. 2 discrepancy, ``sqrt(mean SSSIG_x... )`` aside, it measures how far
        ``N**2 MIG**2`` is from the subsets' own SSSIG.
    step : int, optional
        Grid step of the subsets (default: ``subset``, non-overlapping).
    gradient : {"central", "sobel"}

    Returns
    -------
    PatternMetrics
    """
    img = as_image(image, "image", min_size=3)
    subset = check_odd_subset(subset)
    if noise_sigma is not None:
        check_positive(noise_sigma, "noise_sigma")  # the options first, then the content
    check_textured(img)
    sx = sssig(img, subset=subset, step=step, direction="x", gradient=gradient)
    sy = sssig(img, subset=subset, step=step, direction="y", gradient=gradient)
    m = mig(img, gradient=gradient)
    try:
        size = speckle_size(img)
    except InputError:
        size = math.nan
    mean_level = float(img.mean())
    fields: dict[str, Any] = {
        "shape": (int(img.shape[0]), int(img.shape[1])),
        "subset": subset,
        "n_subsets": int(sx.size),
        "mean_level": mean_level,
        "michelson_contrast": michelson_contrast(img) if mean_level > 0 else math.nan,
        "rms_contrast": rms_contrast(img) if mean_level > 0 else math.nan,
        "mig": m,
        "gradient_variance": gradient_variance(img, gradient=gradient),
        "speckle_size": size,
        "sssig_x_mean": float(sx.mean()),
        "sssig_x_std": float(sx.std()),
        "sssig_y_mean": float(sy.mean()),
        "sssig_y_std": float(sy.std()),
        "pan_sssig": float(subset**2 * m**2),
    }
    if noise_sigma is not None:
        sigma = check_positive(noise_sigma, "noise_sigma")
        ux = match_score_sigma(sx, sigma)
        uy = match_score_sigma(sy, sigma)
        finite_x = ux[np.isfinite(ux)]
        pan_u = float(pan_sigma(m, sigma, subset)) if m > 0 else math.inf
        ms = float(finite_x.mean()) if finite_x.size else math.inf
        fields.update(
            noise_sigma=sigma,
            match_score_x_mean=ms,
            match_score_x_std=float(finite_x.std()) if finite_x.size else math.nan,
            match_score_y_mean=float(uy[np.isfinite(uy)].mean())
            if np.isfinite(uy).any()
            else math.inf,
            pan_u=pan_u,
            pan_over_match_score=pan_u / ms if ms > 0 and math.isfinite(ms) else math.nan,
        )
    return PatternMetrics(**fields)


def directional_sssig(
    image: Float64Array, points: IndexArray, *, subset: int, angle: float
) -> Float64Array:
    """SSSIG along a direction: sum over each subset of ``(cos a f_x + sin a f_y)**2``.

    Central-difference gradients as :func:`dicblur.image_gradients`; ``angle = 0`` is
    :func:`dicblur.sssig` with ``direction="x"``, 90 with ``"y"``.

    Parameters
    ----------
    image : ndarray, shape (rows, cols)
    points : ndarray of int, shape (n, 2)
        Subset centres (row, col).
    subset : int
        Odd subset size, px.
    angle : float
        Degrees from +x (columns) towards +y (rows).

    Returns
    -------
    ndarray, shape (n,)
        (grey levels / px)**2 summed over the subset.
    """
    gy, gx = image_gradients(image)
    return box_sssig(gy, gx, points, subset=subset, angle=angle)


def box_sssig(
    gy: Float64Array,
    gx: Float64Array,
    points: IndexArray,
    *,
    subset: int,
    angle: float,
) -> Float64Array:
    """:func:`directional_sssig` from given gradient images (summed-area table)."""
    a = math.radians(angle)
    g = math.cos(a) * gx + math.sin(a) * gy
    return _box_sums(g * g, points, subset)
