"""The family of generated speckle patterns the design searches, and its bounds.

A member of the family is :func:`dicblur.speckle_pattern` with three free settings:

- ``speckle_size`` D (px, autocorrelation diameter): the one that trades noise
  rejection (small speckles, many edges, high SSSIG) against blur resistance (large
  speckles keep their contrast longer; the paper's Fig. 11).
- ``density`` (black-area fraction): sets how close neighbouring speckles are, i.e. the
  gap g of the 1-D analysis (paper Section V: regimes (c) and (d) start when W exceeds
  the gap).
- ``softness`` (px, Gaussian edge-blur sigma): soft edges lower SSSIG but also the
  blur-mismatch term (the second derivative of the pattern is smaller).

Contrast is not searched: full contrast (0..255) is always best (u_e scales as
1 / contrast at fixed noise), so it is fixed at 1.

Default bounds (documented in docs/design.md):
``speckle_size`` in [2, min(10, subset / 3)] px (below 2 px the pattern aliases;
above subset / 3 a subset holds fewer than about 3 speckles along each axis and DIC
loses robustness), ``density`` in [0.3, 0.7], ``softness`` in [0, 2] px.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..arrays import Float64Array
from ..checks import check_finite_number, describe
from ..errors import InputError

__all__ = ["DEFAULT_CANDIDATE", "Candidate", "PatternFamily"]

_NAMES = ("speckle_size", "density", "softness")


@dataclass(frozen=True)
class Candidate:
    """One member of the pattern family (settings of :func:`dicblur.speckle_pattern`).

    Attributes
    ----------
    speckle_size : float
        Mean speckle diameter, px (autocorrelation definition).
    density : float
        Black-area fraction in (0, 1).
    softness : float
        Edge-blur standard deviation, px (>= 0).
    """

    speckle_size: float
    density: float
    softness: float

    def key(self) -> tuple[float, float, float]:
        """Rounded settings, used to recognise a candidate already evaluated."""
        return (round(self.speckle_size, 4), round(self.density, 4), round(self.softness, 4))

    def label(self) -> str:
        """Short readable label, e.g. ``D=4 p=0.5 s=0``."""
        return f"D={self.speckle_size:.3g} p={self.density:.3g} s={self.softness:.3g}"

    def settings(self, shape: tuple[int, int], seed: int) -> dict[str, Any]:
        """Keyword arguments of :func:`dicblur.speckle_pattern` for this candidate."""
        return {
            "shape": [int(shape[0]), int(shape[1])],
            "speckle_size": self.speckle_size,
            "density": self.density,
            "softness": self.softness,
            "seed": int(seed),
        }

    def to_dict(self) -> dict[str, float]:
        """JSON-ready dict."""
        return {
            "speckle_size": self.speckle_size,
            "density": self.density,
            "softness": self.softness,
        }


#: The defaults of :func:`dicblur.speckle_pattern`: the "default pattern" the design beats.
DEFAULT_CANDIDATE = Candidate(speckle_size=4.0, density=0.5, softness=0.0)


def _bounds(value: Any, name: str, lo_min: float, hi_max: float) -> tuple[float, float]:
    try:
        lo, hi = (check_finite_number(v, name) for v in value)
    except (TypeError, ValueError) as exc:
        if isinstance(exc, InputError):
            raise
        raise InputError(f"{name}={describe(value)}: expected (low, high)") from exc
    if not lo_min <= lo <= hi <= hi_max:
        raise InputError(f"{name}=({lo:g}, {hi:g}): need {lo_min:g} <= low <= high <= {hi_max:g}")
    return lo, hi


@dataclass(frozen=True)
class PatternFamily:
    """Bounds and coarse grid of the searched pattern family.

    Parameters
    ----------
    speckle_size : (float, float)
        Bounds of the speckle diameter, px; within [1.5, 64].
    density : (float, float)
        Bounds of the black-area fraction; within [0.1, 0.9].
    softness : (float, float)
        Bounds of the edge-blur sigma, px; within [0, 8].
    grid : (int, int, int)
        Coarse-grid points along (speckle_size, density, softness); 1 for a fixed setting
        (its bounds' midpoint). Speckle sizes are spaced geometrically, the others linearly.
    """

    speckle_size: tuple[float, float] = (2.0, 10.0)
    density: tuple[float, float] = (0.3, 0.7)
    softness: tuple[float, float] = (0.0, 2.0)
    grid: tuple[int, int, int] = (5, 3, 3)

    def __post_init__(self) -> None:
        object.__setattr__(
            self, "speckle_size", _bounds(self.speckle_size, "speckle_size", 1.5, 64.0)
        )
        object.__setattr__(self, "density", _bounds(self.density, "density", 0.1, 0.9))
        object.__setattr__(self, "softness", _bounds(self.softness, "softness", 0.0, 8.0))
        g = tuple(self.grid)
        if len(g) != 3 or not all(
            isinstance(n, int | np.integer) and not isinstance(n, bool) and 1 <= n <= 25 for n in g
        ):
            raise InputError(
                f"grid={describe(self.grid)}: expected three integers in 1..25 "
                "(points along speckle_size, density, softness)"
            )
        object.__setattr__(self, "grid", tuple(int(n) for n in g))

    @classmethod
    def for_subset(cls, subset: int, **kwargs: Any) -> PatternFamily:
        """The default family with the speckle-size bound capped at ``subset / 3`` px."""
        hi = max(2.0, min(10.0, subset / 3.0))
        kwargs.setdefault("speckle_size", (2.0, hi))
        return cls(**kwargs)

    @property
    def bounds(self) -> tuple[tuple[float, float], ...]:
        """((lo, hi) of speckle_size, density, softness)."""
        return (self.speckle_size, self.density, self.softness)

    @property
    def free(self) -> tuple[bool, ...]:
        """Which settings vary (bounds of non-zero width)."""
        return tuple(hi > lo for lo, hi in self.bounds)

    def axis(self, i: int) -> Float64Array:
        """Grid values of setting ``i`` (0 speckle_size, 1 density, 2 softness)."""
        lo, hi = self.bounds[i]
        n = self.grid[i]
        if n == 1 or hi == lo:
            return np.array([0.5 * (lo + hi)])
        if i == 0:
            return np.geomspace(lo, hi, n)
        return np.linspace(lo, hi, n)

    def grid_candidates(self) -> list[Candidate]:
        """Coarse-grid members, speckle size varying slowest."""
        return [
            Candidate(float(d), float(p), float(s))
            for d in self.axis(0)
            for p in self.axis(1)
            for s in self.axis(2)
        ]

    def to_unit(self, c: Candidate) -> Float64Array:
        """Map a candidate to [0, 1]^3 (log scale for the speckle size)."""
        z = np.zeros(3)
        vals = (c.speckle_size, c.density, c.softness)
        for i, ((lo, hi), v) in enumerate(zip(self.bounds, vals, strict=True)):
            if hi > lo:
                z[i] = (math.log(v / lo) / math.log(hi / lo)) if i == 0 else (v - lo) / (hi - lo)
        return z

    def from_unit(self, z: Sequence[float] | Float64Array) -> Candidate:
        """Candidate at unit coordinates ``z`` (clipped to the bounds)."""
        vals = []
        for i, (lo, hi) in enumerate(self.bounds):
            t = min(max(float(z[i]), 0.0), 1.0)
            if hi == lo:
                vals.append(lo)
            elif i == 0:
                vals.append(lo * (hi / lo) ** t)
            else:
                vals.append(lo + t * (hi - lo))
        return Candidate(*vals)

    def contains(self, c: Candidate, *, tol: float = 1e-9) -> bool:
        """Whether ``c`` lies within the bounds."""
        vals = (c.speckle_size, c.density, c.softness)
        return all(lo - tol <= v <= hi + tol for (lo, hi), v in zip(self.bounds, vals, strict=True))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict."""
        return {
            "speckle_size": list(self.speckle_size),
            "density": list(self.density),
            "softness": list(self.softness),
            "grid": list(self.grid),
        }
