"""Benchmark of the uncertainty-model stage (issue 6).

Prints a table and writes ``benchmarks/results/models.json``.

Part A (always): speed of the static blur sensitivity, of the fits and of planning.
Part C (always, independent of the DIC code): the same comparison with the SSD minimum of
each subset found by brute force (exact Fourier box blur and shift, ``least_squares`` over
the translation (u, v)), i.e. the quantity the expansion approximates.
Part E (when ``dicblur.dic`` exists): held-out comparison of the power law and the
mismatch model on DIC data (W = 0..8 px, noise 1, 2, 4 GL): fit on W <= 5 px and noise
1, 2 GL, predict the rest.
The static ``c`` against IC-GN (formerly part B) is ``benchmarks/bench_blur_sensitivity.py``.

Exposure planning against a brute-force sweep (formerly part D) is
``benchmarks/bench_planning.py``.

Run: ``.venv/bin/python benchmarks/bench_models.py [--quick] [--only c ...]``
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import json
import os
import platform
import time
from pathlib import Path

import numpy as np
from _harness import provenance, use_tests_dir

import dicblur
from dicblur.models import (
    PoissonGaussianCamera,
    blur_sensitivity,
    fit_blur_model,
    mismatch_model,
    plan_exposure,
    sssig_decay,
)

use_tests_dir()
from helpers.models import bruteforce_ssd_u_e, subset_centres  # noqa: E402

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
        rows.append(
            {"case": f"blur_sensitivity 512x512, subset 31, step 10, {shape}", "seconds": t}
        )
    t_metrics = _best(lambda: dicblur.pattern_metrics(img, subset=31))
    t_c = _best(lambda: blur_sensitivity(img, subset=31))
    rows.append(
        {
            "case": "pattern_metrics 512x512 / blur_sensitivity on its subsets",
            "seconds": t_metrics,
            "ratio": (t_metrics + t_c) / t_metrics,
        }
    )
    w = np.arange(0.0, 10.01, 0.5)
    rng = np.random.default_rng(0)
    s = sssig_decay(w, 1.85e5, 0.022)
    u = mismatch_model(w, s, 2.0, c=7e-4) * np.exp(rng.normal(0, 0.02, w.size))
    rows.append(
        {
            "case": "fit_blur_model 21 points, covariance CIs (+ comparison)",
            "seconds": _best(lambda: fit_blur_model(w, s, u, noise_sigma=2.0)),
        }
    )
    rows.append(
        {
            "case": "fit_blur_model 21 points, bootstrap 500",
            "seconds": _best(
                lambda: fit_blur_model(w, s, u, noise_sigma=2.0, ci="bootstrap", seed=0), 1
            ),
        }
    )
    model = fit_blur_model(w, s, u, noise_sigma=2.0, mean_level=127.5)
    cam = PoissonGaussianCamera(full_well=2e4, read_noise=5.0, flux=4e6)
    rows.append(
        {
            "case": "plan_exposure with a Poisson-Gaussian camera",
            "seconds": _best(
                lambda: plan_exposure(model, velocity="120mm/s", scale="0.05mm/px", camera=cam)
            ),
        }
    )
    return rows


def _fit_c(blurs: np.ndarray, u_e: np.ndarray) -> tuple[float, float]:
    """c of u = c W^2 (least squares) and the leading c of u = c W^2 + c4 W^4."""
    c_pure = float(np.sum(u_e * blurs**2) / np.sum(blurs**4))
    a = np.stack([blurs**2, blurs**4], axis=1)
    c_lead = float(np.linalg.lstsq(a, u_e, rcond=None)[0][0])
    return c_pure, c_lead


def part_c(quick: bool) -> list[dict]:

    n, sub = 128, 31
    sizes = (3.0, 6.0) if quick else (3.0, 4.0, 6.0, 8.0)
    blurs = np.arange(0.5, 4.01, 0.5) if not quick else np.array([1.0, 2.0, 3.0, 4.0])
    rows = []
    for size in sizes:
        img = dicblur.speckle_pattern((n, n), speckle_size=size, softness=0.5, seed=7)
        cent = subset_centres(n, sub, 10)
        # exact interpolation in the brute force: true gradients, SSD on the static side
        pred = blur_sensitivity(
            img,
            subset=sub,
            points=cent,
            boundary="periodic",
            derivative="spectral",
            criterion="ssd",
        ).c
        u_e = bruteforce_ssd_u_e(img, blurs, cent, sub)
        c_pure, c_lead = _fit_c(blurs, np.array(u_e))
        rows.append(
            {
                "speckle_size": size,
                "c_static": pred,
                "c_fit": c_pure,
                "c_fit_leading": c_lead,
                "ratio": c_pure / pred,
                "ratio_leading": c_lead / pred,
                "u_e": dict(zip(map(float, blurs), u_e, strict=True)),
            }
        )
    return rows


def part_e(quick: bool) -> list[dict] | None:
    if importlib.util.find_spec("dicblur.dic") is None:
        return None
    from dicblur.blur import motion_blur
    from dicblur.camera import add_gaussian_noise

    correlate = importlib.import_module("dicblur.dic").correlate
    from dicblur.models import compare_models

    out = []
    for size in (4.0,) if quick else (3.0, 6.0):
        img = dicblur.speckle_pattern((192, 192), speckle_size=size, softness=0.5, seed=7)
        w_all, s_all, u_all, n_all = [], [], [], []
        for noise in (1.0, 2.0, 4.0):
            for i, wl in enumerate(np.arange(0.0, 8.01, 1.0)):
                blurred = motion_blur(img, (0.0, float(wl)), substeps=None) if wl else img
                v = []
                for r in range(2):
                    res = correlate(
                        add_gaussian_noise(img, noise, seed=100 * i + r),
                        add_gaussian_noise(blurred, noise, seed=100 * i + r + 50),
                        subset=31,
                        step=12,
                        shape="affine",
                    )
                    v.append(float(np.std(res.u[res.converged])))
                w_all.append(float(wl))
                n_all.append(noise)
                u_all.append(float(np.sqrt(np.mean(np.square(v)))))
                s_all.append(float(dicblur.sssig(blurred, subset=31, step=12).mean()))
        cmp_ = compare_models(w_all, s_all, u_all, noise_sigma=n_all, train_max_blur=5.0)
        out.append({"speckle_size": size, **cmp_.to_dict()})
    return out


PARTS = ("speed", "c", "comparison")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument(
        "--only",
        choices=PARTS,
        action="append",
        help="run only this part (repeatable); the other sections of the JSON file are kept",
    )
    args = ap.parse_args()
    run = set(args.only or PARTS)
    old = json.loads(OUT.read_text()) if OUT.exists() and args.only else {}
    res: dict = {}
    if "speed" in run:
        a = part_a()
        print(f"{'case':62s} {'seconds':>9s}")
        for r in a:
            extra = f"  (x{r['ratio']:.2f})" if "ratio" in r else ""
            print(f"{r['case']:62s} {r['seconds']:9.4f}{extra}")
        res["speed"] = a
    if "c" in run:
        cc = part_c(args.quick)
        print("\nstatic c vs brute-force SSD minima (translation, exact box blur, W <= 4 px)")
        print(
            f"{'speckle px':>10s} {'c static':>10s} {'c fit':>10s} {'ratio':>6s} "
            f"{'c lead':>10s} {'ratio':>6s}"
        )
        for r in cc:
            print(
                f"{r['speckle_size']:10.1f} {r['c_static']:10.3e} {r['c_fit']:10.3e} "
                f"{r['ratio']:6.3f} {r['c_fit_leading']:10.3e} {r['ratio_leading']:6.3f}"
            )
        res["c_vs_bruteforce_ssd"] = cc
    if "comparison" in run:
        e = part_e(args.quick)
        if e is None:
            print("part E (model comparison on DIC data): pending, dicblur.dic absent")
        else:
            print("\nheld-out comparison on DIC data (train W <= 5 px, noise 1, 2 GL)")
            print(
                f"{'speckle px':>10s} {'n test':>6s} {'rms log pl':>10s} "
                f"{'rms log mm':>10s} {'max pl':>7s} {'max mm':>7s} better"
            )
            for r in e:
                print(
                    f"{r['speckle_size']:10.1f} {r['n_test']:6d} "
                    f"{r['rms_log_error']['power_law']:10.3f} "
                    f"{r['rms_log_error']['mismatch']:10.3f} "
                    f"{r['max_rel_error']['power_law']:7.2f} "
                    f"{r['max_rel_error']['mismatch']:7.2f} {r['better']}"
                )
        res["comparison_on_dic"] = e
    OUT.parent.mkdir(parents=True, exist_ok=True)
    out = {**old, **res}
    out["machine"] = {
        "python": platform.python_version(),
        "cpus": os.cpu_count(),
        "load": os.getloadavg(),
    }
    if args.only:
        out["machine"]["parts_run"] = sorted(run)
    OUT.write_text(json.dumps({**out, "provenance": provenance()}, indent=1))
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
