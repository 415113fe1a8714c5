"""Compact HTML for notebooks (``_repr_html_`` of :class:`~meshphase.recording.Recording`
and :class:`~meshphase.Result`): plain tables, every text escaped, no pandas and no
matplotlib."""

from __future__ import annotations

import html
import math
from numbers import Integral, Real

__all__ = ["html_table"]

_STYLE = "border-collapse:collapse;font-size:90%"


def _cell(v) -> str:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, Integral):
        return str(int(v))
    if isinstance(v, Real):
        v = float(v)
        if not math.isfinite(v):
            return "" if math.isnan(v) else str(v)
        return f"{v:.4g}" if v == 0 or 1e-3 <= abs(v) < 1e5 else f"{v:.3e}"
    return html.escape(str(v))


def html_table(rows: list[dict], columns, *, caption: str | None = None,
               headers: dict | None = None) -> str:
    """An HTML table of ``rows`` (dicts) with ``columns`` in order.

    Parameters
    ----------
    rows : list of dict
    columns : sequence of str
        Keys of the rows to show; a missing key shows an empty cell.
    caption : str, optional
        Text above the table (escaped).
    headers : dict, optional
        Column key -> header text (default: the key).

    Returns
    -------
    str
    """
    if not isinstance(rows, list) or not all(isinstance(r, dict) for r in rows):
        raise TypeError("rows must be a list of dicts")
    columns = list(columns)
    if not columns:
        raise ValueError("columns is empty")
    headers = headers or {}
    head = "".join(f"<th style='text-align:left;padding:0 .6em'>{html.escape(str(headers.get(c, c)))}"
                   "</th>" for c in columns)
    body = "".join("<tr>" + "".join(f"<td style='padding:0 .6em'>{_cell(r.get(c))}</td>"
                                    for c in columns) + "</tr>" for r in rows)
    cap = f"<caption style='text-align:left'>{html.escape(caption)}</caption>" if caption else ""
    return f"<table style='{_STYLE}'>{cap}<thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"
