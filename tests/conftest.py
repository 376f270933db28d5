"""Shared fixtures. Tests build their own data; real images are optional."""

from __future__ import annotations

from pathlib import Path

import pytest

REAL_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"


@pytest.fixture(scope="session", autouse=True)
def _numba_cache_first() -> None:
    """Compile the numba kernels in a separate process before any test runs.

    A process that compiles a fast-math kernel itself and one that loads it from numba's
    on-disk cache can differ in the last bit (measured on IC-GN: 1e-16 px). The campaign
    tests compare this process with Dask worker processes bit for bit, so every process
    must load the same cached code: it has to exist before this process compiles anything.
    """
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import campaign_helpers

    campaign_helpers.warm_numba_cache()


@pytest.fixture
def real_data() -> Path:
    """Folder of the real speckle images, or skip when this checkout has none."""
    if not REAL_DATA.is_dir():
        pytest.skip(f"real images not present at {REAL_DATA} (they ship outside the repo)")
    return REAL_DATA
