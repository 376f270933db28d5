"""Lazy readers of high-speed recordings: one frame in memory at a time.

Sources (:func:`open_recording`):

- a folder of TIFF/PNG/BMP/JPEG images in natural order (``img2.tif`` before ``img10.tif``;
  hidden files such as macOS's ``._img2.tif`` left out), or a glob pattern
  (``"run1/*.png"``);
- a multi-page TIFF stack (pages read one at a time by ``tifffile``);
- a Phantom ``.cine`` file (``pims.Cine``: pure Python, random access to any frame, reads
  the setup's frame rate and shutter and the per-frame exposure tag);
- a Photron ``.cih``/``.cihx`` header with its ``.mraw`` data (the header parsed by
  ``pyMRAW.get_cih``; frames read one at a time, 12-bit packed data unpacked per frame, which
  pyMRAW itself would load whole).

Frames come out as float64 grey levels on the file's own scale (8, 10, 12 or 16-bit data,
nothing rescaled); ``bit_depth`` says which. A recording shorter than its header promises
(truncated copy) keeps its complete frames and warns; a frame of another size (or, in a
folder, of another data type than the first) raises :class:`~dicblur.errors.ImageReadError`
naming it.
"""

from __future__ import annotations

import math
import os
import re
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from glob import glob
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .arrays import Float64Array
from .errors import ImageReadError, InputError
from .io import load_image

__all__ = ["IMAGE_SUFFIXES", "LOSSY_SUFFIXES", "Recording", "natural_key", "open_recording"]

IMAGE_SUFFIXES = (".tif", ".tiff", ".png", ".bmp", ".jpg", ".jpeg")
#: Lossy formats among them: read, but their compression error is no part of any noise
#: model (``Recording.meta['lossy']`` names the format; :func:`dicblur.track` says so).
LOSSY_SUFFIXES = {".jpg": "JPEG", ".jpeg": "JPEG"}


def natural_key(name: str) -> tuple[Any, ...]:
    """Sort key that orders embedded numbers by value (``f2`` < ``f10``)."""
    parts = re.split(r"(\d+)", name)
    return tuple(int(p) if p.isdigit() else p.lower() for p in parts)


@dataclass
class Recording:
    """A lazily read sequence of grey-level frames.

    Attributes
    ----------
    source : str
        What was opened (path or glob pattern).
    kind : {"folder", "tiff-stack", "cine", "mraw"}
    n_frames : int
        Number of complete frames.
    shape : (rows, cols)
        Frame size, px.
    bit_depth : int
        Bits per pixel of the data (8, 10, 12, 16; 32/64 for float images).
    fps : float or None
        Frame rate from the file's metadata (Hz), None when the format has none.
    exposure : float or None
        Exposure time from the metadata (s), None when unknown.
    names : list of str
        Per-frame labels (file names for a folder, else ``"frame N"``).
    meta : dict
        Other metadata (JSON-ready).
    """

    source: str
    kind: str
    n_frames: int
    shape: tuple[int, int]
    bit_depth: int
    fps: float | None
    exposure: float | None
    names: list[str]
    _read: Callable[[int], NDArray[Any]] = field(repr=False)
    _close: Callable[[], None] | None = field(default=None, repr=False)
    meta: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return self.n_frames

    def __getitem__(self, index: int) -> Float64Array:
        return self.frame(index)

    def frame(self, index: int) -> Float64Array:
        """Frame ``index`` (0-based) as float64 grey levels, shape ``(rows, cols)``."""
        i = int(index)
        if i < 0:
            i += self.n_frames
        if not 0 <= i < self.n_frames:
            raise InputError(
                f"frame={index}: outside the recording's {self.n_frames} frames "
                f"(0..{self.n_frames - 1})"
            )
        arr = np.asarray(self._read(i))
        if arr.ndim == 3 and arr.shape[-1] in (3, 4):
            arr = arr[..., :3].astype(np.float64) @ np.array([0.299, 0.587, 0.114])
        if arr.shape != self.shape:
            raise ImageReadError(
                f"frame {i} ({self.names[i]}): {arr.shape[0]}x{arr.shape[1]} px, but the "
                f"recording's frames are {self.shape[0]}x{self.shape[1]} px; remove or crop "
                "that frame"
            )
        out = np.asarray(arr, dtype=np.float64)
        # integer grey levels are finite (the check costs ~0.1 ms per 512^2 frame)
        if not np.issubdtype(arr.dtype, np.integer) and not np.all(np.isfinite(out)):
            raise ImageReadError(f"frame {i} ({self.names[i]}): pixels are not finite")
        return out

    def with_non_finite_filled(self, seen: Callable[[int, NDArray[np.bool_]], None]) -> Recording:
        """This recording with each frame's non-finite pixels (NaN, inf: a float TIFF's
        dead or masked pixels) replaced by the median of its finite ones, instead of the
        frame refused; ``seen(index, mask)`` gets the mask (rows, cols) of every frame
        that had any, so the caller can fail what they touch (:mod:`dicblur.track.nan_pixels`).
        A frame without a finite pixel is still refused. Shares this recording's reader."""
        read = self._read

        def filled(i: int) -> NDArray[Any]:
            arr = np.asarray(read(i))
            if np.issubdtype(arr.dtype, np.integer):
                return arr
            arr = np.asarray(arr, dtype=np.float64)
            bad = ~np.isfinite(arr)
            if not bad.any():
                return arr
            if bad.ndim == 3:  # colour: a pixel is bad when one of its channels is
                bad = bad.any(axis=-1)
            if bad.all():
                raise ImageReadError(f"frame {i} ({self.names[i]}): no pixel is finite")
            arr = arr.copy()
            arr[bad] = np.median(arr[~bad], axis=0)
            seen(i, bad)
            return arr

        return Recording(
            source=self.source,
            kind=self.kind,
            n_frames=self.n_frames,
            shape=self.shape,
            bit_depth=self.bit_depth,
            fps=self.fps,
            exposure=self.exposure,
            names=self.names,
            _read=filled,
            _close=self.close,  # one handle: closing either closes it once
            meta=self.meta,
        )

    def frames(self, start: int = 0, stop: int | None = None) -> Iterator[Float64Array]:
        """Iterate over frames ``start .. stop - 1`` (one in memory at a time)."""
        for i in range(start, self.n_frames if stop is None else min(stop, self.n_frames)):
            yield self.frame(i)

    def close(self) -> None:
        """Release the file handles."""
        if self._close is not None:
            self._close()
            self._close = None

    def __enter__(self) -> Recording:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def describe(self) -> dict[str, Any]:
        """JSON-ready summary (source, kind, frames, size, bit depth, fps, exposure)."""
        return {
            "source": self.source,
            "kind": self.kind,
            "n_frames": self.n_frames,
            "shape": list(self.shape),
            "bit_depth": self.bit_depth,
            "fps": self.fps,
            "exposure": self.exposure,
            **self.meta,
        }


def _bits_of(dtype: np.dtype[Any]) -> int:
    return int(np.dtype(dtype).itemsize * 8)


def _folder(files: list[Path], source: str) -> Recording:
    if len(files) == 0:
        raise ImageReadError(
            f"recording={source!r}: no TIFF/PNG/BMP/JPEG images found; give a "
            "folder of frames, a glob such as 'run/*.tif', a multi-page "
            "TIFF, a .cine or a .cih/.mraw recording"
        )
    first = _read_file(files[0])
    shape = (int(first.shape[0]), int(first.shape[1]))
    lossy = sorted(
        {LOSSY_SUFFIXES[f.suffix.lower()] for f in files if f.suffix.lower() in LOSSY_SUFFIXES}
    )
    bits = _bits_of(first.dtype)

    def read(i: int) -> NDArray[Any]:
        arr = _read_file(files[i])
        if arr.dtype != first.dtype:
            # grey levels on another scale (a frame saved again at another bit depth):
            # the noise and the saturation level of the recording would not hold for it
            raise ImageReadError(
                f"frame {i} ({files[i].name}): {_bits_of(arr.dtype)}-bit {arr.dtype}, but "
                f"the recording's frames are {bits}-bit {first.dtype} (from "
                f"{files[0].name}); convert or remove that frame"
            )
        return arr

    return Recording(
        source=source,
        kind="folder",
        n_frames=len(files),
        shape=shape,
        bit_depth=bits,
        fps=None,
        exposure=None,
        names=[f.name for f in files],
        _read=read,
        meta={"lossy": lossy[0]} if lossy else {},
    )


def _one_format(files: list[Path], source: str) -> None:
    """Refuse a folder whose images come in several formats (the frames exported twice,
    f1.png beside f1.tif: each would be a frame of its own, at the wrong time)."""
    counts: dict[str, int] = {}
    for f in files:
        suffix = f.suffix.lower().replace(".tiff", ".tif").replace(".jpeg", ".jpg")
        counts[suffix] = counts.get(suffix, 0) + 1
    if len(counts) > 1:
        found = " and ".join(f"{n} {s}" for s, n in sorted(counts.items(), key=lambda x: -x[1]))
        top = max(counts, key=lambda s: counts[s])
        raise ImageReadError(
            f"recording={source!r}: the folder holds {found} images; give the frames of one "
            f"format as a glob, e.g. {str(Path(source) / ('*' + top))!r}"
        )


def _read_file(path: Path) -> NDArray[Any]:
    """One image file with its stored dtype (8/16-bit integers stay integers)."""
    try:
        if path.suffix.lower() in (".tif", ".tiff"):
            import tifffile

            arr = np.asarray(tifffile.imread(path, key=0))
        else:
            from PIL import Image

            with Image.open(path) as im:
                im.load()
                arr = np.asarray(im, dtype=np.uint16 if im.mode.startswith("I;16") else None)
        if arr.ndim == 2 or (arr.ndim == 3 and arr.shape[-1] in (3, 4)):
            return arr
    except Exception:
        pass
    return load_image(path)


def _tiff_stack(path: Path) -> Recording:
    import tifffile

    try:
        tf = tifffile.TiffFile(path)
        pages = tf.pages
        n = len(pages)
        first = pages[0]
        shape = tuple(int(s) for s in first.shape[:2])
        dtype = np.dtype(first.dtype)
    except Exception as exc:
        raise ImageReadError(
            f"recording={str(path)!r}: cannot be read as a TIFF stack ({type(exc).__name__}: {exc})"
        ) from exc

    pil: list[Any] = []  # the Pillow reader, opened on the first page tifffile cannot decode

    def read(i: int) -> NDArray[Any]:
        try:
            return np.asarray(pages[i].asarray())
        except Exception as exc:
            # a compression tifffile decodes only with imagecodecs (LZW, the default of many
            # camera programs; not a dependency): Pillow's libtiff reads those pages
            got = _pil_page(path, i, pil) if "imagecodecs" in str(exc) else None
            if got is not None:
                return got
            raise ImageReadError(
                f"recording={str(path)!r}: page {i} cannot be read "
                f"({type(exc).__name__}: {exc}); is the file "
                "truncated?"
            ) from exc

    def close() -> None:
        tf.close()
        for im in pil:
            im.close()

    return Recording(
        source=str(path),
        kind="tiff-stack",
        n_frames=n,
        shape=(shape[0], shape[1]),
        bit_depth=_bits_of(dtype),
        fps=None,
        exposure=None,
        names=[f"page {i}" for i in range(n)],
        _read=read,
        _close=close,
    )


def _pil_page(path: Path, i: int, cache: list[Any]) -> NDArray[Any] | None:
    """Page ``i`` of the TIFF ``path`` read by Pillow (the open image kept in ``cache``),
    or None when Pillow cannot read it either."""
    try:
        from PIL import Image

        if not cache:
            cache.append(Image.open(path))
        im = cache[0]
        im.seek(i)
        return np.asarray(im, dtype=np.uint16 if im.mode.startswith("I;16") else None)
    except Exception:
        return None


def _cine(path: Path) -> Recording:
    try:
        import pims
    except ImportError as exc:  # pragma: no cover - a declared dependency
        raise ImageReadError(
            "reading .cine files needs the 'pims' package (pip install pims)"
        ) from exc
    try:
        cine = pims.Cine(str(path))
    except Exception as exc:
        raise ImageReadError(
            f"recording={str(path)!r}: cannot be read as a Phantom cine "
            f"({type(exc).__name__}: {exc})"
        ) from exc
    size = path.stat().st_size
    rows, cols = int(cine.frame_shape[1]), int(cine.frame_shape[0])
    bits = int(cine.setup_fields_dict.get("real_bpp", 0) or _bits_of(cine.pixel_type))
    locations = list(getattr(cine, "image_locations", []))
    n = len(cine)
    frame_bytes = rows * cols * cine.pixel_type.itemsize
    # each image: annotation (>= 8 bytes: its size and the image size) then the pixels
    complete = sum(1 for loc in locations[:n] if loc + 8 + frame_bytes <= size)
    if complete < n:
        warnings.warn(
            f"{path.name}: truncated recording, {complete} of the {n} frames the "
            "header lists are complete; reading those",
            UserWarning,
            stacklevel=3,
        )
        n = complete
    fps = float(cine.frame_rate) or None
    shutter = cine.setup_fields_dict.get("shutter_ns")
    exposure = float(shutter) * 1e-9 if shutter else None
    per_frame = getattr(cine, "all_exposures", None)
    if per_frame:
        exposure = float(np.median(per_frame[: max(n, 1)])) or exposure

    def read(i: int) -> NDArray[Any]:
        return np.asarray(cine.get_frame(i))

    return Recording(
        source=str(path),
        kind="cine",
        n_frames=n,
        shape=(rows, cols),
        bit_depth=bits,
        fps=fps,
        exposure=exposure,
        names=[f"frame {i}" for i in range(n)],
        _read=read,
        _close=cine.close,
    )


def _number(cih: dict[str, Any], *keys: str) -> float | None:
    for k in keys:
        if k in cih:
            try:
                v = float(cih[k])
            except (TypeError, ValueError):
                continue
            if math.isfinite(v) and v > 0:
                return v
    return None


def _mraw(path: Path) -> Recording:
    suffix = path.suffix.lower()
    if suffix == ".mraw":
        heads = [path.with_suffix(s) for s in (".cih", ".cihx")]
        head = next((h for h in heads if h.exists()), None)
        if head is None:
            raise ImageReadError(
                f"recording={str(path)!r}: the Photron header "
                f"{path.with_suffix('.cih').name} (or .cihx) is missing; "
                "keep it next to the .mraw file"
            )
        data = path
    else:
        head, data = path, path.with_suffix(".mraw")
        if not data.exists():
            raise ImageReadError(
                f"recording={str(path)!r}: the data file {data.name} is "
                "missing; keep it next to the header"
            )
    try:
        import pyMRAW
    except ImportError:
        raise ImageReadError(
            f"recording={str(path)!r}: reading Photron .cih/.mraw files "
            "needs pyMRAW (GPL-3.0, not installed with dicblur): pip install "
            "'dicblur[photron]'"
        ) from None
    try:
        cih = pyMRAW.get_cih(str(head))
        n = int(cih["Total Frame"])
        rows, cols = int(cih["Image Height"]), int(cih["Image Width"])
        bits = int(cih["Color Bit"])
    except Exception as exc:
        raise ImageReadError(
            f"recording={str(head)!r}: cannot read the Photron header ({type(exc).__name__}: {exc})"
        ) from exc
    if bits not in (8, 12, 16) or str(cih.get("File Format", "MRaw")).lower() != "mraw":
        raise ImageReadError(
            f"recording={str(head)!r}: Color Bit {bits}, File Format "
            f"{cih.get('File Format')!r}: only 8/12/16-bit mono MRaw data "
            "are supported"
        )
    frame_bytes = rows * cols * bits // 8
    size = data.stat().st_size
    complete = size // frame_bytes
    if complete < n:
        warnings.warn(
            f"{data.name}: truncated recording, {complete} of the {n} frames the "
            "header lists are complete; reading those",
            UserWarning,
            stacklevel=3,
        )
        n = int(complete)
    effective = _number(cih, "EffectiveBit Depth") or bits
    # one seek + read per frame (a memory map would count every page read in the
    # process's resident memory until the kernel drops it)
    fh = open(data, "rb")  # closed by Recording.close

    def read(i: int) -> NDArray[Any]:
        fh.seek(i * frame_bytes)
        chunk = np.frombuffer(fh.read(frame_bytes), dtype=np.uint8)
        if chunk.size != frame_bytes:
            raise ImageReadError(
                f"recording={str(data)!r}: frame {i} is incomplete; is the file truncated?"
            )
        if bits == 8:
            return chunk.reshape(rows, cols)
        if bits == 16:
            return chunk.view("<u2").reshape(rows, cols)
        b = chunk.reshape(-1, 3).astype(np.uint16)  # 12-bit, big-endian pairs
        out = np.empty((b.shape[0], 2), np.uint16)
        out[:, 0] = (b[:, 0] << 4) | (b[:, 1] >> 4)
        out[:, 1] = ((b[:, 1] & 0x0F) << 8) | b[:, 2]
        return out.reshape(rows, cols)

    return Recording(
        source=str(head),
        kind="mraw",
        n_frames=n,
        shape=(rows, cols),
        bit_depth=int(effective),
        fps=_number(cih, "Record Rate(fps)"),
        exposure=_number(cih, "Shutter Speed(s)"),
        names=[f"frame {i}" for i in range(n)],
        _read=read,
        _close=fh.close,
        meta={"camera": str(cih.get("Camera Type", ""))},
    )


def open_recording(source: str | os.PathLike[str]) -> Recording:
    """Open a recording for lazy, frame-by-frame reading.

    Parameters
    ----------
    source : str or path-like
        A folder of TIFF/PNG/BMP/JPEG frames (natural sort), a glob pattern, a multi-page TIFF,
        a single image (one frame), a Phantom ``.cine``, or a Photron ``.cih``/``.cihx``/
        ``.mraw``.

    Returns
    -------
    Recording

    Raises
    ------
    ImageReadError
        Missing path, no frames, unreadable header.
    """
    text = str(source)
    if any(c in text for c in "*?["):
        files = sorted(
            (Path(f) for f in glob(text) if Path(f).is_file()), key=lambda p: natural_key(p.name)
        )
        return _folder(files, text)
    p = Path(text)
    if not p.exists():
        raise ImageReadError(f"recording={text!r}: no such file or folder; check the path")
    if p.is_dir():
        files = sorted(
            # hidden files ('._f1.tif' beside each frame of a macOS copy) are no frames,
            # as a glob '*' leaves them out
            (
                f
                for f in p.iterdir()
                if f.is_file() and f.suffix.lower() in IMAGE_SUFFIXES and not f.name.startswith(".")
            ),
            key=lambda f: natural_key(f.name),
        )
        _one_format(files, text)
        return _folder(files, text)
    if p.stat().st_size == 0:
        raise ImageReadError(f"recording={text!r}: the file is empty (0 bytes)")
    suffix = p.suffix.lower()
    if suffix == ".cine":
        return _cine(p)
    if suffix in (".cih", ".cihx", ".mraw"):
        return _mraw(p)
    if suffix in (".tif", ".tiff"):
        return _tiff_stack(p)
    return _folder([p], text)
