"""Blur-compensated correlation (issue 18): the forward model of a motion-blurred image.

A camera image taken while the target moves from ``d0`` to ``d0 + X`` (``X = (dy, dx)`` px,
blur length ``W = |X|``) is the average of the sharp image over the positions along the
path (Lavatelli & Zappa, IEEE TIM 66(3), 2017, Algorithm 1): the sharp image moved by the
*mean* position ``d0 + X / 2`` and convolved with a centred 1-D box of length ``W`` along
``X``. Correlating it against the sharp reference leaves a deterministic blur-mismatch
error. The compensated matcher instead compares it with the reference convolved with the
same centred box (:func:`blur_reference`): the two then differ only by the translation
``d0 + X / 2`` and the noise, so IC-GN returns the mean position during the exposure
without the mismatch term.

The centred box is applied exactly on the band-limited interpolant of the image by its
transfer function ``H(f) = sinc(f . X)`` (the continuous limit of Algorithm 1 without its
phase factor ``exp(-i pi f . X)``, which is the shift by ``X / 2``); its derivative with
respect to the blur length along a fixed direction ``e`` is
``dH/dW = (f . e) sinc'(W f . e)``, used by the blur estimation. The image is extended by
even mirroring to twice its size first (periodic and continuous: no wrap-around seam), so
within about ``W / 2`` px of the border the blurred reference averages mirrored content.

:func:`deblur_wiener` is the published alternative (deblur the current image, correlate
it against the sharp reference; Lavatelli, Zappa et al., Acta IMEKO), kept as the
baseline the benchmark compares against.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import ArrayLike, NDArray
from scipy import fft as sfft

from ..arrays import BoolArray, Float64Array, Int64Array
from ..checks import as_float_array, as_image, check_positive, describe
from ..errors import InputError
from .icgn import (
    N_PARAMS,
    centre_subsets,
    gauss_newton_matrix,
    raw_jacobian,
    regular,
    scaled_inverse,
)

__all__ = [
    "BLUR_MODES",
    "BlurStepPrep",
    "blur_reference",
    "check_blur_vector",
    "deblur_wiener",
    "noise_gain_slope",
    "prepare_blur_step",
]

#: Matcher modes: ``none`` (plain IC-GN), ``given`` (blur vector known), ``estimate``
#: (blur length along a given direction estimated per subset).
BLUR_MODES: tuple[str, ...] = ("none", "given", "estimate")


def check_blur_vector(
    value: Any, *, n_points: int, subset: int, name: str = "blur_vector"
) -> Float64Array:
    """Validate a blur vector ``(dy, dx)`` px, or one per POI (shape (n_points, 2)).

    Returns an array of shape (2,) or (n_points, 2). Raises :class:`InputError` on NaN or
    infinite components, a wrong shape, or a blur length ``hypot(dy, dx)`` of a subset or
    more (the blurred subset would average content from outside the subset's
    neighbourhood the matcher can trust: use a larger subset).
    """
    arr = as_float_array(
        value, name, expected="expected (dy, dx) in px, e.g. (0.0, 3.5), or an (n_points, 2) array"
    )
    if arr.shape != (2,) and arr.shape != (n_points, 2):
        raise InputError(
            f"{name}={describe(arr)}: expected (dy, dx) in px (shape (2,)) or "
            f"one vector per POI (shape ({n_points}, 2))"
        )
    if not np.all(np.isfinite(arr)):
        raise InputError(
            f"{name}={describe(value)}: must be finite (no NaN or infinity); "
            "give the motion during the exposure in px"
        )
    length = np.hypot(arr[..., 0], arr[..., 1])
    if np.any(length >= subset):
        worst = float(np.max(length))
        raise InputError(
            f"{name}: blur length {worst:.4g} px is not shorter than the "
            f"subset ({subset} px); use a subset larger than the blur"
        )
    return arr


def _dsinc(x: Float64Array) -> Float64Array:
    """d sinc(x) / dx with ``sinc(x) = sin(pi x) / (pi x)``; ``-pi^2 x / 3`` near 0."""
    small = np.abs(x) < 1e-4
    safe = np.where(small, 1.0, x)
    return np.where(small, -(math.pi**2) * x / 3.0, (np.cos(math.pi * safe) - np.sinc(safe)) / safe)


def _symmetric_grid(h: Callable[[NDArray, NDArray], NDArray], n: int, m: int) -> Float64Array:
    """Real, even transfer function ``h(fy, fx)`` on the rfft2 grid of an (n, m) image
    with even n and m: the Nyquist row and column average ``+1/2`` and ``-1/2`` cycles/px
    (the symmetric convention of :mod:`dicblur.blur`), so the output stays real."""
    fy = np.fft.fftfreq(n)[:, None]
    fx = np.fft.rfftfreq(m)[None, :]
    out = np.asarray(h(fy, fx), dtype=np.float64)
    half = np.array([[0.5]])
    out[n // 2, :] = 0.5 * (h(-half, fx) + h(half, fx))[0]
    col = 0.5 * (h(fy, half) + h(fy, -half))[:, 0]
    out[:, -1] = col
    return out


def _mirror(img: Float64Array) -> Float64Array:
    top = np.concatenate([img, img[:, ::-1]], axis=1)
    return np.concatenate([top, top[::-1, :]], axis=0)


def blur_reference(
    image: ArrayLike, blur_vector: ArrayLike, *, derivative: bool = False
) -> tuple[Float64Array, Float64Array | None]:
    """The image convolved with a centred box of the blur vector (the forward model).

    Parameters
    ----------
    image : array_like, shape (rows, cols)
        Sharp image, grey levels.
    blur_vector : array_like (dy, dx)
        Motion during the exposure, px.
    derivative : bool
        Also return the derivative of the blurred image with respect to the blur length
        ``W`` along the fixed direction of ``blur_vector`` (GL / px; needs ``W > 0``).

    Returns
    -------
    blurred : ndarray, shape (rows, cols)
        ``(1 / W) int_{-W/2}^{W/2} f(x + s e) ds`` on the band-limited interpolant (even
        mirror boundary), grey levels; the image itself (a copy) when ``W = 0``.
    d_blurred : ndarray, shape (rows, cols), or None
        ``d blurred / dW`` when ``derivative``.

    Examples
    --------
    >>> import numpy as np
    >>> img = np.random.default_rng(0).random((32, 32))
    >>> out, _ = blur_reference(img, (0.0, 0.0))
    >>> bool(np.array_equal(out, img))
    True
    """
    img = as_image(image, "image")
    vec = np.asarray(blur_vector, dtype=np.float64)
    if vec.shape != (2,) or not np.all(np.isfinite(vec)):
        raise InputError(f"blur_vector={describe(blur_vector)}: expected finite (dy, dx) px")
    dy, dx = float(vec[0]), float(vec[1])
    length = math.hypot(dy, dx)
    if length == 0.0:
        if derivative:
            raise InputError(
                "blur_vector=(0, 0): the derivative with respect to the blur "
                "length needs a direction (a non-zero vector)"
            )
        return img.copy(), None
    work = _mirror(img)
    n, m = work.shape
    spec = sfft.rfft2(work)
    rows, cols = img.shape

    def h(fy: NDArray, fx: NDArray) -> NDArray:
        return np.sinc(fy * dy + fx * dx)

    blurred = sfft.irfft2(spec * _symmetric_grid(h, n, m), s=work.shape)[:rows, :cols]
    d_out = None
    if derivative:
        ey, ex = dy / length, dx / length

        def dh(fy: NDArray, fx: NDArray) -> NDArray:
            s = fy * ey + fx * ex
            return s * _dsinc(length * s)

        d_out = np.ascontiguousarray(
            sfft.irfft2(spec * _symmetric_grid(dh, n, m), s=work.shape)[:rows, :cols]
        )
    return np.ascontiguousarray(blurred), d_out


def deblur_wiener(image: ArrayLike, blur_vector: ArrayLike, noise_sigma: float) -> Float64Array:
    """Deblur a motion-blurred image with the Wiener filter of the known kernel.

    The baseline of issue 18 (Lavatelli, Zappa et al., Acta IMEKO, "Optimization of the
    estimation and compensation algorithm for dynamic DIC measurements"): restore the
    current image, then correlate it with the sharp reference. Filter
    ``conj(H) / (|H|^2 + NSR)`` with the centred box ``H = sinc(f . X)`` and a scalar
    noise-to-signal power ratio ``NSR = sigma^2 / (var(image) - sigma^2)`` (as MATLAB's
    ``deconvwnr(I, PSF, NSR)``); even mirror boundary. The restored image is centred on
    the mean position during the exposure, as the compensated matcher's displacement.

    Parameters
    ----------
    image : array_like, shape (rows, cols)
        Blurred image, grey levels.
    blur_vector : array_like (dy, dx)
        Motion during the exposure, px.
    noise_sigma : float
        Noise std of the image, grey levels (>= 0; 0 gives the inverse filter where
        ``H != 0``).

    Returns
    -------
    ndarray, shape (rows, cols)
    """
    img = as_image(image, "image")
    sigma = check_positive(noise_sigma, "noise_sigma", allow_zero=True)
    vec = np.asarray(blur_vector, dtype=np.float64)
    if vec.shape != (2,) or not np.all(np.isfinite(vec)):
        raise InputError(f"blur_vector={describe(blur_vector)}: expected finite (dy, dx) px")
    dy, dx = float(vec[0]), float(vec[1])
    if dy == 0.0 and dx == 0.0:
        return img.copy()
    work = _mirror(img)
    n, m = work.shape

    def h(fy: NDArray, fx: NDArray) -> NDArray:
        return np.sinc(fy * dy + fx * dx)

    hh = _symmetric_grid(h, n, m)
    signal = max(float(np.var(img)) - sigma**2, 1e-12)
    nsr = sigma**2 / signal
    with np.errstate(divide="ignore", invalid="ignore"):
        filt = hh / (hh * hh + nsr) if nsr > 0 else np.where(hh != 0, 1.0 / hh, 0.0)
    out = sfft.irfft2(sfft.rfft2(work) * filt, s=work.shape)[: img.shape[0], : img.shape[1]]
    return np.ascontiguousarray(out)


def noise_gain_slope(length: float, direction: ArrayLike, *, grid: int = 256) -> float:
    """``d kappa / dW`` of the noise variance gain ``kappa(W) = mean_f sinc^2(W f . e)``.

    The centred box of length ``W`` scales the variance of white noise in the reference by
    ``kappa(W)`` (about ``1 / W`` for ``W >= 1``; mean over the frequency square
    ``[-1/2, 1/2)^2``, midpoint rule on ``grid^2`` points), px^-1. Blurring the *noisy*
    reference further lowers its noise, so the joint estimate of the blur length leans
    long by ``-n sigma^2 kappa'(W) / (2 |D_perp|^2)`` (n subset pixels); the estimation
    removes that lean when the noise level is known.
    """
    e = np.asarray(direction, dtype=np.float64)
    return _noise_gain_slope(float(length), float(e[0]), float(e[1]), int(grid))


@functools.lru_cache(maxsize=64)
def _noise_gain_slope(length: float, ey: float, ex: float, grid: int) -> float:
    f = (np.arange(grid) + 0.5) / grid - 0.5
    s = f[:, None] * ey + f[None, :] * ex
    x = length * s
    return float(np.mean(2.0 * np.sinc(x) * s * _dsinc(x)))


@dataclass(frozen=True)
class BlurStepPrep:
    """Per-subset reference quantities of the joint (shape, blur length) Gauss-Newton step.

    Reference model ``F = f0 + lam D`` (``f0`` the reference blurred to the length ``W0``,
    ``D = d f0 / dW``); ``hinv`` (n, k+1, k+1) the inverse of the constant Gauss-Newton
    matrix of the normalised model in ``(p, lam)``; ``fmean``, ``fnorm`` (n,); ``jsum``,
    ``avec``, ``evec`` (n, k) ``sum J``, ``J_c^T fh``, ``J_c^T D_c``; ``dsum``, ``bval``,
    ``dd`` (n,) ``sum D``, ``D_c^T fh``, ``D_c^T D_c``; ``ok`` (n,) bool: the matrix is
    regular (the subset's texture tells the blur from the shape).
    """

    hinv: Float64Array
    fmean: Float64Array
    fnorm: Float64Array
    jsum: Float64Array
    avec: Float64Array
    evec: Float64Array
    dsum: Float64Array
    bval: Float64Array
    dd: Float64Array
    ok: BoolArray


def prepare_blur_step(
    f0: Float64Array,
    gx: Float64Array,
    gy: Float64Array,
    dimg: Float64Array,
    rows: Int64Array,
    cols: Int64Array,
    half: int,
    shape: str,
    *,
    chunk: int = 256,
) -> BlurStepPrep:
    """Per-subset quantities of the joint step (see :class:`BlurStepPrep`).

    ``f0``, ``gx``, ``gy``, ``dimg`` (rows, cols): blurred reference, its x / y spline
    derivatives and its derivative with respect to the blur length; ``rows``, ``cols``
    (n,) POI centres with the subset inside the image.
    """
    n = len(rows)
    k = N_PARAMS[shape]
    size = 2 * half + 1
    npx = size * size
    out = {
        name: np.zeros((n, *s))
        for name, s in (
            ("hinv", (k + 1, k + 1)),
            ("fmean", ()),
            ("fnorm", ()),
            ("jsum", (k,)),
            ("avec", (k,)),
            ("evec", (k,)),
            ("dsum", ()),
            ("bval", ()),
            ("dd", ()),
        )
    }
    ok = np.zeros(n, bool)
    views = [sliding_window_view(a, (size, size)) for a in (f0, gx, gy, dimg)]
    for s in range(0, n, chunk):
        r = rows[s : s + chunk] - half
        c = cols[s : s + chunk] - half
        fp, gxp, gyp, dp = (
            np.asarray(v[r, c], dtype=np.float64).reshape(len(r), npx) for v in views
        )
        fmean, fnorm, safe, fh, jsum, jc = centre_subsets(fp, raw_jacobian(gxp, gyp, half, shape))
        dsum = dp.sum(axis=1)
        dc = dp - dsum[:, None] / npx
        aug = np.concatenate([jc, dc[:, :, None]], axis=2)  # (m, npx, k+1)
        # Df^2 H = [J_c D_c]^T [J_c D_c] - (a, b)(a, b)^T (normalised-model Gauss-Newton)
        avec_full, gram, big = gauss_newton_matrix(aug, fh)
        good = (fnorm > 0) & regular(big)
        hinv, _ = scaled_inverse(big, ~good, safe)
        sl = slice(s, s + len(r))
        out["hinv"][sl] = hinv
        out["fmean"][sl] = fmean
        out["fnorm"][sl] = fnorm
        out["jsum"][sl] = jsum
        out["avec"][sl] = avec_full[:, :k]
        out["bval"][sl] = avec_full[:, k]
        out["evec"][sl] = gram[:, :k, k]
        out["dsum"][sl] = dsum
        out["dd"][sl] = gram[:, k, k]
        ok[sl] = good
    return BlurStepPrep(ok=ok, **{k_: np.ascontiguousarray(v) for k_, v in out.items()})
