"""``dicblur track``: a high-speed recording in, displacements with a per-point, per-frame
uncertainty (noise and motion blur) out (issue 17, docs/track.md).

Stages, one module each: :mod:`.core` (:func:`track`, the entry point), :mod:`.options`
(rate, frame range, automatic tolerance), :mod:`.frames` (the frame loop's steps),
:mod:`.flags` (per-frame gross-error flags), :mod:`.result` (post-processing and the Dataset),
:mod:`.kinematics` (motion during each exposure from the track), :mod:`.uncertainty`
(per-point blur response table; its nodes in :mod:`.directions`, the skewed exposure's
bias in :mod:`.skew`), :mod:`.noise` (noise estimate), :mod:`.median` (normalised median test),
:mod:`.advice` (the exposure that would have been best).

``dicblur.track(...)`` calls :func:`track`; this package's module object is callable too,
so the name works whether it resolves to the function or to the package.
"""

from __future__ import annotations

from ..callable_module import make_callable
from .advice import ExposureAdvice, advise_exposure
from .core import TrackInterrupted, parse_frame_range, parse_rate, track
from .kinematics import blur_weights, exposure_motion
from .median import normalized_median_test, normalized_residual
from .noise import NoiseEstimate, estimate_static_noise
from .uncertainty import BlurTable, build_blur_table

__all__ = [
    "BlurTable",
    "ExposureAdvice",
    "NoiseEstimate",
    "TrackInterrupted",
    "advise_exposure",
    "blur_weights",
    "build_blur_table",
    "estimate_static_noise",
    "exposure_motion",
    "normalized_median_test",
    "normalized_residual",
    "parse_frame_range",
    "parse_rate",
    "track",
]

make_callable(__name__, "track")
