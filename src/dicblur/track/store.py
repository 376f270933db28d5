"""Writing a track Dataset: netCDF or Zarr, atomically; CSV in long format."""

from __future__ import annotations

import csv
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import StoreError

__all__ = ["CSV_COLUMNS", "save_track", "write_track_csv"]

CSV_COLUMNS = (
    "frame",
    "time",
    "point",
    "row",
    "col",
    "u",
    "v",
    "W",
    "blur_u",
    "blur_v",
    "blur_direction",
    "sigma_u",
    "sigma_v",
    "sigma_u_noise",
    "sigma_u_blur",
    "sigma_v_noise",
    "sigma_v_blur",
    "status",
    "zncc",
    "outlier",
    "valid",
)


def save_track(ds: Any, path: str | os.PathLike[str]) -> Path:
    """Write ``ds`` to ``path`` (``.nc``: netCDF via scipy; ``.zarr``: a Zarr store),
    through a temporary sibling and a rename, so a crash never leaves half a file."""
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix not in (".nc", ".zarr"):
        raise StoreError(f"path={str(p)!r}: use a .nc (netCDF) or .zarr file name")
    if not p.parent.exists():
        raise StoreError(f"path={str(p)!r}: the folder {str(p.parent)!r} does not exist")
    tmp = Path(tempfile.mkdtemp(prefix=f".{p.name}.", dir=p.parent))
    try:
        target = tmp / p.name
        if suffix == ".nc":
            ds.to_netcdf(target, engine="scipy")
            os.replace(target, p)
        else:
            ds.to_zarr(target, mode="w")
            if p.exists():
                old = p.with_name(p.name + ".old")
                os.replace(p, old)
                os.replace(target, p)
                shutil.rmtree(old, ignore_errors=True)
            else:
                os.replace(target, p)
    except OSError as exc:
        raise StoreError(f"path={str(p)!r}: cannot write ({exc})") from exc
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return p


def write_track_csv(ds: Any, path: str | os.PathLike[str]) -> Path:
    """One row per point per frame (columns :data:`CSV_COLUMNS`), written atomically."""
    p = Path(path)
    n_f, n_p = ds.sizes["frame"], ds.sizes["point"]
    cols: dict[str, Any] = {
        "frame": np.repeat(ds["frame"].values, n_p),
        "time": np.repeat(ds["time"].values, n_p),
        "point": np.tile(np.arange(n_p), n_f),
        "row": np.tile(ds["row"].values, n_f),
        "col": np.tile(ds["col"].values, n_f),
    }
    for c in CSV_COLUMNS[5:]:
        cols[c] = ds[c].values.ravel()
    tmp = p.with_name(f".{p.name}.tmp")
    try:
        with tmp.open("w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(CSV_COLUMNS)
            ints = {"frame", "point", "row", "col", "status", "outlier", "valid"}
            for i in range(n_f * n_p):
                w.writerow(
                    [
                        int(cols[c][i]) if c in ints else f"{float(cols[c][i]):.6g}"
                        for c in CSV_COLUMNS
                    ]
                )
        os.replace(tmp, p)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise StoreError(f"path={str(p)!r}: cannot write the CSV ({exc})") from exc
    return p
