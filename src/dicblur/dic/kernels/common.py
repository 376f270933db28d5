"""Constants and inlined helpers shared by the compiled DIC kernels."""

from __future__ import annotations

import math
import os
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any, NamedTuple

import numba as nb
import numpy as np

from ...arrays import Float32Array, Float64Array, IndexArray, Int64Array, UInt8Array
from ..status import PointStatus

# The translation IC-GN's parfor runs on numba's OpenMP layer, whose GNU runtime by default
# keeps each worker spinning ~10 ms after every parallel region: 11 ms of CPU per call on
# 2 cores whatever the POI count (14 POIs: 12.7 ms CPU, 25 ms wall on a loaded machine;
# passive: 0.04 ms), which also took the core from the thread doing the work. Passive
# waiting (sleep at once, woken in tens of us) unless the user set a policy; read by
# libgomp when numba loads its OpenMP pool, at the first parallel call (benchmarks/
# bench_screening.py, issue 26).
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

__all__ = [
    "CONVERGED",
    "DIVERGED",
    "FASTMATH",
    "GAIN_MIN",
    "JUMP_SLACK",
    "LOW_CORRELATION",
    "MAX_ITERATIONS",
    "OUT_OF_BOUNDS",
    "PAD",
    "STALL_ITERATIONS",
    "Outputs",
    "Packed",
    "Passes",
    "ReferenceImages",
    "Settings",
    "Subsets",
    "add_row",
    "blocks_of",
    "centred_norm",
    "compose_inverse_affine",
    "example_args",
    "run_blocks",
    "threads",
]

#: Margin (px) of mirrored coefficients around the image (quintic needs 3 taps + 1).
PAD = 4

CONVERGED = int(PointStatus.CONVERGED)
MAX_ITERATIONS = int(PointStatus.MAX_ITERATIONS)
OUT_OF_BOUNDS = int(PointStatus.OUT_OF_BOUNDS)
DIVERGED = int(PointStatus.DIVERGED)
LOW_CORRELATION = int(PointStatus.LOW_CORRELATION)
#: IC-GN stops (status ``MAX_ITERATIONS``) when the update norm has not reached a new
#: minimum for this many iterations: a converging subset, even one shrinking by 0.97 per
#: iteration, sets a new minimum every iteration; an oscillating or wandering one (a false
#: or flat optimum) would otherwise spend all of ``max_iterations``.
STALL_ITERATIONS = 8
#: Stop on the estimated error left (issues 15, 17). When the Gauss-Newton steps contract
#: by ``q = |d| / |d_prev|`` per iteration (``d_prev`` the previous plain step), the error
#: left in the parameters after ``d`` is about ``|d| q / (1 - q)`` (the rest of a geometric
#: series of steps; the a-posteriori bound of a contraction, conservative for the faster,
#: superlinear first steps of a clean speckle): IC-GN stops when that is below the
#: tolerance, or when ``|d|`` itself is. An aligned step (cos > 0.95, contraction rho >
#: ``GAIN_MIN``) is an Aitken jump ``d / (1 - rho)`` to the limit of the series, which
#: removes the aligned part of that error: after a jump the bound need only be below
#: ``JUMP_SLACK`` x the tolerance. Measured on blurred tracking frames (W ~ 2.5 px, steps
#: contracting by 0.25-0.3, issue 17): slack 1, 3 and 6 leave the same distance to the
#: converged (tolerance 1e-9) solution (rms 1.6e-5 px, 99th percentile 7.5e-5 px) and
#: 2.53, 2.40 and 2.37 iterations from a 0.01 px start; the old rule (the bound only for
#: q > 0.03, slack 1) took 2.66 iterations and left rms 3.1e-5 px.
JUMP_SLACK = 4.0
#: Steps of a subset converging linearly by an aligned factor rho > GAIN_MIN are scaled by
#: ``1 / (1 - rho)`` (Aitken's delta-squared jump to the limit of the series): the rate
#: 0.1-0.3 of blob subsets gains (from 0.3, as first set for blurred images, 4.24 -> 4.07
#: iterations per converging blob POI).
GAIN_MIN = 0.1

# Fast-math flags of the kernels: no "nnan"/"ninf" (the status tests `not dg2 > ...`,
# `math.isfinite(u)` must see NaN and inf). "reassoc" stays: without it LLVM cannot
# vectorise the IC-GN reductions (affine 43k -> 179k POI per CPU-s, translation 299k ->
# 455k, 512^2, subset 21, one thread). A reassociated reduction compiled in one process and
# the same kernel loaded from numba's cache can differ in the last bits, so every process
# of a campaign runs cached code: run_campaign compiles a cold cache in a subprocess first
# (dicblur.dic.cache.compile_kernels), which keeps resumed campaigns bit-identical.
FASTMATH = {"contract", "arcp", "nsz", "reassoc", "afn"}  # a set: numba takes no frozenset


@nb.njit(inline="always", fastmath=FASTMATH, cache=True)
def add_row(q, s2, s3, s4, s5, dy):  # pragma: no cover - compiled
    """A subset row's sums ``s2 = sum gx g``, ``s3 = sum gx g dx``, ``s4 = sum gy g``,
    ``s5 = sum gy g dx`` added to the six affine steepest-descent sums ``q`` in place
    (``dy``: the row's offset from the POI, px, the weight of the du/dy, dv/dy terms)."""
    q[0] += s2
    q[1] += s3
    q[2] += s2 * dy
    q[3] += s4
    q[4] += s5
    q[5] += s4 * dy


@nb.njit(inline="always", fastmath=FASTMATH, cache=True)
def centred_norm(sg, sgg, npx):  # pragma: no cover - compiled
    """Mean and centred norm ``sqrt(sum (g - gm)^2)`` of a warped subset of ``npx``
    pixels from its sums ``sg = sum g`` and ``sgg = sum g^2`` (GL): the ZNSSD
    normalisation of the current subset. The norm is 0 (the POI is ``DIVERGED``) when
    the subset is flat or the difference is lost to rounding."""
    gm = sg / npx
    dg2 = sgg - npx * gm * gm
    if not dg2 > 1e-12 * (sgg + 1e-30):
        return gm, 0.0
    return gm, math.sqrt(dg2)


@nb.njit(inline="always", fastmath=FASTMATH, cache=True)
def compose_inverse_affine(p, du, dux, duy, dv, dvx, dvy):  # pragma: no cover - compiled
    """Inverse-compositional update of an affine warp in place: ``W(p) <- W(p) o W(dp)^-1``
    (3x3 homogeneous matrices; ``p = (u, ux, uy, v, vx, vy)``). Returns False, leaving
    ``p`` unchanged, when ``W(dp)`` is singular."""
    a11 = 1.0 + dux
    a22 = 1.0 + dvy
    det = a11 * a22 - duy * dvx
    if not abs(det) > 1e-12:
        return False
    i11 = a22 / det
    i12 = -duy / det
    i21 = -dvx / det
    i22 = a11 / det
    it1 = -(i11 * du + i12 * dv)
    it2 = -(i21 * du + i22 * dv)
    m11 = 1.0 + p[1]
    m12 = p[2]
    m21 = p[4]
    m22 = 1.0 + p[5]
    p[0] = m11 * it1 + m12 * it2 + p[0]
    p[3] = m21 * it1 + m22 * it2 + p[3]
    p[1] = m11 * i11 + m12 * i21 - 1.0
    p[2] = m11 * i12 + m12 * i22
    p[4] = m21 * i11 + m22 * i21
    p[5] = m21 * i12 + m22 * i22 - 1.0
    return True


# Records of the IC-GN kernels' arguments (numba takes named tuples of arrays and scalars
# as one argument each; a field read compiles to a plain load). Built once per Correlator
# except Settings (its max_iterations changes per call) and Outputs.
class ReferenceImages(NamedTuple):
    """Float32 reference image and its spline gradients, with zero columns on the right
    (at least the kernel's row width) so that padded row slices stay inside."""

    f: Float32Array
    gx: Float32Array
    gy: Float32Array


class Subsets(NamedTuple):
    """Per-POI data of the prepared reference subsets (n POIs; k = 2 or 6 parameters)."""

    rows: Int64Array  # (n,) POI centre row, px
    cols: Int64Array  # (n,) POI centre column, px
    hinv: Float64Array  # (n, k, k) inverse ZNSSD Gauss-Newton Hessian
    jsum: Float64Array  # (n, k) sums of the raw steepest-descent images
    avec: Float64Array  # (n, k) their projections on the normalised subset
    fmean: Float64Array  # (n,) mean of the reference subset, GL
    fnorm: Float64Array  # (n,) norm sqrt(sum (f - fmean)^2), GL


class Packed(NamedTuple):
    """Flat reference subsets of the translation kernel, (n, ng) float32 each (or (0, ng):
    copied per call instead): ``f - fmean``, ``gx``, ``gy``."""

    f: Float32Array
    gx: Float32Array
    gy: Float32Array


class Passes(NamedTuple):
    """POI indices of the translation kernel's two passes: ``first`` start at ``p0``; then
    ``second[m]`` starts at the result of ``source[m]`` when that converged."""

    first: IndexArray
    second: IndexArray
    source: IndexArray


class Settings(NamedTuple):
    """Scalars of one IC-GN kernel call (build with :func:`settings` for stable types)."""

    image_rows: int
    image_cols: int
    order: int  # spline degree, 3 or 5
    half: int  # subset half-width, px
    width: int  # padded row width of the kernel's buffers, px (tw or w)
    max_iterations: int
    tolerance: float  # px
    min_zncc: float
    max_step: float  # px: a larger move from the start is DIVERGED


def settings(
    image_rows: int,
    image_cols: int,
    order: int,
    half: int,
    width: int,
    max_iterations: int,
    tolerance: float,
    min_zncc: float,
    max_step: float,
) -> Settings:
    """A :class:`Settings` with Python int and float fields (one compiled signature)."""
    return Settings(
        int(image_rows),
        int(image_cols),
        int(order),
        int(half),
        int(width),
        int(max_iterations),
        float(tolerance),
        float(min_zncc),
        float(max_step),
    )


class Outputs(NamedTuple):
    """Per-POI outputs written by a kernel (n POIs)."""

    p: Float64Array  # (n, k) parameters
    zncc: Float64Array  # (n,)
    iterations: Int64Array  # (n,)
    status: UInt8Array  # (n,) PointStatus


def outputs(n: int, k: int) -> Outputs:
    """Uninitialised :class:`Outputs` for ``n`` POIs and ``k`` parameters."""
    return Outputs(np.empty((n, k)), np.empty(n), np.empty(n, np.int64), np.empty(n, np.uint8))


# ------------------------------------------------------------------ threads
# The kernels are serial ``nogil`` functions over a range of work items; this runs them on
# a small pool of Python threads instead of a numba parfor (issue 16: a parfor re-links and
# re-optimises its whole body, about 1.5-2 s of first-run compile per parallel kernel, and
# numba's static schedule leaves a core idle when the other is busy).
_POOL: list[tuple[int, ThreadPoolExecutor]] = []
_POOL_LOCK = threading.Lock()


def _pool(size: int) -> ThreadPoolExecutor:
    """The shared worker threads (at least ``size``), started on first use."""
    with _POOL_LOCK:
        if not _POOL or _POOL[0][0] < size:
            if _POOL:
                _POOL.pop()[1].shutdown(wait=False)
            _POOL.append((size, ThreadPoolExecutor(size, thread_name_prefix="dicblur-dic")))
        return _POOL[0][1]


def threads() -> int:
    """Threads the kernels run on: numba's thread count (:func:`numba.get_num_threads`,
    set by ``Correlator(workers=...)``)."""
    return int(nb.get_num_threads())


def run_blocks(work: Callable[[int, int, int], Any], n: int, block: int, nthreads: int) -> None:
    """``work(i0, i1, t)`` over the items ``0:n`` in blocks of ``block`` items on
    ``nthreads`` threads (``t``: the thread's number, ``0 <= t < nthreads``, e.g. for its
    scratch buffers), with dynamic scheduling: each thread takes the next block when done
    with its last, so a thread slowed by another process (a loaded machine) does fewer.
    ``work`` calls serial ``nogil`` kernels (they release the GIL). One thread or one
    block: one call ``work(0, n, 0)`` in this thread. Returns when all blocks are done;
    the first exception raised in a thread is raised here."""
    if n <= 0:
        return
    nblk = (n + block - 1) // block
    nthr = max(1, min(nthreads, nblk))
    if nthr == 1:
        work(0, n, 0)
        return
    starts = iter(range(0, n, block))

    def loop(t: int) -> None:
        # next() on a shared iterator is atomic under the GIL
        for i0 in starts:
            work(i0, min(n, i0 + block), t)

    pool = _pool(nthr - 1)
    futures = [pool.submit(loop, t) for t in range(1, nthr)]
    try:
        loop(0)
    finally:
        for fut in futures:
            fut.result()


def blocks_of(n: int, nthreads: int, *, per_thread: int = 4, multiple: int = 1) -> int:
    """Block size for :func:`run_blocks`: about ``per_thread`` blocks per thread (dynamic
    scheduling evens out uneven work and a loaded core), a multiple of ``multiple``."""
    b = max(1, -(-n // max(1, nthreads * per_thread)))
    return multiple * -(-b // multiple)


def example_args(k: int) -> tuple[Any, ...]:
    """Tiny IC-GN arguments with no POI, of the types the Correlator passes (``k`` = 2 or 6
    parameters): ``(coef, images, subsets, cfg, p0, status_in, out)``. Calling a kernel
    with them compiles (or loads) exactly the machine code a correlation uses."""
    z2 = np.zeros((8, 40), np.float32)
    images = ReferenceImages(z2, z2.copy(), z2.copy())
    subsets = Subsets(
        np.zeros(0, np.int64),
        np.zeros(0, np.int64),
        np.zeros((0, k, k)),
        np.zeros((0, k)),
        np.zeros((0, k)),
        np.zeros(0),
        np.zeros(0),
    )
    cfg = settings(8, 8, 3, 1, 16, 1, 0.01, 0.0, 1.0)
    return (z2.copy(), images, subsets, cfg, np.zeros((0, k)), np.zeros(0, np.uint8), outputs(0, k))
