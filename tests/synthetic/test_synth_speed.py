"""Shaft-locked speed ripple: the SpeedClock against an independent integration of its ODE,
both senses, ramps; the tacho and the truth on the same angle time; config round trips;
bad and empty inputs."""

import json
import math

import numpy as np
import pytest
from scipy.optimize import brentq

from meshphase.models.gearset import Speeds
from meshphase.models.tolerance import table2_case
from meshphase.synthetic import SynthConfig, generate, get_scenario
from meshphase.synthetic.kinematics import (MEMBERS, ShaftRipple, SpeedClock, SpeedProfile, engagement_events,
                                            event_times_for_angles, gauge_rates, member_rate)
from meshphase.synthetic.scenarios import rig_gearset, rig_speeds

from _synth_reference import ode_tau_ref, residual_tau_ref, tau_ref

TWO_PI = 2 * math.pi


def rig(reverse=False):
    g = rig_gearset(direction="ccw" if reverse else "cw")
    return g, rig_speeds(g, reverse=reverse)


# ----------------------------------------------------------------------------- the independent check

# (sense, ramp over 10 min, shaft components (member, amplitude, order, phase), Hz ripple)
CASES = {
    "cw-ramp-up": (False, +0.10, (("carrier", 0.03, 1, 0.4), ("sun", 0.02, 1, -1.0)),
                   ((0.005, 0.013, 0.2),)),
    "ccw-ramp-down": (True, -0.10, (("planet", 0.03, 1, 0.4), ("carrier", 0.02, 2, -1.0)), ()),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_engagements_match_independent_ode_integration_over_10_minutes(case):
    """Item 1's proof: 10 min at 5 % shaft-locked ripple with a +-10 % ramp, both senses.

    Reference: scipy DOP853 on the ODE d tau/dt = s(t, tau) written out independently
    (``ode_tau_ref``; rtol 1e-13 on the deviation from the time part, measured global error
    ~1e-12 s against rtol 2.3e-14) and brentq on the engagement condition with the seed's
    geometry written out in ``line_angle_ref``. Claim: engagement times agree to 1e-9 s
    (measured 3e-12). The clock's own tau(t) agrees with the reference to 1e-10 s.
    """
    reverse, ramp, shaft, rip = CASES[case]
    g, sp = rig(reverse)
    _, _, err = table2_case(1)
    prof = SpeedProfile(ramp_rate=ramp / 600.0, ripple=rip, shaft=shaft)
    clock = prof.clock(sp)
    ref = ode_tau_ref(prof, sp, 600.0)
    tt = np.linspace(0.0, 600.0, 3001)
    assert np.max(np.abs(clock.tau(tt) - ref(tt))) < 1e-10
    # the speed does vary: +-5 % ripple on a +-10 % ramp
    s = clock.factor(tt)
    assert s.max() - s.min() > 0.15
    worst = 0.0
    for gear, stride in (("sun", 23), ("ring", 7)):
        theta = 0.77 if gear == "sun" else 0.2
        ev = engagement_events(g, sp, gear, theta, 0.0, 600.0, errors=err, profile=clock)
        assert len(ev) > 100
        assert ev.time[-1] > 570.0
        w, _ = gauge_rates(g, sp, gear)
        idx = list(range(0, len(ev), stride)) + [len(ev) - 1]
        for i in idx:
            te, n = ev.time[i], ev.planet[i] - 1
            h = 0.05 * TWO_PI / abs(w)
            t_ref = brentq(residual_tau_ref, te - h, min(te + h, 600.0),
                           args=(gear, n, theta, g, sp, err, ref), xtol=1e-13, rtol=1e-15)
            worst = max(worst, abs(t_ref - te))
    assert worst <= 1e-9
    # the tacho (carrier once per revolution) on the same angle time
    st, stop = event_times_for_angles(sp.carrier, 0.3, 0.0, 600.0, width=0.01, profile=clock)
    ang = sp.carrier * ref(st) - 0.3
    assert np.max(np.abs(np.remainder(ang + math.pi, TWO_PI) - math.pi)) < 1e-9 * abs(sp.carrier)
    np.testing.assert_allclose(abs(sp.carrier) * (ref(stop) - ref(st)), 0.01 * TWO_PI, rtol=1e-8)


def test_clock_inverse_and_negative_times():
    g, sp = rig()
    clock = SpeedProfile.shaft_ripple("sun", 0.05, 3, 0.7, ramp_rate=1e-3).clock(sp)
    t = np.concatenate([np.linspace(-30.0, 0.0, 301), np.linspace(0.1, 200.0, 2000)])
    tau = clock.tau(t)
    assert np.all(np.diff(tau) > 0) and abs(clock.tau(0.0)) < 1e-15   # tau(0) = 0 to rounding
    # inverse to a few ulp of t (panel polynomials: eps * panel length)
    np.testing.assert_allclose(clock.time_of(tau), t, rtol=0, atol=1e-12)
    # d tau / dt = s: central differences of the dense solution give the speed factor
    h = 1e-4
    ts = np.linspace(-20.0, 150.0, 171)
    num = (clock.tau(ts + h) - clock.tau(ts - h)) / (2 * h)
    # truncation h^2 tau'''/6 ~ 1e-8 * 0.05 * (3 * 1.9)^2 ~ 2e-8; rounding eps tau / h ~ 1e-10
    np.testing.assert_allclose(num, clock.factor(ts), rtol=0, atol=5e-8)


def test_clock_does_not_depend_on_request_order():
    g, sp = rig()
    prof = SpeedProfile.shaft_ripple("carrier", 0.04, 2, 0.1)
    a, b = prof.clock(sp), prof.clock(sp)
    t = np.linspace(-10.0, 300.0, 777)
    ta = a.tau(t)
    b.time_of([50.0])
    b.tau([299.0, -9.0])
    assert np.array_equal(b.tau(t), ta)


def test_time_only_profiles_are_unchanged_by_the_clock():
    """Without shaft-locked ripple the clock is the closed form, bit for bit (old truths hold)."""
    g, sp = rig()
    prof = SpeedProfile(ramp_rate=0.01, ripple=((0.05, 0.3, 0.4), (0.02, 1.7, -1.0)))
    clock = prof.clock(sp)
    t = np.array([0.0, 0.1, 1.3, 7.7, 30.0])
    assert np.array_equal(clock.tau(t), prof.tau(t))
    assert np.array_equal(clock.time_of(prof.tau(t)), prof.time_of(prof.tau(t)))
    assert np.array_equal(clock.factor(t), prof.factor(t))
    assert clock.n_panels == 0 and not clock.has_shaft
    np.testing.assert_allclose(prof.tau(t), [tau_ref(prof, x) for x in t], rtol=1e-13, atol=1e-13)


def test_ripple_is_locked_to_the_shaft_angle_through_a_ramp():
    """At every tacho edge (one fixed carrier angle) a carrier-locked ripple has the same
    phase, so s(edge) - ramp term is one constant, however the speed ramps."""
    cfg = get_scenario("rig_ramp_up").with_(artefacts=get_scenario("rig_steady").artefacts)
    clock = cfg.speed.clock(cfg.speeds)
    st, _ = event_times_for_angles(cfg.speeds.carrier, cfg.tacho_angle(), 0.0, 120.0,
                                   profile=clock)
    assert st.size >= 8
    tau = clock.tau(st)
    s = clock.rate(st, tau)
    locked = s - cfg.speed.ramp_rate * st
    expect = 1.0 + 0.01 * math.sin(cfg.tacho_angle())
    np.testing.assert_allclose(locked, expect, rtol=0, atol=1e-12)
    # a fixed-frequency ripple of the same mean period would not stay locked
    f = abs(cfg.speeds.carrier) / TWO_PI
    hz = SpeedProfile(ramp_rate=cfg.speed.ramp_rate, ripple=((0.01, f, 0.0),))
    st2, _ = event_times_for_angles(cfg.speeds.carrier, 0.0, 0.0, 120.0, profile=hz)
    drift = hz.factor(st2) - hz.ramp_rate * st2
    assert np.ptp(drift) > 1e-3


@pytest.mark.parametrize("member, order", [("carrier", 1), ("sun", 2), ("planet", 1)])
def test_both_senses_mirror(member, order):
    """Every speed reversed and the ripple phase mirrored (phi -> pi - phi): the member's
    actual angle runs backwards and sin(m theta + phi) is the same function of time, so the
    angle time is the same (the ripple phase follows the member's actual angle)."""
    (g, sp), (gr, spr) = rig(False), rig(True)
    phi = 0.3
    a = SpeedProfile.shaft_ripple(member, 0.05, order, phi, ramp_rate=-5e-4).clock(sp)
    b = SpeedProfile.shaft_ripple(member, 0.05, order, math.pi - phi, ramp_rate=-5e-4).clock(spr)
    t = np.linspace(-5.0, 120.0, 1001)
    np.testing.assert_allclose(b.tau(t), a.tau(t), rtol=0, atol=1e-11)
    # the same phi in both senses is a different history (the angle really runs backwards)
    c = SpeedProfile.shaft_ripple(member, 0.05, order, phi, ramp_rate=-5e-4).clock(spr)
    assert np.max(np.abs(c.factor(t) - a.factor(t))) > 0.02
    # the factor follows the member's actual angle: s = 1 + r t + b sin(m w tau + phi)
    w = member_rate(spr, member)
    np.testing.assert_allclose(c.factor(t), 1 - 5e-4 * t + 0.05 * np.sin(order * w * c.tau(t) + phi),
                               rtol=0, atol=1e-14)


def test_member_rates():
    g, sp = rig()
    assert member_rate(sp, "carrier") == sp.carrier and member_rate(sp, "sun") == sp.sun
    assert member_rate(sp, "ring") == 0.0 == sp.ring
    assert member_rate(sp, "planet") == sp.w_pc == pytest.approx(-25 / 29 * sp.w_sc, rel=1e-14)
    assert set(MEMBERS) == {"carrier", "sun", "planet", "ring"}


# ----------------------------------------------------------------------------- truth and generator

def test_truth_tacho_and_pulses_share_one_angle_time():
    cfg = get_scenario("rig_ripple_sun")
    rec, truth = generate(cfg, duration=30.0, seed=2)
    clock = cfg.speed.clock(cfg.speeds)
    for name, ev in truth.events.items():
        np.testing.assert_allclose(clock.tau(ev.time - rec.t0), ev.tau, rtol=0, atol=1e-11)
        g = next(x for x in cfg.gauges if x.name == name)
        w, z = gauge_rates(cfg.gearset, cfg.speeds, g.gear)
        np.testing.assert_allclose(ev.mesh_period, TWO_PI / (z * abs(w) * clock.factor(ev.time - rec.t0)),
                                   rtol=1e-12)
    ang = cfg.speeds.carrier * clock.tau(truth.tacho_times - rec.t0) - cfg.tacho_angle()
    assert np.max(np.abs(np.remainder(ang + math.pi, TWO_PI) - math.pi)) < 1e-12
    assert truth.extra["speed_clock_panels"] > 0
    lo, hi = truth.extra["speed_factor_range"]
    assert 0.985 < lo < 0.995 and 1.005 < hi < 1.015


def test_shaft_profile_round_trips_through_config_and_truth_sidecar(tmp_path):
    prof = SpeedProfile(ramp_rate=-2e-4, ripple=((0.01, 0.02, 0.5),),
                        shaft=(ShaftRipple("planet", 0.02, 2, -0.3), ("sun", 0.01)))
    assert prof.shaft[1] == ShaftRipple("sun", 0.01, 1, 0.0)
    d = json.loads(json.dumps(prof.to_dict()))
    assert SpeedProfile.from_dict(d) == prof
    assert d["shaft"][0] == {"member": "planet", "amplitude": 0.02, "order": 2, "phase": -0.3}
    # an old sidecar (no "shaft" key) still reads
    assert SpeedProfile.from_dict({"ramp_rate": 0.0, "ripple": []}) == SpeedProfile()
    cfg = get_scenario("rig_ripple1").with_(speed=prof)
    back = SynthConfig.from_dict(json.loads(json.dumps(cfg.to_dict())))
    assert back.speed == prof and back.to_dict() == cfg.to_dict()
    _, truth = generate(cfg, duration=12.0, seed=5)
    p = truth.write(tmp_path / "r.truth.json")
    from meshphase.synthetic import GroundTruth

    read = GroundTruth.read(p)
    assert read == truth
    again = SynthConfig.from_dict(read.config)
    assert again.speed == prof
    _, truth2 = generate(again, duration=12.0, seed=5)
    assert np.array_equal(truth2.events["sun"].time, truth.events["sun"].time)


# ----------------------------------------------------------------------------- bad and empty inputs

@pytest.mark.parametrize("args, exc, match", [
    (("carrier", -0.01), ValueError, "amplitude must be >= 0"),
    (("carrier", 0.01, 0), ValueError, "order must be an integer >= 1"),
    (("carrier", 0.01, -2), ValueError, "order must be an integer >= 1"),
    (("carrier", 0.01, 1.5), ValueError, "order"),
    (("carrier", 0.01, "two"), TypeError, "order"),
    (("shaft", 0.01), ValueError, "member must be one of"),
    ((3, 0.01), TypeError, "member"),
    (("sun", 0.96), ValueError, "s stays > 0.05"),
    (("sun", float("nan")), ValueError, "amplitude"),
    (("sun", 0.01, 1, "zero"), TypeError, "phase"),
])
def test_shaft_ripple_bad_input(args, exc, match):
    with pytest.raises(exc, match=match):
        ShaftRipple(*args)


def test_speed_profile_shaft_bad_input():
    with pytest.raises(ValueError, match="<= 0.05"):
        SpeedProfile(ripple=((0.5, 0.1, 0.0),), shaft=(("carrier", 0.46),))
    with pytest.raises(ValueError, match="stop or reverse"):
        SpeedProfile.shaft_ripple("carrier", 0.05, ramp_rate=-0.1).check(10.0)
    SpeedProfile.shaft_ripple("carrier", 0.05, ramp_rate=-0.1).check(5.0)
    with pytest.raises(TypeError, match="wrap it in a tuple"):
        SpeedProfile(shaft=ShaftRipple("sun", 0.01))
    with pytest.raises(TypeError, match="shaft ripple"):
        SpeedProfile(shaft=(0.01,))
    with pytest.raises(ValueError, match="unknown key"):
        SpeedProfile(shaft=({"member": "sun", "amplitude": 0.01, "freq": 2},))
    with pytest.raises(ValueError, match="needs 'member'"):
        SpeedProfile(shaft=({"amplitude": 0.01},))
    with pytest.raises(ValueError, match="unknown key"):
        SpeedProfile.from_dict({"ramp": 0.1})
    with pytest.raises(TypeError):
        SpeedProfile.from_dict([("sun", 0.01)])


def test_clock_bad_input():
    g, sp = rig()
    prof = SpeedProfile.shaft_ripple("ring", 0.01)         # the rig's ring is fixed
    with pytest.raises(ValueError, match="does not turn"):
        prof.clock(sp)
    shaft = SpeedProfile.shaft_ripple("sun", 0.01)
    for call in (lambda: shaft.tau([1.0]), lambda: shaft.factor([1.0]), lambda: shaft.time_of([1.0])):
        with pytest.raises(ValueError, match="speeds="):
            call()
    np.testing.assert_allclose(shaft.tau([1.0], speeds=sp), shaft.clock(sp).tau([1.0]), rtol=0, atol=0)
    with pytest.raises(TypeError, match="speeds"):
        shaft.clock({"sun": 1.0})
    with pytest.raises(TypeError, match="profile"):
        SpeedClock("fast", sp)
    with pytest.raises(ValueError, match="finite"):
        shaft.clock(sp).tau([np.nan])
    with pytest.raises(ValueError, match="finite"):
        shaft.clock(sp).time_of([np.inf])
    with pytest.raises(ValueError, match="speeds="):
        event_times_for_angles(1.0, 0.0, 0.0, 10.0, profile=shaft)
    with pytest.raises(TypeError, match="profile"):
        event_times_for_angles(1.0, 0.0, 0.0, 10.0, profile="fast")
    other = Speeds(sp.sun * 2, sp.carrier * 2, sp.planet * 2, 0.0)
    with pytest.raises(ValueError, match="bound to speeds"):
        engagement_events(g, other, "sun", 0.0, 0.0, 10.0, profile=shaft.clock(sp))
    with pytest.raises(TypeError, match="profile"):
        engagement_events(g, sp, "sun", 0.0, 0.0, 10.0, profile="fast")
    with pytest.raises(ValueError, match="member"):
        member_rate(sp, "shaft")


def test_empty_inputs():
    g, sp = rig()
    clock = SpeedProfile.shaft_ripple("carrier", 0.03).clock(sp)
    for f in (clock.tau, clock.factor, clock.time_of):
        assert f(np.empty(0)).shape == (0,)
        assert f(np.empty((0, 3))).shape == (0, 3)
    assert clock.n_panels == 0                               # nothing asked, nothing built
    assert SpeedProfile(shaft=()).is_constant and not SpeedProfile(shaft=()).has_shaft
    zero = SpeedProfile(shaft=(("ring", 0.0),))              # zero amplitude: no ripple
    assert zero.is_constant and np.array_equal(zero.tau([1.0, 2.0]), [1.0, 2.0])
    assert zero.clock(sp).tau(3.0) == 3.0
    ev = engagement_events(g, sp, "sun", 0.0, 5.0, 5.0, profile=clock)
    assert len(ev) == 0
    e0, e1 = event_times_for_angles(0.0, 0.0, 0.0, 1.0, profile=clock)
    assert e0.size == 0 and e1.size == 0
    # scalars keep their shape
    assert np.ndim(clock.tau(1.5)) == 0 and np.ndim(clock.time_of(1.5)) == 0
