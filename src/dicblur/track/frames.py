"""The frame loop of :func:`dicblur.track.track`: the start of each frame (extrapolated track,
rigid shift, seed points), its correlation with the FFT-CC fallback, and the record of
the frames tracked (:class:`Tracked`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from ..arrays import BoolArray, Float64Array, IndexArray, UInt8Array
from ..dic import Correlator, PointStatus, PreparedImage
from ..dic.initial import window_spectrum
from ..sequence import Recording
from .grid import extrapolate_fields, fill_with_median

#: A frame falls back to the engine's FFT-CC start when more than this share of its
#: correlatable points fails from the extrapolated guess.
FALLBACK_SHARE = 0.02


class ChunkRunner(Protocol):
    """Runs the correlation of :func:`track` in chunks (:class:`.parallel.ChunkedRun`).

    ``run`` returns a mapping with the lists ``frames``, ``u``, ``v``, ``zncc``,
    ``status``, ``fallback`` (one entry per frame tracked), optionally ``non_finite``
    (per frame, the non-finite pixels a worker filled: :mod:`.nan_pixels`) and ``error``
    (the exception that stopped it, or None). With ``compensate_blur`` the runner's
    ``compensate`` (the signature of :func:`.compensate.compensated_pass`) runs the
    compensated passes.
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
class Tracked:
    """Raw per-frame results of the correlation loop, in frame order."""

    frames: list[int]
    u: list[Float64Array]
    v: list[Float64Array]
    zncc: list[Float64Array]
    status: list[UInt8Array]
    fallback: list[bool]


def _extrapolate(
    hist: list[tuple[Float64Array, Float64Array]],
    grid: tuple[tuple[int, int], IndexArray] | None = None,
) -> Float64Array | None:
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


def _rigid_shift(spectrum: NDArray[np.complex64], img: Float64Array) -> tuple[float, float, float]:
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
    reference: Float64Array, corr: Correlator, opts: dict[str, Any]
) -> tuple[Correlator, IndexArray] | None:
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


def _start(corr: Correlator, guess: Float64Array, grads: Float64Array | None) -> Float64Array:
    """IC-GN start of ``corr``'s points: ``guess`` (n, 2) px, with the displacement
    gradients ``grads`` (n, 4) as the affine parameters (n, 6) when both apply."""
    if grads is None or corr.shape != "affine":
        return guess
    g = grads
    return np.stack([guess[:, 0], g[:, 0], g[:, 1], guess[:, 1], g[:, 2], g[:, 3]], axis=1)


def _seed_correction(
    seeds: tuple[Correlator, IndexArray] | None,
    img: Float64Array | PreparedImage,
    guess: Float64Array,
    grads: Float64Array | None = None,
) -> Float64Array:
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
    hist: list[tuple[Float64Array, Float64Array]],
    rig: list[Float64Array | None],
    img: Float64Array | PreparedImage,
    spectrum: NDArray[np.complex64],
    base: Float64Array,
    seeds: tuple[Correlator, IndexArray] | None,
    *,
    grid: tuple[tuple[int, int], IndexArray] | None = None,
    grads: Float64Array | None = None,
) -> tuple[Float64Array | None, Float64Array | None]:
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


def poi_grid(corr: Correlator) -> tuple[tuple[int, int], IndexArray] | None:
    """The POI grid of ``corr`` as :func:`frame_guess` takes it: ``(grid_shape,
    grid_cells)``, or None when the POIs are not on a grid."""
    cells = corr.grid_cells
    shape = corr.grid_shape
    return None if cells is None or shape is None else (shape, cells)


@dataclass(frozen=True)
class _FrameResult:
    u: Float64Array
    v: Float64Array
    zncc: Float64Array
    status: UInt8Array
    params: Float64Array


def _fit(corr: Correlator, img: Float64Array | PreparedImage, start: Float64Array) -> _FrameResult:
    """IC-GN of all of ``corr``'s POIs from ``start`` (n, 2) or (n, 6): on a prefiltered
    frame by :meth:`~dicblur.dic.Correlator.refine` (no DICResult to build: ~0.3 ms less
    per frame for the seeds and the frame together), otherwise by ``correlate``."""
    if isinstance(img, PreparedImage) and corr.blur == "none":
        r = corr.refine(img, start)
        p = r.params
        return _FrameResult(p[:, 0], p[:, 1 if p.shape[1] == 2 else 3], r.zncc, r.status, p)
    res = corr.correlate(img, initial=start)
    return _FrameResult(res.u, res.v, res.zncc, res.status, res.params)


def frame_gradients(res: _FrameResult) -> Float64Array | None:
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
    img: Float64Array | PreparedImage,
    guess: Float64Array | None,
    ok0: BoolArray,
    grads: Float64Array | None = None,
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
