"""Load sharing and face-width centroids from pulse amplitudes (meshphase.kinematics.loads).

Truth here is worked by hand (load-sharing factors of a small table, the centroid of a linear
or triangular load shape) or integrated numerically with scipy.integrate.quad, so a slip in
the formulas of spec sections 6 and 7 shows up as a mismatch.
"""

import math

import numpy as np
import pytest
from hypothesis import example, given, settings, strategies as st
from scipy.integrate import quad

from meshphase.errors import ProcessingWarning
from meshphase.kinematics.loads import (CentroidResult, LoadSharingResult, centroid_of_shape,
                                        facewidth_centroid, facewidth_readings,
                                        load_sharing_from_amplitudes)

B = 40e-3  # face width [m] of the synthetic scenarios (meshphase.synthetic.scenarios.FACE_WIDTH)


# ----------------------------------------------------------------------------- load sharing

def test_load_sharing_worked_example():
    # planet means 1.0, 2.0, 3.0 (x 100 µε) -> LS = 3 m / 6 = 0.5, 1.0, 1.5 exactly
    amp = np.array([0.9, 1.1, 1.8, 2.2, 3.0, 2.7, 3.3]) * 100e-6
    pl = np.array([1, 1, 2, 2, 3, 3, 3])
    res = load_sharing_from_amplitudes(amp, pl, 3)
    assert isinstance(res, LoadSharingResult)
    np.testing.assert_allclose(res.factors, [0.5, 1.0, 1.5], rtol=1e-12)
    np.testing.assert_array_equal(res.n_passes, [2, 2, 3])
    np.testing.assert_allclose(res.mean_amplitude, [1e-4, 2e-4, 3e-4], rtol=1e-12)
    assert res.factors.sum() == pytest.approx(3.0, rel=1e-12)
    # first-order propagation by hand: LS_i = k m_i / S, dLS_i/dm_j = k (d_ij / S - m_i / S^2)
    m = np.array([1.0, 2.0, 3.0]) * 1e-4
    sem = np.array([np.std(amp[pl == q], ddof=1) / math.sqrt(np.sum(pl == q)) for q in (1, 2, 3)])
    S, k = m.sum(), 3
    want = [math.sqrt(sum((k * ((i == j) / S - m[i] / S ** 2) * sem[j]) ** 2 for j in range(3)))
            for i in range(3)]
    np.testing.assert_allclose(res.std_error, want, rtol=1e-12)
    rows = res.to_rows()
    assert [r["planet"] for r in rows] == [1, 2, 3] and rows[2]["n_passes"] == 3
    assert rows[0]["load_sharing"] == pytest.approx(0.5)


def test_load_sharing_ignores_unassigned_pulses():
    amp = np.array([5.0, 1.0, 1.0, 1.0, 1.0, 9.0])
    pl = np.array([0, 1, 2, 1, 2, -1])  # 0 and -1: unassigned
    res = load_sharing_from_amplitudes(amp, pl, 2)
    np.testing.assert_allclose(res.factors, [1.0, 1.0])
    np.testing.assert_array_equal(res.n_passes, [2, 2])


def test_load_sharing_std_error_monte_carlo():
    # Reported std error against the scatter of the factors over independent records.
    # 2000 records: the empirical std carries ~1.6 % sampling error, the mean of the reported
    # std errors less; 40 pulses per planet make first-order propagation good to ~1 %
    # (relative pulse scatter 5 %), so 8 % tolerance is a few sigma of the check itself.
    rng = np.random.default_rng(2024)
    mu = np.array([1.1, 0.95, 1.0, 0.95]) * 100e-6
    sd = 0.05 * mu
    n_rep, m = 2000, 40
    pl = np.repeat(np.arange(1, 5), m)
    fac = np.empty((n_rep, 4))
    se = np.empty((n_rep, 4))
    for r in range(n_rep):
        amp = rng.normal(np.repeat(mu, m), np.repeat(sd, m))
        res = load_sharing_from_amplitudes(amp, pl, 4)
        fac[r], se[r] = res.factors, res.std_error
    np.testing.assert_allclose(se.mean(axis=0), fac.std(axis=0, ddof=1), rtol=0.08)
    # and the factors are unbiased to first order: mean within 4 std errors of N mu / sum mu
    want = 4 * mu / mu.sum()
    assert np.all(np.abs(fac.mean(axis=0) - want) < 4 * fac.std(axis=0) / math.sqrt(n_rep))


@given(st.lists(st.floats(0.2, 5.0), min_size=2, max_size=6), st.floats(1e-6, 1e-2))
@settings(max_examples=60, deadline=None)
def test_property_factors_sum_to_n_and_are_gain_free(means, gain):
    # two pulses per planet, symmetric about the mean: factors are N m_n / sum m exactly
    m = np.asarray(means)
    n = m.size
    amp = np.concatenate([m * 0.9, m * 1.1]) * gain
    pl = np.tile(np.arange(1, n + 1), 2)
    res = load_sharing_from_amplitudes(amp, pl, n)
    assert res.factors.sum() == pytest.approx(n, rel=1e-12)
    np.testing.assert_allclose(res.factors, n * m / m.sum(), rtol=1e-12)
    assert np.all(np.isfinite(res.std_error)) and np.all(res.std_error >= 0)


def test_missing_planet_warns_and_gives_nan():
    amp = np.array([1.0, 1.2, 2.0, 2.2, 3.0, 3.2])
    pl = np.array([1, 1, 2, 2, 4, 4])
    with pytest.warns(ProcessingWarning, match=r"planet\(s\) \[3\]"):
        res = load_sharing_from_amplitudes(amp, pl, 4)
    assert math.isnan(res.factors[2]) and math.isnan(res.std_error[2])
    assert res.n_passes[2] == 0
    # the planets seen are normalised over themselves: they sum to their count
    seen = np.isfinite(res.factors)
    assert res.factors[seen].sum() == pytest.approx(3.0)
    np.testing.assert_allclose(res.factors[seen], 3 * np.array([1.1, 2.1, 3.1]) / 6.3)


def test_single_pulse_planet_gives_unknown_std_error():
    # one planet seen once: its scatter is unknown, so no factor's std error is known
    amp = np.array([1.0, 1.1, 2.0, 2.0, 2.1])
    pl = np.array([1, 1, 2, 3, 3])
    res = load_sharing_from_amplitudes(amp, pl, 3)
    assert np.all(np.isfinite(res.factors))
    assert np.all(np.isnan(res.std_error))


def test_load_sharing_empty_gives_nan_factors():
    with pytest.warns(ProcessingWarning, match="no pulse"):
        res = load_sharing_from_amplitudes([], np.array([], dtype=int), 3)
    assert res.factors.shape == (3,) and np.all(np.isnan(res.factors))
    assert np.all(np.isnan(res.std_error)) and np.all(res.n_passes == 0)


@pytest.mark.parametrize("amp, pl, n, exc, match", [
    ([1.0, -0.5, 1.0], [1, 2, 2], 2, ValueError, "negative"),
    ([1.0, 0.0, 0.0], [1, 2, 2], 2, ValueError, "mean pulse amplitude"),
    ([1.0, 1.0], [1, 2, 2], 2, ValueError, "match"),
    ([1.0, 1.0], [1, 3], 2, ValueError, "n_planets"),
    ([1.0, np.nan], [1, 2], 2, ValueError, "finite"),
    ([1.0, 1.0], [1, 2], 0, ValueError, "n_planets"),
    ([1.0, 1.0], [1.0, 2.0], 2, TypeError, "integers"),
    ([[1.0, 1.0]], [[1, 2]], 2, ValueError, "1-D"),
])
def test_load_sharing_bad_inputs(amp, pl, n, exc, match):
    with pytest.raises(exc, match=match):
        load_sharing_from_amplitudes(amp, np.asarray(pl), n)


def test_negative_amplitude_of_unassigned_pulse_is_ignored():
    # the sign check covers the pulses that are used, not rejected ones
    res = load_sharing_from_amplitudes([1.0, 1.0, -3.0], np.array([1, 2, 0]), 2)
    np.testing.assert_allclose(res.factors, [1.0, 1.0])


# ----------------------------------------------------------------------------- centroids

def _numeric_centroid(s, b):
    """Centroid [m] of w(z) = max(0, 1 - s z) on [-b/2, b/2] by quadrature (the kink at
    z = 1 / s passed to quad as a break point)."""
    w = lambda z: max(0.0, 1.0 - s * z)
    pts = [1.0 / s] if s != 0 and abs(1.0 / s) < b / 2 else None
    num = quad(lambda z: z * w(z), -b / 2, b / 2, points=pts, epsabs=1e-16, epsrel=1e-12)[0]
    den = quad(w, -b / 2, b / 2, points=pts, epsabs=1e-16, epsrel=1e-12)[0]
    return num / den


@pytest.mark.parametrize("s_b2", [0.0, 0.3, -0.7, 1.0, 1.2, -1.5, 3.0, -8.0])
def test_centroid_of_shape_against_quadrature(s_b2):
    # s b/2 = slope ratio in units of the half face width; > 1: the load leaves the face
    s = s_b2 / (B / 2)
    zc, frac = centroid_of_shape(s, B)
    assert zc == pytest.approx(_numeric_centroid(s, B), rel=1e-9, abs=1e-15)
    if abs(s_b2) <= 1:
        assert frac == 1.0 and zc == pytest.approx(-s * B * B / 12, rel=1e-12, abs=1e-18)
    else:
        # contact from the loaded edge to z0 = 1 / s
        assert frac == pytest.approx((B / 2 + abs(1 / s)) / B, rel=1e-12)
        assert 0.5 < frac < 1.0
    # the centroid moves towards the loaded edge (s > 0: edge at -b/2)
    assert np.sign(zc) == -np.sign(s) or s == 0


def test_centroid_of_shape_bad_inputs():
    with pytest.raises(ValueError, match="face_width"):
        centroid_of_shape(1.0, 0.0)
    with pytest.raises(ValueError, match="slope_ratio"):
        centroid_of_shape(float("nan"), B)
    with pytest.raises(TypeError, match="slope_ratio"):
        centroid_of_shape("steep", B)


def _linear_readings(Z, z, F=1.0, b=B):
    """Spec 7 full-contact load w(z) = (F / b)(1 + 12 Z z / b^2) read at z."""
    return F / b * (1 + 12 * Z * np.asarray(z) / b ** 2)


@given(st.floats(-1.0, 1.0), st.integers(2, 5), st.floats(0.05, 0.5), st.floats(10.0, 5e3))
@example(1.0, 3, 0.4, 100.0)   # contact reaches the far edge: still full contact, not
@example(-1.0, 5, 0.5, 7.0)    # "partial" with a fraction 1 - 2e-16 from rounding
@settings(max_examples=100, deadline=None)
def test_property_linear_full_contact_exact(zfrac, n_gauges, spread, F):
    # full contact needs |Z| <= b / 6 (then 1 + 12 Z z / b^2 >= 0 on the face)
    Z = zfrac * B / 6
    z = np.linspace(-spread, spread, n_gauges) * B
    res = facewidth_centroid(_linear_readings(Z, z, F), z, B)
    assert isinstance(res, CentroidResult)
    assert res.centroid == pytest.approx(Z, abs=1e-12 * B)
    assert res.contact_fraction == 1.0 and res.shape == "linear"
    assert res.residual_rms <= 1e-9 * F / B
    assert math.isnan(res.std_error)  # one row: no pass scatter


@pytest.mark.parametrize("s_b2", [1.5, 2.5, -2.0])
def test_partial_contact_triangle_centroid(s_b2):
    # five gauges read the section 5 shape A max(0, 1 - s z); two of them beyond contact
    s = s_b2 / (B / 2)
    z = np.array([-0.4, -0.2, 0.0, 0.2, 0.4]) * B
    y = 150e-6 * np.maximum(0.0, 1.0 - s * z)
    res = facewidth_centroid(y, z, B)
    assert res.shape == "partial"
    assert res.centroid == pytest.approx(_numeric_centroid(s, B), rel=1e-6)
    assert res.contact_fraction == pytest.approx((B / 2 + abs(1 / s)) / B, rel=1e-6)
    assert res.residual_rms < 1e-6 * 150e-6


def test_gains_divide_out():
    z = np.array([-0.4, 0.0, 0.4]) * B
    true = _linear_readings(0.1 * B, z, 2.0)
    gains = np.array([0.8, 1.25, 1.1])
    plain = facewidth_centroid(true, z, B)
    scaled = facewidth_centroid(true * gains, z, B, gains=gains)
    assert scaled.centroid == pytest.approx(plain.centroid, rel=1e-12)
    # ignoring the gains biases the centroid: the check can fail
    assert abs(facewidth_centroid(true * gains, z, B).centroid - plain.centroid) > 1e-4


def test_per_pass_rows_give_std_error(rng):
    # 200 passes with 2 % reading noise: the std error is the scatter of the per-pass
    # centroids / sqrt(m), and the estimate lies within 4 of them of the truth
    Z = -0.08 * B
    z = np.array([-0.4, -0.2, 0.0, 0.2, 0.4]) * B
    clean = _linear_readings(Z, z, 3.0)
    rows = clean * (1 + 0.02 * rng.standard_normal((200, z.size)))
    res = facewidth_centroid(rows, z, B)
    per = np.array([facewidth_centroid(r, z, B).centroid for r in rows])
    assert res.std_error == pytest.approx(per.std(ddof=1) / math.sqrt(per.size), rel=1e-12)
    assert 0 < res.std_error < 1e-4
    assert abs(res.centroid - Z) < 4 * res.std_error


def test_nonfinite_rows_are_left_out_with_warning():
    z = np.array([-0.4, 0.0, 0.4]) * B
    good = _linear_readings(0.05 * B, z)
    rows = np.vstack([good, [np.nan, 1.0, 1.0], good])
    with pytest.warns(ProcessingWarning, match="1 of 3"):
        res = facewidth_centroid(rows, z, B)
    assert res.centroid == pytest.approx(0.05 * B, rel=1e-9)
    with pytest.raises(ValueError, match="non-finite"):
        facewidth_centroid([[np.nan, 1.0, 1.0]], z, B)


def test_facewidth_empty_rows():
    res = facewidth_centroid(np.empty((0, 3)), [-0.01, 0.0, 0.01], B)
    assert res.shape == "none" and math.isnan(res.centroid) and math.isnan(res.std_error)


@pytest.mark.parametrize("readings, positions, kwargs, match", [
    ([1.0], [0.0], {}, "at least two"),
    ([1.0, 2.0], [0.01, 0.01], {}, "differ"),
    ([1.0, 2.0], [-0.01, 0.03], {}, "on the face"),
    ([1.0, 2.0, 3.0], [-0.01, 0.01], {}, "one column per gauge"),
    ([[[1.0, 2.0]]], [-0.01, 0.01], {}, "one column per gauge"),
    ([1.0, 2.0], [-0.01, 0.01], {"gains": [1.0, 0.0]}, "gains"),
    ([1.0, 2.0], [-0.01, 0.01], {"gains": [1.0]}, "gains"),
    ([-1.0, -2.0], [-0.01, 0.01], {}, "positive load"),
    ([1.0, 2.0], [-0.01, np.nan], {}, "positions"),
])
def test_facewidth_bad_inputs(readings, positions, kwargs, match):
    with pytest.raises(ValueError, match=match):
        facewidth_centroid(readings, positions, B, **kwargs)
    with pytest.raises(ValueError, match="face_width"):
        facewidth_centroid([1.0, 2.0], [-0.01, 0.01], -B)


# ----------------------------------------------------------------------------- face-width passes
def test_facewidth_readings_per_pass_of_the_most_loaded_gauge():
    fs = 1000.0
    t = np.array([1.0, 2.0, 3.0, 4.0])
    # gauge 0 (most clean pulses) times the passes; gauge 1 misses the 3rd pass and is 2 ms
    # late; gauge 2 is the unloaded end of the face (no pulse at all)
    times = [t, np.array([1.002, 2.002, 4.002]), np.empty(0)]
    amps = [np.array([1.0, 1.1, 1.2, 1.3]), np.array([-0.5, -0.6, -0.7]), np.empty(0)]
    good = [np.array([1, 1, 1, 1], bool), np.array([1, 1, 1], bool), np.empty(0, bool)]
    widths = [np.full(4, 0.004), np.full(3, 0.004), np.empty(0)]
    r = facewidth_readings(times, amps, good, widths, fs)
    np.testing.assert_allclose(r, [[1.0, 0.5, 0.0], [1.1, 0.6, 0.0], [1.2, 0.0, 0.0],
                                   [1.3, 0.7, 0.0]])
    # a pass further off than the reference's median width reads 0
    r = facewidth_readings([t, t + 0.01], amps[:1] * 2, good[:1] * 2, [np.full(4, 0.004)] * 2, fs)
    np.testing.assert_allclose(r[:, 1], 0.0)
    # only the reference gauge's clean pulses are passes; a NaN reading drops the row
    amps2 = [amps[0], np.array([np.nan, 0.6, 0.7])]
    good2 = [np.array([1, 0, 1, 1], bool), good[1]]
    r = facewidth_readings(times[:2], amps2, good2, widths[:2], fs)
    np.testing.assert_allclose(r, [[1.2, 0.0], [1.3, 0.7]])


def test_facewidth_readings_empty_and_bad_input():
    assert facewidth_readings([], [], [], [], 1000.0).shape == (0, 0)
    none_clean = facewidth_readings([np.array([1.0])] * 2, [np.array([1.0])] * 2,
                                    [np.array([False])] * 2, [np.array([0.01])] * 2, 1000.0)
    assert none_clean.shape == (0, 2)
    with pytest.raises(ValueError, match="one entry per gauge"):
        facewidth_readings([np.array([1.0])] * 2, [np.array([1.0])], [np.array([True])] * 2,
                           [np.array([0.01])] * 2, 1000.0)
    with pytest.raises(ValueError, match="1-D of one length"):
        facewidth_readings([np.array([1.0, 2.0])], [np.array([1.0])], [np.array([True])],
                           [np.array([0.01])], 1000.0)
    with pytest.raises(ValueError, match="fs"):
        facewidth_readings([], [], [], [], 0.0)
