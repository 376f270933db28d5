"""The image noise of a recording for the per-point sigma of :mod:`dicblur.track`: its std
per grey level from the static frames (:func:`estimate_static_noise`,
:class:`NoiseEstimate`) and the subsets' grey levels (:func:`subset_levels`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..arrays import Float64Array, IndexArray
from ..errors import InputError
from ..metrics import estimate_noise


@dataclass(frozen=True)
class NoiseEstimate:
    """Image noise of a recording (GL), from its static frames or given.

    ``variance(level) = read_variance + slope * level`` (Poisson-Gaussian: the slope is
    the gain in GL per electron); ``slope = 0`` when the noise does not measurably depend
    on the level (or was given as one number).

    Attributes
    ----------
    sigma : float
        Noise std (GL) over the image (pairwise differences, as ``dicblur noise``).
    read_variance, slope : float
        The level model (GL**2 and GL).
    level_dependent : bool
    source : str
        ``"static frames a:b"``, ``"given"`` or ``"estimated from the residuals of
        frames ..."`` (:mod:`.auto_noise`).
    pairs : int
        Frame pairs used.
    interval : (float, float), optional
        95 % interval of ``sigma`` (GL) when estimated from residuals.
    subsets : int
        Converged subsets the residual estimate pooled (0 otherwise).
    """

    sigma: float
    read_variance: float
    slope: float
    level_dependent: bool
    source: str
    pairs: int = 0
    interval: tuple[float, float] | None = None
    subsets: int = 0

    def variance(self, level: Float64Array) -> Float64Array:
        """Noise variance (GL**2) at grey levels ``level``."""
        lv = np.asarray(level, dtype=np.float64)
        if not self.level_dependent:
            return np.full(lv.shape, self.sigma**2)
        return np.maximum(self.read_variance + self.slope * lv, 1e-12)

    def to_dict(self) -> dict[str, Any]:
        return {
            "sigma": self.sigma,
            "read_variance": self.read_variance,
            "slope": self.slope,
            "level_dependent": self.level_dependent,
            "source": self.source,
            "pairs": self.pairs,
            "estimated": int(self.interval is not None),
            **(
                {}
                if self.interval is None
                else {
                    "sigma_low": self.interval[0],
                    "sigma_high": self.interval[1],
                    "subsets": self.subsets,
                }
            ),
        }

    def describe(self) -> str:
        """One line for a summary: ``2.03 GL (estimated ..., 95 % 1.98-2.08 GL)``."""
        if self.interval is None:
            return f"{self.sigma:.4g} GL ({self.source})"
        lo, hi = self.interval
        return f"{self.sigma:.3g} GL ({self.source}, 95 % {lo:.3g}-{hi:.3g} GL)"


def estimate_static_noise(frames: Any, start: int, stop: int, *, bins: int = 24) -> NoiseEstimate:
    """Noise of a recording from its static frames ``start .. stop - 1``.

    Consecutive pairs give ``sigma**2 = var(a - b) / 2`` (a global offset, flicker,
    removed first: :func:`dicblur.estimate_noise`); the same differences binned by the
    pair's mean level give the level model ``var = read + slope * level`` (weighted least
    squares over the bins), kept when it explains the data better than one variance
    (slope > 0 and the variance changes by > 20 % over the levels present).

    A frame identical bit for bit to the one before it (a camera or a copy repeating a
    frame) carries no noise: such pairs are skipped (their zero difference would pull the
    estimate down; ``source`` counts them), and a static range of one frame repeated is
    refused.

    Parameters
    ----------
    frames : Recording or sequence of arrays
        Indexable by frame number.
    start, stop : int
        Static frames, half-open (at least 2).

    Raises
    ------
    InputError
        Fewer than 2 frames, or all of them identical.
    """
    if stop - start < 2:
        raise InputError(
            f"static={start}:{stop}: needs at least 2 frames of the static "
            "scene (e.g. --static 0:20)"
        )
    prev = frames[start]
    lo, hi = float(prev.min()), float(prev.max())
    edges = np.linspace(lo, hi + 1e-9, bins + 1)
    s2 = np.zeros(bins)
    cnt = np.zeros(bins)
    sig2 = []
    duplicated = 0
    for k in range(start + 1, stop):
        cur = frames[k]
        if np.array_equal(prev, cur):
            duplicated += 1
            continue
        sig2.append(estimate_noise(prev, cur) ** 2)
        d = prev - cur
        d = d - d.mean()
        lev = 0.5 * (prev + cur)
        idx = np.clip(np.searchsorted(edges, lev.ravel(), side="right") - 1, 0, bins - 1)
        s2 += np.bincount(idx, weights=d.ravel() ** 2, minlength=bins)
        cnt += np.bincount(idx, minlength=bins)
        prev = cur
    if not sig2 or not np.mean(sig2) > 0:
        raise InputError(
            f"static={start}:{stop}: the frames are identical bit for bit (one frame "
            "repeated: no noise to measure); give the noise std instead (--noise 2, GL)"
        )
    sigma = math.sqrt(float(np.mean(sig2)))
    ok = cnt >= 200
    read, slope, dep = sigma**2, 0.0, False
    if ok.sum() >= 3:
        lev_c = 0.5 * (edges[:-1] + edges[1:])[ok]
        var_b = s2[ok] / cnt[ok] / 2.0
        wts = cnt[ok]
        A = np.stack([np.ones_like(lev_c), lev_c], axis=1) * np.sqrt(wts)[:, None]
        coef = np.linalg.lstsq(A, var_b * np.sqrt(wts), rcond=None)[0]
        span = coef[1] * (lev_c.max() - lev_c.min())
        if coef[1] > 0 and span > 0.2 * sigma**2:
            read, slope, dep = float(max(coef[0], 0.0)), float(coef[1]), True
    return NoiseEstimate(
        sigma=sigma,
        read_variance=read,
        slope=slope,
        level_dependent=dep,
        source=f"static frames {start}:{stop}"
        + (f" ({duplicated} duplicated frames skipped)" if duplicated else ""),
        pairs=len(sig2),
    )


def subset_levels(reference: Float64Array, centres: IndexArray, subset: int) -> Float64Array:
    """Gradient-weighted grey level ``sum(g**2 I) / sum(g**2)`` of each subset (GL): the
    level at which signal-dependent noise enters its displacement error
    (:func:`dicblur.gradient_weighted_level`, per subset and for both directions)."""
    from scipy.ndimage import uniform_filter

    gy, gx = np.gradient(reference)
    g2 = gx * gx + gy * gy
    num = uniform_filter(g2 * reference, subset, mode="reflect")
    den = uniform_filter(g2, subset, mode="reflect")
    r, c = centres[:, 0], centres[:, 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        lv = num[r, c] / den[r, c]
    return np.where(np.isfinite(lv), lv, reference.mean())
