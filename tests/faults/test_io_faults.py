"""Faults a reader must refuse although every byte it reads is intact: HDF5 chunks never
written, sizes declared far beyond the file, CSV headers of millions of columns, absurd
sample rates, control characters in channel names, a TDMS file cut at a segment boundary."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from fault_corpus import hdf5_without_chunks

import meshphase.io as pio
from meshphase.errors import FormatWarning
from meshphase.io import base as iobase
from meshphase.io.base import CorruptFileError, RecordingTooLargeError
from meshphase.recording import ChannelSpec, Recording

FS = 5120.0


def _rec(n=4096, fs=FS):
    data = np.random.default_rng(0).standard_normal((n, 2)) * 1e-5
    return Recording(data, fs, [ChannelSpec("sun", kind="sun"), ChannelSpec("ring", kind="ring")])


@pytest.fixture
def h5(tmp_path):
    return pio.write(_rec(), tmp_path / "rec.h5")


# --------------------------------------------------------------------------- HDF5 chunks never written
@pytest.mark.parametrize("skip, span", [({1}, (1024, 2048)), ({0}, (0, 1024)), ({1, 2}, (1024, 3072)),
                                        ({3}, (3072, 4096))])
def test_unwritten_chunks_are_an_error_naming_channel_and_time(h5, tmp_path, skip, span):
    bad = hdf5_without_chunks(h5, tmp_path / "hole.h5", skip, chunk=1024)
    a, b = span
    # the first channel in the file's order is named, with the first run of missing chunks
    want = rf"channel 'sun' .*samples \[{a}, {b}\) \({a / FS:.6g} s to {b / FS:.6g} s\): never written: " \
           rf"{len(skip)} of its 4 chunks"
    for call in (pio.read_info, pio.read):
        with pytest.raises(CorruptFileError, match=want):
            call(bad)


def test_every_chunk_written_reads_back(h5, tmp_path):
    """The copy with nothing left out is the original (the check has no false alarm)."""
    good = hdf5_without_chunks(h5, tmp_path / "full.h5", set(), chunk=1024)
    assert np.array_equal(pio.read(good).data, pio.read(h5).data)


def test_huge_declared_length_without_data_fails_fast(h5, tmp_path):
    """1e12 samples declared, none stored: refused from the chunk index, nothing allocated."""
    bad = hdf5_without_chunks(h5, tmp_path / "huge.h5", {0}, n_samples=10 ** 12)
    import meshphase

    for call in (pio.read_info, meshphase.read):           # the API's read: no numpy allocation error
        with pytest.raises(CorruptFileError, match=r"samples \[0, 1000000000000\) .*never written"):
            call(bad)


def test_foreign_file_with_unwritten_chunk(tmp_path):
    p = tmp_path / "foreign.h5"
    with h5py.File(p, "w") as f:
        d = f.create_dataset("strain", shape=(4000,), dtype="f8", chunks=(1000,))
        d.attrs["fs"] = FS
        d[:2000] = 1.0
        d[3000:] = 1.0
    with pytest.raises(CorruptFileError, match=r"channel 'strain' .*samples \[2000, 3000\)"):
        pio.read_info(p)


def test_contiguous_dataset_never_written(tmp_path):
    p = tmp_path / "contig.h5"
    with h5py.File(p, "w") as f:
        f.create_dataset("strain", shape=(4000,), dtype="f8").attrs["fs"] = FS   # late allocation: no storage
    with pytest.raises(CorruptFileError, match=r"channel 'strain' .*0 of the 32000 bytes"):
        pio.read_info(p)


def test_empty_channels_pass_the_check(tmp_path):
    p = pio.write(_rec(0), tmp_path / "empty.h5")
    assert pio.read(p).n_samples == 0


# --------------------------------------------------------------------------- memory budget
def test_check_allocation_refuses_more_than_memory(monkeypatch, h5):
    monkeypatch.setattr(iobase, "physical_memory", lambda: 10_000)
    with pytest.raises(RecordingTooLargeError, match=r"rec.h5: 4096 samples x 2 channel\(s\) \(6.55e-05 GB "
                                                     r"in memory\) do not fit in memory, more than "
                                                     r"this machine's 1e-05 GB"):
        pio.read(h5)
    assert pio.read(h5, start=0.0, stop=100 / FS).n_samples == 100     # a window that fits is read


def test_check_allocation_empty_and_bad_input():
    iobase.check_allocation("x", 0, 0, 8)                       # nothing to allocate
    with pytest.raises((TypeError, ValueError)):
        iobase.check_allocation("x", "many", 2, 8)
    ram = iobase.physical_memory()
    assert ram is None or ram > 0


# --------------------------------------------------------------------------- CSV headers of many columns
def _wide_csv(path, k, rows=3):
    with open(path, "w") as f:
        f.write("time [s]," + ",".join(f"c{i}" for i in range(k)) + "\n")
        for r in range(rows):
            f.write(f"{r / FS}," + ",".join(["0.1"] * k) + "\n")
    return path


def test_csv_more_columns_than_the_cap_are_refused(tmp_path):
    from meshphase.io.csv import MAX_CHANNELS

    p = _wide_csv(tmp_path / "wide.csv", MAX_CHANNELS + 1, rows=1)
    with pytest.raises(pio.RecordingFileError, match=rf"wide.csv: line 1: header of {MAX_CHANNELS + 1} channel "
                                                     rf"columns, more than the {MAX_CHANNELS}"):
        pio.read_info(p)


def test_csv_header_line_longer_than_the_limit_is_refused(tmp_path, monkeypatch):
    from meshphase.io import csv as pcsv

    monkeypatch.setattr(pcsv, "MAX_HEADER_LINE", 1000)        # the same code path as 16 MiB, faster
    p = _wide_csv(tmp_path / "long.csv", 300, rows=1)
    with pytest.raises(pio.RecordingFileError, match=r"long.csv: line 1 \(byte 0\) is longer than 1000 bytes"):
        pio.read_info(p)


def test_csv_missing_units_warning_is_one_short_line(tmp_path):
    p = _wide_csv(tmp_path / "units.csv", 200)
    with pytest.warns(FormatWarning) as rec:
        info = pio.read_info(p)
    assert len(info.channels) == 200
    msgs = [str(w.message) for w in rec if "carry no" in str(w.message)]
    assert len(msgs) == 1 and "['c0', 'c1', 'c2', 'c3', 'c4'] and 195 more" in msgs[0]
    assert len(msgs[0]) < 200 + len(str(p))


# --------------------------------------------------------------------------- sample rates outside a physical range
@pytest.fixture
def fs_1e300(tmp_path):
    p = pio.write(_rec(), tmp_path / "fs.h5")
    with h5py.File(p, "r+") as f:                 # the header edited, its checksums kept valid
        f.attrs["fs"] = 1e300
    return p


def test_absurd_fs_is_refused_naming_file_and_value(fs_1e300, monkeypatch):
    monkeypatch.delenv(iobase.ANY_FS_ENV, raising=False)
    with pytest.raises(pio.RecordingFileError, match=r"fs.h5: sample rate fs = 1e\+300 Hz is outside the physical "
                                                     r"range \[0.001, 1e\+08\] Hz.*--any-fs"):
        pio.read_info(fs_1e300)


def test_absurd_fs_passes_when_forced(fs_1e300, monkeypatch):
    monkeypatch.setenv(iobase.ANY_FS_ENV, "1")
    assert pio.read_info(fs_1e300).fs == 1e300


def test_cli_any_fs_option(fs_1e300, monkeypatch, capsys):
    from meshphase.cli import main

    monkeypatch.delenv(iobase.ANY_FS_ENV, raising=False)
    assert main(["-q", "info", "--no-quality", str(fs_1e300)]) == 1
    assert "outside the physical range" in capsys.readouterr().err
    assert main(["-q", "--any-fs", "info", "--no-quality", str(fs_1e300)]) == 0
    assert "1e+300 Hz" in capsys.readouterr().out
    assert iobase.ANY_FS_ENV not in __import__("os").environ      # the option does not outlive the command


@pytest.mark.parametrize("fs", [1e-3, 5120.0, 1e8])
def test_check_fs_range_accepts_the_range_ends(fs, monkeypatch):
    monkeypatch.delenv(iobase.ANY_FS_ENV, raising=False)
    iobase.check_fs_range(fs, "x.h5")


@pytest.mark.parametrize("fs", [9e-4, 1.01e8, float("inf"), float("nan"), "", None])
def test_check_fs_range_refuses(fs, monkeypatch):
    monkeypatch.delenv(iobase.ANY_FS_ENV, raising=False)
    with pytest.raises(pio.RecordingFileError, match="x.h5: sample rate fs"):
        iobase.check_fs_range(fs, "x.h5")


# --------------------------------------------------------------------------- control characters in channel names
@pytest.mark.parametrize("name", ["sun\nmeshphase process: error: fake", "a\rb", "tab\there", "esc\x1b[31m",
                                  "nel\x85", "ls\u2028x", "del\x7f"])
def test_channel_names_with_control_characters_are_refused(name):
    with pytest.raises(ValueError, match=r"holds the control character U\+[0-9A-F]{4}"):
        ChannelSpec(name)


def test_units_with_control_characters_are_refused():
    with pytest.raises(ValueError, match=r"channel 'sun': units 'm/m\\n' hold the control character U\+000A"):
        ChannelSpec("sun", units="m/m\n")


def test_control_character_empty_and_bad_input():
    from meshphase.recording import control_character

    assert control_character("") is None
    assert control_character("µε gauge (T3) – sun") is None     # printable Unicode is fine
    assert control_character("a\x00b") == "\x00"
    with pytest.raises(TypeError):
        control_character(None)


def test_foreign_file_with_a_newline_in_a_name_is_one_escaped_error(tmp_path, capsys):
    """The name cannot forge an output line: the command's one error line shows it escaped."""
    from meshphase.cli import main

    p = tmp_path / "forged.h5"
    with h5py.File(p, "w") as f:
        f.create_dataset("sun\nmeshphase process: error: fake", data=np.zeros(100)).attrs["fs"] = FS
    assert main(["-q", "info", "--no-quality", str(p)]) == 1
    out, err = capsys.readouterr()
    assert err.count("\n") == 1 and err.startswith("meshphase info: error: ") and "forged.h5" in err
    assert "sun\\nmeshphase process: error: fake" in err and "fake" not in out


@pytest.mark.parametrize("suffix", [".mcap", ".tdms"])
def test_check_allocation_guards_every_full_read(monkeypatch, tmp_path, suffix):
    """MCAP and TDMS full reads are refused before allocating, as HDF5's are."""
    if suffix == ".tdms":
        from meshphase.synthetic.tdms_export import write_tdms

        p = write_tdms(_rec(), tmp_path / f"rec{suffix}")
    else:
        p = pio.write(_rec(), tmp_path / f"rec{suffix}")
    monkeypatch.setattr(iobase, "physical_memory", lambda: 10_000)
    with pytest.raises(MemoryError, match=rf"rec{suffix}: 4096 samples x 2 channel\(s\)"):
        pio.read(p)


@pytest.mark.parametrize("fs", [float("nan"), float("inf"), 0.0, -5120.0])
def test_any_fs_still_needs_a_finite_positive_rate(fs, monkeypatch):
    monkeypatch.setenv(iobase.ANY_FS_ENV, "1")
    with pytest.raises(pio.RecordingFileError, match="not a finite positive number"):
        iobase.check_fs_range(fs, "x.h5")
