"""Motion-blur synthesis: the paper's Algorithm 1, computed exactly with one FFT pair.

Lavatelli & Zappa (IEEE TIM 66(3), 2017, doi:10.1109/TIM.2016.2644898, Algorithm 1) make a
blurred image by shifting the image to K + 1 positions ``p_k`` along the motion with an
exact Fourier phase shift and averaging the shifted sub-frames. Averaging phase shifts is
one multiplication of the spectrum by the transfer function

    H(f) = sum_k w_k exp(-2 pi i f . p_k)        (w_k = 1 / (K + 1) for Algorithm 1)

so :func:`motion_blur` computes the same image with one ``rfft2``/``irfft2`` pair. For
linear motion ``p_k = k X / K`` the sum is a Dirichlet kernel with a closed form; in the
limit K -> infinity it becomes ``exp(-i pi f.X) sinc(f.X)``.

Conventions
-----------
- Positions and motion vectors are ``(dy, dx)`` px (rows, cols). A sub-frame at position
  ``p`` is the image *content moved by* ``+p``: ``out(y, x) = in(y - p_y, x - p_x)``.
- Nyquist bins of even-sized axes. A sub-pixel Fourier shift of the Nyquist component of
  a real image is not real. We use the symmetric band-limited interpolant: the Nyquist
  term is split evenly between +1/2 and -1/2 cycles/px, so its shift multiplier along that
  axis is ``cos(pi p)`` instead of ``exp(i pi p)``: the value at the pixels of the
  band-limited interpolant moved by ``p``. Every sub-frame is then real and integer shifts
  equal ``numpy.roll`` exactly. At the Nyquist bin no real-valued convention can make
  sub-pixel shifts compose (the sampled Nyquist component has one real degree of freedom;
  ``cos(pi a) cos(pi b) != cos(pi (a + b))``); elsewhere they compose exactly. Taking the
  real part of a complex inverse FFT (what a
  MATLAB transcription of Algorithm 1 does) gives the same image except at the corner bin
  (both axes at Nyquist), where it uses ``cos(pi (p_y + p_x))`` instead of
  ``cos(pi p_y) cos(pi p_x)``; for odd-sized images the two agree exactly.

See ``docs/blur.md`` for the derivations.

The package, by stage: :mod:`~dicblur.blur.trajectory` (paths and their sub-frames),
:mod:`~dicblur.blur.transfer` (``H(f)``; its compiled kernel in
:mod:`~dicblur.blur.kernels`), :mod:`~dicblur.blur.synthesis` (the blurred images) and
:mod:`~dicblur.blur.units` (``W = v t / scale``).
"""

from __future__ import annotations

from .synthesis import Boundary, Method, motion_blur, render_blurred, valid_region
from .trajectory import AcceleratedMotion, SineMotion, Trajectory, trajectory_positions
from .transfer import blur_transfer
from .units import blur_length

__all__ = [
    "AcceleratedMotion",
    "Boundary",
    "Method",
    "SineMotion",
    "Trajectory",
    "blur_length",
    "blur_transfer",
    "motion_blur",
    "render_blurred",
    "trajectory_positions",
    "valid_region",
]
