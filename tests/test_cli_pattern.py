import json

import numpy as np
import pytest

from dicblur import load_image, save_image, speckle_pattern
from dicblur.cli import main


def test_generate_and_metrics(tmp_path, capsys):
    out = tmp_path / "p.tif"
    assert (
        main(
            [
                "pattern",
                "generate",
                str(out),
                "--size",
                "96x128",
                "--speckle-size",
                "4",
                "--seed",
                "1",
                "--softness",
                "0.5",
            ]
        )
        == 0
    )
    img = load_image(out)
    assert img.shape == (96, 128)
    settings = json.loads((tmp_path / "p.tif.json").read_text())
    assert settings["generator"]["seed"] == 1
    expected = np.clip(
        np.rint(speckle_pattern((96, 128), speckle_size=4, softness=0.5, seed=1)), 0, 255
    )
    np.testing.assert_array_equal(img, expected)
    capsys.readouterr()
    assert main(["pattern", "metrics", str(out), "--subset", "21", "--noise", "2", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["subset"] == 21 and data["match_score_x_mean"] > 0


def test_generate_16bit_and_preset(tmp_path):
    assert (
        main(
            [
                "pattern",
                "generate",
                str(tmp_path / "p.png"),
                "--size",
                "64",
                "--bit-depth",
                "16",
                "--seed",
                "2",
            ]
        )
        == 0
    )
    assert load_image(tmp_path / "p.png").max() == 65535
    assert (
        main(
            [
                "pattern",
                "generate",
                str(tmp_path / "q.png"),
                "--size",
                "64",
                "--preset",
                "paper4",
                "--seed",
                "2",
            ]
        )
        == 0
    )


def test_noise_command(tmp_path, capsys):
    rng = np.random.default_rng(0)
    base = speckle_pattern(128, speckle_size=4, contrast=0.6, seed=3)
    save_image(tmp_path / "a.tif", base + rng.normal(0, 3, base.shape), bit_depth=16)
    save_image(tmp_path / "b.tif", base + rng.normal(0, 3, base.shape), bit_depth=16)
    assert main(["noise", str(tmp_path / "a.tif"), str(tmp_path / "b.tif"), "--json"]) == 0
    sigma = json.loads(capsys.readouterr().out)["noise_sigma"]
    assert sigma == pytest.approx(3.0 * np.sqrt(1 + 1 / 36 / 9), rel=0.05)  # + rounding


@pytest.mark.parametrize(
    "argv",
    [
        ["pattern", "metrics", "/definitely/missing.tif"],
        ["pattern", "metrics", "{tmp}"],
        ["pattern", "metrics", "{tmp}/empty.tif"],
        ["pattern", "metrics", "{tmp}/text.tif"],
        ["pattern", "metrics", "{tmp}/ok.tif", "--subset", "20"],
        ["pattern", "metrics", "{tmp}/ok.tif", "--subset", "-3"],
        ["pattern", "metrics", "{tmp}/ok.tif", "--subset", "101"],
        ["pattern", "metrics", "{tmp}/ok.tif", "--gradient", "roberts"],
        ["pattern", "metrics", "{tmp}/tiny.png"],
        ["pattern", "generate", "{tmp}/x.tif", "--size", "abc"],
        ["pattern", "generate", "{tmp}/x.tif", "--density", "2"],
        ["pattern", "generate", "{tmp}/x.tif", "--preset", "nope"],
        ["pattern", "metrics"],
        ["nonsense-command"],
    ],
)
def test_cli_errors_exit_2_without_traceback(tmp_path, capsys, argv):
    (tmp_path / "empty.tif").write_bytes(b"")
    (tmp_path / "text.tif").write_text("not an image")
    save_image(tmp_path / "ok.tif", speckle_pattern(64, speckle_size=3, seed=1))
    save_image(tmp_path / "tiny.png", np.zeros((1, 1)))
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert err.strip()


def _saved_pattern(tmp_path, size: int, seed: int):
    """An 8-bit PNG of a generated pattern and the grey levels it holds."""
    out = tmp_path / "p.png"
    img = np.clip(
        np.rint(speckle_pattern((size, size), speckle_size=4, softness=0.5, seed=seed)), 0, 255
    )
    save_image(out, img)
    return out, img


PREDICT = ["pattern", "predict"]
NOISE_SUBSET = ["--noise", "2", "--subset", "21"]


def _blurs(*w: str) -> list[str]:
    """``--blur`` once for each value."""
    return [a for v in w for a in ("--blur", v)]


def test_predict_from_the_static_image(tmp_path, capsys):
    import dicblur

    out, img = _saved_pattern(tmp_path, 128, 2)
    args = [*PREDICT, str(out), *NOISE_SUBSET, *_blurs("0", "2"), "--angle", "90", "--json"]
    assert main([*args, "-o", str(tmp_path / "m.json")]) == 0
    data = json.loads(capsys.readouterr().out.split("\nwrote")[0])
    want = dicblur.predict_from_pattern(
        img, [0.0, 2.0], noise_sigma=2.0, subset=21, motion=(1.0, 0.0)
    )
    np.testing.assert_allclose(data["u_e"], want.u_e, rtol=1e-6)
    model = dicblur.BlurUncertaintyModel.from_json(str(tmp_path / "m.json"))
    assert model.provenance["image"] == str(out)
    assert main([*PREDICT, str(out), *NOISE_SUBSET, "--shape", "quadratic"]) == 2
    assert "--shape='quadratic'" in capsys.readouterr().err


def test_predict_with_the_subpixel_position(tmp_path, capsys):
    import dicblur

    out, img = _saved_pattern(tmp_path, 96, 4)
    args = [*PREDICT, str(out), *NOISE_SUBSET, *_blurs("0", "1"), "--subpixel", "0.5", "--json"]
    assert main(args) == 0
    data = json.loads(capsys.readouterr().out)
    want = dicblur.predict_from_pattern(img, [0.0, 1.0], noise_sigma=2.0, subset=21, subpixel=0.5)
    np.testing.assert_allclose(data["u_blur"], want.u_blur, rtol=1e-6)
    assert data["u_blur"][0] > 0 and data["subpixel"] == 0.5
    assert main([*PREDICT, str(out), *NOISE_SUBSET, "--subpixel", "half"]) == 2
    assert "--subpixel='half'" in capsys.readouterr().err


def test_predict_says_where_dic_breaks_down(tmp_path, capsys):
    import dicblur

    img = dicblur.speckle_pattern(
        (128, 128), speckle_size=2.0, density=0.5, softness=0.9, levels=(55.0, 135.0), seed=3
    )
    out = tmp_path / "fine.tif"
    save_image(out, img)
    blur = _blurs("0", "4", "8", "10")
    assert main([*PREDICT, str(out), *NOISE_SUBSET, *blur]) == 0
    text = capsys.readouterr().out
    assert "DIC breaks down from W = " in text
    assert main([*PREDICT, str(out), *NOISE_SUBSET, *blur, "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["breakdown_blur"] in (8.0, 10.0)
