"""The compiled per-point pass: window sums, strains and their covariance (one home of the
strain measures and their Jacobian, docs/strain.md eq. 1, 5-8)."""

from __future__ import annotations

from typing import Any

import numba as nb
import numpy as np
from numpy.typing import NDArray

__all__ = ["N_GRAD", "N_OUT", "measure_pass", "stacked_kernels", "window_pass"]

#: Values per point of :func:`measure_pass`: ``exx, eyy, exy``, the noise covariance
#: ``(xx_xx, yy_yy, xy_xy, xx_yy, xx_xy, yy_xy)`` and the signed blur errors
#: ``(b_xx, b_yy, b_xy)``.
N_OUT = 12


#: Values per point of :func:`window_pass`: the gradients ``(ux, uy, vx, vy)``, their
#: noise covariance ``(uxux, uyuy, uxuy, vxvx, vyvy, vxvy)`` and signed blur errors
#: ``(bux, buy, bvx, bvy)``.
N_GRAD = 14


@nb.njit(cache=True, nogil=True)
def window_pass(
    u: NDArray[np.float64],
    v: NDArray[np.float64],
    use: NDArray[np.int64],
    s2u: NDArray[np.float64],
    s2v: NDArray[np.float64],
    xu: NDArray[np.float64],
    xv: NDArray[np.float64],
    blur: bool,
    gx: NDArray[np.float64],
    gy: NDArray[np.float64],
    kxx: NDArray[np.float64],
    kyy: NDArray[np.float64],
    kxy: NDArray[np.float64],
    out: NDArray[np.float64],
) -> None:
    """Window sums of every point of the (frames, rows, cols) fields whose window
    half-width ``use`` is > 0: ``out[f, r, c, :]`` (:data:`N_GRAD` values; NaN where
    ``use`` is 0, the blur errors 0 without ``blur``).

    ``gx[h]``, ``gy[h]``: slope weights of the window of half-width ``h`` (eq. 1);
    ``kxx[h]``, ``kyy[h]``, ``kxy[h]``: its noise kernels (eq. 5), each (H + 1, 2 H + 1,
    2 H + 1), the window centred at index ``H``. ``s2u``, ``s2v``: noise variances, px**2;
    ``xu``, ``xv``: signed blur shifts, px (read when ``blur``). Callers give windows
    that lie inside the grid.
    """
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
                        a = u[f, rr, cc]
                        b = v[f, rr, cc]
                        acc[0] += wx * a
                        acc[1] += wy * a
                        acc[2] += wx * b
                        acc[3] += wy * b
                        qxx = kxx[h, hm + j, hm + k]
                        qyy = kyy[h, hm + j, hm + k]
                        qxy = kxy[h, hm + j, hm + k]
                        su = s2u[f, rr, cc]
                        sv = s2v[f, rr, cc]
                        acc[4] += qxx * su
                        acc[5] += qyy * su
                        acc[6] += qxy * su
                        acc[7] += qxx * sv
                        acc[8] += qyy * sv
                        acc[9] += qxy * sv
                        if blur:
                            a = xu[f, rr, cc]
                            b = xv[f, rr, cc]
                            acc[10] += wx * a
                            acc[11] += wy * a
                            acc[12] += wx * b
                            acc[13] += wy * b
                o[:] = acc


@nb.njit(cache=True, nogil=True)
def measure_pass(grad: NDArray[np.float64], green: bool, out: NDArray[np.float64]) -> None:
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


def stacked_kernels(half: int, step: float, subset: int) -> tuple[NDArray[np.float64], ...]:
    """``gx, gy, kxx, kyy, kxy`` of every half-width 1..``half`` for :func:`strain_pass`,
    each (half + 1, 2 half + 1, 2 half + 1)."""
    from .covariance import noise_kernels
    from .fit import plane_weights

    n = 2 * half + 1
    out = [np.zeros((half + 1, n, n)) for _ in range(5)]
    for h in range(1, half + 1):
        s = slice(half - h, half + h + 1)
        vals: Any = (*plane_weights(h, step), *noise_kernels(h, step, subset))
        for arr, val in zip(out, vals, strict=True):
            arr[h, s, s] = val
    return tuple(out)
