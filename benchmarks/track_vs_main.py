"""``dicblur.track`` end to end on bench_track's 1,000-frame recording, for a side by side.

Runs whichever dicblur is first on the path, so another version is measured with its source
exported, e.g. main's::

    git archive main src | tar -x -C /tmp/main_src
    NUMBA_NUM_THREADS=1 NUMBA_CACHE_DIR=/tmp/main_numba PYTHONPATH=/tmp/main_src/src \
        .venv/bin/python benchmarks/track_vs_main.py affine,translation /tmp/main.json
    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/track_vs_main.py affine,translation \
        /tmp/branch.json

(one after the other: the machine is shared). The recording (512^2 8-bit .mraw, the 0.2 ms
vibration of bench_track) is written once to ``--folder`` and reused by both runs.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_track as bt

import dicblur
from dicblur.sequence import open_recording


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("shapes", help="e.g. affine,translation")
    ap.add_argument("out", help="JSON file to write")
    ap.add_argument("--folder", default="/tmp/track_vs_main")
    args = ap.parse_args()
    folder = Path(args.folder)
    folder.mkdir(parents=True, exist_ok=True)
    head = folder / "rec1000.cih"
    if not head.exists():
        bt._write_mraw(folder / "rec1000", 512, 1000, 0.2e-3)
    print("dicblur from", dicblur.__file__, flush=True)
    rec = open_recording(head)
    out = []
    for shape in args.shapes.split(","):
        dicblur.Correlator(rec.frame(0), subset=21, step=10, shape=shape).warmup()  # type: ignore[arg-type]
        t0, c0 = time.perf_counter(), time.process_time()
        ds = dicblur.track(rec, static="0:10", subset=21, step=10, shape=shape, workers=1)  # type: ignore[arg-type]
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        r = {
            "shape": shape,
            "workers": 1,
            "end_to_end_s": wall,
            "end_to_end_frames_per_s": len(rec) / wall,
            "cpu_s": cpu,
            "frames_per_cpu_s": len(rec) / cpu,
            "tracking_s": float(ds.attrs["tracking_time_s"]),
            "prediction_s": float(ds.attrs["prediction_time_s"]),
            "load": os.getloadavg()[0],
        }
        print(json.dumps(r), flush=True)
        out.append(r)
    Path(args.out).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
