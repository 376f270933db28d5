"""Image derivatives for the blur-sensitivity formulas of :mod:`dicblur.models.sensitivity`:
spectral, B-spline and central derivatives along a motion direction, the box-blurred
images, the image spectrum, and the derivative kernels and interpolated-gradient noise
covariance of the matcher's interpolant.
"""

from __future__ import annotations

import math
from typing import Any, Literal

import numpy as np

from ..arrays import Float64Array
from ..dic.interpolation import (
    bspline_at_offset,
    bspline_coefficients,
    bspline_gradients,
    bspline_kernel,
    bspline_kernel_derivative,
)
from ..errors import InputError

Derivative = Literal["bspline3", "bspline5", "spectral", "central"]
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


def extend(image: Float64Array, boundary: Boundary) -> Float64Array:
    """The periodic image the spectral operators act on (mirror: even 2x extension)."""
    if boundary == "reflect":
        rows, cols = image.shape
        return np.pad(image, ((0, rows), (0, cols)), mode="symmetric")
    if boundary == "periodic":
        return image
    raise InputError(f"boundary={boundary!r}: choose 'reflect' or 'periodic'")


def spectral_derivatives(
    image: Float64Array,
    boundary: Boundary,
    dy: float,
    dx: float,
    blur: float | None = None,
    spectrum: tuple[Any, tuple[int, int]] | None = None,
) -> tuple[Float64Array, Float64Array, Float64Array]:
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
        out = crop(np.fft.irfft2(spec * np.sinc(blur * (dy * fy_ + dx * fx_)), s=shp), rows, cols)
        return out, out, out
    ky, kx = 2j * np.pi * fy_, 2j * np.pi * fx_
    ky_odd, kx_odd = ky.copy(), kx.copy()
    if shp[0] % 2 == 0:  # the Nyquist bin of an odd derivative is not real
        ky_odd[shp[0] // 2] = 0
    if shp[1] % 2 == 0:
        kx_odd[:, -1] = 0
    fy = crop(np.fft.irfft2(spec * ky_odd, s=shp), rows, cols)
    fx = crop(np.fft.irfft2(spec * kx_odd, s=shp), rows, cols)
    return fy, fx, _second(spec, shp, dy, dx, rows, cols)


def _spectrum(image: Float64Array, boundary: Boundary) -> tuple[Any, tuple[int, int]]:
    """``rfft2`` of the extended image and the extended shape."""
    ext = extend(image, boundary)
    return np.fft.rfft2(ext), (int(ext.shape[0]), int(ext.shape[1]))


def crop(full: Float64Array, rows: int, cols: int) -> Float64Array:
    """The image's part of an extended result, as its own array: a view would keep the
    extended buffer (4x the image) alive (a long track's memory, issue 17)."""
    return np.ascontiguousarray(full[:rows, :cols])


def _second(
    spec: Any, shp: tuple[int, int], dy: float, dx: float, rows: int, cols: int
) -> Float64Array:
    """Second derivative along ``(dy, dx)`` from the spectrum of the extended image."""
    ky = 2j * np.pi * np.fft.fftfreq(shp[0])[:, None]
    kx = 2j * np.pi * np.fft.rfftfreq(shp[1])[None, :]
    fdd = np.fft.irfft2(
        spec * (dx * dx * kx * kx + 2 * dx * dy * ky * kx + dy * dy * ky * ky), s=shp
    )
    return crop(fdd, rows, cols)


def box_blurred(
    image: Float64Array,
    boundary: Boundary,
    dy: float,
    dx: float,
    blur: float,
    spectrum: tuple[Any, tuple[int, int]] | None = None,
) -> Float64Array:
    """``image`` blurred by the centred box of length ``blur`` px along the unit ``(dy, dx)``
    (exact spectral blur, :func:`spectral_derivatives`, whose ``spectrum`` it passes on),
    shape (rows, cols)."""
    return spectral_derivatives(image, boundary, dy, dx, blur=blur, spectrum=spectrum)[0]


def image_spectrum(image: Float64Array, boundary: Boundary) -> tuple[Any, tuple[int, int]]:
    """The spectrum :func:`box_blurred` takes to blur ``image`` by several lengths with one
    forward FFT: ``rfft2`` of the image extended as ``boundary`` asks, and its shape."""
    return _spectrum(image, boundary)


def spline_gradients(image: Float64Array, derivative: str) -> tuple[Float64Array, Float64Array]:
    """``(f_y, f_x)`` of the matcher's B-spline interpolant at the pixels (as IC-GN uses),
    ``derivative`` "bspline3" or "bspline5"; shape (rows, cols) each, GL / px."""
    order = 3 if derivative == "bspline3" else 5
    coef = bspline_coefficients(image, order=order, dtype=np.float64)
    return bspline_gradients(coef, order, image.shape)


def _interpolated_at(
    image: Float64Array, boundary: Boundary, oy: float, ox: float, order: int
) -> tuple[Float64Array, Float64Array, Float64Array]:
    """The current image of a target moved by the sub-pixel offset ``(oy, ox)`` (px), as
    the matcher sees it back on the reference grid: ``(h~, h~_y, h~_x)`` at ``x + o``, with
    ``h = image(x - o)`` (exact spectral shift) sampled at the pixels and ``h~`` its B-spline
    interpolant of degree ``order``. ``h~(x + o) = image(x)`` but for the interpolation
    error, which is the matcher's sub-pixel bias (docs/models.md s. 4)."""
    rows, cols = image.shape
    ext = extend(image, boundary)
    shp = ext.shape
    phase = np.exp(
        -2j * np.pi * (np.fft.fftfreq(shp[0])[:, None] * oy + np.fft.rfftfreq(shp[1])[None, :] * ox)
    )
    h = np.fft.irfft2(np.fft.rfft2(ext) * phase, s=shp)[:rows, :cols]
    coef = bspline_coefficients(h, order=order, dtype=np.float64)
    out, gy, gx = bspline_at_offset(coef, order, h.shape, oy, ox)
    assert out is not None
    return out, gy, gx


def interpolated_noise_covariance(t: float, order: int, size: int) -> Float64Array:
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


def derivative_kernel(derivative: str, subset: int, tol: float = 1e-9) -> Float64Array:
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


def check_derivative(derivative: str) -> None:
    if derivative not in ("bspline3", "bspline5", "spectral", "central"):
        raise InputError(
            f"derivative={derivative!r}: unknown derivative; choose 'bspline3' (the DIC "
            "engine's cubic spline, default), 'bspline5', 'spectral' or 'central'"
        )


def directional_derivatives(
    image: Float64Array,
    motion: tuple[float, float] = (0.0, 1.0),
    *,
    derivative: Derivative = "bspline3",
    boundary: Boundary = "reflect",
) -> tuple[Float64Array, Float64Array, Float64Array]:
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
    check_derivative(derivative)
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
        extend(image, boundary)  # raises the boundary error
    p = np.pad(image, 1, mode="symmetric" if boundary == "reflect" else "wrap")
    c = p[1:-1, 1:-1]
    fx = 0.5 * (p[1:-1, 2:] - p[1:-1, :-2])
    fy = 0.5 * (p[2:, 1:-1] - p[:-2, 1:-1])
    fxx = p[1:-1, 2:] - 2 * c + p[1:-1, :-2]
    fyy = p[2:, 1:-1] - 2 * c + p[:-2, 1:-1]
    fxy = 0.25 * (p[2:, 2:] - p[2:, :-2] - p[:-2, 2:] + p[:-2, :-2])
    return fy, fx, dx * dx * fxx + 2 * dx * dy * fxy + dy * dy * fyy


def matcher_gradients(
    image: Float64Array,
    motion: tuple[float, float],
    derivative: Derivative,
    boundary: Boundary,
) -> tuple[Float64Array, Float64Array]:
    """``(f_y, f_x)``: the gradients the matcher uses, its B-spline's (no spectral pass:
    ``f_dd`` is not needed) or those of :func:`directional_derivatives` (``motion`` as
    there). Raises the boundary error for an unknown ``boundary`` either way."""
    if derivative in ("bspline3", "bspline5"):
        extend(image[:1, :1], boundary)  # raises the boundary error
        return spline_gradients(image, derivative)
    fy, fx, _ = directional_derivatives(image, motion, derivative=derivative, boundary=boundary)
    return fy, fx


def blurred_images(
    image: Float64Array,
    blur: float,
    direction: tuple[float, float],
    grads: tuple[Float64Array, Float64Array],
    derivative: Derivative,
    boundary: Boundary,
    spec: tuple[Any, tuple[int, int]] | None,
    offset: float | None = None,
) -> tuple[Float64Array, Float64Array, Float64Array]:
    """``(g, g_y, g_x)``: ``image`` blurred by the centred box of length ``blur`` px along
    the unit ``direction`` (dy, dx) and its matcher gradients (:func:`blurred_subsets`;
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
    ggy, ggx = matcher_gradients(g, (dy, dx), derivative, boundary)
    return g, ggy, ggx
