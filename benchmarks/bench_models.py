"""Benchmark of the uncertainty-model stage (issue 6).

Prints a table and writes ``benchmarks/results/models.json``.

Part A (always): speed of the static blur sensitivity, of the fits and of planning.
Part C (always, independent of the DIC code): the same comparison with the SSD minimum of
each subset found by brute force (exact Fourier box blur and shift, ``least_squares`` over
the translation (u, v)), i.e. the quantity the expansion approximates.
Part B (when ``dicblur.dic`` and ``dicblur.blur`` exist): the static prediction of ``c``
against ``c`` fitted from DIC on noise-free, exactly box-blurred generated patterns over a
range of speckle sizes, W <= 4 px (acceptance: within 15 %).

Run: ``.venv/bin/python benchmarks/bench_models.py [--quick]``
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

import dicblur
from dicblur.models import (
    PoissonGaussianCamera,
    blur_sensitivity,
    fit_blur_model,
    fit_mismatch,
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


def _fit_c(blurs: np.ndarray, u_e: np.ndarray) -> tuple[float, float]:
    """c of u = c W^2 (least squares) and the leading c of u = c W^2 + c4 W^4."""
    c_pure = float(np.sum(u_e * blurs**2) / np.sum(blurs**4))
    a = np.stack([blurs**2, blurs**4], axis=1)
    c_lead = float(np.linalg.lstsq(a, u_e, rcond=None)[0][0])
    return c_pure, c_lead


def part_c(quick: bool) -> list[dict]:
    from scipy import optimize

    n, sub, h = 128, 31, 15
    sizes = (3.0, 6.0) if quick else (3.0, 4.0, 6.0, 8.0)
    blurs = np.arange(0.5, 4.01, 0.5) if not quick else np.array([1.0, 2.0, 3.0, 4.0])
    rows = []
    for size in sizes:
        img = dicblur.speckle_pattern((n, n), speckle_size=size, softness=0.5, seed=7)
        spec = np.fft.fft2(img)
        ky = np.fft.fftfreq(n)[:, None]
        kx = np.fft.fftfreq(n)[None, :]
        cent = np.array([[r, c] for r in range(h + 1, n - h - 1, 10)
                         for c in range(h + 1, n - h - 1, 10)])
        pred = blur_sensitivity(img, subset=sub, points=cent, boundary="periodic").c
        u_e = []
        for wl in blurs:
            blurred = spec * np.sinc(wl * kx)
            xs = []
            for r, c in cent:
                sl = (slice(r - h, r + h + 1), slice(c - h, c + h + 1))
                ref = img[sl]

                def resid(p, sl=sl, ref=ref, blurred=blurred, kx=kx, ky=ky):
                    shift = np.exp(2j * np.pi * (kx * p[0] + ky * p[1]))
                    return (np.fft.ifft2(blurred * shift).real[sl] - ref).ravel()

                xs.append(optimize.least_squares(resid, [0.0, 0.0], xtol=1e-10).x[0])
            u_e.append(float(np.std(xs)))
        c_pure, c_lead = _fit_c(blurs, np.array(u_e))
        rows.append({"speckle_size": size, "c_static": pred, "c_fit": c_pure,
                     "c_fit_leading": c_lead, "ratio": c_pure / pred,
                     "ratio_leading": c_lead / pred,
                     "u_e": dict(zip(map(float, blurs), u_e, strict=True))})
    return rows


def part_b(quick: bool) -> list[dict] | None:
    if importlib.util.find_spec("dicblur.dic") is None or \
            importlib.util.find_spec("dicblur.blur") is None:
        return None
    # imported by name: the stages may be absent (ruff sorts absent modules differently)
    motion_blur = importlib.import_module("dicblur.blur").motion_blur
    correlate = importlib.import_module("dicblur.dic").correlate

    sizes = (3.0, 6.0) if quick else (3.0, 4.0, 6.0, 8.0)
    blurs = np.arange(0.5, 4.01, 0.5)
    rows = []
    for size in sizes:
        img = dicblur.speckle_pattern((192, 192), speckle_size=size, softness=0.5, seed=7)
        kx = np.fft.fftfreq(img.shape[1])[None, :]
        for shape in ("translation", "affine"):
            ref = correlate(img, img, subset=31, step=12, shape=shape)
            pts = np.stack([ref.rows, ref.cols], axis=1)
            pred = blur_sensitivity(img, subset=31, points=pts, shape=shape,
                                    boundary="periodic").c
            for centred in (True, False):
                u_e, s = [], []
                for wl in blurs:
                    cur = motion_blur(img, (0.0, float(wl)), substeps=None)
                    if centred:  # undo the W/2 translation: no interpolation bias
                        cur = np.fft.ifft2(np.fft.fft2(cur) * np.exp(1j * np.pi * kx * wl)).real
                    res = correlate(img, cur, subset=31, step=12, shape=shape)
                    u_e.append(float(np.std(res.u[res.converged])))
                    s.append(float(dicblur.sssig(cur, subset=31, points=pts).mean()))
                u_arr = np.array(u_e)
                c_pure, _ = _fit_c(blurs, u_arr)
                c_model = fit_mismatch(blurs, np.array(s), u_arr, next_term=True)["c"]
                rows.append({"speckle_size": size, "shape": shape, "centred": centred,
                             "c_static": pred, "c_fit": c_pure, "ratio": c_pure / pred,
                             "c_model": c_model, "ratio_model": c_model / pred,
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
    cc = part_c(args.quick)
    print("\nstatic c vs brute-force SSD minima (translation, exact box blur, W <= 4 px)")
    print(f"{'speckle px':>10s} {'c static':>10s} {'c fit':>10s} {'ratio':>6s} "
          f"{'c lead':>10s} {'ratio':>6s}")
    for r in cc:
        print(f"{r['speckle_size']:10.1f} {r['c_static']:10.3e} {r['c_fit']:10.3e} "
              f"{r['ratio']:6.3f} {r['c_fit_leading']:10.3e} {r['ratio_leading']:6.3f}")
    b = part_b(args.quick)
    if b is None:
        print("part B (static c vs DIC-fitted c): pending, dicblur.dic / dicblur.blur absent")
    else:
        print("\nstatic c vs c fitted from DIC (noise-free, exact box blur, W = 0.5..4 px)")
        print(f"{'speckle px':>10s} {'shape':>12s} {'W/2 shift':>9s} {'c static':>10s} "
              f"{'c W^2 fit':>10s} {'ratio':>6s} {'c model':>10s} {'ratio':>6s}")
        for r in b:
            print(f"{r['speckle_size']:10.1f} {r['shape']:>12s} "
                  f"{'undone' if r['centred'] else 'kept':>9s} {r['c_static']:10.3e} "
                  f"{r['c_fit']:10.3e} {r['ratio']:6.3f} {r['c_model']:10.3e} "
                  f"{r['ratio_model']:6.3f}")
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps({
        "machine": {"python": platform.python_version(), "cpus": os.cpu_count(),
                    "load": os.getloadavg()},
        "speed": a, "c_vs_bruteforce_ssd": cc, "c_vs_dic": b}, indent=1))
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
