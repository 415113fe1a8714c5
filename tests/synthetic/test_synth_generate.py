"""generate / generate_blocks: truth, statistics measured back, reproducibility, scenarios."""

import math
import tracemalloc

import numpy as np
import pytest
from scipy.optimize import brentq

from meshphase.models.mesh_phasing import ideal_phasing
from meshphase.recording import Recording
from meshphase.synthetic import (SCENARIOS, Artefacts, GroundTruth, generate, generate_blocks,
                                 get_scenario, list_scenarios)
from meshphase.synthetic.generate import draw_errors, resolve_seed
from meshphase.synthetic.gauges import face_load_factor
from meshphase.synthetic.kinematics import gauge_rates

from _synth_reference import residual_ref

TWO_PI = 2 * math.pi


def short(name):
    """A duration that covers every pass type of a scenario but keeps the test fast [s]."""
    cfg = get_scenario(name)
    return 0.06 if cfg.fs > 20000 else 13.0


def clean_and(cfg, **artefacts):
    """The config with only the given artefacts (and the same events)."""
    return cfg.with_(artefacts=Artefacts(**artefacts))


# ----------------------------------------------------------------------------- scenarios

@pytest.mark.parametrize("name", list_scenarios())
def test_every_scenario_generates_consistently(name):
    rec, truth = generate(name, duration=short(name), seed=11)
    cfg = get_scenario(name)
    assert isinstance(rec, Recording) and isinstance(truth, GroundTruth)
    assert rec.fs == cfg.fs and rec.n_samples == round(short(name) * cfg.fs)
    assert rec.names == [g.name for g in cfg.gauges] + (["tacho"] if cfg.tacho else []) + (
        [cfg.encoder.name] if cfg.encoder else [])
    assert [c.kind for c in rec.channels[:len(cfg.gauges)]] == [g.kind for g in cfg.gauges]
    assert rec.meta["scenario"] == name and rec.meta["seed"] == 11
    assert truth.seed == 11 and truth.scenario == name and truth.n_samples == rec.n_samples
    # a scenario without face-width gauges simulates none; without artefacts adds none
    if "facewidth" not in SCENARIOS[name].tags:
        assert not rec.by_kind("facewidth")
    if not cfg.artefacts.any:
        assert all(v == 0.0 for v in truth.noise_rms.values()) and truth.gaps.size == 0
        assert np.all(np.isfinite(rec.data))
    for g in cfg.gauges:
        ev = truth.events[g.name]
        assert len(ev) > 0
        assert np.all((ev.time >= rec.t0) & (ev.time < rec.t_end))
        assert np.all(np.diff(ev.time) > 0)
        assert set(np.unique(ev.planet)) <= set(range(1, cfg.gearset.n_planets + 1))
    assert len(truth.passes["sun"]) > 0
    gs_ideal, gr_ideal = ideal_phasing(cfg.gearset)
    assert truth.ideal_phasing["sun"] == gs_ideal.tolist()
    assert truth.ideal_phasing["ring"] == gr_ideal.tolist()


def test_registry_api():
    from meshphase.synthetic import describe_scenarios
    from meshphase.synthetic.scenarios import Scenario, register

    assert "seed_rig" in SCENARIOS and "one_hour" in list_scenarios()
    rows = describe_scenarios()
    assert [r["name"] for r in rows] == list_scenarios()
    assert next(r for r in rows if r["name"] == "one_hour")["duration"] == 3600.0
    with pytest.raises(ValueError, match="already registered"):
        register(Scenario("seed_rig", "dup", lambda: None))
    with pytest.raises(TypeError):
        register("seed_rig")
    with pytest.raises(ValueError, match="known: "):
        get_scenario("nope")
    with pytest.raises(TypeError):
        get_scenario(3)
    assert get_scenario("seed_rig", duration=2.0).duration == 2.0


def test_seed_rig_speeds_and_gearset():
    cfg = get_scenario("seed_rig")
    g, sp = cfg.gearset, cfg.speeds
    # seed 000: sun 18.19 r/min, carrier 1.06 r/min at 5120 Hz
    assert sp.sun * 60 / TWO_PI == pytest.approx(18.19, rel=1e-12)
    assert sp.carrier * 60 / TWO_PI == pytest.approx(1.06, rel=1e-12)
    assert cfg.fs == 5120.0 and g.n_planets == 4
    assert (g.z_sun + g.z_ring) % g.n_planets == 0                  # assemblable
    assert g.z_planet == (g.z_ring - g.z_sun) // 2                  # standard centre distance
    # Willis with the ring driven: w_r = w_c - (Z_s/Z_r)(w_s - w_c) = -3.862 r/min
    assert sp.ring * 60 / TWO_PI == pytest.approx(1.06 - 25 / 87 * (18.19 - 1.06), rel=1e-12)


# ----------------------------------------------------------------------------- truth

@pytest.mark.parametrize("name", ["table1_high_speed", "table1_high_speed_ccw"])
def test_truth_phasing_equals_parker_without_errors(name):
    rec, truth = generate(name, duration=0.3, seed=0)
    for gauge, key in (("sun", "sun"), ("ring", "ring")):
        p = truth.passes[gauge]
        ideal = np.asarray(truth.ideal_phasing[key])
        assert len(p) >= 3 * 3
        np.testing.assert_allclose(p.gamma, ideal[p.planet - 1], atol=1e-9)
        np.testing.assert_allclose(p.gamma_model, ideal[p.planet - 1], atol=1e-9)


def test_truth_phasing_with_errors_from_times_and_model():
    rec, truth = generate("table2_case2", duration=0.2, seed=0)
    cfg = get_scenario("table2_case2")
    for gauge in ("sun", "ring"):
        p = truth.passes[gauge]
        w, z = gauge_rates(cfg.gearset, cfg.speeds, gauge)
        T = TWO_PI / (z * abs(w))
        # constant speed: gamma = frac((t_n - t_1) / T) (spec section 3, counted forward)
        g_time = np.mod((p.time - p.time_planet1) / T, 1.0)
        d = np.abs(g_time - p.gamma)
        assert np.all(np.minimum(d, 1 - d) < 1e-9)
        # the model's instantaneous value differs by the change during the pass: bounded by
        # a few times Dev (case 2 Dev_s ~ 0.02-0.1 mesh cycles)
        d = np.abs(p.gamma_model - p.gamma)
        assert np.all(np.minimum(d, 1 - d) < 0.25)
        assert np.std(np.minimum(d, 1 - d)) > 1e-4       # the errors do move the phasing


def test_truth_events_match_brentq_under_speed_ripple():
    name = "speed_ripple"
    rec, truth = generate(name, duration=25.0, seed=0)
    cfg = get_scenario(name)
    errors = cfg.errors
    for g in cfg.gauges:
        ev = truth.events[g.name]
        theta = cfg.tooth_angle(g)
        w, _ = gauge_rates(cfg.gearset, cfg.speeds, g.gear)
        for i in range(0, len(ev), 2):
            te = ev.time[i] - rec.t0
            h = 0.02 * TWO_PI / abs(w)
            ref = brentq(residual_ref, te - h, te + h,
                         args=(g.gear, ev.planet[i] - 1, theta, cfg.gearset, cfg.speeds, errors,
                               cfg.speed), xtol=1e-15, rtol=1e-15)
            assert abs(ref - te) * abs(w) < 1e-10


def test_pulses_sit_at_truth_times_with_truth_amplitudes():
    rec, truth = generate("facewidth_offcentre", duration=30.0, seed=1)
    for name, ev in truth.events.items():
        x = rec.channel(name)
        peak = ev.time + truth.pulse[name]["peak_offset"] * ev.mesh_period
        i = np.rint((peak - rec.t0) * rec.fs).astype(int)
        ok = (i > 0) & (i < rec.n_samples - 1)
        # a sample within half a sample of the peak: the pulse is flat there (717 samples
        # per mesh period), so it reads the amplitude to 1e-4
        np.testing.assert_allclose(x[i[ok]], ev.amplitude[ok], rtol=1e-4)


def test_load_sharing_and_face_width_centroid_measured_back():
    cfg = get_scenario("facewidth_offcentre")
    rec, truth = generate(cfg, duration=30.0, seed=1)
    ls = np.asarray(cfg.load_sharing)
    # ring gauge: LS_n = N eps_n / sum eps (spec section 6) from the per-planet peak strains
    ev = truth.events["ring"]
    peaks = np.array([ev.amplitude[ev.planet == n].mean() for n in range(1, 5)])
    np.testing.assert_allclose(4 * peaks / peaks.sum(), ls, rtol=1e-12)
    # face-width gauges: least-squares line through the readings gives Z per planet (spec 7)
    names = [g for g in cfg.gauges if g.name.startswith("ring_fw")]
    z = np.array([g.face_position for g in names])
    b = cfg.gearset.face_width
    for n in range(1, 5):
        amp = np.array([truth.events[g.name].amplitude[truth.events[g.name].planet == n][0]
                        for g in names])
        slope, icpt = np.polyfit(z, amp, 1)
        assert slope / icpt * b ** 2 / 12 == pytest.approx(cfg.centroid_ring[n - 1], rel=1e-9)
    np.testing.assert_allclose(truth.centroid_ring, cfg.centroid_ring)


def test_partial_contact_unloads_gauges():
    rec, truth = generate("facewidth_partial", duration=20.0, seed=1)
    cfg = get_scenario("facewidth_partial")
    fw = [g for g in cfg.gauges if g.name.startswith("ring_fw")]
    f = face_load_factor([g.face_position for g in fw], cfg.centroid_ring[0], cfg.gearset.face_width)
    assert f[0] == pytest.approx(0, abs=1e-12)    # z = -16 mm lies off the contact
    assert np.max(np.abs(rec.channel(fw[0].name))) < 1e-15
    assert np.max(rec.channel(fw[-1].name)) > 2 * 100e-6


def test_tacho_edges_at_truth_times():
    rec, truth = generate("table1_high_speed", duration=0.2, seed=0)
    x = rec.channel("tacho")
    i = (truth.tacho_times - rec.t0) * rec.fs
    assert truth.tacho_times.size == pytest.approx(0.2 * 100 / TWO_PI, abs=1)
    # cumulative high time: each pulse integrates to level * width [samples]
    width = (truth.tacho_stop_times - truth.tacho_times) * rec.fs
    assert x.sum() / 5.0 == pytest.approx(width[i + width < rec.n_samples].sum(), rel=0.02)
    k = np.floor(i + 0.5).astype(int)
    k = k[k >= 2]
    assert np.all(x[k + 2] == 5.0) and np.all(x[k - 2] == 0.0)


def test_fixed_ring_tacho_precedes_planet1_ring_pass():
    rec, truth = generate("table1_high_speed", duration=0.3, seed=0)
    ev = truth.events["ring"]
    t1 = ev.time[ev.planet == 1]
    period = TWO_PI / 100.0
    for t in truth.tacho_times:
        nxt = t1[t1 > t]
        if nxt.size:
            # a quarter of the planet spacing of carrier rotation later
            assert nxt[0] - t == pytest.approx(period / 16, rel=1e-9)


# ----------------------------------------------------------------------------- artefacts measured back

def test_snr_measured_back():
    cfg = get_scenario("seed_rig")
    clean, _ = generate(cfg, duration=60.0, seed=3)
    noisy, truth = generate(clean_and(cfg, snr_db=20.0), duration=60.0, seed=3)
    for g in cfg.gauges:
        r = noisy.channel(g.name) - clean.channel(g.name)
        snr = 20 * math.log10(g.amplitude / r.std())
        # 307200 samples: std known to 0.13 % -> 0.011 dB; 0.05 dB tolerance
        assert snr == pytest.approx(20.0, abs=0.05)
        assert truth.noise_rms[g.name] == pytest.approx(g.amplitude / 10, rel=1e-12)


def test_drift_and_hum_measured_back():
    cfg = get_scenario("seed_rig")
    clean, _ = generate(cfg, duration=40.0, seed=3)
    rec, truth = generate(clean_and(cfg, drift_amplitude=20e-6, drift_time_constant=30.0,
                                    hum_amplitude=5e-6, hum_frequency=60.0,
                                    hum_harmonics=(1.0,)), duration=40.0, seed=3)
    r = rec.channel("sun") - clean.channel("sun")
    fs = rec.fs
    # hum: FFT peak at 60 Hz with amplitude 5 µε
    n = r.size
    spec = np.fft.rfft(r - r.mean())
    f = np.fft.rfftfreq(n, 1 / fs)
    k = np.argmax(np.abs(spec[f > 1]))
    assert f[f > 1][k] == pytest.approx(60.0, abs=fs / n)
    assert 2 * np.abs(spec[f > 1][k]) / n == pytest.approx(5e-6, rel=0.01)
    # drift: means over whole mains cycles remove the hum and leave D (1 - exp(-t / T))
    m = int(fs / 60 * 3 * 5)   # 1280 samples = 15 cycles of 60 Hz exactly
    blocks = r[: n // m * m].reshape(-1, m).mean(axis=1)
    tb = (np.arange(blocks.size) * m + (m - 1) / 2) / fs
    expect = 20e-6 * (1 - np.exp(-tb / 30.0))
    np.testing.assert_allclose(blocks, expect, atol=2e-8)


def test_quantisation_and_clipping():
    rec, truth = generate("adc16_clipped", duration=13.0, seed=2)
    lsb = 2 * 140e-6 / 2 ** 16
    x = rec.channel("sun")
    np.testing.assert_allclose(x / lsb, np.rint(x / lsb), atol=1e-6)
    assert x.max() == pytest.approx(140e-6 - lsb)    # sun peaks 150 µε: clipped at the top code
    assert np.sum(x == x.max()) > 10


def test_gaps_are_nan_in_every_channel():
    rec, truth = generate("gaps", duration=60.0, seed=5)
    assert truth.gaps.shape[0] > 5
    mask = np.zeros(rec.n_samples, bool)
    for a, b in truth.gaps:
        mask[a:b] = True
    for j in range(rec.n_channels):
        assert np.array_equal(np.isnan(rec.data[:, j]), mask)


def test_gain_error_scales_pulses():
    cfg = get_scenario("seed_rig")
    clean, _ = generate(cfg, duration=13.0, seed=3)
    rec, truth = generate(clean_and(cfg, gain_error={"sun": 0.03}, gain_error_std=0.0),
                          duration=13.0, seed=3)
    np.testing.assert_allclose(rec.channel("sun"), 1.03 * clean.channel("sun"), rtol=1e-14, atol=1e-20)
    assert np.array_equal(rec.channel("ring"), clean.channel("ring"))
    assert truth.gain_errors == {"sun": 0.03, "ring": 0.0}


def test_speed_ramp_shortens_mesh_period():
    rec, truth = generate("speed_ramp", duration=60.0, seed=0)
    ev = truth.events["sun"]
    # 20 % faster after 60 s: the mesh period shrinks by 1/1.2 (ripple 1 % on top)
    assert ev.mesh_period[-1] / ev.mesh_period[0] == pytest.approx(1 / 1.2, rel=0.025)
    d = np.diff(ev.time[ev.planet == 1])
    assert d[-1] < d[0] * 0.9


# ----------------------------------------------------------------------------- reproducibility

def test_same_seed_same_output_different_seed_differs():
    a, ta = generate("noisy", duration=13.0, seed=42)
    b, tb = generate("noisy", duration=13.0, seed=42)
    c, tc = generate("noisy", duration=13.0, seed=43)
    assert a == b and ta == tb
    assert not np.array_equal(a.data, c.data)
    assert ta.gain_errors != tc.gain_errors


@pytest.mark.parametrize("name, block", [("rig_realistic", 0.37), ("gaps", 1.0001),
                                         ("table2_case3", 0.0071), ("speed_ramp", 3.3)])
def test_blocks_equal_whole(name, block):
    dur = 0.05 if name.startswith("table") else 13.0
    whole, truth = generate(name, duration=dur, seed=9)
    stream = generate_blocks(name, duration=dur, seed=9, block=block)
    assert stream.truth == truth
    parts = list(stream)
    assert len(parts) == len(stream) > 2
    data = np.concatenate([p.data for p in parts])
    assert np.array_equal(data, whole.data, equal_nan=True)
    assert [p.t0 for p in parts] == pytest.approx([whole.t0 + i * round(block * whole.fs) / whole.fs
                                                   for i in range(len(parts))])
    assert all(p.channels == whole.channels for p in parts)


def test_table2_case3_draws_errors_with_the_seed():
    _, t1 = generate("table2_case3", duration=0.01, seed=1)
    _, t2 = generate("table2_case3", duration=0.01, seed=2)
    assert t1.errors != t2.errors
    e = draw_errors(get_scenario("table2_case3").errors, 4, 1)
    assert t1.errors["e_sun"] == pytest.approx(float(e.e_sun))
    assert np.all(np.asarray(e.e_planet) >= 0)
    # Table 2 case 3 bands: e_s 0.2 mm as 3 sigma -> |e| well below 1 mm
    assert float(e.e_sun) < 1e-3


def _stream_peak(duration, block):
    stream = generate_blocks("one_hour", duration=duration, seed=0, block=block)
    tracemalloc.start()
    try:
        n = 0
        for rec in stream:
            n += rec.n_samples
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert n == stream.n_samples == round(duration * 5120)
    return peak


def test_block_stream_memory_is_flat():
    """Peak traced memory while streaming the one-hour scenario does not grow with duration."""
    block = 10.0
    n_block_bytes = 3 * round(block * 5120) * 8
    p1 = _stream_peak(60.0, block)
    p3 = _stream_peak(240.0, block)
    # 4x the duration: the same handful of blocks in flight (events are ~1 per s: tiny)
    assert p3 < 1.2 * p1 + 0.2 * n_block_bytes
    assert p3 < 12 * n_block_bytes


@pytest.mark.slow
def test_one_hour_streams_in_flat_memory():
    stream = generate_blocks("one_hour", seed=0, block=60.0)
    tracemalloc.start()
    try:
        total = sum(r.n_samples for r in stream)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert total == 3600 * 5120
    assert peak < 12 * 3 * 60 * 5120 * 8


# ----------------------------------------------------------------------------- inputs

def test_progress_callback_and_seed_sources():
    seen = []
    rec, truth = generate("seed_rig", duration=2.0, seed=1, progress=lambda d, t: seen.append((d, t)))
    assert seen[-1] == (rec.n_samples, rec.n_samples)
    rng = np.random.default_rng(5)
    s = resolve_seed(rng=rng)
    assert s == resolve_seed(rng=np.random.default_rng(5))
    assert isinstance(resolve_seed(), int)
    _, t = generate("seed_rig", duration=1.0, rng=np.random.default_rng(5))
    assert t.seed == s


def test_generate_bad_and_empty_input():
    with pytest.raises(ValueError, match="unknown scenario"):
        generate("nope")
    with pytest.raises(TypeError, match="scenario_or_config"):
        generate(42)
    with pytest.raises(ValueError, match="duration"):
        generate("seed_rig", duration=-1.0)
    with pytest.raises(ValueError, match="no sample"):
        generate("seed_rig", duration=1e-5)          # empty: shorter than one sample
    with pytest.raises(ValueError, match="seed or rng"):
        generate("seed_rig", duration=1.0, seed=1, rng=2)
    with pytest.raises(ValueError, match="seed"):
        generate("seed_rig", duration=1.0, seed=-3)
    with pytest.raises(TypeError, match="progress"):
        generate("seed_rig", duration=1.0, seed=1, progress="yes")
    with pytest.raises(ValueError, match="block"):
        generate_blocks("seed_rig", duration=1.0, seed=1, block=0.0)


def test_float32_output():
    cfg = get_scenario("noisy").with_(dtype="float32")
    rec, _ = generate(cfg, duration=5.0, seed=1)
    ref, _ = generate(get_scenario("noisy"), duration=5.0, seed=1)
    assert rec.data.dtype == np.float32
    np.testing.assert_allclose(rec.data, ref.data, rtol=1e-6, atol=1e-12)
