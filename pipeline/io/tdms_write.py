"""The TDMS writer: NI TDMS files (npTDMS ``TdmsWriter``) laid out as NI rigs write them.

The files take the reader's path (:mod:`meshphase.io.tdms`, ``data_schemas/tdms_mapping.md``):

* one group (default ``"meshphase"``), one channel per recording channel, in order
  (float64; :func:`write` and :func:`write_blocks` store the recording's or the given dtype);
* per channel: ``wf_increment`` = 1 / fs [s], ``wf_start_offset`` = t0 [s],
  ``wf_start_time`` (the recording's ``start_datetime``, UTC; the LabVIEW zero time
  1904-01-01 when it has none, which the reader takes as "not set"), ``wf_samples``,
  ``unit_string``, ``NI_ChannelName``, ``meshphase_kind``, ``meshphase_gear``,
  ``meshphase_tooth``, ``meshphase_face_position`` [m], ``meshphase_description``
  (an encoder's ``meshphase_shaft``, ``meshphase_pulses_per_rev``), ``meshphase_gain``;
* file properties: ``name`` (the file's stem for :func:`write_tdms`; the ``name`` option of
  :func:`write`), ``meshphase_meta`` and ``meshphase_history`` (JSON text);
* one segment per block (blocks of >= 1e5 samples keep the per-segment overhead of the
  reader negligible), so memory stays flat however long the recording.

:func:`write` and :func:`write_blocks` are the tdms format's writer entry points of the
registry (they write into the temporary file :func:`meshphase.io.write` made);
:func:`write_tdms` writes Recording blocks to a path atomically itself.

:func:`write_ni_log` writes the layout NI-DAQmx logging produces instead (written here byte
by byte after NI's published TDMS format, since npTDMS's writer cannot): small segments of a
fixed number of samples per channel (512 or 1000 are typical), channel data contiguous or
interleaved, the metadata in the first segment only and the following segments made of a
lead-in and raw data ("same layout as before"); a shorter last segment repeats the raw data
index with its own count.
"""

from __future__ import annotations

import datetime as _dt
import json
import struct
from pathlib import Path
from typing import Iterable, Iterator

import numpy as np

from ..recording import Recording
from .atomic import atomic_path
from .base import checked_write_blocks

__all__ = ["write", "write_blocks", "write_tdms", "write_ni_log", "LABVIEW_ZERO", "DEFAULT_GROUP"]

#: TDMS timestamp zero (LabVIEW epoch): "start time not set".
LABVIEW_ZERO = np.datetime64("1904-01-01T00:00:00", "us")
#: Group of the channels written.
DEFAULT_GROUP = "meshphase"


def _start_time(start_datetime: str | None) -> np.datetime64:
    if start_datetime is None:
        return LABVIEW_ZERO
    d = _dt.datetime.fromisoformat(start_datetime)
    if d.tzinfo is not None:
        d = d.astimezone(_dt.timezone.utc).replace(tzinfo=None)
    return np.datetime64(d, "us")


def _channel_props(header, n_total: int) -> list[dict]:
    """The channel properties of ``header`` (a Recording or alike: channels, fs, t0,
    start_datetime), ``n_total`` samples per channel."""
    out = []
    for spec in header.channels:
        p = {
            "wf_increment": 1.0 / header.fs,
            "wf_start_offset": float(header.t0),
            "wf_start_time": _start_time(header.start_datetime),
            "wf_samples": int(n_total),
            "unit_string": spec.units,
            "NI_ChannelName": spec.name,
            "meshphase_kind": spec.kind,
            "meshphase_description": spec.description,
        }
        if spec.gear is not None:
            p["meshphase_gear"] = spec.gear
        if spec.tooth is not None:
            p["meshphase_tooth"] = int(spec.tooth)
        if spec.face_position is not None:
            p["meshphase_face_position"] = float(spec.face_position)
        if spec.shaft is not None:
            p["meshphase_shaft"] = spec.shaft
        if spec.pulses_per_rev is not None:
            p["meshphase_pulses_per_rev"] = int(spec.pulses_per_rev)
        if spec.gain != 1.0:
            p["meshphase_gain"] = float(spec.gain)
        out.append(p)
    return out


def _check_group(group) -> str:
    if not isinstance(group, str) or not group:
        raise ValueError(f"group must be a non-empty string, got {group!r}")
    return group


def _segments(target: Path, header, arrays: Iterable[np.ndarray], *, n_total: int, group: str,
              name: str | None, dtype) -> int:
    """Write ``arrays`` (each (k, channels)) as one TDMS segment each to ``target``, the
    first with the file, group and channel properties of ``header``; the samples written
    (0 and nothing written when ``arrays`` is empty)."""
    from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

    names = [spec.name for spec in header.channels]
    n = 0
    first = True
    with TdmsWriter(str(target)) as w:
        for data in arrays:
            cols = [np.ascontiguousarray(data[:, j], dtype=dtype) for j in range(len(names))]
            if first:
                root = {} if name is None else {"name": name}
                root["meshphase_meta"] = json.dumps(header.meta, default=str)
                root["meshphase_history"] = json.dumps(header.history, default=str)
                props = _channel_props(header, n_total)
                objs = [RootObject(properties=root), GroupObject(group, properties={})]
                objs += [ChannelObject(group, c, x, properties=props[j])
                         for j, (c, x) in enumerate(zip(names, cols))]
                first = False
            else:
                objs = [ChannelObject(group, c, x) for c, x in zip(names, cols)]
            w.write_segment(objs)
            n += data.shape[0]
    return n


def _checked_blocks(blocks: Iterable[Recording], first: Recording) -> Iterator[np.ndarray]:
    """The samples of Recording ``blocks`` (``first`` leading), each checked to continue the
    previous one (same channels and fs, consecutive t0)."""
    expect_t = None
    for rec in blocks:
        if not isinstance(rec, Recording):
            raise TypeError(f"blocks must be Recordings, got {type(rec).__name__}")
        if expect_t is not None:
            if rec.names != first.names or rec.fs != first.fs:
                raise ValueError(f"block at t0={rec.t0!r} s has channels {rec.names} at "
                                 f"{rec.fs!r} Hz, the first block {first.names} at {first.fs!r} Hz")
            if abs(rec.t0 - expect_t) > 0.5 / rec.fs:
                raise ValueError(f"block starts at t0={rec.t0!r} s, expected {expect_t!r} s "
                                 "(blocks must be consecutive)")
        yield rec.data
        expect_t = rec.t0 + rec.n_samples / rec.fs


def write_tdms(blocks: Recording | Iterable[Recording], path, *, n_samples: int | None = None,
               group: str = DEFAULT_GROUP, overwrite: bool = False) -> Path:
    """Write a recording, or consecutive blocks of one, to an NI TDMS file (atomically).

    Parameters
    ----------
    blocks : Recording or iterable of Recording
        The recording, or its consecutive blocks (same channels and fs; each block's t0 must
        continue the previous one); each block becomes one TDMS segment, stored as float64.
    path : str or Path
        Output file (``.tdms``); its stem is the file property ``name``.
    n_samples : int, optional
        Total samples per channel, written as ``wf_samples`` (default: the first block's).
    group : str
        TDMS group name.
    overwrite : bool
        Replace an existing file (default False: FileExistsError).

    Returns
    -------
    Path
    """
    if isinstance(blocks, Recording):
        blocks = [blocks]
    group = _check_group(group)
    path = Path(path)
    it = iter(blocks)
    with atomic_path(path, overwrite=overwrite) as tmp:
        first = next(it, None)
        if first is None:
            raise ValueError("no blocks to write")
        if not isinstance(first, Recording):
            raise TypeError(f"blocks must be Recordings, got {type(first).__name__}")
        total = first.n_samples if n_samples is None else int(n_samples)
        _segments(tmp, first, _checked_blocks(_chain(first, it), first), n_total=total, group=group,
                  name=path.stem, dtype=np.float64)
    return path


def _chain(first, rest) -> Iterator:
    yield first
    yield from rest


def write(recording: Recording, path, *, name: str | None = None, group: str = DEFAULT_GROUP) -> None:
    """Write ``recording`` into ``path`` (the registry's empty temporary file), one segment,
    samples of the recording's dtype.

    Parameters
    ----------
    recording : Recording
    path : str or Path
    name : str, optional
        The file property ``name`` (none written when None).
    group : str
        TDMS group name.
    """
    if not isinstance(recording, Recording):
        raise TypeError(f"recording must be a Recording, got {type(recording).__name__}")
    _segments(Path(path), recording, [recording.data], n_total=recording.n_samples, group=_check_group(group),
              name=name, dtype=recording.data.dtype)


def write_blocks(header, blocks, path, *, dtype="float64", name: str | None = None,
                 group: str = DEFAULT_GROUP) -> None:
    """Write a header and consecutive blocks of samples into ``path`` (the registry's empty
    temporary file), one segment per non-empty block: memory holds one block.

    Parameters
    ----------
    header : Recording, RecordingInfo or alike
        ``fs``, ``t0``, ``n_samples``, ``channels``, ``start_datetime``, ``meta``, ``history``.
    blocks : iterable of ndarray, shape (k, n_channels)
        Together exactly ``header.n_samples`` rows (ValueError otherwise).
    path : str or Path
    dtype : {"float32", "float64"}
        Sample type stored.
    name : str, optional
        The file property ``name`` (none written when None).
    group : str
        TDMS group name.
    """
    group = _check_group(group)
    dtype = np.dtype(dtype)
    n, nch = int(header.n_samples), len(header.channels)

    def arrays():
        for blk in checked_write_blocks(blocks, nch, n):
            if blk.shape[0]:
                yield blk
        if n == 0:
            yield np.empty((0, nch), dtype=dtype)

    _segments(Path(path), header, arrays(), n_total=n, group=group, name=name, dtype=dtype)


# ---------------------------------------------------------------------------- NI-DAQmx log layout
_TOC_META, _TOC_NEW_OBJ_LIST, _TOC_RAW, _TOC_INTERLEAVED = 1 << 1, 1 << 2, 1 << 3, 1 << 5
_VERSION = 4713
_NO_DATA = 0xFFFFFFFF


def _tdms_string(text: str) -> bytes:
    b = text.encode("utf-8")
    return struct.pack("<I", len(b)) + b


def _tdms_property(name: str, value) -> bytes:
    """One property (name, type code, value) in TDMS encoding."""
    if isinstance(value, (bool, np.bool_)):
        body = struct.pack("<IB", 0x21, int(value))
    elif isinstance(value, (int, np.integer)):
        body = struct.pack("<Ii", 0x03, int(value)) if -2**31 <= value < 2**31 else struct.pack("<Iq", 0x04, int(value))
    elif isinstance(value, (float, np.floating)):
        body = struct.pack("<Id", 0x0A, float(value))
    elif isinstance(value, np.datetime64):
        us = int((value.astype("datetime64[us]") - LABVIEW_ZERO) / np.timedelta64(1, "us"))
        sec, frac_us = divmod(us, 1_000_000)
        body = struct.pack("<IQq", 0x44, (frac_us << 64) // 1_000_000, sec)
    elif isinstance(value, str):
        body = struct.pack("<I", 0x20) + _tdms_string(value)
    else:
        raise TypeError(f"property {name!r}: cannot write a {type(value).__name__} to TDMS")
    return _tdms_string(name) + body


def _object(path: str, props: dict, n_values: int | None) -> bytes:
    index = struct.pack("<I", _NO_DATA) if n_values is None else struct.pack("<IIIQ", 20, 10, 1, n_values)
    return (_tdms_string(path) + index + struct.pack("<I", len(props))
            + b"".join(_tdms_property(k, v) for k, v in props.items()))


def _segment(toc: int, meta: bytes, data: bytes) -> bytes:
    return b"TDSm" + struct.pack("<IIQQ", toc, _VERSION, len(meta) + len(data), len(meta)) + meta + data


def write_ni_log(rec: Recording, path, *, samples_per_segment: int = 512, interleaved: bool = False,
                 group: str = "meshphase", overwrite: bool = False) -> Path:
    """Write a recording as NI-DAQmx logging lays TDMS out: many small segments (atomically).

    Parameters
    ----------
    rec : Recording
        Written as float64, one channel per recording channel, with the channel properties
        of :func:`write_tdms`.
    path : str or Path
        Output file (``.tdms``).
    samples_per_segment : int
        Samples per channel per segment [-] (NI-DAQmx logging: 512 or 1000, say).
    interleaved : bool
        Store the samples interleaved (one row of every channel per sample) instead of one
        contiguous run per channel and segment.
    group : str
        TDMS group name.
    overwrite : bool
        Replace an existing file (default False: FileExistsError).

    Returns
    -------
    Path
    """
    if not isinstance(rec, Recording):
        raise TypeError(f"rec must be a Recording, got {type(rec).__name__}")
    if isinstance(samples_per_segment, bool) or not isinstance(samples_per_segment, (int, np.integer)) \
            or samples_per_segment < 1:
        raise ValueError(f"samples_per_segment must be a positive int, got {samples_per_segment!r}")
    if not isinstance(interleaved, (bool, np.bool_)):
        raise TypeError(f"interleaved must be a bool, got {interleaved!r}")
    if not isinstance(group, str) or not group:
        raise ValueError(f"group must be a non-empty string, got {group!r}")
    n, spc, nch = rec.n_samples, int(samples_per_segment), rec.n_channels
    if nch == 0:
        raise ValueError("the recording has no channels")
    flag = _TOC_INTERLEAVED if interleaved else 0
    gpath = "/'" + group.replace("'", "''") + "'"
    cpaths = [gpath + "/'" + spec.name.replace("'", "''") + "'" for spec in rec.channels]
    root = {"name": Path(path).stem, "meshphase_meta": json.dumps(rec.meta, default=str),
            "meshphase_history": json.dumps(rec.history, default=str)}
    props = _channel_props(rec, n)
    path = Path(path)
    with atomic_path(path, overwrite=overwrite) as tmp, open(tmp, "wb") as fh:
        first = min(n, spc)
        meta = (struct.pack("<I", 2 + nch) + _object("/", root, None) + _object(gpath, {}, None)
                + b"".join(_object(cp, props[j], first) for j, cp in enumerate(cpaths)))
        fh.write(_segment(_TOC_META | _TOC_NEW_OBJ_LIST | _TOC_RAW | flag, meta, _block(rec, 0, first, interleaved)))
        full_end = first + (n - first) // spc * spc
        lead = np.frombuffer(_segment(_TOC_RAW | flag, b"", b"\0" * (spc * nch * 8))[:28], dtype=np.uint8)
        step = max(1, (1 << 22) // (spc * nch))        # segments per write: ~32 MB of samples
        for a in range(first, full_end, step * spc):
            b = min(full_end, a + step * spc)
            k = (b - a) // spc
            out = np.empty((k, 28 + spc * nch * 8), dtype=np.uint8)
            out[:, :28] = lead
            out[:, 28:] = np.frombuffer(_block(rec, a, b, interleaved, spc), dtype=np.uint8).reshape(k, -1)
            fh.write(out.tobytes())
        if full_end < n:     # a shorter last segment: new raw data index, same objects
            meta = struct.pack("<I", nch) + b"".join(_object(cp, {}, n - full_end) for cp in cpaths)
            fh.write(_segment(_TOC_META | _TOC_RAW | flag, meta, _block(rec, full_end, n, interleaved)))
    return path


def _block(rec: Recording, a: int, b: int, interleaved: bool, spc: int | None = None) -> bytes:
    """Raw data of samples [a, b) as segments of ``spc`` samples (one segment when None)."""
    if b <= a:
        return b""
    x = np.asarray(rec.data[a:b], dtype="<f8")
    spc = b - a if spc is None else spc
    x = x.reshape((b - a) // spc, spc, rec.n_channels)
    return (x if interleaved else x.transpose(0, 2, 1)).tobytes()
