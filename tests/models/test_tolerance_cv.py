"""Control-variate Monte Carlo about the linearised deviation (meshphase.models.tolerance_cv,
meshphase.models.tolerance_linear). No times are asserted."""

import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from scipy import special

from meshphase.errors import ModelWarning
from meshphase.models import _kernels
from meshphase.models.tolerance import (
                                        ALL_STATISTICS,
                                        ToleranceBand,
                                        Tolerances,
                                        RotationGrid,
                                        map_values,
                                        monte_carlo,
                                        observation_window,
                                        table2_case,
                                        )
from meshphase.models.tolerance_cv import monte_carlo_cv
from meshphase.models.tolerance_linear import (
                                               chi_mean,
                                               chi_pdf,
                                               chi_sf,
                                               exceedance,
                                               linearised_deviation,
                                               solve_level,
                                               )

needs_numba = pytest.mark.skipif(not _kernels.HAVE_NUMBA, reason="numba not importable")


@pytest.fixture(scope="module")
def case3():
    g, sp, tol = table2_case(3)
    return g, sp, tol, observation_window(sp)


def _series(g, sp, win, n_t, tol, values):
    """Full-model deviation series (4, N, n_t) at parameter values (d,) (kernel numpy path)."""
    grid = RotationGrid(g, sp, win, n_t)
    es, ks, er, kr, ep, kp = map_values(np.atleast_2d(values), tol, g.n_planets)
    cks, sks = np.cos(ks), np.sin(ks)
    ckr, skr = np.cos(kr), np.sin(kr)
    d_s, d_r = _kernels.deltas_numpy(*grid.arrays, grid.cpsi, grid.spsi, grid.R, es, cks, sks,
                                     er, ckr, skr, ep, np.cos(kp), np.sin(kp))
    a_s, a_r = grid.g_s * d_s[0].T, grid.g_r * d_r[0].T              # (N, n_t)
    return np.stack([a_s - a_s[:1], a_r - a_r[:1], a_s, a_r])


def test_linearisation_matches_finite_differences():
    # a non-trivial mean point: non-zero mean errors, random angles (normal bands)
    g, sp, _ = table2_case(3)
    win = observation_window(sp)
    tol = Tolerances(e_sun=ToleranceBand(0.1e-3, 0.2e-3), kappa_sun=ToleranceBand(0.3, 0.2),
                     e_ring=ToleranceBand(-0.2e-3, 0.5e-3), kappa_ring=1.0,
                     e_planet=ToleranceBand(0.05e-3, 0.2e-3),
                     kappa_planet=ToleranceBand(0.2, 0.1))
    n_t = 64
    lin = linearised_deviation(g, sp, tol, win, n_t)
    assert lin.n_random == 3 + 2 * g.n_planets and lin.jac.shape == (4, 4, n_t, lin.n_random)
    np.testing.assert_allclose(lin.d0, _series(g, sp, win, n_t, tol, lin.mean), atol=1e-14)
    for j in range(lin.n_random):
        h = 1e-6 * lin.sigma[j]
        step = np.zeros(lin.n_random)
        step[j] = h
        fd = (_series(g, sp, win, n_t, tol, lin.mean + step)
              - _series(g, sp, win, n_t, tol, lin.mean - step)) / (2 * h)
        scale = np.max(np.abs(fd)) + 1e-300
        np.testing.assert_allclose(lin.jac[..., j], fd, atol=1e-6 * scale)
    # planet 1 relative series are identically zero
    assert not np.any(lin.jac[:2, 0]) and not np.any(lin.d0[:2, 0])


def test_linear_distribution_matches_sampling_of_the_linear_model(case3):
    g, sp, tol, win = case3
    lin = linearised_deviation(g, sp, tol, win)
    from meshphase.models.tolerance_cv import cv_surrogate
    levels = np.array([0.1, 0.5, 0.9])
    mean, std, q, lv = cv_surrogate(lin, levels)
    z = np.random.default_rng(3).standard_normal((200000, lin.n_random))
    y = lin.statistics(z)                                    # (8, S, N)
    for i in range(8):
        s = np.std(y[i], axis=0)
        ok = std[i] > 1e-12
        # 200000 samples: relative standard error of a mean ~ 2e-3 * cv, of a std ~ 2e-3
        assert np.all(np.abs(y[i].mean(axis=0) - mean[i])[ok] <= 6 * s[ok] / math.sqrt(2e5))
        np.testing.assert_allclose(s[ok], std[i][ok], rtol=0.02)
        np.testing.assert_allclose(np.quantile(y[i], levels, axis=0)[:, ok], q[i, :3][:, ok],
                                   rtol=0.02, atol=0.02 * np.max(std[i]))


@needs_numba
def test_cv_agrees_with_plain_within_standard_errors(case3):
    """Statistical test. Plain: 2**15 pseudo-random samples in 16 replicates; cv: defaults
    with 16 replicates. Each comparison's z = |difference| / sqrt(SE_cv^2 + SE_plain^2)
    is roughly t-distributed with ~15 degrees of freedom under "both estimate the same
    thing": P(|t_15| > 6) = 2.4e-5, so over the <= 4 x 8 x 4 = 128 comparisons (means,
    stds, both 3-sigma bounds, every statistic and planet with a spread) the false-failure
    rate is <= 0.3 % (union bound), for any seed."""
    g, sp, tol, win = case3
    plain = monte_carlo(g, sp, tol, win, 2 ** 15, sampler="random", rng=11, replicates=16)
    cv = monte_carlo(g, sp, tol, win, 1024, method="cv", rng=12, replicates=16)
    assert cv.method == "cv" and plain.method == "plain"
    n_cmp = 0
    for s in ALL_STATISTICS:
        a, b = plain.stat(s), cv.stat(s)
        ok = a.std > 1e-12
        for x, y, sx, sy in ((a.mean, b.mean, a.se_mean, b.se_mean),
                             (a.std, b.std, a.se_std, b.se_std),
                             (a.bound3[0], b.bound3[0], a.se_bound3[0], b.se_bound3[0]),
                             (a.bound3[1], b.bound3[1], a.se_bound3[1], b.se_bound3[1])):
            z = np.abs(x - y)[ok] / np.sqrt(sx ** 2 + sy ** 2)[ok]
            assert np.all(z < 6.0), (s, z)
            n_cmp += int(ok.sum())
    assert 0 < n_cmp <= 128
    # and the cv's own standard errors are far smaller than plain's at 1/8 of the samples
    assert np.nanmax(cv.dev_s.se_bound3[1][1:] / plain.dev_s.se_bound3[1][1:]) < 0.2


@needs_numba
def test_cv_result_layout_and_reproducible(case3):
    g, sp, tol, win = case3
    a = monte_carlo(g, sp, tol, win, 256, method="cv", rng=5, tail_directions=4)
    b = monte_carlo_cv(g, sp, tol, win, 256, rng=5, tail_directions=4)
    for s in ALL_STATISTICS:
        np.testing.assert_array_equal(a.stat(s).bound3, b.stat(s).bound3)
        assert a.samples[s].shape == (256, 4)
        assert np.all(np.isfinite(a.stat(s).se_mean))
    assert a.n_samples == 256 and a.n_evaluations > 256 and a.sampler == "sobol"
    d = a.to_dict()
    assert d["method"] == "cv" and d["n_evaluations"] == a.n_evaluations
    # planet 1 relative statistics are 0 exactly
    assert a.dev_s.mean[0] == 0.0 and a.dev_s.bound3[1][0] == 0.0
    assert np.all(a.dev_s.bound3[0][1:] < a.dev_s.mean[1:])
    assert np.all(a.dev_s.mean[1:] < a.dev_s.bound3[1][1:])


@needs_numba
def test_zero_tolerances_give_zero_spread(case3):
    g, sp, _, win = case3
    tol = Tolerances(kappa_sun=0.1, kappa_ring=1.0, kappa_planet=0.3)
    res = monte_carlo(g, sp, tol, win, 16, method="cv", rng=0, replicates=2)
    for s in ALL_STATISTICS:
        st_ = res.stat(s)
        assert np.all(st_.std == 0.0) and np.all(st_.bound3 == 0.0) and np.all(st_.mean == 0.0)


@settings(max_examples=25, deadline=None)
@given(c=st.floats(0.05, 20.0), es=st.floats(0.0, 0.5e-3), er=st.floats(0.0, 0.5e-3),
       ep=st.floats(0.0, 0.5e-3), ks=st.floats(-3.0, 3.0), kp=st.floats(-3.0, 3.0))
@example(c=3.0, es=0.0, er=0.000247884223959883, ep=0.000247884223959883, ks=0.0, kp=0.0)
@example(c=2.0, es=0.0, er=0.0, ep=5e-324, ks=0.0, kp=0.0)   # a subnormal spread: no overflow
@example(c=2.0, es=1.4879975500833057e-163, er=0.0, ep=0.0, ks=0.0, kp=0.0)  # rho^2 underflows
def test_scaling_tolerances_scales_the_linear_spread(c, es, er, ep, ks, kp):
    from meshphase.models.tolerance_cv import cv_surrogate
    g, sp, _ = table2_case(3)
    win = observation_window(sp)

    def tol(f):
        return Tolerances(e_sun=ToleranceBand(0.0, f * es), kappa_sun=ks,
                          e_ring=ToleranceBand(0.0, f * er), kappa_ring=0.5,
                          e_planet=ToleranceBand(0.0, f * ep), kappa_planet=kp)

    lin1 = linearised_deviation(g, sp, tol(1.0), win, 48)
    lin2 = linearised_deviation(g, sp, tol(c), win, 48)
    levels = np.array([0.5])
    m1, s1, q1, _ = cv_surrogate(lin1, levels)
    m2, s2, q2, _ = cv_surrogate(lin2, levels)
    scale = max(np.max(s1), 1e-300)
    # Ave rows (even) are exact Gaussians: they scale to rounding. Dev rows (odd) are a
    # direction-set quadrature in the SVD basis of J sigma; c J can come back in a rotated
    # basis where singular values nearly coincide, which moves the result by the
    # quadrature's own error (1024 circle nodes: O(1e-6); 8192 Sobol directions: O(1e-4)),
    # not by the scaling: they are held to 1e-3
    ave, dev = slice(0, None, 2), slice(1, None, 2)
    np.testing.assert_allclose(s2[ave], c * s1[ave], rtol=1e-9, atol=1e-12 * c * scale)
    np.testing.assert_allclose(m2[ave], c * m1[ave], rtol=1e-9, atol=1e-12 * c * scale)
    np.testing.assert_allclose(q2[ave], c * q1[ave], rtol=1e-7, atol=1e-9 * c * scale)
    np.testing.assert_allclose(s2[dev], c * s1[dev], rtol=1e-3, atol=1e-9 * c * scale)
    np.testing.assert_allclose(m2[dev], c * m1[dev], rtol=1e-3, atol=1e-9 * c * scale)
    np.testing.assert_allclose(q2[dev], c * q1[dev], rtol=1e-3, atol=1e-9 * c * scale)
    assert np.all(s1 >= 0) and np.all(np.isfinite(q1))


@settings(max_examples=40, deadline=None)
@given(alpha=st.floats(1e-6, 1 - 1e-6), k=st.integers(1, 7),
       seed=st.integers(0, 2 ** 31 - 1), m=st.integers(1, 40))
@example(alpha=0.5, k=1, seed=4730, m=5)   # a Newton step g / dg overflowed: bisect instead
def test_solve_level_inverts_exceedance(alpha, k, seed, m):
    rho = np.random.default_rng(seed).normal(size=m)
    w = np.full(m, 1.0 / m)
    q = solve_level(np.array([alpha]), rho, w, k)
    p_hi = exceedance(q, rho, w, k)
    # the exceedance is a step at q = 0 when rho has both signs: check the bracket
    if np.all(rho > 0) or np.all(rho < 0) or abs(q[0]) > 1e-9 * np.max(np.abs(rho)):
        assert p_hi[0] == pytest.approx(alpha, rel=1e-6, abs=1e-12)


def test_chi_helpers_against_scipy():
    from scipy import stats
    x = np.linspace(0.0, 8.0, 33)
    for k in (1, 2, 3, 6):
        np.testing.assert_allclose(chi_sf(x, k), stats.chi(k).sf(x), rtol=1e-12, atol=1e-300)
        np.testing.assert_allclose(chi_pdf(x[1:], k), stats.chi(k).pdf(x[1:]), rtol=1e-12)
        assert chi_mean(k) == pytest.approx(stats.chi(k).mean(), rel=1e-13)
    # the single-direction Gaussian case: P(|z| rho > q) with rho = +-1 halves is Phi(-q)
    q = solve_level(np.array([special.ndtr(-3.0)]), np.array([1.0, -1.0]), np.array([.5, .5]), 1)
    assert q[0] == pytest.approx(3.0, rel=1e-10)


def test_helpers_empty_and_bad_inputs():
    assert chi_sf(np.zeros(0), 2).shape == (0,) and chi_pdf(np.zeros(0), 3).shape == (0,)
    for bad_k in (0, -1, 2.5, True):
        with pytest.raises(ValueError):
            chi_sf(1.0, bad_k)
        with pytest.raises(ValueError):
            chi_mean(bad_k)
        with pytest.raises(ValueError):
            chi_pdf(1.0, bad_k)
    with pytest.raises(ValueError, match="direction"):
        exceedance(np.array([0.1]), np.zeros(0), np.zeros(0), 2)
    with pytest.raises(ValueError, match="direction"):
        solve_level(np.array([0.1]), np.zeros(0), np.zeros(0), 2)
    with pytest.raises(ValueError, match="alpha"):
        solve_level(np.array([1.5]), np.ones(3), np.ones(3) / 3, 2)
    with pytest.raises(ValueError, match="weights"):
        solve_level(np.array([0.1]), np.ones(3), np.ones(2), 2)
    assert solve_level(np.zeros(0), np.ones(3), np.ones(3) / 3, 2).shape == (0,)


def test_linearised_deviation_empty_and_bad_inputs(case3):
    g, sp, tol, win = case3
    lin = linearised_deviation(g, sp, tol, win, 32)
    assert lin.statistics(np.zeros((0, lin.n_random))).shape == (8, 0, 4)
    with pytest.raises(ValueError, match="columns"):
        lin.statistics(np.zeros((3, lin.n_random + 1)))
    with pytest.raises(TypeError):
        linearised_deviation(g, sp, {"e_sun": 1e-4}, win)
    with pytest.raises(ValueError, match="uniform"):
        linearised_deviation(g, sp, Tolerances(kappa_sun="uniform"), win)
    with pytest.raises(ValueError):
        linearised_deviation(g, sp, tol, win, n_times=1)
    with pytest.raises(ValueError):
        linearised_deviation(g, sp, Tolerances(e_sun=ToleranceBand(0, 0.2)), win)
    # no random parameter: d = 0, zero Jacobian
    lin0 = linearised_deviation(g, sp, Tolerances(), win, 32)
    assert lin0.n_random == 0 and lin0.statistics(np.zeros((2, 0))).shape == (8, 2, 4)


def test_monte_carlo_cv_empty_and_bad_inputs(case3):
    g, sp, tol, win = case3
    res = monte_carlo(g, sp, tol, win, 0, method="cv")
    assert res.n_samples == 0 and np.all(np.isnan(res.dev_s.mean)) and res.n_evaluations == 0
    assert monte_carlo_cv(g, sp, tol, win, 0).samples["dev_s"].shape == (0, 4)
    with pytest.raises(ValueError, match="method"):
        monte_carlo(g, sp, tol, win, 16, method="importance")
    with pytest.raises(ValueError):
        monte_carlo_cv(g, sp, tol, win, -1)
    with pytest.raises(ValueError):
        monte_carlo_cv(g, sp, tol, win, 16, tail_directions=0)
    with pytest.raises(TypeError):
        monte_carlo_cv(g, sp, "bands", win, 16)
    with pytest.raises(ValueError, match="angles"):
        monte_carlo_cv(g, sp, table2_case(3, angles="uniform")[2], win, 16)
    with pytest.raises(ValueError, match="zero mean"):
        monte_carlo_cv(g, sp, Tolerances(e_sun=ToleranceBand(1e-4, 1e-4)), win, 16)
    with pytest.warns(ModelWarning, match="powers of 2"):
        monte_carlo_cv(g, sp, tol, win, 24, replicates=2, tail_directions=2)


def test_tolerance_import_does_not_load_scipy_stats():
    import subprocess
    import sys
    code = ("import sys, meshphase.models.tolerance, meshphase.models.tolerance_cv, "
            "meshphase.models.tolerance_linear; "
            "print(any(m.startswith('scipy.stats') for m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "False"
