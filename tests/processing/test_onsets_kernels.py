"""The onset stage's fast kernels (issue 13) equal what they replace bit for bit: the sign
folded into the decimation, the Savitzky-Golay interior and the decimated finiteness check
of a block (the single-pivot median: tests/test_median.py)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import signal

from meshphase.onsets import detect_onsets
from meshphase.onsets.coarse import decimate
from meshphase.onsets.features import _features_fit, _savgol_interior

FS = 5120.0


@pytest.mark.parametrize("d", [1, 2, 7, 40])
def test_decimate_sign_equals_negated_copy(d):
    x = np.random.default_rng(d).standard_normal(1000)
    assert np.array_equal(decimate(x, d, -1), decimate(-x, d))
    assert np.array_equal(decimate(x, d, 1), decimate(x, d))


def test_savgol_interior_equals_filter_inside():
    h = np.sin(np.linspace(0, np.pi, 97)) ** 2 + 0.01 * np.random.default_rng(0).standard_normal(97)
    for win in (5, 9, 25):
        full = signal.savgol_filter(h, win, 3)
        inner = _savgol_interior(h, win)
        e = win // 2
        assert np.array_equal(inner[e:h.size - e], full[e:h.size - e])
        assert np.isnan(inner[:e]).all() and np.isnan(inner[h.size - e:]).all()


@pytest.mark.parametrize("centre", [6.0, 20.3])
def test_features_equal_the_full_filter(monkeypatch, centre):
    # centre 6: the rise starts at the first sample, the crossing search reaches the end
    # the interior filter leaves out and the full filter (ends fitted) answers
    t = np.arange(41, dtype=float)
    h = np.exp(-0.5 * ((t - centre) / 4.0) ** 2)
    h += 1e-3 * np.random.default_rng(1).standard_normal(h.size)
    got = _features_fit(h, int(np.argmax(h)), 9.4, "rise", 0.5)
    from meshphase.onsets import features
    monkeypatch.setattr(features, "_savgol_interior", lambda x, win: signal.savgol_filter(x, win, 3))
    assert got == _features_fit(h, int(np.argmax(h)), 9.4, "rise", 0.5)
    assert np.all(np.isfinite(got)) and abs(got[0] - centre) < 0.1


def test_gap_in_block_found_by_decimated_check():
    rng = np.random.default_rng(3)
    n = 1 << 18
    t = np.arange(n) / FS
    x = np.maximum(0.0, np.sin(2 * np.pi * 20.0 * t)) ** 8 + 0.01 * rng.standard_normal(n)
    x[100_003] = np.nan                          # inside a block mean
    x[n - 1] = np.inf                            # in the tail a decimation drops
    on = detect_onsets(x, FS)
    assert len(on) > 1000
    assert np.all(np.isfinite(on.times))
    assert not np.any(np.abs(on.index - 100_003) < 1)


@settings(max_examples=80, deadline=None)
@given(n=st.integers(1, 3000), hh=st.integers(1, 400), seed=st.integers(0, 2 ** 32 - 1),
       k=st.integers(0, 200))
def test_unmasked_equals_span_counting(n, hh, seed, k):
    """The noise estimate's mask of the samples away from every maximum: slice by slice
    (a few maxima per _SLICE_SAMPLES samples) or by counting span starts and ends, the same mask."""
    from meshphase.onsets.coarse import _unmasked

    mx = np.unique(np.random.default_rng(seed).integers(0, n, size=k))
    marks = (np.bincount(np.clip(mx - hh, 0, n), minlength=n + 1)
             - np.bincount(np.clip(mx + hh + 1, 0, n), minlength=n + 1))
    ref = np.cumsum(marks[:-1]) == 0
    got = _unmasked(n, mx, hh)
    assert got.dtype == bool and np.array_equal(got, ref)


def test_unmasked_empty():
    from meshphase.onsets.coarse import _unmasked

    assert _unmasked(0, np.empty(0, dtype=np.int64), 3).size == 0
    assert _unmasked(5, np.empty(0, dtype=np.int64), 3).all()
