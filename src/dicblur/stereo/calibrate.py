"""Stereo calibration from checkerboard image pairs with OpenCV (docs/stereo.md).

Per image: ``cv2.findChessboardCorners`` then ``cv2.cornerSubPix`` (11 x 11 window);
per camera ``cv2.calibrateCamera`` (Zhang's method; distortion k1, k2, p1, p2, with k3
fixed at 0 unless ``k3=True``: a few views do not determine it); then
``cv2.stereoCalibrate`` with the intrinsics fixed for R and T. The RMS reprojection error
(px) of the stereo step is the rig's ``rms``.
"""

from __future__ import annotations

import os
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..arrays import Float32Array, Float64Array
from ..errors import ImageReadError, InputError
from ..io import load_image
from ..sequence import natural_key
from .camera import CameraModel, StereoRig

__all__ = ["board_points", "calibrate_rig", "find_corners", "pair_images"]

_SIDE = re.compile(r"(left|right)", re.IGNORECASE)


def board_points(board: tuple[int, int], square: float) -> Float32Array:
    """Inner-corner coordinates of the board (cols x rows corners), (n, 3) mm, z = 0,
    in OpenCV's order (along a row first)."""
    nx, ny = board
    g = np.zeros((nx * ny, 3), np.float32)
    g[:, :2] = np.mgrid[0:nx, 0:ny].T.reshape(-1, 2) * float(square)
    return g


def find_corners(image: Float64Array, board: tuple[int, int], name: str) -> Float32Array:
    """Sub-pixel inner corners of the board in ``image``, (n, 1, 2) as OpenCV's (x, y).

    Raises
    ------
    InputError
        Naming the image when the board (all of its ``board`` inner corners) is not found.
    """
    import cv2

    img = np.asarray(image, dtype=np.float64)
    lo, hi = float(img.min()), float(img.max())
    if not hi > lo:
        raise InputError(f"image {name!r}: flat image, no checkerboard in it")
    u8 = np.clip((img - lo) / (hi - lo) * 255.0, 0, 255).astype(np.uint8)
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    ok, corners = cv2.findChessboardCorners(u8, board, flags=flags)
    if not ok or corners is None or len(corners) != board[0] * board[1]:
        raise InputError(
            f"image {name!r}: no {board[0]}x{board[1]} checkerboard found (check --board: "
            "inner corners per row x per column, the whole board in view, in focus); "
            "remove the image or retake it"
        )
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4)
    cv2.cornerSubPix(u8, corners, (11, 11), (-1, -1), crit)
    return np.asarray(corners, dtype=np.float32)


def pair_images(paths: Sequence[str | os.PathLike[str]]) -> list[tuple[Path, Path]]:
    """Left/right pairs of calibration images.

    Two folders: their images in natural order, pair by pair. Otherwise files whose names
    hold ``left`` or ``right`` (any case), paired by the rest of the name
    (``left_03.png`` with ``right_03.png``).
    """
    ps = [Path(p) for p in paths]
    exts = {".png", ".tif", ".tiff", ".bmp", ".jpg", ".jpeg"}
    if len(ps) == 2 and all(p.is_dir() for p in ps):
        sides = [
            sorted(
                (f for f in p.iterdir() if f.suffix.lower() in exts),
                key=lambda f: natural_key(f.name),
            )
            for p in ps
        ]
        if len(sides[0]) != len(sides[1]) or not sides[0]:
            raise InputError(
                f"IMAGES={str(ps[0])!r} {str(ps[1])!r}: {len(sides[0])} and {len(sides[1])} "
                "images; the two folders need the same number of images (>= 1)"
            )
        return list(zip(sides[0], sides[1], strict=True))
    left: dict[str, Path] = {}
    right: dict[str, Path] = {}
    for p in ps:
        if not p.is_file():
            raise ImageReadError(f"image {str(p)!r}: no such file")
        m = _SIDE.search(p.name)
        if m is None:
            raise InputError(
                f"image {str(p)!r}: its name says neither left nor right (name the pairs "
                "left_01.png / right_01.png, or give two folders LEFT RIGHT)"
            )
        key = _SIDE.sub("", p.name, count=1).lower()
        (left if m.group(1).lower() == "left" else right)[key] = p
    for a, b, side in ((left, right, "right"), (right, left, "left")):
        for k, p in a.items():
            if k not in b:
                raise InputError(f"image {str(p)!r}: no {side} image of the same name")
    keys = sorted(left, key=natural_key)
    if not keys:
        raise InputError("IMAGES: no calibration image pairs given")
    return [(left[k], right[k]) for k in keys]


def calibrate_rig(
    pairs: Sequence[tuple[Float64Array, Float64Array]],
    *,
    board: tuple[int, int],
    square: float,
    names: Sequence[tuple[str, str]] | None = None,
    k3: bool = False,
) -> StereoRig:
    """Calibrate a stereo rig from checkerboard image pairs.

    Parameters
    ----------
    pairs : sequence of (left, right) images
        Grey levels, each (rows, cols); at least 3 pairs, all of one size per camera.
    board : (cols, rows)
        Inner corners per row and per column of the board (``9x6``).
    square : float
        Side of a square, mm.
    names : sequence of (str, str), optional
        The images' names for the error messages (default ``left[i]``, ``right[i]``).
    k3 : bool
        Estimate the sixth-order radial term too.

    Returns
    -------
    StereoRig
        With ``rms`` the stereo RMS reprojection error (px) and ``info`` the per-camera
        RMS, the board and the number of pairs.
    """
    import cv2

    if len(pairs) < 3:
        raise InputError(
            f"IMAGES: {len(pairs)} pair(s); calibration needs at least 3 (10-20 is usual)"
        )
    if not square > 0:
        raise InputError(f"square={square!r}: must be > 0 mm, e.g. 5mm")
    nms = (
        list(names)
        if names is not None
        else [(f"left[{i}]", f"right[{i}]") for i in range(len(pairs))]
    )
    obj = board_points(board, square)
    pts_l, pts_r = [], []
    shape_l: tuple[int, ...] | None = None
    shape_r: tuple[int, ...] | None = None
    for (lft, rgt), (nl, nr) in zip(pairs, nms, strict=True):
        for img, nm, side in ((lft, nl, "l"), (rgt, nr, "r")):
            shp = np.asarray(img).shape
            ref = shape_l if side == "l" else shape_r
            if ref is not None and shp != ref:
                raise InputError(
                    f"image {nm!r}: size {shp} differs from the camera's first image {ref}"
                )
            if side == "l":
                shape_l = shp
            else:
                shape_r = shp
        pts_l.append(find_corners(lft, board, nl))
        pts_r.append(find_corners(rgt, board, nr))
    assert shape_l is not None and shape_r is not None
    flags = 0 if k3 else cv2.CALIB_FIX_K3
    objs = [obj] * len(pairs)
    cams = []
    rms_cam = []
    for pts, shp in ((pts_l, shape_l), (pts_r, shape_r)):
        size = (int(shp[1]), int(shp[0]))
        rms, k, d, _, _ = cv2.calibrateCamera(objs, pts, size, None, None, flags=flags)
        cams.append((k, d))
        rms_cam.append(float(rms))
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-10)
    rms, k1, d1, k2, d2, rot, t, _, _ = cv2.stereoCalibrate(
        objs,
        pts_l,
        pts_r,
        cams[0][0],
        cams[0][1],
        cams[1][0],
        cams[1][1],
        (int(shape_l[1]), int(shape_l[0])),
        criteria=crit,
        flags=cv2.CALIB_FIX_INTRINSIC,
    )

    def model(k: Any, d: Any, shp: tuple[int, ...]) -> CameraModel:
        dd = np.zeros(5)
        flat = np.asarray(d, dtype=np.float64).ravel()[:5]
        dd[: flat.size] = flat
        # OpenCV's pixel centres are at integers too: (x, y) = (col, row)
        return CameraModel(
            fx=float(k[0, 0]),
            fy=float(k[1, 1]),
            cx=float(k[0, 2]),
            cy=float(k[1, 2]),
            dist=tuple(dd),  # type: ignore[arg-type]
            image_shape=(int(shp[0]), int(shp[1])),
        )

    return StereoRig(
        left=model(k1, d1, shape_l),
        right=model(k2, d2, shape_r),
        rotation=np.asarray(rot, dtype=np.float64),
        translation=np.asarray(t, dtype=np.float64).ravel(),
        rms=float(rms),
        info={
            "board": f"{board[0]}x{board[1]}",
            "square_mm": float(square),
            "pairs": len(pairs),
            "rms_left_px": rms_cam[0],
            "rms_right_px": rms_cam[1],
        },
    )


def load_pairs(
    pairs: Sequence[tuple[Path, Path]],
) -> list[tuple[Float64Array, Float64Array]]:
    """The images of :func:`pair_images` as grey-level arrays."""
    return [(load_image(a), load_image(b)) for a, b in pairs]
