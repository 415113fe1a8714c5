"""What the identification can tell: the combinations of offsets the data determine (SVD of
the weighted design) with their 95 % intervals, the rank decision, what extra gauge or longer
record would identify each blind offset, and the verdict paragraph.

The passes are exact engagements (tests/processing/test_compare.py: 4 planets, Z 25/87/29,
30 s) with Gaussian phasing noise added where a statistical statement is checked.
"""

import dataclasses
import math

import numpy as np
import pytest

from meshphase.compare.identify import (Identification, PARAMETER_NAMES, describe_combination,
                                        identification_verdict, identify_errors)
from meshphase.models.gearset import Gearset
from meshphase.kinematics.pass_table import PassTable

from test_compare import ERRORS, exact_table, gearset

#: phasing noise added to the exact passes [mesh cycles] (the demo's per-pass sigma is
#: 1.2e-3 .. 2.6e-3)
NOISE = 2e-3


def _with(table: PassTable, **arrays) -> PassTable:
    kw = {f.name: getattr(table, f.name) for f in dataclasses.fields(table)}
    kw.update(arrays)
    return PassTable(**kw)


def noisy(table: PassTable, sd: float, rng) -> PassTable:
    """The table with N(0, sd) added to its phasing and sd as its uncertainty."""
    return _with(table, gamma=np.mod(table.gamma + rng.normal(0.0, sd, len(table)), 1.0),
                 uncertainty=np.full(len(table), sd))


def cut(table: PassTable, t_max: float) -> PassTable:
    """The passes before ``t_max`` [s]: a shorter record of the same rig."""
    m = table.time < t_max
    cols = ("time", "planet", "revolution", "gamma", "uncertainty", "mesh_period", "ref_time",
            "angle", "timing_floor", "model_sigma")
    return _with(table, **{c: np.asarray(getattr(table, c))[m] for c in cols})


def truth_vector(err) -> np.ndarray:
    """Cartesian parameters of a ShaftHoleErrors [m], PARAMETER_NAMES order (4 planets)."""
    ep = np.broadcast_to(np.asarray(err.e_planet, float), (4,))
    kp = np.broadcast_to(np.asarray(err.kappa_planet, float), (4,))
    v = [err.e_sun * math.cos(err.kappa_sun), err.e_sun * math.sin(err.kappa_sun),
         err.e_ring * math.cos(err.kappa_ring), err.e_ring * math.sin(err.kappa_ring)]
    for e, k in zip(ep, kp):
        v += [e * math.cos(k), e * math.sin(k)]
    return np.asarray(v, dtype=float)


def test_combinations_cover_the_true_combinations_over_seeds():
    # every gear offset present ("all"), both gauges, noise 2e-3 cycles, five seeds. Without
    # the pass-timing term (pass_offset_std=0: the exact passes have no timing offset) the
    # intervals are purely statistical: each should hold the true combination 95 % of the
    # time. 35 intervals: the 5 % binomial tail lies at >= 30 covered; an interval 3x too
    # narrow covers ~50 %. And they must not be far too wide: RMS z of 0.3 or less would
    # mean intervals 3x wider than the scatter.
    g = gearset("cw")
    p_true = truth_vector(ERRORS["all"])
    z = []
    for seed in range(5):
        rng = np.random.default_rng(seed)
        tabs = [noisy(exact_table("cw", gear, "all"), NOISE, rng) for gear in ("sun", "ring")]
        res = identify_errors(tabs, g, pass_offset_std=0.0)
        assert res.rank == len(res.combinations) == 7
        names = PARAMETER_NAMES(4)
        true_c = res.true_combinations(ERRORS["all"])
        for c, t in zip(res.combinations, true_c):
            v = np.array([c["coefficients"][nm] for nm in names])
            assert abs(np.linalg.norm(v) - 1.0) < 1e-12           # unit norm
            assert c["ci95"][0] < c["estimate"] < c["ci95"][1]
            assert t == pytest.approx(v @ p_true, rel=1e-12, abs=1e-18)
            z.append((c["estimate"] - t) / c["std"])
        stds = [c["std"] for c in res.combinations]
        assert stds == sorted(stds)                                # best determined first
    z = np.asarray(z)
    assert np.sum(np.abs(z) <= 1.96) >= 30, z
    assert 0.3 < float(np.sqrt(np.mean(z ** 2))) < 2.0, z


def test_combinations_exclude_the_blind_offsets():
    # the sun and ring offsets are invisible to both gauges: no determined combination may
    # lean on them (their coefficients stay at the rounding of the SVD)
    res = identify_errors([exact_table("cw", "sun", "all"), exact_table("cw", "ring", "all")],
                          gearset("cw"))
    for c in res.combinations:
        blind = np.hypot.reduce([c["coefficients"][k] for k in ("sun_x", "sun_y", "ring_x", "ring_y")])
        assert blind < 0.02, c
        assert "sun offset" not in c["description"] and "ring offset" not in c["description"]


def test_rank_decision_is_stable_under_tiny_perturbations():
    # a perturbation of 1e-9 cycles of every pass (1e-6 of the noise) must not change the
    # rank or the determined subspace
    g = gearset("cw")
    rng = np.random.default_rng(11)
    tabs = [noisy(exact_table("cw", gear, "all"), NOISE, rng) for gear in ("sun", "ring")]
    base = identify_errors(tabs, g)
    for seed in range(3):
        r2 = np.random.default_rng(100 + seed)
        pert = [_with(t, gamma=np.mod(t.gamma + 1e-9 * r2.standard_normal(len(t)), 1.0))
                for t in tabs]
        res = identify_errors(pert, g)
        assert res.rank == base.rank
        np.testing.assert_allclose(res.projector, base.projector, atol=1e-6)
    assert base.rank_note.startswith(f"rank {base.rank} of 12: singular values above rcond = 0.01")
    assert "smallest kept" in base.rank_note and "largest dropped" in base.rank_note
    assert ("a marginal rank" in identification_verdict(base)) == ("marginal" in base.rank_note)


def test_rank_note_says_when_the_decision_is_marginal():
    # 7.5 s of both gauges, planets only: singular values 0.065 (smallest kept) and 4.6e-3
    # (dropped) of the largest. rcond 8e-3 has the dropped one within a factor 2 (marginal),
    # rcond 2e-2 neither
    g = gearset("cw")
    tabs = [cut(exact_table("cw", gear, "planets"), 7.5) for gear in ("sun", "ring")]
    res = identify_errors(tabs, g, gears=("planet",), rcond=8e-3)
    assert res.rank == 7 and "marginal" in res.rank_note
    assert "(a marginal rank: a singular value lies within a factor 2 of the threshold)" in \
        identification_verdict(res)
    res = identify_errors(tabs, g, gears=("planet",), rcond=2e-2)
    assert res.rank == 7 and "marginal" not in res.rank_note
    # rcond above 1 keeps nothing: said, not a crash
    res = identify_errors(tabs, g, gears=("planet",), rcond=2.0)
    assert res.rank == 0 and res.combinations == [] and "none kept" in res.rank_note


def test_longer_record_prediction_matches_a_longer_record():
    # 7.5 s of both gauges leaves one planet combination at 4.6e-3 of the largest singular
    # value. Continuing every gauge in its own phase adds rows of the same geometry, so no
    # record up to 64x lifts it over rcond: the prediction says so, and recording 4x as
    # long (the exact passes up to 30 s) indeed leaves the rank and flags as they are
    g = gearset("cw")
    rng = np.random.default_rng(3)
    full = [noisy(exact_table("cw", gear, "planets"), NOISE, rng) for gear in ("sun", "ring")]
    short = identify_errors([cut(t, 7.5) for t in full], g, gears=("planet",))
    assert not short.identifiable and short.rank == 7
    assert {s["gear"] for s in short.suggestions} == {f"planet{i}" for i in range(1, 5)}
    assert all(s["record_option"] is None and math.isnan(s["record_factor"])
               for s in short.suggestions)
    longer = identify_errors(full, g, gears=("planet",))
    assert longer.rank == 7 and not longer.identifiable


def test_suggested_second_ring_gauge_identifies_the_planets():
    # the first option the 7.5 s record gets is a second ring gauge a quarter turn from the
    # first; simulating it (the same rig, the gauge tooth a quarter turn further, the same
    # noise) and fitting the three gauges identifies every planet offset, with standard
    # errors near the predicted ones (the prediction is linearised at the two-gauge fit and
    # its noise scale; bound: a factor 1.5)
    g = gearset("cw")
    rng = np.random.default_rng(5)
    tabs = [noisy(cut(exact_table("cw", gear, "planets"), 7.5), NOISE, rng)
            for gear in ("sun", "ring")]
    res = identify_errors(tabs, g, gears=("planet",), pass_offset_std=0.0)
    sugg = {s["gear"]: s for s in res.suggestions}
    assert {s["option"] for s in sugg.values()} == {
        "add a second ring gauge a quarter turn from the first"}
    second = noisy(cut(exact_table("cw", "ring", "planets", tooth=-0.02 + math.pi / 2), 7.5),
                   NOISE, rng)
    both = identify_errors([*tabs, second], g, gears=("planet",), pass_offset_std=0.0)
    assert both.identifiable and both.rank == 8
    for gear, s in sugg.items():
        got = max(both.parameters[f"{gear}_x"][1], both.parameters[f"{gear}_y"][1])
        assert s["predicted_std"] / 1.5 < got < s["predicted_std"] * 1.5, (gear, s, got)


def test_blind_offsets_have_no_option():
    # the sun and ring offsets: no extra gauge or longer record tried identifies them
    res = identify_errors([cut(exact_table("cw", gear, "all"), 10.0) for gear in ("sun", "ring")],
                          gearset("cw"))
    sugg = {s["gear"]: s for s in res.suggestions}
    for gear in ("sun", "ring"):
        assert sugg[gear]["option"] is None and sugg[gear]["record_option"] is None
        assert math.isnan(sugg[gear]["predicted_std"])
        assert len(sugg[gear]["tried"]) == 8 and "none of the options tried" in sugg[gear]["note"]
    # suggest=False: the same fit without them
    quiet = identify_errors([cut(exact_table("cw", gear, "all"), 10.0) for gear in ("sun", "ring")],
                            gearset("cw"), suggest=False)
    assert quiet.suggestions == [] and quiet.rank == res.rank
    np.testing.assert_array_equal(quiet.singular_values, res.singular_values)


# ----------------------------------------------------------------------------- describe

def test_describe_combination_names_directions():
    g = gearset("cw")                         # planets at 0, 90, 180, 270 deg
    names = ["sun_x", "sun_y", "planet1_x", "planet1_y", "planet2_x", "planet2_y"]
    s = 1 / math.sqrt(2)
    text = describe_combination([s, 0.0, -s, 0.0, 0.0, 0.0], names, g)
    assert text == "0.71 sun offset towards planet 1 - 0.71 planet 1 radial offset (towards the sun)"
    # the sun along -y is against planet 4's line (270 deg): towards planet 4 with +
    assert describe_combination([0.0, -1.0, 0, 0, 0, 0], names, g) == "1.00 sun offset towards planet 4"
    assert describe_combination([0, 0, 0, 0, 0.0, -1.0], names, g) == "-1.00 planet 2 tangential offset"
    text = describe_combination([0, 0, 0, 0, 0.6, 0.8], names, g)
    assert text == "1.00 planet 2 offset at 53 deg from its inward radial"
    text = describe_combination([0.999, 0.0, 0.04, 0.0, 0.0, 0.0], names, g)
    assert text == "1.00 sun offset towards planet 1 (+ smaller terms)"


def test_describe_combination_empty_and_bad():
    g = gearset("cw")
    assert describe_combination([], [], g) == "0"
    with pytest.raises(ValueError, match="one entry per name"):
        describe_combination([1.0, 0.0], ["sun_x"], g)
    with pytest.raises(ValueError, match="finite"):
        describe_combination([float("nan")], ["sun_x"], g)
    with pytest.raises(ValueError, match="unknown parameter name"):
        describe_combination([1.0], ["carrier_x"], g)
    with pytest.raises(TypeError, match="Gearset"):
        describe_combination([1.0], ["sun_x"], {"z_sun": 25})


# ----------------------------------------------------------------------------- verdict

def test_verdict_carries_the_key_numbers():
    res = identify_errors([exact_table("cw", gear, "all") for gear in ("sun", "ring")],
                          gearset("cw"))
    speeds = {"text": "ring held; sun 22.4 r/min", "carrier": 5.0}
    text = identification_verdict(res, speeds)
    assert "no single offset is identified" in text
    assert f"from {res.rms_before:.3g} to {res.rms_after:.3g} mesh cycles" in text
    assert f"determine {res.rank} combination(s) of the 12 offset components." in text
    best = res.combinations[0]
    assert f"= {best['estimate'] * 1e3:.4g} mm (95 % interval" in text
    assert "No extra gauge or longer record tried identifies sun, ring" in text
    assert text.endswith("Member speeds: ring held; sun 22.4 r/min.")


def test_verdict_empty_and_bad():
    assert identification_verdict(None) == ("No shaft hole errors were identified (the identify "
                                            "stage did not run).")
    empty = Identification(None, [], {}, np.empty(0), float("nan"), float("nan"), float("nan"),
                           0, 12, 0, 0.0, False)
    assert "there are no measured passes" in identification_verdict(empty)
    with pytest.raises(TypeError, match="Identification"):
        identification_verdict({"rank": 3})
    with pytest.raises(TypeError, match="member_speeds"):
        identification_verdict(None, "18 r/min")


def test_no_tables_has_no_combinations():
    with pytest.warns(Warning, match="no measured passes"):
        res = identify_errors([], gearset("cw"))
    assert res.combinations == [] and res.suggestions == [] and res.rank == 0
    assert res.true_combinations(ERRORS["all"]).size == 0
    with pytest.raises(TypeError, match="ShaftHoleErrors"):
        res.true_combinations({"e_sun": 1e-4})
