"""Lack-of-fit test of the translation shape function: does a deformation the subset
cannot follow (a strain, a rotation) explain its ZNSSD residual?

The residual screen compares a subset's residual with the noise, but the noise it uses is
at least the field's median residual (so a pair that differs everywhere is not flagged as
a whole), and with ``noise_sigma="auto"`` the noise is estimated from those very
residuals: under a uniform strain every translation subset carries the same model error,
the median absorbs it and none stands out (a 5 % zoom at subset 21: residual variances of
~120 GL^2 against 4 GL^2 of noise, errors of median 0.07 px and up to 0.25 px against a
predicted sigma of 0.03 px, all ``CONVERGED``).

This test needs no noise level. At the converged ``(u, v)`` the residual ``e = gh - fh``
(unit-norm zero-mean subsets, ZNSSD) is regressed on the Gauss-Newton directions of the
affine shape's four gradient parameters, ``(gx dx, gx dy, gy dx, gy dy)``, after those of
translation and gain (``gx``, ``gy``, ``fh``), and the F statistic of the extra four

    F = ((RSS_t - RSS_a) / 4) / (RSS_a / (npx - 8))

is ``F(4, npx - 8)`` distributed when the translation shape holds (noise only; the
classical extra-sum-of-squares test of nested linear models, e.g. Seber & Lee, Linear
Regression Analysis, 2nd ed., Wiley 2003, sec. 4.3). ``F`` far above its quantiles means
the subset's displacement varies across it: its translation estimate is biased by the
shape function, not only noisy.
"""

from __future__ import annotations

import numpy as np

from ..arrays import Float64Array, FloatArray, IndexArray
from .interpolation import PAD, bspline_kernel

__all__ = ["LACK_OF_FIT_F", "LACK_OF_FIT_SAMPLE", "translation_lack_of_fit"]

#: ``HIGH_RESIDUAL`` when the lack-of-fit F statistic of a translation subset exceeds
#: this. For noise alone F ~ F(4, 433) at subset 21 (1e-6 upper quantile ~7.8). Measured
#: at 2 GL, 256^2, subset 21 (docs/dic.md, "Lack of fit"): correct matches of a shifted
#: speckle, blobs, thresholded pattern reach F 4.8-7.9, the hard dots 37; a zoom of 0.5 %
#: gives a median 38 (errors up to 0.04 px, kept), 1 % 149, 5 % 1680 (errors to 0.25 px).
LACK_OF_FIT_F = 100.0

#: POIs of a field the screen tests first (evenly spread); the rest only when one fails.
LACK_OF_FIT_SAMPLE = 8


def translation_lack_of_fit(
    reference: Float64Array,
    grad: tuple[Float64Array, Float64Array],
    coefficients: FloatArray,
    order: int,
    rows: IndexArray,
    cols: IndexArray,
    half: int,
    u: Float64Array,
    v: Float64Array,
) -> Float64Array:
    """The lack-of-fit F statistic of the translation shape at each POI's result.

    Parameters
    ----------
    reference : ndarray, shape (rows, cols)
        Reference image, GL.
    grad : (gy, gx) of ndarrays, shape (rows, cols)
        Reference spline gradients along rows and columns, GL/px.
    coefficients : ndarray, shape (rows + 2 PAD, cols + 2 PAD [+ margin])
        Padded B-spline coefficients of the current image.
    order : {3, 5}
        Spline degree.
    rows, cols : ndarray of int, shape (n,)
        POI centres (px), subsets inside the reference.
    half : int
        Subset half-width (px).
    u, v : ndarray, shape (n,)
        The converged displacements (px, columns and rows); warped subsets inside the
        padded margin.

    Returns
    -------
    ndarray, shape (n,)
        F statistic (dimensionless; NaN for a flat subset).
    """
    n = rows.shape[0]
    d = np.arange(-half, half + 1, dtype=np.float64)
    dy, dx = (a.ravel() for a in np.meshgrid(d, d, indexing="ij"))
    npx = dy.size
    out = np.full(n, np.nan)
    gy_img, gx_img = grad
    # in blocks: (block, npx, 7) float64 stays small
    block = 256
    for s in range(0, n, block):
        r = rows[s : s + block, None] + dy.astype(np.intp)[None, :]
        c = cols[s : s + block, None] + dx.astype(np.intp)[None, :]
        f = reference[r, c]
        g = _shifted_subsets(
            coefficients, order, rows[s : s + block], cols[s : s + block], half,
            u[s : s + block], v[s : s + block],
        ).reshape(f.shape)  # fmt: skip
        f = f - f.mean(axis=1, keepdims=True)
        g = g - g.mean(axis=1, keepdims=True)
        with np.errstate(invalid="ignore", divide="ignore"):
            fh = f / np.linalg.norm(f, axis=1, keepdims=True)
            gh = g / np.linalg.norm(g, axis=1, keepdims=True)
        e = gh - fh
        gx, gy = gx_img[r, c], gy_img[r, c]
        cols7 = np.stack([fh, gx, gy, gx * dx, gx * dy, gy * dx, gy * dy], axis=2)
        cols7 -= cols7.mean(axis=1, keepdims=True)
        bad = ~np.all(np.isfinite(cols7), axis=(1, 2)) | ~np.all(np.isfinite(e), axis=1)
        cols7[bad] = 0.0
        e[bad] = 0.0
        # normal equations of the nested fits (3 and 7 columns): explained sums of squares
        xtx = np.matmul(cols7.transpose(0, 2, 1), cols7)
        xte = np.matmul(cols7.transpose(0, 2, 1), e[:, :, None])[..., 0]
        xtx[bad] = np.eye(7)
        ee = np.einsum("np,np->n", e, e)
        b3 = np.linalg.solve(xtx[:, :3, :3], xte[:, :3, None])[..., 0]
        b7 = np.linalg.solve(xtx, xte[:, :, None])[..., 0]
        rss_t = ee - np.einsum("nk,nk->n", b3, xte[:, :3])
        rss_a = ee - np.einsum("nk,nk->n", b7, xte)
        with np.errstate(invalid="ignore", divide="ignore"):
            fstat = ((rss_t - rss_a) / 4.0) / (rss_a / (npx - 8))
        fstat[bad] = np.nan
        out[s : s + block] = fstat
    return out


def _shifted_subsets(
    coefficients: FloatArray,
    order: int,
    rows: IndexArray,
    cols: IndexArray,
    half: int,
    u: Float64Array,
    v: Float64Array,
) -> Float64Array:
    """The current image's spline at each subset's pixels moved by ``(v, u)``, shape
    (n, 2 half + 1, 2 half + 1): one fractional offset per subset, so the tap weights are
    per subset and the interpolation is two separable passes over a coefficient block."""
    w = 2 * half + 1
    lo = -(order - 1) // 2
    taps = np.arange(order + 1) + lo
    fy, fx = np.floor(v), np.floor(u)
    wy = bspline_kernel((v - fy)[:, None] - taps[None, :], order)
    wx = bspline_kernel((u - fx)[:, None] - taps[None, :], order)
    r0 = rows + fy.astype(np.intp) - half + lo + PAD
    c0 = cols + fx.astype(np.intp) - half + lo + PAD
    span = np.arange(w + order)
    blk = np.asarray(coefficients)[
        r0[:, None, None] + span[None, :, None], c0[:, None, None] + span[None, None, :]
    ].astype(np.float64)
    tmp = sum(wy[:, a, None, None] * blk[:, a : a + w, :] for a in range(order + 1))
    return sum(wx[:, b, None, None] * tmp[:, :, b : b + w] for b in range(order + 1))
