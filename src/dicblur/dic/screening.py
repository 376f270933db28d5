"""Screening of a Correlator's IC-GN results: the a-posteriori tests (``HIGH_RESIDUAL``,
``OUTLIER``) and the predicted-imprecise subsets (``IMPRECISE``); docs/dic.md, "Screening
for false convergence"."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..arrays import BoolArray, Float32Array, Float64Array, IndexArray, Int64Array, UInt8Array
from . import kernels
from .icgn import N_PARAMS, uv_columns
from .initial import subset_fftcc_peaks
from .lack_of_fit import LACK_OF_FIT_F, LACK_OF_FIT_SAMPLE, translation_lack_of_fit
from .noise import NoiseEstimate, residual_noise, residual_variance
from .outliers import MEDIAN_EPS, MEDIAN_THRESHOLD, median_screen
from .passes import IcgnPasses, scatter
from .status import PointStatus
from .support import (
    MIN_VERDICTS,
    SUPPORT_ROUNDS,
    Pairs,
    grid_pairs,
    scattered_pairs,
    unsupported_pairs,
)

__all__ = [
    "ACCEPT_DISTANCE",
    "MAX_PREDICTED_SIGMA",
    "OUTLIER_DISTANCE",
    "OUTLIER_SIGMAS",
    "PAIRS_MIN",
    "PROBE_CHI2",
    "PROBE_DISTANCE",
    "RESIDUAL_SPREAD",
    "RETRY_REACH",
    "Screening",
    "pair_medians",
]

#: ``OUTLIER`` when the neighbours' median displacement fits a subset better than its own
#: result by more than this chi-square gain (``Df^2 (zncc_nb - zncc) / sigma^2``; 0 or less
#: at a true optimum): IC-GN stopped at a false optimum.
PROBE_CHI2 = 10.0
#: Only POIs farther than this (px) from their neighbours' median are probed.
PROBE_DISTANCE = 0.05
#: Default ``max_predicted_sigma`` (px): a subset whose predicted random error (the
#: magnitude ``hypot(predicted_sigma_u, predicted_sigma_v)``) exceeds it is ``IMPRECISE``;
#: at 0.1/3 px an error beyond 0.1 px is a 3-sigma event.
MAX_PREDICTED_SIGMA = 0.1 / 3
#: Neighbour check: a retry from the neighbours' median stops (``DIVERGED``) when its u or
#: v moves farther than this many times the largest acceptance threshold of the retried
#: POIs from its start (it could only be taken back within the threshold).
RETRY_REACH = 2.0
#: A predicted-imprecise subset started from its precise neighbours' field
#: (``Screening._run_deferred``) is checked against that start when it has three pairs of
#: precise converged neighbours or is at most this many 3x3 steps from such cells (farther
#: in: the neighbour check's own median). On the blob image (affine) 0 flagged 2.3 % of
#: the correct points, 1 flags 1.5 %, 2 no fewer; no gross error left (issue 26).
ANCHOR_ROUNDS = 1
#: Neighbour check: a predicted-imprecise subset whose (u, v) lies within this distance
#: (px) of the median of its precise converged 3x3 neighbours is kept ``CONVERGED``: its
#: error is then below ~0.1 px whatever its predicted sigma (on the three hostile images of
#: ``benchmarks/bench_screening.py`` no gross error lies this close, while 0.03 px would
#: reject 3-5 times as many correct points).
ACCEPT_DISTANCE = 0.07
#: Neighbour check: a precise converged subset farther than
#: ``max(OUTLIER_DISTANCE, OUTLIER_SIGMAS * its predicted sigma)`` (px) from that median is
#: retried from it, and is ``OUTLIER`` unless the retry converges there with a better fit.
OUTLIER_DISTANCE = 0.1
OUTLIER_SIGMAS = 4.0
#: Peak test of the POIs no neighbour can judge: the best other integer position within
#: +-``subset`` px of the result, farther than ``subset // 2`` px (either axis: a motion
#: blur widens the peak), must leave at least this times the result's ZNSSD residual
#: ``1 - zncc`` (docs/dic.md, "Support", for the measured ratios).
PEAK_RESIDUAL_RATIO = 2.0
#: With an estimated noise, ``HIGH_RESIDUAL`` also needs a residual variance beyond the
#: field's median by this many robust standard deviations (1.4826 x the median absolute
#: deviation): for noise alone that std is ``sqrt(2 / m)`` ~ 7 % of the median at subset
#: 21, so ``max_residual`` = 2 decides; a field whose residuals are content, not noise,
#: spreads wider (a noise-free pair: 8 of 49 subsets above 2x the median).
RESIDUAL_SPREAD = 10.0
MAD_SCALE = 1.4826
#: Fewest pairs of opposite neighbours (of 4: along the rows, the columns and the two
#: diagonals) with both converged the check needs; the mean of a pair is exact on a
#: linear field (a strain, a rotation), and the median of three or four pairs stands one
#: wrong neighbour. With fewer (the grid's border) a POI keeps the other tests' status.
PAIRS_MIN = 3


def pair_medians(
    values: Float64Array,
    grid_shape: tuple[int, int],
    *,
    cells: IndexArray | None = None,
) -> tuple[Float64Array, Int64Array]:
    """Median over the four pairs of opposite 3x3 neighbours of each pair's mean.

    Parameters
    ----------
    values : ndarray, shape (k, ny * nx)
        ``k`` components on the grid in row-major order, NaN where a point is not valid.
    grid_shape : (ny, nx)
    cells : ndarray of int, shape (m,), optional
        Row-major grid cells to evaluate only (the same numbers as the full grid's there).

    Returns
    -------
    median : ndarray, shape (k, ny, nx), or (k, m) with ``cells``
        NaN where no pair is valid.
    pairs : ndarray of int, shape (ny, nx), or (m,) with ``cells``
        Number of valid pairs (both points valid), 0..4.
    """
    ny, nx = grid_shape
    k = values.shape[0]
    pad = np.pad(values.reshape(k, ny, nx), ((0, 0), (1, 1), (1, 1)), constant_values=np.nan)
    dirs = ((0, 1), (1, 0), (1, 1), (1, -1))
    if cells is None:
        means = np.stack(
            [
                0.5
                * (
                    pad[:, 1 + dy : 1 + dy + ny, 1 + dx : 1 + dx + nx]
                    + pad[:, 1 - dy : 1 - dy + ny, 1 - dx : 1 - dx + nx]
                )
                for dy, dx in dirs
            ]
        )
    else:
        # the few cells of the neighbour check's retries: not the whole grid (0.65 ms for
        # six components on a 49 x 49 grid)
        r, c = np.divmod(np.asarray(cells, np.intp), nx)
        means = np.stack(
            [
                0.5 * (pad[:, 1 + r + dy, 1 + c + dx] + pad[:, 1 + r - dy, 1 + c - dx])
                for dy, dx in dirs
            ]
        )
    count = np.isfinite(means[:, 0]).sum(axis=0)
    # the median of 0-4 values without a sort: (sum - min - max) / (count - 2) for 3 or 4
    total = np.where(np.isnan(means), 0.0, means).sum(axis=0)
    low, high = np.fmin.reduce(means, axis=0), np.fmax.reduce(means, axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        med = np.where(
            count >= 3,
            (total - low - high) / np.maximum(count - 2, 1),
            np.where(count == 2, 0.5 * total, np.where(count == 1, total, np.nan)),
        )
    return med, count


def _median_iterations(conv: Int64Array) -> int:
    """The median of the converged POIs' iterations ``conv`` (2 when there are none)."""
    return 2 if conv.size == 0 else int(np.median(conv))


def _uv_first(k: int) -> tuple[int, int, list[int]]:
    """The u and v columns of ``k`` shape parameters and an order of all ``k`` with those
    two first (the neighbour tests look at u and v; the retries start from all)."""
    ucol, vcol = uv_columns(k)
    return ucol, vcol, [ucol, vcol] + [j for j in range(k) if j not in (ucol, vcol)]


def grow_start(grid: Float64Array, cells: IndexArray, start: Float64Array) -> Int64Array:
    """Fill the NaN rows of ``start`` (m, k) at the row-major ``cells`` (m,), in place:
    the mean of the valid 3x3 neighbours on ``grid`` (k, ny, nx; NaN where unknown),
    repeated while it adds cells (a region of predicted-imprecise POIs filled inwards
    from its precise border)."""
    nx = grid.shape[2]
    g = grid.copy()
    r, c = np.divmod(cells, nx)
    have = np.all(np.isfinite(start), axis=1)
    rounds = np.where(have, 0, -1)
    g[:, r[have], c[have]] = start[have].T
    for step in range(1, 9):
        todo = np.flatnonzero(~have)
        if todo.size == 0:
            return rounds
        pad = np.pad(g, ((0, 0), (1, 1), (1, 1)), constant_values=np.nan)
        rr, cc = r[todo] + 1, c[todo] + 1
        nb = np.stack(
            [pad[:, rr + dy, cc + dx] for dy in (-1, 0, 1) for dx in (-1, 0, 1) if dy or dx]
        )
        cnt = np.isfinite(nb[:, 0]).sum(axis=0)
        new = cnt > 0
        if not new.any():
            return rounds
        with np.errstate(invalid="ignore"):
            mean = np.where(np.isnan(nb), 0.0, nb).sum(axis=0) / np.maximum(cnt, 1)
        sel = todo[new]
        start[sel] = mean[:, new].T
        have[sel] = True
        rounds[sel] = step
        g[:, r[sel], c[sel]] = mean[:, new]
    return rounds


class Screening(IcgnPasses):
    """The statuses of a Correlator's results after IC-GN."""

    #: The POIs :meth:`_run_deferred` started from their neighbours (None: none).
    _from_nb: BoolArray | None = None
    #: Their starts' (u, v), (n, 2) px, NaN elsewhere: the field they are checked against.
    _nb_start: Float64Array | None = None
    #: The POIs' neighbour pairs of the support test (:mod:`.support`), once computed.
    _support_pairs: Pairs | None = None

    # ------------------------------------------------------------------ the noise
    def _set_noise(self, noise: NoiseEstimate | None) -> None:
        """Use ``noise`` (an estimate; None: unknown) for the predicted sigmas and the
        predicted-imprecise POIs of this correlation."""
        self.noise = noise
        if noise is None or self._unit_sigma is None:
            self.predicted_sigma_u = self.predicted_sigma_v = None
            imp = None
        else:
            self.predicted_sigma_u = self._unit_sigma[0] * noise.sigma
            self.predicted_sigma_v = self._unit_sigma[1] * noise.sigma
            imp = None
            if self.max_predicted_sigma is not None:
                with np.errstate(invalid="ignore"):
                    mask = np.hypot(self.predicted_sigma_u, self.predicted_sigma_v) > (
                        self.max_predicted_sigma
                    )
                imp = mask if mask.any() else None
        old = self._imprecise
        same = (old is None and imp is None) or (
            old is not None and imp is not None and np.array_equal(old, imp)
        )
        if not same:
            # the affine split into precise and imprecise POIs follows the mask
            for key in self._split_ids:
                self._args_cache.pop(key, None)
            self._split_cache, self._split_ids = {}, set()
        self._imprecise = imp

    def _estimate_noise(
        self,
        z: Float64Array,
        st: UInt8Array,
        idx: IndexArray | None = None,
    ) -> None:
        """The pair's noise from the converged residuals of the POIs ``idx`` (None: all;
        ``z``, ``st`` of those POIs): :func:`.noise.residual_noise`."""
        fnorm = self._prep.fnorm if idx is None else self._prep.fnorm[idx]
        m = self.subset * self.subset - N_PARAMS[self.shape] - 2
        est = residual_noise(residual_variance(z, fnorm, m), st == PointStatus.CONVERGED)
        self._set_noise(est)

    def _noise_info(self) -> dict[str, Any]:
        """The result metadata of the noise used (``noise_sigma`` the value the tests and
        the predicted sigmas used, GL)."""
        nz = self.noise
        return {
            "noise_sigma": None if nz is None else nz.sigma,
            "noise_estimated": int(self.noise_auto),
            "noise_sigma_low": None if nz is None or not nz.estimated else nz.low,
            "noise_sigma_high": None if nz is None or not nz.estimated else nz.high,
            "noise_subsets": None if nz is None or not nz.estimated else nz.count,
        }

    # ------------------------------------------------------------------ the statuses
    def _run_deferred(self, coef: Float32Array, res: kernels.Outputs) -> None:
        """IC-GN of the predicted-imprecise POIs the main pass left, in ``res`` in place.

        Each starts from the precise converged POIs' field: :func:`pair_medians` of its
        precise neighbours' six parameters where it has :data:`PAIRS_MIN` pairs of them
        (the start the neighbour check would retry it from), else :func:`grow_start`
        (a region of such POIs filled inwards), within the check's retry budget and a
        reach of ``RETRY_REACH * ACCEPT_DISTANCE`` px (it is kept only that close to its
        neighbours; one moving farther gets the reduced pass from the same start, for an
        estimate to inspect, and is ``IMPRECISE``). The
        check then takes no retry of them, and tests those at most
        :data:`ANCHOR_ROUNDS` steps from the precise field against their start. A POI
        with no start (no precise POI on the grid) gets the reduced pass from its own.

        Instead of a reduced pass from the seed start (on the blob image of
        ``benchmarks/bench_screening.py``, affine: 3 of 223 converged) and the check's
        retry (~6 iterations each): 5 % fewer iterations, and fewer correct points
        flagged (1.9 -> 1.5 %) with no gross error left (issue 26).
        """
        pts, self._deferred = self._deferred, None
        self._from_nb = self._nb_start = None
        if pts is None or pts.size == 0:
            return
        p, z, it, st = res
        n, k = p.shape
        ok = st == PointStatus.CONVERGED
        # the noise estimated since may have changed the mask: the precise POIs by today's
        precise = ok if self._imprecise is None else ok & ~self._imprecise
        med_it = _median_iterations(it[ok])
        cap = self._retry_limit(med_it)
        reduced = self._imprecise_limit(med_it)
        start = np.full((pts.size, k), np.nan)
        exact = np.zeros(pts.size, bool)
        if self._grid_shape is not None and self._grid_index is not None and precise.any():
            ny, nx = self._grid_shape
            cell = self._grid_index
            grid = np.full((k, ny * nx), np.nan)
            grid[:, cell] = np.where(precise, p.T, np.nan)
            med, count = pair_medians(grid, (ny, nx), cells=cell[pts])
            exact = count >= PAIRS_MIN
            start = np.where(exact, med, np.nan).T
            rounds = grow_start(grid.reshape(k, ny, nx), cell[pts], start)
            exact = (rounds >= 0) & (rounds <= ANCHOR_ROUNDS)
        near = np.all(np.isfinite(start), axis=1)
        if near.any():
            sel = pts[near]
            r = self._run_icgn(
                coef, start[near], self._status0[sel], sel, cap, RETRY_REACH * ACCEPT_DISTANCE
            )
            scatter(res, sel, r)
            gone = np.flatnonzero(r.status == PointStatus.DIVERGED)
            if gone.size:
                # beyond the reach: an estimate for inspection (IMPRECISE) from the same
                # start within the reduced limit, not the reach's NaN
                g = sel[gone]
                r2 = self._run_icgn(coef, start[near][gone], self._status0[g], g, reduced)
                p[g], z[g], st[g] = r2.p, r2.zncc, r2.status
                it[g] += r2.iterations
            # the check's retry would start these from the same medians: not again
            self._from_nb = np.zeros(n, bool)
            self._from_nb[sel] = True
            self._nb_start = np.full((n, 2), np.nan)
            anchored = pts[near & exact]
            self._nb_start[anchored] = start[near & exact][:, list(uv_columns(k))]
        if not near.all():
            rest = pts[~near]
            scatter(res, rest, self._run_icgn(coef, p[rest], self._status0[rest], rest, reduced))

    def _flag(self, coef: Float32Array, res: kernels.Outputs) -> float | None:
        """The statuses of ``res`` after IC-GN, in place: the noise (estimated),
        :meth:`_screen`, :meth:`_neighbour_check`, ``IMPRECISE``, then
        :meth:`_support_check`; returns the screen's
        noise variance (or None). The iterations get those of the check's retries."""
        st = res.status
        if self.noise_auto:
            # chance optima (lone converged POIs among failures) are no measure of the
            # noise: on a pair that does not match, 50-80 of them made a 2 GL pair's
            # estimate ~55 GL and flooded the field with IMPRECISE
            lone = self._unsupported(res, neutral=PointStatus.MAX_ITERATIONS)
            est_st = st if lone is None else np.where(lone, PointStatus.OUTLIER, st)
            self._estimate_noise(res.zncc, est_st)
        noise_var = self._screen(coef, res)
        kept = self._neighbour_check(coef, res)
        if self._imprecise is not None:
            # a predicted-imprecise subset stopped at its (reduced) limit: imprecision is the
            # cause, so it gets that status too
            done = (st == PointStatus.CONVERGED) | (st == PointStatus.MAX_ITERATIONS)
            flag = done & self._imprecise
            if kept is not None:
                flag &= ~kept
            st[flag] = PointStatus.IMPRECISE
        self._support_check(res)
        return noise_var

    def _unsupported(
        self, res: kernels.Outputs, *, neutral: PointStatus | None = None
    ) -> BoolArray | None:
        """The converged POIs of ``res`` their neighbours do not support
        (:func:`.support.unsupported`, or :func:`.support.unsupported_scattered` off a
        grid), or None without the neighbour check. A neighbour with status ``neutral``
        counts neither way (before the screening: ``MAX_ITERATIONS``, which a
        predicted-imprecise subset reaches at its reduced limit)."""
        if not self.neighbour_check:
            return None
        st = res.status
        ok = st == PointStatus.CONVERGED
        if not ok.any():
            return None
        # an IMPRECISE estimate may confirm a neighbour; failed in the current image: not
        # decided by the reference (status0), and not predicted imprecise
        finite = ok | (st == PointStatus.IMPRECISE)
        failed = ~finite & (self._status0 == 0) & (st != PointStatus.LOW_TEXTURE)
        if neutral is not None:
            failed &= st != neutral
        elif self._imprecise is not None:
            failed &= ~self._imprecise
        if self._support_pairs is None:
            # the POIs are fixed: their neighbour pairs once per Correlator
            if self._grid_shape is not None and self._grid_index is not None:
                self._support_pairs = grid_pairs(self._grid_shape, self._grid_index)
            else:
                # explicit points off a grid: the neighbours whose subsets overlap
                self._support_pairs = scattered_pairs(self.rows, self.cols, float(self.subset))
        flag = np.zeros_like(ok)
        for _ in range(SUPPORT_ROUNDS):
            # a later round: the POIs flagged so far vouch for no neighbour
            new = unsupported_pairs(
                res.p, finite, failed, self.rows, self.cols, self._support_pairs
            )
            new &= ok & ~flag
            if not new.any():
                break
            flag |= new
            finite, failed = finite & ~new, failed | new
        return flag

    def _support_check(self, res: kernels.Outputs) -> None:
        """``OUTLIER`` for the converged POIs of the grid that their neighbours do not
        support (:func:`.support.unsupported`: a lone match among failures), in place,
        unless a noise level is known and the POI's residual passes the residual test
        against it alone (``max_residual`` times the noise variance; no field median)."""
        flag = self._unsupported(res)
        if flag is None:
            return
        st = res.status
        if flag.any() and self.noise is not None and self.max_residual is not None:
            # no neighbour vouches for these: kept only when the residual alone is the
            # noise's (a chance optimum's is tens of times larger)
            m = self.subset * self.subset - res.p.shape[1] - 2
            unit = residual_variance(res.zncc, self._prep.fnorm, m)
            flag &= unit > self.max_residual * self.noise.sigma**2
        st[flag] = PointStatus.OUTLIER
        self._unjudged_check(res)

    def _unjudged_check(self, res: kernels.Outputs) -> None:
        """``HIGH_RESIDUAL`` for the converged POIs too few neighbours can judge (fewer than
        :data:`.support.MIN_VERDICTS` prepared ones: scattered explicit points), in place,
        when the match is not distinct: the best other integer position within
        +-``subset`` px (farther than ``subset // 2`` px) leaves less than
        :data:`PEAK_RESIDUAL_RATIO` times its ZNSSD residual (no noise level needed); or,
        with a noise level known, when their residual fails the residual test against the
        noise alone (``max_residual`` times the noise variance; no field median, which
        their own chance optima make). On another pattern's image 11 % of such POIs came
        back ``CONVERGED`` (ZNCC 0.60-0.74) before."""
        pairs = self._support_pairs
        if pairs is None:
            return
        st = res.status
        a, b, _ = pairs
        judge = self._status0[b] == 0
        count = np.bincount(a[judge], minlength=st.size)
        alone = (st == PointStatus.CONVERGED) & (count < MIN_VERDICTS)
        if not alone.any():
            return
        k = res.p.shape[1]
        if self.noise is not None and self.max_residual is not None:
            unit = residual_variance(res.zncc, self._prep.fnorm, self.subset**2 - k - 2)
            high = alone & (unit > self.max_residual * self.noise.sigma**2)
            st[high] = PointStatus.HIGH_RESIDUAL
            alone &= ~high
        idx = np.flatnonzero(alone)
        if idx.size == 0 or self._screen_image is None:
            return
        ucol, vcol = uv_columns(k)
        _, _, _, second = subset_fftcc_peaks(
            self._ref,
            self._screen_image,
            self.rows[idx],
            self.cols[idx],
            self.half,
            guess_u=res.p[idx, ucol],
            guess_v=res.p[idx, vcol],
            search=self.subset,
            exclude=self.half,
            workers=1,
        )
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = (1.0 - second) / np.maximum(1.0 - res.zncc[idx], 0.0)
        st[idx[ratio < PEAK_RESIDUAL_RATIO]] = PointStatus.HIGH_RESIDUAL

    def _neighbour_check(self, coef: Float32Array, res: kernels.Outputs) -> BoolArray | None:
        """Each converged POI of the grid against ``m``, the median of the means of its
        pairs of opposite converged neighbours (:func:`pair_medians`; the precise ones
        where at least :data:`PAIRS_MIN` pairs are, else all), in place.

        A POI farther from ``m`` than its threshold (:data:`ACCEPT_DISTANCE` for a
        predicted-imprecise POI; ``max(OUTLIER_DISTANCE, OUTLIER_SIGMAS * predicted
        sigma)`` for the others) is retried from ``m`` (all shape parameters); the retry
        replaces its result when it converges within the threshold with a better ZNCC
        (the first result was a false optimum). A precise POI still too far is
        ``OUTLIER``. The POIs :meth:`_run_deferred` started from the precise field are not
        retried, and those it anchored are tested against their start instead of ``m``.
        Returns the predicted-imprecise POIs found close to ``m`` (kept ``CONVERGED`` by
        :meth:`_flag`), or None when nothing was checked.
        """
        if not self.neighbour_check or self._grid_shape is None or self.noise is None:
            # without a noise level there is no predicted sigma to scale the test: a
            # fixed 0.1 px would trim a strongly blurred field's legitimate tails
            return None
        p, z, it, st = res
        ok = st == PointStatus.CONVERGED
        if not ok.any():
            return None
        assert self._grid_index is not None
        imp = self._imprecise
        precise = ok if imp is None else ok & ~imp
        # predicted-imprecise POIs stopped at their reduced limit: retried from m too
        stopped = np.zeros_like(ok) if imp is None else imp & (st == PointStatus.MAX_ITERATIONS)
        if self._from_nb is not None:
            # stopped from the precise field's start already (_run_deferred): no retry, and
            # a wandered estimate vouches for no neighbour
            stopped &= ~self._from_nb
        (ny, nx), cell = self._grid_shape, self._grid_index
        n, k = p.shape
        # each grid cell's POI (the grid is full: every cell has one)
        cell_inv = np.empty(ny * nx, np.intp)
        cell_inv[cell] = np.arange(n)
        # (u, v) first: the distance needs only those; all k for the retries' starts
        ucol, vcol, order = _uv_first(k)
        grid = np.full((k, ny * nx), np.nan)
        grid[:, cell] = p[:, order].T
        # the precise neighbours where they suffice, else every converged one; but when
        # most POIs are predicted imprecise (a threshold too strict for the image, a
        # strongly blurred pair) an imprecise POI is vouched for by precise ones alone
        use = precise[cell_inv]
        med, pairs = pair_medians(np.where(use, grid[:2], np.nan), (ny, nx))
        few = (pairs < PAIRS_MIN).ravel()
        if imp is not None and imp.mean() >= 0.5:
            few &= ~imp[cell_inv]
        wider = few & (ok | stopped)[cell_inv] & ~use
        if wider.any():  # only when some neighbour would be added (not on a clean field)
            use = np.where(few, (ok | stopped)[cell_inv], use)
            med, pairs = pair_medians(np.where(use, grid[:2], np.nan), (ny, nx))
        test = np.flatnonzero((ok | stopped) & (pairs.ravel()[cell] >= PAIRS_MIN))
        if test.size == 0:
            return None
        anchor = self._nb_start
        if anchor is not None:
            # started from their precise neighbours' field (_run_deferred): checked
            # against that start, with or without three pairs of precise neighbours
            test = np.union1d(test, np.flatnonzero((ok | stopped) & np.isfinite(anchor[:, 0])))
        if test.size == 0:
            return None
        muv = med.reshape(2, -1)[:, cell[test]]
        if anchor is not None:
            a = anchor[test]
            has = np.isfinite(a[:, 0])
            muv[:, has] = a[has].T
        d = np.hypot(p[test, ucol] - muv[0], p[test, vcol] - muv[1])
        is_imp = np.zeros(test.size, bool) if imp is None else imp[test]
        pu, pv = self.predicted_sigma_u, self.predicted_sigma_v
        pm = np.zeros(test.size) if pu is None or pv is None else np.hypot(pu[test], pv[test])
        thr = np.where(is_imp, ACCEPT_DISTANCE, np.maximum(OUTLIER_DISTANCE, OUTLIER_SIGMAS * pm))
        again = stopped[test]
        far = (d > thr) | again
        # started from these neighbours already (_run_deferred): a retry would repeat it
        nb = self._from_nb
        redo = far if nb is None else far & ~nb[test]
        again &= redo
        if redo.any():
            where = np.flatnonzero(redo)
            idx = test[where]
            # the retries' starts: all k parameters' medians, over the same neighbours
            full, _ = pair_medians(np.where(use, grid, np.nan), (ny, nx), cells=cell[idx])
            start = np.empty((idx.size, k))
            start[:, order] = full.T
            # the retry budget (a subset stopped at its reduced limit, too: from a start
            # near the field most converge within it, 2.0 % of the blob image's correct
            # affine points left flagged against 6.6 % at the reduced limit again)
            cap = self._retry_limit(_median_iterations(it[ok]))
            p2, z2, it2, st2 = self._check_retry(coef, start, idx, cap, thr[where], is_imp[where])
            d2 = np.hypot(p2[:, ucol] - start[:, ucol], p2[:, vcol] - start[:, vcol])
            better = (z2 >= z[idx]) | again[where]  # a stopped POI had no optimum
            take = (st2 == PointStatus.CONVERGED) & better & (d2 <= thr[where])
            got = idx[take]
            p[got], z[got], st[got] = p2[take], z2[take], PointStatus.CONVERGED
            it[idx] += it2
            took = take
            far[where[took]] = False
        st[test[far & ~is_imp]] = PointStatus.OUTLIER
        kept = np.zeros(n, bool)
        kept[test[~far & is_imp]] = True
        return kept

    def _check_retry(
        self,
        coef: Float32Array,
        start: Float64Array,
        idx: IndexArray,
        cap: int,
        thr: Float64Array,
        is_imp: BoolArray,
    ) -> kernels.Outputs:
        """The neighbour check's IC-GN of the POIs ``idx`` from ``start`` within ``cap``
        iterations (``thr`` their acceptance distances, px; ``is_imp`` predicted imprecise).

        A retry is taken only within its threshold of the start, so one whose u or v moves
        farther than :data:`RETRY_REACH` times the largest threshold of its group (the
        precise POIs, the predicted-imprecise ones: one call each) is stopped
        (``DIVERGED``) instead of spending its budget off the fast stencil path. On the
        blob image of ``benchmarks/bench_screening.py`` (affine) the check's IC-GN took
        2.2 instead of 6.4 ms of CPU, the correct points recovered 130 instead of 132
        (issue 26).
        """
        groups = [np.flatnonzero(~is_imp), np.flatnonzero(is_imp)]
        out = kernels.outputs(*start.shape)
        for loc in groups:
            if loc.size == 0:
                continue
            reach = RETRY_REACH * float(thr[loc].max())
            r = self._run_icgn(coef, start[loc], self._status0[idx[loc]], idx[loc], cap, reach)
            scatter(out, loc, r)
        return out

    def _lack_of_fit(
        self, coef: Float32Array, p: Float64Array, cand: BoolArray, suspect: BoolArray
    ) -> BoolArray:
        """The ``cand`` translation POIs whose residual the affine gradients explain
        (:func:`~dicblur.dic.lack_of_fit.translation_lack_of_fit` above
        :data:`~dicblur.dic.lack_of_fit.LACK_OF_FIT_F`): a deformation the shape cannot
        follow, which the field's median residual hides when every subset shares it.

        Tested: the ``suspect`` ones (residual above ``max_residual`` times the noise
        variance, kept by the field's median or spread) and an even sample of
        :data:`~dicblur.dic.lack_of_fit.LACK_OF_FIT_SAMPLE`; all of them once one of the
        sample fails (a model error the median hides is shared by most subsets; a local one
        stands out of the median and is a suspect)."""
        idx = np.flatnonzero(cand)
        flag = np.zeros(cand.shape, bool)
        if idx.size == 0:
            return flag
        sample = idx[:: max(1, idx.size // LACK_OF_FIT_SAMPLE)]
        test = np.union1d(sample, np.flatnonzero(cand & suspect))

        def fails(at: IndexArray) -> BoolArray:
            fstat = translation_lack_of_fit(
                self._ref, self._ref_grad, coef, self.order,
                self.rows[at], self.cols[at], self.half, p[at, 0], p[at, 1],
            )  # fmt: skip
            with np.errstate(invalid="ignore"):
                return fstat > LACK_OF_FIT_F

        bad = fails(test)
        if bad[np.isin(test, sample)].any():
            test = idx
            bad = fails(test)
        flag[test[bad]] = True
        return flag

    def _screen(self, coef: Float32Array, res: kernels.Outputs) -> float | None:
        """Flag false convergence in ``res`` in place: ``HIGH_RESIDUAL``, then ``OUTLIER``.

        Returns the noise variance (GL^2) the tests used, or None when none ran.

        Residual: at the true match, with independent noise of std sigma in both images,
        ``1 - zncc ~ sigma^2 m / Df^2`` with ``m = npx - k - 2`` (ZNSSD ``C = 2 (1 - zncc)``,
        the residual being the difference of the two noises after removing mean, gain and
        the ``k`` fitted parameters). The noise variance used is the larger of
        ``noise_sigma^2`` and the field's median of ``(1 - zncc) Df^2 / m`` (so a blurred
        or otherwise mismatched pair, whose every subset exceeds the noise, is not flagged
        as a whole). The interpolation of the current image slightly smooths its noise,
        so the prediction is conservative (up to ~10 % high at half-pixel shifts).
        """
        p, z, _, st = res
        ok = st == PointStatus.CONVERGED
        sigma = None if self.noise is None else self.noise.sigma
        residual = self.max_residual is not None and sigma is not None
        if not ok.any() or not (residual or self.median_test):
            return None
        k = p.shape[1]
        fnorm2 = self._prep.fnorm**2
        m = self.subset * self.subset - k - 2
        unit = np.maximum(1.0 - z, 0.0) * fnorm2 / m
        noise_var = float(np.median(unit[ok]))
        if sigma is not None:
            noise_var = max(noise_var, sigma**2)
        if self.max_residual is not None and sigma is not None and noise_var > 0:
            limit = self.max_residual * noise_var
            if self.noise_auto:
                # an estimated noise is the pair's effective one: where content the
                # interpolant cannot follow dominates it (hard edges, a noise-free pair),
                # the subsets' residuals spread more than a noise's would
                dev = np.abs(unit[ok] - noise_var)
                limit = max(limit, noise_var + RESIDUAL_SPREAD * MAD_SCALE * float(np.median(dev)))
            high = ok & (unit > limit)
            if self.shape == "translation":
                assert sigma is not None
                high |= self._lack_of_fit(coef, p, ok & ~high, unit > self.max_residual * sigma**2)
            st[high] = PointStatus.HIGH_RESIDUAL
            ok &= ~high
        if not self.median_test or self._grid_shape is None or not ok.any():
            return noise_var
        assert self._grid_index is not None
        shape, cell = self._grid_shape, self._grid_index
        # (k, ny, nx) with u, v first: the components the median test looks at
        ucol, vcol, order = _uv_first(k)
        grid = np.full((k, shape[0] * shape[1]), np.nan)
        grid[:, cell] = np.where(ok, p[:, order].T, np.nan)
        valid = np.zeros(shape[0] * shape[1], bool)
        valid[cell] = ok
        # points within PROBE_DISTANCE of their neighbours' median skip the median (and the
        # probe): the shortcut of median_screen
        out2, med_g = median_screen(
            grid.reshape(k, *shape),
            valid.reshape(shape),
            eps=MEDIAN_EPS,
            threshold=MEDIAN_THRESHOLD,
            within=PROBE_DISTANCE / np.sqrt(2.0),
        )
        out = out2.ravel()[cell]
        st[out] = PointStatus.OUTLIER
        ok &= ~out
        # probe: a POI far from its neighbours' median is evaluated (one IC-GN iteration,
        # which reports the ZNCC at its start) at the neighbours' median parameters; a
        # clearly better fit there means IC-GN stopped at a false optimum
        med = np.empty((len(cell), k))
        med[:, order] = med_g.reshape(k, -1)[:, cell].T
        dist = np.hypot(p[:, ucol] - med[:, ucol], p[:, vcol] - med[:, vcol])
        with np.errstate(invalid="ignore"):
            probe = np.flatnonzero(ok & (dist > PROBE_DISTANCE))
        if probe.size and noise_var > 0:
            _, zp, _, _ = self._run_icgn(coef, med[probe], self._status0[probe], probe, 1)
            with np.errstate(invalid="ignore"):
                gain = fnorm2[probe] * (zp - z[probe]) / noise_var
            st[probe[gain > PROBE_CHI2]] = PointStatus.OUTLIER
        return noise_var
