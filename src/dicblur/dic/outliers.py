"""Validation of a measured displacement field: the normalised median test.

Westerweel & Scarano, "Universal outlier detection for PIV data", Exp. Fluids 39 (2005)
1096-1100, doi:10.1007/s00348-005-0016-6: for each point of a regular grid, with ``U_m``
the median of its (up to 8) valid neighbours in the 3x3 block and ``r_m`` the median of
the neighbours' residuals ``|U_i - U_m|``, the normalised residual is

    r0 = |U_0 - U_m| / (r_m + eps),

and the point is an outlier when ``r0 > threshold`` (``eps`` = 0.1 px, ``threshold`` = 2
recommended: one threshold fits flows of any smoothness). The test is applied to each
component; a point is an outlier when either component fails.
"""

from __future__ import annotations

from typing import Any

import numba as nb
import numpy as np
from numpy.typing import ArrayLike

from ..arrays import BoolArray, Float64Array, IndexArray
from ..checks import check_positive, describe
from ..errors import InputError

__all__ = [
    "MEDIAN_EPS",
    "MEDIAN_THRESHOLD",
    "median_screen",
    "neighbour_median",
    "neighbour_medians",
    "normalized_median_test",
]

#: Default ``eps`` (px) of :func:`normalized_median_test` (Westerweel & Scarano 2005).
MEDIAN_EPS = 0.1
#: Default ``threshold`` of :func:`normalized_median_test` (Westerweel & Scarano 2005).
MEDIAN_THRESHOLD = 2.0


def _grid(name: str, values: ArrayLike, shape: tuple[int, int]) -> Float64Array:
    a = np.asarray(values, dtype=np.float64)
    n = shape[0] * shape[1]
    if a.shape == shape:
        return a
    if a.shape == (n,):
        return a.reshape(shape)
    raise InputError(
        f"{name}: shape {a.shape} does not match grid_shape {shape} (give "
        f"an array of shape {shape} or ({n},) in row-major order)"
    )


def _check_grid_shape(grid_shape: Any) -> tuple[int, int]:
    try:
        ny, nx = (int(s) for s in grid_shape)
    except (TypeError, ValueError) as exc:
        raise InputError(
            f"grid_shape={describe(grid_shape)}: expected (rows, cols) of the POI grid"
        ) from exc
    if ny < 1 or nx < 1:
        raise InputError(f"grid_shape={describe(grid_shape)}: both sizes must be >= 1")
    return ny, nx


@nb.njit(cache=True, inline="always")
def _sorted_median(buf, n):  # pragma: no cover - compiled
    """Median of ``buf[:n]`` after sorting it in place (insertion sort, n <= 8)."""
    for i in range(1, n):
        x = buf[i]
        j = i - 1
        while j >= 0 and buf[j] > x:
            buf[j + 1] = buf[j]
            j -= 1
        buf[j + 1] = x
    return 0.5 * (buf[(n - 1) // 2] + buf[n // 2])


@nb.njit(cache=True, inline="always")
def _gather(a, c, ok, y, x, buf):  # pragma: no cover - compiled
    """Copy component ``c`` of the valid 3x3 neighbours of grid point ``(y, x)`` of ``a``
    (k, ny, nx) into ``buf``; returns their number (0..8)."""
    ny, nx = ok.shape
    n = 0
    for yy in range(max(0, y - 1), min(ny, y + 2)):
        for xx in range(max(0, x - 1), min(nx, x + 2)):
            if ok[yy, xx] and not (yy == y and xx == x):
                buf[n] = a[c, yy, xx]
                n += 1
    return n


@nb.njit(cache=True)
def _neighbour_medians(a, ok, med, res, count):  # pragma: no cover - compiled
    """Per component ``c`` and grid point of ``a`` (k, ny, nx): median of the valid 3x3
    neighbours and median of their absolute residuals; ``count`` (ny, nx) the number of
    valid neighbours."""
    k, ny, nx = a.shape
    buf = np.empty(8)
    for c in range(k):
        for y in range(ny):
            for x in range(nx):
                n = _gather(a, c, ok, y, x, buf)
                count[y, x] = n
                if n == 0:
                    med[c, y, x] = np.nan
                    res[c, y, x] = np.nan
                    continue
                m = _sorted_median(buf, n)
                med[c, y, x] = m
                for i in range(n):
                    buf[i] = abs(buf[i] - m)
                res[c, y, x] = _sorted_median(buf, n)


@nb.njit(cache=True)
def _screen_kernel(a, ntest, ok, eps, thr, min_nb, within, flag, med):  # pragma: no cover
    """Normalised median test of components ``0..ntest-1`` of ``a`` (k, ny, nx) over the
    ``ok`` points (``flag`` (ny, nx)); ``med`` (k, ny, nx) gets the neighbour medians of
    every component where they were computed, NaN elsewhere.

    Shortcut: when more than half of a point's valid neighbours lie within ``within`` of
    it in every tested component, its neighbour median does too (the middle order
    statistics cannot leave that interval), so with ``within <= thr * eps`` it passes
    and its median is not computed (``within < 0``: never)."""
    k, ny, nx = a.shape
    buf = np.empty(8)
    for y in range(ny):
        for x in range(nx):
            flag[y, x] = False
            for c in range(k):
                med[c, y, x] = np.nan
            if not ok[y, x]:
                continue
            n = 0
            for yy in range(max(0, y - 1), min(ny, y + 2)):
                for xx in range(max(0, x - 1), min(nx, x + 2)):
                    if ok[yy, xx] and not (yy == y and xx == x):
                        n += 1
            if n < min_nb:
                continue
            if within >= 0.0:
                skip = True
                for c in range(ntest):
                    close = 0
                    for yy in range(max(0, y - 1), min(ny, y + 2)):
                        for xx in range(max(0, x - 1), min(nx, x + 2)):
                            if ok[yy, xx] and not (yy == y and xx == x):
                                close += abs(a[c, yy, xx] - a[c, y, x]) <= within
                    if 2 * close <= n:
                        skip = False
                if skip:
                    continue
            for c in range(k):
                _gather(a, c, ok, y, x, buf)
                um = _sorted_median(buf, n)
                med[c, y, x] = um
                if c < ntest:
                    for i in range(n):
                        buf[i] = abs(buf[i] - um)
                    rm = _sorted_median(buf, n)
                    if abs(a[c, y, x] - um) > thr * (rm + eps):
                        flag[y, x] = True


def median_screen(
    values: ArrayLike,
    valid: ArrayLike,
    *,
    ntest: int = 2,
    eps: float = MEDIAN_EPS,
    threshold: float = MEDIAN_THRESHOLD,
    min_neighbours: int = 3,
    within: float | None = None,
) -> tuple[BoolArray, Float64Array]:
    """The normalised median test on components ``0..ntest-1`` of ``values`` (k, ny, nx)
    and the neighbour medians of all k components where they were needed.

    ``within`` (px, default ``threshold * eps``): points with more than half of their
    valid neighbours within this distance in every tested component pass without
    computing their medians (exact for ``within <= threshold * eps``); their medians are
    NaN, as those of invalid points and points with fewer than ``min_neighbours``.

    Returns
    -------
    outlier : ndarray of bool, shape (ny, nx)
    median : ndarray, shape (k, ny, nx), px
    """
    a = np.ascontiguousarray(values, dtype=np.float64)
    ok = np.ascontiguousarray(valid, dtype=np.bool_)
    lim = threshold * eps
    w = lim if within is None else min(float(within), lim)
    if not w > 0:
        w = -1.0
    flag = np.zeros(ok.shape, np.bool_)
    med = np.empty(a.shape)
    _screen_kernel(
        a, int(ntest), ok, float(eps), float(threshold), int(min_neighbours), w, flag, med
    )
    return flag, med


def _medians(stack: Float64Array, ok: BoolArray) -> tuple[Float64Array, Float64Array, IndexArray]:
    """Neighbour medians of each component of ``stack`` (k, ny, nx) over the ``ok``
    points: ``(median, residual median, count)``, shapes (k, ny, nx), (k, ny, nx),
    (ny, nx)."""
    med = np.empty(stack.shape)
    res = np.empty(stack.shape)
    count = np.zeros(stack.shape[1:], np.intp)
    _neighbour_medians(
        np.ascontiguousarray(stack, dtype=np.float64),
        np.ascontiguousarray(ok, dtype=np.bool_),
        med,
        res,
        count,
    )
    return med, res, count


@nb.njit(cache=True)
def _medians_at(a, ok, ys, xs, out):  # pragma: no cover - compiled
    """Neighbour medians of the points ``(ys[m], xs[m])`` for each component of ``a``
    (k, ny, nx) over the ``ok`` points into ``out`` (k, m); NaN without a neighbour."""
    k = a.shape[0]
    buf = np.empty(8)
    for m in range(ys.shape[0]):
        y = ys[m]
        x = xs[m]
        for c in range(k):
            n = _gather(a, c, ok, y, x, buf)
            out[c, m] = _sorted_median(buf, n) if n > 0 else np.nan


def neighbour_medians(values: ArrayLike, valid: ArrayLike, at: ArrayLike) -> Float64Array:
    """Median of the valid 3x3 neighbours of some grid points, for each component.

    Parameters
    ----------
    values : array_like, shape (k, ny, nx)
        ``k`` components on the grid.
    valid : array_like of bool, shape (ny, nx)
        Points that may serve as neighbours.
    at : array_like of int, shape (m,)
        Row-major grid cells of the points wanted.

    Returns
    -------
    ndarray, shape (k, m)
        Medians, NaN where a point has no valid neighbour.
    """
    a = np.ascontiguousarray(values, dtype=np.float64)
    ok = np.ascontiguousarray(valid, dtype=np.bool_)
    cells = np.asarray(at, dtype=np.int64)
    ys, xs = np.divmod(cells, a.shape[2])
    out = np.empty((a.shape[0], len(cells)))
    _medians_at(a, ok, ys, xs, out)
    return out


def neighbour_median(
    values: ArrayLike, grid_shape: tuple[int, int], *, valid: ArrayLike | None = None
) -> tuple[Float64Array, Float64Array, IndexArray]:
    """Median of each point's valid 3x3 neighbours and of their residuals.

    Parameters
    ----------
    values : array_like, shape (ny, nx) or (ny * nx,)
        One component of the field on the POI grid (row-major), e.g. ``u``, px.
    grid_shape : (ny, nx)
        Rows and columns of the POI grid.
    valid : array_like of bool, same shape, optional
        Points that may serve as neighbours (default: the finite values).

    Returns
    -------
    median, residual, count : ndarray, shape (ny, nx)
        ``U_m`` (px), ``r_m = median_i |U_i - U_m|`` (px) and the number of valid
        neighbours (0..8); NaN medians where a point has no valid neighbour.
    """
    shape = _check_grid_shape(grid_shape)
    a = _grid("values", values, shape)
    ok = np.isfinite(a)
    if valid is not None:
        ok &= _grid("valid", np.asarray(valid, dtype=float), shape) > 0
    med, res, count = _medians(a[None], ok)
    return med[0], res[0], count


def normalized_median_test(
    u: ArrayLike,
    v: ArrayLike,
    grid_shape: tuple[int, int],
    *,
    valid: ArrayLike | None = None,
    eps: float = MEDIAN_EPS,
    threshold: float = MEDIAN_THRESHOLD,
    min_neighbours: int = 3,
) -> BoolArray:
    """Outliers of a displacement field on a regular POI grid (Westerweel & Scarano 2005).

    Parameters
    ----------
    u, v : array_like, shape (ny, nx) or (ny * nx,)
        Displacement components on the grid (row-major order, as the POIs of a
        :class:`~dicblur.dic.Correlator` grid), px.
    grid_shape : (ny, nx)
        Rows and columns of the POI grid.
    valid : array_like of bool, same shape, optional
        Points to use as neighbours and to test (default: finite ``u`` and ``v``), e.g.
        ``result.converged``.
    eps : float
        Noise level of the field added to the residual median, px (0.1 px recommended).
    threshold : float
        Limit of the normalised residual (2 recommended).
    min_neighbours : int
        Points with fewer valid neighbours are not tested (returned ``False``).

    Returns
    -------
    ndarray of bool, same shape as ``u``
        ``True`` where a valid point fails the test in ``u`` or ``v``.

    Examples
    --------
    >>> import numpy as np
    >>> u = np.full((5, 5), 0.3); v = np.zeros((5, 5)); u[2, 2] = 1.3
    >>> normalized_median_test(u, v, (5, 5))[2, 2]
    np.True_
    """
    shape = _check_grid_shape(grid_shape)
    ua = _grid("u", u, shape)
    va = _grid("v", v, shape)
    eps_f = check_positive(eps, "eps", allow_zero=True)
    thr = check_positive(threshold, "threshold")
    if (
        isinstance(min_neighbours, bool)
        or not isinstance(min_neighbours, int | np.integer)
        or not 1 <= min_neighbours <= 8
    ):
        raise InputError(f"min_neighbours={describe(min_neighbours)}: must be an integer in 1..8")
    ok = np.isfinite(ua) & np.isfinite(va)
    if valid is not None:
        ok &= _grid("valid", np.asarray(valid, dtype=float), shape) > 0
    out, _ = median_screen(
        np.stack([ua, va]), ok, eps=eps_f, threshold=thr, min_neighbours=int(min_neighbours)
    )
    return out if np.shape(u) == shape else out.ravel()
