"""Benchmark: ``dicblur track`` in chunks and with the blur-compensated matcher (#17, #18).

Chunks: a 256^2 speckle target vibrating 10 px at 200 Hz along 20 deg, 2000 fps,
T = 0.45 ms (peak W 5.7 px), written as an 8-bit TIFF folder (read lazily by every
worker), tracked at subset 21, step 10 (affine) serially, in chunks in this process and
in chunks on a local Dask cluster of 2 processes: wall time, frames/s, and the agreement
with the serial run (largest |du|, |dv| over converged points; identical statuses).

Compensation: the same target, plain against ``compensate_blur=True``: per 1 px bin of
the true W, the scatter of the error over points (each frame's mean removed) and the
ratio of the predicted sigma to it, along x and y.

Run: ``NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/bench_track_parallel.py [--quick]``
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import tifffile
from _harness import Run, use_tests_dir

import dicblur
from dicblur.track.parallel import ChunkedRun
from dicblur.track.synthetic import VibratingTarget

use_tests_dir()
from helpers.track import track_pattern, vibrating_target  # noqa: E402


def target(n: int) -> VibratingTarget:
    p = track_pattern(n, seed=5)
    return vibrating_target(p, exposure=0.45e-3, amplitude=10.0, static=10, seed=21)


def groups(tgt: VibratingTarget, ds) -> list[dict]:
    tu, tv, bu, bv = tgt.truth(ds["frame"].values)
    valid = ds["valid"].values.astype(bool)
    w = np.broadcast_to(np.hypot(bu, bv)[:, None], valid.shape)
    rows = []
    for lo in range(0, 6):
        sel = valid & (w >= lo) & (w < lo + 1)
        if sel.sum() < 200:
            continue
        row = {"W": f"{lo}-{lo + 1}", "n": int(sel.sum())}
        for c, truth in (("u", tu), ("v", tv)):
            e = ds[c].values - truth[:, None]
            e = e - np.nanmean(np.where(valid, e, np.nan), axis=1, keepdims=True)
            meas = float(np.sqrt(np.mean(e[sel] ** 2)))
            pred = float(np.sqrt(np.mean(ds[f"sigma_{c}"].values[sel] ** 2)))
            row[f"scatter_{c}"] = meas
            row[f"ratio_{c}"] = pred / meas
        rows.append(row)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args()
    run = Run("track_parallel")
    n_frames = 60 if a.quick else 200
    tgt = target(256)
    kw = {"static": "0:10", "subset": 21, "step": 10, "advice": False, "fps": 2000}
    kw["exposure"] = "0.45ms"
    result: dict = {"n_frames": n_frames, "size": 256, "chunks": [], "compensation": {}}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "frames"
        folder.mkdir()
        for k in range(n_frames):
            img = np.clip(np.rint(tgt.render(k)), 0, 255).astype(np.uint8)
            tifffile.imwrite(folder / f"f{k}.tif", img)
        dicblur.track(str(folder), frames="0:12", **kw)  # compile / load the kernels
        t = time.perf_counter()
        serial = dicblur.track(str(folder), **kw)
        t_serial = time.perf_counter() - t
        conv = serial["status"].values == dicblur.PointStatus.CONVERGED
        modes = [("serial", None), ("chunks here", ChunkedRun(chunk_frames=50))]
        modes.append(("chunks, 2 workers", ChunkedRun(chunk_frames=50, workers=2)))
        print(
            f"{'mode':<20}{'wall s':>9}{'frames/s':>10}{'max |du| px':>13}{'p99':>10}"
            f"{'> 1e-4':>9}{'statuses':>10}"
        )
        for name, chunks in modes:
            if chunks is None:
                ds, wall = serial, t_serial
            else:
                t = time.perf_counter()
                ds = dicblur.track(str(folder), chunks=chunks, **kw)
                wall = time.perf_counter() - t
            diff = np.concatenate(
                [np.abs(ds[c].values - serial[c].values)[conv] for c in ("u", "v")]
            )
            d, p99 = float(diff.max()), float(np.quantile(diff, 0.99))
            over = float(np.mean(diff > 1e-4))
            same = bool(np.array_equal(ds["status"].values, serial["status"].values))
            print(
                f"{name:<20}{wall:>9.2f}{n_frames / wall:>10.1f}{d:>13.2e}{p99:>10.1e}"
                f"{over:>9.2%}{same!s:>10}"
            )
            result["chunks"].append(
                {"mode": name, "wall_s": wall, "frames_per_s": n_frames / wall,
                 "max_abs_diff_px": d, "p99_abs_diff_px": p99, "share_over_1e-4": over,
                 "same_statuses": same}
            )  # fmt: skip
        t = time.perf_counter()
        comp = dicblur.track(str(folder), compensate_blur=True, **kw)
        t_comp = time.perf_counter() - t
    for name, ds, wall in (("plain", serial, t_serial), ("compensated", comp, t_comp)):
        rows = groups(tgt, ds)
        result["compensation"][name] = {"wall_s": wall, "groups": rows}
        print(f"\n{name} ({wall:.1f} s)")
        print(
            f"{'W px':<8}{'n':>7}{'scatter x':>11}{'pred/meas':>11}"
            f"{'scatter y':>11}{'pred/meas':>11}"
        )
        for r in rows:
            print(
                f"{r['W']:<8}{r['n']:>7}{r['scatter_u']:>11.4f}{r['ratio_u']:>11.2f}"
                f"{r['scatter_v']:>11.4f}{r['ratio_v']:>11.2f}"
            )
    print("wrote", run.write(result))


if __name__ == "__main__":
    main()
