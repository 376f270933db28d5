"""One runner per store: an exclusive OS lock on a file next to the campaign store.

``run_campaign`` holds the lock of ``results.zarr`` (the file ``results.zarr.lock``) from
before the store is created or opened until the run ends, so a second runner on the same
store stops at once with one line naming the holder, instead of racing on the creation or
computing every remaining task a second time.

The lock is :func:`fcntl.flock` on the lock file: the operating system releases it when the
holder exits, however it ends (Ctrl-C, a crash, SIGKILL, a power loss), so a stale lock
never blocks the next run. The file holds who took it (host, pid, start time, command) for
the message only; it is never trusted as the lock itself. The holder unlinks the file on
release; a runner that locked a file which was unlinked meanwhile (its inode no longer at
the path) retries, so two runners can never both believe they hold it.

On a network file system flock works where the server supports locks (NFSv4, Linux NFS
clients emulate it with POSIX locks); on one without locking, run one campaign at a time.
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import StoreError

__all__ = ["LockHolder", "StoreLock", "lock_holder", "lock_path"]


def lock_path(store: str | os.PathLike[str]) -> Path:
    """The lock file of a store: ``<store>.lock`` next to it."""
    p = Path(store)
    return p.with_name(p.name + ".lock")


@dataclass(frozen=True)
class LockHolder:
    """Who holds a store's lock (as the holder wrote it; for messages).

    Attributes
    ----------
    host : str
    pid : int
    since : str
        UTC start time of the holder's run, ``YYYY-MM-DD HH:MM:SS UTC``.
    command : str
        The holder's command line.
    """

    host: str
    pid: int
    since: str
    command: str

    def describe(self) -> str:
        """``pid 123 on host h since ...`` for one-line messages."""
        if self.pid <= 0:
            return "a process that has not written its details yet"
        return f"pid {self.pid} on host {self.host} since {self.since}"


def _parse_holder(text: str) -> LockHolder:
    try:
        d: dict[str, Any] = json.loads(text)
        return LockHolder(str(d["host"]), int(d["pid"]), str(d["since"]), str(d.get("command", "")))
    except (ValueError, KeyError, TypeError):
        return LockHolder("?", 0, "?", "")


class StoreLock:
    """Exclusive, non-blocking lock of one campaign store (a context manager).

    Parameters
    ----------
    store : path
        The store (need not exist yet); the lock file is :func:`lock_path` of it. Its
        folder must exist.
    """

    def __init__(self, store: str | os.PathLike[str]) -> None:
        self.store = Path(store)
        self.path = lock_path(store)
        self._fd: int | None = None

    @property
    def held(self) -> bool:
        """Whether this object holds the lock."""
        return self._fd is not None

    def acquire(self) -> None:
        """Take the lock or raise at once.

        Raises
        ------
        StoreError
            If another process holds it: the message names the holder (host, pid, start
            time) and what to do.
        """

        if self._fd is not None:
            return
        for _ in range(100):  # retry only when the file was unlinked under us
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as exc:
                raise StoreError(
                    f"results={str(self.store)!r}: cannot create the lock file "
                    f"{str(self.path)!r} ({exc.strerror}); check that the "
                    "folder exists and is writable"
                ) from exc
            try:
                _flock_soon(fd)
            except BlockingIOError:
                holder = _read_holder(fd)
                os.close(fd)
                raise StoreError(
                    f"results={str(self.store)!r}: another campaign run is using this store "
                    f"({holder.describe()}); wait for it to finish (or stop it), then rerun "
                    "the same command to resume"
                ) from None
            except OSError as exc:
                os.close(fd)
                raise StoreError(
                    f"results={str(self.store)!r}: cannot lock "
                    f"{str(self.path)!r} ({exc.strerror}); the file system "
                    "does not support locks: run one campaign at a time on a "
                    "local disk"
                ) from exc
            try:
                same = os.fstat(fd).st_ino == os.stat(self.path).st_ino
            except FileNotFoundError:
                same = False
            if same:
                break
            os.close(fd)  # the previous holder unlinked this file: lock the new one
        else:  # pragma: no cover - a pathological race
            raise StoreError(
                f"results={str(self.store)!r}: could not take the lock {str(self.path)!r}; retry"
            )
        info = {
            "host": socket.gethostname(),
            "pid": os.getpid(),
            "since": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()),
            "command": " ".join(sys.argv),
        }
        os.ftruncate(fd, 0)
        os.pwrite(fd, (json.dumps(info) + "\n").encode(), 0)
        self._fd = fd

    def release(self) -> None:
        """Release the lock and remove the lock file (no-op if not held)."""
        if self._fd is None:
            return
        fd, self._fd = self._fd, None
        # Unlink while still locked: a runner waiting on this inode sees it gone and
        # retries on a fresh file (see acquire).
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.path)
        os.close(fd)  # closing the descriptor releases the flock

    def __enter__(self) -> StoreLock:
        self.acquire()
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def _flock_soon(fd: int) -> None:
    """Exclusive flock, retried for 0.25 s: a ``lock_holder`` probe (``campaign status``)
    holds a shared lock for an instant and must not make a runner give up."""
    import fcntl

    for _ in range(5):
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return
        except BlockingIOError:
            time.sleep(0.05)
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)


def _read_holder(fd: int) -> LockHolder:
    try:
        return _parse_holder(os.pread(fd, 4096, 0).decode("utf-8", "replace"))
    except OSError:
        return _parse_holder("")


def lock_holder(store: str | os.PathLike[str]) -> LockHolder | None:
    """Who holds the lock of ``store`` now, or None if no run holds it.

    Probes the lock without waiting (taken and released at once when free); a lock file
    left by a process that died is not held.
    """
    import fcntl

    path = lock_path(store)
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return _read_holder(fd)
        except OSError:
            return None
        fcntl.flock(fd, fcntl.LOCK_UN)
        return None
    finally:
        os.close(fd)
