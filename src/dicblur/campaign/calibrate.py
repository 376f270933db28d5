"""Calibration: the paper's blur sweep on one pattern, then the uncertainty-model fits.

This is what a user with their own speckle pattern runs (``dicblur calibrate``): W from
0.1 to 10 px in 0.1 px steps (Lavatelli & Zappa 2017, Section VI), one noise level (or
several: two levels that bracket the noise of the planned exposure separate the mismatch
model's floor and cross term and keep a camera plan inside the model's validity domain),
one subset size, one motion direction; the campaign's dataset is then fitted with
:func:`dicblur.models.fit_blur_model` (SSSIG decay, eq. 18; power law, eq. 17; noise +
blur-mismatch model), the static prediction of the pattern is tabulated and scaled to it
(:func:`dicblur.models.with_static_model`, the model's default: the static kind), and the
model is written; the report layer draws the figures.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..timing import lap_timer
from .spec import CampaignSpec, parse_spec

__all__ = ["CalibrationResult", "calibrate", "calibration_spec"]

PAPER_BLUR = {"start": 0.1, "stop": 10.0, "step": 0.1}
GENERATORS = ("paper4", "speckle")


@dataclass(frozen=True)
class CalibrationResult:
    """Outputs of :func:`calibrate`.

    Attributes
    ----------
    model : BlurUncertaintyModel
        The fitted model (also written to ``model_path``).
    model_path, results_path, csv_path : pathlib.Path
        ``model.json``, the campaign store (Zarr) and its CSV export.
    sssig_r2 : float
        R^2 of the SSSIG decay fit (eq. 18), as the paper reports it.
    spec : CampaignSpec
    curves : xarray.Dataset
        The campaign's variables against ``blur`` (mean over repetitions) that the model
        was fitted to; :func:`dicblur.report.plots.calibration_figures` draws them.
    figures : tuple of pathlib.Path
        Figures written for this calibration (empty from :func:`calibrate`, which does not
        draw; the CLI adds the three of ``calibration_figures``).
    timings : dict of str to float
        Wall time of each phase, s: ``campaign`` (the DIC sweep), ``export`` (the CSV and
        reading the store back), ``static_terms`` (the static prediction's table),
        ``fit`` (the model fits) and ``write`` (``model.json``);
        ``benchmarks/bench_budgets.py`` prints them.

    An interrupted campaign (Ctrl-C) raises no error: :func:`calibrate` returns ``None``
    and rerunning it resumes the store.
    """

    model: Any
    model_path: Path
    results_path: Path
    csv_path: Path
    sssig_r2: float
    spec: CampaignSpec
    curves: Any = None
    figures: tuple[Path, ...] = ()
    timings: dict[str, float] = field(default_factory=dict)


def calibration_spec(
    image: str | os.PathLike[str],
    *,
    noise: float | Sequence[float] = 2.0,
    subset: int = 31,
    angle: float = 0.0,
    step: int = 10,
    noise_model: str = "per-exposure",
    shape: str = "translation",
    size: tuple[int, int] = (512, 512),
    seed: int = 1,
    blur: Any = None,
    repetitions: int = 1,
    compensation: str = "none",
) -> CampaignSpec:
    """The campaign spec of a calibration sweep.

    Parameters
    ----------
    image : path or {"paper4", "speckle"}
        An image file, or a generator name (pattern of ``size`` px, seeded by ``seed``).
    noise : float or sequence of float
        Noise std, grey levels (per image for ``"per-exposure"``); several levels are
        swept and fitted together.
    subset, step : int
        DIC subset size and grid step, px.
    angle : float
        Motion direction, degrees from +x (columns) towards +y (rows).
    noise_model : {"per-exposure", "per-subframe", "poisson-gaussian"}
        Default ``"per-exposure"``: ``noise`` is the camera's noise per image (what
        ``dicblur noise`` measures). The paper adds it per sub-frame instead.
    blur : list or dict, optional
        W grid (px); default the paper's 0.1..10 px in 0.1 px steps.
    compensation : {"none", "given", "estimate", "deblur"}
        Matcher mode of the sweep (campaign key ``dic.compensation``): the plain matcher
        (default), the blur-compensated one with the known motion or with the blur
        estimated, or the deblur baseline. The fitted model records it.

    Notes
    -----
    Image files are blurred with ``boundary = "reflect"`` (no wrap-around; POIs limited to
    the region that saw only image content at the largest W); generated patterns are
    periodic and use ``"periodic"``, exactly the paper.
    """
    from ..models.domain import COMPENSATIONS

    if compensation not in COMPENSATIONS:
        raise InputError(
            f"compensation={compensation!r}: choose one of " + ", ".join(map(repr, COMPENSATIONS))
        )
    name = str(image)
    is_file = Path(name).is_file()
    if is_file:
        pattern: dict[str, Any] = {
            "name": Path(name).stem or "pattern",
            "path": str(Path(name).resolve()),
        }
        boundary = "reflect"
    elif name in GENERATORS:
        pattern = {"name": name, "generator": name, "shape": list(size), "seed": seed}
        boundary = "periodic"
    else:
        raise InputError(
            f"image={name!r}: no such file; give an image file or a generator "
            f"name ({', '.join(GENERATORS)})"
        )
    return parse_spec(
        {
            "campaign": {
                "name": f"calibrate-{pattern['name']}",
                "seed": seed,
                "repetitions": repetitions,
            },
            "pattern": [pattern],
            "blur": {
                "lengths": PAPER_BLUR if blur is None else blur,
                "angles": [angle],
                "boundary": boundary,
            },
            "noise": {"model": noise_model, "levels": _levels(noise)},
            "dic": {
                "subsets": [subset],
                "step": step,
                "shape": shape,
                # only when on: a plain calibration's spec (and hash) is what it was
                **({} if compensation == "none" else {"compensation": compensation}),
            },
        }
    )


def _levels(noise: float | Sequence[float]) -> list[float]:
    if isinstance(noise, int | float):
        return [float(noise)]
    levels = [float(v) for v in noise]
    if not levels:
        raise InputError("noise: give at least one noise level (GL), e.g. 2")
    return levels


TABLE_STEP = 0.25  # px: finest W spacing of the static kind's table
TABLE_EXTENSION = 5.0  # px: the table continues to min(2 W_max, W_max + this)
_STATIC_BREAKDOWN = "static prediction: < 90 % of the subsets keep their IC-GN contraction"


def _static_terms(
    image: Any, blur: Any, spec: CampaignSpec, *, subset: int, angle: float, shape: str
) -> Any:
    """The static prediction's terms of the calibration (None, with a warning, if the
    image leaves none: the model then defaults to the fitted mismatch model)."""
    import math
    import warnings

    from ..errors import FitError
    from ..models import static_terms
    from .simulate import task_points

    rad = math.radians(angle)
    img = np.asarray(image, dtype=np.float64)
    w = np.unique(np.asarray(blur, dtype=np.float64))
    w_max = float(w.max())
    if w.size > 1 and float(np.min(np.diff(w))) < TABLE_STEP:
        # a fine sweep (the paper's 0.1 px): the table on a TABLE_STEP grid, the spline
        # between its points (each static-prediction W costs about as much as a DIC run
        # of the sweep over all W; the terms are smooth on this scale)
        w = np.round(np.arange(0.0, w_max + 1e-9, TABLE_STEP), 10)
        if w[-1] < w_max:
            w = np.append(w, w_max)
    try:
        return static_terms(
            img,
            w,
            subset=subset,
            # the campaign's own POIs (inside the region the blur kept on image content)
            points=task_points(img.shape, spec, subset=subset, angle=angle),
            motion=(math.sin(rad), math.cos(rad)),
            # the table continues beyond the sweep (up to the breakdown): the static
            # prediction needs no measurement there (flagged as outside the fitted W
            # range, but not the closed form's extrapolation)
            extend_to=min(2.0 * w_max, w_max + TABLE_EXTENSION),
            shape=shape,  # type: ignore[arg-type]
            boundary=spec.boundary,  # type: ignore[arg-type]
            # the table's offsets on the machine's cores (the sweep's workers are done)
            threads=os.cpu_count() or 1,
        )
    except (InputError, FitError) as exc:
        warnings.warn(
            f"static prediction not tabulated ({exc}); the default model is the fitted "
            "noise + blur-mismatch model",
            stacklevel=3,
        )
        return None


def calibrate(
    image: str | os.PathLike[str],
    out_dir: str | os.PathLike[str],
    *,
    noise: float | Sequence[float] = 2.0,
    subset: int = 31,
    angle: float = 0.0,
    step: int = 10,
    noise_model: str = "per-exposure",
    shape: str = "translation",
    size: tuple[int, int] = (512, 512),
    seed: int = 1,
    blur: Any = None,
    scheduler: str | None = None,
    workers: int | None = None,
    serial: bool = False,
    progress: Callable[[int, int], None] | None = None,
    compensation: str = "none",
) -> CalibrationResult | None:
    """Run the paper's sweep on one pattern and fit the blur-uncertainty model.

    Parameters are those of :func:`calibration_spec` plus the execution options of
    :func:`dicblur.campaign.run_campaign`. Writes into ``out_dir``: ``results.zarr`` (the
    campaign; rerunning resumes it), ``results.csv`` and ``model.json``. Figures are the
    report layer's (:func:`dicblur.report.plots.calibration_figures`).

    The model's default is the static kind (docs/models.md s. 4): the static prediction
    of the pattern on the sweep's W grid (no finer than 0.25 px; continued to
    ``min(2 W_max, W_max + 5 px)`` or to the static breakdown W), with one fitted scale
    per term; the fitted mismatch model and the
    power law are in the model beside it. If the image leaves no static prediction, the
    default is the mismatch model (with a warning).

    Returns
    -------
    CalibrationResult or None
        None when the campaign was interrupted before it finished (rerun to resume).
    """
    from ..io import check_output
    from ..models import fit_blur_model, with_static_model
    from .engine import run_campaign
    from .store import export_csv, open_results
    from .tasks import make_pattern

    check_output(out_dir, "out", folder=True)
    spec = calibration_spec(
        image,
        noise=noise,
        subset=subset,
        angle=angle,
        step=step,
        noise_model=noise_model,
        shape=shape,
        size=size,
        seed=seed,
        blur=blur,
        compensation=compensation,
    )
    out = Path(out_dir)
    out.mkdir(exist_ok=True)
    results = out / "results.zarr"
    timings: dict[str, float] = {}
    lap = lap_timer(timings)
    summary = run_campaign(
        spec, results, scheduler=scheduler, workers=workers, serial=serial, progress=progress
    )
    if not summary.complete:
        return None  # interrupted (Ctrl-C): the store keeps the finished batches
    lap("campaign")
    csv_path = out / "results.csv"
    export_csv(results, csv_path)
    ds = open_results(results).isel(pattern=0, angle=0, subset=0)
    mean = ds.mean("rep")  # dims (noise, blur)
    w = np.tile(mean["blur"].values, mean.sizes["noise"])

    def flat(da: Any) -> Any:
        return np.asarray(da.transpose("noise", "blur").values, dtype=np.float64).ravel()

    # the effective per-image noise of each level (per-subframe noise is sigma/sqrt(K+1))
    eff = np.repeat(
        [float(v) for v in mean["noise_effective"].mean("blur").values], mean.sizes["blur"]
    )
    hashes = json.loads(ds.attrs["input_hashes"])
    image_px = make_pattern(spec, spec.patterns[0])
    lap("export")
    # the static kind tabulates the plain matcher's static prediction (noise + mismatch);
    # a compensated sweep has no mismatch term to scale, so it keeps the fitted default
    terms = (
        _static_terms(image_px, mean["blur"].values, spec, subset=subset, angle=angle, shape=shape)
        if spec.compensation == "none"
        else None
    )
    lap("static_terms")
    model = fit_blur_model(
        w,
        flat(mean["sssig"]),
        flat(mean["u_e"]),
        noise_sigma=eff,
        contrast_ref=flat(mean["rms_contrast_ref"]),
        contrast=flat(mean["rms_contrast"]),
        subset=subset,
        # validity domain: DIC breaks down where < 90 % of the POIs converge (worst rep)
        converged_fraction=flat(ds["converged_fraction"].min("rep")),
        # ... or where the static prediction's own breakdown test says so
        breakdown_blur=None if terms is None else terms.breakdown_blur,
        breakdown_rule=None if terms is None else _STATIC_BREAKDOWN,
        shape=shape,
        pattern=spec.patterns[0].name,
        pattern_sha256=next(iter(hashes.values()), None) if len(hashes) == 1 else None,
        mean_level=float(np.mean(image_px)),
        # the sweep spans the W range the model will be used in (beyond it predictions are
        # flagged as extrapolated): let the AIC add the W^4 term where the data ask for it.
        # Measured on paper4 512^2 over W = 0..8 px: without it the fit is 24 % rms off
        # and over-predicts W = 3 px by 22-30 %; with it 7 % rms and 1-3 % (BENCHMARKS.md).
        next_term="auto",
        compensation=spec.compensation,
        provenance={
            "source": "dicblur calibrate",
            "pattern": spec.patterns[0].to_dict(),
            "input_hashes": hashes,
            "spec_hash": ds.attrs["spec_hash"],
            "noise_model": noise_model,
            "noise": _levels(noise),
            "angle": angle,
            "step": step,
            "dic_shape": shape,
            **({} if spec.compensation == "none" else {"compensation": spec.compensation}),
        },
    )
    if terms is not None:
        # the default: the static prediction with its two fitted scales, held to 0.15 rms
        # log error up to the breakdown W where the closed form is not (BENCHMARKS.md)
        model = with_static_model(model, terms)
    lap("fit")
    model_path = out / "model.json"
    model.to_json(str(model_path))
    lap("write")
    return CalibrationResult(
        model=model,
        model_path=model_path,
        results_path=results,
        csv_path=csv_path,
        sssig_r2=float(model.decay.r2),
        spec=spec,
        curves=mean.assign_coords(noise_effective_level=("noise", eff[:: mean.sizes["blur"]])),
        timings=timings,
    )
