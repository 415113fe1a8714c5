"""Scenes with an encoder channel: its [[channels]] keys validated up front, errors naming
the key and its line; the keys reach the channel spec."""

from __future__ import annotations

import pytest

from meshphase.io.channels import mapped_specs, map_channels
from meshphase.recording import ChannelSpec
from meshphase.run.scene import SceneError, parse_scene

HEAD = ('results = ["bearing_moments"]\n[bearing]\ncase = "1"\n'
        '[[channels]]\nname = "sg"\nkind = "sun"\n')


def _err(text: str) -> SceneError:
    with pytest.raises(SceneError) as info:
        parse_scene(text, "/data/enc.toml")
    return info.value


def _line(text: str, fragment: str) -> int:
    return next(i + 1 for i, ln in enumerate(text.splitlines()) if fragment in ln)


def test_an_encoder_entry_parses_and_reaches_the_channel_spec():
    text = HEAD + '[[channels]]\nname = "enc"\nkind = "encoder"\nshaft = "input"\npulses_per_rev = 60\n'
    scene = parse_scene(text, "/data/enc.toml")
    entry = scene.channels[1]
    assert (entry["shaft"], entry["pulses_per_rev"]) == ("input", 60)
    specs = [ChannelSpec("sg"), ChannelSpec("enc", units="V")]
    out, _ = mapped_specs(specs, map_channels(["sg", "enc"], scene.channels))
    assert (out[1].kind, out[1].shaft, out[1].pulses_per_rev) == ("encoder", "input", 60)


@pytest.mark.parametrize("missing, example", [("shaft", 'shaft = "sun"'),
                                              ("pulses_per_rev", "pulses_per_rev = 60")])
def test_an_encoder_needs_its_shaft_and_pulses(missing, example):
    keys = {"shaft": 'shaft = "sun"\n', "pulses_per_rev": "pulses_per_rev = 60\n"}
    del keys[missing]
    text = HEAD + '[[channels]]\nname = "enc"\nkind = "encoder"\n' + "".join(keys.values())
    e = _err(text)
    assert e.key == "channels.1.kind"
    assert e.line == _line(text, 'kind = "encoder"')
    assert f"an encoder channel needs {missing} (e.g. {example})" in str(e)


def test_encoder_keys_on_a_gauge_are_refused():
    text = HEAD.replace('kind = "sun"\n', 'kind = "sun"\npulses_per_rev = 60\n')
    e = _err(text)
    assert e.key == "channels.0.pulses_per_rev"
    assert e.line == _line(text, "pulses_per_rev")
    assert "belongs to an encoder channel" in str(e) and "'sun'" in str(e)


@pytest.mark.parametrize("key, value, fragment", [("shaft", '"planet"', "shaft"),
                                                  ("pulses_per_rev", "0", "pulses_per_rev"),
                                                  ("pulses_per_rev", "2.5", "pulses_per_rev")])
def test_bad_encoder_values_name_their_key(key, value, fragment):
    other = {"shaft": 'shaft = "sun"\n', "pulses_per_rev": "pulses_per_rev = 60\n"}
    other[key] = f"{key} = {value}\n"
    text = HEAD + '[[channels]]\nname = "enc"\nkind = "encoder"\n' + "".join(other.values())
    e = _err(text)
    assert e.key == f"channels.1.{key}"
    assert e.line == _line(text, f"{key} = {value}")
