"""CLI: ``dicblur correlate REF CUR`` (subset DIC of two images, issue 4)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from ..errors import InputError
from ._common import console, notice_compile, parse_max_sigma, print_mapping, strain_option
from .options import (
    AngleOption,
    MaxSigmaOption,
    ShapeOption,
    StepOption,
    SubsetOption,
    VsgOption,
)

_UNITS = {
    "mean_u": "px",
    "std_u": "px",
    "mean_v": "px",
    "std_v": "px",
    "predicted_sigma_u": "px",
    "noise_sigma": "GL",
    "noise_sigma_95%": "GL",
    "predicted_sigma_v": "px",
    "prepare_s": "s",
    "compile_s": "s",
    "correlate_s": "s",
    "points_per_s": "POI/s",
    "blur_length_mean": "px",
    "blur_length_std": "px",
    "strain_vsg": "px",
}


def correlate_command(
    reference: Annotated[Path, typer.Argument(help="Reference image (TIFF, PNG, BMP).")],
    current: Annotated[Path, typer.Argument(help="Current (deformed) image, same size.")],
    subset: SubsetOption = 21,
    step: StepOption = 10,
    shape: ShapeOption = "affine",
    interpolation: Annotated[
        str, typer.Option("--interpolation", help="bspline3 or bspline5.")
    ] = "bspline3",
    noise: Annotated[
        float | None,
        typer.Option(
            "--noise",
            help="Noise std (grey levels) for the predicted sigma and the screening "
            "(default: estimated from the pair's residuals; given with --blur-compensation).",
        ),
    ] = None,
    workers: Annotated[
        int | None, typer.Option("--workers", help="Threads (default: all).")
    ] = None,
    out: Annotated[
        Path | None, typer.Option("-o", "--out", help="Write the field to .nc (netCDF) or .csv.")
    ] = None,
    median_test: Annotated[
        bool,
        typer.Option(
            "--median-test",
            help="Flag OUTLIER points: normalised median test of the field "
            "(eps 0.1 px, threshold 2) and a probe of the neighbours' displacement.",
        ),
    ] = False,
    max_predicted_sigma: MaxSigmaOption = None,
    blur_compensation: Annotated[
        str,
        typer.Option(
            "--blur-compensation",
            help="none, given (needs --blur) or estimate (blur length per subset).",
        ),
    ] = "none",
    blur: Annotated[
        float | None,
        typer.Option(
            "--blur", help="Blur length W during the exposure, px (given; estimate: start)."
        ),
    ] = None,
    angle: AngleOption = 0.0,
    strain: Annotated[
        bool,
        typer.Option(
            "--strain",
            help="Also strains (Green-Lagrange) and, with --noise, their sigmas (docs/strain.md).",
        ),
    ] = False,
    vsg: VsgOption = "5",
) -> None:
    """Measure the displacement field of CURRENT against REFERENCE and print a summary."""
    import math

    import numpy as np

    from ..dic import Correlator
    from ..io import atomic_path, check_output, load_image

    if out is not None:
        check_output(out, "--out", suffixes=(".nc", ".csv"), inputs=(reference, current))
    import time

    mode = blur_compensation.strip().lower()
    if mode not in ("none", "given", "estimate"):
        raise InputError(f"--blur-compensation={blur_compensation!r}: use none, given or estimate")
    if blur is not None and not (math.isfinite(blur) and blur >= 0):
        raise InputError(f"--blur={blur}: the blur length must be a finite number >= 0 px")
    if not math.isfinite(angle):
        raise InputError(f"--angle={angle}: must be a finite number of degrees")
    if mode == "given" and blur is None:
        raise InputError(
            "--blur-compensation=given: give the blur length with --blur W "
            "(px) and its direction with --angle (degrees)"
        )
    if mode == "none" and blur is not None:
        raise InputError(f"--blur={blur}: only used with --blur-compensation given or estimate")
    if noise is not None and noise == 0:
        # the API takes 0 (noise-free synthetic images); a camera image is never free of
        # noise, and a zero noise would switch the residual screen off
        raise InputError(
            "--noise=0: a camera image always carries noise (8-bit rounding alone is 0.29 GL)"
            " and zero switches the residual screen off; give the noise std in GL, or leave"
            " out --noise to estimate it from the pair"
        )
    window = strain_option(strain, vsg, step=step, subset=subset)
    extra: dict[str, float | None] = {}
    if max_predicted_sigma is not None:
        extra["max_predicted_sigma"] = parse_max_sigma(max_predicted_sigma)
        if noise is None and mode != "none" and extra["max_predicted_sigma"] is not None:
            raise InputError(
                f"--max-predicted-sigma={max_predicted_sigma!r}: needs --noise (grey levels) "
                "with --blur-compensation: the predicted random error comes from the noise "
                "level (estimated only without compensation)"
            )
    vector = None
    if blur is not None and (mode == "given" or blur > 0):
        rad = math.radians(angle)
        vector = (blur * math.sin(rad), blur * math.cos(rad))
    ref = load_image(reference)
    cur = load_image(current)
    corr = Correlator(
        ref,
        subset=subset,
        step=step,
        shape=shape,  # type: ignore[arg-type]
        interpolation=interpolation,
        noise_sigma="auto" if noise is None else noise,
        workers=workers,
        median_test=median_test,
        blur=mode,  # type: ignore[arg-type]
        **extra,  # type: ignore[arg-type]
    )
    if window is not None:
        from ..strain import check_window_fits, grid_of

        # before the work: the window must fit the Correlator's POI grid
        grid, _, _ = grid_of(corr.rows, corr.cols)
        check_window_fits(window, grid, step=step, subset=subset, name="--vsg")
    notice_compile(shape)
    compile_s = corr.warmup()
    t0 = time.perf_counter()
    if mode == "none":
        res = corr.correlate(cur)
    elif mode == "given":
        res = corr.correlate(cur, blur_vector=vector)
    else:
        res = corr.correlate(
            cur, blur_vector=vector, blur_angle=None if vector is not None else angle
        )
    dt = time.perf_counter() - t0
    data = res.summary()
    if res.blur_length is not None and res.blur_identified is not None:
        ident = res.blur_identified
        data["blur_length_mean"] = float(np.mean(res.blur_length[ident])) if ident.any() else None
        data["blur_length_std"] = (
            float(np.std(res.blur_length[ident], ddof=1)) if ident.sum() > 1 else None
        )
        data["blur_identified_fraction"] = float(ident.mean())
    nz = corr.noise
    if nz is None and noise is None and mode == "none":
        data["noise_source"] = "unknown (too few converged subsets to estimate: give --noise)"
    if nz is not None:
        # the noise the predictions and the screening used: given, or estimated (interval)
        data["noise_sigma"] = nz.sigma
        data["noise_source"] = "estimated (pair residuals)" if nz.estimated else "given"
        if nz.estimated:
            data["noise_sigma_95%"] = f"{nz.low:.3g}-{nz.high:.3g}"
    data.update(
        {
            "prepare_s": corr.prepare_time_s,
            "compile_s": compile_s,
            "correlate_s": dt,
            "points_per_s": len(res) / dt if dt > 0 else None,
        }
    )
    strain_vars = None
    if window is not None:
        from ..strain import strain as strain_of

        sf = strain_of(res, window=window)
        strain_vars = sf.variables()
        data.update(strain_summary(sf))
    print_mapping(
        f"correlate: {reference.name} -> {current.name} ({shape}, subset {subset})", data, _UNITS
    )
    for note in failure_notes(data):
        typer.echo(f"warning: {note}", err=True)
    if out is not None:
        if out.suffix.lower() == ".csv":
            res.to_csv(out, extra=strain_vars)
        else:
            with atomic_path(out) as tmp:
                ds = res.to_xarray(extra=strain_vars)
                if window is not None:
                    ds.attrs.update(strain_window=window, strain_vsg=sf.vsg, strain_kind=sf.kind)
                ds.to_netcdf(tmp, engine="scipy")
        console.print(f"wrote {out}")


def failure_notes(data: dict[str, Any]) -> list[str]:
    """What the summary table alone would hide: no point converged, no strain computed
    (its rows then read ``-``, which also means "not asked for")."""
    notes = []
    n = int(data.get("n_points") or 0)
    if n and not data.get("n_converged"):
        why = sorted(
            (
                (int(v), k[2:])
                for k, v in data.items()
                if k.startswith("n_") and k not in ("n_points", "n_converged") and v
            ),
            reverse=True,
        )
        causes = ", ".join(f"{c} {name.replace('_', ' ')}" for c, name in why)
        notes.append(
            f"no point converged ({n} of {n} failed: {causes}); the field holds no "
            "displacement: are both images of the same scene, and is the motion smaller "
            "than the subset?"
        )
    elif data.get("strain_ok_fraction") == 0.0:
        notes.append(
            "no strain computed at any point (each needs a full --vsg window of converged "
            "points around it): use a smaller --step or --vsg, or more points"
        )
    return notes


def strain_summary(sf: Any) -> dict[str, Any]:
    """Rows of the summary table for a strain field: VSG, medians over the OK points."""
    import numpy as np

    ok = sf.status == 0
    out: dict[str, Any] = {"strain_vsg": sf.vsg, "strain_ok_fraction": float(ok.mean())}
    names = ["exx", "eyy", "exy", "sigma_exx"]
    for name in names:
        val = getattr(sf, name)
        if val is not None and ok.any():
            out[f"median_{name}"] = float(np.median(val[ok]))
    return out


def register(app: typer.Typer) -> None:
    """Attach ``correlate`` to the root app."""
    app.command("correlate")(correlate_command)
