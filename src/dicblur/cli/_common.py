"""Small helpers shared by the CLI command modules."""

from __future__ import annotations

import functools
import json
import math
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Literal, TypeVar

from rich.console import Console
from rich.table import Table

from ..errors import DicblurError, InputError

console = Console(highlight=False, soft_wrap=True)
F = TypeVar("F", bound=Callable[..., Any])


def removes_new_empty_folder(param: str = "out") -> Callable[[F], F]:
    """Decorate a command whose output ``param`` is a folder: when it fails on a bad input
    (a :class:`~dicblur.errors.DicblurError`) after the folder was created, and the folder
    is still empty, remove it (a refused run leaves nothing behind)."""

    def deco(fn: F) -> F:
        @functools.wraps(fn)
        def run(*args: Any, **kwargs: Any) -> Any:
            out = None if kwargs.get(param) is None else Path(kwargs[param])
            fresh = out is not None and not out.exists()
            try:
                return fn(*args, **kwargs)
            except DicblurError:
                if out is not None and fresh and out.is_dir() and not any(out.iterdir()):
                    out.rmdir()
                raise

        return run  # type: ignore[return-value]

    return deco


def fresh_seed() -> int:
    """A seed for a run without ``--seed``, drawn once and written to the settings JSON
    (a null there could not make the same image again)."""
    import secrets

    return secrets.randbits(63)


def split_sides(text: str, name: str, cast: Callable[[str], Any], expected: str) -> list[Any]:
    """The sides of ``"AxB"`` (``"A"``: a square, A both sides) cast by ``cast``; a part
    that does not parse is one error line ``name=text: expected <expected>``. The caller
    checks the count (and ranges) with its own message."""
    try:
        values = [cast(p) for p in text.lower().split("x")]
    except ValueError as exc:
        raise InputError(f"{name}={text!r}: expected {expected}") from exc
    return values * 2 if len(values) == 1 else values


def parse_size(text: str, name: str = "--size") -> tuple[int, int]:
    """Parse ``"512x256"`` (rows x cols) or ``"512"`` into a (rows, cols) tuple."""
    values = split_sides(text.replace("*", "x"), name, int, "ROWSxCOLS, e.g. 512x512")
    if len(values) != 2 or min(values) < 2:
        raise InputError(f"{name}={text!r}: expected ROWSxCOLS with both >= 2, e.g. 512x512")
    return values[0], values[1]


def parse_max_sigma(text: str | None, name: str = "--max-predicted-sigma") -> float | None:
    """``--max-predicted-sigma``: a displacement > 0 px (``0.05``, ``"0.05px"``), or
    ``none``/``off`` (no test: None)."""
    if text is None or text.strip().lower() in ("none", "off"):
        return None
    from ..models import parse_quantity

    value = parse_quantity(text, "displacement", name=name)
    if not value > 0:
        raise InputError(
            f"{name}={text!r}: must be > 0 px (e.g. 0.05px), or none to turn the test off"
        )
    return value


def parse_tolerance(text: str, name: str = "--tolerance") -> float | Literal["auto"]:
    """``--tolerance``: ``auto`` or an IC-GN convergence tolerance > 0 px (``0.001``,
    ``"0.001px"``)."""
    if text.strip().lower() == "auto":
        return "auto"
    from ..models import parse_quantity

    value = parse_quantity(text, "displacement", name=name)
    if not value > 0:
        raise InputError(f"{name}={text!r}: must be auto or > 0 px, e.g. 0.001px")
    return value


def check_serial(serial: bool, *, workers: int | None, scheduler: str | None) -> None:
    """``--serial`` runs in this process: refused beside ``--workers`` or ``--scheduler``,
    which choose a Dask cluster (one of them would be ignored without a word)."""
    if serial and (workers is not None or scheduler is not None):
        opt = f"--workers={workers}" if workers is not None else f"--scheduler={scheduler}"
        raise InputError(
            f"{opt}: --serial runs in this process, without a Dask cluster; leave out "
            f"{opt.split('=')[0]} or --serial"
        )


def check_track_choices(*, fmt: str, shape: str) -> None:
    """``--format`` and ``--shape`` of ``track`` and ``stereo track``."""
    if fmt not in ("netcdf", "zarr"):
        raise InputError(f"--format={fmt!r}: choose netcdf or zarr")
    if shape not in ("affine", "translation"):
        raise InputError(f"--shape={shape!r}: choose affine or translation")


def track_store(out: Path, name: str, fmt: str) -> Path:
    """The dataset a track writes: ``OUT/<name>.nc`` (``--format netcdf``) or
    ``OUT/<name>.zarr``."""
    return out / (f"{name}.nc" if fmt == "netcdf" else f"{name}.zarr")


def all_threads() -> int:
    """``--threads`` left out: numba's thread count (all cores, or NUMBA_NUM_THREADS)."""
    import numba

    return int(numba.config.NUMBA_NUM_THREADS)  # type: ignore[attr-defined]


def fmt(value: Any) -> str:
    """Readable number formatting for tables."""
    if value is None:
        return "-"
    if isinstance(value, float):
        if not math.isfinite(value):
            return "-"  # undefined: callers warn why; never print nan or inf
        if value != 0 and (abs(value) >= 1e5 or abs(value) < 1e-3):
            return f"{value:.4g}"
        return f"{value:.4f}".rstrip("0").rstrip(".") if abs(value) < 1000 else f"{value:.1f}"
    if isinstance(value, tuple | list):
        return "x".join(str(v) for v in value)
    return str(value)


def print_mapping(title: str, data: dict[str, Any], units: dict[str, str] | None = None) -> None:
    """Print a two- or three-column table of name, value (and unit)."""
    units = units or {}
    table = Table(title=title, show_header=True)
    table.add_column("quantity")
    table.add_column("value", justify="right")
    table.add_column("unit")
    for key, value in data.items():
        table.add_row(key, fmt(value), units.get(key, ""))
    console.print(table)


def json_safe(value: Any) -> Any:
    """JSON-safe copy of ``value``: NaN and inf become None (null; strict JSON readers
    reject NaN), tuples become lists, dicts and lists are copied through."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: json_safe(x) for k, x in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(x) for x in value]
    return value


def print_json(data: Any) -> None:
    """Print JSON (NaN and inf as null) for scripts."""
    print(json.dumps(json_safe(data), indent=2))


def notice_on_start(progress: Any, shape: str, enabled: bool) -> Any:
    """Wrap a ``progress(done, total)`` callback so that :func:`notice_compile` runs at its
    first call: after the inputs are validated, just before the first task (a bad input
    then gets its one error line and no compile notice)."""
    fired = [not enabled]

    def cb(done: int, total: int) -> None:
        if not fired[0]:
            fired[0] = True
            notice_compile(shape)
        progress(done, total)

    return cb


def notice_compile(shape: str = "affine") -> None:
    """Say on stderr, before a cold numba compile of the DIC kernels, that it is one
    (the first run after an install compiles for about 20 s with nothing else on screen)."""
    import sys

    from ..dic.cache import COMPILE_NOTICE, kernels_cached

    if not kernels_cached("translation" if shape == "translation" else "affine"):
        print(COMPILE_NOTICE, file=sys.stderr, flush=True)


def strain_option(
    strain: bool, vsg: str, *, step: int, subset: int, points: Any = None
) -> int | None:
    """``--strain`` / ``--vsg``: the window N, or None without ``--strain``."""
    if not strain:
        if vsg.strip() != "5":
            raise InputError(f"--vsg={vsg!r}: only used with --strain")
        return None
    from ..strain import window_from_vsg

    if points is not None:
        raise InputError("--strain: needs the POI grid; leave out --points")
    return window_from_vsg(vsg, step=step, subset=subset, name="--vsg")


@contextmanager
def progress_bar(
    label: str, *, unit: str = "tasks", enabled: bool = True
) -> Iterator[Callable[[int, int], None]]:
    """A rich progress bar with ETA (``campaign``, ``calibrate``, ``track``, ``stereo
    track``); yields the ``progress(done, total)`` callback. The bar starts at the first
    call's ``done``: a resumed run's ETA counts only this run's work."""
    if not enabled:
        yield lambda done, total: None
        return
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    bar = Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn(unit),
        TimeElapsedColumn(),
        TextColumn("ETA"),
        TimeRemainingColumn(),
        console=console,
        transient=False,
    )
    ids: dict[str, Any] = {}

    def update(done: int, total: int) -> None:
        if "t" not in ids:
            ids["t"] = bar.add_task(label, total=total, completed=done)
        else:
            bar.update(ids["t"], completed=done, total=total)

    with bar:
        yield update
