"""``dicblur track --compensate-blur``: the blur-compensated matcher on a recording (issue 18).

A first, plain pass tracks the recording (:func:`~dicblur.track.track`); its track gives
the motion of every point during every exposure (:func:`.kinematics.exposure_motion`),
``W = v x T``. Every frame is then correlated again with ``Correlator(blur="given")``
(docs/dic.md, "Blur-compensated correlation"): the current subset is compared with the
reference blurred by the point's own blur vector, which removes the deterministic
blur-mismatch error; the plain pass's displacement is the initial guess. The plain
track's blur carries that pass's mismatch error, so a second pass runs with the blur from
the compensated track when it moved by more than :data:`ITERATE_PX` (on the test target:
the scatter at W = 4-6 px falls from 0.0090 to 0.0081 px with the second pass, a third
changes nothing).

The matcher prepares one blurred reference per distinct blur vector (65 ms for a 256^2
frame, more than the correlation itself), so the vectors of a frame are grouped: those
within :data:`UNIFORM_PX` of the frame's median vector take it, the others are rounded to
a grid of :data:`QUANTUM` px (doubled until a frame has at most :data:`MAX_GROUPS`
groups). A residual blur length error ``dW`` only leaves the mismatch of a blur
``sqrt(2 W dW)`` (1.1 px at W = 6 px, dW = 0.1 px: a mismatch error of about 0.001 px);
on the test target one vector per frame, 2, 4, 8 groups or a 0.01 px grid gave the same
scatter within 0.0001 px. A point whose blur is unknown (a flagged
sample in the trajectory fit) takes the frame's median vector; a vector not shorter than
the subset becomes zero, which is the plain matcher bit for bit.

Sigma then follows the compensated matcher (:func:`build_compensated_table`): no
mismatch term, and a noise term from the *blurred* reference's gradients,
``A^-1 + A^-1 C A^-1`` per unit noise variance
(:func:`dicblur.models.compensated.compensated_covariance`, the per-point form of
:func:`~dicblur.models.predict_compensated`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields
from functools import partial
from typing import Any

import numpy as np

from ..arrays import Float64Array, FloatArray, IndexArray, Int64Array, UInt8Array
from ..dic import Correlator, PointStatus
from ..dic.compensation import blur_reference
from ..models.compensated import compensated_covariance
from ..sequence import Recording
from ..threads import each
from .directions import direction_motion
from .kinematics import exposure_motion
from .median import normalized_median_test
from .uncertainty import BlurTable, table_start

__all__ = [
    "ITERATE_PX",
    "MATCHER_COMPENSATED",
    "MATCHER_PLAIN",
    "MAX_GROUPS",
    "QUANTUM",
    "UNIFORM_PX",
    "PassStart",
    "blur_vectors",
    "build_compensated_table",
    "compensated_pass",
    "group_vectors",
    "pass_frames",
]

#: A further compensated pass runs while the blur of the compensated track differs from
#: the one it was computed with by more than this (px, rms over points and frames).
ITERATE_PX = 0.01
#: Grid (px) the blur vectors of a frame are rounded to.
QUANTUM = 0.05
#: Blur vectors this close (px) to the frame's median vector are given the median one.
UNIFORM_PX = 0.1
#: Most distinct blur vectors per frame (the grid is coarsened until it holds).
MAX_GROUPS = 8
#: ``matcher`` attribute of the Dataset.
MATCHER_PLAIN = "plain"
MATCHER_COMPENSATED = "compensated (blur='given', blur vector per point from the track)"


def blur_vectors(
    frames: Int64Array,
    u: Float64Array,
    v: Float64Array,
    status: UInt8Array,
    *,
    fps: float,
    exposure: float,
    half_window: int,
    grid_shape: tuple[int, int] | None,
) -> tuple[Float64Array, Float64Array]:
    """Motion of every point during every exposure, ``(blur_u, blur_v)`` (frames, points)
    px, from the track (converged points passing the normalised median test); NaN where
    unknown, all NaN when the frames are not consecutive."""
    ok = status == PointStatus.CONVERGED
    if grid_shape is not None:
        for i in range(u.shape[0]):
            ok[i] &= ~normalized_median_test(
                np.where(ok[i], u[i], np.nan), np.where(ok[i], v[i], np.nan), grid_shape
            )
    if u.shape[0] < 2 or not np.all(np.diff(frames) == 1):
        nan = np.full(u.shape, np.nan)
        return nan, nan.copy()
    wu, wv = exposure_motion(
        np.where(ok, u, np.nan),
        np.where(ok, v, np.nan),
        fps=fps,
        exposure=exposure,
        half_window=half_window,
    )
    return np.asarray(wu, np.float64), np.asarray(wv, np.float64)


def group_vectors(
    vec: Float64Array,
    *,
    subset: int,
    quantum: float = QUANTUM,
    max_groups: int = MAX_GROUPS,
    uniform: float = UNIFORM_PX,
) -> tuple[Float64Array, int]:
    """Blur vectors (n, 2) ``(dy, dx)`` px of one frame, grouped for the matcher.

    Vectors within ``uniform`` px of the frame's median vector take it (rounded to
    ``quantum``): the usual near-rigid frame then needs one blurred reference, and a
    periodic motion finds it again in the matcher's cache. The others are rounded to a
    grid of ``quantum`` px, coarsened until at most ``max_groups`` distinct vectors remain.
    An unknown (NaN) vector takes the median one; vectors not shorter than ``subset - 1``
    px become zero (the plain matcher). Returns the vectors and how many were filled or
    zeroed.
    """
    known = np.asarray(np.isfinite(vec).all(axis=1))
    fill = np.median(vec[known], axis=0) if known.any() else np.zeros(2)
    out = np.where(known.reshape(-1, 1), vec, fill.reshape(1, 2))
    near = np.hypot(out[:, 0] - fill[0], out[:, 1] - fill[1]) <= uniform
    out[near] = fill
    long = np.hypot(out[:, 0], out[:, 1]) >= subset - 1
    out[long] = 0.0
    n_zero = int((~known).sum() + long.sum())
    q = quantum
    while True:
        r = np.rint(out / q) * q
        r[r == 0.0] = 0.0  # no negative zeros: one group for the plain matcher
        if np.unique(r, axis=0).shape[0] <= max_groups:
            return r, n_zero
        q *= 2.0


@dataclass(frozen=True)
class PassStart:
    """The previous pass's track of some frames, where a compensated pass starts.

    Attributes
    ----------
    frames : ndarray of int, shape (f,)
    u, v : ndarray, shape (f, n_points)
        Displacements (px): the initial guesses.
    blur_u, blur_v : ndarray, shape (f, n_points)
        Motion during each exposure (px, NaN unknown).
    status : ndarray of uint8, shape (f, n_points)
        The previous pass's statuses: a point whose subset left the frame there
        (``OUT_OF_BOUNDS``) keeps that result.
    """

    frames: Int64Array
    u: Float64Array
    v: Float64Array
    blur_u: Float64Array
    blur_v: Float64Array
    status: UInt8Array

    def rows(self, start: int, stop: int) -> PassStart:
        """The frames ``start .. stop - 1`` (positions, not frame numbers)."""
        return PassStart(*(getattr(self, f.name)[start:stop] for f in fields(self)))


def compensated_pass(
    rec: Recording,
    start: PassStart,
    *,
    reference: int,
    correlator: dict[str, Any],
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, Any]:
    """Correlate the frames of ``start`` again with the blur-compensated matcher.

    Parameters
    ----------
    rec : Recording
    start : PassStart
        The previous pass's track (initial guesses, blur vectors, statuses).
    reference : int
    correlator : dict
        Keyword arguments of :class:`~dicblur.Correlator` (as the first pass's).
    progress : callable(done, total), optional

    Returns
    -------
    dict
        ``u``, ``v``, ``zncc`` (f, n) float64, ``status`` (f, n) uint8, ``n_zeroed``
        (points whose blur was unknown, given the median, or too long, given zero) and
        ``max_groups`` (most distinct vectors in a frame).
    """
    corr = Correlator(rec.frame(reference), blur="given", **correlator)
    return pass_frames(rec, corr, start, progress=progress)


def pass_frames(
    rec: Recording,
    corr: Correlator,
    start: PassStart,
    *,
    progress: Callable[[int, int], None] | None,
) -> dict[str, Any]:
    """:func:`compensated_pass` with a prepared ``Correlator(blur="given")`` (the task of
    a chunk)."""
    u, v, status = start.u, start.v, start.status
    f, n = u.shape
    out: dict[str, Any] = {
        "u": np.empty((f, n)),
        "v": np.empty((f, n)),
        "zncc": np.empty((f, n)),
        "status": np.empty((f, n), np.uint8),
        "n_zeroed": 0,
        "max_groups": 0,
    }
    for i, k in enumerate(start.frames):
        g = np.stack([u[i], v[i]], axis=1)
        bad = ~np.isfinite(g).all(axis=1)
        if bad.any() and not bad.all():
            g[bad] = np.median(g[~bad], axis=0)
        guess = None if bad.all() else g
        vec, n_zero = group_vectors(
            np.stack([start.blur_v[i], start.blur_u[i]], axis=1), subset=corr.subset
        )
        res = corr.correlate(rec.frame(int(k)), initial=guess, blur_vector=vec)
        # a subset that left the frame stays out (from the median guess it could
        # converge on the wrapped texture of a periodic target)
        keep = status[i] == PointStatus.OUT_OF_BOUNDS
        out["u"][i] = np.where(keep, u[i], res.u)
        out["v"][i] = np.where(keep, v[i], res.v)
        out["zncc"][i] = np.where(keep, np.nan, res.zncc)
        out["status"][i] = np.where(keep, status[i], res.status)
        out["n_zeroed"] += n_zero
        out["max_groups"] = max(out["max_groups"], int(np.unique(vec, axis=0).shape[0]))
        if progress is not None:
            progress(i + 1, f)
    return out


def build_compensated_table(
    reference: Float64Array,
    centres: IndexArray,
    *,
    subset: int,
    shape: str,
    blur: FloatArray,
    angle: FloatArray,
    min_blur: float = 0.5,
    have: BlurTable | None = None,
    threads: int = 1,
) -> BlurTable:
    """The compensated matcher's response table (as :func:`~.uncertainty.build_blur_table`,
    same nodes, ``have`` and ``threads``): mismatch shift zero, noise variance per unit
    noise variance ``A^-1 + A^-1 C A^-1`` of the blurred reference's subset at each node."""
    st = table_start(blur, angle, len(centres), min_blur=min_blur, have=have, threads=threads)
    nodes, angles, values = st.blur, st.angles, st.values
    # (xi_u, xi_v, c_uu, c_vv, c4_uu, c4_vv) as the plain table (track.uncertainty): no
    # mismatch shift; the sigma**4 interaction is left out (at 2 GL it is 0.2-0.4 % of the
    # noise variance at W = 0, measured on the test target); ``have``'s are zero too
    values[..., 0:2] = 0.0
    values[..., 4:6] = 0.0
    ref = np.asarray(reference, dtype=np.float64)
    # (direction node, W node)
    jobs = [(j, i) for j, start in st.todo for i in range(start, nodes.size)]

    def run(job: tuple[int, int]) -> None:
        j, i = job
        dy, dx = direction_motion(angles[j])
        w = float(nodes[i])
        vec = (w * dy, w * dx)
        fw = blur_reference(ref, vec)[0] if w > 0 else ref
        fww = blur_reference(fw, vec)[0] if w > 0 else ref
        cov = compensated_covariance(fw, fww, centres, subset=subset, shape=shape)
        values[j, i, :, 2] = cov[:, 0, 0]
        values[j, i, :, 3] = cov[:, 1, 1]

    each(run, jobs, threads)
    return BlurTable(blur=nodes, angles=angles, available=st.available, values=values)


def compensate_track(
    rec: Recording,
    out: Any,
    *,
    reference: int,
    correlator: dict[str, Any],
    fps: float,
    exposure: float,
    half_window: int,
    grid_shape: tuple[int, int] | None,
    passes: int = 2,
    runner: Any = None,
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, Any]:
    """Replace the first pass's results in ``out`` (lists ``frames``, ``u``, ``v``,
    ``zncc``, ``status``, one entry per frame) by the compensated matcher's: a pass with
    the blur of the plain track, then up to ``passes - 1`` more while the blur of the
    compensated track moves by more than :data:`ITERATE_PX` (rms over points and frames);
    ``runner`` (a :class:`.parallel.ChunkedRun`) runs the frames in chunks.

    Returns the attributes to record (``matcher``, ``compensation_*``). ``out`` is changed
    only once every pass is complete (a stop part-way leaves the first pass's results).
    """
    idx = np.argsort(out.frames)
    frames = np.asarray(out.frames, np.int64)[idx]
    u = np.stack(out.u)[idx]
    v = np.stack(out.v)[idx]
    zn = np.stack(out.zncc)[idx]
    st = np.stack(out.status)[idx]
    n_zero, groups, done, change = 0, 0, 0, float("nan")
    blur_of = partial(
        blur_vectors, fps=fps, exposure=exposure, half_window=half_window, grid_shape=grid_shape
    )  # the blur of the track of every pass
    wu, wv = blur_of(frames, u, v, st)
    run_pass = compensated_pass if runner is None else runner.compensate
    while True:
        res = run_pass(
            rec,
            PassStart(frames, u, v, wu, wv, st),
            reference=reference,
            correlator=correlator,
            progress=progress,
        )
        u, v, zn, st = res["u"], res["v"], res["zncc"], res["status"]
        n_zero, groups = int(res["n_zeroed"]), max(groups, int(res["max_groups"]))
        done += 1
        nu, nv = blur_of(frames, u, v, st)
        d = np.hypot(nu - wu, nv - wv)
        change = float(np.sqrt(np.mean(d[np.isfinite(d)] ** 2))) if np.isfinite(d).any() else 0.0
        wu, wv = nu, nv
        # the first pass's blur carries the plain matcher's mismatch error; once the
        # compensated track moves it by less than ITERATE_PX there is nothing to gain
        if done >= passes or change < ITERATE_PX:
            break
    for pos, i in enumerate(idx):
        out.u[i], out.v[i] = u[pos], v[pos]
        out.zncc[i], out.status[i] = zn[pos], st[pos]
    return {
        "matcher": MATCHER_COMPENSATED,
        "compensation_passes": done,
        "compensation_blur_change_px": change,
        "compensation_filled_vectors": n_zero,
        "compensation_max_groups": groups,
        "compensation_quantum_px": QUANTUM,
    }
