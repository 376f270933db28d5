"""Synthetic images of the blur tests, measured again by ``benchmarks/bench_blur.py``."""

from __future__ import annotations

import numpy as np


def smooth_fine(n: int, ss: int) -> np.ndarray:
    """A band-limited image of shape (n * ss, n * ss) (GL): two plane waves over the unit
    square, sampled at pixel centres of an ``ss``-times supersampled n x n camera, so that
    the camera image (``ss`` x ``ss`` means) has a known smooth limit."""
    c = (np.arange(n * ss) + 0.5) / ss / n
    y, x = np.meshgrid(c, c, indexing="ij")
    return (
        128
        + 60 * np.sin(2 * np.pi * (3 * x + 2 * y) + 0.3)
        + 40 * np.cos(2 * np.pi * (5 * x - 4 * y))
    )
