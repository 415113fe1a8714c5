"""Integrity of stored recordings: byte flips and truncation give ONE clean error.

Every damaged file must raise :class:`CorruptFileError` (a RecordingFileError, so a
ValueError) naming the file, the position and the problem; never another exception type,
never a hang (pytest-timeout), never silently changed samples.

Where the flips go, and why:

* MCAP: inside the records of a chunk (messages: record headers, payload headers, samples),
  the region the chunk CRC32 covers, and, separately, anywhere in the file but the 8-byte
  leading magic (which makes it "not an MCAP file"). Our writer leaves no padding: every
  byte is covered by a chunk CRC, the data-section CRC or the summary CRC.
* HDF5: inside the stored bytes of a sample chunk (samples and its 4-byte fletcher32
  checksum), found through h5py's chunk index; and the value of a root attribute (covered by
  the object-header checksum of the 1.10 file format). Free space and unused bytes of an
  HDF5 file are not read and may legitimately pass, so the test does not flip them.
* CSV and TDMS carry no checksum: their tests are truncation and malformed rows.
"""

from __future__ import annotations

import struct

import h5py
import numpy as np
import pytest
from mcap.reader import make_reader

import meshphase.io as pio
from meshphase.io import CorruptFileError, RecordingFileError
from meshphase.io import csv as mcsv
from meshphase.io import mcap as m
from meshphase.io.mcap import header as mheader
from meshphase.recording import ChannelSpec, Recording

pytestmark = pytest.mark.timeout(120)

N_SEEDS = 20  # default suite; the slow variants run more


def _rec(n=20_000, n_channels=4, dtype=np.float64, seed=0):
    rng = np.random.default_rng(seed)
    data = (rng.standard_normal((n, n_channels)) * 1e-5).astype(dtype)
    specs = [ChannelSpec(name=f"sun_{j}", kind="sun", units="m/m") for j in range(n_channels)]
    return Recording(data, 5120.0, specs)


def _bits(a):
    a = np.ascontiguousarray(a)
    return a.view(np.uint64 if a.dtype == np.float64 else np.uint32)


def _flip(path, offset, rng):
    with open(path, "r+b") as fh:
        fh.seek(offset)
        b = fh.read(1)[0]
        fh.seek(offset)
        fh.write(bytes([b ^ int(rng.integers(1, 256))]))


# ---------------------------------------------------------------------------------- MCAP
def _chunk_records(path):
    """(chunk number, start, end) of the uncompressed records of every chunk (file bytes)."""
    with open(path, "rb") as fh:
        summary = make_reader(fh).get_summary()
        out = []
        for k, ci in enumerate(summary.chunk_indexes):
            fh.seek(ci.chunk_start_offset + 9 + 28)
            (clen,) = struct.unpack("<I", fh.read(4))
            start = ci.chunk_start_offset + 9 + 32 + clen + 8
            out.append((k, start, ci.chunk_start_offset + ci.chunk_length))
    return out


@pytest.fixture(scope="module")
def mcap_blob(tmp_path_factory):
    rec = _rec()
    p = tmp_path_factory.mktemp("mcap") / "r.mcap"
    pio.write(rec, p, block=1000, chunk_size=40_000)
    return rec, p.read_bytes(), _chunk_records(p)


def _mcap_chunk_flip(mcap_blob, tmp_path, seed):
    rec, blob, chunks = mcap_blob
    rng = np.random.default_rng(seed)
    k, a, b = chunks[int(rng.integers(len(chunks)))]
    p = tmp_path / f"flip{seed}.mcap"
    p.write_bytes(blob)
    off = int(rng.integers(a, b))
    _flip(p, off, rng)
    with pytest.raises(CorruptFileError, match=rf"flip{seed}\.mcap: chunk {k} at byte \d+: CRC32 of its \d+ "
                                               rf"uncompressed record bytes is 0x[0-9a-f]{{8}}, the chunk records"):
        pio.read(p)
    with pytest.raises(CorruptFileError, match=rf"chunk {k} at byte"):
        for _ in pio.iter_blocks(p, 0.5):
            pass
    return rec, p


@pytest.mark.parametrize("seed", range(N_SEEDS))
def test_mcap_flip_in_chunk_records_is_detected(mcap_blob, tmp_path, seed):
    _mcap_chunk_flip(mcap_blob, tmp_path, seed)


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(N_SEEDS, 400))
def test_mcap_flip_in_chunk_records_is_detected_many(mcap_blob, tmp_path, seed):
    _mcap_chunk_flip(mcap_blob, tmp_path, seed)


def test_mcap_flip_reads_changed_samples_without_verify(mcap_blob, tmp_path):
    """The check is what catches it: with verify=False the same file reads (changed)."""
    rec, blob, chunks = mcap_blob
    k, a, b = chunks[1]
    p = tmp_path / "f.mcap"
    p.write_bytes(blob)
    _flip(p, b - 3, np.random.default_rng(0))  # a sample byte of the chunk's last message
    with pytest.raises(CorruptFileError, match="CRC32"):
        pio.read(p)
    back = pio.read(p, verify=False)
    assert np.count_nonzero(_bits(back.data) != _bits(rec.data)) == 1


def _mcap_anywhere(tmp_path, seed, compression):
    rec = _rec(6000, 3)
    p = tmp_path / f"any{seed}.mcap"
    pio.write(rec, p, block=1000, chunk_size=20_000, compression=compression)
    rng = np.random.default_rng(seed)
    off = int(rng.integers(8, p.stat().st_size))  # anywhere but the leading magic
    _flip(p, off, rng)
    with pytest.raises(CorruptFileError, match=rf"any{seed}\.mcap: "):
        pio.read(p, format="mcap")


@pytest.mark.parametrize("compression", ["none", "lz4", "zstd"])
@pytest.mark.parametrize("seed", range(N_SEEDS))
def test_mcap_flip_anywhere_is_detected(tmp_path, seed, compression):
    _mcap_anywhere(tmp_path, seed, compression)


@pytest.mark.slow
@pytest.mark.parametrize("compression", ["none", "zstd"])
@pytest.mark.parametrize("seed", range(N_SEEDS, 300))
def test_mcap_flip_anywhere_is_detected_many(tmp_path, seed, compression):
    _mcap_anywhere(tmp_path, seed, compression)


def test_mcap_summary_flip_is_named(mcap_blob, tmp_path):
    rec, blob, chunks = mcap_blob
    p = tmp_path / "s.mcap"
    p.write_bytes(blob)
    _flip(p, len(blob) - 60, np.random.default_rng(1))  # in the summary section
    with pytest.raises(CorruptFileError, match=r"\(summary section and footer\): summary CRC32 is"):
        pio.read_info(p)


def test_mcap_metadata_flip_caught_by_data_section_crc(tmp_path):
    """A digit of fs in the Metadata record: outside every chunk, caught by the DataEnd CRC."""
    rec = _rec(6000, 2)
    p = tmp_path / "md.mcap"
    pio.write(rec, p, block=1000)
    blob = bytearray(p.read_bytes())
    i = blob.find(b"5120.0")
    assert i > 0
    blob[i + 1] = ord("3")  # 5320.0 Hz: a plausible, wrong rate
    p.write_bytes(bytes(blob))
    with pytest.raises(CorruptFileError, match=r"bytes \[0, \d+\) \(data section\): data-section CRC32"):
        pio.read_info(p)
    with pytest.raises(RecordingFileError):  # without the CRC, the channel metadata disagree
        pio.read(p, verify=False)


def test_mcap_verify_is_checked_once_per_file(tmp_path, monkeypatch):
    rec = _rec(6000, 2)
    p = tmp_path / "once.mcap"
    pio.write(rec, p, block=1000)
    calls = []
    real = mheader.check_data_crc
    monkeypatch.setattr(mheader, "check_data_crc", lambda *a: calls.append(1) or real(*a))
    for _ in range(3):
        assert pio.read(p) == rec
    assert len(calls) == 1


@pytest.mark.parametrize("bad", [None, 1, "yes"])
def test_verify_must_be_bool(tmp_path, bad):
    rec = _rec(100, 1)
    for suffix in ("mcap", "h5", "csv"):
        p = pio.write(rec, tmp_path / f"v.{suffix}")
        with pytest.raises(TypeError, match="verify must be a bool"):
            pio.read(p, verify=bad)


def test_crc32_combine_matches_zlib():
    import zlib

    rng = np.random.default_rng(3)
    for n1, n2 in [(0, 0), (0, 5), (5, 0), (1, 1), (100, 1 << 16), (12345, 777)]:
        a = rng.integers(0, 256, n1, dtype=np.uint8).tobytes()
        b = rng.integers(0, 256, n2, dtype=np.uint8).tobytes()
        assert m.crc32_combine(zlib.crc32(a), zlib.crc32(b), n2) == zlib.crc32(a + b)
    with pytest.raises(ValueError, match="len2 must be >= 0"):
        m.crc32_combine(0, 0, -1)


def test_crc_check_takes_precedence_over_parse_errors(mcap_blob, tmp_path):
    """A flip in a message header makes the chunk unparseable; the error still says CRC."""
    rec, blob, chunks = mcap_blob
    k, a, b = chunks[2]
    p = tmp_path / "h.mcap"
    p.write_bytes(blob)
    with open(p, "r+b") as fh:  # the opcode of the chunk's first message record
        fh.seek(a)
        fh.write(b"\x77")
    with pytest.raises(CorruptFileError, match=rf"chunk {k} at byte \d+: CRC32"):
        pio.read(p)


# ---------------------------------------------------------------------------------- HDF5
@pytest.fixture(scope="module")
def h5_blob(tmp_path_factory):
    rec = _rec(50_000, 3)
    p = tmp_path_factory.mktemp("h5") / "r.h5"
    pio.write(rec, p, chunk_samples=8192)
    chunks = []
    with h5py.File(p, "r") as f:
        for name in rec.names:
            ds = f["channels"][name]
            assert ds.fletcher32 and ds.chunks == (8192,)
            for i in range(ds.id.get_num_chunks()):
                info = ds.id.get_chunk_info(i)
                chunks.append((name, info.chunk_offset[0], info.byte_offset, info.size))
    return rec, p.read_bytes(), chunks


def _h5_flip(h5_blob, tmp_path, seed):
    rec, blob, chunks = h5_blob
    rng = np.random.default_rng(seed)
    name, first, off, size = chunks[int(rng.integers(len(chunks)))]
    p = tmp_path / f"flip{seed}.h5"
    p.write_bytes(blob)
    _flip(p, off + int(rng.integers(size)), rng)
    last = min(first + 8192, rec.n_samples)
    with pytest.raises(CorruptFileError,
                       match=rf"flip{seed}\.h5: dataset /channels/{name} \(channel '{name}'\), samples "
                             rf"\[{first}, {last}\) \(chunk {first // 8192} at byte {off}\): fletcher32 "
                             rf"checksum mismatch"):
        pio.read(p)
    return rec, p, name, first, last


@pytest.mark.parametrize("seed", range(N_SEEDS))
def test_hdf5_flip_in_sample_chunk_is_detected(h5_blob, tmp_path, seed):
    _h5_flip(h5_blob, tmp_path, seed)


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(N_SEEDS, 400))
def test_hdf5_flip_in_sample_chunk_is_detected_many(h5_blob, tmp_path, seed):
    _h5_flip(h5_blob, tmp_path, seed)


def test_hdf5_verify_false_salvages_the_other_samples(h5_blob, tmp_path):
    rec, p, name, first, last = _h5_flip(h5_blob, tmp_path, 7)
    back = pio.read(p, verify=False)
    j = rec.names.index(name)
    diff = _bits(back.data) != _bits(rec.data)
    assert diff.sum() <= 1  # the flipped sample (none when the flip hit the checksum bytes)
    assert not diff[:first].any() and not diff[last:].any() and not np.delete(diff, j, axis=1).any()
    # a window that avoids the damaged chunk reads with verification on
    other = 0 if first else 8192
    assert pio.read(p, start=other / rec.fs, stop=(other + 100) / rec.fs) == \
        rec.slice_samples(other, other + 100)


def test_hdf5_flip_in_an_attribute_is_detected(tmp_path):
    """fs = 5120.0 with one mantissa bit flipped would read 5120.000001 Hz without checksums."""
    rec = _rec(1000, 2)
    p = pio.write(rec, tmp_path / "a.h5")
    blob = bytearray(p.read_bytes())
    i = blob.find(np.float64(5120.0).tobytes())
    assert i > 0
    blob[i + 2] ^= 0x10
    p.write_bytes(bytes(blob))
    with pytest.raises(CorruptFileError, match=r"a\.h5: .*checksum"):
        pio.read(p)


def test_hdf5_without_fletcher32_still_reads(tmp_path):
    rec = _rec(1000, 2)
    p = pio.write(rec, tmp_path / "nf.h5", fletcher32=False)
    assert pio.read_info(p).extra["fletcher32"] is False
    assert pio.read(p) == rec and pio.read(p, verify=False) == rec
    with pytest.raises(TypeError, match="fletcher32 must be a bool"):
        pio.write(rec, tmp_path / "x.h5", fletcher32="yes")


@pytest.mark.parametrize("options", [{}, {"compression": "gzip"}, {"compression": "lzf"},
                                     {"chunk_samples": 1000}])
def test_hdf5_fletcher32_composes_with_chunking_and_compression(tmp_path, options, make_recording):
    rec = make_recording(5000, 3)
    p = pio.write(rec, tmp_path / "c.h5", **options)
    info = pio.read_info(p)
    assert info.extra["fletcher32"] is True
    assert pio.read(p) == rec
    assert pio.read(p, verify=False) == rec  # compressed chunks stay checked; same samples
    assert list(pio.iter_blocks(p, 0.1)) == list(rec.blocks(0.1))


# ---------------------------------------------------------------------------------- truncation
def _files(tmp_path, build_recording, write_tdms):
    rec = build_recording(3000, 3)
    out = {}
    for fmt, suffix in [("hdf5", "h5"), ("mcap", "mcap"), ("csv", "csv")]:
        out[fmt] = pio.write(rec, tmp_path / f"full.{suffix}")
    # as meshphase.synthetic.tdms_export writes them: wf_samples = the total, meshphase_kind set
    props = {"wf_increment": 1.0 / rec.fs, "wf_start_offset": 0.0, "wf_samples": 3000, "meshphase_kind": "sun"}
    out["tdms"] = write_tdms(tmp_path / "full.tdms", [("meshphase", name, rec.data[:, j], dict(props))
                                                      for j, name in enumerate(rec.names)], segments=4)
    return out


@pytest.fixture(scope="module")
def originals(tmp_path_factory, make_recording, tdms_tools):
    return _files(tmp_path_factory.mktemp("orig"), make_recording, tdms_tools[0])


def _cuts(size, n):
    return sorted(set(np.linspace(1, size - 1, n).astype(int).tolist()))


def _check_cut(path, cut, tmp_path, fmt):
    blob = path.read_bytes()
    q = tmp_path / f"cut{path.suffix}"
    q.write_bytes(blob[:cut])
    with pytest.raises(CorruptFileError) as err:
        rec = pio.read(q, format=fmt)
        list(pio.iter_blocks(q, 0.05, format=fmt))
        pytest.fail(f"{fmt} cut at byte {cut} of {len(blob)} was accepted ({rec.n_samples} samples)")
    assert str(err.value).startswith(f"{q}: ") and err.value.position


@pytest.mark.parametrize("fmt", ["hdf5", "mcap", "csv", "tdms"])
def test_truncation_anywhere_gives_corrupt_file_error(originals, tmp_path, fmt):
    path = originals[fmt]
    for cut in _cuts(path.stat().st_size, 60):
        _check_cut(path, cut, tmp_path, fmt)


@pytest.mark.slow
@pytest.mark.parametrize("fmt", ["hdf5", "mcap", "csv", "tdms"])
def test_truncation_anywhere_gives_corrupt_file_error_many(originals, tmp_path, fmt):
    path = originals[fmt]
    for cut in _cuts(path.stat().st_size, 1500):
        _check_cut(path, cut, tmp_path, fmt)


def test_tdms_cut_at_a_segment_boundary_is_caught_by_wf_samples(originals, tmp_path):
    blob = originals["tdms"].read_bytes()
    last = blob.rfind(b"TDSm")  # the start of the last segment: a clean cut
    q = tmp_path / "seg.tdms"
    q.write_bytes(blob[:last])
    with pytest.raises(CorruptFileError, match=r"seg\.tdms: channel '\w+', end of file at byte \d+: truncated: "
                                               r"2250 samples, wf_samples says 3000"):
        pio.read(q)


# ---------------------------------------------------------------------------------- CSV rows
def _plain(path, text):
    path.write_bytes(text.encode())
    return path


def test_csv_number_cut_mid_token_is_detected(tmp_path):
    text = "time [s],a [m/m]\n0,1.5e-11\n0.5,-7.85e-11\n"
    p = _plain(tmp_path / "cut.csv", text[:-5])  # "...,-7.85"
    with pytest.raises(CorruptFileError, match=r"cut\.csv: line 3 \(byte 27\): truncated: the last line does not "
                                               r"end with a newline: the file was cut mid-row \(it ends with "
                                               r"'0\.5,-7\.85'"):
        pio.read(p)
    assert mcsv.read(_plain(tmp_path / "ok.csv", text)).data[-1, 0] == -7.85e-11


def test_csv_row_with_a_missing_field_is_detected(tmp_path):
    p = _plain(tmp_path / "m.csv", "time [s],a [V],b [V]\n0,1,2\n1,3\n2,4,5\n")
    with pytest.raises(CorruptFileError, match=r"line 3 \(byte 27\): 2 field\(s\), the header has 3"):
        pio.read(p)


def test_csv_own_file_row_with_a_missing_field_is_detected(tmp_path, make_recording):
    rec = make_recording(3000, 3)
    p = pio.write(rec, tmp_path / "o.csv")
    lines = p.read_bytes().split(b"\n")
    lines[1500] = lines[1500].rsplit(b",", 1)[0]  # drop the last field of data row 1498
    p.write_bytes(b"\n".join(lines))
    with pytest.raises(CorruptFileError, match=r"o\.csv: line 1501 \(byte \d+\): 3 field\(s\), the header has 4"):
        pio.read(p, channels=["ring_1"], start=0.0, stop=0.01)  # even a window elsewhere


def test_csv_crlf_and_trailing_blank_lines_are_fine(tmp_path):
    p = _plain(tmp_path / "w.csv", "time [s],a [V]\r\n0,1\r\n1,2\r\n2,3\r\n\r\n\n")
    assert pio.read(p).data[:, 0].tolist() == [1.0, 2.0, 3.0]


def test_csv_scan_spans_blocks(tmp_path, monkeypatch):
    """Lines, blank runs and errors across the scan's block boundaries."""
    monkeypatch.setattr(mcsv, "_SCAN_BLOCK", 7)
    p = _plain(tmp_path / "b.csv", "time [s],a [V]\n" + "".join(f"{i},{i * 2}\n" for i in range(50)) + "\n\n")
    assert pio.read(p).data[:, 0].tolist() == [2.0 * i for i in range(50)]
    p = _plain(tmp_path / "c.csv", "time [s],a [V]\n" + "".join(f"{i},{i * 2}\n" for i in range(5)) + "\n\n5,10\n")
    with pytest.raises(CorruptFileError, match=r"line 7 \(byte \d+\): blank line inside the data rows"):
        pio.read(p)
    p = _plain(tmp_path / "d.csv", "time [s],a [V]\n" + "".join(f"{i},{i * 2}\n" for i in range(30)) + "30,6,0\n")
    with pytest.raises(CorruptFileError, match=r"line 32 \(byte \d+\): 3 field\(s\)"):
        pio.read(p)
