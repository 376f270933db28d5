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
(the other axis through a transpose); IC-GN is parallel over POIs, reads contiguous row
slices of the coefficient image and of the reference gradients; a rigidly translated
subset shares one set of tap weights for all its pixels, so the 4x4 (6x6) interpolation
becomes a vertical then a horizontal 4-tap (6-tap) pass over contiguous rows.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .status import PointStatus

__all__ = ["PAD", "icgn_affine", "icgn_translation", "prefilter_padded", "weights"]

#: Margin (px) of mirrored coefficients around the image (quintic needs 3 taps + 1).
PAD = 4

_CONVERGED = int(PointStatus.CONVERGED)
_MAX_ITERATIONS = int(PointStatus.MAX_ITERATIONS)
_OUT_OF_BOUNDS = int(PointStatus.OUT_OF_BOUNDS)
_DIVERGED = int(PointStatus.DIVERGED)
_LOW_CORRELATION = int(PointStatus.LOW_CORRELATION)

# Poles of the B-spline prefilters (Unser 1999, Table I).
_POLES3 = np.array([math.sqrt(3.0) - 2.0])
_POLES5 = np.array([
    math.sqrt(135.0 / 2.0 - math.sqrt(17745.0 / 4.0)) + math.sqrt(105.0 / 4.0) - 13.0 / 2.0,
    math.sqrt(135.0 / 2.0 + math.sqrt(17745.0 / 4.0)) - math.sqrt(105.0 / 4.0) - 13.0 / 2.0,
])


@nb.njit(parallel=True, fastmath=True, cache=True)
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
        for r in range(n):
            for j in range(j0, j1):
                x[r, j] = x[r, j] * gain
        for z in poles:
            horizon = int(math.ceil(math.log(tol) / math.log(abs(z))))
            for j in range(w):
                s[j] = 0.0
            if horizon < n:
                zk = 1.0
                for k in range(horizon):
                    for j in range(w):
                        s[j] += zk * x[k, j0 + j]
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
            for j in range(w):
                x[0, j0 + j] = s[j]
            for r in range(1, n):
                for j in range(j0, j1):
                    x[r, j] += z * x[r - 1, j]
            c = z / (z * z - 1.0)
            for j in range(j0, j1):
                x[n - 1, j] = c * (x[n - 1, j] + z * x[n - 2, j])
            for r in range(n - 2, -1, -1):
                for j in range(j0, j1):
                    x[r, j] = z * (x[r + 1, j] - x[r, j])


@nb.njit(parallel=True, cache=True)
def _transpose(a, out):  # pragma: no cover - compiled
    n, m = a.shape
    bs = 32
    nbr = (n + bs - 1) // bs
    for bi in nb.prange(nbr):
        i0 = bi * bs
        i1 = min(n, i0 + bs)
        for j0 in range(0, m, bs):
            j1 = min(m, j0 + bs)
            for i in range(i0, i1):
                for j in range(j0, j1):
                    out[j, i] = a[i, j]


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

    ``out`` has shape ``(rows + 2*PAD, cols + 2*PAD)`` and the dtype of ``image``; its
    margin receives the mirror continuation of the coefficients.
    """
    poles = _POLES3 if order == 3 else _POLES5
    tol = 1e-7 if image.dtype == np.float32 else 1e-14
    rows, cols = image.shape
    t = np.empty((cols, rows), dtype=image.dtype)
    _transpose(image, t)
    _filter_axis0(t, poles, tol)  # along x (columns of the image)
    centre = out[PAD:PAD + rows, PAD:PAD + cols]
    tmp = np.empty((rows, cols), dtype=image.dtype)
    _transpose(t, tmp)
    _filter_axis0(tmp, poles, tol)  # along y (rows)
    centre[...] = tmp
    _fill_margin(out, rows, cols, PAD)


@nb.njit(inline="always", fastmath=True, cache=True)
def _weights3(t, w):  # pragma: no cover - compiled
    t2 = t * t
    t3 = t2 * t
    s = 1.0 - t
    w[0] = s * s * s / 6.0
    w[1] = 2.0 / 3.0 - t2 + 0.5 * t3
    w[2] = (1.0 + 3.0 * t + 3.0 * t2 - 3.0 * t3) / 6.0
    w[3] = t3 / 6.0


@nb.njit(inline="always", fastmath=True, cache=True)
def _beta5(x):  # pragma: no cover - compiled
    a = abs(x)
    if a < 1.0:
        a2 = a * a
        return 0.55 - 0.5 * a2 + 0.25 * a2 * a2 - a2 * a2 * a / 12.0
    if a < 2.0:
        a2 = a * a
        return (17.0 / 40.0 + 0.625 * a - 1.75 * a2 + 1.25 * a2 * a - 0.375 * a2 * a2
                + a2 * a2 * a / 24.0)
    if a < 3.0:
        b = 3.0 - a
        return b * b * b * b * b / 120.0
    return 0.0


@nb.njit(inline="always", fastmath=True, cache=True)
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


@nb.njit(parallel=True, fastmath=True, cache=True)
def icgn_translation(coef, order, f, gx, gy, rows, cols, half, hinv, jsum, avec, fmean,
                     fnorm, p0, status_in, max_iter, tol, min_zncc, max_step,
                     out_p, out_zncc, out_iter, out_status):  # pragma: no cover - compiled
    """IC-GN with the zero-order (translation) shape function, ZNSSD criterion.

    Parameters ``(u, v)`` px. Per POI: ``hinv`` (2, 2) inverse exact ZNSSD Gauss-Newton
    Hessian, ``jsum`` (2,) sums of the raw steepest-descent images ``(gx, gy)``, ``avec``
    (2,) their projections on the normalised reference subset, ``fmean``/``fnorm`` mean and
    norm ``sqrt(sum (f - fmean)^2)`` of the reference subset. See ``icgn.py`` for the
    algebra (the update needs only five running sums per iteration).
    """
    n = rows.shape[0]
    size = 2 * half + 1
    taps = order + 1
    lo = (order - 1) // 2
    himg = coef.shape[0] - 2 * PAD
    wimg = coef.shape[1] - 2 * PAD
    npx = size * size
    for k in nb.prange(n):
        if status_in[k] != 0:
            out_status[k] = status_in[k]
            out_p[k, 0] = np.nan
            out_p[k, 1] = np.nan
            out_zncc[k] = np.nan
            out_iter[k] = 0
            continue
        wx = np.empty(taps, dtype=np.float64)
        wy = np.empty(taps, dtype=np.float64)
        wxf = np.empty(taps, dtype=np.float32)
        wyf = np.empty(taps, dtype=np.float32)
        tmp = np.empty(size + taps - 1, dtype=np.float32)
        grow = np.empty(size, dtype=np.float32)
        u = p0[k, 0]
        v = p0[k, 1]
        u_start = u
        v_start = v
        r0 = rows[k] - half
        c0 = cols[k] - half
        off = np.float32(fmean[k])
        st = _MAX_ITERATIONS
        zn = np.nan
        nit = 0
        for it in range(max_iter):
            x0 = c0 + u
            y0 = r0 + v
            if not (x0 >= 0.0 and y0 >= 0.0 and x0 + 2 * half <= wimg - 1
                    and y0 + 2 * half <= himg - 1):
                st = _OUT_OF_BOUNDS
                break
            ix = int(math.floor(x0))
            iy = int(math.floor(y0))
            _weights(x0 - ix, order, wx)
            _weights(y0 - iy, order, wy)
            for a in range(taps):
                wxf[a] = wx[a]
                wyf[a] = wy[a]
            sg = 0.0
            sgg = 0.0
            sx = 0.0
            sy = 0.0
            sf = 0.0
            cb = ix - lo + PAD
            for i in range(size):
                rb = iy + i - lo + PAD
                # vertical pass: taps rows -> one row of partial sums (contiguous reads)
                row = coef[rb]
                w0 = wyf[0]
                for j in range(size + taps - 1):
                    tmp[j] = w0 * row[cb + j]
                for a in range(1, taps):
                    row = coef[rb + a]
                    wa = wyf[a]
                    for j in range(size + taps - 1):
                        tmp[j] += wa * row[cb + j]
                # horizontal pass
                w0 = wxf[0]
                for j in range(size):
                    grow[j] = w0 * tmp[j]
                for b in range(1, taps):
                    wb = wxf[b]
                    for j in range(size):
                        grow[j] += wb * tmp[j + b]
                fr = f[r0 + i]
                gxr = gx[r0 + i]
                gyr = gy[r0 + i]
                rs = np.float32(0.0)
                rss = np.float32(0.0)
                rx = np.float32(0.0)
                ry = np.float32(0.0)
                rf = np.float32(0.0)
                for j in range(size):
                    g = grow[j] - off
                    rs += g
                    rss += g * g
                    rx += gxr[c0 + j] * g
                    ry += gyr[c0 + j] * g
                    rf += fr[c0 + j] * g
                sg += rs
                sgg += rss
                sx += rx
                sy += ry
                sf += rf
            gm = sg / npx
            dg2 = sgg - npx * gm * gm
            if not dg2 > 1e-12 * (sgg + 1e-30):
                st = _DIVERGED
                break
            dg = math.sqrt(dg2)
            zn = (sf - fmean[k] * sg) / (fnorm[k] * dg)
            q0 = ((sx - jsum[k, 0] * gm) / dg - avec[k, 0] * zn) / fnorm[k]
            q1 = ((sy - jsum[k, 1] * gm) / dg - avec[k, 1] * zn) / fnorm[k]
            du = hinv[k, 0, 0] * q0 + hinv[k, 0, 1] * q1
            dv = hinv[k, 1, 0] * q0 + hinv[k, 1, 1] * q1
            # inverse composition: W(p) <- W(p) o W(dp)^-1
            u -= du
            v -= dv
            nit = it + 1
            if not (math.isfinite(u) and math.isfinite(v)):
                st = _DIVERGED
                break
            if math.sqrt(du * du + dv * dv) < tol:
                st = _CONVERGED
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


@nb.njit(parallel=True, fastmath=True, cache=True)
def icgn_affine(coef, order, f, gx, gy, rows, cols, half, hinv, jsum, avec, fmean,
                fnorm, p0, status_in, max_iter, tol, min_zncc, max_step,
                out_p, out_zncc, out_iter, out_status):  # pragma: no cover - compiled
    """IC-GN with the first-order (affine) shape function, ZNSSD criterion.

    Parameters ``p = (u, du/dx, du/dy, v, dv/dx, dv/dy)``; the warp of a subset pixel at
    offset ``(dx, dy)`` from the POI is ``x' = x + u + ux dx + uy dy``,
    ``y' = y + v + vx dx + vy dy`` (Pan et al. 2013, doi:10.1007/s11340-013-9717-6).
    """
    n = rows.shape[0]
    size = 2 * half + 1
    taps = order + 1
    lo = (order - 1) // 2
    himg = coef.shape[0] - 2 * PAD
    wimg = coef.shape[1] - 2 * PAD
    npx = size * size
    for k in nb.prange(n):
        if status_in[k] != 0:
            out_status[k] = status_in[k]
            for m in range(6):
                out_p[k, m] = np.nan
            out_zncc[k] = np.nan
            out_iter[k] = 0
            continue
        wx = np.empty(taps, dtype=np.float64)
        wy = np.empty(taps, dtype=np.float64)
        q = np.empty(6, dtype=np.float64)
        p = np.empty(6, dtype=np.float64)
        for m in range(6):
            p[m] = p0[k, m]
        xc = cols[k]
        yc = rows[k]
        r0 = rows[k] - half
        c0 = cols[k] - half
        off = fmean[k]
        st = _MAX_ITERATIONS
        zn = np.nan
        nit = 0
        for it in range(max_iter):
            # bounds: an affine map sends the subset's corners to the warped extremes
            inside = True
            for cy in (-half, half):
                for cx in (-half, half):
                    xx = xc + p[0] + (1.0 + p[1]) * cx + p[2] * cy
                    yy = yc + p[3] + p[4] * cx + (1.0 + p[5]) * cy
                    if not (xx >= 0.0 and yy >= 0.0 and xx <= wimg - 1 and yy <= himg - 1):
                        inside = False
            if not inside:
                st = _OUT_OF_BOUNDS
                break
            sg = 0.0
            sgg = 0.0
            s_u = 0.0
            s_ux = 0.0
            s_uy = 0.0
            s_v = 0.0
            s_vx = 0.0
            s_vy = 0.0
            sf = 0.0
            for i in range(size):
                dy = i - half
                xrow = xc + p[0] + p[2] * dy - half * (1.0 + p[1])
                yrow = yc + p[3] + (1.0 + p[5]) * dy - half * p[4]
                fr = f[r0 + i]
                gxr = gx[r0 + i]
                gyr = gy[r0 + i]
                rs = 0.0
                rss = 0.0
                rx = 0.0
                rxd = 0.0
                ry = 0.0
                ryd = 0.0
                rf = 0.0
                for j in range(size):
                    dx = j - half
                    xx = xrow + (1.0 + p[1]) * j
                    yy = yrow + p[4] * j
                    ix = int(math.floor(xx))
                    iy = int(math.floor(yy))
                    _weights(xx - ix, order, wx)
                    _weights(yy - iy, order, wy)
                    g = 0.0
                    rb = iy - lo + PAD
                    cb = ix - lo + PAD
                    for a in range(taps):
                        crow = coef[rb + a]
                        acc = 0.0
                        for b in range(taps):
                            acc += wx[b] * crow[cb + b]
                        g += wy[a] * acc
                    g -= off
                    gxv = gxr[c0 + j] * g
                    gyv = gyr[c0 + j] * g
                    rs += g
                    rss += g * g
                    rx += gxv
                    rxd += gxv * dx
                    ry += gyv
                    ryd += gyv * dx
                    rf += fr[c0 + j] * g
                sg += rs
                sgg += rss
                s_u += rx
                s_ux += rxd
                s_uy += rx * dy
                s_v += ry
                s_vx += ryd
                s_vy += ry * dy
                sf += rf
            gm = sg / npx
            dg2 = sgg - npx * gm * gm
            if not dg2 > 1e-12 * (sgg + 1e-30):
                st = _DIVERGED
                break
            dg = math.sqrt(dg2)
            zn = (sf - fmean[k] * sg) / (fnorm[k] * dg)
            q[0] = s_u
            q[1] = s_ux
            q[2] = s_uy
            q[3] = s_v
            q[4] = s_vx
            q[5] = s_vy
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
            # inverse composition W(p) <- W(p) o W(dp)^-1 on 3x3 homogeneous matrices
            a11 = 1.0 + dux
            a12 = duy
            a21 = dvx
            a22 = 1.0 + dvy
            det = a11 * a22 - a12 * a21
            if not abs(det) > 1e-12:
                st = _DIVERGED
                break
            i11 = a22 / det
            i12 = -a12 / det
            i21 = -a21 / det
            i22 = a11 / det
            it1 = -(i11 * du + i12 * dv)
            it2 = -(i21 * du + i22 * dv)
            m11 = 1.0 + p[1]
            m12 = p[2]
            m21 = p[4]
            m22 = 1.0 + p[5]
            n11 = m11 * i11 + m12 * i21
            n12 = m11 * i12 + m12 * i22
            n21 = m21 * i11 + m22 * i21
            n22 = m21 * i12 + m22 * i22
            nu = m11 * it1 + m12 * it2 + p[0]
            nv = m21 * it1 + m22 * it2 + p[3]
            p[0] = nu
            p[1] = n11 - 1.0
            p[2] = n12
            p[3] = nv
            p[4] = n21
            p[5] = n22 - 1.0
            nit = it + 1
            finite = True
            for m in range(6):
                if not math.isfinite(p[m]):
                    finite = False
            if not finite:
                st = _DIVERGED
                break
            norm = math.sqrt(du * du + dv * dv + half * half * (dux * dux + duy * duy
                                                                  + dvx * dvx + dvy * dvy))
            if norm < tol:
                st = _CONVERGED
                break
            if (abs(p[0] - p0[k, 0]) > max_step or abs(p[3] - p0[k, 3]) > max_step
                    or abs(p[1]) > 0.5 or abs(p[2]) > 0.5 or abs(p[4]) > 0.5
                    or abs(p[5]) > 0.5):
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
