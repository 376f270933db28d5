"""The subset windows and their least-squares algebra under :mod:`dicblur.models.sensitivity`
(derivation there and in docs/models.md): the steepest-descent images of a shape function
per subset, the ZNSSD normalisation and projection, Gram matrices and their solves, the
blurred subsets, and the reference-noise terms of the matcher's gradients.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from ..arrays import Float64Array, IndexArray
from ..errors import InputError
from .derivatives import (
    Boundary,
    Derivative,
    blurred_images,
    image_spectrum,
    matcher_gradients,
    unit_direction,
)

Shape = Literal["translation", "affine"]
Criterion = Literal["znssd", "ssd"]


@dataclass(frozen=True)
class SubsetMatcher:
    """The matcher a static prediction models, as one record passed down its internal
    layers: the ``motion, shape, derivative, boundary`` keywords of the public functions
    (:func:`~dicblur.models.predict_from_pattern`, :func:`~dicblur.models.blur_sensitivity`,
    ...), with their defaults, unchecked.

    Attributes
    ----------
    motion : (dy, dx)
        Motion direction (px; any length).
    shape : {"translation", "affine"}
        Shape function of the matcher.
    derivative : {"bspline3", "bspline5", "spectral", "central"}
        Gradient operator of the matcher.
    boundary : {"reflect", "periodic"}
        Image extension of the spectral operators.
    """

    motion: tuple[float, float] = (0.0, 1.0)
    shape: Shape = "translation"
    derivative: Derivative = "bspline3"
    boundary: Boundary = "reflect"


ENGINE_MATCHER = SubsetMatcher()  # the defaults: the DIC engine's matcher, motion along x


def reference_noise_middle(
    pf: Float64Array,
    ratio: Float64Array,
    sg: Float64Array,
    r0: Float64Array,
    subset: int,
    shape: str,
    ex: Float64Array,
    ey: Float64Array,
    kernel: Float64Array,
    pf_gram: Float64Array | None = None,
) -> Float64Array:
    """``M^T M`` of the reference noise's response ``A^-1 M^T n``, per unit noise variance:
    ``M = ratio P_f J_f + sigma_g Q`` with ``Q = [D_k^T (S_k r0)]`` (docs/models.md s. 4,
    the complete noise term). Shape (m, k, k). ``pf_gram``: ``(P_f J_f)^T (P_f J_f)``
    computed before (it does not depend on the blur).

    ``Q[:, k] = D_k^T (S_k r0)`` is the linear functional of the reference noise ``n`` by
    which the noisy gradients move ``J_f^T r0`` (``delta J_f[:, k] = S_k D n``, ``D`` the
    spline derivative along x or y with impulse response ``kernel``, ``S_k`` the weight
    1, dx or dy of the shape function; the columns in the order of
    :meth:`Windows.jacobian`). ``D^T`` spreads each field by the kernel's half-length
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
    gpf = gram(pf, pf) if pf_gram is None else pf_gram
    return r * r * gpf + r * s * (cross + np.transpose(cross, (0, 2, 1))) + s * s * qq


def check_shape(shape: str) -> None:
    if shape not in ("translation", "affine"):
        raise InputError(f"shape={shape!r}: unknown shape function; use 'translation' or 'affine'")


def check_criterion(criterion: str) -> None:
    if criterion not in ("znssd", "ssd"):
        raise InputError(
            f"criterion={criterion!r}: unknown matching criterion; use 'znssd' (the DIC "
            "engine's, default) or 'ssd'"
        )


class Windows:
    """Subset windows of several images, gathered a chunk of centres at a time."""

    def __init__(self, subset: int, *images: Float64Array) -> None:
        self.h = subset // 2
        self.views = [np.lib.stride_tricks.sliding_window_view(a, (subset, subset)) for a in images]
        off = np.arange(-self.h, self.h + 1, dtype=np.float64)
        oy, ox = np.meshgrid(off, off, indexing="ij")
        self.ex, self.ey = ox.ravel()[None, :], oy.ravel()[None, :]

    def take(self, cc: IndexArray) -> list[Float64Array]:
        r0, c0 = cc[:, 0] - self.h, cc[:, 1] - self.h
        return [v[r0, c0].reshape(len(cc), -1) for v in self.views]

    def jacobian(self, gx: Float64Array, gy: Float64Array, shape: str) -> Float64Array:
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


def normalise(a: Float64Array) -> tuple[Float64Array, Float64Array]:
    """Rows with mean removed and unit norm, and their norms (m, pixels), (m,)."""
    z = a - a.mean(axis=1, keepdims=True)
    n = np.sqrt(np.einsum("np,np->n", z, z))
    return z / np.where(n > 0, n, 1.0)[:, None], n


def project(jac: Float64Array, hat: Float64Array) -> Float64Array:
    """``P jac``: remove from each column the constant and the component along ``hat``
    (zero-mean, unit-norm rows): the ZNSSD offset and scale nuisance parameters."""
    z = jac - jac.mean(axis=1, keepdims=True)
    z -= hat[:, :, None] * np.matmul(hat[:, None, :], z)  # in place: one temporary fewer
    return z


def gram(a: Float64Array, b: Float64Array) -> Float64Array:
    """Batched ``a^T b`` over the pixels: (m, P, i), (m, P, j) -> (m, i, j) (BLAS)."""
    return np.asarray(np.matmul(np.swapaxes(a, 1, 2), b))


def tdot(a: Float64Array, v: Float64Array) -> Float64Array:
    """Batched ``a^T v``: (m, P, i), (m, P) -> (m, i)."""
    return np.asarray(np.matmul(np.swapaxes(a, 1, 2), v[:, :, None])[:, :, 0])


def solve(a: Float64Array, b: Float64Array) -> Float64Array:
    """Batched ``a^-1 b``; NaN rows where ``a`` is singular (no gradient in the subset)."""
    return solve_each(a, [b])[0]


def solve_each(a: Float64Array, bs: list[Float64Array]) -> list[Float64Array]:
    """:func:`solve` of one batch of matrices ``a`` for each right-hand side of ``bs``
    (each (m, k)): the condition numbers (an SVD per matrix) computed once, each system
    solved as :func:`solve` solves it (the same numbers)."""
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


def along_motion(
    sol: Float64Array, shape: str, dy: float, dx: float, max_shift: float = np.inf
) -> Float64Array:
    u = sol[:, 0]
    v = sol[:, 1] if shape == "translation" else sol[:, 3]
    return np.where(np.hypot(u, v) <= max_shift, dx * u + dy * v, np.nan)


def contraction(
    jf: Float64Array,
    fh: Float64Array,
    sf: Float64Array,
    cross: Float64Array,
    sg: Float64Array,
    reference: tuple[Any, ...] | None = None,
) -> Float64Array:
    """Smallest real part of the eigenvalues of ``K = (sigma_f / sigma_g) H^-1 A`` per subset,
    ``H = J_f^T P_f J_f`` (the IC-GN Hessian of ZNSSD) and ``A = J_f^T P_g J_g`` (the
    fixed point's Jacobian). IC-GN against the blurred image moves by ``I - K`` per step
    near its fixed point: ``K = I`` for a warped copy; blur lowers it, and as it nears 0
    the fixed point degenerates (the noise response grows as ``1 / lambda``, IC-GN stalls)
    and beyond 0 it repels (the blur has reversed the subset's gradients along the motion:
    the sinc's negative lobe). ``nan`` where undefined."""
    if reference is None:
        pf = project(jf, fh)
        hess = gram(pf, pf)
        cond = None
    else:  # (P_f J_f, H, cond(H)) kept across blur lengths (ReferenceTerms)
        pf, hess, cond = reference
    ok = np.isfinite(hess).all(axis=(1, 2)) & np.isfinite(cross).all(axis=(1, 2)) & (sg > 0)
    ok[ok] = (np.linalg.cond(hess[ok]) if cond is None else cond[ok]) < 1e12
    lam = np.full(len(jf), np.nan)
    if ok.any():
        k = np.linalg.solve(hess[ok], cross[ok]) * (sf[ok] / sg[ok])[:, None, None]
        lam[ok] = np.linalg.eigvals(k).real.min(axis=1)
    return lam


def blurred_subsets(
    image: Float64Array,
    blur: Float64Array,
    centres: IndexArray,
    subset: int,
    matcher: SubsetMatcher,
    chunk: int,
    offset: float | None = None,
) -> Iterator[tuple[int, int, Float64Array, Float64Array, Float64Array, Float64Array]]:
    """``(j, start, J_f, J_g, f, g)`` for every blur length and chunk of subsets: the
    steepest-descent images of the sharp and of the centred-box-blurred image, and their
    subset intensities (W = 0: ``g = f``). With ``offset`` (px along the motion) the
    blurred target is moved by it and seen through the matcher's B-spline interpolant
    (:func:`_interpolated_at`)."""
    derivative, boundary, shape = matcher.derivative, matcher.boundary, matcher.shape
    dy, dx = unit_direction(matcher.motion)
    fy, fx = matcher_gradients(image, matcher.motion, derivative, boundary)
    spec = None  # the reference's spectrum, one forward FFT for all the blur lengths
    for j, wl in enumerate(np.asarray(blur, dtype=np.float64)):
        if wl != 0 and spec is None:
            spec = image_spectrum(image, boundary)
        g, ggy, ggx = blurred_images(
            image, float(wl), (dy, dx), (fy, fx), derivative, boundary, spec, offset
        )
        win = Windows(subset, fx, fy, ggx, ggy, image, g)
        for start in range(0, len(centres), chunk):
            ax, ay, bx, by, f, gg = win.take(centres[start : start + chunk])
            yield j, start, win.jacobian(ax, ay, shape), win.jacobian(bx, by, shape), f, gg
