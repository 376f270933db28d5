"""Strain fields and their uncertainty under motion blur (issue 28; docs/strain.md).

``dicblur.strain(result, window=5, kind="green-lagrange")`` turns a displacement field on
a POI grid into strains (a local least-squares plane over N x N points, the virtual strain
gauge, or the affine subsets' own gradients) with their covariance: the noise errors of
neighbouring points correlated through the pixels their subsets share, the blur-mismatch
error carried as the deterministic error it is.
"""

from __future__ import annotations

from ..callable_module import make_callable
from .covariance import gradient_factor, overlap_correlation
from .field import (
    StrainField,
    StrainStatus,
    check_window_fits,
    grid_of,
    strain,
    strain_on_grid,
    vsg,
    window_from_vsg,
)
from .fit import plane_weights

__all__ = [
    "StrainField",
    "StrainStatus",
    "check_window_fits",
    "gradient_factor",
    "grid_of",
    "overlap_correlation",
    "plane_weights",
    "strain",
    "strain_on_grid",
    "vsg",
    "window_from_vsg",
]

make_callable(__name__, "strain")
