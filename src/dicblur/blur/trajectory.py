"""Trajectories of the blur: the path ``p(t)`` of the image content during the exposure
(linear, sine, constant acceleration, a sampled array or a callable) and its sub-frame
positions and weights (the paper's Algorithm 1, or the continuous limit by quadrature).
Conventions in :mod:`dicblur.blur`."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..arrays import Float64Array
from ..checks import as_float_array, check_choice, check_finite_number, describe
from ..errors import InputError

__all__ = [
    "AcceleratedMotion",
    "SineMotion",
    "Trajectory",
    "check_motion",
    "check_substeps",
    "classify",
    "is_array_path",
    "trajectory_positions",
]

PathFunction = Callable[[Float64Array], ArrayLike]

_TRAJECTORY_NAMES = ("linear", "sine", "acceleration")
# Composite Gauss-Legendre rule of the continuous limit for non-linear paths: nodes per
# segment, largest phase change per segment (rad), fewest segments (see docs/blur.md).
_GL_NODES = 24
_GL_PHASE_PER_SEGMENT = 8.0
_GL_MIN_SEGMENTS = 4


@dataclass(frozen=True)
class SineMotion:
    """Sinusoidal vibration during the exposure (a structure in modal testing).

    Position at normalised time ``t`` in [0, 1] (``t = 0`` opens the shutter)::

        p(t) = motion * sin(2 pi cycles t + phase)

    so ``motion`` (dy, dx) px is the amplitude vector and the reference (``p = 0``) is the
    equilibrium position.

    Attributes
    ----------
    cycles : float
        Vibration frequency times exposure time (cycles completed during the exposure).
    phase : float
        Phase at shutter opening, radians.
    """

    cycles: float = 1.0
    phase: float = 0.0

    def __post_init__(self) -> None:
        check_finite_number(self.cycles, "SineMotion.cycles")
        check_finite_number(self.phase, "SineMotion.phase")

    def positions(self, motion: Float64Array, t: Float64Array) -> NDArray:
        """Positions (n, 2) px, (dy, dx), at normalised times ``t`` (n,)."""
        s = np.sin(2.0 * math.pi * self.cycles * t + self.phase)
        return s[:, None] * motion[None, :]


@dataclass(frozen=True)
class AcceleratedMotion:
    """Constant acceleration along ``motion`` during the exposure.

    ``p(t) = motion * (s t + (1 - s) t**2)``, t in [0, 1]: the path ends at ``motion``
    (travelled length ``W = |motion|``) and ``s`` is the speed at shutter opening relative
    to the mean speed (0: starts from rest; 1: uniform speed; 2: comes to rest at the end).

    Attributes
    ----------
    start_speed : float
        ``s`` in [0, 2] (outside, the target reverses during the exposure; allowed).
    """

    start_speed: float = 0.0

    def __post_init__(self) -> None:
        check_finite_number(self.start_speed, "AcceleratedMotion.start_speed")

    def positions(self, motion: Float64Array, t: Float64Array) -> NDArray:
        """Positions (n, 2) px, (dy, dx), at normalised times ``t`` (n,)."""
        s = self.start_speed
        frac = s * t + (1.0 - s) * t * t
        return frac[:, None] * motion[None, :]


Trajectory = str | SineMotion | AcceleratedMotion | PathFunction | ArrayLike


def check_motion(motion: Any) -> Float64Array:
    """A motion vector ``(dy, dx)`` px as a finite float64 array of shape (2,)."""
    arr = as_float_array(motion, "motion", expected="expected (dy, dx) in px, e.g. (0.0, 3.5)")
    if arr.shape != (2,):
        raise InputError(f"motion={describe(motion)}: expected (dy, dx) in px, e.g. (0.0, 3.5)")
    if not np.isfinite(arr).all():
        raise InputError(f"motion={describe(motion)}: must be finite (no NaN or infinity)")
    return arr


def check_substeps(substeps: Any) -> int | None:
    """K as an int >= 1, or None for the continuous limit (``None`` or ``"continuous"``)."""
    if substeps is None or (isinstance(substeps, str) and substeps == "continuous"):
        return None
    if isinstance(substeps, bool) or not isinstance(substeps, int | np.integer):
        raise InputError(
            f"substeps={describe(substeps)}: expected an integer >= 1 (the paper uses 100), "
            "or None / 'continuous' for the limit K -> infinity"
        )
    if substeps < 1:
        raise InputError(
            f"substeps={substeps}: must be >= 1 (K + 1 = substeps + 1 sub-frames; the paper "
            "uses 100), or None for the continuous limit"
        )
    return int(substeps)


def _check_path_array(path: Any) -> Float64Array:
    arr = as_float_array(
        path,
        "trajectory",
        expected="a sampled path must be an array of shape (K + 1, 2) with rows (dy, dx) px",
    )
    if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] < 1:
        raise InputError(
            f"trajectory={describe(arr)}: a sampled path must have shape (K + 1, 2) "
            "with rows (dy, dx) px"
        )
    if not np.isfinite(arr).all():
        raise InputError(f"trajectory={describe(arr)}: path positions must be finite")
    return arr


def _call_path(fn: PathFunction, t: Float64Array) -> Float64Array:
    out = np.asarray(fn(t), dtype=np.float64)
    if out.shape != (t.size, 2):
        raise InputError(
            f"trajectory: the callable returned {describe(out)} for t of shape {t.shape}; "
            "it must return positions of shape (len(t), 2) as (dy, dx) px"
        )
    if not np.isfinite(out).all():
        raise InputError("trajectory: the callable returned NaN or infinite positions")
    return out


def classify(trajectory: Any, motion: Any) -> tuple[str, Any, Float64Array | None]:
    """Return (kind, object, motion) with kind in linear|preset|array|callable."""
    if isinstance(trajectory, str):
        name = check_choice(trajectory, "trajectory", _TRAJECTORY_NAMES)
        vec = check_motion(motion)
        if name == "linear":
            return "linear", None, vec
        preset = SineMotion() if name == "sine" else AcceleratedMotion()
        return "preset", preset, vec
    if isinstance(trajectory, SineMotion | AcceleratedMotion):
        return "preset", trajectory, check_motion(motion)
    if callable(trajectory) or isinstance(trajectory, np.ndarray | list | tuple):
        if motion is not None:
            raise InputError(
                f"motion={describe(motion)}: an explicit path (array or callable trajectory) "
                "already gives the positions in px; pass motion=None"
            )
        if callable(trajectory):
            return "callable", trajectory, None
        return "array", _check_path_array(trajectory), None
    raise InputError(
        f"trajectory={describe(trajectory)}: unknown trajectory; use 'linear', 'sine', "
        "'acceleration', a SineMotion/AcceleratedMotion, an array (K + 1, 2) or a callable p(t)"
    )


def _composite_gauss_legendre(segments: int) -> tuple[Float64Array, Float64Array]:
    """Nodes and weights on [0, 1]: ``segments`` equal pieces, each a Gauss-Legendre rule."""
    x, w = np.polynomial.legendre.leggauss(_GL_NODES)
    edges = np.arange(segments, dtype=np.float64)[:, None] / segments
    nodes = edges + 0.5 * (x[None, :] + 1.0) / segments
    weights = np.broadcast_to(0.5 * w[None, :] / segments, nodes.shape)
    return nodes.ravel(), weights.ravel().copy()


def _continuous_nodes(
    fn: Callable[[Float64Array], Float64Array],
) -> tuple[Float64Array, Float64Array]:
    """Quadrature nodes/weights on [0, 1] able to resolve exp(-2 pi i f.p(t)).

    The phase changes by at most pi times the path's total variation (|f| <= 1/2 cycle/px
    per axis). Each segment of a composite 24-node Gauss-Legendre rule (exact for
    polynomials of degree 47) is given at most 8 rad of phase, where the rule reaches
    rounding accuracy for smooth paths.
    """
    fine = np.linspace(0.0, 1.0, 2049)
    p = fn(fine)
    variation = float(np.abs(np.diff(p, axis=0)).sum())
    segments = max(_GL_MIN_SEGMENTS, math.ceil(math.pi * variation / _GL_PHASE_PER_SEGMENT))
    return _composite_gauss_legendre(segments)


def trajectory_positions(
    motion: ArrayLike | None,
    *,
    substeps: int | None = 100,
    trajectory: Trajectory = "linear",
) -> tuple[Float64Array, Float64Array]:
    """Sub-frame positions and weights of a trajectory.

    Parameters
    ----------
    motion : array_like (dy, dx) px, or None
        Motion vector (None for an explicit path).
    substeps : int or None
        K; positions at ``t_k = k / K``, k = 0..K, equal weights ``1 / (K + 1)`` (the
        paper's Algorithm 1). None: composite Gauss-Legendre nodes of the continuous
        average (for ``"linear"`` too; :func:`motion_blur` uses the closed form there).
        Not used by array paths, whose rows are the sub-frames.
    trajectory : see :func:`motion_blur`

    Returns
    -------
    positions : ndarray, shape (n, 2)
        (dy, dx) px.
    weights : ndarray, shape (n,)
        Non-negative, summing to 1.
    """
    kind, obj, vec = classify(trajectory, motion)
    k = check_substeps(substeps)
    if kind == "array":  # the rows are the sub-frames: substeps is not used
        path = obj
        return path, np.full(path.shape[0], 1.0 / path.shape[0])

    def fn(t: Float64Array) -> Float64Array:
        if kind == "linear":
            assert vec is not None
            return t[:, None] * vec[None, :]
        if kind == "preset":
            assert vec is not None
            return np.asarray(obj.positions(vec, t), dtype=np.float64)
        return _call_path(obj, t)

    if k is None:
        t, w = _continuous_nodes(fn)
        return fn(t), w
    t = np.arange(k + 1, dtype=np.float64) / k
    return fn(t), np.full(k + 1, 1.0 / (k + 1))


def is_array_path(trajectory: Any) -> bool:
    """True for an explicit sampled path (an array or a sequence of positions)."""
    return isinstance(trajectory, np.ndarray | list | tuple) and not isinstance(trajectory, str)
