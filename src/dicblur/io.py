"""Reading and writing grey-level images, and writing any output file safely.

Supported formats: TIFF (8/16/32-bit integer or float, uncompressed, LZW, Deflate, PackBits),
PNG (8/16-bit), BMP and JPEG. TIFF files are read with ``tifffile``; compressions it cannot
decode without extra codecs (e.g. LZW) fall back to Pillow, which decodes them natively.

Reliability rules shared by every command (docs/reliability.md):

- **Size limit.** An image's declared size is read from its header and checked against
  :func:`max_pixels` (default 100 Mpx; ``DICBLUR_MAX_PIXELS``, ``max_pixels=``, or
  ``dicblur --max-pixels``) before any pixel is decoded, so a decompression bomb is refused
  at the cost of reading a header.
- **Outputs.** :func:`check_output` is called on every output path before the work starts:
  the parent folder must exist (nothing creates missing parents), a file output must not be
  a folder and a folder output must not be a file. :func:`atomic_path` /
  :func:`write_text` write through a temporary file in the same folder, fsync it and
  rename it over the target, so a crash leaves either the old file or the new one, never
  half a file.
"""

from __future__ import annotations

import contextlib
import hashlib
import logging
import math
import os
import stat
import tempfile
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np
from numpy.typing import ArrayLike

from .arrays import Float64Array
from .checks import as_image
from .errors import ImageReadError, InputError

__all__ = [
    "DEFAULT_MAX_PIXELS",
    "ImageHeader",
    "atomic_open",
    "atomic_path",
    "check_output",
    "check_pixels",
    "file_sha256",
    "fsync_path",
    "load_image",
    "max_pixels",
    "read_image_header",
    "save_image",
    "write_text",
]

logger = logging.getLogger("dicblur")

_TIFF = {".tif", ".tiff"}
_PIL_FORMATS = {".png", ".bmp", ".jpg", ".jpeg"}
# ITU-R BT.601 luma weights: the conversion most cameras and image tools use.
_LUMA = np.array([0.299, 0.587, 0.114])

DEFAULT_MAX_PIXELS = 100_000_000
"""Largest image (rows x cols, after supersampling) read or generated without an override:
100 Mpx is 800 MB as float64, and a DIC or blur stage holds a few such copies."""
_ENV_MAX_PIXELS = "DICBLUR_MAX_PIXELS"


def max_pixels(override: int | float | str | None = None) -> int:
    """The image size limit in pixels: ``override``, else ``$DICBLUR_MAX_PIXELS``, else
    :data:`DEFAULT_MAX_PIXELS`."""
    name = "max_pixels"
    value: Any = override
    if value is None:
        value = os.environ.get(_ENV_MAX_PIXELS)
        name = _ENV_MAX_PIXELS
        if value is None or value == "":
            return DEFAULT_MAX_PIXELS
    try:
        n = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name}={value!r}: expected a number of pixels, e.g. 4e8") from None
    if not math.isfinite(n) or n < 1:
        raise InputError(f"{name}={value!r}: expected a number of pixels >= 1, e.g. 4e8")
    return int(n)


def check_pixels(
    shape: tuple[int, ...], what: str, *, factor: int = 1, limit: int | float | None = None
) -> None:
    """Refuse an image of ``shape`` (times ``factor`` pixels per pixel, e.g. a supersampled
    grid) above the size limit, before it is allocated.

    Raises
    ------
    InputError
        Naming ``what``, the size, the memory it would take and how to raise the limit.
    """
    lim = max_pixels(limit)
    n = math.prod(int(s) for s in shape) * int(factor)
    if n > lim:
        dims = "x".join(str(int(s)) for s in shape)
        extra = f" x {factor} (supersampling)" if factor != 1 else ""
        raise InputError(
            f"{what}: {dims} px{extra} = {n / 1e6:.4g} Mpx, about {8 * n / 1e9:.3g} GB per "
            f"float64 copy, is above the limit of {lim / 1e6:.4g} Mpx; use a smaller image, "
            f"or raise the limit (dicblur --max-pixels N, {_ENV_MAX_PIXELS}=N or "
            "max_pixels=N)"
        )


# ------------------------------------------------------------------------- output paths
def check_output(
    path: str | os.PathLike[str],
    name: str = "path",
    *,
    folder: bool = False,
    suffixes: tuple[str, ...] | None = None,
    inputs: tuple[str | os.PathLike[str], ...] = (),
) -> Path:
    """Check an output path before any work is done, and return it as a ``Path``.

    The rule is the same for every command: the parent folder must exist (dicblur never
    creates missing parents); a file output must not be an existing folder, a folder
    output (``folder=True``, created later if absent) must not be an existing file; the
    parent must accept a new file (tried, not only asked: ``os.access`` says yes to root
    on a read-only mount); the output must not be one of ``inputs`` (the files the
    command reads: writing over one would destroy the data before, or while, it is read).

    Raises
    ------
    InputError
        Naming ``name`` (the option as the user typed it), the path and the fix.
    """
    p = Path(path)
    if str(path) == "":
        raise InputError(f"{name}='': give a file name")
    if suffixes is not None and not folder and p.suffix.lower() not in suffixes:
        raise InputError(
            f"{name}={str(p)!r}: unsupported extension {p.suffix.lower()!r}; "
            f"use {', '.join(suffixes)}"
        )
    parent = p.parent
    if not parent.exists():
        raise InputError(
            f"{name}={str(p)!r}: the folder {str(parent)!r} does not exist; "
            "create it first (dicblur does not create missing parent folders)"
        )
    if not parent.is_dir():
        raise InputError(f"{name}={str(p)!r}: {str(parent)!r} is not a folder")
    if folder:
        if p.exists() and not p.is_dir():
            raise InputError(
                f"{name}={str(p)!r}: exists and is not a folder; give a folder "
                "name (created if absent)"
            )
    elif p.is_dir():
        raise InputError(f"{name}={str(p)!r}: is a directory; give a file name inside it")
    for source in inputs:
        if _same_file(p, Path(source)):
            raise InputError(
                f"{name}={str(p)!r}: is also an input ({str(source)!r}); writing it would "
                "destroy the input: give another output name"
            )
    if not os.access(parent, os.W_OK | os.X_OK) or not _can_create(parent):
        raise InputError(
            f"{name}={str(p)!r}: the folder {str(parent)!r} is not writable; choose a "
            "folder where you can create files"
        )
    return p


def _same_file(a: Path, b: Path) -> bool:
    """Whether ``a`` and ``b`` name one file (a link or another spelling included)."""
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def _can_create(folder: Path) -> bool:
    """Create and delete a probe file in ``folder``: whether a new file can be written."""
    try:
        fd, name = tempfile.mkstemp(prefix=".dicblur-probe.", dir=folder)
    except OSError:
        return False
    os.close(fd)
    with contextlib.suppress(OSError):
        os.unlink(name)
    return True


def fsync_path(path: str | os.PathLike[str]) -> None:
    """Flush a file or folder to disk (``fsync`` of a read-only descriptor of it)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_dir(folder: Path) -> None:
    with contextlib.suppress(OSError):  # not every file system syncs a directory
        fsync_path(folder)


def _file_mode(target: Path) -> int:
    """Permission bits for a file written over ``target``."""
    with contextlib.suppress(OSError):
        return stat.S_IMODE(target.stat().st_mode)
    return 0o666 & ~_umask()


def _umask() -> int:
    """The process umask, read without changing it when the system says it (Linux)."""
    with contextlib.suppress(OSError, ValueError), open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    mask = os.umask(0o022)  # elsewhere: read by setting it, and put it back at once
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; on success fsync it and rename it over
    ``path`` (atomic on POSIX), on an exception delete it.

    The temporary name keeps the suffix, so writers that pick a format from the extension
    (Pillow, matplotlib, tifffile) still work. Use for any writer that takes a path::

        with atomic_path(out) as tmp:
            fig.savefig(tmp)
    """
    target = Path(path)
    fd, name = tempfile.mkstemp(
        prefix=f".{target.name}.", suffix=f".tmp{target.suffix}", dir=target.parent
    )
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        if tmp.is_file():
            # mkstemp makes the file 0600; the output gets the mode of a file the user
            # creates (0666 less the umask), or keeps the mode of the file it replaces
            os.chmod(tmp, _file_mode(target))
            with open(tmp, "rb+") as fh:
                os.fsync(fh.fileno())
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    _fsync_dir(target.parent)


@contextlib.contextmanager
def atomic_open(path: str | os.PathLike[str], mode: str = "w", **kwargs: Any) -> Iterator[IO[Any]]:
    """``open(path, mode)`` through :func:`atomic_path` (``mode`` ``"w"`` or ``"wb"``)."""
    if mode not in ("w", "wb"):
        raise InputError(f"mode={mode!r}: atomic_open writes new files only ('w' or 'wb')")
    if mode == "w":
        kwargs.setdefault("encoding", "utf-8")
    with atomic_path(path) as tmp, open(tmp, mode, **kwargs) as fh:
        yield fh
        fh.flush()


def write_text(path: str | os.PathLike[str], text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically; return the path."""
    with atomic_open(path, "w") as fh:
        fh.write(text)
    return Path(path)


def file_sha256(path: str | os.PathLike[str]) -> str:
    """SHA-256 hex digest of a file's bytes (used as provenance of input images)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


# ------------------------------------------------------------------------- reading
@dataclass(frozen=True)
class ImageHeader:
    """What an image file declares, read without decoding its pixels.

    Attributes
    ----------
    shape : (int, int)
        (rows, cols) of the first image in the file, px.
    channels : int
        Samples per pixel (1 grey, 2 grey + alpha, 3 RGB, 4 RGBA, ...).
    dtype : str
        Sample type as stored (``"uint8"``, ``"uint16"``, ``"float32"``, ...); a palette
        image gives its index type.
    pages : int
        Images in the file (TIFF pages; 1 for other formats, frames beyond the first are
        not counted).
    palette : bool
        Whether pixels are indices into a colour map.
    format : str
        ``"TIFF"``, ``"PNG"``, ``"BMP"``, ``"JPEG"``, ...
    """

    shape: tuple[int, int]
    channels: int
    dtype: str
    pages: int
    palette: bool
    format: str

    @property
    def bit_depth(self) -> int:
        """Bits per sample of the stored data."""
        return int(np.dtype(self.dtype).itemsize * 8)


def _pil_dtype(mode: str) -> str:
    return {
        "1": "bool",
        "L": "uint8",
        "P": "uint8",
        "LA": "uint8",
        "RGB": "uint8",
        "RGBA": "uint8",
        "CMYK": "uint8",
        "I;16": "uint16",
        "I;16B": "uint16",
        "I;16L": "uint16",
        "I": "int32",
        "F": "float32",
    }.get(mode, "uint8")


@contextlib.contextmanager
def _pil_limit(limit: int | None) -> Iterator[None]:
    # Pillow refuses images above 2 * MAX_IMAGE_PIXELS on its own: align its limit with
    # ours (we check the header ourselves first), and restore it afterwards.
    from PIL import Image

    old = Image.MAX_IMAGE_PIXELS
    Image.MAX_IMAGE_PIXELS = None if limit is None else max(int(limit), 1)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            yield
    finally:
        Image.MAX_IMAGE_PIXELS = old


@contextlib.contextmanager
def _quiet_tifffile() -> Iterator[None]:
    # tifffile logs damaged-file warnings on its own; the exception we raise says it
    log = logging.getLogger("tifffile")
    old = log.level
    log.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        log.setLevel(old)


def _header(p: Path) -> ImageHeader:
    suffix = p.suffix.lower()
    with open(p, "rb") as fh:
        magic = fh.read(4)
    if suffix in _TIFF or magic in (b"II*\0", b"MM\0*", b"II+\0", b"MM\0+"):
        import tifffile

        with _quiet_tifffile(), tifffile.TiffFile(p) as tif:
            page: Any = tif.pages[0]
            shape = tuple(int(s) for s in page.shape)
            axes = str(page.axes)
            spp = int(getattr(page, "samplesperpixel", 1))
            rows_cols = [s for s, a in zip(shape, axes, strict=False) if a in "YX"]
            other = [s for s, a in zip(shape, axes, strict=False) if a not in "YXS" and s > 1]
            if len(rows_cols) != 2 or other:
                raise ImageReadError(
                    f"path={str(p)!r}: TIFF page of shape {shape} (axes {axes}) is not a 2-D "
                    "image; save one 2-D plane per page"
                )
            return ImageHeader(
                shape=(rows_cols[0], rows_cols[1]),
                channels=spp,
                dtype=str(page.dtype),
                pages=len(tif.pages),
                palette=int(page.photometric) == 3,
                format="TIFF",
            )
    from PIL import Image

    with _pil_limit(None), Image.open(p) as im:  # the header only: we check its size
        cols, rows = im.size
        return ImageHeader(
            shape=(int(rows), int(cols)),
            channels=len(im.getbands()),
            dtype=_pil_dtype(im.mode),
            pages=1,
            palette=im.mode == "P",
            format=str(im.format),
        )


def read_image_header(path: str | os.PathLike[str]) -> ImageHeader:
    """Read an image file's header (size, channels, sample type) without its pixels.

    Raises
    ------
    ImageReadError
        If the file is missing, a folder, empty, or has no readable image header.
    """
    p = _check_input_file(path)
    try:
        return _header(p)
    except ImageReadError:
        raise
    except Exception as exc:
        raise _unreadable(p, exc) from exc


def _unreadable(p: Path, exc: BaseException) -> ImageReadError:
    """The error of a file whose decoder failed (``exc``): truncated, or not an image."""
    return ImageReadError(
        f"path={str(p)!r}: cannot be read as an image ({type(exc).__name__}: "
        f"{_short(exc)}); is the file truncated or not an image? Supported: TIFF, PNG, "
        "BMP, JPEG"
    )


def _short(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text if len(text) <= 120 else text[:117] + "..."


def _check_input_file(path: str | os.PathLike[str]) -> Path:
    p = Path(path)
    if not p.exists():
        raise ImageReadError(f"path={str(p)!r}: no such file; check the path")
    if p.is_dir():
        raise ImageReadError(f"path={str(p)!r}: is a directory, expected an image file")
    if p.stat().st_size == 0:
        raise ImageReadError(f"path={str(p)!r}: the file is empty (0 bytes)")
    return p


def _read_tiff(path: Path, limit: int) -> np.ndarray:
    import tifffile

    try:
        with _quiet_tifffile(), tifffile.TiffFile(path) as tif:
            page: Any = tif.pages[0]
            arr = np.asarray(page.asarray())
            axes = str(page.axes)
            if "S" in axes and axes.index("S") != len(axes) - 1:
                arr = np.moveaxis(arr, axes.index("S"), -1)  # planar: samples last
            if int(page.photometric) == 3 and page.colormap is not None:
                arr = _apply_colormap(arr, np.asarray(page.colormap))
            return arr
    except ValueError as exc:
        if "imagecodecs" not in str(exc):
            raise
        logger.debug("tifffile cannot decode %s (%s); using Pillow", path, exc)
        return _read_pillow(path, limit)


def _apply_colormap(index: np.ndarray, cmap: np.ndarray) -> np.ndarray:
    """RGB of a palette image, as the PNG path gives it (8-bit when the 16-bit colour map
    holds 8-bit values scaled by 257, as most writers store them)."""
    rgb = np.moveaxis(cmap[:, index.astype(np.intp)], 0, -1)
    if np.all(cmap % 257 == 0):
        return (rgb // 257).astype(np.uint8)
    return rgb.astype(np.uint16)


def _read_pillow(path: Path, limit: int) -> np.ndarray:
    from PIL import Image

    with _pil_limit(limit), Image.open(path) as im:
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
        rgb = arr[..., :3]
        if np.array_equal(rgb[..., 0], rgb[..., 1]) and np.array_equal(rgb[..., 0], rgb[..., 2]):
            return rgb[..., 0]  # grey stored as RGB (e.g. a grey palette): exact
        warnings.warn(
            f"{path.name}: colour image converted to grey with BT.601 luma weights "
            "(0.299 R + 0.587 G + 0.114 B); alpha ignored",
            UserWarning,
            stacklevel=3,
        )
        return rgb.astype(np.float64) @ _LUMA
    if arr.ndim == 3 and arr.shape[-1] in (1, 2):  # grey (+ alpha)
        return arr[..., 0]
    if arr.ndim == 3:
        raise ImageReadError(
            f"path={str(path)!r}: {arr.shape[-1]} channels per pixel; dicblur reads grey, "
            "grey + alpha, RGB or RGBA images: save the channel to analyse as a grey image"
        )
    raise ImageReadError(f"path={str(path)!r}: unsupported image layout {arr.shape}")


def load_image(
    path: str | os.PathLike[str], *, max_pixels: int | float | None = None
) -> Float64Array:
    """Read an image file as grey levels.

    Parameters
    ----------
    path : str or path-like
        TIFF (8/16-bit, incl. LZW-compressed), PNG (8/16-bit), BMP or JPEG file.
    max_pixels : int, optional
        Size limit (rows x cols); default :func:`max_pixels` (100 Mpx unless
        ``DICBLUR_MAX_PIXELS`` says otherwise). Checked on the header, before decoding.

    Returns
    -------
    ndarray of float64, shape (rows, cols)
        Grey levels on the file's own scale (0..255 for 8-bit, 0..65535 for 16-bit files);
        nothing is rescaled. Colour images are converted to grey with BT.601 luma weights,
        with a ``UserWarning``; palette images get their colour map applied first. A
        multi-page TIFF gives its first page, with a ``UserWarning``.

    Raises
    ------
    ImageReadError
        If the file is missing, a directory, empty, truncated, not an image, has more than
        4 channels, or its pixels are not finite real grey levels.
    InputError
        If the declared size exceeds the limit.
    """
    limit = _max_pixels(max_pixels)
    header = read_image_header(path)
    p = Path(path)
    check_pixels(header.shape, f"path={str(p)!r}", factor=max(header.channels, 1), limit=limit)
    if header.pages > 1:
        warnings.warn(
            f"{p.name}: multi-page image with {header.pages} pages; reading page 0",
            UserWarning,
            stacklevel=2,
        )
    try:
        if header.format == "TIFF":
            arr = _read_tiff(p, limit)
        else:
            arr = _read_pillow(p, limit)
    except (ImageReadError, InputError):
        raise
    except Exception as exc:
        raise _unreadable(p, exc) from exc
    arr = _to_grey(np.asarray(arr), p)
    if np.iscomplexobj(arr) or arr.dtype == object:
        raise ImageReadError(
            f"path={str(p)!r}: pixels are not real grey levels ({arr.dtype}); "
            "save a real-valued (integer or float) image"
        )
    try:
        return as_image(arr, "image", min_size=1)
    except InputError as exc:
        raise ImageReadError(f"path={str(p)!r}: {exc}") from exc


_max_pixels = max_pixels  # the keyword of load_image shadows the function's name


def save_image(path: str | os.PathLike[str], image: ArrayLike, *, bit_depth: int = 8) -> Path:
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
    check_output(p, "path")
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
            f"save_image: {clipped} pixel(s) outside 0..{top} were clipped",
            UserWarning,
            stacklevel=2,
        )
    data = np.clip(rounded, 0, top).astype(np.uint8 if bit_depth == 8 else np.uint16)
    check_output(p, "path")
    with atomic_path(p) as tmp:
        if suffix in _TIFF:
            import tifffile

            tifffile.imwrite(tmp, data, photometric="minisblack")
        else:
            from PIL import Image

            Image.fromarray(data).save(tmp, format="PNG" if suffix == ".png" else "BMP")
    return p
