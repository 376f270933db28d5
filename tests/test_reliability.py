"""Reliability promises of issue 15 (docs/reliability.md): property tests of the loaders
and parsers, a bounded random-bytes fuzz of the image loader, size limits, atomic writes,
the output rule, and the API-level refusals behind the CLI corpus."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import dicblur
from bad_inputs import build_corpus, png_bytes, speckle
from dicblur.campaign import parse_spec
from dicblur.cli import cli_message, main
from dicblur.errors import ConfigError, ImageReadError, InputError
from dicblur.io import (
    atomic_open,
    atomic_path,
    check_output,
    load_image,
    max_pixels,
    read_image_header,
    write_text,
)
from dicblur.models import BlurUncertaintyModel, parse_quantity

FUZZ = settings(
    max_examples=60,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)


@pytest.fixture(scope="module")
def corpus(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_corpus(tmp_path_factory.mktemp("corpus"))


def _load_or_refuse(path: Path) -> None:
    """The loader's contract: a finite 2-D float64 image, or a dicblur error."""
    try:
        img = load_image(path)
    except (ImageReadError, InputError):
        return
    assert img.dtype == np.float64 and img.ndim == 2
    assert np.isfinite(img).all()


# ------------------------------------------------------------------ image loader fuzz
@FUZZ
@given(
    data=st.binary(min_size=1, max_size=2048),
    prefix=st.sampled_from([b"", b"II*\0", b"MM\0*", b"\x89PNG\r\n\x1a\n", b"BM"]),
    suffix=st.sampled_from([".tif", ".png", ".bmp", ".jpg", ".dat"]),
)
def test_fuzz_random_bytes(tmp_path: Path, data: bytes, prefix: bytes, suffix: str) -> None:
    path = tmp_path / f"fuzz{suffix}"
    path.write_bytes(prefix + data)
    _load_or_refuse(path)


@FUZZ
@given(
    cut=st.integers(1, 4000),
    flips=st.lists(st.tuples(st.integers(0, 10**6), st.integers(0, 255)), max_size=8),
    kind=st.sampled_from(
        ["good.tif", "good.png", "palette.tif", "five_channels.tif", "scene16.tif", "huge.tif"]
    ),
)
def test_fuzz_damaged_files(
    corpus: Path, tmp_path: Path, cut: int, flips: list[tuple[int, int]], kind: str
) -> None:
    raw = bytearray((corpus / kind).read_bytes())
    raw = raw[: max(1, len(raw) - cut)] if cut % 3 == 0 else raw
    for pos, val in flips:
        raw[pos % len(raw)] = val
    path = tmp_path / kind
    path.write_bytes(bytes(raw))
    _load_or_refuse(path)


@FUZZ
@given(width=st.integers(1, 2**31 - 1), height=st.integers(1, 2**31 - 1))
def test_fuzz_declared_png_sizes(tmp_path: Path, width: int, height: int) -> None:
    path = tmp_path / "declared.png"
    path.write_bytes(png_bytes(width, height, data=b"x\x9c\x03\x00\x00\x00\x00\x01"))
    if width * height > max_pixels():
        with pytest.raises(InputError, match="max-pixels"):
            load_image(path)
    else:
        _load_or_refuse(path)


# ------------------------------------------------------------------ unit parser
_UNITS = {
    "velocity": ["mm/s", "m/s", "um/ms", "px/s"],
    "time": ["s", "ms", "us", "ns"],
    "scale": ["mm/px", "px/mm", "um/px"],
    "length": ["mm", "m", "um", "px"],
    "blur": ["px", "mm"],
}


@FUZZ
@given(
    text=st.text(max_size=30),
    kind=st.sampled_from(sorted(_UNITS)),
    scale=st.one_of(st.none(), st.floats(1e-6, 1e3)),
)
def test_units_any_text(text: str, kind: str, scale: float | None) -> None:
    try:
        x = parse_quantity(text, kind, name="--velocity", scale=scale)  # type: ignore[arg-type]
    except InputError as exc:
        assert "\n" not in str(exc) and "--velocity=" in str(exc)
        return
    assert math.isfinite(x)


@FUZZ
@given(
    x=st.floats(-1e12, 1e12, allow_nan=False), kind=st.sampled_from(sorted(_UNITS)), data=st.data()
)
def test_units_round_trip(x: float, kind: str, data: st.DataObject) -> None:
    unit = data.draw(st.sampled_from(_UNITS[kind]))
    scale = 0.05
    try:
        got = parse_quantity(f"{x!r}{unit}", kind, scale=scale)  # type: ignore[arg-type]
    except InputError:
        assert (unit == "px/mm" and x == 0) or (kind == "length" and unit == "px" and False)
        return
    base = parse_quantity(f"1{unit}", kind, scale=scale)  # type: ignore[arg-type]
    expect = base / x if unit == "px/mm" else base * x
    assert got == pytest.approx(expect, rel=1e-12, abs=1e-300)


# ------------------------------------------------------------------ spec parser
_toml_leaf = st.one_of(
    st.booleans(),
    st.integers(-(10**12), 10**12),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=8),
)
_toml_value = st.recursive(
    _toml_leaf,
    lambda c: st.one_of(
        st.lists(c, max_size=3), st.dictionaries(st.text(max_size=6), c, max_size=3)
    ),
    max_leaves=8,
)


def _valid_spec() -> dict:
    return {
        "campaign": {"seed": 1, "repetitions": 1},
        "pattern": [{"name": "p", "generator": "speckle", "shape": [48, 48]}],
        "blur": {"lengths": [0.0, 1.0]},
        "noise": {"model": "per-exposure"},
        "dic": {"subsets": [11], "step": 8},
    }


@FUZZ
@given(
    section=st.sampled_from(["campaign", "blur", "noise", "dic", "run", "pattern"]),
    key=st.sampled_from(
        [
            "seed",
            "repetitions",
            "lengths",
            "angles",
            "levels",
            "model",
            "subsets",
            "step",
            "blur_chunk",
            "shape",
            "substeps",
            "tolerance",
            "name",
            "generator",
            "x",
        ]
    ),
    value=_toml_value,
)
def test_spec_parser_mutations(section: str, key: str, value: object) -> None:
    d = _valid_spec()
    target = d[section][0] if section == "pattern" else d.setdefault(section, {})
    target[key] = value
    try:
        spec = parse_spec(d)
    except ConfigError as exc:
        assert "\n" not in str(exc)
        return
    assert spec.n_tasks >= 1
    assert all(math.isfinite(w) and w >= 0 for w in spec.blur)


@FUZZ
@given(text=st.text(max_size=200))
def test_spec_loader_any_text(tmp_path: Path, text: str) -> None:
    path = tmp_path / "spec.toml"
    path.write_text(text, encoding="utf-8")
    try:
        dicblur.load_spec(path)
    except ConfigError:
        pass


# ------------------------------------------------------------------ model loader
def _leaves(d: object, path: tuple = ()) -> list[tuple]:
    if isinstance(d, dict):
        return [p for k, v in d.items() for p in _leaves(v, (*path, k))] + [path]
    if isinstance(d, list):
        return [p for i, v in enumerate(d) for p in _leaves(v, (*path, i))] + [path]
    return [path]


@FUZZ
@given(data=st.data(), value=_toml_value, delete=st.booleans())
def test_model_loader_mutations(
    corpus: Path, data: st.DataObject, value: object, delete: bool
) -> None:
    d = json.loads((corpus / "model.json").read_text())
    paths = [p for p in _leaves(d) if p]
    where = data.draw(st.sampled_from(paths))
    parent = d
    for k in where[:-1]:
        parent = parent[k]
    if delete and isinstance(parent, dict):
        del parent[where[-1]]
    else:
        parent[where[-1]] = value
    try:
        model = BlurUncertaintyModel.from_json(json.dumps(d))
    except InputError as exc:
        assert "\n" not in str(exc)
        return
    try:  # a file that loads must predict, or refuse with a dicblur error
        u = model.predict([0.0, 2.0], 2.0 if model.noise_sigma is None else None).u_e
    except dicblur.DicblurError:
        return
    assert u.shape == (2,)


def test_renamed_fit_parameters_are_refused_on_load(corpus: Path) -> None:
    """A blank, unknown or repeated parameter name in any fit is a damaged file (found by
    the fuzzer above: a blank name of the decay fit loaded, then predict raised KeyError)."""
    d0 = json.loads((corpus / "model.json").read_text())
    cases = 0
    for key, fit in d0.items():
        if not (isinstance(fit, dict) and isinstance(fit.get("names"), list)):
            continue
        for i in range(len(fit["names"])):
            for bad in ("", "bogus", fit["names"][i - 1] if i else None):
                if bad is None or bad == fit["names"][i]:
                    continue
                d = json.loads(json.dumps(d0))
                d[key]["names"][i] = bad
                with pytest.raises(InputError, match=r"names"):
                    BlurUncertaintyModel.from_json(json.dumps(d))
                cases += 1
    assert cases >= 8


def test_model_round_trip_still_exact(corpus: Path) -> None:
    text = (corpus / "model.json").read_text()
    model = BlurUncertaintyModel.from_json(text)
    assert json.loads(model.to_json()) == json.loads(text)


# ------------------------------------------------------------------ decoding and limits
def test_palette_tiff_reads_like_palette_png(corpus: Path) -> None:
    tif, png = load_image(corpus / "palette.tif"), load_image(corpus / "palette.png")
    np.testing.assert_array_equal(tif, png)
    raw = load_image(corpus / "good.tif")
    np.testing.assert_array_equal(tif, 255 - raw)  # the palette, not the raw indices


def test_channels_last_tiff_is_refused_not_read_as_pages(corpus: Path) -> None:
    header = read_image_header(corpus / "five_channels.tif")
    assert header.shape == (64, 64) and header.channels == 5 and header.pages == 1
    with pytest.raises(ImageReadError, match="5 channels"):
        load_image(corpus / "five_channels.tif")


def test_planar_rgb_tiff(tmp_path: Path) -> None:
    import tifffile

    rgb = np.stack([np.full((8, 9), v, np.uint8) for v in (10, 20, 30)])
    tifffile.imwrite(tmp_path / "planar.tif", rgb, photometric="rgb", planarconfig="separate")
    with pytest.warns(UserWarning, match="colour"):
        grey = load_image(tmp_path / "planar.tif")
    assert grey.shape == (8, 9)
    np.testing.assert_allclose(grey, 0.299 * 10 + 0.587 * 20 + 0.114 * 30)


def test_size_limit_override(
    corpus: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    path = tmp_path / "big.png"
    from PIL import Image

    Image.fromarray(np.zeros((300, 400), np.uint8)).save(path)
    with pytest.raises(InputError, match=r"0\.12 Mpx"):
        load_image(path, max_pixels=1000)
    assert load_image(path, max_pixels=120_000).shape == (300, 400)
    monkeypatch.setenv("DICBLUR_MAX_PIXELS", "5e4")
    with pytest.raises(InputError, match="DICBLUR_MAX_PIXELS"):
        load_image(path)
    assert main(["pattern", "metrics", str(path)]) == 2
    assert "--max-pixels" in capsys.readouterr().err
    # --max-pixels raises it for one invocation and restores the environment after
    assert (
        main(
            [
                "--max-pixels",
                "2e5",
                "pattern",
                "generate",
                str(tmp_path / "g.tif"),
                "--size",
                "300x400",
                "--seed",
                "1",
            ]
        )
        == 0
    )
    assert os.environ["DICBLUR_MAX_PIXELS"] == "5e4"
    with pytest.raises(InputError, match="max-pixels"):
        dicblur.speckle_pattern((300, 400), seed=1)


def test_bomb_refused_from_header_without_decoding(
    corpus: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import tifffile
    from PIL import Image

    def no_decode(*a: object, **k: object) -> None:
        raise AssertionError("decoded a bomb")

    monkeypatch.setattr(tifffile.TiffPage, "asarray", no_decode)
    monkeypatch.setattr(Image.Image, "load", no_decode)
    for name in ("bomb.png", "bomb.tif"):
        with pytest.raises(InputError, match=r"30000x30000|12000x12000"):
            load_image(corpus / name)


def test_huge_grey_levels_refused() -> None:
    with pytest.raises(InputError, match="grey levels"):
        dicblur.pattern_metrics(speckle() * 1e298, subset=21)


# ------------------------------------------------------------------ outputs
def test_output_rule(tmp_path: Path) -> None:
    (tmp_path / "d").mkdir()
    (tmp_path / "f.txt").write_text("x")
    assert check_output(tmp_path / "new.csv") == tmp_path / "new.csv"
    assert check_output(tmp_path / "newdir", folder=True) == tmp_path / "newdir"
    assert check_output(tmp_path / "d", folder=True) == tmp_path / "d"
    with pytest.raises(InputError, match="does not exist"):
        check_output(tmp_path / "missing" / "x.csv", "--csv")
    with pytest.raises(InputError, match="does not exist"):
        check_output(tmp_path / "missing" / "deeper", folder=True)
    with pytest.raises(InputError, match="is a directory"):
        check_output(tmp_path / "d")
    with pytest.raises(InputError, match="not a folder"):
        check_output(tmp_path / "f.txt", folder=True)
    with pytest.raises(InputError, match="not a folder"):
        check_output(tmp_path / "f.txt" / "x.csv")


def test_atomic_write_keeps_old_file_on_a_crash(tmp_path: Path) -> None:
    target = tmp_path / "table.csv"
    write_text(target, "old\n")
    with pytest.raises(RuntimeError), atomic_open(target) as fh:
        fh.write("half a ")
        raise RuntimeError("killed mid-write")
    assert target.read_text() == "old\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["table.csv"]
    with atomic_path(tmp_path / "fig.png") as tmp:
        assert tmp.parent == tmp_path and tmp.suffix == ".png"
        tmp.write_bytes(b"png")
    assert (tmp_path / "fig.png").read_bytes() == b"png"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fig.png", "table.csv"]


def test_save_image_is_atomic(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import tifffile

    out = tmp_path / "a.tif"
    dicblur.save_image(out, np.full((8, 8), 7.0))

    def crash(path: object, *a: object, **k: object) -> None:
        Path(str(path)).write_bytes(b"II*\0partial")
        raise OSError("disk full")

    monkeypatch.setattr(tifffile, "imwrite", crash)
    with pytest.raises(OSError, match="disk full"):
        dicblur.save_image(out, np.full((8, 8), 9.0))
    np.testing.assert_array_equal(load_image(out), 7.0)
    assert [p.name for p in tmp_path.iterdir()] == ["a.tif"]


@pytest.mark.parametrize(
    ("argv", "stage"),
    [
        (
            [
                "correlate",
                "{d}/good.tif",
                "{d}/good2.tif",
                "--subset",
                "21",
                "-o",
                "{o}/missing/f.nc",
            ],
            "dicblur.dic.Correlator",
        ),
        (
            ["pulse", "-o", "{o}/missing/deeper", "--trials", "10"],
            "dicblur.pulse.study.run_pulse_study",
        ),
        (["fit", "{d}/results.csv", "-o", "{o}/missing/m.json"], "dicblur.cli.models._read_table"),
        (
            ["pattern", "generate", "{o}/missing/x.tif", "--size", "64"],
            "dicblur.patterns.speckle_pattern",
        ),
        (
            ["campaign", "run", "{d}/spec.toml", "-o", "{o}/missing/r.zarr", "--serial", "-q"],
            "dicblur.campaign.load_spec",
        ),
    ],
)
def test_outputs_checked_before_the_work(
    argv: list[str],
    stage: str,
    corpus: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    def never(*a: object, **k: object) -> None:
        raise AssertionError("the computation started before the output was checked")

    # the CLI imports each stage inside its command: patch the stage where it is defined

    monkeypatch.setattr(stage, never)
    args = [a.format(d=corpus, o=tmp_path) for a in argv]
    assert main(args) == 2
    assert "does not exist" in capsys.readouterr().err


# ------------------------------------------------------------------ API refusals
def test_api_refusals() -> None:
    with pytest.raises(InputError, match="seed=-1"):
        dicblur.speckle_pattern(64, seed=-1)
    with pytest.raises(InputError, match="too small for any subset"):
        dicblur.pattern_metrics(speckle((3, 3)), subset=21)
    with pytest.raises(InputError, match="constant"):
        dicblur.pattern_metrics(np.full((64, 64), 3.0), subset=21)
    with pytest.raises(InputError):
        dicblur.blur_sensitivity(np.full((64, 64), 3.0), subset=21)
    with pytest.raises(InputError, match="constant"):
        dicblur.Correlator(np.full((64, 64), 3.0), subset=21)
    with pytest.raises(InputError, match="scheduler='notaurl'"):
        dicblur.run_campaign(parse_spec(_valid_spec()), "/tmp/x.zarr", scheduler="notaurl")


def test_spec_limits() -> None:
    d = _valid_spec()
    d["campaign"]["repetitions"] = 10**9
    with pytest.raises(ConfigError, match="tasks"):
        parse_spec(d)
    d = _valid_spec()
    d["blur"]["lengths"] = [0.0, 500.0]
    with pytest.raises(ConfigError, match="W = 500"):
        parse_spec(d)
    d["blur"]["lengths"] = [0.0, 40.0]
    d["blur"]["angles"] = [90.0]
    with pytest.raises(ConfigError, match="rows"):
        parse_spec(d)
    d["blur"]["lengths"] = [0.0, 36.0]
    d["blur"]["angles"] = [0.0]
    assert parse_spec(d).blur == (0.0, 36.0)  # 48 - 11 = 37 px of room


def test_messages_name_cli_options() -> None:
    args = ["blur", "in.tif", "out.tif", "--length", "2"]
    msg = cli_message("sigma=np.float64(-1.0): must be >= 0", args)
    assert msg == "--noise=-1.0: must be >= 0"
    msg = cli_message("bit_depth=12: must be 8 or 16", args)
    assert msg == "--bit-depth=12: must be 8 or 16"
    assert cli_message("blur.lengths=3: x", args) == "blur.lengths=3: x"  # a spec key stays
    pred = ["predict", "m.json", "--blur", "1"]
    assert cli_message("blur: negative blur length -1.0 px", pred).startswith("--blur:")
    msg = cli_message("subset=20: odd\n  please", ["correlate", "a", "b"])
    assert msg == "--subset=20: odd please"
    # a name the command does not have is left alone
    assert cli_message("sigma=1: x", ["campaign", "status", "r.zarr"]) == "sigma=1: x"


def test_metrics_never_print_nan(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import tifffile

    # negative grey levels (a float TIFF): the mean is < 0, contrasts are undefined
    tifffile.imwrite(tmp_path / "half.tif", speckle((64, 64)) - 300.0)
    assert (
        main(["pattern", "metrics", str(tmp_path / "half.tif"), "--subset", "11", "--noise", "2"])
        == 0
    )
    out = capsys.readouterr()
    values = [line.split("│")[2].strip() for line in out.out.splitlines() if line.count("│") >= 3]
    assert values and not [v for v in values if v.lower() in ("nan", "inf", "-inf")]
    assert "-" in values  # the undefined ones
    assert "undefined" in out.err


@pytest.mark.parametrize("value", [False, 3, "x", []])
def test_static_fit_that_is_not_a_table_is_a_damaged_file(corpus: Path, value: object) -> None:
    """Found by the model-loader fuzzer (CI): a model whose ``static`` fit is
    not a table raised TypeError in the schema check instead of naming the key."""
    d = json.loads((corpus / "model.json").read_text())
    assert "static" in d
    d["static"] = value
    with pytest.raises(InputError, match="static"):
        BlurUncertaintyModel.from_json(json.dumps(d))
