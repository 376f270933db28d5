"""The normalised median test for spurious displacement vectors.

Westerweel & Scarano, "Universal outlier detection for PIV data", Exp. Fluids 39, 1096-1100
(2005), doi:10.1007/s00348-005-0016-6: for each vector and each component, with ``u_m`` the
median of its 8 neighbours and ``r_m`` the median of the neighbours' residuals
``|u_i - u_m|``, the normalised residual is ``r_0 = |u_0 - u_m| / (r_m + eps)``; ``eps``
(0.1 px, the paper's value for the noise level of sub-pixel estimates) keeps the test sane in
uniform flows, and ``r_0 > 2`` marks an outlier.
"""

from __future__ import annotations

import numba as nb
import numpy as np
from numpy.typing import ArrayLike

from ..arrays import BoolArray, Float32Array, Float64Array, IndexArray
from ..errors import InputError

__all__ = [
    "median_critical_eps",
    "median_test_frames",
    "normalized_median_test",
    "normalized_residual",
]


def _neighbours(a: Float64Array) -> Float64Array:
    """The 8 neighbours of every grid node of ``a`` (..., rows, cols), shape
    (8, ..., rows, cols); NaN outside the grid."""
    rows, cols = a.shape[-2:]
    pad = [(0, 0)] * (a.ndim - 2) + [(1, 1), (1, 1)]
    p = np.pad(a, pad, constant_values=np.nan)
    out = np.empty((8, *a.shape))
    i = 0
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            if (dr, dc) != (0, 0):
                out[i] = p[..., 1 + dr : 1 + dr + rows, 1 + dc : 1 + dc + cols]
                i += 1
    return out


# Batcher's odd-even merge sort of 8 values: 19 compare-exchanges, vectorised over points
_NETWORK_8 = (
    (0, 1), (2, 3), (4, 5), (6, 7), (0, 2), (1, 3), (4, 6), (5, 7), (1, 2), (5, 6),
    (0, 4), (3, 7), (1, 5), (2, 6), (1, 4), (3, 6), (2, 4), (3, 5), (3, 4),
)  # fmt: skip


def _nanmedian8(x: Float64Array) -> tuple[Float64Array, IndexArray]:
    """Median over the first axis (8 values) ignoring NaN (NaN where all are), and the
    count of finite values: the middle of the sorted finite values, as ``np.nanmedian``
    (the same numbers), through a sorting network with NaN as +inf."""
    count = np.isfinite(x).sum(axis=0)
    s = np.where(np.isnan(x), np.inf, x)
    for i, j in _NETWORK_8:
        lo = np.minimum(s[i], s[j])
        np.maximum(s[i], s[j], out=s[j])
        s[i] = lo
    lo_i = np.maximum((count - 1) // 2, 0)
    hi_i = np.minimum(count // 2, 7)
    lo_v = np.take_along_axis(s, lo_i[None], axis=0)[0]
    hi_v = np.take_along_axis(s, hi_i[None], axis=0)[0]
    with np.errstate(invalid="ignore"):
        med = np.where(count > 0, (lo_v + hi_v) / 2, np.nan)
    return med, count


def _residuals(a: Float64Array, eps: Float64Array | float, min_neighbours: int) -> Float64Array:
    """``r_0`` of grids ``a`` (..., rows, cols); ``eps`` broadcast against the leading axes."""
    nb = _neighbours(a)
    med, count = _nanmedian8(nb)
    with np.errstate(invalid="ignore"):
        rm, _ = _nanmedian8(np.abs(nb - med[None]))
        r0 = np.abs(a - med) / (rm + eps)
    r0[(count < min_neighbours) | ~np.isfinite(a)] = np.nan
    return r0


def normalized_residual(
    values: ArrayLike, grid_shape: tuple[int, int], *, eps: float = 0.1, min_neighbours: int = 3
) -> Float64Array:
    """Normalised residual ``r_0`` of one displacement component on a grid.

    Parameters
    ----------
    values : array_like, shape (rows * cols,)
        One component (px) on the POI grid in row-major order; NaN = no vector.
    grid_shape : (rows, cols)
    eps : float
        Noise level of the estimates, px.
    min_neighbours : int
        Fewer valid neighbours: residual NaN (not testable).

    Returns
    -------
    ndarray, shape (rows * cols,)
    """
    a = np.asarray(values, dtype=np.float64).reshape(grid_shape)
    return _residuals(a, eps, min_neighbours).ravel()


def median_test_frames(
    u: Float64Array,
    v: Float64Array,
    grid_shape: tuple[int, int],
    *,
    eps: ArrayLike,
    threshold: float = 2.0,
    block: int = 64,
) -> BoolArray:
    """:func:`normalized_median_test` of every frame at once.

    Parameters
    ----------
    u, v : ndarray, shape (frames, rows * cols)
        Displacements (px) on the POI grid, NaN = no vector.
    grid_shape : (rows, cols)
    eps : array_like, shape (frames,) or scalar
        Noise level of each frame's estimates, px (> 0).
    threshold : float
    block : int
        Frames per pass (bounded temporaries: 8 neighbours x 8 bytes per point and frame).

    Returns
    -------
    ndarray of bool, shape (frames, rows * cols)
    """
    rows, cols = (int(grid_shape[0]), int(grid_shape[1]))
    n_f = u.shape[0]
    e = np.broadcast_to(np.asarray(eps, dtype=np.float64), (n_f,))
    out = np.zeros(u.shape, bool)
    for a in range(0, n_f, block):
        b = slice(a, a + block)
        eb = e[b][:, None, None]
        ru = _residuals(np.asarray(u[b], np.float64).reshape(-1, rows, cols), eb, 3)
        rv = _residuals(np.asarray(v[b], np.float64).reshape(-1, rows, cols), eb, 3)
        with np.errstate(invalid="ignore"):
            flag = (np.nan_to_num(ru) > threshold) | (np.nan_to_num(rv) > threshold)
        out[b] = flag.reshape(-1, rows * cols)
    return out


@nb.njit(cache=True, nogil=True, inline="always")
def _median8(x: Float64Array, srt: Float64Array) -> tuple[float, int]:
    """:func:`_nanmedian8` of one point's 8 values ``x`` (``srt``: scratch of 8): the same
    network (unrolled on scalars, branch-free: no NaN left) and the same arithmetic, so
    the same numbers."""
    count = 0
    for i in range(8):
        if np.isfinite(x[i]):
            count += 1
    if count == 0:
        return np.nan, 0
    s0 = np.inf if np.isnan(x[0]) else x[0]
    s1 = np.inf if np.isnan(x[1]) else x[1]
    s2 = np.inf if np.isnan(x[2]) else x[2]
    s3 = np.inf if np.isnan(x[3]) else x[3]
    s4 = np.inf if np.isnan(x[4]) else x[4]
    s5 = np.inf if np.isnan(x[5]) else x[5]
    s6 = np.inf if np.isnan(x[6]) else x[6]
    s7 = np.inf if np.isnan(x[7]) else x[7]
    s0, s1 = min(s0, s1), max(s0, s1)
    s2, s3 = min(s2, s3), max(s2, s3)
    s4, s5 = min(s4, s5), max(s4, s5)
    s6, s7 = min(s6, s7), max(s6, s7)
    s0, s2 = min(s0, s2), max(s0, s2)
    s1, s3 = min(s1, s3), max(s1, s3)
    s4, s6 = min(s4, s6), max(s4, s6)
    s5, s7 = min(s5, s7), max(s5, s7)
    s1, s2 = min(s1, s2), max(s1, s2)
    s5, s6 = min(s5, s6), max(s5, s6)
    s0, s4 = min(s0, s4), max(s0, s4)
    s3, s7 = min(s3, s7), max(s3, s7)
    s1, s5 = min(s1, s5), max(s1, s5)
    s2, s6 = min(s2, s6), max(s2, s6)
    s1, s4 = min(s1, s4), max(s1, s4)
    s3, s6 = min(s3, s6), max(s3, s6)
    s2, s4 = min(s2, s4), max(s2, s4)
    s3, s5 = min(s3, s5), max(s3, s5)
    s3, s4 = min(s3, s4), max(s3, s4)
    srt[0] = s0
    srt[1] = s1
    srt[2] = s2
    srt[3] = s3
    srt[4] = s4
    srt[5] = s5
    srt[6] = s6
    srt[7] = s7
    return (srt[max((count - 1) // 2, 0)] + srt[min(count // 2, 7)]) / 2, count


@nb.njit(cache=True, nogil=True)
def _critical_frames(
    u: Float64Array,
    v: Float64Array,
    ok: BoolArray,
    rows: int,
    cols: int,
    threshold: float,
    out: Float32Array,
) -> None:
    """:func:`median_critical_eps` of the frames of ``u``, ``v`` (frames, rows * cols)
    with the points ``~ok`` missing, into ``out``: one pass per point (8 neighbours, two
    network medians) instead of (8, frames, points) float64 temporaries."""
    nb8 = np.empty(8)
    srt = np.empty(8)
    for f in range(u.shape[0]):
        for r in range(rows):
            for c in range(cols):
                best = -np.inf
                for comp in range(2):
                    a = u if comp == 0 else v
                    g = a[f, r * cols + c] if ok[f, r * cols + c] else np.nan
                    if not np.isfinite(g):
                        continue
                    i = 0
                    for dr in range(-1, 2):
                        for dc in range(-1, 2):
                            if dr == 0 and dc == 0:
                                continue
                            rr, cc = r + dr, c + dc
                            val = np.nan
                            if 0 <= rr < rows and 0 <= cc < cols and ok[f, rr * cols + cc]:
                                val = a[f, rr * cols + cc]
                            nb8[i] = val
                            i += 1
                    med, count = _median8(nb8, srt)
                    if count < 3:
                        continue
                    for k in range(8):
                        nb8[k] = abs(nb8[k] - med)
                    rm, _ = _median8(nb8, srt)
                    e = abs(g - med) / threshold - rm
                    if np.isfinite(e) and e > best:
                        best = e
                out[f, r * cols + c] = best


def median_critical_eps(
    u: Float64Array,
    v: Float64Array,
    grid_shape: tuple[int, int],
    *,
    threshold: float = 2.0,
    block: int = 64,
    valid: BoolArray | None = None,
) -> Float32Array:
    """The largest ``eps`` at which :func:`median_test_frames` still flags each point:
    ``max over u, v of |u_0 - u_m| / threshold - r_m`` (``r_0 > threshold`` holds exactly
    for ``eps`` below it), ``-inf`` where the point is not tested; so the flags at any
    ``eps`` per frame are ``critical > eps[:, None]`` without a second median pass.

    Parameters
    ----------
    u, v : ndarray, shape (frames, rows * cols)
        Displacements (px) on the POI grid, NaN = no vector.
    grid_shape : (rows, cols)
    threshold : float
    block : int
        Frames per pass (kept for compatibility: the compiled pass needs no temporaries).
    valid : ndarray of bool, shape (frames, rows * cols), optional
        Vectors to use; the others count as missing (as NaN), without a masked copy.

    Returns
    -------
    ndarray of float32, shape (frames, rows * cols)
    """
    rows, cols = (int(grid_shape[0]), int(grid_shape[1]))
    uu = np.ascontiguousarray(u, np.float64)
    vv = np.ascontiguousarray(v, np.float64)
    ok = np.ones(uu.shape, bool) if valid is None else np.ascontiguousarray(valid, bool)
    out = np.empty(uu.shape, np.float32)
    if uu.size:
        _critical_frames(uu, vv, ok, rows, cols, float(threshold), out)
    return out


def normalized_median_test(
    u: ArrayLike,
    v: ArrayLike,
    grid_shape: tuple[int, int],
    *,
    eps: float = 0.1,
    threshold: float = 2.0,
) -> BoolArray:
    """Flag spurious vectors with the normalised median test (Westerweel & Scarano 2005).

    Parameters
    ----------
    u, v : array_like, shape (rows * cols,)
        Displacement components (px) on a regular POI grid in row-major order; NaN marks
        a missing vector (never flagged, and ignored as a neighbour).
    grid_shape : (rows, cols)
        Shape of the POI grid.
    eps : float
        Noise level of the estimates, px (the paper: 0.1).
    threshold : float
        Largest acceptable normalised residual (the paper: 2).

    Returns
    -------
    ndarray of bool, shape (rows * cols,)
        True where either component's normalised residual exceeds ``threshold``. Points
        with fewer than 3 valid neighbours are not tested (False).
    """
    rows, cols = (int(grid_shape[0]), int(grid_shape[1]))
    uu = np.asarray(u, dtype=np.float64).ravel()
    vv = np.asarray(v, dtype=np.float64).ravel()
    if uu.shape != (rows * cols,) or vv.shape != uu.shape:
        raise InputError(
            f"grid_shape={grid_shape!r}: u and v must hold rows * cols = "
            f"{rows * cols} values (got {uu.size} and {vv.size})"
        )
    if not (eps > 0 and threshold > 0):
        raise InputError(f"eps={eps!r}, threshold={threshold!r}: both must be > 0")
    ru = normalized_residual(uu, (rows, cols), eps=eps)
    rv = normalized_residual(vv, (rows, cols), eps=eps)
    with np.errstate(invalid="ignore"):
        return np.asarray((np.nan_to_num(ru) > threshold) | (np.nan_to_num(rv) > threshold))
