"""Signal conditioning and quality report (pipeline.condition).

Pulse trains from tests/processing/conftest.py; drift, hum, gaps and clipping are added
here with known values, so every check compares against what was put in.
"""

import json
import math
import warnings

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from pipeline.condition import (ChannelQuality, Conditioned, HumReport, assess_quality,
                                assess_quality_recording, condition_recording, default_band,
                                design_filter, detect_hum, drift_baseline, estimate_noise,
                                estimate_snr, filter_recording, filter_signal, merge_runs,
                                notch_hum, notch_hum_recording, remove_drift,
                                remove_drift_recording)
from pipeline.errors import DataQualityWarning, ProcessingWarning
from pipeline.onsets import FLAG_CLIPPED, FLAG_GAP, detect_onsets_recording
from pipeline.recording import ChannelSpec, Recording

FS = 5120.0               # the pulse trains of conftest.make_train

MESH = FS / 100.0          # the trains below: mesh period 100 samples -> 51.2 Hz


@pytest.fixture(scope="module")
def train(make_train):
    x, truth, shape = make_train(mesh_samples=100.0, spacing_samples=600.0, n_pulses=100,
                                 snr_db=20.0, rng=1)
    return x, truth, shape


def line_power(x, f):
    t = np.arange(x.size) / FS
    return abs(np.mean(x * np.exp(-2j * np.pi * f * t))) ** 2


# ---------------------------------------------------------------- filtering
def test_default_band_relative_to_mesh_frequency():
    assert default_band(FS, 51.2) == pytest.approx((51.2 / 20, 4 * 51.2))
    low, high = default_band(FS, 1000.0)        # 4 f_m above 0.45 fs: no low-pass
    assert low == pytest.approx(50.0) and high is None
    assert default_band(FS) == (0.05, None)
    with pytest.raises(ValueError, match="mesh_freq"):
        default_band(FS, 0.0)
    with pytest.raises(ValueError, match="too high"):
        default_band(FS, 2600.0 * 20)


def test_filter_is_zero_phase_and_keeps_the_pulse(make_train):
    x, _, _ = make_train(mesh_samples=100.0, spacing_samples=600.0, n_pulses=40,
                         snr_db=300.0)               # noise-free: only the filter acts
    y = filter_signal(x, FS, mesh_freq=MESH)
    seg = slice(2000, 20000)
    c = np.correlate(y[seg], x[seg], "full")
    assert int(np.argmax(c)) - (18000 - 1) == 0               # no delay
    # pulse energy sits inside [f_m/20, 4 f_m]: the pulses pass almost unchanged
    d = (y - x)[seg]
    assert np.max(np.abs(d - d.mean())) < 0.05      # the high-pass takes the train's mean
    assert np.corrcoef(y[seg], x[seg])[0, 1] > 0.999


def test_filter_attenuates_out_of_band():
    t = np.arange(1 << 16) / FS
    slow = np.sin(2 * np.pi * 0.1 * t)
    fast = np.sin(2 * np.pi * 1500.0 * t)
    y = filter_signal(slow + fast, FS, low=2.0, high=300.0)
    mid = slice(20000, 45000)
    assert np.std(y[mid]) < 0.01                              # both out of band
    hp = filter_signal(slow + fast, FS, kind="highpass", low=100.0)
    assert np.std(hp[mid]) == pytest.approx(np.std(fast[mid]), rel=0.01)
    lp = filter_signal(slow + fast, FS, kind="lowpass", high=100.0)
    assert np.max(np.abs(lp[mid] - slow[mid])) < 0.01


def test_filter_never_smears_nan():
    x = np.random.default_rng(0).normal(size=20000)
    x[5000:5100] = np.nan
    x[9000:9003] = np.nan                         # short: bridged, then masked back
    x[15000] = np.inf
    y = filter_signal(x, FS, low=5.0, high=500.0)
    assert np.array_equal(np.isnan(y), ~np.isfinite(x))


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 9900), st.integers(1, 300)), max_size=5))
def test_filter_nan_mask_property(gaps):
    x = np.random.default_rng(1).normal(size=10000)
    for a, n in gaps:
        x[a:a + n] = np.nan
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        y = filter_signal(x, FS, low=5.0, high=500.0)
    short = any(issubclass(w.category, DataQualityWarning) for w in rec)
    bad = ~np.isfinite(x)
    assert np.all(np.isnan(y[bad]))                           # never a value in a gap
    if not short:
        assert np.all(np.isfinite(y[~bad]))                   # never NaN outside one
    assert all(issubclass(w.category, DataQualityWarning) for w in rec)


def test_short_segment_between_gaps_warns():
    x = np.random.default_rng(0).normal(size=3000)
    x[1000:1100] = np.nan
    x[1110:1200] = np.nan                       # 10 finite samples in between
    with pytest.warns(DataQualityWarning, match="shorter"):
        y = filter_signal(x, FS, low=5.0, high=500.0)
    assert np.all(np.isnan(y[1100:1110]))


def test_design_filter_and_filter_bad_input():
    with pytest.raises(ValueError, match="low"):
        design_filter(FS, kind="highpass")
    with pytest.raises(ValueError, match="below"):
        design_filter(FS, low=500.0, high=100.0)
    with pytest.raises(ValueError, match="Nyquist"):
        design_filter(FS, kind="lowpass", high=3000.0)
    with pytest.raises(ValueError, match="order"):
        design_filter(FS, kind="lowpass", high=100.0, order=0)
    with pytest.raises(ValueError, match="kind"):
        filter_signal(np.zeros(100), FS, kind="notch")
    with pytest.raises(ValueError, match="1-D"):
        filter_signal(np.zeros((10, 2)), FS)
    with pytest.raises(TypeError, match="numeric"):
        filter_signal(np.array(["a"]), FS)
    with pytest.raises(ValueError, match="lowpass"):
        filter_signal(np.zeros(100), FS, kind="lowpass")
    assert filter_signal(np.zeros(0), FS).shape == (0,)
    assert design_filter(FS, low=1.0, high=100.0).shape[1] == 6


# ---------------------------------------------------------------- drift
@pytest.mark.parametrize("method", ["median", "savgol", "highpass"])
def test_drift_removed_pulses_kept(train, method):
    x, _, _ = train
    t = np.arange(x.size) / FS
    drift = 2.0 + 0.5 * t / t[-1] + 0.3 * np.sin(2 * np.pi * t / 40.0)   # thermal: >> pulses
    y = remove_drift(x + drift, FS, method=method, mesh_freq=MESH)
    mid = slice(3000, x.size - 3000)
    resid = y[mid] - x[mid]
    # what is left of a 2.5-unit drift is a small fraction of the unit pulse height; the
    # high-pass removes the pulse train's mean (~0.09) as well, harmless downstream
    # (savgol averages block medians, so it is not robust to them either)
    robust = method == "median"
    assert abs(np.median(resid)) < (0.03 if robust else 0.12)
    assert np.std(resid) < 0.05
    assert np.max(y[mid]) == pytest.approx(np.max(x[mid]), abs=0.05 if robust else 0.15)


def test_drift_baseline_follows_a_line_exactly():
    n = 50000
    line = 1e-4 * np.arange(n)
    b = drift_baseline(line, FS, window=2.0)
    assert np.max(np.abs(b - line)[2000:-2000]) < 1e-9
    x = line.copy()
    x[1000:30000] = np.nan                      # NaN ignored, kept NaN by remove_drift
    y = remove_drift(x, FS, window=2.0)
    assert np.array_equal(np.isnan(y), np.isnan(x))
    assert np.nanmax(np.abs(y[40000:-2000])) < 1e-9
    assert np.all(np.isnan(drift_baseline(np.full(100, np.nan), FS)))
    assert remove_drift(np.zeros(0), FS).shape == (0,)
    with pytest.raises(ValueError, match="method"):
        remove_drift(x, FS, method="spline")
    with pytest.raises(ValueError, match="window"):
        remove_drift(x, FS, window=-1.0)


# ---------------------------------------------------------------- hum
def test_hum_detected_and_notched(train):
    x, _, _ = train
    t = np.arange(x.size) / FS
    y = x + 0.1 * np.sin(2 * np.pi * 50 * t) + 0.05 * np.sin(2 * np.pi * 150 * t + 1.0)
    rep = detect_hum(y, FS)
    assert isinstance(rep, HumReport) and rep.present and rep.checked
    assert rep.mains == 50.0
    assert set(rep.freqs.tolist()) == {50.0, 150.0}
    z = notch_hum(y, FS)
    for f in (50.0, 150.0):
        assert line_power(z, f) < 1e-3 * line_power(y, f)        # > 30 dB down
    mid = slice(3000, x.size - 3000)
    assert np.std(z[mid] - x[mid]) < 0.03                         # pulses untouched
    json.dumps(rep.to_dict())


def test_no_hum_no_notch_and_60hz(train):
    x, _, _ = train
    assert not detect_hum(x, FS).present
    assert np.array_equal(notch_hum(x, FS), x)
    t = np.arange(x.size) / FS
    rep = detect_hum(x + 0.1 * np.sin(2 * np.pi * 60 * t), FS)
    assert rep.mains == 60.0 and rep.freqs.tolist() == [60.0]
    # a mesh harmonic sitting on 60 Hz is not hum when excluded
    assert not detect_hum(x + 0.1 * np.sin(2 * np.pi * 60 * t), FS, exclude=[60.0]).present
    assert detect_hum(x + 0.1 * np.sin(2 * np.pi * 60 * t), FS, mains=50).mains is None


def test_hum_short_data_and_bad_input():
    short = np.random.default_rng(0).normal(size=2000)
    rep = detect_hum(short, FS)
    assert not rep.checked and not rep.present
    with pytest.warns(ProcessingWarning, match="too short"):
        out = notch_hum(short, FS)
    assert np.array_equal(out, short)
    assert not detect_hum(np.zeros(0), FS).present
    assert notch_hum(np.zeros(0), FS).shape == (0,)
    with pytest.raises(ValueError, match="mains"):
        detect_hum(short, FS, mains=55)
    with pytest.raises(ValueError, match="mains"):
        detect_hum(short, FS, mains="europe")
    with pytest.raises(ValueError, match="freqs"):
        notch_hum(short, FS, freqs=[3000.0])
    with pytest.raises(ValueError, match="q"):
        notch_hum(short, FS, freqs=[50.0], q=0.0)


# ---------------------------------------------------------------- quality
def test_quality_report_finds_gaps_nan_inf_and_clipping(train):
    x, _, _ = train
    y = x.copy()
    y[100:150] = np.nan
    y[1000] = np.inf
    top = np.nanmax(y[np.isfinite(y)])
    y[5000:5008] = top + 1.0                    # the converter's rail
    with pytest.warns(DataQualityWarning, match="gap run"):
        q = assess_quality(y, FS, t0=2.0, name="s1")
    assert q.gap_runs.tolist() == [[100, 150], [1000, 1001]]
    assert q.nan_runs.tolist() == [[100, 150]]
    assert q.clipped_runs.tolist() == [[5000, 5008]]
    assert q.n_gap_samples == 51 and q.n_clipped_samples == 8 and not q.ok
    assert q.runs_time("gap")[0].tolist() == pytest.approx([2.0 + 100 / FS, 2.0 + 150 / FS])
    assert q.bad_runs().tolist() == [[100, 150], [1000, 1001], [5000, 5008]]
    assert q.runs_time("bad").shape == (3, 2)
    d = q.to_dict()
    json.dumps(d)
    assert d["clipped_runs"] == [[5000, 5008]]
    with pytest.raises(ValueError, match="which"):
        q.runs_time("all")


def test_snr_estimate_matches_the_definition(make_train):
    # peak-power SNR 20 log10(A / sigma); the 99.9 % quantile sits near the peaks of
    # these 600-sample-spaced pulses, so the estimate is within ~1.5 dB
    for snr in (15.0, 25.0):
        x, _, _ = make_train(mesh_samples=100.0, spacing_samples=600.0, n_pulses=100,
                             snr_db=snr, rng=2)
        est, a, sig = estimate_snr(x)
        assert sig == pytest.approx(10 ** (-snr / 20), rel=0.05)
        assert est == pytest.approx(snr, abs=1.5)
    assert estimate_noise(np.zeros(0)) != estimate_noise(np.zeros(0))          # NaN
    assert math.isnan(estimate_snr(np.array([1.0]))[0])
    with pytest.raises(ValueError, match="quantile"):
        estimate_snr(np.zeros(10), quantile=1.5)


def test_quality_clean_and_empty(make_train):
    x, _, _ = make_train(n_pulses=20, snr_db=30.0)
    q = assess_quality(x, FS)
    assert q.ok and q.gap_runs.shape == (0, 2) and q.snr_db > 20
    e = assess_quality(np.zeros(0), FS)
    assert e.n_samples == 0 and e.ok and math.isnan(e.snr_db)
    with pytest.warns(DataQualityWarning, match="low SNR"):
        assess_quality(np.random.default_rng(0).normal(size=5000), FS)
    with pytest.raises(ValueError, match="clip_min_run"):
        assess_quality(x, FS, clip_min_run=1)
    with pytest.raises(TypeError, match="name"):
        assess_quality(x, FS, name=3)


def test_merge_runs():
    assert merge_runs([[5, 8], [0, 2], [7, 10], [10, 12], [20, 21]]).tolist() == \
        [[0, 2], [5, 12], [20, 21]]
    assert merge_runs(np.empty((0, 2))).shape == (0, 2)


# ---------------------------------------------------------------- Recording level
def make_rec(train, hum=True, gap=True, clip=True):
    x, _, _ = train
    t = np.arange(x.size) / FS
    y = x + 1.5 + 0.2 * t / t[-1]
    if hum:
        y = y + 0.1 * np.sin(2 * np.pi * 50 * t)
    if gap:
        y[20000:21000] = np.nan
    if clip:
        y[30000:30010] = np.nanmax(y) + 0.5
    tacho = (np.sin(2 * np.pi * t) > 0.99).astype(float)
    return Recording(np.stack([y, tacho], axis=1), FS,
                     [ChannelSpec("sun1", kind="sun"), ChannelSpec("tach", kind="tacho", units="V")],
                     t0=100.0)


def test_recording_wrappers_append_history_and_skip_tacho(train):
    rec = make_rec(train, gap=False, clip=False)
    f = filter_recording(rec, mesh_freq=MESH)
    assert f.history[-1]["step"] == "condition.filter"
    assert f.history[-1]["channels"] == ["sun1"]
    assert f.history[-1]["low_hz"] == pytest.approx(MESH / 20)
    assert np.array_equal(f.channel("tach"), rec.channel("tach"))
    assert not np.array_equal(f.channel("sun1"), rec.channel("sun1"))
    d = remove_drift_recording(rec, channels="sun1", window=5.0)
    assert d.history[-1] == {**d.history[-1], "step": "condition.remove_drift", "window_s": 5.0}
    n = notch_hum_recording(rec)
    assert n.history[-1]["lines_hz"] == {"sun1": [50.0]}
    assert len(rec.history) == 0                                  # input untouched
    with pytest.raises(TypeError, match="Recording"):
        filter_recording(np.zeros(10))
    with pytest.raises(ValueError, match="no channel"):
        filter_recording(rec, channels=["nope"])


def test_condition_recording_end_to_end(train):
    x, truth, _ = train
    rec = make_rec(train)
    with pytest.warns(DataQualityWarning, match="sun1"):
        res = condition_recording(rec, mesh_freq=MESH)
    assert isinstance(res, Conditioned)
    steps = [h["step"] for h in res.recording.history]
    assert steps == ["condition.notch_hum", "condition.remove_drift", "condition.filter",
                     "condition.quality"]
    q = res.quality["sun1"]
    assert set(res.quality) == {"sun1"}
    assert q.gap_runs.tolist() == [[20000, 21000]]
    assert q.clipped_runs.tolist() == [[30000, 30010]]
    assert q.hum is not None and q.hum.freqs.tolist() == [50.0]
    assert q.snr_db == pytest.approx(20.0, abs=2.0)
    assert q.settle > 0
    y = res.recording.channel("sun1")
    assert np.array_equal(np.isnan(y), np.isnan(rec.channel("sun1")))
    good = np.isfinite(y)
    good[19000:22000] = False
    assert np.std((y - x)[good][3000:-3000]) < 0.1              # ~ the noise left in band
    # the onset stage respects the report: nothing in the gap, clipped pulse flagged
    on = detect_onsets_recording(res.recording, "sun1", quality=q)
    idx = on.index
    assert not np.any((idx >= 20000) & (idx < 21000))
    assert np.any(on.has_flag(FLAG_CLIPPED) & (np.abs(idx - 30005) < 600))
    assert np.any(on.has_flag(FLAG_GAP))
    assert on.times[0] > 100.0
    assert json.dumps(res.recording.history)


def test_condition_recording_options_and_bad_input(train):
    rec = make_rec(train, hum=False, gap=False, clip=False)
    res = condition_recording(rec, hum=False, drift=None, lowpass=300.0, highpass=1.0)
    assert [h["step"] for h in res.recording.history] == ["condition.filter", "condition.quality"]
    assert res.recording.history[0]["kind"] == "bandpass"
    q = assess_quality_recording(rec)
    assert list(q) == ["sun1"] and isinstance(q["sun1"], ChannelQuality)
    with pytest.raises(TypeError, match="Recording"):
        condition_recording("rec.h5")
    with pytest.raises(ValueError, match="drift"):
        condition_recording(rec, drift="poly")
    with pytest.raises(ValueError, match="lowpass"):
        condition_recording(rec, lowpass=1e5)
    only_tacho = rec.select(["tach"])
    out = condition_recording(only_tacho)
    assert out.quality == {} and np.array_equal(out.recording.data, only_tacho.data)


def test_remaining_empty_and_bad_inputs():
    assert drift_baseline(np.zeros(0), FS).shape == (0,)
    assert math.isnan(estimate_snr(np.zeros(0))[0])
    with pytest.raises(ValueError, match="1-D"):
        estimate_noise(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="shape"):
        merge_runs([1, 2, 3])
    with pytest.raises(TypeError, match="runs"):
        merge_runs([["a", "b"]])
    with pytest.raises(ValueError, match="fs"):
        drift_baseline(np.zeros(10), 0.0)
    for fn in (remove_drift_recording, notch_hum_recording, assess_quality_recording):
        with pytest.raises(TypeError, match="Recording"):
            fn(np.zeros((10, 1)))
