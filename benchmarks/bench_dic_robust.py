"""Benchmark of the DIC engine on a hostile image (issue 15): cost of failing subsets and
false convergence, against the clean speckle case of ``bench_dic.py``, in one run.

Images (512x512, subset 21, step 10, 2401 POIs, Gaussian noise 2 GL in both images,
translation (u, v) = (0.3, -0.2) px by Fourier shift of the noise-free image):

- ``clean``: ``speckle_pattern(speckle_size=4, softness=1)`` (the ``bench_dic.py`` case);
- ``blobs``: sparse Gaussian blobs (:func:`blobs`: 0.008 blobs per px^2, std 2..3 px,
  amplitude 50..300 GL on a 10 GL background) clipped to [10, 245]. The clipped plateaus
  are not band-limited, so the Fourier-shifted current image is not a spline-warped
  reference, and the sparse texture leaves some subsets with flat or false optima.
- ``fade``: a speckle (seed 11) whose contrast fades from 1.5x to 0.06x across the columns,
  clipped to [10, 200] GL (:func:`fade`): low-texture subsets and saturation.

Per image and shape: throughput (best of ``--repeats``, wall time with ``--workers``
threads and CPU time of one thread, the two images timed alternately so the load hits
both alike), the fraction of POIs returned ``CONVERGED`` more than 0.1 px from the truth
("wrong unflagged": any other status is a flag), the same beyond ``max(0.1 px, 5 predicted
sigma)`` (gross), the share flagged by the screening (``HIGH_RESIDUAL``, ``OUTLIER``,
``IMPRECISE``) and the counts per status. Screening: ``max_residual=2`` (default),
``median_test=True``, ``max_predicted_sigma`` 0.1/3 px (default; engines after issue 15).
Writes ``benchmarks/results/dic_robust.json`` (through ``_harness.Run``: with provenance);
``--dump FILE.npz`` also writes every POI's params, status, iterations and ZNCC.

Usage::

    .venv/bin/python benchmarks/bench_dic_robust.py [--workers 2] [--repeats 10]

Runs against an older checkout too (``PYTHONPATH=OLD/src``; the screening options are
then dropped), to measure the engine before the change on the same images.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
from _harness import Run, use_tests_dir
from _harness import load_1min as load

import dicblur
from dicblur import Correlator, speckle_pattern

use_tests_dir()
from helpers.dic import blobs, fourier_shift  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
IMAGES = ("clean", "blobs", "fade")
TRUE_U, TRUE_V = 0.3, -0.2


def fade(seed: int = 11) -> np.ndarray:
    """Speckle whose contrast fades linearly from 1.5x to 0.06x across the columns,
    clipped to [10, 200] GL (a second hostile image: low texture and saturation)."""
    img = speckle_pattern((512, 512), speckle_size=4, softness=1.0, seed=seed)
    ramp = np.linspace(1.0, 0.04, 512)[None, :]
    return np.clip(128 + (img - img.mean()) * ramp * 1.5, 10, 200)


def make_pair(name: str, seed: int) -> tuple[np.ndarray, np.ndarray]:
    if name == "blobs":
        img = blobs((512, 512))
    elif name == "fade":
        img = fade()
    else:
        img = speckle_pattern((512, 512), speckle_size=4, softness=1.0, seed=seed)
    rng = np.random.default_rng([seed, 99])
    ref = img + rng.normal(0, 2.0, img.shape)
    cur = fourier_shift(img, TRUE_V, TRUE_U) + rng.normal(0, 2.0, img.shape)
    return ref, cur


def correlator(ref: np.ndarray, shape: str, workers: int, screen: bool) -> Correlator:
    kw = dict(subset=21, step=10, shape=shape, noise_sigma=2.0, workers=workers)
    if screen:
        try:
            return Correlator(ref, **kw, median_test=True)  # type: ignore[arg-type]
        except TypeError:  # an engine from before issue 15
            pass
    return Correlator(ref, **kw)  # type: ignore[arg-type]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=10)
    ap.add_argument("--seed", type=int, default=2024)
    ap.add_argument("--no-screen", action="store_true", help="median_test off")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "dic_robust.json"))
    ap.add_argument(
        "--dump",
        default=None,
        help="also write every POI's params, status and iterations to this .npz "
        "(to compare two engines' results bit for bit)",
    )
    args = ap.parse_args(argv)
    run = Run("dic_robust")
    import numba

    numba.set_num_threads(min(args.workers, numba.config.NUMBA_NUM_THREADS))
    record: dict = {
        "command": "benchmarks/bench_dic_robust.py " + " ".join(argv or sys.argv[1:]),
        "machine": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "workers": args.workers,
        "load_start": load(),
        "dicblur": dicblur.__version__,
        "dicblur_path": str(Path(dicblur.__file__).parent),
    }
    pairs = {name: make_pair(name, args.seed) for name in IMAGES}
    results: dict = {}
    dump: dict[str, np.ndarray] = {}
    for shape in ("translation", "affine"):
        cors = {
            name: (
                correlator(ref, shape, args.workers, not args.no_screen),
                correlator(ref, shape, 1, not args.no_screen),
            )
            for name, (ref, _) in pairs.items()
        }
        wall: dict[str, list[float]] = {n: [] for n in pairs}
        cpu: dict[str, list[float]] = {n: [] for n in pairs}
        res = {}
        for name, (cw, c1) in cors.items():
            res[name] = cw.correlate(pairs[name][1])
            c1.correlate(pairs[name][1])
        for _ in range(args.repeats):
            for name, (cw, c1) in cors.items():
                cur = pairs[name][1]
                t0 = time.perf_counter()
                cw.correlate(cur)
                wall[name].append(time.perf_counter() - t0)
                t0 = time.process_time()
                c1.correlate(cur)
                cpu[name].append(time.process_time() - t0)
        for name, r in res.items():
            n = len(r)
            for field in ("params", "status", "iterations", "zncc"):
                dump[f"{name}_{shape}_{field}"] = np.asarray(getattr(r, field))
            err = np.hypot(r.u - TRUE_U, r.v - TRUE_V)
            ok = r.converged
            wrong = ok & (err > 0.1)
            pred = np.hypot(r.predicted_sigma_u, r.predicted_sigma_v)
            gross = wrong & (err > 5 * pred)
            flagged = np.isin(r.status, [6, 7, 8])  # HIGH_RESIDUAL, OUTLIER, IMPRECISE
            results[f"{name}_{shape}"] = {
                "poi_per_s": n / min(wall[name]),
                "poi_per_cpu_s_1thread": n / min(cpu[name]),
                "wrong_unflagged_fraction": float(wrong.mean()),
                "gross_unflagged_fraction": float(gross.mean()),
                "flagged_fraction": float(flagged.mean()),
                "flagged_but_right_fraction": float((flagged & (err <= 0.1)).mean()),
                "imprecise_fraction": float((r.status == 8).mean()),
                "not_converged_fraction": float((~ok).mean()),
                "mean_iterations": float(r.iterations.mean()),
                "mean_iterations_converged": float(r.iterations[ok].mean()),
                # share of all IC-GN iterations spent on POIs that end not CONVERGED
                "failing_iteration_share": float(
                    r.iterations[~ok].sum() / max(1, r.iterations.sum())
                ),
                "max_iterations_used": int(r.iterations.max()),
                "status_counts": r.status_counts(),
            }
        for key in ("poi_per_s", "poi_per_cpu_s_1thread"):
            results[f"ratio_{shape}_{key}"] = (
                results[f"blobs_{shape}"][key] / results[f"clean_{shape}"][key]
            )
            results[f"ratio_fade_{shape}_{key}"] = (
                results[f"fade_{shape}"][key] / results[f"clean_{shape}"][key]
            )
    record["load_end"] = load()
    record["results"] = results
    print(
        f"512x512, subset 21, step 10, noise 2 GL, (u, v) = ({TRUE_U}, {TRUE_V}) px, "
        f"{args.workers} threads, screening {'off' if args.no_screen else 'on'}; "
        f"load {record['load_start']:.1f} -> {record['load_end']:.1f}"
    )
    print(
        f"{'case':20s} {'POI/s':>9s} {'POI/CPU-s':>10s} {'wrong %':>8s} {'gross %':>8s} "
        f"{'flagged %':>9s} {'flag-ok %':>9s} {'imprec %':>8s} {'not ok %':>8s} "
        f"{'mean it':>8s} {'it ok':>6s} {'fail it %':>9s}"
        "  statuses"
    )
    for shape in ("translation", "affine"):
        for name in IMAGES:
            s = results[f"{name}_{shape}"]
            counts = {k: v for k, v in s["status_counts"].items() if v}
            print(
                f"{name + ' ' + shape:20s} {s['poi_per_s']:9.0f} "
                f"{s['poi_per_cpu_s_1thread']:10.0f} "
                f"{100 * s['wrong_unflagged_fraction']:8.2f} "
                f"{100 * s['gross_unflagged_fraction']:8.2f} "
                f"{100 * s['flagged_fraction']:9.2f} "
                f"{100 * s['flagged_but_right_fraction']:9.2f} "
                f"{100 * s['imprecise_fraction']:8.2f} "
                f"{100 * s['not_converged_fraction']:8.2f} "
                f"{s['mean_iterations']:8.2f} {s['mean_iterations_converged']:6.2f} "
                f"{100 * s['failing_iteration_share']:9.1f}  {counts}"
            )
        print(
            f"  blobs / clean ({shape}): wall {results[f'ratio_{shape}_poi_per_s']:.2f}, "
            f"CPU {results[f'ratio_{shape}_poi_per_cpu_s_1thread']:.2f}; fade / clean: "
            f"CPU {results[f'ratio_fade_{shape}_poi_per_cpu_s_1thread']:.2f}"
        )
    # with the shared provenance block (commit of this script's checkout; dicblur_path says
    # which engine ran, e.g. another checkout first on PYTHONPATH)
    out = run.write(record, args.out)
    print(f"wrote {out}")
    if args.dump:
        np.savez_compressed(args.dump, **dump)
        print(f"wrote {args.dump}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
