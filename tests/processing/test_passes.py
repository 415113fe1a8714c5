"""Pass selection (meshphase.kinematics.passes): usable onsets, pass times at the timing centre, the
timing bound from the one Cramer-Rao function, gap intervals, every gauge's passes."""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pytest

from meshphase.signal.crb import crb_delay_std
from meshphase.signal.condition import ChannelQuality
from meshphase.errors import ProcessingWarning
from meshphase.onsets import FLAG_CLIPPED, FLAG_GAP, Onsets, Template
from meshphase.kinematics.passes import (conditioned_gap_runs, gap_intervals_of, gauge_passes, onset_sigma,
                                         pass_times, usable_onsets)
from meshphase.onsets.timing import ONSET_RESOLUTION, centre_shifts, timing_centre
from meshphase.kinematics.phasing import GaugePasses
from meshphase.recording import ChannelSpec

FS = 1000.0


def _template(n=41, decimation=1, skew=0.0, fwhm=0.01, ref=None) -> Template:
    u = np.linspace(-1.0, 1.0, n)
    h = np.exp(-0.5 * ((u - skew * u * u) / 0.3) ** 2)
    peak = float(np.argmax(h))
    return Template(h / h.max(), FS, decimation, peak, peak - 5 if ref is None else ref, fwhm)


def _onsets(times, *, amp=None, flags=None, width=None, tid=None, templates=None) -> Onsets:
    t = np.asarray(times, dtype=float)
    n = t.size
    return Onsets(t, (t * FS), np.ones(n), np.ones(n) if amp is None else np.asarray(amp, float),
                  np.full(n, 0.004) if width is None else np.asarray(width, float),
                  np.zeros(n, np.uint8) if flags is None else np.asarray(flags, np.uint8),
                  np.zeros(n, np.int32) if tid is None else np.asarray(tid, np.int32),
                  (_template(),) if templates is None else tuple(templates), FS, 0.0, "g")


def _old_onset_sigma(on, noise_rms):
    """The stages module's own bound before it used meshphase.signal.crb (kept to hold the numbers)."""
    out = np.full(len(on), np.nan)
    if not len(on) or not on.templates:
        return out
    tid = np.clip(on.template_id, 0, len(on.templates) - 1)
    has = on.template_id >= 0
    floor = np.where(has, np.array([ONSET_RESOLUTION * tp.fwhm for tp in on.templates])[tid], np.nan)
    if not (isinstance(noise_rms, float) and math.isfinite(noise_rms)) or noise_rms <= 0:
        return floor
    info = []
    for tp in on.templates:
        d = np.gradient(np.asarray(tp.samples, dtype=float)) * tp.rate
        info.append(tp.decimation * float(np.sum(d * d)))
    s2 = np.where(has, np.asarray(info)[tid], np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = noise_rms / (np.abs(on.amplitude) * np.sqrt(s2))
    out = np.fmax(out, floor)
    return np.where(np.isfinite(out), out, np.nan)


# ----------------------------------------------------------------------------- timing centre
def test_timing_centre_of_a_symmetric_pulse_is_its_middle_and_moves_with_skew():
    tp = _template(41)
    assert timing_centre(tp) == pytest.approx(20.0, abs=1e-9)
    assert timing_centre(_template(41, skew=0.3)) != pytest.approx(20.0, abs=1e-3)
    flat = Template(np.ones(9), FS, 1, 4.0, 3.0, 0.01)
    assert timing_centre(flat) == 4.0                      # no slope: the peak


def test_timing_centre_bad_and_empty_input():
    with pytest.raises(TypeError, match="Template"):
        timing_centre(np.ones(5))
    with pytest.raises(ValueError, match="at least 2"):
        timing_centre(Template(np.empty(0), FS, 1, 0.0, 0.0, 0.01))


def test_pass_times_move_to_the_timing_centre():
    tp = _template(41, ref=12.0)                           # centre 20: 8 samples later
    on = _onsets([0.1, 0.2, 0.3], templates=[tp])
    np.testing.assert_allclose(pass_times(on), on.times - (12.0 - 20.0) / FS, rtol=0, atol=1e-15)
    # an onset timed by no template keeps its time
    on = _onsets([0.1, 0.2, 0.3], tid=[0, -1, 0], templates=[tp])
    np.testing.assert_allclose(pass_times(on) - on.times, [8e-3, 0.0, 8e-3], rtol=0, atol=1e-15)


def _crossings(h):
    """Half-maximum crossings of the main lobe, linearly interpolated [samples]."""
    i = int(np.argmax(h))
    lo = i - int(np.argmax(h[i::-1] < 0.5))               # last sample below, rising side
    hi = i + int(np.argmax(h[i:] < 0.5))                  # first sample below, falling side
    left = lo + (0.5 - h[lo]) / (h[lo + 1] - h[lo])
    right = hi - 1 + (h[hi - 1] - 0.5) / (h[hi - 1] - h[hi])
    return left, right


def _stretched(s, n_pulses, noise=0.0, rng=None):
    """The skewed test pulse stretched by s, on a 161-sample grid, with Gaussian noise of SD
    ``noise`` in every sample (a template learnt from few pulses); onset feature and FWHM
    from interpolated half-maximum crossings, as the detector reads them."""
    u = (np.arange(161) - 80.0) / 40.0 / s
    h = np.exp(-0.5 * ((u - 0.3 * u * u) / 0.3) ** 2) - 0.2 * np.exp(-0.5 * ((u - 0.9) / 0.2) ** 2)
    if noise:
        h = h + rng.normal(0.0, noise, h.size)
    h = h / h.max()
    left, right = _crossings(h)
    return Template(h, FS, 1, float(np.argmax(h)), left, (right - left) / FS, n_pulses=n_pulses)


def test_centre_shifts_carry_the_best_templates_centre_by_the_fwhm_ratio():
    a, b = _stretched(1.0, 200), _stretched(1.1, 50)
    own = [(timing_centre(t) - t.ref) / t.rate for t in (a, b)]
    got = centre_shifts([b, a])
    # the template of most pulses keeps its own centre; the other gets it scaled
    assert got[1] == pytest.approx(own[0], rel=1e-12)
    assert got[0] == pytest.approx(own[0] * b.fwhm / a.fwhm, rel=1e-12)
    # noise-free, a stretch moves its own centre by the same ratio (to the linear
    # interpolation of the half-maximum crossings)
    assert got[0] == pytest.approx(own[1], rel=0.01)
    # one template, or none with a usable FWHM: each keeps its own
    assert centre_shifts([a]) == pytest.approx([own[0]])
    bad = dataclasses.replace(b, fwhm=float("nan"))
    assert centre_shifts([a, bad])[1] == pytest.approx(own[1])
    assert centre_shifts([]).size == 0
    with pytest.raises(TypeError, match="Template"):
        centre_shifts([a, "b"])


def test_pass_times_do_not_step_when_a_noisy_template_takes_over():
    # the same pulses timed by two templates of one shape, the second learnt from few
    # pulses (noise 1 % of the peak per sample): its own centroid moves by up to 2 samples
    # (SD 0.7), its onset feature (a half-maximum crossing) by a few tenths; the pass times
    # step by no more than that feature does
    rng = np.random.default_rng(3)
    a = _stretched(1.0, 500)
    steps_own, steps = [], []
    for _ in range(20):
        b = _stretched(1.0, 20, noise=0.01, rng=rng)
        on = _onsets([0.1, 0.2, 0.3, 0.4], tid=[0, 0, 1, 1], templates=[a, b])
        # the onsets of b's pulses as b would time them: its onset feature against a's
        on = dataclasses.replace(on, times=on.times + np.array([0, 0, 1, 1]) * (b.ref - a.ref) / FS)
        pt = pass_times(on)
        steps.append((pt[2] - pt[1]) - (pt[1] - pt[0]))
        steps_own.append((timing_centre(b) - timing_centre(a)) / FS)
    assert np.max(np.abs(steps)) < 0.4 / FS
    assert np.max(np.abs(steps_own)) > 1.0 / FS


def test_pass_times_empty_no_templates_and_bad_input():
    assert pass_times(_onsets([])).size == 0
    on = _onsets([0.1, 0.2], templates=[])
    assert pass_times(on) is on.times
    with pytest.raises(TypeError, match="Onsets"):
        pass_times(np.array([0.1, 0.2]))


# ----------------------------------------------------------------------------- usable onsets
def test_usable_keeps_gap_flagged_pulses_whose_window_stays_finite():
    flags = [0, FLAG_GAP, FLAG_GAP, FLAG_GAP | FLAG_CLIPPED, FLAG_CLIPPED]
    on = _onsets([0.1, 0.2, 0.3, 0.4, 0.5], flags=flags, width=np.full(5, 0.002))
    # without gap runs every gap-only pulse counts as bridged
    np.testing.assert_array_equal(usable_onsets(on, None, FS, 0.0), [1, 1, 1, 0, 0])
    # a run over the third pulse's window (+-2 half widths = +-4 samples at 300) removes it
    runs = np.array([[296, 298]])
    np.testing.assert_array_equal(usable_onsets(on, runs, FS, 0.0), [1, 1, 0, 0, 0])
    np.testing.assert_array_equal(usable_onsets(on, np.array([[310, 320]]), FS, 0.0), [1, 1, 1, 0, 0])


def test_usable_empty_and_bad_input():
    assert usable_onsets(_onsets([]), None, FS, 0.0).size == 0
    with pytest.raises(ValueError, match="fs"):
        usable_onsets(_onsets([0.1]), None, 0.0, 0.0)
    with pytest.raises(TypeError, match="Onsets"):
        usable_onsets([0.1], None, FS, 0.0)


# ----------------------------------------------------------------------------- gaps
def _quality(gaps=None, dropouts=None, conditioned=None, t0=0.0):
    e = np.empty((0, 2), np.int64)
    q = ChannelQuality("g", FS, t0, 10_000, e if gaps is None else np.asarray(gaps), e, e,
                       dropout_runs=e if dropouts is None else np.asarray(dropouts))
    if conditioned is not None:
        q = dataclasses.replace(q, conditioned_gap_runs=np.asarray(conditioned))
    return q


def test_conditioned_gap_runs_from_the_report():
    assert conditioned_gap_runs(None) is None
    q = _quality(gaps=[[10, 20]], dropouts=[[40, 50]])
    np.testing.assert_array_equal(conditioned_gap_runs(q), q.all_gap_runs())
    q = _quality(gaps=[[10, 20]], conditioned=[[12, 14]])
    np.testing.assert_array_equal(conditioned_gap_runs(q), [[12, 14]])


def test_gap_intervals_of_every_channel_in_seconds():
    qa = _quality(gaps=[[10, 20]], dropouts=[[40, 50]], t0=1.0)
    qb = _quality(gaps=[[100, 200]])
    np.testing.assert_allclose(gap_intervals_of({"a": qa, "b": qb}),
                               [[1.01, 1.02], [1.04, 1.05], [0.1, 0.2]], rtol=0, atol=1e-12)
    assert gap_intervals_of({}).shape == (0, 2)
    assert gap_intervals_of({"a": _quality()}).shape == (0, 2)
    with pytest.raises(TypeError, match="dict"):
        gap_intervals_of([qa])


# ----------------------------------------------------------------------------- timing bound
def test_onset_sigma_is_the_crb_of_the_template_at_the_pulse_amplitude():
    rng = np.random.default_rng(5)
    tps = [_template(41), _template(33, decimation=4, skew=0.2, fwhm=0.03), _template(57, decimation=2)]
    n = 200
    on = _onsets(np.sort(rng.uniform(0, 10, n)), amp=rng.normal(0, 1e-4, n),
                 tid=rng.integers(-1, 3, n), templates=tps)
    for noise in (1e-7, 3e-6, 2.5e-4, float("nan"), 0.0, -1.0):
        got, want = onset_sigma(on, noise), _old_onset_sigma(on, noise)
        np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
        ok = np.isfinite(want)
        np.testing.assert_allclose(got[ok], want[ok], rtol=1e-12, atol=0)
    # where the bound is above the floor it is crb_delay_std of the derivative at that amplitude
    tp = tps[0]
    d = np.gradient(tp.samples) * tp.rate
    one = _onsets([0.5], amp=[2e-5], templates=[tp])
    assert onset_sigma(one, 1e-6)[0] == pytest.approx(crb_delay_std(2e-5 * d, 1e-6), rel=1e-12)


def test_onset_sigma_floor_empty_and_bad_input():
    tp = _template(41, fwhm=0.02)
    on = _onsets([0.1, 0.2], amp=[1.0, 0.0], templates=[tp])
    # a huge pulse: the resolution floor; a zero amplitude: no bound (NaN)
    got = onset_sigma(on, 1e-12)
    assert got[0] == ONSET_RESOLUTION * 0.02 and math.isnan(got[1])
    assert onset_sigma(_onsets([]), 1e-6).size == 0
    assert np.all(np.isnan(onset_sigma(_onsets([0.1], templates=[]), 1e-6)))
    with pytest.raises(TypeError, match="Onsets"):
        onset_sigma({"times": [0.1]}, 1e-6)


# ----------------------------------------------------------------------------- every gauge
def test_gauge_passes_main_gauges_and_facewidth():
    tp = _template(41, ref=20.0)                           # timing centre = onset feature
    chans = [ChannelSpec("s1", "sun"), ChannelSpec("s2", "sun"), ChannelSpec("r", "ring"),
             ChannelSpec("fw", "facewidth", gear="ring"), ChannelSpec("t", "tacho")]
    ons = {"s1": _onsets([0.1, 0.2, 0.3], templates=[tp]),
           "s2": _onsets([0.15, 0.25], templates=[tp]),
           "r": _onsets([0.12, 0.22], flags=[0, FLAG_CLIPPED], templates=[tp]),
           "fw": _onsets([0.13], templates=[tp])}
    quality = {"s1": _quality()}
    quality["s1"] = dataclasses.replace(quality["s1"], noise_rms=1e-3)   # frozen report
    passes, mains = gauge_passes(chans, ons, quality, FS, 0.0)
    assert mains == {"sun": "s1", "ring": "r"}
    assert [(p.name, p.gear, p.main) for p in passes] == [
        ("s1", "sun", True), ("s2", "sun", False), ("r", "ring", True), ("fw", "ring", False)]
    assert all(isinstance(p, GaugePasses) for p in passes)
    np.testing.assert_allclose(passes[0].times, [0.1, 0.2, 0.3])
    assert passes[0].sigma is not None and passes[1].sigma is not None   # the floor at least
    np.testing.assert_allclose(passes[2].times, [0.12])                  # the clipped one left out


def test_gauge_passes_dead_main_gauge_warns_empty_and_bad_input():
    chans = [ChannelSpec("s", "sun")]
    with pytest.warns(ProcessingWarning, match="no usable pulse"):
        passes, mains = gauge_passes(chans, {"s": _onsets([0.1], flags=[FLAG_CLIPPED])}, {}, FS, 0.0)
    assert passes == [] and mains == {"sun": "s"}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert gauge_passes([], {}, {}, FS, 0.0) == ([], {})
    with pytest.raises(TypeError, match="dicts"):
        gauge_passes(chans, [], {}, FS, 0.0)
    with pytest.raises(ValueError, match="fs"):
        gauge_passes(chans, {}, {}, -1.0, 0.0)
