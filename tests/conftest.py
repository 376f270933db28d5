"""Shared fixtures and hooks. Tests build their own data; real images are optional."""

from __future__ import annotations

from pathlib import Path

import pytest

REAL_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"


def pytest_collection_finish(session: pytest.Session) -> None:
    """Write numba's cache in a separate process before any test compiles, when a selected
    test compares this process with worker processes bit for bit (marker ``numba_cache``).

    A process that compiles a fast-math kernel itself and one that loads it from numba's
    on-disk cache can differ in the last bit (measured on IC-GN: 1e-16 px), so such tests
    need every process to load the same cached code. The other tests compile lazily, only
    the kernels they call (the fast run needs no warm-up of its own).
    """
    if any(item.get_closest_marker("numba_cache") for item in session.items):
        from helpers.campaign import warm_numba_cache

        warm_numba_cache()


@pytest.fixture
def real_data() -> Path:
    """Folder of the real speckle images, or skip when this checkout has none."""
    if not REAL_DATA.is_dir():
        pytest.skip(f"real images not present at {REAL_DATA} (they ship outside the repo)")
    return REAL_DATA
