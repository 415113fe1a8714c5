"""Recordings processed in blocks: conditioning, quality and onsets in bounded memory.

The stages ``load``, ``condition`` and ``onsets`` (:mod:`meshphase.run.stages`) run through this
module, for recording files and for recordings already in memory alike. A recording is read
twice, block by block, channel-major, in the dtype it is stored in (an HDF5 or MCAP file's
checksums are checked in the first read; the second reads the same, unchanged file
unchecked, see :class:`meshphase.io.sources.FileSource`), each read taking the next block on
a thread of its own while it works on this one (:func:`meshphase.runtime.threads.read_ahead`):

1. **Scan** (:func:`scan_source`, one read, :class:`meshphase.signal.quality.ChannelScan`):
   per channel the extremes, the strided subsamples and run-length counts that the dropout
   / plateau thresholds come from, the runs of non-finite samples; the runs at the rails
   (tracked at the running extremes), the candidate flat runs with the samples around them
   (collected from the shortest length any threshold can be, classified at the end), the
   tacho's and encoders' rising edges (from the crossings kept in the middle half of the
   range seen, :class:`_BandEdges`), and the first ``HUM_SECONDS`` of each conditioned
   channel, in which the mains hum is looked for (what
   :func:`meshphase.signal.condition.detect_hum` examines of a whole channel). Each of these
   settles exactly at the end of the read or says that it did not (a rail tolerance, more
   than :data:`meshphase.signal.quality.SCAN_CANDIDATES` flat runs at the threshold, a
   tacho whose levels moved after its first pulses): only then are those channels read a
   second time (``RawScan.n_reads``).
2. **Conditioning and onsets** (:func:`condition_stream`, the last read): dropouts to NaN,
   hum notches, drift removal, band limit, SNR estimate, and the onset detector
   (:class:`meshphase.onsets.OnsetStream`), each channel through a chain of streaming
   filters; only the onsets, the quality reports and a short excerpt of the conditioned
   signal are kept. The dropouts, the clipped runs and the hum lines are needed before
   the first sample is filtered, and come from the whole channel: hence the scan first.

Equality with the whole-array functions
---------------------------------------
The scan gives exactly the whole-array quality report (same code, see ChannelScan). The
zero-phase IIR filters (:func:`scipy.signal.sosfiltfilt`, or its arithmetic compiled by numba
for a long recording, two channels of a gear side by side: :mod:`meshphase.signal.iir`, the same
numbers) are run on windows that overlap
each kept stretch by ``L`` samples on both sides, ``L`` chosen so that the slowest pole
of the filter decays by 1e-15 over it (:func:`meshphase.signal.zero_phase.filter_overlap`): a transient started at an
artificial window edge has decayed below ~1e-13 of the signal at the samples kept; at the
recording's own ends and at gaps the window holds the true edge and the filter pads it as
the whole-array filter does. The drift baseline is computed from the same block medians
(means of whole pulse periods, the partial last period left out, when the recording holds
at least two) as the whole array; its output for a sample waits until every block value that
sample depends on is known (about 9 blocks ahead, further across a gap; stretches of all-NaN
samples are held as their length only). So the conditioned signal equals the whole-array
:func:`meshphase.conditioning.condition_recording` to ~1e-12 of its amplitude and the onset
times equal those of :func:`meshphase.onsets.detect_onsets_recording` to far below a
microsample (tests/processing/test_stream.py states and checks the tolerances).

Memory
------
Per conditioned channel a fixed budget independent of the recording's length: the filter
overlaps (tens of thousands of samples), the drift look-ahead (~10 drift blocks), the onset
detector's two analysis blocks (2 x 2**20 samples), the SNR estimate's subsamples (2 x 2**20
values), the hum window (``HUM_SECONDS`` x fs) and the excerpt, plus up to three read blocks
of every channel (the one worked on, one read ahead, one being read); and in proportion to
what is found (gap, dropout and clip runs, ~20 KB per candidate flat run, the onsets).
:func:`scan_memory` (the scan) and :func:`stream_memory` (the last read) estimate it before
the pass reads anything and refuse (ValueError naming fs, the largest item and
``memory_budget``) when it exceeds the budget;
every buffer that grows with fs is capped at the recording's own length, so a high fs costs
at most the recording's size.

Sources (:class:`meshphase.recording.BlockSource`): :class:`meshphase.io.sources.FileSource`
(a file of any :mod:`meshphase.io` format, read block by block through its format module),
:class:`meshphase.recording.MemorySource` (a Recording in memory) and
:class:`meshphase.io.sources.GeneratedSource` (a generated recording, generated again for
every pass); they are importable from here too.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field, replace
from typing import Callable, Sequence

import numpy as np
from ..errors import DataQualityWarning
from ..io.sources import FileSource, GeneratorSource, StreamedRecording
from ..io.sources import blocks_ahead
from ..kinematics.encoder import pulse_levels, rising_crossing_parts
from ..onsets import DEFAULT_BLOCK, DEFAULT_DETECTOR, make_detector
from ..recording import BlockSource, MemorySource, Recording
from ..runtime.threads import thread_pool
from ..signal import drift as drift_filters
from ..signal import iir
from ..signal.blocks import ConditioningChain, Identity, push_chains
from ..signal.condition import (NOTCH_Q, band_limit, design_notch, detect_hum, drift_highpass,
                                notch_settle, settle_time)
from ..signal.drift import DriftFilter
from ..signal.quality import (ChannelQuality, ChannelScan, RunTracker, quality_from_scan,
                              warn_quality)
from ..signal.snr import SNR_SAMPLES, SnrTap, finite_pairs
from ..signal.zero_phase import ZeroPhase

__all__ = ["StreamedRecording", "BlockSource", "FileSource", "MemorySource", "GeneratorSource",
           "RawScan",
           "ChannelPlan", "StreamResult", "scan_source", "condition_stream",
           "stream_memory", "scan_memory", "MEMORY_BUDGET", "PROCESS_RSS_BUDGET", "BLOCK_SAMPLES",
           "HUM_SECONDS", "EXCERPT_SECONDS"]

#: Samples per channel read at a time [-] (one block of every channel is held).
BLOCK_SAMPLES = 1 << 18
#: Seconds at the start of each conditioned channel examined for mains hum [s]
#: (:func:`meshphase.signal.condition.detect_hum`'s ``max_seconds``).
HUM_SECONDS = 120.0
#: Seconds of conditioned signal kept per channel for the report [s] (at most 2**19 samples).
EXCERPT_SECONDS = 60.0
_EXCERPT_MAX = 1 << 19
#: Default memory budget of the streaming stages [B]: the estimate of
#: :func:`stream_memory` must stay below it.
MEMORY_BUDGET = 2 * 1024 ** 3
#: Peak resident memory of ``meshphase process`` on a recording of up to 8 channels at
#: 5120 Hz, whatever its length [B]: what ``meshphase bench processing`` measures (0.5-0.75
#: GB from 10 min to 1 h, Python and its libraries included, numba too for a long
#: recording) with headroom;
#: tests/processing/test_stream.py holds a 30-minute run to it (slow).
PROCESS_RSS_BUDGET = 1024 ** 3
#: the memory estimates' item for the blocks read (all channels; the passes read ahead)
_READ_BLOCKS = ("read blocks (all channels: this one, one queued, one being read; float64 copies of "
                "two: the onsets' and the chains')")


def _column(data: np.ndarray, j: int) -> np.ndarray:
    """Channel ``j`` of a block as contiguous float64 (a view when it already is)."""
    return np.ascontiguousarray(data[:, j], dtype=np.float64)


# ============================================================================ memory
def stream_memory(fs: float, n_samples: int, n_channels: int, n_conditioned: int, *,
                  overlap: int = 0, drift_block: int = 0, onset_block: int = 1 << 20,
                  itemsize: int = 8, block: int = BLOCK_SAMPLES) -> dict:
    """Estimated peak memory of the streaming stages [B], by item.

    Parameters
    ----------
    fs : float
        Sample rate [Hz].
    n_samples, n_channels : int
        Length [samples] and channels of the recording.
    n_conditioned : int
        Channels conditioned (the gauges).
    overlap : int
        Sum of the filter overlaps of one channel's chain [samples].
    drift_block : int
        Drift baseline block [samples].
    onset_block : int
        Onset detector analysis block [samples].
    itemsize : int
        Bytes per stored sample.
    block : int
        Samples per channel read at a time.

    Returns
    -------
    dict
        Item -> bytes, and ``"total"``. Every buffer that grows with fs is capped at the
        recording's length.
    """
    n = max(int(n_samples), 0)
    cap = lambda k: min(int(k), n)  # noqa: E731 - nothing holds more than the recording
    blk = cap(block)
    per = {
        _READ_BLOCKS: blk * n_channels * (3 * itemsize + 16),
        "filter windows (per channel)": 8 * 6 * cap(blk + 2 * overlap),
        "drift look-ahead": 8 * cap(12 * drift_block + blk),
        "onset detector": 8 * cap(3 * onset_block) + 8 * cap(blk),
        "SNR subsamples": 8 * 2 * cap(SNR_SAMPLES),
        "hum window": 8 * cap(HUM_SECONDS * fs),
        "excerpt": 8 * cap(min(EXCERPT_SECONDS * fs, _EXCERPT_MAX)),
    }
    out = {_READ_BLOCKS: per.pop(_READ_BLOCKS)}
    for k, v in per.items():
        out[k] = v * n_conditioned if k != "filter windows (per channel)" else v
    out["total"] = int(sum(out.values()))
    return out


def scan_memory(fs: float, n_samples: int, n_channels: int, n_conditioned: int, *,
                itemsize: int = 8, block: int = BLOCK_SAMPLES,
                hum_seconds: float = HUM_SECONDS) -> dict:
    """Estimated peak memory of the scan (:func:`scan_source`) [B], by item (the flat-run
    candidates it may hold, ``SCAN_CANDIDATES`` per channel, are findings: not counted).

    Parameters as :func:`stream_memory`; ``hum_seconds`` [s]. Returns a dict with ``"total"``;
    the buffers that grow with fs are capped at the recording's length.
    """
    n = max(int(n_samples), 0)
    blk = min(int(block), n)
    out = {_READ_BLOCKS: blk * n_channels * (3 * itemsize + 8),
           "hum windows": 8 * min(int(hum_seconds * fs), n) * n_conditioned,
           # strided subsamples of the flat-run statistics: 2**16 + 2**16 + 2**18 per channel
           "quality subsamples": 8 * min(3 * 2**16 + 2**18, 2 * n) * n_channels}
    out["total"] = int(sum(out.values()))
    return out


def _check_budget(est: dict, budget: float, fs: float, what: str) -> None:
    if est["total"] > budget:
        big = max((k for k in est if k != "total"), key=lambda k: est[k])
        raise ValueError(f"fs = {fs!r} Hz: the streaming {what} would need about "
                         f"{est['total'] / 1e9:.3g} GB ({big}: {est[big] / 1e9:.3g} GB), over the "
                         f"memory budget of {budget / 1e9:.3g} GB (memory_budget); check fs and "
                         "the mesh frequency, or raise the budget")


# ============================================================================ the scan
@dataclass
class RawScan:
    """What the scan (:func:`scan_source`) found on the raw samples.

    Attributes
    ----------
    header : StreamedRecording
    results : dict of str -> meshphase.signal.quality.ScanResult
        Per channel (all of them).
    quality : list of dict
        :meth:`meshphase.recording.Recording.quality` of the recording (the
        :meth:`~meshphase.signal.quality.ChannelQuality.summary_dict` of ``reports``, with the
        channel's name).
    hum_window : dict of str -> ndarray
        First ``HUM_SECONDS`` of each conditioned channel, dropouts set to NaN (for
        :func:`meshphase.signal.condition.detect_hum`).
    tacho_times : ndarray or None
        Rising half-level crossings of the first tacho channel [s] (None: no tacho, or a
        flat one).
    encoder_times : dict of str -> ndarray
        Rising edges of each encoder channel [s], crossing half-way between its two levels
        (:func:`meshphase.kinematics.encoder.pulse_levels`); an encoder with one level only is absent.
    n_blocks : int
        Blocks per read.
    n_reads : int
        Reads of the source: 1, or 2 when the one read could not settle everything
        exactly (:func:`scan_source`).
    reports : dict of str -> meshphase.signal.quality.ChannelQuality
        The raw-data quality report of every channel.
    """

    header: StreamedRecording
    results: dict
    quality: list
    hum_window: dict = field(default_factory=dict)
    tacho_times: np.ndarray | None = None
    n_blocks: int = 0
    reports: dict = field(default_factory=dict)
    encoder_times: dict = field(default_factory=dict)
    n_reads: int = 1


class _TachoEdges:
    """The rising half-level crossings of a tacho or an encoder fed in blocks
    (:func:`meshphase.kinematics.encoder.rising_crossing_parts`, every sample before counted)."""

    def __init__(self, lo, hi, fs: float, t0: float):
        self.half = 0.5 * (lo + hi)
        self.fs, self.t0 = fs, t0
        self.last = None
        self.pos = 0
        self.parts: list[np.ndarray] = []

    def add(self, x: np.ndarray) -> None:
        if x.size == 0:
            return
        xx = x if self.last is None else np.concatenate([self.last, x])
        off = self.pos - (0 if self.last is None else 1)
        rise, frac = rising_crossing_parts(xx, self.half, finite_only=False)
        if rise.size:
            self.parts.append(self.t0 + (rise + off - 1 + frac) / self.fs)
        self.last = x[-1:].copy()
        self.pos += x.size

    def times(self) -> np.ndarray:
        return np.concatenate(self.parts) if self.parts else np.empty(0)


def scan_source(source: BlockSource, *, conditioned: Sequence[str] = (), tacho: str | None = None,
                encoders: Sequence[str] = (),
                block: int = BLOCK_SAMPLES, hum_seconds: float = HUM_SECONDS,
                memory_budget: float = MEMORY_BUDGET,
                progress: Callable[[str, int, int], None] | None = None) -> RawScan:
    """The scan: the quality of every channel, the tacho and encoder edges and the hum
    windows, in one read of ``source`` (two when the one read could not settle a channel
    exactly: see the module notes).

    Parameters
    ----------
    source : BlockSource
    conditioned : sequence of str
        Channels that will be conditioned (their hum window is kept).
    tacho : str, optional
        The tacho channel whose rising edges are timed.
    encoders : sequence of str
        Encoder channels whose rising edges are timed (half-way between the two levels of
        the channel's strided subsample, :func:`meshphase.kinematics.encoder.pulse_levels`).
    block : int
        Samples per channel read at a time.
    hum_seconds : float
        Length of the hum window [s].
    memory_budget : float
        Largest estimated memory [B] (:func:`scan_memory`); ValueError above it.
    progress : callable(pass name, samples done, samples total), optional

    Returns
    -------
    RawScan
    """
    if not isinstance(source, BlockSource):
        raise TypeError(f"source must be a BlockSource (FileSource, MemorySource, "
                        f"GeneratorSource), got {type(source).__name__}")
    h = source.header
    n = h.n_samples
    specs = h.channels
    unknown = [c for c in list(conditioned) + ([tacho] if tacho else []) + list(encoders)
               if c not in h.names]
    if unknown:
        raise ValueError(f"{source.label}: no channel(s) {unknown}; channels: {h.names}")
    _check_budget(scan_memory(h.fs, n, h.n_channels, len(conditioned), itemsize=h.dtype.itemsize,
                              block=block, hum_seconds=hum_seconds),
                  memory_budget, h.fs, "quality scan")
    scans = {c.name: ChannelScan(n, flat=c.kind not in ("tacho", "encoder")) for c in specs}
    idx = {c.name: j for j, c in enumerate(specs)}
    n_hum = min(n, int(hum_seconds * h.fs))
    hum = {nm: np.empty(n_hum) for nm in conditioned}
    pulses = {nm: _BandEdges(h.fs, h.t0) for nm in ([tacho] if tacho else []) + list(encoders)}
    nblk = 0
    with blocks_ahead(source, block) as blocks:
        for a, data in blocks:
            for j, c in enumerate(specs):
                x = _column(data, j)
                scans[c.name].feed(x)
                if c.name in hum and a < n_hum:
                    hum[c.name][a:min(n_hum, a + x.size)] = x[:n_hum - a]
            for nm, ed in pulses.items():
                ed.add(_pulse_column(data, idx[nm], nm == tacho))
            nblk += 1
            if progress:
                progress("scan", a + data.shape[0], n)
    again = [c.name for c in specs if not scans[c.name].end()]
    timers = _edge_timers(scans, tacho, encoders, h)
    times = {nm: pulses[nm].times(ed.half) for nm, ed in timers.items()}
    redo = [nm for nm, t in times.items() if t is None]
    n_reads = 1
    if again or redo:
        # what the one read could not settle exactly (module notes): read again
        n_reads = 2
        with blocks_ahead(source, block) as blocks:
            for a, data in blocks:
                for nm in again:
                    scans[nm].feed2(_column(data, idx[nm]))
                for nm in redo:
                    timers[nm].add(_pulse_column(data, idx[nm], nm == tacho))
                if progress:
                    progress("scan again", a + data.shape[0], n)
        times.update({nm: timers[nm].times() for nm in redo})
    results = {nm: s.result() for nm, s in scans.items()}
    for nm, x in hum.items():                      # dropouts are gaps for the hum search too
        fr = results[nm].flat
        if fr is not None:
            for s0, s1 in fr.dropout_runs:
                if s0 < n_hum:
                    x[s0:min(s1, n_hum)] = np.nan
    reports = {c.name: quality_from_scan(results[c.name], c.name, h.fs, h.t0) for c in specs}
    quality = [dict(channel=c.name, **reports[c.name].summary_dict()) for c in specs]
    return RawScan(h, results, quality, hum, times.get(tacho) if tacho else None, nblk,
                   reports, {nm: times[nm] for nm in encoders if nm in times}, n_reads)


def _pulse_column(data: np.ndarray, j: int, is_tacho: bool) -> np.ndarray:
    """Column ``j`` of a block as a pulse train's edges are timed from it: a tacho's in its
    floating dtype (float32 samples give float32 crossing fractions), an encoder's as
    float64."""
    col = data[:, j]
    if is_tacho:
        return col if col.dtype in (np.float32, np.float64) else col.astype(np.float64)
    return col.astype(np.float64, copy=False)


def _edge_timers(scans: dict, tacho: str | None, encoders: Sequence[str], h) -> dict:
    """The edge timer (:class:`_TachoEdges`, its level settled by the scan) of the tacho,
    when it has two levels, and of every encoder with two levels."""
    out = {}
    if tacho is not None:
        st = scans[tacho].stats
        if st.n_fin and st.hi > st.lo:
            dt = h.dtype if h.dtype in (np.float32, np.float64) else np.dtype(np.float64)
            out[tacho] = _TachoEdges(dt.type(st.lo), dt.type(st.hi), h.fs, h.t0)
    out.update(_encoder_edges(scans, encoders, h))
    return out


#: Crossing candidates a pulse channel's one-read edge timing holds at most [-]
#: (:class:`_BandEdges`; beyond them the channel's edges are timed in a second read).
BAND_PAIRS = 1 << 20


class _BandEdges:
    """The rising crossings of a pulse train through a level that is known only once the
    whole channel has been read (half-way between its extremes, or its two levels), from
    one read.

    Every sample pair that rises into the middle half of the range seen so far (the block
    itself included) is kept: the sample after it, and the two values (at most
    :data:`BAND_PAIRS` of them). At the end, the crossings of the final level are those
    among them by :func:`meshphase.kinematics.encoder.rising_crossing_parts`' rule and
    arithmetic, exactly, if the level lay in the middle half of the range in every block
    that could hold one of its crossings (a block whose samples all lie above it, or all at
    or below, cannot); :meth:`times` returns None otherwise (a tacho whose levels changed
    after its first pulses: then timed in a second read).
    """

    def __init__(self, fs: float, t0: float):
        self.fs, self.t0 = fs, t0
        self.lo, self.hi = math.inf, -math.inf
        self.last = None
        self.pos = 0
        self.idx: list[np.ndarray] = []
        self.x0: list[np.ndarray] = []
        self.x1: list[np.ndarray] = []
        self.kept = 0
        # per block: (band low, band high, largest non-NaN sample, smallest non-NaN sample
        # of the block with the one before it, whether those hold a NaN)
        self.blocks: list[tuple] = []

    def add(self, x: np.ndarray) -> None:
        """The next samples (in the dtype the crossings are computed in)."""
        if x.size == 0:
            return
        xx = x if self.last is None else np.concatenate([self.last, x])
        nan = np.isnan(xx)
        has_nan = bool(nan.any())
        vals = xx[~nan] if has_nan else xx
        new = x[~np.isnan(x)] if has_nan else x
        fin = new[np.isfinite(new)]
        if fin.size:
            self.lo = min(self.lo, float(np.min(fin)))
            self.hi = max(self.hi, float(np.max(fin)))
        if self.hi > self.lo:
            q = 0.25 * (self.hi - self.lo)
            # float64 scalars: compared with float32 samples exactly, not rounded to them
            a, b = np.float64(self.lo + q), np.float64(self.hi - q)
        else:
            a, b = np.float64(math.inf), np.float64(-math.inf)
        self.blocks.append((a, b, float(np.max(new)) if new.size else -math.inf,
                            float(np.min(vals)) if vals.size else math.inf, has_nan))
        if self.kept <= BAND_PAIRS and xx.size > 1 and a <= b:
            sel = np.flatnonzero((xx[1:] > a) & ~(xx[:-1] > b))
            if sel.size:
                off = self.pos - (0 if self.last is None else 1)
                self.idx.append(sel + (off + 1))
                self.x0.append(xx[sel])
                self.x1.append(xx[sel + 1])
                self.kept += sel.size
        self.last = x[-1:].copy()
        self.pos += x.size

    def times(self, level) -> np.ndarray | None:
        """The crossing times [s] of ``level`` (in the samples' dtype), or None when the
        pairs kept may miss one (class notes)."""
        lv = float(level)
        if self.kept > BAND_PAIRS:
            return None
        for a, b, mx, mn, has_nan in self.blocks:
            if not (a <= lv <= b or mx <= lv or (not has_nan and mn > lv)):
                return None
        if not self.idx:
            return np.empty(0)
        i, x0, x1 = (np.concatenate(p) for p in (self.idx, self.x0, self.x1))
        up = (x1 > level) & ~(x0 > level)
        i, x0, x1 = i[up], x0[up], x1[up]
        with np.errstate(invalid="ignore", divide="ignore"):   # inf edges: frac unused
            frac = np.where(x1 > x0, (level - x0) / np.where(x1 > x0, x1 - x0, 1.0), 0.0)
        frac = np.clip(frac, 0.0, 1.0)
        return self.t0 + (i - 1 + frac) / self.fs


def _encoder_edges(scans: dict, encoders: Sequence[str], h) -> dict:
    """An edge timer per encoder channel with two levels (from pass 1's strided subsample:
    medians of the two clusters, :func:`meshphase.kinematics.encoder.pulse_levels`)."""
    out = {}
    for nm in encoders:
        try:
            lo, hi = pulse_levels(scans[nm].fscan.level.values())
        except ValueError:                     # one level only: no pulses to time
            continue
        out[nm] = _TachoEdges(lo, hi, h.fs, h.t0)
    return out


# ============================================================================ conditioning and onsets
@dataclass
class ChannelPlan:
    """How one channel is conditioned and timed in the last read (:func:`condition_stream`).

    Attributes
    ----------
    name : str
    mesh_freq : float or None
        Mesh frequency of its gear [Hz] (filter defaults, drift window).
    pulse_period : float or None
        Period of its pulse train [s] (drift baseline blocks).
    group : str
        Channels of one group share the gap guard (the hum notches' settling).
    onsets : bool
        Detect onsets on it (a gauge).
    onset_kwargs : dict
        Passed to the onset detector's factory (``mesh_freq``).
    detector : str
        The registered onset detector (:func:`meshphase.onsets.make_detector`).
    """

    name: str
    mesh_freq: float | None = None
    pulse_period: float | None = None
    group: str = ""
    onsets: bool = False
    onset_kwargs: dict = field(default_factory=dict)
    detector: str = DEFAULT_DETECTOR


@dataclass
class StreamResult:
    """What the last read (:func:`condition_stream`) keeps.

    Attributes
    ----------
    quality : dict of str -> ChannelQuality
        Per conditioned channel (SNR, hum, settle, conditioned gap runs).
    onsets : dict of str -> Onsets
        Per planned gauge.
    excerpt : Recording
        The first ``EXCERPT_SECONDS`` of the conditioned channels.
    recording : StreamedRecording
        The conditioned recording's header (history extended by the steps).
    warnings : list of (category, message)
        Warnings of the onset detector, to be issued by the onsets stage.
    timings : dict
        Seconds [s]: ``condition_s``, the conditioning the onset detection did not overlap
        (the chains of a block run while the onsets take the block before), and
        ``onsets_s``, the onset detection.
    memory : dict
        :func:`stream_memory` estimate [B].
    """

    quality: dict
    onsets: dict
    excerpt: Recording
    recording: StreamedRecording
    warnings: list = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    memory: dict = field(default_factory=dict)
    n_blocks: int = 0


def condition_stream(source: BlockSource, scan: RawScan, plans: Sequence[ChannelPlan], *,
                     hum: bool = True, drift: str | None = "median",
                     drift_window: float | None = None, lowpass="auto",
                     highpass: float | None = None, order: int = 4, warn: bool = True,
                     block: int = BLOCK_SAMPLES, memory_budget: float = MEMORY_BUDGET,
                     on_samples: Callable[[str, int, np.ndarray], None] | None = None,
                     progress: Callable[[str, int, int], None] | None = None,
                     filter_engine: str = "auto") -> StreamResult:
    """The last read: condition the planned channels and detect onsets on the gauges, streamed.

    The chain per channel is that of :func:`meshphase.conditioning.condition_recording`
    (dropouts to NaN, hum notches for the lines found in the first ``HUM_SECONDS``, drift
    removal, band limit) with its defaults; channels of one ``group`` share the gap guard
    ``settle`` as channels conditioned in one call do there.

    Parameters
    ----------
    source : BlockSource
        The recording (read once more).
    scan : RawScan
        Its scan (:func:`scan_source`).
    plans : sequence of ChannelPlan
    hum, drift, drift_window, lowpass, highpass, order, warn
        As :func:`meshphase.conditioning.condition_recording`.
    block : int
        Samples per channel read at a time.
    memory_budget : float
        Largest estimated memory [B] (:func:`stream_memory`); ValueError above it.
    on_samples : callable(channel, first sample, samples), optional
        Called with every piece of conditioned samples as it is final (e.g. to write the
        conditioned recording out, block by block); the array is the callee's to keep, not
        to change (float32 for a float32 recording, whose conditioned values are float32).
    progress : callable(name, done, total), optional
    filter_engine : {"auto", "numba", "scipy"}
        Engine of the zero-phase filters (:func:`meshphase.signal.iir.pick_engine`; ``"auto"``
        weighs the samples of all planned channels). The engines give the same numbers.

    Returns
    -------
    StreamResult
    """
    plans = _check_plans(source, scan, plans, drift)
    h = source.header
    n, fs = h.n_samples, h.fs
    engine = iir.pick_engine(filter_engine, n * len(plans))
    quality = {p.name: quality_from_scan(scan.results[p.name], p.name, fs, h.t0) for p in plans}
    settle = {p.group: 0.0 for p in plans}
    notch_sos = _hum_notches(plans, scan, quality, settle, fs, hum)
    scan.hum_window = {}                        # not needed any more
    chains, notes = {}, []
    est_overlap, est_drift = 0, 0
    for p in plans:
        chains[p.name], chain_l, drift_b = _channel_chain(
            p, quality[p.name], notch_sos.get(p.name), settle, notes, n=n, fs=fs, block=block,
            dtype=h.dtype, drift=drift, drift_window=drift_window, lowpass=lowpass,
            highpass=highpass, order=order, engine=engine)
        est_overlap = max(est_overlap, chain_l)        # the longest chain's overlaps
        est_drift = max(est_drift, drift_b)
    for p in plans:
        quality[p.name] = replace(quality[p.name], settle=settle[p.group])
    onsets, est_onset = _onset_streams(plans, quality, fs, h.t0)
    est = stream_memory(fs, n, h.n_channels, len(plans), overlap=est_overlap,
                        drift_block=est_drift, onset_block=est_onset,
                        itemsize=h.dtype.itemsize, block=block)
    _check_budget(est, memory_budget, fs, "conditioning")
    run = _Pass3(plans, chains, onsets, n, min(n, int(min(EXCERPT_SECONDS * fs, _EXCERPT_MAX))))
    run.read(source, block, on_samples, progress)
    out_on = run.finish()
    # ---- quality: SNR, conditioned gaps, warnings as condition_recording issues them
    for p in plans:
        snr_db, peak, noise = chains[p.name].snr.result()
        quality[p.name] = replace(quality[p.name], snr_db=snr_db, signal_peak=peak,
                                  noise_rms=noise, conditioned_gap_runs=run.gaps[p.name].runs())
    if warn:
        for msg in notes:
            warnings.warn(msg, DataQualityWarning, stacklevel=2)
        for p in plans:
            warn_quality(quality[p.name], 6.0)
            _warn_steps(p.name, chains[p.name].drift, quality[p.name], fs, h.t0, h.spec(p.name).units)
    names = [p.name for p in plans]
    rec = _stream_history(h, quality, names, hum=hum, drift=drift, n_blocks=run.n_blocks)
    specs = [h.spec(nm) for nm in names]
    ex = Recording(np.stack([run.excerpts[nm] for nm in names], axis=1) if names
                   else np.empty((run.n_ex, 0)), fs, specs, h.t0, h.start_datetime, h.meta)
    return StreamResult(quality, out_on, ex, rec,
                        [(w.category, str(w.message)) for w in run.caught],
                        {"condition_s": run.t_cond, "onsets_s": run.t_on}, est, run.n_blocks)


def _check_plans(source, scan, plans, drift) -> list:
    """The arguments of :func:`condition_stream`, checked; the plans as a list."""
    if not isinstance(source, BlockSource):
        raise TypeError(f"source must be a BlockSource, got {type(source).__name__}")
    if not isinstance(scan, RawScan):
        raise TypeError(f"scan must be the RawScan of scan_source, got {type(scan).__name__}")
    h = source.header
    plans = list(plans)
    for p in plans:
        if not isinstance(p, ChannelPlan):
            raise TypeError(f"plans must be ChannelPlan objects, got {type(p).__name__}")
        if p.name not in scan.results:
            raise ValueError(f"plan for channel {p.name!r}: not in the recording; channels: {h.names}")
    if drift is not None and drift not in ("median", "savgol", "highpass"):
        raise ValueError(f"drift must be 'median', 'savgol', 'highpass' or None, got {drift!r}")
    return plans


def _hum_notches(plans, scan: RawScan, quality: dict, settle: dict, fs: float,
                 hum: bool) -> dict:
    """Hum lines of each planned channel from the first HUM_SECONDS (what
    :func:`meshphase.signal.condition.detect_hum` looks at): its report into ``quality``, the
    notches' ringing into its group's ``settle`` [s]; returns name -> notch sos."""
    notch_sos = {}
    if not hum:
        return notch_sos
    # the channels' spectra side by side on the run's threads (FFTs and products release
    # the GIL); the reports are taken in the plans' order
    with thread_pool(max_items=len(plans)) as tmap:
        reps = tmap(lambda p: detect_hum(scan.hum_window.get(p.name, np.empty(0)), fs,
                                         mains="auto", exclude=()), plans)
    for p, rep in zip(plans, reps):
        quality[p.name] = replace(quality[p.name], hum=rep)
        if rep.present:
            settle[p.group] = max(settle[p.group], notch_settle(rep.freqs, NOTCH_Q))
            notch_sos[p.name] = design_notch(rep.freqs, fs, NOTCH_Q)
    return notch_sos


def _through_gaps(bad: np.ndarray, st: ZeroPhase, notes: list) -> np.ndarray:
    """The runs that are NaN after the zero-phase stage ``st`` (``bad`` before it), noting
    the stretches too short for it as the whole-array filter warns about them."""
    out, note = st.through_gaps(bad)
    if note is not None:
        notes.append(note)
    return out


def _channel_chain(p: ChannelPlan, q: ChannelQuality, notch_sos, settle: dict, notes: list, *,
                   n: int, fs: float, block: int, dtype, drift, drift_window, lowpass,
                   highpass, order, engine: str = "scipy") -> tuple:
    """One channel's conditioning chain (:class:`meshphase.signal.blocks.ConditioningChain`), the overlap it needs [samples]
    and its drift block [samples]; its filters' settling goes into its group's ``settle``."""
    bad = q.all_gap_runs()                                 # masked input: gaps + dropouts
    notch = None
    chain_l = drift_b = 0
    if notch_sos is not None:
        notch = ZeroPhase(notch_sos, n, what="notch_hum", chunk=block, engine=engine)
        bad = _through_gaps(bad, notch, notes)
    dr = None
    if drift is not None:
        w = drift_filters.drift_window(drift_window, p.mesh_freq)   # (the parameter hides the name)
        if drift == "highpass":
            dr = ZeroPhase(drift_highpass(fs, w, 2), n, what="filter_signal(highpass)", chunk=block,
                           engine=engine)
            bad = _through_gaps(bad, dr, notes)
            settle[p.group] = max(settle[p.group], 2.0 * w)
            chain_l = dr.L
        else:
            dr = DriftFilter(n, fs, method=drift, window=w, pulse_period=p.pulse_period)
            drift_b = dr.b
    snr = SnrTap(n, finite_pairs(bad, n))
    band = None
    bd = band_limit(fs, p.mesh_freq, lowpass, highpass, order)
    if bd is not None:
        kind, low, high, sos = bd
        band = ZeroPhase(sos, n, what=f"filter_signal({kind})", chunk=block, engine=engine)
        _through_gaps(bad, band, notes)
        settle[p.group] = max(settle[p.group], settle_time(low, high))
    chain_l += sum(st.L for st in (notch, band) if st is not None)
    chain = ConditioningChain(n, dropouts=q.dropout_runs, notch=notch,
                   drift=dr if dr is not None else Identity(), snr=snr, band=band, dtype=dtype)
    return chain, chain_l, drift_b


def _onset_streams(plans, quality: dict, fs: float, t0: float) -> tuple[dict, int]:
    """The onset detector of every planned gauge (flagging its clipped runs, guarding its
    gaps by ``settle``, its dropouts as gaps), and the largest analysis block [samples]."""
    onsets, est_onset = {}, DEFAULT_BLOCK
    for p in plans:
        if not p.onsets:
            continue
        q = quality[p.name]
        kw = dict(p.onset_kwargs)
        kw.setdefault("flag_runs", q.clipped_runs)
        kw.setdefault("gap_guard", q.settle)
        if len(q.dropout_runs):
            kw.setdefault("gap_runs", q.dropout_runs)
        onsets[p.name] = make_detector(p.detector, fs, t0=t0, channel=p.name, **kw)
        est_onset = max(est_onset, onsets[p.name].block_samples)
    return onsets, est_onset


def _chain_pairs(plans) -> list:
    """The plans in pairs for the worker threads: two chains on one thread filter side by
    side where their windows fall due together (:func:`meshphase.signal.zero_phase.push_pair`). Channels of one group
    (one gear, one pulse period: their drift-removed windows coincide) are paired first;
    the groups' odd ones out are paired with each other (their notches still coincide),
    the last alone."""
    groups: dict = {}
    for p in plans:
        groups.setdefault(str(p.group), []).append(p)
    pairs, left = [], []
    for members in groups.values():
        k = len(members) - len(members) % 2
        pairs += [tuple(members[i:i + 2]) for i in range(0, k, 2)]
        left += members[k:]
    return pairs + [tuple(left[i:i + 2]) for i in range(0, len(left), 2)]


def _in_plan_order(plans, groups, outs) -> list:
    """The outputs of the groups' chains (``outs``, per group in its order) in the plans'
    order."""
    by = {p.name: y for g, ys in zip(groups, outs) for p, y in zip(g, ys)}
    return [by[p.name] for p in plans]


class _Pass3:
    """The last read (:func:`condition_stream`): every block through the chains, the conditioned samples to the
    onset detectors, the excerpt and the conditioned gap runs; timings and the onset
    detectors' warnings kept."""

    def __init__(self, plans, chains: dict, onsets: dict, n: int, n_ex: int):
        self.plans, self.chains, self.onsets, self.n, self.n_ex = plans, chains, onsets, n, n_ex
        self.gaps = {p.name: _RunTrack() for p in plans}
        self.excerpts = {p.name: np.empty(n_ex) for p in plans}
        self.done = {p.name: 0 for p in plans}
        self.caught: list = []
        self.t_cond = self.t_on = 0.0
        self.n_blocks = 0

    def read(self, source: BlockSource, block: int, on_samples, progress) -> None:
        h = source.header
        idx = {c.name: j for j, c in enumerate(h.channels)}
        # the channels' chains share nothing: filtered side by side on worker threads
        # (meshphase.runtime.threads; the filters release the GIL), each chain whole on one thread
        # per block, two chains per thread item (_chain_pairs: their filters sweep together
        # where their windows coincide), so the samples are those of the serial run. The
        # onset detectors and everything after them run here, in channel order, as before,
        # on the block before while the workers filter this one: a block's chains start
        # only once the block before's have all returned (a chain's state goes from block
        # to block), and the onsets take the blocks in order. (Warnings a chain raised meanwhile would be kept
        # with the onsets' own; the chains report through notes and raise none.)
        def chains(data):
            # a fresh contiguous copy (the stages hold on to what they are given): float32
            # samples of a float32 recording stay float32 (its chains round every step to
            # float32 and widen exactly where they compute), anything else float64
            dt = np.float32 if data.dtype == np.float32 else np.float64
            return lambda group: push_chains(
                [self.chains[p.name] for p in group],
                [np.array(data[:, idx[p.name]], dtype=dt if self.chains[p.name].round
                          else np.float64) for p in group])

        groups = _chain_pairs(self.plans)
        with thread_pool(max_items=len(groups)) as tmap, blocks_ahead(source, block) as blocks:
            prev = None
            for a, data in blocks:
                self.n_blocks += 1
                t = time.perf_counter()
                wait = tmap.start(chains(data), groups)
                end = a + data.shape[0]
                del data
                self.t_cond += time.perf_counter() - t
                if prev is not None:
                    self._after(*prev, on_samples, progress)
                t = time.perf_counter()
                prev = (_in_plan_order(self.plans, groups, wait()), end)
                self.t_cond += time.perf_counter() - t
            if prev is not None:
                self._after(*prev, on_samples, progress)

    def _after(self, ys: list, end: int, on_samples, progress) -> None:
        """A block's conditioned samples (``ys``, in the plans' order) delivered and fed to
        the onset detectors; ``end``: the sample after the block."""
        for p, y in zip(self.plans, ys):
            if on_samples is not None and y.size:
                on_samples(p.name, self.done[p.name], y)
            _deliver(p, y, self.done, self.gaps, self.excerpts, self.n_ex)
            if p.name in self.onsets and y.size:
                self._timed_onsets(lambda: self.onsets[p.name].feed(y))
        if progress:
            progress("condition + onsets", end, self.n)

    def _timed_onsets(self, call):
        t = time.perf_counter()
        with warnings.catch_warnings(record=True) as wl:
            warnings.simplefilter("always")
            out = call()
        self.caught.extend(wl)
        self.t_on += time.perf_counter() - t
        return out

    def finish(self) -> dict:
        """The onsets of every gauge, once every sample went through."""
        out_on = {}
        for p in self.plans:
            if self.done[p.name] != self.n:
                raise RuntimeError(f"channel {p.name!r}: the conditioning chain delivered "
                                   f"{self.done[p.name]} of {self.n} samples")
            if p.name in self.onsets:
                out_on[p.name] = self._timed_onsets(self.onsets[p.name].finish)
        return out_on


#: a level step smaller than this many per-sample noise RMS, or than this share of the pulse
#: height, is not reported [-]: whole-period block means wobble by a few per cent of the pulse
#: height under a speed ramp (the periods no longer whole), which moves no pulse's timing
STEP_NOISE_RMS = 5.0
STEP_PULSE_SHARE = 0.25


def _warn_steps(name: str, drift, q, fs: float, t0: float, units: str) -> None:
    """A DataQualityWarning naming the level steps of a channel's baseline
    (:meth:`meshphase.signal.drift.DriftFilter.steps`), with the stretch whose passes they may have moved."""
    if not isinstance(drift, DriftFilter) or not math.isfinite(q.noise_rms):
        return
    has_peak = math.isfinite(q.signal_peak) and q.signal_peak > 0
    min_size = STEP_NOISE_RMS * q.noise_rms
    if has_peak:
        min_size = max(min_size, STEP_PULSE_SHARE * q.signal_peak)
    st = drift.steps(fs, t0, min_size)
    if not len(st):
        return
    what = ", ".join(f"{s:+.3g} {units}".rstrip()
                     + (f" ({abs(s) / q.signal_peak:.2g}x the pulse height)" if has_peak else "")
                     + f" near t = {t:.1f} s" for t, s in st[:5])
    more = f" and {len(st) - 5} more" if len(st) > 5 else ""
    warnings.warn(f"channel {name!r}: the baseline steps by {what}{more} (a bridge re-zeroed, a range "
                  f"switched, a cable knocked): the pulses within {drift.b / fs:.1f} s of a step sit on "
                  "the drift baseline's ramp across it and may be mis-timed or lost", DataQualityWarning,
                  stacklevel=3)


def _stream_history(h: StreamedRecording, quality: dict, names: list, *, hum: bool,
                    drift, n_blocks: int) -> StreamedRecording:
    """The conditioned recording's header: the history entries condition_recording writes."""
    rec = h
    masked = {nm: quality[nm].n_dropout_samples for nm in names if len(quality[nm].dropout_runs)}
    if masked:
        rec = rec.with_history("condition.mask_dropouts", samples=masked)
    if hum:
        rec = rec.with_history("condition.notch_hum", q=30.0, lines_hz={
            nm: ([] if quality[nm].hum is None else [float(f) for f in quality[nm].hum.freqs])
            for nm in names})
    if drift is not None:
        rec = rec.with_history("condition.remove_drift", method=drift, channels=names)
    return rec.with_history("condition.quality", streamed=True, blocks=n_blocks,
                            quality={nm: quality[nm].history_entry() for nm in names})


class _RunTrack:
    def __init__(self):
        self.t = RunTracker()

    def add(self, y):
        # a finite sum: no NaN or inf among the samples (one read of them, no mask made)
        with np.errstate(over="ignore", invalid="ignore"):
            clean = math.isfinite(float(np.sum(y)))
        if clean:
            self.t.skip(y.size)
        else:
            self.t.add(~np.isfinite(y))

    def runs(self):
        return self.t.runs()


def _deliver(p: ChannelPlan, y: np.ndarray, done: dict, gaps: dict, excerpts: dict, n_ex: int) -> None:
    if y.size == 0:
        return
    a = done[p.name]
    gaps[p.name].add(y)
    if a < n_ex:
        k = min(n_ex - a, y.size)
        excerpts[p.name][a:a + k] = y[:k]
    done[p.name] = a + y.size
