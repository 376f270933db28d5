"""Integer initial guesses by FFT cross-correlation (FFT-CC).

Two stages (as in OpenCorr's FFT-CC initialiser, Jiang et al., "Path-independent digital
image correlation with high accuracy, speed and robustness", Opt. Lasers Eng. 65, 2015,
and Pan, Li & Tong 2013, doi:10.1007/s11340-013-9717-6):

- :func:`global_shift`: one phase correlation of a central window (Hann-tapered) of the two
  images: finds a large rigid motion (tens of px) for the price of three FFTs;
- :func:`subset_fftcc`: per-subset zero-normalised cross-correlation over a search window
  of +-``search`` px around a guess, batched FFTs; robust to displacements of
  ``search >= subset/2`` px that vary from subset to subset.

Both return integer displacements ``(u, v)`` in px (u along columns/x, v along rows/y).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from numpy.typing import NDArray
from scipy import fft as sfft

from ..arrays import Float32Array, Float64Array, FloatArray, IndexArray, Int64Array

__all__ = ["global_shift", "subset_fftcc", "subset_fftcc_peaks", "window_spectrum"]


def _window(shape: tuple[int, int], window: int) -> tuple[slice, slice]:
    rows, cols = shape
    wr = min(window, rows)
    wc = min(window, cols)
    r0 = (rows - wr) // 2
    c0 = (cols - wc) // 2
    return slice(r0, r0 + wr), slice(c0, c0 + wc)


@lru_cache(maxsize=8)
def _taper(rows: int, cols: int) -> Float32Array:
    """The 2-D Hann taper (rows, cols) of :func:`window_spectrum`, made once per window
    shape (read-only: shared by all callers; ~0.1 ms per tracked frame otherwise)."""
    t = np.outer(np.hanning(rows), np.hanning(cols)).astype(np.float32)
    t.flags.writeable = False
    return t


def window_spectrum(
    image: FloatArray, *, window: int = 128, workers: int | None = None
) -> NDArray[np.complex64]:
    """Spectrum of the Hann-tapered, mean-free central ``window`` x ``window`` region of
    ``image`` (clipped to the image): the reference half of :func:`global_shift`, computed
    once per reference by :class:`~dicblur.dic.Correlator`."""
    sl = _window(image.shape, window)
    a = np.asarray(image[sl], dtype=np.float32)
    taper = _taper(a.shape[0], a.shape[1])
    return np.asarray(sfft.rfft2((a - a.mean()) * taper, workers=workers))


def global_shift(
    reference: FloatArray,
    current: FloatArray,
    *,
    window: int = 128,
    workers: int | None = None,
    reference_spectrum: NDArray[np.complex64] | None = None,
) -> tuple[int, int, float]:
    """Integer rigid shift ``(u, v)`` of ``current`` against ``reference`` (px).

    Phase correlation of the central ``window`` x ``window`` region (clipped to the image,
    Hann taper against edge leakage). Shifts up to about a third of the window are found.
    ``reference_spectrum``: :func:`window_spectrum` of ``reference`` (same ``window``), to
    skip recomputing it. ``workers``: threads of the FFTs (at the default window one
    thread is faster than two).

    Returns
    -------
    u, v : int
        Shift along x (columns) and y (rows), px.
    peak : float
        Height of the phase-correlation peak (0..1; near 0 means no common texture).
    """
    fa = (
        window_spectrum(reference, window=window, workers=workers)
        if reference_spectrum is None
        else reference_spectrum
    )
    fb = window_spectrum(current, window=window, workers=workers)
    wr, wc = (s.stop - s.start for s in _window(current.shape, window))
    cross = fb * np.conj(fa)
    cross /= np.maximum(np.abs(cross), 1e-12)
    corr = sfft.irfft2(cross, s=(wr, wc), workers=workers)
    idx = int(np.argmax(corr))
    dy, dx = np.unravel_index(idx, corr.shape)
    v = int(dy) if dy <= wr // 2 else int(dy) - wr
    u = int(dx) if dx <= wc // 2 else int(dx) - wc
    return u, v, float(corr.flat[idx])


def subset_fftcc_peaks(
    reference: FloatArray,
    current: FloatArray,
    rows: IndexArray,
    cols: IndexArray,
    half: int,
    *,
    guess_u: FloatArray | None = None,
    guess_v: FloatArray | None = None,
    search: int | None = None,
    chunk: int = 256,
    workers: int | None = None,
    exclude: int | None = 3,
) -> tuple[Int64Array, Int64Array, Float64Array, Float64Array]:
    """:func:`subset_fftcc` and the second-best ZNCC of each search window: the largest
    outside +-``exclude`` px of the best position (how distinct the match is; no noise
    level needed).

    Parameters
    ----------
    reference, current : ndarray, shape (rows, cols)
        Images (grey levels).
    rows, cols : ndarray of int, shape (n,)
        POI centres (the reference subset must lie inside the image).
    half : int
        Subset half-width, px.
    guess_u, guess_v : ndarray, shape (n,), optional
        Centre of the search (rounded to integers), px; default 0.
    search : int, optional
        Search half-range, px; default the subset size ``2 half + 1`` (so displacements of
        at least subset/2 px relative to the guess are found).

    Returns
    -------
    u, v : ndarray of int, shape (n,)
        Integer displacements, px.
    zncc : ndarray, shape (n,)
        Peak ZNCC (NaN where the reference subset is flat).
    second : ndarray, shape (n,)
        Largest ZNCC farther than ``exclude`` px (either axis) from the peak; all NaN
        with ``exclude=None`` (not searched: :func:`subset_fftcc`).
    """
    n = len(rows)
    size = 2 * half + 1
    s = size if search is None else int(search)
    gu = np.zeros(n, np.int64) if guess_u is None else np.rint(guess_u).astype(np.int64)
    gv = np.zeros(n, np.int64) if guess_v is None else np.rint(guess_v).astype(np.int64)
    win = size + 2 * s
    L = sfft.next_fast_len(win, real=True)
    # windows past the image edge repeat the edge pixels (clipped indices: no padded copy
    # of the whole image, which dominated a retry of a few POIs)
    cur = np.asarray(current, dtype=np.float64)
    ref = np.asarray(reference, dtype=np.float64)
    out_u = np.zeros(n, np.int64)
    out_v = np.zeros(n, np.int64)
    out_z = np.full(n, np.nan)
    out_z2 = np.full(n, np.nan)
    npx = size * size
    for start in range(0, n, chunk):
        sl = slice(start, min(n, start + chunk))
        r = rows[sl]
        c = cols[sl]
        m = len(r)
        ri = np.arange(size)
        fsub = ref[(r[:, None] - half + ri)[:, :, None], (c[:, None] - half + ri)[:, None, :]]
        fsub = fsub - fsub.mean(axis=(1, 2), keepdims=True)
        fnorm = np.sqrt((fsub**2).sum(axis=(1, 2)))
        wi = np.arange(win)
        top = r + gv[sl] - half - s
        left = c + gu[sl] - half - s
        ry = np.clip(top[:, None] + wi, 0, cur.shape[0] - 1)
        rx = np.clip(left[:, None] + wi, 0, cur.shape[1] - 1)
        gwin = cur[ry[:, :, None], rx[:, None, :]]
        ff = sfft.rfft2(fsub, s=(L, L), workers=workers)
        fg = sfft.rfft2(gwin, s=(L, L), workers=workers)
        num = sfft.irfft2(fg * np.conj(ff), s=(L, L), workers=workers)[:, : 2 * s + 1, : 2 * s + 1]
        # local energy of each candidate current subset by summed-area tables
        sat = np.zeros((m, win + 1, win + 1))
        sat[:, 1:, 1:] = gwin.cumsum(1).cumsum(2)
        sat2 = np.zeros((m, win + 1, win + 1))
        sat2[:, 1:, 1:] = (gwin**2).cumsum(1).cumsum(2)

        def box(t: Float64Array) -> Float64Array:
            return (
                t[:, size:, size:]
                - t[:, :-size, size:]
                - t[:, size:, :-size]
                + t[:, :-size, :-size]
            )

        s1 = box(sat)
        s2 = box(sat2)
        var = np.maximum(s2 - s1**2 / npx, 0.0)
        den = np.sqrt(var) * fnorm[:, None, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            zn = np.where(den > 0, num / np.where(den > 0, den, 1.0), -np.inf)
        flat = zn.reshape(m, -1)
        best = np.argmax(flat, axis=1)
        dy, dx = np.unravel_index(best, zn.shape[1:])
        out_u[sl] = gu[sl] + dx - s
        out_v[sl] = gv[sl] + dy - s
        peak = flat[np.arange(m), best]
        out_z[sl] = np.where(np.isfinite(peak) & (fnorm > 0), peak, np.nan)
        if exclude is None:
            continue
        yy = np.arange(zn.shape[1])
        near_y = np.abs(yy[None, :] - dy[:, None]) <= exclude
        near_x = np.abs(yy[None, :] - dx[:, None]) <= exclude
        away = np.where(near_y[:, :, None] & near_x[:, None, :], -np.inf, zn)
        sec = away.reshape(m, -1).max(axis=1)
        out_z2[sl] = np.where(np.isfinite(sec) & (fnorm > 0), sec, np.nan)
    return out_u, out_v, out_z, out_z2


def subset_fftcc(
    reference: FloatArray,
    current: FloatArray,
    rows: IndexArray,
    cols: IndexArray,
    half: int,
    *,
    guess_u: FloatArray | None = None,
    guess_v: FloatArray | None = None,
    search: int | None = None,
    chunk: int = 256,
    workers: int | None = None,
) -> tuple[Int64Array, Int64Array, Float64Array]:
    """Per-subset integer displacement by ZNCC over a +-``search`` px window:
    :func:`subset_fftcc_peaks` (the parameters as there) without the second peak, which
    it then does not search for (the initial guess and the retries need the best only).

    Returns
    -------
    u, v : ndarray of int, shape (n,)
        Integer displacements, px.
    zncc : ndarray, shape (n,)
        Peak ZNCC (NaN where the reference subset is flat).
    """
    u, v, z, _ = subset_fftcc_peaks(
        reference,
        current,
        rows,
        cols,
        half,
        guess_u=guess_u,
        guess_v=guess_v,
        search=search,
        chunk=chunk,
        workers=workers,
        exclude=None,
    )
    return u, v, z
