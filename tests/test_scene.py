"""Scenes: up-front validation with errors naming file, key and line; SI conversion; and
``plan`` running only the stages the requested results need (issue 6, items 1-2)."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest
from seed_rig_toml import SEED_RIG_GEARSET
from hypothesis import given, settings
from hypothesis import strategies as st

from meshphase.models.gearset import rpm_to_rad_s
from meshphase.run.scene import (RESULTS, STAGES, Scene, SceneError, load_scene, parse_scene, plan,
                                 scene_schema_errors)

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"

GEARSET = SEED_RIG_GEARSET

TOLERANCES = """\
[tolerances]
e_sun_mm = 0.2
e_ring_mm = 0.5
e_planet_mm = 0.3
kappa_ring_deg = 60
samples = 64
"""


def _err(text: str, path="/data/my scene.toml") -> SceneError:
    with pytest.raises(SceneError) as info:
        parse_scene(text, path)
    return info.value


def _line_with(text: str, fragment: str, nth: int = 0) -> int:
    """1-based number of the nth line of ``text`` containing ``fragment``."""
    hits = [i + 1 for i, ln in enumerate(text.splitlines()) if fragment in ln]
    return hits[nth]


# --------------------------------------------------------------------------- examples
EXPECTED_PLANS = {
    # a bearing study opens no recording and runs no Monte Carlo
    "bearing_moments.toml": ["bearing_moments", "tilt"],
    "bearing_double_pinion.toml": ["bearing_moments", "tilt"],
    "tolerance_study.toml": ["ideal", "tolerance"],
    # compare pulls in identify and (the scene has tolerances) the Monte Carlo, both before it
    "rig_validation.toml": ["ideal", "load", "condition", "onsets", "phasing", "load_sharing",
                            "identify", "tolerance", "compare"],
}


def test_every_example_scene_is_covered():
    assert sorted(p.name for p in EXAMPLES.glob("*.toml")) == sorted(EXPECTED_PLANS)


@pytest.mark.parametrize("name", sorted(EXPECTED_PLANS))
def test_example_scene_loads_and_plans(name):
    scene = load_scene(EXAMPLES / name)
    assert isinstance(scene, Scene)
    assert scene.path == EXAMPLES / name
    assert plan(scene) == EXPECTED_PLANS[name]


def test_example_units_are_si():
    rig = load_scene(EXAMPLES / "rig_validation.toml")
    assert rig.gearset.carrier_radius == pytest.approx(0.1125)
    assert rig.gearset.face_width == pytest.approx(0.040)
    assert rig.speeds.sun == pytest.approx(rpm_to_rad_s(18.19))
    assert rig.speeds.carrier == pytest.approx(rpm_to_rad_s(1.06))
    assert rig.tolerances["e_ring"] == pytest.approx(0.5e-3)
    assert rig.tolerances["kappa_sun"] == "uniform"
    tol = load_scene(EXAMPLES / "tolerance_study.toml")
    assert tol.tolerances["kappa_ring"] == pytest.approx(math.radians(60))
    assert tol.tolerances["samples"] == 100000
    bm = load_scene(EXAMPLES / "bearing_moments.toml")
    # 20 N/(mm·µm) = 20 / (1e-3 * 1e-6) N/m^2
    assert bm.bearing["c_g"] == pytest.approx(2e10)
    assert bm.bearing["k_tilt"] == [8.8e6, 8.8e4, 8.8e3]
    assert bm.bearing["case"] == "1"


def test_channels_input_and_output_convert_and_resolve(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path / "..")   # output: relative to the current directory, not the scene's
    text = ('results = ["phasing"]\noutput = "results/here"\n' + GEARSET
            + '[input]\nrecording = "rec/run.h5"\nstart_s = 1.5\nstop_s = 9\n'
            + '[[channels]]\nname = "fw1"\nkind = "facewidth"\nface_position_mm = -12.5\n')
    (tmp_path / "rec").mkdir()
    (tmp_path / "rec" / "run.h5").write_bytes(b"")
    scene = parse_scene(text, tmp_path / "s.toml")
    assert scene.input["recording"] == (tmp_path / "rec" / "run.h5").resolve()
    assert (scene.input["start"], scene.input["stop"]) == (1.5, 9)
    assert scene.channels == [{"name": "fw1", "kind": "facewidth", "face_position": pytest.approx(-0.0125)}]
    assert scene.output == Path.cwd() / "results" / "here" != tmp_path.resolve() / "results" / "here"


# --------------------------------------------------------------------------- validation errors
def test_unknown_key_names_key_line_and_file():
    text = 'results = ["ideal_phasing"]\n' + GEARSET.replace("face_width_mm", "face_widht_mm")
    e = _err(text)
    assert e.key == "gearset.face_widht_mm"
    assert e.line == _line_with(text, "face_widht_mm")
    msg = str(e)
    assert msg.startswith(f"/data/my scene.toml, line {e.line}:")
    assert "face_widht_mm" in msg and "face_width_mm" in msg   # lists what is allowed


def test_unknown_table_points_at_its_header():
    text = 'results = ["bearing_moments"]\n[bearing]\ncase = "1"\n\n[bearings]\ncase = "1"\n'
    e = _err(text)
    assert e.key == "bearings"
    assert e.line == 5


def test_wrong_type_names_key_and_line():
    text = 'results = ["ideal_phasing"]\n' + GEARSET.replace("z_sun = 25", 'z_sun = "25"')
    e = _err(text)
    assert e.key == "gearset.z_sun"
    assert e.line == _line_with(text, "z_sun")
    assert "integer" in str(e)


def test_error_in_second_channel_table_points_at_that_table():
    text = ('results = ["bearing_moments"]\n[bearing]\ncase = "1"\n'
            '[[channels]]\nname = "a"\ntooth = 1\n[[channels]]\nname = "b"\ntooth = -1\n')
    e = _err(text)
    assert e.key == "channels.1.tooth"
    assert e.line == _line_with(text, "tooth", nth=1)


def test_unknown_result_points_at_results_line():
    text = 'name = "x"\nresults = ["ideal_phasing", "phasing_typo"]\n'
    e = _err(text)
    assert e.key == "results.1"
    assert e.line == 2
    assert "phasing_typo" in str(e)


def test_missing_gearset_for_phasing_results():
    text = 'name = "no gearset"\nresults = ["phasing"]\n[input]\nrecording = "x.h5"\n'
    e = _err(text)
    assert e.key == "gearset"
    assert e.line == 2
    assert "[gearset]" in str(e)


def test_tolerance_result_without_tolerances_table():
    text = 'results = ["ideal_phasing", "tolerance"]\n' + GEARSET
    e = _err(text)
    assert e.key == "tolerances"
    assert e.line == 1
    assert "[tolerances]" in str(e)


def test_monte_carlo_needs_speeds():
    text = 'results = ["tolerance"]\n' + GEARSET.split("[speeds]")[0] + TOLERANCES
    e = _err(text)
    assert e.key == "speeds"
    assert e.line == _line_with(text, "[tolerances]")


def test_both_recording_and_synthetic():
    text = ('results = ["phasing"]\n' + GEARSET
            + '[input]\nrecording = "x.h5"\nsynthetic = "seed_rig"\n')
    e = _err(text)
    assert e.key == "input.synthetic"
    assert e.line == _line_with(text, "synthetic =")
    assert "not both" in str(e)


def test_toml_syntax_error_gives_line():
    text = 'results = ["phasing"]\n\n[input\nsynthetic = "seed_rig"\n'
    e = _err(text)
    assert e.line == 3
    assert "TOML syntax error" in str(e)
    assert str(e).startswith("/data/my scene.toml, line 3:")


def test_load_scene_error_names_the_file(tmp_path):
    p = tmp_path / "broken.toml"
    p.write_text('results = ["phasing"]\nz = [1,\n', encoding="utf-8")
    with pytest.raises(SceneError, match=re.escape(str(p))) as info:
        load_scene(p)
    assert info.value.path == str(p)
    assert info.value.line is not None


def test_load_scene_missing_file(tmp_path):
    p = tmp_path / "nope.toml"
    with pytest.raises(FileNotFoundError, match=re.escape(str(p))):
        load_scene(p)


def test_missing_recording_is_an_error_only_when_a_stage_reads_it(tmp_path):
    rec = 'recording = "missing/run.h5"\n'
    text = 'results = ["phasing"]\n' + GEARSET + "[input]\n" + rec
    e = _err(text, tmp_path / "s.toml")
    assert e.key == "input.recording"
    assert e.line == _line_with(text, "recording =")
    assert "missing" in str(e)
    # the same stale path in a bearing scene does not matter: nothing opens it
    bearing = 'results = ["bearing_moments"]\n[input]\n' + rec + '[bearing]\ncase = "1"\n'
    scene = parse_scene(bearing, tmp_path / "b.toml")
    assert "load" not in plan(scene)


def test_unknown_synthetic_scenario_lists_known():
    text = 'results = ["phasing"]\n[input]\nsynthetic = "seed_rigg"\n'
    e = _err(text)
    assert e.key == "input.synthetic"
    assert "seed_rig" in str(e)


def test_speeds_given_twice_and_inconsistent_ring():
    e = _err('results = ["ideal_phasing"]\n' + GEARSET + "sun_rad_s = 2.0\n")
    assert e.key == "speeds.sun_rad_s"
    e = _err('results = ["ideal_phasing"]\n' + GEARSET + "ring_rpm = 5.0\n")
    assert e.key == "speeds.ring_rpm"
    assert "kinematics" in str(e)
    # the consistent ring speed (ring driven at -3.862 r/min, seed 000 rig) is accepted
    ok = parse_scene('results = ["ideal_phasing"]\n' + GEARSET + "ring_rpm = -3.862\n")
    assert ok.speeds.ring == pytest.approx(rpm_to_rad_s(-3.862), rel=1e-3)


def test_bearing_results_need_bearing_table_and_tilt_needs_stiffness():
    e = _err('results = ["bearing_moments"]\n')
    assert e.key == "bearing"
    e = _err('results = ["tilt"]\n[bearing]\ncase = "1"\n')
    assert e.key == "bearing.k_tilt_Nm_per_rad"
    assert e.line == 2


def test_bearing_stiffness_in_either_named_unit():
    # seed 001 Table 10 prints N·mm/rad: GA, GB, GC = 8.8e9, 8.8e7, 8.8e6 -> 8.8e6, 8.8e4, 8.8e3
    nmm = parse_scene('results = ["tilt"]\n[bearing]\ncase = "1"\n'
                      "k_tilt_Nmm_per_rad = [8.8e9, 8.8e7, 8.8e6]\n")
    assert nmm.bearing["k_tilt"] == pytest.approx([8.8e6, 8.8e4, 8.8e3], rel=1e-15)
    one = parse_scene('results = ["tilt"]\n[bearing]\ncase = "1"\nk_tilt_Nmm_per_rad = 8.8e7\n')
    assert one.bearing["k_tilt"] == pytest.approx([8.8e4], rel=1e-15)
    e = _err('results = ["tilt"]\n[bearing]\ncase = "1"\nk_tilt_Nm_per_rad = 8.8e4\n'
             "k_tilt_Nmm_per_rad = 8.8e7\n")
    assert e.key == "bearing.k_tilt_Nmm_per_rad" and "not both" in str(e)


def test_double_pinion_angle_keys_old_and_new():
    from meshphase.errors import DeprecatedNameWarning

    head = 'results = ["bearing_moments"]\n[bearing]\ncase = "2-B"\n'
    new = parse_scene(head + "double_pinion_included_angle_sp_deg = [90.0, 111.0]\n"
                      "double_pinion_included_angle_rp_deg = [67.0]\n")
    assert new.bearing["double_pinion_included_angle_sp"] == pytest.approx(
        [math.pi / 2, math.radians(111.0)])
    assert new.bearing["double_pinion_included_angle_rp"] == pytest.approx([math.radians(67.0)])
    with pytest.warns(DeprecatedNameWarning, match="double_pinion_beta_deg is renamed"):
        old = parse_scene(head + "double_pinion_beta_deg = [90.0, 111.0]\n")
    assert old.bearing["double_pinion_included_angle_sp"] == new.bearing[
        "double_pinion_included_angle_sp"]
    e = _err(head + "double_pinion_beta_deg = [90.0]\ndouble_pinion_included_angle_sp_deg = [90.0]\n")
    assert e.key == "bearing.double_pinion_beta_deg"


@pytest.mark.parametrize("written, canonical", [("1", "1"), ("case1", "1"), ("Case 1", "1"),
                                                ("2-B", "2-B"), ("case2B", "2-B"), ("2a", "2-A")])
def test_bearing_case_spellings(written, canonical):
    scene = parse_scene(f'results = ["bearing_moments"]\n[bearing]\ncase = "{written}"\n')
    assert scene.bearing["case"] == canonical


def test_bearing_case_default_and_unknown():
    # no case: seed 001 case 1 (a name the bearing models know)
    assert parse_scene('results = ["bearing_moments"]\n[bearing]\n').bearing["case"] == "1"
    e = _err('results = ["bearing_moments"]\n[bearing]\ncase = "3"\n')
    assert e.key == "bearing.case"
    assert e.line == 3
    assert "2-B" in str(e)


def test_scene_error_without_path_label():
    with pytest.raises(SceneError, match=r"^<scene>"):
        parse_scene("results = [\n")


def test_scene_without_results_plans_nothing():
    # a gearset file for `meshphase process` has no results: valid, plans nothing by itself
    scene = parse_scene(GEARSET)
    assert scene.results == [] and scene.tolerances is None
    assert plan(scene) == []
    # an empty scene is an error (tests/test_scene_checks.py); built in code it plans nothing
    assert plan(Scene(path=None, name="empty", results=[])) == []


def test_bad_input_types():
    with pytest.raises(TypeError):
        parse_scene(b'results = ["phasing"]')
    with pytest.raises(TypeError):
        load_scene(None)
    with pytest.raises(AttributeError):
        plan("not a scene")


# --------------------------------------------------------------------------- plan
def _scene(results, *, tolerances=True) -> Scene:
    return Scene(path=None, name="t", results=list(results),
                 tolerances={"samples": 2} if tolerances else None)


def test_plan_bearing_needs_no_recording():
    assert plan(_scene(["bearing_moments", "tilt"]), check=False) == ["bearing_moments", "tilt"]


def test_plan_without_tolerances_runs_no_monte_carlo():
    stages = plan(_scene(["phasing", "compare"], tolerances=False), check=False)
    assert "tolerance" not in stages
    assert stages == ["load", "condition", "onsets", "phasing", "identify", "ideal", "compare"]


def test_plan_compare_after_identify_and_tolerance():
    # regression: compare reads the identified model and the Monte Carlo band, so both must
    # run before it (they used to be appended after it, leaving compare without them)
    stages = plan(_scene(["compare"]), check=False)
    assert stages.index("identify") < stages.index("compare")
    assert stages.index("tolerance") < stages.index("compare")


def test_plan_centroids_only_when_asked():
    assert "centroids" not in plan(_scene(["phasing", "load_sharing", "compare"]), check=False)
    assert plan(_scene(["centroids"]), check=False) == ["load", "condition", "onsets", "centroids"]


@settings(max_examples=150, deadline=None)
@given(results=st.lists(st.sampled_from(sorted(RESULTS)), unique=True),
       tolerances=st.booleans())
def test_plan_is_the_dependency_closure_in_order(results, tolerances):
    stages = plan(_scene(results, tolerances=tolerances), check=False)
    assert len(stages) == len(set(stages))
    for i, s in enumerate(stages):                       # dependencies first
        assert all(d in stages[:i] for d in STAGES[s])
    wanted = {s for r in results for s in RESULTS[r]}
    if "compare" in wanted:
        wanted |= {"identify"} | ({"tolerance"} if tolerances else set())
    closure, todo = set(), list(wanted)
    while todo:
        s = todo.pop()
        if s not in closure:
            closure.add(s)
            todo.extend(STAGES[s])
    assert set(stages) == closure                        # and nothing more
    if "compare" in stages:
        assert all(stages.index(s) < stages.index("compare")
                   for s in ("identify", "tolerance") if s in stages)


def test_scene_schema_errors_of_the_demo_an_empty_and_a_bad_scene():
    import tomllib

    from meshphase.run.demo import DEMO_SCENE

    assert scene_schema_errors(tomllib.loads(DEMO_SCENE)) == []
    bad = scene_schema_errors({"gearset": 5, "results": ["phasing", "no_such_result"]})
    assert [list(e.absolute_path) for e in bad] == sorted([list(e.absolute_path) for e in bad], key=str)
    assert {str(e.absolute_path[0]) for e in bad} >= {"gearset", "results"}
    assert scene_schema_errors([]) and scene_schema_errors({"name": 3})   # not a table; a bad type


def test_schema_errors_list_every_break_from_the_kept_validator():
    # data_schemas.schema_errors: every violation (validate names the most relevant one)
    import tomllib

    from meshphase.data_schemas import schema_errors
    from meshphase.run.demo import DEMO_SCENE

    assert schema_errors(tomllib.loads(DEMO_SCENE), "scene") == []
    assert len(schema_errors({"gearset": 5, "results": 3}, "scene.schema.json")) >= 2
    assert schema_errors([], "scene")                              # not even a table
    with pytest.raises(ValueError):
        schema_errors({}, "no_such_schema")
