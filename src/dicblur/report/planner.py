"""The interactive exposure planner: one self-contained HTML page per calibrated pattern.

The page carries the fitted model(s) as JSON data and evaluates them in its own script
(:mod:`dicblur.report.planner_js`, no network, no library) with the formulas of
:meth:`dicblur.BlurUncertaintyModel.predict` and :func:`dicblur.plan_exposure`. Inputs are
typed with units as on the CLI (``120mm/s``, ``0.05mm/px``, ``1ms``, ``0.01px``); noise is
given in grey levels or as a camera (full well, read noise, and either the photon flux or
the grey level reached at the chosen exposure).
"""

from __future__ import annotations

import html
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import InputError
from .planner_js import PLANNER_JS
from .planner_strain import strain_fieldset, strain_results

__all__ = [
    "PlannerDefaults",
    "planner_html",
    "planner_payload",
    "starting_noise",
    "write_planner",
]

#: Size budget of a page (bytes); the test holds it.
SIZE_BUDGET = 300_000


@dataclass(frozen=True)
class PlannerDefaults:
    """Initial values of the page's controls, as the user would type them."""

    velocity: str = "120mm/s"
    scale: str = "0.05mm/px"
    exposure: str = "1ms"
    target: str = "0.01px"
    noise: float | None = None
    full_well: float | None = None
    read_noise: float | None = None
    flux: float | None = None
    bit_depth: int = 8
    grey_level: float | None = None
    #: a strain target (``"100microstrain"``): the page starts planning for it
    strain_target: str | None = None
    vsg: str = "41px"
    step: int = 10
    subset: int | None = None


def starting_noise(model: Any, noise: float | None = None) -> float:
    """The noise (GL) the page's noise control starts at: ``noise`` when given, else the
    model's own noise (one calibration level), else its smallest calibration level (a
    model fitted on several), else 2 GL. The page lets the user choose any other value;
    ``dicblur plan --html`` prints its text plan at this noise too, and says so."""
    if noise is not None:
        return float(noise)
    if model.noise_sigma is not None:
        return float(model.noise_sigma)
    return float(model.noise_levels[0]) if model.noise_levels else 2.0


def _fit_payload(fit: Any) -> dict[str, Any]:
    cov = [[float(x) for x in row] for row in fit.covariance]
    finite = all(math.isfinite(x) for row in cov for x in row)
    return {
        "names": list(fit.names),
        "values": [float(v) for v in fit.values],
        # JSON has no inf/NaN: an unidentified covariance is sent as zeros plus a flag
        # (the interval is then unbounded, as in BlurUncertaintyModel.predict)
        "covariance": cov if finite else [[0.0] * len(cov) for _ in cov],
        "covariance_finite": finite,
        "fixed": {k: float(v) for k, v in fit.fixed.items()},
        "extra": {
            k: (list(v) if isinstance(v, list | tuple) else v)
            for k, v in fit.extra.items()
            if isinstance(v, int | float | str | list | tuple) or v is None
        },
        "residual_std": float(fit.residual_std),
        "dof": int(fit.dof),
        "t_quantile": float(fit.t_quantile),
    }


def planner_payload(model: Any, *, label: str | None = None) -> dict[str, Any]:
    """The JSON data the page's script evaluates for one model.

    Everything :meth:`BlurUncertaintyModel.predict` reads: the default model, both fits
    (names, values, covariance, fixed parameters, residual scatter, Student-t quantile of
    the interval), the SSSIG decay, the noise of the data, the mean grey level, and the
    validity domain (W and noise ranges of the fitted data).
    """
    from ..models import BlurUncertaintyModel

    if not isinstance(model, BlurUncertaintyModel):
        raise InputError("model: expected a BlurUncertaintyModel (dicblur fit / calibrate)")
    prov = model.provenance or {}
    pat = prov.get("pattern")
    if isinstance(pat, dict):  # dicblur calibrate records the campaign's pattern table
        pat = pat.get("name")
    name = label or str(pat or prov.get("name") or "calibrated pattern")
    subset = f", subset {model.subset} px" if model.subset else ""
    dom = model.domain.to_dict() if model.domain is not None else None
    if dom is not None:
        dom = {
            k: (None if isinstance(v, float) and not math.isfinite(v) else v)
            for k, v in dom.items()
        }
    return {
        "label": f"{Path(name).name}{subset}",
        "default": model.default,
        "mismatch": None if model.mismatch is None else _fit_payload(model.mismatch),
        "static": None if model.static is None else _fit_payload(model.static),
        "power_law": _fit_payload(model.power_law),
        "decay": _fit_payload(model.decay),
        "noise_sigma": model.noise_sigma,
        "noise_levels": [float(x) for x in model.noise_levels],
        "mean_level": model.mean_level,
        "subset": model.subset,
        "confidence": float(model.confidence),
        "fit_range": [float(model.fit_range[0]), float(model.fit_range[1])],
        "domain": dom,
    }


def _json_for_script(data: Any) -> str:
    text = json.dumps(data, allow_nan=False, separators=(",", ":"))
    # inside <script>: no "</" so no "</script>" can end the block early
    return text.replace("</", "<\\/")


_CSS = """
body{font-family:-apple-system,Segoe UI,Helvetica,Arial,sans-serif;margin:1em auto;
max-width:1200px;padding:0 1em;color:#1d2329;line-height:1.4}
h1{font-size:1.4em;border-bottom:2px solid #2a6f97;padding-bottom:.2em;margin:.2em 0 .6em}
.grid{display:grid;grid-template-columns:360px 1fr;gap:1.2em}
fieldset{border:1px solid #c9d3dc;border-radius:4px;margin:0 0 .7em;padding:.4em .8em .6em}
legend{color:#2a6f97;font-weight:600}
label{display:block;font-size:.9em;margin:.35em 0 .1em}
label.inline{display:inline;margin-right:1em}
input[type=text],input[type=number],select{width:100%;box-sizing:border-box;padding:.3em;
font-size:1em;border:1px solid #9aa8b5;border-radius:3px}
input:focus,select:focus{outline:3px solid #f0b429;outline-offset:1px}
#sentence{font-size:1.25em;font-weight:600;background:#eef3f7;border-left:5px solid #2a6f97;
padding:.6em .9em;margin:0 0 .8em}
table.out{border-collapse:collapse;width:100%;font-size:.95em}
table.out th{text-align:left;font-weight:500;color:#44515c;padding:.2em .5em .2em 0;width:40%}
table.out td{padding:.2em 0}
#message{color:#b00020;min-height:1.2em;font-weight:600}
svg{width:100%;height:auto;background:#fff}
.frame{fill:none;stroke:#44515c}.tick{stroke:#44515c}.curve{fill:none;stroke:#2a6f97;
stroke-width:2.5}.target{stroke:#b35900;stroke-dasharray:6 4;stroke-width:1.5}
.opt{fill:#1a7f37}.curve2{fill:none;stroke:#7b3294;stroke-width:2.5;stroke-dasharray:9 4}
.opt2{fill:#fff;stroke:#1a7f37;stroke-width:2.5}.now{stroke:#7d6608;stroke-width:1.5}.outside{fill:#e9e3d0}
svg text{font-size:12px;fill:#1d2329}
.legend span{display:inline-block;margin-right:1.2em;font-size:.85em}
.sw{display:inline-block;width:1.4em;height:.7em;vertical-align:middle;margin-right:.3em}
footer{font-size:.8em;color:#5a6470;margin-top:1em}
@media print{.grid{grid-template-columns:1fr}fieldset{break-inside:avoid}
body{max-width:none}#sentence{border-left-color:#000}input{border:none}}
"""


def planner_html(
    models: Sequence[Any],
    *,
    labels: Sequence[str] | None = None,
    defaults: PlannerDefaults | None = None,
    title: str | None = None,
) -> str:
    """The planner page (HTML text) for one or more models.

    Parameters
    ----------
    models : sequence of BlurUncertaintyModel
        Calibrations the page offers (e.g. one per subset or matcher mode).
    labels : sequence of str, optional
        A name per model for the selector (default: the pattern of its provenance).
    defaults : PlannerDefaults, optional
        Initial values of the controls.
    """
    if len(models) == 0:
        raise InputError("models: give at least one calibrated model")
    if labels is not None and len(labels) != len(models):
        raise InputError(f"labels: {len(labels)} labels for {len(models)} models")
    d = defaults or PlannerDefaults()
    payload = [
        planner_payload(m, label=None if labels is None else labels[i])
        for i, m in enumerate(models)
    ]
    first = models[0]
    noise = starting_noise(first, d.noise)
    camera = d.full_well is not None
    by_flux = d.flux is not None or d.grey_level is None
    grey = (
        d.grey_level
        if d.grey_level is not None
        else (first.mean_level if first.mean_level is not None else 127.5)
    )
    kinds = [
        k for k in ("static", "mismatch", "power_law") if any(p.get(k) is not None for p in payload)
    ]

    def val(x: Any) -> str:
        return html.escape(str(x), quote=True)

    def num(x: float | None, fallback: float) -> str:
        v = fallback if x is None or not math.isfinite(x) else x
        return val(f"{v:g}")

    names = {
        "static": "static prediction, 2 fitted scales",
        "mismatch": "noise + blur mismatch",
        "power_law": "power law (paper eq. 19)",
    }
    kind_opts = "".join(f'<option value="{k}">{names[k]}</option>' for k in kinds)
    page_title = title or "dicblur exposure planner"
    body = f"""<h1>{html.escape(page_title)}</h1>
<p id="sentence" role="status" aria-live="polite">—</p>
<div class="grid"><form id="controls" onsubmit="return false" aria-label="planner inputs">
<fieldset><legend>Calibration</legend>
<label for="model">pattern and subset</label><select id="model"></select>
<label for="kind">uncertainty model</label><select id="kind"><option value="">model's default
</option>{kind_opts}</select>
<div id="compare-box" hidden><label for="compare">set against (matcher mode)</label>
<select id="compare"></select></div></fieldset>
<fieldset><legend>Motion and optics</legend>
<label for="velocity">velocity in the image plane (mm/s, m/s, px/s)</label>
<input type="text" id="velocity" value="{val(d.velocity)}" inputmode="decimal">
<label for="scale">image scale (mm/px or px/mm)</label>
<input type="text" id="scale" value="{val(d.scale)}">
<label for="exposure">exposure (s, ms, us)</label>
<input type="text" id="exposure" value="{val(d.exposure)}">
<label for="target">target uncertainty (px or um; empty: none)</label>
<input type="text" id="target" value="{val(d.target)}"></fieldset>
{
        strain_fieldset(
            strain_target=d.strain_target,
            vsg=d.vsg,
            step=d.step,
            subset=d.subset if d.subset is not None else first.subset,
        )
    }
<fieldset><legend>Noise</legend>
<input type="radio" name="noise" id="noise-gl" {"" if camera else "checked"}>
<label class="inline" for="noise-gl">grey levels</label>
<input type="radio" name="noise" id="noise-camera" {"checked" if camera else ""}>
<label class="inline" for="noise-camera">camera</label>
<div id="gl-box"><label for="sigma">noise std (GL)</label>
<input type="number" id="sigma" min="0" step="any" value="{num(noise, 2.0)}"></div>
<div id="camera-box" hidden>
<label for="full-well">full well (electrons)</label>
<input type="number" id="full-well" min="1" step="any" value="{num(d.full_well, 20000)}">
<label for="read-noise">read noise (electrons)</label>
<input type="number" id="read-noise" min="0" step="any" value="{num(d.read_noise, 5)}">
<input type="radio" name="light" id="light-flux" {"checked" if by_flux else ""}>
<label class="inline" for="light-flux">photon flux</label>
<input type="radio" name="light" id="light-grey" {"" if by_flux else "checked"}>
<label class="inline" for="light-grey">grey level at this exposure</label>
<div id="flux-box"><label for="flux">electrons per second at the mean grey level</label>
<input type="number" id="flux" min="0" step="any" value="{num(d.flux, 4e6)}"></div>
<div id="grey-box" hidden><label for="bit-depth">bit depth</label>
<input type="number" id="bit-depth" min="1" max="32" step="1" value="{d.bit_depth}">
<label for="grey">mean grey level at this exposure (GL)</label>
<input type="number" id="grey" min="0" step="any" value="{num(grey, 127.5)}"></div>
</div></fieldset>
<p id="message" role="alert"></p></form>
<section aria-label="results">
<table class="out">
<tr><th>blur W at this exposure</th><td id="out-blur"></td></tr>
<tr><th>u_e at this exposure</th><td id="out-ue"></td></tr>
<tr><th>its parts</th><td id="out-parts"></td></tr>
<tr><th>noise at this exposure</th><td id="out-noise"></td></tr>
<tr><th>validity</th><td id="out-domain"></td></tr>
<tr><th>longest exposure meeting the target</th><td id="out-max"></td></tr>
<tr><th>optimum exposure (camera)</th><td id="out-opt"></td></tr>
<tr id="row-gain" hidden><th>gain of compensation at the optimum</th><td id="out-gain"></td></tr>
</table>
{strain_results()}
<svg id="plot" viewBox="0 0 760 380" role="img"
 aria-label="predicted u_e against exposure"></svg>
<p class="legend"><span><i class="sw" style="background:#2a6f97"></i>predicted u_e</span>
<span><i class="sw" style="border-top:2px dashed #b35900"></i>target</span>
<span><i class="sw" style="background:#1a7f37"></i>optimum</span>
<span><i class="sw" style="background:#7d6608"></i>chosen exposure</span>
<span><i class="sw" style="background:#e9e3d0"></i>outside the calibrated range</span>
<span id="legend-compare" hidden><i class="sw" style="border-top:3px dashed #7b3294"></i>the
other matcher mode (its optimum: ring)</span></p>
</section></div>
<footer>u_e is the predicted random displacement error along the motion (px), with its
{100 * first.confidence:g} % prediction interval; it comes from the calibration of the selected
pattern (dicblur), evaluated in this page with the same formulas as the Python models.
Outside the calibrated W and noise range the answer is an extrapolation.</footer>"""
    return (
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
        "<meta name='viewport' content='width=device-width,initial-scale=1'>"
        f"<title>{html.escape(page_title)}</title><style>{_CSS}</style></head><body>"
        f"{body}<script type='application/json' id='dicblur-models'>"
        f"{_json_for_script(payload)}</script><script>{PLANNER_JS}</script>"
        "</body></html>"
    )


def write_planner(models: Sequence[Any], path: str | Path, **kwargs: Any) -> Path:
    """Write :func:`planner_html` to ``path`` atomically (``dicblur.io.write_text``)."""
    from ..io import write_text

    return write_text(Path(path), planner_html(models, **kwargs))
