"""What a run writes: the machine-readable summary (summary.json), the CSV tables, the
arrays (arrays.h5) and the HTML report, from the run context's typed stage results
(:mod:`meshphase.run.results`). The output folder a run writes into is
:func:`meshphase.run.outdir.new_output_dir`'s (re-exported here and from :mod:`meshphase.run.stages`).

``summary.json`` keys: scene, status, missing_results, phasing_reliability,
results_requested, stages_ran, stages_failed, timings_s, error_estimates, messages,
channels_unused and, for what ran, gearset, recording, onsets, ideal, phasing,
phasing_labels, held_member, member_speeds_rpm, angle_model, load_sharing, centroids_m,
tolerance, identify, compare, bearing_moments, tilt, and verdict (the report's opening
paragraph, :func:`meshphase.compare.predict.identification_verdict`).

The rows of a table the summary shares with a CSV carry the CSV's column names
(:data:`SUMMARY_RENAMED`): ``load_sharing`` rows, ``identify.table`` and
``identify.combinations`` rows, ``phasing.<gear>.per_planet`` entries (named as campaign.csv
names them); for one release they also keep the names of the previous one beside them.

CSV tables (columns in ``data_schemas/outputs.md``): passes_<gear>.csv, load_sharing.csv,
identified_errors.csv, identified_combinations.csv, bearing_moments.csv, tilt.csv and
stages.csv, each of what ran. SI values, the unit in the header (``time_s``,
``gamma_cycles``, ``e_m``, ``my_Nm``, ...; no suffix: a label, count, flag, text or a
dimensionless ratio; :func:`meshphase.report.frames.column_unit` reads it), one number per
field (an interval is two columns, ``..._ci95_lo_m`` and ``..._ci95_hi_m``), NaN (not
computed) as an empty field, infinities as ``inf`` / ``-inf``. load_sharing.csv and
identified_errors.csv are the rows of :class:`meshphase.Result`'s ``load_sharing`` and
``identification`` tables (:mod:`meshphase.report.frames`).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..compare.predict import identification_verdict
from ..jsonable import to_jsonable
from ..report.frames import identification_rows, load_sharing_rows
from .context import RunContext, phasing_verdict
from .exits import run_status
from .outdir import new_output_dir
from .results import PhasingStage
from .state import failure_texts
from .table_csv import write_csv

__all__ = ["new_output_dir", "summary_dict", "write_outputs", "PASS_COLUMNS", "SUMMARY_RENAMED"]

#: summary.json rows that a CSV shares -> {name of the previous release: the CSV's name}; the
#: previous names are written beside the CSV's for one release (until meshphase 0.2). An
#: interval ``[lo, hi]`` of the previous release becomes two keys, ``..._lo_...`` and
#: ``..._hi_...``.
SUMMARY_RENAMED: dict[str, dict[str, str | tuple[str, str]]] = {
    "load_sharing": {"mean_amplitude": "mean_amplitude_strain"},
    "identify.table": {"e": "e_m", "e_std": "e_std_m", "e_ci95": ("e_ci95_lo_m", "e_ci95_hi_m"),
                       "kappa": "kappa_rad", "kappa_std": "kappa_std_rad"},
    "identify.combinations": {"estimate": "estimate_m", "std": "std_m",
                              "ci95": ("ci95_lo_m", "ci95_hi_m")},
    "phasing.per_planet": {"n": "n_passes", "mean": "gamma_mean_cycles",
                           "std": "gamma_std_cycles", "range": "gamma_range_cycles"},
}


def _aligned(row: dict, section: str) -> dict:
    """``row`` with the CSV's names of :data:`SUMMARY_RENAMED` ``[section]`` first, then its
    own keys (the previous release's names among them)."""
    new = {}
    for old, name in SUMMARY_RENAMED[section].items():
        if old not in row:
            continue
        if isinstance(name, tuple):
            lo, hi = (list(row[old] or [None, None]) + [None, None])[:2]
            new[name[0]], new[name[1]] = lo, hi
        else:
            new[name] = row[old]
    return {**new, **{k: v for k, v in row.items() if k not in new}}


def summary_dict(ctx: RunContext) -> dict:
    """The machine-readable summary of a run (JSON-friendly)."""
    st = run_status(ctx)
    s: dict = {"scene": ctx.scene.name, "status": st["status"],
               "missing_results": st["missing_results"],
               "phasing_reliability": phasing_verdict(ctx.phasing, ctx.messages),
               "results_requested": ctx.scene.results,
               "stages_ran": ctx.ran, "stages_failed": failure_texts(ctx.failed),
               "timings_s": ctx.timings, "error_estimates": ctx.error_estimates,
               "messages": ctx.messages, "channels_unused": ctx.channels_unused}
    g = ctx.gearset
    if g is not None:
        s["gearset"] = g.to_dict()
    if ctx.load is not None:
        rec = ctx.load.recording
        s["recording"] = {"source": ctx.load.source, "fs_hz": rec.fs, "n_samples": rec.n_samples,
                          "duration_s": rec.duration, "channels": [c.to_dict() for c in rec.channels]}
    if ctx.onsets is not None:
        s["onsets"] = {k: o.summary() for k, o in ctx.onsets.by_channel.items()}
    if ctx.ideal is not None:
        i = ctx.ideal
        s["ideal"] = {"gamma_s": i.gamma_s, "gamma_r": i.gamma_r, "classification": i.classification}
    if ctx.phasing is not None:
        s.update(_phasing_summary(ctx.phasing))
    if ctx.load_sharing is not None and ctx.load_sharing.sharing is not None:
        s["load_sharing"] = [_aligned(r, "load_sharing") for r in ctx.load_sharing.sharing.to_rows()]
    if ctx.centroids is not None and ctx.centroids.by_gear:
        s["centroids_m"] = {k: (None if v is None else vars(v)) for k, v in ctx.centroids.by_gear.items()}
    if ctx.tolerance is not None:
        s["tolerance"] = ctx.tolerance.monte_carlo.to_dict()
    if ctx.identify is not None:
        i = ctx.identify.identification
        s["identify"] = {"table": [_aligned(r, "identify.table") for r in i.table],
                         "rms_before": i.rms_before, "rms_after": i.rms_after,
                         "n_passes": i.n_passes, "identifiable": i.identifiable, "notes": i.notes,
                         "singular_values": i.singular_values, "rank": i.rank, "rank_note": i.rank_note,
                         "combinations": [_aligned(c, "identify.combinations")
                                          for c in i.combinations],
                         "suggestions": i.suggestions}
    if ctx.identify is not None or (ctx.phasing is not None and ctx.phasing.member_speeds):
        s["verdict"] = identification_verdict(
            ctx.identify.identification if ctx.identify is not None else None,
            ctx.phasing.member_speeds if ctx.phasing is not None else None)
    if ctx.compare is not None:
        s["compare"] = {k: {kk: vv for kk, vv in v.as_dict().items() if kk not in ("ideal", "model")}
                        for k, v in ctx.compare.by_gear.items()}
    s.update(_bearing_summary(ctx))
    return to_jsonable(s)


def _phasing_summary(ph: PhasingStage) -> dict:
    """``phasing`` (per gear: passes, per-planet statistics, notes, labels, reliability),
    ``phasing_labels``, ``held_member`` and ``angle_model`` of the summary."""
    assignment, reliability = ph.assignment, ph.reliability or {}
    s = {"phasing": {k: {"n_passes": len(t),
                         "per_planet": {p: _aligned(v, "phasing.per_planet")
                                        for p, v in t.summary().items()},
                         "notes": t.notes,
                         "assignment": assignment.get(k), "reliability": reliability.get(k)}
                     for k, t in ph.tables.items()}}
    cautions = {gear: lab.caution for gear, lab in (ph.labels or {}).items()
                if getattr(lab, "caution", "")}
    rel = [gear for gear in ph.labels_relative or [] if gear not in cautions]
    said = ([f"planet labels of the {' and '.join(rel)} gauge(s) are relative: planet 1 is the "
             "first pulse seen (no tacho geometry, unequal spacing or unequal loads named it)"]
            if rel else [])
    said += [f"planet labels of the {gear} gauge in doubt: {why}" for gear, why in cautions.items()]
    s["phasing_labels"] = "; ".join(said) if said else "planet labels absolute"
    s["held_member"] = {"fixed": ph.fixed, "reason": ph.fixed_reason}
    if ph.member_speeds is not None:
        s["member_speeds_rpm"] = ph.member_speeds
    if ph.model is not None:
        s["angle_model"] = ph.model.summary()
    return s


def _bearing_summary(ctx: RunContext) -> dict:
    """``bearing_moments`` and ``tilt`` of the summary."""
    s: dict = {}
    if ctx.bearing_moments is not None:
        b = ctx.bearing_moments
        s["bearing_moments"] = {"case": b.case.name, "input_torque_Nm": b.torque,
                                "concentrated": _moments_dict(b.concentrated),
                                **({"measured": _moments_dict(b.measured)}
                                   if b.measured is not None else {})}
    if ctx.tilt is not None:
        s["tilt"] = [{"k_tilt_Nm_per_rad": k, "z_m": sol.z, "converged": sol.converged,
                      "iterations": sol.iterations, "residual_m": sol.residual,
                      "contact_fraction": sol.contact_fraction, "moments": _moments_dict(sol.moments)}
                     for k, sol in ctx.tilt.solutions]
    return s


def _moments_dict(m) -> dict:
    out = {}
    for k, v in vars(m).items():
        if isinstance(v, (np.ndarray, float, int, np.floating)):
            out[k] = v
    return out


def write_outputs(ctx: RunContext, out_dir: Path, *, report: bool = True, summary: dict | None = None) -> dict:
    """Write summary.json, CSV tables, arrays.h5 and (optionally) report.html into ``out_dir``.

    ``summary``: :func:`summary_dict` of ``ctx`` when the caller has it already (a campaign
    keeps it; a scene's tolerance Monte Carlo summaries make it no small work); None: made
    here.

    Returns a dict name -> path of what was written.
    """
    if not isinstance(ctx, RunContext):
        raise TypeError(f"ctx must be a RunContext (from run_scene), got {type(ctx).__name__}")
    out_dir = Path(out_dir)
    if not out_dir.is_dir():
        raise FileNotFoundError(f"{out_dir}: output folder does not exist (see new_output_dir)")
    files = {}
    p = out_dir / "summary.json"
    if summary is not None and not isinstance(summary, dict):
        raise TypeError(f"summary must be summary_dict(ctx) (a dict) or None, got {type(summary).__name__}")
    p.write_text(json.dumps(summary_dict(ctx) if summary is None else summary, indent=2))
    files["summary"] = p
    files.update(_write_tables(ctx, out_dir))
    files["stages"] = _csv(
        [{"stage": s, "wall_time_s": ctx.timings.get(s, float("nan")),
          "error_estimate": ctx.error_estimates.get(s, ""),
          "status": "ran" if s in ctx.ran else str(ctx.failed.get(s, ""))}
         for s in list(ctx.timings) + [k for k in ctx.failed if k not in ctx.timings]],
        out_dir / "stages.csv", columns=["stage", "wall_time_s", "error_estimate", "status"])
    files["arrays"] = _write_arrays(ctx, out_dir / "arrays.h5")
    if report:
        from ..report.validation import build_report  # matplotlib: only for the report

        files["report"] = build_report(ctx, out_dir)
    return files


#: passes_<gear>.csv: PassTable.to_dataframe's columns -> the header written (unit suffix)
PASS_COLUMNS = {"gauge": "gauge", "time_s": "time_s", "planet": "planet",
                "revolution": "revolution", "gamma": "gamma_cycles",
                "uncertainty": "uncertainty_cycles", "mesh_period_s": "mesh_period_s",
                "ref_time_s": "ref_time_s", "angle_rad": "angle_rad",
                "timing_floor": "timing_floor_cycles", "model_sigma": "model_sigma_cycles"}


def _write_tables(ctx: RunContext, out_dir: Path) -> dict:
    """passes_<gear>.csv, load_sharing.csv, identified_errors.csv, bearing_moments.csv and
    tilt.csv of what ran: SI values with the unit in each header (``_s``, ``_m``, ``_rad``,
    ``_cycles`` (of one mesh cycle), ``_strain`` (m/m), ``_N``, ``_Nm``, ...; no suffix: a
    label, count, flag or a dimensionless ratio); NaN (not computed) as an empty field."""
    files = {}
    if ctx.phasing is not None:
        cmp = ctx.compare.by_gear if ctx.compare is not None else {}
        for gear, t in ctx.phasing.tables.items():
            cols = {PASS_COLUMNS[k]: v for k, v in t.columns().items()}
            if gear in cmp:
                cols["gamma_ideal_cycles"] = np.asarray(cmp[gear].ideal)
                if cmp[gear].model is not None:
                    cols["gamma_model_cycles"] = np.asarray(cmp[gear].model)
            files[f"passes_{gear}"] = _csv(cols, out_dir / f"passes_{gear}.csv")
    if ctx.load_sharing is not None and ctx.load_sharing.sharing is not None:
        files["load_sharing"] = _csv(load_sharing_rows(ctx), out_dir / "load_sharing.csv")
    if ctx.identify is not None:
        i = ctx.identify.identification
        files["identified_errors"] = _csv(identification_rows(ctx), out_dir / "identified_errors.csv")
        rows = [{"combination": k + 1, "description": c["description"], "estimate_m": c["estimate"],
                 "std_m": c["std"], "ci95_lo_m": c["ci95"][0], "ci95_hi_m": c["ci95"][1],
                 "relative_singular_value": c["relative_singular_value"],
                 **{f"coef_{nm}": v for nm, v in c["coefficients"].items()}}
                for k, c in enumerate(i.combinations)]
        cols = ["combination", "description", "estimate_m", "std_m", "ci95_lo_m", "ci95_hi_m",
                "relative_singular_value", *(f"coef_{nm}" for nm in i.parameters)]
        files["identified_combinations"] = _csv(rows, out_dir / "identified_combinations.csv",
                                                columns=cols)
    if ctx.bearing_moments is not None:
        b = ctx.bearing_moments
        rows = [{"moments": name, "input_torque_Nm": b.torque, **_moment_columns(m)}
                for name, m in (("concentrated", b.concentrated), ("with_offsets", b.with_offsets),
                                ("measured", b.measured)) if m is not None]
        files["bearing_moments"] = _csv(rows, out_dir / "bearing_moments.csv")
    if ctx.tilt is not None:
        rows = [_tilt_columns(k, sol, ctx.tilt.torque) for k, sol in ctx.tilt.solutions]
        files["tilt"] = _csv(rows, out_dir / "tilt.csv")
    return files


def _csv(rows, path: Path, columns=None) -> Path:
    """Rows (list of dicts) or columns (dict) as CSV: NaN and None as an empty field
    (:func:`meshphase.run.table_csv.write_csv`, the bytes pandas' ``to_csv`` wrote, without
    importing pandas)."""
    return write_csv(rows, path, columns)


def _mesh_key(name: str) -> str:
    """A mesh name as a column part: 'sun-SP' -> 'sun_sp'."""
    return name.lower().replace("-", "_")


def _scalar_or_nan(v) -> float:
    a = np.ravel(np.asarray(v, dtype=float))
    return float(a[0]) if a.size == 1 else float("nan")


def _moment_columns(m) -> dict:
    """One row's columns of a BearingMoments or DoublePinionMoments (scalar inputs): every
    moment ``<name>_Nm`` [N·m], then the load-centroid offset of each mesh ``z_<mesh>_m`` [m]."""
    out = {f"{k}_Nm": _scalar_or_nan(v) for k, v in vars(m).items()
           if k not in ("z_s", "z_r", "z") and isinstance(v, (np.ndarray, float, int, np.floating))}
    z = np.atleast_1d(np.asarray(m.z, dtype=float))
    out.update({f"z_{_mesh_key(n)}_m": float(z[..., j].ravel()[0]) for j, n in enumerate(m.mesh_names)})
    return out


def _tilt_columns(k: float, sol, torque: float) -> dict:
    """One tilt.csv row: the stiffness, convergence, per mesh the offset [m], misalignment
    [rad], force [N], contact fraction [-], peak load [N/m] and K_Hbeta [-], then the moments
    at the converged offsets [N·m]."""
    row = {"k_tilt_Nm_per_rad": float(k), "input_torque_Nm": float(torque),
           "converged": bool(np.all(sol.converged)), "iterations": int(np.max(sol.iterations)),
           "residual_m": float(np.max(sol.residual)), "method": str(np.ravel(sol.method)[0])}
    per_mesh = (("z", "m"), ("tilt", "rad"), ("force", "N"), ("contact_fraction", ""),
                ("peak_load", "N_per_m"), ("face_load_factor", ""))
    for j, mesh in enumerate(sol.mesh_names):
        for attr, unit in per_mesh:
            v = np.asarray(getattr(sol, attr), dtype=float)
            row[f"{attr}_{_mesh_key(mesh)}" + (f"_{unit}" if unit else "")] = float(v[..., j].ravel()[0])
    row.update({k2: v for k2, v in _moment_columns(sol.moments).items() if not k2.startswith("z_")})
    return row


def _write_arrays(ctx: RunContext, path: Path) -> Path:
    """arrays.h5: the onsets per channel and the Monte Carlo samples."""
    import h5py  # heavy: only when writing

    with h5py.File(path, "w") as f:
        if ctx.onsets is not None:
            grp = f.create_group("onsets")
            for ch, o in ctx.onsets.by_channel.items():
                gch = grp.create_group(ch)
                for a in ("times", "corr", "amplitude", "width", "flags"):
                    gch.create_dataset(a, data=getattr(o, a))
        if ctx.tolerance is not None and ctx.tolerance.monte_carlo.samples is not None:
            grp = f.create_group("monte_carlo")
            for k, v in ctx.tolerance.monte_carlo.samples.items():
                grp.create_dataset(k, data=v)
    return path
