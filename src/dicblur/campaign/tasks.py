"""Task graph of a campaign: batches, task seeds, pattern images.

One *task* is one point of the sweep (pattern, angle, subset, noise, blur W, repetition):
one blurred, noisy image correlated against its reference. Tasks are grouped in
*batches* that share everything but W (a contiguous chunk of the blur grid): the reference
is prepared once per batch (one :class:`dicblur.Correlator`) and reused over its blur
values. A batch is also the unit of storage (one Zarr chunk per variable, see
:mod:`dicblur.campaign.store`).

Seeds. Every random draw of a task comes from a :class:`numpy.random.SeedSequence` whose
entropy is the campaign's base seed and whose spawn key is a hash of the draw's role and
coordinate *values* (not indices, not order): a task gives the same bytes whatever order,
worker, batch size or retry runs it, and extending a grid leaves the existing points
unchanged. The noise of the reference image depends on (pattern, noise, rep) only and the
noise of the blurred image on (pattern, angle, noise, blur, rep): all subset sizes see the
same images, so the ``subset`` dimension is a paired comparison.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..arrays import Float64Array
from ..errors import ConfigError, InputError
from .spec import CampaignSpec, PatternSpec, check_pattern_fits

__all__ = [
    "Batch",
    "input_hashes",
    "iter_batches",
    "make_pattern",
    "task_seed",
]


@dataclass(frozen=True)
class Batch:
    """A group of tasks sharing pattern, angle, subset, noise and repetition.

    Attributes
    ----------
    index : int
        Position of the batch in :func:`iter_batches` order.
    pattern : str
    angle : float
        Motion direction, degrees from +x (columns) towards +y (rows).
    subset : int
        Subset size, px.
    noise : float
        Noise level, grey levels.
    rep : int
        Repetition number.
    blur : tuple of float
        Blur lengths W (px) of the tasks in this batch.
    loc : tuple of int
        Indices ``(pattern, angle, subset, noise, blur_start, blur_stop, rep)`` of the
        batch in the result arrays.
    """

    index: int
    pattern: str
    angle: float
    subset: int
    noise: float
    rep: int
    blur: tuple[float, ...]
    loc: tuple[int, int, int, int, int, int, int]

    @property
    def region(self) -> tuple[int | slice, ...]:
        """Index of the batch in arrays of dims (pattern, angle, subset, noise, blur, rep)."""
        ip, ia, isub, inoise, b0, b1, irep = self.loc
        return (ip, ia, isub, inoise, slice(b0, b1), irep)


def iter_batches(spec: CampaignSpec) -> Iterator[Batch]:
    """All batches of a campaign, in a fixed order (pattern, angle, subset, noise, rep, W)."""
    nb = len(spec.blur)
    k = 0
    for ip, pat in enumerate(spec.patterns):
        for ia, angle in enumerate(spec.angles):
            for isub, subset in enumerate(spec.subsets):
                for inoise, noise in enumerate(spec.noise_levels):
                    for irep in range(spec.repetitions):
                        for b0 in range(0, nb, spec.blur_chunk):
                            b1 = min(b0 + spec.blur_chunk, nb)
                            yield Batch(
                                k,
                                pat.name,
                                angle,
                                subset,
                                noise,
                                irep,
                                spec.blur[b0:b1],
                                (ip, ia, isub, inoise, b0, b1, irep),
                            )
                            k += 1


def task_seed(base_seed: int, role: str, **coords: Any) -> np.random.SeedSequence:
    """Seed of one random draw, from the base seed and the draw's role and coordinates.

    Parameters
    ----------
    base_seed : int
        The campaign's ``campaign.seed``.
    role : str
        What the draw is for (``"reference"``, ``"current"``).
    **coords
        Coordinate values (str, int or float); their order does not matter.

    Returns
    -------
    numpy.random.SeedSequence
        ``SeedSequence(base_seed, spawn_key=...)`` with a spawn key of four 32-bit words
        of ``sha256("role;k1=v1;k2=v2...")`` (keys sorted, values by ``repr``).
    """
    parts = [role] + [f"{k}={coords[k]!r}" for k in sorted(coords)]
    digest = hashlib.sha256(";".join(parts).encode()).digest()
    words = tuple(int(w) for w in np.frombuffer(digest[:16], dtype="<u4"))
    return np.random.SeedSequence(int(base_seed), spawn_key=words)


def make_pattern(spec: CampaignSpec, pattern: PatternSpec) -> Float64Array:
    """The reference image of a pattern: generated, or read from its file and cropped.

    Returns
    -------
    ndarray of float64, shape (rows, cols)
        Grey levels. With ``spec.method == "rendered"``: the pattern on the fine grid,
        shape ``(rows * supersample, cols * supersample)``, speckle size and softness
        scaled by ``supersample``.
    """
    from ..io import load_image
    from ..patterns import paper_pattern4, speckle_pattern

    if pattern.generator is not None:
        kw = dict(pattern.settings)
        kw["shape"] = tuple(kw["shape"])
        if kw.get("seed") is None:
            # no seed of its own: one from the campaign's, or every run (and every resume
            # check of the store) would draw another pattern
            kw["seed"] = task_seed(spec.seed, "pattern", name=pattern.name)
        if spec.method == "rendered":
            # The fine grid of render_blurred: the same pattern drawn supersample x finer.
            ss = spec.supersample
            kw["shape"] = (kw["shape"][0] * ss, kw["shape"][1] * ss)
            kw["speckle_size"] = kw.get("speckle_size", 4.0) * ss
            kw["softness"] = kw.get("softness", 0.0) * ss
        fn = speckle_pattern if pattern.generator == "speckle" else paper_pattern4
        try:
            img = fn(**kw)
        except InputError as exc:
            raise ConfigError(f"pattern {pattern.name!r}: {exc}") from exc
    else:
        img = load_image(spec.resolve_path(pattern))
    if pattern.crop is not None:
        k = spec.supersample if spec.method == "rendered" else 1
        r0, c0, nr, nc = (v * k for v in pattern.crop)
        if r0 + nr > img.shape[0] or c0 + nc > img.shape[1]:
            raise ConfigError(
                f"pattern {pattern.name!r}: crop={list(pattern.crop)} exceeds the image "
                f"({img.shape[0]}x{img.shape[1]} px); use a window inside it"
            )
        img = img[r0 : r0 + nr, c0 : c0 + nc]
    if pattern.generator is None:
        k = spec.supersample if spec.method == "rendered" else 1
        check_pattern_fits(spec, pattern, (img.shape[0] // k, img.shape[1] // k))
    if float(np.ptp(img)) == 0.0:
        raise ConfigError(
            f"pattern {pattern.name!r}: the image is constant (every pixel "
            f"{float(img.flat[0]):g} GL): no texture to correlate; give a "
            "speckle image"
        )
    return np.ascontiguousarray(img, dtype=np.float64)


def input_hashes(spec: CampaignSpec, images: dict[str, Float64Array]) -> dict[str, str]:
    """Content hash of every input image, by pattern name.

    Image files: ``"file-sha256:<hex>"`` of the file's bytes (what ``sha256sum`` prints).
    Generated patterns: ``"array-sha256:<hex>"`` of the float64 pixels, so a generator
    whose output changed (another numpy version, another algorithm) is detected.
    """
    from ..io import file_sha256

    out: dict[str, str] = {}
    for p in spec.patterns:
        if p.path is not None:
            out[p.name] = "file-sha256:" + file_sha256(spec.resolve_path(p))
        else:
            data = np.ascontiguousarray(images[p.name], dtype="<f8").tobytes()
            out[p.name] = "array-sha256:" + hashlib.sha256(data).hexdigest()
    return out
