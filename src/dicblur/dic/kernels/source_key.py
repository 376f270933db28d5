"""Numba's on-disk cache of the kernels, keyed by the sources of the whole package.

Numba validates a cached kernel against its own source file only. The kernels here
inline helpers from other files (:mod:`.common`, :mod:`.spline`), so with numba's
default a change to a helper alone left its callers' stale machine code in use. That
happens in a source checkout, where an update rewrites only the changed files; a pip
install rewrites every file and was never affected. :func:`keyed_cache` therefore
points numba's cache, while the kernel modules are imported (their decorators choose
the directory), at a directory named after a hash of every ``*.py`` file of the
package: any change to any kernel source compiles afresh, and nothing else does.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

__all__ = ["keyed_cache", "source_key"]

# Directories of other keys older than this are removed: a process started before an
# update may still be writing to its own directory.
_STALE_AFTER = 86_400.0  # s


def source_key(package: Path) -> str:
    """Hash (12 hex digits) of the names and bytes of every ``*.py`` file in ``package``."""
    digest = hashlib.sha256()
    for path in sorted(package.glob("*.py")):
        digest.update(path.name.encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:12]


def _writable(directory: Path) -> bool:
    try:
        directory.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=directory).close()
    except OSError:
        return False
    return True


def _prune(parent: Path, keep: Path) -> None:
    """Remove the directories of other keys that nothing has touched for a day."""
    now = time.time()
    for other in parent.glob("kernels-*"):
        try:
            if other != keep and now - other.stat().st_mtime > _STALE_AFTER:
                shutil.rmtree(other, ignore_errors=True)
        except OSError:
            pass


def _cache_root(package: Path, key: str, user_dir: str) -> Path | None:
    """The first writable place for this key's cache: under the user's
    ``NUMBA_CACHE_DIR`` if set, else beside the sources (as numba's default), else the
    user's cache directory."""
    if user_dir:
        candidates = [Path(user_dir) / "dicblur"]
    else:
        home = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
        candidates = [package / "__pycache__", Path(home) / "dicblur"]
    for parent in candidates:
        root = parent / f"kernels-{key}"
        if _writable(root):
            _prune(parent, root)
            return root
    return None


@contextmanager
def keyed_cache(package: Path) -> Iterator[Path | None]:
    """Within the block, kernels decorated with ``cache=True`` keep their compiled code
    under a directory keyed by :func:`source_key` of ``package``.

    Numba's setting is restored on leaving, so the user's other numba code is not
    affected. Yields the directory, or None when no writable place was found (numba's
    own default then applies).
    """
    from numba.core import config as numba_config

    config: Any = numba_config  # its settings are set at run time, untyped
    user_dir = config.CACHE_DIR
    root = _cache_root(package, source_key(package), user_dir)
    if root is None:
        yield None
        return
    config.CACHE_DIR = str(root)
    try:
        yield root
    finally:
        config.CACHE_DIR = user_dir
