"""A/B of IC-GN translation speed between two source trees, alternated in one session.

Usage (run each tree's src via PYTHONPATH, alternating, on the same machine)::

    git worktree add /tmp/ab <commit>
    PYTHONPATH=/tmp/ab/src python benchmarks/ab_translation_speed.py before
    python benchmarks/ab_translation_speed.py after

Case: 512x512 speckle (4 px, softness 1), (u, v) = (0.3, -0.2) px by Fourier shift, noise
2 GL in both images, subset 21, step 10, 2 threads; prints the best of 40 calls in POI/s.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from dicblur import Correlator, speckle_pattern


def main() -> None:
    label = sys.argv[1] if len(sys.argv) > 1 else "run"
    img = speckle_pattern((512, 512), speckle_size=4, softness=1.0, seed=2024)
    rng = np.random.default_rng(1)
    ky = np.fft.fftfreq(512)[:, None]
    kx = np.fft.rfftfreq(512)[None, :]
    shifted = np.fft.irfft2(np.fft.rfft2(img) * np.exp(-2j * np.pi * (kx * 0.3 - ky * 0.2)),
                            s=img.shape)
    ref = img + rng.normal(0, 2, img.shape)
    cur = shifted + rng.normal(0, 2, img.shape)
    corr = Correlator(ref, subset=21, step=10, shape="translation", workers=2)
    corr.warmup()
    corr.correlate(cur)
    best = np.inf
    for _ in range(40):
        t0 = time.perf_counter()
        res = corr.correlate(cur)
        best = min(best, time.perf_counter() - t0)
    print(f"{label}: translation {len(res.u) / best:,.0f} POI/s, "
          f"mean iterations {float(np.mean(res.iterations)):.2f}")


if __name__ == "__main__":
    main()
