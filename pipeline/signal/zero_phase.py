"""The gap-aware zero-phase IIR filter as a block filter, and its gap rules.

:class:`ZeroPhase` runs second-order sections forwards and backwards
(:func:`meshphase.signal.iir.sosfiltfilt`) over samples pushed in blocks
(:mod:`meshphase.signal.blocks`): each window it filters overlaps the samples it keeps by
:func:`filter_overlap` samples on both sides, so that what it emits equals the filter of the
whole signal to ~1e-13 of its amplitude; given the whole signal in one push it IS the filter
of the whole signal (:func:`meshphase.signal.condition.filter_signal` and
:func:`~meshphase.signal.condition.notch_hum` are that). :func:`apply_finite` is how every
window treats its gaps: short interior non-finite runs bridged by linear interpolation,
long ones splitting the window into segments filtered independently, every non-finite
input sample NaN on output; :func:`finite_apply_gaps` tells the output's gaps from the
input's without the samples.
"""

from __future__ import annotations

import math
import warnings
from typing import Callable

import numpy as np

from ..errors import DataQualityWarning
from . import iir
from .runs import find_runs, merge_runs

__all__ = ["ZeroPhase", "apply_finite", "finite_apply_gaps", "filter_overlap", "push_pair",
           "DECAY", "FILL_MAX", "CHUNK"]

#: Decay of the slowest filter pole over the overlap of two filter windows [-].
DECAY = 1e-15
#: Longest interior gap bridged by interpolation for the filter [samples].
FILL_MAX = 8
#: Samples a block filter emits at a time, at least, once its look-ahead is there [-].
CHUNK = 1 << 18


def _short_signal_message(what: str, n: int, min_len: int) -> str:
    return (f"{what}: signal of {n} sample(s) is shorter than the {min_len} the filter needs; "
            "returned as NaN")


def _short_segments_message(what: str, n_short: int, min_len: int) -> str:
    return (f"{what}: {n_short} finite segment(s) between gaps are shorter than the {min_len} "
            "samples the filter needs; they are set to NaN")


def apply_finite(x: np.ndarray, func: Callable[[np.ndarray], np.ndarray], *, min_len: int,
                 fill_max: int, what: str, warn: bool = True) -> np.ndarray:
    """Apply ``func`` to the finite parts of ``x`` without smearing NaN.

    Parameters
    ----------
    x : ndarray of float64, shape (n,)
        Samples [any unit]; NaN/inf mark gaps.
    func : callable(ndarray) -> ndarray
        The filter of one finite segment (same length out).
    min_len : int
        Shortest segment ``func`` takes [samples]; shorter ones become NaN.
    fill_max : int
        Interior non-finite runs of at most this many samples are bridged by linear
        interpolation [samples]; longer runs split ``x`` into segments processed
        independently.
    what : str
        Name of the filter in warnings.
    warn : bool
        Issue a :class:`~meshphase.errors.DataQualityWarning` for segments set to NaN.

    Returns
    -------
    ndarray of float64, shape (n,)
        Every sample non-finite on input is NaN on output.
    """
    n = x.size
    if n == 0:
        return np.empty(0, dtype=np.float64)
    if math.isfinite(float(np.sum(x))):
        if n < min_len:
            if warn:
                warnings.warn(_short_signal_message(what, n, min_len), DataQualityWarning,
                              stacklevel=3)
            return np.full(n, np.nan)
        return func(x)
    bad = ~np.isfinite(x)
    runs = find_runs(bad)
    lengths = runs[:, 1] - runs[:, 0]
    interior = (runs[:, 0] > 0) & (runs[:, 1] < n)
    short = interior & (lengths <= fill_max)
    xf = x.copy()
    if short.any():
        marks = np.zeros(n + 1, dtype=np.int64)
        np.add.at(marks, runs[short, 0], 1)
        np.add.at(marks, runs[short, 1], -1)
        fill_idx = np.flatnonzero(np.cumsum(marks[:n]) > 0)
        good = np.flatnonzero(~bad)
        xf[fill_idx] = np.interp(fill_idx, good, x[good])
    split = runs[~short]
    # segments = complement of the long runs
    edges = np.concatenate([[0], split.ravel(), [n]]).reshape(-1, 2)
    out = np.full(n, np.nan)
    n_short = 0
    for a, b in edges:
        if b <= a:
            continue
        if b - a < min_len:
            n_short += 1
            continue
        out[a:b] = func(xf[a:b])
    if n_short and warn:
        warnings.warn(_short_segments_message(what, n_short, min_len), DataQualityWarning,
                      stacklevel=3)
    out[bad] = np.nan
    return out


def finite_apply_gaps(bad_runs, n: int, *, min_len: int, fill_max: int) -> tuple[np.ndarray, int, bool]:
    """The non-finite runs of the output of a gap-aware filter, from those of its input.

    What :func:`apply_finite` does to the gaps, without the samples: interior runs of at
    most ``fill_max`` samples are bridged (and non-finite again on output), longer runs split
    the signal, and finite segments shorter than ``min_len`` become NaN.

    Parameters
    ----------
    bad_runs : ndarray of int, shape (k, 2)
        Sorted, disjoint ``[start, stop)`` runs of non-finite input samples.
    n : int
        Samples [-].
    min_len, fill_max : int
        As the filter uses them [samples].

    Returns
    -------
    (runs, n_short, whole_short) : (ndarray, int, bool)
        Non-finite output runs (merged); the number of finite segments set to NaN; True when
        the input was finite throughout and shorter than ``min_len`` (the "signal shorter"
        case, one NaN run over everything).
    """
    r = np.asarray(bad_runs, dtype=np.int64).reshape(-1, 2)
    if n == 0:
        return np.empty((0, 2), dtype=np.int64), 0, False
    if len(r) == 0:
        if n < min_len:
            return np.array([[0, n]], dtype=np.int64), 0, True
        return np.empty((0, 2), dtype=np.int64), 0, False
    lengths = r[:, 1] - r[:, 0]
    interior = (r[:, 0] > 0) & (r[:, 1] < n)
    split = r[~(interior & (lengths <= fill_max))]
    edges = np.concatenate([[0], split.ravel(), [n]]).reshape(-1, 2)
    seg = edges[edges[:, 1] > edges[:, 0]]
    short = seg[(seg[:, 1] - seg[:, 0]) < min_len]
    return merge_runs(np.concatenate([r, short])), int(len(short)), False


def filter_overlap(sos: np.ndarray, *, decay: float = DECAY) -> int:
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


class ZeroPhase:
    """A gap-aware zero-phase filter (:func:`apply_finite` around
    :func:`meshphase.signal.iir.sosfiltfilt`) as a block filter.

    Parameters
    ----------
    sos : ndarray, shape (k, 6)
        Second-order sections.
    n_total : int
        Samples of the whole signal [-] (its end is a true edge, padded as the whole-signal
        filter pads it).
    what : str
        Name of the filter in messages.
    chunk : int
        Samples emitted per window at least, besides the overlap [-].
    fill_max : int
        Gap bridging (:func:`apply_finite`) [samples].
    engine : {"auto", "numba", "scipy"}
        Engine of :func:`meshphase.signal.iir.sosfiltfilt` (the same numbers); on
        ``"numba"`` a gap-free window goes to the kernel whole.
    warn : bool
        Warn (DataQualityWarning) about the segments a window sets to NaN: meant for a
        signal pushed whole (a window cut inside the data may hold a short segment at its
        artificial edge, in the overlap it does not emit: :meth:`through_gaps` tells the
        true ones).

    Notes
    -----
    :meth:`push` returns the samples final so far (a window is filtered once ``L`` =
    :attr:`L` samples of look-ahead beyond ``chunk`` new samples are there, or the end),
    :meth:`flush` the rest.
    """

    def __init__(self, sos: np.ndarray, n_total: int, *, what: str, chunk: int = CHUNK,
                 fill_max: int = FILL_MAX, engine: str = "scipy", warn: bool = False):
        self.sos = sos
        self.engine = engine
        self.padlen = iir.padlen_for(sos)
        self.min_len = self.padlen + 1
        self.fill_max = fill_max
        self.what = what
        self.warn = bool(warn)
        # the transient decays over L; bridging and padding of a gap at a window edge add
        # fill_max + padlen samples more before it starts
        self.L = filter_overlap(sos) + fill_max + self.padlen + 2
        self.chunk = max(int(chunk), 1)
        self.n = int(n_total)
        self.buf: list[np.ndarray] = []
        self.buf_start = 0
        self.buf_n = 0
        self.out_pos = 0

    def through_gaps(self, bad_runs: np.ndarray) -> tuple[np.ndarray, str | None]:
        """The runs that are NaN after this filter (``bad_runs`` before it, over the whole
        signal), and the warning the whole-signal filter gives about the stretches too
        short for it (None when there is none)."""
        out, n_short, whole = finite_apply_gaps(bad_runs, self.n, min_len=self.min_len,
                                                fill_max=self.fill_max)
        if whole:
            return out, _short_signal_message(self.what, self.n, self.min_len)
        if n_short:
            return out, _short_segments_message(self.what, n_short, self.min_len)
        return out, None

    def _func(self, s: np.ndarray) -> np.ndarray:
        return iir.sosfiltfilt(self.sos, s, padlen=self.padlen, engine=self.engine)

    def push(self, x: np.ndarray) -> np.ndarray:
        """The next samples ``x``; returns the filtered samples final so far."""
        if not self._add(x) or self.out_pos >= self.buf_start + self.buf_n:
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
        """The filtered samples not yet returned (the signal ended)."""
        if self.out_pos >= self.buf_start + self.buf_n:
            return np.empty(0)
        return self._run(True)

    def _window(self) -> np.ndarray:
        """The held samples as one float64 window (pieces pushed as float32 widened in the
        same copy that joins them; a single float64 piece as it is)."""
        if len(self.buf) == 1:
            return self.buf[0].astype(np.float64, copy=False)
        return np.concatenate(self.buf, dtype=np.float64)

    def _filtered(self, w: np.ndarray) -> np.ndarray:
        return apply_finite(w, self._func, min_len=self.min_len, fill_max=self.fill_max,
                            what=self.what, warn=self.warn)

    def _whole(self) -> bool:
        """Whether the due window may go to the numba kernel whole (then joined straight
        into the kernel's buffer): on that engine and long enough."""
        return self.engine == "numba" and self.buf_n >= self.min_len

    def _result(self) -> np.ndarray:
        """The due window filtered (what apply_finite gives on it)."""
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


def push_pair(a: ZeroPhase, xa: np.ndarray, b: ZeroPhase, xb: np.ndarray):
    """``(a.push(xa), b.push(xb))``, the two windows filtered in one sweep
    (:func:`meshphase.signal.iir.filter_extended_pair`) when both are due together, of one
    length, free of gaps and on the numba engine, with filters of one section count: the
    same numbers either way (the chains of two channels read in the same blocks are due
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
