"""Tests of meshphase.models.load_sharing (spec section 6, Ligata, Kahraman & Singh 2008)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from meshphase.errors import DataQualityWarning
from meshphase.models.load_sharing import load_sharing


def test_equal_sharing_is_one():
    np.testing.assert_array_equal(load_sharing([120e-6, 120e-6, 120e-6]), [1.0, 1.0, 1.0])


def test_definition_on_a_worked_example():
    # LS_n = N eps_n / sum eps: 3 planets, 100, 110, 90 microstrain -> 1.0, 1.1, 0.9
    np.testing.assert_allclose(load_sharing([100e-6, 110e-6, 90e-6]), [1.0, 1.1, 0.9],
                               rtol=1e-14)
    # a single planet always carries everything
    assert load_sharing([3e-4]).tolist() == [1.0]


@settings(max_examples=100, deadline=None)
@given(eps=arrays(np.float64, st.tuples(st.integers(1, 5), st.integers(1, 7)),
                  elements=st.floats(1e-7, 1e-2)),
       gain=st.floats(1e-3, 1e3))
def test_sums_to_n_and_ignores_gain(eps, gain):
    ls = load_sharing(eps)
    np.testing.assert_allclose(ls.sum(axis=-1), eps.shape[-1], rtol=1e-12)
    np.testing.assert_allclose(load_sharing(gain * eps), ls, rtol=1e-12)
    # planet axis first gives the transposed answer
    np.testing.assert_allclose(load_sharing(eps.T, axis=0), ls.T, rtol=1e-14)
    assert np.all(ls >= 0)


def test_zero_planet_in_a_loaded_slice_is_allowed():
    np.testing.assert_allclose(load_sharing([0.0, 2e-4, 1e-4, 1e-4]), [0.0, 2.0, 1.0, 1.0])


def test_nan_policy_omit_warns_and_renormalises():
    eps = np.array([[100e-6, np.nan, 100e-6, 50e-6],
                    [100e-6, 100e-6, 100e-6, 100e-6]])
    with pytest.warns(DataQualityWarning, match="1 NaN"):
        ls = load_sharing(eps, nan_policy="omit")
    # first slice: N = 3 finite planets, sum 250 -> 1.2, NaN, 1.2, 0.6
    np.testing.assert_allclose(ls[0], [1.2, np.nan, 1.2, 0.6], rtol=1e-14)
    np.testing.assert_array_equal(ls[1], [1, 1, 1, 1])


def test_empty_input():
    assert load_sharing([]).shape == (0,)
    assert load_sharing(np.zeros((3, 0))).shape == (3, 0)
    assert load_sharing(np.zeros((0, 4))).shape == (0, 4)


def test_bad_input():
    with pytest.raises(ValueError, match="NaN"):
        load_sharing([1e-4, np.nan])
    with pytest.raises(ValueError, match="infinite"):
        load_sharing([1e-4, np.inf], nan_policy="omit")
    with pytest.raises(ValueError, match="all zero"):
        load_sharing([[1e-4, 1e-4], [0.0, 0.0]])
    with pytest.raises(ValueError, match=">= 0"):
        load_sharing([2e-4, -1e-4])
    with pytest.raises(ValueError, match="no finite"):
        with pytest.warns(DataQualityWarning):
            load_sharing([[np.nan, np.nan], [1.0, 1.0]], nan_policy="omit")
    with pytest.raises(ValueError, match="nan_policy"):
        load_sharing([1.0, 1.0], nan_policy="drop")
    with pytest.raises(ValueError, match="axis"):
        load_sharing([1.0, 1.0], axis=2)
    with pytest.raises(ValueError, match="dimension"):
        load_sharing(1e-4)
    with pytest.raises(TypeError, match="peak_strains"):
        load_sharing("strain")
    with pytest.raises(TypeError, match="peak_strains"):
        load_sharing([1.0, "x"])
