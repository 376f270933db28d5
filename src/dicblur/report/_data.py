"""Small accessors shared by the reproduce modules."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["series", "spearman"]


def series(ds: Any, var: str, pattern: str, noise: float) -> np.ndarray:
    """One campaign variable against blur W, for one pattern and noise level (float64)."""
    da = ds[var].sel(pattern=pattern, noise=noise)
    return np.asarray(da.squeeze(drop=True).values, dtype=np.float64)


def spearman(a: Any, b: Any) -> float:
    """Spearman rank correlation over the finite pairs (NaN with fewer than 3)."""
    from scipy import stats

    x = np.asarray(a, dtype=float)
    y = np.asarray(b, dtype=float)
    ok = np.isfinite(x) & np.isfinite(y)
    if ok.sum() < 3:
        return math.nan
    return float(stats.spearmanr(x[ok], y[ok]).statistic)
