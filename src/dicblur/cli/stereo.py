"""CLI: ``dicblur stereo calibrate`` and ``dicblur stereo track`` (issue 29, docs/stereo.md)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..errors import InputError
from ._common import (
    all_threads,
    check_track_choices,
    console,
    parse_size,
    print_mapping,
    progress_bar,
    track_store,
)
from .options import (
    FixedNoiseOption,
    FramesOption,
    JsonOption,
    ModelChoiceOption,
    ModelPathArgument,
    OutFolderOption,
    RecordingExposureOption,
    RecordingFpsOption,
    ReferenceFrameOption,
    ReportOption,
    RigOption,
    ShapeOption,
    StaticFramesOption,
    StepOption,
    StoreFormatOption,
    SubsetOption,
)

stereo_app = typer.Typer(
    help="Stereo DIC: calibrate a camera rig, track two recordings in 3-D with sigma.",
    no_args_is_help=True,
    rich_markup_mode=None,
)


def _board(text: str) -> tuple[int, int]:
    try:
        cols, rows = parse_size(text, "--board")
    except InputError:
        raise InputError(f"--board={text!r}: expected inner corners COLSxROWS, e.g. 9x6") from None
    if min(cols, rows) < 3:
        raise InputError(f"--board={text!r}: at least 3x3 inner corners, e.g. 9x6")
    return cols, rows


@stereo_app.command("calibrate")
def calibrate_command(
    images: Annotated[
        list[str],
        typer.Argument(
            help="Checkerboard image pairs: files named left_*/right_* (any case), or two "
            "folders LEFT RIGHT."
        ),
    ],
    out: Annotated[Path, typer.Option("-o", "--out", help="Rig file: .json, .yml or .xml.")],
    board: Annotated[
        str, typer.Option("--board", help="Inner corners per row x per column, e.g. 9x6.")
    ] = "9x6",
    square: Annotated[
        str, typer.Option("--square", help="Side of a square, e.g. 5mm (a bare number is mm).")
    ] = "5mm",
    k3: Annotated[bool, typer.Option("--k3", help="Also estimate the k3 distortion term.")] = False,
) -> None:
    """Calibrate a stereo rig from checkerboard image pairs (OpenCV): intrinsics and
    distortion of each camera, then R and T; prints the RMS reprojection error."""
    from ..models import parse_quantity
    from ..stereo.calibrate import calibrate_rig, load_pairs, pair_images
    from ..stereo.camera import save_rig

    size = _board(board)
    sq = parse_quantity(square, "length", name="--square")
    if not sq > 0:
        raise InputError(f"--square={square!r}: must be > 0, e.g. 5mm")
    if out.suffix.lower() not in (".json", ".yml", ".yaml", ".xml"):
        raise InputError(f"--out={str(out)!r}: use a .json, .yml, .yaml or .xml file name")
    if not out.parent.exists():
        raise InputError(f"--out={str(out)!r}: the folder {str(out.parent)!r} does not exist")
    pairs = pair_images(images)
    rig = calibrate_rig(
        load_pairs(pairs),
        board=size,
        square=sq,
        names=[(str(a), str(b)) for a, b in pairs],
        k3=k3,
    )
    save_rig(rig, out)
    print_mapping(
        "stereo calibrate",
        {
            "pairs": len(pairs),
            "rms": rig.rms,
            "rms_left": float(rig.info["rms_left_px"]),
            "rms_right": float(rig.info["rms_right_px"]),
            "baseline": rig.baseline,
            "stereo_angle": rig.stereo_angle,
            "fx_left": rig.left.fx,
            "fx_right": rig.right.fx,
        },
        {
            "rms": "px",
            "rms_left": "px",
            "rms_right": "px",
            "baseline": "mm",
            "stereo_angle": "deg",
            "fx_left": "px",
            "fx_right": "px",
        },
    )
    console.print(f"wrote {out}")


@stereo_app.command("track")
def track_command(
    left: Annotated[str, typer.Argument(help="Left recording (as dicblur track reads them).")],
    right: Annotated[str, typer.Argument(help="Right recording, synchronised with the left.")],
    rig: RigOption,
    out: OutFolderOption,
    exposure: RecordingExposureOption = None,
    fps: RecordingFpsOption = None,
    static: StaticFramesOption = None,
    noise: Annotated[
        float | None, typer.Option("--noise", help="Noise std (grey levels) instead of --static.")
    ] = None,
    subset: SubsetOption = 21,
    step: StepOption = 10,
    shape: ShapeOption = "affine",
    depth: Annotated[
        str | None,
        typer.Option(
            "--depth",
            help="Rough distance of the target from the left camera, e.g. 400mm (default: "
            "where the optical axes cross).",
        ),
    ] = None,
    reference: ReferenceFrameOption = 0,
    frames: FramesOption = None,
    fmt: StoreFormatOption = "netcdf",
    csv: Annotated[bool, typer.Option("--csv", help="Also write stereo.csv (long).")] = False,
    report: ReportOption = True,
    threads: Annotated[
        int | None,
        typer.Option(
            "--threads",
            help="Threads (default: all cores, NUMBA_NUM_THREADS): >= 2 correlates the two "
            "cameras at the same time.",
        ),
    ] = None,
) -> None:
    """Stereo-track LEFT and RIGHT: the shape X, Y, Z, the 3-D displacement U, V, W3 of
    every point in every frame and their predicted sigma (noise and each camera's blur);
    writes OUT/stereo.nc (or .zarr), OUT/report.html and, with --csv, OUT/stereo.csv."""

    from ..models import parse_quantity
    from ..sequence import open_recording
    from ..stereo.camera import load_rig
    from ..stereo.core import track
    from ..stereo.store import write_stereo_csv
    from ..track.store import save_track
    from .track import writable_folder, write_partial

    check_track_choices(fmt=fmt, shape=shape)
    dep = None if depth is None else parse_quantity(depth, "length", name="--depth")
    if dep is not None and not dep > 0:
        raise InputError(f"--depth={depth!r}: must be > 0, e.g. 400mm")
    if noise is not None and not noise > 0:
        raise InputError(f"--noise={noise!r}: must be > 0 GL, e.g. 2")
    if noise is None and static is None:
        raise InputError("--static / --noise: give the static frames (--static 0:20) or --noise")
    if out.exists() and not out.is_dir():
        raise InputError(f"--out={str(out)!r}: exists and is not a folder")
    if threads is not None and threads < 1:
        raise InputError(f"--threads={threads!r}: must be >= 1, e.g. 2")
    if threads is None:
        threads = all_threads()
    the_rig = load_rig(rig)
    writable_folder(out)
    rec_l, rec_r = open_recording(left), open_recording(right)
    target = track_store(out, "stereo", fmt)
    from ..track import TrackInterrupted

    with progress_bar("stereo", unit="frame pairs") as progress:
        try:
            ds = track(
                rec_l,
                rec_r,
                the_rig,
                exposure=exposure,
                fps=fps,
                static=static,
                noise=noise,
                subset=subset,
                step=step,
                shape=shape,  # type: ignore[arg-type]
                reference=reference,
                frames=frames,
                depth=dep,
                threads=threads,
                progress=progress,
            )
        except TrackInterrupted as exc:
            # the pairs tracked before a bad frame, written before the error (as track's)
            if exc.dataset is not None:
                write_partial(
                    exc.dataset, target, out / "stereo.csv" if csv else None, write_stereo_csv
                )
            raise
    save_track(ds, target)
    written = [str(target)]
    if csv:
        written.append(str(write_stereo_csv(ds, out / "stereo.csv")))
    if report:
        from ..report.stereo import write_stereo_report

        written.append(str(write_stereo_report(ds, out, image=rec_l.frame(reference))))
    import numpy as np

    valid = ds["valid"].values.astype(bool)

    def med(name: str) -> float:
        v = ds[name].values[valid]
        return float(np.median(v)) if v.size else float("nan")

    print_mapping(
        f"stereo track: {left} + {right}",
        {
            "frame_pairs": int(ds.sizes["frame"]),
            "points": int(ds.sizes["point"]),
            "stereo_matched": float((ds["status_stereo"].values == 0).mean()),
            "valid_share": float(valid.mean()),
            "median_sigma_U": med("sigma_U"),
            "median_sigma_V": med("sigma_V"),
            "median_sigma_W3": med("sigma_W3"),
            "pairs_per_s": int(ds.sizes["frame"]) / max(float(ds.attrs["tracking_time_s"]), 1e-9),
        },
        {"median_sigma_U": "mm", "median_sigma_V": "mm", "median_sigma_W3": "mm"},
    )
    for w in written:
        console.print(f"wrote {w}")


@stereo_app.command("plan")
def plan_command(
    model_path: ModelPathArgument,
    rig: RigOption,
    velocity: Annotated[
        str,
        typer.Option(
            "--velocity",
            help="Target velocity x,y,z in the target frame (x along the baseline, z out of "
            "plane, along the bisector), e.g. 0,0,100mm/s.",
        ),
    ],
    target: Annotated[str, typer.Option("--target", help="Largest 3-D sigma, e.g. 0.01mm.")],
    component: Annotated[
        str, typer.Option("--component", help="worst (all three), x, y or z.")
    ] = "worst",
    noise: FixedNoiseOption = None,
    which: ModelChoiceOption = None,
    depth: Annotated[
        str | None,
        typer.Option(
            "--depth",
            help="Distance of the point along the left axis, e.g. 400mm (default: where the "
            "optical axes cross).",
        ),
    ] = None,
    angles: Annotated[
        str, typer.Option("--angles", help="Stereo angles to compare, deg, e.g. 15,30,45.")
    ] = "10,15,20,30,45,60",
    as_json: JsonOption = False,
) -> None:
    """Plan the exposure for a 3-D target: the longest whose predicted sigma (x, y, z in
    the target frame, each camera's blur and the 2-D model's noise and blur terms
    propagated through the triangulation) meets --target, and the stereo angle that
    would allow a longer one (symmetric rigs at the same distance)."""
    import json
    import math

    from ..models import BlurUncertaintyModel, parse_quantity
    from ..stereo.camera import load_rig
    from ..stereo.plan import plan_stereo_exposure

    if component not in ("worst", "x", "y", "z"):
        raise InputError(f"--component={component!r}: choose worst, x, y or z")
    if noise is not None and not noise > 0:
        raise InputError(f"--noise={noise!r}: must be > 0 GL, e.g. 2")
    try:
        angs = [float(a) for a in angles.split(",") if a.strip()]
    except ValueError:
        raise InputError(f"--angles={angles!r}: expected degrees, e.g. 15,30,45") from None
    if not angs or not all(0 < a < 90 for a in angs):
        raise InputError(f"--angles={angles!r}: each in (0, 90) deg, e.g. 15,30,45")
    point = None
    if depth is not None:
        dep = parse_quantity(depth, "length", name="--depth")
        if not dep > 0:
            raise InputError(f"--depth={depth!r}: must be > 0, e.g. 400mm")
        point = (0.0, 0.0, dep)
    if not model_path.exists():
        raise InputError(f"MODEL={str(model_path)!r}: no such file (write one with dicblur fit)")
    model = BlurUncertaintyModel.from_json(str(model_path))
    the_rig = load_rig(rig)
    try:
        plan = plan_stereo_exposure(
            the_rig, model, velocity=velocity, target=target,
            component=component,  # type: ignore[arg-type]
            sigma=noise, which=which, point=point, angles=angs,
        )  # fmt: skip
    except InputError as exc:
        # the API names its keywords: the CLI's options instead
        msg = str(exc)
        for key in ("velocity", "target", "point"):
            if msg.startswith(f"{key}="):
                msg = "--" + ("depth" if key == "point" else key) + msg[len(key) :]
        raise InputError(msg) from None
    if as_json:
        typer.echo(json.dumps(plan.to_dict(), default=float))
        return
    um = "um"
    ms = plan.exposure * 1e3
    print_mapping(
        f"stereo plan: {the_rig.stereo_angle:.3g} deg rig, {plan.distance:.4g} mm",
        {
            "exposure": ms if math.isfinite(ms) else "any",
            "sigma_x": plan.sigma[0] * 1e3,
            "sigma_y": plan.sigma[1] * 1e3,
            "sigma_z": plan.sigma[2] * 1e3,
            "sigma_static_z": plan.sigma_static[2] * 1e3,
            "W_left": plan.blur_left,
            "W_right": plan.blur_right,
            "best_angle": plan.best_angle,
        },
        {
            "exposure": "ms",
            "sigma_x": um,
            "sigma_y": um,
            "sigma_z": um,
            "sigma_static_z": um,
            "W_left": "px",
            "W_right": "px",
            "best_angle": "deg",
        },
    )
    for o in plan.angles:
        console.print(
            f"{o.stereo_angle:5.3g} deg: exposure {o.exposure * 1e3:.4g} ms "
            f"(W {o.blur_left:.3g}/{o.blur_right:.3g} px); at the plan's exposure sigma x, y, z "
            + ", ".join(f"{x * 1e3:.3g}" for x in o.sigma_at_plan)
            + " um"
        )
    for n in plan.notes:
        console.print(n)


def register(app: typer.Typer) -> None:
    """Attach ``stereo`` (calibrate, track, plan) to the root app."""
    app.add_typer(stereo_app, name="stereo")
