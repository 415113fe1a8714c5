"""A scene reads an MCAP file of another tool through ``[input.mcap]``: the same phasing as the
same samples stored in meshphase's own format; the table's mistakes named with their key."""

from __future__ import annotations

import json

import pytest
from mcap.writer import Writer

import meshphase.io as pio
from meshphase.run.scene import SceneError
from meshphase.io.mcap import foreign
from meshphase.recording import Recording
from meshphase.run.scene import parse_scene
from meshphase.run.stages import run_scene, summary_dict
from meshphase.synthetic import generate

GEARSET = ('[gearset]\nz_sun = 25\nz_ring = 87\nz_planet = 31\nn_planets = 4\n'
           'carrier_radius_mm = 112.5\nface_width_mm = 40\ndirection = "cw"\n')
PER = 512  # samples per message


def _foreign_json(rec, path):
    """One topic per channel, JSON arrays of PER samples per message, log times in Unix ns."""
    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start(profile="", library="a DAQ logger")
        sid = w.register_schema("daq.Block", "jsonschema", b'{"type": "object"}')
        cids = [w.register_channel(f"/daq/{n}", "json", sid) for n in rec.names]
        for a in range(0, rec.n_samples, PER):
            t = 1_750_000_000_000_000_000 + (a * 10**9) // int(rec.fs)
            for j, cid in enumerate(cids):
                body = {"seq": a // PER, "values": rec.data[a:a + PER, j].tolist()}
                w.add_message(cid, t, json.dumps(body).encode(), t)
        w.finish()
    return path


def _mapping_toml(rec) -> str:
    out = "[input.mcap]\nfs_Hz = 5120.0\n"
    for c in rec.channels:
        out += (f'[[input.mcap.channels]]\nname = "{c.name}"\ntopic = "/daq/{c.name}"\nfield = "values"\n'
                f'kind = "{c.kind}"\nunits = "{c.units}"\ngear = "{c.gear}"\n')
        if c.tooth is not None:
            out += f"tooth = {c.tooth}\n"
    return out


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("mcapscene")
    rec, _ = generate("seed_rig", duration=30.0, seed=7)
    # the same samples and channels without the generator's meta (gearset, nominal speeds:
    # hints a foreign file does not carry)
    pio.write(Recording(rec.data, rec.fs, rec.channels), d / "rig.h5")
    _foreign_json(rec, d / "rig.mcap")
    return d, rec


def test_scene_with_input_mcap_gives_the_phasing_of_the_same_samples(files):
    d, rec = files
    base = 'name = "x"\nresults = ["phasing"]\n' + GEARSET
    own = run_scene(parse_scene(base + '[input]\nrecording = "rig.h5"\n', d / "a.toml"))
    text = base + '[input]\nrecording = "rig.mcap"\n' + _mapping_toml(rec)
    scene = parse_scene(text, d / "b.toml")
    assert scene.input["mcap"]["fs"] == 5120.0 and len(scene.input["mcap"]["topics"]) == 3
    foreign._CACHE.clear()
    ctx = run_scene(scene)
    assert own.failed == {} and ctx.failed == {}, ctx.failed
    loaded = ctx.load.recording
    assert loaded.names == rec.names and loaded.fs == rec.fs and loaded.n_samples == rec.n_samples
    assert [c.kind for c in loaded.channels] == [c.kind for c in rec.channels]
    a, b = summary_dict(own)["phasing"], summary_dict(ctx)["phasing"]
    assert a and json.dumps(a, sort_keys=True) == json.dumps(b, sort_keys=True)


def test_input_mcap_mistakes_name_their_key(files):
    d, rec = files
    base = 'name = "x"\nresults = ["phasing"]\n' + GEARSET
    ok = parse_scene(base + '[input]\nrecording = "rig.mcap"\n[input.mcap]\nmax_jitter_s = 1e-4\n'
                     'stamp = "header.stamp"\n[[input.mcap.channels]]\nname = "fw"\ntopic = "/a"\n'
                     'field = "v"\nkind = "facewidth"\nface_position_mm = 5.0\nscale = 1e-6\n', d / "c.toml")
    assert ok.input["mcap"] == {"topics": [{"name": "fw", "topic": "/a", "field": "v", "kind": "facewidth",
                                            "face_position": 0.005, "scale": 1e-6}],
                                "max_jitter": 1e-4, "stamp": "header.stamp"}
    with pytest.raises(SceneError, match=r"input.mcap.*give \[input\] recording"):
        parse_scene(base + '[input]\nsynthetic = "seed_rig"\n[input.mcap]\n'
                    '[[input.mcap.channels]]\nname = "a"\ntopic = "/a"\nfield = "v"\n', d / "c.toml")
    with pytest.raises(SceneError, match=r"input.mcap.*channels"):
        parse_scene(base + '[input]\nrecording = "rig.mcap"\n[input.mcap]\nfs_Hz = 5120.0\n', d / "c.toml")
    with pytest.raises(SceneError, match=r"input.mcap.channels.*field"):
        parse_scene(base + '[input]\nrecording = "rig.mcap"\n[input.mcap]\n'
                    '[[input.mcap.channels]]\nname = "a"\ntopic = "/a"\nfield = "v..w"\n', d / "c.toml")
    with pytest.raises(SceneError, match=r"input.mcap.channels.*scael"):
        parse_scene(base + '[input]\nrecording = "rig.mcap"\n[input.mcap]\n'
                    '[[input.mcap.channels]]\nname = "a"\ntopic = "/a"\nfield = "v"\nscael = 2\n', d / "c.toml")
    with pytest.raises(SceneError, match=r"input.mcap.*rig.h5 is a hdf5 file"):
        parse_scene(base + '[input]\nrecording = "rig.h5"\n[input.mcap]\n'
                    '[[input.mcap.channels]]\nname = "a"\ntopic = "/a"\nfield = "v"\n', d / "c.toml")
    # a mapping naming a topic the file lacks: the load stage fails and says which
    ctx = run_scene(parse_scene(base + '[input]\nrecording = "rig.mcap"\n[input.mcap]\n'
                                '[[input.mcap.channels]]\nname = "sun"\ntopic = "/nope"\nfield = "v"\n'
                                'kind = "sun"\n', d / "c.toml"))
    assert "/nope" in str(ctx.failed["load"]) and "topics present" in str(ctx.failed["load"])


def test_process_keeps_the_gearset_files_mcap_mapping(files, tmp_path):
    # meshphase process FILE --gearset G.toml replaces [input] by FILE, and keeps G.toml's
    # [input.mcap] for an MCAP FILE (another tool's file needs its mapping)
    from meshphase.run.stages import process_recording

    d, rec = files
    g = tmp_path / "g.toml"
    g.write_text('name = "x"\nresults = ["phasing"]\n' + GEARSET + '[speeds]\nsun_rpm = 18.19\nfixed = "ring"\n'
                 f'[input]\nrecording = "{(d / "rig.mcap").as_posix()}"\n' + _mapping_toml(rec), encoding="utf-8")
    foreign._CACHE.clear()
    ctx, written = process_recording(d / "rig.mcap", g, out_dir=tmp_path / "out")
    assert ctx.load.recording.names == rec.names and "phasing" not in ctx.failed, ctx.failed


def test_the_scene_of_the_mcap_docs_page_parses(tmp_path):
    # docs/daq/mcap.md: its [input.mcap] scene is a valid scene
    import re
    from pathlib import Path

    from meshphase.io.mcap import describe_topics

    page = (Path(__file__).resolve().parents[2] / "docs" / "daq" / "mcap.md").read_text(encoding="utf-8")
    # its writer snippet (the official ROS 2 writer), on 0.1 s instead of 30 s
    (code,) = [b for b in re.findall(r"```python\n(.*?)```", page, re.S) if "mcap_ros2.writer" in b]
    monkey = code.replace("range(30 * FS)", "range(FS // 10)").replace('"run42.mcap"', repr(str(tmp_path / "run42.mcap")))
    assert monkey != code
    exec(compile(monkey, "docs/daq/mcap.md", "exec"), {})
    (t,) = describe_topics(tmp_path / "run42.mcap")
    assert (t["topic"], t["schema"], t["message_count"]) == ("/rig/strain", "rig_msgs/msg/Strain", 512)
    assert t["rate_Hz"] == pytest.approx(5120.0) and t["start_ns"] == 1_772_614_800_000_000_000
    assert [f["path"] for f in t["numeric_fields"]] == ["header.stamp.sec", "header.stamp.nanosec", "sun_t3",
                                                         "ring_r1", "tacho"]
    (toml,) = [b for b in re.findall(r"```toml\n(.*?)```", page, re.S) if "[input.mcap]" in b]
    scene = parse_scene(toml, tmp_path / "run42.toml")
    assert [t["name"] for t in scene.input["mcap"]["topics"]] == ["sun_T3", "ring_R1", "tacho"]
    assert scene.input["mcap"]["stamp"] == "header.stamp"
    rec = pio.read(tmp_path / "run42.mcap", **scene.input["mcap"])
    assert rec.names == ["sun_T3", "ring_R1", "tacho"] and rec.fs == pytest.approx(5120.0)
    assert rec.start_datetime == "2026-03-04T09:00:00+00:00"
