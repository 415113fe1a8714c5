"""The Recording container, its header and the block-source interface every stage reads.

A :class:`Recording` holds a samples x channels array at a uniform sample rate, the start
time of its first sample, one :class:`ChannelSpec` per channel, free gearset/rig metadata
and the processing history. Array functions further down the package take plain arrays and
sample rates; the thin methods here convert seconds to samples once.

A :class:`RecordingHeader` is everything of a recording but its samples: what a file's
header says (:func:`meshphase.io.read_info`) and what the streamed stages know of a
recording they read block by block. A :class:`BlockSource` is a recording that can be read
again and again in consecutive blocks: its ``header`` and ``blocks(n_block)``.
:class:`MemorySource` is the source of a Recording in memory
(:meth:`Recording.source`); the file, generated and bridge-converting sources are in
:mod:`meshphase.io.sources`.
"""

from __future__ import annotations

import abc
import copy
import datetime as _dt
import json
import math
import unicodedata
import warnings
from dataclasses import asdict, dataclass, field, replace
from typing import Any, Iterator, Sequence

import numpy as np

from .errors import DataQualityWarning
from .html_repr import html_table
from .jsonable import to_jsonable
from .signal.quality import channel_quality
from .validate import as_float, as_nonnegative, as_positive

__all__ = ["ChannelSpec", "Recording", "RecordingHeader", "BlockSource", "MemorySource", "apply_gains",
           "history_entry", "warn_nonfinite_runs", "CHANNEL_KINDS", "GAUGE_KINDS", "ENCODER_SHAFTS", "sample_index",
           "control_character"]

#: Channel kinds a recording may carry.
CHANNEL_KINDS = ("sun", "ring", "facewidth", "tacho", "encoder", "other")
#: The strain gauge kinds among them (the channels whose pulses the onset detector times).
GAUGE_KINDS = ("sun", "ring", "facewidth")
#: Shafts an encoder channel may sit on ("input" is the sun shaft).
ENCODER_SHAFTS = ("sun", "input", "carrier", "ring")


def control_character(text: str) -> str | None:
    """The first control character (Unicode category Cc: C0, DEL, C1) or line / paragraph
    separator (Zl, Zp) in ``text``, or None."""
    return next((c for c in text if unicodedata.category(c) in ("Cc", "Zl", "Zp")), None)


@dataclass(frozen=True)
class ChannelSpec:
    """Description of one recorded channel.

    Parameters
    ----------
    name : str
        Unique channel name, with no control character (C0, DEL, C1) or line / paragraph
        separator: such a name is refused, since every place that writes or prints it (file
        headers, tables, messages) would carry a line break or escape sequence.
    kind : {"sun", "ring", "facewidth", "tacho", "encoder", "other"}
        What the channel measures: a sun tooth-root gauge, a ring tooth-root gauge, a
        face-width gauge (one of several across the face of one tooth root), a carrier
        once-per-revolution tacho, a shaft encoder or multi-pulse tacho (a pulse train of
        ``pulses_per_rev`` pulses per turn of ``shaft``), or anything else.
    units : str
        Physical units of the stored samples after ``gain`` is applied, e.g. ``"m/m"``
        (strain) or ``"V"``; no control character (as ``name``).
    gain : float
        Calibration gain [units per stored unit]; physical value = stored value * gain.
        Readers store samples already scaled to physical units and keep gain = 1 unless the
        format keeps raw counts (documented per format).
    gear : str, optional
        Which gear the gauge sits on ("sun", "ring", "planet"); defaults from ``kind``.
    tooth : int, optional
        Index of the gauged tooth on its gear [-].
    face_position : float, optional
        Axial position of the gauge across the face width, measured from the face centre [m].
    description : str
        Free text.
    shaft : {"sun", "input", "carrier", "ring"}, optional
        The shaft an encoder channel sits on ("input" is the sun); encoder channels only.
    pulses_per_rev : int, optional
        Pulses per revolution of an encoder's shaft [-]; encoder channels only.
    """

    name: str
    kind: str = "other"
    units: str = "m/m"
    gain: float = 1.0
    gear: str | None = None
    tooth: int | None = None
    face_position: float | None = None
    description: str = ""
    shaft: str | None = None
    pulses_per_rev: int | None = None

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name.strip():
            raise ValueError(f"channel name must be a non-empty string, got {self.name!r}")
        bad = control_character(self.name)
        if bad is not None:
            raise ValueError(f"channel name {self.name!r} holds the control character U+{ord(bad):04X}; "
                             "rename the channel (names are written into files and printed on one line)")
        if self.kind not in CHANNEL_KINDS:
            raise ValueError(f"channel {self.name!r}: kind must be one of {CHANNEL_KINDS}, got {self.kind!r}")
        if not isinstance(self.units, str):
            raise TypeError(f"channel {self.name!r}: units must be a string, got {self.units!r}")
        bad = control_character(self.units)
        if bad is not None:
            raise ValueError(f"channel {self.name!r}: units {self.units!r} hold the control character "
                             f"U+{ord(bad):04X}")
        g = as_float(self.gain, f"channel {self.name!r} gain")
        if g == 0.0:
            raise ValueError(f"channel {self.name!r}: gain must be non-zero, got 0.0")
        object.__setattr__(self, "gain", g)
        if self.tooth is not None:
            if isinstance(self.tooth, bool) or int(self.tooth) != self.tooth or self.tooth < 0:
                raise ValueError(f"channel {self.name!r}: tooth must be a non-negative integer, got {self.tooth!r}")
            object.__setattr__(self, "tooth", int(self.tooth))
        if self.face_position is not None:
            object.__setattr__(self, "face_position",
                               as_float(self.face_position, f"channel {self.name!r} face_position"))
        if self.gear is None and self.kind in ("sun", "ring"):
            object.__setattr__(self, "gear", self.kind)
        self._check_encoder()

    def _check_encoder(self) -> None:
        """``shaft`` and ``pulses_per_rev``: an encoder's, valid when given."""
        if self.kind != "encoder":
            given = [k for k in ("shaft", "pulses_per_rev") if getattr(self, k) is not None]
            if given:
                raise ValueError(f"channel {self.name!r}: {', '.join(given)} belong(s) to an "
                                 f"encoder channel (kind 'encoder'), not kind {self.kind!r}")
            return
        if self.shaft is not None and self.shaft not in ENCODER_SHAFTS:
            raise ValueError(f"channel {self.name!r}: encoder shaft must be one of "
                             f"{ENCODER_SHAFTS}, got {self.shaft!r}")
        ppr = self.pulses_per_rev
        if ppr is not None:
            whole = (isinstance(ppr, (int, np.integer)) and not isinstance(ppr, bool)) or (
                isinstance(ppr, float) and ppr.is_integer())
            if not whole or ppr < 1:
                raise ValueError(f"channel {self.name!r}: pulses_per_rev must be a positive "
                                 f"integer, got {ppr!r}")
            object.__setattr__(self, "pulses_per_rev", int(ppr))

    def to_dict(self) -> dict:
        """JSON-friendly dict of every field."""
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "ChannelSpec":
        """Build from a dict; unknown keys raise ValueError naming them."""
        known = set(cls.__dataclass_fields__)
        unknown = set(d) - known
        if unknown:
            raise ValueError(f"channel spec has unknown key(s) {sorted(unknown)}; known: {sorted(known)}")
        return cls(**d)


def sample_index(time: float, t0: float, fs: float, n_samples: int) -> int:
    """Index of the first sample at or after ``time`` [s], clipped to [0, n_samples].

    For the half-open window [start, stop) the samples are
    ``sample_index(start) <= i < sample_index(stop)``. Times within 1e-6 samples of a sample
    instant count as on it, so ``t0 + i / fs`` lands on sample ``i`` despite rounding.
    """
    x = (time - t0) * fs
    i = math.ceil(x - 1e-6)
    return int(min(max(i, 0), n_samples))


def history_entry(step: str, **params: Any) -> dict:
    """One processing-history entry: ``step``, the UTC time [s resolution] and ``params``
    as JSON-friendly values (non-finite floats kept); TypeError when ``step`` is no string."""
    if not isinstance(step, str):
        raise TypeError(f"a history step must be a string, got {type(step).__name__}")
    entry = {"step": step, "time": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")}
    entry.update({k: to_jsonable(v, nonfinite="keep") for k, v in params.items()})
    return entry


class _TimeAxis:
    """The time axis and channel names a recording and its header both derive from ``fs``
    [Hz], ``n_samples``, ``t0`` [s] and ``channels``."""

    @property
    def duration(self) -> float:
        """Duration n_samples / fs [s]."""
        return self.n_samples / self.fs

    @property
    def dt(self) -> float:
        """Sample interval 1 / fs [s]."""
        return 1.0 / self.fs

    @property
    def t_end(self) -> float:
        """Time just after the last sample, t0 + n_samples / fs [s] (exclusive end)."""
        return self.t0 + self.duration

    @property
    def names(self) -> list[str]:
        """Channel names, in column order."""
        return [c.name for c in self.channels]


@dataclass(repr=False)
class RecordingHeader(_TimeAxis):
    """Everything of a recording but its samples.

    What a file's header says (:func:`meshphase.io.read_info`: ``path``, ``format`` and
    ``extra`` set) and what the stages after ``load`` know of a recording they stream (a
    :class:`BlockSource`'s ``header``). Asking it for samples raises a TypeError that says so.

    Parameters
    ----------
    fs : float
        Sample rate [Hz], > 0.
    n_samples : int
        Samples per channel [-].
    channels : list of ChannelSpec
        One per column.
    t0 : float
        Time of the first sample [s].
    start_datetime : str, optional
        Wall-clock time of the first sample (ISO 8601).
    meta : dict
        Gearset / rig metadata.
    history : list of dict
        Processing steps applied so far, oldest first.
    dtype : numpy dtype
        Sample type as stored (float64 until a reader says otherwise).
    path : str, optional
        The recording file, for a file's header.
    format : str, optional
        The file's format name (``"hdf5"``, ``"mcap"``, ``"csv"``, ``"tdms"``).
    extra : dict
        Format-specific details (layout, compression, segment count...).
    """

    fs: float
    n_samples: int
    channels: list = field(default_factory=list)
    t0: float = 0.0
    start_datetime: str | None = None
    meta: dict = field(default_factory=dict)
    history: list = field(default_factory=list)
    dtype: Any = np.dtype(np.float64)
    path: str | None = None
    format: str | None = None
    extra: dict = field(default_factory=dict)

    def __post_init__(self):
        self.fs = as_positive(self.fs, "fs")
        self.n_samples = int(self.n_samples)
        self.channels = list(self.channels)
        self.t0 = float(self.t0)
        self.meta = dict(self.meta) if self.meta else {}
        self.history = list(self.history) if self.history else []
        self.dtype = np.dtype(self.dtype)
        self.extra = dict(self.extra) if self.extra else {}

    @classmethod
    def of(cls, rec) -> "RecordingHeader":
        """The header of a Recording (or of anything with the same attributes)."""
        return cls(rec.fs, rec.n_samples, rec.channels, rec.t0, rec.start_datetime, rec.meta,
                   rec.history, getattr(rec, "dtype", None) or rec.data.dtype)

    @property
    def n_channels(self) -> int:
        """Channels [-]."""
        return len(self.channels)

    def __len__(self) -> int:
        return self.n_samples

    def __repr__(self) -> str:
        where = f"{self.format} file {self.path}" if self.path is not None else "samples not held"
        return (f"RecordingHeader({self.n_samples} samples x {self.n_channels} channels at "
                f"{self.fs:g} Hz, t0={self.t0:g} s, {where})")

    def index(self, name: str) -> int:
        """Column index of channel ``name``; KeyError naming the channels when unknown."""
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"no channel {name!r}; channels: {self.names}") from None

    def spec(self, name: str) -> ChannelSpec:
        """The ChannelSpec of channel ``name``."""
        return self.channels[self.index(name)]

    def by_kind(self, kind: str) -> list[ChannelSpec]:
        """Channel specs of one kind, in column order."""
        return [c for c in self.channels if c.kind == kind]

    def header(self) -> dict:
        """Everything except the samples, as a JSON-friendly dict (as
        :meth:`Recording.header`)."""
        return {"fs": self.fs, "t0": self.t0, "n_samples": self.n_samples,
                "start_datetime": self.start_datetime,
                "channels": [c.to_dict() for c in self.channels], "meta": self.meta,
                "history": self.history}

    def with_history(self, step: str, **params) -> "RecordingHeader":
        """A copy with one processing step appended to the history (:func:`history_entry`)."""
        return replace(self, history=self.history + [history_entry(step, **params)])

    def window(self, start: float | None, stop: float | None) -> tuple[int, int]:
        """Sample range [i0, i1) of the time window [start, stop) [s]; ValueError naming the
        recording when the window is empty, reversed or outside it."""
        where = self.path if self.path is not None else "the recording"
        t_start = self.t0 if start is None else float(start)
        t_stop = self.t_end if stop is None else float(stop)
        if t_stop <= t_start:
            raise ValueError(f"{where}: empty or reversed window [{t_start!r}, {t_stop!r}) s")
        if t_start >= self.t_end or t_stop <= self.t0:
            raise ValueError(f"{where}: window [{t_start!r}, {t_stop!r}) s lies outside the "
                             f"recording [{self.t0!r}, {self.t_end!r}) s")
        i0 = sample_index(t_start, self.t0, self.fs, self.n_samples)
        i1 = sample_index(t_stop, self.t0, self.fs, self.n_samples)
        return i0, max(i0, i1)

    def check_channels(self, channels) -> list[str]:
        """Normalise a channel selection (None, a name, or names) and check it exists."""
        where = self.path if self.path is not None else "the recording"
        if channels is None:
            return self.names
        if isinstance(channels, str):
            channels = [channels]
        channels = list(channels)
        if not channels:
            raise ValueError(f"{where}: channel selection is empty")
        known = set(self.names)
        missing = [c for c in channels if c not in known]
        if missing:
            raise ValueError(f"{where}: no channel(s) {missing}; the file has {self.names}")
        if len(set(channels)) != len(channels):
            raise ValueError(f"{where}: channel selection repeats a channel: {channels}")
        return channels

    def channel(self, name: str):
        """Not held: TypeError (the samples of a streamed recording are read block by block)."""
        raise TypeError(f"channel {name!r}: the recording is streamed in blocks, its samples are "
                        "not held (use the stage results: onsets, quality, the excerpt)")

    @property
    def data(self):
        """Not held: TypeError (the samples of a streamed recording are read block by block)."""
        raise TypeError("the recording is streamed in blocks, its samples are not held")


class Recording(_TimeAxis):
    """Samples x channels at a uniform sample rate, with channel specs, metadata, history.

    Parameters
    ----------
    data : array_like, shape (n_samples, n_channels)
        Samples in physical units (see each :class:`ChannelSpec`). A 1-D array is taken as a
        single channel. float32 and float64 are kept as given; other dtypes become float64.
    fs : float
        Sample rate [Hz], > 0.
    channels : sequence of ChannelSpec or str
        One spec per column; plain strings become ``ChannelSpec(name)``. Names must be unique.
    t0 : float
        Time of the first sample [s] on the recording's own time axis (0 for most rigs).
    start_datetime : str or datetime, optional
        Wall-clock time of the first sample (ISO 8601, UTC preferred).
    meta : dict, optional
        Gearset / rig metadata (JSON-friendly values).
    history : list of dict, optional
        Processing steps applied so far, oldest first.
    copy : bool
        Copy ``data`` (default False: the array is used as given when it already has a
        float dtype and 2-D shape).

    Notes
    -----
    Sample ``i`` is at time ``t0 + i / fs`` [s]. Slicing by time takes samples with
    ``start <= t < stop`` (half-open, like Python slices).
    """

    __slots__ = ("data", "fs", "channels", "t0", "start_datetime", "meta", "history")

    def __init__(self, data, fs: float, channels: Sequence[ChannelSpec | str], t0: float = 0.0,
                 start_datetime: str | _dt.datetime | None = None, meta: dict | None = None,
                 history: list | None = None, copy: bool = False):
        arr = np.asarray(data)
        if arr.dtype.kind not in "fiub":
            raise TypeError(f"data must be numeric, got dtype {arr.dtype}")
        if arr.dtype not in (np.float32, np.float64):
            arr = arr.astype(np.float64)
        elif copy:
            arr = arr.copy()
        if arr.ndim == 1:
            arr = arr[:, None]
        if arr.ndim != 2:
            raise ValueError(f"data must be 2-D (samples x channels), got shape {arr.shape}")
        self.fs = as_positive(fs, "fs")
        specs = []
        for c in channels:
            if isinstance(c, ChannelSpec):
                specs.append(c)
            elif isinstance(c, str):
                specs.append(ChannelSpec(c))
            elif isinstance(c, dict):
                specs.append(ChannelSpec.from_dict(c))
            else:
                raise TypeError(f"channels must be ChannelSpec, dict or str, got {type(c).__name__}")
        if len(specs) != arr.shape[1]:
            raise ValueError(f"data has {arr.shape[1]} channel column(s) but {len(specs)} channel spec(s) were given")
        names = [s.name for s in specs]
        seen: set = set()
        dup: set = set()
        for n in names:                      # linear in the channels (a CSV may have 1024)
            (dup if n in seen else seen).add(n)
        dup = sorted(dup)
        if dup:
            raise ValueError(f"duplicate channel name(s) {dup}")
        self.data = arr
        self.channels = tuple(specs)
        self.t0 = as_float(t0, "t0")
        if isinstance(start_datetime, _dt.datetime):
            start_datetime = start_datetime.isoformat()
        if start_datetime is not None and not isinstance(start_datetime, str):
            raise TypeError(f"start_datetime must be an ISO string or datetime, got {start_datetime!r}")
        self.start_datetime = start_datetime
        self.meta = dict(meta) if meta else {}
        self.history = list(history) if history else []

    # ------------------------------------------------------------------ basic properties
    @property
    def n_samples(self) -> int:
        """Number of samples per channel [-]."""
        return int(self.data.shape[0])

    @property
    def n_channels(self) -> int:
        """Number of channels [-]."""
        return int(self.data.shape[1])

    def times(self) -> np.ndarray:
        """Sample times t0 + i / fs [s], float64."""
        return self.t0 + np.arange(self.n_samples, dtype=np.float64) / self.fs

    def __len__(self) -> int:
        return self.n_samples

    def __repr__(self) -> str:
        kinds = ", ".join(f"{c.name}:{c.kind}" for c in self.channels[:8])
        more = "" if self.n_channels <= 8 else f", ... (+{self.n_channels - 8})"
        return (f"Recording({self.n_samples} samples x {self.n_channels} channels at {self.fs:g} Hz, "
                f"t0={self.t0:g} s, duration={self.duration:.6g} s, [{kinds}{more}])")

    def __eq__(self, other) -> bool:
        if not isinstance(other, Recording):
            return NotImplemented
        return (self.fs == other.fs and self.t0 == other.t0 and self.channels == other.channels
                and self.start_datetime == other.start_datetime and self.meta == other.meta
                and self.history == other.history and self.data.dtype == other.data.dtype
                and self.data.shape == other.data.shape
                and np.array_equal(self.data, other.data, equal_nan=True))

    __hash__ = None  # mutable container

    # ------------------------------------------------------------------ channel access
    def index(self, name: str) -> int:
        """Column index of channel ``name``; ValueError listing the names when unknown."""
        for i, c in enumerate(self.channels):
            if c.name == name:
                return i
        raise ValueError(f"no channel named {name!r}; channels are {self.names}")

    def spec(self, name: str) -> ChannelSpec:
        """The :class:`ChannelSpec` of channel ``name``."""
        return self.channels[self.index(name)]

    def channel(self, name: str) -> np.ndarray:
        """Samples of one channel (a view, 1-D) in its physical units."""
        return self.data[:, self.index(name)]

    def by_kind(self, kind: str) -> list[ChannelSpec]:
        """Channel specs of one kind (``"sun"``, ``"ring"``, ...), in column order."""
        if kind not in CHANNEL_KINDS:
            raise ValueError(f"kind must be one of {CHANNEL_KINDS}, got {kind!r}")
        return [c for c in self.channels if c.kind == kind]

    def select(self, channels: Sequence[str | int] | str | None) -> "Recording":
        """A recording with only the given channels (names or column indices), in that order."""
        if channels is None:
            return self
        if isinstance(channels, (str, int)):
            channels = [channels]
        idx = []
        for c in channels:
            if isinstance(c, str):
                idx.append(self.index(c))
            elif isinstance(c, (int, np.integer)) and not isinstance(c, bool):
                if not -self.n_channels <= c < self.n_channels:
                    raise ValueError(f"channel index {c} out of range for {self.n_channels} channel(s)")
                idx.append(int(c) % self.n_channels)
            else:
                raise TypeError(f"channels must be names or indices, got {c!r}")
        if len(set(idx)) != len(idx):
            raise ValueError(f"channel selection repeats a channel: {list(channels)}")
        if not idx:
            raise ValueError("channel selection is empty")
        data = self.data[:, idx] if idx != list(range(self.n_channels)) else self.data
        return self._derive(data=data, channels=[self.channels[i] for i in idx])

    # ------------------------------------------------------------------ time access
    def sample_range(self, start: float | None = None, stop: float | None = None, *,
                     strict: bool = True) -> tuple[int, int]:
        """Sample index range [i0, i1) of the half-open time window [start, stop) [s].

        ``strict`` raises ValueError when the window lies outside the recording or is empty.
        """
        t_start = self.t0 if start is None else as_float(start, "start")
        t_stop = self.t_end if stop is None else as_float(stop, "stop")
        if t_stop < t_start:
            raise ValueError(f"window stop ({t_stop!r} s) is before start ({t_start!r} s)")
        if strict and (t_start >= self.t_end or t_stop <= self.t0) and self.n_samples:
            raise ValueError(f"window [{t_start!r}, {t_stop!r}) s lies outside the recording "
                             f"[{self.t0!r}, {self.t_end!r}) s")
        i0 = sample_index(t_start, self.t0, self.fs, self.n_samples)
        i1 = sample_index(t_stop, self.t0, self.fs, self.n_samples)
        return i0, max(i0, i1)

    def slice_time(self, start: float | None = None, stop: float | None = None) -> "Recording":
        """Samples with start <= t < stop [s] (a view); ValueError if outside the recording."""
        i0, i1 = self.sample_range(start, stop)
        return self.slice_samples(i0, i1)

    def slice_samples(self, i0: int, i1: int) -> "Recording":
        """Samples i0 <= i < i1 (a view of the data)."""
        i0 = max(0, int(i0))
        i1 = min(self.n_samples, int(i1))
        i1 = max(i0, i1)
        return self._derive(data=self.data[i0:i1], t0=self.t0 + i0 / self.fs)

    def blocks(self, block: float, overlap: float = 0.0) -> Iterator["Recording"]:
        """Iterate over consecutive blocks of ``block`` seconds, each extended by ``overlap``
        seconds of the following samples (the last block is shorter).

        Block k starts at sample k * n_block and ends at (k + 1) * n_block + n_overlap
        (exclusive, clipped). Views, no copies.
        """
        n_block = max(1, int(round(as_positive(block, "block") * self.fs)))
        n_ovl = int(round(as_nonnegative(overlap, "overlap") * self.fs))
        for i0 in range(0, self.n_samples, n_block):
            yield self.slice_samples(i0, i0 + n_block + n_ovl)

    # ------------------------------------------------------------------ conversions
    def to_dataframe(self, *, time_index: bool = True):
        """A pandas DataFrame with one column per channel, indexed by time [s]."""
        import pandas as pd

        df = pd.DataFrame(self.data, columns=self.names, copy=False)
        if time_index:
            df.index = pd.Index(self.times(), name="time_s")
        df.attrs["fs"] = self.fs
        df.attrs["units"] = {c.name: c.units for c in self.channels}
        return df

    def to_xarray(self):
        """The samples as an ``xarray.DataArray`` (time x channel), labelled.

        Needs xarray, an optional dependency: ``pip install "meshphase[xarray]"``.

        Returns
        -------
        xarray.DataArray
            Named ``"samples"``, dims ``("time", "channel")``, the samples as stored (a view
            of :attr:`data` where xarray allows; physical value = sample * ``gain``).
            Coordinates: ``time`` [s] (``t0 + i / fs``, attrs ``units="s"``), ``channel``
            (the names) and, along ``channel``: ``kind``, ``units``, ``gear`` (text, ""
            when unset), ``gain`` [units per stored unit], ``tooth`` [-] and
            ``face_position`` [m] (floats, NaN when unset). Attrs: ``fs`` [Hz], ``t0`` [s],
            ``start_datetime`` (ISO 8601 text, "" when unknown) and ``meta`` (the metadata
            as JSON text, ``json.loads`` reads it back): attrs a netCDF or Zarr file can
            hold.

        Raises
        ------
        ImportError
            xarray is not installed; the message names the extra that installs it.
        """
        try:
            import xarray as xr  # optional, heavy: only when asked for
        except ImportError as exc:
            raise ImportError("Recording.to_xarray needs xarray, an optional dependency of "
                              "meshphase: pip install \"meshphase[xarray]\"") from exc
        specs = self.channels

        def opt_float(values):
            return np.array([np.nan if v is None else float(v) for v in values], dtype=float)

        coords = {
            "time": ("time", self.times(), {"units": "s"}),
            "channel": ("channel", list(self.names)),
            "kind": ("channel", [c.kind for c in specs]),
            "units": ("channel", [c.units for c in specs]),
            "gear": ("channel", [c.gear or "" for c in specs]),
            "gain": ("channel", np.array([c.gain for c in specs], dtype=float)),
            "tooth": ("channel", opt_float(c.tooth for c in specs), {"units": "1"}),
            "face_position": ("channel", opt_float(c.face_position for c in specs),
                              {"units": "m"}),
        }
        attrs = {"fs": self.fs, "t0": self.t0, "start_datetime": self.start_datetime or "",
                 "meta": json.dumps(to_jsonable(self.meta))}
        return xr.DataArray(self.data, dims=("time", "channel"), coords=coords, attrs=attrs,
                            name="samples")

    def header(self) -> dict:
        """Everything except the samples, as a JSON-friendly dict."""
        return {
            "fs": self.fs, "t0": self.t0, "n_samples": self.n_samples,
            "start_datetime": self.start_datetime,
            "channels": [c.to_dict() for c in self.channels],
            "meta": self.meta, "history": self.history,
        }

    @property
    def info(self) -> RecordingHeader:
        """Everything but the samples, as a :class:`RecordingHeader` (dtype included)."""
        return RecordingHeader.of(self)

    def source(self, channels: Sequence[ChannelSpec] | None = None, gains: list | None = None, *,
               label: str = "recording") -> "MemorySource":
        """The recording as a :class:`BlockSource` (:class:`MemorySource`): its samples read
        block by block as views, what the streamed stages read.

        Parameters
        ----------
        channels : sequence of ChannelSpec, optional
            Specs replacing the recording's (channel overrides).
        gains : list of (int, float), optional
            (column, factor) applied to the samples, in order, on copies of the blocks.
        label : str
            What the source is called in messages.
        """
        return MemorySource(self, channels, gains, label=label)

    def with_history(self, step: str, **params: Any) -> "Recording":
        """A shallow copy with one processing step appended to the history."""
        return self._derive(history=self.history + [history_entry(step, **params)])

    def replace_data(self, data, step: str | None = None, **params) -> "Recording":
        """A recording with new samples of the same shape (same specs), optionally logging a step."""
        data = np.asarray(data)
        if data.shape != self.data.shape:
            raise ValueError(f"replacement data shape {data.shape} != recording shape {self.data.shape}")
        out = self._derive(data=data)
        return out.with_history(step, **params) if step else out

    def copy(self) -> "Recording":
        """A deep copy (samples, specs, metadata, history)."""
        return Recording(self.data.copy(), self.fs, self.channels, self.t0, self.start_datetime,
                         copy.deepcopy(self.meta), copy.deepcopy(self.history))

    def _derive(self, **changes) -> "Recording":
        kw = dict(data=self.data, fs=self.fs, channels=self.channels, t0=self.t0,
                  start_datetime=self.start_datetime, meta=self.meta, history=self.history)
        kw.update(changes)
        return Recording(**kw)

    # ------------------------------------------------------------------ notebooks
    def _repr_html_(self) -> str:
        """The channels, sample rate, duration and start as an HTML table (notebooks)."""
        cap = (f"Recording: {self.n_channels} channel(s) at {self.fs:g} Hz, {self.duration:.6g} s "
               f"({self.n_samples} samples), t0 = {self.t0:g} s"
               + (f", started {self.start_datetime}" if self.start_datetime else ""))
        rows = [{"channel": c.name, "kind": c.kind, "units": c.units, "gear": c.gear,
                 "tooth": c.tooth, "face_position_mm": (None if c.face_position is None
                                                        else c.face_position * 1e3),
                 "description": c.description} for c in self.channels]
        cols = ["channel", "kind", "units", "gear"]
        cols += [k for k in ("tooth", "face_position_mm", "description")
                 if any(r[k] not in (None, "") for r in rows)]
        return html_table(rows, cols, caption=cap)

    # ------------------------------------------------------------------ quality
    def quality(self) -> list[dict]:
        """Per-channel quality summary: NaN/inf runs, longest run, min/max, clipped runs,
        dropout runs.

        Uses :func:`meshphase.signal.quality.channel_quality` on each channel (with its kind: a tacho's
        flat levels are not analysed as dropouts or clipped plateaus).
        """
        return [dict(channel=c.name, **channel_quality(self.data[:, i], kind=c.kind))
                for i, c in enumerate(self.channels)]


# ============================================================================ block sources
class BlockSource(abc.ABC):
    """A recording that can be read again and again in consecutive blocks.

    Implementations: :class:`MemorySource` (a Recording in memory), and in
    :mod:`meshphase.io.sources` ``FileSource`` (a recording file), ``GeneratedSource`` (a
    generated recording, again for every pass) and ``BridgeSource`` (another source's bridge
    channels converted to strain).

    Attributes
    ----------
    header : RecordingHeader
        Channels (after any override), fs, t0, length, dtype.
    """

    header: RecordingHeader

    @abc.abstractmethod
    def blocks(self, n_block: int) -> Iterator[tuple[int, np.ndarray]]:
        """(first sample, samples x channels array) of consecutive blocks of about
        ``n_block`` samples, in the stored dtype, channel gains applied; the arrays are the
        caller's."""

    @property
    def label(self) -> str:
        """What the source is called in messages."""
        return "recording"


def apply_gains(data: np.ndarray, gains: list, copy: bool) -> np.ndarray:
    """``data`` with column ``j`` multiplied by ``g`` for each (j, g) of ``gains``, in order,
    in the stored dtype; on a copy (Fortran order) when ``copy``, else in place.

    Parameters
    ----------
    data : ndarray, shape (n, c)
    gains : list of (int, float)
        (column, factor) pairs; empty: ``data`` itself is returned.
    copy : bool
    """
    if not gains:
        return data
    if copy:
        data = data.copy(order="F")
    for j, g in gains:
        data[:, j] *= g
    return data


def warn_nonfinite_runs(label: str, names: Sequence[str], results: dict, first: int = 0) -> None:
    """One DataQualityWarning per channel with NaN/inf runs, as :func:`meshphase.io.read`
    issues it for a whole file.

    Parameters
    ----------
    label : str
        The recording (a file's path), first in each message.
    names : sequence of str
        Channel names, in the order warned.
    results : dict
        Channel name -> anything with ``nonfinite_runs`` (k x 2 [start, stop) sample array, or
        None); channels missing here are skipped.
    first : int
        Sample index of the results' sample 0 in the recording [-] (a window's start).
    """
    for name in names:
        runs = results[name].nonfinite_runs if name in results else None
        if runs is None or not len(runs):
            continue
        lengths = runs[:, 1] - runs[:, 0]
        warnings.warn(DataQualityWarning(
            f"{label}: channel {name!r} has {len(runs)} run(s) of NaN/inf samples "
            f"({int(lengths.sum())} samples, longest {int(lengths.max())}, first at sample "
            f"{int(runs[0, 0]) + first}); kept in the data"), stacklevel=3)


class MemorySource(BlockSource):
    """A Recording held in memory, read as views (gains applied on copies of the blocks).

    Parameters
    ----------
    rec : Recording
    channels : sequence of ChannelSpec, optional
        Specs replacing the recording's (channel overrides); default its own.
    gains : list of (int, float), optional
        (column, factor) applied to the samples, in order.
    label : str
        What the source is called in messages.
    nonfinite_warnings : bool
        :meth:`warn_nonfinite` warns of the NaN/inf runs as a file source does (default
        False: it does nothing).
    """

    def __init__(self, rec: Recording, channels=None, gains: list | None = None, *,
                 label: str = "recording", nonfinite_warnings: bool = False):
        if not isinstance(rec, Recording):
            raise TypeError(f"rec must be a Recording, got {type(rec).__name__}")
        self.rec = rec
        self.gains = list(gains or [])
        h = RecordingHeader.of(rec)
        if channels is not None:
            h.channels = list(channels)
        self.header = h
        self._label = str(label)
        self.nonfinite_warnings = bool(nonfinite_warnings)

    def warn_nonfinite(self, results: dict) -> None:
        """With ``nonfinite_warnings``: one DataQualityWarning per channel with NaN/inf runs
        (:func:`warn_nonfinite_runs`; ``results``: the scan results by channel)."""
        if self.nonfinite_warnings:
            warn_nonfinite_runs(self.label, self.rec.names, results)

    @property
    def label(self) -> str:
        """What the source is called in messages."""
        return self._label

    def blocks(self, n_block: int):
        """Consecutive blocks of ``n_block`` samples (views; copies where gains apply)."""
        n = self.rec.n_samples
        for i0 in range(0, n, n_block):
            yield i0, apply_gains(self.rec.data[i0:i0 + n_block], self.gains, copy=True)
