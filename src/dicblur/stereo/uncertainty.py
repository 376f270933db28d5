"""3-D uncertainty of stereo DIC under motion blur (docs/stereo.md, "Uncertainty").

Each camera's image-plane covariance per point and frame is the one ``dicblur track``
predicts for a 2-D track (docs/track.md, step 5: the complete noise term of the ZNSSD
IC-GN fixed point and the blur-mismatch shift of the point's reference subset at its own
blur), with each camera's blur vector the 3-D motion during the exposure projected
through that camera: ``W_cam = p_cam(X + dX/2) - p_cam(X - dX/2)``. In ``(row, col)``:

    C = diag(var_v, var_u),   var = sigma^2 c + sigma^4 c4,

and the signed mismatch shift ``xi = (xi_v, xi_u)`` of the subset, a deterministic error
of that subset at that blur (random over subsets). The cameras' noises are independent
(separate sensors), so the noise part of the 3-D displacement's covariance is
``G diag(C_L, C_R) G^T`` (:func:`dicblur.stereo.triangulate.propagate`); the two
mismatch shifts are not: both subsets image the same texture, blurred along nearly the same
axis at a narrow stereo angle, so they largely agree and move the point across the line of
sight rather than along it. They are propagated together, as the point's deterministic
error ``b = G (xi_L, xi_R)``, whose square adds to the variance: ``Cov = G diag(C_L, C_R)
G^T + b b^T``. The stereo
match's own error (the reference pair) cancels in the displacement to first order: it
moves the reference and the current point alike.
"""

from __future__ import annotations

import math

import numpy as np

from ..arrays import Float64Array
from ..track.uncertainty import BlurTable
from .camera import StereoRig

__all__ = [
    "blur_vectors",
    "camera_covariance",
    "ratio_out_of_plane",
    "relative_shift",
]


def blur_vectors(
    rig: StereoRig, points: Float64Array, motion: Float64Array
) -> tuple[Float64Array, Float64Array]:
    """Each camera's blur vector ``(d_row, d_col)`` px, (..., 2) each, of points (..., 3)
    mm moving by ``motion`` (..., 3) mm during the exposure (left frame)."""
    a, b = points - 0.5 * motion, points + 0.5 * motion
    la, ra = rig.project(a)
    lb, rb = rig.project(b)
    return lb - la, rb - ra


def length_angle(vec: Float64Array) -> tuple[Float64Array, Float64Array]:
    """Blur length W (px) and direction (deg in [0, 180) from +x towards +y) of
    ``(d_row, d_col)`` vectors, as ``dicblur track`` stores them."""
    w = np.hypot(vec[..., 0], vec[..., 1])
    ang = np.degrees(np.arctan2(vec[..., 0], vec[..., 1])) % 180.0
    return w, ang


def camera_covariance(
    table: BlurTable,
    blur: Float64Array,
    angle: Float64Array,
    variance: Float64Array,
) -> tuple[Float64Array, Float64Array, Float64Array]:
    """Image-plane noise covariance (frames, points, 2, 2) px^2 in ``(row, col)`` of one
    camera, its noise std per component (frames, points, 2), and the signed blur-mismatch
    shift ``xi`` (frames, points, 2) px in ``(row, col)`` (module docstring).

    ``variance`` is the noise variance of each point's subset, GL^2 (points,)."""
    vals = table.lookup(blur, angle)
    s2 = variance[None, :]
    var_u = s2 * vals[..., 2] + s2 * s2 * vals[..., 4]
    var_v = s2 * vals[..., 3] + s2 * s2 * vals[..., 5]
    xi = np.stack([vals[..., 1], vals[..., 0]], axis=-1)  # (row, col)
    cov = np.zeros((*xi.shape, 2))
    cov[..., 0, 0] = var_v
    cov[..., 1, 1] = var_u
    noise = np.sqrt(np.maximum(np.stack([var_v, var_u], axis=-1), 0.0))
    return cov, noise, xi


def relative_shift(xi: Float64Array, reference: int) -> Float64Array:
    """The mismatch shift of each frame against a reference that is itself blurred,
    (frames, points, k) px: ``xi - xi[reference]``.

    The table's ``xi`` is the shift of a subset blurred by a frame's kernel against the
    sharp subset. To first order in the blur the shift is linear in the kernel's second
    moment (``W^2 d d^T / 12``, the reason the table interpolates linearly in ``W^2``), so
    a current frame against a reference blurred by its own exposure's motion (a frame 0
    opening at rest still moves during its exposure) is shifted by the difference of the
    two: a frame blurred as the reference is has no mismatch. A point whose reference shift
    is unknown (NaN) keeps its shift against the sharp subset."""
    ref = np.nan_to_num(xi[reference], nan=0.0)
    return np.asarray(xi - ref[None])


def ratio_out_of_plane(stereo_angle: float) -> float:
    """sigma(out of plane) / sigma(in plane, along the baseline) of a symmetric rig at
    ``stereo_angle`` deg, equal isotropic image errors, a point on the bisector, far from
    the rig (docs/stereo.md): ``1 / tan(theta / 2)``, theta the stereo angle."""
    return 1.0 / math.tan(math.radians(stereo_angle) / 2.0)
