"""Writing a recording as MCAP that Foxglove (and any MCAP tool) can open and plot: one
self-describing JSON message per sample time (schema encoding ``jsonschema``, message
encoding ``json``), all channels as fields of it (``data_schemas/mcap.md``, layout
``foxglove``).

Log times are absolute: sample k of a recording with a start time is stamped
``start_datetime + t0 + k / fs`` in nanoseconds since the Unix epoch, so Foxglove's timeline
shows the wall-clock time of the test; without a start time (or with one that is not ISO
8601) the stamps count from the epoch (``t0 + k / fs``), and the Metadata record says which
(``time_base``).

Foxglove's message paths (``/topic.field.sub``, https://docs.foxglove.dev/docs/visualization/message-path-syntax)
take field names of letters, digits and ``_`` only, so each channel is a field named by
:func:`field_names` (every other character replaced by ``_``, a repeat suffixed ``_2``, ``_3``
...), with the channel's own name as the field's ``title`` in the schema and in the Metadata
record's ``fields`` map; a channel ``sun/T3`` plots as ``/meshphase/samples.channels.sun_T3``.

Foxglove's Plot panel draws one value per message against the message's log time (or a
``header.stamp``-like field), and arrays only against their index: a time series therefore
needs one message per sample time. That costs ~100 bytes and one record per sample time, so
this layout is an export for viewing; meshphase's own block layout stays the default.

The file also carries a ``meshphase.foxglove`` Metadata record (fs, t0, channel specs, meta,
history) so that :func:`meshphase.io.read` reads it back without a mapping, through the
generic decoder path.
"""

from __future__ import annotations

import datetime as _dt
import json
import re

import numpy as np

from mcap.well_known import MessageEncoding, SchemaEncoding
from mcap.writer import LIBRARY_IDENTIFIER, CompressionType, IndexType, Writer

from ...validate import as_choice
from ..base import regroup_blocks
from .layout import DTYPE_CODES, MAX_LOG_TIME, COMPRESSIONS, dumps_metadata, log_time, origin_ns

__all__ = ["write_foxglove", "FOXGLOVE_METADATA", "FOXGLOVE_SCHEMA_NAME", "DEFAULT_TOPIC", "LAYOUTS",
           "field_names", "time_origin", "TIME_BASES"]

#: Layouts of :func:`meshphase.io.mcap.write`: meshphase's own blocks, or Foxglove-plottable JSON.
LAYOUTS = ("meshphase", "foxglove")
#: Name of the JSON schema of one sample-time message.
FOXGLOVE_SCHEMA_NAME = "meshphase.Sample"
#: Name of the Metadata record with the recording header of a ``foxglove`` layout file.
FOXGLOVE_METADATA = "meshphase.foxglove"
#: Topic of the sample messages by default.
DEFAULT_TOPIC = "/meshphase/samples"
#: ``time_base`` of the Metadata record: log times from the recording's start time, or from
#: the Unix epoch when it has none.
TIME_BASES = ("start_datetime", "unix_epoch")
_FORMAT_VERSION = 2
_ROWS = 4096  # sample times formatted at once
_EPOCH = _dt.datetime(1970, 1, 1, tzinfo=_dt.timezone.utc)


def field_names(names) -> list[str]:
    """The message field of each channel: its name with every character other than ASCII
    letters, digits and ``_`` replaced by ``_`` (``""`` becomes ``_``), a name already taken
    suffixed ``_2``, ``_3``, ... (in channel order), so that each is a Foxglove message-path
    name (``[a-zA-Z0-9_]+``)."""
    out: list[str] = []
    taken: set = set()
    for name in names:
        base = re.sub(r"[^A-Za-z0-9_]", "_", str(name)) or "_"
        field, k = base, 1
        while field in taken:
            k += 1
            field = f"{base}_{k}"
        taken.add(field)
        out.append(field)
    return out


def time_origin(start_datetime, t0: float) -> tuple[int, str]:
    """(log time of sample 0 [ns since the Unix epoch], time base) of a ``foxglove`` file.

    ``start_datetime`` (ISO 8601; without a UTC offset it is taken as UTC) + ``t0`` when the
    start time is known, else ``t0`` from the epoch (``"unix_epoch"``; a negative or too
    large ``t0`` gives 0, as the block layout's origin).

    Raises
    ------
    ValueError
        A start time before 1970-01-01 plus ``t0`` (no unsigned MCAP log time).
    """
    if start_datetime is not None:
        try:
            d = _dt.datetime.fromisoformat(str(start_datetime))
        except ValueError:
            d = None
        if d is not None:
            if d.tzinfo is None:
                d = d.replace(tzinfo=_dt.timezone.utc)
            delta = d - _EPOCH
            ns = (delta.days * 86_400 + delta.seconds) * 1_000_000_000 + delta.microseconds * 1000
            origin = ns + int(round(float(t0) * 1e9))
            if origin < 0:
                raise ValueError(f"start_datetime {start_datetime!r} + t0 = {t0!r} s is before 1970-01-01: "
                                 f"MCAP log times are unsigned nanoseconds since the Unix epoch")
            return origin, "start_datetime"
    return origin_ns(t0), "unix_epoch"


def sample_schema(specs, fields=None) -> dict:
    """The JSON schema of one message: ``timestamp`` {sec, nsec}, ``sample`` index and one
    number per channel under ``channels`` (absent where the sample is NaN or inf), keyed by
    ``fields`` (:func:`field_names` of the channel names by default), titled by the channel
    name.

    Only what Foxglove's JSON Schema parser accepts: ``"type"`` a single string (it refuses
    lists such as ``["number", "null"]`` and ``"null"``), objects with ``properties``."""
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": FOXGLOVE_SCHEMA_NAME,
        "description": "One sample time of a meshphase recording: every channel's value.",
        "type": "object",
        "properties": {
            "timestamp": {"title": "time", "type": "object", "description": "time of the sample",
                          "properties": {"sec": {"type": "integer", "minimum": 0},
                                         "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}},
                          "required": ["sec", "nsec"]},
            "sample": {"type": "integer", "minimum": 0, "description": "sample index in the recording"},
            "channels": {"type": "object", "additionalProperties": False,
                         "properties": {f: {"type": "number", "title": s.name,
                                            "description": f"channel {s.name!r}: {s.kind} [{s.units}]; absent: "
                                                           f"NaN or inf"}
                                        for f, s in zip(fields or field_names([s.name for s in specs]), specs)}},
        },
        "required": ["timestamp", "sample", "channels"],
    }


def _header_metadata(rec, topic: str, dtype_name: str, origin: int, base: str, fields: list) -> dict:
    md = {"format_version": str(_FORMAT_VERSION), "topic": topic, "fs": repr(float(rec.fs)),
          "t0": repr(float(rec.t0)), "n_samples": str(int(rec.n_samples)), "dtype": dtype_name,
          "log_time_origin_ns": str(origin), "time_base": base,
          "channels": json.dumps([s.to_dict() for s in rec.channels]),
          "fields": json.dumps(dict(zip(fields, [s.name for s in rec.channels]))),
          "meta": dumps_metadata(rec.meta, "meta"), "history": dumps_metadata(rec.history, "history")}
    if rec.start_datetime is not None:
        md["start_datetime"] = rec.start_datetime
    return md


def write_foxglove(header, blocks, path, *, dtype="float64", compression: str = "zstd",
                   topic: str = DEFAULT_TOPIC, chunk_size: int = 1 << 20) -> None:
    """Write samples as one JSON message per sample time on one topic (streaming).

    Parameters
    ----------
    header : Recording, RecordingInfo or alike
        ``fs``, ``t0``, ``n_samples``, ``channels``, ``start_datetime``, ``meta``, ``history``.
    blocks : iterable of ndarray, shape (k, n_channels)
        The samples in order, together ``header.n_samples`` rows.
    path : str or Path
    dtype : {"float32", "float64"}
        Type the samples are read back as (JSON numbers hold either exactly).
    compression : {"none", "lz4", "zstd"}
        Chunk compression (default zstd: JSON text compresses ~3-5x).
    topic : str
        Topic of the messages.
    chunk_size : int
        Target uncompressed chunk size [B].

    Notes
    -----
    Message k: ``{"timestamp": {"sec": s, "nsec": ns}, "sample": k, "channels": {field:
    value, ...}}`` (fields: :func:`field_names`) with ``log_time = publish_time`` = that
    timestamp = ``log_time_origin_ns + floor(k * 1e9 / fs)``, the origin from
    :func:`time_origin` (the start time + t0 in ns since the Unix epoch). Values are written
    with Python's shortest round-trip ``repr``, so finite values read back bit-exact (-0.0
    included); a NaN or +-inf sample is left out of its message (JSON has no NaN, and
    Foxglove's schema parser takes no ``null`` type) and reads back as NaN.
    """
    compression = as_choice(compression, "compression", COMPRESSIONS)
    if not isinstance(topic, str) or not topic:
        raise ValueError(f"topic must be a non-empty string, got {topic!r}")
    dtype_name = np.dtype(dtype).name
    if dtype_name not in DTYPE_CODES:
        raise TypeError(f"recording data must be float32 or float64, got {np.dtype(dtype)}")
    specs = list(header.channels)
    nch, n = len(specs), int(header.n_samples)
    origin, base = time_origin(header.start_datetime, header.t0)
    if n and log_time(n - 1, header.fs, origin) > MAX_LOG_TIME:
        raise ValueError(f"recording too long for MCAP uint64 nanosecond log times: {n} samples")
    fields = field_names([s.name for s in specs])
    md = _header_metadata(header, topic, dtype_name, origin, base, fields)
    comp = {"none": CompressionType.NONE, "lz4": CompressionType.LZ4, "zstd": CompressionType.ZSTD}[compression]
    names = [json.dumps(f) for f in fields]
    with open(path, "wb") as fh:
        w = Writer(fh, chunk_size=chunk_size, compression=comp, index_types=IndexType.ALL,
                   use_chunking=True, use_statistics=True, use_summary_offsets=True,
                   enable_crcs=True, enable_data_crcs=True)
        w.start(profile="", library=f"meshphase-mcap-foxglove/{_FORMAT_VERSION}; {LIBRARY_IDENTIFIER}")
        sid = w.register_schema(FOXGLOVE_SCHEMA_NAME, SchemaEncoding.JSONSchema,
                                json.dumps(sample_schema(specs, fields)).encode("utf-8"))
        cid = w.register_channel(topic, MessageEncoding.JSON, sid,
                                 {"fs": repr(float(header.fs)), "channels": json.dumps([s.name for s in specs]),
                                  "fields": json.dumps(fields)})
        w.add_metadata(FOXGLOVE_METADATA, md)
        for group, s0 in regroup_blocks(blocks, nch, n, _ROWS, np.dtype(dtype_name)):
            _put_rows(w, cid, names, group, s0, header.fs, origin)
        w.finish()


def _put_rows(w: Writer, cid: int, names: list, group: np.ndarray, s0: int, fs: float,
              origin: int) -> None:
    """One message per column of ``group`` (channels x samples), samples s0, s0 + 1, ...;
    ``names``: the channels' fields as JSON strings. A NaN or inf sample is left out."""
    head = '{"timestamp":{"sec":%d,"nsec":%d},"sample":%d,"channels":{'
    every = head + ",".join(f"{nm}:%r" for nm in names) + "}}"
    finite = np.isfinite(group)
    whole = finite.all(axis=0).tolist()
    cols = group.astype(np.float64).T.tolist()
    for j, vals in enumerate(cols):
        k = s0 + j
        t = log_time(k, fs, origin)
        stamp = (t // 1_000_000_000, t % 1_000_000_000, k)
        if whole[j]:
            text = every % (stamp + tuple(vals))
        else:
            text = (head % stamp + ",".join(f"{nm}:{v!r}" for nm, v, ok in zip(names, vals, finite[:, j])
                                            if ok) + "}}")
        w.add_message(cid, t, text.encode("utf-8"), t, sequence=k & 0xFFFFFFFF)
