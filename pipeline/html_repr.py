"""Compact HTML of a :class:`~meshphase.recording.Recording` and of a run, for notebooks
(``_repr_html_``): plain tables, every text escaped, no pandas and no matplotlib."""

from __future__ import annotations

import html
import math
from numbers import Integral, Real

__all__ = ["html_table", "recording_html", "run_html"]

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


def recording_html(rec) -> str:
    """A recording's channels, sample rate, duration and start, as HTML."""
    from .recording import Recording

    if not isinstance(rec, Recording):
        raise TypeError(f"rec must be a Recording, got {type(rec).__name__}")
    cap = (f"Recording: {rec.n_channels} channel(s) at {rec.fs:g} Hz, {rec.duration:.6g} s "
           f"({rec.n_samples} samples), t0 = {rec.t0:g} s"
           + (f", started {rec.start_datetime}" if rec.start_datetime else ""))
    rows = [{"channel": c.name, "kind": c.kind, "units": c.units, "gear": c.gear,
             "tooth": c.tooth, "face_position_mm": (None if c.face_position is None
                                                    else c.face_position * 1e3),
             "description": c.description} for c in rec.channels]
    cols = ["channel", "kind", "units", "gear"]
    cols += [k for k in ("tooth", "face_position_mm", "description")
             if any(r[k] not in (None, "") for r in rows)]
    return html_table(rows, cols, caption=cap)


def run_html(ctx, status: dict) -> str:
    """A run's status, input and per-planet phasing (and load sharing), as HTML.

    Parameters
    ----------
    ctx : RunContext
    status : dict
        :func:`meshphase.exits.run_status` of ``ctx``.
    """
    from .result_frames import load_sharing_rows, phasing_rows

    parts = [f"<p><b>meshphase result: {html.escape(status['status'])}</b>"]
    if ctx.load is not None:
        rec = ctx.load.recording
        parts.append(f" &middot; {html.escape(str(ctx.load.source))} &middot; {rec.n_channels} "
                     f"channel(s) at {rec.fs:g} Hz, {rec.duration:.6g} s")
    g = ctx.gearset
    if g is not None:
        parts.append(f" &middot; gearset Z {g.z_sun}/{g.z_ring}/{g.z_planet}, {g.n_planets} planets")
    parts.append("</p>")
    for m in status.get("missing_results") or []:
        parts.append(f"<p>not computed: {html.escape(str(m['result']))} "
                     f"({html.escape(str(m['cause']))})</p>")
    for gauge, reasons in (status.get("unreliable") or {}).items():
        parts.append(f"<p>{html.escape(gauge)} phasing not reliable: "
                     f"{html.escape('; '.join(reasons))}</p>")
    rows = phasing_rows(ctx)
    if rows:
        parts.append(html_table(rows, ["gauge", "planet", "n_passes", "mean_cycles", "sd_cycles",
                                       "ideal_cycles", "model_cycles", "residual_model_rms_cycles"],
                                caption="Measured phasing per planet [mesh cycles]"))
    ls = load_sharing_rows(ctx)
    if ls:
        parts.append(html_table(ls, ["planet", "load_sharing", "std_error", "n_passes"],
                                caption="Load sharing [-]"))
    if ctx.messages:
        parts.append(f"<p>{len(ctx.messages)} message(s): see <code>.messages</code></p>")
    return "".join(parts)
