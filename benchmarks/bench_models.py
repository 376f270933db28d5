"""Benchmark of the uncertainty-model stage (issue 6).

Prints a table and writes ``benchmarks/results/models.json``.

Part A (always): speed of the static blur sensitivity, of the fits and of planning.
Part C (always, independent of the DIC code): the same comparison with the SSD minimum of
each subset found by brute force (exact Fourier box blur and shift, ``least_squares`` over
the translation (u, v)), i.e. the quantity the expansion approximates.
Part D (``--only planning``; when ``dicblur.dic`` exists): brute-force exposure planning.
Models are fitted to a calibration sweep (Gaussian noise 2 and 8 GL, W = 0..6 px, 8
patterns; variants: one level as before, floor, noise growth, auto), the optimal exposure
is planned for a Poisson-Gaussian ``dicblur.Camera``, and the exposure is then swept with
that camera on 48 fresh patterns (reference and blurred current image captured at the same
exposure, DIC run). The measured optimum (non-negative variance-sum fit, ``_optimum``) and
its spread (bootstrap over patterns, which carries the POI-to-POI and pattern correlation)
are compared with each planned one.
Part E (when ``dicblur.dic`` exists): held-out comparison of the power law and the
mismatch model on DIC data (W = 0..8 px, noise 1, 2, 4 GL): fit on W <= 5 px and noise
1, 2 GL, predict the rest.
The static ``c`` against IC-GN (formerly part B) is ``benchmarks/bench_blur_sensitivity.py``.

Run: ``.venv/bin/python benchmarks/bench_models.py [--quick] [--only planning ...]
[--tied-shift]``
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import json
import math
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


_POWERS = (-2, -1, 0, 1, 2, 4, 6)


def _optimum(t: np.ndarray, u: np.ndarray) -> float:
    """Exposure of the minimum of a measured u_e(t) curve (the brute-force estimator).

    ``u`` (n_t, n_samples): u_e of independent samples (pattern + noise realisation); the
    curve is their mean square. It is fitted, relative residuals, by a non-negative sum of
    ``t**p`` for p in -2, -1 (read and shot noise), 0 (floor), 1, 2 (noise x SSSIG decay),
    4, 6 (blur mismatch and its next term), i.e. variances that add, and minimised on a
    fine grid. Unbiased on the model curves (checked in the run); a parabola or cubic in
    (log t, log u) through the lowest points is biased 3-4 % short because the curve is
    asymmetric (slope -1 on the noise side, +2 on the blur side).
    """
    from scipy import optimize

    m2 = np.mean(u**2, axis=1)
    t_ref = float(np.exp(np.mean(np.log(t))))
    tn = t / t_ref
    a = np.stack([tn**p for p in _POWERS], axis=1) / m2[:, None]
    coef, _ = optimize.nnls(a, np.ones(t.size))
    x = np.geomspace(tn.min(), tn.max(), 4001)
    f = sum(c * x**p for c, p in zip(coef, _POWERS, strict=True))
    return float(x[np.argmin(f)] * t_ref)


def _cubic_optimum(t: np.ndarray, u: np.ndarray, half_window: float = 1.8) -> float:
    """Cross-check: cubic in (log t, log u) within a factor ``half_window`` of the minimum."""
    lu = np.log(np.sqrt(np.mean(u**2, axis=1)))
    lt = np.log(t)
    j = int(np.argmin(lu))
    sel = np.abs(lt - lt[j]) <= np.log(half_window) + 1e-9
    coef = np.polyfit(lt[sel], lu[sel], 3)
    x = np.linspace(lt[sel].min(), lt[sel].max(), 2001)
    return float(np.exp(x[np.argmin(np.polyval(coef, x))]))


def _parabola_optimum(t: np.ndarray, u: np.ndarray) -> float:
    """The previous estimator: parabola in log t through the five lowest points."""
    lu = np.log(np.sqrt(np.mean(u**2, axis=1)))
    j = int(np.clip(np.argmin(lu), 2, lu.size - 3))
    x = np.log(t[j - 2:j + 3])
    a, b, _ = np.polyfit(x, lu[j - 2:j + 3], 2)
    return float(np.exp(-b / (2 * a))) if a > 0 else float(np.exp(x[2]))


def part_d(quick: bool, tied_shift: bool = False) -> dict | None:
    """Brute-force exposure planning (see the module docstring and BENCHMARKS.md)."""
    if importlib.util.find_spec("dicblur.dic") is None:
        return None
    from dicblur.blur import motion_blur
    from dicblur.camera import Camera, add_gaussian_noise

    correlate = importlib.import_module("dicblur.dic").correlate

    opts = {"subset": 31, "step": 12, "shape": "affine"}
    n_cal = 2 if quick else 8            # calibration patterns (seeds 7, 8, ...)
    n_bf = 6 if quick else 48            # fresh brute-force patterns (seeds 100, 101, ...)
    noise_cal = (2.0, 8.0)
    w_cal = np.arange(0.0, 6.01, 0.5)

    def pattern(seed: int) -> np.ndarray:
        return dicblur.speckle_pattern((192, 192), speckle_size=4.0, softness=0.5, seed=seed)

    def u_e_of(ref: np.ndarray, cur: np.ndarray) -> float:
        res = correlate(ref, cur, **opts)
        return float(np.std(res.u[res.converged]))

    # A real target sits at an arbitrary sub-pixel position, but the blur synthesis ties
    # the fractional shift to W (W/2). DIC's interpolation filters the noise of the current
    # image and biases it by amounts that depend on that fraction (noise term a = 1.25 at
    # 0 and 1.07 at 0.5 px measured), so a sweep over W would carry a W-periodic artefact.
    # Every current image therefore gets an extra random sub-pixel shift along the motion
    # (``--tied-shift`` leaves it out, to reproduce the artefact).
    shift_rng = np.random.default_rng(2024)
    kx = np.fft.fftfreq(192)[None, :]

    def blurred_at(im: np.ndarray, wl: float) -> np.ndarray:
        b = motion_blur(im, (0.0, float(wl)), substeps=None) if wl > 0 else im
        if tied_shift:
            return b
        dx = float(shift_rng.uniform(0.0, 1.0))
        return np.fft.ifft2(np.fft.fft2(b) * np.exp(-2j * np.pi * kx * dx)).real

    # calibration: what a campaign provides (Gaussian noise, several patterns of one kind)
    cal = [pattern(7 + p) for p in range(n_cal)]
    level = float(np.mean([im.mean() for im in cal]))
    var = np.empty((len(noise_cal), w_cal.size, n_cal))
    s_cal = np.empty((w_cal.size, n_cal))
    for p, im in enumerate(cal):
        for i, wl in enumerate(w_cal):
            blurred = blurred_at(im, float(wl))
            s_cal[i, p] = float(dicblur.sssig(blurred, subset=31, step=12).mean())
            for k, sg in enumerate(noise_cal):
                sd = 10000 * p + 100 * i + 10 * k
                var[k, i, p] = u_e_of(add_gaussian_noise(im, sg, seed=sd),
                                      add_gaussian_noise(blurred, sg, seed=sd + 1)) ** 2

    cam = Camera(read_noise=2.0, gain=0.05, full_well=None, bit_depth=None)
    t0, velocity, scale = 1e-3, 100.0, 0.05
    k_px = velocity / scale
    pg = PoissonGaussianCamera.from_camera(cam, nominal_exposure=t0, mean_level=level)

    def fit_plan(pats: np.ndarray, levels: tuple[int, ...], floor: bool | str,
                 growth: bool | str, w_max: float):
        keep = w_cal <= w_max
        u = np.sqrt(var[list(levels)][:, :, pats].mean(axis=2))[:, keep].ravel()
        s = np.tile(s_cal[:, pats].mean(axis=1)[keep], len(levels))
        w = np.tile(w_cal[keep], len(levels))
        n = np.repeat([noise_cal[k] for k in levels], int(keep.sum()))
        m = fit_blur_model(w, s, u, noise_sigma=n, mean_level=level, subset=31,
                           default="mismatch", floor=floor, noise_blur=growth,
                           compare=False)
        return m, plan_exposure(m, velocity=velocity, scale=scale, camera=pg)

    all_p = np.arange(n_cal)
    # name: (noise levels, floor, noise growth (1 + e W^4), largest calibration W)
    variants = {"one level (2 GL), as before": ((0,), False, False, 6.0),
                "two levels (2, 8 GL), floor": ((0, 1), True, False, 6.0),
                "two levels, floor + growth": ((0, 1), True, True, 6.0),
                "two levels, auto": ((0, 1), "auto", "auto", 6.0),
                "two levels, floor, W <= 4 px": ((0, 1), True, False, 4.0)}
    rng = np.random.default_rng(0)
    n_boot_cal = 30 if quick else 100
    cal_boot = [rng.integers(0, n_cal, n_cal) for _ in range(n_boot_cal)]
    plans = {}
    for name, (levels, floor, growth, w_max) in variants.items():
        model, plan = fit_plan(all_p, levels, floor, growth, w_max)
        boots = [fit_plan(b, levels, floor, growth, w_max)[1].exposure for b in cal_boot]
        plans[name] = {
            "exposure": plan.exposure, "blur": plan.blur, "u_e": plan.u_e,
            "exposure_p16_p84": [float(np.percentile(boots, 16)),
                                 float(np.percentile(boots, 84))],
            "params": dict(zip(model.mismatch.names, map(float, model.mismatch.values),
                               strict=True)),
            "residual_std": model.mismatch.residual_std, "model": model,
            "log_sd": float(np.std(np.log(boots), ddof=1)), "notes": list(plan.notes)}
    # the sweep is centred on the previous run's plan of the floor model (kept fixed so that
    # the brute-force data do not depend on the variants)
    ref_plan = 0.694e-3

    # brute force: fresh patterns, one capture pair per pattern and exposure
    factors = np.geomspace(0.25, 4.0, 17)
    t_sweep = ref_plan * factors
    u_rep = np.empty((factors.size, n_bf))
    for p in range(n_bf):
        im = pattern(100 + p)
        for i, t in enumerate(t_sweep):
            c = Camera(read_noise=2.0, gain=0.05, full_well=None, bit_depth=None,
                       exposure_scale=t / t0)
            blurred = blurred_at(im, float(k_px * t))
            u_rep[i, p] = u_e_of(c.capture(im, seed=1000 * p + 2 * i),
                                 c.capture(blurred, seed=1000 * p + 2 * i + 1))
    t_bf = _optimum(t_sweep, u_rep)
    t_par = _parabola_optimum(t_sweep, u_rep)
    t_cub = _cubic_optimum(t_sweep, u_rep)
    idx = [rng.integers(0, n_bf, n_bf) for _ in range(1000)]
    boots = np.array([_optimum(t_sweep, u_rep[:, b]) for b in idx])
    boots_par = np.array([_parabola_optimum(t_sweep, u_rep[:, b]) for b in idx])
    bf_log_sd = float(np.std(np.log(boots), ddof=1))
    # honesty check of that sd: two independent halves (patterns and noise)
    h = n_bf // 2
    halves = [_optimum(t_sweep, u_rep[:, :h]), _optimum(t_sweep, u_rep[:, h:])]
    half_sd = [float(np.std(np.log([_optimum(t_sweep, u_rep[:, part][:, b])
                                    for b in (rng.integers(0, h, h) for _ in range(300))]),
                            ddof=1)) for part in (slice(0, h), slice(h, None))]
    measured = np.sqrt(np.mean(u_rep**2, axis=1))
    # relative standard error of the rms over patterns (delta method on the mean square)
    rel_se = np.std(u_rep**2, axis=1, ddof=1) / np.sqrt(n_bf) / np.mean(u_rep**2, axis=1) / 2
    out_plans = {}
    for name, d in plans.items():
        m = d.pop("model")
        d["predicted_u_e"] = [float(m.predict([k_px * t], float(pg.noise_gl(t, level))).u_e[0])
                              for t in t_sweep]
        d["ratio_to_bruteforce"] = d["exposure"] / t_bf
        d["inside_bruteforce_p2_5_p97_5"] = bool(
            np.percentile(boots, 2.5) <= d["exposure"] <= np.percentile(boots, 97.5))
        # difference in units of the combined sd (calibration + brute-force sampling)
        d["z_combined"] = float(np.log(d["exposure"] / t_bf)
                                / math.hypot(d["log_sd"], bf_log_sd))
        # the estimator on the model's own noise-free curve must return the planned optimum
        d["estimator_on_predicted_curve"] = _optimum(
            t_sweep, np.array(d["predicted_u_e"])[:, None])
        out_plans[name] = d
    return {"calibration_patterns": n_cal, "bruteforce_patterns": n_bf,
            "subpixel_shift": "W/2 (tied to W)" if tied_shift else "W/2 + uniform(0, 1) px",
            "noise_levels_cal": list(noise_cal), "mean_level": level,
            "plans": out_plans, "bruteforce_exposure": t_bf,
            "bruteforce_exposure_p16_p84": [float(np.percentile(boots, 16)),
                                            float(np.percentile(boots, 84))],
            "bruteforce_exposure_p2_5_p97_5": [float(np.percentile(boots, 2.5)),
                                               float(np.percentile(boots, 97.5))],
            "bruteforce_log_sd": bf_log_sd, "cubic_exposure": t_cub,
            "halves_exposure": halves, "halves_log_sd": half_sd,
            "parabola_exposure": t_par,
            "parabola_exposure_p16_p84": [float(np.percentile(boots_par, 16)),
                                          float(np.percentile(boots_par, 84))],
            "exposures": [float(t) for t in t_sweep], "factors": [float(f) for f in factors],
            "measured_u_e": [float(x) for x in measured],
            "measured_rel_se": [float(x) for x in rel_se]}


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


def _print_d(d: dict) -> None:
    print("\nbrute-force exposure planning (affine DIC, Poisson-Gaussian camera, "
          f"{d['bruteforce_patterns']} fresh patterns)")
    lo, hi = d["bruteforce_exposure_p16_p84"]
    lo2, hi2 = d["bruteforce_exposure_p2_5_p97_5"]
    print("brute force optimum (non-negative variance-sum fit) "
          f"{d['bruteforce_exposure'] * 1e3:.4g} ms, "
          f"bootstrap over patterns 16-84 %: {lo * 1e3:.4g} .. {hi * 1e3:.4g} ms, "
          f"2.5-97.5 %: {lo2 * 1e3:.4g} .. {hi2 * 1e3:.4g} ms")
    ha, hb = d["halves_exposure"]
    print(f"independent halves: {ha * 1e3:.4g} and {hb * 1e3:.4g} ms (difference "
          f"{abs(math.log(ha / hb)) / math.hypot(*d['halves_log_sd']):.2f} combined sd of the "
          f"halves' bootstraps, {d['halves_log_sd'][0]:.3f} / {d['halves_log_sd'][1]:.3f} "
          "in log t)")
    plo, phi = d["parabola_exposure_p16_p84"]
    print(f"(cross-checks: cubic in log-log within 1.8x {d['cubic_exposure'] * 1e3:.4g} ms; "
          f"old parabola through 5 points {d['parabola_exposure'] * 1e3:.4g} ms, "
          f"16-84 %: {plo * 1e3:.4g} .. {phi * 1e3:.4g} ms)")
    print(f"{'calibration':30s} {'planned ms':>10s} {'cal. 16-84 %':>15s} {'/ brute':>8s} "
          f"{'in 95%':>6s} {'z':>6s} {'est.':>7s}  parameters")
    for name, p in d["plans"].items():
        par = ", ".join(f"{k}={v:.3g}" for k, v in p["params"].items())
        print(f"{name:30s} {p['exposure'] * 1e3:10.4g} "
              f"{p['exposure_p16_p84'][0] * 1e3:7.4g}..{p['exposure_p16_p84'][1] * 1e3:<6.4g} "
              f"{p['ratio_to_bruteforce']:8.3f} {p['inside_bruteforce_p2_5_p97_5']!s:>6s} "
              f"{p['z_combined']:6.2f} {p['estimator_on_predicted_curve'] / p['exposure']:7.4f}"
              f"  {par}")
    names = list(d["plans"])
    print(f"{'t / t_plan':>10s} {'measured':>10s} {'+- rel':>7s} "
          + " ".join(f"{'pred ' + str(i + 1):>10s}" for i in range(len(names))))
    for i, f in enumerate(d["factors"]):
        print(f"{f:10.3f} {d['measured_u_e'][i]:10.4g} {d['measured_rel_se'][i]:7.3f} "
              + " ".join(f"{d['plans'][n]['predicted_u_e'][i]:10.4g}" for n in names))
    print("pred i = " + "; ".join(f"{i + 1}: {n}" for i, n in enumerate(names)))


PARTS = ("speed", "c", "planning", "comparison")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--tied-shift", action="store_true",
                    help="planning: keep the sub-pixel shift tied to W (W/2), no random shift")
    ap.add_argument("--only", choices=PARTS, action="append",
                    help="run only this part (repeatable); the other sections of the JSON "
                         "file are kept")
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
        print(f"{'speckle px':>10s} {'c static':>10s} {'c fit':>10s} {'ratio':>6s} "
              f"{'c lead':>10s} {'ratio':>6s}")
        for r in cc:
            print(f"{r['speckle_size']:10.1f} {r['c_static']:10.3e} {r['c_fit']:10.3e} "
                  f"{r['ratio']:6.3f} {r['c_fit_leading']:10.3e} {r['ratio_leading']:6.3f}")
        res["c_vs_bruteforce_ssd"] = cc
    if "planning" in run:
        d = part_d(args.quick, args.tied_shift)
        if d is None:
            print("part D (brute-force exposure planning): pending, dicblur.dic absent")
        else:
            _print_d(d)
        res["planning_vs_bruteforce" + ("_tied_shift" if args.tied_shift else "")] = d
    if "comparison" in run:
        e = part_e(args.quick)
        if e is None:
            print("part E (model comparison on DIC data): pending, dicblur.dic absent")
        else:
            print("\nheld-out comparison on DIC data (train W <= 5 px, noise 1, 2 GL)")
            print(f"{'speckle px':>10s} {'n test':>6s} {'rms log pl':>10s} "
                  f"{'rms log mm':>10s} {'max pl':>7s} {'max mm':>7s} better")
            for r in e:
                print(f"{r['speckle_size']:10.1f} {r['n_test']:6d} "
                      f"{r['rms_log_error']['power_law']:10.3f} "
                      f"{r['rms_log_error']['mismatch']:10.3f} "
                      f"{r['max_rel_error']['power_law']:7.2f} "
                      f"{r['max_rel_error']['mismatch']:7.2f} {r['better']}")
        res["comparison_on_dic"] = e
    OUT.parent.mkdir(parents=True, exist_ok=True)
    out = {**old, **res}
    out["machine"] = {"python": platform.python_version(), "cpus": os.cpu_count(),
                      "load": os.getloadavg()}
    if args.only:
        out["machine"]["parts_run"] = sorted(run)
    OUT.write_text(json.dumps(out, indent=1))
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
