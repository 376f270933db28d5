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

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["GridGradients", "box_count", "grid_gradients", "plane_weights"]


def plane_weights(half: int, step: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
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


def box_count(mask: NDArray[np.bool_], half: int) -> NDArray[np.int64]:
    """Number of True cells in the ``(2 half + 1)**2`` window around every cell of
    ``mask`` (..., rows, cols); cells outside the grid count as False."""
    m = np.asarray(mask, np.int64)
    pad = [(0, 0)] * (m.ndim - 2) + [(half + 1, half), (half + 1, half)]
    c = np.pad(m, pad).cumsum(-1).cumsum(-2)
    n = 2 * half + 1
    return np.asarray(
        c[..., n:, n:] - c[..., :-n, n:] - c[..., n:, :-n] + c[..., :-n, :-n], np.int64
    )


def correlate_window(field: NDArray[np.floating[Any]], kernel: NDArray[np.float64]) -> Any:
    """``out[..., r, c] = sum_jk kernel[j, k] field[..., r + j - h, c + k - h]`` with the
    field zero outside the grid (callers use only complete windows)."""
    h = kernel.shape[0] // 2
    f = np.asarray(field, np.float64)
    pad = [(0, 0)] * (f.ndim - 2) + [(h, h), (h, h)]
    p = np.pad(f, pad)
    rows, cols = f.shape[-2:]
    out = np.zeros(f.shape, np.float64)
    for j in range(kernel.shape[0]):
        for k in range(kernel.shape[1]):
            w = kernel[j, k]
            if w != 0.0:
                out += w * p[..., j : j + rows, k : k + cols]
    return out


@dataclass(frozen=True)
class GridGradients:
    """Plane-fit gradients of ``u`` and ``v`` on a grid.

    Attributes
    ----------
    ux, uy, vx, vy : ndarray, shape (..., rows, cols)
        ``du/dx``, ``du/dy``, ``dv/dx``, ``dv/dy`` (dimensionless); NaN where ``half`` is 0.
    half : ndarray of int, shape (..., rows, cols)
        Half-width of the window used (grid points); 0: no complete window of at least
        3 x 3 (or the point itself is missing).
    """

    ux: NDArray[np.float64]
    uy: NDArray[np.float64]
    vx: NDArray[np.float64]
    vy: NDArray[np.float64]
    half: NDArray[np.int64]


def choose_half(valid: NDArray[np.bool_], half: int) -> NDArray[np.int64]:
    """The largest window half-width ``<= half`` whose complete window around each cell
    is all valid (0: none of at least 1), shape of ``valid`` (..., rows, cols)."""
    use = np.zeros(valid.shape, np.int64)
    for h in range(half, 0, -1):
        full = (box_count(valid, h) == (2 * h + 1) ** 2) & (use == 0)
        use[full] = h
    return use


def grid_gradients(
    u: NDArray[np.floating[Any]],
    v: NDArray[np.floating[Any]],
    valid: NDArray[np.bool_],
    *,
    half: int,
    step: float,
) -> GridGradients:
    """Plane-fit gradients of ``u``, ``v`` (..., rows, cols; px) over windows of
    half-width ``half`` (or the largest complete smaller one) on a grid of pitch ``step``
    px; ``valid`` marks the trusted points."""
    use = choose_half(valid, half)
    u0 = np.where(valid, u, 0.0)
    v0 = np.where(valid, v, 0.0)
    out = [np.full(use.shape, np.nan) for _ in range(4)]
    for h in np.unique(use[use > 0]):
        gx, gy = plane_weights(int(h), step)
        sel = use == h
        for o, f, g in zip(out, (u0, u0, v0, v0), (gx, gy, gx, gy), strict=True):
            o[sel] = correlate_window(f, g)[sel]
    return GridGradients(*out, half=use)
