"""CSV reader/writer: preamble + header layout, bit-exact round trip, plain spreadsheet CSVs,
time-column checks, bad input."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import meshphase.io as pio
from meshphase.errors import DataQualityWarning, FormatWarning
from meshphase.io import csv as mcsv
from meshphase.io.base import CorruptFileError, RecordingFileError, nice_fs
from meshphase.recording import ChannelSpec, Recording


def _bits_equal(a, b):
    a = np.ascontiguousarray(a)
    b = np.ascontiguousarray(b)
    view = np.uint64 if a.dtype == np.float64 else np.uint32
    nan = np.isnan(a)
    return (a.dtype == b.dtype and a.shape == b.shape and np.array_equal(nan, np.isnan(b))
            and np.array_equal(a.view(view)[~nan], b.view(view)[~nan]))


def _write(rec, path, **kw):
    mcsv.write(rec, path, **kw)
    return path


def _plain(path, text):
    path.write_text(text, encoding="utf-8", newline="")
    return path


# ---------------------------------------------------------------------------- sniff
def test_sniff_text_with_separators():
    assert mcsv.sniff(b"time [s],a [m/m]\n0,1\n")
    assert mcsv.sniff(b"# comment\n\ntime,a\n0,1\n")
    assert mcsv.sniff(b'# meshphase {"format": "meshphase-csv"}\ntime [s]\n0\n')   # zero channels
    assert mcsv.sniff("\ufefftime [s],\u00b5 [m/m]\n".encode("utf-8"))
    assert mcsv.sniff("time [s],\u00b5 [m/m]\n".encode("latin-1"))
    assert not mcsv.sniff(b"")
    assert mcsv.sniff(b"time;a;b\n0;1;2\n")                   # decimal-comma locales
    assert mcsv.sniff(b"time\ta\tb\n0\t1\t2\n")              # LabVIEW spreadsheet files
    assert not mcsv.sniff(b"time a b\n0 1 2\n")               # spaces only: not a CSV
    assert not mcsv.sniff(b"# only a comment\n")
    assert not mcsv.sniff(b"\x89HDF\r\n\x1a\n,,,,")
    assert not mcsv.sniff(b"TDSm\x0e\x00\x00\x00,,,")
    assert not mcsv.sniff(b"a,b\x00c\n")
    assert not mcsv.sniff(bytes(range(256)))


# ---------------------------------------------------------------------------- round trip
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_round_trip_lossless(tmp_path, make_recording, dtype):
    rec = make_recording(n=1500, n_channels=5, dtype=dtype, t0=-3.5, nan_runs=True)
    extremes = np.array([np.finfo(dtype).max, np.finfo(dtype).tiny, np.finfo(dtype).smallest_subnormal, -0.0,
                         -np.inf, np.finfo(dtype).eps, 1 / 3], dtype=dtype)
    rec.data[50:57, 3] = extremes
    path = _write(rec, tmp_path / "r.csv")
    with pytest.warns(DataQualityWarning):
        back = mcsv.read(path)
    assert back == rec
    assert _bits_equal(back.data, rec.data)
    assert back.data.dtype == dtype and back.data.flags.writeable and back.data.flags.f_contiguous
    assert (back.fs, back.t0, back.start_datetime, back.meta, back.history) == \
        (rec.fs, rec.t0, rec.start_datetime, rec.meta, rec.history)


@settings(max_examples=40, deadline=None)
@given(n=st.integers(0, 120), n_ch=st.integers(0, 3), dtype=st.sampled_from([np.float32, np.float64]),
       t0=st.floats(-1e5, 1e5, allow_nan=False), fs=st.floats(1e-2, 1e6, allow_nan=False),
       chunk=st.integers(1, 50), seed=st.integers(0, 2**32 - 1))
def test_round_trip_property(tmp_path_factory, n, n_ch, dtype, t0, fs, chunk, seed):
    rng = np.random.default_rng(seed)
    if dtype == np.float64:   # random bit patterns: every exponent, subnormals, signed zeros
        data = rng.integers(0, 2**64, size=(n, n_ch), dtype=np.uint64).view(np.float64)
    else:
        data = rng.integers(0, 2**32, size=(n, n_ch), dtype=np.uint64).astype(np.uint32).view(np.float32)
    data = np.where(np.isfinite(data), data, dtype(0.0))
    rec = Recording(data, fs, [f"c{j}" for j in range(n_ch)], t0=t0)
    path = tmp_path_factory.mktemp("csv") / "p.csv"
    _write(rec, path, chunk_rows=chunk)
    back = mcsv.read(path)
    assert back == rec and _bits_equal(back.data, rec.data)


def test_layout_preamble_header_and_time_column(tmp_path):
    specs = [ChannelSpec("sun_1", "sun", "m/m", tooth=4), ChannelSpec("ring, outer", "ring", "µm/m")]
    rec = Recording(np.array([[1.5, -2.0], [np.nan, 3.25], [0.1, np.inf]]), 5120.0, specs, t0=0.5)
    path = _write(rec, tmp_path / "l.csv")
    with pytest.warns(DataQualityWarning):
        mcsv.read(path)
    lines = path.read_text(encoding="utf-8").split("\n")
    assert lines[0].startswith("# meshphase {")
    pre = json.loads(lines[0][len("# meshphase "):])
    assert pre["format"] == "meshphase-csv" and pre["format_version"] == 1
    assert pre["fs"] == 5120.0 and pre["t0"] == 0.5 and pre["n_samples"] == 3 and pre["dtype"] == "float64"
    assert pre["channels"][0] == specs[0].to_dict()
    assert lines[1] == 'time [s],sun_1 [m/m],"ring, outer [µm/m]"'
    assert lines[2] == "0.5,1.5,-2.0"
    assert lines[3] == "0.5001953125,NaN,3.25"
    assert lines[4] == "0.500390625,0.1,inf"
    assert lines[5] == ""


def test_every_channel_spec_field_round_trips(tmp_path, recording):
    back = mcsv.read(_write(recording, tmp_path / "s.csv"))
    assert [c.to_dict() for c in back.channels] == [c.to_dict() for c in recording.channels]


def test_chunked_writing_gives_the_same_file(tmp_path, recording):
    a = _write(recording, tmp_path / "a.csv")
    b = _write(recording, tmp_path / "b.csv", chunk_rows=7)
    assert a.read_bytes() == b.read_bytes()


def test_empty_and_zero_channel_recordings_round_trip(tmp_path):
    for i, rec in enumerate([Recording(np.empty((0, 2), np.float32), 100.0, ["a", "b"]),
                             Recording(np.empty((6, 0)), 100.0, [], t0=2.0)]):
        path = _write(rec, tmp_path / f"e{i}.csv")
        assert mcsv.read(path) == rec
        assert pio.read(path) == rec
        assert mcsv.read_info(path).n_samples == rec.n_samples


# ---------------------------------------------------------------------------- partial reads
def test_read_info_is_header_only_for_our_files(tmp_path, recording, monkeypatch):
    path = _write(recording, tmp_path / "i.csv")
    import pandas as pd

    monkeypatch.setattr(pd, "read_csv", lambda *a, **k: pytest.fail("rows parsed"))
    monkeypatch.setattr(mcsv, "_scan", lambda *a, **k: pytest.fail("rows counted"))
    info = mcsv.read_info(path)
    assert (info.fs, info.n_samples, info.t0, info.format) == (recording.fs, recording.n_samples, 0.0, "csv")
    assert info.channels == list(recording.channels) and info.extra["preamble"] is True


def test_window_and_reordered_subset_match_slices(tmp_path, recording):
    path = _write(recording, tmp_path / "w.csv")
    back = mcsv.read(path, ["tacho_3", "sun_0"], 250, 1111)
    assert back == recording.select(["tacho_3", "sun_0"]).slice_samples(250, 1111)
    assert back.data.flags.f_contiguous
    assert pio.read(path, "ring_1", start=0.1, stop=0.2) == recording.select("ring_1").slice_time(0.1, 0.2)


@pytest.mark.parametrize("block, overlap, channels", [(100, 0, None), (333, 40, ["ring_1", "sun_0"]),
                                                      (50, 120, None), (5000, 10, None)])
def test_iter_blocks_match_in_memory_blocks(tmp_path, recording, block, overlap, channels):
    path = _write(recording, tmp_path / "b.csv")
    got = list(mcsv.iter_blocks(path, block, overlap, channels))
    want = list(recording.select(channels).blocks(block / recording.fs, overlap / recording.fs))
    assert len(got) == len(want) and all(g == w for g, w in zip(got, want))


def test_iter_blocks_bad_input(tmp_path, recording):
    path = _write(recording, tmp_path / "bb.csv")
    with pytest.raises(ValueError):
        list(mcsv.iter_blocks(path, 0, 0))
    with pytest.raises(ValueError):
        list(mcsv.iter_blocks(path, 10, -2))


# ---------------------------------------------------------------------------- plain CSVs
def test_plain_spreadsheet_csv_reads_with_defaults(tmp_path):
    fs = 5120.0
    t = np.arange(2000) / fs
    rows = "\r\n".join(f"{ti:.6f},{np.sin(ti):.5f},{i % 7}" for i, ti in enumerate(t))
    path = _plain(tmp_path / "sheet.csv", "\ufefftime [s],sun_1 [m/m],tacho [V]\r\n" + rows + "\r\n\r\n")
    rec = mcsv.read(path)
    assert rec.fs == 5120.0                   # inferred from rounded times, snapped to the short decimal
    assert rec.n_samples == 2000 and rec.t0 == 0.0
    assert [c.kind for c in rec.channels] == ["other", "other"]
    assert [c.units for c in rec.channels] == ["m/m", "V"]
    assert rec.meta == {} and rec.history == [] and rec.start_datetime is None
    np.testing.assert_array_equal(rec.channel("tacho"), np.arange(2000) % 7)
    info = mcsv.read_info(path)
    assert info.extra["preamble"] is False and info.n_samples == 2000


def test_plain_csv_time_in_milliseconds_and_iter_blocks(tmp_path):
    t_ms = np.arange(500) * 0.5 + 100.0
    path = _plain(tmp_path / "ms.csv", "time [ms],a [V]\n" + "".join(f"{t},{i}\n" for i, t in enumerate(t_ms)))
    rec = mcsv.read(path)
    assert rec.fs == 2000.0 and rec.t0 == pytest.approx(0.1, abs=1e-15)
    blocks = list(mcsv.iter_blocks(path, 64, 8))
    assert all(b == w for b, w in zip(blocks, rec.blocks(64 / 2000, 8 / 2000)))
    assert len(blocks) == 8


def test_plain_csv_without_units_warns(tmp_path):
    path = _plain(tmp_path / "nu.csv", "time,a,b [V]\n0,1,2\n0.5,3,4\n1.0,5,6\n")
    with pytest.warns(FormatWarning, match=r"column\(s\) \['a'\] carry no '\[units\]'"):
        rec = mcsv.read(path)
    assert rec.spec("a").units == "" and rec.spec("b").units == "V" and rec.fs == 2.0


def test_nice_fs_snaps_only_within_tolerance():
    assert nice_fs(5119.9999999999, 10**6, (10**6 - 1) / 5120.0) == 5120.0
    odd = 5120.0 * (1 + 1e-6)   # a real rate offset: 0.1 sample off over 1e5 rows -> kept
    assert nice_fs(odd, 10**5, (10**5 - 1) / odd) != 5120.0


# ---------------------------------------------------------------------------- time checks
def test_non_uniform_time_names_the_line(tmp_path):
    t = np.arange(100) / 100.0
    t[57] += 0.5 / 100.0      # half a sample off the grid
    path = _plain(tmp_path / "nu.csv", "time [s],a [V]\n" + "".join(f"{float(x)!r},1\n" for x in t))
    with pytest.raises(RecordingFileError, match=r"nu\.csv: non-uniform time at line 59 \(data row 57\)"):
        mcsv.read(path)


def test_dropped_sample_is_non_uniform(tmp_path):
    t = np.delete(np.arange(101) / 100.0, 40)
    path = _plain(tmp_path / "drop.csv", "time [s],a [V]\n" + "".join(f"{float(x)!r},1\n" for x in t))
    with pytest.raises(RecordingFileError, match=r"non-uniform time at line 42"):
        mcsv.read(path)


def test_non_monotonic_time_names_the_line(tmp_path):
    t = list(np.arange(50) / 10.0)
    t[30], t[31] = t[31], t[30]
    path = _plain(tmp_path / "nm.csv", "time [s],a [V]\n" + "".join(f"{float(x)!r},1\n" for x in t))
    with pytest.raises(RecordingFileError, match=r"nm\.csv: non-monotonic time at line 33 \(data row 31\)"):
        mcsv.read(path)


def test_blank_line_inside_the_data_is_reported(tmp_path):
    path = _plain(tmp_path / "bl.csv", "time [s],a [V]\n0,1\n0.1,2\n\n0.2,3\n0.3,4\n")
    with pytest.raises(CorruptFileError, match=r"bl\.csv: line 4 \(byte 25\): blank line inside the data rows"):
        mcsv.read(path)


def test_own_file_time_column_is_checked_against_preamble(tmp_path, recording):
    path = _write(recording, tmp_path / "own.csv")
    lines = path.read_text(encoding="utf-8").split("\n")
    parts = lines[2 + 700].split(",")
    parts[0] = repr(float(parts[0]) + 0.3 / recording.fs)
    lines[2 + 700] = ",".join(parts)
    path.write_text("\n".join(lines), encoding="utf-8")
    with pytest.raises(RecordingFileError, match=r"non-uniform time at line 703 \(data row 700\)"):
        mcsv.read(path)
    with pytest.raises(RecordingFileError, match=r"non-uniform time at line 703"):
        list(mcsv.iter_blocks(path, 256, 0))
    assert mcsv.read(path, None, 0, 700) == recording.slice_samples(0, 700)   # rows before it are fine


# ---------------------------------------------------------------------------- bad input
@pytest.mark.parametrize("cut", ["line", "mid-row"])
def test_truncated_own_file(tmp_path, recording, cut):
    path = _write(recording, tmp_path / "t.csv")
    text = path.read_text(encoding="utf-8")
    lines = text.split("\n")
    if cut == "line":
        path.write_text("\n".join(lines[:1000]) + "\n", encoding="utf-8")
    else:
        path.write_text(text[: len(text) // 2], encoding="utf-8")
    with pytest.raises(CorruptFileError, match=r"t\.csv: byte \d+ \(end of file\): truncated"):
        pio.read(path)


def test_own_file_with_extra_rows(tmp_path, recording):
    path = _write(recording, tmp_path / "x.csv")
    with open(path, "a", encoding="utf-8") as fh:
        fh.write(f"{recording.t_end!r},1,2,3,4\n")
    with pytest.raises(RecordingFileError, match="more data rows than the preamble's n_samples = 2000"):
        mcsv.read(path)
    with pytest.raises(RecordingFileError, match="more data rows"):
        list(mcsv.iter_blocks(path, 700, 0))


def _edit_preamble(path, **changes):
    lines = path.read_text(encoding="utf-8").split("\n")
    pre = json.loads(lines[0][len("# meshphase "):])
    pre.update(changes)
    lines[0] = "# meshphase " + json.dumps(pre)
    path.write_text("\n".join(lines), encoding="utf-8")


@pytest.mark.parametrize("fs", [None, 0, -1.0, "fast"])
def test_missing_or_non_positive_sample_rate(tmp_path, recording, fs):
    path = _write(recording, tmp_path / "fs.csv")
    _edit_preamble(path, fs=fs)
    with pytest.raises(RecordingFileError, match=r"fs\.csv: missing or non-positive sample rate"):
        pio.read(path)


def test_plain_csv_with_one_row_has_no_sample_rate(tmp_path):
    path = _plain(tmp_path / "one.csv", "time [s],a [V]\n0,1\n")
    with pytest.raises(RecordingFileError, match=r"missing or non-positive sample rate: cannot infer it from 1"):
        mcsv.read_info(path)
    path = _plain(tmp_path / "zero.csv", "time [s],a [V]\n")
    with pytest.raises(RecordingFileError, match=r"from 0 data row"):
        mcsv.read(path)


def test_duplicate_channel_names(tmp_path, recording):
    path = _plain(tmp_path / "dup.csv", "time [s],a [V],b [V],a [V]\n0,1,2,3\n1,1,2,3\n")
    with pytest.raises(RecordingFileError, match=r"dup\.csv: line 1: duplicate channel name\(s\) \['a'\]"):
        mcsv.read(path)
    own = _write(recording, tmp_path / "dup2.csv")
    chans = [c.to_dict() for c in recording.channels]
    chans[2]["name"] = "sun_0"
    _edit_preamble(own, channels=chans)
    with pytest.raises(RecordingFileError, match=r"duplicate channel name\(s\) \['sun_0'\] in the preamble"):
        mcsv.read(own)


@pytest.mark.parametrize("change, match", [
    ({"format_version": 7}, "preamble version 7"),
    ({"format": "other"}, "preamble format must be 'meshphase-csv'"),
    ({"n_samples": -1}, "n_samples must be a non-negative integer"),
    ({"dtype": "int16"}, "dtype must be"),
    ({"t0": "zero"}, "t0 must be a finite number"),
    ({"meta": []}, "meta must be a JSON object"),
    ({"history": {}}, "history must be a JSON array"),
    ({"start_datetime": "soon"}, "not ISO 8601"),
])
def test_bad_preamble_values(tmp_path, recording, change, match):
    path = _write(recording, tmp_path / "p.csv")
    _edit_preamble(path, **change)
    with pytest.raises(RecordingFileError, match=match):
        mcsv.read(path)


def test_bad_channel_spec_in_preamble_names_the_key(tmp_path, recording):
    path = _write(recording, tmp_path / "k.csv")
    chans = [c.to_dict() for c in recording.channels]
    chans[1]["kind"] = "gear"
    _edit_preamble(path, channels=chans)
    with pytest.raises(RecordingFileError, match=r"preamble channels\[1\]: does not match channel_spec.schema.json: "
                                                 r"at /kind"):
        mcsv.read(path)


def test_unknown_preamble_key_warns(tmp_path, recording):
    path = _write(recording, tmp_path / "u.csv")
    _edit_preamble(path, future_key=1)
    with pytest.warns(FormatWarning, match=r"unknown preamble key\(s\) \['future_key'\]"):
        assert mcsv.read(path) == recording


def test_header_that_disagrees_with_preamble(tmp_path, recording):
    path = _write(recording, tmp_path / "h.csv")
    text = path.read_text(encoding="utf-8").replace("ring_1 [m/m]", "ring_1 [V]", 1)
    path.write_text(text, encoding="utf-8")
    with pytest.raises(RecordingFileError, match="header columns .* do not match the preamble"):
        mcsv.read(path)


@pytest.mark.parametrize("text, match", [
    ("a [V],b [V]\n0,1\n", "first column must be the time"),
    ("time [h],b [V]\n0,1\n", "first column must be the time"),
    ("time [s]\n0\n", "no channel columns"),
    ("time [s],,b [V]\n0,1,2\n1,1,2\n", r"column\(s\) \[2\] have no name"),
])
def test_bad_plain_headers(tmp_path, text, match):
    path = _plain(tmp_path / "h.csv", text)
    with pytest.raises(RecordingFileError, match=match):
        mcsv.read(path)


def test_non_numeric_value_names_the_line(tmp_path):
    path = _plain(tmp_path / "nn.csv", "time [s],a [V]\n0,1\n1,2\n2,oops\n3,4\n")
    with pytest.raises(RecordingFileError, match=r"non-numeric value .*first at line 4, column 2: 'oops'"):
        mcsv.read(path)


def test_row_with_too_many_fields(tmp_path):
    path = _plain(tmp_path / "rag.csv", "time [s],a [V]\n0,1\n1,2,3\n2,4\n")
    with pytest.raises(CorruptFileError, match=r"line 3 \(byte 19\): 3 field\(s\), the header has 2: malformed row"):
        mcsv.read(path)


def test_nan_runs_warn_and_are_kept(tmp_path):
    path = _plain(tmp_path / "nan.csv", "time [s],a [V],b [V]\n0,1,NaN\n1,,NaN\n2,3,4\n3,inf,5\n")
    with pytest.warns(DataQualityWarning) as ws:
        rec = mcsv.read(path)
    msgs = sorted(str(w.message) for w in ws)
    assert "channel 'a' has 2 run(s) of NaN/inf samples (2 samples, longest 1, first at sample 1)" in msgs[0]
    assert "channel 'b' has 1 run(s) of NaN/inf samples (2 samples, longest 2, first at sample 0)" in msgs[1]
    assert rec.n_samples == 4 and np.isnan(rec.data[:2, 1]).all() and np.isinf(rec.data[3, 0])


def test_write_bad_input(tmp_path, recording):
    with pytest.raises(TypeError, match="must be a Recording"):
        mcsv.write("x", tmp_path / "a.csv")
    with pytest.raises(ValueError, match="chunk_rows"):
        mcsv.write(recording, tmp_path / "b.csv", chunk_rows=0)
    with pytest.raises(ValueError, match="control character"):      # no such channel can reach the writer
        ChannelSpec("two", units="m/\nm")
    far = Recording(np.zeros((2, 1)), 1e6, ["a"], t0=1e10)   # times 1e-6 s apart, float64 spacing 2e-6 s
    with pytest.raises(ValueError, match="t0 = 10000000000.0 s is too large for a CSV time column"):
        mcsv.write(far, tmp_path / "d.csv")


def test_empty_file_and_missing_file(tmp_path):
    (tmp_path / "empty.csv").write_bytes(b"")
    with pytest.raises(RecordingFileError, match="file is empty"):
        mcsv.read_info(tmp_path / "empty.csv")
    with pytest.raises(FileNotFoundError):
        mcsv.read(tmp_path / "none.csv")


def test_clean_read_raises_no_warning(tmp_path, recording):
    path = _write(recording, tmp_path / "c.csv")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        mcsv.read(path)
        list(mcsv.iter_blocks(path, 512, 16))


# ---------------------------------------------------------------------------- other writers' dialects
def _dialect_text(sep, decimal, times_fmt="{:.6f}", n=3000, fs=5120.0, drop=None):
    """A plain CSV as other loggers write it: ``sep`` between fields, ``decimal`` as the
    decimal mark, times printed with ``times_fmt``; (text, data)."""
    t = np.arange(n) / fs
    data = np.c_[np.sin(2 * np.pi * 30 * t), np.cos(2 * np.pi * 7 * t)] * 1e-5
    rows = [sep.join([times_fmt.format(a), f"{b:.6e}", f"{c:.6e}"]) for a, b, c in zip(t, *data.T)]
    if decimal != ".":
        rows = [r.replace(".", decimal) for r in rows]
    if drop is not None:
        del rows[drop]
        data = np.delete(data, drop, axis=0)
    return sep.join(["time [s]", "sun [m/m]", "ring [m/m]"]) + "\n" + "\n".join(rows) + "\n", data


@pytest.mark.parametrize("sep, decimal", [(",", "."), (";", "."), (";", ","), ("\t", "."), ("\t", ",")])
def test_semicolon_tab_and_decimal_comma_files_read(tmp_path, sep, decimal):
    # LabVIEW's spreadsheet files are tab-separated, a spreadsheet in a decimal-comma locale
    # writes ';' and '1,5e-05'; every number printed with 6 significant digits (the text's
    # own rounding, 5e-12 here, is all that may differ), blocks equal to the whole read
    text, data = _dialect_text(sep, decimal)
    path = _plain(tmp_path / "d.csv", text)
    assert pio.detect_format(path) == "csv"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rec = pio.read(path)
    assert rec.fs == 5120.0 and rec.names == ["sun", "ring"] and rec.channels[0].units == "m/m"
    assert np.max(np.abs(rec.data - data)) <= 5e-12
    blocks = list(pio.iter_blocks(path, 1000 / 5120, 64 / 5120))
    np.testing.assert_array_equal(np.concatenate([b.data[:1000] for b in blocks]), rec.data)


def test_malformed_row_of_a_semicolon_file_names_the_line(tmp_path):
    text, _ = _dialect_text(";", ",")
    lines = text.split("\n")
    lines[101] = lines[101].rsplit(";", 1)[0]                 # a field lost
    path = _plain(tmp_path / "m.csv", "\n".join(lines))
    with pytest.raises(CorruptFileError, match=r"line 102 .*2 field\(s\), the header has 3"):
        pio.read(path)


def test_non_numeric_value_of_a_decimal_comma_file_names_the_line(tmp_path):
    text, _ = _dialect_text(";", ",")
    lines = text.split("\n")
    lines[51] = lines[51].replace("e-0", "x-0", 1)
    path = _plain(tmp_path / "nn.csv", "\n".join(lines))
    with pytest.raises(RecordingFileError, match=r"first at line 52, column 2"):
        pio.read(path)


def test_times_printed_to_fewer_digits_than_the_grid_needs(tmp_path):
    # '%.4f' at 5120 Hz: each time up to 0.26 sample off the grid t0 + i/fs (it was refused
    # as 'non-uniform time'); checked to half the printed step, so a dropped sample, 1
    # sample, is still caught where it happens
    text, data = _dialect_text(",", ".", "{:.4f}")
    rec = pio.read(_plain(tmp_path / "r4.csv", text))
    assert rec.fs == 5120.0 and np.max(np.abs(rec.data - data)) <= 5e-12
    text, _ = _dialect_text(",", ".", "{:.4f}", drop=1500)
    with pytest.raises(RecordingFileError, match=r"non-uniform time at line 1502"):
        pio.read(_plain(tmp_path / "r4drop.csv", text))


def test_times_coarser_than_a_sample_warn_and_read(tmp_path):
    # '%.3f' at 5120 Hz: times repeat, nothing in them can show a dropped sample; read as
    # the uniform grid, with a warning that says so
    text, data = _dialect_text(",", ".", "{:.3f}")
    with pytest.warns(FormatWarning, match=r"printed to 0.001 s, too coarse .* cannot be seen"):
        rec = pio.read(_plain(tmp_path / "r3.csv", text))
    assert rec.fs == 5120.0 and rec.n_samples == len(data)


def test_times_exact_in_few_digits_do_not_warn(tmp_path):
    # 100 Hz printed to 2 decimals, 1 Hz to none: the grid itself prints exactly
    for fs, fmt in ((100.0, "{:.2f}"), (1.0, "{:.0f}")):
        text, _ = _dialect_text(",", ".", fmt, n=300, fs=fs)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            rec = pio.read(_plain(tmp_path / f"x{fs:g}.csv", text))
        assert rec.fs == fs


def test_separator_is_the_one_the_header_holds_most_of():
    assert mcsv._separator("time [s],sun [m/m]") == ","
    assert mcsv._separator("time [s];sun, tooth 3 [m/m];ring [m/m]") == ";"
    assert mcsv._separator("time [s]\tsun; a [V]\tring [V]") == "\t"
    assert mcsv._separator("time") == ","
    assert mcsv._separator("") == ","


def _stamp_text(n=3000, fs=5120.0, fmt=lambda s: s.replace("T", " "), head="Timestamp", drop=None, bad=None):
    """A plain CSV whose time column holds ISO 8601 timestamps from 2026-11-28 10:00 (to the
    microsecond, as numpy prints them); (text, data)."""
    t = np.arange(n) / fs
    data = np.c_[np.sin(2 * np.pi * 30 * t), np.cos(2 * np.pi * 7 * t)] * 1e-5
    base = np.datetime64("2026-11-28T10:00:00", "ns")
    stamps = np.datetime_as_string(base + np.round(t * 1e9).astype("timedelta64[ns]"), unit="us")
    rows = [f"{fmt(s)},{b:.6e},{c:.6e}" for s, b, c in zip(stamps, *data.T)]
    if drop is not None:
        del rows[drop]
        data = np.delete(data, drop, axis=0)
    if bad is not None:
        rows[bad] = "2026-11-28 10:0x:00," + rows[bad].split(",", 1)[1]
    return f"{head},sun [m/m],ring [m/m]\n" + "\n".join(rows) + "\n", data


@pytest.mark.parametrize("fmt, head, start", [
    (lambda s: s.replace("T", " "), "Timestamp", "2026-11-28T10:00:00"),
    (lambda s: s + "Z", "time [UTC]", "2026-11-28T10:00:00+00:00"),
    (lambda s: s + "+01:00", "datetime", "2026-11-28T10:00:00+01:00"),
])
def test_iso_timestamp_time_column(tmp_path, fmt, head, start):
    # loggers that stamp each row with the wall clock: t0 = 0, the first stamp is the
    # recording's start_datetime, the stamps are checked against the grid like seconds
    text, data = _stamp_text(fmt=fmt, head=head)
    path = _plain(tmp_path / "s.csv", text)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rec = pio.read(path)
    assert rec.fs == 5120.0 and rec.t0 == 0.0 and rec.start_datetime == start
    assert np.max(np.abs(rec.data - data)) <= 5e-12
    blocks = list(pio.iter_blocks(path, 1000 / 5120, 64 / 5120))
    np.testing.assert_array_equal(np.concatenate([b.data[:1000] for b in blocks]), rec.data)


def test_iso_timestamps_name_a_dropped_sample_and_a_bad_stamp(tmp_path):
    text, _ = _stamp_text(drop=700)
    with pytest.raises(RecordingFileError, match=r"non-uniform time at line 702"):
        pio.read(_plain(tmp_path / "d.csv", text))
    text, _ = _stamp_text(bad=900)
    with pytest.raises(RecordingFileError, match=r"missing or non-finite time at line 902"):
        pio.read(_plain(tmp_path / "b.csv", text))


def test_iso_timestamps_truncated_to_milliseconds_warn_and_read(tmp_path):
    # many loggers cut the stamp to ms (not rounded): at 5120 Hz five rows share a stamp.
    # fs comes from the first and last stamp, here 1 ms in 20 s (0.6 s of them leave 5120
    # and 5130 Hz both possible, and the grid check then refuses the wrong one)
    text, data = _stamp_text(n=5120 * 20, fmt=lambda s: s[:-3].replace("T", " "))
    with pytest.warns(FormatWarning, match=r"printed to 0.001 s, too coarse"):
        rec = pio.read(_plain(tmp_path / "ms.csv", text))
    assert rec.fs == 5120.0 and rec.n_samples == len(data)


def test_iso_timestamps_under_another_header_are_refused_with_the_reason(tmp_path):
    text, _ = _stamp_text(head="Sensor")
    with pytest.raises(RecordingFileError, match=r"first column holds timestamps \(2026-11-28T10:00:00\); "
                                                 r"it must be headed 'time', 'timestamp'"):
        pio.read(_plain(tmp_path / "h.csv", text))


def test_a_units_line_under_the_header_gives_the_units(tmp_path):
    # DIAdem and catman exports put the units on a line of their own under the names
    t = np.arange(3000) / 5120.0
    x = np.sin(50.0 * t) * 1e-5
    text = "Time;SG_sun;SG_ring\ns;m/m;m/m\n" + "".join(
        f"{a:.6f};{b:.6e};{-b:.6e}\n".replace(".", ",") for a, b in zip(t, x))
    with warnings.catch_warnings():
        warnings.simplefilter("error")               # units given: no 'carry no [units]' warning
        rec = pio.read(_plain(tmp_path / "u.csv", text))
    assert rec.fs == 5120.0 and rec.names == ["SG_sun", "SG_ring"]
    assert [c.units for c in rec.channels] == ["m/m", "m/m"]
    assert np.max(np.abs(rec.data - np.c_[x, -x])) <= 5e-12
    # the time in ms by its units line; a [units] in the header stands; an empty one is empty
    text = "time,sun [V],ring\nms,,mV\n" + "".join(f"{a * 1e3:.4f},{b:.6e},{b:.6e}\n" for a, b in zip(t, x))
    rec = pio.read(_plain(tmp_path / "u2.csv", text))
    assert rec.fs == 5120.0 and [c.units for c in rec.channels] == ["V", "mV"]
    # a second line that holds a number is data, as before
    rec = pio.read(_plain(tmp_path / "d.csv", "time [s],a [V]\n0,1\n0.5,2\n1.0,3\n"))
    assert rec.n_samples == 3 and rec.fs == 2.0
