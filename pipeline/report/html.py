"""A static, self-contained HTML validation report: sections of text, tables and figures.

Figures are embedded as base64 PNG (no server, no external files), tables come from pandas
DataFrames or lists of dicts. The page carries its own CSS and works offline.
"""

from __future__ import annotations

import base64
import datetime as _dt
import html
import io
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["Report", "Section", "figure_to_png", "escape"]

_CSS = """
body{font-family:-apple-system,Segoe UI,Helvetica,Arial,sans-serif;margin:0;color:#1d2433;background:#f6f7f9}
header{background:#1f3a5f;color:#fff;padding:18px 32px}
header h1{margin:0;font-size:22px} header p{margin:4px 0 0;opacity:.85;font-size:13px}
nav{background:#fff;border-bottom:1px solid #dde2ea;padding:8px 32px;font-size:13px}
nav a{margin-right:14px;color:#1f3a5f;text-decoration:none}
main{padding:8px 32px 40px;max-width:1200px}
section{background:#fff;border:1px solid #dde2ea;border-radius:6px;margin:18px 0;padding:14px 20px}
h2{font-size:18px;margin:4px 0 10px;color:#1f3a5f}
h3{font-size:15px;margin:14px 0 6px}
table{border-collapse:collapse;font-size:12.5px;margin:6px 0 10px}
th,td{border:1px solid #dde2ea;padding:3px 8px;text-align:right}
th{background:#eef2f7} td.l,th.l{text-align:left}
img{max-width:100%;height:auto;border:1px solid #eee;margin:6px 0}
.note{font-size:13px;color:#44506a} .warn{color:#8a4b00;background:#fff4e0;padding:6px 10px;border-radius:4px;font-size:13px}
.ok{color:#1b6b2f} .bad{color:#a4161a}
.verdict{font-size:14px;line-height:1.45;background:#eef3fb;padding:8px 12px;border-left:4px solid #3a5ba0}
code{background:#eef2f7;padding:1px 4px;border-radius:3px}
"""


def escape(text: Any) -> str:
    """HTML-escape any value's string form."""
    return html.escape(str(text), quote=True)


def figure_to_png(fig, dpi: int = 110, *, tight_bbox: bool = True) -> bytes:
    """Render a matplotlib figure to PNG bytes and close it.

    ``tight_bbox``: crop to what the figure draws (``bbox_inches="tight"``, one layout pass
    more); False for a figure laid out already (``tight_layout``, its legends included)."""
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight" if tight_bbox else None)
    plt.close(fig)
    return buf.getvalue()


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        if v != v:
            return "–"
        a = abs(v)
        if a != 0 and (a < 1e-3 or a >= 1e6):
            return f"{v:.4g}"
        return f"{v:.5g}"
    return escape(v)


@dataclass
class Section:
    """One report section: a title and an ordered list of HTML fragments."""

    title: str
    anchor: str
    parts: list[str] = field(default_factory=list)

    def text(self, text: str, cls: str = "note") -> "Section":
        """A paragraph (escaped)."""
        self.parts.append(f'<p class="{cls}">{escape(text)}</p>')
        return self

    def html(self, fragment: str) -> "Section":
        """A raw HTML fragment (caller escapes)."""
        self.parts.append(fragment)
        return self

    def warning(self, text: str) -> "Section":
        self.parts.append(f'<p class="warn">{escape(text)}</p>')
        return self

    def heading(self, text: str) -> "Section":
        self.parts.append(f"<h3>{escape(text)}</h3>")
        return self

    def table(self, rows, columns: list[str] | None = None, caption: str | None = None,
              max_rows: int = 200) -> "Section":
        """A table from a DataFrame or a list of dicts (first column left-aligned)."""
        # a DataFrame exists only where pandas is loaded: a report of lists of dicts (the
        # validation report's) does not import it to find that out
        pd = sys.modules.get("pandas")
        if pd is not None and isinstance(rows, pd.DataFrame):
            columns = columns or [str(c) for c in rows.columns]
            rows = rows.to_dict("records")
        rows = list(rows)
        if columns is None:
            columns = list(rows[0].keys()) if rows else []
        out = ["<table>"]
        if caption:
            out.append(f"<caption class='note'>{escape(caption)}</caption>")
        out.append("<tr>" + "".join(f"<th class='{'l' if i == 0 else ''}'>{escape(c)}</th>"
                                    for i, c in enumerate(columns)) + "</tr>")
        for r in rows[:max_rows]:
            # first column and text cells left-aligned, numbers right-aligned
            out.append("<tr>" + "".join(
                f"<td class='{'l' if i == 0 or isinstance(r.get(c, ''), str) else ''}'>{_fmt(r.get(c, ''))}</td>"
                for i, c in enumerate(columns)) + "</tr>")
        out.append("</table>")
        if len(rows) > max_rows:
            out.append(f"<p class='note'>{len(rows) - max_rows} more row(s) in the CSV files.</p>")
        self.parts.append("\n".join(out))
        return self

    def figure(self, fig_or_png, caption: str = "", alt: str = "") -> "Section":
        """Embed a matplotlib figure (or PNG bytes) as a base64 image."""
        png = fig_or_png if isinstance(fig_or_png, (bytes, bytearray)) else figure_to_png(fig_or_png)
        b64 = base64.b64encode(png).decode("ascii")
        self.parts.append(f'<figure><img alt="{escape(alt or caption)}" '
                          f'src="data:image/png;base64,{b64}"/>'
                          + (f"<figcaption class='note'>{escape(caption)}</figcaption>" if caption else "")
                          + "</figure>")
        return self


@dataclass
class Report:
    """A validation report assembled section by section and written as one HTML file."""

    title: str
    subtitle: str = ""
    sections: list[Section] = field(default_factory=list)

    def section(self, title: str) -> Section:
        """Append and return a new section."""
        anchor = "s" + str(len(self.sections) + 1)
        s = Section(title, anchor)
        self.sections.append(s)
        return s

    def to_html(self) -> str:
        """The whole page as a string."""
        stamp = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
        nav = " ".join(f'<a href="#{s.anchor}">{escape(s.title)}</a>' for s in self.sections)
        body = "\n".join(f'<section id="{s.anchor}"><h2>{escape(s.title)}</h2>\n' + "\n".join(s.parts)
                         + "</section>" for s in self.sections)
        return (f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
                f"<title>{escape(self.title)}</title><style>{_CSS}</style></head><body>"
                f"<header><h1>{escape(self.title)}</h1><p>{escape(self.subtitle)} · generated {stamp}"
                f" by meshphase</p></header><nav>{nav}</nav><main>{body}</main></body></html>")

    def write(self, path) -> Path:
        """Write the page to ``path`` (UTF-8)."""
        path = Path(path)
        path.write_text(self.to_html(), encoding="utf-8")
        return path
