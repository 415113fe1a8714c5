"""The streaming stages (meshphase.run.stream) against the whole-array functions they replace.

Tolerances (claims about the method, see pipeline/run/stream.py):

* quality reports (gaps, dropouts, clipping, thresholds): exact -- the same statistics and
  the same classification, only accumulated over blocks;
* conditioned samples: the zero-phase filters run on windows overlapping by the decay length
  of their slowest pole (1e-15): the transient of an artificial window edge is below ~1e-13
  of the signal where samples are kept. Asserted: 1e-11 of the channel's amplitude for the
  default chain (median drift; measured ~2e-13), 1e-9 for the high-pass drift option (its
  0.36 Hz pole starts from the raw drift level, tens of times the conditioned amplitude;
  measured ~1e-11);
* onset times: 1e-6 of a sample. The matched filter times a pulse by a smooth function of
  its samples, so a 1e-11 relative change of the samples moves an onset by ~1e-11 of the
  pulse width (measured < 1e-10 samples); 1e-6 leaves margin and is still 100 times below
  the detector's noise-free resolution (stages.ONSET_RESOLUTION, 1e-4 of the FWHM);
* SNR and noise estimates: relative 1e-9 (medians and quantiles of samples equal to the
  tolerance above).
"""

import math
import os
import tracemalloc
import warnings

import numpy as np
import pytest
from scipy import signal

from meshphase import io

from meshphase.signal import iir
from meshphase.conditioning import condition_recording
from meshphase.signal.condition import drift_baseline, quality_from_scan
from meshphase.errors import DataQualityWarning, ProcessingWarning
from meshphase.onsets import OnsetStream, detect_onsets, detect_onsets_recording
from meshphase.signal.quality import ChannelScan, FlatScan, channel_quality, classify_flat_runs
from meshphase.recording import ChannelSpec, Recording
from meshphase.run.stream import (ChannelPlan, FileSource, MemorySource, StreamedRecording,
                                  condition_stream, scan_source, stream_memory)
from meshphase.signal.zero_phase import ZeroPhase, apply_finite, filter_overlap, finite_apply_gaps
from meshphase.synthetic import generate
from meshphase.synthetic.scenarios import seed_rig_gearset, seed_rig_speeds

BLOCK = 4000            # samples: ~40 blocks over 30 s at 5120 Hz, many more filter windows


def _mesh():
    """(mesh frequency [Hz], pulse-train period [s]) of the seed rig's sun and ring gauges."""
    g = seed_rig_gearset()
    sp = seed_rig_speeds(g)
    out = {}
    for gear, z, w in (("sun", g.z_sun, sp.sun), ("ring", g.z_ring, sp.ring)):
        fm = z * abs(w - sp.carrier) / (2 * math.pi)
        out[gear] = (fm, z / fm)            # one relative revolution: every planet passes once
    return out


@pytest.fixture(scope="module")
def faulty():
    """30 s of the realistic rig (hum, drift, 1/f noise, 24-bit) with dropouts (zeros, a held
    value), NaN gaps long and short (some bridged by the filters) and a long gap on the
    ring gauge that spans several blocks and drift blocks."""
    rec, _ = generate("rig_realistic", seed=5, duration=30.0)
    data = rec.data.copy()
    s, r = rec.index("sun"), rec.index("ring")
    data[20000:20040, s] = 0.0
    data[50000:50300, s] = data[49999, s]
    data[90000:90005, s] = np.nan
    data[110000:113000, s] = np.nan
    data[130000:130003, s] = np.nan
    data[130010:130012, s] = np.nan
    data[3999:4001, s] = np.nan                  # across a block edge
    data[60000:95000, r] = np.nan                # several blocks of gap
    data[120000:120010, r] = np.inf
    return rec.replace_data(data)


def _whole(rec, drift="median"):
    """The whole-array path: condition_recording per gear, detect_onsets_recording."""
    out = {}
    for ch, (fm, per) in _mesh().items():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DataQualityWarning)
            c = condition_recording(rec, channels=[ch], mesh_freq=fm, pulse_period=per,
                                    drift=drift)
        with warnings.catch_warnings(record=True) as wl:
            warnings.simplefilter("always")
            on = detect_onsets_recording(c.recording, ch, quality=c.quality[ch], mesh_freq=fm)
        out[ch] = (c.recording.channel(ch), c.quality[ch], on, [str(w.message) for w in wl])
    return out


def _streamed(rec, drift="median", block=BLOCK, filter_engine="auto"):
    src = MemorySource(rec)
    scan = scan_source(src, conditioned=["sun", "ring"], tacho="tacho", block=block)
    plans = [ChannelPlan(ch, mesh_freq=fm, pulse_period=per, group=ch, onsets=True,
                         onset_kwargs={"mesh_freq": fm}) for ch, (fm, per) in _mesh().items()]
    got = {ch: np.full(rec.n_samples, -1.0) for ch in ("sun", "ring")}

    def keep(name, a, y):
        got[name][a:a + y.size] = y

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataQualityWarning)
        res = condition_stream(src, scan, plans, drift=drift, block=block, on_samples=keep,
                               filter_engine=filter_engine)
    return scan, res, got


@pytest.mark.parametrize("drift,sample_tol", [("median", 1e-11), ("savgol", 1e-11),
                                              ("highpass", 1e-9)])
def test_streamed_conditioning_and_onsets_equal_the_whole_array(faulty, drift, sample_tol):
    ref = _whole(faulty, drift)
    scan, res, got = _streamed(faulty, drift)
    assert res.n_blocks == math.ceil(faulty.n_samples / BLOCK)
    # the detector's warnings are kept for the onsets stage to issue
    assert sorted(m for _, m in res.warnings) == sorted(m for r in ref.values() for m in r[3])
    for ch, (y_ref, q_ref, on_ref, _) in ref.items():
        y, q, on = got[ch], res.quality[ch], res.onsets[ch]
        # the conditioned samples: NaN exactly where the whole array's are, equal elsewhere
        fin = np.isfinite(y_ref)
        assert np.array_equal(np.isfinite(y), fin)
        scale = np.max(np.abs(y_ref[fin]))
        assert np.max(np.abs(y[fin] - y_ref[fin])) <= sample_tol * scale
        # the quality report: exact, but for the estimates
        for f in ("gap_runs", "nan_runs", "clipped_runs", "dropout_runs", "conditioned_gap_runs"):
            np.testing.assert_array_equal(getattr(q, f), getattr(q_ref, f), err_msg=f)
        assert q.dropout_min_run == q_ref.dropout_min_run and q.settle == q_ref.settle
        np.testing.assert_array_equal(q.hum.freqs, q_ref.hum.freqs)
        for f in ("snr_db", "noise_rms", "signal_peak"):
            assert getattr(q, f) == pytest.approx(getattr(q_ref, f), rel=1e-9), f
        # the onsets
        assert len(on) == len(on_ref) > 5
        np.testing.assert_array_equal(on.flags, on_ref.flags)
        np.testing.assert_array_equal(on.template_id, on_ref.template_id)
        assert np.max(np.abs(on.times - on_ref.times)) * faulty.fs < 1e-6
        np.testing.assert_allclose(on.amplitude, on_ref.amplitude, rtol=1e-9)
    # the planted faults are there (the test exercises what it claims to)
    q = res.quality["sun"]
    assert len(q.dropout_runs) == 2 and len(q.gap_runs) >= 4 and q.hum.present
    assert len(res.quality["ring"].gap_runs) == 2


@pytest.mark.parametrize("n_threads", [1, 3])
@pytest.mark.parametrize("where", ["chain", "onsets"])
def test_a_failure_in_a_chain_or_an_onset_detector_ends_the_pass_with_its_error(
        faulty, monkeypatch, where, n_threads):
    """The onsets take a block while the workers filter the next one: a chain that fails
    (on a worker) or an onset detector that fails (here) ends the pass with that error,
    the other block's work finished first and no reading thread left behind."""
    import threading

    from meshphase.run import stream
    from meshphase.runtime.threads import threads_limited

    calls = {"n": 0}
    target = stream.push_chains if where == "chain" else OnsetStream.feed
    # the chains are pushed every block (two side by side per call); the onsets get the
    # chains' output in larger pieces (the filters' look-ahead): four over this record
    at = 5 if where == "chain" else 2

    def failing(self, x):
        calls["n"] += 1
        if calls["n"] == at:
            raise RuntimeError(f"{where} failed at call {at}")
        return target(self, x)

    if where == "chain":
        monkeypatch.setattr(stream, "push_chains", failing)
    else:
        monkeypatch.setattr(OnsetStream, "feed", failing)
    with threads_limited(n_threads), pytest.raises(RuntimeError, match=f"{where} failed"):
        _streamed(faulty)
    assert calls["n"] >= at
    assert not [t for t in threading.enumerate() if t.name == "meshphase-read"]


@pytest.mark.parametrize("drift", ["median", "highpass"])
def test_streamed_conditioning_on_threads_equals_the_serial_stream(faulty, drift):
    """The channels' chains run side by side on worker threads (meshphase.runtime.threads), each
    whole on one thread per block: the samples, quality and onsets are the serial run's to
    the last bit, and the detectors' warnings are the same."""
    from meshphase.runtime.threads import threads_limited

    with threads_limited(1):
        _, res1, got1 = _streamed(faulty, drift)
    with threads_limited(3):
        _, res3, got3 = _streamed(faulty, drift)
    for ch in ("sun", "ring"):
        assert np.array_equal(got1[ch], got3[ch], equal_nan=True)
        assert np.array_equal(res1.onsets[ch].times, res3.onsets[ch].times)
        assert res1.quality[ch].snr_db == res3.quality[ch].snr_db
        # the hum search runs its channels side by side too: the same reports bit for bit
        h1, h3 = res1.quality[ch].hum, res3.quality[ch].hum
        assert np.array_equal(h1.freqs, h3.freqs) and h1.mains == h3.mains
        assert np.array_equal(h1.excess_db, h3.excess_db, equal_nan=True)
    assert res1.quality["sun"].hum.present                  # the rig's hum was searched for
    assert sorted(m for _, m in res1.warnings) == sorted(m for _, m in res3.warnings)


@pytest.mark.skipif(not iir.HAVE_NUMBA, reason="numba is not installed")
@pytest.mark.parametrize("drift", ["median", "highpass"])
def test_streamed_conditioning_with_numba_filters_equals_scipy(faulty, drift):
    """The filters on either engine (meshphase.signal.iir): the same operations in the same order,
    so the conditioned samples agree to 1e-12 of the amplitude (bit for bit on x86-64; see
    tests/processing/test_iir.py) and the onsets to 1e-6 of a sample, as above."""
    _, res_s, got_s = _streamed(faulty, drift, filter_engine="scipy")
    _, res_n, got_n = _streamed(faulty, drift, filter_engine="numba")
    for ch in ("sun", "ring"):
        a, b = got_s[ch], got_n[ch]
        assert np.array_equal(np.isnan(a), np.isnan(b))
        ok = np.isfinite(a)
        np.testing.assert_allclose(b[ok], a[ok], rtol=0.0, atol=1e-12 * np.max(np.abs(a[ok])))
        ta, tb = res_s.onsets[ch].times, res_n.onsets[ch].times
        assert ta.size == tb.size and ta.size > 0
        np.testing.assert_allclose(tb, ta, rtol=0.0, atol=1e-6 / faulty.fs)


@pytest.mark.skipif(not iir.HAVE_NUMBA, reason="numba is not installed")
@pytest.mark.parametrize("n_threads", [1, 3])
def test_two_chains_of_one_group_filter_side_by_side(n_threads):
    """Two gauges of one gear (one group, one pulse period: their drift-removed windows
    coincide) are filtered in one sweep where their windows hold no gap
    (iir.filter_extended_pair), each alone where one does: the samples and onsets are those of
    each chain alone, bit for bit (the same operations on each channel), and agree with the
    scipy engine to 1e-12 of the amplitude."""
    from dataclasses import replace as dc_replace

    from meshphase.runtime.threads import threads_limited

    base, _ = generate("rig_realistic", seed=5, duration=30.0)     # no gaps: windows pair
    s = base.index("sun")
    twin = base.data[:, s] * 0.8 + 1e-7
    twin[110000:110400] = np.nan                   # a gap of its own: those windows go alone
    data = np.column_stack([base.data, twin])
    specs = list(base.channels) + [dc_replace(base.channels[s], name="sun2", tooth=3)]
    rec = Recording(data, base.fs, specs, base.t0)
    fm, per = _mesh()["sun"]
    plans = [ChannelPlan(ch, mesh_freq=fm, pulse_period=per, group="sun", onsets=True,
                         onset_kwargs={"mesh_freq": fm}) for ch in ("sun", "sun2")]
    src = MemorySource(rec)

    def run(engine, one_by_one=False):
        # (condition_stream lets go of the scan's hum windows: a fresh scan every run)
        scan = scan_source(src, conditioned=["sun", "sun2"], tacho="tacho", block=BLOCK)
        got = {ch: np.full(rec.n_samples, -1.0) for ch in ("sun", "sun2")}

        def keep(name, a, y):
            got[name][a:a + y.size] = y

        with pytest.MonkeyPatch.context() as mp, warnings.catch_warnings():
            warnings.simplefilter("ignore", DataQualityWarning)
            if one_by_one:
                from meshphase.run import stream

                mp.setattr(stream, "_chain_pairs", lambda ps: [(p,) for p in ps])
            mp.setattr(iir, "filter_extended_pair", counted)
            with threads_limited(n_threads):
                res = condition_stream(src, scan, plans, block=BLOCK, on_samples=keep,
                                       filter_engine=engine)
        return res, got

    pairs = {"n": 0}
    pair = iir.filter_extended_pair

    def counted(*a, **k):
        pairs["n"] += 1
        return pair(*a, **k)

    res_p, got_p = run("numba")
    n_joint = pairs["n"]
    res_1, got_1 = run("numba", one_by_one=True)
    assert n_joint > 0 and pairs["n"] == n_joint       # alone: never swept together
    res_s, got_s = run("scipy")
    for ch in ("sun", "sun2"):
        assert np.array_equal(got_p[ch], got_1[ch], equal_nan=True)
        assert np.array_equal(res_p.onsets[ch].times, res_1.onsets[ch].times)
        ok = np.isfinite(got_s[ch])
        assert np.array_equal(ok, np.isfinite(got_p[ch]))
        np.testing.assert_allclose(got_p[ch][ok], got_s[ch][ok], rtol=0.0,
                                   atol=1e-12 * np.max(np.abs(got_s[ch][ok])))


def test_chain_pairs_keep_a_gear_together():
    from meshphase.run.stream import _chain_pairs, _in_plan_order

    plans = [ChannelPlan(nm, group=g) for nm, g in (("sun", "sun"), ("ring", "ring"),
                                                   ("s1", "sun"), ("s2", "sun"), ("r1", "ring"),
                                                   ("r2", "ring"), ("s3", "sun"))]
    pairs = _chain_pairs(plans)
    assert [tuple(p.name for p in g) for g in pairs] == [("sun", "s1"), ("s2", "s3"),
                                                         ("ring", "r1"), ("r2",)]
    outs = [[p.name.upper() for p in g] for g in pairs]
    assert _in_plan_order(plans, pairs, outs) == [p.name.upper() for p in plans]
    odd = [ChannelPlan("a", group="x"), ChannelPlan("b", group="y"), ChannelPlan("c", group="z")]
    assert [tuple(p.name for p in g) for g in _chain_pairs(odd)] == [("a", "b"), ("c",)]
    assert _chain_pairs([]) == []


@pytest.mark.parametrize("n_keep", [
    20 * 5120,          # the ring's train is 12.2 s: under two periods, block medians instead
    2 * 62408,          # exactly two ring periods: no partial block
    2 * 62408 + 1])     # and one sample more: a one-sample partial block left out
def test_streamed_drift_takes_whole_periods_as_the_whole_array(faulty, n_keep):
    rec = Recording(faulty.data[:n_keep], faulty.fs, faulty.channels, faulty.t0)
    ref = _whole(rec)
    _, _, got = _streamed(rec)
    for ch, (y_ref, *_rest) in ref.items():
        fin = np.isfinite(y_ref)
        assert np.array_equal(np.isfinite(got[ch]), fin)
        # the same block values, smoothed and interpolated in another order: rounding only
        assert np.max(np.abs(got[ch][fin] - y_ref[fin])) <= 1e-11 * np.max(np.abs(y_ref[fin]))


def test_scan_gives_the_recording_quality_and_the_tacho_edges(faulty):
    scan, _, _ = _streamed(faulty)
    whole = faulty.quality()
    for a, b in zip(scan.quality, whole):
        assert a.keys() == b.keys()
        for k in a:
            if k == "rms":       # a sum over blocks instead of over the whole: round-off only
                assert a[k] == pytest.approx(b[k], rel=1e-12)
            else:
                assert a[k] == b[k] or (a[k] != a[k] and b[k] != b[k]), k
    # the rising half-level crossings of the tacho, as the onsets stage times them
    x = faulty.channel("tacho")
    lo, hi = np.nanmin(x), np.nanmax(x)
    half = 0.5 * (lo + hi)
    b = x > half
    rise = np.flatnonzero(b[1:] & ~b[:-1]) + 1
    x0, x1 = x[rise - 1], x[rise]
    frac = np.where(x1 > x0, (half - x0) / np.where(x1 > x0, x1 - x0, 1.0), 0.0)
    times = faulty.t0 + (rise - 1 + np.clip(frac, 0.0, 1.0)) / faulty.fs
    assert len(times) >= 1
    np.testing.assert_array_equal(scan.tacho_times, times)


def test_streamed_file_float32_and_window_equal_in_memory(tmp_path):
    rec, _ = generate("noisy", seed=2, duration=20.0)
    rec32 = Recording(rec.data.astype(np.float32), rec.fs, rec.channels, rec.t0, meta=rec.meta)
    path = io.write(rec32, tmp_path / "r.h5")
    src = FileSource(path, start=2.0, stop=18.0)
    assert isinstance(src.header, StreamedRecording) and src.header.n_samples == 16 * 5120
    part = rec32.slice_time(2.0, 18.0)
    a = scan_source(src, conditioned=["sun"], block=3000)
    b = scan_source(MemorySource(part), conditioned=["sun"], block=50000)
    assert src.header.dtype == np.float32
    for qa, qb in zip(a.quality, b.quality):      # rms: summed over other blocks
        assert qa.pop("rms") == pytest.approx(qb.pop("rms"), rel=1e-12) and qa == qb
    np.testing.assert_array_equal(a.hum_window["sun"], b.hum_window["sun"])
    fm, per = _mesh()["sun"]
    plans = [ChannelPlan("sun", mesh_freq=fm, pulse_period=per, onsets=True,
                         onset_kwargs={"mesh_freq": fm})]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataQualityWarning)
        warnings.simplefilter("ignore", ProcessingWarning)     # few pulses: fallback template
        ra = condition_stream(src, a, plans, block=3000)
        c = condition_recording(part, channels=["sun"], mesh_freq=fm, pulse_period=per)
        on = detect_onsets_recording(c.recording, "sun", quality=c.quality["sun"], mesh_freq=fm)
    assert len(ra.onsets["sun"]) == len(on) > 10
    assert np.max(np.abs(ra.onsets["sun"].times - on.times)) * rec.fs < 1e-6
    # the excerpt: the first EXCERPT_SECONDS (here everything) of the conditioned channel.
    # A float32 recording holds every step's result as float32 on both paths: where the
    # float64 results (equal to ~1e-13) straddle a float32 rounding boundary they come out
    # one float32 step (6e-8) apart, and the next filter spreads that step
    ex = ra.excerpt.channel("sun")
    y = c.recording.channel("sun").astype(np.float64)
    scale = np.nanmax(np.abs(y))
    assert ex.size == y.size and np.nanmax(np.abs(ex - y)) <= 1e-6 * scale
    assert np.mean(ex == y) > 0.99


# ---------------------------------------------------------------- the overlap, proven
@pytest.mark.parametrize("kind", ["notch", "lowpass", "highpass"])
def test_filter_overlap_makes_blocks_equal_the_whole_filter(kind):
    fs = 5120.0
    if kind == "notch":
        sos = np.concatenate([signal.tf2sos(*signal.iirnotch(f, 30.0, fs=fs)) for f in (50.0, 150.0)])
    elif kind == "lowpass":
        sos = signal.butter(4, 28.6, btype="lowpass", fs=fs, output="sos")
    else:
        sos = signal.butter(2, 0.357, btype="highpass", fs=fs, output="sos")
    L = filter_overlap(sos)
    # the slowest pole has decayed by 1e-15 over L samples: so has the impulse response
    h = signal.sosfilt(sos, np.r_[1.0, np.zeros(3 * L)])
    assert np.max(np.abs(h[L:])) < 1e-12 * np.max(np.abs(h))
    rng = np.random.default_rng(0)
    n = 7 * L + 12345
    x = np.cumsum(rng.normal(size=n)) * 1e-3 + rng.normal(size=n)
    x[1000:1004] = np.nan                       # bridged
    x[3 * L:3 * L + 500] = np.nan               # splits the signal
    padlen = 3 * (2 * len(sos) + 1)
    ref = apply_finite(x, lambda s: signal.sosfiltfilt(sos, s, padlen=padlen),
                        min_len=padlen + 1, fill_max=8, what="t")
    zp = ZeroPhase(sos, n, what="t", chunk=L // 3 + 1)
    parts = [zp.push(x[a:a + 997]) for a in range(0, n, 997)] + [zp.flush()]
    y = np.concatenate(parts)
    fin = np.isfinite(ref)
    assert np.array_equal(np.isfinite(y), fin)
    # what is left is round-off: the whole filter run on a shorter array differs as much.
    # The states of a pole at radius r carry ~1 / (1 - r) times the input, so a 0.36 Hz
    # high-pass (1 - r = 3e-4) rounds ~3000 times coarser than the notches (measured: 3e-11
    # of the input between two whole-array runs of different lengths)
    tol = 1e-10 if kind == "highpass" else 1e-12
    assert np.max(np.abs(y[fin] - ref[fin])) < tol * np.max(np.abs(x[np.isfinite(x)]))
    if iir.HAVE_NUMBA:
        # the numba engine: windows without a gap joined straight into the kernel's buffer,
        # the others through the same gap handling: scipy's numbers (bit for bit on x86-64;
        # tests/processing/test_iir.py states the tolerance)
        zn = ZeroPhase(sos, n, what="t", chunk=L // 3 + 1, engine="numba")
        yn = np.concatenate([zn.push(x[a:a + 997]) for a in range(0, n, 997)] + [zn.flush()])
        assert np.array_equal(np.isfinite(yn), fin)
        assert np.max(np.abs(yn[fin] - y[fin])) <= 1e-12 * np.max(np.abs(x[np.isfinite(x)]))


def test_filter_overlap_bad_input():
    with pytest.raises(ValueError, match="sos"):
        filter_overlap(np.ones(6))
    with pytest.raises(ValueError, match="decay"):
        filter_overlap(signal.butter(2, 0.1, output="sos"), decay=2.0)
    with pytest.raises(ValueError, match="stable"):
        filter_overlap(np.array([[1.0, 0, 0, 1.0, -2.0, 1.01]]))
    assert filter_overlap(np.array([[1.0, 0, 0, 1.0, 0, 0]])) == 1     # FIR: no memory


# ---------------------------------------------------------------- quality pieces
def test_channel_scan_in_pieces_equals_the_whole_array():
    rng = np.random.default_rng(7)
    x = np.rint(np.maximum(0, np.sin(np.arange(40000) / 90.0)) ** 8 * 400 + rng.normal(0, 2, 40000))
    x[5000:5300] = 0.0                          # a dropout across a piece edge below
    x[9000:9400] = x[8999]                      # a held value
    x[20000:20100] = np.nan
    x = np.minimum(x, 390.0)                    # clipped tops
    whole = channel_quality(x, kind="sun")
    scan = ChannelScan(x.size)
    cuts = [0, 1, 2, 5100, 5101, 9000, 17000, 30001, 40000]
    for a, b in zip(cuts[:-1], cuts[1:]):
        scan.feed1(x[a:b])
    scan.end1()
    for a, b in zip(cuts[:-1], cuts[1:]):
        scan.feed2(x[a:b])
    got = scan.result().to_dict()
    assert whole["n_dropout_runs"] == 2 and whole["n_clipped_runs"] > 5
    for k in whole:
        assert got[k] == pytest.approx(whole[k], rel=1e-12) if k == "rms" else got[k] == whole[k]


def test_scans_empty_and_misused():
    scan = ChannelScan(0)
    scan.end1()
    r = scan.result()
    assert r.n == 0 and r.flat is None and r.rail_runs.shape == (0, 2)
    q = quality_from_scan(r, "x", 10.0, 0.0)
    assert q.n_samples == 0 and q.ok
    s = ChannelScan(10)
    with pytest.raises(RuntimeError, match="before end1"):
        s.feed2(np.zeros(10))
    with pytest.raises(ValueError, match="fed 3 samples"):
        s.feed1(np.zeros(3))
        s.end1()
    with pytest.raises(ValueError, match="pass 2"):
        ChannelScan(0).result()
    with pytest.raises(TypeError, match="integer"):
        ChannelScan(2.5)
    f = FlatScan(4)
    with pytest.raises(ValueError, match="fed 0"):
        f.stats()
    st = FlatScan(0).stats()
    fr = classify_flat_runs(np.empty(0), np.empty((0, 2), np.int64), np.empty(0), st)
    assert fr.dropout_runs.shape == (0, 2) and fr.min_run == 4


def test_finite_apply_gaps_matches_the_filter():
    assert finite_apply_gaps(np.empty((0, 2)), 0, min_len=10, fill_max=8)[0].shape == (0, 2)
    runs, short, whole = finite_apply_gaps(np.empty((0, 2)), 5, min_len=10, fill_max=8)
    assert runs.tolist() == [[0, 5]] and whole and short == 0
    bad = np.array([[3, 5], [20, 40], [45, 46], [60, 100]])
    runs, short, whole = finite_apply_gaps(bad, 100, min_len=10, fill_max=8)
    # [0, 20) bridges [3, 5); [40, 60) bridges [45, 46) and is 20 long; nothing short
    assert runs.tolist() == bad.tolist() and short == 0 and not whole
    runs, short, _ = finite_apply_gaps(bad, 100, min_len=25, fill_max=8)
    assert short == 2 and runs.tolist() == [[0, 100]]


# ---------------------------------------------------------------- memory
def test_block_medians_of_an_absurd_fs_allocate_nothing_big():
    # a 10 s drift window at fs = 1e10 Hz is a block of 6e9 samples: the medians used to pad
    # the data to it (tens of GB); the block is now gathered at its 33 strided samples
    x = np.random.default_rng(0).normal(size=20000)
    tracemalloc.start()
    try:
        base = drift_baseline(x, 1e10)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 50 * x.nbytes and base.shape == x.shape
    assert np.all(base == base[0])              # one block: a constant baseline


def test_memory_guard_names_fs_and_the_budget():
    rec = Recording(np.random.default_rng(1).normal(size=(40000, 1)), 1e10,
                    [ChannelSpec("sun", kind="sun", gear="sun")])
    src = MemorySource(rec)
    scan = scan_source(src, conditioned=["sun"])
    with pytest.raises(ValueError, match=r"fs = 10000000000.0 Hz.*memory_budget"):
        condition_stream(src, scan, [ChannelPlan("sun", mesh_freq=7.0)], memory_budget=1e5)
    est = stream_memory(1e10, 40000, 1, 1, overlap=10**9, drift_block=10**9)
    # every buffer that grows with fs is capped at the recording's own length
    assert est["hum window"] == 8 * 40000 and est["drift look-ahead"] == 8 * 40000
    assert est["total"] == sum(v for k, v in est.items() if k != "total")
    flat = [stream_memory(5120.0, int(m * 60 * 5120), 8, 7, overlap=40000, drift_block=4500)["total"]
            for m in (10, 60, 180)]
    # independent of the length (10 min: the onset detector's blocks hold all of it)
    assert flat[0] <= flat[1] == flat[2]


# ---------------------------------------------------------------- the header and sources
def test_streamed_recording_header_and_bad_input(tmp_path):
    rec, _ = generate("seed_rig", seed=1, duration=2.0)
    h = StreamedRecording.of(rec)
    assert (h.fs, h.n_samples, h.n_channels, h.names, h.t_end) == \
        (rec.fs, rec.n_samples, rec.n_channels, rec.names, rec.t_end)
    assert h.spec("sun") == rec.spec("sun") and h.by_kind("tacho") == rec.by_kind("tacho")
    assert h.with_history("x", a=1).history[-1]["step"] == "x" and h.history == rec.history
    with pytest.raises(TypeError, match="streamed"):
        h.channel("sun")
    with pytest.raises(TypeError, match="streamed"):
        h.data
    with pytest.raises(KeyError, match="nope"):
        h.index("nope")
    with pytest.raises(TypeError, match="Recording"):
        MemorySource(rec.data)
    with pytest.raises(FileNotFoundError):
        FileSource(tmp_path / "missing.h5")
    empty = StreamedRecording(10.0, 0, [])
    assert empty.duration == 0.0 and len(empty) == 0 and "0 samples" in repr(empty)
    with pytest.raises(ValueError, match="fs"):
        StreamedRecording(0.0, 10, [])


def test_onset_stream_equals_detect_onsets_and_refuses_misuse(make_train):
    x, _, _ = make_train(n_pulses=80)
    ref = detect_onsets(x, 5120.0, channel="c")
    st = OnsetStream(5120.0, channel="c")
    for a in range(0, x.size, 1000):
        st.feed(x[a:a + 1000])
    assert st.n_samples == x.size
    got = st.finish()
    np.testing.assert_array_equal(got.times, ref.times)
    with pytest.raises(RuntimeError, match="twice"):
        st.finish()
    with pytest.raises(RuntimeError, match="after finish"):
        st.feed(x[:10])
    assert len(OnsetStream(5120.0).finish()) == 0
    with pytest.raises(TypeError):
        OnsetStream(5120.0, bogus=1)


# ---------------------------------------------------------------- streaming writers
@pytest.mark.parametrize("fmt,suffix", [("hdf5", ".h5"), ("mcap", ".mcap"), ("csv", ".csv")])
def test_write_blocks_equals_write(tmp_path, fmt, suffix):
    rec, _ = generate("gaps", seed=3, duration=3.0)
    warnings.simplefilter("ignore", DataQualityWarning)       # the gaps' NaN, on reading
    whole = io.read(io.write(rec, tmp_path / f"w{suffix}"))
    cuts = [0, 1, 777, 5120, 5121, 9000, rec.n_samples]
    blocks = (rec.data[a:b] for a, b in zip(cuts[:-1], cuts[1:]))
    path = io.write_blocks(rec, blocks, tmp_path / f"s{suffix}", dtype=rec.data.dtype)
    back = io.read(path)
    assert np.array_equal(back.data, whole.data, equal_nan=True)
    assert back.channels == whole.channels and back.history == whole.history
    # too few or too many samples: an error, and nothing is left behind
    for bad in ([rec.data[:100]], [rec.data, rec.data[:1]]):
        with pytest.raises(ValueError, match="n_samples"):
            io.write_blocks(rec, bad, tmp_path / f"bad{suffix}", dtype=rec.data.dtype)
        assert not (tmp_path / f"bad{suffix}").exists()
    with pytest.raises(ValueError, match="shape"):
        io.write_blocks(rec, [rec.data[:, :1]], tmp_path / f"bad{suffix}", dtype=rec.data.dtype)
    # an empty recording
    e = Recording(np.empty((0, 2)), 100.0, ["a", "b"])
    assert io.read(io.write_blocks(e, [], tmp_path / f"e{suffix}")).n_samples == 0


def test_write_blocks_bad_header_and_dtype(tmp_path):
    rec, _ = generate("seed_rig", seed=3, duration=1.0)
    with pytest.raises(TypeError, match="header"):
        io.write_blocks(object(), [rec.data], tmp_path / "x.h5")
    with pytest.raises(TypeError, match="dtype"):
        io.write_blocks(rec, [rec.data], tmp_path / "x.h5", dtype="int16")
    ro = io.register_format(io.FormatSpec(name="tdmsro", module="meshphase.io.tdms", suffixes=(".tdmsro",)))
    try:
        with pytest.raises(ValueError, match="read-only"):
            io.write_blocks(rec, [rec.data], tmp_path / "x.tdmsro")
    finally:
        io.unregister_format(ro.name)


# ---------------------------------------------------------------- peak memory of process
def test_run_child_measures_a_child_and_refuses_other_jobs():
    from meshphase.bench.rss import run_child

    r = run_child("sosfiltfilt_job", n=1 << 16, repeats=1)
    assert r["returncode"] == 0 and r["samples_per_s"] > 0
    assert r["peak_rss_mb"] > 10 and r["wall_s"] >= r["job_s"] > 0
    with pytest.raises(ValueError, match="job"):
        run_child("os_system")


def test_bench_children_write_and_reuse_bytecode(monkeypatch):
    """A bench child compiles meshphase once and reuses the bytecode as a user's interpreter
    does, whatever the calling environment says: PYTHONDONTWRITEBYTECODE is cleared (the
    development machine sets it, and every timed start then compiled ~60 modules again);
    the other variables and the extras are passed on."""
    from meshphase.bench.rss import child_env, run_child

    monkeypatch.setenv("PYTHONDONTWRITEBYTECODE", "1")
    env = child_env(OPENBLAS_NUM_THREADS="1")
    assert "PYTHONDONTWRITEBYTECODE" not in env and env["OPENBLAS_NUM_THREADS"] == "1"
    assert env["HOME"] == os.environ["HOME"] and env["PYTHONPATH"]
    r = run_child("import_job")
    assert r["returncode"] == 0 and r["import_s"] > 0


def test_run_child_peak_is_the_childs_own_not_the_parents():
    # the kernel carries a posix_spawn'ed child's parent's high-water mark into its
    # ru_maxrss; the peak reported is the child's own VmHWM. 400 MB held here (touched)
    # against a child that needs ~100 MB: the child's peak stays far below the 400 MB
    from meshphase.bench.rss import run_child

    held = np.ones(400 * 2**20 // 8)
    r = run_child("sosfiltfilt_job", n=1 << 16, repeats=1)
    assert r["ru_maxrss_mb"] >= 400 > r["peak_rss_mb"] == r["vmhwm_mb"] > 10
    del held


@pytest.mark.slow
def test_process_peak_rss_on_a_30_minute_file_stays_under_the_budget(tmp_path):
    # meshphase process on 30 min x 8 channels (float64 HDF5: 590 MB of samples): a child
    # process, its peak RSS (VmHWM). Before streaming it peaked at ~5x the samples
    # (~2.9 GB); the streaming stages hold a fixed budget (meshphase.run.stream.PROCESS_RSS_BUDGET)
    from meshphase.bench.rss import BENCH_GEARSET, run_child
    from meshphase.run.stream import PROCESS_RSS_BUDGET

    path = tmp_path / "rec30.h5"
    w = run_child("write_job", path=str(path), minutes=30.0)
    assert w["n_samples"] == 30 * 60 * 5120 and w["n_channels"] == 8
    gs = tmp_path / "gearset.toml"
    gs.write_text(BENCH_GEARSET, encoding="utf-8")
    r = run_child("process_job", path=str(path), gearset=str(gs), out_dir=str(tmp_path / "out"))
    assert r["status"] in ("ok", "unreliable") and not r["failed"]
    assert r["n_onsets"] > 5000
    data_mb = path.stat().st_size / 2**20
    assert r["peak_rss_mb"] * 2**20 < PROCESS_RSS_BUDGET
    # far below the whole-array path's ~5x the samples: about the samples' size at 30 min,
    # most of it fixed (Python, numpy, scipy, h5py, and numba with its compiler, which a
    # recording of this length loads for the filters: meshphase.signal.iir.NUMBA_SAMPLES)
    assert r["peak_rss_mb"] < 1.5 * data_mb


def test_generator_source_equals_the_generated_recording():
    # a long synthetic scene streams from the generator, generated again for every pass:
    # the same samples as generated whole
    from meshphase.synthetic import generate_blocks

    from meshphase.run.stream import GeneratorSource

    rec, _ = generate("gaps", seed=4, duration=6.0)
    gen = GeneratorSource(generate_blocks("gaps", seed=4, duration=6.0, block=1.3))
    assert gen.header.n_samples == rec.n_samples and gen.header.names == rec.names
    plans = [ChannelPlan("sun", mesh_freq=_mesh()["sun"][0], onsets=True)]
    out = []
    for src in (MemorySource(rec), gen):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DataQualityWarning)
            scan = scan_source(src, conditioned=["sun"], tacho="tacho", block=5000)
            out.append((scan, condition_stream(src, scan, plans, block=5000)))
    (sa, ra), (sb, rb) = out
    assert sa.quality == sb.quality
    np.testing.assert_array_equal(sa.tacho_times, sb.tacho_times)
    # other blocks (the generator's 1.3 s): other filter windows, equal to the tolerance
    assert len(ra.onsets["sun"]) == len(rb.onsets["sun"]) > 3
    assert np.max(np.abs(ra.onsets["sun"].times - rb.onsets["sun"].times)) * rec.fs < 1e-6


def test_scan_and_condition_stream_bad_input():
    rec, _ = generate("seed_rig", seed=1, duration=2.0)
    src = MemorySource(rec)
    with pytest.raises(TypeError, match="BlockSource"):
        scan_source(rec)
    with pytest.raises(ValueError, match="nope"):
        scan_source(src, conditioned=["nope"])
    with pytest.raises(ValueError, match="quality scan.*memory_budget"):
        scan_source(src, conditioned=["sun"], memory_budget=1e4)
    scan = scan_source(src, conditioned=["sun"])
    with pytest.raises(TypeError, match="RawScan"):
        condition_stream(src, {}, [])
    with pytest.raises(ValueError, match="nope"):
        condition_stream(src, scan, [ChannelPlan("nope")])
    with pytest.raises(TypeError, match="ChannelPlan"):
        condition_stream(src, scan, ["sun"])
    with pytest.raises(ValueError, match="drift"):
        condition_stream(src, scan, [ChannelPlan("sun")], drift="mean")
    with pytest.raises(ValueError, match="engine must be one of"):
        condition_stream(src, scan, [ChannelPlan("sun")], filter_engine="fortran")
    res = condition_stream(src, scan, [])              # nothing planned: nothing conditioned
    assert res.quality == {} and res.onsets == {} and res.excerpt.n_channels == 0


def test_long_synthetic_scene_streams_from_the_generator(monkeypatch):
    # above SYNTHETIC_WHOLE_BYTES the load stage generates the recording again for every
    # pass instead of holding it; with the same blocks the result is the same to rounding
    # (the conditioning is block-wise either way: only where the samples come from differs)
    from meshphase.run import stages
    from meshphase.run.scene import parse_scene
    from meshphase.run.stream import GeneratorSource

    text = ('name = "gen"\nresults = ["phasing"]\n[input]\nsynthetic = "gaps"\nminutes = 0.1\n'
            'seed = 3\n[[channels]]\nname = "sun"\ngain = 2.0\n')
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataQualityWarning)
        warnings.simplefilter("ignore", ProcessingWarning)
        whole = stages.run_scene(parse_scene(text))
        monkeypatch.setattr(stages, "SYNTHETIC_WHOLE_BYTES", 0)
        gen = stages.run_scene(parse_scene(text))
    assert isinstance(gen.load.stream, GeneratorSource)
    assert isinstance(whole.load.stream, MemorySource)
    assert gen.load.recording.history[-1]["step"] == "channel_overrides"
    assert whole.load.quality == gen.load.quality
    assert len(whole.condition.onsets["sun"]) > 3
    for ch, on in whole.condition.onsets.items():
        other = gen.condition.onsets[ch]
        assert len(on) == len(other)
        # same samples, same blocks: equal up to float rounding of the summation order
        np.testing.assert_allclose(on.times, other.times, rtol=0, atol=1e-9 / 5120)


def test_convert_and_process_never_read_the_recording_whole(tmp_path, monkeypatch, capsys):
    # the commands stream whatever the length: with every whole-recording read made to
    # fail, convert (HDF5 -> MCAP) and process (of the MCAP file) still complete
    from meshphase.synthetic import generate_blocks

    from meshphase.bench.rss import BENCH_GEARSET, bench_config
    from meshphase.cli import main

    stream = generate_blocks(bench_config(30.0), seed=1)
    src = tmp_path / "r.h5"
    io.write_blocks(stream, (b.data for b in stream), src, dtype=stream.dtype)
    gearset = tmp_path / "g.toml"
    gearset.write_text(BENCH_GEARSET, encoding="utf-8")

    def whole(*a, **k):
        raise AssertionError("a whole-recording read")

    for mod in (io, io.get_format("hdf5"), io.get_format("mcap")):
        monkeypatch.setattr(mod, "read", whole)
    assert main(["-q", "convert", str(src), str(tmp_path / "r.mcap")]) == 0
    rc = main(["-q", "process", str(tmp_path / "r.mcap"), "--gearset", str(gearset),
               "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert "whole-recording read" not in err
    assert rc in (0, 3), err            # 3: 30 s may leave the phasing flagged unreliable
    assert (tmp_path / "out" / "passes_sun.csv").is_file()
    assert (tmp_path / "out" / "summary.json").is_file()


@pytest.mark.parametrize("n_threads", [1, 2])
def test_a_read_failing_mid_pass_is_raised_and_its_reader_stopped(faulty, n_threads):
    """The blocks are read one ahead on a thread of their own (meshphase.runtime.threads.read_ahead):
    a read that fails in the middle of a pass raises its own error from the pass, and the
    reading thread is gone (its file closed) when the pass has ended."""
    import threading

    from meshphase.runtime.threads import threads_limited

    class Failing(MemorySource):
        closed = 0

        def blocks(self, n_block):
            try:
                for k, (a, data) in enumerate(super().blocks(n_block)):
                    if k == 3:
                        raise OSError("disk read error at block 3")
                    yield a, data
            finally:
                Failing.closed += 1

    with threads_limited(n_threads):
        with pytest.raises(OSError, match="block 3"):
            scan_source(Failing(faulty), conditioned=["sun", "ring"], tacho="tacho", block=BLOCK)
        good = scan_source(MemorySource(faulty), conditioned=["sun", "ring"], tacho="tacho",
                           block=BLOCK)
        plans = [ChannelPlan("sun", mesh_freq=_mesh()["sun"][0], pulse_period=_mesh()["sun"][1],
                             group="sun", onsets=False)]
        with pytest.raises(OSError, match="block 3"), warnings.catch_warnings():
            warnings.simplefilter("ignore", DataQualityWarning)
            condition_stream(Failing(faulty), good, plans, block=BLOCK)
    assert Failing.closed == 2
    assert not [t for t in threading.enumerate() if t.name == "meshphase-read"]


# ----------------------------------------------------------------------------- one read
def _scan_twice(x, cuts, **kw):
    s = ChannelScan(x.size, **kw)
    for a, b in zip(cuts[:-1], cuts[1:]):
        s.feed1(x[a:b])
    s.end1()
    for a, b in zip(cuts[:-1], cuts[1:]):
        s.feed2(x[a:b])
    return quality_from_scan(s.result()).to_dict()


def _scan_once(x, cuts, **kw):
    s = ChannelScan(x.size, **kw)
    for a, b in zip(cuts[:-1], cuts[1:]):
        s.feed(x[a:b])
    settled = s.end()
    if not settled:
        for a, b in zip(cuts[:-1], cuts[1:]):
            s.feed2(x[a:b])
    return quality_from_scan(s.result()).to_dict(), settled


def _signals():
    rng = np.random.default_rng(11)
    x = rng.normal(size=60000)
    x[1000:1050] = 0.0                                   # zeros
    x[5000:5020] = x[4999]                               # a held value
    x[9000:9010] = x.max() + 1.0                         # a new maximum after others
    x[100:130] = np.nan
    x[150] = np.inf
    x[-5:] = x.min() - 1.0                               # the minimum at the very end
    q = np.rint(rng.normal(size=80000) * 1.5)            # quantised: chance runs of equal values
    q[7000:7100] = 0.0
    q[20000:20040] = q.max()
    sine = np.rint(np.sin(np.arange(50000) * 0.01) * 20)  # thousands of runs at every level
    square = np.where((np.arange(30000) // 500) % 2, 1.0, 0.0)
    return {"faults": x, "quantised": q, "sine": sine, "square": square,
            "constant": np.full(5000, 3.0), "empty": np.zeros(0)}


@pytest.mark.parametrize("name", ["faults", "quantised", "sine", "square", "constant", "empty"])
@pytest.mark.parametrize("flat", [True, None])
def test_one_read_scan_equals_the_two_pass_scan(name, flat):
    x = _signals()[name]
    for cuts in ([0, x.size], [0, 1, 2, 999, 1001, 9005, x.size // 2, x.size],
                 list(range(0, x.size, 7)) + [x.size]):
        cuts = sorted({min(c, x.size) for c in cuts})
        once, settled = _scan_once(x, cuts, flat=flat)
        assert settled                      # none of these needs the second pass
        assert once == _scan_twice(x, cuts, flat=flat)


def test_one_read_scan_says_when_it_needs_the_second_pass():
    # 1500 dropouts of zeros, away from the signal's level: more runs at the threshold than
    # the scan holds (SCAN_CANDIDATES), so the shortest were dropped; the second pass then
    # gives what the two-pass scan gives. A rail tolerance needs it too.
    from meshphase.signal.quality import SCAN_CANDIDATES

    x = np.random.default_rng(3).normal(size=900000) + 5.0
    for k in range(1500):
        x[k * 600:k * 600 + 20 + k % 5] = 0.0
    cuts = list(range(0, x.size, 1 << 16)) + [x.size]
    once, settled = _scan_once(x, cuts)
    assert not settled and once == _scan_twice(x, cuts)
    assert once["dropout_runs"] and len(once["dropout_runs"]) == 1500 > SCAN_CANDIDATES
    y = _signals()["faults"]
    once, settled = _scan_once(y, [0, y.size], rail_rtol=0.01)
    assert not settled and once == _scan_twice(y, [0, y.size], rail_rtol=0.01)


def test_one_read_scan_misused():
    s = ChannelScan(10)
    s.feed1(np.zeros(4))
    with pytest.raises(RuntimeError, match="feed1"):
        s.feed(np.zeros(6))
    s = ChannelScan(10)
    s.feed(np.zeros(3))
    with pytest.raises(ValueError, match="fed 3 samples"):
        s.end()
    s = ChannelScan(4)
    s.feed(np.arange(4.0))
    assert s.end()
    with pytest.raises(RuntimeError, match="found everything"):
        s.feed2(np.arange(4.0))
    s = ChannelScan(0)
    assert s.end() and s.result().n == 0


class _CountingSource(MemorySource):
    """A memory source that counts how often each sample was handed out."""

    def __init__(self, rec):
        super().__init__(rec)
        self.reads = np.zeros(rec.n_samples, dtype=np.int64)

    def blocks(self, n_block):
        for a, data in super().blocks(n_block):
            self.reads[a:a + data.shape[0]] += 1
            yield a, data


def test_the_scan_reads_every_sample_once_and_conditioning_once_more(faulty):
    # the scan settles everything in its one read (quality, rails, flat runs, tacho edges,
    # hum windows); conditioning and onsets need the dropouts, clips and hum lines of the
    # whole channel before their first sample, so they read once more: two in all
    src = _CountingSource(faulty)
    scan = scan_source(src, conditioned=["sun", "ring"], tacho="tacho", block=BLOCK)
    assert scan.n_reads == 1 and np.all(src.reads == 1)
    plans = [ChannelPlan(ch, mesh_freq=fm, pulse_period=per, group=ch, onsets=True,
                         onset_kwargs={"mesh_freq": fm}) for ch, (fm, per) in _mesh().items()]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataQualityWarning)
        condition_stream(src, scan, plans, block=BLOCK)
    assert np.all(src.reads == 2)


def test_a_tacho_whose_levels_move_is_timed_in_a_second_read():
    # the tacho's first pulses go from 0 to 1, later ones from -1 to 1.2: the final half
    # level (0.1) lies outside the middle half of the first pulses' range, around which
    # the one read kept their crossings: its edges are timed again, exactly as the
    # whole-array rule times them
    fs, n = 1000.0, 40000
    t = np.arange(n)
    up = (t // 700) % 2 == 1
    tacho = np.where(up, 1.0, 0.0)
    tacho[n // 2:] = np.where(up[n // 2:], 1.2, -1.0)
    gauge = np.random.default_rng(1).normal(size=n)
    rec = Recording(np.stack([gauge, tacho], axis=1), fs,
                    [ChannelSpec("sun", kind="sun"), ChannelSpec("tacho", kind="tacho")])
    src = _CountingSource(rec)
    scan = scan_source(src, conditioned=["sun"], tacho="tacho", block=3000)
    assert scan.n_reads == 2 and np.all(src.reads == 2)
    half = 0.5 * (-1.0 + 1.2)
    b = tacho > half
    rise = np.flatnonzero(b[1:] & ~b[:-1]) + 1
    frac = (half - tacho[rise - 1]) / (tacho[rise] - tacho[rise - 1])
    np.testing.assert_array_equal(scan.tacho_times, (rise - 1 + frac) / fs)
    assert scan.tacho_times.size == np.count_nonzero(np.diff(up.astype(int)) == 1)
    # levels reached in the first pulses: one read, the same edges as the whole array
    half = 1.5
    steady = np.where(up, 3.0, 0.0)
    rec2 = rec.replace_data(np.stack([gauge, steady], axis=1))
    src2 = _CountingSource(rec2)
    scan2 = scan_source(src2, conditioned=["sun"], tacho="tacho", block=3000)
    assert scan2.n_reads == 1 and np.all(src2.reads == 1)
    b = steady > half
    rise = np.flatnonzero(b[1:] & ~b[:-1]) + 1
    np.testing.assert_array_equal(scan2.tacho_times, (rise - 1 + 0.5) / fs)


def test_float32_chains_hand_on_float32_and_equal_float64_copies():
    # a float32 recording's chain rounds every step to float32: it hands float32 samples
    # on (half the bytes), the values the float64 copies of those roundings held
    rec, _ = generate("noisy", seed=4, duration=20.0)
    rec32 = Recording(rec.data.astype(np.float32), rec.fs, rec.channels, rec.t0, meta=rec.meta)
    src = MemorySource(rec32)
    scan = scan_source(src, conditioned=["sun"], block=BLOCK)
    fm, per = _mesh()["sun"]
    pieces = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataQualityWarning)
        res = condition_stream(src, scan, [ChannelPlan("sun", mesh_freq=fm, pulse_period=per)],
                               block=BLOCK, on_samples=lambda nm, a, y: pieces.append(y))
        whole = condition_recording(rec32, channels=["sun"], mesh_freq=fm, pulse_period=per)
    assert pieces and all(p.dtype == np.float32 for p in pieces)
    y = np.concatenate(pieces)
    ref = whole.recording.channel("sun")
    assert ref.dtype == np.float32 and y.size == ref.size
    ok = np.isfinite(ref)
    # the streamed windows equal the whole filter to ~1e-13, rounded to float32: at most
    # one float32 step apart where a value straddles a rounding boundary
    assert np.array_equal(np.isfinite(y), ok)
    assert np.max(np.abs(y[ok] - ref[ok])) <= 4 * np.spacing(np.float32(np.max(np.abs(ref[ok]))))
    assert res.excerpt.data.dtype == np.float64


class _TiledSource(MemorySource):
    """A recording ``reps`` times as long as ``rec``: its samples repeated, block by block
    (never held whole)."""

    def __init__(self, rec, reps):
        super().__init__(rec)
        self.base = rec
        self.header = StreamedRecording(rec.fs, rec.n_samples * reps, list(rec.channels), rec.t0,
                                        None, rec.meta, (), rec.data.dtype)

    def blocks(self, n_block):
        m, n = self.base.n_samples, self.header.n_samples
        for a in range(0, n, n_block):
            b = min(a + n_block, n)
            idx = np.arange(a, b) % m
            yield a, self.base.data[idx]


def _streamed_peak(rec, reps):
    import tracemalloc

    src = _TiledSource(rec, reps)
    fm, per = _mesh()["sun"]
    tracemalloc.start()
    try:
        scan = scan_source(src, conditioned=["sun"], tacho="tacho", block=1 << 16)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DataQualityWarning)
            res = condition_stream(src, scan, [ChannelPlan("sun", mesh_freq=fm, pulse_period=per,
                                                           onsets=True,
                                                           onset_kwargs={"mesh_freq": fm})],
                                   block=1 << 16)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    return peak, len(res.onsets["sun"])


def test_streamed_memory_does_not_grow_with_the_length():
    # 5 and 10 min of a gauge and a tacho (a 30 s recording repeated, read block by block):
    # past 2**20 samples (3.4 min) every fixed buffer (onset analysis blocks, SNR
    # subsamples, filter windows, drift look-ahead) is full, so doubling the length adds
    # only what is found: the onsets (~50 B each) and the drift blocks' values. 4 MB is a
    # third of the 12 MB that 5 more minutes of one float64 channel take: a structure
    # holding anything per sample fails it
    rec, _ = generate("rig_realistic", seed=5, duration=30.0)
    rec = rec.select(["sun", "tacho"])
    p5, n5 = _streamed_peak(rec, 10)
    p10, n10 = _streamed_peak(rec, 20)
    assert n10 > 1.9 * n5 > 0
    assert p10 - p5 < 4 * 2**20, (p5 / 2**20, p10 / 2**20)
