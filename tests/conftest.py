"""Shared fixtures. Tests build their own data; real images are optional."""

from __future__ import annotations

from pathlib import Path

import pytest

REAL_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"


@pytest.fixture
def real_data() -> Path:
    """Folder of the real speckle images, or skip when this checkout has none."""
    if not REAL_DATA.is_dir():
        pytest.skip(f"real images not present at {REAL_DATA} (they ship outside the repo)")
    return REAL_DATA
