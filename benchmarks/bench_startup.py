"""Start-up cost of the package and the CLI (issue 16).

Each case runs in a fresh interpreter ``--repeats`` times; the table gives the median wall
time and the median CPU time (user + sys of the child, less sensitive to the load of this
shared machine), plus the number of modules the case imported (dicblur's and all).

Usage::

    .venv/bin/python benchmarks/bench_startup.py [--repeats 7] [--src OTHER/src] [--tag before]
    .venv/bin/python benchmarks/bench_startup.py --cold-compile [--src OTHER/src] [--tag before]

``--cold-compile`` instead times the first ``dicblur correlate`` of a 512^2 pair (speckle
4 px, softness 1, shift (0.3, -0.2) px, noise 2 GL; default settings: subset 21, step 10,
affine; then ``--shape translation``) in a fresh interpreter with an empty numba cache
(``NUMBA_CACHE_DIR`` a new folder), ``--repeats`` times per shape (default 1 there), and
numba's compile time per kernel (its compile events, CPU s, exclusive of the callees).

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


_COLD = """
import json, sys, time
from numba.core import event
records = []
class Listen(event.Listener):
    def on_start(self, e):
        records.append((time.process_time(), 1, e))
    def on_end(self, e):
        records.append((time.process_time(), 0, e))
event.register("numba:compile", Listen())
from dicblur.cli import main
try:
    main(sys.argv[1:])
except SystemExit:
    pass
stack, excl = [], {}
for t, start, e in records:
    name = e.data["dispatcher"].py_func.__qualname__
    if start:
        stack.append([name, t, 0.0])
    else:
        name, t0, inner = stack.pop()
        excl[name] = excl.get(name, 0.0) + (t - t0) - inner
        if stack:
            stack[-1][2] += t - t0
import resource
try:
    from dicblur.dic.cache import BACKGROUND_LOG as log
except ImportError:  # an older tree
    log = []
me = resource.getrusage(resource.RUSAGE_SELF)
print(json.dumps([excl, me.ru_utime + me.ru_stime, log]), file=sys.stderr)
"""


def cold_compile(opts: argparse.Namespace, env: dict[str, str], run: Run) -> None:
    import tempfile

    import numpy as np

    from dicblur import speckle_pattern
    from dicblur.io import save_image

    tmp = tempfile.mkdtemp(prefix="dicblur-cold-")
    ky = np.fft.fftfreq(512)[:, None]
    kx = np.fft.fftfreq(512)[None, :]
    rng = np.random.default_rng([2024, 99])
    ref0 = speckle_pattern((512, 512), speckle_size=4, softness=1.0, seed=2024)
    cur0 = np.fft.ifft2(np.fft.fft2(ref0) * np.exp(-2j * np.pi * (ky * -0.2 + kx * 0.3))).real
    for name, img in (("ref.tif", ref0), ("cur.tif", cur0)):
        save_image(f"{tmp}/{name}", np.clip(img + rng.normal(0, 2.0, img.shape), 0, 255))
    rows = []
    print(
        "| shape | wall (s) | CPU (s) | quiet wall estimate (s) | compile CPU (s) "
        "| top kernels (compile CPU s, this process) |"
    )
    print("|---|---|---|---|---|---|")
    for shape in ("affine", "translation"):
        for _ in range(opts.repeats):
            cache = tempfile.mkdtemp(prefix="numba-cold-")
            args = ["correlate", f"{tmp}/ref.tif", f"{tmp}/cur.tif"]
            if shape != "affine":
                args += ["--shape", shape]
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            t0 = time.perf_counter()
            proc = subprocess.run(
                [sys.executable, "-c", _COLD, *args],
                env=dict(env, NUMBA_CACHE_DIR=cache),
                capture_output=True,
                text=True,
                check=True,
            )
            wall = time.perf_counter() - t0
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
            excl, own_cpu, log = json.loads(proc.stderr.strip().splitlines()[-1])
            # the wall time on a quiet 2-core machine, from CPU times: this process up to
            # its wait for the compiling child or the child's end, whichever is later,
            # then the rest of this process
            quiet = own_cpu
            for r in log:
                if "wait_cpu_s" in r:
                    ahead = max(r["wait_cpu_s"], r["start_cpu_s"] + r["child_cpu_s"])
                    quiet = ahead + (own_cpu - r["wait_cpu_s"])
            top = sorted(excl.items(), key=lambda kv: -kv[1])[:12]
            row = {
                "shape": shape,
                "wall_s": round(wall, 2),
                "cpu_s": round(cpu, 2),
                "compile_cpu_s": round(sum(excl.values()), 2),
                "own_cpu_s": round(own_cpu, 2),
                "background": log,
                "quiet_wall_estimate_s": round(quiet, 2),
                "kernels_cpu_s": {k: round(v, 2) for k, v in top},
                "notice": "first run only" in proc.stderr,
            }
            rows.append(row)
            tops = ", ".join(f"{k} {v:.1f}" for k, v in top[:6])
            print(
                f"| {shape} | {wall:.1f} | {cpu:.1f} | {quiet:.1f} | "
                f"{row['compile_cpu_s']:.1f} | {tops} |",
                flush=True,
            )
    out = run.write({"src": opts.src, "cold_compile": rows})
    print(f"load {run.load_start} -> {run.record({})['provenance']['load_end']}; wrote {out}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=None, help="default 7 (1 with --cold-compile)")
    ap.add_argument(
        "--cold-compile", action="store_true", help="first correlate on an empty numba cache"
    )
    ap.add_argument("--src", default=None, help="source tree to import instead")
    ap.add_argument("--tag", default="", help="suffix of the result file")
    opts = ap.parse_args()
    if opts.repeats is None:
        opts.repeats = 1 if opts.cold_compile else 7
    stem = "cold_compile" if opts.cold_compile else "startup"
    run = Run(stem + (f"_{opts.tag}" if opts.tag else ""))
    env = dict(os.environ)
    if opts.src:
        env["PYTHONPATH"] = opts.src + os.pathsep + env.get("PYTHONPATH", "")
    if opts.cold_compile:
        cold_compile(opts, env, run)
        return
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
