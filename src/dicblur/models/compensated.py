"""Static prediction of u_e(W) for the blur-compensated matcher (issue 18).

With ``Correlator(blur="given")`` the current image is compared with the reference
blurred by the same centred box (:func:`dicblur.dic.blur_reference`), so the deterministic
blur-mismatch term of docs/models.md s. 4 vanishes and only noise is left. To first order
the IC-GN estimate is linear in the noise of both images (docs/dic.md, "Predicted random
error"), now with the gradients of the *blurred* reference ``f_W``:

- the current image's noise (std ``sigma``) gives ``sigma^2 A^-1`` with
  ``A = J_c^T J_c - a a^T`` the ZNSSD Fisher matrix of ``f_W``'s subset (translation:
  ``1 / SSSIG(W)`` along the motion, paper eq. 2 with the blurred image's SSSIG);
- the reference's noise is blurred with the reference, ``n -> B n`` (``B`` the box), so
  it enters through ``B J``, the gradients of ``f_W`` blurred once more:
  ``sigma^2 A^-1 (B J)_perp^T (B J)_perp A^-1`` (translation:
  ``SSSIG_2(W) / SSSIG(W)^2`` with ``SSSIG_2`` that of ``B f_W``).

At W = 0 both terms are the match-score bound's halves, ``u_e = sqrt(2 sigma^2 / SSSIG)``;
with blur the second shrinks (the blurred reference is less noisy), so the compensated
matcher lands *below* the blurred image's static bound ``sqrt(2 sigma^2 / SSSIG(W))``.
Gradients are the exact derivatives of the engine's cubic B-spline by default (as
:func:`~dicblur.models.predict_from_pattern`), or central differences.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import ArrayLike

from ..arrays import Float64Array, IndexArray
from ..checks import as_blur, as_image, check_choice, check_odd_subset, check_positive, describe
from ..dic.compensation import blur_reference
from ..dic.icgn import raw_jacobian
from ..errors import InputError
from ..metrics import directional_sssig, image_gradients, subset_centres
from .derivatives import spline_gradients, unit_direction
from .pattern import NOISE_FACTORS, PatternPrediction, fit_prediction, model_blur

if TYPE_CHECKING:
    from .model import BlurUncertaintyModel

__all__ = ["compensated_covariance", "model_from_compensated", "predict_compensated"]


def _points(
    img: Float64Array, subset: int, step: int | None, points: ArrayLike | None
) -> IndexArray:
    half = subset // 2
    if points is None:
        if subset + 2 > min(img.shape):
            raise InputError(f"subset={subset}: larger than the image {img.shape} allows")
        return np.asarray(
            subset_centres(img.shape, subset=subset, step=step or subset), dtype=np.intp
        )
    pts = np.asarray(points)
    if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 2:
        raise InputError(
            f"points={describe(pts)}: expected an (n, 2) array of (row, col) subset centres, n >= 2"
        )
    pts = pts.astype(np.intp)
    inside = (
        (pts[:, 0] >= half)
        & (pts[:, 0] < img.shape[0] - half)
        & (pts[:, 1] >= half)
        & (pts[:, 1] < img.shape[1] - half)
    )
    if not inside.all():
        raise InputError(
            f"points: {int((~inside).sum())} subset(s) leave the image; keep "
            f"centres >= {half} px from the border"
        )
    return pts


def _gradients(img: Float64Array, derivative: str) -> tuple[Float64Array, Float64Array]:
    """(d/drow, d/dcol): exact B-spline derivatives (as the matcher) or central
    differences (as dicblur.sssig)."""
    if derivative == "central":
        gy, gx = image_gradients(img)
        return gy, gx
    return spline_gradients(img, derivative)


def _windows(
    fw: Float64Array,
    fww: Float64Array,
    pts: IndexArray,
    half: int,
    derivative: str,
) -> tuple[Float64Array, ...]:
    """Flat subsets (n, size**2) of ``f_W`` and of the gradients of ``f_W`` and ``B f_W``:
    ``f, gx, gy, hx, hy``."""
    size = 2 * half + 1
    gy, gx = _gradients(fw, derivative)
    hy, hx = _gradients(fww, derivative)
    r, c = pts[:, 0] - half, pts[:, 1] - half
    return tuple(
        np.asarray(sliding_window_view(a, (size, size))[r, c]).reshape(len(r), size * size)
        for a in (fw, gx, gy, hx, hy)
    )


def _fisher(
    windows: tuple[Float64Array, ...], half: int, shape: str
) -> tuple[Float64Array, Float64Array, Float64Array]:
    """ZNSSD Fisher matrices ``A`` (current image, ``f_W``) and ``C`` (reference, ``B
    f_W``) of each subset, (n, k, k), and the norm of the centred subset ``f_W``, (n,)."""
    f, gxp, gyp, hxp, hyp = windows
    fc = f - f.mean(axis=1, keepdims=True)
    fn = np.sqrt(np.einsum("ij,ij->i", fc, fc))
    fh = fc / np.where(fn > 0, fn, 1.0)[:, None]

    def perp(jac: Float64Array) -> Float64Array:
        jc = jac - jac.mean(axis=1, keepdims=True)
        a = np.einsum("npk,np->nk", jc, fh)
        return np.asarray(jc - fh[:, :, None] * a[:, None, :])

    j1 = perp(raw_jacobian(gxp, gyp, half, shape))
    j2 = perp(raw_jacobian(hxp, hyp, half, shape))
    amat = np.matmul(j1.transpose(0, 2, 1), j1)
    cmat = np.matmul(j2.transpose(0, 2, 1), j2)
    return amat, cmat, fn


def _noise_variance(
    fw: Float64Array,
    fww: Float64Array,
    pts: IndexArray,
    half: int,
    shape: str,
    e: tuple[float, float],
    derivative: str,
) -> Float64Array:
    """Per-subset variance along ``e`` (dy, dx) per unit noise variance, px^2 / GL^2."""
    windows = _windows(fw, fww, pts, half, derivative)
    if shape == "translation":
        # eq. 2 form (diagonal), as the plain matcher's prediction
        _, gxp, gyp, hxp, hyp = windows
        ge = e[1] * gxp + e[0] * gyp
        he = e[1] * hxp + e[0] * hyp
        s1 = np.einsum("ij,ij->i", ge, ge)
        s2 = np.einsum("ij,ij->i", he, he)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.asarray(1.0 / s1 + s2 / s1**2)
    amat, cmat, _ = _fisher(windows, half, "affine")
    ainv = np.linalg.inv(amat)
    cov = ainv + ainv @ cmat @ ainv
    w = np.zeros(6)
    w[0], w[3] = e[1], e[0]  # (u, v) along the motion
    return np.asarray(np.einsum("i,nij,j->n", w, cov, w))


def predict_compensated(
    image: ArrayLike,
    blur: ArrayLike,
    *,
    noise_sigma: float,
    subset: int,
    step: int | None = None,
    points: ArrayLike | None = None,
    motion: tuple[float, float] = (0.0, 1.0),
    shape: str = "translation",
    derivative: str = "bspline3",
) -> PatternPrediction:
    """Predict u_e(W) of the blur-compensated matcher from the static image.

    Parameters
    ----------
    image : array_like, shape (rows, cols)
        Sharp reference image, grey levels.
    blur : array_like, shape (m,)
        Blur lengths W (px, >= 0) of linear motion along ``motion``.
    noise_sigma : float
        Gaussian noise std (GL) in each image.
    subset : int
        Odd subset size, px.
    step, points
        Subset grid step (px, default ``subset``) or explicit (n, 2) (row, col) centres.
    motion : (dy, dx)
        Motion direction (only the direction matters).
    shape : {"translation", "affine"}
        Shape function of the matcher.
    derivative : {"bspline3", "bspline5", "central"}
        Image gradients: the exact derivatives of the engine's B-spline (default, as
        :func:`~dicblur.models.predict_from_pattern`) or central differences (as
        :func:`dicblur.sssig` and the campaigns' ``u_match_score``).

    Returns
    -------
    PatternPrediction
        ``u_e = u_noise`` (``u_blur = 0``: no mismatch with compensation); ``sssig`` the
        blurred image's mean SSSIG along the motion, so ``sqrt(2 sigma^2 / sssig)`` is its
        static bound.

    Examples
    --------
    >>> import dicblur
    >>> from dicblur.models.compensated import predict_compensated
    >>> img = dicblur.speckle_pattern((96, 96), speckle_size=4, seed=1)
    >>> p = predict_compensated(img, [0.0, 4.0], noise_sigma=2.0, subset=21, step=10)
    >>> bool(p.u_e[1] < (2 * 2.0 ** 2 / p.sssig[1]) ** 0.5)
    True
    """
    img = as_image(image, "image", min_size=3)
    subset = check_odd_subset(subset)
    sigma = check_positive(noise_sigma, "noise_sigma")
    shape = check_choice(shape, "shape", ("translation", "affine"))
    derivative = check_choice(derivative, "derivative", ("bspline3", "bspline5", "central"))
    w = as_blur(blur, "blur", increasing=False)
    e = unit_direction(motion)
    if np.any(w >= subset):
        raise InputError(
            f"blur: {float(w.max()):g} px is not shorter than the subset "
            f"({subset} px); use a subset larger than the blur"
        )
    pts = _points(img, subset, step, points)
    angle = math.degrees(math.atan2(e[0], e[1]))
    u_noise = np.empty(w.size)
    sssig = np.empty(w.size)
    frac = np.empty(w.size)
    for i, wl in enumerate(w):
        vec = (wl * e[0], wl * e[1])
        fw = blur_reference(img, vec)[0]
        fww = blur_reference(fw, vec)[0]
        var = _noise_variance(fw, fww, pts, subset // 2, shape, e, derivative)
        ok = np.isfinite(var) & (var > 0)
        if ok.sum() < 2:
            raise InputError(
                f"image: fewer than two subsets keep an intensity gradient at "
                f"W = {wl:g} px; no prediction there"
            )
        u_noise[i] = sigma * math.sqrt(float(np.mean(var[ok])))
        sssig[i] = float(directional_sssig(fw, pts, subset=subset, angle=angle).mean())
        frac[i] = ok.mean()
    return PatternPrediction(
        blur=w,
        u_e=u_noise.copy(),
        u_noise=u_noise,
        u_blur=np.zeros(w.size),
        sssig=sssig,
        valid_fraction=frac,
        noise_sigma=sigma,
        subset=subset,
        shape=shape,
        motion=e,
    )


def model_from_compensated(
    image: ArrayLike,
    *,
    noise_sigma: float,
    subset: int,
    blur: ArrayLike | None = None,
    step: int | None = None,
    points: ArrayLike | None = None,
    motion: tuple[float, float] = (0.0, 1.0),
    shape: str = "translation",
    provenance: dict[str, Any] | None = None,
) -> BlurUncertaintyModel:
    """A model of the blur-compensated matcher fitted to :func:`predict_compensated`.

    The compensated counterpart of :func:`~dicblur.models.model_from_pattern`: the
    prediction at noise ``sigma/2``, ``sigma`` and ``2 sigma`` over ``blur`` (default
    W = 0..8 px in steps of 0.5, shorter than the subset) is fitted like campaign data
    (:func:`~dicblur.models.fit_blur_model` with ``compensation="given"``). The mismatch
    coefficient comes out near zero; the model records the matcher mode and the same
    pattern hash as ``model_from_pattern`` of the same image, so
    :func:`~dicblur.models.compare_plans` (``dicblur plan --compare``) sets the two
    against each other before any simulation.

    Parameters
    ----------
    image : array_like, shape (rows, cols)
        Sharp reference image, grey levels.
    noise_sigma : float
        Noise std (GL) of the images the model is for.
    subset : int
        Odd subset size (px).
    blur : array_like, optional
        Blur lengths (px, < subset) to predict and fit; at least 4 distinct values.
    step, points, motion, shape
        As for :func:`predict_compensated`.
    provenance : dict, optional
        Extra JSON-ready fields (``"image"``: its path names the pattern).

    Returns
    -------
    BlurUncertaintyModel
    """
    img = as_image(image, "image", min_size=3)
    sigma = check_positive(noise_sigma, "noise_sigma")
    subset = check_odd_subset(subset)
    w = model_blur(blur, below=subset)
    # first order in the noise: u_e is proportional to sigma, one prediction serves all
    unit = predict_compensated(
        img, w, noise_sigma=1.0, subset=subset, step=step, points=points, motion=motion, shape=shape
    )
    prov: dict[str, Any] = {
        "source": "static prediction (blur-compensated matcher)",
        "compensation": "given",
        "subset": subset,
        "shape": str(shape),
        "motion": [float(motion[0]), float(motion[1])],
        "image_shape": list(img.shape),
    }
    prov.update(provenance or {})
    return fit_prediction(
        img,
        w,
        unit.sssig,
        [f * sigma * unit.u_e for f in NOISE_FACTORS],
        noise_sigma=sigma,
        subset=subset,
        shape=str(shape),
        provenance=prov,
        compensation="given",
    )


def compensated_covariance(
    blurred: ArrayLike,
    blurred_twice: ArrayLike,
    points: ArrayLike,
    *,
    subset: int,
    shape: str = "affine",
    derivative: str = "bspline3",
) -> Float64Array:
    """Per-subset 2x2 covariance of (u, v) of the blur-compensated matcher per unit noise
    variance (px^2 / GL^2), from the blurred reference (the module docstring's two terms).

    Parameters
    ----------
    blurred : array_like, shape (rows, cols)
        The reference blurred by the blur vector, ``f_W`` (:func:`dicblur.dic.blur_reference`).
    blurred_twice : array_like, shape (rows, cols)
        ``f_W`` blurred once more by the same vector, ``B f_W``: the gradients through which
        the blurred reference's own noise enters.
    points : array_like, shape (n, 2)
        Subset centres (row, col), px; each subset inside the image.
    subset : int
        Odd subset size, px.
    shape : {"translation", "affine"}
    derivative : {"bspline3", "bspline5", "central"}

    Returns
    -------
    ndarray, shape (n, 2, 2)
        ``A^-1 + A^-1 C A^-1`` restricted to (u, v), with ``A`` and ``C`` the ZNSSD Fisher
        matrices of the current image's (``f_W``) and the reference's (``B f_W``) gradients;
        NaN for a subset without gradient. Times the noise variance: the covariance.
    """
    fw = as_image(blurred, "blurred", min_size=3)
    fww = as_image(blurred_twice, "blurred_twice", min_size=3)
    subset = check_odd_subset(subset)
    shape = check_choice(shape, "shape", ("translation", "affine"))
    derivative = check_choice(derivative, "derivative", ("bspline3", "bspline5", "central"))
    pts = _points(fw, subset, None, points)
    half = subset // 2
    amat, cmat, fn = _fisher(_windows(fw, fww, pts, half, derivative), half, shape)
    out = np.full((len(pts), 2, 2), np.nan)
    ok = np.isfinite(amat).all(axis=(1, 2)) & (np.linalg.cond(amat) < 1e12) & (fn > 0)
    if ok.any():
        ainv = np.linalg.inv(amat[ok])
        cov = ainv + ainv @ cmat[ok] @ ainv
        iv = 1 if shape == "translation" else 3  # v's column (raw_jacobian's order)
        out[ok] = cov[:, [0, iv]][:, :, [0, iv]]
    return out
