"""The claims' own experiments, run as one stage of ``dicblur reproduce`` before the verdicts.

The main campaign cannot answer three claims of the paper: that Algorithm 1 translates the
image by X/2 (C1, a property of the blur measured on the image), that the rigid part of the
motion does not change the uncertainty (C3) and that an equally blurred reference lowers it
(C4). :func:`run_claim_experiments` measures them on pattern #4 and returns typed results;
:func:`dicblur.report.claims.evaluate_claims` only judges them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..arrays import Float64Array

__all__ = [
    "Algorithm1Check",
    "ClaimExperiments",
    "PairedReplicates",
    "algorithm1_translation",
    "paired_replicates",
    "run_claim_experiments",
]

#: Blur lengths (px) of the Algorithm 1 check (C1) and of the paired experiments (C3, C4).
ALGORITHM1_BLUR = (1.0, 3.0, 6.0)
PAIRED_BLUR = (3.0, 6.0)


@dataclass(frozen=True)
class Algorithm1Check:
    """Translation and symmetry of Algorithm 1 at one blur length, measured on an image.

    Attributes
    ----------
    blur : float
        W = |X| (px, along x).
    translation : float
        Translation of the blurred image (px) from the phase of its spectrum.
    expected : float
        X / 2 (px).
    asymmetry : float
        Largest imaginary part of the centred transfer function, relative to max |H|
        (0 for a symmetric kernel).
    """

    blur: float
    translation: float
    expected: float
    asymmetry: float


@dataclass(frozen=True)
class PairedReplicates:
    """u_e (px, std of u over the converged POIs) of three cases, paired per noise draw.

    Each field is indexed ``[j][r]``: blur ``blur[j]``, replicate ``r`` (the same noise
    realisation of the reference across the three cases).

    Attributes
    ----------
    blur : tuple of float
        Blur lengths W (px).
    replicates : int
    sharp_ref : tuple of tuple of float
        The campaign's case: sharp reference, offset 0.
    offset : tuple of tuple of float
        A rigid offset of 0.5 px added to every position of the motion.
    blurred_ref : tuple of tuple of float
        The reference blurred like the current image (independent noise).
    """

    blur: tuple[float, ...]
    replicates: int
    sharp_ref: tuple[tuple[float, ...], ...]
    offset: tuple[tuple[float, ...], ...]
    blurred_ref: tuple[tuple[float, ...], ...]


@dataclass(frozen=True)
class ClaimExperiments:
    """What the claims' experiments measured (:func:`run_claim_experiments`)."""

    algorithm1: tuple[Algorithm1Check, ...]
    paired: PairedReplicates


def algorithm1_translation(image: Float64Array, blur: float) -> Algorithm1Check:
    """Translation and symmetry of Algorithm 1 measured on the image itself.

    The blurred image's spectrum over the sharp one's is the transfer function H(f) of
    the blur. For Algorithm 1 along x it is exp(-i pi f X) times a real (Dirichlet) kernel:
    the phase at the lowest frequency along x gives the translation (X/2 expected), and
    H(f) exp(i pi f X) must be real at every frequency (a symmetric kernel: no other
    shift).
    """
    from ..blur import motion_blur

    img = np.asarray(image, dtype=np.float64)
    b = motion_blur(img, (0.0, float(blur)))
    fi = np.fft.fft(img, axis=1)
    fb = np.fft.fft(b, axis=1)
    n = img.shape[1]
    f = np.fft.fftfreq(n)
    # per-column-frequency transfer function, averaged over rows weighted by |I|^2
    num = np.sum(fb * np.conj(fi), axis=0)
    den = np.sum(np.abs(fi) ** 2, axis=0)
    # the Nyquist bin carries no phase (a real signal): leave it out
    ok = (den > 1e-12 * den.max()) & (np.abs(f) < 0.5)
    h = np.where(ok, num / np.where(ok, den, 1.0), 0.0)
    shift = float(-np.angle(h[1]) / (2 * math.pi * f[1]))
    centred = h * np.exp(1j * math.pi * f * blur)
    resid = float(np.max(np.abs(centred.imag[ok])) / np.max(np.abs(h[ok])))
    return Algorithm1Check(float(blur), shift, blur / 2.0, resid)


def paired_replicates(
    image: Float64Array,
    *,
    blur: tuple[float, ...],
    replicates: int,
    noise_sigma: float,
    subset: int,
    step: int,
    seed: int,
) -> PairedReplicates:
    """u_e on ``image`` with (a) a rigid offset of 0.5 px added to the motion and (b) a
    reference blurred like the current image (independent noise), against (c) the
    campaign's case (sharp reference, offset 0). Same noise (GL), subset, step (px);
    ``replicates`` independent noise realisations of every image, paired across the three
    cases; translation IC-GN."""
    from ..blur import motion_blur
    from ..camera import add_gaussian_noise
    from ..dic import Correlator

    rng = np.random.default_rng(np.random.SeedSequence([seed, 21]))

    def matcher(reference: Float64Array) -> Correlator:
        # the scatter of every converged point is measured: no noise-based screening
        return Correlator(
            reference, subset=subset, step=step, shape="translation", noise_sigma=None
        )

    cases: dict[str, list[tuple[float, ...]]] = {"sharp_ref": [], "offset": [], "blurred_ref": []}
    k = 100
    t = np.linspace(0.0, 1.0, k + 1)
    for w in blur:
        sharp = motion_blur(image, (0.0, w))
        # the same linear motion with a constant 0.5 px added to every position
        # (paper Section III: "adding a constant to the values of p")
        path = np.stack([np.zeros_like(t), 0.5 + w * t], axis=1)
        shifted = motion_blur(image, None, trajectory=path)
        per: dict[str, list[float]] = {key: [] for key in cases}
        for _ in range(replicates):
            base = matcher(add_gaussian_noise(image, noise_sigma, rng=rng))
            cur = add_gaussian_noise(sharp, noise_sigma, rng=rng)
            cur_off = add_gaussian_noise(shifted, noise_sigma, rng=rng)
            ref_b = matcher(add_gaussian_noise(sharp, noise_sigma, rng=rng))
            for key, corr, img in (
                ("sharp_ref", base, cur),
                ("offset", base, cur_off),
                ("blurred_ref", ref_b, cur),
            ):
                res = corr.correlate(img)
                u = np.asarray(res.u)[np.asarray(res.converged)]
                per[key].append(float(np.std(u, ddof=1)))
        for key, vals in per.items():
            cases[key].append(tuple(vals))
    return PairedReplicates(
        blur=tuple(float(w) for w in blur),
        replicates=replicates,
        sharp_ref=tuple(cases["sharp_ref"]),
        offset=tuple(cases["offset"]),
        blurred_ref=tuple(cases["blurred_ref"]),
    )


def run_claim_experiments(
    image: Float64Array,
    *,
    noise_sigma: float,
    subset: int,
    step: int,
    seed: int,
    quick: bool,
) -> ClaimExperiments:
    """Run the claims' experiments on ``image`` (pattern #4): the Algorithm 1 check at
    W = 1, 3, 6 px and the paired replicates at W = 3, 6 px (4 replicates when ``quick``,
    else 12)."""
    return ClaimExperiments(
        algorithm1=tuple(algorithm1_translation(image, w) for w in ALGORITHM1_BLUR),
        paired=paired_replicates(
            image,
            blur=PAIRED_BLUR,
            replicates=4 if quick else 12,
            noise_sigma=noise_sigma,
            subset=subset,
            step=step,
            seed=seed,
        ),
    )
