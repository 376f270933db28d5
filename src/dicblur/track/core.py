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

import itertools
import math
import sys
import threading
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..checks import check_positive
from ..dic import Correlator, MatcherSettings, PointStatus, PreparedImage
from ..dic.initial import window_spectrum
from ..errors import DicblurError, InputError
from ..metrics import box_sssig, image_gradients, match_score_sigma
from ..models.units import parse_quantity
from ..sequence import Recording, open_recording
from ..threads import each
from .advice import advise_exposure
from .compensate import MATCHER_PLAIN, build_compensated_table, compensate_track
from .grid import extrapolate_fields, fill_with_median
from .kinematics import exposure_motion, exposure_skew
from .median import median_critical_eps
from .uncertainty import (
    NoiseEstimate,
    build_blur_table,
    build_skew_table,
    estimate_static_noise,
    subset_levels,
)

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

#: A frame falls back to the engine's FFT-CC start when more than this share of its
#: correlatable points fails from the extrapolated guess.
FALLBACK_SHARE = 0.02
#: Static frames whose median displacement spreads by more than this (px) are moving.
STATIC_MOTION_PX = 0.05


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


def parse_rate(value: float | str, name: str = "fps") -> float:
    """Frame rate from a number (Hz) or ``"5000"``, ``"5000fps"``, ``"5kHz"``, ``"2000Hz"``."""
    if isinstance(value, int | float) and not isinstance(value, bool):
        x = float(value)
    else:
        text = str(value).strip().lower().replace(" ", "")
        mult = 1.0
        for suffix, m in (("khz", 1e3), ("mhz", 1e6), ("hz", 1.0), ("fps", 1.0)):
            if text.endswith(suffix):
                text, mult = text[: -len(suffix)], m
                break
        try:
            x = float(text) * mult
        except ValueError as exc:
            raise InputError(
                f"{name}={value!r}: expected a frame rate such as 5000, '5000fps' or '5kHz'"
            ) from exc
    if not math.isfinite(x) or x <= 0:
        raise InputError(f"{name}={value!r}: the frame rate must be > 0 Hz, e.g. 5000")
    return x


def parse_frame_range(
    text: str | Sequence[int], n_frames: int, name: str = "static"
) -> tuple[int, int]:
    """``"0:20"`` (half-open, Python style; negative counts from the end) -> (0, 20)."""
    if isinstance(text, str):
        parts = text.split(":")
        try:
            if len(parts) != 2:
                raise ValueError
            a = int(parts[0]) if parts[0] else 0
            b = int(parts[1]) if parts[1] else n_frames
        except ValueError as exc:
            raise InputError(
                f"{name}={text!r}: expected START:STOP frame numbers, e.g. 0:20"
            ) from exc
    else:
        a, b = (int(x) for x in text)
    a = a + n_frames if a < 0 else a
    b = b + n_frames if b < 0 else b
    if not 0 <= a < b <= n_frames:
        raise InputError(
            f"{name}={text!r}: must satisfy 0 <= START < STOP <= {n_frames} "
            "(the recording's frames)"
        )
    return a, b


def _resolve(
    value: Any, meta: float | None, kind: str, name: str, flag: str, example: str
) -> float:
    given = None
    if value is not None:
        given = (
            parse_rate(value, name) if kind == "rate" else parse_quantity(value, "time", name=name)
        )
        if given <= 0:
            raise InputError(f"{name}={value!r}: must be > 0, e.g. {example}")
    if given is not None and meta is not None and abs(given - meta) > 0.01 * meta:
        warnings.warn(
            f"{flag}={value}: the recording's metadata says {meta:g} "
            f"{'Hz' if kind == 'rate' else 's'}; using the value given",
            UserWarning,
            stacklevel=3,
        )
    out = given if given is not None else meta
    if out is None:
        raise InputError(
            f"{flag}: the recording has no {name} in its metadata; give "
            f"{flag} (e.g. {flag} {example})"
        )
    return float(out)


def _grid_shape(rows: NDArray[np.int64], cols: NDArray[np.int64]) -> tuple[int, int] | None:
    ur, uc = np.unique(rows), np.unique(cols)
    if ur.size * uc.size != rows.size:
        return None
    if not (
        np.array_equal(rows, np.repeat(ur, uc.size)) and np.array_equal(cols, np.tile(uc, ur.size))
    ):
        return None
    return int(ur.size), int(uc.size)


class ChunkRunner(Protocol):
    """Runs the correlation of :func:`track` in chunks (:class:`.parallel.ChunkedRun`).

    ``run`` returns a mapping with the lists ``frames``, ``u``, ``v``, ``zncc``,
    ``status``, ``fallback`` (one entry per frame tracked) and ``error`` (the exception
    that stopped it, or None). With ``compensate_blur`` the runner's ``compensate`` (the
    signature of :func:`.compensate.compensated_pass`) runs the compensated passes.
    """

    def run(
        self,
        rec: Recording,
        corr: Correlator,
        *,
        reference: int,
        order: list[int],
        correlator: dict[str, Any],
        progress: Callable[[int, int], None] | None,
    ) -> dict[str, Any]: ...


@dataclass
class _Tracked:
    """Raw per-frame results of the correlation loop, in frame order."""

    frames: list[int]
    u: list[NDArray[np.float64]]
    v: list[NDArray[np.float64]]
    zncc: list[NDArray[np.float64]]
    status: list[NDArray[np.uint8]]
    fallback: list[bool]


def _extrapolate(
    hist: list[tuple[NDArray[np.float64], NDArray[np.float64]]],
    grid: tuple[tuple[int, int], NDArray[np.intp]] | None = None,
) -> NDArray[np.float64] | None:
    """Guess (n, 2) for the next frame from up to the last three fields: the last field
    plus the increment of the linear (two fields) or quadratic (three) extrapolation,
    that increment averaged over each point's 3 x 3 neighbours when ``grid`` (the grid
    shape and each point's cell) is given. The quadratic extrapolation ``3 u1 - 3 u2 +
    u3`` multiplies the random error of each point's track by 4.4; its increment ``2 u1 -
    3 u2 + u3`` is a smooth field (the motion), so the mean over 9 points cuts the guess's
    random error to 1.6 sigma (issue 17: 2.8 -> 2.4 IC-GN iterations, affine, W 0-2.5 px),
    at the cost of the increment's curvature over two grid steps (exact for a locally
    linear motion)."""
    if not hist:
        return None
    g = extrapolate_fields(hist[-3:], grid)
    good = np.asarray(np.isfinite(g).all(axis=1))
    if not good.any():
        return None
    fill_with_median(g, good)
    return g


def _rigid_shift(
    spectrum: NDArray[np.complex64], img: NDArray[np.float64]
) -> tuple[float, float, float]:
    """Sub-pixel rigid shift ``(u, v)`` (px) of ``img`` against the reference whose
    :func:`~dicblur.dic.initial.window_spectrum` is ``spectrum``, and the peak height:
    the phase correlation of :func:`~dicblur.dic.initial.global_shift` with a parabola
    through the peak and its neighbours along each axis (about 0.1 px on blurred speckle
    frames, where the integer shift is up to 0.5 px off)."""
    from scipy import fft as sfft

    fb = window_spectrum(img)
    cross = fb * np.conj(spectrum)
    cross /= np.maximum(np.abs(cross), 1e-12)
    wr = min(128, img.shape[0])
    wc = min(128, img.shape[1])
    corr = sfft.irfft2(cross, s=(wr, wc))
    idx = int(np.argmax(corr))
    dy, dx = (int(i) for i in np.unravel_index(idx, corr.shape))
    c0 = float(corr[dy, dx])

    def vertex(cm: float, cp: float) -> float:
        den = cm - 2.0 * c0 + cp
        return 0.5 * (cm - cp) / den if den < 0 else 0.0

    fy = vertex(float(corr[(dy - 1) % wr, dx]), float(corr[(dy + 1) % wr, dx]))
    fx = vertex(float(corr[dy, (dx - 1) % wc]), float(corr[dy, (dx + 1) % wc]))
    v = (dy if dy <= wr // 2 else dy - wr) + fy
    u = (dx if dx <= wc // 2 else dx - wc) + fx
    return u, v, c0


#: Every SEED_EVERY-th point is a seed: correlated first from the guesses, their median
#: correction moves the guesses of all points (a common error of the extrapolation).
SEED_EVERY = 16
#: Large grids thin the seeds, up to every SEED_EVERY_MAX-th point, while at least
#: SEEDS_ENOUGH remain: the median of 64 corrections is within ~1.25 sigma / 8 of the
#: common error already (speed benchmark, 2,401 points: 151 -> 76 seeds, the frame's
#: IC-GN iterations the same to 4 digits, the seeds' cost halved).
SEED_EVERY_MAX = 32
SEEDS_ENOUGH = 64


def seed_correlator(
    reference: NDArray[np.float64], corr: Correlator, opts: dict[str, Any]
) -> tuple[Correlator, NDArray[np.intp]] | None:
    """A Correlator on every :data:`SEED_EVERY`-th POI of ``corr`` (its reference image
    ``reference``; on large grids every k-th, k <= :data:`SEED_EVERY_MAX`, keeping at
    least :data:`SEEDS_ENOUGH` seeds), or None when there are too few POIs for seeds to
    pay."""
    every = max(SEED_EVERY, min(SEED_EVERY_MAX, corr.n_points // SEEDS_ENOUGH))
    idx = np.arange(0, corr.n_points, every)
    if idx.size < 16:
        return None
    pts = np.stack([corr.rows[idx], corr.cols[idx]], axis=1)
    kw = {k: v for k, v in opts.items() if k not in ("step", "roi", "points")}
    return Correlator(reference, points=pts, **kw), idx


def _start(
    corr: Correlator, guess: NDArray[np.float64], grads: NDArray[np.float64] | None
) -> NDArray[np.float64]:
    """IC-GN start of ``corr``'s points: ``guess`` (n, 2) px, with the displacement
    gradients ``grads`` (n, 4) as the affine parameters (n, 6) when both apply."""
    if grads is None or corr.shape != "affine":
        return guess
    g = grads
    return np.stack([guess[:, 0], g[:, 0], g[:, 1], guess[:, 1], g[:, 2], g[:, 3]], axis=1)


def _seed_correction(
    seeds: tuple[Correlator, NDArray[np.intp]] | None,
    img: NDArray[np.float64] | PreparedImage,
    guess: NDArray[np.float64],
    grads: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]:
    """``guess`` (n, 2, relative to the seeds' reference) moved by the median error of
    the guesses at the converged seeds (unchanged when fewer than half converge); affine
    seeds start from the displacement gradients ``grads`` (n, 4) too."""
    if seeds is None:
        return guess
    sc, idx = seeds
    g = guess[idx]
    r = _fit(sc, img, _start(sc, g, None if grads is None else grads[idx]))
    ok = r.status == PointStatus.CONVERGED
    if ok.sum() < max(8, idx.size // 2):
        return guess
    d = np.median(np.stack([r.u[ok] - g[ok, 0], r.v[ok] - g[ok, 1]], axis=1), axis=0)
    return guess + d


def frame_guess(
    hist: list[tuple[NDArray[np.float64], NDArray[np.float64]]],
    rig: list[NDArray[np.float64] | None],
    img: NDArray[np.float64] | PreparedImage,
    spectrum: NDArray[np.complex64],
    base: NDArray[np.float64],
    seeds: tuple[Correlator, NDArray[np.intp]] | None,
    *,
    grid: tuple[tuple[int, int], NDArray[np.intp]] | None = None,
    grads: NDArray[np.float64] | None = None,
) -> tuple[NDArray[np.float64] | None, NDArray[np.float64] | None]:
    """Initial guess (n, 2) px of the next frame ``img`` (None without history) and the
    frame's rigid shift (2,) px (None without a phase-correlation peak), from the last
    fields ``hist`` and their rigid shifts ``rig`` (``img`` as an array or the frame
    Correlator's :meth:`~dicblur.dic.Correlator.prefilter`, which the seeds then share),
    against the current reference (its
    ``window_spectrum``); ``base`` is the displacement of that reference's POIs; ``grid``
    (the POI grid's shape and each point's cell, :func:`poi_grid`) smooths the
    extrapolated increment; ``grads`` (n, 4), the last frame's displacement gradients
    (affine), start the seeds. The serial loop and each chunk of
    :mod:`dicblur.track.parallel` call this one step."""
    gu, gv, peak = _rigid_shift(spectrum, img.image if isinstance(img, PreparedImage) else img)
    g_abs = np.array([gu, gv]) + np.median(base, axis=0) if peak > 0.05 else None
    guess = _extrapolate(hist, grid)
    if guess is not None and g_abs is not None:
        rig_last = rig[-min(len(hist), 3) :]
        if all(r is not None for r in rig_last):
            # the extrapolated field's non-rigid part plus the measured rigid shift: the
            # extrapolation of a sine at 10 frames per cycle misses by ~1-2.5 px (turning
            # points), the phase correlation by ~0.1 px, and IC-GN needs about half the
            # iterations from there
            r = [np.asarray(x) for x in rig_last]
            r_ext = (
                r[-1]
                if len(r) == 1
                else 2 * r[-1] - r[-2]
                if len(r) == 2
                else 3 * r[-1] - 3 * r[-2] + r[-3]
            )
            guess = guess + (g_abs - r_ext)
        else:
            # no rigid shift for the frames of the extrapolation: move the guesses by the
            # whole px when the shift is more than 1 px from their median
            dmed = g_abs - np.median(guess, axis=0)
            if np.hypot(*dmed) > 1.0:
                guess = guess + np.rint(dmed)
    if guess is not None:
        # the seeds (1/16 of the points) from the guesses first: the median of their
        # corrections removes the guesses' common error (~0.1-0.5 px after the rigid
        # shift), so the rest need fewer iterations
        guess = _seed_correction(seeds, img, guess - base, grads) + base
    return guess, g_abs


def poi_grid(corr: Correlator) -> tuple[tuple[int, int], NDArray[np.intp]] | None:
    """The POI grid of ``corr`` as :func:`frame_guess` takes it: ``(grid_shape,
    grid_cells)``, or None when the POIs are not on a grid."""
    cells = corr.grid_cells
    shape = corr.grid_shape
    return None if cells is None or shape is None else (shape, cells)


@dataclass(frozen=True)
class _FrameResult:
    u: NDArray[np.float64]
    v: NDArray[np.float64]
    zncc: NDArray[np.float64]
    status: NDArray[np.uint8]
    params: NDArray[np.float64]


def _fit(
    corr: Correlator, img: NDArray[np.float64] | PreparedImage, start: NDArray[np.float64]
) -> _FrameResult:
    """IC-GN of all of ``corr``'s POIs from ``start`` (n, 2) or (n, 6): on a prefiltered
    frame by :meth:`~dicblur.dic.Correlator.refine` (no DICResult to build: ~0.3 ms less
    per frame for the seeds and the frame together), otherwise by ``correlate``."""
    if isinstance(img, PreparedImage) and corr.blur == "none":
        r = corr.refine(img, start)
        p = r.params
        return _FrameResult(p[:, 0], p[:, 1 if p.shape[1] == 2 else 3], r.zncc, r.status, p)
    res = corr.correlate(img, initial=start)
    return _FrameResult(res.u, res.v, res.zncc, res.status, res.params)


def frame_gradients(res: _FrameResult) -> NDArray[np.float64] | None:
    """The displacement gradients (n, 4) of an affine result for the next frame's start
    (the median of the converged points where a point did not converge), or None."""
    if res.params.shape[1] != 6:
        return None
    ok = (res.status == PointStatus.CONVERGED) & np.isfinite(res.params).all(axis=1)
    if not ok.any():
        return None
    g = res.params.take([1, 2, 4, 5], axis=1)  # a C-contiguous copy
    fill_with_median(g, ok)
    return g


def correlate_frame(
    corr: Correlator,
    img: NDArray[np.float64] | PreparedImage,
    guess: NDArray[np.float64] | None,
    ok0: NDArray[np.bool_],
    grads: NDArray[np.float64] | None = None,
) -> tuple[_FrameResult, bool]:
    """Correlate one frame from ``guess`` (and, affine, the displacement gradients
    ``grads`` of the previous frame: IC-GN then needs about a quarter of the iterations);
    where too many points fail, run the engine's FFT-CC start too and keep, per point, the
    better of the two (converged, higher ZNCC)."""
    if guess is None:
        r = corr.correlate(img)
        return _FrameResult(r.u, r.v, r.zncc, r.status, r.params), True
    res = _fit(corr, img, _start(corr, guess, grads))
    # a subset that leaves the frame (the target moved it out) is no reason to restart
    st = res.status
    failed = (st != PointStatus.CONVERGED) & (st != PointStatus.OUT_OF_BOUNDS) & ok0
    if failed.sum() <= FALLBACK_SHARE * max(int(ok0.sum()), 1):
        return _FrameResult(res.u, res.v, res.zncc, res.status, res.params), False
    alt = corr.correlate(img)
    take = (alt.status == PointStatus.CONVERGED) & (
        (res.status != PointStatus.CONVERGED) | (alt.zncc > res.zncc + 1e-9)
    )
    return _FrameResult(
        np.where(take, alt.u, res.u),
        np.where(take, alt.v, res.v),
        np.where(take, alt.zncc, res.zncc),
        np.where(take, alt.status, res.status).astype(np.uint8),
        np.where(take[:, None], alt.params, res.params),
    ), True


#: A converged point whose ``1 - ZNCC`` exceeds this multiple of its usual value (its
#: frame's median, scaled by the point's own median ratio over the recording) is flagged.
ZNCC_RATIO = 4.0


def _nanmedian_last(x: NDArray[Any], *, overwrite: bool = False) -> NDArray[Any]:
    """``np.nanmedian(x, axis=-1)``, the same numbers and dtype (NaN where a row has no
    value, without the warning): one vectorised sort of the rows (NaN sorts last) instead
    of a partition per row (thousands of Python-level calls on a (frames, points) array).
    ``overwrite``: sort ``x`` itself (a temporary of the caller: no sorted copy).
    """
    n = x.shape[-1] - np.count_nonzero(np.isnan(x), axis=-1)
    if overwrite:
        x.sort(axis=-1)
        s = x
    else:
        s = np.sort(x, axis=-1)
    lo = np.take_along_axis(s, np.maximum((n - 1) // 2, 0)[..., None], axis=-1)[..., 0]
    hi = np.take_along_axis(s, (n // 2)[..., None], axis=-1)[..., 0] if s.shape[-1] else lo
    with np.errstate(invalid="ignore", over="ignore"):
        # np.median: the middle value, or the mean of the two middle ones in x's dtype
        mid = np.where(n % 2 == 1, lo, (lo + hi) / 2)
    return np.where(n > 0, mid, np.nan).astype(x.dtype, copy=False)


def zncc_flags(
    zncc: NDArray[np.floating[Any]], converged: NDArray[np.bool_], *, ratio: float = ZNCC_RATIO
) -> NDArray[np.bool_]:
    """Converged points whose match is much worse than usual (frames, points).

    ``q = 1 - ZNCC`` grows with the noise and the blur of a frame and with how little
    texture a subset has; dividing by the frame's median ``q`` removes the first, by the
    point's median of that ratio over the recording the second. A foreign texture in the
    subset (debris, glare, a false convergence) leaves the ratio far above 1.
    """
    q = np.where(converged, 1.0 - zncc, np.nan)
    with warnings.catch_warnings(), np.errstate(invalid="ignore", divide="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)
        med_f = _nanmedian_last(q)[:, None]
        rel = np.where(med_f > 0, q / med_f, np.nan)
        med_p = _nanmedian_last(rel.T)[None, :]
        score = rel / med_p
    return np.asarray(converged & np.isfinite(score) & (score > ratio))


def _median_critical(
    u: NDArray[np.float64],
    v: NDArray[np.float64],
    ok: NDArray[np.bool_],
    gshape: tuple[int, int] | None,
    threshold: float,
    frames: NDArray[np.intp] | None = None,
    out: NDArray[np.float32] | None = None,
    threads: int = 1,
) -> NDArray[np.float32]:
    """:func:`.median.median_critical_eps` of the points ``ok`` (the others missing) of
    ``frames`` (default all), written into ``out`` (frames, points); ``-inf`` everywhere
    without a grid. The normalised median test at ``eps`` per frame is ``out > eps``."""
    n_f = u.shape[0]
    if out is None:
        out = np.full(u.shape, -np.inf, np.float32)
    if gshape is None:
        return out
    sel = np.arange(n_f) if frames is None else np.asarray(frames)

    def one(b: NDArray[np.intp]) -> None:
        # the mask goes into the compiled pass (no masked float64 copies)
        out[b] = median_critical_eps(u[b], v[b], gshape, threshold=threshold, valid=ok[b])

    _blocks(one, sel, 128, threads)
    return out


def _blocks(
    fn: Callable[[NDArray[np.intp]], None], sel: NDArray[np.intp], size: int, threads: int
) -> None:
    """``fn(block)`` for the consecutive blocks of ``size`` of the frame indices ``sel``,
    on ``threads`` threads (numpy releases the GIL in its array loops; each block writes
    its own frames, so the result is the same on any number of threads)."""
    each(fn, (sel[a : a + size] for a in range(0, sel.size, size)), threads)


#: ``tolerance="auto"``: the IC-GN tolerance is this share of the smallest predicted
#: noise floor (the :data:`TOLERANCE_QUANTILE` of the points' ``sqrt(2 sigma**2 /
#: SSSIG)``), within [:data:`TOLERANCE_MIN`, :data:`TOLERANCE_MAX`] px. The error a
#: converged point keeps is 0.2-0.6 x the tolerance (rms against a 1e-6 px run; 0.2 on the
#: speed recording of benchmarks/bench_track.py, 0.6 on a 3 px blur), so at most ~15 % of
#: that floor: it adds about 1 % to the predicted sigma (in quadrature), for a quarter
#: fewer IC-GN iterations than 1e-4 px (affine, 2.76 -> 2.09 per point).
TOLERANCE_SHARE = 0.25
#: Quantile of the points' noise floors that sets ``tolerance="auto"``.
TOLERANCE_QUANTILE = 0.05
#: Bounds of ``tolerance="auto"`` (px): never tighter than the engine's default, never
#: looser than the 0.001 px of the IC-GN literature (Pan et al., Exp. Mech. 53, 2013).
TOLERANCE_MIN = MatcherSettings().tolerance
TOLERANCE_MAX = 1e-3


def auto_tolerance(
    reference: NDArray[np.float64],
    centres: NDArray[np.intp],
    subset: int,
    noise: NoiseEstimate | None,
) -> float:
    """IC-GN convergence tolerance (px) for tracking the POIs ``centres`` (n, 2) (row,
    col) of ``reference`` at ``subset`` px under ``noise`` (None: the engine default).

    The tolerance bounds the error left in each converged result, so it only needs to be
    small against the random error the track predicts: :data:`TOLERANCE_SHARE` x the
    :data:`TOLERANCE_QUANTILE` of the points' static noise floor, the match-score model
    ``sqrt(2 sigma**2 / SSSIG)`` (paper eq. 2) along the better-textured of x and y at each
    subset's noise level, within [:data:`TOLERANCE_MIN`, :data:`TOLERANCE_MAX`]. Points
    whose subset leaves the image (1-px border) are left out.
    """
    if noise is None:
        return TOLERANCE_MIN
    h = subset // 2
    r, c = centres[:, 0], centres[:, 1]
    inside = (r - h >= 1) & (c - h >= 1) & (r + h < reference.shape[0] - 1)
    inside &= c + h < reference.shape[1] - 1
    pts = centres[inside]
    if pts.shape[0] == 0:
        return TOLERANCE_MIN
    gy, gx = image_gradients(reference)
    s_x = box_sssig(gy, gx, pts, subset=subset, angle=0.0)
    s_y = box_sssig(gy, gx, pts, subset=subset, angle=90.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        unit = match_score_sigma(np.maximum(s_x, s_y), 1.0)  # px per GL of noise
    floor = unit * np.sqrt(noise.variance(subset_levels(reference, pts, subset)))
    floor = floor[np.isfinite(floor)]
    if floor.size == 0:
        return TOLERANCE_MIN
    tol = TOLERANCE_SHARE * float(np.quantile(floor, TOLERANCE_QUANTILE))
    return float(min(max(tol, TOLERANCE_MIN), TOLERANCE_MAX))


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
        Noise std (GL) instead of ``static``.
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
        Missing exposure/fps, exposure longer than the frame interval, no noise source,
        bad ranges.
    TrackInterrupted
        A frame could not be read or tracking was interrupted; ``.dataset`` holds what was
        tracked.
    """
    if strain is not None:
        from ..strain.track import check_strain_window

        check_strain_window(strain, points)
    rec = recording if isinstance(recording, Recording) else open_recording(recording)
    n_total = len(rec)
    if n_total < 2:
        raise InputError(f"recording={rec.source!r}: {n_total} frame(s); tracking needs at least 2")
    fps_v = _resolve(fps, rec.fps, "rate", "fps", "--fps", "5000")
    t_exp = _resolve(exposure, rec.exposure, "time", "exposure", "--exposure", "1ms")
    if t_exp > 1.0 / fps_v * (1 + 1e-6):
        raise InputError(
            f"exposure={t_exp:g} s: longer than the frame interval 1/fps = "
            f"{1.0 / fps_v:g} s; check --exposure and --fps"
        )
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
    elif noise is None:
        raise InputError(
            "noise: give the static frames (--static 0:20) or the noise std "
            "(--noise 2, grey levels)"
        )
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
        except (DicblurError, OSError) as exc:
            noise_error = exc
            if noise_est is None:
                notes.append(f"no noise estimate: {exc}")
    ref_img = rec.frame(reference)
    opts: dict[str, Any] = {
        "subset": subset,
        "step": step,
        "shape": shape,
        "min_zncc": min_zncc,
        "workers": workers,
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
    grads: NDArray[np.float64] | None = None
    grads0: NDArray[np.float64] | None = None
    corr = corr0
    grid = poi_grid(corr0)  # the current Correlator's grid (the guesses' smoothing)
    n_pts = corr0.n_points
    # points that can be correlated at all (set from the reference frame's own result)
    ok0 = np.ones(n_pts, bool)
    order = list(range(reference, f1)) + list(range(reference - 1, f0 - 1, -1))
    out = _Tracked([], [], [], [], [], [])
    refs: list[int] = []
    hist: list[tuple[NDArray[np.float64], NDArray[np.float64]]] = []
    # the rigid shift of each frame in hist (sub-pixel phase correlation; None: no peak)
    rig: list[NDArray[np.float64] | None] = []
    rig_ref: NDArray[np.float64] | None = None
    ref_field: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None
    base = np.zeros((n_pts, 2))  # displacement of the current reference's POIs (px)
    ref_now, ref_share = reference, 1.0
    spectrum = {reference: window_spectrum(ref_img)}
    prev: tuple[int, NDArray[np.float64]] | None = None
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
        out = _Tracked(
            list(got["frames"]),
            list(got["u"]),
            list(got["v"]),
            list(got["zncc"]),
            list(got["status"]),
            list(got["fallback"]),
        )
        refs, error = [reference] * len(out.frames), got["error"]
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
    ds = _assemble(
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


def _by_runs(
    fn: Callable[..., tuple[NDArray[Any], NDArray[Any]]],
    runs: list[slice],
    n_f: int,
    u: NDArray[np.float64],
    v: NDArray[np.float64],
    good: NDArray[np.bool_],
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

    def one(b: NDArray[np.intp]) -> None:
        r = slice(int(b[0]), int(b[-1]) + 1)
        np.hypot(wu[r], wv[r], out=w[r])
        a = np.degrees(np.arctan2(wv[r], wu[r]))
        np.mod(a, 180.0, out=ang[r])

    if wu.size:
        _blocks(one, np.arange(wu.shape[0]), 128, threads)
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


def _assemble(
    rec: Recording,
    corr: Correlator,
    out: _Tracked,
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
    ref_img: NDArray[np.float64],
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
    # pass 1: the median test at its fixed eps (catches errors of tenths of a px) and the
    # ZNCC test; pass 2, once sigma is known, at eps = 2 x the frame's median sigma
    t_med = time.perf_counter()
    # the largest eps at which the test flags each point: both passes from one median pass
    crit = _median_critical(u, v, conv, gshape, threshold, threads=threads)
    outlier = crit > eps
    settings["median_time_s"] = time.perf_counter() - t_med
    low_zncc = zncc_flags(zn, conv)
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

    def motion(good: NDArray[np.bool_]) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
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
                mu = _nanmedian_last(np.where(good[sel], u[sel], np.nan))
                mv = _nanmedian_last(np.where(good[sel], v[sel], np.nan))
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

    def nan_fields() -> dict[str, NDArray[np.float32]]:
        return {k: np.full((n_f, n_p), np.nan, np.float32) for k in names}

    sig: dict[str, NDArray[np.float32]] = {}
    importing: threading.Thread | None = None
    blur_dom = np.full(n_f, np.nan)
    levels: NDArray[np.float64] | None = None  # of the subsets inside, once known
    t0 = time.perf_counter()
    table: Any = None
    if noise is not None and inside.any():
        pin = np.flatnonzero(inside)
        # all points inside (the usual grid): plain slices, no fancy-indexed copies
        cols: slice | NDArray[np.intp] = slice(None) if pin.size == n_p else pin
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

        def predict(rows: NDArray[np.intp] | None = None) -> None:
            def one(b: NDArray[np.intp]) -> None:  # frame blocks on the threads
                table.predict_into(w, ang, nv, b, pin, outs)  # NaN: blur unknown

            _blocks(one, np.arange(n_f) if rows is None else rows, 128, threads)

        predict()
        if gshape is not None:
            s_max = np.empty((n_f, n_p), np.float32)

            def largest(b: NDArray[np.intp]) -> None:  # frame blocks on the threads
                r = slice(int(b[0]), int(b[-1]) + 1)
                np.fmax(
                    np.hypot(sig["sigma_u_noise"][r], sig["sigma_u_blur"][r]),
                    np.hypot(sig["sigma_v_noise"][r], sig["sigma_v_blur"][r]),
                    out=s_max[r],
                )
                s_max[r][~good[r]] = np.nan

            _blocks(largest, np.arange(n_f), 128, threads)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                eps_k = 2.0 * _nanmedian_last(s_max, overwrite=True)
            del s_max
            eps_k = np.where(np.isfinite(eps_k) & (eps_k > 0), eps_k, eps)
            # the second pass leaves out the low-ZNCC points too: the medians change only
            # in the frames that have some
            t_med = time.perf_counter()
            _median_critical(
                u,
                v,
                conv & ~low_zncc,
                gshape,
                threshold,
                frames=np.flatnonzero((conv & low_zncc).any(axis=1)),
                out=crit,
                threads=threads,
            )
            second = crit > eps_k[:, None]
            settings["median_time_s"] += time.perf_counter() - t_med
            if (second & ~outlier).any():
                outlier |= second
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
    sigma_u = np.empty((n_f, n_p), np.float32)
    sigma_v = np.empty((n_f, n_p), np.float32)
    valid = np.empty((n_f, n_p), bool)
    cnt = np.zeros(n_f, np.intp)
    n_dom = np.zeros(n_f, np.intp)
    outlier |= low_zncc

    def totals(b: NDArray[np.intp]) -> None:  # frame blocks on the threads
        r = slice(int(b[0]), int(b[-1]) + 1)
        np.hypot(sig["sigma_u_noise"][r], sig["sigma_u_blur"][r], out=sigma_u[r])
        np.hypot(sig["sigma_v_noise"][r], sig["sigma_v_blur"][r], out=sigma_v[r])
        valid[r] = good[r] & np.isfinite(sigma_u[r]) & np.isfinite(sigma_v[r]) & np.isfinite(w[r])
        with np.errstate(invalid="ignore"):
            dom = np.hypot(sig["sigma_u_blur"][r], sig["sigma_v_blur"][r]) > np.hypot(
                sig["sigma_u_noise"][r], sig["sigma_v_noise"][r]
            )
        cnt[r] = valid[r].sum(axis=1)
        n_dom[r] = (dom & valid[r]).sum(axis=1)

    if n_f:
        _blocks(totals, np.arange(n_f), 128, threads)
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
    bias: NDArray[np.float32] | None = None
    if noise is not None and inside.any() and runs:
        pin = np.flatnonzero(inside)
        # beside the advice's thread: one core each (the advice, about as long as the
        # skew, no longer waits for a core after the skew's threads are done)
        skew_threads = threads if side is None else max(1, threads - 1)
        k3, axis = _by_runs(
            exposure_skew, runs, n_f, u, v, good, **{**kin, "threads": skew_threads}
        )
        at: slice | NDArray[np.intp] = slice(None) if pin.size == n_p else pin  # no copies
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

        def one_bias(b: NDArray[np.intp]) -> None:
            skew.bias_into(k3, axis, b, pin, skew_bias)

        _blocks(one_bias, np.arange(n_f), 128, skew_threads)
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
