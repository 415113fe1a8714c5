"""The mapped fields of another tool's MCAP file decoded chunk by chunk instead of message by
message: the fast form of :mod:`.foreign`'s collection, for JSON and ROS 2 CDR messages.

Each chunk holding a mapped topic is read whole (:class:`~.chunks.ChunkReader`, CRC checked
as for meshphase's own layout), its messages of that topic are found through the chunk's
MessageIndex record, their record headers (channel, log and publish time, payload position)
are read for all of them at once with numpy, and the payloads are decoded together:

* JSON (:class:`~.batch.JsonBatch`): when the messages of the chunk share one shape, the
  wanted number of every message is converted at once; otherwise the chunk's payloads are
  parsed by one :func:`json.loads` call over them joined as a JSON array, and the fields
  taken message by message.
* ROS 2 CDR (:class:`~.batch.CdrBatch`): the field's byte position in every message, then one
  gather.

The values are those of the per-message path (:func:`.mapping.get_field`,
:func:`.mapping.as_values`, :func:`.mapping.stamp_ns` on the objects the mcap project's
decoders give), bit for bit: the first and last message of every chunk are decoded by the
reference decoder and compared. Whatever this path does not handle (protobuf, other
encodings, a topic on several channels, messages outside chunks or without a message index,
values that are not numbers, a failed comparison) is left to the per-message path, topic by
topic, and that path also reports every error.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

from ...runtime.log import logger
from .batch import CdrBatch, JsonBatch, Unsupported, parse_msgdefs
from .chunks import ChunkReader, read_message_index
from .mapping import FieldError, TopicField, as_values, get_field, stamp_ns

__all__ = ["Series", "collect_bulk", "STAMP_PAIRS"]

#: Field names of a time stamp struct, in the order :func:`.mapping.stamp_ns` tries them.
STAMP_PAIRS = (("sec", "nsec"), ("sec", "nanosec"), ("seconds", "nanos"))
_RECORD_HEAD = 9 + 22  # opcode, length; channel id, sequence, log_time, publish_time
_U8 = np.arange(8, dtype=np.int64)


@dataclass
class Series:
    """The decoded samples of one mapped channel, in file order.

    Attributes
    ----------
    stamps : ndarray of int64
        Stamp of each message [ns].
    counts : ndarray of int64 or None
        Samples per message (None: one number per message).
    samples : ndarray of float64
        The samples, message after message.
    """

    stamps: np.ndarray
    counts: np.ndarray | None
    samples: np.ndarray


def _u(buf: np.ndarray, pos: np.ndarray, dtype: str) -> np.ndarray:
    size = np.dtype(dtype).itemsize
    return buf[pos[:, None] + _U8[:size]].view(dtype).reshape(-1)


def _records(buf: np.ndarray, index: np.ndarray, cid: int):
    """(payload start, payload length, log_time, publish_time) of the messages a chunk's
    MessageIndex entries point at, in file order; Unsupported when they are not messages of
    channel ``cid`` at those log times."""
    off = index[:, 1].astype(np.int64)
    order = np.argsort(off, kind="stable")
    off, want_t = off[order], index[order, 0]
    if off.size and (off[0] < 0 or off[-1] + _RECORD_HEAD > buf.size):
        raise Unsupported("message index points outside its chunk")
    length = _u(buf, off + 1, "<u8")
    if np.any(buf[off] != 0x05) or np.any(length < 22) or np.any(off + 9 + length > buf.size):
        raise Unsupported("message index does not point at message records")
    if np.any(_u(buf, off + 9, "<u2") != cid) or np.any(off[1:] < off[:-1] + 9 + length[:-1].astype(np.int64)):
        raise Unsupported("message records of another channel or overlapping")
    log_time = _u(buf, off + 15, "<u8")
    if not np.array_equal(log_time, want_t):
        raise Unsupported("message index log times differ from the records'")
    publish = _u(buf, off + 23, "<u8")
    if np.any(log_time >= 2 ** 63) or np.any(publish >= 2 ** 63):
        raise Unsupported("log times beyond int64")
    return off + _RECORD_HEAD, length.astype(np.int64) - 22, log_time.astype(np.int64), publish.astype(np.int64)


class _Piece:
    """One chunk's decoded part of one channel."""

    __slots__ = ("stamps", "counts", "samples")

    def __init__(self, stamps, counts, samples):
        self.stamps, self.counts, self.samples = stamps, counts, samples


def _record_stamp(e: TopicField, log_time, publish):
    if e.stamp == "log_time":
        return log_time
    if e.stamp == "publish_time":
        return publish
    return None


def _int_stamp(values: np.ndarray, kind_int: bool, limit: float) -> np.ndarray:
    """Integer stamp values as int64 (seconds: ``limit`` 9e9 keeps their nanoseconds in int64)."""
    if not kind_int:
        raise Unsupported("stamp field is not an integer")
    if values.size and (values.max() > limit or values.min() < -limit):
        raise Unsupported("stamp beyond int64 nanoseconds")
    return values.astype(np.int64)


def _json_int(batch: JsonBatch, j: int, limit: int) -> np.ndarray:
    """Token ``j`` of every message as an int64 (Unsupported unless a JSON integer within
    +-limit)."""
    values, is_int, mant = batch.numbers(j)
    if not is_int.all() or np.any(mant > np.uint64(limit)):
        raise Unsupported("stamp is not an integer within int64")
    m = mant.astype(np.int64)
    return np.where(np.signbit(values), -m, m)


# -- JSON ----------------------------------------------------------------------------------

def _json_tokens(batch: JsonBatch, e: TopicField, log_time, publish) -> _Piece:
    try:
        probe = get_field(batch.probe, e.path)
    except FieldError:
        if not e.missing_is_nan:
            raise Unsupported("field missing") from None
        return _Piece(log_time, None, np.full(batch.n, np.nan))
    j = batch.token(probe)
    if j is not None:
        samples, counts = batch.numbers(j)[0], None
    elif probe is None:
        samples, counts = np.full(batch.n, np.nan), None
    elif type(probe) is list:
        toks = [batch.token(v) for v in probe]
        if any(t is None for t in toks) or toks != list(range(toks[0], toks[0] + len(toks)) if toks else []):
            raise Unsupported("array of other values than numbers")
        cols = [batch.numbers(t)[0] for t in toks]
        samples = np.stack(cols, axis=1).reshape(-1) if cols else np.empty(0)
        counts = np.full(batch.n, len(toks), dtype=np.int64)
    else:
        raise Unsupported("not a number")
    stamps = _record_stamp(e, log_time, publish)
    if stamps is None:
        stamps = _json_field_stamp(batch, e)
    return _Piece(stamps, counts, samples)


def _json_field_stamp(batch: JsonBatch, e: TopicField) -> np.ndarray:
    try:
        v = get_field(batch.probe, e.stamp)
    except FieldError:
        raise Unsupported("stamp field missing") from None
    if type(v) is dict:
        for sec, nsec in STAMP_PAIRS:
            if sec in v and nsec in v:
                js, jn = batch.token(v[sec]), batch.token(v[nsec])
                if js is None or jn is None:
                    raise Unsupported("stamp struct of other values than numbers")
                return _json_int(batch, js, 9 * 10 ** 9) * 1_000_000_000 + _json_int(batch, jn, 9 * 10 ** 9)
        raise Unsupported("stamp struct without sec/nsec")
    j = batch.token(v)
    if j is None:
        raise Unsupported("stamp is not a number")
    return _json_int(batch, j, 2 ** 62)


def _json_loaded(buf: np.ndarray, start, length, entries, log_time, publish) -> list[_Piece]:
    """The chunk's messages parsed by one json.loads over them joined as a JSON array."""
    mv = memoryview(buf)
    parts = [mv[a:a + n] for a, n in zip(start.tolist(), length.tolist())]
    try:
        docs = json.loads(b",".join(parts).join((b"[", b"]")).decode("utf-8"))
    except (ValueError, UnicodeDecodeError):
        raise Unsupported("messages are not JSON one by one") from None
    if len(docs) != len(parts):
        raise Unsupported("messages are not one JSON value each")
    out = []
    for e in entries:
        stamps = _record_stamp(e, log_time, publish)
        stamps = stamps.copy() if stamps is not None else np.empty(len(docs), dtype=np.int64)
        values = []
        for i, d in enumerate(docs):
            try:
                raw = get_field(d, e.path)
            except FieldError:
                if not e.missing_is_nan:
                    raise Unsupported("field missing") from None
                values.append(np.nan)
                stamps[i] = log_time[i]
                continue
            v = as_values(raw)
            if v is None:
                raise Unsupported("not a number")
            values.append(v)
            if not isinstance(e.stamp, str):
                try:
                    stamps[i] = stamp_ns(e.stamp, None, d, "")
                except (ValueError, OverflowError):
                    raise Unsupported("stamp") from None
        out.append(_pieces_of(values, stamps))
    return out


def _pieces_of(values: list, stamps: np.ndarray) -> _Piece:
    if all(isinstance(v, float) for v in values):
        return _Piece(stamps, None, np.array(values, dtype=np.float64))
    if any(isinstance(v, float) for v in values):
        raise Unsupported("numbers and arrays mixed")
    counts = np.array([v.size for v in values], dtype=np.int64)
    return _Piece(stamps, counts, np.concatenate(values) if values else np.empty(0))


# -- CDR -------------------------------------------------------------------------------------

def _cdr_stamp_paths(defs: dict, root: str, path: tuple):
    """(sec path, nsec path) of a stamp struct, or None for a stamp number."""
    typ = root
    for p in path:
        if isinstance(p, int) or typ not in defs:
            return None
        f = next((f for f in defs[typ] if f.name == p), None)
        if f is None:
            raise Unsupported("stamp field not in the message type")
        if f.base not in defs:
            return None
        typ = f.base
    names = {f.name for f in defs[typ]}
    for sec, nsec in STAMP_PAIRS:
        if sec in names and nsec in names:
            return path + (sec,), path + (nsec,)
    raise Unsupported("stamp struct without sec/nsec")


_INT_KINDS = ("byte", "char", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64")


def _cdr_pieces(batch: CdrBatch, defs, root, entries, log_time, publish) -> list[_Piece]:
    paths = [e.path for e in entries]
    stamps_of = {}
    for e in entries:
        if not isinstance(e.stamp, str):
            pair = _cdr_stamp_paths(defs, root, e.stamp)
            stamps_of[e.name] = pair if pair is not None else (e.stamp,)
            paths += list(stamps_of[e.name])
    where = batch.locate(paths)
    out = []
    for e in entries:
        loc = where[e.path]
        if loc[0] == "scalar" and loc[1] != "bool":
            counts, samples = None, batch.values(loc[1], loc[2]).astype(np.float64)
        elif loc[0] == "array" and loc[1] not in ("bool", "uint8", "byte"):
            counts, samples = loc[3], batch.array_values(loc[1], loc[2], loc[3]).astype(np.float64)
        else:
            raise Unsupported("not a number or an array of numbers")
        stamps = _record_stamp(e, log_time, publish)
        if stamps is None:
            parts = []
            for p in stamps_of[e.name]:
                sl = where[p]
                if sl[0] != "scalar":
                    raise Unsupported("stamp is not a number")
                parts.append(_int_stamp(batch.values(sl[1], sl[2]), sl[1] in _INT_KINDS,
                                        9e9 if len(stamps_of[e.name]) == 2 else 2 ** 62))
            stamps = parts[0] if len(parts) == 1 else parts[0] * 1_000_000_000 + parts[1]
        out.append(_Piece(stamps, counts, samples))
    return out


# -- the reference check and the chunk loop -----------------------------------------------------

def _same(a, b) -> bool:
    a = np.atleast_1d(np.asarray(a, dtype=np.float64))
    b = np.atleast_1d(np.asarray(b, dtype=np.float64))
    return a.shape == b.shape and np.array_equal(a.view(np.uint64), b.view(np.uint64))


def _check(decoder, buf, start, length, entries, pieces, log_time, publish) -> None:
    """The first and last message decoded by the reference decoder give the same values and
    stamps; Unsupported otherwise."""
    n = start.size
    for i in {0, n - 1}:
        msg = decoder(bytes(buf[start[i]:start[i] + length[i]]))
        for e, pc in zip(entries, pieces):
            a = i if pc.counts is None else int(pc.counts[:i].sum())
            b = a + (1 if pc.counts is None else int(pc.counts[i]))
            try:
                raw = get_field(msg, e.path)
            except FieldError:
                if not (e.missing_is_nan and np.isnan(pc.samples[a]) and pc.stamps[i] == log_time[i]):
                    raise Unsupported("reference check: field missing") from None
                continue
            ref = as_values(raw)
            if ref is None or not _same(ref, pc.samples[a:b]) or (isinstance(ref, float) != (pc.counts is None)):
                raise Unsupported("reference check: values differ")
            t = (int(log_time[i]) if e.stamp == "log_time" else int(publish[i]) if e.stamp == "publish_time"
                 else stamp_ns(e.stamp, None, msg, ""))
            if t != int(pc.stamps[i]):
                raise Unsupported("reference check: stamps differ")


@dataclass
class _Plan:
    cid: int
    entries: list
    kind: str  # "json" or "cdr"
    decoder: object
    defs: dict | None
    root: str
    pieces: dict
    n: int = 0


def _plans(summary, entries: list[TopicField], factories) -> tuple[dict, list]:
    by_topic: dict = {}
    for e in entries:
        by_topic.setdefault(e.topic, []).append(e)
    plans, rest = {}, []
    stats = summary.statistics
    for topic, es in by_topic.items():
        chans = [c for c in summary.channels.values() if c.topic == topic]
        plan = None
        if len(chans) == 1 and stats is not None and stats.channel_message_counts.get(chans[0].id, 0) > 0:
            ch = chans[0]
            schema = summary.schemas.get(ch.schema_id)
            decoder = next((d for d in (f.decoder_for(ch.message_encoding, schema) for f in factories)
                            if d is not None), None)
            try:
                if decoder is not None and ch.message_encoding == "json":
                    plan = _Plan(ch.id, es, "json", decoder, None, "", {e.name: [] for e in es})
                elif decoder is not None and ch.message_encoding == "cdr" and schema is not None \
                        and schema.encoding == "ros2msg":
                    defs = parse_msgdefs(schema.name, schema.data.decode("utf-8"))
                    plan = _Plan(ch.id, es, "cdr", decoder, defs, schema.name, {e.name: [] for e in es})
            except (Unsupported, UnicodeDecodeError):
                plan = None
        if plan is None:
            rest += es
        else:
            plans[topic] = plan
    return plans, rest


def _decode_chunk(plan: _Plan, buf, start, length, log_time, publish) -> list[_Piece]:
    if plan.kind == "json":
        try:
            batch = JsonBatch(buf, start, length)
            return [_json_tokens(batch, e, log_time, publish) for e in plan.entries]
        except Unsupported:
            return _json_loaded(buf, start, length, plan.entries, log_time, publish)
    batch = CdrBatch(buf, start, length, plan.defs, plan.root)
    return _cdr_pieces(batch, plan.defs, plan.root, plan.entries, log_time, publish)


def collect_bulk(fh, path, summary, entries: list[TopicField], factories, *, verify: bool = True):
    """Decode the mapped fields chunk by chunk where this path can.

    Parameters
    ----------
    fh : binary file
        The open MCAP file.
    path : Path
        Its path (for errors).
    summary : mcap.summary.Summary or None
        The file's summary section.
    entries : list of TopicField
        The mapping.
    factories : list
        The per-message path's decoder factories (the reference of the comparison).
    verify : bool
        Check each chunk's CRC.

    Returns
    -------
    got : dict
        Channel name -> :class:`Series` of the entries decoded here.
    rest : list of TopicField
        The entries left to the per-message path.

    Raises
    ------
    CorruptFileError
        A chunk's CRC or structure is wrong.
    """
    if summary is None or not summary.chunk_indexes or summary.statistics is None or not entries:
        return {}, list(entries)
    plans, rest = _plans(summary, entries, factories)
    if not plans:
        return {}, rest
    by_cid = {p.cid: p for p in plans.values()}
    failed: set = set()
    chunks_in_order = sorted(summary.chunk_indexes, key=lambda ci: ci.chunk_start_offset)
    with ChunkReader(fh, path, None, verify=verify) as chunks:
        for ci in chunks_in_order:
            todo = [(cid, off) for cid, off in (ci.message_index_offsets or {}).items()
                    if cid in by_cid and cid not in failed]
            if not todo:
                continue
            indexes = [(cid, read_message_index(fh, path, off, cid)) for cid, off in todo]
            buf = None
            for cid, index in indexes:
                plan = by_cid[cid]
                if index is None:
                    failed.add(cid)
                    continue
                if index.shape[0] == 0:
                    continue
                if buf is None:
                    buf = np.frombuffer(chunks.records(ci), dtype=np.uint8)
                try:
                    start, length, log_time, publish = _records(buf, index, cid)
                    pieces = _decode_chunk(plan, buf, start, length, log_time, publish)
                    _check(plan.decoder, buf, start, length, plan.entries, pieces, log_time, publish)
                except Unsupported as exc:
                    logger.debug("%s: topic %r decoded message by message (%s)", path, plan.entries[0].topic, exc)
                    failed.add(cid)
                    continue
                except Exception as exc:  # the reference decoder refused a message: its path reports it
                    logger.debug("%s: topic %r: %s", path, plan.entries[0].topic, exc)
                    failed.add(cid)
                    continue
                for e, pc in zip(plan.entries, pieces):
                    plan.pieces[e.name].append(pc)
                plan.n += start.size
    got = {}
    counts = summary.statistics.channel_message_counts
    for plan in plans.values():
        mixed = any(len({pc.counts is None for pc in ps}) > 1 for ps in plan.pieces.values())
        if plan.cid in failed or plan.n != counts.get(plan.cid, 0) or mixed:
            rest += plan.entries
            continue
        for e in plan.entries:
            ps = plan.pieces[e.name]
            got[e.name] = Series(
                stamps=np.concatenate([pc.stamps for pc in ps]).astype(np.int64),
                counts=None if ps[0].counts is None else np.concatenate([pc.counts for pc in ps]),
                samples=np.concatenate([pc.samples for pc in ps]).astype(np.float64))
    return got, rest
