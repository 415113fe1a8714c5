"""The format registry: a new format is one module (registered at test time, then read
through meshphase.read, detect_format, the CLI and a scene), and every registered format
does what its FormatSpec declares."""

from __future__ import annotations

import argparse
import importlib.metadata
import inspect
import json
import textwrap
import warnings

import numpy as np
import pytest

import meshphase
import meshphase.io as pio
from meshphase.cli import main
from meshphase.errors import FormatWarning
from meshphase.io import registry
from meshphase.io.registry import FormatChoices, FormatSpec
from meshphase.run.scene import parse_scene
from meshphase.run.stages import run_scene, summary_dict
from meshphase.synthetic import generate

PLUGIN = textwrap.dedent('''
    """A test format: 8 magic bytes, a JSON header, float64 samples row after row."""
    import json
    import struct

    import numpy as np

    from meshphase.io.base import RecordingFileError, RecordingInfo, check_verify
    from meshphase.io.registry import FormatSpec
    from meshphase.recording import ChannelSpec, Recording

    MAGIC = b"MPRAW\\x00\\x01\\n"
    FORMAT = FormatSpec(name="mpraw", module=__name__, suffixes=(".mpraw",), writable=True,
                        streaming_write=True, random_access=True, description="raw float64 rows (a test plugin)")

    def sniff(head):
        return head[:8] == MAGIC

    def _header(path):
        with open(path, "rb") as fh:
            if fh.read(8) != MAGIC:
                raise RecordingFileError(path, "not an mpraw file")
            (n,) = struct.unpack("<Q", fh.read(8))
            return json.loads(fh.read(n)), 16 + n

    def read_info(path, *, verify=True):
        check_verify(verify)
        hd, _ = _header(path)
        return RecordingInfo(path=str(path), format="mpraw", fs=hd["fs"], n_samples=hd["n"],
                             channels=[ChannelSpec.from_dict(c) for c in hd["channels"]], t0=hd["t0"],
                             start_datetime=hd["start"], meta=hd["meta"], history=hd["history"])

    def read(path, channels=None, i0=0, i1=None, *, verify=True):
        info = read_info(path, verify=verify)
        _, off = _header(path)
        i1 = info.n_samples if i1 is None else i1
        nch = len(info.channels)
        data = np.fromfile(path, dtype="<f8", count=(i1 - i0) * nch, offset=off + 8 * i0 * nch)
        cols = [info.names.index(n) for n in (info.names if channels is None else channels)]
        return Recording(data.reshape(i1 - i0, nch)[:, cols].copy(), info.fs, [info.channels[c] for c in cols],
                         t0=info.t0 + i0 / info.fs, start_datetime=info.start_datetime, meta=info.meta,
                         history=info.history)

    def write_blocks(header, blocks, path, *, dtype="float64"):
        hd = json.dumps({"fs": header.fs, "n": header.n_samples, "t0": header.t0,
                         "start": header.start_datetime, "meta": header.meta,
                         "history": header.history,
                         "channels": [c.to_dict() for c in header.channels]}).encode()
        with open(path, "wb") as fh:
            fh.write(MAGIC + struct.pack("<Q", len(hd)) + hd)
            for blk in blocks:
                fh.write(np.ascontiguousarray(blk, dtype="<f8").tobytes())

    def write(recording, path):
        write_blocks(recording, [recording.data], path)
''')

GEARSET = ('[gearset]\nz_sun = 25\nz_ring = 87\nz_planet = 31\nn_planets = 4\n'
           'carrier_radius_mm = 112.5\nface_width_mm = 40\ndirection = "cw"\n')


@pytest.fixture
def plugin(tmp_path, monkeypatch):
    """The mpraw format: one module on sys.path, registered for the test only."""
    d = tmp_path / "plugin"
    d.mkdir()
    (d / "mp_test_rawfmt.py").write_text(PLUGIN)
    monkeypatch.syspath_prepend(str(d))
    mod = __import__("mp_test_rawfmt")
    spec = pio.register_format(mod.FORMAT)
    yield spec
    pio.unregister_format("mpraw")


# ---------------------------------------------------------------------------- a new format is one module
def test_plugin_reads_through_read_detect_and_iter_blocks(plugin, tmp_path, recording):
    assert "mpraw" in pio.FORMATS and pio.FORMATS[:5] == ("hdf5", "mcap", "tdms", "lvm", "csv")
    path = pio.write(recording, tmp_path / "r.mpraw")                 # suffix -> the plugin
    assert pio.detect_format(path) == "mpraw" and pio.format_of_suffix(path) == "mpraw"
    assert meshphase.read(path) == recording
    disguised = tmp_path / "r.csv"
    disguised.write_bytes(path.read_bytes())
    assert pio.detect_format(disguised) == "mpraw"                    # content, not suffix
    part = pio.read(path, ["ring_1"], start=0.1, stop=0.2)
    np.testing.assert_array_equal(part.data[:, 0], recording.data[512:1024, 1])
    blocks = list(pio.iter_blocks(path, 0.1))
    np.testing.assert_array_equal(np.concatenate([b.data for b in blocks]), recording.data)
    whole = pio.register_format(FormatSpec(name="mpwhole", module=plugin.module, writable=True))
    try:
        pio.write(recording, tmp_path / "w.bin", format="mpwhole")
        assert pio.read(tmp_path / "w.bin", format="mpwhole") == recording
        with pytest.raises(ValueError, match="'mpwhole' is not written block by block"):
            pio.write_blocks(recording, [recording.data], tmp_path / "s.bin", format="mpwhole")
    finally:
        pio.unregister_format(whole.name)


def test_plugin_in_the_cli_choices_and_convert(plugin, tmp_path, recording, capsys):
    src = pio.write(recording, tmp_path / "r.h5")
    assert main(["convert", str(src), str(tmp_path / "out.bin"), "--format", "mpraw"]) == 0
    assert pio.detect_format(tmp_path / "out.bin") == "mpraw"
    np.testing.assert_array_equal(pio.read(tmp_path / "out.bin").data, recording.data)
    capsys.readouterr()
    assert main(["info", str(tmp_path / "out.bin"), "--json", "--no-quality"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["format"] == "mpraw" and info["n_samples"] == recording.n_samples
    p = argparse.ArgumentParser()
    p.add_argument("--format", choices=FormatChoices(writable=True))
    assert p.parse_args(["--format", "mpraw"]).format == "mpraw"
    with pytest.raises(SystemExit):
        p.parse_args(["--format", "wav"])


def test_plugin_file_runs_a_scene(plugin, tmp_path):
    rec, _ = generate("seed_rig", duration=10.0, seed=3)
    pio.write(rec, tmp_path / "rig.mpraw")
    pio.write(rec, tmp_path / "rig.h5")
    base = 'name = "x"\nresults = ["phasing"]\n' + GEARSET
    own = run_scene(parse_scene(base + '[input]\nrecording = "rig.h5"\n', tmp_path / "a.toml"))
    ctx = run_scene(parse_scene(base + '[input]\nrecording = "rig.mpraw"\n', tmp_path / "b.toml"))
    assert own.failed == {} and ctx.failed == {}, ctx.failed
    a, b = summary_dict(own)["phasing"], summary_dict(ctx)["phasing"]
    assert a and json.dumps(a, sort_keys=True) == json.dumps(b, sort_keys=True)


def test_unregistered_plugin_is_unknown_again(tmp_path, recording, plugin):
    path = pio.write(recording, tmp_path / "r.mpraw")
    pio.unregister_format("mpraw")
    try:
        assert "mpraw" not in pio.FORMATS and "mpraw" not in FormatChoices()
        with pytest.raises(ValueError, match="unknown format"):
            pio.read(path)
        with pytest.raises(ValueError, match="unknown format 'mpraw'"):
            pio.get_spec("mpraw")
    finally:
        pio.register_format(plugin)


def test_register_and_unregister_refuse_bad_input(plugin):
    with pytest.raises(TypeError, match="FormatSpec"):
        pio.register_format({"name": "x"})
    with pytest.raises(ValueError, match="built in"):
        pio.register_format(FormatSpec(name="hdf5", module="x"))
    with pytest.raises(ValueError, match="registered already"):
        pio.register_format(FormatSpec(name="mpraw", module="x"))
    assert pio.register_format(plugin, replace=True) is plugin
    with pytest.raises(ValueError, match="built in"):
        pio.unregister_format("csv")
    with pytest.raises(ValueError, match="unknown format 'nope'"):
        pio.unregister_format("nope")


@pytest.mark.parametrize("kw, match", [
    ({"name": "HDF"}, "lower-case identifier"), ({"name": ""}, "lower-case identifier"),
    ({"module": "not a module"}, "dotted module path"), ({"suffixes": ("csv",)}, "suffixes"),
    ({"suffixes": ".csv"}, "suffixes"), ({"streaming_write": True}, "needs writable"),
    ({"read_options": {"verify": bool}}, "every format"), ({"rate_option": True}, "read option fs"),
    ({"write_options": {"level": int}}, "not writable"), ({"read_options": {"fs": "float"}}, "type"),
    ({"writable": 1}, "bool"), ({"read_libraries": ["h5py"]}, "tuple of str")])
def test_format_spec_refuses_bad_declarations(kw, match):
    with pytest.raises((TypeError, ValueError), match=match):
        FormatSpec(**{"name": "x", "module": "x", **kw})


def test_empty_declarations_and_lookups():
    spec = FormatSpec(name="bare", module="bare_mod")      # found by content only, read only
    assert spec.suffixes == () and not spec.writable and dict(spec.read_options) == {}
    assert pio.format_of_suffix("no_suffix") is None and pio.format_of_suffix("") is None
    with pytest.raises(ValueError, match="unknown format ''"):
        pio.get_spec("")
    with pytest.raises(ValueError, match="unknown format"):
        pio.format_for_write("x.h5", "")


def test_entry_point_plugins_load_once_and_broken_ones_are_skipped(monkeypatch, plugin):
    pio.unregister_format("mpraw")

    class EP:
        def __init__(self, name, obj):
            self.name, self.value, self._obj = name, f"pkg:{name}", obj

        def load(self):
            if isinstance(self._obj, Exception):
                raise self._obj
            return self._obj

    eps = [EP("mpraw", plugin), EP("broken", ImportError("no such module")), EP("notaspec", 42)]
    monkeypatch.setattr(importlib.metadata, "entry_points",
                        lambda group: eps if group == registry.ENTRY_POINT_GROUP else [])
    monkeypatch.setattr(registry, "_plugins_read", False)
    with pytest.warns(FormatWarning) as got:
        names = pio.format_names()
    assert "mpraw" in names and "broken" not in names and "notaspec" not in names
    assert sorted(str(w.message).split("'")[1] for w in got) == ["broken", "notaspec"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert pio.format_names() == names                  # read once
    pio.unregister_format("mpraw")
    monkeypatch.setattr(registry, "_plugins_read", True)
    pio.register_format(plugin)


# ---------------------------------------------------------------------------- declared = done
def _kwonly(fn, drop=()) -> set:
    return {p.name for p in inspect.signature(fn).parameters.values()
            if p.kind is p.KEYWORD_ONLY and p.name not in drop}


@pytest.mark.parametrize("name", ["hdf5", "mcap", "tdms", "lvm", "csv"])
def test_declared_entry_points_and_options_match_the_module(name):
    spec = pio.get_spec(name)
    mod = spec.load()
    assert mod.FORMAT is spec and pio.get_format(name) is mod
    assert hasattr(mod, "write") == spec.writable and hasattr(mod, "write_blocks") == spec.streaming_write
    for fn in (mod.read_info, mod.read, getattr(mod, "iter_blocks", mod.read)):
        assert _kwonly(fn) == set(spec.read_options) | {"verify"}, fn
    if spec.writable:
        assert _kwonly(mod.write) == set(spec.write_options)
    if spec.streaming_write:
        assert _kwonly(mod.write_blocks) == set(spec.write_options) | {"dtype"}
    assert all(pio.format_of_suffix(f"x{s.upper()}") == name for s in spec.suffixes)


@pytest.mark.parametrize("name", ["hdf5", "mcap", "tdms", "csv"])
def test_writable_formats_round_trip_whole_windows_and_blocks(name, tmp_path, recording):
    spec = pio.get_spec(name)
    assert spec.writable
    path = pio.write(recording, tmp_path / f"r{spec.suffixes[0]}")
    streamed = pio.write_blocks(recording, [recording.data[:700], recording.data[700:]],
                                tmp_path / f"s{spec.suffixes[0]}")
    assert pio.detect_format(path) == name == pio.detect_format(streamed)
    for p in (path, streamed):
        back = pio.read(p)
        np.testing.assert_array_equal(back.data, recording.data)
        assert back.names == recording.names and back.fs == recording.fs and back.t0 == recording.t0
        assert [c.kind for c in back.channels] == [c.kind for c in recording.channels]
        win = pio.read(p, ["ring_1", "sun_0"], start=0.1, stop=0.2)
        np.testing.assert_array_equal(win.data, recording.data[512:1024, [1, 0]])
    if spec.rate_option:
        assert "fs" in spec.read_options


def test_checksum_formats_skip_the_check_without_verify(tmp_path, recording):
    # the formats that declare checksums find a flipped sample byte; verify=False reads on
    from meshphase.io.base import CorruptFileError

    assert [n for n in pio.FORMATS if pio.get_spec(n).checksums] == ["hdf5", "mcap"]
    for name, suffix, opts in (("hdf5", ".h5", {}), ("mcap", ".mcap", {"compression": "none"})):
        path = pio.write(recording, tmp_path / f"r{suffix}", **opts)
        raw = bytearray(path.read_bytes())
        needle = recording.data[1000:1002, 0].astype("<f8").tobytes()
        at = bytes(raw).find(needle)
        if at < 0:   # stored channel by channel
            needle = recording.data[1000:1002, 0].astype("<f8").tobytes()[:8]
            at = bytes(raw).find(needle)
        assert at > 0, name
        raw[at + 3] ^= 0xFF
        path.write_bytes(bytes(raw))
        with pytest.raises(CorruptFileError):
            pio.read(path)
        assert pio.read(path, verify=False).n_samples == recording.n_samples


def test_tdms_write_refuses_bad_blocks(tmp_path, recording):
    with pytest.raises(ValueError, match="the header says n_samples = 2000"):
        pio.write_blocks(recording, [recording.data[:10]], tmp_path / "a.tdms")
    with pytest.raises(ValueError, match=r"\(samples, 4\)"):
        pio.write_blocks(recording, [recording.data[:, :2]], tmp_path / "b.tdms")
    with pytest.raises(ValueError, match="group"):
        pio.write(recording, tmp_path / "c.tdms", group="")
    assert sorted(p.name for p in tmp_path.iterdir()) == []
    with pytest.raises(ValueError, match="blocks hold 0 samples"):
        pio.write_blocks(recording, [], tmp_path / "d.tdms")
