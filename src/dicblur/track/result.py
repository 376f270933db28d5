"""Result assembly of :func:`dicblur.track.track`: the post-processing of the tracked frames
(median test, kinematics, noise, predicted sigma, blur share, exposure advice) and the
``xarray.Dataset`` it returns.
"""

from __future__ import annotations

import itertools
import sys
import threading
import time
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..arrays import BoolArray, Float32Array, Float64Array, IndexArray, Int64Array
from ..dic import Correlator, PointStatus
from ..errors import DicblurError
from ..sequence import Recording
from .advice import advise_exposure
from .flags import (
    frame_blocks,
    frame_filled,
    median_critical,
    nanmedian_last,
    own_sigma_eps,
    zncc_flags,
)
from .frames import Tracked
from .kinematics import exposure_motion, exposure_skew
from .noise import NoiseEstimate, subset_levels
from .saturation import saturated_share, saturation_level, saturation_note, too_saturated
from .skew import build_skew_table
from .uncertainty import build_blur_table

#: Static frames whose median displacement spreads by more than this (px) are moving.
STATIC_MOTION_PX = 0.05


def _grid_shape(rows: Int64Array, cols: Int64Array) -> tuple[int, int] | None:
    ur, uc = np.unique(rows), np.unique(cols)
    if ur.size * uc.size != rows.size:
        return None
    if not (
        np.array_equal(rows, np.repeat(ur, uc.size)) and np.array_equal(cols, np.tile(uc, ur.size))
    ):
        return None
    return int(ur.size), int(uc.size)


def _by_runs(
    fn: Callable[..., tuple[NDArray[Any], NDArray[Any]]],
    runs: list[slice],
    n_f: int,
    u: Float64Array,
    v: Float64Array,
    good: BoolArray,
    **kw: Any,
) -> tuple[NDArray[Any], NDArray[Any]]:
    """``fn(u, v, valid=good, **kw)`` (two (frames, points) arrays, a kinematics function
    of :mod:`.kinematics`) fitted on each run of consecutive frames ``runs`` (slices of
    the ``n_f`` frames, at least one) on its own, NaN between them; one call on the whole
    track when it is one run."""
    if len(runs) == 1 and runs[0] == slice(0, n_f):
        return fn(u, v, valid=good, **kw)
    parts = [(r, fn(u[r], v[r], valid=good[r], **kw)) for r in runs]
    a0, b0 = parts[0][1]
    a = np.full((n_f, *a0.shape[1:]), np.nan, a0.dtype)
    b = np.full((n_f, *b0.shape[1:]), np.nan, b0.dtype)
    for r, (pa, pb) in parts:
        a[r], b[r] = pa, pb
    return a, b


def _polar(wu: NDArray[Any], wv: NDArray[Any], threads: int) -> tuple[NDArray[Any], NDArray[Any]]:
    """Blur length ``W`` (px) and direction (deg in [0, 180), from +x towards +y: a
    centred box blur is the same both ways) of the blur vectors ``(wu, wv)`` (frames,
    points; the dtype of theirs), in blocks of frames on ``threads`` threads (numpy's
    loops release the GIL)."""
    w = np.empty(wu.shape, np.result_type(wu, wv))
    ang = np.empty_like(w)

    def one(b: IndexArray) -> None:
        r = slice(int(b[0]), int(b[-1]) + 1)
        np.hypot(wu[r], wv[r], out=w[r])
        a = np.degrees(np.arctan2(wv[r], wu[r]))
        np.mod(a, 180.0, out=ang[r])

    if wu.size:
        frame_blocks(one, np.arange(wu.shape[0]), 128, threads)
    return w, ang


def _prefetch_xarray() -> threading.Thread | None:
    """Import xarray and what its first Dataset imports (pandas, dask's arrays: about
    0.8 CPU-s in a fresh process) on a side thread while the post-processing runs, off
    its critical path; None when already done. Join before building the Dataset."""
    if "xarray" in sys.modules and "dask.array" in sys.modules:
        return None

    def run() -> None:
        try:
            import xarray as xr

            xr.Dataset({"x": ("x", np.zeros(1))})
        except Exception:  # the main thread's own import reports any problem
            pass

    t = threading.Thread(target=run, name="dicblur-import-xarray", daemon=True)
    t.start()
    return t


def assemble(
    rec: Recording,
    corr: Correlator,
    out: Tracked,
    refs: list[int],
    noise: NoiseEstimate | None,
    st_range: tuple[int, int] | None,
    fps: float,
    t_exp: float,
    settings: dict[str, Any],
    notes: list[str],
    *,
    half_window: int,
    eps: float,
    threshold: float,
    advice: bool,
    ref_img: Float64Array,
    blur_table: Callable[..., Any] = build_blur_table,
    threads: int = 1,
    compensated: bool = False,
    strain: int | None = None,
) -> Any:
    from .._version import __version__

    idx = np.argsort(out.frames)
    frames = np.asarray(out.frames, dtype=np.int64)[idx]

    def stacked(lst: list[Any], dtype: Any) -> Any:
        """Frames in order, one copy; the list is emptied (memory of long recordings)."""
        a = np.empty((len(lst), *np.shape(lst[0])), dtype)
        for i, j in enumerate(idx):
            a[i] = lst[j]
        lst.clear()
        return a

    u = stacked(out.u, np.float64)
    v = stacked(out.v, np.float64)
    zn = stacked(out.zncc, np.float32)
    st = stacked(out.status, np.uint8)
    fb = np.asarray(out.fallback)[idx]
    ref_of = np.asarray(refs, dtype=np.int64)[idx]
    n_f, n_p = u.shape
    conv = st == PointStatus.CONVERGED
    gshape = _grid_shape(corr.rows, corr.cols)
    if gshape is None:
        notes.append("POIs not on a grid: no normalised median test")
    # pass 1: the median test at its fixed eps (keeps errors of tenths of a px out of the
    # blur estimate) and the ZNCC test; pass 2, once sigma is known, at eps from each
    # point's own predicted sigma (flags.own_sigma_eps), which sets the final flags
    t_med = time.perf_counter()
    # the largest eps at which the test flags each point: both passes from one median pass
    crit = median_critical(u, v, conv, gshape, threshold, threads=threads)
    outlier = crit > eps
    settings["median_time_s"] = time.perf_counter() - t_med
    low_zncc = zncc_flags(
        zn, conv, correlatable=~np.isin(st, (PointStatus.OUT_OF_BOUNDS, PointStatus.LOW_TEXTURE))
    )
    # runs of consecutive frames (one, unless tracking stopped in the middle of chunks run
    # side by side): the kinematics fits each run on its own
    cuts = [0, *(np.flatnonzero(np.diff(frames) != 1) + 1).tolist(), n_f]
    runs = [slice(a, b) for a, b in itertools.pairwise(cuts) if b - a >= 2]
    kin: dict[str, Any] = {
        "fps": fps,
        "exposure": t_exp,
        "half_window": half_window,
        "threads": threads,
    }

    def motion(good: BoolArray) -> tuple[Float32Array, Float32Array]:
        if not runs:
            nan = np.full((n_f, n_p), np.nan, np.float32)
            return nan, nan.copy()
        return _by_runs(exposure_motion, runs, n_f, u, v, good, dtype=np.float32, **kin)

    if not runs:
        notes.append("fewer than 2 consecutive frames: no blur estimate")
    elif len(cuts) > 2:
        notes.append(
            f"the frames tracked form {len(cuts) - 1} separate runs (tracking stopped "
            "part-way): the blur is estimated within each run of 2 frames or more"
        )
    good = conv & ~outlier & ~low_zncc
    wu, wv = motion(good)
    w, ang = _polar(wu, wv, threads)
    # static range: check for motion (it inflates the pairwise-difference noise)
    if st_range is not None:
        sel = (frames >= st_range[0]) & (frames < st_range[1])
        if sel.sum() >= 2:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                mu = nanmedian_last(np.where(good[sel], u[sel], np.nan))
                mv = nanmedian_last(np.where(good[sel], v[sel], np.nan))
            spread = float(max(np.nanmax(mu) - np.nanmin(mu), np.nanmax(mv) - np.nanmin(mv)))
            settings["static_motion_px"] = spread
            if spread > STATIC_MOTION_PX:
                msg = (
                    f"static={st_range[0]}:{st_range[1]}: the scene moves by {spread:.3g} "
                    "px over these frames, so the noise estimate from their differences "
                    "is too high; give frames where nothing moves, or --noise"
                )
                warnings.warn(msg, UserWarning, stacklevel=4)
                notes.append(msg)
    centres = np.stack([corr.rows, corr.cols], axis=1).astype(np.intp)
    inside = (
        (corr.rows - corr.half >= 0)
        & (corr.cols - corr.half >= 0)
        & (corr.rows + corr.half < ref_img.shape[0])
        & (corr.cols + corr.half < ref_img.shape[1])
    )
    # derived per-point fields in float32 (7 significant digits; halves the memory of a
    # long recording), displacements stay float64
    names = ("sigma_u_noise", "sigma_v_noise", "sigma_u_blur", "sigma_v_blur")

    def nan_fields() -> dict[str, Float32Array]:
        return {k: np.full((n_f, n_p), np.nan, np.float32) for k in names}

    sig: dict[str, Float32Array] = {}
    importing: threading.Thread | None = None
    blur_dom = np.full(n_f, np.nan)
    levels: Float64Array | None = None  # of the subsets inside, once known
    t0 = time.perf_counter()
    table: Any = None
    if noise is not None and inside.any():
        pin = np.flatnonzero(inside)
        # all points inside (the usual grid): plain slices, no fancy-indexed copies
        cols: slice | IndexArray = slice(None) if pin.size == n_p else pin
        table = blur_table(
            ref_img,
            centres[pin],
            subset=corr.subset,
            shape=corr.shape,
            blur=np.where(good[:, cols], w[:, cols], np.nan),
            angle=ang[:, cols],
            threads=threads,
        )
        settings["blur_table_time_s"] = time.perf_counter() - t0
        # on threads > 1 only (one thread asked for: no second core), after the table;
        # the modules it loads (about 50 MB) stay resident: the 2,000-frame 1 Mpx memory
        # target runs on one thread
        importing = _prefetch_xarray() if threads > 1 else None
        # allocated after the table: its FFTs of the reference are the peak of a long
        # recording's memory (issue 17: < 1 GB for 2,000 frames of 1 Mpx)
        sig = nan_fields()
        levels = subset_levels(ref_img, centres[pin], corr.subset)
        nv = noise.variance(levels)

        outs = tuple(sig[k] for k in names)

        def predict(rows: IndexArray | None = None, at: Any = None) -> None:
            wa, aa = (w, ang) if at is None else at

            def one(b: IndexArray) -> None:  # frame blocks on the threads
                table.predict_into(wa, aa, nv, b, pin, outs)  # NaN: blur unknown

            frame_blocks(one, np.arange(n_f) if rows is None else rows, 128, threads)

        # first at the frame's median blur vector where a point's own blur is unknown (a
        # flag in its stencil): every converged point gets a sigma for the gross-error
        # test below; those stay NaN in the result (masked after the test)
        predict(at=_polar(frame_filled(wu, conv), frame_filled(wv, conv), threads))
        if gshape is not None:
            s_own = np.empty((n_f, n_p), np.float32)

            def largest(b: IndexArray) -> None:  # frame blocks on the threads
                r = slice(int(b[0]), int(b[-1]) + 1)
                np.fmax(
                    np.hypot(sig["sigma_u_noise"][r], sig["sigma_u_blur"][r]),
                    np.hypot(sig["sigma_v_noise"][r], sig["sigma_v_blur"][r]),
                    out=s_own[r],
                )

            frame_blocks(largest, np.arange(n_f), 128, threads)
            # the test at each point's own predicted sigma, at a set false-alarm rate
            # (flags.own_sigma_eps); where no sigma is known, the fixed eps
            eps_pt = own_sigma_eps(frame_filled(s_own, conv & ~outlier), threshold)
            eps_pt = np.where(np.isfinite(eps_pt) & (eps_pt > 0), eps_pt, eps)
            del s_own
            # the second pass leaves out the low-ZNCC points too: the medians change only
            # in the frames that have some
            t_med = time.perf_counter()
            median_critical(
                u,
                v,
                conv & ~low_zncc,
                gshape,
                threshold,
                frames=np.flatnonzero((conv & low_zncc).any(axis=1)),
                out=crit,
                threads=threads,
            )
            # replaces the first pass (its fixed 0.1 px only kept gross errors out of the
            # blur estimate): a point is flagged against its own predicted range
            second = crit > eps_pt
            del eps_pt
            settings["median_time_s"] += time.perf_counter() - t_med
            if (second != outlier).any():
                outlier = second
                good = conv & ~outlier & ~low_zncc
                wu, wv = motion(good)
                w_old, ang_old = w, ang
                w, ang = _polar(wu, wv, threads)
                w_in = np.where(good[:, cols], w[:, cols], np.nan)
                if np.any(w_in > table.blur[-1]):
                    # the new blur reaches past the table's last node: add the nodes
                    # (the computed ones are kept) and predict every frame
                    table = blur_table(
                        ref_img,
                        centres[pin],
                        subset=corr.subset,
                        shape=corr.shape,
                        blur=w_in,
                        angle=ang[:, cols],
                        have=table,
                        threads=threads,
                    )
                    predict()
                else:
                    # only the frames whose blur changed (a new flag in their stencil)
                    same = ((w == w_old) | (np.isnan(w) & np.isnan(w_old))) & (
                        (ang == ang_old) | (np.isnan(ang) & np.isnan(ang_old))
                    )
                    del w_old, ang_old
                    predict(np.flatnonzero(~same.all(axis=1)))
        settings["blur_table_max_px"] = float(table.blur[-1])
        settings["blur_table_angles_deg"] = ",".join(
            f"{a:g}" for a in table.angles[table.available]
        )
    if not sig:
        sig = nan_fields()
    for a in sig.values():  # no sigma where the point's own blur is unknown
        a[~np.isfinite(w)] = np.nan
    del crit
    # after a reference renewal the increments add to the renewal frame's displacement:
    # its predicted variance carries over (into the noise part: a random error)
    pos = {int(f): i for i, f in enumerate(frames)}
    ref0 = int(settings["reference"])
    for i in sorted(range(n_f), key=lambda i: abs(int(frames[i]) - ref0)):
        j = pos.get(int(ref_of[i]))
        if int(ref_of[i]) != ref0 and j is not None:
            for c in ("u", "v"):
                carry = np.hypot(sig[f"sigma_{c}_noise"][j], sig[f"sigma_{c}_blur"][j])
                sig[f"sigma_{c}_noise"][i] = np.hypot(sig[f"sigma_{c}_noise"][i], carry)
    # subsets with clipped pixels in the reference: their sigma does not hold (saturation)
    sat_level = saturation_level(ref_img)
    saturated = saturated_share(ref_img, centres, corr.subset, sat_level)
    clipped = too_saturated(saturated)
    if (saturated > 0).any():
        settings["saturation_level"] = sat_level
        notes.append(saturation_note(saturated, sat_level, n_p))
    sigma_u = np.empty((n_f, n_p), np.float32)
    sigma_v = np.empty((n_f, n_p), np.float32)
    valid = np.empty((n_f, n_p), bool)
    cnt = np.zeros(n_f, np.intp)
    n_dom = np.zeros(n_f, np.intp)
    outlier |= low_zncc

    def totals(b: IndexArray) -> None:  # frame blocks on the threads
        r = slice(int(b[0]), int(b[-1]) + 1)
        np.hypot(sig["sigma_u_noise"][r], sig["sigma_u_blur"][r], out=sigma_u[r])
        np.hypot(sig["sigma_v_noise"][r], sig["sigma_v_blur"][r], out=sigma_v[r])
        valid[r] = good[r] & np.isfinite(sigma_u[r]) & np.isfinite(sigma_v[r]) & np.isfinite(w[r])
        valid[r] &= ~clipped
        with np.errstate(invalid="ignore"):
            dom = np.hypot(sig["sigma_u_blur"][r], sig["sigma_v_blur"][r]) > np.hypot(
                sig["sigma_u_noise"][r], sig["sigma_v_noise"][r]
            )
        cnt[r] = valid[r].sum(axis=1)
        n_dom[r] = (dom & valid[r]).sum(axis=1)

    if n_f:
        frame_blocks(totals, np.arange(n_f), 128, threads)
    with np.errstate(invalid="ignore"):
        blur_dom = np.where(cnt > 0, n_dom / np.maximum(cnt, 1), np.nan)
    # the exposure advice needs only the final blur and valid points: on threads > 1 it
    # runs on a side thread beside the skew table and the bias (both mostly serial)
    want_advice = bool(advice and noise is not None and valid.any())
    adv_out: dict[str, Any] = {}

    def run_advice() -> None:
        assert noise is not None and levels is not None
        t_adv = time.perf_counter()
        try:
            adv_out["advice"] = advise_exposure(
                ref_img,
                centres[inside],
                (w / t_exp)[valid],
                ang[valid],
                exposure=t_exp,
                fps=fps,
                noise=noise,
                level=float(np.median(levels)),
                subset=corr.subset,
                shape=corr.shape,
                bit_depth=rec.bit_depth,
                compensated=compensated,
            )
        except DicblurError as exc:
            adv_out["note"] = f"no exposure advice: {exc}"
        except BaseException as exc:  # re-raised by the main thread
            adv_out["error"] = exc
        adv_out["time"] = time.perf_counter() - t_adv

    side: threading.Thread | None = None
    if want_advice and threads > 1:
        side = threading.Thread(target=run_advice, name="dicblur-advice", daemon=True)
        side.start()
    # the bias of an accelerating blur: the kernel's third moment from the fitted track
    # times each subset's skew coefficient (a shift common to nearly all points)
    bias: Float32Array | None = None
    if noise is not None and inside.any() and runs:
        pin = np.flatnonzero(inside)
        # beside the advice's thread: one core each (the advice, about as long as the
        # skew, no longer waits for a core after the skew's threads are done)
        skew_threads = threads if side is None else max(1, threads - 1)
        k3, axis = _by_runs(
            exposure_skew, runs, n_f, u, v, good, **{**kin, "threads": skew_threads}
        )
        at: slice | IndexArray = slice(None) if pin.size == n_p else pin  # no copies
        skew = build_skew_table(
            ref_img,
            centres[pin],
            subset=corr.subset,
            shape=corr.shape,
            axis=axis[:, at],
            kappa3=k3[:, at],
            threads=skew_threads,
        )
        skew_bias = bias = np.full((n_f, n_p, 2), np.nan, np.float32)  # after the table

        def one_bias(b: IndexArray) -> None:
            skew.bias_into(k3, axis, b, pin, skew_bias)

        frame_blocks(one_bias, np.arange(n_f), 128, skew_threads)
        del k3, axis
    if bias is None:
        bias = np.full((n_f, n_p, 2), np.nan, np.float32)
    settings["prediction_time_s"] = time.perf_counter() - t0
    attrs: dict[str, Any] = {
        **{k: v for k, v in settings.items() if v is not None},
        "dicblur_version": __version__,
        "complete": 1,
        "n_frames_tracked": int(n_f),
        "status_legend": ", ".join(f"{s.value}={s.name}" for s in PointStatus),
    }
    if noise is not None:
        attrs.update(
            {
                f"noise_{k}": (int(v) if isinstance(v, bool) else v)
                for k, v in noise.to_dict().items()
            }
        )
    if want_advice:
        if side is None:
            run_advice()
        else:
            side.join()
        if "error" in adv_out:
            raise adv_out["error"]
        if "advice" in adv_out:
            attrs.update({f"advice_{k}": v for k, v in adv_out["advice"].to_dict().items()})
        else:
            notes.append(adv_out["note"])
        attrs["advice_time_s"] = adv_out["time"]
    if notes:
        attrs["notes"] = " | ".join(notes)
    if importing is not None:
        importing.join()
    strain_vars: dict[str, Any] = {}
    if strain is not None and gshape is not None:  # docs/strain.md: strains beside u, v
        from ..strain.track import track_strain

        t_s = time.perf_counter()
        strain_vars, strain_attrs = track_strain(
            u, v, valid, sig["sigma_u_noise"], sig["sigma_v_noise"], table, w, ang,
            np.flatnonzero(inside), gshape, step=corr.step, subset=corr.subset, window=strain,
        )  # fmt: skip
        attrs.update(strain_attrs, strain_time_s=time.perf_counter() - t_s)
    import xarray as xr

    fr = ("frame", "point")
    pu = {"units": "px"}
    data = {
        "u": (fr, u, {"units": "px", "long_name": "displacement along x"}),
        "v": (fr, v, {"units": "px", "long_name": "displacement along y"}),
        "blur_u": (
            fr,
            np.asarray(wu, np.float32),
            {"units": "px", "long_name": "motion along x during the exposure"},
        ),
        "blur_v": (
            fr,
            np.asarray(wv, np.float32),
            {"units": "px", "long_name": "motion along y during the exposure"},
        ),
        "W": (fr, np.asarray(w, np.float32), {"units": "px", "long_name": "blur length"}),
        "blur_direction": (
            fr,
            np.asarray(ang, np.float32),
            {"units": "deg", "long_name": "blur direction from +x towards +y"},
        ),
        "sigma_u": (fr, sigma_u, pu),
        "sigma_v": (fr, sigma_v, pu),
        **{k: (fr, a, pu) for k, a in sig.items()},
        "bias_u": (
            fr,
            bias[..., 0],
            {
                "units": "px",
                "long_name": "predicted bias of an accelerating blur (kernel skew), along x",
            },
        ),
        "bias_v": (
            fr,
            bias[..., 1],
            {
                "units": "px",
                "long_name": "predicted bias of an accelerating blur (kernel skew), along y",
            },
        ),
        "status": (fr, st, {"legend": attrs["status_legend"]}),
        "zncc": (fr, zn),
        "outlier": (
            fr,
            outlier.astype(np.uint8),
            {
                "long_name": "gross error: normalised median test (Westerweel & "
                "Scarano 2005) or ZNCC far below the point's usual"
            },
        ),
        "valid": (fr, valid.astype(np.uint8)),
        "saturated": (
            "point",
            saturated,
            {"long_name": "share of clipped pixels in the reference subset (not valid if > 0)"},
        ),
        "n_converged": ("frame", conv.sum(axis=1).astype(np.int32)),
        "n_outliers": ("frame", outlier.sum(axis=1).astype(np.int32)),
        "blur_dominated_share": ("frame", blur_dom),
        "reference_frame": ("frame", ref_of.astype(np.int32)),
        "fallback": ("frame", fb.astype(np.uint8), {"long_name": "frame needed the FFT-CC start"}),
        **{k: (fr, a) for k, a in strain_vars.items()},
    }
    return xr.Dataset(
        data,
        coords={
            "frame": ("frame", frames),
            "point": ("point", np.arange(n_p)),
            "row": ("point", corr.rows.astype(np.int32)),
            "col": ("point", corr.cols.astype(np.int32)),
            "time": ("frame", frames / fps + 0.5 * t_exp, {"units": "s"}),
        },
        attrs=attrs,
    )
