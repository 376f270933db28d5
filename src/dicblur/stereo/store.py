"""A stereo track's CSV: one row per point per frame, written atomically."""

from __future__ import annotations

import csv
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import StoreError

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
    p = Path(path)
    n_f, n_p = ds.sizes["frame"], ds.sizes["point"]
    cols: dict[str, Any] = {
        "frame": np.repeat(ds["frame"].values, n_p),
        "time": np.repeat(ds["time"].values, n_p),
        "point": np.tile(np.arange(n_p), n_f),
        "row": np.tile(ds["row"].values, n_f),
        "col": np.tile(ds["col"].values, n_f),
    }
    for c in STEREO_CSV_COLUMNS:
        v = ds[c].values
        cols[c] = np.tile(v, n_f) if v.ndim == 1 else v.ravel()
    names = ("frame", "time", "point", "row", "col", *STEREO_CSV_COLUMNS)
    ints = {"frame", "point", "row", "col", "status", "valid"}
    tmp = p.with_name(f".{p.name}.tmp")
    try:
        with tmp.open("w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(names)
            for i in range(n_f * n_p):
                w.writerow(
                    [int(cols[c][i]) if c in ints else f"{float(cols[c][i]):.7g}" for c in names]
                )
        os.replace(tmp, p)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise StoreError(f"path={str(p)!r}: cannot write the CSV ({exc})") from exc
    return p
