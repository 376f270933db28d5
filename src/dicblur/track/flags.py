"""Per-frame gross-error flags of :func:`dicblur.track.track`: a ZNCC far below the point's
usual (:func:`zncc_flags`), the normalised median test's critical values per frame, and
the blocks of frames the post-processing runs on its threads.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..arrays import BoolArray, Float32Array, Float64Array, FloatArray, IndexArray
from ..threads import each
from .median import median_critical_eps

#: False-alarm rate per correct point of the normalised median test at the point's own
#: predicted sigma (:func:`own_sigma_eps`).
FALSE_ALARM = 1e-4
#: ``k`` of :func:`own_sigma_eps` at false-alarm rates 1e-2, 1e-3, 1e-4 (threshold 2): the
#: ``1 - rate / 2`` quantile of ``|x_0 - m| / 2 - r_m`` with ``x_0 .. x_8`` independent
#: N(0, 1), ``m`` the median of the 8 neighbours and ``r_m`` the median of their
#: ``|x_i - m|`` (seeded Monte Carlo of 1e7 draws; tests/test_track_flags.py checks it).
_K_RATES = np.array([1e-2, 1e-3, 1e-4])
_K_VALUES = np.array([1.044, 1.434, 1.751])


def own_sigma_eps(
    sigma: FloatArray | float,
    threshold: float,
    *,
    false_alarm: float = FALSE_ALARM,
) -> Float64Array:
    """``eps`` (px) of the normalised median test at which a correct point whose predicted
    random error is ``sigma`` (px, any shape) is flagged with probability ``false_alarm``.

    The test flags ``|u_0 - u_m| > threshold (r_m + eps)`` on either component. For a
    correct point among 8 neighbours of the same scatter ``s`` (independent normal
    errors), ``|u_0 - u_m| / threshold - r_m`` in units of ``s`` has a fixed distribution;
    its ``1 - false_alarm / 2`` quantile ``k`` (two components) gives ``eps = k s``
    (k = 1.75 at 1e-4 and the threshold 2; tabulated, interpolated in log rate, for the
    threshold 2; another threshold scales ``k`` by ``2 / threshold``, exact for the
    ``|u_0 - u_m|`` part). ``s`` is the point's own sigma, so a poorly textured or
    strongly blurred subset (a large predicted error, noise or blur-mismatch part) is
    held to its own range, not to the frame's median point.
    """
    lr = math.log10(min(max(false_alarm, 1e-4), 1e-2))
    k = float(np.interp(-lr, -np.log10(_K_RATES), _K_VALUES)) * 2.0 / threshold
    return np.asarray(k * np.asarray(sigma, np.float64))


#: A converged point whose ``1 - ZNCC`` exceeds this multiple of its usual value (its
#: frame's median, scaled by the point's own median ratio over the recording) is flagged.
ZNCC_RATIO = 4.0


def nanmedian_last(x: NDArray[Any], *, overwrite: bool = False) -> NDArray[Any]:
    """``np.nanmedian(x, axis=-1)``, the same numbers and dtype (NaN where a row has no
    value, without the warning): one vectorised sort of the rows (NaN sorts last) instead
    of a partition per row (thousands of Python-level calls on a (frames, points) array).
    ``overwrite``: sort ``x`` itself (a temporary of the caller: no sorted copy).
    """
    n = x.shape[-1] - np.count_nonzero(np.isnan(x), axis=-1)
    if overwrite:
        x.sort(axis=-1)
        s = x
    else:
        s = np.sort(x, axis=-1)
    lo = np.take_along_axis(s, np.maximum((n - 1) // 2, 0)[..., None], axis=-1)[..., 0]
    hi = np.take_along_axis(s, (n // 2)[..., None], axis=-1)[..., 0] if s.shape[-1] else lo
    with np.errstate(invalid="ignore", over="ignore"):
        # np.median: the middle value, or the mean of the two middle ones in x's dtype
        mid = np.where(n % 2 == 1, lo, (lo + hi) / 2)
    return np.where(n > 0, mid, np.nan).astype(x.dtype, copy=False)


def frame_filled(x: FloatArray, use: BoolArray) -> FloatArray:
    """``x`` (frames, points) with its NaN replaced by the frame's median of the finite
    values at the points ``use`` (NaN where a frame has none)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        med = nanmedian_last(np.where(use, x, np.nan))
    return np.where(np.isnan(x), med[:, None].astype(x.dtype), x)


#: A frame whose converged share of its correlatable points is below this sets no median
#: of its own for :func:`zncc_flags` (its few converged points are the ones to test).
RELIABLE_SHARE = 0.5


def zncc_flags(
    zncc: FloatArray,
    converged: BoolArray,
    *,
    ratio: float = ZNCC_RATIO,
    correlatable: BoolArray | None = None,
) -> BoolArray:
    """Converged points whose match is much worse than usual (frames, points).

    ``q = 1 - ZNCC`` grows with the noise and the blur of a frame and with how little
    texture a subset has; dividing by the frame's median ``q`` removes the first, by the
    point's median of that ratio over the recording the second. A foreign texture in the
    subset (debris, glare, a false convergence) leaves the ratio far above 1.

    With ``correlatable`` (frames, points: the points that can be correlated there, not
    out of bounds nor textureless), a frame where fewer than :data:`RELIABLE_SHARE` of
    them converge (a frame of another scene, a flash) takes the largest median of the
    other frames instead of its own: its own is that of the few false convergences
    themselves, which then passed (up to 20 px off, one of them valid).
    """
    q = np.where(converged, 1.0 - zncc, np.nan)
    with warnings.catch_warnings(), np.errstate(invalid="ignore", divide="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)
        med_f = nanmedian_last(q)[:, None]
        if correlatable is not None:
            share = converged.sum(axis=1) / np.maximum(correlatable.sum(axis=1), 1)
            reliable = (share >= RELIABLE_SHARE) & np.isfinite(med_f[:, 0])
            if reliable.any() and not reliable.all():
                # the most blurred reliable frame's median: the fewest flags it can give
                med_f = np.where(reliable[:, None], med_f, np.nanmax(med_f[reliable, 0]))
        rel = np.where(med_f > 0, q / med_f, np.nan)
        med_p = nanmedian_last(rel.T)[None, :]
        score = rel / med_p
    return np.asarray(converged & np.isfinite(score) & (score > ratio))


def median_critical(
    u: Float64Array,
    v: Float64Array,
    ok: BoolArray,
    gshape: tuple[int, int] | None,
    threshold: float,
    frames: IndexArray | None = None,
    out: Float32Array | None = None,
    threads: int = 1,
) -> Float32Array:
    """:func:`.median.median_critical_eps` of the points ``ok`` (the others missing) of
    ``frames`` (default all), written into ``out`` (frames, points); ``-inf`` everywhere
    without a grid. The normalised median test at ``eps`` per frame is ``out > eps``."""
    n_f = u.shape[0]
    if out is None:
        out = np.full(u.shape, -np.inf, np.float32)
    if gshape is None:
        return out
    sel = np.arange(n_f) if frames is None else np.asarray(frames)

    def one(b: IndexArray) -> None:
        # the mask goes into the compiled pass (no masked float64 copies)
        out[b] = median_critical_eps(u[b], v[b], gshape, threshold=threshold, valid=ok[b])

    frame_blocks(one, sel, 128, threads)
    return out


def frame_blocks(
    fn: Callable[[IndexArray], None], sel: IndexArray, size: int, threads: int
) -> None:
    """``fn(block)`` for the consecutive blocks of ``size`` of the frame indices ``sel``,
    on ``threads`` threads (numpy releases the GIL in its array loops; each block writes
    its own frames, so the result is the same on any number of threads)."""
    each(fn, (sel[a : a + size] for a in range(0, sel.size, size)), threads)
