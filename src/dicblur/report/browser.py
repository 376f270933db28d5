"""Open a report in headless Chromium: check that every image decodes, take a screenshot."""

from __future__ import annotations

import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

from ..errors import DicblurError

__all__ = ["BrowserCheck", "check_in_browser", "evaluate_in_browser", "find_browser"]

_CANDIDATES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
# Flags for a closed network and a root user: no sandbox, no background connections.
_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--hide-scrollbars",
)


@dataclass(frozen=True)
class BrowserCheck:
    """Outcome of opening a report in a headless browser.

    Attributes
    ----------
    images_ok : bool
        Every ``<img>`` completed with a non-zero natural width.
    image_count : int
        Number of images the page holds.
    screenshot : pathlib.Path or None
        PNG screenshot, when requested.
    browser : str
        Browser executable used.
    """

    images_ok: bool
    image_count: int
    screenshot: Path | None
    browser: str


def find_browser() -> str | None:
    """Path of a Chromium-family browser on PATH, or None."""
    for name in _CANDIDATES:
        path = shutil.which(name)
        if path:
            return path
    return None


def _run(cmd: list[str], timeout: float) -> subprocess.CompletedProcess[str]:
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, check=False)


def check_in_browser(
    html_path: str | Path,
    *,
    screenshot: str | Path | None = None,
    window: tuple[int, int] = (1280, 2400),
    timeout: float = 120.0,
) -> BrowserCheck:
    """Open ``html_path`` in headless Chromium and read back the page's image check.

    The page must carry the script of :class:`dicblur.report.HtmlReport`, which sets
    ``data-images-ok`` on ``<body>`` after load.

    Raises
    ------
    DicblurError
        If no browser is found or it fails to render the page.
    """
    browser = find_browser()
    if browser is None:
        raise DicblurError(
            "no Chromium-family browser found on PATH; install Debian's 'chromium' package"
        )
    page = Path(html_path).resolve()
    url = page.as_uri()
    with tempfile.TemporaryDirectory(prefix="dicblur-chromium-") as profile:
        base = [browser, *_FLAGS, f"--user-data-dir={profile}", "--virtual-time-budget=10000"]
        dom = _run([*base, "--dump-dom", url], timeout)
        if dom.returncode != 0 or "<body" not in dom.stdout:
            raise DicblurError(
                f"browser failed to render {page} (exit {dom.returncode}): {dom.stderr[-400:]}"
            )
        m_ok = re.search(r'data-images-ok="(true|false)"', dom.stdout)
        m_n = re.search(r'data-images-count="(\d+)"', dom.stdout)
        shot: Path | None = None
        if screenshot is not None:
            shot = Path(screenshot).resolve()
            res = _run(
                [*base, f"--window-size={window[0]},{window[1]}", f"--screenshot={shot}", url],
                timeout,
            )
            if res.returncode != 0 or not shot.exists():
                raise DicblurError(f"browser failed to take a screenshot: {res.stderr[-400:]}")
    return BrowserCheck(
        images_ok=bool(m_ok and m_ok.group(1) == "true"),
        image_count=int(m_n.group(1)) if m_n else 0,
        screenshot=shot,
        browser=browser,
    )


def evaluate_in_browser(html_text: str, script: str, *, timeout: float = 120.0) -> str:
    """Load ``html_text`` in headless Chromium with ``script`` appended, and return the
    text the script writes into ``<pre id="dicblur-result">`` (created by the caller's
    script). Used to run a page's own functions on test inputs.

    Raises
    ------
    DicblurError
        If no browser is found, it fails, or the script wrote no result.
    """
    browser = find_browser()
    if browser is None:
        raise DicblurError(
            "no Chromium-family browser found on PATH; install Debian's 'chromium' package"
        )
    page = html_text.replace("</body>", f"<script>{script}</script></body>")
    with tempfile.TemporaryDirectory(prefix="dicblur-chromium-") as profile:
        path = Path(profile) / "page.html"
        path.write_text(page, encoding="utf-8")
        base = [browser, *_FLAGS, f"--user-data-dir={profile}/u", "--virtual-time-budget=20000"]
        dom = _run([*base, "--dump-dom", path.as_uri()], timeout)
    m = re.search(r'<pre id="dicblur-result">(.*?)</pre>', dom.stdout, re.S)
    if dom.returncode != 0 or m is None:
        raise DicblurError(
            f"browser produced no result (exit {dom.returncode}): {dom.stderr[-400:]}"
        )
    import html as _html

    return _html.unescape(m.group(1))
