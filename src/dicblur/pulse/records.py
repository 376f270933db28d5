"""Result records of the pulse study, shared by :mod:`.study` (which fills them) and
:mod:`.verdict` (which reads them); their own module so neither imports the other."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

__all__ = ["DependenceRow", "LogLogFit"]


@dataclass(frozen=True)
class LogLogFit:
    """Weighted least-squares fit of ``log u = log c + slope log w`` over one segment.

    ``slope_ci`` is a 95% interval from the standard errors of ``log u`` (from the Monte
    Carlo CI), inflated by sqrt(reduced chi^2) when the scatter exceeds them.
    ``slopes_pred`` holds the slope of each prediction over the same widths and
    ``ratio_pred`` the geometric-mean ratio MC / prediction.
    """

    segment: str
    regime: str
    w_min: float
    w_max: float
    n: int
    slope: float
    slope_ci: tuple[float, float]
    prefactor: float
    slopes_pred: dict[str, float] = field(default_factory=dict)
    ratio_pred: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {
            "segment": self.segment,
            "regime": self.regime,
            "w_min": self.w_min,
            "w_max": self.w_max,
            "n": self.n,
            "slope": self.slope,
            "slope_ci_low": self.slope_ci[0],
            "slope_ci_high": self.slope_ci[1],
            "prefactor": self.prefactor,
        }
        d.update({f"slope_{k}": v for k, v in self.slopes_pred.items()})
        d.update({f"ratio_{k}": v for k, v in self.ratio_pred.items()})
        return d


@dataclass(frozen=True)
class DependenceRow:
    """One Monte Carlo variant of the choices the paper leaves open."""

    name: str
    interpolation: str
    shifted: str
    n_periods: int
    dp: float
    du: float
    x0: float
    slope_a: float
    slope_a_ci: tuple[float, float]
    u_e_w1: float
    u_e_w5: float
    ratio_first_principles_w5: float
    ratio_derived_pixel_w5: float
    knee: float
    knee_predicted: float

    def to_dict(self) -> dict[str, Any]:
        d = dict(self.__dict__)
        d["slope_a_ci_low"], d["slope_a_ci_high"] = d.pop("slope_a_ci")
        return d
