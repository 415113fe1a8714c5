"""The per-chunk decoders of other tools' MCAP files (``meshphase.io.mcap.bulk``, ``batch``) against the per-message path they replace, which stays the reference: the same
stamps and the same samples, bit for bit.

The files are written by the mcap project's own writers (``mcap.writer.Writer`` for JSON,
``mcap_ros2.writer.Writer`` for ROS 2 CDR, whose message definitions follow
https://mcap.dev/spec/registry#ros2msg and https://docs.ros.org/en/rolling/Concepts/Basic/About-Interfaces.html).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

import meshphase.io as pio
from meshphase.io.mcap import bulk, foreign
from meshphase.io.mcap.batch import CdrBatch, JsonBatch, Unsupported, parse_msgdefs, parse_numbers, token_matrix
from meshphase.io.mcap.mapping import parse_topics
from meshphase.recording import Recording

T0 = 1_790_000_000_000_000_000


@pytest.fixture(autouse=True)
def _fresh_cache():
    foreign._CACHE.clear()
    yield
    foreign._CACHE.clear()


def _both(path: Path, topics, **kw):
    """(per-chunk, per-message) _collect results, as _series triples, and what bulk left."""
    entries = parse_topics(topics, **kw)
    with open(path, "rb") as fh:
        reader = make_reader(fh, decoder_factories=foreign.decoder_factories())
        summary = reader.get_summary()
        got, rest = bulk.collect_bulk(fh, path, summary, entries, foreign.decoder_factories())
        fast = foreign._collect(reader, path, entries, fh)
        ref = foreign._collect(reader, path, entries)
    out = {}
    for e in entries:
        a, b = foreign._series(fast[e.name]), foreign._series(ref[e.name])
        out[e.name] = (a, b)
    return out, got, rest


def _assert_same(pairs):
    for name, (a, b) in pairs.items():
        np.testing.assert_array_equal(a[0], b[0], err_msg=f"{name}: stamps")
        np.testing.assert_array_equal(a[1], b[1], err_msg=f"{name}: counts")
        assert a[2].dtype == b[2].dtype == np.float64
        np.testing.assert_array_equal(a[2].view(np.uint64), b[2].view(np.uint64), err_msg=f"{name}: samples")


def _json_file(path, bodies, topic="/j", chunk_size=4096):
    with open(path, "wb") as fh:
        w = Writer(fh, chunk_size=chunk_size)
        w.start(profile="", library="test")
        cid = w.register_channel(topic, "json", 0)
        for k, body in enumerate(bodies):
            t = T0 + k * 1_000_000
            w.add_message(cid, t, (body if isinstance(body, bytes) else json.dumps(body).encode()), t + 7)
        w.finish()
    return path


def _values(n, seed=0):
    rng = np.random.default_rng(seed)
    v = rng.standard_normal(n) * 10.0 ** rng.integers(-30, 30, n)
    v[::97] = 0.0
    v[1::97] = -0.0
    v[2::97] = 2 ** 60 + 1.0
    return v


def test_json_scalar_nested_stamp_and_array_fast_and_exact(tmp_path):
    v = _values(3000)
    bodies = [{"header": {"stamp": {"sec": (T0 + k * 1_000_000) // 10**9, "nsec": (T0 + k * 1_000_000) % 10**9}},
               "g": {"sun": float(v[k]), "i": k * 3 - 4000}, "arr": [float(v[k]), k, -k], "label": "x"}
              for k in range(3000)]
    p = _json_file(tmp_path / "j.mcap", bodies)
    topics = [{"name": "sun", "topic": "/j", "field": "g.sun", "stamp": "header.stamp"},
              {"name": "i", "topic": "/j", "field": "g.i"},
              {"name": "arr", "topic": "/j", "field": "arr", "stamp": "publish_time"},
              {"name": "a1", "topic": "/j", "field": "arr[1]"}]
    pairs, got, rest = _both(p, topics)
    assert rest == [] and set(got) == {"sun", "i", "arr", "a1"}
    _assert_same(pairs)
    np.testing.assert_array_equal(pairs["sun"][0][2], v)


def test_json_varying_shapes_nulls_and_ints_take_the_joined_parse(tmp_path):
    bodies = []
    for k in range(600):
        b = {"v": 0.5 * k} if k % 3 else {"other": 1, "v": -k}
        if k % 50 == 7:
            b["v"] = None
        bodies.append(b)
    p = _json_file(tmp_path / "v.mcap", bodies)
    pairs, got, rest = _both(p, {"v": "/j:v"})
    assert rest == [] and "v" in got
    _assert_same(pairs)
    assert np.isnan(pairs["v"][0][2][7])


def test_json_errors_leave_the_topic_to_the_reference_path(tmp_path):
    p = _json_file(tmp_path / "e.mcap", [{"v": k} if k != 300 else {"v": "text"} for k in range(500)])
    with open(p, "rb") as fh:
        got, rest = bulk.collect_bulk(fh, p, make_reader(fh).get_summary(), parse_topics({"v": "/j:v"}),
                                      foreign.decoder_factories())
    assert got == {} and [e.name for e in rest] == ["v"]
    with pytest.raises(pio.RecordingFileError, match=r"message 300 holds str 'text'"):
        pio.read(p, topics={"v": "/j:v"})


def test_foxglove_layout_with_nan_reads_back_through_the_fast_path(tmp_path):
    data = np.column_stack([_values(2000, 1), np.linspace(-1, 1, 2000)])
    data[5, 0] = np.nan
    data[6, 1] = np.inf
    rec = Recording(data, 1000.0, ["a/b", "c"], start_datetime="2026-03-04T05:06:07+00:00")
    p = pio.write(rec, tmp_path / "f.mcap", layout="foxglove")
    back = pio.read(p)
    np.testing.assert_array_equal(back.data[:, 0][~np.isnan(data[:, 0])], data[:, 0][~np.isnan(data[:, 0])])
    assert np.isnan(back.data[5, 0]) and np.isnan(back.data[6, 1])


ROS2_DEF = """std_msgs/Header header
float64 value
int32[] counts
string note
float32[3] xyz
uint8[] raw
Inner[] inner
Inner one
bool ok
int64 big
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: rig_msgs/Inner
string label
uint16 size
"""


def _ros2_file(path, n=1500):
    from mcap_ros2.writer import Writer as Ros2Writer

    v = _values(n, 2)
    with open(path, "wb") as fh:
        w = Ros2Writer(fh, chunk_size=8192)
        schema = w.register_msgdef("rig_msgs/msg/Strain", ROS2_DEF)
        for k in range(n):
            t = T0 + k * 2_000_000
            w.write_message("/r", schema, {
                "header": {"stamp": {"sec": t // 10**9, "nanosec": t % 10**9}, "frame_id": "f" * (k % 5)},
                "value": float(v[k]), "counts": list(range(k % 4)), "note": "n" * (k % 7),
                "xyz": [k, -k, 0.5], "raw": bytes(k % 3), "inner": [{"label": "ab", "size": k % 60000}],
                "one": {"label": "x" * (k % 2), "size": 7}, "ok": bool(k % 2), "big": k * 10**12},
                log_time=t + 1000, publish_time=t)
        w.finish()
    return path, v


def test_ros2_fields_after_strings_and_sequences_fast_and_exact(tmp_path):
    p, v = _ros2_file(tmp_path / "r.mcap")
    topics = [{"name": "value", "topic": "/r", "field": "value", "stamp": "header.stamp"},
              {"name": "y", "topic": "/r", "field": "xyz[1]"},
              {"name": "xyz", "topic": "/r", "field": "xyz", "stamp": "publish_time"},
              {"name": "size", "topic": "/r", "field": "inner[0].size"},
              {"name": "one", "topic": "/r", "field": "one.size"},
              {"name": "big", "topic": "/r", "field": "big"},
              {"name": "sec", "topic": "/r", "field": "header.stamp.sec"}]
    pairs, got, rest = _both(p, topics)
    assert rest == [] and len(got) == len(topics)
    _assert_same(pairs)
    np.testing.assert_array_equal(pairs["value"][0][2], v)


def test_ros2_unsupported_fields_fall_back(tmp_path):
    p, _ = _ros2_file(tmp_path / "r.mcap", n=200)
    for field in ("ok", "raw", "note", "inner"):   # bool, bytes, string, struct array: message by message
        entries = parse_topics({"x": f"/r:{field}"})
        with open(p, "rb") as fh:
            got, rest = bulk.collect_bulk(fh, p, make_reader(fh).get_summary(), entries, foreign.decoder_factories())
        assert got == {} and rest == entries
    pairs, _, _ = _both(p, {"c": "/r:counts"})
    _assert_same(pairs)
    with pytest.raises(pio.RecordingFileError, match="not a number"):
        pio.read(p, topics={"ok": "/r:ok"})


def test_cdr_batch_and_msgdef_parser_direct():
    defs = parse_msgdefs("p/msg/T", "# comment\nint8 A=3\nfloat64 x  # the value\nstring<=4 s\nfloat64 y\n")
    assert [f.name for f in defs["p/msg/T"]] == ["x", "s", "y"]
    assert parse_msgdefs("p/msg/E", "")["p/msg/E"] == []
    with pytest.raises(Unsupported):
        parse_msgdefs("p/msg/T", "float64\n")
    with pytest.raises(Unsupported):
        parse_msgdefs("p/msg/T", "MSG: other/Type\nfloat64 x\n")
    # two messages: x at 4 (aligned 8 from the header end: offset 0), then s, then y aligned to 8
    msgs = []
    for x, s, y in ((1.5, b"ab", -2.0), (2.5, b"", 3.0)):
        body = np.float64(x).tobytes() + np.uint32(len(s)).tobytes() + s
        body += bytes(-len(body) % 8) + np.float64(y).tobytes()
        msgs.append(b"\x00\x01\x00\x00" + body)
    buf = np.frombuffer(b"".join(msgs), np.uint8)
    start = np.array([0, len(msgs[0])])
    batch = CdrBatch(buf, start, np.array([len(m) for m in msgs]), defs, "p/msg/T")
    where = batch.locate([("x",), ("y",)])
    np.testing.assert_array_equal(batch.values("float64", where[("y",)][2]), [-2.0, 3.0])
    with pytest.raises(Unsupported, match="not in the message type"):
        batch.locate([("z",)])
    with pytest.raises(Unsupported, match="a string"):
        batch.locate([("s",)])
    with pytest.raises(Unsupported, match="little-endian"):
        CdrBatch(buf, np.array([4]), np.array([12]), defs, "p/msg/T")
    with pytest.raises(Unsupported, match="shorter"):
        CdrBatch(buf, np.array([0]), np.array([2]), defs, "p/msg/T")
    with pytest.raises(Unsupported, match="past the end"):
        CdrBatch(buf, np.array([0]), np.array([12]), defs, "p/msg/T").locate([("y",)])


def _texts(texts):
    raw = b" ".join(t.encode() for t in texts)
    lens = np.array([len(t) for t in texts])
    starts = np.concatenate(([0], np.cumsum(lens + 1)[:-1]))
    return token_matrix(np.frombuffer(raw, np.uint8), starts, lens), lens


def test_parse_numbers_is_json_loads_bit_for_bit():
    rng = np.random.default_rng(7)
    x = rng.standard_normal(20000) * 10.0 ** rng.integers(-320, 300, 20000)
    texts = [repr(float(v)) for v in x if np.isfinite(v)]
    texts += ["-0", "-0.0", "0", "0e5", "-0E-5", "1e400", "-1E-400", "5e-324", "2.4703282292062327e-324",
              "1.7976931348623157e308", "9007199254740993", "123456789012345678901234567890",
              "0.1000000000000000055511151231257827021181583404541015625", "1.5e+3", "12E5", "0.000123456789012345678",
              "1e1234567", "-1e-1234567"]
    texts += [f"{v:.{d}g}" for v in rng.standard_normal(3000) for d in (3, 9, 17)]
    texts += [str(int(v)) for v in rng.integers(-10**18, 10**18, 500)]
    mat, lens = _texts(texts)
    values, is_int, mant = parse_numbers(mat, lens)
    ref = np.array([float(json.loads(t)) for t in texts])
    np.testing.assert_array_equal(values.view(np.uint64), ref.view(np.uint64))
    np.testing.assert_array_equal(is_int, [isinstance(json.loads(t), int) for t in texts])
    # an integer's magnitude exactly up to 18 digits (the stamps' int64 range), saturated beyond
    ints = [(i, abs(json.loads(t))) for i, t in enumerate(texts) if isinstance(json.loads(t), int)]
    for i, v in ints:
        assert int(mant[i]) == (v if v < 10 ** 18 else np.iinfo(np.uint64).max), texts[i]


@pytest.mark.parametrize("text", ["01", "+1", "1.", ".5", "1e", "--1", "1.2.3", "1e+", "-", "-01", "1e5e5",
                                  "1-", "1+2", "e5", "-.5", "1.e5", "00", "-e1"])
def test_parse_numbers_refuses_what_json_refuses(text):
    mat, lens = _texts([text, "1"])
    with pytest.raises(Unsupported):
        parse_numbers(mat, lens)


def test_parse_numbers_empty_input():
    with pytest.raises(Unsupported, match="empty"):
        parse_numbers(np.zeros((0, 0), np.uint8), np.zeros(0, np.int64))


def test_json_batch_shapes():
    def batch(msgs):
        buf = np.frombuffer(b"#" + b"#".join(msgs), np.uint8)
        lens = np.array([len(m) for m in msgs])
        starts = 1 + np.concatenate(([0], np.cumsum(lens + 1)[:-1]))
        return JsonBatch(buf, starts, lens)

    b = batch([b'{"a": 1, "b": [2, 3.5]}', b'{"a": -10, "b": [20e3, 3]}'])
    assert b.k == 3 and b.token(b.probe["a"]) == 0 and [b.token(x) for x in b.probe["b"]] == [1, 2]
    np.testing.assert_array_equal(b.numbers(2)[0], [3.5, 3.0])
    assert b.token("x") is None and b.token(True) is None
    for msgs in ([b'{"a": 1}', b'{"b": 1}'], [b'{"a": 1}', b'{"a": 1, "c": 2}'], [b'{"a": 1}', b""],
                 [b'{"a": 1', b'{"a": 2']):
        with pytest.raises(Unsupported):
            batch(msgs)


def test_bulk_without_summary_or_mapping_is_a_no_op(tmp_path):
    p = _json_file(tmp_path / "n.mcap", [{"v": 1}])
    assert bulk.collect_bulk(None, p, None, parse_topics({"v": "/j:v"}), []) == ({}, parse_topics({"v": "/j:v"}))
    with open(p, "rb") as fh:
        assert bulk.collect_bulk(fh, p, make_reader(fh).get_summary(), [], []) == ({}, [])


def test_bench_generic_decode_rows(tmp_path):
    from meshphase.bench.io import GENERIC_COLUMNS, _generic_markdown, generic_decode_rows, strain_recording

    rec = strain_recording(600, 2, 200.0, rng=4)
    calls = []

    def timer(fn):
        calls.append(fn)
        return 0.5, fn()

    rows = generic_decode_rows(rec, tmp_path, timer)
    assert [r["encoding"] for r in rows] == ["json", "cdr"] and len(calls) == 4
    for r in rows:
        assert tuple(r) == GENERIC_COLUMNS
        assert r["messages"] == 600 and r["exact"] is True and r["samples_per_s"] == 1200.0
    assert not list(tmp_path.iterdir())  # files removed
    md = _generic_markdown(rows)
    assert md[0] == "## MCAP generic decode, scalar per message" and sum(ln.startswith("| json") for ln in md) == 1
    assert _generic_markdown([]) == []
    with pytest.raises(ValueError, match="at least 2 samples"):
        generic_decode_rows(Recording(np.zeros((1, 1)), 10.0, ["a"]), tmp_path, timer)
