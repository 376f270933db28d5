"""Benchmark: planned optimal exposure against a brute-force simulation (issue 6).

Prints tables and writes ``benchmarks/results/planning.json``.

The question: does ``plan_exposure`` (a model calibrated the way a campaign calibrates it)
return the exposure a brute-force sweep finds best, within the sweep's own uncertainty?

Setup. 192x192 generated patterns (speckle 4 px, softness 0.5), affine IC-GN, subset 31,
step 12; camera ``dicblur.Camera(read_noise=2 GL, gain=0.05 GL/e-)``, nominal exposure
1 ms; 100 mm/s at 0.05 mm/px (2000 px/s). Every pattern gets a random sub-pixel position of
the moving target along the motion (a real target's position is arbitrary; the blur
synthesis alone ties the fractional shift to W/2, and DIC's interpolation bias and noise
filtering depend on it).

Calibration (what a campaign provides): ``--n-cal`` patterns (seeds 7, 8, ...),
W = 0..6 px step 0.5, Gaussian noise 2 and 8 GL in both images, fresh noise at every point,
u_e pooled (rms) over patterns. Model variants are fitted and planned with
``PoissonGaussianCamera.from_camera``; each plan's spread is a bootstrap over the
calibration patterns.

Brute force: ``--n-bf`` fresh patterns (seeds 1000, 1001, ...), 33 exposures from 0.5 to 2
times 0.69 ms (fixed, so the data do not depend on any plan), reference and current image
captured with the camera at the same exposure, DIC run, u_e pooled over patterns. The
camera is simulated as photon accumulation: the counts of a longer exposure are those of the
shorter one plus Poisson counts of the irradiance collected in between (for the current
image, the motion continuing), read noise from one normal field per image. Every exposure
is an exact Poisson-Gaussian capture; across exposures the captures share their photons the
way one continuing exposure does (common random numbers), so a pattern's u_e(t) is smooth
in t.

No-DIC plan: the static prediction ``predict_from_pattern(subpixel="average")`` of the
first ``--n-static`` calibration patterns (default 8) at the two calibration noise levels,
fitted and planned the same way.

Optimum estimator: least-squares fit of the mean square u_e by ``sum_p c_p t**p``,
p = -2..6 (read noise, shot noise, floor, noise x SSSIG decay, blur mismatch and its next
terms), relative residuals, minimised on a fine grid. On smooth model curves and on curves
built from measured noise and mismatch terms it returns the true optimum within 0.1 %
(checked in the run: ``estimator on the plan's own curve``); a cross-check is a local cubic
in log-log within 1.2x of the lowest point. Uncertainty: bootstrap over brute-force patterns
(whole patterns, so POI and exposure correlation is carried), and two independent halves.

Run: ``.venv/bin/python benchmarks/bench_planning.py [--quick] [--n-cal N] [--n-bf N]
[--replicate K] [--workers N] [--out FILE] [--save FILE.npz]``
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from _harness import provenance

OUT = Path(__file__).resolve().parent / "results" / "planning.json"

SIZE = 192
OPTS = {"subset": 31, "step": 12, "shape": "affine"}
READ, GAIN, T0 = 2.0, 0.05, 1e-3  # GL, GL/e-, s (nominal exposure)
VELOCITY, SCALE = 100.0, 0.05  # mm/s, mm/px
K_PX = VELOCITY / SCALE  # px/s
T_REF = 0.69e-3  # centre of the brute-force sweep, s
FACTORS = np.geomspace(0.5, 2.0, 33)
W_CAL = np.arange(0.0, 6.01, 0.5)
NOISE_CAL = (2.0, 8.0)
POWERS = tuple(range(-2, 7))


def _pattern(seed: int) -> np.ndarray:
    import dicblur

    return dicblur.speckle_pattern((SIZE, SIZE), speckle_size=4.0, softness=0.5, seed=seed)


def _moving(im: np.ndarray, offset: float) -> np.ndarray:
    """Irradiance of the moving target: the pattern at sub-pixel position ``offset`` (px)."""
    kx = np.fft.fftfreq(im.shape[1])[None, :]
    out = np.fft.ifft2(np.fft.fft2(im) * np.exp(-2j * np.pi * kx * offset)).real
    return np.maximum(out, 0.0)  # Fourier ringing of hard edges carries no photons


def _blurred(irr: np.ndarray, w: float) -> np.ndarray:
    from dicblur.blur import motion_blur

    return motion_blur(irr, (0.0, float(w)), substeps=None) if w > 0 else irr


def _u_e(ref: np.ndarray, cur: np.ndarray) -> float:
    from dicblur.dic import correlate

    res = correlate(ref, cur, **OPTS)
    return float(np.std(res.u[res.converged]))


def _init_worker() -> None:
    import numba

    numba.set_num_threads(1)  # one process per core


def _calibrate_one(p: int) -> tuple[np.ndarray, np.ndarray, float]:
    """One calibration pattern: u_e**2 (noise level, W), SSSIG (W), mean level.

    ``p`` numbers the pattern (seed ``7 + p``); replicates of the benchmark use ``p`` beyond
    the default range (``--replicate``).
    """
    import dicblur
    from dicblur.camera import add_gaussian_noise

    im = _pattern(7 + p)
    moving = _moving(im, float(np.random.default_rng(50_000 + p).uniform()))
    var = np.empty((len(NOISE_CAL), W_CAL.size))
    s = np.empty(W_CAL.size)
    for i, w in enumerate(W_CAL):
        cur = _blurred(moving, float(w))
        s[i] = float(dicblur.sssig(cur, subset=OPTS["subset"], step=OPTS["step"]).mean())
        for k, sg in enumerate(NOISE_CAL):
            sd = 10_000 * p + 100 * i + 10 * k
            var[k, i] = (
                _u_e(add_gaussian_noise(im, sg, seed=sd), add_gaussian_noise(cur, sg, seed=sd + 1))
                ** 2
            )
    return var, s, float(im.mean())


def _static_one(p: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Static prediction of calibration pattern ``p`` (no DIC run): noise variance per
    GL**2, noise-free variance, SSSIG at W_CAL, target at an arbitrary sub-pixel position."""
    import dicblur
    from dicblur.models.pattern import _terms
    from dicblur.models.subset_algebra import SubsetMatcher

    im = _pattern(7 + p)
    ref = dicblur.correlate(im, im, **OPTS)  # only for the POI grid
    pts = np.stack([ref.rows, ref.cols], axis=1).astype(np.intp)
    mean_var, mis_var, s, _ = _terms(
        im,
        W_CAL,
        pts,
        OPTS["subset"],
        SubsetMatcher((0.0, 1.0), OPTS["shape"], "bspline3", "periodic"),
        1.0,
        "average",
    )
    return mean_var, mis_var, s


def _brute_one(p: int) -> np.ndarray:
    """One brute-force pattern: u_e at every exposure of the sweep (photon accumulation)."""
    im = _pattern(1000 + p)
    rng = np.random.default_rng(70_000 + p)
    moving = _moving(im, float(rng.uniform()))
    z_ref = rng.standard_normal(im.shape)
    z_cur = rng.standard_normal(im.shape)
    n_ref = np.zeros(im.shape)
    n_cur = np.zeros(im.shape)
    prev_ref = np.zeros(im.shape)
    prev_cur = np.zeros(im.shape)
    u = np.empty(FACTORS.size)
    for i, f in enumerate(FACTORS):
        t = T_REF * f
        # expected electrons collected from the start of the exposure to t
        mean_ref = im * (t / T0) / GAIN
        mean_cur = _blurred(moving, K_PX * t) * (t / T0) / GAIN
        n_ref += rng.poisson(np.maximum(mean_ref - prev_ref, 0.0))
        n_cur += rng.poisson(np.maximum(mean_cur - prev_cur, 0.0))
        prev_ref, prev_cur = mean_ref, mean_cur
        u[i] = _u_e(n_ref * GAIN + READ * z_ref, n_cur * GAIN + READ * z_cur)
    return u


def laurent_optimum(t: np.ndarray, m2: np.ndarray) -> float:
    """Exposure minimising a least-squares fit of ``m2`` (mean square u_e) by t**POWERS."""
    t_ref = float(np.exp(np.mean(np.log(t))))
    tn = t / t_ref
    a = np.stack([tn**p for p in POWERS], axis=1) / m2[:, None]
    coef = np.linalg.lstsq(a, np.ones(t.size), rcond=None)[0]
    x = np.geomspace(tn.min(), tn.max(), 8001)
    f = sum(c * x**p for c, p in zip(coef, POWERS, strict=True))
    return float(x[np.argmin(f)] * t_ref)


def laurent_curve(t: np.ndarray, m2: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The fitted mean square of :func:`laurent_optimum` at exposures ``x``."""
    t_ref = float(np.exp(np.mean(np.log(t))))
    a = np.stack([(t / t_ref) ** p for p in POWERS], axis=1) / m2[:, None]
    coef = np.linalg.lstsq(a, np.ones(t.size), rcond=None)[0]
    return sum(c * (x / t_ref) ** p for c, p in zip(coef, POWERS, strict=True))


def cubic_optimum(t: np.ndarray, m2: np.ndarray, half_window: float = 1.2) -> float:
    """Cross-check: cubic in (log t, log u) within a factor ``half_window`` of the lowest."""
    lu = 0.5 * np.log(m2)
    lt = np.log(t)
    j = int(np.argmin(lu))
    sel = np.abs(lt - lt[j]) <= math.log(half_window) + 1e-9
    coef = np.polyfit(lt[sel], lu[sel], 3)
    x = np.linspace(lt[sel].min(), lt[sel].max(), 4001)
    return float(np.exp(x[np.argmin(np.polyval(coef, x))]))


VARIANTS = {  # name: (noise levels used, floor, noise growth (1 + e W^4), cross (b W)^2)
    "one level (2 GL)": ((0,), False, False, False),
    "two levels (2, 8 GL), floor": ((0, 1), True, False, False),
    "two levels, floor + growth": ((0, 1), True, True, False),
    "two levels, floor + cross": ((0, 1), True, False, True),
    "two levels, floor+cross+growth": ((0, 1), True, True, True),
    "two levels, auto (default)": ((0, 1), "auto", "auto", "auto"),
}


def _camera(level: float):
    """The benchmark's camera for planning, at the calibration images' mean level."""
    from dicblur import Camera
    from dicblur.models import PoissonGaussianCamera

    return PoissonGaussianCamera.from_camera(
        Camera(read_noise=READ, gain=GAIN, full_well=None, bit_depth=None),
        nominal_exposure=T0,
        mean_level=level,
    )


def _fit_plan(
    var: np.ndarray,
    s: np.ndarray,
    level: float,
    pats: np.ndarray,
    levels: tuple[int, ...],
    floor: bool | str,
    growth: bool | str,
    cross: bool | str,
):
    from dicblur.models import fit_blur_model, plan_exposure

    u = np.sqrt(var[pats].mean(axis=0)[list(levels)]).ravel()
    ss = np.tile(s[pats].mean(axis=0), len(levels))
    w = np.tile(W_CAL, len(levels))
    n = np.repeat([NOISE_CAL[k] for k in levels], W_CAL.size)
    model = fit_blur_model(
        w,
        ss,
        u,
        noise_sigma=n,
        mean_level=level,
        subset=OPTS["subset"],
        default="mismatch",
        floor=floor,
        noise_blur=growth,
        cross=cross,
        compare=False,
    )
    cam = _camera(level)
    return model, plan_exposure(model, velocity=VELOCITY, scale=SCALE, camera=cam), cam


def run(
    n_cal: int,
    n_bf: int,
    workers: int,
    n_boot: int,
    n_boot_cal: int,
    save: str | None = None,
    replicate: int = 0,
    n_static: int = 8,
) -> dict:
    t_start = time.perf_counter()
    with ProcessPoolExecutor(max_workers=workers, initializer=_init_worker) as ex:
        cal = list(ex.map(_calibrate_one, range(100_000 * replicate, 100_000 * replicate + n_cal)))
        t_cal = time.perf_counter() - t_start
        u_bf = np.array(
            list(ex.map(_brute_one, range(100_000 * replicate, 100_000 * replicate + n_bf)))
        ).T
        t_static = time.perf_counter()
        static = list(
            ex.map(_static_one, range(100_000 * replicate, 100_000 * replicate + n_static))
        )
        t_static = time.perf_counter() - t_static
    t_all = time.perf_counter() - t_start
    var = np.array([c[0] for c in cal])
    s = np.array([c[1] for c in cal])
    level = float(np.mean([c[2] for c in cal]))
    t = T_REF * FACTORS
    if save:
        np.savez(
            save,
            var=var,
            s=s,
            level=level,
            u_bf=u_bf,
            t=t,
            w_cal=W_CAL,
            noise_cal=np.array(NOISE_CAL),
        )
    m2 = np.mean(u_bf**2, axis=1)

    rng = np.random.default_rng(0)
    t_bf = laurent_optimum(t, m2)
    idx = [rng.integers(0, n_bf, n_bf) for _ in range(n_boot)]
    boots = np.array([laurent_optimum(t, np.mean(u_bf[:, b] ** 2, axis=1)) for b in idx])
    bf_log_sd = float(np.std(np.log(boots), ddof=1))
    h = n_bf // 2
    halves = [
        laurent_optimum(t, np.mean(u_bf[:, sl] ** 2, axis=1))
        for sl in (slice(0, h), slice(h, None))
    ]
    half_sd = [
        float(
            np.std(
                np.log(
                    [
                        laurent_optimum(t, np.mean(u_bf[:, part][:, b] ** 2, axis=1))
                        for b in (rng.integers(0, h, h) for _ in range(300))
                    ]
                ),
                ddof=1,
            )
        )
        for part in (slice(0, h), slice(h, None))
    ]
    rel_se = np.std(u_bf**2, axis=1, ddof=1) / math.sqrt(n_bf) / m2 / 2
    x_fine = np.geomspace(t.min(), t.max(), 8001)
    bf_curve = laurent_curve(t, m2, x_fine)

    cal_boot = [rng.integers(0, n_cal, n_cal) for _ in range(n_boot_cal)]
    plans = {}
    for name, opts in VARIANTS.items():
        model, plan, cam = _fit_plan(var, s, level, np.arange(n_cal), *opts)
        bt = np.array([_fit_plan(var, s, level, b, *opts)[1].exposure for b in cal_boot])
        pred = np.array(
            [float(model.predict([K_PX * ti], float(cam.noise_gl(ti, level))).u_e[0]) for ti in t]
        )
        log_sd = float(np.std(np.log(bt), ddof=1))
        # the measured (fitted) brute-force u_e at the planned exposure, above its minimum
        at_plan = float(laurent_curve(t, m2, np.array([plan.exposure]))[0])
        plans[name] = {
            "exposure": plan.exposure,
            "blur": plan.blur,
            "u_e": plan.u_e,
            "exposure_p16_p84": [float(np.percentile(bt, 16)), float(np.percentile(bt, 84))],
            "log_sd": log_sd,
            "params": dict(
                zip(model.mismatch.names, map(float, model.mismatch.values), strict=True)
            ),
            "ratio_to_bruteforce": plan.exposure / t_bf,
            "inside_bruteforce_p2_5_p97_5": bool(
                np.percentile(boots, 2.5) <= plan.exposure <= np.percentile(boots, 97.5)
            ),
            "z_combined": float(math.log(plan.exposure / t_bf) / math.hypot(log_sd, bf_log_sd)),
            "estimator_on_plan_curve": laurent_optimum(t, pred**2) / plan.exposure,
            "measured_u_e_at_plan_over_min": math.sqrt(at_plan / float(bf_curve.min())),
            "predicted_u_e": [float(v) for v in pred],
        }
    # the static prediction (no DIC run, no campaign): pooled over the first calibration
    # patterns, at the two calibration noise levels, fitted like campaign data
    mv = np.mean([r[0] for r in static], axis=0)
    dv = np.mean([r[1] for r in static], axis=0)
    ss = np.mean([r[2] for r in static], axis=0)
    from dicblur.models import fit_blur_model, plan_exposure

    sig = np.repeat(NOISE_CAL, W_CAL.size)
    u_st = np.sqrt(sig**2 * np.tile(mv, 2) + np.tile(dv, 2))
    m_st = fit_blur_model(
        np.tile(W_CAL, 2),
        np.tile(ss, 2),
        u_st,
        noise_sigma=sig,
        mean_level=level,
        subset=OPTS["subset"],
        default="mismatch",
        compare=False,
    )
    cam = _camera(level)
    p_st = plan_exposure(m_st, velocity=VELOCITY, scale=SCALE, camera=cam)
    pred_st = np.array(
        [float(m_st.predict([K_PX * ti], float(cam.noise_gl(ti, level))).u_e[0]) for ti in t]
    )
    static_plan = {
        "patterns": n_static,
        "exposure": p_st.exposure,
        "ratio_to_bruteforce": p_st.exposure / t_bf,
        "inside_bruteforce_p2_5_p97_5": bool(
            np.percentile(boots, 2.5) <= p_st.exposure <= np.percentile(boots, 97.5)
        ),
        "z_bruteforce": float(math.log(p_st.exposure / t_bf) / bf_log_sd),
        "params": dict(zip(m_st.mismatch.names, map(float, m_st.mismatch.values), strict=True)),
        "predicted_u_e": [float(v) for v in pred_st],
        "measured_u_e_at_plan_over_min": math.sqrt(
            float(laurent_curve(t, m2, np.array([p_st.exposure]))[0]) / float(bf_curve.min())
        ),
        "seconds": t_static,
    }
    return {
        "calibration_patterns": n_cal,
        "bruteforce_patterns": n_bf,
        "mean_level": level,
        "static_prediction_plan": static_plan,
        "noise_levels_cal": list(NOISE_CAL),
        "w_cal": [float(w) for w in W_CAL],
        "bruteforce_exposure": t_bf,
        "bruteforce_exposure_p16_p84": [
            float(np.percentile(boots, 16)),
            float(np.percentile(boots, 84)),
        ],
        "bruteforce_exposure_p2_5_p97_5": [
            float(np.percentile(boots, 2.5)),
            float(np.percentile(boots, 97.5)),
        ],
        "bruteforce_log_sd": bf_log_sd,
        "cubic_exposure": cubic_optimum(t, m2),
        "grid_min_exposure": float(t[np.argmin(m2)]),
        "halves_exposure": halves,
        "halves_log_sd": half_sd,
        "exposures": [float(v) for v in t],
        "factors": [float(f) for f in FACTORS],
        "measured_u_e": [float(v) for v in np.sqrt(m2)],
        "measured_rel_se": [float(v) for v in rel_se],
        "plans": plans,
        "seconds": {"calibration": t_cal, "total": t_all},
    }


def _print(d: dict) -> None:
    print(
        f"brute force: {d['bruteforce_patterns']} patterns x {len(d['factors'])} exposures; "
        f"calibration: {d['calibration_patterns']} patterns ({d['seconds']['total']:.0f} s)"
    )
    lo, hi = d["bruteforce_exposure_p16_p84"]
    lo2, hi2 = d["bruteforce_exposure_p2_5_p97_5"]
    print(
        f"brute-force optimum {d['bruteforce_exposure'] * 1e3:.4f} ms; bootstrap 16-84 %: "
        f"{lo * 1e3:.4f}..{hi * 1e3:.4f}, 2.5-97.5 %: {lo2 * 1e3:.4f}..{hi2 * 1e3:.4f} ms "
        f"(log sd {d['bruteforce_log_sd']:.4f})"
    )
    ha, hb = d["halves_exposure"]
    print(
        f"independent halves {ha * 1e3:.4f} / {hb * 1e3:.4f} ms: "
        f"{abs(math.log(ha / hb)) / math.hypot(*d['halves_log_sd']):.2f} combined sd apart; "
        f"cross-check cubic within 1.2x {d['cubic_exposure'] * 1e3:.4f} ms, lowest sampled "
        f"{d['grid_min_exposure'] * 1e3:.4f} ms"
    )
    print(
        f"{'calibration':30s} {'plan ms':>8s} {'cal 16-84 %':>15s} {'/ brute':>8s} "
        f"{'in 95%':>6s} {'z':>6s} {'est.':>7s} {'u at plan':>9s}  parameters"
    )
    for name, p in d["plans"].items():
        par = ", ".join(f"{k}={v:.3g}" for k, v in p["params"].items())
        print(
            f"{name:30s} {p['exposure'] * 1e3:8.4f} "
            f"{p['exposure_p16_p84'][0] * 1e3:7.4f}..{p['exposure_p16_p84'][1] * 1e3:<7.4f} "
            f"{p['ratio_to_bruteforce']:8.4f} {p['inside_bruteforce_p2_5_p97_5']!s:>6s} "
            f"{p['z_combined']:6.2f} {p['estimator_on_plan_curve']:7.4f} "
            f"{p['measured_u_e_at_plan_over_min']:9.5f}  {par}"
        )
    names = list(d["plans"])
    print(
        f"{'t / 0.69ms':>10s} {'measured':>10s} {'+- rel':>7s} "
        + " ".join(f"{'pred ' + str(i + 1):>9s}" for i in range(len(names)))
    )
    for i in range(0, len(d["factors"]), 4):
        print(
            f"{d['factors'][i]:10.3f} {d['measured_u_e'][i]:10.5f} "
            f"{d['measured_rel_se'][i]:7.4f} "
            + " ".join(f"{d['plans'][n]['predicted_u_e'][i]:9.5f}" for n in names)
        )
    print("pred i = " + "; ".join(f"{i + 1}: {n}" for i, n in enumerate(names)))
    st = d["static_prediction_plan"]
    print(
        f"static prediction (no DIC, {st['patterns']} patterns, subpixel='average'): plan "
        f"{st['exposure'] * 1e3:.4f} ms, / brute {st['ratio_to_bruteforce']:.4f}, in 95 % "
        f"{st['inside_bruteforce_p2_5_p97_5']}, z (brute-force sd) {st['z_bruteforce']:.2f}, "
        f"u at plan / min {st['measured_u_e_at_plan_over_min']:.5f}; predicted / measured "
        "u_e along the sweep "
        + " ".join(
            f"{p / m:.3f}"
            for p, m in zip(st["predicted_u_e"][::4], d["measured_u_e"][::4], strict=True)
        )
    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="4 + 8 patterns (smoke run)")
    ap.add_argument("--n-cal", type=int, default=32)
    ap.add_argument("--n-bf", type=int, default=128)
    ap.add_argument(
        "--n-static",
        type=int,
        default=8,
        help="calibration patterns given to the static prediction",
    )
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--save", help="also save the raw u_e arrays to this .npz file")
    ap.add_argument(
        "--replicate",
        type=int,
        default=0,
        help="independent replicate: other patterns and noise (default 0)",
    )
    ap.add_argument("--out", type=Path, default=OUT, help=f"JSON file (default {OUT.name})")
    args = ap.parse_args()
    n_cal, n_bf = (4, 8) if args.quick else (args.n_cal, args.n_bf)
    d = run(
        n_cal,
        n_bf,
        args.workers,
        n_boot=200 if args.quick else 1000,
        n_static=2 if args.quick else args.n_static,
        n_boot_cal=20 if args.quick else 100,
        save=args.save,
        replicate=args.replicate,
    )
    _print(d)
    d["machine"] = {
        "python": platform.python_version(),
        "cpus": os.cpu_count(),
        "load": os.getloadavg(),
        "workers": args.workers,
        "quick": args.quick,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({**d, "provenance": provenance()}, indent=1))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
