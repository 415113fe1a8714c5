"""Reading MCAP files written by other tools (ROS 2, Foxglove bridges, DAQ loggers): their
messages are decoded by the mcap project's decoders (JSON here, protobuf by
``mcap-protobuf-support``, ROS 2 CDR by ``mcap-ros2-support``) and the mapped fields
(:mod:`.mapping`) become channels of one uniform-rate recording (:mod:`.timing`). What any
MCAP file holds, topic by topic, for writing a mapping: :func:`describe_topics`.

JSON and ROS 2 CDR topics are decoded a chunk at a time by :mod:`.bulk` where it can; the
rest (protobuf, the fields and files it leaves) message by message through
``McapReader.iter_decoded_messages`` and Python objects, which is also the path that reports
every error (``meshphase bench io`` measures both against meshphase's own block layout). A
decoded file is kept (one at a time, by file identity and mapping) so that the registry's
``read_info`` + ``read`` decode it once.
"""

from __future__ import annotations

import copy
import datetime as _dt
import json
import math
import os
import threading
from collections import OrderedDict
from pathlib import Path

import numpy as np

from mcap.decoder import DecoderFactory
from mcap.exceptions import DecoderNotFoundError
from mcap.reader import make_reader
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader

from ...recording import ChannelSpec, Recording
from ..base import RecordingFileError, RecordingInfo, check_verify
from .bulk import Series, collect_bulk
from .foxglove import FOXGLOVE_METADATA
from .header import check_ends, lib_errors
from .chunks import read_message_index
from .mapping import (FieldError, TopicField, TopicSummary, as_values, get_field, mapping_key, numeric_fields,
                      parse_topics, stamp_ns)
from .timing import fit_grid

__all__ = ["read_foreign", "describe", "describe_topics", "TOPIC_KEYS", "JsonDecoderFactory", "decoder_factories",
           "FOREIGN_OPTIONS", "clear_cache"]

#: Format options of the foreign path (besides ``verify``).
FOREIGN_OPTIONS = ("topics", "fs", "max_jitter", "stamp")
#: Keys of each dict :func:`describe_topics` returns, in order.
TOPIC_KEYS = ("topic", "schema", "schema_encoding", "message_encoding", "message_count", "rate_Hz",
              "start_ns", "end_ns", "numeric_fields")
_EPOCH_NS = 10 ** 18  # stamps from 2001-09-09 on are taken as Unix time (start_datetime)


class JsonDecoderFactory(DecoderFactory):
    """Decoder of ``json`` messages (schema ``jsonschema`` or none) for ``mcap``'s readers."""

    def decoder_for(self, message_encoding, schema):
        if message_encoding != "json":
            return None
        return lambda data: json.loads(bytes(data).decode("utf-8"))


def decoder_factories() -> list:
    """The decoders of the foreign path: JSON, protobuf and ROS 2 (CDR)."""
    # protobuf's runtime and the ROS 2 message parser load in ~0.1 s: only foreign files need them
    from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory
    from mcap_ros2.decoder import DecoderFactory as Ros2DecoderFactory

    return [JsonDecoderFactory(), ProtobufDecoderFactory(), Ros2DecoderFactory()]


def describe(path, *, verify: bool = True) -> list[TopicSummary]:
    """What an MCAP file holds, topic by topic, for writing a mapping (the listing of a
    missing mapping's error): :func:`describe_topics` as :class:`TopicSummary` records, an
    empty list for a file without channels.

    Parameters
    ----------
    path : str or Path
    verify : bool
        Check chunk CRCs of what is read (default True).

    Returns
    -------
    list of TopicSummary
        Per topic: schema name and encoding, message encoding, message count, and the numeric
        fields of its first message (decoded with :func:`decoder_factories`; JSON, protobuf
        and ROS 2) as (field path, ``"number"`` or ``"array[n]"``), None without a decoder.
    """
    out = []
    for row in _topic_rows(Path(path), check_verify(verify)):
        fields = row["numeric_fields"]
        if fields is not None:
            fields = [(f["path"], "number" if f["length"] is None else f"array[{f['length']}]")
                      for f in fields]
        out.append(TopicSummary(topic=row["topic"], schema=row["schema"],
                                schema_encoding=row["schema_encoding"],
                                message_encoding=row["message_encoding"],
                                messages=row["message_count"], fields=fields))
    return out


def _spans_from_index(fh, path: Path, summary, counts: dict) -> dict | None:
    """{channel id: (start_ns, end_ns)} from the chunks' message indexes, or None when the
    file has messages without index (then the caller scans)."""
    spans: dict = {}
    seen = dict.fromkeys(counts, 0)
    for ci in summary.chunk_indexes:
        for cid, off in (ci.message_index_offsets or {}).items():
            entries = read_message_index(fh, path, off, cid)
            if entries is None:
                return None
            t = entries[:, 0]
            if t.size:
                lo, hi = int(t.min()), int(t.max())
                a, b = spans.get(cid, (lo, hi))
                spans[cid] = (min(a, lo), max(b, hi))
                seen[cid] = seen.get(cid, 0) + int(t.size)
    if any(seen.get(cid, 0) != n for cid, n in counts.items()):
        return None  # messages outside chunks, or chunks without indexes
    return spans


def _scan(path: Path, verify: bool) -> tuple[dict, dict, dict, dict]:
    """(schemas, channels, counts, spans) from reading every record once."""
    schemas, channels, counts, spans = {}, {}, {}, {}
    with open(path, "rb") as fh, lib_errors(path, "scanning the records"):
        for rec in StreamReader(fh, validate_crcs=verify).records:
            if isinstance(rec, Message):
                c = rec.channel_id
                counts[c] = counts.get(c, 0) + 1
                a, b = spans.get(c, (rec.log_time, rec.log_time))
                spans[c] = (min(a, rec.log_time), max(b, rec.log_time))
            elif isinstance(rec, Channel):
                channels[rec.id] = rec
            elif isinstance(rec, Schema):
                schemas[rec.id] = rec
    return schemas, channels, counts, spans


def _fields(reader, factories: list, channel, schema, n: int):
    """The numeric fields of the first message of ``channel`` (None: no decoder)."""
    if not any(f.decoder_for(channel.message_encoding, schema) is not None for f in factories):
        return None
    found: list = []
    if n:
        try:
            for _, _, _, decoded in reader.iter_decoded_messages(topics=[channel.topic], log_time_order=False):
                numeric_fields(decoded, (), found)
                break
        except DecoderNotFoundError:
            return None
    return [{"path": p, "length": None if kind == "number" else int(kind[len("array["):-1])}
            for p, kind in found]


def describe_topics(path, *, verify: bool = True) -> list[dict]:
    """What an MCAP file holds, one dict per topic (MCAP channel), in channel-id order.

    Parameters
    ----------
    path : str or Path
        Any MCAP file: another tool's (ROS 2 CDR, protobuf, JSON), meshphase's block layout
        or its ``foxglove`` layout; with or without a summary section.
    verify : bool
        Check the CRCs of what is read (default True).

    Returns
    -------
    list of dict
        Keys (:data:`TOPIC_KEYS`):

        * ``topic`` (str), ``schema`` (schema name, ``""`` without a schema),
          ``schema_encoding`` (``""`` without a schema), ``message_encoding``;
        * ``message_count`` (int);
        * ``rate_Hz`` (float or None): ``(message_count - 1) / (end_ns - start_ns) * 1e9``
          [messages/s], None with fewer than 2 messages or all at one time;
        * ``start_ns``, ``end_ns`` (int or None): first and last log time [ns since the
          Unix epoch, or whatever origin the writer used], None without messages;
        * ``numeric_fields``: from decoding the topic's first message, a list of
          ``{"path": str, "length": int or None}``; ``path`` is what a scene's
          ``[[input.mcap.channels]] field`` takes, ``length`` is None for a number (one
          sample per message) and the element count for an array of numbers (consecutive
          samples per message; ``path[i]`` picks element i). ``[]`` when the first message
          has no numeric field or the topic has no message; None when no decoder knows the
          message encoding (meshphase's own ``meshphase-block`` layout, which needs no
          mapping, among them).

    Raises
    ------
    RecordingFileError
        Not an MCAP file, an empty or truncated one (:class:`CorruptFileError`), a malformed
        record, or a file without channels; each names the file.
    FileNotFoundError
        No such file.
    """
    path = Path(path)
    rows = _topic_rows(path, check_verify(verify))
    if not rows:
        raise RecordingFileError(path, "the MCAP file has no channels (no topics): nothing to "
                                       "list or read")
    return rows


def _topic_rows(path: Path, verify: bool) -> list[dict]:
    """:func:`describe_topics`'s rows, an empty list for a file without channels."""
    with open(path, "rb") as fh:
        check_ends(fh, path)
        with lib_errors(path, "listing topics"):
            factories = decoder_factories()
            reader = make_reader(fh, validate_crcs=verify, decoder_factories=factories)
            summary = reader.get_summary()
            spans = None
            if summary is not None and summary.statistics is not None:
                schemas, channels = dict(summary.schemas), dict(summary.channels)
                counts = {cid: int(summary.statistics.channel_message_counts.get(cid, 0)) for cid in channels}
                spans = _spans_from_index(fh, path, summary, counts)
            if spans is None:
                schemas, channels, counts, spans = _scan(path, verify)
            out = []
            for cid in sorted(channels):
                ch = channels[cid]
                sc = schemas.get(ch.schema_id)
                n = counts.get(cid, 0)
                start, end = spans.get(cid, (None, None))
                rate = (n - 1) / (end - start) * 1e9 if n >= 2 and end > start else None
                out.append({"topic": ch.topic, "schema": sc.name if sc else "",
                            "schema_encoding": sc.encoding if sc else "",
                            "message_encoding": ch.message_encoding, "message_count": n,
                            "rate_Hz": rate, "start_ns": start, "end_ns": end,
                            "numeric_fields": _fields(reader, factories, ch, sc, n)})
    return out


def listing(topics: list[TopicSummary]) -> str:
    """The text of :func:`describe`'s result, one line per topic."""
    if not topics:
        return "the file has no topics (no MCAP channels)"
    lines = []
    for t in topics:
        fields = ("no decoder for this encoding" if t.fields is None
                  else ", ".join(f"{p} ({k})" for p, k in t.fields) or "no numeric fields")
        lines.append(f"  {t.topic}: schema {t.schema or '(none)'} ({t.schema_encoding or 'none'}), "
                     f"messages {t.message_encoding}, {t.messages if t.messages is not None else '?'} "
                     f"message(s); numeric fields: {fields}")
    return "\n".join(lines)


def no_mapping_error(path: Path, verify: bool) -> RecordingFileError:
    """The error for a foreign MCAP opened without a mapping: what it holds, and how to map it."""
    text = listing(describe(path, verify=verify))
    return RecordingFileError(
        path, "not a meshphase recording: an MCAP file written by another tool (no "
              "meshphase block layout): say which topic "
              "fields are channels, e.g. meshphase.io.read(path, topics={'sun_T3': "
              "'/rig/strain:gauges.sun_T3'}) or a scene's [[input.mcap.channels]] table "
              "(data_schemas/mcap.md). The file holds:\n" + text)


# -- decoding and assembling -------------------------------------------------------------

def _collect(reader, path: Path, entries: list[TopicField], fh=None, verify: bool = True) -> dict:
    """Per entry name: (stamps [ns] list, values list of float or 1-D arrays) in message
    order, or a :class:`~.bulk.Series` for the entries the per-chunk path decodes
    (:func:`~.bulk.collect_bulk`, given the open file ``fh``). Checks every mapped topic
    exists and has messages, fields exist and are numeric, and each field keeps its shape
    (number or array) from message to message."""
    summary = reader.get_summary()
    present = sorted({c.topic for c in summary.channels.values()}) if summary is not None else None
    wanted = sorted({e.topic for e in entries})
    if present is not None:
        missing = [t for t in wanted if t not in present]
        if missing:
            raise RecordingFileError(path, f"topic(s) {missing} not in the file; topics present: "
                                           f"{present or 'none'}")
    done: dict = {}
    if fh is not None:
        done, entries = collect_bulk(fh, path, summary, entries, decoder_factories(), verify=verify)
        if not entries:
            return done
        wanted = sorted({e.topic for e in entries})
    by_topic: dict = {}
    for e in entries:
        by_topic.setdefault(e.topic, []).append(e)
    got = {e.name: ([], []) for e in entries}
    shape: dict = {}
    try:
        # file order (log_time_order=False skips the library's heap merge, ~40 % of the time);
        # each channel's messages are put in stamp order in _series
        for _, channel, msg, decoded in reader.iter_decoded_messages(topics=wanted, log_time_order=False):
            for e in by_topic.get(channel.topic, ()):
                stamps, values = got[e.name]
                try:
                    raw = get_field(decoded, e.path)
                except FieldError as exc:
                    if e.missing_is_nan:
                        stamps.append(msg.log_time)  # the foxglove layout stamps by log time
                        values.append(math.nan)
                        continue
                    found: list = []
                    numeric_fields(decoded, (), found)
                    raise RecordingFileError(path, f"{_where(e)}: message {len(stamps)} has no field "
                                                   f"{str(exc)!r}; numeric fields of that message: "
                                                   f"{', '.join(p for p, _ in found) or 'none'}") from None
                v = as_values(raw)
                if v is None:
                    raise RecordingFileError(path, f"{_where(e)}: message {len(stamps)} holds "
                                                   f"{type(raw).__name__} {str(raw)[:60]!r}, not a number "
                                                   f"or an array of numbers")
                kind = "number" if isinstance(v, float) else "array"
                if shape.setdefault(e.name, kind) != kind:
                    raise RecordingFileError(path, f"{_where(e)}: message {len(stamps)} holds a {kind}, "
                                                   f"earlier messages a {shape[e.name]}")
                stamps.append(stamp_ns(e.stamp, msg, decoded, _where(e)) if not isinstance(e.stamp, str)
                              else msg.log_time if e.stamp == "log_time" else msg.publish_time)
                values.append(v)
    except DecoderNotFoundError as exc:
        raise RecordingFileError(path, f"cannot decode the messages of a mapped topic: {exc}; "
                                       f"decoded here: json, protobuf, cdr (ros2msg)") from None
    for e in entries:
        if not got[e.name][0]:
            raise RecordingFileError(path, f"channel {e.name!r}: topic {e.topic!r} has no messages")
    got.update(done)
    return got


def _where(e: TopicField) -> str:
    return f"channel {e.name!r} (topic {e.topic!r}, field {e.field!r})"


def _series(collected):
    """(stamps ns int64, counts, samples float64) of one channel, in stamp order (stable:
    messages with equal stamps keep their order in the file); ``collected`` is what
    :func:`_collect` holds for the channel."""
    if isinstance(collected, Series):
        t, counts, samples = collected.stamps, collected.counts, collected.samples
        if counts is None:
            counts = np.ones(t.size, dtype=np.int64)
        if np.any(t[1:] < t[:-1]):
            order = np.argsort(t, kind="stable")
            if not np.all(counts == counts[0]):
                starts = np.concatenate(([0], np.cumsum(counts)[:-1]))
                samples = np.concatenate([samples[starts[i]:starts[i] + counts[i]] for i in order])
            else:
                samples = samples.reshape(t.size, -1)[order].reshape(-1)
            t, counts = t[order], counts[order]
        return t, counts, samples
    stamps, values = collected
    t = np.asarray(stamps, dtype=np.int64)
    if isinstance(values[0], float):
        counts = np.ones(t.size, dtype=np.int64)
        parts = None
        samples = np.asarray(values, dtype=np.float64)
    else:
        counts = np.array([v.size for v in values], dtype=np.int64)
        parts = values
        samples = None
    if np.any(t[1:] < t[:-1]):
        order = np.argsort(t, kind="stable")
        t, counts = t[order], counts[order]
        if parts is None:
            samples = samples[order]
        else:
            parts = [parts[i] for i in order]
    if samples is None:
        samples = np.concatenate(parts) if parts else np.empty(0)
    return t, counts, samples


def _assemble(path: Path, entries: list[TopicField], got: dict, fs, max_jitter) -> tuple:
    """(data, fs, origin_ns, notes) of the mapped channels on one uniform grid.

    Each channel's stamps are fitted to a uniform grid (:func:`fit_grid`); without ``fs`` each
    channel's own rate is derived first, their median is the recording's rate and every
    channel is checked against it. The channels then start at the latest first sample
    and end at the earliest last one (whole samples; a start offset off the grid by more
    than ``max_jitter`` is an error)."""
    series = {e.name: _series(got[e.name]) for e in entries}
    what = {e.name: _where(e) for e in entries}
    given = fs is not None
    try:
        own = {} if given else {k: fit_grid(t, c, max_jitter=max_jitter, what=what[k]).fs
                                for k, (t, c, _) in series.items()}
        fs = fs if given else float(np.median(list(own.values())))
        grids = {}
        for k, (t, c, _) in series.items():
            try:
                grids[k] = fit_grid(t, c, fs=fs, max_jitter=max_jitter, what=what[k])
            except ValueError:
                if given or abs(own[k] - fs) <= 1e-9 * fs:
                    raise
                raise ValueError(f"{what[k]}: its stamps give {own[k]:.10g} Hz, other channels "
                                 f"{fs:.10g} Hz; a recording has one sample rate: map channels of "
                                 f"one rate together (rates: " + ", ".join(
                                     f"{n} {r:.10g} Hz" for n, r in own.items()) + ")") from None
    except ValueError as exc:
        raise RecordingFileError(path, str(exc)) from None
    origin = max(g.origin_ns for g in grids.values())
    tol = 0.5 if max_jitter is None else float(max_jitter) * fs  # [samples]
    offsets = {}
    for k, g in grids.items():
        off = (origin - g.origin_ns) * 1e-9 * fs
        o = int(round(off))
        if abs(off - o) > tol:
            raise RecordingFileError(path, f"{what[k]} starts {abs(off - o):.3g} samples off the sample "
                                           f"grid of the other channels (fs = {fs:.10g} Hz): the "
                                           f"channels are not sampled together")
        offsets[k] = o
    n = min(g.n_samples - offsets[k] for k, g in grids.items())
    if n <= 0:
        raise RecordingFileError(path, "the mapped channels do not overlap in time: "
                                       + "; ".join(f"{what[k]} covers {g.origin_ns} ns + {g.n_samples} "
                                                   f"samples" for k, g in grids.items()))
    data = np.empty((n, len(entries)), dtype=np.float64, order="F")
    for j, e in enumerate(entries):
        o = offsets[e.name]
        data[:, j] = series[e.name][2][o:o + n]
        if e.scale != 1.0:
            data[:, j] *= e.scale
    notes = {k: {"dropped_start": offsets[k], "dropped_end": grids[k].n_samples - offsets[k] - n,
                 "max_stamp_residual_s": grids[k].max_residual} for k in grids}
    return data, fs, origin, notes


def _embedded(reader, path: Path):
    """(mapping, header map) of a file meshphase wrote in the ``foxglove`` layout, else None."""
    with lib_errors(path, "reading metadata records"):
        recs = [m for m in reader.iter_metadata() if m.name == FOXGLOVE_METADATA]
    if not recs:
        return None
    md = dict(recs[0].metadata)
    try:
        specs = [ChannelSpec.from_dict(d) for d in json.loads(md["channels"])]
        # format 1 keyed the fields by channel name, format 2 by field_names() ("fields")
        fields = list(json.loads(md["fields"])) if "fields" in md else [s.name for s in specs]
        if len(fields) != len(specs):
            raise ValueError(f"{len(fields)} fields for {len(specs)} channels")
        entries = [TopicField(spec=s, topic=md["topic"], path=("channels", f), missing_is_nan=True)
                   for s, f in zip(specs, fields)]
        header = {"fs": float(md["fs"]), "t0": float(md["t0"]), "n_samples": int(md["n_samples"]),
                  "dtype": md["dtype"], "meta": json.loads(md["meta"]), "history": json.loads(md["history"]),
                  "start_datetime": md.get("start_datetime")}
    except (KeyError, TypeError, ValueError) as exc:
        raise RecordingFileError(path, f"Metadata record {FOXGLOVE_METADATA!r}: {exc}") from None
    if header["dtype"] not in ("float32", "float64"):
        raise RecordingFileError(path, f"Metadata record {FOXGLOVE_METADATA!r}: dtype {header['dtype']!r}")
    return entries, header


def _written_back(path: Path, data: np.ndarray, entries: list, header: dict) -> Recording:
    """The recording a ``foxglove`` layout file holds (its header from the Metadata record)."""
    if data.shape[0] != header["n_samples"]:
        raise RecordingFileError(path, f"{data.shape[0]} sample times decoded, the "
                                       f"{FOXGLOVE_METADATA!r} record says {header['n_samples']}")
    return Recording(data.astype(header["dtype"], order="F"), header["fs"], [e.spec for e in entries],
                     t0=header["t0"], start_datetime=header["start_datetime"], meta=header["meta"],
                     history=header["history"])


def _decode_file(path: Path, entries, fs, max_jitter, verify: bool) -> Recording:
    """The whole mapped recording of a foreign file (``entries`` None: the embedded mapping
    of a ``foxglove`` layout file, else the no-mapping error)."""
    header = None
    with open(path, "rb") as fh, lib_errors(path, "decoding messages"):
        check_ends(fh, path)
        reader = make_reader(fh, validate_crcs=verify, decoder_factories=decoder_factories())
        if entries is None:
            emb = _embedded(reader, path)
            if emb is None:
                raise no_mapping_error(path, verify)
            entries, header = emb
            if fs is not None and fs != header["fs"]:
                raise ValueError(f"{path}: a foxglove-layout file stores its rate ({header['fs']!r} Hz); "
                                 f"leave fs out (got {fs!r})")
            fs = header["fs"]
            if header["n_samples"] == 0:
                return _written_back(path, np.empty((0, len(entries))), entries, header)
        got = _collect(reader, path, entries, fh, verify)
    data, fs, origin, notes = _assemble(path, entries, got, fs, max_jitter)
    if header is not None:
        return _written_back(path, data, entries, header)
    specs = [e.spec for e in entries]
    start = None
    if origin >= _EPOCH_NS:
        start = _dt.datetime.fromtimestamp(origin // 10**9, _dt.timezone.utc).replace(
            microsecond=(origin % 10**9) // 1000).isoformat()
    mapping = [{"name": e.name, "topic": e.topic, "field": e.field, "scale": e.scale,
                "stamp": e.stamp_text()} for e in entries]
    meta = {"mcap_origin_ns": origin, "mcap_mapping": mapping}
    history = [{"step": "mcap_foreign_read", "fs": fs, "channels": notes}]
    return Recording(data, fs, specs, t0=0.0, start_datetime=start, meta=meta, history=history)


# one decoded file: (key, Recording); the registry reads the header, then the samples
_CACHE: OrderedDict = OrderedDict()
_CACHE_MAX = 1
_LOCK = threading.Lock()


def clear_cache() -> None:
    """Forget the decoded file :func:`read_foreign` keeps (the next read decodes anew, as a
    benchmark wants)."""
    with _LOCK:
        _CACHE.clear()


def _options(topics, fs, max_jitter, stamp):
    entries = None if topics is None else parse_topics(topics, stamp=stamp)
    if topics is None and stamp is not None:
        raise ValueError("stamp applies to a mapping: give topics= too")
    if fs is not None:
        if isinstance(fs, bool) or not isinstance(fs, (int, float)) or not (math.isfinite(fs) and fs > 0):
            raise ValueError(f"fs must be a finite number > 0 [Hz], got {fs!r}")
        fs = float(fs)
    if max_jitter is not None:
        if isinstance(max_jitter, bool) or not isinstance(max_jitter, (int, float)) \
                or not (math.isfinite(max_jitter) and max_jitter >= 0):
            raise ValueError(f"max_jitter must be a finite number >= 0 [s], got {max_jitter!r}")
        max_jitter = float(max_jitter)
    return entries, fs, max_jitter


def read_foreign(path, *, topics=None, fs=None, max_jitter=None, stamp=None,
                 verify: bool = True) -> Recording:
    """The whole recording mapped from an MCAP file written by another tool.

    Parameters
    ----------
    path : str or Path
    topics : dict or list, optional
        The mapping (:func:`~meshphase.io.mcap.mapping.parse_topics`); None reads a file
        meshphase wrote in the ``foxglove`` layout (its mapping is stored in it) and
        otherwise raises an error listing the file's topics, schemas and numeric fields.
    fs : float, optional
        Sample rate [Hz]; derived from the stamps when None.
    max_jitter : float, optional
        Largest allowed distance of a message stamp from the uniform sample grid [s] (half
        a sample period when None).
    stamp : str, optional
        Default stamp of every mapping entry (``"log_time"``, ``"publish_time"`` or a field
        path).
    verify : bool
        Check chunk CRCs (default True).

    Returns
    -------
    Recording
        Samples x scale (SI), ``t0 = 0`` at the first common sample, ``start_datetime`` from
        the stamps when they are Unix time, ``meta["mcap_origin_ns"]`` (stamp of sample 0
        [ns]) and ``meta["mcap_mapping"]``; a ``foxglove`` layout file gives back the
        recording that was written (fs, t0, specs, meta, history). Its samples are
        read-only (shared with the next read of the same file: copy them to change them).

    Raises
    ------
    RecordingFileError
        No mapping (with the listing), unknown topic, missing or non-numeric field, topic
        without messages, irregular stamps, channels that do not overlap.
    """
    path = Path(path)
    verify = check_verify(verify)
    entries, fs, max_jitter = _options(topics, fs, max_jitter, stamp)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    st = os.stat(path)
    key = (str(path), st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns,
           None if entries is None else mapping_key(entries), fs, max_jitter, verify)
    with _LOCK:
        rec = _CACHE.get(key)
    if rec is None:
        rec = _decode_file(path, entries, fs, max_jitter, verify)
        # the cached samples are shared by every read of this file (the registry reads the
        # header, then the samples, once per pass): read-only, so an in-place change by a
        # caller is an error instead of a change to the next read
        rec.data.flags.writeable = False
        with _LOCK:
            _CACHE[key] = rec
            while len(_CACHE) > _CACHE_MAX:
                _CACHE.popitem(last=False)
    return rec


def foreign_info(path, rec: Recording) -> RecordingInfo:
    """The header of a recording read by :func:`read_foreign`."""
    return RecordingInfo(path=str(path), format="mcap", fs=rec.fs, n_samples=rec.n_samples,
                         channels=list(rec.channels), t0=rec.t0, start_datetime=rec.start_datetime,
                         meta=copy.deepcopy(rec.meta), history=copy.deepcopy(rec.history),
                         extra={"layout": "decoded messages (foreign or foxglove layout)",
                                "mapping": rec.meta.get("mcap_mapping")})

