# ruff: noqa: RUF046  (int(math.floor(x)) gives numba an integer index)
"""Compiled hot loops of the DIC engine (numba, ``cache=True``).

Each kernel has a plain reference implementation that the tests compare it against:

=========================  ==========================================================
kernel                     reference
=========================  ==========================================================
:func:`prefilter_padded`   :func:`dicblur.dic.interpolation.prefilter_reference`
                           (:func:`scipy.ndimage.spline_filter`, mirror boundary)
:func:`weights`            :func:`dicblur.dic.interpolation.bspline_weights`
:func:`icgn_translation`   :func:`dicblur.dic.icgn.icgn_reference` (translation)
:func:`icgn_affine`        :func:`dicblur.dic.icgn.icgn_reference` (affine)
=========================  ==========================================================

Speed notes (measured on the 512x512, subset 21, step 10 benchmark): float32 working
arrays; the prefilter runs down the rows with the recursion vectorised across columns
(along the rows, blocks of 16 rows are transposed into scratch so the recursion is
vectorised across them); IC-GN is parallel over POIs. Translation works on flat padded
buffers (row width :func:`flat_width`, lengths multiples of 32): the reference subsets are
packed once (:func:`pack_reference`), each iteration copies the coefficient rows under the
subset, filters them with one horizontal and one vertical 4-tap (6-tap) pass (a rigidly
translated subset shares one set of tap weights) and reduces the five sums in one masked
flat loop. Affine reads contiguous row slices of the coefficient image and of the
reference gradients, with a common-base 5x5 stencil fast path.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .status import PointStatus

__all__ = [
    "PAD",
    "STALL_ITERATIONS",
    "compose_inverse_affine",
    "flat_lengths",
    "flat_width",
    "icgn_affine",
    "icgn_translation",
    "pack_reference",
    "prefilter_padded",
    "weights",
]

#: Margin (px) of mirrored coefficients around the image (quintic needs 3 taps + 1).
PAD = 4

_CONVERGED = int(PointStatus.CONVERGED)
_MAX_ITERATIONS = int(PointStatus.MAX_ITERATIONS)
_OUT_OF_BOUNDS = int(PointStatus.OUT_OF_BOUNDS)
_DIVERGED = int(PointStatus.DIVERGED)
_LOW_CORRELATION = int(PointStatus.LOW_CORRELATION)
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
_FASTMATH = {"contract", "arcp", "nsz", "reassoc", "afn"}  # a set: numba takes no frozenset

# Poles of the B-spline prefilters (Unser 1999, Table I).
_POLES3 = np.array([math.sqrt(3.0) - 2.0])
_POLES5 = np.array(
    [
        math.sqrt(135.0 / 2.0 - math.sqrt(17745.0 / 4.0)) + math.sqrt(105.0 / 4.0) - 13.0 / 2.0,
        math.sqrt(135.0 / 2.0 + math.sqrt(17745.0 / 4.0)) - math.sqrt(105.0 / 4.0) - 13.0 / 2.0,
    ]
)


@nb.njit(parallel=True, fastmath=_FASTMATH, cache=True)
def _filter_axis0(x, poles, tol):  # pragma: no cover - compiled
    """In-place B-spline prefilter of every column of ``x`` (recursion down the rows,
    vectorised across a block of columns); mirror (whole-sample symmetric) boundary."""
    n, m = x.shape
    if n == 1:
        return
    gain = 1.0
    for z in poles:
        gain *= (1.0 - z) * (1.0 - 1.0 / z)
    bw = 64
    nblk = (m + bw - 1) // bw
    for blk in nb.prange(nblk):
        j0 = blk * bw
        j1 = min(m, j0 + bw)
        w = j1 - j0
        s = np.zeros(w, dtype=np.float64)
        first = True
        for z in poles:
            # the overall gain is folded into the first causal pass (one sweep less)
            gn = gain if first else 1.0
            first = False
            horizon = int(math.ceil(math.log(tol) / math.log(abs(z))))
            for j in range(w):
                s[j] = 0.0
            if horizon < n:
                zk = 1.0
                for k in range(horizon):
                    xr = x[k, j0:j1]
                    for j in range(w):
                        s[j] += zk * xr[j]
                    zk *= z
            else:
                # exact mirror-symmetric initialisation (Unser 1999; Thevenaz's coeff.c)
                zn = z
                iz = 1.0 / z
                z2n = z ** (n - 1)
                for j in range(w):
                    s[j] = x[0, j0 + j] + z2n * x[n - 1, j0 + j]
                z2n = z2n * z2n * iz
                for k in range(1, n - 1):
                    for j in range(w):
                        s[j] += (zn + z2n) * x[k, j0 + j]
                    zn *= z
                    z2n *= iz
                for j in range(w):
                    s[j] /= 1.0 - zn * zn
            # row slices: loop indices from range(w) are known non-negative, so the
            # loops vectorise (no wraparound selects)
            xr = x[0, j0:j1]
            for j in range(w):
                xr[j] = gn * s[j]
            for r in range(1, n):
                xp = x[r - 1, j0:j1]
                xr = x[r, j0:j1]
                for j in range(w):
                    xr[j] = gn * xr[j] + z * xp[j]
            c = z / (z * z - 1.0)
            xr = x[n - 1, j0:j1]
            xp = x[n - 2, j0:j1]
            for j in range(w):
                xr[j] = c * (xr[j] + z * xp[j])
            for r in range(n - 2, -1, -1):
                xp = x[r + 1, j0:j1]
                xr = x[r, j0:j1]
                for j in range(w):
                    xr[j] = z * (xp[j] - xr[j])


@nb.njit(parallel=True, fastmath=_FASTMATH, cache=True)
def _filter_axis1(src, dst, poles, tol):  # pragma: no cover - compiled
    """B-spline prefilter of every row of ``src`` into ``dst`` (may differ in dtype).

    A block of 8 rows is copied transposed into a float64 scratch array, so the recursion
    along the row runs with the 8 rows side by side in contiguous memory (vectorised),
    then copied back.
    """
    n_r, n = src.shape
    gain = 1.0
    for z in poles:
        gain *= (1.0 - z) * (1.0 - 1.0 / z)
    bh = 16
    nblk = (n_r + bh - 1) // bh
    for blk in nb.prange(nblk):
        r0 = blk * bh
        h = min(n_r, r0 + bh) - r0
        t = np.zeros((n, bh), dtype=np.float64)
        for r in range(h):
            row = src[r0 + r]
            for c in range(n):
                t[c, r] = row[c]
        if n > 1:
            first = True
            for z in poles:
                gn = gain if first else 1.0
                first = False
                horizon = int(math.ceil(math.log(tol) / math.log(abs(z))))
                s = np.zeros(bh, dtype=np.float64)
                if horizon < n:
                    zk = 1.0
                    for k in range(horizon):
                        for r in range(bh):
                            s[r] += zk * t[k, r]
                        zk *= z
                else:
                    # exact mirror-symmetric initialisation (Unser 1999; Thevenaz's coeff.c)
                    zn = z
                    iz = 1.0 / z
                    z2n = z ** (n - 1)
                    for r in range(bh):
                        s[r] = t[0, r] + z2n * t[n - 1, r]
                    z2n = z2n * z2n * iz
                    for k in range(1, n - 1):
                        for r in range(bh):
                            s[r] += (zn + z2n) * t[k, r]
                        zn *= z
                        z2n *= iz
                    for r in range(bh):
                        s[r] /= 1.0 - zn * zn
                for r in range(bh):
                    t[0, r] = gn * s[r]
                for c in range(1, n):
                    for r in range(bh):
                        t[c, r] = gn * t[c, r] + z * t[c - 1, r]
                cc = z / (z * z - 1.0)
                for r in range(bh):
                    t[n - 1, r] = cc * (t[n - 1, r] + z * t[n - 2, r])
                for c in range(n - 2, -1, -1):
                    for r in range(bh):
                        t[c, r] = z * (t[c + 1, r] - t[c, r])
        for r in range(h):
            row = dst[r0 + r]
            for c in range(n):
                row[c] = t[c, r]


@nb.njit(cache=True)
def _mirror(i, n):  # pragma: no cover - compiled
    if n == 1:
        return 0
    period = 2 * n - 2
    i = abs(i) % period
    return period - i if i >= n else i


@nb.njit(parallel=True, cache=True)
def _fill_margin(out, rows, cols, pad):  # pragma: no cover - compiled
    for r in nb.prange(rows + 2 * pad):
        sr = _mirror(r - pad, rows) + pad
        for c in range(pad):
            out[r, c] = out[sr, _mirror(c - pad, cols) + pad]
            out[r, cols + pad + c] = out[sr, _mirror(cols + c, cols) + pad]
        if sr != r:
            for c in range(pad, cols + pad):
                out[r, c] = out[sr, c]


def prefilter_padded(image: np.ndarray, order: int, out: np.ndarray) -> None:
    """B-spline coefficients of ``image`` written into the centre of ``out``.

    ``out`` has shape ``(rows + 2*PAD, cols + 2*PAD)`` (float32 or float64, ``image`` may be
    of another float dtype); its margin receives the mirror continuation of the
    coefficients.
    """
    poles = _POLES3 if order == 3 else _POLES5
    tol = 1e-7 if out.dtype == np.float32 else 1e-14
    rows, cols = image.shape
    centre = out[PAD : PAD + rows, PAD : PAD + cols]
    _filter_axis1(image, centre, poles, tol)  # along x (columns), no transpose
    _filter_axis0(centre, poles, tol)  # along y (rows), in place, vectorised across columns
    _fill_margin(out, rows, cols, PAD)


@nb.njit(inline="always", fastmath=_FASTMATH, cache=True)
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


@nb.njit(inline="always", fastmath=_FASTMATH, cache=True)
def _weights3(t, w):  # pragma: no cover - compiled
    t2 = t * t
    t3 = t2 * t
    s = 1.0 - t
    w[0] = s * s * s / 6.0
    w[1] = 2.0 / 3.0 - t2 + 0.5 * t3
    w[2] = (1.0 + 3.0 * t + 3.0 * t2 - 3.0 * t3) / 6.0
    w[3] = t3 / 6.0


@nb.njit(inline="always", fastmath=_FASTMATH, cache=True)
def _beta5(x):  # pragma: no cover - compiled
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


@nb.njit(inline="always", fastmath=_FASTMATH, cache=True)
def _weights(t, order, w):  # pragma: no cover - compiled
    if order == 3:
        _weights3(t, w)
    else:
        for k in range(6):
            w[k] = _beta5(t - (k - 2))


@nb.njit(cache=True)
def weights(t, order):  # pragma: no cover - compiled
    """Tap weights at fractional offset ``t`` (compiled; see ``bspline_weights``)."""
    w = np.empty(order + 1, dtype=np.float64)
    _weights(t, order, w)
    return w


@nb.njit(inline="always", fastmath=_FASTMATH, cache=True)
def _beta(x, order):  # pragma: no cover - compiled
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


@nb.njit(inline="always", fastmath=_FASTMATH, cache=True)
def _sample(coef, order, y, x):  # pragma: no cover - compiled
    """One spline sample at image position (y, x) (generic path)."""
    taps = order + 1
    lo = (order - 1) // 2
    ix = int(math.floor(x))
    iy = int(math.floor(y))
    tx = x - ix
    ty = y - iy
    g = 0.0
    for a in range(taps):
        wy = _beta5(ty - (a - lo)) if order == 5 else _beta3d(ty - (a - lo))
        crow = coef[iy - lo + a + PAD]
        acc = 0.0
        for b in range(taps):
            wx = _beta5(tx - (b - lo)) if order == 5 else _beta3d(tx - (b - lo))
            acc += wx * crow[ix - lo + b + PAD]
        g += wy * acc
    return g


@nb.njit(inline="always", fastmath=_FASTMATH, cache=True)
def _beta3d(x):  # pragma: no cover - compiled
    a = abs(x)
    p2 = max(0.0, 2.0 - a)
    p1 = max(0.0, 1.0 - a)
    return (p2 * p2 * p2 - 4.0 * p1 * p1 * p1) / 6.0


# Row helpers: small non-parallel functions, compiled on their own so that LLVM vectorises
# their fixed-width (tw, a multiple of 16) loops; inlined into the parfor body they were not.
@nb.njit(fastmath=_FASTMATH, cache=True)
def _row_affine_fast(
    coef, rb, cb, order, tx0, ty0, p1, p4, dxs, tx, ty, wxs, wys, hrow, grow
):  # pragma: no cover
    tw = grow.shape[0]
    sten = order + 2
    lo = (order - 1) // 2
    for j in range(tw):
        tx[j] = tx0 + p1 * dxs[j]
        ty[j] = ty0 + p4 * dxs[j]
    for b in range(sten):
        kb = np.float32(b - lo)
        wxb = wxs[b]
        wyb = wys[b]
        for j in range(tw):
            wxb[j] = _beta(tx[j] - kb, order)
            wyb[j] = _beta(ty[j] - kb, order)
    for j in range(tw):
        grow[j] = 0.0
    for a in range(sten):
        for j in range(tw):
            hrow[j] = 0.0
        for b in range(sten):
            row = coef[rb + a, cb + b : cb + b + tw]
            wxb = wxs[b]
            for j in range(tw):
                hrow[j] += wxb[j] * row[j]
        wya = wys[a]
        for j in range(tw):
            grow[j] += wya[j] * hrow[j]


@nb.njit(inline="always", fastmath=_FASTMATH, cache=True)
def _w5(t):  # pragma: no cover - compiled
    """Cubic weights of taps -1..3 for an offset t in [0, 2) (one of the end taps is 0)."""
    sh = np.float32(1.0) if t >= np.float32(1.0) else np.float32(0.0)
    u = t - sh
    u2 = u * u
    u3 = u2 * u
    v = np.float32(1.0) - u
    w0 = v * v * v * np.float32(1.0 / 6.0)
    w1 = np.float32(2.0 / 3.0) - u2 + np.float32(0.5) * u3
    w2 = (np.float32(1.0) + np.float32(3.0) * (u + u2 - u3)) * np.float32(1.0 / 6.0)
    w3 = u3 * np.float32(1.0 / 6.0)
    ns = np.float32(1.0) - sh
    return (ns * w0, ns * w1 + sh * w0, ns * w2 + sh * w1, ns * w3 + sh * w2, sh * w3)


@nb.njit(fastmath=_FASTMATH, cache=True)
def _row_affine_cubic(
    coef, rb, cb, tx0, ty0, p1, p4, dxs, off, mask, f, gx, gy, r, c0
):  # pragma: no cover
    """Cubic affine fast path, one row: 5x5 stencil at contiguous memory, fused sums."""
    tw = mask.shape[0]
    q0 = coef[rb, cb : cb + tw + 4]
    q1 = coef[rb + 1, cb : cb + tw + 4]
    q2 = coef[rb + 2, cb : cb + tw + 4]
    q3 = coef[rb + 3, cb : cb + tw + 4]
    q4 = coef[rb + 4, cb : cb + tw + 4]
    fr = f[r, c0 : c0 + tw]
    gxr = gx[r, c0 : c0 + tw]
    gyr = gy[r, c0 : c0 + tw]
    s0 = np.float32(0.0)
    s1 = np.float32(0.0)
    s2 = np.float32(0.0)
    s3 = np.float32(0.0)
    s4 = np.float32(0.0)
    s5 = np.float32(0.0)
    s6 = np.float32(0.0)
    for j in range(tw):
        x0, x1, x2, x3, x4 = _w5(tx0 + p1 * dxs[j])
        y0, y1, y2, y3, y4 = _w5(ty0 + p4 * dxs[j])
        h0 = x0 * q0[j] + x1 * q0[j + 1] + x2 * q0[j + 2] + x3 * q0[j + 3] + x4 * q0[j + 4]
        h1 = x0 * q1[j] + x1 * q1[j + 1] + x2 * q1[j + 2] + x3 * q1[j + 3] + x4 * q1[j + 4]
        h2 = x0 * q2[j] + x1 * q2[j + 1] + x2 * q2[j + 2] + x3 * q2[j + 3] + x4 * q2[j + 4]
        h3 = x0 * q3[j] + x1 * q3[j + 1] + x2 * q3[j + 2] + x3 * q3[j + 3] + x4 * q3[j + 4]
        h4 = x0 * q4[j] + x1 * q4[j + 1] + x2 * q4[j + 2] + x3 * q4[j + 3] + x4 * q4[j + 4]
        g = (y0 * h0 + y1 * h1 + y2 * h2 + y3 * h3 + y4 * h4 - off) * mask[j]
        gxg = gxr[j] * g
        gyg = gyr[j] * g
        s0 += g
        s1 += g * g
        s2 += gxg
        s3 += gxg * dxs[j]
        s4 += gyg
        s5 += gyg * dxs[j]
        s6 += fr[j] * g
    return s0, s1, s2, s3, s4, s5, s6


@nb.njit(fastmath=_FASTMATH, cache=True)
def _acc9(grow, off, mask, dxs, f, gx, gy, r, c0):  # pragma: no cover
    """Row sums of g, g^2, gx g, gx g dx, gy g, gy g dx, f g (the dy terms follow)."""
    tw = grow.shape[0]
    fr = f[r, c0 : c0 + tw]
    gxr = gx[r, c0 : c0 + tw]
    gyr = gy[r, c0 : c0 + tw]
    s0 = np.float32(0.0)
    s1 = np.float32(0.0)
    s2 = np.float32(0.0)
    s3 = np.float32(0.0)
    s4 = np.float32(0.0)
    s5 = np.float32(0.0)
    s6 = np.float32(0.0)
    for j in range(tw):
        g = (grow[j] - off) * mask[j]
        gxg = gxr[j] * g
        gyg = gyr[j] * g
        s0 += g
        s1 += g * g
        s2 += gxg
        s3 += gxg * dxs[j]
        s4 += gyg
        s5 += gyg * dxs[j]
        s6 += fr[j] * g
    return s0, s1, s2, s3, s4, s5, s6


@nb.njit(cache=True, inline="always")
def _aitken_gain(du, dv, pdu, pdv):  # pragma: no cover - compiled
    """Step gain of IC-GN translation, and the previous step to remember.

    Against a blurred current image the sharp reference's Gauss-Newton steps shrink
    geometrically, by a factor rho per iteration (slow linear convergence: 88 iterations
    on average at W = 10 px). Two plain, aligned steps give rho = (d . d_prev) / |d_prev|^2;
    scaling the step by 1 / (1 - rho) jumps to the limit of the geometric series (Aitken's
    delta-squared process). Fast-converging subsets (rho < 0.3) keep plain steps, and after
    a jump the memory is cleared so the next ratio is measured on plain steps again.
    """
    pp = pdu * pdu + pdv * pdv
    if pp > 0.0:
        dd = du * du + dv * dv
        dot = du * pdu + dv * pdv
        rho = dot / pp
        # aligned (cos > 0.95) and shrinking by a steady factor
        if 0.3 < rho < 0.97 and dot * dot > 0.9025 * dd * pp:
            return 1.0 / (1.0 - rho), 0.0, 0.0
    return 1.0, du, dv


# Translation IC-GN on flat padded buffers: the subset's rows are copied into per-thread
# flat arrays of row width ``w`` (a multiple of 8 >= subset + taps - 1), so every inner
# loop runs over one long contiguous range whose length is a multiple of 32 (no remainder,
# vectorises), and the five sums are reduced once per iteration instead of once per row.
def flat_width(subset: int, order: int) -> int:
    """Row width (px) of the flat subset buffers of :func:`icgn_translation`."""
    return 8 * ((subset + order + 7) // 8)


def _up32(x: int) -> int:
    return 32 * ((x + 31) // 32)


def flat_lengths(subset: int, order: int) -> tuple[int, int, int]:
    """Lengths ``(ng, nh, nc)`` of the flat buffers of :func:`icgn_translation`: subset
    samples, horizontally filtered coefficient rows, copied coefficient rows."""
    w = flat_width(subset, order)
    ng = _up32(subset * w)
    nh = _up32(ng + order * w)
    return ng, nh, nh + 32


@nb.njit(fastmath=_FASTMATH, cache=True)
def _load_reference(f, gx, gy, fmean, r0, c0, size, w, fp, gxp, gyp):  # pragma: no cover
    """Reference subset rows (f - fmean, gx, gy), ``w`` px wide, into the flat buffers
    (row width ``w``; the columns >= size are masked out by the sums). Unsigned indices:
    numba emits no negative-index wraparound for them, so the row copies vectorise without
    per-row slice set-up (3x faster than slices)."""
    fm = np.float32(fmean)
    cc = np.uint64(c0)
    for i in range(size):
        r = np.uint64(r0 + i)
        o = np.uint64(i * w)
        for j in range(np.uint64(w)):
            fp[o + j] = f[r, cc + j] - fm
            gxp[o + j] = gx[r, cc + j]
            gyp[o + j] = gy[r, cc + j]


@nb.njit(parallel=True, fastmath=_FASTMATH, cache=True)
def pack_reference(
    f, gx, gy, fmean, rows, cols, half, w, status, fpk, gxpk, gypk
):  # pragma: no cover - compiled
    """Flat reference subsets of all POIs (rows of ``fpk``, ``gxpk``, ``gypk``, shape
    (n, ng)) for :func:`icgn_translation`, prepared once with the reference."""
    size = 2 * half + 1
    for k in nb.prange(rows.shape[0]):
        if status[k] == 0:
            _load_reference(
                f,
                gx,
                gy,
                fmean[k],
                rows[k] - half,
                cols[k] - half,
                size,
                w,
                fpk[k],
                gxpk[k],
                gypk[k],
            )


@nb.njit(fastmath=_FASTMATH, cache=True)
def _sums_translation(
    coef, rb, cb, order, size, w, wxf, wyf, cbuf, hbuf, off, maskf, fp, gxp, gyp
):  # pragma: no cover
    """The five sums of one translation IC-GN iteration over the flat subset.

    ``g = sum_a wy_a sum_b wx_b c[rb + row + a, cb + col + b] - off``; returns
    ``(sum m g, sum m g^2, sum m gx g, sum m gy g, sum m (f - fmean) g)`` with the 0/1
    mask ``m`` of the subset pixels in the flat layout. Shifted reads go through slices
    (non-negative loop indices: no wraparound selects, so the loops vectorise without
    gathers).
    """
    taps = order + 1
    ng = maskf.shape[0]
    nh = hbuf.shape[0]
    cu = np.uint64(cb)
    for a in range(size + taps - 1):
        r = np.uint64(rb + a)
        o = np.uint64(a * w)
        for j in range(np.uint64(w)):
            cbuf[o + j] = coef[r, cu + j]
    # horizontal taps along the flat rows: output columns < size never read across a row end
    # because w >= size + order
    c0 = cbuf[0:nh]
    c1 = cbuf[1 : nh + 1]
    c2 = cbuf[2 : nh + 2]
    c3 = cbuf[3 : nh + 3]
    b0 = wxf[0]
    b1 = wxf[1]
    b2 = wxf[2]
    b3 = wxf[3]
    if order == 3:
        for i in range(nh):
            hbuf[i] = b0 * c0[i] + b1 * c1[i] + b2 * c2[i] + b3 * c3[i]
    else:
        c4 = cbuf[4 : nh + 4]
        c5 = cbuf[5 : nh + 5]
        b4 = wxf[4]
        b5 = wxf[5]
        for i in range(nh):
            hbuf[i] = b0 * c0[i] + b1 * c1[i] + b2 * c2[i] + b3 * c3[i] + b4 * c4[i] + b5 * c5[i]
    s0 = np.float32(0.0)
    s1 = np.float32(0.0)
    s2 = np.float32(0.0)
    s3 = np.float32(0.0)
    s4 = np.float32(0.0)
    h0 = hbuf[0:ng]
    h1 = hbuf[w : w + ng]
    h2 = hbuf[2 * w : 2 * w + ng]
    h3 = hbuf[3 * w : 3 * w + ng]
    a0 = wyf[0]
    a1 = wyf[1]
    a2 = wyf[2]
    a3 = wyf[3]
    if order == 3:
        for i in range(ng):
            g = a0 * h0[i] + a1 * h1[i] + a2 * h2[i] + a3 * h3[i] - off
            gm = g * maskf[i]
            s0 += gm
            s1 += gm * g
            s2 += gxp[i] * gm
            s3 += gyp[i] * gm
            s4 += fp[i] * gm
    else:
        h4 = hbuf[4 * w : 4 * w + ng]
        h5 = hbuf[5 * w : 5 * w + ng]
        a4 = wyf[4]
        a5 = wyf[5]
        for i in range(ng):
            g = a0 * h0[i] + a1 * h1[i] + a2 * h2[i] + a3 * h3[i] + a4 * h4[i] + a5 * h5[i] - off
            gm = g * maskf[i]
            s0 += gm
            s1 += gm * g
            s2 += gxp[i] * gm
            s3 += gyp[i] * gm
            s4 += fp[i] * gm
    return s0, s1, s2, s3, s4


@nb.njit(fastmath=_FASTMATH, cache=True)
def _points_translation(
    todo,
    m0,
    m1,
    source,
    p0,
    status_in,
    coef,
    himg,
    wimg,
    order,
    w,
    f,
    gx,
    gy,
    rows,
    cols,
    half,
    hinv,
    jsum,
    avec,
    fmean,
    fnorm,
    max_iter,
    tol,
    min_zncc,
    max_step,
    maskf,
    cbuf,
    hbuf,
    fps,
    gxps,
    gyps,
    fpk,
    gxpk,
    gypk,
    out_p,
    out_zncc,
    out_iter,
    out_status,
):  # pragma: no cover
    """IC-GN translation of the POIs ``todo[m0:m1]`` (see :func:`icgn_translation`): one call
    per chunk of POIs keeps the call overhead of the many array arguments off each POI."""
    packed = fpk.shape[0] > 0
    # tap weights: private to this call (per-thread rows of one small array would share a
    # cache line between the threads and bounce it on every iteration)
    taps = order + 1
    wx = np.empty(taps, dtype=np.float64)
    wy = np.empty(taps, dtype=np.float64)
    wxf = np.empty(taps, dtype=np.float32)
    wyf = np.empty(taps, dtype=np.float32)
    for m in range(m0, m1):
        k = todo[m]
        if status_in[k] != 0:
            out_status[k] = status_in[k]
            out_p[k, 0] = np.nan
            out_p[k, 1] = np.nan
            out_zncc[k] = np.nan
            out_iter[k] = 0
            continue
        u = p0[k, 0]
        v = p0[k, 1]
        if source.shape[0] > 0:
            s = source[m]
            if out_status[s] == _CONVERGED:
                u = out_p[s, 0]
                v = out_p[s, 1]
        if packed:
            _point_translation(
                k,
                u,
                v,
                coef,
                himg,
                wimg,
                order,
                w,
                f,
                gx,
                gy,
                rows,
                cols,
                half,
                hinv,
                jsum,
                avec,
                fmean,
                fnorm,
                max_iter,
                tol,
                min_zncc,
                max_step,
                maskf,
                wx,
                wy,
                wxf,
                wyf,
                cbuf,
                hbuf,
                fpk[k],
                gxpk[k],
                gypk[k],
                False,
                out_p,
                out_zncc,
                out_iter,
                out_status,
            )
        else:
            _point_translation(
                k,
                u,
                v,
                coef,
                himg,
                wimg,
                order,
                w,
                f,
                gx,
                gy,
                rows,
                cols,
                half,
                hinv,
                jsum,
                avec,
                fmean,
                fnorm,
                max_iter,
                tol,
                min_zncc,
                max_step,
                maskf,
                wx,
                wy,
                wxf,
                wyf,
                cbuf,
                hbuf,
                fps,
                gxps,
                gyps,
                True,
                out_p,
                out_zncc,
                out_iter,
                out_status,
            )


@nb.njit(fastmath=_FASTMATH, cache=True)
def _point_translation(
    k,
    u,
    v,
    coef,
    himg,
    wimg,
    order,
    w,
    f,
    gx,
    gy,
    rows,
    cols,
    half,
    hinv,
    jsum,
    avec,
    fmean,
    fnorm,
    max_iter,
    tol,
    min_zncc,
    max_step,
    maskf,
    wx,
    wy,
    wxf,
    wyf,
    cbuf,
    hbuf,
    fp,
    gxp,
    gyp,
    load,
    out_p,
    out_zncc,
    out_iter,
    out_status,
):  # pragma: no cover - compiled
    """IC-GN translation of POI ``k`` started at ``(u, v)``; writes row ``k`` of the
    outputs."""
    size = 2 * half + 1
    taps = order + 1
    lo = (order - 1) // 2
    npx = size * size
    u_start = u
    v_start = v
    r0 = rows[k] - half
    c0 = cols[k] - half
    off = np.float32(fmean[k])
    if load:
        _load_reference(f, gx, gy, fmean[k], r0, c0, size, w, fp, gxp, gyp)
    st = _MAX_ITERATIONS
    zn = np.nan
    nit = 0
    pdu = 0.0
    pdv = 0.0
    best = np.inf
    ibest = 0
    for it in range(max_iter):
        x0 = c0 + u
        y0 = r0 + v
        if not (
            x0 >= 0.0 and y0 >= 0.0 and x0 + 2 * half <= wimg - 1 and y0 + 2 * half <= himg - 1
        ):
            st = _OUT_OF_BOUNDS
            break
        ix = int(math.floor(x0))
        iy = int(math.floor(y0))
        _weights(x0 - ix, order, wx)
        _weights(y0 - iy, order, wy)
        for a in range(taps):
            wxf[a] = wx[a]
            wyf[a] = wy[a]
        sg, sgg, sx, sy, sfc = _sums_translation(
            coef,
            iy - lo + PAD,
            ix - lo + PAD,
            order,
            size,
            w,
            wxf,
            wyf,
            cbuf,
            hbuf,
            off,
            maskf,
            fp,
            gxp,
            gyp,
        )
        gm = sg / npx
        dg2 = sgg - npx * gm * gm
        if not dg2 > 1e-12 * (sgg + 1e-30):
            st = _DIVERGED
            break
        dg = math.sqrt(dg2)
        zn = sfc / (fnorm[k] * dg)
        q0 = ((sx - jsum[k, 0] * gm) / dg - avec[k, 0] * zn) / fnorm[k]
        q1 = ((sy - jsum[k, 1] * gm) / dg - avec[k, 1] * zn) / fnorm[k]
        du = hinv[k, 0, 0] * q0 + hinv[k, 0, 1] * q1
        dv = hinv[k, 1, 0] * q0 + hinv[k, 1, 1] * q1
        gain, pdu, pdv = _aitken_gain(du, dv, pdu, pdv)
        # inverse composition: W(p) <- W(p) o W(dp)^-1
        u -= gain * du
        v -= gain * dv
        nit = it + 1
        if not (math.isfinite(u) and math.isfinite(v)):
            st = _DIVERGED
            break
        norm = math.sqrt(du * du + dv * dv)
        if norm < tol:
            st = _CONVERGED
            break
        if norm < best:
            best = norm
            ibest = it
        elif it - ibest >= STALL_ITERATIONS:
            break
        if abs(u - u_start) > max_step or abs(v - v_start) > max_step:
            st = _DIVERGED
            break
    if st == _CONVERGED and not zn >= min_zncc:
        st = _LOW_CORRELATION
    out_status[k] = st
    if st == _CONVERGED or st == _MAX_ITERATIONS or st == _LOW_CORRELATION:
        out_p[k, 0] = u
        out_p[k, 1] = v
    else:
        out_p[k, 0] = np.nan
        out_p[k, 1] = np.nan
    out_zncc[k] = zn
    out_iter[k] = nit


@nb.njit(cache=True, inline="always")
def _aitken_gain6(d, prev, half):  # pragma: no cover - compiled
    """Step gain of IC-GN affine (as :func:`_aitken_gain`), ratio measured on the 6-vector
    ``(du, h dux, h duy, dv, h dvx, h dvy)`` (``h`` = subset half-width, the weights of
    the convergence norm); updates the remembered step ``prev`` in place."""
    pp = 0.0
    dd = 0.0
    dot = 0.0
    for m in range(6):
        sc = 1.0 if m == 0 or m == 3 else half * 1.0
        a = d[m] * sc
        b = prev[m] * sc
        pp += b * b
        dd += a * a
        dot += a * b
    if pp > 0.0:
        rho = dot / pp
        if 0.3 < rho < 0.97 and dot * dot > 0.9025 * dd * pp:
            for m in range(6):
                prev[m] = 0.0
            return 1.0 / (1.0 - rho)
    for m in range(6):
        prev[m] = d[m]
    return 1.0


@nb.njit(parallel=True, fastmath=_FASTMATH, cache=True)
def icgn_translation(
    coef,
    himg,
    wimg,
    order,
    f,
    gx,
    gy,
    rows,
    cols,
    half,
    w,
    hinv,
    jsum,
    avec,
    fmean,
    fnorm,
    p0,
    status_in,
    max_iter,
    tol,
    min_zncc,
    max_step,
    first,
    second,
    source,
    nthr,
    fpk,
    gxpk,
    gypk,
    out_p,
    out_zncc,
    out_iter,
    out_status,
):  # pragma: no cover - compiled
    """IC-GN with the zero-order (translation) shape function, ZNSSD criterion.

    Parameters ``(u, v)`` px. Per POI: ``hinv`` (2, 2) inverse exact ZNSSD Gauss-Newton
    Hessian, ``jsum`` (2,) sums of the raw steepest-descent images ``(gx, gy)``, ``avec``
    (2,) their projections on the normalised reference subset, ``fmean``/``fnorm`` mean and
    norm ``sqrt(sum (f - fmean)^2)`` of the reference subset. See ``icgn.py`` for the
    algebra (the update needs only five running sums per iteration).

    Two passes in one call (one dispatch): the POIs ``first`` start at ``p0[k]``; then each
    POI ``second[m]`` starts at the result of POI ``source[m]`` when that converged, else at
    its own ``p0``. Outputs (all of length n, indexed by POI) are written only for the POIs
    listed. ``status_in[k] != 0`` is passed through. ``nthr``: numba's thread count limit
    (``numba.config.NUMBA_NUM_THREADS``, sizes the per-thread buffers).

    Layout: ``coef`` holds the padded coefficients of the current image (image pixel
    ``(r, c)`` at ``(r + PAD, c + PAD)``) with at least ``w`` extra columns on the right;
    ``f``, ``gx``, ``gy`` are float32 images with at least ``w`` extra columns. ``w`` is
    :func:`flat_width`. ``fpk``, ``gxpk``, ``gypk``: the flat reference subsets from
    :func:`pack_reference`, shape (n, ng), or shape (0, ng) to copy them per POI into
    per-thread buffers instead (when n x ng is too large to keep).
    """
    size = 2 * half + 1
    ng = 32 * ((size * w + 31) // 32)
    nh = 32 * ((ng + order * w + 31) // 32)
    maskf = np.zeros(ng, dtype=np.float32)
    for i in range(size):
        for j in range(size):
            maskf[i * w + j] = 1.0
    # per-thread buffers (zeros: whatever the masked-out tails hold must be finite)
    cbufs = np.zeros((nthr, nh + 32), dtype=np.float32)
    hbufs = np.zeros((nthr, nh), dtype=np.float32)
    nl = ng if fpk.shape[0] == 0 else 0
    fps = np.zeros((nthr, nl), dtype=np.float32)
    gxps = np.zeros((nthr, nl), dtype=np.float32)
    gyps = np.zeros((nthr, nl), dtype=np.float32)
    chunk = 16
    for npass in range(2):
        todo = first if npass == 0 else second
        src = source[:0] if npass == 0 else source
        nch = (todo.shape[0] + chunk - 1) // chunk
        for c in nb.prange(nch):
            t = nb.get_thread_id()
            _points_translation(
                todo,
                c * chunk,
                min(todo.shape[0], (c + 1) * chunk),
                src,
                p0,
                status_in,
                coef,
                himg,
                wimg,
                order,
                w,
                f,
                gx,
                gy,
                rows,
                cols,
                half,
                hinv,
                jsum,
                avec,
                fmean,
                fnorm,
                max_iter,
                tol,
                min_zncc,
                max_step,
                maskf,
                cbufs[t],
                hbufs[t],
                fps[t],
                gxps[t],
                gyps[t],
                fpk,
                gxpk,
                gypk,
                out_p,
                out_zncc,
                out_iter,
                out_status,
            )


@nb.njit(parallel=True, fastmath=_FASTMATH, cache=True)
def icgn_affine(
    coef,
    himg,
    wimg,
    order,
    f,
    gx,
    gy,
    rows,
    cols,
    half,
    tw,
    hinv,
    jsum,
    avec,
    fmean,
    fnorm,
    p0,
    status_in,
    max_iter,
    tol,
    min_zncc,
    max_step,
    out_p,
    out_zncc,
    out_iter,
    out_status,
):  # pragma: no cover - compiled
    """IC-GN with the first-order (affine) shape function, ZNSSD criterion.

    Parameters ``p = (u, du/dx, du/dy, v, dv/dx, dv/dy)``; the warp of a subset pixel at
    offset ``(dx, dy)`` from the POI is ``x' = x + u + ux dx + uy dy``,
    ``y' = y + v + vx dx + vy dy`` (Pan et al. 2013, doi:10.1007/s11340-013-9717-6).

    Fast path: when the sub-pixel offsets ``x' - x`` (and ``y' - y``) of all subset pixels
    span less than one pixel, one integer base covers the subset and every sample reads
    the same ``(order+2) x (order+2)`` stencil (5x5 for cubic) at contiguous memory,
    with per-pixel weights ``beta(t - k)``, ``t`` in [0, 2): the row loop vectorises.
    Otherwise each pixel is sampled on its own 4x4 (6x6) taps. Layout as in
    :func:`icgn_translation`.
    """
    n = rows.shape[0]
    size = 2 * half + 1
    lo = (order - 1) // 2
    sten = order + 2
    npx = size * size
    mask = np.zeros(tw, dtype=np.float32)
    mask[:size] = 1.0
    dxs = np.zeros(tw, dtype=np.float32)
    for j in range(tw):
        dxs[j] = j - half
    # chunks of 16 POIs: the scratch arrays are allocated once per chunk, not per POI
    chunk = 16
    for ch in nb.prange((n + chunk - 1) // chunk):
        q = np.empty(6, dtype=np.float64)
        p = np.empty(6, dtype=np.float64)
        dstep = np.empty(6, dtype=np.float64)
        dprev = np.zeros(6, dtype=np.float64)
        wxs = np.empty((sten, tw), dtype=np.float32)
        wys = np.empty((sten, tw), dtype=np.float32)
        tx = np.empty(tw, dtype=np.float32)
        ty = np.empty(tw, dtype=np.float32)
        hrow = np.empty(tw, dtype=np.float32)
        grow = np.empty(tw, dtype=np.float32)
        for k in range(ch * chunk, min(n, (ch + 1) * chunk)):
            if status_in[k] != 0:
                out_status[k] = status_in[k]
                for m in range(6):
                    out_p[k, m] = np.nan
                out_zncc[k] = np.nan
                out_iter[k] = 0
                continue
            for m in range(6):
                dprev[m] = 0.0
            for m in range(6):
                p[m] = p0[k, m]
            xc = cols[k]
            yc = rows[k]
            r0 = rows[k] - half
            c0 = cols[k] - half
            off = np.float32(fmean[k])
            st = _MAX_ITERATIONS
            zn = np.nan
            nit = 0
            best = np.inf
            ibest = 0
            for it in range(max_iter):
                # bounds: an affine map sends the subset's corners to the warped extremes
                inside = True
                oxmin = 1e30
                oxmax = -1e30
                oymin = 1e30
                oymax = -1e30
                for cy in (-half, half):
                    for cx in (-half, half):
                        ox = p[0] + p[1] * cx + p[2] * cy
                        oy = p[3] + p[4] * cx + p[5] * cy
                        oxmin = min(oxmin, ox)
                        oxmax = max(oxmax, ox)
                        oymin = min(oymin, oy)
                        oymax = max(oymax, oy)
                        if not (
                            xc + cx + ox >= 0.0
                            and yc + cy + oy >= 0.0
                            and xc + cx + ox <= wimg - 1
                            and yc + cy + oy <= himg - 1
                        ):
                            inside = False
                if not inside:
                    st = _OUT_OF_BOUNDS
                    break
                fast = (oxmax - oxmin) < 0.999 and (oymax - oymin) < 0.999
                bx = int(math.floor(oxmin))
                by = int(math.floor(oymin))
                sg = 0.0
                sgg = 0.0
                sf = 0.0
                for m in range(6):
                    q[m] = 0.0
                p1 = np.float32(p[1])
                p4 = np.float32(p[4])
                for i in range(size):
                    dy = i - half
                    if fast and order == 3:
                        t0s, t1s, t2s, t3s, t4s, t5s, t6s = _row_affine_cubic(
                            coef,
                            r0 + i + by - lo + PAD,
                            c0 + bx - lo + PAD,
                            np.float32(p[0] + p[2] * dy - bx),
                            np.float32(p[3] + p[5] * dy - by),
                            p1,
                            p4,
                            dxs,
                            off,
                            mask,
                            f,
                            gx,
                            gy,
                            r0 + i,
                            c0,
                        )
                    else:
                        if fast:
                            # offsets t in [0, 2) from the common integer base (bx, by)
                            tx0 = np.float32(p[0] + p[2] * dy - bx)
                            ty0 = np.float32(p[3] + p[5] * dy - by)
                            _row_affine_fast(
                                coef,
                                r0 + i + by - lo + PAD,
                                c0 + bx - lo + PAD,
                                order,
                                tx0,
                                ty0,
                                p1,
                                p4,
                                dxs,
                                tx,
                                ty,
                                wxs,
                                wys,
                                hrow,
                                grow,
                            )
                        else:
                            for j in range(tw):
                                grow[j] = 0.0
                            for j in range(size):
                                xx = xc + p[0] + (1.0 + p[1]) * (j - half) + p[2] * dy
                                yy = yc + p[3] + p[4] * (j - half) + (1.0 + p[5]) * dy
                                grow[j] = _sample(coef, order, yy, xx)
                        t0s, t1s, t2s, t3s, t4s, t5s, t6s = _acc9(
                            grow, off, mask, dxs, f, gx, gy, r0 + i, c0
                        )
                    sg += t0s
                    sgg += t1s
                    q[0] += t2s
                    q[1] += t3s
                    q[2] += t2s * dy
                    q[3] += t4s
                    q[4] += t5s
                    q[5] += t4s * dy
                    sf += t6s
                gm = sg / npx
                dg2 = sgg - npx * gm * gm
                if not dg2 > 1e-12 * (sgg + 1e-30):
                    st = _DIVERGED
                    break
                dg = math.sqrt(dg2)
                zn = (sf - fmean[k] * sg) / (fnorm[k] * dg)
                for m in range(6):
                    q[m] = ((q[m] - jsum[k, m] * gm) / dg - avec[k, m] * zn) / fnorm[k]
                du = 0.0
                dux = 0.0
                duy = 0.0
                dv = 0.0
                dvx = 0.0
                dvy = 0.0
                for m in range(6):
                    du += hinv[k, 0, m] * q[m]
                    dux += hinv[k, 1, m] * q[m]
                    duy += hinv[k, 2, m] * q[m]
                    dv += hinv[k, 3, m] * q[m]
                    dvx += hinv[k, 4, m] * q[m]
                    dvy += hinv[k, 5, m] * q[m]
                dstep[0] = du
                dstep[1] = dux
                dstep[2] = duy
                dstep[3] = dv
                dstep[4] = dvx
                dstep[5] = dvy
                gain = _aitken_gain6(dstep, dprev, half)
                du0 = du
                dux0 = dux
                duy0 = duy
                dv0 = dv
                dvx0 = dvx
                dvy0 = dvy
                du *= gain
                dux *= gain
                duy *= gain
                dv *= gain
                dvx *= gain
                dvy *= gain
                if not compose_inverse_affine(p, du, dux, duy, dv, dvx, dvy):
                    st = _DIVERGED
                    break
                nit = it + 1
                finite = True
                for m in range(6):
                    if not math.isfinite(p[m]):
                        finite = False
                if not finite:
                    st = _DIVERGED
                    break
                # convergence on the plain (unscaled) Gauss-Newton step, as the translation
                norm = math.sqrt(
                    du0 * du0
                    + dv0 * dv0
                    + half * half * (dux0 * dux0 + duy0 * duy0 + dvx0 * dvx0 + dvy0 * dvy0)
                )
                if norm < tol:
                    st = _CONVERGED
                    break
                if norm < best:
                    best = norm
                    ibest = it
                elif it - ibest >= STALL_ITERATIONS:
                    break
                if (
                    abs(p[0] - p0[k, 0]) > max_step
                    or abs(p[3] - p0[k, 3]) > max_step
                    or abs(p[1]) > 0.5
                    or abs(p[2]) > 0.5
                    or abs(p[4]) > 0.5
                    or abs(p[5]) > 0.5
                ):
                    st = _DIVERGED
                    break
            if st == _CONVERGED and not zn >= min_zncc:
                st = _LOW_CORRELATION
            out_status[k] = st
            keep = st == _CONVERGED or st == _MAX_ITERATIONS or st == _LOW_CORRELATION
            for m in range(6):
                out_p[k, m] = p[m] if keep else np.nan
            out_zncc[k] = zn
            out_iter[k] = nit
