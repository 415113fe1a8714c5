"""The meshphase.io registry: format by content, clear errors, atomic writes, streaming."""

from __future__ import annotations

import numpy as np
import pytest

import meshphase.io as pio
from meshphase.errors import DataQualityWarning
from meshphase.io import csv as mcsv
from meshphase.io import hdf5, tdms
from meshphase.io.base import RecordingFileError, atomic_path
from meshphase.recording import Recording

WRITABLE = ["hdf5", "csv"]


def _leftovers(directory, keep):
    return sorted(p.name for p in directory.iterdir() if p.name not in keep)


# ---------------------------------------------------------------------------- detection
@pytest.mark.parametrize("fmt, misleading_name", [("hdf5", "looks_like.csv"), ("csv", "looks_like.h5"),
                                                  ("hdf5", "no_suffix"), ("csv", "data.tdms")])
def test_format_is_recognised_by_content_not_suffix(tmp_path, recording, fmt, misleading_name):
    path = pio.write(recording, tmp_path / misleading_name, format=fmt)
    assert pio.detect_format(path) == fmt
    assert pio.read_info(path).format == fmt
    assert pio.read(path) == recording


def test_tdms_by_content(rig_tdms, tmp_path):
    path, data = rig_tdms
    other = tmp_path / "rig.csv"
    other.write_bytes(path.read_bytes())
    assert pio.detect_format(other) == "tdms"
    np.testing.assert_array_equal(pio.read(other).data, data)


@pytest.mark.parametrize("blob", [b"\x89PNG\r\n\x1a\n" + bytes(range(256)) * 4,
                                  b"TDSh\x0e\x00\x00\x00" + b"\0" * 100,      # a TDMS index file
                                  b"just some words without a separator\n",
                                  b"time a\n0 1\n"])
def test_unknown_format_lists_the_supported_ones(tmp_path, blob):
    path = tmp_path / "mystery.h5"
    path.write_bytes(blob)
    with pytest.raises(ValueError, match=r"mystery\.h5: unknown format .*supported formats: hdf5, mcap, tdms, lvm, csv"):
        pio.read(path)


def test_empty_missing_and_directory(tmp_path):
    empty = tmp_path / "empty.h5"
    empty.write_bytes(b"")
    with pytest.raises(RecordingFileError, match=r"empty\.h5: file is empty \(0 bytes\)"):
        pio.read(empty)
    with pytest.raises(FileNotFoundError, match="no such file"):
        pio.read(tmp_path / "missing.h5")
    with pytest.raises(IsADirectoryError, match="is a directory"):   # as process() and the CLI
        pio.read(tmp_path)


def test_explicit_format_skips_detection(tmp_path, recording):
    path = pio.write(recording, tmp_path / "r.bin", format="csv")
    assert pio.read(path, format="csv") == recording
    with pytest.raises(ValueError, match="unknown format 'xml'"):
        pio.read(path, format="xml")


# ---------------------------------------------------------------------------- writing
@pytest.mark.parametrize("suffix, fmt", [(".h5", "hdf5"), (".hdf5", "hdf5"), (".csv", "csv")])
def test_write_picks_format_from_suffix(tmp_path, recording, suffix, fmt):
    path = pio.write(recording, tmp_path / f"r{suffix}")
    assert pio.detect_format(path) == fmt


def test_write_refuses_unknown_suffix_and_read_only_format(tmp_path, recording):
    with pytest.raises(ValueError, match=r"cannot tell the format from suffix '\.xyz'"):
        pio.write(recording, tmp_path / "r.xyz")
    # a read-only format (a spec declaring no write) is refused by name and by suffix
    ro = pio.register_format(pio.FormatSpec(name="tdmsro", module="meshphase.io.tdms", suffixes=(".tdmsro",)))
    try:
        with pytest.raises(ValueError, match="format 'tdmsro' is read-only here; writable formats: hdf5, mcap, tdms, csv"):
            pio.write(recording, tmp_path / "r.tdmsro")
        with pytest.raises(ValueError, match="format 'tdmsro' is read-only"):
            pio.write(recording, tmp_path / "r.h5", format="tdmsro")
    finally:
        pio.unregister_format(ro.name)
    with pytest.raises(TypeError, match="must be a Recording"):
        pio.write(recording.data, tmp_path / "r.h5")
    assert _leftovers(tmp_path, set()) == []


@pytest.mark.parametrize("fmt", WRITABLE)
def test_existing_file_needs_overwrite(tmp_path, recording, make_recording, fmt):
    path = tmp_path / f"r.{'h5' if fmt == 'hdf5' else 'csv'}"
    pio.write(recording, path)
    before = path.read_bytes()
    with pytest.raises(FileExistsError, match="pass overwrite=True"):
        pio.write(make_recording(seed=5), path)
    assert path.read_bytes() == before
    other = make_recording(n=50, seed=5)
    pio.write(other, path, overwrite=True)
    assert pio.read(path) == other


def _fail_hdf5_midway(monkeypatch):
    import h5py

    calls = []
    orig = h5py.Group.create_dataset

    def create(self, *a, **k):
        calls.append(a[0] if a else k.get("name"))
        if len(calls) == 3:
            raise OSError("disk full (simulated)")
        return orig(self, *a, **k)

    monkeypatch.setattr(h5py.Group, "create_dataset", create)


def _fail_csv_midway(monkeypatch):
    calls = []
    orig = mcsv._format_block

    def fmt(*a, **k):
        calls.append(1)
        if len(calls) == 2:
            raise OSError("disk full (simulated)")
        return orig(*a, **k)

    monkeypatch.setattr(mcsv, "_format_block", fmt)


@pytest.mark.parametrize("fmt", WRITABLE)
@pytest.mark.parametrize("existing", [False, True])
def test_failed_write_leaves_nothing_half_written(tmp_path, recording, make_recording, monkeypatch, fmt, existing):
    path = tmp_path / f"r.{'h5' if fmt == 'hdf5' else 'csv'}"
    if existing:
        pio.write(recording, path)
    before = path.read_bytes() if existing else None
    (_fail_hdf5_midway if fmt == "hdf5" else _fail_csv_midway)(monkeypatch)
    with pytest.raises(OSError, match="disk full"):
        pio.write(make_recording(n=3000, seed=9), path, overwrite=True, **({"chunk_rows": 1000} if fmt == "csv" else {}))
    assert _leftovers(tmp_path, {path.name}) == []          # no temporary file left behind
    if existing:
        assert path.read_bytes() == before                   # the old recording is intact
        monkeypatch.undo()
        assert pio.read(path) == recording
    else:
        assert not path.exists()


def test_atomic_path_contract(tmp_path):
    target = tmp_path / "t.bin"
    with atomic_path(target) as tmp:
        # created empty with O_EXCL (the name is reserved), short name next to the target
        assert tmp.parent == tmp_path and tmp != target and tmp.read_bytes() == b""
        assert tmp.name.startswith(".mp-") and tmp.name.endswith(".partial") and len(tmp.name) <= 33
        tmp.write_bytes(b"ok")
        assert not target.exists()
    assert target.read_bytes() == b"ok"
    with pytest.raises(FileNotFoundError, match="does not exist"):
        with atomic_path(tmp_path / "no_dir" / "x.bin"):
            pass


# ---------------------------------------------------------------------------- reading
@pytest.fixture(params=["hdf5", "csv", "tdms"])
def any_file(request, tmp_path, recording, rig_tdms):
    """(path, the same recording held in memory) for every readable format."""
    if request.param == "tdms":
        path, _ = rig_tdms
        return path, tdms.read(path)
    path = pio.write(recording, tmp_path / f"r.{'h5' if request.param == 'hdf5' else 'csv'}")
    return path, recording


@pytest.mark.parametrize("block, overlap", [(0.01, 0.0), (0.0173, 0.004), (0.05, 0.06), (10.0, 1.0)])
def test_iter_blocks_equals_in_memory_blocks(any_file, block, overlap):
    path, rec = any_file
    got = list(pio.iter_blocks(path, block, overlap))
    want = list(rec.blocks(block, overlap))
    assert len(got) == len(want) > 0
    assert all(g == w for g, w in zip(got, want))
    sub = rec.names[1:3][::-1]
    got = list(pio.iter_blocks(path, block, overlap, channels=sub))
    assert all(g == w for g, w in zip(got, rec.select(sub).blocks(block, overlap)))


def test_iter_blocks_bad_input(any_file):
    path, _ = any_file
    with pytest.raises(ValueError, match="block must be > 0"):
        list(pio.iter_blocks(path, 0.0))
    with pytest.raises(ValueError, match="overlap must be >= 0"):
        list(pio.iter_blocks(path, 0.01, -0.1))
    with pytest.raises(ValueError, match=r"no channel\(s\) \['nope'\]"):
        list(pio.iter_blocks(path, 0.01, channels=["nope"]))


def test_read_window_equals_slice(any_file):
    path, rec = any_file
    start, stop = rec.t0 + 0.013, rec.t0 + 0.0771
    assert pio.read(path, start=start, stop=stop) == rec.slice_time(start, stop)
    assert pio.read(path, start=start) == rec.slice_time(start)
    assert pio.read(path, stop=stop) == rec.slice_time(None, stop)


@pytest.mark.parametrize("start, stop", [(5.0, 6.0), (-2.0, -1.0), (0.05, 0.01), (0.02, 0.02)])
def test_window_outside_or_empty_raises_naming_the_file(any_file, start, stop):
    path, _ = any_file
    with pytest.raises(ValueError, match=rf"{path.name}: (window|empty or reversed window)"):
        pio.read(path, start=start, stop=stop)


def test_read_info_matches_read(any_file):
    path, rec = any_file
    info = pio.read_info(path)
    assert (info.fs, info.n_samples, info.t0, info.channels) == (rec.fs, rec.n_samples, rec.t0, list(rec.channels))
    assert info.duration == rec.duration and info.names == rec.names


def test_nan_runs_warn_through_the_registry(tmp_path, make_recording):
    rec = make_recording(n=100, n_channels=3, nan_runs=True)
    for fmt, name in [("hdf5", "n.h5"), ("csv", "n.csv")]:
        path = pio.write(rec, tmp_path / name)
        with pytest.warns(DataQualityWarning, match="channel 'ring_1' has 3 run"):
            back = pio.read(path)
        assert back == rec


def test_zero_channel_and_empty_recordings_through_the_registry(tmp_path):
    for i, rec in enumerate([Recording(np.empty((0, 2)), 10.0, ["a", "b"]), Recording(np.empty((4, 0)), 10.0, [])]):
        for suffix in (".h5", ".csv"):
            path = pio.write(rec, tmp_path / f"e{i}{suffix}")
            assert pio.read(path) == rec
            assert list(pio.iter_blocks(path, 0.1)) == list(rec.blocks(0.1))


def test_hdf5_header_read_once_per_registry_read(tmp_path, recording, monkeypatch):
    path = pio.write(recording, tmp_path / "once.h5")
    calls = []
    orig = hdf5._parse_header
    monkeypatch.setattr(hdf5, "_parse_header", lambda *a: calls.append(1) or orig(*a))
    pio.read(path)
    pio.read(path, channels=["sun_0"])
    assert len(calls) == 1   # the parsed header is cached for this exact file (its file_id)


# ---------------------------------------------------------------------------- throughput
def _best_rate(fn, n_samples, repeats=3):
    import time

    best = float("inf")
    out = None
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return n_samples / best / 1e9, out


@pytest.mark.bench
@pytest.mark.parametrize("minutes", [10.0])
def test_read_throughput_vs_raw_npy(tmp_path, minutes):
    """Measured, not asserted: GS/s of each reader vs np.load of the same samples (the readers'
    targets: HDF5 >= 0.5, TDMS >= 0.3 of raw; CSV at least pandas' C engine on the same file)."""
    import pandas as pd
    from nptdms import ChannelObject, TdmsWriter

    fs, n_ch = 5120, 8
    n = int(fs * 60 * minutes)
    data = np.random.default_rng(0).standard_normal((n, n_ch)) * 1e-5
    np.save(tmp_path / "raw.npy", data)
    rec = Recording(data, fs, [f"sun_{j}" for j in range(n_ch)])
    pio.write(rec, tmp_path / "r.h5")
    with TdmsWriter(str(tmp_path / "r.tdms")) as w:
        for s in range(0, n, 51200):
            w.write_segment([ChannelObject("g", f"sun_{j}", data[s:s + 51200, j],
                                           properties={"wf_increment": 1 / fs} if s == 0 else {})
                             for j in range(n_ch)])
    n_csv = fs * 60
    pio.write(Recording(data[:n_csv], fs, rec.channels), tmp_path / "r.csv")
    raw, _ = _best_rate(lambda: np.load(tmp_path / "raw.npy"), data.size)
    h5, got_h5 = _best_rate(lambda: pio.read(tmp_path / "r.h5"), data.size)
    td, got_td = _best_rate(lambda: pio.read(tmp_path / "r.tdms"), data.size)
    pd_rate, _ = _best_rate(lambda: pd.read_csv(tmp_path / "r.csv", skiprows=1), n_csv * n_ch)
    cs, got_cs = _best_rate(lambda: pio.read(tmp_path / "r.csv"), n_csv * n_ch)
    print(f"\nraw .npy {raw:.3f} GS/s | HDF5 {h5:.3f} ({h5 / raw:.2f} of raw) | TDMS {td:.3f} ({td / raw:.2f}) | "
          f"CSV {cs:.4f} vs pandas alone {pd_rate:.4f} ({cs / pd_rate:.2f})")
    np.testing.assert_array_equal(got_h5.data, data)
    np.testing.assert_array_equal(got_td.data, data)
    np.testing.assert_array_equal(got_cs.data, data[:n_csv])
