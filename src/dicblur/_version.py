"""The package version: its one source (pyproject.toml reads it from here, the CHANGELOG's
latest release heading names it, and every model file records it). A literal rather than
the installed metadata, so a source tree on ``PYTHONPATH`` reports its own version. Bottom
layer: imports nothing from dicblur, so any module may import it without pulling the
package's subpackages (``from .. import __version__`` did, and made a cycle).
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

__all__ = ["DEPENDENCIES", "__version__", "package_versions"]

# A plain assignment: setuptools reads it statically (pyproject.toml [tool.setuptools.dynamic]).
__version__ = "0.2.2"

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
