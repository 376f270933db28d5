"""Reading and writing grey-level images.

Supported formats: TIFF (8/16/32-bit integer or float, uncompressed, LZW, Deflate, PackBits),
PNG (8/16-bit), BMP and JPEG. TIFF files are read with ``tifffile``; compressions it cannot
decode without extra codecs (e.g. LZW) fall back to Pillow, which decodes them natively.
"""

from __future__ import annotations

import hashlib
import logging
import os
import warnings
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._validation import as_image
from .errors import ImageReadError, InputError

__all__ = ["file_sha256", "load_image", "save_image"]

logger = logging.getLogger("dicblur")

_TIFF = {".tif", ".tiff"}
_PIL_FORMATS = {".png", ".bmp", ".jpg", ".jpeg"}
# ITU-R BT.601 luma weights: the conversion most cameras and image tools use.
_LUMA = np.array([0.299, 0.587, 0.114])


def file_sha256(path: str | os.PathLike[str]) -> str:
    """SHA-256 hex digest of a file's bytes (used as provenance of input images)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _read_tiff(path: Path) -> np.ndarray:
    import tifffile

    try:
        return np.asarray(tifffile.imread(path, key=0))
    except ValueError as exc:
        if "imagecodecs" not in str(exc):
            raise
        logger.debug("tifffile cannot decode %s (%s); using Pillow", path, exc)
        return _read_pillow(path)


def _read_pillow(path: Path) -> np.ndarray:
    from PIL import Image

    with Image.open(path) as im:
        im.load()
        if im.mode in ("I;16", "I;16B", "I;16L"):
            return np.asarray(im, dtype=np.uint16)
        if im.mode == "P":
            return np.asarray(im.convert("RGBA" if "transparency" in im.info else "RGB"))
        return np.asarray(im)


def _to_grey(arr: np.ndarray, path: Path) -> np.ndarray:
    if arr.ndim == 2:
        return arr
    if arr.ndim == 3 and arr.shape[-1] in (3, 4):
        warnings.warn(
            f"{path.name}: colour image converted to grey with BT.601 luma weights "
            "(0.299 R + 0.587 G + 0.114 B); alpha ignored",
            UserWarning,
            stacklevel=3,
        )
        return arr[..., :3].astype(np.float64) @ _LUMA
    if arr.ndim == 3 and arr.shape[-1] in (1, 2):  # grey (+ alpha)
        return arr[..., 0]
    if arr.ndim == 3 and arr.shape[0] > 1:
        warnings.warn(
            f"{path.name}: multi-page image with {arr.shape[0]} pages; reading page 0",
            UserWarning,
            stacklevel=3,
        )
        return _to_grey(arr[0], path)
    raise ImageReadError(f"path={str(path)!r}: unsupported image layout {arr.shape}")


def load_image(path: str | os.PathLike[str]) -> NDArray[np.float64]:
    """Read an image file as grey levels.

    Parameters
    ----------
    path : str or path-like
        TIFF (8/16-bit, incl. LZW-compressed), PNG (8/16-bit), BMP or JPEG file.

    Returns
    -------
    ndarray of float64, shape (rows, cols)
        Grey levels on the file's own scale (0..255 for 8-bit, 0..65535 for 16-bit files);
        nothing is rescaled. Colour images are converted to grey with BT.601 luma weights,
        with a ``UserWarning``.

    Raises
    ------
    ImageReadError
        If the file is missing, a directory, empty, truncated, not an image, or its pixels
        are not finite.
    """
    p = Path(path)
    if not p.exists():
        raise ImageReadError(f"path={str(p)!r}: no such file; check the path")
    if p.is_dir():
        raise ImageReadError(f"path={str(p)!r}: is a directory, expected an image file")
    if p.stat().st_size == 0:
        raise ImageReadError(f"path={str(p)!r}: the file is empty (0 bytes)")
    suffix = p.suffix.lower()
    try:
        if suffix in _TIFF:
            arr = _read_tiff(p)
        elif suffix in _PIL_FORMATS:
            arr = _read_pillow(p)
        else:
            # Unknown extension: let Pillow sniff the content.
            arr = _read_pillow(p)
    except ImageReadError:
        raise
    except Exception as exc:
        raise ImageReadError(
            f"path={str(p)!r}: cannot be read as an image ({type(exc).__name__}: {exc}); "
            "is the file truncated or not an image? Supported: TIFF, PNG, BMP, JPEG"
        ) from exc
    arr = _to_grey(np.asarray(arr), p)
    if np.iscomplexobj(arr) or arr.dtype == object:
        raise ImageReadError(f"path={str(p)!r}: pixels are not real grey levels ({arr.dtype})")
    try:
        return as_image(arr, "image", min_size=1)
    except InputError as exc:
        raise ImageReadError(f"path={str(p)!r}: {exc}") from exc


def save_image(
    path: str | os.PathLike[str], image: ArrayLike, *, bit_depth: int = 8
) -> Path:
    """Write grey levels to an image file.

    Values are rounded to the nearest integer (ties to even, ``numpy.rint``) and clipped to
    ``0 .. 2**bit_depth - 1``; a ``UserWarning`` reports how many pixels were clipped.
    No rescaling is applied: an image in 0..255 saved at ``bit_depth=16`` keeps values
    0..255.

    Parameters
    ----------
    path : str or path-like
        Output file; the format follows the extension (``.tif``/``.tiff``: uncompressed
        TIFF, ``.png``; ``.bmp`` only for 8-bit).
    image : array_like, shape (rows, cols)
        Finite grey levels.
    bit_depth : {8, 16}
        Bits per pixel of the stored file.

    Returns
    -------
    pathlib.Path
        The path written.
    """
    if bit_depth not in (8, 16):
        raise InputError(f"bit_depth={bit_depth!r}: must be 8 or 16")
    img = as_image(image, "image", min_size=1)
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix not in _TIFF | {".png", ".bmp"}:
        raise InputError(
            f"path={str(p)!r}: unsupported extension {suffix!r}; use .tif, .tiff, .png or .bmp"
        )
    if suffix == ".bmp" and bit_depth != 8:
        raise InputError(f"bit_depth={bit_depth}: BMP files are 8-bit only; use .tif or .png")
    top = 2**bit_depth - 1
    rounded = np.rint(img)
    clipped = int(np.count_nonzero((rounded < 0) | (rounded > top)))
    if clipped:
        warnings.warn(
            f"save_image: {clipped} pixel(s) outside 0..{top} were clipped", UserWarning,
            stacklevel=2,
        )
    data = np.clip(rounded, 0, top).astype(np.uint8 if bit_depth == 8 else np.uint16)
    if not p.parent.exists():
        raise InputError(f"path={str(p)!r}: the folder {str(p.parent)!r} does not exist")
    if suffix in _TIFF:
        import tifffile

        tifffile.imwrite(p, data, photometric="minisblack")
    else:
        from PIL import Image

        Image.fromarray(data).save(p)
    return p
