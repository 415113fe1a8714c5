"""Measured phasing on a real rig's conditions, end to end, against the synthetic truth.

The matrix of the measured-phasing issue (meshphase.bench.phasing, which ``meshphase bench
processing`` also runs and tabulates): the seed 000 Table 1 gearset on the seed's rig with a
held ring, 0.2 mm shaft hole errors, white noise, hum and drift, under 1 % and 3 % speed ripple
at the carrier rate, 1 % at the sun rate, +-10 % ramps, both senses, three unequally spaced
planets and five planets, with and without the carrier tacho, at 20 and 10 dB.

Targets (the issue's): per-pass RMS error of sun and ring phasing <= 2e-3 mesh cycles, or
<= 1.3 times the floor the two onsets' timing bounds set where that floor is higher (at 20 dB
it is ~2.5e-3 on this rig: the seed rig's pulse times to ~1.3 ms at 5120 Hz, and a pass
compares two of them). Calibration: over the matrix, RMS of error / sigma within 0.7-1.5 and
the 95 % interval holding 90-98 % of the passes. Planet labels: planet 1 of the ring gauge
(on the held ring) comes from the tacho whenever there is one. The "phasing not reliable"
warning: never on these scenarios.

The default suite runs the 2-minute, 20 dB cells of every condition plus the tacho-less and
10 dB variants of the 1 % case; ``-m slow`` the whole matrix (10-minute records included).

The adversarial conditions (planet-rate ripple on four and five planets, the sun at
120 r/min, a +-25 % torque ripple, µε channels, a clean rig) are held to their scenario's
``expect``: the target, or (``goal_or_flag``) the target or a flag whose uncertainty covers
the error; a gauge whose planets the run names must name them right.
"""

import numpy as np
import pytest

from meshphase.bench.conditions import FLAGGED_Z_MAX
from meshphase.bench.phasing import PhasingCase, matrix_cases, run_case
from meshphase.synthetic.scenarios import ADVERSARIAL_SCENARIOS, SCENARIOS

FAST = [PhasingCase(s) for s in ("rig_steady", "rig_ripple1", "rig_ripple3", "rig_ripple_sun",
                                 "rig_ramp_up", "rig_ramp_down", "rig_ccw", "rig_3planets",
                                 "rig_5planets")]
FAST += [PhasingCase("rig_ripple1", tacho=False), PhasingCase("rig_ripple1", snr_db=10.0)]
SLOW = [c for c in matrix_cases() if c not in FAST]

_RUNS: dict = {}


def run(case: PhasingCase) -> dict:
    if case not in _RUNS:
        _RUNS[case] = run_case(case, seed=11)
    return _RUNS[case]


def _check(case):
    res = run(case)
    assert set(res["gauges"]) == {"sun", "ring"}, res["ctx"].failed
    for gear, r in res["gauges"].items():
        assert r["n"] >= 15, (gear, r["n"])
        # the target, with the floor printed next to the error in the message
        assert r["rms"] <= r["target"], (case.name, gear, r["rms"], r["floor"], r["model"])
        assert r["reliable"], (case.name, gear, res["ctx"].messages)
    ph = res["ctx"].phasing
    if case.tacho:
        # the ring gauge sits on the held ring: planet 1 from the tacho (or from the pattern
        # itself when the planets are unequally spaced), and right
        assert ph.assignment["ring"]["shift_decided_by"] in ("tacho", "pattern")
        assert res["gauges"]["ring"]["label_match"] == 1.0
    assert not [m for m in res["ctx"].messages if "not reliable" in m]


@pytest.mark.parametrize("case", FAST, ids=lambda c: c.name)
def test_phasing_meets_the_target(case):
    _check(case)


@pytest.mark.slow
@pytest.mark.parametrize("case", SLOW, ids=lambda c: c.name)
def test_phasing_meets_the_target_whole_matrix(case):
    _check(case)


def test_uncertainty_is_calibrated_over_the_matrix():
    z, n_in = [], 0
    for case in FAST:
        for r in run(case)["gauges"].values():
            zz = r["errors"] / r["sigma"]
            z.append(zz[np.isfinite(zz)])
    z = np.concatenate(z)
    assert z.size > 500
    z_rms = float(np.sqrt(np.mean(z ** 2)))
    cover = float(np.mean(np.abs(z) <= 1.96))
    assert 0.7 <= z_rms <= 1.5, z_rms
    assert 0.90 <= cover <= 0.98, cover


def test_without_a_tacho_labels_are_relative_and_said_once():
    res = run(PhasingCase("rig_ripple1", tacho=False))
    ph = res["ctx"].phasing
    assert ph.assignment["ring"]["shift_decided_by"] != "tacho"
    from meshphase.run.stages import summary_dict

    s = summary_dict(res["ctx"])
    assert "relative" in s["phasing_labels"] or ph.labels_relative == []
    # no warning about it on a clean run: one line in the summary is enough
    assert not [m for m in res["ctx"].messages if "planet 1" in m]


# ----------------------------------------------------------------------------- adversarial
# Conditions where measured phasing was once confident and wrong (the adversarial scenarios
# of meshphase.synthetic.scenarios, held to Scenario.expect): "goal" as above; "goal_or_flag"
# within the target, or flagged unreliable with an uncertainty that covers the error
# (RMS(error / sigma) <= 1.5, the calibration bound above). The rig's own artefacts (20 dB),
# tacho kept, seed 11.
@pytest.mark.parametrize("name", ADVERSARIAL_SCENARIOS)
def test_adversarial_condition_meets_the_goal_or_is_flagged(name):
    res = run(PhasingCase(name, snr_db=None))
    expect = SCENARIOS[name].expect
    assert set(res["gauges"]) == {"sun", "ring"}, res["ctx"].failed
    for gear, r in res["gauges"].items():
        if expect == "goal":
            assert r["rms"] <= r["target"] and r["reliable"], (name, gear, r["rms"], r["target"])
        else:
            flagged = not r["reliable"] and r["z_rms"] <= FLAGGED_Z_MAX
            assert r["rms"] <= r["target"] or flagged, (name, gear, r["rms"], r["target"],
                                                        r["z_rms"], r["reliable"])


def test_clean_slow_rig_gives_no_data_quality_warning():
    res = run(PhasingCase("rig_clean", snr_db=None))
    assert not [m for m in res["ctx"].messages if "DataQualityWarning" in m], res["ctx"].messages


@pytest.mark.parametrize("name", ADVERSARIAL_SCENARIOS)
def test_adversarial_condition_names_planets_right_or_says_relative(name):
    # a gauge whose planets the run names (not declared relative) must name them as the truth
    # does: a wrong planet 1 is a confident wrong answer of its own
    res = run(PhasingCase(name, snr_db=None))
    for gear, r in res["gauges"].items():
        assert r["label_match"] in ("relative", 1.0), (name, gear, r["label_match"],
                                                        res["ctx"].phasing.assignment[gear])
