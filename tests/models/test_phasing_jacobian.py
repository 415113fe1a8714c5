"""Closed-form gradient of the mesh-line deviations (meshphase.models.phasing_jacobian)
against central finite differences and an independent mpmath reference."""

import math

import mpmath
import numpy as np
import pytest

from meshphase.models.gearset import Gearset, Speeds
from meshphase.models.mesh_phasing import ShaftHoleErrors, mesh_angle_deviations
from meshphase.models.phasing_jacobian import (MeshGradientPlan, mesh_angle_gradient,
                                               n_offset_parameters)

R_C = 112.5e-3


def gearset(n=4):
    return Gearset.equally_spaced(25, 87, 29, n, R_C) if n > 1 else \
        Gearset(z_sun=25, z_ring=87, z_planet=29, planet_angles=(0.0,), carrier_radius=R_C)


def speeds(g):
    return Speeds.kinematic(g, sun=22.4, carrier=5.0)


def errors_of(p, n):
    """ShaftHoleErrors from the Cartesian vector (sun_x, sun_y, ring_x, ring_y, planet...)."""
    p = np.asarray(p, dtype=float)
    return ShaftHoleErrors(e_sun=math.hypot(p[0], p[1]), kappa_sun=math.atan2(p[1], p[0]),
                           e_ring=math.hypot(p[2], p[3]), kappa_ring=math.atan2(p[3], p[2]),
                           e_planet=np.hypot(p[4::2], p[5::2]),
                           kappa_planet=np.arctan2(p[5::2], p[4::2]))


# parameter points (Cartesian offsets [m]): zero errors, seed-sized, and near the R_c bound
# (e_sun + e_planet = 0.98 R_c at planet 1)
P_SEED = np.array([1.1e-4, 1.7e-4, -2.0e-4, 1.2e-4, 9e-5, 3e-5, 1e-4, 1.7e-4, -2.7e-4, 1.3e-4,
                   -1e-4, -1.1e-4])
P_EXTREME = np.zeros(12)
P_EXTREME[[0, 1]] = 0.60 * R_C * np.array([math.cos(2.0), math.sin(2.0)])
P_EXTREME[[2, 3]] = 0.50 * R_C * np.array([math.cos(-1.0), math.sin(-1.0)])
P_EXTREME[4:] = 0.38 * R_C * np.array([1.0, 0.0] * 4)
POINTS = {"zero": np.zeros(12), "seed": P_SEED, "extreme": P_EXTREME}


def test_value_is_the_models_deviation_bit_for_bit():
    g = gearset()
    sp = speeds(g)
    err = errors_of(P_SEED, 4)
    t = np.linspace(0.0, 1e5, 57)
    pl = np.arange(57) % 4 + 1
    for k, mesh in enumerate(("sun", "ring")):
        d, _ = mesh_angle_gradient(t, pl, g, sp, err, mesh=mesh)
        ref = mesh_angle_deviations(t, g, sp, err)[k][np.arange(57), pl - 1]
        np.testing.assert_array_equal(d, ref)


@pytest.mark.parametrize("point", list(POINTS))
@pytest.mark.parametrize("mesh", ["sun", "ring"])
def test_gradient_matches_central_differences(point, mesh):
    # Central differences with the step h_j = eps^(1/3) * max(|p_j|, 1e-4 R_c) per parameter
    # (the scale of a typical offset when p_j = 0): the truncation error is
    # h^2 |d3 delta| / 6 and the rounding error eps |delta| / h, both ~eps^(2/3) ~ 4e-11 times
    # the scale of the derivatives (|d delta / dp| ~ 1 / R_c ~ 9 rad/m, growing ~1/(R_c - e)
    # near the bound). The tolerance 1e-6 of the largest entry leaves 4 orders of margin.
    g = gearset()
    sp = speeds(g)
    p0 = POINTS[point]
    t = np.concatenate([np.linspace(0.0, 3.0, 23), [1e6]])
    pl = np.arange(t.size) % 4 + 1
    _, G = mesh_angle_gradient(t, pl, g, sp, errors_of(p0, 4), mesh=mesh)
    eps = np.finfo(float).eps
    Gfd = np.empty_like(G)
    for j in range(p0.size):
        h = eps ** (1 / 3) * max(abs(p0[j]), 1e-4 * R_C)
        pp, pm = p0.copy(), p0.copy()
        pp[j] += h
        pm[j] -= h
        dp = mesh_angle_gradient(t, pl, g, sp, errors_of(pp, 4), mesh=mesh)[0]
        dm = mesh_angle_gradient(t, pl, g, sp, errors_of(pm, 4), mesh=mesh)[0]
        Gfd[:, j] = (dp - dm) / (2 * h)
    scale = np.max(np.abs(G))
    assert scale > 1.0
    np.testing.assert_allclose(G, Gfd, rtol=0, atol=1e-6 * scale)
    # the sparsity pattern: other gear's and other planets' columns are exactly 0
    other = [2, 3] if mesh == "sun" else [0, 1]
    assert np.all(G[:, other] == 0)
    for i, n in enumerate(pl):
        cols = [4 + 2 * k + c for k in range(4) if k != n - 1 for c in (0, 1)]
        assert np.all(G[i, cols] == 0)


def _mp_delta(p, t, n, psi, w, w_pc, mesh):
    """Deviation of planet n's mesh line [rad] from the vector form of spec section 2 in
    mpmath: O_pan = R_c u_n - e_p (cos th u_n + sin th t_n), O_ga = e (cos a, sin a),
    delta = arg(O_pan - O_ga) - psi_n, with the offsets given as Cartesian components."""
    gx, gy = (p[0], p[1]) if mesh == "sun" else (p[2], p[3])
    px, py = p[4 + 2 * (n - 1)], p[5 + 2 * (n - 1)]
    wt = w * t
    a_c = gx * mpmath.cos(wt) - gy * mpmath.sin(wt)      # e cos(w t + kappa)
    a_s = gx * mpmath.sin(wt) + gy * mpmath.cos(wt)
    th_c = px * mpmath.cos(w_pc * t) - py * mpmath.sin(w_pc * t)   # e_p cos th
    th_s = px * mpmath.sin(w_pc * t) + py * mpmath.cos(w_pc * t)
    u = (mpmath.cos(psi), mpmath.sin(psi))
    tn = (-mpmath.sin(psi), mpmath.cos(psi))
    ox = R_C * u[0] - (th_c * u[0] + th_s * tn[0])
    oy = R_C * u[1] - (th_c * u[1] + th_s * tn[1])
    ang = mpmath.atan2(oy - a_s, ox - a_c) - psi
    return ang - 2 * mpmath.pi * mpmath.nint(ang / (2 * mpmath.pi))


@pytest.mark.parametrize("case", ["zero", "seed", "extreme", "one_planet", "long_time"])
@pytest.mark.parametrize("mesh", ["sun", "ring"])
def test_gradient_matches_mpmath_reference(case, mesh):
    # mpmath at 50 digits, derivatives by mpmath.diff (its own high-precision differences):
    # independent of the closed form and of float rounding. The float gradient carries a
    # few ulp of the inputs' cos/sin (the reduced angles w t are correct to ~1e-15 rad), so
    # 1e-12 relative to the largest entry is a bound with margin.
    n_pl = 1 if case == "one_planet" else 4
    g = gearset(n_pl)
    sp = speeds(g)
    p0 = {"zero": np.zeros(12), "seed": P_SEED, "extreme": P_EXTREME,
          "one_planet": P_SEED[:6], "long_time": P_SEED}[case]
    times = [0.0, 0.37, 2.9] if case != "long_time" else [1e6 + 0.123]
    planets = [1, 2, 4] if n_pl == 4 else [1, 1, 1]
    planets = planets[:len(times)]
    w = sp.w_sc if mesh == "sun" else sp.w_rc
    mpmath.mp.dps = 50
    try:
        for t, n in zip(times, planets):
            _, G = mesh_angle_gradient(np.array([t]), np.array([n]), g, sp, errors_of(p0, n_pl),
                                       mesh=mesh)
            psi = mpmath.mpf(float(g.angles[n - 1]))
            ref = np.zeros(n_offset_parameters(n_pl))
            pm = [mpmath.mpf(float(x)) for x in p0]
            for j in range(len(pm)):
                def f(x, j=j):
                    q = list(pm)
                    q[j] = x
                    return _mp_delta(q, mpmath.mpf(t), n, psi, mpmath.mpf(w), mpmath.mpf(sp.w_pc),
                                     mesh)
                ref[j] = float(mpmath.diff(f, pm[j]))
            np.testing.assert_allclose(G[0], ref, rtol=0, atol=1e-12 * np.max(np.abs(ref)))
    finally:
        mpmath.mp.dps = 15


def test_gradient_empty_and_scalar_planet():
    g = gearset()
    sp = speeds(g)
    d, G = mesh_angle_gradient(np.empty(0), np.empty(0, dtype=int), g, sp)
    assert d.shape == (0,) and G.shape == (0, 12)
    d, G = mesh_angle_gradient([0.0, 1.0], 2, g, sp, mesh="ring")
    assert d.shape == (2,) and G.shape == (2, 12)
    np.testing.assert_array_equal(d, 0.0)       # no errors: the nominal mesh line


@pytest.mark.parametrize("kwargs, exc, match", [
    (dict(planet=[1, 5]), ValueError, "planet must lie"),
    (dict(planet=[0, 1]), ValueError, "planet must lie"),
    (dict(planet=[1.0, 2.0]), ValueError, "integer"),
    (dict(planet=[1, 2, 3]), ValueError, "shape"),
    (dict(mesh="carrier"), ValueError, "mesh"),
    (dict(errors=ShaftHoleErrors(e_sun=[1e-4, 2e-4])), ValueError, "one realisation"),
    (dict(errors=ShaftHoleErrors(e_sun=0.06, e_planet=0.06)), ValueError, "carrier_radius"),
    (dict(errors="none"), TypeError, "ShaftHoleErrors"),
    (dict(gearset=None), TypeError, "Gearset"),
])
def test_gradient_bad_inputs(kwargs, exc, match):
    g = gearset()
    args = dict(t=[0.0, 1.0], planet=[1, 2], gearset=g, speeds=speeds(g), errors=None)
    args.update(kwargs)
    mesh = args.pop("mesh", "sun")
    with pytest.raises(exc, match=match):
        mesh_angle_gradient(**args, mesh=mesh)


@pytest.mark.parametrize("mesh", ["sun", "ring"])
def test_plan_equals_the_direct_gradient_bit_for_bit(mesh):
    # the plan only moves the error-independent rotations out of the loop; same operations
    # in the same order, so equality is exact for every error vector it is evaluated at
    g = gearset()
    sp = speeds(g)
    t = np.linspace(-3e4, 1e5, 83)
    pl = np.arange(83) % 4 + 1
    plan = MeshGradientPlan(t, pl, g, sp, mesh=mesh)
    assert len(plan) == 83
    for p in POINTS.values():
        err = errors_of(p, 4)
        d, G = plan.evaluate(err)
        d0, G0 = mesh_angle_gradient(t, pl, g, sp, err, mesh=mesh)
        np.testing.assert_array_equal(d, d0)
        np.testing.assert_array_equal(G, G0)
    d, G = plan.evaluate(None)
    np.testing.assert_array_equal(d, 0.0)
    np.testing.assert_array_equal(G, mesh_angle_gradient(t, pl, g, sp, mesh=mesh)[1])


def test_plan_empty_and_scalar_planet():
    g = gearset()
    sp = speeds(g)
    d, G = MeshGradientPlan(np.empty(0), np.empty(0, dtype=int), g, sp).evaluate(
        errors_of(P_SEED, 4))
    assert d.shape == (0,) and G.shape == (0, 12)
    d, G = MeshGradientPlan([0.3, 1.0], 3, g, sp, mesh="ring").evaluate()
    assert d.shape == (2,) and G.shape == (2, 12)
    assert np.all(G[:, [8, 9]] != 0.0) and np.all(G[:, [4, 5, 6, 7, 10, 11]] == 0.0)


@pytest.mark.parametrize("kwargs, exc, match", [
    (dict(planet=[1, 5]), ValueError, "planet must lie"),
    (dict(planet=[1.0, 2.0]), ValueError, "integer"),
    (dict(planet=[1, 2, 3]), ValueError, "shape"),
    (dict(mesh="carrier"), ValueError, "mesh"),
    (dict(gearset=None), TypeError, "Gearset"),
    (dict(speeds="fast"), TypeError, "Speeds"),
    (dict(t=[0.0, np.nan]), ValueError, "finite"),
    (dict(t=[0.0, 1e13]), ValueError, "shift the time origin"),
])
def test_plan_bad_inputs(kwargs, exc, match):
    g = gearset()
    args = dict(t=[0.0, 1.0], planet=[1, 2], gearset=g, speeds=speeds(g), mesh="sun")
    args.update(kwargs)
    with pytest.raises(exc, match=match):
        MeshGradientPlan(**args)


@pytest.mark.parametrize("errors, exc, match", [
    (ShaftHoleErrors(e_sun=[1e-4, 2e-4]), ValueError, "one realisation"),
    (ShaftHoleErrors(e_sun=0.06, e_planet=0.06), ValueError, "carrier_radius"),
    ("none", TypeError, "ShaftHoleErrors"),
])
def test_plan_bad_errors(errors, exc, match):
    g = gearset()
    plan = MeshGradientPlan([0.0, 1.0], [1, 2], g, speeds(g))
    with pytest.raises(exc, match=match):
        plan.evaluate(errors)
