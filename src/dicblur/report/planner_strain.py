"""The planner page's strain-target controls (issue 28, docs/strain.md "Planning").

The page plans for a displacement target (px) or, with the target unit set to strain, for a
strain-uncertainty target at a virtual strain gauge (VSG) of ``(N - 1) step + subset`` px:
its script (``report/js/planner_strain.js``) mirrors :func:`dicblur.strain.plan.plan_strain`
and shows the VSG / uncertainty trade-off as a table (longest exposure per VSG).
"""

from __future__ import annotations

import html
from typing import Any

__all__ = ["strain_fieldset", "strain_results"]


def strain_fieldset(*, strain_target: str | None, vsg: str, step: int, subset: int | None) -> str:
    """The form's "Target" fieldset: the unit selector (px | strain) and the strain
    controls, starting in strain mode when ``strain_target`` is given."""

    def val(x: Any) -> str:
        return html.escape(str(x), quote=True)

    strain = strain_target is not None
    sub = "" if subset is None else val(subset)
    return f"""<fieldset><legend>Target</legend>
<label for="target-unit">plan for a target in</label><select id="target-unit">
<option value="px"{"" if strain else " selected"}>displacement (px, um)</option>
<option value="strain"{" selected" if strain else ""}>strain (microstrain)</option></select>
<div id="strain-box"{"" if strain else " hidden"}>
<label for="strain-target">strain uncertainty target (microstrain, %, or a number)</label>
<input type="text" id="strain-target" value="{val(strain_target or "100microstrain")}">
<label for="vsg">virtual strain gauge: px, (N - 1) x step + subset, or N points</label>
<input type="text" id="vsg" value="{val(vsg)}">
<label for="strain-step">POI grid step (px)</label>
<input type="number" id="strain-step" min="1" step="1" value="{val(step)}">
<label for="strain-subset">subset (px)</label>
<input type="number" id="strain-subset" min="5" step="2" value="{sub}"></div></fieldset>"""


def strain_results() -> str:
    """The strain rows of the results: sigma_exx at the plan and the VSG trade-off table."""
    return """<table class="out" id="strain-out" hidden>
<tr><th>sigma_exx at the longest exposure</th><td id="out-strain"></td></tr></table>
<table class="out" id="tradeoff" hidden aria-label="VSG trade-off">
<caption>VSG / uncertainty trade-off at this speed and noise</caption>
<thead><tr><th>VSG (px)</th><th>longest exposure meeting the target</th>
<th>sigma_exx at the planned exposure</th></tr></thead><tbody id="tradeoff-body"></tbody>
</table>"""
