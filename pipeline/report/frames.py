"""Tables of a run's typed stage results, one row per pass, planet, gear ...: what
:class:`meshphase.Result`'s DataFrames hold.

Each ``*_rows(ctx)`` function reads the typed results of a :class:`~meshphase.run.context.RunContext`
(``ctx.phasing``, ``ctx.compare``, ...) and returns a list of dicts whose keys are the
columns of :data:`COLUMNS` (units in the names: ``_s`` seconds, ``_cycles`` mesh cycles,
``_um`` micrometres, ``_mm`` millimetres, ``_deg`` degrees, ``_ustrain`` microstrain; no
suffix: dimensionless); an empty list when the stage did not run. :func:`frame` makes the
DataFrame (pandas is imported there only). Values are the typed results' own, converted only
to the unit the column names.
"""

from __future__ import annotations

import math
from typing import Any, Protocol, runtime_checkable

import numpy as np

from ..compare.predict import wrap

__all__ = ["RunResults", "COLUMNS", "passes_rows", "phasing_rows", "load_sharing_rows", "comparison_rows",
           "identification_rows", "centroid_rows", "frame", "circular_mean"]

#: table name -> its columns, in order
COLUMNS: dict[str, tuple[str, ...]] = {
    "passes": ("gauge", "planet", "revolution", "time_s", "phasing_cycles", "sigma_cycles",
               "timing_floor_cycles", "model_sigma_cycles", "mesh_period_s", "ref_time_s",
               "angle_rad", "ideal_cycles", "model_cycles", "residual_ideal_cycles",
               "residual_model_cycles"),
    "phasing": ("gauge", "planet", "n_passes", "mean_cycles", "sd_cycles", "range_cycles",
                "median_sigma_cycles", "ideal_cycles", "model_cycles", "residual_ideal_mean_cycles",
                "residual_ideal_rms_cycles", "residual_model_mean_cycles",
                "residual_model_rms_cycles", "band_dev_lo_cycles", "band_dev_hi_cycles"),
    "load_sharing": ("planet", "load_sharing", "std_error", "n_passes", "mean_amplitude_ustrain"),
    "comparison": ("gauge", "reference", "n_passes", "mean_cycles", "rms_cycles",
                   "max_abs_cycles", "sd_cycles", "inside_band_fraction"),
    "identification": ("gear", "e_um", "e_std_um", "e_ci95_lo_um", "e_ci95_hi_um", "kappa_deg",
                       "kappa_std_deg", "identifiable", "note"),
    "centroids": ("gear", "centroid_mm", "std_error_mm", "contact_fraction", "shape",
                  "residual_rms"),
}

_NAN = float("nan")


@runtime_checkable
class RunResults(Protocol):
    """What the tables and figures read of a run: the typed stage results of a
    :class:`~meshphase.run.context.RunContext` (None where a stage did not run). The report
    sits above the numbers and below the run that writes it, so it names the run's results by
    their shape, not by the run's class."""

    scene: Any
    onsets: Any
    phasing: Any
    load_sharing: Any
    compare: Any
    identify: Any
    centroids: Any


def _check(ctx) -> None:
    if not isinstance(ctx, RunResults):
        raise TypeError(f"ctx must be a RunContext (meshphase.run.stages.run_scene), got "
                        f"{type(ctx).__name__}")


def circular_mean(x) -> float:
    """Circular mean of phasings [mesh cycles] in [0, 1); NaN for none."""
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    if not x.size:
        return _NAN
    return float((np.angle(np.exp(2j * np.pi * x).mean()) / (2 * np.pi)) % 1.0)


def _comparison_arrays(ctx: RunResults, gauge: str, n: int) -> tuple:
    """(ideal, model) phasing at each pass of ``gauge`` [-]; NaN where not compared."""
    cmp = ctx.compare.by_gear.get(gauge) if ctx.compare is not None else None
    ideal = np.full(n, np.nan) if cmp is None else np.asarray(cmp.ideal, dtype=float)
    model = (np.full(n, np.nan) if cmp is None or cmp.model is None
             else np.asarray(cmp.model, dtype=float))
    return ideal, model


def passes_rows(ctx: RunResults) -> list[dict]:
    """One row per measured pass of every gauge: its phasing and one-sigma uncertainty
    [mesh cycles], the ideal and identified-model phasing at it and the residuals (wrapped to
    [-0.5, 0.5))."""
    _check(ctx)
    rows = []
    if ctx.phasing is None:
        return rows
    for gauge, t in ctx.phasing.tables.items():
        ideal, model = _comparison_arrays(ctx, gauge, len(t))
        r_ideal, r_model = wrap(t.gamma - ideal), wrap(t.gamma - model)
        for i in range(len(t)):
            rows.append({
                "gauge": gauge, "planet": int(t.planet[i]), "revolution": int(t.revolution[i]),
                "time_s": float(t.time[i]), "phasing_cycles": float(t.gamma[i]),
                "sigma_cycles": float(t.uncertainty[i]),
                "timing_floor_cycles": float(t.timing_floor[i]),
                "model_sigma_cycles": float(t.model_sigma[i]),
                "mesh_period_s": float(t.mesh_period[i]), "ref_time_s": float(t.ref_time[i]),
                "angle_rad": float(t.angle[i]), "ideal_cycles": float(ideal[i]),
                "model_cycles": float(model[i]), "residual_ideal_cycles": float(r_ideal[i]),
                "residual_model_cycles": float(r_model[i])})
    return rows


def _per_planet(stats: dict | None, planet: int, key: str) -> float:
    if not stats:
        return _NAN
    v = stats.get("per_planet", {}).get(planet, {}).get(key)
    return _NAN if v is None else float(v)


def phasing_rows(ctx: RunResults) -> list[dict]:
    """One row per gauge and measured planet (2..N): the passes' circular mean, standard
    deviation and range [mesh cycles] (:meth:`meshphase.kinematics.phasing.PassTable.summary`, as in
    summary.json), their median one-sigma uncertainty, the ideal phasing, the identified
    model's circular mean over the same passes, the residual statistics against both
    (:func:`meshphase.compare.predict.residual_stats`) and the Monte Carlo 3-sigma band of the
    deviation from the ideal (:meth:`meshphase.run.results.ToleranceStage.band`)."""
    _check(ctx)
    rows = []
    if ctx.phasing is None:
        return rows
    for gauge, t in ctx.phasing.tables.items():
        cmp = ctx.compare.by_gear.get(gauge) if ctx.compare is not None else None
        ideal, model = _comparison_arrays(ctx, gauge, len(t))
        ideal_n = ctx.ideal.gamma(gauge) if ctx.ideal is not None else None
        for planet, s in t.summary().items():
            m = t.planet == planet
            band = cmp.band if cmp is not None else None
            rows.append({
                "gauge": gauge, "planet": planet, "n_passes": s["n"], "mean_cycles": s["mean"],
                "sd_cycles": s["std"], "range_cycles": s["range"],
                "median_sigma_cycles": float(np.median(t.uncertainty[m])) if m.any() else _NAN,
                "ideal_cycles": (float(ideal_n[planet - 1]) if ideal_n is not None
                                 else circular_mean(ideal[m])),
                "model_cycles": circular_mean(model[m]),
                "residual_ideal_mean_cycles": _per_planet(cmp and cmp.vs_ideal, planet, "mean"),
                "residual_ideal_rms_cycles": _per_planet(cmp and cmp.vs_ideal, planet, "rms"),
                "residual_model_mean_cycles": _per_planet(cmp and cmp.vs_model, planet, "mean"),
                "residual_model_rms_cycles": _per_planet(cmp and cmp.vs_model, planet, "rms"),
                "band_dev_lo_cycles": float(band["lo"][planet - 1]) if band else _NAN,
                "band_dev_hi_cycles": float(band["hi"][planet - 1]) if band else _NAN})
    return rows


def load_sharing_rows(ctx: RunResults) -> list[dict]:
    """One row per planet: load-sharing factor LS_n [-] (1 = equal), its standard error [-],
    the passes it comes from and the mean pulse amplitude [microstrain]."""
    _check(ctx)
    if ctx.load_sharing is None or ctx.load_sharing.sharing is None:
        return []
    return [{"planet": r["planet"], "load_sharing": r["load_sharing"],
             "std_error": r["std_error"], "n_passes": r["n_passes"],
             "mean_amplitude_ustrain": r["mean_amplitude"] * 1e6}
            for r in ctx.load_sharing.sharing.to_rows()]


def comparison_rows(ctx: RunResults) -> list[dict]:
    """One row per gauge and reference ("ideal", "model": the identified errors, "truth":
    a synthetic recording's): residual statistics of measured - reference [mesh cycles] and
    the share of passes inside the Monte Carlo band (NaN without one)."""
    _check(ctx)
    rows = []
    if ctx.compare is None:
        return rows
    for gauge, c in ctx.compare.by_gear.items():
        inside = _NAN if not c.coverage else float(c.coverage.get("inside_fraction", _NAN))
        for ref, s in (("ideal", c.vs_ideal), ("model", c.vs_model), ("truth", c.vs_truth)):
            if not s:
                continue
            rows.append({"gauge": gauge, "reference": ref, "n_passes": int(s.get("n", 0)),
                         "mean_cycles": float(s.get("mean", _NAN)), "rms_cycles": float(s["rms"]),
                         "max_abs_cycles": float(s.get("max_abs", _NAN)),
                         "sd_cycles": float(s.get("std", _NAN)), "inside_band_fraction": inside})
    return rows


def _um(v) -> float:
    return _NAN if v is None else float(v) * 1e6


def _deg(v) -> float:
    return _NAN if v is None else math.degrees(float(v))


def identification_rows(ctx: RunResults) -> list[dict]:
    """One row per gear (sun, ring, planet1..N): the identified shaft hole error e [um] with
    its one-sigma and 95 % interval [um], its angle kappa [deg] with its one-sigma [deg],
    whether the data can tell it and why not (NaN values where they cannot)."""
    _check(ctx)
    if ctx.identify is None:
        return []
    rows = []
    for r in ctx.identify.identification.table:
        lo, hi = (list(r.get("e_ci95") or [None, None]) + [None, None])[:2]
        rows.append({"gear": r["gear"], "e_um": _um(r.get("e")), "e_std_um": _um(r.get("e_std")),
                     "e_ci95_lo_um": _um(lo), "e_ci95_hi_um": _um(hi),
                     "kappa_deg": _deg(r.get("kappa")), "kappa_std_deg": _deg(r.get("kappa_std")),
                     "identifiable": bool(r.get("identifiable")), "note": r.get("note") or ""})
    return rows


def centroid_rows(ctx: RunResults) -> list[dict]:
    """One row per gear with face-width gauges: load centroid Z [mm] from the face centre and
    its standard error [mm], the loaded share of the face [-], the load shape and the fit's
    RMS misfit [strain]; NaN for a gear with too few positioned gauges."""
    _check(ctx)
    if ctx.centroids is None:
        return []
    rows = []
    for gear, c in ctx.centroids.by_gear.items():
        if c is None:
            rows.append({"gear": gear, "centroid_mm": _NAN, "std_error_mm": _NAN,
                         "contact_fraction": _NAN, "shape": "none", "residual_rms": _NAN})
        else:
            rows.append({"gear": gear, "centroid_mm": c.centroid * 1e3,
                         "std_error_mm": c.std_error * 1e3, "contact_fraction": c.contact_fraction,
                         "shape": c.shape, "residual_rms": c.residual_rms})
    return rows


def frame(rows: list[dict], name: str):
    """A pandas DataFrame of ``rows`` with the columns of table ``name`` (:data:`COLUMNS`),
    also when there are no rows."""
    import pandas as pd  # heavy: only when a table is asked for

    if name not in COLUMNS:
        raise ValueError(f"unknown table {name!r}; tables: {', '.join(COLUMNS)}")
    return pd.DataFrame(rows, columns=list(COLUMNS[name]))
