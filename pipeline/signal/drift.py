"""Drift removal as a block filter: the slow (thermal) baseline of a pulse train, its level
steps, and the baseline subtracted.

:class:`DriftFilter` takes the samples in blocks (:mod:`meshphase.signal.blocks`): it
computes block medians (at most 33 strided samples each), or the means of whole pulse
periods, smooths them with a moving median or a Savitzky-Golay fit over 17 blocks and
emits each sample less the baseline interpolated between block centres, as soon as every
block value that sample depends on is known (about 9 blocks ahead, further across a gap).
Pushed the whole signal at once it is the whole-signal drift removal
(:func:`drift_baseline`, :func:`meshphase.signal.condition.remove_drift`).
:func:`level_steps` finds the baseline's jumps in the same block values.
"""

from __future__ import annotations

import math

import numpy as np

from ..runtime.lazy import ndimage
from .blocks import run_whole
from .median import MAD_TO_SIGMA, median_and_mad
from .savgol import savgol_filter
from ..validate import as_choice, as_positive, as_signal

__all__ = ["DriftFilter", "PendingSamples", "drift_baseline", "drift_window", "block_medians",
           "block_means", "level_steps", "minus_interp", "STEP_SPREADS",
           "DEFAULT_DRIFT_WINDOW_S", "DRIFT_WINDOW_MESH_PERIODS", "INTERP_RUN"]

#: Drift-removal window used when the mesh frequency is unknown [s].
DEFAULT_DRIFT_WINDOW_S = 10.0
#: Drift-removal window in mesh periods [-].
DRIFT_WINDOW_MESH_PERIODS = 20.0
#: a block-to-block change of the drift baseline this many robust spreads beyond the local
#: trend of its neighbours is a level step [-]
STEP_SPREADS = 10.0
#: mean samples per interval of the knots below which :func:`minus_interp` calls
#: ``np.interp`` instead of its loop over the intervals [-]
INTERP_RUN = 512


def drift_window(window, mesh_freq) -> float:
    """The drift window [s]: ``window`` when given, else 20 mesh periods of ``mesh_freq``
    [Hz], else ``DEFAULT_DRIFT_WINDOW_S``."""
    if window is not None:
        return as_positive(window, "window")
    if mesh_freq is not None:
        return DRIFT_WINDOW_MESH_PERIODS / as_positive(mesh_freq, "mesh_freq")
    return DEFAULT_DRIFT_WINDOW_S


def block_medians(x: np.ndarray, b: int) -> tuple[np.ndarray, np.ndarray]:
    """Medians of consecutive blocks of ``b`` samples (at most 33 evenly strided samples of
    each enter its median; NaN ignored) and the block centre indices.

    Only the strided samples are gathered (a partial last block is padded with NaN to the
    length of the others): the work space is ~34 values per block whatever ``b`` is, so a
    block longer than the data (a window of seconds at an absurd fs) costs nothing."""
    n = x.size
    nb = -(-n // b)
    nf = n // b
    step = max(1, b // 33)
    rows = np.full((nb, -(-b // step)), np.nan)
    if nf:
        rows[:nf] = x[:nf * b].reshape(nf, b)[:, ::step]
    if nb > nf:
        part = x[nf * b::step]
        rows[nf, :part.size] = part
    med = np.median(rows, axis=1)
    bad = np.isnan(med)
    if bad.any():
        fin = np.isfinite(rows[bad]).any(axis=1)
        sub = np.full(int(bad.sum()), np.nan)
        if fin.any():
            sub[fin] = np.nanmedian(rows[bad][fin], axis=1)
        med[bad] = sub
    starts = np.arange(nb) * b
    stops = np.minimum(starts + b, n)
    n_used = -(-(stops - starts) // step)             # strided samples inside each block
    return med, starts + 0.5 * step * (n_used - 1)


def block_means(x: np.ndarray, b: int) -> tuple[np.ndarray, np.ndarray]:
    """Means of consecutive blocks of ``b`` samples (NaN ignored; NaN for an all-NaN block)
    and the block centre indices (no padding: the work space is the data's own size)."""
    n = x.size
    nb = -(-n // b)
    nf = n // b
    cnt = np.zeros(nb, dtype=np.int64)
    tot = np.zeros(nb)
    if nf:
        rows = x[:nf * b].reshape(nf, b)
        with np.errstate(over="ignore", invalid="ignore"):
            sums = rows.sum(axis=1)                  # all finite: every sample is (NaN/inf
        if np.isfinite(sums).all():                  # or an overflow: the masked path below)
            cnt[:nf] = b
            tot[:nf] = sums
        else:
            fin = np.isfinite(rows)
            cnt[:nf] = fin.sum(axis=1)
            tot[:nf] = np.where(fin, rows, 0.0).sum(axis=1)
    if nb > nf:
        part = x[nf * b:]
        fin = np.isfinite(part)
        cnt[nf] = int(fin.sum())
        tot[nf] = float(np.where(fin, part, 0.0).sum())
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(cnt > 0, tot / np.maximum(cnt, 1), np.nan)
    starts = np.arange(nb) * b
    stops = np.minimum(starts + b, n)
    return mean, 0.5 * (starts + stops - 1)


def drift_baseline(x, fs: float, *, method: str = "median", window: float | None = None,
                   mesh_freq: float | None = None, pulse_period: float | None = None) -> np.ndarray:
    """Slow baseline of a pulse train (what :func:`meshphase.signal.condition.remove_drift`
    subtracts): :class:`DriftFilter` pushed the whole signal.

    Parameters
    ----------
    x : array_like, shape (n,)
        Samples [any unit]; NaN/inf ignored.
    fs : float
        Sample rate [Hz].
    method : {"median", "savgol"}
        "median": moving median (``window`` long) of block medians, one block being 1/16
        of the window; robust to the pulses (tensile lobes above, compressive lobes below
        the baseline) as long as they cover less than about half of each block.
        "savgol": Savitzky-Golay (quadratic) smoothing of the same block medians; smoother,
        less robust to outliers.
    window : float, optional
        Baseline window [s]; default 20 mesh periods, or ``DEFAULT_DRIFT_WINDOW_S`` without
        ``mesh_freq``.
    mesh_freq : float, optional
        Mesh frequency [Hz].
    pulse_period : float, optional
        Period of the pulse train [s]: one relative revolution of the gauged gear, in which
        every planet passes once. Given, the blocks are whole periods and each enters with
        its MEAN: every block then holds the same pulses (each planet's, whatever their
        loads), which add a constant instead of a wobble. Needed when the pulses cover more
        than about half of the time (five planets on a sun gauge: tensile lobe and side
        lobes span 3.6 of every 5 mesh periods), where block medians follow the pulses and
        the baseline they leave shifts each pulse's timing (1.1e-3 mesh cycles RMS
        noise-free, against 4e-4 without drift removal); blocks of one planet spacing would
        still wobble with the planets' unequal loads (face-width amplitudes moved by 6 %).

    Returns
    -------
    baseline : ndarray of float64, shape (n,)
        Linearly interpolated between block centres (constant beyond the first and last);
        NaN everywhere when no sample is finite.
    """
    x = as_signal(x, "x", float64=True)
    fs = as_positive(fs, "fs")
    method = as_choice(method, "method", ("median", "savgol"))
    window = drift_window(window, mesh_freq)
    if x.size == 0:
        return np.empty(0)
    return run_whole(DriftFilter(x.size, fs, method=method, window=window,
                                 pulse_period=pulse_period, output="baseline"), x)


def level_steps(values, centres, fs: float, *, t0: float = 0.0, min_size: float = 0.0) -> np.ndarray:
    """Level steps of a channel's baseline: jumps between consecutive drift-baseline blocks
    (:func:`drift_baseline`'s block means or medians) that its slow drift does not make.

    A bridge re-zeroed, an amplifier range switched or a cable knocked moves the baseline
    within a few samples; the drift baseline then ramps across the block holding the jump
    (its values are interpolated between block centres), and the pulses of that stretch sit
    on a slope: they are timed off or lost (independent rig, a step of twice the pulse height
    mid-record: the passes within one relative revolution of it). Thermal drift changes the
    block values smoothly: a step is a change ``d_k`` between blocks that the trend of the
    changes 3 to 5 blocks either side (their median) does not explain, beyond
    :data:`STEP_SPREADS` robust spreads of those residuals and beyond ``min_size``, and that
    stays (the median level of the 5 blocks after it less that of the 5 before, drift
    aside, keeps half of it: a block that caught a pulse goes up and down, a spike); a step
    inside a block splits over two consecutive changes, taken as one.

    Parameters
    ----------
    values : array_like, shape (m,)
        Block values [data units]; NaN where a block had no sample.
    centres : array_like, shape (m,)
        Their centres [samples].
    fs : float
        Sample rate [Hz].
    t0 : float
        Time of sample 0 [s].
    min_size : float
        Smallest step reported [data units] (e.g. a few times the per-sample noise RMS).

    Returns
    -------
    ndarray, shape (k, 2)
        Per step its time [s] (between the two blocks, or the centre of the block it fell
        in) and its size [data units] (the change less its neighbours' trend), in time order;
        empty with fewer than 7 finite blocks (blocks without a sample are interpolated).
    """
    v = np.asarray(values, dtype=np.float64).ravel()
    c = np.asarray(centres, dtype=np.float64).ravel()
    if v.shape != c.shape:
        raise ValueError(f"values and centres must have one shape, got {v.shape} and {c.shape}")
    fs = as_positive(fs, "fs")
    ok = np.isfinite(v)
    if np.count_nonzero(ok) < 7 or not np.all(np.isfinite(c)):
        return np.empty((0, 2))
    if not ok.all():                                    # blocks without a sample: interpolated
        v = np.interp(c, c[ok], v[ok])
    e = _step_residuals(v)
    spread = MAD_TO_SIGMA * float(median_and_mad(e)[1])          # e is finite (v filled)
    thr = max(STEP_SPREADS * spread, float(min_size), 0.0)
    out = []
    v = v.copy()
    spike = np.zeros(e.size, dtype=bool)
    for _ in range(v.size):
        # the largest first, taken out of the values before the next is looked for: the
        # trend of a change next to a large step would otherwise carry a little of it
        j = int(np.argmax(np.where(spike, 0.0, np.abs(e))))
        if not abs(e[j]) > thr or spike[j]:
            break
        pair = [k for k in (j - 1, j + 1)
                if 0 <= k < e.size and abs(e[k]) > thr and np.sign(e[k]) == np.sign(e[j]) and not spike[k]]
        k = max(pair, key=lambda i: abs(e[i])) if pair else j
        a, b = min(j, k), max(j, k)                       # a pair: inside block b
        size = e[a] + (e[b] if b != a else 0.0)
        # a step stays: the level after it is the level before it plus the step, drift
        # aside (a block that caught a pulse goes up and down again: a spike, not a step)
        dv = np.diff(v)
        lo, hi = max(0, a - 5), min(dv.size, b + 6)
        idx = np.r_[lo:a, b + 1:hi]                                 # the drift's changes there
        u = v - _trend_levels(idx, dv[idx], v.size)
        kept = float(np.median(u[b + 1:b + 6])) - float(np.median(u[max(0, a - 4):a + 1]))
        if not (np.sign(kept) == np.sign(size) and abs(kept) > 0.5 * abs(size)):
            spike[a:b + 1] = True
            continue
        t = c[b] if b != a else 0.5 * (c[a] + c[a + 1])
        v[a + 1:] -= e[a]
        if b != a:
            v[b + 1:] -= e[b]
        if abs(size) > min_size:
            out.append((t0 + t / fs, size))
        e = _step_residuals(v)
    out.sort()
    return np.array(out, dtype=np.float64).reshape(-1, 2)


def _trend_levels(idx: np.ndarray, d: np.ndarray, n: int) -> np.ndarray:
    """The levels [data units] of ``n`` blocks that the drift alone gives, from its changes
    ``d`` between blocks ``idx`` and ``idx + 1``: a line through the changes (a quadratic
    drift's changes are linear) by Theil-Sen (the median of the pairwise slopes, so one step
    or spike among them does not tilt it), summed; level 0 at block 0. Fewer than two
    changes: their median as a constant change, or none."""
    if idx.size < 2:
        rate = float(np.median(d)) if d.size else 0.0
        return rate * np.arange(n, dtype=np.float64)
    i, j = np.triu_indices(idx.size, 1)
    slope = float(np.median((d[j] - d[i]) / (idx[j] - idx[i])))
    icpt = float(np.median(d - slope * idx))
    steps = icpt + slope * np.arange(n - 1, dtype=np.float64)
    return np.concatenate(([0.0], np.cumsum(steps)))


def _step_residuals(v: np.ndarray) -> np.ndarray:
    """Each change between consecutive block values less the trend of the changes 3 to 5
    blocks either side (their median: a step among them, or the two parts of one that fell
    inside a block, does not move it; a quadratic drift's changes are linear, and the median
    of a symmetric set is the middle)."""
    d = np.diff(v)
    p = np.pad(d, 5, mode="reflect", reflect_type="odd")
    return d - np.median(np.stack([p[5 + o:5 + o + d.size] for o in (-5, -4, -3, 3, 4, 5)]), axis=0)


class PendingSamples:
    """Samples waiting to go on: arrays, with stretches of all-NaN samples held as lengths."""

    def __init__(self):
        self.parts: list = []        # arrays, or ints (a run of NaN of that length)
        self.start = 0               # global index of the first held sample
        self.n = 0

    def add(self, x: np.ndarray) -> None:
        """Hold ``x`` after the samples held."""
        if x.size == 0:
            return
        if x.size > 64 and math.isnan(x[0]) and math.isnan(x[-1]) and np.isnan(x).all():
            self.parts.append(int(x.size))
        else:
            self.parts.append(x)
        self.n += x.size

    def take(self, k: int) -> np.ndarray:
        """The first ``k`` held samples (removed): a view of the first piece held when they
        lie in it (the pieces are the caller's, never written to), else a float64 copy."""
        p = self.parts[0] if self.parts else None
        if isinstance(p, np.ndarray) and p.size >= k:
            if p.size > k:
                self.parts[0] = p[k:]
            else:
                self.parts.pop(0)
            self.start += k
            self.n -= k
            return p[:k]
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


def minus_interp(x: np.ndarray, a: int, xp: np.ndarray, fp: np.ndarray) -> np.ndarray:
    """``x - np.interp(np.arange(a, a + x.size), xp, fp)``, bit for bit [same units as x].

    A drift baseline's knots sit a pulse period (thousands of samples) apart, and
    ``np.interp`` searches the knots for every sample: here each interval's samples are
    computed at once, with numpy's own steps (``slope * (t - xp[k]) + fp[k]``, the slope
    ``(fp[k+1] - fp[k]) / (xp[k+1] - xp[k])``; ``fp[0]`` before the first knot, ``fp[-1]``
    from the last) on an interval-long scratch array that stays in cache. Knots closer than
    ``INTERP_RUN`` samples on average, values not all finite (numpy's NaN rules) or knots
    not strictly increasing go through ``np.interp``. ``a + x.size`` below 2**53.
    """
    n = x.size
    xp = np.asarray(xp, dtype=np.float64)
    fp = np.asarray(fp, dtype=np.float64)
    if n == 0:
        return np.empty(0)
    if (xp.size < 2 or not xp[-1] - xp[0] >= INTERP_RUN * (xp.size - 1)
            or not np.all(np.isfinite(fp)) or not np.all(xp[1:] > xp[:-1])):
        return x - np.interp(np.arange(a, a + n, dtype=np.float64), xp, fp)
    # sample i (t = a + i) lies in interval k when xp[k] <= t < xp[k + 1]
    cut = np.clip(np.ceil(xp - a), 0, n).astype(np.int64)
    y = np.empty(n)
    c0, c1 = int(cut[0]), int(cut[-1])
    if c0:
        np.subtract(x[:c0], fp[0], out=y[:c0], dtype=np.float64)
    if c1 < n:
        np.subtract(x[c1:], fp[-1], out=y[c1:], dtype=np.float64)
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
            np.subtract(x[i0:i1], d, out=y[i0:i1], dtype=np.float64)
    return y


class DriftFilter:
    """Drift removal with method "median" or "savgol" as a block filter: the baseline of
    block medians / means, smoothed over 17 blocks, interpolated between block centres.

    Parameters
    ----------
    n_total : int
        Samples of the whole signal [-].
    fs : float
        Sample rate [Hz].
    method : {"median", "savgol"}
        As :func:`drift_baseline`.
    window : float
        Baseline window [s] (:func:`drift_window`).
    pulse_period : float or None
        Period of the pulse train [s] (:func:`drift_baseline`).
    output : {"residual", "baseline"}
        What :meth:`push` and :meth:`flush` return: the samples less the baseline, or the
        baseline.

    Attributes
    ----------
    b : int
        Samples per block [-].
    """

    def __init__(self, n_total: int, fs: float, *, method: str, window: float,
                 pulse_period: float | None, output: str = "residual"):
        self.n = int(n_total)
        self.output = as_choice(output, "output", ("residual", "baseline"))
        b_p = None if pulse_period is None else max(
            1, int(round(as_positive(pulse_period, "pulse_period") * fs)))
        if b_p is not None and self.n >= 2 * b_p:
            # means of whole periods only, a partial last block left out: it holds some
            # planets' pulses and not the others', the wobble whole periods avoid
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
        self.pend = PendingSamples()
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
            # block_means leaves every non-finite sample out itself
            with np.errstate(over="ignore", invalid="ignore"):
                total = float(np.sum(seg))
            if not math.isfinite(total):
                seg = np.where(np.isfinite(seg), seg, np.nan)
        if self.means:
            # float64 sums, as of the float64 samples (float32 ones widened exactly); the
            # medians gather their strided samples into float64 rows themselves
            vals, cents = block_means(seg.astype(np.float64, copy=False), self.b)
        else:
            vals, cents = block_medians(seg, self.b)
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
        """:func:`level_steps` of the blocks seen: (time [s], size) rows."""
        if not self.trace:
            return np.empty((0, 2))
        return level_steps(*self._traced(), fs, t0=t0, min_size=min_size)

    # -------------------------------------------------------------- samples
    def push(self, x: np.ndarray) -> np.ndarray:
        """The next samples ``x``; returns the output final so far."""
        return self._step(x, False)

    def flush(self) -> np.ndarray:
        """The output not yet returned (the signal ended)."""
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
            if not self.pend.n:
                return np.empty(0)
            k = self.pend.n
            held = self.pend.take(k)
            return np.full(k, np.nan) if self.output == "baseline" else held * np.nan
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
        if self.output == "baseline":
            y = np.interp(np.arange(a, stop, dtype=np.float64), self.bc[j:], self.bv[j:])
        else:
            y = minus_interp(x, a, self.bc[j:], self.bv[j:])
        # base values no longer needed: all but the one bracketing the next sample
        k = max(0, int(np.searchsorted(self.bc, stop, side="right")) - 1)
        if k:
            self.bv, self.bc, self.b0 = self.bv[k:], self.bc[k:], self.b0 + k
        return y
