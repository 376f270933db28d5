"""Benchmark of ``dicblur design`` (issue 9 target: a design run of the default family in
<= 10 minutes on 2 cores; report how many campaigns and campaign points it used).

Run: ``.venv/bin/python benchmarks/bench_design.py [--quick]``. Runs the default design
(family 5 x 3 x 3 = 45 grid candidates, up to 20 refinement campaigns, confirmation on 8
fresh realisations; 256 px images, 2 realisations per candidate, subset 31, step 10,
noise 2 GL) for several design blurs, prints a table and writes
``benchmarks/results/design.json``. Wall and process CPU time are both recorded (every
step is single-threaded; the machine is shared, so CPU time is the steadier number) with
the load average. The first run includes loading the DIC engine's compiled kernels.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

from _harness import provenance

from dicblur import __version__
from dicblur.design import design_pattern, design_problem


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="Only the W = 3 px run.")
    parser.add_argument(
        "--only",
        default=None,
        help="Run only the cases whose name contains this text; rows of "
        "other cases already in the JSON file are kept.",
    )
    args = parser.parse_args()
    cases: list[tuple[str, dict[str, object], dict[str, object]]] = [
        ("W = 3 px (default run)", {"blur": 3.0}, {})
    ]
    if not args.quick:
        cases += [
            ("W = 0 px (static)", {"blur": 0.0}, {}),
            ("W = 0..5 px (mean)", {"blur_range": (0.0, 5.0)}, {}),
            ("W = 6 px", {"blur": 6.0}, {}),
            ("W = 3 px, 512 px images", {"blur": 3.0, "image_size": 512}, {}),
            ("W = 3 px, surrogate screen 10", {"blur": 3.0}, {"screen": 10}),
        ]
    if args.only:
        cases = [c for c in cases if args.only in c[0]]
    load_before = os.getloadavg()
    rows = []
    for name, kw, dkw in cases:
        problem = design_problem(noise=2.0, subset=31, **kw)  # type: ignore[arg-type]
        t0, c0 = time.perf_counter(), time.process_time()
        r = design_pattern(problem, **dkw)  # type: ignore[arg-type]
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        s = r.summary()
        b = r.best.candidate
        rows.append(
            {
                "case": name,
                "wall_s": wall,
                "cpu_s": cpu,
                "campaigns": r.n_campaigns,
                "campaign_points": r.n_points,
                "grid": s["n_grid"],
                "refine": s["n_refine"],
                "screened": s["n_screened"],
                "best_D": b.speckle_size,
                "best_density": b.density,
                "best_softness": b.softness,
                "best_pred": s["best_predicted_u_e"],
                "best_meas": s["best_measured_u_e"],
                "best_meas_se": s["best_measured_stderr"],
                "default_meas": s["default_measured_u_e"],
                "default_meas_se": s["default_measured_stderr"],
                "worst_meas": s["worst_measured_u_e"],
                "gain_vs_default": s["gain_vs_default"],
                "gain_vs_worst": s["gain_vs_worst"],
            }
        )
        print(f"{name}: {wall:.1f} s wall, {cpu:.1f} s CPU, {r.n_campaigns} campaigns", flush=True)
    load_after = os.getloadavg()
    out = Path(__file__).resolve().parent / "results" / "design.json"
    if args.only and out.is_file():
        old = json.loads(out.read_text())["rows"]
        names = {r_["case"] for r_ in rows}
        rows = [r_ for r_ in old if r_["case"] not in names] + rows
    hdr = (
        "| case | wall (s) | CPU (s) | campaigns (grid+refine+ref+confirm) | points | best "
        "D / p / s (px, -, px) | predicted u_e best (px) | measured best (px) | "
        "measured default (px) | measured worst (px) | gain vs default | gain vs worst |"
    )
    print(hdr)
    print("|" + "---|" * 12)
    for r_ in rows:
        print(
            f"| {r_['case']} | {r_['wall_s']:.1f} | {r_['cpu_s']:.1f} | {r_['campaigns']} "
            f"({r_['grid']}+{r_['refine']}) | {r_['campaign_points']} | "
            f"{r_['best_D']:.2f} / {r_['best_density']:.2f} / {r_['best_softness']:.2f} | "
            f"{r_['best_pred']:.4f} | {r_['best_meas']:.4f} ± {r_['best_meas_se']:.4f} | "
            f"{r_['default_meas']:.4f} ± {r_['default_meas_se']:.4f} | "
            f"{r_['worst_meas']:.4f} | {100 * r_['gain_vs_default']:.0f} % | "
            f"{100 * r_['gain_vs_worst']:.0f} % |"
        )
    print(
        f"load average before {load_before[0]:.1f}, after {load_after[0]:.1f} "
        f"({os.cpu_count()} cores)"
    )
    result = {
        "version": __version__,
        "python": platform.python_version(),
        "cpu_count": os.cpu_count(),
        "load_before": load_before,
        "load_after": load_after,
        "target_s": 600,
        "rows": rows,
    }
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps({**result, "provenance": provenance()}, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
