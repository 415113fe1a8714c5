"""The numba build of the onset stage's per-pulse loops (:mod:`meshphase.onsets.fastpath`).

Imported only when a dense block is processed on the numba engine, so that importing the
onsets (and processing a recording of wide pulses) does not load numba and LLVM. Compiled
functions are cached (``cache=True``) in the per-user directory
:func:`meshphase.models._kernels.numba_cache_dir` names unless ``NUMBA_CACHE_DIR`` is set
(``meshphase bench --warmup`` fills it). ``fastmath`` stays off: the arithmetic is the numpy
path's, in its order, except the correlation sums (BLAS sums in its own order; here each
column is summed in sample order, with fused multiply-adds).
"""

from __future__ import annotations

import numba as _numba
import numpy as np


@_numba.njit(cache=True, nogil=True)
def _run_maxima(ys, thr, gap, long_len):  # pragma: no cover - compiled
    """Index of the first maximum of every run of samples above ``thr`` (samples closer than
    ``gap`` + 1 join a run; a run spanning more than ``long_len`` samples is split at every
    break), as :func:`meshphase.onsets.coarse._coarse_dec` finds them with numpy."""
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
            if prev - first > long_len:
                out[ms] = sb_i
                m = ms + 1
            else:
                out[m] = best_i
                m += 1
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
        if prev - first > long_len:
            out[ms] = sb_i
            m = ms + 1
        else:
            out[m] = best_i
            m += 1
    return out[:m].copy()


@_numba.njit(cache=True, nogil=True)
def _round_half_even(x):  # pragma: no cover - compiled
    """``int(np.rint(x))`` for a finite ``x`` (ties to even)."""
    r = np.floor(x)
    f = x - r
    i = np.int64(r)
    if f > 0.5 or (f == 0.5 and (i & 1) != 0):
        i += 1
    return i


@_numba.njit(cache=True, nogil=True, fastmath={"contract"})
def _correlate(w, off, tf, lw, nc, c):  # pragma: no cover - compiled
    """``c[j] = sum_t w[off + t] tf[t nc + j]`` for the ``nc`` columns of the row-major
    ``(lw, nc)`` matrix ``tf``, each column summed in sample order (rows outer: the inner
    loop over columns vectorises; measured faster in place than register accumulators
    per column, which numba's LLVM pipeline does not vectorise)."""
    for j in range(nc):
        c[j] = 0.0
    for t in range(lw):
        wt = w[off + t]
        row = tf[t * nc:(t + 1) * nc]
        for j in range(nc):
            c[j] += wt * row[j]


@_numba.njit(cache=True, nogil=True)
def _refine_pulses(yd, peaks, anchor, k, u, tf, ncol, e0, tensile, n_base, lo, d, ref, width_unit,
                   min_corr, base_flags, flag_edge, flag_low,
                   index, amp, ncc, width, flags, a_out):  # pragma: no cover - compiled
    """Matched-filter refinement of every pulse in one pass (see ``_Matcher.match`` and
    ``_Engine._refine``, whose arithmetic this repeats pulse by pulse): correlation at
    the (sub-)lags, first maximum, parabolic peak, NCC and width on the window at the
    nearest integer lag, onset index, amplitude and flags; ``a_out`` the first full-rate
    sample of each pulse window (for the gap and clipping flags)."""
    n = yd.shape[0]
    nc = ncol
    lw = tf.shape[0] // nc
    L = lw - 2 * k
    c = np.empty(nc)
    buf = np.empty(lw)
    for i in range(peaks.shape[0]):
        start = peaks[i] - anchor - k
        edge0 = start < 0 or start + lw > n
        if edge0:
            for t in range(lw):
                q = start + t
                q = 0 if q < 0 else (n - 1 if q > n - 1 else q)
                buf[t] = yd[q]
            w = buf
            off = 0
        else:
            w = yd
            off = start
        _correlate(w, off, tf, lw, nc, c)
        jm = 0
        cm = c[0]
        for j in range(1, ncol):
            if c[j] > cm:
                cm = c[j]
                jm = j
        edge = edge0 or jm == 0 or jm == ncol - 1
        jc = min(max(jm, 1), ncol - 2)
        y0 = c[jc - 1]
        y1 = c[jc]
        y2 = c[jc + 1]
        den = y0 - 2.0 * y1 + y2
        dd = 0.5 * (y0 - y2) / den if den < 0 else 0.0
        dd = min(max(dd, -1.0), 1.0)
        lag = (jc - k * u + dd) / u
        cmax = y1 - 0.25 * (y0 - y2) * dd
        mi = _round_half_even(lag) + k
        mi = min(max(mi, 0), 2 * k)
        s1 = 0.0
        s2 = 0.0
        m0 = off + mi
        for t in range(m0, m0 + L):
            s1 += w[t]
            s2 += w[t] * w[t]
        var = max(s2 - s1 * s1 / L, 0.0)
        norm = np.sqrt(var * e0)
        r = cmax / norm if norm > 0 else 0.0
        r = min(max(r, -1.0), 1.0)
        a = cmax / e0
        base = 0.0
        for t in range(n_base):
            base += w[m0 + t]
        for t in range(L - n_base, L):
            base += w[m0 + t]
        half = base / (2 * n_base) + 0.5 * a
        cnt = 0
        for q in range(tensile.shape[0]):
            if w[m0 + tensile[q]] > half:
                cnt += 1
        pos = float(start + k) + lag
        index[i] = lo + (pos + ref) * d + (d - 1) / 2.0
        amp[i] = a
        ncc[i] = r
        width[i] = cnt * width_unit
        f = base_flags
        if edge:
            f |= flag_edge
        if r < min_corr:
            f |= flag_low
        flags[i] = f
        a_out[i] = lo + np.int64(np.floor(pos)) * d
