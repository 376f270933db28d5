"""The compiled per-point pass: window sums, strains and their covariance (one home of the
strain measures and their Jacobian, docs/strain.md eq. 1, 5-8)."""

from __future__ import annotations

from typing import Any, NamedTuple

import numba as nb
import numpy as np

from ..arrays import Float64Array, Int64Array

__all__ = [
    "N_GRAD",
    "N_OUT",
    "WindowFields",
    "WindowKernels",
    "measure_pass",
    "stacked_kernels",
    "window_pass",
]

#: Values per point of :func:`measure_pass`: ``exx, eyy, exy``, the noise covariance
#: ``(xx_xx, yy_yy, xy_xy, xx_yy, xx_xy, yy_xy)`` and the signed blur errors
#: ``(b_xx, b_yy, b_xy)``.
N_OUT = 12


#: Values per point of :func:`window_pass`: the gradients ``(ux, uy, vx, vy)``, their
#: noise covariance ``(uxux, uyuy, uxuy, vxvx, vyvy, vxvy)`` and signed blur errors
#: ``(bux, buy, bvx, bvy)``.
N_GRAD = 14


class WindowFields(NamedTuple):
    """The (frames, rows, cols) fields of :func:`window_pass`."""

    u: Float64Array  # displacements, px (0 where not valid)
    v: Float64Array
    use: Int64Array  # window half-width of each point (0: no window)
    s2u: Float64Array  # noise variances, px**2
    s2v: Float64Array
    xu: Float64Array  # signed blur shifts, px (read when ``blur``)
    xv: Float64Array


class WindowKernels(NamedTuple):
    """The window weights of every half-width ``h`` = 1..H, each (H + 1, 2 H + 1, 2 H + 1),
    the window centred at index ``H``: the slope weights ``gx[h]``, ``gy[h]`` (eq. 1) and
    the noise kernels ``kxx[h]``, ``kyy[h]``, ``kxy[h]`` (eq. 5)."""

    gx: Float64Array
    gy: Float64Array
    kxx: Float64Array
    kyy: Float64Array
    kxy: Float64Array


@nb.njit(inline="always", cache=True)
def _add_gradient(acc: Float64Array, i0: int, wx: float, wy: float, a: float, b: float) -> None:
    """``acc[i0:i0 + 4] += (wx a, wy a, wx b, wy b)``: one point's share of the slopes of
    the two fields ``a`` (u) and ``b`` (v)."""
    acc[i0] += wx * a
    acc[i0 + 1] += wy * a
    acc[i0 + 2] += wx * b
    acc[i0 + 3] += wy * b


@nb.njit(inline="always", cache=True)
def _add_variance(
    acc: Float64Array, i0: int, qxx: float, qyy: float, qxy: float, s2: float
) -> None:
    """``acc[i0:i0 + 3] += (qxx, qyy, qxy) s2``: one point's share of the slopes' noise
    covariance of one field of noise variance ``s2``."""
    acc[i0] += qxx * s2
    acc[i0 + 1] += qyy * s2
    acc[i0 + 2] += qxy * s2


@nb.njit(cache=True, nogil=True)
def window_pass(fields: WindowFields, blur: bool, kern: WindowKernels, out: Float64Array) -> None:
    """Window sums of every point of the (frames, rows, cols) ``fields`` whose window
    half-width ``use`` is > 0: ``out[f, r, c, :]`` (:data:`N_GRAD` values; NaN where
    ``use`` is 0, the blur errors 0 without ``blur``). Callers give windows that lie
    inside the grid.
    """
    u, v, use, s2u, s2v, xu, xv = fields
    gx, gy, kxx, kyy, kxy = kern
    nf, ny, nx = u.shape
    hm = (gx.shape[1] - 1) // 2
    acc = np.empty(N_GRAD)
    for f in range(nf):
        for r in range(ny):
            for c in range(nx):
                h = use[f, r, c]
                o = out[f, r, c]
                if h <= 0:
                    for i in range(N_GRAD):
                        o[i] = np.nan
                    continue
                acc[:] = 0.0
                for j in range(-h, h + 1):
                    rr = r + j
                    for k in range(-h, h + 1):
                        cc = c + k
                        wx = gx[h, hm + j, hm + k]
                        wy = gy[h, hm + j, hm + k]
                        _add_gradient(acc, 0, wx, wy, u[f, rr, cc], v[f, rr, cc])
                        qxx = kxx[h, hm + j, hm + k]
                        qyy = kyy[h, hm + j, hm + k]
                        qxy = kxy[h, hm + j, hm + k]
                        _add_variance(acc, 4, qxx, qyy, qxy, s2u[f, rr, cc])
                        _add_variance(acc, 7, qxx, qyy, qxy, s2v[f, rr, cc])
                        if blur:
                            _add_gradient(acc, 10, wx, wy, xu[f, rr, cc], xv[f, rr, cc])
                o[:] = acc


@nb.njit(cache=True, nogil=True)
def measure_pass(grad: Float64Array, green: bool, out: Float64Array) -> None:
    """Strains and their covariance from the gradients of :func:`window_pass` (any
    leading shape flattened: ``grad`` (n, N_GRAD), ``out`` (n, N_OUT)): eq. 7 (the
    measure: Green-Lagrange when ``green``, else small strain) and eq. 8 (``J Sigma_g
    J^T``, ``u`` and ``v`` errors uncorrelated; the blur errors through the same ``J``)."""
    pairs = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
    for i in range(grad.shape[0]):
        g = grad[i]
        o = out[i]
        ux, uy, vx, vy = g[0], g[1], g[2], g[3]
        if green:
            o[0] = ux + 0.5 * (ux * ux + vx * vx)
            o[1] = vy + 0.5 * (uy * uy + vy * vy)
            o[2] = 0.5 * (uy + vx + ux * uy + vx * vy)
            rows = (
                (1.0 + ux, 0.0, vx, 0.0),
                (0.0, uy, 0.0, 1.0 + vy),
                (0.5 * uy, 0.5 * (1.0 + ux), 0.5 * (1.0 + vy), 0.5 * vx),
            )
        else:
            o[0] = ux
            o[1] = vy
            o[2] = 0.5 * (uy + vx)
            rows = ((1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), (0.0, 0.5, 0.5, 0.0))
        for m in range(6):
            p = rows[pairs[m][0]]
            q = rows[pairs[m][1]]
            o[3 + m] = (
                p[0] * q[0] * g[4]
                + p[1] * q[1] * g[5]
                + (p[0] * q[1] + p[1] * q[0]) * g[6]
                + p[2] * q[2] * g[7]
                + p[3] * q[3] * g[8]
                + (p[2] * q[3] + p[3] * q[2]) * g[9]
            )
        for m in range(3):
            p = rows[m]
            o[9 + m] = p[0] * g[10] + p[1] * g[11] + p[2] * g[12] + p[3] * g[13]


def stacked_kernels(half: int, step: float, subset: int) -> WindowKernels:
    """The window weights of every half-width 1..``half`` for :func:`window_pass`."""
    from .covariance import noise_kernels
    from .fit import plane_weights

    n = 2 * half + 1
    out = [np.zeros((half + 1, n, n)) for _ in range(5)]
    for h in range(1, half + 1):
        s = slice(half - h, half + h + 1)
        vals: Any = (*plane_weights(h, step), *noise_kernels(h, step, subset))
        for arr, val in zip(out, vals, strict=True):
            arr[h, s, s] = val
    return WindowKernels(*out)
