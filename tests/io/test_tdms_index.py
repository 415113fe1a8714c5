"""TDMS read by computed offsets (meshphase.io.tdms_index) against npTDMS's public read_data:
NI-DAQmx-style small segments (contiguous and interleaved), layouts that change between
segments, big-endian data, NI scaling, the fallback when the two disagree, bad input."""

from __future__ import annotations

import ast
import struct
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from meshphase.errors import FormatWarning
from meshphase.io import tdms, tdms_index, tdms_scaling
from meshphase.io.base import CorruptFileError, RecordingFileError
from meshphase.recording import ChannelSpec, Recording
from meshphase.synthetic.tdms_export import write_ni_log

FS = 5120.0
#: _rec puts one NaN in channel 0 (the check at the ends compares NaN as equal); its warning
#: is the reader's normal behaviour, tested in test_tdms.py
pytestmark = pytest.mark.filterwarnings("ignore::meshphase.errors.DataQualityWarning")


def _wf(**extra):
    return dict({"wf_increment": 1.0 / FS, "wf_start_offset": 0.0}, **extra)


def _rec(n=3000, nch=3, seed=0):
    rng = np.random.default_rng(seed)
    data = rng.standard_normal((n, nch))
    data[5, 0] = np.nan
    specs = [ChannelSpec(f"sun_{j}", kind="sun", units="m/m") for j in range(nch)]
    return Recording(data, FS, specs, t0=0.0)


def _both(path, monkeypatch, windows=((0, None), (17, 640), (511, 513), (1023, 2049))):
    """Reads by computed offsets, then by npTDMS's read_data: full, windows, one channel,
    raw, blocks; asserts the computed-offset path was taken and everything is equal."""
    def reads():
        info = tdms.read_info(path)
        out = [tdms.read(path, None, a, info.n_samples if b is None else min(b, info.n_samples))
               for a, b in windows if a <= info.n_samples]
        out.append(tdms.read(path, info.channels[-1].name))
        out.append(tdms.read(path, raw=True))
        out += list(tdms.iter_blocks(path, 700, 45))
        return info, out

    info_fast, fast = reads()
    assert info_fast.extra["fast_path"] is True, info_fast.extra["read_path"]
    monkeypatch.setattr(tdms, "_USE_FAST_PATH", False)
    info_pub, public = reads()
    monkeypatch.setattr(tdms, "_USE_FAST_PATH", True)
    assert info_pub.extra["fast_path"] is False
    assert len(fast) == len(public)
    for f, p in zip(fast, public):
        assert f == p
    return fast[0]


# ---------------------------------------------------------------------------- NI-DAQmx layouts
@pytest.mark.parametrize("spc", [512, 1000, 7, 3000, 5000])
@pytest.mark.parametrize("interleaved", [False, True])
def test_ni_log_layouts_equal_nptdms(tmp_path, monkeypatch, spc, interleaved):
    rec = _rec()
    path = write_ni_log(rec, tmp_path / "log.tdms", samples_per_segment=spc, interleaved=interleaved)
    got = _both(path, monkeypatch)
    np.testing.assert_array_equal(got.data, rec.data)
    assert got.names == rec.names and got.fs == FS


def test_ni_log_metadata_and_properties(tmp_path):
    rec = _rec(100, 2)
    rec = Recording(rec.data, FS, rec.channels, t0=1.5, start_datetime="2024-03-01T12:00:00.250000+00:00",
                    meta={"rig": "B2"}, history=[{"step": "simulate"}])
    path = write_ni_log(rec, tmp_path / "log.tdms", samples_per_segment=32, interleaved=True)
    got = tdms.read(path)
    assert got.t0 == 1.5 and got.start_datetime == rec.start_datetime
    assert got.meta["rig"] == "B2" and got.history[0] == {"step": "simulate"}
    assert got.spec("sun_0").kind == "sun" and got.spec("sun_0").units == "m/m"
    info = tdms.read_info(path)
    assert info.extra["n_segments"] == 4 and info.extra["read_path"] == "computed offsets"


def test_empty_recording_as_ni_log(tmp_path):
    rec = Recording(np.empty((0, 2)), FS, [ChannelSpec("a"), ChannelSpec("b")])
    path = write_ni_log(rec, tmp_path / "e.tdms")
    got = tdms.read(path)
    assert got.n_samples == 0 and got.names == ["a", "b"] and list(tdms.iter_blocks(path, 10, 0)) == []


def test_write_ni_log_bad_arguments(tmp_path):
    rec = _rec(10, 1)
    with pytest.raises(TypeError, match="Recording"):
        write_ni_log(np.zeros((3, 1)), tmp_path / "a.tdms")
    with pytest.raises(ValueError, match="samples_per_segment"):
        write_ni_log(rec, tmp_path / "a.tdms", samples_per_segment=0)
    with pytest.raises(TypeError, match="interleaved"):
        write_ni_log(rec, tmp_path / "a.tdms", interleaved="yes")
    with pytest.raises(ValueError, match="group"):
        write_ni_log(rec, tmp_path / "a.tdms", group="")
    write_ni_log(rec, tmp_path / "a.tdms")
    with pytest.raises(FileExistsError):
        write_ni_log(rec, tmp_path / "a.tdms")


# ---------------------------------------------------------------------------- changing layouts
def test_layout_changes_between_segments(tmp_path, monkeypatch, tdms_tools):
    """Channels joining later (object list extended), a channel without data in a segment,
    segment sizes changing, int16 next to float32 and float64."""
    from nptdms import ChannelObject, TdmsWriter

    path = tmp_path / "mix.tdms"
    rng = np.random.default_rng(1)
    a = rng.standard_normal(900)
    b = rng.integers(-500, 500, 900).astype(np.int16)
    c = rng.standard_normal(900).astype(np.float32)
    with TdmsWriter(str(path)) as w:
        w.write_segment([ChannelObject("g", "a", a[:300], properties=_wf()),
                         ChannelObject("g", "b", b[:300], properties=_wf())])
        w.write_segment([ChannelObject("g", "a", a[300:310]), ChannelObject("g", "b", b[300:310])])
        w.write_segment([ChannelObject("g", "a", a[310:600]), ChannelObject("g", "b", b[310:600])])
        w.write_segment([ChannelObject("g", "a", a[600:]), ChannelObject("g", "b", b[600:])])
    with TdmsWriter(str(tmp_path / "late.tdms")) as w:
        w.write_segment([ChannelObject("g", "a", a[:400], properties=_wf())])
        w.write_segment([ChannelObject("g", "a", a[400:]), ChannelObject("h", "c", c, properties=_wf())])
    got = _both(path, monkeypatch)
    np.testing.assert_array_equal(got.channel("a"), a)
    np.testing.assert_array_equal(got.channel("b"), b)
    got = _both(tmp_path / "late.tdms", monkeypatch)
    np.testing.assert_array_equal(got.data, np.column_stack([a, c.astype(np.float64)]))


def _seg(toc, objs, data, endian="<", new_list=True):
    """One segment by hand: objs = [(path, type code or None, n_values)] in ``endian``."""
    meta = struct.pack(endian + "I", len(objs))
    for p, code, nv in objs:
        pb = p.encode()
        meta += struct.pack(endian + "I", len(pb)) + pb
        meta += (struct.pack(endian + "I", 0xFFFFFFFF) if code is None
                 else struct.pack(endian + "IIIQ", 20, code, 1, nv))
        meta += struct.pack(endian + "I", 0)
    toc |= (1 << 1) | (1 << 3) | ((1 << 2) if new_list else 0) | ((1 << 6) if endian == ">" else 0)
    lead = b"TDSm" + struct.pack("<I", toc) + struct.pack(endian + "IQQ", 4713, len(meta) + len(data), len(meta))
    return lead + meta + data


def _props_segment(names):
    """A first segment carrying only wf_increment properties for the channels (no data)."""
    meta = struct.pack("<I", len(names))
    for p in names:
        pb = p.encode()
        name = b"wf_increment"
        meta += struct.pack("<I", len(pb)) + pb + struct.pack("<II", 0xFFFFFFFF, 1)
        meta += struct.pack("<I", len(name)) + name + struct.pack("<Id", 10, 1.0 / FS)
    toc = (1 << 1) | (1 << 2)
    return b"TDSm" + struct.pack("<IIQQ", toc, 4713, len(meta), len(meta)) + meta


@pytest.mark.parametrize("endian", ["<", ">"])
@pytest.mark.parametrize("interleaved", [False, True])
def test_hand_built_segments_with_chunks_and_byte_order(tmp_path, monkeypatch, endian, interleaved):
    """Several chunks per segment, big- and little-endian, interleaved or not, a segment
    that repeats the previous layout without metadata, a segment with a new count."""
    rng = np.random.default_rng(2)
    x = rng.standard_normal(200)
    y = rng.integers(-1000, 1000, 200).astype(np.int32)
    pa, pb = "/'g'/'x'", "/'g'/'y'"
    blob = _props_segment([pa, pb])

    def data(lo, nv, chunks):
        out = b""
        for k in range(chunks):
            s = slice(lo + k * nv, lo + (k + 1) * nv)
            if interleaved:
                rows = np.empty(nv, dtype=[("x", endian + "f8"), ("y", endian + "i4")])
                rows["x"], rows["y"] = x[s], y[s]
                out += rows.tobytes()
            else:
                out += x[s].astype(endian + "f8").tobytes() + y[s].astype(endian + "i4").tobytes()
        return out

    il = (1 << 5) if interleaved else 0
    blob += _seg(il, [(pa, 10, 20), (pb, 3, 20)], data(0, 20, 3), endian, new_list=False)       # 60
    toc = struct.pack("<I", (1 << 3) | il | ((1 << 6) if endian == ">" else 0))
    body = data(60, 20, 2)
    blob += b"TDSm" + toc + struct.pack(endian + "IQQ", 4713, len(body), 0) + body              # 100
    blob += _seg(il, [(pa, 10, 50), (pb, 3, 50)], data(100, 50, 2), endian, new_list=False)     # 200
    path = tmp_path / "hand.tdms"
    path.write_bytes(blob)
    got = _both(path, monkeypatch, windows=((0, None), (59, 61), (99, 150), (150, 200)))
    np.testing.assert_array_equal(got.channel("x"), x)
    np.testing.assert_array_equal(got.channel("y"), y)


def test_string_channel_between_numeric_ones(tdms_file, monkeypatch):
    """String data take room in every chunk: the numeric channels around them still read."""
    x = np.arange(6.0)
    path = tdms_file([("g", "a", x, _wf()), ("g", "label", np.array(list("uvwxyz")), {}),
                      ("g", "b", -x, _wf())], segments=3)
    with pytest.warns(FormatWarning, match="skipped channel g/label"):
        info = tdms.read_info(path)
    assert info.extra["fast_path"] is True
    rec = tdms.read(path)       # the plan is cached: its warning came with read_info
    np.testing.assert_array_equal(rec.data, np.column_stack([x, -x]))


# ---------------------------------------------------------------------------- scaling
def test_polynomial_and_chained_scaling_equal_nptdms(tdms_file, monkeypatch):
    raw = np.arange(-40, 40, dtype=np.int16)
    poly = {"NI_Scaling_Status": "unscaled", "NI_Number_Of_Scales": 2,
            "NI_Scale[0]_Scale_Type": "Polynomial", "NI_Scale[0]_Polynomial_Coefficients_Size": 3,
            "NI_Scale[0]_Polynomial_Coefficients[0]": 0.5, "NI_Scale[0]_Polynomial_Coefficients[1]": 2.0,
            "NI_Scale[0]_Polynomial_Coefficients[2]": -0.25,
            "NI_Scale[0]_Polynomial_Input_Source": np.uint32(0xFFFFFFFF),
            "NI_Scale[1]_Scale_Type": "Linear", "NI_Scale[1]_Linear_Slope": 1e-3,
            "NI_Scale[1]_Linear_Y_Intercept": 0.125, "NI_Scale[1]_Linear_Input_Source": np.uint32(0)}
    f32 = {"NI_Scaling_Status": "unscaled", "NI_Number_Of_Scales": 1, "NI_Scale[0]_Scale_Type": "Linear",
           "NI_Scale[0]_Linear_Slope": 3.3, "NI_Scale[0]_Linear_Y_Intercept": -1.0}
    path = tdms_file([("g", "p", raw, _wf(**poly)), ("g", "f", np.linspace(-1, 1, 80, dtype=np.float32), _wf(**f32))],
                     segments=4)
    got = _both(path, monkeypatch, windows=((0, None), (3, 77)))
    want = (0.5 + 2.0 * raw - 0.25 * raw.astype(float) ** 2) * 1e-3 + 0.125
    np.testing.assert_allclose(got.channel("p"), want, rtol=1e-15)
    assert got.history[0]["ni_scaled_channels"] == ["p", "f"]


def test_scaling_npTDMS_computes_alone_goes_through_read_data(tdms_file):
    raw = np.arange(10, dtype=np.int16)
    table = {"NI_Scaling_Status": "unscaled", "NI_Number_Of_Scales": 1, "NI_Scale[0]_Scale_Type": "Add",
             "NI_Scale[0]_Add_Left_Operand_Input_Source": np.uint32(0xFFFFFFFF),
             "NI_Scale[0]_Add_Right_Operand_Input_Source": np.uint32(0xFFFFFFFF)}
    path = tdms_file([("g", "a", raw, _wf(**table))], segments=2)
    info = tdms.read_info(path)
    assert info.extra["fast_path"] is False and "NI scaling computed by npTDMS only" in info.extra["read_path"]
    np.testing.assert_array_equal(tdms.read(path).channel("a"), raw * 2.0)


def test_tdms_scaling_parse_and_gain():
    assert tdms_scaling.parse({}, {}, {}) == (False, None)
    assert tdms_scaling.parse({"NI_Scaling_Status": "scaled", "NI_Number_Of_Scales": 1}) == (False, None)
    # a linear scale without its slope: scaling is asked for, this module cannot compute it
    assert tdms_scaling.parse({"NI_Number_Of_Scales": 1, "NI_Scale[0]_Scale_Type": "Linear"}) == (True, None)
    wants, chain = tdms_scaling.parse({}, {"NI_Scale[0]_Scale_Type": "Linear", "NI_Scale[0]_Linear_Slope": 2.0,
                                           "NI_Scale[0]_Linear_Y_Intercept": 0.0})
    assert wants and tdms_scaling.linear_gain(chain) == 2.0
    np.testing.assert_array_equal(chain.apply(np.array([1, 2], dtype=np.int16)), [2.0, 4.0])
    assert tdms_scaling.linear_gain(None) is None
    bad = tdms_scaling.Chain((tdms_scaling.Scale("Linear", (1.0, 0.0), 5),))
    with pytest.raises(ValueError, match="input source 5"):
        bad.apply(np.zeros(2))
    empty = tdms_scaling.Chain((tdms_scaling.Scale("Polynomial", (), tdms_scaling.RAW_INPUT),))
    np.testing.assert_array_equal(empty.apply(np.ones(3)), np.zeros(3))


# ---------------------------------------------------------------------------- fallback, checks
def test_fallback_when_the_computed_offsets_disagree_with_nptdms(tmp_path, monkeypatch):
    """Offsets that do not match what npTDMS reads (as if the index were misread) are caught
    by the check at both ends of every channel: npTDMS's read_data reads, same result."""
    rec = _rec(2000, 2)
    path = write_ni_log(rec, tmp_path / "x.tdms", samples_per_segment=512)
    real_scan = tdms_index.scan

    def shifted(p, mm=None):
        idx = real_scan(p, mm)
        for q, runs in idx.runs.items():
            idx.runs[q] = [tdms_index.Run(**{**r.__dict__, "offset": r.offset + 8}) for r in runs]
        return idx

    monkeypatch.setattr(tdms_index, "scan", shifted)
    info = tdms.read_info(path)
    assert info.extra["fast_path"] is False and "differ from npTDMS's" in info.extra["read_path"]
    np.testing.assert_array_equal(tdms.read(path).data, rec.data)
    assert list(tdms.iter_blocks(path, 300, 0))[3] == tdms.read(path, None, 900, 1200)


def test_partial_chunk_is_corrupt(tmp_path):
    rec = _rec(2048, 2)
    path = write_ni_log(rec, tmp_path / "x.tdms", samples_per_segment=512)
    blob = bytearray(path.read_bytes())
    last = blob.rfind(b"TDSm")
    (next_off,) = struct.unpack_from("<Q", blob, last + 12)
    struct.pack_into("<Q", blob, last + 12, next_off + 8)
    path.write_bytes(bytes(blob) + b"\0" * 8)
    with pytest.raises(CorruptFileError, match=r"segment 3 at byte \d+: truncated or corrupt: the segment "
                                               r"holds a partial chunk"):
        tdms.read(path)


def test_scan_bad_input(tmp_path):
    p = tmp_path / "e.tdms"
    p.write_bytes(b"")
    with pytest.raises(RecordingFileError, match="file is empty"):
        tdms_index.scan(p)
    p.write_bytes(b"TDSm" + b"\0" * 10)
    with pytest.raises(CorruptFileError, match="incomplete lead-in"):
        tdms_index.scan(p)
    p.write_bytes(b"junk" * 10)
    with pytest.raises(CorruptFileError, match="does not start with b'TDSm'"):
        tdms_index.scan(p)
    with pytest.raises(FileNotFoundError):
        tdms_index.scan(tmp_path / "none.tdms")
    p.write_bytes(b"TDSh" + b"\0" * 5)
    assert tdms_index.count_index_segments(p) == -1
    p.write_bytes(b"")
    assert tdms_index.count_index_segments(p) == 0


def test_read_runs_empty_window_and_daqmx_flag(tmp_path):
    rec = _rec(1000, 1)
    path = write_ni_log(rec, tmp_path / "x.tdms", samples_per_segment=100)
    idx = tdms_index.scan(path)
    (p,) = idx.runs
    dest = np.full(0, np.nan)
    with open(path, "rb") as fh, tdms_index.open_map(fh) as mm:
        tdms_index.read_runs(mm, idx.runs[p], idx.starts(p), 500, 500, dest)
    assert idx.lengths[p] == 1000 and idx.unsupported is None
    blob = bytearray(path.read_bytes())
    blob[4] |= 1 << 7                                   # kTocDAQmxRawData on the first segment
    path.write_bytes(bytes(blob))
    assert "DAQmx" in tdms_index.scan(path).unsupported


def test_iter_blocks_memory_is_flat_on_small_segments(tmp_path):
    rec = _rec(200_000, 4)
    path = write_ni_log(rec, tmp_path / "x.tdms", samples_per_segment=512, interleaved=True)
    tdms.read_info(path)                                # the plan is cached: blocks only
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        total = 0
        for blk in tdms.iter_blocks(path, 4096, 0):
            total += blk.n_samples
            del blk
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    assert total == 200_000
    assert peak < 20 * 4096 * 4 * 8           # a few blocks, far below the 6.4 MB of samples


# ---------------------------------------------------------------------------- public API only
def test_reader_uses_only_public_nptdms_names():
    """No npTDMS private internals: only ``TdmsFile`` is imported from npTDMS, and no private
    attribute (``_name``) of anything is touched outside this package's own objects."""
    import meshphase.io.tdms as mod

    root = Path(mod.__file__).parent
    for name in ("tdms.py", "tdms_index.py", "tdms_rows.py", "tdms_scaling.py"):
        tree = ast.parse((root / name).read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("nptdms"):
                assert node.module == "nptdms" and [a.name for a in node.names] == ["TdmsFile"], name
            if isinstance(node, ast.Import):
                assert all(a.name == "nptdms" or not a.name.startswith("nptdms") for a in node.names), name
            if isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__"):
                owner = ast.unparse(node.value)
                assert owner in {"self", "tdms", "tdms_index", "tdms_rows", "tdms_scaling"} or owner.startswith("self."), \
                    f"{name}: {owner}.{node.attr}"


def test_reading_path_switches_and_restores(tmp_path):
    rec = _rec(1500, 2)
    path = write_ni_log(rec, tmp_path / "x.tdms", samples_per_segment=512)
    assert tdms.read_info(path).extra["fast_path"] is True
    with tdms.reading_path(computed_offsets=False):
        assert tdms.read_info(path).extra["fast_path"] is False
        np.testing.assert_array_equal(tdms.read(path).data, rec.data)
    with tdms.reading_path(cache_plans=False):
        assert tdms._PLAN_CACHE_SIZE == 0 and not tdms._PLAN_CACHE
        tdms.read(path)
        assert not tdms._PLAN_CACHE
    assert tdms._USE_FAST_PATH is True and tdms._PLAN_CACHE_SIZE > 0 and tdms._PLAN_CACHE
    with pytest.raises(TypeError, match="computed_offsets must be a bool"):
        with tdms.reading_path(computed_offsets="no"):
            pass
    with pytest.raises(TypeError, match="cache_plans must be a bool"):
        with tdms.reading_path(cache_plans=None):
            pass
    with tdms.reading_path():        # nothing asked: nothing changes
        assert tdms.read_info(path).extra["read_path"] == "computed offsets"


def test_big_endian_float32_stays_float32(tmp_path, monkeypatch):
    x = np.linspace(-1, 1, 40, dtype=np.float32)
    path = tmp_path / "be.tdms"
    path.write_bytes(_props_segment(["/'g'/'a'"]) + _seg(0, [("/'g'/'a'", 9, 40)], x.astype(">f4").tobytes(),
                                                         ">", new_list=False))
    got = _both(path, monkeypatch, windows=((0, None),))
    assert got.data.dtype == np.float32
    np.testing.assert_array_equal(got.channel("a"), x)


def test_read_runs_and_open_map_bad_input(tmp_path):
    rec = _rec(1000, 1)
    path = write_ni_log(rec, tmp_path / "x.tdms", samples_per_segment=100)
    idx = tdms_index.scan(path)
    (p,) = idx.runs
    with open(path, "rb") as fh, tdms_index.open_map(fh) as mm:
        with pytest.raises(ValueError):
            tdms_index.read_runs(mm, idx.runs[p], idx.starts(p), 0, 50, np.empty(10))   # wrong length
        assert len(idx.starts(p)) == len(idx.runs[p])
    (tmp_path / "e").write_bytes(b"")
    with open(tmp_path / "e", "rb") as fh, pytest.raises(ValueError):
        tdms_index.open_map(fh)


def test_tdms_scaling_empty_and_bad():
    assert tdms_scaling.has_scales({}) is False
    assert tdms_scaling.has_scales({"NI_Number_Of_Scales": 0}) is False
    with pytest.raises(ValueError):
        tdms_scaling.has_scales({"NI_Number_Of_Scales": "two"})
    chain = tdms_scaling.Chain((tdms_scaling.Scale("Linear", (2.0, 1.0), tdms_scaling.RAW_INPUT),))
    assert chain.apply(np.empty(0)).shape == (0,)


@pytest.mark.parametrize("chans", [["sun_0", "sun_1"], ["sun_1", "sun_2"], ["sun_2", "sun_0"], ["sun_0", "sun_2"]])
def test_interleaved_channel_subsets(tmp_path, chans):
    """Any columns of the shared rows, in any order, are read together (read_rows)."""
    rec = _rec(3000, 3)
    path = write_ni_log(rec, tmp_path / "x.tdms", samples_per_segment=512, interleaved=True)
    cols = [rec.names.index(c) for c in chans]
    for a, b in ((0, 3000), (100, 2900), (511, 1537), (2999, 3000)):
        np.testing.assert_array_equal(tdms.read(path, chans, a, b).data, rec.data[a:b, cols])


def test_iter_blocks_frees_each_block_before_the_next(tmp_path):
    rec = _rec(64 * 1024, 4)
    path = write_ni_log(rec, tmp_path / "x.tdms", samples_per_segment=1000)
    tdms.read_info(path)
    block_bytes = 8192 * 4 * 8
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        for blk in tdms.iter_blocks(path, 8192, 0):
            del blk
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    assert peak < 1.5 * block_bytes
