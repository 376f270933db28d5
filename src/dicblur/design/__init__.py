"""Pattern design: choose and export the speckle pattern that best resists a given blur.

The paper's conclusion (Lavatelli & Zappa 2017, Fig. 11) is that noise rejection and blur
resistance cannot both be maximised, so the pattern must be chosen for the application.
This stage does it: a family of generated patterns (:class:`PatternFamily`) is swept
through campaigns (:mod:`dicblur.campaign`'s task function), each candidate's blur model is
fitted (:mod:`dicblur.models`), the family is searched for the lowest predicted u_e at the
user's blur (:func:`design_pattern`), the winner is confirmed on fresh seeds and exported
print-ready (:func:`export_pattern`). See docs/design.md.

Campaign, models, scipy and matplotlib are imported inside the functions that use them.
"""

from __future__ import annotations

from .evaluate import Evaluation, evaluate_candidate, surrogate
from .export import PrintExport, export_pattern, regenerate
from .family import DEFAULT_CANDIDATE, Candidate, PatternFamily
from .problem import DesignProblem, design_problem, sine_blur_distribution
from .search import Confirmation, DesignResult, confirm, design_pattern

__all__ = [
    "DEFAULT_CANDIDATE",
    "Candidate",
    "Confirmation",
    "DesignProblem",
    "DesignResult",
    "Evaluation",
    "PatternFamily",
    "PrintExport",
    "confirm",
    "design_pattern",
    "design_problem",
    "evaluate_candidate",
    "export_pattern",
    "regenerate",
    "sine_blur_distribution",
    "surrogate",
]
