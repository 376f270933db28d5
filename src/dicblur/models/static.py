"""Static uncertainty models (no blur): match score (paper eq. 2) and Pan's MIG form (eq. 5).

Vectorised wrappers around :func:`dicblur.metrics.match_score_sigma` and
:func:`dicblur.metrics.pan_sigma` that broadcast over SSSIG (or MIG) and noise arrays.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ..arrays import Float64Array
from ..errors import InputError
from ..metrics import match_score_sigma, pan_sigma

__all__ = ["match_score_uncertainty", "pan_uncertainty"]


def _noise(noise_sigma: ArrayLike) -> Float64Array:
    s = np.asarray(noise_sigma, dtype=np.float64)
    if not np.all(np.isfinite(s)) or np.any(s < 0):
        raise InputError("noise_sigma: must be finite and >= 0 (grey levels)")
    return s


def match_score_uncertainty(sssig: ArrayLike, noise_sigma: ArrayLike) -> Float64Array:
    """``u_e = sqrt(2 sigma**2 / SSSIG)`` (px), eq. 2, broadcast over both arguments.

    Parameters
    ----------
    sssig : array_like
        SSSIG along the motion, (grey levels / px)**2 summed over the subset.
    noise_sigma : array_like
        Noise std (grey levels) of each image.
    """
    s = np.asarray(sssig, dtype=np.float64)
    sig = _noise(noise_sigma)
    s_b, sig_b = np.broadcast_arrays(s, sig)
    # The metrics function is the single implementation; it takes a scalar sigma.
    return match_score_sigma(s_b, 1.0) * sig_b


def pan_uncertainty(mig: ArrayLike, noise_sigma: ArrayLike, subset: int) -> Float64Array:
    """``u_e ~= sqrt(2) sigma / (N MIG)`` (px), eq. 5, broadcast over MIG and noise."""
    m = np.asarray(mig, dtype=np.float64)
    sig = _noise(noise_sigma)
    m_b, sig_b = np.broadcast_arrays(m, sig)
    return np.asarray(pan_sigma(m_b, 1.0, subset)) * sig_b
