"""The package version, read once from the installed metadata (pyproject.toml is its one
source). Bottom layer: imports nothing from dicblur, so any module may import it without
pulling the package's subpackages (``from .. import __version__`` did, and made a cycle).
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

__all__ = ["DEPENDENCIES", "__version__", "package_versions"]

try:
    __version__: str = version("dicblur")
except PackageNotFoundError:  # pragma: no cover - running from a source tree, not installed
    __version__ = "0+unknown"

#: The packages whose versions change dicblur's numbers or files (recorded in provenance).
DEPENDENCIES = ("numpy", "scipy", "numba", "xarray", "zarr", "dask", "distributed", "matplotlib")


def package_versions(packages: tuple[str, ...] = DEPENDENCIES) -> dict[str, str]:
    """Installed versions of dicblur and ``packages`` ("absent" for one not installed)."""
    out = {"dicblur": __version__}
    for pkg in packages:
        try:
            out[pkg] = version(pkg)
        except PackageNotFoundError:
            out[pkg] = "absent"
    return out
