"""Stereo matching of the reference pair: the start of each POI from the epipolar
geometry and a rough surface, then IC-GN (docs/stereo.md, "Stereo correlation")."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..arrays import Float64Array, UInt8Array
from ..dic import Correlator, PointStatus
from .camera import StereoRig
from .triangulate import triangulate

__all__ = ["StereoMatch", "match_reference", "plane_start"]


def _unit(v: Float64Array) -> Float64Array:
    return np.asarray(v / np.linalg.norm(v))


def plane_start(
    rig: StereoRig,
    rows: Float64Array,
    cols: Float64Array,
    *,
    depth: float | None = None,
) -> Float64Array:
    """Affine start ``(u, du/dx, du/dy, v, dv/dx, dv/dy)`` (n, 6) of the left-to-right
    match of each POI, from a plane through the rig's crossing point (or at ``depth`` mm
    along the left axis) facing the bisector of the optical axes: the POI's ray meets the
    plane, the point is projected into the right image; the gradients are the plane's
    homography differentiated by central differences (1 px)."""
    p0 = rig.converge_point()
    if depth is not None:
        p0 = np.array([0.0, 0.0, float(depth)])
    n = -(_unit(p0) + _unit(p0 - rig.right_centre))

    def right_of(r: Float64Array, c: Float64Array) -> Float64Array:
        d = rig.left.rays(np.stack([r, c], axis=1))
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = (p0 @ n) / (d @ n)
        return rig.project(lam[:, None] * d)[1]

    r = np.asarray(rows, np.float64)
    c = np.asarray(cols, np.float64)
    q = right_of(r, c)
    qx1, qx0 = right_of(r, c + 1), right_of(r, c - 1)
    qy1, qy0 = right_of(r + 1, c), right_of(r - 1, c)
    out = np.empty((len(r), 6))
    out[:, 0] = q[:, 1] - c
    out[:, 1] = (qx1[:, 1] - qx0[:, 1]) / 2 - 1.0
    out[:, 2] = (qy1[:, 1] - qy0[:, 1]) / 2
    out[:, 3] = q[:, 0] - r
    out[:, 4] = (qx1[:, 0] - qx0[:, 0]) / 2
    out[:, 5] = (qy1[:, 0] - qy0[:, 0]) / 2 - 1.0
    return out


class StereoMatch:
    """The reference pair's correspondence: per left POI the right image point, its
    affine parameters, status and predicted error, and the triangulated shape.

    Attributes
    ----------
    params : ndarray (n, 6) or (n, 2)
        IC-GN parameters of the left subset in the right reference image.
    right : ndarray (n, 2)
        Right image point ``(row, col)`` px of each left POI.
    status : ndarray (n,) uint8
        ``PointStatus`` (``OUTLIER`` also where the pair misses the epipolar geometry by
        more than ``max_epipolar`` px).
    sigma : ndarray (n, 2)
        Predicted std of the right point ``(row, col)`` px (noise of both references).
    points : ndarray (n, 3)
        Triangulated shape, mm (left frame).
    residual : ndarray (n,)
        RMS reprojection error of the pair, px.
    """

    def __init__(self, **kw: Any) -> None:
        self.__dict__.update(kw)

    params: Float64Array
    right: Float64Array
    status: UInt8Array
    sigma: Float64Array
    points: Float64Array
    residual: Float64Array
    zncc: Float64Array


def match_reference(
    rig: StereoRig,
    left: Correlator,
    right_image: Float64Array,
    *,
    depth: float | None = None,
    max_epipolar: float = 1.0,
) -> StereoMatch:
    """Match the left reference's POIs (the Correlator ``left``) in the right reference
    image, from :func:`plane_start`; the Correlator retries failures from its converged
    neighbours (docs/dic.md). Pairs off the epipolar geometry by more than
    ``max_epipolar`` px (RMS reprojection error of the triangulation) are ``OUTLIER``."""
    # the disparity field of a curved target is not locally linear (a 40 mm cylinder at
    # step 12 px: second differences of ~0.4 px), so the engine's neighbour check (exact on
    # linear fields, docs/dic.md) would call its points outliers: off for the stereo pair,
    # whose gross errors the epipolar test below catches
    check = left.neighbour_check
    left.neighbour_check = False
    try:
        return _match(rig, left, right_image, depth=depth, max_epipolar=max_epipolar)
    finally:
        left.neighbour_check = check


def _match(
    rig: StereoRig,
    left: Correlator,
    right_image: Float64Array,
    *,
    depth: float | None,
    max_epipolar: float,
) -> StereoMatch:
    rows = left.rows.astype(np.float64)
    cols = left.cols.astype(np.float64)
    start = plane_start(rig, rows, cols, depth=depth)
    if left.shape == "translation":
        start = start[:, [0, 3]]
    ok = np.isfinite(start).all(axis=1)
    start[~ok] = 0.0
    res = left.correlate(right_image, initial=start)
    bad = res.status != PointStatus.CONVERGED
    good = ~bad & np.isfinite(res.params).all(axis=1)
    if bad.any() and good.sum() >= 12:
        # a curved surface leaves the plane's start too far off at the edges: start the
        # failures from a quadratic in (row, col) fitted to the converged parameters
        def basis(r: Float64Array, c: Float64Array) -> Float64Array:
            s_ = max(float(np.ptp(rows)), float(np.ptp(cols)), 1.0)
            x, y = (c - cols.mean()) / s_, (r - rows.mean()) / s_
            return np.stack([np.ones_like(x), x, y, x * x, x * y, y * y], axis=1)

        coef, *_ = np.linalg.lstsq(basis(rows[good], cols[good]), res.params[good], rcond=None)
        second = np.where(bad[:, None], basis(rows, cols) @ coef, res.params)
        res2 = left.correlate(right_image, initial=second)
        take = bad & (res2.status == PointStatus.CONVERGED)
        if take.any():
            from dataclasses import replace

            fields = {
                k: np.where(
                    take if getattr(res, k).ndim == 1 else take[:, None],
                    getattr(res2, k),
                    getattr(res, k),
                )
                for k in ("u", "v", "params", "zncc", "status", "iterations")
            }
            res = replace(res, **fields)
    right = np.stack([rows + res.v, cols + res.u], axis=1)
    status = res.status.copy()
    pts, resid = triangulate(rig, np.stack([rows, cols], axis=1), right)
    with np.errstate(invalid="ignore"):
        off = ~(resid <= max_epipolar) & (status == PointStatus.CONVERGED)
    status[off] = PointStatus.OUTLIER
    su = res.predicted_sigma_u if res.predicted_sigma_u is not None else np.full(len(rows), np.nan)
    sv = res.predicted_sigma_v if res.predicted_sigma_v is not None else np.full(len(rows), np.nan)
    return StereoMatch(
        params=res.params,
        right=right,
        status=status,
        sigma=np.stack([sv, su], axis=1),
        points=pts,
        residual=resid,
        zncc=res.zncc,
    )
