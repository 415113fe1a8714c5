"""Plain Monte Carlo reference of the tolerance statistics for ``meshphase bench models``.

A large pseudo-random run (1e7 samples by default) of seed 000 Table 2 case 3, reduced in
bounded memory to exactly what the error table needs: per statistic and planet the mean, the
standard deviation and the two 3-sigma bounds (the sample quantiles at Phi(-3) and Phi(3),
``numpy.quantile``'s linear interpolation, computed exactly from the kept extreme order
statistics), each with a standard error from ``groups`` equal groups of the samples. The
result is cached as JSON in the bench output folder, keyed by everything that defines it, so
reruns of the bench read it back instead of recomputing it.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from ..log import logger
from ..models.tolerance_model import (ALL_STATISTICS, _P3_HI, _P3_LO, _Grid, _map_samples,
                                      default_n_times)
from ..validate import as_positive_int

__all__ = ["plain_reference", "REFERENCE_SUMMARIES"]

#: Summaries held in the reference (and compared by the bench).
REFERENCE_SUMMARIES = ("mean", "std", "bound3_lo", "bound3_hi")


class _Tails:
    """Running k smallest and k largest values per (statistic, planet) column."""

    def __init__(self, k):
        self.k = k
        self.lo = None
        self.hi = None

    def add(self, x):
        # x: (B, C) -> keep the k smallest and k largest over everything seen
        lo = x if self.lo is None else np.concatenate([self.lo, x])
        hi = x if self.hi is None else np.concatenate([self.hi, x])
        k = min(self.k, lo.shape[0])
        self.lo = np.partition(lo, k - 1, axis=0)[:k] if lo.shape[0] > k else lo
        self.hi = (np.partition(hi, hi.shape[0] - k, axis=0)[-k:] if hi.shape[0] > k else hi)

    def quantile(self, n, p):
        """numpy.quantile(x, p) ('linear') of the n values seen, from the kept tails."""
        h = (n - 1) * p
        j = int(math.floor(h))
        frac = h - j
        if p < 0.5:
            s = np.sort(self.lo, axis=0)
            a, b = s[j], s[min(j + 1, s.shape[0] - 1)]
        else:
            s = np.sort(self.hi, axis=0)
            top = s.shape[0]
            a, b = s[top - (n - j)], s[min(top - (n - j) + 1, top - 1)]
        return a + frac * (b - a)


def _tail_k(n, p_lo=_P3_LO, p_hi=_P3_HI):
    return max(int(math.ceil((n - 1) * p_lo)) + 3, n - int(math.floor((n - 1) * p_hi)) + 3)


def _summaries(count, s1, s2, shift, tails):
    mean = shift + s1 / count
    var = (s2 - s1 * s1 / count) / max(count - 1, 1)
    return {"mean": mean, "std": np.sqrt(np.maximum(var, 0.0)),
            "bound3_lo": tails.quantile(count, _P3_LO),
            "bound3_hi": tails.quantile(count, _P3_HI)}


def _run(case, n, seed, groups, batch):
    """Stream n pseudo-random samples in ``groups`` groups; moments and tails per group."""
    g, sp, tol, win = case
    n_p = g.n_planets
    grid = _Grid(g, sp, win, _n_times(sp, win))
    d = tol.n_random(n_p)
    gen = np.random.default_rng(seed)
    sizes = [n // groups + (1 if i < n % groups else 0) for i in range(groups)]
    all_tails = _Tails(_tail_k(n))
    per_group = []
    shift = None
    tot = [0, 0.0, 0.0]
    for m in sizes:
        tails = _Tails(_tail_k(m))
        acc = [0, 0.0, 0.0]
        for a in range(0, m, batch):
            b = min(m, a + batch) - a
            es, ks, er, kr, ep, kp = _map_samples(gen.random((b, d)), tol, n_p)
            x = np.stack(grid.run(es, ks, er, kr, ep, kp, "numba")).transpose(1, 0, 2)
            x = x.reshape(b, -1)                      # columns: statistic-major, then planet
            if shift is None:
                shift = x.mean(axis=0)
            y = x - shift
            for acc_ in (acc, tot):
                acc_[0] += b
                acc_[1] = acc_[1] + y.sum(axis=0)
                acc_[2] = acc_[2] + (y * y).sum(axis=0)
            tails.add(x)
            all_tails.add(x)
        per_group.append(_summaries(acc[0], acc[1], acc[2], shift, tails))
        logger.info("bench models: reference group done (%d samples)", m)
    return _summaries(tot[0], tot[1], tot[2], shift, all_tails), per_group, grid


def _n_times(sp, win):
    return default_n_times(sp, win)


def plain_reference(case, cache_dir, *, n_samples: int = 10 ** 7, seed: int = 20261126,
                    groups: int = 10, batch: int = 1 << 15, case_name: str = "") -> dict:
    """The plain Monte Carlo reference, read from the cache or computed and cached.

    Parameters
    ----------
    case : tuple
        (gearset, speeds, tolerances, window) of the run.
    cache_dir : path-like
        Folder of the cache file ``models_reference_<n>_<seed>.json``.
    n_samples : int
        Pseudo-random samples [-].
    seed : int
        Seed of ``numpy.random.default_rng``.
    groups : int
        Equal groups for the standard errors [-], >= 2.
    batch : int
        Samples per kernel call [-] (bounds the memory).
    case_name : str
        Label stored with the reference (part of the cache key).

    Returns
    -------
    dict
        ``{"values": {summary: {statistic: [N]}}, "stderr": {...}, "n_samples", "seed",
        "wall_time_s", "key", "cached"}``; summaries of :data:`REFERENCE_SUMMARIES`,
        statistics of :data:`meshphase.models.tolerance.ALL_STATISTICS`.
    """
    n = as_positive_int(n_samples, "n_samples")
    groups = as_positive_int(groups, "groups")
    if groups < 2 or n < 2 * groups:
        raise ValueError(f"need groups >= 2 and n_samples >= 2 groups, got {groups}, {n}")
    g, sp, tol, win = case
    key = {"case": case_name, "n_samples": n, "seed": int(seed), "groups": groups,
           "window": win.to_dict(), "n_times": _n_times(sp, win),
           "tolerances": tol.to_dict(), "n_planets": g.n_planets}
    path = Path(cache_dir) / f"models_reference_{n}_{int(seed)}.json"
    if path.is_file():
        try:
            cached = json.loads(path.read_text())
            if cached.get("key") == json.loads(json.dumps(key)):
                cached["cached"] = True
                return cached
        except (OSError, ValueError):
            pass
    t = time.perf_counter()
    total, per_group, grid = _run(case, n, int(seed), groups, as_positive_int(batch, "batch"))
    wall = time.perf_counter() - t
    n_p = g.n_planets

    def split(v):
        v = np.asarray(v).reshape(len(ALL_STATISTICS), n_p)
        return {s: v[i].tolist() for i, s in enumerate(ALL_STATISTICS)}

    values = {k: split(total[k]) for k in REFERENCE_SUMMARIES}
    stderr = {k: split(np.std(np.stack([pg[k] for pg in per_group]), axis=0, ddof=1)
                       / math.sqrt(groups)) for k in REFERENCE_SUMMARIES}
    out = {"key": key, "n_samples": n, "seed": int(seed), "sampler": "random",
           "wall_time_s": wall, "values": values, "stderr": stderr, "cached": False}
    Path(cache_dir).mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(out, indent=1))
    return out
