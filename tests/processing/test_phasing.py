"""Measured phasing from onset times (meshphase.kinematics.phasing), on pass trains with known truth.

The truth here is spec section 1 (ideal phasing, gamma_sn = frac(+-Z_s psi_n / 2 pi),
gamma_rn = frac(-+Z_r psi_n / 2 pi)) evaluated by hand, so a sign slip in the measured
formula shows up as a mismatch on one gear or one direction.
"""

import math
import warnings

import numpy as np
import pytest
from hypothesis import given, strategies as st

from meshphase.errors import ProcessingWarning
from meshphase.kinematics.pass_table import PassTable, measured_phasing, pass_order, planet_fractions
from meshphase.kinematics.planet_labels import (TachoRelabel, assign_planets_by_pattern,
                                                assign_planets_by_tacho, relabel_by_tacho)
from meshphase.kinematics.trains import revolution_numbers

TWO_PI = 2 * math.pi


def ideal(z_s, z_r, psi, direction):
    s = 1 if direction == "cw" else -1
    return (s * z_s * psi / TWO_PI) % 1.0, (-s * z_r * psi / TWO_PI) % 1.0


def pass_train(psi, order, n_rev, angle_of_time=None, period=1.0):
    """Times at which a gauge meets each planet; angle_of_time maps relative angle [rev] ->
    time (identity scaled by `period` for constant speed)."""
    frac = planet_fractions(psi, order)
    rev = (np.arange(n_rev)[:, None] + frac[None, :]).ravel()
    lab = np.tile(np.arange(psi.size), n_rev)
    o = np.argsort(rev, kind="stable")
    rev, lab = rev[o], lab[o]
    t = rev * period if angle_of_time is None else angle_of_time(rev)
    return t, lab


def circ_err(a, b):
    return np.abs((np.asarray(a) - np.asarray(b) + 0.5) % 1.0 - 0.5)


@pytest.mark.parametrize("direction", ["cw", "ccw"])
@pytest.mark.parametrize("gauge", ["sun", "ring"])
def test_measured_equals_section1_both_gears_both_directions(direction, gauge):
    z_s, z_r, n = 25, 87, 4
    psi = TWO_PI * np.arange(n) / n
    order = pass_order(direction, gauge)
    t, lab = pass_train(psi, order, 12, period=0.37)
    planet, info = assign_planets_by_pattern(t, psi, order)
    np.testing.assert_array_equal(planet, lab)
    z = z_s if gauge == "sun" else z_r
    tab = measured_phasing(t, planet, z, n, gauge=gauge)
    g_s, g_r = ideal(z_s, z_r, psi, direction)
    want = (g_s if gauge == "sun" else g_r)[tab.planet - 1]
    assert circ_err(tab.gamma, want).max() < 1e-9
    assert set(tab.planet) == {2, 3, 4}


@given(st.integers(12, 60), st.integers(3, 6), st.sampled_from(["cw", "ccw"]),
       st.sampled_from(["sun", "ring"]), st.integers(0, 10_000))
def test_property_assemblable_layouts_measure_ideal(z_s, n, direction, gauge, seed):
    # assemblable unequal layout: psi_n = 2 pi p_n / (Z_s + Z_r) with distinct p_n
    rng = np.random.default_rng(seed)
    z_r = z_s + 2 * rng.integers(8, 40)
    zt = z_s + z_r
    if zt < 4 * n:
        return
    p = np.sort(rng.choice(np.arange(1, zt), size=n - 1, replace=False))
    psi = TWO_PI * np.concatenate([[0], p]) / zt
    order = pass_order(direction, gauge)
    t, lab = pass_train(psi, order, 6, period=2.0)
    z = z_s if gauge == "sun" else z_r
    tab = measured_phasing(t, lab, z, n, gauge=gauge)
    g_s, g_r = ideal(z_s, z_r, psi, direction)
    assert circ_err(tab.gamma, (g_s if gauge == "sun" else g_r)[tab.planet - 1]).max() < 1e-7
    # the assemblability invariant seen on the measured side: sun and ring phasing agree
    assert circ_err(g_s, g_r).max() < 1e-9


def test_speed_ramp_is_followed_not_nominal_speed():
    # relative angle theta(t) = w0 t + a t^2 / 2 : speed up 40 % over the record
    z_s, n = 25, 4
    psi = TWO_PI * np.arange(n) / n
    w0, a = 1.0, 0.02  # [rev/s], [rev/s^2]
    inv = lambda rev: (-w0 + np.sqrt(w0 ** 2 + 2 * a * rev)) / a
    t, lab = pass_train(psi, 1, 20, angle_of_time=inv)
    tab = measured_phasing(t, lab, z_s, n, gauge="sun")
    want = ideal(z_s, 87, psi, "cw")[0][tab.planet - 1]
    # pchip through the planet-1 knots follows a quadratic angle to ~1e-4 of a revolution
    # inside; Z_s amplifies it 25x: 5e-3 mesh cycles bound at the ends, far below nominal
    # speed's error (0.3 mesh cycles at the end of the ramp)
    assert circ_err(tab.gamma, want).max() < 5e-3
    nominal = (z_s * (t - np.floor(t)) ) % 1.0  # what assuming the start speed gives
    assert circ_err(nominal[lab > 0][-5:], want[-5:]).max() > 0.05


def test_missing_pulse_is_skipped_and_a_pass_without_reference_dropped():
    z_s, n = 25, 4
    psi = TWO_PI * np.arange(n) / n
    t, lab = pass_train(psi, 1, 15)
    drop = [9, 20, 21]  # a planet-2 pulse and a planet-1 + planet-2 pair (a gap)
    keep = np.setdiff1d(np.arange(t.size), drop)
    t, lab = t[keep], lab[keep]
    planet, info = assign_planets_by_pattern(t, psi, 1)
    np.testing.assert_array_equal(planet, lab)
    tab = measured_phasing(t, planet, z_s, n)
    assert circ_err(tab.gamma, ideal(z_s, 87, psi, "cw")[0][tab.planet - 1]).max() < 1e-9
    # revolution 5 lost its planet-1 pass: its planets 3 and 4 are dropped, not bridged
    assert any("without the planet-1 pass" in s for s in tab.notes)
    assert len(tab) == 15 * 3 - 2 - 2
    # the planet-1 pass each row is measured against: its own revolution's
    assert np.all(np.isfinite(tab.ref_time))
    assert np.all(tab.ref_time <= tab.time) and np.all(tab.time - tab.ref_time < 1.0)


def test_unequal_spacing_fixes_planet_one_from_the_pattern():
    z_s, z_r = 25, 87
    psi = TWO_PI * np.array([0, 27, 55, 84]) / 112  # assemblable, unequal
    t, lab = pass_train(psi, 1, 8)
    t, lab = t[2:], lab[2:]  # start mid-revolution: first onset is planet 3
    planet, info = assign_planets_by_pattern(t, psi, 1)
    assert info["shift_decided_by"] == "pattern" and not info["ambiguous"]
    np.testing.assert_array_equal(planet, lab)


def test_symmetric_layout_shift_from_amplitudes():
    psi = TWO_PI * np.arange(4) / 4
    t, lab = pass_train(psi, 1, 8)
    t, lab = t[1:], lab[1:]  # first onset is planet 2
    load = np.array([1.2, 0.9, 1.0, 0.9])
    amp = load[lab]
    planet, info = assign_planets_by_pattern(t, psi, 1, amplitudes=amp, reference_amplitudes=load)
    assert info["shift_decided_by"] == "amplitude"
    np.testing.assert_array_equal(planet, lab)
    # without amplitudes the shift is ambiguous and says so
    _, info2 = assign_planets_by_pattern(t, psi, 1)
    assert info2["ambiguous"]


def test_tacho_assignment_ring_gauge():
    psi = TWO_PI * np.arange(3) / 3
    w_c = 0.5  # carrier [rev/s], ring fixed -> ring turns -w_c relative to the carrier
    gauge_angle = 0.3  # [rad]
    tacho = np.arange(0, 12) / w_c
    # planet n passes the gauge when theta_c + psi_n = gauge_angle (mod 2 pi)
    rev = ((gauge_angle - psi) / TWO_PI) % 1.0
    tt = ((np.arange(11)[:, None] + rev[None, :]) / w_c).ravel()
    lab = np.tile(np.arange(3), 11)
    o = np.argsort(tt)
    planet = assign_planets_by_tacho(tt[o], tacho, psi, gauge_angle, 1)
    np.testing.assert_array_equal(planet, lab[o])
    tab = measured_phasing(tt[o], planet, 87, 3, gauge="ring", reference_times=tacho)
    want = ideal(25, 87, psi, "cw")[1][tab.planet - 1]
    assert circ_err(tab.gamma, want).max() < 1e-9


def test_uncertainty_propagation():
    z_s, n = 25, 4
    psi = TWO_PI * np.arange(n) / n
    t, lab = pass_train(psi, 1, 10, period=2.0)
    tab = measured_phasing(t, lab, z_s, n, sigma_t=1e-3)
    # the two onsets' timing bounds: Z |w| / (2 pi) * sqrt(sigma_n^2 + sigma_ref^2) exactly
    # (the angle model is exact on this uniform train: its rate is the true rate to ~1e-12)
    want = z_s * (1 / 2.0) * math.sqrt(2) * 1e-3
    np.testing.assert_allclose(tab.timing_floor, want, rtol=1e-9)
    # the total adds the angle model's own uncertainty: a fitted angle from 40 passes
    # carries a fraction of one pass's timing error, so a few percent more, never less
    assert np.all(tab.uncertainty >= tab.timing_floor)
    assert np.all(tab.uncertainty <= 1.15 * tab.timing_floor)
    np.testing.assert_allclose(tab.uncertainty, np.hypot(tab.timing_floor, tab.model_sigma), rtol=1e-12)
    np.testing.assert_allclose(tab.mesh_period, 2.0 / z_s, rtol=1e-9)


def test_revolution_numbers_bridge_missing():
    t = np.array([0, 1, 2, 4, 5, 8.02])
    np.testing.assert_array_equal(revolution_numbers(t), [0, 1, 2, 4, 5, 8])
    assert revolution_numbers([]).size == 0
    with pytest.raises(ValueError, match="strictly increasing"):
        revolution_numbers([0, 1, 1])


def test_empty_inputs_give_empty_tables():
    tab = measured_phasing([], np.array([], dtype=int), 25, 4)
    assert isinstance(tab, PassTable) and len(tab) == 0
    planet, info = assign_planets_by_pattern([], np.arange(4.0), 1)
    assert planet.size == 0
    assert assign_planets_by_tacho([], [0, 1], np.arange(3.0), 0.0, 1).size == 0
    assert list(tab.to_dataframe().columns) == ["gauge", "time_s", "planet", "revolution", "gamma",
                                                "uncertainty", "mesh_period_s", "ref_time_s",
                                                "angle_rad", "timing_floor", "model_sigma"]


def test_no_planet1_passes_warns_and_returns_empty():
    with pytest.warns(ProcessingWarning, match="fewer than two reference passes"):
        tab = measured_phasing([0.1, 0.2, 0.3], np.array([1, 2, 3]), 25, 4)
    assert len(tab) == 0


@pytest.mark.parametrize("kwargs, exc, match", [
    (dict(times=[0.0, 1.0], planets=np.array([0]), z_gear=25, n_planets=4), ValueError, "shape"),
    (dict(times=[0.0, np.nan], planets=np.array([0, 1]), z_gear=25, n_planets=4), ValueError, "finite"),
    (dict(times=[0.0, 1.0], planets=np.array([0, 1]), z_gear=-3, n_planets=4), ValueError, "z_gear"),
    (dict(times=[0.0, 1.0], planets=np.array([0, 7]), z_gear=25, n_planets=4), ValueError, "planets"),
    (dict(times=[1.0, 0.0], planets=np.array([0, 1]), z_gear=25, n_planets=4), ValueError, "sorted"),
    (dict(times=[0.0, 1.0], planets=np.array([0.0, 1.0]), z_gear=25, n_planets=4), TypeError, "integers"),
])
def test_bad_inputs(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        measured_phasing(**kwargs)


def test_bad_pass_order_args():
    with pytest.raises(ValueError, match="gauge"):
        pass_order("cw", "planet")
    with pytest.raises(ValueError, match="direction"):
        pass_order("up", "sun")
    with pytest.raises(ValueError, match="order"):
        planet_fractions([0.0, 1.0], 0)
    with pytest.raises(ValueError, match="tacho"):
        assign_planets_by_tacho([0.5], [0.0], np.arange(3.0), 0.0, 1)


# ----------------------------------------------------------------------------- tacho relabelling
def _held_ring_passes(gauge_angle=3.0):
    """A 3-planet ring gauge on a held ring, carrier counter-clockwise at 0.5 rev/s: pass
    times, true 0-based planets, tacho edges (key at planet 1)."""
    psi = TWO_PI * np.arange(3) / 3
    w_c = 0.5
    tacho = np.arange(0, 12) / w_c
    rev = ((gauge_angle - psi) / TWO_PI) % 1.0
    tt = ((np.arange(11)[:, None] + rev[None, :]) / w_c).ravel()
    lab = np.tile(np.arange(3), 11)
    o = np.argsort(tt)
    return psi, tt[o], lab[o], tacho


def test_relabel_by_tacho_names_planet_one_of_the_pattern_labels():
    psi, t, truth, tacho = _held_ring_passes()
    order = pass_order("cw", "ring")
    pl, info = assign_planets_by_pattern(t, psi, order)
    assert info["ambiguous"] and not np.array_equal(pl, truth)   # the pattern alone: relative
    v = relabel_by_tacho(t, pl, info["position"], tacho, psi, 3.0, pass_order=order,
                         carrier_sense=1)
    assert isinstance(v, TachoRelabel) and v.accepted
    assert v.compared == v.agree == t.size and v.shift > 0
    np.testing.assert_array_equal(v.planet, truth)
    np.testing.assert_array_equal(v.position - info["position"], v.shift)


def test_relabel_by_tacho_keeps_labels_the_tacho_does_not_back():
    psi, t, truth, tacho = _held_ring_passes()
    pl = np.random.default_rng(2).integers(0, 3, t.size)     # labels that follow no pattern
    pos = np.arange(t.size)
    v = relabel_by_tacho(t, pl, pos, tacho, psi, 3.0, pass_order=-1, carrier_sense=1)
    assert not v.accepted and v.compared == t.size and v.agree < 0.8 * t.size
    assert v.planet is pl and v.position is pos
    # a stricter or looser share decides the same votes differently
    assert relabel_by_tacho(t, pl, pos, tacho, psi, 3.0, pass_order=-1, carrier_sense=1,
                            agreement=v.agree / t.size).accepted


def test_relabel_by_tacho_empty_and_bad_input():
    psi, t, truth, tacho = _held_ring_passes()
    e = np.empty(0)
    v = relabel_by_tacho(e, e.astype(int), e.astype(int), tacho, psi, 3.0, pass_order=-1,
                         carrier_sense=1)
    assert not v.accepted and v.compared == 0 and v.shift == -1 and v.planet.size == 0
    unlabelled = np.full(t.size, -1)
    assert relabel_by_tacho(t, unlabelled, np.arange(t.size), tacho, psi, 3.0, pass_order=-1,
                            carrier_sense=1).compared == 0
    with pytest.raises(ValueError, match="shape of times"):
        relabel_by_tacho(t, truth[:-1], np.arange(t.size), tacho, psi, 3.0, pass_order=-1,
                         carrier_sense=1)
    with pytest.raises(ValueError, match="agreement"):
        relabel_by_tacho(t, truth, np.arange(t.size), tacho, psi, 3.0, pass_order=-1,
                         carrier_sense=1, agreement=0.0)
    with pytest.raises(ValueError, match="tacho"):
        relabel_by_tacho(t, truth, np.arange(t.size), tacho[:1], psi, 3.0, pass_order=-1,
                         carrier_sense=1)


def _walk_loop(gaps, fs, q0, tol):
    # the pass-order walk as one loop over the gaps (the definition _walk vectorises)
    n = fs.size
    fs_closed = np.concatenate([fs, [1.0]])
    pos = np.empty(gaps.size + 1, dtype=np.int64)
    ok = np.ones(gaps.size + 1, dtype=bool)
    p = pos[0] = q0
    total = 0.0
    for i, g in enumerate(gaps, start=1):
        target = fs[p % n] + g
        whole = math.floor(target)
        rest = target - whole
        q = int(np.argmin(np.abs(fs_closed - rest)))
        miss = abs(fs_closed[q] - rest)
        total += miss
        adv = whole * n + q - (p % n)
        if adv <= 0 or miss > tol:
            ok[i] = False
            adv = max(1, adv)
        p += adv
        pos[i] = p
    return pos, ok, total


@given(st.integers(1, 7), st.booleans(), st.integers(0, 300), st.integers(0, 2**32 - 1),
       st.sampled_from([1, 2, 7, 64, 4096]))
def test_walk_equals_the_loop_over_gaps(n, equal, m, seed, chunk):
    # positions, flags and the summed mismatch to the bit, on trains with missing pulses
    # (double gaps), extra ones (half gaps), slow drift and unequal spacing, the gaps worked
    # out in chunks of every size (the walk carries its place and sum across them)
    from meshphase.kinematics import planet_labels
    from meshphase.kinematics.planet_labels import _walk

    before = planet_labels._WALK_CHUNK
    planet_labels._WALK_CHUNK = chunk
    try:
        _check_walk(n, equal, m, seed, _walk)
    finally:
        planet_labels._WALK_CHUNK = before


def _check_walk(n, equal, m, seed, _walk):
    rng = np.random.default_rng(seed)
    fs = np.arange(n) / n if equal else np.concatenate([[0.0], np.sort(rng.uniform(0, 1, n - 1))])
    gaps = np.abs(rng.normal(1.0 / n, 0.2 / n, m)) * rng.choice([1, 1, 1, 2, 0.5, 3], m)
    q0 = int(rng.integers(0, n))
    tol = 0.3 * float(np.diff(np.concatenate([fs, [1.0]])).min())
    got, want = _walk(gaps, fs, q0, tol), _walk_loop(gaps, fs, q0, tol)
    np.testing.assert_array_equal(got[0], want[0])
    np.testing.assert_array_equal(got[1], want[1])
    assert got[2] == want[2]


def test_walk_empty_and_bad_gaps():
    from meshphase.kinematics.planet_labels import _walk

    pos, ok, total = _walk(np.empty(0), np.array([0.0, 0.5]), 1, 0.1)
    assert pos.tolist() == [1] and ok.tolist() == [True] and total == 0.0
    with pytest.raises(ValueError, match="finite"):
        _walk(np.array([0.5, np.inf]), np.array([0.0, 0.5]), 0, 0.1)


def test_model_choice_reasons_follow_the_verdicts_rule():
    # an inseparable pair that counts is always named (with no timing floor to compare to);
    # a weighed competitor only where the estimated error with the model choice passes 3x
    # the floor; nothing from an empty list
    from meshphase.kinematics.reliability import choice_reasons

    insep = {"words": "a common speed ripple at the planet spin rate",
             "versus": "equal shaft-hole errors on every planet", "inseparable": True,
             "counted": True, "rms": 0.05, "delta_bic": 0.0, "weight": float("nan"),
             "ripple_bound": 0.092}
    weighed = {"words": "a speed ripple at the carrier rate to harmonic 2",
               "versus": "the chosen model",
               "inseparable": False, "counted": True, "rms": 0.004, "delta_bic": 1.0,
               "weight": 0.3, "ripple_bound": float("nan")}
    assert choice_reasons([], 0.002, 0.01) == []
    for floor in (0.002, float("nan")):
        why = choice_reasons([insep], floor, 0.05)
        assert len(why) == 1 and "shaft encoder" in why[0] and "0.092" in why[0]
    assert choice_reasons([dict(insep, counted=False)], 0.002, 0.05) == []
    assert choice_reasons([weighed], 0.002, 0.0059) == []          # 2.95x the floor
    why = choice_reasons([weighed], 0.002, 0.0061)
    assert len(why) == 1 and "posterior weight 0.30" in why[0]
