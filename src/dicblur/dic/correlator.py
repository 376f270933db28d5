"""The subset DIC engine: a prepared reference correlated against current images.

Pipeline per current image (one module per stage): B-spline prefilter
(:mod:`.interpolation`), integer initial guess (:mod:`.initial`), IC-GN refinement with the
ZNSSD criterion (:mod:`.icgn`, compiled in :mod:`.kernels`), result (:mod:`.result`).
"""

from __future__ import annotations

import math
import time
from collections import OrderedDict
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, replace
from enum import Enum
from typing import Any, Literal, NamedTuple

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..checks import (
    as_image,
    check_choice,
    check_positive,
    check_subset_fits,
    check_textured,
    describe,
)
from ..errors import InputError
from ..metrics import image_gradients, subset_centres
from . import cache, kernels
from .compensation import (
    BLUR_MODES,
    blur_reference,
    check_blur_vector,
    noise_gain_slope,
    prepare_blur_step,
)
from .icgn import N_PARAMS, prepare_subsets
from .initial import global_shift, subset_fftcc, window_spectrum
from .interpolation import PAD, bspline_coefficients, bspline_gradients
from .outliers import MEDIAN_EPS, MEDIAN_THRESHOLD, median_screen, neighbour_medians
from .result import DICResult
from .settings import INITIAL_METHODS, SHAPES, MatcherSettings, Shape, check_integer
from .status import PointStatus

__all__ = ["INITIAL_METHODS", "SHAPES", "Correlator", "PreparedImage", "correlate"]

BlurMode = Literal["none", "given", "estimate"]


class _Unset(Enum):
    """Marks a matcher keyword of :class:`Correlator` that was not given."""

    UNSET = 0


_UNSET = _Unset.UNSET

_RETRY = (
    PointStatus.MAX_ITERATIONS,
    PointStatus.DIVERGED,
    PointStatus.LOW_CORRELATION,
    PointStatus.OUT_OF_BOUNDS,
)
#: A retried POI gets at most this many times the median iterations of the converged POIs
#: (at least 10): a subset that failed once rarely needs the full ``max_iterations``.
RETRY_BUDGET = 4
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

    corr: Correlator
    index: NDArray[np.intp] | None
    vector: NDArray[np.float64]
    step: Any = None
    images: tuple[NDArray[np.float64], ...] = ()


@dataclass(frozen=True, eq=False)
class PreparedImage:
    """A deformed image with its B-spline coefficients (:meth:`Correlator.prefilter`).

    Attributes
    ----------
    image : ndarray, shape (rows, cols)
        The image, float64 grey levels.
    coefficients : ndarray of float32, shape (rows + 2 PAD, cols + 2 PAD + margin)
        Its prefiltered coefficients in the Correlator's padded layout (read only by
        the kernels).
    order : int
        B-spline degree (3 or 5).
    """

    image: NDArray[np.float64]
    coefficients: NDArray[np.float32]
    order: int


class Refined(NamedTuple):
    """IC-GN results of :meth:`Correlator.refine` (n POIs, k shape parameters).

    Attributes
    ----------
    params : ndarray, shape (n, k)
        As :attr:`DICResult.params` (px; affine gradients dimensionless).
    zncc : ndarray, shape (n,)
    iterations : ndarray of int64, shape (n,)
    status : ndarray of uint8, shape (n,)
        :class:`PointStatus` codes.
    """

    params: NDArray[np.float64]
    zncc: NDArray[np.float64]
    iterations: NDArray[np.int64]
    status: NDArray[np.uint8]


class Correlator:
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
    noise_sigma : float, optional
        Image noise std, grey levels (assumed in both images); enables the per-point
        predicted sigma.
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
        subset: int | _Unset = _UNSET,
        step: int | _Unset = _UNSET,
        roi: Sequence[int] | None = None,
        points: ArrayLike | None = None,
        shape: Shape | _Unset = _UNSET,
        interpolation: str | _Unset = _UNSET,
        initial: str | _Unset = _UNSET,
        max_iterations: int | _Unset = _UNSET,
        tolerance: float | _Unset = _UNSET,
        noise_sigma: float | None = None,
        min_zncc: float | _Unset = _UNSET,
        workers: int | None = None,
        max_residual: float | _Unset | None = _UNSET,
        median_test: bool | _Unset = _UNSET,
        blur: BlurMode = "none",
        max_blur_sigma: float = 0.5,
        max_predicted_sigma: float | None = MAX_PREDICTED_SIGMA,
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
            if v is not _UNSET
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
        self.noise_sigma = (
            None
            if noise_sigma is None
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

        rows, cols, status0 = self.layout(
            self.image_shape, subset=self.subset, step=self.step, roi=roi, points=points
        )
        self.rows = rows
        self.cols = cols
        self._grid_shape, self._grid_index = self._grid_of(rows, cols, required=bool(median_test))
        #: Whether :meth:`correlate` screens the grid for ``OUTLIER`` points.
        self.median_test = bool(median_test)
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
        self.predicted_sigma_u: NDArray[np.float64] | None = None
        self.predicted_sigma_v: NDArray[np.float64] | None = None
        if self.noise_sigma is not None:
            # predicted sigma from the project's SSSIG (central differences, as
            # dicblur.metrics.sssig): see docs/dic.md for why not the spline gradients
            cgy, cgx = image_gradients(ref)
            pp = prepare_subsets(ref, cgx, cgy, rc, cc, half, self.shape)
            s2 = self.noise_sigma**2
            with np.errstate(divide="ignore", invalid="ignore"):
                if self.shape == "translation":
                    pu = np.sqrt(2.0 * s2 / pp.sssig_x)
                    pv = np.sqrt(2.0 * s2 / pp.sssig_y)
                else:
                    pu = np.sqrt(s2 * pp.cov_unit[:, 0, 0])
                    pv = np.sqrt(s2 * pp.cov_unit[:, 3, 3])
            bad = status0 != 0
            self.predicted_sigma_u = np.where(bad, np.nan, pu)
            self.predicted_sigma_v = np.where(bad, np.nan, pv)
        #: POIs whose predicted random error exceeds ``max_predicted_sigma`` (or None).
        self._imprecise: NDArray[np.bool_] | None = None
        pu_, pv_ = self.predicted_sigma_u, self.predicted_sigma_v
        if pu_ is not None and pv_ is not None and self.max_predicted_sigma is not None:
            with np.errstate(invalid="ignore"):
                imp = np.hypot(pu_, pv_) > self.max_predicted_sigma
            self._imprecise = imp if imp.any() else None
        # blur compensation: prepared blurred references by (blur vector, point set)
        self._blur_cache: OrderedDict[tuple[Any, ...], _BlurredReference] = OrderedDict()
        self._last_blur_length: float | None = None
        self.prepare_time_s = time.perf_counter() - t0
        #: Timings (s) of the last :meth:`correlate` call: prefilter, initial, icgn, total.
        self.last_timings: dict[str, float] = {}

    def fork(self, *, workers: int | _Unset | None = _UNSET) -> Correlator:
        """A Correlator on this one's prepared reference, with its own scratch state, for
        another thread.

        The prepared reference (B-spline gradients, per-subset Hessians, POIs, predicted
        errors) is read-only after ``__init__`` and shared, not copied; the fork gets its
        own coefficient buffer (``correlate`` of an unprepared image writes it), its own
        caches and timings. So this Correlator and its forks may correlate on different
        threads at the same time, each with exactly the results of a Correlator built
        anew with the same arguments (tests/test_dic.py). A fork costs about 1 MB and a
        few microseconds (a 512^2 reference with 2,401 POIs takes ~0.3 s to prepare).

        Parameters
        ----------
        workers : int or None, optional
            Threads of the fork's compiled kernels (default: this Correlator's).

        Returns
        -------
        Correlator

        Examples
        --------
        >>> import numpy as np, dicblur
        >>> ref = dicblur.speckle_pattern((96, 96), speckle_size=4, seed=1)
        >>> corr = dicblur.Correlator(ref, subset=21, step=20)
        >>> one = corr.fork(workers=1)  # e.g. one per thread of a pool
        >>> bool(np.array_equal(one.correlate(ref).u, corr.correlate(ref).u))
        True
        """
        t0 = time.perf_counter()
        new = object.__new__(Correlator)
        new.__dict__.update(self.__dict__)
        if workers is not _UNSET:
            new.workers = None if workers is None else check_integer(workers, "workers", 1)
        # the mutable state: scratch buffer, caches (their entries are read-only and keyed
        # by the shared index arrays, so they are carried over), timings, blur references
        new._coef_buf = np.zeros_like(self._coef_buf)
        new._args_cache = dict(self._args_cache)
        new._split_cache = dict(self._split_cache)
        new._split_ids = set(self._split_ids)
        new._blur_cache = OrderedDict()
        new._last_blur_length = None
        new.last_timings = {}
        new.prepare_time_s = time.perf_counter() - t0
        return new

    # ------------------------------------------------------------------ setup helpers
    @staticmethod
    def layout(
        image_shape: tuple[int, int],
        *,
        subset: int,
        step: int,
        roi: Sequence[int] | None = None,
        points: ArrayLike | None = None,
    ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.uint8]]:
        """The POIs a Correlator on an image of ``image_shape`` lays out, without
        preparing it: ``(rows, cols, status)``, each shape (n,), ``status``
        ``OUT_OF_BOUNDS`` for given ``points`` whose subset leaves the image, else 0.

        ``subset`` (odd, px) and ``step`` (px) as validated by
        :class:`~dicblur.dic.MatcherSettings`; ``roi`` and ``points`` as for the
        constructor (the grid of ``step`` px inside ``roi`` or the whole image, or the
        given centres).
        """
        rows_img, cols_img = (int(image_shape[0]), int(image_shape[1]))
        half = subset // 2
        if points is not None:
            pts = np.asarray(points)
            if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] == 0:
                raise InputError(
                    f"points={describe(pts)}: expected an (n, 2) array of "
                    "(row, col) POI centres, n >= 1"
                )
            if not np.issubdtype(pts.dtype, np.integer):
                if not np.all(np.isfinite(pts)) or not np.all(pts == np.round(pts)):
                    raise InputError(
                        f"points={describe(pts)}: POI centres must be integer "
                        "pixel positions (round them first)"
                    )
            pts = pts.astype(np.int64)
            r, c = pts[:, 0].copy(), pts[:, 1].copy()
            inside = (
                (r - half >= 0)
                & (r + half <= rows_img - 1)
                & (c - half >= 0)
                & (c + half <= cols_img - 1)
            )
            st = np.where(inside, 0, int(PointStatus.OUT_OF_BOUNDS)).astype(np.uint8)
            return r, c, st
        r0, r1, c0, c1 = 0, rows_img, 0, cols_img
        if roi is not None:
            try:
                r0, r1, c0, c1 = (int(x) for x in roi)
            except (TypeError, ValueError) as exc:
                raise InputError(
                    f"roi={describe(roi)}: expected (row_start, row_stop, "
                    "col_start, col_stop) in px"
                ) from exc
            if not (0 <= r0 < r1 <= rows_img and 0 <= c0 < c1 <= cols_img):
                raise InputError(
                    f"roi={describe(roi)}: must satisfy 0 <= row_start < "
                    f"row_stop <= {rows_img} and 0 <= col_start < col_stop <= "
                    f"{cols_img}"
                )
        if min(r1 - r0, c1 - c0) < subset + 2:
            raise InputError(
                f"roi={describe(roi)}: region smaller than the subset "
                f"({subset} px) plus a 1-px border; enlarge it"
            )
        centres = subset_centres((r1 - r0, c1 - c0), subset=subset, step=step)
        r = centres[:, 0].astype(np.int64) + r0
        c = centres[:, 1].astype(np.int64) + c0
        return r, c, np.zeros(len(r), np.uint8)

    @staticmethod
    def _grid_of(
        rows: NDArray[np.int64], cols: NDArray[np.int64], *, required: bool
    ) -> tuple[tuple[int, int] | None, NDArray[np.intp] | None]:
        """Shape of the POI grid and each POI's row-major cell, when the POIs fill one."""
        ur, ri = np.unique(rows, return_inverse=True)
        uc, ci = np.unique(cols, return_inverse=True)
        cell = ri.astype(np.intp) * len(uc) + ci.astype(np.intp)
        if len(rows) == len(ur) * len(uc) and np.unique(cell).size == len(rows):
            return (len(ur), len(uc)), cell
        if required:
            raise InputError(
                f"median_test=True: the {len(rows)} points do not fill a "
                f"regular grid ({len(ur)} rows x {len(uc)} columns of centres)"
                "; use median_test=False or a full grid of points"
            )
        return None, None

    def _setup_seeds(self) -> None:
        """Two-pass start: IC-GN first on sparse seed POIs (about 1 in 16), then every other
        POI starts from its nearest seed's warp carried to its own centre. A start within a
        few hundredths of a px saves about one IC-GN iteration per POI (Pan et al. 2013 use
        the same idea along a reliability path)."""
        n = self.n_points
        self._seeds: NDArray[np.intp] | None = None
        self._rest: NDArray[np.intp] | None = None
        if n < 64:
            return
        from scipy.spatial import cKDTree

        spacing = 4 * self.step
        key = (self.rows // spacing) * 100003 + (self.cols // spacing)
        _, first = np.unique(key, return_index=True)
        seeds = np.sort(first)
        rest = np.setdiff1d(np.arange(n), seeds)
        if seeds.size == 0 or rest.size == 0:
            return
        tree = cKDTree(np.stack([self.rows[seeds], self.cols[seeds]], axis=1))
        _, near = tree.query(np.stack([self.rows[rest], self.cols[rest]], axis=1))
        self._seeds = seeds
        self._rest = rest
        self._rest_seed = seeds[np.asarray(near, dtype=np.intp)]

    #: Largest flat reference copy (bytes) kept for the translation kernel; above it the
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

    def _settings(self, width: int, max_iter: int | None) -> kernels.Settings:
        """The kernels' scalar record (``max_iter`` None: ``max_iterations``)."""
        return kernels.settings(
            self.image_shape[0],
            self.image_shape[1],
            self.order,
            self.half,
            width,
            self.max_iterations if max_iter is None else max_iter,
            self.tolerance,
            self.min_zncc,
            float(self.subset),
        )

    @property
    def n_points(self) -> int:
        """Number of POIs."""
        return int(self.rows.shape[0])

    @property
    def grid_shape(self) -> tuple[int, int] | None:
        """``(rows, cols)`` of the POI grid, or None when the POIs do not fill one.

        The Correlator's own grid lists its POIs in row-major order, so result arrays
        reshape to this shape (e.g. for :func:`~dicblur.dic.normalized_median_test`); for
        explicit ``points`` use :attr:`grid_cells`.
        """
        return self._grid_shape

    @property
    def grid_cells(self) -> NDArray[np.intp] | None:
        """Row-major grid cell of each POI (n,), or None (see :attr:`grid_shape`)."""
        return None if self._grid_index is None else self._grid_index.copy()

    # ------------------------------------------------------------------ correlation
    def _translation(
        self,
        coef: NDArray[np.float32],
        p0: NDArray[np.float64],
        status_in: NDArray[np.uint8],
        first: NDArray[np.intp],
        second: NDArray[np.intp],
        source: NDArray[np.intp],
        max_iter: int | None = None,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64], NDArray[np.uint8]]:
        """Translation kernel on all POIs' arrays (n,): ``first`` from ``p0``, then
        ``second`` from their ``source`` POI's result (see kernels.icgn_translation)."""
        out = kernels.outputs(self.n_points, 2)
        cache.wait_for_background("translation")
        kernels.icgn_translation(
            coef,
            self._images,
            self._subsets,
            self._packed,
            self._settings(self._w, max_iter),
            p0,
            status_in,
            kernels.Passes(first, second, source),
            numba.config.NUMBA_NUM_THREADS,  # type: ignore[attr-defined]
            out,
        )
        return out.p, out.zncc, out.iterations, out.status

    def _run_icgn(
        self,
        coef: NDArray[np.float32],
        p0: NDArray[np.float64],
        status_in: NDArray[np.uint8],
        idx: NDArray[np.intp] | None = None,
        max_iter: int | None = None,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64], NDArray[np.uint8]]:
        if self.shape == "translation":
            full = np.zeros((self.n_points, 2))
            st_full = np.zeros(self.n_points, np.uint8)
            sel = self._all if idx is None else idx
            full[sel] = p0
            st_full[sel] = status_in
            out = self._translation(coef, full, st_full, sel, self._none, self._none, max_iter)
            return out if idx is None else tuple(a[idx] for a in out)  # type: ignore[return-value]
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
            self._settings(self._tw, max_iter),
            np.ascontiguousarray(p0),
            np.ascontiguousarray(status_in),
            out,
        )
        return out.p, out.zncc, out.iterations, out.status

    def _imprecise_split(
        self, idx: NDArray[np.intp] | None
    ) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.intp], NDArray[np.intp]] | None:
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
        coef: NDArray[np.float32],
        p0: NDArray[np.float64],
        status_in: NDArray[np.uint8],
        idx: NDArray[np.intp] | None,
        split: tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.intp], NDArray[np.intp]],
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64], NDArray[np.uint8]]:
        """Affine IC-GN, the predicted-imprecise POIs after the precise ones, within
        IMPRECISE_BUDGET times the median iterations of the precise converged POIs."""
        loc_p, pts_p, loc_i, pts_i = split
        n = len(self.rows) if idx is None else len(idx)
        k = p0.shape[1]
        out_p = np.empty((n, k))
        out_z = np.empty(n)
        out_i = np.empty(n, np.int64)
        out_s = np.empty(n, np.uint8)
        cap = self.max_iterations
        if loc_p.size:
            r = self._run_icgn(coef, p0[loc_p], status_in[loc_p], pts_p, cap)
            out_p[loc_p], out_z[loc_p], out_i[loc_p], out_s[loc_p] = r
            conv = r[2][r[3] == PointStatus.CONVERGED]
            if conv.size:
                budget = math.ceil(IMPRECISE_BUDGET * float(np.median(conv)))
                cap = min(cap, max(IMPRECISE_MIN, budget))
        r = self._run_icgn(coef, p0[loc_i], status_in[loc_i], pts_i, cap)
        out_p[loc_i], out_z[loc_i], out_i[loc_i], out_s[loc_i] = r
        return out_p, out_z, out_i, out_s

    def _seeded_icgn(
        self, coef: NDArray[np.float32], p0: NDArray[np.float64], status0: NDArray[np.uint8]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64], NDArray[np.uint8]]:
        assert self._seeds is not None and self._rest is not None
        seeds, rest, src = self._seeds, self._rest, self._rest_seed
        if self.shape == "translation":
            # both passes in one kernel call: the rest start from their seed's result
            return self._translation(coef, p0, status0, seeds, rest, src)
        n, k = p0.shape
        p = np.empty((n, k))
        z = np.empty(n)
        it = np.empty(n, np.int64)
        st = np.empty(n, np.uint8)
        ps, zs, its, sts = self._run_icgn(coef, p0[seeds], status0[seeds], seeds)
        p[seeds], z[seeds], it[seeds], st[seeds] = ps, zs, its, sts
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
        pr, zr, itr, str_ = self._run_icgn(coef, start, status0[rest], rest)
        p[rest], z[rest], it[rest], st[rest] = pr, zr, itr, str_
        return p, z, it, st

    def _guess_to_params(
        self, u: NDArray[np.float64], v: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        k = N_PARAMS[self.shape]
        p0 = np.zeros((len(u), k))
        p0[:, 0] = u
        p0[:, 1 if k == 2 else 3] = v
        return p0

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

    def _coefficients_into(self, cur: NDArray[np.float64], buf: NDArray[np.float32]) -> None:
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
        p0 = np.asarray(start, dtype=np.float64)
        if p0.shape == (n, 2) and k != 2:
            p0 = self._guess_to_params(p0[:, 0], p0[:, 1])
        if p0.shape != (n, k) or not np.isfinite(p0).all():
            raise InputError(
                f"start={describe(p0)}: expected finite (u, v) px, shape ({n}, 2)"
                + ("" if k == 2 else f", or the {k} affine parameters, shape ({n}, {k})")
            )
        coef = current.coefficients
        with self._kernel_threads():
            p, z, it, st = self._run_icgn(coef, p0, self._status0)
            self._flag(coef, p, z, st)
        return Refined(p, z, it, st)

    def _checked(self, current: ArrayLike) -> NDArray[np.float64]:
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
        coef: NDArray[np.float32] | None = None
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
        cur: NDArray[np.float64],
        initial: ArrayLike | None,
        prepared: NDArray[np.float32] | None = None,
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
        full: NDArray[np.float64] | None = None
        if initial is not None:
            guess = np.asarray(initial, dtype=np.float64)
            if guess.shape == (2,):
                guess = np.broadcast_to(guess, (n, 2))
            k = N_PARAMS[self.shape]
            if k != 2 and guess.shape == (n, k) and np.all(np.isfinite(guess)):
                # all shape parameters (a previous result's params): fewer iterations
                full = np.array(guess)
                guess = full[:, [0, 3]]
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
        if method in ("fftcc", "zero") and self._seeds is not None:
            p, z, it, st = self._seeded_icgn(coef, p0, status0)
        else:
            p, z, it, st = self._run_icgn(coef, p0, status0)
        t3 = time.perf_counter()
        if method == "fftcc":
            self._retry(cur, coef, gu, gv, p, z, it, st)
        t4 = time.perf_counter()
        noise_var = self._flag(coef, p, z, st)
        t5 = time.perf_counter()
        self.last_timings = {
            "prefilter_s": t1 - t0,
            "initial_s": (t2 - t1) + (t4 - t3),
            "icgn_s": t3 - t2,
            "screen_s": t5 - t4,
            "total_s": t5 - t0,
        }
        k = p.shape[1]
        u = p[:, 0].copy()
        v = p[:, 1 if k == 2 else 3].copy()
        info = self._info_base(method)
        info["screen_noise_sigma"] = None if noise_var is None else float(np.sqrt(noise_var))
        return DICResult(
            rows=self.rows.copy(),
            cols=self.cols.copy(),
            u=u,
            v=v,
            params=p,
            zncc=z,
            iterations=it,
            status=st,
            predicted_sigma_u=None
            if self.predicted_sigma_u is None
            else self.predicted_sigma_u.copy(),
            predicted_sigma_v=None
            if self.predicted_sigma_v is None
            else self.predicted_sigma_v.copy(),
            info=info,
        )

    def _flag(
        self,
        coef: NDArray[np.float32],
        p: NDArray[np.float64],
        z: NDArray[np.float64],
        st: NDArray[np.uint8],
    ) -> float | None:
        """The statuses after IC-GN, in place: :meth:`_screen`, then ``IMPRECISE``;
        returns the screen's noise variance (or None)."""
        noise_var = self._screen(coef, p, z, st)
        if self._imprecise is not None:
            # a predicted-imprecise subset stopped at its (reduced) limit: imprecision is the
            # cause, so it gets that status too
            done = (st == PointStatus.CONVERGED) | (st == PointStatus.MAX_ITERATIONS)
            st[done & self._imprecise] = PointStatus.IMPRECISE
        return noise_var

    def _retry(
        self,
        cur: NDArray[np.float64],
        coef: NDArray[np.float32],
        gu: NDArray[np.float64],
        gv: NDArray[np.float64],
        p: NDArray[np.float64],
        z: NDArray[np.float64],
        it: NDArray[np.int64],
        st: NDArray[np.uint8],
    ) -> None:
        """Second chance for the failed POIs, in place, within an iteration budget.

        A POI with converged grid neighbours restarts from their median parameters (a
        start near the local field, one compiled call for all); the others get the
        per-subset FFT-CC integer guess, unless it equals the start they already had.
        """
        status0 = self._status0
        again = np.isin(st, _RETRY) & (status0 == 0)
        if self._imprecise is not None:
            # flagged IMPRECISE even if a retry converged: not worth a second attempt
            again &= ~self._imprecise
        retry = np.flatnonzero(again)
        if retry.size == 0:
            return
        ok = st == PointStatus.CONVERGED
        conv = it[ok]
        budget = (
            self.max_iterations
            if conv.size == 0
            else min(self.max_iterations, max(10, RETRY_BUDGET * int(np.median(conv))))
        )
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

    def _screen(
        self,
        coef: NDArray[np.float32],
        p: NDArray[np.float64],
        z: NDArray[np.float64],
        st: NDArray[np.uint8],
    ) -> float | None:
        """Flag false convergence in place: ``HIGH_RESIDUAL``, then ``OUTLIER``.

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
        ok = st == PointStatus.CONVERGED
        residual = self.max_residual is not None and self.noise_sigma is not None
        if not ok.any() or not (residual or self.median_test):
            return None
        k = p.shape[1]
        fnorm2 = self._prep.fnorm**2
        m = self.subset * self.subset - k - 2
        unit = np.maximum(1.0 - z, 0.0) * fnorm2 / m
        noise_var = float(np.median(unit[ok]))
        if self.noise_sigma is not None:
            noise_var = max(noise_var, self.noise_sigma**2)
        if self.max_residual is not None and self.noise_sigma is not None and noise_var > 0:
            high = ok & (unit > self.max_residual * noise_var)
            st[high] = PointStatus.HIGH_RESIDUAL
            ok &= ~high
        if not self.median_test or self._grid_shape is None or not ok.any():
            return noise_var
        assert self._grid_index is not None
        shape, cell = self._grid_shape, self._grid_index
        ucol, vcol = 0, 1 if k == 2 else 3
        # (k, ny, nx) with u, v first: the components the median test looks at
        order = [ucol, vcol] + [j for j in range(k) if j not in (ucol, vcol)]
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

    # ------------------------------------------------------------------ blur compensation
    def _blurred(
        self,
        vec: NDArray[np.float64],
        index: NDArray[np.intp] | None,
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
        corr = Correlator(
            blurred,
            subset=self.subset,
            step=self.step,
            points=pts,
            shape=self.shape,  # type: ignore[arg-type]
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
        images: tuple[NDArray[np.float64], ...] = ()
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
    def _initial_for(
        initial: ArrayLike | None, index: NDArray[np.intp], n: int
    ) -> ArrayLike | None:
        if initial is None:
            return None
        arr = np.asarray(initial, dtype=np.float64)
        return arr[index] if arr.shape == (n, 2) else arr

    def _blur_info(self, res: DICResult, **extra: Any) -> DICResult:
        info = dict(self._info_base(res.info.get("initial", self.initial)))
        info.update(extra)
        return replace(res, info=info)

    def _info_base(self, method: str) -> dict[str, Any]:
        from .._version import __version__

        return {
            "subset": self.subset,
            "step": self.step,
            "shape": self.shape,
            "interpolation": self.interpolation,
            "initial": method,
            "max_iterations": self.max_iterations,
            "tolerance": self.tolerance,
            "noise_sigma": self.noise_sigma,
            "min_zncc": self.min_zncc,
            "max_residual": self.max_residual,
            "max_predicted_sigma": self.max_predicted_sigma,
            "median_test": int(self.median_test),
            "image_shape": f"{self.image_shape[0]}x{self.image_shape[1]}",
            "grid_shape": (
                None if self._grid_shape is None else f"{self._grid_shape[0]}x{self._grid_shape[1]}"
            ),
            "dicblur_version": __version__,
        }

    def _correlate_given(
        self, cur: NDArray[np.float64], initial: ArrayLike | None, vec: NDArray[np.float64]
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
        return DICResult(
            rows=self.rows.copy(),
            cols=self.cols.copy(),
            u=p[:, 0].copy(),
            v=p[:, 1 if k == 2 else 3].copy(),
            params=p,
            zncc=z,
            iterations=it,
            status=st,
            predicted_sigma_u=pu,
            predicted_sigma_v=pv,
            info=info,
        )

    def _blur_direction(
        self, blur_vector: ArrayLike | None, blur_angle: float | None
    ) -> tuple[NDArray[np.float64], float | None]:
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
        self, entry: _BlurredReference, cur_corr: Correlator, res: DICResult, max_iter: int = 10
    ) -> tuple[
        NDArray[np.float64],
        NDArray[np.float64],
        NDArray[np.float64],
        NDArray[np.float64],
        NDArray[np.int64],
        NDArray[np.uint8],
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
        cur: NDArray[np.float64],
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
        k = p.shape[1]
        length = np.where(np.isfinite(lam), w0 + lam, np.nan)
        self.last_timings = {"total_s": time.perf_counter() - t0}
        info = self._info_base(base.info.get("initial", self.initial))
        info.update(
            blur_compensation="estimate",
            blur_dir_dy=float(e[0]),
            blur_dir_dx=float(e[1]),
            blur_w0=w0,
        )
        return DICResult(
            rows=self.rows.copy(),
            cols=self.cols.copy(),
            u=p[:, 0].copy(),
            v=p[:, 1 if k == 2 else 3].copy(),
            params=p,
            zncc=z,
            iterations=base.iterations + its,
            status=st,
            predicted_sigma_u=base.predicted_sigma_u,
            predicted_sigma_v=base.predicted_sigma_v,
            info=info,
            blur_length=length,
            blur_sigma=sig,
            blur_identified=identified,
        )

    def warmup(self) -> float:
        """Compile (or load from the numba cache) the kernels of this configuration on a
        tiny image and return the seconds it took (the first call's compile time)."""
        t0 = time.perf_counter()
        rng = np.random.default_rng(0)
        img = rng.normal(128.0, 30.0, (self.subset + 12, self.subset + 12))
        c = Correlator(
            img,
            subset=self.subset,
            step=self.step,
            shape=self.shape,  # type: ignore[arg-type]
            interpolation=self.interpolation,
            initial="zero",
            workers=self.workers,
            median_test=self.median_test,
        )
        c.correlate(img)
        if self.blur == "estimate":  # the joint (shape, length) step's kernel too
            e = Correlator(
                img,
                subset=self.subset,
                step=self.step,
                shape=self.shape,  # type: ignore[arg-type]
                interpolation=self.interpolation,
                initial="zero",
                workers=self.workers,
                blur="estimate",
            )
            e.correlate(img, blur_vector=(0.0, 1.0))
        return time.perf_counter() - t0


def correlate(
    reference: ArrayLike,
    current: ArrayLike,
    *,
    settings: MatcherSettings | None = None,
    subset: int | _Unset = _UNSET,
    step: int | _Unset = _UNSET,
    roi: Sequence[int] | None = None,
    points: ArrayLike | None = None,
    shape: Shape | _Unset = _UNSET,
    interpolation: str | _Unset = _UNSET,
    initial: str | ArrayLike = "fftcc",
    max_iterations: int | _Unset = _UNSET,
    tolerance: float | _Unset = _UNSET,
    noise_sigma: float | None = None,
    min_zncc: float | _Unset = _UNSET,
    workers: int | None = None,
    max_residual: float | _Unset | None = _UNSET,
    median_test: bool | _Unset = _UNSET,
    max_predicted_sigma: float | None = MAX_PREDICTED_SIGMA,
) -> DICResult:
    """One-shot subset DIC of ``current`` against ``reference`` (see :class:`Correlator`).

    ``initial`` is a method name (``"fftcc"``, ``"subset"``, ``"zero"``) or an array of
    initial guesses ``(u, v)`` px of shape (n, 2) or (2,).
    """
    method = initial if isinstance(initial, str) else _UNSET
    if settings is None and method is _UNSET:
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
