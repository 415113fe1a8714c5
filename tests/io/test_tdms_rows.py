"""Interleaved TDMS rows read together (meshphase.io.tdms_rows.read_rows): through
``os.preadv`` on a FileMap and through a plain memory map, equal to npTDMS's public
read_data bit for bit, with the NaN/inf scan folded into the copy."""

from __future__ import annotations

import mmap
import struct
import warnings

import numpy as np
import pytest

from meshphase.errors import DataQualityWarning
from meshphase.io import tdms, tdms_index, tdms_rows
from meshphase.recording import ChannelSpec, Recording
from meshphase.synthetic.tdms_export import write_ni_log

FS = 5120.0


def _rec(n, nch, seed=0, dtype=np.float64):
    data = np.random.default_rng(seed).standard_normal((n, nch)).astype(dtype)
    return Recording(data, FS, [ChannelSpec(f"sun_{j}", kind="sun") for j in range(nch)])


def _runs(path):
    idx = tdms_index.scan(path)
    runs = [idx.runs[p] for p in idx.runs]
    return idx, runs, idx.starts(next(iter(idx.runs)))


def _rows(path, i0, i1, nch, plain_map=False, dtype=np.float64):
    """read_rows over a FileMap (os.preadv) or a plain mmap (copies through the map)."""
    _, runs, starts = _runs(path)
    assert tdms_rows.shared_rows(runs)
    out = np.full((nch, i1 - i0), -1.0, dtype=dtype)
    with open(path, "rb") as fh:
        mm = (mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) if plain_map
              else tdms_index.open_map(fh))
        with mm:
            finite = tdms_rows.read_rows(mm, runs, starts, i0, i1, out)
    return out, finite


@pytest.mark.parametrize("spc", [512, 1000, 7, 333])
@pytest.mark.parametrize("plain_map", [False, True])
def test_rows_equal_the_recording_in_windows_across_segments(tmp_path, spc, plain_map):
    n, nch = 5 * spc + 17, 4           # a shorter last segment with its own raw data index
    rec = _rec(n, nch)
    path = write_ni_log(rec, tmp_path / "x.tdms", samples_per_segment=spc, interleaved=True)
    for a, b in ((0, n), (1, n - 1), (spc - 1, spc + 1), (spc, 3 * spc), (2 * spc + 3, n), (n - 1, n)):
        out, finite = _rows(path, a, b, nch, plain_map)
        np.testing.assert_array_equal(out, rec.data[a:b].T)
        assert finite is True


@pytest.mark.parametrize("spc", [512, 1000])
def test_preadv_and_map_paths_agree_with_nptdms_bit_for_bit(tmp_path, monkeypatch, spc):
    rec = _rec(4 * spc + 100, 8, seed=3)
    rec.data[7, 2] = np.nan
    rec.data[spc + 1, 5] = -0.0
    path = write_ni_log(rec, tmp_path / "x.tdms", samples_per_segment=spc, interleaved=True)
    n = rec.n_samples
    a, b = _rows(path, 0, n, 8)[0], _rows(path, 0, n, 8, plain_map=True)[0]
    assert a.tobytes() == b.tobytes() == np.ascontiguousarray(rec.data.T).tobytes()
    with pytest.warns(DataQualityWarning):
        fast = tdms.read(path)
    monkeypatch.setattr(tdms, "_USE_FAST_PATH", False)
    with pytest.warns(DataQualityWarning):
        public = tdms.read(path)
    assert fast.data.tobytes() == public.data.tobytes()


def test_non_finite_samples_are_reported_and_finite_reads_skip_the_scan(tmp_path, monkeypatch):
    rec = _rec(3000, 3)
    path = write_ni_log(rec, tmp_path / "x.tdms", samples_per_segment=512, interleaved=True)
    calls = []
    real = tdms.warn_nonfinite
    monkeypatch.setattr(tdms, "warn_nonfinite", lambda *a, **k: (calls.append(a), real(*a, **k)))
    with warnings.catch_warnings():
        warnings.simplefilter("error", DataQualityWarning)
        tdms.read(path)
        list(tdms.iter_blocks(path, 700, 10))
    assert calls == []                   # every block summed finite while it was copied
    rec.data[2000, 1] = np.inf
    rec.data[100, 2] = np.nan
    path = write_ni_log(rec, tmp_path / "y.tdms", samples_per_segment=512, interleaved=True)
    assert _rows(path, 0, 3000, 3)[1] is False
    with pytest.warns(DataQualityWarning) as caught:
        got = tdms.read(path)
    said = sorted(str(w.message).split(": ", 1)[1] for w in caught)
    assert said[0].startswith("channel 'sun_1' has 1 run(s) of NaN/inf samples (1 samples, longest 1, first at "
                              "sample 2000)") and said[1].startswith("channel 'sun_2' has 1 run")
    assert np.isinf(got.data[2000, 1]) and np.isnan(got.data[100, 2])
    with pytest.warns(DataQualityWarning, match=r"first at sample 2000"):
        tdms.read(path, None, 1500, 2500)
    with warnings.catch_warnings():
        warnings.simplefilter("error", DataQualityWarning)
        tdms.read(path, None, 200, 1900)          # the window holds no NaN/inf


def test_float32_rows_and_float32_output(tmp_path):
    rec = _rec(2100, 3, dtype=np.float32)
    path = write_ni_log(rec, tmp_path / "x.tdms", samples_per_segment=1000, interleaved=True)
    out, finite = _rows(path, 5, 2090, 3, dtype=np.float64)   # the stored float64 into float32 output
    np.testing.assert_array_equal(out, rec.data[5:2090].T.astype(np.float64))
    out32, finite32 = _rows(path, 5, 2090, 3, dtype=np.float32)
    assert out32.dtype == np.float32 and finite and finite32
    np.testing.assert_array_equal(out32, rec.data[5:2090].T)


def test_read_rows_empty_window(tmp_path):
    rec = _rec(1200, 2)
    path = write_ni_log(rec, tmp_path / "x.tdms", samples_per_segment=512, interleaved=True)
    for i in (0, 600, 1200):
        out, finite = _rows(path, i, i, 2)
        assert out.shape == (2, 0) and finite is True


def test_read_rows_bad_input(tmp_path):
    rec = _rec(2048, 2)
    path = write_ni_log(rec, tmp_path / "x.tdms", samples_per_segment=512, interleaved=True)
    _, runs, starts = _runs(path)
    cut = tmp_path / "cut.tdms"
    cut.write_bytes(path.read_bytes()[:-3000])   # the rows end inside the last segment
    for opener in (tdms_index.open_map, lambda fh: mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)):
        with open(cut, "rb") as fh, opener(fh) as mm, pytest.raises((ValueError, TypeError)):
            tdms_rows.read_rows(mm, runs, starts, 0, 2048, np.empty((2, 2048)))
    with open(path, "rb") as fh, tdms_index.open_map(fh) as mm, pytest.raises(ValueError):
        tdms_rows.read_rows(mm, runs, starts, 0, 2048, np.empty((2, 100)))   # out too short
    with open(path, "rb") as fh, tdms_index.open_map(fh) as mm, pytest.raises(ValueError, match="not shared"):
        tdms_rows.read_rows(mm, [], starts, 0, 10, np.empty((0, 10)))
    assert tdms_rows.shared_rows([]) is False and tdms_rows.row_columns([]) is None


def test_row_columns_of_subsets_in_any_order(tmp_path):
    rec = _rec(1500, 4)
    path = write_ni_log(rec, tmp_path / "x.tdms", samples_per_segment=512, interleaved=True)
    _, runs, starts = _runs(path)
    assert tdms_rows.row_columns(runs) == (0, 8, 16, 24)
    assert tdms_rows.row_columns([runs[2], runs[0]]) == (16, 0)
    assert tdms_rows.row_columns([runs[3]]) == (0,)
    for chans in ([2, 0], [3], [1, 3], [3, 2, 1, 0]):
        for plain in (False, True):
            out = np.empty((len(chans), 1100))
            with open(path, "rb") as fh:
                mm = (mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) if plain else tdms_index.open_map(fh))
                with mm:
                    assert tdms_rows.read_rows(mm, [runs[c] for c in chans], starts, 300, 1400, out) is True
            np.testing.assert_array_equal(out, rec.data[300:1400, chans].T)
    flat = write_ni_log(rec, tmp_path / "c.tdms", samples_per_segment=512, interleaved=False)
    _, cruns, _ = _runs(flat)
    assert tdms_rows.row_columns(cruns) is None and tdms_rows.row_columns([cruns[0]]) is None
    assert tdms_rows.row_columns([runs[0], cruns[1]]) is None


@pytest.mark.parametrize("endian", ["<", ">"])
def test_hand_built_interleaved_rows_in_both_byte_orders(tmp_path, monkeypatch, endian):
    """Two float64 channels interleaved, segments of 512 then 1000 rows then 37 rows
    (three runs), big- or little-endian: read_rows equals npTDMS's read_data."""
    x = np.random.default_rng(5).standard_normal((2, 512 * 3 + 1000 * 2 + 37))
    paths = ["/'g'/'a'", "/'g'/'b'"]
    order = ">" if endian == ">" else "<"
    blob, lo = b"", 0
    for k, nv in enumerate([512, 512, 512, 1000, 1000, 37]):
        meta = struct.pack(order + "I", 2)
        for p in paths:
            pb = p.encode()
            meta += struct.pack(order + "I", len(pb)) + pb + struct.pack(order + "IIIQ", 20, 10, 1, nv)
            if k == 0:
                name = b"wf_increment"
                meta += struct.pack(order + "I", 1) + struct.pack(order + "I", len(name)) + name
                meta += struct.pack(order + "Id", 10, 1.0 / FS)
            else:
                meta += struct.pack(order + "I", 0)
        rows = np.ascontiguousarray(x[:, lo:lo + nv].T).astype(order + "f8").tobytes()
        lo += nv
        toc = (1 << 1) | (1 << 3) | (1 << 5) | ((1 << 2) if k == 0 else 0) | ((1 << 6) if endian == ">" else 0)
        blob += (b"TDSm" + struct.pack("<I", toc) + struct.pack(order + "IQQ", 4713, len(meta) + len(rows), len(meta))
                 + meta + rows)
    path = tmp_path / "hand.tdms"
    path.write_bytes(blob)
    idx, runs, starts = _runs(path)
    assert tdms_rows.shared_rows(runs) and len(runs[0]) >= 3
    for plain in (False, True):
        for a, b in ((0, x.shape[1]), (500, 1600), (1535, 1537), (3000, x.shape[1])):
            out, finite = _rows(path, a, b, 2, plain_map=plain)
            np.testing.assert_array_equal(out, x[:, a:b])
    fast = tdms.read(path)
    assert fast.meta is not None and tdms.read_info(path).extra["fast_path"] is True
    monkeypatch.setattr(tdms, "_USE_FAST_PATH", False)
    assert tdms.read(path).data.tobytes() == fast.data.tobytes()
