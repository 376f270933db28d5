"""CLI: ``dicblur pattern generate|metrics|predict`` and ``dicblur noise``."""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path
from typing import Any

import typer

from ..errors import InputError
from ._common import console, fresh_seed, parse_size, print_json, print_mapping
from .options import (
    AngleOption,
    BitDepthOption,
    ImageSeedOption,
    JsonOption,
    ShapeOption,
    SubsetOption,
    SubsetStepOption,
)

pattern_app = typer.Typer(
    help="Generate speckle patterns and measure their metrics.", no_args_is_help=True
)

_UNITS = {
    "mean_level": "GL",
    "mig": "GL/px",
    "gradient_variance": "(GL/px)^2",
    "speckle_size": "px",
    "sssig_x_mean": "(GL/px)^2",
    "sssig_x_std": "(GL/px)^2",
    "sssig_y_mean": "(GL/px)^2",
    "sssig_y_std": "(GL/px)^2",
    "pan_sssig": "(GL/px)^2",
    "noise_sigma": "GL",
    "match_score_x_mean": "px",
    "match_score_x_std": "px",
    "match_score_y_mean": "px",
    "pan_u": "px",
    "blur_sensitivity_c": "px/px^2",
    "subset": "px",
    "shape": "px",
}


@pattern_app.command("generate")
def generate(
    out: Path = typer.Argument(..., help="Output image (.tif, .tiff, .png or .bmp)."),
    size: str = typer.Option("512x512", "--size", help="ROWSxCOLS in px."),
    speckle_size: float = typer.Option(4.0, "--speckle-size", help="Mean speckle diameter, px."),
    density: float = typer.Option(0.5, "--density", help="Black-area fraction in (0, 1)."),
    softness: float = typer.Option(0.0, "--softness", help="Edge-blur sigma, px."),
    contrast: float = typer.Option(1.0, "--contrast", help="Fraction of 0..255 spanned."),
    supersample: int = typer.Option(1, "--supersample", help="Fine-grid factor (>= 1)."),
    preset: str = typer.Option(
        "", "--preset", help="'paper4': the paper's pattern #4 (4x4 Gaussian mask)."
    ),
    seed: ImageSeedOption = None,
    bit_depth: BitDepthOption = 8,
) -> None:
    """Generate a random speckle pattern and write it to OUT (plus OUT.json settings)."""
    from ..io import check_output, save_image, write_text
    from ..patterns import PatternSettings, paper_pattern4, speckle_pattern

    check_output(out, "OUT", suffixes=(".tif", ".tiff", ".png", ".bmp"))
    if bit_depth not in (8, 16):
        raise InputError(f"--bit-depth={bit_depth}: must be 8 or 16")
    if bit_depth == 16 and out.suffix.lower() == ".bmp":
        raise InputError(f"--bit-depth=16: BMP files are 8-bit only; use .tif or .png for {out}")
    shape = parse_size(size)
    if preset not in ("", "paper4"):
        raise InputError(f"--preset={preset!r}: unknown preset; choose 'paper4' or omit it")
    if preset == "paper4":
        for opt, value, default in (
            ("--softness", softness, 0.0),
            ("--contrast", contrast, 1.0),
            ("--supersample", supersample, 1),
        ):
            if value != default:
                raise InputError(f"{opt}={value:g}: not used by --preset paper4; drop one")
    seed = fresh_seed() if seed is None else seed
    if preset == "paper4":
        img = paper_pattern4(shape, speckle_size=speckle_size, density=density, seed=seed)
        settings = {
            "preset": "paper4",
            "shape": list(shape),
            "speckle_size": speckle_size,
            "density": density,
            "seed": seed,
        }
    else:
        img = speckle_pattern(
            shape,
            speckle_size=speckle_size,
            density=density,
            softness=softness,
            contrast=contrast,
            supersample=supersample,
            seed=seed,
        )
        settings = PatternSettings(
            shape,
            speckle_size,
            density,
            softness,
            127.5 - 127.5 * contrast,
            127.5 + 127.5 * contrast,
            supersample,
            seed,
        ).to_dict()
    if bit_depth == 16:
        img = img * (65535.0 / 255.0)
    save_image(out, img, bit_depth=bit_depth)
    sidecar = out.with_name(out.name + ".json")
    write_text(sidecar, json.dumps({"generator": settings, "bit_depth": bit_depth}, indent=2))
    typer.echo(f"wrote {out} ({shape[0]}x{shape[1]} px, {bit_depth}-bit) and {sidecar.name}")


@pattern_app.command("metrics")
def metrics(
    image: Path = typer.Argument(..., help="Image file (TIFF, PNG, BMP, JPEG)."),
    subset: SubsetOption = 31,
    step: SubsetStepOption = None,
    noise: float | None = typer.Option(None, "--noise", help="Noise std, grey levels."),
    gradient: str = typer.Option("central", "--gradient", help="central or sobel."),
    as_json: JsonOption = False,
) -> None:
    """Print the metrics of IMAGE: SSSIG, MIG, speckle size, contrast, static predictions."""
    from ..io import load_image
    from ..metrics import pattern_metrics
    from ..models import blur_sensitivity

    img = load_image(image)
    pm = pattern_metrics(img, subset=subset, noise_sigma=noise, step=step, gradient=gradient)  # type: ignore[arg-type]
    data = pm.to_dict()
    if data.get("n_subsets", 2) < 2:
        # the spread of one subset is undefined, not 0 (a large --step or subset)
        for key in [k for k in data if k.endswith("_std")]:
            data[key] = None
    # the model's c beside the image metrics (motion along x, translation, the same subsets)
    try:
        data["blur_sensitivity_c"] = blur_sensitivity(img, subset=subset, step=step).c
    except InputError:  # fewer than two textured subsets, or no random texture: no c
        data["blur_sensitivity_c"] = None
    undefined = [k for k, v in data.items() if isinstance(v, float) and not math.isfinite(v)]
    if undefined:
        # printed as '-' (null in JSON), never as nan or inf
        warnings.warn(
            f"{image}: {', '.join(undefined)} undefined for this image (a subset or "
            "the whole image without texture, or speckles too large to measure); "
            "shown as '-'",
            UserWarning,
            stacklevel=1,
        )
    if as_json:
        print_json(data)
    else:
        print_mapping(f"pattern metrics: {image}", data, _UNITS)


@pattern_app.command("predict")
def predict(
    image: Path = typer.Argument(..., help="Sharp image of the pattern (TIFF, PNG, ...)."),
    noise: float = typer.Option(..., "--noise", help="Noise std in each image, grey levels."),
    subset: SubsetOption = 31,
    step: SubsetStepOption = None,
    blur: list[float] = typer.Option(
        [], "--blur", help="Blur length W, px (repeatable; default 0..8)."
    ),
    angle: AngleOption = 0.0,
    shape: ShapeOption = "translation",
    subpixel: str | None = typer.Option(
        None,
        "--subpixel",
        help="Target's sub-pixel position: 'average' (arbitrary, ~5x slower) or a fraction "
        "0..1 px; adds DIC's interpolation bias. Default: aligned.",
    ),
    out: Path | None = typer.Option(
        None, "-o", "--out", help="Also write a model JSON for dicblur predict/plan."
    ),
    as_json: JsonOption = False,
    compensation: str = typer.Option(
        "none",
        "--compensation",
        help="'given': also predict the blur-compensated matcher (dicblur correlate "
        "--blur-compensation given) and the gain over the plain one; with -o the model "
        "written is the compensated matcher's (dicblur plan --compare sets it against "
        "the plain one).",
    ),
) -> None:
    """Predict u_e(W) of IMAGE from the static image alone (no simulation, no DIC run)."""
    from rich.table import Table

    from ..io import check_output, load_image
    from ..models import model_from_pattern, predict_from_pattern

    if shape not in ("translation", "affine"):
        raise InputError(f"--shape={shape!r}: choose 'translation' or 'affine'")
    if out is not None:
        check_output(out, "--out", inputs=(image,))
    if compensation not in ("none", "given"):
        raise InputError(f"--compensation={compensation!r}: choose 'none' or 'given'")
    if compensation == "given" and subpixel is not None:
        raise InputError(
            "--compensation=given: the compensated prediction is aligned; drop --subpixel"
        )
    img = load_image(image)
    a = math.radians(angle)
    motion = (math.sin(a), math.cos(a))
    w = list(blur) or [0.0, 0.5, 1.0, 2.0, 3.0, 4.0, 6.0, 8.0]
    sp: float | str | None = subpixel
    if subpixel is not None and subpixel != "average":
        try:
            sp = float(subpixel)
        except ValueError:
            raise InputError(
                f"--subpixel={subpixel!r}: give 'average' or a fraction in [0, 1) px, e.g. 0.5"
            ) from None
    # one matcher for the prediction, the compensated one and the model written
    matcher: dict[str, Any] = {
        "noise_sigma": noise,
        "subset": subset,
        "step": step,
        "motion": motion,
        "shape": shape,
    }
    pred = predict_from_pattern(img, w, **matcher, subpixel=sp)
    provenance = {"image": str(image)}
    if compensation == "given":
        _print_compensated(img, pred, image, matcher=matcher, angle=angle, as_json=as_json)
        if out is not None:
            from ..models import model_from_compensated

            model_from_compensated(img, **matcher, provenance=provenance).to_json(str(out))
            console.print(f"wrote {out}: the blur-compensated matcher's model")
        return
    if out is not None:
        model = model_from_pattern(img, **matcher, provenance=provenance, subpixel=sp)
        model.to_json(str(out))
    if as_json:
        print_json(
            {
                "blur": pred.blur.tolist(),
                "u_e": pred.u_e.tolist(),
                "u_noise": pred.u_noise.tolist(),
                "u_blur": pred.u_blur.tolist(),
                "sssig": pred.sssig.tolist(),
                "valid_fraction": pred.valid_fraction.tolist(),
                "noise_sigma": noise,
                "subset": subset,
                "shape": shape,
                "angle": angle,
                "subpixel": sp,
                "breakdown_blur": pred.breakdown_blur,
            }
        )
    else:
        table = Table(
            title=f"predicted from the static image: {image} (noise {noise:g} GL, "
            f"subset {subset} px, {shape}, motion at {angle:g} deg)"
        )
        for col in (
            "W (px)",
            "u_e (px)",
            "noise term (px)",
            "blur term (px)",
            "SSSIG (GL/px)^2",
            "subsets kept",
        ):
            table.add_column(col, justify="right")
        for j in range(pred.blur.size):
            table.add_row(
                f"{pred.blur[j]:g}",
                f"{pred.u_e[j]:.4g}",
                f"{pred.u_noise[j]:.4g}",
                f"{pred.u_blur[j]:.4g}",
                f"{pred.sssig[j]:.4g}",
                f"{100 * pred.valid_fraction[j]:.0f} %",
            )
        console.print(table)
        if pred.breakdown_blur is not None:
            console.print(
                f"DIC breaks down from W = {pred.breakdown_blur:g} px (fewer than "
                "90 % of the subsets keep their texture along the motion): the "
                "rows from there on do not describe DIC"
            )
    if out is not None:
        console.print(f"wrote {out}: use it with dicblur predict / dicblur plan")


def _print_compensated(
    img: Any,
    pred: Any,
    image: Path,
    *,
    matcher: dict[str, Any],
    angle: float,
    as_json: bool,
) -> None:
    """Plain and blur-compensated predictions side by side (issue 18); ``matcher``: the
    keywords (noise_sigma, subset, step, motion, shape) of the plain prediction ``pred``."""
    from rich.table import Table

    from ..models.compensated import predict_compensated

    comp = predict_compensated(img, pred.blur, **matcher)
    noise, subset, shape = matcher["noise_sigma"], matcher["subset"], matcher["shape"]
    gain = pred.u_e / comp.u_e
    if as_json:
        print_json(
            {
                "blur": pred.blur.tolist(),
                "u_e": pred.u_e.tolist(),
                "u_e_compensated": comp.u_e.tolist(),
                "gain": gain.tolist(),
                "sssig": pred.sssig.tolist(),
                "noise_sigma": noise,
                "subset": subset,
                "shape": shape,
                "angle": angle,
                "compensation": "given",
            }
        )
        return
    table = Table(
        title=f"plain and blur-compensated matcher: {image} (noise {noise:g} GL, "
        f"subset {subset} px, {shape}, motion at {angle:g} deg)"
    )
    for col in ("W (px)", "u_e plain (px)", "u_e compensated (px)", "gain", "static bound (px)"):
        table.add_column(col, justify="right")
    for j in range(pred.blur.size):
        bound = math.sqrt(2.0 * noise**2 / comp.sssig[j])
        table.add_row(
            f"{pred.blur[j]:g}",
            f"{pred.u_e[j]:.4g}",
            f"{comp.u_e[j]:.4g}",
            f"{gain[j]:.2f}x",
            f"{bound:.4g}",
        )
    console.print(table)


def noise_command(
    image_a: Path = typer.Argument(..., help="First image of a static scene."),
    image_b: Path = typer.Argument(..., help="Second image of the same scene."),
    as_json: JsonOption = False,
) -> None:
    """Estimate the image noise std (grey levels) from two images of a static scene."""
    from ..io import load_image, read_image_header
    from ..metrics import estimate_noise

    img_a, img_b = load_image(image_a), load_image(image_b)  # each file checked first
    ha, hb = read_image_header(image_a), read_image_header(image_b)
    if ha.shape != hb.shape:
        raise InputError(
            f"IMAGE_B={str(image_b)!r}: shape {hb.shape[0]}x{hb.shape[1]} px, "
            f"IMAGE_A is {ha.shape[0]}x{ha.shape[1]} px; give two images of the "
            "same scene from the same camera"
        )
    if ha.dtype != hb.dtype:
        raise InputError(
            f"IMAGE_B={str(image_b)!r}: {hb.bit_depth}-bit {hb.dtype} samples, "
            f"IMAGE_A has {ha.bit_depth}-bit {ha.dtype}: their grey levels are on "
            "different scales; give two images saved at the same bit depth"
        )
    if image_a.resolve() == image_b.resolve():
        raise InputError(
            f"IMAGE_B={str(image_b)!r}: the same file as IMAGE_A; give two images of the "
            "static scene taken one after the other"
        )
    sigma = estimate_noise(img_a, img_b)
    for note in _noise_notes(img_a, img_b, ha):
        typer.echo(f"warning: {note}", err=True)
    if as_json:
        print_json({"noise_sigma": sigma})
    else:
        typer.echo(f"noise sigma = {sigma:.4f} grey levels (per image)")


def _noise_notes(img_a: Any, img_b: Any, header: Any) -> list[str]:
    """What makes a pair's noise estimate wrong without an error: identical images, and
    clipped pixels (black or at the top level), whose noise the pair does not show."""
    import numpy as np

    if np.array_equal(img_a, img_b):
        return ["the two images are identical pixel for pixel: no noise between them"]
    if not header.dtype.startswith(("uint", "int")):
        return []
    top = 2 ** int(header.bit_depth) - 1
    clipped = float(np.mean((img_a <= 0) | (img_a >= top) | (img_b <= 0) | (img_b >= top)))
    if clipped > 0.01:
        return [
            f"{100 * clipped:.3g} % of the pixels are clipped (0 or {top} GL): their noise "
            "does not show, the estimate is low; lower the exposure or gain"
        ]
    return []


def register(app: typer.Typer) -> None:
    """Attach the pattern commands to the root app."""
    app.add_typer(pattern_app, name="pattern")
    app.command("noise")(noise_command)
