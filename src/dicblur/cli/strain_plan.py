"""``dicblur plan MODEL --target 100microstrain --vsg 41px``: plan for a strain target
(docs/strain.md, "Planning"); called by ``plan`` when the target is a strain."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import typer

from ..errors import InputError
from ._common import console, print_json

__all__ = ["is_strain_target", "run_strain_plan"]

_STRAIN_UNIT = re.compile(r"(microstrain|ustrain|µstrain|μstrain|%)\s*$", re.IGNORECASE)


def is_strain_target(target: str | None) -> bool:
    """``--target`` carries a strain unit (``100microstrain``, ``100ustrain``, ``0.01%``)."""
    return target is not None and bool(_STRAIN_UNIT.search(target.strip()))


def run_strain_plan(
    model_path: Path,
    *,
    velocity: str | None,
    scale: str | None,
    target: str | None,
    vsg: str | None,
    step: int,
    subset: int | None,
    noise: float | None,
    which: str | None,
    plot: Path | None,
    as_json: bool,
    unsupported: dict[str, Any],
    html_out: Path | None = None,
) -> None:
    """Plan the exposure for a strain target and print it (``--plot``: the trade-off;
    ``--html``: the planner page, starting at this strain target)."""
    given = [k for k, v in unsupported.items() if v not in (None, False)]
    if given:
        raise InputError(
            f"{', '.join(given)}: not used with a strain target (fixed noise only); give "
            "--noise, or plan a displacement target (e.g. --target 0.01px)"
        )
    if target is None or not is_strain_target(target):
        raise InputError(
            f"--vsg={vsg!r}: plans for a strain target; give --target with a strain unit, "
            "e.g. --target 100microstrain"
        )
    if (velocity is None or scale is None) and html_out is None:
        raise InputError(
            "--velocity, --scale: give both (e.g. --velocity 120mm/s --scale 0.05mm/px)"
        )
    from ..models import BlurUncertaintyModel
    from ..strain.plan import plan_strain

    model = BlurUncertaintyModel.from_json(str(model_path))
    if html_out is not None:
        from ..report.planner import PlannerDefaults, starting_noise, write_planner
        from ..strain.field import vsg as vsg_of
        from ..strain.field import window_from_vsg

        sub = model.subset if model.subset is not None else subset
        vsg_px = vsg or "5"
        if sub is not None and not str(vsg_px).strip().lower().endswith("px"):
            # the page takes the VSG in px: N points -> (N - 1) step + subset
            n = window_from_vsg(vsg_px, step=step, subset=int(sub), name="--vsg")
            vsg_px = f"{vsg_of(n, step, int(sub)):g}px"
        defaults = PlannerDefaults(
            velocity=velocity or "120mm/s", scale=scale or "0.05mm/px", noise=noise,
            strain_target=target, vsg=vsg_px, step=step, subset=subset,
        )  # fmt: skip
        write_planner([model], html_out, defaults=defaults)
        typer.echo(f"wrote {html_out}")
        if velocity is None or scale is None:
            return
        if noise is None and model.noise_sigma is None and model.noise_levels:
            noise = starting_noise(model)
            typer.echo(
                f"note: the text plan at --noise {noise:g} (GL; the page's starting value); "
                "give --noise to plan at another",
                err=True,
            )
    assert velocity is not None and scale is not None  # checked above, or the page alone
    try:
        plan = plan_strain(
            model,
            velocity=velocity,
            scale=scale,
            target=target,
            vsg=vsg or "5",
            step=step,
            subset=subset,
            sigma=noise,
            which=which,
        )
    except InputError as exc:
        # the library names its keywords; the CLI user typed options
        msg = str(exc)
        for key, opt in (
            ("vsg=", "--vsg="),
            ("target=", "--target="),
            ("step=", "--step="),
            ("subset", "--subset"),
            ("sigma=None", "--noise"),
        ):
            if msg.startswith(key):
                msg = opt + msg[len(key) :]
        raise InputError(msg) from None
    for note in plan.notes:
        if "beyond" in note or "end of the model" in note:
            typer.echo(f"warning: {note}", err=True)
    if as_json:
        print_json(plan.to_dict())
    else:
        console.print(plan.summary())
    if plot is not None:
        from ..report.strain import strain_plan_figure

        strain_plan_figure(plan, plot)
        typer.echo(f"wrote {plot}")
