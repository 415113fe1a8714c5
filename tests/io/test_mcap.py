"""MCAP reader/writer: lossless round trip, windows through the index, bad input.

Everything here is checked against the Recording that was written (no stored reference
files); the independent TypeScript reader is exercised in tests/interop/.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from mcap.writer import CompressionType, IndexType, Writer

import meshphase.io as pio
from meshphase.io import CorruptFileError, RecordingFileError
from meshphase.io import mcap as m
from meshphase.io.mcap import layout as mlayout
from meshphase.io.mcap import reader as mreader
from meshphase.io.mcap import writer as mwriter
from meshphase.recording import ChannelSpec, Recording


# ---------------------------------------------------------------------------------- helpers
def _specs():
    return [
        ChannelSpec("sun_1", kind="sun", units="m/m", gain=1.0, tooth=3, face_position=None,
                    description="sun tooth root, tooth 3"),
        ChannelSpec("ring_2", kind="ring", units="V", gain=2.5e-4, gear="ring", tooth=0,
                    face_position=-0.0125, description=""),
        ChannelSpec("fw_a", kind="facewidth", units="m/m", gear="planet", face_position=0.01),
        ChannelSpec("tacho", kind="tacho", units="V"),
    ]


def _recording(n=12_345, dtype=np.float64, t0=0.0, fs=5120.0, seed=0) -> Recording:
    rng = np.random.default_rng(seed)
    data = (rng.standard_normal((n, 4)) * 1e-6).astype(dtype)
    if n > 20:
        data[3, 0] = np.nan
        data[5, 1] = np.inf
        data[7, 2] = -np.inf
        data[9, 3] = -0.0
        # a NaN with a payload: must come back bit-exact
        if dtype == np.float64:
            data[11, 0] = np.array([0x7FF80000DEADBEEF], dtype=np.uint64).view(np.float64)[0]
        else:
            data[11, 0] = np.array([0x7FC0BEEF], dtype=np.uint32).view(np.float32)[0]
    return Recording(data, fs, _specs(), t0=t0, start_datetime="2024-05-06T07:08:09.123456+00:00",
                     meta={"gearset": {"z_sun": 21, "z_ring": 69}, "module_m": 0.002, "note": "rig 2"},
                     history=[{"step": "acquire", "time": "2024-05-06T07:08:09+00:00", "rate": 5120}])


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a).view(np.uint32 if a.dtype == np.float32 else np.uint64)


def _write(rec, path, **opts) -> Path:
    return pio.write(rec, path, format="mcap", **opts)


def _summary(path):
    with open(path, "rb") as fh:
        return make_reader(fh).get_summary()


def _chunk_of(path, channel_name, which=0):
    """(offset, length) of the ``which``-th chunk holding channel ``channel_name``."""
    s = _summary(path)
    cid = next(c.id for c in s.channels.values() if c.topic == channel_name)
    chunks = sorted((ci for ci in s.chunk_indexes if cid in ci.message_index_offsets),
                    key=lambda ci: ci.message_start_time)
    ci = chunks[which]
    return ci.chunk_start_offset, ci.chunk_length


def _corrupt_chunk(path, offset):
    with open(path, "r+b") as fh:
        fh.seek(offset)
        fh.write(b"\xff")


def _custom_file(path, rec, *, block=100, drop=None, duplicate=None, recording_md=None,
                 channel_md=None, payload_edit=None):
    """Write an MCAP file the way meshphase does, with one thing changed (tests only)."""
    origin = mlayout.origin_ns(rec.t0)
    rmd = mwriter._recording_metadata(rec, block, "none", origin)
    if recording_md:
        rmd = recording_md(rmd)
    code = mlayout.DTYPE_CODES[rec.data.dtype.name]
    with open(path, "wb") as fh:
        w = Writer(fh, compression=CompressionType.NONE)
        w.start(profile="meshphase", library="test")
        sid = w.register_schema(m.SCHEMA_NAME, m.SCHEMA_ENCODING, json.dumps(m.LAYOUT).encode())
        cids = []
        for i, s in enumerate(rec.channels):
            cmd = mwriter._channel_metadata(s, i, rec.fs, rec.data.dtype.name)
            if channel_md:
                cmd = channel_md(i, cmd)
            cids.append(w.register_channel(s.name, m.MESSAGE_ENCODING, sid, cmd))
        w.add_metadata(m.RECORDING_METADATA, rmd)
        for j, cid in enumerate(cids):
            col = np.ascontiguousarray(rec.data[:, j]).astype(rec.data.dtype.newbyteorder("<"))
            for k, a in enumerate(range(0, rec.n_samples, block)):
                if drop == (j, k):
                    continue
                b = min(rec.n_samples, a + block)
                payload = mlayout.HEADER.pack(a, b - a, 1, code, 1) + col[a:b].tobytes()
                if payload_edit:
                    payload = payload_edit(j, k, payload)
                t = m.log_time_ns(a, rec.fs, origin)
                w.add_message(cid, t, payload, t)
                if duplicate == (j, k):
                    w.add_message(cid, t, payload, t)
        w.finish()
    return Path(path)


# ---------------------------------------------------------------------------------- sniffing
def test_sniff_magic():
    assert m.sniff(m.MAGIC + b"\x01\x02")
    assert m.sniff(b"\x89MCAP0\r\n")
    assert not m.sniff(b"\x89HDF\r\n\x1a\n")
    assert not m.sniff(b"time,a,b\n")
    assert not m.sniff(b"")  # empty input


def test_detect_format_by_content_not_suffix(tmp_path):
    p = _write(_recording(200), tmp_path / "rec.dat")
    assert pio.detect_format(p) == "mcap"
    assert pio.read(p) == _recording(200)


# ---------------------------------------------------------------------------------- round trip
@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("compression", ["none", "lz4", "zstd"])
def test_round_trip_lossless(tmp_path, dtype, compression):
    rec = _recording(12_345, dtype=dtype)
    p = _write(rec, tmp_path / "r.mcap", compression=compression, block=1000)
    back = pio.read(p)
    assert back == rec  # every field: fs, t0, specs, start_datetime, meta, history, samples
    assert back.data.dtype == dtype
    np.testing.assert_array_equal(_bits(back.data), _bits(rec.data))  # NaN payloads, -0.0
    assert back.channels == rec.channels
    assert back.meta == rec.meta and back.history == rec.history
    assert back.start_datetime == rec.start_datetime
    info = pio.read_info(p)
    assert info.format == "mcap" and info.extra["compression"] == compression
    assert info.extra["block"] == 1000 and info.extra["dtype"] == np.dtype(dtype).name


def test_default_block_is_5120_and_output_is_channel_major(tmp_path):
    rec = _recording(20_000)
    p = _write(rec, tmp_path / "r.mcap")
    info = pio.read_info(p)
    assert info.extra["block"] == m.DEFAULT_BLOCK == 5120
    assert info.extra["n_messages"] == 4 * 4  # ceil(20000 / 5120) messages per channel
    back = pio.read(p)
    assert back.data.flags.f_contiguous  # one allocation, channels contiguous


def test_read_info_has_header_only(tmp_path):
    rec = _recording(3000, t0=-1.25)
    p = _write(rec, tmp_path / "r.mcap")
    info = pio.read_info(p)
    assert (info.fs, info.n_samples, info.t0) == (rec.fs, rec.n_samples, rec.t0)
    assert info.channels == list(rec.channels)
    assert info.meta == rec.meta and info.history == rec.history
    assert info.start_datetime == rec.start_datetime
    assert info.extra["log_time_origin_ns"] == 0  # negative t0: log times count from sample 0


def test_every_channel_spec_field_round_trips(tmp_path):
    specs = [ChannelSpec("a", kind="sun", units="µm/m", gain=-3.5e-7, gear="sun", tooth=17,
                         face_position=0.0, description="ünïcode, commas, \"quotes\""),
             ChannelSpec("b with space", kind="other", units="", gain=1e300, gear=None, tooth=None,
                         face_position=None, description="")]
    rec = Recording(np.zeros((10, 2), np.float32), 51200.0 / 10, specs, t0=1e-9,
                    start_datetime=None, meta={}, history=[])
    back = pio.read(_write(rec, tmp_path / "r.mcap"))
    assert back.channels == tuple(specs)
    assert back.start_datetime is None and back.t0 == 1e-9


@settings(max_examples=40, deadline=None)
@given(n=st.integers(0, 700), n_ch=st.integers(1, 3), block=st.integers(1, 300),
       dtype=st.sampled_from([np.float32, np.float64]),
       t0=st.one_of(st.just(0.0), st.floats(-1e6, 1e9, allow_nan=False)),
       fs=st.one_of(st.sampled_from([5120.0, 1000.0 / 3.0, 0.5, 2.5e6]),
                    st.floats(1e-3, 1e7, allow_nan=False)),
       compression=st.sampled_from(["none", "lz4", "zstd"]), seed=st.integers(0, 2 ** 32 - 1))
def test_round_trip_property(n, n_ch, block, dtype, t0, fs, compression, seed):
    rng = np.random.default_rng(seed)
    bits = rng.integers(0, 2 ** 63, size=(n, n_ch), dtype=np.uint64)
    data = bits.view(np.float64) if dtype == np.float64 else bits.astype(np.uint32).view(np.float32)
    rec = Recording(data, fs, [f"c{i}" for i in range(n_ch)], t0=t0)
    with tempfile.TemporaryDirectory() as d:
        p = _write(rec, Path(d) / "r.mcap", block=block, compression=compression, chunk_size=2000)
        back = pio.read(p)
        assert back == rec
        np.testing.assert_array_equal(_bits(back.data), _bits(rec.data))
        if n:
            i0, i1 = sorted(rng.integers(0, n + 1, size=2).tolist())
            part = m.read(p, [f"c{n_ch - 1}"], i0, i1)
            np.testing.assert_array_equal(_bits(part.data[:, 0]), _bits(rec.data[i0:i1, n_ch - 1]))
            assert part.t0 == rec.slice_samples(i0, i1).t0


def test_empty_recording_round_trips(tmp_path):
    rec = Recording(np.empty((0, 2)), 100.0, ["a", "b"])
    p = _write(rec, tmp_path / "e.mcap")
    assert pio.read(p) == rec
    assert pio.read_info(p).n_samples == 0
    assert list(pio.iter_blocks(p, 1.0)) == []


def test_zero_channel_recording_round_trips(tmp_path):
    rec = Recording(np.empty((10, 0)), 100.0, [])
    back = pio.read(_write(rec, tmp_path / "z.mcap"))
    assert back == rec and back.data.shape == (10, 0)


# ---------------------------------------------------------------------------------- windows
@pytest.mark.parametrize("start, stop", [
    (None, None), (0.0, 0.1), (0.05, 0.5), (0.1953125, 0.3906250),  # block edges (1000 / 5120 s)
    (1.0, None), (None, 0.0002), (2.0, 2.0 + 1 / 5120), (-5.0, 100.0), (2.41, 10.0)])
def test_window_read_matches_slice(tmp_path, start, stop):
    rec = _recording(12_345)
    p = _write(rec, tmp_path / "r.mcap", block=1000, chunk_size=20_000)
    back = pio.read(p, start=start, stop=stop)
    assert back == rec.slice_time(start, stop)


def test_window_with_negative_t0_and_channel_subset(tmp_path):
    rec = _recording(5000, t0=-0.5, fs=1000.0)
    p = _write(rec, tmp_path / "r.mcap", block=333)
    back = pio.read(p, channels=["tacho", "sun_1"], start=-0.4, stop=1.2345)
    assert back == rec.select(["tacho", "sun_1"]).slice_time(-0.4, 1.2345)
    assert back.names == ["tacho", "sun_1"]


@pytest.mark.parametrize("start, stop", [(100.0, 200.0), (-10.0, -1.0), (0.5, 0.2)])
def test_window_outside_recording_raises(tmp_path, start, stop):
    p = _write(_recording(5120), tmp_path / "r.mcap")  # [0, 1) s
    with pytest.raises(ValueError, match="window"):
        pio.read(p, start=start, stop=stop)


def test_unknown_channel_raises(tmp_path):
    p = _write(_recording(100), tmp_path / "r.mcap")
    with pytest.raises(ValueError, match="no channel"):
        pio.read(p, channels=["nope"])


def test_one_channel_read_touches_only_its_chunks(tmp_path):
    rec = _recording(20_000)
    p = _write(rec, tmp_path / "r.mcap", block=1000, chunk_size=20_000)
    off, _ = _chunk_of(p, "ring_2", which=1)
    _corrupt_chunk(p, off)  # break a chunk of another channel (its opcode byte)
    # verify=False: the file-level data-section CRC would catch the damage at open
    np.testing.assert_array_equal(_bits(pio.read(p, channels=["sun_1"], verify=False).data[:, 0]),
                                  _bits(rec.data[:, 0]))
    with pytest.raises(CorruptFileError, match=r"chunk \d+ at byte"):
        pio.read(p, verify=False)
    with pytest.raises(CorruptFileError, match="data-section CRC32"):
        pio.read(p, channels=["sun_1"])


def test_window_read_uses_the_chunk_index(tmp_path):
    rec = _recording(50_000, fs=5000.0)  # 10 s
    p = _write(rec, tmp_path / "r.mcap", block=1000, chunk_size=40_100)  # 5 blocks = 1 s per chunk
    off, _ = _chunk_of(p, "sun_1", which=8)  # samples 40000..44999, t in [8, 9) s
    _corrupt_chunk(p, off)
    assert pio.read(p, start=1.0, stop=3.5, verify=False) == rec.slice_time(1.0, 3.5)
    with pytest.raises(RecordingFileError, match=str(p.name)):
        pio.read(p, start=7.5, stop=8.5, verify=False)


# ---------------------------------------------------------------------------------- streaming
@pytest.mark.parametrize("block_s, overlap_s, channels", [
    (0.1, 0.0, None), (0.05, 0.01, ["fw_a", "sun_1"]), (1.0, 0.25, ["tacho"]), (10.0, 0.0, None),
    (0.01, 0.05, ["ring_2"])])
def test_iter_blocks_matches_in_memory_blocks(tmp_path, block_s, overlap_s, channels):
    rec = _recording(12_345)
    p = _write(rec, tmp_path / "r.mcap", block=1000, chunk_size=30_000)
    got = list(pio.iter_blocks(p, block_s, overlap_s, channels=channels))
    want = list(rec.select(channels).blocks(block_s, overlap_s))
    assert len(got) == len(want)
    assert all(a == b for a, b in zip(got, want))


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 400), block=st.integers(1, 120), n_block=st.integers(1, 150),
       n_overlap=st.integers(0, 200), chunk_size=st.sampled_from([100, 1000, 1 << 20]))
def test_iter_blocks_property(n, block, n_block, n_overlap, chunk_size):
    data = np.arange(2 * n, dtype=np.float64).reshape(n, 2)
    rec = Recording(data, 10.0, ["a", "b"], t0=-1.0)
    with tempfile.TemporaryDirectory() as d:
        p = _write(rec, Path(d) / "r.mcap", block=block, chunk_size=chunk_size)
        got = list(m.iter_blocks(p, n_block, n_overlap))
    starts = list(range(0, n, n_block))
    assert len(got) == len(starts)
    for b0, blk in zip(starts, got):
        assert blk == rec.slice_samples(b0, b0 + n_block + n_overlap)


def test_iter_blocks_bad_input(tmp_path):
    p = _write(_recording(100), tmp_path / "r.mcap")
    with pytest.raises(ValueError):
        list(m.iter_blocks(p, 0, 0))
    with pytest.raises(ValueError):
        list(m.iter_blocks(p, 10, -1))


def test_iter_blocks_reports_lost_messages(tmp_path):
    rec = _recording(1000)
    p = _custom_file(tmp_path / "x.mcap", rec, block=100, drop=(1, 4))
    with pytest.raises(RecordingFileError, match=r"ring_2.*\[400, 500\) are missing"):
        list(m.iter_blocks(p, 300, 0))


# ---------------------------------------------------------------------------------- time stamps
@pytest.mark.parametrize("t0, origin", [(0.0, 0), (1.5, 1_500_000_000), (-2.0, 0), (1e-9, 1)])
def test_log_times_follow_the_documented_rule(tmp_path, t0, origin):
    rec = _recording(3000, t0=t0, fs=1000.0 / 3.0)
    p = _write(rec, tmp_path / "r.mcap", block=250)
    with open(p, "rb") as fh:
        msgs = [(msg.log_time, mlayout.HEADER.unpack_from(msg.data)[0])
                for _, ch, msg in make_reader(fh).iter_messages(topics=["sun_1"])]
    assert len(msgs) == 12
    for lt, first in msgs:
        # floor(first * 1e9 / fs) with fs = 1000/3 Hz -> first * 3e6 ns exactly
        assert lt == origin + first * 3_000_000
    assert pio.read_info(p).extra["log_time_origin_ns"] == origin


def test_log_time_ns_values_and_bad_input():
    assert m.log_time_ns(5120, 5120.0, 0) == 1_000_000_000
    assert m.log_time_ns(1, 5120.0, 7) == 7 + 195_312  # floor(195312.5)
    assert m.log_time_ns(0, 1000.0 / 3.0, 0) == 0  # empty: first sample is the origin
    # float(1000/3) is a hair below 1000/3 Hz, so 3 samples last a hair over 9 ms: floor -> 9 ms
    assert m.log_time_ns(3, 1000.0 / 3.0, 0) == 9_000_000
    with pytest.raises(TypeError, match="fs"):
        m.log_time_ns(1, "fast", 0)
    with pytest.raises(ValueError, match="fs"):
        m.log_time_ns(1, 0.0, 0)
    with pytest.raises(ValueError, match="first_sample"):
        m.log_time_ns(-1, 100.0, 0)
    with pytest.raises(ValueError, match="first_sample"):
        m.log_time_ns(1.5, 100.0, 0)
    with pytest.raises(ValueError, match="origin_ns"):
        m.log_time_ns(1, 100.0, -5)


@settings(max_examples=100, deadline=None)
@given(i=st.integers(0, 10 ** 12), fs=st.floats(1e-3, 1e9, allow_nan=False))
def test_log_time_ns_monotone_and_close(i, fs):
    a, b = m.log_time_ns(i, fs, 0), m.log_time_ns(i + 1, fs, 0)
    assert a <= b
    assert abs(a - i * 1e9 / fs) <= 1 + 1e-15 * i * 1e9 / fs


def test_python_reader_window_is_half_open(tmp_path):
    """mcap's iter_messages(starting_at, ending_before) excludes a message at the end bound
    (the TypeScript reader includes it: tests/interop); ending_at includes it."""
    rec = _recording(5000)
    p = _write(rec, tmp_path / "r.mcap", block=1000)
    t2 = m.log_time_ns(2000, rec.fs, 0)
    with open(p, "rb") as fh:
        r = make_reader(fh)
        excl = [mlayout.HEADER.unpack_from(x.data)[0]
                for _, _, x in r.iter_messages(topics=["sun_1"], starting_at=0, ending_before=t2)]
        incl = [mlayout.HEADER.unpack_from(x.data)[0]
                for _, _, x in r.iter_messages(topics=["sun_1"], starting_at=0, ending_at=t2)]
    assert excl == [0, 1000] and incl == [0, 1000, 2000]


def test_mcap_library_decodes_the_same_samples(tmp_path):
    """The mcap package's own message iteration reproduces the data from the payloads."""
    rec = _recording(7777, dtype=np.float32)
    p = _write(rec, tmp_path / "r.mcap", block=512, compression="lz4")
    out = np.full(rec.data.shape, 7.0, np.float32)
    with open(p, "rb") as fh:
        r = make_reader(fh)
        s = r.get_summary()
        schema = next(iter(s.schemas.values()))
        assert (schema.name, schema.encoding) == (m.SCHEMA_NAME, m.SCHEMA_ENCODING)
        assert json.loads(schema.data) == m.LAYOUT
        for _, ch, msg in r.iter_messages():
            first, n, nch, code, ver = mlayout.HEADER.unpack_from(msg.data)
            assert (nch, code, ver) == (1, 1, 1) and ch.message_encoding == m.MESSAGE_ENCODING
            out[first:first + n, int(ch.metadata["index"])] = np.frombuffer(msg.data, "<f4", n, 16)
        md = {x.name: x.metadata for x in r.iter_metadata()}
    np.testing.assert_array_equal(_bits(out), _bits(rec.data))
    assert float(md[m.RECORDING_METADATA]["fs"]) == rec.fs


# ---------------------------------------------------------------------------------- schemas
def test_schema_files_are_valid_and_describe_what_we_write(tmp_path):
    from jsonschema import Draft202012Validator

    for name in ("mcap_message.schema.json", "mcap_channel_metadata.schema.json"):
        Draft202012Validator.check_schema(mlayout._json_schema(name))
    assert mlayout.schema_problem("layout", m.LAYOUT) is None
    rec = _recording(10)
    assert mlayout.schema_problem("recording", mwriter._recording_metadata(rec, 5120, "none", 0)) is None
    for i, s in enumerate(rec.channels):
        assert mlayout.schema_problem("channel", mwriter._channel_metadata(s, i, rec.fs, "float64")) is None
    bad = dict(m.LAYOUT, version=2)
    assert mlayout.schema_problem("layout", bad) == "version: 1 was expected"


# ---------------------------------------------------------------------------------- bad input
@pytest.mark.parametrize("where", ["10%", "50%", "99%", "before_footer", "no_magic_end", "header"])
def test_truncated_file_raises_recording_file_error(tmp_path, where):
    p = _write(_recording(30_000), tmp_path / "r.mcap", block=1000, chunk_size=50_000)
    data = p.read_bytes()
    cut = {"10%": len(data) // 10, "50%": len(data) // 2, "99%": len(data) * 99 // 100,
           "before_footer": len(data) - 8 - 29,  # footer record is 1 + 8 + 20 bytes
           "no_magic_end": len(data) - 1, "header": 20}[where]
    p.write_bytes(data[:cut])
    with pytest.raises(RecordingFileError, match="truncated") as exc:
        pio.read(p)
    assert str(exc.value).startswith(str(p))
    with pytest.raises(RecordingFileError, match="truncated"):
        pio.read_info(p)


def test_chunk_corrupted_in_the_middle_raises(tmp_path):
    rec = _recording(20_000)
    p = _write(rec, tmp_path / "r.mcap", block=1000, chunk_size=20_000)
    off, length = _chunk_of(p, "fw_a", which=2)
    with open(p, "r+b") as fh:  # overwrite the record length field with garbage
        fh.seek(off + 1)
        fh.write(b"\x01\x02\x03\x04\x05\x06\x07\x08")
    with pytest.raises(RecordingFileError, match=str(p.name)):
        pio.read(p)


def test_crc_validation_catches_flipped_sample(tmp_path):
    rec = _recording(5000)
    p = _write(rec, tmp_path / "r.mcap", block=1000)
    off, length = _chunk_of(p, "sun_1", which=0)
    with open(p, "r+b") as fh:  # flip a byte inside the last message's samples
        fh.seek(off + length - 3)
        b = fh.read(1)
        fh.seek(off + length - 3)
        fh.write(bytes([b[0] ^ 0xFF]))
    with pytest.raises(CorruptFileError, match="CRC"):
        m.read(p)  # checked by default
    assert not np.array_equal(_bits(m.read(p, verify=False).data), _bits(rec.data))  # switched off


def test_foreign_mcap_file_raises_clear_error(tmp_path):
    p = tmp_path / "robot.mcap"
    with open(p, "wb") as fh:
        w = Writer(fh)
        w.start(profile="", library="someone else")
        sid = w.register_schema("Pose", "jsonschema", b'{"type": "object"}')
        cid = w.register_channel("/robot/pose", "json", sid)
        for i in range(5):
            w.add_message(cid, i * 1000, json.dumps({"x": i}).encode(), i * 1000)
        w.finish()
    assert pio.detect_format(p) == "mcap"
    with pytest.raises(RecordingFileError, match=r"(?s)not a meshphase recording.*/robot/pose: schema "
                                                  r"Pose \(jsonschema\), messages json, 5 message.*x \(number\)"):
        pio.read(p)


def test_mcap_without_summary_raises(tmp_path):
    p = tmp_path / "nosum.mcap"
    with open(p, "wb") as fh:
        w = Writer(fh, index_types=IndexType.NONE, repeat_channels=False, repeat_schemas=False,
                   use_statistics=False, use_summary_offsets=False, use_chunking=False)
        w.start()
        w.finish()
    with pytest.raises(RecordingFileError, match="no summary"):
        pio.read(p)


def test_missing_fs_raises(tmp_path):
    rec = _recording(300)

    def drop_fs(md):
        md = dict(md)
        del md["fs"]
        return md

    p = _custom_file(tmp_path / "nofs.mcap", rec, recording_md=drop_fs)
    with pytest.raises(RecordingFileError, match="'fs' is a required property"):
        pio.read(p)


def test_channel_metadata_without_fs_or_with_other_fs_raises(tmp_path):
    rec = _recording(300)
    p = _custom_file(tmp_path / "a.mcap", rec,
                     channel_md=lambda i, md: {k: v for k, v in md.items() if not (i == 2 and k == "fs")})
    with pytest.raises(RecordingFileError, match=r"fw_a.*'fs' is a required property"):
        pio.read_info(p)
    p = _custom_file(tmp_path / "b.mcap", rec,
                     channel_md=lambda i, md: dict(md, fs="100.0") if i == 1 else md)
    with pytest.raises(RecordingFileError, match="ring_2.*fs 100.0 Hz differs"):
        pio.read_info(p)


@pytest.mark.parametrize("fs", ["0.0", "-5.0", "inf", "nan"])
def test_bad_fs_value_raises(tmp_path, fs):
    p = _custom_file(tmp_path / "x.mcap", _recording(50), recording_md=lambda md: dict(md, fs=fs))
    with pytest.raises(RecordingFileError, match="fs"):
        pio.read_info(p)


def test_lost_or_duplicated_messages_raise(tmp_path):
    rec = _recording(1000)
    p = _custom_file(tmp_path / "lost.mcap", rec, block=100, drop=(3, 7))
    with pytest.raises(RecordingFileError, match=r"tacho.*\[700, 800\) are missing"):
        pio.read(p)
    assert pio.read(p, channels=["sun_1"]) == rec.select(["sun_1"])  # other channels intact
    assert pio.read(p, start=0.0, stop=600 / rec.fs) == rec.slice_samples(0, 600)
    p = _custom_file(tmp_path / "dup.mcap", rec, block=100, duplicate=(0, 2))
    with pytest.raises(RecordingFileError, match=r"sun_1.*stored twice"):
        pio.read(p)


def test_bad_payload_header_raises(tmp_path):
    rec = _recording(500)

    def bad_version(j, k, payload):
        return payload[:15] + b"\x07" + payload[16:] if (j, k) == (0, 1) else payload

    p = _custom_file(tmp_path / "v.mcap", rec, block=100, payload_edit=bad_version)
    with pytest.raises(RecordingFileError, match="version 7"):
        pio.read(p)

    def short(j, k, payload):
        return payload[:-8] if (j, k) == (1, 0) else payload

    p = _custom_file(tmp_path / "s.mcap", rec, block=100, payload_edit=short)
    with pytest.raises(RecordingFileError, match="claims 100 samples"):
        pio.read(p)


def test_not_an_mcap_file_raises(tmp_path):
    p = tmp_path / "x.mcap"
    p.write_bytes(b"hello world, not mcap at all" * 3)
    with pytest.raises(RecordingFileError, match="MCAP magic"):
        m.read_info(p)
    with pytest.raises(FileNotFoundError):
        m.read_info(tmp_path / "missing.mcap")


@pytest.mark.parametrize("opts, exc", [
    ({"block": 0}, ValueError), ({"block": 2.5}, ValueError), ({"block": "big"}, TypeError),
    ({"compression": "gzip"}, ValueError), ({"compression": 5}, TypeError),
    ({"chunk_size": 0}, ValueError), ({"blok": 10}, TypeError)])
def test_write_bad_options(tmp_path, opts, exc):
    with pytest.raises(exc):
        _write(_recording(10), tmp_path / "r.mcap", **opts)
    assert not (tmp_path / "r.mcap").exists()  # nothing half-written left behind


def test_write_rejects_non_json_meta_and_non_recording(tmp_path):
    rec = _recording(10)
    rec.meta["bad"] = object()
    with pytest.raises(TypeError, match="meta"):
        _write(rec, tmp_path / "r.mcap")
    with pytest.raises(TypeError):
        m.write(np.zeros((3, 1)), tmp_path / "s.mcap")


def test_numpy_values_in_meta_are_stored_as_numbers(tmp_path):
    rec = _recording(10)
    rec.meta.update({"n": np.int64(3), "x": np.float32(0.5), "v": np.arange(3)})
    back = pio.read(_write(rec, tmp_path / "r.mcap"))
    assert back.meta["n"] == 3 and back.meta["x"] == 0.5 and back.meta["v"] == [0, 1, 2]


def test_returned_header_is_a_copy_and_rewrites_are_seen(tmp_path):
    rec = _recording(300)
    p = _write(rec, tmp_path / "r.mcap")
    first = pio.read(p)
    first.meta["gearset"]["z_sun"] = -1  # must not leak into the next read (header cache)
    pio.read_info(p).history.append({"step": "x"})
    again = pio.read(p)
    assert again.meta == rec.meta and again.history == rec.history
    other = Recording(rec.data[:100] * 2, 1000.0, rec.channels, t0=3.0)
    _write(other, p, overwrite=True)
    assert pio.read(p) == other


def test_whole_chunk_copies_match_message_by_message(tmp_path, monkeypatch):
    rec = _recording(40_000, dtype=np.float32)
    p = _write(rec, tmp_path / "r.mcap", block=1000, chunk_size=10_000)
    hits = []
    real = mreader._uniform_chunk
    monkeypatch.setattr(mreader, "_uniform_chunk", lambda *a: hits.append(real(*a)) or hits[-1])
    fast = pio.read(p)
    n_chunks = pio.read_info(p).extra["n_chunks"]
    # every chunk but the first (it also holds the schema and channel records) in one copy
    assert sum(h is not None for h in hits) == n_chunks - 1
    monkeypatch.setattr(mreader, "_uniform_chunk", lambda *a: None)
    slow = pio.read(p)
    assert fast == slow == rec
