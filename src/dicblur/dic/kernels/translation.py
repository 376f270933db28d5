# ruff: noqa: RUF046  (int(math.floor(x)) gives numba an integer index)
"""IC-GN kernel of the translation shape function (flat padded buffers)."""

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
    Packed,
    Passes,
    centred_norm,
    example_args,
)
from .spline import weights_into

__all__ = [
    "compile_icgn",
    "flat_lengths",
    "flat_width",
    "icgn_translation",
    "pack_reference",
]


@nb.njit(cache=True, inline="always")
def _aitken_gain(du, dv, pdu, pdv):  # pragma: no cover - compiled
    """Step gain of IC-GN translation, the measured contraction, and the previous step to
    remember: ``(gain, rho, ratio, pdu, pdv)``.

    Against a blurred current image the sharp reference's Gauss-Newton steps shrink
    geometrically, by a factor rho per iteration (slow linear convergence: 88 iterations
    on average at W = 10 px). Two plain, aligned steps give rho = (d . d_prev) / |d_prev|^2;
    scaling the step by 1 / (1 - rho) jumps to the limit of the geometric series (Aitken's
    delta-squared process). Fast-converging subsets (rho < ``GAIN_MIN``) keep plain steps,
    and after a jump the memory is cleared so the next ratio is measured on plain steps
    again. ``rho`` is 0 unless the steps are aligned (cos > 0.95); ``ratio`` =
    ``|d| / |d_prev|`` (0 without a previous plain step) is the contraction of the stop
    test (``common.JUMP_SLACK``).
    """
    pp = pdu * pdu + pdv * pdv
    if pp > 0.0:
        dd = du * du + dv * dv
        dot = du * pdu + dv * pdv
        ratio = math.sqrt(dd / pp)
        # aligned (cos > 0.95) and shrinking by a steady factor
        if dot > 0.0 and dot * dot > 0.9025 * dd * pp:
            rho = dot / pp
            if GAIN_MIN < rho < 0.97:
                return 1.0 / (1.0 - rho), rho, ratio, 0.0, 0.0
            return 1.0, rho, ratio, du, dv
        return 1.0, 0.0, ratio, du, dv
    return 1.0, 0.0, 0.0, du, dv


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


@nb.njit(fastmath=FASTMATH, cache=True)
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


@nb.njit(cache=True)
def pack_reference(images, subsets, half, w, status, packed):  # pragma: no cover - compiled
    """Flat reference subsets of all POIs (rows of ``packed.f``, ``.gx``, ``.gy``, shape
    (n, ng)) for :func:`icgn_translation`, prepared once with the reference (one thread: a
    few ms, and no parallel variant to compile)."""
    size = 2 * half + 1
    rows = subsets.rows
    cols = subsets.cols
    for k in range(rows.shape[0]):
        if status[k] == 0:
            _load_reference(
                images.f,
                images.gx,
                images.gy,
                subsets.fmean[k],
                rows[k] - half,
                cols[k] - half,
                size,
                w,
                packed.f[k],
                packed.gx[k],
                packed.gy[k],
            )


@nb.njit(fastmath=FASTMATH, cache=True)
def _sums_translation(
    coef, rb, cb, order, size, w, wxf, wyf, cbuf, hbuf, off, maskf, fp, gxp, gyp
):  # pragma: no cover
    """The five sums of one translation IC-GN iteration over the flat subset.

    ``g = sum_a wy_a sum_b wx_b c[rb + row + a, cb + col + b] - off``; returns
    ``(sum m g, sum m g^2, sum m gx g, sum m gy g, sum m (f - fmean) g)`` with the 0/1
    mask ``m`` of the subset pixels in the flat layout. Shifted reads go through slices
    (non-negative loop indices: no wraparound selects, so the loops vectorise without
    gathers). The arrays stay separate arguments, not the tuples of
    :func:`_point_translation`: passed packed, this per-iteration call measured 1-4 %
    slower (512^2, subset 21, one thread).
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


@nb.njit(fastmath=FASTMATH, cache=True)
def _points_translation(
    todo, m0, m1, source, coef, images, subsets, packed, cfg, p0, status_in, bufs, out
):  # pragma: no cover
    """IC-GN translation of the POIs ``todo[m0:m1]`` (see :func:`icgn_translation`): one call
    per chunk of POIs; ``bufs``: this thread's flat buffers ``(maskf, cbuf, hbuf, fp, gxp,
    gyp)``."""
    out_p, out_zncc, out_iter, out_status = out
    is_packed = packed.f.shape[0] > 0
    # tap weights: private to this call (per-thread rows of one small array would share a
    # cache line between the threads and bounce it on every iteration)
    taps = cfg.order + 1
    wx = np.empty(taps, dtype=np.float64)
    wy = np.empty(taps, dtype=np.float64)
    wxf = np.empty(taps, dtype=np.float32)
    wyf = np.empty(taps, dtype=np.float32)
    maskf, cbuf, hbuf, fps, gxps, gyps = bufs
    work = (wx, wy, wxf, wyf, cbuf, hbuf, maskf)
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
            if out_status[s] == CONVERGED:
                u = out_p[s, 0]
                v = out_p[s, 1]
        # one call site (one compiled signature): the packed rows or this thread's buffers
        if is_packed:
            flat = (packed.f[k], packed.gx[k], packed.gy[k])
        else:
            flat = (fps, gxps, gyps)
        _point_translation(k, u, v, coef, images, subsets, cfg, work, flat, not is_packed, out)


@nb.njit(fastmath=FASTMATH, cache=True)
def _point_translation(
    k, u, v, coef, images, subsets, cfg, work, flat, load, out
):  # pragma: no cover - compiled
    """IC-GN translation of POI ``k`` started at ``(u, v)``; writes row ``k`` of the
    outputs. ``work``: the scratch of :func:`_points_translation`, ``(wx, wy, wxf, wyf,
    cbuf, hbuf, maskf)`` (tap weights in float64 and float32, the copied and the filtered
    coefficient rows, the flat subset mask); ``flat``: the flat reference subset ``(f -
    fmean, gx, gy)``, loaded here first when ``load``."""
    f, gx, gy = images
    wx, wy, wxf, wyf, cbuf, hbuf, maskf = work
    fp, gxp, gyp = flat
    rows, cols, hinv, jsum, avec, fmean, fnorm = subsets
    himg, wimg, order, half, w, max_iter, tol, min_zncc, max_step = cfg
    out_p, out_zncc, out_iter, out_status = out
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
    st = MAX_ITERATIONS
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
            st = OUT_OF_BOUNDS
            break
        ix = int(math.floor(x0))
        iy = int(math.floor(y0))
        weights_into(x0 - ix, order, wx)
        weights_into(y0 - iy, order, wy)
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
        gm, dg = centred_norm(sg, sgg, npx)
        if dg == 0.0:
            st = DIVERGED
            break
        zn = sfc / (fnorm[k] * dg)
        q0 = ((sx - jsum[k, 0] * gm) / dg - avec[k, 0] * zn) / fnorm[k]
        q1 = ((sy - jsum[k, 1] * gm) / dg - avec[k, 1] * zn) / fnorm[k]
        du = hinv[k, 0, 0] * q0 + hinv[k, 0, 1] * q1
        dv = hinv[k, 1, 0] * q0 + hinv[k, 1, 1] * q1
        gain, rho, ratio, pdu, pdv = _aitken_gain(du, dv, pdu, pdv)
        # stop: |d| < tol, or the error left |d| q / (1 - q) < tol (JUMP_SLACK x tol when the
        # step is an Aitken jump) when the steps contract by q = |d| / |d_prev|
        norm = math.sqrt(du * du + dv * dv)
        lim = tol * JUMP_SLACK if gain > 1.0 else tol
        linear = 0.0 < ratio < 0.97 and norm * ratio < lim * (1.0 - ratio)
        if linear and rho > 0.0:
            gain = 1.0 / (1.0 - rho)
        # inverse composition: W(p) <- W(p) o W(dp)^-1
        u -= gain * du
        v -= gain * dv
        nit = it + 1
        if not (math.isfinite(u) and math.isfinite(v)):
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
        if abs(u - u_start) > max_step or abs(v - v_start) > max_step:
            st = DIVERGED
            break
    if st == CONVERGED and not zn >= min_zncc:
        st = LOW_CORRELATION
    out_status[k] = st
    if st == CONVERGED or st == MAX_ITERATIONS or st == LOW_CORRELATION:
        out_p[k, 0] = u
        out_p[k, 1] = v
    else:
        out_p[k, 0] = np.nan
        out_p[k, 1] = np.nan
    out_zncc[k] = zn
    out_iter[k] = nit


@nb.njit(parallel=True, fastmath=FASTMATH, cache=True, nogil=True)
def icgn_translation(
    coef, images, subsets, packed, cfg, p0, status_in, passes, nthr, out
):  # pragma: no cover - compiled
    """IC-GN with the zero-order (translation) shape function, ZNSSD criterion.

    Parameters ``(u, v)`` px. Per POI: ``hinv`` (2, 2) inverse exact ZNSSD Gauss-Newton
    Hessian, ``jsum`` (2,) sums of the raw steepest-descent images ``(gx, gy)``, ``avec``
    (2,) their projections on the normalised reference subset, ``fmean``/``fnorm`` mean and
    norm ``sqrt(sum (f - fmean)^2)`` of the reference subset. See ``icgn.py`` for the
    algebra (the update needs only five running sums per iteration).

    Arguments are records (:mod:`.common`): ``images`` (:class:`ReferenceImages`),
    ``subsets`` (:class:`Subsets`, the per-POI data above), ``packed`` (:class:`Packed`),
    ``cfg`` (:class:`Settings`, ``width`` = ``w``), ``passes`` (:class:`Passes`), ``out``
    (:class:`Outputs`); ``p0`` (n, 2) and ``status_in`` (n,) per call.

    Two passes in one call (one dispatch): the POIs ``passes.first`` start at ``p0[k]``;
    then each POI ``second[m]`` starts at the result of POI ``source[m]`` when that
    converged, else at its own ``p0``. Outputs (all of length n, indexed by POI) are
    written only for the POIs listed. ``status_in[k] != 0`` is passed through. ``nthr``:
    numba's thread count limit (``numba.config.NUMBA_NUM_THREADS``, sizes the per-thread
    buffers).

    Layout: ``coef`` holds the padded coefficients of the current image (image pixel
    ``(r, c)`` at ``(r + PAD, c + PAD)``) with at least ``w`` extra columns on the right;
    ``images.f``, ``.gx``, ``.gy`` are float32 images with at least ``w`` extra columns.
    ``w`` is :func:`flat_width`. ``packed``: the flat reference subsets from
    :func:`pack_reference`, shape (n, ng), or shape (0, ng) to copy them per POI into
    per-thread buffers instead (when n x ng is too large to keep).
    """
    maskf, cbufs, hbufs, fps, gxps, gyps = _translation_buffers(cfg, nthr, packed.f.shape[0] == 0)
    first, second, source = passes
    chunk = 16
    for npass in range(2):
        todo = first if npass == 0 else second
        src = source[:0] if npass == 0 else source
        nch = (todo.shape[0] + chunk - 1) // chunk
        for c in nb.prange(nch):
            t = nb.get_thread_id()
            m0 = np.int64(c) * chunk  # int64: the parfor's own index is unsigned
            _points_translation(
                todo,
                m0,
                min(todo.shape[0], m0 + chunk),
                src,
                coef,
                images,
                subsets,
                packed,
                cfg,
                p0,
                status_in,
                (maskf, cbufs[t], hbufs[t], fps[t], gxps[t], gyps[t]),
                out,
            )


@nb.njit(cache=True)
def _translation_buffers(cfg, nthr, copy):  # pragma: no cover - compiled
    """Mask and per-thread flat buffers of :func:`icgn_translation` (``copy``: buffers for
    the per-call copies of the reference subsets too)."""
    half = cfg.half
    w = cfg.width
    order = cfg.order
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
    nl = ng if copy else 0
    fps = np.zeros((nthr, nl), dtype=np.float32)
    gxps = np.zeros((nthr, nl), dtype=np.float32)
    gyps = np.zeros((nthr, nl), dtype=np.float32)
    return maskf, cbufs, hbufs, fps, gxps, gyps


def compile_icgn() -> None:
    """Compile (or load from numba's cache) the translation IC-GN kernel for the argument
    types of a correlation, running it on no POI
    (:func:`dicblur.dic.cache.compile_in_background`)."""
    coef, images, subsets, cfg, p0, status_in, out = example_args(2)
    none = np.zeros(0, np.intp)
    packed = Packed(*(np.zeros((0, 32), np.float32) for _ in range(3)))
    icgn_translation(
        coef, images, subsets, packed, cfg, p0, status_in, Passes(none, none, none), 1, out
    )
