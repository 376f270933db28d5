"""Predicted random error of every point in every frame: noise term + blur-mismatch term.

Both terms come from the static reference subset of each point (docs/models.md s. 4; the
machinery of :func:`dicblur.models.predict_from_pattern`), evaluated at the point's own
blur length ``W`` and direction in that frame:

- noise: the response of the ZNSSD IC-GN fixed point to the noise of both images, the
  complete noise term of the static prediction (docs/models.md s. 4: the reference's
  intensities and its noisy spline gradients meeting the mismatch residual, a negative
  O(W**2) share, plus the ``sigma**4`` interaction of the two noises), per component
  ``var = sigma**2 c + sigma**4 c4`` with the noise variance ``sigma**2`` of the static
  frames (at the subset's gradient-weighted grey level when the noise depends on the
  level);
- blur: the mismatch shift ``xi(W)`` of the subset against its exactly blurred copy, a
  deterministic error of that subset at that ``W`` (its quadratic mean over the subsets
  is the field's ``u_blur``); its magnitude per component is the blur part of sigma.

The per-point responses are tabulated once per recording on a grid of ``W`` (1 px steps
up to the largest measured blur; about 0.3 s per node for 2,401 affine subsets of a
512^2 frame) and of directions (nodes 15 degrees apart, one of them on the blur-weighted
dominant direction; only those the measured motion needs: a direction whose nearest node
is within :data:`ANGLE_TOLERANCE_PX` of perpendicular blur needs that node alone, others
the two around it), then interpolated (linearly in ``W**2``: the shift's leading order is
``k W**2``; between the two nearest direction nodes). ``W = 0`` (no blur, no direction)
is computed once for all directions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numba as nb
import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from ..metrics import estimate_noise
from ..models.blur_response import subset_blur_response
from ..threads import each

__all__ = [
    "ANGLE_STEP",
    "ANGLE_TOLERANCE_PX",
    "BLUR_STEP",
    "BlurTable",
    "NoiseEstimate",
    "build_blur_table",
    "direction_nodes",
    "estimate_static_noise",
    "subset_levels",
    "table_nodes",
]

ANGLE_STEP = 15.0  # deg between direction nodes of the table
BLUR_STEP = 1.0  # px between blur nodes of the table
#: A direction whose blur ``W`` is at most this far (px) across the nearest direction
#: node (``W |sin(angle - node)|``) uses that node alone.
ANGLE_TOLERANCE_PX = 0.05


@dataclass(frozen=True)
class BlurTable:
    """Per-point blur response on a grid of blur lengths and directions.

    Attributes
    ----------
    blur : ndarray, shape (m,)
        Blur lengths W (px), from 0 in steps of :data:`BLUR_STEP`.
    angles : ndarray, shape (a,)
        Direction nodes (deg, from the x axis towards +y (rows)): ``angles[0] +
        k ANGLE_STEP``, ``angles[0]`` in [0, ANGLE_STEP); a centred box blur is the same
        for theta and theta + 180.
    available : ndarray of bool, shape (a,)
        Nodes that were computed.
    values : ndarray, shape (a, m, n, 6)
        ``(xi_u, xi_v, c_uu, c_vv, c4_uu, c4_vv)``: mismatch shift (px), noise variance
        per unit noise variance (px**2 / GL**2) and the interaction of the two noises per
        unit ``sigma**4`` (px**2 / GL**4) of each point (NaN: no gradient or breakdown);
        :meth:`noise_variance` combines the last four.
    """

    blur: NDArray[np.float64]
    angles: NDArray[np.float64]
    available: NDArray[np.bool_]
    values: NDArray[np.float64]

    def lookup(
        self, w: NDArray[np.floating[Any]], angle: NDArray[np.floating[Any]]
    ) -> NDArray[np.float64]:
        """Interpolated ``values`` at ``w`` (px) and ``angle`` (deg), both shape (frames,
        points); returns shape (frames, points, 6) (NaN where ``w`` is NaN or beyond the
        table). Linear in ``W**2`` between the W nodes, then linear between the two
        direction nodes around ``angle`` (a missing node: the nearest computed one alone),
        :func:`_interpolate`."""
        ww, aa = _samples(w, angle)
        n = ww.shape[1]
        out = np.empty((*ww.shape, 6))
        if out.size:
            _lookup_rows(*self._kernel_args(), ww, aa, np.arange(n), out.reshape(-1, n, 6))
        return out

    def predict_into(
        self,
        w: NDArray[np.floating[Any]],
        angle: NDArray[np.floating[Any]],
        variance: NDArray[np.float64],
        rows: NDArray[np.intp],
        cols: NDArray[np.intp],
        out: tuple[NDArray[np.float32], ...],
    ) -> None:
        """The four sigma parts of the frames ``rows`` written in place, from the
        interpolated values (:meth:`lookup`, without its (frames, points, 6) float64
        copy): ``out = (sigma_u_noise, sigma_v_noise, sigma_u_blur, sigma_v_blur)``, each
        float32 of shape (frames, all points), px; table point ``q`` is column ``cols[q]``.

        The noise parts are ``sqrt(sigma**2 c + sigma**4 c4)`` (the complete noise term,
        module docstring) at the noise variance ``variance[q]`` (GL**2, shape (n,)); the
        blur parts are ``|xi_u|``, ``|xi_v|``; NaN where the blur ``w[f, cols[q]]`` (px) is
        NaN or beyond the table. ``w``, ``angle`` (deg): shape (frames, all points). Runs
        without the GIL (frame blocks on threads write their own rows)."""
        ww, aa = _samples(w, angle)
        var = np.ascontiguousarray(variance, np.float64).ravel()
        if var.size != len(cols) or len(cols) != self.values.shape[2]:
            raise InputError(
                f"variance, cols: one per table point ({self.values.shape[2]}), got "
                f"{var.size} and {len(cols)}"
            )
        _sigma_rows(
            *self._kernel_args(),
            ww,
            aa,
            var,
            np.asarray(rows, np.intp),
            np.asarray(cols, np.intp),
            *out,
        )

    def _kernel_args(
        self,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], float, float, NDArray[np.intp]]:
        """The table as :func:`_interpolate` takes it."""
        return (
            np.ascontiguousarray(self.values, np.float64),
            np.ascontiguousarray(self.blur, np.float64) ** 2,
            float(self.blur[-1]),
            float(self.angles[0]),
            np.where(self.available, np.arange(self.angles.size), -1).astype(np.intp),
        )


def _samples(
    w: NDArray[np.floating[Any]], angle: NDArray[np.floating[Any]]
) -> tuple[NDArray[np.floating[Any]], NDArray[np.floating[Any]]]:
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
def _direction_pair(
    angle: float, phase: float, node: NDArray[np.intp]
) -> tuple[int, int, float, bool]:
    """The direction nodes ``phase + k ANGLE_STEP`` (deg) around ``angle`` (deg; NaN: 0)
    and the fraction of the way from the first to the second: ``(j0, j1, t, True)`` when
    both were computed (``node[k]`` is ``k``, else -1), else ``(k, k, 0, False)`` with
    ``k`` the computed node nearest to the nearer of the two (the first of two at one
    distance around the circle)."""
    a = node.size
    t = (angle if np.isfinite(angle) else 0.0) - phase
    # np.mod(t, 180): fmod, then the sign of the divisor; without the (slow) fmod call
    # over the usual range, where the subtraction is exact (Sterbenz) and the same value
    if 180.0 <= t < 360.0:
        t -= 180.0
    elif not 0.0 <= t < 180.0:
        t = np.fmod(t, 180.0)
        if t < 0.0:
            t += 180.0
    th = t / ANGLE_STEP
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


@nb.njit(cache=True, nogil=True, inline="always")
def _interpolate(
    values: NDArray[np.float64],
    b2: NDArray[np.float64],
    w_top: float,
    phase: float,
    node: NDArray[np.intp],
    w: float,
    angle: float,
    q: int,
    buf: NDArray[np.float64],
) -> None:
    """The 6 table values of point ``q`` at blur ``w`` (px) along ``angle`` (deg) into
    ``buf``: linear in ``W**2`` between the W nodes (squares ``b2``; the mismatch shift's
    leading order is ``k W**2``, module docstring), then linear between the direction
    nodes ``phase + k ANGLE_STEP`` around ``angle`` when both were computed (``node[k]``
    is ``k``, else -1), else the computed node nearest ``angle`` alone; NaN where ``w`` is
    NaN or beyond the last node ``w_top``. The operations in the order of the earlier
    numpy lookup (the same numbers)."""
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
    j0, j1, ta, both = _direction_pair(angle, phase, node)
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
def _lookup_rows(
    values: NDArray[np.float64],
    b2: NDArray[np.float64],
    w_top: float,
    phase: float,
    node: NDArray[np.intp],
    w: NDArray[np.floating[Any]],
    angle: NDArray[np.floating[Any]],
    cols: NDArray[np.intp],
    out: NDArray[np.float64],
) -> None:
    """:func:`_interpolate` of every frame of ``w``, ``angle`` (frames, points) and table
    point ``q`` (column ``cols[q]``) into ``out`` (frames, n, 6)."""
    for f in range(w.shape[0]):
        for q in range(cols.size):
            _interpolate(
                values, b2, w_top, phase, node, w[f, cols[q]], angle[f, cols[q]], q, out[f, q]
            )


@nb.njit(cache=True, nogil=True)
def _sigma_rows(
    values: NDArray[np.float64],
    b2: NDArray[np.float64],
    w_top: float,
    phase: float,
    node: NDArray[np.intp],
    w: NDArray[np.floating[Any]],
    angle: NDArray[np.floating[Any]],
    variance: NDArray[np.float64],
    rows: NDArray[np.intp],
    cols: NDArray[np.intp],
    su_n: NDArray[np.float32],
    sv_n: NDArray[np.float32],
    su_b: NDArray[np.float32],
    sv_b: NDArray[np.float32],
) -> None:
    """:meth:`BlurTable.predict_into`: per frame ``rows[i]`` and table point ``q``, the
    interpolated values (:func:`_interpolate`) into the noise parts
    ``sqrt(v c + v**2 c4)`` and the blur parts ``|xi|`` (float32)."""
    buf = np.empty(values.shape[3])
    for i in range(rows.size):
        f = rows[i]
        for q in range(cols.size):
            p = cols[q]
            _interpolate(values, b2, w_top, phase, node, w[f, p], angle[f, p], q, buf)
            v = variance[q]
            su_n[f, p] = np.sqrt(v * buf[2] + v * v * buf[4])
            sv_n[f, p] = np.sqrt(v * buf[3] + v * v * buf[5])
            su_b[f, p] = abs(buf[0])
            sv_b[f, p] = abs(buf[1])


# samples per block of :func:`direction_nodes` (a few MB of temporaries per block)
_SAMPLE_BLOCK = 1 << 18


def direction_nodes(
    blur: NDArray[np.floating[Any]],
    angle: NDArray[np.floating[Any]],
    *,
    min_blur: float = 0.5,
    tolerance: float = ANGLE_TOLERANCE_PX,
    threads: int = 1,
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
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
    w: NDArray[np.floating[Any]],
    t: NDArray[np.floating[Any]],
    min_blur: float,
    out: NDArray[np.float64],
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
    w: NDArray[np.floating[Any]],
    t: NDArray[np.floating[Any]],
    min_blur: float,
    phase: float,
    tolerance: float,
    hit: NDArray[np.bool_],
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
        x = ti - phase  # np.mod(x, 180): fmod, then the sign of the divisor
        if 180.0 <= x < 360.0:
            x -= 180.0
        elif not 0.0 <= x < 180.0:
            x = np.fmod(x, 180.0)
            if x < 0.0:
                x += 180.0
        th = x / ANGLE_STEP
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
    blur: NDArray[np.floating[Any]],
    angle: NDArray[np.floating[Any]],
    *,
    min_blur: float = 0.5,
    threads: int = 1,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
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


def reused_nodes(
    blur: NDArray[np.floating[Any]],
    angle: NDArray[np.floating[Any]],
    *,
    min_blur: float,
    have: BlurTable | None,
    threads: int = 1,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_], BlurTable | None]:
    """:func:`table_nodes`, merged with the nodes of a table ``have`` built earlier for the
    same points (kept: more W nodes and more directions at most); ``have`` comes back as
    None when its direction nodes differ (another dominant direction: nothing to keep);
    ``threads`` as :func:`table_nodes`."""
    nodes, angles, need = table_nodes(blur, angle, min_blur=min_blur, threads=threads)
    if have is None or not np.allclose(have.angles, angles):
        return nodes, angles, need, None
    nodes = have.blur if have.blur[-1] >= nodes[-1] else nodes
    return nodes, angles, need | have.available, have


def build_blur_table(
    reference: NDArray[np.float64],
    centres: NDArray[np.intp],
    *,
    subset: int,
    shape: str,
    blur: NDArray[np.floating[Any]],
    angle: NDArray[np.floating[Any]],
    min_blur: float = 0.5,
    complete: bool = True,
    have: BlurTable | None = None,
    threads: int = 1,
) -> BlurTable:
    """Tabulate the blur response of every point for the blur vectors that occur.

    Parameters
    ----------
    reference : ndarray, shape (rows, cols)
        Reference frame, grey levels.
    centres : ndarray of int, shape (n, 2)
        POI centres (row, col); each subset must lie inside the frame.
    subset : int
    shape : {"translation", "affine"}
    blur, angle : ndarray, shape (frames, points)
        Measured blur lengths (px) and directions (deg); NaN ignored. The direction nodes
        computed are the two around every direction whose blur is >= ``min_blur`` px (the
        one nearest the dominant direction when none is).
    complete : bool
        The complete noise term (default); ``False``: the first-order response to the
        reference's intensities alone, without the ``sigma**4`` interaction (the earlier
        formula, for comparisons).
    have : BlurTable, optional
        A table built earlier for the same points and settings: its nodes are kept and
        only the missing ones computed (the second pass of :func:`~dicblur.track.track`,
        whose blur may reach a little further).
    threads : int
        Threads sharing the chunks of subsets of each node (each subset computed alone:
        the same values on any number of threads).
    """
    nodes, angles, need, have = reused_nodes(
        blur, angle, min_blur=min_blur, have=have, threads=threads
    )
    a = angles.size
    values = np.full((a, nodes.size, len(centres), 6), np.nan)
    # W = 0 (no blur, no direction) is the same for every direction: computed once
    zero = None if have is None else have.values[np.flatnonzero(have.available)[0], :1]
    for j in np.flatnonzero(need):
        start = 0
        if have is not None and have.available[j]:
            start = have.blur.size
            values[j, :start] = have.values[j]
        todo = np.arange(start, nodes.size)
        if todo.size and todo[0] == 0 and (zero is not None or j != np.flatnonzero(need)[0]):
            todo = todo[1:]  # copied from the first direction's W = 0 below
        if todo.size:
            # the subsets' chunks on the threads (each computed alone: the same values)
            values[j, todo] = _response(
                reference, nodes[todo], centres, subset, shape, angles[j], complete, threads
            )
    if zero is None:
        zero = values[np.flatnonzero(need)[0], :1]
    for j in np.flatnonzero(need):
        values[j, 0] = zero[0]
    return BlurTable(blur=nodes, angles=angles, available=need, values=values)


# subsets per pass of the response: (64, 441, 6) float64 steepest-descent images (1.4 MB)
# stay in the cache (256: 8-12 % more CPU on the benchmark's 2,401 affine subsets); each
# subset's numbers do not depend on it
_CHUNK = 64


def _response(
    reference: NDArray[np.float64],
    nodes: NDArray[np.float64],
    centres: NDArray[np.intp],
    subset: int,
    shape: str,
    angle: float,
    complete: bool,
    threads: int = 1,
) -> NDArray[np.float64]:
    """``(xi_u, xi_v, c_uu, c_vv, c4_uu, c4_vv)`` of every point at the blur lengths
    ``nodes`` along ``angle`` (deg), shape (m, n, 6), the chunks of subsets on
    ``threads`` threads."""
    t = math.radians(angle)
    shift, cov, cov4 = subset_blur_response(
        reference,
        nodes,
        centres,
        subset,
        motion=(math.sin(t), math.cos(t)),
        shape=shape,  # type: ignore[arg-type]
        max_shift=1.0,
        complete=complete,
        chunk=_CHUNK,
        threads=threads,
    )
    out = np.empty((nodes.size, len(centres), 6))
    out[..., 0:2] = shift
    out[..., 2] = cov[..., 0, 0]
    out[..., 3] = cov[..., 1, 1]
    out[..., 4] = cov4[..., 0, 0]
    out[..., 5] = cov4[..., 1, 1]
    return out


@dataclass(frozen=True)
class NoiseEstimate:
    """Image noise of a recording (GL), from its static frames or given.

    ``variance(level) = read_variance + slope * level`` (Poisson-Gaussian: the slope is
    the gain in GL per electron); ``slope = 0`` when the noise does not measurably depend
    on the level (or was given as one number).

    Attributes
    ----------
    sigma : float
        Noise std (GL) over the image (pairwise differences, as ``dicblur noise``).
    read_variance, slope : float
        The level model (GL**2 and GL).
    level_dependent : bool
    source : str
        ``"static frames a:b"`` or ``"given"``.
    pairs : int
        Frame pairs used.
    """

    sigma: float
    read_variance: float
    slope: float
    level_dependent: bool
    source: str
    pairs: int = 0

    def variance(self, level: NDArray[np.float64]) -> NDArray[np.float64]:
        """Noise variance (GL**2) at grey levels ``level``."""
        lv = np.asarray(level, dtype=np.float64)
        if not self.level_dependent:
            return np.full(lv.shape, self.sigma**2)
        return np.maximum(self.read_variance + self.slope * lv, 1e-12)

    def to_dict(self) -> dict[str, Any]:
        return {
            "sigma": self.sigma,
            "read_variance": self.read_variance,
            "slope": self.slope,
            "level_dependent": self.level_dependent,
            "source": self.source,
            "pairs": self.pairs,
        }


def estimate_static_noise(frames: Any, start: int, stop: int, *, bins: int = 24) -> NoiseEstimate:
    """Noise of a recording from its static frames ``start .. stop - 1``.

    Consecutive pairs give ``sigma**2 = var(a - b) / 2`` (a global offset, flicker,
    removed first: :func:`dicblur.estimate_noise`); the same differences binned by the
    pair's mean level give the level model ``var = read + slope * level`` (weighted least
    squares over the bins), kept when it explains the data better than one variance
    (slope > 0 and the variance changes by > 20 % over the levels present).

    Parameters
    ----------
    frames : Recording or sequence of arrays
        Indexable by frame number.
    start, stop : int
        Static frames, half-open (at least 2).
    """
    if stop - start < 2:
        raise InputError(
            f"static={start}:{stop}: needs at least 2 frames of the static "
            "scene (e.g. --static 0:20)"
        )
    prev = frames[start]
    lo, hi = float(prev.min()), float(prev.max())
    edges = np.linspace(lo, hi + 1e-9, bins + 1)
    s2 = np.zeros(bins)
    cnt = np.zeros(bins)
    sig2 = []
    for k in range(start + 1, stop):
        cur = frames[k]
        sig2.append(estimate_noise(prev, cur) ** 2)
        d = prev - cur
        d = d - d.mean()
        lev = 0.5 * (prev + cur)
        idx = np.clip(np.searchsorted(edges, lev.ravel(), side="right") - 1, 0, bins - 1)
        s2 += np.bincount(idx, weights=d.ravel() ** 2, minlength=bins)
        cnt += np.bincount(idx, minlength=bins)
        prev = cur
    sigma = math.sqrt(float(np.mean(sig2)))
    ok = cnt >= 200
    read, slope, dep = sigma**2, 0.0, False
    if ok.sum() >= 3:
        lev_c = 0.5 * (edges[:-1] + edges[1:])[ok]
        var_b = s2[ok] / cnt[ok] / 2.0
        wts = cnt[ok]
        A = np.stack([np.ones_like(lev_c), lev_c], axis=1) * np.sqrt(wts)[:, None]
        coef = np.linalg.lstsq(A, var_b * np.sqrt(wts), rcond=None)[0]
        span = coef[1] * (lev_c.max() - lev_c.min())
        if coef[1] > 0 and span > 0.2 * sigma**2:
            read, slope, dep = float(max(coef[0], 0.0)), float(coef[1]), True
    return NoiseEstimate(
        sigma=sigma,
        read_variance=read,
        slope=slope,
        level_dependent=dep,
        source=f"static frames {start}:{stop}",
        pairs=len(sig2),
    )


def subset_levels(
    reference: NDArray[np.float64], centres: NDArray[np.intp], subset: int
) -> NDArray[np.float64]:
    """Gradient-weighted grey level ``sum(g**2 I) / sum(g**2)`` of each subset (GL): the
    level at which signal-dependent noise enters its displacement error
    (:func:`dicblur.gradient_weighted_level`, per subset and for both directions)."""
    from scipy.ndimage import uniform_filter

    gy, gx = np.gradient(reference)
    g2 = gx * gx + gy * gy
    num = uniform_filter(g2 * reference, subset, mode="reflect")
    den = uniform_filter(g2, subset, mode="reflect")
    r, c = centres[:, 0], centres[:, 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        lv = num[r, c] / den[r, c]
    return np.where(np.isfinite(lv), lv, reference.mean())


@dataclass(frozen=True)
class SkewTable:
    """Per-point shift per unit third moment of the blur kernel on direction nodes.

    ``values`` (a, n, 2): ``(u, v)`` px / px**3
    (:func:`dicblur.models.blur_response.subset_skew_coefficients`).
    """

    angles: NDArray[np.float64]
    available: NDArray[np.bool_]
    values: NDArray[np.float64]

    def bias_into(
        self,
        kappa3: NDArray[np.floating[Any]],
        axis: NDArray[np.floating[Any]],
        rows: NDArray[np.intp],
        cols: NDArray[np.intp],
        out: NDArray[np.float32],
    ) -> None:
        """Predicted shift ``(u, v)`` (px) of kernels with third moment ``kappa3``
        (px**3) along ``axis`` (deg), both shape (frames, all points), written into
        ``out`` (frames, all points, 2) float32 at the frames ``rows``; table point ``q``
        is column ``cols[q]``. The coefficients are linear between the two direction nodes
        around ``axis`` (the nearest computed node alone when one is missing); NaN where
        ``kappa3`` is not finite. Runs without the GIL (frame blocks on threads)."""
        k3, ax = _samples(kappa3, axis)
        if len(cols) != self.values.shape[1]:
            raise InputError(f"cols: one per table point ({self.values.shape[1]}), got {len(cols)}")
        node = np.where(self.available, np.arange(self.angles.size), -1).astype(np.intp)
        _bias_rows(
            np.ascontiguousarray(self.values, np.float64),
            float(self.angles[0]),
            node,
            k3,
            ax,
            np.asarray(rows, np.intp),
            np.asarray(cols, np.intp),
            out,
        )


@nb.njit(cache=True, nogil=True)
def _bias_rows(
    values: NDArray[np.float64],
    phase: float,
    node: NDArray[np.intp],
    kappa3: NDArray[np.floating[Any]],
    axis: NDArray[np.floating[Any]],
    rows: NDArray[np.intp],
    cols: NDArray[np.intp],
    out: NDArray[np.float32],
) -> None:
    """:meth:`SkewTable.bias_into`: ``((1 - t) c_j0 + t c_j1) kappa3`` per frame
    ``rows[i]`` and table point ``q`` (:func:`_direction_pair`)."""
    for i in range(rows.size):
        f = rows[i]
        for q in range(cols.size):
            p = cols[q]
            j0, j1, ta, _ = _direction_pair(axis[f, p], phase, node)
            k = kappa3[f, p]
            k = k if np.isfinite(k) else np.nan
            for c in range(2):
                out[f, p, c] = ((1 - ta) * values[j0, q, c] + ta * values[j1, q, c]) * k


def build_skew_table(
    reference: NDArray[np.float64],
    centres: NDArray[np.intp],
    *,
    subset: int,
    shape: str,
    axis: NDArray[np.floating[Any]],
    kappa3: NDArray[np.floating[Any]],
    min_fraction: float = 0.05,
    threads: int = 1,
) -> SkewTable:
    """Compute the skew coefficients at the direction nodes of the axes whose
    ``|kappa3|`` exceeds ``min_fraction`` of the largest (:func:`direction_nodes`, weights
    ``|kappa3|`` over the largest: the nearest node alone within 0.05 of it across); the
    nodes and the chunks of subsets on ``threads`` threads."""
    from ..models.blur_response import subset_skew_coefficients

    ok = np.isfinite(kappa3) & np.isfinite(axis)
    top = float(np.max(np.abs(kappa3[ok]))) if ok.any() else 0.0
    rel = np.where(ok, np.abs(np.where(ok, kappa3, 0.0)) / (top if top > 0 else 1.0), np.nan)
    angles, need = direction_nodes(
        rel, axis, min_blur=min_fraction if top > 0 else np.inf, threads=threads
    )
    a = angles.size
    values = np.full((a, len(centres), 2), np.nan)
    for j in np.flatnonzero(need):
        t = math.radians(angles[j])
        values[j] = subset_skew_coefficients(
            reference,
            centres,
            subset,
            motion=(math.sin(t), math.cos(t)),
            shape=shape,  # type: ignore[arg-type]
            chunk=_CHUNK,
            threads=threads,
        )
    return SkewTable(angles=angles, available=need, values=values)
