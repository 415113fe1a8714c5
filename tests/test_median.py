"""meshphase.signal.median.median_of_finite: np.median's value and dtype for finite samples, by
one partition (the robust noise, SNR and quality estimates and the onset detector's noise
level take it)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from meshphase.signal.median import MAD_TO_SIGMA, median_and_mad, median_of_finite, sigma_of_differences

_BIG = float(np.float32(1e30))    # a float32 value: no sum of two overflows


def _same(got, want):
    # equal value and dtype; a zero's sign is not ordered by either partition
    assert got == want and np.asarray(got).dtype == np.asarray(want).dtype


@settings(max_examples=300, deadline=None)
@given(hnp.arrays(st.sampled_from([np.float64, np.float32]), st.integers(1, 300),
                  elements=st.floats(-_BIG, _BIG, width=32)))
def test_equals_np_median_for_finite_floats(a):
    _same(median_of_finite(a), np.median(a))


@settings(max_examples=100, deadline=None)
@given(hnp.arrays(np.float64, st.integers(1, 200), elements=st.sampled_from([-2.0, -0.0, 0.0, 1.5, 7.0])))
def test_ties_and_signed_zeros(a):
    # many equal values: whichever copy the partition puts in the middle, the value is the same
    _same(median_of_finite(a), np.median(a))


@pytest.mark.parametrize("n", [1, 2, 3, 8, 8191, 8192])
def test_short_arrays_rounded_and_constant(n):
    # the onset detector's noise pieces are 8192 samples
    rng = np.random.default_rng(n)
    for a in (rng.standard_normal(n), np.round(rng.standard_normal(n) * 3), np.zeros(n)):
        _same(median_of_finite(a), np.median(a))


@pytest.mark.parametrize("n", [614399, 614400])
def test_long_arrays_of_both_parities(n):
    a = np.random.default_rng(n).standard_normal(n)
    _same(median_of_finite(a), np.median(a))
    # the input is left as it was (the partition works on a copy)
    assert np.array_equal(a, np.random.default_rng(n).standard_normal(n))


@pytest.mark.parametrize("a", [np.array([30000, 30000, -7, 32767], dtype=np.int16),
                               np.array([3, 1, 2], dtype=np.int64),
                               np.array([0.1, 0.7, 0.3, 0.2], dtype=np.float16)])
def test_other_dtypes_are_np_medians(a):
    # integers (which a sum of the two middle values would overflow) and float16 average in
    # a wider type in np.median: they go to it
    _same(median_of_finite(a), np.median(a))


def test_any_shape_is_taken_flat():
    a = np.arange(12.0).reshape(3, 4)[:, ::-1]
    _same(median_of_finite(a), np.median(a))


def test_empty_is_an_error():
    with pytest.raises(ValueError, match="empty"):
        median_of_finite(np.empty(0))


def test_not_an_array_is_an_error():
    with pytest.raises((TypeError, AttributeError, ValueError)):
        median_of_finite(None)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_median_and_mad_are_np_medians(dtype):
    # the MAD is the median of the absolute deviations from the median, both as np.median
    a = np.random.default_rng(5).standard_normal(1001).astype(dtype) ** 3
    med, mad = median_and_mad(a)
    _same(med, np.median(a))
    _same(mad, np.median(np.abs(a - np.median(a))))
    with pytest.raises(ValueError, match="empty"):
        median_and_mad(np.empty(0, dtype=dtype))


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_sigma_of_differences_is_the_mad_of_the_differences(dtype):
    # the noise estimate of condition and quality: MAD of the first differences -> sigma
    x = np.random.default_rng(6).standard_normal(20001).astype(dtype)
    d = np.diff(x)
    want = MAD_TO_SIGMA * np.median(np.abs(d - np.median(d))) / math.sqrt(2.0)   # as written before
    assert float(sigma_of_differences(d)) == float(want)
    assert float(sigma_of_differences(d)) == pytest.approx(1.0, rel=0.05)   # 20000 samples: ~1 %
    with pytest.raises(ValueError, match="empty"):
        sigma_of_differences(np.empty(0, dtype=dtype))
