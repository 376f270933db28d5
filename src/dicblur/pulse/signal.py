"""The periodic rectangular pulse train of the paper's Section V and its box-blurred version.

Lavatelli & Zappa, IEEE TIM 66(3), 2017, doi:10.1109/TIM.2016.2644898, Section V, Fig. 3-4
and Table II. The seed's equations are garbled by text extraction; the closed forms below are
our derivation (``docs/pulse.md``, "Regimes and closed forms"), checked against numerical
convolution in ``tests/test_pulse.py``.

Geometry (1-D, x in px): pulses of height ``a`` (grey levels) and width ``dp`` repeat with
period ``du``; the gap is ``g = du - dp``. The first pulse occupies ``[x0, x0 + dp)``. The
default ``x0 = -0.5`` puts the edges on pixel boundaries, so with pixel centres at integer x
the pixel-integrated (w = 1) signal is exactly 0 or ``a`` at every pixel.

Blur is a centred moving average (box) of width ``w = 1 + W`` px, where 1 is the pixel's own
integration and W the motion during the exposure (paper eq. 8). With ``P`` the antiderivative
of the pulse train, the blurred signal is exactly ``p_b(x) = (P(x + w/2) - P(x - w/2)) / w``
and its derivative ``(p(x + w/2) - p(x - w/2)) / w`` takes only the values ``0, +-a/w``.

Closed forms (per period unless stated; ``m(w)`` is the length, per period, over which the
blurred gradient is ``+a/w``, equal to the cross-correlation of the pulse and gap indicators):

- ``m(w) = min(s, dp, g, du - s)`` with ``s = w mod du`` (for ``0 <= w <= du`` this is
  ``min(w, dp, g, du - w)``);
- MIG ``= 2 a m / (w du)``; mean gradient ``= 0``; gradient variance ``= 2 a^2 m / (w^2 du)``;
- contrast (max - min) ``= a m / w``;
- SSSIG of N periods (sum over pixels of unit size) ``= 2 N a^2 m / w^2``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from ..arrays import Float64Array
from ..checks import as_whole, check_finite_number, check_positive, describe
from ..errors import InputError

__all__ = [
    "REGIMES",
    "PulseMetrics",
    "PulseTrain",
    "closed_form_metrics",
    "edge_length",
    "numeric_metrics",
    "pixel_metrics",
    "regime",
    "spectral_derivative",
]

Regime = Literal["a", "b", "c", "d", "e", "none"]

#: Regime labels: the four branches of ``m(w)`` (paper Fig. 4 / Table II) plus ``e`` for
#: windows longer than a period (``w >= du``: contrast reversal, see :func:`regime`).
REGIMES: dict[str, str] = {
    "a": "w < dp and w < g: edges soften, contrast and MIG unchanged (m = w)",
    "b": "dp <= w < g: contrast loss, pulses do not merge (m = dp)",
    "c": "w >= dp and w >= g (w < du): neighbouring pulses merge (m = du - w)",
    "d": "g <= w < dp: dense pattern, edges and contrast lost together (m = g)",
    "e": "w >= du: the window spans a whole period; the pattern reappears shifted by du/2",
    "none": "w = 0: no blur",
}


@dataclass(frozen=True)
class PulseTrain:
    """A periodic train of rectangular pulses (paper Fig. 3).

    Parameters
    ----------
    a : float
        Pulse height, grey levels (> 0).
    dp : float
        Pulse width, px (0 < dp < du).
    du : float
        Period (centre-to-centre spacing), px.
    x0 : float
        Position of the first pulse's left edge, px. The default -0.5 puts edges on pixel
        boundaries (pixel centres at integer x).
    """

    a: float = 1.0
    dp: float = 6.0
    du: float = 22.0
    x0: float = -0.5

    def __post_init__(self) -> None:
        check_positive(self.a, "a")
        check_positive(self.dp, "dp")
        check_positive(self.du, "du")
        check_finite_number(self.x0, "x0")
        if not self.dp < self.du:
            raise InputError(
                f"dp={self.dp!r}, du={self.du!r}: the pulse width must be smaller than the "
                "period (dp < du), otherwise the signal is constant"
            )

    @property
    def g(self) -> float:
        """Gap between pulses, ``du - dp`` (px)."""
        return self.du - self.dp

    # -- signal ---------------------------------------------------------------------------
    def antiderivative(self, x: ArrayLike) -> Float64Array:
        """``P(x) = integral from x0 to x of p``, exact (grey levels x px)."""
        t = np.asarray(x, dtype=np.float64) - self.x0
        k = np.floor(t / self.du)
        r = t - k * self.du
        return self.a * (k * self.dp + np.clip(r, 0.0, self.dp))

    def value(self, x: ArrayLike) -> Float64Array:
        """The sharp (unblurred, continuous) signal ``p(x)``: ``a`` inside pulses, else 0."""
        t = np.mod(np.asarray(x, dtype=np.float64) - self.x0, self.du)
        return np.where(t < self.dp, self.a, 0.0)

    def blurred(self, x: ArrayLike, w: float) -> Float64Array:
        """Box-blurred signal ``p_b(x, w)``, exact at any x (closed form).

        Parameters
        ----------
        x : array_like
            Positions, px.
        w : float
            Box width, px (``w = 1 + W``). ``w = 0`` returns the sharp signal.

        Returns
        -------
        ndarray, same shape as ``x``
            Grey levels.
        """
        w = check_width(w)
        x = np.asarray(x, dtype=np.float64)
        if w == 0.0:
            return self.value(x)
        return (self.antiderivative(x + w / 2) - self.antiderivative(x - w / 2)) / w

    def blurred_gradient(self, x: ArrayLike, w: float) -> Float64Array:
        """Exact derivative ``d p_b / dx`` (grey levels / px), values in {0, +a/w, -a/w}.

        At a kink the right-hand derivative is returned (pulses are closed on the left).
        """
        w = check_width(w)
        if w == 0.0:
            raise InputError("w=0: the sharp pulse train has no finite gradient; use w > 0")
        x = np.asarray(x, dtype=np.float64)
        return (self.value(x + w / 2) - self.value(x - w / 2)) / w

    def breakpoints(self, w: float) -> Float64Array:
        """Kinks of ``p_b(., w)`` in one period ``[0, du)`` (edges of the sharp pulse if w = 0)."""
        w = check_width(w)
        edges = np.array([self.x0, self.x0 + self.dp])
        pts = edges if w == 0.0 else np.concatenate([edges - w / 2, edges + w / 2])
        return np.unique(np.mod(pts, self.du))

    def sample(self, n: int, w: float, *, shift: float = 0.0) -> Float64Array:
        """The blurred signal at pixel centres ``x = 0, 1, ..., n - 1``, displaced by ``shift``.

        Returns ``p_b(k - shift, w)``, shape (n,), grey levels: pixel values of a camera whose
        pixel integration (1 px) is part of ``w`` (so ``w = 1`` is the sharp, pixel-integrated
        image).
        """
        if not isinstance(n, int | np.integer) or n < 1:
            raise InputError(f"n={describe(n)}: the number of pixels must be a positive int")
        shift = check_finite_number(shift, "shift")
        return self.blurred(np.arange(int(n), dtype=np.float64) - shift, w)


def check_width(w: float, name: str = "w") -> float:
    """One blur window width ``w`` (px) as a float; InputError unless finite and >= 0."""
    value = check_finite_number(w, name)
    if value < 0:
        raise InputError(f"{name}={w!r}: the blur window width must be >= 0 px (w = 1 + W)")
    return value


def as_widths(w: ArrayLike, name: str = "w") -> Float64Array:
    """Blur window widths ``w`` (px) as a float array; InputError unless finite and > 0."""
    arr = np.asarray(w, dtype=np.float64)
    if arr.size == 0 or not np.all(np.isfinite(arr)) or np.any(arr <= 0):
        raise InputError(f"{name}={describe(w)}: blur widths must be finite and > 0 px")
    return arr


def edge_length(train: PulseTrain, w: ArrayLike) -> Float64Array:
    """``m(w)``: length per period (px) on which the blurred gradient is ``+a/w``.

    ``m(w) = min(s, dp, g, du - s)``, ``s = w mod du``: the circular cross-correlation, at
    lag w, of the pulse indicator (length dp) and the gap indicator (length g).
    """
    s = np.mod(np.asarray(w, dtype=np.float64), train.du)
    return np.minimum.reduce([s, np.full_like(s, train.dp), np.full_like(s, train.g), train.du - s])


def regime(train: PulseTrain, w: float) -> Regime:
    """Regime of width ``w`` (paper Fig. 4 / Table II cases a-d; ``e`` for ``w >= du``).

    (a) ``w < dp, w < g``; (b) ``dp <= w < g``; (c) ``w >= dp, w >= g``; (d) ``g <= w < dp``;
    (e) ``w >= du``: the window holds a whole period plus ``w - du``; the blurred signal is
    then the ``(w - du)``-blurred one shifted by half a period (contrast reversal) and scaled.
    """
    w = check_width(w)
    if w == 0:
        return "none"
    if w >= train.du:
        return "e"
    if w < train.dp:
        return "a" if w < train.g else "d"
    return "b" if w < train.g else "c"


@dataclass(frozen=True)
class PulseMetrics:
    """Metrics of the blurred pulse train for a subset of ``n_periods`` periods.

    All arrays have the shape of ``w``. Units: ``mig`` grey levels/px, ``gradient_variance``
    (grey levels/px)^2, ``contrast`` grey levels, ``sssig`` (grey levels/px)^2 summed over
    ``n_periods * du`` unit pixels, ``m`` px.
    """

    w: Float64Array
    m: Float64Array
    mig: Float64Array
    gradient_mean: Float64Array
    gradient_variance: Float64Array
    contrast: Float64Array
    sssig: Float64Array
    n_periods: float
    method: str

    def to_dict(self) -> dict[str, list[float]]:
        """Plain-Python lists, for JSON."""
        keys = ("w", "m", "mig", "gradient_mean", "gradient_variance", "contrast", "sssig")
        return {k: np.atleast_1d(getattr(self, k)).tolist() for k in keys}


def closed_form_metrics(train: PulseTrain, w: ArrayLike, *, n_periods: float = 1.0) -> PulseMetrics:
    """Closed-form MIG, gradient variance, contrast and SSSIG of the blurred train (Table II).

    Parameters
    ----------
    train : PulseTrain
    w : array_like
        Box widths, px (> 0).
    n_periods : float
        Number of periods in the subset (the paper's N).
    """
    wa = as_widths(w)
    n_periods = check_positive(n_periods, "n_periods")
    m = edge_length(train, wa)
    a, du = train.a, train.du
    return PulseMetrics(
        w=wa,
        m=m,
        mig=2 * a * m / (wa * du),
        gradient_mean=np.zeros_like(wa),
        gradient_variance=2 * a**2 * m / (wa**2 * du),
        contrast=a * m / wa,
        sssig=2 * n_periods * a**2 * m / wa**2,
        n_periods=n_periods,
        method="closed form",
    )


def _gradient_stats(f: Float64Array, d: Float64Array) -> tuple[float, float, float, float, float]:
    """``(mean |d|, mean d, var d, max f - min f, sum d**2)`` of samples ``f`` of one
    signal and their derivative ``d``: MIG, gradient mean and variance, contrast, and
    the SSSIG sum before its scaling to the window."""
    mean = float(d.mean())
    return (
        float(np.mean(np.abs(d))),
        mean,
        float(np.mean((d - mean) ** 2)),
        float(f.max() - f.min()),
        float(np.sum(d**2)),
    )


def _pulse_metrics(
    wa: Float64Array, out: Float64Array, n_periods: float, method: str
) -> PulseMetrics:
    """:class:`PulseMetrics` from the rows of ``out`` (shape (5, n): the metrics of
    :func:`_gradient_stats`, the SSSIG scaled) at the widths ``wa``."""
    return PulseMetrics(
        w=wa,
        m=np.full(wa.shape, np.nan),
        mig=out[0],
        gradient_mean=out[1],
        gradient_variance=out[2],
        contrast=out[3],
        sssig=out[4],
        n_periods=n_periods,
        method=method,
    )


def numeric_metrics(
    train: PulseTrain, w: ArrayLike, *, n_periods: float = 1.0, supersample: int = 64
) -> PulseMetrics:
    """The same metrics by numerical convolution of a finely sampled pulse train.

    The sharp train is sampled on cells of ``h = 1 / supersample`` px (cell values taken at
    cell centres, independent of the closed form), convolved circularly with a box whose
    weights are the exact overlaps of ``[-w/2, w/2]`` with each cell, and differentiated by
    forward differences. Nodes are placed so that ``x +- w/2`` fall on cell boundaries.
    When ``x0, dp, du`` and ``w`` are multiples of ``h``, every kink of the blurred signal is
    a node and the result equals the continuous limit to round-off; otherwise the error is
    O(h) (kinks inside a cell).

    Parameters
    ----------
    train, w, n_periods
        As for :func:`closed_form_metrics`.
    supersample : int
        Cells per px (``du * supersample`` must be an integer).
    """
    wa = np.atleast_1d(as_widths(w))
    n_periods = check_positive(n_periods, "n_periods")
    if not isinstance(supersample, int | np.integer) or supersample < 1:
        raise InputError(f"supersample={describe(supersample)}: expected an int >= 1")
    h = 1.0 / supersample
    n = as_whole(
        train.du * supersample,
        f"supersample={supersample}: du * supersample = {train.du * supersample:g} must be an "
        "integer; choose supersample so that the period is a whole number of cells",
    )
    out = np.empty((5, wa.size))
    for i, wi in enumerate(wa):
        # Nodes at x_j = x0 + w/2 + j h: the window [x_j - w/2, x_j + w/2] starts at a cell
        # boundary; cells c_i = [x0 + i h, x0 + (i + 1) h].
        cells = train.value(train.x0 + (np.arange(n) + 0.5) * h)
        nfull = int(np.floor(wi / h + 1e-9))
        frac = wi / h - nfull
        kernel = np.ones(nfull + (1 if frac > 1e-9 else 0))
        if frac > 1e-9:
            kernel[-1] = frac
        kernel *= h / wi
        # b_j = sum_i kernel[i] * cells[j + i] (circular): FFT correlation.
        kfull = np.zeros(n)
        idx = np.arange(kernel.size) % n
        np.add.at(kfull, idx, kernel)
        b = np.fft.irfft(np.fft.rfft(cells) * np.conj(np.fft.rfft(kfull)), n)
        d = (np.roll(b, -1) - b) / h  # forward differences over one period (circular)
        stats = _gradient_stats(b, d)
        out[:, i] = (*stats[:4], float(n_periods * stats[4] * h))
    return _pulse_metrics(wa, out, n_periods, f"numerical convolution, h = 1/{supersample} px")


def pixel_metrics(
    train: PulseTrain,
    w: ArrayLike,
    *,
    n_periods: int = 1,
    gradient: Literal["forward", "central", "spectral"] = "forward",
) -> PulseMetrics:
    """Metrics from the signal sampled at pixel centres (h = 1 px), as an image sees it.

    ``forward``: ``f[k+1] - f[k]`` (the derivative averaged over one pixel);
    ``central``: ``(f[k+1] - f[k-1]) / 2`` (as ``numpy.gradient``); ``spectral``: the
    derivative of the band-limited (Fourier) interpolant, the one seen by a Fourier-shift
    correlator. These depart from the continuous closed forms; see ``docs/pulse.md``.
    """
    wa = np.atleast_1d(as_widths(w))
    if not isinstance(n_periods, int | np.integer) or n_periods < 1:
        raise InputError(f"n_periods={describe(n_periods)}: expected an int >= 1")
    n = train.du * n_periods
    if abs(n - round(n)) > 1e-9:
        raise InputError(f"du={train.du!r}: du * n_periods must be a whole number of pixels")
    n = round(n)
    out = np.empty((5, wa.size))
    for i, wi in enumerate(wa):
        f = train.sample(n, float(wi))
        if gradient == "forward":
            d = np.roll(f, -1) - f
        elif gradient == "central":
            d = (np.roll(f, -1) - np.roll(f, 1)) / 2
        elif gradient == "spectral":
            d = spectral_derivative(f)
        else:
            raise InputError(f"gradient={gradient!r}: choose 'forward', 'central' or 'spectral'")
        out[:, i] = _gradient_stats(f, d)
    return _pulse_metrics(wa, out, float(n_periods), f"pixel samples, {gradient} differences")


def spectral_derivative(f: Float64Array) -> Float64Array:
    """Derivative (per px) of the band-limited periodic interpolant of the last axis of ``f``.

    The Nyquist bin (even length) is dropped: the derivative of the real interpolant's
    ``cos(pi x)`` term vanishes at the samples.
    """
    n = f.shape[-1]
    freqs = np.fft.rfftfreq(n)
    k = 2j * math.pi * freqs
    if n % 2 == 0:
        k[-1] = 0.0
    return np.fft.irfft(np.fft.rfft(f, axis=-1) * k, n, axis=-1)
