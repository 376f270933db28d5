# ruff: noqa: RUF046  (int(math.floor(x)) gives numba an integer index)
"""B-spline prefilter of the DIC engine: the image to padded spline coefficients."""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .common import FASTMATH, PAD

__all__ = ["prefilter_padded", "prefilter_parallel", "prefilter_serial"]

# Poles of the B-spline prefilters (Unser 1999, Table I).
_POLES3 = np.array([math.sqrt(3.0) - 2.0])
_POLES5 = np.array(
    [
        math.sqrt(135.0 / 2.0 - math.sqrt(17745.0 / 4.0)) + math.sqrt(105.0 / 4.0) - 13.0 / 2.0,
        math.sqrt(135.0 / 2.0 + math.sqrt(17745.0 / 4.0)) - math.sqrt(105.0 / 4.0) - 13.0 / 2.0,
    ]
)


@nb.njit(fastmath=FASTMATH, cache=True)
def _gain(poles):  # pragma: no cover - compiled
    gain = 1.0
    for z in poles:
        gain *= (1.0 - z) * (1.0 - 1.0 / z)
    return gain


@nb.njit(fastmath=FASTMATH, cache=True)
def _columns_block(x, j0, j1, poles, tol, gain):  # pragma: no cover - compiled
    """In-place B-spline prefilter of the columns ``j0:j1`` of ``x`` (recursion down the
    rows, vectorised across the block); mirror (whole-sample symmetric) boundary."""
    n = x.shape[0]
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


@nb.njit(fastmath=FASTMATH, cache=True)
def _rows_block(src, dst, r0, h, poles, tol, gain):  # pragma: no cover - compiled
    """B-spline prefilter of the rows ``r0:r0+h`` of ``src`` into ``dst`` (may differ in
    dtype): the rows are copied transposed into a float64 scratch array (16 columns), so
    the recursion along the row runs with the rows side by side in contiguous memory
    (vectorised), then copied back."""
    n = src.shape[1]
    bh = 16
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


@nb.njit(cache=True)
def _margin_row(out, r, rows, cols, pad):  # pragma: no cover - compiled
    """Row ``r`` of the mirrored margin of ``out`` (the coefficients at its centre)."""
    sr = _mirror(r - pad, rows) + pad
    for c in range(pad):
        out[r, c] = out[sr, _mirror(c - pad, cols) + pad]
        out[r, cols + pad + c] = out[sr, _mirror(cols + c, cols) + pad]
    if sr != r:
        for c in range(pad, cols + pad):
            out[r, c] = out[sr, c]


# Block sizes: 16 rows transposed per block along x, 64 columns per block along y.
_ROWS = 16
_COLS = 64


@nb.njit(parallel=True, cache=True, nogil=True)
def prefilter_parallel(image, out, poles, tol):  # pragma: no cover - compiled
    """Padded B-spline coefficients of ``image`` into ``out`` (see
    :func:`prefilter_padded`), each stage parallel over blocks. The loop bodies are calls
    of the small serial block functions above: a parfor compiles in a fraction of the time
    of the same loops inlined into its body (issue 16, first-run compile)."""
    rows, cols = image.shape
    centre = out[PAD : PAD + rows, PAD : PAD + cols]
    gain = _gain(poles)
    # int64 indices: a parfor's own index is unsigned, which would compile the block
    # functions a second time
    for blk in nb.prange((rows + _ROWS - 1) // _ROWS):
        r0 = np.int64(blk) * _ROWS
        _rows_block(image, centre, r0, min(rows, r0 + _ROWS) - r0, poles, tol, gain)
    if rows > 1:
        for blk in nb.prange((cols + _COLS - 1) // _COLS):
            j0 = np.int64(blk) * _COLS
            _columns_block(centre, j0, min(cols, j0 + _COLS), poles, tol, gain)
    # the margin is a few thousand copies: serial (one parfor less to compile)
    for r in range(rows + 2 * PAD):
        _margin_row(out, r, rows, cols, PAD)


@nb.njit(cache=True)
def prefilter_serial(image, out, poles, tol):  # pragma: no cover - compiled
    """:func:`prefilter_parallel` on one thread (the float64 reference, prepared once:
    one parallel variant less to compile)."""
    rows, cols = image.shape
    centre = out[PAD : PAD + rows, PAD : PAD + cols]
    gain = _gain(poles)
    for blk in range((rows + _ROWS - 1) // _ROWS):
        r0 = blk * _ROWS
        _rows_block(image, centre, r0, min(rows, r0 + _ROWS) - r0, poles, tol, gain)
    if rows > 1:
        for blk in range((cols + _COLS - 1) // _COLS):
            j0 = blk * _COLS
            _columns_block(centre, j0, min(cols, j0 + _COLS), poles, tol, gain)
    for r in range(rows + 2 * PAD):
        _margin_row(out, r, rows, cols, PAD)


def prefilter_padded(image: np.ndarray, order: int, out: np.ndarray) -> None:
    """B-spline coefficients of ``image`` written into the centre of ``out``.

    ``out`` has shape ``(rows + 2*PAD, cols + 2*PAD)`` (float32 or float64, ``image`` may be
    of another float dtype); its margin receives the mirror continuation of the
    coefficients.
    """
    poles = _POLES3 if order == 3 else _POLES5
    if out.dtype == np.float32:  # the current image, once per correlation: parallel
        prefilter_parallel(image, out, poles, 1e-7)
    else:  # float64: the reference, prepared once
        prefilter_serial(image, out, poles, 1e-14)
