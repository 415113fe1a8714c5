"""Engagement times against an independent slow reference (brentq on the rotation angles)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy.optimize import brentq

from meshphase.models.gearset import Gearset, Speeds
from meshphase.models.mesh_phasing import ShaftHoleErrors, mesh_angles
from meshphase.models.tolerance import table2_case
from meshphase.synthetic.kinematics import (EngagementEvents, SpeedProfile, engagement_events,
                                            event_times_for_angles, gauge_rates)

TWO_PI = 2 * math.pi


from _synth_reference import line_angle_ref, residual_ref, tau_ref  # noqa: E402


def table1():
    return table2_case(1)


# ----------------------------------------------------------------------------- SpeedProfile

def test_speed_profile_tau_matches_quadrature_and_inverts():
    prof = SpeedProfile(ramp_rate=0.01, ripple=((0.05, 0.3, 0.4), (0.02, 1.7, -1.0)))
    t = np.array([0.0, 0.1, 1.3, 7.7, 30.0])
    tau = prof.tau(t)
    ref = np.array([tau_ref(prof, x) for x in t])
    np.testing.assert_allclose(tau, ref, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(prof.time_of(tau), t, rtol=1e-14, atol=1e-14)


def test_speed_profile_constant_is_identity_and_empty():
    prof = SpeedProfile()
    assert prof.is_constant
    t = np.linspace(0, 5, 7)
    assert np.array_equal(prof.tau(t), t)
    assert prof.time_of(np.empty(0)).shape == (0,)
    assert SpeedProfile(ramp_rate=0.1).time_of(np.empty(0)).shape == (0,)


def test_speed_profile_roundtrip_dict():
    prof = SpeedProfile(ramp_rate=-0.002, ripple=((0.05, 0.3, 0.4),))
    assert SpeedProfile.from_dict(prof.to_dict()) == prof


@pytest.mark.parametrize("kw, exc", [
    (dict(ripple=((0.1, -1.0, 0.0),)), ValueError),
    (dict(ripple=((0.1, 1.0),)), TypeError),
    (dict(ripple=((-0.1, 1.0, 0.0),)), ValueError),
    (dict(ramp_rate="fast"), TypeError),
])
def test_speed_profile_bad_input(kw, exc):
    with pytest.raises(exc):
        SpeedProfile(**kw)


def test_speed_profile_check_rejects_stalling_rig():
    with pytest.raises(ValueError, match="stop or reverse"):
        SpeedProfile(ramp_rate=-0.1).check(20.0)
    SpeedProfile(ramp_rate=-0.01).check(20.0)  # 0.8 at the end: fine


# ----------------------------------------------------------------------------- engagements

@pytest.mark.parametrize("gear", ["sun", "ring"])
@pytest.mark.parametrize("reverse", [False, True])
def test_engagements_match_brentq_reference(gear, reverse):
    gs, sp, err = table2_case(2)  # 1 mm errors: the largest of Table 2
    if reverse:
        gs = Gearset(gs.z_sun, gs.z_ring, gs.z_planet, gs.planet_angles, gs.carrier_radius,
                     direction="ccw")
        sp = Speeds(-sp.sun, -sp.carrier, -sp.planet, -sp.ring)
    prof = SpeedProfile(ramp_rate=0.2, ripple=((0.04, 7.0, 0.3),))
    theta = 0.77
    ev = engagement_events(gs, sp, gear, theta, 0.0, 0.25, errors=err, profile=prof)
    assert len(ev) >= 12
    w, z = gauge_rates(gs, sp, gear)
    worst = 0.0
    for i in range(0, len(ev), 3):
        te, n = ev.time[i], ev.planet[i] - 1
        h = 0.05 * TWO_PI / abs(w)
        ref = brentq(residual_ref, te - h, te + h, args=(gear, n, theta, gs, sp, err, prof),
                     xtol=1e-16, rtol=1e-15, maxiter=200)
        worst = max(worst, abs(ref - te))
    # angle accuracy ~1e-13 rad of the quadrature/geometry reference -> time / |w|
    assert worst * abs(w) < 1e-10


def test_engagements_without_errors_are_ideal_roots():
    gs, sp, _ = table1()
    theta = 0.3
    ev = engagement_events(gs, sp, "sun", theta, 0.0, 0.1)
    psi = gs.angles[ev.planet - 1]
    expect = (psi + TWO_PI * ev.revolution - theta) / sp.w_sc
    np.testing.assert_allclose(ev.time, expect, rtol=0, atol=1e-15)
    assert np.all(np.diff(ev.time) > 0)


@pytest.mark.parametrize("gear", ["sun", "ring"])
@pytest.mark.parametrize("reverse", [False, True])
def test_pass_order_and_rates(gear, reverse):
    gs, sp, _ = table1()
    if reverse:
        sp = Speeds(-sp.sun, -sp.carrier, -sp.planet, -sp.ring)
    w, z = gauge_rates(gs, sp, gear)
    t_rev = TWO_PI / abs(w)
    ev = engagement_events(gs, sp, gear, 0.1, 0.0, 10.5 * t_rev)
    # one engagement per planet per relative revolution
    assert len(ev) in (42, 43)
    counts = np.bincount(ev.planet, minlength=5)[1:]
    assert counts.max() - counts.min() <= 1
    # same planet: once per relative revolution; ring fixed -> once per carrier revolution
    d = np.diff(ev.time[ev.planet == 1])
    np.testing.assert_allclose(d, t_rev, rtol=1e-12)
    if gear == "ring":
        np.testing.assert_allclose(d, TWO_PI / abs(sp.carrier), rtol=1e-12)
    # order: increasing planet angle when the gear turns counter-clockwise relative to carrier
    step = np.diff(ev.planet) % 4
    assert np.all(step == (1 if w > 0 else 3))


def test_rotating_ring_rate_follows_willis():
    from meshphase.synthetic.scenarios import seed_rig_gearset, seed_rig_speeds

    g = seed_rig_gearset()
    sp = seed_rig_speeds(g)
    # Willis: w_rc = -(Z_s / Z_r) w_sc
    assert sp.w_rc == pytest.approx(-g.z_sun / g.z_ring * sp.w_sc, rel=1e-14)
    ev = engagement_events(g, sp, "ring", 0.0, 0.0, 60.0)
    d = np.diff(ev.time[ev.planet == 1])
    np.testing.assert_allclose(d, TWO_PI / abs(sp.w_rc), rtol=1e-12)


@settings(max_examples=60, deadline=None)
@given(theta=st.floats(-10, 10), e=st.floats(0, 2e-3), ks=st.floats(0, 6.3),
       kp=st.floats(0, 6.3), gear=st.sampled_from(["sun", "ring"]),
       sign=st.sampled_from([1.0, -1.0]), ripple=st.floats(0, 0.2))
def test_engagement_invariants(theta, e, ks, kp, gear, sign, ripple):
    gs, sp, _ = table1()
    if sign < 0:
        gs = Gearset(gs.z_sun, gs.z_ring, gs.z_planet, gs.planet_angles, gs.carrier_radius,
                     direction="ccw")
        sp = Speeds(-sp.sun, -sp.carrier, -sp.planet, -sp.ring)
    err = ShaftHoleErrors(e_sun=e, kappa_sun=ks, e_ring=e, kappa_ring=ks + 1, e_planet=e,
                          kappa_planet=kp)
    prof = SpeedProfile(ripple=((ripple, 11.0, 0.0),))
    ev = engagement_events(gs, sp, gear, theta, 0.01, 0.2, errors=err, profile=prof)
    assert np.all(np.diff(ev.time) > 0)
    assert np.all((ev.time >= 0.01) & (ev.time < 0.2))
    w, _ = gauge_rates(gs, sp, gear)
    which = 0 if gear == "sun" else 1
    psi = mesh_angles(ev.tau, gs, sp, err)[which][np.arange(len(ev)), ev.planet - 1]
    r = np.remainder(theta + w * ev.tau - psi + math.pi, TWO_PI) - math.pi
    assert np.max(np.abs(r)) < 1e-9
    np.testing.assert_allclose(prof.tau(ev.time), ev.tau, rtol=1e-13, atol=1e-14)


def test_engagements_empty_window_and_non_turning_gear():
    gs, sp, _ = table1()
    assert len(engagement_events(gs, sp, "sun", 0.0, 1.0, 1.0)) == 0
    assert isinstance(engagement_events(gs, sp, "sun", 0.0, 1.0, 0.5), EngagementEvents)
    # carrier held: the ring does not turn relative to the carrier... when the ring turns with it
    locked = Speeds(sun=10.0, carrier=3.0, planet=3.0, ring=3.0)
    ev = engagement_events(gs, locked, "ring", 0.0, 0.0, 1.0)
    assert len(ev) == 0 and ev.time.dtype == np.float64


def test_engagements_bad_input():
    gs, sp, err = table1()
    with pytest.raises(ValueError, match="gear"):
        engagement_events(gs, sp, "planet", 0.0, 0.0, 1.0)
    with pytest.raises(TypeError, match="gearset"):
        engagement_events("gs", sp, "sun", 0.0, 0.0, 1.0)
    with pytest.raises(TypeError, match="errors"):
        engagement_events(gs, sp, "sun", 0.0, 0.0, 1.0, errors={"e_sun": 1})
    with pytest.raises(ValueError, match="one realisation"):
        engagement_events(gs, sp, "sun", 0.0, 0.0, 1.0,
                          errors=ShaftHoleErrors(e_sun=[1e-4, 2e-4]))
    with pytest.raises(TypeError, match="tooth_angle"):
        engagement_events(gs, sp, "sun", "zero", 0.0, 1.0)


def test_tacho_times_once_per_carrier_revolution():
    prof = SpeedProfile(ripple=((0.05, 0.5, 0.0),))
    w_c = 2.0
    st_, sp_ = event_times_for_angles(w_c, 0.4, 0.0, 40.0, width=0.01, profile=prof)
    # each rising edge is where the carrier angle w_c tau(t) = 0.4 + 2 pi m
    ang = w_c * prof.tau(st_)
    np.testing.assert_allclose(np.remainder(ang - 0.4 + 1, TWO_PI) - 1, 0.0, atol=1e-12)
    np.testing.assert_allclose(w_c * (prof.tau(sp_) - prof.tau(st_)), 0.01 * TWO_PI, rtol=1e-12)
    assert st_.size == pytest.approx(w_c * prof.tau(40.0) / TWO_PI, abs=1)
    e0, e1 = event_times_for_angles(0.0, 0.0, 0.0, 1.0)
    assert e0.size == 0 and e1.size == 0
    with pytest.raises(ValueError):
        event_times_for_angles(1.0, 0.0, 0.0, 1.0, width=-0.1)


@pytest.mark.parametrize("gear", ["sun", "ring"])
def test_reference_geometry_equals_mesh_angles_at_constant_speed(gear):
    """The test's own rotation-angle geometry agrees with mesh_angles(t) (tau = t) to 1e-12,
    so the brentq references above check the engagement solver, not a convention."""
    gs, sp, err = table2_case(2)
    t = np.linspace(0.0, 0.3, 97)
    which = 0 if gear == "sun" else 1
    ang = mesh_angles(t, gs, sp, err)[which]
    for i in range(0, t.size, 7):
        for n in range(gs.n_planets):
            ref = line_angle_ref(t[i], gear, n, gs, sp, err)
            assert math.remainder(ang[i, n] - ref, TWO_PI) == pytest.approx(0.0, abs=1e-12)
