"""The bad-input corpus (issue 15): every CLI command that takes a file or a value, fed
damaged files and hostile values, in-process (``main(argv)``, no subprocess).

Each case must end with exit code 2, exactly one line on stderr (``error: ...``), no
traceback, no numpy repr, and no file left in the output folder (not even a partial one).
Cases that name a CLI option check that the message uses the option as typed (``--noise``),
not the API parameter (``sigma=``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import pytest

from bad_inputs import build_corpus
from dicblur.cli import main
from helpers.cli import CAMERA_PLAN, TARGET_PLAN


@dataclass(frozen=True)
class Case:
    id: str
    argv: tuple[str, ...]
    must: tuple[str, ...] = ()  # substrings of the error line
    must_not: tuple[str, ...] = ()  # substrings it must not contain
    dirs: tuple[str, ...] = field(default=())  # folders to create in the output folder

    def args(self, corpus: Path, out: Path, store: Path) -> list[str]:
        return [a.format(d=corpus, o=out, s=store) for a in self.argv]


BAD_IMAGES = {
    "missing": ("{d}/no_such.tif", "no such file"),
    "directory": ("{d}/notastore.zarr", "directory"),
    "empty": ("{d}/empty.tif", "empty"),
    "text-tif": ("{d}/text.tif", ""),
    "text-png": ("{d}/text.png", ""),
    "truncated-tif": ("{d}/truncated.tif", ""),
    "truncated-png": ("{d}/truncated.png", ""),
    "bomb-png": ("{d}/bomb.png", "--max-pixels"),
    "bomb-tif": ("{d}/bomb.tif", "--max-pixels"),
    "random-tif": ("{d}/random.tif", ""),
    "random-png": ("{d}/random.png", ""),
    "five-channels": ("{d}/five_channels.tif", "channel"),
    "nan": ("{d}/nan.tif", "NaN"),
    "inf": ("{d}/inf.tif", "infinite"),
    "huge-values": ("{d}/huge.tif", "grey levels"),
    "constant": ("{d}/constant.tif", "constant"),
    "tiny-3x3": ("{d}/tiny.tif", ""),
    "one-row": ("{d}/row.tif", ""),
    "complex": ("{d}/complex.tif", ""),
}
# every bad image through `pattern metrics`; the decoding ones through the other readers
_DECODE = (
    "missing",
    "empty",
    "truncated-tif",
    "bomb-png",
    "bomb-tif",
    "five-channels",
    "nan",
    "huge-values",
)
_NO_GOOD = ("subset <= 1", "subset <= 0", "subset <= -")

CASES: list[Case] = []
for key, (path, text) in BAD_IMAGES.items():
    CASES.append(
        Case(
            f"metrics-{key}",
            ("pattern", "metrics", path, "--subset", "21"),
            must=(text,) if text else (),
            must_not=_NO_GOOD,
        )
    )
for key in _DECODE:
    path, text = BAD_IMAGES[key]
    must = (text,) if text else ()
    CASES += [
        Case(f"blur-{key}", ("blur", path, "{o}/out.tif", "--length", "2"), must=must),
        Case(
            f"predict-image-{key}",
            ("pattern", "predict", path, "--noise", "2", "--subset", "21", "-o", "{o}/m.json"),
            must=must,
        ),
    ]
for key in ("missing", "bomb-tif", "five-channels", "constant", "huge-values", "tiny-3x3"):
    path, text = BAD_IMAGES[key]
    CASES.append(
        Case(
            f"correlate-{key}",
            ("correlate", path, "{d}/good.tif", "--subset", "21", "-o", "{o}/f.nc"),
            must=(text,) if text else (),
            must_not=_NO_GOOD,
        )
    )
for key in ("bomb-png", "nan", "text-tif"):
    path, text = BAD_IMAGES[key]
    CASES.append(
        Case(f"noise-{key}", ("noise", "{d}/good.tif", path), must=(text,) if text else ())
    )
for key in ("constant", "bomb-tif"):
    path, text = BAD_IMAGES[key]
    CASES.append(
        Case(
            f"plan-reference-{key}",
            ("plan", "{d}/model.json", *CAMERA_PLAN, "--reference", path),
            must=(text,),
        )
    )
    CASES.append(
        Case(
            f"calibrate-{key}",
            ("calibrate", path, "-o", "{o}/cal", "--serial", "--quiet"),
            must=(text,),
        )
    )
CASES += [
    Case("noise-bit-depths", ("noise", "{d}/good.tif", "{d}/scene16.tif"), must=("bit",)),
    Case("noise-shapes", ("noise", "{d}/good.tif", "{d}/bigger.tif"), must=("shape",)),
]

BAD_MODELS = {
    "missing-file": "{d}/no_such_model.json",
    "directory": "{d}/notastore.zarr",
    "missing-key": "{d}/model_missing_key.json",
    "wrong-type": "{d}/model_wrong_type.json",
    "wrong-type2": "{d}/model_wrong_type2.json",
    "binary": "{d}/model_binary.json",
    "tiff": "{d}/model_tiff.json",
    "truncated": "{d}/model_truncated.json",
    "list": "{d}/model_list.json",
    "empty": "{d}/model_empty.json",
    "nan": "{d}/model_nan.json",
    "inf": "{d}/model_inf.json",
    "version": "{d}/model_version.json",
    "inconsistent": "{d}/model_inconsistent.json",
}
for key, path in BAD_MODELS.items():
    CASES += [
        Case(
            f"predict-model-{key}",
            ("predict", path, "--blur", "2", "--noise", "2"),
            must=("model",),
        ),
        Case(
            f"plan-model-{key}",
            ("plan", path, *TARGET_PLAN, "--plot", "{o}/plan.png"),
            must=("model",),
        ),
    ]

BAD_TABLES = {
    "negative-u_e": ("{d}/neg_ue.csv", "u_e"),
    "nan-u_e": ("{d}/nan_ue.csv", "u_e"),
    "inf-u_e": ("{d}/inf_ue.csv", "u_e"),
    "text-u_e": ("{d}/text_ue.csv", "u_e"),
    "zero-u_e": ("{d}/zero_ue.csv", "u_e"),
    "no-u_e": ("{d}/no_ue.csv", "u_e"),
    "binary": ("{d}/binary.csv", "RESULTS"),
    "header-only": ("{d}/header_only.csv", "RESULTS"),
    "empty": ("{d}/empty.csv", "RESULTS"),
    "missing": ("{d}/no_such.csv", "RESULTS"),
    "zarr-not-a-store": ("{d}/notastore.zarr", "RESULTS"),
    "zarr-a-file": ("{d}/file.zarr", "RESULTS"),
    "zarr-bad-metadata": ("{d}/badmeta.zarr", "RESULTS"),
}
for key, (path, text) in BAD_TABLES.items():
    CASES.append(Case(f"fit-{key}", ("fit", path, "-o", "{o}/model.json"), must=(text,)))

BAD_SPECS = {
    "repetitions-1e9": ("spec_reps.toml", "repetitions"),
    "repetitions-int": ("spec_reps_int.toml", "tasks"),
    "blur-wider-than-pattern": ("spec_wide_blur.toml", "blur"),
    "blur-wider-than-image": ("spec_wide_blur_image.toml", "blur"),
    "constant-image": ("spec_constant.toml", "constant"),
    "missing-image": ("spec_missing_image.toml", "no such file"),
    "bomb-image": ("spec_bomb.toml", "max-pixels"),
    "text-image": ("spec_text_image.toml", "image"),
    "huge-shape": ("spec_huge_shape.toml", "max-pixels"),
    "subset-too-big": ("spec_subset_too_big.toml", "subset"),
    "binary": ("spec_binary.toml", "TOML"),
    "invalid": ("spec_invalid.toml", "TOML"),
    "empty": ("spec_empty.toml", "seed"),
    "missing": ("no_such_spec.toml", "no such file"),
}
for key, (name, text) in BAD_SPECS.items():
    CASES.append(
        Case(
            f"campaign-run-{key}",
            ("campaign", "run", "{d}/" + name, "-o", "{o}/r.zarr", "--serial", "-q"),
            must=(text,),
        )
    )
CASES.append(
    Case(
        "campaign-run-scheduler",
        ("campaign", "run", "{d}/spec.toml", "-o", "{o}/r.zarr", "--scheduler", "notaurl", "-q"),
        must=("--scheduler",),
    )
)
for key, path in {
    "not-a-store": "{d}/notastore.zarr",
    "a-file": "{d}/file.zarr",
    "bad-metadata": "{d}/badmeta.zarr",
    "missing": "{d}/none.zarr",
}.items():
    CASES += [
        Case(f"status-{key}", ("campaign", "status", path)),
        Case(f"export-{key}", ("campaign", "export", path, "--csv", "{o}/x.csv")),
    ]


def _output_cases(
    name: str, argv: tuple[str, ...], missing: str, directory: str = ""
) -> list[Case]:
    """``argv`` (``{out}`` where the output goes) writing into a missing folder, and, when
    ``directory`` is given, onto a directory of that name: refused before any computation."""

    def fill(out: str) -> tuple[str, ...]:
        return tuple(out if a == "{out}" else a for a in argv)

    cases = [Case(f"out-{name}-missing-dir", fill(missing), must=("does not exist",))]
    if directory:
        cases.append(
            Case(
                f"out-{name}-directory",
                fill("{o}/" + directory),
                must=("directory",),
                dirs=(directory,),
            )
        )
    return cases


# outputs: a missing folder or a directory is refused before any computation
PREDICT_PATTERN = ("pattern", "predict", "{d}/good.tif", "--noise", "2", "--subset", "21")
GOOD_PAIR = ("{d}/good.tif", "{d}/good2.tif")
for name, argv, missing, directory in (
    ("generate", ("pattern", "generate", "{out}", "--size", "64"), "x.tif", "adir.tif"),
    ("blur", ("blur", "{d}/good.tif", "{out}", "--length", "2"), "x.tif", "adir.tif"),
    ("correlate", ("correlate", *GOOD_PAIR, "--subset", "21", "-o", "{out}"), "f.nc", "adir.csv"),
    ("fit", ("fit", "{d}/results.csv", "-o", "{out}"), "m.json", "adir.json"),
    ("pattern-predict", (*PREDICT_PATTERN, "-o", "{out}"), "m.json", ""),
    ("plan-plot", ("plan", "{d}/model.json", *TARGET_PLAN, "--plot", "{out}"), "p.png", "adir.png"),
    ("export", ("campaign", "export", "{s}", "--csv", "{out}"), "x.csv", "adir.csv"),
):
    CASES += _output_cases(name, argv, "{o}/missing/" + missing, directory)
CASES.append(
    Case(
        "out-generate-extension",
        ("pattern", "generate", "{o}/x.jpg", "--size", "64"),
        must=(".jpg",),
    )
)
RUN = ("campaign", "run", "{d}/spec.toml", "-o")
CASES += [
    Case(
        "out-campaign-run-missing-dir",
        (*RUN, "{o}/missing/r.zarr", "--serial", "-q"),
        must=("does not exist",),
    ),
    Case("out-campaign-run-a-file", (*RUN, "{d}/good.tif", "--serial", "-q"), must=("not a",)),
    Case(
        "out-pulse-missing-parent",
        ("pulse", "-o", "{o}/missing/deeper", "--trials", "10"),
        must=("does not exist",),
    ),
    Case(
        "out-pulse-a-file",
        ("pulse", "-o", "{d}/good.tif", "--trials", "10"),
        must=("not a folder",),
    ),
    Case(
        "out-calibrate-missing-parent",
        ("calibrate", "{d}/good.tif", "-o", "{o}/missing/deeper", "--serial", "-q"),
        must=("does not exist",),
    ),
    Case(
        "out-design-missing-parent",
        ("design", "--blur", "3", "-o", "{o}/missing/deeper"),
        must=("does not exist",),
    ),
    Case(
        "out-reproduce-missing-parent",
        ("reproduce", "--quick", "--out", "{o}/missing/deeper"),
        must=("does not exist",),
    ),
]

# option values: refused, and the message names the option as typed
BLUR = ("blur", "{d}/good.tif", "{o}/x.tif", "--length")
GENERATE = ("pattern", "generate", "{o}/x.tif", "--size")
METRICS = ("pattern", "metrics", "{d}/good.tif")
CORRELATE = ("correlate", *GOOD_PAIR)
TRACK = ("track", "{d}/good*.tif", "-o", "{o}/t", "--noise", "2")
SIGMA = "--max-predicted-sigma"
CASES += [
    Case("blur-negative-length", (*BLUR, "-1"), must=("--length",)),
    Case(
        "blur-start-speed",
        (*BLUR, "2", "--trajectory", "acceleration", "--start-speed", "-3"),
        must=("--start-speed", "0..2"),
    ),
    Case(
        "blur-substeps-0",
        (*BLUR, "2", "--substeps", "0"),
        must=("--substeps", "--continuous"),
        must_not=("None",),
    ),
    Case(
        "blur-negative-noise",
        (*BLUR, "2", "--noise", "-1"),
        must=("--noise",),
        must_not=("sigma=", "np.float64"),
    ),
    Case("blur-bit-depth", (*BLUR, "2", "--bit-depth", "12"), must=("--bit-depth",)),
    Case("generate-huge-size", (*GENERATE, "100000x100000"), must=("--max-pixels",)),
    Case("generate-negative-seed", (*GENERATE, "64", "--seed", "-1"), must=("--seed",)),
    Case(
        "generate-bit-depth",
        (*GENERATE, "64", "--bit-depth", "12"),
        must=("--bit-depth",),
        must_not=("bit_depth=",),
    ),
    Case(
        "generate-speckle-size",
        (*GENERATE, "64", "--speckle-size", "-2"),
        must=("--speckle-size",),
    ),
    Case(
        "generate-supersample",
        (*GENERATE, "4000", "--supersample", "8"),
        must=("--max-pixels",),
    ),
    Case(
        "metrics-negative-noise",
        (*METRICS, "--subset", "21", "--noise", "-2"),
        must=("--noise",),
        must_not=("noise_sigma=",),
    ),
    Case("metrics-even-subset", (*METRICS, "--subset", "20"), must=("--subset",)),
    Case(
        "predict-negative-blur",
        ("predict", "{d}/model.json", "--blur", "-1", "--noise", "2"),
        must=("--blur",),
        must_not=("np.float64",),
    ),
    Case(
        "predict-negative-noise",
        ("predict", "{d}/model.json", "--blur", "1", "--noise", "-1"),
        must=("--noise",),
        must_not=("sigma=",),
    ),
    Case(
        "plan-velocity-text",
        ("plan", "{d}/model.json", "--velocity", "fast", *TARGET_PLAN[2:]),  # not 120mm/s
        must=("--velocity",),
    ),
    Case("correlate-even-subset", (*CORRELATE, "--subset", "20"), must=("--subset",)),
    Case("correlate-step-0", (*CORRELATE, "--subset", "21", "--step", "0"), must=("--step",)),
    Case(
        "correlate-max-predicted-sigma-negative",
        (*CORRELATE, "--noise", "2", SIGMA, "-0.05px"),
        must=(SIGMA, "none"),
    ),
    Case(
        "correlate-max-predicted-sigma-unit",
        (*CORRELATE, "--noise", "2", SIGMA, "1ms"),
        must=(SIGMA, "px"),
    ),
    Case(
        "correlate-max-predicted-sigma-no-noise",
        (*CORRELATE, "--blur-compensation", "given", "--blur", "2", SIGMA, "0.05px"),
        must=(SIGMA, "--noise"),
    ),
    Case("track-max-predicted-sigma", (*TRACK, SIGMA, "0"), must=(SIGMA,)),
    Case("track-tolerance-zero", (*TRACK, "--tolerance", "0"), must=("--tolerance", "auto")),
    Case("track-tolerance-unit", (*TRACK, "--tolerance", "1ms"), must=("--tolerance", "px")),
    Case("pattern-predict-subpixel", (*PREDICT_PATTERN, "--subpixel", "7"), must=("--subpixel",)),
    Case("max-pixels-bad", ("--max-pixels", "0", *METRICS), must=("--max-pixels",)),
]

# found by a hunt over the commands (each failed before its fix)
CAL = ("calibrate", "{d}/good.tif", "-o", "{o}/cal", "--serial", "-q")
DESIGN = ("design", "-o", "{o}/d")
FIT = ("fit", "{d}/results.csv", "-o", "{o}/m.json")
CASES += [
    # click's usage errors: one line that names the option, the value and where the help is
    Case(
        "usage-not-an-integer",
        (*GENERATE, "64", "--seed", "1e3"),
        must=("--seed", "'1e3'", "--help"),
    ),
    Case("usage-unknown-option", (*BLUR, "2", "--foo", "3"), must=("--foo",)),
    Case("usage-missing-argument", ("blur", "--length", "2"), must=("image", "--help")),
    # numpy's "expected non-negative integer" traceback, exit 1
    Case(
        "pulse-negative-seed",
        ("pulse", "-o", "{o}/p", "--trials", "10", "--seed", "-1"),
        must=("--seed=-1",),
    ),
    Case("fit-negative-seed", (*FIT, "--ci", "bootstrap", "--seed", "-1"), must=("--seed=-1",)),
    Case("fit-even-subset", (*FIT, "--subset", "4"), must=("--subset=4",)),  # was recorded
    # blur: an unknown --noise-model and options of another trajectory were ignored
    Case("blur-noise-model-unknown", (*BLUR, "2", "--noise-model", "foo"), must=("--noise-model",)),
    Case(
        "blur-noise-model-without-noise",
        (*BLUR, "2", "--noise-model", "per-subframe"),
        must=("--noise-model", "--noise"),
    ),
    Case("blur-cycles-not-sine", (*BLUR, "2", "--cycles", "3"), must=("--cycles", "sine")),
    Case(
        "blur-start-speed-not-acceleration",
        (*BLUR, "2", "--start-speed", "1"),
        must=("--start-speed", "acceleration"),
    ),
    Case("blur-wider-than-image", (*BLUR, "1e9"), must=("--length", "64 px")),  # 0 exit before
    Case(
        "blur-sine-cycles-nan",
        (*BLUR, "2", "--trajectory", "sine", "--cycles", "nan"),
        must=("--cycles=nan",),
        must_not=("SineMotion",),
    ),
    # a 16-bit image blurred at the default 8 bits: every pixel 255, exit 0
    Case(
        "blur-16-bit-into-8",
        ("blur", "{d}/scene16.tif", "{o}/x.tif", "--length", "2", "--bit-depth", "8"),
        must=("--bit-depth=8", "saturate", "--bit-depth 16"),
    ),
    # a float image normalised to 0..1: quantised to 2 grey levels, exit 0
    Case(
        "blur-normalised-float",
        ("blur", "{d}/unit.tif", "{o}/x.tif", "--length", "2"),
        must=("normalised", "2 levels"),
    ),
    # "fewer than two subsets keep an intensity gradient (flat...)" for a textured image
    # where a single 55 px subset fits
    Case(
        "pattern-predict-one-subset",
        ("pattern", "predict", "{d}/good.tif", "--noise", "2", "--subset", "55"),
        must=("--subset=55", "1 subset"),
        must_not=("flat",),
    ),
    # reproduce wrote its patterns and a campaign store before the cluster refused these
    Case(
        "reproduce-workers-0",
        ("reproduce", "--quick", "--out", "{o}/rep", "--workers", "0"),
        must=("--workers=0",),
    ),
    Case(
        "reproduce-scheduler",
        ("reproduce", "--quick", "--out", "{o}/rep", "--scheduler", "foo"),
        must=("--scheduler='foo'",),
    ),
    # "model='foo'": the name of the MODEL file argument, not of --model
    Case(
        "predict-model-kind",
        ("predict", "{d}/model.json", "--blur", "2", "--noise", "2", "--model", "foo"),
        must=("--model='foo'",),
    ),
    # the table's noise column reported as "--noise: value 0.0 ...", an option not given
    Case(
        "fit-zero-noise-column",
        ("fit", "{d}/zero_noise.csv", "-o", "{o}/m.json"),
        must=("column noise", "line 2"),
    ),
    # a signed 16-bit image with negative levels: clipped to black, exit 0
    Case(
        "blur-negative-levels",
        ("blur", "{d}/signed.tif", "{o}/x.tif", "--length", "2"),
        must=("down to -", "clip"),
    ),
    # options that --preset paper4 does not use were ignored
    Case(
        "generate-preset-softness",
        (*GENERATE, "64", "--preset", "paper4", "--softness", "1"),
        must=("--softness", "--preset"),
    ),
    # --select of a numeric column with a unit: ValueError traceback, exit 1
    Case(
        "fit-select-not-a-number",
        (*FIT, "--select", "blur=2px"),
        must=("--select 'blur=2px'", "numbers"),
    ),
    # "--select ['--noise=3']": the user's own text rewritten into an option
    Case(
        "fit-select-no-match",
        ("fit", "{d}/noisy.csv", "-o", "{o}/m.json", "--select", "noise=3"),
        must=("'noise=3'",),
        must_not=("--noise",),
    ),
    # "smaller than the study crop ...; pass a larger image or a smaller --size": reproduce
    # has no --size, and the message did not say which of the two images
    Case(
        "reproduce-small-pattern",
        ("reproduce", "--quick", "--out", "{o}/rep", "--pattern2", "{d}/good.tif"),
        must=("--pattern2=", "512x512"),
        must_not=("--size",),
    ),
    # "motion=(nan, nan)" instead of the option
    Case("pattern-predict-angle-nan", (*PREDICT_PATTERN, "--angle", "nan"), must=("--angle",)),
    # "image=array(--shape=(64, 64), ...)": the option rewrite reached inside the repr
    Case(
        "correlate-nan-image",
        ("correlate", "{d}/nan.tif", "{d}/good.tif", "--subset", "21"),
        must=("NaN",),
        must_not=("--shape",),
    ),
    # an HTML page written under any name (.png, .json)
    Case(
        "plan-html-extension",
        ("plan", "{d}/model.json", *TARGET_PLAN, "--html", "{o}/p.png"),
        must=("--html", ".html"),
    ),
    # calibrate named the spec keys it builds (noise.levels=nan), not its options
    Case("calibrate-noise-nan", (*CAL, "--noise", "nan"), must=("--noise=nan",)),
    Case("calibrate-blur-inverted", (*CAL, "--blur", "5:1:1"), must=("--blur='5:1:1'",)),
    Case("calibrate-blur-too-long", (*CAL, "--blur", "0:100:50"), must=("--blur:",)),
    Case("calibrate-step-0", (*CAL, "--step", "0"), must=("--step=0",)),
    Case("calibrate-negative-seed", (*CAL, "--seed", "-1"), must=("--seed=-1",)),
    Case("calibrate-noise-model", (*CAL, "--noise-model", "foo"), must=("--noise-model",)),
    # design named the API's parameters (weights=, speckle_size=, confirm_realisations=)
    Case("design-blur-dist-negative", (*DESIGN, "--blur-dist", "1:-1"), must=("--blur-dist",)),
    Case(
        "design-speckle-range-inverted",
        (*DESIGN, "--blur", "3", "--speckle-range", "5..1"),
        must=("--speckle-range",),
    ),
    Case(
        "design-confirm-negative", (*DESIGN, "--blur", "3", "--confirm", "-1"), must=("--confirm",)
    ),
    Case("design-negative-seed", (*DESIGN, "--blur", "3", "--seed", "-1"), must=("--seed",)),
    # matplotlib's "Format 'txt' is not supported" traceback after the plan
    Case(
        "plan-plot-extension",
        ("plan", "{d}/model.json", *TARGET_PLAN, "--plot", "{o}/p.txt"),
        must=("--plot", ".png"),
    ),
    # the page's starting values were not read: a page that opens on an error, exit 0
    Case(
        "plan-html-bad-velocity",
        ("plan", "{d}/model.json", "--html", "{o}/p.html", "--velocity", "12GL"),
        must=("--velocity", "GL"),
    ),
    Case(
        "plan-html-bad-scale",
        ("plan", "{d}/model.json", "--html", "{o}/p.html", "--scale", "nan"),
        must=("--scale",),
    ),
    # "--noise=None: ...; give sigma (GL)": the API's name and a value nobody typed
    Case(
        "predict-several-noise-levels",
        ("predict", "{d}/model.json", "--blur", "2"),
        must=("--noise", "1.0, 2.0"),
        must_not=("None", "sigma"),
    ),
    # typer reads an empty path as ".": the study was written into the current folder
    Case("pulse-empty-out", ("pulse", "-o", "", "--trials", "10"), must=("-o=''", "empty")),
    Case("pulse-empty-out-equals", ("pulse", "--out=", "--trials", "10"), must=("--out=''",)),
    # a value pasted from a document: the typographic minus read as "not a number" only
    Case("usage-typographic-minus", (*GENERATE, "64", "--seed", "\u22121"), must=("ASCII '-'",)),
    # a predicted sigma of 0 px and the residual screen off, exit 0
    Case(
        "correlate-noise-zero",
        ("correlate", "{d}/good.tif", "{d}/good.tif", "--noise", "0"),
        must=("--noise=0", "estimate"),
    ),
    # --serial beside --workers / --scheduler: one of the two was ignored without a word
    Case(
        "reproduce-serial-workers",
        ("reproduce", "--quick", "--out", "{o}/rep", "--serial", "--workers", "2"),
        must=("--workers=2", "--serial"),
    ),
    Case("calibrate-serial-workers", (*CAL, "--workers", "2"), must=("--workers=2", "--serial")),
    Case(
        "campaign-serial-scheduler",
        (*RUN, "{o}/r.zarr", "--serial", "--scheduler", "tcp://127.0.0.1:8786", "-q"),
        must=("--scheduler=tcp://127.0.0.1:8786", "--serial"),
    ),
]


@pytest.fixture(scope="module")
def corpus(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_corpus(tmp_path_factory.mktemp("corpus"))


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small finished campaign store (cheap task function, serial)."""
    from dicblur.campaign import parse_spec, run_campaign
    from helpers.campaign import shift_task, small_spec_dict

    d = small_spec_dict(blur__lengths=[0.0, 1.0], campaign__repetitions=1)
    d["pattern"] = d["pattern"][:1]
    path = tmp_path_factory.mktemp("store") / "r.zarr"
    run_campaign(parse_spec(d), path, serial=True, task=shift_task)
    return path


def _files(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file())


def test_corpus_is_large_enough() -> None:
    assert len(CASES) >= 60
    assert len({c.id for c in CASES}) == len(CASES)


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_input(
    case: Case, corpus: Path, store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    out.mkdir()
    for d in case.dirs:
        (out / d).mkdir()
    capsys.readouterr()
    rc = main(case.args(corpus, out, store))
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert rc == 2, f"exit {rc}, stderr: {err!r}"
    assert len(lines) == 1, f"expected one line on stderr, got {err!r}"
    line = lines[0]
    assert line.startswith("error: "), line
    assert "Traceback" not in err
    assert "np.float64(" not in line and "np.int64(" not in line, line
    for text in case.must:
        assert text in line, f"{text!r} not in {line!r}"
    for text in case.must_not:
        assert text not in line, f"{text!r} in {line!r}"
    assert _files(out) == [], f"output left behind: {_files(out)}"


# outputs equal to an input: refused before any work, the input left intact
SAME = {
    "blur": ("blur", "{i}", "{i}", "--length", "2"),
    "pattern-predict": ("pattern", "predict", "{i}", "--noise", "2", "--subset", "21", "-o", "{i}"),
    "fit": ("fit", "{r}", "-o", "{r}"),
    "plan-plot-link": ("plan", "{m}", *TARGET_PLAN, "--plot", "{p}"),
    "plan-html-link": ("plan", "{m}", *TARGET_PLAN, "--html", "{h}"),
}


@pytest.mark.parametrize("key", sorted(SAME))
def test_output_that_is_an_input_is_refused(
    key: str, corpus: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import shutil

    files = {"i": "good.tif", "r": "results.csv", "m": "model.json"}
    paths = {k: tmp_path / name for k, name in files.items()}
    for k, name in files.items():
        shutil.copy(corpus / name, paths[k])
    for name in ("page.html", "plot.png"):  # other names of the model file
        (tmp_path / name).symlink_to(paths["m"])
    before = {k: p.read_bytes() for k, p in paths.items()}
    fill = {k: str(p) for k, p in paths.items()}
    fill.update(h=str(tmp_path / "page.html"), p=str(tmp_path / "plot.png"))
    capsys.readouterr()
    rc = main([a.format(**fill) for a in SAME[key]])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert "is also an input" in err and len(err.strip().splitlines()) == 1, err
    assert {k: p.read_bytes() for k, p in paths.items()} == before


def test_outputs_get_the_mode_of_a_new_file(tmp_path: Path) -> None:
    """Atomic writes went through mkstemp, which makes 0600 files: a figure or model
    written for colleagues was unreadable to them. Now: 0666 less the umask, or the mode
    of the file replaced."""
    import os
    import stat

    from dicblur.io import write_text

    old = os.umask(0o022)
    try:
        new = write_text(tmp_path / "a.json", "{}")
        assert stat.S_IMODE(new.stat().st_mode) == 0o644
        kept = tmp_path / "b.json"
        kept.write_text("old")
        kept.chmod(0o640)
        write_text(kept, "{}")
        assert stat.S_IMODE(kept.stat().st_mode) == 0o640
    finally:
        os.umask(old)


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs Linux /proc")
def test_unwritable_folder_is_refused_before_work(capsys: pytest.CaptureFixture[str]) -> None:
    """``os.access`` says yes to root on any folder; the check now creates a probe file.
    Before: the error came from the writer, naming its temporary file ('/proc/.x.tif.k0b3')."""
    rc = main(["pattern", "generate", "/proc/x.tif", "--size", "64"])
    err = capsys.readouterr().err
    assert rc == 2
    assert "'/proc/x.tif'" in err and "not writable" in err and ".tmp" not in err, err


def test_campaign_pattern_without_seed_is_reproducible() -> None:
    """A generated pattern without a seed of its own was drawn afresh on every run, so
    rerunning (resuming) the same spec was refused: 'the input image changed'."""
    import numpy as np

    from dicblur.campaign import parse_spec
    from dicblur.campaign.tasks import make_pattern
    from helpers.campaign import small_spec_dict

    d = small_spec_dict()
    del d["pattern"][0]["seed"]
    d["pattern"][1] = dict(d["pattern"][0], name="b")  # the same settings, another name
    spec = parse_spec(d)
    a, b = (make_pattern(spec, spec.patterns[0]) for _ in range(2))
    np.testing.assert_array_equal(a, b)
    other = make_pattern(spec, spec.patterns[1])  # another name: another draw
    assert other.shape == a.shape and not np.array_equal(a, other)


def test_correlate_says_when_no_point_converged(
    corpus: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Two unrelated images: every point fails. The table showed n_converged 0 among 25
    rows of dashes, exit 0, and nothing else; now a warning line says so and why."""
    import numpy as np
    import tifffile

    noise = np.random.default_rng(3).integers(0, 256, (64, 64)).astype(np.uint8)
    tifffile.imwrite(tmp_path / "other.tif", noise, photometric="minisblack")
    rc = main(
        ["correlate", str(corpus / "good.tif"), str(tmp_path / "other.tif"), "--subset", "21"]
    )
    err = capsys.readouterr().err
    assert rc == 0
    assert "warning: no point converged" in err and "failed" in err, err
    rc = main(["correlate", str(corpus / "good.tif"), str(corpus / "good2.tif"), "--subset", "21"])
    assert rc == 0 and "warning" not in capsys.readouterr().err  # a good pair: no warning


def test_blur_keeps_a_16_bit_image_16_bit(corpus: Path, tmp_path: Path) -> None:
    """The default --bit-depth was 8 whatever the input: a 16-bit image came out all 255."""
    import numpy as np
    import tifffile

    assert (
        main(["blur", str(corpus / "scene16.tif"), str(tmp_path / "b.tif"), "--length", "2"]) == 0
    )
    out = tifffile.imread(tmp_path / "b.tif")
    src = tifffile.imread(corpus / "scene16.tif").astype(float)
    assert out.dtype == np.uint16
    assert abs(out.mean() - src.mean()) < 0.01 * src.mean()  # the same grey levels, blurred


def test_spreadsheet_and_editor_files_are_read(corpus: Path, tmp_path: Path) -> None:
    """A byte-order mark (spreadsheets' "CSV UTF-8", some editors) made fit report the
    column blur missing, and a model or spec "invalid"; a ';'-separated CSV (comma-decimal
    locales) had no column at all. All are read now."""
    from dicblur.campaign import load_spec

    bom = b"\xef\xbb\xbf"
    csv_text = (corpus / "results.csv").read_bytes()
    (tmp_path / "bom.csv").write_bytes(bom + csv_text)
    (tmp_path / "semi.csv").write_bytes(csv_text.replace(b",", b";"))
    (tmp_path / "bom.json").write_bytes(bom + (corpus / "model.json").read_bytes())
    spec = (corpus / "spec.toml").read_bytes()
    (tmp_path / "bom.toml").write_bytes(bom + spec)
    for name in ("bom.csv", "semi.csv"):
        assert main(["fit", str(tmp_path / name), "-o", str(tmp_path / f"{name}.json")]) == 0
    assert main(["predict", str(tmp_path / "bom.json"), "--blur", "2", "--noise", "2"]) == 0
    assert load_spec(tmp_path / "bom.toml").seed == load_spec(corpus / "spec.toml").seed


def test_noise_of_the_same_file_twice_is_refused(
    corpus: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The same file given twice printed 'noise sigma = 0.0000 grey levels', exit 0."""
    rc = main(["noise", str(corpus / "good.tif"), str(corpus / "good.tif")])
    err = capsys.readouterr().err
    assert rc == 2 and "same file" in err and len(err.strip().splitlines()) == 1, err


def test_noise_warns_of_identical_and_clipped_pairs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Identical copies (sigma 0) and an over-exposed pair (the clipped pixels hide their
    noise: the estimate is low) printed a plain number."""
    import numpy as np
    import tifffile

    from bad_inputs import speckle

    rng = np.random.default_rng(0)
    base = speckle()
    a, b = (np.clip(np.rint(base + 60 + rng.normal(0, 3, base.shape)), 0, 255) for _ in "ab")
    for name, img in (("a", a), ("b", b), ("c", a)):
        tifffile.imwrite(tmp_path / f"{name}.tif", img.astype(np.uint8), photometric="minisblack")
    assert main(["noise", str(tmp_path / "a.tif"), str(tmp_path / "b.tif")]) == 0
    err = capsys.readouterr().err
    assert "clipped" in err and "low" in err, err
    assert main(["noise", str(tmp_path / "a.tif"), str(tmp_path / "c.tif")]) == 0
    assert "identical" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("damage", "must", "must_not"),
    [
        # a rig from a newer dicblur was read as if it were version 1
        ({"version": 99}, "version 99", "expected keys"),
        # the file named twice and a wrong hint: the keys are all there, fx is bad
        ({"left": {"fx": float("nan")}}, "fx=nan", "expected keys"),
    ],
)
def test_damaged_rig_file(
    damage: dict,
    must: str,
    must_not: str,
    corpus: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    import json

    from dicblur.stereo import CameraModel, save_rig
    from dicblur.stereo.synthetic import symmetric_rig

    cam = CameraModel(2000.0, 2000.0, 127.5, 127.5, image_shape=(256, 256))
    save_rig(symmetric_rig(stereo_angle=30.0, distance=400.0, camera=cam), tmp_path / "rig.json")
    d = json.loads((tmp_path / "rig.json").read_text())
    for key, value in damage.items():
        d[key] = {**d[key], **value} if isinstance(value, dict) else value
    (tmp_path / "rig.json").write_text(json.dumps(d))
    argv = ["stereo", "plan", str(corpus / "model.json"), "--rig", str(tmp_path / "rig.json")]
    rc = main([*argv, "--velocity", "0,0,100mm/s", "--target", "0.01mm", "--noise", "2"])
    err = capsys.readouterr().err
    assert rc == 2 and len(err.strip().splitlines()) == 1, err
    assert must in err and must_not not in err and err.count("rig.json") == 1, err


def test_fit_summary_prints_no_none(
    corpus: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A table without a subset column printed 'subset None px'."""
    assert main(["fit", str(corpus / "results.csv"), "-o", str(tmp_path / "m.json")]) == 0
    out = capsys.readouterr().out
    assert "subset unknown" in out and "None" not in out, out


def test_metrics_of_one_subset_print_no_spread(
    corpus: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A step larger than the image leaves one subset: its SSSIG std read 0 (GL/px)^2."""
    import json

    argv = ["pattern", "metrics", str(corpus / "good.tif"), "--subset", "21", "--json"]
    assert main([*argv, "--step", "1000"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["n_subsets"] == 1
    assert data["sssig_x_std"] is None and data["sssig_y_std"] is None


@pytest.mark.parametrize(
    "argv",
    [
        ("calibrate", "{d}/good.tif", "-o", "{o}", "--serial", "-q", "--subset", "10001"),
        ("design", "-o", "{o}", "--blur", "3", "--confirm", "-1"),
    ],
    ids=["calibrate", "design"],
)
def test_refused_run_leaves_no_empty_output_folder(
    argv: tuple[str, ...], corpus: Path, tmp_path: Path
) -> None:
    """These created their output folder before a bad value was refused, and left it."""
    out = tmp_path / "out"
    assert main([a.format(d=corpus, o=out) for a in argv]) == 2
    assert not out.exists()
    out.mkdir()  # a folder the user made is kept, even empty
    assert main([a.format(d=corpus, o=out) for a in argv]) == 2
    assert out.is_dir()


def test_store_without_finished_tasks(
    store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """export wrote a header-only CSV, 'wrote x.csv (0 rows)', exit 0; fit printed
    xarray's six-line warning about consolidated metadata before its error."""
    from dicblur.campaign import parse_spec, run_campaign
    from helpers.campaign import small_spec_dict

    def interrupted(*args: object, **kwargs: object) -> None:
        raise KeyboardInterrupt

    d = small_spec_dict(blur__lengths=[0.0, 1.0], campaign__repetitions=1)
    d["pattern"] = d["pattern"][:1]
    empty = tmp_path / "r.zarr"
    run_campaign(parse_spec(d), empty, serial=True, task=interrupted)
    capsys.readouterr()
    assert main(["campaign", "export", str(empty), "--csv", str(tmp_path / "x.csv")]) == 2
    err = capsys.readouterr().err
    assert "no finished task" in err and not (tmp_path / "x.csv").exists(), err
    assert main(["fit", str(empty), "-o", str(tmp_path / "m.json")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "consolidat" not in err, err
    assert main(["fit", str(store), "-o", str(tmp_path / "m.json")]) in (0, 2)
    assert "consolidat" not in capsys.readouterr().err  # a finished store: no warning either


def test_numeric_options_take_their_unit(corpus: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """'--noise 2GL', '--blur 2px' were usage errors although the CLI writes quantities
    with their unit (120mm/s, 0.05mm/px, 2GL); a number in its option's unit is read, a
    wrong unit is still refused."""
    base = ["predict", str(corpus / "model.json")]
    assert main([*base, "--blur", "2", "--noise", "2"]) == 0
    plain = capsys.readouterr().out
    assert main([*base, "--blur", "2px", "--noise=2GL"]) == 0
    assert capsys.readouterr().out == plain
    assert main([*base, "--blur", "2px", "--noise", "2px"]) == 2
    err = capsys.readouterr().err
    assert "--noise" in err and "'2px'" in err and len(err.strip().splitlines()) == 1, err


@pytest.mark.parametrize("command", ["generate", "blur"])
def test_settings_json_makes_the_same_image_again(
    command: str, corpus: Path, tmp_path: Path
) -> None:
    """Without --seed the sidecar said "seed": null: the image could not be made again.
    The seed drawn is now recorded, and rerunning with it gives the same bytes."""
    import json

    first, again = tmp_path / "a.tif", tmp_path / "b.tif"
    if command == "generate":
        argv = ["pattern", "generate", "{out}", "--size", "32"]
    else:
        argv = ["blur", str(corpus / "good.tif"), "{out}", "--length", "2", "--noise", "2"]
    assert main([a.replace("{out}", str(first)) for a in argv]) == 0
    side = json.loads((tmp_path / "a.tif.json").read_text())
    seed = (side["generator"] if command == "generate" else side)["seed"]
    assert isinstance(seed, int)
    assert main([*(a.replace("{out}", str(again)) for a in argv), "--seed", str(seed)]) == 0
    assert first.read_bytes() == again.read_bytes()


def test_fit_prints_no_inf_for_an_unconstrained_parameter(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A parameter the data do not constrain printed its interval as '[-inf, inf]'."""
    import re

    rows = ["blur,sssig,u_e,noise"]
    for noise, scale in ((2, 1.0), (4, 2.0)):
        for w, s, u in ((0, 1e5, 0.01), (1, 9e4, 0.012), (2, 8e4, 0.015), (3, 7e4, 0.02)):
            rows.append(f"{w},{s},{u * scale},{noise}")
    (tmp_path / "r.csv").write_text("\n".join(rows) + "\n")
    assert main(["fit", str(tmp_path / "r.csv"), "-o", str(tmp_path / "m.json")]) == 0
    out = capsys.readouterr().out
    assert "unidentified" in out and not re.search(r"(?<![\w/])-?inf\b", out), out
