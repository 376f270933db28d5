"""``dicblur reproduce``: the paper's whole study, end to end, as a report.

Stages (each reported through ``progress``):

1. the four study patterns (:mod:`dicblur.report.study`), written as float64 TIFFs;
2. the Section III / VI campaign: every pattern blurred along x over a W grid, with
   per-exposure Gaussian noise at three levels, correlated against its sharp reference
   (:func:`dicblur.campaign.run_campaign`; a rerun reuses finished tasks);
3. a family of generated patterns (speckle size swept) for the paper's Fig. 11;
4. the 1-D analysis of Section V (:func:`dicblur.pulse.run_pulse_study`);
5. every fit of Section VI and the noise + blur-mismatch model
   (:func:`dicblur.models.fit_blur_model`);
6. figures, tables, the claims table, ``results.json`` and ``report.html``.

Noise: the paper adds Gaussian noise of std s to each of the K + 1 sub-frames, which is the
same in distribution as one draw of std s / sqrt(K + 1) per exposure; we state noise as the
effective per-image std (the main level is 2 GL, as in the brief's reference sweep).
"""

from __future__ import annotations

import json
import math
import platform
import sys
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from .._version import package_versions
from ..arrays import BoolArray, Float64Array
from ..errors import InputError
from ..io import atomic_path, check_output, write_text
from ._data import series
from .records import Campaigns, ReproduceSettings, StudyData, StudyFits
from .study import (
    StudyPattern,
    emulated_camera_pattern3,
    load_user_pattern,
    numerical_pattern4,
    stand_in_pattern1,
    stand_in_pattern2,
)

__all__ = ["ReproduceResult", "ReproduceSettings", "reproduce"]

Progress = Callable[[str, int, int], None]

#: Sweep points with a smaller fraction of converged POIs are excluded from fits and claims.
MIN_CONVERGED = 0.9


@dataclass(frozen=True)
class ReproduceResult:
    """What a reproduce run produced."""

    report: Path
    results_json: Path
    figures: tuple[str, ...]
    claims: tuple[dict[str, Any], ...]
    timings: dict[str, float] = field(default_factory=dict)
    campaign_runs: dict[str, dict[str, int]] = field(default_factory=dict)


# ---------------------------------------------------------------------------------------
#: Patterns #1 and #2: the DIC Challenge image's label, and the stand-in used without it
#: (label, generator, seed offset, source).
_STAND_INS = {
    "p1": (
        "#1 Sample 13",
        "#1 stand-in (fine, low contrast)",
        stand_in_pattern1,
        1,
        "stand_in_pattern1: speckle 2 px, softness 0.9, levels 55..135",
    ),
    "p2": (
        "#2 Sample 3",
        "#2 stand-in (coarse, high contrast)",
        stand_in_pattern2,
        2,
        "stand_in_pattern2: speckle 7 px, softness 1.6, levels 30..190",
    ),
}


def _study_patterns(s: ReproduceSettings) -> list[StudyPattern]:
    """The four study patterns: #1 and #2 from the given images or their stand-ins, the
    emulated camera pattern #3 and the numerical pattern #4."""
    given = {"p1": s.pattern1, "p2": s.pattern2}
    pats = []
    for key, (real, label, make, offset, source) in _STAND_INS.items():
        path = given[key]
        if path is not None:
            pats.append(load_user_pattern(key, real, path, s.size))
        else:
            pats.append(StudyPattern(key, label, make(s.size, s.seed + offset), True, source))
    return [
        *pats,
        emulated_camera_pattern3(s.size, s.seed + 3),
        numerical_pattern4(s.size, s.seed + 4),
    ]


def _write_float_tiff(path: Path, image: np.ndarray) -> None:
    import tifffile

    with atomic_path(path) as tmp:
        tifffile.imwrite(tmp, np.ascontiguousarray(image, dtype=np.float64))


def _campaign(
    s: ReproduceSettings,
    name: str,
    patterns: list[dict[str, Any]],
    blur: dict[str, float],
    noise: tuple[float, ...],
    progress: Progress | None,
    *,
    compensation: str = "none",
) -> Any:
    from ..campaign import open_results, parse_spec, run_campaign

    spec = parse_spec(
        {
            "campaign": {"name": name, "seed": s.seed, "repetitions": 1},
            "pattern": patterns,
            "blur": {
                "lengths": blur,
                "angles": [0.0],
                "trajectory": "linear",
                "method": "transfer",
                "substeps": 100,
                "boundary": "periodic",
            },
            "noise": {"model": "per-exposure", "levels": list(noise)},
            "dic": {
                "subsets": [s.subset],
                "step": s.poi_step,
                "shape": "translation",
                **({} if compensation == "none" else {"compensation": compensation}),
            },
        },
        base_dir=s.out,
    )
    store = s.out / "campaign" / f"{name}.zarr"
    store.parent.mkdir(parents=True, exist_ok=True)

    def cb(done: int, total: int) -> None:
        if progress is not None:
            progress(f"campaign {name}", done, total)

    summary = run_campaign(
        spec, store, scheduler=s.scheduler, workers=s.workers, serial=s.serial, progress=cb
    )
    return open_results(store), {
        "tasks": summary.n_tasks,
        "run": summary.n_run,
        "skipped": summary.n_skipped,
    }


def _warm_kernels(s: ReproduceSettings) -> float:
    """Run the campaign's own task once on a tiny pattern, in this process.

    With an empty numba cache (a fresh install) every Dask worker would otherwise compile
    the same blur and DIC kernels at once; compiled here first, the workers load them from
    the on-disk cache in a fraction of a second. Returns the seconds spent.
    """
    from ..campaign import iter_batches, make_pattern, parse_spec, simulate_batch

    t0 = time.perf_counter()
    size = 4 * s.subset
    spec = parse_spec(
        {
            "campaign": {"name": "warm-up", "seed": 0},
            "pattern": [
                {
                    "name": "w",
                    "generator": "speckle",
                    "shape": [size, size],
                    "speckle_size": 4.0,
                    "seed": 0,
                }
            ],
            "blur": {"lengths": [0.0, 1.0], "method": "transfer", "substeps": 100},
            "noise": {"model": "per-exposure", "levels": [s.main_noise]},
            "dic": {"subsets": [s.subset], "step": s.poi_step, "shape": "translation"},
        }
    )
    batch = next(iter(iter_batches(spec)))
    simulate_batch(make_pattern(spec, spec.patterns[0]), batch, spec)
    return time.perf_counter() - t0


def _param(fit: Any, name: str) -> dict[str, float]:
    p = fit.parameter(name)
    return {"value": p.value, "low": p.low, "high": p.high}


# ---------------------------------------------------------------------------------------
def reproduce(settings: ReproduceSettings, *, progress: Progress | None = None) -> ReproduceResult:
    """Run the whole study and write the report folder (see the module docs)."""
    from .claims import evaluate_claims
    from .experiments import run_claim_experiments
    from .write import write_report

    s = settings
    if s.size < 4 * s.subset:
        raise InputError(
            f"size={s.size}: the study images need at least 4 subsets a side "
            f"(size >= {4 * s.subset})"
        )
    if s.main_noise not in s.noise_levels:
        raise InputError(f"main_noise={s.main_noise}: must be one of noise_levels {s.noise_levels}")
    out = check_output(s.out, "out", folder=True)
    out.mkdir(exist_ok=True)
    timings: dict[str, float] = {}
    t0 = time.perf_counter()

    def stage(name: str) -> None:
        if progress is not None:
            progress(name, 0, 1)

    # 1. patterns ------------------------------------------------------------------------
    stage("patterns")
    pats, static = _stage_patterns(s, out)
    timings["patterns"] = time.perf_counter() - t0

    # 2. main campaign, and pattern #2 with the compensated and deblurring matchers -------
    stage("compiling kernels")
    timings["warm_up"] = _warm_kernels(s)
    t = time.perf_counter()
    study_patterns = [{"name": p.key, "path": f"patterns/{p.key}.tif"} for p in pats]
    ds, run_study = _campaign(s, "study", study_patterns, _blur_grid(s), s.noise_levels, progress)
    timings["campaign_study"] = time.perf_counter() - t
    t = time.perf_counter()
    compensation, comp_runs = _compensation_campaigns(s, pats[1], study_patterns[1], ds, progress)
    timings["campaign_compensation"] = time.perf_counter() - t

    # 3. family for Fig. 11 --------------------------------------------------------------
    t = time.perf_counter()
    fam_specs = _family_specs(s)
    fam_grid = {"start": 0.0, "stop": 6.0, "step": 1.0 if s.quick else 0.25}
    ds_fam, run_family = _campaign(s, "family", fam_specs, fam_grid, (s.main_noise,), progress)
    timings["campaign_family"] = time.perf_counter() - t
    campaigns = Campaigns(
        study=ds,
        family=ds_fam,
        family_specs=tuple(fam_specs),
        compensation=compensation,
        runs={"study": run_study, "family": run_family, **comp_runs},
    )

    # 4. 1-D analysis --------------------------------------------------------------------
    t = time.perf_counter()
    stage("1-D pulse analysis")
    pulse = _stage_pulse(s)
    timings["pulse"] = time.perf_counter() - t

    # 5. fits ----------------------------------------------------------------------------
    t = time.perf_counter()
    stage("fits")
    fits = _stage_fits(s, out, pats, static, campaigns)
    timings["fits"] = time.perf_counter() - t

    # 6. the claims' own experiments (pattern #4) ----------------------------------------
    t = time.perf_counter()
    stage("claim experiments")
    p4 = next(p for p in pats if p.key == "p4")
    experiments = run_claim_experiments(
        p4.image,
        noise_sigma=s.main_noise,
        subset=s.subset,
        step=s.poi_step,
        seed=s.seed,
        quick=s.quick,
    )
    timings["claim_experiments"] = time.perf_counter() - t

    # 7. report --------------------------------------------------------------------------
    t = time.perf_counter()
    stage("figures and report")
    data = StudyData(s, pats, static, campaigns, fits, pulse)
    claims = evaluate_claims(data, experiments)
    versions = {
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        **package_versions(),
    }
    report_path, figures = write_report(
        out=out, study=data, claims=claims, versions=versions, timings=timings, clock=(t0, t)
    )
    timings["report"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - t0
    rj = _write_results(
        out, data, claims=claims, figures=figures, versions=versions, timings=timings
    )
    return ReproduceResult(
        report_path,
        rj,
        tuple(figures),
        tuple(claims),
        timings,
        {"study": run_study, "family": run_family},
    )


def _stage_patterns(
    s: ReproduceSettings, out: Path
) -> tuple[list[StudyPattern], dict[str, dict[str, Any]]]:
    """The four study patterns, written as float64 TIFFs, and their static numbers."""
    from ..metrics import pattern_metrics
    from ..models import blur_sensitivity

    pats = _study_patterns(s)
    pdir = out / "patterns"
    pdir.mkdir(exist_ok=True)
    static: dict[str, dict[str, Any]] = {}
    for p in pats:
        _write_float_tiff(pdir / f"{p.key}.tif", p.image)
        m = pattern_metrics(p.image, subset=s.subset, noise_sigma=s.main_noise, step=s.poi_step)
        c = blur_sensitivity(p.image, subset=s.subset, step=s.poi_step)
        static[p.key] = {
            "label": p.label,
            "synthetic": p.synthetic,
            "source": p.source,
            "sha256": p.sha256,
            "metrics": m.to_dict(),
            "c_static": c.c,
        }
    return pats, static


def _blur_grid(s: ReproduceSettings) -> dict[str, float]:
    """The study's W grid (px): 0..10 px in steps of ``s.blur_step``."""
    return {"start": 0.0, "stop": 10.0, "step": s.blur_step}


def _compensation_campaigns(
    s: ReproduceSettings,
    pattern: StudyPattern,
    table: dict[str, Any],
    ds: Any,
    progress: Progress | None,
) -> tuple[dict[str, Any], dict[str, dict[str, int]]]:
    """Beyond the paper: the study sweep of ``pattern`` (#2) with the blur-compensated
    matcher and with the deblur baseline (issue 18; main noise level only), beside the
    plain matcher's u_e and the blurred image's static bound from ``ds``."""
    runs = {
        mode: _campaign(
            s, f"study_{mode}", [table], _blur_grid(s), (s.main_noise,), progress, compensation=mode
        )
        for mode in ("given", "deblur")
    }
    key, n = pattern.key, s.main_noise
    compensation = {
        "pattern": key,
        "label": pattern.label,
        "blur": np.asarray(ds["blur"].values, dtype=np.float64),
        "plain": series(ds, "u_e", key, n),
        "given": series(runs["given"][0], "u_e", key, n),
        "deblur": series(runs["deblur"][0], "u_e", key, n),
        "bound": series(ds, "u_match_score", key, n),
    }
    return compensation, {f"study_{m}": r[1] for m, r in runs.items()}


def _family_specs(s: ReproduceSettings) -> list[dict[str, Any]]:
    """The ``[[pattern]]`` tables of the Fig. 11 family (speckle size swept)."""
    return [
        {
            "name": f"d{d:g}",
            "generator": "speckle",
            "shape": [s.size, s.size],
            "speckle_size": d,
            "density": 0.5,
            "softness": 0.5,
            "seed": s.seed + 100 + i,
        }
        for i, d in enumerate(s.family_sizes)
    ]


def _stage_pulse(s: ReproduceSettings) -> Any:
    """The 1-D analysis of Section V (:func:`dicblur.pulse.run_pulse_study`)."""
    from ..pulse.study import run_pulse_study

    return run_pulse_study(
        trials=s.pulse_trials,
        seed=s.seed,
        dependence_trials=(
            min(s.pulse_trials, 500 if s.quick else 2000) if s.pulse_dependence else None
        ),
    )


def _stage_fits(
    s: ReproduceSettings,
    out: Path,
    pats: list[StudyPattern],
    static: dict[str, dict[str, Any]],
    campaigns: Campaigns,
) -> StudyFits:
    """Every fit of Section VI per study pattern (models written as JSON, the static
    prediction added to ``static``), and the family's fits."""
    ds = campaigns.study
    W = np.asarray(ds["blur"].values, dtype=np.float64)
    fits: dict[str, dict[str, Any]] = {}
    models: dict[str, tuple[Any, Any]] = {}
    valid: dict[str, np.ndarray] = {}
    for p in pats:
        k = p.key
        # Points where DIC broke down (< 90 % of POIs converged) measure failure, not the
        # random error the models describe: they are shown but not fitted.
        ok = {lv: series(ds, "converged_fraction", k, lv) >= MIN_CONVERGED for lv in s.noise_levels}
        valid[k] = ok[s.main_noise]
        paper, full, range_notes = _fit_pattern(s, p, static[k]["c_static"], ds, W, ok)
        models[k] = (paper, full)
        paper.to_json(str(out / f"model_{k}.json"))
        full.to_json(str(out / f"model_{k}_all_noise.json"))
        static[k].update(_static_prediction(s, p, W))
        fits[k] = _fit_numbers(s, k, static[k], ds, W, valid[k], paper, full, range_notes)
    family = [_fit_family_pattern(s, campaigns.family, row) for row in campaigns.family_specs]
    return StudyFits(fits=fits, models=models, valid=valid, family=family)


def _fit_pattern(
    s: ReproduceSettings,
    p: StudyPattern,
    c_static: float,
    ds: Any,
    W: Float64Array,
    ok: dict[float, BoolArray],
) -> tuple[Any, Any, list[str]]:
    """The paper-like fit of pattern ``p`` at the main noise level, the fit over every
    level (with the mismatch model) and the notes on eq. 17's automatic range."""
    from ..models import fit_blur_model

    k = p.key
    v = ok[s.main_noise]
    u = series(ds, "u_e", k, s.main_noise)[v]
    sg = series(ds, "sssig", k, s.main_noise)[v]
    # RMS contrast: the 2-D analogue of the paper's 1-D contrast (Fig. 8).
    cref = series(ds, "rms_contrast_ref", k, s.main_noise)[v]
    con = series(ds, "rms_contrast", k, s.main_noise)[v]
    prov = {
        "pattern": p.source,
        "sha256": p.sha256,
        "subset": s.subset,
        "step": s.poi_step,
        "dic": "translation IC-GN, ZNSSD, bspline3",
        "noise": "per-exposure Gaussian",
        "points": f"W with >= {MIN_CONVERGED:.0%} POIs converged",
    }
    # the two fits of the pattern: the same subset, static constant and provenance
    fit = partial(
        fit_blur_model,
        subset=s.subset,
        c_static=c_static,
        provenance=prov,
        mean_level=float(p.image.mean()),
    )
    # the automatic eq. 17 range may fall back on its minimum number of points; the
    # report states the range it used (table "eq.17 range"), so the warning, which
    # tells an API user to pass fit_range, is kept as a note instead of printed
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        paper = fit(W[v], sg, u, noise_sigma=s.main_noise, contrast_ref=cref, contrast=con)
    range_notes = [
        str(wm.message).split(". Pass fit_range")[0]
        for wm in caught
        if "edge-driven range" in str(wm.message)
    ]
    for wm in caught:
        if "edge-driven range" not in str(wm.message):
            warnings.warn_explicit(wm.message, wm.category, wm.filename, wm.lineno)
    allw = np.concatenate([W[ok[lv]] for lv in s.noise_levels])
    allu = np.concatenate([series(ds, "u_e", k, lv)[ok[lv]] for lv in s.noise_levels])
    alls = np.concatenate([series(ds, "sssig", k, lv)[ok[lv]] for lv in s.noise_levels])
    alln = np.concatenate([np.full(int(ok[lv].sum()), lv) for lv in s.noise_levels])
    allc = np.concatenate(
        [
            (series(ds, "rms_contrast_ref", k, lv) / series(ds, "rms_contrast", k, lv))[ok[lv]]
            for lv in s.noise_levels
        ]
    )
    full = fit(allw, alls, allu, noise_sigma=alln, contrast_ratio=allc)
    return paper, full, range_notes


def _static_prediction(s: ReproduceSettings, p: StudyPattern, W: Float64Array) -> dict[str, Any]:
    """The whole u_e(W) of ``p`` from the static image alone, no fit (docs/models.md s. 4),
    per noise level, and the W where that prediction stops describing DIC."""
    from scipy.interpolate import CubicSpline

    from ..models import predict_from_pattern

    # one call at sigma = 1 GL: the noise term scales with sigma
    # both terms are smooth in W (u_blur ~ c W^2 at first): predicted every 0.5 px
    # (the quick grid) and interpolated by cubic splines onto a finer study grid
    wc = np.union1d(np.arange(0.0, float(W.max()) + 0.25, 0.5), [float(W.max())])
    unit = predict_from_pattern(
        p.image, wc, noise_sigma=1.0, subset=s.subset, step=s.poi_step, boundary="periodic"
    )
    # first-order noise scales with sigma, the two noises' interaction with sigma^2
    assert unit.u_noise_interaction is not None
    un = np.clip(
        CubicSpline(wc, np.sqrt(np.maximum(unit.u_noise**2 - unit.u_noise_interaction**2, 0.0)))(W),
        0.0,
        None,
    )
    ui = np.clip(CubicSpline(wc, unit.u_noise_interaction)(W), 0.0, None)
    ub = np.clip(CubicSpline(wc, unit.u_blur)(W), 0.0, None)
    return {
        "predicted_u_e": {
            f"{lv:g}": np.sqrt((lv * un) ** 2 + (lv * lv * ui) ** 2 + ub**2).tolist()
            for lv in s.noise_levels
        },
        # where the static prediction stops describing DIC (docs/models.md s. 4)
        "breakdown_blur": unit.breakdown_blur,
    }


def _fit_numbers(
    s: ReproduceSettings,
    k: str,
    static: dict[str, Any],
    ds: Any,
    W: Float64Array,
    v: BoolArray,
    paper: Any,
    full: Any,
    range_notes: list[str],
) -> dict[str, Any]:
    """The JSON-ready numbers of pattern ``k``'s fits and of their errors on ``W[v]``."""
    u = series(ds, "u_e", k, s.main_noise)[v]
    st = np.asarray(static["predicted_u_e"][f"{s.main_noise:g}"])[v]
    eq19 = paper.predict(W[v], s.main_noise, model="power_law").u_e
    mism = full.predict(W[v], s.main_noise, model="mismatch").u_e if full.mismatch else None
    return {
        # eq. 17 around SSSIG_0: u_ref (px) = its u_e(0); eta = u_ref SSSIG_0^alpha is
        # kept as a derived number (its units depend on alpha)
        "u_ref": _param(paper.power_law, "u_ref"),
        "eta": paper.eta,
        "sssig_ref": paper.sssig_ref,
        "alpha": _param(paper.power_law, "alpha"),
        "beta": _param(paper.decay, "beta"),
        "sssig0": _param(paper.decay, "sssig0"),
        "mbrf": paper.mbrf,
        "r2_decay": paper.decay.r2,
        "r2_power_law": paper.power_law.r2,
        "fit_range": list(paper.fit_range),
        "range_rule": paper.range_rule,
        "range_note": "; ".join(range_notes),
        "mig0": static["metrics"]["mig"],
        "c_static": static["c_static"],
        "c_fitted": full.c,
        "c_fitted_param": _param(full.mismatch, "c") if full.mismatch else None,
        "comparison": full.comparison,
        "default_model": full.default,
        "eq19_max_rel_error": float(np.max(np.abs(eq19 / u - 1))),
        "mismatch_max_rel_error": (
            float(np.max(np.abs(mism / u - 1))) if mism is not None else None
        ),
        "static_max_rel_error": float(np.max(np.abs(st / u - 1))),
        "static_rms_log_error": float(np.sqrt(np.mean(np.log(st / u) ** 2))),
        "w_fitted_max": float(W[v].max()),
        "bias_max": float(np.nanmax(np.abs(series(ds, "bias", k, s.main_noise)[v]))),
        "converged_min": float(np.nanmin(series(ds, "converged_fraction", k, s.main_noise))),
    }


def _fit_family_pattern(
    s: ReproduceSettings, ds_fam: Any, spec_row: dict[str, Any]
) -> dict[str, Any]:
    """The eq. 17-19 fit of one family pattern at the main noise level (Fig. 11)."""
    from ..models import fit_blur_model

    name = str(spec_row["name"])
    Wf = np.asarray(ds_fam["blur"].values, dtype=np.float64)
    vf = series(ds_fam, "converged_fraction", name, s.main_noise) >= MIN_CONVERGED
    u = series(ds_fam, "u_e", name, s.main_noise)[vf]
    sg = series(ds_fam, "sssig", name, s.main_noise)[vf]
    ratio = (
        series(ds_fam, "rms_contrast_ref", name, s.main_noise)
        / series(ds_fam, "rms_contrast", name, s.main_noise)
    )[vf]
    Wf = Wf[vf]
    with warnings.catch_warnings():
        # the family table lists each fit's range; the API hint to pass fit_range
        # is not actionable here
        warnings.filterwarnings("ignore", message="edge-driven range")
        fm = fit_blur_model(
            Wf,
            sg,
            u,
            noise_sigma=s.main_noise,
            contrast_ratio=ratio,
            subset=s.subset,
            compare=False,
            default="power_law",
        )
    return {
        "name": name,
        "speckle_size": spec_row["speckle_size"],
        "mig0": float(series(ds_fam, "mig_ref", name, s.main_noise)[0]),
        "u_ref": fm.u_ref,
        "alpha": fm.alpha,
        "beta": fm.beta,
        "mbrf": fm.mbrf,
        "u_e0": float(u[0]),
        "u_e_max": float(u[-1]),
    }


def _write_results(
    out: Path,
    data: StudyData,
    *,
    claims: list[dict[str, Any]],
    figures: list[str],
    versions: dict[str, str],
    timings: dict[str, float],
) -> Path:
    """Write ``results.json`` (every number of the run) and ``command.txt``; return the
    former's path."""
    s, pulse = data.settings, data.pulse
    results = {
        "command": s.command,
        "versions": versions,
        "mode": "quick" if s.quick else "full",
        "settings": {
            "size": s.size,
            "subset": s.subset,
            "poi_step": s.poi_step,
            "blur_step": s.blur_step,
            "noise_levels": list(s.noise_levels),
            "main_noise": s.main_noise,
            "seed": s.seed,
        },
        "patterns": data.static,
        "fits": data.fits.fits,
        "family": data.fits.family,
        "pulse": {
            "table_ii": list(pulse.table),
            "knee": pulse.knee,
            "knee_predicted": pulse.knee_predicted,
            "knee_paper": pulse.knee_paper,
            "fits": [f.__dict__ if hasattr(f, "__dict__") else str(f) for f in pulse.fits],
            "verdict": pulse.verdict,
        },
        "claims": claims,
        "figures": figures,
        "timings": timings,
        "campaign_runs": data.campaigns.runs,
        "compensation": {
            k: (v.tolist() if isinstance(v, np.ndarray) else v)
            for k, v in data.campaigns.compensation.items()
        },
    }
    rj = out / "results.json"
    write_text(rj, json.dumps(_clean(results), indent=2))
    write_text(
        out / "command.txt",
        s.command + "\n\n" + "\n".join(f"{k}: {v}" for k, v in versions.items()) + "\n",
    )
    return rj


def _clean(obj: Any) -> Any:
    """JSON-ready copy: numpy scalars to Python, NaN/inf to None, tuples to lists."""
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_clean(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _clean(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, Path):
        return str(obj)
    if isinstance(obj, str | int | float | bool) or obj is None:
        return obj
    if hasattr(obj, "to_dict"):
        return _clean(obj.to_dict())
    return str(obj)
