"""``describe_topics``: what any MCAP file holds, topic by topic (files written here with the
mcap project's own writers, whose record layout is the MCAP specification's,
https://mcap.dev/spec; ROS 2 messages as ``mcap_ros2.writer`` writes them, CDR per
https://mcap.dev/spec/registry#ros2msg)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from mcap.writer import IndexType, Writer

import meshphase.io as pio
from meshphase.io import RecordingFileError
from meshphase.io import mcap as m
from meshphase.io.base import CorruptFileError
from meshphase.recording import Recording

T0_NS = 1_790_000_000_000_000_000  # 2026-09-21


def _json(path, n=100, fs=1000.0, **writer_kw):
    with open(path, "wb") as fh:
        w = Writer(fh, **writer_kw)
        w.start(profile="", library="test")
        sid = w.register_schema("rig.Strain", "jsonschema", b'{"type": "object"}')
        cid = w.register_channel("/rig/strain", "json", sid)
        other = w.register_channel("/rig/status", "json", 0)
        for k in range(n):
            t = T0_NS + round(k * 1e9 / fs)
            w.add_message(cid, t, json.dumps({"g": {"sun": 0.5 * k, "ring": -k}, "block": [k, k, k],
                                              "label": "x"}).encode(), t)
            if k % 10 == 0:
                w.add_message(other, t, b'{"ok": true, "temp": 21.5}', t)
        w.finish()
    return path


def test_json_topics_counts_rates_spans_and_fields(tmp_path):
    topics = m.describe_topics(_json(tmp_path / "j.mcap"))
    assert [tuple(t) for t in topics] == [m.TOPIC_KEYS] * 2
    strain, status = topics
    assert (strain["topic"], strain["schema"], strain["schema_encoding"], strain["message_encoding"]) == (
        "/rig/strain", "rig.Strain", "jsonschema", "json")
    assert strain["message_count"] == 100 and status["message_count"] == 10
    assert strain["start_ns"] == T0_NS and strain["end_ns"] == T0_NS + 99_000_000
    assert strain["rate_Hz"] == pytest.approx(1000.0, rel=1e-12)
    assert status["rate_Hz"] == pytest.approx(100.0, rel=1e-12) and status["schema"] == ""
    assert strain["numeric_fields"] == [{"path": "g.sun", "length": None}, {"path": "g.ring", "length": None},
                                        {"path": "block", "length": 3}]
    assert status["numeric_fields"] == [{"path": "temp", "length": None}]
    # every listed path reads through a mapping
    rec = pio.read(tmp_path / "j.mcap", topics={"sun": "/rig/strain:g.sun", "ring": "/rig/strain:g.ring"})
    np.testing.assert_array_equal(rec.data[:, 0], 0.5 * np.arange(100))
    assert pio.read(tmp_path / "j.mcap", topics={"b": "/rig/strain:block"}).n_samples == 300


def test_file_without_summary_or_index_is_scanned(tmp_path):
    p = _json(tmp_path / "s.mcap", use_statistics=False, index_types=IndexType.NONE, repeat_channels=False,
              repeat_schemas=False, use_summary_offsets=False)
    plain = m.describe_topics(_json(tmp_path / "i.mcap"))
    assert m.describe_topics(p) == plain
    unchunked = _json(tmp_path / "u.mcap", use_chunking=False, index_types=IndexType.NONE)
    assert m.describe_topics(unchunked) == plain


def test_ros2_topic_fields(tmp_path):
    from mcap_ros2.writer import Writer as Ros2Writer

    p = tmp_path / "r.mcap"
    with open(p, "wb") as fh:
        w = Ros2Writer(fh)
        schema = w.register_msgdef("std_msgs/msg/Float64MultiArray",
                                   "std_msgs/MultiArrayLayout layout\nfloat64[] data\n"
                                   "================================================================================\n"
                                   "MSG: std_msgs/MultiArrayLayout\nuint32 data_offset\n")
        for k in range(5):
            w.write_message("/arr", schema, {"layout": {"data_offset": 0}, "data": [k, 1.0]},
                            log_time=T0_NS + k * 10_000_000)
        w.finish()
    (t,) = m.describe_topics(p)
    assert (t["schema"], t["schema_encoding"], t["message_encoding"]) == (
        "std_msgs/msg/Float64MultiArray", "ros2msg", "cdr")
    assert t["rate_Hz"] == pytest.approx(100.0)
    assert t["numeric_fields"] == [{"path": "layout.data_offset", "length": None}, {"path": "data", "length": 2}]


def test_own_layouts(tmp_path):
    rec = Recording(np.zeros((12_000, 2)), 1000.0, ["a/b", "c"], start_datetime="2026-01-02T03:04:05+00:00")
    own = m.describe_topics(pio.write(rec, tmp_path / "own.mcap"))
    assert [t["topic"] for t in own] == ["a/b", "c"]
    assert all(t["message_encoding"] == m.MESSAGE_ENCODING and t["numeric_fields"] is None for t in own)
    assert [t["message_count"] for t in own] == [3, 3]   # 5120-sample blocks
    fox = m.describe_topics(pio.write(rec, tmp_path / "fox.mcap", layout="foxglove"))
    assert sum(t["message_count"] for t in fox) >= 12_000
    assert all(t["message_encoding"] == "json" and t["numeric_fields"] for t in fox)


def test_one_message_no_messages_and_bad_input(tmp_path):
    (one, none_) = m.describe_topics(_json(tmp_path / "one.mcap", n=1))
    assert one["rate_Hz"] is None and one["start_ns"] == one["end_ns"] == T0_NS
    (zero, _) = m.describe_topics(_json(tmp_path / "zero.mcap", n=0))
    assert zero["message_count"] == 0 and zero["rate_Hz"] is None and zero["start_ns"] is None
    assert zero["numeric_fields"] == []
    empty_mcap = tmp_path / "nochan.mcap"
    with open(empty_mcap, "wb") as fh:
        w = Writer(fh)
        w.start()
        w.finish()
    with pytest.raises(RecordingFileError, match="nochan.mcap.*no channels"):
        m.describe_topics(empty_mcap)
    (tmp_path / "empty.mcap").write_bytes(b"")
    with pytest.raises(CorruptFileError, match="empty.mcap.*truncated"):
        m.describe_topics(tmp_path / "empty.mcap")
    (tmp_path / "text.mcap").write_text("time,a\n0,1\n" * 10)
    with pytest.raises(RecordingFileError, match="not an MCAP file"):
        m.describe_topics(tmp_path / "text.mcap")
    with pytest.raises(FileNotFoundError):
        m.describe_topics(tmp_path / "missing.mcap")
    with pytest.raises(TypeError, match="verify"):
        m.describe_topics(tmp_path / "one.mcap", verify=1)
