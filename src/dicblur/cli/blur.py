"""CLI: ``dicblur blur IMAGE OUT``: motion blur (Algorithm 1) plus a camera model."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Annotated, Any

import typer

from ..errors import InputError
from ._common import fresh_seed
from .options import AngleOption, ImageSeedOption


def blur_command(
    image: Annotated[Path, typer.Argument(help="Sharp input image (TIFF, PNG, BMP, JPEG).")],
    out: Annotated[Path, typer.Argument(help="Output image (.tif, .tiff, .png or .bmp).")],
    length: Annotated[
        float,
        typer.Option(
            "--length", help="Path length W in px (linear, acceleration) or amplitude (sine)."
        ),
    ],
    angle: AngleOption = 0.0,
    trajectory: Annotated[
        str, typer.Option("--trajectory", help="linear, sine or acceleration.")
    ] = "linear",
    cycles: Annotated[float, typer.Option("--cycles", help="sine: frequency x exposure.")] = 1.0,
    phase: Annotated[
        float, typer.Option("--phase", help="sine: phase at shutter opening, deg.")
    ] = 0.0,
    start_speed: Annotated[
        float, typer.Option("--start-speed", help="acceleration: start speed / mean speed (0..2).")
    ] = 0.0,
    substeps: Annotated[
        int, typer.Option("--substeps", help="K (K + 1 sub-frames; paper: 100).")
    ] = 100,
    continuous: Annotated[
        bool, typer.Option("--continuous", help="Use the limit K -> inf.")
    ] = False,
    boundary: Annotated[str, typer.Option("--boundary", help="periodic or reflect.")] = "periodic",
    noise: Annotated[
        float | None,
        typer.Option("--noise", help="Gaussian noise std, grey levels (no shot noise)."),
    ] = None,
    noise_model: Annotated[
        str, typer.Option("--noise-model", help="per-exposure (camera) or per-subframe (paper).")
    ] = "per-exposure",
    full_well: Annotated[
        float | None,
        typer.Option("--full-well", help="Full well, electrons: enables Poisson-Gaussian noise."),
    ] = None,
    gain: Annotated[
        float | None,
        typer.Option("--gain", help="Grey levels per electron (default: top level / full well)."),
    ] = None,
    read_noise: Annotated[
        float,
        typer.Option("--read-noise", help="Read noise std, grey levels (Poisson-Gaussian model)."),
    ] = 0.0,
    exposure_scale: Annotated[
        float,
        typer.Option("--exposure-scale", help="Exposure relative to nominal (scales the signal)."),
    ] = 1.0,
    bit_depth: Annotated[
        int | None,
        typer.Option(
            "--bit-depth",
            help="8 or 16: quantisation and file (default: 16 for a 16-bit IMAGE, else 8).",
        ),
    ] = None,
    seed: ImageSeedOption = None,
) -> None:
    """Blur IMAGE along a path of LENGTH px and write OUT (plus OUT.json settings)."""
    from ..blur import AcceleratedMotion, SineMotion, motion_blur
    from ..camera import Camera, add_gaussian_noise
    from ..io import (
        check_output,
        file_sha256,
        load_image,
        read_image_header,
        save_image,
        write_text,
    )

    check_output(out, "OUT", suffixes=(".tif", ".tiff", ".png", ".bmp"), inputs=(image,))
    header = read_image_header(image)
    if bit_depth is None:  # the input's: an 8-bit default quantised a 16-bit image to 255
        bit_depth = 16 if header.dtype in ("uint16", "int16") else 8
    if bit_depth not in (8, 16):
        raise InputError(f"--bit-depth={bit_depth}: must be 8 or 16")
    if noise is not None and (full_well is not None or gain is not None or read_noise > 0):
        raise InputError(
            "--noise with --full-well/--gain/--read-noise: choose one noise model "
            "(--noise for Gaussian only, --full-well/--gain/--read-noise for Poisson-Gaussian)"
        )
    if not math.isfinite(length) or not math.isfinite(angle):
        raise InputError(f"--length={length}, --angle={angle}: must be finite numbers")
    if length < 0:
        raise InputError(
            f"--length={length:g}: the path length (or sine amplitude) is >= 0 "
            f"px; reverse the motion with --angle {angle + 180:g} instead"
        )
    if trajectory == "acceleration" and not 0.0 <= start_speed <= 2.0:
        raise InputError(
            f"--start-speed={start_speed:g}: must be in 0..2 (0 starts from "
            "rest, 1 is uniform speed, 2 comes to rest at the end)"
        )
    if noise_model not in ("per-exposure", "per-subframe"):
        raise InputError(f"--noise-model={noise_model!r}: choose per-exposure or per-subframe")
    if noise is None and noise_model != "per-exposure":
        raise InputError(f"--noise-model={noise_model}: only used with --noise")
    for opt, value, default, needs in (
        ("--cycles", cycles, 1.0, "sine"),
        ("--phase", phase, 0.0, "sine"),
        ("--start-speed", start_speed, 0.0, "acceleration"),
    ):
        if value != default and trajectory != needs:
            raise InputError(f"{opt}={value:g}: only used with --trajectory {needs}")
    if not continuous and substeps < 1:
        raise InputError(
            f"--substeps={substeps}: K must be >= 1 sub-steps (the paper uses "
            "100); for the continuous limit K -> inf use --continuous"
        )
    rad = math.radians(angle)
    motion = (length * math.sin(rad), length * math.cos(rad))
    traj: str | SineMotion | AcceleratedMotion
    if trajectory == "sine":
        traj = SineMotion(cycles=cycles, phase=math.radians(phase))
    elif trajectory == "acceleration":
        traj = AcceleratedMotion(start_speed=start_speed)
    elif trajectory == "linear":
        traj = "linear"
    else:
        raise InputError(
            f"--trajectory={trajectory!r}: unknown trajectory; choose linear, sine or acceleration"
        )
    k = None if continuous else substeps
    seed = fresh_seed() if seed is None else seed
    img = load_image(image)
    _check_levels(img, header.dtype, bit_depth, image)
    # a path as long as the image wraps it onto itself (periodic) or mirrors it (reflect):
    # no camera records that, and the blur models have no meaning there
    if abs(motion[0]) >= img.shape[0] or abs(motion[1]) >= img.shape[1]:
        limit = img.shape[1] if abs(motion[1]) >= img.shape[1] else img.shape[0]
        raise InputError(
            f"--length={length:g}: at --angle {angle:g} the path crosses the whole image "
            f"({img.shape[0]}x{img.shape[1]} px); use a length below {limit} px or a "
            "larger image"
        )
    blurred = motion_blur(img, motion, substeps=k, trajectory=traj, boundary=boundary)  # type: ignore[arg-type]
    if noise is not None:
        if continuous and noise_model == "per-subframe":
            raise InputError(
                "--noise-model per-subframe with --continuous: per-subframe noise needs a "
                "finite K (its std is sigma / sqrt(K + 1)); drop --continuous"
            )
        noisy = add_gaussian_noise(
            blurred,
            noise,
            model=noise_model,  # type: ignore[arg-type]
            substeps=substeps,
            seed=seed,
        )
        camera = Camera(bit_depth=bit_depth)
        final = camera.capture(noisy)  # quantisation and clipping only: draws nothing
    else:
        camera = Camera(
            read_noise=read_noise,
            gain=gain,
            full_well=full_well,
            exposure_scale=exposure_scale,
            bit_depth=bit_depth,
        )
        final = camera.capture(blurred, seed=seed)
    save_image(out, final, bit_depth=bit_depth)
    settings = {
        "input": str(image),
        "input_sha256": file_sha256(image),
        "motion_dy_dx_px": list(motion),
        "length_px": length,
        "angle_deg": angle,
        "trajectory": trajectory,
        "cycles": cycles if trajectory == "sine" else None,
        "phase_deg": phase if trajectory == "sine" else None,
        "start_speed": start_speed if trajectory == "acceleration" else None,
        "substeps": k,
        "boundary": boundary,
        "noise": noise,
        "noise_model": noise_model if noise is not None else None,
        "camera": camera.to_dict(),
        "seed": seed,
    }
    sidecar = out.with_name(out.name + ".json")
    write_text(sidecar, json.dumps(settings, indent=2))
    typer.echo(
        f"wrote {out} ({img.shape[0]}x{img.shape[1]} px, W = {length:g} px) and {sidecar.name}"
    )


def _check_levels(img: Any, dtype: str, bit_depth: int, image: Path) -> None:
    """The input's grey levels must fit the output's: above its top level they all clip
    to white, below 0 to black; a float (or boolean) image in 0..1 rounds to 2 levels."""
    top = 2**bit_depth - 1
    hi, lo = float(img.max()), float(img.min())
    if lo < 0:
        raise InputError(
            f"IMAGE={str(image)!r}: grey levels down to {lo:.6g} GL ({dtype} samples): below "
            "0 they would clip to black; shift the image to grey levels >= 0 first"
        )
    if hi > top:
        fix = "use --bit-depth 16" if hi <= 65535 and bit_depth == 8 else "rescale the image"
        raise InputError(
            f"--bit-depth={bit_depth}: IMAGE {str(image)!r} has grey levels up to {hi:.6g} "
            f"GL, above the output's top level {top}: the blurred image would saturate; {fix}"
        )
    if dtype.startswith(("float", "bool")) and hi <= 1.0:
        raise InputError(
            f"IMAGE={str(image)!r}: a {dtype} image with grey levels in 0..{hi:.3g} "
            f"(normalised): quantised to {bit_depth} bits it keeps at most 2 levels; scale "
            f"it to grey levels first (x {top})"
        )


def register(app: typer.Typer) -> None:
    """Attach the blur command to the root app."""
    app.command("blur")(blur_command)
