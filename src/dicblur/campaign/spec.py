"""Campaign specification: a TOML file that describes a synthetic blur experiment.

A campaign is the paper's experiment (Lavatelli & Zappa 2017, Sections III and VI) as a
grid: patterns x motion angles x subset sizes x noise levels x blur lengths W x
repetitions. :func:`load_spec` reads and validates a TOML file; :func:`parse_spec` does the
same for a dict. Every error is a :class:`~dicblur.errors.ConfigError` naming the key, the
value and the fix.

Example
-------
.. code-block:: toml

    [campaign]
    name = "paper-sweep"
    seed = 2017              # base seed of every task seed
    repetitions = 1

    [[pattern]]
    name = "p4"
    generator = "paper4"     # or "speckle" (keyword arguments of speckle_pattern)
    shape = [512, 512]
    speckle_size = 4.0
    seed = 4

    [[pattern]]
    name = "sample3"
    path = "Sample3_Reference.tif"   # relative to the spec file
    crop = [0, 0, 512, 512]          # row, col, rows, cols

    [blur]
    lengths = { start = 0.1, stop = 10.0, step = 0.1 }   # px, or a list
    angles = [0.0]           # degrees from +x (columns) towards +y (rows)
    trajectory = "linear"
    method = "transfer"      # or "rendered" (generator patterns only)
    substeps = 100           # K; 0 = the continuous limit
    boundary = "periodic"

    [noise]
    model = "per-subframe"   # the paper's; or "per-exposure", "poisson-gaussian"
    levels = [2.0]           # grey levels (read noise for poisson-gaussian)
    full_well = 20000        # electrons at grey level 255 (poisson-gaussian only)

    [dic]
    subsets = [31]
    step = 10
    shape = "translation"
    interpolation = "bspline3"
    max_iterations = 50
    tolerance = 1e-4
    compensation = "none"    # "given": blur-compensated matcher; "estimate": with the blur
                             # length estimated; "deblur": Wiener baseline

    [run]
    blur_chunk = 10          # blur values per task batch (one Correlator per batch)
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..checks import bad_value, check_choice, check_finite_number, check_integer
from ..errors import ConfigError, DicblurError, InputError
from ..io import check_pixels

if TYPE_CHECKING:
    from ..dic.settings import MatcherSettings

__all__ = [
    "BLUR_METHODS",
    "NOISE_MODELS",
    "CampaignSpec",
    "PatternSpec",
    "check_pattern_fits",
    "load_spec",
    "parse_spec",
]

NOISE_MODELS = ("per-subframe", "per-exposure", "poisson-gaussian")
BLUR_METHODS = ("transfer", "rendered")
GENERATORS = ("speckle", "paper4")
DIC_SHAPES = ("translation", "affine")
#: ``dic.compensation``: the plain matcher; blur-compensated with the known motion
#: (``Correlator(blur="given")``, issue 18); blur-compensated with the blur length
#: estimated along the known direction (``Correlator(blur="estimate")``); or the deblur
#: baseline (Wiener-deblurred current image with the known kernel, then the plain matcher).
COMPENSATIONS = ("none", "given", "estimate", "deblur")
INTERPOLATIONS = ("bspline3", "bspline5")
_MAX_BLUR_VALUES = 100_000
MAX_TASKS = 10_000_000
"""Most tasks (DIC runs) in one campaign: the store holds ~20 float64 arrays of this size
(1.6 GB), and at ~10 ms per task it is more than a day of computing."""

_SECTIONS = {
    "campaign": {"name", "seed", "repetitions", "description"},
    "blur": {
        "lengths",
        "angles",
        "trajectory",
        "trajectory_params",
        "method",
        "substeps",
        "boundary",
        "supersample",
    },
    "noise": {"model", "levels", "full_well"},
    "dic": {
        "subsets",
        "step",
        "shape",
        "interpolation",
        "max_iterations",
        "tolerance",
        "compensation",
    },
    "run": {"blur_chunk"},
}
_PATTERN_KEYS = {
    "name",
    "generator",
    "path",
    "crop",
    "shape",
    "speckle_size",
    "density",
    "softness",
    "contrast",
    "supersample",
    "seed",
    "mask_sigma",
}
_GENERATOR_KEYS = {
    "speckle": {"shape", "speckle_size", "density", "softness", "contrast", "supersample", "seed"},
    "paper4": {"shape", "speckle_size", "density", "mask_sigma", "seed"},
}


@dataclass(frozen=True)
class PatternSpec:
    """One pattern of a campaign: a generator with its settings, or an image file.

    Attributes
    ----------
    name : str
        Label of the pattern (the ``pattern`` coordinate of the results).
    generator : {"speckle", "paper4"} or None
        Generator (:func:`dicblur.speckle_pattern` or :func:`dicblur.paper_pattern4`).
    settings : dict
        Keyword arguments of the generator (``shape`` as a list of two ints).
    path : str or None
        Image file as written in the spec (resolved against the spec's folder).
    crop : tuple of int or None
        ``(row, col, rows, cols)`` window of the image, px.
    """

    name: str
    generator: str | None = None
    settings: Mapping[str, Any] = field(default_factory=dict)
    path: str | None = None
    crop: tuple[int, int, int, int] | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (only the keys that apply)."""
        d: dict[str, Any] = {"name": self.name}
        if self.generator is not None:
            d["generator"] = self.generator
            d.update(self.settings)
        if self.path is not None:
            d["path"] = self.path
        if self.crop is not None:
            d["crop"] = list(self.crop)
        return d


@dataclass(frozen=True)
class CampaignSpec:
    """A validated campaign specification (see the module docs for the TOML layout).

    Lengths in px, angles in degrees (from +x, the columns, towards +y, the rows), noise
    levels in grey levels. ``substeps=None`` is the continuous-motion limit.
    """

    name: str
    seed: int
    patterns: tuple[PatternSpec, ...]
    blur: tuple[float, ...]
    angles: tuple[float, ...] = (0.0,)
    trajectory: str = "linear"
    trajectory_params: Mapping[str, Any] = field(default_factory=dict)
    method: str = "transfer"
    substeps: int | None = 100
    boundary: str = "periodic"
    supersample: int = 8
    noise_model: str = "per-subframe"
    noise_levels: tuple[float, ...] = (2.0,)
    full_well: float | None = None
    subsets: tuple[int, ...] = (31,)
    step: int = 10
    dic_shape: str = "translation"
    compensation: str = "none"
    interpolation: str = "bspline3"
    max_iterations: int = 50
    tolerance: float = 1e-4
    repetitions: int = 1
    blur_chunk: int = 10
    description: str = ""
    base_dir: str = field(default=".", compare=False)

    # -- derived ------------------------------------------------------------------------
    def matcher(self, subset: int) -> MatcherSettings:
        """The DIC matcher settings of the ``dic`` section for one of its ``subsets``."""
        from ..dic.settings import MatcherSettings

        return MatcherSettings(
            subset=subset,
            step=self.step,
            shape=self.dic_shape,  # type: ignore[arg-type]
            interpolation=self.interpolation,  # type: ignore[arg-type]
            max_iterations=self.max_iterations,
            tolerance=self.tolerance,
        )

    @property
    def dims(self) -> dict[str, int]:
        """Size of each dimension of the results, in storage order."""
        return {
            "pattern": len(self.patterns),
            "angle": len(self.angles),
            "subset": len(self.subsets),
            "noise": len(self.noise_levels),
            "blur": len(self.blur),
            "rep": self.repetitions,
        }

    @property
    def n_tasks(self) -> int:
        """Number of sweep points (one DIC run each)."""
        return math.prod(self.dims.values())

    def to_dict(self) -> dict[str, Any]:
        """Canonical JSON-ready dict (what the spec hash is computed from)."""
        return {
            "campaign": {
                "name": self.name,
                "seed": self.seed,
                "repetitions": self.repetitions,
                "description": self.description,
            },
            "pattern": [p.to_dict() for p in self.patterns],
            "blur": {
                "lengths": list(self.blur),
                "angles": list(self.angles),
                "trajectory": self.trajectory,
                "trajectory_params": dict(self.trajectory_params),
                "method": self.method,
                "substeps": 0 if self.substeps is None else self.substeps,
                "boundary": self.boundary,
                "supersample": self.supersample,
            },
            "noise": {
                "model": self.noise_model,
                "levels": list(self.noise_levels),
                **({} if self.full_well is None else {"full_well": self.full_well}),
            },
            "dic": {
                "subsets": list(self.subsets),
                "step": self.step,
                "shape": self.dic_shape,
                "interpolation": self.interpolation,
                "max_iterations": self.max_iterations,
                "tolerance": self.tolerance,
                # only when on: the hashes of existing specs stay what they were
                **({} if self.compensation == "none" else {"compensation": self.compensation}),
            },
            "run": {"blur_chunk": self.blur_chunk},
        }

    def to_json(self) -> str:
        """Canonical JSON text (sorted keys, no whitespace variation)."""
        return json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":"))

    def content_hash(self) -> str:
        """SHA-256 of :meth:`to_json`: two specs that run the same experiment share it.

        Comments, key order and number spelling in the TOML file do not change it; image
        contents are hashed separately (see :func:`dicblur.campaign.input_hashes`).
        """
        return hashlib.sha256(self.to_json().encode()).hexdigest()

    def resolve_path(self, pattern: PatternSpec) -> Path:
        """Absolute path of an image pattern (relative paths are from the spec's folder)."""
        if pattern.path is None:
            raise ConfigError(f"pattern {pattern.name!r}: has no path (it is generated)")
        p = Path(os.path.expanduser(pattern.path))
        return p if p.is_absolute() else Path(self.base_dir) / p


def check_pattern_fits(spec: CampaignSpec, pattern: PatternSpec, shape: tuple[int, int]) -> None:
    """Refuse a pattern too small for the campaign's largest blur and subset.

    The blur path at the largest W must be shorter, along each image axis, than the
    pattern minus the largest subset: beyond, a blurred subset is smeared over the whole
    (periodic) pattern and every u_e would be NaN. Called by :func:`parse_spec` for
    generated and cropped patterns, and before any task for image files.

    Raises
    ------
    ConfigError
    """
    rows, cols = int(shape[0]), int(shape[1])
    s = max(spec.subsets)
    if s + 2 > min(rows, cols):
        raise ConfigError(
            f"dic.subsets={s}: pattern {pattern.name!r} is {rows}x{cols} px, "
            f"too small for a subset of {s} px plus a 1-px border; use "
            "smaller subsets or a larger pattern"
        )
    w = max(spec.blur)
    for a in spec.angles:
        dy = abs(w * math.sin(math.radians(a)))
        dx = abs(w * math.cos(math.radians(a)))
        for ext, size, axis in ((dx, cols, "columns"), (dy, rows, "rows")):
            if ext > size - s:
                room = (size - s) / max(
                    abs(math.cos(math.radians(a)))
                    if axis == "columns"
                    else abs(math.sin(math.radians(a))),
                    1e-12,
                )
                raise ConfigError(
                    f"blur.lengths: W = {w:g} px at angle {a:g} deg moves {ext:.4g} px along "
                    f"the {axis}, more than pattern {pattern.name!r} ({rows}x{cols} px) "
                    f"minus the subset ({s} px) allows: the blurred subsets would be smeared "
                    f"over the whole pattern and u_e would be NaN; use W <= {room:.4g} px "
                    "or a larger pattern"
                )


# -- parsing helpers -----------------------------------------------------------------------


# the shared checks of dicblur.checks, raising ConfigError named by the spec's key


def _err(key: str, value: Any, why: str) -> DicblurError:
    return bad_value(key, value, why, error=ConfigError)


def _number(value: Any, key: str) -> float:
    return check_finite_number(value, key, strict=True, error=ConfigError)


def _int(value: Any, key: str, *, minimum: int) -> int:
    return check_integer(value, key, minimum=minimum, error=ConfigError)


def _choice(value: Any, key: str, choices: tuple[str, ...]) -> str:
    return check_choice(value, key, choices, error=ConfigError)


def _list(value: Any, key: str) -> list[Any]:
    if isinstance(value, list | tuple):
        if not value:
            raise _err(key, value, "must not be empty")
        return list(value)
    return [value]


def _unique(values: list[Any], key: str) -> None:
    if len(set(values)) != len(values):
        raise _err(key, values, "values must be distinct (a duplicated grid point)")


def _clean(x: float) -> float:
    # 0.1 * 3 = 0.30000000000000004: round grid values so coordinates, seeds and hashes
    # do not depend on how a grid was spelled.
    return float(round(x, 10)) + 0.0


def _blur_lengths(value: Any) -> tuple[float, ...]:
    key = "blur.lengths"
    if isinstance(value, Mapping):
        unknown = set(value) - {"start", "stop", "step"}
        if unknown or {"start", "stop", "step"} - set(value):
            raise _err(
                key,
                dict(value),
                "a range needs exactly start, stop and step (px), "
                "e.g. {start = 0.1, stop = 10.0, step = 0.1}",
            )
        start = _number(value["start"], key + ".start")
        stop = _number(value["stop"], key + ".stop")
        step = _number(value["step"], key + ".step")
        if step <= 0 or stop < start:
            raise _err(key, dict(value), "need step > 0 and stop >= start")
        n = math.floor((stop - start) / step + 1e-9) + 1
        if n > _MAX_BLUR_VALUES:
            raise _err(key, dict(value), f"{n} values; at most {_MAX_BLUR_VALUES}")
        values = [_clean(start + i * step) for i in range(n)]
    else:
        values = [_clean(_number(v, key)) for v in _list(value, key)]
    if any(v < 0 for v in values):
        raise _err(key, value, "blur lengths W are px travelled during the exposure, >= 0")
    _unique(values, key)
    return tuple(values)


def _pattern(entry: Any, index: int) -> PatternSpec:
    where = f"pattern[{index}]"
    if not isinstance(entry, Mapping):
        raise _err(where, entry, "expected a table ([[pattern]] with name and generator or path)")
    unknown = sorted(set(entry) - _PATTERN_KEYS)
    if unknown:
        raise _err(
            f"{where}.{unknown[0]}",
            entry[unknown[0]],
            "unknown key; allowed: " + ", ".join(sorted(_PATTERN_KEYS)),
        )
    name = entry.get("name", f"pattern{index}")
    if not isinstance(name, str) or not name or name.strip() != name:
        raise _err(f"{where}.name", name, "expected a non-empty name without outer spaces")
    has_gen, has_path = "generator" in entry, "path" in entry
    if has_gen == has_path:
        raise _err(
            where,
            dict(entry),
            "give exactly one of 'generator' (speckle, paper4) and 'path' (an image file)",
        )
    crop = None
    if "crop" in entry:
        c = entry["crop"]
        if not isinstance(c, list) or len(c) != 4:
            raise _err(f"{where}.crop", c, "expected [row, col, rows, cols] in px")
        r0, c0 = (_int(v, f"{where}.crop", minimum=0) for v in c[:2])
        nr, nc = (_int(v, f"{where}.crop", minimum=8) for v in c[2:])
        crop = (r0, c0, nr, nc)
    if has_path:
        extra = sorted(set(entry) - {"name", "path", "crop"})
        if extra:
            raise _err(
                f"{where}.{extra[0]}",
                entry[extra[0]],
                "generator settings do not apply to an image file",
            )
        path = entry["path"]
        if not isinstance(path, str) or not path:
            raise _err(f"{where}.path", path, "expected an image file path")
        return PatternSpec(name=name, path=path, crop=crop)
    gen = _choice(entry["generator"], f"{where}.generator", GENERATORS)
    settings: dict[str, Any] = {}
    for key in sorted(set(entry) - {"name", "generator", "crop"}):
        if key not in _GENERATOR_KEYS[gen]:
            raise _err(
                f"{where}.{key}",
                entry[key],
                f"not a setting of generator {gen!r}; "
                "allowed: " + ", ".join(sorted(_GENERATOR_KEYS[gen])),
            )
        value = entry[key]
        if key == "shape":
            if isinstance(value, int) and not isinstance(value, bool):
                value = [value, value]
            if not isinstance(value, list) or len(value) != 2:
                raise _err(f"{where}.shape", value, "expected [rows, cols] in px")
            value = [_int(v, f"{where}.shape", minimum=16) for v in value]
        elif key in ("seed", "supersample"):
            value = _int(value, f"{where}.{key}", minimum=0 if key == "seed" else 1)
        else:
            value = _number(value, f"{where}.{key}")
        settings[key] = value
    if "shape" not in settings:
        raise _err(f"{where}.shape", None, "a generated pattern needs shape = [rows, cols]")
    return PatternSpec(name=name, generator=gen, settings=settings, crop=crop)


def parse_spec(data: Mapping[str, Any], *, base_dir: str | os.PathLike[str] = ".") -> CampaignSpec:
    """Validate a campaign spec given as a dict (the parsed TOML) and return it.

    Parameters
    ----------
    data : mapping
        Sections ``campaign``, ``pattern`` (a list of tables), ``blur``, ``noise``,
        ``dic`` and ``run``; see the module docs.
    base_dir : path
        Folder against which relative image paths are resolved.

    Raises
    ------
    ConfigError
        Naming the first offending key, its value and the fix.
    """
    if not isinstance(data, Mapping):
        raise ConfigError("spec: expected a table of sections (campaign, pattern, blur, ...)")
    allowed = set(_SECTIONS) | {"pattern"}
    for key in data:
        if key not in allowed:
            raise _err(key, data[key], "unknown section; allowed: " + ", ".join(sorted(allowed)))
    sec: dict[str, Mapping[str, Any]] = {}
    for name, keys in _SECTIONS.items():
        s = data.get(name, {})
        if not isinstance(s, Mapping):
            raise _err(name, s, f"expected a table [{name}]")
        for key in s:
            if key not in keys:
                raise _err(
                    f"{name}.{key}", s[key], "unknown key; allowed: " + ", ".join(sorted(keys))
                )
        sec[name] = s

    camp = sec["campaign"]
    name = camp.get("name", "campaign")
    if not isinstance(name, str):
        raise _err("campaign.name", name, "expected a string")
    description = camp.get("description", "")
    if not isinstance(description, str):
        raise _err("campaign.description", description, "expected a string")
    if "seed" not in camp:
        raise _err(
            "campaign.seed",
            None,
            "a base seed is required (e.g. seed = 1): it makes every task reproducible",
        )
    seed = _int(camp["seed"], "campaign.seed", minimum=0)
    repetitions = _int(camp.get("repetitions", 1), "campaign.repetitions", minimum=1)

    raw_patterns = data.get("pattern")
    if raw_patterns is None:
        raise ConfigError(
            "pattern: at least one [[pattern]] table is required "
            '(generator = "paper4" or path = "image.tif")'
        )
    if isinstance(raw_patterns, Mapping):
        raw_patterns = [raw_patterns]
    if not isinstance(raw_patterns, list) or not raw_patterns:
        raise _err("pattern", raw_patterns, "expected one or more [[pattern]] tables")
    patterns = tuple(_pattern(p, i) for i, p in enumerate(raw_patterns))
    _unique([p.name for p in patterns], "pattern.name")

    blur = sec["blur"]
    if "lengths" not in blur:
        raise _err("blur.lengths", None, "required: a list of W (px) or {start, stop, step}")
    lengths = _blur_lengths(blur["lengths"])
    angles = tuple(
        _clean(_number(a, "blur.angles")) for a in _list(blur.get("angles", [0.0]), "blur.angles")
    )
    _unique(list(angles), "blur.angles")
    trajectory = _choice(
        blur.get("trajectory", "linear"), "blur.trajectory", ("linear", "sine", "acceleration")
    )
    tparams = blur.get("trajectory_params", {})
    if not isinstance(tparams, Mapping) or not all(
        isinstance(v, int | float) and not isinstance(v, bool) for v in tparams.values()
    ):
        raise _err("blur.trajectory_params", tparams, "expected a table of numbers")
    method = _choice(blur.get("method", "transfer"), "blur.method", BLUR_METHODS)
    substeps_raw = _int(blur.get("substeps", 100), "blur.substeps", minimum=0)
    substeps = None if substeps_raw == 0 else substeps_raw
    boundary = _choice(blur.get("boundary", "periodic"), "blur.boundary", ("periodic", "reflect"))
    supersample = _int(blur.get("supersample", 8), "blur.supersample", minimum=1)
    if method == "rendered":
        for p in patterns:
            if p.generator != "speckle" or "supersample" in p.settings:
                raise _err(
                    "blur.method",
                    method,
                    f"pattern {p.name!r}: rendering draws the "
                    'pattern on a fine grid, so it needs generator = "speckle" '
                    'without its own supersample (or use method = "transfer")',
                )

    noise = sec["noise"]
    model = _choice(noise.get("model", "per-subframe"), "noise.model", NOISE_MODELS)
    levels = tuple(
        _clean(_number(v, "noise.levels"))
        for v in _list(noise.get("levels", [2.0]), "noise.levels")
    )
    if any(v < 0 for v in levels):
        raise _err("noise.levels", list(levels), "noise std in grey levels must be >= 0")
    _unique(list(levels), "noise.levels")
    if model == "per-subframe" and substeps is None:
        raise _err(
            "noise.model",
            model,
            "per-subframe noise needs a finite blur.substeps "
            "(K + 1 sub-frames); use per-exposure with substeps = 0",
        )
    full_well = None
    if model == "poisson-gaussian":
        if "full_well" not in noise:
            raise _err(
                "noise.full_well",
                None,
                "poisson-gaussian needs full_well (electrons at grey level 255), e.g. 20000",
            )
        full_well = _number(noise["full_well"], "noise.full_well")
        if full_well <= 0:
            raise _err("noise.full_well", full_well, "must be > 0 electrons")
    elif "full_well" in noise:
        raise _err(
            "noise.full_well", noise["full_well"], 'applies to model = "poisson-gaussian" only'
        )

    dic = sec["dic"]
    subsets = tuple(
        _int(s, "dic.subsets", minimum=5) for s in _list(dic.get("subsets", [31]), "dic.subsets")
    )
    for s in subsets:
        if s % 2 == 0:
            raise _err("dic.subsets", s, f"subset sizes must be odd (use {s - 1} or {s + 1})")
    _unique(list(subsets), "dic.subsets")
    step = _int(dic.get("step", 10), "dic.step", minimum=1)
    dic_shape = _choice(dic.get("shape", "translation"), "dic.shape", DIC_SHAPES)
    interpolation = _choice(
        dic.get("interpolation", "bspline3"), "dic.interpolation", INTERPOLATIONS
    )
    max_iterations = _int(dic.get("max_iterations", 50), "dic.max_iterations", minimum=1)
    tolerance = _number(dic.get("tolerance", 1e-4), "dic.tolerance")
    if tolerance <= 0:
        raise _err("dic.tolerance", tolerance, "must be > 0")

    compensation = _choice(dic.get("compensation", "none"), "dic.compensation", COMPENSATIONS)
    if compensation != "none":
        if trajectory != "linear":
            raise _err(
                "dic.compensation",
                compensation,
                "the compensated matcher models linear motion (a centred box); "
                'use blur.trajectory = "linear"',
            )
        if max(lengths) >= min(subsets):
            raise _err(
                "dic.compensation",
                compensation,
                f"blur lengths up to {max(lengths):g} px need subsets larger than "
                f"that (smallest: {min(subsets)} px)",
            )

    blur_chunk = _int(sec["run"].get("blur_chunk", 10), "run.blur_chunk", minimum=1)
    blur_chunk = min(blur_chunk, len(lengths))

    n_tasks = len(patterns) * len(angles) * len(subsets) * len(levels) * len(lengths) * repetitions
    if n_tasks > MAX_TASKS:
        raise _err(
            "campaign.repetitions",
            repetitions,
            f"{n_tasks:.4g} tasks in all ({len(patterns)} pattern(s) x {len(angles)} "
            f"angle(s) x {len(subsets)} subset(s) x {len(levels)} noise level(s) x "
            f"{len(lengths)} W x {repetitions} repetition(s)); at most "
            f"{MAX_TASKS:.0e} tasks per campaign: split it or use fewer repetitions",
        )
    for p in patterns:
        if p.generator is not None:
            ss = supersample if method == "rendered" else int(p.settings.get("supersample", 1))
            try:
                check_pixels(
                    tuple(p.settings["shape"]), f"pattern {p.name!r} shape", factor=ss * ss
                )
            except InputError as exc:
                raise ConfigError(str(exc)) from None

    spec = CampaignSpec(
        name=name,
        seed=seed,
        patterns=patterns,
        blur=lengths,
        angles=angles,
        trajectory=trajectory,
        trajectory_params=dict(tparams),
        method=method,
        substeps=substeps,
        boundary=boundary,
        supersample=supersample,
        noise_model=model,
        noise_levels=levels,
        full_well=full_well,
        subsets=subsets,
        step=step,
        dic_shape=dic_shape,
        compensation=compensation,
        interpolation=interpolation,
        max_iterations=max_iterations,
        tolerance=tolerance,
        repetitions=repetitions,
        blur_chunk=blur_chunk,
        description=description,
        base_dir=str(Path(base_dir).resolve()),
    )
    for p in patterns:
        if p.crop is not None:
            check_pattern_fits(spec, p, (p.crop[2], p.crop[3]))
        elif p.generator is not None:
            check_pattern_fits(spec, p, tuple(p.settings["shape"]))
    return spec


def load_spec(path: str | os.PathLike[str]) -> CampaignSpec:
    """Read and validate a campaign spec TOML file.

    Raises
    ------
    ConfigError
        If the file is missing, is not valid TOML, or a key is invalid.
    """
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"spec={str(p)!r}: no such file; give a campaign spec .toml")
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8-sig"))  # a BOM from a text editor
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"spec={str(p)!r}: not valid TOML ({exc})") from exc
    return parse_spec(data, base_dir=p.parent)
