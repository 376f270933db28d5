"""Triangulation of image-point pairs to 3-D points, and its Jacobian (docs/stereo.md).

Linear triangulation (DLT, Hartley & Zisserman, *Multiple View Geometry*, 2nd ed., s. 12.2)
on the undistorted normalised coordinates, refined by Gauss-Newton on the reprojection
error in pixels through each camera's distortion (the maximum-likelihood point for equal,
isotropic image noise; s. 12.3's criterion, solved iteratively instead of by the
polynomial). At the refined point ``X`` the image coordinates ``x = (r_L, c_L, r_R, c_R)``
and ``X`` are tied by ``J_p^T (p(X) - x) = 0`` (``J_p = dp/dX``, 4 x 3), hence to first
order ``dX/dx = (J_p^T J_p)^-1 J_p^T`` (exact for a zero residual) and the covariance of
``X`` from independent image covariances ``C_L``, ``C_R`` is

    Cov(X) = G diag(C_L, C_R) G^T,   G = (J_p^T J_p)^-1 J_p^T         (paper-brief s. 11)
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ..arrays import Float64Array
from ..errors import InputError
from .camera import UNDISTORT_ITERATIONS, StereoRig
from .kernels import PackedRig, pack_camera, projection_jacobian_kernel, triangulate_kernel

__all__ = [
    "numeric_projection_jacobian",
    "projection_jacobian",
    "propagate",
    "triangulate",
    "triangulation_jacobian",
]

#: Gauss-Newton iterations of the refinement (quadratic convergence: 3 reach 1e-12 px on
#: the tests' points).
REFINE_ITERATIONS = 4


def _points(rc: ArrayLike, name: str) -> Float64Array:
    p = np.asarray(rc, dtype=np.float64)
    if p.ndim == 1:
        p = p[None, :]
    if p.ndim != 2 or p.shape[1] != 2:
        raise InputError(f"{name}: expected (row, col) pairs, shape (n, 2), got {p.shape}")
    return p


def _dlt(rig: StereoRig, ab_l: Float64Array, ab_r: Float64Array) -> Float64Array:
    """Linear triangulation of normalised coordinates, (n, 3); the smallest singular vector
    of the 4 x 4 system of each pair."""
    p_l = np.hstack([np.eye(3), np.zeros((3, 1))])
    p_r = np.hstack([rig.rotation, rig.translation[:, None]])
    a = np.empty((len(ab_l), 4, 4))
    a[:, 0] = ab_l[:, 0:1] * p_l[2] - p_l[0]
    a[:, 1] = ab_l[:, 1:2] * p_l[2] - p_l[1]
    a[:, 2] = ab_r[:, 0:1] * p_r[2] - p_r[0]
    a[:, 3] = ab_r[:, 1:2] * p_r[2] - p_r[1]
    ok = np.isfinite(a).all(axis=(1, 2))
    out = np.full((len(ab_l), 3), np.nan)
    if ok.any():
        _, _, vt = np.linalg.svd(a[ok])
        h = vt[:, -1, :]
        with np.errstate(divide="ignore", invalid="ignore"):
            out[ok] = h[:, :3] / h[:, 3:4]
    return out


def _project4(rig: StereoRig, x: Float64Array) -> Float64Array:
    pl, pr = rig.project(x)
    return np.concatenate([pl, pr], axis=-1)


def _packed(rig: StereoRig) -> PackedRig:
    pose_l = np.hstack([np.eye(3), np.zeros((3, 1))])
    pose_r = np.ascontiguousarray(np.hstack([rig.rotation, rig.translation[:, None]]))
    return PackedRig(pack_camera(rig.left), pack_camera(rig.right), pose_l, pose_r)


def projection_jacobian(rig: StereoRig, x: ArrayLike) -> Float64Array:
    """``d(r_L, c_L, r_R, c_R) / d(X, Y, Z)`` at left-frame points (n, 3) mm: (n, 4, 3)
    px/mm (analytic, :mod:`.kernels`; NaN for a point at or behind a camera)."""
    p = np.ascontiguousarray(np.atleast_2d(np.asarray(x, dtype=np.float64)))
    return np.asarray(projection_jacobian_kernel(p, _packed(rig)))


def numeric_projection_jacobian(rig: StereoRig, x: ArrayLike) -> Float64Array:
    """:func:`projection_jacobian` by central differences (step 1e-6 of the distance:
    relative error ~1e-10), the check of the analytic one."""
    p = np.atleast_2d(np.asarray(x, dtype=np.float64))
    h = 1e-6 * np.maximum(np.linalg.norm(p, axis=1), 1.0)
    jac = np.empty((len(p), 4, 3))
    for k in range(3):
        d = np.zeros_like(p)
        d[:, k] = h
        jac[:, :, k] = (_project4(rig, p + d) - _project4(rig, p - d)) / (2 * h[:, None])
    return jac


def triangulate(
    rig: StereoRig, left: ArrayLike, right: ArrayLike, *, refine: bool = True
) -> tuple[Float64Array, Float64Array]:
    """3-D points of image-point pairs.

    Parameters
    ----------
    rig : StereoRig
    left, right : array_like, shape (n, 2)
        ``(row, col)`` px in the left and the right image (distorted, as measured).
    refine : bool
        Gauss-Newton on the pixel reprojection error after the linear solution (default);
        False: the DLT point alone.

    Returns
    -------
    points : ndarray, shape (n, 3)
        ``(X, Y, Z)`` in the left camera frame, mm (NaN where an input is NaN).
    residual : ndarray, shape (n,)
        RMS reprojection error over the four coordinates, px (the distance of the pair
        from the epipolar geometry: ~0 for a consistent pair).
    """
    pl, pr = _points(left, "left"), _points(right, "right")
    if len(pl) != len(pr):
        raise InputError(f"left, right: {len(pl)} and {len(pr)} points; give one pair each")
    if refine:
        # compiled: the linear point of each pair and Gauss-Newton with the analytic
        # Jacobian in one pass (the same fixed point as the numpy iteration)
        xk, rk = triangulate_kernel(
            np.ascontiguousarray(pl),
            np.ascontiguousarray(pr),
            _packed(rig),
            REFINE_ITERATIONS,
            UNDISTORT_ITERATIONS,
        )
        return np.asarray(xk), np.asarray(rk)
    x = _dlt(rig, rig.left.normalised(pl), rig.right.normalised(pr))
    obs = np.concatenate([pl, pr], axis=1)
    res = _project4(rig, x) - obs
    return x, np.sqrt(np.mean(res * res, axis=1))


def triangulation_jacobian(rig: StereoRig, points: ArrayLike) -> Float64Array:
    """``G = dX / d(r_L, c_L, r_R, c_R)`` at triangulated points (n, 3): (n, 3, 4) mm/px,
    ``(J_p^T J_p)^-1 J_p^T`` (module docstring)."""
    jp = projection_jacobian(rig, points)
    jtj = np.einsum("nki,nkj->nij", jp, jp)
    return np.asarray(np.linalg.solve(jtj, np.transpose(jp, (0, 2, 1))))


def propagate(jacobian: ArrayLike, cov_left: ArrayLike, cov_right: ArrayLike) -> Float64Array:
    """Covariance of the 3-D points (n, 3, 3), mm^2, from the image covariances.

    Parameters
    ----------
    jacobian : array_like, shape (n, 3, 4)
        :func:`triangulation_jacobian`.
    cov_left, cov_right : array_like, shape (n, 2, 2)
        Covariance of ``(row, col)`` of each image point, px^2 (independent cameras).
    """
    g = np.asarray(jacobian, dtype=np.float64)
    gl, gr = g[:, :, :2], g[:, :, 2:]
    # the block-diagonal image covariance: G_L C_L G_L^T + G_R C_R G_R^T (stacked matmuls,
    # ~10x the three-operand einsum on a frame pair's points)
    cl = np.asarray(cov_left, dtype=np.float64)
    cr = np.asarray(cov_right, dtype=np.float64)
    out = gl @ cl @ np.transpose(gl, (0, 2, 1))
    out += gr @ cr @ np.transpose(gr, (0, 2, 1))
    return np.asarray(out)
