"""MCAP files as other tools write them (JSON, protobuf, ROS 2), built here with the mcap
project's own writers holding known values, read through a mapping of topic fields onto
channels; and the ``foxglove`` layout meshphase writes, read back with the decoders."""

from __future__ import annotations

import json

import jsonschema
import numpy as np
import pytest
from google.protobuf import descriptor_pb2, descriptor_pool
from google.protobuf.message_factory import GetMessageClass
from mcap.reader import make_reader
from mcap.writer import Writer

import meshphase.io as pio
from meshphase.io import RecordingFileError
from meshphase.io import mcap as m
from meshphase.io.mcap import foreign
from meshphase.io.mcap.foreign import JsonDecoderFactory
from meshphase.recording import ChannelSpec, Recording

T0_NS = 1_700_000_000_000_000_000  # 2023-11-14T22:13:20 UTC


def _bits(a):
    a = np.ascontiguousarray(a)
    return a.view(np.uint32 if a.dtype == np.float32 else np.uint64)


@pytest.fixture(autouse=True)
def _fresh_cache():
    foreign._CACHE.clear()
    yield
    foreign._CACHE.clear()


def _json_file(path, n=200, fs=1000.0, *, stamps=None, body=None, topic="/rig/strain", schema=True):
    """JSON messages: gauges.sun_T3 = 0.5 k, gauges.ring = -k, a string field, arrays."""
    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start(profile="", library="a DAQ logger")
        sid = w.register_schema("rig.Strain", "jsonschema", b'{"type": "object"}') if schema else 0
        cid = w.register_channel(topic, "json", sid)
        for k in range(n):
            t = T0_NS + round(k * 1e9 / fs) if stamps is None else stamps[k]
            msg = {"gauges": {"sun_T3": 0.5 * k, "ring": -float(k)}, "label": "run 1",
                   "stamp": {"sec": t // 10**9, "nsec": t % 10**9}} if body is None else body(k)
            w.add_message(cid, t, json.dumps(msg).encode(), t)
        w.finish()
    return path


def test_decoded_samples_are_shared_read_only(tmp_path):
    # one decode serves the header and every pass: the cached recording is read-only, and
    # what the registry hands out is the caller's own copy
    from meshphase.io.mcap import read_foreign

    p = _json_file(tmp_path / "j.mcap")
    topics = {"sun_T3": "/rig/strain:gauges.sun_T3"}
    shared = read_foreign(p, topics=topics)
    with pytest.raises(ValueError, match="read-only"):
        shared.data[:] = 0.0
    a = pio.read(p, topics=topics)
    a.data[:] = 0.0                                  # the caller's copy
    np.testing.assert_array_equal(pio.read(p, topics=topics).data[:, 0], 0.5 * np.arange(200))


# -- mapping forms -------------------------------------------------------------------------

def test_json_scalar_per_message_values_fs_and_time(tmp_path):
    p = _json_file(tmp_path / "j.mcap")
    rec = pio.read(p, topics={"sun_T3": "/rig/strain:gauges.sun_T3",
                              "ring": {"topic": "/rig/strain", "field": "gauges.ring", "kind": "ring",
                                       "scale": 1e-6}})
    assert rec.names == ["sun_T3", "ring"]
    assert rec.fs == pytest.approx(1000.0, rel=1e-9)
    np.testing.assert_array_equal(rec.data[:, 0], 0.5 * np.arange(200))
    np.testing.assert_allclose(rec.data[:, 1], -1e-6 * np.arange(200), rtol=1e-15)
    assert rec.channels[1].kind == "ring" and rec.channels[0].kind == "other"
    assert rec.t0 == 0.0 and rec.start_datetime == "2023-11-14T22:13:20+00:00"
    assert rec.meta["mcap_origin_ns"] == T0_NS
    info = pio.read_info(p, topics={"sun_T3": "/rig/strain:gauges.sun_T3"})
    assert info.n_samples == 200 and info.names == ["sun_T3"]


def test_list_form_header_stamp_and_given_fs(tmp_path):
    # log times jitter by up to 3 ms (receive time) while the stamp field is exact
    rng = np.random.default_rng(0)
    exact = T0_NS + np.arange(100) * 10_000_000  # 100 Hz
    p = tmp_path / "s.mcap"
    with open(p, "wb") as fh:
        w = Writer(fh)
        w.start()
        cid = w.register_channel("/x", "json", 0)  # schemaless JSON
        for k in range(100):
            lt = int(exact[k] + rng.integers(0, 3_000_000))
            w.add_message(cid, lt, json.dumps({"v": k, "header": {"stamp": {"sec": int(exact[k]) // 10**9,
                                                                               "nsec": int(exact[k]) % 10**9}}}).encode(), lt)
        w.finish()
    topics = [{"name": "v", "topic": "/x", "field": "v", "stamp": "header.stamp"}]
    rec = pio.read(p, topics=topics, fs=100.0)
    assert rec.fs == 100.0 and rec.meta["mcap_origin_ns"] == exact[0]
    np.testing.assert_array_equal(rec.data[:, 0], np.arange(100))
    # by log time (receive time): within the default half period, not within 1 ms
    assert pio.read(p, topics={"v": "/x:v"}).n_samples == 100
    with pytest.raises(RecordingFileError, match="irregular"):
        pio.read(p, topics={"v": "/x:v"}, max_jitter=1e-3)
    got = pio.read(p, topics={"v": "/x:v"}, fs=100.0, max_jitter=4e-3)  # tolerated explicitly
    np.testing.assert_array_equal(got.data[:, 0], np.arange(100))


def test_array_per_message_blocks_fs_derived_and_window(tmp_path):
    fs, per = 2048.0, 64
    truth = np.sin(np.arange(40 * per) * 0.01)

    def body(k):
        return {"samples": truth[k * per:(k + 1) * per].tolist(), "n": per}

    p = _json_file(tmp_path / "a.mcap", n=40, fs=fs / per, body=body)
    rec = pio.read(p, topics={"s": "/rig/strain:samples"})
    assert rec.fs == pytest.approx(fs, rel=1e-9)
    np.testing.assert_array_equal(rec.data[:, 0], truth)
    w = pio.read(p, start=0.1, stop=0.2, topics={"s": "/rig/strain:samples"})
    i0, i1 = rec.sample_range(0.1, 0.2)
    np.testing.assert_array_equal(w.data[:, 0], truth[i0:i1])
    blocks = list(pio.iter_blocks(p, block=0.25, overlap=0.01, topics={"s": "/rig/strain:samples"}))
    assert len(blocks) == -(-rec.n_samples // 512)
    np.testing.assert_array_equal(np.concatenate([b.data[:512, 0] for b in blocks]), truth)
    np.testing.assert_array_equal(blocks[0].data[:, 0], truth[:512 + round(0.01 * fs)])


def test_array_element_and_quoted_keys(tmp_path):
    p = _json_file(tmp_path / "q.mcap", n=50, body=lambda k: {"a b": {"x.y": [k, 2 * k, 3 * k]}})
    rec = pio.read(p, topics=[{"name": "third", "topic": "/rig/strain", "field": '["a b"]["x.y"][2]'}])
    np.testing.assert_array_equal(rec.data[:, 0], 3 * np.arange(50))


def test_two_topics_aligned_on_common_span(tmp_path):
    p = tmp_path / "two.mcap"
    with open(p, "wb") as fh:
        w = Writer(fh)
        w.start()
        a = w.register_channel("/a", "json", 0)
        b = w.register_channel("/b", "json", 0)
        for k in range(100):  # /b starts 10 samples later and ends 5 samples earlier
            t = T0_NS + k * 1_000_000
            w.add_message(a, t, json.dumps({"v": k}).encode(), t)
            if 10 <= k < 95:
                w.add_message(b, t, json.dumps({"v": 1000 + k}).encode(), t)
        w.finish()
    rec = pio.read(p, topics={"a": "/a:v", "b": "/b:v"})
    assert rec.n_samples == 85 and rec.meta["mcap_origin_ns"] == T0_NS + 10_000_000
    np.testing.assert_array_equal(rec.data[:, 0], np.arange(10, 95))
    np.testing.assert_array_equal(rec.data[:, 1], 1000 + np.arange(10, 95))


# -- protobuf and ROS 2 ------------------------------------------------------------------------

def _proto_class():
    fdp = descriptor_pb2.FileDescriptorProto(name="meshtest_strain.proto", package="meshtest", syntax="proto3")
    t = fdp.message_type.add(name="Time")
    t.field.add(name="seconds", number=1, type=descriptor_pb2.FieldDescriptorProto.TYPE_INT64,
                label=descriptor_pb2.FieldDescriptorProto.LABEL_OPTIONAL)
    t.field.add(name="nanos", number=2, type=descriptor_pb2.FieldDescriptorProto.TYPE_INT32,
                label=descriptor_pb2.FieldDescriptorProto.LABEL_OPTIONAL)
    s = fdp.message_type.add(name="Strain")
    F = descriptor_pb2.FieldDescriptorProto
    s.field.add(name="stamp", number=1, type=F.TYPE_MESSAGE, type_name=".meshtest.Time", label=F.LABEL_OPTIONAL)
    s.field.add(name="sun_t3", number=2, type=F.TYPE_DOUBLE, label=F.LABEL_OPTIONAL)
    s.field.add(name="block", number=3, type=F.TYPE_FLOAT, label=F.LABEL_REPEATED)
    s.field.add(name="label", number=4, type=F.TYPE_STRING, label=F.LABEL_OPTIONAL)
    pool = descriptor_pool.DescriptorPool()
    pool.Add(fdp)
    return GetMessageClass(pool.FindMessageTypeByName("meshtest.Strain"))


def test_protobuf_scalar_array_and_stamp(tmp_path):
    from mcap_protobuf.writer import Writer as PbWriter

    Strain = _proto_class()
    fs_msg, per = 100.0, 32
    blocks = np.arange(50 * per, dtype=np.float32) / 7
    p = tmp_path / "pb.mcap"
    with open(p, "wb") as fh, PbWriter(fh) as w:
        for k in range(50):
            t = T0_NS + k * 10_000_000
            msg = Strain(sun_t3=k * 0.25, block=blocks[k * per:(k + 1) * per].tolist(), label="x")
            msg.stamp.seconds, msg.stamp.nanos = t // 10**9, t % 10**9
            w.write_message("/pb/strain", msg, log_time=t + 777, publish_time=t)
    rec = pio.read(p, topics={"sun": {"topic": "/pb/strain", "field": "sun_t3", "kind": "sun", "tooth": 3,
                                      "stamp": "stamp"}})
    assert rec.fs == pytest.approx(fs_msg) and rec.meta["mcap_origin_ns"] == T0_NS
    np.testing.assert_array_equal(rec.data[:, 0], 0.25 * np.arange(50))
    assert rec.channels[0].tooth == 3
    arr = pio.read(p, topics={"b": "/pb/strain:block"}, stamp="publish_time")
    assert arr.fs == pytest.approx(fs_msg * per)
    np.testing.assert_array_equal(arr.data[:, 0], blocks.astype(np.float64))
    with pytest.raises(RecordingFileError, match=r"not a number.*|holds str"):
        pio.read(p, topics={"bad": "/pb/strain:label"})
    with pytest.raises(RecordingFileError) as exc:
        pio.read(p)
    assert "meshtest.Strain (protobuf)" in str(exc.value) and "sun_t3 (number)" in str(exc.value)
    assert "block (array[32])" in str(exc.value)


ROS2_MSGDEF = """std_msgs/Header header
float64 sun_t3
float64[] samples
string label
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
"""


def test_ros2_cdr_scalar_and_header_stamp(tmp_path):
    from mcap_ros2.writer import Writer as Ros2Writer

    p = tmp_path / "ros2.mcap"
    exact = T0_NS + np.arange(60) * 2_000_000  # 500 Hz
    with open(p, "wb") as fh:
        w = Ros2Writer(fh)
        schema = w.register_msgdef("rig_msgs/msg/Strain", ROS2_MSGDEF)
        for k in range(60):
            t = int(exact[k])
            w.write_message("/ros/strain", schema, {
                "header": {"stamp": {"sec": t // 10**9, "nanosec": t % 10**9}, "frame_id": "rig"},
                "sun_t3": 1e-6 * k, "samples": [k, k + 0.5], "label": "ok"}, log_time=t + 5_000 * (k % 3))
        w.finish()
    rec = pio.read(p, topics={"sun_T3": {"topic": "/ros/strain", "field": "sun_t3", "kind": "sun",
                                         "stamp": "header.stamp"}})
    assert rec.fs == pytest.approx(500.0, rel=1e-12) and rec.meta["mcap_origin_ns"] == exact[0]
    np.testing.assert_array_equal(rec.data[:, 0], 1e-6 * np.arange(60))
    arr = pio.read(p, topics={"s": "/ros/strain:samples"}, stamp="header.stamp")
    assert arr.fs == pytest.approx(1000.0, rel=1e-12)
    np.testing.assert_array_equal(arr.data[:, 0], np.arange(120) / 2)
    with pytest.raises(RecordingFileError) as exc:
        pio.read(p)
    msg = str(exc.value)
    assert "rig_msgs/msg/Strain (ros2msg)" in msg and "sun_t3 (number)" in msg and "header.stamp.sec" in msg


# -- errors ------------------------------------------------------------------------------------

def test_bad_mappings_name_the_problem(tmp_path):
    p = _json_file(tmp_path / "j.mcap", n=20)
    with pytest.raises(RecordingFileError, match=r"topic\(s\) \['/nope'\] not in the file; topics present: \['/rig/strain'\]"):
        pio.read(p, topics={"a": "/nope:v"})
    with pytest.raises(RecordingFileError, match=r"has no field 'gauges.sun'; numeric fields of that message: "
                                                 r"gauges.sun_T3, gauges.ring"):
        pio.read(p, topics={"a": "/rig/strain:gauges.sun"})
    with pytest.raises(RecordingFileError, match=r"holds str 'run 1', not a number"):
        pio.read(p, topics={"a": "/rig/strain:label"})
    with pytest.raises(RecordingFileError, match=r"holds dict"):
        pio.read(p, topics={"a": "/rig/strain:gauges"})
    with pytest.raises(ValueError, match="channel 'a' is mapped twice"):
        pio.read(p, topics=[{"name": "a", "topic": "/rig/strain", "field": "x"}] * 2)
    with pytest.raises(ValueError, match="write 'TOPIC:FIELD'"):
        pio.read(p, topics={"a": "no-colon"})
    with pytest.raises(ValueError, match="unknown key"):
        pio.read(p, topics=[{"name": "a", "topic": "/rig/strain", "field": "x", "gian": 2}])
    with pytest.raises(ValueError, match="kind must be one of"):
        pio.read(p, topics=[{"name": "a", "topic": "/rig/strain", "field": "x", "kind": "planet"}])
    with pytest.raises(ValueError, match="topics is empty"):
        pio.read(p, topics={})
    with pytest.raises(TypeError, match="topics must be"):
        pio.read(p, topics="/rig/strain:x")
    with pytest.raises(ValueError, match="fs must be"):
        pio.read(p, topics={"a": "/rig/strain:gauges.ring"}, fs=-1.0)
    with pytest.raises(ValueError, match="max_jitter must be"):
        pio.read(p, topics={"a": "/rig/strain:gauges.ring"}, max_jitter=float("nan"))
    with pytest.raises(ValueError, match="without a key before it"):
        pio.read(p, topics={"a": "/rig/strain:gauges..ring"})
    with pytest.raises(ValueError, match="cannot parse"):
        pio.read(p, topics={"a": "/rig/strain:gauges-ring"})


def test_irregular_and_lost_messages_are_reported(tmp_path):
    stamps = [T0_NS + k * 1_000_000 for k in range(100)]
    del stamps[50:53]  # three lost messages
    p = _json_file(tmp_path / "gap.mcap", n=97, stamps=stamps)
    with pytest.raises(RecordingFileError, match=r"timestamps are irregular: message \d+ .* ms off a uniform "
                                                 r"grid .*spacing from the stamps ranges 1 \.\. 4 ms"):
        pio.read(p, topics={"a": "/rig/strain:gauges.ring"})
    with pytest.raises(RecordingFileError, match="irregular"):
        pio.read(p, topics={"a": "/rig/strain:gauges.ring"}, fs=1000.0)


def test_one_message_needs_fs_and_topic_without_messages(tmp_path):
    p = _json_file(tmp_path / "one.mcap", n=1, body=lambda k: {"s": [1.0, 2.0, 3.0]})
    with pytest.raises(RecordingFileError, match="give fs"):
        pio.read(p, topics={"s": "/rig/strain:s"})
    rec = pio.read(p, topics={"s": "/rig/strain:s"}, fs=3.0)
    np.testing.assert_array_equal(rec.data[:, 0], [1.0, 2.0, 3.0])
    empty = _json_file(tmp_path / "empty.mcap", n=0)
    with pytest.raises(RecordingFileError, match="topic '/rig/strain' has no messages"):
        pio.read(empty, topics={"a": "/rig/strain:gauges.ring"})
    with pytest.raises(RecordingFileError, match=r"(?s)/rig/strain: schema rig.Strain .* 0 message"):
        pio.read(empty)


def test_empty_mcap_without_channels_lists_nothing(tmp_path):
    p = tmp_path / "none.mcap"
    with open(p, "wb") as fh:
        w = Writer(fh)
        w.start()
        w.finish()
    with pytest.raises(RecordingFileError, match="the file has no topics"):
        pio.read(p)
    assert m.describe(p) == []


def test_options_on_own_layout_and_bad_input(tmp_path):
    rec = Recording(np.zeros((10, 1)), 100.0, ["a"])
    p = pio.write(rec, tmp_path / "own.mcap")
    with pytest.raises(ValueError, match="apply to MCAP files of other tools"):
        pio.read(p, fs=100.0)
    with pytest.raises(RecordingFileError, match="cannot decode"):
        pio.read(p, topics={"a": "a:first_sample"})
    with pytest.raises(FileNotFoundError):
        m.read_foreign(tmp_path / "missing.mcap", topics={"a": "/x:y"})
    with pytest.raises(TypeError, match="verify must be a bool"):
        m.describe(p, verify="yes")
    with pytest.raises(RecordingFileError, match="not an MCAP file"):
        (tmp_path / "x.mcap").write_bytes(b"hello world, not mcap at all" * 4)
        m.describe(tmp_path / "x.mcap")


def test_parse_field_path_and_fit_grid_direct():
    assert m.parse_field_path('a.b[3]["c.d"]') == ("a", "b", 3, "c.d")
    for bad in ("", ".a", "a.", "[1]", "a b", "a..b"):
        with pytest.raises(ValueError):
            m.parse_field_path(bad)
    with pytest.raises(TypeError):
        m.parse_field_path(3)
    g = m.fit_grid(np.arange(5) * 1_000_000 + 7, np.ones(5, int))
    assert g.fs == pytest.approx(1000.0) and g.origin_ns == 7 and g.n_samples == 5
    with pytest.raises(ValueError, match="no messages"):
        m.fit_grid([], [])
    with pytest.raises(ValueError, match="do not advance"):
        m.fit_grid([5, 5, 5], [1, 1, 1])
    with pytest.raises(ValueError, match="no samples"):
        m.fit_grid([1, 2], [0, 0], fs=1.0)


# -- the foxglove layout ---------------------------------------------------------------------

def _rec(dtype=np.float64, n=3000):
    rng = np.random.default_rng(7)
    data = (rng.standard_normal((n, 3)) * 1e-5).astype(dtype)
    data[4, 0], data[9, 1], data[11, 2] = np.nan, -0.0, np.inf
    specs = [ChannelSpec("sun_1", kind="sun", tooth=2), ChannelSpec("ring.1", kind="ring", units="V"),
             ChannelSpec("tacho", kind="tacho", units="V")]
    return Recording(data, 5120.0, specs, t0=1.25, start_datetime="2025-01-01T00:00:00+00:00",
                     meta={"rig": "A"}, history=[{"step": "acquire"}])


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_foxglove_layout_round_trip_without_mapping(tmp_path, dtype):
    rec = _rec(dtype)
    p = pio.write(rec, tmp_path / "fox.mcap", layout="foxglove")
    back = pio.read(p)
    assert back.fs == rec.fs and back.t0 == rec.t0 and back.channels == rec.channels
    assert back.meta == rec.meta and back.history == rec.history and back.data.dtype == rec.data.dtype
    want = rec.data.copy()
    want[~np.isfinite(want)] = np.nan  # left out of the message
    np.testing.assert_array_equal(_bits(back.data[np.isfinite(want)]), _bits(want[np.isfinite(want)]))
    assert np.array_equal(np.isnan(back.data), np.isnan(want))
    part = pio.read(p, channels=["tacho"], start=1.25 + 100 / 5120, stop=1.25 + 200 / 5120)
    np.testing.assert_array_equal(part.data[:, 0], want[100:200, 2])
    info = pio.read_info(p)
    assert info.n_samples == rec.n_samples and info.t0 == 1.25


def _foxglove_parser_accepts(schema: dict) -> None:
    """What Foxglove's JSON Schema parser (``parseJsonSchema`` of its mcap-support package)
    accepts: an object with properties whose ``type`` is one of boolean, string, number,
    integer, object (recursively) or array; a list of types or ``null`` makes it throw."""
    assert schema["type"] == "object"
    for name, field in schema["properties"].items():
        assert field["type"] in ("boolean", "string", "number", "integer", "object", "array"), name
        if field["type"] == "object":
            _foxglove_parser_accepts(field)


def test_foxglove_layout_decodes_with_mcap_python_and_validates(tmp_path):
    rec = _rec(n=500)
    p = pio.write(rec, tmp_path / "fox.mcap", layout="foxglove", compression="lz4")
    with open(p, "rb") as fh:
        reader = make_reader(fh, decoder_factories=[JsonDecoderFactory()])
        summary = reader.get_summary()
        (sc,) = summary.schemas.values()
        assert (sc.name, sc.encoding) == (m.FOXGLOVE_SCHEMA_NAME, "jsonschema")
        (ch,) = summary.channels.values()
        assert (ch.topic, ch.message_encoding) == ("/meshphase/samples", "json")
        schema = json.loads(sc.data)
        validator = jsonschema.Draft202012Validator(schema)
        _foxglove_parser_accepts(schema)
        got = list(reader.iter_decoded_messages())
    assert len(got) == rec.n_samples
    fields = m.field_names(rec.names)
    assert fields == ["sun_1", "ring_1", "tacho"]  # "ring.1" is no Foxglove message-path name
    assert [schema["properties"]["channels"]["properties"][f]["title"] for f in fields] == rec.names
    start_ns = 1_735_689_600 * 10**9  # 2025-01-01T00:00:00Z
    for k, (_, _, msg, obj) in enumerate(got):
        validator.validate(obj)
        want_ns = m.log_time_ns(k, rec.fs, start_ns + 1_250_000_000)  # start_datetime + t0 + k / fs
        assert msg.log_time == want_ns == obj["timestamp"]["sec"] * 10**9 + obj["timestamp"]["nsec"]
        assert obj["sample"] == k
        for j, field in enumerate(fields):
            if np.isfinite(rec.data[k, j]):
                assert obj["channels"][field] == rec.data[k, j]
            else:
                assert field not in obj["channels"]


def test_foxglove_layout_streaming_and_bad_options(tmp_path):
    rec = _rec(n=1000)
    a = pio.write(rec, tmp_path / "a.mcap", layout="foxglove", topic="/rig/all")
    b = pio.write_blocks(rec, [rec.data[:333], rec.data[333:]], tmp_path / "b.mcap", layout="foxglove",
                         topic="/rig/all")
    assert a.read_bytes() == b.read_bytes()
    assert pio.read(a, fs=rec.fs).n_samples == 1000  # the stored rate may be repeated
    with pytest.raises(ValueError, match="stores its rate"):
        pio.read(a, fs=1.0)
    with pytest.raises(ValueError, match="block sets the samples per message"):
        pio.write(rec, tmp_path / "c.mcap", layout="foxglove", block=100)
    with pytest.raises(ValueError, match="layout"):
        pio.write(rec, tmp_path / "c.mcap", layout="plotjuggler")
    with pytest.raises(ValueError, match="topic names the topic of the foxglove layout"):
        pio.write(rec, tmp_path / "c.mcap", topic="/x")
    with pytest.raises(ValueError, match="compression"):
        pio.write(rec, tmp_path / "c.mcap", layout="foxglove", compression="gzip")
    empty = Recording(np.empty((0, 1)), 10.0, ["a"])
    e = pio.write(empty, tmp_path / "e.mcap", layout="foxglove")
    assert pio.read(e) == empty


def test_nulls_booleans_and_publish_time(tmp_path):
    p = _json_file(tmp_path / "n.mcap", n=30, body=lambda k: {"a": [k, None], "b": None if k == 3 else k,
                                                               "flag": True, "flags": [True, False]})
    rec = pio.read(p, topics={"a": "/rig/strain:a"}, stamp="publish_time")
    assert rec.fs == pytest.approx(2000.0) and np.isnan(rec.data[1::2, 0]).all()
    np.testing.assert_array_equal(rec.data[0::2, 0], np.arange(30))
    assert np.isnan(pio.read(p, topics={"b": "/rig/strain:b"}).data[3, 0])
    with pytest.raises(RecordingFileError, match=r"channel 'a' .*its stamps give 2000 Hz, other channels "
                                                 r"1[0-9.]+ Hz; a recording has one sample rate"):
        pio.read(p, topics={"a": "/rig/strain:a", "b": "/rig/strain:b", "c": "/rig/strain:b"})
    for f in ("flag", "flags"):
        with pytest.raises(RecordingFileError, match="not a number or an array of numbers"):
            pio.read(p, topics={"x": f"/rig/strain:{f}"})
    with pytest.raises(RecordingFileError, match="holds a number, earlier messages a array|holds a array"):
        pio.read(_json_file(tmp_path / "mix.mcap", n=5, body=lambda k: {"v": [1.0] if k else 1.0}),
                 topics={"v": "/rig/strain:v"}, fs=1.0)
    with pytest.raises(RecordingFileError, match="stamp field 'ts' not found"):
        pio.read(p, topics={"b": "/rig/strain:b"}, stamp="ts")
    with pytest.raises(RecordingFileError, match="a stamp is"):
        pio.read(p, topics={"b": "/rig/strain:b"}, stamp="flags")


def test_json_decoder_factory_and_describe_fields(tmp_path):
    f = JsonDecoderFactory()
    assert f.decoder_for("cbor", None) is None
    assert f.decoder_for("json", None)(b'{"x": [1, 2]}') == {"x": [1, 2]}
    p = _json_file(tmp_path / "d.mcap", n=3)
    (t,) = m.describe(p)
    assert (t.topic, t.schema, t.schema_encoding, t.message_encoding, t.messages) == (
        "/rig/strain", "rig.Strain", "jsonschema", "json", 3)
    assert t.fields == [("gauges.sun_T3", "number"), ("gauges.ring", "number"), ("stamp.sec", "number"),
                        ("stamp.nsec", "number")]
    with pytest.raises(FileNotFoundError):
        m.describe(tmp_path / "nope.mcap")


def test_mcap_bench_paths_bad_input(tmp_path):
    from meshphase.bench.mcap_paths import markdown, mcap_path_rows

    assert markdown([], 8, 5120.0) == []
    with pytest.raises(ValueError, match="at least 2 samples"):
        mcap_path_rows(Recording(np.empty((1, 2)), 10.0, ["a", "b"]), tmp_path, lambda fn: (1.0, fn()))
