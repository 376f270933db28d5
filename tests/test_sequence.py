"""Lazy recording readers: each format on tiny files the tests write themselves."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from dicblur.errors import ImageReadError
from dicblur.sequence import natural_key, open_recording


def _frames(n=5, shape=(12, 16), top=255, seed=0):
    rng = np.random.default_rng(seed)
    return rng.integers(0, top + 1, size=(n, *shape)).astype(np.uint16)


def write_cine(path, frames, *, fps=5000, exposure_ns=100_000, bits=16, truncate=0):
    """A monochrome uncompressed Phantom cine, byte by byte from the published layout
    (Vision Research "Cine File Format"; the field tables pims encodes): CINEFILEHEADER,
    BITMAPINFOHEADER, SETUP (frame_rate, shutter_ns, real_bpp), tagged blocks 1002 (time
    stamps) and 1003 (exposure), the image offset table, and per image an 8-byte annotation
    then the rows bottom-up."""
    from pims.cine import BITMAP_INFO_FIELDS, HEADER_FIELDS, SETUP_FIELDS

    n, rows, cols = frames.shape
    dtype = "<u1" if bits == 8 else "<u2"

    def pack(fields, values):
        out = b""
        for name, fmt in fields:
            s = struct.Struct("<" + fmt)
            v = values.get(name)
            if v is None:
                v = [b"" if c == "s" else 0 for c in _kinds(fmt)]
            elif not isinstance(v, list | tuple):
                v = [v]
            out += s.pack(*v)
        return out

    setup_size = sum(struct.calcsize("<" + f) for _, f in SETUP_FIELDS)
    head_size = sum(struct.calcsize("<" + f) for _, f in HEADER_FIELDS)
    bmp_size = sum(struct.calcsize("<" + f) for _, f in BITMAP_INFO_FIELDS)
    off_setup = head_size + bmp_size
    tag_ts = struct.pack("<IHH", 8 + 8 * n, 1002, 1) + struct.pack(
        f"<{n}Q", *[(1_700_000_000 << 32) + int(k / fps * 2**32) for k in range(n)]
    )
    tag_exp = struct.pack("<IHH", 8 + 4 * n, 1003, 0) + struct.pack(
        f"<{n}I", *[int(exposure_ns * 1e-9 * 2**32)] * n
    )
    off_offsets = off_setup + setup_size + len(tag_ts) + len(tag_exp)
    first_image = off_offsets + 8 * n
    img_bytes = rows * cols * np.dtype(dtype).itemsize
    offsets = [first_image + k * (8 + img_bytes) for k in range(n)]
    header = pack(
        HEADER_FIELDS,
        {
            "type": b"CI",
            "header_size": head_size,
            "version": 1,
            "total_image_count": n,
            "image_count": n,
            "off_image_header": head_size,
            "off_setup": off_setup,
            "off_image_offsets": off_offsets,
            "trigger_time": 1_700_000_000 << 32,
        },
    )
    bmp = pack(
        BITMAP_INFO_FIELDS,
        {
            "bi_size": bmp_size,
            "bi_width": cols,
            "bi_height": rows,
            "bi_planes": 1,
            "bi_bit_count": bits,
            "bi_image_size": img_bytes,
        },
    )
    setup = pack(
        SETUP_FIELDS,
        {
            "length": setup_size,
            "software_version": 100000,
            "frame_rate": fps,
            "shutter_ns": exposure_ns,
            "real_bpp": bits if bits != 16 else 12,
            "cfa": 0,
        },
    )
    body = b"".join(
        struct.pack("<II", 8, img_bytes) + np.ascontiguousarray(f[::-1]).astype(dtype).tobytes()
        for f in frames
    )
    data = header + bmp + setup + tag_ts + tag_exp + struct.pack(f"<{n}Q", *offsets) + body
    path.write_bytes(data[: len(data) - truncate] if truncate else data)
    return path


def _kinds(fmt):
    out = []
    num = ""
    for c in fmt:
        if c.isdigit():
            num += c
            continue
        if c == "s":
            out.append("s")
        else:
            out += [c] * (int(num) if num else 1)
        num = ""
    return out


def write_mraw_12bit(path, frames, *, fps=2000, shutter=2e-4):
    n, rows, cols = frames.shape
    flat = frames.reshape(-1).astype(np.uint16)
    a, b = flat[0::2], flat[1::2]
    packed = np.stack([(a >> 4) & 0xFF, ((a & 0x0F) << 4) | (b >> 8), b & 0xFF], axis=1)
    path.with_suffix(".mraw").write_bytes(packed.astype(np.uint8).tobytes())
    info = {
        "Record Rate(fps)": fps,
        "Shutter Speed(s)": shutter,
        "Total Frame": n,
        "Original Total Frame": n,
        "Image Width": cols,
        "Image Height": rows,
        "Color Type": "Mono",
        "Color Bit": 12,
        "File Format": "MRaw",
        "EffectiveBit Depth": 12,
        "EffectiveBit Side": "Lower",
    }
    with path.with_suffix(".cih").open("w") as fh:
        fh.write("#Camera Information Header\n")
        for k, v in info.items():
            fh.write(f"{k} : {v}\n")
    return path.with_suffix(".cih")


def test_natural_sort_folder_and_glob(tmp_path):
    from PIL import Image

    frames = _frames(12).astype(np.uint8)
    for k, f in enumerate(frames):
        Image.fromarray(f).save(tmp_path / f"img{k}.png")
    rec = open_recording(tmp_path)
    assert rec.kind == "folder" and len(rec) == 12 and rec.shape == (12, 16)
    assert rec.names[:3] == ["img0.png", "img1.png", "img2.png"] and rec.names[-1] == "img11.png"
    np.testing.assert_array_equal(rec[10], frames[10])
    assert rec.bit_depth == 8 and rec.fps is None and rec.exposure is None
    g = open_recording(str(tmp_path / "img1*.png"))
    assert g.names == ["img1.png", "img10.png", "img11.png"]
    assert natural_key("a2b") < natural_key("a10b")


def test_folder_frame_of_another_size(tmp_path):
    import tifffile

    frames = _frames(3, top=4095)
    for k, f in enumerate(frames):
        tifffile.imwrite(tmp_path / f"f{k}.tif", f)
    tifffile.imwrite(tmp_path / "f3.tif", frames[0][:-1])
    rec = open_recording(tmp_path)
    assert rec.bit_depth == 16
    np.testing.assert_array_equal(rec[2], frames[2])
    with pytest.raises(ImageReadError, match=r"frame 3 \(f3.tif\): 11x16 px"):
        rec[3]


def test_multipage_tiff_is_lazy(tmp_path):
    import tifffile

    frames = _frames(6, top=65535)
    tifffile.imwrite(tmp_path / "stack.tif", frames)
    with open_recording(tmp_path / "stack.tif") as rec:
        assert rec.kind == "tiff-stack" and len(rec) == 6 and rec.bit_depth == 16
        np.testing.assert_array_equal(rec[4], frames[4])
        assert rec[-1].dtype == np.float64


@pytest.mark.parametrize("bits", [8, 16])
def test_cine(tmp_path, bits):
    frames = _frames(4, top=255 if bits == 8 else 4095)
    path = write_cine(tmp_path / "a.cine", frames, bits=bits, fps=5000, exposure_ns=150_000)
    rec = open_recording(path)
    assert rec.kind == "cine" and len(rec) == 4 and rec.shape == (12, 16)
    assert rec.fps == 5000
    assert rec.exposure == pytest.approx(150e-6, rel=1e-6)
    for k in range(4):
        np.testing.assert_array_equal(rec[k], frames[k])


def test_cine_truncated_keeps_complete_frames(tmp_path):
    frames = _frames(4)
    path = write_cine(tmp_path / "t.cine", frames, truncate=10)
    with pytest.warns(UserWarning, match="3 of the 4 frames"):
        rec = open_recording(path)
    assert len(rec) == 3
    np.testing.assert_array_equal(rec[2], frames[2])


@pytest.mark.parametrize("bits", [8, 16])
def test_mraw_written_by_pymraw(tmp_path, bits):
    import pyMRAW

    frames = _frames(5, top=255 if bits == 8 else 65535)
    pyMRAW.save_mraw(
        frames,
        str(tmp_path / "rec.cih"),
        bit_depth=bits,
        info_dict={"Record Rate(fps)": 4000, "Shutter Speed(s)": 0.0001},
    )
    rec = open_recording(tmp_path / "rec.cih")
    assert rec.kind == "mraw" and len(rec) == 5 and rec.fps == 4000
    assert rec.exposure == pytest.approx(1e-4)
    np.testing.assert_array_equal(rec[3], frames[3])
    rec2 = open_recording(tmp_path / "rec.mraw")  # the data file finds its header
    np.testing.assert_array_equal(rec2[0], frames[0])


def test_mraw_12bit_and_truncated(tmp_path):
    frames = _frames(4, top=4095)
    head = write_mraw_12bit(tmp_path / "r12", frames)
    rec = open_recording(head)
    assert rec.bit_depth == 12
    for k in range(4):
        np.testing.assert_array_equal(rec[k], frames[k])
    data = head.with_suffix(".mraw")
    data.write_bytes(data.read_bytes()[:-5])
    with pytest.warns(UserWarning, match="3 of the 4 frames"):
        rec = open_recording(head)
    assert len(rec) == 3


def test_missing_inputs(tmp_path):
    with pytest.raises(ImageReadError, match="no such file"):
        open_recording(tmp_path / "nope")
    with pytest.raises(ImageReadError, match="no TIFF/PNG/BMP"):
        open_recording(tmp_path)
    (tmp_path / "x.mraw").write_bytes(b"\0" * 10)
    with pytest.raises(ImageReadError, match="header"):
        open_recording(tmp_path / "x.mraw")
