"""Prefiltered B-spline interpolation (cubic and quintic) of grey-level images.

An image is represented by the coefficients ``c`` of its interpolating B-spline of degree
``n`` (3 or 5): ``f(x) = sum_k c[k] beta_n(x - k)`` passes exactly through the pixel values.
The coefficients come from a recursive (IIR) prefilter with mirror boundaries (Unser,
Aldroubi & Eden, IEEE Trans. Signal Process. 41(2), 1993, doi:10.1109/78.193220; Unser,
IEEE Signal Process. Mag. 16(6), 1999, doi:10.1109/79.799930). Evaluating a sample needs
``(n+1)**2`` taps: (4x4 for cubic, 6x6 for quintic).

The fast prefilter lives in :mod:`dicblur.dic.kernels`; this module holds the public
helpers and the plain reference implementations the tests compare the kernels against.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike
from scipy import ndimage

from ..arrays import Float64Array, FloatArray
from ..checks import check_choice
from ..errors import InputError
from . import kernels

__all__ = [
    "INTERPOLATIONS",
    "PAD",
    "bspline_at_offset",
    "bspline_coefficients",
    "bspline_gradients",
    "bspline_kernel",
    "bspline_kernel_derivative",
    "bspline_weights",
    "interpolate_reference",
    "order_of",
    "prefilter_reference",
]

Interpolation = Literal["bspline3", "bspline5"]
INTERPOLATIONS: tuple[str, ...] = ("bspline3", "bspline5")

#: Margin (px) of mirrored coefficients around the image in padded coefficient arrays.
PAD = kernels.PAD


def order_of(interpolation: str) -> int:
    """Spline degree (3 or 5) of an interpolation name (``"bspline3"``, ``"bspline5"``)."""
    return int(check_choice(interpolation, "interpolation", INTERPOLATIONS)[-1])


def bspline_kernel(x: ArrayLike, order: int) -> Float64Array:
    """Centred B-spline ``beta_n(x)`` of degree ``order`` (closed form, reference).

    ``beta_n(x) = 1/n! sum_{j=0}^{n+1} (-1)^j C(n+1, j) max(0, x + (n+1)/2 - j)^n``.
    """
    x = np.asarray(x, dtype=np.float64)
    out = np.zeros_like(x)
    for j in range(order + 2):
        shifted = np.maximum(0.0, x + (order + 1) / 2 - j)
        out += (-1) ** j * math.comb(order + 1, j) * shifted**order
    return out / math.factorial(order)


def bspline_kernel_derivative(x: ArrayLike, order: int) -> Float64Array:
    """Derivative ``beta_n'(x) = beta_{n-1}(x + 1/2) - beta_{n-1}(x - 1/2)``."""
    x = np.asarray(x, dtype=np.float64)
    return bspline_kernel(x + 0.5, order - 1) - bspline_kernel(x - 0.5, order - 1)


def bspline_weights(t: float, order: int) -> Float64Array:
    """Weights of the ``order + 1`` taps for a sample at fractional offset ``t`` in [0, 1).

    The taps sit at integer offsets ``k = -(order-1)/2, ..., (order+1)/2`` from
    ``floor(x)``; the weight of tap ``k`` is ``beta_n(t - k)``.
    """
    ks = np.arange(-(order - 1) // 2, (order + 1) // 2 + 1)
    return bspline_kernel(t - ks, order)


def prefilter_reference(image: ArrayLike, order: int) -> Float64Array:
    """B-spline coefficients by :func:`scipy.ndimage.spline_filter` (mirror boundary).

    Plain reference for :func:`bspline_coefficients` (float64, unpadded).
    """
    return ndimage.spline_filter(np.asarray(image, dtype=np.float64), order=order, mode="mirror")


def bspline_coefficients(
    image: ArrayLike,
    *,
    order: int = 3,
    dtype: type = np.float32,
    out: FloatArray | None = None,
) -> FloatArray:
    """Padded B-spline coefficients of ``image`` (compiled recursive prefilter).

    Parameters
    ----------
    image : array_like, shape (rows, cols)
        Grey levels.
    order : {3, 5}
        Spline degree.
    dtype : {numpy.float32, numpy.float64}
        Working precision.
    out : ndarray, optional
        Array (or view) of the right shape and dtype to write into (reused buffers).

    Returns
    -------
    ndarray, shape (rows + 2*PAD, cols + 2*PAD)
        Coefficients; pixel ``(r, c)`` of the image is entry ``(r + PAD, c + PAD)``; the
        margin holds the mirror-symmetric continuation (whole-sample symmetry).
    """
    if order not in (3, 5):
        raise InputError(f"order={order}: the B-spline order must be 3 or 5 (bspline3 or bspline5)")
    img: FloatArray = np.asarray(image)
    if img.dtype not in (np.float32, np.float64):
        img = img.astype(np.float64)
    img = np.ascontiguousarray(img)
    shape = (img.shape[0] + 2 * PAD, img.shape[1] + 2 * PAD)
    if out is None:
        out = np.empty(shape, dtype=dtype)
    elif out.shape != shape or out.dtype != np.dtype(dtype):
        raise InputError(
            f"out: expected an array of shape {shape} and dtype "
            f"{np.dtype(dtype)}; pass out=None to allocate one"
        )
    kernels.prefilter_padded(img, order, out)
    return out


def bspline_gradients(
    coeffs: FloatArray, order: int, shape: tuple[int, int]
) -> tuple[Float64Array, Float64Array]:
    """Exact derivatives ``(d/drow, d/dcol)`` of the spline at the integer pixels:
    :func:`bspline_at_offset` at offset 0 without the values (``coeffs``, ``order``,
    ``shape`` as there).

    Returns
    -------
    gy, gx : ndarray, shape (rows, cols)
        Gradients in grey levels / px along rows (y) and columns (x).
    """
    _, gy, gx = bspline_at_offset(coeffs, order, shape, 0.0, 0.0, values=False)
    return gy, gx


def bspline_at_offset(
    coeffs: FloatArray,
    order: int,
    shape: tuple[int, int],
    oy: float,
    ox: float,
    *,
    values: bool = True,
) -> tuple[Float64Array | None, Float64Array, Float64Array]:
    """The spline and its exact derivatives at every pixel moved by ``(oy, ox)``.

    Parameters
    ----------
    coeffs : ndarray, shape (rows + 2*PAD, cols + 2*PAD)
        Padded coefficients from :func:`bspline_coefficients`.
    order : {3, 5}
        Spline degree.
    shape : (rows, cols)
        Image shape.
    oy, ox : float
        Offset (px, rows and columns) with ``|o| < 1``: the positions ``(r + oy, c + ox)``.
    values : bool
        Also return the spline values (else ``None`` in their place).

    Returns
    -------
    h, hy, hx : ndarray, shape (rows, cols)
        Values (grey levels) and derivatives along rows and columns (grey levels / px).
    """
    rows, cols = shape
    c = np.asarray(coeffs, dtype=np.float64)
    iy, ix = math.floor(oy), math.floor(ox)
    # separable: taps at integer offsets k from floor(position), weight beta(t - k)
    ks = range(-(order - 1) // 2, (order + 1) // 2 + 1)

    def taps(t: float) -> tuple[list[float], list[float]]:
        return (
            [float(bspline_kernel(t - k, order)) for k in ks],
            [float(bspline_kernel_derivative(t - k, order)) for k in ks],
        )

    vy, dy = taps(oy - iy)
    vx, dx = taps(ox - ix)
    r0, c0 = PAD + iy, PAD + ix
    val_r = np.zeros((rows, c.shape[1]))
    der_r = np.zeros((rows, c.shape[1]))
    for k, a, b in zip(ks, vy, dy, strict=True):
        band = c[r0 + k : r0 + k + rows, :]
        val_r += a * band
        der_r += b * band
    h = np.zeros(shape) if values else None
    gy = np.zeros(shape)
    gx = np.zeros(shape)
    for k, a, b in zip(ks, vx, dx, strict=True):
        cv = val_r[:, c0 + k : c0 + k + cols]
        if h is not None:
            h += a * cv
        gy += a * der_r[:, c0 + k : c0 + k + cols]
        gx += b * cv
    return h, gy, gx


def interpolate_reference(
    coeffs: FloatArray, y: ArrayLike, x: ArrayLike, order: int
) -> Float64Array:
    """Evaluate the spline at image positions ``(y, x)`` (px, row and column): reference.

    Plain NumPy tap loop over the closed-form kernel; positions must lie inside the padded
    margin. Used by the tests and by :func:`dicblur.dic.icgn.icgn_reference`.
    """
    c = np.asarray(coeffs, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    x = np.asarray(x, dtype=np.float64)
    iy = np.floor(y).astype(np.intp)
    ix = np.floor(x).astype(np.intp)
    ty = y - iy
    tx = x - ix
    lo = -(order - 1) // 2
    out = np.zeros(np.broadcast(y, x).shape)
    for a in range(order + 1):
        wy = bspline_kernel(ty - (lo + a), order)
        for b in range(order + 1):
            wx = bspline_kernel(tx - (lo + b), order)
            out += wy * wx * c[iy + lo + a + PAD, ix + lo + b + PAD]
    return out
