"""MCAP files written by meshphase read back with the independent TypeScript reader.

``read_mcap.mjs`` uses ``@mcap/core`` (McapIndexedReader, from the npm registry) and decodes
the payload itself from the layout documented in ``data_schemas/mcap.md`` (JSON messages of
the ``foxglove`` layout with ``JSON.parse``); nothing is shared with the Python code. The
first run installs the reader's locked packages (``npm ci`` in this folder) when Node.js and
npm are on PATH; without them the tests are skipped with the reason printed (``-ra``), unless
``MESHPHASE_REQUIRE_INTEROP=1`` (set by ``.ci/run``) turns the skip into a failure.
"""

from __future__ import annotations

import base64
import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

import meshphase.io as pio
from meshphase.io import mcap as m
from meshphase.io.mcap import layout as mlayout
from meshphase.io.mcap import writer as mwriter
from meshphase.recording import ChannelSpec, Recording

pytestmark = pytest.mark.interop

HERE = Path(__file__).resolve().parent
SCRIPT = HERE / "read_mcap.mjs"


def _install() -> str | None:
    """``npm ci`` of the locked reader packages; the reason it could not, or None."""
    npm = shutil.which("npm")
    if npm is None:
        return "npm is not on PATH, so the TypeScript reader (@mcap/core) cannot be installed"
    try:
        res = subprocess.run([npm, "ci", "--no-audit", "--no-fund", "--loglevel=error"], cwd=HERE,
                             capture_output=True, text=True, timeout=600)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return f"`npm ci` in tests/interop failed: {exc}"
    if res.returncode != 0:
        return f"`npm ci` in tests/interop failed: {res.stderr.strip()[-300:]}"
    return None


def _skip_reason() -> str | None:
    if shutil.which("node") is None:
        return "node is not on PATH (the interop test needs Node.js >= 18)"
    if not (HERE / "node_modules" / "@mcap" / "core").is_dir():
        return _install()
    return None


@pytest.fixture(scope="module")
def node():
    reason = _skip_reason()
    if reason:
        if os.environ.get("MESHPHASE_REQUIRE_INTEROP") == "1":
            pytest.fail(f"MESHPHASE_REQUIRE_INTEROP=1 but {reason}")
        pytest.skip(reason)
    return shutil.which("node")


def _node_read(node, path, *args) -> dict:
    res = subprocess.run([node, str(SCRIPT), str(path), *map(str, args)], cwd=HERE,
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, f"read_mcap.mjs failed:\n{res.stderr}"
    return json.loads(res.stdout)


def _recording(dtype, t0) -> Recording:
    rng = np.random.default_rng(2024)
    n = 23_456
    data = (rng.standard_normal((n, 3)) * 1e-5).astype(dtype)
    data[10, 0] = np.nan
    data[20, 1] = -np.inf
    data[30, 2] = -0.0
    specs = [ChannelSpec("sun_1", kind="sun", tooth=4, description="sun root"),
             ChannelSpec("ring_1", kind="ring", units="V", gain=0.25, face_position=-0.005),
             ChannelSpec("tacho", kind="tacho", units="V")]
    return Recording(data, 5120.0, specs, t0=t0, start_datetime="2025-01-01T00:00:00+00:00",
                     meta={"rig": "A", "z": [21, 33, 87]}, history=[{"step": "acquire"}])


def _bits(a):
    a = np.ascontiguousarray(a)
    return a.view(np.uint32 if a.dtype == np.float32 else np.uint64)


@pytest.mark.parametrize("compression", ["none", "lz4", "zstd"])
@pytest.mark.parametrize("dtype, t0", [(np.float64, 0.0), (np.float32, 12.5), (np.float64, -3.0)])
def test_typescript_reader_sees_same_samples_times_and_metadata(node, tmp_path, compression, dtype, t0):
    rec = _recording(dtype, t0)
    block = 2000
    p = pio.write(rec, tmp_path / "r.mcap", block=block, compression=compression, chunk_size=50_000)
    out = _node_read(node, p)

    origin = mlayout.origin_ns(t0)
    assert origin == (12_500_000_000 if t0 == 12.5 else 0)
    starts = list(range(0, rec.n_samples, block))
    want_times = [str(m.log_time_ns(a, rec.fs, origin)) for a in starts]

    # schema, channels and metadata records as documented
    assert [(s["name"], s["encoding"]) for s in out["schemas"]] == [(m.SCHEMA_NAME, m.SCHEMA_ENCODING)]
    assert out["schemas"][0]["data"] == m.LAYOUT
    chans = {c["topic"]: c for c in out["channels"]}
    assert list(chans) == rec.names
    for i, spec in enumerate(rec.channels):
        c = chans[spec.name]
        assert c["messageEncoding"] == m.MESSAGE_ENCODING
        assert c["metadata"] == mwriter._channel_metadata(spec, i, rec.fs, rec.data.dtype.name)
    (md,) = [x for x in out["metadata"] if x["name"] == m.RECORDING_METADATA]
    assert md["metadata"] == mwriter._recording_metadata(rec, block, compression, origin)
    assert float(md["metadata"]["fs"]) == rec.fs and float(md["metadata"]["t0"]) == rec.t0
    assert out["statistics"]["messageCount"] == str(len(starts) * rec.n_channels)

    # samples: bit-exact, in order, at the documented log times
    for j, name in enumerate(rec.names):
        t = out["topics"][name]
        assert t["dtype"] == rec.data.dtype.name
        assert t["contiguous"] and t["nSamples"] == rec.n_samples
        assert t["firstSamples"] == [str(a) for a in starts]
        assert t["logTimes"] == want_times
        got = np.frombuffer(base64.b64decode(t["base64"]), rec.data.dtype.newbyteorder("<"))
        np.testing.assert_array_equal(_bits(got.astype(rec.data.dtype)), _bits(rec.data[:, j]))
        assert t["nNaN"] == int(np.isnan(rec.data[:, j]).sum())
        head = [float(x) if not isinstance(x, str) else float(x.replace("Infinity", "inf"))
                for x in t["head"]]
        np.testing.assert_array_equal(np.array(head, dtype=rec.data.dtype), rec.data[:8, j])

    # and our own reader agrees with itself on the same file
    assert pio.read(p) == rec


def test_time_window_end_is_inclusive_in_typescript_half_open_in_python(node, tmp_path):
    rec = _recording(np.float64, 0.0)
    block = 2000
    p = pio.write(rec, tmp_path / "w.mcap", block=block)
    t_start = m.log_time_ns(1 * block, rec.fs, 0)
    t_end = m.log_time_ns(3 * block, rec.fs, 0)  # exactly the log time of block 3

    out = _node_read(node, p, "--start", t_start, "--end", t_end)
    ts = sorted({int(x["firstSample"]) for x in out["window"]["messages"] if x["topic"] == "sun_1"})
    assert ts == [2000, 4000, 6000]  # @mcap/core: [startTime, endTime], end included

    with open(p, "rb") as fh:
        py = sorted(mlayout.HEADER.unpack_from(x.data)[0] for _, _, x in make_reader(fh).iter_messages(
            topics=["sun_1"], starting_at=t_start, ending_before=t_end))
    assert py == [2000, 4000]  # mcap (Python): [start, end), end excluded

    # meshphase's window read asks for what it needs whatever the convention
    i0, i1 = 2500, 6001
    got = pio.read(p, start=rec.t0 + i0 / rec.fs, stop=rec.t0 + i1 / rec.fs)
    assert got == rec.slice_samples(i0, i1)


@pytest.mark.parametrize("compression", ["none", "zstd"])
def test_typescript_reader_decodes_foxglove_layout(node, tmp_path, compression):
    """The ``foxglove`` layout (data_schemas/mcap.md) through @mcap/core: absolute log times
    (start_datetime + t0 + k / fs in ns since the Unix epoch) and one field per channel named
    for Foxglove's message paths (https://docs.foxglove.dev/docs/visualization/message-path-syntax:
    field names of letters, digits and ``_``)."""
    base = _recording(np.float64, 12.5).slice_samples(0, 1500)
    specs = [ChannelSpec("sun/T3", kind="sun"), ChannelSpec("ring 1.a", kind="ring"), ChannelSpec("sun_T3")]
    rec = Recording(base.data, base.fs, specs, t0=base.t0, start_datetime="2026-03-04T05:06:07.5+01:00")
    p = pio.write(rec, tmp_path / "fox.mcap", layout="foxglove", compression=compression)
    out = _node_read(node, p)
    assert out["topics"] == {}  # no meshphase-block channel
    (topic,) = out["jsonTopics"]
    jt = out["jsonTopics"][topic]
    assert topic == "/meshphase/samples"
    assert (jt["schemaName"], jt["schemaEncoding"]) == (m.FOXGLOVE_SCHEMA_NAME, "jsonschema")
    (schema,) = [s["data"] for s in out["schemas"] if s["name"] == m.FOXGLOVE_SCHEMA_NAME]
    fields = ["sun_T3", "ring_1_a", "sun_T3_2"]
    props = schema["properties"]["channels"]["properties"]
    assert list(props) == fields and [props[f]["title"] for f in fields] == rec.names
    (md,) = [x["metadata"] for x in out["metadata"] if x["name"] == m.FOXGLOVE_METADATA]
    assert md["time_base"] == "start_datetime" and json.loads(md["fields"]) == dict(zip(fields, rec.names))
    origin = 1_772_597_167_500_000_000 + 12_500_000_000  # 2026-03-04T04:06:07.5Z + t0
    assert int(md["log_time_origin_ns"]) == origin
    want_ns = [m.log_time_ns(k, rec.fs, origin) for k in range(rec.n_samples)]
    assert [int(t) for t in jt["logTimes"]] == want_ns
    msgs = jt["messages"]
    assert [x["sample"] for x in msgs] == list(range(rec.n_samples))
    assert [x["timestamp"]["sec"] * 10**9 + x["timestamp"]["nsec"] for x in msgs] == want_ns
    for j, field in enumerate(fields):
        got = np.array([x["channels"].get(field, np.nan) for x in msgs])  # NaN/inf left out
        want = np.where(np.isfinite(rec.data[:, j]), rec.data[:, j], np.nan)
        np.testing.assert_array_equal(got, want)  # finite values bit-exact through JSON
    # the official Python reader sees the same messages at the same times
    with open(p, "rb") as fh:
        py = [(msg.log_time, json.loads(msg.data)) for _, _, msg in make_reader(fh).iter_messages()]
    assert [t for t, _ in py] == want_ns and [d for _, d in py] == msgs
    # and meshphase reads the same file back without a mapping
    back = pio.read(p)
    assert back.fs == rec.fs and back.t0 == rec.t0 and back.names == rec.names
    assert back.start_datetime == rec.start_datetime
    np.testing.assert_array_equal(back.data[np.isfinite(rec.data)], rec.data[np.isfinite(rec.data)])


def test_skip_reason_names_what_is_missing(monkeypatch, tmp_path):
    # runs everywhere: without node (or without npm ci) the tests above are skipped with this
    # reason, which pytest's -ra (pyproject addopts) prints in the summary
    monkeypatch.setattr(shutil, "which", lambda name: None)
    assert "node is not on PATH" in _skip_reason()
    monkeypatch.setattr(shutil, "which", lambda name: "/usr/bin/node" if name == "node" else None)
    monkeypatch.setitem(globals(), "HERE", tmp_path)  # no node_modules here, and no npm to install them
    assert "npm is not on PATH" in _skip_reason()
