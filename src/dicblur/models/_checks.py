"""Input checks of the model fits (each error names the parameter, the value and the fix)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..checks import describe
from ..errors import InputError


def as_vector(x: ArrayLike, name: str, n: int | None = None) -> NDArray[np.float64]:
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name}={describe(x)}: expected a 1-D array of numbers") from exc
    if a.ndim == 0:
        a = a[None]
    if a.ndim != 1:
        raise InputError(f"{name}={describe(a)}: expected a 1-D array (one value per point)")
    if n is not None and a.size != n:
        raise InputError(f"{name}: {a.size} values but blur has {n}; give one value per blur level")
    bad = ~np.isfinite(a)
    if bad.any():
        raise InputError(
            f"{name}: {int(bad.sum())} NaN or infinite value(s) (first at index "
            f"{int(np.argmax(bad))}); drop those points or fix the data"
        )
    return a


def as_blur(
    x: ArrayLike,
    name: str = "blur",
    *,
    increasing: bool = True,
    groups: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]:
    w = as_vector(x, name)
    if w.size == 0:
        raise InputError(f"{name}: empty; give the blur lengths W (px) of the measurements")
    if np.any(w < 0):
        raise InputError(
            f"{name}: negative blur length {float(w[w < 0][0])!r} px; W = |motion| is >= 0"
        )
    if increasing:
        keys = np.zeros(w.size) if groups is None else groups
        for g in np.unique(keys):
            wg = w[keys == g]
            if np.any(np.diff(wg) <= 0):
                where = "" if groups is None else f" (noise level {g:g})"
                raise InputError(
                    f"{name}: W must be strictly increasing{where}; sort the points by W "
                    "and average repeated W first"
                )
    return w


def as_positive(x: ArrayLike, name: str, n: int) -> NDArray[np.float64]:
    a = as_vector(x, name, n)
    if np.any(a <= 0):
        raise InputError(
            f"{name}: value {float(a[a <= 0][0])!r} at index {int(np.argmax(a <= 0))} is <= 0; "
            f"{name} must be > 0"
        )
    return a
