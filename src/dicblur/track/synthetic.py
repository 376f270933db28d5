"""A synthetic high-speed recording of a vibrating target with known truth.

Frame ``k`` integrates the scene over its exposure window ``[k / fps, k / fps + T]``: the
sharp speckle pattern moves along its own stretch of the trajectory during the window
(:func:`dicblur.motion_blur` with the trajectory as a callable, continuous limit) and a
Poisson-Gaussian :class:`dicblur.Camera` takes the picture. The target rests for
``static`` frames, then vibrates as ``x(t) = A (1 - cos(2 pi f (t - t_s)))`` along a
fixed direction (zero speed at the start, amplitude ``A`` about ``A``). The truth of each
frame is the time-average position over its window (what DIC measures of a blurred
frame) and the motion during the window.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..arrays import Float64Array, Int64Array
from ..blur import motion_blur
from ..camera import Camera
from ..sequence import Recording
from .directions import direction_motion

__all__ = ["VibratingTarget"]


@dataclass(frozen=True)
class VibratingTarget:
    """A sinusoidally vibrating speckle target filmed by a high-speed camera.

    Attributes
    ----------
    pattern : ndarray, shape (rows, cols)
        Sharp, periodic (tiling) pattern in grey levels at the nominal exposure.
    fps : float
        Frame rate, Hz.
    exposure : float
        Exposure time, s.
    amplitude : float
        Vibration amplitude ``A``, px.
    frequency : float
        Vibration frequency, Hz.
    angle : float
        Motion direction, deg from +x towards +y.
    static : int
        Frames at rest before the vibration starts.
    camera : Camera
    seed : int
        Frame ``k`` uses noise seed ``(seed, k)``.
    """

    pattern: Float64Array
    fps: float
    exposure: float
    amplitude: float = 10.0
    frequency: float = 200.0
    angle: float = 0.0
    static: int = 10
    camera: Camera = field(
        default_factory=lambda: Camera(read_noise=2.0, full_well=20000.0, bit_depth=8)
    )
    seed: int = 0

    @property
    def _dir(self) -> tuple[float, float]:
        return direction_motion(self.angle)

    def position(self, t: Float64Array) -> Float64Array:
        """Displacement along the motion direction (px) at times ``t`` (s)."""
        ts = self.static / self.fps
        tt = np.maximum(np.asarray(t, dtype=np.float64) - ts, 0.0)
        return np.asarray(self.amplitude * (1.0 - np.cos(2 * math.pi * self.frequency * tt)))

    def truth(self, frames: Int64Array) -> tuple[Float64Array, ...]:
        """``(u, v, blur_u, blur_v)`` of frames (px): the window-mean displacement and the
        motion during the window."""
        t0 = np.asarray(frames, dtype=np.float64) / self.fps
        nodes, weights = np.polynomial.legendre.leggauss(32)
        tau = 0.5 * (nodes + 1.0)
        mean = (
            self.position(t0[:, None] + self.exposure * tau[None, :]) * (0.5 * weights)[None, :]
        ).sum(axis=1)
        rise = self.position(t0 + self.exposure) - self.position(t0)
        dy, dx = self._dir
        return mean * dx, mean * dy, rise * dx, rise * dy

    def render(self, k: int) -> Float64Array:
        """Frame ``k`` (grey levels)."""
        t0 = k / self.fps
        dy, dx = self._dir

        def path(tau: Float64Array) -> Float64Array:
            s = self.position(t0 + self.exposure * np.asarray(tau))
            return np.stack([s * dy, s * dx], axis=1)

        img = motion_blur(self.pattern, None, substeps=None, trajectory=path)
        return self.camera.capture(img, rng=np.random.default_rng([self.seed, k]))

    def recording(self, n_frames: int) -> Recording:
        """A lazy :class:`~dicblur.sequence.Recording` rendering frames on demand (with the
        exposure and frame rate as metadata)."""
        shape = (int(self.pattern.shape[0]), int(self.pattern.shape[1]))
        return Recording(
            source="synthetic vibrating target",
            kind="synthetic",
            n_frames=int(n_frames),
            shape=shape,
            bit_depth=int(self.camera.bit_depth or 16),
            fps=self.fps,
            exposure=self.exposure,
            names=[f"frame {i}" for i in range(n_frames)],
            _read=self.render,
        )
