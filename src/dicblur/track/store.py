"""Writing a track Dataset: netCDF or Zarr, atomically; CSV in long format."""

from __future__ import annotations

import csv
import os
import shutil
import tempfile
from collections.abc import Collection, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import StoreError
from ..strain.track import TRACK_STRAIN_NAMES

__all__ = [
    "CSV_COLUMNS",
    "STRAIN_CSV_COLUMNS",
    "save_track",
    "write_long_csv",
    "write_track_csv",
]

#: The strain columns of a track with strains (docs/strain.md), after :data:`CSV_COLUMNS`:
#: the strain stage's variables and their status.
STRAIN_CSV_COLUMNS = (*TRACK_STRAIN_NAMES, "strain_status")

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
    # with strains (docs/strain.md) their columns follow
    columns = [*CSV_COLUMNS[5:], *(k for k in STRAIN_CSV_COLUMNS if k in ds)]
    ints = {"status", "outlier", "valid", "strain_status"}
    return write_long_csv(ds, path, columns, integers=ints, digits=6)


def write_long_csv(
    ds: Any,
    path: str | os.PathLike[str],
    columns: Sequence[str],
    *,
    integers: Collection[str] = (),
    digits: int = 6,
) -> Path:
    """``frame, time, point, row, col`` and ``columns`` of the Dataset ``ds``, one row per
    point per frame (long format), written atomically.

    A variable of dims ``(frame, point)`` gives its value; one of dims ``(point,)`` repeats
    in every frame. ``integers`` are written as whole numbers (``frame``, ``point``,
    ``row``, ``col`` always), the rest with ``digits`` significant digits.
    """
    p = Path(path)
    n_f, n_p = ds.sizes["frame"], ds.sizes["point"]
    cols: dict[str, Any] = {
        "frame": np.repeat(ds["frame"].values, n_p),
        "time": np.repeat(ds["time"].values, n_p),
        "point": np.tile(np.arange(n_p), n_f),
        "row": np.tile(ds["row"].values, n_f),
        "col": np.tile(ds["col"].values, n_f),
    }
    for c in columns:
        v = ds[c].values
        cols[c] = np.tile(v, n_f) if v.ndim == 1 else v.ravel()
    names = ("frame", "time", "point", "row", "col", *columns)
    ints = {"frame", "point", "row", "col", *integers}
    tmp = p.with_name(f".{p.name}.tmp")
    try:
        with tmp.open("w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(names)
            for i in range(n_f * n_p):
                w.writerow(
                    [
                        int(cols[c][i]) if c in ints else f"{float(cols[c][i]):.{digits}g}"
                        for c in names
                    ]
                )
        os.replace(tmp, p)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise StoreError(f"path={str(p)!r}: cannot write the CSV ({exc})") from exc
    return p
