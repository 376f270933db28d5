"""A tiny unit parser for the planning inputs (no external unit library).

Base units: length mm, time s, velocity mm/s, image scale mm/px, blur px, displacement px
(px only: no scale), strain (dimensionless; ``microstrain``, ``ustrain``, ``µstrain`` are
1e-6, ``%`` 1e-2). A quantity is a
float in the base unit or a string ``"<number><unit>"`` such as ``"120mm/s"``, ``"0.12 m/s"``,
``"1ms"``, ``"0.05mm/px"``, ``"20px/mm"``, ``"0.01px"``, ``"800px/s"``, ``"100microstrain"``.
"""

from __future__ import annotations

import math
import re
from typing import Literal

from ..checks import describe
from ..errors import InputError

__all__ = ["Kind", "parse_quantity"]

Kind = Literal["length", "time", "velocity", "scale", "blur", "displacement", "strain"]

_LENGTH = {"m": 1e3, "cm": 10.0, "mm": 1.0, "um": 1e-3, "µm": 1e-3, "μm": 1e-3, "nm": 1e-6}
_STRAIN = {"microstrain": 1e-6, "ustrain": 1e-6, "µstrain": 1e-6, "μstrain": 1e-6, "%": 1e-2}
_TIME = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6, "μs": 1e-6, "ns": 1e-9, "min": 60.0}
_NUM = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(.*?)\s*$")
_EXAMPLES = {
    "length": "'2mm' or '150um'",
    "time": "'1ms' or '0.002s'",
    "velocity": "'120mm/s', '0.12m/s' or '800px/s'",
    "scale": "'0.05mm/px' or '20px/mm'",
    "blur": "'0.01px' or '2um' (with a scale)",
    "displacement": "'0.033px'",
    "strain": "'100microstrain', '100ustrain' or '1e-4'",
}
_BASE = {
    "length": "mm",
    "time": "s",
    "velocity": "mm/s",
    "scale": "mm/px",
    "blur": "px",
    "displacement": "px",
    "strain": "strain (dimensionless)",
}


def _fail(value: object, name: str, kind: str, why: str) -> InputError:
    return InputError(
        f"{name}={describe(value)}: {why}; give a number in {_BASE[kind]} or a string such "
        f"as {_EXAMPLES[kind]}"
    )


def parse_quantity(
    value: float | str, kind: Kind, *, name: str = "value", scale: float | None = None
) -> float:
    """Return ``value`` in the base unit of ``kind`` (mm, s, mm/s, mm/px or px).

    Parameters
    ----------
    value : float or str
        A number (already in the base unit) or ``"<number><unit>"``.
    kind : {"length", "time", "velocity", "scale", "blur", "displacement", "strain"}
    name : str
        Parameter name for error messages.
    scale : float, optional
        Image scale in mm/px, needed to convert px to mm (velocity in px/s) or a blur given
        as a length to px.

    Returns
    -------
    float
        Finite value in the base unit (signs are kept; callers check the range). A strain
        is dimensionless (``"100microstrain"`` -> 1e-4).
    """
    if kind not in _BASE:
        raise InputError(f"kind={kind!r}: choose one of {sorted(_BASE)}")
    if isinstance(value, bool):
        raise _fail(value, name, kind, "expected a number or a string with a unit")
    if isinstance(value, int | float):
        x = float(value)
        if not math.isfinite(x):
            raise _fail(value, name, kind, "must be finite")
        return x
    if not isinstance(value, str):
        raise _fail(value, name, kind, "expected a number or a string with a unit")
    m = _NUM.match(value)
    if not m:
        raise _fail(value, name, kind, "cannot read a number followed by a unit")
    x = float(m.group(1))
    unit = m.group(2).replace(" ", "")
    if not math.isfinite(x):
        raise _fail(value, name, kind, "must be finite")
    if unit == "":
        return x
    num, _, den = unit.partition("/")
    if kind == "displacement" and unit == "px":
        return x
    if kind == "strain" and unit.lower() in _STRAIN:
        return x * _STRAIN[unit.lower()]
    if kind in ("length", "blur") and not den:
        if num == "px":
            if kind == "blur":
                return x
            if scale is None:
                raise _fail(value, name, kind, "a length in px needs the image scale")
            return x * scale
        if num in _LENGTH:
            mm = x * _LENGTH[num]
            if kind == "length":
                return mm
            if scale is None:
                raise _fail(value, name, kind, "a blur given as a length needs the image scale")
            return mm / scale
    if kind == "time" and not den and num in _TIME:
        return x * _TIME[num]
    if kind == "velocity" and den in _TIME:
        if num in _LENGTH:
            return x * _LENGTH[num] / _TIME[den]
        if num == "px":
            if scale is None:
                raise _fail(value, name, kind, "a velocity in px/s needs the image scale")
            return x * scale / _TIME[den]
    if kind == "scale":
        if den == "px" and num in _LENGTH:
            return x * _LENGTH[num]
        if num == "px" and den in _LENGTH:
            if x == 0:
                raise _fail(value, name, kind, "must be non-zero")
            return _LENGTH[den] / x
    raise _fail(value, name, kind, f"unit {unit!r} is not a {kind} unit")
