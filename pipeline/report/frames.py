"""Tables of a run's typed stage results, one row per pass, planet, gear ...: what
:class:`meshphase.Result`'s DataFrames hold, and the unit of every column of every table a run
writes (the CSV files and these DataFrames share their names and their units).

Each ``*_rows(ctx)`` function reads the typed results of a :class:`~meshphase.run.context.RunContext`
(``ctx.phasing``, ``ctx.compare``, ...) and returns a list of dicts whose keys are the
columns of :data:`COLUMNS`; an empty list when the stage did not run. A column that a CSV of
the run holds has that CSV's name and unit (``data_schemas/outputs.md``): SI values, the unit
as the name's suffix (:data:`SUFFIX_UNITS`; no suffix: a label, count, flag, text or a
dimensionless ratio, :data:`PLAIN_UNITS`). :func:`column_unit` reads a column's unit off its
name: the one table behind the CSV headers' documentation and ``DataFrame.attrs["units"]``.

:func:`frame` makes the DataFrame (pandas is imported there only): a :class:`ResultFrame`,
whose ``attrs`` carry ``table``, ``description``, ``file`` (the CSV with the same columns,
or None) and ``units`` (column -> unit), and which still answers a column's name of the
previous release (:data:`RENAMED`) with a FutureWarning naming the column that replaced it.
"""

from __future__ import annotations

import math
import warnings
from typing import Any, Protocol, runtime_checkable

import numpy as np

from ..compare.predict import wrap

__all__ = ["RunResults", "COLUMNS", "TABLES", "RENAMED", "SUFFIX_UNITS", "PLAIN_UNITS",
           "PLAIN_PREFIX_UNITS", "column_unit", "table_units", "passes_rows", "phasing_rows",
           "load_sharing_rows", "comparison_rows", "identification_rows", "centroid_rows",
           "frame", "ResultFrame", "circular_mean"]

#: a column name's unit suffix -> its unit; the longest suffix a name ends with wins
#: (``_Nm_per_rad`` before ``_rad``). "cycles": fractions of one mesh cycle; "strain": m/m.
SUFFIX_UNITS: dict[str, str] = {
    "_s": "s", "_m": "m", "_rad": "rad", "_cycles": "cycles", "_strain": "strain",
    "_N": "N", "_Nm": "N*m", "_Nm_per_rad": "N*m/rad", "_N_per_m": "N/m",
}

#: columns without a unit suffix -> their unit: "1" for a count or a dimensionless ratio,
#: "" for a label, flag or text (not a quantity)
PLAIN_UNITS: dict[str, str] = {
    "gauge": "", "gear": "", "reference": "", "shape": "", "identifiable": "", "note": "",
    "identified_by": "", "stage": "", "status": "", "error_estimate": "", "description": "",
    "moments": "", "converged": "", "method": "",
    "name": "", "recording": "", "format": "", "error": "", "worker": "", "retries": "",
    "resumed": "", "out_dir": "",
    "planet": "1", "revolution": "1", "n_passes": "1", "load_sharing": "1", "std_error": "1",
    "coverage": "1", "contact_fraction": "1", "record_factor": "1", "combination": "1",
    "relative_singular_value": "1", "iterations": "1", "attempts": "1", "n_messages": "1",
}

#: per-mesh, per-parameter, per-gauge and per-planet columns without a unit suffix:
#: name prefix -> unit
PLAIN_PREFIX_UNITS: dict[str, str] = {
    "coef_": "1", "contact_fraction_": "1", "face_load_factor_": "1", "passes_": "1",
    "coverage_": "1", "load_sharing_": "1",
}

_SUFFIXES = sorted(SUFFIX_UNITS, key=len, reverse=True)


def column_unit(name: str) -> str:
    """The unit of a result table's column, from its name (the convention of every CSV a run
    writes, ``data_schemas/outputs.md``).

    Parameters
    ----------
    name : str
        A column name of a run's CSV file or of a :class:`meshphase.Result` table.

    Returns
    -------
    str
        The unit ("s", "m", "rad", "cycles", "strain", "N", "N*m", "N*m/rad", "N/m"), "1" for
        a count or a dimensionless ratio, "" for a label, flag or text.

    Raises
    ------
    TypeError
        ``name`` not a string.
    ValueError
        A name with neither a unit suffix nor a known unitless meaning.
    """
    if not isinstance(name, str):
        raise TypeError(f"column name must be a string, got {type(name).__name__} {name!r}")
    if name in PLAIN_UNITS:
        return PLAIN_UNITS[name]
    for suffix in _SUFFIXES:
        if name.endswith(suffix) and len(name) > len(suffix):
            return SUFFIX_UNITS[suffix]
    for prefix, unit in PLAIN_PREFIX_UNITS.items():
        if name.startswith(prefix) and len(name) > len(prefix):
            return unit
    raise ValueError(f"column {name!r} has no unit: it neither ends with a unit suffix "
                     f"({', '.join(_SUFFIXES)}) nor is a known label, count or ratio")


def table_units(columns) -> dict[str, str]:
    """Column -> unit (:func:`column_unit`) of each of ``columns``, in order."""
    if isinstance(columns, str):
        raise TypeError("columns must be a sequence of column names, got a string")
    return {c: column_unit(c) for c in columns}


#: table name -> its columns, in order; a column a CSV of the run holds has that CSV's name
#: and unit, and the passes table's first columns are those of passes_<gear>.csv in its order
COLUMNS: dict[str, tuple[str, ...]] = {
    "passes": ("gauge", "time_s", "planet", "revolution", "gamma_cycles", "uncertainty_cycles",
               "mesh_period_s", "ref_time_s", "angle_rad", "timing_floor_cycles",
               "model_sigma_cycles", "gamma_ideal_cycles", "gamma_model_cycles",
               "residual_ideal_cycles", "residual_model_cycles"),
    "phasing": ("gauge", "planet", "n_passes", "gamma_mean_cycles", "gamma_std_cycles",
                "gamma_range_cycles", "median_uncertainty_cycles", "gamma_ideal_cycles",
                "gamma_model_cycles", "residual_ideal_mean_cycles", "residual_ideal_rms_cycles",
                "residual_model_mean_cycles", "residual_model_rms_cycles", "band_dev_lo_cycles",
                "band_dev_hi_cycles"),
    "load_sharing": ("planet", "load_sharing", "std_error", "n_passes", "mean_amplitude_strain"),
    "comparison": ("gauge", "reference", "n_passes", "mean_cycles", "rms_cycles",
                   "max_abs_cycles", "std_cycles", "coverage"),
    "identification": ("gear", "e_m", "e_std_m", "e_ci95_lo_m", "e_ci95_hi_m", "kappa_rad",
                       "kappa_std_rad", "identifiable", "note", "identified_by",
                       "predicted_std_m", "record_factor", "record_predicted_std_m"),
    "centroids": ("gear", "centroid_m", "std_error_m", "contact_fraction", "shape",
                  "residual_rms_strain"),
}

#: table name -> (what a row is, the CSV file with the same columns or None)
TABLES: dict[str, tuple[str, str | None]] = {
    "passes": ("one row per measured pass of each gauge: its phasing and uncertainty, the "
               "ideal and identified-model phasing at it and the residuals (wrapped to "
               "[-0.5, 0.5))", "passes_<gear>.csv"),
    "phasing": ("one row per gauge and measured planet: circular mean, standard deviation and "
                "range of the passes' phasing, the ideal and model phasing, residual statistics "
                "and the Monte Carlo band of the deviation from the ideal", None),
    "load_sharing": ("one row per planet: load-sharing factor (1: equal), its standard error, "
                     "the passes used and the mean peak strain of the planet's pulses",
                     "load_sharing.csv"),
    "comparison": ("one row per gauge and reference (ideal, model, truth): statistics of the "
                   "residual measured - reference and the share of passes inside the Monte "
                   "Carlo band", None),
    "identification": ("one row per gear: the identified shaft hole error and its angle with "
                       "their uncertainties, whether the data can tell it, and what would",
                       "identified_errors.csv"),
    "centroids": ("one row per gear with face-width gauges: load centroid from the face centre, "
                  "its standard error, the loaded share of the face, the load shape and the "
                  "fit's RMS misfit", None),
}

#: table -> {column name of the previous release: (its column now, factor)}: ``df[old]``
#: answers ``df[new] * factor`` (the old unit) with a FutureWarning, for one release
RENAMED: dict[str, dict[str, tuple[str, float]]] = {
    "passes": {"phasing_cycles": ("gamma_cycles", 1.0), "sigma_cycles": ("uncertainty_cycles", 1.0),
               "ideal_cycles": ("gamma_ideal_cycles", 1.0),
               "model_cycles": ("gamma_model_cycles", 1.0)},
    "phasing": {"mean_cycles": ("gamma_mean_cycles", 1.0), "sd_cycles": ("gamma_std_cycles", 1.0),
                "range_cycles": ("gamma_range_cycles", 1.0),
                "median_sigma_cycles": ("median_uncertainty_cycles", 1.0),
                "ideal_cycles": ("gamma_ideal_cycles", 1.0),
                "model_cycles": ("gamma_model_cycles", 1.0)},
    "load_sharing": {"mean_amplitude_ustrain": ("mean_amplitude_strain", 1e6)},
    "comparison": {"sd_cycles": ("std_cycles", 1.0), "inside_band_fraction": ("coverage", 1.0)},
    "identification": {"e_um": ("e_m", 1e6), "e_std_um": ("e_std_m", 1e6),
                       "e_ci95_lo_um": ("e_ci95_lo_m", 1e6), "e_ci95_hi_um": ("e_ci95_hi_m", 1e6),
                       "kappa_deg": ("kappa_rad", 180.0 / math.pi),
                       "kappa_std_deg": ("kappa_std_rad", 180.0 / math.pi)},
    "centroids": {"centroid_mm": ("centroid_m", 1e3), "std_error_mm": ("std_error_m", 1e3),
                  "residual_rms": ("residual_rms_strain", 1.0)},
}

#: the release that drops the names of :data:`RENAMED`
_RENAMED_UNTIL = "0.2"

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
                "gauge": gauge, "time_s": float(t.time[i]), "planet": int(t.planet[i]),
                "revolution": int(t.revolution[i]), "gamma_cycles": float(t.gamma[i]),
                "uncertainty_cycles": float(t.uncertainty[i]),
                "mesh_period_s": float(t.mesh_period[i]), "ref_time_s": float(t.ref_time[i]),
                "angle_rad": float(t.angle[i]), "timing_floor_cycles": float(t.timing_floor[i]),
                "model_sigma_cycles": float(t.model_sigma[i]),
                "gamma_ideal_cycles": float(ideal[i]), "gamma_model_cycles": float(model[i]),
                "residual_ideal_cycles": float(r_ideal[i]),
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
                "gauge": gauge, "planet": planet, "n_passes": s["n"],
                "gamma_mean_cycles": s["mean"], "gamma_std_cycles": s["std"],
                "gamma_range_cycles": s["range"],
                "median_uncertainty_cycles": (float(np.median(t.uncertainty[m])) if m.any()
                                              else _NAN),
                "gamma_ideal_cycles": (float(ideal_n[planet - 1]) if ideal_n is not None
                                       else circular_mean(ideal[m])),
                "gamma_model_cycles": circular_mean(model[m]),
                "residual_ideal_mean_cycles": _per_planet(cmp and cmp.vs_ideal, planet, "mean"),
                "residual_ideal_rms_cycles": _per_planet(cmp and cmp.vs_ideal, planet, "rms"),
                "residual_model_mean_cycles": _per_planet(cmp and cmp.vs_model, planet, "mean"),
                "residual_model_rms_cycles": _per_planet(cmp and cmp.vs_model, planet, "rms"),
                "band_dev_lo_cycles": float(band["lo"][planet - 1]) if band else _NAN,
                "band_dev_hi_cycles": float(band["hi"][planet - 1]) if band else _NAN})
    return rows


def load_sharing_rows(ctx: RunResults) -> list[dict]:
    """One row per planet: load-sharing factor LS_n [-] (1 = equal), its standard error [-],
    the passes it comes from and the mean peak strain of the planet's pulses [m/m]: the rows
    of load_sharing.csv."""
    _check(ctx)
    if ctx.load_sharing is None or ctx.load_sharing.sharing is None:
        return []
    return [{"planet": r["planet"], "load_sharing": r["load_sharing"],
             "std_error": r["std_error"], "n_passes": r["n_passes"],
             "mean_amplitude_strain": r["mean_amplitude"]}
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
                         "std_cycles": float(s.get("std", _NAN)), "coverage": inside})
    return rows


def _num(v) -> float:
    return _NAN if v is None else float(v)


def identification_rows(ctx: RunResults) -> list[dict]:
    """One row per gear (sun, ring, planet1..N), the rows of identified_errors.csv: the
    identified shaft hole error e [m] with its one-sigma and 95 % interval [m], its angle
    kappa [rad] with its one-sigma [rad], whether the data can tell it and why not (NaN values
    where they cannot); for a gear not identifiable, the first addition that would identify
    it (``identified_by``), the standard deviation predicted with it [m], the shortest longer
    record that would (as a multiple of this one's length [-]) and the standard deviation
    predicted with that record [m]."""
    _check(ctx)
    if ctx.identify is None:
        return []
    ident = ctx.identify.identification
    sugg = {sg["gear"]: sg for sg in ident.suggestions}
    rows = []
    for r in ident.table:
        lo, hi = (list(r.get("e_ci95") or [None, None]) + [None, None])[:2]
        sg = sugg.get(r["gear"])
        rows.append({"gear": r["gear"], "e_m": _num(r.get("e")), "e_std_m": _num(r.get("e_std")),
                     "e_ci95_lo_m": _num(lo), "e_ci95_hi_m": _num(hi),
                     "kappa_rad": _num(r.get("kappa")), "kappa_std_rad": _num(r.get("kappa_std")),
                     "identifiable": bool(r.get("identifiable")), "note": r.get("note") or "",
                     "identified_by": ("" if sg is None
                                       else (sg["option"] or "none of the options tried")),
                     "predicted_std_m": _NAN if sg is None else _num(sg.get("predicted_std")),
                     "record_factor": _NAN if sg is None else _num(sg.get("record_factor")),
                     "record_predicted_std_m": (_NAN if sg is None
                                                else _num(sg.get("record_predicted_std")))})
    return rows


def centroid_rows(ctx: RunResults) -> list[dict]:
    """One row per gear with face-width gauges: load centroid Z [m] from the face centre and
    its standard error [m], the loaded share of the face [-], the load shape and the fit's
    RMS misfit [strain] (summary.json's ``centroids_m``); NaN for a gear with too few
    positioned gauges."""
    _check(ctx)
    if ctx.centroids is None:
        return []
    rows = []
    for gear, c in ctx.centroids.by_gear.items():
        if c is None:
            rows.append({"gear": gear, "centroid_m": _NAN, "std_error_m": _NAN,
                         "contact_fraction": _NAN, "shape": "none", "residual_rms_strain": _NAN})
        else:
            rows.append({"gear": gear, "centroid_m": float(c.centroid),
                         "std_error_m": float(c.std_error),
                         "contact_fraction": float(c.contact_fraction), "shape": c.shape,
                         "residual_rms_strain": float(c.residual_rms)})
    return rows


def frame(rows: list[dict], name: str):
    """A :class:`ResultFrame` of ``rows`` with the columns of table ``name`` (:data:`COLUMNS`),
    also when there are no rows.

    Parameters
    ----------
    rows : list of dict
        What the table's ``*_rows`` function returns.
    name : str
        A table of :data:`COLUMNS`.

    Returns
    -------
    ResultFrame
        ``attrs``: ``table`` (``name``), ``description`` (what a row is), ``file`` (the CSV a
        run writes with these columns, or None) and ``units`` (column -> unit,
        :func:`column_unit`).

    Raises
    ------
    ValueError
        An unknown table.
    TypeError
        ``rows`` not a list of dicts.
    """
    if not isinstance(name, str) or name not in COLUMNS:
        raise ValueError(f"unknown table {name!r}; tables: {', '.join(COLUMNS)}")
    if not isinstance(rows, (list, tuple)) or any(not isinstance(r, dict) for r in rows):
        raise TypeError(f"rows must be a list of dicts, got {type(rows).__name__}")
    cls = _result_frame_class()
    df = cls(list(rows), columns=list(COLUMNS[name]))
    df._table = name
    description, file = TABLES[name]
    df.attrs.update(table=name, description=description, file=file,
                    units=table_units(COLUMNS[name]))
    return df


def _renamed_column(table: str | None, key, present, stacklevel: int):
    """``key`` (a column name or a list of them) with each name of the previous release that
    is not a column of ``present`` replaced by the current one, with a FutureWarning each:
    (key, {old name: (new name, factor)} of the names replaced)."""
    renamed = RENAMED.get(table) if table is not None else None
    if not renamed:
        return key, {}
    if isinstance(key, str):
        keys, single = [key], True
    elif isinstance(key, list) and all(isinstance(k, str) for k in key):
        keys, single = key, False
    else:
        return key, {}
    hits = {k: renamed[k] for k in keys if k in renamed and k not in present}
    for old, (new, factor) in hits.items():
        how = (f"df[{old!r}] gives df[{new!r}] * {factor:.15g} (the old unit)"
               if factor != 1.0 else f"df[{old!r}] gives df[{new!r}]")
        warnings.warn(f"the {table} table's column {old!r} is now {new!r} "
                      f"[{column_unit(new)}] (the name and unit of the CSV a run writes); "
                      f"{how} until meshphase {_RENAMED_UNTIL}", FutureWarning,
                      stacklevel=stacklevel + 1)
    new_keys = [hits[k][0] if k in hits else k for k in keys]
    return (new_keys[0] if single else new_keys), hits


def _result_frame_class():
    """The :class:`ResultFrame` class, made on first use (pandas is imported then)."""
    cls = globals().get("_ResultFrame")
    if cls is not None:
        return cls
    import pandas as pd  # heavy: only when a table is asked for

    class ResultFrame(pd.DataFrame):
        """A result table (:func:`frame`): a pandas DataFrame that answers a column name of the
        previous release (:data:`RENAMED`) for one release, with a FutureWarning naming the
        column that replaced it, in its unit then.

        The table's name is kept in the ``_table`` attribute (pandas' ``_metadata``), which
        pandas carries to the result of an operation through ``_constructor`` and
        ``__finalize__``: selecting rows or columns, ``head``, ``copy``, ``sort_values``,
        ``query``, ``assign``, ``reset_index``, ``dropna``, ``rename``, arithmetic, pickling;
        ``pd.concat`` and ``merge`` keep the class and ``attrs`` but not ``_metadata``, and
        the name is read from ``attrs["table"]`` then (concat: when every part has the same
        ``attrs``). The old names are answered by
        ``df[old]``, ``df[[..., old, ...]]`` and ``df.old``; not by ``.loc`` / ``.iloc``,
        ``query`` strings, ``groupby(...)[old]``, assignment (``df[old] = ...`` adds a
        column), nor by what leaves pandas (``to_numpy``, ``to_dict``, ``to_csv`` write the
        current names).
        """

        _metadata = ["_table"]
        _table = None

        @property
        def _constructor(self):
            return ResultFrame

        def __getitem__(self, key):
            return self._select(key, stacklevel=3)

        def __getattr__(self, name):
            if (not name.startswith("_") and name in RENAMED.get(self._table_name(), {})
                    and name not in self.columns):
                return self._select(name, stacklevel=3)
            return super().__getattr__(name)

        def _table_name(self):
            """The table's name: ``_table``, else ``attrs["table"]`` (what ``pd.concat``
            and ``merge`` keep)."""
            if self._table is not None:
                return self._table
            name = self.attrs.get("table")
            return name if isinstance(name, str) else None

        def _select(self, key, stacklevel):
            table = self._table_name()
            if table is None or not isinstance(key, (str, list)):
                return super().__getitem__(key)
            key, hits = _renamed_column(table, key, set(self.columns), stacklevel)
            out = super().__getitem__(key)
            if not hits:
                return out
            if isinstance(out, pd.Series):
                (old, (_, factor)), = hits.items()
                return (out * factor if factor != 1.0 else out).rename(old)
            out = out.copy()
            for new, factor in hits.values():
                if factor != 1.0:
                    out[new] = out[new] * factor
            return out.rename(columns={new: old for old, (new, _) in hits.items()})

    ResultFrame.__module__ = __name__
    ResultFrame.__qualname__ = "ResultFrame"
    globals()["_ResultFrame"] = ResultFrame
    return ResultFrame


def __getattr__(name: str):
    """``ResultFrame``: the class, made (and pandas imported) on first use."""
    if name == "ResultFrame":
        return _result_frame_class()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
