"""Writing MCAP recordings: the schema, channels and recording metadata, then the samples
in messages of ``block`` samples, one channel per chunk, chunk groups in time order."""

from __future__ import annotations

import json

import numpy as np

from mcap.writer import LIBRARY_IDENTIFIER, CompressionType, IndexType, Writer

from ..base import regroup_blocks
from ...recording import ChannelSpec, Recording
from ...validate import as_choice, as_positive_int
from .foxglove import DEFAULT_TOPIC, LAYOUTS, write_foxglove
from .layout import (DTYPE_CODES, HEADER, MAX_LOG_TIME, COMPRESSIONS, DEFAULT_BLOCK, DEFAULT_CHUNK_SIZE,
                     FORMAT_VERSION, HEADER_SIZE, LAYOUT, MESSAGE_ENCODING, PROFILE, RECORDING_METADATA,
                     SCHEMA_ENCODING, SCHEMA_NAME, dumps_metadata, log_time, origin_ns, schema_problem)

__all__ = ["write", "write_blocks"]


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
    if spec.shaft is not None:
        md["shaft"] = str(spec.shaft)
    if spec.pulses_per_rev is not None:
        md["pulses_per_rev"] = str(int(spec.pulses_per_rev))
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
          "meta": dumps_metadata(rec.meta, "meta"), "history": dumps_metadata(rec.history, "history")}
    if rec.start_datetime is not None:
        md["start_datetime"] = rec.start_datetime
    return md


def write(recording: Recording, path, *, layout: str = "meshphase", block: int | None = None,
          compression: str | None = None, chunk_size: int = DEFAULT_CHUNK_SIZE,
          topic: str | None = None) -> None:
    """Write a recording as MCAP (called through :func:`meshphase.io.write`).

    Parameters
    ----------
    recording : Recording
    path : str or Path
        Written directly (the registry wraps this in a temporary file and a rename).
    layout : {"meshphase", "foxglove"}
        ``"meshphase"`` (default): blocks of samples per message, one MCAP channel per
        recording channel, read back by the fast path. ``"foxglove"``: one self-describing
        JSON message (``jsonschema``) per sample time on one topic, which Foxglove plots
        (:func:`~meshphase.io.mcap.foxglove.write_foxglove`; read back by the generic
        decoder path).
    topic : str, optional
        Topic of the ``foxglove`` layout (default ``/meshphase/samples``).
    block : int
        Samples per message [-] (default 5120: fewer makes the readers' per-message cost,
        ~8-15 µs, dominate).
    compression : {"none", "lz4", "zstd"}
        Chunk compression (default none for the meshphase layout: fastest to read; lz4 reads
        ~0.7x as fast, zstd is codec-bound near 0.3 GS/s per core; noisy strain compresses
        little. Default zstd for the foxglove layout: JSON text compresses).
    chunk_size : int
        Target uncompressed chunk size [B] (default 1 MiB); each chunk holds whole messages
        of one channel.
    """
    if not isinstance(recording, Recording):
        raise TypeError(f"recording must be a Recording, got {type(recording).__name__}")
    write_blocks(recording, [recording.data], path, dtype=recording.data.dtype, layout=layout,
                 block=block, compression=compression, chunk_size=chunk_size, topic=topic)


def write_blocks(header, blocks, path, *, dtype="float64", layout: str = "meshphase",
                 block: int | None = None, compression: str | None = None,
                 chunk_size: int = DEFAULT_CHUNK_SIZE, topic: str | None = None) -> None:
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
    layout, block, compression, chunk_size, topic
        As :func:`write`.

    Notes
    -----
    The file is the one :func:`write` makes of the same samples: messages are grouped into
    chunks as they come, so one chunk group (about n_channels x chunk_size bytes) is
    buffered, whatever the length.
    """
    layout = as_choice(layout, "layout", LAYOUTS)
    if layout == "foxglove":
        if block is not None:
            raise ValueError("block sets the samples per message of the meshphase layout; the "
                             "foxglove layout writes one message per sample time")
        chunk_size = as_positive_int(chunk_size, "chunk_size")
        write_foxglove(header, blocks, path, dtype=dtype, chunk_size=chunk_size,
                       compression="zstd" if compression is None else compression,
                       topic=DEFAULT_TOPIC if topic is None else topic)
        return
    if topic is not None:
        raise ValueError("topic names the topic of the foxglove layout; the meshphase layout "
                         "has one topic per channel (its name)")
    block = as_positive_int(DEFAULT_BLOCK if block is None else block, "block")
    compression = "none" if compression is None else compression
    if block > 2 ** 32 - 1:
        raise ValueError(f"block must be < 2**32 samples, got {block}")
    compression = as_choice(compression, "compression", COMPRESSIONS)
    chunk_size = as_positive_int(chunk_size, "chunk_size")
    rec = header
    nch = len(rec.channels)
    if nch > 65000:
        raise ValueError(f"MCAP holds at most 65000 channels here, the recording has {nch}")
    dtype_name = np.dtype(dtype).name
    if dtype_name not in DTYPE_CODES:  # Recording guarantees float32/float64
        raise TypeError(f"recording data must be float32 or float64, got {np.dtype(dtype)}")
    le = np.dtype(dtype_name).newbyteorder("<")
    n = int(rec.n_samples)
    origin = origin_ns(rec.t0)
    if n and log_time(n - 1, rec.fs, origin) > MAX_LOG_TIME:
        raise ValueError(f"recording too long for MCAP uint64 nanosecond log times: "
                         f"{n} samples at fs={rec.fs!r} Hz from origin {origin} ns")
    rec_md, ch_md = _checked_metadata(rec, block, compression, origin, dtype_name)
    code = DTYPE_CODES[dtype_name]
    per_chunk = max(1, chunk_size // (HEADER_SIZE + block * le.itemsize))
    with open(path, "wb") as fh:
        w, cids = _start_writer(fh, compression, rec, rec_md, ch_md)
        for group, s0 in regroup_blocks(blocks, nch, n, per_chunk * block, le):
            _put_group(w, cids, group, s0, block=block, fs=rec.fs, origin=origin, code=code)
        w.finish()


def _checked_metadata(rec, block: int, compression: str, origin: int, dtype_name: str) -> tuple[dict, list]:
    """The recording's and each channel's metadata map, validated against their schemas."""
    rec_md = _recording_metadata(rec, block, compression, origin, dtype_name)
    ch_md = [_channel_metadata(s, i, rec.fs, dtype_name) for i, s in enumerate(rec.channels)]
    for kind, md in [("recording", rec_md)] + [("channel", m) for m in ch_md]:
        problem = schema_problem(kind, md)
        if problem:  # a bug of ours, or a value the schema does not allow
            raise ValueError(f"{kind} metadata {md.get('name', '')!r} does not validate: {problem}")
    return rec_md, ch_md


def _start_writer(fh, compression: str, rec, rec_md: dict, ch_md: list) -> tuple[Writer, list]:
    """An MCAP writer on ``fh`` with the header, schema, channels and recording metadata
    written; returns it and the MCAP channel ids in recording order."""
    comp = {"none": CompressionType.NONE, "lz4": CompressionType.LZ4,
            "zstd": CompressionType.ZSTD}[compression]
    # chunk_size of the library writer is set out of reach: chunks are closed here
    # (one channel per chunk, one group of blocks per chunk).
    w = Writer(fh, chunk_size=1 << 62, compression=comp, index_types=IndexType.ALL,
               use_chunking=True, use_statistics=True, use_summary_offsets=True,
               enable_crcs=True, enable_data_crcs=True)
    w.start(profile=PROFILE, library=f"meshphase-mcap/{FORMAT_VERSION}; {LIBRARY_IDENTIFIER}")
    sid = w.register_schema(SCHEMA_NAME, SCHEMA_ENCODING, json.dumps(LAYOUT, indent=1).encode("utf-8"))
    cids = [w.register_channel(s.name, MESSAGE_ENCODING, sid, md)
            for s, md in zip(rec.channels, ch_md)]
    w.add_metadata(RECORDING_METADATA, rec_md)
    return w, cids


def _put_group(w: Writer, cids: list, group: np.ndarray, s0: int, *, block: int, fs: float,
               origin: int, code: int) -> None:
    """Write the messages of samples [s0, s0 + group width) (``group``: channels x samples):
    one chunk per channel."""
    s1 = s0 + group.shape[1]
    g0, g1 = s0 // block, -(-s1 // block)
    times = [log_time(k * block, fs, origin) for k in range(g0, g1)]
    for j, cid in enumerate(cids):
        row = group[j]
        for k in range(g0, g1):
            a = k * block
            b = min(s1, a + block)
            payload = HEADER.pack(a, b - a, 1, code, FORMAT_VERSION) + row[a - s0:b - s0].tobytes()
            w.add_message(cid, times[k - g0], payload, times[k - g0], sequence=k & 0xFFFFFFFF)
        w.flush()  # close the chunk: one channel per chunk
