"""NI TDMS (npTDMS): what NI DAQ rigs record. Read only (``CAN_WRITE = False``).

Mapping (full description in ``data_schemas/tdms_mapping.md``):

* Every numeric channel of every group becomes one Recording channel, in file order. Its
  name is the TDMS channel name when those are unique across groups, else
  ``"<group>/<channel>"`` for every channel. Channels with no numeric data (strings,
  timestamps, no data type) are skipped with a FormatWarning.
* kind: the channel property ``meshphase_kind`` when present; else from the channel name,
  then the group name (case-insensitive): ``sun*`` -> sun, ``ring*`` -> ring, ``fw*``/``face*``
  -> facewidth, ``tacho*``/``once*`` -> tacho; else "other".
* units: ``unit_string`` (else ``NI_UnitDescription``, else ""); tooth, face position [m],
  gear, gain and description from ``meshphase_tooth``, ``meshphase_face_position``,
  ``meshphase_gear``, ``meshphase_gain``, ``meshphase_description`` (else ``description``).
* fs = 1 / ``wf_increment`` (the same on every channel); missing or non-positive ->
  RecordingFileError "missing or non-positive sample rate" unless ``fs=`` is given.
  t0 = ``wf_start_offset`` [s] (0 when absent); start_datetime = ``wf_start_time`` (UTC; the
  LabVIEW zero time 1904-01-01 means "not set").
* NI scaling (``NI_Scale[...]`` properties) is applied by default: samples are physical,
  gain = 1. ``raw=True`` keeps the stored values: gain = slope for a single zero-intercept
  linear scale (units stay physical), else gain = 1 and units "raw". Either way the history
  gets one entry ``{"step": "read_tdms", "file", "scaled", "ni_scaled_channels"}``.
* meta: the file property ``meshphase_meta`` (JSON object text) when present, plus
  meta["tdms"] with the file, group and channel properties (JSON-friendly); history: the file
  property ``meshphase_history`` (JSON array text) when present, then the read_tdms entry.

Channels of unequal length, files npTDMS cannot parse and a stale ``.tdms_index`` raise
RecordingFileError naming the file and the problem. Truncated or damaged structure raises
its subclass CorruptFileError with the segment and byte offset: every segment lead-in is
followed from byte 0 to the end of the file (a lead-in cut short, a segment whose
next-segment offset runs past the end of the file or was never written, a lead-in without
the ``TDSm`` tag, a raw-data offset beyond its segment), a segment holding a partial chunk
of data, and, in files written by meshphase (channel property ``meshphase_kind``), fewer
samples than ``wf_samples`` says (a cut exactly at a segment boundary). TDMS stores no
checksums: a flipped byte in the raw data cannot be detected.

Reading: metadata through ``TdmsFile.open``; the samples of plain segments (contiguous,
little-endian, non-DAQmx) are read with ``readinto`` straight into the preallocated output
(in file order, scaling applied per segment); other files go through npTDMS's
``read_data(offset, length)`` per channel. :func:`iter_blocks` keeps the file open and reads
block after block, so memory stays flat.
"""

from __future__ import annotations

import contextlib
import copy
import hashlib
import json
import logging
import math
import os
import sys
from collections import OrderedDict
import re
import struct
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from ..errors import FormatWarning
from ..jsonable import to_jsonable
from ..recording import CHANNEL_KINDS, ChannelSpec, Recording
from ..validate import as_int, as_positive, as_positive_int
from .base import CorruptFileError, RecordingFileError, RecordingInfo, check_verify, spec_from_dict, warn_nonfinite

__all__ = ["NAME", "SUFFIXES", "CAN_WRITE", "sniff", "read_info", "read", "iter_blocks", "kind_from_name"]

NAME = "tdms"
SUFFIXES = (".tdms",)
CAN_WRITE = False

_LEAD_IN = 28
_TOC_RAW = 1 << 3
_TOC_INTERLEAVED = 1 << 5
_TOC_BIG_ENDIAN = 1 << 6
_TOC_DAQMX = 1 << 7
_INCOMPLETE = 0xFFFFFFFFFFFFFFFF
#: Read plain segments with readinto (tests switch it off to compare with npTDMS's reader).
_USE_FAST_PATH = True
_LABVIEW_ZERO = np.datetime64("1904-01-01T00:00:00", "us")

_KIND_PATTERNS = (
    ("sun", re.compile(r"^sun", re.I)),
    ("ring", re.compile(r"^ring", re.I)),
    ("facewidth", re.compile(r"^(fw|face)", re.I)),
    ("tacho", re.compile(r"^(tacho|once)", re.I)),
)


def kind_from_name(*names: str) -> str:
    """Channel kind from the first name (channel, then group) matching a pattern, else "other"."""
    for name in names:
        for kind, pat in _KIND_PATTERNS:
            if pat.match(name.strip()):
                return kind
    return "other"


def sniff(head: bytes) -> bool:
    """True for a TDMS data file (lead-in tag ``TDSm``); ``TDSh`` index files are not recordings."""
    return head[:4] == b"TDSm"


# ---------------------------------------------------------------------------- structure check
def _walk_segments(path) -> tuple[int, bytes]:
    """Follow the segment lead-ins from byte 0 to the end; RecordingFileError on any cut.

    Returns the number of segments and a digest of every lead-in and metadata block (all that
    the read plan depends on; the raw data are not hashed).
    """
    size = os.path.getsize(path)
    if size == 0:
        raise RecordingFileError(path, "file is empty (0 bytes)")
    digest = hashlib.blake2b(digest_size=16)
    digest.update(struct.pack("<Q", size))
    n = 0
    pos = 0
    with open(path, "rb") as fh:
        while pos < size:
            if size - pos < _LEAD_IN:
                raise CorruptFileError(path, f"segment {n} at byte {pos}", f"truncated: incomplete lead-in "
                                                                           f"({size - pos} of {_LEAD_IN} bytes)")
            fh.seek(pos)
            lead = fh.read(_LEAD_IN)
            if lead[:4] != b"TDSm":
                raise CorruptFileError(path, f"segment {n} at byte {pos}", f"corrupt: the lead-in does not start "
                                                                           f"with b'TDSm' (found {lead[:4]!r})")
            toc = struct.unpack("<I", lead[4:8])[0]
            endian = ">" if toc & _TOC_BIG_ENDIAN else "<"
            _version, next_off, raw_off = struct.unpack(endian + "IQQ", lead[8:28])
            if next_off == _INCOMPLETE:
                raise CorruptFileError(path, f"segment {n} at byte {pos}", "truncated: the segment was never "
                                       "finished (next-segment offset unset; the writer stopped mid-segment)")
            if raw_off > next_off:
                raise CorruptFileError(path, f"segment {n} at byte {pos}", f"corrupt: raw-data offset {raw_off} "
                                                                           f"beyond the segment length {next_off}")
            nxt = pos + _LEAD_IN + next_off
            if nxt > size:
                raise CorruptFileError(path, f"segment {n} at byte {pos}", f"truncated: the segment needs {nxt} "
                                                                           f"bytes, the file has {size}")
            digest.update(lead)
            if raw_off:
                digest.update(fh.read(raw_off))
            pos = nxt
            n += 1
    return n, digest.digest()


# ---------------------------------------------------------------------------- plan
@dataclass
class _Chan:
    name: str
    ch: Any                 # npTDMS TdmsChannel
    scaling: Any            # npTDMS scaling or None
    raw_dtype: np.dtype
    extents: tuple | None = None   # (starts, counts, offsets) arrays for the fast path


@dataclass
class _Plan:
    info: RecordingInfo
    chans: dict
    dtype: np.dtype
    raw: bool
    fast: bool


def _jsonable(v: Any) -> Any:
    """TDMS property values as strict JSON (non-finite floats as their repr text)."""
    if hasattr(v, "as_datetime64"):  # npTDMS TdmsTimestamp
        v = v.as_datetime64("us")
    elif isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    elif isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    out = to_jsonable(v, nonfinite="repr")
    return out if out is None or isinstance(out, (str, int, float, bool, list, dict)) else str(out)


def _iso(v: np.datetime64) -> str:
    return np.datetime_as_string(v.astype("datetime64[us]"), unit="us") + "+00:00"


def _prop_float(props, key, path, cname):
    v = props.get(key)
    if v is None:
        return None
    try:
        return float(v)
    except (TypeError, ValueError) as exc:
        raise RecordingFileError(path, f"channel {cname!r}: property {key} = {v!r} is not a number") from exc


def _json_property(text, path, key: str, kind: type):
    """A JSON-text file property written by meshphase (meta / history), decoded and checked."""
    if text is None:
        return None
    if not isinstance(text, str):
        raise RecordingFileError(path, f"file property {key} must be JSON text, got {type(text).__name__}")
    try:
        value = json.loads(text)
    except json.JSONDecodeError as exc:
        raise RecordingFileError(path, f"file property {key} is not valid JSON ({exc})") from exc
    if not isinstance(value, kind):
        raise RecordingFileError(path, f"file property {key} must hold a JSON {'object' if kind is dict else 'array'}, "
                                       f"got {type(value).__name__}")
    return value


def _linear_gain(scaling) -> float | None:
    """Slope of a single, zero-intercept linear scale on the raw data, else None."""
    from nptdms import scaling as _sc

    scales = getattr(scaling, "scalings", None)
    if not scales or len(scales) != 1:
        return None
    s = scales[0]
    if isinstance(s, _sc.LinearScaling) and s.intercept == 0 and s.input_source == _sc.RAW_DATA_INPUT_SOURCE:
        return float(s.slope)
    return None


def _has_scale_props(props) -> bool:
    if props.get("NI_Scaling_Status", "unscaled") == "scaled":
        return False
    n = props.get("NI_Number_Of_Scales")
    if n is not None:
        return int(n) > 0
    return any(k.startswith("NI_Scale[") and k.endswith("_Scale_Type") for k in props)


class _Collect(logging.Filter):
    """Keeps npTDMS's log records instead of letting them through (a logger filter that
    returns False stops the record before any handler and before propagation)."""

    def __init__(self):
        super().__init__()
        self.messages: list[str] = []

    #: npTDMS messages this reader reports in its own words already
    SAID = ("Unsupported scale type",)

    def filter(self, record):
        if record.levelno >= logging.WARNING:
            text = " ".join(record.getMessage().split())
            if text.startswith(self.SAID):
                return False
            self.messages.append(text if len(text) <= 200 else text[:197] + "...")
        return False


@contextlib.contextmanager
def _nptdms_logs_as_warnings(path):
    """npTDMS logs what it finds odd ("Segment version mismatch", "Error decoding string",
    "Data size ... is not a multiple of the chunk size") to stderr through its own handler,
    one multi-line record per segment: route its loggers' records into one FormatWarning per
    distinct message naming the file, issued when the read succeeds (when it fails, the
    error says what is wrong and the log lines would only repeat it)."""
    import nptdms  # noqa: F401  (its modules create their loggers on import)

    grab = _Collect()
    loggers = [logging.getLogger(name) for name in list(sys.modules)
               if name == "nptdms" or name.startswith("nptdms.")]
    for lg in loggers:
        lg.addFilter(grab)
    try:
        yield
    finally:
        for lg in loggers:
            lg.removeFilter(grab)
    for msg in dict.fromkeys(grab.messages):
        warnings.warn(FormatWarning(f"{path}: npTDMS: {msg}"), stacklevel=3)


def _open(path):
    from nptdms import TdmsFile

    try:
        return TdmsFile.open(str(path))
    except Exception as exc:  # npTDMS raises ValueError, KeyError, EOFError, struct.error, Exception
        raise RecordingFileError(path, f"cannot parse as TDMS ({type(exc).__name__}: {exc})") from exc


def _plan(tdms, path, n_segments: int, fs_opt, raw: bool) -> _Plan:
    """What a read of this open TDMS file needs: its header as a RecordingInfo, the
    channels to read (with npTDMS's scaling unless ``raw``) and the fast-path extents."""
    path = Path(path)
    groups, usable, names = _usable_channels(tdms, path, n_segments)
    n_samples = _n_samples(path, names, usable)
    fs, t0, start_datetime = _timing(path, names, usable, fs_opt)
    chans = {}
    specs = []
    scaled_names = []
    for n, (g, ch) in zip(names, usable):
        spec, chans[n], scaled = _channel(tdms, path, n, g, ch, raw)
        specs.append(spec)
        if scaled:
            scaled_names.append(n)
    out_kinds = [(c.raw_dtype if (raw or c.scaling is None) else np.dtype(c.ch.dtype)) for c in chans.values()]
    dtype = np.dtype(np.float32) if all(k == np.float32 for k in out_kinds) else np.dtype(np.float64)
    fast = _build_extents(tdms, path, chans, raw)
    file_props = dict(tdms.properties)
    meta = _json_property(file_props.pop("meshphase_meta", None), path, "meshphase_meta", dict) or {}
    history = _json_property(file_props.pop("meshphase_history", None), path, "meshphase_history", list) or []
    meta["tdms"] = {"file": _jsonable(file_props),
                    "groups": {g.name: _jsonable(dict(g.properties)) for g in groups},
                    "channels": {n: _jsonable(dict(ch.properties)) for n, (_, ch) in zip(names, usable)}}
    history.append({"step": "read_tdms", "file": path.name, "scaled": not raw, "ni_scaled_channels": scaled_names})
    info = RecordingInfo(path=str(path), format=NAME, fs=fs, n_samples=int(n_samples), channels=specs, t0=t0,
                         start_datetime=start_datetime, meta=meta, history=history,
                         extra={"n_segments": n_segments, "groups": [g.name for g in groups],
                                "tdms_paths": {n: ch.path for n, (_, ch) in zip(names, usable)},
                                "scaled": not raw, "fast_path": fast})
    return _Plan(info=info, chans=chans, dtype=dtype, raw=raw, fast=fast)


def _usable_channels(tdms, path: Path, n_segments: int) -> tuple[list, list, list]:
    """(groups, [(group, channel)] of the numeric channels, their names): the plain channel
    names, or ``group/channel`` where plain names repeat."""
    reader = getattr(tdms, "_reader", None)
    segs = getattr(reader, "_segments", None)
    if segs is not None and len(segs) != n_segments:
        raise RecordingFileError(path, f"the metadata npTDMS read lists {len(segs)} segments but the file holds "
                                       f"{n_segments} (stale .tdms_index file?)")
    groups = tdms.groups()
    found = []
    for g in groups:
        for ch in g.channels():
            found.append((g, ch))
    usable = []
    for g, ch in found:
        try:
            dt = np.dtype(ch.dtype)
        except TypeError:
            dt = np.dtype("V8")
        if ch.data_type is None or dt.kind not in "biuf":
            warnings.warn(FormatWarning(f"{path}: skipped channel {g.name}/{ch.name}: no numeric data "
                                        f"(type {getattr(ch.data_type, '__name__', ch.data_type)})"), stacklevel=5)
            continue
        usable.append((g, ch))
    if not usable:
        raise RecordingFileError(path, f"no numeric channels (groups: {[g.name for g in groups]})")
    plain = [ch.name for _, ch in usable]
    unique = len(set(plain)) == len(plain)
    names = [ch.name if unique else f"{g.name}/{ch.name}" for g, ch in usable]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise RecordingFileError(path, f"duplicate channel name(s) {dup}")
    return groups, usable, names


def _n_samples(path: Path, names: list, usable: list) -> int:
    """The common length of the channels; a meshphase file shorter than its wf_samples is
    truncated."""
    lengths = {n: len(ch) for n, (_, ch) in zip(names, usable)}
    for n, (_, ch) in zip(names, usable):
        # meshphase writes the total sample count as wf_samples (NI writers use it for other
        # counts, so only our own files are held to it)
        want = ch.properties.get("wf_samples")
        if "meshphase_kind" in ch.properties and isinstance(want, (int, np.integer)) and lengths[n] < want:
            raise CorruptFileError(path, f"channel {n!r}, end of file at byte {os.path.getsize(path)}",
                                   f"truncated: {lengths[n]} samples, wf_samples says {int(want)} (the file was "
                                   f"cut at a segment boundary)")
    if len(set(lengths.values())) > 1:
        raise RecordingFileError(path, f"channels of unequal length: {lengths}")
    return next(iter(lengths.values()))


def _timing(path: Path, names: list, usable: list, fs_opt) -> tuple[float, float, str | None]:
    """(fs [Hz], t0 [s], start_datetime) common to the channels, from their waveform
    properties (``fs_opt`` [Hz], when given, overrides wf_increment)."""
    incs = {}
    for n, (_, ch) in zip(names, usable):
        incs[n] = _prop_float(ch.properties, "wf_increment", path, n)
    if fs_opt is not None:
        fs = as_positive(fs_opt, "fs")
        clash = {n: v for n, v in incs.items() if v is not None and v > 0 and abs(v * fs - 1) > 1e-9}
        if clash:
            warnings.warn(FormatWarning(f"{path}: fs={fs!r} Hz given overrides the file's wf_increment {clash}"),
                          stacklevel=5)
    else:
        bad = {n: v for n, v in incs.items() if v is None or not (math.isfinite(v) and v > 0)}
        if bad:
            raise RecordingFileError(path, f"missing or non-positive sample rate: wf_increment of {bad} "
                                           f"(pass fs= to read it anyway)")
        vals = list(incs.values())
        if max(vals) - min(vals) > 1e-9 * max(vals):
            raise RecordingFileError(path, f"channels have different sample intervals (wf_increment {incs})")
        fs = 1.0 / vals[0]
    offsets = {n: _prop_float(ch.properties, "wf_start_offset", path, n) or 0.0 for n, (_, ch) in zip(names, usable)}
    if max(offsets.values()) - min(offsets.values()) > 0.5 / fs:
        raise RecordingFileError(path, f"channels have different wf_start_offset {offsets}")
    t0 = next(iter(offsets.values()))
    starts = {}
    for n, (_, ch) in zip(names, usable):
        v = ch.properties.get("wf_start_time")
        if hasattr(v, "as_datetime64"):
            v = v.as_datetime64("us")
        if isinstance(v, np.datetime64) and v.astype("datetime64[us]") != _LABVIEW_ZERO:
            starts[n] = v.astype("datetime64[us]")
    start_datetime = None
    if starts:
        vals = list(starts.values())
        spread = (max(vals) - min(vals)) / np.timedelta64(1, "us") * 1e-6
        if spread > 0.5 / fs:
            raise RecordingFileError(path, f"channels start at different times (wf_start_time spread {spread!r} s)")
        start_datetime = _iso(min(vals))
    return fs, t0, start_datetime


def _channel(tdms, path: Path, n: str, g, ch, raw: bool) -> tuple[ChannelSpec, _Chan, bool]:
    """(spec, read plan, whether npTDMS scales it) of channel ``ch`` of group ``g``, named
    ``n``: kind, units and gain from the meshphase properties, else from NI's."""
    from nptdms import scaling as _sc

    props = ch.properties
    scaling = _sc.get_scaling(props, g.properties, tdms.properties)
    wants_scaling = any(_has_scale_props(p) for p in (props, g.properties, tdms.properties))
    if wants_scaling and scaling is None:
        warnings.warn(FormatWarning(f"{path}: channel {n!r} has NI scaling properties that npTDMS cannot "
                                    f"apply; its samples are the raw (unscaled) values"), stacklevel=5)
    kind = props.get("meshphase_kind")
    if kind is None:
        kind = kind_from_name(ch.name, g.name)
    elif kind not in CHANNEL_KINDS:
        raise RecordingFileError(path, f"channel {n!r}: property meshphase_kind = {kind!r} is not one of "
                                       f"{CHANNEL_KINDS}")
    units = props.get("unit_string", props.get("NI_UnitDescription", ""))
    gain = _prop_float(props, "meshphase_gain", path, n)
    gain = 1.0 if gain is None else gain
    if raw and scaling is not None:
        lin = _linear_gain(scaling)
        if lin is not None and lin != 0:
            gain *= lin
        else:
            units, gain = "raw", 1.0
    tooth = props.get("meshphase_tooth")
    d = {"name": n, "kind": kind, "units": str(units), "gain": gain,
         "gear": props.get("meshphase_gear"),
         "tooth": int(tooth) if isinstance(tooth, (int, np.integer)) else tooth,
         "face_position": _prop_float(props, "meshphase_face_position", path, n),
         "description": str(props.get("meshphase_description", props.get("description", "")))}
    spec = spec_from_dict(_jsonable(d), path, f"channel {n!r}")
    raw_dtype = np.dtype(ch._raw_data_dtype()) if hasattr(ch, "_raw_data_dtype") else np.dtype(ch.dtype)
    return spec, _Chan(n, ch, None if raw else scaling, raw_dtype), scaling is not None


def _build_extents(tdms, path, chans: dict, raw: bool) -> bool:
    """Byte extents of every selected channel in plain segments; False when the file needs
    npTDMS's general reader (interleaved, big-endian or DAQmx data, unusual types)."""
    reader = getattr(tdms, "_reader", None)
    segs = getattr(reader, "_segments", None)
    if segs is None or not _USE_FAST_PATH:
        return False
    by_path = {c.ch.path: c for c in chans.values()}
    ext = {p: ([], [], []) for p in by_path}
    done = {p: 0 for p in by_path}
    try:
        for seg in segs:
            if seg.segment_incomplete or seg.final_chunk_lengths_override is not None:
                raise CorruptFileError(path, f"segment at byte {seg.position}", "truncated or corrupt: the segment "
                                                                                "holds a partial chunk of data")
            toc = seg.toc_mask
            if not toc & _TOC_RAW:
                continue
            if toc & (_TOC_INTERLEAVED | _TOC_BIG_ENDIAN | _TOC_DAQMX):
                return False
            objs = [o for o in seg.ordered_objects if o.has_data]
            chunk = 0
            for o in objs:
                if o.data_type is None or o.data_type.size is None:
                    if o.path in by_path or o.data_size:
                        return False
                chunk += int(o.data_size)
            if chunk == 0:
                continue
            for c in range(int(seg.num_chunks)):
                pos = int(seg.data_position) + c * chunk
                for o in objs:
                    e = ext.get(o.path)
                    nv = int(o.number_values)
                    if e is not None and nv:
                        if np.dtype(o.data_type.nptype) != by_path[o.path].raw_dtype:
                            return False
                        e[0].append(done[o.path])
                        e[1].append(nv)
                        e[2].append(pos)
                        done[o.path] += nv
                    pos += int(o.data_size)
    except AttributeError:  # a future npTDMS without these internals: use the general reader
        return False
    for p, c in by_path.items():
        if done[p] != len(c.ch):
            return False
        starts, counts, offs = (np.asarray(a, dtype=np.int64) for a in ext[p])
        c.extents = (starts, counts, offs)
    return True


# ---------------------------------------------------------------------------- reading
def _read_window(fh, plan: _Plan, names, i0: int, i1: int, path) -> np.ndarray:
    """Samples [i0, i1) of ``names`` as a Fortran-ordered (n, n_channels) array."""
    n = i1 - i0
    buf = np.empty((len(names), n), dtype=plan.dtype)   # channel-major; data = buf.T
    if n == 0:
        return buf.T
    if plan.fast:
        _read_fast(fh, plan, names, i0, i1, buf, path)
    else:
        _read_general(plan, names, i0, i1, buf, path)
    return buf.T


def _read_fast(fh, plan: _Plan, names, i0, i1, buf, path):
    from nptdms.base_segment import RawChannelDataChunk

    jobs = []   # (file offset, column, dest start, count)
    for j, name in enumerate(names):
        starts, counts, offs = plan.chans[name].extents
        k0 = max(0, int(np.searchsorted(starts, i0, side="right")) - 1)
        k1 = int(np.searchsorted(starts, i1, side="left"))
        item = plan.chans[name].raw_dtype.itemsize
        for k in range(k0, k1):
            s = max(int(starts[k]), i0)
            e = min(int(starts[k] + counts[k]), i1)
            if e > s:
                jobs.append((int(offs[k]) + (s - int(starts[k])) * item, j, s - i0, e - s))
    jobs.sort()
    tmp = {}
    for off, j, d0, cnt in jobs:
        c = plan.chans[names[j]]
        dest = buf[j, d0:d0 + cnt]
        direct = c.scaling is None and c.raw_dtype == buf.dtype and c.raw_dtype.isnative
        fh.seek(off)
        if direct:
            target = dest
        else:
            t = tmp.get(c.raw_dtype)
            if t is None or len(t) < cnt:
                t = tmp[c.raw_dtype] = np.empty(max(cnt, 65536), dtype=c.raw_dtype)
            target = t[:cnt]
        got = fh.readinto(memoryview(target).cast("B"))
        if got != target.nbytes:
            raise CorruptFileError(path, f"byte {off}", f"truncated: {got} of {target.nbytes} bytes of channel "
                                                        f"{names[j]!r}")
        if not direct:
            if c.scaling is not None:
                dest[:] = c.scaling.scale(RawChannelDataChunk.channel_data(target))
            else:
                dest[:] = target


def _read_general(plan: _Plan, names, i0, i1, buf, path):
    n = i1 - i0
    for j, name in enumerate(names):
        ch = plan.chans[name].ch
        try:
            with _nptdms_logs_as_warnings(path):
                arr = ch.read_data(offset=i0, length=n, scaled=not plan.raw)
        except Exception as exc:  # npTDMS raises plain Exception for some malformed data
            raise RecordingFileError(path, f"channel {name!r}: npTDMS cannot read the data "
                                           f"({type(exc).__name__}: {exc})") from exc
        if isinstance(arr, dict):  # DAQmx raw scaler data
            if len(arr) != 1:
                raise RecordingFileError(path, f"channel {name!r} has {len(arr)} DAQmx raw scalers; read it scaled")
            arr = next(iter(arr.values()))
        if len(arr) != n:
            raise CorruptFileError(path, f"channel {name!r}, samples [{i0}, {i1})",
                                   f"truncated: npTDMS gave {len(arr)} of {n} samples")
        buf[j] = arr


_PLAN_CACHE: "OrderedDict[tuple, _Plan]" = OrderedDict()
_PLAN_CACHE_SIZE = 32


def _prepare(path, fs, raw):
    """(path, open TdmsFile or None, plan). Plans of plain files (fast path) are cached under a
    digest of the file's lead-ins and metadata, so the registry's read_info + read parse the
    TDMS metadata once; the general path keeps the TdmsFile open for npTDMS's reader."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file")
    if not isinstance(raw, (bool, np.bool_)):
        raise TypeError(f"raw must be a bool, got {raw!r}")
    if fs is not None:
        fs = as_positive(fs, "fs")
    n_segments, digest = _walk_segments(path)
    key = None
    if _USE_FAST_PATH and not Path(str(path) + "_index").exists():
        key = (os.path.realpath(path), digest, fs, bool(raw))
        plan = _PLAN_CACHE.get(key)
        if plan is not None:
            _PLAN_CACHE.move_to_end(key)
            return path, None, plan
    with _nptdms_logs_as_warnings(path):     # shown only when the file passes the checks
        tdms = _open(path)
        try:
            plan = _plan(tdms, path, n_segments, fs, bool(raw))
        except BaseException:
            tdms.close()
            raise
    if plan.fast:
        tdms.close()
        tdms = None
        if key is not None:
            _PLAN_CACHE[key] = plan
            while len(_PLAN_CACHE) > _PLAN_CACHE_SIZE:
                _PLAN_CACHE.popitem(last=False)
    return path, tdms, plan


def read_info(path, *, fs: float | None = None, raw: bool = False, verify: bool = True) -> RecordingInfo:
    """Header of a TDMS file (segment structure and properties; no samples are read).

    Parameters
    ----------
    path : str or Path
    fs : float, optional
        Sample rate [Hz] to use when the file has no (or a wrong) ``wf_increment``.
    raw : bool
        Describe the raw (unscaled) values instead of the NI-scaled ones.
    verify : bool
        Accepted for the registry's uniform options: TDMS stores no checksum; the segment
        structure is always checked.
    """
    check_verify(verify)
    path, tdms, plan = _prepare(path, fs, raw)
    if tdms is not None:
        tdms.close()
    return copy.deepcopy(plan.info)


def _recording(plan: _Plan, data, names, i0) -> Recording:
    info = plan.info
    by_name = {c.name: c for c in info.channels}
    return Recording(data, info.fs, [by_name[n] for n in names], t0=info.t0 + i0 / info.fs,
                     start_datetime=info.start_datetime, meta=copy.deepcopy(info.meta),
                     history=copy.deepcopy(info.history))


def read(path, channels=None, i0: int = 0, i1: int | None = None, *, fs: float | None = None,
         raw: bool = False, verify: bool = True) -> Recording:
    """Samples ``i0 <= i < i1`` of the named channels (all when None) of a TDMS file.

    Parameters
    ----------
    path : str or Path
    channels : str or sequence of str, optional
    i0, i1 : int
        Sample range [i0, i1) (default: all).
    fs : float, optional
        Sample rate [Hz] when the file lacks ``wf_increment``.
    raw : bool
        Return the stored (unscaled) values instead of NI-scaled physical values.
    verify : bool
        As in :func:`read_info`.

    Returns
    -------
    Recording
        float64 (float32 when every channel is unscaled float32), Fortran-ordered.

    Raises
    ------
    CorruptFileError
        Truncated or damaged segment structure (segment and byte offset named).
    """
    check_verify(verify)
    path, tdms, plan = _prepare(path, fs, raw)
    with contextlib.ExitStack() as stack:
        if tdms is not None:
            stack.enter_context(tdms)
        names = plan.info.check_channels(channels)
        n = plan.info.n_samples
        i0 = as_int(i0, "i0")
        i1 = n if i1 is None else as_int(i1, "i1")
        if not 0 <= i0 <= i1 <= n:
            raise ValueError(f"{path}: sample range [{i0}, {i1}) outside the recording's [0, {n})")
        fh = stack.enter_context(open(path, "rb"))
        data = _read_window(fh, plan, names, i0, i1, path)
    warn_nonfinite(path, data, names, i0)
    return _recording(plan, data, names, i0)


def iter_blocks(path, n_block: int, n_overlap: int, channels=None, *, fs: float | None = None,
                raw: bool = False, verify: bool = True) -> Iterator[Recording]:
    """Blocks of ``n_block`` samples plus ``n_overlap`` following samples; file opened once.

    Block k covers samples [k n_block, (k + 1) n_block + n_overlap), clipped to the recording.
    """
    check_verify(verify)
    n_block = as_positive_int(n_block, "n_block")
    n_overlap = as_int(n_overlap, "n_overlap")
    if n_overlap < 0:
        raise ValueError(f"n_overlap must be >= 0, got {n_overlap}")
    path, tdms, plan = _prepare(path, fs, raw)
    with contextlib.ExitStack() as stack:
        if tdms is not None:
            stack.enter_context(tdms)
        fh = stack.enter_context(open(path, "rb"))
        names = plan.info.check_channels(channels)
        n = plan.info.n_samples
        for i0 in range(0, n, n_block):
            i1 = min(n, i0 + n_block + n_overlap)
            data = _read_window(fh, plan, names, i0, i1, path)
            warn_nonfinite(path, data, names, i0)
            yield _recording(plan, data, names, i0)
