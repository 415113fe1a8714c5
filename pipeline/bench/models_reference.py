"""Monte Carlo references of the tolerance statistics for ``meshphase bench models``.

:func:`directional_reference` (the default of the bench): 1e7 full-model evaluations of seed
000 Table 2 case 3 spent on the directional control-variate estimator of
:mod:`.models_reference_tail` (2.5e6 rays x 4 radii), which resolves the means, standard
deviations and 3-sigma bounds to relative standard errors of about 1e-4 and below (the plain
run below: 1e-3 on the bounds); it needs what the linear model needs (normal radial bands with
zero mean, fixed angles) and raises ValueError otherwise.

:func:`plain_reference` (the fallback): a large pseudo-random run (1e7 samples by default)
of seed 000 Table 2 case 3, reduced in bounded memory to exactly what the error table
needs: per statistic and planet the mean, the standard deviation and the two 3-sigma bounds
(the sample quantiles at Phi(-3) and Phi(3), ``numpy.quantile``'s linear interpolation,
computed exactly from the kept extreme order statistics), each with a standard error from
``groups`` equal groups of the samples. Both are cached as JSON in the bench output folder,
keyed by everything that defines them, so reruns of the bench read them back instead of
recomputing them.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from scipy import special

from ..jsonable import to_jsonable
from ..runtime.log import logger
from ..models import _kernels
from ..models.tolerance_model import (ALL_STATISTICS, P3_HI, P3_LO, RotationGrid, map_samples,
                                      map_values, default_n_times)
from ..validate import as_positive_int
from .models_reference_tail import directional_bounds, interpolation_check

__all__ = ["plain_reference", "directional_reference", "REFERENCE_SUMMARIES"]

#: Label of the bench's case (part of the cache keys).
CASE3_NAME = "seed000 Table 2 case 3 (angles given)"
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


def _tail_k(n, p_lo=P3_LO, p_hi=P3_HI):
    return max(int(math.ceil((n - 1) * p_lo)) + 3, n - int(math.floor((n - 1) * p_hi)) + 3)


def _summaries(count, s1, s2, shift, tails):
    mean = shift + s1 / count
    var = (s2 - s1 * s1 / count) / max(count - 1, 1)
    return {"mean": mean, "std": np.sqrt(np.maximum(var, 0.0)),
            "bound3_lo": tails.quantile(count, P3_LO),
            "bound3_hi": tails.quantile(count, P3_HI)}


def _run(case, n, seed, groups, batch):
    """Stream n pseudo-random samples in ``groups`` groups; moments and tails per group."""
    g, sp, tol, win = case
    n_p = g.n_planets
    grid = RotationGrid(g, sp, win, _n_times(sp, win))
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
            es, ks, er, kr, ep, kp = map_samples(gen.random((b, d)), tol, n_p)
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
    cached = _read_cache(path, key)
    if cached is not None:
        return cached
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
    out = {"key": key, "method": "plain", "n_samples": n, "seed": int(seed),
           "sampler": "random", "wall_time_s": wall, "values": values, "stderr": stderr,
           "cached": False, "file": str(path)}
    _write_cache(path, out)
    return out


def _read_cache(path, key):
    """The cached reference at ``path`` when its key equals ``key`` (else None)."""
    if not path.is_file():
        return None
    try:
        cached = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    if cached.get("key") != json.loads(json.dumps(key)):
        return None
    cached["cached"] = True
    cached["file"] = str(path)
    return cached


def _write_cache(path, out):
    """Strict JSON (NaN, e.g. a batch-means SE that could not be formed, becomes null)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(to_jsonable(out), indent=1))


#: Version of the directional estimator's settings (r_max, threshold grid, iterations) in the
#: cache key: a change of them invalidates cached references.
_DIRECTIONAL_VERSION = 1


class _CaseModel:
    """The full model of a tolerance case in standard normal coordinates, its first-order
    model (slopes, exact tails and moments) and the 3-sigma targets, for
    :func:`.models_reference_tail.directional_bounds`. Columns: statistic-major, then planet
    (as :func:`plain_reference`)."""

    def __init__(self, case):
        from ..models.tolerance_cv import check_cv_bands, cv_surrogate
        from ..models.tolerance_linear import exceedance, linearised_deviation
        g, sp, tol, win = case
        self.n_p = g.n_planets
        self.n_t = _n_times(sp, win)
        check_cv_bands(tol, self.n_p)                 # zero-mean normal radii, fixed angles
        self.lin = linearised_deviation(g, sp, tol, win, self.n_t)
        if self.lin.n_random == 0 or not self.lin.homogeneous():
            raise ValueError("directional reference: needs random radial errors and a "
                             "deviation that vanishes at the mean errors")
        self.tol = tol
        self.grid = RotationGrid(g, sp, win, self.n_t)
        self.engine = _kernels.resolve_engine("auto")
        self._exceedance = exceedance
        self.mean, self.std, q, _ = cv_surrogate(self.lin, np.zeros(0))   # q: (8, 2, N)
        scale = np.max(self.std, initial=0.0)
        self.targets, self.q_lin, self.info, self._dirs = [], [], [], {}
        for i in range(len(ALL_STATISTICS)):
            for n in range(self.n_p):
                if not scale > 0 or not self.std[i, n] > 1e-9 * scale:
                    continue
                for j, side in enumerate((-1, 1)):
                    self.targets.append((i * self.n_p + n, side))
                    self.q_lin.append(float(q[i, j, n]))
                    self.info.append((i, n, side))
                if i % 2:
                    self._dirs[(i, n)] = self.lin.dev_directions(i // 2, n)
        self._mat = self.lin.scaled.reshape(-1, self.lin.n_random).T      # (d, 4 N n_t)

    @property
    def d(self):
        return self.lin.n_random

    def model(self, z):
        """Full-model statistics (S, 8 N) at standard normal points z (S, d)."""
        vals = self.lin.mean + self.lin.sigma * z
        es, ks, er, kr, ep, kp = map_values(vals, self.tol, self.n_p)
        out = np.stack(self.grid.run(es, ks, er, kr, ep, kp, self.engine))
        return out.transpose(1, 0, 2).reshape(z.shape[0], -1)

    def lin_rho(self, u):
        """First-order slopes (S, 8 N) at unit directions u (S, d)."""
        s = (u @ self._mat).reshape(u.shape[0], 4, self.n_p, self.n_t)
        out = np.empty((u.shape[0], 8, self.n_p))
        out[:, 0::2] = s.mean(axis=-1)
        out[:, 1::2] = s.max(axis=-1) - s.min(axis=-1)
        return out.reshape(u.shape[0], -1)

    def lin_tail(self, qg):
        """Exact tail probabilities (T, J) of the linear model at thresholds qg (T, J):
        Ave_L Gaussian, Dev_L by its direction integral (:func:`exceedance`)."""
        out = np.empty_like(qg)
        for t, (i, n, side) in enumerate(self.info):
            if i % 2 == 0:
                z = (qg[t] - self.mean[i, n]) / self.std[i, n]
                out[t] = special.ndtr(-z) if side > 0 else special.ndtr(z)
            else:
                k, rho, w = self._dirs[(i, n)]
                e = self._exceedance(qg[t], rho, w, k)
                out[t] = e if side > 0 else 1.0 - e
        return out

    def lin_moments(self):
        """Exact E[Y_L] and E[Y_L^2] per column, (8 N,) each."""
        return self.mean.reshape(-1), (self.std ** 2 + self.mean ** 2).reshape(-1)


def _tail_split(res, cm, key_bound, key_se):
    """{summary: {statistic: [N]}} of the bounds (and their SEs); columns without a spread
    keep the linear model's bound with SE 0."""
    n_p = cm.n_p
    lo = np.zeros((len(ALL_STATISTICS), n_p))
    hi = np.zeros_like(lo)
    lo_se, hi_se = np.zeros_like(lo), np.zeros_like(lo)
    for t, (i, n, side) in enumerate(cm.info):
        (hi if side > 0 else lo)[i, n] = res[key_bound][t]
        (hi_se if side > 0 else lo_se)[i, n] = res[key_se][t]
    return ({"bound3_lo": lo, "bound3_hi": hi}, {"bound3_lo": lo_se, "bound3_hi": hi_se})


def directional_reference(case, cache_dir, *, n_evaluations: int = 10 ** 7, nodes: int = 4,
                          seed: int = 20261126, groups: int = 10, batch: int = 4096,
                          case_name: str = "", progress: bool = False,
                          check_directions: int = 256) -> dict:
    """The directional control-variate reference, read from the cache or computed and cached.

    Parameters
    ----------
    case : tuple
        (gearset, speeds, tolerances, window); normal radial bands with zero mean and fixed
        angles (ValueError otherwise: use :func:`plain_reference`).
    cache_dir : path-like
        Folder of the cache file ``models_reference_directional_<n>_<seed>.json``.
    n_evaluations : int
        Full-model evaluations [-]: ``n_evaluations // nodes`` rays of ``nodes`` radii.
    nodes : int
        Radii per ray [-].
    seed : int
        Seed of the directions (``numpy.random.default_rng``).
    groups : int
        Groups of rays for the batch-means check of the standard errors [-], >= 2.
    batch : int
        Rays per kernel call [-] (bounds the memory).
    case_name : str
        Label stored with the reference (part of the cache key).
    progress : bool
        Show a progress bar (tqdm, on stderr) while computing.
    check_directions : int
        Rays of the interpolation check [-] (:func:`interpolation_check`, ~8 evaluations per
        ray and bound).

    Returns
    -------
    dict
        As :func:`plain_reference` (``"values"``, ``"stderr"``: delta method), plus
        ``"stderr_batch"`` (batch means over ``groups``), ``"method": "directional-cv"``,
        ``"n_directions"``, ``"interpolation"`` (:func:`interpolation_check` at the bounds:
        largest mean tail-probability bias relative to the tail mass), ``"unconverged"``,
        ``"file"``.
    """
    n = as_positive_int(n_evaluations, "n_evaluations")
    nodes = as_positive_int(nodes, "nodes")
    groups = as_positive_int(groups, "groups")
    m_dir = n // nodes
    if groups < 2 or m_dir < 2 * groups:
        raise ValueError(f"need groups >= 2 and n_evaluations >= 2 groups x nodes, got "
                         f"{groups}, {n}")
    g, sp, tol, win = case
    cm = _CaseModel(case)
    key = {"case": case_name, "method": "directional-cv", "version": _DIRECTIONAL_VERSION,
           "n_evaluations": n, "nodes": nodes, "seed": int(seed), "groups": groups,
           "window": win.to_dict(), "n_times": cm.n_t, "tolerances": tol.to_dict(),
           "n_planets": g.n_planets}
    path = Path(cache_dir) / f"models_reference_directional_{n}_{int(seed)}.json"
    cached = _read_cache(path, key)
    if cached is not None:
        return cached
    t = time.perf_counter()
    with _bar(m_dir, progress) as bar:
        res = directional_bounds(
            cm.model, cm.lin_rho, cm.lin_tail, cm.d, cm.targets, cm.q_lin, m_dir,
            lin_moments=cm.lin_moments(), nodes=nodes, groups=groups, batch=batch,
            rng=np.random.default_rng(int(seed)), progress=bar)
    chk = interpolation_check(cm.model, cm.lin_rho, cm.d, cm.targets, res["bound"],
                              as_positive_int(check_directions, "check_directions"),
                              nodes=nodes, rng=np.random.default_rng(int(seed) + 1))
    wall = time.perf_counter() - t
    n_p = g.n_planets

    def split(v):
        v = np.asarray(v).reshape(len(ALL_STATISTICS), n_p)
        return {s: v[i].tolist() for i, s in enumerate(ALL_STATISTICS)}

    b_val, b_se = _tail_split(res, cm, "bound", "se")
    b_batch = _tail_split(res, cm, "bound", "se_batch")[1]
    values = {"mean": split(res["mean"]), "std": split(res["std"])}
    values.update({k: split(v) for k, v in b_val.items()})
    stderr = {"mean": split(res["se_mean"]), "std": split(res["se_std"])}
    stderr.update({k: split(v) for k, v in b_se.items()})
    stderr_batch = {"mean": split(res["se_batch_mean"]), "std": split(res["se_batch_std"])}
    stderr_batch.update({k: split(v) for k, v in b_batch.items()})
    out = {"key": key, "method": "directional-cv", "n_samples": n,
           "n_directions": res["n_directions"], "nodes": nodes, "seed": int(seed),
           "sampler": "random directions", "wall_time_s": wall, "values": values,
           "stderr": stderr, "stderr_batch": stderr_batch,
           "unconverged": res["unconverged"],
           "interpolation": {"n_directions": chk["n_directions"],
                             "max_rel_radius": float(np.max(chk["max_rel_radius"])),
                             "max_rel_tail_bias": float(np.max(np.abs(chk["mean_dp"]))
                                                        / special.ndtr(-3.0))},
           "cached": False, "file": str(path)}
    _write_cache(path, out)
    logger.info("bench models: directional reference (%d evaluations) in %.0f s -> %s", n,
                wall, path)
    return out


class _bar:
    """A tqdm progress bar over rays as a ``progress(done, total)`` callable (or None)."""

    def __init__(self, total, enabled):
        self.total = total
        self.enabled = bool(enabled)
        self.tq = None

    def __enter__(self):
        if not self.enabled:
            return None
        import sys

        from tqdm import tqdm
        self.tq = tqdm(total=self.total, desc="directional reference", unit="ray",
                       unit_scale=True, file=sys.stderr)
        return self

    def __call__(self, done, total):
        self.tq.update(done - self.tq.n)

    def __exit__(self, *exc):
        if self.tq is not None:
            self.tq.close()


def build_reference(out_dir, *, evaluations: int = 10 ** 7, plain: bool = False,
                    progress: bool = True) -> dict:
    """Build (or read from the cache in ``out_dir``) the reference of ``meshphase bench
    models``' estimator table, seed 000 Table 2 case 3, as a separate step
    (``meshphase bench reference``).

    Parameters
    ----------
    out_dir : str or Path
        The bench output folder (the cache goes there).
    evaluations : int
        Full-model evaluations [-] (default 1e7).
    plain : bool
        The plain pseudo-random reference instead of the directional one.
    progress : bool
        A progress bar while the directional reference is built.

    Returns
    -------
    dict
        The reference (:func:`directional_reference` / :func:`plain_reference`).
    """
    from ..models.tolerance import observation_window, table2_case

    g, sp, tol = table2_case(3)
    case = (g, sp, tol, observation_window(sp, "slowest-offset"))
    if plain:
        return plain_reference(case, out_dir, n_samples=evaluations, case_name=CASE3_NAME)
    return directional_reference(case, out_dir, n_evaluations=evaluations,
                                 case_name=CASE3_NAME, progress=progress)


def reference_line(ref: dict) -> str:
    """One line naming a reference, whether it was built or read, and its cache file."""
    state = "read from the cache" if ref["cached"] else "built"
    return (f"{ref['method']} reference, {ref['n_samples']} evaluations, {state} "
            f"(build time {ref['wall_time_s']:.0f} s): {ref['file']}")
