"""Calibration: the paper's blur sweep on one pattern, then the uncertainty-model fits.

This is what a user with their own speckle pattern runs (``dicblur calibrate``): W from
0.1 to 10 px in 0.1 px steps (Lavatelli & Zappa 2017, Section VI), one noise level (or
several: two levels that bracket the noise of the planned exposure separate the mismatch
model's floor and cross term and keep a camera plan inside the model's validity domain),
one subset size, one motion direction; the campaign's dataset is then fitted with
:func:`dicblur.models.fit_blur_model` (SSSIG decay, eq. 18; power law, eq. 17; noise +
blur-mismatch model) and written with figures.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Sequence
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
        "noise": {"model": noise_model, "levels": _levels(noise)},
        "dic": {"subsets": [subset], "step": step, "shape": shape},
    })


def _levels(noise: float | Sequence[float]) -> list[float]:
    if isinstance(noise, int | float):
        return [float(noise)]
    levels = [float(v) for v in noise]
    if not levels:
        raise InputError("noise: give at least one noise level (GL), e.g. 2")
    return levels


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
    from ..models import fit_blur_model
    from .engine import run_campaign
    from .store import export_csv, open_results
    from .tasks import make_pattern

    spec = calibration_spec(image, noise=noise, subset=subset, angle=angle, step=step,
                            noise_model=noise_model, shape=shape, size=size, seed=seed,
                            blur=blur)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    results = out / "results.zarr"
    summary = run_campaign(spec, results, scheduler=scheduler, workers=workers,
                           serial=serial, progress=progress)
    if not summary.complete:
        raise KeyboardInterrupt
    csv_path = out / "results.csv"
    export_csv(results, csv_path)
    ds = open_results(results).isel(pattern=0, angle=0, subset=0)
    mean = ds.mean("rep")  # dims (noise, blur)
    w = np.tile(mean["blur"].values, mean.sizes["noise"])

    def flat(da: Any) -> Any:
        return np.asarray(da.transpose("noise", "blur").values, dtype=np.float64).ravel()

    # the effective per-image noise of each level (per-subframe noise is sigma/sqrt(K+1))
    eff = np.repeat([float(v) for v in mean["noise_effective"].mean("blur").values],
                    mean.sizes["blur"])
    hashes = json.loads(ds.attrs["input_hashes"])
    model = fit_blur_model(
        w, flat(mean["sssig"]), flat(mean["u_e"]),
        noise_sigma=eff,
        contrast_ref=flat(mean["rms_contrast_ref"]),
        contrast=flat(mean["rms_contrast"]),
        subset=subset,
        # validity domain: DIC breaks down where < 90 % of the POIs converge (worst rep)
        converged_fraction=flat(ds["converged_fraction"].min("rep")),
        shape=shape, pattern=spec.patterns[0].name,
        pattern_sha256=next(iter(hashes.values()), None) if len(hashes) == 1 else None,
        mean_level=float(np.mean(make_pattern(spec, spec.patterns[0]))),
        # the sweep spans the W range the model will be used in (beyond it predictions are
        # flagged as extrapolated): let the AIC add the W^4 term where the data ask for it.
        # Measured on paper4 512^2 over W = 0..8 px: without it the fit is 24 % rms off
        # and over-predicts W = 3 px by 22-30 %; with it 7 % rms and 1-3 % (BENCHMARKS.md).
        next_term="auto",
        provenance={
            "source": "dicblur calibrate",
            "pattern": spec.patterns[0].to_dict(),
            "input_hashes": hashes,
            "spec_hash": ds.attrs["spec_hash"],
            "noise_model": noise_model, "noise": _levels(noise), "angle": angle,
            "step": step,
            "dic_shape": shape,
        },
    )
    model_path = out / "model.json"
    model_path.write_text(model.to_json())
    figs = _figures(mean, model, out, eff[:: mean.sizes["blur"]]) if figures else ()
    return CalibrationResult(model=model, model_path=model_path, results_path=results,
                             csv_path=csv_path, figures=figs,
                             sssig_r2=float(model.decay.r2), spec=spec)


def _figures(dsn: Any, model: Any, out: Path, sigmas: Any) -> tuple[Path, ...]:
    """The three figures; ``dsn`` has dims (noise, blur), ``sigmas`` the effective noise."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..models import sssig_decay

    ds = dsn.isel(noise=0)  # SSSIG is noise-free; the log-log fit is at the first level
    w = ds["blur"].values
    ue = ds["u_e"].values
    s = ds["sssig"].values
    wf = np.linspace(0.0, float(w.max()), 200)
    paths = []

    fig, ax = plt.subplots(figsize=(5.5, 4))
    for i, sig in enumerate(sigmas):
        col = f"C{i}"
        ax.plot(w, dsn["u_e"].isel(noise=i).values, "o", ms=3, color=col,
                label=f"campaign, noise {sig:.3g} GL")
        for kind, style in (("mismatch", "-"), ("power_law", "--")):
            if kind == "mismatch" and model.mismatch is None:
                continue
            pred = model.predict(wf, float(sig), model=kind)  # NaN where DIC breaks down
            ax.plot(wf, pred.u_e, style, color=col,
                    label=(("noise + blur mismatch" if kind == "mismatch"
                            else "power law, eq. 19")
                           + (" (default)" if kind == model.default else "")) if i == 0
                    else None)
        ax.plot(w, dsn["u_match_score"].isel(noise=i).values, ":", color=col,
                label="static match score, eq. 2" if i == 0 else None)
    ax.set(xlabel="blur length W (px)", ylabel="u_e (px)",
           title="random error vs blur")
    ax.legend()
    fig.tight_layout()
    paths.append(out / "ue_vs_blur.png")
    fig.savefig(paths[-1], dpi=120)
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
    fig.savefig(paths[-1], dpi=120)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(5.5, 4))
    ax.loglog(s, ue, "o", ms=3, label="campaign")
    sf = np.geomspace(float(s.min()), float(s.max()), 100)
    pl = model.power_law
    ref = pl.extra.get("sigma_ref")
    at_first = ((float(sigmas[0]) / ref) ** pl["kappa"] if "kappa" in pl and ref else 1.0)
    ax.loglog(sf, at_first * pl["u_ref"] * (sf / pl.extra["sssig_ref"]) ** (-pl["alpha"]), "-",
              label=f"eq. 17 fit, alpha = {pl['alpha']:.2f} (W in {model.fit_range[0]:g}.."
                    f"{model.fit_range[1]:g} px)")
    ax.set(xlabel="SSSIG ((GL/px)^2)", ylabel="u_e (px)", title="log u_e vs log SSSIG")
    ax.legend()
    fig.tight_layout()
    paths.append(out / "ue_vs_sssig.png")
    fig.savefig(paths[-1], dpi=120)
    plt.close(fig)
    return tuple(paths)
