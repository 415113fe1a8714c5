"""NI TDMS (npTDMS): what NI DAQ rigs record. Written by :mod:`meshphase.io.tdms_write`
(:func:`write`, :func:`write_blocks`, :func:`write_tdms`, :func:`write_ni_log`).

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
  ``meshphase_gear``, ``meshphase_gain``, ``meshphase_description`` (else ``description``);
  an encoder's shaft and pulses per revolution from ``meshphase_shaft``,
  ``meshphase_pulses_per_rev``.
* fs = 1 / ``wf_increment`` (the same on every channel). A file without waveform timing
  (DIAdem, "Write to Measurement File" without waveforms, scripts) may hold a clock
  channel instead: one named as :data:`~meshphase.io.timenames.CLOCK_NAMES` (``Time``, ``t``,
  ``Zeit``, ``Temps``, ...) or
  holding timestamps; fs then comes from its first and last time, every time is checked
  against the grid (0.1 sample plus the clock's resolution: a dropped sample is named),
  t0 is its first value (timestamps: t0 = 0 and start_datetime the first), and it is not a
  channel of the recording. Neither -> RecordingFileError "missing or non-positive sample
  rate" unless ``fs=`` is given (a scene's ``[input] fs_Hz``).
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

Reading uses npTDMS's public API only (``TdmsFile.open``, groups, channels, properties,
``len``, ``dtype`` and ``TdmsChannel.read_data(offset, length, scaled)``). The samples of
plain numeric data (any byte order, contiguous or interleaved, any segment size) are read
by byte offsets computed from the segment index that :mod:`meshphase.io.tdms_index` reads
from the file after NI's published format (one pass; segments repeating the previous
lead-in and metadata are taken together), through a memory map, NI-scaled by
:mod:`meshphase.io.tdms_scaling` (linear and polynomial scales): each channel's length
must equal npTDMS's and its first and last samples must equal what ``read_data`` returns,
else, and for DAQmx raw data or scales only npTDMS computes, ``read_data`` reads every
sample (``read_info(...).extra["read_path"]`` says which path and why). Channels interleaved
in the same rows are read together by :mod:`meshphase.io.tdms_rows` (one compiled pass
per run of segments when numba is already loaded, else whole segments per block copied
through the map and transposed in one numpy assignment each; every sample shown finite on
the way, so a finite read skips the separate NaN/inf scan). The segments are scanned
through the memory map the samples are then read from, so its pages are mapped in once.
The read plan is
cached under a digest of the lead-ins and metadata. :func:`iter_blocks` keeps the file open
and reads block after block, so memory stays flat.
"""

from __future__ import annotations

import contextlib
import copy
import json
import logging
import math
import mmap
import os
import sys
from collections import OrderedDict
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from ..errors import FormatWarning
from ..jsonable import to_jsonable
from ..recording import CHANNEL_KINDS, ChannelSpec, Recording
from ..validate import as_int, as_positive, as_positive_int
from . import tdms_index, tdms_rows, tdms_scaling
from .base import (CorruptFileError, RecordingFileError, RecordingInfo, check_allocation,
                   check_verify, clock_timing, kind_from_name, spec_from_dict, warn_nonfinite)
from .registry import FormatSpec
from .timenames import CLOCK_NAMES, is_clock_name
from .tdms_write import write, write_blocks, write_ni_log, write_tdms

__all__ = ["NAME", "FORMAT", "sniff", "read_info", "read", "iter_blocks", "write", "write_blocks", "write_tdms",
           "write_ni_log", "kind_from_name",
           "reading_path"]

NAME = "tdms"
#: The format's declaration in the registry (:mod:`meshphase.io.registry`).
FORMAT = FormatSpec(
    name=NAME, module=__name__, suffixes=(".tdms",), writable=True, streaming_write=True, rate_option=True,
    read_options={"fs": float, "raw": bool}, write_options={"name": str, "group": str},
    read_libraries=("nptdms",),
    description="NI TDMS as NI DAQ rigs record it (NI scaling applied)")

#: Read through the segment index and computed offsets (tests switch it off to compare with
#: npTDMS's public ``read_data``, the path every file can take).
_USE_FAST_PATH = True
#: engine of interleaved rows read together (:func:`meshphase.io.tdms_rows.rows_engine`)
_ROWS_ENGINE = "auto"
#: Samples at each end of every channel compared with npTDMS's ``read_data`` before the
#: computed-offset path is trusted for a file.
_CHECK_SAMPLES = 64
_LABVIEW_ZERO = np.datetime64("1904-01-01T00:00:00", "us")

def sniff(head: bytes) -> bool:
    """True for a TDMS data file (lead-in tag ``TDSm``); ``TDSh`` index files are not recordings."""
    return head[:4] == b"TDSm"


# ---------------------------------------------------------------------------- plan
@dataclass
class _Chan:
    name: str
    ch: Any                 # npTDMS TdmsChannel (public API only)
    scaling: Any            # tdms_scaling.Chain applied on the computed-offset path, or None
    raw_dtype: np.dtype     # stored type (byte order included on the computed-offset path)
    scaled: bool = False    # npTDMS scales this channel (read scaled=True on its path)
    runs: list | None = None        # tdms_index.Run list for the computed-offset path
    starts: np.ndarray | None = None


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


def _plan(tdms, path, index, fs_opt, raw: bool) -> _Plan:
    """What a read of this open TDMS file needs: its header as a RecordingInfo, the
    channels to read (NI-scaled unless ``raw``) and, when the segment ``index`` allows and
    agrees with npTDMS, the computed-offset runs of every channel."""
    path = Path(path)
    n_segments = index.n_segments
    groups, usable, names, unapplied = _usable_channels(tdms, path)
    clock = _clock_channel(path, names, usable) if fs_opt is None else None
    if clock is not None:
        k = names.index(clock)
        _, clock_ch = usable.pop(k)
        names.pop(k)
    usable, names = _drop_stamps(path, usable, names)
    n_samples = _n_samples(path, names, usable)
    if clock is not None:
        fs, t0, start_datetime = clock_timing(path, f"clock channel {clock!r}", np.asarray(clock_ch[:]), n_samples)
    else:
        fs, t0, start_datetime = _timing(path, names, usable, fs_opt)
    chans = {}
    specs = []
    scaled_names = []
    for n, (g, ch) in zip(names, usable):
        spec, chans[n], scaled = _channel(tdms, path, n, g, ch, raw, index, n in unapplied)
        specs.append(spec)
        if scaled:
            scaled_names.append(n)
    out_kinds = [(c.raw_dtype if (raw or not c.scaled) else np.dtype(c.ch.dtype)) for c in chans.values()]
    dtype = (np.dtype(np.float32) if all(k.newbyteorder("=") == np.float32 for k in out_kinds)
             else np.dtype(np.float64))
    fast, why = _use_index(path, index, chans, raw, n_samples)
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
                                "scaled": not raw, "fast_path": fast, "read_path": why})
    return _Plan(info=info, chans=chans, dtype=dtype, raw=raw, fast=fast)


def _usable_channels(tdms, path: Path) -> tuple[list, list, list, set]:
    """(groups, [(group, channel)] of the numeric and timestamp channels, their names, the
    names whose NI scaling npTDMS cannot apply): the plain channel names, or
    ``group/channel`` where plain names repeat. Timestamps are kept for the clock
    (:func:`_clock_channel`); :func:`_drop_stamps` drops the others."""
    groups = tdms.groups()
    found = []
    for g in groups:
        for ch in g.channels():
            found.append((g, ch))
    usable = []
    unapplied = set()
    for g, ch in found:
        try:
            with _scale_complaints() as said:   # the first dtype access sets up the scaling
                dt = np.dtype(ch.dtype)
        except TypeError:
            dt = np.dtype("V8")
        if said:
            unapplied.add(ch.path)
        if ch.data_type is None or dt.kind not in "biufM":
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
    unapplied = {n for n, (_, ch) in zip(names, usable) if ch.path in unapplied}
    return groups, usable, names, unapplied


@contextlib.contextmanager
def _scale_complaints():
    """Collects npTDMS's "Unsupported scale type" log records (its public signal that it
    leaves a channel unscaled) while the block runs; the list is truthy when one came."""
    said: list = []

    class _Grab(logging.Filter):
        def filter(self, record):
            if record.getMessage().startswith("Unsupported scale type"):
                said.append(record.getMessage())
                return False
            return True

    grab = _Grab()
    lg = logging.getLogger("nptdms.scaling")
    lg.filters.insert(0, grab)      # ahead of _nptdms_logs_as_warnings' filter, which drops all
    try:
        yield said
    finally:
        lg.removeFilter(grab)


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


def _stamp_dtype(ch) -> bool:
    try:
        return np.dtype(ch.dtype).kind == "M"
    except TypeError:
        return False


def _drop_stamps(path: Path, usable: list, names: list) -> tuple[list, list]:
    """``usable`` and ``names`` without channels of timestamps (not samples), each dropped
    with the warning a non-numeric channel gets."""
    keep = []
    for n, (g, ch) in zip(names, usable):
        if _stamp_dtype(ch):
            warnings.warn(FormatWarning(f"{path}: skipped channel {g.name}/{ch.name}: no numeric data "
                                        f"(timestamps; a clock channel only where no channel has "
                                        f"wf_increment)"), stacklevel=5)
        else:
            keep.append((n, (g, ch)))
    if not keep:
        raise RecordingFileError(path, "no numeric channels besides the clock")
    return [u for _, u in keep], [n for n, _ in keep]


def _clock_channel(path: Path, names: list, usable: list) -> str | None:
    """The channel holding each sample's time when no channel carries waveform timing
    (``wf_increment``): named as :data:`CLOCK_NAMES` or holding timestamps, and not the only
    channel; None otherwise."""
    if any(_prop_float(ch.properties, "wf_increment", path, n) for n, (_, ch) in zip(names, usable)):
        return None
    found = [n for n, (_, ch) in zip(names, usable)
             if _stamp_dtype(ch) or is_clock_name(ch.name)]
    return found[0] if found and len(usable) > 1 else None


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
                                           f"and no clock channel (one named {', '.join(CLOCK_NAMES[:3])}, ... "
                                           f"or of timestamps); give the rate: [input] fs_Hz in a scene, "
                                           f"fs= to meshphase.io.read")
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


def _channel(tdms, path: Path, n: str, g, ch, raw: bool, index, unapplied: bool) -> tuple[ChannelSpec, _Chan, bool]:
    """(spec, read plan, whether NI scaling applies) of channel ``ch`` of group ``g``, named
    ``n``: kind, units and gain from the meshphase properties, else from NI's."""
    props = ch.properties
    wants, chain = tdms_scaling.parse(props, g.properties, tdms.properties)
    if unapplied:
        warnings.warn(FormatWarning(f"{path}: channel {n!r} has NI scaling properties that npTDMS cannot "
                                    f"apply; its samples are the raw (unscaled) values"), stacklevel=5)
    scaled = wants and not unapplied
    kind = props.get("meshphase_kind")
    if kind is None:
        kind = kind_from_name(ch.name, g.name)
    elif kind not in CHANNEL_KINDS:
        raise RecordingFileError(path, f"channel {n!r}: property meshphase_kind = {kind!r} is not one of "
                                       f"{CHANNEL_KINDS}")
    units = props.get("unit_string", props.get("NI_UnitDescription", ""))
    gain = _prop_float(props, "meshphase_gain", path, n)
    gain = 1.0 if gain is None else gain
    if raw and scaled:
        lin = tdms_scaling.linear_gain(chain)
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
    ppr = props.get("meshphase_pulses_per_rev")
    if "meshphase_shaft" in props or ppr is not None:      # an encoder's (spec_from_dict checks)
        d.update(shaft=props.get("meshphase_shaft"),
                 pulses_per_rev=int(ppr) if isinstance(ppr, (int, np.integer)) else ppr)
    spec = spec_from_dict(_jsonable(d), path, f"channel {n!r}")
    raw_dtype = index.dtypes.get(ch.path) if index.unsupported is None else None
    if raw_dtype is None:
        raw_dtype = _stored_dtype(ch, path, n, scaled)
    use_chain = chain if (scaled and not raw) else None
    return spec, _Chan(n, ch, use_chain, np.dtype(raw_dtype), scaled), scaled


def _stored_dtype(ch, path, n, scaled: bool) -> np.dtype:
    """The stored (unscaled) type of a channel from npTDMS's public API: its dtype when
    unscaled, else the type of one raw value read back."""
    if not scaled or len(ch) == 0:
        return np.dtype(ch.dtype)
    with _nptdms_logs_as_warnings(path):
        try:
            one = ch.read_data(offset=0, length=1, scaled=False)
        except Exception as exc:  # npTDMS raises plain Exception for some malformed data
            raise RecordingFileError(path, f"channel {n!r}: npTDMS cannot read the data "
                                           f"({type(exc).__name__}: {exc})") from exc
    if isinstance(one, dict):   # DAQmx raw scaler data: read scaled or through its one scaler
        return np.dtype(next(iter(one.values())).dtype) if len(one) == 1 else np.dtype(np.float64)
    return np.dtype(one.dtype)


def _use_index(path, index, chans: dict, raw: bool, n_samples: int) -> tuple[bool, str]:
    """(True, "computed offsets") when every channel can be read from the segment index and
    its first and last samples equal npTDMS's ``read_data``; else (False, why npTDMS reads).
    A segment holding a partial chunk raises CorruptFileError either way."""
    if index.partial is not None and index.unsupported is None:
        raise CorruptFileError(path, index.partial.split(": ", 1)[0], index.partial.split(": ", 1)[1])
    if not _USE_FAST_PATH:
        return False, "npTDMS read_data (computed offsets switched off)"
    if index.unsupported is not None:
        return False, f"npTDMS read_data ({index.unsupported})"
    for c in chans.values():
        p = c.ch.path
        if c.scaled and not raw and c.scaling is None:
            return False, f"npTDMS read_data (channel {c.name!r}: NI scaling computed by npTDMS only)"
        if index.lengths.get(p, 0) != len(c.ch) or (len(c.ch) and p not in index.runs):
            return False, (f"npTDMS read_data (channel {c.name!r}: {index.lengths.get(p, 0)} samples in the "
                           f"segment index, npTDMS says {len(c.ch)})")
        if p in index.runs:
            c.runs, c.starts = index.runs[p], index.starts(p)
    return _agrees(path, chans, raw, n_samples)


def _agrees(path, chans: dict, raw: bool, n_samples: int) -> tuple[bool, str]:
    """Compare the first and last samples of every channel read by computed offsets with
    npTDMS's ``read_data`` (exact, NaN equal to NaN)."""
    k = min(_CHECK_SAMPLES, n_samples)
    if k == 0:
        return True, "computed offsets"
    with open(path, "rb") as fh, tdms_index.open_map(fh) as mm:
        for c in chans.values():
            for i0 in sorted({0, n_samples - k}):
                mine = np.empty(k, dtype=np.float64)
                _read_channel(mm, c, i0, i0 + k, mine)
                try:
                    with _nptdms_logs_as_warnings(path):
                        theirs = c.ch.read_data(offset=i0, length=k, scaled=not raw)
                except Exception:  # npTDMS cannot read it: its own path will say why
                    return False, f"npTDMS read_data (channel {c.name!r}: npTDMS could not read the check samples)"
                if isinstance(theirs, dict) or not np.array_equal(mine, np.asarray(theirs, dtype=np.float64),
                                                                  equal_nan=True):
                    return False, (f"npTDMS read_data (channel {c.name!r}: samples [{i0}, {i0 + k}) by computed "
                                   f"offsets differ from npTDMS's)")
    return True, "computed offsets"


# ---------------------------------------------------------------------------- reading
def _read_window(mm, plan: _Plan, names, i0: int, i1: int, path) -> tuple[np.ndarray, bool]:
    """(samples [i0, i1) of ``names`` as a Fortran-ordered (n, n_channels) array, whether the
    read showed them all finite) (``mm``: the file's memory map on the computed-offset path,
    else None)."""
    n = i1 - i0
    check_allocation(path, n, len(names), np.dtype(plan.dtype).itemsize)
    buf = np.empty((len(names), n), dtype=plan.dtype)   # channel-major; data = buf.T
    if n == 0:
        return buf.T, True
    if plan.fast:
        return buf.T, _read_fast(mm, plan, names, i0, i1, buf, path)
    _read_general(plan, names, i0, i1, buf, path)
    return buf.T, False


def _read_channel(mm, c: _Chan, i0: int, i1: int, dest: np.ndarray) -> None:
    """Samples [i0, i1) of one channel by computed offsets into ``dest``, NI-scaled when
    its plan says so (on the stored type first, as npTDMS computes it)."""
    if c.scaling is None:
        tdms_index.read_runs(mm, c.runs, c.starts, i0, i1, dest)
        return
    tmp = np.empty(i1 - i0, dtype=c.raw_dtype.newbyteorder("="))
    tdms_index.read_runs(mm, c.runs, c.starts, i0, i1, tmp)
    dest[:] = c.scaling.apply(tmp)


#: Samples per channel read from interleaved data before moving on to the next channel, so
#: the rows just read are still in the CPU cache for the other channels.
_INTERLEAVED_BLOCK = 1 << 15


def _read_fast(mm, plan: _Plan, names, i0, i1, buf, path) -> bool:
    """Samples [i0, i1) of ``names`` by computed offsets into ``buf`` (channel-major); True
    when the read showed them all finite (interleaved rows read together sum each block
    while it is in the cache), False when the caller must look for NaN/inf itself."""
    chans = [plan.chans[name] for name in names]
    # two or more channels of the same interleaved rows: together, whole rows per block; one
    # channel alone is read faster by its strided walk over the map (read_runs below)
    if len(chans) > 1 and all(c.scaling is None for c in chans) and tdms_rows.shared_rows([c.runs for c in chans]):
        try:
            return tdms_rows.read_rows(mm, [c.runs for c in chans], chans[0].starts, i0, i1, buf,
                                       engine=_ROWS_ENGINE)
        except (TypeError, ValueError) as exc:   # a strided view past the end of the file
            raise CorruptFileError(path, f"samples [{i0}, {i1})", f"truncated or corrupt: {exc}") from exc
    interleaved = any(r.value_stride != r.dtype.itemsize for c in chans for r in c.runs)
    step = _INTERLEAVED_BLOCK if interleaved and len(chans) > 1 else max(1, i1 - i0)
    for a in range(i0, i1, step):
        b = min(i1, a + step)
        for j, c in enumerate(chans):
            try:
                _read_channel(mm, c, a, b, buf[j, a - i0:b - i0])
            except (TypeError, ValueError) as exc:   # a strided view past the end of the file
                raise CorruptFileError(path, f"channel {c.name!r}, samples [{a}, {b})",
                                       f"truncated or corrupt: {exc}") from exc
    return False


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


def _prepare(path, fs, raw, stack: contextlib.ExitStack | None = None):
    """(path, open TdmsFile or None, plan, None). Plans read by computed offsets are cached under a
    digest of the file's lead-ins and metadata, so the registry's read_info + read parse the
    TDMS metadata once; the read_data path keeps the TdmsFile open for npTDMS's reader.

    With ``stack``, the file is opened and memory-mapped first (both closed with ``stack``)
    and scanned through that map, which is returned for the read (the pages the scan maps
    in are not faulted in again): (path, TdmsFile or None, plan, map or None).
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file")
    if not isinstance(raw, (bool, np.bool_)):
        raise TypeError(f"raw must be a bool, got {raw!r}")
    if fs is not None:
        fs = as_positive(fs, "fs")
    mm = _open_map(stack, path) if stack is not None else None
    index = tdms_index.scan(path, mm)
    key = None
    index_file = Path(str(path) + "_index")
    if index_file.exists():
        listed = tdms_index.count_index_segments(index_file)
        if listed != index.n_segments:
            raise RecordingFileError(path, f"the .tdms_index file lists {listed} segments but the file holds "
                                           f"{index.n_segments} (stale .tdms_index file?)")
    elif _USE_FAST_PATH:
        key = (os.path.realpath(path), index.digest, fs, bool(raw))
        plan = _PLAN_CACHE.get(key)
        if plan is not None:
            _PLAN_CACHE.move_to_end(key)
            return path, None, plan, mm
    with _nptdms_logs_as_warnings(path):     # shown only when the file passes the checks
        tdms = _open(path)
        try:
            plan = _plan(tdms, path, index, fs, bool(raw))
        except BaseException:
            tdms.close()
            raise
    if plan.fast:
        tdms.close()
        tdms = None
        if key is not None and _PLAN_CACHE_SIZE > 0:
            _PLAN_CACHE[key] = plan
            while len(_PLAN_CACHE) > _PLAN_CACHE_SIZE:
                _PLAN_CACHE.popitem(last=False)
    return path, tdms, plan, (mm if plan.fast else None)


def _open_map(stack: contextlib.ExitStack, path):
    """The file's read-only memory map, kept open (with the file) until ``stack`` closes;
    None for an empty file (the scan then says it is empty). It carries no descriptor
    (``fd`` -1): the numpy engine of :mod:`meshphase.io.tdms_rows` copies the rows through
    the map, whose pages the scan has mapped in, instead of ``os.preadv`` (slower then)."""
    fh = stack.enter_context(open(path, "rb"))
    if os.fstat(fh.fileno()).st_size == 0:
        return None
    return stack.enter_context(tdms_index.FileMap(fh.fileno(), 0, access=mmap.ACCESS_READ))


@contextlib.contextmanager
def reading_path(*, computed_offsets: bool = True, cache_plans: bool = True, rows_engine: str = "auto"):
    """Choose how TDMS files are read inside the ``with`` block (``meshphase bench io``
    measures both ways; results are the same).

    Parameters
    ----------
    computed_offsets : bool
        True (default): samples by computed offsets from the segment index when the file
        allows; False: every sample through npTDMS's public ``TdmsChannel.read_data``.
    cache_plans : bool
        True (default): a file's read plan (npTDMS's metadata parse, channel specs, offsets)
        is kept for the next read of the unchanged file; False: every read builds it anew.
    rows_engine : {"auto", "numba", "numpy"}
        Engine of the interleaved rows read together
        (:func:`meshphase.io.tdms_rows.rows_engine`; "auto": numba when already loaded).
    """
    global _USE_FAST_PATH, _PLAN_CACHE_SIZE, _ROWS_ENGINE
    for name, v in (("computed_offsets", computed_offsets), ("cache_plans", cache_plans)):
        if not isinstance(v, (bool, np.bool_)):
            raise TypeError(f"{name} must be a bool, got {v!r}")
    tdms_rows.rows_engine(rows_engine)            # checked: a ValueError names the engines
    saved = _USE_FAST_PATH, _PLAN_CACHE_SIZE, list(_PLAN_CACHE.items()), _ROWS_ENGINE
    _USE_FAST_PATH = bool(computed_offsets)
    _ROWS_ENGINE = rows_engine
    if not cache_plans:
        _PLAN_CACHE_SIZE = 0
        _PLAN_CACHE.clear()
    try:
        yield
    finally:
        _USE_FAST_PATH, _PLAN_CACHE_SIZE, items, _ROWS_ENGINE = saved
        if not cache_plans:
            _PLAN_CACHE.clear()
            _PLAN_CACHE.update(items)


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
    path, tdms, plan, _ = _prepare(path, fs, raw)
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
    with contextlib.ExitStack() as stack:
        path, tdms, plan, mm = _prepare(path, fs, raw, stack)
        if tdms is not None:
            stack.enter_context(tdms)
        names = plan.info.check_channels(channels)
        n = plan.info.n_samples
        i0 = as_int(i0, "i0")
        i1 = n if i1 is None else as_int(i1, "i1")
        if not 0 <= i0 <= i1 <= n:
            raise ValueError(f"{path}: sample range [{i0}, {i1}) outside the recording's [0, {n})")
        data, finite = _read_window(mm, plan, names, i0, i1, path)
    if not finite:
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
    with contextlib.ExitStack() as stack:
        path, tdms, plan, mm = _prepare(path, fs, raw, stack)
        if tdms is not None:
            stack.enter_context(tdms)
        names = plan.info.check_channels(channels)
        n = plan.info.n_samples
        for i0 in range(0, n, n_block):
            # no name in this frame holds the block: once the caller drops it, it is freed
            # before the next one is read
            yield _read_block(mm, plan, names, i0, min(n, i0 + n_block + n_overlap), path)


def _read_block(mm, plan: _Plan, names, i0: int, i1: int, path) -> Recording:
    data, finite = _read_window(mm, plan, names, i0, i1, path)
    if not finite:
        warn_nonfinite(path, data, names, i0)
    return _recording(plan, data, names, i0)
