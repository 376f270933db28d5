"""CLI: ``dicblur track RECORDING`` (displacements with per-point, per-frame sigma, issue 17)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any

import typer

from ..errors import InputError
from ._common import (
    all_threads,
    check_track_choices,
    console,
    parse_max_sigma,
    parse_tolerance,
    print_mapping,
    progress_bar,
    strain_option,
    track_store,
)
from .options import (
    FramesOption,
    MaxSigmaOption,
    OutFolderOption,
    RecordingExposureOption,
    RecordingFpsOption,
    ReferenceFrameOption,
    ReportOption,
    ShapeOption,
    StaticFramesOption,
    StepOption,
    StoreFormatOption,
    SubsetOption,
    VsgOption,
)


def _ints(text: str, name: str, count: int | None = None) -> list[int]:
    try:
        vals = [int(x) for x in text.replace(";", ",").split(",") if x.strip()]
    except ValueError as exc:
        raise InputError(f"{name}={text!r}: expected integers separated by commas") from exc
    if count is not None and len(vals) != count:
        raise InputError(f"{name}={text!r}: expected {count} integers separated by commas")
    return vals


def track_command(
    recording: Annotated[
        str,
        typer.Argument(
            help="Folder of frames, glob ('run/*.tif'), multi-page TIFF, .cine or .cih/.mraw."
        ),
    ],
    out: OutFolderOption,
    exposure: RecordingExposureOption = None,
    fps: RecordingFpsOption = None,
    static: StaticFramesOption = None,
    noise: Annotated[
        float | None,
        typer.Option(
            "--noise",
            help="Noise std (grey levels) instead of --static (neither: estimated from the "
            "frames' residuals).",
        ),
    ] = None,
    subset: SubsetOption = 21,
    step: StepOption = 10,
    shape: ShapeOption = "affine",
    points: Annotated[
        str | None,
        typer.Option("--points", help="Explicit POIs 'r1,c1;r2,c2' (px) instead of a grid."),
    ] = None,
    roi: Annotated[
        str | None, typer.Option("--roi", help="Grid region ROW0,ROW1,COL0,COL1 (px, half-open).")
    ] = None,
    reference: ReferenceFrameOption = 0,
    update_reference: Annotated[
        bool,
        typer.Option(
            "--update-reference", help="Renew the reference when the correlation degrades."
        ),
    ] = False,
    frames: FramesOption = None,
    plot: Annotated[
        str | None,
        typer.Option(
            "--plot-points", help="Point indices for the report's time series, e.g. 0,40."
        ),
    ] = None,
    fmt: StoreFormatOption = "netcdf",
    csv: Annotated[bool, typer.Option("--csv", help="Also write track.csv (long).")] = False,
    report: ReportOption = True,
    workers: Annotated[
        int | None,
        typer.Option(
            "--workers",
            help="Worker processes (local Dask cluster): the frames run in chunks, "
            "resumable from OUT/track.chunks.",
        ),
    ] = None,
    scheduler: Annotated[
        str | None,
        typer.Option(
            "--scheduler",
            help="Dask scheduler tcp://HOST:PORT for the chunks (instead of --workers).",
        ),
    ] = None,
    chunk_frames: Annotated[
        int | None,
        typer.Option(
            "--chunk-frames",
            help="Frames per chunk (default 100). Given alone: chunks in this process, "
            "resumable from OUT/track.chunks; 0: one serial loop over the frames (kernel "
            "threads).",
        ),
    ] = None,
    threads: Annotated[
        int | None,
        typer.Option(
            "--threads",
            help="Threads (default: all cores, NUMBA_NUM_THREADS). Without --workers, "
            "--scheduler or --update-reference: threads that track chunks of frames at the "
            "same time (single-threaded kernels each); with --chunk-frames 0 or "
            "--update-reference: threads of the correlation kernels.",
        ),
    ] = None,
    max_predicted_sigma: MaxSigmaOption = None,
    tolerance: Annotated[
        str,
        typer.Option(
            "--tolerance",
            help="IC-GN convergence tolerance, px (e.g. 0.001px), or auto: a quarter of the "
            "5th percentile of the points' static noise floor, within 0.0001-0.001 px.",
        ),
    ] = "auto",
    compensate_blur: Annotated[
        bool,
        typer.Option(
            "--compensate-blur",
            help="Correlate again with the blur-compensated matcher (blur vector per point "
            "from the track) and predict sigma for it.",
        ),
    ] = False,
    strain: Annotated[
        bool,
        typer.Option("--strain", help="Also write strains and their sigmas (docs/strain.md)."),
    ] = False,
    vsg: VsgOption = "5",
) -> None:
    """Track RECORDING and predict the random error (noise + motion blur) of every point in
    every frame; writes OUT/track.nc (or .zarr), OUT/report.html and, with --csv,
    OUT/track.csv. A run that stops part-way writes what was tracked (attribute
    complete = 0) before reporting the error. With --workers, --scheduler or
    --chunk-frames the frames run in chunks stored in OUT/track.chunks: the same command
    again continues from the finished chunks. By default, on a machine with several cores,
    the frames run in chunks of 100 on --threads threads of this process (not stored:
    --chunk-frames N stores them; --chunk-frames 0 tracks frame after frame)."""
    from ..sequence import open_recording
    from ..track import TrackInterrupted, track
    from ..track.store import save_track, write_track_csv

    check_track_choices(fmt=fmt, shape=shape)
    if points is not None and roi is not None:
        raise InputError("--points and --roi: give one of them")
    pts = None
    if points is not None:
        pairs = [p for p in points.split(";") if p.strip()]
        pts = [_ints(p, "--points", 2) for p in pairs]
    roi_v = None if roi is None else _ints(roi, "--roi", 4)
    max_sigma = parse_max_sigma(max_predicted_sigma)
    tol = parse_tolerance(tolerance)
    strain_window = strain_option(strain, vsg, step=step, subset=subset, points=pts)
    if chunk_frames is not None and chunk_frames < 0:
        raise InputError(f"--chunk-frames={chunk_frames}: must be >= 0 (0: no chunks), e.g. 100")
    if threads is not None and threads < 1:
        raise InputError(f"--threads={threads}: must be >= 1, e.g. 2")
    if chunk_frames == 0 and (workers is not None or scheduler is not None):
        raise InputError(
            "--chunk-frames 0: --workers and --scheduler run chunks; give --chunk-frames >= 1"
        )
    if out.exists() and not out.is_dir():
        raise InputError(f"--out={str(out)!r}: exists and is not a folder")
    writable_folder(out)
    rec = open_recording(recording)
    plot_pts = None if plot is None else _ints(plot, "--plot-points")
    if plot_pts and (roi_v is not None or pts is not None or subset + 2 <= min(rec.shape)):
        # (a subset larger than the frames: track's own error names --subset)
        # checked before tracking: the POIs follow from the frame size and the grid options
        from ..dic import Correlator

        layout = Correlator.layout(rec.shape, subset=subset, step=step, roi=roi_v, points=pts)
        n_pts = len(layout[0])
        if not all(0 <= p < n_pts for p in plot_pts):
            raise InputError(
                f"--plot-points={plot!r}: the recording has {n_pts} points (0..{n_pts - 1})"
            )
    target = track_store(out, "track", fmt)
    chunks = None
    n_threads = threads if threads is not None else all_threads()
    if (
        chunk_frames is None
        and workers is None
        and scheduler is None
        and not update_reference
        and n_threads > 1
    ):
        from ..track.parallel import ChunkedRun

        # the default on several cores: chunks of frames on threads of this process (each
        # thread its own frames: faster than kernel threads over each frame's points,
        # docs/track.md), not stored between runs
        chunks = ChunkedRun(chunk_frames=100, threads=n_threads)
    elif workers is not None or scheduler is not None or chunk_frames:
        from ..track.parallel import ChunkedRun

        if workers is not None and scheduler is not None:
            raise InputError("--workers and --scheduler: give one of them")
        chunks = ChunkedRun(
            store=out / "track.chunks",
            workers=workers,
            scheduler=scheduler,
            chunk_frames=100 if chunk_frames is None else chunk_frames,
            threads=threads if threads and workers is None and scheduler is None else 1,
        )
    with progress_bar("tracking", unit="frames") as progress:
        try:
            ds = track(
                rec,
                exposure=exposure,
                fps=fps,
                static=static,
                noise=noise,
                subset=subset,
                step=step,
                shape=shape,  # type: ignore[arg-type]
                points=pts,
                roi=roi_v,
                reference=reference,
                frames=frames,
                update_reference=update_reference,
                workers=threads,
                progress=progress,
                chunks=chunks,
                compensate_blur=compensate_blur,
                max_predicted_sigma=max_sigma,
                tolerance=tol,
                strain=strain_window,
            )
        except TrackInterrupted as exc:
            if exc.dataset is not None:
                write_partial(
                    exc.dataset, target, out / "track.csv" if csv else None, write_track_csv
                )
            if isinstance(exc.__cause__, KeyboardInterrupt):
                raise KeyboardInterrupt from exc
            raise
    save_track(ds, target)
    written = [str(target)]
    if csv:
        written.append(str(write_track_csv(ds, out / "track.csv")))
    if report:
        from ..report.track import write_track_report

        written.append(
            str(write_track_report(ds, out, image=rec.frame(reference), points=plot_pts))
        )
        page = _write_planner_page(ds, rec.frame(reference), out, subset=subset, step=step)
        if page is not None:
            written.append(str(page))
    a = ds.attrs
    valid = ds["valid"].values.astype(bool)
    print_mapping(
        f"track: {recording}",
        {
            "frames": int(ds.sizes["frame"]),
            "points": int(ds.sizes["point"]),
            "exposure": float(a["exposure"]),
            "fps": float(a["fps"]),
            "noise_sigma": float(a.get("noise_sigma", float("nan"))),
            "noise_source": str(a.get("noise_source", "-"))
            + (
                f" (95 % {a['noise_sigma_low']:.3g}-{a['noise_sigma_high']:.3g} GL)"
                if a.get("noise_estimated")
                else ""
            ),
            "valid_share": float(valid.mean()),
            "outliers": int(ds["n_outliers"].values.sum()),
            "frames_per_s": int(ds.sizes["frame"]) / max(float(a["tracking_time_s"]), 1e-9),
            "matcher": str(a.get("matcher", "plain")),
            "chunks": (
                f"{a['chunks_n_run']} run, {a['chunks_n_resumed']} resumed of "
                f"{a['chunks_n_chunks']} ({a['chunks_scheduler']})"
                if "chunks_n_chunks" in a
                else "-"
            ),
            "advice": str(a.get("advice_sentence", "-")),
        },
        {"exposure": "s", "fps": "Hz", "noise_sigma": "GL"},
    )
    if a.get("notes"):
        # what the run could not do (no noise estimate, no advice, ...): said, not only
        # stored, so a column of NaN sigma is never silent
        for note in str(a["notes"]).split(" | "):
            console.print(f"note: {note}")
    for w in written:
        console.print(f"wrote {w}")


def write_partial(
    ds: Any, target: Path, csv_path: Path | None, write_csv: Callable[[Any, Path], Any]
) -> None:
    """The frames of a track stopped by a bad frame, written before its error line: the
    store, and with ``write_csv`` the CSV when asked (``track`` and ``stereo track``)."""
    from ..track.store import save_track

    save_track(ds, target)
    if csv_path is not None:
        write_csv(ds, csv_path)
    console.print(f"wrote the {ds.sizes['frame']} frames tracked before the stop to {target}")


def writable_folder(out: Path) -> None:
    """Create ``out`` and check that a file can be written there, before any work."""
    import tempfile

    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=out, prefix=".probe-"):
            pass
    except OSError as exc:
        raise InputError(
            f"--out={str(out)!r}: cannot write there ({exc.strerror or exc}); give a "
            "writable folder"
        ) from None


def _write_planner_page(ds: Any, image: Any, out: Path, *, subset: int, step: int) -> Path | None:
    """OUT/planner.html: the exposure planner for this specimen (the reference frame's
    static prediction at the recording's noise, motion along its median blur direction),
    to set the exposure of the next test. The tracking results are already written, so a
    failure here is one warning line."""
    import math

    import numpy as np

    from .planner_page import write_pattern_planner

    sigma = float(ds.attrs.get("noise_sigma", float("nan")))
    if not math.isfinite(sigma) or sigma <= 0:
        return None
    a = 0.0
    if "blur_direction" in ds:
        # the axial mean (a blur has no sign: theta and theta + 180 deg are the same axis),
        # weighted by the blur length
        ang = np.radians(np.asarray(ds["blur_direction"].values, dtype=float)).ravel()
        w = np.asarray(ds["W"].values, dtype=float).ravel()
        ok = np.isfinite(ang) & np.isfinite(w)
        if ok.any() and float(w[ok].sum()) > 0:
            a = 0.5 * float(np.angle(np.sum(w[ok] * np.exp(2j * ang[ok]))))
    return write_pattern_planner(
        np.asarray(image, dtype=float),
        out,
        noise=sigma,
        subset=subset,
        step=step,
        label=f"this specimen, subset {subset} px",
        provenance={"pattern": "reference frame", "source": "dicblur track"},
        motion=(math.sin(a), math.cos(a)),
    )


def register(app: typer.Typer) -> None:
    """Attach ``track`` to the root app."""
    app.command("track")(track_command)
