"""Interleaved int16 rows (meshphase.io.tdms_rows.read_rows) into float64 output, through
``os.preadv`` and through a plain memory map: equal to npTDMS's unscaled read_data bit for
bit, for segments of 333 and 1000 rows with a short last one, and channel subsets."""

from __future__ import annotations

import mmap
import struct

import numpy as np
import pytest
from nptdms import TdmsFile

from meshphase.io import tdms_index, tdms_rows

NAMES = ("a", "b")
SIZES = (333, 333, 333, 1000, 41)


def _int16_rows(path, x):
    """Two int16 channels of group 'g' interleaved, segments of ``SIZES`` rows (hand-built,
    little-endian, the object list written in the first segment only)."""
    blob, lo = b"", 0
    for k, nv in enumerate(SIZES):
        meta = struct.pack("<I", 2)
        for name in NAMES:
            pb = f"/'g'/'{name}'".encode()
            meta += struct.pack("<I", len(pb)) + pb + struct.pack("<IIIQ", 20, 2, 1, nv)   # tdsTypeI16
            meta += struct.pack("<I", 0)
        rows = np.ascontiguousarray(x[:, lo:lo + nv].T).astype("<i2").tobytes()
        lo += nv
        toc = (1 << 1) | (1 << 3) | (1 << 5) | ((1 << 2) if k == 0 else 0)
        blob += b"TDSm" + struct.pack("<IIQQ", toc, 4713, len(meta) + len(rows), len(meta)) + meta + rows
    path.write_bytes(blob)


def _read(path, chans, i0, i1, plain_map):
    idx = tdms_index.scan(path)
    runs = [idx.runs[p] for p in idx.runs]
    starts = idx.starts(next(iter(idx.runs)))
    out = np.full((len(chans), i1 - i0), -1.0)
    with open(path, "rb") as fh:
        mm = (mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) if plain_map
              else tdms_index.open_map(fh))
        with mm:
            finite = tdms_rows.read_rows(mm, [runs[c] for c in chans], starts, i0, i1, out)
    return out, finite


@pytest.mark.parametrize("plain_map", [False, True])
def test_int16_rows_equal_nptdms_unscaled_read_data(tmp_path, plain_map):
    x = np.random.default_rng(9).integers(-32768, 32767, size=(2, sum(SIZES)), dtype=np.int16)
    path = tmp_path / "i16.tdms"
    _int16_rows(path, x)
    n = sum(SIZES)
    with TdmsFile.open(path) as f:
        theirs = np.asarray([f["g"][name].read_data(scaled=False) for name in NAMES], dtype=np.float64)
    out, finite = _read(path, [0, 1], 0, n, plain_map)
    assert out.tobytes() == theirs.tobytes() and finite is True
    for chans, a, b in (([1, 0], 300, 1500), ([1], 998, 1002), ([0, 1], n - 41, n), ([0, 1], 5, 5)):
        part, finite = _read(path, chans, a, b, plain_map)
        np.testing.assert_array_equal(part, x[chans, a:b].astype(np.float64))
        assert finite is True
