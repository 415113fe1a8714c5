"""Recordings processed in blocks: conditioning, quality and onsets in bounded memory.

The stages ``load``, ``condition`` and ``onsets`` (:mod:`meshphase.run.stages`) run through this
module, for recording files and for recordings already in memory alike. A recording is read
three times, block by block, channel-major, in the dtype it is stored in (an HDF5 or MCAP
file's checksums are checked in the first pass; the later ones read the same, unchanged
file unchecked, see :class:`meshphase.io.sources.FileSource`), each pass reading the next block on a
thread of its own while it works on this one (:func:`meshphase.runtime.threads.read_ahead`):

1. **Statistics** (pass 1, :class:`meshphase.signal.quality.ChannelScan`): per channel the extremes,
   the strided subsamples and run-length counts that the dropout / plateau thresholds come
   from, the runs of non-finite samples.
2. **Runs** (pass 2): the runs at the rails, the candidate flat runs with the samples around
   them (classified at the end of the pass), the tacho's rising edges, and the first
   ``HUM_SECONDS`` of each conditioned channel, in which the mains hum is looked for (what
   :func:`meshphase.signal.condition.detect_hum` examines of a whole channel).
3. **Conditioning and onsets** (pass 3, :func:`condition_stream`): dropouts to NaN, hum
   notches, drift removal, band limit, SNR estimate, and the onset detector
   (:class:`meshphase.onsets.OnsetStream`), each channel through a chain of streaming
   filters; only the onsets, the quality reports and a short excerpt of the conditioned
   signal are kept.

Equality with the whole-array functions
---------------------------------------
Passes 1 and 2 give exactly the whole-array quality report (same code, see ChannelScan). The
zero-phase IIR filters (:func:`scipy.signal.sosfiltfilt`, or its arithmetic compiled by numba
for a long recording, two channels of a gear side by side: :mod:`meshphase.signal.iir`, the same
numbers) are run on windows that overlap
each kept stretch by ``L`` samples on both sides, ``L`` chosen so that the slowest pole
of the filter decays by 1e-15 over it (:func:`filter_overlap`): a transient started at an
artificial window edge has decayed below ~1e-13 of the signal at the samples kept; at the
recording's own ends and at gaps the window holds the true edge and the filter pads it as
the whole-array filter does. The drift baseline is computed from the same block medians
(means of whole pulse periods, the partial last period left out, when the recording holds
at least two) as the whole array; its output for a sample waits until every block value that
sample depends on is known (about 9 blocks ahead, further across a gap; stretches of all-NaN
samples are held as their length only). So the conditioned signal equals the whole-array
:func:`meshphase.signal.condition.condition_recording` to ~1e-12 of its amplitude and the onset
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
:func:`scan_memory` (passes 1 and 2) and :func:`stream_memory` (pass 3) estimate it before
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
from scipy import ndimage

from meshphase.signal import iir
from meshphase.signal.condition import (_apply_finite, _block_means, _block_medians, _check_freq, _drift_window,
                                        _noise_from_diffs, _resolve_band, _settle_time, _short_segments_message,
                                        _short_signal_message, _snr_combine, _snr_peak, _warn_quality, default_band,
                                        design_filter, design_notch, detect_hum, finite_apply_gaps, level_steps)
from meshphase.kinematics.encoder import pulse_levels, rising_crossing_parts
from meshphase.errors import DataQualityWarning
from meshphase.onsets import DEFAULT_BLOCK, DEFAULT_DETECTOR, make_detector
from meshphase.signal.quality import ChannelQuality, ChannelScan, _RunTracker, merge_runs, quality_from_scan
from meshphase.recording import BlockSource, MemorySource, Recording
from meshphase.signal.savgol import savgol_filter
from meshphase.runtime.threads import thread_pool
from meshphase.io.sources import FileSource, GeneratorSource, StreamedRecording
from meshphase.io.sources import blocks_ahead as _blocks_ahead
from meshphase.validate import as_choice, as_positive

__all__ = ["StreamedRecording", "BlockSource", "FileSource", "MemorySource", "GeneratorSource",
           "RawScan",
           "ChannelPlan", "StreamResult", "scan_source", "condition_stream", "filter_overlap",
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
#: Decay of the slowest filter pole over the overlap of two filter windows [-].
_DECAY = 1e-15
_FILL_MAX = 8          # gap bridging of the conditioning filters (filter_signal's default)
_SNR_SAMPLES = 1 << 20  # condition._SUBSAMPLE
#: the memory estimates' item for the blocks read (all channels; the passes read ahead)
_READ_BLOCKS = ("read blocks (all channels: this one, one queued, one being read; float64 copies of "
                "two: the onsets' and the chains')")


def _column(data: np.ndarray, j: int) -> np.ndarray:
    """Channel ``j`` of a block as contiguous float64 (a view when it already is)."""
    return np.ascontiguousarray(data[:, j], dtype=np.float64)


# ============================================================================ memory
def filter_overlap(sos: np.ndarray, *, decay: float = _DECAY) -> int:
    """Samples over which the slowest pole of ``sos`` decays by ``decay`` [-].

    A zero-phase filter (:func:`scipy.signal.sosfiltfilt`) run on a window that starts or
    ends inside the data starts with the wrong state there; the error it leaves decays like
    the slowest pole, ``r**m`` after ``m`` samples (``r`` its radius). Kept samples at least
    this far from an artificial window edge carry an error below ``decay`` times the state
    error (itself of the order of the signal).

    Parameters
    ----------
    sos : ndarray, shape (k, 6)
        Second-order sections.
    decay : float
        In (0, 1).

    Returns
    -------
    int
    """
    sos = np.asarray(sos, dtype=np.float64)
    if sos.ndim != 2 or sos.shape[1] != 6:
        raise ValueError(f"sos must have shape (k, 6), got {sos.shape}")
    if not 0.0 < decay < 1.0:
        raise ValueError(f"decay must be in (0, 1), got {decay!r}")
    r = 0.0
    for sec in sos:
        if sec[3] == 0:
            continue
        r = max(r, float(np.max(np.abs(np.roots(sec[3:])))) if np.any(sec[4:]) else 0.0)
    if r <= 0.0:
        return 1
    if r >= 1.0:
        raise ValueError(f"filter is not stable (pole radius {r!r})")
    return int(math.ceil(math.log(decay) / math.log(r)))


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
        "SNR subsamples": 8 * 2 * cap(_SNR_SAMPLES),
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
    """Estimated peak memory of passes 1 and 2 (:func:`scan_source`) [B], by item.

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


# ============================================================================ passes 1 and 2
@dataclass
class RawScan:
    """What passes 1 and 2 found on the raw samples.

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
        Blocks read per pass.
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
    """Passes 1 and 2: the quality of every channel, the tacho edges and the hum windows.

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
    nblk = 0
    with _blocks_ahead(source, block) as blocks:
        for a, data in blocks:
            for j, c in enumerate(specs):
                scans[c.name].feed1(_column(data, j))
            nblk += 1
            if progress:
                progress("scan 1/2", a + data.shape[0], n)
    for s in scans.values():
        s.end1()
    n_hum = min(n, int(hum_seconds * h.fs))
    hum = {nm: np.empty(n_hum) for nm in conditioned}
    edges = None
    if tacho is not None:
        st = scans[tacho].stats
        if st.n_fin and st.hi > st.lo:
            dt = h.dtype if h.dtype in (np.float32, np.float64) else np.dtype(np.float64)
            edges = _TachoEdges(dt.type(st.lo), dt.type(st.hi), h.fs, h.t0)
    enc_edges = _encoder_edges(scans, encoders, h)
    idx = {c.name: j for j, c in enumerate(specs)}
    with _blocks_ahead(source, block) as blocks:
        for a, data in blocks:
            for j, c in enumerate(specs):
                x = _column(data, j)
                scans[c.name].feed2(x)
                if c.name in hum and a < n_hum:
                    hum[c.name][a:min(n_hum, a + x.size)] = x[:n_hum - a]
            if edges is not None:
                col = data[:, idx[tacho]]
                edges.add(col if col.dtype in (np.float32, np.float64) else col.astype(np.float64))
            for nm, ed in enc_edges.items():
                ed.add(data[:, idx[nm]].astype(np.float64, copy=False))
            if progress:
                progress("scan 2/2", a + data.shape[0], n)
    results = {nm: s.result() for nm, s in scans.items()}
    for nm, x in hum.items():                      # dropouts are gaps for the hum search too
        fr = results[nm].flat
        if fr is not None:
            for s0, s1 in fr.dropout_runs:
                if s0 < n_hum:
                    x[s0:min(s1, n_hum)] = np.nan
    reports = {c.name: quality_from_scan(results[c.name], c.name, h.fs, h.t0) for c in specs}
    quality = [dict(channel=c.name, **reports[c.name].summary_dict()) for c in specs]
    return RawScan(h, results, quality, hum, None if edges is None else edges.times(), nblk,
                   reports, {nm: ed.times() for nm, ed in enc_edges.items()})


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


# ============================================================================ filter chains
class _Pending:
    """Samples waiting to go on: arrays, with stretches of all-NaN samples held as lengths."""

    def __init__(self):
        self.parts: list = []        # arrays, or ints (a run of NaN of that length)
        self.start = 0               # global index of the first held sample
        self.n = 0

    def add(self, x: np.ndarray) -> None:
        if x.size == 0:
            return
        if x.size > 64 and math.isnan(x[0]) and math.isnan(x[-1]) and np.isnan(x).all():
            self.parts.append(int(x.size))
        else:
            self.parts.append(x)
        self.n += x.size

    def take(self, k: int) -> np.ndarray:
        """The first ``k`` held samples (removed)."""
        out = np.empty(k)
        got = 0
        while got < k:
            p = self.parts[0]
            m = p if isinstance(p, int) else p.size
            use = min(m, k - got)
            if isinstance(p, int):
                out[got:got + use] = np.nan
                rest = m - use
                if rest:
                    self.parts[0] = rest
                else:
                    self.parts.pop(0)
            else:
                out[got:got + use] = p[:use]
                if use < m:
                    self.parts[0] = p[use:]
                else:
                    self.parts.pop(0)
            got += use
        self.start += k
        self.n -= k
        return out


class _ZeroPhase:
    """A gap-aware zero-phase filter (condition._apply_finite + sosfiltfilt) on a stream."""

    def __init__(self, sos: np.ndarray, n_total: int, *, what: str, chunk: int = BLOCK_SAMPLES,
                 fill_max: int = _FILL_MAX, engine: str = "scipy"):
        self._apply = _apply_finite
        self.sos = sos
        self.engine = engine
        self.padlen = iir.padlen_for(sos)
        self.min_len = self.padlen + 1
        self.fill_max = fill_max
        self.what = what
        # the transient decays over L; bridging and padding of a gap at a window edge add
        # fill_max + padlen samples more before it starts
        self.L = filter_overlap(sos) + fill_max + self.padlen + 2
        self.chunk = max(int(chunk), 1)
        self.n = int(n_total)
        self.buf: list[np.ndarray] = []
        self.buf_start = 0
        self.buf_n = 0
        self.out_pos = 0

    def _func(self, s: np.ndarray) -> np.ndarray:
        return iir.sosfiltfilt(self.sos, s, padlen=self.padlen, engine=self.engine)

    def push(self, x: np.ndarray) -> np.ndarray:
        if not self._add(x):
            return np.empty(0)
        return self._run(self._at_end)

    @property
    def _at_end(self) -> bool:
        """Whether the samples held reach the recording's end (the due window is the last)."""
        return self.buf_start + self.buf_n >= self.n

    def _add(self, x: np.ndarray) -> bool:
        """``x`` appended; whether a window is due (the look-ahead is there, or the end)."""
        if x.size:
            self.buf.append(x)
            self.buf_n += x.size
        end = self.buf_start + self.buf_n
        return not (end < self.n and end - self.out_pos < self.L + self.chunk)

    def flush(self) -> np.ndarray:
        if self.out_pos >= self.buf_start + self.buf_n:
            return np.empty(0)
        return self._run(True)

    def _window(self) -> np.ndarray:
        return self.buf[0] if len(self.buf) == 1 else np.concatenate(self.buf)

    def _filtered(self, w: np.ndarray) -> np.ndarray:
        return self._apply(w, self._func, min_len=self.min_len, fill_max=self.fill_max,
                           what=self.what, warn=False)

    def _whole(self) -> bool:
        """Whether the due window may go to the numba kernel whole (then joined straight
        into the kernel's buffer): on that engine and long enough."""
        return self.engine == "numba" and self.buf_n >= self.min_len

    def _result(self) -> np.ndarray:
        """The due window filtered (what _apply_finite gives on it)."""
        if self._whole():
            ext = iir.extended(self.buf, self.padlen)
            return self._or_gaps(iir.filter_extended(self.sos, ext, self.padlen))
        return self._filtered(self._window())

    def _or_gaps(self, y: np.ndarray) -> np.ndarray:
        """``y``, the due window filtered whole, where it held no gap (:func:`_no_gap`); else
        the window again through the gap handling."""
        return y if _no_gap(y) else self._filtered(self._window())

    def _run(self, final: bool) -> np.ndarray:
        return self._emit(self._result(), final)

    def _emit(self, y: np.ndarray, final: bool) -> np.ndarray:
        """The final samples of the due window's result ``y``; the overlap kept (a copy:
        the window's pieces go)."""
        w0 = self.buf_start
        end = w0 + self.buf_n
        stop = end if final else end - self.L
        # a view: y is this window's own result, which nothing else holds or changes; a
        # copy cost a fresh allocation per window
        out = y[self.out_pos - w0:stop - w0]
        self.out_pos = stop
        keep = max(0, stop - self.L)
        tail, pos = [], w0
        for p in self.buf:
            if pos + p.size > keep:
                tail.append(p[max(keep - pos, 0):])
            pos += p.size
        self.buf = [np.concatenate(tail) if len(tail) != 1 else tail[0].copy()]
        self.buf_start = keep
        self.buf_n = end - keep
        return out


def _no_gap(y: np.ndarray) -> bool:
    """Whether a window filtered whole held no gap: a NaN or inf sample anywhere makes the
    forward sweep's last state, and with it every sample of the backward sweep, NaN, so
    its first and last samples tell (finite samples so large the filter overflows fail it
    too, and take the gap handling's path, which gives them the same result)."""
    return y.size > 0 and math.isfinite(float(y[0])) and math.isfinite(float(y[-1]))


def _push_pair(a: _ZeroPhase, xa: np.ndarray, b: _ZeroPhase, xb: np.ndarray):
    """``(a.push(xa), b.push(xb))``, the two windows filtered in one sweep
    (:func:`meshphase.signal.iir.filter_extended_pair`) when both are due together, of one length,
    free of gaps and on the numba engine, with filters of one section count: the same
    numbers either way (the chains of two channels read in the same blocks are due
    together unless their gaps or drift blocks differ)."""
    ra, rb = a._add(xa), b._add(xb)
    if not (ra and rb):
        return (a._run(a._at_end) if ra else np.empty(0),
                b._run(b._at_end) if rb else np.empty(0))
    # (equal section counts make equal padlens)
    if a.buf_n == b.buf_n and a.sos.shape == b.sos.shape and a._whole() and b._whole():
        ya, yb = iir.filter_extended_pair(a.sos, iir.extended(a.buf, a.padlen), b.sos,
                                          iir.extended(b.buf, b.padlen), a.padlen)
        ya, yb = a._or_gaps(ya), b._or_gaps(yb)
    else:
        ya, yb = a._result(), b._result()
    return a._emit(ya, a._at_end), b._emit(yb, b._at_end)


#: mean samples per interval of the knots below which :func:`_minus_interp` calls
#: ``np.interp`` instead of its loop over the intervals [-]
_INTERP_RUN = 512


def _minus_interp(x: np.ndarray, a: int, xp: np.ndarray, fp: np.ndarray) -> np.ndarray:
    """``x - np.interp(np.arange(a, a + x.size), xp, fp)``, bit for bit [same units as x].

    A drift baseline's knots sit a pulse period (thousands of samples) apart, and
    ``np.interp`` searches the knots for every sample: here each interval's samples are
    computed at once, with numpy's own steps (``slope * (t - xp[k]) + fp[k]``, the slope
    ``(fp[k+1] - fp[k]) / (xp[k+1] - xp[k])``; ``fp[0]`` before the first knot, ``fp[-1]``
    from the last) on an interval-long scratch array that stays in cache. Knots closer than
    ``_INTERP_RUN`` samples on average, values not all finite (numpy's NaN rules) or knots
    not strictly increasing go through ``np.interp``. ``a + x.size`` below 2**53.
    """
    n = x.size
    xp = np.asarray(xp, dtype=np.float64)
    fp = np.asarray(fp, dtype=np.float64)
    if n == 0:
        return np.empty(0)
    if (xp.size < 2 or not xp[-1] - xp[0] >= _INTERP_RUN * (xp.size - 1)
            or not np.all(np.isfinite(fp)) or not np.all(xp[1:] > xp[:-1])):
        return x - np.interp(np.arange(a, a + n, dtype=np.float64), xp, fp)
    # sample i (t = a + i) lies in interval k when xp[k] <= t < xp[k + 1]
    cut = np.clip(np.ceil(xp - a), 0, n).astype(np.int64)
    y = np.empty(n)
    c0, c1 = int(cut[0]), int(cut[-1])
    if c0:
        np.subtract(x[:c0], fp[0], out=y[:c0])
    if c1 < n:
        np.subtract(x[c1:], fp[-1], out=y[c1:])
    seg = np.flatnonzero(cut[1:] > cut[:-1])
    if seg.size:
        longest = int(np.max(cut[seg + 1] - cut[seg]))
        ramp = np.arange(longest, dtype=np.float64)
        tmp = np.empty(longest)
        slopes = (fp[1:] - fp[:-1]) / (xp[1:] - xp[:-1])
        for k in seg.tolist():
            i0, i1 = int(cut[k]), int(cut[k + 1])
            m = i1 - i0
            d = tmp[:m]
            np.add(ramp[:m], float(a + i0), out=d)                # t, exact integers
            d -= xp[k]
            d *= slopes[k]
            d += fp[k]
            np.subtract(x[i0:i1], d, out=y[i0:i1])
    return y


class _Drift:
    """Streaming :func:`meshphase.signal.condition.remove_drift` with method "median" or "savgol"
    (the baseline of block medians / means, smoothed over 17 blocks, interpolated)."""

    def __init__(self, n_total: int, fs: float, *, method: str, window: float,
                 pulse_period: float | None):
        self.n = int(n_total)
        b_p = None if pulse_period is None else max(
            1, int(round(as_positive(pulse_period, "pulse_period") * fs)))
        if b_p is not None and self.n >= 2 * b_p:
            # as drift_baseline: means of whole periods only, a partial last block left out
            self.b = b_p
            self.means = True
            self.nb = self.n // self.b
        else:
            self.b = max(1, int(round(window * fs / 16.0)))
            self.means = False
            self.nb = -(-self.n // self.b) if self.n else 0
        self.method = method
        if method == "median":
            self.h = (min(17, self.nb) | 1) // 2
            self.global_mean = False
        else:
            self.h = 8
            self.global_mean = self.nb < 17
        self.acc: list[np.ndarray] = []
        self.acc_n = 0
        # every block's (values, centres): the global mean's input, and the level steps'
        self.trace: list[tuple[np.ndarray, np.ndarray]] = []
        self.j_next = 0                         # next block whose value is computed
        # filled block values and centres of blocks [f0, f0 + len(fv))
        self.f0 = 0
        self.fv = np.empty(0)
        self.fc = np.empty(0)
        self.wait_c = np.empty(0)               # centres of NaN blocks awaiting a right value
        self.last = None                        # (centre, value) of the last finite block
        # base values and centres of blocks [b0, b0 + len(bv))
        self.b0 = 0
        self.bv = np.empty(0)
        self.bc = np.empty(0)
        self.pend = _Pending()
        self.nan_all = False
        self.n_in = 0
        self.filled_final = False

    # -------------------------------------------------------------- block values
    def _values(self, final: bool) -> None:
        k = min(self.acc_n // self.b, self.nb - self.j_next)
        if final and self.acc_n > k * self.b and self.j_next + k < self.nb:
            k += 1                              # the partial last block (medians only)
        if k == 0:
            if final and self.j_next >= self.nb and not self.filled_final:
                # the last whole block came before the end (a partial block left out)
                self.filled_final = True
                self._fill(np.empty(0), np.empty(0), True)
            return
        x = self.acc[0] if len(self.acc) == 1 else np.concatenate(self.acc)
        m = min(x.size, k * self.b)
        seg = x[:m]
        if not self.means:
            # a median would take an inf as a value: inf to NaN first (a finite sum: none);
            # _block_means leaves every non-finite sample out itself
            with np.errstate(over="ignore", invalid="ignore"):
                total = float(np.sum(seg))
            if not math.isfinite(total):
                seg = np.where(np.isfinite(seg), seg, np.nan)
        vals, cents = (_block_means if self.means else _block_medians)(seg, self.b)
        cents = cents + self.j_next * self.b
        self.trace.append((vals, cents))
        rest = x[m:]
        self.acc = [rest] if rest.size else []
        self.acc_n = rest.size
        self.j_next += vals.size
        last = final and self.j_next >= self.nb
        self.filled_final = self.filled_final or last
        self._fill(vals, cents, last)

    def _fill(self, vals: np.ndarray, cents: np.ndarray, final: bool) -> None:
        ok = np.isfinite(vals)
        if self.global_mean:
            if final:
                self._global()
            return
        wait_c = np.concatenate([self.wait_c, cents])
        if ok.any():
            last_ok = np.flatnonzero(ok)[-1]
            n_wait_old = self.wait_c.size
            xs = wait_c[:n_wait_old + last_ok + 1]
            fin_c = cents[ok]
            fin_v = vals[ok]
            if self.last is not None:
                fin_c = np.concatenate([[self.last[0]], fin_c])
                fin_v = np.concatenate([[self.last[1]], fin_v])
            filled = np.interp(xs, fin_c, fin_v)
            self._append_filled(filled, xs)
            self.last = (float(fin_c[-1]), float(fin_v[-1]))
            self.wait_c = wait_c[n_wait_old + last_ok + 1:]
        else:
            self.wait_c = wait_c
        if final and self.wait_c.size:
            if self.last is None:
                self.nan_all = True
                return
            self._append_filled(np.full(self.wait_c.size, self.last[1]), self.wait_c)
            self.wait_c = np.empty(0)

    def _traced(self) -> tuple[np.ndarray, np.ndarray]:
        """(values, centres) of every block seen, in order (empty before the first)."""
        if not self.trace:
            return np.empty(0), np.empty(0)
        return np.concatenate([v for v, _ in self.trace]), np.concatenate([c for _, c in self.trace])

    def _global(self) -> None:
        vals, cents = self._traced()
        ok = np.isfinite(vals)
        if not ok.any():
            self.nan_all = True
            return
        if not ok.all():
            vals = np.interp(cents, cents[ok], vals[ok])
        self.fv, self.fc, self.f0 = np.full(vals.size, np.mean(vals)), cents, 0
        self.bv, self.bc, self.b0 = self.fv.copy(), cents, 0

    def _append_filled(self, v: np.ndarray, c: np.ndarray) -> None:
        self.fv = np.concatenate([self.fv, v])
        self.fc = np.concatenate([self.fc, c])
        self._bases()

    def _bases(self) -> None:
        """Base values of every block whose neighbourhood of filled values is known."""
        if self.global_mean:
            return
        h, nb = self.h, self.nb
        f_end = self.f0 + self.fv.size
        j_start = self.b0 + self.bv.size
        j_stop = nb if f_end >= nb else f_end - h       # base j needs filled up to j + h
        if self.method == "savgol" and f_end < nb and j_stop > 0 and j_start < 8:
            j_stop = j_stop if f_end >= 17 else 0       # the first 8: a fit to blocks 0..16
        if self.method == "savgol" and f_end < nb:
            j_stop = min(j_stop, nb - 8)                # the last 8: a fit to the last 17
        if j_stop <= j_start:
            return
        lo = max(0, j_start - h)
        hi = min(nb, j_stop + h)
        if self.method == "savgol" and hi == nb:
            lo = max(0, min(lo, nb - 17))               # the end fit reads the last 17
        win = self.fv[lo - self.f0:hi - self.f0]
        if self.method == "median":
            base = ndimage.median_filter(win, size=2 * h + 1, mode="nearest")
        else:
            base = savgol_filter(win, 17, 2)
        new = base[j_start - lo:j_stop - lo]
        self.bv = np.concatenate([self.bv, new])
        self.bc = np.concatenate([self.bc, self.fc[j_start - self.f0:j_stop - self.f0]])
        # filled values older than the next base's neighbourhood are no longer needed
        keep = j_stop - h - 1
        if self.method == "savgol":
            keep = min(keep, nb - 17)
        drop = max(0, keep - self.f0)
        if drop:
            self.fv, self.fc, self.f0 = self.fv[drop:], self.fc[drop:], self.f0 + drop

    def steps(self, fs: float, t0: float, min_size: float) -> np.ndarray:
        """:func:`meshphase.signal.condition.level_steps` of the blocks seen: (time [s], size) rows."""
        if not self.trace:
            return np.empty((0, 2))
        return level_steps(*self._traced(), fs, t0=t0, min_size=min_size)

    # -------------------------------------------------------------- samples
    def push(self, x: np.ndarray) -> np.ndarray:
        return self._step(x, False)

    def flush(self) -> np.ndarray:
        return self._step(np.empty(0), True)

    def _step(self, x: np.ndarray, final: bool) -> np.ndarray:
        if x.size:
            self.pend.add(x)
            self.acc.append(x)
            self.acc_n += x.size
            self.n_in += x.size
        final = final or self.n_in >= self.n
        self._values(final)
        if self.nan_all:
            return self.pend.take(self.pend.n) * np.nan if self.pend.n else np.empty(0)
        return self._emit(final)

    def _emit(self, final: bool) -> np.ndarray:
        nb_known = self.b0 + self.bv.size
        if nb_known == 0:
            return np.empty(0)
        if nb_known >= self.nb:
            stop = self.n
        else:
            stop = int(math.ceil(self.bc[-1]))          # samples before the last known centre
        stop = min(stop, self.pend.start + self.pend.n)
        a = self.pend.start
        if stop <= a:
            return np.empty(0)
        x = self.pend.take(stop - a)
        # the bracketing centres of [a, stop): from the last centre <= a
        j = max(0, int(np.searchsorted(self.bc, a, side="right")) - 1)
        y = _minus_interp(x, a, self.bc[j:], self.bv[j:])
        # base values no longer needed: all but the one bracketing the next sample
        k = max(0, int(np.searchsorted(self.bc, stop, side="right")) - 1)
        if k:
            self.bv, self.bc, self.b0 = self.bv[k:], self.bc[k:], self.b0 + k
        return y


class _Chain:
    """A channel's conditioning: dropouts to NaN -> notch -> drift -> (SNR tap) -> band
    limit, each stage streaming; :func:`_push_chains` pushes one or two chains and returns
    the newly final conditioned samples."""

    def __init__(self, n: int, *, dropouts: np.ndarray | None, notch: _ZeroPhase | None,
                 drift, snr: "_SnrTap", band: _ZeroPhase | None, dtype=np.float64):
        self.n = n
        self.dropouts = dropouts if dropouts is not None and len(dropouts) else None
        self.notch, self.drift, self.snr, self.band = notch, drift, snr, band
        self.pos = 0
        # a float32 recording holds each conditioning step's result as float32 (as the
        # whole-array path does, writing every step back into the recording's array)
        self.round = np.dtype(dtype) == np.float32

    def _rounded(self, x: np.ndarray) -> np.ndarray:
        return x.astype(np.float32).astype(np.float64) if self.round and x.size else x

    def _mask(self, x: np.ndarray) -> np.ndarray:
        if self.dropouts is None:
            return x
        a, b = self.pos, self.pos + x.size
        r = self.dropouts
        i = np.searchsorted(r[:, 1], a, side="right")
        j = np.searchsorted(r[:, 0], b, side="left")
        if j > i:
            x = x.copy()
            for s0, s1 in r[i:j]:
                x[max(s0, a) - a:min(s1, b) - a] = np.nan
        return x


def _live(st) -> bool:
    return not (st is None or isinstance(st, _Identity))


def _stage(sts, xs: list, finals: list) -> list:
    """One stage of one or two chains (``sts``: that stage of each, None where a chain has
    none) pushed their samples ``xs``, flushed where the chain is final; the outputs (the
    input where a chain has no such stage). Two filters go through :func:`_push_pair`."""
    out = list(xs)
    live = [i for i, st in enumerate(sts) if _live(st)]
    if (len(live) == 2 and all(isinstance(sts[i], _ZeroPhase) and xs[i].size for i in live)):
        out[0], out[1] = _push_pair(sts[0], xs[0], sts[1], xs[1])
    else:
        for i in live:
            out[i] = sts[i].push(xs[i]) if xs[i].size else np.empty(0)
    for i in live:
        if finals[i]:
            tail = sts[i].flush()
            out[i] = np.concatenate([out[i], tail]) if tail.size else out[i]
    return out


def _push_chains(chains, xs) -> list:
    """Each of ``chains`` (one, or two filtered side by side: :func:`_push_pair`) pushed
    its next samples ``xs``; the newly final conditioned samples of each."""
    xs = [c._mask(x) for c, x in zip(chains, xs)]
    for c, x in zip(chains, xs):
        c.pos += x.size
    finals = [c.pos >= c.n for c in chains]
    for attr in ("notch", "drift"):
        sts = [getattr(c, attr) for c in chains]
        ys = _stage(sts, xs, finals)
        xs = [c._rounded(y) if _live(st) else y for c, st, y in zip(chains, sts, ys)]
    for c, x in zip(chains, xs):
        if x.size:
            c.snr.add(x)
    sts = [c.band for c in chains]
    ys = _stage(sts, xs, finals)
    return [c._rounded(y) if _live(st) else y for c, st, y in zip(chains, sts, ys)]


class _Identity:
    def push(self, x):
        return x

    def flush(self):
        return np.empty(0)


class _SnrTap:
    """:func:`meshphase.signal.condition.estimate_snr` of the drift-free signal, streamed: the noise
    from the first differences at the same stride over the finite ones, the pulse peak from
    the first 2**20 samples."""

    def __init__(self, n: int, n_finite_diffs: int, q: float = 0.999):
        self.n = n
        self.step = max(1, -(-n_finite_diffs // _SNR_SAMPLES))
        self.expect = n_finite_diffs
        self.rank = 0
        self.parts: list[np.ndarray] = []
        self.last = None
        self.pos = 0
        self.n_pre = min(n, _SNR_SAMPLES)
        self.pre = np.empty(self.n_pre)
        self.peak = None
        self.peak_done = self.n_pre == 0
        self.q = q

    def add(self, x: np.ndarray) -> None:
        if x.size == 0:
            return
        first = (-self.rank) % self.step
        lo, hi = float(np.min(x)), float(np.max(x))     # NaN when x holds a NaN
        if self.last is not None:
            v = float(self.last[0])
            lo, hi = (min(lo, v), max(hi, v)) if math.isfinite(v) else (math.nan, math.nan)
        if math.isfinite(hi - lo):
            # every difference finite (none exceeds hi - lo): only the kept ones computed
            self.parts.append(self._strided(x, first))
            self.rank += x.size - (self.last is None)
        else:
            xx = x if self.last is None else np.concatenate([self.last, x])
            with np.errstate(invalid="ignore", over="ignore"):   # inf - inf: dropped below
                d = np.diff(xx)
            d = d[np.isfinite(d)]
            self.parts.append(d[first::self.step].copy())
            self.rank += d.size
        if self.pos < self.n_pre:
            k = min(self.n_pre - self.pos, x.size)
            self.pre[self.pos:self.pos + k] = x[:k]
            if self.pos + k >= self.n_pre:
                xs = self.pre[np.isfinite(self.pre)]
                self.peak = _snr_peak(xs, self.q) if xs.size >= 2 else None
                self.pre = None
                self.peak_done = True
        self.last = x[-1:].copy()
        self.pos += x.size

    def _strided(self, x: np.ndarray, first: int) -> np.ndarray:
        """``np.diff([last] + x)[first::step]`` (``last`` when there is one), computed for
        the kept differences only."""
        s = self.step
        if self.last is None:
            a, b = x[first + 1::s], x[first::s]
            return a - b[:a.size]
        if first == 0:                                   # the one across the block edge
            head = x[:1] - self.last
            a, b = x[s::s], x[s - 1::s]
            return np.concatenate([head, a - b[:a.size]])
        a, b = x[first::s], x[first - 1::s]
        return a - b[:a.size]

    def result(self) -> tuple[float, float, float]:
        if self.rank != self.expect:
            raise RuntimeError(f"SNR tap saw {self.rank} finite differences, expected {self.expect}")
        d = np.concatenate(self.parts) if self.parts else np.empty(0)
        return _snr_combine(_noise_from_diffs(d), self.peak)


# ============================================================================ pass 3
@dataclass
class ChannelPlan:
    """How one channel is conditioned and timed in pass 3.

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
    """What pass 3 keeps.

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


def _band(fs: float, mesh_freq, lowpass, highpass, order):
    """(kind, low, high, sos) of condition_recording's band limit, or None."""
    low = None if highpass is None else _check_freq(highpass, "highpass", fs)
    if isinstance(lowpass, str):
        as_choice(lowpass, "lowpass", ("auto",))
        high = default_band(fs, mesh_freq)[1] if mesh_freq is not None else None
    elif lowpass is None:
        high = None
    else:
        high = _check_freq(lowpass, "lowpass", fs)
    if low is None and high is None:
        return None
    kind = "bandpass" if (low is not None and high is not None) else (
        "highpass" if low is not None else "lowpass")
    kind, low, high = _resolve_band(fs, kind, low, high, None)
    kind, low, high = _resolve_band(fs, kind, low, high, None)   # filter_signal resolves again
    return kind, low, high, design_filter(fs, kind=kind, low=low, high=high, order=order)


def _pairs_finite(bad: np.ndarray, n: int) -> int:
    """Number of i in [0, n - 1) with samples i and i + 1 both outside the ``bad`` runs."""
    if n < 2:
        return 0
    if len(bad) == 0:
        return n - 1
    r = bad.copy()
    r[:, 0] = np.maximum(r[:, 0] - 1, 0)          # pair i is lost when i or i + 1 is bad
    r[:, 1] = np.minimum(r[:, 1], n - 1)
    r = merge_runs(r[r[:, 1] > r[:, 0]])
    return int((n - 1) - (r[:, 1] - r[:, 0]).sum())


def condition_stream(source: BlockSource, scan: RawScan, plans: Sequence[ChannelPlan], *,
                     hum: bool = True, drift: str | None = "median",
                     drift_window: float | None = None, lowpass="auto",
                     highpass: float | None = None, order: int = 4, warn: bool = True,
                     block: int = BLOCK_SAMPLES, memory_budget: float = MEMORY_BUDGET,
                     on_samples: Callable[[str, int, np.ndarray], None] | None = None,
                     progress: Callable[[str, int, int], None] | None = None,
                     filter_engine: str = "auto") -> StreamResult:
    """Pass 3: condition the planned channels and detect onsets on the gauges, streamed.

    The chain per channel is that of :func:`meshphase.signal.condition.condition_recording`
    (dropouts to NaN, hum notches for the lines found in the first ``HUM_SECONDS``, drift
    removal, band limit) with its defaults; channels of one ``group`` share the gap guard
    ``settle`` as channels conditioned in one call do there.

    Parameters
    ----------
    source : BlockSource
        The recording (read once more).
    scan : RawScan
        Its passes 1 and 2 (:func:`scan_source`).
    plans : sequence of ChannelPlan
    hum, drift, drift_window, lowpass, highpass, order, warn
        As :func:`meshphase.signal.condition.condition_recording`.
    block : int
        Samples per channel read at a time.
    memory_budget : float
        Largest estimated memory [B] (:func:`stream_memory`); ValueError above it.
    on_samples : callable(channel, first sample, samples), optional
        Called with every piece of conditioned samples as it is final (e.g. to write the
        conditioned recording out, block by block); the array is the callee's to keep.
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
            _warn_quality(quality[p.name], 6.0)
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
            settle[p.group] = max(settle[p.group], 2.0 * 30.0 / (math.pi * float(np.min(rep.freqs))))
            notch_sos[p.name] = design_notch(rep.freqs, fs, 30.0)
    return notch_sos


def _through_gaps(bad: np.ndarray, n: int, st: _ZeroPhase, notes: list) -> np.ndarray:
    """The runs that are NaN after the zero-phase stage ``st`` (``bad`` before it), noting
    the stretches too short for it as the whole-array filter warns about them."""
    out, n_short, whole = finite_apply_gaps(bad, n, min_len=st.min_len, fill_max=_FILL_MAX)
    if whole:
        notes.append(_short_signal_message(st.what, n, st.min_len))
    elif n_short:
        notes.append(_short_segments_message(st.what, n_short, st.min_len))
    return out


def _channel_chain(p: ChannelPlan, q: ChannelQuality, notch_sos, settle: dict, notes: list, *,
                   n: int, fs: float, block: int, dtype, drift, drift_window, lowpass,
                   highpass, order, engine: str = "scipy") -> tuple:
    """One channel's conditioning chain (:class:`_Chain`), the overlap it needs [samples]
    and its drift block [samples]; its filters' settling goes into its group's ``settle``."""
    bad = q.all_gap_runs()                                 # masked input: gaps + dropouts
    notch = None
    chain_l = drift_b = 0
    if notch_sos is not None:
        notch = _ZeroPhase(notch_sos, n, what="notch_hum", chunk=block, engine=engine)
        bad = _through_gaps(bad, n, notch, notes)
    dr = None
    if drift is not None:
        w = _drift_window(drift_window, p.mesh_freq)
        if drift == "highpass":
            sos = design_filter(fs, kind="highpass", low=min(1.0 / w, 0.25 * fs), order=2)
            dr = _ZeroPhase(sos, n, what="filter_signal(highpass)", chunk=block, engine=engine)
            bad = _through_gaps(bad, n, dr, notes)
            settle[p.group] = max(settle[p.group], 2.0 * w)
            chain_l = dr.L
        else:
            dr = _Drift(n, fs, method=drift, window=w, pulse_period=p.pulse_period)
            drift_b = dr.b
    snr = _SnrTap(n, _pairs_finite(bad, n))
    band = None
    bd = _band(fs, p.mesh_freq, lowpass, highpass, order)
    if bd is not None:
        kind, low, high, sos = bd
        band = _ZeroPhase(sos, n, what=f"filter_signal({kind})", chunk=block, engine=engine)
        _through_gaps(bad, n, band, notes)
        settle[p.group] = max(settle[p.group], _settle_time(low, high))
    chain_l += sum(st.L for st in (notch, band) if st is not None)
    chain = _Chain(n, dropouts=q.dropout_runs, notch=notch,
                   drift=dr if dr is not None else _Identity(), snr=snr, band=band, dtype=dtype)
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
    side where their windows fall due together (:func:`_push_pair`). Channels of one group
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
    """The read of pass 3: every block through the chains, the conditioned samples to the
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
            # a fresh float64 copy: the stages hold on to what they are given
            return lambda group: _push_chains(
                [self.chains[p.name] for p in group],
                [np.array(data[:, idx[p.name]], dtype=np.float64) for p in group])

        groups = _chain_pairs(self.plans)
        with thread_pool(max_items=len(groups)) as tmap, _blocks_ahead(source, block) as blocks:
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
    (:meth:`_Drift.steps`), with the stretch whose passes they may have moved."""
    if not isinstance(drift, _Drift) or not math.isfinite(q.noise_rms):
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
        self.t = _RunTracker()

    def add(self, y):
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
