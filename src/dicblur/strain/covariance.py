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
``J Sigma_g J^T`` with the Jacobian ``J`` of the chosen strain measure (eq. 7-8).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from .fit import GridGradients, correlate_window, plane_weights

__all__ = [
    "GradientCovariance",
    "gradient_covariance",
    "noise_kernels",
    "overlap_correlation",
    "strain_covariance",
    "strains",
]

Kind = Literal["green-lagrange", "small"]


def overlap_correlation(dr: Any, dc: Any, subset: int) -> NDArray[np.float64]:
    """Correlation of the noise errors of two points ``(dr, dc)`` px apart whose square
    subsets of ``subset`` px share pixels: their shared area over a subset's (eq. 4)."""
    a = np.clip(1.0 - np.abs(np.asarray(dr, np.float64)) / subset, 0.0, None)
    b = np.clip(1.0 - np.abs(np.asarray(dc, np.float64)) / subset, 0.0, None)
    return np.asarray(a * b)


def window_correlation(half: int, step: float, subset: int) -> NDArray[np.float64]:
    """The (N**2, N**2) correlation matrix of the noise errors of a window's points
    (row-major), eq. 4."""
    k = np.arange(-half, half + 1)
    jj, kk = np.meshgrid(k, k, indexing="ij")
    r = jj.ravel() * step
    c = kk.ravel() * step
    return overlap_correlation(r[:, None] - r[None, :], c[:, None] - c[None, :], subset)


def noise_kernels(
    half: int, step: float, subset: int
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
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


@dataclass(frozen=True)
class GradientCovariance:
    """Noise covariance of the gradients and their deterministic blur errors.

    Attributes
    ----------
    uxux, uyuy, uxuy, vxvx, vyvy, vxvy : ndarray, shape (..., rows, cols)
        Noise (co)variances of ``(ux, uy)`` and of ``(vx, vy)`` (``u`` and ``v`` errors
        taken as uncorrelated).
    bux, buy, bvx, bvy : ndarray or None
        Blur errors of the gradients ``g^T xi`` (signed), None without blur shifts.
    """

    uxux: NDArray[np.float64]
    uyuy: NDArray[np.float64]
    uxuy: NDArray[np.float64]
    vxvx: NDArray[np.float64]
    vyvy: NDArray[np.float64]
    vxvy: NDArray[np.float64]
    bux: NDArray[np.float64] | None = None
    buy: NDArray[np.float64] | None = None
    bvx: NDArray[np.float64] | None = None
    bvy: NDArray[np.float64] | None = None


def gradient_covariance(
    grad: GridGradients,
    var_u: NDArray[np.floating[Any]],
    var_v: NDArray[np.floating[Any]],
    *,
    step: float,
    subset: int,
    shift_u: NDArray[np.floating[Any]] | None = None,
    shift_v: NDArray[np.floating[Any]] | None = None,
) -> GradientCovariance:
    """Noise covariance (eq. 5) and blur errors (eq. 6) of the gradients of ``grad``.

    ``var_u``, ``var_v``: noise variance of each point's ``u``, ``v`` (px**2), shape of
    the grid; ``shift_u``, ``shift_v``: signed blur-mismatch shift of each point (px).
    """
    use = grad.half
    shape = use.shape
    nv = [np.full(shape, np.nan) for _ in range(6)]
    blur = shift_u is not None and shift_v is not None
    bl = [np.full(shape, np.nan) for _ in range(4)] if blur else []
    ok = use > 0
    su = np.nan_to_num(np.asarray(var_u, np.float64))
    sv = np.nan_to_num(np.asarray(var_v, np.float64))
    if blur:
        xu = np.nan_to_num(np.asarray(shift_u, np.float64))
        xv = np.nan_to_num(np.asarray(shift_v, np.float64))
    for h in np.unique(use[ok]):
        h = int(h)
        sel = use == h
        kxx, kyy, kxy = noise_kernels(h, step, subset)
        for o, f, k in zip(
            nv, (su, su, su, sv, sv, sv), (kxx, kyy, kxy, kxx, kyy, kxy), strict=True
        ):
            o[sel] = correlate_window(f, k)[sel]
        if blur:
            gx, gy = plane_weights(h, step)
            for o, f, g in zip(bl, (xu, xu, xv, xv), (gx, gy, gx, gy), strict=True):
                o[sel] = correlate_window(f, g)[sel]
    return GradientCovariance(*nv, *(bl if blur else [None] * 4))


def strains(
    grad: GridGradients, kind: Kind
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """``(exx, eyy, exy)`` from the gradients: small strain ``ux, vy, (uy + vx) / 2`` or
    Green-Lagrange ``ux + (ux**2 + vx**2) / 2``, ``vy + (uy**2 + vy**2) / 2``,
    ``(uy + vx + ux uy + vx vy) / 2`` (eq. 7; tensor shear, not the engineering
    ``gamma = 2 exy``)."""
    ux, uy, vx, vy = grad.ux, grad.uy, grad.vx, grad.vy
    if kind == "small":
        return ux, vy, 0.5 * (uy + vx)
    return (
        ux + 0.5 * (ux**2 + vx**2),
        vy + 0.5 * (uy**2 + vy**2),
        0.5 * (uy + vx + ux * uy + vx * vy),
    )


def _jacobian(grad: GridGradients, kind: Kind) -> list[tuple[Any, Any, Any, Any]]:
    """Rows ``d(exx, eyy, exy) / d(ux, uy, vx, vy)`` (eq. 8)."""
    if kind == "small":
        return [(1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), (0.0, 0.5, 0.5, 0.0)]
    ux, uy, vx, vy = grad.ux, grad.uy, grad.vx, grad.vy
    return [
        (1.0 + ux, 0.0, vx, 0.0),
        (0.0, uy, 0.0, 1.0 + vy),
        (0.5 * uy, 0.5 * (1.0 + ux), 0.5 * (1.0 + vy), 0.5 * vx),
    ]


def strain_covariance(
    grad: GridGradients, cov: GradientCovariance, kind: Kind
) -> dict[str, tuple[NDArray[np.float64], NDArray[np.float64] | None]]:
    """``J Sigma_g J^T`` (eq. 8) of ``(exx, eyy, exy)``: for each pair ``"xx_xx"``,
    ``"yy_yy"``, ``"xy_xy"``, ``"xx_yy"``, ``"xx_xy"``, ``"yy_xy"`` the noise covariance
    and the product of the two signed blur errors (None without blur shifts)."""
    rows = _jacobian(grad, kind)
    names = ("xx", "yy", "xy")
    out: dict[str, tuple[NDArray[np.float64], NDArray[np.float64] | None]] = {}
    blur_err = None
    if cov.bux is not None:
        b = (cov.bux, cov.buy, cov.bvx, cov.bvy)
        blur_err = [sum(j * x for j, x in zip(row, b, strict=True)) for row in rows]
    for a, b_ in ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)):
        p, q = rows[a], rows[b_]
        noise = (
            p[0] * q[0] * cov.uxux
            + p[1] * q[1] * cov.uyuy
            + (p[0] * q[1] + p[1] * q[0]) * cov.uxuy
            + p[2] * q[2] * cov.vxvx
            + p[3] * q[3] * cov.vyvy
            + (p[2] * q[3] + p[3] * q[2]) * cov.vxvy
        )
        bl = None if blur_err is None else np.asarray(blur_err[a] * blur_err[b_])
        out[f"{names[a]}_{names[b_]}"] = (np.asarray(noise, np.float64), bl)
    return out
