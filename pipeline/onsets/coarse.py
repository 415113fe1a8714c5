"""Coarse pulse detection: block-mean decimation, robust noise level, smoothed maxima.

Steps 1 and 2 of the pipeline (see :mod:`meshphase.onsets`): the signal is decimated by
``D = max(1, floor(w / 16))``, smoothed over ``w / 2`` and thresholded at ``median + k_sigma
* noise``; one maximum per run above the threshold. Timing to about +-w/4; the refinement
(:mod:`meshphase.onsets.matched`) is what makes onsets.
"""

from __future__ import annotations

import math

import numpy as np

from ..runtime.lazy import ndimage
from ..signal.median import MAD_TO_SIGMA, median_and_mad, median_of_finite
from ..validate import as_choice, as_positive, as_positive_int, as_signal
from .fastpath import run_maxima
from .results import CoarsePeaks

__all__ = ["coarse_peaks", "coarse_decimated", "decimate", "decimation_for", "fill_nan"]

_SAMPLES_PER_WIDTH = 16      # decimate so that the pulse FWHM keeps >= 16 samples


def decimation_for(w: float) -> int:
    """Decimation factor D for pulses ``w`` samples wide (FWHM): ``max(1, floor(w / 16))``."""
    return max(1, int(w // _SAMPLES_PER_WIDTH))


def decimate(seg: np.ndarray, d: int, sign: int = 1) -> np.ndarray:
    """Block means of ``d`` samples (trailing partial block dropped), times ``sign`` (+-1).

    One BLAS matrix-vector product of the ``(n / d, d)`` view with ``sign * ones(d) / d``:
    a single pass over contiguous samples for any ``d`` (a strided column sum per pass, or
    ``reshape(-1, d).sum(1)`` with its per-row reduction overhead, cost 5-100x more for
    ``d`` of 2 to 35); a strided input is made contiguous first. Equal to the plain block
    mean to ~4e-16 relative (the summation order differs); ``sign=-1`` equals the block
    means of ``-seg`` bit for bit (rounding is symmetric in the sign) without negating a
    copy first.
    """
    if d == 1:
        return seg if sign > 0 else -seg
    m = (seg.size // d) * d
    v = np.ascontiguousarray(seg[:m]).reshape(-1, d)
    return v @ np.full(d, (1.0 if sign > 0 else -1.0) / d)


def fill_nan(seg: np.ndarray) -> np.ndarray:
    """``seg`` with its non-finite samples replaced by the median of its finite ones (0 when
    none is finite); ``seg`` itself when every sample is finite."""
    if math.isfinite(float(np.sum(seg))):
        return seg
    bad = ~np.isfinite(seg)
    fin = seg[~bad]
    fill = float(median_of_finite(fin[:: max(1, fin.size >> 16)])) if fin.size else 0.0
    out = seg.copy()
    out[bad] = fill
    return out


#: samples of the piece per maximum down to which :func:`_unmasked` clears the spans one
#: slice each [-]: the slices cost in proportion to the maxima, the span counting to the
#: samples; on the noise estimate's 8192-sample pieces they cross near one maximum per 256
_SLICE_SAMPLES = 256


def _unmasked(n: int, mx: np.ndarray, hh: int) -> np.ndarray:
    """Samples of ``n`` farther than ``hh`` from every index in ``mx``: True outside the
    spans [m - hh, m + hh] (clipped to the piece). A few maxima (a sparse train: at most
    16, or one per ``_SLICE_SAMPLES`` samples) clear their spans slice by slice; many, by
    counting span starts and ends (bincount and cumsum): the same mask."""
    if mx.size <= max(16, n // _SLICE_SAMPLES):
        keep = np.ones(n, dtype=bool)
        for m in mx.tolist():
            keep[max(m - hh, 0):m + hh + 1] = False
        return keep
    # np.maximum / np.minimum: np.clip's dispatch costs more than its work on a few hundred maxima
    marks = (np.bincount(np.maximum(mx - hh, 0), minlength=n + 1)
             - np.bincount(np.minimum(mx + (hh + 1), n), minlength=n + 1))
    return np.cumsum(marks[:-1]) == 0


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
    # a gap filled with one constant (see fill_nan) carries no noise: leave constant runs
    # out of the pieces, else a gap at the start or end collapses the MAD (and the threshold)
    def _live(p):
        if p.size < 3:
            return p
        eq = np.diff(p) == 0
        if not eq.any():                              # the usual piece: nothing flat
            return p
        flat = np.concatenate([[False], eq])
        flat[:-1] |= flat[1:]
        return p[~flat]
    pieces = [q for q in (_live(p) for p in pieces) if q.size >= 16]
    if not pieces:
        live = _live(y)
        pieces = [live if live.size >= 3 else y]
    for p in pieces:                                  # <= 4 pieces
        med, mad = median_and_mad(p)
        med, sig = float(med), MAD_TO_SIGMA * float(mad)
        keep = None
        for _ in range(2):
            if p.size < 3 or not sig > 0:
                break
            q = p[1:-1]
            mx = np.flatnonzero((q > med + 3.0 * sig) & (q >= p[:-2]) & (q > p[2:])) + 1
            for hh in (h, max(1, h // 2)):         # narrower mask for very dense trains
                new_keep = _unmasked(p.size, mx, hh)
                n_keep = np.count_nonzero(new_keep)
                if n_keep >= 0.05 * p.size:
                    break
            if n_keep < 0.05 * p.size:
                break
            if keep is not None and np.array_equal(new_keep, keep):
                break                                  # same mask: same median and sigma
            keep = new_keep
            r = p[keep]
            med, mad = median_and_mad(r)
            med, sig = float(med), MAD_TO_SIGMA * float(mad)
        rest.append(p if keep is None else p[keep])
    r = np.concatenate(rest) if len(rest) > 1 else rest[0]
    if len(rest) == 1:                                # the piece's own last estimate
        return med, float(sig), float(pieces[0].max())
    med, mad = median_and_mad(r)
    top = max(float(p.max()) for p in pieces)
    return float(med), MAD_TO_SIGMA * float(mad), top


def coarse_decimated(yd: np.ndarray, w_d: float, spacing_d: float, k_sigma: float, fast: bool = False):
    """Coarse maxima on decimated data: (peaks, heights, threshold, noise, median).

    ``fast``: the run maxima from the numba kernel (:func:`meshphase.onsets.fastpath.run_maxima`,
    the same maxima bit for bit) instead of the numpy run bookkeeping below."""
    m = max(1, int(round(0.5 * w_d)))
    ys = ndimage.uniform_filter1d(yd, m, mode="nearest") if m > 1 else yd
    med, sig, top = _noise_level(ys, w_d)
    sig = max(sig, 1e-6 * (top - med), 1e-300)       # noise-free data: a tiny floor
    thr = med + k_sigma * sig
    if fast:
        peaks = run_maxima(ys, thr, max(1, int(math.ceil(spacing_d))), 3.0 * spacing_d)
        return _resolve_close(peaks, ys[peaks] - med, spacing_d) + (thr - med, sig, med)
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
    return _resolve_close(peaks, ys[peaks] - med, spacing_d) + (thr - med, sig, med)


def _resolve_close(peaks: np.ndarray, heights: np.ndarray, spacing_d: float):
    """Maxima of runs closer than the spacing: keep the strongest (loop over peaks);
    (peaks as int64, heights)."""
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
    return peaks.astype(np.int64), heights


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
    arr = as_signal(x)
    fs = as_positive(fs, "fs")
    w = as_positive(width, "width") * fs
    sp = 2.0 * w if min_spacing is None else as_positive(min_spacing, "min_spacing") * fs
    k_sigma = as_positive(k_sigma, "k_sigma")
    pol = 1 if as_choice(polarity, "polarity", ("positive", "negative")) == "positive" else -1
    d = decimation_for(w) if decimation is None else as_positive_int(decimation, "decimation")
    if arr.size == 0:
        return CoarsePeaks(np.empty(0, dtype=np.int64), np.empty(0), float("nan"), float("nan"), d)
    seg = fill_nan(arr.astype(np.float64, copy=False))
    if pol < 0:
        seg = -seg
    yd = decimate(seg, d)
    peaks, heights, thr, noise, _ = coarse_decimated(yd, w / d, sp / d, k_sigma)
    return CoarsePeaks(peaks * d + (d - 1) // 2, heights, thr, noise, d)

