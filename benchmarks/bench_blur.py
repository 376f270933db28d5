"""Benchmark: literal Algorithm 1 (K = 100) against motion_blur (one FFT pair).

Run from the repository root::

    python benchmarks/bench_blur.py [--sizes 512 1024 2048] [--repeats 10]

Both methods run side by side on the same image in one process, so their time ratio is
meaningful on a shared machine. Prints a table and writes benchmarks/results/blur.json.
A second table compares render_blurred (supersampled, whole fine-pixel moves) with the
Fourier method for a band-limited pattern and for a hard-edged speckle pattern.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np
from _harness import provenance, use_tests_dir

import dicblur
from dicblur import motion_blur, render_blurred, speckle_pattern

use_tests_dir()
from helpers.blur import smooth_fine  # noqa: E402

MOTION = (1.7, 4.3)  # diagonal, sub-pixel, W = 4.62 px
SUBSTEPS = 100


def _best(fn, repeats: int) -> tuple[float, float, np.ndarray]:
    """Best wall time and best process CPU time (s) over ``repeats`` runs, and the output.

    Every step is single-threaded (scipy.fft with workers=1, numba kernel, numpy), so the
    CPU time is close to the uncontended wall time and much less sensitive to other jobs
    on a shared machine.
    """
    best_wall, best_cpu, out = float("inf"), float("inf"), None
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        best_cpu = min(best_cpu, time.process_time() - c0)
        best_wall = min(best_wall, time.perf_counter() - t0)
    assert out is not None
    return best_wall, best_cpu, out


def speed(sizes: list[int], repeats: int) -> list[dict]:
    rows = []
    for n in sizes:
        img = speckle_pattern((n, n), speckle_size=4, softness=0.5, seed=1)
        grey_range = float(np.ptp(img))
        motion_blur(img[:64, :64], MOTION)  # warm-up (FFT plans, imports)
        t_fft, c_fft, fast = _best(
            lambda img=img: motion_blur(img, MOTION, substeps=SUBSTEPS), repeats
        )
        loop_repeats = 1 if n >= 2048 else 2
        t_loop, c_loop, slow = _best(
            lambda img=img: motion_blur(img, MOTION, substeps=SUBSTEPS, method="loop"),
            loop_repeats,
        )
        diff = float(np.abs(fast - slow).max())
        rows.append(
            {
                "size": n,
                "substeps": SUBSTEPS,
                "motion_dy_dx": list(MOTION),
                "loop_s": t_loop,
                "fft_s": t_fft,
                "speedup": t_loop / t_fft,
                "loop_cpu_s": c_loop,
                "fft_cpu_s": c_fft,
                "speedup_cpu": c_loop / c_fft,
                "max_abs_diff": diff,
                "max_abs_diff_over_range": diff / grey_range,
            }
        )
    return rows


def rendering(n: int = 64) -> list[dict]:
    rows = []
    for ss in (2, 4, 8, 16):
        for kind in ("band-limited", "hard-edged speckle"):
            if kind == "band-limited":
                fine = smooth_fine(n, ss)
            else:
                fine = speckle_pattern((n * ss, n * ss), speckle_size=3 * ss, seed=1)
            camera = fine.reshape(n, ss, n, ss).mean(axis=(1, 3))
            diff = render_blurred(fine, MOTION, supersample=ss) - motion_blur(
                camera, MOTION, substeps=None
            )
            rows.append(
                {
                    "pattern": kind,
                    "supersample": ss,
                    "rms_diff_gl": float(np.sqrt(np.mean(diff**2))),
                    "max_diff_gl": float(np.abs(diff).max()),
                    "grey_range": float(np.ptp(camera)),
                }
            )
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[512, 1024, 2048])
    ap.add_argument("--repeats", type=int, default=10, help="motion_blur runs (best kept)")
    args = ap.parse_args()
    load = os.getloadavg()
    speed_rows = speed(args.sizes, args.repeats)
    print(f"motion_blur vs literal Algorithm 1, K = {SUBSTEPS}, motion (dy, dx) = {MOTION} px")
    print(
        f"{'size':>6} {'loop s':>9} {'fft s':>9} {'speedup':>8} {'loop cpu':>9} "
        f"{'fft cpu':>9} {'cpu x':>7} {'max|diff|':>10} {'/range':>9}"
    )
    for r in speed_rows:
        print(
            f"{r['size']:>6} {r['loop_s']:>9.3f} {r['fft_s']:>9.4f} {r['speedup']:>8.1f} "
            f"{r['loop_cpu_s']:>9.3f} {r['fft_cpu_s']:>9.4f} {r['speedup_cpu']:>7.1f} "
            f"{r['max_abs_diff']:>10.2e} {r['max_abs_diff_over_range']:>9.2e}"
        )
    render_rows = rendering()
    print("\nrender_blurred vs motion_blur(continuous) on 64x64 px, same motion")
    print(f"{'pattern':>20} {'ss':>3} {'rms GL':>8} {'max GL':>8}")
    for r in render_rows:
        print(
            f"{r['pattern']:>20} {r['supersample']:>3} {r['rms_diff_gl']:>8.3f} "
            f"{r['max_diff_gl']:>8.3f}"
        )
    end = os.getloadavg()
    print(
        f"\nload average at start: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}, at end "
        f"{end[0]:.2f} ({os.cpu_count()} cpus)"
    )
    out = Path(__file__).resolve().parent / "results" / "blur.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(
        json.dumps(
            {
                "provenance": provenance(),
                "benchmark": "blur",
                "dicblur_version": dicblur.__version__,
                "numpy": np.__version__,
                "python": platform.python_version(),
                "machine": platform.machine(),
                "cpus": os.cpu_count(),
                "load_average_start": load,
                "load_average_end": end,
                "speed": speed_rows,
                "rendering": render_rows,
            },
            indent=2,
        )
    )
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
