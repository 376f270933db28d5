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

from dataclasses import dataclass

import numpy as np

from ..arrays import BoolArray, Float32Array, Float64Array, FloatArray, IndexArray
from ..errors import InputError
from ..models.blur_response import subset_blur_response
from ..models.subset_algebra import SubsetMatcher
from .directions import ANGLE_STEP as ANGLE_STEP
from .directions import ANGLE_TOLERANCE_PX as ANGLE_TOLERANCE_PX
from .directions import BLUR_STEP as BLUR_STEP
from .directions import (
    RESPONSE_CHUNK,
    KernelTable,
    direction_motion,
    lookup_rows,
    node_index,
    samples,
    sigma_rows,
    table_nodes,
)
from .directions import direction_nodes as direction_nodes
from .noise import NoiseEstimate as NoiseEstimate
from .noise import estimate_static_noise as estimate_static_noise
from .noise import subset_levels as subset_levels
from .skew import SkewTable as SkewTable
from .skew import build_skew_table as build_skew_table

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

    blur: Float64Array
    angles: Float64Array
    available: BoolArray
    values: Float64Array

    def lookup(self, w: FloatArray, angle: FloatArray) -> Float64Array:
        """Interpolated ``values`` at ``w`` (px) and ``angle`` (deg), both shape (frames,
        points); returns shape (frames, points, 6) (NaN where ``w`` is NaN or beyond the
        table). Linear in ``W**2`` between the W nodes, then linear between the two
        direction nodes around ``angle`` (a missing node: the nearest computed one alone),
        :func:`_interpolate`."""
        ww, aa = samples(w, angle)
        n = ww.shape[1]
        out = np.empty((*ww.shape, 6))
        if out.size:
            lookup_rows(self._kernel_table(), ww, aa, np.arange(n), out.reshape(-1, n, 6))
        return out

    def predict_into(
        self,
        w: FloatArray,
        angle: FloatArray,
        variance: Float64Array,
        rows: IndexArray,
        cols: IndexArray,
        out: tuple[Float32Array, ...],
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
        ww, aa = samples(w, angle)
        var = np.ascontiguousarray(variance, np.float64).ravel()
        if var.size != len(cols) or len(cols) != self.values.shape[2]:
            raise InputError(
                f"variance, cols: one per table point ({self.values.shape[2]}), got "
                f"{var.size} and {len(cols)}"
            )
        sigma_rows(
            self._kernel_table(),
            ww,
            aa,
            var,
            np.asarray(rows, np.intp),
            np.asarray(cols, np.intp),
            tuple(out),
        )

    def _kernel_table(self) -> KernelTable:
        """The table as the compiled lookup takes it (:data:`.directions.KernelTable`)."""
        return (
            np.ascontiguousarray(self.values, np.float64),
            np.ascontiguousarray(self.blur, np.float64) ** 2,
            float(self.blur[-1]),
            float(self.angles[0]),
            node_index(self.available),
        )


@dataclass(frozen=True)
class TableStart:
    """Where a response table's build starts (:func:`table_start`).

    Attributes
    ----------
    blur, angles, available
        The nodes and the direction nodes to compute, as :class:`BlurTable`'s.
    have : BlurTable or None
        The earlier table whose values were kept (None: nothing kept).
    values : ndarray, shape (a, m, n, 6)
        NaN but for ``have``'s values.
    todo : list of (int, int)
        Per direction node to compute, ``(j, first W node not kept)``.
    """

    blur: Float64Array
    angles: Float64Array
    available: BoolArray
    have: BlurTable | None
    values: Float64Array
    todo: list[tuple[int, int]]


def table_start(
    blur: FloatArray,
    angle: FloatArray,
    n_points: int,
    *,
    min_blur: float,
    have: BlurTable | None,
    threads: int = 1,
) -> TableStart:
    """:func:`table_nodes` for ``n_points`` points, merged with the nodes of a table
    ``have`` built earlier for the same points (kept: more W nodes and more directions at
    most; its values copied); ``have`` is not kept when its direction nodes differ
    (another dominant direction); ``threads`` as :func:`table_nodes`."""
    nodes, angles, need = table_nodes(blur, angle, min_blur=min_blur, threads=threads)
    if have is None or not np.allclose(have.angles, angles):
        have = None
    else:
        nodes = have.blur if have.blur[-1] >= nodes[-1] else nodes
        need = need | have.available
    values = np.full((angles.size, nodes.size, n_points, 6), np.nan)
    todo = []
    for j in np.flatnonzero(need):
        start = 0
        if have is not None and have.available[j]:
            start = have.blur.size
            values[j, :start] = have.values[j]
        todo.append((int(j), start))
    return TableStart(nodes, angles, need, have, values, todo)


def build_blur_table(
    reference: Float64Array,
    centres: IndexArray,
    *,
    subset: int,
    shape: str,
    blur: FloatArray,
    angle: FloatArray,
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
    st = table_start(blur, angle, len(centres), min_blur=min_blur, have=have, threads=threads)
    nodes, values = st.blur, st.values
    j_first = st.todo[0][0] if st.todo else -1  # the first direction node computed
    # W = 0 (no blur, no direction) is the same for every direction: computed once
    zero = None if st.have is None else st.have.values[np.flatnonzero(st.have.available)[0], :1]

    def response(j: int, todo: IndexArray) -> None:
        """``(xi_u, xi_v, c_uu, c_vv, c4_uu, c4_vv)`` of every point at the W nodes
        ``todo`` of direction node ``j``, the subsets' chunks on the threads (each
        computed alone: the same values)."""
        shift, cov, cov4 = subset_blur_response(
            reference,
            nodes[todo],
            centres,
            subset,
            SubsetMatcher(direction_motion(st.angles[j]), shape),  # type: ignore[arg-type]
            max_shift=1.0,
            complete=complete,
            chunk=RESPONSE_CHUNK,
            threads=threads,
        )
        values[j, todo, :, 0:2] = shift
        values[j, todo, :, 2] = cov[..., 0, 0]
        values[j, todo, :, 3] = cov[..., 1, 1]
        values[j, todo, :, 4] = cov4[..., 0, 0]
        values[j, todo, :, 5] = cov4[..., 1, 1]

    for j, start in st.todo:
        todo = np.arange(start, nodes.size)
        if todo.size and todo[0] == 0 and (zero is not None or j != j_first):
            todo = todo[1:]  # copied from the first direction's W = 0 below
        if todo.size:
            response(j, todo)
    if zero is None:
        zero = values[j_first, :1]
    for j, _ in st.todo:
        values[j, 0] = zero[0]
    return BlurTable(blur=nodes, angles=st.angles, available=st.available, values=values)
