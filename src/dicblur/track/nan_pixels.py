"""Non-finite pixels in the frames of a track (a float TIFF's NaN or inf: dead, masked or
saturated-and-flagged pixels): the frames are read with those pixels filled
(:meth:`dicblur.sequence.Recording.with_non_finite_filled`) and the points whose subsets
touch them fail, as the points of any bad region do, instead of the whole track stopping.

A point fails (:attr:`~dicblur.dic.PointStatus.DIVERGED`, NaN displacement: the residual
of such a subset is not finite) in a frame when its subset there, grown by
:data:`SUPPORT_PX` for the bicubic interpolation's 4 x 4 support and the spline
prefilter's reach, covers a non-finite pixel of that frame, and in every frame when its
reference subset does.
"""

from __future__ import annotations

import threading

import numpy as np
from scipy.ndimage import maximum_filter

from ..arrays import BoolArray, Float64Array, IndexArray, UInt8Array
from ..dic import PointStatus
from ..sequence import Recording

__all__ = ["SUPPORT_PX", "NonFinitePixels"]

#: Pixels beyond the subset's half-width that still enter its match: 2 for the 4 x 4
#: bicubic support (the B-spline prefilter's influence decays by 0.27 per pixel beyond).
SUPPORT_PX = 2


class NonFinitePixels:
    """The masks of the frames that had non-finite pixels, collected as they are read.

    ``recording`` is the recording to track (the frames' non-finite pixels filled);
    :meth:`fail` marks the points they touch, :meth:`note` says what was done.
    """

    def __init__(self, rec: Recording) -> None:
        self.masks: dict[int, BoolArray] = {}
        self._lock = threading.Lock()
        self._names = rec.names
        self.recording = rec.with_non_finite_filled(self._seen)

    def _seen(self, index: int, mask: BoolArray) -> None:
        with self._lock:
            self.masks[int(index)] = mask

    def read(self, frames: list[int]) -> None:
        """Read ``frames`` (those another process read, e.g. a worker of
        :mod:`.parallel` that reported non-finite pixels in them) for their masks."""
        for k in frames:
            if k not in self.masks:
                self.recording.frame(k)

    def touched(self, index: int, rows: Float64Array, cols: Float64Array, subset: int) -> BoolArray:
        """Points (n,) whose subset centred at (``rows``, ``cols``) (px, NaN: the centre
        unknown, taken as touched when the frame has non-finite pixels) covers a
        non-finite pixel of frame ``index``, within :data:`SUPPORT_PX`."""
        mask = self.masks.get(int(index))
        if mask is None:
            return np.zeros(rows.shape, bool)
        grown = maximum_filter(mask, size=subset + 2 * SUPPORT_PX, mode="constant", cval=0)
        known = np.isfinite(rows) & np.isfinite(cols)
        r = np.clip(np.rint(np.where(known, rows, 0)), 0, mask.shape[0] - 1).astype(np.intp)
        c = np.clip(np.rint(np.where(known, cols, 0)), 0, mask.shape[1] - 1).astype(np.intp)
        return np.asarray(np.where(known, grown[r, c], True))

    def fail(
        self,
        frames: list[int],
        u: list[Float64Array],
        v: list[Float64Array],
        zncc: list[Float64Array],
        status: list[UInt8Array],
        *,
        reference: int,
        centres: IndexArray,
        subset: int,
    ) -> list[str]:
        """Fail in place (status DIVERGED, NaN ``u``, ``v``, ``zncc``) the points of the
        tracked ``frames`` whose subsets touch a non-finite pixel: at their displaced
        position in that frame (the frame's median displacement where the point has
        none), and at their reference position in every frame; ``centres`` (n, 2): the
        points' reference centres (row, col). Returns the notes, one per frame with
        non-finite pixels."""
        if not self.masks:
            return []
        rows0 = centres[:, 0].astype(np.float64)
        cols0 = centres[:, 1].astype(np.float64)
        in_ref = self.touched(reference, rows0, cols0, subset)
        notes = []
        for i, k in enumerate(frames):
            hit = in_ref.copy()
            if k in self.masks and k != reference:
                du, dv = u[i], v[i]
                fu = np.where(
                    np.isfinite(du), du, np.nanmedian(du) if np.isfinite(du).any() else np.nan
                )
                fv = np.where(
                    np.isfinite(dv), dv, np.nanmedian(dv) if np.isfinite(dv).any() else np.nan
                )
                hit |= self.touched(k, rows0 + fv, cols0 + fu, subset)
            if hit.any():
                u[i] = np.where(hit, np.nan, u[i])
                v[i] = np.where(hit, np.nan, v[i])
                zncc[i] = np.where(hit, np.nan, zncc[i])
                status[i] = np.where(hit, np.uint8(PointStatus.DIVERGED), status[i]).astype(
                    np.uint8
                )
            if k in self.masks:
                notes.append(
                    f"frame {k} ({self._names[k]}): {int(self.masks[k].sum())} non-finite "
                    f"pixels (NaN/inf); the {int(hit.sum())} points whose subsets touch them "
                    "failed (status diverged)"
                    + (", in every frame: it is the reference" if k == reference else "")
                )
        return notes
