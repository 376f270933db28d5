"""Start-up cost of the package and the CLI (issue 16).

Each case runs in a fresh interpreter ``--repeats`` times; the table gives the median wall
time and the median CPU time (user + sys of the child, less sensitive to the load of this
shared machine), plus the number of modules the case imported (dicblur's and all).

Usage::

    .venv/bin/python benchmarks/bench_startup.py [--repeats 7] [--src OTHER/src] [--tag before]

``--src`` puts another source tree first on ``PYTHONPATH`` (e.g. an exported older commit),
so the same interpreter and dependencies measure the old and the new code side by side.
Writes ``benchmarks/results/startup[_TAG].json``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import time

from _harness import Run

COUNT = (
    "import json, sys; print(json.dumps([len(sys.modules), "
    "len([m for m in sys.modules if m.startswith('dicblur')])]), file=sys.stderr)"
)
CASES = {
    "import dicblur": "import dicblur",
    "import dicblur.dic": "import dicblur.dic",
    "dicblur --version": "import sys; sys.argv = ['dicblur', '--version']; "
    "from dicblur.cli import main; main(['--version'])",
    "dicblur --help": "from dicblur.cli import main; main(['--help'])",
}


def run_case(code: str, env: dict[str, str]) -> tuple[float, float, list[int]]:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-c", f"{code}\n{COUNT}"],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    counts = json.loads(proc.stderr.strip().splitlines()[-1])
    return wall, cpu, counts


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--src", default=None, help="source tree to import instead")
    ap.add_argument("--tag", default="", help="suffix of the result file")
    opts = ap.parse_args()
    run = Run("startup" + (f"_{opts.tag}" if opts.tag else ""))
    env = dict(os.environ)
    if opts.src:
        env["PYTHONPATH"] = opts.src + os.pathsep + env.get("PYTHONPATH", "")
    rows = []
    print("| case | wall median (s) | CPU median (s) | modules | dicblur modules |")
    print("|---|---|---|---|---|")
    for name, code in CASES.items():
        run_case(code, env)  # warm the OS file cache and the .pyc files
        walls, cpus, counts = [], [], [0, 0]
        for _ in range(opts.repeats):
            w, c, counts = run_case(code, env)
            walls.append(w)
            cpus.append(c)
        row = {
            "case": name,
            "wall_median_s": round(statistics.median(walls), 3),
            "wall_min_s": round(min(walls), 3),
            "cpu_median_s": round(statistics.median(cpus), 3),
            "modules": counts[0],
            "dicblur_modules": counts[1],
        }
        rows.append(row)
        print(
            f"| {name} | {row['wall_median_s']:.3f} | {row['cpu_median_s']:.3f} | "
            f"{counts[0]} | {counts[1]} |"
        )
    out = run.write({"src": opts.src, "repeats": opts.repeats, "cases": rows})
    print(f"load {run.load_start} -> {run.record({})['provenance']['load_end']}; wrote {out}")


if __name__ == "__main__":
    main()
