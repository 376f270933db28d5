"""CLI: ``dicblur design`` -- choose and export the speckle pattern that best resists a blur."""

from __future__ import annotations

import csv
import json
import math
import shlex
from pathlib import Path
from typing import Any

import typer

from ..errors import InputError
from ._common import (
    console,
    fmt,
    json_safe,
    print_json,
    removes_new_empty_folder,
    split_sides,
)
from .options import (
    BaseSeedOption,
    CheckBrowserOption,
    OutFolderOption,
    ShapeOption,
    StepOption,
    SubsetOption,
)
from .planner_page import write_pattern_planner


def parse_range(text: str, name: str) -> tuple[float, float]:
    """Parse ``"LO..HI"`` (numbers) into a tuple; the order is checked by the caller."""
    parts = text.split("..")
    try:
        if len(parts) != 2:
            raise ValueError(text)
        return float(parts[0]), float(parts[1])
    except ValueError as exc:
        raise InputError(f"{name}={text!r}: expected LO..HI, e.g. 0..5") from exc


def _grid(text: str) -> tuple[int, int, int]:
    parts = text.lower().split("x")
    try:
        vals = tuple(int(p) for p in parts)
    except ValueError as exc:
        raise InputError(f"--grid={text!r}: expected NDxNPxNS, e.g. 5x3x3") from exc
    if len(vals) != 3:
        raise InputError(f"--grid={text!r}: expected three counts NDxNPxNS, e.g. 5x3x3")
    return vals[0], vals[1], vals[2]


def _size_mm(text: str) -> tuple[float, float]:
    vals = split_sides(text, "--print-size", float, "HxW in mm, e.g. 100x100")
    if len(vals) != 2:
        raise InputError(f"--print-size={text!r}: expected HxW in mm, e.g. 100x100")
    return vals[0], vals[1]


def _distribution(text: str) -> tuple[list[float], list[float]]:
    """Parse ``"W1:w1,W2:w2,..."`` (px : weight) into two lists."""
    blurs, weights = [], []
    try:
        for item in text.split(","):
            w, p = item.split(":")
            blurs.append(float(w))
            weights.append(float(p))
    except ValueError as exc:
        raise InputError(
            f"--blur-dist={text!r}: expected W:weight pairs, e.g. 1:0.2,3:0.5,5:0.3"
        ) from exc
    return blurs, weights


def _in_words(c: Any) -> str:
    """A candidate in words, e.g. "speckle 2.8 px, density 0.50, edge softness 0.95 px"."""
    return (
        f"speckle {c.speckle_size:.2g} px, density {c.density:.2f}, edge softness "
        f"{c.softness:.2g} px"
    )


def _stamps(folder: Path) -> dict[Path, int]:
    return {p: p.stat().st_mtime_ns for p in folder.rglob("*") if p.is_file()}


def _written_since(folder: Path, before: dict[Path, int]) -> list[str]:
    """Files under ``folder`` created or rewritten since ``before`` (relative names)."""
    return sorted(
        str(p.relative_to(folder)) for p, t in _stamps(folder).items() if before.get(p) != t
    )


@removes_new_empty_folder()
def design_command(
    ctx: typer.Context,
    out: OutFolderOption,
    blur: float | None = typer.Option(None, "--blur", help="Design blur length W, px."),
    blur_range: str | None = typer.Option(
        None, "--blur-range", help="LO..HI px: minimise the mean u_e over it."
    ),
    velocity: str | None = typer.Option(
        None,
        "--velocity",
        help="Target speed, e.g. 200mm/s or 800px/s (a bare "
        "number is mm/s; with --exposure, --scale).",
    ),
    exposure: str | None = typer.Option(
        None, "--exposure", help="Exposure time, e.g. 1ms (a bare number is s)."
    ),
    blur_dist: str | None = typer.Option(
        None, "--blur-dist", help="Blur distribution W:weight,... px, e.g. 1:0.2,3:0.5,5:0.3."
    ),
    amplitude: str | None = typer.Option(
        None,
        "--amplitude",
        help="Sine vibration amplitude, e.g. 0.5mm (a bare "
        "number is mm; with --frequency, --exposure, "
        "--scale).",
    ),
    frequency: float | None = typer.Option(
        None, "--frequency", help="Sine vibration frequency, Hz."
    ),
    scale: str | None = typer.Option(
        None,
        "--scale",
        help="Camera scale, e.g. 0.05mm/px or 20px/mm (a bare "
        "number is mm/px; enables the print export).",
    ),
    noise: float = typer.Option(2.0, "--noise", help="Camera noise std, grey levels."),
    subset: SubsetOption = 31,
    step: StepOption = 10,
    shape: ShapeOption = "translation",
    image_size: int = typer.Option(256, "--image-size", help="Synthetic image side, px."),
    realisations: int = typer.Option(
        2, "--realisations", help="Pattern realisations per candidate."
    ),
    grid: str = typer.Option(
        "5x3x3", "--grid", help="Coarse grid: points along size x density x softness."
    ),
    speckle_range: str | None = typer.Option(
        None, "--speckle-range", help="Speckle size bounds LO..HI px."
    ),
    density_range: str = typer.Option("0.3..0.7", "--density-range", help="Density bounds."),
    softness_range: str = typer.Option(
        "0..2", "--softness-range", help="Softness bounds LO..HI px."
    ),
    max_refine: int = typer.Option(20, "--max-refine", help="Refinement campaigns (0: none)."),
    screen: int | None = typer.Option(
        None,
        "--screen",
        help="Measure only the N grid members with the best static surrogate (default: all).",
    ),
    confirm: int = typer.Option(
        8, "--confirm", help="Fresh realisations of the confirmation (0: none)."
    ),
    seed: BaseSeedOption = 0,
    print_size: str = typer.Option("100x100", "--print-size", help="Printed HxW, mm."),
    dpi: float = typer.Option(600.0, "--dpi", help="Printer resolution, dots per inch."),
    no_report: bool = typer.Option(False, "--no-report", help="Skip the HTML page."),
    check_browser: CheckBrowserOption = False,
    as_json: bool = typer.Option(False, "--json", help="Print the summary as JSON."),
) -> None:
    """Search a speckle-pattern family for the lowest u_e at your blur; export the winner.

    Writes OUT/design.json, OUT/evaluations.csv, OUT/best_pattern.png (camera px),
    OUT/pattern.png|pdf|json (print-ready, when --scale is given) and OUT/report.html.
    """
    from ..design import (
        PatternFamily,
        design_pattern,
        design_problem,
        export_pattern,
        sine_blur_distribution,
    )
    from ..io import atomic_open, check_output, save_image, write_text
    from ..models import parse_quantity
    from ..patterns import speckle_pattern
    from ..report.design_page import write_design_report

    check_output(out, "--out", folder=True)

    # unit strings (120mm/s, 1ms, 0.05mm/px, 0.5mm); bare numbers in the documented units
    scale_v = parse_quantity(scale, "scale", name="--scale") if scale is not None else None
    if scale_v is not None and not scale_v > 0:
        raise InputError(f"--scale={scale!r}: must be > 0 mm/px")
    velocity_v = (
        parse_quantity(velocity, "velocity", name="--velocity", scale=scale_v)
        if velocity is not None
        else None
    )
    exposure_v = (
        parse_quantity(exposure, "time", name="--exposure") if exposure is not None else None
    )
    amplitude_v = (
        parse_quantity(amplitude, "length", name="--amplitude") if amplitude is not None else None
    )
    rng = parse_range(blur_range, "--blur-range") if blur_range is not None else None
    if rng is not None and rng[1] < rng[0]:
        raise InputError(
            f"--blur-range={blur_range}: inverted; give it as "
            f"{fmt(rng[1])}..{fmt(rng[0])} (low..high)"
        )
    if dpi <= 0 or not math.isfinite(dpi):
        raise InputError(
            f"--dpi={dpi!r}: the printer resolution must be > 0 dots per inch (e.g. 600)"
        )
    size_mm = _size_mm(print_size)
    if min(size_mm) <= 0 or not all(math.isfinite(v) for v in size_mm):
        raise InputError(f"--print-size={print_size!r}: both sides must be > 0 mm")
    blurs = weights = None
    if blur_dist is not None:
        blurs, weights = _distribution(blur_dist)
    if amplitude_v is not None or frequency is not None:
        if amplitude_v is None or frequency is None or exposure_v is None or scale_v is None:
            raise InputError(
                "--amplitude, --frequency: a sine vibration needs --amplitude "
                "(mm), --frequency (Hz), --exposure (s) and --scale (mm/px)"
            )
        if velocity_v is not None or blurs is not None:
            raise InputError(
                "--amplitude: give either a sine vibration or --velocity / --blur-dist, not both"
            )
        bl, wt = sine_blur_distribution(amplitude_v / scale_v, frequency, exposure_v)
        blurs, weights = list(bl), list(wt)
        exposure_v = None
    problem = design_problem(
        blur=blur,
        blur_range=rng,
        blurs=blurs,
        weights=weights,
        velocity=velocity_v,
        exposure=exposure_v,
        scale=scale_v,
        noise=noise,
        subset=subset,
        step=step,
        image_size=image_size,
        dic_shape=shape,
        realisations=realisations,
        seed=seed,
    )
    sz = (
        parse_range(speckle_range, "--speckle-range")
        if speckle_range is not None
        else (2.0, max(2.0, min(10.0, subset / 3.0)))
    )
    family = PatternFamily(
        speckle_size=sz,
        density=parse_range(density_range, "--density-range"),
        softness=parse_range(softness_range, "--softness-range"),
        grid=_grid(grid),
    )
    out.mkdir(exist_ok=True)
    before = _stamps(out)
    n_grid = len(family.grid_candidates())
    if not as_json:
        console.print(
            f"design: {problem.describe_target()}, {n_grid} grid candidates, up "
            f"to {max_refine} refinement campaigns"
        )

    def progress(stage: str, i: int, e: object) -> None:
        if not as_json and (i % 10 == 0):
            console.print(f"  {i} campaigns done")

    result = design_pattern(
        problem,
        family,
        max_refine=max_refine,
        confirm_realisations=confirm,
        screen=screen,
        progress=progress,
    )
    best = result.best.candidate
    cam = speckle_pattern(
        problem.image_size,
        speckle_size=best.speckle_size,
        density=best.density,
        softness=best.softness,
        seed=seed,
    )
    save_image(out / "best_pattern.png", cam, bit_depth=8)
    write_text(
        out / "best_pattern.png.json",
        json.dumps(
            {"generator": best.settings((problem.image_size, problem.image_size), seed)}, indent=2
        ),
    )
    export = None
    if scale_v is not None:
        export = export_pattern(
            best,
            out,
            scale=scale_v,
            size_mm=size_mm,
            dpi=dpi,
            seed=seed,
            extra={"design_summary": result.summary()},
        )
    doc = result.to_dict()
    doc["export"] = None if export is None else export.to_dict()
    write_text(out / "design.json", json.dumps(json_safe(doc), indent=2, allow_nan=False))
    with atomic_open(out / "evaluations.csv", "w", newline="") as fh:
        cols = [
            "stage",
            "speckle_size",
            "density",
            "softness",
            "objective",
            "surrogate",
            "eta",
            "alpha",
            "beta",
            "mbrf",
            "c_fit",
            "c_static",
            "mig0",
            "fit_ok",
            "n_points",
            "time_s",
        ]
        w = csv.DictWriter(fh, fieldnames=cols, extrasaction="ignore")
        w.writeheader()
        for e in result.evaluations:
            w.writerow(e.to_dict())
    if not no_report:
        # The options as parsed (defaults included), so the page says how to re-run it.
        parts = []
        for key, value in ctx.params.items():
            opt = "--" + key.replace("_", "-")
            if value is None or value is False:
                continue
            parts.append(opt if value is True else f"{opt}={shlex.quote(str(value))}")
        cmd = "dicblur design " + " ".join(parts)
        page = write_design_report(result, out, export=export, command=cmd)
        if check_browser:
            from ..report import check_in_browser

            chk = check_in_browser(page)
            if not chk.images_ok:
                raise InputError(
                    f"report: {chk.image_count} images, not all decoded in {chk.browser}"
                )
    # the exposure planner of the winner, from its static prediction
    write_pattern_planner(
        cam,
        out,
        noise=noise,
        subset=subset,
        step=step,
        label=f"best pattern ({_in_words(best)}), subset {subset} px",
        provenance={"pattern": "best_pattern.png", "source": "dicblur design"},
    )
    summary = result.summary()
    if export is not None:
        summary["speckle_size_mm"] = export.speckle_size_mm
        summary["print_dpi"] = export.dpi
    # what this run wrote, counted on disk (the report's figures included)
    summary["files"] = _written_since(out, before)
    if as_json:
        print_json(summary)
        return
    console.print(
        f"best pattern: {_in_words(best)} ({best.label()}), predicted u_e "
        f"{result.best.objective:.4g} px "
        f"(default {result.reference.objective:.4g}, worst "
        f"{result.worst.objective:.4g})"
    )
    if result.confirmation is not None:
        c = result.confirmation
        console.print(
            f"measured on fresh seeds: best {c.mean('best'):.4g} +- "
            f"{c.stderr('best'):.2g} px, default {c.mean('default'):.4g} +- "
            f"{c.stderr('default'):.2g} px ({100 * summary['gain_vs_default']:.1f} "
            "% lower)"
        )
    if export is not None:
        console.print(
            f"print: {export.shape[0]}x{export.shape[1]} dots at {export.dpi:g} "
            f"DPI = {export.size_mm[0]:.1f}x{export.size_mm[1]:.1f} mm, speckle "
            f"{export.speckle_size_mm:.3g} mm"
        )
    console.print(
        f"{result.n_campaigns} campaigns, {result.n_points} campaign points, "
        f"{result.wall_s:.1f} s; wrote {len(summary['files'])} files to {out}"
    )


def register(app: typer.Typer) -> None:
    """Attach ``dicblur design`` to the root app."""
    app.command("design")(design_command)
