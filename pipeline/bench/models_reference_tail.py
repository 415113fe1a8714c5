"""Directional control-variate reference of tail quantiles (the 3-sigma bounds), means and
standard deviations for ``meshphase bench models``.

Why: a plain Monte Carlo of n samples resolves a quantile at tail mass alpha = Phi(-3) only
to a relative standard error of about sqrt(alpha / n) / (f(q) q) (1e-3 for seed 000 case 3 at
n = 1e7), so it cannot judge an estimator's bound to 1e-3. This reference spends the same
budget of full-model evaluations on an estimator of the tail probability whose variance is
far smaller, and computes its standard error from the sample it uses.

Method. The model Y(z) of standard normal errors z (d dimensions) is written along rays,
z = r u with u uniform on the unit sphere and r ~ chi_d independent, and Y(0) = 0 (zero mean
errors). Its first-order model Y_L(r u) = r rho_L(u) has an exactly known tail probability
P_L(q) (the caller supplies it). For a threshold q, conditioning on the direction,

    P(Y > q) = P_L(q) + E_u[ P(r rho(r, u) > q | u) - P(r rho_L(u) > q | u) ],

with rho(r, u) = Y(r u) / r. Both conditional probabilities are chi_d tail masses beyond a
crossing radius (chi_d survival function), so every direction contributes a number in
(-1, 1) that is
the difference of two nearly equal probabilities: the variance is that of the small
nonlinear part, not of an indicator. The full model is evaluated at ``nodes`` fixed radii
per direction (all statistics at once); rho(., u) is the polynomial through rho_L(u) at
r = 0 (its exact limit) and those values, and each crossing radius solves r rho(r, u) = q
by Newton's method from the linear crossing q / rho_L(u) (rho is nearly constant in r;
crossings inside ``r_max`` that do not converge are counted in the diagnostics). Lower
bounds are the upper bounds of -Y. Beyond ``r_max`` rho is held at its ``r_max`` value
(P(chi_6 > 8) = 7e-12).

The correction E_u[...] is estimated on a grid of ``n_grid`` thresholds around the linear
bound (+- ``span`` relative); the bound is the root of P_L(q) (exact, at any q) plus the
cubic spline of the correction through the grid (Illinois regula falsi inside the grid cell
where the sign changes). Standard errors: the delta method, SE(q) = SE(P(q)) / |dP/dq|, with
SE(P) from the sample variance of the independent per-direction terms (pseudo-random
directions); and, as a check, batch means over ``groups`` groups of directions (both are
reported). With the exact first two moments of the linear model the same rays give the means
and standard deviations: E_r[Y(r u)] and E_r[Y(r u)^2] of the polynomial are sums of chi_d
moments (:func:`chi_moments`), corrected the same way.

The polynomial in r is exact for smooth rho; a Dev on a finite time grid is only piecewise
smooth in r (its argmax jumps between grid points), and the interpolation error of that is
measured by :func:`interpolation_check` (exact crossings by secant iteration on the full
model against the interpolated ones, on a subset of directions) and reported with the
reference.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import special
from scipy.interpolate import CubicSpline

from ..validate import as_positive, as_positive_int

__all__ = ["directional_bounds", "radial_nodes", "interpolation_check", "chi_moments"]


def radial_nodes(n_nodes: int, r_max: float) -> np.ndarray:
    """Radii of the full-model evaluations along a ray: Chebyshev-Lobatto points of
    [0, r_max] without 0, shape (n_nodes,) [-] (radii of standard normal points).

    Parameters
    ----------
    n_nodes : int
        Number of radii [-], >= 1.
    r_max : float
        Largest radius [-], > 0.
    """
    k = as_positive_int(n_nodes, "n_nodes")
    r = as_positive(r_max, "r_max")
    return 0.5 * r * (1.0 - np.cos(np.pi * np.arange(1, k + 1) / k))


def _chi_tail(x, d, upper):
    """P(chi_d > x) (upper) or P(chi_d < x) for x >= 0, elementwise (closed form for even d:
    exp(-x^2/2) times the first d/2 terms of the exponential series)."""
    h = 0.5 * x * x
    if d % 2 == 0 and d <= 32:
        term = np.ones_like(h)
        acc = np.ones_like(h)
        for j in range(1, d // 2):
            term = term * h / j
            acc = acc + term
        sf = np.exp(-h) * acc
        return sf if upper else 1.0 - sf
    return special.gammaincc(0.5 * d, h) if upper else special.gammainc(0.5 * d, h)


def chi_moments(d: int, m: int) -> np.ndarray:
    """E[r^j], j = 0 .. m, of r ~ chi_d: 2^(j/2) Gamma((d + j) / 2) / Gamma(d / 2) [-]."""
    j = np.arange(m + 1)
    return np.exp(0.5 * j * math.log(2.0) + special.gammaln(0.5 * (d + j))
                  - special.gammaln(0.5 * d))


def _poly(coef, r):
    """Horner: value and derivative of coef (K+1, ...) (increasing powers) at r."""
    if coef.shape[0] == 1:
        return coef[0] + np.zeros_like(r), np.zeros_like(r)
    der = coef[-1] + np.zeros_like(r)
    val = coef[-1] * r
    val += coef[-2]
    for c in coef[-3::-1]:
        der *= r
        der += val
        val *= r
        val += c
    return val, der


def _newton_crossing(c, tt, ok, r_start, r_max, iters):
    """Radius r where r p(r) = tt, p the polynomial c (rho held at p(r_max) beyond r_max),
    by Newton's method from r_start, on the rays where ok (elsewhere r_start is kept)."""
    r = np.minimum(r_start, 2.0 * r_max)
    for _ in range(iters):
        inside = r < r_max
        val, der = _poly(c, np.minimum(r, r_max))
        f = r * val - tt
        fp = val + np.where(inside, r * der, 0.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            step = np.where(ok & (fp != 0.0), f / fp, 0.0)
        r = np.clip(r - step, 1e-12, 2.0 * r_max)
        if np.all((np.abs(step) <= 1e-13 * r) | (r >= 2.0 * r_max)):
            break
    return r


def _ray_terms(coef, rho_l, sgn, tau, d, r_max, iters):
    """Per-direction differences P_full - P_lin of the tail events at thresholds tau.

    coef (K+1, B, T) polynomial of rho(r) per direction and target, rho_l (B, T) linear
    slopes, sgn (T,) side, tau (T, J) signed thresholds (event sgn Y > tau). The crossing
    of the full model solves r sgn rho(r) = tau by Newton's method from the linear crossing
    (rho held at its r_max value beyond r_max). Returns (diff (B, T, J), unconverged count).
    """
    tt = tau[None]                                          # (1, T, J)
    srl = (sgn * rho_l)[..., None]                          # (B, T, 1)
    ok = tt * srl > 0.0
    up = np.broadcast_to(tt > 0.0, ok.shape)
    with np.errstate(divide="ignore", invalid="ignore"):
        r_lin = np.where(ok, tt / srl, 0.0)
    c = coef[:, :, :, None] * sgn[None, None, :, None]      # sgn rho, (K+1, B, T, 1)
    r = _newton_crossing(c, tt, ok, r_lin, r_max, iters)
    val = _poly(c, np.minimum(r, r_max))[0]
    bad = ok & (r < r_max) & ~(np.abs(r * val - tt) <= 1e-9 * np.abs(tt))
    out = []
    for rr in (r_lin, r):
        p = np.where(ok, _chi_tail(np.where(ok, rr, 0.0), d, True), 0.0)
        p = np.where(up | ok, p, 1.0)                       # no crossing, tau < 0: always
        out.append(np.where(ok & ~up, 1.0 - p, p))          # tau < 0: the event is r < r*
    return out[1] - out[0], int(np.count_nonzero(bad))


def _fit(model, lin_rho, u, nodes, vinv):
    """(coef (K+1, B, C), rho_L (B, C)) of the rays u (B, d)."""
    rho_l = np.asarray(lin_rho(u), dtype=float)
    vals = [rho_l] + [np.asarray(model(r * u), dtype=float) / r for r in nodes]
    if rho_l.ndim != 2 or rho_l.shape[1] == 0 or any(v.shape != rho_l.shape for v in vals):
        raise ValueError("model and lin_rho must give the same (S, C) columns, C >= 1; got "
                         f"{[v.shape for v in vals]}")
    return np.einsum("jk,kbc->jbc", vinv, np.stack(vals)), rho_l


def _solve(q_grid, d_grids, lin_tail, alpha, iters=40):
    """Roots of P(q) = alpha, P(q) = P_L(q) (exact) + D(q) (cubic spline of an estimated
    correction through the grid), for several corrections at once, and dP/dq there.

    q_grid (T, J); d_grids (G, T, J). The root is bracketed by the grid cell where P - alpha
    changes sign and refined by the Illinois variant of regula falsi. Returns q, dp (G, T);
    NaN where P - alpha does not change sign on the grid.
    """
    n_g, n_t, _ = d_grids.shape
    splines = [CubicSpline(q_grid[t], d_grids[:, t].T) for t in range(n_t)]
    cols = np.arange(n_g)

    def f(q):                                                    # q (G, T) -> (G, T)
        d = np.stack([splines[t](q[:, t])[cols, cols] for t in range(n_t)], axis=1)
        return np.asarray(lin_tail(q.T), dtype=float).T + d - alpha

    fg = np.asarray(lin_tail(q_grid), dtype=float)[None] + d_grids - alpha     # (G, T, J)
    change = np.sign(fg[..., :-1]) * np.sign(fg[..., 1:]) <= 0
    ok = change.any(axis=-1)
    j = np.argmax(change, axis=-1)                                               # (G, T)
    a = np.take_along_axis(np.broadcast_to(q_grid, fg.shape), j[..., None], -1)[..., 0]
    b = np.take_along_axis(np.broadcast_to(q_grid, fg.shape), j[..., None] + 1, -1)[..., 0]
    fa = np.take_along_axis(fg, j[..., None], -1)[..., 0]
    fb = np.take_along_axis(fg, j[..., None] + 1, -1)[..., 0]
    for _ in range(iters):
        with np.errstate(divide="ignore", invalid="ignore"):
            c = np.where(fb != fa, b - fb * (b - a) / (fb - fa), 0.5 * (a + b))
        c = np.where(np.isfinite(c), c, 0.5 * (a + b))
        fc = f(c)
        same = np.sign(fc) == np.sign(fb)
        # Illinois: the end a kept while the new point lands on b's side has its value
        # halved, so the retained end moves too
        a, fa = np.where(same, a, b), np.where(same, 0.5 * fa, fb)
        b, fb = c, fc
        if np.all((np.abs(b - a) <= 1e-14 * np.abs(b)) | (fb == 0) | ~ok):
            break
    q = np.where(ok, b, np.nan)
    h = 1e-5 * (q_grid[:, -1] - q_grid[:, 0])[None]
    qq = np.where(ok, q, q_grid[None, :, 0])
    return q, np.where(ok, (f(qq + h) - f(qq - h)) / (2 * h), np.nan)


class _Sums:
    """Running sums over directions, per group: tail differences (targets x thresholds) and
    the radial moment corrections (columns)."""

    def __init__(self, groups, grid_shape, n_cols, moments):
        self.count = np.zeros(groups, dtype=np.int64)
        self.p1 = np.zeros((groups,) + grid_shape)
        self.p2 = np.zeros(grid_shape)
        self.moments = moments
        if moments:
            self.m1 = np.zeros((groups, n_cols))
            self.m2 = np.zeros((groups, n_cols))
            self.cov = np.zeros((3, n_cols))                # sums of a^2, b^2, a b

    def add(self, g, diff, dm1=None, dm2=None):
        self.count[g] += diff.shape[0]
        self.p1[g] += diff.sum(axis=0)
        self.p2 += (diff * diff).sum(axis=0)
        if self.moments:
            self.m1[g] += dm1.sum(axis=0)
            self.m2[g] += dm2.sum(axis=0)
            self.cov += np.stack([(dm1 * dm1).sum(0), (dm2 * dm2).sum(0), (dm1 * dm2).sum(0)])


def _moment_terms(coef, mu):
    """Radial corrections E_r[Y - Y_L | u] and E_r[Y^2 - Y_L^2 | u] of the rays, (B, C) each,
    from the polynomial rho(r, u) = sum_j coef_j r^j (coef_0 = rho_L) and mu_j = E[r^j]."""
    k1 = coef.shape[0]
    dm1 = sum(coef[j] * mu[j + 1] for j in range(1, k1))
    dm2 = sum(coef[j] * coef[i] * mu[i + j + 2] for j in range(k1) for i in range(k1)
              if i + j > 0)
    return dm1, dm2


def _check_inputs(d, n_directions, groups, n_grid, alpha, span, targets, q_lin):
    d = as_positive_int(d, "d")
    m_dir = as_positive_int(n_directions, "n_directions")
    groups = as_positive_int(groups, "groups")
    n_grid = as_positive_int(n_grid, "n_grid")
    if groups < 2 or m_dir < 2 * groups:
        raise ValueError(f"need groups >= 2 and n_directions >= 2 groups, got {groups}, {m_dir}")
    if n_grid < 4:
        raise ValueError(f"n_grid must be >= 4 (cubic spline), got {n_grid}")
    alpha = float(alpha)
    if not 0.0 < alpha < 0.5:
        raise ValueError(f"alpha must lie in (0, 0.5), got {alpha!r}")
    span = as_positive(span, "span")
    if span >= 1.0:
        raise ValueError(f"span must be < 1 (relative half width), got {span!r}")
    tg = [(int(c), int(s)) for c, s in targets]
    if not tg or any(s not in (-1, 1) or c < 0 for c, s in tg):
        raise ValueError(f"targets must be non-empty (column >= 0, side +-1), got {targets!r}")
    q_lin = np.asarray(q_lin, dtype=float)
    if q_lin.shape != (len(tg),) or not np.all(np.isfinite(q_lin)) or np.any(q_lin == 0):
        raise ValueError(f"q_lin must be finite and non-zero, one per target, got {q_lin!r}")
    return d, m_dir, groups, n_grid, alpha, span, tg, q_lin


def directional_bounds(model, lin_rho, lin_tail, d: int, targets, q_lin, n_directions: int, *,
                       lin_moments=None, alpha: float = float(special.ndtr(-3.0)),
                       nodes: int = 4, r_max: float = 8.0, span: float = 0.04,
                       n_grid: int = 5, groups: int = 10, batch: int = 4096, iters: int = 8,
                       rng=None, progress=None) -> dict:
    """Tail quantiles (and optionally means and standard deviations) of a model of Gaussian
    errors by directional sampling with the linear model as a control variate (module
    docstring).

    Parameters
    ----------
    model : callable
        ``model(z)`` -> values (S, C) of C columns at standard normal points z (S, d) [-];
        ``model(0) = 0``.
    lin_rho : callable
        ``lin_rho(u)`` -> first-order slopes (S, C) at unit directions u (S, d): the linear
        model is Y_L(r u) = r lin_rho(u).
    lin_tail : callable
        ``lin_tail(q)`` -> (T, J) exact tail probabilities of the linear model at thresholds
        q (T, J): P(Y_L > q) for an upper target, P(Y_L < q) for a lower one.
    d : int
        Dimension of z [-], >= 1.
    targets : sequence of (int, int)
        (column, side), side +1 for the upper quantile (tail mass ``alpha`` above), -1 for
        the lower one.
    q_lin : array_like
        The linear model's quantile of each target (centre of the threshold grid), shape (T,).
    n_directions : int
        Directions [-] (full-model evaluations: ``nodes`` per direction).
    lin_moments : (array_like, array_like), optional
        Exact E[Y_L] and E[Y_L^2] per column, shapes (C,); with them the result also holds
        the means and standard deviations of Y (the polynomial's radial moments, corrected
        the same way).
    alpha : float
        Tail mass [-] in (0, 0.5); default Phi(-3).
    nodes : int
        Full-model radii per direction (:func:`radial_nodes`) [-].
    r_max : float
        Largest radius [-].
    span : float
        Half width of the threshold grid relative to |q_lin| [-], in (0, 1).
    n_grid : int
        Thresholds on the grid [-], >= 4.
    groups : int
        Groups of directions for the batch-means check [-], >= 2.
    batch : int
        Directions per model call [-] (bounds the memory).
    iters : int
        Newton iterations of each crossing radius [-].
    rng : None, int or numpy.random.Generator
        Source of the (pseudo-random, independent) directions.
    progress : callable, optional
        ``progress(done, total)`` after each batch (directions).

    Returns
    -------
    dict
        ``"bound"``, ``"se"`` (delta method), ``"se_batch"`` (batch means), each (T,);
        (over the groups whose bound lies on the grid; NaN when fewer than 2 do),
        ``"n_directions"``, ``"n_evaluations"``, ``"unconverged"`` (crossings inside r_max
        whose residual stayed above 1e-9 relative), ``"q_grid"``, ``"p_grid"`` (T, J); with
        ``lin_moments`` also ``"mean"``, ``"std"``, ``"se_mean"``, ``"se_std"``,
        ``"se_batch_mean"``, ``"se_batch_std"`` (C,).

    Raises
    ------
    ValueError
        On bad sizes, or when a bound falls outside the threshold grid (widen ``span``).
    """
    d, m_dir, groups, n_grid, alpha, span, tg, q_lin = _check_inputs(
        d, n_directions, groups, n_grid, alpha, span, targets, q_lin)
    batch = as_positive_int(batch, "batch")
    nd = radial_nodes(nodes, r_max)
    vinv = np.linalg.inv(np.vander(np.concatenate([[0.0], nd]), increasing=True))
    mu = chi_moments(d, 2 * nd.size + 2)
    cols = np.array([c for c, _ in tg])
    sgn = np.array([s for _, s in tg], dtype=float)
    q_grid = q_lin[:, None] + span * np.abs(q_lin)[:, None] * np.linspace(-1, 1, n_grid)
    tau = sgn[:, None] * q_grid
    gen = np.random.default_rng(rng)
    sizes = [m_dir // groups + (1 if i < m_dir % groups else 0) for i in range(groups)]
    sums = None
    bad = done = 0
    for gi, m in enumerate(sizes):
        for a in range(0, m, batch):
            b = min(m, a + batch) - a
            u = gen.standard_normal((b, d))
            u /= np.linalg.norm(u, axis=1, keepdims=True)
            coef, rho_l = _fit(model, lin_rho, u, nd, vinv)
            if cols.max() >= rho_l.shape[1]:
                raise ValueError(f"target column {cols.max()} >= {rho_l.shape[1]} columns")
            if sums is None:
                sums = _Sums(groups, tau.shape, rho_l.shape[1], lin_moments is not None)
            diff, nb = _ray_terms(coef[:, :, cols], rho_l[:, cols], sgn, tau, d, r_max, iters)
            bad += nb
            sums.add(gi, diff, *(_moment_terms(coef, mu) if sums.moments else ()))
            done += b
            if progress is not None:
                progress(done, m_dir)
    out = _finish_bounds(sums, lin_tail, q_grid, alpha, span)
    out.update({"n_directions": m_dir, "n_evaluations": m_dir * nd.size, "unconverged": bad})
    if lin_moments is not None:
        out.update(_finish_moments(sums, lin_moments))
    return out


def _finish_bounds(sums, lin_tail, q_grid, alpha, span):
    """Bounds, delta-method and batch-means standard errors from the sums."""
    m_dir = int(sums.count.sum())
    mean = sums.p1.sum(axis=0) / m_dir
    var = np.maximum(sums.p2 / m_dir - mean * mean, 0.0) / (m_dir - 1)
    d_all = np.concatenate([mean[None], sums.p1 / sums.count[:, None, None]])
    q_all, dp_all = _solve(q_grid, d_all, lin_tail, alpha)
    q, dp, qb = q_all[0], dp_all[0], q_all[1:]
    if np.any(~np.isfinite(q)):
        raise ValueError("directional_bounds: a bound lies outside the threshold grid "
                         f"(span {span:g} around the linear bound); widen span")
    se_p = np.array([np.sqrt(np.interp(q[t], q_grid[t], var[t])) for t in range(q.size)])
    n_ok = np.sum(np.isfinite(qb), axis=0)                  # groups whose root is on the grid
    with np.errstate(invalid="ignore", divide="ignore"):
        se_batch = np.where(n_ok >= 2, np.nanstd(np.where(n_ok >= 2, qb, 0.0), axis=0, ddof=1)
                            / np.sqrt(np.maximum(n_ok, 1)), np.nan)
    p_grid = np.asarray(lin_tail(q_grid), dtype=float) + mean
    return {"bound": q, "se": se_p / np.abs(dp), "se_batch": se_batch, "q_grid": q_grid,
            "p_grid": p_grid}


def _finish_moments(sums, lin_moments):
    """Means and standard deviations with delta-method and batch-means standard errors."""
    e1, e2 = (np.asarray(v, dtype=float) for v in lin_moments)
    if e1.shape != sums.m1.shape[1:] or e2.shape != e1.shape:
        raise ValueError(f"lin_moments must be two arrays of shape {sums.m1.shape[1:]}")
    n = int(sums.count.sum())
    a1, a2 = sums.m1.sum(0) / n, sums.m2.sum(0) / n
    m1, m2 = e1 + a1, e2 + a2
    std = np.sqrt(np.maximum(m2 - m1 * m1, 0.0))
    v11 = (sums.cov[0] / n - a1 * a1) / (n - 1)
    v22 = (sums.cov[1] / n - a2 * a2) / (n - 1)
    v12 = (sums.cov[2] / n - a1 * a2) / (n - 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        g1, g2 = np.where(std > 0, -m1 / std, 0.0), np.where(std > 0, 0.5 / std, 0.0)
        gm1 = e1 + sums.m1 / sums.count[:, None]
        gstd = np.sqrt(np.maximum(e2 + sums.m2 / sums.count[:, None] - gm1 * gm1, 0.0))
    r = sums.count.size
    return {"mean": m1, "std": std, "se_mean": np.sqrt(np.maximum(v11, 0.0)),
            "se_std": np.sqrt(np.maximum(g1 * g1 * v11 + g2 * g2 * v22 + 2 * g1 * g2 * v12,
                                         0.0)),
            "se_batch_mean": np.std(gm1, axis=0, ddof=1) / math.sqrt(r),
            "se_batch_std": np.std(gstd, axis=0, ddof=1) / math.sqrt(r)}


def interpolation_check(model, lin_rho, d: int, targets, q, n_directions: int = 256, *,
                        nodes: int = 4, r_max: float = 8.0, iters: int = 6, rng=None) -> dict:
    """Interpolated against exact crossing radii at the thresholds q (T,), on a few rays.

    The exact crossing solves sgn Y(r u) = sgn q by secant iteration on the full model
    (a few extra evaluations per ray and target); the result is the largest relative
    difference of the crossing radii and the mean difference of the tail probabilities,
    relative to the tail mass of the linear bound (what a bias of the reference's P would
    be), both per target.

    Returns
    -------
    dict
        ``"max_rel_radius"`` (T,), ``"mean_dp"`` (T,) [-], ``"n_directions"``.
    """
    m = as_positive_int(n_directions, "n_directions")
    nd = radial_nodes(nodes, r_max)
    vinv = np.linalg.inv(np.vander(np.concatenate([[0.0], nd]), increasing=True))
    tg = [(int(c), int(s)) for c, s in targets]
    q = np.asarray(q, dtype=float)
    if q.shape != (len(tg),):
        raise ValueError(f"q must have one value per target, got shape {q.shape}")
    cols = np.array([c for c, _ in tg])
    sgn = np.array([s for _, s in tg], dtype=float)
    gen = np.random.default_rng(rng)
    u = gen.standard_normal((m, d))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    coef, rho_l = _fit(model, lin_rho, u, nd, vinv)
    coef, rho_l = coef[:, :, cols], rho_l[:, cols]
    tau = sgn * q                                                      # (T,)
    srl = sgn * rho_l
    ok = (tau * srl > 0) & (tau / np.where(srl == 0, 1, srl) < r_max)
    r0 = np.where(ok, tau / np.where(srl == 0, 1, srl), 1.0)
    c = coef * sgn[None, None, :]
    r = _newton_crossing(c, tau[None], ok, r0, r_max, iters)
    ok &= (np.abs(r * _poly(c, np.minimum(r, r_max))[0] - tau) <= 1e-9 * np.abs(tau)) & (r < r_max)
    r_int = r
    # exact: secant on the full model, from the interpolated radius
    rr = [r_int * (1 - 1e-3), r_int]
    ff = []
    for x in rr:
        y = np.asarray(model((x[..., None] * u[:, None, :]).reshape(-1, d)), float)
        y = y.reshape(m, len(tg), -1)[:, np.arange(len(tg)), cols]
        ff.append(sgn * y - tau)
    for _ in range(iters):
        df = ff[1] - ff[0]
        with np.errstate(divide="ignore", invalid="ignore"):
            x = np.where(ok & (df != 0), rr[1] - ff[1] * (rr[1] - rr[0]) / df, rr[1])
        y = np.asarray(model((x[..., None] * u[:, None, :]).reshape(-1, d)), float)
        y = y.reshape(m, len(tg), -1)[:, np.arange(len(tg)), cols]
        rr = [rr[1], x]
        ff = [ff[1], sgn * y - tau]
    r_ex = rr[1]
    rel = np.where(ok, np.abs(r_ex - r_int) / np.where(ok, r_ex, 1.0), 0.0)
    up = tau > 0
    p_int = np.where(ok, _chi_tail(np.where(ok, r_int, 0), d, True), 0.0)
    p_ex = np.where(ok, _chi_tail(np.where(ok, r_ex, 0), d, True), 0.0)
    dp = np.where(up, p_int - p_ex, p_ex - p_int).mean(axis=0)
    return {"max_rel_radius": rel.max(axis=0), "mean_dp": dp, "n_directions": m}
