"""Support of a converged POI by its grid neighbours: a lone match among failures.

IC-GN reports ``CONVERGED`` when its step falls below the tolerance and the ZNCC is above
``min_zncc``; that says nothing about whether the optimum is the true match. Where the
current image no longer shows the reference's texture (another pattern, a heavy defocus,
a motion much larger than the subset from a zero start), almost every POI fails, and the
few that stop at a chance optimum (ZNCC 0.62-0.85 at subset 21-31, measured on such
pairs) are tens of px off. Their neighbours, whose subsets share most of their pixels,
failed or landed elsewhere; a true match's overlapping neighbours see the same texture and
agree with it. The neighbour check (:mod:`.screening`) needs :data:`~.screening.PAIRS_MIN`
pairs of converged neighbours and a noise level; this test covers the POIs it cannot
reach: a converged POI that fewer than :data:`MIN_SUPPORT` neighbours confirm while at
least :data:`MIN_AGAINST` contradict it (failed, or converged elsewhere) is ``OUTLIER``.
On a field where most POIs converge (any correct correlation) no POI is flagged by it.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..arrays import BoolArray, Float64Array, IndexArray, Int64Array

__all__ = [
    "MIN_AGAINST",
    "MIN_SUPPORT",
    "MIN_VERDICTS",
    "SUPPORT_DISTANCE",
    "SUPPORT_ROUNDS",
    "Pairs",
    "grid_pairs",
    "scattered_pairs",
    "unsupported",
    "unsupported_pairs",
    "unsupported_scattered",
]

#: A converged neighbour confirms a POI when its (u, v) lies within this distance (px) of
#: the POI's own shape function carried to the neighbour's centre (its displacement for
#: translation). A chance optimum is px to tens of px off; the error of a correct
#: neighbour, imprecise ones included, is well below 1 px.
SUPPORT_DISTANCE = 1.0
#: Fewest confirming neighbours a POI needs where :data:`MIN_AGAINST` contradict it (two,
#: so that two adjacent chance optima, whose subsets overlap, do not vouch for each
#: other alone).
MIN_SUPPORT = 2
#: Fewest contradicting neighbours (of 8) that make a POI with less support ``OUTLIER``:
#: a POI at the edge of a converged region keeps more than one confirming neighbour. A POI
#: with fewer neighbours that give a verdict (a corner of the grid has three) needs all of
#: them against it, and at least :data:`MIN_VERDICTS` of them.
MIN_AGAINST = 4
MIN_VERDICTS = 3

#: Rounds of the test, each with the POIs flagged before as failed: a line of three chance
#: optima (their subsets overlap, so they agree) loses its two ends in the first round and
#: its middle in the second; more rounds would peel a legitimate one-POI-wide strip of
#: converged POIs from its ends.
SUPPORT_ROUNDS = 2

_OFFSETS = [(dr, dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1) if (dr, dc) != (0, 0)]


def grid_pairs(grid_shape: tuple[int, int], cell: IndexArray) -> Pairs:
    """The ordered pairs ``(a, b, start)`` of POIs that are 8-neighbours on a grid.

    Parameters
    ----------
    grid_shape : (ny, nx)
        Shape of the POI grid.
    cell : ndarray of int, shape (n,)
        Each POI's row-major cell of the grid.

    Returns
    -------
    a, b : ndarray of int, shape (m,)
        POI indices: ``b`` is a neighbour of ``a`` (each pair in both orders), sorted by
        ``a``.
    start : ndarray of int, shape (n + 1,)
        The pairs of POI ``i`` are ``start[i]:start[i + 1]``.
    """
    ny, nx = grid_shape
    n = cell.size
    index = np.full((ny + 2, nx + 2), -1, np.intp)
    r, c = np.divmod(cell, nx)
    index[r + 1, c + 1] = np.arange(n)
    inner = index[1 : ny + 1, 1 : nx + 1]
    a_parts, b_parts = [], []
    for dr, dc in _OFFSETS:
        nb = index[1 + dr : ny + 1 + dr, 1 + dc : nx + 1 + dc]
        keep = (inner >= 0) & (nb >= 0)
        a_parts.append(inner[keep])
        b_parts.append(nb[keep])
    return _by_first(np.concatenate(a_parts), np.concatenate(b_parts), n)


def scattered_pairs(rows: Int64Array, cols: Int64Array, radius: float) -> Pairs:
    """The ordered pairs ``(a, b, start)`` of POIs within ``radius`` px of each other
    (both orders; as :func:`grid_pairs`), for POIs that do not fill a grid."""
    from scipy.spatial import cKDTree

    xy = np.c_[rows, cols].astype(float)
    pairs = cKDTree(xy).query_pairs(radius, output_type="ndarray").astype(np.intp)
    a, b = np.r_[pairs[:, 0], pairs[:, 1]], np.r_[pairs[:, 1], pairs[:, 0]]
    return _by_first(a, b, rows.size)


#: Ordered neighbour pairs ``(a, b, start)``: sorted by ``a``, the pairs of POI ``i`` at
#: ``start[i]:start[i + 1]``.
Pairs = tuple[IndexArray, IndexArray, IndexArray]


def _by_first(a: IndexArray, b: IndexArray, n: int) -> Pairs:
    order = np.argsort(a, kind="stable")
    a, b = a[order], b[order]
    return a, b, np.searchsorted(a, np.arange(n + 1)).astype(np.intp)


def _entries(start: IndexArray, sel: IndexArray) -> IndexArray:
    """The indices of the pairs of the POIs ``sel`` (rows of the sorted pairs)."""
    first = start[sel]
    count = start[sel + 1] - first
    offset = np.repeat(first - np.cumsum(count) + count, count)
    return offset + np.arange(int(count.sum()))


def unsupported_pairs(
    params: Float64Array,
    converged: BoolArray,
    failed: BoolArray,
    rows: Int64Array,
    cols: Int64Array,
    pairs: Pairs,
) -> BoolArray:
    """The converged POIs their neighbours (``pairs``, :func:`grid_pairs` or
    :func:`scattered_pairs`) do not support; the rule of :func:`unsupported`.

    Only POIs with a failed neighbour are tested: one among converged neighbours alone is
    the neighbour check's (:mod:`.screening`), and a clean field costs one pass over the
    pairs.

    Parameters
    ----------
    params, converged, failed, rows, cols
        As for :func:`unsupported`.
    pairs : (a, b, start)
        Ordered neighbour pairs (:func:`grid_pairs`): ``b`` is a neighbour of ``a``.

    Returns
    -------
    ndarray of bool, shape (n,)
    """
    a_all, b_all, start = pairs
    n, k = params.shape
    out = np.zeros(n, bool)
    # the candidates: the converged neighbours of the failed POIs (pairs are symmetric)
    bad = np.flatnonzero(failed)
    if bad.size == 0:
        return out
    test = np.zeros(n, bool)
    test[b_all[_entries(start, bad)]] = True
    test &= converged
    if not test.any():
        return out
    sel = _entries(start, np.flatnonzero(test))
    a, b = a_all[sel], b_all[sel]
    iu, iv = (0, 1) if k == 2 else (0, 3)
    # b's estimate against a's shape function carried to b's centre (px offsets)
    drow = (rows[b] - rows[a]).astype(float)
    dcol = (cols[b] - cols[a]).astype(float)
    pu, pv = params[a, iu], params[a, iv]
    if k == 6:
        pu = pu + params[a, 1] * dcol + params[a, 2] * drow
        pv = pv + params[a, 4] * dcol + params[a, 5] * drow
    with np.errstate(invalid="ignore"):
        near = np.hypot(params[b, iu] - pu, params[b, iv] - pv) <= SUPPORT_DISTANCE
    conv_b = converged[b]
    support = np.bincount(a, weights=conv_b & near, minlength=n)
    against = np.bincount(a, weights=(conv_b & ~near) | failed[b], minlength=n)
    return _verdict(support, against) & converged & test


def unsupported(
    params: Float64Array,
    converged: BoolArray,
    failed: BoolArray,
    rows: Int64Array,
    cols: Int64Array,
    grid_shape: tuple[int, int],
    cell: IndexArray,
) -> BoolArray:
    """The converged POIs of a grid that their neighbours do not support.

    Parameters
    ----------
    params : ndarray, shape (n, k)
        Shape parameters of each POI, ``(u, v)`` or ``(u, ux, uy, v, vx, vy)``, px.
    converged : ndarray of bool, shape (n,)
        The POIs with an estimate that may confirm a neighbour (``CONVERGED``, and
        ``IMPRECISE``): the candidates.
    failed : ndarray of bool, shape (n,)
        The POIs whose matching failed in the current image (they contradict a
        neighbour); POIs neither converged nor failed (e.g. decided by the reference
        alone) count neither way.
    rows, cols : ndarray of int, shape (n,)
        POI centres, px.
    grid_shape : (ny, nx)
        Shape of the POI grid.
    cell : ndarray of int, shape (n,)
        Each POI's row-major cell of the grid.

    Returns
    -------
    ndarray of bool, shape (n,)
        Converged POIs with a failed neighbour, fewer than :data:`MIN_SUPPORT`
        confirming neighbours and at least :data:`MIN_AGAINST` contradicting ones (all
        of those that give a verdict where fewer do, at least :data:`MIN_VERDICTS`).
    """
    pairs = grid_pairs(grid_shape, cell)
    return unsupported_pairs(params, converged, failed, rows, cols, pairs)


def _verdict(support: NDArray[Any], against: NDArray[Any]) -> BoolArray:
    """Too little support against enough contradiction (the rule of :func:`unsupported`)."""
    verdicts = support + against
    need = np.maximum(np.minimum(MIN_AGAINST, verdicts), MIN_VERDICTS)
    return (support < MIN_SUPPORT) & (against >= need)


def unsupported_scattered(
    params: Float64Array,
    converged: BoolArray,
    failed: BoolArray,
    rows: Int64Array,
    cols: Int64Array,
    radius: float,
) -> BoolArray:
    """:func:`unsupported` for POIs that do not fill a grid: a POI's neighbours are the
    POIs within ``radius`` px of it (the caller's subset size: their subsets share
    pixels, so a true match's neighbours see the same texture).

    Parameters
    ----------
    params, converged, failed, rows, cols
        As for :func:`unsupported`.
    radius : float
        Neighbour distance, px.

    Returns
    -------
    ndarray of bool, shape (n,)
    """
    pairs = scattered_pairs(rows, cols, radius)
    return unsupported_pairs(params, converged, failed, rows, cols, pairs)
