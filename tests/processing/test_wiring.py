"""Wrong wiring named from the gauges' own pass rates and samples (meshphase.kinematics.pass_rates:
wiring_findings, two_level_train), on pass trains made by hand at the seed rig's rates
(sun 0.942 passes/s, ring 0.271, carrier 0.0677 turns/s: tests/processing/test_pass_rates.py
works them out)."""

import warnings

import numpy as np
import pytest

from meshphase.models.gearset import Gearset, Speeds, rpm_to_rad_s
from meshphase.kinematics.pass_rates import TWO_LEVEL_SPREAD, two_level_train, wiring_findings
from meshphase.kinematics.planet_labels import GaugePasses

RIG = Gearset.equally_spaced(25, 87, 29, 4, 0.1125)
SUN, RING, CARRIER = 0.94198, 0.27068, 18.19 * 25 / 112 / 60


def speeds() -> Speeds:
    return Speeds.kinematic(RIG, rpm_to_rad_s(18.19), rpm_to_rad_s(18.19 * 25 / 112))


def train(name, gear, rate, seconds=120.0):
    t = np.arange(0.0, seconds, 1.0 / rate)
    return GaugePasses(name, gear, t, np.ones(t.size))


def test_right_wiring_has_no_finding():
    passes = [train("SG_sun", "sun", SUN), train("SG_sun2", "sun", SUN), train("SG_ring", "ring", RING)]
    assert wiring_findings(passes, RIG, speeds()) == {}
    assert wiring_findings(passes, RIG) == {}
    tacho = np.arange(0.0, 120.0, 1.0 / CARRIER)
    assert wiring_findings(passes, RIG, speeds(), tacho) == {}


def test_wiring_findings_empty_and_bad_input():
    assert wiring_findings([], RIG, speeds()) == {}
    assert wiring_findings([train("a", "sun", SUN, seconds=2.0)], RIG, speeds()) == {}  # < 3 passes
    with pytest.raises(TypeError, match="gearset must be a Gearset"):
        wiring_findings([], None)


def test_both_gauges_mapped_as_sun_names_the_ring_gauge():
    # a glob "SG_*" with kind sun: the ring gauge's passes feed the sun's angle model
    passes = [train("SG_sun", "sun", SUN), train("SG_ring", "sun", RING)]
    got = wiring_findings(passes, RIG, speeds())
    assert list(got) == ["sun"] and len(got["sun"]) == 1
    assert "'SG_ring' (kind sun)" in got["sun"][0] and 'kind = "ring"' in got["sun"][0]
    # without speeds the two sun channels still disagree by Z_r / Z_s
    got = wiring_findings(passes, RIG)
    assert "'SG_sun' and 'SG_ring' are both mapped as sun gauges" in got["sun"][0]
    assert "a ring gauge's" in got["sun"][0]


def test_swapped_kinds_name_both_channels():
    got = wiring_findings([train("SG_sun", "ring", SUN), train("SG_ring", "sun", RING)], RIG, speeds())
    assert "'SG_sun' (kind ring)" in got["ring"][0] and 'kind = "sun"' in got["ring"][0]
    assert "'SG_ring' (kind sun)" in got["sun"][0] and 'kind = "ring"' in got["sun"][0]


def test_the_tacho_mapped_as_a_gauge_is_named():
    tacho = np.arange(0.0, 600.0, 1.0 / CARRIER)
    passes = [train("SG_sun", "sun", SUN), train("OPR", "ring", CARRIER, seconds=600.0)]
    got = wiring_findings(passes, RIG, speeds(), tacho)
    assert "'OPR' (kind ring)" in got["ring"][0] and "once per carrier turn" in got["ring"][0]
    assert 'kind = "tacho"' in got["ring"][0]
    got = wiring_findings([train("SG_sun", "sun", SUN)], RIG, speeds(),
                          pulse_trains={"OPR": ("ring", 0.0, 5.0)})
    assert "'OPR' (kind ring) is a two-level pulse train" in got["ring"][0]


def _ttl(n=60000, noise=0.005, rng=0):
    x = np.where((np.arange(n) % 15000) < 300, 5.0, 0.0)       # 2 % duty, as a key's pulse
    return x + np.random.default_rng(rng).normal(0.0, noise, n)


def _gauge(n=60000, snr_noise=0.1, rng=0):
    u = (np.arange(n) % 1000) / 1000.0                       # one pulse per 1000 samples
    pulse = np.exp(-0.5 * ((u - 0.5) / 0.05) ** 2)
    return pulse + np.random.default_rng(rng).normal(0.0, snr_noise, n)


def test_two_level_train_finds_a_tacho_and_not_a_gauge():
    lv = two_level_train(_ttl())
    assert lv is not None and lv[0] == pytest.approx(0.0, abs=1e-3) and lv[1] == pytest.approx(5.0, abs=1e-3)
    assert two_level_train(_ttl(noise=0.0)) is not None
    # a tooth-root pulse train, noisy or clean, and a clipped one: round tops, no two levels
    assert two_level_train(_gauge()) is None
    assert two_level_train(_gauge(snr_noise=0.0)) is None
    assert two_level_train(np.minimum(_gauge(snr_noise=0.01), 0.6)) is None
    # a TTL with noise far past TWO_LEVEL_SPREAD of its swing is not taken for one
    assert two_level_train(_ttl(noise=5.0 * TWO_LEVEL_SPREAD * 5.0)) is None


def test_two_level_train_empty_and_bad_input():
    assert two_level_train([]) is None
    assert two_level_train(np.full(100, np.nan)) is None
    assert two_level_train(np.ones(100)) is None                # flat
    assert two_level_train(np.r_[np.zeros(100), 5.0]) is None   # one high sample
    with pytest.raises((TypeError, ValueError)):
        two_level_train(["a", "b"])


@pytest.mark.parametrize("scale", [1e-310, 1e-6, 1.0, 1e300])
def test_two_level_train_is_scale_free(scale):
    # a tacho-like train at any sample size gives the same verdict and levels in proportion:
    # no overflow of the range or the spreads at 1e300, no loss at subnormal sizes (the
    # levels are exact multiples of the train's 0 and 1 up to one rounding of the scaling)
    x = np.tile(np.r_[np.zeros(20), np.ones(20)], 10) * scale
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        lv = two_level_train(x)
    assert lv is not None
    assert lv[0] == 0.0 and lv[1] == pytest.approx(scale, rel=1e-12 if scale > 1e-300 else 1e-6)
