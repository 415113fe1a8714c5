"""Planet labels by load pattern that survive a load variation with the carrier's phase.

A torque ripple once per carrier turn scales every planet's pulses by one function of the
carrier angle; a ring gauge on the held ring meets each planet at one carrier angle, so its
per-planet amplitudes are the loads times that function there, and matching them against the
sun gauge's named the sun's planet 1 one planet off with "ambiguous False". Here the sun
gauge measures the variation (:func:`meshphase.kinematics.label_checks.carrier_load_variation`), the ring's
loads are divided by it and must match the sun's under one labelling clearly
(:func:`meshphase.kinematics.label_checks.load_shift_chi2`), else the labels are relative with a caution.

The recordings are the independent rig's engagement instants (tests/independent/rig.py, no
code shared with the package) with pulse amplitudes of 1 % noise: the labelling logic
alone, a second each; tests/independent/test_labels_on_rig.py runs whole TDMS files.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from meshphase.models.gearset import Gearset
from meshphase.kinematics.label_checks import carrier_load_variation, load_shift_chi2
from meshphase.kinematics.phasing import measure_phasing
from meshphase.kinematics.planet_labels import GaugePasses
from independent import rig as R

TWO_PI = 2.0 * math.pi


# ----------------------------------------------------------------------------- carrier_load_variation
def _pulses(n_pulses=400, n=4, a=0.25, phase0=0.7, noise=0.02, seed=0):
    rng = np.random.default_rng(seed)
    ph = rng.uniform(0.0, 10 * TWO_PI, n_pulses)
    place = rng.integers(0, n, n_pulses)
    loads = np.array([1.1, 0.9, 1.05, 0.95, 1.0][:n])
    amp = loads[place] * (1 + a * np.cos(ph + phase0)) * (1 + noise * rng.standard_normal(n_pulses))
    return ph, amp, place, loads


def test_carrier_load_variation_separates_the_variation_from_the_loads():
    ph, amp, place, loads = _pulses()
    lv = carrier_load_variation(ph, amp, place, 4)
    assert lv is not None and lv.n_pulses == 400
    # 2 % amplitude noise over 400 pulses: the swing's standard error is about 0.002, the
    # loads' about 0.002 each; 0.01 is five of them
    assert lv.swing == pytest.approx(0.25, abs=0.01)
    d = lv.log_loads - np.log(loads)
    assert np.ptp(d) < 0.01
    assert np.all(lv.log_loads_se < 0.005)
    # the fitted factor at a phase is the one applied there (1 + a cos: its log, orders 1-2)
    f, se = lv.log_factor(np.array([-0.7, math.pi - 0.7]))
    assert np.exp(f[0] - f[1]) == pytest.approx(1.25 / 0.75, rel=0.03)
    assert np.all(se > 0)
    # far beyond chance: a Wald statistic of 4 degrees of freedom
    assert lv.chi2 > 100
    f, se = lv.log_factor([])
    assert f.shape == se.shape == (0,)
    with pytest.raises((TypeError, ValueError)):
        lv.log_factor("a")


def test_carrier_load_variation_finds_none_where_there_is_none():
    ph, amp, place, _ = _pulses(a=0.0)
    lv = carrier_load_variation(ph, amp, place, 4)
    # 99.9 % quantile of chi-square with 4 degrees of freedom: 18.5
    assert lv.chi2 < 18.5 and lv.swing < 0.01


def test_carrier_load_variation_empty_and_too_few_pulses_give_none():
    assert carrier_load_variation([], [], [], 4) is None
    ph, amp, place, _ = _pulses(n_pulses=15)
    assert carrier_load_variation(ph, amp, place, 4) is None      # 15 < 2 x 8 parameters
    ph, amp, place, _ = _pulses()
    assert carrier_load_variation(np.zeros(ph.size), amp, place, 4) is None  # one phase only
    assert carrier_load_variation(ph, amp, np.where(place == 3, 2, place), 4) is None  # no place 3


def test_carrier_load_variation_bad_input_names_the_parameter():
    ph, amp, place, _ = _pulses()
    with pytest.raises(ValueError, match="one value per pulse"):
        carrier_load_variation(ph, amp[:-1], place, 4)
    with pytest.raises(ValueError, match=r"place must hold integers 0\.\.3"):
        carrier_load_variation(ph, amp, place + 1, 4)
    with pytest.raises(ValueError, match="amplitudes must be non-zero"):
        carrier_load_variation(ph, np.where(place == 0, 0.0, amp), place, 4)
    with pytest.raises(ValueError, match="phase"):
        carrier_load_variation(np.full(ph.size, np.nan), amp, place, 4)
    with pytest.raises(ValueError, match="n_places"):
        carrier_load_variation(ph, amp, place, 0)
    with pytest.raises(ValueError, match="orders"):
        carrier_load_variation(ph, amp, place, 4, orders=())


# ----------------------------------------------------------------------------- load_shift_chi2
def test_load_shift_chi2_is_smallest_at_the_labelling_that_matches():
    seq = np.array([0, 3, 2, 1])                  # planets in pass order
    ring = np.log([1.2, 0.9, 1.0, 0.95])          # per planet
    sun = ring[seq[(np.arange(4) + 2) % 4]] + 0.3  # places named with shift 2, another scale
    chi2 = load_shift_chi2(sun, np.full(4, 0.01), ring, np.full(4, 0.01), seq)
    assert chi2.shape == (4,)
    assert int(np.argmin(chi2)) == 2 and chi2[2] == pytest.approx(0.0, abs=1e-9)
    assert np.sort(chi2)[1] > 25                  # the other labellings misfit by far


def test_load_shift_chi2_empty_and_bad_input():
    assert load_shift_chi2([], [], [], [], []).shape == (0,)
    with pytest.raises(ValueError, match="one value per planet"):
        load_shift_chi2([0, 0], [1, 1], [0, 0, 0], [1, 1, 1], [0, 1])
    with pytest.raises(ValueError, match="standard errors must be positive"):
        load_shift_chi2([0, 0], [0, 1], [0, 0], [1, 1], [0, 1])
    with pytest.raises(ValueError, match="seq must be a permutation"):
        load_shift_chi2([0, 0], [1, 1], [0, 0], [1, 1], [1, 1])
    with pytest.raises(ValueError, match="reference"):
        load_shift_chi2([0, 0], [1, 1], [0, np.inf], [1, 1], [0, 1])


# ----------------------------------------------------------------------------- measure_phasing
def _measure(*, load_modulation=(), load_sharing=None, seed=1, label_shifts=None, **rig_kw):
    """Labels of measure_phasing on the independent rig's engagement instants (2 min, ring
    held, tacho geometry given), pulse amplitudes the rig's gains with 1 % noise; returns
    (PhasingResult, {gear: true 0-based planet per pulse})."""
    cfg = R.make_rig_config(minutes=2.0, seed=seed, snr_db=None, load_modulation=load_modulation,
                            load_sharing=load_sharing, **rig_kw)
    rig = R.Rig(cfg)
    g = cfg.gearset
    gs = Gearset(g.z_sun, g.z_ring, g.z_planet, tuple(g.planet_angles), g.carrier_radius,
                 direction=rig.kinematics.planet_rotation)
    rng = np.random.default_rng(seed)
    passes, truth = [], {}
    sig = 2e-5
    for gear in ("ring", "sun"):
        t, p = rig.engagements(gear)
        amp = rig.amp_factor[p - 1] * rig.load_factor(t) * (1 + 0.01 * rng.standard_normal(t.size))
        passes.append(GaugePasses(gear, gear, t + rng.normal(0.0, sig, t.size), amp,
                                  np.full(t.size, sig)))
        truth[gear] = p - 1
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ph = measure_phasing(passes, gs, fixed="ring", tacho_times=rig.tacho_edges,
                             key_angle=float(np.mod(-cfg.tacho_edge_angle, TWO_PI)),
                             mounts={"ring": cfg.ring_gauge_angle}, label_shifts=label_shifts)
    return ph, truth


def _right(ph, truth, gear) -> float:
    lab = ph.labels[gear]
    ok = lab.planet >= 0
    return float(np.mean(lab.planet[ok] == truth[gear][ok]))


MODULATED = {
    "4 planets, phase 0": dict(load_modulation=((0.25, 1, 0.0),)),
    "4 planets, phase 2": dict(load_modulation=((0.25, 1, 2.0),), seed=2),
    "4 planets, phase 4, ccw": dict(load_modulation=((0.25, 1, 4.0),), sun_rpm=-18.19),
    "5 planets": dict(load_modulation=((0.25, 1, 1.0),), z=(25, 85, 30), planets=5,
                      carrier_radius=0.110),
}


@pytest.mark.parametrize("case", list(MODULATED))
def test_equal_loads_under_a_carrier_rate_load_variation_name_no_planet(case):
    # the ring gauge's per-planet loads differ by +-25 % through the variation alone: before,
    # they named the sun's planet 1 (often wrongly) with ambiguous False
    ph, truth = _measure(**MODULATED[case])
    assert _right(ph, truth, "ring") == 1.0 and ph.labels["ring"].decided_by == "tacho"
    sun = ph.labels["sun"]
    assert sun.decided_by == "first pulse" and "sun" in ph.labels_relative
    # the loads as the ring sees them named planet 1 in every case here: said why not
    assert "load variation of +-2" in sun.caution and "carrier's phase" in sun.caution


@pytest.mark.parametrize("case", list(MODULATED))
def test_unequal_loads_under_a_carrier_rate_load_variation_name_the_right_planet(case):
    kw = dict(MODULATED[case])
    n = 5 if "5" in case else 4
    ph, truth = _measure(load_sharing=(1.15, 0.9, 1.0, 0.95, 1.0)[:n], **kw)
    sun = ph.labels["sun"]
    assert sun.decided_by == "amplitude" and not sun.caution and "sun" not in ph.labels_relative
    assert _right(ph, truth, "sun") == 1.0


def test_unequal_spacing_under_a_load_variation_keeps_the_pattern():
    ph, truth = _measure(load_modulation=((0.25, 1, 0.5),), planets={"positions": (0, 37, 75)})
    assert ph.labels["sun"].decided_by == "pattern" and _right(ph, truth, "sun") == 1.0


def test_without_a_load_variation_the_labels_are_as_before():
    # equal loads: relative, no caution; unequal loads: by amplitude, right
    ph, _ = _measure()
    assert ph.labels["sun"].decided_by == "first pulse" and not ph.labels["sun"].caution
    ph, truth = _measure(load_sharing=(1.15, 0.9, 1.0, 0.95))
    assert ph.labels["sun"].decided_by == "amplitude" and _right(ph, truth, "sun") == 1.0


def test_load_pattern_and_planet_offsets_that_disagree_are_reported(monkeypatch):
    # the planets' own offsets (label_shift_costs) name the sun's planet 1 one place on from
    # where the loads name it: the labels follow the offsets, are relative, and say why
    import meshphase.kinematics.label_checks as checks

    monkeypatch.setattr(checks, "label_shift_costs",
                        lambda refs, tr, frac, kin, n: np.array([1e4, 10.0, 1e4, 1e4]))
    ph, truth = _measure(load_sharing=(1.15, 0.9, 1.0, 0.95))
    sun = ph.labels["sun"]
    assert sun.caution.startswith("the sun's labels by load pattern and the ring's by tacho "
                                  "disagree by one planet: the planets' own offsets")
    assert "sun" in ph.labels_relative
    assert _right(ph, truth, "sun") == 0.0       # moved by the offsets, one planet off


def test_a_scene_shift_pins_the_labels():
    # each shift names another pulse planet 1; exactly one of them is the truth's, and the
    # pinned labels are absolute whatever the loads say
    right = []
    for k in range(4):
        ph, truth = _measure(load_modulation=((0.25, 1, 0.0),), label_shifts={"sun": k})
        assert ph.labels["sun"].decided_by == "scene" and "sun" not in ph.labels_relative
        right.append(_right(ph, truth, "sun"))
    assert sorted(right) == [0.0, 0.0, 0.0, 1.0]


@pytest.mark.slow
@pytest.mark.parametrize("spread", [0.01, 0.02, 0.04, 0.08])
@pytest.mark.parametrize("mod", [0.0, 0.25])
def test_never_a_confident_wrong_planet_over_seeds(spread, mod):
    # six seeds, each with its own phase of the variation: labels taken as absolute are the
    # truth's; with loads 2 % apart or more (1 % pulse noise) they are always taken
    right = []
    for seed in range(1, 7):
        ph, truth = _measure(load_sharing=(1 + spread, 1 - spread, 1.0, 1 - spread / 2),
                             seed=seed, load_modulation=((mod, 1, float(seed)),) if mod else ())
        sun = ph.labels["sun"]
        if sun.decided_by != "first pulse" and not sun.caution:
            assert _right(ph, truth, "sun") == 1.0, seed
            right.append(seed)
    if spread >= 0.02:
        assert len(right) == 6


@pytest.mark.parametrize("q,dof", [(0.999, 1), (0.999, 3), (0.999, 4), (0.95, 2), (0.5, 10)])
def test_chi2_quantile_is_scipy_stats(q, dof):
    # the label check's chi-square quantile without importing scipy.stats: the same function
    # (inverse regularised gamma); 1e-12 relative, the two paths' rounding
    from scipy import stats

    from meshphase.kinematics.label_checks import _chi2_quantile
    assert _chi2_quantile(q, dof) == pytest.approx(float(stats.chi2.ppf(q, dof)), rel=1e-12)
