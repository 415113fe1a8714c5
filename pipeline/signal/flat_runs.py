"""Flat runs of an analogue channel: DAQ dropouts and clipped plateaus, found whole or
from a channel fed in pieces (the statistics in pass 1, the candidates in pass 2).

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

from .median import median_of_finite, sigma_of_differences
from .runs import EqualRuns, as_count, as_samples, equal_runs

__all__ = ["quantisation_step", "chance_min_run", "FlatRuns", "flat_runs", "dropout_runs",
           "plateau_runs", "FlatScan", "FlatStats", "FlatCandidates", "classify_flat_runs",
           "check_false_alarm", "FALSE_ALARM", "DROPOUT_MIN_RUN", "CLIP_MIN_RUN", "FLAT_WINDOW"]

#: Expected number of chance runs over a channel below which a run is significant [-].
FALSE_ALARM = 1e-3
#: Shortest run of equal samples ever reported as a dropout [samples].
DROPOUT_MIN_RUN = 4
#: Shortest plateau ever reported as clipped [samples].
CLIP_MIN_RUN = 3

_SUBSAMPLE = 1 << 20          # samples entering the smoothness test
_ROBUST_SAMPLES = 1 << 16     # samples (and sample pairs) entering the median and the noise
_SMOOTH_SIGN_CHANGES = 0.25   # below this share of sign changes a channel is noise-free
_JUMP_FACTOR = 5.0            # a step above this many local median steps (+ 2 q) is a jump
_STEEP_STEPS = 6.0            # a clip is entered steeply: > this many q inside its level
_EXTEND_SPAN = 512            # samples searched beyond a plateau for more clipped samples
_EXTEND_GAP = 128             # longest dip between two fragments of one clipped plateau

#: Runs of >= 3 equal samples needed before the bulk tail ratios are used (module doc).
_TAIL_RUNS = 30
#: Samples kept on either side of each candidate flat run for its classification
#: [samples]: :func:`classify_flat_runs` reads at most _EXTEND_SPAN + 128 + 1 samples
#: beyond a run's ends (extension, bounding window), and inside runs only their value.
FLAT_WINDOW = _EXTEND_SPAN + 128 + 16


def check_false_alarm(value) -> float:
    """``false_alarm`` as a float in (0, 1) (TypeError for a non-number, ValueError outside)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.number)):
        raise TypeError(f"false_alarm must be a real number, got {type(value).__name__} {value!r}")
    v = float(value)
    if not 0.0 < v < 1.0:
        raise ValueError(f"false_alarm must be in (0, 1), got {value!r}")
    return v


def quantisation_step(x) -> float:
    """Quantisation step ``q`` of a channel [units of x]; 0.0 for continuous data.

    The smallest non-zero absolute first difference among up to 2**18 strided sample pairs
    is taken as ``q`` when at least 99 % of the (up to 65536 examined) non-zero differences
    are integer multiples of it (to 0.01 q) and are below 2**31 q; otherwise the data are
    not on a grid (float64 noise; or noise so large against the step that no one-step
    difference turned up, where the step does not matter) and 0.0 is returned.
    """
    x = as_samples(x)
    pairs = _StridedPairs(x.size, 1 << 18)
    pairs.add(x)
    return _quant_from_pairs(pairs.values())


def _quant_from_pairs(d: np.ndarray) -> float:
    """:func:`quantisation_step` from its strided first differences (finite, in order)."""
    d = np.abs(d)
    d = d[d > 0]
    if d.size < 16:
        return 0.0
    q = float(d.min())
    # a difference beyond float64 over the step (a 1e300 sample, a 1e-20 step) gives an
    # infinite ratio: far above 2**31 steps, and off the grid (inf - inf is NaN, not <= 0.01)
    with np.errstate(over="ignore", invalid="ignore"):
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
    n = as_count(n, "n", 0)
    fa = check_false_alarm(false_alarm)
    if p <= 0.0 or n * p < fa:
        return 2
    if p >= 1.0:
        return n + 1
    return int(1 + math.floor(math.log(fa / n) / math.log(p)) + 1)


def _continuation_prob(n_runs2: int, bulk_counts, n_runs: int) -> float:
    """Upper estimate of the probability that a run of equal samples continues (module doc).

    ``n_runs2``: number of runs of >= 2 equal samples (S(2)); ``bulk_counts``: numbers of
    those runs in the bulk of the signal that are at least 2, 3 and 4 samples long (used for
    the tail ratios); ``n_runs``: number of runs of finite samples of any length (S(1))."""
    if n_runs <= 0:
        return 1.0
    c = float(n_runs2)
    p = (c + 2.0 * math.sqrt(c) + 3.0) / n_runs               # S(2) / S(1), all runs
    s = [float(v) for v in bulk_counts]
    for k in range(2):                                        # S(3) / S(2), S(4) / S(3)
        c = s[k + 1]
        if c < max(30.0, 1e-3 * n_runs):
            break
        p = max(p, (c + 2.0 * math.sqrt(c) + 3.0) / s[k])
    return min(p, 1.0)


def _level_from(xs: np.ndarray, d: np.ndarray) -> tuple[float, float]:
    """(median, per-sample noise sigma) of a channel from its strided finite samples
    ``xs`` and first differences ``d`` (sigma = 1.4826 MAD of the first difference / sqrt 2)."""
    if xs.size == 0:
        return 0.0, 0.0
    med = float(median_of_finite(xs))
    if d.size == 0:
        return med, 0.0
    sig = float(sigma_of_differences(d))
    return med, sig


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

    Notes
    -----
    The channel-wide statistics (:class:`FlatScan`) and the classification of the few
    candidate runs (:func:`classify_flat_runs`) are separate steps, so that a recording
    streamed in blocks gets the same result (:class:`ChannelScan`).
    """
    x = as_samples(x)
    fa = check_false_alarm(false_alarm)
    min_run = as_count(min_run, "min_run", 2)
    clip_min_run = as_count(clip_min_run, "clip_min_run", 2)
    scan = FlatScan(x.size)
    scan.add(x)
    st = scan.stats(false_alarm=fa, min_run=min_run, clip_min_run=clip_min_run)
    cand = equal_runs(x, min_run=st.min_candidate)
    return classify_flat_runs(x, cand, x[cand[:, 0]], st)


def classify_flat_runs(x, runs: np.ndarray, values: np.ndarray, st: "FlatStats") -> FlatRuns:
    """Classify the candidate flat runs of one channel as dropouts or clipped plateaus.

    Parameters
    ----------
    x : ndarray or sample lookup
        The channel's samples, or any object with ``size`` (the channel's length) and
        integer-array indexing that returns the samples within ``WINDOW`` samples of every
        candidate run and inside them (:class:`ChannelScan` keeps exactly those).
    runs : ndarray of int64, shape (k, 2)
        Every maximal run of equal finite samples at least ``st.min_candidate`` long, sorted.
    values : ndarray, shape (k,)
        The value of each run [units of x].
    st : FlatStats
        The channel-wide statistics (:meth:`FlatScan.stats`).

    Returns
    -------
    FlatRuns
    """
    empty = np.empty((0, 2), dtype=np.int64)
    thr_drop, thr_clip, p, clip_min_run = st.thr_drop, st.thr_clip, st.p, st.clip_min_run
    if len(runs) == 0:
        return FlatRuns(empty, empty.copy(), thr_drop, thr_clip, p,
                        st.q if st.n_long >= _TAIL_RUNS else 0.0)
    runs = np.asarray(runs, dtype=np.int64).reshape(-1, 2)
    lengths = runs[:, 1] - runs[:, 0]
    a, b = runs[:, 0], runs[:, 1]
    v = np.asarray(values, dtype=np.float64)
    q, med, sigma = st.q, st.med, st.sigma

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
    rail = (cv == st.hi) | (cv == st.lo)
    cclip = (((sgn != 0) & steep & away & ~cjump) | rail) & (cv != 0.0) & (longest >= thr_clip)
    clip = cclip[cid]

    # ---- dropouts: everything else significant, except a noise-free channel's rest level
    drop = ~clip & (lengths >= thr_drop)
    smooth = None
    if drop.any():
        smooth = st.smooth
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


def dropout_runs(x, **kwargs) -> np.ndarray:
    """Dropout runs of one channel, ``[start, stop)`` rows (:func:`flat_runs`)."""
    return flat_runs(x, **kwargs).dropout_runs


def plateau_runs(x, **kwargs) -> np.ndarray:
    """Clipped plateaus (at any level) of one channel, ``[start, stop)`` rows
    (:func:`flat_runs`)."""
    return flat_runs(x, **kwargs).clipped_runs


class _Strided:
    """``x[::step]`` (finite only) of a channel of ``n`` samples fed in pieces, with
    ``step = max(1, ceil(n / n_max))``."""

    def __init__(self, n: int, n_max: int):
        self.step = max(1, -(-n // n_max))
        self.parts: list[np.ndarray] = []
        self.pos = 0

    def add(self, x: np.ndarray) -> None:
        first = (-self.pos) % self.step
        v = x[first::self.step]
        self.parts.append(v[np.isfinite(v)])
        self.pos += x.size

    def values(self) -> np.ndarray:
        return np.concatenate(self.parts) if self.parts else np.empty(0)


class _StridedPairs:
    """First differences ``x[i+1] - x[i]`` (finite ones) at up to ``n_max`` evenly strided
    ``i`` of a channel of ``n`` samples fed in pieces."""

    def __init__(self, n: int, n_max: int):
        self.n = n
        self.step = max(1, -(-(n - 1) // n_max)) if n >= 2 else 1
        self.parts: list[np.ndarray] = []
        self.pos = 0
        self.last = None

    def add(self, x: np.ndarray) -> None:
        m, pos = x.size, self.pos
        if m == 0:
            return
        if self.n >= 2:
            # pairs (i, i + 1) with i + 1 in this piece: i in [pos - 1, pos + m - 1)
            lo = max(pos - 1, 0)
            first = lo + (-lo) % self.step
            i = np.arange(first, min(pos + m - 1, self.n - 1), self.step) - pos
            if i.size:
                left = x[np.maximum(i, 0)]
                if i[0] < 0:
                    left[0] = self.last
                with np.errstate(invalid="ignore"):    # inf - inf: dropped below
                    d = x[i + 1] - left
                self.parts.append(d[np.isfinite(d)])
        self.last = x[-1]
        self.pos += m

    def values(self) -> np.ndarray:
        return np.concatenate(self.parts) if self.parts else np.empty(0)


class _SmoothTest:
    """Whether a channel has no sample-level noise (few sign changes of the non-zero first
    differences over its first ``min(n, 2**20)`` samples; white noise has 2/3), fed in pieces."""

    def __init__(self, n: int):
        self.limit = min(n, _SUBSAMPLE)
        self.pos = 0
        self.last = None
        self.kept = 0
        self.changes = 0
        self.sign = None

    def add(self, x: np.ndarray) -> None:
        m, pos = x.size, self.pos
        if m and pos < self.limit:
            seg = x[:self.limit - pos]
            xx = seg if self.last is None else np.concatenate(([self.last], seg))
            with np.errstate(invalid="ignore"):        # inf - inf: dropped below
                d = np.diff(xx)
            d = d[np.isfinite(d) & (d != 0)]
            if d.size:
                s = np.signbit(d)
                self.changes += int(np.count_nonzero(s[1:] != s[:-1]))
                if self.sign is not None:
                    self.changes += int(s[0] != self.sign)
                self.sign = bool(s[-1])
                self.kept += d.size
        if m:
            self.last = x[-1]
        self.pos += m

    def result(self) -> bool:
        if self.kept < 16:
            return True
        return bool(self.changes / (self.kept - 1) < _SMOOTH_SIGN_CHANGES)


@dataclass(frozen=True, eq=False)
class FlatStats:
    """The channel-wide statistics behind :func:`flat_runs` (from :meth:`FlatScan.stats`).

    Attributes
    ----------
    n, n_fin : int
        Samples, finite samples [-].
    n_long : int
        Runs of at least 3 equal samples [-].
    q, med, sigma : float
        Quantisation step, median level and per-sample noise sigma [units].
    hi, lo : float
        Largest and smallest finite sample [units] (NaN when none is finite).
    smooth : bool
        The channel has no sample-level noise (few sign changes of its first differences).
    p : float
        Continuation probability of a run of equal samples [-].
    thr_drop, thr_clip : int
        Dropout and plateau run-length thresholds [samples].
    clip_min_run : int
        Floor of the plateau threshold [samples].
    """

    n: int
    n_fin: int
    n_long: int
    q: float
    med: float
    sigma: float
    hi: float
    lo: float
    smooth: bool
    p: float
    thr_drop: int
    thr_clip: int
    clip_min_run: int

    @property
    def min_candidate(self) -> int:
        """Shortest run classified at all [samples]."""
        return min(self.thr_drop, self.thr_clip)


class FlatScan:
    """Accumulates the statistics of :func:`flat_runs` over a channel fed in pieces.

    Parameters
    ----------
    n : int
        Length of the whole channel [samples] (the strided subsamples depend on it).

    Notes
    -----
    Memory is bounded by the subsamples (at most 2**16 + 2**16 + 2**18 values) and a
    histogram of the values at which runs of equal samples occur (one row per distinct
    value: a few thousand for quantised data, ~0 for noisy float data).
    """

    def __init__(self, n: int):
        self.n = int(n)
        self.runs = EqualRuns()
        self.n_fin = 0
        self.n_runs2 = 0
        self.n_long = 0
        self.vals = np.empty(0)
        self.cnt = np.zeros((0, 3), dtype=np.int64)   # per value: runs >= 2, >= 3, >= 4
        self.hi = -np.inf
        self.lo = np.inf
        self.level = _Strided(self.n, _ROBUST_SAMPLES)
        self.pairs16 = _StridedPairs(self.n, _ROBUST_SAMPLES)
        self.pairs18 = _StridedPairs(self.n, 1 << 18)
        self.smooth = _SmoothTest(self.n)
        self.pos = 0
        self.closed = False

    def add(self, x: np.ndarray, finite: np.ndarray | None = None) -> None:
        """Feed the next piece of float64 samples (``finite``: its np.isfinite, if known)."""
        if self.closed:
            raise RuntimeError("FlatScan.add after stats(): the scan is closed")
        if x.size == 0:
            return
        fin = np.isfinite(x) if finite is None else finite
        nf = int(np.count_nonzero(fin))
        self.n_fin += nf
        if nf == x.size:
            self.hi = max(self.hi, float(np.max(x)))
            self.lo = min(self.lo, float(np.min(x)))
        elif nf:
            self.hi = max(self.hi, float(np.max(x, where=fin, initial=-np.inf)))
            self.lo = min(self.lo, float(np.min(x, where=fin, initial=np.inf)))
        self._count(*self.runs.add(x))
        self.level.add(x)
        self.pairs16.add(x)
        self.pairs18.add(x)
        self.smooth.add(x)
        self.pos += x.size

    def _count(self, starts, stops, values) -> None:
        if starts.size == 0:
            return
        L = stops - starts
        self.n_runs2 += int(L.size)
        self.n_long += int(np.count_nonzero(L >= 3))
        u, inv = np.unique(values, return_inverse=True)
        inv = inv.ravel()
        c = np.stack([np.bincount(inv, minlength=u.size),
                      np.bincount(inv, weights=(L >= 3), minlength=u.size),
                      np.bincount(inv, weights=(L >= 4), minlength=u.size)], axis=1).astype(np.int64)
        if self.vals.size:
            allv = np.concatenate([self.vals, u])
            u, inv = np.unique(allv, return_inverse=True)
            cc = np.zeros((u.size, 3), dtype=np.int64)
            np.add.at(cc, inv.ravel(), np.concatenate([self.cnt, c]))
            c = cc
        self.vals, self.cnt = u, c

    def stats(self, *, false_alarm: float = FALSE_ALARM, min_run: int = DROPOUT_MIN_RUN,
              clip_min_run: int = CLIP_MIN_RUN) -> FlatStats:
        """The statistics and thresholds, once every sample has been fed."""
        if not self.closed:
            if self.pos != self.n:
                raise ValueError(f"FlatScan fed {self.pos} samples, the channel has {self.n}")
            self._count(*self.runs.finish())
            self.closed = True
        fa = check_false_alarm(false_alarm)
        min_run = as_count(min_run, "min_run", 2)
        clip_min_run = as_count(clip_min_run, "clip_min_run", 2)
        med, sigma = _level_from(self.level.values(), self.pairs16.values())
        q = _quant_from_pairs(self.pairs18.values())
        if self.n_long >= _TAIL_RUNS:
            bulk = np.abs(self.vals - med) <= 3.0 * sigma + q
            counts = self.cnt[bulk].sum(axis=0)
        else:
            counts = (0, 0, 0)
        p = _continuation_prob(self.n_runs2, counts, self.n_fin - self.runs.n_pairs)
        chance = chance_min_run(p, max(self.n_fin, 1), fa) if self.n_fin else 2
        has = self.n_fin > 0
        return FlatStats(self.n, self.n_fin, self.n_long, q, med, sigma,
                         self.hi if has else float("nan"), self.lo if has else float("nan"),
                         self.smooth.result(), p, max(min_run, chance),
                         max(clip_min_run, chance), clip_min_run)


class FlatCandidates:
    """Maximal runs of equal finite samples at least ``min_len`` long, with the samples
    within ``FLAT_WINDOW`` of their ends, from a channel fed in consecutive pieces.

    With ``cap``, at most ``cap`` runs are held: when one more is found, ``min_len`` is
    raised to the shortest length that at most ``cap // 2`` of the runs held reach, and the
    shorter ones are dropped (a scan that does not know its threshold yet collects from the
    floor up; :meth:`keep_at_least` then tells whether it still holds every run of the
    threshold found at the end)."""

    def __init__(self, n: int, min_len: int, window: int = FLAT_WINDOW, cap: int | None = None):
        self.n = n
        self.min_len = int(min_len)
        self.cap = None if cap is None else max(2, int(cap))
        self.w = int(window)
        self.runs = EqualRuns()
        self.tail = np.empty(0)                  # the last <= w samples before the piece
        self.pos = 0
        self.open_left: tuple | None = None      # (start, left window) of the open run
        self._x = None                           # the piece being fed, and the index of
        self._e0 = 0                             # the tail's first sample
        self.found: list[tuple] = []             # (a, b, v, left window start, left, right)
        self.pending: list[list] = []            # right windows still filling: [row, need]

    def add(self, x: np.ndarray) -> None:
        m, pos = x.size, self.pos
        if m == 0:
            return
        for p in self.pending:                    # right windows of earlier candidates
            row, need = p
            take = x[:need]
            row[5] = np.concatenate([row[5], take])
            p[1] = need - take.size
        self.pending = [p for p in self.pending if p[1] > 0]
        self._x, self._e0 = x, pos - self.tail.size
        was_open = self.runs.open
        starts, stops, values = self.runs.add(x)
        for a, b, v in zip(starts.tolist(), stops.tolist(), values):
            if b - a >= self.min_len:
                self._found(a, b, v)
        op = self.runs.open
        if op is not None and (was_open is None or was_open[0] != op[0]):
            a = op[0]
            lo = max(a - self.w, 0)
            self.open_left = (a, lo, self._slice(lo, a))
        elif op is None:
            self.open_left = None
        # w + 1: a run may start on the previous piece's last sample
        k = self.w + 1
        self.tail = x[-k:].copy() if m >= k else np.concatenate([self.tail, x])[-k:]
        self._x = None
        self.pos = pos + m

    def _slice(self, lo: int, hi: int) -> np.ndarray:
        """Samples [lo, hi) of the tail followed by the current piece (a copy)."""
        e0, t, x = self._e0, self.tail, self._x
        split = e0 + t.size                        # global index of the piece's first sample
        if lo >= split:
            return x[lo - split:hi - split].copy()
        if hi <= split:
            return t[lo - e0:hi - e0].copy()
        return np.concatenate([t[lo - e0:], x[:hi - split]])

    def _found(self, a, b, v) -> None:
        lo = max(a - self.w, 0)
        if self._x is not None and lo >= self._e0:
            left = self._slice(lo, a)
        else:
            if self.open_left is None or self.open_left[0] != a:
                raise RuntimeError(f"flat-run scan lost the left window of the run at {a}")
            _, lo, left = self.open_left
        hi = min(b + self.w, self.n)
        right = self._slice(b, min(hi, self._e0 + self.tail.size + self._x.size)) \
            if self._x is not None else np.empty(0)
        row = [a, b, v, lo, left, right]
        self.found.append(row)
        need = hi - b - right.size
        if need > 0:
            self.pending.append([row, need])
        if self.cap is not None and len(self.found) > self.cap:
            self._raise_min_len()

    def _raise_min_len(self) -> None:
        """``min_len`` raised so that at most ``cap // 2`` of the runs held reach it; the
        shorter runs dropped."""
        lengths = np.sort(np.array([r[1] - r[0] for r in self.found]))[::-1]
        # the (cap // 2 + 1)-th longest run is the longest one that must go
        self.min_len = max(self.min_len, int(lengths[self.cap // 2]) + 1)
        self.found = [r for r in self.found if r[1] - r[0] >= self.min_len]
        kept = {id(r) for r in self.found}
        self.pending = [p for p in self.pending if id(p[0]) in kept]

    def keep_at_least(self, min_len: int) -> bool:
        """Keep only the runs at least ``min_len`` long (after :meth:`finish`); whether those
        are all of them (False: runs of ``min_len`` or longer were dropped under ``cap``,
        or ``min_len`` is below the length collected from)."""
        complete = int(min_len) >= self.min_len
        self.found = [r for r in self.found if r[1] - r[0] >= min_len]
        self.min_len = max(self.min_len, int(min_len))
        return complete

    def finish(self) -> None:
        starts, stops, values = self.runs.finish()
        for a, b, v in zip(starts.tolist(), stops.tolist(), values):
            if b - a >= self.min_len:
                self._found(a, b, v)

    def result(self):
        """(runs, values, sample lookup) for :func:`classify_flat_runs`."""
        if not self.found:
            return np.empty((0, 2), dtype=np.int64), np.empty(0), None
        runs = np.array([[r[0], r[1]] for r in self.found], dtype=np.int64)
        values = np.array([r[2] for r in self.found], dtype=np.float64)
        windows = []
        for a, b, v, lo, left, right in self.found:
            windows.append((lo, left))
            windows.append((b, right))
        return runs, values, _SampleWindows(self.n, windows, runs, values)


class _SampleWindows:
    """The samples of a channel near its candidate flat runs (and inside them: their value),
    indexable like the array by integer arrays; reading anywhere else is an error."""

    def __init__(self, n: int, windows: list, runs: np.ndarray, values: np.ndarray):
        self.size = int(n)
        ws = sorted(((int(a), w) for a, w in windows if w.size), key=lambda t: t[0])
        starts, arrays = [], []
        for a, w in ws:                            # merge overlapping windows (they agree)
            if starts and a <= starts[-1] + arrays[-1].size:
                s0, arr = starts[-1], arrays[-1]
                end = max(s0 + arr.size, a + w.size)
                merged = np.empty(end - s0)
                merged[:arr.size] = arr
                merged[a - s0:a - s0 + w.size] = w
                arrays[-1] = merged
            else:
                starts.append(a)
                arrays.append(w)
        self.starts = np.array(starts, dtype=np.int64)
        self.stops = np.array([s + a.size for s, a in zip(starts, arrays)], dtype=np.int64)
        self.arrays = arrays
        self.runs = runs
        self.values = values

    def __getitem__(self, idx):
        idx = np.asarray(idx, dtype=np.int64)
        out = np.full(idx.shape, np.nan)
        done = np.zeros(idx.shape, dtype=bool)
        if self.starts.size:
            j = np.searchsorted(self.starts, idx, side="right") - 1
            inw = (j >= 0) & (idx < self.stops[np.maximum(j, 0)])
            for k in np.unique(j[inw]):
                sel = inw & (j == k)
                out[sel] = self.arrays[k][idx[sel] - self.starts[k]]
            done |= inw
        if len(self.runs):
            r = np.searchsorted(self.runs[:, 0], idx, side="right") - 1
            inr = ~done & (r >= 0) & (idx < self.runs[np.maximum(r, 0), 1])
            out[inr] = self.values[r[inr]]
            done |= inr
        if not np.all(done):
            raise RuntimeError("flat-run classification read samples the scan did not keep "
                               f"(e.g. index {int(idx[~done].ravel()[0])})")
        return out
