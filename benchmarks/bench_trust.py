"""Benchmark: `dicblur calibrate`, then `predict` at another noise level and a camera `plan`,
against a direct simulation at those settings (issue 14, "done when").

1. ``dicblur calibrate paper4 --size 512x512 --noise 2 --subset 21 --blur 0:8:0.5`` (one
   noise level; the default model: the static kind, with the fitted noise + blur-mismatch
   model beside it, whose prediction is recorded too as ``predicted_mismatch``).
2. ``dicblur predict model.json --blur 3 --noise 1|4`` and ``--blur 7 --noise 4`` (the
   large-blur regime) against a campaign at that noise and W on the same pattern (fresh
   noise, ``--reps`` repetitions).
3. ``dicblur plan model.json --velocity 120mm/s --scale 0.05mm/px --full-well 20000
   --read-noise 5 --flux 4e6``: the predicted u_e at the planned optimum against a
   campaign at the optimum's W and the camera's noise there (Gaussian, std
   ``PoissonGaussianCamera.noise_gl``).
4. The power law of the same calibration at noise 4 is refused (exit 2).

Target: |predicted / simulated - 1| <= 10 %. Writes ``benchmarks/results/trust.json``.

Run: ``NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/bench_trust.py [--size 512]
[--reps 3] [--out-dir /tmp/bench_trust]``
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import shutil
import time
from pathlib import Path

import numpy as np
from _harness import Run, use_tests_dir

from dicblur.cli import main as cli
from dicblur.models import BlurUncertaintyModel, PoissonGaussianCamera

use_tests_dir()
from helpers.cli import CAMERA_PLAN, calibrate_args  # noqa: E402
from helpers.models import simulated_u_e  # noqa: E402

OUT = Path(__file__).resolve().parent / "results" / "trust.json"
CAMERA = {"full_well": 20000.0, "read_noise": 5.0, "flux": 4e6}


def _cli_json(args: list[str]) -> dict:
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = cli(args)
    if code != 0:
        raise SystemExit(f"dicblur {' '.join(args)} exited with {code}")
    return json.loads(buf.getvalue())


def _direct(
    work: Path, tag: str, *, noise: float, blur: float, size: int, reps: int
) -> tuple[float, float]:
    """RMS u_e over repetitions and its standard error, same pattern (seed 1)."""
    u = simulated_u_e(work, tag, noise=noise, blur=blur, size=size, reps=reps)
    rms = float(np.sqrt(np.mean(u**2)))
    return rms, float(np.std(u, ddof=1) / np.sqrt(u.size)) if u.size > 1 else float("nan")


def run(size: int, reps: int, work: Path) -> dict:
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    t0 = time.perf_counter()
    code = cli(calibrate_args(work / "cal", blur="0:8:0.5", size=size))
    if code != 0:
        raise SystemExit(f"calibrate exited with {code}")
    t_cal = time.perf_counter() - t0
    model_path = str(work / "cal" / "model.json")
    m = BlurUncertaintyModel.from_json(model_path)
    rows = []
    for wb, noise in ((3.0, 1.0), (3.0, 4.0), (7.0, 4.0)):
        pred = _cli_json(
            ["predict", model_path, "--blur", f"{wb:g}", "--noise", f"{noise:g}", "--json"]
        )["predictions"][0]["u_e_px"]
        tag = f"n{noise:g}" if wb == 3.0 else f"w{wb:g}n{noise:g}"
        meas, se = _direct(work, tag, noise=noise, blur=wb, size=size, reps=reps)
        mism = float(m.predict([wb], noise, model="mismatch").u_e[0]) if m.mismatch else None
        rows.append(
            {
                "case": f"predict W={wb:g} px, noise {noise:g} GL",
                "predicted": pred,
                "predicted_mismatch": mism,
                "simulated": meas,
                "simulated_se": se,
                "ratio": pred / meas,
            }
        )
    plan = _cli_json(["plan", model_path, *CAMERA_PLAN, "--json"])
    cam = PoissonGaussianCamera(**CAMERA)
    sigma = float(cam.noise_gl(plan["exposure"], m.mean_level))
    meas, se = _direct(work, "plan", noise=sigma, blur=plan["blur"], size=size, reps=reps)
    rows.append(
        {
            "case": f"camera plan optimum {plan['exposure'] * 1e3:.3g} ms, W "
            f"{plan['blur']:.3g} px, noise {sigma:.3g} GL",
            "predicted": plan["u_e"],
            "predicted_mismatch": None,
            "simulated": meas,
            "simulated_se": se,
            "ratio": plan["u_e"] / meas,
        }
    )
    with contextlib.redirect_stderr(io.StringIO()) as err:
        refused = cli(
            ["predict", model_path, "--blur", "3", "--noise", "4", "--model", "power_law"]
        )
    return {
        "size": size,
        "reps": reps,
        "calibrate_s": t_cal,
        "default": m.default,
        "domain": m.domain.to_dict() if m.domain else None,
        "plan": {k: plan[k] for k in ("exposure", "blur", "u_e", "inside_domain", "notes")},
        "rows": rows,
        "power_law_refused": refused == 2,
        "power_law_message": err.getvalue().strip(),
        "ok": all(abs(r["ratio"] - 1) <= 0.10 for r in rows) and refused == 2,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--out-dir", type=Path, default=Path("/tmp/bench_trust"))
    args = ap.parse_args()
    bench = Run("trust")
    res = run(args.size, args.reps, args.out_dir)
    print(f"calibrate {args.size}^2: {res['calibrate_s']:.0f} s, default {res['default']}")
    print(f"{'case':58s} {'predicted':>10s} {'simulated':>10s} {'ratio':>7s} mismatch ratio")
    for r in res["rows"]:
        mm = r["predicted_mismatch"]
        print(
            f"{r['case']:58s} {r['predicted']:10.4g} {r['simulated']:10.4g} {r['ratio']:7.3f}"
            + ("" if mm is None else f" {mm / r['simulated']:7.3f}")
        )
    print(f"power law at noise 4 refused: {res['power_law_refused']} ({res['power_law_message']})")
    print(f"wrote {bench.write({'results': res}, OUT)}")


if __name__ == "__main__":
    main()
