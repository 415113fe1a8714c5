"""What an MCAP file holds, topic by topic (:func:`describe_topics`): schema, encodings,
message count and rate, time span and the numeric fields a scene can map, for any MCAP file
(meshphase's own layouts and other tools' files, with or without a summary section).

Counts come from the summary's Statistics record, each topic's time span from the chunks'
MessageIndex records (16 bytes per message, read without decompressing a chunk); a file
without a summary, without statistics or without message indexes is scanned once instead
(every record read, no message decoded). The numeric fields come from decoding each topic's
first message with the foreign path's decoders (JSON, protobuf, ROS 2 CDR).
"""

from __future__ import annotations

from pathlib import Path

from mcap.exceptions import DecoderNotFoundError
from mcap.reader import make_reader
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader

from ..base import RecordingFileError, check_verify
from .chunks import read_message_index
from .fields import numeric_fields
from .foreign import decoder_factories
from .header import check_ends, lib_errors

__all__ = ["describe_topics", "TOPIC_KEYS"]

#: Keys of each dict :func:`describe_topics` returns, in order.
TOPIC_KEYS = ("topic", "schema", "schema_encoding", "message_encoding", "message_count", "rate_Hz",
              "start_ns", "end_ns", "numeric_fields")

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
    verify = check_verify(verify)
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
            if not channels:
                raise RecordingFileError(path, "the MCAP file has no channels (no topics): nothing to "
                                               "list or read")
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
