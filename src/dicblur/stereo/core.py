"""``dicblur.stereo.track``: two synchronised recordings in, the 3-D shape, the 3-D
displacement of every point in every frame and their predicted uncertainty out
(issue 29, docs/stereo.md).

Pipeline: (1) the left reference's POI grid is matched in the right reference
(:func:`~dicblur.stereo.matching.match_reference`: the shape); (2) each camera's frames
are correlated against its own reference (the right camera's POIs at the matched points,
rounded to whole px, the affine parameters carrying the sub-pixel rest), each frame
starting from the previous one; (3) every pair is triangulated, and the 3-D displacement
is the difference from the reference's point; (4) the motion during each exposure is
fitted from the 3-D track (``dicblur track``'s local polynomial of the window averages),
projected into each camera as its blur, and each camera's image covariance (noise and blur
mismatch) is propagated through the triangulation (:mod:`.uncertainty`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from typing import Any, Literal

import numpy as np

from .._version import __version__
from ..arrays import BoolArray, Float32Array, Float64Array, IndexArray, UInt8Array
from ..dic import Correlator, PointStatus
from ..errors import DicblurError, InputError
from ..sequence import Recording, open_recording
from ..threads import each
from ..track.core import TrackInterrupted
from ..track.frames import correlate_frame, frame_gradients, poi_grid
from ..track.grid import extrapolate_fields, fill_with_median
from ..track.kinematics import exposure_motion
from ..track.noise import NoiseEstimate, estimate_static_noise, subset_levels
from ..track.options import parse_frame_range, parse_rate
from ..track.parallel import HISTORY, thread_safe_kernels
from ..track.saturation import (
    saturated_share,
    saturation_level,
    saturation_note,
    too_saturated,
)
from ..track.uncertainty import build_blur_table
from .camera import StereoRig
from .matching import match_reference
from .triangulate import propagate, triangulate, triangulation_jacobian
from .uncertainty import (
    blur_vectors,
    camera_covariance,
    length_angle,
    relative_shift,
)

__all__ = ["ArrayRecording", "track"]


class ArrayRecording:
    """Frames held in memory (an array (frames, rows, cols) or a list of 2-D arrays) read
    like a :class:`dicblur.sequence.Recording`."""

    def __init__(self, frames: Any, source: str = "array") -> None:
        self._frames = frames
        self.source = source
        self.fps: float | None = None
        self.exposure: float | None = None

    def __len__(self) -> int:
        return len(self._frames)

    def __getitem__(self, index: int) -> Float64Array:
        return self.frame(index)

    def frame(self, index: int) -> Float64Array:
        return np.asarray(self._frames[index], dtype=np.float64)


def _open(src: Any, name: str) -> Any:
    if isinstance(src, Recording | ArrayRecording):
        return src
    if isinstance(src, str) or hasattr(src, "__fspath__"):
        return open_recording(src)
    if isinstance(src, np.ndarray | list | tuple):
        a = src if isinstance(src, np.ndarray) else list(src)
        if len(a) == 0 or np.asarray(a[0]).ndim != 2:
            raise InputError(f"{name}: expected frames (frames, rows, cols) or a recording path")
        return ArrayRecording(a, source=name)
    raise InputError(f"{name}={type(src).__name__}: expected a recording path or frames")


def _number(value: Any, meta: float | None, kind: str, name: str) -> float:
    if value is None:
        if meta is None:
            raise InputError(f"{name}: the recording has no {name} in its metadata; give it")
        return float(meta)
    if kind == "rate":
        return parse_rate(value, name)
    from ..models import parse_quantity

    x = parse_quantity(value, "time", name=name)
    if not x > 0:
        raise InputError(f"{name}={value!r}: must be > 0, e.g. 1ms")
    return x


def _noise(rec: Any, static: Any, noise: float | None, name: str) -> NoiseEstimate:
    if noise is not None:
        if not (math.isfinite(noise) and noise > 0):
            raise InputError(f"noise={noise!r}: the noise std must be > 0 GL, e.g. 2")
        return NoiseEstimate(
            sigma=float(noise),
            read_variance=float(noise) ** 2,
            slope=0.0,
            level_dependent=False,
            source="given",
        )
    if static is None:
        raise InputError("static, noise: give the static frames (e.g. static='0:20') or noise")
    a, b = parse_frame_range(static, len(rec), name="static")
    est = estimate_static_noise(rec, a, b)
    return est


def _camera_correlator(reference: Float64Array, noise: NoiseEstimate, **where: Any) -> Correlator:
    """One camera's matcher on its reference (``where``: the grid or points, subset and
    shape). Gross errors: the epipolar test of every pair instead of the engine's neighbour
    check, exact on linear fields only (docs/stereo.md)."""
    return Correlator(
        reference,
        noise_sigma=noise.sigma,
        max_predicted_sigma=None,
        neighbour_check=False,
        tolerance=1e-3,
        **where,
    )


def _combine(*statuses: UInt8Array) -> UInt8Array:
    """The first non-converged status of the stages (stereo, left, right)."""
    out = np.zeros(np.broadcast_shapes(*(s.shape for s in statuses)), np.uint8)
    for s in reversed(statuses):
        s_b = np.broadcast_to(s, out.shape)
        out = np.where(s_b != 0, s_b, out).astype(np.uint8)
    return out


def _track_camera(
    corr: Correlator,
    rec: Any,
    order: Sequence[int],
    history: list[Float64Array],
    out_p: Float64Array,
    out_s: UInt8Array,
    ok0: BoolArray,
    grid: tuple[tuple[int, int], IndexArray] | None,
) -> tuple[int, BaseException | None]:
    """IC-GN of the frames ``order`` (in tracking order) as ``dicblur track`` runs its
    frames (docs/track.md): each from the extrapolation of the last (up to) three
    converged fields ``history`` (params (n, k), NaN where a point failed; the increment
    smoothed over the POI grid ``grid``) with the previous frame's displacement gradients;
    a frame where more than 2 % of the correlatable points ``ok0`` fail from there is
    correlated again from the engine's FFT-CC start and the better result kept per point
    (:func:`~dicblur.track.frames.correlate_frame`). Returns the frames done and the
    error that stopped it (a frame that cannot be read), or None."""
    iv = 1 if corr.shape == "translation" else 3
    hist = [(h[:, 0].copy(), h[:, iv].copy()) for h in history[-HISTORY:]]
    grads = None
    if corr.shape == "affine" and history:
        last = history[-1]
        ok = np.asarray(np.isfinite(last).all(axis=1))
        if ok.any():
            grads = last.take([1, 2, 4, 5], axis=1)
            fill_with_median(grads, ok)
    for done, f in enumerate(order):
        try:
            img = corr.prefilter(rec.frame(f))
        except (DicblurError, OSError) as exc:
            return done, exc  # the frames before it are kept (track below)
        guess = extrapolate_fields(hist, grid) if hist else None
        if guess is not None:
            good = np.asarray(np.isfinite(guess).all(axis=1))
            if good.any():
                fill_with_median(guess, good)
            else:
                guess = None
        res, _ = correlate_frame(corr, img, guess, ok0, grads)
        p, st = res.params, res.status
        out_p[f], out_s[f] = p, st
        keep = (st == PointStatus.CONVERGED) & np.isfinite(p).all(axis=1)
        hist.append((np.where(keep, p[:, 0], np.nan), np.where(keep, p[:, iv], np.nan)))
        del hist[:-HISTORY]
        grads = frame_gradients(res)
    return len(order), None


def track(
    left: Any,
    right: Any,
    rig: StereoRig,
    *,
    exposure: float | str | None = None,
    fps: float | str | None = None,
    static: str | Sequence[int] | None = None,
    noise: float | None = None,
    subset: int = 21,
    step: int = 10,
    shape: Literal["affine", "translation"] = "affine",
    roi: Sequence[int] | None = None,
    reference: int = 0,
    frames: str | None = None,
    depth: float | None = None,
    max_epipolar: float = 1.0,
    threads: int = 1,
    progress: Callable[[int, int], None] | None = None,
) -> Any:
    """Stereo DIC of two synchronised recordings: shape, 3-D displacement and their sigma.

    Parameters
    ----------
    left, right : path, Recording or array (frames, rows, cols)
        The two cameras' recordings (as ``dicblur track`` reads them), frame k of one
        taken with frame k of the other.
    rig : StereoRig
        The calibration (:func:`dicblur.stereo.load_rig`); world = left camera frame, mm.
    exposure : float or str
        s (``"1ms"``); default from the left recording's metadata.
    fps : float or str
        Hz (``"5kHz"``); default from the metadata.
    static : "START:STOP", optional
        Frames of the static scene for each camera's noise; or ``noise``.
    noise : float, optional
        Noise std, GL (both cameras).
    subset, step, shape, roi
        The matcher (as :class:`dicblur.Correlator`); the POI grid lies on the left
        reference.
    reference : int
        Reference frame of both cameras.
    frames : "START:STOP", optional
        Frames to track (default all).
    depth : float, optional
        Rough distance of the target along the left optical axis, mm, for the start of the
        stereo match (default: where the optical axes cross).
    max_epipolar : float
        Pairs whose triangulation leaves an RMS reprojection error above this (px) are
        ``OUTLIER`` (a wrong match or a wrong calibration), in the reference pair and in
        every frame pair (the gross-error test of the stereo track).
    threads : int
        Threads: >= 2 runs the two cameras' correlations at the same time (where numba's
        threading layer is thread-safe) and shares the uncertainty tables' chunks.
    progress : callable, optional
        ``progress(done, total)`` after each frame pair.

    Returns
    -------
    xarray.Dataset
        Dims ``frame``, ``point``. Per point: ``X, Y, Z`` (reference shape, mm),
        ``sigma_X/Y/Z`` (from the stereo match's noise), ``right_row, right_col``,
        ``epipolar_residual`` (px), ``status_stereo``. Per (frame, point): ``U, V, W3``
        (3-D displacement, mm), ``sigma_U/V/W3`` and ``cov_UV, cov_UW3, cov_VW3`` (mm,
        mm^2), ``sigma_*_noise`` / ``sigma_*_blur`` splits, each camera's image
        displacement ``u_left, v_left, u_right, v_right`` (px), blur ``W_left, W_right``
        (px) and direction, ``status`` (the first failure of stereo, left, right),
        ``status_left``, ``status_right``, ``valid``. docs/stereo.md lists them.
    """
    import xarray as xr

    t_start = time.perf_counter()
    if not isinstance(rig, StereoRig):
        raise InputError(f"rig={type(rig).__name__}: expected a dicblur.stereo.StereoRig")
    rec_l, rec_r = _open(left, "left"), _open(right, "right")
    n_total = len(rec_l)
    if len(rec_r) != n_total:
        raise InputError(
            f"right: {len(rec_r)} frames, left {n_total}: the recordings must be synchronised "
            "(the same number of frames)"
        )
    if n_total < 2:
        raise InputError(f"left: {n_total} frame(s); tracking needs at least 2")
    fps_v = _number(fps, getattr(rec_l, "fps", None), "rate", "fps")
    t_exp = _number(exposure, getattr(rec_l, "exposure", None), "time", "exposure")
    if t_exp > 1.0 / fps_v * (1 + 1e-9):
        raise InputError(f"exposure={exposure!r}: longer than the frame interval 1/fps")
    f0, f1 = (0, n_total) if frames is None else parse_frame_range(frames, n_total, "frames")
    if not f0 <= reference < f1:
        raise InputError(f"reference={reference}: outside the frames tracked {f0}:{f1}")
    ref_l, ref_r = rec_l.frame(reference), rec_r.frame(reference)
    for img, cam, nm in ((ref_l, rig.left, "left"), (ref_r, rig.right, "right")):
        if tuple(img.shape) != tuple(cam.image_shape):
            raise InputError(
                f"{nm}: frames of {img.shape[0]}x{img.shape[1]} px, the rig's {nm} camera "
                f"{cam.image_shape[0]}x{cam.image_shape[1]}: the calibration is of another camera"
            )
    nz_l = _noise(rec_l, static, noise, "left")
    nz_r = _noise(rec_r, static, noise, "right")
    # (1) the shape: the left reference's POIs matched in the right reference
    corr_l = _camera_correlator(ref_l, nz_l, subset=subset, step=step, shape=shape, roi=roi)
    rows, cols = corr_l.rows.astype(np.float64), corr_l.cols.astype(np.float64)
    n = len(rows)
    match = match_reference(rig, corr_l, ref_r, depth=depth, max_epipolar=max_epipolar)
    half = subset // 2
    # a failed match (NaN) is cast as the corner subset (replaced below): no invalid cast
    rr = np.rint(np.where(np.isfinite(match.right), match.right, half)).astype(np.int64)
    inside = (
        np.isfinite(match.right).all(axis=1)
        & (rr[:, 0] >= half)
        & (rr[:, 0] < ref_r.shape[0] - half)
        & (rr[:, 1] >= half)
        & (rr[:, 1] < ref_r.shape[1] - half)
    )
    st_stereo = match.status.copy()
    st_stereo[~inside & (st_stereo == 0)] = PointStatus.OUT_OF_BOUNDS
    rr[~inside] = [half, half]
    delta = np.where(inside[:, None], match.right - rr, 0.0)  # (row, col) sub-pixel rest
    corr_r = _camera_correlator(ref_r, nz_r, subset=subset, points=rr, shape=shape)
    # (2) each camera against its own reference
    order = list(range(reference + 1, f1)) + list(range(reference - 1, f0 - 1, -1))
    nf = n_want = f1 - f0
    k = 6 if shape == "affine" else 2
    p_l = np.full((n_total, n, k), np.nan)
    p_r = np.full((n_total, n, k), np.nan)
    s_l = np.zeros((n_total, n), np.uint8)
    s_r = np.zeros((n_total, n), np.uint8)
    p_l[reference] = 0.0
    p_r[reference] = 0.0
    t_track = time.perf_counter()
    done = 0
    error: BaseException | None = None  # a frame that could not be read: what was is kept
    # the two cameras on two threads (each Correlator on single-threaded kernels, which
    # release the GIL) where numba's threading layer allows concurrent kernel calls
    two = threads >= 2 and thread_safe_kernels()
    cams = [(corr_l, p_l, s_l, rec_l), (corr_r, p_r, s_r, rec_r)]
    # the points either camera can correlate (the right ones where the stereo match holds)
    ok0 = inside & (match.status == 0)
    grid = poi_grid(corr_l)  # right point i images left POI i: the same neighbours
    if two:
        cams = [(c.fork(workers=1), pp, ss, rec) for c, pp, ss, rec in cams]
    n_order = len(order)
    for forward, seg in (
        (True, list(range(reference + 1, f1))),
        (False, list(range(reference - 1, f0 - 1, -1))),
    ):
        before = [reference]  # the frames whose fields start the block's first frame
        for a in range(0, len(seg), 25):  # blocks of pairs, so that the progress moves
            blk = seg[a : a + 25]
            got: dict[int, tuple[int, BaseException | None]] = {}

            def one(
                cam: tuple[Any, ...],
                blk: list[int] = blk,
                before: list[int] = before,
                got: dict[int, tuple[int, BaseException | None]] = got,
            ) -> None:
                cc, pp, ss, rec = cam
                hist = [np.where((ss[f] == 0)[:, None], pp[f], np.nan) for f in before]
                got[id(cam)] = _track_camera(cc, rec, blk, hist, pp, ss, ok0, grid)

            each(one, cams, 2 if two else 1)
            n_done = min(d for d, _ in got.values())
            error = next((e for _, e in got.values() if e is not None), None)
            before = (before + blk[:n_done])[-HISTORY:]
            done += n_done
            if progress is not None:
                progress(done, n_order)
            if error is not None:
                # keep the pairs both cameras tracked, in one run from the reference
                kept = blk[:n_done]
                if forward:
                    f1 = kept[-1] + 1 if kept else blk[0]
                    f0 = reference  # the backward frames are not tracked yet
                else:
                    f0 = kept[-1] if kept else blk[0] + 1
                break
        if error is not None:
            break
    if error is not None and f1 - f0 < 2:
        raise error  # the reference pair alone: nothing tracked to keep
    tracking_time = time.perf_counter() - t_track
    nf = f1 - f0  # fewer when a frame stopped the tracking
    sl = slice(f0, f1)
    p_l, p_r, s_l, s_r = p_l[sl], p_r[sl], s_l[sl], s_r[sl]
    # (3) triangulation of every pair
    t_tri = time.perf_counter()
    iu, iv = 0, (1 if k == 2 else 3)
    cur_l = np.stack([rows + p_l[..., iv], cols + p_l[..., iu]], axis=-1)
    if k == 6:
        # the matched point lies delta off the right POI: the affine map carries it
        du = p_r[..., 0] + p_r[..., 1] * delta[:, 1] + p_r[..., 2] * delta[:, 0]
        dv = p_r[..., 3] + p_r[..., 4] * delta[:, 1] + p_r[..., 5] * delta[:, 0]
    else:
        du, dv = p_r[..., 0], p_r[..., 1]
    cur_r = np.stack([match.right[:, 0] + dv, match.right[:, 1] + du], axis=-1)
    xyz, resid = triangulate(rig, cur_l.reshape(-1, 2), cur_r.reshape(-1, 2))
    xyz = xyz.reshape(nf, n, 3)
    resid = resid.reshape(nf, n)
    disp = xyz - match.points[None]
    status = _combine(st_stereo[None, :], s_l, s_r)
    # a pair whose two points no longer meet one 3-D point is a gross error of either camera
    with np.errstate(invalid="ignore"):
        off = (status == 0) & ~(resid <= max_epipolar)
    status[off] = PointStatus.OUTLIER
    converged = status == 0
    triangulation_time = time.perf_counter() - t_tri
    # (4) blur of each camera from the 3-D track, and the propagated covariance
    t_pred = time.perf_counter()
    mx, my = exposure_motion(
        disp[..., 0], disp[..., 1], fps=fps_v, exposure=t_exp, valid=converged, threads=threads
    )
    mz, _ = exposure_motion(
        disp[..., 2], disp[..., 2], fps=fps_v, exposure=t_exp, valid=converged, threads=threads
    )
    motion = np.stack([mx, my, mz], axis=-1)
    wv_l, wv_r = blur_vectors(rig, xyz, motion)
    w_l, a_l = length_angle(wv_l)
    w_r, a_r = length_angle(wv_r)
    cen_l = np.stack([corr_l.rows, corr_l.cols], axis=1).astype(np.intp)
    cen_r = rr.astype(np.intp)
    use = inside & (match.status == 0)
    cov_l = np.full((nf, n, 2, 2), np.nan)
    cov_r = np.full((nf, n, 2, 2), np.nan)
    xi = np.full((nf, n, 4), np.nan)  # the signed mismatch shifts, (row, col) left, right
    if use.any():
        for j, ref, cen, w, ang, nz, cov in (
            (0, ref_l, cen_l, w_l, a_l, nz_l, cov_l),
            (1, ref_r, cen_r, w_r, a_r, nz_r, cov_r),
        ):
            ww = np.where(converged[:, use], w[:, use], np.nan)
            table = build_blur_table(
                ref,
                cen[use],
                subset=subset,
                shape=shape,
                blur=ww,
                angle=ang[:, use],
                threads=threads,
            )
            var = nz.variance(subset_levels(ref, cen[use], subset))
            c, _, shift = camera_covariance(table, ww, ang[:, use], var)
            cov[:, use] = c
            xi[:, use, 2 * j : 2 * j + 2] = shift
    pts = np.where(np.isfinite(xyz), xyz, match.points[None]).reshape(-1, 3)
    g = triangulation_jacobian(rig, pts)
    cov3_noise = propagate(g, cov_l.reshape(-1, 2, 2), cov_r.reshape(-1, 2, 2)).reshape(nf, n, 3, 3)
    # the two cameras' mismatch shifts together, each against its blurred reference: the
    # point's deterministic blur error
    xi = relative_shift(xi, reference - f0)
    bvec = (g @ xi.reshape(-1, 4, 1)).reshape(nf, n, 3)
    cov3_blur = bvec[..., :, None] * bvec[..., None, :]
    cov3 = cov3_noise + cov3_blur
    # the shape's sigma: the stereo match's noise in the right point
    g0 = triangulation_jacobian(rig, np.where(np.isfinite(match.points), match.points, 0.0))
    c_s = np.zeros((n, 2, 2))
    c_s[:, 0, 0], c_s[:, 1, 1] = match.sigma[:, 0] ** 2, match.sigma[:, 1] ** 2
    cov_shape = propagate(g0, np.zeros((n, 2, 2)), c_s)
    prediction_time = time.perf_counter() - t_pred
    sig = np.sqrt(np.maximum(np.diagonal(cov3, axis1=2, axis2=3), 0.0))
    sig_n = np.sqrt(np.maximum(np.diagonal(cov3_noise, axis1=2, axis2=3), 0.0))
    sig_b = np.sqrt(np.maximum(np.diagonal(cov3_blur, axis1=2, axis2=3), 0.0))
    valid = converged & np.isfinite(sig).all(axis=-1) & np.isfinite(disp).all(axis=-1)
    # subsets with clipped pixels in either reference: no noise or blur model there
    # (track/saturation.py, as dicblur track's `saturated`)
    notes: list[str] = []
    sat: dict[str, Float32Array] = {}
    for nm, ref, cen in (("left", ref_l, cen_l), ("right", ref_r, cen_r)):
        level = saturation_level(ref)
        sat[nm] = saturated_share(ref, cen, subset, level)
        if (sat[nm] > 0).any():
            notes.append(saturation_note(sat[nm], level, n, f" {nm}"))
    valid &= ~(too_saturated(sat["left"]) | too_saturated(sat["right"]))[None, :]
    fp = ("frame", "point")
    data: dict[str, Any] = {
        "X": ("point", match.points[:, 0]),
        "Y": ("point", match.points[:, 1]),
        "Z": ("point", match.points[:, 2]),
        "sigma_X": ("point", np.sqrt(cov_shape[:, 0, 0])),
        "sigma_Y": ("point", np.sqrt(cov_shape[:, 1, 1])),
        "sigma_Z": ("point", np.sqrt(cov_shape[:, 2, 2])),
        "right_row": ("point", match.right[:, 0]),
        "right_col": ("point", match.right[:, 1]),
        "epipolar_residual": ("point", match.residual),
        "zncc_stereo": ("point", match.zncc),
        "status_stereo": ("point", st_stereo),
        "U": (fp, disp[..., 0]),
        "V": (fp, disp[..., 1]),
        "W3": (fp, disp[..., 2]),
        "sigma_U": (fp, sig[..., 0]),
        "sigma_V": (fp, sig[..., 1]),
        "sigma_W3": (fp, sig[..., 2]),
        "cov_UV": (fp, cov3[..., 0, 1]),
        "cov_UW3": (fp, cov3[..., 0, 2]),
        "cov_VW3": (fp, cov3[..., 1, 2]),
        "u_left": (fp, p_l[..., iu]),
        "v_left": (fp, p_l[..., iv]),
        "u_right": (fp, du),
        "v_right": (fp, dv),
        "W_left": (fp, w_l),
        "W_right": (fp, w_r),
        "blur_direction_left": (fp, a_l),
        "blur_direction_right": (fp, a_r),
        "reprojection_residual": (fp, resid),
        "status": (fp, status),
        "status_left": (fp, s_l),
        "status_right": (fp, s_r),
        "valid": (fp, valid.astype(np.uint8)),
        "saturated_left": ("point", sat["left"]),
        "saturated_right": ("point", sat["right"]),
    }
    for j, nm in enumerate(("U", "V", "W3")):
        data[f"sigma_{nm}_noise"] = (fp, sig_n[..., j])
        data[f"sigma_{nm}_blur"] = (fp, sig_b[..., j])
    ds = xr.Dataset(
        data,
        coords={
            "frame": np.arange(f0, f1),
            "point": np.arange(n),
            "row": ("point", corr_l.rows),
            "col": ("point", corr_l.cols),
            "time": ("frame", np.arange(f0, f1) / fps_v + 0.5 * t_exp),
        },
    )
    ds["status"].attrs["legend"] = ", ".join(f"{s.value}={s.name}" for s in PointStatus)
    for v, unit in (("X", "mm"), ("U", "mm"), ("W_left", "px"), ("u_left", "px")):
        ds[v].attrs["units"] = unit
    ds.attrs.update(
        {
            "dicblur": __version__,
            "source_left": str(getattr(rec_l, "source", "left")),
            "source_right": str(getattr(rec_r, "source", "right")),
            "exposure": t_exp,
            "fps": fps_v,
            "subset": subset,
            "step": step,
            "shape": shape,
            "reference": reference,
            "noise_sigma_left": nz_l.sigma,
            "noise_sigma_right": nz_r.sigma,
            "noise_source": nz_l.source,
            "stereo_angle_deg": rig.stereo_angle,
            "baseline_mm": rig.baseline,
            "rig_rms_px": rig.rms if math.isfinite(rig.rms) else -1.0,
            "frame_of_reference": "left camera: x right, y down, z along the optical axis (mm)",
            "setup_time_s": t_track - t_start,
            "tracking_time_s": tracking_time,
            "triangulation_time_s": triangulation_time,
            "prediction_time_s": prediction_time,
            "total_time_s": time.perf_counter() - t_start,
            "n_frames_tracked": nf,
            "complete": int(error is None),
        }
    )
    if notes:
        ds.attrs["notes"] = " | ".join(notes)
    if error is not None:
        ds.attrs["stop_reason"] = f"stopped: {error}"
        raise TrackInterrupted(
            f"tracking stopped: {error} after {nf} of {n_want} frames; "
            "the frames tracked so far are kept",
            ds,
        ) from error
    return ds
