"""``dicblur.track``: displacements of a recording with a per-point, per-frame sigma.

Pipeline (docs/track.md):

1. one prepared :class:`~dicblur.Correlator` on the reference frame; each frame starts
   from the extrapolated track of the previous frames (quadratic over the last three) and
   falls back to the engine's FFT-CC start (global phase correlation, then per-subset
   FFT-CC) where that fails, point by point;
2. gross errors per frame: the normalised median test on the POI grid (at its fixed eps,
   then at eps = 2 x the frame's median predicted sigma) and a ZNCC far below the point's
   usual (:func:`zncc_flags`);
3. noise from the static frames (pairwise differences, per grey level where it varies),
   or given;
4. blur of every point in every frame from its track (:mod:`.kinematics`);
5. predicted sigma along x and y, noise and blur parts (:mod:`.uncertainty`);
6. per frame the share of points where blur dominates; per recording the exposure that
   would have minimised the error (:mod:`.advice`).

If reading or tracking stops part-way (a bad frame, Ctrl-C), :class:`TrackInterrupted`
carries the Dataset of the frames tracked so far, with steps 2-6 done on them.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..arrays import Float64Array
from ..checks import check_positive
from ..dic import Correlator, MatcherSettings, PointStatus
from ..dic.initial import window_spectrum
from ..errors import DicblurError, InputError
from ..sequence import Recording, open_recording
from .auto_noise import residual_frame_noise
from .compensate import MATCHER_PLAIN, build_compensated_table, compensate_track
from .flags import ZNCC_RATIO as ZNCC_RATIO
from .flags import zncc_flags as zncc_flags
from .frames import FALLBACK_SHARE as FALLBACK_SHARE
from .frames import SEED_EVERY as SEED_EVERY
from .frames import SEED_EVERY_MAX as SEED_EVERY_MAX
from .frames import SEEDS_ENOUGH as SEEDS_ENOUGH
from .frames import (
    ChunkRunner,
    Tracked,
    correlate_frame,
    frame_gradients,
    frame_guess,
    poi_grid,
    seed_correlator,
)
from .nan_pixels import NonFinitePixels
from .noise import NoiseEstimate, estimate_static_noise
from .options import TOLERANCE_MAX as TOLERANCE_MAX
from .options import TOLERANCE_MIN as TOLERANCE_MIN
from .options import TOLERANCE_QUANTILE as TOLERANCE_QUANTILE
from .options import TOLERANCE_SHARE as TOLERANCE_SHARE
from .options import auto_tolerance, parse_frame_range, resolve
from .options import parse_rate as parse_rate
from .result import STATIC_MOTION_PX as STATIC_MOTION_PX
from .result import assemble
from .uncertainty import build_blur_table

__all__ = [
    "ZNCC_RATIO",
    "ChunkRunner",
    "TrackInterrupted",
    "correlate_frame",
    "frame_guess",
    "parse_frame_range",
    "parse_rate",
    "poi_grid",
    "track",
    "zncc_flags",
]


class TrackInterrupted(DicblurError, RuntimeError):
    """Tracking stopped part-way; ``dataset`` holds the frames tracked before the stop.

    Attributes
    ----------
    dataset : xarray.Dataset or None
        The partial result (``attrs["complete"] == 0``, ``attrs["n_frames_tracked"]``).
    """

    def __init__(self, message: str, dataset: Any = None) -> None:
        super().__init__(message)
        self.dataset = dataset

    def __reduce__(self) -> tuple[Any, ...]:
        return (type(self), (str(self), self.dataset))


def _check_layout(
    shape: tuple[int, int], *, subset: int, roi: Sequence[int] | None, points: ArrayLike | None
) -> None:
    """Refuse, naming the option, explicit POIs outside the frames and a subset larger
    than frames of ``shape`` (rows, cols) px (the Correlator would report either as a
    region problem, or track an off-frame point as OUT_OF_BOUNDS in every frame)."""
    rows, cols = shape
    if points is not None:
        pts = np.asarray(points)
        if pts.ndim == 2 and pts.shape[1] == 2 and pts.size:
            off = (pts[:, 0] < 0) | (pts[:, 0] >= rows) | (pts[:, 1] < 0) | (pts[:, 1] >= cols)
            if off.any():
                r, c = (int(x) for x in pts[np.flatnonzero(off)[0]])
                raise InputError(
                    f"points={_describe_points(pts)}: ({r}, {c}) is outside the {rows}x{cols} "
                    "px frames; give (row, col) points inside them"
                )
    if roi is None and points is None and isinstance(subset, int) and subset + 2 > min(shape):
        raise InputError(
            f"subset={subset}: larger than the {rows}x{cols} px frames less a 1-px border; "
            f"give a subset of at most {min(shape) - 2 - (min(shape) % 2 == 0)} px"
        )


def _describe_points(pts: NDArray[Any]) -> str:
    text = ";".join(f"{int(r)},{int(c)}" for r, c in pts[:4])
    return repr(text + (";..." if len(pts) > 4 else ""))


def track(
    recording: Recording | str,
    *,
    exposure: float | str | None = None,
    fps: float | str | None = None,
    subset: int = 21,
    step: int = 10,
    roi: Sequence[int] | None = None,
    points: ArrayLike | None = None,
    static: str | Sequence[int] | None = None,
    noise: float | None = None,
    reference: int = 0,
    frames: str | Sequence[int] | None = None,
    shape: Literal["affine", "translation"] = "affine",
    min_zncc: float = 0.6,
    update_reference: bool = False,
    update_share: float = 0.9,
    half_window: int = 2,
    median_eps: float = 0.1,
    median_threshold: float = 2.0,
    advice: bool = True,
    workers: int | None = None,
    progress: Callable[[int, int], None] | None = None,
    chunks: ChunkRunner | None = None,
    compensate_blur: bool = False,
    max_predicted_sigma: float | None = None,
    tolerance: float | Literal["auto"] = "auto",
    strain: int | None = None,
) -> Any:
    """Track a recording and predict the random error of every point in every frame.

    Parameters
    ----------
    recording : Recording or str
        An open :class:`~dicblur.sequence.Recording` or anything
        :func:`~dicblur.sequence.open_recording` takes (folder, glob, TIFF stack, .cine,
        .cih/.mraw).
    exposure : float or str, optional
        Exposure time (s, or ``"1ms"``); default from the metadata. Given and metadata
        disagreeing by > 1 %: a warning, the given value is used.
    fps : float or str, optional
        Frame rate (Hz, or ``"5000fps"``, ``"5kHz"``); default from the metadata.
    subset, step, roi, points, shape, min_zncc
        As for :class:`~dicblur.Correlator` (``roi`` = (row_start, row_stop, col_start,
        col_stop) px).
    static : str or (start, stop), optional
        Frames of the static scene (``"0:20"``, half-open) for the noise estimate.
    noise : float, optional
        Noise std (GL) instead of ``static``. Neither given: estimated from the converged
        residuals of the frames nearest the reference (:mod:`.auto_noise`), recorded in
        the attributes ``noise_estimated``, ``noise_sigma_low``, ``noise_sigma_high``.
    reference : int
        Reference frame (tracking runs forwards from it, then backwards).
    frames : str or (start, stop), optional
        Frames to track (default all).
    update_reference : bool
        Renew the reference on the last tracked frame when a frame's converged share falls
        below ``update_share`` x the reference frame's (large deformation, decorrelation);
        the new reference's POIs sit at the points' positions there and its increments add
        to their displacement (recorded per frame in ``reference_frame``; the predicted
        variance of the renewal frame is carried into the later frames). The blur
        prediction still uses the first reference's subsets.
    half_window : int
        Frames on each side of the local trajectory fit (:mod:`.kinematics`).
    median_eps, median_threshold : float
        Normalised median test parameters (px, -).
    advice : bool
        Compute the exposure advice (a static prediction of the reference, a few s).
    workers : int, optional
        Threads of the correlation kernels, and of the post-processing (median test,
        tables, lookups, kinematics: the same numbers on any count; with
        ``ChunkedRun(threads=N)`` at least N).
    progress : callable(done, total), optional
        Called after every frame (every chunk with ``chunks``).
    chunks : ChunkRunner, optional
        Track in chunks of frames, in parallel and resumable:
        :class:`dicblur.track.parallel.ChunkedRun` (Dask workers, a scheduler, a store of
        the finished chunks). Not with ``update_reference``.
    compensate_blur : bool
        Correlate every frame again with the blur-compensated matcher
        (``Correlator(blur="given")``, the blur vector of each point from the first
        pass's track) and predict sigma for that matcher (no mismatch term; the noise
        term from the blurred reference): :mod:`.compensate`.
    max_predicted_sigma : float, optional
        Flag ``IMPRECISE`` (not valid) the points whose predicted random error from the
        reference subset and the noise (the Correlator's test, ``noise`` or the static
        frames' noise std) exceeds this, px. None (default): no test.
    tolerance : float or "auto"
        IC-GN convergence tolerance, px (the error left in a converged point, as for
        :class:`~dicblur.Correlator`). ``"auto"`` (default): a quarter of the 5th
        percentile of the points' static noise floor ``sqrt(2 sigma**2 / SSSIG)``, within
        [1e-4, 1e-3] px (:func:`auto_tolerance`): small against every sigma the track
        predicts (it adds about 1 %), and up to a quarter fewer iterations than the
        engine's default 1e-4 px. Stored in the attribute ``tolerance``.
    strain : int, optional
        Window N (odd, grid points) of the strains written beside ``u``, ``v``
        (:func:`dicblur.strain.track.track_strain`, docs/strain.md); None: no strains.

    Returns
    -------
    xarray.Dataset
        Dimensions ``frame`` and ``point``. Coordinates ``row``, ``col`` (point, px),
        ``time`` (frame, s: centre of the exposure, frame 0 opening at 0). Variables
        (frame, point): ``u``, ``v`` (px), ``blur_u``, ``blur_v`` (motion during the
        exposure, px), ``W`` (px), ``blur_direction`` (deg in [0, 180) from +x towards +y),
        ``sigma_u``, ``sigma_v`` and their ``_noise`` and ``_blur`` parts (px),
        ``status`` (:class:`~dicblur.PointStatus`), ``zncc``, ``outlier`` (normalised
        median test), ``valid`` (converged, not an outlier, sigma defined). Per frame:
        ``n_converged``, ``n_outliers``, ``blur_dominated_share``, ``fallback``. Attributes:
        settings, noise model, exposure advice (``advice_*``), ``complete``,
        ``n_frames_tracked``.

    Raises
    ------
    InputError
        Missing exposure/fps, exposure longer than the frame interval, bad ranges.
    TrackInterrupted
        A frame could not be read or tracking was interrupted; ``.dataset`` holds what was
        tracked.
    """
    if strain is not None:
        from ..strain.track import check_strain_window

        check_strain_window(strain, points)
    rec = recording if isinstance(recording, Recording) else open_recording(recording)
    # non-finite pixels fail the points they touch, not the track (track.nan_pixels)
    non_finite = NonFinitePixels(rec)
    rec = non_finite.recording
    n_total = len(rec)
    if n_total < 2:
        raise InputError(f"recording={rec.source!r}: {n_total} frame(s); tracking needs at least 2")
    fps_v = resolve(fps, rec.fps, "rate", "fps", "--fps", "5000")
    t_exp = resolve(exposure, rec.exposure, "time", "exposure", "--exposure", "1ms")
    if t_exp > 1.0 / fps_v * (1 + 1e-6):
        # name what was given and what came from the header (a header's shutter longer
        # than its frame interval is the recording's, not the user's)
        interval = f"the frame interval 1/fps = {1.0 / fps_v:g} s"
        if exposure is None and fps is None:
            msg = (
                f"the recording's metadata: exposure {t_exp:g} s longer than {interval}; "
                "give the right values with --exposure and --fps"
            )
        elif exposure is None:
            msg = (
                f"exposure={t_exp:g} s from the metadata: longer than {interval} of "
                f"fps={fps!r}; check --fps, or give --exposure"
            )
        else:
            msg = f"exposure={exposure!r} (given): longer than {interval}; check --exposure"
            msg += " and --fps" if fps is not None else f" (the metadata's fps {fps_v:g} Hz)"
        raise InputError(msg)
    f0, f1 = (0, n_total) if frames is None else parse_frame_range(frames, n_total, "frames")
    if not f0 <= reference < f1:
        raise InputError(f"reference={reference}: must be one of the tracked frames {f0}..{f1 - 1}")
    if chunks is not None and update_reference:
        raise InputError(
            "--update-reference: not available with --workers/--scheduler/--chunk-frames "
            "(each renewal depends on all the frames before it); run without them"
        )
    st_range = None
    if static is not None:
        st_range = parse_frame_range(static, n_total, "static")
        if st_range[1] - st_range[0] < 2:
            raise InputError(
                f"static={static!r}: {st_range[1] - st_range[0]} frame; the noise needs at "
                "least 2 frames of the static scene (e.g. --static 0:20)"
            )
    _check_layout(rec.shape, subset=subset, roi=roi, points=points)
    if noise is not None and (not math.isfinite(float(noise)) or float(noise) <= 0):
        raise InputError(f"noise={noise!r}: must be a noise std > 0 (GL)")
    limit = None
    if max_predicted_sigma is not None:
        limit = check_positive(max_predicted_sigma, "max_predicted_sigma")
    tol_given = None
    if not (isinstance(tolerance, str) and tolerance == "auto"):
        tol_given = check_positive(tolerance, "tolerance")
    # the noise first: it sets the IC-GN tolerance ("auto") and the IMPRECISE test
    noise_est: NoiseEstimate | None = None
    noise_error: BaseException | None = None
    notes: list[str] = []
    if rec.meta.get("lossy"):
        notes.append(
            f"frames stored as {rec.meta['lossy']}: the lossy compression adds an error "
            "(8 x 8 block artefacts, fine texture lost) that the noise model does not "
            "describe, so sigma is too small by an unknown amount; record TIFF or PNG"
        )
    if noise is not None:
        noise_est = NoiseEstimate(
            sigma=float(noise),
            read_variance=float(noise) ** 2,
            slope=0.0,
            level_dependent=False,
            source="given",
        )
    if st_range is not None:
        try:
            est = estimate_static_noise(rec, *st_range)
            noise_est = noise_est or est
            if noise is not None:
                notes.append(f"static frames give {est.sigma:.3g} GL; using --noise {noise}")
        except InputError:
            raise  # the range given cannot give a noise (one frame repeated): say so
        except (DicblurError, OSError) as exc:
            noise_error = exc
            if noise_est is None:
                notes.append(f"no noise estimate: {exc}")
    ref_img = rec.frame(reference)
    if float(ref_img.min()) == float(ref_img.max()):
        # a dropped frame (all black) as the reference: say which and what to give
        alt = next((k for k in range(f0, f1) if k != reference), reference)
        raise InputError(
            f"reference={reference} ({rec.names[reference]}): the frame is constant "
            f"({float(ref_img.min()):g} GL everywhere, a dropped frame?); give another "
            f"reference frame, e.g. --reference {alt}"
        )
    if noise_est is None and st_range is None:
        # neither given: the residuals of the frames nearest the reference (auto_noise)
        noise_est = residual_frame_noise(
            rec,
            Correlator(
                ref_img, roi=roi, points=points, subset=subset, step=step, shape=shape,
                min_zncc=min_zncc, workers=workers, noise_sigma=None,
            ),
            ref_img,
            reference=reference,
            frames=(f0, f1),
        )  # fmt: skip
        if noise_est is None:
            noise_error = InputError(
                "noise: too few subsets converge to estimate it from the frames; give "
                "the static frames (--static 0:20) or the noise std (--noise 2, GL)"
            )
            notes.append(f"no noise estimate: {noise_error}")
    opts: dict[str, Any] = {
        "subset": subset,
        "step": step,
        "shape": shape,
        "min_zncc": min_zncc,
        "workers": workers,
        # the track screens with its own per-frame noise model (track/uncertainty.py),
        # not the Correlator's per-pair estimate
        "noise_sigma": None,
    }
    if tol_given is None:
        cfg = MatcherSettings(subset=subset, step=step)  # validated before the layout
        rows, cols, _ = Correlator.layout(
            ref_img.shape, subset=cfg.subset, step=cfg.step, roi=roi, points=points
        )
        tol = auto_tolerance(ref_img, np.stack([rows, cols], axis=1), cfg.subset, noise_est)
    else:
        tol = tol_given
    opts["tolerance"] = tol
    if limit is not None:
        if noise_est is None:
            assert noise_error is not None
            raise noise_error  # the test needs the noise: the static frames' own error
        # only the IMPRECISE test: no residual screening (max_residual=None)
        opts.update(noise_sigma=noise_est.sigma, max_residual=None, max_predicted_sigma=limit)
    corr0 = Correlator(ref_img, roi=roi, points=points, **opts)
    # the serial loop's seeds (the chunks make theirs: track.parallel)
    seeds0 = seeds = None if chunks is not None else seed_correlator(ref_img, corr0, opts)
    # the last frame's displacement gradients (affine: the next frame's start)
    grads: Float64Array | None = None
    grads0: Float64Array | None = None
    corr = corr0
    grid = poi_grid(corr0)  # the current Correlator's grid (the guesses' smoothing)
    n_pts = corr0.n_points
    # points that can be correlated at all (set from the reference frame's own result)
    ok0 = np.ones(n_pts, bool)
    order = list(range(reference, f1)) + list(range(reference - 1, f0 - 1, -1))
    out = Tracked([], [], [], [], [], [])
    refs: list[int] = []
    hist: list[tuple[Float64Array, Float64Array]] = []
    # the rigid shift of each frame in hist (sub-pixel phase correlation; None: no peak)
    rig: list[Float64Array | None] = []
    rig_ref: Float64Array | None = None
    ref_field: tuple[Float64Array, Float64Array] | None = None
    base = np.zeros((n_pts, 2))  # displacement of the current reference's POIs (px)
    ref_now, ref_share = reference, 1.0
    spectrum = {reference: window_spectrum(ref_img)}
    prev: tuple[int, Float64Array] | None = None
    error: BaseException | None = None
    t_start = time.perf_counter()
    t_corr = 0.0  # inside Correlator.correlate (the engine, with the loop's guesses)
    if chunks is not None:
        # chunks of frames, in parallel and resumable (track.parallel): the same per-frame
        # step, each chunk started by the frames before it in place of the serial history
        got = chunks.run(
            rec,
            corr0,
            reference=reference,
            order=order,
            correlator={"roi": roi, "points": points, **opts},
            progress=progress,
        )
        out = Tracked(
            list(got["frames"]),
            list(got["u"]),
            list(got["v"]),
            list(got["zncc"]),
            list(got["status"]),
            list(got["fallback"]),
        )
        refs, error = [reference] * len(out.frames), got["error"]
        # frames whose non-finite pixels a worker filled: read here too for their masks
        counts = got.get("non_finite") or [0] * len(out.frames)
        non_finite.read([k for k, c in zip(out.frames, counts, strict=True) if c])
    try:
        for k in order if chunks is None else ():
            if k == reference - 1:  # backwards from the reference, on the first one
                hist = [ref_field] if ref_field is not None else []
                rig = [rig_ref] if ref_field is not None else []
                corr, base, ref_now, prev = corr0, np.zeros((n_pts, 2)), reference, None
                grid = poi_grid(corr0)
                seeds = seeds0
                grads = grads0
            img = rec.frame(k)
            # one prefilter for the seeds, the frame and a fallback
            frame = corr.prefilter(img)
            guess, g_abs = frame_guess(
                hist, rig, frame, spectrum[ref_now], base, seeds, grid=grid, grads=grads
            )
            t_c = time.perf_counter()
            res, fb = correlate_frame(
                corr, frame, None if guess is None else guess - base, ok0, grads
            )
            t_corr += time.perf_counter() - t_c
            share = float(np.mean(res.status[ok0] == PointStatus.CONVERGED)) if ok0.any() else 0.0
            if k == reference:
                ok0 = ~np.isin(res.status, (PointStatus.LOW_TEXTURE, PointStatus.OUT_OF_BOUNDS))
                ref_share = (
                    max(float(np.mean(res.status[ok0] == PointStatus.CONVERGED)), 1e-9)
                    if ok0.any()
                    else 1.0
                )
            elif (
                update_reference and prev is not None and hist and share < update_share * ref_share
            ):
                # renew the reference on the last frame tracked, POIs at their positions
                # there (Lagrangian: the increments add to that frame's displacement)
                last = np.stack(hist[-1], axis=1)
                bad = ~np.isfinite(last).all(axis=1)
                if not bad.all():
                    last[bad] = np.median(last[~bad], axis=0)
                    pts = np.stack(
                        [np.rint(corr0.rows + last[:, 1]), np.rint(corr0.cols + last[:, 0])], axis=1
                    ).astype(int)
                    new = Correlator(prev[1], points=pts, **opts)
                    g2 = None if guess is None else guess - last
                    res2, fb2 = correlate_frame(new, frame, g2, ok0)
                    share2 = float(np.mean(res2.status[ok0] == PointStatus.CONVERGED))
                    if share2 > share:
                        # increments of the subset now centred at the rounded position:
                        # within half a px of the material point, the field locally uniform
                        corr, base, ref_now, fb = new, last, prev[0], fb or fb2
                        grid = poi_grid(new)
                        seeds = seed_correlator(prev[1], new, opts)
                        spectrum[ref_now] = window_spectrum(prev[1])
                        res = res2
            out.frames.append(k)
            out.u.append(np.asarray(res.u, np.float64) + base[:, 0])
            out.v.append(np.asarray(res.v, np.float64) + base[:, 1])
            out.zncc.append(np.asarray(res.zncc, np.float64))
            out.status.append(np.asarray(res.status, np.uint8))
            out.fallback.append(bool(fb))
            refs.append(ref_now)
            good = res.status == PointStatus.CONVERGED
            hist.append((np.where(good, out.u[-1], np.nan), np.where(good, out.v[-1], np.nan)))
            rig.append(g_abs)
            del rig[:-3]
            grads = frame_gradients(res)
            if k == reference:
                ref_field, rig_ref, grads0 = hist[-1], g_abs, grads
            del hist[:-3]  # the extrapolation uses the last three
            prev = (k, img)
            if progress is not None:
                progress(len(out.frames), len(order))
    except (DicblurError, KeyboardInterrupt, OSError, MemoryError) as exc:
        error = exc
    comp_info: dict[str, Any] = {"matcher": MATCHER_PLAIN}
    if compensate_blur and out.frames and error is None:
        try:
            comp_info = compensate_track(
                rec,
                out,
                reference=reference,
                correlator={"roi": roi, "points": points, **opts},
                fps=fps_v,
                exposure=t_exp,
                half_window=half_window,
                grid_shape=corr0.grid_shape,
                runner=chunks,
                progress=progress,
            )
        except (DicblurError, KeyboardInterrupt, OSError, MemoryError) as exc:
            error = exc  # the first (plain) pass is kept
    notes.extend(
        non_finite.fail(
            out.frames, out.u, out.v, out.zncc, out.status, reference=reference,
            centres=np.stack([corr0.rows, corr0.cols], axis=1), subset=corr0.subset,
        )
    )  # fmt: skip
    elapsed = time.perf_counter() - t_start
    if not out.frames:
        if error is not None:
            raise error
    settings = {
        "subset": corr0.subset,
        "step": corr0.step,
        "shape": corr0.shape,
        "reference": reference,
        "min_zncc": min_zncc,
        "max_predicted_sigma": max_predicted_sigma,
        "tolerance": tol,
        "tolerance_source": "given" if tol_given is not None else "auto",
        "half_window": half_window,
        "median_eps": median_eps,
        "median_threshold": median_threshold,
        "exposure": t_exp,
        "fps": fps_v,
        "source": rec.source,
        "kind": rec.kind,
        "bit_depth": rec.bit_depth,
        "n_frames_recording": n_total,
        "tracking_time_s": elapsed,
        "correlation_time_s": t_corr,
    }
    if chunks is not None:
        settings.update({f"chunks_{k}": v for k, v in getattr(chunks, "summary", {}).items()})
    settings.update(comp_info)
    settings["update_reference"] = int(update_reference)
    settings["n_reference_updates"] = len(set(refs)) - 1
    ds = assemble(
        rec,
        corr0,
        out,
        refs,
        noise_est,
        st_range,
        fps_v,
        t_exp,
        settings,
        notes,
        half_window=half_window,
        eps=median_eps,
        threshold=median_threshold,
        advice=advice and error is None,
        ref_img=ref_img,
        threads=max(1, int(workers or 1), int(getattr(chunks, "threads", 1))),
        blur_table=(
            build_compensated_table if comp_info["matcher"] != MATCHER_PLAIN else build_blur_table
        ),
        compensated=comp_info["matcher"] != MATCHER_PLAIN,
        strain=strain,
    )
    if error is not None:
        what = "interrupted" if isinstance(error, KeyboardInterrupt) else f"stopped: {error}"
        ds.attrs["complete"] = 0
        ds.attrs["stop_reason"] = what
        raise TrackInterrupted(
            f"tracking {what} after {len(out.frames)} of {len(order)} "
            "frames; the frames tracked so far are kept",
            ds,
        ) from error
    return ds
