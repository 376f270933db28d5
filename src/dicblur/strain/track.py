"""Strains of every frame of a track, with their noise and blur uncertainty.

Called by ``dicblur.track(..., strain=N)`` with the arrays it assembles: the fields, the
valid points, the per-point noise parts of sigma and, for the blur part, the per-point
blur table (any object with ``lookup(w, angle) -> (frames, points, 6)`` whose first two
values are the signed mismatch shift ``(xi_u, xi_v)``, px; docs/track.md step 5).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..arrays import BoolArray, IndexArray
from ..errors import InputError
from .covariance import Kind
from .field import strain_on_grid, vsg

__all__ = ["FRAME_BLOCK", "TRACK_STRAIN_NAMES", "check_strain_window", "track_strain"]

#: Frames per block (bounded temporaries: about 40 arrays of block x points float64).
FRAME_BLOCK = 64

#: Per (frame, point) variables written beside u, v (float32; status uint8).
TRACK_STRAIN_NAMES = (
    "exx",
    "eyy",
    "exy",
    "e1",
    "e2",
    "principal_angle",
    "sigma_exx",
    "sigma_eyy",
    "sigma_exy",
    "sigma_exx_noise",
    "sigma_exx_blur",
)


def check_strain_window(window: Any, points: Any = None, name: str = "strain") -> int:
    """``window`` as an odd number of grid points >= 3; strain needs the POI grid, so
    explicit ``points`` are refused."""
    if isinstance(window, bool) or not isinstance(window, int | np.integer) or window < 3:
        raise InputError(f"{name}={window!r}: use an odd number of grid points >= 3 (e.g. 5)")
    if window % 2 == 0:
        raise InputError(f"{name}={window!r}: the window must be odd (use {window + 1})")
    if points is not None:
        raise InputError(f"{name}={window!r}: strain needs the POI grid; leave out points")
    return int(window)


def track_strain(
    u: NDArray[Any],
    v: NDArray[Any],
    valid: BoolArray,
    sigma_u_noise: NDArray[Any],
    sigma_v_noise: NDArray[Any],
    table: Any,
    w: NDArray[Any],
    angle: NDArray[Any],
    table_points: IndexArray,
    grid_shape: tuple[int, int],
    *,
    step: int,
    subset: int,
    window: int = 5,
    kind: Kind = "green-lagrange",
) -> tuple[dict[str, NDArray[Any]], dict[str, Any]]:
    """Strain variables of a track, shape (frames, points) each, and their attributes.

    Parameters
    ----------
    u, v : ndarray, shape (frames, points)
        Displacements, px (points in row-major grid order).
    valid : ndarray of bool, shape (frames, points)
        The track's ``valid`` points.
    sigma_u_noise, sigma_v_noise : ndarray, shape (frames, points)
        Noise parts of sigma, px.
    table : BlurTable or None
        Per-point blur response (None: no blur part).
    w, angle : ndarray, shape (frames, points)
        Blur length (px) and direction (deg) per point and frame.
    table_points : ndarray of int, shape (m,)
        The points of the table (its column ``q`` is point ``table_points[q]``).
    grid_shape : (rows, cols)
    step, subset, window, kind
        As for :func:`dicblur.strain`.

    Returns
    -------
    variables : dict
        :data:`TRACK_STRAIN_NAMES` (float32) and ``strain_status`` (uint8).
    attrs : dict
        ``strain_window``, ``strain_vsg`` (px), ``strain_kind``.
    """
    n_f, n_p = u.shape
    ny, nx = grid_shape
    out = {k: np.full((n_f, n_p), np.nan, np.float32) for k in TRACK_STRAIN_NAMES}
    status = np.zeros((n_f, n_p), np.uint8)
    pts = np.asarray(table_points, np.intp)
    for f0 in range(0, n_f, FRAME_BLOCK):
        r = slice(f0, min(n_f, f0 + FRAME_BLOCK))
        nb = r.stop - r.start
        xu = xv = None
        if table is not None:
            vals = table.lookup(w[r][:, pts], angle[r][:, pts])
            xu = np.zeros((nb, n_p))
            xv = np.zeros((nb, n_p))
            xu[:, pts] = np.nan_to_num(vals[..., 0])
            xv[:, pts] = np.nan_to_num(vals[..., 1])
            xu = xu.reshape(nb, ny, nx)
            xv = xv.reshape(nb, ny, nx)
        ok = valid[r] & np.isfinite(sigma_u_noise[r]) & np.isfinite(sigma_v_noise[r])
        sf = strain_on_grid(
            u[r].reshape(nb, ny, nx),
            v[r].reshape(nb, ny, nx),
            ok.reshape(nb, ny, nx),
            step=step,
            subset=subset,
            window=window,
            kind=kind,
            sigma_u=sigma_u_noise[r].reshape(nb, ny, nx),
            sigma_v=sigma_v_noise[r].reshape(nb, ny, nx),
            shift_u=xu,
            shift_v=xv,
            with_principal_sigma=False,
            with_covariance=False,
        )
        for k in TRACK_STRAIN_NAMES:
            val = getattr(sf, "angle" if k == "principal_angle" else k)
            if val is not None:
                out[k][r] = val
        status[r] = sf.status
    if table is None:
        del out["sigma_exx_blur"]
    out_all: dict[str, NDArray[Any]] = {**out, "strain_status": status}
    attrs: dict[str, Any] = {
        "strain_window": int(window),
        "strain_vsg": vsg(window, step, subset),
        "strain_kind": kind,
    }
    return out_all, attrs
