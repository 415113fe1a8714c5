"""First-order (linearised) phasing deviation and the exact distribution of its statistics.

The phasing deviation series D(t; theta) (sun and ring meshes, relative to planet 1 and
absolute, every planet) is a smooth function of the shaft hole position errors theta. About
the mean errors mu it is, to first order,

    D_L(t; theta) = D(t; mu) + J(t) (theta - mu),      J(t) = dD/dtheta (analytic),

so with Gaussian errors theta = mu + sigma z, z ~ N(0, I_d) (the tolerance bands read as
+-3 sigma), the linearised statistics have a distribution known in closed form or as a
one-dimensional integral:

- Ave_L = mean_t D_L is Gaussian, mean mean_t D(t; mu), std |mean_t J sigma|;
- when D(t; mu) = 0 (zero mean radial errors), Dev_L = max_t - min_t of J(t) sigma z is
  positively homogeneous of degree 1 in z. Writing J sigma = U S V^T (rank k) and
  w = V^T z ~ N(0, I_k) = r u with r ~ chi_k independent of the direction u,
  Dev_L = r rho(u), rho(u) = Dev of U S u. Then E[Dev_L] = E[chi_k] E_u[rho],
  E[Dev_L^2] = k E_u[rho^2] and P(Dev_L <= q) = E_u[P(chi_k <= q / rho(u))]; the direction
  average is a trapezoid rule on the circle (k = 2, 1024 nodes, periodic: the kinks of a max
  make it second order, ~1e-6 relative here), the two directions +-1 (k = 1), or scrambled
  Sobol points on the sphere (k >= 3, 8192 points, fixed seed).

This is what the control-variate estimator of :mod:`.tolerance_cv` corrects with the full
model. Derivatives: each mesh angle is delta = atan2(Y, X) with
X = R - e_p cos th - e_j cos(a_j - psi_n), Y = -e_p sin th - e_j sin(a_j - psi_n)
(kernel notation, :mod:`._kernels`), so d delta = (X dY - Y dX) / (X^2 + Y^2) with
(dX, dY) = (-cos(a_j - psi_n), -sin(a_j - psi_n)) for e_j, (e_j sin(a_j - psi_n),
-e_j cos(a_j - psi_n)) for kappa_j, (-cos th, -sin th) for e_p and (e_p sin th, -e_p cos th)
for kappa_p. A radial error is signed along its angle (the Monte Carlo's |e| with the angle
turned by pi is the same offset).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from ..runtime.lazy import special, stats
from ..validate import as_finite_array
from .tolerance_model import case_inputs, RotationGrid, resolve_n_times

__all__ = ["LinearisedDeviation", "linearised_deviation", "SERIES", "chi_sf", "chi_pdf",
           "chi_mean", "exceedance", "solve_level"]

#: Deviation series, in the order of the statistics pairs of
#: :data:`meshphase.models.tolerance.ALL_STATISTICS` (series i gives statistics 2i (Ave) and
#: 2i + 1 (Dev)).
SERIES = ("sun", "ring", "sun_abs", "ring_abs")
_CIRCLE_NODES = 1024
_SPHERE_POINTS = 8192


@dataclass(frozen=True, eq=False)
class LinearisedDeviation:
    """The first-order deviation model about the mean errors (:func:`linearised_deviation`).

    Attributes
    ----------
    t : numpy.ndarray
        Time grid [s], shape (n_t,).
    d0 : numpy.ndarray
        Deviation series at the mean errors [-] (mesh cycles), shape (4, N, n_t), series in
        the order of :data:`SERIES`.
    jac : numpy.ndarray
        dD/dtheta per random error parameter [1/m] or [1/rad], shape (4, N, n_t, d).
    mean, sigma : numpy.ndarray
        Mean and standard deviation of each random parameter [m] or [rad], shape (d,).
    columns : tuple
        (field, planet index or None) of each random parameter, the sampling order of
        :meth:`meshphase.models.tolerance.Tolerances.columns`.
    """

    t: np.ndarray
    d0: np.ndarray
    jac: np.ndarray
    mean: np.ndarray
    sigma: np.ndarray
    columns: tuple

    @property
    def n_random(self) -> int:
        """Number of random parameters d [-]."""
        return self.mean.size

    @functools.cached_property
    def scaled(self) -> np.ndarray:
        """J sigma: change of the series per standard normal unit [-], shape (4, N, n_t, d)."""
        return self.jac * self.sigma

    def series(self, z) -> np.ndarray:
        """Linearised series for standard normal points z (S, d) [-], shape (S, 4, N, n_t)."""
        z = as_finite_array(z, "z", ndim=2)
        if z.shape[1] != self.n_random:
            raise ValueError(f"z must have {self.n_random} columns, got shape {z.shape}")
        return self.d0[None] + np.einsum("gntd,sd->sgnt", self.scaled, z, optimize=True)

    def statistics(self, z) -> np.ndarray:
        """Ave and Dev of the linearised series for points z (S, d) [-], shape (8, S, N)
        in the order of :data:`meshphase.models.tolerance.ALL_STATISTICS`."""
        z = as_finite_array(z, "z", ndim=2)
        if z.shape[1] != self.n_random:
            raise ValueError(f"z must have {self.n_random} columns, got shape {z.shape}")
        n_s, (n_g, n_p, n_t) = z.shape[0], self.d0.shape
        out = np.empty((8, n_s, n_p))
        mat = np.ascontiguousarray(self.scaled.reshape(self.d0.size, self.n_random).T)  # (d, 4Nn_t)
        d0 = self.d0.reshape(-1)
        step = max(1, (1 << 20) // max(1, d0.size))
        for a in range(0, n_s, step):
            zz = z[a:a + step]
            s = np.broadcast_to(d0, (zz.shape[0], d0.size)).copy()
            for j in range(self.n_random):    # d axpy's: no BLAS threads for this small product
                s += zz[:, j:j + 1] * mat[j]
            s = s.reshape(-1, n_g, n_p, n_t)
            out[0::2, a:a + step] = s.mean(axis=-1).transpose(1, 0, 2)
            out[1::2, a:a + step] = (s.max(axis=-1) - s.min(axis=-1)).transpose(1, 0, 2)
        return out

    def ave_moments(self) -> tuple[np.ndarray, np.ndarray]:
        """Exact mean and std of Ave_L [-], each shape (4, N) (Ave_L is Gaussian)."""
        a = self.scaled.mean(axis=2)
        return self.d0.mean(axis=2), np.sqrt(np.sum(a * a, axis=-1))

    def homogeneous(self, tol: float = 1e-13) -> bool:
        """True when D(t; mu) = 0, so that Dev_L is homogeneous of degree 1 in z."""
        return bool(np.max(np.abs(self.d0), initial=0.0) <= tol)

    def dev_directions(self, series: int, planet: int):
        """Reduced direction set of Dev_L of one series: (k, rho, weights).

        rho(u) = Dev of (J sigma) restricted to its rank-k range, on the direction nodes of
        the module docstring; weights sum to 1. k = 0 for a constant series (rho empty).
        """
        m = self.scaled[series, planet]                       # (n_t, d)
        if m.size == 0 or not np.any(m):
            return 0, np.zeros(0), np.zeros(0)
        u_, s, _ = np.linalg.svd(m, full_matrices=False)
        k = int(np.sum(s > 1e-12 * s[0]))
        us = u_[:, :k] * s[:k]
        if k == 1:
            dirs = np.array([[1.0], [-1.0]])
        elif k == 2:
            phi = 2.0 * math.pi * (np.arange(_CIRCLE_NODES) + 0.5) / _CIRCLE_NODES
            dirs = np.stack([np.cos(phi), np.sin(phi)], axis=1)
        else:
            u = stats.qmc.Sobol(k, scramble=True, rng=np.random.default_rng(12345)).random(
                _SPHERE_POINTS)
            dirs = special.ndtri(np.clip(u, 2.0 ** -53, 1.0 - 2.0 ** -53))
            dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        v = dirs @ us.T                                      # (M, n_t)
        rho = v.max(axis=1) - v.min(axis=1)
        return k, rho, np.full(rho.size, 1.0 / rho.size)


def _planet_derivs(X, Y, grads):
    den = X * X + Y * Y
    return [(X * dy - Y * dx) / den for dx, dy in grads]


def linearised_deviation(gearset, speeds, tolerances, window, n_times: int | None = None, *,
                         points_per_rev: int = 64) -> LinearisedDeviation:
    """Analytic first-order model of the phasing deviation series about the mean errors.

    Parameters
    ----------
    gearset : Gearset
        Tooth counts, planet angles psi_n [rad], carrier radius R_c [m], direction.
    speeds : Speeds
        Absolute speeds [rad/s].
    tolerances : Tolerances
        Error bands ([m], [rad]); every random band must be "normal" (the linear map of a
        Gaussian is Gaussian).
    window : ObservationWindow or (t0, T) tuple [s] or window kind
        Observation window.
    n_times : int, optional
        Time samples [-], >= 2; default :func:`meshphase.models.tolerance.default_n_times`.
    points_per_rev : int
        Used by the default ``n_times`` [-].

    Returns
    -------
    LinearisedDeviation

    Raises
    ------
    TypeError, ValueError
        On bad arguments, a uniform random band, or bands reaching the carrier radius.
    """
    g, sp, win = case_inputs(gearset, speeds, tolerances, window)
    n_t = resolve_n_times(sp, win, n_times, points_per_rev)
    n_p = g.n_planets
    cols = tolerances.columns(n_p)
    for name, _, band in cols:
        if band.is_random and band.distribution != "normal":
            raise ValueError(f"linearised_deviation: {name} has a {band.distribution!r} band; "
                             "the first-order distribution needs normal bands")
    grid = RotationGrid(g, sp, win, n_t)
    cs, ss, cr, sr, cp, spn = grid.arrays
    val = {}
    for name, n, band in cols:
        val[(name, n)] = band.mean
    rand = [(name, n) for name, n, band in cols if band.is_random]
    idx = {c: i for i, c in enumerate(rand)}
    d = len(rand)
    d0 = np.zeros((4, n_p, n_t))
    jac = np.zeros((4, n_p, n_t, d))
    for gi, (gear, c, s, gfac) in enumerate((("sun", cs, ss, grid.g_s),
                                             ("ring", cr, sr, grid.g_r))):
        e_j, k_j = val[(f"e_{gear}", None)], val[(f"kappa_{gear}", None)]
        ca = c * math.cos(k_j) - s * math.sin(k_j)
        sa = s * math.cos(k_j) + c * math.sin(k_j)
        for n in range(n_p):
            e_p, k_p = val[("e_planet", n)], val[("kappa_planet", n)]
            ct = cp * math.cos(k_p) - spn * math.sin(k_p)
            st = spn * math.cos(k_p) + cp * math.sin(k_p)
            crel = ca * grid.cpsi[n] + sa * grid.spsi[n]
            srel = sa * grid.cpsi[n] - ca * grid.spsi[n]
            X = grid.R - e_p * ct - e_j * crel
            Y = -e_p * st - e_j * srel
            d0[gi + 2, n] = gfac * np.arctan2(Y, X)
            params = ((f"e_{gear}", None), (f"kappa_{gear}", None), ("e_planet", n),
                      ("kappa_planet", n))
            grads = ((-crel, -srel), (e_j * srel, -e_j * crel), (-ct, -st),
                     (e_p * st, -e_p * ct))
            for p, dv in zip(params, _planet_derivs(X, Y, grads)):
                if p in idx:
                    jac[gi + 2, n, :, idx[p]] = gfac * dv
        d0[gi] = d0[gi + 2] - d0[gi + 2, :1]
        jac[gi] = jac[gi + 2] - jac[gi + 2, :1]
    mean = np.array([val[c] for c in rand], dtype=float)
    sigma = np.array([b.sigma for _, _, b in cols if b.is_random], dtype=float)
    return LinearisedDeviation(grid.t, d0, jac, mean, sigma, tuple(rand))


def _check_k(k):
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 1:
        raise ValueError(f"k (degrees of freedom) must be a positive integer, got {k!r}")
    return int(k)


def _check_rho(alpha, rho, weights):
    rho = np.asarray(rho, dtype=float)
    if rho.ndim == 0 or rho.shape[-1] == 0:
        raise ValueError(f"rho must have at least one direction (last axis), got {rho.shape}")
    w = np.asarray(weights, dtype=float)
    if w.shape not in ((), rho.shape[-1:]) or np.any(w < 0) or not np.all(np.isfinite(rho)):
        raise ValueError("weights must be >= 0 with one per direction and rho finite")
    if alpha is not None:
        a = np.asarray(alpha, dtype=float)
        if np.any(~(a > 0.0)) or np.any(~(a < 1.0)):
            raise ValueError(f"alpha must lie in (0, 1), got {a.tolist()}")
    return rho, w


def chi_sf(x, k: int):
    """P(chi_k > x) for x >= 0 [-] (k = 1, 2 in closed form)."""
    k = _check_k(k)
    x = np.asarray(x, dtype=float)
    if k == 2:
        return np.exp(-0.5 * x * x)
    if k == 1:
        return special.erfc(x / math.sqrt(2.0))
    return special.gammaincc(0.5 * k, 0.5 * x * x)


def chi_mean(k: int) -> float:
    """E[chi_k] = sqrt(2) Gamma((k + 1) / 2) / Gamma(k / 2) [-]."""
    k = _check_k(k)
    return math.sqrt(2.0) * math.exp(math.lgamma(0.5 * (k + 1)) - math.lgamma(0.5 * k))


def exceedance(q, rho, weights, k: int):
    """P(r rho(u) > q), r ~ chi_k, averaged over directions with ``weights`` [-].

    ``q`` has shape (L,) (or broadcasts against rho's leading axes); rho (..., M).
    """
    k = _check_k(k)
    rho, w = _check_rho(None, rho, weights)
    return _exceedance_and_slope(np.asarray(q, dtype=float), rho, w, k)[0]


def chi_pdf(x, k: int):
    """Density of chi_k at x >= 0 [-]."""
    k = _check_k(k)
    x = np.asarray(x, dtype=float)
    c = (1.0 - 0.5 * k) * math.log(2.0) - math.lgamma(0.5 * k)
    with np.errstate(divide="ignore"):
        lx = np.log(x)
    return np.exp(c + (k - 1) * lx - 0.5 * x * x) if k != 1 else np.exp(c - 0.5 * x * x)


def _exceedance_and_slope(q, rho, weights, k):
    """exceedance(q) and its derivative in q [1/-] (rho (..., M), q (...))."""
    qq = q[..., None]
    with np.errstate(divide="ignore", invalid="ignore"):
        x = np.where(rho != 0.0, qq / rho, -1.0)
    ok = x > 0.0
    xs = np.where(ok, x, 0.0)
    if k == 2:       # sf = exp(-x^2 / 2), pdf = x sf: one exponential
        sf = np.exp(-0.5 * xs * xs)
        pdf = xs * sf
    else:
        sf = chi_sf(xs, k)
        pdf = chi_pdf(xs, k)
    pos = rho > 0.0
    p = np.where(pos, np.where(qq <= 0.0, 1.0, sf), np.where(qq >= 0.0, 0.0, 1.0 - sf))
    p = np.where((rho == 0.0) & (qq < 0.0), 1.0, p)
    p = np.where((rho == 0.0) & (qq >= 0.0), 0.0, p)
    # a subnormal rho (a spread of 1e-322) overflows the density to inf: the Newton step of
    # _solve_upper is then not finite and falls back to bisection
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        dens = np.where(ok, pdf / np.abs(rho), 0.0)
    return np.sum(p * weights, axis=-1), -np.sum(dens * weights, axis=-1)


def solve_level(alpha, rho, weights, k: int, start=None, iters: int = 100,
                rtol: float = 1e-11):
    """q with P(r rho(u) > q) = alpha (r ~ chi_k, averaged over the directions) [-].

    Newton's method on log P, safeguarded by bisection on the bracket +-max|rho| r_max
    (P(chi_k > r_max) < 1e-300). ``alpha`` shape (L,) or broadcasting against rho's
    leading axes; rho (..., M); ``start`` an initial guess of the shape of the result.
    """
    k = _check_k(k)
    rho, weights = _check_rho(alpha, rho, weights)
    alpha = np.asarray(alpha, dtype=float)
    flip = alpha > 0.5
    if np.any(flip):
        # P(r rho > q) = alpha  <=>  P(r (-rho) > -q) = 1 - alpha: Newton on the log of the
        # small probability converges in a few steps, on the log of one near 1 it does not
        shape = np.broadcast_shapes(alpha.shape, rho.shape[:-1])
        fl = np.broadcast_to(flip, shape)
        sg = np.where(fl, -1.0, 1.0)
        rho2 = np.broadcast_to(rho, shape + rho.shape[-1:]) * sg[..., None]
        a2 = np.where(fl, 1.0 - np.broadcast_to(alpha, shape), np.broadcast_to(alpha, shape))
        st = None if start is None else sg * np.broadcast_to(np.asarray(start, float), shape)
        return sg * _solve_upper(a2, rho2, weights, k, st, iters, rtol)
    return _solve_upper(alpha, rho, weights, k, start, iters, rtol)


def _solve_upper(alpha, rho, weights, k, start, iters, rtol):
    """:func:`solve_level` for alpha <= 0.5."""
    rmax = math.sqrt(k) + 40.0
    big = np.max(np.abs(rho), axis=-1, initial=0.0) * rmax + 1e-300
    shape = np.broadcast_shapes(alpha.shape, np.shape(big))
    lo = np.broadcast_to(-big, shape).copy()
    hi = -lo
    if start is None:
        x = np.zeros(shape)
    else:
        x = np.clip(np.broadcast_to(np.asarray(start, float), shape), lo, hi).copy()
    la = np.log(alpha)
    done = np.zeros(shape, dtype=bool)
    for _ in range(iters):
        g, dg = _exceedance_and_slope(x, rho, weights, k)
        above = g > alpha
        lo = np.where(above, x, lo)
        hi = np.where(above, hi, x)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # -> bisection below
            xn = x - (np.log(g) - la) * g / dg
        bad = ~np.isfinite(xn) | (xn < lo) | (xn > hi) | (g <= 0.0)
        xn = np.where(bad, 0.5 * (lo + hi), xn)
        done = done | (np.abs(xn - x) <= rtol * np.maximum(np.abs(xn), 1e-300))
        x = np.where(done & ~bad, xn, np.where(done, x, xn))
        if np.all(done):
            break
    return x
