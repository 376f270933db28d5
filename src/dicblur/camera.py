"""Camera model applied after blurring: noise, quantisation, saturation.

Two noise models:

- Gaussian read noise only (``Camera(read_noise=2.0)``): additive, signal independent,
  as in the paper (which adds Gaussian noise in Algorithm 1, step 9).
- Poisson-Gaussian (``Camera(gain=..., full_well=..., read_noise=...)``): the signal in
  electrons is Poisson (shot noise), plus Gaussian read noise, the standard sensor model
  (Foi et al., IEEE TIP 17(10), 2008, doi:10.1109/TIP.2008.2001399). In grey levels the
  variance is ``gain * signal + read_noise**2``.

Noise of the paper's Algorithm 1 (step 9) is added to every sub-frame and then averaged:
that is one Gaussian draw of standard deviation ``sigma / sqrt(K + 1)``
(:func:`add_gaussian_noise` with ``model="per-subframe"``). A camera adds its noise once per
exposure (``model="per-exposure"``, the default here): the paper's blurred images are
therefore ``sqrt(K + 1)`` (about 10) times less noisy than a camera with the same sigma.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from .arrays import Float64Array
from .checks import as_image, check_choice, check_positive, describe
from .errors import InputError
from .patterns import SeedLike, make_rng

__all__ = ["Camera", "add_gaussian_noise"]

NoiseModel = Literal["per-exposure", "per-subframe"]


def _generator(rng: np.random.Generator | None, seed: SeedLike) -> np.random.Generator:
    if rng is not None and seed is not None:
        raise InputError(
            f"rng={describe(rng)}, seed={describe(seed)}: pass either rng or seed, not both"
        )
    if rng is not None:
        if not isinstance(rng, np.random.Generator):
            raise InputError(f"rng={describe(rng)}: expected a numpy.random.Generator or None")
        return rng
    return make_rng(seed)


def add_gaussian_noise(
    image: ArrayLike,
    sigma: float,
    *,
    model: NoiseModel = "per-exposure",
    substeps: int = 100,
    rng: np.random.Generator | None = None,
    seed: SeedLike = None,
) -> Float64Array:
    """Add zero-mean Gaussian noise (grey levels) to an image.

    Parameters
    ----------
    image : array_like, shape (rows, cols)
        Grey levels.
    sigma : float
        Noise standard deviation, grey levels (>= 0).
    model : {"per-exposure", "per-subframe"}
        ``"per-exposure"``: one draw of std ``sigma`` per pixel, as a camera (default).
        ``"per-subframe"``: the paper's Algorithm 1, noise of std ``sigma`` added to each of
        the K + 1 sub-frames before averaging, which is distributed exactly as one draw of
        std ``sigma / sqrt(K + 1)``; that draw is what is returned.
    substeps : int
        K of the blur (used by ``"per-subframe"`` only), >= 0.
    rng, seed
        Source of randomness (one of them, or neither for fresh entropy). Same seed, same
        bytes.

    Returns
    -------
    ndarray of float64, shape (rows, cols)
    """
    img = as_image(image, "image", min_size=1)
    s = check_positive(sigma, "sigma", allow_zero=True)
    check_choice(model, "model", ("per-exposure", "per-subframe"))
    if isinstance(substeps, bool) or not isinstance(substeps, int | np.integer) or substeps < 0:
        raise InputError(f"substeps={describe(substeps)}: expected an integer >= 0 (K)")
    gen = _generator(rng, seed)
    if model == "per-subframe":
        s = s / math.sqrt(int(substeps) + 1)
    return img + gen.normal(0.0, 1.0, img.shape) * s


@dataclass(frozen=True)
class Camera:
    """A digital camera: shot and read noise, full well, gain, quantisation, saturation.

    The input of :meth:`capture` is the noise-free irradiance expressed in grey levels at
    the nominal exposure (e.g. a blurred pattern in 0..255). Processing order:

    1. scale by ``exposure_scale`` (relative exposure: doubling the exposure doubles the
       signal);
    2. if ``gain`` (or ``full_well``) is set: convert to electrons (``signal / gain``,
       negative values, e.g. Fourier ringing of hard edges, count as 0), draw Poisson
       counts, clip at ``full_well`` electrons, convert back (``* gain``);
    3. add Gaussian read noise of std ``read_noise`` grey levels;
    4. if ``bit_depth`` is set: round to integers and clip to ``0 .. 2**bit_depth - 1``
       (saturation); otherwise the output is left unclipped, in float.

    Variance (grey levels^2) before quantisation and clipping:
    ``gain * exposure_scale * signal + read_noise**2``.

    Attributes
    ----------
    read_noise : float
        Gaussian read noise std, grey levels (>= 0).
    gain : float or None
        Grey levels per electron (> 0). None with ``full_well`` set: full well maps to the
        top grey level, ``gain = (2**bit_depth - 1) / full_well``. None without
        ``full_well``: no shot noise.
    full_well : float or None
        Full-well capacity, electrons (> 0); None for no electron saturation.
    exposure_scale : float
        Exposure relative to the nominal one (> 0).
    bit_depth : int or None
        ADC bits (1..32); None keeps float output without quantisation.
    """

    read_noise: float = 0.0
    gain: float | None = None
    full_well: float | None = None
    exposure_scale: float = 1.0
    bit_depth: int | None = 8

    def __post_init__(self) -> None:
        check_positive(self.read_noise, "read_noise", allow_zero=True)
        check_positive(self.exposure_scale, "exposure_scale")
        if self.gain is not None:
            check_positive(self.gain, "gain")
        if self.full_well is not None:
            check_positive(self.full_well, "full_well")
        if self.bit_depth is not None and (
            isinstance(self.bit_depth, bool)
            or not isinstance(self.bit_depth, int | np.integer)
            or not 1 <= self.bit_depth <= 32
        ):
            raise InputError(
                f"bit_depth={describe(self.bit_depth)}: expected an integer in 1..32 "
                "(e.g. 8 or 16) or None for no quantisation"
            )
        if self.gain is None and self.full_well is not None and self.bit_depth is None:
            raise InputError(
                "gain=None, full_well set, bit_depth=None: the gain cannot be derived; "
                "give gain (grey levels per electron) or a bit_depth"
            )

    @property
    def effective_gain(self) -> float | None:
        """Grey levels per electron used for shot noise (None: no shot noise)."""
        if self.gain is not None:
            return float(self.gain)
        if self.full_well is not None and self.bit_depth is not None:
            return (2.0**self.bit_depth - 1.0) / float(self.full_well)
        return None

    @property
    def max_level(self) -> float:
        """Top grey level of the ADC (inf without quantisation)."""
        return math.inf if self.bit_depth is None else 2.0**self.bit_depth - 1.0

    def variance(self, signal: ArrayLike) -> Float64Array:
        """Predicted noise variance (grey levels^2) at noise-free ``signal`` grey levels."""
        sig = np.asarray(signal, dtype=np.float64) * self.exposure_scale
        g = self.effective_gain
        shot = g * np.maximum(sig, 0.0) if g is not None else np.zeros_like(sig)
        return shot + self.read_noise**2

    def to_dict(self) -> dict[str, Any]:
        """Parameters as a JSON-ready dict."""
        return asdict(self)

    def capture(
        self,
        image: ArrayLike,
        *,
        rng: np.random.Generator | None = None,
        seed: SeedLike = None,
    ) -> Float64Array:
        """Simulate one exposure of a noise-free image.

        Parameters
        ----------
        image : array_like, shape (rows, cols)
            Noise-free irradiance in grey levels at the nominal exposure.
        rng, seed
            Source of randomness (one of them, or neither). Same seed, same bytes.

        Returns
        -------
        ndarray of float64, shape (rows, cols)
            Grey levels (integers stored as float64 when ``bit_depth`` is set).
        """
        img = as_image(image, "image", min_size=1)
        gen = _generator(rng, seed)
        signal = img * self.exposure_scale
        g = self.effective_gain
        if g is not None:
            # Irradiance cannot be negative; small negative values are the ringing of
            # Fourier-shifted hard edges and carry no photons.
            electrons = gen.poisson(np.maximum(signal, 0.0) / g).astype(np.float64)
            if self.full_well is not None:
                np.minimum(electrons, float(self.full_well), out=electrons)
            out = electrons * g
        else:
            out = signal.copy()
        if self.read_noise > 0:
            out += gen.normal(0.0, self.read_noise, out.shape)
        if self.bit_depth is not None:
            out = np.clip(np.rint(out), 0.0, self.max_level)
        return out
