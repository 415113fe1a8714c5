"""Every member's speed from the measured mesh frequency (meshphase.kinematics.member_speeds), against
the independent rig's kinematics (tests/independent/rig.py: its own Willis coefficients, no
meshphase code) and Willis by hand for a differential."""

import math

import numpy as np
import pytest

from meshphase.kinematics.member_speeds import mean_mesh_rate, member_speeds, tacho_rate
from meshphase.models.gearset import Gearset, Speeds

from independent import rig as R

RPM = 2 * math.pi / 60.0
G = Gearset.equally_spaced(25, 87, 29, 4, 112.5e-3, direction="cw")
RG = R.Gearset.equally_spaced(25, 87, 29, 4, 112.5e-3)


def _rig(fixed, **rpm):
    """The rig's kinematics and speeds [r/min] (its "planet" is the spin relative to the
    carrier), and the meshphase gearset turning its planets the same way."""
    kin = R.nominal_kinematics(RG, fixed, **rpm)
    speeds = {m: kin.rpm(m) for m in ("sun", "carrier", "ring", "planet")}
    return kin, speeds, Gearset.equally_spaced(25, 87, 29, 4, 112.5e-3,
                                               direction=kin.planet_rotation)


@pytest.mark.parametrize("fixed, rpm", [("ring", {"sun_rpm": 18.19}), ("sun", {"carrier_rpm": 1.06})])
def test_held_member_speeds_match_the_rig(fixed, rpm):
    # only the mesh frequency and which member is held: every speed follows (exact algebra,
    # so 1e-12 relative)
    kin, truth, g = _rig(fixed, **rpm)
    got = member_speeds(g, kin.mesh_frequency, fixed=fixed)
    for m in ("sun", "carrier", "ring"):
        assert got[m] == pytest.approx(truth[m], rel=1e-12, abs=1e-12), m
    # the rig's "planet" is the spin relative to the carrier
    assert got["planet_relative"] == pytest.approx(truth["planet"], rel=1e-12)
    assert got["planet"] == pytest.approx(truth["planet"] + truth["carrier"], rel=1e-12)
    assert got["held"] == fixed and got["text"].startswith(f"{fixed} held;")
    assert got[fixed] == 0.0


def test_star_arrangement_ring_turns():
    # carrier held (the rig's third case) with the nominal speeds saying so: the ring turns
    kin, truth, g = _rig("carrier", sun_rpm=18.19)
    nominal = Speeds.kinematic(g, sun=18.19 * RPM, carrier=0.0)
    got = member_speeds(g, kin.mesh_frequency, fixed=None, speeds=nominal)
    assert got["ring"] == pytest.approx(truth["ring"], rel=1e-12)      # -5.227 r/min
    assert got["carrier"] == 0.0
    assert got["text"].startswith(f"carrier held (a star arrangement): the ring turns at "
                                  f"{truth['ring']:.4g} r/min")


def test_differential_sun_18_19_carrier_1_06():
    # both driven: sun 18.19, carrier 1.06 r/min. Willis by hand: ring = c - Z_s/Z_r (s - c)
    # = -3.8624 r/min, planet relative = -Z_s/Z_p (s - c); mesh frequency Z_s (s - c) / 60
    s, c = 18.19, 1.06
    f_m = 25 * (s - c) / 60.0
    nominal = Speeds.kinematic(G, sun=s * RPM, carrier=c * RPM)
    got = member_speeds(G, f_m, fixed=None, speeds=nominal)
    assert got["sun"] == pytest.approx(s, rel=1e-12)
    assert got["carrier"] == pytest.approx(c, rel=1e-12)
    assert got["ring"] == pytest.approx(c - 25 / 87 * (s - c), rel=1e-12)
    assert got["planet_relative"] == pytest.approx(-25 / 29 * (s - c), rel=1e-12)
    assert got["text"].startswith("none held: the ring turns at -3.862 r/min")
    assert got["carrier_from"] == "nominal carrier / sun-relative ratio"
    # a carrier tacho measures the carrier instead of the nominal ratio: a tacho 1 % faster
    # than nominal moves the carrier 1 %
    got = member_speeds(G, f_m, fixed=None, speeds=nominal, carrier_rate=1.01 * c / 60.0)
    assert got["carrier"] == pytest.approx(1.01 * c, rel=1e-12)
    assert got["carrier_from"] == "carrier tacho"


def test_differential_without_speeds_or_tacho_leaves_the_carrier_unknown():
    got = member_speeds(G, 5.0, fixed=None)
    assert math.isnan(got["carrier"]) and math.isnan(got["sun"]) and math.isnan(got["ring"])
    assert got["planet_relative"] == pytest.approx(-5.0 / 29 * 60.0)  # relative speeds known
    assert got["text"].startswith("none held; sun unknown")


def test_sense_follows_the_nominal_speeds():
    kin, truth, g = _rig("ring", sun_rpm=-18.19)
    nominal = Speeds.kinematic(g, sun=-18.19 * RPM, carrier=-4.06 * RPM)
    got = member_speeds(g, kin.mesh_frequency, fixed="ring", speeds=nominal)
    assert got["sun"] == pytest.approx(truth["sun"], rel=1e-12) and got["sun"] < 0


def test_member_speeds_bad_inputs():
    with pytest.raises(ValueError, match="mesh_rate"):
        member_speeds(G, 0.0, fixed="ring")
    with pytest.raises(ValueError, match="mesh_rate"):
        member_speeds(G, float("nan"), fixed="ring")
    with pytest.raises(ValueError, match="fixed must be"):
        member_speeds(G, 5.0, fixed="carrier")
    with pytest.raises(TypeError, match="Gearset"):
        member_speeds({"z_sun": 25}, 5.0, fixed="ring")
    with pytest.raises(TypeError, match="Speeds"):
        member_speeds(G, 5.0, fixed=None, speeds=(18.19, 1.06))


class _Model:
    def __init__(self, span, rate):
        self.t_span, self.rate = span, rate

    def mesh_angle(self, t):
        return self.rate * np.asarray(t, dtype=float)


def test_mean_mesh_rate_and_tacho_rate():
    assert mean_mesh_rate(_Model((1.0, 11.0), 5.8874)) == pytest.approx(5.8874, rel=1e-14)
    assert math.isnan(mean_mesh_rate(_Model((2.0, 2.0), 5.0)))          # no span
    with pytest.raises(TypeError, match="angle model"):
        mean_mesh_rate(object())
    # once-per-turn edges every 14.78 s, the fourth missing: 6 turns over 6 periods
    t = 0.5 + 14.78 * np.array([0, 1, 2, 4, 5, 6])
    assert tacho_rate(t) == pytest.approx(1 / 14.78, rel=1e-12)
    assert math.isnan(tacho_rate(None)) and math.isnan(tacho_rate([])) and math.isnan(tacho_rate([1.0]))
    with pytest.raises(ValueError, match="1-D"):
        tacho_rate([[0.0, 1.0]])
