"""dicblur: displacement uncertainty of 2-D digital image correlation under motion blur.

Implements and extends Lavatelli & Zappa, "A Displacement Uncertainty Model for 2-D DIC
Measurement Under Motion Blur Conditions", IEEE Trans. Instrum. Meas. 66(3), 2017,
doi:10.1109/TIM.2016.2644898.

Conventions: images are 2-D arrays indexed (row, col); x runs along columns, y along rows;
displacements and lengths in px, grey levels (GL) for intensities, seconds for time.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from ._version import __version__

# Public name -> submodule that defines it. Nothing below the package root is imported
# until a name is first used (PEP 562), so ``import dicblur`` and ``import dicblur.dic``
# stay cheap and the CLI starts fast.
_SUBMODULES: dict[str, tuple[str, ...]] = {
    "blur": (
        "AcceleratedMotion",
        "SineMotion",
        "blur_length",
        "blur_transfer",
        "motion_blur",
        "render_blurred",
        "trajectory_positions",
        "valid_region",
    ),
    "camera": ("Camera", "add_gaussian_noise"),
    "campaign": (
        "CampaignSpec",
        "campaign_status",
        "export_csv",
        "load_spec",
        "open_results",
        "run_campaign",
    ),
    "design": (
        "DesignResult",
        "PatternFamily",
        "design_pattern",
        "design_problem",
        "export_pattern",
    ),
    "dic": ("Correlator", "DICResult", "MatcherSettings", "PointStatus", "correlate"),
    "errors": (
        "ConfigError",
        "DicblurError",
        "FitError",
        "ImageReadError",
        "InputError",
        "StoreError",
    ),
    "io": ("file_sha256", "load_image", "save_image"),
    "metrics": (
        "PatternMetrics",
        "estimate_noise",
        "gradient_variance",
        "image_gradients",
        "match_score_sigma",
        "michelson_contrast",
        "mig",
        "pan_sigma",
        "pattern_metrics",
        "rms_contrast",
        "speckle_size",
        "sssig",
        "subset_centres",
    ),
    "models": (
        "BlurMismatchCurve",
        "BlurSensitivity",
        "BlurUncertaintyModel",
        "ExposurePlan",
        "PatternPrediction",
        "PoissonGaussianCamera",
        "blur_mismatch_curve",
        "blur_sensitivity",
        "compare_models",
        "fit_blur_model",
        "gradient_weighted_level",
        "model_from_pattern",
        "plan_exposure",
        "predict_from_pattern",
    ),
    "patterns": ("PatternSettings", "gaussian_mask", "paper_pattern4", "speckle_pattern"),
    "pulse": ("PulseTrain",),
    "pulse.study": ("PulseStudy", "run_pulse_study"),
    "strain": ("StrainField", "StrainStatus", "strain"),
    "track": ("track",),
}
_LAZY: dict[str, str] = {name: mod for mod, names in _SUBMODULES.items() for name in names}
# Submodules reachable as attributes (``dicblur.campaign.run_campaign``) after a bare
# ``import dicblur``, as when the root imported them all.
_MODULES = frozenset(
    {
        "blur",
        "camera",
        "campaign",
        "cli",
        "design",
        "dic",
        "errors",
        "io",
        "metrics",
        "models",
        "patterns",
        "pulse",
        "report",
        "sequence",
    }
)

if TYPE_CHECKING:  # pragma: no cover - for type checkers and IDEs only
    from .blur import (
        AcceleratedMotion,
        SineMotion,
        blur_length,
        blur_transfer,
        motion_blur,
        render_blurred,
        trajectory_positions,
        valid_region,
    )
    from .camera import Camera, add_gaussian_noise
    from .campaign import (
        CampaignSpec,
        campaign_status,
        export_csv,
        load_spec,
        open_results,
        run_campaign,
    )
    from .design import (
        DesignResult,
        PatternFamily,
        design_pattern,
        design_problem,
        export_pattern,
    )
    from .dic import Correlator, DICResult, MatcherSettings, PointStatus, correlate
    from .errors import (
        ConfigError,
        DicblurError,
        FitError,
        ImageReadError,
        InputError,
        StoreError,
    )
    from .io import file_sha256, load_image, save_image
    from .metrics import (
        PatternMetrics,
        estimate_noise,
        gradient_variance,
        image_gradients,
        match_score_sigma,
        michelson_contrast,
        mig,
        pan_sigma,
        pattern_metrics,
        rms_contrast,
        speckle_size,
        sssig,
        subset_centres,
    )
    from .models import (
        BlurMismatchCurve,
        BlurSensitivity,
        BlurUncertaintyModel,
        ExposurePlan,
        PatternPrediction,
        PoissonGaussianCamera,
        blur_mismatch_curve,
        blur_sensitivity,
        compare_models,
        fit_blur_model,
        gradient_weighted_level,
        model_from_pattern,
        plan_exposure,
        predict_from_pattern,
    )
    from .patterns import PatternSettings, gaussian_mask, paper_pattern4, speckle_pattern
    from .pulse import PulseTrain
    from .pulse.study import PulseStudy, run_pulse_study
    from .strain import StrainField, StrainStatus, strain


def __getattr__(name: str) -> Any:
    if name in _MODULES:
        return importlib.import_module(f".{name}", __name__)
    mod = _LAZY.get(name)
    if mod is None:
        raise AttributeError(f"module 'dicblur' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{mod}", __name__), name)
    globals()[name] = value  # later look-ups skip __getattr__
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__) | _MODULES)


__all__ = [
    "AcceleratedMotion",
    "BlurMismatchCurve",
    "BlurSensitivity",
    "BlurUncertaintyModel",
    "Camera",
    "CampaignSpec",
    "ConfigError",
    "Correlator",
    "DICResult",
    "DesignResult",
    "DicblurError",
    "ExposurePlan",
    "FitError",
    "ImageReadError",
    "InputError",
    "MatcherSettings",
    "PatternFamily",
    "PatternMetrics",
    "PatternPrediction",
    "PatternSettings",
    "PointStatus",
    "PoissonGaussianCamera",
    "PulseStudy",
    "PulseTrain",
    "SineMotion",
    "StoreError",
    "StrainField",
    "StrainStatus",
    "__version__",
    "add_gaussian_noise",
    "blur_length",
    "blur_mismatch_curve",
    "blur_sensitivity",
    "blur_transfer",
    "campaign_status",
    "compare_models",
    "correlate",
    "design_pattern",
    "design_problem",
    "estimate_noise",
    "export_csv",
    "export_pattern",
    "file_sha256",
    "fit_blur_model",
    "gaussian_mask",
    "gradient_variance",
    "gradient_weighted_level",
    "image_gradients",
    "load_image",
    "load_spec",
    "match_score_sigma",
    "michelson_contrast",
    "mig",
    "model_from_pattern",
    "motion_blur",
    "open_results",
    "pan_sigma",
    "paper_pattern4",
    "pattern_metrics",
    "plan_exposure",
    "predict_from_pattern",
    "render_blurred",
    "rms_contrast",
    "run_campaign",
    "run_pulse_study",
    "save_image",
    "speckle_pattern",
    "speckle_size",
    "sssig",
    "strain",
    "subset_centres",
    "track",
    "trajectory_positions",
    "valid_region",
]
