"""Export a designed pattern as a print-ready file (PNG with DPI metadata, PDF) + settings.

The design chooses the *statistics* of the pattern (speckle size, density, edge softness,
in camera pixels), not one realisation. For printing, the pattern is regenerated at the
printer's resolution: with a camera scale ``s`` (mm per camera px) and a printer pitch
``p = 25.4 / dpi`` (mm per printed dot), the speckle size becomes ``D * s / p`` printed
dots and the softness ``softness * s / p`` dots, so on the specimen the speckles have the
designed size ``D * s`` mm and, imaged by the camera, the designed size ``D`` px. The
generator settings and seed are written to JSON; ``speckle_pattern(**settings)``
(:func:`regenerate`) gives the printed image bit for bit.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..arrays import UInt8Array
from ..checks import check_positive, describe
from ..errors import InputError
from ..io import atomic_path, write_text
from .family import Candidate

__all__ = ["PrintExport", "export_pattern", "regenerate"]

MM_PER_INCH = 25.4


@dataclass(frozen=True)
class PrintExport:
    """Files and physical facts of an exported pattern.

    Attributes
    ----------
    png, pdf, settings : pathlib.Path
        Written files (``pdf`` is None if not requested).
    dpi : float
        Printer resolution, dots per inch.
    shape : (int, int)
        (rows, cols) printed dots.
    size_mm : (float, float)
        Printed (height, width), mm: ``shape * 25.4 / dpi`` (the requested size rounded to
        whole dots).
    speckle_size_mm, softness_mm : float
        Speckle diameter and edge-blur sigma on the specimen, mm.
    speckle_size_dots, softness_dots : float
        The same in printed dots (the generator settings).
    generator : dict
        Keyword arguments of :func:`dicblur.speckle_pattern` that regenerate the image.
    """

    png: Path
    pdf: Path | None
    settings: Path
    dpi: float
    shape: tuple[int, int]
    size_mm: tuple[float, float]
    speckle_size_mm: float
    softness_mm: float
    speckle_size_dots: float
    softness_dots: float
    generator: dict[str, Any]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict."""
        return {
            "png": str(self.png),
            "pdf": None if self.pdf is None else str(self.pdf),
            "settings": str(self.settings),
            "dpi": self.dpi,
            "shape": list(self.shape),
            "size_mm": list(self.size_mm),
            "speckle_size_mm": self.speckle_size_mm,
            "softness_mm": self.softness_mm,
            "speckle_size_dots": self.speckle_size_dots,
            "softness_dots": self.softness_dots,
            "generator": dict(self.generator),
        }


def _size_mm(size_mm: Any) -> tuple[float, float]:
    if isinstance(size_mm, int | float) and not isinstance(size_mm, bool):
        size_mm = (size_mm, size_mm)
    try:
        h, w = size_mm
    except (TypeError, ValueError) as exc:
        raise InputError(
            f"size_mm={describe(size_mm)}: expected (height, width) in mm, e.g. (100, 100)"
        ) from exc
    return check_positive(h, "size_mm"), check_positive(w, "size_mm")


def export_pattern(
    candidate: Candidate,
    out_dir: str | os.PathLike[str],
    *,
    scale: float,
    size_mm: float | tuple[float, float],
    dpi: float,
    seed: int = 0,
    stem: str = "pattern",
    pdf: bool = True,
    max_pixels: int = 25_000_000,
    extra: dict[str, Any] | None = None,
) -> PrintExport:
    """Write the candidate as ``stem.png`` (with DPI), ``stem.pdf`` and ``stem.json``.

    Parameters
    ----------
    candidate : Candidate
        Speckle size and softness in camera px, density.
    out_dir : path
    scale : float
        Camera scale, mm of specimen per camera px, > 0.
    size_mm : float or (float, float)
        Printed (height, width), mm, > 0.
    dpi : float
        Printer resolution, dots per inch, > 0.
    seed : int
        Seed of the printed realisation.
    pdf : bool
        Also write a one-page PDF of the same physical size.
    max_pixels : int
        Guard against images too large to generate in memory.
    extra : dict, optional
        More JSON-ready facts to store in ``stem.json`` (e.g. the design summary).

    Raises
    ------
    InputError
        ``dpi <= 0``, ``size_mm <= 0``, ``scale <= 0``, a printed speckle under 1 dot
        (raise the DPI), a print too large for memory, or a print smaller than two speckles.
    """
    from PIL import Image

    from ..patterns import speckle_pattern

    dpi_f = check_positive(dpi, "dpi")
    scale_f = check_positive(scale, "scale")
    h_mm, w_mm = _size_mm(size_mm)
    pitch = MM_PER_INCH / dpi_f
    rows, cols = max(1, round(h_mm / pitch)), max(1, round(w_mm / pitch))
    d_mm = candidate.speckle_size * scale_f
    s_mm = candidate.softness * scale_f
    d_dots = d_mm / pitch
    s_dots = s_mm / pitch
    if d_dots < 1.0:
        need = math.ceil(MM_PER_INCH / d_mm)
        raise InputError(
            f"dpi={dpi_f:g}: a speckle of {d_mm:.3g} mm is {d_dots:.2f} printed "
            f"dots; use dpi >= {need} (>= {3 * need} for well-formed speckles)"
        )
    if rows * cols > max_pixels:
        raise InputError(
            f"size_mm=({h_mm:g}, {w_mm:g}) at dpi={dpi_f:g}: {rows}x{cols} dots "
            f"exceeds max_pixels={max_pixels}; lower the DPI, print a smaller "
            "tile, or raise max_pixels"
        )
    if d_dots > min(rows, cols) / 2:
        raise InputError(
            f"size_mm=({h_mm:g}, {w_mm:g}): smaller than two speckles of "
            f"{d_mm:.3g} mm; print a larger area"
        )
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise InputError(f"seed={describe(seed)}: expected an integer >= 0")
    gen = {
        "shape": [rows, cols],
        "speckle_size": d_dots,
        "density": candidate.density,
        "softness": s_dots,
        "seed": int(seed),
    }
    img = speckle_pattern(
        (rows, cols),
        speckle_size=d_dots,
        density=candidate.density,
        softness=s_dots,
        seed=int(seed),
    )
    data = np.rint(np.clip(img, 0.0, 255.0)).astype(np.uint8)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    png = out / f"{stem}.png"
    pil = Image.fromarray(data)  # 2-D uint8 -> mode "L"
    with atomic_path(png) as tmp:
        pil.save(tmp, format="PNG", dpi=(dpi_f, dpi_f))
    pdf_path = None
    if pdf:
        pdf_path = out / f"{stem}.pdf"
        with atomic_path(pdf_path) as tmp:
            pil.save(tmp, "PDF", resolution=dpi_f)
    size = (rows * pitch, cols * pitch)
    record = {
        "schema": "dicblur.design.PrintExport/1",
        "regenerate": "numpy.rint(dicblur.speckle_pattern(**generator)).astype(uint8)",
        "generator": gen,
        "design": {**candidate.to_dict(), "units": "camera px", "scale_mm_per_px": scale_f},
        "dpi": dpi_f,
        "size_mm_requested": [h_mm, w_mm],
        "size_mm": list(size),
        "speckle_size_mm": d_mm,
        "softness_mm": s_mm,
        "png_pixels_sha256": hashlib.sha256(data.tobytes()).hexdigest(),
        **(extra or {}),
    }
    settings = out / f"{stem}.json"
    write_text(settings, json.dumps(record, indent=2, default=float))
    return PrintExport(
        png=png,
        pdf=pdf_path,
        settings=settings,
        dpi=dpi_f,
        shape=(rows, cols),
        size_mm=size,
        speckle_size_mm=d_mm,
        softness_mm=s_mm,
        speckle_size_dots=d_dots,
        softness_dots=s_dots,
        generator=gen,
    )


def regenerate(settings: str | os.PathLike[str] | dict[str, Any]) -> UInt8Array:
    """Regenerate an exported pattern (8-bit dots) from its JSON file or dict."""
    from ..patterns import speckle_pattern

    if isinstance(settings, dict):
        record = settings
    else:
        p = Path(settings)
        if not p.is_file():
            raise InputError(
                f"settings={str(p)!r}: no such file; give the .json written by export_pattern"
            )
        record = json.loads(p.read_text(encoding="utf-8"))
    gen = dict(record.get("generator", {}))
    if "shape" not in gen:
        raise InputError("settings: no 'generator' table with a shape; not an export record")
    gen["shape"] = tuple(gen["shape"])
    img = speckle_pattern(**gen)
    return np.rint(np.clip(img, 0.0, 255.0)).astype(np.uint8)
