"""Interleaved TDMS rows read by several threads (meshphase.io.tdms_rows.read_rows with
``threads`` > 1, ``meshphase.io.tdms.reading_path(threads=...)``): the same samples, bit for
bit, as one thread and as npTDMS's public read_data, for odd segment sizes, a short last
segment, channel subsets, float32 output and int16 rows."""

from __future__ import annotations

import mmap
import struct

import numpy as np
import pytest
from nptdms import TdmsFile

from meshphase.io import tdms, tdms_index, tdms_rows
from meshphase.recording import ChannelSpec, Recording
from meshphase.synthetic.tdms_export import write_ni_log

FS = 5120.0


@pytest.fixture(autouse=True)
def _small_parts(monkeypatch):
    """Threads also for the short windows of these tests."""
    monkeypatch.setattr(tdms_rows, "_MIN_THREAD_SAMPLES", 1)


def _rec(n, nch, seed=0):
    data = np.random.default_rng(seed).standard_normal((n, nch))
    return Recording(data, FS, [ChannelSpec(f"sun_{j}", kind="sun") for j in range(nch)])


def _read(path, chans, i0, i1, threads, dtype=np.float64, plain_map=False):
    idx = tdms_index.scan(path)
    runs = [idx.runs[p] for p in idx.runs]
    starts = idx.starts(next(iter(idx.runs)))
    out = np.full((len(chans), i1 - i0), -1.0, dtype=dtype)
    with open(path, "rb") as fh:
        mm = (mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) if plain_map
              else tdms_index.open_map(fh))
        with mm:
            finite = tdms_rows.read_rows(mm, [runs[c] for c in chans], starts, i0, i1, out,
                                         threads=threads)
    return out, finite


@pytest.mark.parametrize("spc", [512, 1000, 7, 333])
@pytest.mark.parametrize("threads", [2, 3])
def test_threads_read_the_same_samples_as_one_thread(tmp_path, spc, threads):
    n, nch = 5 * spc + 17, 4           # the last segment is shorter than the others
    rec = _rec(n, nch, seed=spc)
    path = write_ni_log(rec, tmp_path / "x.tdms", samples_per_segment=spc, interleaved=True)
    for chans in ([0, 1, 2, 3], [2, 0], [1, 3], [3, 2, 1, 0]):
        for a, b in ((0, n), (1, n - 1), (spc - 1, spc + 2), (2 * spc + 3, n), (n - 2, n)):
            for plain in (False, True):
                one, f1 = _read(path, chans, a, b, 1, plain_map=plain)
                many, fk = _read(path, chans, a, b, threads, plain_map=plain)
                assert many.tobytes() == one.tobytes() == np.ascontiguousarray(rec.data[a:b, chans].T).tobytes()
                assert f1 is True and fk is True


@pytest.mark.parametrize("spc", [512, 1000])
def test_reading_path_threads_equal_nptdms_read_data(tmp_path, monkeypatch, spc):
    rec = _rec(4 * spc + 100, 8, seed=3)
    rec.data[spc + 1, 5] = -0.0
    path = write_ni_log(rec, tmp_path / "x.tdms", samples_per_segment=spc, interleaved=True)
    with tdms.reading_path(threads=2):
        assert tdms._ROW_THREADS == 2
        fast = tdms.read(path)
        part = tdms.read(path, ["sun_6", "sun_1"], 17, 3 * spc + 5)
    assert tdms._ROW_THREADS == 1
    with tdms.reading_path(computed_offsets=False):
        public = tdms.read(path)
    assert fast.data.tobytes() == public.data.tobytes() == rec.data.tobytes()
    np.testing.assert_array_equal(part.data, rec.data[17:3 * spc + 5][:, [6, 1]])


def test_threads_report_a_non_finite_sample_in_any_part(tmp_path):
    rec = _rec(3000, 3)
    rec.data[2900, 2] = np.nan          # in the last thread's part
    path = write_ni_log(rec, tmp_path / "x.tdms", samples_per_segment=512, interleaved=True)
    out, finite = _read(path, [0, 1, 2], 0, 3000, 2)
    assert finite is False and np.isnan(out[2, 2900])
    assert _read(path, [0, 1, 2], 0, 2800, 2)[1] is True


def test_threads_float32_output(tmp_path):
    rec = _rec(2100, 3)
    path = write_ni_log(rec, tmp_path / "x.tdms", samples_per_segment=1000, interleaved=True)
    out, finite = _read(path, [0, 1, 2], 5, 2090, 2, dtype=np.float32)
    assert out.dtype == np.float32 and finite is True
    np.testing.assert_array_equal(out, rec.data[5:2090].T.astype(np.float32))


def _int16_rows(path, x, sizes):
    """Two int16 channels interleaved, segments of ``sizes`` rows (hand-built, little-endian)."""
    names = ["/'g'/'a'", "/'g'/'b'"]
    blob, lo = b"", 0
    for k, nv in enumerate(sizes):
        meta = struct.pack("<I", 2)
        for p in names:
            pb = p.encode()
            meta += struct.pack("<I", len(pb)) + pb + struct.pack("<IIIQ", 20, 2, 1, nv)   # tdsTypeI16
            meta += struct.pack("<I", 0)
        rows = np.ascontiguousarray(x[:, lo:lo + nv].T).astype("<i2").tobytes()
        lo += nv
        toc = (1 << 1) | (1 << 3) | (1 << 5) | ((1 << 2) if k == 0 else 0)
        blob += b"TDSm" + struct.pack("<IIQQ", toc, 4713, len(meta) + len(rows), len(meta)) + meta + rows
    path.write_bytes(blob)
    return names


def test_int16_rows_by_threads_equal_nptdms_unscaled(tmp_path):
    sizes = [333, 333, 333, 1000, 41]
    x = np.random.default_rng(9).integers(-32768, 32767, size=(2, sum(sizes)), dtype=np.int16)
    path = tmp_path / "i16.tdms"
    names = _int16_rows(path, x, sizes)
    n = sum(sizes)
    with TdmsFile.open(path) as f:
        theirs = [f[names[j].split("'")[1]][names[j].split("'")[3]].read_data(scaled=False) for j in (0, 1)]
    for threads in (1, 2, 4):
        out, finite = _read(path, [0, 1], 0, n, threads)
        assert out.tobytes() == np.asarray(theirs, dtype=np.float64).tobytes()
        assert finite is True
        part, _ = _read(path, [1, 0], 300, 1500, threads)
        np.testing.assert_array_equal(part, x[[1, 0], 300:1500].astype(np.float64))


def test_threads_empty_window_and_bad_input(tmp_path):
    rec = _rec(2048, 2)
    path = write_ni_log(rec, tmp_path / "x.tdms", samples_per_segment=512, interleaved=True)
    for i in (0, 1000, 2048):
        out, finite = _read(path, [0, 1], i, i, 2)
        assert out.shape == (2, 0) and finite is True
    for bad, err in ((0, ValueError), (-1, ValueError), (1.5, TypeError), (True, TypeError), ("2", TypeError)):
        with pytest.raises(err, match="threads"):
            _read(path, [0, 1], 0, 10, bad)
    with pytest.raises(ValueError, match="threads"), tdms.reading_path(threads=0):
        pass
    with pytest.raises(TypeError), tdms.reading_path(threads=None):
        pass
    assert tdms._ROW_THREADS == 1


def test_an_error_in_a_worker_thread_reaches_the_caller(tmp_path):
    rec = _rec(2048, 2)
    path = write_ni_log(rec, tmp_path / "x.tdms", samples_per_segment=512, interleaved=True)
    idx = tdms_index.scan(path)
    runs = [idx.runs[p] for p in idx.runs]
    starts = idx.starts(next(iter(idx.runs)))
    cut = tmp_path / "cut.tdms"
    cut.write_bytes(path.read_bytes()[:-3000])   # the rows end inside the last segment (2nd part)
    for opener in (tdms_index.open_map, lambda fh: mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)):
        with open(cut, "rb") as fh, opener(fh) as mm, pytest.raises((ValueError, TypeError)):
            tdms_rows.read_rows(mm, runs, starts, 0, 2048, np.empty((2, 2048)), threads=2)
