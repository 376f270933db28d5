"""Constants and inlined helpers shared by the compiled DIC kernels."""

from __future__ import annotations

import numba as nb

from ..status import PointStatus

__all__ = [
    "CONVERGED",
    "DIVERGED",
    "FASTMATH",
    "LOW_CORRELATION",
    "MAX_ITERATIONS",
    "OUT_OF_BOUNDS",
    "PAD",
    "STALL_ITERATIONS",
    "compose_inverse_affine",
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

# Fast-math flags of the kernels: no "nnan"/"ninf" (the status tests `not dg2 > ...`,
# `math.isfinite(u)` must see NaN and inf). "reassoc" stays: without it LLVM cannot
# vectorise the IC-GN reductions (affine 43k -> 179k POI per CPU-s, translation 299k ->
# 455k, 512^2, subset 21, one thread). A reassociated reduction compiled in one process and
# the same kernel loaded from numba's cache can differ in the last bits, so every process
# of a campaign runs cached code: run_campaign compiles a cold cache in a subprocess first
# (dicblur.dic.cache.compile_kernels), which keeps resumed campaigns bit-identical.
FASTMATH = {"contract", "arcp", "nsz", "reassoc", "afn"}  # a set: numba takes no frozenset


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
