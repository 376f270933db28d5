"""Blur-compensated matching of a Correlator (``blur="given"``, ``"estimate"``):
blurred references, the joint (shape, blur length) step; docs/dic.md, "Blur-compensated
correlation"."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from numpy.typing import ArrayLike

from ..arrays import Float32Array, Float64Array, IndexArray, Int64Array, UInt8Array
from ..checks import describe
from ..errors import InputError
from . import kernels
from .compensation import blur_reference, check_blur_vector, noise_gain_slope, prepare_blur_step
from .icgn import N_PARAMS
from .interpolation import bspline_coefficients, bspline_gradients
from .result import DICResult
from .screening import Screening
from .status import PointStatus

__all__ = ["BlurMatching"]


#: Most blurred references kept per Correlator (each holds a prepared reference; fewer
#: for large images, see Correlator._blurred).
_BLUR_CACHE_SIZE = 12
#: Grid (px) of the blur lengths W0 the estimation blurs the reference to; the per-subset
#: joint step estimates the remainder (|lam| <= 1/8 px at convergence).
_BLUR_GRID = 0.25
#: Convergence of the blur length in the joint step, px (its random error is 0.01-0.1 px).
_BLUR_TOLERANCE = 1e-3
#: Most POIs the estimation's image-level search of W0 uses.
_BLUR_SAMPLE = 64


@dataclass(frozen=True)
class _BlurredReference:
    """A plain Correlator on the blurred reference, and (estimation) the joint-step data."""

    corr: Any  # a Correlator
    index: IndexArray | None
    vector: Float64Array
    step: Any = None
    images: tuple[Float64Array, ...] = ()


class BlurMatching(Screening):
    """Correlation against a blurred reference (the Correlator's ``blur`` modes)."""

    if TYPE_CHECKING:

        def _correlate(
            self,
            cur: Float64Array,
            initial: ArrayLike | None,
            prepared: Float32Array | None = None,
        ) -> DICResult: ...

    def _blurred(
        self,
        vec: Float64Array,
        index: IndexArray | None,
        *,
        tag: str = "given",
        step: bool = False,
    ) -> _BlurredReference:
        """The prepared blurred reference for ``vec`` on the POIs ``index`` (None: all)."""
        key = (tag, float(vec[0]), float(vec[1]), None if index is None else index.tobytes(), step)
        hit = self._blur_cache.get(key)
        if hit is not None:
            self._blur_cache.move_to_end(key)
            return hit
        blurred, dimg = blur_reference(self._ref, vec, derivative=step)
        sel = self._all if index is None else index
        pts = np.stack([self.rows[sel], self.cols[sel]], axis=1)
        corr = cast(Any, type(self))(
            blurred,
            subset=self.subset,
            step=self.step,
            points=pts,
            shape=self.shape,
            interpolation=self.interpolation,
            initial=self.initial,
            max_iterations=self.max_iterations,
            tolerance=self.tolerance,
            noise_sigma=self.noise_sigma,
            min_zncc=self.min_zncc,
            workers=self.workers,
            max_predicted_sigma=self.max_predicted_sigma,
        )
        prep = None
        images: tuple[Float64Array, ...] = ()
        if step:
            assert dimg is not None
            coef = bspline_coefficients(blurred, order=self.order, dtype=np.float64)
            gy, gx = bspline_gradients(coef, self.order, self.image_shape)
            rc = np.clip(pts[:, 0], self.half, self.image_shape[0] - 1 - self.half)
            cc = np.clip(pts[:, 1], self.half, self.image_shape[1] - 1 - self.half)
            prep = prepare_blur_step(blurred, gx, gy, dimg, rc, cc, self.half, self.shape)
            images = (blurred, gx, gy, dimg)
        entry = _BlurredReference(
            corr=corr, index=index, vector=np.array(vec, dtype=float), step=prep, images=images
        )
        self._blur_cache[key] = entry
        # about 64 bytes per image pixel per entry: keep the cache under ~1 GiB
        limit = max(2, min(_BLUR_CACHE_SIZE, 2**30 // (64 * self._ref.size)))
        while len(self._blur_cache) > limit:
            self._blur_cache.popitem(last=False)
        return entry

    @staticmethod
    def _initial_for(initial: ArrayLike | None, index: IndexArray, n: int) -> ArrayLike | None:
        if initial is None:
            return None
        arr = np.asarray(initial, dtype=np.float64)
        return arr[index] if arr.shape == (n, 2) else arr

    def _blur_info(self, res: DICResult, **extra: Any) -> DICResult:
        info = dict(self._info_base(res.info.get("initial", self.initial)))
        info.update(extra)
        return replace(res, info=info)

    def _correlate_given(
        self, cur: Float64Array, initial: ArrayLike | None, vec: Float64Array
    ) -> DICResult:
        t0 = time.perf_counter()
        n = self.n_points
        if vec.ndim == 2 and np.all(vec == vec[:1]):
            vec = vec[0]
        if vec.ndim == 1:
            if vec[0] == 0.0 and vec[1] == 0.0:
                # zero blur: the blurred reference is the reference (bit-identical path)
                res = self._correlate(cur, initial)
            else:
                entry = self._blurred(vec, None)
                res = entry.corr._correlate(cur, initial)
                self.last_timings = dict(entry.corr.last_timings)
            self.last_timings["total_with_blur_s"] = time.perf_counter() - t0
            return self._blur_info(
                res, blur_compensation="given", blur_dy=float(vec[0]), blur_dx=float(vec[1])
            )
        # one vector per POI: group the POIs that share a vector
        uniq, inverse = np.unique(vec, axis=0, return_inverse=True)
        inverse = np.asarray(inverse).ravel()
        k = N_PARAMS[self.shape]
        p = np.full((n, k), np.nan)
        z = np.full(n, np.nan)
        it = np.zeros(n, np.int64)
        st = np.zeros(n, np.uint8)
        pu = np.full(n, np.nan) if self.noise_sigma is not None else None
        pv = np.full(n, np.nan) if self.noise_sigma is not None else None
        for g, v in enumerate(uniq):
            idx = np.flatnonzero(inverse == g).astype(np.intp)
            if v[0] == 0.0 and v[1] == 0.0:
                entry = self._blurred(np.zeros(2), idx, tag="plain")
            else:
                entry = self._blurred(v, idx)
            r = entry.corr._correlate(cur, self._initial_for(initial, idx, n))
            p[idx], z[idx], it[idx], st[idx] = r.params, r.zncc, r.iterations, r.status
            if pu is not None and pv is not None:
                assert r.predicted_sigma_u is not None and r.predicted_sigma_v is not None
                pu[idx], pv[idx] = r.predicted_sigma_u, r.predicted_sigma_v
        self.last_timings = {"total_s": time.perf_counter() - t0}
        info = self._info_base(self.initial)
        info.update(blur_compensation="given", blur_vectors=len(uniq))
        return self._result(kernels.Outputs(p, z, it, st), info=info, predicted_sigma=(pu, pv))

    def _blur_direction(
        self, blur_vector: ArrayLike | None, blur_angle: float | None
    ) -> tuple[Float64Array, float | None]:
        if blur_vector is not None:
            vec = check_blur_vector(blur_vector, n_points=self.n_points, subset=self.subset)
            if vec.ndim != 1:
                raise InputError(
                    f"blur_vector={describe(vec)}: blur='estimate' takes one "
                    "vector (dy, dx) px: its direction and starting length"
                )
            length = math.hypot(float(vec[0]), float(vec[1]))
            if length == 0.0:
                raise InputError(
                    "blur_vector=(0, 0): blur='estimate' needs the direction; "
                    "give a non-zero vector or blur_angle (degrees)"
                )
            return vec / length, length
        if blur_angle is None:
            raise InputError(
                "blur_angle=None: blur='estimate' needs the blur direction; "
                "pass blur_angle (degrees from +x towards +y) or blur_vector"
            )
        try:
            ang = float(blur_angle)
        except (TypeError, ValueError) as exc:
            raise InputError(f"blur_angle={describe(blur_angle)}: expected degrees") from exc
        if not math.isfinite(ang):
            raise InputError(f"blur_angle={blur_angle!r}: must be a finite number (degrees)")
        rad = math.radians(ang)
        return np.array([math.sin(rad), math.cos(rad)]), None

    def _joint_step(
        self, entry: _BlurredReference, cur_corr: BlurMatching, res: DICResult, max_iter: int = 10
    ) -> tuple[
        Float64Array,
        Float64Array,
        Float64Array,
        Float64Array,
        Int64Array,
        UInt8Array,
    ]:
        """Joint (shape, blur length) Gauss-Newton from the compensated IC-GN result."""
        from .kernels.blur import (
            BlurImages,
            BlurTerms,
            blur_outputs,
            blur_settings,
            joint_blur_step,
        )

        sp = entry.step
        c = cur_corr
        n = len(res)
        k = res.params.shape[1]
        out = blur_outputs(n, k)
        st_in = np.where(res.status == PointStatus.CONVERGED, 0, res.status).astype(np.uint8)
        st_in[~sp.ok & (st_in == 0)] = int(PointStatus.LOW_TEXTURE)
        joint_blur_step(
            c._coef_buf,
            BlurImages(*entry.images),
            kernels.Subsets(c.rows, c.cols, sp.hinv, sp.jsum, sp.avec, sp.fmean, sp.fnorm),
            BlurTerms(sp.evec, sp.dsum, sp.bval, sp.dd),
            blur_settings(
                self.image_shape[0],
                self.image_shape[1],
                self.order,
                self.half,
                self.shape == "affine",
                max_iter,
                self.tolerance,
                _BLUR_TOLERANCE,
            ),
            np.ascontiguousarray(res.params),
            st_in,
            out,
        )
        out_p, out_lam, out_z, out_r, out_i, out_s = out
        npx = self.subset**2
        with np.errstate(invalid="ignore", divide="ignore"):
            sig = np.sqrt(np.maximum(out_r, 0.0) / (npx - k - 1) * sp.hinv[:, k, k])
            if self.noise_sigma:
                # the blurred noisy reference loses noise as W grows: remove the lean
                # -n sigma^2 kappa'(W0) / 2 (Df^-2 hinv) of the length (noise_gain_slope)
                length = math.hypot(float(entry.vector[0]), float(entry.vector[1]))
                slope = noise_gain_slope(length, entry.vector / length)
                out_lam += (
                    sp.hinv[:, k, k]
                    / np.where(sp.fnorm > 0, sp.fnorm, 1.0) ** 2
                    * npx
                    * self.noise_sigma**2
                    * slope
                    / 2.0
                )
        return out_p, out_lam, out_z, sig, out_i, out_s

    def _correlate_estimate(
        self,
        cur: Float64Array,
        initial: ArrayLike | None,
        blur_vector: ArrayLike | None,
        blur_angle: float | None,
    ) -> DICResult:
        """Blur length along a fixed direction, estimated with the displacement.

        1. image level, on up to 64 spread POIs: compensated IC-GN at ``W0`` (a 0.25 px
           grid), then the joint step; ``W0`` <- the grid length nearest
           ``W0 + median(lam)`` until it stays (a coarse search over 1..11 px starts it
           when no length is known);
        2. every POI: compensated IC-GN at the final ``W0``, then the joint step gives the
           per-subset blur length ``W0 + lam``, its standard error and the displacement.
        """
        t0 = time.perf_counter()
        e, guess = self._blur_direction(blur_vector, blur_angle)
        wmax = self.subset - 1.0
        n = self.n_points
        good = np.flatnonzero(self._status0 == 0)
        if good.size == 0:
            good = self._all
        sample = (
            good
            if good.size <= _BLUR_SAMPLE
            else good[np.linspace(0, good.size - 1, _BLUR_SAMPLE).round().astype(np.intp)]
        )

        def grid(w: float) -> float:
            return float(min(max(round(w / _BLUR_GRID) * _BLUR_GRID, 0.5), wmax))

        def sample_run(w0: float) -> tuple[float, float]:
            entry = self._blurred(w0 * e, sample, tag="estimate", step=True)
            r = entry.corr._correlate(cur, self._initial_for(initial, sample, n))
            _, lam, z, _, _, s = self._joint_step(entry, entry.corr, r)
            ok = (s == PointStatus.CONVERGED) & np.isfinite(lam)
            if not ok.any():
                return w0, -np.inf
            return w0 + float(np.median(lam[ok])), float(np.median(z[ok]))

        # warm start (the previous image's W0, no length given): skip the sample search
        # and check W0 on the full pass instead
        warm = guess is None and self._last_blur_length is not None
        if guess is None:
            guess = self._last_blur_length
        if guess is None:
            cands = [w for w in (1.0, 3.0, 6.0, 10.0) if w <= wmax] or [grid(wmax / 2)]
            trials = [(sample_run(w)) for w in cands]
            guess = max(trials, key=lambda t: t[1])[0]
        w0 = grid(guess)
        if not warm:
            for _ in range(8):
                w_new, _ = sample_run(w0)
                # a linear step far from W0 is only a direction: at most 3 px per pass
                w_new = w0 + max(-3.0, min(3.0, w_new - w0))
                if grid(w_new) == w0:
                    break
                w0 = grid(w_new)
        for _ in range(4):
            entry = self._blurred(w0 * e, None, tag="estimate", step=True)
            base = entry.corr._correlate(cur, initial)
            p, lam, z, sig, its, st = self._joint_step(entry, entry.corr, base)
            good_lam = (st == PointStatus.CONVERGED) & np.isfinite(lam)
            if not warm or not good_lam.any():
                break
            step = max(-3.0, min(3.0, float(np.median(lam[good_lam]))))
            if grid(w0 + step) == w0:
                break
            w0 = grid(w0 + step)  # the blur changed since the last image
        self._last_blur_length = w0
        identified = (st == PointStatus.CONVERGED) & np.isfinite(sig) & (sig <= self.max_blur_sigma)
        # a subset that cannot tell its own blur keeps the displacement at the image's W0
        keep = ~identified
        p[keep] = base.params[keep]
        z[keep] = base.zncc[keep]
        st = np.where(keep, base.status, st).astype(np.uint8)
        st[(st == PointStatus.CONVERGED) & ~(z >= self.min_zncc)] = int(PointStatus.LOW_CORRELATION)
        length = np.where(np.isfinite(lam), w0 + lam, np.nan)
        self.last_timings = {"total_s": time.perf_counter() - t0}
        info = self._info_base(base.info.get("initial", self.initial))
        info.update(
            blur_compensation="estimate",
            blur_dir_dy=float(e[0]),
            blur_dir_dx=float(e[1]),
            blur_w0=w0,
        )
        return self._result(
            kernels.Outputs(p, z, base.iterations + its, st),
            info=info,
            predicted_sigma=(base.predicted_sigma_u, base.predicted_sigma_v),
            blur=(length, sig, identified),
        )
