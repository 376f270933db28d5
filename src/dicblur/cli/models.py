"""CLI: ``dicblur fit``, ``dicblur predict`` and ``dicblur plan`` (uncertainty models)."""

from __future__ import annotations

import csv
import math
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from ..errors import InputError
from ._common import console, print_json
from .options import (
    FixedNoiseOption,
    JsonOption,
    ModelChoiceOption,
    ModelPathArgument,
    ScaleOption,
    TargetSpeedOption,
)

if TYPE_CHECKING:  # numpy and the models are imported inside the commands (fast --help)
    import numpy as np

_COLUMNS = ("blur", "sssig", "u_e")
# --plot: the formats a figure is saved in (others made matplotlib raise after the plan)
FIGURE_SUFFIXES = (".png", ".pdf", ".svg", ".jpg", ".jpeg", ".tif", ".tiff", ".eps", ".webp")
_OPTIONAL = (
    "noise",
    "noise_effective",
    "contrast_ref",
    "contrast",
    "rms_contrast_ref",
    "rms_contrast",
    "contrast_ratio",
    "converged_fraction",
)
# Coordinates of a campaign (dicblur.campaign.store.DIMS) other than noise, blur and rep:
# one setting is fitted at a time.
_SETTINGS = ("pattern", "angle", "subset", "shape", "step", "noise_model")


# The paper's column names (W, SSSIG, u_e) and the campaign store's (blur, sssig, u_e) are
# both accepted, in any case: names are compared lower-cased, then W means blur.
_ALIASES = {"w": "blur"}


def _canonical(column: str) -> str:
    low = column.strip().lower()
    return _ALIASES.get(low, low)


def _check_noise_column(values: Any, path: Path) -> None:
    """The table's own noise column (the API names it noise_sigma, which the CLI would
    show as --noise, an option the user did not give)."""
    import numpy as np

    v = np.asarray(values, dtype=object)
    for i, x in enumerate(v):
        try:
            ok = math.isfinite(float(x)) and float(x) > 0
        except (TypeError, ValueError):
            ok = False
        if not ok:
            raise InputError(
                f"RESULTS={str(path)!r}: column noise is {x!r} in line {i + 2}; the "
                "noise std must be a number > 0 GL (fix the table, or drop the column and "
                "give --noise)"
            )


def _read_table(path: Path) -> dict[str, np.ndarray]:
    """Columns of a flat CSV, or the flattened variables of a netCDF / zarr dataset."""
    import numpy as np

    if not path.exists():
        raise InputError(f"RESULTS={str(path)!r}: no such file or directory")
    suffix = path.suffix.lower()
    if suffix == ".csv":
        if path.is_dir():
            raise InputError(f"RESULTS={str(path)!r}: is a directory, expected a .csv file")
        try:
            # utf-8-sig: spreadsheets save "CSV UTF-8" with a byte-order mark, which
            # would otherwise stick to the first column's name ("\ufeffblur")
            text = path.read_bytes().decode("utf-8-sig")
        except UnicodeDecodeError:
            raise InputError(
                f"RESULTS={str(path)!r}: binary data, not a UTF-8 CSV text "
                "file; give the CSV of dicblur campaign export"
            ) from None
        if "\0" in text:
            raise InputError(f"RESULTS={str(path)!r}: binary data (NUL bytes), not a CSV text file")
        try:
            lines = text.splitlines()
            head = lines[0] if lines else ""
            # a spreadsheet in a comma-decimal locale separates with ';' (or a tab)
            sep = next((c for c in ",;\t" if c in head), ",")
            rows = list(csv.DictReader(lines, delimiter=sep))
        except csv.Error as exc:
            raise InputError(f"RESULTS={str(path)!r}: not a readable CSV ({exc})") from exc
        if not rows:
            raise InputError(f"RESULTS={str(path)!r}: empty CSV (expected a header and rows)")
        cols: dict[str, np.ndarray] = {}
        seen: dict[str, str] = {}
        for key in rows[0]:
            if key is None:
                raise InputError(f"RESULTS={str(path)!r}: a row has more fields than the header")
            name = _canonical(key)
            if name in seen:
                raise InputError(
                    f"RESULTS={str(path)!r}: columns {seen[name]!r} and {key!r} "
                    f"both mean {name!r}; keep one"
                )
            seen[name] = key
            values = [r[key] if r[key] is not None else "" for r in rows]
            try:
                cols[name] = np.array([float(v) if v != "" else math.nan for v in values])
            except ValueError:
                cols[name] = np.array(values, dtype=object)
        return cols
    if suffix in (".nc", ".netcdf", ".zarr", ".h5") or path.is_dir():
        import xarray as xr

        try:
            # consolidated=False, as the store reads itself: a campaign store has no
            # consolidated metadata, and xarray's fallback warns in six lines
            ds = (
                xr.open_zarr(path, consolidated=False)
                if suffix == ".zarr" or path.is_dir()
                else xr.open_dataset(path)
            )
        except Exception as exc:  # xarray raises many types for unreadable files
            raise InputError(f"RESULTS={str(path)!r}: cannot open as netCDF/zarr ({exc})") from exc
        if "u_e" not in ds:
            raise InputError(f"RESULTS={str(path)!r}: no 'u_e' variable in the dataset")
        template = ds["u_e"]
        out: dict[str, np.ndarray] = {}
        for name in (*template.dims, *_COLUMNS[1:], *_OPTIONAL):
            if name in ds.variables:
                arr = np.asarray(ds[name].broadcast_like(template).values).ravel()
                out[name] = arr if np.issubdtype(arr.dtype, np.number) else arr.astype(object)
        return out
    raise InputError(f"RESULTS={str(path)!r}: unknown format; use .csv, .nc or .zarr")


def _aggregate(cols: dict[str, np.ndarray], select: list[str]) -> dict[str, np.ndarray]:
    """Filter by ``--select key=value``, then one row per (noise, blur): SSSIG and contrast
    averaged, u_e pooled as the root mean square over repetitions."""
    import numpy as np

    from ..models import check_measurements

    missing = [c for c in _COLUMNS if c not in cols]
    if missing:
        raise InputError(
            f"RESULTS: missing column(s) {missing}; the table needs blur (or W), sssig and "
            "u_e, in any case "
            f"(optional: {', '.join(_OPTIONAL)})"
        )
    mask = np.ones(cols["u_e"].size, dtype=bool)
    for item in select:
        key, sep, value = item.partition("=")
        key = _canonical(key)
        if not sep or key not in cols:
            raise InputError(
                f"--select {item!r}: expected COLUMN=VALUE with a column of "
                f"RESULTS ({sorted(cols)})"
            )
        col = cols[key]
        if col.dtype == object:
            mask &= col == value
        else:
            try:
                number = float(value)
            except ValueError:
                raise InputError(
                    f"--select {item!r}: column {key} holds numbers; give a number, e.g. "
                    f"'{key}={float(col[0]):g}'"
                ) from None
            mask &= np.isclose(col.astype(float), number)
    keep = {k: v[mask] for k, v in cols.items()}
    if not mask.any():
        raise InputError(f"--select {' '.join(select)!r}: no row matches")
    for key, col in keep.items():
        if (key in _SETTINGS or col.dtype == object) and np.unique(col.astype(str)).size > 1:
            raise InputError(
                f"RESULTS: column {key!r} has several values; fit one setting at a time "
                f"with --select {key}=VALUE"
            )
    # the API's checks (fit_blur_model: u_e, SSSIG finite and > 0) on every row, before
    # the RMS over repetitions hides a sign; rows without u_e (unfinished tasks) are dropped
    ue = keep["u_e"]
    if ue.dtype == object:
        check_measurements(u_e=ue)
    ok = np.isfinite(ue.astype(float))
    if not ok.any():
        raise InputError(
            f"RESULTS: u_e has no finite value ({ue.size} row(s), all NaN or "
            "infinite); export a campaign with finished tasks"
        )
    check_measurements(u_e=ue[ok], sssig=keep["sssig"][ok])
    if not ok.all():
        warnings.warn(f"{int((~ok).sum())} row(s) without u_e dropped", stacklevel=2)
    if "noise" in keep:
        noise = keep["noise"].astype(float)
    elif "noise_effective" in keep:
        noise = keep["noise_effective"].astype(float)
    else:
        noise = np.zeros(keep["u_e"].size)
    blur = keep["blur"].astype(float)
    out: dict[str, list[float]] = {
        k: [] for k in ("blur", "sssig", "u_e", "noise", "contrast_ratio", "converged_fraction")
    }
    # without a contrast_ratio column, the ratio of a contrast pair (reference / blurred):
    # RMS contrast first, it tracks blur-induced contrast loss (campaign stores it)
    contrasts = next(
        (
            (ref, cur)
            for ref, cur in (("rms_contrast_ref", "rms_contrast"), ("contrast_ref", "contrast"))
            if ref in keep and cur in keep
        ),
        None,
    )
    for nz in np.unique(noise[ok]):
        for w in np.unique(blur[ok & (noise == nz)]):
            sel = ok & (noise == nz) & (blur == w)
            out["blur"].append(float(w))
            # the campaign's effective per-image noise (per-subframe noise is sigma /
            # sqrt(K + 1)) is what the models need; the nominal level groups the rows
            eff = keep.get("noise_effective")
            out["noise"].append(
                float(np.mean(eff[sel].astype(float))) if eff is not None else float(nz)
            )
            out["sssig"].append(float(np.mean(keep["sssig"][sel].astype(float))))
            out["u_e"].append(float(np.sqrt(np.mean(keep["u_e"][sel].astype(float) ** 2))))
            if "converged_fraction" in keep:  # the worst repetition decides breakdown
                out["converged_fraction"].append(
                    float(np.min(keep["converged_fraction"][sel].astype(float)))
                )
            if "contrast_ratio" in keep:
                out["contrast_ratio"].append(float(np.mean(keep["contrast_ratio"][sel])))
            elif contrasts is not None:
                ref, cur = contrasts
                ratio = keep[ref][sel].astype(float) / keep[cur][sel].astype(float)
                out["contrast_ratio"].append(float(np.mean(ratio)))
    res = {k: np.array(v) for k, v in out.items() if v}
    if "noise" not in cols and "noise_effective" not in cols:
        res.pop("noise")
    if "subset" in keep and keep["subset"].dtype != object:
        res["subset"] = np.array([float(keep["subset"][0])])
    for key in ("shape", "pattern"):  # recorded in the model's validity domain
        if key in keep and keep[key].size:
            res[key] = np.array([str(keep[key][0])], dtype=object)
    return res


def fit_command(
    results: Path = typer.Argument(..., help="Campaign results: .csv, .nc or .zarr."),
    out: Path = typer.Option(..., "-o", "--out", help="Output model file (.json)."),
    select: list[str] = typer.Option([], "--select", help="Keep rows with COLUMN=VALUE."),
    noise: float | None = typer.Option(None, "--noise", help="Noise std (GL) if no column."),
    subset: int | None = typer.Option(None, "--subset", help="Subset size (px), recorded."),
    fit_range: str | None = typer.Option(
        None, "--fit-range", help="Power-law W range 'LO:HI' px (default: auto)."
    ),
    ci: str = typer.Option("covariance", "--ci", help="covariance or bootstrap."),
    default: str = typer.Option(
        "mismatch",
        "--default",
        help="mismatch (noise + blur mismatch), power_law (eq. 17, "
        "at the fitted noise only) or auto (held-out comparison).",
    ),
    seed: int | None = typer.Option(None, "--seed", help="Bootstrap seed."),
    as_json: bool = typer.Option(False, "--json", help="Print the model JSON."),
    compensation: str | None = typer.Option(
        None,
        "--compensation",
        help="Matcher of the data: none, given, estimate or deblur (default: the "
        "campaign's dic.compensation for a .zarr store, else none).",
    ),
) -> None:
    """Fit the uncertainty models to RESULTS and write the model JSON."""
    from ..checks import check_odd_subset, check_seed
    from ..io import check_output, file_sha256
    from ..models import fit_blur_model

    check_output(out, "--out", inputs=(results,))
    check_seed(seed, "--seed")
    if subset is not None:
        check_odd_subset(subset, "--subset")
    table = _read_table(results)
    if "noise" in table and results.suffix.lower() == ".csv":
        _check_noise_column(table["noise"], results)
    data = _aggregate(table, select)
    rng = None
    if fit_range is not None:
        lo, _, hi = fit_range.partition(":")
        try:
            rng = (float(lo), float(hi))
        except ValueError as exc:
            raise InputError(f"--fit-range={fit_range!r}: expected LO:HI in px, e.g. 0:4") from exc
    sigma: Any = data.get("noise", noise)
    mode = _results_compensation(results, compensation)
    model = fit_blur_model(
        data["blur"],
        data["sssig"],
        data["u_e"],
        noise_sigma=sigma,
        contrast_ratio=data.get("contrast_ratio"),
        subset=subset if subset is not None or "subset" not in data else int(data["subset"][0]),
        fit_range=rng,
        ci=ci,
        default=default,
        seed=seed,
        converged_fraction=data.get("converged_fraction"),
        shape=str(data["shape"][0]) if "shape" in data else None,
        pattern=str(data["pattern"][0]) if "pattern" in data else None,
        compensation=mode,
        provenance={
            "results": str(results),
            "select": list(select),
            "results_sha256": file_sha256(results) if results.is_file() else None,
        },
    )
    model.to_json(str(out))
    if as_json:
        typer.echo(model.to_json())
    else:
        typer.echo(model.report())
        typer.echo(f"wrote {out}")


def _results_compensation(results: Path, given: str | None) -> str:
    """The matcher mode of RESULTS: ``--compensation``, else a campaign store's spec."""
    from ..models.domain import COMPENSATIONS

    if given is not None:
        if given not in COMPENSATIONS:
            raise InputError(
                f"--compensation={given!r}: choose {', '.join(COMPENSATIONS[:-1])} or deblur"
            )
        return given
    if results.is_dir() or results.suffix.lower() == ".zarr":
        import json

        import xarray as xr

        try:
            spec = json.loads(xr.open_zarr(results, consolidated=False).attrs.get("spec", "{}"))
        except Exception:  # not a campaign store: no recorded mode
            return "none"
        mode = spec.get("dic", {}).get("compensation", "none") if isinstance(spec, dict) else "none"
        return mode if mode in COMPENSATIONS else "none"
    return "none"


def predict_command(
    model_path: ModelPathArgument,
    blur: list[float] = typer.Option([], "--blur", help="Blur length W, px (repeatable)."),
    velocity: TargetSpeedOption = None,
    exposure: str | None = typer.Option(None, "--exposure", help="e.g. 1ms."),
    scale: ScaleOption = None,
    noise: FixedNoiseOption = None,
    which: ModelChoiceOption = None,
    as_json: JsonOption = False,
) -> None:
    """Predict u_e at blur lengths (--blur) or from velocity x exposure / scale."""
    from ..blur import blur_length
    from ..models import BlurUncertaintyModel, parse_quantity

    model = BlurUncertaintyModel.from_json(str(model_path))
    ws = list(blur)
    if velocity is not None or exposure is not None or scale is not None:
        if velocity is None or exposure is None or scale is None:
            raise InputError("--velocity, --exposure and --scale: give all three (or --blur)")
        sc = parse_quantity(scale, "scale", name="--scale")
        if sc <= 0:
            raise InputError(f"--scale={scale!r}: must be > 0")
        v = parse_quantity(velocity, "velocity", name="--velocity", scale=sc)
        t = parse_quantity(exposure, "time", name="--exposure")
        if t < 0:
            raise InputError(f"--exposure={exposure!r}: must be >= 0")
        ws.append(blur_length(v, t, sc))  # W = |v| t / scale
    if not ws:
        raise InputError("--blur: give at least one blur length (px) or velocity/exposure/scale")
    pred = model.predict(ws, noise, model=which)
    assert pred.inside_domain is not None and pred.broken_down is not None
    rows = [
        {
            "blur_px": float(w),
            "u_e_px": float(u),
            "low_px": float(lo),
            "high_px": float(hi),
            "inside_domain": bool(ins),
            "broken_down": bool(brk),
        }
        for w, u, lo, hi, ins, brk in zip(
            pred.blur,
            pred.u_e,
            pred.low,
            pred.high,
            pred.inside_domain,
            pred.broken_down,
            strict=True,
        )
    ]
    _warn_notes(pred.notes)
    if as_json:
        print_json(
            {
                "model": pred.model,
                "compensation": pred.compensation,
                "sigma": pred.sigma,
                "confidence": pred.confidence,
                "extrapolated": pred.extrapolated,
                "notes": list(pred.notes),
                "domain": model.domain.to_dict() if model.domain else None,
                "predictions": rows,
            }
        )
        return
    pct = f"{100 * pred.confidence:g}%"
    typer.echo(f"matcher: {model.matcher}")
    for r in rows:
        if r["broken_down"]:
            typer.echo(f"W = {r['blur_px']:.4g} px: no prediction (DIC breaks down) [{pred.model}]")
            continue
        flag = "" if r["inside_domain"] else " (extrapolated)"
        typer.echo(
            f"W = {r['blur_px']:.4g} px: u_e = {r['u_e_px']:.4g} px "
            f"({pct} prediction interval {r['low_px']:.4g} .. {r['high_px']:.4g}) "
            f"[{pred.model}]{flag}"
        )


def plan_command(
    model_path: ModelPathArgument,
    velocity: TargetSpeedOption = None,
    scale: ScaleOption = None,
    target: str | None = typer.Option(None, "--target", help="Largest u_e, e.g. 0.01px."),
    full_well: float | None = typer.Option(None, "--full-well", help="Full well, e-."),
    read_noise: float | None = typer.Option(None, "--read-noise", help="Read noise, e-."),
    flux: float | None = typer.Option(
        None, "--flux", help="e-/s at the pattern's mean grey level."
    ),
    peak_to_mean: float = typer.Option(2.0, "--peak-to-mean", help="Brightest / mean grey level."),
    noise: FixedNoiseOption = None,
    reference: Path | None = typer.Option(
        None,
        "--reference",
        help="Reference image of the specimen: shot noise at its gradient-weighted level.",
    ),
    noise_level: float | None = typer.Option(
        None,
        "--noise-level",
        help="Grey level (of the fitted images) at which shot noise is evaluated.",
    ),
    which: ModelChoiceOption = None,
    plot: Path | None = typer.Option(None, "--plot", help="Write u_e(exposure) figure."),
    html_out: Path | None = typer.Option(
        None,
        "--html",
        help="Write an interactive planner page (one self-contained HTML "
        "file; the options given here are its starting values).",
    ),
    as_json: JsonOption = False,
    compare: Path | None = typer.Option(
        None,
        "--compare",
        help="A second model of the same calibration with another matcher mode (e.g. "
        "calibrate --compensation given): plan both and state the gain of compensation.",
    ),
    vsg: str | None = typer.Option(
        None,
        "--vsg",
        help="With a strain --target (e.g. 100microstrain): the strain window, in grid "
        "points (5) or px (41px = (N - 1) x step + subset); default 5.",
    ),
    step: int = typer.Option(10, "--step", help="POI grid step of the strain plan, px."),
    subset: int | None = typer.Option(
        None, "--subset", help="Subset of the strain plan, px (when the model records none)."
    ),
) -> None:
    """Plan the exposure: longest under --target, or the optimum with a camera.

    A strain target (--target 100microstrain, with --vsg and --step) plans the longest
    exposure whose predicted sigma_exx meets it, and --plot shows the VSG trade-off.

    With --html (alone, or with the other options as starting values), writes a planner
    page that computes the same answers in the browser as the controls change. With
    --compare, the plan with blur compensation is set against the one without.
    """
    import numpy as np

    from ..io import check_output, load_image
    from ..models import (
        BlurUncertaintyModel,
        PoissonGaussianCamera,
        gradient_weighted_level,
        plan_exposure,
    )

    sources = tuple(p for p in (model_path, compare, reference) if p is not None)
    if plot is not None:
        check_output(plot, "--plot", suffixes=FIGURE_SUFFIXES, inputs=sources)
    if html_out is not None:
        check_output(html_out, "--html", suffixes=(".html", ".htm"), inputs=sources)
    from .strain_plan import is_strain_target, run_strain_plan

    if vsg is not None or is_strain_target(target):
        cam = {"--full-well": full_well, "--read-noise": read_noise, "--flux": flux}
        run_strain_plan(
            model_path, velocity=velocity, scale=scale, target=target, vsg=vsg, step=step,
            subset=subset, noise=noise, which=which, plot=plot, as_json=as_json,
            html_out=html_out, unsupported={**cam, "--compare": compare,
                         "--reference": reference, "--noise-level": noise_level},
        )  # fmt: skip
        return
    if (velocity is None or scale is None) and html_out is None:
        raise InputError(
            "--velocity, --scale: give both (e.g. --velocity 120mm/s --scale "
            "0.05mm/px), or --html planner.html for the interactive page"
        )
    model = BlurUncertaintyModel.from_json(str(model_path))
    other = None
    if compare is not None:
        from ..models import check_same_calibration

        other = BlurUncertaintyModel.from_json(str(compare))
        if other.compensation == model.compensation:
            raise InputError(
                f"--compare={str(compare)!r}: both models use the {model.matcher}; give "
                "one calibrated with blur compensation (dicblur calibrate --compensation "
                "given) and one without"
            )
        check_same_calibration(model, other, names=("MODEL", "--compare"))
    noise_note = None
    if html_out is not None:
        from ..models import parse_quantity
        from ..report.planner import PlannerDefaults, starting_noise, write_planner

        # the page's starting values are read in the browser: check them here, or a typo
        # (--velocity 12GL) writes a page that opens on an error
        mm_px = parse_quantity(scale or "0.05mm/px", "scale", name="--scale")
        if velocity is not None:
            parse_quantity(velocity, "velocity", name="--velocity", scale=mm_px)
        if target is not None:
            parse_quantity(target, "blur", name="--target", scale=mm_px)
        defaults = PlannerDefaults(
            velocity=velocity or "120mm/s",
            scale=scale or "0.05mm/px",
            target=target or "0.01px",
            noise=noise,
            full_well=full_well,
            read_noise=read_noise,
            flux=flux,
        )
        write_planner(
            [model] if other is None else [model, other], html_out, labels=None, defaults=defaults
        )
        typer.echo(f"wrote {html_out}")
        if velocity is None or scale is None:
            return
        if noise is None and model.noise_sigma is None and model.noise_levels:
            # the page chooses the noise; the text plan takes the page's starting value
            # (used only without a camera) and says which
            noise = starting_noise(model)
            levels = ", ".join(f"{v:g}" for v in model.noise_levels)
            noise_note = (
                f"note: the text plan at --noise {noise:g} (GL; the page's starting value, "
                f"the model was calibrated at {levels} GL); give --noise to plan at another"
            )
    if reference is not None and noise_level is not None:
        raise InputError(
            "--reference, --noise-level: give one (the image's level is computed from it)"
        )
    mean_level: float | None = None
    if reference is not None:
        # the image's gradient-weighted level relative to its mean, on the model's scale;
        # a model that does not record its mean level takes the reference's own
        img = load_image(reference)
        base = model.mean_level if model.mean_level is not None else float(np.mean(img))
        if model.mean_level is None:
            mean_level = base
        try:
            level = gradient_weighted_level(img)
        except InputError as exc:
            raise InputError(f"--reference={str(reference)!r}: {exc}") from None
        noise_level = level / float(np.mean(img)) * base
    camera = None
    cam_opts = (full_well, read_noise, flux)
    if any(o is not None for o in cam_opts):
        if any(o is None for o in cam_opts):
            raise InputError(
                "--full-well, --read-noise and --flux: give all three for a "
                "Poisson-Gaussian camera (or none for fixed noise)"
            )
        camera = PoissonGaussianCamera(
            full_well=float(full_well),  # type: ignore[arg-type]
            read_noise=float(read_noise),  # type: ignore[arg-type]
            flux=float(flux),  # type: ignore[arg-type]
            peak_to_mean=peak_to_mean,
        )
    if noise_level is not None and camera is None:
        raise InputError(
            "--reference/--noise-level: only with a camera (--full-well, "
            "--read-noise, --flux); with fixed noise give --noise"
        )
    assert velocity is not None and scale is not None
    if noise_note is not None and camera is None:
        typer.echo(noise_note, err=True)
    kwargs: dict[str, Any] = {
        "velocity": velocity,
        "scale": scale,
        "target": target,
        "camera": camera,
        "sigma": noise if camera is None or noise_note is None else None,
        "which": which,
        "noise_level": noise_level,
        "mean_level": mean_level,
    }
    comparison = None
    if other is not None:
        from ..models import compare_plans

        comparison = compare_plans(model, other, names=("MODEL", "--compare"), **kwargs)
        plans = [comparison.baseline, comparison.compensated]
        plan = plans[0] if comparison.baseline_compensation == model.compensation else plans[1]
    else:
        plans = [plan := plan_exposure(model, **kwargs)]
    for p in plans:
        if not p.inside_domain or p.limited_by_breakdown:
            _warn_notes(
                [
                    n
                    for n in p.notes
                    if "outside the model's validity domain" in n or "breaks down" in n
                ]
            )
    if as_json:
        print_json(plan.to_dict() if comparison is None else comparison.to_dict())
    elif comparison is None:
        console.print(plan.summary())
    else:
        console.print(comparison.summary())
    if plot is not None:
        from ..report.plots import plan_figure

        plan_figure(
            plan,
            plot,
            other=None if comparison is None else next(p for p in plans if p is not plan),
        )
        typer.echo(f"wrote {plot}")


def _warn_notes(notes: Any) -> None:
    """Each extrapolation / breakdown note as one visible line on stderr."""
    for note in notes:
        typer.echo(f"warning: {note}", err=True)


def register(app: typer.Typer) -> None:
    """Attach ``fit``, ``predict`` and ``plan`` to the root app."""
    app.command("fit")(fit_command)
    app.command("predict")(predict_command)
    app.command("plan")(plan_command)
