"""Benchmark of ``dicblur reproduce``: wall time of --quick (cold numba cache, so the
first-run compilation is included, as on a fresh install) and of the full mode.

Usage::

    python benchmarks/bench_reproduce.py [--skip-full] [--out benchmarks/results/reproduce.json]

Each mode runs in a fresh interpreter (``python -m dicblur reproduce``) into a fresh output
folder, so no campaign result is reused. Targets (issue 8): quick <= 90 s, full <= 300 s on
2 cores.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _harness import provenance


def _run(args: list[str], env: dict[str, str]) -> tuple[float, dict]:
    with tempfile.TemporaryDirectory(prefix="dicblur-bench-") as tmp:
        out = Path(tmp) / "report"
        t0 = time.perf_counter()
        subprocess.run(
            [sys.executable, "-m", "dicblur", "reproduce", *args, "--out", str(out)],
            check=True,
            env=env,
            stdout=subprocess.DEVNULL,
        )
        wall = time.perf_counter() - t0
        results = json.loads((out / "results.json").read_text())
    return wall, results


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--skip-full", action="store_true")
    ap.add_argument("--out", default="benchmarks/results/reproduce.json")
    opts = ap.parse_args()
    load = os.getloadavg()
    rows = []
    with tempfile.TemporaryDirectory(prefix="dicblur-numba-") as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)  # empty cache: compile included
        wall, res = _run(["--quick"], env)
        rows.append(
            {
                "mode": "quick (cold numba cache)",
                "wall_s": wall,
                "target_s": 90,
                "stages": res["timings"],
                "claims_agree": sum(c["verdict"] == "agrees" for c in res["claims"]),
            }
        )
        if not opts.skip_full:
            wall, res = _run([], env)
            rows.append(
                {
                    "mode": "full (warm cache)",
                    "wall_s": wall,
                    "target_s": 300,
                    "stages": res["timings"],
                    "claims_agree": sum(c["verdict"] == "agrees" for c in res["claims"]),
                }
            )
    print(f"load average at start: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} (2 cores)")
    print(f"{'mode':<28}{'wall (s)':>10}{'target':>8}  stages (s)")
    for r in rows:
        st = ", ".join(f"{k} {v:.1f}" for k, v in r["stages"].items() if k != "total")
        print(f"{r['mode']:<28}{r['wall_s']:>10.1f}{r['target_s']:>8}  {st}")
    Path(opts.out).parent.mkdir(parents=True, exist_ok=True)
    Path(opts.out).write_text(
        json.dumps({"load_average": load, "runs": rows, "provenance": provenance()}, indent=2)
    )


if __name__ == "__main__":
    main()
