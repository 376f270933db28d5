"""The 1-D periodic-pulse model of the paper's Section V, its Monte Carlo, and a verdict.

Lavatelli & Zappa, IEEE TIM 66(3), 2017, doi:10.1109/TIM.2016.2644898, Section V.
See ``docs/pulse.md`` (model, methods) and ``docs/pulse-verdict.md`` (results).
"""

from __future__ import annotations

from .correlation import (
    chi2_continuous,
    chi2_regime_a,
    chi2_sampled,
    gradient_sums,
    min_chi2,
    predict_first_principles,
    predict_interpolated_noise,
    predict_paper_linear,
)
from .montecarlo import PAPER_TRAIN, PAPER_WIDTHS, estimate_shift, simulate
from .signal import (
    REGIMES,
    PulseMetrics,
    PulseTrain,
    closed_form_metrics,
    edge_length,
    numeric_metrics,
    pixel_metrics,
    regime,
    spectral_derivative,
)

__all__ = [
    "PAPER_TRAIN",
    "PAPER_WIDTHS",
    "REGIMES",
    "PulseMetrics",
    "PulseTrain",
    "chi2_continuous",
    "chi2_regime_a",
    "chi2_sampled",
    "closed_form_metrics",
    "edge_length",
    "estimate_shift",
    "gradient_sums",
    "min_chi2",
    "numeric_metrics",
    "pixel_metrics",
    "predict_first_principles",
    "predict_interpolated_noise",
    "predict_paper_linear",
    "regime",
    "simulate",
    "spectral_derivative",
]
