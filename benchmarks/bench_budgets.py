"""Time budgets of ``dicblur pulse`` and ``dicblur calibrate`` (issue 26: each <= 20 s warm),
phase by phase, so that the next regression shows at once.

Run: ``python benchmarks/bench_budgets.py [--repeats 2] [--image IMAGE] [--skip-cli]``.

- ``pulse``: the command end to end (``dicblur pulse -o TMP``, default 10^4 trials, a fresh
  process, warm numba cache) ``--repeats`` times, then the phases of one in-process run from
  the library's own timer (``PulseStudy.timings``: the main Monte Carlo, the log-log fits,
  the dependence study, Table II, Fig. 5, the verdict) plus the figures
  (``report.pulse_figures.write_figures``).
- ``calibrate``: ``dicblur calibrate IMAGE -o TMP -q`` end to end, then the phases of one
  in-process run (``CalibrationResult.timings``: the DIC sweep, the CSV export, the static
  prediction's table, the fits, the model file) plus the figures and the planner page.
  IMAGE defaults to a 384^2 centre crop of the real printed pattern
  ``../shared/data/real/sundic_planar/img_0.tif`` (the issue's case) and, when that folder
  is absent, to a generated ``paper4`` pattern of 384^2.

Prints a table and writes ``benchmarks/results/budgets.json`` (with the harness's commit,
machine and load: wall times on a shared machine mean little without the load; the process
CPU time of the in-process phases is recorded beside each wall time).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from _harness import Run

REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"
PRINTED = REAL / "sundic_planar" / "img_0.tif"
BUDGET_S = 20.0


def _cli(args: list[str]) -> tuple[float, float]:
    """Wall and CPU time (s, children included) of ``python -m dicblur ARGS``."""
    before = os.times()
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "dicblur", *args], check=True, capture_output=True)
    wall = time.perf_counter() - t0
    after = os.times()
    cpu = (after.children_user - before.children_user) + (
        after.children_system - before.children_system
    )
    return wall, cpu


def _image(path: str | None, folder: Path) -> tuple[str, str]:
    """The calibration image (a file) and its description."""
    if path is not None:
        return path, path
    from dicblur.io import load_image, save_image

    if PRINTED.is_file():
        img = load_image(PRINTED)
        r0, c0 = (img.shape[0] - 384) // 2, (img.shape[1] - 384) // 2
        crop = img[r0 : r0 + 384, c0 : c0 + 384]
        what = f"{PRINTED.name} (sundic_planar), 384^2 centre crop at ({r0}, {c0})"
    else:
        from dicblur.patterns import paper_pattern4

        crop = np.clip(paper_pattern4((384, 384), seed=1), 0, 255)
        what = "generated paper4 pattern, 384^2, seed 1 (real images absent)"
    out = folder / "pattern384.tif"
    save_image(out, np.round(crop))
    return str(out), what


def _phase_rows(command: str, phases: dict[str, float], cpu: dict[str, float]) -> list[dict]:
    return [
        {
            "command": command,
            "phase": k,
            "wall_s": round(v, 3),
            "cpu_s": None if k not in cpu else round(cpu[k], 3),
        }
        for k, v in phases.items()
    ]


def bench_pulse(repeats: int, tmp: Path, cli: bool) -> list[dict[str, Any]]:
    from dicblur.pulse.study import run_pulse_study
    from dicblur.report.pulse_figures import write_figures

    rows: list[dict[str, Any]] = []
    if cli:
        for i in range(repeats):
            wall, cpu = _cli(["pulse", "-o", str(tmp / f"pulse{i}")])
            rows.append(
                {
                    "command": "dicblur pulse",
                    "phase": f"end to end, run {i + 1}",
                    "wall_s": round(wall, 3),
                    "cpu_s": round(cpu, 3),
                }
            )
    c0 = time.process_time()
    study = run_pulse_study()
    cpu_study = time.process_time() - c0
    (tmp / "pulse_fig").mkdir()
    t0 = time.perf_counter()
    write_figures(study, tmp / "pulse_fig")
    phases = {**study.timings, "figures": time.perf_counter() - t0}
    rows += _phase_rows("dicblur pulse", phases, {})
    rows.append(
        {
            "command": "dicblur pulse",
            "phase": "library total (run_pulse_study)",
            "wall_s": round(sum(study.timings.values()), 3),
            "cpu_s": round(cpu_study, 3),
        }
    )
    return rows


def bench_calibrate(repeats: int, tmp: Path, image: str, cli: bool) -> list[dict[str, Any]]:
    from dicblur.campaign.calibrate import calibrate
    from dicblur.report.planner import write_planner
    from dicblur.report.plots import calibration_figures

    rows: list[dict[str, Any]] = []
    if cli:
        for i in range(repeats):
            wall, cpu = _cli(["calibrate", image, "-o", str(tmp / f"cal{i}"), "-q"])
            rows.append(
                {
                    "command": "dicblur calibrate",
                    "phase": f"end to end, run {i + 1}",
                    "wall_s": round(wall, 3),
                    "cpu_s": round(cpu, 3),
                }
            )
    c0 = time.process_time()
    res = calibrate(image, tmp / "cal_lib")
    cpu_lib = time.process_time() - c0
    assert res is not None
    t0 = time.perf_counter()
    calibration_figures(res)
    t1 = time.perf_counter()
    write_planner([res.model], tmp / "cal_lib" / "planner.html")
    t2 = time.perf_counter()
    phases = {**res.timings, "figures": t1 - t0, "planner": t2 - t1}
    rows += _phase_rows("dicblur calibrate", phases, {})
    global _CALIBRATION
    _CALIBRATION = res
    rows.append(
        {
            "command": "dicblur calibrate",
            "phase": "library total (calibrate, main process CPU)",
            "wall_s": round(sum(res.timings.values()), 3),
            "cpu_s": round(cpu_lib, 3),
        }
    )
    return rows


_CALIBRATION: Any = None


def bench_predictions(image: str, reps: int) -> list[dict[str, Any]]:
    """Calibrated at 2 GL (the calibrate run above), predicted at W = 1, 3, 5 px and 1, 2,
    4 GL, against a direct simulation of the same image (fresh noise, ``reps``
    repetitions; u_e as the rms over them), with the static kind's noise scale fixed at 1
    (the default at one level) and fitted (the earlier rule) side by side."""
    import tempfile as _tf

    from dicblur.campaign.calibrate import calibration_spec
    from dicblur.campaign.engine import run_campaign
    from dicblur.campaign.store import open_results
    from dicblur.models.scaled import StaticTerms, fit_static_scales, static_variance

    res = _CALIBRATION
    m = res.model
    blur, levels = [1.0, 3.0, 5.0], [1.0, 2.0, 4.0]
    spec = calibration_spec(image, noise=levels, blur=blur, repetitions=reps, seed=7)
    with _tf.TemporaryDirectory() as d:
        run_campaign(spec, Path(d) / "direct.zarr", serial=True)
        ds = open_results(Path(d) / "direct.zarr").isel(pattern=0, angle=0, subset=0)
        u = ds["u_e"].transpose("noise", "blur", "rep").values
    direct = np.sqrt(np.mean(u**2, axis=2))
    ex = m.static.extra
    terms = StaticTerms(
        blur=tuple(ex["table_blur"]),
        noise=tuple(ex["table_noise"]),
        noise2=tuple(ex["table_noise2"]),
        mismatch=tuple(ex["table_mismatch"]),
        valid_fraction=tuple(ex["table_valid_fraction"]),
        breakdown_blur=ex["table_breakdown_blur"],
    )
    w, sig, ue = (np.asarray(m.data[k], dtype=np.float64) for k in ("blur", "noise", "u_e"))
    rows = []
    for rule in ("auto", "fit"):
        f = fit_static_scales(terms, w, sig, ue, noise_scale=rule)
        for i, s in enumerate(levels):
            nv, bv = static_variance(f.extra, blur, s, f["k_noise"], f["k_blur"])
            for j, wj in enumerate(blur):
                pred = float(np.sqrt(nv[j] + bv[j]))
                rows.append(
                    {
                        "k_noise rule": "fixed at 1 (default)" if rule == "auto" else "fitted",
                        "k_noise": round(f["k_noise"], 4),
                        "k_blur": round(f["k_blur"], 4),
                        "noise_GL": s,
                        "blur_px": wj,
                        "predicted_px": round(pred, 6),
                        "direct_px": round(float(direct[i, j]), 6),
                        "ratio": round(pred / float(direct[i, j]), 4),
                    }
                )
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=2, help="end-to-end runs per command")
    parser.add_argument("--image", default=None, help="calibration image (default: see above)")
    parser.add_argument("--skip-cli", action="store_true", help="phases only, no end-to-end runs")
    parser.add_argument("--only", choices=("pulse", "calibrate"), default=None)
    parser.add_argument(
        "--reps", type=int, default=4, help="repetitions of the direct simulation (0 skips)"
    )
    args = parser.parse_args()
    run = Run("budgets")
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        image, what = _image(args.image, tmp)
        # warm: numba caches loaded (a first call may compile) before anything is timed
        from dicblur.pulse.montecarlo import PAPER_TRAIN, simulate

        for kind in ("fourier", "bspline"):
            simulate(PAPER_TRAIN, widths=[1.0], trials=4, interpolation=kind)
        rows: list[dict[str, Any]] = []
        preds: list[dict[str, Any]] = []
        if args.only in (None, "pulse"):
            rows += bench_pulse(args.repeats, tmp, not args.skip_cli)
        if args.only in (None, "calibrate"):
            rows += bench_calibrate(args.repeats, tmp, image, not args.skip_cli)
            if args.reps > 0:
                preds = bench_predictions(image, args.reps)
    print(f"{'command':20s} {'phase':45s} {'wall s':>8s} {'cpu s':>8s}")
    for r in rows:
        cpu = "" if r["cpu_s"] is None else f"{r['cpu_s']:8.2f}"
        print(f"{r['command']:20s} {r['phase']:45s} {r['wall_s']:8.2f} {cpu:>8s}")
    ends = {
        c: [r["wall_s"] for r in rows if r["command"] == c and r["phase"].startswith("end")]
        for c in ("dicblur pulse", "dicblur calibrate")
    }
    summary = {
        c: {"wall_min_s": min(v), "budget_s": BUDGET_S, "within": min(v) <= BUDGET_S}
        for c, v in ends.items()
        if v
    }
    for c, s in summary.items():
        print(f"{c}: best end-to-end {s['wall_min_s']:.2f} s (budget {BUDGET_S:g} s)")
    if preds:
        print("\ncalibrated at 2 GL, predicted against a direct simulation (static kind)")
        print(f"{'k_noise':22s} {'noise GL':>8s} {'W px':>5s} {'pred px':>9s} {'direct':>9s} ratio")
        for p in preds:
            print(
                f"{p['k_noise rule']:22s} {p['noise_GL']:8g} {p['blur_px']:5g} "
                f"{p['predicted_px']:9.5f} {p['direct_px']:9.5f} {p['ratio']:.3f}"
            )
    path = run.write({"image": what, "cases": rows, "summary": summary, "predictions": preds})
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
