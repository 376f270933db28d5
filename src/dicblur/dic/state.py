"""The prepared state of a :class:`~dicblur.dic.Correlator`, shared by its stages.

The Correlator is built from stages, one module each: the IC-GN passes
(:mod:`.passes`), the screening of their results (:mod:`.screening`) and the
blur-compensated matching (:mod:`.blur_matching`), each a class the Correlator inherits.
:class:`CorrelatorState` declares the attributes ``Correlator.__init__`` prepares (read
only after it, except the scratch buffer, the caches and the timings) and the result
metadata, so every stage sees the same names.
"""

from __future__ import annotations

import time
from collections import OrderedDict
from dataclasses import dataclass
from enum import Enum
from typing import Any, NamedTuple

import numpy as np

from ..arrays import BoolArray, Float32Array, Float64Array, IndexArray, Int64Array, UInt8Array
from . import kernels
from .icgn import PreparedSubsets, uv_columns
from .noise import NoiseEstimate
from .result import DICResult
from .settings import MatcherSettings, check_integer

__all__ = ["UNSET", "CorrelatorState", "PreparedImage", "Refined", "Unset"]


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

    image: Float64Array
    coefficients: Float32Array
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

    params: Float64Array
    zncc: Float64Array
    iterations: Int64Array
    status: UInt8Array


class Unset(Enum):
    """Marks a matcher keyword of :class:`~dicblur.dic.Correlator` that was not given."""

    UNSET = 0


UNSET = Unset.UNSET


class CorrelatorState:
    """Attributes of a prepared Correlator (set by ``Correlator.__init__``)."""

    settings: MatcherSettings
    subset: int
    step: int
    half: int
    shape: str
    interpolation: str
    order: int
    initial: str
    max_iterations: int
    tolerance: float
    min_zncc: float
    noise_sigma: float | None
    noise_auto: bool
    noise: NoiseEstimate | None
    neighbour_check: bool
    max_residual: float | None
    max_predicted_sigma: float | None
    median_test: bool
    workers: int | None
    blur: str
    max_blur_sigma: float
    image_shape: tuple[int, int]
    rows: Int64Array
    cols: Int64Array
    predicted_sigma_u: Float64Array | None
    predicted_sigma_v: Float64Array | None
    last_timings: dict[str, float]
    prepare_time_s: float
    _grid_shape: tuple[int, int] | None
    _grid_index: IndexArray | None
    _prep: PreparedSubsets
    _status0: UInt8Array
    _ref: Float64Array
    _ref_grad: tuple[Float64Array, Float64Array]
    _screen_image: Float64Array | None
    _tw: int
    _w: int
    _images: kernels.ReferenceImages
    _subsets: kernels.Subsets
    _packed: kernels.Packed
    _coef_buf: Float32Array
    _all: IndexArray
    _none: IndexArray
    _args_cache: dict[int, Any]
    _split_cache: dict[int, Any]
    _split_ids: set[int]
    _seeds: IndexArray | None
    _rest: IndexArray | None
    _rest_seed: IndexArray
    _imprecise: BoolArray | None
    _unit_sigma: Float64Array | None
    _blur_cache: OrderedDict[tuple[Any, ...], Any]
    _last_blur_length: float | None

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
    def grid_cells(self) -> IndexArray | None:
        """Row-major grid cell of each POI (n,), or None (see :attr:`grid_shape`)."""
        return None if self._grid_index is None else self._grid_index.copy()

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

    def _result(
        self,
        res: kernels.Outputs,
        *,
        info: dict[str, Any],
        predicted_sigma: tuple[Float64Array | None, Float64Array | None],
        blur: tuple[Float64Array, Float64Array, BoolArray] | None = None,
    ) -> DICResult:
        """The :class:`DICResult` of all POIs from their IC-GN results ``res`` (``u``, ``v``
        the translation columns of its parameters; ``blur``: ``blur="estimate"``'s
        ``blur_length``, ``blur_sigma``, ``blur_identified``)."""
        ucol, vcol = uv_columns(res.p.shape[1])
        length, sigma, identified = (None, None, None) if blur is None else blur
        return DICResult(
            rows=self.rows.copy(),
            cols=self.cols.copy(),
            u=res.p[:, ucol].copy(),
            v=res.p[:, vcol].copy(),
            params=res.p,
            zncc=res.zncc,
            iterations=res.iterations,
            status=res.status,
            predicted_sigma_u=predicted_sigma[0],
            predicted_sigma_v=predicted_sigma[1],
            info=info,
            blur_length=length,
            blur_sigma=sigma,
            blur_identified=identified,
        )

    def fork(self, *, workers: int | Unset | None = UNSET) -> Any:
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
        new = object.__new__(type(self))
        new.__dict__.update(self.__dict__)
        if workers is not UNSET:
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
