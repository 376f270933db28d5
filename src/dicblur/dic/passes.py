"""The IC-GN passes of a Correlator: the compiled kernels on all or some POIs, the seed
pass, the predicted-imprecise subsets after the precise ones, the retry of failed POIs."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numba
import numpy as np

from ..arrays import Float32Array, Float64Array, IndexArray, UInt8Array
from . import cache, kernels
from .icgn import N_PARAMS, uv_columns
from .initial import subset_fftcc
from .outliers import neighbour_medians
from .state import CorrelatorState
from .status import PointStatus

__all__ = [
    "IMPRECISE_BUDGET",
    "IMPRECISE_MIN",
    "RETRY_BUDGET",
    "SERIAL_BELOW",
    "IcgnPasses",
    "scatter",
]

_RETRY = (
    PointStatus.MAX_ITERATIONS,
    PointStatus.DIVERGED,
    PointStatus.LOW_CORRELATION,
    PointStatus.OUT_OF_BOUNDS,
)
_RETRY_TABLE = np.zeros(256, bool)
_RETRY_TABLE[list(_RETRY)] = True
#: A retried POI gets at most this many times the median iterations of the converged POIs
#: (at least 10): a subset that failed once rarely needs the full ``max_iterations``.
RETRY_BUDGET = 4
#: Subsets predicted ``IMPRECISE`` are flagged whatever their outcome, so they get no
#: retry and (affine) an iteration limit of this many times the median iterations of the
#: precise POIs that converged in the same pass (at least :data:`IMPRECISE_MIN`, at most
#: ``max_iterations``). Their estimate is kept for inspection only: on the blob image of
#: ``benchmarks/bench_dic_robust.py`` three iterations leave it a median 0.003 px from
#: where six did, and no farther from the truth (0.1 px off: 68 against 78 of 255). 1.0 and
#: 3 since issue 15's third pass (1.5 and 4 before, when 15 % of the blob image's affine
#: iterations went to these 11 % of its POIs).
IMPRECISE_BUDGET = 1.0
IMPRECISE_MIN = 3
#: A translation kernel call on fewer POIs runs on this thread alone: waking numba's
#: OpenMP workers costs more than they give on a few subsets (a retry, the neighbour
#: check), and on a loaded machine a woken worker waits for a core (issue 26).
SERIAL_BELOW = 128


def scatter(dst: kernels.Outputs, idx: IndexArray, src: kernels.Outputs) -> None:
    """Write the IC-GN results ``src`` of the POIs ``idx`` into ``dst``, in place."""
    dst.p[idx], dst.zncc[idx], dst.iterations[idx], dst.status[idx] = src


class IcgnPasses(CorrelatorState):
    """IC-GN on the POIs of a prepared Correlator (its kernels' calls)."""

    #: Whether the main pass leaves its predicted-imprecise POIs to
    #: ``Screening._run_deferred`` (set by ``correlate`` for the grid's main pass).
    _defer_imprecise = False
    #: The POIs the main pass left (None: none).
    _deferred: IndexArray | None = None

    if TYPE_CHECKING:

        def _estimate_noise(
            self,
            z: Float64Array,
            st: UInt8Array,
            idx: IndexArray | None = None,
        ) -> None: ...

    def _settings(
        self,
        width: int,
        max_iter: int | None,
        max_step: float | None = None,
        tol: float | None = None,
    ) -> kernels.Settings:
        """The kernels' scalar record (``max_iter`` None: ``max_iterations``; ``max_step``
        None: the subset size, px, the farthest (u, v) may move from its start before the
        POI is ``DIVERGED``; ``tol`` None: ``tolerance``, px)."""
        return kernels.settings(
            self.image_shape[0],
            self.image_shape[1],
            self.order,
            self.half,
            width,
            self.max_iterations if max_iter is None else max_iter,
            self.tolerance if tol is None else tol,
            self.min_zncc,
            float(self.subset) if max_step is None else max_step,
        )

    def _retry_limit(self, median_iterations: int) -> int:
        """A retried POI's iteration limit: :data:`RETRY_BUDGET` times the median
        iterations of the converged POIs, at least 10, at most ``max_iterations``."""
        return min(self.max_iterations, max(10, RETRY_BUDGET * median_iterations))

    def _imprecise_limit(self, median_iterations: float) -> int:
        """A predicted-imprecise POI's iteration limit: :data:`IMPRECISE_BUDGET` times the
        median iterations of the precise converged POIs, at least :data:`IMPRECISE_MIN`,
        at most ``max_iterations``."""
        budget = math.ceil(IMPRECISE_BUDGET * median_iterations)
        return min(self.max_iterations, max(IMPRECISE_MIN, budget))

    def _translation(
        self,
        coef: Float32Array,
        p0: Float64Array,
        status_in: UInt8Array,
        passes: kernels.Passes,
        settings: kernels.Settings,
    ) -> kernels.Outputs:
        """Translation kernel on all POIs' arrays (n,): ``passes.first`` from ``p0``, then
        ``passes.second`` from their ``source`` POI's result (see kernels.icgn_translation),
        with the scalars ``settings`` (:meth:`_settings`)."""
        out = kernels.outputs(self.n_points, 2)
        cache.wait_for_background("translation")
        old = numba.get_num_threads()
        if passes.first.size + passes.second.size < SERIAL_BELOW:
            numba.set_num_threads(1)  # same bytes: each POI's result is its own
        try:
            kernels.icgn_translation(
                coef,
                self._images,
                self._subsets,
                self._packed,
                settings,
                p0,
                status_in,
                passes,
                numba.config.NUMBA_NUM_THREADS,  # type: ignore[attr-defined]
                out,
            )
        finally:
            numba.set_num_threads(old)
        return out

    def _run_icgn(
        self,
        coef: Float32Array,
        p0: Float64Array,
        status_in: UInt8Array,
        idx: IndexArray | None = None,
        max_iter: int | None = None,
        max_step: float | None = None,
        tol: float | None = None,
    ) -> kernels.Outputs:
        """IC-GN of the POIs ``idx`` (None: all) from ``p0``; ``max_iter``, ``max_step``,
        ``tol`` as :meth:`_settings` (None: the Correlator's)."""
        if self.shape == "translation":
            full = np.zeros((self.n_points, 2))
            st_full = np.zeros(self.n_points, np.uint8)
            sel = self._all if idx is None else idx
            full[sel] = p0
            st_full[sel] = status_in
            one_pass = kernels.Passes(sel, self._none, self._none)
            settings = self._settings(self._w, max_iter, max_step, tol)
            out = self._translation(coef, full, st_full, one_pass, settings)
            if idx is None:
                return out
            return kernels.Outputs(out.p[idx], out.zncc[idx], out.iterations[idx], out.status[idx])
        if max_iter is None and self._imprecise is not None:
            split = self._imprecise_split(idx)
            if split is not None:
                return self._run_split(coef, p0, status_in, idx, split)
        if idx is None:
            subsets = self._subsets
        else:
            key = id(idx)
            cached = self._args_cache.get(key)
            if cached is not None and cached[0] is idx:
                subsets = cached[1]
            else:
                subsets = kernels.Subsets(*(a[idx] for a in self._subsets))  # type: ignore[arg-type]
                if (
                    idx is self._seeds
                    or (self._rest is not None and idx is self._rest)
                    or key in self._split_ids
                ):
                    self._args_cache[key] = (idx, subsets)
        n = len(self.rows) if idx is None else len(idx)
        out = kernels.outputs(n, N_PARAMS[self.shape])
        cache.wait_for_background("affine")
        kernels.icgn_affine(
            coef,
            self._images,
            subsets,
            self._settings(self._tw, max_iter, max_step, tol),
            np.ascontiguousarray(p0),
            np.ascontiguousarray(status_in),
            out,
        )
        return out

    def _imprecise_split(
        self, idx: IndexArray | None
    ) -> tuple[IndexArray, IndexArray, IndexArray, IndexArray] | None:
        """``idx`` (None: all POIs) split into the precise and the predicted-imprecise POIs:
        (positions in idx, POIs) of each, or None when none is imprecise."""
        assert self._imprecise is not None
        key = id(idx)
        hit = self._split_cache.get(key)
        if hit is not None and hit[0] is idx:
            return hit[1]
        sel = self._all if idx is None else idx
        imp = self._imprecise[sel]
        out = None
        if imp.any():
            loc_p, loc_i = np.flatnonzero(~imp), np.flatnonzero(imp)
            out = (loc_p, sel[loc_p], loc_i, sel[loc_i])
        if idx is None or idx is self._seeds or idx is self._rest:
            self._split_cache[key] = (idx, out)
            if out is not None:
                self._split_ids.update((id(out[1]), id(out[3])))
        return out

    def _run_split(
        self,
        coef: Float32Array,
        p0: Float64Array,
        status_in: UInt8Array,
        idx: IndexArray | None,
        split: tuple[IndexArray, IndexArray, IndexArray, IndexArray],
    ) -> kernels.Outputs:
        """Affine IC-GN, the predicted-imprecise POIs after the precise ones, within
        IMPRECISE_BUDGET times the median iterations of the precise converged POIs."""
        loc_p, pts_p, loc_i, pts_i = split
        n = len(self.rows) if idx is None else len(idx)
        out = kernels.outputs(n, p0.shape[1])
        cap = self.max_iterations
        defer = self._defer_imprecise and (idx is None or idx is self._rest)
        if loc_p.size:
            r = self._run_icgn(coef, p0[loc_p], status_in[loc_p], pts_p, cap)
            scatter(out, loc_p, r)
            conv = r.iterations[r.status == PointStatus.CONVERGED]
            if conv.size:
                cap = self._imprecise_limit(float(np.median(conv)))
        if defer:
            # run after the whole grid's precise POIs, from their neighbours' parameters
            # (Screening._run_deferred): a start near the field, no reduced pass + retry
            out.p[loc_i], out.zncc[loc_i], out.iterations[loc_i] = p0[loc_i], 0.0, 0
            out.status[loc_i] = PointStatus.MAX_ITERATIONS
            self._deferred = pts_i
            return out
        scatter(out, loc_i, self._run_icgn(coef, p0[loc_i], status_in[loc_i], pts_i, cap))
        return out

    def _seeded_icgn(
        self, coef: Float32Array, p0: Float64Array, status0: UInt8Array
    ) -> kernels.Outputs:
        assert self._seeds is not None and self._rest is not None
        seeds, rest, src = self._seeds, self._rest, self._rest_seed
        if self.shape == "translation":
            # both passes in one kernel call: the rest start from their seed's result
            both = kernels.Passes(seeds, rest, src)
            return self._translation(coef, p0, status0, both, self._settings(self._w, None))
        n, k = p0.shape
        out = kernels.outputs(n, k)
        p, st = out.p, out.status
        first = self._run_icgn(coef, p0[seeds], status0[seeds], seeds)
        scatter(out, seeds, first)
        if self.noise_auto:
            # the seeds' residuals give the noise, so the rest pass knows its imprecise POIs
            self._estimate_noise(first.zncc, first.status, seeds)
        start = p0[rest].copy()
        good = st[src] == PointStatus.CONVERGED
        q = p[src[good]]
        dx = (self.cols[rest[good]] - self.cols[src[good]]).astype(float)
        dy = (self.rows[rest[good]] - self.rows[src[good]]).astype(float)
        if k == 2:
            start[good] = q
        elif good.any():
            # carry the seed's translation to this POI's centre with the median gradients of
            # all converged seeds (a single seed's gradients are too noisy to extrapolate)
            ok_seeds = st[seeds] == PointStatus.CONVERGED
            grad = np.median(p[seeds[ok_seeds]][:, [1, 2, 4, 5]], axis=0)
            start[good] = q
            start[good, 0] = q[:, 0] + grad[0] * dx + grad[1] * dy
            start[good, 3] = q[:, 3] + grad[2] * dx + grad[3] * dy
            start[good, 1], start[good, 2] = grad[0], grad[1]
            start[good, 4], start[good, 5] = grad[2], grad[3]
        scatter(out, rest, self._run_icgn(coef, start, status0[rest], rest))
        return out

    def _guess_to_params(self, u: Float64Array, v: Float64Array) -> Float64Array:
        k = N_PARAMS[self.shape]
        ucol, vcol = uv_columns(k)
        p0 = np.zeros((len(u), k))
        p0[:, ucol] = u
        p0[:, vcol] = v
        return p0

    def _retry(
        self,
        cur: Float64Array,
        coef: Float32Array,
        gu: Float64Array,
        gv: Float64Array,
        res: kernels.Outputs,
    ) -> None:
        """Second chance for the failed POIs of ``res``, in place, within an iteration budget.

        A POI with converged grid neighbours restarts from their median parameters (a
        start near the local field, one compiled call for all); the others get the
        per-subset FFT-CC integer guess, unless it equals the start they already had.
        """
        p, z, it, st = res
        status0 = self._status0
        again = _RETRY_TABLE[st] & (status0 == 0)  # a table: np.isin costs ~1 ms
        if self._imprecise is not None:
            # flagged IMPRECISE even if a retry converged: not worth a second attempt
            again &= ~self._imprecise
        retry = np.flatnonzero(again)
        if retry.size == 0:
            return
        ok = st == PointStatus.CONVERGED
        conv = it[ok]
        budget = self.max_iterations if conv.size == 0 else self._retry_limit(int(np.median(conv)))
        k = p.shape[1]
        start = np.full((retry.size, k), np.nan)
        if self._grid_shape is not None and ok.any():
            assert self._grid_index is not None
            ny, nx = self._grid_shape
            cell = self._grid_index
            grid = np.full((k, ny * nx), np.nan)
            grid[:, cell] = p.T
            valid = np.zeros(ny * nx, bool)
            valid[cell] = ok
            start = neighbour_medians(grid.reshape(k, ny, nx), valid.reshape(ny, nx), cell[retry]).T
        near = np.all(np.isfinite(start), axis=1)
        far = retry[~near]
        if far.size:
            iu, iv, _ = subset_fftcc(
                self._ref,
                cur,
                self.rows[far],
                self.cols[far],
                self.half,
                guess_u=gu[far],
                guess_v=gv[far],
                workers=1,
            )
            # the first pass started there already: nothing new to try
            new = (iu != np.rint(gu[far])) | (iv != np.rint(gv[far]))
            start[~near] = self._guess_to_params(iu.astype(float), iv.astype(float))
            near[~near] = new
        retry, start = retry[near], start[near]
        if retry.size == 0:
            return
        p2, z2, it2, st2 = self._run_icgn(coef, start, status0[retry], retry, budget)
        better = (st2 == PointStatus.CONVERGED) | (st[retry] != PointStatus.CONVERGED)
        idx = retry[better]
        p[idx], z[idx], st[idx] = p2[better], z2[better], st2[better]
        it[idx] = it[idx] + it2[better]
