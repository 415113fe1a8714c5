"""The numba engine of interleaved TDMS rows (meshphase.io.tdms_rows.read_rows, engine="numba"):
bit for bit the numpy engine's samples and finiteness verdicts, in windows across segments,
channel subsets in any order with gaps, float32 output, int16 rows, both byte orders, NaN/inf
anywhere; "auto" takes it only when numba is already loaded, and reading a file does not
load numba by itself."""

from __future__ import annotations

import mmap
import struct
import subprocess
import sys
import warnings

import numpy as np
import pytest

from meshphase.errors import DataQualityWarning
from meshphase.io import tdms, tdms_index, tdms_rows
from meshphase.io.base import RecordingFileError
from meshphase.recording import ChannelSpec, Recording
from meshphase.synthetic.tdms_export import write_ni_log

pytest.importorskip("numba")

FS = 5120.0


def _rec(n, nch, seed=0):
    data = np.random.default_rng(seed).standard_normal((n, nch))
    return Recording(data, FS, [ChannelSpec(f"sun_{j}", kind="sun") for j in range(nch)])


def _both(path, chans, i0, i1, dtype=np.float64, plain_map=False):
    """(numpy engine's (out, finite), numba engine's (out, finite)) of ``chans``."""
    idx = tdms_index.scan(path)
    runs = [idx.runs[p] for p in idx.runs]
    starts = idx.starts(next(iter(idx.runs)))
    got = []
    for engine in ("numpy", "numba"):
        out = np.full((len(chans), i1 - i0), -1.0, dtype=dtype)
        with open(path, "rb") as fh:
            mm = (mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) if plain_map
                  else tdms_index.open_map(fh))
            with mm:
                finite = tdms_rows.read_rows(mm, [runs[c] for c in chans], starts, i0, i1, out, engine=engine)
        got.append((out, finite))
    return got


def _same(got):
    (a, fa), (b, fb) = got
    assert a.tobytes() == b.tobytes() and fa is fb
    return a, fa


@pytest.mark.parametrize("spc", [512, 1000, 7, 333])
@pytest.mark.parametrize("plain_map", [False, True])
def test_numba_engine_equals_numpy_engine_in_windows_and_subsets(tmp_path, spc, plain_map):
    n, nch = 5 * spc + 17, 5               # a shorter last segment: a second run
    rec = _rec(n, nch)
    path = write_ni_log(rec, tmp_path / "x.tdms", samples_per_segment=spc, interleaved=True)
    windows = ((0, n), (1, n - 1), (spc - 1, spc + 1), (spc, 3 * spc), (2 * spc + 3, n), (n - 1, n))
    for chans in ([0, 1, 2, 3, 4], [0, 1, 2], [3, 1], [4, 0, 2], [2], [4, 3, 2, 1, 0], [1, 4]):
        for a, b in windows:
            out, finite = _same(_both(path, chans, a, b, plain_map=plain_map))
            np.testing.assert_array_equal(out, rec.data[a:b, chans].T)
            assert finite is True


def test_numba_engine_keeps_every_bit_and_finds_every_nan_and_inf(tmp_path):
    rec = _rec(3 * 512 + 40, 4, seed=2)
    bits = rec.data.view(np.uint64)
    bits[5, 0] = 0x7FF8_0000_0000_0ABC          # a NaN with a payload
    rec.data[700, 3] = -0.0
    rec.data[900, 1] = 5e-324                   # subnormal
    path = write_ni_log(rec, tmp_path / "ok.tdms", samples_per_segment=512, interleaved=True)
    out, finite = _same(_both(path, [0, 1, 2, 3], 0, rec.n_samples))
    assert out.tobytes() == np.ascontiguousarray(rec.data.T).tobytes() and finite is False
    out, finite = _same(_both(path, [1, 3], 0, rec.n_samples))      # the NaN's channel left out
    assert finite is True
    for where, value in (((0, 2), np.inf), ((1535, 3), -np.inf), ((1575, 0), np.nan), ((513, 1), np.nan)):
        r = _rec(3 * 512 + 40, 4, seed=3)
        r.data[where] = value
        p = write_ni_log(r, tmp_path / f"bad{where[0]}.tdms", samples_per_segment=512, interleaved=True)
        assert _same(_both(p, [0, 1, 2, 3], 0, r.n_samples))[1] is False
        assert _same(_both(p, [where[1]], where[0], where[0] + 1))[1] is False
        lo, hi = (0, where[0]) if where[0] else (1, r.n_samples)
        assert _same(_both(p, [0, 1, 2, 3], lo, hi))[1] is True      # the window misses it


def test_numba_engine_float32_output_and_overflow_to_inf(tmp_path):
    rec = _rec(2100, 3)
    rec.data[1000, 1] = 1e300                  # finite as float64, inf as float32
    path = write_ni_log(rec, tmp_path / "x.tdms", samples_per_segment=1000, interleaved=True)
    out, finite = _same(_both(path, [0, 1, 2], 5, 2090, dtype=np.float32))
    with np.errstate(over="ignore"):
        np.testing.assert_array_equal(out, rec.data[5:2090].T.astype(np.float32))
    assert finite is False and np.isinf(out[1, 995])
    out, finite = _same(_both(path, [2, 0], 5, 2090, dtype=np.float32))
    assert finite is True


def _hand_rows(path, x, order, code, fmt):
    """Channels of ``x`` interleaved in segments of 512, 512, 1000 and 37 rows (hand-built,
    type ``code``, byte order ``order``, object list in the first segment only)."""
    blob, lo = b"", 0
    for k, nv in enumerate([512, 512, 1000, 37]):
        meta = struct.pack(order + "I", len(x))
        for j in range(len(x)):
            pb = f"/'g'/'c{j}'".encode()
            meta += struct.pack(order + "I", len(pb)) + pb + struct.pack(order + "IIIQ", 20, code, 1, nv)
            meta += struct.pack(order + "I", 0)
        rows = np.ascontiguousarray(x[:, lo:lo + nv].T).astype(order + fmt).tobytes()
        lo += nv
        toc = (1 << 1) | (1 << 3) | (1 << 5) | ((1 << 2) if k == 0 else 0) | ((1 << 6) if order == ">" else 0)
        blob += (b"TDSm" + struct.pack("<I", toc) + struct.pack(order + "IQQ", 4713, len(meta) + len(rows),
                                                                 len(meta)) + meta + rows)
    path.write_bytes(blob)
    return path


@pytest.mark.parametrize("order", ["<", ">"])
@pytest.mark.parametrize("code, fmt", [(10, "f8"), (9, "f4"), (2, "i2"), (3, "i4")])
def test_numba_engine_on_hand_built_rows_of_every_type_and_byte_order(tmp_path, order, code, fmt):
    rng = np.random.default_rng(11)
    x = (rng.integers(-30000, 30000, size=(3, 2061)) if fmt[0] == "i"
         else rng.standard_normal((3, 2061))).astype(fmt)
    path = _hand_rows(tmp_path / "h.tdms", x, order, code, fmt)   # big-endian: the numpy engine
    for chans, a, b in (([0, 1, 2], 0, 2061), ([2, 0], 500, 1600), ([1], 1023, 1025), ([0, 2], 2030, 2061)):
        out, finite = _same(_both(path, chans, a, b))
        np.testing.assert_array_equal(out, x[chans, a:b].astype(np.float64))
        assert finite is True


def test_numba_engine_empty_window_and_bad_input(tmp_path):
    rec = _rec(2048, 2)
    path = write_ni_log(rec, tmp_path / "x.tdms", samples_per_segment=512, interleaved=True)
    for i in (0, 600, 2048):
        out, finite = _same(_both(path, [0, 1], i, i))
        assert out.shape == (2, 0) and finite is True
    idx = tdms_index.scan(path)
    runs = [idx.runs[p] for p in idx.runs]
    starts = idx.starts(next(iter(idx.runs)))
    cut = tmp_path / "cut.tdms"
    cut.write_bytes(path.read_bytes()[:-3000])   # the rows end inside the last segment
    with open(cut, "rb") as fh, tdms_index.open_map(fh) as mm, pytest.raises(ValueError, match="file ends"):
        tdms_rows.read_rows(mm, runs, starts, 0, 2048, np.empty((2, 2048)), engine="numba")
    with open(path, "rb") as fh, tdms_index.open_map(fh) as mm:
        for bad in ("fast", None, 1):
            with pytest.raises(ValueError, match="engine must be one of"):
                tdms_rows.read_rows(mm, runs, starts, 0, 10, np.empty((2, 10)), engine=bad)
        with pytest.raises(ValueError, match="expected"):
            tdms_rows.read_rows(mm, runs, starts, 0, 2048, np.empty((2, 100)), engine="numba")
    with pytest.raises(ValueError, match="engine must be one of"):
        with tdms.reading_path(rows_engine="fast"):
            pass


def test_rows_engine_auto_takes_numba_only_when_loaded(monkeypatch):
    import numba  # noqa: F401  (loaded: auto takes it)

    assert tdms_rows.rows_engine() == "numba" and tdms_rows.rows_engine("numpy") == "numpy"
    monkeypatch.delitem(sys.modules, "numba")
    assert tdms_rows.rows_engine("auto") == "numpy" and tdms_rows.rows_engine("numba") == "numba"
    monkeypatch.setattr(tdms_rows, "HAVE_NUMBA", False)
    with pytest.raises(ValueError, match="numba is not importable"):
        tdms_rows.rows_engine("numba")
    assert tdms_rows.rows_engine("auto") == "numpy"
    assert tdms_rows.warmup() == {"engine": "numpy", "seconds": 0.0}


def test_warmup_loads_the_kernel():
    w = tdms_rows.warmup()
    assert w["engine"] == "numba" and w["seconds"] >= 0.0


def test_tdms_read_is_the_same_on_both_engines_and_warns_the_same(tmp_path):
    rec = _rec(4000, 3, seed=4)
    rec.data[3000, 2] = np.nan
    path = write_ni_log(rec, tmp_path / "x.tdms", samples_per_segment=1000, interleaved=True)
    got = {}
    for engine in ("numpy", "numba"):
        with tdms.reading_path(rows_engine=engine), pytest.warns(DataQualityWarning, match="first at sample 3000"):
            got[engine] = tdms.read(path)
        with tdms.reading_path(rows_engine=engine), warnings.catch_warnings():
            warnings.simplefilter("error", DataQualityWarning)
            tdms.read(path, None, 0, 2999)
            assert sum(b.n_samples for b in tdms.iter_blocks(path, 700, 0, ["sun_0", "sun_1"])) == 4000
    assert got["numpy"].data.tobytes() == got["numba"].data.tobytes()
    assert tdms._ROWS_ENGINE == "auto"                 # reading_path put it back


def test_reading_a_tdms_file_does_not_load_numba(tmp_path):
    rec = _rec(3000, 3)
    path = write_ni_log(rec, tmp_path / "x.tdms", samples_per_segment=512, interleaved=True)
    code = ("import sys\nfrom meshphase.io import read\nr = read(sys.argv[1])\n"
            "assert r.n_samples == 3000\nprint('numba' in sys.modules)")
    res = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "False"


def test_scan_through_the_callers_map_equals_its_own(tmp_path):
    rec = _rec(3000, 3)
    path = write_ni_log(rec, tmp_path / "x.tdms", samples_per_segment=512, interleaved=True)
    own = tdms_index.scan(path)
    with open(path, "rb") as fh, tdms_index.open_map(fh) as mm:
        given = tdms_index.scan(path, mm)
    assert given.digest == own.digest and given.runs == own.runs and given.n_segments == own.n_segments
    empty = tmp_path / "empty.tdms"
    empty.write_bytes(b"")
    for reader in (tdms.read, lambda p: list(tdms.iter_blocks(p, 100, 0)), tdms.read_info):
        with pytest.raises(RecordingFileError, match="file is empty"):
            reader(empty)
