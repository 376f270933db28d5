import base64

import numpy as np
import pytest

from dicblur.report import HtmlReport, check_in_browser, find_browser


def _report(tmp_path, broken=False):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rep = HtmlReport("Test report", tmp_path)
    rep.section("Numbers")
    rep.paragraph("Some **bold** and `code` <escaped>.")
    rep.table(
        [{"name": "eta", "value": 0.0123, "verdict": "agrees"}],
        left=["name", "verdict"],
        classes={"verdict": {"agrees": "agrees"}},
    )
    fig, ax = plt.subplots()
    ax.plot(np.arange(5), np.arange(5) ** 2)
    rep.figure(fig, "fig_test", "A parabola")
    if broken:
        rep._parts.append('<img alt="broken" src="data:image/png;base64,AAAA">')
    return rep.write()


def test_html_is_self_contained(tmp_path):
    path = _report(tmp_path)
    text = path.read_text()
    assert "data:image/png;base64," in text
    assert "&lt;escaped&gt;" in text and "<strong>bold</strong>" in text
    assert (tmp_path / "figures" / "fig_test.png").exists()
    assert (tmp_path / "figures" / "fig_test.svg").exists()
    # The embedded PNG is the file written next to it.
    b64 = text.split("data:image/png;base64,")[1].split('"')[0]
    assert base64.b64decode(b64) == (tmp_path / "figures" / "fig_test.png").read_bytes()


@pytest.mark.skipif(find_browser() is None, reason="no Chromium on PATH (.ci/run installs it)")
def test_browser_sees_images_and_detects_broken_ones(tmp_path):
    good = check_in_browser(_report(tmp_path / "good"), screenshot=tmp_path / "shot.png")
    assert good.images_ok and good.image_count == 1
    assert (tmp_path / "shot.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    bad = check_in_browser(_report(tmp_path / "bad", broken=True))
    assert not bad.images_ok and bad.image_count == 2
