"""Uncertainty models of DIC under motion blur (Lavatelli & Zappa 2017, Section VI, and
beyond): static models, the power law, SSSIG decay, the noise + blur-mismatch model, the
fitted :class:`BlurUncertaintyModel` and exposure planning. See docs/models.md.
"""

from __future__ import annotations

from ._result import FitResult, ParameterEstimate
from .compare import PlanComparison, check_same_calibration, compare_plans
from .compensated import model_from_compensated, predict_compensated
from .decay import (
    combined_model,
    combined_pan_model,
    fit_sssig_decay,
    mbrf,
    sssig_decay,
    taylor_model,
)
from .fit import ModelComparison, check_measurements, compare_models, fit_blur_model
from .mismatch import fit_mismatch, mismatch_model, mismatch_terms
from .mismatch_prediction import (
    BlurMismatchCurve,
    BlurSensitivity,
    blur_mismatch_curve,
    blur_sensitivity,
)
from .model import BlurUncertaintyModel, Prediction
from .pattern import PatternPrediction, model_from_pattern, predict_from_pattern, static_terms
from .plan import (
    RULE_OF_THUMB_BLUR,
    ExposurePlan,
    PoissonGaussianCamera,
    gradient_weighted_level,
    plan_exposure,
)
from .powerlaw import edge_driven_range, fit_power_law, power_law
from .scaled import StaticTerms, fit_static_scales, with_static_model
from .static import match_score_uncertainty, pan_uncertainty
from .units import parse_quantity

__all__ = [
    "RULE_OF_THUMB_BLUR",
    "BlurMismatchCurve",
    "BlurSensitivity",
    "BlurUncertaintyModel",
    "ExposurePlan",
    "FitResult",
    "ModelComparison",
    "ParameterEstimate",
    "PatternPrediction",
    "PlanComparison",
    "PoissonGaussianCamera",
    "Prediction",
    "StaticTerms",
    "blur_mismatch_curve",
    "blur_sensitivity",
    "check_measurements",
    "check_same_calibration",
    "combined_model",
    "combined_pan_model",
    "compare_models",
    "compare_plans",
    "edge_driven_range",
    "fit_blur_model",
    "fit_mismatch",
    "fit_power_law",
    "fit_sssig_decay",
    "fit_static_scales",
    "gradient_weighted_level",
    "match_score_uncertainty",
    "mbrf",
    "mismatch_model",
    "mismatch_terms",
    "model_from_compensated",
    "model_from_pattern",
    "pan_uncertainty",
    "parse_quantity",
    "plan_exposure",
    "power_law",
    "predict_compensated",
    "predict_from_pattern",
    "sssig_decay",
    "static_terms",
    "taylor_model",
    "with_static_model",
]
