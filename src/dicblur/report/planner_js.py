"""The planner page's script (plain ES2017, no library): model evaluation and the UI.

Inlined in the page so that it is one self-contained file. The script is kept in parts,
package data under ``report/js/`` (joined in this order, one function scope opened in the
first and closed in the last, so a part is not a script on its own): ``planner_units.js``
(the CLI's unit parsers), ``planner_model.js`` (the model), ``planner_solvers.js`` (the
root finding and minimisation), ``planner_format.js`` (formatting, validity domain,
matcher modes), ``planner_strain.js`` (the strain target, :func:`dicblur.strain.plan.plan_strain`),
``planner_ui.js`` (the page). The model functions mirror
:meth:`dicblur.BlurUncertaintyModel.predict` (``_log_u``, ``_mismatch_terms``, the static
kind's table interpolation of :mod:`dicblur.models.scaled`, the delta-method interval) and
:func:`dicblur.plan_exposure` line by line; the equality test (``tests/test_planner.py``)
holds them to 1e-9 relative on u_e.
"""

from __future__ import annotations

from importlib.resources import files

__all__ = ["PLANNER_JS", "PLANNER_JS_PARTS"]

#: The parts of the script under ``report/js/``, in page order.
PLANNER_JS_PARTS = (
    "planner_units.js",
    "planner_model.js",
    "planner_solvers.js",
    "planner_format.js",
    "planner_strain.js",
    "planner_ui.js",
)

PLANNER_JS = "".join(
    files(__package__).joinpath("js", name).read_text(encoding="utf-8") for name in PLANNER_JS_PARTS
)
