"""Benchmark of the uncertainty-model stage (issue 6).

Prints a table and writes ``benchmarks/results/models.json``.

Part A (always): speed of the static blur sensitivity, of the fits and of planning.
Part B (when ``dicblur.dic`` and ``dicblur.blur`` exist): the static prediction of ``c``
against ``c`` fitted from DIC on noise-free, exactly box-blurred generated patterns over a
range of speckle sizes, W <= 4 px (acceptance: within 15 %).

Run: ``.venv/bin/python benchmarks/bench_models.py [--quick]``
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import platform
import time
from pathlib import Path

import numpy as np

import dicblur
from dicblur.models import (
    PoissonGaussianCamera,
    blur_sensitivity,
    fit_blur_model,
    mismatch_model,
    plan_exposure,
    sssig_decay,
)

OUT = Path(__file__).resolve().parent / "results" / "models.json"


def _best(fn, repeat: int = 3) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def part_a() -> list[dict]:
    img = dicblur.speckle_pattern((512, 512), speckle_size=4.0, softness=0.5, seed=1)
    rows = []
    for shape in ("translation", "affine"):
        t = _best(lambda shape=shape: blur_sensitivity(img, subset=31, step=10, shape=shape))
        rows.append({"case": f"blur_sensitivity 512x512, subset 31, step 10, {shape}",
                     "seconds": t})
    t_on = _best(lambda: dicblur.pattern_metrics(img, subset=31))
    t_off = _best(lambda: dicblur.pattern_metrics(img, subset=31, blur_sensitivity=False))
    rows.append({"case": "pattern_metrics 512x512 with c / without c", "seconds": t_on,
                 "ratio": t_on / t_off})
    w = np.arange(0.0, 10.01, 0.5)
    rng = np.random.default_rng(0)
    s = sssig_decay(w, 1.85e5, 0.022)
    u = mismatch_model(w, s, 2.0, c=7e-4) * np.exp(rng.normal(0, 0.02, w.size))
    rows.append({"case": "fit_blur_model 21 points, covariance CIs (+ comparison)",
                 "seconds": _best(lambda: fit_blur_model(w, s, u, noise_sigma=2.0))})
    rows.append({"case": "fit_blur_model 21 points, bootstrap 500",
                 "seconds": _best(lambda: fit_blur_model(w, s, u, noise_sigma=2.0,
                                                         ci="bootstrap", seed=0), 1)})
    model = fit_blur_model(w, s, u, noise_sigma=2.0, mean_level=127.5)
    cam = PoissonGaussianCamera(full_well=2e4, read_noise=5.0, flux=4e6)
    rows.append({"case": "plan_exposure with a Poisson-Gaussian camera",
                 "seconds": _best(lambda: plan_exposure(model, velocity="120mm/s",
                                                        scale="0.05mm/px", camera=cam))})
    return rows


def part_b(quick: bool) -> list[dict] | None:
    if importlib.util.find_spec("dicblur.dic") is None or \
            importlib.util.find_spec("dicblur.blur") is None:
        return None
    from dicblur.blur import motion_blur
    from dicblur.dic import Correlator

    sizes = (3.0, 5.0) if quick else (3.0, 4.0, 6.0, 8.0)
    blurs = np.array([1.0, 2.0, 3.0, 4.0])
    rows = []
    for size in sizes:
        for shape in ("translation", "affine"):
            img = dicblur.speckle_pattern((256, 256), speckle_size=size, softness=0.5, seed=7)
            corr = Correlator(img, subset=31, step=10, shape=shape)
            pts = np.stack([corr.correlate(img).rows, corr.correlate(img).cols], axis=1)
            pred = blur_sensitivity(img, subset=31, points=pts, shape=shape,
                                    boundary="periodic").c
            u_e = []
            for wl in blurs:
                res = corr.correlate(motion_blur(img, (0.0, float(wl)), substeps=None))
                ok = res.converged
                u_e.append(float(np.std(res.u[ok])))
            u_arr = np.array(u_e)
            c_fit = float(np.sum(u_arr * blurs**2) / np.sum(blurs**4))
            rows.append({"speckle_size": size, "shape": shape, "c_static": pred,
                         "c_fit": c_fit, "ratio": c_fit / pred,
                         "u_e": dict(zip(map(float, blurs), u_e, strict=True))})
    return rows


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    a = part_a()
    print(f"{'case':62s} {'seconds':>9s}")
    for r in a:
        extra = f"  (x{r['ratio']:.2f})" if "ratio" in r else ""
        print(f"{r['case']:62s} {r['seconds']:9.4f}{extra}")
    b = part_b(args.quick)
    if b is None:
        print("part B (static c vs DIC-fitted c): pending, dicblur.dic / dicblur.blur absent")
    else:
        print(f"\n{'speckle px':>10s} {'shape':>12s} {'c static':>10s} {'c fitted':>10s} "
              f"{'ratio':>6s}")
        for r in b:
            print(f"{r['speckle_size']:10.1f} {r['shape']:>12s} {r['c_static']:10.3e} "
                  f"{r['c_fit']:10.3e} {r['ratio']:6.3f}")
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps({
        "machine": {"python": platform.python_version(), "cpus": os.cpu_count(),
                    "load": os.getloadavg()},
        "speed": a, "c_validation": b}, indent=1))
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
