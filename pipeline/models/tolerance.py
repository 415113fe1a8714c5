"""Phasing statistics under shaft hole position errors and their tolerance Monte Carlo.

Spec section 2 (seed 000): for one realisation of the errors, over an explicit observation
window [t0, t0 + T], Ave_jn is the time mean and Dev_jn = max - min of the phasing deviation
gamma_jn(t) - gamma_jn,ideal (j = s sun-planet, r ring-planet). Two references are kept side by
side: relative to planet 1 (``ave_s`` ..., planet 1 identically 0, what a rig measures from
onset differences) and absolute (``ave_s_abs`` ..., each mesh's own phase
gamma_jn = +-Z_j psi_ejpn / 2 pi as seed 000 writes it, so planet 1 has its own Ave and Dev).
The Monte Carlo draws the error parameters from tolerance bands (normal with the band read as
+-3 sigma, or uniform) and returns the distributions of Ave and Dev.

Window and time grid
--------------------
Dev is a max - min, so the grid must resolve the fastest offset rotation; Ave depends on
the window length because the ring offset turns only at carrier speed. Both are explicit:
:func:`observation_window` names the standard choices ("slowest-offset", the default: every
offset turns at least one full relative revolution; "fastest-offset"; "common-period": every
offset turns a whole number of revolutions, where first-order terms average out exactly), and
:func:`default_n_times` puts ``points_per_rev`` (64) samples on each revolution of the
fastest offset. The grid is t_k = t0 + k T / n_times, k = 0 .. n_times - 1 (rectangle rule:
exact for the mean of trigonometric polynomials of degree < n_times over whole periods). With
64 points per revolution, max - min of a sinusoid is underestimated by at most
1 - cos(pi / 64) = 0.12 %.

Performance
-----------
The inner loop (realisations x times x planets, two atan2 each) runs in a numba kernel,
parallel over realisations, on precomputed cos/sin of the time grid (angle addition), when
numba imports; otherwise (or with ``engine="numpy"``) a chunked numpy path gives the same
numbers to ~1e-15. Realisations are processed in batches, so working memory does not grow
with the sample count; the per-sample results are kept only while they fit in
``max_memory`` bytes, beyond that the quantiles and histograms come from fixed fine
histograms (4096 bins over three times the range of the first batch; bounded memory; the
quantiles land within about two bins of the exact order statistics).

Estimators
----------
``monte_carlo(method="plain")`` (default) takes every summary from the samples of the chosen
``sampler``. ``method="cv"`` (:mod:`.tolerance_cv`) starts from the exact distribution of the
analytic first-order model (:mod:`.tolerance_linear`) and corrects it with the full model:
randomised Sobol points for the means, standard deviations and ordinary quantiles,
directional and line sampling for the 3-sigma bounds, standard errors from the replicates;
it needs normal radial bands with zero mean and fixed angles (seed 000 case 3). ``meshphase
bench models`` reports each estimator's error and wall time against a 1e7-evaluation
reference: directional sampling with the first-order model as control variate
(:mod:`meshphase.bench.models_reference_tail`, its own SE on the 3-sigma bounds ~1e-4),
the plain reference where the case does not allow it. The windows, grid, bands and result types live in :mod:`.tolerance_model` and are
re-exported here.
"""

from __future__ import annotations

import math
import time
import warnings

import numpy as np

from ..errors import ModelWarning
from ..runtime.lazy import stats
from ..runtime.log import logger
from ..validate import as_choice, as_int, as_positive_int
from . import _kernels
from .gearset import Gearset, Speeds
from ._geometry import ShaftHoleErrors, broadcast_errors, check_error_size, check_gearset, \
    check_speeds
from .tolerance_model import (  # noqa: F401  (re-exported: the public and test-used names)
                              ERROR_FIELDS, P3_HI, P3_LO, ABSOLUTE_STATISTICS, ALL_STATISTICS, DEFAULT_QUANTILES, METHODS,
                              SAMPLERS, STATISTICS, WINDOW_KINDS, MonteCarloResult, ObservationWindow, PhasingStats,
                              StatSummary, ToleranceBand, Tolerances, as_band, as_window, RotationGrid, map_samples,
                              map_values, mc_inputs, nan_summary, offset_speeds, resolve_n_times, default_n_times,
                              observation_window, time_grid)

__all__ = [
    "ObservationWindow",
    "observation_window",
    "default_n_times",
    "time_grid",
    "PhasingStats",
    "phasing_statistics",
    "ToleranceBand",
    "Tolerances",
    "StatSummary",
    "MonteCarloResult",
    "monte_carlo",
    "table2_case",
    "STATISTICS",
    "ABSOLUTE_STATISTICS",
    "ALL_STATISTICS",
    "WINDOW_KINDS",
    "SAMPLERS",
    "METHODS",
    "DEFAULT_QUANTILES",
]


def phasing_statistics(gearset: Gearset, speeds: Speeds, errors: ShaftHoleErrors | None,
                       window, n_times: int | None = None, *, engine: str = "auto",
                       points_per_rev: int = 64, batch_size: int = 65536) -> PhasingStats:
    """Ave_jn and Dev_jn of the phasing deviation for each realisation of the errors.

    Parameters
    ----------
    gearset : Gearset
        Tooth counts, planet angles psi_n [rad], carrier radius R_c [m], direction.
    speeds : Speeds
        Absolute speeds [rad/s].
    errors : ShaftHoleErrors or None
        Position errors with sample dims S (None: a single ideal realisation, S = ()).
    window : ObservationWindow or (t0, T) tuple [s] or window kind
        Observation window (see :func:`observation_window`); explicit on purpose.
    n_times : int, optional
        Time samples on the window [-], >= 2; default :func:`default_n_times`.
    engine : {"auto", "numba", "numpy"}
        Inner loop implementation (same numbers to ~1e-15).
    points_per_rev : int
        Used by the default ``n_times`` [-].
    batch_size : int
        Realisations per kernel call [-] (bounds the working memory).

    Returns
    -------
    PhasingStats
        Arrays of shape (*S, N).

    Notes
    -----
    Seed 000: Ave_jn = mean over the window of gamma_jn(t) - gamma_jn,ideal and
    Dev_jn = max - min of it, with the continuous deviation of
    :func:`meshphase.models.mesh_phasing.phasing_deviation` (``wrap=False``) on the grid of
    :func:`time_grid` (relative to planet 1), and of the unwrapped mesh-line deviations
    s Z_s delta_s / 2 pi, -s Z_r delta_r / 2 pi of
    :func:`meshphase.models.mesh_phasing.mesh_angle_deviations` (absolute, ``*_abs``).
    """
    g = check_gearset(gearset)
    sp = check_speeds(speeds)
    win = as_window(window, sp)
    n_t = resolve_n_times(sp, win, n_times, points_per_rev)
    eng = _kernels.resolve_engine(engine)
    bs = as_positive_int(batch_size, "batch_size")
    shape, b = broadcast_errors(errors, g.n_planets)
    check_error_size(b, g.carrier_radius)
    grid = RotationGrid(g, sp, win, n_t)
    flat = int(np.prod(shape, dtype=np.int64))
    n_p = g.n_planets
    es, ks = b.es.reshape(flat), b.ks.reshape(flat)
    er, kr = b.er.reshape(flat), b.kr.reshape(flat)
    ep, kp = b.ep.reshape(flat, n_p), b.kp.reshape(flat, n_p)
    outs = [np.empty((flat, n_p)) for _ in range(8)]
    for a in range(0, flat, bs):
        z = min(flat, a + bs)
        res = grid.run(es[a:z], ks[a:z], er[a:z], kr[a:z], ep[a:z], kp[a:z], eng)
        for o, r in zip(outs, res):
            o[a:z] = r
    outs = [o.reshape(tuple(shape) + (n_p,)) for o in outs]
    return PhasingStats(*outs[:4], window=win, n_times=n_t, engine=eng,
                        **dict(zip(ABSOLUTE_STATISTICS, outs[4:])))


def _replicate_bounds(n, r):
    base, extra = divmod(n, r)
    sizes = [base + (1 if i < extra else 0) for i in range(r)]
    return np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)


def _summary_exact(x, levels, bins, bounds):
    """x (n, N) -> StatSummary with replicate standard errors."""
    n, n_p = x.shape
    lv = np.concatenate([levels, [P3_LO, P3_HI]])

    def point(xx):
        m = xx.mean(axis=0)
        s = xx.std(axis=0, ddof=1) if xx.shape[0] > 1 else np.zeros(n_p)
        q = np.quantile(xx, lv, axis=0)
        return m, s, q

    m, s, q = point(x)
    r = len(bounds) - 1
    if r >= 2:
        sizes = np.diff(bounds)
        if sizes[0] > 1 and np.all(sizes == sizes[0]):
            # equal replicates (the usual): one reduction over a (R, n/R, N) view rather
            # than R calls per statistic
            xr = x[bounds[0]:bounds[-1]].reshape(r, int(sizes[0]), n_p)
            reps = [xr.mean(axis=1), xr.std(axis=1, ddof=1), np.moveaxis(np.quantile(xr, lv, axis=1), 1, 0)]
        else:
            each = [point(x[bounds[i]:bounds[i + 1]]) for i in range(r)]
            reps = [np.stack([rp[k] for rp in each]) for k in range(3)]
        se = [np.std(reps[k], axis=0, ddof=1) / math.sqrt(r) for k in range(3)]
    else:
        se = [np.full(n_p, np.nan), np.full(n_p, np.nan), np.full((lv.size, n_p), np.nan)]
    counts = np.zeros((n_p, bins), dtype=np.int64)
    edges = np.zeros((n_p, bins + 1))
    for p in range(n_p):   # loop over planets (N is small), not samples
        c, e = np.histogram(x[:, p], bins=bins)
        counts[p], edges[p] = c, e
    nq = levels.size
    return StatSummary(m, s, levels, q[:nq], q[nq:], np.stack([m - 3 * s, m + 3 * s]),
                       counts, edges, se[0], se[1], se[2][:nq], se[2][nq:])


class _Stream:
    """Bounded-memory accumulator: moments and fine histograms per replicate."""

    def __init__(self, first, n_rep, n_fine=4096):
        # first: (4, B, N) from the first batch -> fixed ranges, extended by one span each side
        lo = first.min(axis=1)
        hi = first.max(axis=1)
        span = np.maximum(hi - lo, 1e-12 * np.maximum(1.0, np.abs(hi)))
        self.lo = lo - span
        self.width = 3.0 * span / n_fine
        self.center = 0.5 * (lo + hi)
        self.n_fine = n_fine
        shp = (n_rep,) + lo.shape
        self.count = np.zeros(n_rep, dtype=np.int64)
        self.s1 = np.zeros(shp)
        self.s2 = np.zeros(shp)
        self.hist = np.zeros(shp + (n_fine + 2,), dtype=np.int64)

    def add(self, x, rep):
        # x: (4, B, N)
        self.count[rep] += x.shape[1]
        d = x - self.center[:, None, :]
        self.s1[rep] += d.sum(axis=1)
        self.s2[rep] += (d * d).sum(axis=1)
        idx = np.floor((x - self.lo[:, None, :]) / self.width[:, None, :])
        idx = np.clip(idx, -1, self.n_fine).astype(np.int64) + 1     # 0 under, n_fine+1 over
        n_stat, _, n_p = x.shape
        m = self.n_fine + 2
        offs = (np.arange(n_stat)[:, None] * n_p + np.arange(n_p)[None, :]) * m
        flat = (idx + offs[:, None, :]).ravel()
        self.hist[rep] += np.bincount(flat, minlength=n_stat * n_p * m).reshape(n_stat, n_p, m)

    def _point(self, count, s1, s2, hist, levels):
        m = s1 / count
        var = (s2 - count * m * m) / max(count - 1, 1)
        mean = self.center + m
        std = np.sqrt(np.maximum(var, 0.0))
        cum = np.cumsum(hist, axis=-1)
        q = np.empty((levels.size,) + mean.shape)
        bad = False
        for a in range(mean.shape[0]):
            for p in range(mean.shape[1]):
                c = cum[a, p]
                for i, lev in enumerate(levels):
                    target = lev * count
                    k = int(np.searchsorted(c, target, side="left"))
                    if k == 0 or k >= self.n_fine + 1:
                        q[i, a, p] = np.nan
                        bad = True
                        continue
                    prev = c[k - 1]
                    frac = (target - prev) / max(c[k] - prev, 1)
                    q[i, a, p] = self.lo[a, p] + self.width[a, p] * (k - 1 + frac)
        return mean, std, q, bad

    def summaries(self, levels, bins):
        lv = np.concatenate([levels, [P3_LO, P3_HI]])
        tot = self.count.sum()
        mean, std, q, bad = self._point(tot, self.s1.sum(0), self.s2.sum(0), self.hist.sum(0), lv)
        r = self.count.size
        if r >= 2 and np.all(self.count > 0):
            reps = [self._point(self.count[i], self.s1[i], self.s2[i], self.hist[i], lv)
                    for i in range(r)]
            se = [np.std(np.stack([rp[k] for rp in reps]), axis=0, ddof=1) / math.sqrt(r)
                  for k in range(3)]
        else:
            se = [np.full(mean.shape, np.nan), np.full(mean.shape, np.nan),
                  np.full(q.shape, np.nan)]
        if bad:
            warnings.warn("monte_carlo: some quantiles fall outside the fixed histogram range of "
                          "the bounded-memory mode and are NaN; raise max_memory to keep the "
                          "samples", ModelWarning, stacklevel=3)
        hist = self.hist.sum(0)[..., 1:-1]
        group = max(1, self.n_fine // bins)
        nb = self.n_fine // group
        coarse = hist[..., :nb * group].reshape(hist.shape[:-1] + (nb, group)).sum(-1)
        out = []
        nq = levels.size
        for a in range(mean.shape[0]):
            edges = self.lo[a][:, None] + self.width[a][:, None] * group * np.arange(nb + 1)
            out.append(StatSummary(mean[a], std[a], levels, q[:nq, a], q[nq:, a],
                                   np.stack([mean[a] - 3 * std[a], mean[a] + 3 * std[a]]),
                                   coarse[a], edges, se[0][a], se[1][a], se[2][:nq, a],
                                   se[2][nq:, a]))
        return out


# ----------------------------------------------------------------------------- Monte Carlo

def _next_pow2(n):
    return 1 << max(0, int(n - 1).bit_length())


def monte_carlo(gearset: Gearset, speeds: Speeds, tolerances: Tolerances, window,
                n_samples: int, *, sampler: str = "random", n_times: int | None = None,
                batch_size: int = 8192, rng=None, replicates: int = 8,
                quantile_levels=DEFAULT_QUANTILES, bins: int = 64, engine: str = "auto",
                points_per_rev: int = 64, max_memory: float = 256 * 2 ** 20,
                keep_samples: bool | None = None, progress=None, method: str = "plain",
                tail_directions: int = 16) -> MonteCarloResult:
    """Monte Carlo of Ave_jn / Dev_jn over tolerance bands of the shaft hole position errors.

    Parameters
    ----------
    gearset : Gearset
        Tooth counts, planet angles psi_n [rad], carrier radius R_c [m], direction.
    speeds : Speeds
        Absolute speeds [rad/s].
    tolerances : Tolerances
        Bands of the error parameters ([m], [rad]).
    window : ObservationWindow or (t0, T) tuple [s] or window kind
        Observation window of Ave / Dev (named in the result).
    n_samples : int
        Number of realisations S [-], >= 0.
    sampler : {"random", "sobol"}
        Plain pseudo-random (``rng``) or scrambled Sobol (scipy.stats.qmc), one independent
        scrambling per replicate (randomised QMC). Sobol balance needs
        n_samples = replicates * 2**m (ModelWarning otherwise).
    n_times : int, optional
        Time samples on the window [-]; default :func:`default_n_times`.
    batch_size : int
        Realisations per batch [-] (working memory ~ batch_size x n_times x N x 8 B only on the
        numpy path; the numba path needs none). Rounded down to a power of 2 for Sobol.
    rng : None, int or numpy.random.Generator
        Randomness source (``np.random.default_rng(rng)``).
    replicates : int
        Independent replicates R for the standard errors [-] (>= 2 for an estimate).
    quantile_levels : sequence of float
        Levels in (0, 1) of the reported quantiles [-].
    bins : int
        Histogram bins [-].
    engine : {"auto", "numba", "numpy"}
        Inner loop implementation.
    points_per_rev : int
        Used by the default ``n_times`` [-].
    max_memory : float
        Bytes allowed for keeping the per-sample results (8 statistics x N planets x 8 B per
        sample); beyond, bounded-memory fine histograms are used (``exact_quantiles=False``).
    keep_samples : bool, optional
        Force keeping (True) or not keeping (False) the per-sample arrays.
    progress : callable, optional
        Called as ``progress(done, total)`` after each batch.
    method : {"plain", "cv"}
        "plain" (default): every summary from the ``n_samples`` samples of ``sampler``.
        "cv": control variate about the analytic first-order (linearised) distribution,
        randomised Sobol for the correction and directional sampling for the 3-sigma bounds
        (:func:`meshphase.models.tolerance_cv.monte_carlo_cv`; needs normal radial bands with
        zero mean and fixed angles; ``sampler``, ``batch_size``, ``max_memory`` and
        ``keep_samples`` do not apply, the paired samples are kept). Same accuracy for a
        fraction of the samples: ``meshphase bench models`` reports error against time.
    tail_directions : int
        "cv" only: directions per replicate and per 3-sigma bound [-].

    Returns
    -------
    MonteCarloResult

    Notes
    -----
    Seed 000: theta_k ~ N(mu_k, sigma_k^2) with the band = 3 sigma; the empirical
    distribution of Ave_jn / Dev_jn over S samples estimates their probability densities.
    Each sample's Ave / Dev are those of :func:`phasing_statistics`. Unit-cube points are
    mapped through the inverse CDF of each band (the same mapping for both samplers).
    Every statistic comes relative to planet 1 and absolute (``*_abs``), from the same samples.

    Code layout: argument checks (``mc_inputs``), the unit-cube sampler per replicate
    (``_unit_draws``), the batched evaluation (``_run_batches``) and the summaries here; the
    Sobol balance warning stays here so that it points at the caller.
    """
    method = as_choice(method, "method", METHODS)
    if method == "cv":
        from .tolerance_cv import monte_carlo_cv
        return monte_carlo_cv(gearset, speeds, tolerances, window, n_samples,
                              tail_directions=tail_directions, n_times=n_times, rng=rng,
                              replicates=replicates, quantile_levels=quantile_levels,
                              bins=bins, engine=engine, points_per_rev=points_per_rev,
                              progress=progress)
    t_start = time.perf_counter()
    g, sp, win, n, sampler, n_t, bs, reps, bins, levels, max_memory, eng = mc_inputs(
        gearset, speeds, tolerances, window, n_samples, sampler, n_times, batch_size,
        replicates, bins, quantile_levels, max_memory, engine, progress, points_per_rev)
    gen = np.random.default_rng(rng)
    n_p = g.n_planets
    d = tolerances.n_random(n_p)
    reps = min(reps, n) if n > 0 else reps
    bounds = _replicate_bounds(n, reps)
    n_stat = len(ALL_STATISTICS)
    keep = n * n_stat * n_p * 8 <= max_memory if keep_samples is None else bool(keep_samples)
    grid = RotationGrid(g, sp, win, n_t)
    if sampler == "sobol":
        bs = 1 << (bs.bit_length() - 1)
        sizes = np.diff(bounds)
        if n > 0 and d > 0 and np.any(sizes & (sizes - 1)):
            warnings.warn(f"monte_carlo: sobol replicates of {sorted(set(sizes.tolist()))} "
                          "samples are not powers of 2 (balance properties lost); use "
                          f"n_samples = {reps} * 2**m", ModelWarning, stacklevel=2)
    draw = _unit_draws(sampler, gen, d, reps)
    store = np.empty((n_stat, n, n_p)) if keep else None
    stream = _run_batches(grid, tolerances, g.carrier_radius, draw, bounds, bs, eng, store,
                          progress)
    if n == 0:
        summaries = [nan_summary(n_p, levels, bins) for _ in ALL_STATISTICS]
        samples = {s: np.zeros((0, n_p)) for s in ALL_STATISTICS} if keep else None
    elif keep:
        summaries = [_summary_exact(store[i], levels, bins, bounds) for i in range(n_stat)]
        samples = {s: store[i] for i, s in enumerate(ALL_STATISTICS)}
    else:
        summaries = stream.summaries(levels, bins)
        samples = None
    wall = time.perf_counter() - t_start
    logger.debug("monte_carlo: %d samples (%s, %s engine, %d times) in %.3f s", n, sampler, eng,
                 n_t, wall)
    return MonteCarloResult(*summaries[:4], n_samples=n, sampler=sampler, window=win,
                            n_times=n_t, replicates=reps, engine=eng, wall_time=wall,
                            tolerances=tolerances, samples=samples, exact_quantiles=keep,
                            **dict(zip(ABSOLUTE_STATISTICS, summaries[4:])))


def _unit_draws(sampler, gen, d, reps):
    """draw(r, m, first) -> (m, d) unit-cube points of replicate r (its first batch: first)."""
    if sampler == "random":
        return lambda r, m, first: gen.random((m, d))
    engines = [stats.qmc.Sobol(max(d, 1), scramble=True, rng=child) for child in gen.spawn(reps)]

    def draw(r, m, first):
        if first and (m & (m - 1)):
            return engines[r].random(_next_pow2(m))[:m, :d]
        return engines[r].random(m)[:, :d]
    return draw


def _run_batches(grid, tolerances, carrier_radius, draw, bounds, bs, eng, store, progress):
    """Evaluate every replicate in batches; results into ``store`` or a bounded-memory stream.

    Returns the :class:`_Stream` (None when ``store`` keeps the samples or nothing ran).
    """
    n_p = grid.n_planets
    n = int(bounds[-1])
    stream = None
    done = 0
    for r in range(len(bounds) - 1):
        a0, a1 = int(bounds[r]), int(bounds[r + 1])
        for a in range(a0, a1, bs):
            z = min(a1, a + bs)
            m = z - a
            es, ks, er, kr, ep, kp = map_samples(draw(r, m, a == a0), tolerances, n_p)
            for name, e in (("e_sun", es), ("e_ring", er)):
                if np.any(e + ep.max(axis=1) >= carrier_radius):
                    raise ValueError(f"monte_carlo: a sampled {name} + e_planet reached the "
                                     f"carrier radius {carrier_radius!r} m; narrow the bands")
            res = np.stack(grid.run(es, ks, er, kr, ep, kp, eng))
            if store is not None:
                store[:, a:z] = res
            else:
                if stream is None:
                    stream = _Stream(res, len(bounds) - 1)
                stream.add(res, r)
            done += m
            if progress is not None:
                progress(done, n)
    return stream


# ----------------------------------------------------------------------------- seed 000 scenes

def table2_case(case: int, *, planet_speed: str = "kinematic", angles: str = "given"):
    """Seed 000 Table 1 gearset and Table 2 error case 1, 2 or 3, in SI units.

    Parameters
    ----------
    case : {1, 2, 3}
        Table 2 column.
    planet_speed : {"kinematic", "seed"}
        "kinematic" (default): planet speed from the tooth counts with the ring fixed
        (w_p = -200 rad/s, w_pc = -300 rad/s, planets turning clockwise as the seed's
        formulas assume). "seed": the printed w_p = 286.2 rad/s, which does not follow from
        Z_s = 25, Z_p = 29 and w_s = 448, w_c = 100 rad/s (it equals 448 * 25 / 29 - 100).
    angles : {"given", "uniform"}
        Case 3 only: keep the Table 2 angles fixed ("given", default) or draw every angle
        uniformly on [0, 2 pi).

    Returns
    -------
    gearset : Gearset
        Z_s 25, Z_r 87, Z_p 29, four equally spaced planets, R_c = 0.1125 m, clockwise planets.
    speeds : Speeds
        w_s = 448, w_c = 100 rad/s, fixed ring (w_s / w_c = 4.48 = 1 + Z_r / Z_s).
    errors : ShaftHoleErrors or Tolerances
        Cases 1 and 2: deterministic errors (e = 0.2 / 1.0 mm for sun, ring and every planet;
        kappa_s = 4 deg, kappa_r = 60 deg, kappa_p = 20 deg for every planet; the seed lists
        the angles of planet 1 only). Case 3 ("Normal"): the Table 2 values read as tolerance
        bands, e ~ N(0, (band / 3)^2) with band e_s = 0.2, e_r = 0.5, e_p = 0.2 mm (a signed
        radial error along the given angle; |e| with the angle turned by pi when negative),
        angles as chosen by ``angles``.
    """
    c = as_int(case, "case")
    if c not in (1, 2, 3):
        raise ValueError(f"case must be 1, 2 or 3 (seed 000 Table 2), got {case!r}")
    planet_speed = as_choice(planet_speed, "planet_speed", ("kinematic", "seed"))
    angles = as_choice(angles, "angles", ("given", "uniform"))
    g = Gearset.equally_spaced(25, 87, 29, 4, 112.5e-3, direction="cw",
                               name="seed000-table1")
    if planet_speed == "kinematic":
        sp = Speeds.kinematic(g, sun=448.0, carrier=100.0)
    else:
        sp = Speeds(sun=448.0, carrier=100.0, planet=286.2, ring=0.0)
    ks, kr, kp = np.deg2rad([4.0, 60.0, 20.0])
    if c in (1, 2):
        e = 0.2e-3 if c == 1 else 1.0e-3
        return g, sp, ShaftHoleErrors(e_sun=e, kappa_sun=ks, e_ring=e, kappa_ring=kr,
                                      e_planet=e, kappa_planet=kp)
    if angles == "given":
        ang = [ToleranceBand.fixed(ks), ToleranceBand.fixed(kr), ToleranceBand.fixed(kp)]
    else:
        ang = [ToleranceBand.full_circle()] * 3
    tol = Tolerances(e_sun=ToleranceBand(0.0, 0.2e-3), kappa_sun=ang[0],
                     e_ring=ToleranceBand(0.0, 0.5e-3), kappa_ring=ang[1],
                     e_planet=ToleranceBand(0.0, 0.2e-3), kappa_planet=ang[2])
    return g, sp, tol
