"""The schema of a model JSON file (``dicblur fit -o``), checked on every load.

The schema is a table: one :class:`Rule` per key, for the model and for each fit result
inside it. To add a field to :class:`~dicblur.models.BlurUncertaintyModel` or
:class:`~dicblur.models.FitResult`, add its rule to :data:`MODEL_RULES` or
:data:`FIT_RULES` (``required=False`` if files written before it must still load) and,
if old files must be told apart, bump :data:`SCHEMA_VERSION`.

:func:`validate_model_dict` turns every defect (a missing key, a wrong type, NaN where a
number must be finite, a list of the wrong length) into one
:class:`~dicblur.errors.InputError` naming the file, the key path and what was expected;
nothing reaches the model's constructor unchecked.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from ..errors import InputError

__all__ = [
    "DOMAIN_RULES",
    "FIT_RULES",
    "MODEL_RULES",
    "SCHEMA",
    "SCHEMA_V1",
    "SCHEMA_VERSION",
    "STATIC_TABLE_RULES",
    "Rule",
    "validate_model_dict",
]

SCHEMA_NAME = "dicblur.BlurUncertaintyModel"
SCHEMA_VERSION = 3
SCHEMA = f"{SCHEMA_NAME}/{SCHEMA_VERSION}"
#: /1: the power law as ``eta`` and no validity domain (upgraded on load by the model)
SCHEMA_V1 = f"{SCHEMA_NAME}/1"
#: /2: no static kind (``static`` absent; loads as None)
READABLE_VERSIONS = ("1", "2", "3")

Check = Callable[[Any], str | None]  # returns why the value is wrong, or None


@dataclass(frozen=True)
class Rule:
    """How one key is checked: ``check(value)`` returns what is wrong, or None."""

    check: Check
    expected: str
    required: bool = True


def _is_num(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def number(
    *,
    finite: bool = True,
    nan: bool = False,
    minimum: float | None = None,
    low: float | None = None,
    high: float | None = None,
) -> Check:
    """A JSON number; ``finite`` refuses +-inf, ``nan`` allows NaN, bounds are inclusive
    (``minimum``) or exclusive (``low``, ``high``)."""

    def check(v: Any) -> str | None:
        if not _is_num(v):
            return "not a number"
        x = float(v)
        if math.isnan(x):
            return None if nan else "NaN"
        if finite and math.isinf(x):
            return "infinite"
        if minimum is not None and x < minimum:
            return f"below {minimum:g}"
        if (low is not None and x <= low) or (high is not None and x >= high):
            return "out of range"
        return None

    return check


def integer(minimum: int = 0) -> Check:
    def check(v: Any) -> str | None:
        if isinstance(v, bool) or not isinstance(v, int):
            return "not an integer"
        return None if v >= minimum else f"below {minimum}"

    return check


def string(choices: tuple[str, ...] | None = None) -> Check:
    def check(v: Any) -> str | None:
        if not isinstance(v, str):
            return "not a string"
        if choices is not None and v not in choices:
            return "not one of " + ", ".join(repr(c) for c in choices)
        return None

    return check


def optional(inner: Check) -> Check:
    """``inner`` or JSON null."""
    return lambda v: None if v is None else inner(v)


def array(item: Check, *, length: int | None = None, nonempty: bool = False) -> Check:
    def check(v: Any) -> str | None:
        if not isinstance(v, list):
            return "not a list"
        if length is not None and len(v) != length:
            return f"{len(v)} items, expected {length}"
        if nonempty and not v:
            return "empty"
        for i, x in enumerate(v):
            why = item(x)
            if why is not None:
                return f"item {i} is {why}"
        return None

    return check


def mapping(value: Check | None = None) -> Check:
    def check(v: Any) -> str | None:
        if not isinstance(v, dict):
            return "not a table"
        if value is not None:
            for k, x in v.items():
                why = value(x)
                if why is not None:
                    return f"{k!r} is {why}"
        return None

    return check


def anything(v: Any) -> str | None:
    return None


_FINITE = number()
_BOUND = number(finite=False)  # an interval end may be +-inf (an unconstrained factor)

FIT_RULES: dict[str, Rule] = {
    "model": Rule(string(), "a fit name"),
    "names": Rule(array(string()), "a list of parameter names"),
    "values": Rule(array(_FINITE), "a list of finite numbers"),
    "covariance": Rule(array(array(_FINITE)), "a matrix of finite numbers"),
    "low": Rule(array(_BOUND), "a list of numbers"),
    "high": Rule(array(_BOUND), "a list of numbers"),
    "fixed": Rule(mapping(_FINITE), "a table of finite numbers"),
    "r2": Rule(number(nan=True), "a number"),
    "residual_std": Rule(number(minimum=0.0), "a finite number >= 0"),
    "residuals": Rule(array(number(nan=True)), "a list of numbers"),
    "dof": Rule(integer(1), "an integer >= 1"),
    "n_points": Rule(integer(1), "an integer >= 1"),
    "blur_range": Rule(array(number(minimum=0.0), length=2), "[W_min, W_max] in px"),
    "confidence": Rule(number(low=0.0, high=1.0), "a number in (0, 1)"),
    "ci_method": Rule(
        string(("covariance", "bootstrap", "unidentified")),
        "'covariance', 'bootstrap' or 'unidentified'",
    ),
    "extra": Rule(mapping(), "a table", required=False),
}


def _fit(v: Any) -> str | None:
    if not isinstance(v, dict):
        return "not a table"
    _check_table(v, FIT_RULES, "")  # a defect inside names its own key
    n = len(v["names"])
    for key in ("values", "low", "high"):
        if len(v[key]) != n:
            raise _Defect(f".{key}", f"{len(v[key])} items for {n} parameter names")
    if len(v["covariance"]) != n or any(len(r) != n for r in v["covariance"]):
        raise _Defect(".covariance", f"not a {n}x{n} matrix")
    return None


def _fit_of(allowed: frozenset[str], *required: frozenset[str]) -> Callable[[Any], str | None]:
    """A fit result whose parameter names are unique, among ``allowed``, and cover one of
    each ``required`` set (in ``names`` or ``fixed``): a renamed or blank parameter is a
    damaged file, not a KeyError at prediction time."""

    def check(v: Any) -> str | None:
        why = _fit(v)
        if why is not None:
            return why
        names = list(v["names"])
        if len(set(names)) != len(names):
            raise _Defect(".names", f"repeated parameter names {names}")
        odd = [n for n in names if n not in allowed]
        if odd:
            raise _Defect(".names", f"unknown parameter {odd[0]!r} (expected {sorted(allowed)})")
        have = set(names) | set(v["fixed"])
        for need in required:
            if not have & need:
                raise _Defect(".names", f"no parameter {' or '.join(sorted(need))!r}")
        return None

    return check


_DECAY_FIT = _fit_of(frozenset({"sssig0", "beta"}), frozenset({"sssig0"}), frozenset({"beta"}))
# "eta": the schema-1 power law (u_e = eta SSSIG^-alpha), converted on load
_POWER_FIT = _fit_of(
    frozenset({"u_ref", "eta", "alpha", "kappa"}), frozenset({"u_ref", "eta"}), frozenset({"alpha"})
)
_MISMATCH_FIT = _fit_of(
    frozenset({"a", "k", "gamma", "noise_blur2", "noise_blur", "floor", "cross", "c", "c4"}),
    frozenset({"a", "k"}),
    frozenset({"c"}),
)


DOMAIN_RULES: dict[str, Rule] = {
    "blur_min": Rule(number(minimum=0.0), "W_min >= 0 px"),
    "blur_max": Rule(number(finite=False, minimum=0.0), "W_max >= 0 px"),
    "noise_min": Rule(optional(number(minimum=0.0)), "a noise std >= 0 GL or null"),
    "noise_max": Rule(optional(number(finite=False, minimum=0.0)), "a noise std >= 0 GL or null"),
    "subset": Rule(optional(integer(1)), "a subset size in px or null"),
    "shape": Rule(optional(string()), "a shape name or null"),
    "pattern": Rule(optional(string()), "a pattern name or null"),
    "pattern_sha256": Rule(optional(string()), "a hash or null"),
    "breakdown_blur": Rule(optional(number(minimum=0.0)), "a W in px or null"),
    "breakdown_rule": Rule(optional(string()), "a string or null"),
    # matcher mode (issue 18); files written before it are the plain matcher ("none")
    "compensation": Rule(
        string(("none", "given", "estimate", "deblur")),
        "'none', 'given', 'estimate' or 'deblur'",
        required=False,
    ),
}


def _grid(v: Any) -> str | None:
    """A strictly increasing W grid from 0 px."""
    why = array(number(minimum=0.0), nonempty=True)(v)
    if why is not None:
        return why
    if len(v) < 2 or float(v[0]) != 0.0:
        return "not a grid from W = 0 with >= 2 points"
    if any(float(b) <= float(a) for a, b in itertools.pairwise(v)):
        return "not strictly increasing"
    return None


#: the static kind's table in its fit's ``extra`` (docs/models.md s. 4)
STATIC_TABLE_RULES: dict[str, Rule] = {
    "table_blur": Rule(_grid, "a strictly increasing W grid from 0 px"),
    "table_noise": Rule(array(number(minimum=0.0)), "noise variances >= 0 px^2/GL^2"),
    "table_noise2": Rule(array(number(minimum=0.0)), "noise interactions >= 0 px^2/GL^4"),
    "table_mismatch": Rule(array(number(minimum=0.0)), "noise-free variances >= 0 px^2"),
    "table_valid_fraction": Rule(array(number(minimum=0.0)), "fractions of subsets in [0, 1]"),
    "table_breakdown_blur": Rule(optional(number(minimum=0.0)), "a W in px or null"),
    "subpixel": Rule(string(), "the sub-pixel offset rule"),
    "noise_levels": Rule(array(number(minimum=0.0)), "a list of noise stds >= 0 GL"),
}


def _static_fit(v: Any) -> str | None:
    """A fit result of the static kind: two scales and a consistent table."""
    why = _fit(v)
    if why is not None:
        return why
    if list(v["names"]) != ["k_noise", "k_blur"]:
        raise _Defect(".names", "not ['k_noise', 'k_blur'] (the static kind's scales)")
    if any(float(x) <= 0 for x in v["values"]):
        raise _Defect(".values", "a scale <= 0")
    extra = v.get("extra")
    if not isinstance(extra, dict):
        raise _Defect(".extra", "missing (expected the static prediction's table)")
    try:
        _check_table(extra, STATIC_TABLE_RULES, "")
    except _Defect as inner:
        raise _Defect(f".extra{inner.where}", inner.why) from None
    n = len(extra["table_blur"])
    for key in ("table_noise", "table_noise2", "table_mismatch", "table_valid_fraction"):
        if len(extra[key]) != n:
            raise _Defect(f".extra.{key}", f"{len(extra[key])} items for {n} grid points")
    return None


def _domain(v: Any) -> str | None:
    if v is None:
        return None
    if not isinstance(v, dict):
        return "not a table"
    _check_table(v, DOMAIN_RULES, "")
    return None


MODEL_RULES: dict[str, Rule] = {
    "schema": Rule(string(), f"{SCHEMA!r}"),
    "default": Rule(
        string(("mismatch", "power_law", "static")), "'mismatch', 'power_law' or 'static'"
    ),
    "decay": Rule(_DECAY_FIT, "a fit result (SSSIG decay)"),
    "power_law": Rule(_POWER_FIT, "a fit result (power law)"),
    "mismatch": Rule(optional(_MISMATCH_FIT), "a fit result or null"),
    "fit_range": Rule(array(number(minimum=0.0), length=2), "[W_lo, W_hi] in px"),
    "range_rule": Rule(string(), "a string"),
    "noise_sigma": Rule(optional(number(minimum=0.0)), "a noise std >= 0 GL or null"),
    "noise_levels": Rule(array(number(minimum=0.0)), "a list of noise stds >= 0 GL"),
    "subset": Rule(optional(integer(1)), "a subset size in px or null"),
    "mean_level": Rule(optional(_FINITE), "a grey level or null"),
    "c_static": Rule(optional(_FINITE), "a finite number or null"),
    "data": Rule(mapping(array(number(nan=True))), "a table of number lists"),
    "comparison": Rule(optional(mapping()), "a table or null"),
    "provenance": Rule(mapping(), "a table"),
    "version": Rule(string(), "a version string"),
    "confidence": Rule(number(low=0.0, high=1.0), "a number in (0, 1)"),
    "domain": Rule(_domain, "a validity-domain table or null", required=False),
    "static": Rule(optional(_static_fit), "a static-kind fit result or null", required=False),
}


class _Defect(Exception):
    def __init__(self, where: str, why: str) -> None:
        super().__init__(where, why)
        self.where, self.why = where, why


def _check_table(d: Mapping[str, Any], rules: Mapping[str, Rule], where: str) -> None:
    for key, rule in rules.items():
        if key not in d:
            if rule.required:
                raise _Defect(f"{where}.{key}", f"missing (expected {rule.expected})")
            continue
        try:
            why = rule.check(d[key])
        except _Defect as inner:
            raise _Defect(f"{where}.{key}{inner.where}", inner.why) from None
        if why is not None:
            raise _Defect(f"{where}.{key}", f"{why} (expected {rule.expected})")
    unknown = sorted(set(d) - set(rules))
    if unknown:
        raise _Defect(f"{where}.{unknown[0]}", "unknown key (a newer or edited file?)")


def validate_model_dict(d: Any, source: str = "model") -> dict[str, Any]:
    """Check a parsed model file against the schema and return it.

    Parameters
    ----------
    d : any
        The result of ``json.loads`` on the file.
    source : str
        What to call the file in messages (its path).

    Raises
    ------
    InputError
        ``"<source>: <key path>: <what is wrong>; ..."``, one line.
    """
    fix = "refit it with dicblur fit, or restore the file written by it"
    if not isinstance(d, dict):
        raise InputError(
            f"{source}: not a dicblur model file (expected a JSON object with "
            f"schema {SCHEMA!r}, got a {type(d).__name__}); {fix}"
        )
    tag = d.get("schema")
    if not isinstance(tag, str) or not tag.startswith(SCHEMA_NAME + "/"):
        raise InputError(
            f"{source}: not a dicblur model file (schema must be {SCHEMA!r}, got {tag!r}); {fix}"
        )
    version = tag.rpartition("/")[2]
    if version not in READABLE_VERSIONS:
        raise InputError(
            f"{source}: model schema version {version!r}, this dicblur reads "
            f"versions {', '.join(READABLE_VERSIONS)}; refit the model with "
            "this dicblur"
        )
    try:
        _check_table(d, MODEL_RULES, "")
        if d["default"] == "static" and d.get("static") is None:
            raise _Defect(".default", "'static' but the file has no static kind")
    except _Defect as defect:
        raise InputError(f"{source}: key {defect.where.lstrip('.')}: {defect.why}; {fix}") from None
    return d
