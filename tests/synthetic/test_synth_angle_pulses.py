"""Pulses that last a fixed angle of the gauged gear: the renderer against direct evaluation,
pulse widths that follow the local speed, the truth engagement at the pulse's angle-domain
centre, block invariance, the rig scenario family, bad and empty inputs."""

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy.optimize import brentq

from meshphase.models.mesh_phasing import assembly_check, classify_phasing
from meshphase.models.gearset import rad_s_to_rpm
from meshphase.synthetic import (SCENARIOS, Artefacts, GaugeConfig, SynthConfig, generate, generate_blocks,
                                 get_scenario)
from meshphase.synthetic.gauges import (AnglePulses, PulseTable, angle_pulse_map, pulse_shape,
                                        render_angle_pulses)
from meshphase.synthetic.kinematics import SpeedProfile, gauge_rates
from meshphase.synthetic.scenarios import RIG_3PLANETS_P, RIG_SCENARIOS, rig_gearset, rig_speeds

TWO_PI = 2 * math.pi


def sun_only(speed, *, skew=0.0, duration=16.0, reverse=False):
    """Rig gearset, one clean sun gauge (symmetric pulse when skew = 0), no errors, no tacho."""
    g = rig_gearset(direction="ccw" if reverse else "cw")
    return SynthConfig(name="angle-test", gearset=g, speeds=rig_speeds(g, reverse=reverse),
                       fs=5120.0, duration=duration,
                       gauges=(GaugeConfig("sun", "sun", amplitude=150e-6, contact_ratio=1.6,
                                           side_lobe=0.25, skew=skew),),
                       speed=speed)


def half_crossings(x, i_peak, level):
    """Sub-sample positions [samples] where x falls below ``level`` either side of the peak
    (linear interpolation between the two samples that straddle it)."""
    i = i_peak
    while x[i - 1] >= level:
        i -= 1
    left = (i - 1) + (level - x[i - 1]) / (x[i] - x[i - 1])
    j = i_peak
    while x[j + 1] >= level:
        j += 1
    right = j + (x[j] - level) / (x[j] - x[j + 1])
    return left, right


def u_half(side):
    """Where the symmetric pulse (eps 1.6, lobe 0.25, skew 0) crosses half its peak [mesh periods]."""
    f = lambda u: pulse_shape(np.array([u]), 1.6, 0.25, 0.0)[0] - 0.5
    return brentq(f, 0.0, 0.8, xtol=1e-14) * side


# ----------------------------------------------------------------------------- renderer

def test_angle_renderer_matches_direct_evaluation():
    """Every sample equals A p(Z |w| (tau(t_i) - tau_e) / 2 pi) with the exact tau, to the
    pulse table's interpolation error (5e-7 of the peak)."""
    cfg = sun_only(SpeedProfile.shaft_ripple("sun", 0.05, 3, 0.4, ramp_rate=2e-3), skew=0.2)
    clock = cfg.speed.clock(cfg.speeds)
    w, z = gauge_rates(cfg.gearset, cfg.speeds, "sun")
    T = TWO_PI / (z * abs(w))
    tab = PulseTable(1.6, 0.25, 0.2)
    tau_e = np.array([1.234, 2.5, 3.05, 6.0])                # 2.5 / 3.05 overlap: they add
    amp = np.array([1.0, 2.0, -1.0, 0.5])
    ap = angle_pulse_map(tau_e, T, clock.tau, clock.time_of, cfg.fs, tab)
    assert ap.degree > 1 and ap.fit_error <= 1e-9
    out = np.zeros(int(8 * cfg.fs))
    render_angle_pulses(out, 0, ap, amp, tab)
    t = np.arange(out.size) / cfg.fs
    tau = clock.tau(t)
    ref = sum(a * pulse_shape((tau - te) / T, 1.6, 0.25, 0.2) for te, a in zip(tau_e, amp))
    np.testing.assert_allclose(out, ref, rtol=0, atol=1e-6)
    # the samples inside each support are exactly those the map names
    for e, te in enumerate(tau_e):
        inside = np.flatnonzero(np.abs((tau - te) / T) < tab.half)
        assert inside[0] == ap.first[e] and inside.size == ap.count[e]
        assert inside[-1] == ap.first[e] + ap.count[e] - 1 < ap.first[e] + ap.width


def test_angle_map_is_linear_at_constant_speed():
    tab = PulseTable()
    prof = SpeedProfile()
    ap = angle_pulse_map([0.5, 1.5], 0.17, prof.tau, prof.time_of, 5120.0, tab)
    assert ap.degree == 1 and ap.fit_error < 1e-12


@settings(max_examples=40, deadline=None)
@given(cut=st.lists(st.integers(1, 40959), min_size=1, max_size=6, unique=True))
def test_angle_renderer_blocks_bit_identical(cut):
    cfg = sun_only(SpeedProfile.shaft_ripple("carrier", 0.05, 2, 1.0))
    clock = cfg.speed.clock(cfg.speeds)
    tab = PulseTable(1.8, 0.3, -0.2)
    tau_e = np.sort(np.random.default_rng(3).uniform(-0.3, 8.3, 25))
    ap = angle_pulse_map(tau_e, 0.17, clock.tau, clock.time_of, 5120.0, tab)
    amp = np.linspace(1.0, 2.0, tau_e.size)
    whole = np.zeros(40960)
    render_angle_pulses(whole, 0, ap, amp, tab)
    edges = [0] + sorted(cut) + [40960]
    parts = []
    for a, b in zip(edges[:-1], edges[1:]):
        blk = np.zeros(b - a)
        render_angle_pulses(blk, a, ap, amp, tab, max_elems=3001)
        parts.append(blk)
    assert np.array_equal(np.concatenate(parts), whole)


@pytest.mark.parametrize("name, block", [("rig_ripple_sun", 1.7), ("rig_ramp_down", 3.0001),
                                         ("rig_ccw", 2.2)])
def test_rig_blocks_equal_whole(name, block):
    whole, truth = generate(name, duration=14.0, seed=4)
    parts = list(generate_blocks(name, duration=14.0, seed=4, block=block))
    assert np.array_equal(np.concatenate([p.data for p in parts]), whole.data, equal_nan=True)


def test_angle_renderer_empty_and_bad_input():
    tab = PulseTable()
    prof = SpeedProfile()
    empty = angle_pulse_map(np.empty(0), 0.17, prof.tau, prof.time_of, 5120.0, tab)
    assert len(empty) == 0 and empty.width == 0
    out = np.zeros(10)
    render_angle_pulses(out, 0, empty, np.empty(0), tab)
    ap = angle_pulse_map([100.0], 0.17, prof.tau, prof.time_of, 5120.0, tab)
    render_angle_pulses(out, 0, ap, [1.0], tab)              # far outside the buffer
    render_angle_pulses(np.zeros(0), 0, ap, [1.0], tab)
    assert not out.any()
    with pytest.raises(ValueError, match="one value per event"):
        render_angle_pulses(out, 0, ap, [1.0, 2.0], tab)
    with pytest.raises(TypeError, match="AnglePulses"):
        render_angle_pulses(out, 0, (ap.first, ap.coef), [1.0], tab)
    with pytest.raises(TypeError, match="PulseTable"):
        angle_pulse_map([1.0], 0.17, prof.tau, prof.time_of, 5120.0, "table")
    with pytest.raises(ValueError, match="mesh_angle"):
        angle_pulse_map([1.0], -0.17, prof.tau, prof.time_of, 5120.0, tab)
    with pytest.raises(ValueError, match="fs"):
        angle_pulse_map([1.0], 0.17, prof.tau, prof.time_of, 0.0, tab)
    with pytest.raises(TypeError, match="callables"):
        angle_pulse_map([1.0], 0.17, None, prof.time_of, 5120.0, tab)
    with pytest.raises(ValueError, match="finite"):
        angle_pulse_map([np.nan], 0.17, prof.tau, prof.time_of, 5120.0, tab)
    # a speed that swings within one pulse: no low-degree polynomial follows it
    fast = SpeedProfile(ripple=((0.5, 40.0, 0.0),))
    with pytest.raises(ValueError, match="too fast within one pulse"):
        angle_pulse_map([1.0], 0.17, fast.tau, fast.time_of, 5120.0, tab, max_degree=4)


# ----------------------------------------------------------------------------- generated pulses

RIPPLES = {"carrier-5%": SpeedProfile.shaft_ripple("carrier", 0.05, 1, 0.3),
           "sun-x3-5%": SpeedProfile.shaft_ripple("sun", 0.05, 3, 0.3)}


@pytest.mark.parametrize("reverse", [False, True])
@pytest.mark.parametrize("which", sorted(RIPPLES))
def test_pulse_width_follows_local_speed_and_centre_is_the_engagement(which, reverse):
    """A pulse spans a fixed angle: its width in samples is the time the gear takes to turn
    that angle (1 / local speed), and its angle-domain centre is the truth engagement.

    5 % shaft-locked ripple. "sun-x3" (3rd order of the sun, period 1.1 s) changes the speed by
    several % within one 0.6 s pulse, so the pulse is also stretched unevenly; its time-domain
    centre then misses the engagement, the angle-domain centre does not.
    """
    cfg = sun_only(RIPPLES[which], reverse=reverse)
    rec, truth = generate(cfg, seed=0)
    x = rec.channel("sun") / 150e-6
    ev = truth.events["sun"]
    clock = truth.speed_clock()
    T = truth.pulse["sun"]["nominal_mesh_period"]
    u1, u2 = u_half(-1), u_half(+1)
    widths, s_e, mid_tau, mid_t = [], [], [], []
    exact = []
    for te, tau_e in zip(ev.time, ev.tau):
        i = int(round(te * rec.fs))
        if i < 2000 or i > rec.n_samples - 2000:
            continue
        a, b = half_crossings(x, i, 0.5)
        widths.append(b - a)
        exact.append((clock.time_of(tau_e + u2 * T) - clock.time_of(tau_e + u1 * T)) * rec.fs)
        s_e.append(float(clock.factor(te)))
        mid_tau.append((0.5 * (clock.tau(a / rec.fs) + clock.tau(b / rec.fs)) - tau_e) / T)
        mid_t.append((0.5 * (a + b) / rec.fs - te) / float(ev.mesh_period[np.searchsorted(ev.time, te)]))
    widths, exact, s_e = map(np.asarray, (widths, exact, s_e))
    assert widths.size >= 10
    # crossings by linear interpolation at ~870 samples per mesh period: error ~1e-4 samples
    # (measured 3e-4)
    np.testing.assert_allclose(widths, exact, rtol=0, atol=0.01)
    # the width follows 1 / speed: it varies by the ripple (+-5 %), width * s(t_e) stays: the
    # speed changes by b w_c dt ~ 6e-3 across one pulse, but symmetrically, so the width moves
    # only at second order (measured spread 2e-5)
    assert np.ptp(widths) / widths.mean() > 0.05
    if which.startswith("carrier"):
        prod = widths * s_e
        assert np.ptp(prod) / prod.mean() < 2e-4
    # engagement = angle-domain centre of the (symmetric) pulse, to the crossing error
    # (3e-4 samples / 870 per mesh period; measured 8e-8 mesh periods)
    assert np.max(np.abs(mid_tau)) < 1e-6
    if which.startswith("sun"):
        assert np.max(np.abs(mid_t)) > 1e-3            # the time-domain centre does not hold


def test_truth_event_angle_times_give_the_pulse_peaks():
    cfg = get_scenario("rig_ripple3").with_(artefacts=Artefacts())
    rec, truth = generate(cfg, duration=40.0, seed=1)
    for name in ("sun", "ring"):
        peaks = truth.event_angle_times(name, truth.pulse[name]["peak_offset"])
        np.testing.assert_allclose(truth.event_angle_times(name, 0.0), truth.events[name].time,
                                   rtol=0, atol=1e-9)
        x = rec.channel(name)
        i = np.rint((peaks - rec.t0) * rec.fs).astype(int)
        ok = (i > 1000) & (i < rec.n_samples - 1000)
        # the pulse is flat at its peak (870 samples per mesh period): the nearest sample
        # reads the amplitude to 1e-4, and no sample within +-300 is higher than the peak by more
        np.testing.assert_allclose(x[i[ok]], truth.events[name].amplitude[ok], rtol=1e-4)
        for k in i[ok]:
            assert x[k - 300:k + 300].max() <= x[k] * (1 + 1e-4)
    with pytest.raises(ValueError, match="channels"):
        truth.event_angle_times("nope", 0.0)


# ----------------------------------------------------------------------------- the rig family

def test_rig_family_is_registered_and_one_factor_each():
    assert set(RIG_SCENARIOS) == {"rig_steady", "rig_ripple1", "rig_ripple3", "rig_ripple_sun",
                                  "rig_ripple_planet", "rig_ramp_up", "rig_ramp_down", "rig_ccw",
                                  "rig_3planets", "rig_5planets"}
    base = get_scenario("rig_steady")
    g, sp = base.gearset, base.speeds
    assert (g.z_sun, g.z_ring, g.z_planet, g.n_planets) == (25, 87, 29, 4)
    assert g.carrier_radius == 112.5e-3 and g.face_width == 40e-3 and g.direction == "cw"
    np.testing.assert_allclose(np.degrees(g.angles), [0, 90, 180, 270], atol=1e-12)
    assert sp.ring == 0.0                                      # fixed ring, exactly
    assert rad_s_to_rpm(sp.sun) == pytest.approx(18.19, rel=1e-14)
    assert rad_s_to_rpm(sp.carrier) == pytest.approx(18.19 / (1 + 87 / 25), rel=1e-14)
    assert rad_s_to_rpm(sp.carrier) == pytest.approx(4.0603, abs=1e-4)
    a = base.artefacts
    assert (a.snr_db, a.pink_fraction, a.hum_frequency, a.adc_bits) == (20.0, 0.0, 50.0, 24)
    assert a.hum_amplitude > 0 and a.drift_amplitude > 0 and base.fs == 5120.0
    assert base.duration == 120.0 and base.tacho is not None and base.speed.is_constant
    assert [x.gear for x in base.gauges] == ["sun", "ring"]
    assert base.errors is not None and float(base.errors.e_sun) == pytest.approx(0.2e-3)
    for name in RIG_SCENARIOS:
        cfg = get_scenario(name)
        assert "rig" in SCENARIOS[name].tags and cfg.duration == 120.0
        assert cfg.speeds.ring == 0.0 and cfg.artefacts == a and cfg.fs == 5120.0
    amp = {n: [(c.member, c.amplitude) for c in get_scenario(n).speed.shaft] for n in RIG_SCENARIOS}
    assert amp["rig_ripple1"] == [("carrier", 0.01)] and amp["rig_ripple3"] == [("carrier", 0.03)]
    assert amp["rig_ripple_sun"] == [("sun", 0.01)] and amp["rig_ripple_planet"] == [("planet", 0.01)]
    assert get_scenario("rig_ramp_up").speed.ramp_rate * 120 == pytest.approx(0.10)
    assert get_scenario("rig_ramp_down").speed.ramp_rate * 120 == pytest.approx(-0.10)
    ccw = get_scenario("rig_ccw")
    assert ccw.gearset.direction == "ccw" and ccw.speeds.sun == -sp.sun
    assert ccw.speeds.carrier == -sp.carrier and ccw.speeds.planet == -sp.planet


def test_rig_planet_layouts():
    three = get_scenario("rig_3planets").gearset
    chk = assembly_check(three)
    assert chk.all_assemblable and chk.p.tolist() == list(RIG_3PLANETS_P)
    assert classify_phasing(three) == "mixed"
    gaps = np.diff(np.r_[chk.p, 112])
    assert len(set(gaps.tolist())) == 3                       # unequally spaced
    # tip circles clear: (Z_s + Z_p) sin(gap / 2) > Z_p + 2
    assert np.all(54 * np.sin(np.pi * gaps / 112) > 31)
    five = get_scenario("rig_5planets")
    g = five.gearset
    assert (g.z_sun, g.z_ring, g.z_planet, g.n_planets) == (25, 85, 30, 5)
    assert assembly_check(g).all_assemblable
    assert rad_s_to_rpm(five.speeds.carrier) == pytest.approx(18.19 / (1 + 85 / 25), rel=1e-14)


@pytest.mark.parametrize("name", ["rig_ripple1", "rig_ccw", "rig_3planets", "rig_5planets"])
def test_rig_without_tacho_and_other_snr(name):
    cfg = get_scenario(name)
    with_t, truth = generate(cfg, duration=20.0, seed=7)
    bare = cfg.with_(tacho=None, artefacts=Artefacts(**{**cfg.artefacts.to_dict(), "snr_db": 40.0,
                                                        "hum_harmonics": cfg.artefacts.hum_harmonics}))
    rec, t2 = generate(bare, duration=20.0, seed=7)
    assert rec.names == ["sun", "ring"] and "tacho" in with_t.names
    assert t2.tacho_times.size == 0 and truth.tacho_times.size >= 1
    assert t2.noise_rms["sun"] == pytest.approx(150e-6 / 100, rel=1e-12)
    for ch in ("sun", "ring"):
        np.testing.assert_array_equal(t2.events[ch].time, truth.events[ch].time)
        np.testing.assert_array_equal(t2.passes[ch].gamma, truth.passes[ch].gamma)
    assert len(t2.passes["sun"]) > 0
    n = cfg.gearset.n_planets
    assert set(np.unique(t2.events["ring"].planet)) <= set(range(1, n + 1))


def test_cli_lists_the_rig_family(capsys):
    import re

    from meshphase.cli import main

    assert main(["synth", "--list"]) == 0
    out = capsys.readouterr().out
    for name in RIG_SCENARIOS:
        assert re.search(rf"^{name}\s+5120 Hz\s+120 s", out, re.M), name
