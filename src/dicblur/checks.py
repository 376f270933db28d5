"""Shared argument checks. Each raises :class:`~dicblur.errors.InputError` with a message
that names the parameter, the value and the fix."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import InputError

__all__ = [
    "as_image",
    "check_choice",
    "check_finite_number",
    "check_odd_subset",
    "check_positive",
    "check_seed",
    "check_shape2d",
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


def as_image(image: ArrayLike, name: str = "image", *, min_size: int = 2) -> NDArray[np.float64]:
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
    if not np.isfinite(out).all():
        bad = int(np.count_nonzero(~np.isfinite(out)))
        raise InputError(
            f"{name}={describe(arr)}: {bad} pixel(s) are NaN or infinite; "
            "replace or crop them before processing"
        )
    if out.size and float(np.max(np.abs(out))) > MAX_GREY:
        raise InputError(
            f"{name}={describe(arr)}: grey levels up to {float(np.max(np.abs(out))):.3g} GL, "
            f"beyond +-{MAX_GREY:.0e} GL (no camera records these; squared gradients would "
            "overflow); rescale the image to its camera's grey-level range"
        )
    return out


def check_textured(image: NDArray[np.float64], name: str = "image") -> None:
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


def check_finite_number(value: Any, name: str) -> float:
    """Check that ``value`` is a finite real scalar and return it as float."""
    if isinstance(value, bool):
        raise InputError(f"{name}={value!r}: expected a number, not a bool")
    try:
        x = float(value)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name}={describe(value)}: expected a real number") from exc
    if not math.isfinite(x):
        raise InputError(f"{name}={describe(value)}: must be finite (not NaN or infinite)")
    return x


def check_choice(value: Any, name: str, choices: Sequence[str]) -> str:
    """Check that ``value`` is one of ``choices`` and return it."""
    if not isinstance(value, str) or value not in choices:
        options = ", ".join(repr(c) for c in choices)
        raise InputError(f"{name}={describe(value)}: unknown option; choose one of {options}")
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
