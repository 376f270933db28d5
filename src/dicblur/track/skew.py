"""The bias of a skewed exposure profile per point (:func:`build_skew_table`,
:class:`SkewTable`): the table of :func:`dicblur.models.blur_response.subset_skew_coefficients`
on the direction nodes of :mod:`.directions`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from ..arrays import BoolArray, Float32Array, Float64Array, FloatArray, IndexArray
from ..errors import InputError
from .directions import (
    RESPONSE_CHUNK,
    direction_motion,
    direction_nodes,
    direction_pair,
    node_index,
    samples,
)


@dataclass(frozen=True)
class SkewTable:
    """Per-point shift per unit third moment of the blur kernel on direction nodes.

    ``values`` (a, n, 2): ``(u, v)`` px / px**3
    (:func:`dicblur.models.blur_response.subset_skew_coefficients`).
    """

    angles: Float64Array
    available: BoolArray
    values: Float64Array

    def bias_into(
        self,
        kappa3: FloatArray,
        axis: FloatArray,
        rows: IndexArray,
        cols: IndexArray,
        out: Float32Array,
    ) -> None:
        """Predicted shift ``(u, v)`` (px) of kernels with third moment ``kappa3``
        (px**3) along ``axis`` (deg), both shape (frames, all points), written into
        ``out`` (frames, all points, 2) float32 at the frames ``rows``; table point ``q``
        is column ``cols[q]``. The coefficients are linear between the two direction nodes
        around ``axis`` (the nearest computed node alone when one is missing); NaN where
        ``kappa3`` is not finite. Runs without the GIL (frame blocks on threads)."""
        k3, ax = samples(kappa3, axis)
        if len(cols) != self.values.shape[1]:
            raise InputError(f"cols: one per table point ({self.values.shape[1]}), got {len(cols)}")
        _bias_rows(
            np.ascontiguousarray(self.values, np.float64),
            float(self.angles[0]),
            node_index(self.available),
            k3,
            ax,
            np.asarray(rows, np.intp),
            np.asarray(cols, np.intp),
            out,
        )


@nb.njit(cache=True, nogil=True)
def _bias_rows(
    values: Float64Array,
    phase: float,
    node: IndexArray,
    kappa3: FloatArray,
    axis: FloatArray,
    rows: IndexArray,
    cols: IndexArray,
    out: Float32Array,
) -> None:
    """:meth:`SkewTable.bias_into`: ``((1 - t) c_j0 + t c_j1) kappa3`` per frame
    ``rows[i]`` and table point ``q`` (:func:`direction_pair`)."""
    for i in range(rows.size):
        f = rows[i]
        for q in range(cols.size):
            p = cols[q]
            j0, j1, ta, _ = direction_pair(axis[f, p], phase, node)
            k = kappa3[f, p]
            k = k if np.isfinite(k) else np.nan
            for c in range(2):
                out[f, p, c] = ((1 - ta) * values[j0, q, c] + ta * values[j1, q, c]) * k


def build_skew_table(
    reference: Float64Array,
    centres: IndexArray,
    *,
    subset: int,
    shape: str,
    axis: FloatArray,
    kappa3: FloatArray,
    min_fraction: float = 0.05,
    threads: int = 1,
) -> SkewTable:
    """Compute the skew coefficients at the direction nodes of the axes whose
    ``|kappa3|`` exceeds ``min_fraction`` of the largest (:func:`direction_nodes`, weights
    ``|kappa3|`` over the largest: the nearest node alone within 0.05 of it across); the
    nodes and the chunks of subsets on ``threads`` threads."""
    from ..models.blur_response import subset_skew_coefficients
    from ..models.subset_algebra import SubsetMatcher

    ok = np.isfinite(kappa3) & np.isfinite(axis)
    top = float(np.max(np.abs(kappa3[ok]))) if ok.any() else 0.0
    rel = np.where(ok, np.abs(np.where(ok, kappa3, 0.0)) / (top if top > 0 else 1.0), np.nan)
    angles, need = direction_nodes(
        rel, axis, min_blur=min_fraction if top > 0 else np.inf, threads=threads
    )
    a = angles.size
    values = np.full((a, len(centres), 2), np.nan)
    for j in np.flatnonzero(need):
        values[j] = subset_skew_coefficients(
            reference,
            centres,
            subset,
            SubsetMatcher(direction_motion(angles[j]), shape),  # type: ignore[arg-type]
            chunk=RESPONSE_CHUNK,
            threads=threads,
        )
    return SkewTable(angles=angles, available=need, values=values)
