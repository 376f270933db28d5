"""The sharp reference's terms of the static prediction, kept across blur lengths.

In :func:`dicblur.models.sensitivity.shifts_and_variance` every blur length W re-reads the
same reference subsets: their ZNSSD normalisation ``f_hat``, the projected
steepest-descent images ``P_f J_f`` and the IC-GN Hessian ``H = J_f^T P_f J_f`` (with its
condition number, the contraction's test) do not depend on W or on the sub-pixel offset.
A :class:`ReferenceTerms` given to it (``reference=``) computes them once per chunk of
subsets and hands the same arrays back to every later W and call: the same functions on
the same inputs, so the predictions are bit-identical, at about a third less work per W
(`dicblur calibrate` tabulates 40-60 W).
"""

from __future__ import annotations

import hashlib
from typing import Any

import numpy as np

from ..arrays import Float64Array, IndexArray
from ..errors import InputError
from .subset_algebra import gram, normalise, project

__all__ = ["ReferenceTerms"]

Terms = tuple[Float64Array, Float64Array, Float64Array, Float64Array, Any]


class ReferenceTerms:
    """Per-chunk reference terms ``(f_hat, sigma_f, P_f J_f, H, cond(H))`` of one image,
    one set of subset centres and one matcher (shape, derivative, chunk size).

    Parameters
    ----------
    max_bytes : int
        Largest memory (bytes) the stored ``P_f J_f`` may take; beyond it a chunk's terms
        are computed and returned but not kept (same numbers, no saving).

    Notes
    -----
    The first call fixes what the terms belong to (a hash of the image and the centres,
    the subset, shape, derivative and chunk); a call for anything else raises
    :class:`~dicblur.errors.InputError` instead of returning another image's terms.
    """

    def __init__(self, *, max_bytes: int = 256 * 2**20) -> None:
        self.max_bytes = int(max_bytes)
        self._key: tuple[Any, ...] | None = None
        self._store: dict[tuple[int, int], Terms] = {}
        self._bytes = 0

    def bind(self, image: Float64Array, centres: IndexArray, *settings: Any) -> None:
        """Check (or, on first use, fix) the image, centres and settings the terms are of."""
        h = hashlib.blake2b(np.ascontiguousarray(image).tobytes(), digest_size=16)
        h.update(np.ascontiguousarray(centres).tobytes())
        key = (image.shape, centres.shape, h.hexdigest(), *settings)
        if self._key is None:
            self._key = key
        elif key != self._key:
            raise InputError(
                "reference: these ReferenceTerms belong to another image, set of subsets or "
                "matcher; use one ReferenceTerms per image and settings"
            )

    def terms(self, start: int, jf: Float64Array, f: Float64Array) -> Terms:
        """The terms of the chunk of subsets from ``start`` (``jf``, ``f``: its reference
        steepest-descent images and intensities, as :func:`blurred_subsets` yields them)."""
        key = (start, len(f))
        got = self._store.get(key)
        if got is not None:
            return got
        fh, sf = normalise(f)
        pf = project(jf, fh)
        hess = gram(pf, pf)
        finite = np.isfinite(hess).all(axis=(1, 2))
        cond = np.full(len(f), np.inf)
        if finite.any():
            cond[finite] = np.linalg.cond(hess[finite])
        out: Terms = (fh, sf, pf, hess, cond)
        size = fh.nbytes + pf.nbytes + hess.nbytes
        if self._bytes + size <= self.max_bytes:
            self._store[key] = out
            self._bytes += size
        return out
