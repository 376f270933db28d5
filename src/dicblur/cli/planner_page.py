"""OUT/planner.html of ``design`` and ``track``: the exposure planner of one pattern."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer

__all__ = ["write_pattern_planner"]


def write_pattern_planner(
    image: Any,
    out: Path,
    *,
    noise: float,
    subset: int,
    step: int,
    label: str,
    provenance: dict[str, Any],
    motion: tuple[float, float] = (0.0, 1.0),
) -> Path | None:
    """Write OUT/planner.html from the static prediction of ``image`` (no simulation).

    Parameters
    ----------
    image : array_like, shape (rows, cols)
        The pattern, GL.
    out : Path
        The output folder.
    noise : float
        Image noise std, GL.
    subset, step : int
        Subset size and grid step of the command, px; the prediction steps at least half
        a subset (enough subsets for the fit, a fraction of the time).
    label : str
        The model's name on the page.
    provenance : dict
        Recorded in the model (where the pattern came from).
    motion : (float, float)
        Motion direction ``(dy, dx)``, a unit vector.

    Returns
    -------
    Path or None
        The page; None when it could not be made: the command's results are already
        written, so the reason is one warning line on stderr, not a lost run.
    """
    from ..errors import DicblurError
    from ..models import model_from_pattern
    from ..report.planner import write_planner

    try:
        model = model_from_pattern(
            image,
            noise_sigma=noise,
            subset=subset,
            step=max(step, subset // 2),
            motion=motion,
            provenance=provenance,
        )
        return write_planner([model], out / "planner.html", labels=[label])
    except DicblurError as exc:
        typer.echo(f"warning: planner page not written ({exc})", err=True)
        return None
