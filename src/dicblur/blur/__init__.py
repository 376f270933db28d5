"""Motion-blur synthesis: the paper's Algorithm 1, computed exactly with one FFT pair.

Lavatelli & Zappa (IEEE TIM 66(3), 2017, doi:10.1109/TIM.2016.2644898, Algorithm 1) make a
blurred image by shifting the image to K + 1 positions ``p_k`` along the motion with an
exact Fourier phase shift and averaging the shifted sub-frames. Averaging phase shifts is
one multiplication of the spectrum by the transfer function

    H(f) = sum_k w_k exp(-2 pi i f . p_k)        (w_k = 1 / (K + 1) for Algorithm 1)

so :func:`motion_blur` computes the same image with one ``rfft2``/``irfft2`` pair. For
linear motion ``p_k = k X / K`` the sum is a Dirichlet kernel with a closed form; in the
limit K -> infinity it becomes ``exp(-i pi f.X) sinc(f.X)``.

Conventions
-----------
- Positions and motion vectors are ``(dy, dx)`` px (rows, cols). A sub-frame at position
  ``p`` is the image *content moved by* ``+p``: ``out(y, x) = in(y - p_y, x - p_x)``.
- Nyquist bins of even-sized axes. A sub-pixel Fourier shift of the Nyquist component of
  a real image is not real. We use the symmetric band-limited interpolant: the Nyquist
  term is split evenly between +1/2 and -1/2 cycles/px, so its shift multiplier along that
  axis is ``cos(pi p)`` instead of ``exp(i pi p)``: the value at the pixels of the
  band-limited interpolant moved by ``p``. Every sub-frame is then real and integer shifts
  equal ``numpy.roll`` exactly. At the Nyquist bin no real-valued convention can make
  sub-pixel shifts compose (the sampled Nyquist component has one real degree of freedom;
  ``cos(pi a) cos(pi b) != cos(pi (a + b))``); elsewhere they compose exactly. Taking the
  real part of a complex inverse FFT (what a
  MATLAB transcription of Algorithm 1 does) gives the same image except at the corner bin
  (both axes at Nyquist), where it uses ``cos(pi (p_y + p_x))`` instead of
  ``cos(pi p_y) cos(pi p_x)``; for odd-sized images the two agree exactly.

See ``docs/blur.md`` for the derivations.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import fft as sfft

from ..checks import as_image, check_choice, check_finite_number, check_positive, describe
from ..errors import InputError

__all__ = [
    "AcceleratedMotion",
    "SineMotion",
    "blur_length",
    "blur_transfer",
    "motion_blur",
    "render_blurred",
    "trajectory_positions",
    "valid_region",
]

Boundary = Literal["periodic", "reflect"]
Method = Literal["fft", "loop"]
PathFunction = Callable[[NDArray[np.float64]], ArrayLike]

_TRAJECTORY_NAMES = ("linear", "sine", "acceleration")
# Composite Gauss-Legendre rule of the continuous limit for non-linear paths: nodes per
# segment, largest phase change per segment (rad), fewest segments (see docs/blur.md).
_GL_NODES = 24
_GL_PHASE_PER_SEGMENT = 8.0
_GL_MIN_SEGMENTS = 4


@dataclass(frozen=True)
class SineMotion:
    """Sinusoidal vibration during the exposure (a structure in modal testing).

    Position at normalised time ``t`` in [0, 1] (``t = 0`` opens the shutter)::

        p(t) = motion * sin(2 pi cycles t + phase)

    so ``motion`` (dy, dx) px is the amplitude vector and the reference (``p = 0``) is the
    equilibrium position.

    Attributes
    ----------
    cycles : float
        Vibration frequency times exposure time (cycles completed during the exposure).
    phase : float
        Phase at shutter opening, radians.
    """

    cycles: float = 1.0
    phase: float = 0.0

    def __post_init__(self) -> None:
        check_finite_number(self.cycles, "SineMotion.cycles")
        check_finite_number(self.phase, "SineMotion.phase")

    def positions(self, motion: NDArray[np.float64], t: NDArray[np.float64]) -> NDArray:
        """Positions (n, 2) px, (dy, dx), at normalised times ``t`` (n,)."""
        s = np.sin(2.0 * math.pi * self.cycles * t + self.phase)
        return s[:, None] * motion[None, :]


@dataclass(frozen=True)
class AcceleratedMotion:
    """Constant acceleration along ``motion`` during the exposure.

    ``p(t) = motion * (s t + (1 - s) t**2)``, t in [0, 1]: the path ends at ``motion``
    (travelled length ``W = |motion|``) and ``s`` is the speed at shutter opening relative
    to the mean speed (0: starts from rest; 1: uniform speed; 2: comes to rest at the end).

    Attributes
    ----------
    start_speed : float
        ``s`` in [0, 2] (outside, the target reverses during the exposure; allowed).
    """

    start_speed: float = 0.0

    def __post_init__(self) -> None:
        check_finite_number(self.start_speed, "AcceleratedMotion.start_speed")

    def positions(self, motion: NDArray[np.float64], t: NDArray[np.float64]) -> NDArray:
        """Positions (n, 2) px, (dy, dx), at normalised times ``t`` (n,)."""
        s = self.start_speed
        frac = s * t + (1.0 - s) * t * t
        return frac[:, None] * motion[None, :]


Trajectory = str | SineMotion | AcceleratedMotion | PathFunction | ArrayLike


# --------------------------------------------------------------------------- validation
def _check_motion(motion: Any) -> NDArray[np.float64]:
    try:
        arr = np.asarray(motion, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(
            f"motion={describe(motion)}: expected (dy, dx) in px, e.g. (0.0, 3.5)"
        ) from exc
    if arr.shape != (2,):
        raise InputError(f"motion={describe(motion)}: expected (dy, dx) in px, e.g. (0.0, 3.5)")
    if not np.isfinite(arr).all():
        raise InputError(f"motion={describe(motion)}: must be finite (no NaN or infinity)")
    return arr


def _check_substeps(substeps: Any) -> int | None:
    if substeps is None or (isinstance(substeps, str) and substeps == "continuous"):
        return None
    if isinstance(substeps, bool) or not isinstance(substeps, int | np.integer):
        raise InputError(
            f"substeps={describe(substeps)}: expected an integer >= 1 (the paper uses 100), "
            "or None / 'continuous' for the limit K -> infinity"
        )
    if substeps < 1:
        raise InputError(
            f"substeps={substeps}: must be >= 1 (K + 1 = substeps + 1 sub-frames; the paper "
            "uses 100), or None for the continuous limit"
        )
    return int(substeps)


def _check_path_array(path: Any) -> NDArray[np.float64]:
    try:
        arr = np.asarray(path, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(
            f"trajectory={describe(path)}: a sampled path must be an array of shape "
            "(K + 1, 2) with rows (dy, dx) px"
        ) from exc
    if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] < 1:
        raise InputError(
            f"trajectory={describe(arr)}: a sampled path must have shape (K + 1, 2) "
            "with rows (dy, dx) px"
        )
    if not np.isfinite(arr).all():
        raise InputError(f"trajectory={describe(arr)}: path positions must be finite")
    return arr


def _call_path(fn: PathFunction, t: NDArray[np.float64]) -> NDArray[np.float64]:
    out = np.asarray(fn(t), dtype=np.float64)
    if out.shape != (t.size, 2):
        raise InputError(
            f"trajectory: the callable returned {describe(out)} for t of shape {t.shape}; "
            "it must return positions of shape (len(t), 2) as (dy, dx) px"
        )
    if not np.isfinite(out).all():
        raise InputError("trajectory: the callable returned NaN or infinite positions")
    return out


def _classify(trajectory: Any, motion: Any) -> tuple[str, Any, NDArray[np.float64] | None]:
    """Return (kind, object, motion) with kind in linear|preset|array|callable."""
    if isinstance(trajectory, str):
        name = check_choice(trajectory, "trajectory", _TRAJECTORY_NAMES)
        vec = _check_motion(motion)
        if name == "linear":
            return "linear", None, vec
        preset = SineMotion() if name == "sine" else AcceleratedMotion()
        return "preset", preset, vec
    if isinstance(trajectory, SineMotion | AcceleratedMotion):
        return "preset", trajectory, _check_motion(motion)
    if callable(trajectory) or isinstance(trajectory, np.ndarray | list | tuple):
        if motion is not None:
            raise InputError(
                f"motion={describe(motion)}: an explicit path (array or callable trajectory) "
                "already gives the positions in px; pass motion=None"
            )
        if callable(trajectory):
            return "callable", trajectory, None
        return "array", _check_path_array(trajectory), None
    raise InputError(
        f"trajectory={describe(trajectory)}: unknown trajectory; use 'linear', 'sine', "
        "'acceleration', a SineMotion/AcceleratedMotion, an array (K + 1, 2) or a callable p(t)"
    )


def _composite_gauss_legendre(segments: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Nodes and weights on [0, 1]: ``segments`` equal pieces, each a Gauss-Legendre rule."""
    x, w = np.polynomial.legendre.leggauss(_GL_NODES)
    edges = np.arange(segments, dtype=np.float64)[:, None] / segments
    nodes = edges + 0.5 * (x[None, :] + 1.0) / segments
    weights = np.broadcast_to(0.5 * w[None, :] / segments, nodes.shape)
    return nodes.ravel(), weights.ravel().copy()


def _continuous_nodes(
    fn: Callable[[NDArray[np.float64]], NDArray[np.float64]],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Quadrature nodes/weights on [0, 1] able to resolve exp(-2 pi i f.p(t)).

    The phase changes by at most pi times the path's total variation (|f| <= 1/2 cycle/px
    per axis). Each segment of a composite 24-node Gauss-Legendre rule (exact for
    polynomials of degree 47) is given at most 8 rad of phase, where the rule reaches
    rounding accuracy for smooth paths.
    """
    fine = np.linspace(0.0, 1.0, 2049)
    p = fn(fine)
    variation = float(np.abs(np.diff(p, axis=0)).sum())
    segments = max(_GL_MIN_SEGMENTS, math.ceil(math.pi * variation / _GL_PHASE_PER_SEGMENT))
    return _composite_gauss_legendre(segments)


def trajectory_positions(
    motion: ArrayLike | None,
    *,
    substeps: int | None = 100,
    trajectory: Trajectory = "linear",
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Sub-frame positions and weights of a trajectory.

    Parameters
    ----------
    motion : array_like (dy, dx) px, or None
        Motion vector (None for an explicit path).
    substeps : int or None
        K; positions at ``t_k = k / K``, k = 0..K, equal weights ``1 / (K + 1)`` (the
        paper's Algorithm 1). None: composite Gauss-Legendre nodes of the continuous
        average (for ``"linear"`` too; :func:`motion_blur` uses the closed form there).
        Not used by array paths, whose rows are the sub-frames.
    trajectory : see :func:`motion_blur`

    Returns
    -------
    positions : ndarray, shape (n, 2)
        (dy, dx) px.
    weights : ndarray, shape (n,)
        Non-negative, summing to 1.
    """
    kind, obj, vec = _classify(trajectory, motion)
    k = _check_substeps(substeps)
    if kind == "array":  # the rows are the sub-frames: substeps is not used
        path = obj
        return path, np.full(path.shape[0], 1.0 / path.shape[0])

    def fn(t: NDArray[np.float64]) -> NDArray[np.float64]:
        if kind == "linear":
            assert vec is not None
            return t[:, None] * vec[None, :]
        if kind == "preset":
            assert vec is not None
            return np.asarray(obj.positions(vec, t), dtype=np.float64)
        return _call_path(obj, t)

    if k is None:
        t, w = _continuous_nodes(fn)
        return fn(t), w
    t = np.arange(k + 1, dtype=np.float64) / k
    return fn(t), np.full(k + 1, 1.0 / (k + 1))


# --------------------------------------------------------------------------- transfer
def _axis_factors(freqs: NDArray[np.float64], shifts: NDArray[np.float64], nyq: int | None):
    """exp(-2 pi i f p) for shifts (n,) x freqs (m,), Nyquist column -> cos(pi p)."""
    e = np.exp(-2j * math.pi * shifts[:, None] * freqs[None, :])
    if nyq is not None:
        e[:, nyq] = np.cos(math.pi * shifts)
    return e


def _grid(shape: tuple[int, int]) -> tuple[NDArray, NDArray, int | None, int | None]:
    n, m = shape
    fy = np.fft.fftfreq(n)
    fx = np.fft.rfftfreq(m)
    ny = n // 2 if n % 2 == 0 else None
    nx = fx.size - 1 if m % 2 == 0 else None
    return fy, fx, ny, nx


def _nyquist_lines(
    h: Callable[[NDArray, NDArray], NDArray],
    fy: NDArray[np.float64],
    fx: NDArray[np.float64],
    ny: int | None,
    nx: int | None,
) -> tuple[NDArray | None, NDArray | None]:
    """Nyquist row and column of the transfer function, split evenly over +-1/2.

    Averaging exp(-2 pi i f p) over f = +-1/2 gives cos(pi p): the symmetric Nyquist
    convention of the module docs, applied to a transfer function that is an average of
    exponentials (the average commutes with the split). The corner (both axes at Nyquist)
    averages the four sign combinations and is stored in both lines.
    """
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


def _symmetrise(
    h: Callable[[NDArray, NDArray], NDArray],
    fy: NDArray[np.float64],
    fx: NDArray[np.float64],
    ny: int | None,
    nx: int | None,
) -> NDArray[np.complex128]:
    """Evaluate h(fy, fx) on the rfft2 grid with the symmetric Nyquist convention."""
    H = np.asarray(h(fy[:, None], fx[None, :]), dtype=np.complex128)
    row, col = _nyquist_lines(h, fy, fx, ny, nx)
    if row is not None:
        H[ny, :] = row
    if col is not None:
        H[:, nx] = col
    return H


def _dirichlet(theta: NDArray[np.float64], k: int) -> NDArray[np.complex128]:
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
    fy, fx, ny, nx = _grid((rows, cols))
    kind, _, vec = _classify(trajectory, motion)
    k = _check_substeps(substeps)
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

        return _symmetrise(h, fy, fx, ny, nx)
    pos, w = trajectory_positions(motion, substeps=substeps, trajectory=trajectory)
    # H = sum_k w_k a_k(f_y) b_k(f_x): a weighted sum of outer products, i.e. one complex
    # matrix product (rows x n) @ (n x cols/2+1), with per-axis Nyquist factors cos(pi p).
    a = _axis_factors(fy, pos[:, 0], ny) * w[:, None]
    b = _axis_factors(fx, pos[:, 1], nx)
    return a.T @ b


# --------------------------------------------------------------------------- blur
def _mirror(img: NDArray[np.float64]) -> NDArray[np.float64]:
    """Even (half-sample symmetric) extension to 2x size: periodic and continuous."""
    top = np.concatenate([img, img[:, ::-1]], axis=1)
    return np.concatenate([top, top[::-1, :]], axis=0)


def _loop(img: NDArray[np.float64], pos: NDArray[np.float64], w: NDArray[np.float64]):
    """Literal Algorithm 1: complex FFT, one inverse FFT per sub-frame, weighted average."""
    n, m = img.shape
    spectrum = sfft.fft2(img)
    fy = np.fft.fftfreq(n)
    fx = np.fft.fftfreq(m)
    ny = n // 2 if n % 2 == 0 else None
    nx = m // 2 if m % 2 == 0 else None
    out = np.zeros_like(img)
    for (py, px), wk in zip(pos, w, strict=True):
        ey = np.exp(-2j * math.pi * fy * py)
        ex = np.exp(-2j * math.pi * fx * px)
        if ny is not None:
            ey[ny] = math.cos(math.pi * py)
        if nx is not None:
            ex[nx] = math.cos(math.pi * px)
        frame = sfft.ifft2(spectrum * np.outer(ey, ex))
        out += wk * frame.real
    return out


def motion_blur(
    image: ArrayLike,
    motion: ArrayLike | None,
    *,
    substeps: int | None = 100,
    trajectory: Trajectory = "linear",
    boundary: Boundary = "periodic",
    method: Method = "fft",
) -> NDArray[np.float64]:
    """Noise-free motion-blurred image (the paper's Algorithm 1 without its noise step).

    The image content travels along a path ``p(t)``, t in [0, 1], during the exposure; the
    output is the average of the image shifted (exact Fourier shift) to K + 1 positions
    ``p(k / K)``, k = 0..K, i.e. the image translated by the mean position (``motion / 2``
    for linear motion) and blurred along the path. Add noise afterwards with
    :func:`dicblur.add_gaussian_noise` or :class:`dicblur.Camera`.

    Parameters
    ----------
    image : array_like, shape (rows, cols)
        Sharp image, grey levels.
    motion : array_like (dy, dx), px, or None
        Motion vector: for ``"linear"`` and ``"acceleration"`` the displacement during the
        exposure (blur length ``W = hypot(dy, dx)``); for ``"sine"`` the amplitude vector.
        None for an explicit path (array or callable ``trajectory``).
    substeps : int >= 1, None or "continuous"
        K (the paper: 100). None or ``"continuous"``: the exact limit K -> infinity
        (``exp(-i pi f.X) sinc(f.X)`` for linear motion; Gauss-Legendre quadrature,
        accurate to rounding for smooth paths, otherwise). Ignored by array paths, whose
        rows are the sub-frames.
    trajectory : str, SineMotion, AcceleratedMotion, array (K + 1, 2) or callable
        ``"linear"`` (uniform velocity, the paper), ``"sine"`` (``SineMotion()``: one
        cycle, zero phase), ``"acceleration"`` (``AcceleratedMotion()``: from rest), a
        preset instance, an array of K + 1 positions (dy, dx) px (equal weights), or a
        callable ``p(t)`` taking t of shape (n,) in [0, 1] and returning (n, 2) px.
    boundary : {"periodic", "reflect"}
        ``"periodic"``: Fourier shifting wraps content across the edges, exactly the
        paper. ``"reflect"``: the image is extended by even mirroring to 2x its size
        (periodic and continuous, no seam), blurred and cropped; no wrap-around, but within
        the path's extent of each edge (see :func:`valid_region`) the output averages
        mirrored content, not the unseen scene.
    method : {"fft", "loop"}
        ``"fft"``: one rfft2/irfft2 pair and the transfer function (default; for linear
        motion with ``|dy| + |dx| <= K`` a compiled kernel fuses the Dirichlet kernel with
        the spectrum product).
        ``"loop"``: literal Algorithm 1 (one complex inverse FFT per sub-frame, averaged),
        for verification; needs a finite ``substeps``.

    Returns
    -------
    ndarray of float64, shape (rows, cols)

    Raises
    ------
    InputError
        Bad image (not 2-D, NaN), motion (NaN, wrong shape), substeps (< 1, not an
        integer), unknown trajectory, boundary or method.

    Examples
    --------
    >>> import numpy as np
    >>> img = np.random.default_rng(0).random((64, 64))
    >>> out = motion_blur(img, (0.0, 3.5))
    >>> ref = motion_blur(img, (0.0, 3.5), method="loop")
    >>> bool(np.allclose(out, ref, rtol=0, atol=1e-12))
    True
    """
    img = as_image(image, "image")
    check_choice(boundary, "boundary", ("periodic", "reflect"))
    check_choice(method, "method", ("fft", "loop"))
    work = _mirror(img) if boundary == "reflect" else img
    if method == "loop":
        if _check_substeps(substeps) is None and not _is_array_path(trajectory):
            raise InputError(
                "method='loop' needs a finite substeps (the literal Algorithm 1 averages "
                "K + 1 sub-frames); use method='fft' for substeps=None"
            )
        pos, w = trajectory_positions(motion, substeps=substeps, trajectory=trajectory)
        out = _loop(work, pos, w)
    else:
        spectrum = sfft.rfft2(work)
        product = _linear_fast(spectrum, work.shape, motion, substeps, trajectory)
        if product is None:
            H = blur_transfer(work.shape, motion, substeps=substeps, trajectory=trajectory)
            product = spectrum * H
        out = sfft.irfft2(product, s=work.shape, overwrite_x=True)
    if boundary == "reflect":
        out = out[: img.shape[0], : img.shape[1]]
    return np.ascontiguousarray(out)


def _linear_fast(
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
    k = _check_substeps(substeps)
    vec = _check_motion(motion)
    if k is None or abs(vec[0]) + abs(vec[1]) > k:
        return None
    from .kernels import apply_linear_dirichlet

    fy, fx, ny, nx = _grid(shape)
    dy, dx = float(vec[0]), float(vec[1])
    out = np.empty_like(spectrum)
    apply_linear_dirichlet(spectrum, math.pi * fy * dy / k, math.pi * fx * dx / k, k, out)

    def h(gy: NDArray, gx: NDArray) -> NDArray:
        return _dirichlet(2.0 * math.pi * (gy * dy + gx * dx) / k, k)

    row, col = _nyquist_lines(h, fy, fx, ny, nx)
    if row is not None:
        out[ny, :] = spectrum[ny, :] * row
    if col is not None:
        out[:, nx] = spectrum[:, nx] * col
    return out


def _is_array_path(trajectory: Any) -> bool:
    return isinstance(trajectory, np.ndarray | list | tuple) and not isinstance(trajectory, str)


def valid_region(
    shape: tuple[int, int],
    motion: ArrayLike | None,
    *,
    substeps: int | None = 100,
    trajectory: Trajectory = "linear",
    guard: int = 2,
) -> tuple[slice, slice]:
    """Rows and cols of a blurred image that only saw image content (no wrap, no mirror).

    Output pixel (y, x) averages input pixels (y - p_y, x - p_x) over the path; it is
    trustworthy when every such position lies inside the image. ``guard`` extra px per
    side absorb the decaying ringing of Fourier shifting near the edge (see
    ``docs/blur.md``). Meant for ``boundary="reflect"``; with ``"periodic"`` and an image
    that is not periodic, the wrapped seam rings through the whole output.

    Returns
    -------
    (slice, slice)
        Index as ``out[rows, cols]``; empty slices when the path is longer than the image.
    """
    rows, cols = (int(s) for s in shape)
    if isinstance(guard, bool) or not isinstance(guard, int | np.integer) or guard < 0:
        raise InputError(f"guard={describe(guard)}: expected an integer >= 0 (px)")
    pos, _ = trajectory_positions(motion, substeps=substeps, trajectory=trajectory)
    lo = np.ceil(np.maximum(pos.max(axis=0), 0.0)).astype(int) + guard
    hi = np.floor(np.minimum(pos.min(axis=0), 0.0)).astype(int) - guard
    r0, c0 = int(lo[0]), int(lo[1])
    r1, c1 = rows + int(hi[0]), cols + int(hi[1])
    return slice(r0, max(r0, r1)), slice(c0, max(c0, c1))


def blur_length(velocity: float, exposure: float, scale: float) -> float:
    """Blur length W (px) travelled during one exposure.

    ``W = |velocity| * exposure / scale``.

    Parameters
    ----------
    velocity : float
        Speed of the target in length units per second (e.g. mm/s).
    exposure : float
        Exposure time, s (>= 0).
    scale : float
        Object-space size of one pixel in the same length unit per px (e.g. mm/px), > 0.

    Returns
    -------
    float
        W in px.

    Examples
    --------
    >>> blur_length(100.0, 1e-3, 0.05)   # 100 mm/s, 1 ms, 0.05 mm/px
    2.0
    """
    v = abs(check_finite_number(velocity, "velocity"))
    t = check_positive(exposure, "exposure", allow_zero=True)
    s = check_positive(scale, "scale")
    return v * t / s


# --------------------------------------------------------------------------- rendering
def render_blurred(
    fine: ArrayLike,
    motion: ArrayLike | None,
    *,
    supersample: int,
    substeps: int | None = None,
    trajectory: Trajectory = "linear",
) -> NDArray[np.float64]:
    """Blurred camera image rendered without interpolation (unbiased reference).

    Fourier-shifted test images can make DIC look more accurate than it is (Reu, Exp.
    Mech. 51, 2011, doi:10.1007/s11340-010-9417-4; Bornert et al., Opt. Lasers Eng. 91,
    2017).
    Here a pattern drawn on a grid ``supersample`` times finer than the camera is moved
    along the path in *whole fine pixels* (``numpy.roll``, periodic), the sub-frames are
    averaged (integration over the exposure), and the result is binned to camera pixels
    (integration over each pixel's area). Positions are rounded to the nearest fine pixel,
    so the path is reproduced to within ``1 / (2 supersample)`` px.

    Parameters
    ----------
    fine : array_like, shape (rows * supersample, cols * supersample)
        Pattern on the fine grid, grey levels; periodic (e.g. ``speckle_pattern``).
    motion, trajectory : as :func:`motion_blur` (motion in camera px).
    supersample : int >= 1
        Fine pixels per camera pixel along each axis.
    substeps : int or None
        Sub-frames K (+1). None (default): one sub-frame per fine-pixel step along the
        path (``K = ceil(4 * supersample * path length)``), the discrete analogue of the
        continuous limit.

    Returns
    -------
    ndarray of float64, shape (rows, cols)
    """
    arr = as_image(fine, "fine")
    if isinstance(supersample, bool) or not isinstance(supersample, int | np.integer):
        raise InputError(f"supersample={describe(supersample)}: expected an integer >= 1")
    ss = int(supersample)
    if ss < 1:
        raise InputError(f"supersample={ss}: must be >= 1")
    if arr.shape[0] % ss or arr.shape[1] % ss:
        raise InputError(
            f"fine={describe(arr)}: each side must be a multiple of supersample={ss} "
            "(draw the pattern at (rows * supersample, cols * supersample))"
        )
    k = _check_substeps(substeps)
    if k is None and not _is_array_path(trajectory):
        # Path length measured on a fine sample of the trajectory.
        probe, _ = trajectory_positions(motion, substeps=1024, trajectory=trajectory)
        length = float(np.hypot(*np.diff(probe, axis=0).T).sum())
        k = max(1, math.ceil(4 * ss * length))
    pos, w = trajectory_positions(motion, substeps=k, trajectory=trajectory)
    steps = np.rint(pos * ss).astype(np.int64)
    acc = np.zeros_like(arr)
    # Equal positions repeat: accumulate each distinct shift once with its total weight.
    uniq, inverse = np.unique(steps, axis=0, return_inverse=True)
    weights = np.bincount(inverse.ravel(), weights=w, minlength=uniq.shape[0])
    for (sy, sx), wk in zip(uniq, weights, strict=True):
        acc += wk * np.roll(arr, (int(sy), int(sx)), axis=(0, 1))
    rows, cols = arr.shape[0] // ss, arr.shape[1] // ss
    return acc.reshape(rows, ss, cols, ss).mean(axis=(1, 3))
