"""HDF5 read again unchecked: ``verify=False`` reads fletcher32 chunks at their byte offsets
(``os.preadv``, :class:`meshphase.io.hdf5._ChunkReader`), and a :class:`FileSource` checks the
checksums (HDF5's and MCAP's) in its first whole pass only, while the file stays unchanged."""

from __future__ import annotations

import os

import numpy as np
import pytest

from meshphase import io as pio
from meshphase.io import hdf5
from meshphase.errors import DataQualityWarning
from meshphase.io.base import CorruptFileError
from meshphase.recording import Recording
from meshphase.run.stream import FileSource


def _rec(n: int, n_ch: int, dtype=np.float64, seed: int = 0) -> Recording:
    x = np.random.default_rng(seed).normal(size=(n, n_ch)).astype(dtype)
    return Recording(x, 5120.0, [f"sun_g{j}" for j in range(n_ch)])


def _bits(a: np.ndarray) -> np.ndarray:
    return a.view(np.uint64 if a.dtype.itemsize == 8 else np.uint32)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("window", [(0, None), (0, 1), (999, 1001), (1000, 3000), (4321, 5000), (5000, 5000)])
def test_unchecked_read_equals_the_checked_one(tmp_path, dtype, window):
    rec = _rec(5000, 3, dtype)                  # 5 chunks of 1000, the last one whole
    p = pio.write(rec, tmp_path / "r.h5", chunk_samples=1000)
    i0, i1 = window
    a = hdf5.read(p, i0=i0, i1=i1)
    b = hdf5.read(p, i0=i0, i1=i1, verify=False)
    assert a.data.dtype == b.data.dtype == np.dtype(dtype)
    np.testing.assert_array_equal(_bits(np.ascontiguousarray(a.data)), _bits(np.ascontiguousarray(b.data)))


def test_unchecked_read_of_a_partial_last_chunk_and_nan_payloads(tmp_path):
    rec = _rec(2500, 2)
    rec.data[7, 1] = np.float64(np.nan)
    rec.data[2499, 0] = -np.inf
    p = pio.write(rec, tmp_path / "r.h5", chunk_samples=1000)
    with pytest.warns(DataQualityWarning, match="NaN/inf"):
        back = hdf5.read(p, verify=False)
    np.testing.assert_array_equal(_bits(np.ascontiguousarray(back.data)),
                                  _bits(np.ascontiguousarray(rec.data)))


def test_chunk_reader_declines_what_it_cannot_read_raw(tmp_path):
    rec = _rec(3000, 1)
    p = pio.write(rec, tmp_path / "r.h5", chunk_samples=1000)
    import h5py

    with h5py.File(p, "r") as f, hdf5._ChunkReader(p) as cr:
        ds = next(iter(f["channels"].values()))
        out = np.empty(1000)
        assert cr.read(ds, 1000, 1000, 2000, out)
        np.testing.assert_array_equal(out, rec.data[1000:2000, 0])
        assert not cr.read(ds, 0, 0, 10, np.empty(10, dtype=">f8"))     # byte order differs
        assert not cr.read(ds, 0, 0, 10, np.empty(20)[::2])             # not contiguous
        assert cr.read(ds, 2000, 2500, 2500, np.empty(0))               # nothing to read
    cr.close()                                                          # closing twice is fine


def test_chunk_reader_leaves_unallocated_chunks_to_the_library(tmp_path):
    import h5py

    p = tmp_path / "sparse.h5"
    with h5py.File(p, "w") as f:
        ds = f.create_dataset("x", shape=(3000,), dtype="f8", chunks=(1000,), fletcher32=True,
                              fillvalue=2.5)
        ds[2000:3000] = np.arange(1000.0)           # chunks 0 and 1 never written
    with h5py.File(p, "r") as f, hdf5._ChunkReader(p) as cr:
        ds = f["x"]
        assert not cr.read(ds, 0, 0, 1000, np.empty(1000))
        out = np.empty(3000)
        hdf5._read_raw_chunks(ds, out, 0, 3000, cr)     # unwritten chunks: the fill value
        np.testing.assert_array_equal(out, np.r_[np.full(2000, 2.5), np.arange(1000.0)])


def _spy_verify(monkeypatch, module, name: str, default=True) -> list:
    """Replace ``module.name`` by a wrapper that notes the ``verify`` option of every call
    (``default`` when not given); the notes come back as a list."""
    seen = []
    real = getattr(module, name)

    def spy(*a, **kw):
        seen.append(kw.get("verify", default))
        return real(*a, **kw)

    monkeypatch.setattr(module, name, spy)
    return seen


def _passes(src: FileSource, n: int, block: int = 700) -> list:
    return [np.concatenate([d for _, d in src.blocks(block)]) for _ in range(n)]


def test_file_source_checks_the_first_pass_only(tmp_path, monkeypatch):
    rec = _rec(5000, 2)
    p = pio.write(rec, tmp_path / "r.h5", chunk_samples=1000)
    seen = _spy_verify(monkeypatch, hdf5, "iter_blocks")
    src = FileSource(p)
    got = _passes(src, 3)
    assert seen == [True, False, False]
    for g in got:
        np.testing.assert_array_equal(g, rec.data)


def test_file_source_checks_again_after_the_file_changed(tmp_path, monkeypatch):
    rec = _rec(5000, 2)
    p = pio.write(rec, tmp_path / "r.h5", chunk_samples=1000)
    seen = _spy_verify(monkeypatch, hdf5, "iter_blocks")
    src = FileSource(p)
    _passes(src, 1)
    st = p.stat()
    os.utime(p, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000))   # touched between passes
    _passes(src, 2)
    assert seen == [True, True, False]


def test_file_source_names_a_file_changed_during_an_unchecked_pass(tmp_path):
    rec = _rec(5000, 2)
    p = pio.write(rec, tmp_path / "r.h5", chunk_samples=1000)
    src = FileSource(p)
    _passes(src, 1)
    it = src.blocks(1000)
    next(it)
    st = p.stat()
    os.utime(p, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000))
    with pytest.raises(CorruptFileError, match="changed while it was being read"):
        list(it)


def test_file_source_obeys_an_explicit_verify(tmp_path, monkeypatch):
    rec = _rec(3000, 1)
    p = pio.write(rec, tmp_path / "r.h5", chunk_samples=1000)
    seen = _spy_verify(monkeypatch, hdf5, "read")
    src = FileSource(p, start=0.0, stop=2000 / 5120.0, options={"verify": True})
    got = _passes(src, 2, block=1000)
    assert seen and all(seen)                         # a window: one read per block, all checked
    np.testing.assert_array_equal(got[1], rec.data[:2000])


def test_a_damaged_chunk_is_caught_in_the_checked_pass(tmp_path):
    rec = _rec(3000, 1)
    p = pio.write(rec, tmp_path / "r.h5", chunk_samples=1000)
    import h5py

    with h5py.File(p, "r") as f:
        off = next(iter(f["channels"].values())).id.get_chunk_info_by_coord((1000,)).byte_offset
    blob = bytearray(p.read_bytes())
    blob[off + 100] ^= 0x01
    p.write_bytes(bytes(blob))
    src = FileSource(p)
    with pytest.raises(CorruptFileError, match="checksum"):
        _passes(src, 1)
    with pytest.raises(CorruptFileError, match="checksum"):     # not trusted after a failure
        _passes(src, 1)


def test_file_source_checks_an_mcap_file_once_too(tmp_path, monkeypatch):
    from meshphase.io import mcap

    rec = _rec(5000, 2)
    p = pio.write(rec, tmp_path / "r.mcap")
    seen = _spy_verify(monkeypatch, mcap, "iter_blocks")
    src = FileSource(p)
    for g in _passes(src, 3):
        np.testing.assert_array_equal(g, rec.data)
    assert seen == [True, False, False]


def test_file_source_of_a_format_without_checksums_passes_no_verify(tmp_path, monkeypatch):
    from meshphase.io import csv

    rec = _rec(500, 2)
    p = pio.write(rec, tmp_path / "r.csv")
    seen = _spy_verify(monkeypatch, csv, "iter_blocks", default=None)
    _passes(FileSource(p), 2, block=100)
    assert seen == [None, None]
