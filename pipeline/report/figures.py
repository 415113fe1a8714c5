"""Figures of the validation report (matplotlib, Agg backend, no display needed).

Every function takes plain arrays / tables and returns a matplotlib Figure; the caller embeds
it (:meth:`meshphase.report.html.Section.figure`) or saves it. Units on every axis.
"""

from __future__ import annotations

import math

import matplotlib
import matplotlib.ticker

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

__all__ = [
    "signal_with_onsets",
    "phasing_over_time",
    "residual_histograms",
    "load_sharing_bars",
    "bearing_moments_bars",
    "stage_times",
    "error_vs_runtime",
    "quality_overview",
    "tacho_geometry",
    "angle_model_residuals",
]

_COLORS = plt.rcParams["axes.prop_cycle"].by_key()["color"]


def _c(i: int) -> str:
    return _COLORS[i % len(_COLORS)]


def signal_with_onsets(t, x, onset_times, planets=None, *, title="", units="µε", scale=1e6,
                       max_points: int = 20000):
    """A stretch of one gauge's signal with its detected onsets marked, coloured by planet.

    Parameters
    ----------
    t, x : array_like
        Sample times [s] and samples [strain m/m] (scaled by ``scale`` for display).
    onset_times : array_like
        Onset times [s].
    planets : array_like of int, optional
        1-based planet number per onset (0 or -1: unassigned).
    """
    t = np.asarray(t)
    x = np.asarray(x) * scale
    step = max(1, t.size // max_points)
    fig, ax = plt.subplots(figsize=(10, 3.2))
    ax.plot(t[::step], x[::step], lw=0.6, color="0.3")
    on = np.asarray(onset_times)
    pl = np.zeros(on.size, int) if planets is None else np.asarray(planets)
    lo, hi = np.nanmin(x) if x.size else 0, np.nanmax(x) if x.size else 1
    for p in np.unique(pl):
        m = pl == p
        label = f"planet {p}" if p > 0 else "unassigned"
        ax.vlines(on[m], lo, hi, colors=_c(int(p) - 1) if p > 0 else "k", lw=0.8, alpha=0.8,
                  label=label, linestyles="-" if p > 0 else ":")
    ax.set_xlabel("time [s]")
    ax.set_ylabel(f"strain [{units}]")
    ax.set_title(title)
    if on.size:
        # outside the axes: the onset marks span the full height and a legend inside hides them
        ax.legend(loc="upper left", bbox_to_anchor=(1.005, 1.0), fontsize=8, borderaxespad=0.0)
    fig.tight_layout()
    return fig


def phasing_over_time(tables: dict, *, predicted: dict | None = None, bands: dict | None = None,
                      ideal: dict | None = None, title: str = ""):
    """Measured vs predicted phasing over time, one panel per gauge, one colour per planet.

    Parameters
    ----------
    tables : dict gauge -> DataFrame or dict of arrays
        Measured passes with columns time_s [s], planet, gamma [mesh cycles] and
        uncertainty [mesh cycles] (NaN: no error bar), e.g.
        :meth:`meshphase.kinematics.pass_table.PassTable.columns`.
    predicted : dict gauge -> dict planet -> (t [s], gamma [-])
        Model curves (e.g. shaft-hole-error model with identified errors).
    bands : dict gauge -> dict planet -> (lo, hi)
        Monte Carlo 3-sigma band of gamma [-] per planet (constant over time).
    ideal : dict gauge -> dict planet -> gamma
        Ideal phasing (spec section 1) [-].
    """
    gauges = [g for g in ("sun", "ring") if g in tables]
    fig, axes = plt.subplots(len(gauges) or 1, 1, figsize=(10, 3.2 * max(1, len(gauges))),
                             squeeze=False)
    for ax, g in zip(axes[:, 0], gauges):
        planet = np.asarray(tables[g]["planet"])
        time_s, gamma, unc = (np.asarray(tables[g][c], dtype=float) for c in ("time_s", "gamma", "uncertainty"))
        for p in np.unique(planet):
            m = planet == p
            col = _c(int(p) - 1)
            ref = ideal[g][p] if ideal and g in ideal and p in ideal[g] else None
            if ref is not None:
                # unwrap around the ideal value so 0.99 and 0.01 sit together
                y = ref + ((gamma[m] - ref + 0.5) % 1.0 - 0.5)
                ax.axhline(ref, color=col, lw=0.8, ls=":")
            else:
                y = gamma[m]
            ax.errorbar(time_s[m], y, yerr=np.where(np.isnan(unc[m]), 0.0, unc[m]), fmt="o", ms=2.5,
                        color=col, lw=0.6, label=f"planet {p}")
            if bands and g in bands and p in bands[g]:
                lo, hi = bands[g][p]
                ax.axhspan(lo, hi, color=col, alpha=0.12)
            if predicted and g in predicted and p in predicted[g]:
                tt, gg = predicted[g][p]
                gg = np.asarray(gg)
                if ref is not None:
                    gg = ref + ((gg - ref + 0.5) % 1.0 - 0.5)
                ax.plot(tt, gg, color=col, lw=1.2)
        ax.set_ylabel(f"gamma_{g[0]}n [mesh cycles]")
        ax.set_title(f"{g} gauge" + (f" — {title}" if title else ""), fontsize=10)
        ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.005, 1.0), borderaxespad=0.0)
    axes[-1, 0].set_xlabel("time [s]")
    fig.tight_layout()
    return fig


def residual_histograms(residuals: dict, *, title: str = "residuals: measured - predicted"):
    """Histograms of phasing residuals [mesh cycles] per gauge (dict gauge -> array)."""
    n = max(1, len(residuals))
    # at most two panels per row: four side by side shrink to unreadable text in the report
    ncol = min(n, 2)
    nrow = math.ceil(n / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(5 * ncol, 2.8 * nrow + 0.4), squeeze=False)
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    for ax, (g, r) in zip(axes.ravel(), residuals.items()):
        r = np.asarray(r, dtype=float)
        r = r[np.isfinite(r)]
        if r.size:
            ax.hist(r, bins=min(60, max(10, int(math.sqrt(r.size)))), color=_c(0), alpha=0.8)
            ax.axvline(0, color="k", lw=0.8)
            ax.set_title(f"{g}: RMS {np.sqrt(np.mean(r ** 2)):.2e}, n={r.size}", fontsize=10)
            ax.yaxis.set_major_locator(matplotlib.ticker.MaxNLocator(integer=True))  # counts
        else:
            ax.set_title(f"{g}: no residuals", fontsize=10)
        ax.set_xlabel("residual [mesh cycles]")
    for ax in axes[:, 0]:
        ax.set_ylabel("passes")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


def load_sharing_bars(ls_measured, ls_true=None, ls_unc=None):
    """Load-sharing factor per planet [-] (1 = equal), measured vs true/model."""
    ls = np.asarray(ls_measured, dtype=float)
    x = np.arange(1, ls.size + 1)
    fig, ax = plt.subplots(figsize=(5.5, 3))
    w = 0.38 if ls_true is not None else 0.6
    ax.bar(x - (w / 2 if ls_true is not None else 0), ls, width=w, color=_c(0), label="measured",
           yerr=None if ls_unc is None else np.asarray(ls_unc), capsize=3)
    if ls_true is not None:
        ax.bar(x + w / 2, np.asarray(ls_true, dtype=float), width=w, color=_c(1), label="truth/model")
    ax.axhline(1.0, color="k", lw=0.8, ls=":")
    ax.set_xticks(x)
    ax.set_xlabel("planet")
    ax.set_ylabel("load sharing factor [-]")
    lo = min(0.8, float(np.nanmin(ls)) - 0.05) if ls.size else 0.8
    ax.set_ylim(lo, max(1.2, float(np.nanmax(ls)) + 0.05) if ls.size else 1.2)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def bearing_moments_bars(labels, series: dict, *, ylabel="moment [N·m]", title=""):
    """Grouped bars: one group per label (e.g. M_LOA sun / ring), one bar per series."""
    x = np.arange(len(labels))
    k = max(1, len(series))
    w = 0.8 / k
    fig, ax = plt.subplots(figsize=(max(5, 1.4 * len(labels) + 2), 3.2))
    for i, (name, vals) in enumerate(series.items()):
        ax.bar(x - 0.4 + w * (i + 0.5), np.asarray(vals, dtype=float), width=w, label=name, color=_c(i))
    ax.axhline(0, color="k", lw=0.8)
    ax.set_xticks(x)
    ax.set_xticklabels(labels, fontsize=8)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def stage_times(names, seconds, errors=None):
    """Horizontal bars of each stage's wall time [s], annotated with its error estimate."""
    s = np.asarray(seconds, dtype=float)
    h = 0.4 * len(names) + 1.0
    fig, ax = plt.subplots(figsize=(4.5, h))
    y = np.arange(len(names))
    ax.barh(y, s, color=_c(0))
    ax.set_yticks(y)
    ax.set_yticklabels(names, fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel("wall time [s]")
    if errors is not None:
        # one aligned column right of the axes (text at the bar ends crosses the frame); the
        # axes keep their size (no tight_layout, which would shrink them to fit the text) and
        # the saved figure grows to the text (figure_to_png saves with bbox_inches="tight")
        for yi, e in zip(y, errors):
            if e:
                ax.text(1.03, yi, e, va="center", fontsize=7, transform=ax.get_yaxis_transform())
        fig.subplots_adjust(left=0.3, right=0.95, bottom=0.7 / h, top=1 - 0.2 / h)
    else:
        fig.tight_layout()
    return fig


def error_vs_runtime(curves: dict, *, xlabel="wall time [s]", ylabel="error", title=""):
    """Log-log error against run time, one curve per method (dict name -> (time, error))."""
    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    for i, (name, (tm, err)) in enumerate(curves.items()):
        tm, err = np.asarray(tm, float), np.asarray(err, float)
        ok = (tm > 0) & (err > 0)
        ax.loglog(tm[ok], err[ok], "o-", color=_c(i), label=name, ms=4)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def quality_overview(rows):
    """Per channel bar chart of non-finite samples and clipped runs (rows: dicts from a
    quality report with keys channel, n_nonfinite, n_clipped_runs)."""
    names = [r["channel"] for r in rows]
    nf = [r.get("n_nonfinite", 0) for r in rows]
    cl = [r.get("n_clipped_runs", 0) for r in rows]
    fig, ax = plt.subplots(figsize=(max(5, 0.9 * len(names) + 2), 2.8))
    x = np.arange(len(names))
    ax.bar(x - 0.2, nf, width=0.4, label="NaN/gap samples", color=_c(3))
    ax.bar(x + 0.2, cl, width=0.4, label="clipped runs", color=_c(1))
    ax.set_xticks(x)
    ax.set_xticklabels(names, fontsize=8, rotation=20)
    ax.set_ylabel("count")
    ax.set_ylim(0, max([1, *nf, *cl]) * 1.1)   # counts: never a negative axis
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def tacho_geometry(planet_angles, key_angle: float, mounts: dict | None = None, *,
                   carrier_angle: float = math.radians(30.0), title: str = ""):
    """The geometry that names planet 1 from a carrier tacho (``data_schemas/scene.md``).

    Ground frame, counter-clockwise positive, angle 0 at the tacho probe. Planet n sits at
    carrier-frame angle psi_n (planet 1 at 0), the key at carrier-frame angle ``key_angle``;
    the carrier is drawn turned by ``carrier_angle``. Each gauge on the held ring is drawn at
    its ground angle (``mounts``: name -> [rad]).

    Parameters
    ----------
    planet_angles : array_like
        psi_n [rad].
    key_angle : float
        Carrier-frame angle of the tacho key from planet 1 [rad].
    mounts : dict of str to float, optional
        Ground angles of gauges on the held member [rad].
    carrier_angle : float
        Carrier angle theta_c at which to draw [rad].
    """
    psi = np.asarray(planet_angles, dtype=float)
    fig, ax = plt.subplots(figsize=(6.4, 6.0))
    ax.set_aspect("equal")
    ax.axis("off")
    th = np.linspace(0, 2 * math.pi, 361)
    ax.plot(1.55 * np.cos(th), 1.55 * np.sin(th), color="0.6", lw=8, alpha=0.5)
    ax.text(-2.0, -1.95, "held ring (ground frame)", color="0.4", fontsize=8)
    ax.plot(np.cos(th), np.sin(th), color=_c(2), lw=1.2, ls="--")
    ax.add_patch(plt.Circle((0, 0), 0.33, fc="0.93", ec="0.2"))
    ax.text(0, 0, "sun", ha="center", va="center")
    for i, p in enumerate(psi):
        a = carrier_angle + p
        ax.add_patch(plt.Circle((math.cos(a), math.sin(a)), 0.45, fc="#fdf2d0" if i == 0 else "white",
                                ec="0.2", lw=1.5 if i == 0 else 1.0))
        ax.text(math.cos(a), math.sin(a), f"planet {i + 1}\nψ={math.degrees(p):.0f}°", ha="center",
                va="center", fontsize=8, fontweight="bold" if i == 0 else "normal")
    # the probe at ground angle 0, the key on the carrier
    ax.plot([0, 1.85], [0, 0], color="0.3", ls=":", lw=1)
    ax.add_patch(plt.Rectangle((1.72, -0.07), 0.2, 0.14, color="#c33"))
    ax.text(1.72, -0.2, "tacho probe\n(ground 0°)", color="#c33", fontsize=8, va="top")
    ka = carrier_angle + key_angle
    ax.plot([0, 1.08 * math.cos(ka)], [0, 1.08 * math.sin(ka)], color="#c33", lw=1)
    ax.plot(1.08 * math.cos(ka), 1.08 * math.sin(ka), "s", color="#c33", ms=8)
    ax.text(1.2 * math.cos(ka), 1.2 * math.sin(ka), f"tacho key\nkey_angle_deg = {math.degrees(key_angle):.1f}",
            color="#c33", fontsize=8, ha="center", va="center")
    arc = np.linspace(0, carrier_angle, 40)
    ax.plot(0.62 * np.cos(arc), 0.62 * np.sin(arc), color=_c(2), lw=1.5)
    ax.text(0.7 * math.cos(carrier_angle / 2), 0.7 * math.sin(carrier_angle / 2), "θc", color=_c(2))
    for name, mu in (mounts or {}).items():
        ax.plot(1.55 * math.cos(mu), 1.55 * math.sin(mu), "D", color=_c(0), ms=9)
        ax.text(1.75 * math.cos(mu), 1.75 * math.sin(mu),
                f"{name}\nmount_angle_deg = {math.degrees(mu):.1f}", color=_c(0), fontsize=8,
                ha="center", va="center")
    ax.set_xlim(-2.1, 2.3)
    ax.set_ylim(-2.1, 2.1)
    ax.set_title(title or "tacho edge: the key passes the probe, θc = -key_angle\nplanet n meets "
                 "a gauge on the held ring when θc + ψn = mount_angle (mod 360°)", fontsize=9)
    fig.tight_layout()
    return fig


def angle_model_residuals(series: dict, *, title: str = ""):
    """Residuals of the angle model per pass train against time.

    Parameters
    ----------
    series : dict of str to (ndarray, ndarray)
        Train name -> (times [s], residuals [mesh cycles]).
    """
    fig, ax = plt.subplots(figsize=(7.0, 3.2))
    for i, (name, (t, r)) in enumerate(series.items()):
        t, r = np.asarray(t, float), np.asarray(r, float)
        ax.plot(t, r * 1e3, ".", ms=3, color=_c(i), label=name)
    ax.axhline(0.0, color="0.5", lw=0.8)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("residual [1e-3 mesh cycles]")
    ax.set_title(title or "angle model residuals", fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, markerscale=3)
    fig.tight_layout()
    return fig
