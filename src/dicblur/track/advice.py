"""Exposure advice: the exposure that would have minimised the error of this recording.

For the measured velocities (the blur of every valid point in every frame divided by the
exposure), the random error at another exposure ``T'`` follows the static prediction of the
reference frame (:func:`dicblur.models.predict_from_pattern`, evaluated directly: the
point value, no fitted model form and no intervals) with blur ``v T'`` and the noise of a
Poisson-Gaussian camera at ``T'`` (:class:`dicblur.models.PoissonGaussianCamera` built
from the noise measured on the static frames: ``var = read + slope * level``, signal
proportional to the exposure). The optimum minimises the RMS error over all points and
frames; the gain is the ratio of the RMS errors at the actual and the optimal exposure.
Without a measurable level dependence the camera is taken as shot-noise limited.

The prediction is computed once, at one noise level, on the W nodes ``0, 1, 2, ...`` px up
to the largest blur the search reaches (``v_max T'_max``, at most :data:`MAX_BLUR`); its
parts scale with the noise as the static prediction's do (the reference and current
shares ``~ sigma``, their interaction ``~ sigma**2``, the mismatch not at all) and are
interpolated linearly in ``W**2`` between the nodes (the mismatch shift's leading order is
``k W**2``). Blur beyond the prediction's breakdown leaves that exposure out of the search.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from ..arrays import Float64Array, IndexArray
from ..errors import InputError
from ..models import PoissonGaussianCamera, predict_compensated, predict_from_pattern
from .noise import NoiseEstimate

__all__ = ["MAX_BLUR", "ExposureAdvice", "advise_exposure", "static_error_curve"]

#: Largest blur (px) of the advice's prediction nodes: longer exposures are not searched.
MAX_BLUR = 16.0


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


def static_error_curve(
    reference: Float64Array,
    points: IndexArray,
    *,
    w_max: float,
    noise_sigma: float,
    subset: int,
    motion: tuple[float, float],
    shape: str,
    compensated: bool = False,
) -> Any:
    """The static prediction's random error ``u_e(W, sigma)`` (px) of the subsets at
    ``points`` along ``motion``, as a function of blur lengths ``W`` (px, array) and a
    noise std ``sigma`` (GL): computed at ``noise_sigma`` on the nodes 0, 1, ... px up to
    ``w_max`` (module docstring); NaN beyond the largest node and where the prediction has
    no value (breakdown). ``compensated``: the blur-compensated matcher's prediction
    (:func:`dicblur.models.predict_compensated`: no mismatch term, a noise term that grows
    as the blurred reference loses its gradients), for ``dicblur track --compensate-blur``.
    """
    nodes = np.arange(0.0, math.ceil(max(w_max, 1.0) - 1e-9) + 1.0)
    # the same prediction settings for either matcher
    settings: dict[str, Any] = {
        "noise_sigma": noise_sigma,
        "subset": subset,
        "points": points,
        "motion": motion,
        "shape": shape,
    }
    if compensated:
        comp = predict_compensated(reference, nodes, **settings)
        # u_e = u_noise, linear in the noise std (u_blur = 0)
        return _curve(nodes, comp.u_noise**2 / noise_sigma**2, 0.0 * nodes, 0.0 * nodes)
    pred = predict_from_pattern(reference, nodes, **settings, sssig=False)  # sssig: not used
    assert pred.u_noise_reference is not None and pred.u_noise_current is not None
    assert pred.u_noise_interaction is not None
    lin = (pred.u_noise_reference**2 + pred.u_noise_current**2) / noise_sigma**2
    quad = pred.u_noise_interaction**2 / noise_sigma**4
    mis = pred.u_blur
    if pred.breakdown_blur is not None:  # DIC is not described from there on
        cut = nodes >= pred.breakdown_blur
        lin, quad, mis = (np.where(cut, np.nan, a) for a in (lin, quad, mis))
    return _curve(nodes, lin, quad, mis)


def _curve(
    nodes: Float64Array,
    lin: Float64Array,
    quad: Float64Array,
    mis: Float64Array,
) -> Any:
    """``u_e(W, sigma)`` from the terms per unit sigma^2, sigma^4 and the mismatch (px) at
    ``nodes``, linear in W^2 between them; NaN beyond the last node."""
    b2 = nodes**2

    def u_e(w: Float64Array, sigma: float) -> Float64Array:
        w2 = np.asarray(w, dtype=np.float64) ** 2
        out = np.sqrt(
            sigma**2 * np.interp(w2, b2, lin)
            + sigma**4 * np.interp(w2, b2, quad)
            + np.interp(w2, b2, mis) ** 2
        )
        return np.where(w2 <= b2[-1] * (1 + 1e-12), out, np.nan)

    return u_e


def advise_exposure(
    reference: Float64Array,
    centres: IndexArray,
    speed: Float64Array,
    angle: Float64Array,
    *,
    exposure: float,
    fps: float,
    noise: NoiseEstimate,
    level: float,
    subset: int,
    shape: str,
    bit_depth: int,
    compensated: bool = False,
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
    compensated : bool
        The recording was tracked with the blur-compensated matcher (``--compensate-blur``):
        advise for that matcher (:func:`static_error_curve`).
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
    if not (gain > 0 and mean_level > 0):
        raise InputError(
            f"noise: {noise.sigma:.3g} GL and a mean level of {mean_level:.3g} GL give no "
            "camera model; give the noise std (--noise 2, GL)"
        )
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
    if not v.size:
        v = np.zeros(1)
    v_max = float(v.max())
    # the prediction's nodes reach the longest exposure's blur (up to MAX_BLUR px)
    w_need = min(v_max * float(grid[-1]), MAX_BLUR)
    if v_max * exposure > MAX_BLUR:
        raise InputError(
            f"blur: the measured blur reaches {v_max * exposure:.3g} px, beyond the "
            f"advice's {MAX_BLUR:g} px; no exposure advice"
        )
    grid = grid[(grid <= exposure) | (v_max * grid <= MAX_BLUR)]
    u_e = static_error_curve(
        reference,
        pts,
        w_max=w_need,
        noise_sigma=noise.sigma,
        subset=subset,
        motion=(math.sin(dom), math.cos(dom)),
        shape=shape,
        compensated=compensated,
    )

    def rms(t: float) -> float:
        sig = float(cam.noise_gl(t, mean_level, level))
        return float(np.sqrt(np.mean(u_e(v * t, sig) ** 2)))

    errs = np.array([rms(t) for t in grid])
    e_now = float(errs[grid == exposure][0])
    if not math.isfinite(e_now):
        raise InputError(
            "blur: the static prediction breaks down at the measured blur; no exposure advice"
        )
    i = int(np.nanargmin(errs))
    t_opt = float(grid[i])
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
