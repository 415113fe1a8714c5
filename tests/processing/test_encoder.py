"""Shaft encoders: edge levels and sub-sample timing, extra and missing edges, the encoder's
angle train and its shaft's mesh cycles (meshphase.kinematics.encoder, meshphase.kinematics.angles)."""

import math

import numpy as np
import pytest

from meshphase.kinematics.shafts import kinematics, shaft_cycles
from meshphase.kinematics.trains import encoder_train
from meshphase.errors import DataQualityWarning
from meshphase.kinematics.encoder import (EncoderEdges, clean_edges, edge_timing_sigma, edge_times,
                                          pulse_levels, rising_crossings, shaft_of)
from meshphase.models.gearset import Speeds
from meshphase.recording import ChannelSpec

FS = 5120.0


def pulse_train(f_pulse, seconds, *, ripple=0.003, noise=0.005, rise=0.0, seed=1):
    """A 0 / 5 V pulse train of ``f_pulse`` pulses per second with a slow phase wobble; its
    true rising edges [s] (phase through whole numbers) and samples. ``rise``: edge width
    [s] of a raised-cosine edge (0: a sharp step)."""
    n = int(seconds * FS)
    t = np.arange(n) / FS

    def phase(s):
        return f_pulse * s + ripple * np.sin(2 * np.pi * 0.2 * s)

    ph = phase(t)
    k = np.arange(1, int(ph[-1]) + 1)
    # the phase is monotone: Newton's method from the linear guess converges in a few steps
    te = k / f_pulse
    for _ in range(8):
        te -= (phase(te) - k) / (f_pulse + ripple * 2 * np.pi * 0.2 * np.cos(2 * np.pi * 0.2 * te))
    frac = np.mod(ph, 1.0)
    if rise > 0:
        u = np.clip(frac / (rise * f_pulse), 0.0, 1.0)          # 0 -> 1 over the edge
        x = np.where(frac < 0.5, 5.0 * 0.5 * (1 - np.cos(np.pi * u)), 0.0)
    else:
        x = np.where(frac < 0.5, 5.0, 0.0)
    x = x + noise * np.random.default_rng(seed).standard_normal(n)
    return t, x, te


# ----------------------------------------------------------------------------- levels
def test_pulse_levels_are_the_clusters_medians_not_the_extremes():
    _, x, _ = pulse_train(18.0, 4.0)
    x[100] = 40.0                                   # a spike
    x[200] = -30.0
    lo, hi = pulse_levels(x)
    # medians of 0 V and 5 V with 5 mV noise: within a few noise sigma / sqrt(n) of the truth
    assert abs(lo) < 1e-3 and abs(hi - 5.0) < 1e-3


def test_pulse_levels_empty_and_bad_input():
    with pytest.raises(ValueError, match="at least 2 finite"):
        pulse_levels([])
    with pytest.raises(ValueError, match="one level"):
        pulse_levels(np.full(100, 3.0))
    with pytest.raises(TypeError, match="numeric"):
        pulse_levels(np.array(["a", "b"]))
    with pytest.raises(ValueError, match="1-D"):
        pulse_levels(np.zeros((3, 3)))


# ----------------------------------------------------------------------------- timing
def test_rising_crossings_interpolate_between_samples():
    x = np.array([0.0, 0.0, 1.0, 3.0, 5.0, 5.0, 0.0, 4.0])
    # 2.5 crossed between samples 2 (1.0) and 3 (3.0) at 0.75, and between 6 and 7 at 0.625
    assert rising_crossings(x, 2.5) == pytest.approx([2.75, 6.625], abs=1e-12)
    # non-finite samples never cross
    assert rising_crossings([0.0, np.nan, 5.0, 0.0, 5.0], 2.5) == pytest.approx([3.5])


def test_rising_crossings_empty_and_bad_input():
    assert rising_crossings([], 1.0).size == 0
    with pytest.raises(ValueError, match="level must be finite"):
        rising_crossings([0.0, 1.0], float("nan"))
    with pytest.raises(ValueError, match="1-D"):
        rising_crossings(np.zeros((2, 2)), 0.5)


def test_sharp_edges_are_timed_to_their_sample_quantisation():
    # a TTL step is timed no better than its sample: error uniform over one sample period,
    # RMS 1 / sqrt(12) = 0.289 samples, mean ~0 (the half level sits half-way in time)
    _, x, te = pulse_train(18.2, 20.0)
    got = edge_times(x, FS)
    assert got.size == te.size
    err = (got - te) * FS
    assert abs(float(np.mean(err))) < 0.05        # 364 edges: the mean's sigma is 0.015
    assert float(np.std(err)) == pytest.approx(1 / math.sqrt(12), rel=0.1)
    assert edge_timing_sigma(FS) == pytest.approx(1 / (math.sqrt(12) * FS))


def test_smooth_edges_are_timed_to_a_small_fraction_of_a_sample():
    # a raised-cosine edge over ~8 samples: linear interpolation at its steepest point is
    # exact to second order; the noise (5 mV on a 0.98 V/sample slope) adds ~0.005 sample
    _, x, te = pulse_train(18.2, 20.0, rise=8.0 / FS)
    got = edge_times(x, FS, levels=(0.0, 5.0))
    # the half level is crossed 4 samples after the phase passes a whole number (0 too:
    # the train starts low, at the foot of its first edge)
    err = (got - np.concatenate([[0.0], te])) * FS - 4.0
    assert float(np.max(np.abs(err - np.mean(err)))) < 0.05
    assert abs(float(np.mean(err))) < 0.05


def test_edge_times_empty_and_bad_input():
    assert edge_times([], FS).size == 0
    assert edge_times([1.0], FS).size == 0
    with pytest.raises(ValueError, match="fs must be > 0"):
        edge_times([0.0, 5.0, 0.0], 0.0)
    with pytest.raises(ValueError, match="high > low"):
        edge_times([0.0, 5.0, 0.0], FS, levels=(5.0, 0.0))
    with pytest.raises(ValueError, match="fs must be > 0"):
        edge_timing_sigma(-1.0)


# ----------------------------------------------------------------------------- clean edges
def test_missing_and_extra_edges_are_counted_and_dropped():
    _, x, te = pulse_train(18.2, 20.0)
    e = edge_times(x, FS)
    period = 1 / 18.2
    missing = [10, 50, 51, 200]                      # one, two together, one
    extra = [e[20] + 0.3 * period, e[30] + 0.02 * period, e[40] + 0.97 * period,
             e[100] + 0.5 * period]
    cut = np.sort(np.concatenate([np.delete(e, missing), extra]))
    c = clean_edges(cut)
    assert (c.n_extra, c.n_missing) == (4, 4)
    assert len(c) == e.size - 4
    # every kept edge is a true one with its true pulse count
    kept = np.setdiff1d(np.arange(e.size), missing)
    assert np.array_equal(c.times, e[kept])
    assert np.array_equal(c.count, kept)
    assert c.period == pytest.approx(period, rel=0.01)
    assert c.summary() == f"{e.size - 4} edges, 4 extra dropped, 4 missing counted"


def test_clean_edges_leaves_a_clean_train_alone():
    _, x, _ = pulse_train(18.2, 5.0)
    e = edge_times(x, FS)
    c = clean_edges(e)
    assert (c.n_extra, c.n_missing) == (0, 0)
    assert np.array_equal(c.count, np.arange(e.size))


def test_clean_edges_empty_and_bad_input():
    c = clean_edges([])
    assert len(c) == 0 and c.count.size == 0 and math.isnan(c.period)
    assert clean_edges([1.0]).count.tolist() == [0]
    with pytest.raises(ValueError, match="strictly increasing"):
        clean_edges([0.0, 0.2, 0.1])
    with pytest.raises(ValueError, match="finite"):
        clean_edges([0.0, np.inf])
    with pytest.raises(ValueError, match="tol must be below 0.5"):
        clean_edges([0.0, 1.0], tol=0.5)


# ----------------------------------------------------------------------------- angle train
def test_shaft_cycles_from_the_kinematics():
    ring = kinematics(25, 87, 29, fixed="ring")
    assert shaft_cycles(ring, "sun") == pytest.approx(25 * 87 / 112)
    assert shaft_cycles(ring, "input") == shaft_cycles(ring, "sun")
    assert shaft_cycles(ring, "carrier") == 87.0
    sun = kinematics(25, 87, 29, fixed="sun")
    assert shaft_cycles(sun, "ring") == pytest.approx(25 * 87 / 112)
    assert shaft_cycles(sun, "carrier") == 25.0


def test_shaft_cycles_bad_input():
    ring = kinematics(25, 87, 29, fixed="ring")
    with pytest.raises(ValueError, match="the ring is held"):
        shaft_cycles(ring, "ring")
    with pytest.raises(ValueError, match="one of .* got 'planet'"):
        shaft_cycles(ring, "planet")
    with pytest.raises(TypeError, match="Kinematics"):
        shaft_cycles(None, "sun")
    with pytest.raises(ValueError, match="not known"):
        shaft_cycles(kinematics(25, 87, 29, fixed=None), "sun")
    # a differential with its speeds: the sun's turn in mesh cycles Z_s w_sc / w_s
    diff = kinematics(25, 87, 29, fixed=None, speeds=Speeds(sun=10.0, carrier=2.0, planet=0.0, ring=-1.0))
    assert shaft_cycles(diff, "sun") == pytest.approx(25 * 8.0 / 10.0)
    with pytest.raises(ValueError, match="got 3"):
        shaft_of(3)


def test_encoder_train_observes_the_mesh_angle_every_pulse():
    edges = clean_edges(np.sort(np.concatenate([np.arange(10) * 0.1, [0.905]])))
    p = 25 * 87 / 112 / 60
    tr = encoder_train(edges, p, sigma=1e-5, name="enc")
    assert tr.kind == "tacho" and tr.name == "enc" and tr.sigma_given
    assert tr.target == pytest.approx(p * np.arange(10))
    assert np.all(tr.planet == -1)
    empty = encoder_train(clean_edges([]), p)
    assert len(empty) == 0


def test_encoder_train_bad_input():
    edges = clean_edges([0.0, 0.1, 0.2])
    with pytest.raises(TypeError, match="EncoderEdges"):
        encoder_train([0.0, 0.1], 0.3)
    with pytest.raises(ValueError, match="cycles_per_pulse must be > 0"):
        encoder_train(edges, 0.0)
    with pytest.raises(ValueError, match="name must be a non-empty string"):
        encoder_train(edges, 0.3, name="")
    bad = EncoderEdges(np.array([0.0, 0.1]), np.array([0, 0]), 0, 0, 0.1)
    with pytest.raises(ValueError, match="increase by at least 1"):
        encoder_train(bad, 0.3)


# ----------------------------------------------------------------------------- channel spec
def test_encoder_channel_spec_is_validated():
    c = ChannelSpec("enc", kind="encoder", units="V", shaft="input", pulses_per_rev=60.0)
    assert c.pulses_per_rev == 60 and isinstance(c.pulses_per_rev, int)
    with pytest.raises(ValueError, match="'enc'.*shaft must be one of.*'wheel'"):
        ChannelSpec("enc", kind="encoder", shaft="wheel")
    with pytest.raises(ValueError, match="'enc'.*pulses_per_rev must be a positive integer, got 0"):
        ChannelSpec("enc", kind="encoder", pulses_per_rev=0)
    with pytest.raises(ValueError, match="got 2.5"):
        ChannelSpec("enc", kind="encoder", pulses_per_rev=2.5)
    with pytest.raises(ValueError, match="'sg'.*shaft belong.*not kind 'sun'"):
        ChannelSpec("sg", kind="sun", shaft="sun")


# ----------------------------------------------------------------------------- in the fit
def test_encoders_that_cannot_observe_the_mesh_angle_are_named_not_used():
    from meshphase.kinematics.phasing import _encoder_trains

    t = np.arange(200) / 18.2
    ring = kinematics(25, 87, 29, fixed="ring")
    notes = []
    out = _encoder_trains([("E1", "sun", 60, t, 1e-5), ("E2", "ring", 60, t, None)], ring, notes)
    assert [tr.name for tr in out] == ["E1"]
    assert out[0].target[-1] == pytest.approx(199 * 25 * 87 / 112 / 60)
    assert "encoder E1 (sun shaft, 60 pulses per turn, 0.3237 mesh cycles per pulse): " \
           "200 edges, 0 extra dropped, 0 missing counted" in notes
    assert any("encoder E2" in n and "the ring is held" in n and "not used" in n for n in notes)
    notes = []
    assert _encoder_trains([("E1", "sun", 60, t, None)], kinematics(25, 87, 29, fixed=None),
                           notes) == []
    assert "differential rig: encoder E1" in notes[0]
    with pytest.raises(ValueError, match="'E1' pulses_per_rev must be a positive integer"):
        _encoder_trains([("E1", "sun", 0, t, None)], ring, [])


def test_an_encoder_channel_without_its_shaft_is_left_out_with_a_warning():
    from meshphase.errors import ProcessingWarning
    from meshphase.recording import Recording
    from meshphase.run.stages import _encoder_inputs

    specs = [ChannelSpec("enc", kind="encoder", units="V", pulses_per_rev=60),
             ChannelSpec("enc2", kind="encoder", units="V", shaft="sun", pulses_per_rev=60)]
    rec = Recording(np.zeros((10, 2)), FS, specs)
    t = np.arange(5) / 18.2
    with pytest.warns(ProcessingWarning, match="encoder channel 'enc': no shaft"):
        got = _encoder_inputs(rec, {"enc": t, "enc2": t})
    assert [g[:3] for g in got] == [("enc2", "sun", 60)]
    assert got[0][4] == pytest.approx(edge_timing_sigma(FS))
    assert _encoder_inputs(rec, {}) == []


def test_the_streamed_scan_times_encoder_edges_as_the_array_function_does():
    from meshphase.recording import Recording
    from meshphase.run.stream import MemorySource, scan_source

    _, x, te = pulse_train(18.2, 20.0)
    specs = [ChannelSpec("enc", kind="encoder", units="V", shaft="sun", pulses_per_rev=60),
             ChannelSpec("dead", kind="encoder", units="V", shaft="sun", pulses_per_rev=60)]
    rec = Recording(np.column_stack([x, np.zeros_like(x)]), FS, specs, t0=2.0)
    # blocks much shorter than the record: edges across block boundaries are timed alike
    scan = scan_source(MemorySource(rec), encoders=["enc", "dead"], block=4096)
    assert set(scan.encoder_times) == {"enc"}                 # one level only: nothing to time
    got = scan.encoder_times["enc"]
    # the scan's levels come from a strided subsample, the array function's from every
    # sample: their half levels differ by ~1e-5 V, which moves a 5 V-per-sample edge by
    # ~1e-6 of a sample
    assert got == pytest.approx(edge_times(x, FS, t0=2.0), abs=1e-5 / FS)
    assert got.size == te.size
    with pytest.raises(ValueError, match=r"no channel\(s\) \['nope'\]"):
        scan_source(MemorySource(rec), encoders=["nope"])


def test_a_long_gap_splits_the_train_and_each_piece_is_counted_anew():
    from meshphase.kinematics.encoder import MAX_GAP_PULSES, split_at_gaps
    from meshphase.kinematics.phasing import _encoder_trains

    t = np.arange(100) * 0.05
    gone = np.r_[10, 40:40 + MAX_GAP_PULSES + 1]          # one missing, then a dropout
    c = clean_edges(np.delete(t, gone))
    assert c.n_missing == 1 + MAX_GAP_PULSES + 1
    pieces = split_at_gaps(c)
    assert [len(p) for p in pieces] == [39, 100 - 40 - MAX_GAP_PULSES - 1]
    assert [p.n_missing for p in pieces] == [1, 0]
    assert pieces[1].count[0] == 0 and pieces[1].times[0] == t[40 + MAX_GAP_PULSES + 1]
    # a gap of max_gap pulses is counted across: one piece
    assert len(split_at_gaps(clean_edges(np.delete(t, np.r_[40:40 + MAX_GAP_PULSES - 1])))) == 1
    notes = []
    with pytest.warns(DataQualityWarning, match=r"encoder E: 0 extra edge\(s\) dropped "
                      rf"\(glitches\), {MAX_GAP_PULSES + 2} missing edge\(s\) counted"):
        trains = _encoder_trains([("E", "sun", 60, np.delete(t, gone), None)],
                                 kinematics(25, 87, 29, fixed="ring"), notes)
    assert [tr.name for tr in trains] == ["E", "E [2]"]
    assert f"counted anew after 1 gap(s) of more than {MAX_GAP_PULSES} pulses" in notes[0]


def test_split_at_gaps_empty_and_bad_input():
    from meshphase.kinematics.encoder import split_at_gaps

    assert split_at_gaps(clean_edges([])) == []
    assert len(split_at_gaps(clean_edges([0.0]))) == 1
    with pytest.raises(TypeError, match="EncoderEdges"):
        split_at_gaps([0.0, 1.0])
    with pytest.raises(ValueError, match="max_gap must be a positive integer, got 0"):
        split_at_gaps(clean_edges([0.0, 1.0]), 0)


def test_rising_crossing_parts_one_rule_for_whole_arrays_and_streams():
    # a rise after a NaN counts in the streamed edges (finite_only=False, the tacho's rule)
    # and not in the whole-array function; float32 samples keep float32 fractions
    from meshphase.kinematics.encoder import rising_crossing_parts
    x = np.array([0.0, 5.0, np.nan, 5.0, 0.0, 2.0, 4.0], dtype=np.float32)
    i, f = rising_crossing_parts(x, np.float32(2.5), finite_only=False)
    assert i.tolist() == [1, 3, 6] and f.dtype == np.float32
    assert f[0] == np.float32(0.5) and f[2] == np.float32(0.25)
    i, f = rising_crossing_parts(x, 2.5)
    assert i.tolist() == [1, 6]
    assert rising_crossings(x, 2.5).tolist() == [0.5, 5.25]
    i, f = rising_crossing_parts(np.empty(0), 1.0)
    assert i.size == 0 and f.size == 0
    with pytest.raises(ValueError, match="1-D"):
        rising_crossing_parts(np.zeros((2, 2)), 1.0)
    with pytest.raises(TypeError):
        rising_crossing_parts(np.array(["a", "b"]), 1.0)
