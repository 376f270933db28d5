"""Planning for a strain target: the exposure whose strain uncertainty meets it, and the
VSG / uncertainty trade-off (docs/strain.md, "Planning").

A fitted displacement model (:class:`~dicblur.models.BlurUncertaintyModel`) gives the
noise part ``u_noise(W)`` and the blur-mismatch part ``u_blur(W)`` of the random error. The
plane fit over N x N points turns them into the uncertainty of ``exx`` (eq. 11):

    sigma_exx(W)**2 = (k_noise(N) u_noise(W))**2 + (k_blur(N) u_blur(W))**2,

``k_noise = sqrt(g^T R g)`` with the subset-overlap correlation (eq. 5), ``k_blur`` the
independent-points factor ``sqrt(12) / (step N sqrt(N**2 - 1))`` times
:data:`BLUR_GRADIENT_EXCESS` (the mismatch shifts of neighbouring subsets are nearly
uncorrelated, eq. 12). A model without the split (the power law) takes ``k_noise`` for all
of ``u_e`` (a note says so).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..arrays import Float64Array
from ..errors import InputError
from ..models.model import BlurUncertaintyModel
from ..models.units import parse_quantity
from .covariance import gradient_factor
from .field import vsg as vsg_of
from .field import window_from_vsg

__all__ = ["BLUR_GRADIENT_EXCESS", "StrainPlan", "plan_strain", "strain_sigma_curve"]

#: ``k_blur / k_independent``: the blur-mismatch shifts' strain factor over that of
#: independent points, measured 1.13-1.36 (N = 3..7, W = 2 and 4 px, both components) on
#: the benchmark's 4 px speckle (benchmarks/bench_strain.py, ``blur_factor``); the
#: middle of that range.
BLUR_GRADIENT_EXCESS = 1.25


def factors(window: int, step: float, subset: int) -> tuple[float, float]:
    """``(k_noise, k_blur)`` of a window of N points (1/px): eq. 5 and eq. 12."""
    k_n = gradient_factor(window // 2, step, subset)
    k_b = BLUR_GRADIENT_EXCESS * math.sqrt(12.0) / (step * window * math.sqrt(window**2 - 1))
    return k_n, k_b


def strain_sigma_curve(
    model: BlurUncertaintyModel,
    blur: Float64Array,
    *,
    window: int,
    step: float,
    subset: int,
    sigma: float | None = None,
    which: str | None = None,
) -> tuple[Float64Array, bool]:
    """``sigma_exx`` at the blur lengths ``blur`` (px) for a window of N points, grid step
    and subset in px (eq. 11), and whether the model split noise from blur."""
    pred = model.predict(blur, sigma, model=which)
    k_n, k_b = factors(window, step, subset)
    if pred.u_noise is not None and pred.u_blur is not None:
        return np.hypot(k_n * pred.u_noise, k_b * pred.u_blur), True
    return k_n * np.asarray(pred.u_e), False


@dataclass(frozen=True)
class StrainPlan:
    """The exposure that meets a strain-uncertainty target.

    Attributes
    ----------
    target : float
        Largest acceptable ``sigma_exx`` (strain).
    window, vsg, step, subset
        Plane-fit window (points), its VSG (px), grid step and subset (px).
    velocity_px : float
        Target speed, px/s.
    exposure, blur, sigma_exx : float
        The longest exposure meeting the target (s), its blur W (px) and ``sigma_exx``.
    curve_exposure, curve_sigma_exx : ndarray
        ``sigma_exx`` against the exposure for this VSG.
    tradeoff_vsg, tradeoff_exposure, tradeoff_sigma : ndarray
        Per VSG (px): the longest exposure that meets the target (s; NaN: none) and
        ``sigma_exx`` at the planned exposure.
    notes : tuple of str
    """

    target: float
    window: int
    vsg: float
    step: int
    subset: int
    velocity_px: float
    exposure: float
    blur: float
    sigma_exx: float
    curve_exposure: Float64Array
    curve_sigma_exx: Float64Array
    tradeoff_vsg: Float64Array
    tradeoff_exposure: Float64Array
    tradeoff_sigma: Float64Array
    notes: tuple[str, ...] = field(default_factory=tuple)

    def summary(self) -> str:
        """A few lines for the terminal."""
        lines = [
            f"strain target {self.target * 1e6:.4g} microstrain at VSG {self.vsg:g} px "
            f"({self.window} x {self.window} points, step {self.step} px, subset "
            f"{self.subset} px)",
            f"longest exposure: {self.exposure * 1e3:.4g} ms (W = {self.blur:.3g} px, "
            f"sigma_exx = {self.sigma_exx * 1e6:.4g} microstrain)",
        ]
        for v, t in zip(self.tradeoff_vsg, self.tradeoff_exposure, strict=True):
            tt = "target not met" if not np.isfinite(t) else f"{t * 1e3:.4g} ms"
            lines.append(f"  VSG {v:5g} px: {tt}")
        lines += [f"note: {n}" for n in self.notes]
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (arrays as lists)."""
        out: dict[str, Any] = {}
        for k, v in self.__dict__.items():
            out[k] = v.tolist() if isinstance(v, np.ndarray) else v
        out["notes"] = list(self.notes)
        return out


def _longest(
    model: BlurUncertaintyModel, target: float, w_top: float, **kw: Any
) -> tuple[float, float]:
    """The largest W in [0, w_top] with sigma_exx(W) <= target (bisection on a grid, the
    curve rising with W) and sigma_exx there; (NaN, sigma(0)) when W = 0 misses it."""
    grid = np.linspace(0.0, w_top, 401)
    s, _ = strain_sigma_curve(model, grid, **kw)
    s = np.where(np.isfinite(s), s, np.inf)
    if s[0] > target:
        return math.nan, float(s[0])
    over = np.flatnonzero(s > target)
    if over.size == 0:
        return float(grid[-1]), float(s[-1])
    lo, hi = float(grid[over[0] - 1]), float(grid[over[0]])
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        if strain_sigma_curve(model, np.array([mid]), **kw)[0][0] <= target:
            lo = mid
        else:
            hi = mid
    return lo, float(strain_sigma_curve(model, np.array([lo]), **kw)[0][0])


def plan_strain(
    model: BlurUncertaintyModel,
    *,
    velocity: float | str,
    scale: float | str,
    target: float | str,
    vsg: int | float | str,
    step: int,
    subset: int | None = None,
    sigma: float | None = None,
    which: str | None = None,
    windows: tuple[int, ...] = (3, 5, 7, 9, 11, 13, 15),
) -> StrainPlan:
    """The longest exposure whose predicted ``sigma_exx`` meets ``target``.

    Parameters
    ----------
    model : BlurUncertaintyModel
        Displacement model of the pattern, subset and noise (``dicblur fit``).
    velocity, scale : float or str
        As for :func:`dicblur.plan_exposure` (``"120mm/s"``, ``"0.05mm/px"``).
    target : float or str
        Largest acceptable strain uncertainty: ``"100microstrain"`` or a number (1e-4).
    vsg : int, float or str
        Window in grid points (``5``) or the VSG in px (``"41px"``).
    step : int
        POI grid step, px.
    subset : int, optional
        Subset size, px, when the model records none (else it must match the model's).
    sigma : float, optional
        Noise std, GL (default the model's).
    which : str, optional
        Model kind (``mismatch``, ``static``, ``power_law``).
    windows : tuple of int
        The windows of the VSG trade-off.

    Returns
    -------
    StrainPlan
    """
    if not isinstance(model, BlurUncertaintyModel):
        raise InputError("model: expected a BlurUncertaintyModel (dicblur.fit_blur_model)")
    if model.subset is None and subset is None:
        raise InputError("subset: the model records no subset size; give it (px), e.g. 21")
    if model.subset is not None and subset is not None and int(subset) != int(model.subset):
        raise InputError(
            f"subset={subset!r}: the model was fitted with subset {model.subset} px; "
            "leave it out or use that model's subset"
        )
    subset = int(model.subset if model.subset is not None else subset)  # type: ignore[arg-type]
    if subset < 5 or subset % 2 == 0:
        raise InputError(f"subset={subset!r}: an odd subset size >= 5 px, e.g. 21")
    if not (isinstance(step, int) and step > 0):
        raise InputError(f"step={step!r}: the POI grid step must be an integer > 0 px")
    tgt = parse_quantity(target, "strain", name="target")
    if not tgt > 0:
        raise InputError(f"target={target!r}: must be > 0, e.g. '100microstrain'")
    window = window_from_vsg(vsg, step=step, subset=subset, name="vsg")
    sc = parse_quantity(scale, "scale", name="scale")
    if sc <= 0:
        raise InputError(f"scale={scale!r}: must be > 0 (mm/px), e.g. '0.05mm/px'")
    v = abs(parse_quantity(velocity, "velocity", name="velocity", scale=sc))
    if v == 0:
        raise InputError(f"velocity={velocity!r}: zero speed means no blur; any exposure works")
    v_px = v / sc
    assert model.domain is not None
    w_top = model.domain.breakdown_blur or 2.0 * float(max(model.domain.blur_max, 1.0))
    notes: list[str] = []
    kw: dict[str, Any] = {"step": float(step), "subset": subset, "sigma": sigma, "which": which}
    w_best, s_best = _longest(model, tgt, w_top, window=window, **kw)
    _, split = strain_sigma_curve(model, np.array([0.0]), window=window, **kw)
    if not split:
        notes.append("the model does not split noise from blur: k_noise taken for all of u_e")
    if not math.isfinite(w_best):
        raise InputError(
            f"target={target!r}: below the static strain uncertainty {s_best * 1e6:.3g} "
            f"microstrain at VSG {vsg_of(window, step, subset):g} px; raise the target or "
            "the VSG (--vsg)"
        )
    if w_best >= w_top * (1 - 1e-9):
        notes.append(f"the target holds up to W = {w_top:g} px, the end of the model's range")
    if w_best > model.domain.blur_max:
        notes.append(
            f"W = {w_best:.3g} px is beyond the fitted blur range (up to "
            f"{model.domain.blur_max:g} px): extrapolated"
        )
    t_best = w_best / v_px
    t = np.linspace(0.0, 2.0 * t_best, 200)
    curve, _ = strain_sigma_curve(model, np.minimum(t * v_px, w_top), window=window, **kw)
    vs, ts, ss = [], [], []
    for n in windows:
        wn, _ = _longest(model, tgt, w_top, window=n, **kw)
        vs.append(vsg_of(n, step, subset))
        ts.append(wn / v_px if math.isfinite(wn) else math.nan)
        ss.append(float(strain_sigma_curve(model, np.array([w_best]), window=n, **kw)[0][0]))
    return StrainPlan(
        target=tgt,
        window=window,
        vsg=vsg_of(window, step, subset),
        step=step,
        subset=subset,
        velocity_px=v_px,
        exposure=t_best,
        blur=w_best,
        sigma_exx=s_best,
        curve_exposure=t,
        curve_sigma_exx=curve,
        tradeoff_vsg=np.asarray(vs),
        tradeoff_exposure=np.asarray(ts),
        tradeoff_sigma=np.asarray(ss),
        notes=tuple(notes),
    )
