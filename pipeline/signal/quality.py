"""Array functions for data-quality flags: runs of NaN/inf, clipped runs, gaps, dropouts;
and the per-channel quality report they make.

Numpy in, numpy out; no Recording here (see :meth:`pipeline.Recording.quality`). A channel is
scanned by :class:`ChannelScan` (whole, or in blocks) and reported as one
:class:`ChannelQuality`, the report that conditioning (:mod:`meshphase.signal.condition`), the
streamed stages (:mod:`meshphase.run.stream`) and the onset stage read.

The runs themselves are :mod:`meshphase.signal.runs`, the dropout and plateau rule
:mod:`meshphase.signal.flat_runs` (both re-exported here).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

from ..errors import DataQualityWarning
from .flat_runs import (CLIP_MIN_RUN, DROPOUT_MIN_RUN, FALSE_ALARM, FLAT_WINDOW, FlatCandidates,
                        FlatRuns, FlatScan, FlatStats, chance_min_run, check_false_alarm,
                        classify_flat_runs, dropout_runs, flat_runs, plateau_runs,
                        quantisation_step)
from .runs import (RunTracker, as_count, as_samples, equal_runs, find_runs, merge_runs,
                   nonfinite_runs, outside_runs)
from ..validate import as_choice

__all__ = ["find_runs", "nonfinite_runs", "clipped_runs", "channel_quality", "equal_runs",
           "quantisation_step", "chance_min_run", "FlatRuns", "flat_runs", "dropout_runs",
           "plateau_runs", "outside_runs", "FALSE_ALARM", "DROPOUT_MIN_RUN", "CLIP_MIN_RUN",
           "FlatScan", "FlatStats", "classify_flat_runs", "ChannelScan", "ScanResult",
           "FLAT_WINDOW", "ChannelQuality", "HumReport", "quality_from_scan", "merge_runs",
           "RunTracker", "warn_quality", "rail_mask", "SCAN_CANDIDATES"]


#: Candidate flat runs the one-pass scan holds per channel at most [-]
#: (:class:`ChannelScan`): ~2 * FLAT_WINDOW float64 samples each, ~10 MB at most.
SCAN_CANDIDATES = 1024


def rail_mask(x: np.ndarray, hi: float, lo: float, rtol: float) -> np.ndarray:
    """Whether each sample of ``x`` sits at a rail: within ``rtol`` times the range
    ``hi - lo`` of the largest finite sample ``hi`` or of the smallest ``lo`` [units of x]."""
    tol = rtol * (hi - lo)
    return (x >= hi - tol) | (x <= lo + tol)


def clipped_runs(x, *, min_run: int = 3, rtol: float = 0.0) -> np.ndarray:
    """Runs of at least ``min_run`` consecutive samples sitting at the channel's extreme value.

    A converter that saturates holds its full-scale value; a run of identical samples equal to
    the channel maximum (or minimum) is flagged. ``rtol`` widens "equal" relative to the
    channel range.

    Returns
    -------
    runs : ndarray of int64, shape (n_runs, 2)
    """
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 1:
        raise ValueError(f"x must be 1-D, got shape {x.shape}")
    if min_run < 2:
        raise ValueError(f"min_run must be >= 2, got {min_run!r}")
    finite = np.isfinite(x)
    if not finite.any():
        return np.empty((0, 2), dtype=np.int64)
    hi = np.max(x[finite])
    lo = np.min(x[finite])
    if hi == lo:
        return np.empty((0, 2), dtype=np.int64)
    runs = find_runs(rail_mask(x, hi, lo, rtol))
    return runs[(runs[:, 1] - runs[:, 0]) >= min_run]


# ====================================================================== the report
@dataclass(frozen=True)
class HumReport:
    """Mains hum found on one channel (:func:`meshphase.signal.condition.detect_hum`).

    Attributes
    ----------
    mains : float or None
        Detected mains family fundamental [Hz] (50 or 60), None when no hum was found.
    freqs : ndarray
        Hum lines found above the threshold [Hz] (empty when none).
    candidates : ndarray
        Lines examined [Hz] (harmonics of the examined families below 0.45 fs).
    excess_db : ndarray
        Line power over the local noise floor for each candidate [dB] (NaN when excluded).
    threshold_db : float
        Detection threshold [dB].
    checked : bool
        False when the data were too short (< 2 s of finite samples) to resolve the lines.
    """

    mains: float | None
    freqs: np.ndarray
    candidates: np.ndarray
    excess_db: np.ndarray
    threshold_db: float
    checked: bool = True

    @property
    def present(self) -> bool:
        """True when at least one hum line was found."""
        return bool(self.freqs.size)

    def to_dict(self) -> dict:
        """JSON-friendly dict."""
        return {"mains": self.mains, "freqs": self.freqs.tolist(),
                "candidates": self.candidates.tolist(),
                "excess_db": [None if not np.isfinite(v) else float(v) for v in self.excess_db],
                "threshold_db": self.threshold_db, "checked": self.checked}


def _no_runs() -> np.ndarray:
    return np.empty((0, 2), dtype=np.int64)


@dataclass(frozen=True, eq=False)
class ChannelQuality:
    """Data-quality report of one channel: what every later stage must respect.

    The one quality report of the package. :func:`quality_from_scan` makes it from a
    :class:`ChannelScan` (whole arrays and streamed blocks alike);
    :func:`meshphase.signal.condition.assess_quality`, :func:`meshphase.conditioning.condition_recording`
    and :func:`meshphase.run.stream.condition_stream` return it, the conditioning steps adding
    their findings (SNR, hum, ``settle``, ``conditioned_gap_runs``) to a copy
    (:func:`dataclasses.replace`). Two plain forms: :meth:`to_dict` (a conditioned channel's
    report, JSON-friendly) and :meth:`summary_dict` (the raw-data summary of
    :func:`channel_quality` and :meth:`meshphase.recording.Recording.quality`).

    Runs are ``[start, stop)`` sample indices relative to the first sample of the assessed
    data; sample ``i`` is at ``t0 + i / fs`` [s].

    Attributes
    ----------
    name : str
        Channel name.
    fs : float or None
        Sample rate [Hz]; None for a report of bare samples (:func:`channel_quality`), whose
        runs have no times.
    t0 : float
        Time of sample 0 [s].
    n_samples : int
        Samples assessed [-].
    gap_runs : ndarray of int64, shape (k, 2)
        Gaps: runs of non-finite samples (NaN, +-inf; missing samples are stored as NaN by
        the readers and the streaming stages). Dropouts are listed apart
        (``dropout_runs``); :meth:`all_gap_runs` merges both.
    nan_runs : ndarray of int64, shape (k, 2)
        Runs of NaN only.
    clipped_runs : ndarray of int64, shape (k, 2)
        Clipped samples, found on the raw data: runs of >= ``clip_min_run`` samples held at
        the channel's extreme value (converter saturation; not when the run is a dropout
        that happens to sit at the extreme, e.g. zeros on a positive channel) and clipped
        plateaus at any level (:func:`flat_runs`), merged.
    snr_db : float
        Peak-power SNR estimate [dB] (:func:`meshphase.signal.condition.estimate_snr`), NaN when
        unknown.
    signal_peak : float
        Pulse peak amplitude estimate [units].
    noise_rms : float
        Noise standard deviation estimate [units].
    settle : float
        Guard time around gaps within which filter transients may distort the data [s]
        (set by :func:`meshphase.conditioning.condition_recording`; the onset stage flags pulses
        that close).
    hum : HumReport or None
        Mains hum found (None when not examined).
    dropout_runs : ndarray of int64, shape (k, 2)
        DAQ dropouts found on the raw data: runs of exact zeros or of one held value longer
        than chance allows (:func:`flat_runs`); gaps for every later stage.
    dropout_min_run : int or None
        Shortest run of equal samples counted as a dropout on this channel [samples] (None:
        not examined).
    p_equal : float
        Estimated probability that a run of equal samples continues, by chance [-] (NaN:
        not examined).
    quant_step : float
        Quantisation step found [units]; 0.0 for continuous data or when not examined.
    conditioned_gap_runs : ndarray of int64, shape (k, 2), or None
        Runs of non-finite samples of the conditioned channel: its gaps and dropouts plus
        the stretches between gaps too short for the filters (set by
        :func:`meshphase.conditioning.condition_recording` and the streaming stage; None when not
        conditioned). What the phasing stage checks a pulse's window against.
    min, max : float
        Smallest and largest finite raw sample [units]; NaN when none is finite.
    rms : float
        Root mean square of the finite raw samples [units]; NaN when none is finite.
    """

    name: str
    fs: float | None
    t0: float
    n_samples: int
    gap_runs: np.ndarray
    nan_runs: np.ndarray
    clipped_runs: np.ndarray
    snr_db: float = float("nan")
    signal_peak: float = float("nan")
    noise_rms: float = float("nan")
    settle: float = 0.0
    hum: HumReport | None = None
    dropout_runs: np.ndarray = field(default_factory=_no_runs)
    dropout_min_run: int | None = None
    p_equal: float = float("nan")
    quant_step: float = 0.0
    conditioned_gap_runs: np.ndarray | None = None
    min: float = float("nan")
    max: float = float("nan")
    rms: float = float("nan")

    @property
    def n_gap_samples(self) -> int:
        """Samples inside gaps [-]."""
        return int((self.gap_runs[:, 1] - self.gap_runs[:, 0]).sum())

    @property
    def n_clipped_samples(self) -> int:
        """Samples inside clipped runs [-]."""
        return int((self.clipped_runs[:, 1] - self.clipped_runs[:, 0]).sum())

    @property
    def n_dropout_samples(self) -> int:
        """Samples inside dropout runs [-]."""
        return int((self.dropout_runs[:, 1] - self.dropout_runs[:, 0]).sum())

    @property
    def ok(self) -> bool:
        """True when there are no gaps, no dropouts and no clipped runs."""
        return not (len(self.gap_runs) or len(self.clipped_runs) or len(self.dropout_runs))

    def all_gap_runs(self) -> np.ndarray:
        """Gaps and dropouts merged into sorted, non-overlapping ``[start, stop)`` rows: the
        samples that are NaN in the conditioned channel (``dropouts="nan"``)."""
        return merge_runs(np.concatenate([self.gap_runs, self.dropout_runs]))

    def bad_runs(self) -> np.ndarray:
        """Gaps, dropouts and clipped runs merged into sorted, non-overlapping
        ``[start, stop)`` rows."""
        return merge_runs(np.concatenate([self.gap_runs, self.dropout_runs, self.clipped_runs]))

    def runs_time(self, which: str = "gap") -> np.ndarray:
        """Runs of one kind as ``[t_start, t_stop)`` [s]: "gap" (non-finite), "nan",
        "dropout", "clipped", "bad" (all of them) or "all_gaps" (gaps and dropouts, as
        :func:`meshphase.signal.condition.gap_intervals`)."""
        which = as_choice(which, "which", ("gap", "nan", "dropout", "clipped", "bad", "all_gaps"))
        if self.fs is None:
            raise ValueError(f"channel {self.name!r}: a report of bare samples has no sample "
                             "rate, so its runs have no times")
        runs = {"gap": self.gap_runs, "nan": self.nan_runs, "dropout": self.dropout_runs,
                "clipped": self.clipped_runs}.get(which)
        if runs is None:
            runs = self.bad_runs() if which == "bad" else self.all_gap_runs()
        return self.t0 + runs.astype(np.float64) / self.fs

    def gap_intervals(self) -> np.ndarray:
        """Gaps and dropouts as ``[t_start, t_stop)`` rows [s] (see
        :func:`meshphase.signal.condition.gap_intervals`)."""
        return self.runs_time("all_gaps")

    def summary(self) -> str:
        """One line for logs and warnings."""
        return (f"channel {self.name!r}: {len(self.gap_runs)} gap run(s) ({self.n_gap_samples} "
                f"samples), {len(self.dropout_runs)} dropout run(s) ({self.n_dropout_samples} "
                f"samples), {len(self.clipped_runs)} clipped run(s) ({self.n_clipped_samples} "
                f"samples), SNR {self.snr_db:.1f} dB")

    def to_dict(self) -> dict:
        """JSON-friendly dict (runs as lists; non-finite floats as None)."""
        def fl(v):
            return None if v is None or not np.isfinite(v) else float(v)
        return {"name": self.name, "fs": self.fs, "t0": self.t0, "n_samples": self.n_samples,
                "gap_runs": self.gap_runs.tolist(), "nan_runs": self.nan_runs.tolist(),
                "clipped_runs": self.clipped_runs.tolist(), "snr_db": fl(self.snr_db),
                "signal_peak": fl(self.signal_peak), "noise_rms": fl(self.noise_rms),
                "settle": self.settle, "hum": None if self.hum is None else self.hum.to_dict(),
                "dropout_runs": self.dropout_runs.tolist(), "dropout_min_run": self.dropout_min_run,
                "p_equal": fl(self.p_equal), "quant_step": float(self.quant_step),
                "conditioned_gap_runs": (None if self.conditioned_gap_runs is None
                                         else self.conditioned_gap_runs.tolist())}

    def history_entry(self) -> dict:
        """The short form a conditioned recording's history keeps: numbers of gap, dropout
        and clipped runs, and the SNR to 0.01 dB (None when unknown)."""
        return {"gap_runs": len(self.gap_runs), "dropout_runs": len(self.dropout_runs),
                "clipped_runs": len(self.clipped_runs),
                "snr_db": None if not np.isfinite(self.snr_db) else round(self.snr_db, 2)}

    def summary_dict(self) -> dict:
        """The raw-data summary (:func:`channel_quality`): counts and runs of non-finite,
        dropout and clipped samples, and the range of the finite samples."""
        nf, cl, dr = self.gap_runs, self.clipped_runs, self.dropout_runs
        nl, dl = nf[:, 1] - nf[:, 0], dr[:, 1] - dr[:, 0]
        return {
            "n_samples": int(self.n_samples),
            "n_nonfinite": int(nl.sum()),
            "nonfinite_runs": nf.tolist(),
            "longest_nonfinite_run": int(nl.max()) if nl.size else 0,
            "n_clipped_runs": int(len(cl)),
            "clipped_runs": cl.tolist(),
            "n_dropout_runs": int(len(dr)),
            "dropout_runs": dr.tolist(),
            "n_dropout_samples": int(dl.sum()),
            "longest_dropout_run": int(dl.max()) if dl.size else 0,
            "dropout_min_run": self.dropout_min_run,
            "min": self.min, "max": self.max, "rms": self.rms,
        }


def quality_from_scan(res: ScanResult, name: str = "", fs: float | None = None,
                      t0: float = 0.0) -> ChannelQuality:
    """The :class:`ChannelQuality` (no SNR, hum or conditioning yet) of a channel scanned by
    :class:`ChannelScan` (whole, or streamed in blocks: the same report).

    Parameters
    ----------
    res : ScanResult
        :meth:`ChannelScan.result`.
    name : str
        Channel name.
    fs : float or None
        Sample rate [Hz] (None: bare samples).
    t0 : float
        Time of sample 0 [s].

    Returns
    -------
    ChannelQuality
    """
    if not isinstance(res, ScanResult):
        raise TypeError(f"res must be the ScanResult of ChannelScan.result(), got {type(res).__name__}")
    if res.n == 0:
        e = _no_runs()
        return ChannelQuality(name, fs, t0, 0, e, e.copy(), e.copy())
    extra = {}
    if res.flat is not None:
        fr = res.flat
        extra = dict(dropout_runs=fr.dropout_runs, dropout_min_run=fr.min_run,
                     p_equal=fr.p_equal, quant_step=fr.quant_step)
    return ChannelQuality(name, fs, t0, int(res.n), res.nonfinite_runs, res.nan_runs,
                          res.clipped(), min=res.min, max=res.max, rms=res.rms, **extra)


def warn_quality(rep: ChannelQuality, snr_warn_db: float) -> None:
    """One :class:`~meshphase.errors.DataQualityWarning` listing what ``rep`` found: gap,
    dropout and clipped runs, and an SNR below ``snr_warn_db`` [dB]; none when clean."""
    problems = []
    if len(rep.gap_runs):
        problems.append(f"{len(rep.gap_runs)} gap run(s) of non-finite samples "
                        f"({rep.n_gap_samples} samples)")
    if len(rep.dropout_runs):
        problems.append(f"{len(rep.dropout_runs)} dropout run(s) of zeros or a held value "
                        f"({rep.n_dropout_samples} samples, treated as gaps)")
    if len(rep.clipped_runs):
        problems.append(f"{len(rep.clipped_runs)} clipped run(s) ({rep.n_clipped_samples} samples)")
    if np.isfinite(rep.snr_db) and rep.snr_db < snr_warn_db:
        problems.append(f"low SNR {rep.snr_db:.1f} dB (< {snr_warn_db:g} dB)")
    if problems:
        warnings.warn(f"channel {rep.name!r}: " + "; ".join(problems), DataQualityWarning,
                      stacklevel=3)


def channel_quality(x, *, kind: str | None = None) -> dict:
    """Summary of one channel: counts and runs of non-finite, dropout and clipped samples, range.

    Parameters
    ----------
    x : array_like, shape (n,)
        Raw samples of one channel [any unit].
    kind : str, optional
        Channel kind (:class:`meshphase.recording.ChannelSpec`). A "tacho" or an "encoder"
        is a pulse train, flat by design: its dropout and plateau analysis is skipped (the
        rail runs at its two levels are still listed as clipped, as before). Without a kind, a channel whose
        finite samples take at most 8 distinct values (among 4096 evenly strided ones) is
        taken for a pulse train; an analogue channel shows hundreds.

    Returns
    -------
    dict
        ``n_samples``, ``n_nonfinite``, ``nonfinite_runs`` (list of [start, stop)),
        ``longest_nonfinite_run``, ``n_clipped_runs``, ``clipped_runs`` (runs at the
        channel's extreme values that are not dropouts and, for analogue channels, clipped
        plateaus at any level from :func:`flat_runs`, merged), ``n_dropout_runs``,
        ``dropout_runs``,
        ``n_dropout_samples``, ``longest_dropout_run``, ``dropout_min_run`` (threshold used
        [samples]; None when not examined), ``min``, ``max``, ``rms`` (of finite samples; NaN
        when none is finite).
    """
    x = np.asarray(x)
    if kind is not None and not isinstance(kind, str):
        raise TypeError(f"kind must be a string or None, got {type(kind).__name__} {kind!r}")
    if x.ndim != 1:
        raise ValueError(f"x must be 1-D, got shape {x.shape}")
    x = as_samples(x)
    scan = ChannelScan(x.size, flat=None if kind is None else kind not in ("tacho", "encoder"))
    scan.feed1(x)
    scan.end1()
    scan.feed2(x)
    return quality_from_scan(scan.result()).summary_dict()


@dataclass(eq=False)
class ScanResult:
    """What :class:`ChannelScan` found on one channel (raw samples): the scan's raw findings,
    rail runs and flat runs apart; :func:`quality_from_scan` makes the channel's report.

    Attributes
    ----------
    n : int
    nonfinite_runs, nan_runs : ndarray of int64, shape (k, 2)
        ``[start, stop)`` runs of non-finite and of NaN samples.
    rail_runs : ndarray of int64, shape (k, 2)
        Runs at the channel's extreme finite value (:func:`clipped_runs`).
    flat : FlatRuns or None
        Dropouts and plateaus (None: not examined, e.g. a tacho).
    n_finite : int
    min, max, rms : float
        Of the finite samples (NaN when none).
    """

    n: int
    nonfinite_runs: np.ndarray
    nan_runs: np.ndarray
    rail_runs: np.ndarray
    flat: FlatRuns | None
    n_finite: int
    min: float
    max: float
    rms: float

    def clipped(self) -> np.ndarray:
        """Rail runs that are not dropouts, merged with the clipped plateaus."""
        cl = self.rail_runs
        if self.flat is not None:
            cl = outside_runs(cl, self.flat.dropout_runs)
            if len(self.flat.clipped_runs):
                cl = merge_runs(np.concatenate([cl, self.flat.clipped_runs]))
        return cl

    def to_dict(self) -> dict:
        """The summary :func:`channel_quality` returns (:meth:`ChannelQuality.summary_dict`)."""
        return quality_from_scan(self).summary_dict()


def _norm2(x: np.ndarray) -> float:
    """The Euclidean norm of finite samples ``x``, scaled by their largest magnitude so that
    neither 1e300 nor subnormal samples overflow or vanish in the squares."""
    if x.size == 0:
        return 0.0
    m = float(np.max(np.abs(x)))
    if m == 0.0:
        return 0.0
    y = x / m
    return m * math.sqrt(float(np.dot(y, y)))


class ChannelScan:
    """The quality of one channel from its raw samples fed in consecutive pieces: once
    (:meth:`feed`, :meth:`end`), or twice (:meth:`feed1`, :meth:`end1`, :meth:`feed2`).

    Twice: pass 1 accumulates the channel-wide statistics (extremes, strided subsamples,
    run-length counts: :class:`FlatScan`), pass 2 the runs at the rails and the candidate
    flat runs with the samples around them; :meth:`result` classifies them. The result
    equals that of the whole array (:func:`channel_quality`,
    :func:`meshphase.signal.condition.assess_quality`) whatever the pieces, in memory bounded
    by the subsamples plus ~2 * ``FLAT_WINDOW`` samples per candidate flat run (the faults
    found) and the run lists themselves.

    Once: :meth:`feed` does pass 1's work and, without the channel-wide statistics, pass
    2's: the runs at the running extremes (a new extreme drops the runs at the old one;
    infinities are always at the rails) and the candidate flat runs from the shortest
    length any threshold can be (``min(min_run, clip_min_run)``), at most
    :data:`SCAN_CANDIDATES` of them held (the shortest dropped first,
    :class:`FlatCandidates`). :meth:`end` then has what pass 2 would have found, exactly,
    unless ``rail_rtol`` is not 0 or more candidate runs reached the final threshold than
    were held: it returns False, and the second pass (:meth:`feed2`) is needed.

    Parameters
    ----------
    n : int
        Samples of the channel [-].
    flat : bool or None
        Look for dropouts and plateaus (:func:`flat_runs`); None: unless the channel is a
        pulse train (at most 8 distinct values among 4096 strided samples).
    rail_min_run : int
        Shortest run at the rails reported [samples] (:func:`clipped_runs`).
    rail_rtol : float
        Tolerance of "at the rail" relative to the range [-] (:func:`clipped_runs`).
    false_alarm, min_run, clip_min_run
        As :func:`flat_runs`.
    """

    def __init__(self, n: int, *, flat: bool | None = True, rail_min_run: int = 3,
                 rail_rtol: float = 0.0, false_alarm: float = FALSE_ALARM,
                 min_run: int = DROPOUT_MIN_RUN, clip_min_run: int = CLIP_MIN_RUN):
        self.n = as_count(n, "n", 0)
        self.flat = flat
        self.rail_min_run = as_count(rail_min_run, "rail_min_run", 2)
        self.rail_rtol = float(rail_rtol)
        self.fa = check_false_alarm(false_alarm)
        self.min_run = as_count(min_run, "min_run", 2)
        self.clip_min_run = as_count(clip_min_run, "clip_min_run", 2)
        self.nonfinite = RunTracker()
        self.nan = RunTracker()
        self.fscan = FlatScan(self.n)
        self.pulse: list | None = [] if flat is None else None   # the pulse-train test
        self.pulse_step = max(1, self.n // 4096)
        self.norm = 0.0          # Euclidean norm of the finite samples fed in pass 1
        self.pos1 = self.pos2 = 0
        self.stats: FlatStats | None = None
        self.rails = RunTracker()
        self.cand: FlatCandidates | None = None
        # the one-pass scan (feed): runs at the running extremes, candidates from the floor
        self.once = False
        self.run_hi = self.run_lo = None        # RunTrackers of x == running max / min
        self.run_inf = RunTracker()             # +-inf: at the rails whatever the extremes
        self.cand1: FlatCandidates | None = None

    def feed1(self, x: np.ndarray) -> None:
        """Pass 1: the next piece of float64 samples."""
        if self.stats is not None:
            raise RuntimeError("ChannelScan.feed1 after end1()")
        fin = np.isfinite(x)
        bad = ~fin
        self.nonfinite.add(bad)
        self.nan.add(np.isnan(x) if bad.any() else bad)
        self.fscan.add(x, fin)
        if self.pulse is not None:
            first = (-self.pos1) % self.pulse_step
            self.pulse.append(x[first::self.pulse_step])
        if x.size:
            self.norm = math.hypot(self.norm, _norm2(x[fin] if bad.any() else x))
        self.pos1 += x.size

    def feed(self, x: np.ndarray) -> None:
        """The one-pass scan: the next piece of float64 samples (pass 1's work and pass 2's
        at the running extremes; see the class notes)."""
        if not self.once:
            if self.pos1:
                raise RuntimeError("ChannelScan.feed after feed1(): one scan or the other")
            self.once = True
            self.run_hi, self.run_lo = RunTracker(), RunTracker()
            if self.flat is not False and self.n:
                self.cand1 = FlatCandidates(self.n, min(self.min_run, self.clip_min_run),
                                            cap=SCAN_CANDIDATES)
        hi0, lo0 = self.fscan.hi, self.fscan.lo
        self.feed1(x)
        if x.size == 0:
            return
        with np.errstate(over="ignore", invalid="ignore"):
            clean = math.isfinite(float(np.sum(x)))
        if clean:
            self.run_inf.skip(x.size)
        else:
            self.run_inf.add(np.isinf(x))
        for tr, old, new, attr in ((self.run_hi, hi0, self.fscan.hi, "run_hi"),
                                   (self.run_lo, lo0, self.fscan.lo, "run_lo")):
            if not math.isfinite(new):                  # no finite sample yet
                tr.skip(x.size)
            elif new != old:                            # a new extreme: runs at the old go
                fresh = RunTracker()
                fresh.skip(tr.n)
                fresh.add(x == new)
                setattr(self, attr, fresh)
            else:
                tr.add(x == new)
        if self.cand1 is not None:
            self.cand1.add(x)

    def end(self) -> bool:
        """End of the one-pass scan: True when it found what pass 2 would have (then
        :meth:`result`), False when the second pass (:meth:`feed2` of every piece again) is
        needed."""
        if not self.once:
            self.feed(np.empty(0))
        self.end1()
        st = self.stats
        complete = self.rail_rtol == 0.0
        # (a range beyond float64 makes rail_mask's tolerance NaN: no sample at a rail)
        if complete and st.n_fin and st.hi != st.lo and math.isfinite(st.hi - st.lo):
            runs = merge_runs(np.concatenate([self.run_hi.runs(), self.run_lo.runs(),
                                              self.run_inf.runs()]))
            self.rails = RunTracker()
            self.rails.done = [runs]
            self.rails.n = self.n
        if self.cand is not None:
            if self.cand1 is None:
                complete = False
            else:
                self.cand1.finish()
                complete = self.cand1.keep_at_least(st.min_candidate) and complete
                if complete:
                    self.cand = self.cand1
        self.cand1 = self.run_hi = self.run_lo = None
        if complete:
            self.pos2 = self.n
        else:
            self.rails = RunTracker()
            if self.cand is not None:
                self.cand = FlatCandidates(self.n, st.min_candidate)
        return complete

    def end1(self) -> None:
        """End of pass 1: the thresholds for pass 2."""
        if self.pos1 != self.n:
            raise ValueError(f"ChannelScan pass 1 fed {self.pos1} samples, the channel has {self.n}")
        self.stats = self.fscan.stats(false_alarm=self.fa, min_run=self.min_run,
                                      clip_min_run=self.clip_min_run)
        if self.flat is None:
            xs = np.concatenate(self.pulse) if self.pulse else np.empty(0)
            xs = xs[np.isfinite(xs)]
            self.flat = not (xs.size > 0 and np.unique(xs).size <= 8)
            self.pulse = None
        if self.n == 0:
            self.flat = False
        if self.flat:
            self.cand = FlatCandidates(self.n, self.stats.min_candidate)

    def feed2(self, x: np.ndarray) -> None:
        """Pass 2: the same pieces again."""
        if self.stats is None:
            raise RuntimeError("ChannelScan.feed2 before end1()")
        if self.pos2 >= self.n and x.size:
            raise RuntimeError("ChannelScan.feed2 after the scan found everything (end() "
                               "returned True)")
        st = self.stats
        if st.n_fin and st.hi != st.lo:
            self.rails.add(rail_mask(x, st.hi, st.lo, self.rail_rtol))
        if self.cand is not None:
            self.cand.add(x)
        self.pos2 += x.size

    def result(self) -> ScanResult:
        """The quality found, once both passes are complete."""
        if self.stats is None or self.pos2 != self.n:
            raise ValueError(f"ChannelScan: pass 2 fed {self.pos2} of {self.n} samples")
        st = self.stats
        rails = self.rails.runs()
        rails = rails[(rails[:, 1] - rails[:, 0]) >= self.rail_min_run]
        fr = None
        if self.cand is not None:
            self.cand.finish()
            runs, values, lookup = self.cand.result()
            fr = classify_flat_runs(lookup, runs, values, st)
        nf = st.n_fin
        return ScanResult(self.n, self.nonfinite.runs(), self.nan.runs(), rails, fr, nf,
                          st.lo if nf else float("nan"), st.hi if nf else float("nan"),
                          self.norm / math.sqrt(nf) if nf else float("nan"))
