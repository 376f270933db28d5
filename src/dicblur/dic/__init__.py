"""Subset digital image correlation (issue 4): FFT-CC initial guess, IC-GN with the ZNSSD
criterion, prefiltered B-spline interpolation, per-point status and predicted sigma.

Stages, one module each (OpenCorr/DICe style): :mod:`.interpolation`, :mod:`.initial`,
:mod:`.icgn` (+ compiled :mod:`.kernels`), :mod:`.result`, :mod:`.status`,
:mod:`.correlator`.
"""

from __future__ import annotations

from .compensation import blur_reference, deblur_wiener
from .correlator import Correlator, PreparedImage, Refined, correlate
from .outliers import neighbour_median, normalized_median_test
from .result import DICResult
from .settings import MatcherSettings
from .status import PointStatus

__all__ = [
    "Correlator",
    "DICResult",
    "MatcherSettings",
    "PointStatus",
    "PreparedImage",
    "Refined",
    "blur_reference",
    "correlate",
    "deblur_wiener",
    "neighbour_median",
    "normalized_median_test",
]
