"""The directional control-variate reference (meshphase.bench.models_reference_tail) on models
with a known exact answer: a monotone transform of a Gaussian linear form (the quantiles are
the transformed Gaussian quantiles) and a homogeneous, Dev-like transform of a chi_2 radius.
Exact values come from mpmath; the standard errors are checked by z-scores over repeats."""

import math

import mpmath
import numpy as np
import pytest
from scipy import special, stats

from meshphase.bench.models_reference_tail import (chi_moments, directional_bounds,
                                                   interpolation_check, radial_nodes)

ALPHA = float(special.ndtr(-3.0))
mpmath.mp.dps = 30


def _mp_alpha():
    return mpmath.ncdf(-3)


class Quadratic:
    """Y = x + c x^2, x = a . z (|a| = 1); Y_L = x. Monotone for x > -1 / (2 c)."""

    def __init__(self, c, d=3):
        self.c = c
        self.d = d
        self.a = np.zeros(d)
        self.a[:2] = (0.6, 0.8)

    def model(self, z):
        x = z @ self.a
        return np.stack([x + self.c * x * x], axis=1)

    def lin_rho(self, u):
        return (u @ self.a)[:, None]

    @staticmethod
    def lin_tail(q):
        out = np.empty_like(q)
        out[0] = special.ndtr(q[0])          # target 0: lower
        out[1] = special.ndtr(-q[1])         # target 1: upper
        return out

    targets = [(0, -1), (0, 1)]
    q_lin = [-3.0, 3.0]

    def exact(self):
        c = mpmath.mpf(self.c)
        lo, hi = -mpmath.sqrt(2) * mpmath.erfinv(1 - 2 * _mp_alpha()), None
        hi = -lo
        bounds = [float(x + c * x * x) for x in (lo, hi)]
        mean = float(c)                                     # E[x^2] = 1
        std = float(mpmath.sqrt(1 + 3 * c * c - c * c))     # E[Y^2] = 1 + 3 c^2
        return bounds, mean, std

    def lin_moments(self):
        return np.zeros(1), np.ones(1)


class ChiRadius:
    """Y = s (1 + e s), s = sigma |z_1:2| (sigma chi_2); Y_L = s: homogeneous, Dev-like."""

    def __init__(self, eps, sigma=0.5, d=4):
        self.eps, self.sigma, self.d = eps, sigma, d

    def model(self, z):
        s = self.sigma * np.hypot(z[:, 0], z[:, 1])
        return (s * (1 + self.eps * s / self.sigma))[:, None]

    def lin_rho(self, u):
        return (self.sigma * np.hypot(u[:, 0], u[:, 1]))[:, None]

    def lin_tail(self, q):
        x = q / self.sigma
        out = np.empty_like(q)
        out[0] = -np.expm1(-0.5 * x[0] ** 2)            # lower: P(s < q)
        out[1] = np.exp(-0.5 * x[1] ** 2)                # upper: P(s > q)
        return out

    targets = [(0, -1), (0, 1)]

    @property
    def q_lin(self):
        a = ALPHA
        return [self.sigma * math.sqrt(-2 * math.log1p(-a)),
                self.sigma * math.sqrt(-2 * math.log(a))]

    def exact(self):
        a = _mp_alpha()
        sg, e = mpmath.mpf(self.sigma), mpmath.mpf(self.eps)
        xs = [mpmath.sqrt(-2 * mpmath.log(1 - a)), mpmath.sqrt(-2 * mpmath.log(a))]
        bounds = [float(sg * x * (1 + e * x)) for x in xs]
        pi2 = mpmath.sqrt(mpmath.pi / 2)
        m1 = sg * (pi2 + 2 * e)
        m2 = sg ** 2 * (2 + 6 * e * pi2 + 8 * e * e)
        return bounds, float(m1), float(mpmath.sqrt(m2 - m1 * m1))

    def lin_moments(self):
        return (np.array([self.sigma * math.sqrt(math.pi / 2)]),
                np.array([2 * self.sigma ** 2]))


def _run(m, n_dir, rng, **kw):
    # the test models are far more nonlinear than the gear model: a wider threshold grid
    kw = {"span": 0.15, "n_grid": 9, **kw}
    return directional_bounds(m.model, m.lin_rho, m.lin_tail, m.d, m.targets, m.q_lin, n_dir,
                              lin_moments=m.lin_moments(), rng=rng, **kw)


@pytest.mark.parametrize("m", [Quadratic(0.02), ChiRadius(0.01)], ids=["quadratic", "chi"])
def test_exact_answer(m):
    bounds, mean, std = m.exact()
    res = _run(m, 20000, 1)
    for t in range(2):
        assert abs(res["bound"][t] - bounds[t]) < 4.5 * res["se"][t] + 1e-12 * abs(bounds[t])
        assert res["se"][t] < 2e-3 * abs(bounds[t])
        # the delta-method and batch-means errors agree within their own scatter (10 groups)
        assert 0.3 < res["se_batch"][t] / res["se"][t] < 2.5
    assert abs(res["mean"][0] - mean) < 4.5 * res["se_mean"][0] + 1e-12
    assert abs(res["std"][0] - std) < 4.5 * res["se_std"][0] + 1e-12
    assert res["unconverged"] == 0
    assert res["n_evaluations"] == 4 * 20000


@pytest.mark.parametrize("m", [Quadratic(0.0), ChiRadius(0.0)], ids=["quadratic", "chi"])
def test_linear_model_is_reproduced_exactly(m):
    # without a nonlinear part every ray's difference is 0: the exact linear answer, SE 0
    res = _run(m, 200, 2)
    bounds, mean, std = m.exact()
    np.testing.assert_allclose(res["bound"], bounds, rtol=1e-9)
    np.testing.assert_allclose([res["mean"][0], res["std"][0]], [mean, std], rtol=1e-12,
                               atol=1e-15)
    assert np.all(res["se"] < 1e-9 * np.abs(bounds))


def _z_scores(m, n_dir, reps, seed0):
    """z = (estimate - exact) / SE of the two bounds, the mean and the std, (reps, 4)."""
    bounds, mean, std = m.exact()
    zs = []
    for j in range(reps):
        r = _run(m, n_dir, seed0 + j)
        zs.append([(r["bound"][0] - bounds[0]) / r["se"][0],
                   (r["bound"][1] - bounds[1]) / r["se"][1],
                   (r["mean"][0] - mean) / r["se_mean"][0],
                   (r["std"][0] - std) / r["se_std"][0]])
    return np.array(zs)


@pytest.mark.parametrize("m", [Quadratic(0.03), ChiRadius(0.02)], ids=["quadratic", "chi"])
def test_standard_errors_are_calibrated(m):
    """Coverage of the z-scores over R independent repeats, per summary: the count with
    |z| < 0.674 (expected R / 2) and with |z| > 1.96 (expected R / 20) inside the central
    99.9 % of their binomial distributions. Counts, not mean z^2: at a few thousand rays the
    per-ray terms of a lower bound are heavy-tailed, so one repeat can hold a large z (the
    slow test below checks mean z^2 at a larger size)."""
    reps = 60
    zs = _z_scores(m, 4000, reps, 100)
    inside = np.sum(np.abs(zs) < 0.6745, axis=0)
    outside = np.sum(np.abs(zs) > 1.96, axis=0)
    lo, hi = stats.binom.ppf([0.0005, 0.9995], reps, 0.5)
    assert np.all((inside >= lo) & (inside <= hi)), inside
    assert np.all(outside <= stats.binom.ppf(0.9995, reps, 0.05)), outside


@pytest.mark.slow
@pytest.mark.parametrize("m", [Quadratic(0.03), ChiRadius(0.02)], ids=["quadratic", "chi"])
def test_standard_errors_mean_square_z(m):
    """mean z^2 inside the central 99.9 % of chi^2_R / R and |mean z| < 3.3 / sqrt(R)."""
    reps = 100
    zs = _z_scores(m, 40000, reps, 5000)
    lo, hi = stats.chi2.ppf([0.0005, 0.9995], reps) / reps
    msq = np.mean(zs ** 2, axis=0)
    assert np.all((msq > lo) & (msq < hi)), msq
    assert np.all(np.abs(zs.mean(axis=0)) < 3.3 / math.sqrt(reps)), zs.mean(axis=0)


def test_interpolation_check_on_polynomial_rays():
    # rho(r, u) of the quadratic model is linear in r: the interpolated crossings are exact
    m = Quadratic(0.02)
    chk = interpolation_check(m.model, m.lin_rho, m.d, m.targets, m.exact()[0], 64, rng=3)
    assert chk["n_directions"] == 64
    assert np.all(chk["max_rel_radius"] < 1e-8)
    assert np.all(np.abs(chk["mean_dp"]) < 1e-12)


def test_helpers():
    nd = radial_nodes(4, 8.0)
    assert nd.shape == (4,) and nd[-1] == pytest.approx(8.0) and np.all(np.diff(nd) > 0)
    # chi_2: E[r] = sqrt(pi / 2), E[r^2] = 2, E[r^4] = 8; chi_6: E[r^2] = 6
    np.testing.assert_allclose(chi_moments(2, 4), [1, math.sqrt(math.pi / 2), 2,
                                                   3 * math.sqrt(math.pi / 2), 8])
    assert chi_moments(6, 2)[2] == pytest.approx(6.0)
    assert chi_moments(3, 0).tolist() == [1.0]


def test_bad_inputs():
    m = Quadratic(0.05)
    good = dict(model=m.model, lin_rho=m.lin_rho, lin_tail=m.lin_tail, d=m.d,
                targets=m.targets, q_lin=m.q_lin, n_directions=100)
    for bad in ({"targets": []}, {"targets": [(0, 2), (0, 1)]}, {"q_lin": [0.0, 3.0]},
                {"q_lin": [3.0]}, {"q_lin": [np.nan, 3.0]}, {"n_directions": 10},
                {"n_directions": 0}, {"d": 0}, {"alpha": 0.5}, {"alpha": 0.0},
                {"span": 1.0}, {"span": -0.1}, {"n_grid": 3}, {"groups": 1},
                {"targets": [(1, -1), (1, 1)]}, {"nodes": 0}, {"r_max": 0.0},
                {"lin_moments": (np.zeros(2), np.ones(2))}):
        with pytest.raises((ValueError, TypeError)):
            directional_bounds(**{**good, **bad})
    # a bound outside the threshold grid: ask to widen it
    with pytest.raises(ValueError, match="widen span"):
        directional_bounds(**{**good, "q_lin": [-2.0, 2.0]}, span=0.01)
    with pytest.raises(ValueError):
        radial_nodes(0, 8.0)
    with pytest.raises(ValueError):
        radial_nodes(4, -1.0)
    with pytest.raises(ValueError):
        interpolation_check(m.model, m.lin_rho, m.d, m.targets, [1.0], 8)
    with pytest.raises(ValueError):
        interpolation_check(m.model, m.lin_rho, m.d, m.targets, [1.0, 2.0], 0)


def test_empty_model_output_is_rejected():
    # a model with no columns: the target column does not exist
    m = Quadratic(0.05)
    with pytest.raises(ValueError, match="column"):
        directional_bounds(m.model, lambda u: np.zeros((u.shape[0], 0)), m.lin_tail, m.d,
                           m.targets, m.q_lin, 100)
