"""CLI: ``dicblur reproduce`` (the paper's study as a report)."""

from __future__ import annotations

import shlex
import sys
from pathlib import Path

import typer

from ..errors import InputError
from ._common import check_serial, console, removes_new_empty_folder
from .options import (
    BaseSeedOption,
    CheckBrowserOption,
    OutFolderOption,
    SchedulerOption,
    SerialOption,
    WorkersOption,
)


@removes_new_empty_folder()
def reproduce_command(
    out: OutFolderOption = Path("report"),
    quick: bool = typer.Option(False, "--quick", help="Coarser W grid and fewer POIs."),
    pattern1: Path | None = typer.Option(
        None, "--pattern1", help="DIC Challenge Sample 13 image (central crop)."
    ),
    pattern2: Path | None = typer.Option(
        None, "--pattern2", help="DIC Challenge Sample 3 image (central crop)."
    ),
    workers: WorkersOption = None,
    scheduler: SchedulerOption = None,
    serial: SerialOption = False,
    seed: BaseSeedOption = 2017,
    check_browser: CheckBrowserOption = False,
) -> None:
    """Reproduce Lavatelli & Zappa (2017): figures, tables, claims, report.html."""
    from rich.progress import BarColumn, Progress, TaskID, TextColumn, TimeElapsedColumn

    from ..io import check_output
    from ..report.reproduce import ReproduceSettings, reproduce

    check_output(out, "--out", folder=True)
    check_serial(serial, workers=workers, scheduler=scheduler)
    size = ReproduceSettings(out=out).size
    for opt, path in (("--pattern1", pattern1), ("--pattern2", pattern2)):
        if path is not None:  # the study crops its centre: refused before any work
            from ..io import read_image_header

            rows, cols = read_image_header(path).shape
            if rows < size or cols < size:
                raise InputError(
                    f"{opt}={str(path)!r}: {rows}x{cols} px, smaller than the study's "
                    f"central crop of {size}x{size} px; give a larger image"
                )

    settings = ReproduceSettings(
        out=out,
        quick=quick,
        pattern1=pattern1,
        pattern2=pattern2,
        workers=workers,
        scheduler=scheduler,
        serial=serial,
        seed=seed,
        command="dicblur " + " ".join(shlex.quote(a) for a in sys.argv[1:]),
    )
    with Progress(
        TextColumn("{task.description:<28}"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total}"),
        TimeElapsedColumn(),
        console=console,
        transient=False,
        disable=not console.is_terminal,
    ) as bar:
        tasks: dict[str, TaskID] = {}

        def progress(stage: str, done: int, total: int) -> None:
            if not console.is_terminal and stage not in tasks:
                console.print(f"[stage] {stage}")
            if stage not in tasks:
                for tid in tasks.values():
                    t = bar.tasks[tid]
                    bar.update(tid, completed=t.total)
                tasks[stage] = bar.add_task(stage, total=max(total, 1))
            bar.update(tasks[stage], completed=done, total=max(total, 1))

        result = reproduce(settings, progress=progress)
    agree = sum(1 for c in result.claims if c["verdict"] == "agrees")
    console.print(f"report: {result.report}")
    console.print(
        f"results: {result.results_json} ({len(result.figures)} figures, "
        f"{agree}/{len(result.claims)} claims agree, "
        f"{result.timings.get('total', 0):.1f} s)"
    )
    if check_browser:
        from ..report.browser import check_in_browser

        chk = check_in_browser(result.report, screenshot=out / "screenshot.png")
        console.print(
            f"browser: {chk.image_count} images, all loaded: {chk.images_ok}; "
            f"screenshot {chk.screenshot}"
        )
        if not chk.images_ok:
            raise typer.Exit(1)


def register(app: typer.Typer) -> None:
    """Attach ``reproduce`` to the root app."""
    app.command("reproduce")(reproduce_command)
