"""The numba build of the onset stage's per-pulse loops (:mod:`meshphase.onsets.fastpath`).

Imported when a block takes the numba engine (a dense block, or any block once numba is
loaded in the process), so that importing the onsets, or processing a recording of wide
pulses where numba is not loaded, does not load numba and LLVM. Compiled
functions are cached (``cache=True``) in the per-user directory
:func:`meshphase.runtime.numba_cache.numba_cache_dir` names unless ``NUMBA_CACHE_DIR`` is set
(``meshphase bench --warmup`` fills it). ``fastmath`` stays off: the arithmetic is the numpy
path's, in its order, except the window sums of the NCC and baseline (numpy: BLAS and
einsum; here each in sample order). The correlations are BLAS's matrix product, as on the
numpy path, on 32 windows at a time (numba's ``np.dot`` calls the BLAS scipy ships).
"""

from __future__ import annotations

import numba as _numba
import numpy as np


@_numba.njit(cache=True, nogil=True)
def _run_maxima(ys, thr, gap, long_len):  # pragma: no cover - compiled
    """Index of the first maximum of every run of samples above ``thr`` (samples closer than
    ``gap`` + 1 join a run; a run spanning more than ``long_len`` samples is split at every
    break), as :func:`meshphase.onsets.coarse.coarse_decimated` finds them with numpy."""
    n = ys.shape[0]
    out = np.empty(max(n, 1), dtype=np.int64)
    m = 0                      # maxima written so far (of finished runs)
    ms = 0                     # sub-run maxima of the current run written from m on
    in_run = False
    first = 0
    prev = 0
    best_v = 0.0
    best_i = 0
    sb_v = 0.0
    sb_i = 0
    for i in range(n):
        v = ys[i]
        if not v > thr:
            continue
        if in_run and i - prev > gap:              # the run ended at prev
            m = _end_run(out, m, ms, prev - first > long_len, best_i, sb_i)
            in_run = False
        if not in_run:
            in_run = True
            first = i
            best_v = v
            best_i = i
            sb_v = v
            sb_i = i
            ms = m
        else:
            if v > best_v:
                best_v = v
                best_i = i
            if i - prev > 1:                        # a break: a new sub-run
                out[ms] = sb_i
                ms += 1
                sb_v = v
                sb_i = i
            elif v > sb_v:
                sb_v = v
                sb_i = i
        prev = i
    if in_run:
        m = _end_run(out, m, ms, prev - first > long_len, best_i, sb_i)
    return out[:m].copy()


@_numba.njit(cache=True, nogil=True, inline="always")
def _end_run(out, m, ms, split, best_i, sb_i):  # pragma: no cover - compiled
    """Close a run: a split (long) run keeps its sub-run maxima ``out[m:ms]`` and adds the
    last one, else its single maximum goes to ``out[m]``; returns the new count."""
    if split:
        out[ms] = sb_i
        return ms + 1
    out[m] = best_i
    return m + 1


@_numba.njit(cache=True, nogil=True)
def _round_half_even(x):  # pragma: no cover - compiled
    """``int(np.rint(x))`` for a finite ``x`` (ties to even)."""
    r = np.floor(x)
    f = x - r
    i = np.int64(r)
    if f > 0.5 or (f == 0.5 and (i & 1) != 0):
        i += 1
    return i


_CHUNK = 32        # pulses correlated together (one small matrix product; windows in L1)


@_numba.njit(cache=True, nogil=True)
def _refine_pulses(yd, peaks, anchor, k, u, t_all, e0, tensile, n_base, lo, d, ref, width_unit,
                   min_corr, base_flags, flag_edge, flag_low,
                   index, amp, ncc, width, flags, a_out):  # pragma: no cover - compiled
    """Matched-filter refinement of every pulse, 32 at a time (see ``Matcher.match`` and
    ``BlockEngine._refine``, whose arithmetic this repeats pulse by pulse): windows gathered
    as the rows of a matrix and correlated at the (sub-)lags by one BLAS product with the
    template's lagged columns, as the numpy path's ``w @ t_all`` does (BLAS's blocked
    product is faster than a compiled loop over the sums), then each step done for the
    whole chunk before the next (independent pulses interleave instead of one long
    dependency chain per pulse): first maximum, parabolic peak, NCC and width on the window
    at the nearest integer lag, onset index, amplitude and flags; ``a_out`` the first
    full-rate sample of each pulse window (for the gap and clipping flags)."""
    n = yd.shape[0]
    lw, ncol = t_all.shape
    L = lw - 2 * k
    wr = np.zeros((_CHUNK, lw))
    cc = np.empty((_CHUNK, ncol))
    jm = np.empty(_CHUNK, dtype=np.int64)
    lag = np.empty(_CHUNK)
    cmax = np.empty(_CHUNK)
    mi = np.empty(_CHUNK, dtype=np.int64)
    s1 = np.empty(_CHUNK)
    s2 = np.empty(_CHUNK)
    bs = np.empty(_CHUNK)
    for i0 in range(0, peaks.shape[0], _CHUNK):
        m = min(_CHUNK, peaks.shape[0] - i0)
        _gather_rows(yd, peaks, i0, m, anchor + k, wr)
        np.dot(wr, t_all, cc)                    # rows past m: earlier windows, unused
        _first_max(cc, m, jm)
        for p in range(m):
            lag[p], cmax[p] = _parabola(cc, p, jm[p], k, u)
            mi[p] = min(max(_round_half_even(lag[p]) + k, 0), 2 * k)
            s1[p] = 0.0
            s2[p] = 0.0
            bs[p] = 0.0
        for t in range(L):                       # NCC sums, sample order per pulse
            for p in range(m):
                v = wr[p, mi[p] + t]
                s1[p] += v
                s2[p] += v * v
        for t in range(n_base):                  # baseline: first and last n_base samples
            for p in range(m):
                bs[p] += wr[p, mi[p] + t]
        for t in range(L - n_base, L):
            for p in range(m):
                bs[p] += wr[p, mi[p] + t]
        for p in range(m):
            a = cmax[p] / e0
            half = bs[p] / (2 * n_base) + 0.5 * a
            c = 0
            for q in range(tensile.shape[0]):
                c += wr[p, mi[p] + tensile[q]] > half
            var = max(s2[p] - s1[p] * s1[p] / L, 0.0)
            norm = np.sqrt(var * e0)
            r = cmax[p] / norm if norm > 0 else 0.0
            r = min(max(r, -1.0), 1.0)
            i = i0 + p
            start = peaks[i] - anchor - k
            pos = float(start + k) + lag[p]
            index[i] = lo + (pos + ref) * d + (d - 1) / 2.0
            amp[i] = a
            ncc[i] = r
            width[i] = c * width_unit
            f = base_flags
            if start < 0 or start + lw > n or jm[p] == 0 or jm[p] == ncol - 1:
                f |= flag_edge
            if r < min_corr:
                f |= flag_low
            flags[i] = f
            a_out[i] = lo + np.int64(np.floor(pos)) * d


@_numba.njit(cache=True, nogil=True, inline="always")
def _gather_rows(yd, peaks, i0, m, shift, wr):  # pragma: no cover - compiled
    """Windows of pulses ``i0 .. i0 + m - 1`` as the rows of ``wr`` (samples past the
    ends of ``yd`` repeat the edge sample)."""
    n = yd.shape[0]
    lw = wr.shape[1]
    for p in range(m):
        start = peaks[i0 + p] - shift
        if start < 0 or start + lw > n:
            for t in range(lw):
                wr[p, t] = yd[min(max(start + t, 0), n - 1)]
        else:
            for t in range(lw):
                wr[p, t] = yd[start + t]


@_numba.njit(cache=True, nogil=True, inline="always")
def _first_max(cc, m, jm):  # pragma: no cover - compiled
    """``jm[p]``: the first column of the maximum of row ``p`` of ``cc`` (np.argmax)."""
    for p in range(m):
        best = cc[p, 0]
        j_best = 0
        for j in range(1, cc.shape[1]):
            v = cc[p, j]
            if v > best:
                best = v
                j_best = j
        jm[p] = j_best


@_numba.njit(cache=True, nogil=True, inline="always")
def _parabola(cc, p, jm, k, u):  # pragma: no cover - compiled
    """Lag [samples, relative to K] and height of the parabola through the maximum of
    row ``p`` and its neighbours (the ends: through the next-inner three)."""
    jc = min(max(jm, 1), cc.shape[1] - 2)
    y0 = cc[p, jc - 1]
    y1 = cc[p, jc]
    y2 = cc[p, jc + 1]
    den = y0 - 2.0 * y1 + y2
    dd = 0.5 * (y0 - y2) / den if den < 0 else 0.0
    dd = min(max(dd, -1.0), 1.0)
    return (jc - k * u + dd) / u, y1 - 0.25 * (y0 - y2) * dd
