"""Blur sensitivity of a pattern: the deterministic blur-mismatch shift of subset DIC.

Shared by :mod:`dicblur.metrics` (the ``blur_sensitivity_c`` field of
:class:`~dicblur.metrics.PatternMetrics`) and :mod:`dicblur.models` (the noise + blur-mismatch
model). It imports nothing from either, so neither import creates a cycle.

Derivation (docs/models.md has it in full)
------------------------------------------
A box blur of length ``W`` px along the unit direction ``d`` is, for a smooth image,
``g = f + (W**2 / 24) f_dd + O(W**4)`` with ``f_dd = d^T H(f) d`` the second directional
derivative (the centred box's second moment is ``W**2 / 12``). The SSD matcher of a subset
minimises ``sum [g(x + p) - f(x)]**2`` over the shape parameters ``p``; linearising in ``p``
gives ``sum [J p + (W**2 / 24) f_dd]**2`` with ``J`` the steepest-descent images of the
shape function, hence ``p = -(W**2 / 24) (J^T J)^-1 J^T f_dd``:

- translation: ``J = [f_x, f_y]``;
- affine (first-order): ``J = [f_x, f_x dx, f_x dy, f_y, f_y dx, f_y dy]`` with ``(dx, dy)``
  the offsets from the subset centre; the centre displacement is ``(p[0], p[3])``, i.e. the
  blur term projected off the components that the gradient terms explain.

For subset ``i`` the displacement along the motion is ``xi_i = k_i W**2`` and the spread
over subsets gives ``u_blur = c W**2`` with ``c = std_i(k_i)``. For motion along x, the
translation form without the ``f_x f_y`` coupling reduces to the paper-brief's
``k_i = -sum(f_x f_xx) / (24 sum(f_x**2))``.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from .errors import InputError

__all__ = ["directional_derivatives", "subset_blur_coefficients"]

Shape = Literal["translation", "affine"]
Derivative = Literal["spectral", "central"]
Boundary = Literal["reflect", "periodic"]


def _unit(motion: tuple[float, float]) -> tuple[float, float]:
    try:
        dy, dx = (float(motion[0]), float(motion[1]))
    except (TypeError, ValueError, IndexError) as exc:
        raise InputError(
            f"motion={motion!r}: expected a (dy, dx) pair of numbers (px), e.g. (0, 1)"
        ) from exc
    n = math.hypot(dy, dx)
    if not math.isfinite(n) or n == 0:
        raise InputError(
            f"motion={motion!r}: the motion direction must be a finite, non-zero (dy, dx) "
            "vector, e.g. (0, 1) for motion along x"
        )
    return dy / n, dx / n


def directional_derivatives(
    image: NDArray[np.float64],
    motion: tuple[float, float] = (0.0, 1.0),
    *,
    derivative: Derivative = "spectral",
    boundary: Boundary = "reflect",
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """``(f_y, f_x, f_dd)``: gradients and the second derivative along ``motion``.

    Parameters
    ----------
    image : ndarray, shape (rows, cols)
        Grey levels (float64, finite).
    motion : (dy, dx)
        Motion direction (any length; normalised here).
    derivative : {"spectral", "central"}
        Fourier derivatives (exact for band-limited images) or second-order finite
        differences (``f_x = (f[i+1] - f[i-1]) / 2``, ``f_xx = f[i+1] - 2 f[i] + f[i-1]``).
    boundary : {"reflect", "periodic"}
        How the spectral derivative extends the image: mirror-symmetric (no intensity jump
        at the border, for camera images) or periodic (exact for tiling synthetic patterns).
        Finite differences use the same extension for the 1-px border.

    Returns
    -------
    fy, fx, fdd : ndarray, shape (rows, cols)
        Grey levels / px and grey levels / px**2.
    """
    dy, dx = _unit(motion)
    rows, cols = image.shape
    if derivative == "spectral":
        if boundary == "reflect":
            ext = np.pad(image, ((0, rows), (0, cols)), mode="symmetric")
        else:
            ext = image
        shp = ext.shape
        spec = np.fft.rfft2(ext)
        ky = 2j * np.pi * np.fft.fftfreq(shp[0])[:, None]
        kx = 2j * np.pi * np.fft.rfftfreq(shp[1])[None, :]
        kyy, kxx = ky * ky, kx * kx
        ky_odd, kx_odd = ky.copy(), kx.copy()
        if shp[0] % 2 == 0:  # the Nyquist bin of an odd derivative is not real
            ky_odd[shp[0] // 2] = 0
        if shp[1] % 2 == 0:
            kx_odd[:, -1] = 0
        fy = np.fft.irfft2(spec * ky_odd, s=shp)[:rows, :cols]
        fx = np.fft.irfft2(spec * kx_odd, s=shp)[:rows, :cols]
        fdd = np.fft.irfft2(spec * (dx * dx * kxx + 2 * dx * dy * ky * kx + dy * dy * kyy),
                            s=shp)
        return fy, fx, fdd[:rows, :cols]
    if derivative != "central":
        raise InputError(
            f"derivative={derivative!r}: unknown derivative; choose 'spectral' or 'central'"
        )
    p = np.pad(image, 1, mode="symmetric" if boundary == "reflect" else "wrap")
    c = p[1:-1, 1:-1]
    fx = 0.5 * (p[1:-1, 2:] - p[1:-1, :-2])
    fy = 0.5 * (p[2:, 1:-1] - p[:-2, 1:-1])
    fxx = p[1:-1, 2:] - 2 * c + p[1:-1, :-2]
    fyy = p[2:, 1:-1] - 2 * c + p[:-2, 1:-1]
    fxy = 0.25 * (p[2:, 2:] - p[2:, :-2] - p[:-2, 2:] + p[:-2, :-2])
    return fy, fx, dx * dx * fxx + 2 * dx * dy * fxy + dy * dy * fyy


def subset_blur_coefficients(
    image: NDArray[np.float64],
    centres: NDArray[np.intp],
    subset: int,
    *,
    motion: tuple[float, float] = (0.0, 1.0),
    shape: Shape = "translation",
    derivative: Derivative = "spectral",
    boundary: Boundary = "reflect",
    chunk: int = 256,
) -> NDArray[np.float64]:
    """Per-subset blur-mismatch coefficient ``k_i`` (px / px**2): ``xi_i = k_i W**2``.

    ``xi_i`` is the displacement (px) along ``motion`` that an SSD matcher with the given
    shape function finds between the sharp reference and the copy blurred by a centred box
    of length ``W`` along ``motion``, to leading order in ``W`` (module docstring).

    Parameters
    ----------
    image : ndarray, shape (rows, cols)
    centres : ndarray of int, shape (n, 2)
        Subset centres (row, col); each subset must lie inside the image.
    subset : int
        Odd subset size, px.
    motion, derivative, boundary
        See :func:`directional_derivatives`.
    shape : {"translation", "affine"}
        Shape function of the matcher.

    Returns
    -------
    ndarray, shape (n,)
        ``k_i``; ``nan`` where the subset has no gradient (singular normal matrix).
    """
    if shape not in ("translation", "affine"):
        raise InputError(f"shape={shape!r}: unknown shape function; use 'translation' or 'affine'")
    dy, dx = _unit(motion)
    fy, fx, fdd = directional_derivatives(image, motion, derivative=derivative, boundary=boundary)
    h = subset // 2
    off = np.arange(-h, h + 1, dtype=np.float64)
    oy, ox = np.meshgrid(off, off, indexing="ij")
    wins = [np.lib.stride_tricks.sliding_window_view(a, (subset, subset)) for a in (fx, fy, fdd)]
    out = np.empty(len(centres))
    for start in range(0, len(centres), chunk):
        cc = centres[start : start + chunk]
        r0 = cc[:, 0] - h
        c0 = cc[:, 1] - h
        gx, gy, e = (w[r0, c0].reshape(len(cc), -1) for w in wins)
        if shape == "translation":
            jac = np.stack([gx, gy], axis=2)
        else:
            ex = ox.ravel()[None, :]
            ey = oy.ravel()[None, :]
            jac = np.stack([gx, gx * ex, gx * ey, gy, gy * ex, gy * ey], axis=2)
        jtj = np.einsum("npi,npj->nij", jac, jac)
        jte = np.einsum("npi,np->ni", jac, e)
        det_ok = np.linalg.cond(jtj) < 1e12
        sol = np.full(jte.shape, np.nan)
        if det_ok.any():
            sol[det_ok] = np.linalg.solve(jtj[det_ok], jte[det_ok][..., None])[..., 0]
        u = sol[:, 0]
        v = sol[:, 1] if shape == "translation" else sol[:, 3]
        out[start : start + len(cc)] = -(dx * u + dy * v) / 24.0
    return out
