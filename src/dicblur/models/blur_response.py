"""Per-subset blur response of subset DIC for the per-point sigma of :mod:`dicblur.track`
(:func:`subset_blur_response`: the mismatch shift and noise variance on a table of blur
vectors; :func:`subset_skew_coefficients`: the bias of a skewed exposure profile), from the
subset-level formulas of :mod:`dicblur.models.sensitivity` (derivation there and in
docs/models.md).
"""

from __future__ import annotations

import functools

import numpy as np
from numpy.typing import ArrayLike

from ..arrays import Float64Array, IndexArray
from ..threads import each
from .derivatives import (
    blurred_images,
    check_derivative,
    crop,
    derivative_kernel,
    extend,
    image_spectrum,
    matcher_gradients,
    unit_direction,
)
from .subset_algebra import (
    ENGINE_MATCHER,
    SubsetMatcher,
    Windows,
    check_shape,
    gram,
    normalise,
    project,
    reference_noise_middle,
    solve,
    solve_each,
    tdot,
)


def subset_blur_response(
    image: Float64Array,
    blur: ArrayLike,
    centres: IndexArray,
    subset: int,
    matcher: SubsetMatcher = ENGINE_MATCHER,
    *,
    max_shift: float = 1.0,
    chunk: int = 256,
    complete: bool = True,
    threads: int = 1,
) -> tuple[Float64Array, Float64Array, Float64Array]:
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
    centres, subset, matcher
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
    shape, derivative, boundary = matcher.shape, matcher.derivative, matcher.boundary
    check_shape(shape)
    check_derivative(derivative)
    dy, dx = unit_direction(matcher.motion)
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
    win = Windows(subset)
    kernel = derivative_kernel(derivative, subset) if complete else None
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
        jf: Float64Array,
        jg: Float64Array,
        fh: Float64Array,
        sf: Float64Array,
        pf: Float64Array,
        pf_gram: Float64Array,
        gg: Float64Array,
    ) -> None:
        """The shift and covariances of the subsets ``rows`` at ``W = w[j]``."""
        if w[j] == 0:  # g is f: its normalised subsets and projection are f's
            gh, sg, pg, pg_gram = fh, sf, pf, pf_gram
        else:
            gh, sg = normalise(gg)
            pg = project(jf, gh)
            pg_gram = gram(pg, pg)
        # J_f^T P_g J_g = (P_g J_f)^T J_g (P_g a symmetric projection: one project less)
        cross = gram(pg, jg)
        sol = None
        sg_ok = np.where(sg > 0, sg, np.nan)
        if w[j] > 0:
            sol = solve(cross / sg_ok[:, None, None], tdot(jf, fh - gh))
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
            mid_ref = reference_noise_middle(
                pf, np.sqrt(ratio2), sg, r0, subset, shape, win.ex, win.ey, kernel, pf_gram
            )
        else:
            mid_ref = ratio2[:, None, None] * pf_gram
        mid = mid_ref + pg_gram
        at = np.transpose(cross, (0, 2, 1))
        z = np.stack(
            solve_each(at, [np.broadcast_to(e[c], (len(gg), k)).copy() for c in range(2)]),
            axis=1,
        )  # (m, 2, k): A^T z_c = e_c (one condition number per subset for both)
        cov[j, rows] = np.einsum("nci,nij,ndj->ncd", z, mid, z)
        if kernel is not None:
            cov4[j, rows] = np.einsum("nci,ij,ndj->ncd", z, gmat, z)

    grads = matcher_gradients(image, (dy, dx), derivative, boundary)
    spec = image_spectrum(image, boundary) if np.any(w != 0) else None
    sharp = Windows(subset, grads[1], grads[0], image)
    # W nodes in groups whose blurred images (3 per node) fit in about 64 MB: each chunk
    # of subsets then runs through a group's nodes with its sharp-image terms (J_f, the
    # normalised f, P_f J_f and its Gram matrix: none depends on W) computed once
    per_group = max(1, (64 << 20) // (3 * image.nbytes))

    def prepare(j: int, out: dict[int, Windows]) -> None:
        g, ggy, ggx = blurred_images(
            image, float(w[j]), (dy, dx), grads, derivative, boundary, spec
        )
        out[j] = Windows(subset, ggx, ggy, g)

    def one(start: int, wins: dict[int, Windows]) -> None:
        cc = centres[start : start + chunk]
        rows = slice(start, start + len(cc))
        ax, ay, f = sharp.take(cc)
        jf = sharp.jacobian(ax, ay, shape)
        fh, sf = normalise(f)
        pf = project(jf, fh)
        pf_gram = gram(pf, pf)
        for j, win_j in wins.items():
            bx, by, gg = win_j.take(cc)
            _response_chunk(j, rows, jf, win_j.jacobian(bx, by, shape), fh, sf, pf, pf_gram, gg)

    for g0 in range(0, len(w), per_group):
        wins: dict[int, Windows] = {}
        group = range(g0, min(g0 + per_group, len(w)))
        each(functools.partial(prepare, out=wins), group, threads)
        wins = {j: wins[j] for j in group}  # in the order of the nodes
        each(functools.partial(one, wins=wins), range(0, n, chunk), threads)
    return shift, cov, cov4


def subset_skew_coefficients(
    image: Float64Array,
    centres: IndexArray,
    subset: int,
    matcher: SubsetMatcher = ENGINE_MATCHER,
    *,
    chunk: int = 256,
    threads: int = 1,
) -> Float64Array:
    """Per-subset shift per unit third moment of the blur kernel, ``(u, v)`` px / px**3.

    A blur kernel of positions ``s`` along ``d`` (an accelerating target: the time spent
    per px is not uniform) with third central moment ``kappa_3`` adds
    ``-(kappa_3 / 6) f_ddd`` to the image about its mean position; the ZNSSD IC-GN fixed
    point then moves by ``+(kappa_3 / 6) (J^T P J)^-1 J^T P f_ddd`` (the same
    linearisation as the ``W**2 / 24`` term of :func:`subset_blur_coefficients`, which is
    ``kappa_2 / 2`` of a box). By parts ``sum f_d f_ddd = -sum f_dd**2``: the shift has
    the same sign in every subset, a common offset of the field. Returns the factor of
    ``kappa_3``, shape (n, 2) (NaN: no gradient). ``matcher``: as for
    :func:`subset_blur_coefficients`; ``threads``: threads sharing the chunks of ``chunk``
    subsets (the same numbers).
    """
    shape, derivative, boundary = matcher.shape, matcher.derivative, matcher.boundary
    check_shape(shape)
    check_derivative(derivative)
    dy, dx = unit_direction(matcher.motion)
    rows, cols = image.shape
    ext = extend(image, boundary)
    shp = ext.shape
    k = (2j * np.pi) * (
        dy * np.fft.fftfreq(shp[0])[:, None] + dx * np.fft.rfftfreq(shp[1])[None, :]
    )
    spec = np.fft.rfft2(ext)
    del ext
    spec *= k**3  # in place: the same products, one extended array fewer
    del k
    fddd = crop(np.fft.irfft2(spec, s=shp), rows, cols)
    del spec
    fy, fx = matcher_gradients(image, matcher.motion, derivative, boundary)
    win = Windows(subset, fx, fy, fddd, image)
    out = np.full((len(centres), 2), np.nan)
    iv = 1 if shape == "translation" else 3

    def one(start: int) -> None:
        cc = centres[start : start + chunk]
        gx, gy, e3, f = win.take(cc)
        jp = project(win.jacobian(gx, gy, shape), normalise(f)[0])
        sol = solve(gram(jp, jp), tdot(jp, e3)) / 6.0
        out[start : start + len(cc), 0] = sol[:, 0]
        out[start : start + len(cc), 1] = sol[:, iv]

    each(one, range(0, len(centres), chunk), threads)
    return out
