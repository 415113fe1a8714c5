"""Engagement onsets of tooth-root strain pulses, to a fraction of a sample.

A strain gauge at a tooth root sees one pulse per engagement: a compressive lobe, a tensile
peak while the tooth carries load, a compressive lobe. This module finds those pulses and
times each one with a matched filter against a pulse template learnt from the recording.

Onset definition (amplitude independent)
----------------------------------------
Every pulse is timed by its best-fitting shift of the template (maximum of the
cross-correlation with the zero-mean template; amplitude and baseline drop out). The onset
is then a fixed feature *of the template*, carried over to each pulse by that shift:

- ``reference="rise"`` (default), ``level=0.5``: the leading-edge crossing of ``level``
  times the tensile peak height above the baseline (the leading-edge half-amplitude point);
  ``level`` closer to 0 approaches the contact start at the cost of a flatter, noisier edge.
- ``reference="peak"``: the tensile peak of the template.

A fixed threshold on the signal would walk with load and with each planet's share of it;
this feature does not: scaling a pulse changes its amplitude estimate, not its onset.
Phasing only uses differences of onsets within a pass, so the constant offset between this
feature and the physical contact start cancels.

Pipeline (per analysis block, vectorised)
-----------------------------------------
1. Block-mean decimation by ``D = max(1, floor(w / 16))`` (``w`` the tensile full width at
   half maximum in samples): at >= 16 samples per pulse width it keeps essentially all the
   timing information and makes the rest of the work ``D`` times cheaper.
2. Coarse detection: moving average over ``w / 2``, threshold ``median + k_sigma * noise``
   (MAD noise of the pulse-free parts: +-1.5 w around strong maxima masked, because pulses
   every ~8 widths would otherwise inflate a plain MAD), runs above it merged within
   ``min_spacing``, one maximum per run.
3. Template (re-)learning from the block's own clean pulses: windows around the coarse
   maxima, aligned to sub-sample precision against the running template (Fourier shifts)
   and averaged with least-squares amplitude weights; baseline 0, tensile peak 1, tapered.
   Its peak and level crossings are located by local least-squares fits (not by the noisy
   maximum), see ``_template_features``.
4. Refinement of every detection: correlation with the zero-mean template at lags
   ``-K..K`` in steps of ``1/U`` (one BLAS product with a Toeplitz matrix of shifted
   templates; ``U = ceil(4 / w_D)``, i.e. > 1 only for pulses a few samples wide, whose
   fractional shifts are band-limited FFT shifts) and parabolic interpolation of the
   correlation peak.

The first block also estimates ``w`` (autocorrelation, then the FWHM of a first template)
unless ``width`` or ``template`` is given; later blocks take ``w`` from the previous block's
template, so the detector follows slow speed changes. Blocks are processed with margins
and a fixed grid, so a recording fed whole or as a stream of chunks of any size gives
bit-identical onsets (:func:`detect_onsets_stream`).

Quality per onset: normalised correlation with the template, amplitude (signed, in data
units: the fitted tensile peak above baseline), width (FWHM measured on the pulse) and a
bit mask of flags (``FLAG_*``). No onset is ever placed inside a gap (NaN samples, or the
sample ranges passed as ``gap_runs``, e.g. DAQ dropouts that read zeros or a held value) or
outside the data; pulses whose window touches a gap or a flagged run are kept but flagged.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Iterable

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy import fft as sfft
from scipy import ndimage, signal

from .errors import DataQualityWarning, ProcessingWarning
from .log import logger
from .quality import find_runs
from .recording import Recording
from .validate import as_signal, as_choice, as_float, as_nonnegative, as_positive, as_positive_int

__all__ = [
    "Onsets", "Template", "CoarsePeaks", "detect_onsets", "detect_onsets_recording",
    "detect_onsets_stream", "OnsetStream", "learn_template", "coarse_peaks", "estimate_pulse_width",
    "FLAG_GAP", "FLAG_CLIPPED", "FLAG_LOW_CORR", "FLAG_EDGE", "FLAG_TEMPLATE", "FLAG_NAMES",
]

#: The pulse window overlaps (or lies within ``gap_guard`` of) a gap: non-finite samples or
#: a ``gap_runs`` range (a DAQ dropout from the quality report).
FLAG_GAP = 1
#: The pulse window overlaps a flagged run (clipping at a rail or a plateau at any level,
#: from the quality report).
FLAG_CLIPPED = 2
#: Normalised correlation with the template below ``min_corr``.
FLAG_LOW_CORR = 4
#: The pulse window runs past the data, or the correlation peak sits on the search limit.
FLAG_EDGE = 8
#: The block's template is a fallback (learnt from fewer than ``min_template_pulses`` pulses
#: or re-used from an earlier block).
FLAG_TEMPLATE = 16
FLAG_NAMES = {FLAG_GAP: "gap", FLAG_CLIPPED: "clipped", FLAG_LOW_CORR: "low_corr",
              FLAG_EDGE: "edge", FLAG_TEMPLATE: "template"}

_MAD_TO_SIGMA = 1.482602218505602
_SAMPLES_PER_WIDTH = 16      # decimate so that the pulse FWHM keeps >= 16 samples
_HALF_LENGTH = 3.0           # template half-length [FWHM]
_TAPER = 0.2                 # Tukey taper fraction of the template
_SUBLAG_TARGET = 4.0        # sub-lag grid: U = ceil(4 / FWHM) steps per sample (>= 4 per FWHM)
_AUTOCORR_TO_FWHM = 1.6      # FWHM ~ 1.6 x lag where the autocorrelation halves (raised cosine)
_WIDTH_SAMPLES = 1 << 20     # samples entering the width estimate
_DEFAULT_BLOCK = 1 << 20     # analysis block [samples] when ``block`` is None


# ====================================================================== result types
@dataclass(frozen=True, eq=False)
class Template:
    """A pulse template learnt from a recording (or given).

    Attributes
    ----------
    samples : ndarray of float64, shape (L,)
        Pulse shape at the decimated rate ``fs / decimation``, baseline 0, tensile peak 1,
        polarity-corrected (tension positive), Tukey-tapered at its ends.
    fs : float
        Sample rate of the recording [Hz].
    decimation : int
        Block-mean decimation factor D of the template samples [-].
    peak : float
        Position of the tensile maximum [template samples].
    ref : float
        Position of the onset feature [template samples].
    fwhm : float
        Full width at half maximum of the tensile lobe [s].
    reference : str
        "rise" or "peak" (see the module docstring).
    level : float
        Level of the "rise" feature, fraction of the peak height [-].
    n_pulses : int
        Pulses averaged [-].
    polarity : int
        +1 when tension reads positive in the data, -1 otherwise.
    """

    samples: np.ndarray
    fs: float
    decimation: int
    peak: float
    ref: float
    fwhm: float
    reference: str = "rise"
    level: float = 0.5
    n_pulses: int = 0
    polarity: int = 1

    @property
    def rate(self) -> float:
        """Sample rate of the template samples, fs / decimation [Hz]."""
        return self.fs / self.decimation

    @property
    def ref_after_peak(self) -> float:
        """Time from the tensile peak to the onset feature [s] (negative for "rise")."""
        return (self.ref - self.peak) / self.rate

    def to_dict(self) -> dict:
        """JSON-friendly dict."""
        return {"samples": self.samples.tolist(), "fs": self.fs, "decimation": self.decimation,
                "peak": self.peak, "ref": self.ref, "fwhm": self.fwhm,
                "reference": self.reference, "level": self.level, "n_pulses": self.n_pulses,
                "polarity": self.polarity}


@dataclass(frozen=True, eq=False)
class CoarsePeaks:
    """Coarse pulse maxima (:func:`coarse_peaks`).

    Attributes
    ----------
    index : ndarray of int64
        Full-rate sample index of each smoothed maximum (relative to the first sample).
    height : ndarray of float64
        Smoothed height above the median, polarity-corrected [data units].
    threshold : float
        Detection threshold above the median [data units].
    noise : float
        Robust noise level of the smoothed signal [data units].
    decimation : int
        Decimation used [-].
    """

    index: np.ndarray
    height: np.ndarray
    threshold: float
    noise: float
    decimation: int

    def __len__(self) -> int:
        return int(self.index.size)


@dataclass(frozen=True, eq=False)
class Onsets:
    """Engagement onsets of one channel, with per-onset quality.

    Attributes
    ----------
    times : ndarray of float64, shape (n,)
        Onset times [s] on the recording's time axis (``t0 + index / fs``), increasing.
    index : ndarray of float64, shape (n,)
        Fractional sample index of each onset, relative to the first sample [samples].
    corr : ndarray of float64, shape (n,)
        Normalised correlation of the pulse with the template [-], in [-1, 1].
    amplitude : ndarray of float64, shape (n,)
        Fitted tensile peak above baseline, signed, in data units (e.g. strain [m/m]).
    width : ndarray of float64, shape (n,)
        Tensile full width at half maximum measured on the pulse [s] (noisy at low SNR).
    flags : ndarray of uint8, shape (n,)
        Bit mask of ``FLAG_*`` values; 0 for a clean onset.
    template_id : ndarray of int32, shape (n,)
        Index into ``templates`` of the template that timed each onset.
    templates : tuple of Template
        Templates in use, one per analysis block that had pulses (repeated objects when a
        block re-used an earlier one).
    fs : float
        Sample rate [Hz].
    t0 : float
        Time of sample 0 [s].
    channel : str or None
    reference : str
    level : float
    """

    times: np.ndarray
    index: np.ndarray
    corr: np.ndarray
    amplitude: np.ndarray
    width: np.ndarray
    flags: np.ndarray
    template_id: np.ndarray
    templates: tuple = ()
    fs: float = float("nan")
    t0: float = 0.0
    channel: str | None = None
    reference: str = "rise"
    level: float = 0.5

    def __post_init__(self):
        n = self.times.size
        for name in ("index", "corr", "amplitude", "width", "flags", "template_id"):
            if getattr(self, name).shape != (n,):
                raise ValueError(f"Onsets.{name} must have shape ({n},), got {getattr(self, name).shape}")

    def __len__(self) -> int:
        return int(self.times.size)

    @property
    def good(self) -> np.ndarray:
        """Boolean mask of onsets without any flag."""
        return self.flags == 0

    def has_flag(self, flag: int) -> np.ndarray:
        """Boolean mask of onsets carrying ``flag`` (one of the ``FLAG_*`` values)."""
        return (self.flags & np.uint8(flag)) != 0

    def select(self, mask) -> "Onsets":
        """Onsets where ``mask`` (boolean or integer index array) selects."""
        m = np.asarray(mask)
        return Onsets(self.times[m], self.index[m], self.corr[m], self.amplitude[m],
                      self.width[m], self.flags[m], self.template_id[m], self.templates,
                      self.fs, self.t0, self.channel, self.reference, self.level)

    def flag_counts(self) -> dict:
        """Number of onsets carrying each flag, by flag name."""
        return {name: int(np.count_nonzero(self.flags & np.uint8(f))) for f, name in FLAG_NAMES.items()}

    def summary(self) -> dict:
        """Counts and medians, JSON-friendly."""
        def med(a):
            return float(np.median(a)) if a.size else None
        return {"channel": self.channel, "n": len(self), "n_good": int(self.good.sum()),
                "flags": self.flag_counts(), "median_corr": med(self.corr),
                "median_amplitude": med(self.amplitude), "median_width_s": med(self.width),
                "n_templates": len(self.templates), "reference": self.reference,
                "level": self.level}


def _empty_onsets(fs, t0, channel, reference, level, templates=()) -> Onsets:
    f = np.empty(0, dtype=np.float64)
    return Onsets(f, f.copy(), f.copy(), f.copy(), f.copy(), np.empty(0, dtype=np.uint8),
                  np.empty(0, dtype=np.int32), tuple(templates), fs, t0, channel, reference, level)


# ====================================================================== array helpers
def _decimate(seg: np.ndarray, d: int) -> np.ndarray:
    """Block means of ``d`` samples (trailing partial block dropped).

    Summing the ``d`` strided columns is ~5x faster than ``reshape(-1, d).mean(axis=1)``
    for small ``d`` (no per-row reduction overhead).
    """
    if d == 1:
        return seg
    v = seg[:(seg.size // d) * d].reshape(-1, d)
    acc = v[:, 0].copy()
    for j in range(1, d):                       # d columns, each a vectorised pass
        acc += v[:, j]
    acc *= 1.0 / d
    return acc


def _noise_level(y: np.ndarray, w: float) -> tuple[float, float, float]:
    """Baseline and noise standard deviation of a pulse train ``y`` (pulse FWHM ``w``
    samples), robust to pulses covering most of the samples.

    The MAD of a dense pulse train measures the pulses, not the noise (pulses a few samples
    wide, every ~8 widths, leave ~40 % of the samples pulse-free). So: on up to two
    contiguous pieces of 8192 samples (first and last), mask +-1.5 w (tensile lobe) around every local maximum above
    median + 3 sigma, re-estimate median and MAD-sigma from the rest, and repeat once.
    Pure noise loses ~1 % of its samples to the mask (sigma biased low by ~1 %).
    Returns (median, sigma, maximum of the pieces).
    """
    n = y.size
    if n == 0:
        return 0.0, 0.0, 0.0
    piece = 1 << 13
    if n <= 2 * piece:
        pieces = [y]
    else:
        starts = np.linspace(0, n - piece, 2).astype(np.int64)
        pieces = [y[a:a + piece] for a in starts]
    h = int(math.ceil(1.5 * w)) + 1
    rest = []
    # a gap filled with one constant (see _fill_nan) carries no noise: leave constant runs
    # out of the pieces, else a gap at the start or end collapses the MAD (and the threshold)
    def _live(p):
        if p.size < 3:
            return p
        flat = np.concatenate([[False], np.diff(p) == 0])
        flat[:-1] |= flat[1:]
        return p if not flat.any() else p[~flat]
    pieces = [q for q in (_live(p) for p in pieces) if q.size >= 16]
    if not pieces:
        live = _live(y)
        pieces = [live if live.size >= 3 else y]
    for p in pieces:                                  # <= 4 pieces
        med = float(np.median(p))
        sig = float(_MAD_TO_SIGMA * np.median(np.abs(p - med)))
        keep = np.ones(p.size, dtype=bool)
        for _ in range(2):
            if p.size < 3 or not sig > 0:
                break
            q = p[1:-1]
            mx = np.flatnonzero((q > med + 3.0 * sig) & (q >= p[:-2]) & (q > p[2:])) + 1
            for hh in (h, max(1, h // 2)):         # narrower mask for very dense trains
                marks = (np.bincount(np.clip(mx - hh, 0, p.size), minlength=p.size + 1)
                         - np.bincount(np.clip(mx + hh + 1, 0, p.size), minlength=p.size + 1))
                new_keep = np.cumsum(marks[:-1]) == 0
                if new_keep.sum() >= 0.05 * p.size:
                    break
            if new_keep.sum() < 0.05 * p.size:
                break
            keep = new_keep
            r = p[keep]
            med = float(np.median(r))
            sig = float(_MAD_TO_SIGMA * np.median(np.abs(r - med)))
        rest.append(p[keep])
    r = np.concatenate(rest) if len(rest) > 1 else rest[0]
    med = float(np.median(r))
    top = max(float(p.max()) for p in pieces)
    return med, float(_MAD_TO_SIGMA * np.median(np.abs(r - med))), top


def _runs_overlap(a: np.ndarray, b: np.ndarray, runs: np.ndarray) -> np.ndarray:
    """For intervals [a, b): does any of the sorted, disjoint ``runs`` overlap it?"""
    if len(runs) == 0 or a.size == 0:
        return np.zeros(a.size, dtype=bool)
    j = np.searchsorted(runs[:, 0], b, side="left") - 1
    ok = j >= 0
    out = np.zeros(a.size, dtype=bool)
    out[ok] = runs[j[ok], 1] > a[ok]
    return out


def _inside_runs(x: np.ndarray, runs: np.ndarray) -> np.ndarray:
    """Is the (fractional) position ``x`` inside one of the sorted, disjoint ``runs``?"""
    if len(runs) == 0 or x.size == 0:
        return np.zeros(x.size, dtype=bool)
    j = np.searchsorted(runs[:, 0], x, side="right") - 1
    ok = j >= 0
    out = np.zeros(x.size, dtype=bool)
    out[ok] = x[ok] < runs[j[ok], 1]
    return out


def _merge(runs: np.ndarray) -> np.ndarray:
    r = np.asarray(runs, dtype=np.int64).reshape(-1, 2)
    if len(r) == 0:
        return np.empty((0, 2), dtype=np.int64)
    r = r[np.argsort(r[:, 0], kind="stable")]
    ends = np.maximum.accumulate(r[:, 1])
    new = np.ones(len(r), dtype=bool)
    new[1:] = r[1:, 0] > ends[:-1]
    return np.stack([r[new, 0], np.maximum.reduceat(r[:, 1], np.flatnonzero(new))], axis=1)


def _shifted_rows(h: np.ndarray, shifts: np.ndarray, out_len: int) -> np.ndarray:
    """Rows ``r_i[t] = h(t - shifts[i])`` for t = 0..out_len-1 (band-limited, zero outside).

    Integer shifts are exact placements; fractional ones use an FFT phase ramp on a
    zero-padded copy of ``h`` (h is tapered to zero at its ends, so the padding is clean).
    """
    shifts = np.asarray(shifts, dtype=np.float64)
    out = np.zeros((shifts.size, out_len))
    integer = np.abs(shifts - np.round(shifts)) < 1e-12
    for i in np.flatnonzero(integer):           # a handful of columns, not samples
        s = int(round(shifts[i]))
        lo, hi = max(0, s), min(out_len, s + h.size)
        if hi > lo:
            out[i, lo:hi] = h[lo - s:hi - s]
    frac = np.flatnonzero(~integer)
    if frac.size:
        pad = 16
        p = sfft.next_fast_len(out_len + h.size + 2 * pad)
        buf = np.zeros(p)
        buf[pad:pad + h.size] = h
        spec = sfft.rfft(buf)
        f = np.arange(spec.size) / p
        ph = np.exp(-2j * np.pi * f[None, :] * (shifts[frac, None] - pad))
        rows = sfft.irfft(spec[None, :] * ph, p, axis=1)
        out[frac] = rows[:, :out_len]
    return out


def _frac_advance(w: np.ndarray, frac: np.ndarray) -> np.ndarray:
    """Rows advanced by ``frac`` samples, ``out_i[t] = w_i(t + frac_i)`` (band-limited).

    A straight line through each row's end points is removed before the FFT and restored
    after (shifted exactly), so the circular transform sees no jump at the ends.
    """
    n = w.shape[1]
    t = np.arange(n, dtype=np.float64)
    slope = (w[:, -1] - w[:, 0]) / max(n - 1, 1)
    line = w[:, :1] + slope[:, None] * t[None, :]
    r = w - line
    p = sfft.next_fast_len(2 * n)
    spec = sfft.rfft(r, p, axis=1)
    f = np.arange(spec.shape[1]) / p
    out = sfft.irfft(spec * np.exp(2j * np.pi * f[None, :] * frac[:, None]), p, axis=1)[:, :n]
    return out + line + slope[:, None] * frac[:, None]


def _col_sum(w: np.ndarray, cols) -> np.ndarray:
    """Sum of the given columns of each row: a loop over the (few) columns, which avoids
    numpy's per-row reduction overhead on short rows."""
    acc = np.zeros(w.shape[0])
    for j in cols:
        acc += w[:, j]
    return acc


def _window_baseline(w: np.ndarray) -> np.ndarray:
    """Mean of the outer 10 % of each row at both ends."""
    n = w.shape[1]
    e = max(1, n // 10)
    return _col_sum(w, list(range(e)) + list(range(n - e, n))) / (2 * e)


def _crossing_left(y: np.ndarray, start: int, level: float) -> float:
    """Last position left of ``start`` where ``y`` rises through ``level`` (linear interp)."""
    below = np.flatnonzero(y[:start + 1] < level)
    if below.size == 0:
        return float("nan")
    k = int(below[-1])
    if k + 1 > start:
        return float("nan")
    return k + (level - y[k]) / (y[k + 1] - y[k])


def _crossing_right(y: np.ndarray, start: int, level: float) -> float:
    below = np.flatnonzero(y[start:] < level)
    if below.size == 0:
        return float("nan")
    k = start + int(below[0])
    return k - 1 + (y[k - 1] - level) / (y[k - 1] - y[k])


# ====================================================================== template building
def _template_features(h: np.ndarray, reference: str, level: float):
    """(peak, ref, fwhm) of a normalised template [template samples]; NaN when not found.

    Templates >= 8 samples wide (all decimated ones) are measured by least-squares fits,
    which average the template's residual noise instead of picking its extremes: a
    quadratic over the top +-w/4 for the peak and its height, and a local quadratic over
    +-w/8 around each level crossing (found first on a Savitzky-Golay smoothed copy).
    Picking the noisy maximum and the last noisy crossing instead biased the onset late by
    ~0.8 Cramer-Rao standard deviations at 10 dB. Narrower templates (pulses a few samples
    wide, high SNR needed anyway) use band-limited upsampling and linear interpolation.
    """
    i0 = int(np.argmax(h))
    # FWHM in samples, roughly, to choose the method
    l0, r0 = _crossing_left(h, i0, 0.5), _crossing_right(h, i0, 0.5)
    w0 = (r0 - l0) if np.isfinite(l0) and np.isfinite(r0) else 4.0
    if w0 >= 8.0:
        return _features_fit(h, i0, w0, reference, level)
    u = int(min(32, max(1, math.ceil(64.0 / max(w0, 1.0)))))
    if u > 1:
        pad = 8
        buf = np.concatenate([np.zeros(pad), h, np.zeros(pad)])
        hu = signal.resample(buf, buf.size * u)
        off = pad * u
    else:
        hu, off = h, 0
    k = int(np.argmax(hu))
    if 0 < k < hu.size - 1:
        y0, y1, y2 = hu[k - 1], hu[k], hu[k + 1]
        den = y0 - 2 * y1 + y2
        dk = 0.5 * (y0 - y2) / den if den < 0 else 0.0
        top = y1 - 0.25 * (y0 - y2) * dk
    else:
        dk, top = 0.0, hu[k]
    peak = (k + dk - off) / u
    left = _crossing_left(hu, k, 0.5 * top)
    right = _crossing_right(hu, k, 0.5 * top)
    fwhm = (right - left) / u if np.isfinite(left) and np.isfinite(right) else float("nan")
    if reference == "peak":
        ref = peak
    else:
        c = _crossing_left(hu, k, level * top)
        ref = (c - off) / u if np.isfinite(c) else float("nan")
    return float(peak), float(ref), float(fwhm)


def _features_fit(h: np.ndarray, i0: int, w0: float, reference: str, level: float):
    n = h.size
    m = max(2, int(round(w0 / 4)))
    c = float(i0)
    top = float(h[i0])
    for _ in range(3):                                # re-centre the quadratic on its vertex
        lo, hi = max(0, int(round(c)) - m), min(n, int(round(c)) + m + 1)
        t = np.arange(lo, hi) - c
        a2, a1, a0 = np.polyfit(t, h[lo:hi], 2)
        if not a2 < 0:
            break
        v = float(np.clip(-a1 / (2 * a2), -m, m))
        c, top = c + v, float(a0 - a1 * a1 / (4 * a2))
        if abs(v) < 0.05:
            break
    hs = signal.savgol_filter(h, min(n - (1 - n % 2), 2 * m + 1), 3)
    k = int(round(c))
    m2 = max(2, int(round(w0 / 8)))

    def cross(lvl, side):
        g = _crossing_left(hs, k, lvl) if side < 0 else _crossing_right(hs, k, lvl)
        if not np.isfinite(g):
            return float("nan")
        lo, hi = max(0, int(round(g)) - m2), min(n, int(round(g)) + m2 + 1)
        t = np.arange(lo, hi, dtype=np.float64) - g
        q2, q1, q0 = np.polyfit(t, h[lo:hi], 2)
        # root of q2 t^2 + q1 t + q0 = lvl nearest to g (the edge is monotonic there)
        if q1 * side >= 0:
            return float(g)
        if abs(q2) < 1e-12 * abs(q1):
            return float(g + (lvl - q0) / q1)
        disc = q1 * q1 - 4 * q2 * (q0 - lvl)
        if disc < 0:
            return float(g)
        r = np.array([(-q1 + math.sqrt(disc)) / (2 * q2), (-q1 - math.sqrt(disc)) / (2 * q2)])
        r = r[np.argmin(np.abs(r))]
        return float(g + r) if abs(r) <= m2 else float(g)

    left, right = cross(0.5 * top, -1), cross(0.5 * top, +1)
    fwhm = right - left if np.isfinite(left) and np.isfinite(right) else float("nan")
    ref = c if reference == "peak" else cross(level * top, -1)
    return float(c), float(ref), float(fwhm)


def _normalise(h: np.ndarray) -> np.ndarray | None:
    e = max(1, h.size // 10)
    base = 0.5 * (h[:e].mean() + h[-e:].mean())
    h = h - base
    top = h.max()
    if not top > 0:
        return None
    return (h / top) * signal.windows.tukey(h.size, _TAPER)


class _Matcher:
    """Correlation machinery for one template: a Toeplitz matrix of (sub-)lagged copies.

    The window of a pulse (``L + 2K`` samples, template length ``L``) is correlated with
    the zero-mean template at lags ``-K .. K`` in steps of ``1/U`` by one matrix product;
    the columns for fractional lags are band-limited (FFT) shifts of the template.
    """

    def __init__(self, tpl: Template, k: int, u: int):
        h = tpl.samples
        self.h = h
        self.L = h.size
        self.h0 = h - h.mean()
        self.e0 = float(self.h0 @ self.h0)
        self.k = int(k)
        self.u = int(u)
        self.anchor = int(round(tpl.peak))
        lags = np.arange(-self.k * self.u, self.k * self.u + 1) / self.u
        # column j: template placed at window position K + lags[j]
        self.t_all = _shifted_rows(self.h0, self.k + lags, self.L + 2 * self.k).T.copy()
        self.ncol = lags.size
        self.tensile = h > 0.1
        self.ones = np.ones(self.L)

    def match(self, w: np.ndarray):
        """Best lag (fractional, relative to K), peak correlation, NCC, edge flag, the
        integer-aligned window and its mean, per row of ``w`` (shape (n, L + 2K))."""
        n = w.shape[0]
        k, L, u, ncol = self.k, self.L, self.u, self.ncol
        c = w @ self.t_all                                    # (n, ncol)
        j = np.argmax(c, axis=1)
        edge = (j == 0) | (j == ncol - 1)
        jc = np.clip(j, 1, ncol - 2)
        rows = np.arange(n)
        flat = c.ravel()
        b = rows * ncol + jc
        y0, y1, y2 = flat[b - 1], flat[b], flat[b + 1]
        den = y0 - 2.0 * y1 + y2
        with np.errstate(divide="ignore", invalid="ignore"):
            d = np.where(den < 0, 0.5 * (y0 - y2) / den, 0.0)
        d = np.clip(d, -1.0, 1.0)
        lag = (jc - k * u + d) / u
        cmax = y1 - 0.25 * (y0 - y2) * d
        # NCC and pulse width on the window at the nearest integer lag (one gather)
        mi = np.clip(np.rint(lag).astype(np.int64) + k, 0, 2 * k)
        wa = sliding_window_view(w, L, axis=1)[rows, mi]
        s1 = wa @ self.ones                       # BLAS gemv: row sums without per-row overhead
        var_l = np.maximum(np.einsum("ij,ij->i", wa, wa) - s1 * s1 / L, 0.0)
        norm = np.sqrt(var_l * self.e0)
        with np.errstate(divide="ignore", invalid="ignore"):
            ncc = np.clip(np.where(norm > 0, cmax / norm, 0.0), -1.0, 1.0)
        return lag, cmax, ncc, edge, wa, s1 / L


def _gather(y: np.ndarray, start: np.ndarray, length: int) -> tuple[np.ndarray, np.ndarray]:
    """Rows y[start_i + 0..length-1] and whether the row ran past the data (those rows
    repeat the edge sample)."""
    out_of = (start < 0) | (start + length > y.size)
    if y.size < length:
        idx = np.clip(start[:, None] + np.arange(length)[None, :], 0, max(y.size - 1, 0))
        return y[idx], np.ones(start.size, dtype=bool)
    rows = sliding_window_view(y, length)[np.clip(start, 0, y.size - length)]
    if out_of.any():
        bad = np.flatnonzero(out_of)
        idx = np.clip(start[bad, None] + np.arange(length)[None, :], 0, y.size - 1)
        rows[bad] = y[idx]
    return rows, out_of


def _learn_dec(yd: np.ndarray, peaks: np.ndarray, *, fs: float, d: int, w_d: float,
               reference: str, level: float, polarity: int, max_pulses: int, n_align: int,
               min_corr: float, max_half: int | None = None) -> Template | None:
    """Learn a template from decimated data ``yd`` around coarse maxima ``peaks``.

    The template spans +-3 FWHM, but never more than half the usual distance between
    pulses (``max_half`` [decimated samples]): a template reaching into the neighbouring
    pulses (planets a few mesh periods apart) learns their tails and times every pulse
    worse (five planets, sun gauge: 1.6x the Cramer-Rao bound before the cap, 1.2x after)."""
    h_half = max(4, int(math.ceil(_HALF_LENGTH * w_d)))
    if max_half is not None:
        h_half = max(4, min(h_half, int(max_half)))
    k = int(math.ceil(0.5 * w_d)) + 2
    L = 2 * h_half + 1
    start = peaks - h_half - k
    ok = (start >= 0) & (start + L + 2 * k <= yd.size)
    peaks = peaks[ok]
    if peaks.size == 0:
        return None
    if peaks.size > max_pulses:
        peaks = peaks[np.round(np.linspace(0, peaks.size - 1, max_pulses)).astype(np.int64)]
    w, _ = _gather(yd, peaks - h_half - k, L + 2 * k)
    w = w - _window_baseline(w)[:, None]
    c0 = w[:, k:k + L]
    centre = slice(max(0, h_half - int(w_d)), h_half + int(w_d) + 1)
    a0 = c0[:, centre].max(axis=1)
    if not np.any(a0 > 0):
        return None
    h = _normalise((a0[:, None] * c0).sum(axis=0) / float(a0 @ a0))
    if h is None:
        return None
    u = int(min(16, max(1, math.ceil(_SUBLAG_TARGET / max(w_d, 1.0)))))
    n_used = peaks.size
    for _ in range(n_align):
        tpl = Template(h, fs, d, float(h_half), float(h_half), float("nan"))
        mt = _Matcher(tpl, k, u)
        lag, cmax, ncc, edge, _, _ = mt.match(w)
        use = (~edge) & (ncc >= min_corr) & (cmax > 0)
        if not use.any():
            return None
        lag, amp = lag[use], cmax[use] / mt.e0
        pos = k + lag                                    # window position of template sample 0
        q = np.floor(pos).astype(np.int64)
        fr = pos - q
        # integer part by gathering, fraction by band-limited advance
        idx = q[:, None] + np.arange(-2, L + 2)[None, :]
        idx = np.clip(idx, 0, w.shape[1] - 1)
        rows = np.take_along_axis(w[use], idx, axis=1)
        al = _frac_advance(rows, fr)[:, 2:2 + L]
        al = al - _window_baseline(al)[:, None]
        h_new = _normalise((amp[:, None] * al).sum(axis=0) / float(amp @ amp))
        if h_new is None:
            return None
        h = h_new
        n_used = int(use.sum())
    peak, ref, fwhm = _template_features(h, reference, level)
    if not (np.isfinite(peak) and np.isfinite(ref) and np.isfinite(fwhm)):
        return None
    return Template(h, fs, d, peak, ref, fwhm * d / fs, reference, level, n_used, polarity)


def _coarse_dec(yd: np.ndarray, w_d: float, spacing_d: float, k_sigma: float):
    """Coarse maxima on decimated data: (peaks, heights, threshold, noise, median)."""
    m = max(1, int(round(0.5 * w_d)))
    ys = ndimage.uniform_filter1d(yd, m, mode="nearest") if m > 1 else yd
    med, sig, top = _noise_level(ys, w_d)
    sig = max(sig, 1e-6 * (top - med), 1e-300)       # noise-free data: a tiny floor
    thr = med + k_sigma * sig
    cand = np.flatnonzero(ys > thr)
    if cand.size == 0:
        e = np.empty(0, dtype=np.int64)
        return e, np.empty(0), thr - med, sig, med
    # samples above the threshold closer than the minimum spacing form one run (a broad pulse
    # dipping below the threshold, or its side lobes, gives one maximum). A run much longer
    # than a pulse is a dense train whose quiet stretches are shorter than that spacing (sun
    # gauge at 2.5 samples per mesh period: every pulse after the first 0.2 s was lost): it
    # is split where the samples above the threshold break; maxima closer than the spacing
    # are resolved below
    gap = max(1, int(math.ceil(spacing_d)))
    step = np.diff(cand)
    new = np.ones(cand.size, dtype=bool)
    new[1:] = step > gap
    first = np.flatnonzero(new)
    last = np.append(first[1:] - 1, cand.size - 1)
    long_run = (cand[last] - cand[first] > 3.0 * spacing_d)[np.cumsum(new) - 1]
    new[1:] |= long_run[1:] & (step > 1)
    starts = np.flatnonzero(new)
    vals = ys[cand]
    cmax = np.maximum.reduceat(vals, starts)
    cid = np.cumsum(new) - 1
    at = np.flatnonzero(vals == cmax[cid])
    first = np.ones(at.size, dtype=bool)
    first[1:] = cid[at[1:]] != cid[at[:-1]]
    peaks = cand[at[first]]
    heights = ys[peaks] - med
    # maxima of runs closer than the spacing: keep the strongest (loop over peaks)
    if peaks.size > 1 and np.any(np.diff(peaks) < spacing_d):
        keep = np.ones(peaks.size, dtype=bool)
        for i in np.argsort(-heights, kind="stable"):
            if not keep[i]:
                continue
            lo = np.searchsorted(peaks, peaks[i] - spacing_d, side="right")
            hi = np.searchsorted(peaks, peaks[i] + spacing_d, side="left")
            keep[lo:hi] = False
            keep[i] = True
        peaks, heights = peaks[keep], heights[keep]
    return peaks.astype(np.int64), heights, thr - med, sig, med


# ====================================================================== width estimate
def _width_autocorr(x: np.ndarray) -> float:
    """Tensile FWHM estimate [samples] from the autocorrelation half-lag.

    The autocorrelation of the (median-removed) signal is evaluated at geometrically spaced
    lags only (one dot product each), and the first lag where it falls below half its
    lag-1 value (lag 0 carries the noise) is interpolated in log-lag. Scaled by 1.6 to the
    FWHM of a raised-cosine pulse; only a starting value for the template-based refinement.
    """
    x = x[:_WIDTH_SAMPLES]
    n = x.size
    if n < 8:
        return 2.0
    step = max(1, n >> 16)
    z = x - float(np.median(x[::step]))
    lags = np.unique(np.round(np.geomspace(1, max(2, n // 4), 48)).astype(np.int64))
    r = np.array([float(z[:n - k] @ z[k:]) for k in lags])       # ~48 dot products
    if not r[0] > 0:
        return 2.0
    below = np.flatnonzero(r < 0.5 * r[0])
    if below.size == 0:
        return float(max(2.0, _AUTOCORR_TO_FWHM * lags[-1]))
    j = int(below[0])
    if j == 0:
        return 2.0
    l0, l1 = math.log(lags[j - 1]), math.log(lags[j])
    fr = (r[j - 1] - 0.5 * r[0]) / (r[j - 1] - r[j])
    return float(max(2.0, _AUTOCORR_TO_FWHM * math.exp(l0 + fr * (l1 - l0))))


def estimate_pulse_width(x, fs: float, *, polarity: str = "positive") -> float:
    """Estimate the tensile full width at half maximum of the pulses in ``x`` [s].

    Parameters
    ----------
    x : array_like, shape (n,)
        Conditioned samples of one channel; NaN allowed (bridged by the median).
    fs : float
        Sample rate [Hz].
    polarity : {"positive", "negative"}
        Sign of the tensile peak in ``x``.

    Returns
    -------
    float
        FWHM [s]: the autocorrelation half-lag (first 2**20 samples) scaled to a raised-cosine
        pulse, then refined by the FWHM of a template learnt on those samples (up to three
        rounds). ``2 / fs`` when no pulse structure is found.
    """
    x = _as_signal(x)
    fs = as_positive(fs, "fs")
    pol = 1 if as_choice(polarity, "polarity", ("positive", "negative")) == "positive" else -1
    if x.size == 0:
        return 2.0 / fs
    seg = x[:_WIDTH_SAMPLES] * pol
    seg = _fill_nan(seg)
    w, _ = _refine_width(seg, fs, _width_autocorr(seg), 5.0, pol)
    return w / fs


def _refine_width(seg: np.ndarray, fs: float, w0: float, k_sigma: float, pol: int,
                  decimation: int | None = None) -> tuple[float, Template | None]:
    """Up to three rounds of coarse detection + template learning to pin the FWHM [samples]."""
    w = w0
    tpl = None
    for _ in range(3):
        d = decimation or max(1, int(w // _SAMPLES_PER_WIDTH))
        yd = _decimate(seg, d)
        peaks, *_ = _coarse_dec(yd, w / d, 2.0 * w / d, k_sigma)
        t = _learn_dec(yd, peaks, fs=fs, d=d, w_d=w / d, reference="peak", level=0.5,
                       polarity=pol, max_pulses=128, n_align=1, min_corr=0.3)
        if t is None:
            break
        tpl = t
        w_new = t.fwhm * fs
        done = 0.8 < w_new / w < 1.25
        w = w_new
        if done:
            break
    return float(w), tpl


def _fill_nan(seg: np.ndarray) -> np.ndarray:
    if math.isfinite(float(np.sum(seg))):
        return seg
    bad = ~np.isfinite(seg)
    fin = seg[~bad]
    fill = float(np.median(fin[:: max(1, fin.size >> 16)])) if fin.size else 0.0
    out = seg.copy()
    out[bad] = fill
    return out


_as_signal = as_signal


# ====================================================================== options
@dataclass
class _Options:
    fs: float
    t0: float
    width: float | None            # samples
    mesh_width: float | None       # samples, from mesh_freq
    min_spacing: float | None      # samples
    template: Template | None
    relearn: str
    polarity: str | None
    reference: str
    level: float
    k_sigma: float
    min_corr: float
    block: int                     # samples
    decimation: int | None
    max_template_pulses: int
    min_template_pulses: int
    n_align: int
    flag_runs: np.ndarray          # absolute samples, merged
    gap_guard: int                 # samples
    channel: str | None
    gap_runs: np.ndarray           # absolute samples, merged: finite samples that are gaps


def _options(fs, *, t0=0.0, width=None, mesh_freq=None, min_spacing=None, template=None,
             relearn="block", polarity=None, reference="rise", level=0.5, k_sigma=5.0,
             min_corr=0.5, block=None, decimation=None, max_template_pulses=256,
             min_template_pulses=8, n_align=2, flag_runs=None, gap_guard=0.0,
             channel=None, gap_runs=None) -> _Options:
    fs = as_positive(fs, "fs")
    t0 = as_float(t0, "t0")
    w = None if width is None else as_positive(width, "width") * fs
    mw = None
    if mesh_freq is not None:
        # tensile FWHM of a pulse of contact ratio ~1.6: about 0.8 mesh periods
        mw = 0.8 * fs / as_positive(mesh_freq, "mesh_freq")
    sp = None if min_spacing is None else as_positive(min_spacing, "min_spacing") * fs
    if template is not None and not isinstance(template, Template):
        raise TypeError(f"template must be a Template, got {type(template).__name__}")
    if template is not None and template.fs != fs:
        raise ValueError(f"template was learnt at fs = {template.fs!r} Hz, data are at {fs!r} Hz")
    relearn = as_choice(relearn, "relearn", ("block", "never"))
    if polarity is not None:
        polarity = as_choice(polarity, "polarity", ("positive", "negative", "auto"))
        if template is not None and polarity != "auto" and \
                (1 if polarity == "positive" else -1) != template.polarity:
            raise ValueError(f"polarity={polarity!r} contradicts the template's polarity "
                             f"{template.polarity:+d}")
    reference = as_choice(reference, "reference", ("rise", "peak"))
    level = as_float(level, "level")
    if not 0.0 <= level < 1.0:
        raise ValueError(f"level must be in [0, 1), got {level!r}")
    k_sigma = as_positive(k_sigma, "k_sigma")
    min_corr = as_float(min_corr, "min_corr")
    if not -1.0 <= min_corr <= 1.0:
        raise ValueError(f"min_corr must be in [-1, 1], got {min_corr!r}")
    blk = _DEFAULT_BLOCK if block is None else max(16, int(round(as_positive(block, "block") * fs)))
    dec = None if decimation is None else as_positive_int(decimation, "decimation")
    if template is not None:
        if dec is not None and dec != template.decimation:
            raise ValueError(f"decimation={dec} contradicts the template's {template.decimation}")
        dec = template.decimation
    mtp = as_positive_int(max_template_pulses, "max_template_pulses")
    mnp = as_positive_int(min_template_pulses, "min_template_pulses")
    n_align = as_positive_int(n_align, "n_align")
    fr = _check_runs(flag_runs, "flag_runs")
    gr = _check_runs(gap_runs, "gap_runs")
    guard = int(math.ceil(as_nonnegative(gap_guard, "gap_guard") * fs))
    if channel is not None and not isinstance(channel, str):
        raise TypeError(f"channel must be a string, got {channel!r}")
    return _Options(fs, t0, w, mw, sp, template, relearn, polarity, reference, level, k_sigma,
                    min_corr, blk, dec, mtp, mnp, n_align, fr, guard, channel, gr)


def _check_runs(runs, name: str) -> np.ndarray:
    """``[start, stop)`` integer rows, merged; (0, 2) for None."""
    if runs is None:
        return np.empty((0, 2), dtype=np.int64)
    r = np.asarray(runs)
    if r.dtype.kind not in "iu" or r.ndim != 2 or r.shape[1] != 2:
        raise ValueError(f"{name} must be an integer array of [start, stop) rows, got "
                         f"dtype {r.dtype}, shape {r.shape}")
    return _merge(r)


# ====================================================================== the engine
class _Engine:
    """Block processor shared by the whole-array and the streaming entry points.

    Samples are fed in chunks of any size; analysis block ``k`` covers the samples
    ``[k B, (k+1) B)`` and is processed, with margins, as soon as its look-ahead is there,
    so the segments (and therefore the results) do not depend on the chunking.
    """

    def __init__(self, opt: _Options):
        self.o = opt
        self.chunks: list[tuple[int, np.ndarray]] = []
        self.n = 0
        self.k = 0
        self.ready = False
        self.pol = 1
        self.w = None            # current FWHM [samples]
        self.d = 1
        self.B = opt.block
        self.template: Template | None = opt.template
        self.templates: list[Template] = []
        self.out: list[tuple] = []
        self.last_index = -np.inf
        self.n_fallback = 0
        self.n_dropped_gap = 0
        self.warned_width = False

    # ---------------------------------------------------------------- buffer
    def feed(self, arr: np.ndarray) -> None:
        if arr.size == 0:
            return
        self.chunks.append((self.n, arr))
        self.n += arr.size
        if not self.ready:
            if self.n < self.o.block:
                return
            self._init()
        while self.n >= self._block_hi(self.k, final=False):
            self._process(self.k, final=False)
            self.k += 1
            self._trim()

    def finish(self) -> Onsets:
        o = self.o
        if self.n == 0:
            return _empty_onsets(o.fs, o.t0, o.channel, o.reference, o.level)
        if not self.ready:
            self._init()
        while self.k * self.B < self.n:
            self._process(self.k, final=True)
            self.k += 1
        if self.n_fallback:
            warnings.warn(f"{self._who()}{self.n_fallback} analysis block(s) had fewer than "
                          f"{o.min_template_pulses} clean pulses to learn a template from; their "
                          "onsets carry FLAG_TEMPLATE", ProcessingWarning, stacklevel=3)
        if not self.out:
            return _empty_onsets(o.fs, o.t0, o.channel, o.reference, o.level, self.templates)
        cols = [np.concatenate(c) for c in zip(*self.out)]
        index, corr, amp, width, flags, tid = cols
        return Onsets(o.t0 + index / o.fs, index, corr, amp, width, flags.astype(np.uint8),
                      tid.astype(np.int32), tuple(self.templates), o.fs, o.t0, o.channel,
                      o.reference, o.level)

    def _who(self) -> str:
        return f"channel {self.o.channel!r}: " if self.o.channel else ""

    def _get(self, lo: int, hi: int) -> np.ndarray:
        parts = []
        for s, a in self.chunks:
            e = s + a.size
            if e <= lo or s >= hi:
                continue
            parts.append(a[max(lo, s) - s:min(hi, e) - s])
        seg = parts[0] if len(parts) == 1 else np.concatenate(parts)
        seg = seg.astype(np.float64, copy=False)
        gr = self.o.gap_runs
        if len(gr):
            # finite samples that are gaps (dropouts) read as NaN, like any other gap
            i = np.searchsorted(gr[:, 1], lo, side="right")
            j = np.searchsorted(gr[:, 0], hi, side="left")
            if j > i:
                r = np.clip(gr[i:j] - lo, 0, seg.size)
                marks = np.zeros(seg.size + 1, dtype=np.int64)
                np.add.at(marks, r[:, 0], 1)
                np.add.at(marks, r[:, 1], -1)
                seg = np.where(np.cumsum(marks[:-1]) > 0, np.nan, seg)
        return seg

    def _trim(self) -> None:
        # the next block reads from k B - its margin, rounded down to the decimation grid
        # (as _process computes it; the geometry does not change before it runs)
        keep_from = max(0, self.k * self.B - min(self._geom()[3], self.B))
        keep_from -= keep_from % self.d
        while self.chunks and self.chunks[0][0] + self.chunks[0][1].size <= keep_from:
            self.chunks.pop(0)

    # ---------------------------------------------------------------- geometry
    def _geom(self):
        """Sizes for the next block from the current width: (w_d, h_half, k, margin), the
        last in full-rate samples (uncapped)."""
        d = self.d
        w_d = self.w / d
        h_half = max(4, int(math.ceil(_HALF_LENGTH * w_d)))
        if self.template is not None:
            h_half = max(h_half, self.template.samples.size // 2 + 1)
        # search radius: half a width plus half the coarse smoothing length, plus slack
        k = int(math.ceil(0.5 * w_d + 0.5 * max(1, int(round(0.5 * w_d))))) + 1
        margin = (2 * h_half + 2 * k + int(w_d) + 4) * d
        return w_d, h_half, k, margin

    def _block_hi(self, k: int, final: bool) -> int:
        hi = (k + 1) * self.B + min(self._geom()[3], self.B)
        return min(hi, self.n) if final else hi

    # ---------------------------------------------------------------- initialisation
    def _init(self) -> None:
        o = self.o
        seg = _fill_nan(self._get(0, min(self.n, o.block)))
        if o.template is not None:
            self.pol = o.template.polarity
        elif o.polarity in (None, "positive"):
            self.pol = 1
        elif o.polarity == "negative":
            self.pol = -1
        else:
            self.pol = _auto_polarity(seg)
        if self.pol < 0:
            seg = -seg
        if o.template is not None:
            self.w = o.template.fwhm * o.fs
        elif o.width is not None:
            self.w = o.width
        else:
            w0 = o.mesh_width if o.mesh_width is not None else _width_autocorr(seg)
            self.w, _ = _refine_width(seg, o.fs, w0, o.k_sigma, self.pol, o.decimation)
        self.d = o.decimation or max(1, int(self.w // _SAMPLES_PER_WIDTH))
        # blocks at least 4 margins long: the overlap costs at most ~50 % extra work
        self.B = int(max(o.block, 4 * self._geom()[3]))
        self.ready = True
        logger.debug("onsets: fs=%g, width=%.3g samples, decimation=%d, block=%d, polarity=%+d",
                     o.fs, self.w, self.d, self.B, self.pol)

    # ---------------------------------------------------------------- one block
    def _learn_block(self, yd, peaks, lo, d, w_d, h_half, kk, bad_runs):
        """The template for this block and whether it is a fallback (None: no template)."""
        o = self.o
        tpl = self.template
        if o.template is not None or (tpl is not None and o.relearn == "never"):
            return tpl, False
        clean = peaks
        if len(bad_runs):
            a = lo + (peaks - h_half - kk) * d
            b = lo + (peaks + h_half + kk + 1) * d
            clean = peaks[~_runs_overlap(a - o.gap_guard, b + o.gap_guard, bad_runs)]
        new = None
        # half the usual distance between pulses bounds the template (see _learn_dec)
        cap = int(0.5 * np.quantile(np.diff(peaks), 0.25)) if peaks.size >= 4 else None
        if clean.size >= 3:
            new = _learn_dec(yd, clean, fs=o.fs, d=d, w_d=w_d, reference=o.reference,
                             level=o.level, polarity=self.pol, max_pulses=o.max_template_pulses,
                             n_align=o.n_align, min_corr=o.min_corr, max_half=cap)
        if new is not None and new.n_pulses >= o.min_template_pulses:
            return new, False
        if tpl is not None:
            return tpl, True
        if clean.size < peaks.size and (new is None or new.n_pulses < o.min_template_pulses):
            # too few clean pulses (e.g. every peak clipped): learn from all of them; the
            # leading edge below the rail still times them, and their flags say so
            every = _learn_dec(yd, peaks, fs=o.fs, d=d, w_d=w_d, reference=o.reference,
                               level=o.level, polarity=self.pol,
                               max_pulses=o.max_template_pulses, n_align=o.n_align,
                               min_corr=o.min_corr, max_half=cap) if peaks.size >= 3 else None
            if every is not None and (new is None or every.n_pulses > new.n_pulses):
                new = every
        if new is not None and new.n_pulses >= 3:
            return new, True
        return None, False

    def _process(self, k: int, final: bool) -> None:
        o = self.o
        d = self.d
        w_d, h_half, kk, margin = self._geom()
        margin = min(margin, self.B)
        if w_d < 4 and d > 1 and not self.warned_width:
            self.warned_width = True
            warnings.warn(f"{self._who()}pulse width fell to {w_d:.2g} decimated samples "
                          f"(decimation {d}); timing degrades: pass a smaller decimation or "
                          "split the recording by operating point", ProcessingWarning, stacklevel=4)
        lo = max(0, k * self.B - margin)
        lo -= lo % d
        hi = self._block_hi(k, final)
        is_last = (k + 1) * self.B >= self.n if final else False
        seg = self._get(lo, hi)
        gaps = np.empty((0, 2), dtype=np.int64)
        if not math.isfinite(float(np.sum(seg))):
            gaps = find_runs(~np.isfinite(seg)) + lo
            seg = _fill_nan(seg)
        if self.pol < 0:
            seg = -seg
        yd = _decimate(seg, d)
        spacing = (o.min_spacing if o.min_spacing is not None else 2.0 * self.w)
        peaks, *_ = _coarse_dec(yd, w_d, spacing / d, o.k_sigma)
        if peaks.size == 0:
            return
        bad_runs = _merge(np.concatenate([gaps, o.flag_runs]))
        tpl, fallback = self._learn_block(yd, peaks, lo, d, w_d, h_half, kk, bad_runs)
        if tpl is None:
            logger.info("%sblock %d: %d coarse detection(s) but no template could be learnt; "
                        "skipped", self._who(), k, peaks.size)
            return
        self.template = tpl
        if fallback:
            self.n_fallback += 1
        # ---- ownership: coarse maxima in [kB - g, (k+1)B + g), duplicates removed below
        g = h_half * d
        full = lo + peaks * d + (d - 1) // 2
        own = np.ones(peaks.size, dtype=bool)
        if k > 0:
            own &= full >= k * self.B - g
        if not is_last:
            own &= full < (k + 1) * self.B + g
        peaks = peaks[own]
        if peaks.size == 0:
            return
        # ---- refinement against the template
        u = int(min(16, max(1, math.ceil(_SUBLAG_TARGET / max(tpl.fwhm * o.fs / d, 1.0)))))
        k_ref = max(kk, 2)
        mt = _Matcher(tpl, k_ref, u)
        L = mt.L
        start = peaks - mt.anchor - k_ref
        w, edge0 = _gather(yd, start, L + 2 * k_ref)
        lag, cmax, ncc, edge, wa, wmean = mt.match(w)
        pos_d = start + k_ref + lag                      # decimated position of template sample 0
        index = lo + (pos_d + tpl.ref) * d + (d - 1) / 2.0
        amp = cmax / mt.e0
        # pulse FWHM: samples above half the fitted amplitude inside the tensile lobe
        base = _window_baseline(wa)
        half = base + 0.5 * amp
        count = np.zeros(peaks.size)
        for j in np.flatnonzero(mt.tensile):          # columns of the tensile lobe
            count += wa[:, j] > half
        width = count * (d / o.fs)
        flags = np.zeros(peaks.size, dtype=np.uint8)
        flags[edge | edge0] |= FLAG_EDGE
        flags[ncc < o.min_corr] |= FLAG_LOW_CORR
        if fallback:
            flags |= FLAG_TEMPLATE
        a = lo + np.floor(pos_d).astype(np.int64) * d
        b = a + (L + 1) * d
        if len(gaps):
            flags[_runs_overlap(a - o.gap_guard, b + o.gap_guard, gaps)] |= FLAG_GAP
        if len(o.flag_runs):
            flags[_runs_overlap(a, b, o.flag_runs)] |= FLAG_CLIPPED
        # ---- no onset inside a gap or outside the data
        keep = (index >= 0) & (index <= hi - 1)
        if len(gaps):
            inside = _inside_runs(index, gaps)
            self.n_dropped_gap += int(inside.sum())
            keep &= ~inside
        order = np.argsort(index, kind="stable")
        order = order[keep[order]]
        index, amp, ncc, width, flags = (v[order] for v in (index, amp, ncc, width, flags))
        # ---- de-duplicate against the previous blocks (overlapping ownership)
        fresh = index >= self.last_index + 0.5 * spacing
        if not fresh.all():
            index, amp, ncc, width, flags = (v[fresh] for v in (index, amp, ncc, width, flags))
        if index.size:
            if not self.templates or self.templates[-1] is not tpl:
                self.templates.append(tpl)
            self.last_index = float(index[-1])
            self.out.append((index, ncc, amp * self.pol, width, flags,
                             np.full(index.size, len(self.templates) - 1, dtype=np.int32)))
        # ---- follow the speed: the next block uses this template's width
        if not fallback and o.template is None:
            self.w = tpl.fwhm * o.fs


def _auto_polarity(seg: np.ndarray) -> int:
    step = max(1, seg.size >> 16)
    s = seg[::step]
    med = np.median(s)
    hi = np.quantile(s, 0.999) - med
    lo = med - np.quantile(s, 0.001)
    return 1 if hi >= lo else -1


# ====================================================================== public API
def detect_onsets(x, fs: float, *, t0: float = 0.0, width: float | None = None,
                  mesh_freq: float | None = None, min_spacing: float | None = None,
                  template: Template | None = None, relearn: str = "block",
                  polarity: str | None = None, reference: str = "rise", level: float = 0.5,
                  k_sigma: float = 5.0, min_corr: float = 0.5, block: float | None = None,
                  decimation: int | None = None, max_template_pulses: int = 256,
                  min_template_pulses: int = 8, n_align: int = 2, flag_runs=None,
                  gap_guard: float = 0.0, channel: str | None = None, gap_runs=None) -> Onsets:
    """Engagement onsets of the pulses in one conditioned strain channel.

    Parameters
    ----------
    x : array_like, shape (n,)
        Conditioned samples (drift removed, see :mod:`pipeline.condition`) [data units];
        NaN/inf mark gaps. float32 or float64.
    fs : float
        Sample rate [Hz].
    t0 : float
        Time of the first sample [s].
    width : float, optional
        Tensile full width at half maximum of the pulses [s]; default: estimated from the
        first analysis block (see :func:`estimate_pulse_width`), or from ``mesh_freq``.
    mesh_freq : float, optional
        Mesh frequency [Hz]: initial width guess ``0.8 / mesh_freq`` (refined on the data).
    min_spacing : float, optional
        Minimum time between two pulses [s]; default twice the width.
    template : Template, optional
        A fixed template (e.g. from :func:`learn_template` or an earlier run); no learning.
    relearn : {"block", "never"}
        Re-learn the template in every analysis block (follows load and speed), or learn it
        once from the first block with enough pulses.
    polarity : {"positive", "negative", "auto"}, optional
        Sign of the tensile peak in ``x``; default positive (or the template's).
    reference : {"rise", "peak"}
        Onset feature of the template (module docstring).
    level : float
        Level of the "rise" feature, fraction of the tensile peak [-], in [0, 1).
    k_sigma : float
        Coarse threshold in robust noise standard deviations of the smoothed signal [-].
    min_corr : float
        Normalised correlation below which an onset is flagged ``FLAG_LOW_CORR`` and a pulse
        is left out of the template [-].
    block : float, optional
        Analysis block length [s] (default 2**20 samples; at least 4 pulse windows). The
        template is re-learnt per block; results do not depend on how data are chunked.
    decimation : int, optional
        Block-mean decimation factor (default ``max(1, floor(w / 16))`` samples).
    max_template_pulses, min_template_pulses : int
        Pulses averaged into a template at most; fewer clean pulses than the minimum in a
        block make it re-use the previous template (``FLAG_TEMPLATE``).
    n_align : int
        Alignment iterations when learning a template.
    flag_runs : array_like of int, shape (k, 2), optional
        ``[start, stop)`` sample ranges (relative to the first sample) to flag as
        ``FLAG_CLIPPED`` (e.g. ``ChannelQuality.clipped_runs``).
    gap_guard : float
        Pulses within this time of a gap are flagged ``FLAG_GAP`` too [s] (filter settling,
        ``ChannelQuality.settle``).
    channel : str, optional
        Channel name carried into the result and messages.
    gap_runs : array_like of int, shape (k, 2), optional
        ``[start, stop)`` sample ranges (relative to the first sample) that are gaps although
        their samples are finite (e.g. ``ChannelQuality.dropout_runs``: a DAQ writing zeros
        or holding its last value). Treated exactly as NaN samples: no onset inside, left
        out of template learning, touching pulses flagged ``FLAG_GAP``.

    Returns
    -------
    Onsets
        Always an :class:`Onsets`; empty arrays when no pulse is found.

    Notes
    -----
    See the module docstring for the method and the onset definition. Measured timing
    jitter (``pipeline.bench.processing``, 400 pulses each): 0.95-1.14 times the
    Cramer-Rao bound at 10, 20 and 30 dB peak SNR for pulses of 80 and 574 samples FWHM,
    and at 20 and 30 dB for 2-sample pulses (mesh frequency 0.4 fs); constant feature
    offset below 0.2 samples (0.9 at 10 dB for 574-sample pulses). Pulses of only a few
    samples need >= ~15 dB to be detected at ``k_sigma = 5``.
    """
    arr = _as_signal(x)
    opt = _options(fs, t0=t0, width=width, mesh_freq=mesh_freq, min_spacing=min_spacing,
                   template=template, relearn=relearn, polarity=polarity, reference=reference,
                   level=level, k_sigma=k_sigma, min_corr=min_corr, block=block,
                   decimation=decimation, max_template_pulses=max_template_pulses,
                   min_template_pulses=min_template_pulses, n_align=n_align,
                   flag_runs=flag_runs, gap_guard=gap_guard, channel=channel, gap_runs=gap_runs)
    eng = _Engine(opt)
    eng.feed(arr)
    return eng.finish()


def detect_onsets_recording(rec: Recording, channel: str, *, quality=None, **kwargs) -> Onsets:
    """:func:`detect_onsets` on one channel of a recording.

    Parameters
    ----------
    rec : Recording
        Conditioned recording.
    channel : str
        Channel name.
    quality : ChannelQuality, optional
        The channel's report from :mod:`pipeline.condition`: its clipped runs are flagged
        (``FLAG_CLIPPED``), its dropout runs are gaps (``gap_runs``; already NaN in a
        recording conditioned with ``dropouts="nan"``) and its ``settle`` time is used as
        ``gap_guard``.
    **kwargs
        Passed to :func:`detect_onsets` (not ``fs``, ``t0``, ``channel``).

    Returns
    -------
    Onsets
    """
    if not isinstance(rec, Recording):
        raise TypeError(f"rec must be a Recording, got {type(rec).__name__}")
    if not isinstance(channel, str):
        raise TypeError(f"channel must be a channel name (str), got {channel!r}")
    for bad in ("fs", "t0", "channel"):
        if bad in kwargs:
            raise TypeError(f"detect_onsets_recording takes {bad} from the recording, not as an argument")
    x = rec.channel(channel)
    if quality is not None:
        from .condition import ChannelQuality

        if not isinstance(quality, ChannelQuality):
            raise TypeError(f"quality must be a ChannelQuality, got {type(quality).__name__}")
        if quality.n_samples != rec.n_samples or quality.fs != rec.fs:
            raise ValueError(f"quality report ({quality.n_samples} samples at {quality.fs} Hz) does "
                             f"not describe this recording ({rec.n_samples} samples at {rec.fs} Hz)")
        kwargs.setdefault("flag_runs", quality.clipped_runs)
        kwargs.setdefault("gap_guard", quality.settle)
        if len(quality.dropout_runs):
            kwargs.setdefault("gap_runs", quality.dropout_runs)
    return detect_onsets(x, rec.fs, t0=rec.t0, channel=channel, **kwargs)


class OnsetStream:
    """:func:`detect_onsets` on samples fed in consecutive chunks, in bounded memory.

    Parameters
    ----------
    fs : float
        Sample rate [Hz].
    **kwargs
        As :func:`detect_onsets` (``t0``, ``mesh_freq``, ``flag_runs``, ``gap_runs``,
        ``gap_guard``, ``channel``...), runs in samples from the first sample fed.

    Notes
    -----
    :meth:`feed` keeps references to the arrays it is given (no copy): do not change them
    afterwards. The result of :meth:`finish` is identical to :func:`detect_onsets` on the
    concatenated samples, however they are chunked; about two analysis blocks (2**20
    samples each by default) are held at a time.
    """

    def __init__(self, fs: float, **kwargs):
        self._eng = _Engine(_options(fs, **kwargs))
        self._done = False

    @property
    def n_samples(self) -> int:
        """Samples fed so far [-]."""
        return self._eng.n

    def feed(self, x) -> None:
        """Feed the next chunk of samples (1-D, float32 or float64; NaN marks gaps)."""
        if self._done:
            raise RuntimeError("OnsetStream.feed after finish()")
        self._eng.feed(_as_signal(x))

    def finish(self) -> Onsets:
        """The onsets of everything fed (call once)."""
        if self._done:
            raise RuntimeError("OnsetStream.finish called twice")
        self._done = True
        return self._eng.finish()


def detect_onsets_stream(blocks: Iterable[Recording], channel: str, *, flag_times=None,
                         gap_times=None, **kwargs) -> Onsets:
    """:func:`detect_onsets` over a stream of recording blocks, in bounded memory.

    Parameters
    ----------
    blocks : iterable of Recording
        Consecutive pieces of one recording (``Recording.blocks``,
        ``pipeline.io.iter_blocks``...), possibly overlapping; samples already seen are
        skipped (by each block's ``t0``), missing samples between blocks become a gap (NaN,
        with a DataQualityWarning).
    channel : str
        Channel name.
    flag_times : array_like, shape (k, 2), optional
        ``[t_start, t_stop)`` time ranges [s] to flag ``FLAG_CLIPPED``.
    gap_times : array_like, shape (k, 2), optional
        ``[t_start, t_stop)`` time ranges [s] that are gaps although finite (dropouts, e.g.
        ``ChannelQuality.runs_time("dropout")``); see ``gap_runs`` of :func:`detect_onsets`.
    **kwargs
        Passed to :func:`detect_onsets` (not ``fs``, ``t0``, ``channel``, ``flag_runs``,
        ``gap_runs``).

    Returns
    -------
    Onsets
        Identical to :func:`detect_onsets` on the concatenated samples; empty (with
        ``fs = nan``) when ``blocks`` is empty.

    Notes
    -----
    Memory holds about two analysis blocks whatever the length of the stream.
    """
    if isinstance(blocks, Recording):
        raise TypeError("blocks must be an iterable of Recording blocks, got a single Recording "
                        "(use detect_onsets_recording)")
    if not isinstance(channel, str):
        raise TypeError(f"channel must be a channel name (str), got {channel!r}")
    for bad in ("fs", "t0", "channel", "flag_runs", "gap_runs"):
        if bad in kwargs:
            raise TypeError(f"detect_onsets_stream takes {bad} from the blocks, not as an argument")
    eng = None
    fs = t0 = None
    missing = 0
    for blk in blocks:
        if not isinstance(blk, Recording):
            raise TypeError(f"blocks must yield Recording objects, got {type(blk).__name__}")
        col = blk.channel(channel)
        if eng is None:
            fs, t0 = blk.fs, blk.t0
            fr = _time_runs(flag_times, "flag_times", fs, t0)
            gr = _time_runs(gap_times, "gap_times", fs, t0)
            eng = _Engine(_options(fs, t0=t0, channel=channel, flag_runs=fr, gap_runs=gr,
                                   **kwargs))
        elif blk.fs != fs:
            raise ValueError(f"block at t0={blk.t0!r} s has fs={blk.fs!r} Hz, the stream started at {fs!r} Hz")
        pos = (blk.t0 - t0) * fs
        i0 = int(round(pos))
        if abs(pos - i0) > 1e-3:
            raise ValueError(f"block at t0={blk.t0!r} s is off the sample grid of the stream "
                             f"(t0={t0!r} s, fs={fs!r} Hz)")
        if i0 > eng.n:
            missing += i0 - eng.n
            eng.feed(np.full(i0 - eng.n, np.nan))
        skip = eng.n - i0
        if skip < col.size:
            eng.feed(col[skip:])
    if eng is None:
        o = _options(1.0, channel=channel, **{k: v for k, v in kwargs.items()
                                               if k in ("reference", "level")})
        return _empty_onsets(float("nan"), 0.0, channel, o.reference, o.level)
    if missing:
        warnings.warn(f"channel {channel!r}: {missing} sample(s) missing between stream blocks; "
                      "treated as a gap", DataQualityWarning, stacklevel=2)
    return eng.finish()


def _time_runs(times, name: str, fs: float, t0: float) -> np.ndarray | None:
    """``[t_start, t_stop)`` rows [s] as sample runs ``[ceil((t-t0) fs), ...)`` (None: None)."""
    if times is None:
        return None
    ft = np.asarray(times, dtype=np.float64).reshape(-1, 2)
    if ft.size and not np.all(np.isfinite(ft)):
        raise ValueError(f"{name} must be finite")
    return np.ceil((ft - t0) * fs - 1e-6).astype(np.int64)


def coarse_peaks(x, fs: float, *, width: float, min_spacing: float | None = None,
                 k_sigma: float = 5.0, polarity: str = "positive",
                 decimation: int | None = None) -> CoarsePeaks:
    """The coarse stage alone: smoothed maxima above a robust threshold.

    Parameters
    ----------
    x : array_like, shape (n,)
        Conditioned samples [data units]; NaN bridged by the median.
    fs : float
        Sample rate [Hz].
    width : float
        Tensile FWHM of the pulses [s].
    min_spacing : float, optional
        Minimum time between pulses [s] (default ``2 * width``).
    k_sigma : float
        Threshold in robust noise standard deviations [-].
    polarity : {"positive", "negative"}
    decimation : int, optional
        Block-mean decimation (default ``max(1, floor(width * fs / 16))``).

    Returns
    -------
    CoarsePeaks
        Timing to about +-w/4: the refinement of :func:`detect_onsets` is what makes onsets.
    """
    arr = _as_signal(x)
    fs = as_positive(fs, "fs")
    w = as_positive(width, "width") * fs
    sp = 2.0 * w if min_spacing is None else as_positive(min_spacing, "min_spacing") * fs
    k_sigma = as_positive(k_sigma, "k_sigma")
    pol = 1 if as_choice(polarity, "polarity", ("positive", "negative")) == "positive" else -1
    d = max(1, int(w // _SAMPLES_PER_WIDTH)) if decimation is None else as_positive_int(decimation, "decimation")
    if arr.size == 0:
        return CoarsePeaks(np.empty(0, dtype=np.int64), np.empty(0), float("nan"), float("nan"), d)
    seg = _fill_nan(arr.astype(np.float64, copy=False))
    if pol < 0:
        seg = -seg
    yd = _decimate(seg, d)
    peaks, heights, thr, noise, _ = _coarse_dec(yd, w / d, sp / d, k_sigma)
    return CoarsePeaks(peaks * d + (d - 1) // 2, heights, thr, noise, d)


def learn_template(x, fs: float, coarse_idx, *, width: float | None = None,
                   decimation: int | None = None, reference: str = "rise", level: float = 0.5,
                   polarity: str = "positive", max_pulses: int = 256, n_align: int = 2,
                   min_corr: float = 0.5) -> Template:
    """Learn a pulse template from the pulses around ``coarse_idx``.

    Parameters
    ----------
    x : array_like, shape (n,)
        Conditioned samples [data units].
    fs : float
        Sample rate [Hz].
    coarse_idx : array_like of int
        Approximate sample indices of pulse maxima (e.g. ``coarse_peaks(...).index``).
    width : float, optional
        Tensile FWHM [s]; estimated when None.
    decimation : int, optional
        Block-mean decimation (default from the width).
    reference, level
        Onset feature (see :func:`detect_onsets`).
    polarity : {"positive", "negative"}
    max_pulses : int
        At most this many pulses (evenly spread) are averaged.
    n_align : int
        Sub-sample alignment iterations.
    min_corr : float
        Pulses correlating worse with the running template are left out [-].

    Returns
    -------
    Template

    Raises
    ------
    ValueError
        When ``coarse_idx`` is empty or no usable pulse (full window inside ``x``, positive
        correlation) is found.
    """
    arr = _as_signal(x)
    fs = as_positive(fs, "fs")
    idx = np.asarray(coarse_idx)
    if idx.dtype.kind not in "iu":
        raise TypeError(f"coarse_idx must be integer sample indices, got dtype {idx.dtype}")
    idx = idx.ravel().astype(np.int64)
    if idx.size == 0:
        raise ValueError("coarse_idx is empty: no pulse to learn a template from")
    reference = as_choice(reference, "reference", ("rise", "peak"))
    level = as_float(level, "level")
    if not 0.0 <= level < 1.0:
        raise ValueError(f"level must be in [0, 1), got {level!r}")
    pol = 1 if as_choice(polarity, "polarity", ("positive", "negative")) == "positive" else -1
    seg = _fill_nan(arr.astype(np.float64, copy=False))
    if pol < 0:
        seg = -seg
    w = as_positive(width, "width") * fs if width is not None else _refine_width(
        seg, fs, _width_autocorr(seg), 5.0, pol, decimation)[0]
    d = max(1, int(w // _SAMPLES_PER_WIDTH)) if decimation is None else as_positive_int(decimation, "decimation")
    yd = _decimate(seg, d)
    tpl = _learn_dec(yd, np.sort(idx) // d, fs=fs, d=d, w_d=w / d, reference=reference,
                     level=level, polarity=pol, max_pulses=as_positive_int(max_pulses, "max_pulses"),
                     n_align=as_positive_int(n_align, "n_align"), min_corr=as_float(min_corr, "min_corr"))
    if tpl is None:
        raise ValueError(f"no usable pulse among the {idx.size} coarse indices (windows outside the "
                         "data, or no positive correlation)")
    return tpl
