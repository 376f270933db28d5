"""The blurred images: :func:`motion_blur` (the paper's Algorithm 1, exactly, with one FFT
pair), its literal loop for verification, :func:`valid_region` and :func:`render_blurred`
(the interpolation-free reference on a fine grid). Conventions in :mod:`dicblur.blur`."""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike
from scipy import fft as sfft

from ..arrays import Float64Array
from ..checks import as_image, check_choice, describe
from ..errors import InputError
from .trajectory import Trajectory, check_substeps, is_array_path, trajectory_positions
from .transfer import transfer_product

__all__ = ["motion_blur", "render_blurred", "valid_region"]

Boundary = Literal["periodic", "reflect"]
Method = Literal["fft", "loop"]


def _mirror(img: Float64Array) -> Float64Array:
    """Even (half-sample symmetric) extension to 2x size: periodic and continuous."""
    top = np.concatenate([img, img[:, ::-1]], axis=1)
    return np.concatenate([top, top[::-1, :]], axis=0)


def _loop(img: Float64Array, pos: Float64Array, w: Float64Array):
    """Literal Algorithm 1: complex FFT, one inverse FFT per sub-frame, weighted average."""
    n, m = img.shape
    spectrum = sfft.fft2(img)
    fy = np.fft.fftfreq(n)
    fx = np.fft.fftfreq(m)
    ny = n // 2 if n % 2 == 0 else None
    nx = m // 2 if m % 2 == 0 else None
    out = np.zeros_like(img)
    for (py, px), wk in zip(pos, w, strict=True):
        ey = np.exp(-2j * math.pi * fy * py)
        ex = np.exp(-2j * math.pi * fx * px)
        if ny is not None:
            ey[ny] = math.cos(math.pi * py)
        if nx is not None:
            ex[nx] = math.cos(math.pi * px)
        frame = sfft.ifft2(spectrum * np.outer(ey, ex))
        out += wk * frame.real
    return out


def motion_blur(
    image: ArrayLike,
    motion: ArrayLike | None,
    *,
    substeps: int | None = 100,
    trajectory: Trajectory = "linear",
    boundary: Boundary = "periodic",
    method: Method = "fft",
) -> Float64Array:
    """Noise-free motion-blurred image (the paper's Algorithm 1 without its noise step).

    The image content travels along a path ``p(t)``, t in [0, 1], during the exposure; the
    output is the average of the image shifted (exact Fourier shift) to K + 1 positions
    ``p(k / K)``, k = 0..K, i.e. the image translated by the mean position (``motion / 2``
    for linear motion) and blurred along the path. Add noise afterwards with
    :func:`dicblur.add_gaussian_noise` or :class:`dicblur.Camera`.

    Parameters
    ----------
    image : array_like, shape (rows, cols)
        Sharp image, grey levels.
    motion : array_like (dy, dx), px, or None
        Motion vector: for ``"linear"`` and ``"acceleration"`` the displacement during the
        exposure (blur length ``W = hypot(dy, dx)``); for ``"sine"`` the amplitude vector.
        None for an explicit path (array or callable ``trajectory``).
    substeps : int >= 1, None or "continuous"
        K (the paper: 100). None or ``"continuous"``: the exact limit K -> infinity
        (``exp(-i pi f.X) sinc(f.X)`` for linear motion; Gauss-Legendre quadrature,
        accurate to rounding for smooth paths, otherwise). Ignored by array paths, whose
        rows are the sub-frames.
    trajectory : str, SineMotion, AcceleratedMotion, array (K + 1, 2) or callable
        ``"linear"`` (uniform velocity, the paper), ``"sine"`` (``SineMotion()``: one
        cycle, zero phase), ``"acceleration"`` (``AcceleratedMotion()``: from rest), a
        preset instance, an array of K + 1 positions (dy, dx) px (equal weights), or a
        callable ``p(t)`` taking t of shape (n,) in [0, 1] and returning (n, 2) px.
    boundary : {"periodic", "reflect"}
        ``"periodic"``: Fourier shifting wraps content across the edges, exactly the
        paper. ``"reflect"``: the image is extended by even mirroring to 2x its size
        (periodic and continuous, no seam), blurred and cropped; no wrap-around, but within
        the path's extent of each edge (see :func:`valid_region`) the output averages
        mirrored content, not the unseen scene.
    method : {"fft", "loop"}
        ``"fft"``: one rfft2/irfft2 pair and the transfer function (default; for linear
        motion with ``|dy| + |dx| <= K`` a compiled kernel fuses the Dirichlet kernel with
        the spectrum product).
        ``"loop"``: literal Algorithm 1 (one complex inverse FFT per sub-frame, averaged),
        for verification; needs a finite ``substeps``.

    Returns
    -------
    ndarray of float64, shape (rows, cols)

    Raises
    ------
    InputError
        Bad image (not 2-D, NaN), motion (NaN, wrong shape), substeps (< 1, not an
        integer), unknown trajectory, boundary or method.

    Examples
    --------
    >>> import numpy as np
    >>> img = np.random.default_rng(0).random((64, 64))
    >>> out = motion_blur(img, (0.0, 3.5))
    >>> ref = motion_blur(img, (0.0, 3.5), method="loop")
    >>> bool(np.allclose(out, ref, rtol=0, atol=1e-12))
    True
    """
    img = as_image(image, "image")
    check_choice(boundary, "boundary", ("periodic", "reflect"))
    check_choice(method, "method", ("fft", "loop"))
    work = _mirror(img) if boundary == "reflect" else img
    if method == "loop":
        if check_substeps(substeps) is None and not is_array_path(trajectory):
            raise InputError(
                "method='loop' needs a finite substeps (the literal Algorithm 1 averages "
                "K + 1 sub-frames); use method='fft' for substeps=None"
            )
        pos, w = trajectory_positions(motion, substeps=substeps, trajectory=trajectory)
        out = _loop(work, pos, w)
    else:
        spectrum = sfft.rfft2(work)
        product = transfer_product(
            spectrum, work.shape, motion, substeps=substeps, trajectory=trajectory
        )
        out = sfft.irfft2(product, s=work.shape, overwrite_x=True)
    if boundary == "reflect":
        out = out[: img.shape[0], : img.shape[1]]
    return np.ascontiguousarray(out)


def valid_region(
    shape: tuple[int, int],
    motion: ArrayLike | None,
    *,
    substeps: int | None = 100,
    trajectory: Trajectory = "linear",
    guard: int = 2,
) -> tuple[slice, slice]:
    """Rows and cols of a blurred image that only saw image content (no wrap, no mirror).

    Output pixel (y, x) averages input pixels (y - p_y, x - p_x) over the path; it is
    trustworthy when every such position lies inside the image. ``guard`` extra px per
    side absorb the decaying ringing of Fourier shifting near the edge (see
    ``docs/blur.md``). Meant for ``boundary="reflect"``; with ``"periodic"`` and an image
    that is not periodic, the wrapped seam rings through the whole output.

    Returns
    -------
    (slice, slice)
        Index as ``out[rows, cols]``; empty slices when the path is longer than the image.
    """
    rows, cols = (int(s) for s in shape)
    if isinstance(guard, bool) or not isinstance(guard, int | np.integer) or guard < 0:
        raise InputError(f"guard={describe(guard)}: expected an integer >= 0 (px)")
    pos, _ = trajectory_positions(motion, substeps=substeps, trajectory=trajectory)
    lo = np.ceil(np.maximum(pos.max(axis=0), 0.0)).astype(int) + guard
    hi = np.floor(np.minimum(pos.min(axis=0), 0.0)).astype(int) - guard
    r0, c0 = int(lo[0]), int(lo[1])
    r1, c1 = rows + int(hi[0]), cols + int(hi[1])
    return slice(r0, max(r0, r1)), slice(c0, max(c0, c1))


def render_blurred(
    fine: ArrayLike,
    motion: ArrayLike | None,
    *,
    supersample: int,
    substeps: int | None = None,
    trajectory: Trajectory = "linear",
) -> Float64Array:
    """Blurred camera image rendered without interpolation (unbiased reference).

    Fourier-shifted test images can make DIC look more accurate than it is (Reu, Exp.
    Mech. 51, 2011, doi:10.1007/s11340-010-9417-4; Bornert et al., Opt. Lasers Eng. 91,
    2017).
    Here a pattern drawn on a grid ``supersample`` times finer than the camera is moved
    along the path in *whole fine pixels* (``numpy.roll``, periodic), the sub-frames are
    averaged (integration over the exposure), and the result is binned to camera pixels
    (integration over each pixel's area). Positions are rounded to the nearest fine pixel,
    so the path is reproduced to within ``1 / (2 supersample)`` px.

    Parameters
    ----------
    fine : array_like, shape (rows * supersample, cols * supersample)
        Pattern on the fine grid, grey levels; periodic (e.g. ``speckle_pattern``).
    motion, trajectory : as :func:`motion_blur` (motion in camera px).
    supersample : int >= 1
        Fine pixels per camera pixel along each axis.
    substeps : int or None
        Sub-frames K (+1). None (default): one sub-frame per fine-pixel step along the
        path (``K = ceil(4 * supersample * path length)``), the discrete analogue of the
        continuous limit.

    Returns
    -------
    ndarray of float64, shape (rows, cols)
    """
    arr = as_image(fine, "fine")
    if isinstance(supersample, bool) or not isinstance(supersample, int | np.integer):
        raise InputError(f"supersample={describe(supersample)}: expected an integer >= 1")
    ss = int(supersample)
    if ss < 1:
        raise InputError(f"supersample={ss}: must be >= 1")
    if arr.shape[0] % ss or arr.shape[1] % ss:
        raise InputError(
            f"fine={describe(arr)}: each side must be a multiple of supersample={ss} "
            "(draw the pattern at (rows * supersample, cols * supersample))"
        )
    k = check_substeps(substeps)
    if k is None and not is_array_path(trajectory):
        # Path length measured on a fine sample of the trajectory.
        probe, _ = trajectory_positions(motion, substeps=1024, trajectory=trajectory)
        length = float(np.hypot(*np.diff(probe, axis=0).T).sum())
        k = max(1, math.ceil(4 * ss * length))
    pos, w = trajectory_positions(motion, substeps=k, trajectory=trajectory)
    steps = np.rint(pos * ss).astype(np.int64)
    acc = np.zeros_like(arr)
    # Equal positions repeat: accumulate each distinct shift once with its total weight.
    uniq, inverse = np.unique(steps, axis=0, return_inverse=True)
    weights = np.bincount(inverse.ravel(), weights=w, minlength=uniq.shape[0])
    for (sy, sx), wk in zip(uniq, weights, strict=True):
        acc += wk * np.roll(arr, (int(sy), int(sx)), axis=(0, 1))
    rows, cols = arr.shape[0] // ss, arr.shape[1] // ss
    return acc.reshape(rows, ss, cols, ss).mean(axis=(1, 3))
