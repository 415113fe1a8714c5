"""The conditioning steps as block filters (meshphase.signal.blocks, zero_phase, drift, snr):
pushed in any blocks they give what the whole-array functions give, which are the same
filters pushed the whole array; and the helpers they share, on empty and bad input."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from meshphase.errors import DataQualityWarning
from meshphase.signal.blocks import ConditioningChain, Identity, push_chains, run_whole
from meshphase.signal.condition import (band_limit, check_freq, design_filter, drift_highpass, filter_signal,
                                        notch_settle, remove_drift, resolve_band, settle_time)
from meshphase.signal.drift import (DriftFilter, PendingSamples, block_means, block_medians, drift_baseline,
                                    drift_window)
from meshphase.signal.flat_runs import FlatCandidates, check_false_alarm
from meshphase.signal.quality import ChannelQuality, RunTracker, rail_mask, warn_quality
from meshphase.signal.runs import EqualRuns, as_count, as_samples, equal_runs, find_runs
from meshphase.signal.snr import SnrTap, estimate_snr, finite_pairs, subsample
from meshphase.signal.zero_phase import ZeroPhase, apply_finite, push_pair

FS = 1000.0


def _signal(n=20000, seed=3):
    rng = np.random.default_rng(seed)
    t = np.arange(n) / FS
    x = 0.3 * t + np.sin(2 * np.pi * 7.0 * t) ** 9 + 0.05 * rng.normal(size=n)
    x[5000:5003] = np.nan                        # bridged
    x[12000:12400] = np.nan                      # splits
    return x


def _blocks(filt, x, sizes):
    out, a, k = [], 0, 0
    while a < x.size:
        b = min(x.size, a + sizes[k % len(sizes)])
        out.append(filt.push(x[a:b]))
        a, k = b, k + 1
    out.append(filt.flush())
    return np.concatenate(out)


# ------------------------------------------------------------------ the protocol
def test_run_whole_and_identity():
    x = np.arange(5.0)
    assert run_whole(Identity(), x) is x
    assert run_whole(Identity(), np.empty(0)).size == 0
    assert Identity().flush().size == 0
    with pytest.raises(AttributeError):
        run_whole(object(), x)                     # not a block filter


def test_filter_signal_is_the_zero_phase_filter_pushed_whole():
    x = _signal()
    sos = design_filter(FS, kind="bandpass", low=1.0, high=40.0)
    whole = filter_signal(x, FS, kind="bandpass", low=1.0, high=40.0)
    zp = ZeroPhase(sos, x.size, what="t", engine="auto")
    np.testing.assert_array_equal(run_whole(zp, x), whole)
    blocks = _blocks(ZeroPhase(sos, x.size, what="t", chunk=1500), x, [777, 3001, 50])
    fin = np.isfinite(whole)
    assert np.array_equal(np.isfinite(blocks), fin)
    assert np.max(np.abs(blocks[fin] - whole[fin])) < 1e-12 * np.nanmax(np.abs(x))


def test_zero_phase_empty_short_and_notes():
    sos = design_filter(FS, kind="highpass", low=5.0)
    zp = ZeroPhase(sos, 0, what="t")
    assert zp.push(np.empty(0)).size == 0 and zp.flush().size == 0
    short = ZeroPhase(sos, 10, what="short", warn=True)
    with pytest.warns(DataQualityWarning, match="shorter"):
        y = run_whole(short, np.ones(10))
    assert y.shape == (10,) and np.isnan(y).all()
    runs, note = short.through_gaps(np.empty((0, 2), dtype=np.int64))
    assert runs.tolist() == [[0, 10]] and "short" in note
    long = ZeroPhase(sos, 1000, what="t")
    assert long.through_gaps(np.empty((0, 2), dtype=np.int64))[1] is None
    with pytest.raises(ValueError):
        ZeroPhase(np.ones((2, 5)), 100, what="t")            # not second-order sections


def test_apply_finite_empty_and_bad():
    assert apply_finite(np.empty(0), lambda s: s, min_len=3, fill_max=2, what="t").size == 0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        y = apply_finite(np.array([1.0, 2.0]), lambda s: s, min_len=3, fill_max=2, what="t",
                         warn=False)
    assert np.isnan(y).all()
    x = np.array([1.0, np.nan, 3.0, 4.0, 5.0])
    y = apply_finite(x, lambda s: 2 * s, min_len=1, fill_max=1, what="t")
    assert np.isnan(y[1]) and y[0] == 2.0 and y[4] == 10.0
    with pytest.raises(TypeError):
        apply_finite(x, None, min_len=1, fill_max=1, what="t")


def test_push_pair_equals_two_pushes():
    x = _signal()
    sos = design_filter(FS, kind="lowpass", high=40.0)
    a, b = ZeroPhase(sos, x.size, what="a", chunk=2000), ZeroPhase(sos, x.size, what="b", chunk=2000)
    c = ZeroPhase(sos, x.size, what="c", chunk=2000)
    ya, yb = push_pair(a, x[:9000], b, 2 * x[:9000])
    np.testing.assert_array_equal(ya, c.push(x[:9000]))
    np.testing.assert_array_equal(yb, 2 * ya)
    ea, eb = push_pair(a, np.empty(0), b, np.empty(0))           # nothing new: nothing due
    assert ea.size == 0 and eb.size == 0
    with pytest.raises(AttributeError):
        push_pair(a, x[:10], None, x[:10])


# ------------------------------------------------------------------ drift
@pytest.mark.parametrize("method,period", [("median", None), ("savgol", None), ("median", 0.5)])
def test_drift_filter_in_blocks_equals_the_whole_array_bit_for_bit(method, period):
    x = _signal()
    whole = remove_drift(x, FS, method=method, window=2.0, pulse_period=period)
    f = DriftFilter(x.size, FS, method=method, window=2.0, pulse_period=period)
    np.testing.assert_array_equal(_blocks(f, x, [1234, 99, 4000]), whole)
    base = drift_baseline(x, FS, method=method, window=2.0, pulse_period=period)
    g = DriftFilter(x.size, FS, method=method, window=2.0, pulse_period=period, output="baseline")
    np.testing.assert_array_equal(_blocks(g, x, [501, 7777]), base)
    assert np.nanmax(np.abs(base)) > 0.1                     # the 0.3/s drift is there


def test_drift_filter_empty_all_nan_and_bad():
    f = DriftFilter(0, FS, method="median", window=1.0, pulse_period=None)
    assert f.push(np.empty(0)).size == 0 and f.flush().size == 0
    g = DriftFilter(100, FS, method="median", window=0.02, pulse_period=None)
    assert np.isnan(run_whole(g, np.full(100, np.nan))).all()
    assert drift_baseline(np.empty(0), FS).size == 0
    with pytest.raises(ValueError):
        DriftFilter(10, FS, method="median", window=1.0, pulse_period=None, output="both")
    with pytest.raises(ValueError):
        DriftFilter(10, FS, method="median", window=1.0, pulse_period=-1.0)


def test_drift_window_and_block_values():
    assert drift_window(3.0, 50.0) == 3.0
    assert drift_window(None, 50.0) == pytest.approx(20.0 / 50.0)
    assert drift_window(None, None) == 10.0
    with pytest.raises(ValueError):
        drift_window(-1.0, None)
    for fn in (block_medians, block_means):
        v, c = fn(np.empty(0), 4)
        assert v.size == 0 and c.size == 0
    v, c = block_means(np.array([1.0, 3.0, np.nan, np.nan, 5.0]), 2)
    assert v[0] == 2.0 and np.isnan(v[1]) and v[2] == 5.0 and c.tolist() == [0.5, 2.5, 4.0]
    v, _ = block_medians(np.array([1.0, 2.0, 30.0, np.inf, np.nan, 4.0]), 3)
    assert v[0] == 2.0
    with pytest.raises(ZeroDivisionError):
        block_means(np.ones(4), 0)


def test_pending_samples_holds_nan_runs_as_lengths():
    p = PendingSamples()
    p.add(np.empty(0))
    assert p.n == 0
    p.add(np.full(100, np.nan))
    p.add(np.arange(3.0))
    assert isinstance(p.parts[0], int) and p.n == 103
    out = p.take(101)
    assert np.isnan(out[:100]).all() and out[100] == 0.0 and p.start == 101
    with pytest.raises(IndexError):
        p.take(5)                                  # only 2 held


# ------------------------------------------------------------------ snr
def test_snr_tap_in_blocks_equals_estimate_snr():
    x = remove_drift(_signal(), FS, window=2.0)
    whole = estimate_snr(x)
    bad = find_runs(~np.isfinite(x))
    tap = SnrTap(x.size, finite_pairs(bad, x.size))
    for a in range(0, x.size, 777):
        tap.add(x[a:a + 777])
    assert tap.result() == whole and np.isfinite(whole[0]) and whole[0] > 10.0


def test_snr_helpers_empty_and_bad():
    assert all(np.isnan(v) for v in estimate_snr(np.empty(0)))
    assert finite_pairs(np.empty((0, 2)), 1) == 0 and finite_pairs(np.empty((0, 2)), 5) == 4
    assert finite_pairs(np.array([[1, 2]]), 5) == 2                       # pairs 0 and 1 lost
    assert subsample(np.empty(0)).size == 0 and subsample(np.arange(10.0), 3).tolist() == [0, 4, 8]
    tap = SnrTap(10, 3)
    tap.add(np.arange(10.0))                                          # 9 differences, not 3
    with pytest.raises(RuntimeError, match="expected 3"):
        tap.result()
    with pytest.raises(ValueError):
        estimate_snr(np.ones(10), quantile=1.5)


# ------------------------------------------------------------------ the chain
def test_conditioning_chain_masks_dropouts_and_bad_input():
    n = 3000
    x = np.sin(np.arange(n) / 9.0)
    snr = SnrTap(n, None)
    chain = ConditioningChain(n, dropouts=np.array([[100, 200]]), notch=None, drift=Identity(),
                              snr=snr, band=None)
    y = np.concatenate([push_chains([chain], [x[a:a + 700]])[0] for a in range(0, n, 700)])
    assert np.isnan(y[100:200]).all() and np.array_equal(y[:100], x[:100])
    assert push_chains([], []) == []
    with pytest.raises(AttributeError):
        push_chains([None], [x])


# ------------------------------------------------------------------ band and settle helpers
def test_band_helpers():
    assert band_limit(FS, None, None, None) is None
    kind, low, high, sos = band_limit(FS, 20.0, "auto", None)
    assert (kind, low, high) == ("lowpass", None, 80.0) and sos.shape[1] == 6
    assert resolve_band(FS, "bandpass", 1.0, None, None)[0] == "highpass"
    assert settle_time(None, None) == 0.0 and settle_time(0.5, 40.0) == 4.0
    assert notch_settle([]) == 0.0 and notch_settle([50.0, 100.0], 30.0) == pytest.approx(60 / (np.pi * 50))
    assert drift_highpass(FS, 10.0).shape == (1, 6)
    with pytest.raises(ValueError, match="Nyquist"):
        check_freq(600.0, "f", FS)
    with pytest.raises(ValueError):
        band_limit(FS, None, "maybe", None)
    with pytest.raises(ValueError):
        drift_highpass(FS, 0.0)


# ------------------------------------------------------------------ quality helpers
def test_quality_helpers_empty_and_bad():
    e = np.empty((0, 2), dtype=np.int64)
    clean = ChannelQuality("g", FS, 0.0, 10, e, e.copy(), e.copy())
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warn_quality(clean, 6.0)                                      # clean: no warning
    gappy = ChannelQuality("g", FS, 0.0, 10, np.array([[2, 4]]), e.copy(), e.copy())
    with pytest.warns(DataQualityWarning, match="1 gap run"):
        warn_quality(gappy, 6.0)
    with pytest.raises(AttributeError):
        warn_quality(None, 6.0)
    assert rail_mask(np.empty(0), 1.0, 0.0, 0.0).size == 0
    assert rail_mask(np.array([0.0, 0.5, 1.0]), 1.0, 0.0, 0.0).tolist() == [True, False, True]
    t = RunTracker()
    t.add(np.empty(0, dtype=bool))
    assert t.runs().shape == (0, 2)
    t.add(np.array([False, True]))
    t.add(np.array([True, False, True]))
    assert t.runs().tolist() == [[1, 3], [4, 5]]


def test_runs_and_flat_helpers_empty_and_bad():
    assert as_samples(np.empty(0)).dtype == np.float64
    with pytest.raises(TypeError):
        as_samples(np.array(["a"]))
    with pytest.raises(ValueError):
        as_samples(np.ones((2, 2)))
    assert as_count(3, "n", 2) == 3
    with pytest.raises(TypeError):
        as_count(True, "n", 0)
    with pytest.raises(ValueError):
        as_count(1, "n", 2)
    assert check_false_alarm(0.5) == 0.5
    with pytest.raises(ValueError):
        check_false_alarm(1.0)
    with pytest.raises(TypeError):
        check_false_alarm("x")
    r = EqualRuns()
    assert r.add(np.empty(0))[0].size == 0 and r.finish()[0].size == 0
    x = np.array([1.0, 2.0, 2.0, 2.0, 3.0, 3.0])
    got = [r.add(x[:3]), r.add(x[3:]), r.finish()]
    starts = np.concatenate([g[0] for g in got])
    stops = np.concatenate([g[1] for g in got])
    assert np.stack([starts, stops], 1).tolist() == equal_runs(x).tolist() == [[1, 4], [4, 6]]
    c = FlatCandidates(0, 3)
    c.add(np.empty(0))
    c.finish()
    assert c.result()[0].shape == (0, 2)
    c = FlatCandidates(8, 3, window=2)
    c.add(np.array([1.0, 5.0, 5.0, 5.0]))
    c.add(np.array([5.0, 2.0, 3.0, 4.0]))
    c.finish()
    runs, values, lookup = c.result()
    assert runs.tolist() == [[1, 5]] and values.tolist() == [5.0]
    assert lookup[np.array([0, 3, 6])].tolist() == [1.0, 5.0, 3.0]
    with pytest.raises(RuntimeError, match="did not keep"):
        lookup[np.array([7])]
