"""One version everywhere: the package, the CHANGELOG's latest release, the README and the
model files; model files of earlier versions still load."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

import dicblur
from dicblur._version import __version__
from dicblur.models import fit_blur_model, sssig_decay
from dicblur.models.model import BlurUncertaintyModel

ROOT = Path(__file__).resolve().parents[1]
RELEASE = re.compile(r"^## \[(\d+\.\d+\.\d+)\] - (\d{4}-\d\d-\d\d)$", re.MULTILINE)


def read(name: str) -> str:
    path = ROOT / name
    if not path.exists():
        pytest.skip(f"{name} absent: not a source checkout")
    return path.read_text()


def test_the_changelog_is_by_version_and_its_latest_release_is_the_package_version() -> None:
    text = read("CHANGELOG.md")
    headings = re.findall(r"^## .*$", text, re.MULTILINE)
    assert headings[0] == "## [Unreleased]"
    releases = RELEASE.findall(text)
    assert len(releases) == len(headings) - 1, "every other heading is '## [X.Y.Z] - date'"
    assert releases[0][0] == __version__
    dates = [d for _, d in releases]
    assert dates == sorted(dates, reverse=True)
    kinds = set(re.findall(r"^### (.*)$", text, re.MULTILINE))
    assert kinds <= {"Added", "Changed", "Deprecated", "Removed", "Fixed", "Security"}


def test_the_readme_names_the_version_and_stays_short() -> None:
    text = read("README.md")
    assert f"Version {__version__}" in text
    assert text.count("\n") <= 150
    quickstart = text.split("## Quickstart", 1)[1].split("\n## ", 1)[0]
    commands = [ln for ln in quickstart.splitlines() if ln.startswith("python3 -m venv")]
    assert commands == [
        "python3 -m venv .venv && . .venv/bin/activate && pip install . && "
        "dicblur reproduce --quick --out report",
        'python3 -m venv .venv && . .venv/bin/activate && pip install -e ".[test]" && '
        "python -m pytest",
    ]
    image = re.search(r"!\[[^\]]*\]\((docs/images/[^)]+\.png)\)", text)
    assert image is not None
    assert (ROOT / image.group(1)).stat().st_size < 200_000


def _model() -> BlurUncertaintyModel:
    w = np.arange(0.0, 8.01, 0.5)
    s = sssig_decay(w, 1.85e5, 0.022)
    u = 0.01 * s**-0.5 * np.exp(np.random.default_rng(3).normal(0, 0.01, w.size))
    return fit_blur_model(w, s, u, noise_sigma=2.0, default="power_law")


def test_a_new_model_records_this_version_and_an_earlier_ones_file_still_loads() -> None:
    model = _model()
    assert model.version == __version__ == dicblur.__version__
    old = json.loads(model.to_json())
    old["version"] = "0.1.0"
    loaded = BlurUncertaintyModel.from_json(json.dumps(old))
    assert loaded.version == "0.1.0"
    assert loaded.predict([2.0]).u_e == pytest.approx(model.predict([2.0]).u_e, rel=1e-12)
