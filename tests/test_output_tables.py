"""The CSV tables and summary.json of a run are tidy: a unit in every header of a
dimensional column (one unit table, meshphase.report.frames.column_unit, which the
documentation's unit column agrees with), one number per field (interval bounds in two
columns), NaN as an empty field, bearing moments and tilt results as CSV; summary.json's
numbers are numbers and its rows shared with a CSV carry the CSV's names
(data_schemas/outputs.md lists every column)."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pandas as pd
import pytest
from seed_rig_toml import SEED_RIG_GEARSET

import meshphase.io
from meshphase.report.frames import column_unit
from meshphase.run.outputs import PASS_COLUMNS, SUMMARY_RENAMED
from meshphase.run.scene import load_scene
from meshphase.run.stages import process_recording, run_scene, write_outputs

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
SCHEMA_DOC = Path(__file__).resolve().parents[1] / "data_schemas" / "outputs.md"

#: the unit column of data_schemas/outputs.md -> column_unit's unit
DOC_UNITS = {"label": "", "text": "", "flag": "", "count": "1", "ratio": "1", "fraction": "1",
             "mesh cycles": "cycles", "m/m": "strain", "s": "s", "m": "m", "rad": "rad", "N": "N",
             "N·m": "N*m", "N·m/rad": "N*m/rad", "N/m": "N/m"}


def _has_unit(col: str) -> bool:
    try:
        column_unit(col)
    except ValueError:
        return False
    return True


def _documented_units() -> dict:
    """Column -> the unit outputs.md's tables give it (rows with one unit for named columns),
    from the CSV tables (column | unit | meaning) and the Python tables (table | column | ...)."""
    out, first = {}, None
    for line in SCHEMA_DOC.read_text(encoding="utf-8").splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if cells[-3:] == ["column", "unit", "meaning"]:
            first = len(cells) - 3
        if not line.startswith("|"):
            first = None
        if first is None or len(cells) != first + 3 or "," in cells[first + 1]:
            continue
        for col in re.findall(r"`([^`]+)`", cells[first]):
            if "<" not in col and "." not in col:
                out[col] = cells[first + 1]
    return out


def test_documented_units_are_the_unit_table():
    doc = _documented_units()
    assert len(doc) > 60 and {"gamma_cycles", "e_m", "mean_amplitude_strain", "wall_time_s"} <= set(doc)
    assert {"coverage", "median_uncertainty_cycles", "residual_ideal_cycles"} <= set(doc)
    wrong = {c: (u, column_unit(c)) for c, u in doc.items() if DOC_UNITS[u] != column_unit(c)}
    assert not wrong


def test_every_python_table_column_is_documented():
    from meshphase.report.frames import COLUMNS, RENAMED

    doc = SCHEMA_DOC.read_text(encoding="utf-8")
    for table, cols in COLUMNS.items():
        missing = [c for c in cols if f"`{c}`" not in doc]
        assert not missing, (table, missing)
        missing = [old for old in RENAMED[table] if f"`{old}`" not in doc]
        assert not missing, (table, missing)


def test_column_unit_bad_input():
    with pytest.raises(ValueError, match="has no unit"):
        column_unit("amplitude")
    with pytest.raises(ValueError, match="has no unit"):
        column_unit("")
    with pytest.raises(ValueError, match="has no unit"):
        column_unit("_m")                               # a suffix alone names nothing
    with pytest.raises(TypeError, match="must be a string"):
        column_unit(3)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """A processed recording (phasing, load sharing, identification) and the single and double
    pinion bearing scenes: name -> output folder."""
    from meshphase.synthetic import generate

    d = tmp_path_factory.mktemp("tables")
    rec, _ = generate("seed_rig", duration=20.0, seed=4)
    path = meshphase.io.write(rec, d / "rig.h5")
    gs = d / "gearset.toml"
    gs.write_text('name = "rig"\n' + SEED_RIG_GEARSET, encoding="utf-8")
    _, files = process_recording(path, gs, out_dir=d / "process")
    outs = {"process": files["summary"].parent}
    for name in ("bearing_moments", "bearing_double_pinion"):
        ctx = run_scene(load_scene(EXAMPLES / f"{name}.toml"))
        out = d / name
        out.mkdir()
        write_outputs(ctx, out, report=False)
        outs[name] = out
    return outs


def test_every_csv_header_has_its_unit(runs):
    seen = set()
    for out in runs.values():
        for p in out.glob("*.csv"):
            cols = list(pd.read_csv(p).columns)
            bad = [c for c in cols if not _has_unit(c)]
            assert not bad, f"{p.name}: columns without a unit: {bad}"
            seen.add(p.name)
    assert {"passes_sun.csv", "passes_ring.csv", "load_sharing.csv", "identified_errors.csv",
            "stages.csv", "bearing_moments.csv", "tilt.csv"} <= seen


def test_every_csv_column_is_documented(runs):
    doc = SCHEMA_DOC.read_text(encoding="utf-8")
    for out in runs.values():
        for p in out.glob("*.csv"):
            for c in pd.read_csv(p).columns:
                # per-mesh columns are documented with <mesh> in place of the mesh name
                generic = re.sub(r"_(sun_sp|sp_rp|rp_ring|sun|ring)(?=_|$)", "_<mesh>", c, count=1)
                # per-planet columns with <n> in place of the planet number
                numbered = re.sub(r"planet\d+", "planet<n>", c)
                assert (f"`{c}`" in doc or f"`{generic}`" in doc or f"`{numbered}`" in doc), \
                    f"{p.name}: {c} not in outputs.md"


def test_interval_bounds_are_numbers_and_nan_is_an_empty_field(runs):
    p = runs["process"] / "identified_errors.csv"
    text = p.read_text()
    assert "[" not in text and "nan" not in text.lower().replace("identifiable", "")
    df = pd.read_csv(p)
    assert {"e_m", "e_std_m", "e_ci95_lo_m", "e_ci95_hi_m", "kappa_rad", "kappa_std_rad"} <= set(df.columns)
    for c in ("e_m", "e_ci95_lo_m", "e_ci95_hi_m"):
        assert pd.api.types.is_float_dtype(df[c])       # numbers (NaN where not identifiable)
    ok = df["identifiable"]
    assert (df.loc[ok, "e_ci95_lo_m"] <= df.loc[ok, "e_m"]).all()
    assert (df.loc[ok, "e_m"] <= df.loc[ok, "e_ci95_hi_m"]).all()
    assert df.loc[~ok, ["e_m", "e_ci95_lo_m", "e_ci95_hi_m"]].isna().all().all()


def test_passes_columns_carry_cycles_and_seconds(runs):
    df = pd.read_csv(runs["process"] / "passes_sun.csv")
    assert list(df.columns[:len(PASS_COLUMNS)]) == list(PASS_COLUMNS.values())
    assert {"gamma_ideal_cycles", "gamma_model_cycles"} <= set(df.columns)
    assert df["gamma_cycles"].between(0.0, 1.0).all() and (df["time_s"] > 0).all()


def test_bearing_moments_and_tilt_as_csv_match_summary(runs):
    for name in ("bearing_moments", "bearing_double_pinion"):
        out = runs[name]
        summary = json.loads((out / "summary.json").read_text())
        bm = pd.read_csv(out / "bearing_moments.csv")
        conc = bm[bm["moments"] == "concentrated"].iloc[0]
        for k, v in summary["bearing_moments"]["concentrated"].items():
            if not k.startswith("z"):
                assert conc[f"{k}_Nm"] == pytest.approx(v, abs=1e-12), (name, k)
        tilt = pd.read_csv(out / "tilt.csv")
        assert list(tilt["k_tilt_Nm_per_rad"]) == [t["k_tilt_Nm_per_rad"] for t in summary["tilt"]]
        for (_, row), t in zip(tilt.iterrows(), summary["tilt"]):
            z_cols = [c for c in tilt.columns if c.startswith("z_") and c.endswith("_m")]
            assert [row[c] for c in z_cols] == pytest.approx(t["z_m"], abs=1e-15)
            assert row["my_Nm" if "my_Nm" in tilt.columns else "my_sp_Nm"] == pytest.approx(
                t["moments"]["my" if "my" in t["moments"] else "my_sp"])
            assert bool(row["converged"]) == t["converged"]


def _number_like_strings(obj, path=""):
    """Paths of strings in a JSON tree that hold a number, a NaN or a bracketed list."""
    if isinstance(obj, dict):
        return [p for k, v in obj.items() for p in _number_like_strings(v, f"{path}.{k}")]
    if isinstance(obj, list):
        return [p for i, v in enumerate(obj) for p in _number_like_strings(v, f"{path}[{i}]")]
    if isinstance(obj, str) and re.fullmatch(r"\s*([-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?|[-+]?(nan|inf)"
                                             r"|\[.*\])\s*", obj, re.I):
        return [path]
    if isinstance(obj, float):
        assert math.isfinite(obj), path                  # strict JSON: no NaN, no Infinity
    return []


def test_summary_numbers_are_numbers(runs):
    for name, out in runs.items():
        summary = json.loads((out / "summary.json").read_text())
        # the seed 001 case names ("1", "2", ...) are labels, not numbers
        found = [p for p in _number_like_strings(summary) if p != ".bearing_moments.case"]
        assert not found, (name, found)
        if "identify" in summary:
            for row in summary["identify"]["table"]:
                assert isinstance(row["e_ci95"], list) and len(row["e_ci95"]) == 2


def _same(json_value, csv_value) -> bool:
    """A summary.json number and a CSV field: equal, or null and empty (NaN)."""
    if json_value is None:
        return isinstance(csv_value, float) and math.isnan(csv_value)
    return json_value == csv_value


def test_summary_rows_carry_the_csv_names(runs):
    """summary.json's rows shared with a CSV: the CSV's names and values, and for one release
    the previous names beside them (SUMMARY_RENAMED)."""
    out = runs["process"]
    summary = json.loads((out / "summary.json").read_text())
    ls = pd.read_csv(out / "load_sharing.csv")
    for row, (_, csv) in zip(summary["load_sharing"], ls.iterrows(), strict=True):
        assert _same(row["mean_amplitude_strain"], csv["mean_amplitude_strain"])
        assert row["mean_amplitude"] == row["mean_amplitude_strain"]      # deprecated
        assert set(csv.index) <= set(row)
    ident = pd.read_csv(out / "identified_errors.csv")
    for row, (_, csv) in zip(summary["identify"]["table"], ident.iterrows(), strict=True):
        for c in ("e_m", "e_std_m", "e_ci95_lo_m", "e_ci95_hi_m", "kappa_rad", "kappa_std_rad"):
            assert _same(row[c], csv[c]), c
        assert row["e_ci95"] == [row["e_ci95_lo_m"], row["e_ci95_hi_m"]]   # deprecated
    comb = pd.read_csv(out / "identified_combinations.csv")
    for row, (_, csv) in zip(summary["identify"]["combinations"], comb.iterrows(), strict=True):
        for c in ("estimate_m", "std_m", "ci95_lo_m", "ci95_hi_m"):
            assert _same(row[c], csv[c]), c
    for gear, ph in summary["phasing"].items():
        for p, v in ph["per_planet"].items():
            assert {"n_passes", "gamma_mean_cycles", "gamma_std_cycles", "gamma_range_cycles"} <= set(v)
            for old, new in SUMMARY_RENAMED["phasing.per_planet"].items():
                assert v[old] == v[new], (gear, p, old)
