"""Benchmark: blur-compensated correlation against the plain matcher and the deblur baseline
(issue 18).

Prints tables and writes ``benchmarks/results/compensation.json``.

Patterns: the DIC Challenge 1 Sample 3 reference (512 x 512; skipped when
``/work/shared/data/real/dicchallenge1_sample3`` is absent) and two generated speckle
patterns (256 x 256, speckle 4 px, softness 0.5). Current image: Algorithm 1 (K = 100,
mirror boundary) of the reference moved by ``X`` (length W = 0..10 px along 0 and 30
degrees); the true displacement is the mean position ``X / 2``. Gaussian noise of 2 GL in
both images (independent per repetition). Subset 31, POIs on a grid inside a 16 px margin.

Matchers, per (pattern, shape, angle, W): ``plain`` (sharp reference), ``given``
(``blur="given"`` with the true ``X``), ``deblur`` (Wiener-deblurred current image with the
known kernel and noise level, plain matcher; Lavatelli, Zappa et al., Acta IMEKO),
``estimate`` (``blur="estimate"`` along the true direction, no length given).
``u_e`` is the std over POIs of the displacement along the motion (as the campaigns),
``bias`` the mean error along the motion; ``bound`` is the blurred image's static bound
``sqrt(mean_i 2 sigma^2 / SSSIG_i(W))`` (directional SSSIG of the noise-free blurred image,
paper eq. 2); for affine also the affine Fisher bound (docs/dic.md) of the same image.

Speed (Sample 3, or the first pattern, W = 8 px along x, one thread each): plain IC-GN,
compensated IC-GN with the blurred reference prepared (cached) and with its preparation,
estimation (warm: the previous image's length as the start; cold: a new Correlator).

Run: ``NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/bench_compensation.py [--quick]``
"""

from __future__ import annotations

import argparse
import math
import time
import zlib
from pathlib import Path

import numpy as np
from _harness import Run

import dicblur
from dicblur.blur import motion_blur
from dicblur.dic import Correlator, deblur_wiener
from dicblur.dic.icgn import prepare_subsets
from dicblur.metrics import directional_sssig, image_gradients
from dicblur.models.compensated import predict_compensated

OUT = Path(__file__).resolve().parent / "results" / "compensation.json"
SAMPLE3 = Path("/work/shared/data/real/dicchallenge1_sample3/Sample3_Reference.tif")
SIGMA = 2.0
SUBSET = 31
MARGIN = 16


def _patterns() -> list[tuple[str, np.ndarray]]:
    out = []
    if SAMPLE3.exists():
        out.append(("sample3", dicblur.load_image(SAMPLE3)))
    for seed in (11, 12):
        out.append(
            (
                f"speckle{seed}",
                dicblur.speckle_pattern((256, 256), speckle_size=4.0, softness=0.5, seed=seed),
            )
        )
    return out


def _vector(w: float, angle: float) -> np.ndarray:
    a = math.radians(angle)
    return w * np.array([math.sin(a), math.cos(a)])


def _bounds(blurred: np.ndarray, pts: np.ndarray, angle: float, shape: str) -> tuple[float, float]:
    """Eq. 2 bound and (affine) the Fisher bound along the motion, RMS over the POIs."""
    s = directional_sssig(blurred, pts, subset=SUBSET, angle=angle)
    eq2 = math.sqrt(float(np.mean(2 * SIGMA**2 / s)))
    if shape != "affine":
        return eq2, eq2
    gy, gx = image_gradients(blurred)
    prep = prepare_subsets(blurred, gx, gy, pts[:, 0], pts[:, 1], SUBSET // 2, "affine")
    a = math.radians(angle)
    e = np.array([math.cos(a), math.sin(a)])  # (u, v) weights
    cuv = prep.cov_unit[:, [0, 3]][:, :, [0, 3]]
    var = SIGMA**2 * np.einsum("i,nij,j->n", e, cuv, e)
    return eq2, math.sqrt(float(np.mean(var)))


def accuracy(
    patterns: list[tuple[str, np.ndarray]],
    blurs: list[float],
    angles: list[float],
    shapes: list[str],
    reps: int,
) -> list[dict]:
    rows = []
    for name, ref in patterns:
        n = ref.shape[0]
        roi = (MARGIN, n - MARGIN, MARGIN, n - MARGIN)
        step = 16 if n > 300 else 12
        for shape in shapes:
            kw = {"subset": SUBSET, "step": step, "shape": shape, "roi": roi, "noise_sigma": SIGMA}
            grid = Correlator(ref, **kw)
            grid_pts = np.stack([grid.rows, grid.cols], axis=1)
            for angle in angles:
                a = math.radians(angle)
                t0 = time.perf_counter()
                pred = predict_compensated(
                    ref,
                    blurs,
                    noise_sigma=SIGMA,
                    subset=SUBSET,
                    points=grid_pts,
                    motion=(math.sin(a), math.cos(a)),
                    shape=shape,
                )
                t_pred = time.perf_counter() - t0
                for j, w in enumerate(blurs):
                    x = _vector(w, angle)
                    blurred = motion_blur(ref, x, substeps=100, boundary="reflect")
                    a = math.radians(angle)
                    ca, sa = math.cos(a), math.sin(a)
                    truth = x[1] / 2 * ca + x[0] / 2 * sa
                    rng = np.random.default_rng(zlib.crc32(f"{name}/{shape}/{angle}/{w}".encode()))
                    acc: dict[str, list] = {m: [] for m in ("plain", "given", "deblur", "estimate")}
                    lengths: list[np.ndarray] = []
                    t_method = dict.fromkeys(acc, 0.0)
                    pts = None
                    for _ in range(reps):
                        r_noisy = ref + rng.normal(0, SIGMA, ref.shape)
                        c_noisy = blurred + rng.normal(0, SIGMA, ref.shape)
                        corr = {
                            m: Correlator(
                                r_noisy, **kw, blur="none" if m in ("plain", "deblur") else m
                            )
                            for m in acc
                        }
                        for m, c in corr.items():
                            t0 = time.perf_counter()
                            if m == "plain":
                                res = c.correlate(c_noisy)
                            elif m == "given":
                                res = c.correlate(c_noisy, blur_vector=x)
                            elif m == "deblur":
                                res = c.correlate(deblur_wiener(c_noisy, x, SIGMA))
                            else:
                                res = c.correlate(c_noisy, blur_angle=angle)
                                assert res.blur_length is not None
                                assert res.blur_identified is not None
                                lengths.append(res.blur_length[res.blur_identified])
                            t_method[m] += time.perf_counter() - t0
                            ok = res.converged
                            along = res.u * ca + res.v * sa
                            acc[m].append(
                                (
                                    float(np.std(along[ok], ddof=1)),
                                    float(np.mean(along[ok])) - truth,
                                    float(ok.mean()),
                                )
                            )
                            pts = np.stack([res.rows, res.cols], axis=1)
                    assert pts is not None
                    eq2, fisher = _bounds(blurred, pts, angle, shape)
                    row = {
                        "pattern": name,
                        "shape": shape,
                        "angle": angle,
                        "blur": w,
                        "bound_eq2": eq2,
                        "bound_fisher": fisher,
                        "n_points": len(pts),
                        "u_e_predicted_given": float(pred.u_e[j]),
                        "seconds_prediction": t_pred / len(blurs),
                    }
                    for m, vals in acc.items():
                        arr = np.array(vals)
                        row[f"u_e_{m}"] = float(np.sqrt(np.mean(arr[:, 0] ** 2)))
                        row[f"bias_{m}"] = float(np.mean(arr[:, 1]))
                        row[f"converged_{m}"] = float(np.mean(arr[:, 2]))
                        row[f"seconds_{m}"] = t_method[m] / reps
                    ls = np.concatenate(lengths) if lengths else np.zeros(0)
                    row["blur_length_mean"] = float(np.mean(ls)) if ls.size else None
                    row["blur_length_std"] = float(np.std(ls, ddof=1)) if ls.size > 1 else None
                    row["blur_identified"] = ls.size / (reps * len(pts))
                    rows.append(row)
                    print(
                        f"{name:10s} {shape:11s} {angle:4.0f} {w:5.1f} | bound "
                        f"{eq2:.4f} {fisher:.4f} pred {pred.u_e[j]:.4f} | u_e plain "
                        f"{row['u_e_plain']:.4f} given "
                        f"{row['u_e_given']:.4f} deblur {row['u_e_deblur']:.4f} est "
                        f"{row['u_e_estimate']:.4f} | bias given {row['bias_given']:+.4f}"
                        f" est {row['bias_estimate']:+.4f} | W_est "
                        f"{row['blur_length_mean'] or float('nan'):.3f} +- "
                        f"{row['blur_length_std'] or float('nan'):.3f}",
                        flush=True,
                    )
    return rows


def prediction_check(
    patterns: list[tuple[str, np.ndarray]],
    blurs: list[float],
    angles: list[float],
    shapes: list[str],
    target_se: float = 0.02,
    max_reps: int = 40,
) -> list[dict]:
    """The compensated static prediction against u_e measured to a stated precision.

    The std over POIs of one image pair is itself a random number: on a 256 x 256
    pattern (256 overlapping subsets) it scatters by 7.5-10 % from pair to pair, so the
    two pairs of :func:`accuracy` leave u_e about 6 % uncertain, too coarse for a 10 %
    target (at W = 0, 30 deg, seed 11 they read 0.00126 px where 30 pairs give 0.00149
    and the prediction 0.00152). Here each case gets repetitions until the standard
    error of its u_e is below ``target_se`` (relative; at least 4, at most
    ``max_reps``), with one ``blur="given"`` Correlator per noisy reference for all
    angles and W (its cache holds the blurred references).
    """
    rows = []
    for name, ref in patterns:
        n = ref.shape[0]
        roi = (MARGIN, n - MARGIN, MARGIN, n - MARGIN)
        step = 16 if n > 300 else 12
        for shape in shapes:
            kw = {"subset": SUBSET, "step": step, "shape": shape, "roi": roi}
            grid = Correlator(ref, **kw)
            pts = np.stack([grid.rows, grid.cols], axis=1)
            cases = [(a, w) for a in angles for w in blurs]
            pred = {}
            for angle in angles:
                a = math.radians(angle)
                p = predict_compensated(
                    ref,
                    blurs,
                    noise_sigma=SIGMA,
                    subset=SUBSET,
                    points=pts,
                    motion=(math.sin(a), math.cos(a)),
                    shape=shape,
                )
                for j, w in enumerate(blurs):
                    pred[(angle, w)] = float(p.u_e[j])
            blurred = {
                (a, w): motion_blur(ref, _vector(w, a), substeps=100, boundary="reflect")
                for a, w in cases
            }
            stds: dict[tuple[float, float], list[float]] = {c: [] for c in cases}
            rng = np.random.default_rng(zlib.crc32(f"prediction/{name}/{shape}".encode()))
            for rep in range(max_reps):
                corr = Correlator(ref + rng.normal(0, SIGMA, ref.shape), **kw, blur="given")
                for a, w in cases:
                    cur = blurred[(a, w)] + rng.normal(0, SIGMA, ref.shape)
                    res = corr.correlate(cur, blur_vector=_vector(w, a))
                    ra = math.radians(a)
                    along = res.u * math.cos(ra) + res.v * math.sin(ra)
                    stds[(a, w)].append(float(np.std(along[res.converged], ddof=1)))
                if rep + 1 >= 4 and all(_rel_se(v) <= target_se for v in stds.values()):
                    break
            for a, w in cases:
                v = np.array(stds[(a, w)])
                u = float(np.sqrt(np.mean(v**2)))
                row = {
                    "pattern": name,
                    "shape": shape,
                    "angle": a,
                    "blur": w,
                    "reps": int(v.size),
                    "u_e_given": u,
                    "u_e_given_rel_se": _rel_se(list(v)),
                    "u_e_given_first2": float(np.sqrt(np.mean(v[:2] ** 2))),
                    "u_e_predicted_given": pred[(a, w)],
                }
                row["rel_error"] = row["u_e_predicted_given"] / u - 1
                rows.append(row)
                print(
                    f"prediction {name:10s} {shape:11s} {a:4.0f} {w:5.1f} | reps {v.size:2d} "
                    f"u_e {u:.5f} +- {100 * row['u_e_given_rel_se']:.1f} % (first 2 "
                    f"{row['u_e_given_first2']:.5f}) | predicted {pred[(a, w)]:.5f} "
                    f"{100 * row['rel_error']:+.1f} %",
                    flush=True,
                )
    return rows


def _rel_se(stds: list[float]) -> float:
    """Relative standard error of ``sqrt(mean(s^2))`` over repetitions (delta method)."""
    v = np.asarray(stds) ** 2
    if v.size < 2:
        return math.inf
    return float(np.std(v, ddof=1) / math.sqrt(v.size) / (2 * np.mean(v)))


def speed(ref: np.ndarray, repeat: int) -> list[dict]:
    n = ref.shape[0]
    roi = (MARGIN, n - MARGIN, MARGIN, n - MARGIN)
    x = _vector(8.0, 0.0)
    rng = np.random.default_rng(3)
    cur = motion_blur(ref, x, substeps=100, boundary="reflect") + rng.normal(0, SIGMA, ref.shape)
    r_noisy = ref + rng.normal(0, SIGMA, ref.shape)
    return [_speed_one(shape, r_noisy, cur, x, roi, repeat) for shape in ("translation", "affine")]


def _speed_one(
    shape: str,
    r_noisy: np.ndarray,
    cur: np.ndarray,
    x: np.ndarray,
    roi: tuple[int, int, int, int],
    repeat: int,
) -> dict:
    kw = {"subset": SUBSET, "step": 8, "shape": shape, "roi": roi}
    plain = Correlator(r_noisy, **kw)
    plain.warmup()
    given = Correlator(r_noisy, blur="given", **kw)
    est = Correlator(r_noisy, blur="estimate", **kw)
    given.correlate(cur, blur_vector=x)
    est.correlate(cur, blur_angle=0.0)
    npts = plain.n_points

    def cold_given() -> None:
        Correlator(r_noisy, blur="given", **kw).correlate(cur, blur_vector=x)

    def cold_est() -> None:
        Correlator(r_noisy, blur="estimate", **kw).correlate(cur, blur_angle=0.0)

    # interleaved, best of `repeat` (the machine is shared: the minimum is the least
    # disturbed run); the cold timings exclude the sharp reference's preparation
    fns = {
        "plain": lambda: plain.correlate(cur),
        "given": lambda: given.correlate(cur, blur_vector=x),
        "estimate": lambda: est.correlate(cur, blur_angle=0.0),
        "prep": lambda: Correlator(r_noisy, **kw),
        "given_cold": cold_given,
        "estimate_cold": cold_est,
    }
    best = dict.fromkeys(fns, np.inf)
    for _ in range(repeat):
        for name, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            best[name] = min(best[name], time.perf_counter() - t0)
    t_plain, t_given, t_est = best["plain"], best["given"], best["estimate"]
    t_given_cold = best["given_cold"] - best["prep"]
    t_est_cold = best["estimate_cold"] - best["prep"]
    row = {
        "shape": shape,
        "n_points": npts,
        "plain_poi_s": npts / t_plain,
        "given_poi_s": npts / t_given,
        "given_cold_poi_s": npts / t_given_cold,
        "estimate_poi_s": npts / t_est,
        "estimate_cold_poi_s": npts / t_est_cold,
    }
    row["given_ratio"] = row["given_poi_s"] / row["plain_poi_s"]
    row["estimate_ratio"] = row["estimate_poi_s"] / row["plain_poi_s"]
    print(
        f"speed {shape:11s} {npts} POIs: plain {row['plain_poi_s']:.0f} POI/s, given "
        f"{row['given_poi_s']:.0f} ({row['given_ratio']:.2f}x; cold "
        f"{row['given_cold_poi_s']:.0f}), estimate {row['estimate_poi_s']:.0f} "
        f"({row['estimate_ratio']:.2f}x; cold {row['estimate_cold_poi_s']:.0f})",
        flush=True,
    )
    return row


def summary(rows: list[dict], prediction: list[dict] | None = None) -> dict:
    """The issue's targets, each over every (pattern, shape, angle) case; the prediction
    target from :func:`prediction_check` when given (u_e measured to 2 %)."""

    def ratio(r: dict, m: str) -> float:
        b = r["bound_eq2"] if r["shape"] == "translation" else r["bound_fisher"]
        return r[f"u_e_{m}"] / b

    le8 = [r for r in rows if r["blur"] <= 8]
    at8 = [r for r in rows if r["blur"] == 8]
    at4 = [r for r in rows if r["blur"] == 4]
    return {
        "given_max_ratio_to_bound_w_le_8": max(ratio(r, "given") for r in le8),
        "given_max_abs_bias_w_le_8": max(abs(r["bias_given"]) for r in le8),
        "deblur_over_given_at_8_min": min(r["u_e_deblur"] / r["u_e_given"] for r in at8),
        "plain_over_given_at_8_min": min(r["u_e_plain"] / r["u_e_given"] for r in at8),
        "estimate_length_std_at_4_max": max(r["blur_length_std"] or np.nan for r in at4),
        "estimate_length_bias_at_4_max": max(
            abs((r["blur_length_mean"] or np.nan) - 4) for r in at4
        ),
        "predicted_given_max_rel_error_w_le_8": max(
            abs(r["u_e_predicted_given"] / r["u_e_given"] - 1)
            for r in (le8 if prediction is None else prediction)
        ),
        "estimate_max_ratio_to_bound_w_le_8": max(
            ratio(r, "estimate") for r in le8 if r["blur"] > 0
        ),
        "bound_used": "eq. 2 (translation), affine Fisher bound (affine)",
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument(
        "--speed-only",
        action="store_true",
        help="only the speed table (writes compensation_speed.json)",
    )
    ap.add_argument(
        "--prediction-only",
        action="store_true",
        help="only the static prediction check (writes compensation_prediction.json)",
    )
    args = ap.parse_args()
    run = Run("compensation")  # the start load; provenance when each file is written
    pats = _patterns()
    if args.prediction_only:
        t0 = time.perf_counter()
        pr = prediction_check(
            pats, [0.0, 2.0, 4.0, 6.0, 8.0], [0.0, 30.0], ["translation", "affine"]
        )
        worst = max(abs(r["rel_error"]) for r in pr)
        n_ok = sum(abs(r["rel_error"]) <= 0.10 for r in pr)
        print(f"\nwithin 10 %: {n_ok} of {len(pr)} cases; largest |error| {100 * worst:.1f} %")
        path = OUT.with_name("compensation_prediction.json")
        run.write(
            {
                "seconds": time.perf_counter() - t0,
                "prediction": pr,
                "within_10_percent": n_ok,
                "cases": len(pr),
                "max_abs_rel_error": worst,
            },
            path,
        )
        print(f"wrote {path} ({time.perf_counter() - t0:.0f} s)")
        return
    if args.speed_only:
        sp = speed(pats[0][1], 5)
        path = OUT.with_name("compensation_speed.json")
        run.write(
            {
                "pattern": pats[0][0],
                "speed": sp,
            },
            path,
        )
        print(f"wrote {path}")
        return
    if args.quick:
        pats = pats[:1]
    blurs = [0.0, 4.0, 8.0] if args.quick else [0.0, 2.0, 4.0, 6.0, 8.0, 10.0]
    t0 = time.perf_counter()
    sp = speed(pats[0][1], 3 if args.quick else 5)
    rows = accuracy(
        pats, blurs, [0.0, 30.0], ["translation", "affine"], reps=1 if args.quick else 2
    )
    pr = None
    if not args.quick:  # the prediction target, against u_e measured to 2 %
        pr = prediction_check(
            pats, [0.0, 2.0, 4.0, 6.0, 8.0], [0.0, 30.0], ["translation", "affine"]
        )
    summ = summary(rows, pr)
    print("\ntargets:")
    for k, v in summ.items():
        print(f"  {k}: {v if isinstance(v, str) else round(v, 4)}")
    run.write(
        {
            "quick": args.quick,
            "seconds": time.perf_counter() - t0,
            "speed": sp,
            "accuracy": rows,
            "prediction": pr,
            "summary": summ,
        },
        OUT,
    )
    print(f"wrote {OUT} ({time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
