"""Type aliases for the arrays dicblur passes around, one per element type.

``NDArray[np.float64]`` spelled in full hundreds of times adds nothing a reader needs: an
alias names the element type once. They are annotations only (numba and numpy ignore
them); shapes and units stay in the numpydoc docstrings.
"""

from __future__ import annotations

from typing import Any, TypeAlias

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "BoolArray",
    "Float32Array",
    "Float64Array",
    "FloatArray",
    "IndexArray",
    "Int64Array",
    "UInt8Array",
]

#: float64 array: images, fields, parameters (GL, px, s as documented).
Float64Array: TypeAlias = NDArray[np.float64]
#: float32 array: the kernels' spline coefficients and scratch.
Float32Array: TypeAlias = NDArray[np.float32]
#: any floating array (float32 or float64): inputs the code accepts in either precision.
FloatArray: TypeAlias = NDArray[np.floating[Any]]
#: np.intp array: pixel indices (row, col) and point indices.
IndexArray: TypeAlias = NDArray[np.intp]
#: int64 array: frame numbers, counts.
Int64Array: TypeAlias = NDArray[np.int64]
#: uint8 array: point statuses, 8-bit images.
UInt8Array: TypeAlias = NDArray[np.uint8]
#: bool array: masks.
BoolArray: TypeAlias = NDArray[np.bool_]
