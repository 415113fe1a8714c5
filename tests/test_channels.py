"""The channel mapping of a scene onto a recording (issue 12 item 6, issue 11's scene <->
stages loop): exact names, globs and regexes, each channel mapped once, the listing that
``meshphase info --scene`` and the report show, unmapped channels said in the run."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from seed_rig_toml import SEED_RIG_GEARSET as G

import meshphase.io
from meshphase.io.channels import (ChannelMapError, apply_channel_overrides, check_gauges,
                                   entry_values, is_glob, map_channels, mapped_specs,
                                   mapping_report, mapping_rows, unmapped_message)
from meshphase.cli import main
from meshphase.recording import ChannelSpec, Recording
from meshphase.run.scene import SceneError, load_scene, parse_scene

RIG_NAMES = ["SG01_sun_T3", "SG02_sun_T7", "SG03_ring_T5", "Carrier OPR", "Temp [C]"]


def _rec(names=RIG_NAMES, n=8) -> Recording:
    return Recording(np.arange(n * len(names), dtype=float).reshape(n, len(names)), 100.0,
                     [ChannelSpec(x, units="V") for x in names])


# =========================================================================== map_channels
def test_exact_names_keep_working():
    m = map_channels(RIG_NAMES, [{"name": "Carrier OPR", "kind": "tacho"}])
    assert [(x.channel, x.how, x.entry) for x in m.matches] == [("Carrier OPR", "exact", 0)]
    assert m.unmapped == ("SG01_sun_T3", "SG02_sun_T7", "SG03_ring_T5", "Temp [C]")


def test_glob_maps_several_channels_in_column_order():
    m = map_channels(RIG_NAMES, [{"name": "SG*_sun*", "kind": "sun"}])
    assert [x.channel for x in m.matches] == ["SG01_sun_T3", "SG02_sun_T7"]
    assert {x.how for x in m.matches} == {"glob"}


def test_a_name_with_glob_characters_that_is_a_channel_is_exact():
    # "Temp [C]" holds "[": as a glob it would match "Temp C"; it is a channel's name
    m = map_channels(RIG_NAMES, [{"name": "Temp [C]"}])
    assert [(x.channel, x.how) for x in m.matches] == [("Temp [C]", "exact")]


def test_regex_fullmatch_and_tooth_group():
    m = map_channels(RIG_NAMES, [{"regex": r"SG\d+_sun_T(?P<tooth>\d+)", "kind": "sun"}])
    assert [(x.channel, x.tooth) for x in m.matches] == [("SG01_sun_T3", 3), ("SG02_sun_T7", 7)]
    specs, gains = mapped_specs(_rec().channels, m)
    assert [s.tooth for s in specs[:2]] == [3, 7] and gains == []
    assert specs[0].kind == "sun" and specs[0].gear == "sun" and specs[3].kind == "other"
    # fullmatch: a regex matching only part of a name maps nothing
    with pytest.raises(ChannelMapError, match="matches no channel"):
        map_channels(RIG_NAMES, [{"regex": "sun"}])


def test_two_entries_on_one_channel_name_both():
    entries = [{"name": "SG*", "kind": "sun"}, {"regex": "SG03_.*", "kind": "ring"}]
    with pytest.raises(ChannelMapError) as info:
        map_channels(RIG_NAMES, entries)
    msg = str(info.value)
    assert "'SG03_ring_T5'" in msg and '[[channels]] 1 (name = "SG*")' in msg
    assert '[[channels]] 2 (regex = "SG03_.*")' in msg and info.value.entry == 1
    # an exact name inside a pattern's reach counts too
    with pytest.raises(ChannelMapError, match="matched by"):
        map_channels(RIG_NAMES, [{"name": "Carrier OPR"}, {"name": "Carrier*"}])


def test_pattern_matching_nothing_is_an_error_listing_the_channels():
    with pytest.raises(ChannelMapError) as info:
        map_channels(RIG_NAMES, [{"name": "SG*_planet*"}], "rig.h5", "a (other)")
    assert "rig.h5" in str(info.value) and "matches no channel" in str(info.value)
    assert "channels present: a (other)" in str(info.value)


def test_missing_exact_name_message_unchanged():
    with pytest.raises(ChannelMapError) as info:
        map_channels(["sun", "ring"], [{"name": "sun"}, {"name": "ring_gauge"}], "f.h5",
                     "sun (sun), ring (ring)")
    e = info.value
    assert e.entry == 1 and e.key == "name"
    assert str(e) == ("f.h5: the scene's [[channels]] name 'ring_gauge' is not in the file; "
                      "channels present: sun (sun), ring (ring) (did you mean 'ring_gauge' -> "
                      "'ring'?)")


def test_map_channels_empty_and_bad_input():
    m = map_channels([], [])
    assert m.matches == () and m.unmapped == ()
    assert map_channels(["a"], []).unmapped == ("a",)
    with pytest.raises(TypeError):
        map_channels("abc", [])
    with pytest.raises(ChannelMapError, match="one of them"):
        map_channels(["a"], [{"name": "a", "regex": "a"}])
    with pytest.raises(ChannelMapError, match="one of them"):
        map_channels(["a"], [{"kind": "sun"}])
    with pytest.raises(ChannelMapError, match="not a regular expression"):
        map_channels(["a"], [{"regex": "("}])
    with pytest.raises(ChannelMapError, match="tooth group and from the tooth key"):
        map_channels(["T3"], [{"regex": r"T(?P<tooth>\d)", "tooth": 1}])


def test_is_glob_and_entry_values():
    assert is_glob("SG*") and is_glob("a?") and is_glob("T[12]") and not is_glob("SG01")
    assert not is_glob("")
    m = map_channels(RIG_NAMES, [{"name": "SG*_sun*", "mount_angle": 0.5}])
    assert entry_values(m, "mount_angle") == {"SG01_sun_T3": 0.5, "SG02_sun_T7": 0.5}
    assert entry_values(m, "nothing") == {}


# =========================================================================== specs, records
def test_mapped_specs_gain_and_bridge_units_and_bad_input():
    m = map_channels(RIG_NAMES, [{"name": "SG01*", "gain": 2.0, "bridge": object()}])
    specs, gains = mapped_specs(_rec().channels, m)
    assert gains == [(0, 2.0)] and specs[0].units == "m/m" and specs[0].gain == 2.0
    with pytest.raises(ValueError, match="different channels"):
        mapped_specs(_rec(["x"]).channels, m)
    empty = map_channels([], [])
    assert mapped_specs([], empty) == ([], [])


def test_apply_channel_overrides_gains_history_and_bad_input():
    rec = _rec()
    out = apply_channel_overrides(rec, [{"name": "SG0[12]*", "kind": "sun", "gain": -1.0},
                                        {"name": "Carrier OPR", "kind": "tacho"}], "r")
    np.testing.assert_array_equal(out.data[:, :2], -rec.data[:, :2])
    np.testing.assert_array_equal(out.data[:, 2:], rec.data[:, 2:])
    assert out.history[-1]["channels"] == ["SG01_sun_T3", "SG02_sun_T7", "Carrier OPR"]
    assert apply_channel_overrides(rec, []) is rec
    with pytest.raises(TypeError):
        apply_channel_overrides(rec.data, [{"name": "x"}])


def test_check_gauges_rules_and_empty_input():
    rec = apply_channel_overrides(_rec(), [{"name": "SG*_sun*", "kind": "sun"},
                                           {"name": "Carrier OPR", "kind": "tacho"}])
    unused = check_gauges(rec, ["load", "condition", "onsets", "phasing"], ["phasing"], "r")
    assert unused == ["SG03_ring_T5", "Temp [C]"]
    assert check_gauges(rec, [], [], "r") == RIG_NAMES
    with pytest.raises(ValueError, match="no gauge channel"):
        check_gauges(_rec(), ["onsets"], ["phasing"], "r")
    empty = Recording(np.empty((0, 0)), 10.0, [])
    assert check_gauges(empty, [], [], "r") == []


def test_mapping_rows_report_and_message():
    rep = mapping_report(_rec().channels, [{"regex": r"SG\d+_sun_T(?P<tooth>\d+)", "kind": "sun"},
                                           {"name": "Carrier OPR", "kind": "tacho"}], "rig.h5")
    rows = {r["channel"]: r for r in rep["rows"]}
    assert rows["SG02_sun_T7"]["tooth"] == 7 and rows["SG02_sun_T7"]["matched by"] == "regex"
    assert rows["SG02_sun_T7"]["scene entry"].startswith("[[channels]] 1 (regex")
    assert rows["Carrier OPR"]["kind"] == "tacho" and rows["Carrier OPR"]["matched by"] == "exact"
    assert rows["Temp [C]"]["scene entry"] == "unmapped (as in the file)"
    assert rep["unmapped"] == ["SG03_ring_T5", "Temp [C]"]
    assert "SG03_ring_T5 (other), Temp [C] (other) not mapped" in rep["message"]
    # empty: no entries, every channel as the file says, no message
    none = mapping_report(_rec().channels, [])
    assert none["unmapped"] == [] and none["message"] is None and len(none["rows"]) == 5
    assert mapping_report([], []) == {"rows": [], "unmapped": [], "message": None}
    assert mapping_rows([], None) == []
    with pytest.raises(TypeError):
        mapping_report(["not a spec"], [])
    with pytest.raises(ChannelMapError):
        mapping_report(_rec().channels, [{"name": "nope*"}])


def test_unmapped_message_none_when_all_mapped():
    m = map_channels(["a", "b"], [{"name": "*"}])
    assert unmapped_message(m) is None
    assert unmapped_message(map_channels(["a"], [])) is None
    assert unmapped_message(map_channels(["a", "b"], [{"name": "a"}])).startswith("channel(s) b ")


# =========================================================================== scenes
@pytest.fixture(scope="module")
def rig_names_file(tmp_path_factory):
    """10 s of the seed rig with a rig's own channel names (no kinds in the file)."""
    from meshphase.synthetic import generate

    rec, _ = generate("seed_rig", duration=10.0, seed=0)
    d = tmp_path_factory.mktemp("channels")
    specs = [ChannelSpec("SG01_sun_T3"), ChannelSpec("SG03_ring_T5"), ChannelSpec("Carrier OPR"),
             ChannelSpec("Temp [C]", units="degC")]
    data = np.column_stack([rec.data, np.full(rec.n_samples, 21.5)])
    path = meshphase.io.write(Recording(data, rec.fs, specs, meta=rec.meta), d / "rig.h5")
    return Path(path), rec


def _scene(tmp_path, rec_path, channels: str, results='["phasing"]') -> Path:
    p = tmp_path / "s.toml"
    p.write_text(f"results = {results}\n" + G + channels
                 + f'[input]\nrecording = "{rec_path}"\n', encoding="utf-8")
    return p


PATTERNS = ("[[channels]]\nregex = 'SG\\d+_sun_T(?P<tooth>\\d+)'\nkind = \"sun\"\n"
            '[[channels]]\nname = "SG*_ring*"\nkind = "ring"\n'
            '[[channels]]\nname = "Carrier OPR"\nkind = "tacho"\n')


def test_scene_with_patterns_runs_like_exact_names(rig_names_file, tmp_path):
    from meshphase.run.outputs import summary_dict
    from meshphase.run.stages import run_scene

    path, _ = rig_names_file
    exact = ('[[channels]]\nname = "SG01_sun_T3"\nkind = "sun"\ntooth = 3\n'
             '[[channels]]\nname = "SG03_ring_T5"\nkind = "ring"\n'
             '[[channels]]\nname = "Carrier OPR"\nkind = "tacho"\n')
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    a = run_scene(load_scene(_scene(tmp_path / "a", path, PATTERNS)))
    b = run_scene(load_scene(_scene(tmp_path / "b", path, exact)))
    assert a.load.recording.channels == b.load.recording.channels
    assert a.load.recording.spec("SG01_sun_T3").tooth == 3
    assert summary_dict(a)["phasing"] == summary_dict(b)["phasing"]
    # the channel no entry maps is said in the run, not silently kept
    said = [m for m in a.messages if "not mapped by the scene's [[channels]]" in m]
    assert len(said) == 1 and "Temp [C] (other)" in said[0] and said[0].startswith("load: SceneWarning")


def test_scene_pattern_errors_name_key_and_line(rig_names_file, tmp_path):
    path, _ = rig_names_file
    p = _scene(tmp_path, path, '[[channels]]\nname = "SG*"\nkind = "sun"\n'
               '[[channels]]\nregex = "SG03.*"\nkind = "ring"\n')
    with pytest.raises(SceneError) as info:
        load_scene(p)
    e = info.value
    line = p.read_text().splitlines().index('regex = "SG03.*"') + 1
    assert e.key == "channels.1.regex" and e.line == line and "map each channel once" in str(e)
    p = _scene(tmp_path, path, '[[channels]]\nname = "SG*_planet*"\nkind = "sun"\n')
    with pytest.raises(SceneError) as info:
        load_scene(p)
    assert info.value.key == "channels.0.name" and "matches no channel" in str(info.value)


def test_scene_channel_keys_checked_without_a_recording():
    with pytest.raises(SceneError, match="one of them"):
        parse_scene('results = ["ideal_phasing"]\n' + G + '[[channels]]\nkind = "sun"\n')
    with pytest.raises(SceneError) as info:
        parse_scene('results = ["ideal_phasing"]\n' + G + '[[channels]]\nregex = "("\n')
    assert info.value.key == "channels.0.regex" and "not a regular expression" in str(info.value)
    with pytest.raises(SceneError) as info:
        parse_scene('results = ["ideal_phasing"]\n' + G
                    + "[[channels]]\nregex = 'T(?P<tooth>\\d)'\ntooth = 2\n")
    assert info.value.key == "channels.0.tooth"
    with pytest.raises(SceneError, match="mapped twice"):
        parse_scene('results = ["ideal_phasing"]\n' + G
                    + '[[channels]]\nname = "SG*"\n[[channels]]\nname = "SG*"\n')


def test_mount_angle_on_a_pattern_reaches_the_channel(rig_names_file, tmp_path):
    from meshphase.run.stages import _tacho_geometry, run_scene

    path, _ = rig_names_file
    p = _scene(tmp_path, path, PATTERNS.replace('name = "SG*_ring*"\nkind = "ring"\n',
                                                'name = "SG*_ring*"\nkind = "ring"\nmount_angle_deg = 90\n'))
    ctx = run_scene(load_scene(p))
    _, mounts = _tacho_geometry(ctx)
    assert mounts["SG03_ring_T5"] == pytest.approx(np.pi / 2)


# =========================================================================== info, report
def test_info_with_scene_lists_the_mapping(rig_names_file, tmp_path, capsys):
    path, _ = rig_names_file
    p = _scene(tmp_path, path, PATTERNS)
    assert main(["-q", "info", str(path), "--scene", str(p), "--no-quality"]) == 0
    out = capsys.readouterr().out
    assert "mapping   scene" in out
    line = next(ln for ln in out.splitlines() if ln.strip().startswith("SG01_sun_T3") and "[[channels]]" in ln)
    assert "sun" in line and " 3 " in line and "[regex]" in line
    assert "unmapped  Temp [C]: as the file describes them" in out
    assert main(["-q", "info", str(path), "--scene", str(p), "--no-quality", "--json"]) == 0
    js = json.loads(capsys.readouterr().out)
    assert js["channel_map"]["unmapped"] == ["Temp [C]"]
    assert [r["channel"] for r in js["channel_map"]["rows"]][:2] == ["SG01_sun_T3", "SG03_ring_T5"]
    # without --scene: as before (no mapping)
    assert main(["-q", "info", str(path), "--no-quality", "--json"]) == 0
    assert "channel_map" not in json.loads(capsys.readouterr().out)


def test_info_with_a_scene_that_does_not_map(rig_names_file, tmp_path, capsys):
    path, _ = rig_names_file
    p = _scene(tmp_path, path, PATTERNS)
    other = tmp_path / "other.h5"
    meshphase.io.write(_rec(["x", "y"], 50), other)
    assert main(["-q", "info", str(other), "--scene", str(p), "--no-quality"]) == 1
    assert "'Carrier OPR' is not in the file; channels present: x (other), y (other)" in capsys.readouterr().err


def test_report_has_a_channel_mapping_section(rig_names_file, tmp_path):
    from meshphase.run.stages import run_scene, write_outputs

    path, _ = rig_names_file
    ctx = run_scene(load_scene(_scene(tmp_path, path, PATTERNS)))
    (tmp_path / "out").mkdir()
    files = write_outputs(ctx, tmp_path / "out")
    html = Path(files["report"]).read_text(encoding="utf-8")
    assert "Channel mapping" in html and "SG03_ring_T5" in html and "unmapped (as in the file)" in html
    assert "Not mapped by the scene" in html


def test_regex_tooth_beyond_the_gear_is_refused(tmp_path):
    # the seed rig's sun has 25 teeth (0 .. 24): "T7" reads as tooth 7, "T40" as 40
    f = tmp_path / "r.h5"
    meshphase.io.write(_rec(["SG01_sun_T7", "SG02_sun_T40"], 50), f)
    ok = _scene(tmp_path, f, "[[channels]]\nregex = 'SG01_sun_T(?P<tooth>\\d+)'\nkind = \"sun\"\n")
    assert load_scene(ok).channels[0]["regex"] == r"SG01_sun_T(?P<tooth>\d+)"
    bad = _scene(tmp_path, f, "[[channels]]\nregex = 'SG\\d+_sun_T(?P<tooth>\\d+)'\nkind = \"sun\"\n")
    with pytest.raises(SceneError) as info:
        load_scene(bad)
    e = info.value
    assert e.key == "channels.0.regex" and "'SG02_sun_T40' reads as tooth 40" in str(e)
    assert "the sun has 25 teeth" in str(e)


def test_a_message_lists_the_first_missing_names_and_counts_the_rest():
    # a scene can name any number of channels the file lacks: the message stays one short
    # line (the first MESSAGE_NAMES names, their hints, then how many more)
    from meshphase.io.channels import MESSAGE_NAMES

    many = [{"name": f"gauge_{i:05d}", "kind": "sun"} for i in range(25)]
    with pytest.raises(ChannelMapError) as e:
        map_channels(["sun_g1", "ring_g1"], many, "f.h5")
    msg = str(e.value)
    assert msg.count("'gauge_") == MESSAGE_NAMES and f"... and {25 - MESSAGE_NAMES} more is not" in msg
    assert "'gauge_00009'" in msg and "'gauge_00010'" not in msg
    few = [{"name": "sun_gauge", "kind": "sun"}]
    with pytest.raises(ChannelMapError) as e:
        map_channels(["sun_g1", "ring_g1"], few, "f.h5")
    assert "more" not in str(e.value) and "'sun_gauge'" in str(e.value)
