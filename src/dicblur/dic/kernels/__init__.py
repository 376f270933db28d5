"""Compiled hot loops of the DIC engine (numba, ``cache=True``).

Each kernel has a plain reference implementation that the tests compare it against:

=========================  ==========================================================
kernel                     reference
=========================  ==========================================================
:func:`prefilter_padded`   :func:`dicblur.dic.interpolation.prefilter_reference`
                           (:func:`scipy.ndimage.spline_filter`, mirror boundary)
:func:`weights`            :func:`dicblur.dic.interpolation.bspline_weights`
:func:`icgn_translation`   :func:`dicblur.dic.icgn.icgn_reference` (translation)
:func:`icgn_affine`        :func:`dicblur.dic.icgn.icgn_reference` (affine)
=========================  ==========================================================

Speed notes (measured on the 512x512, subset 21, step 10 benchmark): float32 working
arrays; the prefilter runs down the rows with the recursion vectorised across columns
(along the rows, blocks of 16 rows are transposed into scratch so the recursion is
vectorised across them); IC-GN is parallel over POIs. Translation works on flat padded
buffers (row width :func:`flat_width`, lengths multiples of 32): the reference subsets are
packed once (:func:`pack_reference`), each iteration copies the coefficient rows under the
subset, filters them with one horizontal and one vertical 4-tap (6-tap) pass (a rigidly
translated subset shares one set of tap weights) and reduces the five sums in one masked
flat loop. Affine reads contiguous row slices of the coefficient image and of the
reference gradients, with a common-base 5x5 stencil fast path.

Modules: :mod:`.common` (flags, status codes, shared inlined helpers), :mod:`.prefilter`,
:mod:`.spline`, :mod:`.translation`, :mod:`.affine`, :mod:`.blur` (the blur-estimating
step of the compensated matcher). Numba compiles each kernel on its first call, so a
correlation compiles only the modules its shape calls.

Compile time (issue 16): a parallel kernel (``parallel=True``, ``prange``) is a thin loop
whose body is one call of a serial function (``icgn_affine`` -> ``_affine_points``,
``icgn_translation`` -> ``_points_translation``, ``prefilter_parallel`` -> the block
functions): the parfor machinery then compiles a call, not the whole loop nest, and the
callee is compiled once (its index passed as int64: the parfor's own index is unsigned
and would compile a second signature). Arguments travel in named-tuple records
(:class:`ReferenceImages`, :class:`Subsets`, :class:`Packed`, :class:`Passes`,
:class:`Settings`, :class:`Outputs`) instead of 26-39 positionals.
"""

from __future__ import annotations

from .affine import icgn_affine
from .common import (
    GAIN_MIN,
    PAD,
    RATE_MIN,
    STALL_ITERATIONS,
    Outputs,
    Packed,
    Passes,
    ReferenceImages,
    Settings,
    Subsets,
    compose_inverse_affine,
    outputs,
    settings,
)
from .prefilter import prefilter_padded
from .spline import weights
from .translation import flat_lengths, flat_width, icgn_translation, pack_reference

__all__ = [
    "GAIN_MIN",
    "PAD",
    "RATE_MIN",
    "STALL_ITERATIONS",
    "Outputs",
    "Packed",
    "Passes",
    "ReferenceImages",
    "Settings",
    "Subsets",
    "compose_inverse_affine",
    "flat_lengths",
    "flat_width",
    "icgn_affine",
    "icgn_translation",
    "outputs",
    "pack_reference",
    "prefilter_padded",
    "settings",
    "weights",
]
