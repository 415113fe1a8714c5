"""Onset detectors by name (meshphase.onsets.detector): the registry, the interface, the
timing model the onsets carry, the scene's ``[onsets] detector``, and a second detector (a
plain threshold crossing, defined here) run through a scene end to end."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from meshphase.kinematics.passes import gauge_passes, onset_sigma, pass_times, usable_onsets
from meshphase.onsets import (DEFAULT_DETECTOR, OnsetDetector, Onsets, OnsetStream, OnsetTiming, TemplateTiming,
                              check_detector, detect_onsets_recording, detect_recording, detector_names,
                              make_detector, register_detector, unregister_detector)
from meshphase.recording import Recording
from meshphase.run.scene import SceneError, parse_scene
from meshphase.run.stages import run_scene
from meshphase.runtime.registry import Registry

FS = 5120.0               # the pulse trains of conftest.make_train


# ----------------------------------------------------------------------------- a second detector
@dataclass(frozen=True)
class SlopeTiming:
    """Timing of a threshold crossing: noise RMS over the slope at the crossing."""

    slope: np.ndarray            # [data units / s] per onset

    def __len__(self) -> int:
        return int(self.slope.size)

    def centre_shifts(self) -> np.ndarray:
        return np.zeros(self.slope.size)

    def sigma(self, noise_rms, noise=None) -> np.ndarray:
        if not (isinstance(noise_rms, float) and math.isfinite(noise_rms) and noise_rms > 0):
            return np.full(self.slope.size, np.nan)
        return noise_rms / np.abs(self.slope)

    def select(self, mask) -> "SlopeTiming":
        return SlopeTiming(self.slope[np.asarray(mask)])


class ThresholdDetector:
    """Rising crossings of half the pulses' height (linear interpolation), runs above it
    closer than a quarter of their median length merged: no template, no decimation."""

    def __init__(self, fs, *, t0=0.0, channel=None, mesh_freq=None, flag_runs=None, gap_runs=None,
                 gap_guard=0.0):
        self.fs, self.t0, self.channel = float(fs), float(t0), channel
        self.parts: list = []

    @property
    def n_samples(self) -> int:
        return sum(p.size for p in self.parts)

    @property
    def block_samples(self) -> int:
        return 1 << 16

    def feed(self, x) -> None:
        self.parts.append(np.asarray(x, dtype=np.float64))

    def finish(self) -> Onsets:
        x = np.concatenate(self.parts) if self.parts else np.empty(0)
        x = np.where(np.isfinite(x), x, np.nanmedian(x) if x.size else 0.0)
        med = float(np.median(x)) if x.size else 0.0
        lo, hi = np.quantile(x - med, [0.001, 0.999]) if x.size else (0.0, 0.0)
        pol = 1 if hi >= -lo else -1
        y = pol * (x - med)
        level = 0.5 * max(hi, -lo)
        above = np.concatenate([[False], y > level, [False]]) if x.size else np.zeros(2, bool)
        starts = np.flatnonzero(~above[:-1] & above[1:])          # first sample above
        stops = np.flatnonzero(above[:-1] & ~above[1:])           # first sample below again
        if starts.size:
            gap_min = 0.25 * np.median(stops - starts)
            keep = np.ones(starts.size, bool)
            keep[1:] = starts[1:] - stops[:-1] > gap_min              # noise dips merge
            ends = np.append(stops[np.flatnonzero(keep)[1:] - 1], stops[-1])
            starts = starts[keep]
            long = ends - starts > gap_min
            starts, ends = starts[long & (starts > 0)], ends[long & (starts > 0)]
        i = starts
        dy = y[i] - y[i - 1]
        index = (i - 1) + (level - y[i - 1]) / dy
        amp = np.array([y[a:b].max() for a, b in zip(i, ends)]) if i.size else np.empty(0)
        n = index.size
        return Onsets(self.t0 + index / self.fs, index, np.full(n, np.nan), pol * amp,
                      (ends - i) / self.fs, np.zeros(n, np.uint8), np.full(n, -1, np.int32), (),
                      self.fs, self.t0, self.channel, "rise", 0.5, pol if n else 0,
                      SlopeTiming(dy * self.fs))


@pytest.fixture
def threshold():
    register_detector("threshold", ThresholdDetector)
    yield "threshold"
    unregister_detector("threshold")


# ----------------------------------------------------------------------------- the registry
def test_matched_is_built_in_and_the_default():
    assert DEFAULT_DETECTOR == "matched" and "matched" in detector_names()
    det = make_detector("matched", 1000.0, t0=0.0, channel="g", mesh_freq=50.0)
    assert isinstance(det, OnsetStream) and isinstance(det, OnsetDetector)
    # 16 pulse widths of 0.8 / 50 s at 1 kHz are far below the default block
    assert det.block_samples == 1 << 20
    # 16 pulse widths of 0.8 / 1 s at 1 MHz are more than it
    assert make_detector("matched", 1e6, mesh_freq=1.0).block_samples == int(16 * (0.8 * 1e6 / 1.0))
    assert det.n_samples == 0 and len(det.finish()) == 0       # empty input: no onset


def test_register_and_unregister(threshold):
    assert threshold in detector_names() and check_detector(threshold) == threshold
    assert isinstance(make_detector(threshold, 100.0), ThresholdDetector)
    with pytest.raises(ValueError, match="registered already"):
        register_detector(threshold, ThresholdDetector)
    register_detector(threshold, ThresholdDetector, replace=True)


def test_registry_bad_input():
    with pytest.raises(ValueError, match=r"unknown onset detector 'nope'; known: .*matched"):
        check_detector("nope")
    with pytest.raises(ValueError, match="unknown onset detector"):
        make_detector("nope", 100.0)
    with pytest.raises(TypeError, match="name"):
        check_detector(3)
    with pytest.raises(ValueError, match="built-in"):
        register_detector("matched", ThresholdDetector, replace=True)
    with pytest.raises(ValueError, match="built-in"):
        unregister_detector("matched")
    with pytest.raises(ValueError, match="empty"):
        register_detector(" ", ThresholdDetector)
    with pytest.raises(TypeError, match="callable"):
        register_detector("x", 5)
    with pytest.raises(ValueError, match="unknown"):
        unregister_detector("never_registered")


def test_a_factory_must_build_a_detector():
    register_detector("broken", lambda fs, **kw: object())
    try:
        with pytest.raises(TypeError, match="not an OnsetDetector"):
            make_detector("broken", 100.0)
    finally:
        unregister_detector("broken")


def test_registry_loads_a_built_in_only_when_asked():
    reg = Registry("thing", {"dummy": "no_such_module_anywhere:Thing"})
    assert reg.names() == ("dummy",)                      # naming it imports nothing
    with pytest.raises(ModuleNotFoundError):
        reg.factory("dummy")
    assert Registry("thing", {}).names() == ()            # empty registry


# ----------------------------------------------------------------------------- detect_recording
def test_detect_recording_equals_the_matched_filter(make_train):
    x, _, _ = make_train(snr_db=25.0, rng=4)
    fs = FS
    rec = Recording(x[:, None], fs, ["sun_g1"])
    a = detect_recording(rec, "sun_g1")
    b = detect_onsets_recording(rec, "sun_g1")
    assert len(a) > 10 and np.array_equal(a.times, b.times) and np.array_equal(a.amplitude, b.amplitude)
    assert a.polarity == 1 and isinstance(a.timing, TemplateTiming)
    empty = detect_recording(Recording(np.empty((0, 1)), fs, ["sun_g1"]), "sun_g1")
    assert len(empty) == 0 and empty.polarity == 0


def test_detect_recording_bad_input():
    rec = Recording(np.zeros((100, 1)), 100.0, ["g"])
    with pytest.raises(TypeError, match="Recording"):
        detect_recording(np.zeros(100), "g")
    with pytest.raises(TypeError, match="channel"):
        detect_recording(rec, 0)
    with pytest.raises(TypeError, match="from the recording"):
        detect_recording(rec, "g", fs=100.0)
    with pytest.raises(ValueError, match="unknown onset detector"):
        detect_recording(rec, "g", detector="nope")
    with pytest.raises(TypeError, match="ChannelQuality"):
        detect_recording(rec, "g", quality=object())


# ----------------------------------------------------------------------------- the timing model
def test_onsets_check_their_timing_model():
    t = np.array([0.1, 0.2, 0.3])
    z = np.zeros(3)
    args = (t, t * 100, z, np.ones(3), z, np.zeros(3, np.uint8), np.full(3, -1, np.int32), (), 100.0)
    on = Onsets(*args, timing=SlopeTiming(np.array([1.0, 2.0, 4.0])))
    assert isinstance(on.timing, OnsetTiming)
    assert np.array_equal(on.sigma(2.0), [2.0, 1.0, 0.5])
    assert on.centres is on.times                          # no shift: the onset times themselves
    sel = on.select(np.array([False, True, True]))
    assert np.array_equal(sel.sigma(2.0), [1.0, 0.5]) and np.all(np.isnan(sel.sigma(float("nan"))))
    with pytest.raises(ValueError, match="describes 2 onsets"):
        Onsets(*args, timing=SlopeTiming(np.ones(2)))
    with pytest.raises(TypeError, match="OnsetTiming"):
        Onsets(*args, timing=object())
    empty = on.select(np.zeros(3, bool))
    assert empty.sigma(1.0).size == 0 and empty.centres.size == 0


def test_passes_use_only_the_timing_model():
    t = np.array([0.1, 0.2, 0.3])
    z = np.zeros(3)

    @dataclass(frozen=True)
    class Shifted(SlopeTiming):
        def centre_shifts(self):
            return np.full(self.slope.size, 0.01)

        def select(self, mask):
            return Shifted(self.slope[np.asarray(mask)])

    on = Onsets(t, t * 100, z, np.ones(3), np.full(3, 0.01), np.zeros(3, np.uint8), np.full(3, -1, np.int32),
                (), 100.0, timing=Shifted(np.array([1.0, 2.0, 4.0])))
    assert np.allclose(pass_times(on), t + 0.01)
    assert np.array_equal(onset_sigma(on, 2.0), [2.0, 1.0, 0.5])
    assert usable_onsets(on, None, 100.0, 0.0).all()


# ----------------------------------------------------------------------------- the scene
def test_scene_chooses_the_detector_by_name(threshold):
    base = 'results = ["phasing"]\n[input]\nsynthetic = "seed_rig"\nminutes = 0.25\n'
    assert parse_scene(base).onset_detector == "matched"
    assert parse_scene(base + '[onsets]\ndetector = "matched"\n').onset_detector == "matched"
    assert parse_scene(base + f'[onsets]\ndetector = "{threshold}"\n').onset_detector == threshold
    with pytest.raises(SceneError, match=r"onsets\.detector.*unknown onset detector 'cusum'; known: matched, "
                                         r"threshold"):
        parse_scene(base + '[onsets]\ndetector = "cusum"\n')
    with pytest.raises(SceneError, match="onsets"):
        parse_scene(base + '[onsets]\ndetector = 3\n')            # the schema: a string
    with pytest.raises(SceneError, match="onsets"):
        parse_scene(base + '[onsets]\nwindow = 3\n')              # no other key


def test_a_second_detector_runs_through_a_scene_end_to_end(threshold):
    text = ('results = ["phasing"]\n[input]\nsynthetic = "seed_rig"\nminutes = 0.25\nseed = 2\n'
            f'[onsets]\ndetector = "{threshold}"\n')
    ctx = run_scene(parse_scene(text))
    assert ctx.failed == {}
    ons = ctx.onsets.by_channel
    assert ons and all(isinstance(o.timing, SlopeTiming) and len(o) >= 3 for o in ons.values())
    assert max(len(o) for o in ons.values()) > 10            # the sun gauge
    # the phasing table of every gauged gear, from the threshold crossings
    tables = ctx.phasing.tables
    assert tables and all(len(tb.gamma) > 0 for tb in tables.values())
    for tb in tables.values():
        assert np.all((tb.gamma >= 0) & (tb.gamma < 1))
        assert np.all(np.isfinite(tb.uncertainty)) and np.all(tb.uncertainty > 0)
        assert np.all(np.isfinite(tb.timing_floor))
    # the uncertainties are the detector's: noise RMS over the slope at each crossing
    rec = ctx.condition.recording
    passes, _ = gauge_passes(rec.channels, ons, ctx.condition.quality, rec.fs, rec.t0)
    assert passes
    for gp in passes:
        on = ons[gp.name]
        ok = usable_onsets(on, None, rec.fs, rec.t0)
        rms = ctx.condition.quality[gp.name].noise_rms
        assert gp.sigma is not None
        assert np.array_equal(gp.sigma, rms / np.abs(on.timing.slope[ok]))
        assert np.array_equal(gp.times, on.times[ok])
