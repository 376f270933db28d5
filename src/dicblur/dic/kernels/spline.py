# ruff: noqa: RUF046  (int(math.floor(x)) gives numba an integer index)
"""Compiled B-spline tap weights and samples (cubic and quintic), inlined into the
IC-GN kernels."""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .common import FASTMATH, PAD

__all__ = ["beta", "beta3d", "beta5", "cubic4", "sample", "weights", "weights3", "weights_into"]


@nb.njit(inline="always", fastmath=FASTMATH, cache=True)
def cubic4(t):  # pragma: no cover - compiled
    """Cubic B-spline weights of the taps -1..2 at the fractional offset t in [0, 1)."""
    t2 = t * t
    t3 = t2 * t
    s = 1.0 - t
    return (
        s * s * s / 6.0,
        2.0 / 3.0 - t2 + 0.5 * t3,
        (1.0 + 3.0 * t + 3.0 * t2 - 3.0 * t3) / 6.0,
        t3 / 6.0,
    )


@nb.njit(inline="always", fastmath=FASTMATH, cache=True)
def weights3(t, w):  # pragma: no cover - compiled
    w[0], w[1], w[2], w[3] = cubic4(t)


@nb.njit(inline="always", fastmath=FASTMATH, cache=True)
def beta5(x):  # pragma: no cover - compiled
    a = abs(x)
    if a < 1.0:
        a2 = a * a
        return 0.55 - 0.5 * a2 + 0.25 * a2 * a2 - a2 * a2 * a / 12.0
    if a < 2.0:
        a2 = a * a
        return (
            17.0 / 40.0
            + 0.625 * a
            - 1.75 * a2
            + 1.25 * a2 * a
            - 0.375 * a2 * a2
            + a2 * a2 * a / 24.0
        )
    if a < 3.0:
        b = 3.0 - a
        return b * b * b * b * b / 120.0
    return 0.0


@nb.njit(inline="always", fastmath=FASTMATH, cache=True)
def weights_into(t, order, w):  # pragma: no cover - compiled
    if order == 3:
        weights3(t, w)
    else:
        for k in range(6):
            w[k] = beta5(t - (k - 2))


@nb.njit(cache=True)
def weights(t, order):  # pragma: no cover - compiled
    """Tap weights at fractional offset ``t`` (compiled; see ``bspline_weights``)."""
    w = np.empty(order + 1, dtype=np.float64)
    weights_into(t, order, w)
    return w


@nb.njit(inline="always", fastmath=FASTMATH, cache=True)
def beta(x, order):  # pragma: no cover - compiled
    """Branch-free centred B-spline (truncated-power form), vectorisable."""
    a = abs(x)
    if order == 3:
        p2 = max(np.float32(0.0), np.float32(2.0) - a)
        p1 = max(np.float32(0.0), np.float32(1.0) - a)
        return (p2 * p2 * p2 - np.float32(4.0) * p1 * p1 * p1) * np.float32(1.0 / 6.0)
    p3 = max(np.float32(0.0), np.float32(3.0) - a)
    p2 = max(np.float32(0.0), np.float32(2.0) - a)
    p1 = max(np.float32(0.0), np.float32(1.0) - a)
    q3 = p3 * p3
    q2 = p2 * p2
    q1 = p1 * p1
    return (
        q3 * q3 * p3 - np.float32(6.0) * q2 * q2 * p2 + np.float32(15.0) * q1 * q1 * p1
    ) * np.float32(1.0 / 120.0)


@nb.njit(inline="always", fastmath=FASTMATH, cache=True)
def sample(coef, order, y, x):  # pragma: no cover - compiled
    """One spline sample at image position (y, x) (generic path)."""
    taps = order + 1
    lo = (order - 1) // 2
    ix = int(math.floor(x))
    iy = int(math.floor(y))
    tx = x - ix
    ty = y - iy
    if order == 3:
        # each axis's 4 weights once (not 4 x 4 truncated powers per sample): 3.2 -> 2.1 us
        # per POI-iteration of the strained subsets that take this path
        x0, x1, x2, x3 = cubic4(tx)
        y0, y1, y2, y3 = cubic4(ty)
        r = iy - 1 + PAD
        c = ix - 1 + PAD
        h0 = x0 * coef[r, c] + x1 * coef[r, c + 1] + x2 * coef[r, c + 2] + x3 * coef[r, c + 3]
        h1 = (
            x0 * coef[r + 1, c]
            + x1 * coef[r + 1, c + 1]
            + x2 * coef[r + 1, c + 2]
            + x3 * coef[r + 1, c + 3]
        )
        h2 = (
            x0 * coef[r + 2, c]
            + x1 * coef[r + 2, c + 1]
            + x2 * coef[r + 2, c + 2]
            + x3 * coef[r + 2, c + 3]
        )
        h3 = (
            x0 * coef[r + 3, c]
            + x1 * coef[r + 3, c + 1]
            + x2 * coef[r + 3, c + 2]
            + x3 * coef[r + 3, c + 3]
        )
        return y0 * h0 + y1 * h1 + y2 * h2 + y3 * h3
    g = 0.0
    for a in range(taps):
        wy = beta5(ty - (a - lo)) if order == 5 else beta3d(ty - (a - lo))
        crow = coef[iy - lo + a + PAD]
        acc = 0.0
        for b in range(taps):
            wx = beta5(tx - (b - lo)) if order == 5 else beta3d(tx - (b - lo))
            acc += wx * crow[ix - lo + b + PAD]
        g += wy * acc
    return g


@nb.njit(inline="always", fastmath=FASTMATH, cache=True)
def beta3d(x):  # pragma: no cover - compiled
    a = abs(x)
    p2 = max(0.0, 2.0 - a)
    p1 = max(0.0, 1.0 - a)
    return (p2 * p2 * p2 - 4.0 * p1 * p1 * p1) / 6.0
