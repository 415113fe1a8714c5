"""Opening an MCAP recording: the file's ends, its summary (chunk index, schema, channels)
and the recording header, checked and parsed into a :class:`Layout`, cached per file
identity together with the outcome of the summary and data-section CRC checks."""

from __future__ import annotations

import contextlib
import json
import math
import os
import struct
import threading
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

from mcap.exceptions import McapError
from mcap.reader import make_reader

from ...recording import ChannelSpec
from ..base import CorruptFileError, RecordingFileError, RecordingInfo, check_verify
from .crc import check_data_crc, check_summary_crc
from .layout import (DTYPE_CODES, FORMAT_VERSION, MAGIC, MESSAGE_ENCODING, NAME, RECORDING_METADATA,
                     SCHEMA_ENCODING, SCHEMA_NAME, log_time, schema_problem)

__all__: list[str] = ["ForeignMcapError"]


class ForeignMcapError(RecordingFileError):
    """An MCAP file without meshphase's block layout (another tool's file): the foreign path
    (:mod:`.foreign`) reads it with a mapping."""

# Exceptions the mcap package (and its codecs) raise on malformed input; wrapped into
# RecordingFileError so a caller never sees a raw struct/EOF error.
LIB_ERRORS: tuple[type[BaseException], ...] = (McapError, struct.error, EOFError, ValueError, KeyError,
                                               IndexError, RuntimeError, UnicodeDecodeError,
                                               OverflowError)
try:  # zstandard's error does not derive from a standard class
    import zstandard as _zstd

    LIB_ERRORS = LIB_ERRORS + (_zstd.ZstdError,)
except ImportError:  # pragma: no cover - zstandard is a dependency
    pass


@dataclass
class Layout:
    info: RecordingInfo
    dtype: np.dtype
    block: int
    origin_ns: int
    channel_ids: dict  # name -> MCAP channel id
    schema_id: int
    summary: object  # mcap.summary.Summary
    code: int  # payload dtype code

    def log_time(self, i: int) -> int:
        return log_time(i, self.info.fs, self.origin_ns)


@contextlib.contextmanager
def lib_errors(path: Path, what: str):
    """Turn errors of the mcap package into RecordingFileError naming the file."""
    try:
        yield
    except RecordingFileError:
        raise
    except LIB_ERRORS as exc:
        detail = str(exc) or type(exc).__name__
        raise RecordingFileError(path, f"malformed MCAP while {what}: {type(exc).__name__}: "
                                       f"{detail}") from exc


def check_ends(fh, path: Path) -> None:
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


def _summary(fh, path: Path, verify: bool):
    """(reader, summary) from ``mcap.reader.make_reader`` (summary None when absent)."""
    with lib_errors(path, "reading the summary section"):
        reader = make_reader(fh, validate_crcs=verify)
        return reader, reader.get_summary()


def _read_layout(fh, path: Path, verify: bool = True, opened=None) -> tuple[object, Layout]:
    """Open an MCAP stream, check it is one of ours and parse the header records.
    ``opened``: (reader, summary) already made by :func:`_summary`."""
    check_ends(fh, path)
    reader, summary = opened if opened is not None else _summary(fh, path, verify)
    if summary is None:
        raise RecordingFileError(path, "MCAP file has no summary section (no index); meshphase "
                                       "needs the chunk index to read blocks and time windows")
    schema = _our_schema(summary, path)
    hd = _recording_header(reader, path)
    specs, ids = _channel_specs(summary, schema.id, hd, path)
    compressions = sorted({ci.compression or "none" for ci in summary.chunk_indexes})
    stats = summary.statistics
    extra = {
        "layout": "one MCAP channel per recording channel, blocks of samples per message",
        "block": hd.block,
        "dtype": hd.dtype_name,
        "compression": hd.md.get("compression", compressions[0] if len(compressions) == 1 else None),
        "chunk_compressions": compressions,
        "n_chunks": len(summary.chunk_indexes),
        "n_messages": int(stats.message_count) if stats is not None else None,
        "log_time_origin_ns": hd.origin,
    }
    info = RecordingInfo(path=str(path), format=NAME, fs=hd.fs, n_samples=hd.n_samples,
                         channels=specs, t0=hd.t0, start_datetime=hd.md.get("start_datetime"),
                         meta=hd.meta, history=hd.history, extra=extra)
    return reader, Layout(info=info, dtype=np.dtype(hd.dtype_name).newbyteorder("<"), block=hd.block,
                           origin_ns=hd.origin, channel_ids=ids, schema_id=schema.id, summary=summary,
                           code=DTYPE_CODES[hd.dtype_name])


def _our_schema(summary, path: Path):
    """The one ``meshphase.SampleBlock`` Schema record, its payload layout checked."""
    ours = [s for s in summary.schemas.values() if s.name == SCHEMA_NAME]
    if not ours:
        schemas = sorted({f"{s.name} ({s.encoding})" for s in summary.schemas.values()})
        topics = sorted({c.topic for c in summary.channels.values()})
        raise ForeignMcapError(
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
    problem = schema_problem("layout", layout)
    if problem:
        raise RecordingFileError(path, f"schema {SCHEMA_NAME!r}: unsupported payload layout "
                                       f"({problem}); this reader knows version {FORMAT_VERSION}")
    return schema


class _Header(NamedTuple):
    """The ``meshphase.recording`` Metadata record, parsed (``md``: its string map)."""

    md: dict
    fs: float  # [Hz]
    t0: float  # [s]
    n_samples: int
    block: int  # samples per message
    origin: int  # log time of sample 0 [ns]
    names: list
    meta: dict
    history: list
    dtype_name: str


def _recording_header(reader, path: Path) -> _Header:
    """The one ``meshphase.recording`` Metadata record, checked against its schema."""
    with lib_errors(path, "reading metadata records"):
        records = [m for m in reader.iter_metadata() if m.name == RECORDING_METADATA]
    if not records:
        raise RecordingFileError(path, f"no {RECORDING_METADATA!r} Metadata record: the recording "
                                       f"header (fs, t0, n_samples, channels) is missing")
    if len(records) > 1:
        raise RecordingFileError(path, f"{len(records)} {RECORDING_METADATA!r} Metadata records; "
                                       f"expected one")
    md = dict(records[0].metadata)
    problem = schema_problem("recording", md)
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
    return _Header(md, fs, t0, n_samples, block, origin, names, meta, history, md["dtype"])


def _channel_specs(summary, schema_id: int, hd: _Header, path: Path) -> tuple[list, dict]:
    """(ChannelSpecs in recording order, name -> MCAP channel id) of the channels of our
    schema, each checked against the recording header."""
    names, n_channels = hd.names, len(hd.names)
    channels = {}
    ids = {}
    for ch in summary.channels.values():
        if ch.schema_id != schema_id:
            continue  # another writer's channel in the same file: not ours, ignored
        if ch.message_encoding != MESSAGE_ENCODING:
            raise RecordingFileError(path, f"channel {ch.topic!r}: message encoding "
                                           f"{ch.message_encoding!r}, expected {MESSAGE_ENCODING!r}")
        cm = dict(ch.metadata)
        problem = schema_problem("channel", cm)
        if problem:
            raise RecordingFileError(path, f"channel {ch.topic!r} metadata: {problem}")
        idx = int(cm["index"])
        if idx >= n_channels or idx in channels or cm["name"] != ch.topic or names[idx] != ch.topic:
            raise RecordingFileError(path, f"channel {ch.topic!r}: index {idx} / name "
                                           f"{cm['name']!r} do not match the channel list {names}")
        if float(cm["fs"]) != hd.fs:
            raise RecordingFileError(path, f"channel {ch.topic!r}: fs {cm['fs']} Hz differs from "
                                           f"the recording's {hd.md['fs']} Hz")
        if cm["dtype"] != hd.dtype_name:
            raise RecordingFileError(path, f"channel {ch.topic!r}: dtype {cm['dtype']} differs from "
                                           f"the recording's {hd.dtype_name}")
        try:
            spec = ChannelSpec(
                name=cm["name"], kind=cm["kind"], units=cm["units"], gain=float(cm["gain"]),
                gear=cm.get("gear"),
                tooth=int(cm["tooth"]) if "tooth" in cm else None,
                face_position=float(cm["face_position"]) if "face_position" in cm else None,
                description=cm["description"], shaft=cm.get("shaft"),
                pulses_per_rev=int(cm["pulses_per_rev"]) if "pulses_per_rev" in cm else None)
        except (TypeError, ValueError) as exc:
            raise RecordingFileError(path, f"channel {ch.topic!r} metadata: {exc}") from exc
        channels[idx] = spec
        ids[spec.name] = ch.id
    missing = [names[i] for i in range(n_channels) if i not in channels]
    if missing:
        raise RecordingFileError(path, f"channel(s) {missing} listed in {RECORDING_METADATA!r} have "
                                       f"no MCAP channel")
    return [channels[i] for i in range(n_channels)], ids


# Parsed headers of the last few files, keyed by path and file identity (device, inode,
# size, mtime, ctime): the registry opens a file twice per read (read_info, then read), and a
# 1-hour recording's summary (~1200 chunk indexes) takes ~20 ms to parse. Only the header
# is cached; samples are always read from the file.
_LAYOUTS: OrderedDict = OrderedDict()
_LAYOUTS_MAX = 8
# identities of files whose summary and data-section CRCs passed (same key as _LAYOUTS)
_VERIFIED: OrderedDict = OrderedDict()
_LOCK = threading.Lock()


@contextlib.contextmanager
def open_layout(path, verify: bool = True):
    """Open ``path`` (once per file identity: the CRC checks and the parsed header are
    cached); yields (path, open file, :class:`Layout`)."""
    path = Path(path)
    verify = check_verify(verify)
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
            check_ends(fh, path)
            _, data_end = check_summary_crc(fh, path)
            opened = _summary(fh, path, verify)  # the summary passed its CRC
            summary = opened[1]
            if summary is not None and any(sc.name == SCHEMA_NAME for sc in summary.schemas.values()):
                # one of ours (else _read_layout says what it is, without walking a foreign
                # file); the summary starts right after the DataEnd record: the walk stops there
                check_data_crc(fh, path, data_end)
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

