"""Transfer functions of the blur on the ``rfft2`` grid: ``H(f) = sum_k w_k exp(-2 pi i
f . p_k)`` with the symmetric Nyquist convention of :mod:`dicblur.blur`, in closed form for
linear motion (a Dirichlet kernel, its sinc limit) and as one matrix product otherwise."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..arrays import Float64Array
from .trajectory import Trajectory, check_motion, check_substeps, classify, trajectory_positions

__all__ = ["blur_transfer", "transfer_product"]


def _axis_factors(freqs: Float64Array, shifts: Float64Array, nyq: int | None):
    """exp(-2 pi i f p) for shifts (n,) x freqs (m,), Nyquist column -> cos(pi p)."""
    e = np.exp(-2j * math.pi * shifts[:, None] * freqs[None, :])
    if nyq is not None:
        e[:, nyq] = np.cos(math.pi * shifts)
    return e


class _Grid(NamedTuple):
    """The ``rfft2`` frequency grid of an image: row and column frequencies (cycles/px)
    and the index of each axis's Nyquist bin (``None`` for an odd-sized axis)."""

    fy: NDArray
    fx: NDArray
    ny: int | None
    nx: int | None


def _grid(shape: tuple[int, int]) -> _Grid:
    n, m = shape
    fy = np.fft.fftfreq(n)
    fx = np.fft.rfftfreq(m)
    ny = n // 2 if n % 2 == 0 else None
    nx = fx.size - 1 if m % 2 == 0 else None
    return _Grid(fy, fx, ny, nx)


def _nyquist_lines(
    h: Callable[[NDArray, NDArray], NDArray], grid: _Grid
) -> tuple[NDArray | None, NDArray | None]:
    """Nyquist row and column of the transfer function, split evenly over +-1/2.

    Averaging exp(-2 pi i f p) over f = +-1/2 gives cos(pi p): the symmetric Nyquist
    convention of the module docs, applied to a transfer function that is an average of
    exponentials (the average commutes with the split). The corner (both axes at Nyquist)
    averages the four sign combinations and is stored in both lines.
    """
    fy, fx, ny, nx = grid
    half = np.array([[0.5]])
    row = col = None
    if ny is not None:
        row = 0.5 * (h(-half, fx[None, :]) + h(half, fx[None, :]))[0]
    if nx is not None:
        col = 0.5 * (h(fy[:, None], half) + h(fy[:, None], -half))[:, 0]
    if row is not None and col is not None:
        corner = 0.25 * sum(
            complex(h(sy * half, sx * half)[0, 0]) for sy in (-1, 1) for sx in (-1, 1)
        )
        row[-1] = corner
        col[ny] = corner
    return row, col


def _symmetrise(h: Callable[[NDArray, NDArray], NDArray], grid: _Grid) -> NDArray[np.complex128]:
    """Evaluate h(fy, fx) on the rfft2 grid with the symmetric Nyquist convention."""
    H = np.asarray(h(grid.fy[:, None], grid.fx[None, :]), dtype=np.complex128)
    row, col = _nyquist_lines(h, grid)
    if row is not None:
        H[grid.ny, :] = row
    if col is not None:
        H[:, grid.nx] = col
    return H


def _dirichlet(theta: Float64Array, k: int) -> NDArray[np.complex128]:
    """mean_{j=0..K} exp(-i j theta), accurate near every pole of the closed form.

    Closed form exp(-i K theta/2) sin((K+1) theta/2) / ((K+1) sin(theta/2)), which is
    periodic in theta/2 with period pi; reducing theta/2 to r in [-pi/2, pi/2] first keeps
    sin(r) accurate where sin(theta/2) is near zero.
    """
    half = 0.5 * theta
    r = half - np.round(half / math.pi) * math.pi
    s = np.sin(r)
    zero = s == 0.0
    ratio = np.sin((k + 1) * r) / ((k + 1) * np.where(zero, 1.0, s))
    ratio = np.where(zero, 1.0, ratio)
    return np.exp(-1j * k * r) * ratio


def blur_transfer(
    shape: tuple[int, int],
    motion: ArrayLike | None,
    *,
    substeps: int | None = 100,
    trajectory: Trajectory = "linear",
) -> NDArray[np.complex128]:
    """Transfer function of the blur on the ``rfft2`` grid of an image of ``shape``.

    ``H = sum_k w_k exp(-2 pi i (f_y p_k,y + f_x p_k,x))`` with the symmetric Nyquist
    convention (module docs); frequencies in cycles/px from ``numpy.fft.fftfreq`` (rows)
    and ``numpy.fft.rfftfreq`` (cols).

    Returns
    -------
    ndarray of complex128, shape (rows, cols // 2 + 1)
    """
    rows, cols = (int(s) for s in shape)
    grid = _grid((rows, cols))
    kind, _, vec = classify(trajectory, motion)
    k = check_substeps(substeps)
    if kind == "linear":
        assert vec is not None
        dy, dx = float(vec[0]), float(vec[1])
        if k is None:

            def h(gy: NDArray, gx: NDArray) -> NDArray:
                phi = gy * dy + gx * dx
                return np.exp(-1j * math.pi * phi) * np.sinc(phi)

        else:
            kk = k

            def h(gy: NDArray, gx: NDArray) -> NDArray:
                return _dirichlet(2.0 * math.pi * (gy * dy + gx * dx) / kk, kk)

        return _symmetrise(h, grid)
    pos, w = trajectory_positions(motion, substeps=substeps, trajectory=trajectory)
    # H = sum_k w_k a_k(f_y) b_k(f_x): a weighted sum of outer products, i.e. one complex
    # matrix product (rows x n) @ (n x cols/2+1), with per-axis Nyquist factors cos(pi p).
    a = _axis_factors(grid.fy, pos[:, 0], grid.ny) * w[:, None]
    b = _axis_factors(grid.fx, pos[:, 1], grid.nx)
    return a.T @ b


def transfer_product(
    spectrum: NDArray[np.complex128],
    shape: tuple[int, int],
    motion: ArrayLike | None,
    *,
    substeps: int | None = 100,
    trajectory: Trajectory = "linear",
) -> NDArray[np.complex128]:
    """``spectrum * H``: the ``rfft2`` spectrum of an image of ``shape`` times the blur's
    transfer function (:func:`blur_transfer`), fused in a compiled kernel for linear
    motion with ``|dy| + |dx| <= K``."""
    product = _linear_product(spectrum, shape, motion, substeps, trajectory)
    if product is None:
        product = spectrum * blur_transfer(shape, motion, substeps=substeps, trajectory=trajectory)
    return product


def _linear_product(
    spectrum: NDArray[np.complex128],
    shape: tuple[int, int],
    motion: Any,
    substeps: Any,
    trajectory: Any,
) -> NDArray[np.complex128] | None:
    """spectrum * H for linear motion with the compiled kernel, or None if not applicable.

    Applies when the trajectory is ``"linear"``, K is finite and ``|dy| + |dx| <= K`` (then
    ``|r| <= pi / 2`` on the whole grid and the kernel needs no range reduction).
    """
    if not (isinstance(trajectory, str) and trajectory == "linear"):
        return None
    k = check_substeps(substeps)
    vec = check_motion(motion)
    if k is None or abs(vec[0]) + abs(vec[1]) > k:
        return None
    from .kernels import apply_linear_dirichlet

    grid = _grid(shape)
    fy, fx, ny, nx = grid
    dy, dx = float(vec[0]), float(vec[1])
    out = np.empty_like(spectrum)
    apply_linear_dirichlet(spectrum, math.pi * fy * dy / k, math.pi * fx * dx / k, k, out)

    def h(gy: NDArray, gx: NDArray) -> NDArray:
        return _dirichlet(2.0 * math.pi * (gy * dy + gx * dx) / k, k)

    row, col = _nyquist_lines(h, grid)
    if row is not None:
        out[ny, :] = spectrum[ny, :] * row
    if col is not None:
        out[:, nx] = spectrum[:, nx] * col
    return out
