"""Benchmark of the subset DIC engine (issue 4): random error, bias, speed, peers.

Case: 512x512 ``speckle_pattern(speckle_size=4, softness=1)``, translation
(u, v) = (0.3, -0.2) px by Fourier shift, Gaussian noise sigma = 2 GL in both images, subset
21, step 10. Prints tables and writes ``benchmarks/results/dic.json``.

Usage::

    .venv/bin/python benchmarks/bench_dic.py [--workers 2] [--repeats 15] [--quick]

Speed is the best of ``--repeats`` timed calls of ``Correlator.correlate(current)`` (its
B-spline prefilter, initial guess and IC-GN; compile time measured separately by
``warmup``). OpenCV ``calcOpticalFlowPyrLK`` (optional ``bench`` extra) runs on the same
8-bit-rounded images; pyvale is reported when importable.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
from _harness import load_1min as load
from _harness import provenance, use_tests_dir

import dicblur
from dicblur import Correlator, correlate, estimate_noise, load_image, speckle_pattern

use_tests_dir()
from helpers.dic import fourier_shift  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
REAL = ROOT.parent / "shared" / "data" / "real" / "dicchallenge1_sample3"
TRUE_U, TRUE_V = 0.3, -0.2


def best_time(fn, repeats: int) -> tuple[float, float]:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times), float(np.median(times))


def stats(u, v, ok, pred_u=None, pred_v=None, tu=TRUE_U, tv=TRUE_V) -> dict:
    eu, ev = u[ok] - tu, v[ok] - tv
    out = {
        "converged": float(ok.mean()),
        "bias_u": float(eu.mean()),
        "bias_v": float(ev.mean()),
        "std_u": float(eu.std(ddof=1)),
        "std_v": float(ev.std(ddof=1)),
    }
    if pred_u is not None:
        out["pred_u"] = float(np.mean(pred_u[ok]))
        out["pred_v"] = float(np.mean(pred_v[ok]))
        out["norm_std_u"] = float(np.std(eu / pred_u[ok], ddof=1))
        out["norm_std_v"] = float(np.std(ev / pred_v[ok], ddof=1))
    return out


def run_opencv(ref8, cur8, rows, cols, subset, repeats, pred_u, pred_v) -> dict | None:
    try:
        import cv2
    except ImportError:
        print("OpenCV not importable: install the 'bench' extra (opencv-python-headless)")
        return None
    pts = np.stack([cols, rows], axis=1).astype(np.float32).reshape(-1, 1, 2)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-4)

    def call():
        return cv2.calcOpticalFlowPyrLK(
            ref8, cur8, pts, None, winSize=(subset, subset), maxLevel=0, criteria=crit
        )

    nxt, st, _ = call()
    best, med = best_time(call, repeats)
    d = nxt.reshape(-1, 2) - pts.reshape(-1, 2)
    ok = st.ravel() == 1
    out = stats(d[:, 0], d[:, 1], ok, pred_u, pred_v)
    out.update(
        {
            "poi_per_s": len(rows) / best,
            "poi_per_s_median": len(rows) / med,
            "version": cv2.__version__,
            "notes": "LK, bilinear, 8-bit, maxLevel=0",
        }
    )
    return out


def run_pyvale(
    python: str | None, ref, cur, shape: str, workers: int, repeats: int, noise: float
) -> dict | None:
    """pyvale's C++ DIC (``calculate_2d``), run by its own interpreter ``python`` (it has a
    heavy GUI/VTK dependency stack, so it lives in a separate venv); time includes its
    FFT initialisation and CSV output."""
    if not python:
        try:
            import pyvale  # noqa: F401
        except Exception as exc:
            print(
                f"pyvale not importable ({type(exc).__name__}); pass --pyvale-python "
                "PATH to a venv that has it; skipped"
            )
            return None
        python = sys.executable
    import csv
    import subprocess
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        np.save(Path(tmp) / "ref.npy", ref)
        np.save(Path(tmp) / "cur.npy", cur)
        pv_shape = "RIGID" if shape == "translation" else "AFFINE"
        proc = subprocess.run(
            [
                python,
                str(ROOT / "benchmarks" / "_pyvale_runner.py"),
                tmp,
                pv_shape,
                str(workers),
                str(max(1, repeats // 5)),
            ],
            capture_output=True,
            text=True,
            check=False,
        )
        if proc.returncode != 0:
            print(f"pyvale run failed: {proc.stderr.strip().splitlines()[-1:]}")
            return None
        best = float(proc.stdout.strip().splitlines()[-1])
        with (Path(tmp) / pv_shape / "dic_results_def_img_0000.csv").open() as fh:
            rows = list(csv.DictReader(fh))
    x = np.array([float(r["subset_x"]) for r in rows])
    y = np.array([float(r["subset_y"]) for r in rows])
    u = np.array([float(r["disp_u"]) for r in rows])
    v = np.array([float(r["disp_v"]) for r in rows])
    ok = np.array([r["converged"].strip() == "1" for r in rows])
    pts = np.stack([y, x], axis=1).astype(int)
    pred = Correlator(
        ref,
        points=pts,
        subset=21,
        shape=shape,  # type: ignore[arg-type]
        noise_sigma=noise,
    )
    out = stats(
        u,
        v,
        ok & np.isfinite(pred.predicted_sigma_u),
        pred.predicted_sigma_u,
        pred.predicted_sigma_v,
    )
    out.update(
        {
            "poi_per_s": len(rows) / best,
            "n_poi": len(rows),
            "notes": f"pyvale calculate_2d {pv_shape}, time incl. FFT init and CSV",
        }
    )
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--seed", type=int, default=2024)
    ap.add_argument("--quick", action="store_true", help="skip the bias curves")
    ap.add_argument(
        "--no-render", action="store_true", help="skip the supersample-and-bin rendered case"
    )
    ap.add_argument(
        "--cold-compile",
        action="store_true",
        help="also time the first call with an empty numba cache",
    )
    ap.add_argument(
        "--pyvale-python",
        default=None,
        help="interpreter of a venv with pyvale (it is not a dependency)",
    )
    args = ap.parse_args(argv)
    import numba

    numba.set_num_threads(min(args.workers, numba.config.NUMBA_NUM_THREADS))
    record: dict = {
        "command": "benchmarks/bench_dic.py " + " ".join(argv or sys.argv[1:]),
        "machine": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "workers": args.workers,
        "load_start": load(),
        "dicblur": dicblur.__version__,
    }
    # independent streams: the pattern generator draws its own normals from `seed`
    rng = np.random.default_rng([args.seed, 99])
    ref0 = speckle_pattern((512, 512), speckle_size=4, softness=1.0, seed=args.seed)
    ref = ref0 + rng.normal(0, 2.0, ref0.shape)
    cur = fourier_shift(ref0, TRUE_V, TRUE_U) + rng.normal(0, 2.0, ref0.shape)
    subset, step = 21, 10

    rows_out = []
    results: dict = {}
    if args.cold_compile:
        # first-call compile time with an empty numba cache, in a fresh interpreter
        import subprocess
        import tempfile

        code = (
            "import time, numpy as np; t=time.perf_counter(); import dicblur; "
            "c=dicblur.Correlator(np.random.default_rng(0).normal(128,30,(64,64)), "
            "shape='{s}'); print(c.warmup())"
        )
        for shape in ("translation", "affine"):
            with tempfile.TemporaryDirectory() as tmp:
                env = dict(os.environ, NUMBA_CACHE_DIR=tmp)
                out = subprocess.run(
                    [sys.executable, "-c", code.format(s=shape)],
                    env=env,
                    capture_output=True,
                    text=True,
                    check=True,
                )
            results[f"cold_compile_s_{shape}"] = float(out.stdout.strip().splitlines()[-1])
            print(
                f"cold compile ({shape}, empty numba cache): "
                f"{results[f'cold_compile_s_{shape}']:.1f} s"
            )
    for shape in ("translation", "affine"):
        t0 = time.perf_counter()
        corr = Correlator(
            ref, subset=subset, step=step, shape=shape, noise_sigma=2.0, workers=args.workers
        )
        prep = time.perf_counter() - t0
        compile_s = corr.warmup()
        res = corr.correlate(cur)
        best, med = best_time(lambda c=corr: c.correlate(cur), args.repeats)
        timings = dict(corr.last_timings)
        # load-robust companion: CPU seconds of one thread (process_time), best of repeats
        c1 = Correlator(ref, subset=subset, step=step, shape=shape, noise_sigma=2.0, workers=1)
        c1.correlate(cur)
        cpu = []
        for _ in range(args.repeats):
            t0 = time.process_time()
            c1.correlate(cur)
            cpu.append(time.process_time() - t0)
        t0 = time.perf_counter()
        correlate(
            ref, cur, subset=subset, step=step, shape=shape, noise_sigma=2.0, workers=args.workers
        )
        one_shot = time.perf_counter() - t0
        s = stats(res.u, res.v, res.converged, res.predicted_sigma_u, res.predicted_sigma_v)
        s.update(
            {
                "n_poi": len(res),
                "poi_per_s": len(res) / best,
                "poi_per_s_median": len(res) / med,
                "correlate_s": best,
                "prepare_s": prep,
                "compile_s": compile_s,
                "one_shot_s": one_shot,
                "mean_iterations": float(res.iterations.mean()),
                "poi_per_cpu_s_1thread": len(res) / min(cpu),
                "last_call_timings": timings,
            }
        )
        results[f"dicblur_{shape}"] = s
        rows_out.append((f"dicblur IC-GN {shape}", s))
        if shape == "translation":
            pu, pv = res.predicted_sigma_u, res.predicted_sigma_v
            rows_, cols_ = res.rows, res.cols

    ref8 = np.clip(np.rint(ref), 0, 255).astype(np.uint8)
    cur8 = np.clip(np.rint(cur), 0, 255).astype(np.uint8)
    cv = run_opencv(ref8, cur8, rows_, cols_, subset, args.repeats, pu, pv)
    if cv is not None:
        results["opencv_lk"] = cv
        rows_out.append(("OpenCV LK (8-bit)", cv))
    for shape in ("translation", "affine"):
        pv_res = run_pyvale(args.pyvale_python, ref, cur, shape, args.workers, args.repeats, 2.0)
        if pv_res is None:
            results["pyvale"] = "not importable / skipped"
            break
        results[f"pyvale_{shape}"] = pv_res
        rows_out.append((f"pyvale {shape}", pv_res))
    record["load_after_speed"] = load()

    print(
        f"\nCase: 512x512 speckle (4 px, softness 1), (u, v) = ({TRUE_U}, {TRUE_V}) px by "
        f"Fourier shift, noise 2 GL in both images, subset {subset}, step {step}, "
        f"{args.workers} threads; load {record['load_start']:.2f}"
    )
    hdr = (
        f"{'method':26s} {'POI/s':>10s} {'bias_u':>9s} {'bias_v':>9s} {'std_u':>8s} "
        f"{'std_v':>8s} {'pred':>8s} {'nstd_u':>7s} {'nstd_v':>7s}"
    )
    print(hdr)
    for name, s in rows_out:
        print(
            f"{name:26s} {s['poi_per_s']:10.0f} {s['bias_u']:9.5f} {s['bias_v']:9.5f} "
            f"{s['std_u']:8.5f} {s['std_v']:8.5f} {s.get('pred_u', float('nan')):8.5f} "
            f"{s.get('norm_std_u', float('nan')):7.3f} {s.get('norm_std_v', float('nan')):7.3f}"
        )
    for shape in ("translation", "affine"):
        s = results[f"dicblur_{shape}"]
        print(
            f"{shape}: compile {s['compile_s']:.2f} s, prepare {s['prepare_s'] * 1e3:.1f} ms, "
            f"correlate best {s['correlate_s'] * 1e3:.2f} ms (median POI/s "
            f"{s['poi_per_s_median']:.0f}), one-shot correlate {s['one_shot_s'] * 1e3:.1f} ms, "
            f"iterations {s['mean_iterations']:.2f}, 1 thread "
            f"{s['poi_per_cpu_s_1thread']:.0f} POI per CPU-s, last call "
            + ", ".join(f"{k} {v * 1e3:.2f} ms" for k, v in s["last_call_timings"].items())
        )

    if not args.quick:
        print("\nBias curve (translation shape, u shift s, v = 0, same noise):")
        print(f"{'shift':>6s} {'bias bspline3':>14s} {'bias bspline5':>14s}")
        curve = []
        for sh in np.round(np.arange(0.1, 0.91, 0.1), 2):
            c = fourier_shift(ref0, 0.0, float(sh)) + rng.normal(0, 2.0, ref0.shape)
            row = {"shift": float(sh)}
            for interp in ("bspline3", "bspline5"):
                r = correlate(
                    ref,
                    c,
                    subset=subset,
                    step=step,
                    shape="translation",
                    interpolation=interp,
                    workers=args.workers,
                )
                row[interp] = float(np.mean(r.u[r.converged]) - sh)
            curve.append(row)
            print(f"{sh:6.1f} {row['bspline3']:14.5f} {row['bspline5']:14.5f}")
        results["bias_curve"] = curve
        results["max_abs_bias_bspline3"] = max(abs(r["bspline3"]) for r in curve)
        results["max_abs_bias_bspline5"] = max(abs(r["bspline5"]) for r in curve)

    if not args.no_render:
        # same case rendered without interpolation: a 10x finer pattern moved by whole fine
        # pixels and binned (dicblur.render_blurred with zero motion), noise as above
        from dicblur import render_blurred

        ss = 10
        fine = speckle_pattern(
            (512 * ss, 512 * ss), speckle_size=4 * ss, softness=1.0 * ss, seed=args.seed
        )
        ref_r = render_blurred(fine, (0.0, 0.0), supersample=ss, substeps=1)
        cur_r = render_blurred(
            np.roll(fine, (round(TRUE_V * ss), round(TRUE_U * ss)), axis=(0, 1)),
            (0.0, 0.0),
            supersample=ss,
            substeps=1,
        )
        del fine
        ref_r = ref_r + rng.normal(0, 2.0, ref_r.shape)
        cur_r = cur_r + rng.normal(0, 2.0, cur_r.shape)
        print("\nSupersample-and-bin rendering (10x, whole fine-pixel shift), same noise:")
        rend = {}
        for shape in ("translation", "affine"):
            r = correlate(
                ref_r,
                cur_r,
                subset=subset,
                step=step,
                shape=shape,
                noise_sigma=2.0,
                workers=args.workers,
            )
            st = stats(r.u, r.v, r.converged, r.predicted_sigma_u, r.predicted_sigma_v)
            rend[shape] = st
            print(
                f"{shape:12s} bias {st['bias_u']:.5f} / {st['bias_v']:.5f} px, std "
                f"{st['std_u']:.5f} / {st['std_v']:.5f} px, predicted {st['pred_u']:.5f} px,"
                f" normalised {st['norm_std_u']:.3f} / {st['norm_std_v']:.3f}"
            )
        results["supersample_bin"] = rend

    if (REAL / "Sample3_Reference.tif").exists():
        a = load_image(REAL / "Sample3_Reference.tif")
        b = load_image(REAL / "Sample3-000_X0.00_Y0.00_N2_C0_R0.tif")
        sigma = estimate_noise(a, b)
        print(
            f"\nReal zero-shift pair (DIC Challenge 1 Sample 3, Reference vs -000): "
            f"estimate_noise = {sigma:.3f} GL"
        )
        real = {"noise_sigma": sigma}
        for shape in ("translation", "affine"):
            r = correlate(
                a, b, subset=subset, step=step, shape=shape, noise_sigma=sigma, workers=args.workers
            )
            s = stats(
                r.u, r.v, r.converged, r.predicted_sigma_u, r.predicted_sigma_v, tu=0.0, tv=0.0
            )
            real[shape] = s
            print(
                f"{shape:12s} std_u {s['std_u']:.5f} std_v {s['std_v']:.5f} px, predicted "
                f"{s['pred_u']:.5f} / {s['pred_v']:.5f} px, normalised {s['norm_std_u']:.3f}"
                f" / {s['norm_std_v']:.3f}, bias {s['bias_u']:.5f} / {s['bias_v']:.5f}"
            )
        results["real_sample3_zero_shift"] = real
    else:
        print(f"\n{REAL} not found: real-image noise floor skipped")

    record["load_end"] = load()
    record["results"] = results
    out = ROOT / "benchmarks" / "results" / "dic.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({**record, "provenance": provenance()}, indent=2))
    print(
        f"\nload average: start {record['load_start']:.2f}, after speed runs "
        f"{record['load_after_speed']:.2f}, end {record['load_end']:.2f}; wrote {out}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
