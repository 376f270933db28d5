"""A corpus of damaged and hostile input files, built by the tests (never shipped).

:func:`build_corpus` writes every file into one folder and returns it; the names are the
keys the corpus tests use. Bombs are written by hand (a header that declares a huge image
over a few bytes of data), so building the corpus takes well under a second.
"""

from __future__ import annotations

import csv
import json
import struct
import zlib
from pathlib import Path

import numpy as np


def png_bytes(
    width: int, height: int, data: bytes | None = None, *, color_type: int = 0, bit_depth: int = 8
) -> bytes:
    """A PNG file whose IHDR declares ``width x height``, with ``data`` as its IDAT."""

    def chunk(kind: bytes, body: bytes) -> bytes:
        return (
            struct.pack(">I", len(body))
            + kind
            + body
            + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF)
        )

    ihdr = struct.pack(">IIBBBBB", width, height, bit_depth, color_type, 0, 0, 0)
    if data is None:
        # a few compressed rows of zeros: the stream ends long before the declared size
        data = zlib.compress(b"\0" * (width + 1) * 4, 9)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", data) + chunk(b"IEND", b"")


def tiff_bytes(
    width: int, height: int, *, bits: int = 8, compression: int = 8, data: bytes | None = None
) -> bytes:
    """A little-endian single-strip grey TIFF declaring ``width x height``."""
    if data is None:
        data = zlib.compress(b"\0" * 4096, 9)
    tags = [  # (tag, type, count, value) with type 3 = SHORT, 4 = LONG
        (256, 4, 1, width),
        (257, 4, 1, height),
        (258, 3, 1, bits),
        (259, 3, 1, compression),
        (262, 3, 1, 1),
        (273, 4, 1, 0),
        (277, 3, 1, 1),
        (278, 4, 1, height),
        (279, 4, 1, len(data)),
    ]
    ifd_offset = 8
    n = len(tags)
    data_offset = ifd_offset + 2 + 12 * n + 4
    out = bytearray(b"II*\0" + struct.pack("<I", ifd_offset) + struct.pack("<H", n))
    for tag, typ, count, value in tags:
        if tag == 273:
            value = data_offset
        if typ == 3:
            out += struct.pack("<HHIHH", tag, typ, count, value, 0)
        else:
            out += struct.pack("<HHII", tag, typ, count, value)
    out += struct.pack("<I", 0)
    return bytes(out) + data


def speckle(shape: tuple[int, int] = (64, 64), seed: int = 1) -> np.ndarray:
    """A small textured image in 0..255 (a smoothed random field), float64."""
    from scipy import ndimage

    rng = np.random.default_rng(seed)
    field = ndimage.gaussian_filter(rng.normal(size=shape), 1.5, mode="wrap")
    field = (field - field.min()) / (field.max() - field.min())
    return 20.0 + 215.0 * field


def _valid_model_dict(folder: Path) -> dict:
    from dicblur.models import fit_blur_model, mismatch_model, sssig_decay

    rng = np.random.default_rng(0)
    w = np.tile(np.arange(0.0, 10.01, 1.0), 2)
    noise = np.repeat([1.0, 2.0], 11)
    s = sssig_decay(w, 1.85e5, 0.022)
    u = mismatch_model(w, s, noise, c=7e-4) * np.exp(rng.normal(0, 0.02, w.size))
    model = fit_blur_model(w, s, u, noise_sigma=noise)
    return json.loads(model.to_json())


def build_corpus(folder: Path) -> Path:
    """Write the whole corpus into ``folder`` and return it."""
    import tifffile
    from PIL import Image

    folder.mkdir(parents=True, exist_ok=True)
    good = speckle()
    good8 = np.rint(good).astype(np.uint8)
    tifffile.imwrite(folder / "good.tif", good8, photometric="minisblack")
    tifffile.imwrite(folder / "good2.tif", np.roll(good8, 1, axis=1), photometric="minisblack")
    # --- images ------------------------------------------------------------------------
    (folder / "empty.tif").write_bytes(b"")
    (folder / "text.tif").write_text("this is not an image\n")
    (folder / "text.png").write_text("this is not an image either\n")
    raw = (folder / "good.tif").read_bytes()
    (folder / "truncated.tif").write_bytes(raw[: len(raw) // 3])
    Image.fromarray(good8).save(folder / "good.png")
    raw = (folder / "good.png").read_bytes()
    (folder / "truncated.png").write_bytes(raw[: len(raw) // 2])
    (folder / "bomb.png").write_bytes(png_bytes(12000, 12000))
    (folder / "bomb.tif").write_bytes(tiff_bytes(30000, 30000))
    rng = np.random.default_rng(5)
    (folder / "random.tif").write_bytes(b"II*\0" + rng.bytes(600))
    (folder / "random.png").write_bytes(b"\x89PNG\r\n\x1a\n" + rng.bytes(600))
    # palette: indices 0..255 mapped to a non-identity grey ramp (index i -> 255 - i)
    idx = good8
    ramp = (255 - np.arange(256)).astype(np.uint16) * 257
    cmap = np.stack([ramp, ramp, ramp])
    tifffile.imwrite(folder / "palette.tif", idx, photometric="palette", colormap=cmap)
    pim = Image.fromarray(idx, mode="P")
    pim.putpalette([int(v) // 257 for v in np.repeat(ramp, 3)])
    pim.save(folder / "palette.png")
    five = np.stack([good8] * 5, axis=-1)
    tifffile.imwrite(
        folder / "five_channels.tif", five, photometric="minisblack", planarconfig="contig"
    )
    f = good.astype(np.float32)
    f[3, 4] = np.nan
    tifffile.imwrite(folder / "nan.tif", f)
    f = good.astype(np.float32)
    f[5, 5] = np.inf
    tifffile.imwrite(folder / "inf.tif", f)
    tifffile.imwrite(folder / "huge.tif", good * 1e298)  # values near 1e300
    tifffile.imwrite(folder / "unit.tif", (good / 255).astype(np.float32))  # normalised 0..1
    tifffile.imwrite(folder / "signed.tif", good8.astype(np.int16) - 128)  # levels -108..107
    tifffile.imwrite(
        folder / "constant.tif", np.full((64, 64), 128, np.uint8), photometric="minisblack"
    )
    tifffile.imwrite(folder / "tiny.tif", good8[:3, :3], photometric="minisblack")
    tifffile.imwrite(folder / "row.tif", good8[:1, :], photometric="minisblack")
    tifffile.imwrite(folder / "complex.tif", good.astype(np.complex64))
    # one scene at two bit depths (8-bit and the same grey levels scaled to 16 bits)
    tifffile.imwrite(
        folder / "scene16.tif", (good8.astype(np.uint16) * 257), photometric="minisblack"
    )
    tifffile.imwrite(
        folder / "bigger.tif", np.rint(speckle((80, 80))).astype(np.uint8), photometric="minisblack"
    )
    # --- model JSON --------------------------------------------------------------------
    model = _valid_model_dict(folder)
    (folder / "model.json").write_text(json.dumps(model))
    m = dict(model)
    del m["decay"]
    (folder / "model_missing_key.json").write_text(json.dumps(m))
    m = dict(model)
    m["decay"] = dict(model["decay"], values="not numbers")
    (folder / "model_wrong_type.json").write_text(json.dumps(m))
    m = dict(model)
    m["noise_levels"] = {"a": 1}
    (folder / "model_wrong_type2.json").write_text(json.dumps(m))
    (folder / "model_binary.json").write_bytes(b"{\xff\xfe\x00\x81binary" + rng.bytes(200))
    (folder / "model_tiff.json").write_bytes((folder / "good.tif").read_bytes())
    (folder / "model_truncated.json").write_text(json.dumps(model)[:300])
    (folder / "model_list.json").write_text("[1, 2, 3]")
    (folder / "model_empty.json").write_text("")
    m = json.loads(json.dumps(model))
    m["mismatch"]["values"][0] = float("nan")
    (folder / "model_nan.json").write_text(json.dumps(m))  # writes NaN (not strict JSON)
    m = json.loads(json.dumps(model))
    m["decay"]["values"][0] = float("inf")
    (folder / "model_inf.json").write_text(json.dumps(m))
    m = dict(model, schema="dicblur.BlurUncertaintyModel/99")
    (folder / "model_version.json").write_text(json.dumps(m))
    m = json.loads(json.dumps(model))
    m["decay"]["names"] = ["sssig0"]  # fewer names than values
    (folder / "model_inconsistent.json").write_text(json.dumps(m))
    # --- result tables (fit) -----------------------------------------------------------
    w = np.arange(0.0, 8.01, 1.0)
    s = 1.8e5 * np.exp(-0.02 * w * w)
    u = 0.01 * (1 + 0.01 * w * w)

    def table(
        name: str,
        u_e: list[object],
        header: tuple[str, ...] = ("blur", "sssig", "u_e"),
    ) -> None:
        with (folder / name).open("w", newline="") as fh:
            wr = csv.writer(fh)
            wr.writerow(header)
            for row in zip(w, s, u_e, strict=True):
                wr.writerow(row)

    table("results.csv", list(u))
    table("neg_ue.csv", list(-u))
    table("nan_ue.csv", ["nan"] * w.size)
    table("inf_ue.csv", ["inf"] * w.size)
    table("text_ue.csv", ["abc"] * w.size)
    table("zero_ue.csv", [0.0] * w.size)
    table("no_ue.csv", list(u), header=("blur", "sssig", "u_x"))
    with (folder / "noisy.csv").open("w", newline="") as fh:
        wr = csv.writer(fh)
        wr.writerow(("blur", "sssig", "u_e", "noise"))
        wr.writerows(zip(w, s, u, [2.0] * w.size, strict=True))
    with (folder / "zero_noise.csv").open("w", newline="") as fh:
        wr = csv.writer(fh)
        wr.writerow(("blur", "sssig", "u_e", "noise"))
        wr.writerows(zip(w, s, u, [0.0] * w.size, strict=True))
    (folder / "binary.csv").write_bytes(b"blur,sssig,u_e\n\xff\xfe\x00\x81" + rng.bytes(300))
    (folder / "header_only.csv").write_text("blur,sssig,u_e\n")
    (folder / "empty.csv").write_text("")
    # --- campaign specs (TOML) ---------------------------------------------------------
    base = """
[campaign]
seed = 1
repetitions = {reps}

[[pattern]]
name = "p"
{pattern}

[blur]
lengths = {lengths}

[noise]
model = "per-exposure"
levels = [1.0]

[dic]
subsets = [{subset}]
step = 8
"""

    def spec(
        name: str,
        *,
        reps: object = 1,
        pattern: str = 'generator = "speckle"\nshape = [64, 64]',
        lengths: str = "[0.0, 1.0]",
        subset: int = 15,
    ) -> None:
        (folder / name).write_text(
            base.format(reps=reps, pattern=pattern, lengths=lengths, subset=subset)
        )

    spec("spec.toml")
    spec("spec_reps.toml", reps="1e9")
    spec("spec_reps_int.toml", reps=1_000_000_000)
    spec("spec_wide_blur.toml", lengths="[0.0, 500.0]")
    spec("spec_constant.toml", pattern='path = "constant.tif"')
    spec("spec_missing_image.toml", pattern='path = "no_such_image.tif"')
    spec("spec_bomb.toml", pattern='path = "bomb.png"')
    spec("spec_text_image.toml", pattern='path = "text.tif"')
    spec("spec_huge_shape.toml", pattern='generator = "speckle"\nshape = [100000, 100000]')
    spec("spec_subset_too_big.toml", subset=101)
    spec("spec_wide_blur_image.toml", pattern='path = "good.tif"', lengths="[0.0, 300.0]")
    (folder / "spec_binary.toml").write_bytes(b"\xff\xfe\x00[campaign" + rng.bytes(200))
    (folder / "spec_invalid.toml").write_text("[campaign\nseed = = 1\n")
    (folder / "spec_empty.toml").write_text("")
    # --- damaged Zarr stores -----------------------------------------------------------
    (folder / "notastore.zarr").mkdir()
    (folder / "notastore.zarr" / "junk.txt").write_text("hello")
    (folder / "file.zarr").write_text("not a folder")
    z = folder / "badmeta.zarr"
    z.mkdir()
    (z / ".zgroup").write_text("{ this is not json")
    (z / ".zattrs").write_bytes(rng.bytes(64))
    return folder
