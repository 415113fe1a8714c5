"""The CSV tables and summary.json of a run are tidy (issue 12, item 7): a unit in every
header of a dimensional column, one number per field (interval bounds in two columns), NaN
as an empty field, bearing moments and tilt results as CSV; summary.json's numbers are
numbers (data_schemas/outputs.md lists every column)."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pandas as pd
import pytest
from seed_rig_toml import SEED_RIG_GEARSET

import meshphase.io
from meshphase.run.outputs import PASS_COLUMNS
from meshphase.run.scene import load_scene
from meshphase.run.stages import process_recording, run_scene, write_outputs

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
SCHEMA_DOC = Path(__file__).resolve().parents[1] / "data_schemas" / "outputs.md"

#: unit suffixes a dimensional column ends with
UNITS = ("_s", "_m", "_rad", "_cycles", "_strain", "_N", "_Nm", "_Nm_per_rad", "_N_per_m")
#: columns that are labels, counts, flags, text or dimensionless ratios (no unit)
UNITLESS = re.compile(r"^(gauge|planet|revolution|gear|identifiable|note|stage|status|error_estimate|"
                      r"load_sharing|std_error|n_passes|moments|converged|iterations|method|"
                      r"contact_fraction_\w+|face_load_factor_\w+|"
                      r"identified_by|record_factor|combination|description|"
                      r"relative_singular_value|coef_\w+)$")


def _has_unit(col: str) -> bool:
    return col.endswith(UNITS) or bool(UNITLESS.match(col))


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
