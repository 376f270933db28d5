"""The input checks of every stage, in one place. Each raises
:class:`~dicblur.errors.InputError` (or the ``error`` class given: the campaign spec's
:class:`~dicblur.errors.ConfigError`) with a one-line message that names the parameter as the
user gave it, the value and the fix."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .arrays import Float64Array
from .errors import DicblurError, InputError

__all__ = [
    "as_blur",
    "as_float_array",
    "as_image",
    "as_positive",
    "as_vector",
    "as_whole",
    "bad_value",
    "check_choice",
    "check_finite_number",
    "check_integer",
    "check_odd_subset",
    "check_positive",
    "check_seed",
    "check_shape2d",
    "check_subpixel",
    "check_subset_fits",
    "check_textured",
    "describe",
]

MAX_GREY = 1e20
"""Largest magnitude accepted as a grey level (GL): above any integer camera format
(2**64 = 1.8e19), and far enough below the float64 range (1.8e308) that squared gradients
summed over a subset cannot overflow."""


def describe(value: Any) -> str:
    """Short, safe representation of a value for error messages."""
    if isinstance(value, np.ndarray):
        if value.ndim == 0:
            value = value.item()
        else:
            return f"array(shape={value.shape}, dtype={value.dtype})"
    if isinstance(value, np.generic):
        value = value.item()  # -1.0, not np.float64(-1.0)
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def bad_value(
    name: str, value: Any, why: str, *, error: type[DicblurError] = InputError
) -> DicblurError:
    """The exception ``name=value: why`` (``value`` as :func:`describe` shows it), to raise."""
    return error(f"{name}={describe(value)}: {why}")


def as_image(image: ArrayLike, name: str = "image", *, min_size: int = 2) -> Float64Array:
    """Return ``image`` as a C-contiguous 2-D float64 array of finite grey levels.

    Parameters
    ----------
    image : array_like, shape (rows, cols)
        Grey levels (any real dtype).
    name : str
        Parameter name used in error messages.
    min_size : int
        Smallest accepted number of rows and of columns.

    Raises
    ------
    InputError
        If the array is not 2-D, is smaller than ``min_size`` along an axis, is complex or
        not numeric, or holds NaN or infinite values.
    """
    try:
        arr = np.asarray(image)
    except Exception as exc:  # pragma: no cover - exotic array-likes
        raise InputError(f"{name}: cannot be converted to an array ({exc})") from exc
    if arr.dtype == bool:
        arr = arr.astype(np.float64)
    if not (np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)):
        raise InputError(
            f"{name}={describe(arr)}: expected real grey levels (integer or float dtype); "
            "convert colour or complex data to real grey levels first"
        )
    if arr.ndim != 2:
        raise InputError(
            f"{name}={describe(arr)}: expected a 2-D grey-level image of shape (rows, cols); "
            "convert colour images to grey (dicblur.load_image does) or pass one channel"
        )
    if arr.shape[0] < min_size or arr.shape[1] < min_size:
        raise InputError(
            f"{name}={describe(arr)}: the image must be at least {min_size}x{min_size} px"
        )
    out = np.ascontiguousarray(arr, dtype=np.float64)
    # two reductions without temporaries (a 512^2 frame: ~0.1 instead of ~0.4 ms, once per
    # tracked frame): a NaN propagates through min and max, an infinity is one of them
    lo, hi = (float(out.min()), float(out.max())) if out.size else (0.0, 0.0)
    if not (math.isfinite(lo) and math.isfinite(hi)):
        bad = int(np.count_nonzero(~np.isfinite(out)))
        raise InputError(
            f"{name}={describe(arr)}: {bad} pixel(s) are NaN or infinite; "
            "replace or crop them before processing"
        )
    if max(-lo, hi) > MAX_GREY:
        raise InputError(
            f"{name}={describe(arr)}: grey levels up to {max(-lo, hi):.3g} GL, "
            f"beyond +-{MAX_GREY:.0e} GL (no camera records these; squared gradients would "
            "overflow); rescale the image to its camera's grey-level range"
        )
    return out


def check_textured(image: Float64Array, name: str = "image") -> None:
    """Refuse an image without texture (every pixel the same grey level): no metric, no
    correlation and no blur sensitivity is defined on it."""
    if image.size and float(np.ptp(image)) == 0.0:
        raise InputError(
            f"{name}: the image is constant ({image.shape[0]}x{image.shape[1]} px, every "
            f"pixel {describe(float(image.flat[0]))} GL): no texture to measure or "
            "correlate; give an image of the speckle pattern"
        )


def check_seed(seed: Any, name: str = "seed") -> Any:
    """Check a seed argument: None, an int >= 0, a numpy Generator or SeedSequence."""
    if seed is None or isinstance(seed, np.random.Generator | np.random.SeedSequence):
        return seed
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer):
        raise InputError(
            f"{name}={describe(seed)}: expected an int >= 0, a numpy Generator, "
            "a SeedSequence or None"
        )
    if seed < 0:
        raise InputError(f"{name}={describe(seed)}: seeds must be integers >= 0 (e.g. 1)")
    return int(seed)


def check_odd_subset(subset: Any, name: str = "subset", *, minimum: int = 3) -> int:
    """Check that ``subset`` is an odd integer >= ``minimum`` and return it as ``int``."""
    if isinstance(subset, bool) or not isinstance(subset, int | np.integer):
        if isinstance(subset, float) and subset.is_integer():
            subset = int(subset)
        else:
            raise InputError(
                f"{name}={describe(subset)}: the subset size must be an odd integer "
                f">= {minimum} (e.g. 21)"
            )
    subset = int(subset)
    if subset < minimum or subset % 2 == 0:
        hint = f"use {subset - 1} or {subset + 1}" if subset >= minimum else "e.g. 21"
        raise InputError(
            f"{name}={subset}: the subset size must be an odd integer >= {minimum} ({hint})"
        )
    return subset


def check_subset_fits(
    subset: int, shape: tuple[int, ...], name: str = "subset", *, border: int = 1, minimum: int = 3
) -> None:
    """Check that an odd ``subset`` plus ``border`` px on each side fits in an image of
    ``shape``; the message gives the largest subset that fits, or says that none does."""
    rows, cols = int(shape[0]), int(shape[1])
    if subset + 2 * border <= min(rows, cols):
        return
    largest = min(rows, cols) - 2 * border
    largest -= 1 - largest % 2
    what = f"a subset plus a {border}-px border" if border else "a subset"
    if largest < minimum:
        raise InputError(
            f"{name}={subset}: the image is {rows}x{cols} px, too small for any subset "
            f"({what} needs at least {minimum + 2 * border}x{minimum + 2 * border} px); "
            "use a larger image"
        )
    raise InputError(
        f"{name}={subset}: {what} does not fit in an image of {rows}x{cols} px; use a "
        f"subset <= {largest}"
    )


def check_positive(value: Any, name: str, *, allow_zero: bool = False) -> float:
    """Check that ``value`` is a finite real number > 0 (or >= 0) and return it as float."""
    x = check_finite_number(value, name)
    if x < 0 or (x == 0 and not allow_zero):
        need = ">= 0" if allow_zero else "> 0"
        raise InputError(f"{name}={describe(value)}: must be {need}")
    return x


def check_finite_number(
    value: Any, name: str, *, strict: bool = False, error: type[DicblurError] = InputError
) -> float:
    """Check that ``value`` is a finite real scalar and return it as float.

    ``strict``: only an int or a float is a number (a parsed TOML value; no string
    ``"3"`` converted by ``float``)."""
    if isinstance(value, bool):
        raise error(f"{name}={value!r}: expected a number, not a bool")
    if strict and not isinstance(value, int | float):
        raise bad_value(name, value, "expected a number", error=error)
    try:
        x = float(value)
    except (TypeError, ValueError) as exc:
        raise bad_value(name, value, "expected a real number", error=error) from exc
    if not math.isfinite(x):
        raise bad_value(name, value, "must be finite (not NaN or infinite)", error=error)
    return x


def check_integer(
    value: Any, name: str, *, minimum: int, error: type[DicblurError] = InputError
) -> int:
    """Check that ``value`` is an integer (or an integral float) >= ``minimum``; return it."""
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        else:
            raise bad_value(name, value, f"expected an integer >= {minimum}", error=error)
    if value < minimum:
        raise bad_value(name, value, f"must be an integer >= {minimum}", error=error)
    return int(value)


def check_choice(
    value: Any, name: str, choices: Sequence[str], *, error: type[DicblurError] = InputError
) -> str:
    """Check that ``value`` is one of ``choices`` and return it."""
    if not isinstance(value, str) or value not in choices:
        options = ", ".join(repr(c) for c in choices)
        raise bad_value(name, value, f"unknown option; choose one of {options}", error=error)
    return value


def check_shape2d(shape: Any, name: str = "shape", *, min_size: int = 2) -> tuple[int, int]:
    """Check a (rows, cols) shape and return it as a tuple of ints."""
    if isinstance(shape, int | np.integer) and not isinstance(shape, bool):
        shape = (int(shape), int(shape))
    try:
        rows, cols = (int(s) for s in shape)
        ok = all(float(s) == int(s) for s in shape)
    except (TypeError, ValueError) as exc:
        raise InputError(
            f"{name}={describe(shape)}: expected (rows, cols) as two integers, e.g. (512, 512)"
        ) from exc
    if not ok or rows < min_size or cols < min_size:
        raise InputError(f"{name}={describe(shape)}: rows and cols must be integers >= {min_size}")
    return rows, cols


def as_float_array(value: Any, name: str, *, expected: str) -> Float64Array:
    """``value`` as a float64 array of any shape; the shape and the values are the caller's
    to check. Raises ``InputError("{name}={value}: {expected}")`` when it holds no numbers."""
    try:
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name}={describe(value)}: {expected}") from exc


# -- measurement vectors of the model fits ----------------------------------------------


def as_vector(x: ArrayLike, name: str, n: int | None = None) -> Float64Array:
    """``x`` as a 1-D float64 array of finite values (``n`` of them when given)."""
    a = as_float_array(x, name, expected="expected a 1-D array of numbers")
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
    groups: Float64Array | None = None,
) -> Float64Array:
    """Blur lengths W (px): a non-empty 1-D array of values >= 0, strictly increasing
    (within each of ``groups``, e.g. per noise level) unless ``increasing=False``."""
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


def as_positive(x: ArrayLike, name: str, n: int) -> Float64Array:
    """``n`` finite values > 0 as a 1-D float64 array."""
    a = as_vector(x, name, n)
    if np.any(a <= 0):
        raise InputError(
            f"{name}: value {float(a[a <= 0][0])!r} at index {int(np.argmax(a <= 0))} is <= 0; "
            f"{name} must be > 0"
        )
    return a


def as_whole(value: float, why: str) -> int:
    """``value`` as the integer it equals to within 1e-9; else ``InputError(why)`` (``why``
    names the parameters whose product or ratio ``value`` is, their values and the fix)."""
    if abs(value - round(value)) > 1e-9:
        raise InputError(why)
    return round(value)


def check_subpixel(subpixel: object) -> float:
    """A sub-pixel offset (px) as a float in [0, 1)."""
    if (
        isinstance(subpixel, bool)
        or not isinstance(subpixel, (int, float))
        or not (math.isfinite(subpixel) and 0.0 <= subpixel < 1.0)
    ):
        raise InputError(
            f"subpixel={subpixel!r}: give the target's sub-pixel position along "
            "the motion in [0, 1) px (e.g. 0.5)"
        )
    return float(subpixel)
