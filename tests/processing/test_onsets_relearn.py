"""Onset detection speed-ups (issue 13): the template learnt once per operating point
(relearn="auto", meshphase.onsets.relearn) and the one-product decimation, held against the
former per-block learning and the plain block mean."""

import math

import numpy as np
import pytest

from meshphase.bench.processing import match_onsets
from meshphase.onsets import detect_onsets, detect_onsets_stream
from meshphase.onsets.coarse import decimate
from meshphase.onsets.relearn import TemplateFit, good_median, pulse_period, timing_bound
from meshphase.recording import ChannelSpec, Recording

FS = 5120.0


def _crb(truth):
    return float(np.sqrt(np.mean(truth["crb"] ** 2))) * FS


@pytest.mark.parametrize("d", [1, 2, 3, 5, 16, 35])
def test_decimate_equals_the_block_mean(d):
    x = np.random.default_rng(d).normal(size=(10007, 3))
    col = x[:, 1]                                    # a strided column, as rec.channel gives
    m = (col.size // d) * d
    ref = col[:m].reshape(-1, d).mean(axis=1)
    np.testing.assert_allclose(decimate(col, d), ref, rtol=0, atol=1e-14)
    assert decimate(np.zeros(0), d).size == 0
    assert decimate(col[: d - 1], d).size == 0


def test_auto_learns_once_on_a_steady_run_and_keeps_the_accuracy(make_train):
    # 8 analysis blocks of a steady train: learnt once; onsets within a fraction of the
    # timing bound of the per-block templates' (each learnt from ~50 pulses, whose noise
    # is most of the difference: measured median 0.56 bound), same error against truth
    x, truth, _ = make_train(n_pulses=400, snr_db=20.0, rng=31)
    auto = detect_onsets(x, FS, block=2.4)
    block = detect_onsets(x, FS, block=2.4, relearn="block")
    assert len(auto.templates) == 1 and len(block.templates) >= 7
    assert len(auto) == len(block) == truth["onset"].size
    crb = _crb(truth)
    diff = auto.index - block.index
    assert np.median(np.abs(diff)) < 0.8 * crb
    errs = []
    for on in (auto, block):
        it, idt = match_onsets(on.times, truth["onset"], 0.4 * 240 / FS)
        errs.append(((on.times[idt] - truth["onset"][it]) * FS).std())
    assert errs[0] == pytest.approx(errs[1], rel=0.1)
    assert errs[0] < 1.5 * crb


def test_a_reused_template_reuses_its_matcher(make_train, monkeypatch):
    # the matched filter's shifted template columns are built once per template, not per
    # block: on a steady run (one template, 8 blocks) the refinement builds one matcher
    # (the learning builds its own), and the onsets equal those of a matcher per block
    import meshphase.onsets.engine as engine

    x, _, _ = make_train(n_pulses=400, snr_db=20.0, rng=31)
    built = []
    real = engine.Matcher

    class Counting(real):
        def __init__(self, *a):
            built.append(a[1:])
            super().__init__(*a)

    monkeypatch.setattr(engine, "Matcher", Counting)
    auto = detect_onsets(x, FS, block=2.4, engine="numpy")
    assert len(auto.templates) == 1 and len(built) == 1
    fresh = []

    def per_block(self, tpl, k, u):
        fresh.append(k)
        return real(tpl, k, u)

    monkeypatch.setattr(engine.BlockEngine, "_matcher_for", per_block)
    again = detect_onsets(x, FS, block=2.4, engine="numpy")
    assert len(fresh) >= 7
    np.testing.assert_array_equal(again.index, auto.index)
    np.testing.assert_array_equal(again.corr, auto.corr)


def test_auto_relearns_on_a_speed_step(make_train):
    # the speed steps by 10 % after two blocks: the template is learnt again there
    a, ta, _ = make_train(mesh_samples=40, spacing_samples=240, n_pulses=120, snr_db=25.0, rng=1)
    b, tb, _ = make_train(mesh_samples=44, spacing_samples=264, n_pulses=120, snr_db=25.0, rng=2)
    x = np.concatenate([a, b])
    truth = np.concatenate([ta["onset"], tb["onset"] + a.size / FS])
    on = detect_onsets(x, FS, block=a.size / 2 / FS)
    assert 2 <= len(on.templates) <= 3
    fw = np.array([t.fwhm for t in on.templates]) * FS
    assert fw[0] == pytest.approx(32.0, rel=0.05) and fw[-1] == pytest.approx(35.2, rel=0.05)
    it, idt = match_onsets(on.times, truth, 0.3 * 240 / FS)
    assert it.size == truth.size


def test_auto_streamed_equals_whole(make_train):
    x, _, _ = make_train(n_pulses=150, snr_db=20.0, rng=21)
    rec = Recording(x, FS, [ChannelSpec("sun1", kind="sun")])
    whole = detect_onsets(x, FS, block=4.0, channel="sun1")
    streamed = detect_onsets_stream(rec.blocks(0.7, 0.1), "sun1", block=4.0)
    for name in ("times", "index", "corr", "amplitude", "flags", "template_id"):
        np.testing.assert_array_equal(getattr(streamed, name), getattr(whole, name), err_msg=name)


def test_period_of_a_train_with_missed_pulses():
    peaks = np.arange(0, 100 * 50, 50, dtype=np.int64)
    assert pulse_period(peaks) == pytest.approx(50.0)
    holed = np.delete(peaks, [10, 11, 40])          # missed pulses count as whole periods
    assert pulse_period(holed) == pytest.approx(50.0)
    assert pulse_period(np.empty(0, dtype=np.int64)) is None
    assert pulse_period(peaks[:5]) is None
    assert pulse_period(np.zeros(10, dtype=np.int64)) is None          # no interval


def test_fit_checks_and_timing_bound(make_train):
    x, truth, _ = make_train(n_pulses=200, snr_db=20.0, rng=4)
    on = detect_onsets(x, FS)
    tpl = on.templates[0]
    c = good_median(on.corr, on.flags)
    # the bound from the correlations matches the true Cramer-Rao bound within ~25 %
    assert timing_bound(tpl, c) == pytest.approx(_crb(truth), rel=0.25)
    assert math.isinf(timing_bound(tpl, 0.0)) and math.isinf(timing_bound(tpl, -0.5))
    assert timing_bound(tpl, 1.0) == 0.0
    fit = TemplateFit.measure(tpl, on.corr, on.flags, 40.0)
    assert 0 < fit.speed_tol < 0.01
    assert fit.speed_holds(40.0) and fit.speed_holds(40.0 * (1 + 0.5 * fit.speed_tol))
    assert not fit.speed_holds(40.0 * (1 + 2 * fit.speed_tol))
    assert not fit.speed_holds(None)                 # unknown now, known before: re-learn
    assert TemplateFit(0.9, None, 0.0).speed_holds(None)
    assert fit.holds(on.corr, on.flags)
    assert not fit.holds(on.corr - 0.1, on.flags)
    # fewer than 3 unflagged pulses: the median of all of them
    assert good_median(np.array([0.5, 0.7, 0.9]), np.array([1, 0, 1], np.uint8)) == 0.7
