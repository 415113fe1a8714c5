"""What a scene is checked for before anything runs (issue 10, items 5 and 6): the gearset
(coaxiality, assembly, planet tip clearance), physical ranges with the key and line, and the
scene against its recording (planet count, Nyquist, window, channels) from the header only.

Every fault-campaign case gives a SceneError naming the file, the key and the line; every valid
scene of the repository still loads. Reference formulas: Parker & Lin (2004) for assembly,
Z_r = Z_s + 2 Z_p for coaxial standard gears, (Z_s + Z_p) sin(pi / N) > Z_p + 2 for planet
tip clearance (pipeline/models/assembly.py).
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from seed_rig_toml import SEED_RIG_GEARSET

import meshphase.io
import meshphase.run.scene as scene_mod
from meshphase.errors import SceneWarning
from meshphase.recording import ChannelSpec, Recording
from meshphase.run.scene import LIMITS, Scene, SceneError, check_recording, load_scene, parse_scene, plan

REPO = Path(__file__).resolve().parents[1]
EXAMPLES = REPO / "examples"
FILE = "/data/rig scene.toml"
G = SEED_RIG_GEARSET                      # Z 25/87/31, 4 planets, R_c 112.5 mm, b 40 mm
# Z 25/85/30 with five planets: assemblable (110 / 5) and coaxial, tips clear (rig_5planets)
G5 = (G.replace("z_ring = 87", "z_ring = 85").replace("z_planet = 31", "z_planet = 30")
      .replace("n_planets = 4", "n_planets = 5"))


def _err(text: str, path=FILE) -> SceneError:
    with pytest.raises(SceneError) as info:
        parse_scene(text, path)
    return info.value


def _line_with(text: str, fragment: str, nth: int = 0) -> int:
    return [i + 1 for i, ln in enumerate(text.splitlines()) if fragment in ln][nth]


def _names(e: SceneError, key: str, text: str, fragment: str, path=FILE) -> None:
    """The error names the file, the key and the line of ``fragment``."""
    assert e.key == key
    assert e.line == _line_with(text, fragment)
    assert str(e).startswith(f"{path}, line {e.line}: [{key}]")


@pytest.fixture(scope="module")
def rig_files(tmp_path_factory):
    """2 s of the seed rig (4 planets, 5120 Hz; channels sun, ring, tacho) in every writable
    format (each carries the generator's gearset in its metadata)."""
    from meshphase.synthetic import generate

    d = tmp_path_factory.mktemp("scene_checks")
    rec, _ = generate("seed_rig", duration=2.0, seed=0)
    return {ext: Path(meshphase.io.write(rec, d / f"rig.{ext}")) for ext in ("h5", "mcap", "csv")}


@pytest.fixture(scope="module")
def rig_file(rig_files):
    return rig_files["h5"]


def _with_file(rec_path: Path, body: str, tmp_path: Path) -> tuple[Path, str]:
    text = body + f'[input]\nrecording = "{rec_path}"\n'
    p = tmp_path / "scene.toml"
    p.write_text(text, encoding="utf-8")
    return p, text


# =========================================================================== fault campaign
@pytest.mark.parametrize("ext", ["h5", "mcap", "csv"])
def test_five_planets_against_a_four_planet_recording(rig_files, tmp_path, ext):
    p, text = _with_file(rig_files[ext], 'results = ["phasing"]\n' + G5, tmp_path)
    with pytest.raises(SceneError) as info:
        load_scene(p)
    e = info.value
    _names(e, "gearset.n_planets", text, "n_planets", path=p)
    assert "5 planets" in str(e) and "made with 4" in str(e) and str(rig_files[ext]) in str(e)


def test_five_planets_against_a_four_planet_synthetic_scenario():
    text = 'results = ["phasing"]\n' + G5 + '[input]\nsynthetic = "seed_rig"\n'
    e = _err(text)
    _names(e, "gearset.n_planets", text, "n_planets")
    assert "'seed_rig' was made with 4" in str(e)


def test_planet_count_matching_the_recording_loads(rig_file, tmp_path):
    p, _ = _with_file(rig_file, 'results = ["phasing"]\n' + G, tmp_path)
    assert load_scene(p).gearset.n_planets == 4


def test_z_planet_30_with_25_87_is_not_coaxial():
    text = 'results = ["ideal_phasing"]\n' + G.replace("z_planet = 31", "z_planet = 30")
    e = _err(text)
    _names(e, "gearset.z_planet", text, "z_planet")
    assert "Z_s + 2 Z_p = 25 + 2 x 30 = 85" in str(e)
    assert "(Z_r - Z_s)/2 = 31" in str(e) and "profile_shift = true" in str(e)


def test_profile_shift_declared_accepts_the_seed_table1_gearset():
    text = ('results = ["ideal_phasing"]\n'
            + G.replace("z_planet = 31", "z_planet = 29\nprofile_shift = true"))
    scene = parse_scene(text, FILE)
    assert scene.profile_shift and scene.gearset.z_planet == 29
    assert load_scene(EXAMPLES / "tolerance_study.toml").profile_shift


@pytest.mark.parametrize("results", ['["phasing"]', '["compare"]', '["identify"]', '["tolerance"]'])
def test_missing_z_planet_is_an_error_when_a_result_needs_it(results):
    text = (f"results = {results}\n" + G.replace("z_planet = 31\n", "")
            + '[input]\nsynthetic = "seed_rig"\n[tolerances]\ne_sun_mm = 0.1\nsamples = 64\n')
    e = _err(text)
    _names(e, "gearset.z_planet", text, "[gearset]")        # not written: its table's header
    assert "need z_planet" in str(e) and "(Z_r - Z_s)/2 = 31" in str(e)


def test_missing_z_planet_is_allowed_where_no_result_needs_it():
    # ideal phasing, load sharing and centroids never use the planet speed
    text = ('results = ["ideal_phasing", "load_sharing"]\n' + G.replace("z_planet = 31\n", "")
            + '[input]\nsynthetic = "seed_rig"\n')
    scene = parse_scene(text, FILE)
    assert scene.gearset.z_planet == 0
    # the ring speed comes from Willis without Z_p (it used to default to 0: a held ring)
    assert scene.speeds.ring == pytest.approx(
        scene.speeds.carrier - 25 / 87 * (scene.speeds.sun - scene.speeds.carrier))


def test_missing_z_planet_found_later_by_plan_still_names_the_line(tmp_path):
    # `meshphase process`: a gearset file without results; the results are added in code
    gs = tmp_path / "gearset.toml"
    gs.write_text(G.replace("z_planet = 31\n", ""), encoding="utf-8")
    scene = load_scene(gs)
    scene.results = ["phasing"]
    scene.input = {"recording": tmp_path / "x.h5"}
    with pytest.raises(SceneError) as info:
        plan(scene)
    assert info.value.key == "gearset.z_planet" and info.value.line == 1
    assert str(info.value).startswith(f"{gs}, line 1:")


@pytest.mark.parametrize("key, value, hint", [
    ("carrier_radius_mm", "0.1125", "0.1125 m = 112.5 mm"),
    ("carrier_radius_mm", "112500", "112500 µm = 112.5 mm"),
    ("face_width_mm", "0.04", "0.04 m = 40 mm"),
])
def test_lengths_in_the_wrong_unit(key, value, hint):
    old = "112.5" if key == "carrier_radius_mm" else "40"
    text = 'results = ["ideal_phasing"]\n' + G.replace(f"{key} = {old}", f"{key} = {value}")
    e = _err(text)
    _names(e, f"gearset.{key}", text, key)
    assert hint in str(e)


def test_notch_above_nyquist_of_the_recording(rig_file, tmp_path):
    p, text = _with_file(rig_file, 'results = ["phasing"]\n' + G + "[processing]\nnotch_hz = 3000\n",
                         tmp_path)
    with pytest.raises(SceneError) as info:
        load_scene(p)
    _names(info.value, "processing.notch_hz", text, "notch_hz", path=p)
    assert "Nyquist frequency 2560 Hz" in str(info.value) and "fs 5120 Hz" in str(info.value)


def test_notch_above_nyquist_of_a_synthetic_scenario_and_below_it():
    body = 'results = ["phasing"]\n' + G + '[input]\nsynthetic = "seed_rig"\n[processing]\n'
    e = _err(body + "notch_hz = 2560\n")                   # at Nyquist: refused too
    assert e.key == "processing.notch_hz" and "'seed_rig'" in str(e)
    assert parse_scene(body + "notch_hz = 50\n").processing["notch_hz"] == 50


@pytest.mark.parametrize("text", ["", "\n\n", "# only a comment\n", 'name = "nothing"\n'])
def test_empty_scene_file(tmp_path, text):
    p = tmp_path / "empty.toml"
    p.write_text(text, encoding="utf-8")
    with pytest.raises(SceneError) as info:
        load_scene(p)
    e = info.value
    assert e.key == "results" and e.line == 1
    msg = str(e)
    assert msg.startswith(f"{p}, line 1: [results] the scene is empty")
    for need in ("results = [...]", "ideal_phasing", "[gearset]", "[input]", "[tolerances]",
                 "[bearing]", "data_schemas/scene.md"):
        assert need in msg


def test_minutes_that_cannot_fit_in_memory(monkeypatch):
    # a machine of 16 GiB, whatever this one has: 1e6 min of 5120 Hz x 3 channels needs ~5e4 GiB
    monkeypatch.setattr(scene_mod, "_physical_memory", lambda: 16 * 2**30)
    text = 'results = ["phasing"]\n' + G + '[input]\nsynthetic = "seed_rig"\nminutes = 1e6\n'
    e = _err(text)
    _names(e, "input.minutes", text, "minutes")
    assert "GiB" in str(e) and "16 GiB" in str(e) and "meshphase synth" in str(e)
    # an hour fits (~3.5 GiB at 8 copies)
    assert parse_scene(text.replace("minutes = 1e6", "minutes = 60")).input["minutes"] == 60


def test_two_billion_monte_carlo_samples_refused():
    text = 'results = ["tolerance"]\n' + G + "[tolerances]\ne_sun_mm = 0.1\nsamples = 2000000000\n"
    e = _err(text)
    _names(e, "tolerances.samples", text, "samples")
    assert "100000000" in str(e) and "above 1e8 refused" in str(e)


def test_many_monte_carlo_samples_warn_with_a_run_time_estimate():
    text = 'results = ["tolerance"]\n' + G + "[tolerances]\ne_sun_mm = 0.1\nsamples = 2000000\n"
    with pytest.warns(SceneWarning) as rec:
        parse_scene(text, FILE)
    (w,) = rec
    line = _line_with(text, "samples")
    assert str(w.message).startswith(f"{FILE}, line {line}: [tolerances.samples]")
    assert "evaluations" in str(w.message) and "numba" in str(w.message)
    # the same table when the Monte Carlo does not run: no warning
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        parse_scene(text.replace('["tolerance"]', '["ideal_phasing"]'), FILE)


def test_monte_carlo_window_too_long():
    text = ('results = ["tolerance"]\n' + G
            + "[tolerances]\ne_sun_mm = 0.1\nsamples = 100000\nwindow_s = 1e7\n")
    e = _err(text)
    _names(e, "tolerances.window_s", text, "window_s")
    assert "time points" in str(e)


# =========================================================================== more ranges
@pytest.mark.parametrize("line, key", [
    ("sun_rpm = inf", "speeds.sun_rpm"), ("carrier_rpm = nan", "speeds.carrier_rpm"),
    ("carrier_radius_mm = -inf", "gearset.carrier_radius_mm"),
])
def test_non_finite_numbers(line, key):
    name = line.split(" =")[0]
    text = "results = [\"ideal_phasing\"]\n" + "\n".join(
        line if ln.startswith(name + " =") else ln for ln in G.splitlines()) + "\n"
    e = _err(text)
    _names(e, key, text, name)
    assert "not a finite number" in str(e)


def test_speeds_absurd_or_locked():
    text = 'results = ["ideal_phasing"]\n' + G.replace("sun_rpm = 18.19", "sun_rpm = 2e6")
    e = _err(text)
    _names(e, "speeds.sun_rpm", text, "sun_rpm")
    assert "limit 100000 r/min" in str(e)
    text = 'results = ["ideal_phasing"]\n' + G.replace("sun_rpm = 18.19", "sun_rpm = 1.06")
    e = _err(text)
    _names(e, "speeds.sun_rpm", text, "sun_rpm")
    assert "no tooth meshes" in str(e)


def test_equally_spaced_planets_that_cannot_be_assembled():
    text = 'results = ["ideal_phasing"]\n' + G.replace("n_planets = 4", "n_planets = 5")
    e = _err(text)
    _names(e, "gearset.n_planets", text, "n_planets")
    assert "112/5 = 22.4 is not an integer" in str(e) and ": 1, 2, 4" in str(e)


def test_equally_spaced_planets_that_collide():
    # Z 20/80/30, 5 planets: assemblable (100 / 5) and coaxial, but 50 sin 36 deg = 29.4 < 32
    text = ('results = ["ideal_phasing"]\n'
            + G.replace("z_sun = 25", "z_sun = 20").replace("z_ring = 87", "z_ring = 80")
            .replace("z_planet = 31", "z_planet = 30").replace("n_planets = 4", "n_planets = 5"))
    e = _err(text)
    _names(e, "gearset.n_planets", text, "n_planets")
    assert "collide" in str(e) and "Z_p + 2 = 32" in str(e) and "at most 4 fit" in str(e)


def test_typed_planet_angles_snap_to_the_assemblable_ones():
    # rig_3planets: p = 0, 36, 75 of 360 / 112 deg = 0, 115.714..., 241.071... typed to 0.1 deg
    text = 'results = ["ideal_phasing"]\n' + G.replace(
        "n_planets = 4", "planet_angles_deg = [0, 115.7, 241.1]")
    scene = parse_scene(text, FILE)
    np.testing.assert_allclose(scene.gearset.angles, 2 * np.pi * np.array([0, 36, 75]) / 112,
                               rtol=0, atol=1e-15)


def test_planet_angles_that_cannot_be_assembled_or_coincide():
    text = 'results = ["ideal_phasing"]\n' + G.replace("n_planets = 4", "planet_angles_deg = [0, 117, 241]")
    e = _err(text)
    _names(e, "gearset.planet_angles_deg", text, "planet_angles_deg")
    assert "planet 2 at 117 deg" in str(e) and "115.714 deg (p = 36)" in str(e)
    text = 'results = ["ideal_phasing"]\n' + G.replace("n_planets = 4", "planet_angles_deg = [0, 90, 450]")
    e = _err(text)
    assert e.key == "gearset.planet_angles_deg" and "same place" in str(e)


def test_channel_tables_against_the_gearset():
    base = 'results = ["ideal_phasing"]\n' + G
    cases = [('name = "s"\nkind = "sun"\ntooth = 25\n', "channels.0.tooth", "tooth", "25 teeth"),
             ('name = "r"\nkind = "facewidth"\ngear = "ring"\ntooth = 87\n', "channels.0.tooth", "tooth",
              "numbered 0 .. 86"),
             ('name = "f"\nkind = "facewidth"\ngear = "sun"\nface_position_mm = 25\n',
              "channels.0.face_position_mm", "face_position_mm", "outside the face"),
             ('name = "g"\ngain = 0\n', "channels.0.gain", "gain", "erase")]
    for body, key, frag, words in cases:
        text = base + "[[channels]]\n" + body
        e = _err(text)
        _names(e, key, text, frag)
        assert words in str(e)
    text = base + '[[channels]]\nname = "sun"\n[[channels]]\nname = "sun"\nkind = "sun"\n'
    e = _err(text)
    assert e.key == "channels.1.name" and e.line == _line_with(text, 'name = "sun"', nth=1)
    assert "mapped twice" in str(e)


def test_input_keys_that_would_be_ignored(tmp_path):
    e = _err('results = ["phasing"]\n' + G + '[input]\nrecording = "x.h5"\nminutes = 2\n')
    assert e.key == "input.minutes" and "synthetic" in str(e)
    e = _err('results = ["phasing"]\n' + G + '[input]\nsynthetic = "seed_rig"\nstart_s = 2\n')
    assert e.key == "input.start_s" and "recording file" in str(e)
    text = 'results = ["phasing"]\n' + G + '[input]\nrecording = "x.h5"\nstart_s = 9\nstop_s = 9\n'
    e = _err(text)
    _names(e, "input.stop_s", text, "stop_s")


def test_bands_beyond_the_carrier_radius_and_c_g_unit():
    text = ('results = ["tolerance"]\n' + G
            + "[tolerances]\ne_sun_mm = 100\ne_planet_mm = 20\nsamples = 64\n")
    e = _err(text)
    _names(e, "tolerances.e_sun_mm", text, "e_sun_mm")
    assert "carrier radius" in str(e)
    text = 'results = ["bearing_moments"]\n[bearing]\ncase = "1"\nc_g_N_per_mm_um = 2e10\n'
    e = _err(text)
    _names(e, "bearing.c_g_N_per_mm_um", text, "c_g")
    assert "not SI" in str(e)


# =========================================================================== against the file
def test_window_outside_the_recording(rig_file, tmp_path):
    body = 'results = ["phasing"]\n' + G
    text = body + f'[input]\nrecording = "{rig_file}"\nstart_s = 5\n'
    p = tmp_path / "w.toml"
    p.write_text(text, encoding="utf-8")
    with pytest.raises(SceneError) as info:
        load_scene(p)
    _names(info.value, "input.start_s", text, "start_s", path=p)
    assert "not before the end of the recording" in str(info.value) and "0 .. 2 s" in str(info.value)


def test_mapped_channel_missing_from_the_recording(rig_file, tmp_path):
    # the load stage's message (meshphase.io.channels.map_channels), with key and line
    body = ('results = ["phasing"]\n' + G + '[[channels]]\nname = "sun"\nkind = "sun"\n'
            '[[channels]]\nname = "ring_gauge"\nkind = "ring"\n')
    p, text = _with_file(rig_file, body, tmp_path)
    with pytest.raises(SceneError) as info:
        load_scene(p)
    e = info.value
    _names(e, "channels.1.name", text, 'name = "ring_gauge"', path=p)
    assert "'ring_gauge'" in str(e) and "channels present: sun (sun), ring (ring), tacho (tacho)" in str(e)
    assert "did you mean 'ring_gauge' -> 'ring'" in str(e)


def test_tacho_channel_missing_from_the_recording(rig_file, tmp_path):
    p, text = _with_file(rig_file, 'results = ["phasing"]\n' + G + '[tacho]\nchannel = "key"\n', tmp_path)
    with pytest.raises(SceneError) as info:
        load_scene(p)
    _names(info.value, "tacho.channel", text, 'channel = "key"', path=p)
    assert "sun, ring, tacho" in str(info.value)


def test_recording_without_any_gauge(rig_file, tmp_path):
    rec = meshphase.io.read(rig_file)
    specs = [ChannelSpec("a", kind="other"), ChannelSpec("b", kind="other"),
             ChannelSpec("tacho", kind="tacho", units="V")]
    path = meshphase.io.write(Recording(rec.data, rec.fs, specs), tmp_path / "nogauge.h5")
    p, text = _with_file(path, 'results = ["phasing"]\n' + G, tmp_path)
    with pytest.raises(SceneError) as info:
        load_scene(p)
    _names(info.value, "input.recording", text, "recording =", path=p)
    assert "channels present: a (other), b (other), tacho (tacho)" in str(info.value)


def test_unreadable_recording_is_left_to_the_load_stage(tmp_path):
    bad = tmp_path / "garbage.h5"
    bad.write_bytes(b"this is not a recording")
    p, _ = _with_file(bad, 'results = ["phasing"]\n' + G, tmp_path)
    assert load_scene(p).input["recording"] == bad.resolve()


def test_check_recording_reads_only_the_header(rig_file, tmp_path, monkeypatch):
    p, _ = _with_file(rig_file, 'results = ["phasing"]\n' + G, tmp_path)
    scene = load_scene(p)
    monkeypatch.setattr(meshphase.io, "read", lambda *a, **k: pytest.fail("samples read"))
    check_recording(scene)                                  # reads the header itself
    check_recording(scene, meshphase.io.read_info(rig_file))


def test_check_recording_bad_inputs():
    with pytest.raises(TypeError, match="scene must be a Scene"):
        check_recording({"input": {}})
    with pytest.raises(ValueError, match="no recording"):
        check_recording(Scene(path=None, name="x", results=[]))


# =========================================================================== valid scenes load
@pytest.mark.parametrize("name", sorted(p.name for p in EXAMPLES.glob("*.toml")))
def test_every_example_still_loads(name):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_scene(EXAMPLES / name)


def test_seed_rig_toml_and_the_demo_scene_load(tmp_path):
    from meshphase.run.demo import demo_scene_path

    parse_scene('results = ["ideal_phasing", "tolerance"]\n' + G
                + "[tolerances]\ne_sun_mm = 0.2\nsamples = 64\n", FILE)
    load_scene(demo_scene_path(tmp_path))


def test_end_to_end_scenes_load(rig_file, tmp_path):
    import test_end_to_end as e2e

    for name in e2e.EXPECT:
        scene = parse_scene(e2e._scene_text(name, e2e.EXPECT[name].minutes))
        assert plan(scene)[0] == "load"
    # the file scene of its bad-input tests (run_file), with the right tooth counts
    text = (f'name = "bad input"\nresults = {e2e.RESULTS}\n'
            + e2e.GEARSET.format(z_sun=25, z_ring=87, profile_shift="false") + f'[input]\nrecording = "{rig_file}"\n')
    (tmp_path / "s.toml").write_text(text, encoding="utf-8")
    load_scene(tmp_path / "s.toml")


def test_phasing_accuracy_scenes_plan():
    from meshphase.bench.phasing import case_config, matrix_cases

    for case in matrix_cases():
        scene = Scene(path=None, name=case.name, results=["phasing", "compare"],
                      input={"synthetic": case.scenario, "minutes": case.minutes, "seed": 0,
                             "config": case_config(case)})
        assert "phasing" in plan(scene)


def _scenario_scene(cfg) -> str:
    """A scene for a synthetic scenario with its gearset written out (as tests/test_stability
    does), declaring profile shift where the tooth counts are not coaxial."""
    g, sp = cfg.gearset, cfg.speeds
    shift = "profile_shift = true\n" if g.z_ring != g.z_sun + 2 * g.z_planet else ""
    angles = ", ".join(repr(math.degrees(a)) for a in g.planet_angles)
    return (f'results = ["phasing", "compare"]\n[gearset]\nz_sun = {g.z_sun}\nz_ring = {g.z_ring}\n'
            f"z_planet = {g.z_planet}\n{shift}planet_angles_deg = [{angles}]\n"
            f"carrier_radius_mm = {g.carrier_radius * 1e3!r}\n"
            f'direction = "{g.direction}"\n'
            f"[speeds]\nsun_rad_s = {sp.sun!r}\ncarrier_rad_s = {sp.carrier!r}\n"
            f'[input]\nsynthetic = "{cfg.name}"\n')


def test_every_synthetic_scenario_gearset_loads_as_a_scene():
    from meshphase.synthetic.scenarios import SCENARIOS, get_scenario

    for name in SCENARIOS:
        cfg = get_scenario(name)
        scene = parse_scene(_scenario_scene(cfg), FILE)
        np.testing.assert_allclose(scene.gearset.angles, cfg.gearset.angles, rtol=0, atol=1e-12)


# =========================================================================== property
@settings(max_examples=300, deadline=None)
@given(zs=st.integers(3, 120), zp=st.integers(3, 120), d=st.integers(-6, 6),
       coax=st.booleans(), n=st.integers(1, 12), shift=st.booleans())
def test_gearset_verdicts_match_the_formulas(zs, zp, d, coax, n, shift):
    zr = zs + 2 * zp + (0 if coax else d)
    assume(zr > zs)                               # a ring smaller than the sun: schema/Gearset
    text = (f'results = ["ideal_phasing"]\n[gearset]\nz_sun = {zs}\nz_ring = {zr}\nz_planet = {zp}\n'
            f"n_planets = {n}\ncarrier_radius_mm = 100\nprofile_shift = {str(shift).lower()}\n")
    # the formulas, written out independently of meshphase.models.assembly
    coaxial = zr == zs + 2 * zp
    assemblable = (zs + zr) % n == 0
    radius = zs + zp if coaxial else (zs + zr) / 2        # 2 R_c / m
    clear = n == 1 or radius * math.sin(math.pi / n) - (zp + 2) > 1e-9
    if not (coaxial or shift):
        expected = "gearset.z_planet"
    elif not assemblable or not clear:
        expected = "gearset.n_planets"
    else:
        expected = None
    try:
        scene = parse_scene(text, FILE)
    except SceneError as exc:
        assert exc.key == expected, str(exc)
        assert exc.line == _line_with(text, expected.split(".")[1])
        if expected == "gearset.n_planets":
            assert ("not an integer" in str(exc)) == (not assemblable)
        return
    assert expected is None
    assert scene.gearset.n_planets == n


@settings(max_examples=150, deadline=None)
@given(zs=st.integers(3, 60), zp=st.integers(3, 60), data=st.data())
def test_typed_angle_verdicts_match_the_assembly_formula(zs, zp, data):
    zr = zs + 2 * zp
    z_sum = zs + zr
    p = data.draw(st.lists(st.integers(1, z_sum - 1), min_size=1, max_size=3, unique=True))
    off = data.draw(st.sampled_from([0.0, 0.3, 0.5]))      # fraction of a step off
    angles = [0.0] + [360.0 * (q + off) / z_sum for q in p]
    text = (f'results = ["ideal_phasing"]\n[gearset]\nz_sun = {zs}\nz_ring = {zr}\n'
            f"planet_angles_deg = [{', '.join(repr(a) for a in angles)}]\ncarrier_radius_mm = 100\n")
    try:
        scene = parse_scene(text, FILE)           # no z_planet: assembly only, no tip check
    except SceneError as exc:
        assert exc.key == "gearset.planet_angles_deg"
        assert off > 0, str(exc)                  # exact multiples always assemble
        return
    assert off == 0                               # a 0.3 or 0.5 step miss is always refused
    np.testing.assert_allclose(scene.gearset.angles, np.radians(angles), rtol=0, atol=1e-12)


def test_limits_are_documented():
    doc = (REPO / "data_schemas" / "scene.md").read_text(encoding="utf-8")
    assert "## What is checked before anything runs" in doc
    lo, hi = LIMITS["length_mm"]
    assert f"{lo:g} .. {hi:g} mm" in doc and "1e8" in doc and "profile_shift" in doc


@pytest.mark.parametrize("speeds, held", [
    ('sun_rpm = 18.19\nfixed = "ring"\n', "ring"),       # the input speed and the held member
    ("sun_rpm = 18.19\nring_rpm = 0\n", None),
    ("carrier_rpm = 4.0602678571429\nring_rpm = 0\n", None),
])
def test_any_two_speeds_or_one_and_the_held_member(speeds, held):
    # a rig's user knows the input speed and which member is held; two of sun, carrier and
    # ring give the third by Willis (w_r - w_c = -(Z_s/Z_r)(w_s - w_c)): the seed rig's
    # carrier turns at 18.19 x 25/112 = 4.0603 r/min with the ring held. Asking for sun and
    # carrier alone refused these
    text = 'results = ["ideal_phasing"]\n' + G.replace("sun_rpm = 18.19\ncarrier_rpm = 1.06\n", speeds)
    scene = parse_scene(text, FILE)
    rpm = 60.0 / (2.0 * math.pi)
    assert scene.speeds.sun * rpm == pytest.approx(18.19, rel=1e-9)
    assert scene.speeds.carrier * rpm == pytest.approx(18.19 * 25 / 112, rel=1e-9)
    assert abs(scene.speeds.ring) <= 1e-12
    assert scene.fixed == held
    from meshphase.kinematics.angles import held_member

    assert held_member(25, 87, scene.speeds, resolution=scene.speeds_resolution)[0] == "ring"


def test_one_speed_alone_says_what_else_to_give():
    text = 'results = ["ideal_phasing"]\n' + G.replace("carrier_rpm = 1.06\n", "")
    e = _err(text)
    assert "give two of the sun, carrier and ring speeds, or one of them with the held member" in str(e)


def test_input_fs_hz_reads_a_tdms_file_without_timing_and_nothing_else(rig_files, tmp_path):
    from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

    rec = meshphase.io.read(rig_files["h5"])
    plain = tmp_path / "plain.tdms"
    with TdmsWriter(str(plain)) as w:
        w.write_segment([RootObject(), GroupObject("Log")]
                        + [ChannelObject("Log", c.name, rec.data[:, j].copy()) for j, c in enumerate(rec.channels)])
    body = 'results = ["ideal_phasing"]\n' + G
    p, text = _with_file(plain, body, tmp_path)
    text = text.replace("[input]\n", "[input]\nfs_Hz = 5120\n")
    scene = parse_scene(text, p)
    assert scene_mod.read_options(scene) == {"fs": 5120.0}
    got = meshphase.io.read(plain, **scene_mod.read_options(scene))
    assert got.fs == 5120.0 and np.array_equal(got.data, rec.data)
    for ext in ("mcap", "csv"):                # a file that states its own rate
        _, text = _with_file(rig_files[ext], body, tmp_path)
        text = text.replace("[input]\n", "[input]\nfs_Hz = 5120\n")
        e = _err(text)
        assert e.key == "input.fs_Hz" and "gives its own sample rate" in str(e)
    e = _err(body + "[input]\nfs_Hz = 5120\n")
    assert e.key == "input.fs_Hz" and "give [input] recording" in str(e)
