"""The normalised median test for spurious displacement vectors.

Westerweel & Scarano, "Universal outlier detection for PIV data", Exp. Fluids 39, 1096-1100
(2005), doi:10.1007/s00348-005-0016-6: for each vector and each component, with ``u_m`` the
median of its 8 neighbours and ``r_m`` the median of the neighbours' residuals
``|u_i - u_m|``, the normalised residual is ``r_0 = |u_0 - u_m| / (r_m + eps)``; ``eps``
(0.1 px, the paper's value for the noise level of sub-pixel estimates) keeps the test sane in
uniform flows, and ``r_0 > 2`` marks an outlier.
"""

from __future__ import annotations

import warnings

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import InputError

__all__ = ["normalized_median_test", "normalized_residual"]


def _neighbours(a: NDArray[np.float64]) -> NDArray[np.float64]:
    """The 8 neighbours of every grid node, shape (8, rows, cols); NaN outside the grid."""
    p = np.pad(a, 1, constant_values=np.nan)
    rows, cols = a.shape
    out = [
        p[1 + dr : 1 + dr + rows, 1 + dc : 1 + dc + cols]
        for dr in (-1, 0, 1)
        for dc in (-1, 0, 1)
        if (dr, dc) != (0, 0)
    ]
    return np.stack(out)


def normalized_residual(
    values: ArrayLike, grid_shape: tuple[int, int], *, eps: float = 0.1, min_neighbours: int = 3
) -> NDArray[np.float64]:
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
    nb = _neighbours(a)
    count = np.isfinite(nb).sum(axis=0)
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN neighbourhoods: counted
        med = np.nanmedian(nb, axis=0)
        rm = np.nanmedian(np.abs(nb - med[None]), axis=0)
        r0 = np.abs(a - med) / (rm + eps)
    r0[(count < min_neighbours) | ~np.isfinite(a)] = np.nan
    return r0.ravel()


def normalized_median_test(
    u: ArrayLike,
    v: ArrayLike,
    grid_shape: tuple[int, int],
    *,
    eps: float = 0.1,
    threshold: float = 2.0,
) -> NDArray[np.bool_]:
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
