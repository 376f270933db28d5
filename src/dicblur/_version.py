"""The package version, read once from the installed metadata (pyproject.toml is its one
source). Bottom layer: imports nothing from dicblur, so any module may import it without
pulling the package's subpackages (``from .. import __version__`` did, and made a cycle).
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

__all__ = ["__version__"]

try:
    __version__: str = version("dicblur")
except PackageNotFoundError:  # pragma: no cover - running from a source tree, not installed
    __version__ = "0+unknown"
