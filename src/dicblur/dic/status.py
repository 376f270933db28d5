"""Outcome of the correlation of one point of interest (DICe-style status enum)."""

from __future__ import annotations

from enum import IntEnum

__all__ = ["PointStatus"]


class PointStatus(IntEnum):
    """Status code of one POI, stored as ``uint8`` in :class:`~dicblur.dic.DICResult`.

    Only ``CONVERGED`` points carry a trusted displacement. ``MAX_ITERATIONS``,
    ``LOW_CORRELATION``, ``HIGH_RESIDUAL``, ``OUTLIER`` and ``IMPRECISE`` points keep their
    last (finite) estimate for inspection; the others carry NaN displacements.
    """

    #: IC-GN met the tolerance, the ZNCC is above ``min_zncc`` and no screening test
    #: flagged the point.
    CONVERGED = 0
    #: ``max_iterations`` reached before the update fell below ``tolerance``, or the update
    #: stopped shrinking (no new minimum for ``kernels.STALL_ITERATIONS`` iterations).
    MAX_ITERATIONS = 1
    #: The reference subset has (almost) no grey-level variation: the Hessian is singular.
    LOW_TEXTURE = 2
    #: The subset, in the reference or warped into the current image, leaves the image.
    OUT_OF_BOUNDS = 3
    #: The iteration produced a non-finite or runaway update, or a flat current subset.
    DIVERGED = 4
    #: Converged, but to a poor match (ZNCC below ``min_zncc``): not the same texture.
    LOW_CORRELATION = 5
    #: Converged, but the ZNSSD residual exceeds ``max_residual`` times the value the noise
    #: predicts for this subset (``noise_sigma`` given): the images differ there; or
    #: (translation shape) the affine gradients explain its residual, a deformation the
    #: shape function cannot follow (:mod:`dicblur.dic.lack_of_fit`).
    HIGH_RESIDUAL = 6
    #: Converged, but inconsistent with its grid neighbours: it fails the normalised
    #: median test, or the neighbours' displacement matches its subset better (a false
    #: optimum; see :func:`dicblur.dic.normalized_median_test`), or no neighbour supports
    #: it among failed ones (:func:`dicblur.dic.support.unsupported`).
    OUTLIER = 7
    #: The subset's predicted random error ``hypot(predicted_sigma_u, predicted_sigma_v)``
    #: exceeds ``max_predicted_sigma`` px (``noise_sigma`` given): too little texture for
    #: the shape function, an error of 0.1 px is likely. IC-GN converged or reached the
    #: reduced iteration limit such subsets get; the screening did not flag it otherwise.
    IMPRECISE = 8
