"""The four patterns of the paper's study (Lavatelli & Zappa 2017, Section III, Fig. 1).

#1 DIC Challenge 1.0 Sample 13 (fine speckle, soft edges, low contrast: the "worst case")
#2 DIC Challenge 1.0 Sample 3 (sharper, higher contrast)
#3 a camera image of pattern #4 (here emulated: supersampled rendering, optics blur, pixel
   integration, camera noise)
#4 a numerically generated pattern smoothed by a 4x4 Gaussian mask

The DIC Challenge images are not redistributed with dicblur: pass their paths, or clearly
labelled synthetic stand-ins of the same character are generated.

Crop rule for user images: the central ``size x size`` window (for Sample 13, 1392 x 1040,
that is rows 440:952, cols 264:776, well inside the specimen and away from the grips).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..arrays import Float64Array
from ..errors import InputError
from ..io import file_sha256, load_image
from ..patterns import paper_pattern4, speckle_pattern

__all__ = ["StudyPattern", "central_crop", "stand_in_pattern1", "stand_in_pattern2"]


@dataclass(frozen=True)
class StudyPattern:
    """One pattern of the study.

    Attributes
    ----------
    key : str
        "p1" .. "p4".
    label : str
        Short label for figures, e.g. "#2 Sample 3" or "#2 stand-in (sharp)".
    image : ndarray, shape (size, size)
        Grey levels.
    synthetic : bool
        True for generated images and stand-ins.
    source : str
        File path and crop, or the generator settings.
    sha256 : str or None
        Hash of the source file, for user images.
    """

    key: str
    label: str
    image: Float64Array
    synthetic: bool
    source: str
    sha256: str | None = None


def central_crop(image: Float64Array, size: int) -> tuple[Float64Array, str]:
    """Central ``size x size`` window of ``image`` and a text stating the crop."""
    rows, cols = image.shape
    if rows < size or cols < size:
        raise InputError(
            f"image of {rows}x{cols} px is smaller than the study crop {size}x{size}; "
            f"pass an image of at least {size}x{size} px"
        )
    r0 = (rows - size) // 2
    c0 = (cols - size) // 2
    crop = f"rows {r0}:{r0 + size}, cols {c0}:{c0 + size}"
    return image[r0 : r0 + size, c0 : c0 + size].copy(), crop


def stand_in_pattern1(size: int, seed: int) -> Float64Array:
    """Stand-in for Sample 13: fine soft speckle, low contrast.

    2 px binary speckles with a 0.9 px edge blur in grey levels 55..135; it measures about
    4 px speckles, Michelson contrast 0.4, RMS contrast 0.25, MIG 15 GL/px, close to the
    Sample 13 crop (3.8 px, 0.53, 0.24, 13 GL/px).
    """
    return speckle_pattern(
        size, speckle_size=2.0, density=0.5, softness=0.9, levels=(55.0, 135.0), seed=seed
    )


def stand_in_pattern2(size: int, seed: int) -> Float64Array:
    """Stand-in for Sample 3: larger, sharper-looking speckles, high contrast.

    7 px binary speckles with a 1.6 px edge blur in grey levels 30..190; it measures about
    10 px speckles, Michelson 0.73, RMS 0.56, MIG 16 GL/px, close to Sample 3
    (9.8 px, 0.79, 0.51, 16 GL/px).
    """
    return speckle_pattern(
        size, speckle_size=7.0, density=0.5, softness=1.6, levels=(30.0, 190.0), seed=seed
    )


def load_user_pattern(
    key: str, label: str, path: str | os.PathLike[str], size: int
) -> StudyPattern:
    """A user image, centrally cropped, with its file hash as provenance."""
    img, crop = central_crop(load_image(path), size)
    return StudyPattern(key, label, img, False, f"{Path(path).name} ({crop})", file_sha256(path))


def numerical_pattern4(size: int, seed: int) -> StudyPattern:
    """Pattern #4: 4 px binary speckles smoothed by the 4x4 Gaussian mask."""
    img = paper_pattern4(size, speckle_size=4.0, seed=seed)
    return StudyPattern(
        "p4",
        "#4 numerical",
        img,
        True,
        f"paper_pattern4(size={size}, speckle_size=4, sigma=0.5, seed={seed})",
    )


def emulated_camera_pattern3(size: int, seed: int, *, supersample: int = 4) -> StudyPattern:
    """Pattern #3: a camera image of a pattern like #4, emulated.

    Pipeline: the #4 recipe (4 px binary speckles, Gaussian mask of sigma 0.5 px) drawn
    ``supersample`` times finer (the printed pattern); printed/lit grey levels 25..215 (ink is
    not black, paper not white); a Gaussian optics PSF of sigma 0.6 camera px; pixel
    integration by :func:`dicblur.render_blurred` with no motion; one exposure of an 8-bit
    Poisson-Gaussian camera (20,000 e- full well, 1 GL read noise).
    """
    from ..blur import render_blurred
    from ..camera import Camera
    from ..patterns import gaussian_filter_periodic

    ss = supersample
    ss_seq = np.random.SeedSequence([seed, 3])
    fine = speckle_pattern(
        size * ss, speckle_size=4.0 * ss, density=0.5, seed=np.random.default_rng(ss_seq)
    )
    fine = gaussian_filter_periodic(fine, 0.5 * ss)  # the 4x4 mask of pattern #4
    fine = 25.0 + fine * (190.0 / 255.0)
    fine = gaussian_filter_periodic(fine, 0.6 * ss)  # optics PSF
    irradiance = render_blurred(fine, (0.0, 0.0), supersample=ss)
    camera = Camera(read_noise=1.0, full_well=20000.0, bit_depth=8)
    img = camera.capture(irradiance, rng=np.random.default_rng(ss_seq.spawn(1)[0]))
    return StudyPattern(
        "p3",
        "#3 emulated camera",
        img,
        True,
        f"#4 recipe at {ss}x, levels 25..215, PSF sigma 0.6 px, pixel integration, "
        f"Camera(full_well=20000, read_noise=1, 8-bit), seed={seed}",
    )
