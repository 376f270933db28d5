"""A/B of IC-GN speed between two source trees, alternated in one run.

Usage::

    git worktree add /tmp/ab <commit>          # the "before" tree
    python benchmarks/ab_translation_speed.py --ab /tmp/ab/src --rounds 6

alternates fresh processes running the "before" tree (``PYTHONPATH=/tmp/ab/src``) and this
tree, prints each round's POI/s, then the median of each side and their ratio, with the
load average (``os.getloadavg``) before and after. One side alone::

    PYTHONPATH=/tmp/ab/src python benchmarks/ab_translation_speed.py before

Case: 512x512 speckle (4 px, softness 1), (u, v) = (0.3, -0.2) px by Fourier shift, noise
2 GL in both images, subset 21, step 10, 2 threads; each process reports the best of 40
calls of ``Correlator.correlate`` in POI/s (``--shape affine`` or ``both`` for the affine
shape function too).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve()
SRC = HERE.parents[1] / "src"


def measure(label: str, shapes: list[str], calls: int = 40) -> None:
    from dicblur import Correlator, speckle_pattern

    img = speckle_pattern((512, 512), speckle_size=4, softness=1.0, seed=2024)
    rng = np.random.default_rng(1)
    ky = np.fft.fftfreq(512)[:, None]
    kx = np.fft.rfftfreq(512)[None, :]
    shifted = np.fft.irfft2(
        np.fft.rfft2(img) * np.exp(-2j * np.pi * (kx * 0.3 - ky * 0.2)), s=img.shape
    )
    ref = img + rng.normal(0, 2, img.shape)
    cur = shifted + rng.normal(0, 2, img.shape)
    for shape in shapes:
        corr = Correlator(ref, subset=21, step=10, shape=shape, workers=2)  # type: ignore[arg-type]
        corr.warmup()
        corr.correlate(cur)
        best = np.inf
        for _ in range(calls):
            t0 = time.perf_counter()
            res = corr.correlate(cur)
            best = min(best, time.perf_counter() - t0)
        print(
            f"{label}: {shape} {len(res.u) / best:,.0f} POI/s, "
            f"mean iterations {float(np.mean(res.iterations)):.2f}",
            flush=True,
        )


def _run(src: Path, label: str, shapes: list[str]) -> dict[str, float]:
    env = dict(os.environ, PYTHONPATH=str(src))
    out = subprocess.run(
        [sys.executable, str(HERE), label, "--shape", ",".join(shapes)],
        env=env,
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    rates = {}
    for line in out.splitlines():
        _, rest = line.split(": ", 1)
        shape, rate = rest.split()[:2]
        rates[shape] = float(rate.replace(",", ""))
    return rates


def ab(before: Path, rounds: int, shapes: list[str]) -> None:
    load0 = os.getloadavg()
    print(f"load average before: {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}")
    res: dict[str, dict[str, list[float]]] = {"before": {}, "after": {}}
    for r in range(rounds):
        for label, src in (("before", before), ("after", SRC)):
            for shape, rate in _run(src, label, shapes).items():
                res[label].setdefault(shape, []).append(rate)
                print(f"round {r + 1} {label:6s} {shape:11s} {rate:12,.0f} POI/s", flush=True)
    load1 = os.getloadavg()
    print(f"load average after: {load1[0]:.2f} {load1[1]:.2f} {load1[2]:.2f}")
    for shape in shapes:
        b = float(np.median(res["before"][shape]))
        a = float(np.median(res["after"][shape]))
        print(
            f"{shape}: before median {b:,.0f} (max {max(res['before'][shape]):,.0f}) | "
            f"after median {a:,.0f} (max {max(res['after'][shape]):,.0f}) POI/s | "
            f"ratio of medians {a / b:.2f}"
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("label", nargs="?", default="run")
    ap.add_argument(
        "--shape", default="translation", help="translation, affine, both, or a comma list"
    )
    ap.add_argument(
        "--ab",
        type=Path,
        default=None,
        help="src directory of the 'before' tree: alternate it with this tree",
    )
    ap.add_argument("--rounds", type=int, default=6)
    args = ap.parse_args()
    shapes = ["translation", "affine"] if args.shape == "both" else args.shape.split(",")
    if args.ab is not None:
        ab(args.ab, args.rounds, shapes)
    else:
        measure(args.label, shapes)


if __name__ == "__main__":
    main()
