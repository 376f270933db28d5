"""CLI: ``dicblur pulse`` (the paper's Section V: 1-D pulse model, Monte Carlo, verdict)."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Annotated, Any

import typer

from ..errors import InputError
from ._common import removes_new_empty_folder
from .options import OutFolderOption


def _table_markdown(rows: tuple[dict[str, Any], ...]) -> str:
    qs = ("mig", "gradient_variance", "contrast", "sssig")
    head = ["regime", "condition", "m(w)", "dp", "du", "w"]
    for q in qs:
        head += [f"{q} closed", f"{q} numeric", f"{q} pixel"]
    lines = [
        "# Table II: the blurred pulse train per regime (N = 1 period)",
        "",
        "closed = our closed form; numeric = numerical convolution (h = 1/64 px, "
        "continuous limit); pixel = samples at pixel centres, forward differences. "
        "MIG in GL/px, gradient variance in (GL/px)^2, contrast in GL, SSSIG in "
        "(GL/px)^2. Formulas: MIG = 2 a m/(w du), var = 2 a^2 m/(w^2 du), contrast = "
        "a m/w, SSSIG = 2 N a^2 m/w^2.",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]
    for r in rows:
        cells = [r["regime"], r["condition"], r["m"], f"{r['dp']:g}", f"{r['du']:g}", f"{r['w']:g}"]
        for q in qs:
            cells += [
                f"{r[q + '_closed']:.6g}",
                f"{r[q + '_numeric']:.6g}",
                f"{r[q + '_pixel']:.6g}",
            ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _write_csv(path: Path, rows: list[dict[str, Any]]) -> None:
    from ..io import atomic_open

    with atomic_open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


@removes_new_empty_folder()
def pulse_command(
    out: OutFolderOption,
    trials: Annotated[int, typer.Option("--trials", help="Noise realisations per w.")] = 10000,
    seed: Annotated[int, typer.Option("--seed", help="Random seed (same seed, same numbers).")] = 1,
    n_periods: Annotated[int, typer.Option("--n-periods", help="Periods in the signal (N).")] = 10,
    dependence_trials: Annotated[
        int,
        typer.Option("--dependence-trials", help="Trials per w of the dependence study (0 skips)."),
    ] = 2000,
    figures: Annotated[
        bool, typer.Option("--figures/--no-figures", help="Write PNG figures.")
    ] = True,
) -> None:
    """Section V of the paper: Table II, Fig. 4-6, the Monte Carlo and verdict.md in OUT."""
    from ..checks import check_seed
    from ..io import atomic_path, check_output, write_text
    from ..pulse.study import run_pulse_study

    check_output(out, "--out", folder=True)
    check_seed(seed, "--seed")

    if trials < 2:
        raise InputError(f"--trials={trials}: expected an int >= 2 (default 10000)")
    if n_periods < 1:
        raise InputError(f"--n-periods={n_periods}: expected an int >= 1 (default 10)")
    if dependence_trials < 0:
        raise InputError(f"--dependence-trials={dependence_trials}: expected >= 0")
    study = run_pulse_study(
        trials=trials, seed=seed, n_periods=n_periods, dependence_trials=dependence_trials or None
    )
    out.mkdir(exist_ok=True)
    _write_csv(out / "table_ii.csv", list(study.table))
    write_text(out / "table_ii.md", _table_markdown(study.table))
    ds = study.dataset
    summary = ds.drop_vars("u") if "u" in ds else ds
    with atomic_path(out / "montecarlo.csv") as tmp:
        summary.to_dataframe().to_csv(tmp)
    with atomic_path(out / "montecarlo.nc") as tmp:
        summary.to_netcdf(tmp, engine="scipy")
    with atomic_path(out / "fig5_min_chi2.csv") as tmp:
        study.fig5.to_dataframe().to_csv(tmp)
    _write_csv(out / "fits.csv", [f.to_dict() for f in study.fits])
    if study.dependence:
        _write_csv(out / "dependence.csv", [r.to_dict() for r in study.dependence])
    write_text(out / "verdict.md", study.verdict)
    write_text(
        out / "settings.json",
        json.dumps(
            {
                **study.settings,
                "seed": seed,
                "montecarlo_seconds": study.elapsed_s,
                "knee": study.knee,
                "knee_predicted": study.knee_predicted,
            },
            indent=2,
        ),
    )
    written = [
        "table_ii.csv",
        "table_ii.md",
        "montecarlo.csv",
        "montecarlo.nc",
        "fig5_min_chi2.csv",
        "fits.csv",
        "verdict.md",
        "settings.json",
    ]
    if study.dependence:
        written.append("dependence.csv")
    if figures:
        from ..report.pulse_figures import write_figures

        written += [p.name for p in write_figures(study, out)]
    fa = next((f for f in study.fits if f.segment == "a"), study.fits[0])
    typer.echo(f"wrote {len(written)} files to {out}")
    typer.echo(
        f"regime (a) slope {fa.slope:.3f} ({fa.slope_ci[0]:.3f}..{fa.slope_ci[1]:.3f});"
        f" knee at w = {study.knee:g} (2 dp = {study.knee_predicted:g}, du - dp = "
        f"{study.knee_paper:g}); Monte Carlo {study.elapsed_s:.2f} s"
    )


def register(app: typer.Typer) -> None:
    """Attach ``dicblur pulse`` to the root app."""
    app.command("pulse")(pulse_command)
