"""CLI: ``dicblur campaign run|status|export`` and ``dicblur calibrate``."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from ..errors import ConfigError, InputError
from ._common import (
    check_serial,
    console,
    notice_on_start,
    parse_size,
    print_json,
    print_mapping,
    progress_bar,
    removes_new_empty_folder,
)
from .options import (
    AngleOption,
    JsonOption,
    QuietOption,
    ResultsStoreArgument,
    SchedulerOption,
    SerialOption,
    ShapeOption,
    StepOption,
    SubsetOption,
    WorkersOption,
)

if TYPE_CHECKING:  # the campaign stage is imported inside the commands (fast --help)
    from ..campaign.engine import RunSummary

campaign_app = typer.Typer(
    help="Run blur campaigns (Dask), inspect and export their results.", no_args_is_help=True
)


def _print_summary(s: RunSummary) -> None:
    rate = s.n_run / s.wall_s if s.wall_s > 0 else 0.0
    print_mapping(
        "campaign run" + (" (interrupted: finished tasks kept)" if s.interrupted else ""),
        {
            "results": s.path,
            "tasks": s.n_tasks,
            "run now": s.n_run,
            "already stored": s.n_skipped,
            "remaining": s.n_tasks - s.n_run - s.n_skipped,
            "scheduler": s.scheduler,
            "workers": s.workers,
            "wall time": s.wall_s,
            "task time (sum)": s.task_s,
            "throughput": rate,
        },
        {"wall time": "s", "task time (sum)": "s", "throughput": "tasks/s"},
    )
    if s.interrupted:
        console.print("rerun the same command to finish the remaining tasks")


@campaign_app.command("run")
def run_command(
    spec: Path = typer.Argument(..., help="Campaign spec (TOML)."),
    out: Path = typer.Option(..., "-o", "--out", "--output", help="Results store (Zarr folder)."),
    scheduler: SchedulerOption = None,
    workers: WorkersOption = None,
    serial: SerialOption = False,
    quiet: QuietOption = False,
) -> int:
    """Run (or resume) the campaign SPEC and store its results in OUT."""
    from ..campaign import campaign_status, load_spec, run_campaign
    from ..campaign.cluster import check_scheduler_address
    from ..io import check_output

    # every check before the spec's patterns are built: the store folder may be created,
    # its parent must exist (the rule of every output)
    check_output(out, "--output", folder=True)
    check_serial(serial, workers=workers, scheduler=scheduler)
    if scheduler is not None and not serial:
        check_scheduler_address(scheduler)
    s = load_spec(spec)
    try:
        with progress_bar(f"campaign {s.name}", enabled=not quiet) as progress:
            # a cluster's workers compile in their own processes: the notice only serial
            summary = run_campaign(
                s,
                out,
                scheduler=scheduler,
                workers=workers,
                serial=serial,
                progress=notice_on_start(progress, s.dic_shape, serial),
            )
    except KeyboardInterrupt:  # before the tasks started (patterns, store creation)
        try:
            n_done = campaign_status(out).n_done
        except Exception:
            n_done = 0
        return _interrupted(n_done, s.n_tasks)
    if summary.interrupted:
        return _interrupted(summary.n_skipped + summary.n_run, summary.n_tasks)
    _print_summary(summary)
    return 0


def _interrupted(n_done: int, n_tasks: int) -> int:
    """The one line of an interrupted run (stderr); exit code 130."""
    typer.echo(
        f"interrupted: {n_done} of {n_tasks} tasks done, rerun the same command to resume", err=True
    )
    return 130


@campaign_app.command("status")
def status_command(
    results: ResultsStoreArgument,
    as_json: JsonOption = False,
) -> None:
    """Progress and provenance of a campaign store."""
    from ..campaign import campaign_status

    st = campaign_status(results)
    if as_json:
        print_json(st.to_dict())
        return
    data = {
        "campaign": st.name,
        "tasks done": f"{st.n_done} / {st.n_tasks} ({100.0 * st.n_done / st.n_tasks:.1f}%)",
        "complete": st.complete,
        "damaged": (
            f"{st.n_damaged} tasks (rerun the campaign to recompute them)"
            if st.n_damaged
            else "none"
        ),
        "running": st.running or "no",
        "dims": ", ".join(f"{k}={v}" for k, v in st.dims.items()),
        "spec hash": st.spec_hash[:16],
        "task time (sum)": st.total_task_s,
    }
    for name, done in st.done_by_pattern.items():
        data[f"pattern {name}"] = f"{done} / {st.tasks_per_pattern}"
    for name, h in st.input_hashes.items():
        data[f"input {name}"] = h[:28] + "..."
    print_mapping(f"campaign store: {results}", data, {"task time (sum)": "s"})


@campaign_app.command("export")
def export_command(
    results: ResultsStoreArgument,
    csv: Path = typer.Option(..., "--csv", help="Output CSV, one row per finished task."),
) -> None:
    """Export the finished tasks of a store as a flat CSV."""
    from ..campaign import export_csv, open_results
    from ..io import check_output

    check_output(csv, "--csv")
    done = open_results(results)["done"].values
    if not (done == 1).any():
        raise InputError(
            f"RESULTS={str(results)!r}: no finished task yet (0 of {done.size}), nothing to "
            "export; run or resume it with dicblur campaign run"
        )
    n = export_csv(results, csv)
    typer.echo(f"wrote {csv} ({n} rows)")


@removes_new_empty_folder()
def calibrate_command(
    image: str = typer.Argument(
        ..., help="Pattern image file, or 'paper4' / 'speckle' to generate one."
    ),
    out: Path = typer.Option(..., "-o", "--out", "--output", help="Output folder."),
    noise: list[float] = typer.Option(
        [2.0],
        "--noise",
        help="Noise std per image, GL; repeat (e.g. --noise 2 --noise 8) to calibrate at "
        "several levels: the model then separates its floor and cross term and a camera "
        "plan between the levels stays inside its validity domain.",
    ),
    subset: SubsetOption = 31,
    angle: AngleOption = 0.0,
    step: StepOption = 10,
    noise_model: str = typer.Option(
        "per-exposure",
        "--noise-model",
        help="per-exposure, per-subframe (the paper's) or poisson-gaussian.",
    ),
    shape: ShapeOption = "translation",
    seed: int = typer.Option(1, "--seed", help="Base seed (and generator seed)."),
    blur: str = typer.Option(
        "0.1:10:0.1", "--blur", help="W grid START:STOP:STEP in px (the paper's by default)."
    ),
    size: str = typer.Option("512x512", "--size", help="ROWSxCOLS of a generated pattern."),
    scheduler: SchedulerOption = None,
    workers: WorkersOption = None,
    serial: SerialOption = False,
    quiet: QuietOption = False,
    compensation: str = typer.Option(
        "none",
        "--compensation",
        help="Matcher of the sweep: none (plain), given (blur-compensated with the known "
        "motion), estimate (blur length estimated) or deblur (Wiener baseline); the "
        "model records it (plan --compare sets one against another).",
    ),
) -> int:
    """The paper's blur sweep (W = 0.1..10 px) on IMAGE, then the model fits.

    Writes OUT/model.json, OUT/results.zarr (+ results.csv), three figures and
    OUT/planner.html (the interactive exposure planner for this calibration).
    """
    from dataclasses import replace

    from ..campaign.calibrate import calibrate
    from ..report.plots import calibration_figures

    if compensation not in ("none", "given", "estimate", "deblur"):
        raise InputError(f"--compensation={compensation!r}: choose none, given, estimate or deblur")
    check_serial(serial, workers=workers, scheduler=scheduler)
    try:
        start, stop, inc = (float(v) for v in blur.split(":"))
    except ValueError as exc:
        raise InputError(
            f"--blur={blur!r}: expected START:STOP:STEP in px, e.g. 0.1:10:0.1"
        ) from exc
    with progress_bar("calibrate", enabled=not quiet) as progress, _as_options(blur):
        progress = notice_on_start(progress, shape, serial)
        res = calibrate(
            image,
            out,
            noise=noise if len(noise) > 1 else noise[0],
            subset=subset,
            angle=angle,
            step=step,
            noise_model=noise_model,
            shape=shape,
            seed=seed,
            blur={"start": start, "stop": stop, "step": inc},
            size=parse_size(size),
            scheduler=scheduler,
            workers=workers,
            serial=serial,
            progress=progress,
            compensation=compensation,
        )
    if res is None:
        console.print("interrupted: rerun the same command to finish the remaining tasks")
        return 130
    res = replace(res, figures=calibration_figures(res))
    m = res.model
    from ..report.planner import write_planner

    planner = write_planner([m], out / "planner.html")
    mm = m.mismatch
    dom = m.domain
    print_mapping(
        f"calibration: {image}",
        {
            "SSSIG_0": m.decay["sssig0"],
            "beta (eq. 18)": m.decay["beta"],
            "R^2 of the SSSIG fit": res.sssig_r2,
            "power law (paper): u_ref = u_e(0)": m.u_ref,
            "power law (paper): alpha (eq. 17)": m.alpha,
            "MBRF = 2 alpha beta": m.mbrf,
            "mismatch model: a": None if mm is None or "a" not in mm else mm["a"],
            "mismatch model: c": None if mm is None else mm["c"],
            "static kind: k_noise": None if m.static is None else m.static["k_noise"],
            "static kind: k_blur": None if m.static is None else m.static["k_blur"],
            "default model": m.default,
            "matcher": m.matcher,
            "validity domain": dom.describe() if dom else None,
            "DIC breaks down from W": None if dom is None else dom.breakdown_blur,
            "model": str(res.model_path),
            "results": str(res.results_path),
            "figures": ", ".join(p.name for p in res.figures),
            "planner page": str(planner),
        },
        {
            "SSSIG_0": "(GL/px)^2",
            "beta (eq. 18)": "1/px^2",
            "MBRF = 2 alpha beta": "1/px^2",
            "power law (paper): u_ref = u_e(0)": "px",
            "mismatch model: c": "px/px^2",
            "DIC breaks down from W": "px",
        },
    )
    return 0


# the campaign spec keys that calibrate fills from its options
_SPEC_OPTIONS = {
    "campaign.seed": "--seed",
    "noise.levels": "--noise",
    "noise.model": "--noise-model",
    "blur.angles": "--angle",
    "dic.subsets": "--subset",
    "dic.step": "--step",
    "dic.shape": "--shape",
}


@contextmanager
def _as_options(blur: str) -> Iterator[None]:
    """Errors of the campaign spec that calibrate builds name the option as typed
    (``--noise=nan``), not the spec key (``noise.levels=nan``)."""
    try:
        yield
    except ConfigError as exc:
        text = str(exc)
        if text.startswith("blur.lengths="):  # its value is the dict calibrate built
            cut = text.find("}: ")
            text = f"--blur={blur!r}" + text[cut + 1 :] if cut > 0 else text
        elif text.startswith("blur.lengths"):
            text = "--blur" + text[len("blur.lengths") :]
        else:
            for key, opt in _SPEC_OPTIONS.items():
                if text.startswith(key) and text[len(key) : len(key) + 1] in ("=", ":"):
                    text = opt + text[len(key) :]
                    break
        if text == str(exc):
            raise
        raise InputError(text) from exc


def register(app: typer.Typer) -> None:
    """Attach the campaign commands to the root app."""
    app.add_typer(campaign_app, name="campaign")
    app.command("calibrate")(calibrate_command)
