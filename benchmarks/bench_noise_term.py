"""Benchmark: the static prediction's noise term against a Monte Carlo of the engine (issue 14).

Prints a table and writes ``benchmarks/results/noise_term.json``.

``predict_from_pattern`` gives the noise term of u_e as two shares: the reference image's
noise (through the reference intensities *and* its spline gradients, whose noise meets the
blur mismatch left at the fixed point: docs/models.md s. 4, the complete noise term) and the
current image's. Checked against the real ``Correlator`` (default settings: FFT-CC initial
guess, tolerance 1e-4 px; translation shape, subset 31) on 256x256 images, the current
image the reference blurred by a centred box along x (``motion_blur`` on the path
-W/2..W/2, so no interpolation bias at W/2), with three separate Monte Carlo runs per
(pattern, noise, W): noise in the reference only, in the current image only, and in both.
The measured noise term is the variance over realisations of each POI's displacement,
averaged over the POIs that converged in every realisation; the prediction is made on the
same POIs. ``ref``, ``cur``: predicted / measured share; ``total``: their sum against the
sum of the two single-image runs; ``both``: the prediction with the second-order
interaction of the two noises against the run with noise in both images. ``old`` is the
earlier formula without the reference-gradient terms.

Patterns: two generated (speckle 4 px, softness 0.5, periodic; speckle 6 px, softness 1.0)
and the DIC Challenge Sample 3 reference (central 256x256 crop, mirror boundary) when
``../shared/data/real`` is present.

Run: ``NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/bench_noise_term.py [--quick]``;
``--predict-only results/noise_term.json`` keeps that run's Monte Carlo and recomputes the
predictions with the current code
(full: 400 realisations per run, W = 0, 2, 4, 6, 8 px, noise 2 and 8 GL; about 15 min on
one loaded core).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from _harness import Run, use_tests_dir

import dicblur
from dicblur.models import predict_from_pattern

use_tests_dir()
from helpers.blur import centred_blur  # noqa: E402
from helpers.models import noise_variance_terms  # noqa: E402

OUT = Path(__file__).resolve().parent / "results" / "noise_term.json"
# /work/shared/data/real next to the checkout (main or a worktree under /work/wt)
REAL = next(
    (
        p / "shared" / "data" / "real"
        for p in Path(__file__).resolve().parents
        if (p / "shared" / "data" / "real").is_dir()
    ),
    Path("shared/data/real"),
)
SUBSET = 31
OPTS = {"subset": SUBSET, "shape": "translation"}


def _patterns() -> list[tuple[str, np.ndarray, str]]:
    out = [
        (
            "speckle 4 px",
            dicblur.speckle_pattern((256, 256), speckle_size=4.0, softness=0.5, seed=3),
            "periodic",
        ),
        (
            "speckle 6 px soft",
            dicblur.speckle_pattern((256, 256), speckle_size=6.0, softness=1.0, seed=5),
            "periodic",
        ),
    ]
    sample3 = REAL / "dicchallenge1_sample3" / "Sample3_Reference.tif"
    if sample3.is_file():
        img = dicblur.load_image(sample3).astype(np.float64)
        r0, c0 = (img.shape[0] - 256) // 2, (img.shape[1] - 256) // 2
        out.append(("Sample 3", img[r0 : r0 + 256, c0 : c0 + 256].copy(), "reflect"))
    else:
        print(f"(Sample 3 skipped: {sample3} absent)")
    return out


def _centred_blur(img: np.ndarray, wl: float, boundary: str) -> np.ndarray:
    if wl == 0:
        return img.copy()
    return centred_blur(img, wl, boundary=boundary)


def _se(v: np.ndarray, reps: int) -> float:
    """Standard error of the POI mean of per-POI variances (Gaussian: var(s^2) = 2 s^4 /
    (R - 1))."""
    return float(np.sqrt(np.sum(v**2) * 2.0 / (reps - 1)) / len(v))


def case(
    name: str,
    img: np.ndarray,
    boundary: str,
    sigma: float,
    w: float,
    reps: int,
    step: int,
    rng: np.random.Generator,
) -> dict:
    cur = _centred_blur(img, w, boundary)
    c0 = dicblur.Correlator(img, step=step, **OPTS)
    pts = np.stack([c0.rows, c0.cols], axis=1)
    base = c0.correlate(cur)
    ok = base.converged.copy()
    runs: dict[str, list[np.ndarray]] = {"reference": [], "current": [], "both": []}
    t0 = time.perf_counter()
    for _ in range(reps):
        res = c0.correlate(cur + rng.normal(0.0, sigma, cur.shape))
        ok &= res.converged
        runs["current"].append(res.u)
        for which in ("reference", "both"):
            c = dicblur.Correlator(img + rng.normal(0.0, sigma, img.shape), points=pts, **OPTS)
            res = c.correlate(
                cur if which == "reference" else cur + rng.normal(0.0, sigma, cur.shape)
            )
            ok &= res.converged
            runs[which].append(res.u)
    seconds = time.perf_counter() - t0
    meas = {k: np.var(np.array(v)[:, ok], axis=0) for k, v in runs.items()}
    row = {
        "pattern": name,
        "noise": sigma,
        "blur": w,
        "reps": reps,
        "n_poi": int(ok.sum()),
        "n_poi_grid": len(pts),
        "points": pts[ok].tolist(),
        "seconds": seconds,
        "mc_reference": float(meas["reference"].mean()),
        "mc_current": float(meas["current"].mean()),
        "mc_both": float(meas["both"].mean()),
        "mc_se": {k: _se(v, reps) for k, v in meas.items()},
    }
    return row | predict(img, boundary, row)


def predict(img: np.ndarray, boundary: str, row: dict) -> dict:
    """The prediction (and the earlier formula) on a Monte Carlo row's POIs."""
    pts = np.asarray(row["points"], dtype=np.intp)
    sigma, w = row["noise"], row["blur"]
    # every POI the Monte Carlo kept (no breakdown test: same POIs on both sides)
    pr = predict_from_pattern(
        img, [w], noise_sigma=sigma, points=pts, boundary=boundary, min_contraction=0.0, **OPTS
    )
    assert pr.u_noise_reference is not None and pr.u_noise_current is not None
    assert pr.u_noise_interaction is not None
    old = noise_variance_terms(img, [w], pts, SUBSET, boundary=boundary)
    return {
        "pred_reference": float(pr.u_noise_reference[0] ** 2),
        "pred_current": float(pr.u_noise_current[0] ** 2),
        "pred_interaction": float(pr.u_noise_interaction[0] ** 2),
        "old_reference": float(sigma**2 * np.nanmean(old[0, 0])),
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument(
        "--predict-only",
        metavar="JSON",
        default=None,
        help="reuse the Monte Carlo of an earlier run, recompute the predictions",
    )
    args = ap.parse_args()
    bench = Run("noise_term")
    prior = None
    if args.predict_only:
        prior = json.loads(Path(args.predict_only).read_text())
        args.quick = prior["quick"]
    reps = 60 if args.quick else 400
    blurs = [0.0, 4.0, 8.0] if args.quick else [0.0, 2.0, 4.0, 6.0, 8.0]
    noises = [2.0] if args.quick else [2.0, 8.0]
    rng = np.random.default_rng(20261201)
    rows = []
    print(
        "noise term, predicted / Monte Carlo of the engine (variances, px^2); "
        f"{reps} realisations per run"
    )
    print(
        f"{'pattern':>18s} {'GL':>3s} {'W':>3s} {'POIs':>4s} {'ref':>6s} {'cur':>6s} "
        f"{'total':>6s} {'both':>6s} {'old ref':>7s} {'old tot':>7s} {'MC se':>6s}"
    )
    for name, img, boundary in _patterns():
        for sigma in noises:
            for w in blurs:
                if prior is None:
                    r = case(name, img, boundary, sigma, w, reps, 32, rng)
                else:
                    old_rows = [
                        q
                        for q in prior["rows"]
                        if q["pattern"] == name and q["noise"] == sigma and q["blur"] == w
                    ]
                    if not old_rows:
                        continue
                    r = old_rows[0]
                    if "points" not in r:  # runs before the POIs were stored: full grid
                        assert r["n_poi"] == r["n_poi_grid"], r
                        c0 = dicblur.Correlator(img, step=32, **OPTS)
                        r["points"] = np.stack([c0.rows, c0.cols], axis=1).tolist()
                    r = r | predict(img, boundary, r)
                rows.append(r)
                pt = r["pred_reference"] + r["pred_current"]
                mt = r["mc_reference"] + r["mc_current"]
                ot = r["old_reference"] + r["pred_current"]
                pb = pt + r["pred_interaction"]
                print(
                    f"{name:>18s} {sigma:3g} {w:3g} {r['n_poi']:4d} "
                    f"{r['pred_reference'] / r['mc_reference']:6.3f} "
                    f"{r['pred_current'] / r['mc_current']:6.3f} {pt / mt:6.3f} "
                    f"{pb / r['mc_both']:6.3f} {r['old_reference'] / r['mc_reference']:7.3f} "
                    f"{ot / mt:7.3f} {r['mc_se']['reference'] / r['mc_reference']:6.3f}",
                    flush=True,
                )
    worst = {
        k: max(abs(f(r) - 1) for r in rows)
        for k, f in (
            ("reference", lambda r: r["pred_reference"] / r["mc_reference"]),
            ("current", lambda r: r["pred_current"] / r["mc_current"]),
            (
                "total",
                lambda r: (
                    (r["pred_reference"] + r["pred_current"])
                    / (r["mc_reference"] + r["mc_current"])
                ),
            ),
            (
                "both",
                lambda r: (
                    (r["pred_reference"] + r["pred_current"] + r["pred_interaction"]) / r["mc_both"]
                ),
            ),
        )
    }
    print(
        "largest |predicted / measured - 1|: " + ", ".join(f"{k} {v:.3f}" for k, v in worst.items())
    )
    result = {
        "quick": args.quick,
        "worst": worst,
        "rows": rows,
    }
    print(f"wrote {bench.write(result, OUT)}")


if __name__ == "__main__":
    main()
