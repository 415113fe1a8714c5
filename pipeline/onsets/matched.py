"""Matched-filter refinement: pulse windows correlated with the zero-mean template at
(sub-)sample lags, the correlation peak interpolated.

Step 4 of the pipeline (see :mod:`meshphase.onsets`): one BLAS product with a Toeplitz
matrix of shifted templates per block; ``U = ceil(4 / w_D)`` sub-lags per sample (> 1 only
for pulses a few samples wide, whose fractional shifts are band-limited FFT shifts).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from ..runtime.lazy import fft as sfft
from .template import Template

__all__ = ["Matcher", "gather_windows", "sublags", "window_baseline"]

_SUBLAG_TARGET = 4.0        # sub-lag grid: U = ceil(4 / FWHM) steps per sample (>= 4 per FWHM)


def sublags(w_d: float) -> int:
    """Sub-lags per sample U for a template ``w_d`` samples wide (FWHM), 1 to 16."""
    return int(min(16, max(1, math.ceil(_SUBLAG_TARGET / max(w_d, 1.0)))))


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


def _col_sum(w: np.ndarray, cols) -> np.ndarray:
    """Sum of the given columns of each row: a loop over the (few) columns, which avoids
    numpy's per-row reduction overhead on short rows."""
    acc = np.zeros(w.shape[0])
    for j in cols:
        acc += w[:, j]
    return acc


def window_baseline(w: np.ndarray) -> np.ndarray:
    """Mean of the outer 10 % of each row at both ends."""
    n = w.shape[1]
    e = max(1, n // 10)
    return _col_sum(w, list(range(e)) + list(range(n - e, n))) / (2 * e)


def gather_windows(y: np.ndarray, start: np.ndarray, length: int) -> tuple[np.ndarray, np.ndarray]:
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


class Matcher:
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
        # np.take: a 1-d gather faster than fancy indexing, the same values
        y0, y1, y2 = np.take(flat, b - 1), np.take(flat, b), np.take(flat, b + 1)
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

