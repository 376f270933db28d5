"""Benchmark of the uncertainty-model stage (issue 6).

Prints a table and writes ``benchmarks/results/models.json``.

Part A (always): speed of the static blur sensitivity, of the fits and of planning.
Part C (always, independent of the DIC code): the same comparison with the SSD minimum of
each subset found by brute force (exact Fourier box blur and shift, ``least_squares`` over
the translation (u, v)), i.e. the quantity the expansion approximates.
Part D (when ``dicblur.dic`` exists): brute-force exposure planning. A model is fitted to a
calibration sweep (fixed Gaussian noise), the optimal exposure is planned for a
Poisson-Gaussian ``dicblur.Camera``, and the exposure is then swept with that camera
(reference and blurred current image captured at the same exposure, DIC run, several
repetitions); the measured optimum (parabola in log t through the lowest points, its
spread from a bootstrap over repetitions) is compared with the planned one.
Part E (when ``dicblur.dic`` exists): held-out comparison of the power law and the
mismatch model on DIC data (W = 0..8 px, noise 1, 2, 4 GL): fit on W <= 5 px and noise
1, 2 GL, predict the rest.
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
        # exact interpolation in the brute force: true gradients, SSD on the static side
        pred = blur_sensitivity(img, subset=sub, points=cent, boundary="periodic",
                                derivative="spectral", criterion="ssd").c
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


def part_d(quick: bool) -> dict | None:
    if importlib.util.find_spec("dicblur.dic") is None:
        return None
    from dicblur.blur import motion_blur
    from dicblur.camera import Camera, add_gaussian_noise

    correlate = importlib.import_module("dicblur.dic").correlate
    from dicblur.models import PoissonGaussianCamera

    img = dicblur.speckle_pattern((192, 192), speckle_size=4.0, softness=0.5, seed=7)
    level = float(img.mean())
    opts = {"subset": 31, "step": 12, "shape": "affine"}
    reps = 2 if quick else 4

    def u_e_of(ref: np.ndarray, cur: np.ndarray) -> float:
        res = correlate(ref, cur, **opts)
        return float(np.std(res.u[res.converged]))

    # calibration sweep at a fixed noise (what a campaign provides)
    sigma_cal = 2.0
    w_cal = np.arange(0.0, 6.01, 0.5)
    u_cal = []
    for i, wl in enumerate(w_cal):
        blurred = motion_blur(img, (0.0, float(wl)), substeps=None) if wl > 0 else img
        v = [u_e_of(add_gaussian_noise(img, sigma_cal, seed=1000 * i + r),
                    add_gaussian_noise(blurred, sigma_cal, seed=1000 * i + r + 500))
             for r in range(reps)]
        u_cal.append(float(np.sqrt(np.mean(np.square(v)))))
    s_cal = [float(dicblur.sssig(motion_blur(img, (0.0, float(wl)), substeps=None),
                                 subset=31, step=12).mean()) for wl in w_cal]
    model = fit_blur_model(w_cal, s_cal, u_cal, noise_sigma=sigma_cal, mean_level=level,
                           subset=31, default="mismatch")
    cam = Camera(read_noise=2.0, gain=0.05, full_well=None, bit_depth=None)
    t0, velocity, scale = 1e-3, 100.0, 0.05
    pg = PoissonGaussianCamera.from_camera(cam, nominal_exposure=t0, mean_level=level)
    plan = plan_exposure(model, velocity=velocity, scale=scale, camera=pg)
    # brute force: sweep the exposure with the camera
    factors = np.geomspace(0.25, 4.0, 9 if quick else 13)
    k_px = velocity / scale
    u_rep = np.empty((factors.size, reps))
    for i, f in enumerate(factors):
        t = plan.exposure * f
        c = Camera(read_noise=2.0, gain=0.05, full_well=None, bit_depth=None,
                   exposure_scale=t / t0)
        blurred = motion_blur(img, (0.0, float(k_px * t)), substeps=None)
        for r in range(reps):
            u_rep[i, r] = u_e_of(c.capture(img, seed=77 * i + r),
                                 c.capture(blurred, seed=77 * i + r + 5000))
    rng = np.random.default_rng(0)

    def t_min(u: np.ndarray) -> float:
        lu = np.log(np.sqrt(np.mean(u**2, axis=1)))
        j = int(np.clip(np.argmin(lu), 2, lu.size - 3))
        x = np.log(plan.exposure * factors[j - 2:j + 3])
        a, b, _ = np.polyfit(x, lu[j - 2:j + 3], 2)
        return float(np.exp(-b / (2 * a))) if a > 0 else float(np.exp(x[2]))

    t_bf = t_min(u_rep)
    boots = [t_min(u_rep[:, rng.integers(0, reps, reps)]) for _ in range(200)]
    pred_curve = [float(model.predict([k_px * plan.exposure * f],
                                      float(pg.noise_gl(plan.exposure * f, level))).u_e[0])
                  for f in factors]
    return {"planned_exposure": plan.exposure, "planned_blur": plan.blur,
            "planned_u_e": plan.u_e, "bruteforce_exposure": t_bf,
            "bruteforce_exposure_p16_p84": [float(np.percentile(boots, 16)),
                                            float(np.percentile(boots, 84))],
            "factors": [float(f) for f in factors],
            "measured_u_e": [float(x) for x in np.sqrt(np.mean(u_rep**2, axis=1))],
            "predicted_u_e": pred_curve, "model_default": model.default,
            "model_c": model.c, "model_a": model.mismatch["a"] if model.mismatch else None}


def part_e(quick: bool) -> list[dict] | None:
    if importlib.util.find_spec("dicblur.dic") is None:
        return None
    from dicblur.blur import motion_blur
    from dicblur.camera import add_gaussian_noise

    correlate = importlib.import_module("dicblur.dic").correlate
    from dicblur.models import compare_models

    out = []
    for size in ((4.0,) if quick else (3.0, 6.0)):
        img = dicblur.speckle_pattern((192, 192), speckle_size=size, softness=0.5, seed=7)
        w_all, s_all, u_all, n_all = [], [], [], []
        for noise in (1.0, 2.0, 4.0):
            for i, wl in enumerate(np.arange(0.0, 8.01, 1.0)):
                blurred = motion_blur(img, (0.0, float(wl)), substeps=None) if wl else img
                v = []
                for r in range(2):
                    res = correlate(add_gaussian_noise(img, noise, seed=100 * i + r),
                                    add_gaussian_noise(blurred, noise, seed=100 * i + r + 50),
                                    subset=31, step=12, shape="affine")
                    v.append(float(np.std(res.u[res.converged])))
                w_all.append(float(wl))
                n_all.append(noise)
                u_all.append(float(np.sqrt(np.mean(np.square(v)))))
                s_all.append(float(dicblur.sssig(blurred, subset=31, step=12).mean()))
        cmp_ = compare_models(w_all, s_all, u_all, noise_sigma=n_all, train_max_blur=5.0)
        out.append({"speckle_size": size, **cmp_.to_dict()})
    return out


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
    d = part_d(args.quick)
    if d is None:
        print("part D (brute-force exposure planning): pending, dicblur.dic absent")
    else:
        print("\nbrute-force exposure planning (affine DIC, Poisson-Gaussian camera)")
        print(f"planned optimum {d['planned_exposure'] * 1e3:.4g} ms (W = "
              f"{d['planned_blur']:.3g} px, u_e {d['planned_u_e']:.4g} px); brute force "
              f"{d['bruteforce_exposure'] * 1e3:.4g} ms (16-84 %: "
              f"{d['bruteforce_exposure_p16_p84'][0] * 1e3:.4g} .. "
              f"{d['bruteforce_exposure_p16_p84'][1] * 1e3:.4g} ms)")
        print(f"{'t / t_plan':>10s} {'measured':>10s} {'predicted':>10s}")
        for f, m, p in zip(d["factors"], d["measured_u_e"], d["predicted_u_e"], strict=True):
            print(f"{f:10.3f} {m:10.4g} {p:10.4g}")
    e = part_e(args.quick)
    if e is None:
        print("part E (model comparison on DIC data): pending, dicblur.dic absent")
    else:
        print("\nheld-out comparison on DIC data (train W <= 5 px, noise 1, 2 GL)")
        print(f"{'speckle px':>10s} {'n test':>6s} {'rms log pl':>10s} {'rms log mm':>10s} "
              f"{'max pl':>7s} {'max mm':>7s} better")
        for r in e:
            print(f"{r['speckle_size']:10.1f} {r['n_test']:6d} "
                  f"{r['rms_log_error']['power_law']:10.3f} "
                  f"{r['rms_log_error']['mismatch']:10.3f} "
                  f"{r['max_rel_error']['power_law']:7.2f} "
                  f"{r['max_rel_error']['mismatch']:7.2f} {r['better']}")
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps({
        "machine": {"python": platform.python_version(), "cpus": os.cpu_count(),
                    "load": os.getloadavg()},
        "speed": a, "c_vs_bruteforce_ssd": cc, "c_vs_dic": b,
        "planning_vs_bruteforce": d, "comparison_on_dic": e}, indent=1))
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
