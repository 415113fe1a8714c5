"""The numba path of the onset stage (:mod:`meshphase.onsets.fastpath`) gives the numpy
path's onsets: the same pulses, times and amplitudes to rounding, widths and flags equal,
through gaps, clipped runs, edges, float32 input and streaming."""

import sys

import numpy as np
import pytest

from meshphase.errors import ProcessingWarning
from meshphase.onsets import (FLAG_CLIPPED, FLAG_EDGE, FLAG_GAP, FLAG_TEMPLATE, OnsetStream,
                              detect_onsets)
from meshphase.onsets import fastpath
from meshphase.onsets.coarse import coarse_decimated
from meshphase.signal.condition import assess_quality

FS = 5120.0
pytestmark = pytest.mark.skipif(not fastpath.HAVE_NUMBA, reason="numba not installed")


def assert_same(a, b):
    """Onsets ``a`` (numba) equal ``b`` (numpy) to rounding."""
    assert len(a) == len(b)
    np.testing.assert_allclose(a.index, b.index, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(a.times, b.times, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(a.amplitude, b.amplitude, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(a.corr, b.corr, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(a.width, b.width)
    np.testing.assert_array_equal(a.flags, b.flags)
    np.testing.assert_array_equal(a.template_id, b.template_id)


def both(x, **kw):
    return detect_onsets(x, FS, engine="numba", **kw), detect_onsets(x, FS, engine="numpy", **kw)


def narrow_train(make_train, n_pulses=3000, rng=0, **kw):
    # pulses ~2 samples wide every 15 samples, band-limited like a DAQ: the dense case
    return make_train(mesh_samples=2.5, spacing_samples=15.0, n_pulses=n_pulses, bandlimit=0.45,
                      rng=rng, **kw)


@pytest.mark.parametrize("snr_db", [12.0, 20.0, 30.0])
def test_dense_train_equal_to_numpy(snr_db, make_train):
    # 12 dB: most of these narrow pulses fall below the threshold, low correlations
    x, _, _ = narrow_train(make_train, snr_db=snr_db, rng=int(snr_db))
    a, b = both(x)
    assert len(a) > (50 if snr_db < 15 else 2500)
    assert_same(a, b)


@pytest.mark.parametrize("mesh, spacing", [(40.0, 240.0), (100.0, 600.0)])
def test_wide_pulses_equal_to_numpy(mesh, spacing, make_train):
    x, _, _ = make_train(mesh_samples=mesh, spacing_samples=spacing, n_pulses=80, rng=4)
    assert_same(*both(x))


def test_gaps_nan_and_dropouts_equal_to_numpy(make_train):
    x, _, _ = narrow_train(make_train, rng=5)
    y = x.copy()
    y[10000:10500] = np.nan
    y[30000:30003] = np.inf
    a, b = both(y, gap_guard=20 / FS, gap_runs=np.array([[20000, 20400]]))
    assert a.has_flag(FLAG_GAP).sum() >= 2
    assert_same(a, b)


def test_clipped_runs_equal_to_numpy(make_train):
    x, _, _ = make_train(n_pulses=60, snr_db=30.0, rng=2)
    y = np.minimum(x, 0.6)
    q = assess_quality(y, FS, warn=False)
    with pytest.warns(ProcessingWarning):
        a = detect_onsets(y, FS, flag_runs=q.clipped_runs, engine="numba")
    with pytest.warns(ProcessingWarning):
        b = detect_onsets(y, FS, flag_runs=q.clipped_runs, engine="numpy")
    assert np.all(a.has_flag(FLAG_CLIPPED) & a.has_flag(FLAG_TEMPLATE))
    assert_same(a, b)


def test_edges_float32_and_polarity_equal_to_numpy(make_train):
    x, truth, _ = narrow_train(make_train, rng=6)
    i = int(truth["contact"][3] * FS) + 1          # cut through the fourth pulse
    cut = x[i:i + 20001]
    a, b = both(cut)
    assert_same(a, b)
    assert a.has_flag(FLAG_EDGE).any() or a.index[0] > 5
    assert_same(*both(cut.astype(np.float32)))
    assert_same(*both(-cut, polarity="negative"))


def test_tiny_input_shorter_than_a_window(make_train):
    x, _, _ = narrow_train(make_train, n_pulses=200, rng=7)
    tpl = detect_onsets(x, FS).templates[0]
    for n in (5, 9, 40):
        assert_same(*both(x[:n], template=tpl))


def test_stream_bit_identical_on_the_numba_path(make_train):
    x, _, _ = narrow_train(make_train, n_pulses=6000, rng=8)
    whole = detect_onsets(x, FS, engine="numba", block=20000 / FS)
    assert len(whole.templates) >= 1 and len(whole) > 5000
    st = OnsetStream(FS, engine="numba", block=20000 / FS)
    rng = np.random.default_rng(0)
    i = 0
    while i < x.size:
        j = min(x.size, i + int(rng.integers(1, 30000)))
        st.feed(x[i:j])
        i = j
    streamed = st.finish()
    for name in ("times", "index", "corr", "amplitude", "width", "flags", "template_id"):
        np.testing.assert_array_equal(getattr(streamed, name), getattr(whole, name), err_msg=name)


def test_auto_takes_the_numba_path_for_dense_blocks(monkeypatch, make_train):
    x, _, _ = narrow_train(make_train, n_pulses=400, rng=9)
    calls = []
    real = fastpath.refine_pulses
    monkeypatch.setattr(fastpath, "refine_pulses", real)
    import meshphase.onsets.engine as engine

    def spy(*args, **kw):
        calls.append(args[1].size)
        return real(*args, **kw)

    monkeypatch.setattr(engine, "refine_pulses", spy)
    with monkeypatch.context() as m:                # numba not loaded in this process
        m.delitem(sys.modules, "numba", raising=False)
        detect_onsets(x, FS)
    assert calls == []                              # 400 pulses: sparse, numpy path
    detect_onsets(x, FS)
    assert sum(calls) >= 350                        # numba loaded: its kernels are cheap and faster
    calls.clear()
    monkeypatch.setattr(fastpath, "DENSE_PULSES", 100)
    a = detect_onsets(x, FS)
    assert calls and sum(calls) >= 350
    assert_same(a, detect_onsets(x, FS, engine="numpy"))
    monkeypatch.setattr(fastpath, "HAVE_NUMBA", False)
    calls.clear()
    assert_same(detect_onsets(x, FS), a)            # no numba: numpy, same onsets
    assert calls == []


def test_dense_rule(monkeypatch):
    # auto: numba for a dense block, or for any block once numba is loaded; never without it
    monkeypatch.setattr(fastpath, "HAVE_NUMBA", True)
    monkeypatch.delitem(sys.modules, "numba", raising=False)
    assert not fastpath.dense("auto", fastpath.DENSE_PULSES - 1)
    assert fastpath.dense("auto", fastpath.DENSE_PULSES)
    assert fastpath.dense("numba", 0) and not fastpath.dense("numpy", 10 ** 9)
    monkeypatch.setitem(sys.modules, "numba", object())
    assert fastpath.dense("auto", 0)
    monkeypatch.setattr(fastpath, "HAVE_NUMBA", False)
    assert not fastpath.dense("auto", 10 ** 9)


def test_coarse_run_maxima_bit_equal():
    rng = np.random.default_rng(1)
    for trial in range(40):
        n = int(rng.integers(1, 3000))
        y = rng.standard_normal(n)
        if trial % 3 == 0:                          # dense: long runs above the threshold
            y += 3.0 * (np.sin(np.arange(n) * rng.uniform(0.3, 2.0)) > -0.3)
        if trial % 5 == 0:
            y = np.round(y)                         # ties between maxima
        w_d, sp = rng.uniform(1.0, 12.0), rng.uniform(1.0, 30.0)
        fast = coarse_decimated(y, w_d, sp, 3.0, True)
        slow = coarse_decimated(y, w_d, sp, 3.0, False)
        np.testing.assert_array_equal(fast[0], slow[0])
        np.testing.assert_array_equal(fast[1], slow[1])
        assert fast[2:] == slow[2:]


def test_kernels_empty_input():
    assert fastpath.run_maxima(np.empty(0), 0.0, 1, 3.0).size == 0
    out = fastpath.refine_pulses(np.zeros(10), np.empty(0, dtype=np.int64), 0, 1, 1, np.eye(3),
                                 1.0, np.array([0]), 1, 0, 1, 0.0, 1.0, 0.5, 0, FLAG_EDGE, 2)
    assert [v.size for v in out] == [0] * 6
    assert out[4].dtype == np.uint8 and out[5].dtype == np.int64


def test_kernels_bad_input():
    with pytest.raises(ValueError, match="1-D"):
        fastpath.run_maxima(np.zeros((3, 3)), 0.0, 1, 3.0)
    with pytest.raises(ValueError, match="t_all"):
        fastpath.refine_pulses(np.zeros(10), np.array([3]), 0, 2, 1, np.eye(3), 1.0,
                               np.array([0]), 1, 0, 1, 0.0, 1.0, 0.5, 0, 1, 2)


def test_engine_option_checked(monkeypatch):
    x = np.zeros(100)
    with pytest.raises(ValueError, match="engine"):
        detect_onsets(x, FS, engine="fast")
    with pytest.raises(ValueError, match="engine"):
        OnsetStream(FS, engine=None)
    monkeypatch.setattr(fastpath, "HAVE_NUMBA", False)
    with pytest.raises(ValueError, match="numba"):
        detect_onsets(x, FS, engine="numba")
    assert len(detect_onsets(x, FS, engine="auto")) == 0


def test_warmup_compiles_or_says_numpy(monkeypatch):
    w = fastpath.warmup()
    assert w["engine"] == "numba" and w["seconds"] >= 0.0
    monkeypatch.setattr(fastpath, "HAVE_NUMBA", False)
    assert fastpath.warmup() == {"engine": "numpy", "seconds": 0.0}
