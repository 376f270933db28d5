"""Pinhole cameras with lens distortion and a stereo rig (issue 29, docs/stereo.md).

Conventions (OpenCV's, so calibrations move between the two unchanged): a camera looks
along +Z of its own frame, x to the right (image columns), y down (image rows). A point
``X_c = (X, Y, Z)`` in the camera frame has normalised coordinates ``(a, b) = (X/Z, Y/Z)``;
the distortion ``(k1, k2, p1, p2, k3)`` of Brown-Conrady as OpenCV writes it,

    r2 = a^2 + b^2,  radial = 1 + k1 r2 + k2 r2^2 + k3 r2^3,
    a' = a radial + 2 p1 a b + p2 (r2 + 2 a^2),
    b' = b radial + p1 (r2 + 2 b^2) + 2 p2 a b,

then ``col = fx a' + cx``, ``row = fy b' + cy`` (px; pixel centres at integers, as the
arrays of dicblur are indexed). The rig holds the right camera's pose in the left camera's
frame: ``X_R = R X_L + t`` (OpenCV's ``stereoCalibrate`` R, T); world = left camera frame,
in mm.

Image points are given and returned as ``(row, col)`` like every dicblur array, unlike
OpenCV's ``(x, y)``.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._version import __version__
from ..arrays import Float64Array
from ..errors import ConfigError, InputError
from ..io import write_text

__all__ = ["CameraModel", "StereoRig", "load_rig", "rotation_matrix", "save_rig"]

#: Iterations of the fixed-point undistortion (OpenCV's undistortPoints uses 5; 20 reach
#: 1e-10 px for |k1| r^2 < 0.3, tested).
UNDISTORT_ITERATIONS = 20


def rotation_matrix(rvec: ArrayLike) -> Float64Array:
    """Rotation matrix (3, 3) of a rotation vector (axis times angle, rad; Rodrigues)."""
    r = np.asarray(rvec, dtype=np.float64).reshape(3)
    theta = float(np.linalg.norm(r))
    if theta < 1e-15:
        return np.eye(3)
    k = r / theta
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(theta) * kx + (1.0 - math.cos(theta)) * (kx @ kx)


def _array(value: ArrayLike, shape: tuple[int, ...], name: str) -> Float64Array:
    a = np.asarray(value, dtype=np.float64)
    if a.size != int(np.prod(shape)) or not np.isfinite(a).all():
        raise InputError(f"{name}={value!r}: expected {int(np.prod(shape))} finite numbers")
    return a.reshape(shape)


@dataclass(frozen=True)
class CameraModel:
    """One pinhole camera with radial/tangential distortion (OpenCV's model).

    Attributes
    ----------
    fx, fy : float
        Focal lengths, px.
    cx, cy : float
        Principal point, px (column, row).
    dist : tuple of 5 floats
        ``(k1, k2, p1, p2, k3)``, dimensionless.
    image_shape : (rows, cols)
        Image size, px.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    dist: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)
    image_shape: tuple[int, int] = (512, 512)

    def __post_init__(self) -> None:
        for name in ("fx", "fy"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise InputError(f"{name}={v!r}: the focal length must be > 0 px, e.g. 2000")
        for name in ("cx", "cy"):
            if not math.isfinite(getattr(self, name)):
                raise InputError(f"{name}={getattr(self, name)!r}: must be finite px")
        d = tuple(float(x) for x in self.dist)
        if len(d) != 5 or not all(math.isfinite(x) for x in d):
            raise InputError(f"dist={self.dist!r}: expected 5 finite numbers (k1, k2, p1, p2, k3)")
        object.__setattr__(self, "dist", d)
        shp = tuple(int(x) for x in self.image_shape)
        if len(shp) != 2 or min(shp) < 8:
            raise InputError(f"image_shape={self.image_shape!r}: expected (rows, cols) >= 8 px")
        object.__setattr__(self, "image_shape", shp)
        for name in ("fx", "fy", "cx", "cy"):
            object.__setattr__(self, name, float(getattr(self, name)))

    @property
    def matrix(self) -> Float64Array:
        """The 3 x 3 intrinsic matrix K (OpenCV's cameraMatrix)."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def distort(self, ab: ArrayLike) -> Float64Array:
        """Distorted normalised coordinates of ideal ones, shape (..., 2) as (a, b)."""
        p = np.asarray(ab, dtype=np.float64)
        a, b = p[..., 0], p[..., 1]
        k1, k2, p1, p2, k3 = self.dist
        r2 = a * a + b * b
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        ad = a * radial + 2.0 * p1 * a * b + p2 * (r2 + 2.0 * a * a)
        bd = b * radial + p1 * (r2 + 2.0 * b * b) + 2.0 * p2 * a * b
        return np.stack([ad, bd], axis=-1)

    def undistort(self, abd: ArrayLike) -> Float64Array:
        """Ideal normalised coordinates of distorted ones (fixed-point iteration, as
        OpenCV's undistortPoints), shape (..., 2)."""
        d = np.asarray(abd, dtype=np.float64)
        if not any(self.dist):
            return d.copy()
        k1, k2, p1, p2, k3 = self.dist
        a, b = d[..., 0].copy(), d[..., 1].copy()
        for _ in range(UNDISTORT_ITERATIONS):
            r2 = a * a + b * b
            radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
            da = 2.0 * p1 * a * b + p2 * (r2 + 2.0 * a * a)
            db = p1 * (r2 + 2.0 * b * b) + 2.0 * p2 * a * b
            a = (d[..., 0] - da) / radial
            b = (d[..., 1] - db) / radial
        return np.stack([a, b], axis=-1)

    def project(self, xc: ArrayLike) -> Float64Array:
        """Image points ``(row, col)`` px of camera-frame points ``xc`` (..., 3) mm;
        NaN for points at or behind the camera (Z <= 0)."""
        p = np.asarray(xc, dtype=np.float64)
        z = p[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            ab = np.where((z > 0)[..., None], p[..., :2] / z[..., None], np.nan)
        d = self.distort(ab)
        return np.stack([self.fy * d[..., 1] + self.cy, self.fx * d[..., 0] + self.cx], axis=-1)

    def normalised(self, rc: ArrayLike) -> Float64Array:
        """Ideal normalised coordinates ``(a, b)`` of image points ``(row, col)`` px
        (the distortion removed), shape (..., 2)."""
        q = np.asarray(rc, dtype=np.float64)
        d = np.stack([(q[..., 1] - self.cx) / self.fx, (q[..., 0] - self.cy) / self.fy], -1)
        return self.undistort(d)

    def rays(self, rc: ArrayLike) -> Float64Array:
        """Directions (..., 3) (not normalised, Z = 1) of the rays through image points
        ``(row, col)`` px, in the camera frame."""
        ab = self.normalised(rc)
        return np.concatenate([ab, np.ones((*ab.shape[:-1], 1))], axis=-1)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (docs/stereo.md, "Rig file")."""
        return {
            "fx": self.fx,
            "fy": self.fy,
            "cx": self.cx,
            "cy": self.cy,
            "dist": list(self.dist),
            "image_shape": list(self.image_shape),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any], name: str = "camera") -> CameraModel:
        try:
            return cls(
                fx=float(data["fx"]),
                fy=float(data["fy"]),
                cx=float(data["cx"]),
                cy=float(data["cy"]),
                dist=tuple(float(x) for x in data.get("dist", (0,) * 5)),  # type: ignore[arg-type]
                image_shape=tuple(int(x) for x in data["image_shape"]),  # type: ignore[arg-type]
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise ConfigError(f"{name}: {exc} (keys fx, fy, cx, cy, dist, image_shape)") from exc


@dataclass(frozen=True)
class StereoRig:
    """Two cameras and the right camera's pose in the left camera's frame.

    Attributes
    ----------
    left, right : CameraModel
    rotation : ndarray, shape (3, 3)
        ``R`` of ``X_R = R X_L + t`` (OpenCV stereoCalibrate's R).
    translation : ndarray, shape (3,)
        ``t``, mm.
    rms : float
        RMS reprojection error of the calibration, px (NaN when not calibrated).
    info : dict
        Provenance (board, images, date), kept in the file.
    """

    left: CameraModel
    right: CameraModel
    rotation: Float64Array
    translation: Float64Array
    rms: float = float("nan")
    info: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        r = _array(self.rotation, (3, 3), "rotation")
        if not np.allclose(r @ r.T, np.eye(3), atol=1e-6) or np.linalg.det(r) < 0:
            raise InputError("rotation: not a rotation matrix (R R^T = I, det R = +1)")
        t = _array(self.translation, (3,), "translation")
        if np.linalg.norm(t) == 0:
            raise InputError("translation=(0, 0, 0): the two cameras need a baseline")
        r.setflags(write=False)
        t.setflags(write=False)
        object.__setattr__(self, "rotation", r)
        object.__setattr__(self, "translation", t)

    @property
    def baseline(self) -> float:
        """Distance between the optical centres, mm."""
        return float(np.linalg.norm(self.translation))

    @property
    def right_centre(self) -> Float64Array:
        """Optical centre of the right camera in the left frame, mm: ``-R^T t``."""
        return np.asarray(-self.rotation.T @ self.translation)

    @property
    def stereo_angle(self) -> float:
        """Angle between the two optical axes, deg."""
        c = float(np.clip(self.rotation[2, 2], -1.0, 1.0))  # z_R . z_L in the left frame
        return math.degrees(math.acos(c))

    def to_right(self, x: ArrayLike) -> Float64Array:
        """Left-frame points (..., 3) in the right camera's frame."""
        p = np.asarray(x, dtype=np.float64)
        return np.asarray(p @ self.rotation.T + self.translation)

    def project(self, x: ArrayLike) -> tuple[Float64Array, Float64Array]:
        """``(row, col)`` in the left and the right image of left-frame points (..., 3)."""
        return self.left.project(x), self.right.project(self.to_right(x))

    @property
    def fundamental(self) -> Float64Array:
        """Fundamental matrix F (3, 3) of the ideal (undistorted) pixel coordinates
        ``(x, y, 1) = (col, row, 1)``: ``x_R^T F x_L = 0``."""
        t = self.translation
        tx = np.array([[0.0, -t[2], t[1]], [t[2], 0.0, -t[0]], [-t[1], t[0], 0.0]])
        e = tx @ self.rotation
        return np.asarray(np.linalg.inv(self.right.matrix).T @ e @ np.linalg.inv(self.left.matrix))

    def converge_point(self) -> Float64Array:
        """The point nearest both optical axes (left frame, mm): a rough working distance
        for the start of the stereo matching."""
        c_l, d_l = np.zeros(3), np.array([0.0, 0.0, 1.0])
        c_r, d_r = self.right_centre, self.rotation.T @ np.array([0.0, 0.0, 1.0])
        a = np.array([[d_l @ d_l, -d_l @ d_r], [d_l @ d_r, -d_r @ d_r]])
        b = np.array([(c_r - c_l) @ d_l, (c_r - c_l) @ d_r])
        try:
            s, u = np.linalg.solve(a, b)
        except np.linalg.LinAlgError:
            return np.array([0.0, 0.0, 10.0 * self.baseline])
        if not s > 0:
            return np.array([0.0, 0.0, 10.0 * self.baseline])
        return np.asarray(0.5 * ((c_l + s * d_l) + (c_r + u * d_r)))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (docs/stereo.md, "Rig file")."""
        return {
            "format": "dicblur-stereo-rig",
            "version": 1,
            "units": "mm",
            "left": self.left.to_dict(),
            "right": self.right.to_dict(),
            "R": self.rotation.tolist(),
            "T": self.translation.tolist(),
            "rms_px": None if not math.isfinite(self.rms) else float(self.rms),
            "info": dict(self.info),
            "dicblur": __version__,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any], name: str = "rig") -> StereoRig:
        version = data.get("version", 1)
        if data.get("format") == "dicblur-stereo-rig" and not (
            isinstance(version, int) and version <= 1
        ):
            raise ConfigError(
                f"{name}: rig file version {version!r}, this dicblur reads version 1; "
                "update dicblur or write the rig again with dicblur stereo calibrate"
            )
        try:
            rms = data.get("rms_px")
            return cls(
                left=CameraModel.from_dict(data["left"], f"{name}: left"),
                right=CameraModel.from_dict(data["right"], f"{name}: right"),
                rotation=np.asarray(data["R"], dtype=np.float64),
                translation=np.asarray(data["T"], dtype=np.float64).ravel(),
                rms=float("nan") if rms is None else float(rms),
                info=dict(data.get("info", {})),
            )
        except ConfigError:
            raise  # a camera's own message, which names the file and the key
        except (KeyError, TypeError, ValueError) as exc:
            raise ConfigError(f"{name}: {exc!s} (expected keys left, right, R, T)") from exc


def _yaml_write(rig: StereoRig, path: Path) -> None:
    import cv2

    tmp = path.with_name(f".{path.stem}.tmp{path.suffix}")
    fs = cv2.FileStorage(str(tmp), cv2.FILE_STORAGE_WRITE)
    try:
        for side, cam in (("1", rig.left), ("2", rig.right)):
            fs.write(f"M{side}", cam.matrix)
            fs.write(f"D{side}", np.asarray(cam.dist, dtype=np.float64).reshape(1, 5))
            fs.write(f"size{side}", np.array([[cam.image_shape[1], cam.image_shape[0]]], float))
        fs.write("R", np.asarray(rig.rotation))
        fs.write("T", np.asarray(rig.translation).reshape(3, 1))
        fs.write("rms", float(rig.rms) if math.isfinite(rig.rms) else -1.0)
    finally:
        fs.release()
    os.replace(tmp, path)


def _yaml_read(path: Path) -> StereoRig:
    import cv2

    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    try:
        if not fs.isOpened():
            raise ConfigError(f"rig={str(path)!r}: cannot be read as OpenCV YAML")

        def mat(key: str) -> Float64Array:
            node = fs.getNode(key)
            m = None if node.empty() else node.mat()
            if m is None:
                raise ConfigError(f"rig={str(path)!r}: the key {key} is missing (docs/stereo.md)")
            return np.asarray(m, dtype=np.float64)

        cams = []
        for side in ("1", "2"):
            k, d, size = mat(f"M{side}"), mat(f"D{side}").ravel(), mat(f"size{side}").ravel()
            d = np.concatenate([d, np.zeros(max(0, 5 - d.size))])[:5]
            cams.append(
                CameraModel(
                    fx=k[0, 0],
                    fy=k[1, 1],
                    cx=k[0, 2],
                    cy=k[1, 2],
                    dist=tuple(d),  # type: ignore[arg-type]
                    image_shape=(int(size[1]), int(size[0])),
                )
            )
        rms_node = fs.getNode("rms")
        rms = float("nan") if rms_node.empty() else float(rms_node.real())
        return StereoRig(
            left=cams[0],
            right=cams[1],
            rotation=mat("R"),
            translation=mat("T").ravel(),
            rms=rms if rms >= 0 else float("nan"),
        )
    finally:
        fs.release()


def save_rig(rig: StereoRig, path: str | os.PathLike[str]) -> Path:
    """Write ``rig`` to ``path``: ``.json`` (dicblur's format) or ``.yml``/``.yaml``/``.xml``
    (OpenCV FileStorage: M1, D1, size1, M2, D2, size2, R, T, rms), atomically."""
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix == ".json":
        return write_text(p, json.dumps(rig.to_dict(), indent=2) + "\n")
    if suffix in (".yml", ".yaml", ".xml"):
        _yaml_write(rig, p)
        return p
    raise InputError(f"path={str(p)!r}: use a .json, .yml, .yaml or .xml rig file name")


def load_rig(path: str | os.PathLike[str]) -> StereoRig:
    """Read a rig file written by :func:`save_rig` (or by OpenCV with the same keys)."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"rig={str(p)!r}: no such file (write one with dicblur stereo calibrate)")
    suffix = p.suffix.lower()
    if suffix == ".json":
        try:
            data = json.loads(p.read_text())
        except (OSError, ValueError) as exc:
            raise ConfigError(f"rig={str(p)!r}: not valid JSON ({exc})") from exc
        if not isinstance(data, dict):
            raise ConfigError(f"rig={str(p)!r}: expected a JSON object")
        return StereoRig.from_dict(data, name=f"rig={str(p)!r}")
    if suffix in (".yml", ".yaml", ".xml"):
        return _yaml_read(p)
    raise ConfigError(f"rig={str(p)!r}: use a .json, .yml, .yaml or .xml rig file")
