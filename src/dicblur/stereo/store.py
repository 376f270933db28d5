"""A stereo track's CSV: one row per point per frame, written atomically."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from ..track.store import write_long_csv

__all__ = ["STEREO_CSV_COLUMNS", "write_stereo_csv"]

#: Columns after ``frame, time, point, row, col`` (point variables repeat per frame).
STEREO_CSV_COLUMNS = (
    "X",
    "Y",
    "Z",
    "U",
    "V",
    "W3",
    "sigma_U",
    "sigma_V",
    "sigma_W3",
    "cov_UV",
    "cov_UW3",
    "cov_VW3",
    "W_left",
    "W_right",
    "status",
    "valid",
)


def write_stereo_csv(ds: Any, path: str | os.PathLike[str]) -> Path:
    """``frame, time, point, row, col`` and :data:`STEREO_CSV_COLUMNS`, long format."""
    return write_long_csv(ds, path, STEREO_CSV_COLUMNS, integers={"status", "valid"}, digits=7)
