"""The MCAP layout of a meshphase recording: names, record framing, the payload header,
log times and the JSON schemas of the metadata (``data_schemas/mcap.md``)."""

from __future__ import annotations

import json
import struct
from functools import lru_cache
from pathlib import Path

from ...jsonable import json_default
from ...validate import as_int, as_positive
from ..registry import FormatSpec

__all__ = ["NAME", "FORMAT", "MAGIC", "SCHEMA_NAME", "MESSAGE_ENCODING",
           "RECORDING_METADATA", "COMPRESSIONS", "DEFAULT_BLOCK", "sniff", "log_time_ns"]

NAME = "mcap"
#: The format's declaration in the registry (:mod:`meshphase.io.registry`); the reader and
#: writer are the package's (``meshphase.io.mcap``). No read libraries: ``mcap`` is imported
#: with the package already.
FORMAT = FormatSpec(
    name=NAME, module="meshphase.io.mcap", suffixes=(".mcap",), writable=True, streaming_write=True,
    checksums=True, read_options={"topics": (list, tuple, dict), "fs": float, "max_jitter": float, "stamp": str},
    write_options={"layout": str, "block": int, "compression": str, "chunk_size": int, "topic": str},
    description="MCAP: ours (CRC32 per chunk), or another tool's mapped by topics=")

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
#: Samples per message by default (>= 5120 keeps the reader's per-message cost, ~8-15 µs, small).
DEFAULT_BLOCK = 5120
#: Target uncompressed chunk size by default [B].
DEFAULT_CHUNK_SIZE = 1 << 20

HEADER = struct.Struct("<QIHBB")  # first_sample, n_samples, n_channels, dtype code, version
HEADER_SIZE = HEADER.size  # 16
DTYPE_CODES = {"float32": 1, "float64": 2}
_CODE_DTYPES = {v: k for k, v in DTYPE_CODES.items()}
MAX_LOG_TIME = 2 ** 64 - 1
MAX_RECORD = 4 * 2 ** 30  # the mcap package's record size limit [B]

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
    "dtypes": {str(v): k for k, v in DTYPE_CODES.items()},
    "samples": "channel-major",
    "log_time": "log_time_origin_ns + floor(first_sample * 1e9 / fs)",
}

# MCAP records: opcode uint8, length uint64, then the record's fields
REC = struct.Struct("<BQ")  # opcode, record length
CHUNK_HEAD = struct.Struct("<QQQII")  # start, end, uncompressed size, crc, compression length
U64 = struct.Struct("<Q")
MSG_HEAD = struct.Struct("<HIQQ")  # channel id, sequence, log_time, publish_time
OP_MESSAGE = 0x05
OP_CHUNK = 0x06


def _json_schema(filename: str) -> dict:
    from ... import data_schemas

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


def schema_problem(kind: str, instance) -> str | None:
    """First validation problem of ``instance`` against schema ``kind``, or None."""
    from jsonschema.exceptions import best_match

    err = best_match(_validator(kind).iter_errors(instance))
    if err is None:
        return None
    where = "/".join(str(p) for p in err.absolute_path)
    return f"{where + ': ' if where else ''}{err.message}"


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
    return log_time(first_sample, as_positive(fs, "fs"), origin_ns)


def log_time(first_sample: int, fs: float, origin_ns: int) -> int:
    p, q = fs.as_integer_ratio()
    return origin_ns + (first_sample * 1_000_000_000 * q) // p


def origin_ns(t0: float) -> int:
    x = t0 * 1e9
    if 0.0 <= x < 2.0 ** 63:
        return int(round(x))
    return 0


def sniff(head: bytes) -> bool:
    """True when ``head`` (the first bytes of a file) starts with the MCAP magic."""
    return bytes(head[:8]) == MAGIC


def dumps_metadata(value, what: str) -> str:
    """``value`` (a recording's meta or history) as JSON text; TypeError naming ``what``."""
    try:
        return json.dumps(value, default=json_default)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"recording {what} must be JSON-friendly: {exc}") from exc
