"""One frozen record of the subset matcher's settings, shared by the Correlator, the
campaigns and the predictions (issue 16: instead of the same nine keywords repeated).

Names follow the glossary (docs/architecture.md): ``subset``, ``step``, ``shape``,
``interpolation``. Validated once, on construction, with the messages the Correlator gave
for the same values.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from ..checks import check_choice, check_odd_subset, check_positive, describe
from ..errors import InputError

__all__ = ["INITIAL_METHODS", "INTERPOLATIONS", "SHAPES", "MatcherSettings"]

Shape = Literal["affine", "translation"]
Interpolation = Literal["bspline3", "bspline5"]
Initial = Literal["fftcc", "subset", "zero"]
SHAPES: tuple[str, ...] = ("affine", "translation")
INTERPOLATIONS: tuple[str, ...] = ("bspline3", "bspline5")
#: ``fftcc``: global phase correlation, then per-subset FFT-CC for the POIs that fail;
#: ``subset``: per-subset FFT-CC for every POI; ``zero``: start every POI at (0, 0).
INITIAL_METHODS: tuple[str, ...] = ("fftcc", "subset", "zero")


def check_integer(value: Any, name: str, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < minimum:
        raise InputError(f"{name}={describe(value)}: must be an integer >= {minimum}")
    return int(value)


@dataclass(frozen=True)
class MatcherSettings:
    """Settings of the subset matcher (IC-GN with the ZNSSD criterion).

    Parameters
    ----------
    subset : int
        Odd subset size, px.
    step : int
        Grid spacing of the POIs, px.
    shape : {"affine", "translation"}
        First-order (6 parameters) or zero-order (2 parameters) shape function. The
        default is the DIC engine's ``"affine"``; the models and predictions use
        ``"translation"`` (the paper's setting) unless given a MatcherSettings.
    interpolation : {"bspline3", "bspline5"}
        Prefiltered cubic or quintic B-spline.
    initial : {"fftcc", "subset", "zero"}
        Initial-guess method (see :data:`INITIAL_METHODS`).
    max_iterations : int
        IC-GN iteration limit.
    tolerance : float
        Convergence threshold, px: the estimated error left in the parameters, in the norm
        ``|d| = sqrt(du^2 + dv^2 + h^2 |grad|^2)`` of the Gauss-Newton step (``h`` = subset
        half-width). IC-GN stops when ``|d| < tolerance``, or, when its steps contract by
        ``q = |d| / |d_prev|``, when the rest of that series ``|d| q / (1 - q)`` is below it
        (below 4 x it when the step is an Aitken jump to the series' limit,
        ``kernels.JUMP_SLACK``; docs/dic.md, "IC-GN with ZNSSD").
    min_zncc : float
        Converged points with a lower ZNCC get status ``LOW_CORRELATION``.
    max_residual : float or None
        With a noise level: converged points whose ZNSSD residual exceeds this many times
        the noise prediction get ``HIGH_RESIDUAL`` (None: no test).
    median_test : bool
        Screen the POI grid for ``OUTLIER`` points (normalised median test and probe).

    Examples
    --------
    >>> from dicblur.dic import MatcherSettings
    >>> s = MatcherSettings(subset=31, shape="translation")
    >>> s.subset, s.step, s.order
    (31, 10, 3)
    >>> MatcherSettings(subset=20)
    Traceback (most recent call last):
    ...
    dicblur.errors.InputError: subset=20: the subset size must be an odd integer >= 3 (use 19 or 21)
    """

    subset: int = 21
    step: int = 10
    shape: Shape = "affine"
    interpolation: Interpolation = "bspline3"
    initial: Initial = "fftcc"
    max_iterations: int = 50
    tolerance: float = 1e-4
    min_zncc: float = 0.6
    max_residual: float | None = 2.0
    median_test: bool = False

    def __post_init__(self) -> None:
        put = object.__setattr__  # frozen: store the normalised values once
        put(self, "subset", check_odd_subset(self.subset))
        put(self, "step", check_integer(self.step, "step", 1))
        check_choice(self.shape, "shape", SHAPES)
        check_choice(self.interpolation, "interpolation", INTERPOLATIONS)
        check_choice(self.initial, "initial", INITIAL_METHODS)
        put(self, "max_iterations", check_integer(self.max_iterations, "max_iterations", 1))
        put(self, "tolerance", check_positive(self.tolerance, "tolerance"))
        try:
            zncc = float(self.min_zncc)
        except (TypeError, ValueError):
            zncc = float("nan")
        if not -1.0 <= zncc <= 1.0:
            raise InputError(f"min_zncc={self.min_zncc!r}: must lie in [-1, 1]")
        put(self, "min_zncc", zncc)
        if self.max_residual is not None:
            put(self, "max_residual", check_positive(self.max_residual, "max_residual"))
        if not isinstance(self.median_test, bool | np.bool_):
            raise InputError(f"median_test={describe(self.median_test)}: must be True or False")
        put(self, "median_test", bool(self.median_test))

    @property
    def order(self) -> int:
        """Spline degree of :attr:`interpolation` (3 or 5)."""
        return int(self.interpolation[-1])

    @property
    def half(self) -> int:
        """Subset half-width, px."""
        return self.subset // 2
