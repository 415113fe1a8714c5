"""Control-variate Monte Carlo of the phasing statistics (``monte_carlo(method="cv")``).

The statistics Y (Ave_jn, Dev_jn, relative and absolute) are smooth, nearly linear
functions of the Gaussian errors theta = mu + sigma z. Their first-order model Y_L
(:mod:`.tolerance_linear`) has a distribution known exactly (Ave_L Gaussian; Dev_L a
one-dimensional integral over directions). The estimator is that exact answer plus a
correction E[Y - Y_L] estimated from the full model, whose variance is small because
Y - Y_L is of second order (relative size ~ e / R_c, a few 1e-3 for seed 000 case 3):

- means and second moments: E[Y] = E[Y_L] + mean(Y - Y_L) over randomised QMC points
  (scrambled Sobol, ``replicates`` independent scramblings of ``n_samples / replicates``
  points each); std = sqrt(E[Y^2] - E[Y]^2). Other quantiles: q_L plus the difference of
  the paired sample quantiles of Y and Y_L.
- 3-sigma bounds (quantiles at Phi(-3), Phi(3)), by directional sampling: with z = r u,
  r ~ chi_d, P(Y > q) = E_u[P(r > r*(u))] where Y(r* u) = q. Y is homogeneous of degree 1
  in r to first order, so one full-model evaluation per direction, at the radius
  r0 = q_L / rho_L(u) where the linear model reaches its bound, gives the local slope
  rho(u) = Y(r0 u) / r0 and r*(u) = q / rho(u) up to terms of second order in
  (q - q_L) / q_L. The bound solves E_u[P(chi_d > q / rho(u))] = 1 - p; the same equation
  with rho_L on the same directions gives the linear model's bound, and their difference
  (paired, so the direction noise cancels) corrects the exact q_L.

Standard errors: the standard deviation over the replicates / sqrt(R), for every summary.
Conditions (ValueError otherwise): every random band normal, no random angle, and zero
mean radial errors (then the deviation vanishes at the mean errors and the linear model is
homogeneous). Cost: ``n_samples + replicates * tail_directions * T`` full-model
evaluations, T = 2 x the number of (statistic, planet) pairs with a spread (42 for case 3).
"""

from __future__ import annotations

import math
import time
import warnings

import numpy as np

from ..runtime.lazy import special, stats
from ..errors import ModelWarning
from ..runtime.log import logger
from ..validate import as_positive_int
from .tolerance_linear import chi_mean, linearised_deviation, solve_level
from .tolerance_model import (ALL_STATISTICS, DEFAULT_QUANTILES, MonteCarloResult, StatSummary,
                              RotationGrid, map_values, mc_inputs, nan_summary)

__all__ = ["monte_carlo_cv"]


def check_cv_bands(tolerances, n_p):
    """Raise ValueError where the control variate cannot be used on ``tolerances`` with
    ``n_p`` planets (a random angle, or an offset band whose mean is not 0 [m])."""
    for name, _, band in tolerances.columns(n_p):
        if band.is_random and name.startswith("kappa"):
            raise ValueError(f"method='cv': {name} is random; the control variate needs "
                             "fixed angles (use method='plain')")
        if name.startswith("e_") and band.mean != 0.0:
            raise ValueError(f"method='cv': {name} has mean {band.mean!r} m; the control "
                             "variate needs zero mean radial errors (use method='plain')")


def _sobol_normals(gen, d, reps, m):
    """reps independent scrambled Sobol sets of m standard normal points, (reps, m, d)."""
    out = np.empty((reps, m, d))
    for r, child in enumerate(gen.spawn(reps)):
        m2 = 1 << max(0, int(m - 1).bit_length())          # balanced draw, then the first m
        u = stats.qmc.Sobol(max(d, 1), scramble=True, rng=child).random(m2)[:m, :d]
        out[r] = special.ndtri(np.clip(u, 2.0 ** -53, 1.0 - 2.0 ** -53))
    return out


def cv_surrogate(lin, levels):
    """Exact mean, std and quantiles (levels + the two 3-sigma levels) of the linear
    statistics, shapes (8, N), (8, N), (8, L + 2, N)."""
    n_p = lin.d0.shape[1]
    lv = np.concatenate([levels, [special.ndtr(-3.0), special.ndtr(3.0)]])
    mean = np.zeros((8, n_p))
    std = np.zeros((8, n_p))
    q = np.zeros((8, lv.size, n_p))
    a_mean, a_std = lin.ave_moments()
    for s in range(4):
        mean[2 * s], std[2 * s] = a_mean[s], a_std[s]
        q[2 * s] = a_mean[s][None] + a_std[s][None] * special.ndtri(lv)[:, None]
        for n in range(n_p):
            k, rho, w = lin.dev_directions(s, n)
            r = float(np.max(np.abs(rho), initial=0.0))
            if k == 0 or r == 0.0:
                continue
            # in units of the largest |rho|: rho ~ J sigma is as small as the spread, and its
            # square underflows below ~1e-154 (a spread of 1e-163 m came out 0.3 off)
            rho = rho / r
            m1 = chi_mean(k) * np.sum(w * rho)
            sd = math.sqrt(max(k * np.sum(w * rho * rho) - m1 * m1, 0.0))
            mean[2 * s + 1, n], std[2 * s + 1, n] = m1 * r, sd * r
            start = np.maximum(m1 + sd * special.ndtri(lv), 1e-3 * m1)
            q[2 * s + 1, :, n] = solve_level(1.0 - lv, rho, w, k, start=start) * r
    return mean, std, q, lv


def _full(grid, lin, tol, z, eng, batch=8192):
    """Full-model statistics at theta = mu + sigma z, z (S, d) -> (8, S, N)."""
    n_p = grid.n_planets
    out = np.empty((8, z.shape[0], n_p))
    for a in range(0, z.shape[0], batch):
        vals = lin.mean + lin.sigma * z[a:a + batch]
        es, ks, er, kr, ep, kp = map_values(vals, tol, n_p)
        out[:, a:a + batch] = np.stack(grid.run(es, ks, er, kr, ep, kp, eng))
    return out


def _tail_targets(lin, surr_std):
    """(statistic, planet) pairs with a spread, and their linear slopes per direction."""
    scale = np.max(surr_std, initial=0.0)
    return [(i, n) for i in range(8) for n in range(surr_std.shape[1])
            if scale > 0 and surr_std[i, n] > 1e-9 * scale]


def _linear_rho(lin, i, n, u):
    """rho_L(u) of statistic i, planet n for unit directions u (M, d)."""
    m = lin.scaled[i // 2, n]                         # (n_t, d)
    if i % 2 == 0:
        return u @ m.mean(axis=0)
    v = u @ m.T
    return v.max(axis=1) - v.min(axis=1)


def _tail_corrections(grid, lin, tol, eng, targets, q3, dirs, passes=2):
    """Directional corrections of the 3-sigma bounds, shape (R, len(targets), 2).

    Every bound is solved as an upper tail (the lower one of -Y). Pass 1 evaluates the
    full model where the linear model reaches its bound, pass 2 where the pass-1 slopes
    reach the pass-1 bound, so the homogeneity assumption is used only over the small
    step between the pass-2 radius and the final bound.
    """
    reps, m_dir, d = dirs.shape
    u = dirs / np.linalg.norm(dirs, axis=2, keepdims=True)
    rmax = math.sqrt(d) + 6.0
    info = [(i, n, sgn) for i, n in targets for sgn in (-1.0, 1.0)]
    alpha = np.array([special.ndtr(-3.0)] * len(info))              # tail mass of each side
    q_lin = np.array([sgn * q3[i, 0 if sgn < 0 else 1, n] for i, n, sgn in info])
    sgns = np.array([sgn for _, _, sgn in info])
    w = np.full(m_dir, 1.0 / m_dir)
    out = np.zeros((reps, len(targets), 2))
    for r in range(reps):
        rho_l = np.stack([sgn * _linear_rho(lin, i, n, u[r]) for i, n, sgn in info])
        q_hat_l = solve_level(alpha, rho_l, w, d, start=q_lin)
        rho, q = rho_l, q_lin
        for _ in range(passes):
            with np.errstate(divide="ignore", invalid="ignore"):
                r0 = np.where(rho * q[:, None] > 0, q[:, None] / rho, rmax)
            r0 = np.clip(r0, 1e-6, rmax)
            y = _full(grid, lin, tol, (r0[..., None] * u[r][None]).reshape(-1, d), eng)
            y = y.reshape(8, len(info), m_dir, -1)
            rho = np.stack([sgn * y[i, t, :, n] for t, (i, n, sgn) in enumerate(info)]) / r0
            q = solve_level(alpha, rho, w, d, start=q)
        out[r] = (sgns * (q - q_hat_l)).reshape(len(targets), 2)
    return out


def _line_bounds(grid, lin, tol, eng, targets, zs, passes=2):
    """3-sigma bounds of the Ave statistics by line sampling, shape (R, len(targets), 2).

    Ave_L = a . z is linear, so the tail event lies beyond a hyperplane orthogonal to
    alpha = a / |a|. Each line z = z_perp + c alpha (z_perp the QMC point with its alpha
    component removed) crosses Y = q at c*(q), and P(Y > q) = E[Phi(-c*(q))] exactly.
    Pass 1 evaluates Y at c = 3 (the linear bound) and steps with the linear slope |a|;
    pass 2 evaluates at the pass-1 crossing and uses the secant of the two.
    """
    reps, m, d = zs.shape
    info = [(i, n, sgn) for i, n in targets for sgn in (-1.0, 1.0)]
    p3 = special.ndtr(-3.0)
    out = np.zeros((reps, len(targets), 2))
    for r in range(reps):
        al, zp, amp = [], [], []
        for i, n, sgn in info:
            a = lin.scaled[i // 2, n].mean(axis=0)
            a_n = float(np.linalg.norm(a))
            u = sgn * a / a_n
            al.append(u)
            zp.append(zs[r] - (zs[r] @ u)[:, None] * u)
            amp.append(a_n)
        al, zp, amp = np.array(al), np.array(zp), np.array(amp)[:, None]
        base = np.array([sgn * lin.d0[i // 2, n].mean() for i, n, sgn in info])[:, None]
        c_prev, y_prev = None, None
        c = np.full((len(info), m), 3.0)
        q = (base + 3.0 * amp)[:, 0]
        slope = np.broadcast_to(amp, c.shape)
        for _ in range(passes):
            y = _full(grid, lin, tol, (zp + c[..., None] * al[:, None, :]).reshape(-1, d), eng)
            y = y.reshape(8, len(info), m, -1)
            yt = np.stack([sgn * y[i, t, :, n] for t, (i, n, sgn) in enumerate(info)])
            if c_prev is not None:
                dc = c - c_prev
                sec = np.where(np.abs(dc) > 1e-9, (yt - y_prev) / np.where(dc == 0, 1, dc),
                               slope)
                slope = np.where(sec > 0.1 * amp, sec, slope)
            q = _solve_lines(c, yt, slope, p3, q)
            c_prev, y_prev = c, yt
            c = c + (q[:, None] - yt) / slope
        out[r] = (np.array([sgn for _, _, sgn in info]) * q).reshape(len(targets), 2)
    return out


def _solve_lines(c, y, slope, p, start, iters=50):
    """q with mean over lines of Phi(-(c + (q - y) / slope)) = p (Newton), shape (T,)."""
    q = np.array(start, dtype=float)
    for _ in range(iters):
        cs = c + (q[:, None] - y) / slope
        f = special.ndtr(-cs).mean(axis=1) - p
        df = -(np.exp(-0.5 * cs * cs) / math.sqrt(2 * math.pi) / slope).mean(axis=1)
        step = f / df
        q = q - step
        if np.all(np.abs(step) <= 1e-13 * np.maximum(np.abs(q), 1e-300)):
            break
    return q


def _replicate_summary(vals):
    """(mean over replicates, standard error) of per-replicate estimates (R, ...)."""
    r = vals.shape[0]
    se = (np.std(vals, axis=0, ddof=1) / math.sqrt(r) if r >= 2
          else np.full(vals.shape[1:], np.nan))
    return vals.mean(axis=0), se


def monte_carlo_cv(gearset, speeds, tolerances, window, n_samples: int = 2048, *,
                   tail_directions: int = 16, n_times: int | None = None, rng=None,
                   replicates: int = 8, quantile_levels=None, bins: int = 64,
                   engine: str = "auto", points_per_rev: int = 64, progress=None):
    """Control-variate randomised-QMC Monte Carlo of Ave_jn / Dev_jn (module docstring).

    Parameters
    ----------
    gearset, speeds, tolerances, window
        As :func:`meshphase.models.tolerance.monte_carlo`.
    n_samples : int
        Paired QMC points for the moments and ordinary quantiles [-], >= 0; each replicate
        gets ``n_samples / replicates`` (a power of 2 keeps the Sobol balance).
    tail_directions : int
        Directions per replicate and per 3-sigma bound [-] (a power of 2).
    n_times : int, optional
        Time samples on the window [-].
    rng : None, int or numpy.random.Generator
        Seed of the scramblings.
    replicates : int
        Independent scramblings R for the standard errors [-], >= 2 for an estimate.
    quantile_levels : sequence of float, optional
        Levels in (0, 1) [-]; default that of ``monte_carlo``.
    bins : int
        Histogram bins of the paired samples [-].
    engine : {"auto", "numba", "numpy"}
        Inner loop of the full model.
    points_per_rev : int
        Used by the default ``n_times`` [-].
    progress : callable, optional
        Called as ``progress(done, total)`` after each stage.

    Returns
    -------
    MonteCarloResult
        ``method="cv"``, ``sampler="sobol"``; ``samples`` holds the full-model statistics
        at the paired points; ``n_evaluations`` counts every full-model evaluation.

    Notes
    -----
    The stages are separate functions: the exact linear answer (``cv_surrogate``), the paired
    moment correction (here) and the directional tail correction (``_tail_corrections``).
    """
    t_start = time.perf_counter()
    levels_in = DEFAULT_QUANTILES if quantile_levels is None else quantile_levels
    g, sp, win, n, _, n_t, _, reps, bins, levels, _, eng = mc_inputs(
        gearset, speeds, tolerances, window, n_samples, "sobol", n_times, 1, replicates,
        bins, levels_in, 0.0, engine, progress, points_per_rev)
    n_dir = as_positive_int(tail_directions, "tail_directions")
    n_p = g.n_planets
    check_cv_bands(tolerances, n_p)
    common = dict(sampler="sobol", window=win, n_times=n_t, engine=eng,
                  tolerances=tolerances, method="cv")
    if n == 0:
        s = [nan_summary(n_p, levels, bins) for _ in ALL_STATISTICS]
        return MonteCarloResult(*s[:4], n_samples=0, replicates=reps,
                                wall_time=time.perf_counter() - t_start,
                                samples={k: np.zeros((0, n_p)) for k in ALL_STATISTICS},
                                n_evaluations=0, **common,
                                **dict(zip(ALL_STATISTICS[4:], s[4:])))
    reps = max(1, min(reps, n))
    m = n // reps
    if m * reps != n or (m & (m - 1)) or (n_dir & (n_dir - 1)):
        warnings.warn(f"monte_carlo(method='cv'): n_samples / replicates = {n / reps:g} and "
                      f"tail_directions = {n_dir} should be powers of 2 (Sobol balance); "
                      f"running {reps} x {m} points", ModelWarning, stacklevel=3)
    lin = linearised_deviation(g, sp, tolerances, win, n_t)
    d = lin.n_random
    grid = RotationGrid(g, sp, win, n_t)
    surr_mean, surr_std, surr_q, lv = cv_surrogate(lin, levels)
    gen = np.random.default_rng(rng)
    g_mom, g_tail = gen.spawn(2)
    z = _sobol_normals(g_mom, d, reps, m)                    # (R, m, d)
    zf = z.reshape(reps * m, d)
    y = _full(grid, lin, tolerances, zf, eng).reshape(8, reps, m, n_p)
    y_l = lin.statistics(zf).reshape(8, reps, m, n_p)
    if progress is not None:
        progress(reps * m, reps * m)
    m2_l = surr_std ** 2 + surr_mean ** 2
    mean_r = surr_mean[None] + (y - y_l).mean(axis=2).transpose(1, 0, 2)      # (R, 8, N)
    m2_r = m2_l[None] + (y * y - y_l * y_l).mean(axis=2).transpose(1, 0, 2)
    std_r = np.sqrt(np.maximum(m2_r - mean_r ** 2, 0.0))
    q_r = surr_q[None] + (np.quantile(y, lv, axis=2) - np.quantile(y_l, lv, axis=2)
                          ).transpose(2, 1, 0, 3)                              # (R, 8, L+2, N)
    mean, se_mean = _replicate_summary(mean_r)
    m2 = m2_r.mean(axis=0)
    std = np.sqrt(np.maximum(m2 - mean ** 2, 0.0))
    se_std = _replicate_summary(std_r)[1]
    q, se_q = _replicate_summary(q_r)
    targets = _tail_targets(lin, surr_std) if d > 0 else []
    n_eval = reps * m
    dirs = _sobol_normals(g_tail, d, reps, n_dir) if targets else None
    dev_t = [t for t in targets if t[0] % 2 == 1]
    ave_t = [t for t in targets if t[0] % 2 == 0]
    if dev_t:
        corr = _tail_corrections(grid, lin, tolerances, eng, dev_t, surr_q[:, -2:], dirs)
        c_mean, c_se = _replicate_summary(corr)
        for t, (i, p) in enumerate(dev_t):
            q[i, -2:, p] = surr_q[i, -2:, p] + c_mean[t]
            se_q[i, -2:, p] = c_se[t]
    if ave_t:
        c_mean, c_se = _replicate_summary(_line_bounds(grid, lin, tolerances, eng, ave_t,
                                                       dirs))
        for t, (i, p) in enumerate(ave_t):
            q[i, -2:, p] = c_mean[t]
            se_q[i, -2:, p] = c_se[t]
    n_eval += reps * n_dir * 2 * len(targets) * 2
    flat_y = y.reshape(8, reps * m, n_p)
    summaries = [_summary(flat_y[i], mean[i], std[i], q[i], se_mean[i], se_std[i], se_q[i],
                          levels, bins) for i in range(8)]
    wall = time.perf_counter() - t_start
    logger.debug("monte_carlo(cv): %d paired + %d tail evaluations in %.3f s", reps * m,
                 n_eval - reps * m, wall)
    return MonteCarloResult(*summaries[:4], n_samples=reps * m, replicates=reps,
                            wall_time=wall, n_evaluations=n_eval,
                            samples={k: flat_y[i] for i, k in enumerate(ALL_STATISTICS)},
                            **common, **dict(zip(ALL_STATISTICS[4:], summaries[4:])))


def _summary(x, mean, std, q, se_mean, se_std, se_q, levels, bins):
    """StatSummary from the estimates and the paired samples x (S, N) (histograms)."""
    n_p = x.shape[1]
    counts = np.zeros((n_p, bins), dtype=np.int64)
    edges = np.zeros((n_p, bins + 1))
    for p in range(n_p):
        counts[p], edges[p] = np.histogram(x[:, p], bins=bins)
    nq = levels.size
    return StatSummary(mean, std, levels, q[:nq], q[nq:], np.stack([mean - 3 * std,
                                                                    mean + 3 * std]),
                       counts, edges, se_mean, se_std, se_q[:nq], se_q[nq:])
