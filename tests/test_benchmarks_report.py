"""BENCHMARKS.md is generated from benchmarks/results/*.json and cannot drift from them."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "benchmarks" / "report.py"

pytestmark = pytest.mark.skipif(
    not SCRIPT.exists() or not (ROOT / "BENCHMARKS.md").exists(),
    reason="benchmarks/report.py or BENCHMARKS.md absent (not a source checkout)",
)


@pytest.fixture(scope="module")
def report():
    spec = importlib.util.spec_from_file_location("benchmarks_report", SCRIPT)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_committed_benchmarks_md_is_the_generators_output(report) -> None:
    text = report.render()
    assert (ROOT / "BENCHMARKS.md").read_text() == text, (
        "BENCHMARKS.md is stale: run `python -m benchmarks.report`"
    )
    assert text.count("\n") <= report.MAX_LINES


def test_every_known_renderer_reads_its_file(report) -> None:
    # render() falls back to the generic table when a renderer fails; here none may fail.
    for stem, renderer in report.RENDERERS.items():
        path = report.RESULTS / f"{stem}.json"
        if path.exists():
            lines = renderer(json.loads(path.read_text()))
            assert any(line.startswith("| ") for line in lines), stem


def test_an_unknown_result_file_appears_with_its_provenance(report, tmp_path: Path) -> None:
    doc = {
        "cases": [{"case": "a", "poi_per_s": 1234.5, "ratio": 2.0}, {"case": "b", "ratio": 1.5}],
        "provenance": {
            "commit": "abcdef0123456789",
            "date_utc": "2027-01-02T03:04:05Z",
            "machine": {"processor": "x86_64", "cpus": 4},
            "load_start": [1.0, 1.0, 1.0],
            "load_end": [2.0, 2.0, 2.0],
            "argv": ["benchmarks/bench_new.py", "--quick"],
        },
    }
    (tmp_path / "zz_new.json").write_text(json.dumps(doc))
    (tmp_path / "strain_x.json").write_text(json.dumps({"results": {"one": {"err": 0.5}}}))
    text = report.render(tmp_path)
    assert "## Other results\n### zz_new" in text
    assert "`python benchmarks/bench_new.py --quick` · commit abcdef0 · 2027-01-02" in text
    assert "4 cores, load 1.0 -> 2.0" in text
    assert "| case | poi_per_s | ratio |" in text and "| b | - | 1.5 |" in text
    assert "## Strain\n### strain_x" in text and "| one | 0.5 |" in text
