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

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..arrays import Float64Array, IndexArray
from ..errors import InputError
from .blur_response import subset_blur_response as subset_blur_response
from .blur_response import subset_skew_coefficients as subset_skew_coefficients
from .derivatives import box_blurred as box_blurred
from .derivatives import (
    check_derivative,
    derivative_kernel,
    directional_derivatives,
    interpolated_noise_covariance,
    unit_direction,
)
from .derivatives import image_spectrum as image_spectrum
from .derivatives import spectral_derivatives as spectral_derivatives
from .derivatives import spline_gradients as spline_gradients
from .reference_terms import ReferenceTerms
from .subset_algebra import (
    ENGINE_MATCHER,
    Criterion,
    SubsetMatcher,
    Windows,
    along_motion,
    blurred_subsets,
    check_criterion,
    check_shape,
    contraction,
    gram,
    normalise,
    project,
    reference_noise_middle,
    solve,
    tdot,
)

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


def subset_blur_coefficients(
    image: Float64Array,
    centres: IndexArray,
    subset: int,
    matcher: SubsetMatcher = ENGINE_MATCHER,
    *,
    criterion: Criterion = "znssd",
    chunk: int = 256,
) -> Float64Array:
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
    matcher : SubsetMatcher
        The matcher's motion direction and shape function, and the gradients' derivative
        and boundary (see :func:`directional_derivatives`); default the DIC engine's
        translation matcher, motion along x.
    criterion : {"znssd", "ssd"}
        Matching criterion: ZNSSD (the engine's; projects off the intensity offset and
        scale) or plain SSD.

    Returns
    -------
    ndarray, shape (n,)
        ``k_i``; ``nan`` where the subset has no gradient (singular normal matrix).
    """
    shape = matcher.shape
    check_shape(shape)
    check_criterion(criterion)
    dy, dx = unit_direction(matcher.motion)
    fy, fx, fdd = directional_derivatives(
        image, matcher.motion, derivative=matcher.derivative, boundary=matcher.boundary
    )
    win = Windows(subset, fx, fy, fdd, image)
    out = np.empty(len(centres))
    for start in range(0, len(centres), chunk):
        cc = centres[start : start + chunk]
        gx, gy, e, f = win.take(cc)
        jac = win.jacobian(gx, gy, shape)
        if criterion == "znssd":
            jp = project(jac, normalise(f)[0])
        else:
            jp = jac
        # J^T P J and J^T P f_dd (P symmetric and idempotent)
        sol = solve(gram(jp, jp), tdot(jp, e))
        out[start : start + len(cc)] = -along_motion(sol, shape, dy, dx) / 24.0
    return out


def subset_blur_shifts(
    image: Float64Array,
    blur: Float64Array,
    centres: IndexArray,
    subset: int,
    matcher: SubsetMatcher = ENGINE_MATCHER,
    *,
    criterion: Criterion = "znssd",
    max_shift: float = 1.0,
    chunk: int = 256,
    offset: float | None = None,
) -> Float64Array:
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
    centres, subset, matcher, criterion
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
    check_criterion(criterion)
    return shifts_and_variance(
        image,
        blur,
        centres,
        subset,
        matcher,
        criterion=criterion,
        max_shift=max_shift,
        chunk=chunk,
        variance=False,
        offset=offset,
    )[0]


def shifts_and_variance(
    image: Float64Array,
    blur: ArrayLike,
    centres: IndexArray,
    subset: int,
    matcher: SubsetMatcher,
    *,
    criterion: Criterion,
    max_shift: float,
    chunk: int,
    variance: bool,
    offset: float | None = None,
    complete: bool = True,
    min_contraction: float = 0.0,
    contraction_out: Float64Array | None = None,
    reference: ReferenceTerms | None = None,
) -> tuple[Float64Array, Float64Array | None]:
    """One pass over blur lengths and subsets: the shifts (and, with ``variance``, the
    noise variance per unit noise variance) of :func:`subset_blur_shifts` and
    :func:`subset_noise_variance`.

    The variance comes as shape (3, m, n): the reference image's share and the current
    image's (per unit noise variance, first order in the noise), then the interaction of
    the two noises (per unit ``sigma**4``: the reference-gradient noise against the current
    image's noise, second order; it exists only when both images are noisy).
    ``complete=False`` drops the reference-gradient noise terms (the earlier, incomplete
    formula; kept for the benchmark's comparison). ``min_contraction > 0``: a subset whose
    IC-GN contraction (:func:`contraction`) falls below it has broken down (``nan``).
    ``contraction_out``, shape (m, n): filled with the contraction of every subset.
    ``reference``: a :class:`~dicblur.models.reference_terms.ReferenceTerms` that keeps the
    reference's terms across blur lengths and calls (same numbers, less work)."""
    shape, derivative = matcher.shape, matcher.derivative
    check_shape(shape)
    check_derivative(derivative)
    dy, dx = unit_direction(matcher.motion)
    w = np.asarray(blur, dtype=np.float64)
    shifts = np.zeros((len(w), len(centres)))
    var = np.full((3, len(w), len(centres)), np.nan) if variance else None
    kernel = derivative_kernel(derivative, subset) if variance and complete else None
    e = np.zeros(2 if shape == "translation" else 6)
    e[0] = dx
    e[1 if shape == "translation" else 3] = dy
    if offset is not None and derivative not in ("bspline3", "bspline5"):
        raise InputError(
            f"subpixel={offset!r} with derivative={derivative!r}: the sub-pixel "
            "position is seen through the matcher's B-spline; use "
            "derivative='bspline3' or 'bspline5'"
        )
    noise_cov: tuple[Float64Array | None, ...] | None = None
    if offset is not None and variance:
        order = 3 if derivative == "bspline3" else 5
        oy, ox = offset * dy, offset * dx
        # None: no fractional offset along that axis, the interpolant passes noise as is
        noise_cov = tuple(
            None if t == 0.0 else interpolated_noise_covariance(t, order, subset)
            for t in (oy - math.floor(oy), ox - math.floor(ox))
        )
    offsets = Windows(subset)
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
    if reference is not None:
        reference.bind(image, centres, subset, shape, derivative, chunk)
    ref_terms: tuple[Any, ...] | None = None
    for j, start, jf, jg, f, gg in blurred_subsets(
        image, w, centres, subset, matcher, chunk, offset
    ):
        rows = slice(start, start + len(f))
        if criterion == "znssd" or variance:
            if reference is None:
                fh, sf = normalise(f)
            else:
                fh, sf, *rest = reference.terms(start, jf, f)
                ref_terms = tuple(rest)
            gh, sg = normalise(gg)
            pjg = project(jg, gh)  # P_g J_g
            cross = gram(jf, pjg)  # J_f^T P_g J_g
        p0 = None
        broken = np.zeros(len(f), dtype=bool)
        if w[j] > 0 or offset is not None:
            if criterion == "znssd":
                sg_ok = np.where(sg > 0, sg, np.nan)  # a flat blurred subset: no fixed point
                a = cross / sg_ok[:, None, None]
                b = tdot(jf, fh - gh)
            else:
                a = gram(jf, jg)
                b = tdot(jf, f - gg)
            p0 = solve(a, b)
            shifts[j, rows] = along_motion(p0, shape, dy, dx, max_shift)
            if min_contraction > 0 or contraction_out is not None:
                lam = contraction(jf, fh, sf, cross, sg, ref_terms)
                if contraction_out is not None:
                    contraction_out[j, rows] = lam
                if min_contraction > 0:
                    broken = ~(lam >= min_contraction)
                    shifts[j, rows][broken] = np.nan
        elif contraction_out is not None:
            contraction_out[j, rows] = 1.0  # the reference itself: K = I
        if var is not None:
            ratio2 = (sg / np.where(sf > 0, sf, np.nan)) ** 2
            pf = project(jf, fh) if ref_terms is None else ref_terms[0]
            pg = project(jf, gh)
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
                    p0 = solve(cross / sg_ok[:, None, None], tdot(jf, fh - gh))
                # residual at the linearised fixed point, orthogonal to J_f
                r0 = fh - gh - np.matmul(pjg, p0[:, :, None])[:, :, 0] / sg_ok[:, None]
                mid_ref = reference_noise_middle(
                    pf,
                    np.sqrt(ratio2),
                    sg,
                    r0,
                    subset,
                    shape,
                    win_ex,
                    win_ey,
                    kernel,
                    pf_gram=None if ref_terms is None else ref_terms[1],
                )
            else:
                mid_ref = ratio2[:, None, None] * gram(pf, pf)
            # e^T A^-1 M A^-T e = z^T M z with A^T z = e
            z = solve(np.transpose(cross, (0, 2, 1)), np.broadcast_to(e, (len(f), e.size)).copy())
            var[0, j, rows] = np.einsum("ni,nij,nj->n", z, mid_ref, z)
            var[1, j, rows] = np.einsum("ni,nij,nj->n", z, gram(pg, pg_c), z)
            var[2, j, rows] = np.einsum("ni,ij,nj->n", z, gmat, z)
            var[:, j, rows] = np.where(broken[None, :], np.nan, var[:, j, rows])
    return shifts, var


def subset_noise_variance(
    image: Float64Array,
    blur: Float64Array,
    centres: IndexArray,
    subset: int,
    matcher: SubsetMatcher = ENGINE_MATCHER,
    *,
    chunk: int = 256,
) -> Float64Array:
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
        matcher,
        criterion="znssd",
        max_shift=np.inf,
        chunk=chunk,
        variance=True,
    )[1]
    assert var is not None
    return np.asarray(var[0] + var[1])  # first order (the sigma**4 interaction left out)
