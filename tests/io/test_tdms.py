"""NI TDMS reader: channel mapping, sample rate and start time, NI scaling, streaming, bad
input. Every file is built in code with npTDMS's TdmsWriter."""

from __future__ import annotations

import struct

import numpy as np
import pytest

import meshphase.io as pio
from meshphase.errors import DataQualityWarning, FormatWarning
from meshphase.io import tdms
from meshphase.io.base import CorruptFileError, RecordingFileError

FS = 5120.0


def _wf(**extra):
    return dict({"wf_increment": 1.0 / FS, "wf_start_offset": 0.0}, **extra)


@pytest.fixture
def general_path(monkeypatch):
    """Force npTDMS's general reader (read_data per channel) instead of the readinto fast path."""
    monkeypatch.setattr(tdms, "_USE_FAST_PATH", False)


# ---------------------------------------------------------------------------- sniff
def test_sniff_data_files_not_index_files():
    assert tdms.sniff(b"TDSm\x0e\x00\x00\x00")
    assert not tdms.sniff(b"TDSh\x0e\x00\x00\x00")
    assert not tdms.sniff(b"")
    assert not tdms.sniff(b"\x89HDF\r\n\x1a\n")


def test_registry_detects_tdms_by_content_and_writes_it_back(rig_tdms, tmp_path):
    path, data = rig_tdms
    renamed = tmp_path / "rig.dat"
    renamed.write_bytes(path.read_bytes())
    assert pio.detect_format(renamed) == "tdms"
    rec = pio.read(renamed)
    out = pio.write(rec, tmp_path / "out.tdms", format="tdms")
    back = pio.read(out)
    assert back.names == rec.names and back.fs == rec.fs and back.t0 == rec.t0
    assert [c.kind for c in back.channels] == [c.kind for c in rec.channels]
    np.testing.assert_array_equal(back.data, rec.data)
    with pytest.raises(FileExistsError):
        pio.write(rec, out, format="tdms")


# ---------------------------------------------------------------------------- mapping
def test_rig_file_maps_to_channel_specs(rig_tdms):
    path, data = rig_tdms
    rec = tdms.read(path)
    assert rec.names == ["sun_1", "Ring_1", "fw_left", "once_per_rev"]
    assert [c.kind for c in rec.channels] == ["sun", "ring", "facewidth", "tacho"]
    assert [c.units for c in rec.channels] == ["m/m", "m/m", "m/m", "V"]
    assert rec.spec("sun_1").tooth == 3 and rec.spec("sun_1").gear == "sun"
    assert rec.spec("fw_left").face_position == -0.01
    assert all(c.gain == 1.0 for c in rec.channels)
    assert rec.fs == FS and rec.t0 == 0.0
    assert rec.start_datetime == "2024-03-01T12:00:00.250000+00:00"
    np.testing.assert_array_equal(rec.data, data)   # float64 stored, read bit for bit
    assert rec.data.flags.f_contiguous
    assert rec.meta["tdms"]["file"] == {"title": "run 12", "author": "rig"}
    assert rec.meta["tdms"]["channels"]["sun_1"]["meshphase_tooth"] == 3
    assert rec.history == [{"step": "read_tdms", "file": "rig.tdms", "scaled": True, "ni_scaled_channels": []}]


def test_read_info_reads_no_samples(rig_tdms, monkeypatch):
    path, data = rig_tdms
    monkeypatch.setattr(tdms, "_read_window", lambda *a, **k: pytest.fail("samples read"))
    info = tdms.read_info(path)
    assert (info.fs, info.n_samples, info.format) == (FS, len(data), "tdms")
    assert info.extra["n_segments"] == 3 and info.extra["groups"] == ["Strain", "Speed"]
    assert info.extra["tdms_paths"]["sun_1"] == "/'Strain'/'sun_1'"


def test_kind_from_property_then_channel_then_group(tdms_file):
    x = np.arange(10.0)
    path = tdms_file([("Sun gauges", "SG1", x, _wf()),
                      ("Sun gauges", "ring_like", x, _wf()),
                      ("Misc", "SG3", x, _wf(meshphase_kind="facewidth", meshphase_gear="planet")),
                      ("Misc", "temp", x, _wf())])
    rec = tdms.read(path)
    assert [c.kind for c in rec.channels] == ["sun", "ring", "facewidth", "other"]
    assert rec.spec("SG3").gear == "planet"
    assert tdms.kind_from_name("TACHO", "x") == "tacho" and tdms.kind_from_name("Face2", "") == "facewidth"
    assert tdms.kind_from_name("", "") == "other"


def test_bad_meshphase_kind_property(tdms_file):
    path = tdms_file([("g", "a", np.arange(4.0), _wf(meshphase_kind="gear"))])
    with pytest.raises(RecordingFileError, match=r"channel 'a': property meshphase_kind = 'gear'"):
        tdms.read_info(path)


def test_names_clashing_across_groups_get_group_prefix(tdms_file):
    x = np.arange(6.0)
    path = tdms_file([("Left", "sun", x, _wf()), ("Right", "sun", x + 1, _wf()), ("Right", "ring", x, _wf())])
    rec = tdms.read(path)
    assert rec.names == ["Left/sun", "Right/sun", "Right/ring"]
    np.testing.assert_array_equal(rec.channel("Right/sun"), x + 1)


def test_start_offset_and_unset_start_time(tdms_file):
    x = np.arange(8.0)
    path = tdms_file([("g", "a", x, _wf(wf_start_offset=2.5, wf_start_time=np.datetime64("1904-01-01T00:00:00")))])
    rec = tdms.read(path)
    assert rec.t0 == 2.5 and rec.start_datetime is None
    assert tdms.read(path, None, 4, 8).t0 == 2.5 + 4 / FS


def test_non_numeric_channels_are_skipped_with_warning(tdms_file):
    x = np.arange(3.0)
    path = tdms_file([("g", "a", x, _wf()), ("g", "label", np.array(["u", "v", "w"]), {}),
                      ("g", "stamp", np.array(["2020-01-01T00:00:00"] * 3, dtype="datetime64[us]"), {})],
                     segments=1)
    with pytest.warns(FormatWarning, match=r"skipped channel g/\w+: no numeric data") as ws:
        rec = tdms.read(path)
    msgs = [str(w.message) for w in ws]
    assert any("g/label" in m and "String" in m for m in msgs) and any("g/stamp" in m for m in msgs)
    assert rec.names == ["a"]


def test_file_without_numeric_channels(tdms_file):
    path = tdms_file([("g", "label", np.array(["u", "v"]), {})], segments=1)
    with pytest.warns(FormatWarning), pytest.raises(RecordingFileError, match="no numeric channels"):
        tdms.read(path)


# ---------------------------------------------------------------------------- scaling
@pytest.mark.parametrize("segments", [1, 4])
def test_ni_linear_scaling_applied_and_raw_kept(tdms_file, tdms_tools, segments):
    _, linear = tdms_tools
    raw = np.arange(-50, 50, dtype=np.int16)
    path = tdms_file([("g", "sun_a", raw, _wf(**linear(2.5e-6, 1e-6), unit_string="m/m")),
                      ("g", "sun_b", raw, _wf(**linear(-3e-6, 0.0), unit_string="m/m")),
                      ("g", "plain", raw.astype(np.float64), _wf(unit_string="V"))], segments=segments)
    rec = tdms.read(path)
    np.testing.assert_array_equal(rec.channel("sun_a"), raw * 2.5e-6 + 1e-6)
    np.testing.assert_array_equal(rec.channel("sun_b"), raw * -3e-6 + 0.0)
    assert rec.data.dtype == np.float64 and all(c.gain == 1.0 for c in rec.channels)
    assert rec.history[0]["scaled"] is True and rec.history[0]["ni_scaled_channels"] == ["sun_a", "sun_b"]

    raw_rec = tdms.read(path, raw=True)
    np.testing.assert_array_equal(raw_rec.data, np.repeat(raw[:, None].astype(np.float64), 3, axis=1))
    a, b, plain = raw_rec.channels
    assert (a.units, a.gain) == ("raw", 1.0)             # offset: gain cannot express it
    assert (b.units, b.gain) == ("m/m", -3e-6)           # pure slope: physical = raw * gain
    assert (plain.units, plain.gain) == ("V", 1.0)
    assert raw_rec.history[0]["scaled"] is False
    np.testing.assert_array_equal(raw_rec.channel("sun_b") * b.gain, rec.channel("sun_b"))


def test_group_level_scaling_applies_to_its_channels(tdms_file, tdms_tools):
    _, linear = tdms_tools
    raw = np.arange(10, dtype=np.int32)
    path = tdms_file([("g", "a", raw, _wf())], group_props={"g": linear(10.0, 0.0)})
    np.testing.assert_array_equal(tdms.read(path).channel("a"), raw * 10.0)


def test_unsupported_scaling_warns_and_keeps_raw(tdms_file):
    raw = np.arange(5, dtype=np.int16)
    props = _wf(NI_Scaling_Status="unscaled", NI_Number_Of_Scales=1, **{"NI_Scale[0]_Scale_Type": "Magic"})
    path = tdms_file([("g", "a", raw, props)], segments=1)
    with pytest.warns(FormatWarning, match="cannot apply; its samples are the raw"):
        rec = tdms.read(path)
    np.testing.assert_array_equal(rec.channel("a"), raw)


def test_float32_channels_stay_float32(tdms_file):
    x = np.linspace(-1, 1, 50, dtype=np.float32)
    path = tdms_file([("g", "a", x, _wf()), ("g", "b", -x, _wf())])
    rec = tdms.read(path)
    assert rec.data.dtype == np.float32
    np.testing.assert_array_equal(rec.channel("b"), -x)


# ---------------------------------------------------------------------------- paths agree
@pytest.mark.parametrize("segments", [1, 5])
def test_fast_path_equals_nptdms_general_reader(tdms_file, tdms_tools, monkeypatch, segments):
    _, linear = tdms_tools
    rng = np.random.default_rng(3)
    n = 1001
    chans = [("g", "sun_1", rng.standard_normal(n), _wf()),
             ("g", "ring_1", rng.integers(-3000, 3000, n).astype(np.int16), _wf(**linear(1e-6, -2e-7))),
             ("h", "fw_1", rng.standard_normal(n).astype(np.float32), _wf())]
    path = tdms_file(chans, segments=segments)
    fast = [tdms.read(path), tdms.read(path, ["fw_1", "sun_1"], 17, 640), tdms.read(path, raw=True),
            *tdms.iter_blocks(path, 100, 33)]
    assert tdms.read_info(path).extra["fast_path"] is True
    monkeypatch.setattr(tdms, "_USE_FAST_PATH", False)
    general = [tdms.read(path), tdms.read(path, ["fw_1", "sun_1"], 17, 640), tdms.read(path, raw=True),
               *tdms.iter_blocks(path, 100, 33)]
    assert tdms.read_info(path).extra["fast_path"] is False
    assert len(fast) == len(general) and all(f == g for f, g in zip(fast, general))
    np.testing.assert_array_equal(fast[0].channel("sun_1"), chans[0][2])


# ---------------------------------------------------------------------------- windows, blocks
@pytest.mark.parametrize("use_general", [False, True])
def test_window_and_subset_match_slices(rig_tdms, monkeypatch, use_general):
    monkeypatch.setattr(tdms, "_USE_FAST_PATH", not use_general)
    path, _ = rig_tdms
    whole = tdms.read(path)
    assert tdms.read(path, ["fw_left", "sun_1"], 150, 451) == whole.select(["fw_left", "sun_1"]).slice_samples(150, 451)
    assert pio.read(path, "Ring_1", start=0.01, stop=0.05) == whole.select("Ring_1").slice_time(0.01, 0.05)


@pytest.mark.parametrize("block, overlap", [(64, 0), (199, 57), (1000, 10), (1, 0)])
def test_iter_blocks_match_in_memory_blocks(rig_tdms, block, overlap):
    path, _ = rig_tdms
    whole = tdms.read(path)
    got = list(tdms.iter_blocks(path, block, overlap, ["once_per_rev", "sun_1"]))
    want = list(whole.select(["once_per_rev", "sun_1"]).blocks(block / FS, overlap / FS))
    assert len(got) == len(want) and all(g == w for g, w in zip(got, want))


def test_bad_arguments(rig_tdms, tmp_path):
    path, _ = rig_tdms
    with pytest.raises(TypeError, match="raw must be a bool"):
        tdms.read(path, raw="yes")
    with pytest.raises(ValueError, match="fs must be > 0"):
        tdms.read(path, fs=-1.0)
    with pytest.raises(ValueError, match="sample range"):
        tdms.read(path, None, 5, 2)
    with pytest.raises(ValueError, match=r"no channel\(s\) \['x'\]"):
        tdms.read(path, ["x"])
    with pytest.raises(ValueError):
        list(tdms.iter_blocks(path, 0, 0))
    with pytest.raises(FileNotFoundError):
        tdms.read(tmp_path / "none.tdms")
    (tmp_path / "empty.tdms").write_bytes(b"")
    with pytest.raises(RecordingFileError, match="file is empty"):
        tdms.read_info(tmp_path / "empty.tdms")


# ---------------------------------------------------------------------------- bad input
@pytest.mark.parametrize("props", [{}, {"wf_increment": 0.0}, {"wf_increment": -1e-3}])
def test_missing_or_non_positive_sample_rate(tdms_file, props):
    x = np.arange(20.0)
    path = tdms_file([("g", "a", x, {"wf_increment": 1 / FS}), ("g", "b", x, props)])
    with pytest.raises(RecordingFileError, match=r"rec\.tdms: missing or non-positive sample rate: "
                                                 r"wf_increment of \{'b'"):
        tdms.read(path)
    with pytest.warns(FormatWarning, match=r"fs=1000.0 Hz given overrides the file's wf_increment \{'a'"):
        rec = tdms.read(path, fs=1000.0)
    assert rec.fs == 1000.0 and rec.n_samples == 20


def test_different_sample_intervals(tdms_file):
    path = tdms_file([("g", "a", np.arange(5.0), {"wf_increment": 1e-3}),
                      ("g", "b", np.arange(5.0), {"wf_increment": 2e-3})])
    with pytest.raises(RecordingFileError, match="different sample intervals"):
        tdms.read_info(path)


def test_different_start_times(tdms_file):
    path = tdms_file([("g", "a", np.arange(5.0), _wf(wf_start_time=np.datetime64("2024-01-01T00:00:00"))),
                      ("g", "b", np.arange(5.0), _wf(wf_start_time=np.datetime64("2024-01-01T00:00:01")))])
    with pytest.raises(RecordingFileError, match="channels start at different times"):
        tdms.read_info(path)


def test_channels_of_unequal_length(tdms_file):
    path = tdms_file([("g", "a", np.arange(30.0), _wf()), ("g", "b", np.arange(29.0), _wf())])
    with pytest.raises(RecordingFileError, match=r"rec\.tdms: channels of unequal length: \{'a': 30, 'b': 29\}"):
        pio.read(path)


@pytest.mark.parametrize("fraction", [0.1, 0.5, 0.99])
def test_truncated_file(rig_tdms, fraction):
    path, _ = rig_tdms
    blob = path.read_bytes()
    cut = int(len(blob) * fraction)
    path.write_bytes(blob[:cut])
    with pytest.raises(CorruptFileError, match=r"rig\.tdms: segment \d+ at byte \d+: truncated"):
        tdms.read_info(path)
    with pytest.raises(CorruptFileError, match="truncated"):
        pio.read(path)


def test_segment_never_finished(rig_tdms):
    path, _ = rig_tdms
    blob = bytearray(path.read_bytes())
    # the last segment's next-segment offset, as LabVIEW leaves it when it stops mid-segment
    last = blob.rfind(b"TDSm")
    blob[last + 12:last + 20] = struct.pack("<Q", 0xFFFFFFFFFFFFFFFF)
    path.write_bytes(bytes(blob))
    with pytest.raises(CorruptFileError, match="was never finished"):
        tdms.read(path)


def test_garbage_after_the_last_segment(rig_tdms):
    path, _ = rig_tdms
    path.write_bytes(path.read_bytes() + b"\0" * 40)
    with pytest.raises(CorruptFileError, match=r"does not start with b'TDSm'"):
        tdms.read(path)


def test_stale_index_file(tmp_path):
    from nptdms import ChannelObject, TdmsWriter

    path = tmp_path / "idx.tdms"
    with TdmsWriter(str(path), index_file=True) as w:
        w.write_segment([ChannelObject("g", "a", np.arange(5.0), properties=_wf())])
    with TdmsWriter(str(path), mode="a") as w:   # appended without updating the index
        w.write_segment([ChannelObject("g", "a", np.arange(5.0))])
    assert (tmp_path / "idx.tdms_index").exists()
    with pytest.raises(RecordingFileError, match="stale .tdms_index"):
        tdms.read(path)


def test_rewritten_file_is_not_served_from_a_stale_plan(tdms_file):
    x = np.arange(10.0)
    path = tdms_file([("g", "a", x, _wf())])
    assert tdms.read(path).names == ["a"]
    path = tdms_file([("g", "b", x, _wf(unit_string="V"))])   # same size, same place
    rec = tdms.read(path)
    assert rec.names == ["b"] and rec.spec("b").units == "V"


def test_nan_runs_warn_and_are_kept(tdms_file):
    x = np.arange(40.0)
    x[3:6] = np.nan
    x[30] = -np.inf
    path = tdms_file([("g", "sun_1", x, _wf())])
    with pytest.warns(DataQualityWarning, match=r"channel 'sun_1' has 2 run\(s\) of NaN/inf samples "
                                                r"\(4 samples, longest 3, first at sample 3\)"):
        rec = tdms.read(path)
    assert rec.n_samples == 40 and np.isnan(rec.data[3:6, 0]).all()


def test_empty_channels_read_as_zero_samples(tdms_file):
    path = tdms_file([("g", "a", np.array([], dtype=np.float64), _wf())], segments=1)
    rec = tdms.read(path)
    assert rec.n_samples == 0 and rec.names == ["a"] and list(tdms.iter_blocks(path, 10, 0)) == []


def test_meshphase_properties_restore_gain_meta_and_history(tdms_file, tdms_tools):
    import json

    _, linear = tdms_tools
    raw = np.arange(12, dtype=np.int16)
    meta = {"gearset": {"z_sun": 21}, "rig": "B2"}
    history = [{"step": "simulate", "seed": 3}]
    path = tdms_file([("meshphase", "sun_1", raw.astype(float), _wf(meshphase_gain=0.5)),
                      ("meshphase", "ring_1", raw, _wf(meshphase_gain=2.0, **linear(1e-6, 0.0)))],
                     file_props={"meshphase_meta": json.dumps(meta), "meshphase_history": json.dumps(history),
                                 "name": "synthetic"})
    rec = tdms.read(path)
    assert rec.spec("sun_1").gain == 0.5 and rec.spec("ring_1").gain == 2.0
    assert {k: v for k, v in rec.meta.items() if k != "tdms"} == meta
    assert rec.meta["tdms"]["file"] == {"name": "synthetic"}
    assert rec.history[:1] == history and rec.history[1]["step"] == "read_tdms" and len(rec.history) == 2
    assert tdms.read(path, raw=True).spec("ring_1").gain == pytest.approx(2e-6)


@pytest.mark.parametrize("props, match", [({"meshphase_meta": "{oops"}, "meshphase_meta is not valid JSON"),
                                          ({"meshphase_history": "{}"}, "meshphase_history must hold a JSON array")])
def test_bad_meshphase_file_properties(tdms_file, props, match):
    path = tdms_file([("g", "a", np.arange(3.0), _wf())], file_props=props)
    with pytest.raises(RecordingFileError, match=match):
        tdms.read(path)


def test_duplicate_channel_names_after_group_prefixing(tdms_file):
    x = np.arange(4.0)
    # "c" appears twice, so every channel gets its group prefix, and two become "a/b/c"
    path = tdms_file([("a", "b/c", x, _wf()), ("a/b", "c", x, _wf()), ("x", "c", x, _wf())])
    with pytest.raises(RecordingFileError, match=r"rec\.tdms: duplicate channel name\(s\) \['a/b/c'\]"):
        tdms.read_info(path)


# ---------------------------------------------------------------------------- clock channels
def _clocked(path, clock, n=10240, extra=()):
    """A TDMS file without waveform timing, as DIAdem or a script writes one: a clock
    channel (``clock`` = (name, values) or None) beside two data channels; the data."""
    from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

    rng = np.random.default_rng(3)
    x, y = rng.normal(size=n), rng.normal(size=n)
    objs = [RootObject(), GroupObject("Log")]
    if clock is not None:
        objs.append(ChannelObject("Log", clock[0], clock[1]))
    objs += [ChannelObject("Log", "sun_T3", x), ChannelObject("Log", "ring_T1", y), *extra]
    with TdmsWriter(str(path)) as w:
        w.write_segment(objs)
    return np.c_[x, y]


@pytest.mark.parametrize("name, values, t0, start", [
    ("Time", np.arange(10240) / 5120.0, 0.0, None),
    ("zeit", (600.0 + np.arange(10240) / 5120.0).astype(np.float32), 600.0, None),   # LabVIEW SGL
    ("Stamp", (np.datetime64("2026-11-28T10:00:00", "us")
               + np.round(np.arange(10240) / 5120.0 * 1e6).astype("timedelta64[us]")),
     0.0, "2026-11-28T10:00:00"),
])
def test_clock_channel_gives_the_time_axis(tmp_path, name, values, t0, start):
    # no wf_increment anywhere: the file was 'missing or non-positive sample rate' however
    # plainly its Time channel said it; now that channel is the time axis, not a channel
    path = tmp_path / "clock.tdms"
    data = _clocked(path, (name, values))
    rec = pio.read(path)
    assert rec.fs == 5120.0 and rec.names == ["sun_T3", "ring_T1"]
    assert rec.t0 == pytest.approx(t0, abs=1e-4)
    assert (rec.start_datetime or "").startswith(start) if start else rec.start_datetime is None
    np.testing.assert_array_equal(rec.data, data)
    blocks = list(pio.iter_blocks(path, 0.5, 0.01))
    np.testing.assert_array_equal(np.concatenate([b.data[:2560] for b in blocks]), data)


def test_clock_channel_names_a_dropped_sample(tmp_path):
    t = np.delete(np.arange(10241) / 5120.0, 700)
    path = tmp_path / "drop.tdms"
    _clocked(path, ("Time", t))
    with pytest.raises(RecordingFileError, match=r"non-uniform time in clock channel 'Time' at sample 700"):
        pio.read(path)


def test_without_clock_or_waveform_timing_the_error_says_how_to_give_the_rate(tmp_path):
    path = tmp_path / "none.tdms"
    data = _clocked(path, None)
    with pytest.raises(RecordingFileError, match=r"no clock channel .*\[input\] fs_Hz in a scene"):
        pio.read(path)
    np.testing.assert_array_equal(pio.read(path, fs=5120.0).data, data)   # the rate given


def test_a_channel_named_time_in_a_waveform_file_stays_a_channel(tmp_path):
    # with wf_increment present the file's timing stands, and 'Time' is just a channel
    from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

    wf = {"wf_increment": 1 / 5120.0, "wf_start_offset": 0.0}
    with TdmsWriter(str(tmp_path / "wf.tdms")) as w:
        w.write_segment([RootObject(), GroupObject("G"),
                         ChannelObject("G", "Time", np.arange(100.0), properties=wf),
                         ChannelObject("G", "sun", np.ones(100), properties=wf)])
    rec = pio.read(tmp_path / "wf.tdms")
    assert rec.names == ["Time", "sun"] and rec.fs == 5120.0


def test_a_lone_time_channel_is_not_a_clock(tmp_path):
    from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

    with TdmsWriter(str(tmp_path / "lone.tdms")) as w:
        w.write_segment([RootObject(), GroupObject("G"), ChannelObject("G", "Time", np.arange(100) / 10.0)])
    with pytest.raises(RecordingFileError, match="missing or non-positive sample rate"):
        pio.read(tmp_path / "lone.tdms")
