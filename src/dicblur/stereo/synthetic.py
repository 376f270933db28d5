"""A synthetic stereo laboratory: a speckled 3-D target seen by both cameras of a known
rig, moving during each exposure, with exact motion blur in each view (docs/stereo.md).

Rendering (no 2-D shortcut): every pixel is integrated over its area (``supersample`` x
``supersample`` ray samples) and over the exposure (``substeps`` sub-exposures at the
mid-points of equal time slices). Each ray is cast through the camera's distortion (the
ideal direction of the distorted pixel position, :meth:`CameraModel.rays`), intersected
with the surface moved to its position at that instant, and the surface's texture is read
there by a cubic B-spline of a band-limited speckle texture (its edges smoothed by at least
1.5 texels, the texel a quarter of a pixel's footprint or finer): the image is the average
of all these samples, then :class:`dicblur.Camera` adds the noise of one exposure. Each
camera therefore sees its own blur: the 3-D motion projected through its own projection.

The target moves rigidly by a translation ``d(t)`` (mm, left camera frame); its shape is a
plane or a circular cylinder (axis along the rig's y, the convex side towards the rig).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

import numba as nb
import numpy as np
from numpy.typing import ArrayLike

from ..arrays import Float64Array
from ..camera import Camera
from ..errors import InputError
from ..patterns import SeedLike, make_rng, speckle_pattern
from .camera import CameraModel, StereoRig

__all__ = ["SpeckleTarget", "StereoLab", "symmetric_rig"]

Trajectory = Callable[[Float64Array], Float64Array]


def symmetric_rig(
    *,
    stereo_angle: float,
    distance: float,
    camera: CameraModel,
    right: CameraModel | None = None,
) -> StereoRig:
    """A rig whose optical axes meet at ``(0, 0, distance)`` of the left frame at
    ``stereo_angle`` degrees, the right camera on the +x side (a rotation about y).

    Parameters
    ----------
    stereo_angle : float
        Angle between the optical axes, deg, in (0, 90).
    distance : float
        Distance from the left camera to the axes' crossing, mm.
    camera, right : CameraModel
        The left camera, and the right one (default the same intrinsics).
    """
    if not 0 < stereo_angle < 90:
        raise InputError(f"stereo_angle={stereo_angle!r}: expected (0, 90) deg, e.g. 30")
    if not distance > 0:
        raise InputError(f"distance={distance!r}: must be > 0 mm")
    a = math.radians(stereo_angle)
    rot = np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])
    centre = np.array([distance * math.tan(a), 0.0, 0.0])
    return StereoRig(
        left=camera,
        right=camera if right is None else right,
        rotation=rot,
        translation=-rot @ centre,
        info={"synthetic": f"symmetric, {stereo_angle} deg at {distance} mm"},
    )


@dataclass(frozen=True)
class SpeckleTarget:
    """A speckled surface in the left camera frame (mm).

    Attributes
    ----------
    kind : {"plane", "cylinder"}
    origin : (3,) mm
        Plane: a point of the plane (texture origin). Cylinder: the point of its surface
        nearest the rig (texture origin); the axis lies ``radius`` behind it along
        ``-normal``.
    normal : (3,)
        Unit normal towards the cameras (at ``origin`` for the cylinder).
    radius : float
        Cylinder radius, mm (ignored for a plane).
    texture : ndarray (rows, cols)
        Periodic grey levels on the surface; texel ``texel`` mm; texture coordinates
        ``(s, t)`` = (along the rig's x, along y) from ``origin`` (arc length on a cylinder).
    texel : float
        Texel pitch, mm.
    """

    kind: Literal["plane", "cylinder"]
    origin: tuple[float, float, float]
    normal: tuple[float, float, float]
    texture: Float64Array
    texel: float
    radius: float = math.inf

    @classmethod
    def speckled(
        cls,
        *,
        kind: Literal["plane", "cylinder"] = "plane",
        origin: ArrayLike = (0.0, 0.0, 400.0),
        normal: ArrayLike | None = None,
        rig: StereoRig | None = None,
        radius: float = 60.0,
        size: float = 120.0,
        speckle_size: float = 0.8,
        texel: float = 0.05,
        levels: tuple[float, float] = (30.0, 220.0),
        seed: SeedLike = None,
    ) -> SpeckleTarget:
        """A speckle target (docs/stereo.md).

        Parameters
        ----------
        kind : {"plane", "cylinder"}
        origin : (3,) mm
            Texture origin on the surface (the rig's crossing point, typically).
        normal : (3,), optional
            Towards the cameras; default: the bisector of the rig's optical axes (``rig``),
            else -z.
        radius : float
            Cylinder radius, mm.
        size : float
            Side of the (periodic) texture tile, mm.
        speckle_size : float
            Mean speckle diameter, mm.
        texel : float
            Texture pitch, mm: a quarter of a pixel's footprint or finer.
        levels : (black, white) GL
        seed
            The speckle's randomness (same seed, same texture).
        """
        o = np.asarray(origin, dtype=np.float64).reshape(3)
        if normal is None:
            if rig is not None:
                cl = o / np.linalg.norm(o)
                cr = (o - rig.right_centre) / np.linalg.norm(o - rig.right_centre)
                n = -(cl + cr)
            else:
                n = np.array([0.0, 0.0, -1.0])
        else:
            n = np.asarray(normal, dtype=np.float64).reshape(3)
        n = n / np.linalg.norm(n)
        px = round(size / texel)
        if not 64 <= px <= 8192:
            raise InputError(f"size={size!r}, texel={texel!r}: the tile needs 64..8192 texels")
        tex = speckle_pattern(
            (px, px),
            speckle_size=speckle_size / texel,
            density=0.5,
            softness=max(1.5, 0.15 * speckle_size / texel),
            levels=levels,
            seed=make_rng(seed),
        )
        return cls(
            kind=kind,
            origin=(float(o[0]), float(o[1]), float(o[2])),
            normal=(float(n[0]), float(n[1]), float(n[2])),
            texture=tex,
            texel=float(texel),
            radius=float(radius) if kind == "cylinder" else math.inf,
        )

    @classmethod
    def checkerboard(
        cls,
        *,
        board: tuple[int, int],
        square: float,
        origin: ArrayLike,
        normal: ArrayLike,
        texel: float = 0.1,
        levels: tuple[float, float] = (20.0, 230.0),
    ) -> SpeckleTarget:
        """A plane with a checkerboard of ``board`` = (cols, rows) inner corners and
        squares of ``square`` mm, centred on ``origin`` (its inner corners at texture
        coordinates ``((i - (cols-1)/2) square, (j - (rows-1)/2) square)``), on a white
        margin of two squares; edges smoothed by 1.5 texels (band-limited)."""
        from scipy.ndimage import gaussian_filter

        nx, ny = board
        side = (max(nx, ny) + 5) * square
        px = round(side / texel)
        if not 64 <= px <= 8192:
            raise InputError(f"square={square!r}, texel={texel!r}: the tile needs 64..8192 texels")
        c = (np.arange(px) + 0.0) * texel
        c = np.where(c >= side / 2, c - side, c)  # texel k at coordinate k texel, wrapped
        ss, tt = np.meshgrid(c, c, indexing="xy")
        i = np.floor(ss / square + (nx + 1) / 2.0)
        j = np.floor(tt / square + (ny + 1) / 2.0)
        inside = (i >= 0) & (i <= nx) & (j >= 0) & (j <= ny)
        black = inside & ((i + j) % 2 == 0)
        tex = np.where(black, levels[0], levels[1]).astype(np.float64)
        tex = gaussian_filter(tex, 1.5, mode="wrap")
        o = np.asarray(origin, dtype=np.float64).reshape(3)
        n = np.asarray(normal, dtype=np.float64).reshape(3)
        n = n / np.linalg.norm(n)
        return cls(
            kind="plane",
            origin=(float(o[0]), float(o[1]), float(o[2])),
            normal=(float(n[0]), float(n[1]), float(n[2])),
            texture=tex,
            texel=float(texel),
        )

    def frame(self) -> tuple[Float64Array, Float64Array, Float64Array]:
        """Unit axes ``(e_s, e_t, n)`` of the texture at ``origin``: ``e_t`` along the
        rig's y projected on the surface, ``e_s = e_t x n``."""
        n = np.asarray(self.normal)
        et = np.array([0.0, 1.0, 0.0]) - n[1] * n
        et /= np.linalg.norm(et)
        es = np.cross(et, n)
        return es, et, n

    def intersect(
        self, origins: Float64Array, dirs: Float64Array
    ) -> tuple[Float64Array, Float64Array]:
        """Ray parameter ``lam`` (n,) of the first hit of rays ``origins + lam dirs`` and
        the texture coordinates (n, 2) ``(s, t)`` mm there (NaN: a miss)."""
        o0 = np.asarray(self.origin)
        es, et, n = self.frame()
        rel = origins - o0
        if self.kind == "plane":
            with np.errstate(divide="ignore", invalid="ignore"):
                lam = -(rel @ n) / (dirs @ n)
            p = rel + lam[:, None] * dirs
            st = np.stack([p @ es, p @ et], axis=1)
            return lam, st
        # cylinder: axis through c = origin - radius n, along e_t
        rad = self.radius
        rc = rel + rad * n  # relative to the axis point
        ra = rc - (rc @ et)[:, None] * et
        da = dirs - (dirs @ et)[:, None] * et
        a = np.einsum("ij,ij->i", da, da)
        b = 2.0 * np.einsum("ij,ij->i", ra, da)
        c = np.einsum("ij,ij->i", ra, ra) - rad * rad
        disc = b * b - 4 * a * c
        with np.errstate(invalid="ignore", divide="ignore"):
            lam = (-b - np.sqrt(disc)) / (2 * a)
        p = rc + lam[:, None] * dirs
        ang = np.arctan2(p @ es, p @ n)
        st = np.stack([rad * ang, p @ et], axis=1)
        return lam, st

    def point(self, st: ArrayLike) -> Float64Array:
        """Surface points (n, 3) mm at texture coordinates ``(s, t)`` (n, 2) mm, at rest."""
        q = np.asarray(st, dtype=np.float64)
        es, et, n = self.frame()
        o0 = np.asarray(self.origin)
        if self.kind == "plane":
            return np.asarray(o0 + q[:, :1] * es + q[:, 1:2] * et)
        ang = q[:, 0] / self.radius
        c = o0 - self.radius * n
        return np.asarray(
            c
            + self.radius * (np.sin(ang)[:, None] * es + np.cos(ang)[:, None] * n)
            + q[:, 1:2] * et
        )


@dataclass(frozen=True)
class StereoLab:
    """A rig, a target, a trajectory and a camera: renders synchronised stereo frames.

    Attributes
    ----------
    rig : StereoRig
    target : SpeckleTarget
    trajectory : callable
        ``d(t)``: times (m,) s -> translations (m, 3) mm of the target (left frame).
    exposure : float
        s.
    fps : float
        Hz; frame k opens at ``k / fps``.
    camera : dicblur.Camera
        Noise, quantisation (the same model for both cameras).
    supersample : int
        Ray samples per pixel side.
    substeps : int or None
        Sub-exposures per frame; None: enough for at most 0.25 px of image motion
        between two of them (at least 8).
    """

    rig: StereoRig
    target: SpeckleTarget
    trajectory: Trajectory
    exposure: float
    fps: float
    camera: Camera = field(default_factory=lambda: Camera(read_noise=2.0, bit_depth=None))
    supersample: int = 2
    substeps: int | None = None
    _rays_cache: dict[str, tuple[Float64Array, Float64Array]] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )
    _coef: Float64Array | None = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not self.fps > 0 or not 0 <= self.exposure <= 1.0 / self.fps:
            raise InputError(
                f"exposure={self.exposure!r}, fps={self.fps!r}: need 0 <= exposure <= 1/fps"
            )
        if not 1 <= int(self.supersample) <= 8:
            raise InputError(f"supersample={self.supersample!r}: expected 1..8")

    def times(self, frame: int) -> Float64Array:
        """Sub-exposure instants of a frame, s (the mid-points of equal slices)."""
        k = self._substeps(frame)
        t0 = frame / self.fps
        return np.asarray(t0 + (np.arange(k) + 0.5) / k * self.exposure)

    def _substeps(self, frame: int) -> int:
        if self.substeps is not None:
            return int(self.substeps)
        t0 = frame / self.fps
        ends = self.trajectory(np.array([t0, t0 + self.exposure]))
        x0 = self.target.point(np.zeros((1, 2)))[0]
        wl, wr = self.rig.project(x0 + ends)
        w = max(float(np.linalg.norm(wl[1] - wl[0])), float(np.linalg.norm(wr[1] - wr[0])))
        return max(8, math.ceil(4 * w) + 1) if self.exposure > 0 else 1

    def mean_displacement(self, frame: int) -> Float64Array:
        """The target's translation averaged over the frame's exposure (3,) mm: what a
        blurred frame shows (its sub-exposures' mean, as rendered)."""
        return np.asarray(self.trajectory(self.times(frame)).mean(axis=0))

    def _rays(self, side: Literal["left", "right"]) -> tuple[Float64Array, Float64Array]:
        # cast once per laboratory and camera (kept on the instance: a key such as id()
        # could be reused by a later laboratory)
        if side not in self._rays_cache:
            self._rays_cache[side] = self._cast(side)
        return self._rays_cache[side]

    def _cast(self, side: Literal["left", "right"]) -> tuple[Float64Array, Float64Array]:
        """Origins and directions (n, 3) of the supersampled pixel rays (left frame)."""
        cam = self.rig.left if side == "left" else self.rig.right
        s = int(self.supersample)
        rows, cols = cam.image_shape
        off = (np.arange(s) + 0.5) / s - 0.5
        rr = (np.arange(rows)[:, None] + off[None, :]).ravel()
        cc = (np.arange(cols)[:, None] + off[None, :]).ravel()
        grid = np.stack(np.meshgrid(rr, cc, indexing="ij"), axis=-1).reshape(-1, 2)
        d = cam.rays(grid)
        if side == "left":
            return np.zeros((len(d), 3)), d
        return np.broadcast_to(self.rig.right_centre, d.shape).copy(), d @ self.rig.rotation

    def render(
        self, frame: int, *, seed: SeedLike = None, noise: bool = True
    ) -> tuple[Float64Array, Float64Array]:
        """The left and the right image of ``frame`` (grey levels, (rows, cols) each).

        ``seed`` draws the two images' noise (independent streams of one generator);
        ``noise=False`` returns the noise-free irradiance."""
        from scipy.ndimage import spline_filter

        if self._coef is None:  # the texture's cubic B-spline coefficients, once
            object.__setattr__(
                self, "_coef", spline_filter(self.target.texture, order=3, mode="grid-wrap")
            )
        coef = self._coef
        assert coef is not None
        times = self.times(frame)
        disp = self.trajectory(times)
        rng = make_rng(seed)
        out = []
        for side in ("left", "right"):
            cam = self.rig.left if side == "left" else self.rig.right
            origins, dirs = self._rays(side)
            acc = np.zeros(len(dirs))
            es, et, nn = self.target.frame()
            fr = np.stack([np.asarray(self.target.origin), es, et, nn])
            for d in disp:
                # the surface moved by d is the surface at rest seen from origins - d
                accumulate_rays(
                    coef, origins - d, dirs, fr, self.target.radius, self.target.texel, acc
                )
            s = int(self.supersample)
            rows, cols = cam.image_shape
            img = (acc / len(disp)).reshape(rows, s, cols, s).mean(axis=(1, 3))
            out.append(self.camera.capture(img, rng=rng) if noise else img)
        return out[0], out[1]

    def surface_point(self, left_rc: ArrayLike, frame: int | None = None) -> Float64Array:
        """The true 3-D point (n, 3) mm seen at left image points ``(row, col)`` with the
        target at rest (``frame`` None) or at its mean position of ``frame``."""
        rc = np.atleast_2d(np.asarray(left_rc, dtype=np.float64))
        d = np.zeros(3) if frame is None else self.mean_displacement(frame)
        dirs = self.rig.left.rays(rc)
        lam, _ = self.target.intersect(np.zeros_like(dirs) - d, dirs)
        return np.asarray(lam[:, None] * dirs)


@nb.njit(cache=True, nogil=True)
def _bspline3(coef: Float64Array, y: float, x: float) -> float:  # pragma: no cover
    """The periodic cubic B-spline of coefficients ``coef`` at texel coordinates."""
    ny, nx = coef.shape
    fy, fx = math.floor(y), math.floor(x)
    ty, tx = y - fy, x - fx
    sy, sx = 1.0 - ty, 1.0 - tx
    wy0, wy3 = sy * sy * sy / 6.0, ty * ty * ty / 6.0
    wy1 = (4.0 - 6.0 * ty * ty + 3.0 * ty * ty * ty) / 6.0
    wy2 = 1.0 - wy0 - wy1 - wy3
    wx0, wx3 = sx * sx * sx / 6.0, tx * tx * tx / 6.0
    wx1 = (4.0 - 6.0 * tx * tx + 3.0 * tx * tx * tx) / 6.0
    wx2 = 1.0 - wx0 - wx1 - wx3
    iy, ix = int(fy) - 1, int(fx) - 1
    v = 0.0
    for a in range(4):
        r = (iy + a) % ny
        c0, c1, c2, c3 = (ix % nx), ((ix + 1) % nx), ((ix + 2) % nx), ((ix + 3) % nx)
        row = wx0 * coef[r, c0] + wx1 * coef[r, c1] + wx2 * coef[r, c2] + wx3 * coef[r, c3]
        v += (wy0, wy1, wy2, wy3)[a] * row
    return v


@nb.njit(cache=True, nogil=True, parallel=True)
def accumulate_rays(
    coef: Float64Array,
    origins: Float64Array,
    dirs: Float64Array,
    frame: Float64Array,
    radius: float,
    texel: float,
    acc: Float64Array,
) -> None:  # pragma: no cover - compiled
    """``acc += texture`` where each ray ``origins + lam dirs`` first meets the surface
    (``SpeckleTarget.intersect``, the same formulas; a miss adds 0). ``frame`` rows:
    surface origin, ``e_s``, ``e_t``, ``n``; ``radius`` inf for a plane."""
    o0, es, et, nn = frame[0], frame[1], frame[2], frame[3]
    for i in nb.prange(dirs.shape[0]):
        rx, ry, rz = origins[i, 0] - o0[0], origins[i, 1] - o0[1], origins[i, 2] - o0[2]
        dx, dy, dz = dirs[i, 0], dirs[i, 1], dirs[i, 2]
        if math.isinf(radius):
            den = dx * nn[0] + dy * nn[1] + dz * nn[2]
            if den == 0.0:
                continue
            lam = -(rx * nn[0] + ry * nn[1] + rz * nn[2]) / den
            px, py, pz = rx + lam * dx, ry + lam * dy, rz + lam * dz
            s = px * es[0] + py * es[1] + pz * es[2]
            t = px * et[0] + py * et[1] + pz * et[2]
        else:
            cx, cy, cz = rx + radius * nn[0], ry + radius * nn[1], rz + radius * nn[2]
            ca = cx * et[0] + cy * et[1] + cz * et[2]
            da_ = dx * et[0] + dy * et[1] + dz * et[2]
            ax, ay, az = cx - ca * et[0], cy - ca * et[1], cz - ca * et[2]
            bx, by, bz = dx - da_ * et[0], dy - da_ * et[1], dz - da_ * et[2]
            qa = bx * bx + by * by + bz * bz
            qb = 2.0 * (ax * bx + ay * by + az * bz)
            qc = ax * ax + ay * ay + az * az - radius * radius
            disc = qb * qb - 4.0 * qa * qc
            if disc < 0.0 or qa == 0.0:
                continue
            lam = (-qb - math.sqrt(disc)) / (2.0 * qa)
            px, py, pz = cx + lam * dx, cy + lam * dy, cz + lam * dz
            ang = math.atan2(
                px * es[0] + py * es[1] + pz * es[2], px * nn[0] + py * nn[1] + pz * nn[2]
            )
            s = radius * ang
            t = px * et[0] + py * et[1] + pz * et[2]
        acc[i] += _bspline3(coef, t / texel, s / texel)
