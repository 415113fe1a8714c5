"""Can the gearset be built: coaxiality and planet tip clearance in tooth counts
(meshphase.models.assembly).

Reference conditions: coaxial standard gears Z_r = Z_s + 2 Z_p; N equally spaced planets clear
when (Z_s + Z_p) sin(pi / N) > Z_p + 2 (tip diameter m (Z_p + 2), e.g. Lynwander, Gear Drive
Systems, 1983, ch. 5). Numbers for the seed gearsets from meshphase.synthetic/scenarios.py's docstring.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from meshphase.models.assembly import (CLEARANCE_ATOL, assemblable_planet_counts, coaxiality_error,
                                       max_equal_planets, tip_clearance)


def _equal(n):
    return 2 * math.pi * np.arange(n) / n


def test_coaxiality_of_the_seed_gearsets():
    assert coaxiality_error(25, 87, 31) == 0        # the seed rig as modelled (Z_p = 31)
    assert coaxiality_error(25, 87, 29) == 4        # seed 000 Table 1: profile shift needed
    assert coaxiality_error(25, 85, 30) == 0        # rig_5planets


def test_tip_clearance_of_the_seed_gearsets():
    # seed rig, 4 planets: 56 sin 45 deg = 39.6 > 33; rig_5planets: 55 sin 36 deg = 32.33 > 32
    assert tip_clearance(25, 87, 31, _equal(4)) == pytest.approx(56 * math.sin(math.pi / 4) - 33, abs=1e-12)
    assert tip_clearance(25, 85, 30, _equal(5)) == pytest.approx(55 * math.sin(math.pi / 5) - 32, abs=1e-12)
    assert tip_clearance(25, 85, 30, _equal(5)) > 0
    # five planets do not fit the seed rig: 56 sin 36 deg = 32.9 < 33
    assert tip_clearance(25, 87, 31, _equal(5)) < 0
    assert max_equal_planets(25, 87, 31) == 4
    assert max_equal_planets(25, 85, 30) == 5


def test_unequal_spacing_uses_the_smallest_gap_in_any_order():
    # rig_3planets: p = 0, 36, 75 of 2 pi / 112; the smallest gap is 112 - 75 = 37 steps
    psi = 2 * math.pi * np.array([75, 0, 36]) / 112
    expected = 56 * math.sin(math.pi * 36 / 112) - 31
    assert tip_clearance(25, 87, 29, psi) == pytest.approx(expected, abs=1e-12)
    # two planets at one place collide
    assert tip_clearance(25, 87, 31, [0.0, 0.0]) == pytest.approx(-33.0)


def test_exact_boundary_counts_as_collision():
    # Z_s = Z_p + 4: (Z_s + Z_p) sin(pi / 6) = Z_p + 2 exactly, tips touching
    m = tip_clearance(14, 34, 10, _equal(6))
    assert abs(m) < 1e-12 and not m > CLEARANCE_ATOL
    assert max_equal_planets(14, 34, 10) == 5


def test_assemblable_counts():
    assert assemblable_planet_counts(25, 87) == [1, 2, 4, 7, 8, 14, 16, 28, 56]
    assert assemblable_planet_counts(25, 87, 31) == [1, 2, 4]
    assert assemblable_planet_counts(25, 85, 30, n_max=4) == [1, 2]


@settings(max_examples=200, deadline=None)
@given(zs=st.integers(3, 150), zp=st.integers(3, 150), n=st.integers(2, 16))
def test_tip_clearance_matches_the_classical_formula(zs, zp, n):
    zr = zs + 2 * zp
    margin = (zs + zp) * math.sin(math.pi / n) - (zp + 2)
    assert tip_clearance(zs, zr, zp, _equal(n)) == pytest.approx(margin, abs=1e-9)
    fits = max_equal_planets(zs, zr, zp)
    assert all(tip_clearance(zs, zr, zp, _equal(k)) > CLEARANCE_ATOL for k in range(2, fits + 1))
    assert not tip_clearance(zs, zr, zp, _equal(fits + 1)) > CLEARANCE_ATOL


def test_empty_and_single_planet():
    assert tip_clearance(25, 87, 31, []) == math.inf
    assert tip_clearance(25, 87, 31, [0.3]) == math.inf
    assert max_equal_planets(3, 400, 190) >= 1


def test_bad_inputs():
    with pytest.raises(ValueError, match="z_ring must exceed z_sun"):
        coaxiality_error(87, 25, 31)
    with pytest.raises(ValueError, match="z_planet"):
        coaxiality_error(25, 87, 0)
    with pytest.raises(TypeError, match="z_sun"):
        tip_clearance("25", 87, 31, [0.0, 1.0])
    with pytest.raises(ValueError, match="planet_angles"):
        tip_clearance(25, 87, 31, [0.0, np.nan])
    with pytest.raises(ValueError, match="1-D"):
        tip_clearance(25, 87, 31, np.zeros((2, 2)))
    with pytest.raises(ValueError, match="n_max"):
        assemblable_planet_counts(25, 87, n_max=0)
    with pytest.raises(ValueError, match="z_sun"):
        max_equal_planets(0, 87, 31)
