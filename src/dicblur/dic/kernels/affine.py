# ruff: noqa: RUF046  (int(math.floor(x)) gives numba an integer index)
"""IC-GN kernel of the affine shape function (row slices, 4x4 and 5x5 stencil fast
paths)."""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .common import (
    CONVERGED,
    DIVERGED,
    FASTMATH,
    GAIN_MIN,
    JUMP_SLACK,
    LOW_CORRELATION,
    MAX_ITERATIONS,
    OUT_OF_BOUNDS,
    PAD,
    STALL_ITERATIONS,
    add_row,
    blocks_of,
    centred_norm,
    compose_inverse_affine,
    example_args,
    run_blocks,
    threads,
)
from .spline import beta, sample

__all__ = ["CHUNK", "compile_icgn", "icgn_affine"]


# Row and subset helpers: small functions compiled on their own so that LLVM vectorises
# their fixed-width (tw) row loops; inlined into the parfor body they were not.
@nb.njit(fastmath=FASTMATH, cache=True)
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
            wxb[j] = beta(tx[j] - kb, order)
            wyb[j] = beta(ty[j] - kb, order)
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


@nb.njit(inline="always", fastmath=FASTMATH, cache=True)
def _add_pixel(s0, s1, s2, s3, s4, s5, s6, g, gxj, gyj, fj, dx):  # pragma: no cover
    """A pixel's terms added to a row's sums of g, g^2, gx g, gx g dx, gy g, gy g dx,
    f g (``g`` the warped current minus the reference mean, masked; ``dx`` its column
    offset from the POI, px)."""
    gxg = gxj * g
    gyg = gyj * g
    return (
        s0 + g,
        s1 + g * g,
        s2 + gxg,
        s3 + gxg * dx,
        s4 + gyg,
        s5 + gyg * dx,
        s6 + fj * g,
    )


@nb.njit(inline="always", fastmath=FASTMATH, cache=True)
def _add_row_sums(q, totals, row, dy):  # pragma: no cover - compiled
    """A subset row's float32 sums ``row`` (as :func:`_add_pixel`'s) added in float64 to
    the subset's ``totals = (sum g, sum g^2, sum f g)``, returned, and to the six
    steepest-descent sums ``q`` in place (:func:`~.common.add_row`; ``dy`` the row's
    offset from the POI, px)."""
    sg, sgg, sf = totals
    s0, s1, s2, s3, s4, s5, s6 = row
    sg += float(s0)
    sgg += float(s1)
    sf += float(s6)
    add_row(q, s2, s3, s4, s5, dy)
    return sg, sgg, sf


@nb.njit(inline="always", cache=True)
def _reference_row(f, gx, gy, r, c0, tw):  # pragma: no cover - compiled
    """Row ``r`` of the reference and its gradients under a subset: ``tw`` px from column
    ``c0`` (the padded width; the image arrays carry zero columns on the right)."""
    return f[r, c0 : c0 + tw], gx[r, c0 : c0 + tw], gy[r, c0 : c0 + tw]


@nb.njit(inline="always", cache=True)
def _row_offsets(p, dy, bx, by):  # pragma: no cover - compiled
    """Warped offsets (x, y) of the subset row ``dy`` at its centre column past the
    integer base ``(bx, by)``, px, float32 (the row's pixels add ``p[1] dx``,
    ``p[4] dx``)."""
    return np.float32(p[0] + p[2] * dy - bx), np.float32(p[3] + p[5] * dy - by)


@nb.njit(inline="always", fastmath=FASTMATH, cache=True)
def _w4(u):  # pragma: no cover - compiled
    """Cubic weights of taps -1..2 for an offset u in [0, 1) (also :func:`_w5`'s, shifted)."""
    u2 = u * u
    u3 = u2 * u
    v = np.float32(1.0) - u
    w0 = v * v * v * np.float32(1.0 / 6.0)
    w1 = np.float32(2.0 / 3.0) - u2 + np.float32(0.5) * u3
    w2 = (np.float32(1.0) + np.float32(3.0) * (u + u2 - u3)) * np.float32(1.0 / 6.0)
    w3 = u3 * np.float32(1.0 / 6.0)
    return w0, w1, w2, w3


@nb.njit(inline="always", fastmath=FASTMATH, cache=True)
def _w5(t):  # pragma: no cover - compiled
    """Cubic weights of taps -1..3 for an offset t in [0, 2) (one of the end taps is 0)."""
    sh = np.float32(1.0) if t >= np.float32(1.0) else np.float32(0.0)
    w0, w1, w2, w3 = _w4(t - sh)
    ns = np.float32(1.0) - sh
    return (ns * w0, ns * w1 + sh * w0, ns * w2 + sh * w1, ns * w3 + sh * w2, sh * w3)


@nb.njit(fastmath=FASTMATH, cache=True)
def _subset_affine_cubic(
    coef, p, fast, bx, by, half, r0, c0, dxs, off, mask, f, gx, gy, q
):  # pragma: no cover
    """Cubic affine fast path, one IC-GN iteration's sums over the whole subset.

    Each row reads its 5x5 stencil at contiguous memory from the integer base ``(bx, by)``
    (the subset's common base when ``fast``, else the row's own), with per-pixel weights
    ``_w5``; the row's sums are float32, added in float64 across rows. Adds the sums of
    the steepest-descent terms to ``q`` (zeroed by the caller) and returns
    ``(sg, sgg, sf)``. One call per iteration rather than one per row (each passing 5
    arrays and slicing 8): 19.3k -> 17.4k instructions (callgrind) and 2.69 -> 2.27 us
    per POI-iteration (512^2, subset 21, one thread), same results to the bit."""
    tw = mask.shape[0]
    size = 2 * half + 1
    p1 = np.float32(p[1])
    p4 = np.float32(p[4])
    totals = (0.0, 0.0, 0.0)
    for i in range(size):
        dy = i - half
        if not fast:
            rx = p[0] + p[2] * dy
            ry = p[3] + p[5] * dy
            bx = int(math.floor(min(rx - p[1] * half, rx + p[1] * half)))
            by = int(math.floor(min(ry - p[4] * half, ry + p[4] * half)))
        rb = r0 + i + by - 1 + PAD  # cubic: taps from base - 1
        cb = c0 + bx - 1 + PAD
        b0 = coef[rb, cb : cb + tw + 4]
        b1 = coef[rb + 1, cb : cb + tw + 4]
        b2 = coef[rb + 2, cb : cb + tw + 4]
        b3 = coef[rb + 3, cb : cb + tw + 4]
        b4 = coef[rb + 4, cb : cb + tw + 4]
        fr, gxr, gyr = _reference_row(f, gx, gy, r0 + i, c0, tw)
        tx0, ty0 = _row_offsets(p, dy, bx, by)
        s0 = s1 = s2 = s3 = s4 = s5 = s6 = np.float32(0.0)
        for j in range(tw):
            x0, x1, x2, x3, x4 = _w5(tx0 + p1 * dxs[j])
            y0, y1, y2, y3, y4 = _w5(ty0 + p4 * dxs[j])
            h0 = x0 * b0[j] + x1 * b0[j + 1] + x2 * b0[j + 2] + x3 * b0[j + 3] + x4 * b0[j + 4]
            h1 = x0 * b1[j] + x1 * b1[j + 1] + x2 * b1[j + 2] + x3 * b1[j + 3] + x4 * b1[j + 4]
            h2 = x0 * b2[j] + x1 * b2[j + 1] + x2 * b2[j + 2] + x3 * b2[j + 3] + x4 * b2[j + 4]
            h3 = x0 * b3[j] + x1 * b3[j + 1] + x2 * b3[j + 2] + x3 * b3[j + 3] + x4 * b3[j + 4]
            h4 = x0 * b4[j] + x1 * b4[j + 1] + x2 * b4[j + 2] + x3 * b4[j + 3] + x4 * b4[j + 4]
            g = (y0 * h0 + y1 * h1 + y2 * h2 + y3 * h3 + y4 * h4 - off) * mask[j]
            s0, s1, s2, s3, s4, s5, s6 = _add_pixel(
                s0, s1, s2, s3, s4, s5, s6, g, gxr[j], gyr[j], fr[j], dxs[j]
            )
        totals = _add_row_sums(q, totals, (s0, s1, s2, s3, s4, s5, s6), dy)
    return totals


@nb.njit(fastmath=FASTMATH, cache=True)
def _subset_affine_cubic4(
    coef, p, bx, by, half, r0, c0, dxs, off, mask, f, gx, gy, q
):  # pragma: no cover
    """:func:`_subset_affine_cubic` of a subset whose warped pixels all lie in one pixel
    cell past the integer base ``(bx, by)`` (offsets in [0, 1) along x and along y): the
    4x4 taps that ``_w5`` weights non-zero, weights ``_w4``, the zero tap left out (16
    products for the interpolant instead of 25 and no blend of two weight sets). Nearly
    every subset of a field whose warp spans a small fraction of a pixel takes it. A
    function of its own: inlined beside the 5x5 loop its loop spilled registers."""
    tw = mask.shape[0]
    size = 2 * half + 1
    p1 = np.float32(p[1])
    p4 = np.float32(p[4])
    totals = (0.0, 0.0, 0.0)
    cb = c0 + bx - 1 + PAD  # cubic: taps from base - 1
    for i in range(size):
        dy = i - half
        rb = r0 + i + by - 1 + PAD
        b0 = coef[rb, cb : cb + tw + 3]
        b1 = coef[rb + 1, cb : cb + tw + 3]
        b2 = coef[rb + 2, cb : cb + tw + 3]
        b3 = coef[rb + 3, cb : cb + tw + 3]
        fr, gxr, gyr = _reference_row(f, gx, gy, r0 + i, c0, tw)
        tx0, ty0 = _row_offsets(p, dy, bx, by)
        s0 = s1 = s2 = s3 = s4 = s5 = s6 = np.float32(0.0)
        for j in range(tw):
            x0, x1, x2, x3 = _w4(tx0 + p1 * dxs[j])
            y0, y1, y2, y3 = _w4(ty0 + p4 * dxs[j])
            h0 = x0 * b0[j] + x1 * b0[j + 1] + x2 * b0[j + 2] + x3 * b0[j + 3]
            h1 = x0 * b1[j] + x1 * b1[j + 1] + x2 * b1[j + 2] + x3 * b1[j + 3]
            h2 = x0 * b2[j] + x1 * b2[j + 1] + x2 * b2[j + 2] + x3 * b2[j + 3]
            h3 = x0 * b3[j] + x1 * b3[j + 1] + x2 * b3[j + 2] + x3 * b3[j + 3]
            g = (y0 * h0 + y1 * h1 + y2 * h2 + y3 * h3 - off) * mask[j]
            s0, s1, s2, s3, s4, s5, s6 = _add_pixel(
                s0, s1, s2, s3, s4, s5, s6, g, gxr[j], gyr[j], fr[j], dxs[j]
            )
        totals = _add_row_sums(q, totals, (s0, s1, s2, s3, s4, s5, s6), dy)
    return totals


@nb.njit(fastmath=FASTMATH, cache=True)
def _acc9(grow, off, mask, dxs, f, gx, gy, r, c0):  # pragma: no cover
    """Row sums of g, g^2, gx g, gx g dx, gy g, gy g dx, f g (the dy terms follow)."""
    tw = grow.shape[0]
    fr, gxr, gyr = _reference_row(f, gx, gy, r, c0, tw)
    s0 = s1 = s2 = s3 = s4 = s5 = s6 = np.float32(0.0)
    for j in range(tw):
        g = (grow[j] - off) * mask[j]
        s0, s1, s2, s3, s4, s5, s6 = _add_pixel(
            s0, s1, s2, s3, s4, s5, s6, g, gxr[j], gyr[j], fr[j], dxs[j]
        )
    return s0, s1, s2, s3, s4, s5, s6


@nb.njit(cache=True, inline="always")
def _aitken_gain6(d, prev, half):  # pragma: no cover - compiled
    """Step gain of IC-GN affine (as :func:`_aitken_gain`), ratio measured on the 6-vector
    ``(du, h dux, h duy, dv, h dvx, h dvy)`` (``h`` = subset half-width, the weights of
    the convergence norm); updates the remembered step ``prev`` in place. Returns
    ``(gain, rho, ratio)``: ``rho`` = ``(d . prev) / |prev|^2`` when the two steps are
    aligned (cos > 0.95), else 0; ``ratio`` = ``|d| / |prev|`` (0 without a previous plain
    step): the contraction of the stop test (``common.JUMP_SLACK``)."""
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
    rho = 0.0
    ratio = 0.0
    if pp > 0.0:
        ratio = math.sqrt(dd / pp)
        if dot > 0.0 and dot * dot > 0.9025 * dd * pp:
            rho = dot / pp
            if GAIN_MIN < rho < 0.97:
                for m in range(6):
                    prev[m] = 0.0
                return 1.0 / (1.0 - rho), rho, ratio
    for m in range(6):
        prev[m] = d[m]
    return 1.0, rho, ratio


#: A subset takes the 4x4 stencil (:func:`_subset_affine_cubic4`) when its warped offsets
#: past the integer base stay below this (px): a margin for the float32 rounding of the
#: per-pixel offsets, which must stay below 1.
CELL = 0.999

#: POIs per chunk of :func:`_affine_points` (its ``chunk``: scratch arrays per chunk).
CHUNK = 16


def icgn_affine(
    coef, images, subsets, cfg, p0, status_in, out, *, nthreads: int | None = None
) -> None:
    """IC-GN with the first-order (affine) shape function, ZNSSD criterion.

    Parameters ``p = (u, du/dx, du/dy, v, dv/dx, dv/dy)``; the warp of a subset pixel at
    offset ``(dx, dy)`` from the POI is ``x' = x + u + ux dx + uy dy``,
    ``y' = y + v + vx dx + vy dy`` (Pan et al. 2013, doi:10.1007/s11340-013-9717-6).

    Fast path: when the sub-pixel offsets ``x' - x`` (and ``y' - y``) of all subset pixels
    span less than one pixel, one integer base covers the subset and every sample reads
    the same ``(order+2) x (order+2)`` stencil (5x5 for cubic) at contiguous memory,
    with per-pixel weights ``beta(t - k)``, ``t`` in [0, 2): the row loop vectorises;
    cubic, when the offsets past the base all stay below :data:`CELL` along both axes,
    only the 4x4 taps that carry weight (:func:`_subset_affine_cubic4`). Otherwise each
    pixel is sampled on its own 4x4 (6x6) taps. Layout and records as in
    :func:`icgn_translation` (``cfg.width`` = ``tw``, a multiple of 8 >= subset); ``p0``
    (n, 6), ``status_in`` (n,).

    Runs the compiled serial ``nogil`` :func:`_affine_points` over chunks of
    :data:`CHUNK` POIs on ``nthreads`` threads (default: numba's thread count), scheduled
    dynamically (:func:`~.common.run_blocks`; no parfor to compile, issue 16).
    """
    n = subsets.rows.shape[0]
    nch = (n + CHUNK - 1) // CHUNK
    nthr = threads() if nthreads is None else nthreads
    args = (coef, images, subsets, cfg, p0, status_in, out)
    run_blocks(lambda c0, c1, t: _affine_points(c0, c1, *args), nch, blocks_of(nch, nthr), nthr)


def compile_icgn() -> None:
    """Compile (or load from numba's cache) the affine IC-GN kernel for the argument types
    of a correlation, running it on no POI (:func:`dicblur.dic.cache.compile_in_background`)."""
    _affine_points(0, 0, *example_args(6))


@nb.njit(fastmath=FASTMATH, cache=True, nogil=True)
def _affine_points(ch0, ch1, coef, images, subsets, cfg, p0, status_in, out):  # pragma: no cover
    """IC-GN affine of the POI chunks ``ch0:ch1`` (16 POIs each) of :func:`icgn_affine`."""
    f, gx, gy = images
    rows, cols, hinv, jsum, avec, fmean, fnorm = subsets
    himg, wimg, order, half, tw, max_iter, tol, min_zncc, max_step = cfg
    out_p, out_zncc, out_iter, out_status = out
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
    for ch in range(ch0, ch1):
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
            st = MAX_ITERATIONS
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
                    st = OUT_OF_BOUNDS
                    break
                fast = (oxmax - oxmin) < 0.999 and (oymax - oymin) < 0.999
                # a strained or wandering subset (span >= 1 px) still takes the stencil
                # path row by row when each row spans < 1 px, with the row's own base
                rowfast = fast or (
                    2.0 * half * abs(p[1]) < 0.999 and 2.0 * half * abs(p[4]) < 0.999
                )
                bx = int(math.floor(oxmin))
                by = int(math.floor(oymin))
                sg = 0.0
                sgg = 0.0
                sf = 0.0
                for m in range(6):
                    q[m] = 0.0
                if fast and order == 3 and oxmax < bx + CELL and oymax < by + CELL:
                    sg, sgg, sf = _subset_affine_cubic4(
                        coef, p, bx, by, half, r0, c0, dxs, off, mask, f, gx, gy, q
                    )
                elif rowfast and order == 3:
                    sg, sgg, sf = _subset_affine_cubic(
                        coef, p, fast, bx, by, half, r0, c0, dxs, off, mask, f, gx, gy, q
                    )
                else:
                    p1 = np.float32(p[1])
                    p4 = np.float32(p[4])
                    for i in range(size):
                        dy = i - half
                        if not fast and rowfast:
                            rx = p[0] + p[2] * dy
                            ry = p[3] + p[5] * dy
                            bx = int(math.floor(min(rx - p[1] * half, rx + p[1] * half)))
                            by = int(math.floor(min(ry - p[4] * half, ry + p[4] * half)))
                        if rowfast:
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
                                grow[j] = sample(coef, order, yy, xx)
                        row = _acc9(grow, off, mask, dxs, f, gx, gy, r0 + i, c0)
                        sg, sgg, sf = _add_row_sums(q, (sg, sgg, sf), row, dy)
                gm, dg = centred_norm(sg, sgg, npx)
                if dg == 0.0:
                    st = DIVERGED
                    break
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
                gain, rho, ratio = _aitken_gain6(dstep, dprev, half)
                # convergence on the plain (unscaled) Gauss-Newton step, as the translation:
                # |d| < tol, or the error left |d| q / (1 - q) < tol (JUMP_SLACK x tol when
                # the step is an Aitken jump) when the steps contract by q = |d| / |d_prev|
                norm = math.sqrt(
                    du * du
                    + dv * dv
                    + half * half * (dux * dux + duy * duy + dvx * dvx + dvy * dvy)
                )
                lim = tol * JUMP_SLACK if gain > 1.0 else tol
                linear = 0.0 < ratio < 0.97 and norm * ratio < lim * (1.0 - ratio)
                if linear and rho > 0.0:
                    gain = 1.0 / (1.0 - rho)
                du *= gain
                dux *= gain
                duy *= gain
                dv *= gain
                dvx *= gain
                dvy *= gain
                if not compose_inverse_affine(p, du, dux, duy, dv, dvx, dvy):
                    st = DIVERGED
                    break
                nit = it + 1
                finite = True
                for m in range(6):
                    if not math.isfinite(p[m]):
                        finite = False
                if not finite:
                    st = DIVERGED
                    break
                if norm < tol or linear:
                    st = CONVERGED
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
                    st = DIVERGED
                    break
            if st == CONVERGED and not zn >= min_zncc:
                st = LOW_CORRELATION
            out_status[k] = st
            keep = st == CONVERGED or st == MAX_ITERATIONS or st == LOW_CORRELATION
            for m in range(6):
                out_p[k, m] = p[m] if keep else np.nan
            out_zncc[k] = zn
            out_iter[k] = nit
