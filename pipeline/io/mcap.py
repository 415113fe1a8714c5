"""MCAP recordings: blocks of samples per message, one MCAP channel per recording channel.

Layout (full description, with the reasons, in ``data_schemas/mcap.md``):

* One Schema record ``meshphase.SampleBlock`` (encoding ``meshphase-layout``) whose data is a
  JSON description of the payload, validated by ``data_schemas/mcap_message.schema.json``.
* One MCAP channel per recording channel: topic = channel name, message encoding
  ``meshphase-block``, channel metadata = every :class:`~pipeline.recording.ChannelSpec`
  field plus ``fs``, ``index`` and ``dtype`` (``data_schemas/mcap_channel_metadata.schema.json``).
* One Metadata record ``meshphase.recording``: fs, t0, n_samples, channel order, dtype, block,
  log-time origin, start_datetime, meta and history (JSON).
* Messages: a 16-byte little-endian header (first sample index uint64, n_samples uint32,
  n_channels uint16 = 1, dtype code uint8, layout version uint8) followed by ``block`` samples
  (5120 by default) of one channel. ``log_time = log_time_origin_ns + floor(first_sample *
  1e9 / fs)`` [ns], with ``log_time_origin_ns = round(t0 * 1e9)`` for 0 <= t0 < 2**63 ns and 0
  otherwise (negative t0: log times count from the first sample).
* Chunks hold messages of one channel only, written in time-ordered groups (all channels of
  one stretch of time, then the next), so a one-channel read skips the other channels'
  chunks through the chunk index and a time-window read skips chunks outside the window.

Reads take the summary section (chunk index, channels, schema, metadata) from
``mcap.reader.make_reader`` and pick the chunks of the wanted channels whose log-time range
meets the wanted samples. The library's own message iteration costs ~15 us and three copies
per message (measured ~0.1 GS/s), so the chunks are read here: each is read whole into one
reused buffer, decompressed if needed, and its messages are copied once into one
preallocated Fortran-order output array (a chunk of full messages of one channel, as
:func:`write` makes them, in a single strided copy). Every wanted sample must arrive
exactly once. Anything the file does not hold as promised (truncated, another writer's
MCAP, metadata missing or inconsistent, samples missing) raises
:class:`~pipeline.io.base.RecordingFileError` naming the file and the problem.

Integrity (``verify=True``, the default of :func:`read`, :func:`read_info` and
:func:`iter_blocks`; ``data_schemas/mcap.md`` has the details): once per file (cached by
file identity) the footer's summary CRC and the DataEnd record's data-section CRC are
checked, and every chunk read has its CRC32 (over the uncompressed records) checked, in a
worker thread while the samples are copied. Together they cover every byte of the file but
the leading magic. The data-section CRC is checked without reading the uncompressed chunks'
records: their stored CRC is combined in (``crc32_combine``), and each record byte is checked
by its chunk's CRC when that chunk is read. A mismatch raises
:class:`~pipeline.io.base.CorruptFileError` naming the file, the chunk (number and byte
offset) or byte range, and the CRCs.
"""

from __future__ import annotations

import contextlib
import copy
import json
import threading
import math
import os
import struct
import zlib
from collections import OrderedDict, deque
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Iterator

import numpy as np

from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.writer import LIBRARY_IDENTIFIER, CompressionType, IndexType, Writer

from ..jsonable import json_default
from ..recording import ChannelSpec, Recording
from ..validate import as_choice, as_int, as_positive, as_positive_int
from .base import CorruptFileError, RecordingFileError, RecordingInfo

__all__ = ["NAME", "SUFFIXES", "CAN_WRITE", "MAGIC", "SCHEMA_NAME", "MESSAGE_ENCODING",
           "RECORDING_METADATA", "COMPRESSIONS", "DEFAULT_BLOCK", "sniff", "read_info", "read",
           "write", "write_blocks", "iter_blocks", "log_time_ns", "crc32_combine"]

NAME = "mcap"
SUFFIXES = (".mcap",)
CAN_WRITE = True

#: The 8 magic bytes that open and close every MCAP file.
MAGIC = b"\x89MCAP0\r\n"
#: Name and encoding of the Schema record describing the message payload.
SCHEMA_NAME = "meshphase.SampleBlock"
SCHEMA_ENCODING = "meshphase-layout"
#: Message encoding of every channel we write.
MESSAGE_ENCODING = "meshphase-block"
#: Name of the Metadata record with the recording header.
RECORDING_METADATA = "meshphase.recording"
#: MCAP header profile written (informative, not checked on read).
PROFILE = "meshphase"
#: Layout version (payload header field ``version`` and metadata ``format_version``).
FORMAT_VERSION = 1
#: Chunk compressions offered by :func:`write`.
COMPRESSIONS = ("none", "lz4", "zstd")
#: Samples per message by default (DESIGN.md: >= 5120 keeps the per-message cost small).
DEFAULT_BLOCK = 5120
#: Target uncompressed chunk size by default [B].
DEFAULT_CHUNK_SIZE = 1 << 20

_HEADER = struct.Struct("<QIHBB")  # first_sample, n_samples, n_channels, dtype code, version
HEADER_SIZE = _HEADER.size  # 16
_DTYPE_CODES = {"float32": 1, "float64": 2}
_CODE_DTYPES = {v: k for k, v in _DTYPE_CODES.items()}
_MAX_LOG_TIME = 2 ** 64 - 1
_MAX_RECORD = 4 * 2 ** 30  # the mcap package's record size limit [B]

#: JSON layout description stored as the data of the Schema record (see mcap_message.schema.json).
LAYOUT = {
    "name": SCHEMA_NAME,
    "version": FORMAT_VERSION,
    "byte_order": "little",
    "header_size": HEADER_SIZE,
    "header": [
        {"name": "first_sample", "type": "uint64", "offset": 0},
        {"name": "n_samples", "type": "uint32", "offset": 8},
        {"name": "n_channels", "type": "uint16", "offset": 12},
        {"name": "dtype", "type": "uint8", "offset": 14},
        {"name": "version", "type": "uint8", "offset": 15},
    ],
    "dtypes": {str(v): k for k, v in _DTYPE_CODES.items()},
    "samples": "channel-major",
    "log_time": "log_time_origin_ns + floor(first_sample * 1e9 / fs)",
}

# Exceptions the mcap package (and its codecs) raise on malformed input; wrapped into
# RecordingFileError so a caller never sees a raw struct/EOF error.
_LIB_ERRORS: tuple[type[BaseException], ...] = (McapError, struct.error, EOFError, ValueError, KeyError,
                                               IndexError, RuntimeError, UnicodeDecodeError,
                                               OverflowError)
try:  # zstandard's error does not derive from a standard class
    import zstandard as _zstd

    _LIB_ERRORS = _LIB_ERRORS + (_zstd.ZstdError,)
except ImportError:  # pragma: no cover - zstandard is a dependency
    pass


# ---------------------------------------------------------------------------------- schemas
def _json_schema(filename: str) -> dict:
    import data_schemas

    if hasattr(data_schemas, "load_schema"):
        return data_schemas.load_schema(filename)
    # data_schemas seen as a namespace package (an editable install made before it had an
    # __init__.py): read the same file from its directory
    for base in data_schemas.__path__:
        p = Path(base) / filename
        if p.is_file():
            return json.loads(p.read_text(encoding="utf-8"))
    raise FileNotFoundError(f"data_schemas/{filename} not found")


@lru_cache(maxsize=None)
def _validator(kind: str):
    from jsonschema import Draft202012Validator

    if kind == "layout":
        schema = _json_schema("mcap_message.schema.json")
    else:
        root = _json_schema("mcap_channel_metadata.schema.json")
        schema = root if kind == "channel" else {"$defs": root["$defs"],
                                                  "$ref": "#/$defs/recording_metadata"}
    return Draft202012Validator(schema)


def _schema_problem(kind: str, instance) -> str | None:
    """First validation problem of ``instance`` against schema ``kind``, or None."""
    from jsonschema.exceptions import best_match

    err = best_match(_validator(kind).iter_errors(instance))
    if err is None:
        return None
    where = "/".join(str(p) for p in err.absolute_path)
    return f"{where + ': ' if where else ''}{err.message}"


# ---------------------------------------------------------------------------------- time
def log_time_ns(first_sample: int, fs: float, origin_ns: int = 0) -> int:
    """log_time [ns] of the message whose first sample is ``first_sample``.

    ``origin_ns + floor(first_sample * 1e9 / fs)`` evaluated exactly on the binary fraction
    of ``fs`` (integer arithmetic), so writer and reader always agree to the nanosecond.

    Parameters
    ----------
    first_sample : int
        Index of the sample [-], >= 0.
    fs : float
        Sample rate [Hz], > 0.
    origin_ns : int
        log_time of sample 0 [ns], >= 0 (``log_time_origin_ns`` of the file).

    Returns
    -------
    int
        Log time [ns].
    """
    first_sample = as_int(first_sample, "first_sample")
    origin_ns = as_int(origin_ns, "origin_ns")
    if first_sample < 0:
        raise ValueError(f"first_sample must be >= 0, got {first_sample}")
    if origin_ns < 0:
        raise ValueError(f"origin_ns must be >= 0, got {origin_ns}")
    return _log_time(first_sample, as_positive(fs, "fs"), origin_ns)


def _log_time(first_sample: int, fs: float, origin_ns: int) -> int:
    p, q = fs.as_integer_ratio()
    return origin_ns + (first_sample * 1_000_000_000 * q) // p


def _origin_ns(t0: float) -> int:
    x = t0 * 1e9
    if 0.0 <= x < 2.0 ** 63:
        return int(round(x))
    return 0


# ---------------------------------------------------------------------------------- CRC32
_CRC_POLY = 0xEDB88320  # CRC-32 (ISO-HDLC, zlib), reflected

try:  # ISA-L's CRC-32 (same polynomial as zlib, SIMD): ~3x zlib's speed where installed
    from isal.isal_zlib import crc32 as _crc32
except ImportError:  # the default: zlib (releases the GIL for large buffers, as does isal)
    _crc32 = zlib.crc32


def _crc_mulmod(a: int, b: int) -> int:
    """a * b modulo the CRC-32 polynomial (reflected bit order, as zlib's multmodp)."""
    m = 1 << 31
    p = 0
    while m:
        if a & m:
            p ^= b
            if not a & (m - 1):
                break
        m >>= 1
        b = (b >> 1) ^ _CRC_POLY if b & 1 else b >> 1
    return p


def _x2n_table() -> list[int]:
    t = [0] * 32
    p = 1 << 30  # x^1
    for k in range(32):
        t[k] = p
        p = _crc_mulmod(p, p)
    return t


_X2N = _x2n_table()  # x^(2^k) mod P


@lru_cache(maxsize=1024)
def _x8n(n: int) -> int:
    """x^(8 n) mod P: the factor that shifts a CRC over n zero bytes."""
    p = 1 << 31  # x^0
    k = 3
    while n:
        if n & 1:
            p = _crc_mulmod(_X2N[k & 31], p)
        n >>= 1
        k += 1
    return p


def crc32_combine(crc1: int, crc2: int, len2: int) -> int:
    """CRC-32 of ``A + B`` from ``crc1 = crc32(A)``, ``crc2 = crc32(B)`` and ``len(B)``.

    The algorithm of zlib's ``crc32_combine`` (not exposed by Python's zlib): shift
    ``crc1`` over ``len2`` bytes by multiplying with x^(8 len2) modulo the polynomial.

    Parameters
    ----------
    crc1, crc2 : int
        CRC-32 values (as ``zlib.crc32`` returns).
    len2 : int
        Length of the second block [B], >= 0.

    Returns
    -------
    int
    """
    len2 = as_int(len2, "len2")
    if len2 < 0:
        raise ValueError(f"len2 must be >= 0, got {len2}")
    return _crc_mulmod(_x8n(len2), crc1 & 0xFFFFFFFF) ^ (crc2 & 0xFFFFFFFF)


# ---------------------------------------------------------------------------------- sniff
def sniff(head: bytes) -> bool:
    """True when ``head`` (the first bytes of a file) starts with the MCAP magic."""
    return bytes(head[:8]) == MAGIC


# ---------------------------------------------------------------------------------- layout
@dataclass
class _Layout:
    info: RecordingInfo
    dtype: np.dtype
    block: int
    origin_ns: int
    channel_ids: dict  # name -> MCAP channel id
    schema_id: int
    summary: object  # mcap.summary.Summary
    code: int  # payload dtype code

    def log_time(self, i: int) -> int:
        return _log_time(i, self.info.fs, self.origin_ns)


@contextlib.contextmanager
def _lib_errors(path: Path, what: str):
    """Turn errors of the mcap package into RecordingFileError naming the file."""
    try:
        yield
    except RecordingFileError:
        raise
    except _LIB_ERRORS as exc:
        detail = str(exc) or type(exc).__name__
        raise RecordingFileError(path, f"malformed MCAP while {what}: {type(exc).__name__}: "
                                       f"{detail}") from exc


def _check_ends(fh, path: Path) -> None:
    fh.seek(0, 2)
    size = fh.tell()
    fh.seek(0)
    head = fh.read(8)
    if len(head) < 8 and MAGIC.startswith(head):
        raise CorruptFileError(path, f"byte {size} (end of file)", f"truncated MCAP file: only {size} bytes, "
                                                                  f"part of the opening magic")
    if head != MAGIC:
        raise RecordingFileError(path, f"not an MCAP file: it does not start with the MCAP magic "
                                       f"{MAGIC!r} (first bytes {head!r})")
    # magic + header record + ... + footer record (1 + 8 + 20 bytes) + magic
    if size < 8 + 9 + 29 + 8:
        raise CorruptFileError(path, f"byte {size} (end of file)",
                               f"truncated MCAP file: only {size} bytes, too short for a header, "
                               f"a footer and the closing magic")
    fh.seek(size - 8)
    tail = fh.read(8)
    fh.seek(0)
    if tail != MAGIC:
        raise CorruptFileError(path, f"byte {size} (end of file)",
                               f"truncated MCAP file ({size} bytes): it does not end with the "
                               f"closing MCAP magic, so the footer and summary (the index) are "
                               f"missing; the write was probably interrupted")


_FOOTER = struct.Struct("<BQQQI")  # opcode, length (20), summary_start, summary_offset_start, crc
_OP_FOOTER = 0x02
_OP_DATA_END = 0x0F
_IO_BLOCK = 1 << 22  # bytes CRC'd per read while walking the data section


def _check_summary_crc(fh, path: Path) -> tuple[int, int]:
    """Check the footer record and the summary CRC (when not 0) before anything parses the
    summary. Returns (footer offset, summary_start)."""
    fh.seek(0, 2)
    size = fh.tell()
    pos = size - 8 - _FOOTER.size
    fh.seek(pos)
    op, length, summary_start, offset_start, crc = _FOOTER.unpack(fh.read(_FOOTER.size))
    if op != _OP_FOOTER or length != 20:
        raise CorruptFileError(path, f"byte {pos} (footer)", f"no footer record before the closing magic "
                                                            f"(opcode {op:#04x}, length {length})")
    start = summary_start or pos
    if not 8 <= start <= pos or (offset_start and not start <= offset_start <= pos):
        raise CorruptFileError(path, f"byte {pos} (footer)", f"footer points outside the file (summary "
                                                            f"at byte {summary_start}, summary offsets at "
                                                            f"byte {offset_start}, footer at byte {pos})")
    if crc:
        fh.seek(start)
        got = _crc32(fh.read(pos - start))
        got = _crc32(_FOOTER.pack(op, length, summary_start, offset_start, 0)[:-4], got)
        if got != crc:
            raise CorruptFileError(path, f"bytes [{start}, {pos + 25}) (summary section and footer)",
                                   f"summary CRC32 is {got:#010x}, the footer records {crc:#010x}: the "
                                   f"index, channel or schema records are damaged")
    fh.seek(0)
    return pos, start


def _check_data_crc(fh, path: Path, data_end_limit: int) -> bool:
    """Walk the records of the data section and check the DataEnd record's CRC (when not 0).

    The CRC covers bytes [0, start of DataEnd). Uncompressed chunks with a stored CRC are
    not read: their record prefix is CRC'd and the stored CRC of their records combined in
    (:func:`crc32_combine`); a damaged record byte is caught by that chunk's own CRC when it
    is read. Other records (and compressed chunks) are read and CRC'd. Returns True when a
    CRC was checked, False when the file stores none.
    """
    crc = _crc32(MAGIC)
    pos = 8
    fh.seek(pos)
    head_size = 9 + _CHUNK_HEAD.size
    while True:
        if pos + 9 > data_end_limit:
            raise CorruptFileError(path, f"byte {pos}", f"the data section ends without a DataEnd record "
                                                        f"(records run into the summary at byte {data_end_limit})")
        head = fh.read(9)
        op, length = _REC.unpack(head)
        end = pos + 9 + length
        if end > data_end_limit:
            raise CorruptFileError(path, f"byte {pos}", f"record (opcode {op:#04x}) of {length} bytes runs past "
                                                        f"the data section (ends at byte {data_end_limit})")
        if op == _OP_DATA_END:
            if length < 4:
                raise CorruptFileError(path, f"byte {pos}", f"DataEnd record of {length} bytes is too short")
            (stored,) = struct.unpack("<I", fh.read(4))
            if stored and stored != crc:
                raise CorruptFileError(path, f"bytes [0, {pos}) (data section)",
                                       f"data-section CRC32 is {crc:#010x}, the DataEnd record says "
                                       f"{stored:#010x}: a record outside the chunks' records (header, "
                                       f"metadata, chunk headers, message indexes) is damaged")
            return bool(stored)
        crc = _crc32(head, crc)
        done = 9
        if op == _OP_CHUNK and length >= _CHUNK_HEAD.size + 4 + 8:
            fixed = fh.read(_CHUNK_HEAD.size)
            _, _, usize, ccrc, clen = _CHUNK_HEAD.unpack(fixed)
            if head_size + clen + 8 <= 9 + length:
                rest = fh.read(clen + 8)
                (rlen,) = _U64.unpack_from(rest, clen)
                if ccrc and clen == 0 and head_size + clen + 8 + rlen == 9 + length and usize == rlen:
                    crc = _crc32(rest, _crc32(fixed, crc))
                    crc = crc32_combine(crc, ccrc, rlen)
                    pos = end
                    fh.seek(pos)
                    continue
                crc = _crc32(rest, _crc32(fixed, crc))
                done = head_size + clen + 8
            else:
                crc = _crc32(fixed, crc)
                done = head_size
        left = 9 + length - done
        while left > 0:
            piece = fh.read(min(left, _IO_BLOCK))
            if not piece:
                raise CorruptFileError(path, f"byte {pos}", "record runs past the end of the file")
            crc = _crc32(piece, crc)
            left -= len(piece)
        pos = end


def _summary(fh, path: Path, verify: bool):
    """(reader, summary) from ``mcap.reader.make_reader`` (summary None when absent)."""
    with _lib_errors(path, "reading the summary section"):
        reader = make_reader(fh, validate_crcs=verify)
        return reader, reader.get_summary()


def _read_layout(fh, path: Path, verify: bool = True, opened=None) -> tuple[object, _Layout]:
    """Open an MCAP stream, check it is one of ours and parse the header records.
    ``opened``: (reader, summary) already made by :func:`_summary`."""
    _check_ends(fh, path)
    reader, summary = opened if opened is not None else _summary(fh, path, verify)
    if summary is None:
        raise RecordingFileError(path, "MCAP file has no summary section (no index); meshphase "
                                       "needs the chunk index to read blocks and time windows")
    ours = [s for s in summary.schemas.values() if s.name == SCHEMA_NAME]
    if not ours:
        schemas = sorted({f"{s.name} ({s.encoding})" for s in summary.schemas.values()})
        topics = sorted({c.topic for c in summary.channels.values()})
        raise RecordingFileError(
            path, f"not a meshphase recording: the MCAP file has no {SCHEMA_NAME!r} schema "
                  f"(schemas: {schemas or 'none'}; topics: {topics[:10] or 'none'}"
                  f"{' ...' if len(topics) > 10 else ''})")
    if len(ours) > 1:
        raise RecordingFileError(path, f"{len(ours)} {SCHEMA_NAME!r} schemas; expected one")
    schema = ours[0]
    if schema.encoding != SCHEMA_ENCODING:
        raise RecordingFileError(path, f"schema {SCHEMA_NAME!r} has encoding {schema.encoding!r}, "
                                       f"expected {SCHEMA_ENCODING!r}")
    try:
        layout = json.loads(bytes(schema.data).decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise RecordingFileError(path, f"schema {SCHEMA_NAME!r}: data is not JSON ({exc})") from exc
    problem = _schema_problem("layout", layout)
    if problem:
        raise RecordingFileError(path, f"schema {SCHEMA_NAME!r}: unsupported payload layout "
                                       f"({problem}); this reader knows version {FORMAT_VERSION}")

    with _lib_errors(path, "reading metadata records"):
        records = [m for m in reader.iter_metadata() if m.name == RECORDING_METADATA]
    if not records:
        raise RecordingFileError(path, f"no {RECORDING_METADATA!r} Metadata record: the recording "
                                       f"header (fs, t0, n_samples, channels) is missing")
    if len(records) > 1:
        raise RecordingFileError(path, f"{len(records)} {RECORDING_METADATA!r} Metadata records; "
                                       f"expected one")
    md = dict(records[0].metadata)
    problem = _schema_problem("recording", md)
    if problem:
        raise RecordingFileError(path, f"Metadata record {RECORDING_METADATA!r}: {problem}")
    try:
        fs = float(md["fs"])
        t0 = float(md["t0"])
        n_samples = int(md["n_samples"])
        n_channels = int(md["n_channels"])
        block = int(md["block"])
        origin = int(md["log_time_origin_ns"])
        names = json.loads(md["channels"])
        meta = json.loads(md["meta"])
        history = json.loads(md["history"])
    except (ValueError, json.JSONDecodeError) as exc:
        raise RecordingFileError(path, f"Metadata record {RECORDING_METADATA!r}: {exc}") from exc
    if not (math.isfinite(fs) and fs > 0):
        raise RecordingFileError(path, f"sample rate fs must be finite and > 0, got {md['fs']!r}")
    if not math.isfinite(t0):
        raise RecordingFileError(path, f"t0 must be finite, got {md['t0']!r}")
    if block < 1:
        raise RecordingFileError(path, f"block must be >= 1, got {block}")
    if not (isinstance(names, list) and all(isinstance(n, str) for n in names)
            and len(names) == n_channels):
        raise RecordingFileError(path, f"'channels' must be a JSON list of {n_channels} names, "
                                       f"got {md['channels']!r}")
    if not isinstance(meta, dict) or not isinstance(history, list):
        raise RecordingFileError(path, "'meta' must be a JSON object and 'history' a JSON list")
    dtype_name = md["dtype"]

    channels = {}
    ids = {}
    for ch in summary.channels.values():
        if ch.schema_id != schema.id:
            continue  # another writer's channel in the same file: not ours, ignored
        if ch.message_encoding != MESSAGE_ENCODING:
            raise RecordingFileError(path, f"channel {ch.topic!r}: message encoding "
                                           f"{ch.message_encoding!r}, expected {MESSAGE_ENCODING!r}")
        cm = dict(ch.metadata)
        problem = _schema_problem("channel", cm)
        if problem:
            raise RecordingFileError(path, f"channel {ch.topic!r} metadata: {problem}")
        idx = int(cm["index"])
        if idx >= n_channels or idx in channels or cm["name"] != ch.topic or names[idx] != ch.topic:
            raise RecordingFileError(path, f"channel {ch.topic!r}: index {idx} / name "
                                           f"{cm['name']!r} do not match the channel list {names}")
        if float(cm["fs"]) != fs:
            raise RecordingFileError(path, f"channel {ch.topic!r}: fs {cm['fs']} Hz differs from "
                                           f"the recording's {md['fs']} Hz")
        if cm["dtype"] != dtype_name:
            raise RecordingFileError(path, f"channel {ch.topic!r}: dtype {cm['dtype']} differs from "
                                           f"the recording's {dtype_name}")
        try:
            spec = ChannelSpec(
                name=cm["name"], kind=cm["kind"], units=cm["units"], gain=float(cm["gain"]),
                gear=cm.get("gear"),
                tooth=int(cm["tooth"]) if "tooth" in cm else None,
                face_position=float(cm["face_position"]) if "face_position" in cm else None,
                description=cm["description"])
        except (TypeError, ValueError) as exc:
            raise RecordingFileError(path, f"channel {ch.topic!r} metadata: {exc}") from exc
        channels[idx] = spec
        ids[spec.name] = ch.id
    missing = [names[i] for i in range(n_channels) if i not in channels]
    if missing:
        raise RecordingFileError(path, f"channel(s) {missing} listed in {RECORDING_METADATA!r} have "
                                       f"no MCAP channel")

    compressions = sorted({ci.compression or "none" for ci in summary.chunk_indexes})
    stats = summary.statistics
    extra = {
        "layout": "one MCAP channel per recording channel, blocks of samples per message",
        "block": block,
        "dtype": dtype_name,
        "compression": md.get("compression", compressions[0] if len(compressions) == 1 else None),
        "chunk_compressions": compressions,
        "n_chunks": len(summary.chunk_indexes),
        "n_messages": int(stats.message_count) if stats is not None else None,
        "log_time_origin_ns": origin,
    }
    info = RecordingInfo(path=str(path), format=NAME, fs=fs, n_samples=n_samples,
                         channels=[channels[i] for i in range(n_channels)], t0=t0,
                         start_datetime=md.get("start_datetime"), meta=meta, history=history,
                         extra=extra)
    return reader, _Layout(info=info, dtype=np.dtype(dtype_name).newbyteorder("<"), block=block,
                           origin_ns=origin, channel_ids=ids, schema_id=schema.id, summary=summary,
                           code=_DTYPE_CODES[dtype_name])


# Parsed headers of the last few files, keyed by path and file identity (device, inode,
# size, mtime, ctime): the registry opens a file twice per read (read_info, then read), and a
# 1-hour recording's summary (~1200 chunk indexes) takes ~20 ms to parse. Only the header
# is cached; samples are always read from the file.
_LAYOUTS: OrderedDict = OrderedDict()
_LAYOUTS_MAX = 8
# identities of files whose summary and data-section CRCs passed (same key as _LAYOUTS)
_VERIFIED: OrderedDict = OrderedDict()
_LOCK = threading.Lock()


def _check_verify(verify) -> bool:
    if not isinstance(verify, (bool, np.bool_)):
        raise TypeError(f"verify must be a bool, got {verify!r}")
    return bool(verify)


@contextlib.contextmanager
def _open(path, verify: bool = True):
    path = Path(path)
    verify = _check_verify(verify)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    with open(path, "rb") as fh:
        st = os.fstat(fh.fileno())
        key = (str(path), st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns)
        with _LOCK:
            lay = _LAYOUTS.get(key)
            checked = key in _VERIFIED
        opened = None
        if verify and not checked:  # before anything parses the data section's records
            _check_ends(fh, path)
            _, data_end = _check_summary_crc(fh, path)
            opened = _summary(fh, path, verify)  # the summary passed its CRC
            summary = opened[1]
            if summary is not None and any(sc.name == SCHEMA_NAME for sc in summary.schemas.values()):
                # one of ours (else _read_layout says what it is, without walking a foreign
                # file); the summary starts right after the DataEnd record: the walk stops there
                _check_data_crc(fh, path, data_end)
        if lay is None:
            _, lay = _read_layout(fh, path, verify, opened)
        with _LOCK:
            _LAYOUTS[key] = lay
            _LAYOUTS.move_to_end(key)
            while len(_LAYOUTS) > _LAYOUTS_MAX:
                _LAYOUTS.popitem(last=False)
            if verify:
                _VERIFIED[key] = True
                _VERIFIED.move_to_end(key)
                while len(_VERIFIED) > _LAYOUTS_MAX:
                    _VERIFIED.popitem(last=False)
        yield path, fh, lay


def read_info(path, *, verify: bool = True) -> RecordingInfo:
    """Header of an MCAP recording (channels, fs, n_samples, t0, metadata); no samples read.

    Parameters
    ----------
    path : str or Path
    verify : bool
        Check the summary and data-section CRCs (default True; once per file identity).

    Returns
    -------
    RecordingInfo
        ``extra`` holds ``block`` [samples per message], ``dtype``, ``compression``,
        ``n_chunks``, ``n_messages`` and ``log_time_origin_ns`` [ns].
    """
    with _open(path, verify) as (_, _, lay):
        return copy.deepcopy(lay.info)


# ---------------------------------------------------------------------------------- reading
_REC = struct.Struct("<BQ")  # opcode, record length
_CHUNK_HEAD = struct.Struct("<QQQII")  # start, end, uncompressed size, crc, compression length
_U64 = struct.Struct("<Q")
_MSG_HEAD = struct.Struct("<HIQQ")  # channel id, sequence, log_time, publish_time
_OP_MESSAGE = 0x05
_OP_CHUNK = 0x06
# One message record as written by write(): record header, message header, payload header.
_RECORD_VIEW = np.dtype({
    "names": ["op", "length", "channel", "first", "n", "nch", "code", "version"],
    "formats": ["u1", "<u8", "<u2", "<u8", "<u4", "<u2", "u1", "u1"],
    "offsets": [0, 1, 9, 31, 39, 43, 45, 46],
    "itemsize": 47})


_CRC_ASYNC_MIN = 1 << 16  # chunks at least this large [B] get their CRC in the worker thread


class _ChunkReader:
    """Reads the uncompressed records of one chunk given its ChunkIndex (summary section).

    The file bytes go into two buffers used in turn: the returned view is valid until the
    next call but one (callers copy the samples out at once). With ``verify``, the CRC32 of
    each chunk's uncompressed records is computed in a worker thread (zlib releases the GIL)
    while the caller copies the samples and reads the next chunk; :meth:`finish` waits for
    it. Use as a context manager: on leaving, the last CRC is checked, and a CRC mismatch
    takes precedence over an error raised while parsing the damaged chunk.
    """

    def __init__(self, fh, path: Path, lay: _Layout | None = None, *, verify: bool = True):
        self.fh = fh
        self.file_size = os.fstat(fh.fileno()).st_size
        self.path = path
        self.lay = lay
        self.verify = verify
        self.bufs = [bytearray(0), bytearray(0)]
        self.turn = 0
        self.pending = None  # (future, chunk index, stored crc, n bytes)
        self._pending_turn = -1  # buffer the pending CRC reads (-1: none of ours)
        self.pool = None
        self._zstd = None
        self._numbers = None

    def __enter__(self):
        return self

    def __exit__(self, typ, exc, tb):
        try:
            if exc is None:
                self.finish()
            else:
                try:
                    self.finish()
                except CorruptFileError as crc_error:
                    if isinstance(exc, (RecordingFileError,) + _LIB_ERRORS):
                        raise crc_error from exc
        finally:
            if self.pool is not None:
                self.pool.shutdown(wait=True)
                self.pool = None
        return False

    def _where(self, ci) -> str:
        if self.lay is not None:
            if self._numbers is None:
                self._numbers = {c.chunk_start_offset: k for k, c in enumerate(self.lay.summary.chunk_indexes)}
            k = self._numbers.get(ci.chunk_start_offset)
            if k is not None:
                return f"chunk {k} at byte {ci.chunk_start_offset}"
        return f"chunk at byte {ci.chunk_start_offset}"

    def _bad(self, ci, problem: str):
        return CorruptFileError(self.path, self._where(ci), problem)

    def _crc_error(self, ci, got: int, want: int, nbytes: int):
        names = []
        if self.lay is not None:
            by_id = {v: k for k, v in self.lay.channel_ids.items()}
            names = [by_id[i] for i in (ci.message_index_offsets or {}) if i in by_id]
        return self._bad(ci, f"CRC32 of its {nbytes} uncompressed record bytes is {got:#010x}, the chunk "
                             f"records {want:#010x}: the chunk is damaged (channel(s) {names}, log time "
                             f"[{ci.message_start_time}, {ci.message_end_time}] ns)")

    def finish(self) -> None:
        """Wait for the pending CRC and raise CorruptFileError when it does not match."""
        if self.pending is None:
            return
        fut, ci, want, nbytes = self.pending
        self.pending = None
        self._pending_turn = -1
        got = fut.result()
        if got != want:
            raise self._crc_error(ci, got, want, nbytes)

    def _check_crc(self, ci, data, want: int, turn: int) -> None:
        """Check (or start checking) the CRC of ``data``, which lives in buffer ``turn``
        (-1: in its own object)."""
        if len(data) < _CRC_ASYNC_MIN:
            got = _crc32(data)
            if got != want:
                raise self._crc_error(ci, got, want, len(data))
            return
        if self.pool is None:
            from concurrent.futures import ThreadPoolExecutor

            self.pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="meshphase-crc")
        self.finish()  # one CRC in flight at a time
        self.pending = (self.pool.submit(_crc32, data), ci, want, len(data))
        self._pending_turn = turn

    def records(self, ci) -> memoryview:
        size = int(ci.chunk_length)
        if ci.chunk_start_offset + size > self.file_size:
            raise self._bad(ci, f"the chunk index says {size} bytes, past the end of the "
                                f"{self.file_size}-byte file")
        self.fh.seek(ci.chunk_start_offset)
        if self.pending is not None and self._pending_turn == self.turn:
            self.finish()  # the pending CRC still reads this buffer
        buf = self.bufs[self.turn]
        if len(buf) < size:
            buf = self.bufs[self.turn] = bytearray(size)
        mv = memoryview(buf)[:size]
        got = self.fh.readinto(mv)
        if got != size:
            raise self._bad(ci, f"only {got} of {size} bytes present (file truncated)")
        if size < 9 + _CHUNK_HEAD.size + 8:
            raise self._bad(ci, f"{size} bytes is too short for a chunk record")
        op, length = _REC.unpack_from(mv, 0)
        if op != _OP_CHUNK or 9 + length != size:
            raise self._bad(ci, f"the chunk index points at a record with opcode {op:#04x} and "
                                f"length {length}, not a {size}-byte chunk")
        _, _, usize, crc, clen = _CHUNK_HEAD.unpack_from(mv, 9)
        pos = 9 + _CHUNK_HEAD.size
        comp = bytes(mv[pos:pos + clen]).decode("utf-8", "replace")
        pos += clen
        if pos + 8 > size:
            raise self._bad(ci, "chunk header runs past the record")
        (rlen,) = _U64.unpack_from(mv, pos)
        pos += 8
        if pos + rlen != size:
            raise self._bad(ci, f"records length {rlen} does not fit the {size}-byte record")
        data = mv[pos:pos + rlen]
        if usize > _MAX_RECORD:
            raise self._bad(ci, f"claims {usize} bytes uncompressed, more than {_MAX_RECORD}")
        try:
            if comp == "":
                pass
            elif comp == "lz4":
                import lz4.frame

                data = memoryview(lz4.frame.decompress(data))
            elif comp == "zstd":
                if self._zstd is None:
                    import zstandard

                    self._zstd = zstandard.ZstdDecompressor()
                data = memoryview(self._zstd.decompress(data, max_output_size=usize))
            else:
                raise self._bad(ci, f"unsupported compression {comp!r} (supported: none, lz4, zstd)")
        except RecordingFileError:
            raise
        except _LIB_ERRORS as exc:
            raise self._bad(ci, f"{comp} data do not decompress ({type(exc).__name__}: {exc}): the chunk "
                                f"is damaged") from exc
        if len(data) != usize:
            raise self._bad(ci, f"decompressed to {len(data)} bytes, the chunk says {usize}")
        if self.verify and crc:
            self._check_crc(ci, data, crc, self.turn if comp == "" else -1)
        self.turn ^= 1
        return data


def _payloads(recs: memoryview, ids, path: Path):
    """(channel id, payload offset, payload length, log_time) of the messages of the wanted
    channel ids in the uncompressed records of one chunk, in file order."""
    q = 0
    end = len(recs)
    while q < end:
        if q + 9 > end:
            raise RecordingFileError(path, "record header runs past the end of its chunk")
        op, length = _REC.unpack_from(recs, q)
        nxt = q + 9 + length
        if nxt > end:
            raise RecordingFileError(path, f"record of {length} bytes runs past the end of its chunk")
        if op == _OP_MESSAGE:
            if length < _MSG_HEAD.size:
                raise RecordingFileError(path, f"message record of {length} bytes is too short")
            cid, _, log_time, _ = _MSG_HEAD.unpack_from(recs, q + 9)
            if cid in ids:
                yield cid, q + 9 + _MSG_HEAD.size, length - _MSG_HEAD.size, log_time
        q = nxt


def _decode(buf, off: int, size: int, lay: _Layout, path: Path, name: str) -> tuple[int, int]:
    """Check one payload header; return (first_sample, n_samples)."""
    if size < HEADER_SIZE:
        raise RecordingFileError(path, f"channel {name!r}: message payload of {size} bytes is "
                                       f"shorter than the {HEADER_SIZE}-byte header")
    first, n, nch, code, version = _HEADER.unpack_from(buf, off)
    if version != FORMAT_VERSION or nch != 1 or code != lay.code:
        raise RecordingFileError(path, f"channel {name!r}: message header (version {version}, "
                                       f"n_channels {nch}, dtype code {code}) does not match the "
                                       f"layout (version {FORMAT_VERSION}, 1 channel, code {lay.code})")
    if size != HEADER_SIZE + n * lay.dtype.itemsize or n > lay.block or n == 0:
        raise RecordingFileError(path, f"channel {name!r}: message at sample {first} claims {n} "
                                       f"samples in {size - HEADER_SIZE} payload bytes "
                                       f"(block {lay.block}, {lay.dtype.itemsize} B/sample)")
    if first + n > lay.info.n_samples:
        raise RecordingFileError(path, f"channel {name!r}: message holds samples [{first}, {first + n}) "
                                       f"beyond n_samples = {lay.info.n_samples}")
    return first, n


def _uniform_chunk(recs: memoryview, lay: _Layout, col: dict, i0: int, i1: int):
    """Fast path of :func:`read` for the chunks :func:`write` produces.

    When the chunk holds only full-size messages of one wanted channel, with contiguous
    sample ranges inside [i0, i1) and valid headers, return (column, first sample, strided
    (messages x samples) view of the samples); otherwise None, and the caller parses the
    chunk message by message (which also reports what is wrong, if anything is).
    """
    size = len(recs)
    if size < 9 + _MSG_HEAD.size + HEADER_SIZE:
        return None
    op, length = _REC.unpack_from(recs, 0)
    rec_size = 9 + length
    n = lay.block
    if op != _OP_MESSAGE or length != _MSG_HEAD.size + HEADER_SIZE + n * lay.dtype.itemsize \
            or size % rec_size:
        return None
    k = size // rec_size
    heads = np.ndarray((k,), dtype=_RECORD_VIEW, buffer=recs, strides=(rec_size,))
    cid = int(heads["channel"][0])
    first = int(heads["first"][0])
    if (cid not in col or first < i0 or first + k * n > i1
            or not (np.all(heads["op"] == _OP_MESSAGE) and np.all(heads["length"] == length)
                    and np.all(heads["channel"] == cid) and np.all(heads["n"] == n)
                    and np.all(heads["nch"] == 1) and np.all(heads["code"] == lay.code)
                    and np.all(heads["version"] == FORMAT_VERSION)
                    and np.array_equal(heads["first"], first + n * np.arange(k, dtype=np.uint64)))):
        return None
    samples = np.ndarray((k, n), dtype=lay.dtype, buffer=recs, offset=9 + _MSG_HEAD.size + HEADER_SIZE,
                         strides=(rec_size, lay.dtype.itemsize))
    return col[cid], first, samples


def _check_tiling(path: Path, name: str, spans: list, i0: int, i1: int) -> None:
    """Samples [i0, i1) of one channel must be covered exactly once by ``spans``."""
    if i1 <= i0:
        return
    if not spans:
        raise RecordingFileError(path, f"channel {name!r}: no message holds samples [{i0}, {i1}) "
                                       f"(messages lost)")
    s = np.asarray(spans, dtype=np.int64)
    s = s[np.argsort(s[:, 0], kind="stable")]
    starts = np.concatenate(([i0], s[:, 1]))
    ends = np.concatenate((s[:, 0], [i1]))
    bad = np.flatnonzero(starts != ends)
    if bad.size:
        k = int(bad[0])
        a, b = int(starts[k]), int(ends[k])
        what = (f"samples [{a}, {b}) are missing" if b > a
                else f"samples [{b}, {a}) are stored twice")
        raise RecordingFileError(path, f"channel {name!r}: {what} (messages lost or duplicated)")


def _names(info: RecordingInfo, channels) -> list:
    """Channel selection; the registry passes [] for a file with no channels at all."""
    if channels is None or (not info.channels and not isinstance(channels, str)
                            and len(list(channels)) == 0):
        return info.names
    return info.check_channels(channels)


def _recording(lay: _Layout, data: np.ndarray, names: list, i0: int) -> Recording:
    info = lay.info
    specs = {c.name: c for c in info.channels}
    return Recording(data, info.fs, [specs[n] for n in names], t0=info.t0 + i0 / info.fs,
                     start_datetime=info.start_datetime, meta=copy.deepcopy(info.meta),
                     history=copy.deepcopy(info.history))


def _window_ns(lay: _Layout, i0: int, i1: int) -> tuple[int, int]:
    """Inclusive log-time range [ns] of every message that can hold a sample of [i0, i1)."""
    return lay.log_time(max(0, i0 - lay.block + 1)), lay.log_time(i1 - 1)


def _select_chunks(lay: _Layout, ids, start_ns: int, end_ns: int) -> list:
    """Chunk indexes that may hold messages of channel ids ``ids`` with log_time in
    [start_ns, end_ns] (inclusive), in log-time order."""
    out = []
    for ci in lay.summary.chunk_indexes:
        if ci.message_start_time > end_ns or ci.message_end_time < start_ns:
            continue
        if ci.message_index_offsets and not any(i in ci.message_index_offsets for i in ids):
            continue
        out.append(ci)
    out.sort(key=lambda ci: (ci.message_start_time, ci.chunk_start_offset))
    return out


def read(path, channels=None, i0: int = 0, i1: int | None = None, *,
         verify: bool = True) -> Recording:
    """Samples ``i0 <= i < i1`` of the named channels of an MCAP recording.

    Parameters
    ----------
    path : str or Path
    channels : str or sequence of str, optional
        Channel names (all when None), in the order wanted.
    i0, i1 : int
        Sample range [i0, i1) [-]; ``i1=None`` reads to the end.
    verify : bool
        Check the CRCs (default True): summary and data-section CRC once per file, and the
        CRC of every chunk read (computed in a worker thread while the samples are copied).
        False skips them (a damaged chunk then reads as whatever its bytes say).

    Returns
    -------
    Recording
        Data in one array allocated once, Fortran order (each channel contiguous); ``t0`` of
        the returned recording is the time of sample ``i0`` [s].

    Notes
    -----
    The chunk index of the summary section (parsed by ``mcap.reader.make_reader``) selects
    the chunks of the wanted channels whose log-time range meets the inclusive range
    ``[log_time(i0 - block + 1), log_time(i1 - 1)]``. Each chunk is read whole into one
    reused buffer (and decompressed); a chunk of full messages of one channel (what
    :func:`write` produces) is copied into the output in one strided copy, any other chunk
    message by message. (Scatter reads straight from the file into the output, saving that
    buffer, measured no faster here: first-touch page faults of the output dominate.)

    Raises
    ------
    CorruptFileError
        A CRC does not match or the file is truncated (the chunk or byte range is named).
    RecordingFileError
        The file is not a meshphase MCAP recording or does not hold what its index says.
    """
    with _open(path, verify) as (path, fh, lay):
        info = lay.info
        names = _names(info, channels)
        n_total = info.n_samples
        i1 = n_total if i1 is None else int(i1)
        i0 = int(i0)
        if not 0 <= i0 <= i1 <= n_total:
            raise ValueError(f"{path}: sample range [{i0}, {i1}) is outside [0, {n_total}]")
        out = np.empty((i1 - i0, len(names)), dtype=lay.dtype.newbyteorder("="), order="F")
        if i1 > i0 and names:
            col = {lay.channel_ids[n]: c for c, n in enumerate(names)}
            spans: list[list] = [[] for _ in names]
            start_ns, end_ns = _window_ns(lay, i0, i1)
            itemsize = lay.dtype.itemsize
            dtype = lay.dtype
            with _lib_errors(path, "reading chunks"), \
                    _ChunkReader(fh, path, lay, verify=verify) as chunks:
                for ci in _select_chunks(lay, col, start_ns, end_ns):
                    recs = chunks.records(ci)
                    fast = _uniform_chunk(recs, lay, col, i0, i1)
                    if fast is not None:  # whole chunk in one strided copy
                        c, first, samples = fast
                        m_, n_ = samples.shape
                        out[first - i0:first - i0 + m_ * n_, c].reshape(m_, n_)[...] = samples
                        spans[c].append((first, first + m_ * n_))
                        continue
                    for cid, off, size, _ in _payloads(recs, col, path):
                        c = col[cid]
                        first, n = _decode(recs, off, size, lay, path, names[c])
                        a = first if first > i0 else i0
                        b = first + n if first + n < i1 else i1
                        if a >= b:
                            continue
                        out[a - i0:b - i0, c] = np.frombuffer(
                            recs, dtype, b - a, off + HEADER_SIZE + (a - first) * itemsize)
                        spans[c].append((a, b))
            for c, name in enumerate(names):
                _check_tiling(path, name, spans[c], i0, i1)
        return _recording(lay, out, names, i0)


def iter_blocks(path, n_block: int, n_overlap: int, channels=None, *,
                verify: bool = True) -> Iterator[Recording]:
    """Stream an MCAP recording in blocks of ``n_block`` samples plus ``n_overlap``.

    One pass over the chunks in log-time order; each message's samples are copied at once
    into the block being filled (samples of later blocks that arrive early are kept aside),
    and a block is handed out as soon as every channel has reached its end. Memory stays
    flat however long the recording is: one block plus one chunk group (about
    n_channels x chunk_size, 8 MiB by default). Block k
    covers samples [k n_block, (k + 1) n_block + n_overlap), clipped to the recording. Each
    channel's messages must come in sample order (as :func:`write` stores them).

    Parameters
    ----------
    path : str or Path
    n_block : int
        Samples per block [-], >= 1.
    n_overlap : int
        Extra samples of the following block appended to each block [-], >= 0.
    channels : sequence of str, optional
        Channel names (all when None).
    verify : bool
        Check the CRCs as :func:`read` does (default True); every chunk feeding a block has
        passed its CRC before the block is handed out.

    Yields
    ------
    Recording
    """
    n_block = as_positive_int(n_block, "n_block")
    if isinstance(n_overlap, bool) or not isinstance(n_overlap, (int, np.integer)) or n_overlap < 0:
        raise ValueError(f"n_overlap must be a non-negative integer, got {n_overlap!r}")
    n_overlap = int(n_overlap)
    with _open(path, verify) as (path, fh, lay):
        info = lay.info
        names = _names(info, channels)
        n_total = info.n_samples
        if n_total == 0:
            return
        n_blocks = -(-n_total // n_block)
        native = lay.dtype.newbyteorder("=")

        def span(k):
            b0 = k * n_block
            return b0, min(n_total, b0 + n_block + n_overlap)

        if not names:
            for k in range(n_blocks):
                b0, b1 = span(k)
                yield _recording(lay, np.empty((b1 - b0, 0), native), names, b0)
            return
        col = {lay.channel_ids[n]: c for c, n in enumerate(names)}
        n_col = len(names)
        # Only block k_next is allocated ("cur"); samples that later blocks need and that
        # arrive early (other channels lag by up to one chunk group) wait in "later" as
        # copies, so the peak is one block plus one chunk group, however long the file.
        later = [deque() for _ in names]  # per channel: (first sample, samples) >= next block
        done = [0] * n_col  # samples [0, done[c]) of channel c have arrived
        k_next = 0  # block being filled

        def start_block(k):
            b0, b1 = span(k)
            out = np.empty((b1 - b0, n_col), native, order="F")
            nxt = b0 + n_block  # samples before this are no longer needed by later blocks
            for c, q in enumerate(later):
                for first, arr in q:
                    a, b = max(first, b0), min(first + arr.size, b1)
                    if a < b:
                        out[a - b0:b - b0, c] = arr[a - first:b - first]
                while q and q[0][0] + q[0][1].size <= nxt:
                    q.popleft()
                if q and q[0][0] < nxt:
                    first, arr = q.popleft()
                    q.appendleft((nxt, arr[nxt - first:]))
            return out

        cur = start_block(0)
        with _lib_errors(path, "streaming chunks"), \
                _ChunkReader(fh, path, lay, verify=verify) as chunks:  # samples are copied out at once
            for ci in _select_chunks(lay, col, 0, _MAX_LOG_TIME):
                recs = chunks.records(ci)
                for cid, off, size, _ in _payloads(recs, col, path):
                    c = col[cid]
                    first, n = _decode(recs, off, size, lay, path, names[c])
                    if first != done[c]:
                        what = "missing" if first > done[c] else "stored twice or out of order"
                        raise RecordingFileError(path, f"channel {names[c]!r}: samples "
                                                       f"[{min(first, done[c])}, {max(first, done[c])}) "
                                                       f"are {what}")
                    arr = np.frombuffer(recs, lay.dtype, n, off + HEADER_SIZE)
                    b0, b1 = span(k_next)
                    a, b = max(first, b0), min(first + n, b1)
                    if a < b:
                        cur[a - b0:b - b0, c] = arr[a - first:b - first]
                    nxt = b0 + n_block
                    if first + n > nxt and k_next + 1 < n_blocks:
                        a = max(first, nxt)
                        later[c].append((a, arr[a - first:].copy()))
                    done[c] = first + n
                low = min(done)
                while k_next < n_blocks and low >= span(k_next)[1]:
                    chunks.finish()  # the chunks feeding this block passed their CRC
                    out, cur = cur, None
                    yield _recording(lay, out, names, span(k_next)[0])
                    del out
                    k_next += 1
                    if k_next < n_blocks:
                        cur = start_block(k_next)
        if k_next < n_blocks:
            c = int(np.argmin(done))
            raise RecordingFileError(path, f"channel {names[c]!r}: samples [{done[c]}, {n_total}) "
                                           f"are missing (messages lost)")


# ---------------------------------------------------------------------------------- writing
def _dumps(value, what: str) -> str:
    try:
        return json.dumps(value, default=json_default)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"recording {what} must be JSON-friendly: {exc}") from exc


def _channel_metadata(spec: ChannelSpec, index: int, fs: float, dtype_name: str) -> dict:
    """The string map stored as MCAP channel metadata for one channel."""
    md = {"name": spec.name, "index": str(index), "kind": spec.kind, "units": spec.units,
          "gain": repr(float(spec.gain)), "fs": repr(float(fs)), "dtype": dtype_name,
          "description": spec.description}
    if spec.gear is not None:
        md["gear"] = str(spec.gear)
    if spec.tooth is not None:
        md["tooth"] = str(int(spec.tooth))
    if spec.face_position is not None:
        md["face_position"] = repr(float(spec.face_position))
    return md


def _recording_metadata(rec, block: int, compression: str, origin: int,
                        dtype_name: str | None = None) -> dict:
    """The string map of the ``meshphase.recording`` Metadata record (``rec``: a Recording,
    or a header with the same attributes and ``dtype_name``)."""
    if dtype_name is None:
        dtype_name = rec.data.dtype.name
    names = [c.name for c in rec.channels]
    md = {"format_version": str(FORMAT_VERSION), "fs": repr(float(rec.fs)), "t0": repr(float(rec.t0)),
          "n_samples": str(int(rec.n_samples)), "n_channels": str(len(names)),
          "channels": json.dumps(names), "dtype": dtype_name, "block": str(block),
          "log_time_origin_ns": str(origin), "compression": compression,
          "meta": _dumps(rec.meta, "meta"), "history": _dumps(rec.history, "history")}
    if rec.start_datetime is not None:
        md["start_datetime"] = rec.start_datetime
    return md


def write(recording: Recording, path, *, block: int = DEFAULT_BLOCK, compression: str = "none",
          chunk_size: int = DEFAULT_CHUNK_SIZE) -> None:
    """Write a recording as MCAP (called through :func:`pipeline.io.write`).

    Parameters
    ----------
    recording : Recording
    path : str or Path
        Written directly (the registry wraps this in a temporary file and a rename).
    block : int
        Samples per message [-] (default 5120; DESIGN.md: fewer makes the per-message cost of
        the readers dominate).
    compression : {"none", "lz4", "zstd"}
        Chunk compression (default none: fastest to read; lz4 reads ~0.7x as fast, zstd is
        codec-bound near 0.3 GS/s per core; noisy strain compresses little).
    chunk_size : int
        Target uncompressed chunk size [B] (default 1 MiB); each chunk holds whole messages
        of one channel.
    """
    if not isinstance(recording, Recording):
        raise TypeError(f"recording must be a Recording, got {type(recording).__name__}")
    write_blocks(recording, [recording.data], path, dtype=recording.data.dtype, block=block,
                 compression=compression, chunk_size=chunk_size)


def write_blocks(header, blocks, path, *, dtype="float64", block: int = DEFAULT_BLOCK,
                 compression: str = "none", chunk_size: int = DEFAULT_CHUNK_SIZE) -> None:
    """Write a recording given as a header and consecutive blocks of samples (streaming).

    Parameters
    ----------
    header : Recording, RecordingInfo or alike
        ``fs``, ``t0``, ``n_samples``, ``channels``, ``start_datetime``, ``meta``,
        ``history`` (samples, if any, not read).
    blocks : iterable of ndarray, shape (k, n_channels)
        The samples, in order; together exactly ``header.n_samples`` rows.
    path : str or Path
    dtype : {"float32", "float64"}
    block, compression, chunk_size
        As :func:`write`.

    Notes
    -----
    The file is the one :func:`write` makes of the same samples: messages are grouped into
    chunks as they come, so one chunk group (about n_channels x chunk_size bytes) is
    buffered, whatever the length.
    """
    block = as_positive_int(block, "block")
    if block > 2 ** 32 - 1:
        raise ValueError(f"block must be < 2**32 samples, got {block}")
    compression = as_choice(compression, "compression", COMPRESSIONS)
    chunk_size = as_positive_int(chunk_size, "chunk_size")
    rec = header
    nch = len(rec.channels)
    if nch > 65000:
        raise ValueError(f"MCAP holds at most 65000 channels here, the recording has {nch}")
    dtype_name = np.dtype(dtype).name
    if dtype_name not in _DTYPE_CODES:  # Recording guarantees float32/float64
        raise TypeError(f"recording data must be float32 or float64, got {np.dtype(dtype)}")
    le = np.dtype(dtype_name).newbyteorder("<")
    n = int(rec.n_samples)
    origin = _origin_ns(rec.t0)
    if n and _log_time(n - 1, rec.fs, origin) > _MAX_LOG_TIME:
        raise ValueError(f"recording too long for MCAP uint64 nanosecond log times: "
                         f"{n} samples at fs={rec.fs!r} Hz from origin {origin} ns")

    rec_md = _recording_metadata(rec, block, compression, origin, dtype_name)
    ch_md = [_channel_metadata(s, i, rec.fs, dtype_name) for i, s in enumerate(rec.channels)]
    for kind, md in [("recording", rec_md)] + [("channel", m) for m in ch_md]:
        problem = _schema_problem(kind, md)
        if problem:  # a bug of ours, or a value the schema does not allow
            raise ValueError(f"{kind} metadata {md.get('name', '')!r} does not validate: {problem}")

    comp = {"none": CompressionType.NONE, "lz4": CompressionType.LZ4,
            "zstd": CompressionType.ZSTD}[compression]
    layout = json.dumps(LAYOUT, indent=1).encode("utf-8")
    code = _DTYPE_CODES[dtype_name]
    n_msgs = -(-n // block)
    per_chunk = max(1, chunk_size // (HEADER_SIZE + block * le.itemsize))
    group_len = per_chunk * block
    with open(path, "wb") as fh:
        # chunk_size of the library writer is set out of reach: chunks are closed here
        # (one channel per chunk, one group of blocks per chunk).
        w = Writer(fh, chunk_size=1 << 62, compression=comp, index_types=IndexType.ALL,
                   use_chunking=True, use_statistics=True, use_summary_offsets=True,
                   enable_crcs=True, enable_data_crcs=True)
        w.start(profile=PROFILE, library=f"meshphase-mcap/{FORMAT_VERSION}; {LIBRARY_IDENTIFIER}")
        sid = w.register_schema(SCHEMA_NAME, SCHEMA_ENCODING, layout)
        cids = [w.register_channel(s.name, MESSAGE_ENCODING, sid, md)
                for s, md in zip(rec.channels, ch_md)]
        w.add_metadata(RECORDING_METADATA, rec_md)

        def put(group: np.ndarray, s0: int) -> None:
            """Write the messages of samples [s0, s0 + group width): one chunk per channel."""
            s1 = s0 + group.shape[1]
            g0, g1 = s0 // block, -(-s1 // block)
            times = [_log_time(k * block, rec.fs, origin) for k in range(g0, g1)]
            for j, cid in enumerate(cids):
                row = group[j]
                for k in range(g0, g1):
                    a = k * block
                    b = min(s1, a + block)
                    payload = _HEADER.pack(a, b - a, 1, code, FORMAT_VERSION) + \
                        row[a - s0:b - s0].tobytes()
                    w.add_message(cid, times[k - g0], payload, times[k - g0], sequence=k & 0xFFFFFFFF)
                w.flush()  # close the chunk: one channel per chunk

        # groups of per_chunk messages, (channels, samples), little-endian
        buf = np.empty((nch, min(group_len, max(n, 1))), dtype=le)
        fill = pos = 0
        for blk in blocks:
            blk = np.asarray(blk)
            if blk.ndim != 2 or blk.shape[1] != nch:
                raise ValueError(f"blocks must be (samples, {nch}) arrays, got shape {blk.shape}")
            k = blk.shape[0]
            if pos + fill + k > n:
                raise ValueError(f"blocks hold more than the header's n_samples = {n}")
            i = 0
            while i < k:
                if fill == 0 and k - i >= group_len:
                    put(np.ascontiguousarray(blk[i:i + group_len].T, dtype=le), pos)
                    pos += group_len
                    i += group_len
                    continue
                m = min(group_len - fill, k - i)
                buf[:, fill:fill + m] = blk[i:i + m].T
                fill += m
                i += m
                if fill == group_len:
                    put(buf, pos)
                    pos += group_len
                    fill = 0
        if fill:
            put(buf[:, :fill], pos)
            pos += fill
        if pos != n:
            raise ValueError(f"blocks hold {pos} samples, the header says n_samples = {n}")
        w.finish()
