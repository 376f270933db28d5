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

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "MIN_AGAINST",
    "MIN_SUPPORT",
    "MIN_VERDICTS",
    "SUPPORT_DISTANCE",
    "SUPPORT_ROUNDS",
    "unsupported",
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


def unsupported(
    params: NDArray[np.float64],
    converged: NDArray[np.bool_],
    failed: NDArray[np.bool_],
    rows: NDArray[np.int64],
    cols: NDArray[np.int64],
    grid_shape: tuple[int, int],
    cell: NDArray[np.intp],
) -> NDArray[np.bool_]:
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
        Converged POIs with fewer than :data:`MIN_SUPPORT` confirming neighbours and at
        least :data:`MIN_AGAINST` contradicting ones (all of those that give a verdict
        where fewer do, at least :data:`MIN_VERDICTS`).
    """
    k = params.shape[1]
    ny, nx = grid_shape
    iu, iv = (0, 1) if k == 2 else (0, 3)

    def on_grid(values: NDArray[np.float64], fill: float) -> NDArray[np.float64]:
        g = np.full((ny + 2) * (nx + 2), fill)
        r, c = np.divmod(cell, nx)
        g[(r + 1) * (nx + 2) + c + 1] = values
        return g.reshape(ny + 2, nx + 2)

    conv = on_grid(converged.astype(float), 0.0)
    fail = on_grid(failed.astype(float), 0.0)
    u = on_grid(np.where(converged, params[:, iu], np.nan), np.nan)
    v = on_grid(np.where(converged, params[:, iv], np.nan), np.nan)
    gr = on_grid(rows.astype(float), np.nan)
    gc = on_grid(cols.astype(float), np.nan)
    grads = None
    if k == 6:
        grads = [on_grid(np.where(converged, params[:, j], 0.0), 0.0) for j in (1, 2, 4, 5)]
    inner = (slice(1, ny + 1), slice(1, nx + 1))
    support = np.zeros((ny, nx), np.int64)
    against = np.zeros((ny, nx), np.int64)
    for dr, dc in _OFFSETS:
        nb = (slice(1 + dr, ny + 1 + dr), slice(1 + dc, nx + 1 + dc))
        # the POI's shape function carried to the neighbour's centre (px offsets)
        drow, dcol = gr[nb] - gr[inner], gc[nb] - gc[inner]
        pu, pv = u[inner], v[inner]
        if grads is not None:
            ux, uy, vx, vy = (g[inner] for g in grads)
            pu = pu + ux * dcol + uy * drow
            pv = pv + vx * dcol + vy * drow
        with np.errstate(invalid="ignore"):
            near = np.hypot(u[nb] - pu, v[nb] - pv) <= SUPPORT_DISTANCE
        is_conv = conv[nb] > 0
        support += is_conv & near
        against += (is_conv & ~near) | (fail[nb] > 0)
    return _verdict(support, against).ravel()[cell] & converged


def _verdict(support: NDArray[np.int64], against: NDArray[np.int64]) -> NDArray[np.bool_]:
    """Too little support against enough contradiction (the rule of :func:`unsupported`)."""
    verdicts = support + against
    need = np.maximum(np.minimum(MIN_AGAINST, verdicts), MIN_VERDICTS)
    return (support < MIN_SUPPORT) & (against >= need)


def unsupported_scattered(
    params: NDArray[np.float64],
    converged: NDArray[np.bool_],
    failed: NDArray[np.bool_],
    rows: NDArray[np.int64],
    cols: NDArray[np.int64],
    radius: float,
) -> NDArray[np.bool_]:
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
    from scipy.spatial import cKDTree

    k = params.shape[1]
    iu, iv = (0, 1) if k == 2 else (0, 3)
    n = rows.size
    support = np.zeros(n, np.int64)
    against = np.zeros(n, np.int64)
    xy = np.c_[rows, cols].astype(float)
    pairs = cKDTree(xy).query_pairs(radius, output_type="ndarray")
    if pairs.size == 0:
        return np.zeros(n, bool)
    for a, b in ((pairs[:, 0], pairs[:, 1]), (pairs[:, 1], pairs[:, 0])):
        # b's estimate against a's shape function carried to b's centre
        drow, dcol = xy[b, 0] - xy[a, 0], xy[b, 1] - xy[a, 1]
        pu, pv = params[a, iu], params[a, iv]
        if k == 6:
            pu = pu + params[a, 1] * dcol + params[a, 2] * drow
            pv = pv + params[a, 4] * dcol + params[a, 5] * drow
        with np.errstate(invalid="ignore"):
            near = np.hypot(params[b, iu] - pu, params[b, iv] - pv) <= SUPPORT_DISTANCE
        conf = converged[b] & near
        np.add.at(support, a, conf)
        np.add.at(against, a, (converged[b] & ~near) | failed[b])
    return _verdict(support, against) & converged
