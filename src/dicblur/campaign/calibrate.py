"""Calibration: the paper's blur sweep on one pattern, then the uncertainty-model fits.

This is what a user with their own speckle pattern runs (``dicblur calibrate``): W from
0.1 to 10 px in 0.1 px steps (Lavatelli & Zappa 2017, Section VI), one noise level, one
subset size, one motion direction; the campaign's dataset is then fitted with
:func:`dicblur.models.fit_blur_model` (SSSIG decay, eq. 18; power law, eq. 17; noise +
blur-mismatch model) and written with figures.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
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
    figures : tuple of pathlib.Path
        PNG figures: u_e vs W with the fits, SSSIG vs W with the eq. 18 fit, log-log u_e
        vs SSSIG.
    sssig_r2 : float
        R^2 of the SSSIG decay fit (eq. 18), as the paper reports it.
    spec : CampaignSpec
    """

    model: Any
    model_path: Path
    results_path: Path
    csv_path: Path
    figures: tuple[Path, ...]
    sssig_r2: float
    spec: CampaignSpec


def calibration_spec(
    image: str | os.PathLike[str],
    *,
    noise: float = 2.0,
    subset: int = 31,
    angle: float = 0.0,
    step: int = 10,
    noise_model: str = "per-exposure",
    shape: str = "translation",
    size: tuple[int, int] = (512, 512),
    seed: int = 1,
    blur: Any = None,
    repetitions: int = 1,
) -> CampaignSpec:
    """The campaign spec of a calibration sweep.

    Parameters
    ----------
    image : path or {"paper4", "speckle"}
        An image file, or a generator name (pattern of ``size`` px, seeded by ``seed``).
    noise : float
        Noise std, grey levels (per image for ``"per-exposure"``).
    subset, step : int
        DIC subset size and grid step, px.
    angle : float
        Motion direction, degrees from +x (columns) towards +y (rows).
    noise_model : {"per-exposure", "per-subframe", "poisson-gaussian"}
        Default ``"per-exposure"``: ``noise`` is the camera's noise per image (what
        ``dicblur noise`` measures). The paper adds it per sub-frame instead.
    blur : list or dict, optional
        W grid (px); default the paper's 0.1..10 px in 0.1 px steps.

    Notes
    -----
    Image files are blurred with ``boundary = "reflect"`` (no wrap-around; POIs limited to
    the region that saw only image content at the largest W); generated patterns are
    periodic and use ``"periodic"``, exactly the paper.
    """
    name = str(image)
    is_file = Path(name).is_file()
    if is_file:
        pattern: dict[str, Any] = {"name": Path(name).stem or "pattern",
                                   "path": str(Path(name).resolve())}
        boundary = "reflect"
    elif name in GENERATORS:
        pattern = {"name": name, "generator": name, "shape": list(size), "seed": seed}
        boundary = "periodic"
    else:
        raise InputError(f"image={name!r}: no such file; give an image file or a generator "
                         f"name ({', '.join(GENERATORS)})")
    return parse_spec({
        "campaign": {"name": f"calibrate-{pattern['name']}", "seed": seed,
                     "repetitions": repetitions},
        "pattern": [pattern],
        "blur": {"lengths": PAPER_BLUR if blur is None else blur, "angles": [angle],
                 "boundary": boundary},
        "noise": {"model": noise_model, "levels": [noise]},
        "dic": {"subsets": [subset], "step": step, "shape": shape},
    })


def calibrate(
    image: str | os.PathLike[str],
    out_dir: str | os.PathLike[str],
    *,
    noise: float = 2.0,
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
    figures: bool = True,
    progress: Callable[[int, int], None] | None = None,
) -> CalibrationResult:
    """Run the paper's sweep on one pattern and fit the blur-uncertainty model.

    Parameters are those of :func:`calibration_spec` plus the execution options of
    :func:`dicblur.campaign.run_campaign`. Writes into ``out_dir``: ``results.zarr`` (the
    campaign; rerunning resumes it), ``results.csv``, ``model.json`` and, with
    ``figures=True``, ``ue_vs_blur.png``, ``sssig_vs_blur.png``, ``ue_vs_sssig.png``.

    Returns
    -------
    CalibrationResult
    """
    from ..io import check_output
    from ..models import fit_blur_model
    from .engine import run_campaign
    from .store import export_csv, open_results

    check_output(out_dir, "out", folder=True)
    spec = calibration_spec(image, noise=noise, subset=subset, angle=angle, step=step,
                            noise_model=noise_model, shape=shape, size=size, seed=seed,
                            blur=blur)
    out = Path(out_dir)
    out.mkdir(exist_ok=True)
    results = out / "results.zarr"
    summary = run_campaign(spec, results, scheduler=scheduler, workers=workers,
                           serial=serial, progress=progress)
    if not summary.complete:
        raise KeyboardInterrupt
    csv_path = out / "results.csv"
    export_csv(results, csv_path)
    ds = open_results(results).isel(pattern=0, angle=0, subset=0, noise=0)
    mean = ds.mean("rep")
    w = mean["blur"].values
    model = fit_blur_model(
        w, mean["sssig"].values, mean["u_e"].values,
        noise_sigma=float(mean["noise_effective"].mean()),
        contrast_ref=mean["rms_contrast_ref"].values,
        contrast=mean["rms_contrast"].values,
        subset=subset,
        provenance={
            "source": "dicblur calibrate",
            "pattern": spec.patterns[0].to_dict(),
            "input_hashes": json.loads(ds.attrs["input_hashes"]),
            "spec_hash": ds.attrs["spec_hash"],
            "noise_model": noise_model, "noise": noise, "angle": angle, "step": step,
            "dic_shape": shape,
        },
    )
    model_path = out / "model.json"
    model.to_json(str(model_path))
    figs = _figures(mean, model, out) if figures else ()
    return CalibrationResult(model=model, model_path=model_path, results_path=results,
                             csv_path=csv_path, figures=figs,
                             sssig_r2=float(model.decay.r2), spec=spec)


def _save(fig: Any, path: Path) -> None:
    from ..io import atomic_path

    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120)


def _figures(ds: Any, model: Any, out: Path) -> tuple[Path, ...]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..models import sssig_decay

    w = ds["blur"].values
    ue = ds["u_e"].values
    s = ds["sssig"].values
    wf = np.linspace(0.0, float(w.max()), 200)
    paths = []

    fig, ax = plt.subplots(figsize=(5.5, 4))
    ax.plot(w, ue, "o", ms=3, label="campaign (std over POIs)")
    pred = model.predict(wf)
    ax.plot(wf, getattr(pred, "u_e", pred), "-", label=f"model ({model.default})")
    ax.plot(w, ds["u_match_score"].values, ":", label="static match score, eq. 2")
    ax.set(xlabel="blur length W (px)", ylabel="u_e (px)",
           title="random error vs blur")
    ax.legend()
    fig.tight_layout()
    paths.append(out / "ue_vs_blur.png")
    _save(fig, paths[-1])
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(5.5, 4))
    ax.plot(w, s, "o", ms=3, label="campaign (mean over POIs)")
    ax.plot(wf, sssig_decay(wf, model.decay["sssig0"], model.decay["beta"]), "-",
            label=f"eq. 18 fit, R^2 = {model.decay.r2:.3f}")
    ax.set(xlabel="blur length W (px)", ylabel="SSSIG along the motion ((GL/px)^2)",
           title="SSSIG vs blur")
    ax.legend()
    fig.tight_layout()
    paths.append(out / "sssig_vs_blur.png")
    _save(fig, paths[-1])
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(5.5, 4))
    ax.loglog(s, ue, "o", ms=3, label="campaign")
    sf = np.geomspace(float(s.min()), float(s.max()), 100)
    pl = model.power_law
    ax.loglog(sf, pl["eta"] / sf ** pl["alpha"], "-",
              label=f"eq. 17 fit, alpha = {pl['alpha']:.2f} (W in {model.fit_range[0]:g}.."
                    f"{model.fit_range[1]:g} px)")
    ax.set(xlabel="SSSIG ((GL/px)^2)", ylabel="u_e (px)", title="log u_e vs log SSSIG")
    ax.legend()
    fig.tight_layout()
    paths.append(out / "ue_vs_sssig.png")
    _save(fig, paths[-1])
    plt.close(fig)
    return tuple(paths)
