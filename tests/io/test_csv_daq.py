"""CSV exports of DAQ software: metadata blocks above the header, units lines, decimal
comma, localized time headers, files without a time column (``fs=``), and the layout
options ``header_row``, ``skip_rows``, ``decimal``, ``delimiter``."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import meshphase.io as pio
from meshphase.io import csv as mcsv
from meshphase.io.base import CorruptFileError, RecordingFileError
from meshphase.io.timenames import CLOCK_NAMES, time_header

FS = 5120.0
N = 3000


def _signal():
    t = np.arange(N) / FS
    return t, np.c_[120.0 * np.sin(2 * np.pi * 30 * t), -80.0 * np.cos(2 * np.pi * 7 * t)]


def _write(path, text, encoding="utf-8"):
    path.write_text(text, encoding=encoding, newline="")
    return path


def _rows(t, data, sep, decimal, time_fmt="{:.6f}"):
    out = []
    for ti, row in zip(t, data):
        line = sep.join([time_fmt.format(ti)] + [f"{v:.4f}" for v in row])
        out.append(line.replace(".", decimal) if decimal != "." else line)
    return "".join(r + "\r\n" for r in out)


def test_catman_ascii_export(tmp_path):
    """HBM catman's ASCII export (catman Easy/AP manual, "Export -> ASCII"): an information
    block of ``key;value`` lines (file, comment, date, time), one line of channel names
    with the time channel named ``Zeit  1 - Standard-Messrate``, one line of units, then the
    rows, ``;``-separated with a decimal comma (German Windows locale), CRLF line ends."""
    t, data = _signal()
    head = ("Datei;D:\\catman\\Pruefstand\\Lauf_12.bin\r\n"
            "Kommentar;Planetenstufe 1, Lauf 12\r\n"
            "Datum;28.11.2026\r\n"
            "Uhrzeit;10:00:00\r\n"
            "\r\n"
            "Zeit  1 - Standard-Messrate;DMS Sonne Z3;DMS Hohlrad 11\r\n"
            "s;µm/m;µm/m\r\n")
    path = _write(tmp_path / "catman.csv", head + _rows(t, data, ";", ","))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rec = pio.read(path)
    assert rec.fs == FS and rec.t0 == 0.0 and rec.n_samples == N
    assert rec.names == ["DMS Sonne Z3", "DMS Hohlrad 11"]
    assert [c.units for c in rec.channels] == ["µm/m", "µm/m"]
    assert np.max(np.abs(rec.data - data)) <= 5e-5
    md = rec.meta["csv"]
    assert md["header_row"] == 6
    assert md["metadata"] == {"Datei": "D:\\catman\\Pruefstand\\Lauf_12.bin", "Kommentar":
                              "Planetenstufe 1, Lauf 12", "Datum": "28.11.2026", "Uhrzeit": "10:00:00"}
    info = pio.read_info(path)
    assert info.meta == rec.meta and info.extra["header_lines"] == 7
    blocks = list(pio.iter_blocks(path, 1000 / FS, 64 / FS))
    np.testing.assert_array_equal(np.concatenate([b.data[:1000] for b in blocks]), rec.data)


def test_dewesoft_csv_export(tmp_path):
    """DEWESoft X's CSV export (DEWESoft X user manual, "Export -> Text / CSV"): a header
    block of ``key,value`` lines (setup, start time, sample rate), a line of per-channel
    properties, a blank line, then the column names with the units in brackets, the time
    column ``Time [s]``, comma-separated with a decimal point."""
    t, data = _signal()
    t = t + 2.5
    head = ("Setup file,gearbox_rig.dxs\n"
            "Start time,28.11.2026 10:00:00.000\n"
            "Sample rate,5120 Hz\n"
            "Channel range,+-1000 um/m,+-1000 um/m\n"
            "\n"
            "Time [s],SG03_sun_T3 [um/m],SG11_ring [um/m]\n")
    path = _write(tmp_path / "dewesoft.csv", head + _rows(t, data, ",", ".").replace("\r\n", "\n"))
    rec = pio.read(path)
    assert rec.fs == FS and rec.t0 == pytest.approx(2.5, abs=1e-12)
    assert [c.units for c in rec.channels] == ["um/m", "um/m"]
    assert rec.meta["csv"]["metadata"] == {"Setup file": "gearbox_rig.dxs", "Start time": "28.11.2026 10:00:00.000",
                                           "Sample rate": "5120 Hz",
                                           "Channel range": ["+-1000 um/m", "+-1000 um/m"]}
    assert rec.meta["csv"]["header_row"] == 6


def test_labview_write_to_measurement_file_spreadsheet_text(tmp_path):
    """LabVIEW "Write Delimited Spreadsheet" / "Write To Measurement File" in text mode
    without the LVM header: tab-separated, the time column ``Time``, English names, no
    units (a FormatWarning) and a two-line comment block written by the VI's caller."""
    t, data = _signal()
    head = "Operator\tlab\nRun\t12\nTime\tsun\tring\n"
    path = _write(tmp_path / "lv.txt", head + _rows(t, data, "\t", ".").replace("\r\n", "\n"))
    with pytest.warns(Warning, match=r"carry no '\[units\]'"):
        rec = mcsv.read(path)
    assert rec.fs == FS and rec.names == ["sun", "ring"]
    assert rec.meta["csv"]["metadata"] == {"Operator": "lab", "Run": "12"}


@pytest.mark.parametrize("head, scale", [("Zeit [s]", 1.0), ("Temps (s)", 1.0), ("Tiempo/ms", 1e-3),
                                         ("Tempo in s", 1.0), ("t [us]", 1e-6)])
def test_german_decimal_comma_semicolon_and_localized_time_headers(tmp_path, head, scale):
    """A German spreadsheet CSV (Excel/LibreOffice in a de-DE locale): ``;`` between fields,
    decimal comma, ``Zeit [s]``; the same with French, Spanish, Italian headers and ms/us."""
    t, data = _signal()
    text = f"{head};Sonne [µm/m];Hohlrad [µm/m]\n" + _rows(t / scale, data, ";", ",", "{:.9g}").replace("\r\n", "\n")
    rec = pio.read(_write(tmp_path / "de.csv", text))
    assert rec.fs == FS and rec.t0 == 0.0 and rec.meta == {}
    assert np.max(np.abs(rec.data - data)) <= 5e-5


def test_decimal_and_delimiter_options(tmp_path):
    t, data = _signal()
    text = "Zeit [s];a [V];b [V]\n" + _rows(t, data, ";", ",").replace("\r\n", "\n")
    path = _write(tmp_path / "o.csv", text)
    rec = pio.read(path, decimal=",", delimiter=";")
    assert rec.fs == FS and np.max(np.abs(rec.data - data)) <= 5e-5
    with pytest.raises(RecordingFileError, match="no header found"):
        pio.read(path, delimiter="\t")        # the wrong separator: no line is a header


def test_no_time_column_needs_fs(tmp_path):
    """A CSV of samples only (a logger exporting the channels without a time base): the
    rate comes from ``fs=`` and t0 is 0."""
    _, data = _signal()
    text = "Operator,Smith\nsun [V],ring [V]\n" + "".join(f"{a:.4f},{b:.4f}\n" for a, b in data)
    path = _write(tmp_path / "nt.csv", text)
    with pytest.raises(RecordingFileError, match=r"line 2: first column must be the time.*got 'sun \[V\]'.*fs="):
        pio.read(path)
    rec = pio.read(path, fs=FS)
    assert rec.fs == FS and rec.t0 == 0.0 and rec.n_samples == N and rec.names == ["sun", "ring"]
    assert rec.meta["csv"]["metadata"] == {"Operator": "Smith"}
    assert np.max(np.abs(rec.data - data)) <= 5e-5
    info = pio.read_info(path, fs=FS)
    assert info.extra["time_column"] is False and info.duration == pytest.approx(N / FS)
    win = pio.read(path, ["ring"], start=0.1, stop=0.2, fs=FS)
    np.testing.assert_array_equal(win.data[:, 0], rec.data[512:1024, 1])
    blocks = list(pio.iter_blocks(path, 1000 / FS, 10 / FS, fs=FS))
    np.testing.assert_array_equal(np.concatenate([b.data[:1000] for b in blocks]), rec.data)


def test_fs_with_a_time_column_must_agree(tmp_path):
    t, data = _signal()
    path = _write(tmp_path / "t.csv", "time [s],a [V],b [V]\n" + _rows(t, data, ",", "."))
    assert pio.read(path, fs=FS).fs == FS
    with pytest.raises(RecordingFileError, match=r"fs = 5000.0 Hz given, but the time column spans"):
        pio.read(path, fs=5000.0)


def test_header_row_and_skip_rows(tmp_path):
    t, data = _signal()
    head = "Sensor,Value\nSample rate,5120\nsun,ring,time\n"   # a line that looks like names
    text = head + "Time [s],sun [V],ring [V]\n" + _rows(t, data, ",", ".")
    path = _write(tmp_path / "h.csv", text)
    a, b, c = pio.read(path), pio.read(path, header_row=4), pio.read(path, skip_rows=3)
    assert a == b == c and a.meta["csv"]["header_row"] == 4
    assert a.meta["csv"]["metadata"] == {"Sensor": "Value", "Sample rate": "5120", "sun": ["ring", "time"]}
    with pytest.raises(ValueError, match="name different header lines"):
        pio.read(path, header_row=4, skip_rows=1)
    with pytest.raises(RecordingFileError, match=r"header_row = 99999 is past the end of the file \(3004 lines\)"):
        pio.read(path, header_row=99999)
    with pytest.raises(RecordingFileError, match=r"line 2: first column must be the time"):
        pio.read(path, header_row=2)


def test_no_header_found_names_the_lines_it_looked_at(tmp_path):
    path = _write(tmp_path / "x.csv", "Versuch;Lauf 12\nPruefer;Mueller\nKanal;A;B\n1;2\n")
    with pytest.raises(RecordingFileError, match=r"no header found in the first 4 line\(s\) \(line 1: "
                                                 r"'Versuch;Lauf 12'; line 2: 'Pruefer;Mueller'; line 3"):
        pio.read(path)


def test_inconsistent_field_counts(tmp_path):
    path = _write(tmp_path / "f.csv", "Info;x\nZeit [s];a [V];b [V]\n0;1;2;3\n")
    with pytest.raises(CorruptFileError, match=r"line 3 \(byte 28\): 4 field\(s\), the header \(line 2\) has 3"):
        pio.read(path)
    t, data = _signal()
    text = "Info;x\nZeit [s];a [V];b [V]\n" + _rows(t, data, ";", ",").replace("\r\n", "\n")
    lines = text.split("\n")
    lines[500] = lines[500].rsplit(";", 1)[0]
    with pytest.raises(CorruptFileError, match=r"line 501 .*2 field\(s\), the header has 3"):
        pio.read(_write(tmp_path / "g.csv", "\n".join(lines)))


def test_bad_options(tmp_path):
    path = _write(tmp_path / "b.csv", "time [s],a [V]\n0,1\n1,2\n")
    for kw, exc in [({"header_row": 0}, ValueError), ({"skip_rows": -1}, ValueError), ({"fs": 0.0}, ValueError),
                    ({"fs": "5120"}, ValueError), ({"decimal": ";"}, ValueError), ({"delimiter": ":"}, ValueError),
                    ({"delimiter": ",", "decimal": ","}, ValueError), ({"header_row": 1.5}, ValueError)]:
        with pytest.raises(exc):
            pio.read(path, **kw)
    with pytest.raises(TypeError):
        pio.read(path, hedaer_row=1)


def test_empty_file_and_header_only_file(tmp_path):
    with pytest.raises(RecordingFileError, match="file is empty"):
        pio.read_info(_write(tmp_path / "e.csv", ""), format="csv", fs=FS)
    info = pio.read_info(_write(tmp_path / "h.csv", "Info;x\na [V];b [V]\n"), format="csv", fs=FS)
    assert info.n_samples == 0 and info.names == ["a", "b"]


def test_own_files_keep_their_layout_with_the_options(tmp_path, recording):
    path = pio.write(recording, tmp_path / "own.csv")
    assert pio.read(path, fs=recording.fs) == recording
    with pytest.raises(RecordingFileError, match="the preamble says"):
        pio.read_info(path, fs=recording.fs * 2)


def test_one_list_of_time_names_for_csv_and_tdms():
    from meshphase.io import base, tdms

    assert base.CLOCK_NAMES is CLOCK_NAMES and tdms.CLOCK_NAMES is CLOCK_NAMES
    for name in ("zeit", "temps", "tiempo", "tempo", "time", "t"):
        assert name in CLOCK_NAMES and time_header(name.capitalize() + " [s]")[2] == 1.0
    assert time_header("Zeit (ms)")[2] == 1e-3 and time_header("Time / us")[2] == 1e-6
    assert time_header("Zeit  1 - Standard-Messrate") is not None
    for bad in ("", "sun [s]", "time [h]", "Timer", "T3 sun", None, 3):
        assert time_header(bad) is None


def test_a_title_line_without_separators_above_the_header(tmp_path):
    """A text export whose first lines are a title and a free-text comment (no separator on
    the first line) is still recognised as CSV by content, and reads with the header found
    or named: detection looks for a separator on any line of the file's head."""
    t, data = _signal()
    head = "Rig A export\nfree text, with a comma\nTime [s],sun [m/m],ring [m/m]\n"
    path = _write(tmp_path / "title.txt", head + _rows(t, data, ",", "."))
    assert pio.detect_format(path) == "csv"
    a, b = pio.read(path), pio.read(path, header_row=3)
    assert a == b and a.names == ["sun", "ring"] and a.fs == FS
    assert a.meta["csv"]["header_row"] == 3
    assert not mcsv.sniff(b"Rig A export\nno separators here\n")   # plain prose is no CSV
