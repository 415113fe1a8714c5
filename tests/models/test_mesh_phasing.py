"""Ideal and time-varying mesh phasing (spec sections 1 and 2; meshphase.models.mesh_phasing)."""

import math

import mpmath as mp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from meshphase.errors import ModelWarning
from meshphase.models.gearset import Gearset, Speeds
from meshphase.models.mesh_phasing import (
                                           MAX_PHASE,
                                           ShaftHoleErrors,
                                           assembly_check,
                                           centre_positions,
                                           classify_phasing,
                                           harmonic_excitation,
                                           ideal_phasing,
                                           ideal_phasing_angles,
                                           mesh_angle_deviations,
                                           mesh_angles,
                                           modal_excitation,
                                           phasing_deviation,
                                           reduce_angle,
                                           rotation_angle,
                                           rotation_cos_sin,
                                           time_varying_phasing,
                                           )

TWO_PI = 2 * math.pi


def table1():
    """Seed 000 Table 1 gearset (Z_s 25, Z_r 87, Z_p 29, 4 planets, R_c 112.5 mm)."""
    g = Gearset.equally_spaced(25, 87, 29, 4, 0.1125, direction="cw")
    return g, Speeds.kinematic(g, sun=448.0, carrier=100.0)


def circ(a, b):
    """Circular distance of two phasings [-] (mod 1)."""
    d = np.abs(np.asarray(a) - np.asarray(b)) % 1.0
    return np.minimum(d, 1.0 - d)


# ----------------------------------------------------------------------------- section 1

def test_ideal_table1_by_hand():
    # Z_s = 25, 4 planets at 90 deg, clockwise: gamma_s = frac(25 k / 4) = 0, 1/4, 1/2, 3/4;
    # gamma_r = frac(-87 k / 4) = frac(-21.75 k) = 0, 1/4, 1/2, 3/4 (by hand).
    g, _ = table1()
    gs, gr = ideal_phasing(g)
    np.testing.assert_allclose(gs, [0, 0.25, 0.5, 0.75], atol=1e-12)
    np.testing.assert_allclose(gr, [0, 0.25, 0.5, 0.75], atol=1e-12)
    assert classify_phasing(g) == "sequential"       # 25 mod 4 = 1


def test_ideal_ccw_flips_signs():
    g = Gearset.equally_spaced(25, 87, 29, 4, 0.1125, direction="ccw")
    gs, gr = ideal_phasing(g)
    np.testing.assert_allclose(gs, [0, 0.75, 0.5, 0.25], atol=1e-12)
    np.testing.assert_allclose(gr, [0, 0.75, 0.5, 0.25], atol=1e-12)


@pytest.mark.parametrize("zs, zr, n, expected_s, cls", [
    # by hand: 20 * k / 3 -> 0, 2/3, 1/3; 20 mod 3 = 2 = N - 1 -> sequential
    (20, 70, 3, [0, 2 / 3, 1 / 3], "sequential"),
    # 24 mod 4 = 0 -> in phase, every gamma exactly 0
    (24, 72, 4, [0, 0, 0, 0], "in-phase"),
    # 22 * k / 5 -> 0, .4, .8, .2, .6; 22 mod 5 = 2 -> counter-phase
    (22, 78, 5, [0, 0.4, 0.8, 0.2, 0.6], "counter-phase"),
])
def test_ideal_worked_examples(zs, zr, n, expected_s, cls):
    g = Gearset.equally_spaced(zs, zr, 0, n, 0.1)
    gs, gr = ideal_phasing(g)
    np.testing.assert_allclose(gs, expected_s, atol=1e-12)
    assert np.all(circ(gs, gr) < 1e-9)
    assert classify_phasing(g) == cls
    if cls == "in-phase":
        assert np.all(gs == 0.0) and np.all(gr == 0.0)     # snapped, not 0.9999999


def test_ideal_unequal_spacing_mixed():
    # planets at p = 0, 27, 56, 85 of Z_s + Z_r = 112: gamma_s2 = frac(25 * 27 / 112) = 3/112
    g = Gearset(25, 87, 29, tuple(TWO_PI * p / 112 for p in (0, 27, 56, 85)), 0.1125)
    gs, gr = ideal_phasing(g)
    assert gs[1] == pytest.approx(3 / 112, abs=1e-12)
    assert np.all(circ(gs, gr) < 1e-9)
    assert classify_phasing(g) == "mixed"
    assert assembly_check(g).all_assemblable
    with pytest.raises(ValueError, match="equally spaced"):
        harmonic_excitation(g, [1])
    me = modal_excitation(g, [1, 2])
    assert me["rotational"].shape == (2,)


@settings(max_examples=150, deadline=None)
@given(zs=st.integers(3, 200), dz=st.integers(1, 300), data=st.data(),
       direction=st.sampled_from(["cw", "ccw"]))
def test_property_assemblable_layouts_have_equal_sun_and_ring_phasing(zs, dz, data, direction):
    zr = zs + dz
    p = data.draw(st.lists(st.integers(0, zs + zr - 1), min_size=1, max_size=8))
    p[0] = 0
    psi = TWO_PI * np.asarray(p, float) / (zs + zr)
    gs, gr = ideal_phasing_angles(zs, zr, psi, direction)
    assert np.all((gs >= 0) & (gs < 1) & (gr >= 0) & (gr < 1))
    assert np.all(circ(gs, gr) < 1e-9)
    chk = assembly_check(zs, zr, psi)
    assert chk.all_assemblable
    np.testing.assert_array_equal(chk.p, p)


def test_assembly_check_nearest_layout():
    # Z_s + Z_r = 110: 4 planets at 90 deg need p = 27.5 (no), 55 (yes), 82.5 (no)
    chk = assembly_check(25, 85, [0, np.pi / 2, np.pi, 3 * np.pi / 2])
    np.testing.assert_array_equal(chk.assemblable, [True, False, True, False])
    np.testing.assert_array_equal(chk.p, [0, 28, 55, 82])        # round half to even
    np.testing.assert_allclose(chk.nearest_angles, TWO_PI * np.array([0, 28, 55, 82]) / 110)
    np.testing.assert_allclose(chk.angle_error[1], np.pi / 2 - TWO_PI * 28 / 110)
    assert not chk.all_assemblable
    # the nearest layout is assemblable: its phasings satisfy the invariant
    gs, gr = ideal_phasing_angles(25, 85, chk.nearest_angles)
    assert np.all(circ(gs, gr) < 1e-9)
    assert assembly_check(25, 85, chk.nearest_angles).all_assemblable


def test_classify_warns_when_not_assemblable():
    g = Gearset.equally_spaced(25, 85, 0, 4, 0.1)
    with pytest.warns(ModelWarning, match="cannot be assembled"):
        assert classify_phasing(g) == "sequential"


def test_classify_single_planet_minimal_input():
    # a Gearset cannot be empty (it rejects no planets); one planet is the smallest input
    assert classify_phasing(Gearset(25, 87, 0, (0.0,), 0.1)) == "in-phase"
    with pytest.raises(ValueError):
        Gearset(25, 87, 0, (), 0.1)


def test_harmonic_rule_table1():
    # Z_s = 25, N = 4: l=1: 26/4 no, 24/4 yes -> translational; l=2: 50, 49, 51 no -> planet;
    # l=3: 76/4 -> translational; l=4: 100/4 -> rotational (Parker's rule by hand)
    g, _ = table1()
    assert harmonic_excitation(g, [1, 2, 3, 4]) == {1: "translational", 2: "planet",
                                                    3: "translational", 4: "rotational"}
    me = modal_excitation(g, [1, 2, 3, 4])
    np.testing.assert_allclose(me["rotational"], [0, 0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(me["translational"], [1, 0, 1, 0], atol=1e-12)
    assert harmonic_excitation(g, []) == {}
    assert modal_excitation(g, [])["rotational"].shape == (0,)
    with pytest.raises(ValueError):
        modal_excitation(g, [-1])
    with pytest.raises(TypeError):
        modal_excitation("g", [1])


@settings(max_examples=60, deadline=None)
@given(zs=st.integers(3, 120), n=st.integers(2, 8), l=st.integers(1, 12))
def test_property_parker_rule_matches_modal_sums(zs, n, l):
    g = Gearset.equally_spaced(zs, zs + n * 10 + (-zs) % n + n, 0, n, 0.1)
    kind = harmonic_excitation(g, [l])[l]
    me = modal_excitation(g, [l])
    if kind == "rotational":
        assert me["rotational"][0] == pytest.approx(1.0, abs=1e-9)
    elif kind == "translational":
        assert me["rotational"][0] < 1e-9 and me["translational"][0] == pytest.approx(1, abs=1e-9)
    else:
        assert me["rotational"][0] < 1e-9 and me["translational"][0] < 1e-9


@pytest.mark.parametrize("args, exc", [
    ((-25, 87, [0.0]), ValueError),
    ((25, -87, [0.0]), ValueError),
    ((25, 20, [0.0]), ValueError),
    ((25.5, 87, [0.0]), ValueError),
    ((25, 87, [0.0, np.nan]), ValueError),
    ((25, 87, [0.0, np.inf]), ValueError),
    (("25", 87, [0.0]), TypeError),
])
def test_ideal_bad_inputs(args, exc):
    with pytest.raises(exc):
        ideal_phasing_angles(*args)
    with pytest.raises(exc):
        assembly_check(*args)


def test_section1_empty_and_type_inputs():
    gs, gr = ideal_phasing_angles(25, 87, [])
    assert gs.shape == (0,) and gr.shape == (0,)
    # leading dims are kept: one layout per row, relative to the first planet of each row
    gs, _ = ideal_phasing_angles(25, 87, [[0.0, np.pi / 2], [np.pi / 2, np.pi]])
    np.testing.assert_allclose(gs, [[0.0, 0.25], [0.0, 0.25]], atol=1e-12)
    chk = assembly_check(25, 87, [])
    assert chk.p.shape == (0,) and chk.all_assemblable
    with pytest.raises(ValueError):
        ideal_phasing_angles(25, 87, [0.0], direction="up")
    for fn in (ideal_phasing, classify_phasing):
        with pytest.raises(TypeError):
            fn("gearset")
    with pytest.raises(TypeError):
        harmonic_excitation(table1()[0], ["a"])
    with pytest.raises(ValueError):
        harmonic_excitation(table1()[0], [0])
    with pytest.raises(TypeError):
        assembly_check(table1()[0], 87, [0.0])
    with pytest.raises(ValueError):
        assembly_check(25, 87, [0.0], atol=-1)


# ----------------------------------------------------------------------------- angle reduction

def test_reduce_angle_against_mpmath():
    mp.mp.dps = 50
    x = np.array([0.0, 1e-300, 3.0, -7.5, 1234.5678, 3.5e8, -4.9e10, 2 * math.pi * 1e9])
    r = reduce_angle(x)
    for xi, ri in zip(x, r):
        ref = mp.mpf(float(xi)) - 2 * mp.pi * mp.nint(mp.mpf(float(xi)) / (2 * mp.pi))
        assert abs(float(mp.mpf(float(ri)) - ref)) <= 4e-16
    # the 2 pi split constants carry 2 pi to ~1e-28
    from meshphase.models import _geometry as geo
    assert abs(mp.mpf(geo._C1) + mp.mpf(geo._C2) + mp.mpf(geo._C3) - 2 * mp.pi) < 1e-27
    assert reduce_angle([]).shape == (0,)
    with pytest.raises(ValueError):
        reduce_angle([MAX_PHASE * 2])
    with pytest.raises(ValueError):
        reduce_angle([np.nan])


def test_rotation_angle_long_times_against_mpmath():
    mp.mp.dps = 50
    w = 348.0
    t = np.array([0.0, 0.123, 1e3 + 0.37, 999999.123456, 1e6])
    r = rotation_angle(w, t, 0.3)
    naive = np.mod(w * t + 0.3 + np.pi, TWO_PI) - np.pi
    worst_naive = 0.0
    for ti, ri, ni in zip(t, r, naive):
        x = mp.mpf(w) * mp.mpf(float(ti)) + mp.mpf(0.3)
        ref = x - 2 * mp.pi * mp.nint(x / (2 * mp.pi))
        assert abs(float(mp.mpf(float(ri)) - ref)) <= 2e-15
        worst_naive = max(worst_naive, abs(float(mp.mpf(float(ni)) - ref)))
    assert worst_naive > 1e-9          # the naive product really loses digits at 1e6 s
    c, s = rotation_cos_sin(w, t)
    np.testing.assert_allclose(c ** 2 + s ** 2, 1.0, atol=1e-15)
    assert rotation_angle(w, []).shape == (0,)
    assert rotation_cos_sin(w, [])[0].shape == (0,)
    with pytest.raises(ValueError):
        rotation_angle(1e6, [1e6])
    with pytest.raises(ValueError):
        rotation_angle(w, [np.inf])
    with pytest.raises(TypeError):
        rotation_angle("fast", [1.0])


# ----------------------------------------------------------------------------- section 2

def test_zero_errors_give_exactly_ideal():
    g, sp = table1()
    t = np.linspace(0.0, 0.5, 37)
    gs0, gr0 = ideal_phasing(g)
    for err in (None, ShaftHoleErrors(),
                ShaftHoleErrors(kappa_sun=1.0, kappa_ring=2.0, kappa_planet=[0.1, 0.2, 0.3, 0.4])):
        gs, gr = time_varying_phasing(t, g, sp, err)
        assert gs.shape == (37, 4)
        assert np.array_equal(gs, np.broadcast_to(gs0, gs.shape))
        assert np.array_equal(gr, np.broadcast_to(gr0, gr.shape))
        ps, pr = mesh_angles(t, g, sp, err)
        assert np.array_equal(ps, np.broadcast_to(g.angles, ps.shape))
        assert np.array_equal(pr, np.broadcast_to(g.angles, pr.shape))
        ds, dr = phasing_deviation(t, g, sp, err)
        assert not np.any(ds) and not np.any(dr)


def test_vector_form_reproduces_seed_scalar_formulas():
    """Seed 000 eqs: |O_si O_pan|, dpsi_epn, |O_sa O_pan|, Delta_sn, varsigma_spn, psi_espn.

    The distance holds with (w_pc, kappa) as they are; the seed's angles hold with the offset
    phases read clockwise, i.e. seed(w, kappa) == vector form(-w, -kappa) (module docstring).
    """
    g, sp = table1()
    R = g.carrier_radius
    es, ks, ep, kp = 0.3e-3, 0.4, 0.5e-3, 1.1
    err = ShaftHoleErrors(e_sun=es, kappa_sun=ks, e_planet=ep, kappa_planet=kp)
    t = np.linspace(0.0, 0.1, 9)
    pos = centre_positions(t, g, sp, err)
    psi_es, _ = mesh_angles(t, g, sp, err)
    first_order = []
    for k, tk in enumerate(t):
        for n, psin in enumerate(g.angles):
            d = math.sqrt(R * R + ep * ep - 2 * R * ep * math.cos(sp.w_pc * tk + kp))
            P = pos["planets"][k, n]
            assert math.hypot(*P) == pytest.approx(d, rel=1e-15)
            phs = (-sp.w_pc) * tk + (-kp)
            dpsi = math.asin(ep * math.sin(phs) / d)
            ang = math.atan2(P[1], P[0]) - psin
            ang = (ang + math.pi) % TWO_PI - math.pi
            assert ang == pytest.approx(dpsi, abs=1e-15)
            D = (-sp.w_sc) * tk + psin + dpsi + (-ks)
            dsa = math.sqrt(d * d + es * es - 2 * d * es * math.cos(D))
            vs = math.asin(es * math.sin(D) / dsa)
            assert psi_es[k, n] == pytest.approx(psin + dpsi + vs, abs=2e-15)
            # first order in e / R_c: -(e_p sin th + e_s sin(a_s - psi_n)) / R_c
            lin = -(ep * math.sin(sp.w_pc * tk + kp) + es * math.sin(sp.w_sc * tk + ks - psin)) / R
            first_order.append(abs(psi_es[k, n] - psin - lin))
    assert max(first_order) < 3 * ((es + ep) / R) ** 2


def _ref_delta(tk, w_s, w_p, R, es, ks, ep, kp, psi):
    """mpmath reference of the mesh-line deviation delta [rad] (inputs as exact binaries)."""
    tk, w_s, w_p, R, es, ks, ep, kp, psi = (mp.mpf(float(v)) for v in
                                            (tk, w_s, w_p, R, es, ks, ep, kp, psi))
    th = w_p * tk + kp
    a = w_s * tk + ks
    vx = R - ep * mp.cos(th) - es * mp.cos(a - psi)
    vy = -ep * mp.sin(th) - es * mp.sin(a - psi)
    return mp.atan2(vy, vx)


@pytest.mark.parametrize("ratio", [1e-12, 1e-8, 1e-4, 1e-2, 0.3, 0.9, 0.99])
def test_accuracy_against_mpmath(ratio):
    """What is compared: the deviation delta = psi_es,n - psi_n (and the ring's) from
    mesh_angle_deviations, absolute error <= 1e-12 * (e_s + e_p) / R_c, i.e. relative to the
    deviation's amplitude (delta crosses zero, so a pointwise relative error is meaningless);
    the full angle psi from mesh_angles to <= 1e-12 * max(1, |psi|) rad; and the phasing
    deviation in mesh cycles relative to its amplitude Z (e_s + e_p) / (pi R_c). Times up to
    1e6 s, inputs taken as exact binary numbers."""
    mp.mp.dps = 40
    g, sp = table1()
    R = g.carrier_radius
    rng = np.random.default_rng(int(-math.log10(ratio) * 10))
    t = np.array([0.0, 0.37, 1234.567, 999999.123, 1e6])
    for mode in ("sun", "planet", "both"):
        es = {"sun": ratio * R, "planet": 0.0, "both": ratio * R / 2}[mode]
        ep = {"sun": 0.0, "planet": ratio * R, "both": ratio * R / 2}[mode]
        er = ratio * R / 2 if mode == "both" else 0.0
        ks, kr = rng.uniform(-10, 10, 2)
        kp = rng.uniform(-10, 10, 4)
        err = ShaftHoleErrors(e_sun=es, kappa_sun=ks, e_ring=er, kappa_ring=kr, e_planet=ep,
                              kappa_planet=kp)
        d_s, d_r = mesh_angle_deviations(t, g, sp, err)
        psi_s, _ = mesh_angles(t, g, sp, err)
        v_s, _ = phasing_deviation(t, g, sp, err, wrap=False)
        for k in range(t.size):
            ref1 = _ref_delta(t[k], sp.w_sc, sp.w_pc, R, es, ks, ep, kp[0], g.angles[0])
            for n in range(4):
                ref = _ref_delta(t[k], sp.w_sc, sp.w_pc, R, es, ks, ep, kp[n], g.angles[n])
                refr = _ref_delta(t[k], sp.w_rc, sp.w_pc, R, er, kr, ep, kp[n], g.angles[n])
                amp = (es + ep) / R
                assert abs(float(mp.mpf(float(d_s[k, n])) - ref)) <= 1e-12 * amp
                if er + ep:
                    assert abs(float(mp.mpf(float(d_r[k, n])) - refr)) <= 1e-12 * (er + ep) / R
                psi_ref = mp.mpf(float(g.angles[n])) + ref
                err_psi = abs(float(mp.mpf(float(psi_s[k, n])) - psi_ref))
                assert err_psi <= 1e-12 * max(1, abs(psi_ref))
                vref = 25 / (2 * mp.pi) * (ref - ref1)
                assert abs(float(mp.mpf(float(v_s[k, n])) - vref)) <= 1e-12 * 25 * amp / math.pi


@pytest.mark.parametrize("case, e", [(1, 0.2e-3), (2, 1.0e-3)])
def test_seed_cases_dev_linear_in_e_sun_ave_flat(case, e):
    """Seed 000 Table 2 cases 1, 2: as e_s grows from 0 to e, Dev_sn grows linearly while
    Ave_sn stays nearly constant ("changes are under 4e-5"). Over a window in which every
    offset turns whole revolutions ("common-period"), first-order terms average out; the
    seed's 4e-5 is the tolerance."""
    from meshphase.models.tolerance import observation_window, phasing_statistics, table2_case
    g, sp, err = table2_case(case)
    es = np.linspace(0.0, 1.0, 5) * e
    sweep = ShaftHoleErrors(e_sun=es, kappa_sun=err.kappa_sun, e_ring=err.e_ring,
                            kappa_ring=err.kappa_ring, e_planet=err.e_planet,
                            kappa_planet=err.kappa_planet)
    st_ = phasing_statistics(g, sp, sweep, observation_window(sp, "common-period"))
    dev = st_.dev_s[:, 1:]
    # linear through the origin (identical planet errors cancel in relative phasing):
    slope = dev[-1] / es[-1]
    np.testing.assert_allclose(dev, np.outer(es, slope), rtol=2e-3, atol=1e-12)
    assert np.all(slope > 0)
    assert np.max(np.ptp(st_.ave_s, axis=0)) < 4e-5


def test_broadcasting_matches_single_realisations():
    g, sp = table1()
    t = np.linspace(0.0, 0.05, 11)
    e_s = np.array([[0.1e-3, 0.2e-3], [0.3e-3, 0.0]])          # sample dims (2, 2)
    e_p = np.array([0.1e-3, 0.2e-3, 0.3e-3, 0.4e-3])             # per planet, every sample
    err = ShaftHoleErrors(e_sun=e_s, kappa_sun=0.3, e_ring=0.2e-3, kappa_ring=[[1.0], [2.0]],
                          e_planet=e_p, kappa_planet=0.5)
    gs, gr = time_varying_phasing(t, g, sp, err)
    assert gs.shape == (2, 2, 11, 4)
    assert err.sample_shape(4) == (2, 2)
    for i in range(2):
        for j in range(2):
            one = ShaftHoleErrors(e_sun=e_s[i, j], kappa_sun=0.3, e_ring=0.2e-3,
                                  kappa_ring=[1.0, 2.0][i], e_planet=e_p, kappa_planet=0.5)
            a, b = time_varying_phasing(t, g, sp, one)
            np.testing.assert_array_equal(gs[i, j], a)
            np.testing.assert_array_equal(gr[i, j], b)
    pos = centre_positions(t, g, sp, err)
    assert pos["sun"].shape == (2, 2, 11, 2) and pos["planets"].shape == (2, 2, 11, 4, 2)


def test_phasing_deviation_wrap_and_gamma_consistent():
    g, sp = table1()
    t = np.linspace(0.0, 0.07, 50)
    err = ShaftHoleErrors(e_sun=1e-3, kappa_sun=0.2, e_ring=4e-3, kappa_ring=1.0,
                          e_planet=1e-3, kappa_planet=0.4)
    gs, gr = time_varying_phasing(t, g, sp, err)
    ds, dr = phasing_deviation(t, g, sp, err)
    gs0, gr0 = ideal_phasing(g)
    assert np.all((ds >= -0.5) & (ds < 0.5)) and np.all((dr >= -0.5) & (dr < 0.5))
    assert np.max(circ(gs, gs0 + ds)) < 1e-12
    assert np.max(circ(gr, gr0 + dr)) < 1e-12
    ds_c, dr_c = phasing_deviation(t, g, sp, err, wrap=False)
    assert np.max(np.abs(dr_c)) > 0.5          # large ring deviation: wrapping matters here
    assert np.max(circ(dr_c, dr)) < 1e-12
    # absolute phasing (not relative to planet 1)
    ga, _ = time_varying_phasing(t, g, sp, None, relative_to_first=False)
    np.testing.assert_allclose(ga[0], np.mod(25 * g.angles / TWO_PI, 1.0) % 1.0, atol=1e-9)


def test_section2_empty_inputs():
    g, sp = table1()
    gs, gr = time_varying_phasing([], g, sp, None)
    assert gs.shape == (0, 4) and gr.shape == (0, 4)
    err = ShaftHoleErrors(e_sun=np.zeros(0))
    for fn in (time_varying_phasing, mesh_angles, mesh_angle_deviations, phasing_deviation):
        a, b = fn([0.0, 1.0], g, sp, err)
        assert a.shape == (0, 2, 4) and b.shape == (0, 2, 4)
    pos = centre_positions([], g, sp, None)
    assert pos["planets"].shape == (0, 4, 2)


@pytest.mark.parametrize("kwargs, match", [
    ({"e_sun": -1e-3}, "e_sun must be >= 0"),
    ({"e_planet": [0.0, -1e-4, 0.0, 0.0]}, "e_planet must be >= 0"),
    ({"e_ring": np.nan}, "e_ring must be finite"),
    ({"kappa_sun": np.inf}, "kappa_sun must be finite"),
    ({"kappa_planet": [np.nan] * 4}, "kappa_planet must be finite"),
])
def test_errors_bad_values(kwargs, match):
    with pytest.raises(ValueError, match=match):
        ShaftHoleErrors(**kwargs)


@pytest.mark.parametrize("fn", [time_varying_phasing, mesh_angles, mesh_angle_deviations,
                                phasing_deviation, centre_positions])
def test_section2_bad_inputs(fn):
    g, sp = table1()
    R = g.carrier_radius
    with pytest.raises(ValueError, match="carrier_radius"):
        fn([0.0], g, sp, ShaftHoleErrors(e_sun=R))                       # e >= R_c
    with pytest.raises(ValueError, match="carrier_radius"):
        fn([0.0], g, sp, ShaftHoleErrors(e_ring=0.6 * R, e_planet=0.5 * R))
    with pytest.raises(ValueError, match="t must be finite"):
        fn([0.0, np.nan], g, sp, None)
    with pytest.raises(ValueError, match="shape"):
        fn(np.zeros((2, 2)), g, sp, None)
    with pytest.raises(ValueError, match="trailing planet axis"):
        fn([0.0], g, sp, ShaftHoleErrors(e_planet=[1e-4, 1e-4, 1e-4]))
    with pytest.raises(ValueError, match="time origin"):
        fn([1e9], g, sp, None)
    with pytest.raises(TypeError):
        fn([0.0], "gearset", sp, None)
    with pytest.raises(TypeError):
        fn([0.0], g, (448.0, 100.0), None)
    with pytest.raises(TypeError):
        fn([0.0], g, sp, {"e_sun": 1e-4})


def test_errors_from_mm_deg():
    e = ShaftHoleErrors.from_mm_deg(e_sun=0.2, kappa_ring=60)
    assert float(e.e_sun) == pytest.approx(0.2e-3)
    assert float(e.kappa_ring) == pytest.approx(math.pi / 3)
    assert not e.is_zero and ShaftHoleErrors().is_zero
    with pytest.raises(TypeError):
        ShaftHoleErrors.from_mm_deg(size=1)
