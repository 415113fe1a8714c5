"""The combined report of a campaign: many recordings, one static HTML page.

One row per recording (status, passes, residual RMS, band coverage, wall time), the measured
phasing per planet and the load sharing per recording as tables, and figures across the
recordings: each planet's mean phasing (deviation from the ideal, with its pass-to-pass
spread), the load sharing, the residual RMS and the wall time per recording. Failed
recordings are listed with their error message. Input: the dict that
:func:`meshphase.campaign.runner.run_campaign` builds (per-recording dicts from
:func:`meshphase.campaign.runner.run_recording`).

Drawing the figures is most of the report's time. The page is laid out first, each figure as a call to draw (:func:`figure_png`: a figure function
of this module and its arguments); then they are drawn, one after another here, or by
``draw`` (:func:`build_campaign_report`): the campaign hands them to its workers, which draw
them side by side while the cluster is still up.
"""

from __future__ import annotations

import functools
import math
import urllib.parse
from pathlib import Path
from typing import Callable

import numpy as np

from ..io import atomic_path
from .html import Report, escape, figure_to_png

__all__ = ["build_campaign_report", "figure_png", "phasing_across_recordings", "load_sharing_across_recordings",
           "residual_rms_across_recordings", "wall_times_across_recordings", "pyplot"]

_STATUS_COLOR = {"ok": "#1b6b2f", "unreliable": "#7a5195", "partial": "#c77800", "failed": "#a4161a"}


@functools.cache
def pyplot():
    """matplotlib's pyplot on the Agg backend, imported by the first figure drawn (or by
    :mod:`meshphase.campaign.fork_ready` in the workers' fork server): a campaign's client assembles
    the report without matplotlib, its workers draw the figures.

    Returns
    -------
    module
        ``matplotlib.pyplot``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _c(i: int) -> str:
    colors = pyplot().rcParams["axes.prop_cycle"].by_key()["color"]
    return colors[i % len(colors)]


def _num(v) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        return float("nan")
    return f if math.isfinite(f) else float("nan")


def _fmt(v, fmt="{:.4g}") -> str:
    if v is None:
        return "–"
    if isinstance(v, (int, np.integer)) and not isinstance(v, bool):
        return str(int(v))
    f = _num(v)
    if isinstance(v, (float, np.floating)) or f == f:
        return "–" if f != f else fmt.format(f)
    return escape(v)


def _empty_axes(ax, text="no data"):
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes, fontsize=10, color="0.4")
    ax.set_xticks([])
    ax.set_yticks([])


def _legend_outside(ax, *handles_labels) -> None:
    """The legend right of the axes, as the run report places it (meshphase.report.figures):
    it never hides a point, and matplotlib does not search the axes for a free corner
    (``loc="best"`` tests every artist, ~0.04 s of a campaign figure). ``handles_labels``:
    ``(handles, labels)`` as :meth:`matplotlib.axes.Axes.legend` takes them (default: the
    axes' labelled artists)."""
    ax.legend(*handles_labels, fontsize=8, loc="upper left", bbox_to_anchor=(1.005, 1.0), borderaxespad=0.0)


def _names_check(names) -> list[str]:
    if isinstance(names, str) or not hasattr(names, "__iter__"):
        raise TypeError(f"names must be a sequence of str, got {type(names).__name__} {names!r}")
    return [str(n) for n in names]


#: Longest recording name a figure's axis shows whole [characters]; longer ones keep their
#: head and tail around an ellipsis (the recordings table shows them whole).
TICK_NAME_CHARS = 32


def _tick_names(names) -> list[str]:
    n = TICK_NAME_CHARS
    return [s if len(s) <= n else s[:(n - 1) // 2] + "…" + s[len(s) - (n - 1 - (n - 1) // 2):] for s in names]


def _xaxis(ax, names):
    x = np.arange(len(names))
    ax.set_xticks(x)
    ax.set_xticklabels(_tick_names(names), rotation=30 if len(names) > 4 else 0,
                       ha="right" if len(names) > 4 else "center", fontsize=8)
    ax.set_xlim(-0.6, len(names) - 0.4)
    return x


# ---------------------------------------------------------------------------- figures
def phasing_across_recordings(names, phasing: dict, ideal: dict | None = None):
    """Each planet's mean phasing per recording with its pass-to-pass spread.

    Parameters
    ----------
    names : sequence of str
        Recording names (x axis), length R.
    phasing : dict gauge -> dict planet -> (mean, std)
        ``mean`` and ``std`` arrays of length R [mesh cycles]; NaN where a recording has no
        pass of that planet.
    ideal : dict gauge -> dict planet -> float, optional
        Ideal phasing [mesh cycles]; when given the deviation from it is plotted (wrapped
        to [-0.5, 0.5) cycles) so that all planets share one scale.

    Returns
    -------
    matplotlib.figure.Figure
        One panel per gauge, sharing the recordings' axis (named under the last panel) and
        one legend of the planets (the same colour in every panel).
    """
    names = _names_check(names)
    if not isinstance(phasing, dict):
        raise TypeError(f"phasing must be a dict gauge -> planet -> (mean, std), got {type(phasing).__name__}")
    gauges = [g for g in ("sun", "ring") if g in phasing] + [g for g in phasing if g not in ("sun", "ring")]
    n_panels = max(1, len(gauges))
    fig, axes = pyplot().subplots(n_panels, 1, figsize=(max(6.0, 0.7 * len(names) + 3), 0.4 + 2.6 * n_panels),
                                  squeeze=False, sharex=True)
    if not gauges or not names:
        _empty_axes(axes[0, 0], "no phasing measured")
        return fig
    x = _xaxis(axes[-1, 0], names)
    legend: dict = {}   # planet -> its first handle, over all panels: one legend
    for ax, g in zip(axes[:, 0], gauges):
        planets = sorted(phasing[g], key=lambda k: int(k))
        width = 0.6 / max(1, len(planets))
        for j, p in enumerate(planets):
            mean, std = (np.asarray(a, dtype=float) for a in phasing[g][p])
            if mean.shape != (len(names),) or std.shape != (len(names),):
                raise ValueError(f"phasing[{g!r}][{p!r}] must hold two arrays of length {len(names)} "
                                 f"(one value per recording), got shapes {mean.shape}, {std.shape}")
            ref = None if not ideal or g not in ideal or p not in ideal[g] else float(ideal[g][p])
            y = mean if ref is None else (mean - ref + 0.5) % 1.0 - 0.5
            h = ax.errorbar(x - 0.3 + width * (j + 0.5), y, yerr=np.nan_to_num(std), fmt="o", ms=4, capsize=3,
                            color=_c(int(p) - 1), label=f"planet {p}")
            legend.setdefault(int(p), h)
        if ideal:
            ax.axhline(0.0, color="k", lw=0.8, ls=":")
        ax.set_ylabel(("gamma - ideal" if ideal else "gamma") + " [mesh cycles]", fontsize=9)
        ax.set_title(f"{g} gauge: mean phasing per planet, bars = pass-to-pass std", fontsize=10)
    if legend:
        _legend_outside(axes[0, 0], [legend[p] for p in sorted(legend)], [f"planet {p}" for p in sorted(legend)])
    fig.tight_layout()
    return fig


def load_sharing_across_recordings(names, load_sharing, std_error=None):
    """Load-sharing factor per planet [-] for each recording (1 = equal share).

    Parameters
    ----------
    names : sequence of str
        Recording names, length R.
    load_sharing : array_like, shape (R, N)
        Factor per recording and planet [-]; NaN where not measured.
    std_error : array_like, shape (R, N), optional
        Standard error of each factor [-].

    Returns
    -------
    matplotlib.figure.Figure
    """
    names = _names_check(names)
    ls = np.asarray(load_sharing, dtype=float)
    if ls.size == 0:
        ls = ls.reshape(len(names), 0)
    if ls.ndim != 2 or ls.shape[0] != len(names):
        raise ValueError(f"load_sharing must have shape (n_recordings={len(names)}, n_planets), got {ls.shape}")
    se = None if std_error is None else np.asarray(std_error, dtype=float)
    if se is not None and se.shape != ls.shape:
        raise ValueError(f"std_error must have the shape of load_sharing {ls.shape}, got {se.shape}")
    fig, ax = pyplot().subplots(figsize=(max(6.0, 0.7 * len(names) + 3), 3.2))
    if not names or ls.shape[1] == 0 or not np.isfinite(ls).any():
        _empty_axes(ax, "no load sharing measured")
        return fig
    x = _xaxis(ax, names)
    n = ls.shape[1]
    width = 0.6 / n
    for k in range(n):
        ax.errorbar(x - 0.3 + width * (k + 0.5), ls[:, k], yerr=None if se is None else np.nan_to_num(se[:, k]),
                    fmt="s", ms=4, capsize=3, color=_c(k), label=f"planet {k + 1}")
    ax.axhline(1.0, color="k", lw=0.8, ls=":")
    ax.set_ylabel("load sharing factor [-]")
    ax.set_title("load sharing per recording", fontsize=10)
    _legend_outside(ax)
    fig.tight_layout()
    return fig


def residual_rms_across_recordings(names, rms: dict, *, label: str = "RMS residual vs ideal"):
    """Bars of the phasing residual RMS [mesh cycles] per recording, one bar per gauge.

    Parameters
    ----------
    names : sequence of str
    rms : dict gauge -> array_like of length R
        RMS [mesh cycles]; NaN where not computed.
    label : str
        Axis title.
    """
    names = _names_check(names)
    if not isinstance(rms, dict):
        raise TypeError(f"rms must be a dict gauge -> values, got {type(rms).__name__}")
    fig, ax = pyplot().subplots(figsize=(max(6.0, 0.7 * len(names) + 3), 3.0))
    vals = {g: np.asarray(v, dtype=float) for g, v in rms.items()}
    for g, v in vals.items():
        if v.shape != (len(names),):
            raise ValueError(f"rms[{g!r}] must have length {len(names)}, got shape {v.shape}")
    if not names or not any(np.isfinite(v).any() for v in vals.values()):
        _empty_axes(ax, "no residuals")
        return fig
    x = _xaxis(ax, names)
    w = 0.8 / max(1, len(vals))
    for i, (g, v) in enumerate(vals.items()):
        ax.bar(x - 0.4 + w * (i + 0.5), np.nan_to_num(v), width=w, color=_c(i), label=g)
    ax.set_ylabel("[mesh cycles]")
    ax.set_title(label, fontsize=10)
    _legend_outside(ax)
    fig.tight_layout()
    return fig


def wall_times_across_recordings(names, seconds, statuses=None):
    """Horizontal bars of each recording's task wall time [s], coloured by status."""
    names = _names_check(names)
    s = np.asarray(seconds, dtype=float).reshape(-1)
    if s.shape != (len(names),):
        raise ValueError(f"seconds must have one value per recording ({len(names)}), got shape {s.shape}")
    st = list(statuses) if statuses is not None else ["ok"] * len(names)
    if len(st) != len(names):
        raise ValueError(f"statuses must have one entry per recording ({len(names)}), got {len(st)}")
    fig, ax = pyplot().subplots(figsize=(7, 0.32 * len(names) + 1.3))
    if not names:
        _empty_axes(ax, "no recordings")
        return fig
    y = np.arange(len(names))
    ax.barh(y, np.nan_to_num(s), color=[_STATUS_COLOR.get(x, "0.5") for x in st])
    ax.set_yticks(y)
    ax.set_yticklabels(_tick_names(names), fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel("task wall time [s] (green ok, purple unreliable, orange partial, red failed)")
    fig.tight_layout()
    return fig


def figure_png(make, *args, **kwargs) -> bytes:
    """One figure of the report, drawn: ``make(*args, **kwargs)`` rendered to PNG bytes.

    What :func:`build_campaign_report` hands to its ``draw`` (a campaign's workers run it).

    Parameters
    ----------
    make : callable
        A figure function of this module (e.g. :func:`load_sharing_across_recordings`),
        returning a matplotlib figure.
    *args, **kwargs
        Its arguments.

    Returns
    -------
    bytes
        The PNG (:func:`meshphase.report.html.figure_to_png`; the figure is closed). The
        figures of this module lay themselves out (``tight_layout``, their legends right of
        the axes included; recording names past :data:`TICK_NAME_CHARS` shortened, which
        ``tight_layout`` could not fit at 80 characters), so the PNG is not cropped to a
        tight box, which laid each out a second time.

    Raises
    ------
    TypeError
        ``make`` is not callable or does not return a figure.
    """
    if not callable(make):
        raise TypeError(f"make must be a figure function, got {type(make).__name__} {make!r}")
    fig = make(*args, **kwargs)
    if not hasattr(fig, "savefig"):
        raise TypeError(f"{getattr(make, '__name__', make)!r} returned {type(fig).__name__}, not a figure")
    return figure_to_png(fig, tight_bbox=False)


# ---------------------------------------------------------------------------- collection
def _planets(recs, gear) -> list[str]:
    ps = set()
    for r in recs:
        ps |= set(((r.get("phasing") or {}).get(gear) or {}).get("per_planet", {}) or {})
    return sorted(ps, key=int)


def _ideal(recs) -> dict:
    for r in recs:
        ide = r.get("ideal")
        if ide:
            return {"sun": {str(k + 1): v for k, v in enumerate(ide.get("gamma_s") or [])},
                    "ring": {str(k + 1): v for k, v in enumerate(ide.get("gamma_r") or [])}}
    return {}


def _link(path, base) -> str:
    """A relative URL of ``path`` from the folder ``base`` (the page's folder)."""
    try:
        rel = Path(path).relative_to(base).as_posix()
    except (ValueError, TypeError):
        rel = Path(str(path)).name
    return urllib.parse.quote(rel)


def _records_table(recs, base=None) -> str:
    cols = ["recording", "format", "status", "duration [s]", "sun passes", "ring passes",
            "RMS vs ideal sun", "RMS vs ideal ring", "RMS vs model sun", "RMS vs model ring",
            "band coverage sun", "band coverage ring", "wall time [s]", "attempts", "worker", "results"]
    out = ["<table>", "<tr>" + "".join(f"<th class='{'l' if i == 0 else ''}'>{escape(c)}</th>"
                                       for i, c in enumerate(cols)) + "</tr>"]
    for r in recs:
        ph = r.get("phasing") or {}
        cp = r.get("compare") or {}
        info = r.get("recording_info") or {}
        st = r.get("status", "failed")
        cls = {"ok": "ok", "failed": "bad"}.get(st, "")
        summary = (r.get("files") or {}).get("summary")
        link = (f"<a href='{escape(_link(summary, base))}'>summary.json</a>" if summary else "–")
        cells = [f"<td class='l' title='{escape(r.get('recording', ''))}'>{escape(r.get('name', ''))}</td>",
                 f"<td>{escape(r.get('format') or '–')}</td>",
                 f"<td class='{cls}'>{escape(st)}</td>",
                 f"<td>{_fmt(info.get('duration_s'))}</td>"]
        for g in ("sun", "ring"):
            cells.append(f"<td>{_fmt((ph.get(g) or {}).get('n_passes'))}</td>")
        for key in ("rms_vs_ideal", "rms_vs_model", "coverage"):
            for g in ("sun", "ring"):
                v = (cp.get(g) or {}).get(key)
                cells.append(f"<td>{_fmt(v, '{:.1%}' if key == 'coverage' else '{:.3g}')}</td>")
        attempts = _fmt(r.get("attempts", 1)) + (" (resumed)" if r.get("resumed") else "")
        cells += [f"<td>{_fmt(r.get('wall_time_s'), '{:.2f}')}</td>", f"<td>{escape(attempts)}</td>",
                  f"<td>{escape(r.get('worker') or '–')}</td>", f"<td>{link}</td>"]
        out.append("<tr>" + "".join(cells) + "</tr>")
    out.append("</table>")
    return "\n".join(out)


def build_campaign_report(campaign: dict, out_dir, *, filename: str = "campaign_report.html",
                          draw: Callable[[list], list] | None = None) -> Path:
    """Write the combined HTML report of a campaign (figures embedded, PNGs in ``figures/``).

    Parameters
    ----------
    campaign : dict
        As built by :func:`meshphase.campaign.runner.run_campaign`: ``recordings`` (list of dicts
        from :func:`meshphase.campaign.runner.run_recording`) and optionally ``scene``, ``counts``,
        ``timing_s``, ``cluster``, ``scene_level``, ``skipped_inputs`` and ``out_dir`` (the
        folder the page will be read in: links to the recordings' results are relative to it;
        default ``out_dir`` below).
    out_dir : str or Path
        Existing folder; the page (and its PNGs) are written there, each atomically.
    filename : str
    draw : callable, optional
        ``draw(calls) -> list of PNG bytes``, one per call ``(make, args, kwargs)``, in order,
        each as :func:`figure_png` gives it (the campaign draws them on its workers). None:
        drawn here, one after another.

    Returns
    -------
    Path
        The HTML file.
    """
    if not isinstance(campaign, dict):
        raise TypeError(f"campaign must be a dict (run_campaign's result), got {type(campaign).__name__}")
    recs = campaign.get("recordings", [])
    if not isinstance(recs, list) or not all(isinstance(r, dict) for r in recs):
        raise TypeError("campaign['recordings'] must be a list of dicts (run_recording results)")
    out_dir = Path(out_dir)
    if not out_dir.is_dir():
        raise FileNotFoundError(f"{out_dir}: output folder does not exist")
    figs = _Figures(out_dir / "figures")
    names = [str(r.get("name", f"#{i + 1}")) for i, r in enumerate(recs)]
    counts = campaign.get("counts") or {s: sum(r.get("status") == s for r in recs)
                                        for s in ("ok", "unreliable", "partial", "failed")}
    rep = Report(f"meshphase campaign — {campaign.get('scene', '')}",
                 f"{len(recs)} recording(s) · {counts.get('ok', 0)} ok, "
                 + (f"{counts['unreliable']} unreliable, " if counts.get("unreliable") else "")
                 + f"{counts.get('partial', 0)} partial, {counts.get('failed', 0)} failed")
    _overview_section(rep, campaign, recs)
    if recs:
        _recordings_sections(rep, recs, names, campaign.get("out_dir") or out_dir, figs)
    _phasing_section(rep, recs, names, figs)
    _load_sharing_section(rep, recs, names, figs)
    if campaign.get("scene_level"):
        _scene_level_section(rep, campaign["scene_level"])
    msg_rows = [{"recording": names[i], "message": m} for i, r in enumerate(recs)
                for m in (r.get("messages") or [])[:8]]
    if msg_rows:
        s = rep.section("Warnings per recording")
        s.table(msg_rows, max_rows=300)
    figs.draw(draw)
    path = out_dir / filename
    with atomic_path(path, overwrite=True) as tmp:  # never a half-written page
        rep.write(tmp)
    return path


class _Figures:
    """The report's figures: each keeps its place in its section (:meth:`add`) until all are
    drawn (:meth:`draw`); their PNGs go to ``fig_dir``, each atomically."""

    def __init__(self, fig_dir: Path):
        self.fig_dir = fig_dir
        self.pending: list[tuple] = []  # (section, index in its parts, name, caption, call)

    def add(self, section, name: str, caption: str, make, *args, **kwargs) -> None:
        section.parts.append("")  # the figure's place; filled by draw()
        self.pending.append((section, len(section.parts) - 1, name, caption, (make, args, kwargs)))

    def draw(self, draw: Callable[[list], list] | None) -> None:
        calls = [p[4] for p in self.pending]
        pngs = list(draw(calls)) if draw is not None and calls else [figure_png(m, *a, **k) for m, a, k in calls]
        if len(pngs) != len(calls) or not all(isinstance(p, (bytes, bytearray)) for p in pngs):
            raise TypeError(f"draw must return one PNG (bytes) per figure ({len(calls)}), got "
                            f"{[type(p).__name__ for p in pngs]}")
        if pngs:
            self.fig_dir.mkdir(exist_ok=True)
        for (section, idx, name, caption, _), png in zip(self.pending, pngs):
            with atomic_path(self.fig_dir / f"{name}.png", overwrite=True) as tmp:
                tmp.write_bytes(png)
            section.figure(png, caption)
            section.parts[idx] = section.parts.pop()
        self.pending.clear()


def _overview_section(rep, campaign: dict, recs: list) -> None:
    """The "Campaign" section: scene, results, cluster, step times, inputs left out."""
    timing = campaign.get("timing_s") or {}
    cluster = campaign.get("cluster") or {}
    s = rep.section("Campaign")
    s.text(f"Scene {campaign.get('scene_path', campaign.get('scene', ''))}; per-recording results: "
           f"{', '.join(campaign.get('results_per_recording', [])) or '–'}; computed once for the scene: "
           f"{', '.join(campaign.get('results_client', [])) or '–'}.")
    if cluster:
        s.text(f"Dask cluster {'(local)' if cluster.get('local') else '(external)'} at "
               f"{cluster.get('scheduler')}, {cluster.get('n_workers')} worker(s).")
    if timing:
        s.table([{"step": k, "wall time [s]": float(v)} for k, v in timing.items()],
                caption="wall time of the campaign's steps")
        busy = float(np.nansum([_num(r.get("wall_time_s")) for r in recs])) if recs else 0.0
        if timing.get("processing"):
            s.text(f"Sum of the tasks' wall times {busy:.2f} s over {float(timing['processing']):.2f} s of "
                   f"processing: {busy / float(timing['processing']):.2f} tasks running on average.")
    if not recs:
        s.warning("No recordings in this campaign.")
    skipped = campaign.get("skipped_inputs") or []
    if skipped:
        by_reason: dict[str, list[str]] = {}
        for sk in skipped:
            reason = str(sk.get("reason", "")).split(":")[0]
            by_reason.setdefault(reason, []).append(Path(str(sk.get("path", ""))).name)
        s.text("Folder entries left out: " + "; ".join(
            f"{len(v)} {k} ({', '.join(v[:6])}{', ...' if len(v) > 6 else ''})" for k, v in by_reason.items()))


def _recordings_sections(rep, recs: list, names: list, base, figs: _Figures) -> None:
    """The "Recordings" table and wall-time figure; "Failures" and "Retries" when any."""
    s = rep.section("Recordings")
    s.html(_records_table(recs, base))
    s.text("RMS residuals are of the measured phasing [mesh cycles] against the ideal phasing "
           "and against the shaft-hole-error model identified from the recording itself; band "
           "coverage is the fraction of passes inside the tolerance Monte Carlo 3-sigma band.")
    figs.add(s, "wall_times", "Task wall time per recording", wall_times_across_recordings, names,
             [_num(r.get("wall_time_s")) for r in recs], [r.get("status", "failed") for r in recs])
    bad = [r for r in recs if r.get("status") in ("failed", "partial", "unreliable")]
    if bad:
        s = rep.section("Failures")
        s.table([{"recording": r.get("name"), "status": r.get("status"), "error": r.get("error") or "",
                  "file": r.get("recording")} for r in bad])
    retried = [r for r in recs if r.get("retries")]
    if retried:
        s = rep.section("Retries")
        s.text("Tasks whose worker was lost (killed, crashed, out of memory, or restarted after "
               "another task's timeout) are given to another worker by Dask; each loss is listed.")
        s.table([{"recording": r.get("name"), "attempts": r.get("attempts"), "status": r.get("status"),
                  "cause": c} for r in retried for c in r["retries"]])


def _per_planet(r: dict, g: str, p: str) -> dict:
    return (((r.get("phasing") or {}).get(g) or {}).get("per_planet") or {}).get(p) or {}


def _phasing_rows(recs: list, names: list, g: str, planets: list, ideal: dict):
    """(table rows, {planet: (mean, std)} arrays across recordings) of gauge ``g``."""
    rows = []
    if g in ideal:
        rows.append({"recording": "ideal", **{f"planet {p}": _fmt(ideal[g].get(p), "{:.5f}")
                                              for p in planets}})
    data = {}
    for p in planets:
        mean, std = [], []
        for r in recs:
            v = _per_planet(r, g, p)
            mean.append(_num(v.get("mean")))
            std.append(_num(v.get("std")))
        data[p] = (np.array(mean), np.array(std))
    for i, r in enumerate(recs):
        row = {"recording": names[i]}
        for p in planets:
            v = _per_planet(r, g, p)
            row[f"planet {p}"] = ("–" if v.get("mean") is None else
                                  f"{v['mean']:.5f} ± {_fmt(v.get('std'), '{:.1e}')} "
                                  f"(n={v.get('n', '–')})")
        rows.append(row)
    return rows, data


def _phasing_section(rep, recs: list, names: list, figs: _Figures) -> None:
    """"Phasing per planet": a table per gauge, the phasing and residual-RMS figures."""
    ideal = _ideal(recs)
    gauges = [g for g in ("sun", "ring") if _planets(recs, g)]
    if not gauges:
        return
    s = rep.section("Phasing per planet")
    data = {}
    for g in gauges:
        rows, data[g] = _phasing_rows(recs, names, g, _planets(recs, g), ideal)
        s.heading(f"{g} gauge: measured gamma [mesh cycles], mean ± pass-to-pass std (passes)")
        s.table(rows)
    figs.add(s, "phasing_across_recordings", "Mean measured phasing per planet and recording (deviation "
             "from the ideal), error bars the pass-to-pass standard deviation", phasing_across_recordings,
             names, data, {g: ideal[g] for g in gauges if g in ideal} or None)
    rms = {f"{g} vs {ref}": np.array([_num(((r.get("compare") or {}).get(g) or {}).get(f"rms_vs_{ref}"))
                                      for r in recs])
           for g in gauges for ref in ("ideal", "model")}
    rms = {k: v for k, v in rms.items() if np.isfinite(v).any()}
    if rms:
        figs.add(s, "residual_rms", "RMS of the measured phasing against the ideal and against the "
                 "error model identified from each recording", residual_rms_across_recordings, names, rms,
                 label="RMS residual of the measured phasing")


def _load_sharing_section(rep, recs: list, names: list, figs: _Figures) -> None:
    """"Load sharing": factor ± standard error per planet and recording, table and figure."""
    n_pl = max((len(r.get("load_sharing") or []) for r in recs), default=0)
    if not n_pl:
        return
    s = rep.section("Load sharing")
    ls = np.full((len(recs), n_pl), np.nan)
    se = np.full((len(recs), n_pl), np.nan)
    rows = []
    for i, r in enumerate(recs):
        row = {"recording": names[i]}
        for d in r.get("load_sharing") or []:
            k = int(d["planet"]) - 1
            ls[i, k], se[i, k] = _num(d.get("load_sharing")), _num(d.get("std_error"))
            row[f"planet {k + 1}"] = ("–" if d.get("load_sharing") is None else
                                      f"{d['load_sharing']:.4f} ± {_fmt(d.get('std_error'), '{:.1e}')}")
        rows.append(row)
    s.table(rows, columns=["recording"] + [f"planet {k + 1}" for k in range(n_pl)],
            caption="load-sharing factor [-] ± standard error (1 = equal share)")
    figs.add(s, "load_sharing_across_recordings", "Load-sharing factor per planet and recording",
             load_sharing_across_recordings, names, ls, se)


def _scene_level_section(rep, sl: dict) -> None:
    """"Scene-level results (computed once)": stages, their times, the Monte Carlo band."""
    s = rep.section("Scene-level results (computed once)")
    s.text(f"Stages: {', '.join(sl.get('stages_ran', []))}"
           + (f"; failed: {sl.get('stages_failed')}" if sl.get("stages_failed") else ""))
    s.table([{"stage": k, "wall time [s]": float(v),
              "error estimate": (sl.get("error_estimates") or {}).get(k, "")}
             for k, v in (sl.get("timings_s") or {}).items()])
    bands = sl.get("bands") or {}
    if bands:
        rows = []
        for g, b in bands.items():
            for k, (lo, hi) in enumerate(zip(b["lo"], b["hi"])):
                rows.append({"gauge": g, "planet": k + 1, "band lo [cycles]": lo, "band hi [cycles]": hi})
        s.table(rows, caption="tolerance Monte Carlo 3-sigma band of the deviation from ideal phasing")
