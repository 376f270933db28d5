"""The nodes of the per-point blur response tables of :mod:`dicblur.track.uncertainty`
(blur length x direction, :func:`table_nodes`; the directions a track's blur vectors need,
:func:`direction_nodes`) and the compiled interpolation between them.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..arrays import BoolArray, Float32Array, Float64Array, FloatArray, IndexArray
from ..errors import InputError
from ..threads import each

ANGLE_STEP = 15.0  # deg between direction nodes of the table
BLUR_STEP = 1.0  # px between blur nodes of the table
#: A direction whose blur ``W`` is at most this far (px) across the nearest direction
#: node (``W |sin(angle - node)|``) uses that node alone.
ANGLE_TOLERANCE_PX = 0.05


def samples(w: FloatArray, angle: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``w``, ``angle`` as C-contiguous 2-d float arrays of one shape (float32 stays
    float32: :func:`_interpolate` squares ``w`` in its own precision, as the table's
    lookup always has)."""
    ww = np.asarray(w)
    aa = np.asarray(angle)
    if ww.dtype.kind != "f":
        ww = ww.astype(np.float64)
    if aa.dtype.kind != "f":
        aa = aa.astype(np.float64)
    if ww.ndim != 2 or ww.shape != aa.shape:
        raise InputError(
            f"w, angle: expected two (frames, points) arrays of one shape, got {ww.shape} "
            f"and {aa.shape}"
        )
    return np.ascontiguousarray(ww), np.ascontiguousarray(aa)


@nb.njit(cache=True, nogil=True, inline="always")
def _mod180(t: float) -> float:
    """``np.mod(t, 180)`` (deg): fmod, then the sign of the divisor; without the (slow)
    fmod call over the usual range, where the subtraction is exact (Sterbenz) and the
    same value."""
    if 180.0 <= t < 360.0:
        return t - 180.0
    if 0.0 <= t < 180.0:
        return t
    t = np.fmod(t, 180.0)
    return t + 180.0 if t < 0.0 else t


@nb.njit(cache=True, nogil=True, inline="always")
def direction_pair(angle: float, phase: float, node: IndexArray) -> tuple[int, int, float, bool]:
    """The direction nodes ``phase + k ANGLE_STEP`` (deg) around ``angle`` (deg; NaN: 0)
    and the fraction of the way from the first to the second: ``(j0, j1, t, True)`` when
    both were computed (``node[k]`` is ``k``, else -1), else ``(k, k, 0, False)`` with
    ``k`` the computed node nearest to the nearer of the two (the first of two at one
    distance around the circle)."""
    a = node.size
    th = _mod180((angle if np.isfinite(angle) else 0.0) - phase) / ANGLE_STEP
    fl = math.floor(th)
    j0 = int(fl) % a
    j1 = (j0 + 1) % a
    ta = th - fl
    if node[j0] >= 0 and node[j1] >= 0:
        return j0, j1, ta, True
    j = j0 if ta < 0.5 else j1
    best = a
    k0 = j
    for k in range(a):
        if node[k] >= 0:
            d = abs(k - j)
            d = min(d, a - d)
            if d < best:
                best = d
                k0 = k
    return k0, k0, 0.0, False


#: A :class:`~dicblur.track.uncertainty.BlurTable` as the compiled lookup takes it:
#: ``(values, b2, w_top, phase, node)``, the values (a, m, n, 6), the squares of the W
#: nodes (m,), the last W node (px), the first direction node (deg) and
#: :func:`node_index` of the computed direction nodes.
KernelTable = tuple[Float64Array, Float64Array, float, float, IndexArray]


def node_index(available: BoolArray) -> IndexArray:
    """``node[k]``: ``k`` where direction node ``k`` was computed, else -1 (as
    :func:`direction_pair` takes them)."""
    return np.where(available, np.arange(available.size), -1).astype(np.intp)


@nb.njit(cache=True, nogil=True, inline="always")
def _interpolate(
    table: KernelTable,
    w: float,
    angle: float,
    q: int,
    buf: Float64Array,
) -> None:
    """The 6 table values of point ``q`` at blur ``w`` (px) along ``angle`` (deg) into
    ``buf``: linear in ``W**2`` between the W nodes (squares ``b2``; the mismatch shift's
    leading order is ``k W**2``, module docstring), then linear between the direction
    nodes ``phase + k ANGLE_STEP`` around ``angle`` when both were computed (``node[k]``
    is ``k``, else -1), else the computed node nearest ``angle`` alone; NaN where ``w`` is
    NaN or beyond the last node ``w_top``. The operations in the order of the earlier
    numpy lookup (the same numbers)."""
    values, b2, w_top, phase, node = table
    nv = values.shape[3]
    if not (np.isfinite(w) and w <= w_top + 1e-9):
        for c in range(nv):
            buf[c] = np.nan
        return
    s2 = w * w  # in w's own precision
    m = b2.size
    i1 = 0
    while i1 < m and b2[i1] <= s2:  # searchsorted(b2, s2, side="right")
        i1 += 1
    i1 = min(max(i1, 1), m - 1)
    i0 = i1 - 1
    tw = min(max((s2 - b2[i0]) / (b2[i1] - b2[i0]), 0.0), 1.0)
    j0, j1, ta, both = direction_pair(angle, phase, node)
    for c in range(nv):
        lo = values[j0, i0, q, c]
        hi = values[j0, i1, q, c]
        o = (hi - lo) * tw + lo
        if both:
            lo = values[j1, i0, q, c]
            hi = values[j1, i1, q, c]
            o = o + ta * ((hi - lo) * tw + lo - o)
        buf[c] = o


@nb.njit(cache=True, nogil=True)
def lookup_rows(
    table: KernelTable,
    w: FloatArray,
    angle: FloatArray,
    cols: IndexArray,
    out: Float64Array,
) -> None:
    """:func:`_interpolate` of every frame of ``w``, ``angle`` (frames, points) and table
    point ``q`` (column ``cols[q]``) into ``out`` (frames, n, 6)."""
    for f in range(w.shape[0]):
        for q in range(cols.size):
            _interpolate(table, w[f, cols[q]], angle[f, cols[q]], q, out[f, q])


@nb.njit(cache=True, nogil=True)
def sigma_rows(
    table: KernelTable,
    w: FloatArray,
    angle: FloatArray,
    variance: Float64Array,
    rows: IndexArray,
    cols: IndexArray,
    out: tuple[Float32Array, ...],
) -> None:
    """:meth:`BlurTable.predict_into`: per frame ``rows[i]`` and table point ``q``, the
    interpolated values (:func:`_interpolate`) into ``out = (su_n, sv_n, su_b, sv_b)``
    (float32): the noise parts ``sqrt(v c + v**2 c4)`` and the blur parts ``|xi|``."""
    su_n, sv_n, su_b, sv_b = out
    buf = np.empty(table[0].shape[3])
    for i in range(rows.size):
        f = rows[i]
        for q in range(cols.size):
            p = cols[q]
            _interpolate(table, w[f, p], angle[f, p], q, buf)
            v = variance[q]
            su_n[f, p] = np.sqrt(v * buf[2] + v * v * buf[4])
            sv_n[f, p] = np.sqrt(v * buf[3] + v * v * buf[5])
            su_b[f, p] = abs(buf[0])
            sv_b[f, p] = abs(buf[1])


# samples per block of :func:`direction_nodes` (a few MB of temporaries per block)
_SAMPLE_BLOCK = 1 << 18


def direction_nodes(
    blur: FloatArray,
    angle: FloatArray,
    *,
    min_blur: float = 0.5,
    tolerance: float = ANGLE_TOLERANCE_PX,
    threads: int = 1,
) -> tuple[Float64Array, BoolArray]:
    """Direction nodes of a table for blur lengths ``blur`` (px; for the skew table any
    weight) along ``angle`` (deg), NaN ignored: the nodes (every :data:`ANGLE_STEP`, one
    on the ``blur``-weighted dominant direction of the samples with ``blur >= min_blur``)
    and which of them to compute: the nearest node of every such direction when the blur
    across it, ``blur |sin(angle - node)|``, is at most ``tolerance``, else the two around
    it; the node of the dominant direction when no sample has ``blur >= min_blur``.
    ``threads``: threads sharing the blocks of samples (the same result on any number)."""
    a = round(180.0 / ANGLE_STEP)
    # one compiled pass per block of the flattened samples (a long recording has millions,
    # frames x points: no float64 temporaries), blocks on the threads, their sums added in
    # block order: the same result on any number of threads
    w_all = np.ravel(blur)
    t_all = np.ravel(angle)
    if w_all.dtype.kind != "f":
        w_all = w_all.astype(np.float64)
    if t_all.dtype.kind != "f":
        t_all = t_all.astype(np.float64)
    starts = list(range(0, w_all.size, _SAMPLE_BLOCK))
    sums = np.zeros((len(starts), 5))

    def scan(k: int) -> None:
        i = starts[k]
        _direction_sums(
            w_all[i : i + _SAMPLE_BLOCK], t_all[i : i + _SAMPLE_BLOCK], min_blur, sums[k]
        )

    each(scan, range(len(starts)), threads)
    has_big = bool(sums[:, 0].sum() > 0)
    c = s = 0.0
    for k in range(len(starts)):  # in block order
        c += sums[k, 1 if has_big else 3]
        s += sums[k, 2 if has_big else 4]
    dom = (math.degrees(math.atan2(s, c)) / 2.0) % 180.0 if (c or s) else 0.0
    phase = dom % ANGLE_STEP
    angles = phase + np.arange(a, dtype=np.float64) * ANGLE_STEP
    need = np.zeros(a, bool)
    if has_big:
        hits = np.zeros((len(starts), a), bool)

        def needed(k: int) -> None:
            i = starts[k]
            _direction_hits(
                w_all[i : i + _SAMPLE_BLOCK],
                t_all[i : i + _SAMPLE_BLOCK],
                min_blur,
                phase,
                tolerance,
                hits[k],
            )

        each(needed, range(len(starts)), threads)
        need = np.asarray(hits.any(axis=0))
    else:
        need[round((dom - phase) / ANGLE_STEP) % a] = True
    return angles, need


@nb.njit(cache=True, nogil=True)
def _direction_sums(
    w: FloatArray,
    t: FloatArray,
    min_blur: float,
    out: Float64Array,
) -> None:
    """:func:`direction_nodes`' pass 1 over samples ``w``, ``t`` (deg): ``out`` = (count
    with ``w >= min_blur``, their ``sum (w + 1e-12) cos 2t``, ``... sin 2t``, the same two
    sums over all finite samples); NaN in either: left out."""
    n_big = 0.0
    cb = sb = cf = sf = 0.0
    for i in range(w.size):
        wi = np.float64(w[i])
        ti = np.float64(t[i])
        if not (np.isfinite(wi) and np.isfinite(ti)):
            continue
        r2 = (2.0 * ti) * (np.pi / 180.0)
        wt = wi + 1e-12  # a direction of zero blur still counts when nothing moves
        cw = wt * np.cos(r2)
        sw = wt * np.sin(r2)
        cf += cw
        sf += sw
        if wi >= min_blur:
            n_big += 1.0
            cb += cw
            sb += sw
    out[0] = n_big
    out[1] = cb
    out[2] = sb
    out[3] = cf
    out[4] = sf


@nb.njit(cache=True, nogil=True)
def _direction_hits(
    w: FloatArray,
    t: FloatArray,
    min_blur: float,
    phase: float,
    tolerance: float,
    hit: BoolArray,
) -> None:
    """:func:`direction_nodes`' pass 2: the direction nodes ``phase + k ANGLE_STEP`` that
    the samples with ``w >= min_blur`` need (``hit[k]`` set): the nearest node alone when
    the blur across it, ``w |sin(t - node)|``, is at most ``tolerance``, else the two
    around ``t``."""
    a = hit.size
    for i in range(w.size):
        wi = np.float64(w[i])
        ti = np.float64(t[i])
        if not (np.isfinite(wi) and np.isfinite(ti) and wi >= min_blur):
            continue
        th = _mod180(ti - phase) / ANGLE_STEP
        near = np.rint(th)
        y = ((th - near) * ANGLE_STEP) * (np.pi / 180.0)  # within 7.5 deg
        ay = abs(y)
        # |y| - |y|**3 / 6 <= |sin y| <= |y|: the sine only where the bounds (with a
        # margin for rounding) leave the test open
        one = wi * ay <= tolerance * (1.0 - 1e-9)
        if not one and wi * (ay - ay * ay * ay / 6.0) < tolerance * (1.0 + 1e-9):
            one = wi * abs(np.sin(y)) <= tolerance
        if one:
            hit[int(near) % a] = True
        else:
            lo = int(np.floor(th)) % a
            hit[lo] = True
            hit[(lo + 1) % a] = True


def table_nodes(
    blur: FloatArray,
    angle: FloatArray,
    *,
    min_blur: float = 0.5,
    threads: int = 1,
) -> tuple[Float64Array, Float64Array, BoolArray]:
    """Nodes of a blur table for the measured ``blur`` (px) and ``angle`` (deg), both
    shape (frames, points), NaN ignored: the W nodes (every ``BLUR_STEP`` from 0 up to
    the first at or beyond the largest W) and the direction nodes with which of them to
    compute (:func:`direction_nodes`, on ``threads`` threads)."""
    finite = np.isfinite(blur) & np.isfinite(angle)
    w_max = float(np.max(blur[finite])) if finite.any() else 0.0
    nodes = np.arange(
        0.0, BLUR_STEP * max(math.ceil(w_max / BLUR_STEP - 1e-9), 1) + 1e-9, BLUR_STEP
    )
    angles, need = direction_nodes(blur, angle, min_blur=min_blur, threads=threads)
    return nodes, angles, need


def direction_motion(angle: float) -> tuple[float, float]:
    """The unit motion ``(dy, dx)`` along the direction ``angle`` (deg, from the x axis
    towards +y (rows)), as the response functions take ``motion``."""
    t = math.radians(angle)
    return math.sin(t), math.cos(t)


# subsets per pass of the response: (64, 441, 6) float64 steepest-descent images (1.4 MB)
# stay in the cache (256: 8-12 % more CPU on the benchmark's 2,401 affine subsets); each
# subset's numbers do not depend on it
RESPONSE_CHUNK = 64
