"""The noise of an image pair, estimated from its converged ZNSSD residuals.

At the true match of a subset, with independent noise of std sigma in both images, the
ZNSSD residual is ``1 - zncc ~ sigma^2 m / Df^2`` (``m = npx - k - 2``, ``Df`` the norm of
the zero-mean reference subset; docs/dic.md, "Screening for false convergence"), so each
converged subset gives ``(1 - zncc) Df^2 / m``, an estimate of sigma^2 with ``m`` degrees
of freedom. The field's median of it is the pair's noise variance, robust to the few
subsets at a false optimum. It is the *effective* noise of the pair: whatever the
interpolant of the current image cannot represent (a hard edge moved by a fraction of a
pixel, a blur difference) counts as noise, and it does move the displacement as noise
would: on hard-edged images (2 GL of camera noise, 6-9 GL effective) the measured
scatter over the predicted sigma is 0.7-1.0 with the effective value and 2.8-3.4 with the
camera's 2 GL (``benchmarks/bench_screening.py``). A wavelet (MAD) estimate of the
reference alone measures image content as noise on textured images (14x the true value at
0.5 GL on a speckle) and misses the pair's mismatch, so it is not used.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..arrays import BoolArray, Float64Array

__all__ = [
    "MIN_SUBSETS",
    "QUANTISATION_SIGMA",
    "NoiseEstimate",
    "residual_noise",
    "residual_variance",
]

#: The estimate is never below the quantisation noise of an integer image, 1/sqrt(12) GL
#: (a noise-free float pair would otherwise make interpolation residuals its noise).
QUANTISATION_SIGMA = 1.0 / math.sqrt(12.0)
#: Fewest converged subsets an estimate needs (with fewer the noise stays unknown: the
#: median of a handful is as much the subsets' content as the noise).
MIN_SUBSETS = 50
#: Two-sided confidence of the estimate's interval.
CONFIDENCE_Z = 1.959963984540054  # 95 %


@dataclass(frozen=True)
class NoiseEstimate:
    """The noise std a correlation used, GL.

    Attributes
    ----------
    sigma : float
        Noise std per image, GL (given, or the estimate).
    low, high : float
        95 % confidence interval of the estimate (the order statistics around the
        median of the subsets' residual variances), GL; ``sigma`` itself when given.
    estimated : bool
        True when estimated from the pair's residuals, False when given.
    count : int
        Number of converged subsets the estimate used (0 when given).
    """

    sigma: float
    low: float
    high: float
    estimated: bool
    count: int

    @classmethod
    def given(cls, sigma: float) -> NoiseEstimate:
        """The caller's noise std (no interval)."""
        return cls(float(sigma), float(sigma), float(sigma), False, 0)

    def describe(self) -> str:
        """One line for a summary, e.g. ``2.03 GL (estimated, 95 % 1.98-2.08 GL, 2301
        subsets)`` or ``2 GL (given)``."""
        if not self.estimated:
            return f"{self.sigma:.4g} GL (given)"
        return (
            f"{self.sigma:.3g} GL (estimated from the pair's residuals, 95 % "
            f"{self.low:.3g}-{self.high:.3g} GL, {self.count} subsets)"
        )


def residual_variance(zncc: Float64Array, fnorm: Float64Array, m: int) -> Float64Array:
    """Each subset's noise variance from its residual, ``(1 - zncc) Df^2 / m``, GL^2.

    Parameters
    ----------
    zncc : ndarray, shape (n,)
        ZNCC of each subset at its result.
    fnorm : ndarray, shape (n,)
        ``Df``, the norm of the zero-mean reference subset, GL.
    m : int
        Degrees of freedom of the residual, ``npx - k - 2``.
    """
    return np.maximum(1.0 - zncc, 0.0) * fnorm**2 / m


def residual_noise(unit: Float64Array, ok: BoolArray) -> NoiseEstimate | None:
    """The pair's noise std from the residual variances ``unit`` of the ``ok`` subsets.

    Parameters
    ----------
    unit : ndarray, shape (n,)
        :func:`residual_variance` of each subset, GL^2.
    ok : ndarray of bool, shape (n,)
        The converged subsets.

    Returns
    -------
    NoiseEstimate or None
        sqrt of the median, with the 95 % interval of the median from its order
        statistics (ranks ``n/2 -+ 1.96 sqrt(n)/2``), each at least
        :data:`QUANTISATION_SIGMA`; None with fewer than :data:`MIN_SUBSETS` converged
        subsets.
    """
    vals = unit[ok]
    vals = vals[np.isfinite(vals)]
    n = int(vals.size)
    if n < MIN_SUBSETS:
        return None
    half = CONFIDENCE_Z * math.sqrt(n) / 2.0
    lo = max(0, math.floor(n / 2.0 - half))
    hi = min(n - 1, math.ceil(n / 2.0 + half))
    mid = (n - 1) // 2
    ranks = sorted({lo, mid, n // 2, hi})
    part = np.partition(vals, ranks)
    median = 0.5 * (float(part[mid]) + float(part[n // 2]))
    q = QUANTISATION_SIGMA
    return NoiseEstimate(
        max(q, math.sqrt(median)),
        max(q, math.sqrt(float(part[lo]))),
        max(q, math.sqrt(float(part[hi]))),
        True,
        n,
    )
