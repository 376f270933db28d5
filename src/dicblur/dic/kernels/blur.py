"""Compiled joint (shape, blur length) Gauss-Newton step of the blur estimation (issue 18).

Kept apart from :mod:`.kernels` (the plain IC-GN kernels): the step samples each subset
pixel on its own spline taps (no fast path) because it runs once or twice per POI after
the compensated IC-GN at the image's blur length ``W0`` has converged.

Model of the normalised reference subset: ``Fh = normalise(f0 + lam D)`` with ``f0`` the
reference blurred to ``W0`` and ``D = d f0 / dW`` (a linear appearance parameter, Baker &
Matthews, IJCV 56, 2004). The Gauss-Newton matrix is held at ``lam = 0`` (constant, as in
IC-GN), so per iteration only the sums of ``g``, ``g^2``, ``f0 g``, ``D g`` and ``J^T g``
over the warped current subset are needed; the projections of ``Fh`` onto the model's
tangent vectors have the closed forms used below (``a = J_c^T fh``, ``b = D_c^T fh``,
``e = J_c^T D_c``, ``dd = D_c^T D_c``, ``Df = ||f0_c||``):

    Jh^T Fh = lam (e - a b) / (|F_c| Df),   Dh^T Fh = lam (dd - b^2) / (|F_c| Df),
    |F_c|^2 = Df^2 + 2 lam Df b + lam^2 dd.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from ...arrays import Float64Array, Int64Array, UInt8Array
from .common import (
    CONVERGED,
    DIVERGED,
    MAX_ITERATIONS,
    OUT_OF_BOUNDS,
    PAD,
    add_row,
    centred_norm,
    compose_inverse_affine,
)
from .spline import beta5

__all__ = [
    "BlurImages",
    "BlurOutputs",
    "BlurSettings",
    "BlurTerms",
    "blur_outputs",
    "blur_settings",
    "joint_blur_step",
]

# reassociation only (vectorised sums); no 'nnan'/'ninf', so the finiteness checks stay.
# The spline helpers are compiled functions of their own, not inlined into the parfor body
# at each of their call sites: a third less compile time for the same bits.
_FASTMATH = {"reassoc", "contract", "arcp", "nsz"}


# Records of the joint step's arguments, as the IC-GN kernels' (kernels/common.py); the
# per-POI subset data travel in a common.Subsets.
class BlurImages(NamedTuple):
    """Float64 reference blurred to the length ``W0``, its spline x / y derivatives and its
    derivative with respect to the blur length, ``d f0 / dW`` (rows, cols) each."""

    f: Float64Array
    gx: Float64Array
    gy: Float64Array
    d: Float64Array


class BlurTerms(NamedTuple):
    """Per-POI projections of the blur tangent ``D`` (n POIs, k shape parameters)."""

    evec: Float64Array  # (n, k) J_c^T D_c
    dsum: Float64Array  # (n,) sum D
    bval: Float64Array  # (n,) D_c^T fh
    dd: Float64Array  # (n,) D_c^T D_c


class BlurSettings(NamedTuple):
    """Scalars of one joint-step call (build with :func:`blur_settings` for stable types)."""

    image_rows: int
    image_cols: int
    order: int  # spline degree, 3 or 5
    half: int  # subset half-width, px
    affine: bool  # shape function: affine (6 parameters) or translation (2)
    max_iterations: int
    tolerance: float  # px, the IC-GN norm of the shape step
    length_tolerance: float  # px, the blur-length step


def blur_settings(
    image_rows: int,
    image_cols: int,
    order: int,
    half: int,
    affine: bool,
    max_iterations: int,
    tolerance: float,
    length_tolerance: float,
) -> BlurSettings:
    """A :class:`BlurSettings` with Python int, bool and float fields (one signature)."""
    return BlurSettings(
        int(image_rows),
        int(image_cols),
        int(order),
        int(half),
        bool(affine),
        int(max_iterations),
        float(tolerance),
        float(length_tolerance),
    )


class BlurOutputs(NamedTuple):
    """Per-POI outputs of the joint step (n POIs, k shape parameters)."""

    p: Float64Array  # (n, k) parameters
    lam: Float64Array  # (n,) blur-length correction, px
    zncc: Float64Array  # (n,)
    res2: Float64Array  # (n,) normalised squared residual
    iterations: Int64Array  # (n,)
    status: UInt8Array  # (n,) PointStatus


def blur_outputs(n: int, k: int) -> BlurOutputs:
    """Uninitialised :class:`BlurOutputs` for ``n`` POIs and ``k`` shape parameters."""
    return BlurOutputs(
        np.empty((n, k)),
        np.empty(n),
        np.empty(n),
        np.empty(n),
        np.empty(n, np.int64),
        np.empty(n, np.uint8),
    )


@nb.njit(cache=True, fastmath=_FASTMATH)
def _bspline(x, order):  # pragma: no cover - compiled
    """Centred B-spline of degree ``order`` (3: piecewise form; 5: :func:`.spline.beta5`)."""
    a = abs(x)
    if order == 3:
        if a < 1.0:
            return 2.0 / 3.0 - a * a + 0.5 * a * a * a
        if a < 2.0:
            b = 2.0 - a
            return b * b * b / 6.0
        return 0.0
    return beta5(x)


@nb.njit(cache=True, fastmath=_FASTMATH)
def _sample(coef, order, y, x, wy, wx):  # pragma: no cover - compiled
    """One spline sample at image position (y, x), tap weights into ``wy``, ``wx``."""
    lo = (order - 1) // 2
    ix = int(math.floor(x))  # noqa: RUF046 - numba needs the int
    iy = int(math.floor(y))  # noqa: RUF046 - numba needs the int
    tx = x - ix
    ty = y - iy
    for a in range(order + 1):
        wy[a] = _bspline(ty - (a - lo), order)
        wx[a] = _bspline(tx - (a - lo), order)
    r0 = iy - lo + PAD
    c0 = ix - lo + PAD
    g = 0.0
    for a in range(order + 1):
        acc = 0.0
        for b in range(order + 1):
            acc += wx[b] * coef[r0 + a, c0 + b]
        g += wy[a] * acc
    return g


@nb.njit(cache=True)
def _store(out, pt, status, iterations, keep, p, lam, zncc, res2):  # pragma: no cover
    """Write POI ``pt``'s results into ``out`` (a :class:`BlurOutputs`): the parameters
    ``p``, ``lam``, ``zncc`` and ``res2`` when ``keep``, else NaN.

    A call, not stores in the parfor body: numba's parfor dead-code elimination drops
    stores into arrays reached through a tuple argument (its alias analysis skips
    immutable types, and a named tuple is one; seen with numba 0.68.1: ``lam``, ``zncc``
    and ``res2`` came out NaN), so every output goes through this function."""
    out_p, out_lam, out_z, out_res2, out_iter, out_status = out
    out_status[pt] = status
    out_iter[pt] = iterations
    for m in range(p.shape[0]):
        out_p[pt, m] = p[m] if keep else np.nan
    out_lam[pt] = lam if keep else np.nan
    out_z[pt] = zncc if keep else np.nan
    out_res2[pt] = res2 if keep else np.nan


@nb.njit(parallel=True, cache=True, fastmath=_FASTMATH)
def joint_blur_step(
    coef, images, subsets, terms, cfg, p_in, status_in, out
):  # pragma: no cover - compiled
    """Joint Gauss-Newton in the shape parameters and the blur-length correction ``lam``.

    ``coef`` the padded spline coefficients of the current image; ``images``
    (:class:`BlurImages`) the reference blurred to ``W0`` and its derivatives;
    ``subsets`` (:class:`~dicblur.dic.kernels.Subsets`, ``hinv`` of shape (n, k+1, k+1):
    the inverse Gauss-Newton matrix in ``(p, lam)``) and ``terms`` (:class:`BlurTerms`)
    the prepared per-POI quantities (:func:`dicblur.dic.compensation.prepare_blur_step`);
    ``cfg`` (:class:`BlurSettings`, from :func:`blur_settings`) the scalars; ``p_in``
    (n, k) and ``status_in`` (n,) the compensated IC-GN result; ``out``
    (:class:`BlurOutputs`, from :func:`blur_outputs`) written in place.

    Points with ``status_in != 0`` are copied through (``lam`` NaN). ``p`` as the IC-GN
    kernels (translation ``(u, v)``; affine ``(u, ux, uy, v, vx, vy)``), updated by inverse
    composition; ``lam`` additively. Outputs: parameters, ``lam`` (px), ZNCC of the model
    ``Fh`` with the warped current subset, the normalised squared residual
    ``|gh - Fh|^2 = 2 - 2 zncc``, iterations, status (``OUT_OF_BOUNDS``, ``DIVERGED``,
    ``MAX_ITERATIONS`` or ``CONVERGED``). Converged when the shape step meets
    ``cfg.tolerance`` (the IC-GN norm) and the length step ``cfg.length_tolerance`` (px).
    """
    f, gx, gy, dimg = images
    rows, cols, hinv, jsum, avec, fmean, fnorm = subsets
    evec, dsum, bval, dd = terms
    himg, wimg, order, half, affine, max_iter, tol, lam_tol = cfg
    n = rows.shape[0]
    k = 6 if affine else 2
    size = 2 * half + 1
    npx = size * size
    for pt in nb.prange(n):
        q = np.zeros(k + 1)
        rhs = np.zeros(k + 1)
        stp = np.zeros(k + 1)
        p = np.empty(k)
        wy = np.empty(order + 1)
        wx = np.empty(order + 1)
        hbuf = np.empty((size + order, size))
        grow = np.empty(size)
        for m in range(k):
            p[m] = p_in[pt, m]
        if status_in[pt] != 0:
            _store(out, pt, status_in[pt], 0, True, p, np.nan, np.nan, np.nan)
            continue
        lam = 0.0
        xc = cols[pt]
        yc = rows[pt]
        r0 = yc - half
        c0 = xc - half
        df = fnorm[pt]
        st = MAX_ITERATIONS
        zf = np.nan
        nit = 0
        for it in range(max_iter):
            inside = True
            for cy in (-half, half):
                for cx in (-half, half):
                    if affine:
                        ox = p[0] + p[1] * cx + p[2] * cy
                        oy = p[3] + p[4] * cx + p[5] * cy
                    else:
                        ox = p[0]
                        oy = p[1]
                    x = xc + cx + ox
                    y = yc + cy + oy
                    if not (x >= 0.0 and y >= 0.0 and x <= wimg - 1 and y <= himg - 1):
                        inside = False
            if not inside:
                st = OUT_OF_BOUNDS
                break
            sg = 0.0
            sgg = 0.0
            sfg = 0.0
            for m in range(k + 1):
                q[m] = 0.0
            if not affine:
                # translation: every pixel has the same sub-pixel offset, so the spline is
                # separable on one set of taps: one pass along x into hbuf, one along y
                bx = int(math.floor(xc + p[0]))  # noqa: RUF046 - numba needs the int
                by = int(math.floor(yc + p[1]))  # noqa: RUF046 - numba needs the int
                lo = (order - 1) // 2
                for a in range(order + 1):
                    wy[a] = _bspline(yc + p[1] - by - (a - lo), order)
                    wx[a] = _bspline(xc + p[0] - bx - (a - lo), order)
                rb = by - half - lo + PAD
                cb = bx - half - lo + PAD
                # tap loops outside, pixel loops inside: contiguous, vectorisable
                for r in range(size + order):
                    w0 = wx[0]
                    for j in range(size):
                        hbuf[r, j] = w0 * coef[rb + r, cb + j]
                    for b in range(1, order + 1):
                        wb = wx[b]
                        for j in range(size):
                            hbuf[r, j] += wb * coef[rb + r, cb + j + b]
            for i in range(size):
                dyo = float(i - half)
                if affine:
                    for j in range(size):
                        dxo = float(j - half)
                        x = xc + p[0] + (1.0 + p[1]) * dxo + p[2] * dyo
                        y = yc + p[3] + p[4] * dxo + (1.0 + p[5]) * dyo
                        grow[j] = _sample(coef, order, y, x, wy, wx)
                else:
                    w0 = wy[0]
                    for j in range(size):
                        grow[j] = w0 * hbuf[i, j]
                    for a in range(1, order + 1):
                        wa = wy[a]
                        for j in range(size):
                            grow[j] += wa * hbuf[i + a, j]
                # row sums in scalars (a vectorisable reduction)
                s_g = 0.0
                s_gg = 0.0
                s_fg = 0.0
                s_x = 0.0
                s_y = 0.0
                s_xd = 0.0
                s_yd = 0.0
                s_d = 0.0
                ri = r0 + i
                for j in range(size):
                    g = grow[j]
                    cj = c0 + j
                    tx = gx[ri, cj] * g
                    ty = gy[ri, cj] * g
                    s_g += g
                    s_gg += g * g
                    s_fg += f[ri, cj] * g
                    s_x += tx
                    s_y += ty
                    s_xd += tx * (j - half)
                    s_yd += ty * (j - half)
                    s_d += dimg[ri, cj] * g
                sg += s_g
                sgg += s_gg
                sfg += s_fg
                if affine:
                    add_row(q, s_x, s_xd, s_y, s_yd, dyo)
                else:
                    q[0] += s_x
                    q[1] += s_y
                q[k] += s_d
            gm, dg = centred_norm(sg, sgg, npx)
            if dg == 0.0:
                st = DIVERGED
                break
            nf2 = df * df + 2.0 * lam * df * bval[pt] + lam * lam * dd[pt]
            if not nf2 > 0.0:
                st = DIVERGED
                break
            nf = math.sqrt(nf2)
            zn0 = (sfg - fmean[pt] * sg) / (df * dg)
            zf = ((sfg + lam * q[k]) - (fmean[pt] + lam * dsum[pt] / npx) * sg) / (nf * dg)
            for m in range(k):
                rhs[m] = (
                    ((q[m] - jsum[pt, m] * gm) / dg - avec[pt, m] * zn0)
                    - lam * (evec[pt, m] - avec[pt, m] * bval[pt]) / nf
                ) / df
            rhs[k] = (
                ((q[k] - dsum[pt] * gm) / dg - bval[pt] * zn0)
                - lam * (dd[pt] - bval[pt] * bval[pt]) / nf
            ) / df
            for m in range(k + 1):
                acc = 0.0
                for l_ in range(k + 1):
                    acc += hinv[pt, m, l_] * rhs[l_]
                stp[m] = acc
            lam += stp[k]
            if affine:
                du, dux, duy, dv, dvx, dvy = stp[0], stp[1], stp[2], stp[3], stp[4], stp[5]
                if not compose_inverse_affine(p, du, dux, duy, dv, dvx, dvy):
                    st = DIVERGED
                    break
                norm = math.sqrt(
                    du * du
                    + dv * dv
                    + half * half * (dux * dux + duy * duy + dvx * dvx + dvy * dvy)
                )
            else:
                p[0] -= stp[0]
                p[1] -= stp[1]
                norm = math.hypot(stp[0], stp[1])
            nit = it + 1
            finite = math.isfinite(lam)
            for m in range(k):
                if not math.isfinite(p[m]):
                    finite = False
            if not finite or abs(lam) > size:
                st = DIVERGED
                break
            if norm < tol and abs(stp[k]) < lam_tol:
                st = CONVERGED
                break
        keep = st == CONVERGED or st == MAX_ITERATIONS
        _store(out, pt, st, nit, keep, p, lam, zf, 2.0 - 2.0 * zf)
