"""The covariance of the plane-fit strains: noise correlated through shared pixels, blur.

docs/strain.md derives these formulas. In short, for a gradient ``d = g^T u`` of a window:

- noise: each point's error is a weighted sum of pixel noise (IC-GN linearised,
  ``e_i = sum_p a_i(p) n(p)``), so two points whose subsets share pixels have correlated
  errors. With the gradient energy spread evenly over a subset of ``M x M`` px the
  correlation of two points ``(dr, dc)`` px apart is the shared area,
  ``rho = (1 - |dr| / M) (1 - |dc| / M)`` for ``|dr|, |dc| < M``, else 0 (eq. 4), and
  ``var(d) = sum_kl g_k g_l rho_kl s_k s_l``, evaluated with ``s_k s_l`` replaced by
  ``(s_k**2 + s_l**2) / 2`` (exact for a uniform sigma; one correlation per field):
  ``var(d) = sum_k s_k**2 g_k (R g)_k`` (eq. 5);
- blur: the mismatch shift ``xi_i`` of a subset is a deterministic error of that subset at
  that blur (docs/track.md), so the blur error of the gradient is ``g^T xi`` itself, its
  own magnitude the blur part of sigma (the sign known, it neither averages out nor adds
  in quadrature over the window) (eq. 6).

The strains are functions of the four gradients ``(ux, uy, vx, vy)``; their covariance is
``J Sigma_g J^T`` with the Jacobian ``J`` of the chosen strain measure (eq. 7-8;
:mod:`.kernels`).
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np

from ..arrays import Float64Array
from .fit import plane_weights

__all__ = [
    "Kind",
    "gradient_factor",
    "noise_kernels",
    "overlap_correlation",
    "window_correlation",
]

Kind = Literal["green-lagrange", "small"]


def overlap_correlation(dr: Any, dc: Any, subset: int) -> Float64Array:
    """Correlation of the noise errors of two points ``(dr, dc)`` px apart whose square
    subsets of ``subset`` px share pixels: their shared area over a subset's (eq. 4)."""
    a = np.clip(1.0 - np.abs(np.asarray(dr, np.float64)) / subset, 0.0, None)
    b = np.clip(1.0 - np.abs(np.asarray(dc, np.float64)) / subset, 0.0, None)
    return np.asarray(a * b)


def window_correlation(half: int, step: float, subset: int) -> Float64Array:
    """The (N**2, N**2) correlation matrix of the noise errors of a window's points
    (row-major), eq. 4."""
    k = np.arange(-half, half + 1)
    jj, kk = np.meshgrid(k, k, indexing="ij")
    r = jj.ravel() * step
    c = kk.ravel() * step
    return overlap_correlation(r[:, None] - r[None, :], c[:, None] - c[None, :], subset)


def noise_kernels(
    half: int, step: float, subset: int
) -> tuple[Float64Array, Float64Array, Float64Array]:
    """Kernels ``K`` with ``var(ux) = sum_k K_xx[k] s_k**2`` (eq. 5), and ``K_yy``,
    ``K_xy`` (for ``cov(ux, uy)``), each (N, N), 1/px**2."""
    gx, gy = plane_weights(half, step)
    r = window_correlation(half, step, subset)
    ax, ay = gx.ravel(), gy.ravel()
    rx, ry = r @ ax, r @ ay
    n = gx.shape
    kxx = (ax * rx).reshape(n)
    kyy = (ay * ry).reshape(n)
    kxy = (0.5 * (ax * ry + ay * rx)).reshape(n)
    return kxx, kyy, kxy


def gradient_factor(half: int, step: float, subset: int) -> float:
    """``sigma(du/dx) / sigma_u`` (1/px) of a complete window for a uniform noise sigma
    with the overlap correlation (eq. 5): ``sqrt(g^T R g)``."""
    kxx, _, _ = noise_kernels(half, step, subset)
    return float(np.sqrt(kxx.sum()))
