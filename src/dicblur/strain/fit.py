"""Displacement gradients on a POI grid by a local least-squares plane (the VSG).

Over a complete, symmetric window of ``N x N`` grid points (``N = 2 h + 1``) centred on a
point, the plane ``u = a + b x + c y`` fitted by least squares has the slopes

    b = sum_jk k u_jk / (step N S_h),   c = sum_jk j u_jk / (step N S_h),
    S_h = sum_{k=-h..h} k**2 = h (h + 1) (2 h + 1) / 3,

(``j`` the row offset, ``k`` the column offset in grid steps): each gradient is a fixed
linear combination ``g^T u`` of the window's displacements (docs/strain.md, eq. 1). A point
whose full window holds a missing point takes the largest smaller symmetric window that is
complete (at least 3 x 3); a window is never filled in or averaged across a missing point,
so a crack or an edge (failed points there) is never smoothed over.
"""

from __future__ import annotations

import numpy as np

from ..arrays import BoolArray, Float64Array, Int64Array

__all__ = ["box_count", "choose_half", "plane_weights"]


def plane_weights(half: int, step: float) -> tuple[Float64Array, Float64Array]:
    """The weights of the plane fit's slopes over a complete ``(2 half + 1)**2`` window.

    Parameters
    ----------
    half : int
        Half-width ``h`` of the window, grid points (``N = 2 h + 1``).
    step : float
        Grid step, px.

    Returns
    -------
    gx, gy : ndarray, shape (N, N)
        ``du/dx = sum(gx * u_window)``, ``du/dy = sum(gy * u_window)`` (1/px), windows
        indexed (row offset, column offset).
    """
    n = 2 * half + 1
    k = np.arange(-half, half + 1, dtype=np.float64)
    s = float(np.sum(k**2))
    gx = np.broadcast_to(k[None, :], (n, n)) / (step * n * s)
    return np.ascontiguousarray(gx), np.ascontiguousarray(gx.T)


def box_count(mask: BoolArray, half: int) -> Int64Array:
    """Number of True cells in the ``(2 half + 1)**2`` window around every cell of
    ``mask`` (..., rows, cols); cells outside the grid count as False."""
    m = np.asarray(mask, np.int64)
    pad = [(0, 0)] * (m.ndim - 2) + [(half + 1, half), (half + 1, half)]
    c = np.pad(m, pad).cumsum(-1).cumsum(-2)
    n = 2 * half + 1
    return np.asarray(
        c[..., n:, n:] - c[..., :-n, n:] - c[..., n:, :-n] + c[..., :-n, :-n], np.int64
    )


def choose_half(valid: BoolArray, half: int) -> Int64Array:
    """The largest window half-width ``<= half`` whose complete window around each cell
    is all valid (0: none of at least 1), shape of ``valid`` (..., rows, cols)."""
    use = np.zeros(valid.shape, np.int64)
    for h in range(half, 0, -1):
        full = (box_count(valid, h) == (2 * h + 1) ** 2) & (use == 0)
        use[full] = h
    return use
