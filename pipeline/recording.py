"""The Recording container: the one type every stage passes on.

A Recording holds a samples x channels array at a uniform sample rate, the start time of
its first sample, one :class:`ChannelSpec` per channel, free gearset/rig metadata and the
processing history. Array functions further down the package take plain arrays and sample
rates; the thin methods here convert seconds to samples once.
"""

from __future__ import annotations

import copy
import datetime as _dt
import math
import unicodedata
from dataclasses import asdict, dataclass
from typing import Any, Iterator, Sequence

import numpy as np

from meshphase.jsonable import to_jsonable
from meshphase.validate import as_float, as_nonnegative, as_positive

__all__ = ["ChannelSpec", "Recording", "CHANNEL_KINDS", "GAUGE_KINDS", "ENCODER_SHAFTS", "sample_index", "control_character"]

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


class Recording:
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

    def header(self) -> dict:
        """Everything except the samples, as a JSON-friendly dict."""
        return {
            "fs": self.fs, "t0": self.t0, "n_samples": self.n_samples,
            "start_datetime": self.start_datetime,
            "channels": [c.to_dict() for c in self.channels],
            "meta": self.meta, "history": self.history,
        }

    def with_history(self, step: str, **params: Any) -> "Recording":
        """A shallow copy with one processing step appended to the history."""
        entry = {"step": step, "time": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")}
        entry.update({k: to_jsonable(v, nonfinite="keep") for k, v in params.items()})
        return self._derive(history=self.history + [entry])

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
    def plot(self, channels=None, start: float | None = None, stop: float | None = None,
             onsets=None, *, ax=None, max_points: int = 20000):
        """Plot channels against time, one panel each, with onsets marked (matplotlib,
        imported now; :func:`meshphase.report.notebook.plot_channels`).

        Parameters
        ----------
        channels : str or sequence of str, optional
            Channels to draw (default all).
        start, stop : float, optional
            Time window [s] (half-open; default the whole recording).
        onsets : array_like, dict, Result or RunContext, optional
            Onset times [s] to mark: one array for every channel, a dict channel -> times
            (or Onsets, or (times, 1-based planets)), or a :class:`meshphase.Result` (its
            onsets, coloured by planet).
        ax : matplotlib Axes, optional
            Draw a single channel into it.
        max_points : int
            Samples drawn per channel at most (decimated by striding).

        Returns
        -------
        matplotlib.figure.Figure
        """
        if self.n_samples == 0 or self.n_channels == 0:
            raise ValueError("the recording is empty: nothing to plot")
        part = self.select(channels).slice_time(start, stop)
        if part.n_samples == 0:
            raise ValueError(f"no samples in the window [{start}, {stop}) s")
        from meshphase.report.notebook import plot_channels  # matplotlib: only when plotting

        return plot_channels(part.times(), part.data, part.channels, onsets, ax=ax,
                             max_points=max_points)

    def _repr_html_(self) -> str:
        """The channels, sample rate, duration and start as an HTML table (notebooks)."""
        from meshphase.html_repr import html_table

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
        from meshphase.signal.quality import channel_quality

        return [dict(channel=c.name, **channel_quality(self.data[:, i], kind=c.kind))
                for i, c in enumerate(self.channels)]
