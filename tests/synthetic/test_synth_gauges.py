"""Pulse shape, face-width load weighting and the pulse / box renderers."""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from meshphase.synthetic.gauges import (PulseTable, face_load_factor, pulse_peak_offset, pulse_shape,
                                        pulse_support, render_box, render_pulses)


# ----------------------------------------------------------------------------- pulse shape

@pytest.mark.parametrize("eps", [1.0, 1.3, 1.6, 1.9, 2.4])
@pytest.mark.parametrize("skew", [-0.3, 0.0, 0.3])
def test_pulse_shape_tensile_peak_compressive_lobes(eps, skew):
    half = pulse_support(eps)
    u = np.linspace(-half - 0.5, half + 0.5, 40001)
    p = pulse_shape(u, eps, 0.25, skew)
    assert p.max() == pytest.approx(1.0, abs=1e-6)
    assert np.all(p[np.abs(u) >= half] == 0.0)
    # tensile while the tooth carries load, compressive lobes before and after it
    assert p[np.argmin(np.abs(u))] > 0.5
    before = p[(u < -0.5 * eps) & (u > -half)]
    after = p[(u > 0.5 * eps) & (u < half)]
    assert before.min() < -0.1 and after.min() < -0.1
    # the tensile lobe sits inside the contact interval |u| < eps/2
    assert np.all(np.abs(u[p > 0]) < 0.5 * eps)


def test_pulse_skew_moves_the_peak():
    assert pulse_peak_offset(1.6, 0.25, 0.3) > 0.05
    assert pulse_peak_offset(1.6, 0.25, -0.3) < -0.05
    assert pulse_peak_offset(1.6, 0.25, -0.3) == pytest.approx(-pulse_peak_offset(1.6, 0.25, 0.3))
    assert abs(pulse_peak_offset(1.6, 0.25, 0.0)) < 0.3   # flat plateau: anywhere on it


def test_pulse_shape_empty_and_bad_input():
    assert pulse_shape(np.empty(0)).shape == (0,)
    with pytest.raises(ValueError, match="contact_ratio"):
        pulse_shape([0.0], contact_ratio=0.9)
    with pytest.raises(ValueError, match="side_lobe"):
        pulse_shape([0.0], side_lobe=1.0)
    with pytest.raises(ValueError, match="skew"):
        pulse_shape([0.0], skew=1.5)
    with pytest.raises(TypeError, match="contact_ratio"):
        pulse_support("wide")
    with pytest.raises(ValueError, match="finite"):
        pulse_shape([np.nan])


def test_pulse_table_matches_shape():
    tab = PulseTable(1.7, 0.3, 0.2)
    u = np.random.default_rng(0).uniform(-tab.half - 0.2, tab.half + 0.2, 20000)
    ref = pulse_shape(u, 1.7, 0.3, 0.2)
    # linear interpolation on 32768 points: error ~ du^2/8 max|p''| ~ 1e-7 of the peak
    np.testing.assert_allclose(tab(u), ref, atol=5e-7)
    x = np.clip((u + tab.half) * tab.scale, 0, None)
    np.testing.assert_allclose(tab.lookup(x), ref, atol=5e-7)


# ----------------------------------------------------------------------------- face load

def _face_ref(z, Z, b):
    """Spec section 7 linear form, and the section 5 triangle beyond |Z| = b/6 (closed form)."""
    if abs(Z) <= b / 6:
        return 1 + 12 * Z * z / b ** 2
    lc = 3 * (b / 2 - abs(Z))
    x = np.sign(Z) * z - (b / 2 - lc)
    return 2 * b / lc * np.clip(x, 0, None) / lc


@pytest.mark.parametrize("Z", [-0.015, -0.008, -0.002, 0.0, 0.003, 0.0066, 0.012, 0.019])
def test_face_load_factor_mean_centroid_and_closed_form(Z):
    b = 0.04
    z = np.linspace(-b / 2, b / 2, 400001)
    f = face_load_factor(z, Z, b)
    np.testing.assert_allclose(f, _face_ref(z, Z, b), atol=1e-12)
    assert np.all(f >= -1e-12)
    assert np.trapezoid(f, z) / b == pytest.approx(1.0, abs=1e-6)
    assert np.trapezoid(f * z, z) / np.trapezoid(f, z) == pytest.approx(Z, abs=1e-8)


def test_face_load_factor_partial_contact_unloads_one_end():
    b = 0.04
    f = face_load_factor([-0.02, -0.01, 0.02], 0.012, b)
    assert f[0] == pytest.approx(0, abs=1e-12) and f[1] == pytest.approx(0, abs=1e-12)
    assert f[2] > 2.0
    # continuous at |Z| = b/6
    lo = face_load_factor(0.02, b / 6 * (1 - 1e-9), b)
    hi = face_load_factor(0.02, b / 6 * (1 + 1e-9), b)
    assert lo == pytest.approx(hi, rel=1e-6)


def test_face_load_factor_least_squares_recovers_centroid():
    """Spec section 7: a line through the gauge readings gives Z (linear distribution)."""
    b, Z = 0.04, 0.0031
    z = np.array([-0.016, -0.008, 0.0, 0.008, 0.016])
    w = face_load_factor(z, Z, b)
    slope, icpt = np.polyfit(z, w, 1)
    assert slope / icpt * b ** 2 / 12 == pytest.approx(Z, rel=1e-12)


def test_face_load_factor_empty_and_bad_input():
    assert face_load_factor(np.empty(0), 0.0, 0.04).shape == (0,)
    with pytest.raises(ValueError, match="within the face"):
        face_load_factor(0.03, 0.0, 0.04)
    with pytest.raises(ValueError, match="centroid"):
        face_load_factor(0.0, 0.02, 0.04)
    with pytest.raises(ValueError, match="face_width"):
        face_load_factor(0.0, 0.0, -0.04)
    with pytest.raises(TypeError, match="face_width"):
        face_load_factor(0.0, 0.0, "wide")


# ----------------------------------------------------------------------------- renderers

def test_render_pulses_matches_direct_evaluation():
    tab = PulseTable(1.6, 0.25, 0.2)
    fs = 1000.0
    t_e = np.array([0.1234567, 0.5, 0.61, 1.9999])   # 0.5/0.61 overlap: contributions add
    T = np.array([0.05, 0.05, 0.06, 0.04])
    A = np.array([1e-4, 2e-4, -1e-4, 3e-4])
    out = np.zeros(2000)
    render_pulses(out, 0, t_e * fs, T * fs, A, tab)
    t = np.arange(2000) / fs
    ref = sum(a * pulse_shape((t - te) / tp, 1.6, 0.25, 0.2) for te, tp, a in zip(t_e, T, A))
    np.testing.assert_allclose(out, ref, atol=1e-10)


@settings(max_examples=50, deadline=None)
@given(cut=st.lists(st.integers(1, 4999), min_size=1, max_size=6, unique=True))
def test_render_pulses_blocks_bit_identical(cut):
    tab = PulseTable(1.8, 0.3, -0.2)
    rng = np.random.default_rng(3)
    pos = np.sort(rng.uniform(-50, 5050, 60))
    per = rng.uniform(20, 40, 60)
    amp = rng.uniform(1, 2, 60)
    whole = np.zeros(5000)
    render_pulses(whole, 0, pos, per, amp, tab)
    edges = [0] + sorted(cut) + [5000]
    parts = []
    for a, b in zip(edges[:-1], edges[1:]):
        blk = np.zeros(b - a)
        render_pulses(blk, a, pos, per, amp, tab, max_elems=257)
        parts.append(blk)
    assert np.array_equal(np.concatenate(parts), whole)


def test_render_pulses_empty_and_outside():
    tab = PulseTable()
    out = np.zeros(10)
    render_pulses(out, 0, np.empty(0), np.empty(0), np.empty(0), tab)
    render_pulses(out, 0, [1000.0], [5.0], [1.0], tab)
    render_pulses(np.zeros(0), 0, [1.0], [5.0], [1.0], tab)
    assert not out.any()


def test_render_box_area_and_subsample_edges():
    out = np.zeros(100)
    render_box(out, 0, [10.3, 50.0], [20.55, 50.4], 5.0)
    assert out.sum() == pytest.approx(5.0 * (20.55 - 10.3 + 0.4))
    assert out[11] == 5.0 and out[19] == 5.0 and out[9] == 0.0 and out[22] == 0.0
    assert out[10] == pytest.approx(5.0 * 0.2)     # cell [9.5, 10.5): 0.2 covered
    assert out[21] == pytest.approx(5.0 * 0.05)    # cell [20.5, 21.5): 0.05 covered
    assert out[50] == pytest.approx(5.0 * 0.4)
    blocks = np.zeros(100)
    for a in range(0, 100, 7):
        seg = np.zeros(min(7, 100 - a))
        render_box(seg, a, [10.3, 50.0], [20.55, 50.4], 5.0)
        blocks[a:a + seg.size] = seg
    np.testing.assert_allclose(blocks, out, atol=1e-15)
    empty = np.zeros(5)
    render_box(empty, 0, [], [], 1.0)
    assert not empty.any()
