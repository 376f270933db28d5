"""CLI: ``dicblur correlate REF CUR`` (subset DIC of two images, issue 4)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ._common import console, notice_compile, print_mapping

_UNITS = {"mean_u": "px", "std_u": "px", "mean_v": "px", "std_v": "px",
          "predicted_sigma_u": "px", "predicted_sigma_v": "px", "prepare_s": "s",
          "compile_s": "s", "correlate_s": "s", "points_per_s": "POI/s"}


def correlate_command(
    reference: Annotated[Path, typer.Argument(help="Reference image (TIFF, PNG, BMP).")],
    current: Annotated[Path, typer.Argument(help="Current (deformed) image, same size.")],
    subset: Annotated[int, typer.Option("--subset", help="Odd subset size, px.")] = 21,
    step: Annotated[int, typer.Option("--step", help="POI grid step, px.")] = 10,
    shape: Annotated[str, typer.Option("--shape", help="affine or translation.")] = "affine",
    interpolation: Annotated[str, typer.Option("--interpolation",
                                               help="bspline3 or bspline5.")] = "bspline3",
    noise: Annotated[float | None, typer.Option(
        "--noise", help="Noise std (grey levels) for the predicted sigma.")] = None,
    workers: Annotated[int | None, typer.Option("--workers",
                                                help="Threads (default: all).")] = None,
    out: Annotated[Path | None, typer.Option(
        "-o", "--out", help="Write the field to .nc (netCDF) or .csv.")] = None,
    median_test: Annotated[bool, typer.Option(
        "--median-test", help="Flag OUTLIER points: normalised median test of the field "
        "(eps 0.1 px, threshold 2) and a probe of the neighbours' displacement.")] = False,
) -> None:
    """Measure the displacement field of CURRENT against REFERENCE and print a summary."""
    from ..dic import Correlator
    from ..io import atomic_path, check_output, load_image

    if out is not None:
        check_output(out, "--out", suffixes=(".nc", ".csv"))
    import time

    ref = load_image(reference)
    cur = load_image(current)
    corr = Correlator(ref, subset=subset, step=step, shape=shape,  # type: ignore[arg-type]
                      interpolation=interpolation, noise_sigma=noise, workers=workers,
                      median_test=median_test)
    notice_compile(shape)
    compile_s = corr.warmup()
    t0 = time.perf_counter()
    res = corr.correlate(cur)
    dt = time.perf_counter() - t0
    data = res.summary()
    data.update({"prepare_s": corr.prepare_time_s, "compile_s": compile_s,
                 "correlate_s": dt, "points_per_s": len(res) / dt if dt > 0 else None})
    print_mapping(f"correlate: {reference.name} -> {current.name} ({shape}, subset {subset})",
                  data, _UNITS)
    if out is not None:
        if out.suffix.lower() == ".csv":
            res.to_csv(out)
        else:
            with atomic_path(out) as tmp:
                res.to_xarray().to_netcdf(tmp, engine="scipy")
        console.print(f"wrote {out}")


def register(app: typer.Typer) -> None:
    """Attach ``correlate`` to the root app."""
    app.command("correlate")(correlate_command)
