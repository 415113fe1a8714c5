"""HDF5 reader/writer: layout, lossless round trip, partial reads, bad input."""

from __future__ import annotations

import json
import warnings

import h5py
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import meshphase.io as pio
from meshphase.data_schemas import validate
from meshphase.errors import DataQualityWarning, FormatWarning
from meshphase.io import hdf5
from meshphase.io.base import CorruptFileError, RecordingFileError
from meshphase.recording import ChannelSpec, Recording


def _write(rec, path, **kw):
    hdf5.write(rec, path, **kw)
    return path


def _bits_equal(a, b):
    a = np.ascontiguousarray(a)
    b = np.ascontiguousarray(b)
    view = np.uint64 if a.dtype == np.float64 else np.uint32
    return a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a.view(view), b.view(view))


# ---------------------------------------------------------------------------- sniff
def test_sniff_magic_at_start_and_in_userblock_offsets():
    magic = b"\x89HDF\r\n\x1a\n"
    assert hdf5.sniff(magic + b"\0" * 100)
    assert hdf5.sniff(b"\0" * 512 + magic)
    assert hdf5.sniff(b"\0" * 1024 + magic)
    assert not hdf5.sniff(b"\0" * 100 + magic)      # not a userblock offset
    assert not hdf5.sniff(b"")
    assert not hdf5.sniff(b"TDSm" + b"\0" * 40)
    assert not hdf5.sniff(b"time [s],a [m/m]\n0,1\n")


def test_file_with_userblock_is_read(tmp_path, recording):
    import h5py

    path = tmp_path / "ub.h5"
    with h5py.File(path, "w", userblock_size=512) as f:
        f.create_group("x")
    head = path.read_bytes()[:4096]
    assert hdf5.sniff(head) and head[:8] != b"\x89HDF\r\n\x1a\n"
    assert pio.detect_format(path) == "hdf5"


# ---------------------------------------------------------------------------- round trip
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("compression", [None, "gzip", "lzf"])
def test_round_trip_lossless(tmp_path, dtype, compression, make_recording):
    rec = make_recording(n=3000, n_channels=5, dtype=dtype, t0=-1.25, nan_runs=True)
    # a NaN with a non-default payload and a negative zero must survive bit for bit
    payload_nan = np.array([0x7FF800000000BEEF], dtype=np.uint64).view(np.float64)[0]
    rec.data[100, 2] = payload_nan.astype(dtype) if dtype == np.float64 else np.float32(np.nan)
    path = _write(rec, tmp_path / "r.h5", compression=compression)
    with pytest.warns(DataQualityWarning) as rec_w:
        back = hdf5.read(path)
    assert back == rec
    assert _bits_equal(back.data, rec.data)
    assert back.channels == rec.channels
    assert (back.fs, back.t0, back.start_datetime) == (rec.fs, rec.t0, rec.start_datetime)
    assert back.meta == rec.meta and back.history == rec.history
    msgs = [str(w.message) for w in rec_w]
    assert any("'ring_1'" in m and "2 run(s)" not in m and "run(s)" in m for m in msgs)


def test_nan_runs_warn_with_channel_and_run_count_and_keep_data(tmp_path, make_recording):
    rec = make_recording(n=200, n_channels=3, nan_runs=True)
    path = _write(rec, tmp_path / "nan.h5")
    with pytest.warns(DataQualityWarning, match=r"channel 'ring_1' has 3 run\(s\) of NaN/inf samples \(7 samples, "
                                                r"longest 4, first at sample 5\)"):
        back = hdf5.read(path)
    assert np.isnan(back.data[5:9, 1]).all() and np.isinf(back.data[20, 1])
    assert back.n_samples == 200  # nothing dropped


def test_every_channel_spec_field_round_trips(tmp_path):
    specs = [ChannelSpec("sun a/b%", "sun", "m/m", 2.5, "sun", 7, None, "root gauge, 45 deg"),
             ChannelSpec(".", "facewidth", "µm/m", -1.0, "planet", 0, -0.0125, ""),
             ChannelSpec("tacho", "tacho", "", 1.0, None, None, None, "once per rev")]
    rec = Recording(np.zeros((10, 3)), 51200.0, specs)
    path = _write(rec, tmp_path / "s.h5")
    back = hdf5.read(path)
    assert back.channels == tuple(specs)
    for got, want in zip(back.channels, specs):
        assert got.to_dict() == want.to_dict()


@settings(max_examples=40, deadline=None)
@given(n=st.integers(0, 300), n_ch=st.integers(0, 4), dtype=st.sampled_from([np.float32, np.float64]),
       t0=st.floats(-1e4, 1e4, allow_nan=False), fs=st.floats(1e-3, 1e6, allow_nan=False, exclude_min=True),
       chunk=st.integers(1, 400), seed=st.integers(0, 2**32 - 1))
def test_round_trip_property(tmp_path_factory, n, n_ch, dtype, t0, fs, chunk, seed):
    rng = np.random.default_rng(seed)
    if dtype == np.float64:   # random bit patterns: every exponent, subnormals, signed zeros
        data = rng.integers(0, 2**64, size=(n, n_ch), dtype=np.uint64).view(np.float64)
    else:
        data = rng.integers(0, 2**32, size=(n, n_ch), dtype=np.uint64).astype(np.uint32).view(np.float32)
    data = np.where(np.isfinite(data), data, dtype(0.0))   # NaN/inf runs are covered elsewhere
    rec = Recording(data, fs, [f"c{j}" for j in range(n_ch)], t0=t0)
    path = tmp_path_factory.mktemp("h5") / "p.h5"
    _write(rec, path, chunk_samples=chunk)
    back = hdf5.read(path)
    assert back == rec and _bits_equal(back.data, rec.data)


def test_empty_recording_and_zero_channels_round_trip(tmp_path):
    for i, rec in enumerate([Recording(np.empty((0, 2), np.float32), 100.0, ["a", "b"]),
                             Recording(np.empty((7, 0)), 100.0, [], t0=3.0)]):
        path = _write(rec, tmp_path / f"e{i}.h5")
        back = hdf5.read(path)
        assert back == rec
        assert hdf5.read_info(path).n_samples == rec.n_samples


# ---------------------------------------------------------------------------- layout
def test_layout_is_channel_major_chunked_with_spec_attributes(tmp_path, recording):
    path = _write(recording, tmp_path / "l.h5", chunk_samples=512)
    with h5py.File(path, "r") as f:
        # text attributes are fixed-length UTF-8 (checksummed object header): bytes in h5py
        assert f.attrs["meshphase_format"] == b"recording"
        assert f.attrs["format_version"] == hdf5.FORMAT_VERSION
        assert [n.decode() for n in f.attrs["channel_order"]] == recording.names
        assert json.loads(f.attrs["meta"]) == recording.meta
        for spec in recording.channels:
            ds = f["channels"][spec.name]
            assert ds.shape == (recording.n_samples,) and ds.chunks == (512,)
            assert ds.compression is None
            assert ds.attrs["kind"].decode() == spec.kind and ds.attrs["gain"] == spec.gain
            assert ("tooth" in ds.attrs) == (spec.tooth is not None)


def test_default_chunking_and_compression_options(tmp_path, recording):
    p1 = _write(recording, tmp_path / "d.h5")
    p2 = _write(recording, tmp_path / "g.h5", compression="gzip", compression_opts=9)
    with h5py.File(p1, "r") as f1, h5py.File(p2, "r") as f2:
        d1, d2 = f1["channels/sun_0"], f2["channels/sun_0"]
        assert d1.chunks == (min(recording.n_samples, hdf5.DEFAULT_CHUNK_SAMPLES),)
        assert d2.compression == "gzip" and d2.compression_opts == 9 and d2.shuffle
    assert hdf5.read_info(p2).extra["compression"] == "gzip"


@pytest.mark.parametrize("kw, exc", [({"compression": "zstd"}, ValueError),
                                     ({"compression": "lzf", "compression_opts": 4}, ValueError),
                                     ({"compression": "gzip", "compression_opts": 12}, ValueError),
                                     ({"chunk_samples": 0}, ValueError),
                                     ({"shuffle": "yes"}, TypeError)])
def test_bad_write_options(tmp_path, recording, kw, exc):
    with pytest.raises(exc):
        hdf5.write(recording, tmp_path / "x.h5", **kw)


def test_what_we_write_matches_the_schema(tmp_path, recording):
    path = _write(recording, tmp_path / "v.h5")
    with h5py.File(path, "r") as f:
        inst = {"attrs": {k: hdf5._plain(v) for k, v in f.attrs.items()},
                "channels": {k: {"shape": list(d.shape), "dtype": str(d.dtype),
                                 "attrs": {a: hdf5._plain(v) for a, v in d.attrs.items()}}
                             for k, d in f["channels"].items()}}
    validate(inst, "hdf5_layout")
    inst["channels"]["sun_0"]["attrs"]["kind"] = "gear"
    with pytest.raises(ValueError, match=r"hdf5_layout.schema.json: at /channels/sun_0/attrs/kind"):
        validate(inst, "hdf5_layout")


# ---------------------------------------------------------------------------- partial reads
def test_read_info_reads_no_samples(tmp_path, recording, monkeypatch):
    path = _write(recording, tmp_path / "i.h5")

    def boom(*a, **k):
        raise AssertionError("samples read")

    monkeypatch.setattr(h5py.Dataset, "read_direct", boom)
    monkeypatch.setattr(h5py.Dataset, "__getitem__", boom)
    info = hdf5.read_info(path)
    assert (info.fs, info.n_samples, info.t0) == (recording.fs, recording.n_samples, recording.t0)
    assert info.channels == list(recording.channels) and info.meta == recording.meta
    assert info.format == "hdf5" and info.extra["dtype"] == "float64"


def test_window_and_channel_subset_match_slices(tmp_path, recording):
    path = _write(recording, tmp_path / "w.h5", chunk_samples=300)
    back = hdf5.read(path, ["ring_1", "sun_0"], 123, 1017)
    want = recording.select(["ring_1", "sun_0"]).slice_samples(123, 1017)
    assert back == want
    assert back.t0 == recording.t0 + 123 / recording.fs
    via_registry = pio.read(path, channels="tacho_3", start=0.01, stop=0.2)
    assert via_registry == recording.select(["tacho_3"]).slice_time(0.01, 0.2)


def test_one_channel_read_touches_only_its_dataset(tmp_path, recording, monkeypatch):
    path = _write(recording, tmp_path / "o.h5")
    seen = []
    orig = h5py.Dataset.read_direct

    def spy(self, dest, source_sel=None, dest_sel=None):
        seen.append((self.name, source_sel))
        return orig(self, dest, source_sel, dest_sel)

    monkeypatch.setattr(h5py.Dataset, "read_direct", spy)
    hdf5.read(path, ["facewidth_2"], 10, 20)
    assert seen == [("/channels/facewidth_2", np.s_[10:20])]


def test_output_is_channel_major_writable_and_keeps_dtype(tmp_path, make_recording):
    rec = make_recording(n=100, n_channels=3, dtype=np.float32)
    path = _write(rec, tmp_path / "f.h5")
    back = hdf5.read(path)
    assert back.data.dtype == np.float32
    assert back.data.flags.f_contiguous and back.data.flags.writeable


@pytest.mark.parametrize("block_s, overlap_s, channels", [(0.05, 0.0, None), (0.031, 0.007, ["ring_1"]),
                                                          (1.0, 0.5, None)])
def test_iter_blocks_match_in_memory_blocks(tmp_path, recording, block_s, overlap_s, channels):
    path = _write(recording, tmp_path / "b.h5", chunk_samples=256)
    got = list(hdf5.iter_blocks(path, round(block_s * recording.fs), round(overlap_s * recording.fs), channels))
    want = list(recording.select(channels).blocks(block_s, overlap_s))
    assert len(got) == len(want) and all(g == w for g, w in zip(got, want))


def test_read_bad_range_and_channels(tmp_path, recording):
    path = _write(recording, tmp_path / "r.h5")
    with pytest.raises(ValueError, match="sample range"):
        hdf5.read(path, None, 10, 5)
    with pytest.raises(ValueError, match="sample range"):
        hdf5.read(path, None, 0, recording.n_samples + 1)
    with pytest.raises(ValueError, match=r"no channel\(s\) \['nope'\]"):
        hdf5.read(path, ["nope"])
    with pytest.raises(ValueError, match="empty"):
        hdf5.read(path, [])
    with pytest.raises(ValueError):
        list(hdf5.iter_blocks(path, 0, 0))
    with pytest.raises(ValueError):
        list(hdf5.iter_blocks(path, 10, -1))


# ---------------------------------------------------------------------------- header cache
def test_rewritten_file_is_never_served_from_a_stale_header(tmp_path, recording, make_recording):
    path = tmp_path / "c.h5"
    pio.write(recording, path)
    assert hdf5.read_info(path).channels == list(recording.channels)
    other = make_recording(n=recording.n_samples, n_channels=recording.n_channels, seed=1)
    other = Recording(other.data, other.fs, [ChannelSpec(f"x{j}") for j in range(other.n_channels)])
    pio.write(other, path, overwrite=True)
    assert hdf5.read_info(path).names == other.names
    assert hdf5.read(path) == other


def test_returned_metadata_is_not_shared_between_reads(tmp_path, recording):
    path = _write(recording, tmp_path / "m.h5")
    a = hdf5.read(path)
    a.meta["gearset"]["z_sun"] = 999
    a.history[0]["step"] = "changed"
    b = hdf5.read(path)
    assert b.meta == recording.meta and b.history == recording.history


# ---------------------------------------------------------------------------- bad input
@pytest.mark.parametrize("fraction", [0.1, 0.5, 0.99])
def test_truncated_file_raises(tmp_path, recording, fraction):
    path = _write(recording, tmp_path / "t.h5")
    blob = path.read_bytes()
    path.write_bytes(blob[: int(len(blob) * fraction)])
    with pytest.raises(CorruptFileError, match=r"t\.h5: file of \d+ bytes: cannot open as HDF5: truncated or corrupt"):
        hdf5.read_info(path)
    with pytest.raises(RecordingFileError, match="truncated or corrupt"):
        pio.read(path)


def _edit(path, fn):
    with h5py.File(path, "r+") as f:
        fn(f)


@pytest.mark.parametrize("fs", [None, 0.0, -5120.0, float("nan")])
def test_missing_or_non_positive_sample_rate(tmp_path, recording, fs):
    path = tmp_path / "fs.h5"
    hdf5.write(recording, path)

    def edit(f):
        del f.attrs["fs"]
        if fs is not None:
            f.attrs["fs"] = fs

    _edit(path, edit)
    with pytest.raises(RecordingFileError, match=r"fs\.h5: missing or non-positive sample rate"):
        hdf5.read(path)


def test_channels_of_unequal_length(tmp_path, recording):
    path = tmp_path / "u.h5"
    hdf5.write(recording, path)

    def edit(f):
        attrs = dict(f["channels/ring_1"].attrs)
        del f["channels/ring_1"]
        ds = f["channels"].create_dataset("ring_1", data=np.zeros(recording.n_samples - 3))
        ds.attrs.update(attrs)

    _edit(path, edit)
    with pytest.raises(RecordingFileError, match=r"u\.h5: channels of unequal length .*'ring_1': 1997"):
        hdf5.read_info(path)


def test_duplicate_channel_names(tmp_path, recording):
    path = tmp_path / "d.h5"
    hdf5.write(recording, path)
    _edit(path, lambda f: f.attrs.__setitem__(
        "channel_order", np.array(["sun_0", "sun_0", "facewidth_2", "tacho_3"], dtype=h5py.string_dtype())))
    with pytest.raises(RecordingFileError, match=r"d\.h5: duplicate channel name\(s\) \['sun_0'\]"):
        hdf5.read(path)


def test_schema_violation_names_the_key(tmp_path, recording):
    path = tmp_path / "k.h5"
    hdf5.write(recording, path)
    _edit(path, lambda f: f["channels/sun_0"].attrs.__setitem__("kind", "planet"))
    with pytest.raises(RecordingFileError, match=r"k\.h5: bad header: .*at /channels/sun_0/attrs/kind: 'planet'"):
        hdf5.read_info(path)


@pytest.mark.parametrize("edit, match", [
    (lambda f: f.attrs.__setitem__("meshphase_format", "other"), "not a meshphase recording"),
    (lambda f: f.attrs.__setitem__("format_version", 99), "layout version 99"),
    (lambda f: f.attrs.__setitem__("meta", "{not json"), "meta is not valid JSON"),
    (lambda f: f.attrs.__setitem__("history", "{}"), "history must be a JSON array"),
    (lambda f: f.attrs.__setitem__("start_datetime", "yesterday"), "not ISO 8601"),
    (lambda f: f["channels/sun_0"].attrs.__setitem__("name", "zzz"), "name attribute 'zzz'"),
    (lambda f: f["channels"].create_dataset("stray", data=np.zeros(3)), r"at /channels/stray/attrs: 'name' is a "),
    (lambda f: f["channels"].copy("sun_0", "stray"), r"\['stray'\] in /channels are not listed in channel_order"),
    (lambda f: f["channels"].move("tacho_3", "gone"), r"\['tacho_3'\] listed in channel_order have no dataset"),
    (lambda f: f.__delitem__("channels"), "group /channels missing"),
])
def test_malformed_headers_raise(tmp_path, recording, edit, match):
    path = tmp_path / "h.h5"
    hdf5.write(recording, path)
    _edit(path, edit)
    with pytest.raises(RecordingFileError, match=match):
        hdf5.read(path)


def test_foreign_hdf5_file_without_a_rate_says_how_to_give_it(tmp_path):
    path = tmp_path / "foreign.h5"
    with h5py.File(path, "w") as f:
        f["data"] = np.arange(10.0)
    with pytest.raises(RecordingFileError, match=r"foreign.h5: an HDF5 file of another tool with no sample "
                                                 r"rate: .*\[input\] fs_Hz in a scene"):
        pio.read(path)
    rec = pio.read(path, fs=100.0)
    assert rec.fs == 100.0 and rec.names == ["data"] and np.array_equal(rec.data[:, 0], np.arange(10.0))
    with h5py.File(tmp_path / "empty.h5", "w") as f:
        f["text"] = "no samples"
    with pytest.raises(RecordingFileError, match="not a meshphase recording .* no 1-D numeric dataset"):
        pio.read(tmp_path / "empty.h5")


def _foreign(path, layout):
    """An HDF5 file as other tools write one; the samples of its channels by name."""
    rng = np.random.default_rng(5)
    x, y = rng.normal(size=10240), rng.normal(size=10240)
    with h5py.File(path, "w") as f:
        if layout == "rate attribute":                  # one dataset per channel, rate on each
            for n, v in (("sun", x), ("ring", y)):
                f[n] = v
                f[n].attrs["sample_rate"] = 5120.0
                f[n].attrs["units"] = "m/m"
        elif layout == "interval on the group":         # a group with dt, mixed dtypes, a stray
            g = f.create_group("Rig")
            g.attrs["dt"] = 1 / 5120.0
            g["SG_sun_T3"] = x.astype(np.float32)
            g["SG_ring_T1"] = (y * 1000).astype(np.int16)
            f["calibration"] = [1.0, 2.0, 3.0]
            return {"SG_sun_T3": x.astype(np.float32), "SG_ring_T1": (y * 1000).astype(np.int16)}
        else:                                           # a clock dataset
            f["time"] = 100.0 + np.arange(10240) / 5120.0
            f["sun"], f["ring"] = x, y
    return {"sun": x, "ring": y}


@pytest.mark.parametrize("layout, t0", [("rate attribute", 0.0), ("interval on the group", 0.0),
                                        ("clock dataset", 100.0)])
def test_hdf5_files_of_other_tools_read(tmp_path, layout, t0):
    # it was 'an HDF5 file but not a meshphase recording' whatever it held: now its 1-D
    # numeric datasets of one length are the channels, the rate from an attribute or a clock
    path = tmp_path / "other.h5"
    want = _foreign(path, layout)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rec = pio.read(path)
    assert rec.fs == 5120.0 and rec.t0 == pytest.approx(t0) and sorted(rec.names) == sorted(want)
    for n, v in want.items():
        np.testing.assert_array_equal(rec.channel(n), v.astype(np.float64))
    assert [str(w.message) for w in caught if "skipped dataset" in str(w.message)] == (
        [f"{path}: skipped dataset(s) ['/calibration']: shorter than the channels (10240 samples)"]
        if layout == "interval on the group" else [])
    blocks = list(pio.iter_blocks(path, 0.5, 0.01))
    np.testing.assert_array_equal(np.concatenate([b.data[:2560] for b in blocks]), rec.data)
    assert rec.history[-1]["layout"] == "other tool"


def test_write_bad_input(tmp_path, recording):
    with pytest.raises(TypeError, match="must be a Recording"):
        hdf5.write(recording.data, tmp_path / "x.h5")
    bad = Recording(recording.data, recording.fs, recording.channels, meta={"obj": object()})
    with pytest.raises(TypeError, match="recording meta: value of type object"):
        hdf5.write(bad, tmp_path / "y.h5")


def test_meta_that_changes_on_json_round_trip_warns(tmp_path, recording):
    rec = Recording(recording.data, recording.fs, recording.channels, meta={"pair": (1, 2)})
    with pytest.warns(FormatWarning, match="tuples become lists"):
        hdf5.write(rec, tmp_path / "t.h5")
    assert hdf5.read(tmp_path / "t.h5").meta == {"pair": [1, 2]}


def test_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError):
        hdf5.read_info(tmp_path / "none.h5")


def test_no_warning_for_clean_data(tmp_path, recording):
    path = _write(recording, tmp_path / "clean.h5")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        hdf5.read(path)


# ---------------------------------------------------------------------------- schema loader
def test_schema_loader():
    from meshphase.data_schemas import load_schema, schema_names

    assert {"channel_spec", "hdf5_layout"} <= set(schema_names())
    a = load_schema("hdf5_layout")
    assert a == load_schema("hdf5_layout.schema.json") and a["title"].startswith("meshphase HDF5")
    a["title"] = "changed"
    assert load_schema("hdf5_layout")["title"] != "changed"        # callers get a fresh copy
    validate({"name": "a", "kind": "sun", "tooth": 2, "gear": None}, "channel_spec")
    with pytest.raises(ValueError, match=r"^x\.h5: does not match channel_spec\.schema\.json: at /tooth: -1 is less"):
        validate({"name": "a", "kind": "sun", "tooth": -1}, "channel_spec", where="x.h5")
    with pytest.raises(ValueError, match=r"at \(top level\): Additional properties .*'colour'"):
        validate({"name": "a", "kind": "sun", "colour": 1}, "channel_spec")
    with pytest.raises(ValueError, match=r"no schema 'nope\.schema\.json' .*available: .*channel_spec"):
        load_schema("nope")
    with pytest.raises(ValueError, match="plain name"):
        load_schema("../pyproject")
    with pytest.raises(TypeError, match="schema name must be a string"):
        validate({}, 3)


# ------------------------------------------------------------------ text attribute integrity
def test_damaged_text_attribute_is_an_error_naming_the_file(tmp_path, recording):
    """A letter of a channel attribute changed in the file: fixed-length text attributes live
    in the object header, whose checksum HDF5 checks (variable-length ones, in the global
    heap, would read back silently changed)."""
    path = _write(recording, tmp_path / "t.h5")
    blob = bytearray(path.read_bytes())
    off = blob.index(recording.channels[0].name.encode(), 2048)
    blob[off] ^= 0x20
    bad = tmp_path / "bad.h5"
    bad.write_bytes(bytes(blob))
    with pytest.raises(CorruptFileError, match="bad.h5"):
        pio.read(bad)


def test_large_meta_carries_a_crc_that_is_checked(tmp_path, recording):
    """meta over 60 kB leaves the checksummed object header: its CRC32 stays there and
    catches a changed letter; the text still round-trips."""
    rec = Recording(recording.data, recording.fs, recording.channels,
                    meta={"note": "x" * 70_000, "rig": "bench 3"})
    path = _write(rec, tmp_path / "m.h5")
    assert pio.read(path).meta == rec.meta
    with h5py.File(path, "r+") as f:
        assert "meta_crc32" in f.attrs
        f.attrs["meta"] = json.dumps({"note": "x" * 70_000, "rig": "bench 4"})
    with pytest.raises(CorruptFileError, match="root attribute meta.*CRC32"):
        pio.read(path)


def test_attributes_edited_with_h5py_defaults_still_read(tmp_path, recording):
    """A user editing a small attribute with h5py (variable-length str) is not damage."""
    path = _write(recording, tmp_path / "e.h5")
    with h5py.File(path, "r+") as f:
        f.attrs["meta"] = json.dumps({"operator": "K. Lee"})
        f["channels"][hdf5.dataset_name(recording.channels[0].name)].attrs["units"] = "V"
    back = pio.read(path)
    assert back.meta == {"operator": "K. Lee"}
    assert back.channels[0].units == "V"


@pytest.mark.parametrize("layout", ["samples x channels, names and units lists", "channels x samples, float32",
                                    "clock column, names as one string"])
def test_hdf5_matrix_datasets_of_other_tools_read(tmp_path, layout):
    # an h5py script often stores one 2-D array: each column (or row, whichever axis is the
    # shorter) a channel; names from a names attribute, else data_0, data_1, ...
    rng = np.random.default_rng(6)
    x = rng.normal(size=(10240, 3))
    path = tmp_path / "matrix.h5"
    with h5py.File(path, "w") as f:
        if layout.startswith("samples x channels"):
            d = f.create_dataset("data", data=x)
            d.attrs["channels"] = ["sun_T3", "ring_T1", "tacho"]
            d.attrs["units"] = ["m/m", "m/m", "V"]
            d.attrs["fs"] = 5120.0
            names, units, t0, want = ["sun_T3", "ring_T1", "tacho"], ["m/m", "m/m", "V"], 0.0, x
        elif layout.startswith("channels x samples"):
            f.create_dataset("rig/data", data=x.T.astype(np.float32), chunks=(3, 1024))
            f["rig"].attrs["sample_rate"] = 5120
            names, units, t0, want = ["data_0", "data_1", "data_2"], ["", "", ""], 0.0, x.astype(np.float32)
        else:
            d = f.create_dataset("log", data=np.c_[5.0 + np.arange(10240) / 5120.0, x])
            d.attrs["names"] = "Time, sun, ring, tacho"
            names, units, t0, want = ["sun", "ring", "tacho"], ["", "", ""], 5.0, x
    rec = pio.read(path)
    assert rec.fs == 5120.0 and rec.t0 == pytest.approx(t0) and rec.names == names
    assert [c.units for c in rec.channels] == units and rec.data.dtype == want.dtype
    np.testing.assert_array_equal(rec.data, want)
    part = hdf5.read(path, [names[1]], 100, 300)
    np.testing.assert_array_equal(part.data[:, 0], want[100:300, 1])
    np.testing.assert_array_equal(hdf5.read(path, verify=False).data, want)
    blocks = list(pio.iter_blocks(path, 0.5, 0.01))
    np.testing.assert_array_equal(np.concatenate([b.data[:2560] for b in blocks]), want)


def test_hdf5_wide_matrices_are_channels_and_square_ones_ambiguous(tmp_path):
    # a 2-D dataset of any size is channels (the longer axis the samples); a smaller square
    # one beside it is skipped as shorter; a square one of the longest length is refused as
    # ambiguous, naming its shape and the attribute that resolves it
    with h5py.File(tmp_path / "img.h5", "w") as f:
        f["image"] = np.arange(200 * 300, dtype=float).reshape(200, 300)
        f["square"] = np.zeros((3, 3))
    with pytest.warns(FormatWarning, match="skipped dataset.*square"):
        rec = pio.read(tmp_path / "img.h5", fs=10.0)
    assert rec.n_channels == 200 and rec.n_samples == 300 and rec.names[:2] == ["image_0", "image_1"]
    np.testing.assert_array_equal(rec.data[:, 7], np.arange(300.0) + 7 * 300)
    with h5py.File(tmp_path / "sq.h5", "w") as f:
        f["square"] = np.zeros((300, 300))
    with pytest.raises(RecordingFileError, match=r"dataset /square of shape \(300, 300\).*ambiguous.*time_axis"):
        pio.read(tmp_path / "sq.h5", fs=10.0)
    with h5py.File(tmp_path / "sq.h5", "r+") as f:
        f["square"].attrs["time_axis"] = 1
    assert pio.read(tmp_path / "sq.h5", fs=10.0).n_channels == 300