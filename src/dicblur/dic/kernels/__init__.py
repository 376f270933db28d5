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
vectorised across them); IC-GN is parallel over POIs (see "Compile time" for how).
Translation works on flat padded buffers (row width :func:`flat_width`, lengths
multiples of 32): the reference subsets are packed once (:func:`pack_reference`), each
iteration copies the coefficient rows under the subset, filters them with one horizontal
and one vertical 4-tap (6-tap) pass (a rigidly translated subset shares one set of tap
weights) and reduces the five sums in one masked flat loop. Affine reads contiguous row
slices of the coefficient image and of the reference gradients, with a common-base 5x5
stencil fast path, 4x4 when the whole warped subset lies in one pixel cell (cubic).

Modules: :mod:`.common` (flags, status codes, records, threads, shared inlined helpers),
:mod:`.prefilter`, :mod:`.spline`, :mod:`.translation`, :mod:`.affine`, :mod:`.blur`
(the blur-estimating step of the compensated matcher). Numba compiles each kernel on its
first call, so a correlation compiles only the modules its shape calls.

Compile time (issue 16): numba links every callee's LLVM module into each caller and
re-optimises it there, and a parfor (``parallel=True``, ``prange``) adds two such levels
(about 1.5-2 s of first-run compile each). The affine IC-GN (:func:`icgn_affine` ->
the serial ``_affine_points``) and the prefilter (:func:`prefilter_padded` ->
``_rows_block``, ``_columns_block``; the margin in numpy) are therefore plain Python functions
that run serial ``nogil`` kernels over blocks of POIs (image lines) on Python threads
(:func:`.common.run_blocks`: dynamic scheduling, so a core slowed by another process does
less; each item is computed by the same code whatever the thread: same bytes on any
thread count). :func:`icgn_translation` keeps its thin ``prange`` over calls of the serial
``_points_translation``: called from Python threads the same serial code ran 35 % slower
than the parfor's re-optimised copy (measured, cause not found). On a cold numba cache
:func:`dicblur.dic.cache.compile_in_background` compiles the IC-GN kernel of the shape in
a child process (``compile_icgn`` of :mod:`.affine` / :mod:`.translation`, on no POI with
arguments of the Correlator's types, :func:`.common.example_args`) while this process
compiles the prefilter; the first IC-GN call waits for the child and loads the kernel from
the cache. Arguments travel in named-tuple records (:class:`ReferenceImages`,
:class:`Subsets`, :class:`Packed`, :class:`Passes`, :class:`Settings`, :class:`Outputs`)
instead of 26-39 positionals.
"""

from __future__ import annotations

from pathlib import Path

from .source_key import keyed_cache

# Every kernel module is imported here, inside the keyed cache: their decorators choose the
# cache directory, and a module imported directly still runs this file first.
with keyed_cache(Path(__file__).parent):
    from . import blur  # noqa: F401  (the compensated matcher's kernels: keyed too)
    from .affine import icgn_affine
    from .common import (
        GAIN_MIN,
        JUMP_SLACK,
        PAD,
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
    "JUMP_SLACK",
    "PAD",
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
