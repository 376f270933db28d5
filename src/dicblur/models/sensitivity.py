"""Blur sensitivity of a pattern: the deterministic blur-mismatch shift of subset DIC.

The subset-level formulas under :func:`dicblur.models.blur_sensitivity`,
:func:`~dicblur.models.blur_mismatch_curve`, :func:`~dicblur.models.predict_from_pattern`
(the noise + blur-mismatch model) and the per-point sigma of :mod:`dicblur.track`.

Derivation (docs/models.md has it in full)
------------------------------------------
A box blur of length ``W`` px along the unit direction ``d`` is, for a smooth image,
``g = f + (W**2 / 24) f_dd + O(W**4)`` with ``f_dd = d^T H(f) d`` the second directional
derivative (the centred box's second moment is ``W**2 / 12``).

IC-GN with the ZNSSD criterion stops where ``sum J_f^T [f_hat - g_hat(x + p)] = 0``:
``J_f`` are the steepest-descent images of the shape function built from the *reference
gradients the matcher uses* (the derivatives of its B-spline interpolant, not the true
ones), and ``f_hat``, ``g_hat`` are the subset intensities with mean removed and unit norm.
Linearised in ``p`` (the mismatch is a few hundredths of a pixel), with ``P_g`` the
projection off the constant and off ``g_hat`` (the ZNSSD offset and scale)::

    p = sigma_g (J_f^T P_g J_g)^-1 J_f^T (f_hat - g_hat)                      (exact in W)
    p = -(W**2 / 24) (J_f^T P_f J_f)^-1 J_f^T P_f f_dd + O(W**4)           (leading order)

- translation: ``J = [f_x, f_y]``;
- affine (first-order): ``J = [f_x, f_x dx, f_x dy, f_y, f_y dx, f_y dy]`` with ``(dx, dy)``
  the offsets from the subset centre; the centre displacement is ``(p[0], p[3])``.

The first form keeps every order of the blur (``g`` is the exactly blurred image and
``J_g`` its spline gradients: the blurred image's weaker gradients enlarge the shift at
large ``W``); only the shift itself is linearised. For subset ``i`` the leading-order
displacement along the motion is ``xi_i = k_i W**2`` and the spread over subsets gives
``u_blur = c W**2`` with ``c = std_i(k_i)``. For motion along x, SSD (no projection),
spectral derivatives and no ``f_x f_y`` coupling this is the paper-brief's
``k_i = -sum(f_x f_xx) / (24 sum(f_x**2))``.

Why the matcher's gradients: the blur difference ``f_dd`` lives at high spatial
frequencies, where the spline derivative is weaker than the true one, so the weighting
``J_f^T f_dd`` is the matcher's own. With true (spectral) gradients ``c`` is 8-25 % lower
than noise-free IC-GN measures on thresholded speckles; with the spline gradients and the
ZNSSD projection it agrees within 0.5 % as W -> 0 (BENCHMARKS.md, models section).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterator
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..dic.interpolation import (
    bspline_at_offset,
    bspline_coefficients,
    bspline_gradients,
    bspline_kernel,
    bspline_kernel_derivative,
)
from ..errors import InputError
from ..threads import each

__all__ = [
    "box_blurred",
    "directional_derivatives",
    "image_spectrum",
    "shifts_and_variance",
    "spectral_derivatives",
    "spline_gradients",
    "subset_blur_coefficients",
    "subset_blur_response",
    "subset_blur_shifts",
    "subset_noise_variance",
    "subset_skew_coefficients",
    "unit_direction",
]

Shape = Literal["translation", "affine"]
Derivative = Literal["bspline3", "bspline5", "spectral", "central"]
Criterion = Literal["znssd", "ssd"]
Boundary = Literal["reflect", "periodic"]


def unit_direction(motion: tuple[float, float]) -> tuple[float, float]:
    """The unit vector ``(dy, dx)`` of a motion direction given as any non-zero (dy, dx)."""
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


def _extend(image: NDArray[np.float64], boundary: Boundary) -> NDArray[np.float64]:
    """The periodic image the spectral operators act on (mirror: even 2x extension)."""
    if boundary == "reflect":
        rows, cols = image.shape
        return np.pad(image, ((0, rows), (0, cols)), mode="symmetric")
    if boundary == "periodic":
        return image
    raise InputError(f"boundary={boundary!r}: choose 'reflect' or 'periodic'")


def spectral_derivatives(
    image: NDArray[np.float64],
    boundary: Boundary,
    dy: float,
    dx: float,
    blur: float | None = None,
    spectrum: tuple[Any, tuple[int, int]] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Spectral ``(f_y, f_x, f_dd)``; with ``blur`` the centred box blur along ``(dy, dx)``
    of length ``blur`` px replaces ``f_dd`` (transfer ``sinc(blur * k.d)``, real: no shift).
    ``spectrum``: ``_spectrum(image, boundary)`` computed before (the same numbers; one
    forward FFT for the several blur lengths of a table).
    """
    rows, cols = image.shape
    spec, shp = _spectrum(image, boundary) if spectrum is None else spectrum
    fy_ = np.fft.fftfreq(shp[0])[:, None]
    fx_ = np.fft.rfftfreq(shp[1])[None, :]
    if blur is not None:
        out = _crop(np.fft.irfft2(spec * np.sinc(blur * (dy * fy_ + dx * fx_)), s=shp), rows, cols)
        return out, out, out
    ky, kx = 2j * np.pi * fy_, 2j * np.pi * fx_
    ky_odd, kx_odd = ky.copy(), kx.copy()
    if shp[0] % 2 == 0:  # the Nyquist bin of an odd derivative is not real
        ky_odd[shp[0] // 2] = 0
    if shp[1] % 2 == 0:
        kx_odd[:, -1] = 0
    fy = _crop(np.fft.irfft2(spec * ky_odd, s=shp), rows, cols)
    fx = _crop(np.fft.irfft2(spec * kx_odd, s=shp), rows, cols)
    return fy, fx, _second(spec, shp, dy, dx, rows, cols)


def _spectrum(image: NDArray[np.float64], boundary: Boundary) -> tuple[Any, tuple[int, int]]:
    """``rfft2`` of the extended image and the extended shape."""
    ext = _extend(image, boundary)
    return np.fft.rfft2(ext), (int(ext.shape[0]), int(ext.shape[1]))


def _crop(full: NDArray[np.float64], rows: int, cols: int) -> NDArray[np.float64]:
    """The image's part of an extended result, as its own array: a view would keep the
    extended buffer (4x the image) alive (a long track's memory, issue 17)."""
    return np.ascontiguousarray(full[:rows, :cols])


def _second(
    spec: Any, shp: tuple[int, int], dy: float, dx: float, rows: int, cols: int
) -> NDArray[np.float64]:
    """Second derivative along ``(dy, dx)`` from the spectrum of the extended image."""
    ky = 2j * np.pi * np.fft.fftfreq(shp[0])[:, None]
    kx = 2j * np.pi * np.fft.rfftfreq(shp[1])[None, :]
    fdd = np.fft.irfft2(
        spec * (dx * dx * kx * kx + 2 * dx * dy * ky * kx + dy * dy * ky * ky), s=shp
    )
    return _crop(fdd, rows, cols)


def box_blurred(
    image: NDArray[np.float64],
    boundary: Boundary,
    dy: float,
    dx: float,
    blur: float,
    spectrum: tuple[Any, tuple[int, int]] | None = None,
) -> NDArray[np.float64]:
    """``image`` blurred by the centred box of length ``blur`` px along the unit ``(dy, dx)``
    (exact spectral blur, :func:`spectral_derivatives`, whose ``spectrum`` it passes on),
    shape (rows, cols)."""
    return spectral_derivatives(image, boundary, dy, dx, blur=blur, spectrum=spectrum)[0]


def image_spectrum(image: NDArray[np.float64], boundary: Boundary) -> tuple[Any, tuple[int, int]]:
    """The spectrum :func:`box_blurred` takes to blur ``image`` by several lengths with one
    forward FFT: ``rfft2`` of the image extended as ``boundary`` asks, and its shape."""
    return _spectrum(image, boundary)


def spline_gradients(
    image: NDArray[np.float64], derivative: str
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(f_y, f_x)`` of the matcher's B-spline interpolant at the pixels (as IC-GN uses),
    ``derivative`` "bspline3" or "bspline5"; shape (rows, cols) each, GL / px."""
    order = 3 if derivative == "bspline3" else 5
    coef = bspline_coefficients(image, order=order, dtype=np.float64)
    return bspline_gradients(coef, order, image.shape)


def _interpolated_at(
    image: NDArray[np.float64], boundary: Boundary, oy: float, ox: float, order: int
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The current image of a target moved by the sub-pixel offset ``(oy, ox)`` (px), as
    the matcher sees it back on the reference grid: ``(h~, h~_y, h~_x)`` at ``x + o``, with
    ``h = image(x - o)`` (exact spectral shift) sampled at the pixels and ``h~`` its B-spline
    interpolant of degree ``order``. ``h~(x + o) = image(x)`` but for the interpolation
    error, which is the matcher's sub-pixel bias (docs/models.md s. 4)."""
    rows, cols = image.shape
    ext = _extend(image, boundary)
    shp = ext.shape
    phase = np.exp(
        -2j * np.pi * (np.fft.fftfreq(shp[0])[:, None] * oy + np.fft.rfftfreq(shp[1])[None, :] * ox)
    )
    h = np.fft.irfft2(np.fft.rfft2(ext) * phase, s=shp)[:rows, :cols]
    coef = bspline_coefficients(h, order=order, dtype=np.float64)
    out, gy, gx = bspline_at_offset(coef, order, h.shape, oy, ox)
    assert out is not None
    return out, gy, gx


def _interpolated_noise_covariance(t: float, order: int, size: int) -> NDArray[np.float64]:
    """Toeplitz covariance (size, size) of unit white noise after B-spline interpolation of
    degree ``order`` at the fractional offset ``t`` (px): ``C(d) = sum_m k(m) k(m + d)``
    with ``k`` the interpolator's impulse response, transfer
    ``sum_m beta(t - m) e^{i w m} / sum_m beta(m) e^{-i w m}`` (prefilter, then taps)."""
    n = 4096
    om = 2.0 * np.pi * np.fft.fftfreq(n)
    lo = -(order - 1) // 2
    num = sum(
        float(bspline_kernel(np.array(t - m), order)) * np.exp(1j * om * m)
        for m in range(lo, lo + order + 1)
    )
    half = (order + 1) // 2
    den = sum(
        float(bspline_kernel(np.array(float(m)), order)) * np.cos(om * m)
        for m in range(-half, half + 1)
    )
    acov = np.fft.ifft(np.abs(num) ** 2 / den**2).real
    d = np.abs(np.arange(size)[:, None] - np.arange(size)[None, :])
    return np.asarray(acov[d])


def _derivative_kernel(derivative: str, subset: int, tol: float = 1e-9) -> NDArray[np.float64]:
    """Impulse response ``d[m]``, ``m = -L..L``, of the matcher's derivative at the pixels:
    ``f_x[j] = sum_m d[m] n[j - m]``. For a B-spline, the derivative of the interpolant of
    the samples ``n`` (prefilter, then the derivative taps; transfer ``sum_m beta'(m)
    e^{-i w m} / sum_m beta(m) e^{-i w m}``), truncated where ``|d| < tol max |d|`` (the
    prefilter's poles decay as 0.27^m for the cubic, 0.43^m for the quintic spline);
    ``"central"``: ``(n[j+1] - n[j-1]) / 2``; ``"spectral"``: the ideal derivative
    ``(-1)^(m+1) / m`` of an infinite signal, cut at ``L = 3 subset`` (it decays as 1/m).
    Real and odd."""
    if derivative == "central":
        return np.array([0.5, 0.0, -0.5])
    if derivative == "spectral":
        m = np.arange(-3 * subset, 3 * subset + 1, dtype=np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.asarray(np.where(m == 0, 0.0, -((-1.0) ** np.abs(m)) / m))
    order = 3 if derivative == "bspline3" else 5
    n = 4096
    om = 2.0 * np.pi * np.fft.fftfreq(n)
    half = (order + 1) // 2
    ms = range(-half, half + 1)
    num = sum(
        float(bspline_kernel_derivative(np.array(float(m)), order)) * np.exp(-1j * om * m)
        for m in ms
    )
    den = sum(float(bspline_kernel(np.array(float(m)), order)) * np.cos(om * m) for m in ms)
    d = np.fft.ifft(num / den).real
    d = np.concatenate([d[n // 2 :], d[: n // 2]])  # lag -n/2 .. n/2 - 1
    big = np.flatnonzero(np.abs(d) >= tol * np.abs(d).max())
    lag = max(abs(int(big[0]) - n // 2), abs(int(big[-1]) - n // 2))
    return np.asarray(d[n // 2 - lag : n // 2 + lag + 1])


def _reference_noise_middle(
    pf: NDArray[np.float64],
    ratio: NDArray[np.float64],
    sg: NDArray[np.float64],
    r0: NDArray[np.float64],
    subset: int,
    shape: str,
    ex: NDArray[np.float64],
    ey: NDArray[np.float64],
    kernel: NDArray[np.float64],
    pf_gram: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]:
    """``M^T M`` of the reference noise's response ``A^-1 M^T n``, per unit noise variance:
    ``M = ratio P_f J_f + sigma_g Q`` with ``Q = [D_k^T (S_k r0)]`` (docs/models.md s. 4,
    the complete noise term). Shape (m, k, k). ``pf_gram``: ``(P_f J_f)^T (P_f J_f)``
    computed before (it does not depend on the blur).

    ``Q[:, k] = D_k^T (S_k r0)`` is the linear functional of the reference noise ``n`` by
    which the noisy gradients move ``J_f^T r0`` (``delta J_f[:, k] = S_k D n``, ``D`` the
    spline derivative along x or y with impulse response ``kernel``, ``S_k`` the weight
    1, dx or dy of the shape function; the columns in the order of
    :meth:`_Windows.jacobian`). ``D^T`` spreads each field by the kernel's half-length
    ``L`` along its axis (the gradients at the subset's pixels depend on noise just
    outside it): with ``T`` (S + 2L, S) the spreading matrix, ``Q_k^T Q_l`` of two fields
    spread along one axis is ``v_k^T (T^T T) v_l`` row by row (or column by column),
    ``v_k = S_k r0`` (S, S), so the spread fields are never formed; on the subset's own
    pixels (where x- and y-spread fields and ``P_f J_f`` meet them) ``Q`` is
    ``T[L:L+S]`` applied to ``v_k``.
    """
    m, npx, k = pf.shape
    size = subset
    lag = len(kernel) // 2
    if shape == "translation":
        weights = [np.ones_like(ex)]
    else:
        weights = [np.ones_like(ex), ex, ey]
    kx = len(weights)  # x-type columns; as many y-type
    w3 = np.stack([(wt * np.ones((1, npx))).reshape(size, size) for wt in weights])
    # T[a, i] = d[i - (a - L)]: (D^T v)[a] = sum_i d[i - a] v[i] over the extended axis
    idx = np.arange(size)[None, :] - (np.arange(size + 2 * lag)[:, None] - lag) + lag
    tmat = np.where((idx >= 0) & (idx < len(kernel)), kernel[np.clip(idx, 0, len(kernel) - 1)], 0.0)
    tt = tmat.T @ tmat  # (S, S): the spread fields' inner products
    tsub = tmat[lag : lag + size]  # (S, S): the spread fields on the subset's pixels
    v = r0.reshape(m, 1, size, size) * w3[None]  # (m, kx, S, S): S_k r0
    vt = v.reshape(m, kx, npx).transpose(0, 2, 1)  # (m, P, kx)
    qq = np.empty((m, k, k))
    qq[:, :kx, :kx] = np.matmul(np.matmul(v, tt).reshape(m, kx, npx), vt)  # along rows
    qq[:, kx:, kx:] = np.matmul(np.matmul(tt, v).reshape(m, kx, npx), vt)  # along columns
    q_sub = np.concatenate(
        [np.matmul(v, tsub.T).reshape(m, kx, npx), np.matmul(tsub, v).reshape(m, kx, npx)],
        axis=1,
    )  # (m, k, P): Q on the subset's own pixels
    xy = np.matmul(q_sub[:, :kx], q_sub[:, kx:].transpose(0, 2, 1))
    qq[:, :kx, kx:] = xy  # x- and y-spread fields overlap on the subset only
    qq[:, kx:, :kx] = np.transpose(xy, (0, 2, 1))
    cross = np.matmul(np.swapaxes(pf, 1, 2), q_sub.transpose(0, 2, 1))
    r = ratio[:, None, None]
    s = sg[:, None, None]
    gpf = _gram(pf, pf) if pf_gram is None else pf_gram
    return r * r * gpf + r * s * (cross + np.transpose(cross, (0, 2, 1))) + s * s * qq


def _check_derivative(derivative: str) -> None:
    if derivative not in ("bspline3", "bspline5", "spectral", "central"):
        raise InputError(
            f"derivative={derivative!r}: unknown derivative; choose 'bspline3' (the DIC "
            "engine's cubic spline, default), 'bspline5', 'spectral' or 'central'"
        )


def directional_derivatives(
    image: NDArray[np.float64],
    motion: tuple[float, float] = (0.0, 1.0),
    *,
    derivative: Derivative = "bspline3",
    boundary: Boundary = "reflect",
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """``(f_y, f_x, f_dd)``: gradients and the second derivative along ``motion``.

    Parameters
    ----------
    image : ndarray, shape (rows, cols)
        Grey levels (float64, finite).
    motion : (dy, dx)
        Motion direction (any length; normalised here).
    derivative : {"bspline3", "bspline5", "spectral", "central"}
        Operator for the gradients ``f_y, f_x``: the derivatives of the cubic / quintic
        B-spline interpolant (what the IC-GN engine with that interpolation uses, default),
        Fourier derivatives (exact for band-limited images) or central differences
        (``f_x = (f[i+1] - f[i-1]) / 2``). ``f_dd`` is the action of the blur on the image
        itself, so it is spectral for the spline and spectral options and the second
        difference ``f[i+1] - 2 f[i] + f[i-1]`` for ``"central"``.
    boundary : {"reflect", "periodic"}
        How the spectral operators extend the image: mirror-symmetric (no intensity jump
        at the border, for camera images) or periodic (exact for tiling synthetic patterns).
        Finite differences use the same extension for the 1-px border.

    Returns
    -------
    fy, fx, fdd : ndarray, shape (rows, cols)
        Grey levels / px and grey levels / px**2.
    """
    _check_derivative(derivative)
    dy, dx = unit_direction(motion)
    if derivative in ("bspline3", "bspline5"):
        # the spline's own gradients; only the second derivative is spectral
        spec, shp = _spectrum(image, boundary)
        fdd = _second(spec, shp, dy, dx, *image.shape)
        del spec
        fy, fx = spline_gradients(image, derivative)
        return fy, fx, fdd
    if derivative != "central":
        return spectral_derivatives(image, boundary, dy, dx)
    if boundary not in ("reflect", "periodic"):
        _extend(image, boundary)  # raises the boundary error
    p = np.pad(image, 1, mode="symmetric" if boundary == "reflect" else "wrap")
    c = p[1:-1, 1:-1]
    fx = 0.5 * (p[1:-1, 2:] - p[1:-1, :-2])
    fy = 0.5 * (p[2:, 1:-1] - p[:-2, 1:-1])
    fxx = p[1:-1, 2:] - 2 * c + p[1:-1, :-2]
    fyy = p[2:, 1:-1] - 2 * c + p[:-2, 1:-1]
    fxy = 0.25 * (p[2:, 2:] - p[2:, :-2] - p[:-2, 2:] + p[:-2, :-2])
    return fy, fx, dx * dx * fxx + 2 * dx * dy * fxy + dy * dy * fyy


def _check_shape(shape: str) -> None:
    if shape not in ("translation", "affine"):
        raise InputError(f"shape={shape!r}: unknown shape function; use 'translation' or 'affine'")


def _check_criterion(criterion: str) -> None:
    if criterion not in ("znssd", "ssd"):
        raise InputError(
            f"criterion={criterion!r}: unknown matching criterion; use 'znssd' (the DIC "
            "engine's, default) or 'ssd'"
        )


class _Windows:
    """Subset windows of several images, gathered a chunk of centres at a time."""

    def __init__(self, subset: int, *images: NDArray[np.float64]) -> None:
        self.h = subset // 2
        self.views = [np.lib.stride_tricks.sliding_window_view(a, (subset, subset)) for a in images]
        off = np.arange(-self.h, self.h + 1, dtype=np.float64)
        oy, ox = np.meshgrid(off, off, indexing="ij")
        self.ex, self.ey = ox.ravel()[None, :], oy.ravel()[None, :]

    def take(self, cc: NDArray[np.intp]) -> list[NDArray[np.float64]]:
        r0, c0 = cc[:, 0] - self.h, cc[:, 1] - self.h
        return [v[r0, c0].reshape(len(cc), -1) for v in self.views]

    def jacobian(
        self, gx: NDArray[np.float64], gy: NDArray[np.float64], shape: str
    ) -> NDArray[np.float64]:
        """Steepest-descent images, shape (m, pixels, 2 | 6)."""
        if shape == "translation":
            return np.stack([gx, gy], axis=2)
        ex, ey = self.ex, self.ey
        # the products written into their columns (no temporaries to stack)
        out = np.empty((*gx.shape, 6))
        for c, (g, e) in enumerate(
            ((gx, None), (gx, ex), (gx, ey), (gy, None), (gy, ex), (gy, ey))
        ):
            if e is None:
                out[:, :, c] = g
            else:
                np.multiply(g, e, out=out[:, :, c])
        return out


def _normalise(a: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Rows with mean removed and unit norm, and their norms (m, pixels), (m,)."""
    z = a - a.mean(axis=1, keepdims=True)
    n = np.sqrt(np.einsum("np,np->n", z, z))
    return z / np.where(n > 0, n, 1.0)[:, None], n


def _project(jac: NDArray[np.float64], hat: NDArray[np.float64]) -> NDArray[np.float64]:
    """``P jac``: remove from each column the constant and the component along ``hat``
    (zero-mean, unit-norm rows): the ZNSSD offset and scale nuisance parameters."""
    z = jac - jac.mean(axis=1, keepdims=True)
    z -= hat[:, :, None] * np.matmul(hat[:, None, :], z)  # in place: one temporary fewer
    return z


def _gram(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Batched ``a^T b`` over the pixels: (m, P, i), (m, P, j) -> (m, i, j) (BLAS)."""
    return np.asarray(np.matmul(np.swapaxes(a, 1, 2), b))


def _tdot(a: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
    """Batched ``a^T v``: (m, P, i), (m, P) -> (m, i)."""
    return np.asarray(np.matmul(np.swapaxes(a, 1, 2), v[:, :, None])[:, :, 0])


def _solve(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Batched ``a^-1 b``; NaN rows where ``a`` is singular (no gradient in the subset)."""
    return _solve_each(a, [b])[0]


def _solve_each(a: NDArray[np.float64], bs: list[NDArray[np.float64]]) -> list[NDArray[np.float64]]:
    """:func:`_solve` of one batch of matrices ``a`` for each right-hand side of ``bs``
    (each (m, k)): the condition numbers (an SVD per matrix) computed once, each system
    solved as :func:`_solve` solves it (the same numbers)."""
    fin = np.isfinite(a).all(axis=(1, 2))
    sing = np.ones(len(a), dtype=bool)  # singular or not finite
    sing[fin] = ~(np.linalg.cond(a[fin]) < 1e12)
    out = []
    for b in bs:
        ok = ~sing & np.isfinite(b).all(axis=1)
        sol = np.full(b.shape, np.nan)
        if ok.any():
            sol[ok] = np.linalg.solve(a[ok], b[ok][..., None])[..., 0]
        out.append(sol)
    return out


def _along(
    sol: NDArray[np.float64], shape: str, dy: float, dx: float, max_shift: float = np.inf
) -> NDArray[np.float64]:
    u = sol[:, 0]
    v = sol[:, 1] if shape == "translation" else sol[:, 3]
    return np.where(np.hypot(u, v) <= max_shift, dx * u + dy * v, np.nan)


def subset_blur_coefficients(
    image: NDArray[np.float64],
    centres: NDArray[np.intp],
    subset: int,
    *,
    motion: tuple[float, float] = (0.0, 1.0),
    shape: Shape = "translation",
    derivative: Derivative = "bspline3",
    boundary: Boundary = "reflect",
    criterion: Criterion = "znssd",
    chunk: int = 256,
) -> NDArray[np.float64]:
    """Per-subset blur-mismatch coefficient ``k_i`` (px / px**2): ``xi_i = k_i W**2``.

    ``xi_i`` is the displacement (px) along ``motion`` that a matcher with the given shape
    function and criterion finds between the sharp reference and the copy blurred by a
    centred box of length ``W`` along ``motion``, to leading order in ``W`` (module
    docstring).

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
    criterion : {"znssd", "ssd"}
        Matching criterion: ZNSSD (the engine's; projects off the intensity offset and
        scale) or plain SSD.

    Returns
    -------
    ndarray, shape (n,)
        ``k_i``; ``nan`` where the subset has no gradient (singular normal matrix).
    """
    _check_shape(shape)
    _check_criterion(criterion)
    dy, dx = unit_direction(motion)
    fy, fx, fdd = directional_derivatives(image, motion, derivative=derivative, boundary=boundary)
    win = _Windows(subset, fx, fy, fdd, image)
    out = np.empty(len(centres))
    for start in range(0, len(centres), chunk):
        cc = centres[start : start + chunk]
        gx, gy, e, f = win.take(cc)
        jac = win.jacobian(gx, gy, shape)
        if criterion == "znssd":
            jp = _project(jac, _normalise(f)[0])
        else:
            jp = jac
        # J^T P J and J^T P f_dd (P symmetric and idempotent)
        sol = _solve(_gram(jp, jp), _tdot(jp, e))
        out[start : start + len(cc)] = -_along(sol, shape, dy, dx) / 24.0
    return out


def subset_blur_shifts(
    image: NDArray[np.float64],
    blur: NDArray[np.float64],
    centres: NDArray[np.intp],
    subset: int,
    *,
    motion: tuple[float, float] = (0.0, 1.0),
    shape: Shape = "translation",
    derivative: Derivative = "bspline3",
    boundary: Boundary = "reflect",
    criterion: Criterion = "znssd",
    max_shift: float = 1.0,
    chunk: int = 256,
    offset: float | None = None,
) -> NDArray[np.float64]:
    """Per-subset blur-mismatch shifts at finite blur lengths, every order in ``W``.

    The displacement (px) along ``motion`` at which the matcher's fixed point
    ``sum J_f^T [f_hat - g_hat(x + p)] = 0`` sits, with ``g`` the image blurred by a centred
    box of length ``W`` (exact spectral blur), linearised in the shift only (module
    docstring). As ``W -> 0`` it tends to ``k_i W**2`` of :func:`subset_blur_coefficients`.

    This is where inverse-compositional Gauss-Newton stops (its update uses the reference
    gradients ``J_f``). Once the images differ by more than a warp, it is not the ZNSSD
    minimum (stationary in the *current* image's gradients): the two differ at order
    ``W**4``, and noise-free IC-GN follows this one.

    Parameters
    ----------
    image : ndarray, shape (rows, cols)
        Sharp reference image, grey levels.
    blur : ndarray, shape (m,)
        Blur lengths ``W`` (px, >= 0).
    centres, subset, motion, shape, derivative, boundary, criterion
        As for :func:`subset_blur_coefficients`.
    max_shift : float
        Breakdown threshold (px): a subset whose linearised shift vector is longer is
        reported ``nan``. The linearisation needs shifts well below a pixel; beyond, the
        blur has erased the subset's texture along the motion and IC-GN itself stops
        converging on about as many POIs (3 px speckles, affine, W = 8 px: the rule keeps
        90 % of the subsets, IC-GN converges on 90-92 %).
    offset : float, optional
        Sub-pixel position (px along the motion) of the moving target: the blurred image is
        moved by it and matched through the B-spline interpolant of ``derivative``, so the
        shifts carry the matcher's interpolation bias at that offset (the floor and the
        cross term of the mismatch model). Default: no interpolation (exactly aligned).

    Returns
    -------
    ndarray, shape (m, n)
        Shift of subset ``i`` at blur ``W_j`` (px, along the motion, relative to the blur's
        own centre and the offset); ``nan`` where the subset has no gradient or breaks
        down.
    """
    _check_criterion(criterion)
    return shifts_and_variance(
        image,
        blur,
        centres,
        subset,
        motion=motion,
        shape=shape,
        derivative=derivative,
        boundary=boundary,
        criterion=criterion,
        max_shift=max_shift,
        chunk=chunk,
        variance=False,
        offset=offset,
    )[0]


def shifts_and_variance(
    image: NDArray[np.float64],
    blur: ArrayLike,
    centres: NDArray[np.intp],
    subset: int,
    *,
    motion: tuple[float, float],
    shape: Shape,
    derivative: Derivative,
    boundary: Boundary,
    criterion: Criterion,
    max_shift: float,
    chunk: int,
    variance: bool,
    offset: float | None = None,
    complete: bool = True,
    min_contraction: float = 0.0,
    contraction_out: NDArray[np.float64] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
    """One pass over blur lengths and subsets: the shifts (and, with ``variance``, the
    noise variance per unit noise variance) of :func:`subset_blur_shifts` and
    :func:`subset_noise_variance`.

    The variance comes as shape (3, m, n): the reference image's share and the current
    image's (per unit noise variance, first order in the noise), then the interaction of
    the two noises (per unit ``sigma**4``: the reference-gradient noise against the current
    image's noise, second order; it exists only when both images are noisy).
    ``complete=False`` drops the reference-gradient noise terms (the earlier, incomplete
    formula; kept for the benchmark's comparison). ``min_contraction > 0``: a subset whose
    IC-GN contraction (:func:`_contraction`) falls below it has broken down (``nan``).
    ``contraction_out``, shape (m, n): filled with the contraction of every subset."""
    _check_shape(shape)
    _check_derivative(derivative)
    dy, dx = unit_direction(motion)
    w = np.asarray(blur, dtype=np.float64)
    shifts = np.zeros((len(w), len(centres)))
    var = np.full((3, len(w), len(centres)), np.nan) if variance else None
    kernel = _derivative_kernel(derivative, subset) if variance and complete else None
    e = np.zeros(2 if shape == "translation" else 6)
    e[0] = dx
    e[1 if shape == "translation" else 3] = dy
    if offset is not None and derivative not in ("bspline3", "bspline5"):
        raise InputError(
            f"subpixel={offset!r} with derivative={derivative!r}: the sub-pixel "
            "position is seen through the matcher's B-spline; use "
            "derivative='bspline3' or 'bspline5'"
        )
    noise_cov: tuple[NDArray[np.float64] | None, ...] | None = None
    if offset is not None and variance:
        order = 3 if derivative == "bspline3" else 5
        oy, ox = offset * dy, offset * dx
        # None: no fractional offset along that axis, the interpolant passes noise as is
        noise_cov = tuple(
            None if t == 0.0 else _interpolated_noise_covariance(t, order, subset)
            for t in (oy - math.floor(oy), ox - math.floor(ox))
        )
    offsets = _Windows(subset)
    win_ex, win_ey = offsets.ex, offsets.ey
    # E[dJ_f^T P_g n_g n_g^T P_g dJ_f] ~= sigma**4 R(0) G (interaction share): same-axis
    # columns only (the x and y kernels share no tap: d[0] = 0), G the sums of the shape
    # weights' products; the projections' O(1/N) parts are left out
    # (the current noise through the interpolant: sum_D R(D) C(D) along the column's axis,
    # times C(0) across it; R the kernel's autocorrelation)
    gmat = np.zeros((e.size, e.size))
    if kernel is not None:
        rk = np.correlate(kernel, kernel, "full")[len(kernel) - 1 :]  # R(0), R(1), ...
        cov_yx = (None, None) if noise_cov is None else noise_cov
        c_axis = [np.eye(1)[0] if c is None else c[0] for c in cov_yx]  # C(0), C(1), ...
        along = [
            float(rk[0] * c[0] + 2 * np.dot(rk[1 : len(c)], c[1 : len(rk)])) for c in c_axis
        ]  # (y, x)
        wts = (
            np.ones((subset * subset, 1))
            if shape == "translation"
            else np.stack([np.ones(subset * subset), win_ex[0], win_ey[0]], axis=1)
        )
        gs = wts.T @ wts
        kx = wts.shape[1]
        gmat[:kx, :kx] = along[1] * c_axis[0][0] * gs  # x-type columns
        gmat[kx:, kx:] = along[0] * c_axis[1][0] * gs  # y-type columns
    for j, start, jf, jg, f, gg in _blurred_subsets(
        image, w, centres, subset, motion, shape, derivative, boundary, chunk, offset
    ):
        rows = slice(start, start + len(f))
        if criterion == "znssd" or variance:
            fh, sf = _normalise(f)
            gh, sg = _normalise(gg)
            pjg = _project(jg, gh)  # P_g J_g
            cross = _gram(jf, pjg)  # J_f^T P_g J_g
        p0 = None
        broken = np.zeros(len(f), dtype=bool)
        if w[j] > 0 or offset is not None:
            if criterion == "znssd":
                sg_ok = np.where(sg > 0, sg, np.nan)  # a flat blurred subset: no fixed point
                a = cross / sg_ok[:, None, None]
                b = _tdot(jf, fh - gh)
            else:
                a = _gram(jf, jg)
                b = _tdot(jf, f - gg)
            p0 = _solve(a, b)
            shifts[j, rows] = _along(p0, shape, dy, dx, max_shift)
            if min_contraction > 0 or contraction_out is not None:
                lam = _contraction(jf, fh, sf, cross, sg)
                if contraction_out is not None:
                    contraction_out[j, rows] = lam
                if min_contraction > 0:
                    broken = ~(lam >= min_contraction)
                    shifts[j, rows][broken] = np.nan
        elif contraction_out is not None:
            contraction_out[j, rows] = 1.0  # the reference itself: K = I
        if var is not None:
            ratio2 = (sg / np.where(sf > 0, sf, np.nan)) ** 2
            pf, pg = _project(jf, fh), _project(jf, gh)
            if noise_cov is None:
                pg_c = pg
            else:  # the current image's noise as the interpolant passes it: (C_y x C_x) pg
                m_, _, k_ = pg.shape
                cy, cx = noise_cov
                # batched BLAS along columns, then rows (an identity factor is skipped)
                pg_c = pg.reshape(m_, subset, subset, k_)
                if cx is not None:
                    pg_c = np.matmul(cx, pg_c)
                if cy is not None:
                    pg_c = np.matmul(cy, pg_c.reshape(m_, subset, subset * k_))
                pg_c = pg_c.reshape(pg.shape)
            if kernel is not None and p0 is not None:
                if criterion != "znssd":  # the ZNSSD fixed point's own shift
                    sg_ok = np.where(sg > 0, sg, np.nan)
                    p0 = _solve(cross / sg_ok[:, None, None], _tdot(jf, fh - gh))
                # residual at the linearised fixed point, orthogonal to J_f
                r0 = fh - gh - np.matmul(pjg, p0[:, :, None])[:, :, 0] / sg_ok[:, None]
                mid_ref = _reference_noise_middle(
                    pf, np.sqrt(ratio2), sg, r0, subset, shape, win_ex, win_ey, kernel
                )
            else:
                mid_ref = ratio2[:, None, None] * _gram(pf, pf)
            # e^T A^-1 M A^-T e = z^T M z with A^T z = e
            z = _solve(np.transpose(cross, (0, 2, 1)), np.broadcast_to(e, (len(f), e.size)).copy())
            var[0, j, rows] = np.einsum("ni,nij,nj->n", z, mid_ref, z)
            var[1, j, rows] = np.einsum("ni,nij,nj->n", z, _gram(pg, pg_c), z)
            var[2, j, rows] = np.einsum("ni,ij,nj->n", z, gmat, z)
            var[:, j, rows] = np.where(broken[None, :], np.nan, var[:, j, rows])
    return shifts, var


def _contraction(
    jf: NDArray[np.float64],
    fh: NDArray[np.float64],
    sf: NDArray[np.float64],
    cross: NDArray[np.float64],
    sg: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Smallest real part of the eigenvalues of ``K = (sigma_f / sigma_g) H^-1 A`` per subset,
    ``H = J_f^T P_f J_f`` (the IC-GN Hessian of ZNSSD) and ``A = J_f^T P_g J_g`` (the
    fixed point's Jacobian). IC-GN against the blurred image moves by ``I - K`` per step
    near its fixed point: ``K = I`` for a warped copy; blur lowers it, and as it nears 0
    the fixed point degenerates (the noise response grows as ``1 / lambda``, IC-GN stalls)
    and beyond 0 it repels (the blur has reversed the subset's gradients along the motion:
    the sinc's negative lobe). ``nan`` where undefined."""
    pf = _project(jf, fh)
    hess = _gram(pf, pf)
    ok = np.isfinite(hess).all(axis=(1, 2)) & np.isfinite(cross).all(axis=(1, 2)) & (sg > 0)
    ok[ok] = np.linalg.cond(hess[ok]) < 1e12
    lam = np.full(len(jf), np.nan)
    if ok.any():
        k = np.linalg.solve(hess[ok], cross[ok]) * (sf[ok] / sg[ok])[:, None, None]
        lam[ok] = np.linalg.eigvals(k).real.min(axis=1)
    return lam


def _blurred_subsets(
    image: NDArray[np.float64],
    blur: NDArray[np.float64],
    centres: NDArray[np.intp],
    subset: int,
    motion: tuple[float, float],
    shape: str,
    derivative: Derivative,
    boundary: Boundary,
    chunk: int,
    offset: float | None = None,
) -> Iterator[
    tuple[
        int, int, NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]
    ]
]:
    """``(j, start, J_f, J_g, f, g)`` for every blur length and chunk of subsets: the
    steepest-descent images of the sharp and of the centred-box-blurred image, and their
    subset intensities (W = 0: ``g = f``). With ``offset`` (px along the motion) the
    blurred target is moved by it and seen through the matcher's B-spline interpolant
    (:func:`_interpolated_at`)."""
    dy, dx = unit_direction(motion)
    if derivative in ("bspline3", "bspline5"):  # the spline's gradients (f_dd not needed)
        _extend(image[:1, :1], boundary)  # raises the boundary error
        fy, fx = spline_gradients(image, derivative)
    else:
        fy, fx, _ = directional_derivatives(image, motion, derivative=derivative, boundary=boundary)
    spec = None  # the reference's spectrum, one forward FFT for all the blur lengths
    for j, wl in enumerate(np.asarray(blur, dtype=np.float64)):
        if wl != 0 and spec is None:
            spec = image_spectrum(image, boundary)
        g, ggy, ggx = _blurred_images(
            image, float(wl), (dy, dx), (fy, fx), derivative, boundary, spec, offset
        )
        win = _Windows(subset, fx, fy, ggx, ggy, image, g)
        for start in range(0, len(centres), chunk):
            ax, ay, bx, by, f, gg = win.take(centres[start : start + chunk])
            yield j, start, win.jacobian(ax, ay, shape), win.jacobian(bx, by, shape), f, gg


def _blurred_images(
    image: NDArray[np.float64],
    blur: float,
    direction: tuple[float, float],
    grads: tuple[NDArray[np.float64], NDArray[np.float64]],
    derivative: Derivative,
    boundary: Boundary,
    spec: tuple[Any, tuple[int, int]] | None,
    offset: float | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """``(g, g_y, g_x)``: ``image`` blurred by the centred box of length ``blur`` px along
    the unit ``direction`` (dy, dx) and its matcher gradients (:func:`_blurred_subsets`;
    ``grads`` = ``(f_y, f_x)`` of the sharp image, ``spec`` its spectrum
    (:func:`image_spectrum`, needed when ``blur`` > 0))."""
    dy, dx = direction
    if offset is not None:
        g = image if blur == 0 else box_blurred(image, boundary, dy, dx, blur, spec)
        return _interpolated_at(
            g, boundary, offset * dy, offset * dx, 3 if derivative == "bspline3" else 5
        )
    if blur == 0:
        return image, grads[0], grads[1]
    g = box_blurred(image, boundary, dy, dx, blur, spec)
    if derivative in ("bspline3", "bspline5"):  # no spectral pass needed
        ggy, ggx = spline_gradients(g, derivative)
    else:
        ggy, ggx, _ = directional_derivatives(g, (dy, dx), derivative=derivative, boundary=boundary)
    return g, ggy, ggx


def subset_noise_variance(
    image: NDArray[np.float64],
    blur: NDArray[np.float64],
    centres: NDArray[np.intp],
    subset: int,
    *,
    motion: tuple[float, float] = (0.0, 1.0),
    shape: Shape = "translation",
    derivative: Derivative = "bspline3",
    boundary: Boundary = "reflect",
    chunk: int = 256,
) -> NDArray[np.float64]:
    """Per-subset variance of the ZNSSD IC-GN shift along ``motion`` per unit noise variance.

    Independent Gaussian noise of std ``sigma`` (GL) in both images moves the fixed point
    ``p = sigma_g A^-1 J_f^T (f_hat - g_hat)`` (module docstring, ``A = J_f^T P_g J_g``) by a
    linear response with covariance

        sigma**2 A^-1 [(sigma_g / sigma_f)**2 J_f^T P_f J_f
                       + (sigma_g**2 / sigma_f) (J_f^T P_f Q + Q^T P_f J_f)
                       + sigma_g**2 Q^T Q + J_f^T P_g J_f] A^-T,

    ``Q[:, k] = D_k^T (S_k r_0)``: the reference's noise moves the fixed point through its
    intensities and through its spline gradients ``D_k`` (weighted by the shape function's
    ``S_k``), which meet the residual ``r_0`` left at the fixed point (docs/models.md s. 4,
    the complete noise term; the middle term is negative, O(W**2)). At ``W = 0`` it is
    ``2 sigma**2 (J^T P J)^-1``, the match-score bound (eq. 2) with the ZNSSD projection;
    with blur, the weaker current gradients in ``A`` raise it.

    Returns
    -------
    ndarray, shape (m, n)
        ``var_i(W_j) / sigma**2`` (px**2 / GL**2), first order in the noise (the
        ``sigma**4`` interaction of the two noises, which ``predict_from_pattern`` adds, is
        left out); ``nan`` where the subset has no gradient.
    """
    var = shifts_and_variance(
        image,
        blur,
        centres,
        subset,
        motion=motion,
        shape=shape,
        derivative=derivative,
        boundary=boundary,
        criterion="znssd",
        max_shift=np.inf,
        chunk=chunk,
        variance=True,
    )[1]
    assert var is not None
    return np.asarray(var[0] + var[1])  # first order (the sigma**4 interaction left out)


def subset_blur_response(
    image: NDArray[np.float64],
    blur: ArrayLike,
    centres: NDArray[np.intp],
    subset: int,
    *,
    motion: tuple[float, float] = (0.0, 1.0),
    shape: Shape = "translation",
    derivative: Derivative = "bspline3",
    boundary: Boundary = "reflect",
    max_shift: float = 1.0,
    chunk: int = 256,
    complete: bool = True,
    threads: int = 1,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Blur-mismatch shift vector and noise covariance of each subset, along x and y.

    The same fixed point and linear noise response as :func:`subset_blur_shifts` and
    :func:`subset_noise_variance` (ZNSSD IC-GN, exactly blurred current image, module
    docstring), but both displacement components instead of the one along the motion:
    ``dicblur track`` needs ``sigma_u`` and ``sigma_v`` of a point whose blur runs in any
    direction.

    Parameters
    ----------
    image : ndarray, shape (rows, cols)
        Sharp reference image, grey levels.
    blur : array_like, shape (m,)
        Blur lengths ``W`` (px, >= 0) of a centred box along ``motion``.
    centres, subset, motion, shape, derivative, boundary
        As for :func:`subset_blur_coefficients`.
    max_shift : float
        Breakdown threshold (px) on the linearised shift vector (NaN beyond).
    complete : bool
        The complete noise term of :func:`subset_noise_variance` (docs/models.md s. 4:
        the reference's noisy spline gradients meeting the mismatch residual, and the
        ``sigma**4`` interaction of the two noises), as ``predict_from_pattern``;
        ``False``: the first-order response to the reference's intensities only (the
        earlier formula, for comparisons).
    threads : int
        Threads sharing the chunks of ``chunk`` subsets (numpy and BLAS release the GIL;
        each subset's numbers do not depend on it).

    Returns
    -------
    shift : ndarray, shape (m, n, 2)
        ``(u, v)`` mismatch shift of subset ``i`` at ``W_j`` (px; NaN: no gradient or
        breakdown).
    cov : ndarray, shape (m, n, 2, 2)
        Covariance of ``(u, v)`` per unit noise variance in each image (px**2 / GL**2):
        ``A^-1 [M^T M + J_f^T P_g J_f] A^-T`` restricted to the centre displacement,
        ``M = (sigma_g / sigma_f) P_f J_f + sigma_g Q`` (``Q = 0`` with
        ``complete=False``; NaN where the subset has no gradient).
    cov4 : ndarray, shape (m, n, 2, 2)
        The interaction of the two noises per unit ``sigma**4`` (px**2 / GL**4; zeros
        with ``complete=False``): the variance is ``sigma**2 cov + sigma**4 cov4``.
    """
    _check_shape(shape)
    _check_derivative(derivative)
    dy, dx = unit_direction(motion)
    w = np.asarray(blur, dtype=np.float64)
    n = len(centres)
    shift = np.full((len(w), n, 2), np.nan)
    cov = np.full((len(w), n, 2, 2), np.nan)
    cov4 = np.zeros((len(w), n, 2, 2))
    k = 2 if shape == "translation" else 6
    iu, iv = 0, (1 if shape == "translation" else 3)
    e = np.zeros((2, k))
    e[0, iu] = 1.0
    e[1, iv] = 1.0
    win = _Windows(subset)
    kernel = _derivative_kernel(derivative, subset) if complete else None
    gmat = np.zeros((k, k))
    if kernel is not None:
        # the sigma**4 interaction as shifts_and_variance (no sub-pixel offset: the
        # current noise is sampled as is): R(0) G on the same-axis columns
        wts = (
            np.ones((subset * subset, 1))
            if shape == "translation"
            else np.stack([np.ones(subset * subset), win.ex[0], win.ey[0]], axis=1)
        )
        r00 = float(np.dot(kernel, kernel))
        kx = wts.shape[1]
        gmat[:kx, :kx] = r00 * (wts.T @ wts)
        gmat[kx:, kx:] = r00 * (wts.T @ wts)

    def _response_chunk(
        j: int,
        rows: slice,
        jf: NDArray[np.float64],
        jg: NDArray[np.float64],
        fh: NDArray[np.float64],
        sf: NDArray[np.float64],
        pf: NDArray[np.float64],
        pf_gram: NDArray[np.float64],
        gg: NDArray[np.float64],
    ) -> None:
        """The shift and covariances of the subsets ``rows`` at ``W = w[j]``."""
        if w[j] == 0:  # g is f: its normalised subsets and projection are f's
            gh, sg, pg, pg_gram = fh, sf, pf, pf_gram
        else:
            gh, sg = _normalise(gg)
            pg = _project(jf, gh)
            pg_gram = _gram(pg, pg)
        # J_f^T P_g J_g = (P_g J_f)^T J_g (P_g a symmetric projection: one _project less)
        cross = _gram(pg, jg)
        sol = None
        sg_ok = np.where(sg > 0, sg, np.nan)
        if w[j] > 0:
            sol = _solve(cross / sg_ok[:, None, None], _tdot(jf, fh - gh))
            uv = np.stack([sol[:, iu], sol[:, iv]], axis=1)
            uv[~(np.hypot(uv[:, 0], uv[:, 1]) <= max_shift)] = np.nan
            shift[j, rows] = uv
        else:
            shift[j, rows] = np.where(np.isfinite(sf)[:, None] & (sf > 0)[:, None], 0.0, np.nan)
        ratio2 = (sg / np.where(sf > 0, sf, np.nan)) ** 2
        if kernel is not None and sol is not None:
            # residual at the linearised fixed point (orthogonal to J_f), met by the
            # reference's noisy gradients: the complete noise term (P_g J_g p = P_g (J_g p))
            jp = np.matmul(jg, sol[:, :, None])[:, :, 0]
            jp -= jp.mean(axis=1, keepdims=True)
            jp -= gh * np.einsum("np,np->n", gh, jp)[:, None]
            r0 = fh - gh - jp / sg_ok[:, None]
            mid_ref = _reference_noise_middle(
                pf, np.sqrt(ratio2), sg, r0, subset, shape, win.ex, win.ey, kernel, pf_gram
            )
        else:
            mid_ref = ratio2[:, None, None] * pf_gram
        mid = mid_ref + pg_gram
        at = np.transpose(cross, (0, 2, 1))
        z = np.stack(
            _solve_each(at, [np.broadcast_to(e[c], (len(gg), k)).copy() for c in range(2)]),
            axis=1,
        )  # (m, 2, k): A^T z_c = e_c (one condition number per subset for both)
        cov[j, rows] = np.einsum("nci,nij,ndj->ncd", z, mid, z)
        if kernel is not None:
            cov4[j, rows] = np.einsum("nci,ij,ndj->ncd", z, gmat, z)

    if derivative in ("bspline3", "bspline5"):  # the spline's gradients (f_dd not needed)
        _extend(image[:1, :1], boundary)  # raises the boundary error
        grads = spline_gradients(image, derivative)
    else:
        fy_, fx_, _ = directional_derivatives(
            image, (dy, dx), derivative=derivative, boundary=boundary
        )
        grads = (fy_, fx_)
    spec = image_spectrum(image, boundary) if np.any(w != 0) else None
    sharp = _Windows(subset, grads[1], grads[0], image)
    # W nodes in groups whose blurred images (3 per node) fit in about 64 MB: each chunk
    # of subsets then runs through a group's nodes with its sharp-image terms (J_f, the
    # normalised f, P_f J_f and its Gram matrix: none depends on W) computed once
    per_group = max(1, (64 << 20) // (3 * image.nbytes))

    def prepare(j: int, out: dict[int, _Windows]) -> None:
        g, ggy, ggx = _blurred_images(
            image, float(w[j]), (dy, dx), grads, derivative, boundary, spec
        )
        out[j] = _Windows(subset, ggx, ggy, g)

    def one(start: int, wins: dict[int, _Windows]) -> None:
        cc = centres[start : start + chunk]
        rows = slice(start, start + len(cc))
        ax, ay, f = sharp.take(cc)
        jf = sharp.jacobian(ax, ay, shape)
        fh, sf = _normalise(f)
        pf = _project(jf, fh)
        pf_gram = _gram(pf, pf)
        for j, win_j in wins.items():
            bx, by, gg = win_j.take(cc)
            _response_chunk(j, rows, jf, win_j.jacobian(bx, by, shape), fh, sf, pf, pf_gram, gg)

    for g0 in range(0, len(w), per_group):
        wins: dict[int, _Windows] = {}
        group = range(g0, min(g0 + per_group, len(w)))
        each(functools.partial(prepare, out=wins), group, threads)
        wins = {j: wins[j] for j in group}  # in the order of the nodes
        each(functools.partial(one, wins=wins), range(0, n, chunk), threads)
    return shift, cov, cov4


def subset_skew_coefficients(
    image: NDArray[np.float64],
    centres: NDArray[np.intp],
    subset: int,
    *,
    motion: tuple[float, float] = (0.0, 1.0),
    shape: Shape = "translation",
    derivative: Derivative = "bspline3",
    boundary: Boundary = "reflect",
    chunk: int = 256,
    threads: int = 1,
) -> NDArray[np.float64]:
    """Per-subset shift per unit third moment of the blur kernel, ``(u, v)`` px / px**3.

    A blur kernel of positions ``s`` along ``d`` (an accelerating target: the time spent
    per px is not uniform) with third central moment ``kappa_3`` adds
    ``-(kappa_3 / 6) f_ddd`` to the image about its mean position; the ZNSSD IC-GN fixed
    point then moves by ``+(kappa_3 / 6) (J^T P J)^-1 J^T P f_ddd`` (the same
    linearisation as the ``W**2 / 24`` term of :func:`subset_blur_coefficients`, which is
    ``kappa_2 / 2`` of a box). By parts ``sum f_d f_ddd = -sum f_dd**2``: the shift has
    the same sign in every subset, a common offset of the field. Returns the factor of
    ``kappa_3``, shape (n, 2) (NaN: no gradient). ``threads``: threads sharing the
    chunks of ``chunk`` subsets (the same numbers).
    """
    _check_shape(shape)
    _check_derivative(derivative)
    dy, dx = unit_direction(motion)
    rows, cols = image.shape
    ext = _extend(image, boundary)
    shp = ext.shape
    k = (2j * np.pi) * (
        dy * np.fft.fftfreq(shp[0])[:, None] + dx * np.fft.rfftfreq(shp[1])[None, :]
    )
    spec = np.fft.rfft2(ext)
    del ext
    spec *= k**3  # in place: the same products, one extended array fewer
    del k
    fddd = _crop(np.fft.irfft2(spec, s=shp), rows, cols)
    del spec
    if derivative in ("bspline3", "bspline5"):
        fy, fx = spline_gradients(image, derivative)
    else:
        fy, fx, _ = directional_derivatives(image, motion, derivative=derivative, boundary=boundary)
    win = _Windows(subset, fx, fy, fddd, image)
    out = np.full((len(centres), 2), np.nan)
    iv = 1 if shape == "translation" else 3

    def one(start: int) -> None:
        cc = centres[start : start + chunk]
        gx, gy, e3, f = win.take(cc)
        jp = _project(win.jacobian(gx, gy, shape), _normalise(f)[0])
        sol = _solve(_gram(jp, jp), _tdot(jp, e3)) / 6.0
        out[start : start + len(cc), 0] = sol[:, 0]
        out[start : start + len(cc), 1] = sol[:, iv]

    each(one, range(0, len(centres), chunk), threads)
    return out
