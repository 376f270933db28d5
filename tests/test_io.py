import numpy as np
import pytest
from PIL import Image

from dicblur import ImageReadError, InputError, load_image, save_image


@pytest.fixture
def ramp():
    return np.add.outer(np.arange(20.0), np.arange(30.0) * 7.0)  # 0 .. 222


@pytest.mark.parametrize("ext", [".tif", ".tiff", ".png"])
@pytest.mark.parametrize("bits", [8, 16])
def test_round_trip(tmp_path, ext, bits, ramp):
    img = ramp * (200 if bits == 16 else 1)
    path = save_image(tmp_path / f"a{ext}", img, bit_depth=bits)
    back = load_image(path)
    assert back.dtype == np.float64
    np.testing.assert_array_equal(back, img)


def test_bmp_and_jpeg(tmp_path, ramp):
    save_image(tmp_path / "a.bmp", ramp)
    np.testing.assert_array_equal(load_image(tmp_path / "a.bmp"), ramp)
    Image.fromarray(ramp.astype(np.uint8)).save(tmp_path / "a.jpg", quality=95)
    back = load_image(tmp_path / "a.jpg")
    assert np.abs(back - ramp).max() < 12  # lossy


def test_rounding_and_clipping_stated(tmp_path):
    img = np.array([[-3.0, 0.5, 1.5, 254.6], [255.4, 300.0, 2.5, 7.49]])
    with pytest.warns(UserWarning, match="2 pixel"):
        save_image(tmp_path / "c.png", img)
    back = load_image(tmp_path / "c.png")
    # rint: ties to even; clip to 0..255
    np.testing.assert_array_equal(back, [[0, 0, 2, 255], [255, 255, 2, 7]])


def test_colour_to_grey_with_warning(tmp_path):
    rgb = np.zeros((4, 5, 3), dtype=np.uint8)
    rgb[..., 0] = 100
    rgb[..., 1] = 200
    rgb[..., 2] = 50
    Image.fromarray(rgb).save(tmp_path / "rgb.png")
    with pytest.warns(UserWarning, match="colour"):
        grey = load_image(tmp_path / "rgb.png")
    np.testing.assert_allclose(grey, 0.299 * 100 + 0.587 * 200 + 0.114 * 50)


@pytest.mark.parametrize("mode", ["L", "I;16"])
def test_lzw_tiff_made_here(tmp_path, mode):
    # tifffile needs imagecodecs for LZW; the loader must fall back to Pillow.
    data = (np.arange(64 * 48).reshape(64, 48) % 251).astype(np.uint8 if mode == "L" else np.uint16)
    if mode == "I;16":
        data = data * 200
    Image.fromarray(data).save(tmp_path / "lzw.tif", compression="tiff_lzw")
    np.testing.assert_array_equal(load_image(tmp_path / "lzw.tif"), data)


def test_real_lzw_tiff(real_data):
    img = load_image(real_data / "sundic_planar" / "img_0.tif")
    assert img.shape == (582, 1514)
    assert img.min() == 4 and img.max() == 255
    assert abs(img.mean() - 72.5) < 0.1


def test_bad_files(tmp_path):
    with pytest.raises(ImageReadError, match="no such file"):
        load_image(tmp_path / "missing.tif")
    with pytest.raises(ImageReadError, match="directory"):
        load_image(tmp_path)
    (tmp_path / "empty.tif").write_bytes(b"")
    with pytest.raises(ImageReadError, match="empty"):
        load_image(tmp_path / "empty.tif")
    (tmp_path / "text.tif").write_text("this is not an image\n" * 10)
    with pytest.raises(ImageReadError, match="cannot be read"):
        load_image(tmp_path / "text.tif")
    save_image(tmp_path / "full.tif", np.full((200, 200), 9.0))
    raw = (tmp_path / "full.tif").read_bytes()
    (tmp_path / "trunc.tif").write_bytes(raw[: len(raw) // 3])
    with pytest.raises(ImageReadError):
        load_image(tmp_path / "trunc.tif")
    (tmp_path / "noise.png").write_bytes(b"\x89PNG\r\n\x1a\n" + b"\x00" * 50)
    with pytest.raises(ImageReadError):
        load_image(tmp_path / "noise.png")


def test_bad_save_arguments(tmp_path):
    with pytest.raises(InputError, match="bit_depth"):
        save_image(tmp_path / "a.png", np.zeros((3, 3)), bit_depth=12)
    with pytest.raises(InputError, match="NaN"):
        save_image(tmp_path / "a.png", np.full((3, 3), np.nan))
    with pytest.raises(InputError, match="extension"):
        save_image(tmp_path / "a.gif", np.zeros((3, 3)))
    with pytest.raises(InputError, match="does not exist"):
        save_image(tmp_path / "nowhere" / "a.png", np.zeros((3, 3)))
