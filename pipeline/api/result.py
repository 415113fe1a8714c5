"""The result of :func:`meshphase.process`: a run's typed stage results as pandas DataFrames
(the names and SI units of the CSV files a run writes; ``df.attrs["units"]`` maps each
column to its unit), a short summary, plots, HTML for notebooks, and the usual output files.

The tables come from :mod:`meshphase.report.frames`, the plots from
:mod:`meshphase.report.notebook` (matplotlib, imported only when plotting), the files from
:func:`meshphase.run.outputs.write_outputs`. :attr:`Result.context` is the
:class:`~meshphase.run.results.RunContext` itself (``.phasing``, ``.compare``, ...).
"""

from __future__ import annotations

import html
import math
import os
import warnings

from ..report import frames as rf
from ..html_repr import html_table
from ..run.exits import run_status
from ..run.context import RunContext, phasing_verdict
from ..run.outdir import OutputDir
from ..run.outputs import write_outputs
from ..run.state import failure_texts

__all__ = ["Result", "Summary", "PLOT_KINDS", "run_html"]

#: what :meth:`Result.plot` draws
PLOT_KINDS = ("phasing", "onsets", "load_sharing", "residuals")


class Result:
    """What a run computed, for a notebook.

    Parameters
    ----------
    context : RunContext
        A finished run (:func:`meshphase.run.stages.run_scene`).

    Attributes
    ----------
    context : RunContext
        The run: typed stage results (``context.phasing``, ``context.compare`` ...).
    """

    def __init__(self, context: RunContext):
        if not isinstance(context, RunContext):
            raise TypeError(f"context must be a RunContext (meshphase.run.stages.run_scene), got "
                            f"{type(context).__name__}")
        self.context = context

    # ------------------------------------------------------------------ state
    @property
    def status(self) -> str:
        """"ok", "partial", "unreliable" or "failed" (:func:`meshphase.run.exits.run_status`)."""
        return run_status(self.context)["status"]

    @property
    def messages(self) -> list[str]:
        """The run's warnings ("stage: Category: message")."""
        return list(self.context.messages)

    # ------------------------------------------------------------------ tables
    # Each table is a meshphase.report.frames.ResultFrame: attrs["units"] (column -> unit),
    # attrs["description"], attrs["file"] (the CSV with the same columns, or None).
    @property
    def passes(self):
        """Per pass: the columns of passes_<gear>.csv (gauge, time_s, planet, revolution,
        gamma_cycles, uncertainty_cycles, ..., gamma_ideal_cycles, gamma_model_cycles), then
        the residuals against the ideal and the model [mesh cycles]
        (:func:`meshphase.report.frames.passes_rows`)."""
        return rf.frame(rf.passes_rows(self.context), "passes")

    @property
    def phasing(self):
        """Per gauge and planet: gamma_mean_cycles, gamma_std_cycles, ideal, model, residuals,
        band [mesh cycles] (:func:`meshphase.report.frames.phasing_rows`)."""
        return rf.frame(rf.phasing_rows(self.context), "phasing")

    @property
    def load_sharing(self):
        """Per planet: the columns of load_sharing.csv: load-sharing factor and its standard
        error [-], passes used, mean peak strain [m/m]
        (:func:`meshphase.report.frames.load_sharing_rows`)."""
        return rf.frame(rf.load_sharing_rows(self.context), "load_sharing")

    @property
    def comparison(self):
        """Per gauge and reference (ideal, model, truth): residual statistics [mesh cycles]
        and the share of passes inside the Monte Carlo band
        (:func:`meshphase.report.frames.comparison_rows`)."""
        return rf.frame(rf.comparison_rows(self.context), "comparison")

    @property
    def identification(self):
        """Per gear: the columns of identified_errors.csv: identified shaft hole error [m] and
        angle [rad] with uncertainties, and what would identify it
        (:func:`meshphase.report.frames.identification_rows`)."""
        return rf.frame(rf.identification_rows(self.context), "identification")

    @property
    def centroids(self):
        """Per gear with face-width gauges: load centroid [m] and its standard error [m]
        (:func:`meshphase.report.frames.centroid_rows`); no rows without face-width gauges."""
        return rf.frame(rf.centroid_rows(self.context), "centroids")

    # ------------------------------------------------------------------ summary
    def summary(self) -> "Summary":
        """Status and key numbers, one level deep (``pandas.Series(res.summary())`` shows it).

        Per-gauge keys are named as campaign.csv names them (``<quantity>_<gauge>[_<unit>]``).

        Returns
        -------
        Summary
            A dict: ``status``, ``error``, ``source``, ``duration_s``, ``fs_hz``,
            ``held_member``, ``n_messages``, ``stages_failed``; per gauge ``passes_<gauge>``,
            ``reliable_<gauge>``, ``error_estimate_<gauge>_cycles`` (per-pass error estimate),
            ``planet1_by_<gauge>``, ``rms_vs_ideal_<gauge>_cycles``,
            ``rms_vs_model_<gauge>_cycles``; ``load_sharing_max_dev`` (max |LS_n - 1|);
            ``identify_rms_before_cycles``, ``identify_rms_after_cycles``. A key of the
            previous release (``<gauge>_passes``, ``<gauge>_sigma_cycles``, ...,
            :data:`Summary.RENAMED`) is answered with a FutureWarning.
        """
        ctx = self.context
        st = run_status(ctx)
        out = Summary(status=st["status"], error=st["error"])
        if ctx.load is not None:
            rec = ctx.load.recording
            out.update(source=str(ctx.load.source), duration_s=rec.duration, fs_hz=rec.fs)
        ph = ctx.phasing
        if ph is not None:
            out["held_member"] = ph.fixed or "none"
        out["n_messages"] = len(ctx.messages)
        out["stages_failed"] = ", ".join(f"{k} ({v})" for k, v in failure_texts(ctx.failed).items())
        verdict = phasing_verdict(ph, ctx.messages)
        rel = (ph.reliability or {}) if ph is not None else {}
        for gauge, t in (ph.tables.items() if ph is not None else ()):
            out[f"passes_{gauge}"] = len(t)
            out[f"reliable_{gauge}"] = verdict.get(gauge, {}).get("reliable", True)
            out[f"error_estimate_{gauge}_cycles"] = float(rel.get(gauge, {}).get("error_estimate",
                                                                                 math.nan))
            lab = ph.labels.get(gauge)
            out[f"planet1_by_{gauge}"] = lab.decided_by if lab is not None else ""
            c = ctx.compare.by_gear.get(gauge) if ctx.compare is not None else None
            out[f"rms_vs_ideal_{gauge}_cycles"] = c.vs_ideal["rms"] if c else math.nan
            out[f"rms_vs_model_{gauge}_cycles"] = (c.vs_model["rms"] if c and c.vs_model
                                                   else math.nan)
        ls = rf.load_sharing_rows(ctx)
        if ls:
            dev = [abs(r["load_sharing"] - 1.0) for r in ls if math.isfinite(r["load_sharing"])]
            out["load_sharing_max_dev"] = max(dev) if dev else math.nan
        if ctx.identify is not None:
            ident = ctx.identify.identification
            out["identify_rms_before_cycles"] = ident.rms_before
            out["identify_rms_after_cycles"] = ident.rms_after
        return out

    # ------------------------------------------------------------------ plots, files
    def plot(self, kind: str = "phasing", *, gauge: str | None = None, ax=None, **kwargs):
        """Plot one view of the result (matplotlib, imported now).

        Parameters
        ----------
        kind : {"phasing", "onsets", "load_sharing", "residuals"}
            "phasing": measured phasing per pass against time, one colour per planet, with
            the ideal (dotted) and the identified model (line), one panel per gauge;
            "onsets": the conditioned signal's first stretch with the onsets marked, coloured
            by planet, one panel per gauge; "load_sharing": factor per planet with its
            standard error; "residuals": measured - model (else - ideal) per pass [mesh
            cycles] against time.
        gauge : {"sun", "ring"}, optional
            Only this gauge ("phasing", "onsets", "residuals").
        ax : matplotlib Axes, optional
            Draw into it (one gauge, or "load_sharing"); default a new figure.
        **kwargs
            Passed to the plot function of :mod:`meshphase.report.notebook`.

        Returns
        -------
        matplotlib.figure.Figure
        """
        if not isinstance(kind, str) or kind not in PLOT_KINDS:
            raise ValueError(f"kind must be one of {', '.join(PLOT_KINDS)}, got {kind!r}")
        if gauge is not None and gauge not in ("sun", "ring"):
            raise ValueError(f"gauge must be 'sun', 'ring' or None, got {gauge!r}")
        from ..report import notebook  # matplotlib: only when plotting

        fn = {"phasing": notebook.plot_phasing, "onsets": notebook.plot_result_onsets,
              "load_sharing": notebook.plot_load_sharing,
              "residuals": notebook.plot_residuals}[kind]
        if kind == "load_sharing":
            return fn(self.context, ax=ax, **kwargs)
        return fn(self.context, gauge=gauge, ax=ax, **kwargs)

    def write(self, folder, *, report: bool = True, overwrite: bool = False) -> dict:
        """Write summary.json, the CSV tables, arrays.h5 and (``report``) report.html into
        ``folder``, as ``meshphase process`` does (:func:`meshphase.run.outputs.write_outputs`).

        The folder is put in place whole (:class:`meshphase.run.outdir.OutputDir`); an existing
        one is kept and ``folder-2``, ... is used unless ``overwrite``.

        Returns
        -------
        dict
            Name -> path of each file written.
        """
        if not isinstance(folder, (str, os.PathLike)):
            raise TypeError(f"folder must be a path, got {type(folder).__name__}")
        with OutputDir(folder, overwrite=overwrite, staged=True) as out:
            written = write_outputs(self.context, out.path, report=report)
            return {k: out.published(v) for k, v in written.items()}

    # ------------------------------------------------------------------ display
    def __repr__(self) -> str:
        ctx = self.context
        src = f", {ctx.load.source}" if ctx.load is not None else ""
        gauges = ", ".join(f"{g}: {len(t)} passes" for g, t in
                           (ctx.phasing.tables.items() if ctx.phasing is not None else ()))
        return f"Result({self.status}{src}{'; ' + gauges if gauges else ''})"

    def _repr_html_(self) -> str:
        return run_html(self.context, run_status(self.context))


class Summary(dict):
    """:meth:`Result.summary`: a plain dict of its current keys that answers a key of the
    previous release (``<gauge>_passes`` ... , :data:`RENAMED`) for one release, by item
    access and ``get``, with a FutureWarning naming the current key; ``in``, iteration,
    ``keys()`` and ``json.dumps`` see the current keys only."""

    #: key of the previous release, ``{gauge}`` for the gauge -> the current key
    RENAMED = {"{gauge}_passes": "passes_{gauge}", "{gauge}_reliable": "reliable_{gauge}",
               "{gauge}_sigma_cycles": "error_estimate_{gauge}_cycles",
               "{gauge}_planet1_by": "planet1_by_{gauge}",
               "{gauge}_rms_vs_ideal_cycles": "rms_vs_ideal_{gauge}_cycles",
               "{gauge}_rms_vs_model_cycles": "rms_vs_model_{gauge}_cycles"}

    def _current(self, key):
        if not isinstance(key, str):
            return None
        for gauge in ("sun", "ring"):
            for old, new in self.RENAMED.items():
                if key == old.format(gauge=gauge):
                    return new.format(gauge=gauge)
        return None

    def __missing__(self, key):
        new = self._current(key)
        if new is None or new not in self:
            raise KeyError(key)
        warnings.warn(f"summary key {key!r} is now {new!r} (as campaign.csv names it); the old "
                      f"key goes in meshphase 0.2", FutureWarning, stacklevel=3)
        return self[new]

    def get(self, key, default=None):
        """``self[key]`` (a key of the previous release too, with a FutureWarning), else
        ``default``."""
        if key in self:
            return dict.__getitem__(self, key)
        new = self._current(key)
        if new is None or new not in self:
            return default
        warnings.warn(f"summary key {key!r} is now {new!r} (as campaign.csv names it); the old "
                      f"key goes in meshphase 0.2", FutureWarning, stacklevel=2)
        return dict.__getitem__(self, new)


def run_html(ctx, status: dict) -> str:
    """A run's status, input and per-planet phasing (and load sharing), as HTML.

    Parameters
    ----------
    ctx : RunContext
    status : dict
        :func:`meshphase.run.exits.run_status` of ``ctx``.
    """
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
    rows = rf.phasing_rows(ctx)
    if rows:
        parts.append(html_table(rows, ["gauge", "planet", "n_passes", "gamma_mean_cycles",
                                       "gamma_std_cycles", "gamma_ideal_cycles",
                                       "gamma_model_cycles", "residual_model_rms_cycles"],
                                caption="Measured phasing per planet [mesh cycles]"))
    ls = rf.load_sharing_rows(ctx)
    if ls:
        parts.append(html_table(ls, ["planet", "load_sharing", "std_error", "n_passes"],
                                caption="Load sharing [-]"))
    if ctx.messages:
        parts.append(f"<p>{len(ctx.messages)} message(s): see <code>.messages</code></p>")
    return "".join(parts)
