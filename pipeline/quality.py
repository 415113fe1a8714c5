"""Array functions for data-quality flags: runs of NaN/inf, clipped runs, gaps, dropouts.

Numpy in, numpy out; no Recording here (see :meth:`pipeline.Recording.quality`).

Flat runs: DAQ dropouts and clipped plateaus
--------------------------------------------
Besides NaN, an acquisition chain loses data as *flat runs*: a dropout writes exact zeros
or holds the last sample, a saturating ADC or amplifier stage holds a plateau, at any level
(below the nominal full scale, or on one polarity only). :func:`flat_runs` finds both and
tells them apart; every step is a vectorised pass over the samples (``np.diff``,
``np.flatnonzero``) plus work on the few candidate runs.

1. **Runs.** Maximal runs of exactly equal consecutive finite samples (``x[i+1] == x[i]``).
2. **Chance threshold, from the channel's own statistics.** A quantised quiet channel (a
   16-bit ADC with a few LSB of noise) repeats values by chance. With ``p`` the probability
   that a run of equal samples continues (for independent repeats this is the probability
   that two consecutive samples are equal), a run of ``L`` samples has probability
   ``~p^(L-1)`` per position, and the expected number of chance runs that long in ``N``
   finite samples is ``N p^(L-1)``. Runs at least as long as the smallest ``L`` with
   ``N p^(L-1) < false_alarm`` (default 1e-3; :func:`chance_min_run`) are *significant*,
   never shorter than the floors ``min_run`` (dropouts, default 4) and ``clip_min_run``
   (plateaus, default 3).
   ``p`` is estimated from the run-length survival counts ``S(k)`` (number of runs of at
   least ``k`` samples) as the largest continuation ratio ``S(k+1) / S(k)``, k = 1..3, each
   an upper 97.5 % Poisson bound (``(c + 2 sqrt(c) + 3) / S(k)``, c = S(k+1)). The ratios
   for k = 2, 3 count only runs in the bulk of the signal (level within ``3 sigma + q`` of
   the channel median: where a quiet channel's chance repeats are densest, and away from
   the pulse extremes where the fragments of a clipped plateau pile up) and are used only
   while ``S(k+1)`` is at least 30 runs and 0.1 % of all runs. So ``p`` is conservative
   where levels or stretches with different repeat rates mix (it follows the slowest-decaying
   part of the run-length tail), cannot be dragged up by the faults themselves (each fault
   is one run among ~N, whatever its length), and is ~0 for float64 or 24-bit noisy data
   (threshold = the floor: such data never repeat a value by chance).
3. **Clipped plateau or dropout.** A significant run at level ``v`` (with the fragments of
   its plateau, step 5; ``L`` below is the extent of the whole cluster) is a *clipped
   plateau* when all of these hold, else a *dropout*:

   - it bounds the signal around it: every finite sample within ``clip(2 L, 8, 128)``
     samples on either side lies on one side of ``v`` (below for a top clip, above for a
     bottom clip), to within one quantisation step ``q`` (:func:`quantisation_step`);
   - it is entered and left steeply: the mean of the samples ``D/2 .. D`` samples beyond
     each end (``D = clip(L // 2, 2, 64)``) lies more than ``6 q`` (and more than 0) inside
     ``v``. A smooth, unclipped pulse top that a quantiser flattens over ``L`` samples
     (curvature ``8 q / L^2``) drops only ~3 q there, a clip drops at the pulse's slope;
   - it lies away from the baseline: ``|v - median(x)| > 3 sigma + q`` (``sigma`` the robust
     per-sample noise, MAD of the first difference / sqrt 2), i.e. at a pulse extreme;
   - it is reached and left without a jump: the step between ``v`` and the sample beyond
     each end is at most 5 times the larger of ``sigma`` and the median absolute difference
     of the 8 samples beyond that end, plus ``2 q`` (a clip follows the pulse's own pace; in
     noise a step of more than 5 sigma has probability ~1e-6);
   - ``v`` is not exactly 0.0 (the fill value of dropping DAQs).

   A run at the channel's extreme finite value (its rail) that is not 0.0 is a clip whatever
   the tests above say (converter saturation, the rule of :func:`clipped_runs`; a DAQ error
   code written at full scale reads the same). A dropout therefore sits at 0, or at an
   arbitrary mid-signal value that the signal passes through (a held sample on a pulse
   flank: the signal is above it on one side), or on the baseline, or ends with a jump (a
   hold that outlasts the pulse it started on: the signal is back at the baseline when the
   DAQ recovers). The one ambiguous case, a sample
   held briefly at a pulse's own maximum (no jump when it ends), is reported as clipped;
   either flag takes the pulse out of the clean set.
4. **Noise-free channels.** In a channel without sample-level noise (synthetic, noise-free
   data: fewer than 25 % sign changes between consecutive non-zero first differences; white
   noise gives 2/3) a constant rest level between pulses is signal, not a fault, and the
   chance model does not apply. There a significant run that is not a clip counts as a
   dropout only when it is entered or left by a jump (as defined above: dropping to zero
   inside a pulse, or the signal having moved on during a hold). A dropout at exactly the
   rest level of a noise-free channel is undetectable, and harmless.
5. **Clip extent.** Noise makes the signal dip below a clip level near the plateau's ends,
   splitting the clipped samples into fragments. Every significant run whose level could
   be a clip (not 0.0, away from the baseline) is first extended over the samples within
   ``q`` of its level that follow each other with gaps of at most
   ``clip(L // 4, clip_min_run, 128)`` samples (searching up to 512 samples beyond each
   end); overlapping extents at one level (values within ``q``) form a cluster, classified
   once (the tests above, on the cluster's extent, at the level of its longest run). Runs
   at other levels (a dropout inside a clipped pulse) stay apart, and an end that borders
   another flat run gives no evidence for the jump and steepness tests. A clipped cluster
   is reported whole, from its first to its last sample at the level (the dips between are
   inside); a dropout is reported as its exact run of equal samples.

Flagged sample ranges: a dropout writing zeros is flagged exactly; a held-value dropout
starts one sample early (the last good sample equals its held copies and is
indistinguishable from them), and in a quantised channel it also takes in the following
samples that happen to equal the held value (probability ``p`` each).

Limits: a dropout shorter than the threshold is not seen (with 1 LSB of noise on a 16-bit
channel the threshold is ~21 samples: below that, chance repeats are as likely); neither is
one at the rest level of a noise-free channel, nor a channel that is constant throughout
(one run: no statistics to call it improbable). A clip followed by more than one step of
noise (added downstream of the saturating stage) is not flat and is not found. At 20 dB
SNR a few isolated samples that the noise lifted over the clip level, far out on the
flanks, stay outside the reported extent. Pulse trains (a tacho) are flat by design: do
not pass them. Cost on clean float data: one comparison pass and ``np.flatnonzero``, a few
ms per million samples; the candidate runs add work in proportion to their number.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["find_runs", "nonfinite_runs", "clipped_runs", "channel_quality", "equal_runs",
           "quantisation_step", "chance_min_run", "FlatRuns", "flat_runs", "dropout_runs",
           "plateau_runs", "outside_runs", "FALSE_ALARM", "DROPOUT_MIN_RUN", "CLIP_MIN_RUN"]

#: Expected number of chance runs over a channel below which a run is significant [-].
FALSE_ALARM = 1e-3
#: Shortest run of equal samples ever reported as a dropout [samples].
DROPOUT_MIN_RUN = 4
#: Shortest plateau ever reported as clipped [samples].
CLIP_MIN_RUN = 3

_MAD_TO_SIGMA = 1.482602218505602
_SUBSAMPLE = 1 << 20          # samples entering the smoothness test
_ROBUST_SAMPLES = 1 << 16     # samples (and sample pairs) entering the median and the noise
_SMOOTH_SIGN_CHANGES = 0.25   # below this share of sign changes a channel is noise-free
_JUMP_FACTOR = 5.0            # a step above this many local median steps (+ 2 q) is a jump
_STEEP_STEPS = 6.0            # a clip is entered steeply: > this many q inside its level
_EXTEND_SPAN = 512            # samples searched beyond a plateau for more clipped samples
_EXTEND_GAP = 128             # longest dip between two fragments of one clipped plateau


def find_runs(mask) -> np.ndarray:
    """Start and stop indices of the runs of True in a 1-D boolean mask.

    Parameters
    ----------
    mask : array_like of bool, shape (n,)

    Returns
    -------
    runs : ndarray of int64, shape (n_runs, 2)
        ``[start, stop)`` sample indices of each run, in order; shape (0, 2) when none.
    """
    m = np.asarray(mask, dtype=bool)
    if m.ndim != 1:
        raise ValueError(f"mask must be 1-D, got shape {m.shape}")
    if m.size == 0:
        return np.empty((0, 2), dtype=np.int64)
    d = np.diff(m.view(np.int8), prepend=np.int8(0), append=np.int8(0))
    starts = np.flatnonzero(d == 1)
    stops = np.flatnonzero(d == -1)
    return np.stack([starts, stops], axis=1).astype(np.int64)


def nonfinite_runs(x) -> np.ndarray:
    """Runs of NaN or +-inf samples in a 1-D array, as ``[start, stop)`` rows."""
    x = np.asarray(x)
    if x.ndim != 1:
        raise ValueError(f"x must be 1-D, got shape {x.shape}")
    return find_runs(~np.isfinite(x))


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
    tol = rtol * (hi - lo)
    at_rail = (x >= hi - tol) | (x <= lo + tol)
    runs = find_runs(at_rail)
    return runs[(runs[:, 1] - runs[:, 0]) >= min_run]


# ====================================================================== flat runs
def _as_1d(x, name: str = "x") -> np.ndarray:
    arr = np.asarray(x)
    if arr.dtype.kind not in "fiub":
        raise TypeError(f"{name} must be a numeric array, got dtype {arr.dtype}")
    if arr.ndim != 1:
        raise ValueError(f"{name} must be 1-D, got shape {arr.shape}")
    return arr.astype(np.float64, copy=False)


def _check_int(value, name: str, lowest: int) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be an integer, got {type(value).__name__} {value!r}")
    if int(value) < lowest:
        raise ValueError(f"{name} must be >= {lowest}, got {value!r}")
    return int(value)


def _check_false_alarm(value) -> float:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.number)):
        raise TypeError(f"false_alarm must be a real number, got {type(value).__name__} {value!r}")
    v = float(value)
    if not 0.0 < v < 1.0:
        raise ValueError(f"false_alarm must be in (0, 1), got {value!r}")
    return v


def _equal_pairs(x: np.ndarray) -> np.ndarray:
    """Indices ``i`` with ``x[i+1] == x[i]``, both finite (``inf == inf`` excluded)."""
    if x.size < 2:
        return np.empty(0, dtype=np.int64)
    eq = x[1:] == x[:-1]
    idx = np.flatnonzero(eq)
    if idx.size:
        idx = idx[np.isfinite(x[idx])]
    return idx


def _runs_from_pairs(idx: np.ndarray) -> np.ndarray:
    """Sample runs ``[start, stop)`` from sorted equal-pair indices (pair i joins i, i+1)."""
    if idx.size == 0:
        return np.empty((0, 2), dtype=np.int64)
    new = np.ones(idx.size, dtype=bool)
    new[1:] = np.diff(idx) > 1
    starts = idx[new]
    last = np.ones(idx.size, dtype=bool)
    last[:-1] = new[1:]
    stops = idx[last] + 2
    return np.stack([starts, stops], axis=1).astype(np.int64)


def equal_runs(x, *, min_run: int = 2) -> np.ndarray:
    """Runs of at least ``min_run`` consecutive, exactly equal, finite samples.

    Parameters
    ----------
    x : array_like, shape (n,)
        Samples [any unit]; NaN/inf break runs.
    min_run : int
        Shortest run reported [samples], >= 2.

    Returns
    -------
    runs : ndarray of int64, shape (k, 2)
        ``[start, stop)`` of each maximal run, in order.
    """
    x = _as_1d(x)
    min_run = _check_int(min_run, "min_run", 2)
    runs = _runs_from_pairs(_equal_pairs(x))
    return runs[(runs[:, 1] - runs[:, 0]) >= min_run]


def quantisation_step(x) -> float:
    """Quantisation step ``q`` of a channel [units of x]; 0.0 for continuous data.

    The smallest non-zero absolute first difference among up to 2**18 strided sample pairs
    is taken as ``q`` when at least 99 % of the (up to 65536 examined) non-zero differences
    are integer multiples of it (to 0.01 q) and are below 2**31 q; otherwise the data are
    not on a grid (float64 noise; or noise so large against the step that no one-step
    difference turned up, where the step does not matter) and 0.0 is returned.
    """
    x = _as_1d(x)
    d = np.abs(_strided_pairs(x, 1 << 18))
    d = d[d > 0]
    if d.size < 16:
        return 0.0
    q = float(d.min())
    r = d[:: max(1, d.size >> 16)] / q
    if np.median(r) > 2.0 ** 31:
        return 0.0
    on_grid = np.abs(r - np.rint(r)) <= 0.01
    return q if np.mean(on_grid) >= 0.99 else 0.0


def chance_min_run(p: float, n: int, false_alarm: float = FALSE_ALARM) -> int:
    """Shortest run of equal samples that chance produces less than ``false_alarm`` times.

    Smallest ``L >= 2`` with ``n p^(L-1) < false_alarm`` [samples]: ``p`` the probability
    that a run of equal samples continues, ``n`` the number of samples. ``p <= 0`` gives 2;
    ``p >= 1`` gives ``n + 1`` (no run is improbable).
    """
    if isinstance(p, (bool, np.bool_)) or not isinstance(p, (int, float, np.number)):
        raise TypeError(f"p must be a real number, got {type(p).__name__} {p!r}")
    p = float(p)
    if not 0.0 <= p <= 1.0:
        raise ValueError(f"p must be in [0, 1], got {p!r}")
    n = _check_int(n, "n", 0)
    fa = _check_false_alarm(false_alarm)
    if p <= 0.0 or n * p < fa:
        return 2
    if p >= 1.0:
        return n + 1
    return int(1 + math.floor(math.log(fa / n) / math.log(p)) + 1)


def _continuation_prob(lengths: np.ndarray, bulk: np.ndarray, n_runs: int) -> float:
    """Upper estimate of the probability that a run of equal samples continues (module doc).

    ``lengths``: length of every run of >= 2 equal samples; ``bulk``: whether the run lies
    in the bulk of the signal (used for the tail ratios); ``n_runs``: number of runs of
    finite samples of any length (S(1))."""
    if n_runs <= 0:
        return 1.0
    c = float(lengths.size)
    p = (c + 2.0 * math.sqrt(c) + 3.0) / n_runs               # S(2) / S(1), all runs
    lb = lengths[bulk]
    s = [float(np.count_nonzero(lb >= k)) for k in (2, 3, 4)]
    for k in range(2):                                        # S(3) / S(2), S(4) / S(3)
        c = s[k + 1]
        if c < max(30.0, 1e-3 * n_runs):
            break
        p = max(p, (c + 2.0 * math.sqrt(c) + 3.0) / s[k])
    return min(p, 1.0)


def _strided_pairs(x: np.ndarray, n_max: int) -> np.ndarray:
    """First differences ``x[i+1] - x[i]`` at up to ``n_max`` evenly strided ``i``, finite."""
    if x.size < 2:
        return np.empty(0)
    i = np.arange(0, x.size - 1, max(1, -(-(x.size - 1) // n_max)))
    d = x[i + 1] - x[i]
    return d[np.isfinite(d)]


def _robust_level(x: np.ndarray) -> tuple[float, float]:
    """(median, per-sample noise sigma) of the finite samples, from up to 2**16 strided
    samples and sample pairs (sigma = 1.4826 MAD of the first difference / sqrt 2)."""
    xs = x[:: max(1, -(-x.size // _ROBUST_SAMPLES))]
    xs = xs[np.isfinite(xs)]
    if xs.size == 0:
        return 0.0, 0.0
    med = float(np.median(xs))
    d = _strided_pairs(x, _ROBUST_SAMPLES)
    if d.size == 0:
        return med, 0.0
    sig = float(_MAD_TO_SIGMA * np.median(np.abs(d - np.median(d))) / math.sqrt(2.0))
    return med, sig


def _is_smooth(x: np.ndarray) -> bool:
    """True for a channel without sample-level noise (few sign changes of the non-zero
    first differences; white noise has 2/3)."""
    d = np.diff(x[:_SUBSAMPLE])
    d = d[np.isfinite(d) & (d != 0)]
    if d.size < 16:
        return True
    return bool(np.mean(np.signbit(d[1:]) != np.signbit(d[:-1])) < _SMOOTH_SIGN_CHANGES)


def _side(x: np.ndarray, edge: np.ndarray, width: int, direction: int) -> np.ndarray:
    """Samples beyond each run end, nearest first: row i holds ``x[edge_i + direction * j]``
    for j = 0..width-1 (``edge`` = start-1 going left, stop going right); NaN off the data."""
    j = np.arange(width)
    idx = edge[:, None] + direction * j[None, :]
    ok = (idx >= 0) & (idx < x.size)
    out = np.full(idx.shape, np.nan)
    out[ok] = x[idx[ok]]
    return out


def _jumps(x: np.ndarray, a: np.ndarray, b: np.ndarray, v: np.ndarray, q: float,
           sigma: float, flat: np.ndarray) -> np.ndarray:
    """Whether the flat runs ``[a, b)`` at level ``v`` are entered or left by a jump: a step
    from the sample beyond an end to ``v`` above ``_JUMP_FACTOR`` times the larger of the
    median absolute difference of the 8 samples beyond that end and the channel's noise
    ``sigma``, plus ``2 q`` (a clip is reached and left at the pulse's own pace; a dropout
    falls to zero or ends where the signal went). A neighbour inside another of the sorted,
    disjoint ``flat`` runs (a dropout next to a plateau) is no evidence either way."""
    jump = np.zeros(a.size, dtype=bool)
    for edge, direction in ((a - 1, -1), (b, +1)):
        sd = _side(x, edge, 9, direction)
        scale = np.nan_to_num(_row_nanmedian(np.abs(np.diff(sd, axis=1))), nan=0.0)
        scale = np.maximum(scale, sigma)
        with np.errstate(invalid="ignore"):
            jump |= ~_in_runs(edge, flat) & (np.abs(sd[:, 0] - v) > _JUMP_FACTOR * scale + 2.0 * q)
    return jump


def _in_runs(i: np.ndarray, runs: np.ndarray) -> np.ndarray:
    """Whether each index ``i`` lies inside one of the sorted, disjoint ``[start, stop)`` runs."""
    j = np.searchsorted(runs[:, 0], i, side="right") - 1
    return (j >= 0) & (i < runs[np.maximum(j, 0), 1])


def _row_nanmedian(a: np.ndarray) -> np.ndarray:
    """Median of the finite entries of each row; NaN (no warning) for rows without any."""
    out = np.full(a.shape[0], np.nan)
    ok = np.isfinite(a).any(axis=1)
    if ok.any():
        out[ok] = np.nanmedian(np.where(np.isfinite(a[ok]), a[ok], np.nan), axis=1)
    return out


def _row_nanmean(a: np.ndarray) -> np.ndarray:
    """Mean of the finite entries of each row; NaN (no warning) for rows without any."""
    fin = np.isfinite(a)
    cnt = fin.sum(axis=1)
    tot = np.where(fin, a, 0.0).sum(axis=1)
    return np.where(cnt > 0, tot / np.maximum(cnt, 1), np.nan)


@dataclass(frozen=True, eq=False)
class FlatRuns:
    """Result of :func:`flat_runs`.

    Attributes
    ----------
    dropout_runs : ndarray of int64, shape (k, 2)
        ``[start, stop)`` of the dropout runs (zeros or a held value; treat as gaps).
    clipped_runs : ndarray of int64, shape (k, 2)
        ``[start, stop)`` of the clipped plateaus (any level), extended over their fragments.
    min_run : int
        Shortest run reported as a dropout [samples] (chance threshold or floor).
    clip_min_run : int
        Shortest plateau reported as clipped [samples].
    p_equal : float
        Upper estimate of the probability that a run of equal samples continues [-].
    quant_step : float
        Quantisation step found [units]; 0.0 for continuous data or when not examined (it
        is, when at least 30 runs of 3 or more equal samples exist, or any candidate run).
    smooth : bool or None
        The channel has no sample-level noise (None: not examined, no candidate run).
    """

    dropout_runs: np.ndarray
    clipped_runs: np.ndarray
    min_run: int
    clip_min_run: int
    p_equal: float
    quant_step: float = 0.0
    smooth: bool | None = None


def flat_runs(x, *, false_alarm: float = FALSE_ALARM, min_run: int = DROPOUT_MIN_RUN,
              clip_min_run: int = CLIP_MIN_RUN) -> FlatRuns:
    """Dropout runs and clipped plateaus of one analogue channel (module docstring).

    Parameters
    ----------
    x : array_like, shape (n,)
        Raw (unfiltered) samples of one strain channel [any unit]; NaN/inf are gaps and
        break runs. Not meant for pulse-train (tacho) channels, which are flat by design.
    false_alarm : float
        Expected number of chance runs over the channel at the threshold [-], in (0, 1).
    min_run : int
        Floor of the dropout threshold [samples], >= 2.
    clip_min_run : int
        Floor of the plateau threshold [samples], >= 2.

    Returns
    -------
    FlatRuns
    """
    x = _as_1d(x)
    fa = _check_false_alarm(false_alarm)
    min_run = _check_int(min_run, "min_run", 2)
    clip_min_run = _check_int(clip_min_run, "clip_min_run", 2)
    empty = np.empty((0, 2), dtype=np.int64)
    idx = _equal_pairs(x)
    n_fin = int(np.count_nonzero(np.isfinite(x))) if x.size else 0
    runs = _runs_from_pairs(idx)
    lengths = runs[:, 1] - runs[:, 0]
    if np.count_nonzero(lengths >= 3) >= 30:                 # enough for a tail ratio
        q = quantisation_step(x)
        med, sigma = _robust_level(x)
        bulk = np.abs(x[runs[:, 0]] - med) <= 3.0 * sigma + q
    else:
        q = med = sigma = None
        bulk = np.zeros(len(runs), dtype=bool)
    p = _continuation_prob(lengths, bulk, n_fin - idx.size)
    chance = chance_min_run(p, max(n_fin, 1), fa) if n_fin else 2
    thr_drop, thr_clip = max(min_run, chance), max(clip_min_run, chance)
    cand = lengths >= min(thr_drop, thr_clip)
    if not cand.any():
        return FlatRuns(empty, empty.copy(), thr_drop, thr_clip, p, q or 0.0)
    runs, lengths = runs[cand], lengths[cand]
    a, b = runs[:, 0], runs[:, 1]
    v = x[a]
    if q is None:
        q = quantisation_step(x)
        med, sigma = _robust_level(x)

    # ---- each candidate extended over the samples at its level (a clip's fragments);
    # overlapping extents at one level (values within q) form a cluster, classified once
    k = runs.shape[0]
    ext = runs.copy()
    level = (v != 0.0) & (np.abs(v - med) > 3.0 * sigma + q)      # could be a clip level
    if level.any():
        ext[level] = _extend(x, runs[level], v[level], q, clip_min_run)
    vs = np.argsort(v, kind="stable")
    grp = np.empty(k, dtype=np.int64)
    grp[vs] = np.cumsum(np.concatenate([[0], np.diff(v[vs]) > q]))
    off = grp * (x.size + 1)                             # groups never overlap each other
    order = np.lexsort((ext[:, 0], grp))
    ends = np.maximum.accumulate(ext[order, 1] + off[order])
    new = np.ones(k, dtype=bool)
    new[1:] = ext[order[1:], 0] + off[order[1:]] > ends[:-1]
    cid = np.empty(k, dtype=np.int64)
    cid[order] = np.cumsum(new) - 1
    nc = int(new.sum())
    ca = np.full(nc, np.iinfo(np.int64).max)
    np.minimum.at(ca, cid, ext[:, 0])
    cb = np.zeros(nc, dtype=np.int64)
    np.maximum.at(cb, cid, ext[:, 1])
    longest = np.zeros(nc, dtype=np.int64)
    np.maximum.at(longest, cid, lengths)
    # representative run of each cluster: its longest (first such) member
    by = np.lexsort((np.arange(k), -lengths, cid))
    first = np.ones(k, dtype=bool)
    first[1:] = cid[by[1:]] != cid[by[:-1]]
    cv = v[by[first]]
    cl = cb - ca
    # ---- clipped plateau: bound, steep, away from the baseline, not 0.0
    wb = np.clip(2 * cl, 8, 128)
    width = int(wb.max())
    within = np.arange(width)[None, :] < wb[:, None]
    left = np.where(within, _side(x, ca - 1, width, -1), np.nan)
    right = np.where(within, _side(x, cb, width, +1), np.nan)
    both = np.concatenate([left, right], axis=1)
    fin = np.isfinite(both)
    has_any = fin.any(axis=1)
    above = np.where(fin, both - cv[:, None], -np.inf).max(axis=1)    # largest excess over v
    below = np.where(fin, cv[:, None] - both, -np.inf).max(axis=1)    # largest shortfall
    top = has_any & (above <= q) & (below > q)
    bottom = has_any & (below <= q) & (above > q)
    sgn = np.where(top, 1.0, np.where(bottom, -1.0, 0.0))
    dd = np.clip(cl // 2, 2, 64)                       # <= wb: inside the windows above
    jj = np.arange(int(dd.max()))[None, :]
    far = (jj >= (dd // 2 - 1)[:, None]) & (jj < dd[:, None])
    steep = np.ones(nc, dtype=bool)
    for sd, edge in ((left, ca - 1), (right, cb)):
        m = _row_nanmean(np.where(far, sd[:, :far.shape[1]], np.nan))
        inner = sgn * (cv - m)
        steep &= np.isnan(m) | _in_runs(edge, runs) | ((inner > _STEEP_STEPS * q) & (inner > 0.0))
    away = sgn * (cv - med) > 3.0 * sigma + q
    cjump = _jumps(x, ca, cb, cv, q, sigma, runs)
    fin_x = x[np.isfinite(x)]
    rail = (cv == fin_x.max()) | (cv == fin_x.min())
    cclip = (((sgn != 0) & steep & away & ~cjump) | rail) & (cv != 0.0) & (longest >= thr_clip)
    clip = cclip[cid]

    # ---- dropouts: everything else significant, except a noise-free channel's rest level
    drop = ~clip & (lengths >= thr_drop)
    smooth = None
    if drop.any():
        smooth = _is_smooth(x)
        if smooth:
            drop &= _jumps(x, a, b, v, q, sigma, runs) | ~has_any[cid]
    clipped = np.stack([ca[cclip], cb[cclip]], axis=1).astype(np.int64)
    return FlatRuns(runs[drop], clipped, thr_drop, thr_clip, p, q, smooth)


def _extend(x: np.ndarray, runs: np.ndarray, v: np.ndarray, q: float,
            clip_min_run: int) -> np.ndarray:
    """Each run extended over the samples at its level ``v`` (within ``q``) that follow each
    other with gaps of at most ``clip(L // 4, clip_min_run, _EXTEND_GAP)`` samples (at most
    ``_EXTEND_SPAN`` samples searched beyond each end); one row per run, not merged."""
    lengths = runs[:, 1] - runs[:, 0]
    gap = np.clip(lengths // 4, clip_min_run, max(clip_min_run, _EXTEND_GAP))
    span = int(min(_EXTEND_SPAN, 4 * int(gap.max()) + 1))
    j = np.arange(span)[None, :]
    rows = np.arange(len(runs))
    out = runs.copy()
    for col, edge, direction in ((0, runs[:, 0] - 1, -1), (1, runs[:, 1], +1)):
        sd = _side(x, edge, span, direction)
        at = np.abs(sd - v[:, None]) <= q                          # NaN compares False
        last = np.maximum.accumulate(np.where(at, j, -1), axis=1)   # last at-level so far
        broken = (j - last) > gap[:, None]
        first = np.where(broken.any(axis=1), broken.argmax(axis=1), span)
        reach = np.where(first > 0, last[rows, np.maximum(first - 1, 0)] + 1, 0)
        out[:, col] += direction * reach
    return out


def _merge_sorted(r: np.ndarray) -> np.ndarray:
    r = r[np.argsort(r[:, 0], kind="stable")]
    ends = np.maximum.accumulate(r[:, 1])
    new = np.ones(len(r), dtype=bool)
    new[1:] = r[1:, 0] > ends[:-1]
    return np.stack([r[new, 0], np.maximum.reduceat(r[:, 1], np.flatnonzero(new))],
                    axis=1).astype(np.int64)


def _as_runs(runs, name: str) -> np.ndarray:
    r = np.asarray(runs)
    if r.size == 0:
        return np.empty((0, 2), dtype=np.int64)
    if r.dtype.kind not in "iu":
        raise TypeError(f"{name} must be integer [start, stop) rows, got dtype {r.dtype}")
    if r.ndim != 2 or r.shape[1] != 2:
        raise ValueError(f"{name} must have shape (k, 2), got {r.shape}")
    return r.astype(np.int64)


def outside_runs(runs, cover) -> np.ndarray:
    """The rows of ``runs`` not contained in one row of ``cover`` (both ``[start, stop)``;
    ``cover`` sorted and disjoint), e.g. rail runs that are really dropouts at the rail."""
    r, c = _as_runs(runs, "runs"), _as_runs(cover, "cover")
    if len(r) == 0 or len(c) == 0:
        return r
    j = np.searchsorted(c[:, 0], r[:, 0], side="right") - 1
    inside = (j >= 0) & (r[:, 1] <= c[np.maximum(j, 0), 1])
    return r[~inside]


def dropout_runs(x, **kwargs) -> np.ndarray:
    """Dropout runs of one channel, ``[start, stop)`` rows (:func:`flat_runs`)."""
    return flat_runs(x, **kwargs).dropout_runs


def plateau_runs(x, **kwargs) -> np.ndarray:
    """Clipped plateaus (at any level) of one channel, ``[start, stop)`` rows
    (:func:`flat_runs`)."""
    return flat_runs(x, **kwargs).clipped_runs


def _pulse_train(x: np.ndarray) -> bool:
    """True when the finite samples take at most 8 distinct values (4096 strided ones)."""
    xs = x[:: max(1, x.size // 4096)]
    xs = xs[np.isfinite(xs)]
    return xs.size > 0 and np.unique(xs).size <= 8


def channel_quality(x, *, kind: str | None = None) -> dict:
    """Summary of one channel: counts and runs of non-finite, dropout and clipped samples, range.

    Parameters
    ----------
    x : array_like, shape (n,)
        Raw samples of one channel [any unit].
    kind : str, optional
        Channel kind (:class:`pipeline.recording.ChannelSpec`). A "tacho" is a pulse train,
        flat by design: its dropout and plateau analysis is skipped (the rail runs at its
        two levels are still listed as clipped, as before). Without a kind, a channel whose
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
    nf = nonfinite_runs(x)
    cl = clipped_runs(x)
    if kind == "tacho" or x.size == 0 or (kind is None and _pulse_train(x)):
        dr, thr = np.empty((0, 2), dtype=np.int64), None
    else:
        fr = flat_runs(x)
        dr, thr = fr.dropout_runs, fr.min_run
        cl = outside_runs(cl, dr)             # a dropout at the channel's min/max is no clip
        if len(fr.clipped_runs):
            cl = _merge_sorted(np.concatenate([cl, fr.clipped_runs]))
    finite = x[np.isfinite(x)]
    dl = dr[:, 1] - dr[:, 0]
    return {
        "n_samples": int(x.size),
        "n_nonfinite": int((nf[:, 1] - nf[:, 0]).sum()),
        "nonfinite_runs": nf.tolist(),
        "longest_nonfinite_run": int((nf[:, 1] - nf[:, 0]).max()) if len(nf) else 0,
        "n_clipped_runs": int(len(cl)),
        "clipped_runs": cl.tolist(),
        "n_dropout_runs": int(len(dr)),
        "dropout_runs": dr.tolist(),
        "n_dropout_samples": int(dl.sum()),
        "longest_dropout_run": int(dl.max()) if dl.size else 0,
        "dropout_min_run": thr,
        "min": float(finite.min()) if finite.size else float("nan"),
        "max": float(finite.max()) if finite.size else float("nan"),
        "rms": float(np.sqrt(np.mean(np.square(finite, dtype=np.float64)))) if finite.size else float("nan"),
    }
