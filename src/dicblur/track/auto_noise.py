"""The noise of a recording without static frames or a given value: estimated from the
converged ZNSSD residuals of frames against the reference
(:func:`dicblur.dic.noise.residual_noise`, the estimator of ``Correlator(noise_sigma=
"auto")``), several frames pooled for a tight interval.

Whatever the reference's subsets cannot represent in a frame (a blur difference from the
reference, a hard edge moved by a fraction of a pixel) adds to a frame's residual
(docs/dic.md, "noise estimated by default"): on a target vibrating from the first frame
(0.4 ms, 2 GL) the frames next to the reference give 13 GL. That term only adds, so
:data:`NOISE_FRAMES` frames spread over the recording (the two next to the reference
among them) are each estimated and the frames whose interval reaches the lowest estimate's
are pooled (the least blur-mismatched ones: a target at rest, near a turning point). On
a recording blurred throughout the estimate, and the noise part of sigma with it, still
errs high: give the static frames or the noise then.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.ndimage import uniform_filter

from ..arrays import BoolArray, Float64Array
from ..dic import Correlator, PointStatus
from ..dic.noise import residual_noise, residual_variance
from ..sequence import Recording
from .noise import NoiseEstimate

#: Frames correlated against the reference for the estimate (spread over the recording).
NOISE_FRAMES = 8

__all__ = ["NOISE_FRAMES", "residual_frame_noise"]


def _subset_norms(reference: Float64Array, corr: Correlator) -> Float64Array:
    """``Df`` of every POI: the norm of its zero-mean reference subset, GL."""
    n = corr.subset
    img = np.asarray(reference, np.float64)
    mean = uniform_filter(img, n, mode="reflect")
    mean2 = uniform_filter(img * img, n, mode="reflect")
    r, c = corr.rows, corr.cols
    return np.sqrt(np.maximum(mean2[r, c] - mean[r, c] ** 2, 0.0) * n * n)


def residual_frame_noise(
    rec: Recording,
    corr: Correlator,
    reference_image: Float64Array,
    *,
    reference: int,
    frames: tuple[int, int],
    count: int = NOISE_FRAMES,
) -> NoiseEstimate | None:
    """Noise std of ``rec`` from the residuals of ``count`` frames of ``frames``
    (half-open; the two nearest ``reference`` and the rest spread evenly), each correlated
    against the reference by ``corr`` (its own FFT-CC start); the converged subsets of the
    frames whose 95 % interval reaches the lowest frame's are pooled.

    Returns
    -------
    NoiseEstimate or None
        ``source`` names the frames and the 95 % interval (``interval``); None when too
        few subsets converge (:data:`dicblur.dic.noise.MIN_SUBSETS`) or every frame
        is the reference repeated bit for bit (skipped: no residual noise).
    """
    others = [k for k in range(*frames) if k != reference]
    if not others:
        return None
    near = sorted(others, key=lambda k: abs(k - reference))[:2]
    spread = np.linspace(0, len(others) - 1, max(count - len(near), 0)).round().astype(int)
    use = sorted(set(near) | {others[i] for i in spread})
    fnorm = _subset_norms(reference_image, corr)
    m = corr.subset * corr.subset - (6 if corr.shape == "affine" else 2) - 2
    per: list[tuple[int, Float64Array, BoolArray, Any]] = []
    for k in use:
        img = rec.frame(k)
        if np.array_equal(img, reference_image):
            continue  # the reference repeated bit for bit: a zero residual, no noise
        res = corr.correlate(img)
        unit = residual_variance(np.asarray(res.zncc, np.float64), fnorm, m)
        ok = np.asarray(res.status) == PointStatus.CONVERGED
        per.append((k, unit, ok, residual_noise(unit, ok)))
    keep = [p for p in per if p[3] is not None]
    if keep:
        # the blur mismatch only adds: pool the frames consistent with the lowest estimate
        low = min(keep, key=lambda p: p[3].sigma)[3]
        keep = [p for p in keep if p[3].low <= low.high]
    else:
        keep = per  # too few subsets per frame to compare them: all pooled
    if not keep:
        return None
    est = residual_noise(np.concatenate([p[1] for p in keep]), np.concatenate([p[2] for p in keep]))
    if est is None or not est.sigma > 0:
        return None
    use = [p[0] for p in keep]
    names = ",".join(str(k) for k in use)
    return NoiseEstimate(
        sigma=est.sigma,
        read_variance=est.sigma**2,
        slope=0.0,
        level_dependent=False,
        source=f"estimated from the residuals of frames {names} against {reference}",
        interval=(est.low, est.high),
        subsets=est.count,
    )
