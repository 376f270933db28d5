"""Exposure advice: the exposure that would have minimised the error of this recording.

For the measured velocities (the blur of every valid point in every frame divided by the
exposure), the random error at another exposure ``T'`` follows the static prediction of the
reference frame (:func:`dicblur.models.model_from_pattern`) with blur ``v T'`` and the
noise of a Poisson-Gaussian camera at ``T'`` (:class:`dicblur.models.PoissonGaussianCamera`
built from the noise measured on the static frames: ``var = read + slope * level``, signal
proportional to the exposure). The optimum minimises the RMS error over all points and
frames; the gain is the ratio of the RMS errors at the actual and the optimal exposure.
Without a measurable level dependence the camera is taken as shot-noise limited.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..models import PoissonGaussianCamera, model_from_pattern
from .uncertainty import NoiseEstimate

__all__ = ["ExposureAdvice", "advise_exposure"]


@dataclass(frozen=True)
class ExposureAdvice:
    """Result of :func:`advise_exposure` (times in s, errors in px)."""

    exposure: float
    optimal_exposure: float
    rms_error: float
    optimal_rms_error: float
    gain: float
    limit: str
    assumption: str
    sentence: str

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def _fmt(t: float) -> str:
    return f"{t * 1e3:.3g} ms" if t >= 1e-3 else f"{t * 1e6:.3g} us"


def advise_exposure(
    reference: NDArray[np.float64],
    centres: NDArray[np.intp],
    speed: NDArray[np.float64],
    angle: NDArray[np.float64],
    *,
    exposure: float,
    fps: float,
    noise: NoiseEstimate,
    level: float,
    subset: int,
    shape: str,
    bit_depth: int,
    max_points: int = 300,
    max_samples: int = 20000,
    seed: int = 0,
) -> ExposureAdvice:
    """Best exposure for the measured velocities (module docstring).

    Parameters
    ----------
    reference : ndarray, shape (rows, cols)
    centres : ndarray of int, shape (n, 2)
        POI centres used for the static prediction (a random subset of ``max_points``).
    speed : ndarray
        Blur speed samples, px/s (valid points and frames).
    angle : ndarray
        Their directions (deg); the dominant one sets the prediction's motion direction.
    exposure, fps : float
        The recording's exposure (s) and frame rate (Hz); exposures up to ``1 / fps`` are
        searched.
    noise : NoiseEstimate
    level : float
        Gradient-weighted grey level of the reference.
    bit_depth : int
        Of the data (the top grey level sets the saturation exposure).
    """
    rng = np.random.default_rng(seed)
    pts = (
        centres
        if len(centres) <= max_points
        else centres[np.sort(rng.choice(len(centres), max_points, replace=False))]
    )
    v = np.abs(speed[np.isfinite(speed)])
    if v.size > max_samples:
        v = rng.choice(v, max_samples, replace=False)
    ang = angle[np.isfinite(angle)]
    if ang.size:
        mu = np.mean(np.exp(2j * np.deg2rad(ang)))
        dom = math.radians((math.degrees(np.angle(mu)) / 2.0) % 180.0)
    else:
        dom = 0.0
    model = model_from_pattern(
        reference,
        noise_sigma=noise.sigma,
        subset=subset,
        points=pts,
        motion=(math.sin(dom), math.cos(dom)),
        shape=shape,  # type: ignore[arg-type]
    )
    mean_level = float(reference.mean())
    top = float(2 ** min(int(bit_depth), 16) - 1)
    if noise.level_dependent and noise.slope > 0:
        gain = noise.slope  # GL per electron
        read_e = math.sqrt(max(noise.read_variance, 0.0)) / gain
        assumption = (
            f"camera from the static frames: gain {gain:.3g} GL/e-, read noise {read_e:.3g} e-"
        )
    else:
        # shot-noise limited: sigma(T) = sigma0 sqrt(T0 / T) at the same contrast
        gain = noise.sigma**2 / max(level, 1e-9)
        read_e = 0.0
        assumption = "noise not level-dependent in the static frames: shot-noise limited"
    flux = mean_level / (gain * exposure)
    cam = PoissonGaussianCamera(
        full_well=top / gain,
        read_noise=read_e,
        flux=flux,
        peak_to_mean=max(float(reference.max()) / mean_level, 1.0),
    )
    t_max = min(1.0 / fps, cam.saturation_exposure * 0.999)
    t_max = max(t_max, exposure)
    grid = np.geomspace(exposure / 50.0, t_max, 60)
    grid = np.unique(np.append(grid, exposure))

    def rms(t: float) -> float:
        sig = float(cam.noise_gl(t, mean_level, level))
        if not v.size:
            ue = model.predict([0.0], sig).u_e
        else:
            ue = model.predict(v * t, sig).u_e
        return float(np.sqrt(np.mean(np.asarray(ue, dtype=np.float64) ** 2)))

    errs = np.array([rms(t) for t in grid])
    i = int(np.nanargmin(errs))
    t_opt = float(grid[i])
    e_now = float(errs[grid == exposure][0])
    e_opt = float(errs[i])
    limit = (
        "the frame interval"
        if t_opt >= 0.999 / fps
        else "sensor saturation"
        if t_opt >= 0.99 * cam.saturation_exposure
        else "the shortest exposure searched"
        if i == 0
        else "the error minimum"
    )
    g = e_now / e_opt if e_opt > 0 else 1.0
    if g < 1.05:
        sentence = (
            f"The exposure of {_fmt(exposure)} was close to the best for the "
            f"measured motion (optimum {_fmt(t_opt)}, set by {limit}; predicted RMS "
            f"error {e_now:.3g} px vs {e_opt:.3g} px)."
        )
    else:
        word = "shorter" if t_opt < exposure else "longer"
        sentence = (
            f"A {word} exposure of {_fmt(t_opt)} instead of {_fmt(exposure)} would "
            f"have lowered the predicted RMS error from {e_now:.3g} px to "
            f"{e_opt:.3g} px ({g:.2f}x; set by {limit})."
        )
    return ExposureAdvice(
        exposure=exposure,
        optimal_exposure=t_opt,
        rms_error=e_now,
        optimal_rms_error=e_opt,
        gain=g,
        limit=limit,
        assumption=assumption,
        sentence=sentence,
    )
