"""The streamed conditioning's taps take a short path when a block is all finite (the SNR
tap's first differences, the drift's block means and its all-NaN test); these tests hold the
short path to the full one bit for bit, on finite blocks and on blocks with NaN, inf and
values near the float64 limit, fed in any chunking."""

from __future__ import annotations

import numpy as np
from hypothesis import example, given, settings
from hypothesis import strategies as st

from meshphase.signal.drift import PendingSamples, block_means, minus_interp
from meshphase.signal.snr import SnrTap


def _finite_diffs(x: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore", over="ignore"):
        d = np.diff(x)
    return d[np.isfinite(d)]


def _tap_parts(x: np.ndarray, cuts, n_keep: int) -> tuple[np.ndarray, int]:
    d_all = _finite_diffs(x)
    tap = SnrTap(x.size, d_all.size)
    tap.step = max(1, -(-d_all.size // n_keep))        # a stride > 1 on short data too
    # (the pulse peak of the first samples may overflow in its median with +-1.7e308 in
    # them, and its quantile then meets inf - inf: warnings of that estimate, not of the
    # differences tested here)
    with np.errstate(over="ignore", invalid="ignore"):
        for a, b in zip(cuts[:-1], cuts[1:]):
            tap.add(x[a:b])
    got = np.concatenate(tap.parts) if tap.parts else np.empty(0)
    return got, tap.step, tap.rank


def _cuts(n: int, sizes) -> list:
    cuts, pos = [0], 0
    for s in sizes:
        pos = min(n, pos + s)
        cuts.append(pos)
    if cuts[-1] < n:
        cuts.append(n)
    return cuts


_specials = st.sampled_from([np.nan, np.inf, -np.inf, 1.7e308, -1.7e308])


@settings(max_examples=60, deadline=None)
@given(n=st.integers(2, 400), sizes=st.lists(st.integers(1, 97), min_size=1, max_size=12),
       n_keep=st.integers(1, 50), seed=st.integers(0, 2**32 - 1),
       bad=st.lists(st.tuples(st.integers(0, 399), _specials), max_size=4))
@example(n=10, sizes=[3, 3], n_keep=3, seed=0, bad=[])
@example(n=2, sizes=[1], n_keep=1, seed=0, bad=[(0, np.nan)])    # a NaN carried over as last
@example(n=10, sizes=[1] * 10, n_keep=4, seed=1, bad=[(4, 1.7e308), (5, -1.7e308)])
@example(n=2, sizes=[1], n_keep=1, seed=0, bad=[(0, 1.7e308), (1, 1.7e308)])  # peak: inf - inf
def test_snr_tap_keeps_the_strided_finite_differences(n, sizes, n_keep, seed, bad):
    x = np.random.default_rng(seed).normal(size=n)
    for i, v in bad:
        x[i % n] = v
    got, step, rank = _tap_parts(x, _cuts(n, sizes), n_keep)
    want = _finite_diffs(x)
    assert rank == want.size
    np.testing.assert_array_equal(got, want[::step])


def test_snr_tap_on_empty_and_single_sample_blocks():
    x = np.arange(7.0) ** 2
    got, step, rank = _tap_parts(x, [0, 0, 1, 1, 2, 7, 7], 3)
    np.testing.assert_array_equal(got, np.diff(x)[::step])
    assert rank == 6


@settings(max_examples=60, deadline=None)
@given(n=st.integers(1, 300), b=st.integers(1, 40), seed=st.integers(0, 2**32 - 1),
       bad=st.lists(st.tuples(st.integers(0, 299), st.sampled_from([np.nan, 1e300, -1e300])),
                    max_size=3))
def testblock_means_finite_path_equals_the_masked_one(n, b, seed, bad):
    x = np.random.default_rng(seed).normal(size=n) * 1e3
    for i, v in bad:
        x[i % n] = v
    x = np.where(np.isfinite(x), x, np.nan)            # as the callers hand it over
    mean, cent = block_means(x, b)
    nb = -(-n // b)
    for j in range(nb):
        blk = x[j * b:(j + 1) * b]
        fin = np.isfinite(blk)
        want = np.where(fin, blk, 0.0).sum() / fin.sum() if fin.any() else np.nan
        np.testing.assert_allclose(mean[j], want, rtol=1e-12)
        assert cent[j] == 0.5 * (j * b + min((j + 1) * b, n) - 1)
    if n >= b and np.isfinite(x[: (n // b) * b]).all():   # the finite path: the rows' own sums
        rows = x[: (n // b) * b].reshape(-1, b)
        np.testing.assert_array_equal(mean[: n // b], rows.sum(axis=1) / b)


def test_pending_holds_all_nan_stretches_as_lengths_only():
    p = PendingSamples()
    p.add(np.full(100, np.nan))
    x = np.full(100, np.nan)
    x[50] = 1.0                                        # NaN at both ends, not all NaN
    p.add(x)
    p.add(np.empty(0))
    assert isinstance(p.parts[0], int) and isinstance(p.parts[1], np.ndarray)
    out = p.take(200)
    assert np.isnan(out[:150]).all() and out[150] == 1.0 and np.isnan(out[151:]).all()


@settings(max_examples=150, deadline=None)
@given(n=st.integers(0, 6000), a=st.integers(0, 2**40), n_knots=st.integers(1, 12),
       spacing=st.integers(1, 3000), shift=st.floats(-4000.0, 4000.0), half=st.booleans(),
       seed=st.integers(0, 2**32 - 1))
@example(n=5000, a=0, n_knots=4, spacing=1000, shift=0.0, half=False, seed=0)   # knots on samples
def testminus_interp_equals_numpy_interp_bit_for_bit(n, a, n_knots, spacing, shift, half,
                                                      seed):
    # the drift's baseline subtracted interval by interval: numpy's own arithmetic, so the
    # same bits as x - np.interp on the sample indices, for knots on samples, on halves and
    # at arbitrary positions, before, inside and beyond the block, sparse and dense
    rng = np.random.default_rng(seed)
    x = rng.normal(size=n) * 10.0 ** rng.integers(-6, 4)
    steps = rng.uniform(0.5, 1.5, n_knots) * spacing
    xp = a + shift + np.cumsum(steps)
    if half:
        xp = np.round(2.0 * xp) / 2.0
        xp = np.unique(xp)
    fp = rng.normal(size=xp.size) * 10.0 ** rng.integers(-6, 4)
    want = x - np.interp(np.arange(a, a + n, dtype=np.float64), xp, fp)
    got = minus_interp(x, a, xp, fp)
    np.testing.assert_array_equal(got, want)


def testminus_interp_empty_non_finite_and_dense_knots():
    assert minus_interp(np.empty(0), 5, np.array([0.0, 1e4]), np.array([1.0, 2.0])).size == 0
    x = np.arange(3000.0)
    xp = np.array([100.0, 1200.0, 2500.0])
    for fp in (np.array([1.0, np.nan, 3.0]), np.array([1.0, np.inf, 3.0])):   # numpy's rules
        with np.errstate(invalid="ignore"):
            want = x - np.interp(np.arange(7, 3007.0), xp, fp)
        np.testing.assert_array_equal(minus_interp(x, 7, xp, fp), want)
    dense = np.arange(0.0, 3000.0, 10.0)                 # knots 10 samples apart: np.interp
    fp = np.sin(dense)
    np.testing.assert_array_equal(minus_interp(x, 0, dense, fp),
                                  x - np.interp(np.arange(3000.0), dense, fp))
    twice = np.array([100.0, 1200.0, 1200.0, 2500.0])    # a repeated knot: numpy's rule
    fp = np.array([1.0, 2.0, 5.0, 3.0])
    np.testing.assert_array_equal(minus_interp(x, 0, twice, fp),
                                  x - np.interp(np.arange(3000.0), twice, fp))
    one = minus_interp(x, 0, np.array([50.0]), np.array([2.0]))  # a single knot: constant
    np.testing.assert_array_equal(one, x - 2.0)
