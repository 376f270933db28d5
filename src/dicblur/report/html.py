"""A small builder of self-contained HTML reports.

Every figure is embedded as a base64 PNG (the page opens from disk without a server) and
also written next to the page as PNG and SVG. Tables are plain HTML. The page carries a
tiny script that marks ``<body data-images-ok="true|false">`` once every image has
decoded, which :func:`dicblur.report.check_in_browser` reads back from a headless browser.
"""

from __future__ import annotations

import base64
import html
import io
import math
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from ..io import atomic_open, atomic_path, write_text

__all__ = ["HtmlReport", "fig_to_files", "markdown_to_html"]

_CSS = """
body{font-family:-apple-system,Segoe UI,Helvetica,Arial,sans-serif;max-width:1100px;
margin:2em auto;padding:0 1em;color:#1d2329;line-height:1.45}
h1{border-bottom:2px solid #2a6f97;padding-bottom:.3em}h2{color:#2a6f97;margin-top:2em}
table{border-collapse:collapse;margin:1em 0;font-size:.92em}
th,td{border:1px solid #c9d3dc;padding:.3em .6em;text-align:right}
th{background:#eef3f7}td.l,th.l{text-align:left}
figure{margin:1.5em 0;text-align:center}figure img{max-width:100%;height:auto}
figcaption{font-size:.9em;color:#44515c;margin-top:.4em}
.agrees{color:#1a7f37;font-weight:600}.partly{color:#7d6608;font-weight:600}
.differs{color:#b35900;font-weight:600}.inconclusive{color:#5a6470;font-weight:600}
.note{background:#f6f8fa;border-left:4px solid #2a6f97;padding:.6em 1em}
nav ul{columns:2}code,pre{background:#f6f8fa;padding:.1em .3em}
pre{padding:.8em;overflow-x:auto}
"""

_SCRIPT = """
<script>
window.addEventListener('load', function () {
  var imgs = Array.prototype.slice.call(document.images);
  var ok = imgs.every(function (im) { return im.complete && im.naturalWidth > 0; });
  document.body.setAttribute('data-images-ok', ok ? 'true' : 'false');
  document.body.setAttribute('data-images-count', String(imgs.length));
});
</script>
"""


def _inline(text: str) -> str:
    body = html.escape(text)
    body = re.sub(r"\*\*(.+?)\*\*", r"<strong>\1</strong>", body)
    body = re.sub(r"(?<![\w*])\*(?!\s)(.+?)(?<!\s)\*(?![\w*])", r"<em>\1</em>", body)
    return re.sub(r"`(.+?)`", r"<code>\1</code>", body)


def markdown_to_html(text: str, *, heading_offset: int = 0) -> str:
    """Render the small Markdown subset of dicblur's generated texts as HTML.

    Blocks: ``#``..``######`` headings, ``- `` bullet lists, ``|``-delimited tables (the
    second row a ``|---|`` separator), blank-line separated paragraphs, ``---`` rules.
    Inline: ``**bold**``, ``*italic*``, ```code```. Everything else is escaped text.
    """
    out: list[str] = []
    para: list[str] = []
    items: list[str] = []
    rows: list[list[str]] = []

    def flush() -> None:
        if para:
            out.append("<p>" + _inline(" ".join(para)) + "</p>")
            para.clear()
        if items:
            out.append("<ul>" + "".join(f"<li>{_inline(i)}</li>" for i in items) + "</ul>")
            items.clear()
        if rows:
            head, body = rows[0], rows[1:]
            cells = "".join(f"<th>{_inline(c)}</th>" for c in head)
            trs = "".join(
                "<tr>" + "".join(f"<td>{_inline(c)}</td>" for c in r) + "</tr>" for r in body
            )
            out.append(f"<table><tr>{cells}</tr>{trs}</table>")
            rows.clear()

    for raw in text.splitlines():
        line = raw.rstrip()
        m = re.match(r"^(#{1,6})\s+(.*)$", line)
        if m:
            flush()
            level = min(len(m.group(1)) + heading_offset + 1, 6)
            out.append(f"<h{level}>{_inline(m.group(2))}</h{level}>")
        elif line.startswith("|"):
            if para or items:
                flush()
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            if not all(re.fullmatch(r":?-{3,}:?", c) for c in cells):
                rows.append(cells)
        elif re.match(r"^\s*[-*]\s+", line) and not re.fullmatch(r"-{3,}", line.strip()):
            if para or rows:
                flush()
            items.append(re.sub(r"^\s*[-*]\s+", "", line))
        elif re.fullmatch(r"-{3,}", line.strip()):
            flush()
            out.append("<hr>")
        elif not line.strip():
            flush()
        elif items and raw.startswith(("  ", "\t")):
            items[-1] += " " + line.strip()
        else:
            if rows or items:
                flush()
            para.append(line.strip())
    flush()
    return "".join(out)


def _slug(text: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-") or "section"


def fig_to_files(fig: Any, folder: Path, name: str, *, dpi: int = 110) -> bytes:
    """Save a matplotlib figure as ``folder/name.png`` and ``.svg``; return the PNG bytes."""
    folder.mkdir(parents=True, exist_ok=True)
    buf = io.BytesIO()
    # Figures are laid out by their builders (tight_layout); bbox_inches="tight" would
    # redo the text layout on every save, the slowest part of writing a report.
    fig.savefig(buf, format="png", dpi=dpi)
    png = buf.getvalue()
    with atomic_open(folder / f"{name}.png", "wb") as fh:
        fh.write(png)
    with atomic_path(folder / f"{name}.svg") as tmp:
        fig.savefig(tmp, format="svg")
    return png


def _cell(value: Any, digits: int) -> str:
    if isinstance(value, float):
        if math.isnan(value):
            return "–"
        if value != 0 and (abs(value) >= 1e5 or abs(value) < 10 ** (-digits)):
            return f"{value:.{digits}g}"
        return f"{value:.{digits}g}" if abs(value) < 1 else f"{value:.{digits + 1}g}"
    return html.escape(str(value))


@dataclass
class HtmlReport:
    """Accumulates sections, text, tables and figures, then writes one HTML file.

    Parameters
    ----------
    title : str
        Page title.
    folder : pathlib.Path
        Output folder; figures are written to ``folder / "figures"``.
    """

    title: str
    folder: Path
    _parts: list[str] = field(default_factory=list)
    _toc: list[tuple[str, str]] = field(default_factory=list)
    figures: list[str] = field(default_factory=list)

    def section(self, heading: str) -> None:
        """Start a new section (``<h2>``, listed in the table of contents)."""
        anchor = _slug(heading)
        self._toc.append((anchor, heading))
        self._parts.append(f'<h2 id="{anchor}">{html.escape(heading)}</h2>')

    def paragraph(self, text: str, *, css_class: str | None = None) -> None:
        """Add a paragraph of plain text (escaped); ``**bold**`` and ``code`` are rendered."""
        body = html.escape(text)
        body = re.sub(r"\*\*(.+?)\*\*", r"<strong>\1</strong>", body)
        body = re.sub(r"`(.+?)`", r"<code>\1</code>", body)
        cls = f' class="{css_class}"' if css_class else ""
        self._parts.append(f"<p{cls}>{body}</p>")

    def markdown(self, text: str, *, heading_offset: int = 0) -> None:
        """Add a block of simple Markdown (what dicblur's own generated texts use): ``#``
        headings, ``-`` lists, ``|`` tables, paragraphs, ``**bold**``, ``*italic*`` and
        ``code``. Headings are shifted down by ``heading_offset`` levels and are not listed
        in the table of contents."""
        self._parts.append(markdown_to_html(text, heading_offset=heading_offset))

    def preformatted(self, text: str) -> None:
        """Add a block of preformatted text (commands, versions)."""
        self._parts.append(f"<pre>{html.escape(text)}</pre>")

    def table(
        self,
        rows: Sequence[Mapping[str, Any]],
        *,
        columns: Sequence[str] | None = None,
        caption: str | None = None,
        digits: int = 4,
        left: Iterable[str] = (),
        classes: Mapping[str, Mapping[Any, str]] | None = None,
    ) -> None:
        """Add a table from a list of row mappings.

        ``left`` names left-aligned (text) columns; ``classes[col][value]`` gives a CSS class
        to cells of ``col`` holding ``value`` (e.g. verdict colouring).
        """
        if not rows:
            self.paragraph("(no rows)")
            return
        cols = list(columns or rows[0].keys())
        left_set = set(left)
        classes = classes or {}
        out = ["<table>"]
        if caption:
            out.append(f"<caption>{html.escape(caption)}</caption>")
        out.append(
            "<tr>"
            + "".join(
                f'<th class="{"l" if c in left_set else ""}">{html.escape(c)}</th>' for c in cols
            )
            + "</tr>"
        )
        for row in rows:
            cells = []
            for c in cols:
                v = row.get(c, "")
                cls = ["l"] if c in left_set else []
                extra = classes.get(c, {}).get(v)
                if extra:
                    cls.append(extra)
                attr = f' class="{" ".join(cls)}"' if cls else ""
                cells.append(f"<td{attr}>{_cell(v, digits)}</td>")
            out.append("<tr>" + "".join(cells) + "</tr>")
        out.append("</table>")
        self._parts.append("".join(out))

    def figure(self, fig: Any, name: str, caption: str) -> None:
        """Embed a matplotlib figure (and write it as PNG and SVG)."""
        png = fig_to_files(fig, self.folder / "figures", name)
        self._embed(png, name, caption)

    def figure_from_writer(self, writer: Any, name: str, caption: str) -> None:
        """Embed a figure made by ``writer(path)`` (a function that saves one figure to a
        path, format from the extension); it is called for PNG and for SVG."""
        folder = self.folder / "figures"
        folder.mkdir(parents=True, exist_ok=True)
        png = folder / f"{name}.png"
        writer(png)
        writer(folder / f"{name}.svg")
        self._embed(png.read_bytes(), name, caption)

    def _embed(self, png: bytes, name: str, caption: str) -> None:
        data = base64.b64encode(png).decode("ascii")
        self.figures.append(name)
        self._parts.append(
            f'<figure id="fig-{_slug(name)}"><img alt="{html.escape(caption)}" '
            f'src="data:image/png;base64,{data}"><figcaption>{html.escape(caption)}'
            "</figcaption></figure>"
        )

    def write(self, filename: str = "report.html") -> Path:
        """Write the page and return its path."""
        self.folder.mkdir(parents=True, exist_ok=True)
        stamp = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
        toc = "".join(f'<li><a href="#{a}">{html.escape(t)}</a></li>' for a, t in self._toc)
        page = (
            "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
            f"<title>{html.escape(self.title)}</title><style>{_CSS}</style></head><body>"
            f"<h1>{html.escape(self.title)}</h1><p class='note'>Generated {stamp} by dicblur."
            f"</p><nav><ul>{toc}</ul></nav>{''.join(self._parts)}{_SCRIPT}</body></html>"
        )
        path = self.folder / filename
        write_text(path, page)
        return path
