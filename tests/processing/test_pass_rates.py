"""Pass rates against the gearset and the typed speeds (meshphase.kinematics.pass_rates).

The expected rates are worked by hand from the seed rig (Z 25/87/29, 4 planets, ring held,
sun 18.19 r/min): carrier 18.19 x 25 / 112 = 4.0603 r/min, sun relative to the carrier
14.1297 r/min, so a sun gauge sees 4 x 14.1297 / 60 = 0.94198 passes/s and a ring gauge
4 x 4.0603 / 60 = 0.27068 (the independent rig measures 0.942 and 0.2706).
"""

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from meshphase.models.gearset import Gearset, Speeds, rpm_to_rad_s
from meshphase.kinematics.pass_rates import (RATE_TOLERANCE, expected_pass_rates, measured_pass_rate,
                                             pass_rate_warnings)
from meshphase.kinematics.planet_labels import GaugePasses

RIG = Gearset.equally_spaced(25, 87, 29, 4, 0.1125)


def rig_speeds(sun_rpm=18.19) -> Speeds:
    carrier = sun_rpm * 25 / 112
    return Speeds.kinematic(RIG, rpm_to_rad_s(sun_rpm), rpm_to_rad_s(carrier))


def train(name, gear, rate, seconds=120.0, jitter=0.0, rng=0):
    t = np.arange(0.0, seconds, 1.0 / rate)
    t = t + np.random.default_rng(rng).normal(0.0, jitter / rate, t.size)
    return GaugePasses(name, gear, np.sort(t), np.ones(t.size))


def test_expected_rates_by_hand():
    e = expected_pass_rates(RIG, rig_speeds())
    assert e["sun"] == pytest.approx(4 * 18.19 * 87 / 112 / 60, rel=1e-12)   # 0.94198
    assert e["ring"] == pytest.approx(4 * 18.19 * 25 / 112 / 60, rel=1e-12)  # 0.27068
    assert e["sun"] / e["ring"] == pytest.approx(87 / 25, rel=1e-12)
    assert expected_pass_rates(RIG, None) == {}
    # the sun held: no sun gauge rate to expect
    held = Speeds(sun=0.0, carrier=0.0, planet=0.0, ring=0.0)
    assert expected_pass_rates(RIG, held) == {}


def test_measured_rate_is_robust_to_missing_passes():
    t = np.arange(200) * 0.25
    assert measured_pass_rate(t) == pytest.approx(4.0, rel=1e-12)
    keep = np.ones(t.size, bool)
    keep[10:60:3] = False                                   # 17 passes lost, 0.2 of them
    assert measured_pass_rate(t[keep]) == pytest.approx(4.0, rel=1e-12)
    assert measured_pass_rate(t[::-1]) == pytest.approx(4.0, rel=1e-12)


def test_measured_rate_of_too_little_is_nan():
    assert math.isnan(measured_pass_rate([]))
    assert math.isnan(measured_pass_rate([1.0, 2.0]))
    assert math.isnan(measured_pass_rate([1.0, np.nan, 2.0]))
    assert math.isnan(measured_pass_rate([3.0, 3.0, 3.0]))


def test_measured_rate_bad_input():
    with pytest.raises((TypeError, ValueError)):
        measured_pass_rate(["a", "b", "c"])


def test_a_right_scene_says_nothing():
    e = expected_pass_rates(RIG, rig_speeds())
    passes = [train("S", "sun", e["sun"], jitter=0.05), train("R", "ring", e["ring"], jitter=0.05)]
    assert pass_rate_warnings(passes, RIG, rig_speeds()) == []
    assert pass_rate_warnings(passes, RIG) == []
    assert pass_rate_warnings([], RIG, rig_speeds()) == []


def test_swapped_channels_are_named():
    e = expected_pass_rates(RIG, rig_speeds())
    passes = [train("SG_ring", "sun", e["ring"]), train("SG_sun", "ring", e["sun"])]
    for sp in (rig_speeds(), None):                         # the ratio needs no speeds
        msg, = pass_rate_warnings(passes, RIG, sp)
        assert "look swapped" in msg and "'SG_ring' (kind sun)" in msg and "3.48" in msg


def test_speeds_typed_off_are_said_once_for_both_gauges():
    e = expected_pass_rates(RIG, rig_speeds())
    passes = [train("S", "sun", e["sun"]), train("R", "ring", e["ring"])]
    msg, = pass_rate_warnings(passes, RIG, rig_speeds(2 * 18.19))
    assert "typed speeds look 2x the rig's" in msg
    # within the tolerance: nothing
    assert pass_rate_warnings(passes, RIG, rig_speeds(1.4 * 18.19)) == []


def test_one_gauge_of_the_other_gear_is_named():
    e = expected_pass_rates(RIG, rig_speeds())
    msg, = pass_rate_warnings([train("SG_sun_T3", "ring", e["sun"])], RIG, rig_speeds())
    assert "ring gauge 'SG_sun_T3'" in msg and "is the channel's kind sun?" in msg
    msg, = pass_rate_warnings([train("X", "ring", 3 * e["sun"])], RIG, rig_speeds())
    assert "check the typed speeds, the planet count" in msg


def test_only_main_gauges_count():
    e = expected_pass_rates(RIG, rig_speeds())
    side = GaugePasses("F", "sun", np.arange(100) / (5 * e["sun"]), np.ones(100), main=False)
    assert pass_rate_warnings([side], RIG, rig_speeds()) == []


def test_bad_gearset():
    with pytest.raises(TypeError, match="Gearset"):
        pass_rate_warnings([], None)


@settings(max_examples=40, deadline=None)
@given(sun_rpm=st.floats(1.0, 3000.0), n=st.integers(3, 7), zs=st.integers(13, 40),
       zp=st.integers(13, 40), jitter=st.floats(0.0, 0.1))
def test_right_is_quiet_and_swapped_is_named_at_any_speed(sun_rpm, n, zs, zp, jitter):
    # whatever the gearset and speed: gauges at their own gear's rate raise nothing, the
    # same trains under each other's kind are called swapped (Z_r / Z_s > 2 always)
    g = Gearset.equally_spaced(zs, zs + 2 * zp, zp, n, 0.1)
    carrier = sun_rpm * zs / (2 * zs + 2 * zp)
    sp = Speeds.kinematic(g, rpm_to_rad_s(sun_rpm), rpm_to_rad_s(carrier))
    e = expected_pass_rates(g, sp)
    secs = 40.0 / e["ring"]                                 # 40 ring passes
    right = [train("S", "sun", e["sun"], secs, jitter), train("R", "ring", e["ring"], secs, jitter)]
    assert pass_rate_warnings(right, g, sp) == []
    swapped = [train("S", "ring", e["sun"], secs, jitter), train("R", "sun", e["ring"], secs, jitter)]
    msg, = pass_rate_warnings(swapped, g, sp)
    assert "look swapped" in msg
    assert RATE_TOLERANCE < (2 * zs + 2 * zp) / zs
