"""Noise, drift, hum, ADC, clipping and gaps: statistics measured back from the samples."""

import math

import numpy as np
import pytest
from scipy import signal

from meshphase.synthetic import artefacts as art


def _noise(sigma, pf, n, fs=5120.0, blocks=None, seed=7, fmin=0.05):
    src = art.NoiseSource(seed, 0, fs, sigma, pf, fmin)
    out = np.zeros(n)
    edges = [0, n] if blocks is None else blocks
    for a, b in zip(edges[:-1], edges[1:]):
        src.add_to(out[a:b], a)
    return out


def test_white_noise_rms():
    x = _noise(2e-6, 0.0, 400_000)
    # 4e5 samples: the std of the sample std is 1/sqrt(2n) = 0.11 %
    assert x.std() == pytest.approx(2e-6, rel=0.01)
    assert abs(x.mean()) < 5 * 2e-6 / math.sqrt(x.size)


def test_pink_noise_slope_and_rms():
    fs = 5120.0
    x = _noise(1.0, 1.0, 1 << 21, fs=fs, fmin=0.05)
    f, p = signal.welch(x, fs=fs, nperseg=1 << 16)
    band = (f > 1.0) & (f < 500.0)
    slope = np.polyfit(np.log10(f[band]), np.log10(p[band]), 1)[0]
    assert slope == pytest.approx(-1.0, abs=0.08)
    # 1/f noise: the variance estimate over 410 s converges slowly (a few % spread)
    assert x.std() == pytest.approx(1.0, rel=0.08)


def test_mixed_noise_rms_adds_in_power():
    x = _noise(3e-6, 0.3, 1 << 20, fs=51200.0, fmin=1.0)
    assert x.std() == pytest.approx(3e-6, rel=0.04)


def test_noise_blocks_bit_identical_and_sequential():
    n = 300_001
    whole = _noise(1.0, 0.4, n)
    cuts = [0, 1, 65535, 65537, 200_000, 200_001, n]
    assert np.array_equal(_noise(1.0, 0.4, n, blocks=cuts), whole)
    src = art.NoiseSource(1, 0, 5120.0, 1.0)
    src.add_to(np.zeros(10), 0)
    with pytest.raises(ValueError, match="sequential"):
        src.add_to(np.zeros(10), 20)
    src.add_to(np.zeros(0), 5)   # empty block: nothing, no error


def test_noise_streams_independent_per_channel_and_seed():
    a = art.NoiseSource(1, 0, 5120.0, 1.0)
    b = art.NoiseSource(1, 1, 5120.0, 1.0)
    c = art.NoiseSource(2, 0, 5120.0, 1.0)
    xa, xb, xc = np.zeros(50_000), np.zeros(50_000), np.zeros(50_000)
    a.add_to(xa, 0), b.add_to(xb, 0), c.add_to(xc, 0)
    assert abs(np.corrcoef(xa, xb)[0, 1]) < 0.02
    assert abs(np.corrcoef(xa, xc)[0, 1]) < 0.02


def test_noise_source_bad_input():
    with pytest.raises(ValueError, match="pink_fraction"):
        art.NoiseSource(1, 0, 5120.0, 1.0, pink_fraction=1.5)
    with pytest.raises(ValueError, match="sigma"):
        art.NoiseSource(1, 0, 5120.0, -1.0)
    with pytest.raises(ValueError, match="pink_fmin"):
        art.pink_filter(5120.0, 500.0)
    with pytest.raises(ValueError, match="fs"):
        art.pink_filter(0.0, 1.0)


def test_pink_filter_rms_matches_simulation():
    sos, rms = art.pink_filter(1000.0, 2.0)
    x = np.random.default_rng(0).standard_normal(1 << 20)
    y = signal.sosfilt(sos, x)[20000:]
    assert y.std() == pytest.approx(rms, rel=0.03)


def test_drift_shape():
    t = np.array([0.0, 600.0, 1e6])
    d = art.drift(t, 2e-5, 600.0)
    np.testing.assert_allclose(d, [0.0, 2e-5 * (1 - math.exp(-1)), 2e-5], rtol=1e-12)
    assert art.drift(np.empty(0), 1.0, 1.0).shape == (0,)
    with pytest.raises(ValueError, match="drift_time_constant"):
        art.drift(t, 1.0, 0.0)


@pytest.mark.parametrize("f_mains", [50.0, 60.0])
def test_hum_frequency_and_block_source(f_mains):
    fs = 5120.0
    n = 1 << 18
    phases = [0.3, 1.1, -2.0]
    ref = art.hum(np.arange(n), fs, 4e-6, f_mains, phases, (1.0, 0.0, 0.25))
    spec = np.abs(np.fft.rfft(ref * np.hanning(n)))
    f = np.fft.rfftfreq(n, 1 / fs)
    assert f[np.argmax(spec)] == pytest.approx(f_mains, abs=fs / n)
    assert np.abs(ref).max() <= 4e-6 * 1.25 + 1e-18
    src = art.HumSource(fs, 4e-6, f_mains, (1.0, 0.0, 0.25))
    out = np.zeros(n)
    for a in range(0, n, 50_000):
        src.add_to(out[a:a + 50_000], a, phases)
    np.testing.assert_allclose(out, ref, rtol=0, atol=4e-6 * 1e-12)
    # the value at a sample does not depend on the block cut
    out2 = np.zeros(n)
    src.add_to(out2, 0, phases)
    assert np.array_equal(out, out2)


def test_quantise_levels_and_range():
    x = np.array([0.0, 1.0000001e-4, -3e-3, 3e-3, np.nan, 0.5e-3])
    q = art.quantise(x.copy(), 16, 2e-3)
    lsb = 4e-3 / 2 ** 16
    fin = np.isfinite(q)
    np.testing.assert_allclose(q[fin] / lsb, np.rint(q[fin] / lsb), atol=1e-9)
    assert q[2] == pytest.approx(-2e-3) and q[3] == pytest.approx(2e-3 - lsb)
    assert np.isnan(q[4])
    assert abs(q[1] - x[1]) <= lsb / 2
    with pytest.raises(ValueError, match="adc_bits"):
        art.quantise(x.copy(), 40, 1.0)
    assert art.quantise(np.empty(0), 24, 1.0).shape == (0,)


def test_clip():
    x = np.array([-2.0, 0.5, 3.0])
    assert art.clip(x, 1.0).tolist() == [-1.0, 0.5, 1.0]
    with pytest.raises(ValueError, match="clip_level"):
        art.clip(x, 0.0)


def test_draw_gaps_rates_and_merging():
    rng = np.random.default_rng(0)
    fs, n = 1000.0, 2_000_000
    g = art.draw_gaps(rng, n, fs, gap_rate=0.05, gap_length=0.2, dropout_rate=0.5)
    assert g.dtype == np.int64 and g.shape[1] == 2
    assert np.all(g[:, 1] > g[:, 0]) and np.all(g[1:, 0] > g[:-1, 1])   # sorted, merged
    assert g.min() >= 0 and g.max() <= n
    single = np.sum(g[:, 1] - g[:, 0] == 1)
    # Poisson counts over 2000 s: 100 gaps, 1000 dropouts (+- a few sigma)
    assert 850 < single < 1150
    assert 60 < np.sum(g[:, 1] - g[:, 0] > 1) < 140
    assert art.draw_gaps(rng, 0, fs, 1.0).shape == (0, 2)
    assert art.draw_gaps(rng, 1000, fs).shape == (0, 2)
    with pytest.raises(ValueError, match="gap_rate"):
        art.draw_gaps(rng, 10, fs, gap_rate=-1.0)


def test_apply_gaps_blockwise():
    gaps = np.array([[2, 5], [9, 10], [18, 25]])
    whole = np.zeros((20, 2))
    art.apply_gaps(whole, 0, gaps)
    parts = np.zeros((20, 2))
    for a in range(0, 20, 3):
        art.apply_gaps(parts[a:a + 3], a, gaps)
    assert np.array_equal(np.isnan(whole), np.isnan(parts))
    assert np.isnan(whole[:, 0]).sum() == 3 + 1 + 2
    art.apply_gaps(np.zeros((0, 2)), 0, gaps)


def test_stream_rng_is_keyed():
    a = art.stream_rng(5, "white", 0, 0).standard_normal(4)
    b = art.stream_rng(5, "white", 0, 0).standard_normal(4)
    c = art.stream_rng(5, "white", 0, 1).standard_normal(4)
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    with pytest.raises(KeyError):
        art.stream_rng(5, "nope")
