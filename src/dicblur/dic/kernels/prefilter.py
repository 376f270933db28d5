# ruff: noqa: RUF046  (int(math.floor(x)) gives numba an integer index)
"""B-spline prefilter of the DIC engine: the image to padded spline coefficients."""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .common import FASTMATH, PAD, blocks_of, run_blocks, threads

__all__ = ["prefilter_blocks", "prefilter_padded"]

# Block sizes: 16 rows transposed per block along x, 64 columns per block along y.
_ROWS = 16
_COLS = 64

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


@nb.njit(inline="always", fastmath=FASTMATH, cache=True)
def _pole_pass(x, j0, j1, z, gn, tol, s):  # pragma: no cover - compiled
    """One pole ``z`` of the prefilter down the rows of ``x[:, j0:j1]`` in place (the
    columns side by side: vectorised across them): the causal recursion, from its
    mirror-boundary initial value (truncated at ``tol``, or exact for a short column),
    scaled by ``gn`` (the overall gain, folded into the first pole's pass), then the
    anticausal one. ``s``: float64 scratch of at least ``j1 - j0``."""
    n = x.shape[0]
    w = j1 - j0
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


@nb.njit(fastmath=FASTMATH, cache=True, nogil=True)
def _columns_block(x, c0, c1, poles, tol, gain):  # pragma: no cover - compiled
    """In-place B-spline prefilter of the columns ``c0:c1`` of ``x``, in blocks of
    ``_COLS`` columns (recursion down the rows, vectorised across the block); mirror
    (whole-sample symmetric) boundary. Releases the GIL."""
    for j0 in range(c0, c1, _COLS):
        j1 = min(c1, j0 + _COLS)
        s = np.empty(j1 - j0, dtype=np.float64)
        first = True
        for z in poles:
            # the overall gain is folded into the first causal pass (one sweep less)
            gn = gain if first else 1.0
            first = False
            _pole_pass(x, j0, j1, z, gn, tol, s)


@nb.njit(fastmath=FASTMATH, cache=True, nogil=True)
def _rows_block(src, dst, b0, b1, poles, tol, gain):  # pragma: no cover - compiled
    """B-spline prefilter of the rows ``b0:b1`` of ``src`` into ``dst`` (may differ in
    dtype), in blocks of ``_ROWS`` rows: the rows are copied transposed into a float64
    scratch array (16 columns), so the recursion along the row runs with the rows side by
    side in contiguous memory (vectorised), then copied back. Releases the GIL."""
    for r0 in range(b0, b1, _ROWS):
        h = min(b1, r0 + _ROWS) - r0
        n = src.shape[1]
        bh = 16
        t = np.zeros((n, bh), dtype=np.float64)
        # the transposed copies four rows at a time: four contiguous row reads and one
        # 32-byte write per column (one row at a time wrote 8 bytes at a 128-byte stride:
        # the copies in and out took ~0.45 of the ~0.65 ms of this pass for 512^2)
        h4 = h - h % 4
        for r in range(0, h4, 4):
            a0, a1, a2, a3 = src[r0 + r], src[r0 + r + 1], src[r0 + r + 2], src[r0 + r + 3]
            for c in range(n):
                tc = t[c]
                tc[r], tc[r + 1], tc[r + 2], tc[r + 3] = a0[c], a1[c], a2[c], a3[c]
        for r in range(h4, h):
            row = src[r0 + r]
            for c in range(n):
                t[c, r] = row[c]
        if n > 1:
            s = np.empty(bh, dtype=np.float64)
            first = True
            for z in poles:
                gn = gain if first else 1.0
                first = False
                _pole_pass(t, 0, bh, z, gn, tol, s)
        for r in range(0, h4, 4):
            a0, a1, a2, a3 = dst[r0 + r], dst[r0 + r + 1], dst[r0 + r + 2], dst[r0 + r + 3]
            for c in range(n):
                tc = t[c]
                a0[c], a1[c], a2[c], a3[c] = tc[r], tc[r + 1], tc[r + 2], tc[r + 3]
        for r in range(h4, h):
            row = dst[r0 + r]
            for c in range(n):
                row[c] = t[c, r]


def _mirror(i: np.ndarray, n: int) -> np.ndarray:
    """Whole-sample mirror of the indices ``i`` into ``0:n``."""
    if n == 1:
        return np.zeros_like(i)
    period = 2 * n - 2
    i = np.abs(i) % period
    return np.where(i >= n, period - i, i)


def _margin(out: np.ndarray, rows: int, cols: int, pad: int) -> None:
    """The mirrored margin of ``out`` (the coefficients at its centre): copies only, in
    numpy (no kernel to compile). The margin columns of the centre rows first, then the
    margin rows as whole copies of their mirrored centre rows."""
    src = _mirror(np.arange(-pad, 0), cols) + pad
    out[pad : pad + rows, :pad] = out[pad : pad + rows, src]
    src = _mirror(np.arange(cols, cols + pad), cols) + pad
    out[pad : pad + rows, cols + pad : cols + 2 * pad] = out[pad : pad + rows, src]
    width = cols + 2 * pad
    top = _mirror(np.arange(-pad, 0), rows) + pad
    out[:pad, :width] = out[top, :width]
    bottom = _mirror(np.arange(rows, rows + pad), rows) + pad
    out[rows + pad : rows + 2 * pad, :width] = out[bottom, :width]


def prefilter_blocks(
    image: np.ndarray, out: np.ndarray, poles: np.ndarray, tol: float, nthreads: int
) -> None:
    """Padded B-spline coefficients of ``image`` into ``out`` (see
    :func:`prefilter_padded`): the rows in blocks of ``_ROWS``, then the columns in blocks
    of ``_COLS``, each stage on ``nthreads`` threads (:func:`~.common.run_blocks` over the
    compiled serial ``nogil`` block functions; no parfor to compile, issue 16), then the
    margin."""
    rows, cols = image.shape
    centre = out[PAD : PAD + rows, PAD : PAD + cols]
    gain = _gain(poles)
    run_blocks(
        lambda r0, r1, t: _rows_block(image, centre, r0, r1, poles, tol, gain),
        rows,
        blocks_of(rows, nthreads, multiple=_ROWS),
        nthreads,
    )
    if rows > 1:
        run_blocks(
            lambda j0, j1, t: _columns_block(centre, j0, j1, poles, tol, gain),
            cols,
            blocks_of(cols, nthreads, multiple=_COLS),
            nthreads,
        )
    _margin(out, rows, cols, PAD)


def prefilter_padded(image: np.ndarray, order: int, out: np.ndarray) -> None:
    """B-spline coefficients of ``image`` written into the centre of ``out``.

    ``out`` has shape ``(rows + 2*PAD, cols + 2*PAD)`` (float32 or float64, ``image`` may be
    of another float dtype); its margin receives the mirror continuation of the
    coefficients. A float32 ``out`` (the current image, once per correlation) is computed
    on numba's thread count, a float64 one (the reference, prepared once) on one thread.
    """
    poles = _POLES3 if order == 3 else _POLES5
    if out.dtype == np.float32:
        prefilter_blocks(image, out, poles, 1e-7, threads())
    else:
        prefilter_blocks(image, out, poles, 1e-14, 1)
