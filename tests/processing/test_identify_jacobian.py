"""identify_errors with the closed-form Jacobian against the finite-difference path, and
pass_phasing_jacobian against differences of predict_pass_phasing.

Tables and errors are those of tests/processing/test_compare.py (seed 000 Table 1 gearset at
5 % speed, 30 s, exact and measured passes).
"""

import math

import numpy as np
import pytest

from meshphase.compare.identify import PARAMETER_NAMES, identify_errors
from meshphase.compare.pass_model import pass_phasing_jacobian, predict_pass_phasing
from meshphase.models.mesh_phasing import ShaftHoleErrors
from meshphase.kinematics.pass_table import PassTable

from test_compare import ERRORS, exact_table, gearset, measured


def _vec(err, n=4):
    ep = np.broadcast_to(np.asarray(err.e_planet, float), (n,))
    kp = np.broadcast_to(np.asarray(err.kappa_planet, float), (n,))
    v = [float(err.e_sun) * math.cos(float(err.kappa_sun)),
         float(err.e_sun) * math.sin(float(err.kappa_sun)),
         float(err.e_ring) * math.cos(float(err.kappa_ring)),
         float(err.e_ring) * math.sin(float(err.kappa_ring))]
    for e, k in zip(ep, kp):
        v += [e * math.cos(k), e * math.sin(k)]
    return np.array(v)


def _err(p):
    return ShaftHoleErrors(e_sun=math.hypot(p[0], p[1]), kappa_sun=math.atan2(p[1], p[0]),
                           e_ring=math.hypot(p[2], p[3]), kappa_ring=math.atan2(p[3], p[2]),
                           e_planet=np.hypot(p[4::2], p[5::2]),
                           kappa_planet=np.arctan2(p[5::2], p[4::2]))


@pytest.mark.parametrize("gauge", ["sun", "ring"])
@pytest.mark.parametrize("err", ["none", "all"])
def test_pass_jacobian_value_and_central_differences(gauge, err):
    # gamma equals predict_pass_phasing bit for bit; the Jacobian matches central
    # differences of predict_pass_phasing (wrapped, so a pass near a whole cycle does not
    # jump). Step h_j = 1e-2 max(|p_j|, 1e-4 R_c) (1e-7 .. 3e-6 m): gamma carries the rounding
    # of its whole argument o Z lag / 2 pi (up to ~Z cycles, so ~eps Z = 2e-14 cycles), which
    # over h gives <= 2e-7 cycles/m, while the truncation (h / R_c)^2 |J| stays below 1e-9
    # of |J| (~30 cycles/m). Tolerance 1e-6 of the largest entry: 30x the rounding bound.
    g = gearset("cw")
    tab = exact_table("cw", gauge, "all")
    e = ERRORS[err]
    gam, J = pass_phasing_jacobian(tab, g, e)
    np.testing.assert_array_equal(gam, predict_pass_phasing(tab, g, e))
    p0 = np.zeros(12) if e is None else _vec(e)
    Jfd = np.empty_like(J)
    for j in range(12):
        h = 1e-2 * max(abs(p0[j]), 1e-4 * g.carrier_radius)
        pp, pm = p0.copy(), p0.copy()
        pp[j] += h
        pm[j] -= h
        d = predict_pass_phasing(tab, g, _err(pp)) - predict_pass_phasing(tab, g, _err(pm))
        Jfd[:, j] = (d - np.floor(d + 0.5)) / (2 * h)
    ok = np.isfinite(gam)
    assert ok.any()
    np.testing.assert_allclose(J[ok], Jfd[ok], rtol=0, atol=1e-6 * np.max(np.abs(J[ok])))
    assert np.all(np.isnan(J[~ok]))


def test_pass_jacobian_empty_and_bad_inputs():
    g = gearset("cw")
    gam, J = pass_phasing_jacobian(PassTable.empty("sun"), g, None)
    assert gam.shape == (0,) and J.shape == (0, 12)
    with pytest.raises(TypeError, match="PassTable"):
        pass_phasing_jacobian("sun.csv", g, None)
    with pytest.raises(TypeError, match="ShaftHoleErrors"):
        pass_phasing_jacobian(exact_table("cw", "sun", "all"), g, {"e_sun": 1e-4})
    with pytest.raises(ValueError, match="one realisation"):
        pass_phasing_jacobian(exact_table("cw", "sun", "all"), g, ShaftHoleErrors(e_sun=[0, 1e-4]))


def test_identify_bad_jac_option():
    with pytest.raises(ValueError, match="jac"):
        identify_errors([exact_table("cw", "sun", "none")], gearset("cw"), jac="exact")


def _params(res):
    return (np.array([v[0] for v in res.parameters.values()]),
            np.array([v[1] for v in res.parameters.values()]),
            np.array([v[2] for v in res.parameters.values()]))


@pytest.mark.parametrize("case", ["planets", "measured"])
def test_analytic_and_finite_difference_identify_agree(case):
    # Full-rank (planets, rcond 1e-3) and rank-deficient measured (Table 2) fits: the same
    # estimates, sigma, rank, flags and notes. Measured differences: 1.1e-11 m and 2.5e-11 m
    # on estimates of 1e-4 m (against e_std ~1e-8 m), sigma 2e-7 and 6e-7 relative, std
    # 8e-5 and 3e-6 relative: the finite-difference Jacobian's own error (diff_step 1e-6).
    # Bounds: 1e-9 m, 1e-5 and 1e-3 relative.
    g = gearset("cw")
    if case == "planets":
        tabs = [exact_table("cw", "sun", "planets"), exact_table("cw", "ring", "planets")]
        kw = dict(gears=("planet",), rcond=1e-3)
    else:
        tabs = [measured("cw", "table2", "sun")[1], measured("cw", "table2", "ring_sun_encoder")[1]]
        kw = {}
    a = identify_errors(tabs, g, jac="2-point", **kw)
    b = identify_errors(tabs, g, **kw)
    pa, sa, fa = _params(a)
    pb, sb, fb = _params(b)
    assert list(a.parameters) == list(b.parameters)
    np.testing.assert_array_equal(fa, fb)
    assert fa.any()
    np.testing.assert_allclose(pb[fa], pa[fa], rtol=0, atol=1e-9)
    np.testing.assert_allclose(sb[fa], sa[fa], rtol=1e-3)
    assert b.sigma == pytest.approx(a.sigma, rel=1e-5)
    assert b.rms_after == pytest.approx(a.rms_after, rel=1e-5)
    assert round(np.trace(a.projector)) == round(np.trace(b.projector))
    assert a.identifiable == b.identifiable and a.notes == b.notes
    assert [r["identifiable"] for r in a.table] == [r["identifiable"] for r in b.table]
    np.testing.assert_allclose(b.singular_values, a.singular_values,
                               rtol=0, atol=1e-5 * a.singular_values[0])
    # the closed form gives residuals and Jacobian in one evaluation
    assert b.cost_evaluations < a.cost_evaluations / 5
    assert 0 < b.jacobian_evaluations <= b.cost_evaluations


def test_analytic_identify_on_flat_directions_stays_in_the_subspace():
    # Every offset free, sun and ring invisible: both paths fit inside the directions the
    # design at zero determines, where the flat ones stay 0, so they reach the same point.
    # Measured: estimates within 2.6e-9 m of each other (|p| 4.0e-4 m), singular values
    # within 3.5e-6 of the largest, each path 2.5e-8 m from the projected truth. Bounds:
    # 1e-8 m, and 1e-7 m from the truth (the fits over all directions, whose flat ones ran to
    # the 5 % R_c bounds, were 4e-7 m from it and 1.5e-6 m apart).
    g = gearset("cw")
    tabs = [exact_table("cw", "sun", "all"), exact_table("cw", "ring", "all")]
    a = identify_errors(tabs, g, jac="2-point")
    b = identify_errors(tabs, g)
    assert round(np.trace(a.projector)) == round(np.trace(b.projector))
    np.testing.assert_array_equal(_params(a)[2], _params(b)[2])
    assert a.notes == b.notes and a.identifiable == b.identifiable
    assert b.subspace_error(ERRORS["all"]) < 1e-7 and a.subspace_error(ERRORS["all"]) < 1e-7
    np.testing.assert_allclose(_params(b)[0], _params(a)[0], rtol=0, atol=1e-8)
    assert b.sigma == pytest.approx(a.sigma, rel=1e-3)
    assert b.cost_evaluations < a.cost_evaluations / 5
    assert list(b.parameters) == PARAMETER_NAMES(4)
