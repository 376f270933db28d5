"""Typed records passed between the stages of ``dicblur reproduce``.

Each stage of :func:`dicblur.report.reproduce.reproduce` returns one of these; the claims
(:func:`dicblur.report.claims.evaluate_claims`) and the page
(:func:`dicblur.report.write.write_report`) read :class:`StudyData`, which bundles them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..arrays import BoolArray

if TYPE_CHECKING:  # pragma: no cover - types only
    from ..pulse.study import PulseStudy
    from .study import StudyPattern

__all__ = ["Campaigns", "ReproduceSettings", "StudyData", "StudyFits"]


@dataclass(frozen=True)
class ReproduceSettings:
    """Settings of a reproduce run.

    Attributes
    ----------
    out : Path
        Output folder.
    quick : bool
        Coarser W grid (0..10 px, step 0.5 instead of 0.1), POIs every 20 px instead of
        10, a smaller family and fewer 1-D trials: same figures and tables.
    pattern1, pattern2 : Path or None
        DIC Challenge Sample 13 and Sample 3 images (central crop); None: stand-ins.
    size : int
        Side of the square study images (px).
    subset : int
        Subset size (px).
    main_noise : float
        Noise std (GL) of the paper-like fits.
    noise_levels : tuple of float
        Noise levels of the campaign (GL, per image).
    seed : int
        Base seed of everything random.
    blur_step_px, family, trials : optional
        Override the mode's W step (px), the family's speckle sizes (px) and the 1-D
        Monte Carlo trials.
    pulse_dependence : bool
        Run the 1-D study's dependence on the choices the paper leaves open (signal
        length, shifted signal, interpolation).
    workers, scheduler, serial
        Campaign execution (see :func:`dicblur.campaign.run_campaign`).
    command : str
        The command line, recorded in the outputs.
    """

    out: Path
    quick: bool = False
    pattern1: Path | None = None
    pattern2: Path | None = None
    size: int = 512
    subset: int = 31
    main_noise: float = 2.0
    noise_levels: tuple[float, ...] = (0.5, 2.0, 4.0)
    seed: int = 2017
    blur_step_px: float | None = None
    family: tuple[float, ...] | None = None
    trials: int | None = None
    pulse_dependence: bool = True
    workers: int | None = None
    scheduler: str | None = None
    serial: bool = False
    command: str = ""

    @property
    def blur_step(self) -> float:
        if self.blur_step_px is not None:
            return self.blur_step_px
        return 0.5 if self.quick else 0.1

    @property
    def poi_step(self) -> int:
        return 20 if self.quick else 10

    @property
    def family_sizes(self) -> tuple[float, ...]:
        if self.family is not None:
            return self.family
        return (
            (2.0, 3.0, 4.0, 6.0, 9.0) if self.quick else (2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0)
        )

    @property
    def pulse_trials(self) -> int:
        if self.trials is not None:
            return self.trials
        return 2000 if self.quick else 10_000


@dataclass(frozen=True)
class Campaigns:
    """The campaigns of a reproduce run (stage 2 and 3).

    Attributes
    ----------
    study : xarray.Dataset
        The Section III / VI campaign: the study patterns, every noise level, the W grid.
    family : xarray.Dataset
        The generated family of Fig. 11 (main noise level).
    family_specs : tuple of dict
        The family's ``[[pattern]]`` tables (name, speckle size, ...).
    compensation : dict
        Pattern #2 with the plain, the blur-compensated (``given``) and the deblurring
        matcher, and its static bound: arrays over ``blur`` (px), plus its key and label.
    runs : dict
        Tasks run / skipped per campaign (``study``, ``family``, ``study_given``,
        ``study_deblur``).
    """

    study: Any
    family: Any
    family_specs: tuple[dict[str, Any], ...]
    compensation: dict[str, Any]
    runs: dict[str, dict[str, int]]


@dataclass(frozen=True)
class StudyFits:
    """The fits of a reproduce run (stage 5).

    Attributes
    ----------
    fits : dict
        Per pattern key: the JSON-ready numbers of its fits (eq. 17-19, mismatch model,
        static prediction errors).
    models : dict
        Per pattern key: ``(paper, full)``, the :class:`~dicblur.models.BlurUncertaintyModel`
        fitted at the main noise level and at every level.
    valid : dict
        Per pattern key: bool array over the W grid, True where >= 90 % of POIs converged.
    family : list of dict
        One row per family pattern (MIG_0, u_ref, alpha, beta, MBRF, u_e).
    """

    fits: dict[str, dict[str, Any]]
    models: dict[str, tuple[Any, Any]]
    valid: dict[str, BoolArray]
    family: list[dict[str, Any]]


@dataclass(frozen=True)
class StudyData:
    """Everything the claims and the report read: the settings and each stage's result.

    Attributes
    ----------
    settings : ReproduceSettings
    patterns : list of StudyPattern
        The four study patterns, in order #1..#4.
    static : dict
        Per pattern key: label, source, sha256, image metrics, the static ``c`` and the
        static prediction of u_e per noise level.
    campaigns : Campaigns
    fits : StudyFits
    pulse : PulseStudy
        The 1-D analysis of Section V.
    """

    settings: ReproduceSettings
    patterns: list[StudyPattern]
    static: dict[str, dict[str, Any]]
    campaigns: Campaigns
    fits: StudyFits
    pulse: PulseStudy
