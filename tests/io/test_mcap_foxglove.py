"""The ``foxglove`` layout of ``meshphase.io.mcap`` (data_schemas/mcap.md): absolute log
times and channel fields named for Foxglove's message paths
(https://docs.foxglove.dev/docs/visualization/message-path-syntax: ``/topic.field[index]``,
field names ``[a-zA-Z0-9_]+``)."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

import meshphase.io as pio
from meshphase.io.mcap import foreign
from meshphase.io.mcap import describe_topics
from meshphase.io.mcap import foxglove as fx
from meshphase.recording import ChannelSpec, Recording


@pytest.fixture(autouse=True)
def _fresh_cache():
    foreign._CACHE.clear()
    yield
    foreign._CACHE.clear()


def _metadata(path) -> dict:
    with open(path, "rb") as fh:
        (md,) = [r for r in make_reader(fh).iter_metadata() if r.name == fx.FOXGLOVE_METADATA]
    return dict(md.metadata)


def test_field_names_rule():
    assert fx.field_names([]) == []
    got = fx.field_names(["sun/T3", "sun T3", "sun_T3", "", "ring.1", "été", "a[0]", "x"])
    assert got == ["sun_T3", "sun_T3_2", "sun_T3_3", "_", "ring_1", "_t_", "a_0_", "x"]
    assert all(re.fullmatch(r"[A-Za-z0-9_]+", f) for f in got) and len(set(got)) == len(got)
    assert fx.field_names(["a", "a_2", "a"]) == ["a", "a_2", "a_3"]


def test_time_origin_bases():
    assert fx.time_origin(None, 0.0) == (0, "unix_epoch")
    assert fx.time_origin(None, 1.5) == (1_500_000_000, "unix_epoch")
    assert fx.time_origin(None, -2.0) == (0, "unix_epoch")
    assert fx.time_origin("not a date", 1.0) == (1_000_000_000, "unix_epoch")
    assert fx.time_origin("2026-01-01T00:00:00+00:00", 0.0) == (1_767_225_600 * 10**9, "start_datetime")
    # no offset: UTC; an offset is honoured; microseconds and t0 are exact in ns
    assert fx.time_origin("2026-01-01T00:00:00", 0.25)[0] == 1_767_225_600 * 10**9 + 250_000_000
    assert fx.time_origin("2026-01-01T02:00:00.000001+02:00", -1.0)[0] == 1_767_225_599 * 10**9 + 1000
    with pytest.raises(ValueError, match="before 1970"):
        fx.time_origin("1969-12-31T23:59:59+00:00", 0.0)


def test_names_with_slashes_round_trip_and_plot_paths(tmp_path):
    specs = [ChannelSpec("sun/T3", kind="sun", tooth=3), ChannelSpec("sun T3", kind="sun"),
             ChannelSpec("ring.a", kind="ring", units="V")]
    data = np.random.default_rng(3).standard_normal((700, 3)) * 1e-6
    rec = Recording(data, 2000.0, specs, t0=0.5, start_datetime="2026-05-06T07:08:09+00:00",
                    meta={"rig": "B"})
    p = pio.write(rec, tmp_path / "f.mcap", layout="foxglove")
    md = _metadata(p)
    assert md["time_base"] == "start_datetime" and md["format_version"] == "2"
    assert json.loads(md["fields"]) == {"sun_T3": "sun/T3", "sun_T3_2": "sun T3", "ring_a": "ring.a"}
    with open(p, "rb") as fh:
        msgs = list(make_reader(fh).iter_messages())
    start = 1_778_051_289 * 10**9 + 500_000_000  # 2026-05-06T07:08:09Z + t0
    assert msgs[0][2].log_time == start and msgs[1][2].log_time == start + 500_000
    first = json.loads(msgs[0][2].data)
    assert list(first["channels"]) == ["sun_T3", "sun_T3_2", "ring_a"]
    back = pio.read(p)
    assert back.channels == rec.channels and back.t0 == 0.5 and back.start_datetime == rec.start_datetime
    np.testing.assert_array_equal(back.data, rec.data)
    # the topics listing names the plottable fields
    (t,) = describe_topics(p)
    assert [f["path"] for f in t["numeric_fields"]][:5] == ["timestamp.sec", "timestamp.nsec", "sample",
                                                            "channels.sun_T3", "channels.sun_T3_2"]
    assert t["start_ns"] == start


def test_without_start_time_log_times_count_from_the_epoch(tmp_path):
    rec = Recording(np.arange(20.0).reshape(10, 2), 100.0, ["a", "b"], t0=3.0)
    p = pio.write(rec, tmp_path / "e.mcap", layout="foxglove")
    md = _metadata(p)
    assert md["time_base"] == "unix_epoch" and "start_datetime" not in md
    assert md["log_time_origin_ns"] == "3000000000"
    assert pio.read(p) == rec


def test_before_1970_is_refused(tmp_path):
    rec = Recording(np.zeros((3, 1)), 10.0, ["a"], start_datetime="1960-01-01T00:00:00+00:00")
    with pytest.raises(ValueError, match="before 1970"):
        pio.write(rec, tmp_path / "old.mcap", layout="foxglove")


def test_format_1_files_keyed_by_channel_name_still_read(tmp_path):
    # a format-1 file: fields named as the channels, no "fields" entry, log times from t0
    p = tmp_path / "v1.mcap"
    specs = [ChannelSpec("ring.1", kind="ring")]
    with open(p, "wb") as fh:
        w = Writer(fh)
        w.start()
        sid = w.register_schema(fx.FOXGLOVE_SCHEMA_NAME, "jsonschema", b'{"type": "object"}')
        cid = w.register_channel("/meshphase/samples", "json", sid)
        w.add_metadata(fx.FOXGLOVE_METADATA, {
            "format_version": "1", "topic": "/meshphase/samples", "fs": "10.0", "t0": "0.0", "n_samples": "4",
            "dtype": "float64", "log_time_origin_ns": "0", "channels": json.dumps([s.to_dict() for s in specs]),
            "meta": "{}", "history": "[]"})
        for k in range(4):
            t = k * 100_000_000
            w.add_message(cid, t, json.dumps({"timestamp": {"sec": 0, "nsec": t}, "sample": k,
                                              "channels": {"ring.1": k / 4}}).encode(), t)
        w.finish()
    back = pio.read(p)
    assert back.names == ["ring.1"]
    np.testing.assert_array_equal(back.data[:, 0], np.arange(4) / 4)
