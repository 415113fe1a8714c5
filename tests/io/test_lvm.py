"""NI LabVIEW Measurement files (.lvm), laid out as NI's "Specification for the LabVIEW
Measurement File (.lvm)" (ni.com/tutorial/4139) describes and LabVIEW's "Write To
Measurement File" Express VI writes them: the ``LabVIEW Measurement`` line, the file header
(Writer_Version, Reader_Version, Separator, Decimal_Separator, Multi_Headings, X_Columns,
Time_Pref, Operator, Date, Time) closed by ``***End_of_Header***``, then per segment a
header (Channels, Samples, Date, Time, Y_Unit_Label, X_Dimension, X0, Delta_X, one value per
column, closed by ``***End_of_Header***``), the column headings (X_Value, the channel names,
Comment) and the rows."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import meshphase.io as pio
from meshphase.io import lvm
from meshphase.io.base import CorruptFileError, RecordingFileError

FS = 5120.0


def _signal(n, i0=0):
    t = (i0 + np.arange(n)) / FS
    return t, np.c_[120.0 * np.sin(2 * np.pi * 30 * t), -80.0 * np.cos(2 * np.pi * 7 * t)]


def _file_header(sep="\t", decimal=".", x_columns="One", multi="Yes", pref="Relative"):
    tags = [("LabVIEW Measurement", ""), ("Writer_Version", "2"), ("Reader_Version", "2"),
            ("Separator", "Tab" if sep == "\t" else "Comma"), ("Decimal_Separator", decimal),
            ("Multi_Headings", multi), ("X_Columns", x_columns), ("Time_Pref", pref), ("Operator", "rig"),
            ("Date", "2026/11/28"), ("Time", "10:00:00" + decimal + "0000000000000000000"),
            ("***End_of_Header***", "")]
    return "".join(f"{k}{sep}{v}\n" for k, v in tags) + f"{sep}\n"


def _segment(n, i0=0, sep="\t", decimal=".", x_columns="One", names=("sun", "ring"), units=("um/m", "um/m"),
             clock="10:00:00", dx="1.953125E-4", samples=None):
    """One segment: header, column headings, rows (values 6 decimals as LabVIEW prints)."""
    t, data = _signal(n, i0)
    nch = len(names)
    multi = x_columns == "Multi"

    def row(tag, vals):       # one value per column after the tag (X columns of Multi blank)
        cells = []
        for v in vals:
            cells += ([""] if multi and cells else []) + [v]
        return sep.join([tag] + cells) + sep + "\n"

    def num(v):
        return v.replace(".", decimal)

    start = f"{clock[:-2]}{i0 / FS:09.6f}".replace(".", decimal)
    head = (sep.join(["Channels", str(nch)] + [""] * (nch - 1)) + sep + "\n"
            + row("Samples", [str(samples if samples is not None else n)] * nch)
            + row("Date", ["2026/11/28"] * nch) + row("Time", [start] * nch)
            + row("Y_Unit_Label", list(units)) + row("X_Dimension", ["Time"] * nch)
            + row("X0", [num("0.0000000000000000E+0")] * nch) + row("Delta_X", [num(dx)] * nch)
            + "***End_of_Header***" + sep * (nch + 1) + "\n")
    cols = []
    for nm in names:
        cols += (["X_Value"] if multi or not cols else []) + [nm]
    head += sep.join(cols + ["Comment"]) + "\n"
    lines = []
    for ti, vals in zip(t, data):
        x = f"{ti:.6f}"
        cells = []
        for j, v in enumerate(vals):
            if multi or j == 0:
                cells.append(x if x_columns != "No" else "")
            cells.append(f"{v:.6f}")
        lines.append(num(sep.join(cells)) if decimal != "." else sep.join(cells))
    return head + "".join(ln + "\n" for ln in lines), data


def _write(path, text, crlf=False):
    path.write_bytes((text.replace("\n", "\r\n") if crlf else text).encode("utf-8"))
    return path


@pytest.mark.parametrize("x_columns", ["No", "One", "Multi"])
def test_one_segment_each_x_columns_mode(tmp_path, x_columns):
    """One call of Write To Measurement File: X_Columns No (the X_Value column left empty),
    One (one x column first), Multi (an x column before every channel)."""
    seg, data = _segment(3000, x_columns=x_columns)
    path = _write(tmp_path / "one.lvm", _file_header(x_columns=x_columns) + seg, crlf=True)
    assert pio.detect_format(path) == "lvm"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rec = pio.read(path)
    assert rec.fs == FS and rec.t0 == 0.0 and rec.n_samples == 3000
    assert rec.names == ["sun", "ring"] and [c.units for c in rec.channels] == ["um/m", "um/m"]
    assert rec.start_datetime == "2026-11-28T10:00:00"
    assert np.max(np.abs(rec.data - data)) <= 5e-7
    md = rec.meta["lvm"]
    assert md["file"]["X_Columns"] == x_columns and md["file"]["Operator"] == "rig"
    assert md["segments"][0]["Y_Unit_Label"][0] == "um/m"
    info = pio.read_info(path)
    assert info.extra == {"segments": 1, "x_columns": x_columns, "dtype": "float64", "encoding": "utf-8"}
    blocks = list(pio.iter_blocks(path, 1000 / FS, 64 / FS))
    np.testing.assert_array_equal(np.concatenate([b.data[:1000] for b in blocks]), rec.data)
    win = pio.read(path, ["ring"], start=0.1, stop=0.2)
    np.testing.assert_array_equal(win.data[:, 0], rec.data[512:1024, 1])


def test_several_segments_concatenate(tmp_path):
    """Three calls of the Express VI with Multi_Headings Yes: a header before each segment,
    each segment's Date/Time one sample after the last of the one before."""
    parts = [_segment(1000, i0=k * 1000) for k in range(3)]
    text = _file_header() + "\n".join(p[0] for p in parts)
    rec = pio.read(_write(tmp_path / "seg.lvm", text))
    assert rec.n_samples == 3000 and rec.fs == FS
    assert np.max(np.abs(rec.data - np.concatenate([p[1] for p in parts]))) <= 5e-7
    assert len(rec.meta["lvm"]["segments"]) == 3


@pytest.mark.parametrize("x_columns", ["No", "One"])
def test_comma_decimal_separator(tmp_path, x_columns):
    """LVM 2.0's Decimal_Separator ``,`` (a decimal-comma locale): numbers and clock times
    with a comma, fields tab-separated (the layout of docs/daq/lvm.md)."""
    seg, data = _segment(2000, decimal=",", x_columns=x_columns)
    rec = pio.read(_write(tmp_path / "de.lvm", _file_header(decimal=",", x_columns=x_columns) + seg))
    assert rec.fs == FS and rec.start_datetime == "2026-11-28T10:00:00"
    assert np.max(np.abs(rec.data - data)) <= 5e-7


def test_comma_separator(tmp_path):
    seg, data = _segment(500, sep=",")
    rec = pio.read(_write(tmp_path / "c.lvm", _file_header(sep=",") + seg))
    assert rec.fs == FS and np.max(np.abs(rec.data - data)) <= 5e-7


def test_delta_x_printed_short_warns_without_an_x_column(tmp_path):
    """LVM 1 writers print Delta_X with 6 decimals (``0.000977`` for 1024 Hz): the shortest
    rate that prints so is taken, with a warning when no x column pins it."""
    seg, _ = _segment(1000, x_columns="No", dx="0.000977")
    with pytest.warns(Warning, match=r"Delta_X '0.000977' is printed to 1e-06 s"):
        info = pio.read_info(_write(tmp_path / "old.lvm", _file_header(x_columns="No") + seg))
    assert info.fs == 1024.0


def test_multi_headings_no_rows_of_later_calls_follow(tmp_path):
    seg, data = _segment(600, x_columns="No", samples=200)
    rec = pio.read(_write(tmp_path / "mh.lvm", _file_header(x_columns="No", multi="No") + seg))
    assert rec.n_samples == 600 and np.max(np.abs(rec.data - data)) <= 5e-7


def test_sniff():
    assert lvm.sniff(b"LabVIEW Measurement\t\nWriter_Version\t2\n")
    assert lvm.sniff(b"\xef\xbb\xbfLabVIEW Measurement,\n")
    assert not lvm.sniff(b"")
    assert not lvm.sniff(b"time [s],a [V]\n0,1\n")


def test_bad_files(tmp_path):
    seg, _ = _segment(100)
    good = _file_header() + seg
    with pytest.raises(RecordingFileError, match="file is empty"):
        lvm.read_info(_write(tmp_path / "e.lvm", ""))
    with pytest.raises(CorruptFileError, match="truncated: the last line does not end with a newline"):
        lvm.read_info(_write(tmp_path / "cut.lvm", good[:-5]))
    lines = good.split("\n")
    with pytest.raises(CorruptFileError, match=r"Samples says 100 rows, the segment holds 90 \(truncated\)"):
        lvm.read_info(_write(tmp_path / "short.lvm", "\n".join(lines[:-11]) + "\n"))
    bad = list(lines)
    bad[40] = bad[40].split("\t")[0]
    with pytest.raises(CorruptFileError, match=r"line 41: 1 field\(s\), the 2 channel\(s\) need 3"):
        lvm.read_info(_write(tmp_path / "row.lvm", "\n".join(bad)))
    with pytest.raises(RecordingFileError, match="no ...End_of_Header... line"):
        lvm.read_info(_write(tmp_path / "nh.lvm", "LabVIEW Measurement\t\nSeparator\tTab\n"))
    with pytest.raises(RecordingFileError, match="Separator 'Space' is neither Tab nor Comma"):
        lvm.read_info(_write(tmp_path / "sp.lvm", good.replace("Separator\tTab", "Separator\tSpace")))
    with pytest.raises(RecordingFileError, match="X_Columns 'Two'"):
        lvm.read_info(_write(tmp_path / "x.lvm", good.replace("X_Columns\tOne", "X_Columns\tTwo")))
    gap = _file_header() + _segment(100)[0] + "\n" + _segment(100, i0=150)[0]
    with pytest.raises(RecordingFileError, match="segment 2 starts .* not one continuous recording"):
        lvm.read_info(_write(tmp_path / "gap.lvm", gap))
    other = _file_header() + _segment(100)[0] + "\n" + _segment(100, i0=100, names=("sun", "planet"))[0]
    with pytest.raises(RecordingFileError, match="the same channels in every segment"):
        lvm.read_info(_write(tmp_path / "other.lvm", other))
    jitter = good.replace("\n0.000195\t", "\n0.000300\t", 1)
    with pytest.raises(RecordingFileError, match=r"non-uniform time at line 25 \(sample 1\)"):
        lvm.read(_write(tmp_path / "j.lvm", jitter))
    with pytest.raises(FileNotFoundError):
        lvm.read_info(tmp_path / "none.lvm")


def test_bad_arguments(tmp_path):
    seg, _ = _segment(100)
    path = _write(tmp_path / "a.lvm", _file_header() + seg)
    with pytest.raises(ValueError, match="outside the recording"):
        lvm.read(path, None, 0, 101)
    with pytest.raises(TypeError):
        lvm.read_info(path, verify="yes")
    with pytest.raises(ValueError):
        list(lvm.iter_blocks(path, 0, 0))
    assert lvm.read(path, None, 5, 5).n_samples == 0
