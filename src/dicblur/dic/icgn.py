"""IC-GN refinement with the ZNSSD criterion: per-subset preparation and the reference
implementation.

Inverse-compositional Gauss-Newton (Pan, Li & Tong, Exp. Mech. 53, 2013,
doi:10.1007/s11340-013-9717-6): the warp increment is applied to the *reference* subset, so
the steepest-descent images and the Hessian depend on the reference only and are computed
once per subset here (:func:`prepare_subsets`), then reused for every current image.

Algebra used by the kernels. For a subset of ``n`` pixels let ``J`` (n, k) hold the raw
steepest-descent images (``gx``, ``gx dx``, ``gx dy``, ``gy``, ``gy dx``, ``gy dy`` for the
affine shape; ``gx``, ``gy`` for translation), ``f_c = f - mean(f)``,
``Df = ||f_c||`` and ``fh = f_c / Df``. The ZNSSD criterion
``C = sum (fh - gh)^2`` is invariant to an offset and a gain of either subset, so its exact
Gauss-Newton Jacobian with respect to the reference warp is
``Jh = (J_c - fh a^T) / Df`` with ``J_c`` the column-centred ``J`` and ``a = J_c^T fh``.
``Jh^T fh = 0``, hence the update is ``dp = H^-1 Jh^T gh`` with ``H = Jh^T Jh``, and
``Jh^T gh = ((J^T g - J^T 1 mean(g)) / Dg - a zncc) / Df``: each iteration needs only the
sums of ``g``, ``g^2``, ``f g`` and ``J^T g`` over the warped current subset.

Predicted random error (noise std ``sigma`` in both images, first order): the estimate
``dp`` is linear in the noise with covariance ``2 sigma^2 (Df^2 H)^-1`` (the inverse of the
Fisher information of the ZNSSD model; IC-GN random-error analysis: Pan & Wang, Exp. Mech.
56, 2016, doi:10.1007/s11340-016-0180-z). For the translation shape the issue fixes the
match-score form ``sqrt(2 sigma^2 / SSSIG)`` per axis (Lavatelli & Zappa eq. 2).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from ..arrays import BoolArray, Float64Array, FloatArray, IndexArray, UInt8Array
from .interpolation import interpolate_reference
from .kernels import GAIN_MIN, JUMP_SLACK, STALL_ITERATIONS
from .status import PointStatus

__all__ = [
    "CentredSubsets",
    "PreparedSubsets",
    "centre_subsets",
    "compose_affine",
    "gauss_newton_matrix",
    "icgn_reference",
    "prepare_subsets",
    "raw_jacobian",
    "regular",
    "scaled_inverse",
    "uv_columns",
]

#: Number of shape parameters per shape function.
N_PARAMS = {"translation": 2, "affine": 6}


def uv_columns(k: int) -> tuple[int, int]:
    """The columns of ``u`` and ``v`` among ``k`` shape parameters: translation ``(u, v)``,
    affine ``(u, ux, uy, v, vx, vy)``."""
    return 0, 1 if k == 2 else 3


@dataclass(frozen=True)
class PreparedSubsets:
    """Per-subset reference quantities (arrays over the n POIs).

    ``hinv`` (n, k, k) inverse exact ZNSSD Hessian; ``jsum`` (n, k) column sums of the raw
    steepest-descent images; ``avec`` (n, k) ``J_c^T fh``; ``fmean``, ``fnorm`` (n,) mean and
    norm of the zero-mean subset; ``status`` (n,) uint8 (``LOW_TEXTURE`` where the Hessian
    is singular); ``cov_unit`` (n, k, k) the parameter covariance for unit noise variance
    in both images, ``2 (Df^2 H)^-1`` (px^2 per GL^2); ``sssig_x``, ``sssig_y`` (n,) SSSIG
    of the reference subset ((GL/px)^2).
    """

    hinv: Float64Array
    jsum: Float64Array
    avec: Float64Array
    fmean: Float64Array
    fnorm: Float64Array
    status: UInt8Array
    cov_unit: Float64Array
    sssig_x: Float64Array
    sssig_y: Float64Array


def _patches(image: Float64Array, rows: IndexArray, cols: IndexArray, half: int) -> Float64Array:
    size = 2 * half + 1
    view = sliding_window_view(image, (size, size))
    return np.asarray(view[rows - half, cols - half], dtype=np.float64).reshape(len(rows), -1)


def raw_jacobian(gx: Float64Array, gy: Float64Array, half: int, shape: str) -> Float64Array:
    """Raw steepest-descent images ``J`` (n, npx, k) from subset gradients (n, npx).

    Column order follows the parameters: translation ``(u, v)``; affine
    ``(u, ux, uy, v, vx, vy)``. Pixel order is row-major with offsets ``dx`` along columns
    and ``dy`` along rows from the subset centre.
    """
    size = 2 * half + 1
    d = np.arange(size, dtype=np.float64) - half
    dy, dx = (a.ravel() for a in np.meshgrid(d, d, indexing="ij"))
    if shape == "translation":
        return np.stack([gx, gy], axis=-1)
    return np.stack([gx, gx * dx, gx * dy, gy, gy * dx, gy * dy], axis=-1)


class CentredSubsets(NamedTuple):
    """Reference subsets (n, npx) and their raw steepest-descent images ``J`` (n, npx, k)
    centred for ZNSSD (module docstring): ``fmean`` (n,) the subset's mean and ``fnorm``
    (n,) ``Df = ||f_c||``, GL; ``safe`` (n,) ``Df``, 1 where it is 0; ``fh`` (n, npx)
    ``f_c / safe``; ``jsum`` (n, k) ``sum J``; ``jc`` (n, npx, k) the column-centred ``J``."""

    fmean: Float64Array
    fnorm: Float64Array
    safe: Float64Array
    fh: Float64Array
    jsum: Float64Array
    jc: Float64Array


def centre_subsets(fp: Float64Array, jac: Float64Array) -> CentredSubsets:
    """The subsets ``fp`` (n, npx) and their ``jac`` (n, npx, k) centred for ZNSSD."""
    npx = fp.shape[1]
    fmean = fp.mean(axis=1)
    fc = fp - fmean[:, None]
    fnorm = np.sqrt(np.einsum("ij,ij->i", fc, fc))
    safe = np.where(fnorm > 0, fnorm, 1.0)
    jsum = jac.sum(axis=1)
    jc = jac - jsum[:, None, :] / npx
    return CentredSubsets(fmean, fnorm, safe, fc / safe[:, None], jsum, jc)


def regular(big: Float64Array) -> BoolArray:
    """Which symmetric Gauss-Newton matrices ``big`` (n, k, k) are regular: the smallest
    eigenvalue above 1e-10 of the largest (else the subset's texture cannot fix all the
    parameters)."""
    eig = np.linalg.eigvalsh(big)
    return np.asarray(eig[:, 0] > 1e-10 * np.maximum(eig[:, -1], 1e-300))


def gauss_newton_matrix(
    jc: Float64Array, fh: Float64Array
) -> tuple[Float64Array, Float64Array, Float64Array]:
    """The exact ZNSSD Gauss-Newton matrix (module docstring) of the centred
    steepest-descent images ``jc`` (n, npx, k) and the normalised subsets ``fh`` (n, npx):
    ``a = J_c^T fh`` (n, k), the Gram matrix ``J_c^T J_c`` and ``Df^2 H = J_c^T J_c - a a^T``
    (n, k, k), GL^2."""
    # batched BLAS products (einsum's loops were 80 % of a one-off correlate call)
    jct = jc.transpose(0, 2, 1)
    avec = np.matmul(jct, fh[:, :, None])[:, :, 0]
    gram = np.matmul(jct, jc)
    return avec, gram, gram - avec[:, :, None] * avec[:, None, :]


def scaled_inverse(
    big: Float64Array, bad: BoolArray, safe: Float64Array
) -> tuple[Float64Array, Float64Array]:
    """``hinv = H^-1 = Df^2 (Df^2 H)^-1`` (0 where ``bad``) and ``(Df^2 H)^-1`` (the
    identity where ``bad``), each (n, k, k), from ``big = Df^2 H`` (n, k, k) and ``safe``
    (n,) ``Df`` (:class:`CentredSubsets`)."""
    big_inv = np.linalg.inv(np.where(bad[:, None, None], np.eye(big.shape[1])[None], big))
    hinv = big_inv * (safe**2)[:, None, None]
    hinv[bad] = 0.0
    return hinv, big_inv


def prepare_subsets(
    f: Float64Array,
    gx: Float64Array,
    gy: Float64Array,
    rows: IndexArray,
    cols: IndexArray,
    half: int,
    shape: str,
) -> PreparedSubsets:
    """Compute the per-subset quantities of IC-GN once for a reference image.

    Parameters
    ----------
    f, gx, gy : ndarray, shape (rows, cols)
        Reference grey levels and their x (column) and y (row) derivatives.
    rows, cols : ndarray of int, shape (n,)
        POI centres; every subset must lie inside the image.
    half : int
        Subset half-width (subset = 2 half + 1 px).
    shape : {"translation", "affine"}
        Shape function.
    """
    fp = _patches(f, rows, cols, half)
    gxp = _patches(gx, rows, cols, half)
    gyp = _patches(gy, rows, cols, half)
    n, npx = fp.shape
    fmean, fnorm, safe, fh, jsum, jc = centre_subsets(fp, raw_jacobian(gxp, gyp, half, shape))
    avec, _, big = gauss_newton_matrix(jc, fh)
    status = np.zeros(n, dtype=np.uint8)
    scale = np.maximum(np.abs(fp).max(axis=1), 1.0)
    flat = fnorm <= 1e-6 * scale * np.sqrt(npx)
    bad = flat | ~regular(big)
    status[bad] = PointStatus.LOW_TEXTURE
    hinv, big_inv = scaled_inverse(big, bad, safe)
    cov_unit = 2.0 * big_inv
    cov_unit[bad] = np.nan
    return PreparedSubsets(
        hinv=np.ascontiguousarray(hinv),
        jsum=np.ascontiguousarray(jsum),
        avec=np.ascontiguousarray(avec),
        fmean=fmean,
        fnorm=fnorm,
        status=status,
        cov_unit=cov_unit,
        sssig_x=np.einsum("ij,ij->i", gxp, gxp),
        sssig_y=np.einsum("ij,ij->i", gyp, gyp),
    )


def compose_affine(p: Float64Array, dp: Float64Array) -> Float64Array:
    """``W(p) o W(dp)^-1`` for affine parameters ``(u, ux, uy, v, vx, vy)``."""

    def mat(q: Float64Array) -> Float64Array:
        return np.array([[1 + q[1], q[2], q[0]], [q[4], 1 + q[5], q[3]], [0, 0, 1.0]])

    m = mat(p) @ np.linalg.inv(mat(dp))
    return np.array([m[0, 2], m[0, 0] - 1, m[0, 1], m[1, 2], m[1, 0], m[1, 1] - 1])


def icgn_reference(
    ref: Float64Array,
    gx: Float64Array,
    gy: Float64Array,
    coef: FloatArray,
    order: int,
    row: int,
    col: int,
    half: int,
    shape: str,
    p0: Float64Array,
    *,
    max_iterations: int = 50,
    tolerance: float = 1e-4,
    step_gain: bool = True,
) -> tuple[Float64Array, float, int, bool]:
    """Plain IC-GN for one POI (direct ZNSSD formulas, no precomputed sums): reference.

    Returns ``(p, zncc, iterations, converged)``; ``p`` as in the kernels (translation
    ``(u, v)``, affine ``(u, ux, uy, v, vx, vy)``), px. Stops as the kernels: the step norm
    below ``tolerance``, or, when the steps contract by ``q = |d| / |d_prev|``, the
    estimated error left ``|d| q / (1 - q)`` below it (below ``kernels.JUMP_SLACK`` x it
    when the step is an Aitken jump).
    ``step_gain=False`` takes plain Gauss-Newton steps and stops on the step norm only (no
    Aitken gain, see ``kernels.translation._aitken_gain``).
    """
    size = 2 * half + 1
    d = np.arange(size, dtype=np.float64) - half
    dy, dx = (a.ravel() for a in np.meshgrid(d, d, indexing="ij"))
    sl = (slice(row - half, row + half + 1), slice(col - half, col + half + 1))
    f = ref[sl].ravel()
    jr = raw_jacobian(gx[sl].ravel()[None], gy[sl].ravel()[None], half, shape)[0]
    fc = f - f.mean()
    fnorm = np.linalg.norm(fc)
    fh = fc / fnorm
    # exact derivative of the normalised reference subset fh w.r.t. the warp increment
    jc = jr - jr.mean(axis=0)
    jh = (jc - np.outer(fh, jc.T @ fh)) / fnorm
    hess = jh.T @ jh
    p = np.array(p0, dtype=np.float64)
    zncc = float("nan")
    prev = np.zeros(len(p))  # the last plain step (zero after a jump)
    best, ibest = np.inf, 0
    for it in range(max_iterations):
        if shape == "translation":
            xs, ys = col + dx + p[0], row + dy + p[1]
        else:
            xs = col + p[0] + (1 + p[1]) * dx + p[2] * dy
            ys = row + p[3] + p[4] * dx + (1 + p[5]) * dy
        g = interpolate_reference(coef, ys, xs, order)
        gc = g - g.mean()
        gh = gc / np.linalg.norm(gc)
        zncc = float(fh @ gh)
        dp = np.linalg.solve(hess, -jh.T @ (fh - gh))
        # the norm of the convergence test and the 6-vector of the step gain: (du, dv) for
        # translation, (du, h dux, h duy, dv, h dvx, h dvy) for affine
        sc = np.ones(2) if shape == "translation" else np.array([1.0, half, half, 1.0, half, half])
        norm = float(np.linalg.norm(dp * sc))
        # Aitken step gain, aligned contraction rho and step ratio q, as the compiled
        # kernels (kernels.translation._aitken_gain, kernels.affine._aitken_gain6)
        a, b = dp * sc, prev * sc
        pp, dot = float(b @ b), float(a @ b)
        ratio = float(np.sqrt(a @ a / pp)) if pp > 0 else 0.0
        rho = dot / pp if pp > 0 and dot > 0 and dot * dot > 0.9025 * float(a @ a) * pp else 0.0
        if not step_gain:
            rho = ratio = 0.0
        gain = 1.0
        if GAIN_MIN < rho < 0.97:
            gain, prev = 1.0 / (1.0 - rho), np.zeros_like(dp)
        else:
            prev = dp.copy()
        # the stop on the estimated error left (kernels.JUMP_SLACK): |d| q / (1 - q) below
        # the tolerance (JUMP_SLACK x it after an Aitken jump); an aligned step then jumps
        lim = tolerance * JUMP_SLACK if gain > 1.0 else tolerance
        linear = 0.0 < ratio < 0.97 and norm * ratio < lim * (1.0 - ratio)
        if linear and rho > 0:
            gain = 1.0 / (1.0 - rho)
        p = p - gain * dp if shape == "translation" else compose_affine(p, gain * dp)
        if norm < tolerance or linear:
            return p, zncc, it + 1, True
        # stall test, as the kernels (kernels.STALL_ITERATIONS)
        if norm < best:
            best, ibest = norm, it
        elif it - ibest >= STALL_ITERATIONS:
            return p, zncc, it + 1, False
    return p, zncc, max_iterations, False
