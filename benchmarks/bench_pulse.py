"""Benchmark of the 1-D pulse Monte Carlo (issue 5 target: the default run, 27 widths x
10^4 trials, in <= 10 s on 2 cores).

Run: ``.venv/bin/python benchmarks/bench_pulse.py [--repeats 3]``. Prints a table and writes
``benchmarks/results/pulse.json``. The first call includes loading (or compiling) the numba
kernel; the target is judged on the warm runs. The machine load is recorded because these
machines are shared.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time
from pathlib import Path

import numba
import numpy as np
from _harness import provenance

from dicblur import __version__
from dicblur.pulse import PAPER_WIDTHS, simulate
from dicblur.pulse.montecarlo import _white_noise_spectrum


def _time(**kw: object) -> float:
    t0 = time.perf_counter()
    simulate(**kw)  # type: ignore[arg-type]
    return time.perf_counter() - t0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--trials", type=int, default=10_000)
    args = parser.parse_args()
    load_before = os.getloadavg()
    cold = _time(widths=[1.0], trials=10, seed=0)  # numba kernel load / compile
    rows = []
    for name, kw in (
        ("default: fourier, shift blurred", {}),
        ("linear interpolation", {"interpolation": "linear"}),
        ("analytic (oracle) interpolation", {"interpolation": "analytic"}),
    ):
        reps = [
            _time(widths=PAPER_WIDTHS, trials=args.trials, seed=1, **kw)
            for _ in range(args.repeats)
        ]
        rows.append(
            {
                "variant": name,
                "widths": len(PAPER_WIDTHS),
                "trials": args.trials,
                "seconds_min": min(reps),
                "seconds_median": statistics.median(reps),
                "repeats": reps,
            }
        )
    # noise generation alone (as the default draws it: spectra from float32 normals)
    t0 = time.perf_counter()
    for child in np.random.SeedSequence(1).spawn(len(PAPER_WIDTHS)):
        rng = np.random.default_rng(child)
        _white_noise_spectrum(rng, args.trials, 220, 0.05)
        _white_noise_spectrum(rng, args.trials, 220, 0.05)
    noise_s = time.perf_counter() - t0
    load_after = os.getloadavg()
    result = {
        "stage": "pulse",
        "command": ".venv/bin/python benchmarks/bench_pulse.py",
        "target": "default Monte Carlo (27 w x 1e4 trials) <= 10 s on 2 cores",
        "cold_first_call_s": cold,
        "noise_generation_s": noise_s,
        "rows": rows,
        "target_met": rows[0]["seconds_median"] <= 10.0,
        "machine": {
            "cpu_count": os.cpu_count(),
            "numba_threads": numba.get_num_threads(),
            "python": platform.python_version(),
            "numpy": np.__version__,
            "numba": numba.__version__,
            "loadavg_before": load_before,
            "loadavg_after": load_after,
        },
        "dicblur_version": __version__,
    }
    out = Path(__file__).resolve().parent / "results" / "pulse.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({**result, "provenance": provenance()}, indent=2))
    print(
        f"pulse Monte Carlo, {args.trials} trials x {len(PAPER_WIDTHS)} widths, "
        f"{args.repeats} repeats; load avg {load_before[0]:.2f} -> {load_after[0]:.2f} "
        f"on {os.cpu_count()} cores"
    )
    print(f"{'variant':36s} {'min s':>8s} {'median s':>9s}")
    for r in rows:
        print(f"{r['variant']:36s} {r['seconds_min']:8.2f} {r['seconds_median']:9.2f}")
    print(
        f"cold first call (kernel load): {cold:.2f} s; noise generation alone: "
        f"{noise_s:.2f} s; target met: {result['target_met']}"
    )
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
