"""A resumable store of the finished chunks of one job (e.g. ``dicblur track --workers``).

The campaign store's conventions (:mod:`dicblur.campaign.store`) for results that are not a
campaign grid: a folder holding

- ``store.json``: what the job is (its ``key``: every setting that changes the results,
  canonical JSON, and its SHA-256), the number of chunks, package versions;
- ``chunk-NNNNNN.npz``: one finished chunk, its arrays (uncompressed ``.npz``) plus a
  CRC-32 of each array's bytes.

One writer: the holder of the store's lock (:class:`~dicblur.campaign.lock.StoreLock`, the
file ``<store>.lock`` beside it) while the store is open. Crash safety: a chunk is written
to a temporary file in the folder, flushed to disk (``fsync``), then renamed over its name
and the folder flushed, so a chunk file is either absent or complete; a file that does not
read back with its checksums (a power loss before the disk wrote it, a copy cut short) is
*damaged*, ignored by :meth:`ChunkStore.done` and rewritten by the next run.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import zipfile
import zlib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._version import package_versions
from ..errors import StoreError
from ..io import fsync_path
from .lock import StoreLock

__all__ = ["CHUNKS_LAYOUT", "ChunkStore"]

#: Layout of :class:`ChunkStore` folders.
CHUNKS_LAYOUT = 1
_FORMAT = "dicblur-chunks"


def _canonical(key: Mapping[str, Any]) -> str:
    return json.dumps(key, sort_keys=True, separators=(",", ":"), default=str)


def _difference(a: Any, b: Any, where: str = "") -> str:
    """First place where two JSON values differ, for the message."""
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if a.get(k) != b.get(k):
                return _difference(a.get(k), b.get(k), f"{where}.{k}" if where else k)
    text_a, text_b = json.dumps(a, default=str)[:40], json.dumps(b, default=str)[:40]
    return f"{where or 'key'} (stored {text_a}, requested {text_b})"


def _crc(arr: NDArray[Any]) -> int:
    a = np.ascontiguousarray(arr)
    head = f"{a.dtype.str}{a.shape}".encode()
    return zlib.crc32(a.tobytes(), zlib.crc32(head))


class ChunkStore:
    """Finished chunks of one job, durable and checksummed; open it as a context manager.

    Parameters
    ----------
    path : path
        The store folder (created if absent; its parent must exist).
    key : mapping
        JSON-ready description of the job (settings, input identity). An existing store
        must hold the same key, else :class:`~dicblur.errors.StoreError` names the first
        difference.
    n_chunks : int
        Chunks of the job (checked against an existing store too).

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> from dicblur.campaign import ChunkStore
    >>> path = os.path.join(tempfile.mkdtemp(), "job.chunks")
    >>> with ChunkStore(path, key={"n": 3}, n_chunks=2) as store:
    ...     store.write(0, {"x": np.arange(3.0)})
    ...     sorted(store.done())
    [0]
    """

    def __init__(self, path: str | os.PathLike[str], *, key: Mapping[str, Any], n_chunks: int):
        self.path = Path(path)
        self.key = json.loads(_canonical(key))
        self.key_hash = hashlib.sha256(_canonical(key).encode()).hexdigest()
        self.n_chunks = int(n_chunks)
        self._lock = StoreLock(self.path)

    # -- opening ------------------------------------------------------------------------
    def __enter__(self) -> ChunkStore:
        if not self.path.parent.is_dir():
            raise StoreError(
                f"store={str(self.path)!r}: the folder {str(self.path.parent)!r} does not exist"
            )
        self._lock.acquire()
        try:
            self._open_or_create()
        except BaseException:
            self._lock.release()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        self._lock.release()

    def _open_or_create(self) -> None:
        meta = self.path / "store.json"
        if self.path.exists() and not self.path.is_dir():
            raise StoreError(f"store={str(self.path)!r}: exists and is not a folder")
        if meta.is_file():
            try:
                stored = json.loads(meta.read_text())
            except (OSError, ValueError) as exc:
                raise StoreError(
                    f"store={str(self.path)!r}: store.json is unreadable ({exc}); "
                    "remove the folder to start again"
                ) from exc
            if stored.get("format") != _FORMAT or stored.get("layout") != CHUNKS_LAYOUT:
                raise StoreError(
                    f"store={str(self.path)!r}: not a dicblur chunk store of layout "
                    f"{CHUNKS_LAYOUT}; remove it or use another output folder"
                )
            if stored.get("key_hash") != self.key_hash or stored.get("n_chunks") != self.n_chunks:
                diff = _difference(stored.get("key"), self.key)
                if stored.get("key_hash") == self.key_hash:
                    diff = f"n_chunks (stored {stored.get('n_chunks')}, requested {self.n_chunks})"
                raise StoreError(
                    f"store={str(self.path)!r}: holds the chunks of another run (first "
                    f"difference at {diff}); remove it or use another output folder "
                    "to start again, or rerun with the original settings to resume"
                )
            return
        # a folder without store.json: an interrupted creation (no chunk can be in it
        # before store.json, which is written first); anything else is not ours
        if self.path.is_dir() and any(
            not (e.name.startswith(".") and e.name.endswith(".partial"))
            for e in self.path.iterdir()
        ):
            raise StoreError(
                f"store={str(self.path)!r}: a folder that is not a chunk store; "
                "remove it or use another output folder"
            )
        self.path.mkdir(exist_ok=True)
        info = {
            "format": _FORMAT,
            "layout": CHUNKS_LAYOUT,
            "key": self.key,
            "key_hash": self.key_hash,
            "n_chunks": self.n_chunks,
            "versions": package_versions(),
        }
        self._atomic(meta, (json.dumps(info, indent=1, default=str) + "\n").encode())

    # -- chunks -------------------------------------------------------------------------
    def chunk_path(self, index: int) -> Path:
        """File of chunk ``index``."""
        return self.path / f"chunk-{int(index):06d}.npz"

    def _check_index(self, index: int) -> int:
        i = int(index)
        if not 0 <= i < self.n_chunks:
            raise StoreError(f"chunk={index}: outside 0..{self.n_chunks - 1}")
        return i

    def read(self, index: int) -> dict[str, NDArray[Any]]:
        """Arrays of a finished chunk.

        Raises
        ------
        StoreError
            If the chunk is missing or damaged (unreadable, checksum mismatch).
        """
        path = self.chunk_path(self._check_index(index))
        try:
            with np.load(path, allow_pickle=False) as z:
                data = {k: z[k] for k in z.files}
        except (OSError, ValueError, KeyError, EOFError, zlib.error, zipfile.BadZipFile) as exc:
            raise StoreError(f"chunk {index} ({path.name}): unreadable ({exc})") from exc
        names = [str(n) for n in data.pop("_names", np.array([], dtype=str))]
        crcs = data.pop("_crc32", np.array([], dtype=np.uint32))
        if sorted(names) != sorted(data) or len(crcs) != len(names):
            raise StoreError(f"chunk {index} ({path.name}): incomplete (arrays missing)")
        for n, c in zip(names, crcs, strict=True):
            if _crc(data[n]) != int(c):
                raise StoreError(f"chunk {index} ({path.name}): checksum mismatch in {n!r}")
        return data

    def done(self) -> set[int]:
        """Indices of the finished chunks (present and reading back with their checksums)."""
        out = set()
        for i in range(self.n_chunks):
            if self.chunk_path(i).is_file():
                try:
                    self.read(i)
                except StoreError:
                    continue  # damaged: recomputed and rewritten
                out.add(i)
        return out

    def write(self, index: int, arrays: Mapping[str, Any]) -> None:
        """Store chunk ``index`` (atomic and durable when this returns)."""
        if not self._lock.held:
            raise StoreError(f"store={str(self.path)!r}: open the store (with ...) before writing")
        i = self._check_index(index)
        data = {str(k): np.asarray(v) for k, v in arrays.items()}
        for k, v in data.items():
            if k.startswith("_") or k == "allow_pickle" or v.dtype.hasobject:
                raise StoreError(f"chunk {index}: array {k!r} has a reserved name or object dtype")
        names = sorted(data)
        payload: dict[str, Any] = {
            "_names": np.array(names, dtype=str),
            "_crc32": np.array([_crc(data[n]) for n in names], dtype=np.uint32),
            **data,
        }
        buf = io.BytesIO()
        np.savez(buf, **payload)
        self._atomic(self.chunk_path(i), buf.getvalue())

    def _atomic(self, target: Path, payload: bytes) -> None:
        tmp = target.with_name(f".{target.name}.{os.getpid()}.partial")
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
            try:
                view = memoryview(payload)
                while view:
                    view = view[os.write(fd, view) :]
                os.fsync(fd)
            finally:
                os.close(fd)
            os.replace(tmp, target)
            fsync_path(self.path)
        except OSError as exc:
            tmp.unlink(missing_ok=True)
            raise StoreError(
                f"store={str(self.path)!r}: cannot write {target.name} ({exc})"
            ) from exc
