"""Shared synthetic data for the DIC tests (independent of the engine); the DIC benchmarks
import it too (``benchmarks/_harness.use_tests_dir``)."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from dicblur import speckle_pattern


def fourier_shift(image: np.ndarray, dy: float, dx: float) -> np.ndarray:
    """Exact periodic translation: content moves by (+dy, +dx) px."""
    ky = np.fft.fftfreq(image.shape[0])[:, None]
    kx = np.fft.fftfreq(image.shape[1])[None, :]
    return np.fft.ifft2(np.fft.fft2(image) * np.exp(-2j * np.pi * (ky * dy + kx * dx))).real


def pattern(n: int = 128, seed: int = 1) -> np.ndarray:
    """Band-limited enough speckle (soft edges) for sub-pixel shifts by Fourier shift."""
    return speckle_pattern((n, n), speckle_size=4, softness=1.0, seed=seed)


def affine_warp(image: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Current image of a body deformed by x' = c + A (x - c) (A 2x2 on (x, y))."""
    n_r, n_c = image.shape
    cy, cx = (n_r - 1) / 2, (n_c - 1) / 2
    yy, xx = np.mgrid[0:n_r, 0:n_c].astype(float)
    inv = np.linalg.inv(a)
    xs = cx + inv[0, 0] * (xx - cx) + inv[0, 1] * (yy - cy)
    ys = cy + inv[1, 0] * (xx - cx) + inv[1, 1] * (yy - cy)
    return ndimage.map_coordinates(image, [ys, xs], order=5, mode="grid-wrap")


def blobs(
    shape: tuple[int, int],
    *,
    density: float = 0.008,
    sigma: tuple[float, float] = (2.0, 3.0),
    amplitude: tuple[float, float] = (50, 300),
    background: float = 10.0,
    clip: tuple[float, float] = (10.0, 245.0),
    seed: int = 3,
) -> np.ndarray:
    """Sparse Gaussian blobs at uniform random centres, clipped to ``clip`` GL (the hostile
    image of issue 15, also measured by ``benchmarks/bench_dic_robust.py``): saturated
    plateaus and flat gaps."""
    rng = np.random.default_rng(seed)
    h, w = shape
    n = int(density * h * w)
    ys, xs = rng.uniform(0, h, n), rng.uniform(0, w, n)
    ss, aa = rng.uniform(*sigma, n), rng.uniform(*amplitude, n)
    img = np.full(shape, float(background))
    for y, x, s, a in zip(ys, xs, ss, aa, strict=True):
        r = int(np.ceil(4 * s))
        y0, y1 = max(0, int(y) - r), min(h, int(y) + r + 1)
        x0, x1 = max(0, int(x) - r), min(w, int(x) + r + 1)
        yy = np.arange(y0, y1)[:, None] - y
        xx = np.arange(x0, x1)[None, :] - x
        img[y0:y1, x0:x1] += a * np.exp(-(yy**2 + xx**2) / (2 * s * s))
    return np.clip(img, *clip)


def hard_dots(
    shape: tuple[int, int],
    shift: tuple[float, float] = (0.0, 0.0),
    *,
    density: float = 0.012,
    radius: tuple[float, float] = (1.5, 3.5),
    levels: tuple[float, float] = (30.0, 220.0),
    supersample: int = 4,
    seed: int = 5,
) -> np.ndarray:
    """Hard-edged discs at random centres moved by ``shift`` (dy, dx) px, each pixel the
    area average of ``supersample^2`` point samples (a camera's pixel): not band-limited,
    and exactly shifted (no Fourier ringing), GL."""
    rng = np.random.default_rng(seed)
    h, w = shape
    n = int(density * h * w)
    ys, xs = rng.uniform(0, h, n) + shift[0], rng.uniform(0, w, n) + shift[1]
    rr = rng.uniform(*radius, n)
    s = supersample
    fine = np.zeros((h * s, w * s), bool)
    for y, x, r in zip(ys, xs, rr, strict=True):
        # fine-sample centres of pixel i: i + (k + 0.5) / s - 0.5
        y0, y1 = max(0, int((y - r) * s)), min(h * s, int((y + r + 1) * s) + 1)
        x0, x1 = max(0, int((x - r) * s)), min(w * s, int((x + r + 1) * s) + 1)
        fy = (np.arange(y0, y1) + 0.5) / s - 0.5
        fx = (np.arange(x0, x1) + 0.5) / s - 0.5
        fine[y0:y1, x0:x1] |= (fy[:, None] - y) ** 2 + (fx[None, :] - x) ** 2 <= r * r
    cover = fine.reshape(h, s, w, s).mean(axis=(1, 3))
    return levels[0] + (levels[1] - levels[0]) * cover


def thresholded(
    shape: tuple[int, int],
    shift: tuple[float, float] = (0.0, 0.0),
    *,
    speckle_size: float = 5.0,
    levels: tuple[float, float] = (20.0, 230.0),
    supersample: int = 4,
    seed: int = 7,
) -> np.ndarray:
    """A smooth periodic random field moved by ``shift`` (dy, dx) px, thresholded at its
    median on a ``supersample``-times finer grid and area-averaged back (hard edges:
    not band-limited, no Fourier ringing), GL."""
    rng = np.random.default_rng(seed)
    h, w = shape
    s = supersample
    field = ndimage.gaussian_filter(rng.standard_normal((h, w)), speckle_size / 4.0, mode="wrap")
    # the field on the fine grid, moved: a band-limited interpolation (Fourier), then hard;
    # fine sample j of pixel i sits at i + (j + 0.5) / s - 0.5, i.e. at J / s + c
    c = 0.5 / s - 0.5
    fy = np.fft.fftfreq(h)[:, None]
    fx = np.fft.fftfreq(w)[None, :]
    phase = np.exp(-2j * np.pi * (fy * (shift[0] - c) + fx * (shift[1] - c)))
    spec = np.fft.fft2(field) * phase
    big = np.zeros((h * s, w * s), complex)
    hy, hx = h // 2, w // 2
    big[:hy, :hx], big[:hy, -hx:] = spec[:hy, :hx], spec[:hy, -hx:]
    big[-hy:, :hx], big[-hy:, -hx:] = spec[-hy:, :hx], spec[-hy:, -hx:]
    fine = np.fft.ifft2(big).real
    hard = fine > np.median(fine)
    cover = hard.reshape(h, s, w, s).mean(axis=(1, 3))
    return levels[0] + (levels[1] - levels[0]) * cover
