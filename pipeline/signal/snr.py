"""The noise and peak-power SNR estimate of a pulse train, as a tap on a block stream.

:class:`SnrTap` sees the drift-free samples of a channel in blocks (it passes nothing on):
the noise from the first differences at a stride that keeps at most ``SNR_SAMPLES`` of
the finite ones, the pulse peak from the first ``SNR_SAMPLES`` samples.
:func:`estimate_snr` is the tap fed the whole signal at once; :func:`estimate_noise` the
noise half alone.
"""

from __future__ import annotations

import math

import numpy as np

from ..runtime.lazy import ndimage
from .median import median_of_finite, sigma_of_differences
from .runs import find_runs, merge_runs
from ..validate import as_float, as_signal

__all__ = ["SnrTap", "estimate_noise", "estimate_snr", "finite_pairs", "subsample", "SNR_SAMPLES"]

#: At most this many samples enter a median or quantile of the estimate [-].
SNR_SAMPLES = 1 << 20


def subsample(x: np.ndarray, n_max: int = SNR_SAMPLES) -> np.ndarray:
    """Every k-th sample of ``x`` so that at most ``n_max`` remain (deterministic)."""
    step = max(1, -(-x.size // n_max))
    return x[::step]


def estimate_noise(x) -> float:
    """Robust white-noise standard deviation of ``x`` [units of x].

    ``1.4826 * MAD(diff(x)) / sqrt(2)``: the first difference removes the slow pulse and
    drift content, the MAD ignores the sparse large differences at pulse edges. It
    overestimates the noise when pulses are only a few samples wide (their edges then fill a
    large share of the differences). NaN when fewer than 2 finite neighbours exist.
    """
    x = as_signal(x, "x", float64=True)
    with np.errstate(invalid="ignore"):                # inf - inf: dropped below
        d = np.diff(x)
    return _noise_from_diffs(subsample(d[np.isfinite(d)]))


def _noise_from_diffs(d: np.ndarray) -> float:
    """:func:`estimate_noise` from its (subsampled, finite) first differences."""
    if d.size == 0:
        return float("nan")
    return float(sigma_of_differences(d))


def estimate_snr(x, *, quantile: float = 0.999) -> tuple[float, float, float]:
    """Peak-power SNR estimate of a pulse train (:class:`SnrTap` fed ``x`` whole).

    SNR = 10 log10(A^2 / sigma^2) [dB], the definition of the onset accuracy tests (peak
    pulse power over noise variance): ``sigma`` from :func:`estimate_noise`, ``A`` the
    median pulse peak above the median level. The peaks are the maxima of the runs above
    half the ``quantile`` level of ``x - median(x)``, taken on a copy smoothed over a
    quarter of the median run length (so that the noise on top of a peak does not bias
    it upwards); the median over runs is insensitive to the planets' different loads.
    Uses the first 2**20 samples; needs drift-free data (condition first).

    Returns
    -------
    (snr_db, signal_peak, noise_rms) : tuple of float
        [dB], [units of x], [units of x]; NaN when not computable.
    """
    x = as_signal(x, "x", float64=True)
    q = as_float(quantile, "quantile")
    if not 0.5 < q < 1.0:
        raise ValueError(f"quantile must be in (0.5, 1), got {q!r}")
    tap = SnrTap(x.size, None, q)
    tap.add(x)
    return tap.result()


def _snr_peak(xs: np.ndarray, q: float) -> float:
    """The pulse peak amplitude ``A`` of :func:`estimate_snr` from the finite samples ``xs``
    of the first ``SNR_SAMPLES`` samples (at least 2)."""
    z = xs - median_of_finite(xs)
    top = float(np.quantile(z, q))
    a = top
    runs = find_runs(z > 0.5 * top) if top > 0 else np.empty((0, 2), dtype=np.int64)
    if len(runs):
        # noise chops a pulse's run at its edges: merge runs closer than half a typical
        # pulse run, then drop the slivers
        typ = float(np.quantile(runs[:, 1] - runs[:, 0], 0.9))
        new = np.ones(len(runs), dtype=bool)
        new[1:] = (runs[1:, 0] - runs[:-1, 1]) > 0.5 * typ
        runs = np.stack([runs[new, 0], np.maximum.reduceat(runs[:, 1], np.flatnonzero(new))], 1)
        runs = runs[(runs[:, 1] - runs[:, 0]) >= max(1.0, 0.25 * typ)]
    if len(runs):
        m = max(1, int(np.median(runs[:, 1] - runs[:, 0])) // 4)
        zs = ndimage.uniform_filter1d(z, m, mode="nearest") if m > 1 else z
        a = float(np.median(_run_max(zs, runs)))
    return a


def _snr_combine(sigma: float, a: float | None) -> tuple[float, float, float]:
    """(snr_db, signal_peak, noise_rms) of :func:`estimate_snr` from the noise ``sigma``
    and the peak ``a`` (None: fewer than 2 finite samples in the first ``SNR_SAMPLES``)."""
    if a is None or not np.isfinite(sigma):
        return float("nan"), float("nan"), sigma
    if sigma == 0.0:
        return (float("inf") if a > 0 else float("nan")), a, sigma
    if a <= 0:
        return float("nan"), a, sigma
    return float(20.0 * np.log10(a / sigma)), a, sigma


def _run_max(z: np.ndarray, runs: np.ndarray) -> np.ndarray:
    """Maximum of ``z`` over each ``[start, stop)`` run (runs sorted, disjoint)."""
    edges = runs.ravel()
    if edges[-1] == z.size:
        edges = edges[:-1]
    return np.maximum.reduceat(z, edges)[::2]


def finite_pairs(bad_runs: np.ndarray, n: int) -> int:
    """Number of i in [0, n - 1) with samples i and i + 1 both outside the ``bad_runs``
    (sorted, disjoint ``[start, stop)`` rows): the finite first differences an
    :class:`SnrTap` will see."""
    if n < 2:
        return 0
    if len(bad_runs) == 0:
        return n - 1
    r = np.array(bad_runs, dtype=np.int64).reshape(-1, 2)
    r[:, 0] = np.maximum(r[:, 0] - 1, 0)          # pair i is lost when i or i + 1 is bad
    r[:, 1] = np.minimum(r[:, 1], n - 1)
    r = merge_runs(r[r[:, 1] > r[:, 0]])
    return int((n - 1) - (r[:, 1] - r[:, 0]).sum())


class SnrTap:
    """:func:`estimate_snr` of samples fed in blocks (:meth:`add`; nothing is passed on).

    Parameters
    ----------
    n : int
        Samples of the whole signal [-].
    n_finite_diffs : int or None
        Finite first differences the tap will see (:func:`finite_pairs`): it then keeps
        only those at the stride that leaves at most ``SNR_SAMPLES``, and checks the count
        at the end. None: unknown, every finite difference is kept and strided at the end
        (the whole signal in one block).
    q : float
        Quantile of the peak level [-] (:func:`estimate_snr`).
    """

    def __init__(self, n: int, n_finite_diffs: int | None, q: float = 0.999):
        self.n = n
        self.expect = n_finite_diffs
        self.step = 1 if n_finite_diffs is None else max(1, -(-n_finite_diffs // SNR_SAMPLES))
        self.rank = 0
        self.parts: list[np.ndarray] = []
        self.last = None
        self.pos = 0
        self.n_pre = min(n, SNR_SAMPLES)
        self.pre = np.empty(self.n_pre)
        self.peak = None
        self.peak_done = self.n_pre == 0
        self.q = q

    def add(self, x: np.ndarray) -> None:
        """The next samples ``x`` (float64)."""
        if x.size == 0:
            return
        first = (-self.rank) % self.step
        lo, hi = float(np.min(x)), float(np.max(x))     # NaN when x holds a NaN
        if self.last is not None:
            v = float(self.last[0])
            lo, hi = (min(lo, v), max(hi, v)) if math.isfinite(v) else (math.nan, math.nan)
        if self.expect is not None and math.isfinite(hi - lo):
            # every difference finite (none exceeds hi - lo): only the kept ones computed
            self.parts.append(self._strided(x, first))
            self.rank += x.size - (self.last is None)
        else:
            xx = x if self.last is None else np.concatenate([self.last, x])
            with np.errstate(invalid="ignore", over="ignore"):   # inf - inf: dropped below
                d = np.diff(xx)
            d = d[np.isfinite(d)]
            self.parts.append(d[first::self.step].copy() if self.step > 1 else d)
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
        """(snr_db, signal_peak, noise_rms) of every sample fed: [dB], [units], [units]."""
        if self.expect is not None and self.rank != self.expect:
            raise RuntimeError(f"SNR tap saw {self.rank} finite differences, expected {self.expect}")
        d = np.concatenate(self.parts) if self.parts else np.empty(0)
        if self.expect is None:
            d = subsample(d)
        return _snr_combine(_noise_from_diffs(d), self.peak)
