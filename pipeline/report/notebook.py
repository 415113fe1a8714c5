"""Plots for notebooks: :func:`plot_recording` and :meth:`meshphase.Result.plot`.

Unlike :mod:`meshphase.report.figures` (the report's, drawn on the Agg backend), these leave
matplotlib's backend alone, so a notebook shows them inline; each returns its Figure and
takes an ``ax`` to draw into an existing axes. Strain channels (units ``m/m``) are drawn in
microstrain; phasing in mesh cycles, unwrapped around the ideal value so 0.99 and 0.01 sit
together.
"""

from __future__ import annotations

import numpy as np

import matplotlib.pyplot as plt

from ..compare.pass_model import wrap
from ..recording import Recording
from .frames import RunResults, load_sharing_rows, passes_rows, phasing_rows

__all__ = ["plot_recording", "plot_channels", "plot_result_onsets", "plot_phasing", "plot_load_sharing",
           "plot_residuals", "onset_marks"]

_GAUGES = ("sun", "ring")


def _colour(i: int) -> str:
    cycle = plt.rcParams["axes.prop_cycle"].by_key().get("color") or ["C0"]
    return cycle[i % len(cycle)]


def _axes(n: int, ax, *, height: float = 2.6, sharex: bool = True):
    """(figure, list of n axes): ``ax`` itself for one panel, else a new figure."""
    if ax is not None:
        if n != 1:
            raise ValueError(f"ax= draws one panel, but this plot has {n}; pick one (channels= "
                             "or gauge=) or leave ax out")
        return ax.figure, [ax]
    fig, axes = plt.subplots(n, 1, figsize=(10, height * n + 0.4), sharex=sharex, squeeze=False)
    return fig, list(axes[:, 0])


def _scale(units: str) -> tuple[float, str]:
    """(factor, display unit) of a channel's units: strain in microstrain."""
    return (1e6, "µε") if units in ("m/m", "strain") else (1.0, units or "-")


def _signal_panel(ax, t, x, units: str, title: str, marks, max_points: int) -> None:
    """One channel's samples (decimated to at most ``max_points``) with vertical onset marks
    ``marks``: (times [s], 1-based planets or None)."""
    if isinstance(max_points, bool) or not isinstance(max_points, int) or max_points < 2:
        raise ValueError(f"max_points must be an integer >= 2, got {max_points!r}")
    k, unit = _scale(units)
    step = max(1, -(-t.size // max_points))     # ceil: at most max_points
    ax.plot(t[::step], x[::step] * k, lw=0.6, color="0.3")
    ax.set_ylabel(f"{title} [{unit}]")
    if marks is None:
        return
    times, planets = marks
    times = np.asarray(times, dtype=float)
    inside = (times >= t[0]) & (times <= t[-1]) if t.size else np.zeros(times.size, bool)
    times = times[inside]
    pl = None if planets is None else np.asarray(planets)[inside]
    if pl is None:
        ax.vlines(times, 0, 1, transform=ax.get_xaxis_transform(), colors="C3", lw=0.8,
                  label="onsets")
    else:
        for p in np.unique(pl):
            m = pl == p
            ax.vlines(times[m], 0, 1, transform=ax.get_xaxis_transform(), lw=0.8,
                      colors=_colour(int(p) - 1) if p > 0 else "k",
                      linestyles="-" if p > 0 else ":",
                      label=f"planet {p}" if p > 0 else "unassigned")
    if times.size:
        ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.005, 1.0), borderaxespad=0.0)


def onset_marks(source, channel: str):
    """The onset marks of ``channel``: (times [s], 1-based planets or None), or None.

    ``source`` is an array of times (every channel), a dict channel -> times / Onsets /
    (times, planets), a :class:`~meshphase.Result` or a RunContext (its planet labels where
    the phasing named them, else its onsets)."""
    ctx = getattr(source, "context", source)
    if isinstance(ctx, RunResults):
        ph = ctx.phasing
        for lab in (ph.labels.values() if ph is not None else ()):
            if lab.channel == channel:
                return lab.times, lab.planet + 1
        on = ctx.onsets.by_channel.get(channel) if ctx.onsets is not None else None
        return None if on is None else (on.times, None)
    if isinstance(source, dict):
        v = source.get(channel)
        if v is None:
            return None
        if isinstance(v, tuple) and len(v) == 2:
            return np.asarray(v[0], dtype=float), np.asarray(v[1])
        return np.asarray(getattr(v, "times", v), dtype=float), None
    arr = np.asarray(source)
    if arr.dtype.kind not in "fiu" or arr.ndim != 1:
        raise TypeError("onsets must be an array of times [s], a dict channel -> times, a "
                        f"Result or a RunContext; got {type(source).__name__}")
    return arr.astype(float), None


def plot_channels(t, data, channels, onsets=None, *, ax=None, max_points: int = 20000):
    """Channels against time, one panel each, with onsets marked
    (:func:`plot_recording` cuts the window and channels of a Recording).

    Parameters
    ----------
    t : array_like, shape (n,)
        Sample times [s].
    data : array_like, shape (n, c)
        Samples, one column per channel, in the channels' units.
    channels : sequence of ChannelSpec
        One per column (name, kind, units).
    onsets : array_like, dict, Result or RunContext, optional
        Onset times to mark (:func:`onset_marks`); coloured by planet when labelled.
    ax : matplotlib Axes, optional
        Draw the single channel into it.
    max_points : int
        Samples drawn per channel at most (decimated by striding).

    Returns
    -------
    matplotlib.figure.Figure
    """
    t = np.asarray(t, dtype=float)
    data = np.asarray(data)
    if data.ndim != 2 or data.shape != (t.size, len(channels)) or not t.size:
        raise ValueError(f"data must be samples x channels matching t ({t.size}) and "
                         f"channels ({len(channels)}), got shape {data.shape}")
    fig, axes = _axes(len(channels), ax)
    for j, (a, c) in enumerate(zip(axes, channels)):
        marks = None if onsets is None else onset_marks(onsets, c.name)
        _signal_panel(a, t, data[:, j], c.units, f"{c.name} ({c.kind})", marks, max_points)
    axes[-1].set_xlabel("time [s]")
    fig.tight_layout()
    return fig


def plot_recording(rec, channels=None, start: float | None = None, stop: float | None = None,
                   onsets=None, *, ax=None, max_points: int = 20000):
    """Plot a recording's channels against time, one panel each, with onsets marked.

    Parameters
    ----------
    rec : meshphase.Recording
    channels : str or sequence of str, optional
        Channels to draw (default all).
    start, stop : float, optional
        Time window [s] (half-open; default the whole recording).
    onsets : array_like, dict, Result or RunContext, optional
        Onset times [s] to mark: one array for every channel, a dict channel -> times
        (or Onsets, or (times, 1-based planets)), or a :class:`meshphase.Result` (its
        onsets, coloured by planet).
    ax : matplotlib Axes, optional
        Draw a single channel into it.
    max_points : int
        Samples drawn per channel at most (decimated by striding).

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    TypeError
        ``rec`` is no Recording.
    ValueError
        An empty recording, unknown channels, a window holding no sample.
    """
    if not isinstance(rec, Recording):
        raise TypeError(f"rec must be a meshphase.Recording, got {type(rec).__name__}")
    if rec.n_samples == 0 or rec.n_channels == 0:
        raise ValueError("the recording is empty: nothing to plot")
    part = rec.select(channels).slice_time(start, stop)
    if part.n_samples == 0:
        raise ValueError(f"no samples in the window [{start}, {stop}) s")
    return plot_channels(part.times(), part.data, part.channels, onsets, ax=ax,
                         max_points=max_points)


def _gauges(ctx: RunResults, gauge, have) -> list[str]:
    """The gauges to draw: ``gauge`` or every one in ``have``; ValueError when none."""
    want = [g for g in _GAUGES if g in have and (gauge is None or g == gauge)]
    if not want:
        raise ValueError(f"nothing to plot: no {gauge or 'sun or ring'} gauge result in this run "
                         f"(stages ran: {', '.join(ctx.ran) or 'none'})")
    return want


def plot_result_onsets(ctx: RunResults, gauge=None, *, ax=None, revolutions: float = 2.0,
                       max_points: int = 20000):
    """The conditioned signal of each gauge (the first minute the run keeps) over about
    ``revolutions`` relative revolutions from its first onset, onsets coloured by planet."""
    cond = ctx.condition
    rec = None if cond is None else (cond.excerpt if cond.excerpt is not None else cond.recording)
    try:
        has_samples = rec is not None and rec.data is not None
    except TypeError:                     # a streamed recording's header holds no samples
        has_samples = False
    if not has_samples or ctx.onsets is None:
        raise ValueError("nothing to plot: this run kept no conditioned signal and onsets "
                         f"(stages ran: {', '.join(ctx.ran) or 'none'})")
    chans = {g: next((c.name for c in rec.channels if c.kind == g), None) for g in _GAUGES}
    want = _gauges(ctx, gauge, [g for g, c in chans.items() if c in ctx.onsets.by_channel])
    fig, axes = _axes(len(want), ax, sharex=False)
    n_pl = ctx.gearset.n_planets if ctx.gearset is not None else 4
    for a, g in zip(axes, want):
        ch = chans[g]
        on = ctx.onsets.by_channel[ch]
        span = (revolutions * n_pl * float(np.median(np.diff(on.times))) if len(on) > 2
                else rec.duration)
        t0 = max(rec.t0, float(on.times[0]) - 0.05 * span) if len(on) else rec.t0
        i0, i1 = rec.sample_range(t0, min(rec.t_end, t0 + span), strict=False)
        part = rec.slice_samples(i0, i1)
        _signal_panel(a, part.times(), part.channel(ch), rec.spec(ch).units,
                      f"{ch} ({g} gauge)", onset_marks(ctx, ch), max_points)
        a.set_xlabel("time [s]")
    fig.tight_layout()
    return fig


def _unwrap(y, ref):
    return ref + wrap(np.asarray(y, dtype=float) - ref)


def plot_phasing(ctx: RunResults, gauge=None, *, ax=None):
    """Measured phasing per pass against time, one colour per planet: error bars of one
    sigma, the ideal (dotted), the identified model (line) and the Monte Carlo band (shaded)
    [mesh cycles]; one panel per gauge."""
    tabs = {g: t for g, t in (ctx.phasing.tables.items() if ctx.phasing is not None else ())
            if len(t)}
    want = _gauges(ctx, gauge, tabs)
    fig, axes = _axes(len(want), ax, height=3.0)
    rows, per_planet = passes_rows(ctx), phasing_rows(ctx)
    for a, g in zip(axes, want):
        for s in (r for r in per_planet if r["gauge"] == g):
            p, col = s["planet"], _colour(s["planet"] - 1)
            ref = (s["gamma_ideal_cycles"] if np.isfinite(s["gamma_ideal_cycles"])
                   else s["gamma_mean_cycles"])
            d = [r for r in rows if r["gauge"] == g and r["planet"] == p]
            t = np.array([r["time_s"] for r in d])
            a.errorbar(t, _unwrap([r["gamma_cycles"] for r in d], ref),
                       yerr=np.nan_to_num([r["uncertainty_cycles"] for r in d]), fmt="o", ms=3,
                       lw=0.6, color=col, label=f"planet {p}")
            if np.isfinite(s["gamma_ideal_cycles"]):
                a.axhline(s["gamma_ideal_cycles"], color=col, lw=0.8, ls=":")
            model = np.array([r["gamma_model_cycles"] for r in d])
            if np.isfinite(model).any():
                a.plot(t, _unwrap(model, ref), color=col, lw=1.2)
            if np.isfinite(s["band_dev_lo_cycles"]) and np.isfinite(s["gamma_ideal_cycles"]):
                a.axhspan(s["gamma_ideal_cycles"] + s["band_dev_lo_cycles"],
                          s["gamma_ideal_cycles"] + s["band_dev_hi_cycles"], color=col,
                          alpha=0.12)
        a.set_ylabel(f"{g} phasing [mesh cycles]")
        a.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.005, 1.0), borderaxespad=0.0)
    axes[-1].set_xlabel("time [s]")
    fig.tight_layout()
    return fig


def plot_residuals(ctx: RunResults, gauge=None, *, ax=None):
    """Measured - model phasing per pass (measured - ideal where no model was identified)
    [mesh cycles] against time, one colour per planet, one panel per gauge."""
    rows = passes_rows(ctx)
    want = _gauges(ctx, gauge, {r["gauge"] for r in rows})
    fig, axes = _axes(len(want), ax)
    for a, g in zip(axes, want):
        d = [r for r in rows if r["gauge"] == g]
        has_model = any(np.isfinite(r["residual_model_cycles"]) for r in d)
        key = "residual_model_cycles" if has_model else "residual_ideal_cycles"
        for p in sorted({r["planet"] for r in d}):
            dp = [r for r in d if r["planet"] == p]
            a.plot([r["time_s"] for r in dp], [r[key] for r in dp], "o", ms=3,
                   color=_colour(p - 1), label=f"planet {p}")
        a.axhline(0.0, color="k", lw=0.8)
        a.set_ylabel(f"{g} - {'model' if has_model else 'ideal'} [mesh cycles]")
        a.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.005, 1.0), borderaxespad=0.0)
    axes[-1].set_xlabel("time [s]")
    fig.tight_layout()
    return fig


def plot_load_sharing(ctx: RunResults, *, ax=None):
    """Load-sharing factor per planet [-] with its standard error; 1 is equal sharing."""
    rows = load_sharing_rows(ctx)
    if not rows:
        raise ValueError("nothing to plot: this run has no load sharing (it needs a ring gauge; "
                         f"stages ran: {', '.join(ctx.ran) or 'none'})")
    if ax is None:
        fig, ax = plt.subplots(figsize=(5.5, 3.0))
    x = np.array([r["planet"] for r in rows])
    ax.bar(x, [r["load_sharing"] for r in rows], width=0.6, color=_colour(0),
           yerr=np.nan_to_num([r["std_error"] for r in rows]), capsize=3)
    ax.axhline(1.0, color="k", lw=0.8, ls=":")
    ax.set_xticks(x)
    ax.set_xlabel("planet")
    ax.set_ylabel("load sharing factor [-]")
    ax.figure.tight_layout()
    return ax.figure
