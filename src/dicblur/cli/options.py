"""The options that several CLI commands share, as ``typing.Annotated`` aliases.

One definition (option name, help text) per option that means the same in every command
that takes it; each command gives its own default, e.g. ``subset: SubsetOption = 21``. An
option whose meaning differs between commands (``--noise``, ``--workers`` of
``correlate``, ``--csv``, ...) stays with its command.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import typer

from ..errors import InputError

__all__ = [
    "MAX_SIGMA_HELP",
    "VSG_HELP",
    "AngleOption",
    "BaseSeedOption",
    "BitDepthOption",
    "CheckBrowserOption",
    "FixedNoiseOption",
    "FramesOption",
    "ImageSeedOption",
    "JsonOption",
    "MaxSigmaOption",
    "ModelChoiceOption",
    "ModelPathArgument",
    "OutFolderOption",
    "QuietOption",
    "RecordingExposureOption",
    "RecordingFpsOption",
    "ReferenceFrameOption",
    "ReportOption",
    "ResultsStoreArgument",
    "RigOption",
    "ScaleOption",
    "SchedulerOption",
    "SerialOption",
    "ShapeOption",
    "StaticFramesOption",
    "StepOption",
    "StoreFormatOption",
    "SubsetOption",
    "SubsetStepOption",
    "TargetSpeedOption",
    "VsgOption",
    "WorkersOption",
]

# --- outputs and printing ---------------------------------------------------------------

OutFolderOption = Annotated[Path, typer.Option("-o", "--out", help="Output folder.")]
JsonOption = Annotated[bool, typer.Option("--json", help="Print JSON.")]
CheckBrowserOption = Annotated[
    bool,
    typer.Option("--check-browser", help="Open report.html in headless Chromium afterwards."),
]

# --- images and seeds -------------------------------------------------------------------


def _seed(value: int | None) -> int | None:
    """``--seed``: an integer >= 0 (numpy's seeds), refused at parse time."""
    if value is not None and value < 0:
        raise InputError(f"--seed={value}: seeds are integers >= 0, e.g. 1")
    return value


def _angle(value: float) -> float:
    """``--angle``: a finite number of degrees (NaN would give a NaN motion vector)."""
    if not math.isfinite(value):
        raise InputError(f"--angle={value}: must be a finite number of degrees, e.g. 90")
    return value


ImageSeedOption = Annotated[
    int | None,
    typer.Option("--seed", help="Random seed (same seed, same image).", callback=_seed),
]
BaseSeedOption = Annotated[int, typer.Option("--seed", help="Base seed.", callback=_seed)]
BitDepthOption = Annotated[int, typer.Option("--bit-depth", help="8 or 16: quantisation and file.")]
AngleOption = Annotated[
    float,
    typer.Option(
        "--angle",
        help="Motion direction in degrees from +x (columns) towards +y (rows).",
        callback=_angle,
    ),
]

# --- the matcher (subset DIC) -----------------------------------------------------------

SubsetOption = Annotated[int, typer.Option("--subset", help="Odd subset size, px.")]
StepOption = Annotated[int, typer.Option("--step", help="POI grid step, px.")]
#: ``--step`` of the static pattern measures (default: their own grid)
SubsetStepOption = Annotated[int | None, typer.Option("--step", help="Subset grid step, px.")]
ShapeOption = Annotated[
    str, typer.Option("--shape", help="DIC shape function: affine or translation.")
]

#: ``--max-predicted-sigma`` of ``correlate`` and ``track`` (one help text for both).
MAX_SIGMA_HELP = (
    "Flag IMPRECISE the points whose predicted random error (from the reference subset and "
    "the noise) exceeds this, px (e.g. 0.05px; none: no test). correlate: default 0.1/3 px, "
    "the noise given or estimated; track: default none."
)
MaxSigmaOption = Annotated[str | None, typer.Option("--max-predicted-sigma", help=MAX_SIGMA_HELP)]

#: ``--vsg`` of ``correlate`` and ``track`` (one help text for both).
VSG_HELP = (
    "With --strain: the plane fit's window, in grid points (odd, e.g. 5) or as the virtual "
    "strain gauge in px (e.g. 61px = (N - 1) x step + subset)."
)
VsgOption = Annotated[str, typer.Option("--vsg", help=VSG_HELP)]

# --- campaigns: serial or on a Dask cluster ---------------------------------------------


def _scheduler(value: str | None) -> str | None:
    """``--scheduler``: its form checked at parse time (reproduce wrote its patterns and
    its store before the cluster start refused it)."""
    if value is not None:
        from ..campaign.cluster import check_scheduler_address

        try:
            check_scheduler_address(value)
        except InputError as exc:
            raise InputError(str(exc).replace("scheduler=", "--scheduler=", 1)) from None
    return value


def _workers(value: int | None) -> int | None:
    """``--workers``: >= 1 when given, checked at parse time (as ``--scheduler``)."""
    if value is not None and value < 1:
        raise InputError(f"--workers={value}: must be >= 1 (or omit it: all cores)")
    return value


SchedulerOption = Annotated[
    str | None,
    typer.Option(
        "--scheduler",
        help="Existing Dask scheduler, tcp://HOST:PORT (default: a local cluster).",
        callback=_scheduler,
    ),
]
WorkersOption = Annotated[
    int | None,
    typer.Option(
        "--workers",
        help="Worker processes of the local cluster (default: all cores).",
        callback=_workers,
    ),
]
SerialOption = Annotated[bool, typer.Option("--serial", help="Run in this process, no Dask.")]
QuietOption = Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar.")]
ResultsStoreArgument = Annotated[Path, typer.Argument(help="Results store (Zarr folder).")]

# --- recordings (track, stereo track) ---------------------------------------------------

RecordingExposureOption = Annotated[
    str | None,
    typer.Option("--exposure", help="Exposure time, e.g. 1ms (default: from the metadata)."),
]
RecordingFpsOption = Annotated[
    str | None,
    typer.Option("--fps", help="Frame rate, e.g. 5000 or 5kHz (default: from the metadata)."),
]
StaticFramesOption = Annotated[
    str | None,
    typer.Option("--static", help="Frames of the static scene for the noise, e.g. 0:20."),
]
ReferenceFrameOption = Annotated[int, typer.Option("--reference", help="Reference frame.")]
FramesOption = Annotated[
    str | None, typer.Option("--frames", help="Frames to track, START:STOP (default all).")
]
StoreFormatOption = Annotated[str, typer.Option("--format", help="netcdf or zarr.")]
ReportOption = Annotated[bool, typer.Option("--report/--no-report", help="Write report.html.")]
RigOption = Annotated[Path, typer.Option("--rig", help="Rig file (.json/.yml) of the two cameras.")]

# --- uncertainty models (predict, plan, stereo plan) -------------------------------------

ModelPathArgument = Annotated[Path, typer.Argument(help="Model file written by 'dicblur fit'.")]


def _model_choice(value: str | None) -> str | None:
    """``--model``: the model kind (the API's message would read ``model='foo'``, the
    name of the MODEL argument)."""
    if value is not None and value not in ("static", "mismatch", "power_law"):
        raise InputError(f"--model={value!r}: choose static, mismatch or power_law")
    return value


ModelChoiceOption = Annotated[
    str | None,
    typer.Option(
        "--model",
        help="static (calibrate's default), mismatch or power_law.",
        callback=_model_choice,
    ),
]
FixedNoiseOption = Annotated[
    float | None, typer.Option("--noise", help="Fixed noise std, GL (default the model's).")
]
TargetSpeedOption = Annotated[
    str | None, typer.Option("--velocity", help="Target speed, e.g. 120mm/s.")
]
ScaleOption = Annotated[str | None, typer.Option("--scale", help="Image scale, e.g. 0.05mm/px.")]
