"""The subset DIC engine: a prepared reference correlated against current images.

Pipeline per current image (one module per stage): B-spline prefilter
(:mod:`.interpolation`), integer initial guess (:mod:`.initial`), IC-GN refinement with the
ZNSSD criterion (:mod:`.icgn`, compiled in :mod:`.kernels`; its passes in :mod:`.passes`),
screening (:mod:`.screening`), result (:mod:`.result`); blur compensation in
:mod:`.blur_matching`. The prepared state the stages share: :mod:`.state`.
"""

from __future__ import annotations

import time
from collections import OrderedDict
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import replace
from typing import Any, Literal

import numba
import numpy as np
from numpy.typing import ArrayLike

from ..arrays import BoolArray, Float32Array, Float64Array
from ..checks import (
    as_float_array,
    as_image,
    check_choice,
    check_positive,
    check_subset_fits,
    check_textured,
    describe,
)
from ..errors import InputError
from ..metrics import image_gradients
from . import cache, kernels
from .blur_matching import BlurMatching
from .compensation import BLUR_MODES, check_blur_vector
from .icgn import N_PARAMS, prepare_subsets, uv_columns
from .initial import global_shift, subset_fftcc, window_spectrum
from .interpolation import PAD, bspline_coefficients, bspline_gradients
from .layout import grid_of, layout, seed_passes
from .noise import NoiseEstimate
from .passes import IMPRECISE_BUDGET, IMPRECISE_MIN, RETRY_BUDGET
from .result import DICResult
from .screening import MAX_PREDICTED_SIGMA, PROBE_CHI2, PROBE_DISTANCE
from .settings import INITIAL_METHODS, SHAPES, MatcherSettings, Shape, check_integer
from .state import UNSET, PreparedImage, Refined, Unset

__all__ = [
    "IMPRECISE_BUDGET",
    "IMPRECISE_MIN",
    "INITIAL_METHODS",
    "MAX_PREDICTED_SIGMA",
    "PROBE_CHI2",
    "PROBE_DISTANCE",
    "RETRY_BUDGET",
    "SHAPES",
    "Correlator",
    "PreparedImage",
    "Refined",
    "correlate",
]

BlurMode = Literal["none", "given", "estimate"]


class Correlator(BlurMatching):
    """Subset DIC against one prepared reference image.

    The reference is prepared once (B-spline coefficients and gradients, per-subset
    ZNSSD Hessians, predicted random errors); :meth:`correlate` then measures any number of
    current images against it. One instance reuses a coefficient buffer between calls:
    do not call :meth:`correlate` of the same instance from several threads at once
    (processes, or one instance per thread, are fine: :meth:`fork` makes one cheaply).
    For the translation shape the flat reference subsets are kept too (12 bytes per
    subset pixel, about 6 kB per POI at subset 21; above :attr:`pack_limit_bytes` they are
    copied per call instead, with the same results).

    Parameters
    ----------
    reference : array_like, shape (rows, cols)
        Reference image, grey levels (finite).
    settings : MatcherSettings, optional
        The matcher's settings in one record (:class:`~dicblur.dic.MatcherSettings`).
        The keywords ``subset`` to ``median_test`` below build one, or override the
        fields of ``settings`` they name; :attr:`settings` holds the result.
    subset : int
        Odd subset size, px.
    step : int
        Grid spacing of the POIs, px (ignored when ``points`` is given).
    roi : (row_start, row_stop, col_start, col_stop), optional
        Region (px, half-open) inside which the grid of subsets is laid out.
    points : array_like of int, shape (n, 2), optional
        Explicit POI centres ``(row, col)``; subsets that leave the reference get status
        ``OUT_OF_BOUNDS``.
    shape : {"affine", "translation"}
        First-order (6 parameters) or zero-order (2 parameters) shape function.
    interpolation : {"bspline3", "bspline5"}
        Prefiltered cubic or quintic B-spline.
    initial : {"fftcc", "subset", "zero"}
        Initial-guess method (see :data:`INITIAL_METHODS`).
    max_iterations : int
        IC-GN iteration limit.
    tolerance : float
        Convergence threshold, px: the estimated error left in the parameters (as
        :class:`~dicblur.dic.MatcherSettings`): the Gauss-Newton step norm
        ``|d| = sqrt(du^2 + dv^2 + h^2 |grad|^2)`` (``h`` = subset half-width) below it, or,
        for steps contracting by ``q = |d| / |d_prev|``, ``|d| q / (1 - q)`` below it (below
        4 x it after an Aitken jump, ``kernels.JUMP_SLACK``).
    noise_sigma : float, "auto" or None
        Image noise std, grey levels (assumed in both images): enables the per-point
        predicted sigma and the noise-based screening. ``"auto"`` (default): each
        correlation estimates it from the pair's converged ZNSSD residuals
        (:func:`~dicblur.dic.noise.residual_noise`; the plain matcher, ``blur="none"``;
        with compensation "auto" acts as None), reported in :attr:`noise` and the
        result's ``info``. None: no noise known, no noise-based test.
    min_zncc : float
        Converged points with a lower ZNCC get status ``LOW_CORRELATION``.
    max_residual : float or None
        With ``noise_sigma``: converged points whose ZNSSD residual exceeds this many times
        the subset's noise prediction get status ``HIGH_RESIDUAL`` (None: no test).
    median_test : bool
        Screen the converged points of the POI grid for ``OUTLIER``: the normalised median
        test (:func:`~dicblur.dic.normalized_median_test`, eps 0.1 px, threshold 2) and a
        probe of the neighbours' median displacement (explicit ``points`` must then fill a
        regular grid). Off by default: where the random error itself approaches eps
        (strong blur) the test trims the tails of the field and biases its std low.
    workers : int, optional
        Threads of the compiled kernels (default: all numba threads).
    blur : {"none", "given", "estimate"}
        Motion-blur compensation (docs/dic.md, "Blur-compensated correlation"): ``none``
        correlates the sharp reference as is; ``given`` compares each current image with
        the reference blurred by the ``blur_vector`` passed to :meth:`correlate`;
        ``estimate`` also estimates the blur length along a given direction per subset.
        With compensation the displacement is the mean position during the exposure.
    max_blur_sigma : float
        ``blur="estimate"``: a subset whose estimated blur length has a larger standard
        error (px) is flagged as not identifying the blur (``DICResult.blur_identified``).
    max_predicted_sigma : float or None
        With ``noise_sigma``: points whose predicted random error
        ``hypot(predicted_sigma_u, predicted_sigma_v)`` exceeds this (px; default 0.1/3,
        so that a 0.1 px error is a 3-sigma event) and that converged or stopped at their
        iteration limit get status ``IMPRECISE``; such subsets are known before
        correlating, so they are not retried and (affine) get at most
        :data:`IMPRECISE_BUDGET` times the median iterations of the converging subsets.
        None: no test.
    neighbour_check : bool
        On a grid of POIs, compare each converged POI with the median of its precise
        converged 3x3 neighbours (docs/dic.md, "Screening"): a POI farther than
        ``max(0.1 px, 4 predicted sigma)`` is retried from that median and is
        ``OUTLIER`` unless the retry fits better there; a predicted-imprecise POI within
        0.07 px of it is kept ``CONVERGED`` instead of ``IMPRECISE``. False: no check.

    Examples
    --------
    >>> import numpy as np, dicblur
    >>> ref = dicblur.speckle_pattern((96, 96), speckle_size=4, seed=1)
    >>> cur = np.roll(ref, 2, axis=1)
    >>> res = dicblur.Correlator(ref, subset=21, step=20, shape="translation").correlate(cur)
    >>> bool(np.allclose(res.u[res.converged], 2.0, atol=1e-3))
    True
    """

    def __init__(
        self,
        reference: ArrayLike,
        *,
        settings: MatcherSettings | None = None,
        subset: int | Unset = UNSET,
        step: int | Unset = UNSET,
        roi: Sequence[int] | None = None,
        points: ArrayLike | None = None,
        shape: Shape | Unset = UNSET,
        interpolation: str | Unset = UNSET,
        initial: str | Unset = UNSET,
        max_iterations: int | Unset = UNSET,
        tolerance: float | Unset = UNSET,
        noise_sigma: float | Literal["auto"] | None = "auto",
        min_zncc: float | Unset = UNSET,
        workers: int | None = None,
        max_residual: float | Unset | None = UNSET,
        median_test: bool | Unset = UNSET,
        blur: BlurMode = "none",
        max_blur_sigma: float = 0.5,
        max_predicted_sigma: float | None = MAX_PREDICTED_SIGMA,
        neighbour_check: bool = True,
    ) -> None:
        t0 = time.perf_counter()
        given: dict[str, Any] = {
            k: v
            for k, v in (
                ("subset", subset),
                ("step", step),
                ("shape", shape),
                ("interpolation", interpolation),
                ("initial", initial),
                ("max_iterations", max_iterations),
                ("tolerance", tolerance),
                ("min_zncc", min_zncc),
                ("max_residual", max_residual),
                ("median_test", median_test),
            )
            if v is not UNSET
        }
        if settings is not None and not isinstance(settings, MatcherSettings):
            raise InputError(
                f"settings={describe(settings)}: expected a dicblur.dic.MatcherSettings"
            )
        # validated once, by MatcherSettings
        cfg = replace(settings, **given) if settings is not None else MatcherSettings(**given)
        #: The matcher's settings (subset, step, shape, interpolation, ...).
        self.settings: MatcherSettings = cfg
        self.blur: str = check_choice(blur, "blur", BLUR_MODES)
        self.max_blur_sigma = check_positive(max_blur_sigma, "max_blur_sigma")
        ref = as_image(reference, "reference", min_size=3)
        self.subset = cfg.subset
        check_subset_fits(self.subset, ref.shape)
        check_textured(ref, "reference")
        self.step = cfg.step
        self.shape: str = cfg.shape
        self.interpolation: str = cfg.interpolation
        self.order = cfg.order
        self.initial: str = cfg.initial
        self.max_iterations = cfg.max_iterations
        self.tolerance = cfg.tolerance
        #: Whether each correlation estimates the noise (``noise_sigma="auto"``).
        auto = isinstance(noise_sigma, str) and noise_sigma == "auto"
        self.noise_auto = auto and self.blur == "none"
        self.noise_sigma = (
            None
            if noise_sigma is None or auto
            else check_positive(noise_sigma, "noise_sigma", allow_zero=True)
        )
        self.min_zncc = cfg.min_zncc
        self.workers = None if workers is None else check_integer(workers, "workers", 1)
        self.max_residual = cfg.max_residual
        self.max_predicted_sigma = (
            None
            if max_predicted_sigma is None
            else check_positive(max_predicted_sigma, "max_predicted_sigma")
        )
        median_test = cfg.median_test
        self.image_shape: tuple[int, int] = (int(ref.shape[0]), int(ref.shape[1]))
        # a cold numba cache: a child process compiles the IC-GN kernel meanwhile (issue 16)
        cache.compile_in_background(self.shape)
        half = self.subset // 2
        self.half = half

        rows, cols, status0 = layout(
            self.image_shape, subset=self.subset, step=self.step, roi=roi, points=points
        )
        self.rows = rows
        self.cols = cols
        self._grid_shape, self._grid_index = grid_of(rows, cols, required=bool(median_test))
        #: Whether :meth:`correlate` screens the grid for ``OUTLIER`` points.
        self.median_test = bool(median_test)
        #: Whether :meth:`correlate` checks each converged POI against its grid
        #: neighbours (screening.py: retry from their median, ``OUTLIER``, IMPRECISE kept).
        self.neighbour_check = bool(neighbour_check)
        coef = bspline_coefficients(ref, order=self.order, dtype=np.float64)
        # IC-GN uses the exact derivatives of the reference spline (consistent with the
        # interpolant of the current image: fast, unbiased convergence)
        gy, gx = bspline_gradients(coef, self.order, self.image_shape)
        # out-of-bounds POIs are prepared on a clipped centre and keep their status
        rc = np.clip(rows, half, ref.shape[0] - 1 - half)
        cc = np.clip(cols, half, ref.shape[1] - 1 - half)
        prep = prepare_subsets(ref, gx, gy, rc, cc, half, self.shape)
        status0 = np.where(status0 != 0, status0, prep.status).astype(np.uint8)
        self._prep = prep
        self._status0 = status0
        self._ref = ref
        #: reference spline gradients (gy, gx), for the translation lack-of-fit test
        self._ref_grad = (gy, gx)
        #: the current image being screened (set by correlate and refine)
        self._screen_image: Float64Array | None = None
        # padded float32 layouts of the kernels (see kernels.icgn_translation)
        # affine row width: a multiple of 8 (one AVX2 vector of float32): subset 21 runs 3
        # vectors per row instead of 4 (per POI-iteration 17.4k -> 15.0k instructions,
        # 2.31 -> 2.01 us, one thread of a 2-core AVX2 EPYC)
        self._tw = 8 * ((self.subset + 7) // 8)
        self._w = kernels.flat_width(self.subset, self.order)
        rows_img, cols_img = self.image_shape
        extra = max(self._tw, self._w) + 16
        self._f32 = np.zeros((rows_img, cols_img + max(self._tw, self._w)), np.float32)
        self._f32[:, :cols_img] = ref
        self._gx32 = np.zeros_like(self._f32)
        self._gx32[:, :cols_img] = gx
        self._gy32 = np.zeros_like(self._f32)
        self._gy32[:, :cols_img] = gy
        # the kernels' records (dicblur.dic.kernels.common)
        self._images = kernels.ReferenceImages(self._f32, self._gx32, self._gy32)
        self._subsets = kernels.Subsets(
            *(  # type: ignore[arg-type]
                np.ascontiguousarray(a)
                for a in (rows, cols, prep.hinv, prep.jsum, prep.avec, prep.fmean, prep.fnorm)
            )
        )
        self._coef_buf = np.zeros((rows_img + 2 * PAD, cols_img + 2 * PAD + extra), np.float32)
        self._all = np.arange(len(rows), dtype=np.intp)
        self._none = np.zeros(0, dtype=np.intp)
        self._args_cache: dict[int, Any] = {}
        self._split_cache: dict[int, Any] = {}
        self._split_ids: set[int] = set()
        self._setup_seeds()
        self._pack_translation()
        self._ref_spectrum = window_spectrum(ref)
        self.predicted_sigma_u: Float64Array | None = None
        self.predicted_sigma_v: Float64Array | None = None
        #: The noise of the last correlation (given or estimated), or None.
        self.noise: NoiseEstimate | None = (
            None if self.noise_sigma is None else NoiseEstimate.given(self.noise_sigma)
        )
        self._unit_sigma: Float64Array | None = None
        if self.noise_sigma is not None or self.noise_auto:
            # predicted sigma from the project's SSSIG (central differences, as
            # dicblur.metrics.sssig): see docs/dic.md for why not the spline gradients
            cgy, cgx = image_gradients(ref)
            pp = prepare_subsets(ref, cgx, cgy, rc, cc, half, self.shape)
            s2 = 1.0 if self.noise_sigma is None else self.noise_sigma**2
            with np.errstate(divide="ignore", invalid="ignore"):
                if self.shape == "translation":
                    pu = np.sqrt(2.0 * s2 / pp.sssig_x)
                    pv = np.sqrt(2.0 * s2 / pp.sssig_y)
                else:
                    pu = np.sqrt(s2 * pp.cov_unit[:, 0, 0])
                    pv = np.sqrt(s2 * pp.cov_unit[:, 3, 3])
            bad = status0 != 0
            if self.noise_sigma is None:
                # per unit noise: scaled by each correlation's estimate (screening.py)
                self._unit_sigma = np.stack([np.where(bad, np.nan, pu), np.where(bad, np.nan, pv)])
            else:
                self.predicted_sigma_u = np.where(bad, np.nan, pu)
                self.predicted_sigma_v = np.where(bad, np.nan, pv)
        #: POIs whose predicted random error exceeds ``max_predicted_sigma`` (or None).
        self._imprecise: BoolArray | None = None
        pu_, pv_ = self.predicted_sigma_u, self.predicted_sigma_v
        if pu_ is not None and pv_ is not None and self.max_predicted_sigma is not None:
            with np.errstate(invalid="ignore"):
                imp = np.hypot(pu_, pv_) > self.max_predicted_sigma
            self._imprecise = imp if imp.any() else None
        # blur compensation: prepared blurred references by (blur vector, point set)
        self._blur_cache = OrderedDict()
        self._last_blur_length = None
        self.prepare_time_s = time.perf_counter() - t0
        #: Timings (s) of the last :meth:`correlate` call: prefilter, initial, icgn, total.
        self.last_timings: dict[str, float] = {}

    # ------------------------------------------------------------------ setup helpers
    #: :func:`.layout.layout` (the POIs a Correlator lays out, without preparing it), as
    #: ``Correlator.layout(image_shape, subset=..., step=...)``.
    layout = staticmethod(layout)

    def _setup_seeds(self) -> None:
        """The two-pass start's seed POIs and the rest (:func:`.layout.seed_passes`)."""
        passes = seed_passes(self.rows, self.cols, self.step)
        self._seeds = None if passes is None else passes[0]
        self._rest = None if passes is None else passes[1]
        if passes is not None:
            self._rest_seed = passes[2]

    #: kernel copies each POI's subset per call instead (same results).
    pack_limit_bytes = 256 * 2**20

    def _pack_translation(self) -> None:
        ng = kernels.flat_lengths(self.subset, self.order)[0]
        n = self.n_points if self.shape == "translation" else 0
        if 3 * 4 * n * ng > self.pack_limit_bytes:
            n = 0
        self._packed = kernels.Packed(*(np.zeros((n, ng), np.float32) for _ in range(3)))
        if n:
            kernels.pack_reference(
                self._images, self._subsets, self.half, self._w, self._status0, self._packed
            )

    def prefilter(self, current: ArrayLike) -> PreparedImage:
        """The checked image ``current`` with its B-spline coefficients, for several
        correlations of the same frame.

        :meth:`correlate` of this Correlator, or of any other on a reference of the same
        shape with the same subset, shape function and interpolation (e.g. one on a few of
        its points, or a renewed reference), then skips the prefilter (about 1.5 ms for
        512^2; issue 17: the seed points of ``dicblur track`` and the frame share one).

        Parameters
        ----------
        current : array_like, shape (rows, cols)
            Deformed image, same shape as the reference, grey levels.

        Returns
        -------
        PreparedImage
        """
        cur = self._checked(current)
        # only the margin columns on the right are not written by the prefilter (1.1 MB
        # zeroed per frame otherwise)
        coef = np.empty_like(self._coef_buf)
        coef[:, self.image_shape[1] + 2 * PAD :] = 0.0
        # on this Correlator's threads, as correlate() (one in a chunk thread of dicblur
        # track: numba's two there cost 2.45 instead of ~1.4 ms)
        with self._kernel_threads():
            self._coefficients_into(cur, coef)
        return PreparedImage(cur, coef, self.order)

    def _coefficients_into(self, cur: Float64Array, buf: Float32Array) -> None:
        """The float32 B-spline coefficients of ``cur`` into ``buf`` (the padded layout of
        ``_coef_buf``; its zero columns on the right stay zero)."""
        cols_img = self.image_shape[1]
        bspline_coefficients(
            cur, order=self.order, dtype=np.float32, out=buf[:, : cols_img + 2 * PAD]
        )

    @contextmanager
    def _kernel_threads(self) -> Iterator[None]:
        """numba's thread count set to ``workers`` (numba's setting is per calling thread)
        for the block, restored after it."""
        old_threads = numba.get_num_threads()
        if self.workers is not None:
            numba.set_num_threads(min(self.workers, numba.config.NUMBA_NUM_THREADS))  # type: ignore[attr-defined]
        try:
            yield
        finally:
            numba.set_num_threads(old_threads)

    def _check_prepared(self, current: PreparedImage) -> None:
        if (
            current.image.shape != self.image_shape
            or current.coefficients.shape != self._coef_buf.shape
            or current.order != self.order
        ):
            raise InputError(
                f"current: a PreparedImage of a {current.image.shape} image "
                f"(interpolation order {current.order}) does not fit this Correlator "
                f"({self.image_shape}, order {self.order}, subset {self.subset}); "
                "prepare it with this Correlator's prefilter()"
            )

    def refine(self, current: PreparedImage, start: ArrayLike) -> Refined:
        """IC-GN of every POI from ``start`` on a prefiltered image: the numbers of
        ``correlate(current, initial=start)`` without building a :class:`DICResult`.

        For loops over many frames (``dicblur track`` runs it twice per frame: the seed
        points, then all points), where the result's copies and metadata cost more than
        the few POIs' IC-GN. The statuses are screened as by :meth:`correlate`
        (``HIGH_RESIDUAL``, ``OUTLIER``, ``IMPRECISE``).

        Parameters
        ----------
        current : PreparedImage
            The :meth:`prefilter` of the deformed image by a Correlator of this layout.
        start : array_like, shape (n, 2) or, affine, (n, 6)
            Finite initial ``(u, v)`` px per POI, or all affine parameters (as
            :attr:`DICResult.params`).

        Returns
        -------
        Refined
            ``params`` (n, k), ``zncc`` (n,), ``iterations`` (n,) int64, ``status`` (n,)
            uint8, as the :class:`DICResult` of :meth:`correlate`.

        Raises
        ------
        InputError
            With blur compensation (use :meth:`correlate`), a PreparedImage of another
            layout, or a ``start`` of another shape or with non-finite values.
        """
        if self.blur != "none":
            raise InputError(
                f"refine: this Correlator has blur={self.blur!r}; use correlate() with "
                "its blur_vector"
            )
        if not isinstance(current, PreparedImage):
            raise InputError(
                f"current={describe(current)}: expected the PreparedImage of this "
                "Correlator's prefilter()"
            )
        self._check_prepared(current)
        n, k = self.n_points, N_PARAMS[self.shape]
        p0 = as_float_array(start, "start", expected=f"expected finite (u, v) px, shape ({n}, 2)")
        if p0.shape == (n, 2) and k != 2:
            p0 = self._guess_to_params(p0[:, 0], p0[:, 1])
        if p0.shape != (n, k) or not np.isfinite(p0).all():
            raise InputError(
                f"start={describe(p0)}: expected finite (u, v) px, shape ({n}, 2)"
                + ("" if k == 2 else f", or the {k} affine parameters, shape ({n}, {k})")
            )
        coef = current.coefficients
        with self._kernel_threads():
            if self.noise_auto:
                self._set_noise(None)
            self._defer_imprecise, self._deferred = self.shape != "translation", None
            try:
                res = self._run_icgn(coef, p0, self._status0)
            finally:
                self._defer_imprecise = False
            self._run_deferred(coef, res)  # as correlate
            self._screen_image = current.image
            self._flag(coef, res)
        return Refined(*res)

    def _checked(self, current: ArrayLike) -> Float64Array:
        cur = as_image(current, "current", min_size=3)
        if cur.shape != self.image_shape:
            raise InputError(
                f"current: shape {cur.shape} differs from the reference "
                f"{self.image_shape}; both images must have the same size"
            )
        return cur

    def correlate(
        self,
        current: ArrayLike | PreparedImage,
        *,
        initial: ArrayLike | None = None,
        blur_vector: ArrayLike | None = None,
        blur_angle: float | None = None,
    ) -> DICResult:
        """Measure the displacement of every POI in ``current``.

        Parameters
        ----------
        current : array_like, shape (rows, cols), or PreparedImage
            Deformed image, same shape as the reference, grey levels; or the
            :meth:`prefilter` of one by a Correlator of the same layout (its coefficients
            are used as they are).
        initial : array_like, shape (n, 2) or (2,), optional
            Initial guess ``(u, v)`` per POI (or one for all), px; overrides the
            initial-guess method. With ``shape="affine"`` also (n, 6): all parameters,
            ordered as :attr:`DICResult.params` (e.g. the previous frame's, so IC-GN
            starts with the subset's deformation too).
        blur_vector : array_like, shape (2,) or (n, 2), optional
            Motion during the exposure ``(dy, dx)`` px, as :func:`dicblur.motion_blur`
            takes it, for the whole image or per POI. Required with ``blur="given"``
            (blur length ``hypot(dy, dx)`` shorter than the subset); with
            ``blur="estimate"`` one vector gives the direction and the starting length.
        blur_angle : float, optional
            ``blur="estimate"`` without ``blur_vector``: the blur direction, degrees from
            +x (columns) towards +y (rows), as ``dicblur blur --angle``.

        Returns
        -------
        DICResult
            With compensation the displacement is the mean position during the exposure
            (``d0 + X / 2`` for a target moving from ``d0`` to ``d0 + X``);
            ``blur="estimate"`` adds ``blur_length``, ``blur_sigma``, ``blur_identified``.
        """
        coef: Float32Array | None = None
        if isinstance(current, PreparedImage):
            self._check_prepared(current)
            cur, coef = current.image, current.coefficients
        else:
            cur = self._checked(current)
        with self._kernel_threads():
            if self.blur == "none":
                if blur_vector is not None or blur_angle is not None:
                    raise InputError(
                        f"blur_vector={describe(blur_vector)}: this Correlator "
                        "has blur='none'; create it with blur='given' or "
                        "blur='estimate' to compensate the blur"
                    )
                return self._correlate(cur, initial, coef)
            if self.blur == "given":
                if blur_vector is None:
                    raise InputError(
                        "blur_vector=None: blur='given' needs the motion "
                        "during the exposure (dy, dx) px, e.g. (0.0, 3.5)"
                    )
                if blur_angle is not None:
                    raise InputError(
                        f"blur_angle={blur_angle!r}: only for blur='estimate'; "
                        "with blur='given' the vector holds the direction"
                    )
                vec = check_blur_vector(blur_vector, n_points=self.n_points, subset=self.subset)
                return self._correlate_given(cur, initial, vec)
            return self._correlate_estimate(cur, initial, blur_vector, blur_angle)

    def _correlate(
        self,
        cur: Float64Array,
        initial: ArrayLike | None,
        prepared: Float32Array | None = None,
    ) -> DICResult:
        t0 = time.perf_counter()
        if prepared is None:
            coef = self._coef_buf
            self._coefficients_into(cur, coef)
        else:
            coef = prepared
        t1 = time.perf_counter()
        n = self.n_points
        status0 = self._status0
        method = self.initial
        full: Float64Array | None = None
        if initial is not None:
            if isinstance(initial, str):
                raise InputError(
                    f"initial={initial!r}: correlate() takes initial guesses (u, v) px; "
                    f"set the method with Correlator(..., initial={initial!r})"
                )
            guess = as_float_array(
                initial, "initial", expected="expected finite (u, v) px, shape (2,) or (n, 2)"
            )
            if guess.shape == (2,):
                guess = np.broadcast_to(guess, (n, 2))
            k = N_PARAMS[self.shape]
            if k != 2 and guess.shape == (n, k) and np.all(np.isfinite(guess)):
                # all shape parameters (a previous result's params): fewer iterations
                full = np.array(guess)
                guess = full[:, list(uv_columns(k))]
            if guess.shape != (n, 2) or not np.all(np.isfinite(guess)):
                raise InputError(
                    f"initial={describe(guess)}: expected finite (u, v) px, shape (2,) or ({n}, 2)"
                    + ("" if k == 2 else f", or the {k} affine parameters, shape ({n}, {k})")
                )
            gu, gv = guess[:, 0].copy(), guess[:, 1].copy()
            method = "given"
        elif method == "fftcc":
            # one FFT thread: at the 128 px window a second one costs more than it gives
            su, sv, _ = global_shift(
                self._ref, cur, workers=1, reference_spectrum=self._ref_spectrum
            )
            gu = np.full(n, float(su))
            gv = np.full(n, float(sv))
        elif method == "subset":
            iu, iv, _ = subset_fftcc(
                self._ref, cur, self.rows, self.cols, self.half, workers=self.workers
            )
            gu, gv = iu.astype(float), iv.astype(float)
        else:
            gu = np.zeros(n)
            gv = np.zeros(n)
        t2 = time.perf_counter()
        p0 = self._guess_to_params(gu, gv) if full is None else full
        if self.noise_auto:
            self._set_noise(None)  # this pair's noise is not known yet
        self._defer_imprecise, self._deferred = self.shape != "translation", None
        try:
            if method in ("fftcc", "zero") and self._seeds is not None:
                res = self._seeded_icgn(coef, p0, status0)
            else:
                res = self._run_icgn(coef, p0, status0)
        finally:
            self._defer_imprecise = False
        if self.noise_auto:
            self._estimate_noise(res.zncc, res.status)  # the retry skips the imprecise POIs
        self._run_deferred(coef, res)
        t3 = time.perf_counter()
        if method == "fftcc":
            self._retry(cur, coef, gu, gv, res)
        t4 = time.perf_counter()
        self._screen_image = cur  # the unjudged POIs' peak test searches it
        noise_var = self._flag(coef, res)
        t5 = time.perf_counter()
        self.last_timings = {
            "prefilter_s": t1 - t0,
            "initial_s": (t2 - t1) + (t4 - t3),
            "icgn_s": t3 - t2,
            "screen_s": t5 - t4,
            "total_s": t5 - t0,
        }
        info = self._info_base(method)
        info["screen_noise_sigma"] = None if noise_var is None else float(np.sqrt(noise_var))
        info.update(self._noise_info())
        pu, pv = self.predicted_sigma_u, self.predicted_sigma_v
        return self._result(
            res,
            info=info,
            predicted_sigma=(None if pu is None else pu.copy(), None if pv is None else pv.copy()),
        )

    def warmup(self) -> float:
        """Compile (or load from the numba cache) the kernels of this configuration on a
        tiny image and return the seconds it took (the first call's compile time)."""
        t0 = time.perf_counter()
        rng = np.random.default_rng(0)
        img = rng.normal(128.0, 30.0, (self.subset + 12, self.subset + 12))
        s = self.settings  # its geometry and interpolation; the other settings' defaults
        cfg = MatcherSettings(
            subset=s.subset,
            step=s.step,
            shape=s.shape,
            interpolation=s.interpolation,
            initial="zero",
        )
        c = Correlator(img, settings=cfg, workers=self.workers, median_test=self.median_test)
        c.correlate(img)
        if self.blur == "estimate":  # the joint (shape, length) step's kernel too
            e = Correlator(img, settings=cfg, workers=self.workers, blur="estimate")
            e.correlate(img, blur_vector=(0.0, 1.0))
        return time.perf_counter() - t0


def correlate(
    reference: ArrayLike,
    current: ArrayLike,
    *,
    settings: MatcherSettings | None = None,
    subset: int | Unset = UNSET,
    step: int | Unset = UNSET,
    roi: Sequence[int] | None = None,
    points: ArrayLike | None = None,
    shape: Shape | Unset = UNSET,
    interpolation: str | Unset = UNSET,
    initial: str | ArrayLike = "fftcc",
    max_iterations: int | Unset = UNSET,
    tolerance: float | Unset = UNSET,
    noise_sigma: float | Literal["auto"] | None = "auto",
    min_zncc: float | Unset = UNSET,
    workers: int | None = None,
    max_residual: float | Unset | None = UNSET,
    median_test: bool | Unset = UNSET,
    max_predicted_sigma: float | None = MAX_PREDICTED_SIGMA,
) -> DICResult:
    """One-shot subset DIC of ``current`` against ``reference`` (see :class:`Correlator`).

    ``initial`` is a method name (``"fftcc"``, ``"subset"``, ``"zero"``) or an array of
    initial guesses ``(u, v)`` px of shape (n, 2) or (2,).
    """
    method = initial if isinstance(initial, str) else UNSET
    if settings is None and method is UNSET:
        method = "fftcc"
    c = Correlator(
        reference,
        settings=settings,
        subset=subset,
        step=step,
        roi=roi,
        points=points,
        shape=shape,
        interpolation=interpolation,
        initial=method,
        max_iterations=max_iterations,
        tolerance=tolerance,
        noise_sigma=noise_sigma,
        min_zncc=min_zncc,
        workers=workers,
        max_residual=max_residual,
        median_test=median_test,
        max_predicted_sigma=max_predicted_sigma,
    )
    return c.correlate(current, initial=None if isinstance(initial, str) else initial)
