"""A plan with blur compensation set against the plan without it (issue 18).

Two models of the same calibration (pattern, subset, shape function), one fitted on the
plain matcher and one on the blur-compensated matcher (``dicblur calibrate
--compensation given``), are planned with the same motion, optics and camera; the gain at
the optimum is the ratio of the two answers. With a camera the compensated matcher, which
has no blur-mismatch term, can expose longer (more light, less noise) before the blur costs
more than the light gains; with fixed noise and a target it keeps the target up to a
longer exposure.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ..errors import InputError
from .domain import compensation_label
from .model import BlurUncertaintyModel
from .plan import ExposurePlan, format_time, plan_exposure

__all__ = ["PlanComparison", "check_same_calibration", "compare_plans"]


@dataclass(frozen=True)
class PlanComparison:
    """Result of :func:`compare_plans`.

    Attributes
    ----------
    baseline : ExposurePlan
        The plan of the baseline model (the plain matcher when one of the two is plain).
    compensated : ExposurePlan
        The plan of the other model (blur-compensated).
    baseline_compensation, compensation : str
        Their matcher modes (``"none"``, ``"given"``, ``"estimate"``, ``"deblur"``).
    u_e_ratio : float
        ``compensated.u_e / baseline.u_e`` at the planned exposures (< 1: compensation
        lowers the error).
    exposure_ratio : float
        ``compensated.exposure / baseline.exposure`` (> 1: it may expose longer).
    sentence : str
        Both ratios in one sentence.
    """

    baseline: ExposurePlan
    compensated: ExposurePlan
    baseline_compensation: str
    compensation: str
    u_e_ratio: float
    exposure_ratio: float
    sentence: str

    def summary(self) -> str:
        """Both plans, each under its matcher, then the sentence."""
        return "\n".join(
            [
                f"{compensation_label(self.baseline_compensation)}:",
                self.baseline.summary(),
                "",
                f"{compensation_label(self.compensation)}:",
                self.compensated.summary(),
                "",
                self.sentence,
            ]
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "baseline": self.baseline.to_dict(),
            "compensated": self.compensated.to_dict(),
            "baseline_compensation": self.baseline_compensation,
            "compensation": self.compensation,
            "u_e_ratio": self.u_e_ratio,
            "exposure_ratio": self.exposure_ratio,
            "sentence": self.sentence,
        }


def check_same_calibration(
    model: BlurUncertaintyModel,
    other: BlurUncertaintyModel,
    *,
    names: tuple[str, str] = ("model", "other"),
) -> None:
    """Refuse two models that were not calibrated on the same pattern, subset and shape.

    A setting unknown in one of the two (None) is not compared.

    Raises
    ------
    InputError
        Naming the setting and both values.
    """
    a, b = model.domain, other.domain
    assert a is not None and b is not None
    for key in ("pattern_sha256", "pattern", "subset", "shape"):
        va, vb = getattr(a, key), getattr(b, key)
        if va is not None and vb is not None and va != vb:
            what = "pattern hash" if key == "pattern_sha256" else key
            raise InputError(
                f"{names[1]}: calibrated with {what} {vb!r}, {names[0]} with {va!r}; "
                "compare models of the same pattern, subset and shape (calibrate both "
                "with the same settings, one with --compensation given)"
            )


def compare_plans(
    model: BlurUncertaintyModel,
    other: BlurUncertaintyModel,
    *,
    names: tuple[str, str] = ("model", "other"),
    **plan_kwargs: Any,
) -> PlanComparison:
    """Plan the exposure with two matcher modes and state the gain of compensation.

    Parameters
    ----------
    model, other : BlurUncertaintyModel
        Models of the same calibration with different matcher modes
        (``model.compensation``). The plain one (``"none"``) is the baseline, whichever
        argument it is; with neither plain, ``model`` is.
    names : (str, str)
        What to call the two models in messages (the CLI: ``("MODEL", "--compare")``).
    **plan_kwargs
        The keywords of :func:`plan_exposure` (``velocity``, ``scale``, ``target``,
        ``camera``, ``sigma``, ``which``, ...), the same for both plans.

    Returns
    -------
    PlanComparison

    Raises
    ------
    InputError
        Both models have the same matcher mode, or they were calibrated on different
        patterns, subsets or shape functions.
    """
    for m, name in zip((model, other), names, strict=True):
        if not isinstance(m, BlurUncertaintyModel):
            raise InputError(f"{name}: expected a BlurUncertaintyModel (dicblur fit / calibrate)")
    if model.compensation == other.compensation:
        raise InputError(
            f"{names[1]}: both models use the {model.matcher}; set a model calibrated "
            "with blur compensation (dicblur calibrate --compensation given) against one "
            "calibrated without it"
        )
    check_same_calibration(model, other, names=names)
    swap = model.compensation != "none" and other.compensation == "none"
    base, comp = (other, model) if swap else (model, other)
    p_base = plan_exposure(base, **plan_kwargs)
    p_comp = plan_exposure(comp, **plan_kwargs)
    u_ratio = p_comp.u_e / p_base.u_e
    t_ratio = p_comp.exposure / p_base.exposure
    sentence = _sentence(p_base, p_comp, comp.matcher, u_ratio, t_ratio)
    return PlanComparison(
        baseline=p_base,
        compensated=p_comp,
        baseline_compensation=base.compensation,
        compensation=comp.compensation,
        u_e_ratio=float(u_ratio),
        exposure_ratio=float(t_ratio),
        sentence=sentence,
    )


def _times(x: float) -> str:
    return f"{x:.3g}x"


def _sentence(
    base: ExposurePlan, comp: ExposurePlan, label: str, u_ratio: float, t_ratio: float
) -> str:
    exposures = f"{format_time(comp.exposure)} against {format_time(base.exposure)}"
    errors = f"{comp.u_e:.3g} px against {base.u_e:.3g} px"
    if abs(u_ratio - 1.0) < 1e-6:
        u_words = f"u_e is {comp.u_e:.3g} px in both"
    elif u_ratio < 1:
        u_words = f"u_e {_times(1 / u_ratio)} lower ({errors})"
    else:
        u_words = f"u_e {_times(u_ratio)} higher ({errors})"
    if comp.optimal:
        return (
            f"With the {label} the optimum exposure is {_times(t_ratio)} as long "
            f"({exposures}) and {u_words}."
        )
    tail = "." if abs(u_ratio - 1.0) < 1e-6 else f"; there {u_words}."
    return (
        f"With the {label} the target {comp.target:g} px holds up to {_times(t_ratio)} "
        f"the exposure ({exposures}){tail}"
    )
