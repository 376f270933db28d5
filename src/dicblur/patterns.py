"""Synthetic speckle patterns.

Model
-----
A speckle pattern is a *thresholded Gaussian random field*. White Gaussian noise is
filtered by a Gaussian kernel of standard deviation ``s`` (periodically, in the Fourier
domain, so the pattern tiles seamlessly and Fourier shifting does not wrap a seam), then
thresholded at its ``density`` quantile: pixels below are black. The black-area fraction is
therefore exactly ``density``.

The speckle size is defined from the autocorrelation (as :func:`dicblur.speckle_size`
measures it): the diameter ``D = 2 r_half`` at which the normalised autocovariance of the
binary pattern falls to 1/2. The filtered field has correlation
``rho(r) = exp(-r**2 / (4 s**2))``; thresholding at level ``t = Phi^-1(density)`` maps it to
the binary autocovariance ``Phi2(t, t; rho) - p**2`` (bivariate normal orthant
probability). We solve for the ``rho*`` at which that equals ``p (1 - p) / 2`` and set
``s = D / (4 sqrt(-ln rho*))``, so the requested size holds exactly in expectation for the
binary pattern (``softness=0``); sampling at pixels does not change the autocorrelation at
integer lags.

An optional edge blur (Gaussian, standard deviation ``softness`` px) softens edges as optics
or ink spreading do; it widens the measured autocorrelation slightly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import integrate, optimize, special

from .arrays import Float64Array
from .checks import (
    check_finite_number,
    check_positive,
    check_seed,
    check_shape2d,
    describe,
)
from .errors import InputError
from .io import check_pixels

__all__ = [
    "PatternSettings",
    "gaussian_filter_periodic",
    "gaussian_mask",
    "make_rng",
    "paper_pattern4",
    "speckle_pattern",
]

SeedLike = int | np.random.Generator | np.random.SeedSequence | None


def make_rng(seed: SeedLike) -> np.random.Generator:
    """A numpy Generator from ``seed`` (int, SeedSequence, None) or ``seed`` itself."""
    if isinstance(seed, np.random.Generator):
        return seed
    return np.random.default_rng(check_seed(seed))


@dataclass(frozen=True)
class PatternSettings:
    """Generator settings of a speckle pattern, enough to regenerate it exactly.

    Attributes
    ----------
    shape : tuple of int
        (rows, cols) in px.
    speckle_size : float
        Requested mean speckle diameter (px), autocorrelation definition.
    density : float
        Black-area fraction in (0, 1).
    softness : float
        Standard deviation (px) of the Gaussian edge blur.
    black, white : float
        Grey levels of black and white areas.
    supersample : int
        Fine-grid factor used before pixel integration.
    seed : int or None
        Seed of the generator.
    """

    shape: tuple[int, int]
    speckle_size: float
    density: float
    softness: float
    black: float
    white: float
    supersample: int
    seed: int | None

    def to_dict(self) -> dict[str, Any]:
        """Settings as a JSON-ready dict."""
        return {
            "shape": list(self.shape),
            "speckle_size": self.speckle_size,
            "density": self.density,
            "softness": self.softness,
            "black": self.black,
            "white": self.white,
            "supersample": self.supersample,
            "seed": self.seed,
        }


def _half_correlation(density: float) -> float:
    """Field correlation rho* at which the binary autocovariance is half its variance."""
    p = density
    t = float(special.ndtri(p))
    target = 0.5 * p * (1.0 - p)

    def cov(rho: float) -> float:
        # d Phi2(t, t; r) / dr = exp(-t^2 / (1 + r)) / (2 pi sqrt(1 - r^2))  (Plackett, 1954)
        val, _ = integrate.quad(
            lambda r: math.exp(-t * t / (1.0 + r)) / (2.0 * math.pi * math.sqrt(1.0 - r * r)),
            0.0,
            rho,
        )
        return val - target

    return float(optimize.brentq(cov, 1e-9, 1.0 - 1e-12, xtol=1e-14))


def gaussian_filter_periodic(field: Float64Array, sigma: float) -> Float64Array:
    """Gaussian filter of std ``sigma`` px with periodic boundaries (one rFFT pair)."""
    if sigma <= 0:
        return field
    fy = np.fft.fftfreq(field.shape[0])[:, None]
    fx = np.fft.rfftfreq(field.shape[1])[None, :]
    transfer = np.exp(-2.0 * math.pi**2 * sigma**2 * (fx**2 + fy**2))
    return np.fft.irfft2(np.fft.rfft2(field) * transfer, s=field.shape)


def speckle_pattern(
    shape: int | tuple[int, int],
    *,
    speckle_size: float = 4.0,
    density: float = 0.5,
    softness: float = 0.0,
    contrast: float = 1.0,
    levels: tuple[float, float] = (0.0, 255.0),
    supersample: int = 1,
    seed: SeedLike = None,
) -> Float64Array:
    """Generate a random speckle pattern (black speckles on white).

    Parameters
    ----------
    shape : int or tuple of int
        (rows, cols) of the output in px; an int gives a square image.
    speckle_size : float
        Mean speckle diameter in px (autocorrelation definition, see the module docs),
        >= 1. Keep it >= 2 px for patterns meant for DIC.
    density : float
        Black-area fraction, in (0, 1). Exact on the fine grid.
    softness : float
        Standard deviation (px) of a Gaussian edge blur applied after thresholding; 0 gives
        hard edges.
    contrast : float
        Fraction in (0, 1] of the ``levels`` range spanned, about its mid-level.
    levels : (float, float)
        Grey levels (black, white) at full contrast; default 0..255.
    supersample : int
        If > 1, the binary pattern is drawn on a grid ``supersample`` times finer and
        area-averaged to pixels (pixel integration of a continuous pattern).
    seed : int, numpy Generator, SeedSequence or None
        Source of randomness. The same seed gives the same bytes.

    Returns
    -------
    ndarray of float64, shape (rows, cols)
        Grey levels in ``levels``. The pattern is periodic: it tiles without a seam.

    Examples
    --------
    >>> img = speckle_pattern((256, 256), speckle_size=4, density=0.5, seed=1)
    >>> img.shape, float(img.min()), float(img.max())
    ((256, 256), 0.0, 255.0)
    """
    rows, cols = check_shape2d(shape, "shape", min_size=2)
    d = check_positive(speckle_size, "speckle_size")
    if d < 1.0:
        raise InputError(f"speckle_size={speckle_size!r}: must be >= 1 px")
    if d > min(rows, cols) / 2:
        raise InputError(
            f"speckle_size={speckle_size!r}: larger than half the image ({rows}x{cols}); "
            "use a larger shape or smaller speckles"
        )
    p = check_finite_number(density, "density")
    if not 0.0 < p < 1.0:
        raise InputError(f"density={density!r}: the black-area fraction must be in (0, 1)")
    soft = check_positive(softness, "softness", allow_zero=True)
    c = check_positive(contrast, "contrast")
    if c > 1.0:
        raise InputError(f"contrast={contrast!r}: must be in (0, 1]")
    try:
        black, white = (check_finite_number(v, "levels") for v in levels)
    except (TypeError, ValueError) as exc:
        raise InputError(f"levels={describe(levels)}: expected (black, white)") from exc
    if isinstance(supersample, bool) or not isinstance(supersample, int | np.integer):
        raise InputError(f"supersample={describe(supersample)}: expected an integer >= 1")
    ss = int(supersample)
    if ss < 1 or ss > 16:
        raise InputError(f"supersample={supersample!r}: must be between 1 and 16")
    check_pixels((rows, cols), f"shape={describe((rows, cols))}", factor=ss * ss)
    rng = make_rng(seed)

    rho_star = _half_correlation(p)
    sigma_fine = d * ss / (4.0 * math.sqrt(-math.log(rho_star)))
    noise = rng.standard_normal((rows * ss, cols * ss))
    field = gaussian_filter_periodic(noise, sigma_fine)
    flat = field.ravel()
    k = round(p * flat.size)
    k = min(max(k, 1), flat.size - 1)
    threshold = np.partition(flat, k)[k]
    blackness = (field < threshold).astype(np.float64)
    if ss > 1:
        blackness = blackness.reshape(rows, ss, cols, ss).mean(axis=(1, 3))
    # Clip the ~1e-16 ringing of the FFT filter so grey levels stay within `levels`.
    blackness = np.clip(gaussian_filter_periodic(blackness, soft), 0.0, 1.0)
    mid = 0.5 * (black + white)
    half = 0.5 * (white - black) * c
    return (mid + half) - 2.0 * half * blackness


def gaussian_mask(size: int = 4, sigma: float = 0.5) -> Float64Array:
    """Normalised square Gaussian mask, as MATLAB's ``fspecial('gaussian', size, sigma)``.

    Taps sit at offsets ``k - (size - 1) / 2``; for an even ``size`` the mask's centre is
    between pixels, so filtering with it shifts the image by half a pixel along each axis.
    """
    if size < 1:
        raise InputError(f"size={size!r}: must be >= 1")
    sigma = check_positive(sigma, "sigma")
    x = np.arange(size) - (size - 1) / 2.0
    g = np.exp(-(x[:, None] ** 2 + x[None, :] ** 2) / (2.0 * sigma**2))
    return g / g.sum()


def paper_pattern4(
    shape: int | tuple[int, int] = (512, 512),
    *,
    speckle_size: float = 4.0,
    density: float = 0.5,
    mask_sigma: float = 0.5,
    seed: SeedLike = None,
) -> Float64Array:
    """The paper's numerical pattern #4: a random pattern smoothed by a 4x4 Gaussian mask.

    Lavatelli & Zappa (2017, Section III) describe pattern #4 as "numerically generated ...
    treated with a plain Gaussian blur mask of 4x4 pixels" without further detail. We take
    a hard-edged binary :func:`speckle_pattern` (``speckle_size`` px, black fraction
    ``density``, grey levels 0..255) and filter it, periodically, with the 4x4 mask of
    MATLAB's ``fspecial('gaussian', 4)`` (``sigma = 0.5`` px by default), the tool such a
    study would most likely have used. The even-sized mask shifts the content by
    (0.5, 0.5) px, which is harmless: every experiment uses this image as its own reference.

    Returns
    -------
    ndarray of float64, shape (rows, cols)
        Grey levels in 0..255.
    """
    base = speckle_pattern(shape, speckle_size=speckle_size, density=density, seed=seed)
    mask = gaussian_mask(4, mask_sigma)
    kernel = np.zeros_like(base)
    kernel[:4, :4] = mask
    out = np.fft.irfft2(np.fft.rfft2(base) * np.fft.rfft2(kernel), s=base.shape)
    return np.clip(out, 0.0, 255.0)
