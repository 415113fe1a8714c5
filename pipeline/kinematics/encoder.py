"""Shaft encoders and multi-pulse tachos: pulse-train edges as an angle observation.

An encoder (or a gear-tooth pick-up) on a shaft gives ``pulses_per_rev`` pulses per
revolution of that shaft. Its rising edges sit at equal shaft angles, so edge k fires at

    A = (P_shaft / pulses_per_rev) k + c            [mesh cycles]

with ``P_shaft`` the mesh cycles per revolution of the shaft
(:func:`meshphase.kinematics.shafts.shaft_cycles`, from the gear kinematics) and ``c`` an unknown
constant (which pulse is the index). That is the form of a carrier tacho's train
(:func:`meshphase.kinematics.trains.tacho_train`), sampled many times per revolution: a sun-shaft
encoder of 60 pulses on the seed rig (Z_s 25, Z_r 87, ring held) observes the mesh angle
every 25 x 87 / (112 x 60) = 0.32 mesh cycles and so sees a speed ripple at the planets'
spin rate that the gauges and a once-per-turn tacho cannot tell from the planets' own terms.

Array functions, no Recording:

* :func:`pulse_levels`: the low and high level of a two-level signal (medians of the two
  clusters, not the extremes: a spike does not move them);
* :func:`rising_crossings` / :func:`edge_times`: rising crossings of the level half-way
  between them, timed to a fraction of a sample by linear interpolation between the two
  samples that straddle it;
* :func:`clean_edges`: extra edges (glitches: an edge that puts its intervals off the pulse
  grid) dropped, missing edges (an interval of about k pulse periods) counted, so the pulse
  count k of every kept edge stays right (as MATLAB's ``tachorpm`` with its pulses per
  revolution), both reported in counts; :func:`split_at_gaps` cuts the train where too many
  pulses are missing in a row to count across (a dropout);
* :func:`meshphase.kinematics.trains.encoder_train` then makes the cleaned edges a
  :class:`~meshphase.kinematics.trains.PassTrain` of kind ``"tacho"`` (an angle train with a constant
  of its own and no planet terms), ``P_shaft`` from :func:`meshphase.kinematics.shafts.shaft_cycles`.

Nothing here depends on the angle model: the streamed scan (:mod:`meshphase.run.stream`) times
encoder edges with these functions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..recording import ENCODER_SHAFTS
from ..validate import as_finite_array, as_positive, as_positive_int, as_signal

__all__ = ["ENCODER_SHAFTS", "EncoderEdges", "shaft_of", "pulse_levels", "rising_crossing_parts", "rising_crossings",
           "edge_times", "clean_edges", "split_at_gaps", "edge_timing_sigma"]

#: an interval whose ratio to the local pulse period is further than this from a whole
#: number is off the pulse grid (an extra edge next to it) [-]
GRID_TOL = 0.25
#: intervals in the running median that sets the local pulse period [-]
PERIOD_WINDOW = 15
#: a gap of more than this many pulse periods is not counted across: the speed may have
#: changed by more than one pulse's worth over it (1 % in 8 periods is 0.08 of a pulse)
MAX_GAP_PULSES = 8


def shaft_of(shaft: str) -> str:
    """The gear member an encoder's ``shaft`` names: "input" is the sun.

    Raises
    ------
    ValueError
        ``shaft`` not one of :data:`ENCODER_SHAFTS` (the value is echoed).
    """
    if not isinstance(shaft, str) or shaft not in ENCODER_SHAFTS:
        raise ValueError(f"encoder shaft must be one of {ENCODER_SHAFTS}, got {shaft!r}")
    return "sun" if shaft == "input" else shaft


def edge_timing_sigma(fs: float) -> float:
    """One-sigma timing of an edge crossed between two samples [s]: 1 / (sqrt(12) fs).

    A sharp (TTL) edge is timed no better than to its sample: the crossing is uniform
    within one sample period, whose standard deviation is 1 / sqrt(12) of it.
    """
    return 1.0 / (math.sqrt(12.0) * as_positive(fs, "fs"))


def pulse_levels(x, *, iterations: int = 5) -> tuple[float, float]:
    """Low and high level of a two-level (pulse-train) signal [units of x].

    Two clusters split at a threshold that starts half-way between the 1st and 99th
    percentile and moves to half-way between the clusters' medians (a few rounds). Spikes
    and single glitches do not move a median, so the half level stays well inside the edges.

    Parameters
    ----------
    x : array_like, shape (n,)
        Samples (non-finite ones are ignored), e.g. a strided subsample of the channel.
    iterations : int
        Rounds of the split [-].

    Returns
    -------
    (low, high) : (float, float)

    Raises
    ------
    ValueError
        Fewer than 2 finite samples, or no two levels (every sample alike).
    """
    v = as_signal(x, "x", float64=True)
    v = v[np.isfinite(v)]
    if v.size < 2:
        raise ValueError(f"pulse_levels needs at least 2 finite samples, got {v.size}")
    lo_p, hi_p = np.percentile(v, [1.0, 99.0])
    if not hi_p > lo_p:
        lo_p, hi_p = float(v.min()), float(v.max())
    if not hi_p > lo_p:
        raise ValueError(f"pulse_levels: the signal has one level only ({lo_p!r}): no pulses")
    thr = 0.5 * (lo_p + hi_p)
    low = high = thr
    for _ in range(as_positive_int(iterations, "iterations")):
        below = v <= thr
        if below.all() or not below.any():
            break
        low, high = float(np.median(v[below])), float(np.median(v[~below]))
        thr = 0.5 * (low + high)
    if not high > low:
        raise ValueError(f"pulse_levels: no two levels in the signal (low {low!r}, high {high!r})")
    return low, high


def rising_crossing_parts(x, level, *, finite_only: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Where ``x`` rises through ``level``: the sample after each crossing and the crossing's
    fraction of the interval before it.

    The one crossing rule of the pulse trains: :func:`rising_crossings` (whole arrays) and the
    streamed tacho and encoder edges (:mod:`meshphase.run.stream`) both use it. A crossing lies
    between samples i - 1 (at or below the level) and i (above), at ``i - 1 + frac`` with
    ``frac = (level - x[i-1]) / (x[i] - x[i-1])`` (linear interpolation, clipped to [0, 1]).
    The arithmetic stays in ``x``'s floating dtype (float32 samples give float32 fractions).

    Parameters
    ----------
    x : array_like, shape (n,)
    level : float
        Threshold [units of x].
    finite_only : bool
        Leave out a crossing whose sample before is non-finite (a NaN or -inf run ending).

    Returns
    -------
    (ndarray of int, ndarray)
        ``i`` [samples] and ``frac`` [-], shape (m,) each.
    """
    v = as_signal(x, "x")
    if v.dtype.kind not in "f":
        v = v.astype(np.float64)
    b = v > level
    up = b[1:] & ~b[:-1]
    if finite_only:
        up &= np.isfinite(v[:-1])
    rise = np.flatnonzero(up) + 1
    x0, x1 = v[rise - 1], v[rise]
    with np.errstate(invalid="ignore", divide="ignore"):   # inf edges: frac unused
        frac = np.where(x1 > x0, (level - x0) / np.where(x1 > x0, x1 - x0, 1.0), 0.0)
    return rise, np.clip(frac, 0.0, 1.0)


def rising_crossings(x, level: float) -> np.ndarray:
    """Fractional sample indices where ``x`` rises through ``level`` [samples].

    A crossing lies between samples i - 1 (at or below the level) and i (above); its index is
    ``i - 1 + (level - x[i-1]) / (x[i] - x[i-1])`` (linear interpolation, clipped to the
    interval; :func:`rising_crossing_parts`). Non-finite samples never cross.

    Parameters
    ----------
    x : array_like, shape (n,)
    level : float
        Threshold [units of x].

    Returns
    -------
    ndarray, shape (m,)
    """
    v = as_signal(x, "x", float64=True)
    lev = float(level)
    if not math.isfinite(lev):
        raise ValueError(f"level must be finite, got {level!r}")
    rise, frac = rising_crossing_parts(v, lev)
    return rise - 1 + frac


def edge_times(x, fs: float, *, t0: float = 0.0, levels: tuple | None = None) -> np.ndarray:
    """Rising edges of a pulse-train channel [s], timed to a fraction of a sample.

    Parameters
    ----------
    x : array_like, shape (n,)
        Samples of the channel.
    fs : float
        Sample rate [Hz].
    t0 : float
        Time of sample 0 [s].
    levels : (float, float), optional
        Low and high level [units of x] (default :func:`pulse_levels` of ``x``); the edges
        cross half-way between them.

    Returns
    -------
    ndarray, shape (m,)
        Edge times [s], increasing (empty for fewer than 2 samples).
    """
    v = as_signal(x, "x", float64=True)
    fs = as_positive(fs, "fs")
    if v.size < 2:
        return np.empty(0)
    lo, hi = pulse_levels(v) if levels is None else (float(levels[0]), float(levels[1]))
    if not hi > lo:
        raise ValueError(f"levels must be (low, high) with high > low, got {levels!r}")
    return float(t0) + rising_crossings(v, 0.5 * (lo + hi)) / fs


@dataclass(frozen=True)
class EncoderEdges:
    """An encoder's edges after :func:`clean_edges`.

    Attributes
    ----------
    times : ndarray, shape (m,)
        Kept edge times [s], increasing.
    count : ndarray of int, shape (m,)
        Pulse count of each kept edge from the first (0) [-]; steps by k over k - 1
        missing edges.
    n_extra : int
        Edges dropped as off the pulse grid (glitches, chatter) [-].
    n_missing : int
        Edges missing between kept ones [-].
    period : float
        Median pulse period [s] (NaN for fewer than 2 edges).
    """

    times: np.ndarray
    count: np.ndarray
    n_extra: int
    n_missing: int
    period: float

    def __len__(self) -> int:
        return int(self.times.size)

    def summary(self) -> str:
        """``"2183 edges, 2 extra dropped, 3 missing counted"``."""
        return (f"{self.times.size} edges, {self.n_extra} extra dropped, {self.n_missing} missing "
                "counted")


def _local_period(t: np.ndarray) -> np.ndarray:
    """Running median of the intervals of ``t`` over :data:`PERIOD_WINDOW` [s] (the global
    median for shorter trains), per interval."""
    d = np.diff(t)
    w = PERIOD_WINDOW
    if d.size < w:
        return np.full(d.size, np.median(d) if d.size else np.nan)
    pad = np.pad(d, (w // 2, w - 1 - w // 2), mode="reflect")
    return np.median(np.lib.stride_tricks.sliding_window_view(pad, w), axis=1)


def _off_grid(r: np.ndarray, tol: float) -> np.ndarray:
    """Intervals (ratios to the local period) that are no whole number of periods >= 1."""
    k = np.rint(r)
    return (k < 1) | (np.abs(r - k) > tol)


def clean_edges(times, *, tol: float = GRID_TOL) -> EncoderEdges:
    """Drop extra edges and count missing ones of an encoder's edge train.

    The local pulse period is the running median of the intervals. An interval of about k
    periods (k >= 1, within ``tol``) steps the pulse count by k (k - 1 edges missing). An
    interval off that grid has an extra edge at one of its ends: of the two, the edge
    whose removal leaves the intervals around it nearer whole periods is dropped, until no
    interval is off the grid (only the few edges next to an off-grid interval are looked at
    one by one).

    Parameters
    ----------
    times : array_like, shape (m,)
        Rising edge times [s], strictly increasing (:func:`edge_times`).
    tol : float
        Largest distance of an interval's period ratio from a whole number [-] (0 < tol <
        0.5).

    Returns
    -------
    EncoderEdges
    """
    t = as_finite_array(times, "times", ndim=1)
    if t.size > 1 and np.any(np.diff(t) <= 0):
        raise ValueError("times must be strictly increasing")
    tol = as_positive(tol, "tol")
    if tol >= 0.5:
        raise ValueError(f"tol must be below 0.5 (a whole number of periods), got {tol!r}")
    if t.size < 2:
        return EncoderEdges(t.copy(), np.zeros(t.size, dtype=np.int64), 0, 0,
                            float("nan"))
    period = _local_period(t)
    # the local period of each edge (the intervals' medians, carried to the edges), from
    # the original train: dropping an edge does not change the pulse period there
    p_edge = np.concatenate([period[:1], 0.5 * (period[:-1] + period[1:]), period[-1:]])
    keep = np.ones(t.size, bool)
    n_extra = 0
    bad = np.flatnonzero(_off_grid(np.diff(t) / period, tol))
    while bad.size:
        idx = np.flatnonzero(keep)
        tk = t[idx]
        pk = p_edge[idx]
        r = np.diff(tk) / pk[1:]
        bad = np.flatnonzero(_off_grid(r, tol))
        if not bad.size:
            break
        i = int(bad[0])                         # interval between kept edges i and i + 1
        cost = []
        for j in (i, i + 1):                   # drop kept edge j: the intervals around it
            a = tk[j - 1] if j > 0 else None
            b = tk[j + 1] if j + 1 < tk.size else None
            if a is not None and b is not None:
                rr = (b - a) / pk[j]
                cost.append(abs(rr - max(1.0, np.rint(rr))))
            else:
                cost.append(0.0)               # an end edge: dropping it leaves no interval
        drop = i if cost[0] <= cost[1] else i + 1
        keep[idx[drop]] = False
        n_extra += 1
        if np.count_nonzero(keep) < 2:
            break
    tk = t[keep]
    if tk.size < 2:
        return EncoderEdges(tk, np.zeros(tk.size, dtype=np.int64), n_extra, 0, float("nan"))
    steps = np.maximum(1, np.rint(np.diff(tk) / p_edge[keep][1:])).astype(np.int64)
    count = np.concatenate([[0], np.cumsum(steps)])
    return EncoderEdges(tk, count, n_extra, int(np.sum(steps - 1)), float(np.median(np.diff(t))))


def split_at_gaps(edges: EncoderEdges, max_gap: int = MAX_GAP_PULSES) -> list:
    """The cleaned edges cut where more than ``max_gap`` pulses are missing in a row.

    Across a long gap (a dropout of the channel) the pulse count is a guess: each piece is
    counted from its own first edge and joins the angle model with a constant of its own.

    Parameters
    ----------
    edges : EncoderEdges
    max_gap : int
        Largest count step kept within a piece [pulses] (>= 1).

    Returns
    -------
    list of EncoderEdges
        In time order; each piece's ``n_missing`` counts the edges missing inside it, the
        first piece carries ``n_extra``; no piece for an empty train.
    """
    if not isinstance(edges, EncoderEdges):
        raise TypeError(f"edges must be EncoderEdges (clean_edges), got {type(edges).__name__}")
    max_gap = as_positive_int(max_gap, "max_gap")
    if len(edges) == 0:
        return []
    step = np.diff(edges.count)
    cuts = np.flatnonzero(step > max_gap) + 1
    out = []
    starts, stops = np.concatenate([[0], cuts]), np.concatenate([cuts, [len(edges)]])
    for q, (a, b) in enumerate(zip(starts, stops)):
        c = edges.count[a:b] - edges.count[a]
        out.append(EncoderEdges(edges.times[a:b], c, edges.n_extra if q == 0 else 0,
                                int(c[-1] + 1 - c.size), edges.period))
    return out

