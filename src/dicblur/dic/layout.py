"""Where a Correlator's POIs lie: the grid (or given points), its cells, the seed passes."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from ..arrays import IndexArray, Int64Array, UInt8Array
from ..checks import describe
from ..errors import InputError
from ..metrics import subset_centres
from .status import PointStatus

__all__ = ["grid_of", "layout", "seed_passes"]


def layout(
    image_shape: tuple[int, int],
    *,
    subset: int,
    step: int,
    roi: Sequence[int] | None = None,
    points: ArrayLike | None = None,
) -> tuple[Int64Array, Int64Array, UInt8Array]:
    """The POIs a Correlator on an image of ``image_shape`` lays out, without
    preparing it: ``(rows, cols, status)``, each shape (n,), ``status``
    ``OUT_OF_BOUNDS`` for given ``points`` whose subset leaves the image, else 0.

    ``subset`` (odd, px) and ``step`` (px) as validated by
    :class:`~dicblur.dic.MatcherSettings`; ``roi`` and ``points`` as for the
    constructor (the grid of ``step`` px inside ``roi`` or the whole image, or the
    given centres).
    """
    rows_img, cols_img = (int(image_shape[0]), int(image_shape[1]))
    half = subset // 2
    if points is not None:
        pts = np.asarray(points)
        if pts.dtype.kind not in "iuf":
            raise InputError(
                f"points={describe(points)}: expected an (n, 2) array of integer "
                "(row, col) POI centres, px"
            )
        if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] == 0:
            raise InputError(
                f"points={describe(pts)}: expected an (n, 2) array of "
                "(row, col) POI centres, n >= 1"
            )
        if not np.issubdtype(pts.dtype, np.integer):
            if not np.all(np.isfinite(pts)) or not np.all(pts == np.round(pts)):
                raise InputError(
                    f"points={describe(pts)}: POI centres must be integer "
                    "pixel positions (round them first)"
                )
        pts = pts.astype(np.int64)
        r, c = pts[:, 0].copy(), pts[:, 1].copy()
        inside = (
            (r - half >= 0)
            & (r + half <= rows_img - 1)
            & (c - half >= 0)
            & (c + half <= cols_img - 1)
        )
        st = np.where(inside, 0, int(PointStatus.OUT_OF_BOUNDS)).astype(np.uint8)
        return r, c, st
    r0, r1, c0, c1 = 0, rows_img, 0, cols_img
    if roi is not None:
        try:
            r0, r1, c0, c1 = (int(x) for x in roi)
            whole = all(float(x) == int(x) for x in roi)
        except (TypeError, ValueError) as exc:
            raise InputError(
                f"roi={describe(roi)}: expected (row_start, row_stop, col_start, col_stop) in px"
            ) from exc
        if not whole:
            # int() would truncate a fractional bound silently
            raise InputError(
                f"roi={describe(roi)}: the bounds must be whole pixels (row_start, row_stop, "
                "col_start, col_stop); round them first"
            )
        if not (0 <= r0 < r1 <= rows_img and 0 <= c0 < c1 <= cols_img):
            raise InputError(
                f"roi={describe(roi)}: must satisfy 0 <= row_start < "
                f"row_stop <= {rows_img} and 0 <= col_start < col_stop <= "
                f"{cols_img}"
            )
    if min(r1 - r0, c1 - c0) < subset + 2:
        raise InputError(
            f"roi={describe(roi)}: region smaller than the subset "
            f"({subset} px) plus a 1-px border; enlarge it"
        )
    centres = subset_centres((r1 - r0, c1 - c0), subset=subset, step=step)
    r = centres[:, 0].astype(np.int64) + r0
    c = centres[:, 1].astype(np.int64) + c0
    return r, c, np.zeros(len(r), np.uint8)


def grid_of(
    rows: Int64Array, cols: Int64Array, *, required: bool
) -> tuple[tuple[int, int] | None, IndexArray | None]:
    """Shape of the POI grid and each POI's row-major cell, when the POIs fill one."""
    ur, ri = np.unique(rows, return_inverse=True)
    uc, ci = np.unique(cols, return_inverse=True)
    cell = ri.astype(np.intp) * len(uc) + ci.astype(np.intp)
    if len(rows) == len(ur) * len(uc) and np.unique(cell).size == len(rows):
        return (len(ur), len(uc)), cell
    if required:
        raise InputError(
            f"median_test=True: the {len(rows)} points do not fill a "
            f"regular grid ({len(ur)} rows x {len(uc)} columns of centres)"
            "; use median_test=False or a full grid of points"
        )
    return None, None


def seed_passes(
    rows: Int64Array, cols: Int64Array, step: int
) -> tuple[IndexArray, IndexArray, IndexArray] | None:
    """Two-pass start: IC-GN first on sparse seed POIs (about 1 in 16), then every other
    POI starts from its nearest seed's warp carried to its own centre. A start within a
    few hundredths of a px saves about one IC-GN iteration per POI (Pan et al. 2013 use
    the same idea along a reliability path).

    Returns ``(seeds, rest, rest_seed)`` (POI indices; ``rest_seed`` the nearest seed of
    each of ``rest``), or None below 64 POIs or when one of the two passes would be empty.
    """
    n = int(rows.shape[0])
    if n < 64:
        return None
    from scipy.spatial import cKDTree

    spacing = 4 * step
    key = (rows // spacing) * 100003 + (cols // spacing)
    _, first = np.unique(key, return_index=True)
    seeds = np.sort(first)
    rest = np.setdiff1d(np.arange(n), seeds)
    if seeds.size == 0 or rest.size == 0:
        return None
    tree = cKDTree(np.stack([rows[seeds], cols[seeds]], axis=1))
    _, near = tree.query(np.stack([rows[rest], cols[rest]], axis=1))
    return seeds, rest, seeds[np.asarray(near, dtype=np.intp)]
