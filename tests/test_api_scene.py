"""The scene meshphase.process builds from a gearset given as a path, a dict, a Gearset or a
scene; the dict -> TOML writer; the frames of hand-built stage results (identification and
centroids with values, units converted)."""

import math
import tomllib

import numpy as np
import pytest

from meshphase.api.scene import build_scene, gearset_table, toml_text
from meshphase.run.stages import PROCESS_RESULTS
from meshphase.compare.predict import Identification, wrap
from meshphase.run.demo import demo_scene_path
from meshphase.kinematics.loads import CentroidResult
from meshphase.models.gearset import Gearset
from meshphase.models.mesh_phasing import ShaftHoleErrors
from meshphase.report.frames import (COLUMNS, RENAMED, table_units, centroid_rows, circular_mean, comparison_rows,
                                     frame, identification_rows, load_sharing_rows, passes_rows,
                                     phasing_rows)
from meshphase.run.context import RunContext
from meshphase.run.results import CentroidsStage, IdentifyStage
from meshphase.run.scene import Scene, SceneError

TABLE = {"z_sun": 25, "z_ring": 87, "z_planet": 29, "n_planets": 4, "carrier_radius_mm": 112.5,
         "face_width_mm": 40, "direction": "cw", "profile_shift": True}


def _same_gearset(a: Gearset, b: Gearset) -> None:
    assert (a.z_sun, a.z_ring, a.z_planet, a.n_planets) == (b.z_sun, b.z_ring, b.z_planet,
                                                            b.n_planets)
    assert a.carrier_radius == pytest.approx(b.carrier_radius, rel=1e-12)
    np.testing.assert_allclose(a.angles, b.angles, atol=1e-12)


# ----------------------------------------------------------------------------- gearset forms
def test_every_gearset_form_gives_the_same_gearset(tmp_path):
    from_path = build_scene(demo_scene_path(tmp_path))
    g = from_path.gearset
    for form in (TABLE, g, g.to_dict(), {"name": "s", "gearset": TABLE}):
        _same_gearset(build_scene(form).gearset, g)
    assert build_scene(None, None, meta_gearset=g.to_dict).gearset.z_ring == 87


def test_results_default_to_the_cli_process(tmp_path):
    sc = build_scene(demo_scene_path(tmp_path))
    assert sc.results == list(PROCESS_RESULTS)           # as `meshphase process`
    assert sc.tolerances is None                         # set aside: no Monte Carlo unless asked
    mc = build_scene(demo_scene_path(tmp_path), tolerance=True)
    assert mc.results == list(PROCESS_RESULTS) + ["tolerance"] and mc.tolerances is not None
    with pytest.raises(ValueError, match="tolerances"):
        build_scene(TABLE, tolerance=True)               # a bare gearset has none
    assert build_scene(TABLE, results="phasing").results == ["phasing"]


def test_a_scene_object_is_copied_not_changed(tmp_path):
    sc = build_scene(demo_scene_path(tmp_path))
    before = (dict(sc.input), list(sc.results))
    out = build_scene(scene=sc, results=["phasing"])
    out.input["recording"] = "x.h5"
    assert out is not sc and (sc.input, sc.results) == before


def test_gearset_table_uneven_planets_and_no_profile_shift():
    g = Gearset(24, 84, 30, (0.0, 2 * math.pi * 27 / 108, 2 * math.pi * 54 / 108), 0.1)
    t = gearset_table(g)
    assert "n_planets" not in t and len(t["planet_angles_deg"]) == 3
    assert "profile_shift" not in t                      # 24 + 2 x 30 = 84: coaxial
    _same_gearset(build_scene(g).gearset, g)


def test_a_bad_gearset_is_a_scene_error_naming_the_key():
    bad = dict(TABLE, profile_shift=False)
    with pytest.raises(SceneError, match="z_planet"):
        build_scene(bad)
    with pytest.raises(SceneError, match="carrier_radius_mm"):
        build_scene(dict(TABLE, carrier_radius_mm=0.1125))


def test_build_scene_empty_and_bad_input(tmp_path):
    with pytest.raises(ValueError, match="needs a gearset"):
        build_scene()
    with pytest.raises(ValueError, match="needs a gearset"):
        build_scene(meta_gearset=lambda: None)
    with pytest.raises(SceneError):
        build_scene({})                                  # an empty [gearset] table
    with pytest.raises(TypeError, match="gearset must be"):
        build_scene(3.5)
    with pytest.raises(TypeError, match="scene must be"):
        build_scene(scene=3.5)
    with pytest.raises(TypeError, match="not both"):
        build_scene(TABLE, scene=TABLE)
    with pytest.raises(FileNotFoundError):
        build_scene(tmp_path / "missing.toml")
    with pytest.raises(TypeError, match="results must be"):
        build_scene(TABLE, results=[1, 2])


# ----------------------------------------------------------------------------- TOML writer
def test_toml_text_round_trips():
    d = {"name": 'a "quoted" name\\with\nlines', "results": ["phasing"],
         "gearset": {"z_sun": 25, "angles": [0.0, 1.5e-300, 90.5], "shift": True},
         "channels": [{"name": "SG01", "kind": "sun"}, {"name": "SG 02", "gain": np.float64(2.0)}],
         "input": {"window": {"start_s": 1.0}}}
    back = tomllib.loads(toml_text(d))
    assert back == {**d, "channels": [{"name": "SG01", "kind": "sun"},
                                      {"name": "SG 02", "gain": 2.0}]}


def test_toml_text_empty_and_bad_input():
    assert tomllib.loads(toml_text({})) == {}
    with pytest.raises(TypeError, match="must be a dict"):
        toml_text([("a", 1)])
    with pytest.raises(TypeError, match="cannot be written"):
        toml_text({"a": object()})
    with pytest.raises(TypeError, match="non-empty strings"):
        toml_text({1: 2})
    assert "nan" in toml_text({"a": float("nan")})       # the scene's own check refuses it
    with pytest.raises(TypeError, match="must be a Gearset"):
        gearset_table(TABLE)


# ----------------------------------------------------------------------------- frames
def _ctx() -> RunContext:
    return RunContext(Scene(path=None, name="t", results=[]))


def test_identification_rows_in_m_and_rad():
    ctx = _ctx()
    table = [{"gear": "sun", "e": 2.0e-4, "e_std": 1.0e-5, "e_ci95": [1.8e-4, 2.2e-4],
              "kappa": math.pi / 2, "kappa_std": math.pi / 180, "identifiable": True, "note": ""},
             {"gear": "ring", "e": float("nan"), "e_std": float("nan"), "e_ci95": None,
              "kappa": float("nan"), "kappa_std": float("nan"), "identifiable": False,
              "note": "not identifiable"}]
    ident = Identification(ShaftHoleErrors(), table, {}, np.ones(1), 0.1, 0.01, 0.01, 10, 2, 1,
                           0.0, False)
    ctx.record("identify", IdentifyStage(identification=ident))
    rows = identification_rows(ctx)
    assert {k: v for k, v in rows[0].items() if not isinstance(v, float) or not math.isnan(v)} == {
        "gear": "sun", "e_m": 2.0e-4, "e_std_m": 1.0e-5, "e_ci95_lo_m": 1.8e-4, "e_ci95_hi_m": 2.2e-4,
        "kappa_rad": math.pi / 2, "kappa_std_rad": math.pi / 180, "identifiable": True, "note": "",
        "identified_by": ""}                         # no suggestion: its numbers NaN
    assert math.isnan(rows[1]["e_ci95_lo_m"]) and rows[1]["note"] == "not identifiable"
    assert list(frame(rows, "identification").columns) == list(COLUMNS["identification"])


def test_centroid_rows_in_m():
    ctx = _ctx()
    ctx.record("centroids", CentroidsStage(by_gear={
        "sun": CentroidResult(centroid=2.5e-3, std_error=1e-4, contact_fraction=1.0,
                              shape="linear", residual_rms=1e-6), "ring": None}))
    sun, ring = centroid_rows(ctx)
    assert sun["centroid_m"] == 2.5e-3 and sun["std_error_m"] == 1e-4
    assert sun["residual_rms_strain"] == 1e-6
    assert sun["shape"] == "linear" and ring["shape"] == "none"
    assert math.isnan(ring["centroid_m"])
    df = frame([sun, ring], "centroids")
    with pytest.warns(FutureWarning, match="'centroid_mm' is now 'centroid_m'"):
        assert df["centroid_mm"].iloc[0] == pytest.approx(2.5)


def test_rows_of_a_run_without_stages_and_bad_input():
    ctx = _ctx()
    for fn in (passes_rows, phasing_rows, load_sharing_rows, comparison_rows,
               identification_rows, centroid_rows):
        assert fn(ctx) == []
        with pytest.raises(TypeError, match="RunContext"):
            fn({"phasing": None})
    with pytest.raises(ValueError, match="unknown table"):
        frame([], "nope")


def test_circular_mean():
    assert abs(wrap(circular_mean([0.98, 0.02]))) < 1e-12      # across the wrap, not 0.5
    assert circular_mean([0.2, 0.3]) == pytest.approx(0.25)
    assert math.isnan(circular_mean([]))
    assert math.isnan(circular_mean([float("nan")]))


def test_frame_attrs_carry_table_units_and_file():
    for name, cols in COLUMNS.items():
        df = frame([], name)                               # empty: columns and attrs still there
        assert df.empty and list(df.columns) == list(cols)
        assert list(df.attrs["units"]) == list(cols) and df.attrs["table"] == name
        assert df.attrs["description"]
    assert frame([], "passes").attrs["file"] == "passes_<gear>.csv"
    assert frame([], "phasing").attrs["file"] is None
    assert table_units([]) == {}
    assert table_units(["time_s", "gauge", "coef_sun_x"]) == {"time_s": "s", "gauge": "",
                                                             "coef_sun_x": "1"}


def test_frame_and_table_units_bad_input():
    with pytest.raises(TypeError, match="rows must be a list of dicts"):
        frame([1, 2], "passes")
    with pytest.raises(TypeError, match="rows must be a list of dicts"):
        frame({"gauge": "sun"}, "passes")
    with pytest.raises(ValueError, match="unknown table"):
        frame([], 3)
    with pytest.raises(TypeError, match="not a string|sequence of column names"):
        table_units("time_s")
    with pytest.raises(ValueError, match="has no unit"):
        table_units(["time_s", "amplitude"])


def test_renamed_columns_point_at_current_columns_with_their_unit():
    """Every name of the previous release maps onto a column of its table; the factor turns
    the current SI value back into the old unit (um, deg, mm, microstrain)."""
    for table, renamed in RENAMED.items():
        for old, (new, factor) in renamed.items():
            assert new in COLUMNS[table] and old not in COLUMNS[table], (table, old)
            assert factor > 0
    assert RENAMED["identification"]["kappa_deg"][1] == pytest.approx(180 / math.pi)
