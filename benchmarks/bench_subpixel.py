"""Benchmark: the static prediction with the target at a sub-pixel position (issue 6).

Prints tables and writes ``benchmarks/results/subpixel.json``.

The matcher sees a moving target through its B-spline interpolant at the target's
sub-pixel offset: an interpolation bias (the mismatch model's floor ``u_0`` and its cross
term ``b W``) and a filtered current-image noise. ``blur_mismatch_curve(subpixel=...)`` and
``predict_from_pattern(subpixel=...)`` compute both from the static image. Checked here
against affine IC-GN (subset 31, step 12) on 192x192 generated patterns (speckle 4 px,
softness 0.5), the current image blurred by a centred box and moved by the offset with an
exact Fourier shift:

- noise-free: variance over POIs of the IC-GN displacement against the predicted
  ``u_blur**2``, offsets 0.125..0.875, W = 0, 0.5, 1, 1.5, 2 px, 6 patterns;
- noisy (Gaussian 2 GL in both images, 8 repetitions, 4 patterns): u_e against
  ``predict_from_pattern(subpixel=offset)`` at W = 0 and 1 px, and against
  ``subpixel="average"`` with a random offset per capture at W = 0..3 px.

Run: ``.venv/bin/python benchmarks/bench_subpixel.py [--quick]``
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from _harness import Run

import dicblur
from dicblur.models import blur_mismatch_curve, predict_from_pattern

OUT = Path(__file__).resolve().parent / "results" / "subpixel.json"
N = 192
OPTS = {"subset": 31, "step": 12, "shape": "affine"}


def _pattern(seed: int) -> np.ndarray:
    return dicblur.speckle_pattern((N, N), speckle_size=4.0, softness=0.5, seed=seed)


def _current(img: np.ndarray, w: float, offset: float) -> np.ndarray:
    """Centred box blur of length ``w`` (px, along x), then a move by ``offset`` px."""
    kx = np.fft.fftfreq(N)[None, :]
    spec = np.fft.fft2(img) * np.sinc(w * kx) * np.exp(-2j * np.pi * kx * offset)
    return np.fft.ifft2(spec).real


def noise_free(seeds: range, blurs: list[float], offsets: list[float]) -> list[dict]:
    rows = []
    for w in blurs:
        for d in offsets:
            meas, pred = [], []
            for seed in seeds:
                img = _pattern(seed)
                res = dicblur.correlate(img, _current(img, w, d), **OPTS)
                pts = np.stack([res.rows, res.cols], axis=1)
                cv = blur_mismatch_curve(
                    img, [w], subset=31, points=pts, shape="affine", boundary="periodic", subpixel=d
                )
                ok = res.converged & np.isfinite(cv.shifts[0])
                meas.append(float(np.var(res.u[ok])))
                pred.append(float(np.nanvar(cv.shifts[0][ok])))
            rows.append(
                {
                    "blur": w,
                    "offset": d,
                    "measured_var": float(np.mean(meas)),
                    "predicted_var": float(np.mean(pred)),
                }
            )
    return rows


def noisy(seeds: range, reps: int, sigma: float = 2.0) -> dict:
    fixed = []
    for w in (0.0, 1.0):
        for d in (0.0, 0.25, 0.5):
            m = p = 0.0
            for seed in seeds:
                img = _pattern(seed)
                rng = np.random.default_rng(1000 * seed + int(100 * d) + int(10 * w))
                cur = _current(img, w, d)
                grid = dicblur.correlate(img, cur, **OPTS)  # only for the POI grid
                pts = np.stack([grid.rows, grid.cols], axis=1)
                pr = predict_from_pattern(
                    img,
                    [w],
                    noise_sigma=sigma,
                    subset=31,
                    points=pts,
                    shape="affine",
                    boundary="periodic",
                    subpixel=d,
                )
                p += float(pr.u_e[0]) ** 2
                for _ in range(reps):
                    res = dicblur.correlate(
                        img + rng.normal(0, sigma, img.shape),
                        cur + rng.normal(0, sigma, img.shape),
                        **OPTS,
                    )
                    m += float(np.var(res.u[res.converged])) / reps
            fixed.append(
                {
                    "blur": w,
                    "offset": d,
                    "measured_u_e": float(np.sqrt(m / len(seeds))),
                    "predicted_u_e": float(np.sqrt(p / len(seeds))),
                }
            )
    blurs = [0.0, 0.5, 1.0, 1.5, 2.0, 3.0]
    meas = np.zeros(len(blurs))
    pa = np.zeros(len(blurs))
    pn = np.zeros(len(blurs))
    t_avg = t_none = 0.0
    for seed in seeds:
        img = _pattern(seed)
        rng = np.random.default_rng(seed)
        r0 = dicblur.correlate(img, img, **OPTS)
        pts = np.stack([r0.rows, r0.cols], axis=1)
        kw = dict(noise_sigma=sigma, subset=31, points=pts, shape="affine", boundary="periodic")
        t0 = time.perf_counter()
        pn += predict_from_pattern(img, blurs, **kw).u_e ** 2
        t1 = time.perf_counter()
        pa += predict_from_pattern(img, blurs, subpixel="average", **kw).u_e ** 2
        t_none += t1 - t0
        t_avg += time.perf_counter() - t1
        for i, w in enumerate(blurs):
            for _ in range(reps):
                cur = _current(img, w, float(rng.uniform()))
                res = dicblur.correlate(
                    img + rng.normal(0, sigma, img.shape),
                    cur + rng.normal(0, sigma, img.shape),
                    **OPTS,
                )
                meas[i] += float(np.var(res.u[res.converged])) / reps
    n = len(seeds)
    return {
        "noise": sigma,
        "reps": reps,
        "patterns": n,
        "fixed_offset": fixed,
        "random_offset": {
            "blur": blurs,
            "measured_u_e": np.sqrt(meas / n).tolist(),
            "predicted_average": np.sqrt(pa / n).tolist(),
            "predicted_aligned": np.sqrt(pn / n).tolist(),
        },
        "seconds_per_prediction": {"aligned": t_none / n, "average": t_avg / n},
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    bench = Run("subpixel")
    nf = noise_free(
        range(300, 302 if args.quick else 306),
        [0.0, 0.5, 1.0, 1.5, 2.0],
        [0.125, 0.25, 0.5, 0.75, 0.875],
    )
    print("noise-free IC-GN: predicted / measured variance over POIs (subpixel=offset)")
    offs = sorted({r["offset"] for r in nf})
    print(f"{'W px':>5s} " + " ".join(f"{d:7.3f}" for d in offs))
    for w in sorted({r["blur"] for r in nf}):
        print(
            f"{w:5.2f} "
            + " ".join(
                f"{r['predicted_var'] / r['measured_var']:7.3f}"
                for d in offs
                for r in nf
                if r["blur"] == w and r["offset"] == d
            )
        )
    nz = noisy(range(500, 502 if args.quick else 504), reps=4 if args.quick else 8)
    print(f"\nnoisy IC-GN ({nz['noise']:g} GL, {nz['reps']} reps): predicted / measured u_e")
    for r in nz["fixed_offset"]:
        print(
            f"  W {r['blur']:.1f} px, offset {r['offset']:.2f}: "
            f"{r['predicted_u_e'] / r['measured_u_e']:.3f}"
        )
    ro = nz["random_offset"]
    print("random offset per capture, W = " + ", ".join(f"{w:g}" for w in ro["blur"]))
    print(
        "  subpixel='average': "
        + " ".join(
            f"{a / m:.3f}" for a, m in zip(ro["predicted_average"], ro["measured_u_e"], strict=True)
        )
    )
    print(
        "  aligned (default):  "
        + " ".join(
            f"{a / m:.3f}" for a, m in zip(ro["predicted_aligned"], ro["measured_u_e"], strict=True)
        )
    )
    print(
        f"seconds per prediction (6 W): aligned {nz['seconds_per_prediction']['aligned']:.2f}, "
        f"average {nz['seconds_per_prediction']['average']:.2f}"
    )
    result = {
        "quick": args.quick,
        "noise_free": nf,
        "noisy": nz,
    }
    print(f"wrote {bench.write(result, OUT)}")


if __name__ == "__main__":
    main()
