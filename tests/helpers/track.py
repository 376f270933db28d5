"""The synthetic vibrating target of the track tests, measured again by
``benchmarks/bench_track.py`` and ``benchmarks/bench_track_parallel.py``."""

from __future__ import annotations

import numpy as np

from dicblur import speckle_pattern
from dicblur.track.synthetic import VibratingTarget


def track_pattern(n: int = 112, seed: int = 1) -> np.ndarray:
    """An n x n speckle pattern (4 px speckles, density 0.5, softness 0.5) stretched to
    30..210 GL: no saturation and no zero grey level in any frame."""
    p = speckle_pattern((n, n), speckle_size=4, density=0.5, softness=0.5, seed=seed)
    return 30 + 180 * (p - p.min()) / (p.max() - p.min())


def vibrating_target(
    pattern: np.ndarray,
    *,
    exposure: float,
    amplitude: float,
    static: int,
    seed: int = 0,
    angle: float = 20.0,
) -> VibratingTarget:
    """``pattern`` vibrating ``amplitude`` px at 200 Hz along ``angle`` deg, filmed at 2000
    fps with ``exposure`` s after ``static`` still frames (peak blur W = A 2 pi f T px)."""
    return VibratingTarget(
        pattern,
        fps=2000.0,
        exposure=exposure,
        amplitude=amplitude,
        frequency=200.0,
        angle=angle,
        static=static,
        seed=seed,
    )
