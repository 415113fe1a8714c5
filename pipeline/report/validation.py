"""The validation report of a scene run: one static HTML file with embedded figures.

Sections appear only for what the run computed (a result that was not computed is not
shown): recording quality, onsets over the signal, measured vs predicted phasing with the
Monte Carlo band, residual histograms, identified errors, load sharing, centroids, bearing
moments (with seed 001's GSAM table side by side for that gearset), tilt solve, and "error
against run time" with each stage's wall time and error estimate. Each section is built by
its own function from the run's typed stage results (:mod:`meshphase.run.results`).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..io.channels import mapping_report
from ..compare.predict import RECORD_FACTORS, identification_verdict, wrap
from ..models.bearing import BearingMoments
from ..models.tilt import TABLE11_THEORY, table10_cases, table11_cases
from . import figures
from .html import Report, figure_to_png

__all__ = ["build_report", "SECTION_KEYS"]


def _f(x, unit="", scale=1.0, fmt="{:.4g}"):
    try:
        v = float(x) * scale
    except (TypeError, ValueError):
        return str(x)
    return "–" if not math.isfinite(v) else fmt.format(v) + (f" {unit}" if unit else "")


#: the double-pinion meshes in seed 001 Table 11 order
_DP_MESHES = ("sun-SP", "SP-RP", "RP-SP", "RP-ring")


def _columns(rows) -> list:
    """Union of the rows' keys in first-seen order (rows may carry different columns)."""
    return list(dict.fromkeys(k for row in rows for k in row))


class _Figures:
    """Adds a figure to a section and writes its PNG into ``figures/`` beside the report."""

    def __init__(self, fig_dir: Path):
        self.dir = fig_dir

    def add(self, section, fig, name: str, caption: str) -> None:
        png = figure_to_png(fig)
        (self.dir / f"{name}.png").write_bytes(png)
        section.figure(png, caption)


def build_report(ctx, out_dir) -> Path:
    """Write ``report.html`` (and the PNG figures beside it) for a finished run."""
    out_dir = Path(out_dir)
    scene = ctx.scene
    sub = f"scene {scene.path.name if scene.path else scene.name}"
    if ctx.load is not None:
        sub += f" · input {ctx.load.source}"
    rep = Report(f"meshphase validation — {scene.name}", sub)
    fig_dir = out_dir / "figures"
    fig_dir.mkdir(exist_ok=True)
    figs = _Figures(fig_dir)
    _summary_section(rep, ctx)
    for _, write in _SECTIONS:
        write(rep, ctx, figs)
    _runtime_section(rep, ctx, figs)
    return rep.write(out_dir / "report.html")


def _recording_part(rep: Report, ctx, figs: _Figures) -> None:
    if ctx.load is not None:
        _recording_section(rep, ctx, figs)
        if ctx.scene.channels:
            _channel_map_section(rep, ctx)


def _onsets_part(rep: Report, ctx, figs: _Figures) -> None:
    if ctx.onsets is not None:
        _onsets_section(rep, ctx, figs)


def _ideal_part(rep: Report, ctx, figs: _Figures) -> None:
    if ctx.ideal is not None:
        _ideal_section(rep, ctx.ideal)


def _phasing_part(rep: Report, ctx, figs: _Figures) -> None:
    if ctx.phasing is not None and ctx.phasing.tables:
        _phasing_section(rep, ctx, figs)


def _identify_part(rep: Report, ctx, figs: _Figures) -> None:
    if ctx.identify is not None:
        _identify_section(rep, ctx)


def _load_sharing_part(rep: Report, ctx, figs: _Figures) -> None:
    if ctx.load_sharing is not None and ctx.load_sharing.sharing is not None:
        _load_sharing_section(rep, ctx, figs)


def _centroids_part(rep: Report, ctx, figs: _Figures) -> None:
    if ctx.centroids is not None and ctx.centroids.by_gear:
        _centroids_section(rep, ctx.centroids)


def _bearing_part(rep: Report, ctx, figs: _Figures) -> None:
    if ctx.bearing_moments is not None:
        _bearing_section(rep, ctx.bearing_moments)


def _tilt_part(rep: Report, ctx, figs: _Figures) -> None:
    if ctx.tilt is not None:
        _tilt_section(rep, ctx.tilt, figs)


#: the sections between the summary and "error against run time", in report order: section
#: key (a stage declaration's ``report``, :data:`meshphase.run.declare.STAGE_REGISTRY`) ->
#: its writer, which writes it when the run computed something for it
_SECTIONS = (("recording", _recording_part), ("onsets", _onsets_part), ("ideal", _ideal_part),
             ("phasing", _phasing_part), ("identify", _identify_part),
             ("load_sharing", _load_sharing_part), ("centroids", _centroids_part),
             ("bearing_moments", _bearing_part), ("tilt", _tilt_part))
#: the report's section keys, in report order
SECTION_KEYS: tuple[str, ...] = tuple(k for k, _ in _SECTIONS)


def _summary_section(rep: Report, ctx) -> None:
    s = rep.section("Summary")
    speeds = ctx.phasing.member_speeds if ctx.phasing is not None else None
    if ctx.identify is not None or speeds:
        s.text(identification_verdict(
            ctx.identify.identification if ctx.identify is not None else None, speeds),
            cls="verdict")
    s.text(f"Results requested: {', '.join(ctx.scene.results)}. Stages run: {', '.join(ctx.ran)}.")
    if ctx.failed:
        for k, v in ctx.failed.items():
            s.warning(f"stage {k}: {v}")          # a StageFailure says itself
    if ctx.messages:
        s.heading("Warnings raised")
        s.table([{"message": m} for m in ctx.messages[:40]])


def _recording_section(rep: Report, ctx, figs: _Figures) -> None:
    rec = ctx.load.recording
    s = rep.section("Recording and its quality")
    s.text(f"{rec.n_channels} channels at {rec.fs:g} Hz, {rec.duration:.1f} s "
           f"({rec.n_samples} samples per channel).")
    q = ctx.load.quality
    # a tacho or an encoder is a pulse train that sits at its two levels by design:
    # "clipped" runs there are its pulses, not converter saturation, so they are neither
    # counted nor plotted
    pulse = {c.name for c in rec.channels if c.kind in ("tacho", "encoder")}
    s.table([{"channel": x["channel"], "kind": rec.spec(x["channel"]).kind,
              "units": rec.spec(x["channel"]).units,
              "NaN/gap samples": x["n_nonfinite"], "NaN runs": len(x["nonfinite_runs"]),
              "clipped runs": "n/a (pulse train)" if x["channel"] in pulse else x["n_clipped_runs"],
              "min": x["min"], "max": x["max"]} for x in q])
    if ctx.condition is not None:
        s.heading("After conditioning (SNR from the conditioned signal)")
        s.table(_conditioned_rows(ctx.condition.quality))
    qf = [dict(x, n_clipped_runs=0) if x["channel"] in pulse else x for x in q]
    if any(x["n_nonfinite"] or x["n_clipped_runs"] for x in qf):
        figs.add(s, figures.quality_overview(qf), "quality",
                 "Non-finite samples and clipped runs per channel (pulse trains: no clipping count).")
    else:  # an all-zero bar chart says nothing a sentence does not
        s.text("No non-finite samples and no clipped runs in any gauge channel.", cls="note ok")


def _channel_map_section(rep: Report, ctx) -> None:
    """Which recording channel the scene's [[channels]] map to what; the bridge channels'
    conversion to strain (from the recording's history)."""
    rec = ctx.load.recording
    m = mapping_report(rec.channels, ctx.scene.channels, ctx.load.source)
    s = rep.section("Channel mapping")
    s.table(m["rows"])
    if m["unmapped"]:
        s.text(f"Not mapped by the scene's [[channels]]: {', '.join(m['unmapped'])} "
               "(kept as the file describes them).", cls="note")
    bridges = [h for h in rec.history if h.get("step") == "bridge_strain"]
    if bridges:
        s.heading("Bridge volts converted to strain")
        s.table([{"channel": name, "bridge": b["bridge"], "gauge factor": b["gauge_factor"],
                  "excitation [V]": b["excitation_V"], "1 + R_L/R_g": _lead(b),
                  "null window [s]": b["null_window_s"] or "none",
                  "V_init [mV]": _f(b["v_init_V"], scale=1e3)}
                 for h in bridges for name, b in h["channels"].items()])


def _lead(b: dict) -> str:
    return _f(1.0 + b["lead_ohm"] / b["gauge_ohm"]) if b.get("lead_ohm") else "1"


def _conditioned_rows(quality: dict) -> list:
    """SNR, gap guard and hum per conditioned channel."""
    rows = []
    for name, qq in quality.items():
        d = {"channel": name}
        for a, col in (("snr_db", "SNR [dB]"), ("settle", "gap guard [s]")):
            if hasattr(qq, a):
                d[col] = getattr(qq, a)
        hum = getattr(qq, "hum", None)
        d["hum"] = (", ".join(f"{f:g}" for f in hum.freqs) + " Hz") if hum is not None and getattr(hum, "present", False) else "none"
        rows.append(d)
    return rows


def _onsets_section(rep: Report, ctx, figs: _Figures) -> None:
    s = rep.section("Engagement onsets")
    by_channel = ctx.onsets.by_channel
    # the conditioned signal is streamed, not kept: the condition stage keeps its first
    # minute (meshphase.run.stream.EXCERPT_SECONDS) for this figure
    rec = ctx.condition.excerpt
    if rec is None:
        rec = ctx.condition.recording
    rows = []
    for ch, o in by_channel.items():
        sm = o.summary()
        rows.append({"channel": ch, "onsets": sm["n"], "clean": sm["n_good"],
                     "median corr": sm["median_corr"], "median amplitude [µε]":
                     None if sm["median_amplitude"] is None else sm["median_amplitude"] * 1e6,
                     "median width [ms]": None if sm["median_width_s"] is None else sm["median_width_s"] * 1e3})
    s.table(rows)
    labels = ctx.phasing.labels if ctx.phasing is not None else {}
    for gear in ("sun", "ring"):
        ch = next((c.name for c in rec.channels if c.kind == gear), None)
        if ch is None or ch not in by_channel:
            continue
        o = by_channel[ch]
        if not len(o) or ch not in rec.names or not rec.n_samples:
            continue
        # a stretch showing ~2 relative revolutions
        span = 8 * float(np.median(np.diff(o.times))) * 4 if len(o) > 2 else rec.duration
        t0 = float(o.times[0]) - 0.05 * span
        if t0 >= rec.t_end:          # the first pulse comes after the excerpt
            continue
        i0, i1 = rec.sample_range(max(rec.t0, t0), min(rec.t_end, t0 + span), strict=False)
        tt = rec.times()[i0:i1]
        x = rec.channel(ch)[i0:i1]
        if gear in labels:
            lab = labels[gear]
            mm = (lab.times >= tt[0]) & (lab.times <= tt[-1]) if tt.size else np.zeros(lab.times.size, bool)
            figs.add(s, figures.signal_with_onsets(tt, x, lab.times[mm], lab.planet[mm] + 1,
                                                   title=f"{ch} ({gear} gauge), conditioned"),
                     f"onsets_{ch}", f"Conditioned {gear}-gauge strain with the detected onsets, coloured by planet.")
        else:
            m = (o.times >= tt[0]) & (o.times <= tt[-1]) if tt.size else np.zeros(len(o), bool)
            figs.add(s, figures.signal_with_onsets(tt, x, o.times[m], None, title=ch),
                     f"onsets_{ch}", f"Conditioned strain of {ch} with its onsets.")


def _ideal_section(rep: Report, ideal) -> None:
    s = rep.section("Ideal phasing (Parker & Lin 2004)")
    s.text(f"Phasing class: {ideal.classification}.")
    s.table([{"planet": n + 1, "gamma_sn": ideal.gamma_s[n], "gamma_rn": ideal.gamma_r[n]}
             for n in range(len(ideal.gamma_s))])


def _phasing_section(rep: Report, ctx, figs: _Figures) -> None:
    s = rep.section("Measured phasing against the models")
    ph = ctx.phasing
    tabs = {g: t.columns() for g, t in ph.tables.items() if len(t)}
    if ph.fixed_reason:
        s.text(f"Held member: {ph.fixed or 'none (a differential)'} — {ph.fixed_reason}.")
    if ph.model is not None:
        _angle_model_text(s, ph.model, figs)
    for g, inf in ph.assignment.items():
        s.text(f"{g} gauge: planet 1 named by {inf.get('shift_decided_by')}"
               f"{' (relative: planet 1 is the first pulse seen)' if inf.get('ambiguous') else ''}, "
               f"{inf.get('n_unassigned', 0)} pulse(s) unassigned.")
        if inf.get("caution"):
            s.warning(f"{g} gauge: planet labels in doubt: {inf['caution']}")
    for g, rel in (ph.reliability or {}).items():
        if rel.get("reliable"):
            s.text(f"{g} gauge phasing: reliable — per-pass uncertainty {rel['error_estimate']:.2e} "
                   f"cycles (RMS), timing floor {rel['floor']:.2e}.")
        else:
            s.warning(f"{g} gauge phasing NOT reliable: " + "; ".join(rel["reasons"]))
    _phasing_figure(s, ctx, tabs, figs)
    rows = []
    for g, t in ph.tables.items():
        for n, v in t.summary().items():
            rows.append({"gauge": g, "planet": n, "passes": v["n"], "mean gamma": v["mean"],
                         "std": v["std"], "range": v["range"]})
    s.table(rows, caption="Per planet: circular mean, pass-to-pass std and range [mesh cycles]")
    if ctx.compare is not None:
        _residuals(s, ph.tables, ctx.compare.by_gear, figs)


def _angle_model_text(s, model, figs: _Figures) -> None:
    """The angle model: its terms, its fit per train and its residuals over time."""
    s.text(f"One angle model for the whole recording (mesh angle of every pass train"
           f"{' and the tacho' if any(t.kind == 'tacho' for t in model.trains) else ''}): "
           f"{model.terms}; rank {model.rank} of {model.n_parameters} columns; residual "
           f"RMS {model.residual_rms:.2e} mesh cycles; chosen by BIC from "
           f"{len(model.selection)} step(s).")
    s.table([{"train": t.name, "observations": t.n, "left out": t.n_outliers,
              "scatter / timing bound": t.scale, "residual RMS [cycles]": t.rms,
              "lag-1 correlation": t.lag1} for t in model.trains],
            caption="Angle model per train (scatter / timing bound near 1: the passes "
                    "scatter as their onsets' timing bound says)")
    for n in model.notes:
        s.text(n)
    series = {t.name: model.residuals(t.name) for t in model.trains}
    figs.add(s, figures.angle_model_residuals(series), "angle_residuals",
             "Angle model residuals per pass train [mesh cycles] against time: structure "
             "here (a drift, a periodic pattern) is speed variation the model does not "
             "follow.")


def _phasing_figure(s, ctx, tabs: dict, figs: _Figures) -> None:
    """Measured phasing per pass with the ideal, the identified model and the band."""
    ideal = None
    if ctx.ideal is not None:
        ideal = {"sun": {n + 1: float(v) for n, v in enumerate(ctx.ideal.gamma_s)},
                 "ring": {n + 1: float(v) for n, v in enumerate(ctx.ideal.gamma_r)}}
    predicted, bands = {}, {}
    for g, c in (ctx.compare.by_gear if ctx.compare is not None else {}).items():
        if c.model is not None and g in tabs:
            time_s, planet = tabs[g]["time_s"], tabs[g]["planet"]
            predicted[g] = {int(p): (time_s[planet == p], c.model[planet == p])
                            for p in np.unique(planet)}
        if c.band is not None and ideal:
            bands[g] = {n + 1: (ideal[g][n + 1] + c.band["lo"][n], ideal[g][n + 1] + c.band["hi"][n])
                        for n in range(len(c.band["lo"]))}
    figs.add(s, figures.phasing_over_time(tabs, predicted=predicted or None, bands=bands or None,
                                          ideal=ideal),
             "phasing", "Measured phasing per pass (points, ±1σ), ideal (dotted), the fitted "
                        "shaft-hole-error model (lines) and the Monte Carlo 3σ band (shaded).")


def _residuals(s, tables: dict, comparisons: dict, figs: _Figures) -> None:
    """Residuals per gauge against the ideal, the model, the band and the truth."""
    rows, res = [], {}
    for g, c in comparisons.items():
        tab = tables[g]
        row = {"gauge": g, "RMS vs ideal": c.vs_ideal["rms"], "max vs ideal": c.vs_ideal["max_abs"]}
        if c.vs_model:
            row["RMS vs model"] = c.vs_model["rms"]
            res[f"{g} - model"] = wrap(tab.gamma - c.model)
        res[f"{g} - ideal"] = wrap(tab.gamma - c.ideal)
        if c.coverage is not None:
            row["inside MC 3σ band"] = c.coverage["inside_fraction"]
        row["per-pass σ (RMS)"] = float(np.sqrt(np.mean(tab.uncertainty ** 2)))
        row["timing floor (RMS)"] = float(np.sqrt(np.mean(tab.timing_floor ** 2)))
        if c.vs_truth:
            row["RMS vs truth"] = c.vs_truth["rms"]
            row["error/σ RMS"] = c.vs_truth["z_rms"]
            row["inside 1.96σ"] = c.vs_truth["coverage95"]
            row["labels = truth"] = c.vs_truth["label_match"]
        rows.append(row)
    s.table(rows, caption="Residuals [mesh cycles]")
    if any(c.coverage is not None for c in comparisons.values()):
        s.text("The Monte Carlo band is the 3σ envelope (Ave bound3 ∓ half the upper Dev "
               "bound) of seed 000's fixed-time phasing deviation over the named window; "
               "the measured gauge phasing compares two engagement instants, so the band "
               "is an envelope, not the distribution of the measured quantity.")
    figs.add(s, figures.residual_histograms(res), "residuals", "Residual histograms.")


def _identify_section(rep: Report, ctx) -> None:
    s = rep.section("Identified shaft hole errors")
    i = ctx.identify.identification
    s.text(f"Weighted least squares over {i.n_passes} passes, {i.n_parameters} parameters: "
           f"residual RMS {i.rms_before:.3e} → {i.rms_after:.3e} mesh cycles.")
    for n in i.notes:
        s.warning(n)
    s.table([{"gear": row["gear"], "e [mm]": row["e"] * 1e3, "±95% [mm]": 1.96 * row["e_std"] * 1e3,
              "kappa [deg]": math.degrees(row["kappa"]) if math.isfinite(row["kappa"]) else float("nan"),
              "±σ [deg]": math.degrees(row["kappa_std"]) if math.isfinite(row["kappa_std"]) else float("nan"),
              "identifiable": "yes" if row["identifiable"] else "no", "note": row["note"]}
             for row in i.table])
    sv = i.singular_values
    if sv.size:
        s.text("Singular values of the weighted Jacobian (relative): "
               + ", ".join(f"{v / sv[0]:.1e}" for v in sv))
    if i.rank_note:
        s.text(i.rank_note[0].upper() + i.rank_note[1:] + ".")
    if i.combinations:
        s.heading("What the data determine")
        s.text("Unit-norm combinations of the offset components (right singular vectors of the "
               "weighted design), best determined first; 95 % intervals are +-1.96 standard "
               "deviations scaled by the fit's residual scale.")
        true_err = ctx.load.true_errors if ctx.load is not None else None
        truth = i.true_combinations(true_err) if true_err is not None else None
        s.table([{"#": k + 1, "combination": c["description"],
                  "estimate [mm]": c["estimate"] * 1e3,
                  "95% interval [mm]": f"{c['ci95'][0] * 1e3:.4g} to {c['ci95'][1] * 1e3:.4g}",
                  "std [mm]": c["std"] * 1e3,
                  **({} if truth is None else {"synthetic truth [mm]": truth[k] * 1e3}),
                  "relative singular value": c["relative_singular_value"]}
                 for k, c in enumerate(i.combinations)])
    if i.suggestions:
        s.heading("What would identify each error")
        s.table([{"gear": sg["gear"], "first option that identifies it": sg["option"] or
                  "none of the options tried",
                  "predicted std [mm]": sg["predicted_std"] * 1e3,
                  "shortest longer record that does":
                      sg["record_option"] or f"none up to {RECORD_FACTORS[-1]}x",
                  "its predicted std [mm]": sg["record_predicted_std"] * 1e3,
                  "options tried": "; ".join(sg["tried"])} for sg in i.suggestions])
    true_err = ctx.load.true_errors if ctx.load is not None else None
    if true_err is not None:
        s.text(f"Against the synthetic truth, the distance inside the identifiable subspace is "
               f"{i.subspace_error(true_err) * 1e3:.4f} mm.")


def _load_sharing_section(rep: Report, ctx, figs: _Figures) -> None:
    s = rep.section("Planet load sharing (ring gauge, Ligata et al. 2008)")
    ls = ctx.load_sharing.sharing
    truth = ctx.load.truth if ctx.load is not None else None
    true_ls = None
    if truth is not None and truth.load_sharing is not None:
        true_ls = np.asarray(truth.load_sharing, dtype=float)
    s.table(ls.to_rows())
    figs.add(s, figures.load_sharing_bars(ls.factors, true_ls, ls.std_error), "load_sharing",
             "Load-sharing factor per planet (1 = equal)" + (", measured vs truth." if true_ls is not None else "."))


def _centroids_section(rep: Report, centroids) -> None:
    s = rep.section("Face-width load centroids")
    s.table([{"gear": g, "Z [mm]": v.centroid * 1e3, "std error [mm]": v.std_error * 1e3,
              "contact fraction": v.contact_fraction, "shape": v.shape}
             for g, v in centroids.by_gear.items() if v is not None])


def _bearing_section(rep: Report, b) -> None:
    s = rep.section(f"Bearing moments — seed 001 case {b.case.name}")
    s.text(f"Input torque {b.torque:.1f} N·m. {b.case.source}")
    m = b.concentrated
    if isinstance(m, BearingMoments):
        rows = [{"load": "model, concentrated (Z = 0)", "Mx [N·m]": m.mx, "My [N·m]": m.my,
                 "M_LOA sun [N·m]": m.m_loa_sun, "M_LOA ring [N·m]": m.m_loa_ring}]
        if b.measured is not None:
            mm = b.measured
            rows.append({"load": "model, measured centroids", "Mx [N·m]": mm.mx, "My [N·m]": mm.my,
                         "M_LOA sun [N·m]": mm.m_loa_sun, "M_LOA ring [N·m]": mm.m_loa_ring})
        if b.case.name == "1":
            for g in table10_cases():
                stiff = "" if g.c_g_scale == 1.0 else f", gears {g.c_g_scale:g}x stiffer"
                rows.append({"load": f"seed 001 Table 10 GSAM {g.name} (k_t {g.k_tilt:.2g} N·m/rad{stiff})",
                             "Mx [N·m]": g.mx, "My [N·m]": g.my, "M_LOA sun [N·m]": g.m_loa_sun,
                             "M_LOA ring [N·m]": g.m_loa_ring})
        s.table([{k: (float(np.ravel(v)[0]) if not isinstance(v, str) else v) for k, v in row.items()}
                 for row in rows],
                caption="The model's moments side by side with GSAM (seed 001 Table 10)"
                if b.case.name == "1" else None)
    else:
        loa = [float(v) for v in np.ravel(m.loa)]
        rows = []
        for n, name in enumerate(_DP_MESHES):
            row = {"mesh": name, "model M_LOA [N·m]": loa[n]}
            if b.case.name == "2-B":
                row["seed 001 Table 11 theor. [N·m]"] = TABLE11_THEORY[n]
                for g in table11_cases():
                    row[f"GSAM {g.name} (k_t {g.k_tilt:.2g}) [N·m]"] = g.loa[n]
            rows.append(row)
        s.table(rows, caption="Concentrated-load LOA moments side by side with seed 001 Table 11 "
                              "(theory row and GSAM)" if b.case.name == "2-B" else None)


def _tilt_section(rep: Report, t, figs: _Figures) -> None:
    s = rep.section("Coupled bearing tilt / load distribution")
    single = t.case.name == "1"
    rows = [_tilt_row(k, sol, single, t.case.name) for k, sol in t.solutions]
    has_gsam = any("GSAM case" in x for x in rows)
    table_no = "10" if single else "11"
    s.table(rows, columns=_columns(rows),
            caption="Reduced model (c_g per scene)" + (
                f" side by side with seed 001 Table {table_no} (GSAM) where the stiffness matches"
                if has_gsam else "; seed 001 has no GSAM result at these stiffnesses"))
    if rows and "My [N·m]" in rows[0] and has_gsam:
        labels = [f"{x.get('GSAM case', '')} k={x['k_tilt [N·m/rad]']:.2g}" for x in rows]
        figs.add(s, figures.bearing_moments_bars(
            labels, {"model My": [x["My [N·m]"] for x in rows],
                     "GSAM My": [x.get("GSAM My [N·m]", float("nan")) for x in rows]},
            title="My on the pinion: the self-correcting drop with flexibility"),
            "tilt_my", "Pinion moment My, reduced model vs GSAM.")
    elif rows and has_gsam:
        labels = list(_DP_MESHES)
        series = {}
        for x in rows:
            if "GSAM case" in x:
                series[f"model k={x['k_tilt [N·m/rad]']:.2g}"] = [x[f"M_LOA {n} [N·m]"] for n in labels]
                series[f"GSAM {x['GSAM case']}"] = [x[f"GSAM {n}"] for n in labels]
        figs.add(s, figures.bearing_moments_bars(labels, series, title="LOA moments, double pinion"),
                 "tilt_loa", "LOA moments per mesh, reduced model vs GSAM (seed 001 Table 11).")


def _tilt_row(k: float, sol, single: bool, case_name: str) -> dict:
    """One tilt solution's row, with seed 001's GSAM result at the same stiffness."""
    z = np.ravel(sol.z)
    mom = sol.moments
    row = {"k_tilt [N·m/rad]": k, "Z_S [mm]": z[0] * 1e3, "Z_R [mm]": z[-1] * 1e3,
           "contact": float(np.min(sol.contact_fraction)),
           "iterations": f"{int(np.max(sol.iterations))} ({np.ravel(sol.method)[0]})",
           "residual [m]": float(np.max(sol.residual))}
    if isinstance(mom, BearingMoments):
        row["My [N·m]"] = float(np.ravel(mom.my)[0])
        row["M_LOA sun [N·m]"] = float(np.ravel(mom.m_loa_sun)[0])
        row["M_LOA ring [N·m]"] = float(np.ravel(mom.m_loa_ring)[0])
        gsam = {round(c.k_tilt): c for c in table10_cases() if c.c_g_scale == 1.0}
        g = gsam.get(round(k)) if single else None
        if g is not None:
            row.update({"GSAM case": g.name, "GSAM Z_S [mm]": g.z_s * 1e3,
                        "GSAM Z_R [mm]": g.z_r * 1e3, "GSAM My [N·m]": g.my})
    elif hasattr(mom, "m_sp_sun"):
        loa = np.ravel(mom.loa)
        for name, v in zip(_DP_MESHES, loa):
            row[f"M_LOA {name} [N·m]"] = float(v)
        gsam2 = {round(c.k_tilt): c for c in table11_cases()}
        g = gsam2.get(round(k)) if case_name == "2-B" else None
        if g is not None:
            row["GSAM case"] = g.name
            for name, v in zip(_DP_MESHES, g.loa):
                row[f"GSAM {name}"] = v
    return row


def _runtime_section(rep: Report, ctx, figs: _Figures) -> None:
    s = rep.section("Error against run time")
    names = list(ctx.timings)
    # stages that were skipped never started: listed too (no wall time), so every planned
    # stage appears with what became of it
    listed = names + [n for n in ctx.failed if n not in ctx.timings]
    s.table([{"stage": n, "wall time [s]": ctx.timings.get(n, float("nan")),
              "error estimate": ctx.error_estimates.get(n, ""),
              "status": "ran" if n in ctx.ran else str(ctx.failed.get(n, ""))} for n in listed])
    if names:
        s.text(f"Total wall time of the stages: {sum(ctx.timings.values()):.3g} s.")
    if ctx.tolerance is not None:
        mc = ctx.tolerance.monte_carlo
        s.text(f"Monte Carlo window: {mc.window} ({mc.n_times} time samples), {mc.n_samples} "
               f"{mc.sampler} samples on the {mc.engine} engine in {mc.wall_time:.2f} s.")
    if names:
        figs.add(s, figures.stage_times(names, [ctx.timings[n] for n in names],
                                        [ctx.error_estimates.get(n, "") for n in names]),
                 "stage_times", "Wall time per stage, with its error estimate.")
