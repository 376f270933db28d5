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


def centred_blur(image: np.ndarray, w: float, *, boundary: str = "periodic") -> np.ndarray:
    """``image`` blurred by a centred box of ``w`` px along the columns (the path from
    -w/2 to +w/2, continuous): no sub-pixel offset of the blurred image's centre, so DIC's
    interpolation bias at w/2 stays out of a measured u_e (docs/models.md s. 4)."""
    from dicblur import motion_blur

    return motion_blur(
        image,
        None,
        substeps=None,
        boundary=boundary,  # type: ignore[arg-type]
        trajectory=lambda t: np.stack([0 * t, w * (t - 0.5)], 1),
    )
