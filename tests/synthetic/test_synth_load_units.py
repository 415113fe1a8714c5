"""Load modulation locked to the carrier angle, gauge unit strings in every writer, the truth
phasing under several shaft-locked ripples at once against an independent integration, and
the adversarial rig scenarios."""

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from meshphase.io import read
from meshphase.models.tolerance import table2_case
from meshphase.synthetic import (SCENARIOS, Artefacts, GaugeConfig, LoadModulation, SpeedProfile,
                                 cli_synth, generate, get_scenario)
from meshphase.synthetic.config import STRAIN_UNITS, SynthConfig, errors_to_dict, load_factor
from meshphase.synthetic.kinematics import gauge_rates
from meshphase.synthetic.scenarios import ADVERSARIAL_SCENARIOS, EXPECTS, Scenario

from _synth_reference import ode_tau_ref, residual_tau_ref

TWO_PI = 2 * math.pi
TERMS = ((0.25, 1, 0.4), (0.05, 3, -1.0))


def _clean(name="rig_steady", **changes):
    return get_scenario(name).with_(artefacts=Artefacts(), **changes)


# ----------------------------------------------------------------------------- load modulation

def test_load_modulation_follows_the_carrier_angle_of_the_tacho():
    """Every pulse amplitude is nominal x (1 + sum a cos(m theta_c + phi)); theta_c taken here
    from the tacho channel (the key passes at the carrier angle ``tacho_angle``) and the
    constant carrier speed, not from the generator's angle time."""
    cfg = _clean(load_modulation=TERMS)
    rec, truth = generate(cfg, duration=40.0, seed=2)
    sp = cfg.speeds
    t_key = truth.tacho_times[0]
    assert truth.tacho_times.size >= 2
    for g in cfg.gauges:
        ev = truth.events[g.name]
        theta = truth.extra["tacho_angle"] + sp.carrier * (ev.time - t_key)
        want = g.amplitude * (1 + sum(a * np.cos(m * theta + ph) for a, m, ph in TERMS))
        # constant speed: theta agrees to rounding of t (~1e-14 s x 0.43 rad/s)
        np.testing.assert_allclose(ev.amplitude, want, rtol=1e-12)
        assert np.ptp(ev.amplitude / g.amplitude) > 0.4      # the +-25 % term does show
        # the rendered pulse peaks at that amplitude: 869 samples per mesh period put a sample
        # within 1e-3 mesh periods of the peak, where the shape is flat to ~1e-4
        x = rec.channel(g.name)
        for t_e, amp in zip(ev.time[1:-1], ev.amplitude[1:-1]):
            i = int(round((t_e - rec.t0) * rec.fs))
            peak = x[i - 400:i + 400].max()
            assert peak == pytest.approx(amp, rel=1e-3)


def test_load_modulation_terms_round_trip_and_no_terms_change_nothing():
    cfg = _clean(load_modulation=TERMS)
    assert cfg.load_modulation == tuple(LoadModulation(*t) for t in TERMS)
    assert SynthConfig.from_dict(cfg.to_dict()).to_dict() == cfg.to_dict()
    same = _clean(load_modulation=[{"amplitude": 0.25, "order": 1, "phase": 0.4}, (0.05, 3, -1.0)])
    assert same.load_modulation == cfg.load_modulation
    # empty: no terms, the samples bit for bit those of a config without the field
    a, _ = generate(_clean(), duration=5.0, seed=3)
    b, _ = generate(_clean(load_modulation=()), duration=5.0, seed=3)
    assert np.array_equal(a.data, b.data)
    np.testing.assert_array_equal(load_factor((), [0.0, 1.0]), [1.0, 1.0])
    assert load_factor(cfg.load_modulation, []).shape == (0,)
    np.testing.assert_allclose(load_factor(cfg.load_modulation, [0.0]),
                               [1 + 0.25 * math.cos(0.4) + 0.05 * math.cos(-1.0)], rtol=1e-15)


@pytest.mark.parametrize("terms, err, match", [
    (((-0.1, 1),), ValueError, "amplitude"),
    (((1.0, 1),), ValueError, r"\[0, 1\)"),
    (((0.1, 0),), ValueError, "order"),
    (((0.6, 1), (0.5, 2)), ValueError, "sum to 1.1"),
    (LoadModulation(0.1), TypeError, "wrap it in a tuple"),
    (0.25, TypeError, "sequence"),
    (({"amplitude": 0.1, "freq": 2},), ValueError, "keys"),
    (((0.1, 1, 0.0, 9),), TypeError, "load modulation term"),
])
def test_load_modulation_bad_inputs(terms, err, match):
    with pytest.raises(err, match=match):
        _clean(load_modulation=terms)


# ----------------------------------------------------------------------------- gauge units

@pytest.mark.parametrize("units", ["µε", "mm/m", "%"])
def test_gauge_units_scale_the_samples_and_name_the_channel(units):
    base = _clean(load_modulation=TERMS)
    gauges = tuple(GaugeConfig(g.name, g.gear, g.tooth, g.face_position, g.amplitude,
                               g.contact_ratio, g.side_lobe, g.skew, units=units) for g in base.gauges)
    a, ta = generate(base, duration=5.0, seed=4)
    b, tb = generate(base.with_(gauges=gauges), duration=5.0, seed=4)
    scale = STRAIN_UNITS[units]
    assert [c.units for c in b.channels] == [units, units, "V"]
    for g in ("sun", "ring"):
        # the same float64 product of the same strain: equal bit for bit
        assert np.array_equal(b.channel(g), scale * a.channel(g))
    assert np.array_equal(b.channel("tacho"), a.channel("tacho"))
    # the truth stays SI, with the channel's units beside it
    np.testing.assert_array_equal(tb.events["sun"].amplitude, ta.events["sun"].amplitude)
    assert tb.extra["gauge_units"]["sun"] == {"units": units, "scale": scale}
    assert SynthConfig.from_dict(base.with_(gauges=gauges).to_dict()).gauges == gauges


def test_gauge_units_bad_input():
    with pytest.raises(ValueError, match=r"gauge 'sun': units must be one of .*'microstrain'"):
        GaugeConfig("sun", "sun", units="microstrain")
    with pytest.raises(ValueError, match="units must be one of"):
        GaugeConfig("sun", "sun", units="")


@pytest.mark.parametrize("suffix", [".h5", ".mcap", ".csv", ".tdms"])
def test_every_writer_carries_the_unit_string(tmp_path, suffix):
    out = tmp_path / f"rec{suffix}"
    path, _ = cli_synth("rig_microstrain", out, minutes=0.1, seed=5, progress=False)
    ref, _ = generate("rig_microstrain", duration=6.0, seed=5)
    # the unit string is in the file's channel metadata (UTF-8 in all four formats)
    assert "µε".encode() in path.read_bytes()
    rec = read(path)
    for g in ("sun", "ring"):
        unit = rec.channels[rec.index(g)].units
        # a reader keeps the file's units, or converts at the door to SI: either way the
        # samples are what the unit says (CSV: 17 significant digits)
        assert unit in ("µε", "m/m"), unit
        want = ref.channel(g) if unit == "µε" else ref.channel(g) / 1e6
        np.testing.assert_allclose(rec.channel(g), want, rtol=1e-15, atol=0)


# ----------------------------------------------------------------------------- truth phasing

def test_truth_phasing_under_several_shaft_ripples_matches_an_independent_integration():
    """Planet-, carrier- and sun-locked ripple at once, 0.2 mm errors: the truth's phasing of
    each pass against one computed from scipy DOP853 on the ODE d tau/dt = s(t, tau) and
    brentq on the engagement condition (tests/synthetic/_synth_reference.py, no synthetic
    code). Claim: 1e-8 mesh cycles, i.e. the engagement times to ~2e-9 s (one second is 5.9
    mesh cycles on this rig); measured 1.7e-13."""
    shaft = (("planet", 0.01, 1, 0.3), ("carrier", 0.01, 1, -0.5), ("sun", 0.005, 2, 1.0))
    cfg = _clean(speed=SpeedProfile(shaft=shaft))
    _, truth = generate(cfg, duration=30.0, seed=1)
    g, sp, err = cfg.gearset, cfg.speeds, table2_case(1)[2]
    ref = ode_tau_ref(cfg.speed, sp, 31.0)
    worst, n_checked = 0.0, 0
    for gear in ("sun", "ring"):
        w, z = gauge_rates(g, sp, gear)
        theta = truth.extra["tooth_angles"][gear]
        p = truth.passes[gear]
        assert len(p) > 3

        def t_ref(t_e, planet):
            h = 0.05 * TWO_PI / abs(w)
            return brentq(residual_tau_ref, t_e - h, t_e + h,
                          args=(gear, planet - 1, theta, g, sp, err, ref), xtol=1e-13, rtol=1e-15)

        for i in range(0, len(p), max(1, len(p) // 6)):
            t1 = t_ref(p.time_planet1[i], 1)
            tn = t_ref(p.time[i], p.planet[i])
            gam = (z * abs(w) * (float(ref(tn)) - float(ref(t1))) / TWO_PI) % 1.0
            d = abs(math.remainder(gam - p.gamma[i], 1.0))
            worst = max(worst, d)
            n_checked += 1
    assert n_checked >= 8
    assert worst <= 1e-8, worst


# ----------------------------------------------------------------------------- scenarios

def test_adversarial_scenarios_change_one_factor_each():
    steady = get_scenario("rig_steady")
    assert set(ADVERSARIAL_SCENARIOS) == {"rig_ripple_planet", "rig_5planets_ripple_planet",
                                          "rig_fast_ripple1", "rig_load_ripple",
                                          "rig_microstrain", "rig_clean"}
    for name in ADVERSARIAL_SCENARIOS:
        sc = SCENARIOS[name]
        assert {"rig", "adversarial"} <= set(sc.tags)
        assert sc.expect == ("goal" if name == "rig_clean" else "goal_or_flag")
    five = get_scenario("rig_5planets_ripple_planet")
    assert five.gearset.n_planets == 5 and five.speed.shaft[0].member == "planet"
    fast = get_scenario("rig_fast_ripple1")
    assert fast.speeds.sun * 30 / math.pi == pytest.approx(120.0, rel=1e-14)
    assert fast.speed.shaft[0].member == "carrier" and fast.speed.shaft[0].amplitude == 0.01
    assert get_scenario("rig_load_ripple").load_modulation[0].amplitude == 0.25
    assert [x.units for x in get_scenario("rig_microstrain").gauges] == ["µε", "µε"]
    assert not get_scenario("rig_clean").artefacts.any and steady.artefacts.any
    # everything else as rig_steady
    for name in ("rig_load_ripple", "rig_microstrain", "rig_clean"):
        cfg = get_scenario(name)
        assert cfg.speeds == steady.speeds and cfg.gearset == steady.gearset
        assert cfg.speed.is_constant and errors_to_dict(cfg.errors) == errors_to_dict(steady.errors)
    assert all(SCENARIOS[n].expect == "goal" for n in SCENARIOS if n not in ADVERSARIAL_SCENARIOS)


def test_scenario_expect_bad_input():
    assert EXPECTS == ("goal", "goal_or_flag")
    with pytest.raises(ValueError, match="expect must be one of .* got 'flag'"):
        Scenario("x", "d", lambda: None, (), "flag")
