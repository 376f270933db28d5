"""Smoothing of a field on the POI grid (the per-frame guess of :func:`~dicblur.track.track`).

One compiled pass over the points (issue 17's least-squares plane through each point's
3 x 3 neighbourhood): about 0.05 ms for the 2,401 points of a 49 x 49 grid, where the
whole-grid numpy version took about 0.6 ms per frame in temporaries. The sums are taken in
the order of that version (3-tap sums along x, then along y), so the numbers are the same
bit for bit (tests/test_track.py compares it with a plain numpy reference).
"""

from __future__ import annotations

import numba as nb
import numpy as np
from numpy.typing import NDArray

__all__ = ["smooth_on_grid"]

#: |determinant| of the plane's normal equations below which the neighbours are taken as
#: not spanning a plane (their mean is used).
_DET_MIN = 1e-6


def smooth_on_grid(
    values: NDArray[np.float64], grid: tuple[int, int], cells: NDArray[np.intp]
) -> NDArray[np.float64]:
    """Each point's value of the least-squares plane through the finite ``values`` of its
    3 x 3 neighbourhood on the POI grid.

    Inside the grid this is the neighbourhood's mean (the random error of one value / 3);
    at the edges and next to missing points the plane keeps it exact for a linear field
    (a mean there would be off by a third of the field's change over a grid step).
    Where the neighbours do not span a plane (fewer than three, or all on one line): their
    mean; NaN where there is none.

    Parameters
    ----------
    values : ndarray, shape (n, k)
        Values of the n points (a point with a non-finite value in any column: missing).
    grid : (int, int)
        Rows and columns of the POI grid.
    cells : ndarray of int, shape (n,)
        Row-major grid cell of each point (``0 <= cells < rows * cols``).

    Returns
    -------
    ndarray, shape (n, k)
    """
    vals = np.ascontiguousarray(values, dtype=np.float64)
    idx = np.ascontiguousarray(cells, dtype=np.intp)
    out = np.empty_like(vals)
    _smooth(vals, int(grid[0]), int(grid[1]), idx, out)
    return out


@nb.njit(cache=True, nogil=True)
def _smooth(values, ny, nx, cells, out):  # pragma: no cover - compiled
    """:func:`smooth_on_grid` into ``out`` (n, k). No fastmath: the sums keep the order
    (and the roundings) of the numpy formulation, ``((a[x-1] + a[x]) + a[x+1])`` along x,
    then the same along y, and the cofactor expansion's products one by one."""
    n, k = values.shape
    # channel 0 the weights, 1.. the values, on the grid with a margin of one empty cell
    a = np.zeros((1 + k, ny + 2, nx + 2))
    for i in range(n):
        ok = True
        for j in range(k):
            if not np.isfinite(values[i, j]):
                ok = False
        if not ok:
            continue
        r = cells[i] // nx + 1
        c = cells[i] % nx + 1
        a[0, r, c] = 1.0
        for j in range(k):
            a[1 + j, r, c] = values[i, j]
    b0 = np.empty(k)
    bx = np.empty(k)
    by = np.empty(k)
    for i in range(n):
        y = cells[i] // nx + 1
        x = cells[i] % nx + 1
        # weights: 3-tap sums (rx), differences (dxa) and the dx = +-1 weights (ex) of the
        # rows y - 1, y, y + 1
        w = a[0]
        rw0 = w[y - 1, x - 1] + w[y - 1, x] + w[y - 1, x + 1]
        rw1 = w[y, x - 1] + w[y, x] + w[y, x + 1]
        rw2 = w[y + 1, x - 1] + w[y + 1, x] + w[y + 1, x + 1]
        dw0 = w[y - 1, x + 1] - w[y - 1, x - 1]
        dw1 = w[y, x + 1] - w[y, x - 1]
        dw2 = w[y + 1, x + 1] - w[y + 1, x - 1]
        s0 = rw0 + rw1 + rw2
        sx = dw0 + dw1 + dw2
        sy = rw2 - rw0
        sxx = (w[y - 1, x - 1] + w[y - 1, x + 1]) + (w[y, x - 1] + w[y, x + 1])
        sxx = sxx + (w[y + 1, x - 1] + w[y + 1, x + 1])
        syy = s0 - rw1
        sxy = dw2 - dw0
        for j in range(k):
            v = a[1 + j]
            r0 = v[y - 1, x - 1] + v[y - 1, x] + v[y - 1, x + 1]
            r1 = v[y, x - 1] + v[y, x] + v[y, x + 1]
            r2 = v[y + 1, x - 1] + v[y + 1, x] + v[y + 1, x + 1]
            d0 = v[y - 1, x + 1] - v[y - 1, x - 1]
            d1 = v[y, x + 1] - v[y, x - 1]
            d2 = v[y + 1, x + 1] - v[y + 1, x - 1]
            b0[j] = r0 + r1 + r2
            bx[j] = d0 + d1 + d2
            by[j] = r2 - r0
        # a0 of the normal equations [[s0 sx sy] [sx sxx sxy] [sy sxy syy]] a = b, by the
        # first row of the cofactors (the matrix is symmetric)
        c0 = sxx * syy - sxy * sxy
        c1 = sy * sxy - sx * syy
        c2 = sx * sxy - sxx * sy
        det = s0 * c0 + sx * c1 + sy * c2
        if s0 >= 3 and abs(det) > _DET_MIN:
            for j in range(k):
                out[i, j] = (c0 * b0[j] + c1 * bx[j] + c2 * by[j]) / det
        elif s0 > 0:
            for j in range(k):
                out[i, j] = b0[j] / s0
        else:
            for j in range(k):
                out[i, j] = np.nan
