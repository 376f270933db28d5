"""The design problem: the user's blur, noise and DIC settings, and the objective."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..arrays import Float64Array
from ..checks import check_finite_number, check_odd_subset, check_positive, describe
from ..errors import InputError

__all__ = ["DesignProblem", "design_problem", "sine_blur_distribution"]


@dataclass(frozen=True)
class DesignProblem:
    """What the pattern must resist, and how each candidate is measured.

    The objective of a candidate is the weighted mean of its predicted u_e (px) over
    ``blurs`` with ``weights``: one blur length, a uniform grid over a range, or the
    distribution of blur lengths of a trajectory.

    Attributes
    ----------
    blurs : tuple of float
        Design blur lengths W (px), >= 0.
    weights : tuple of float
        Their weights (sum 1).
    noise : float
        Camera noise std (grey levels of 0..255), added once per exposure, > 0.
    subset : int
        Odd subset size, px.
    step : int
        POI grid step, px.
    image_size : int
        Side of the square synthetic images, px.
    dic_shape : {"translation", "affine"}
    substeps : int
        K of the blur synthesis (K + 1 positions).
    realisations : int
        Pattern realisations (seeds) per candidate in the search.
    fit_blurs : tuple of float
        W grid (px) of each candidate's campaign, to which the blur model is fitted.
    scale : float or None
        Object-space size of a camera pixel (mm/px), for physical speckle sizes.
    seed : int
        Base seed of every pattern and noise draw.
    """

    blurs: tuple[float, ...]
    weights: tuple[float, ...]
    noise: float = 2.0
    subset: int = 31
    step: int = 10
    image_size: int = 256
    dic_shape: str = "translation"
    substeps: int = 100
    realisations: int = 2
    fit_blurs: tuple[float, ...] = field(default=())
    scale: float | None = None
    seed: int = 0

    @property
    def blur_array(self) -> Float64Array:
        return np.asarray(self.blurs, dtype=np.float64)

    @property
    def weight_array(self) -> Float64Array:
        return np.asarray(self.weights, dtype=np.float64)

    def objective(self, u_e: Float64Array) -> float:
        """Weighted mean of ``u_e`` given at :attr:`blurs` (px)."""
        return float(np.dot(self.weight_array, np.asarray(u_e, dtype=np.float64)))

    def describe_target(self) -> str:
        """Readable statement of the design blur."""
        if len(self.blurs) == 1:
            return f"W = {self.blurs[0]:g} px"
        return f"mean over W = {self.blurs[0]:g}..{self.blurs[-1]:g} px ({len(self.blurs)} values)"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict."""
        return {
            "blurs": list(self.blurs),
            "weights": list(self.weights),
            "noise": self.noise,
            "subset": self.subset,
            "step": self.step,
            "image_size": self.image_size,
            "dic_shape": self.dic_shape,
            "substeps": self.substeps,
            "realisations": self.realisations,
            "fit_blurs": list(self.fit_blurs),
            "scale": self.scale,
            "seed": self.seed,
        }


def sine_blur_distribution(
    amplitude: float, frequency: float, exposure: float, *, points: int = 11
) -> tuple[Float64Array, Float64Array]:
    """Blur lengths seen by a camera triggered at a random phase of a sine vibration.

    The target moves as ``x(t) = A sin(2 pi f t)`` (px). An exposure of length T starting
    at phase phi sees the displacement ``W(phi) = |x(t + T) - x(t)| =
    2 A |sin(pi f T)| |cos(2 pi f t + pi f T)|``: with a uniformly random trigger phase,
    W follows an arcsine law on [0, 2 A |sin(pi f T)|]. Returned as ``points`` equally
    weighted quantiles (the mid-point quantiles of the phase). The blur of one exposure is
    treated as linear of length W, fair while ``f T`` is small (less than about 1/8).

    Parameters
    ----------
    amplitude : float
        Vibration amplitude A, px (> 0).
    frequency : float
        Hz (> 0).
    exposure : float
        Exposure time T, s (> 0).
    points : int
        Number of blur lengths returned.

    Returns
    -------
    blurs, weights : ndarray, shape (points,)
        W (px), ascending, and equal weights summing to 1.
    """
    a = check_positive(amplitude, "amplitude")
    f = check_positive(frequency, "frequency")
    t = check_positive(exposure, "exposure")
    if isinstance(points, bool) or not isinstance(points, int) or points < 1:
        raise InputError(f"points={describe(points)}: expected an integer >= 1")
    w_max = 2.0 * a * abs(np.sin(np.pi * f * t))
    phase = (np.arange(points) + 0.5) / points * (np.pi / 2)
    blurs = np.sort(w_max * np.cos(phase))
    return blurs, np.full(points, 1.0 / points)


def _blur_value(value: Any, name: str) -> float:
    w = check_finite_number(value, name)
    if w < 0:
        raise InputError(
            f"{name}={value!r}: a blur length W is the distance (px) travelled "
            "during the exposure, it must be >= 0"
        )
    return w


def design_problem(
    *,
    blur: float | None = None,
    blur_range: tuple[float, float] | None = None,
    blurs: Any = None,
    weights: Any = None,
    velocity: float | None = None,
    exposure: float | None = None,
    scale: float | None = None,
    noise: float = 2.0,
    subset: int = 31,
    step: int = 10,
    image_size: int = 256,
    dic_shape: str = "translation",
    substeps: int = 100,
    realisations: int = 2,
    n_fit_blurs: int = 6,
    range_points: int = 11,
    seed: int = 0,
) -> DesignProblem:
    """Build and validate a :class:`DesignProblem`.

    Give exactly one of: ``blur`` (px); ``blur_range`` (lo, hi) px, averaged uniformly over
    ``range_points`` values; ``blurs`` (+ optional ``weights``), a distribution of blur
    lengths (e.g. of a vibrating target's trajectory); or ``velocity`` (mm/s),
    ``exposure`` (s) and ``scale`` (mm/px), giving ``W = velocity * exposure / scale``
    (:func:`dicblur.blur_length`).

    Raises
    ------
    InputError
        Negative or non-finite blur, inverted range, noise <= 0, even subset, too small
        an image for the subset, inconsistent options.
    """
    from ..blur import blur_length

    given = [
        blur is not None,
        blur_range is not None,
        blurs is not None,
        velocity is not None or exposure is not None,
    ]
    if sum(given) != 1:
        raise InputError(
            "blur: give exactly one of blur (px), blur_range (lo, hi px), blurs (a "
            "distribution) or velocity + exposure + scale"
        )
    if blur is not None:
        w = np.array([_blur_value(blur, "blur")])
        wt = np.ones(1)
    elif blur_range is not None:
        try:
            lo_raw, hi_raw = blur_range
        except (TypeError, ValueError) as exc:
            raise InputError(f"blur_range={describe(blur_range)}: expected (lo, hi) in px") from exc
        lo, hi = _blur_value(lo_raw, "blur_range"), _blur_value(hi_raw, "blur_range")
        if hi < lo:
            raise InputError(
                f"blur_range=({lo:g}, {hi:g}): inverted range; give it as "
                f"{hi:g}..{lo:g} (low..high)"
            )
        n = 1 if hi == lo else max(2, int(range_points))
        w = np.linspace(lo, hi, n)
        wt = np.full(n, 1.0 / n)
    elif blurs is not None:
        w = np.atleast_1d(np.asarray(blurs, dtype=np.float64))
        if w.ndim != 1 or w.size == 0 or not np.all(np.isfinite(w)) or np.any(w < 0):
            raise InputError(f"blurs={describe(blurs)}: expected finite blur lengths >= 0 px")
        wt = np.ones(w.size) if weights is None else np.asarray(weights, dtype=np.float64)
        if wt.shape != w.shape or not np.all(np.isfinite(wt)) or np.any(wt < 0) or wt.sum() <= 0:
            raise InputError(
                f"weights={describe(weights)}: expected one weight >= 0 per "
                "blur length, not all zero"
            )
        order = np.argsort(w)
        w, wt = w[order], wt[order]
        wt = wt / wt.sum()
    else:
        if velocity is None or exposure is None or scale is None:
            raise InputError(
                "velocity, exposure, scale: all three are needed to compute the "
                "blur length W = velocity * exposure / scale"
            )
        w = np.array([blur_length(velocity, exposure, scale)])
        wt = np.ones(1)
    noise = check_positive(noise, "noise")
    subset = check_odd_subset(subset, minimum=5)
    if isinstance(step, bool) or not isinstance(step, int | np.integer) or step < 1:
        raise InputError(f"step={describe(step)}: expected an integer >= 1 px")
    if isinstance(image_size, bool) or not isinstance(image_size, int | np.integer):
        raise InputError(f"image_size={describe(image_size)}: expected an integer (px)")
    if image_size < 2 * subset + 2 * int(step):
        raise InputError(
            f"image_size={image_size}: too small for subset {subset} px; use "
            f">= {2 * subset + 2 * int(step)} px so several subsets fit"
        )
    if dic_shape not in ("translation", "affine"):
        raise InputError(f"dic_shape={dic_shape!r}: choose 'translation' or 'affine'")
    if isinstance(realisations, bool) or not isinstance(realisations, int) or realisations < 1:
        raise InputError(f"realisations={describe(realisations)}: expected an integer >= 1")
    if not isinstance(n_fit_blurs, int) or n_fit_blurs < 4:
        raise InputError(
            f"n_fit_blurs={describe(n_fit_blurs)}: the blur model needs at least 4 blur levels"
        )
    if scale is not None:
        scale = check_positive(scale, "scale")
    w_max = float(w.max())
    if w_max > image_size / 4:
        raise InputError(
            f"blur: W = {w_max:g} px is more than a quarter of the {image_size} "
            "px synthetic image; use a larger image_size"
        )
    # Each candidate's campaign spans 0 .. 1.25 max(W) (>= 1 px): the model interpolates.
    w_hi = max(1.25 * w_max, 1.0)
    fit = tuple(float(round(v, 4)) for v in np.linspace(0.0, w_hi, n_fit_blurs))
    return DesignProblem(
        blurs=tuple(float(v) for v in w),
        weights=tuple(float(v) for v in wt),
        noise=noise,
        subset=subset,
        step=int(step),
        image_size=int(image_size),
        dic_shape=dic_shape,
        substeps=int(substeps),
        realisations=realisations,
        fit_blurs=fit,
        scale=scale,
        seed=int(seed),
    )
