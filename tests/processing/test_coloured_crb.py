"""The timing floor in coloured noise: the Cramer-Rao bound from a noise spectrum
(meshphase.signal.crb.crb_delay_std_psd), the Welch degrees of freedom (welch_dof), the noise
spectrum a conditioned channel's pulses leave (meshphase.signal.noise_spectrum.pulse_residual_psd)
and the per-onset bounds built on them (meshphase.kinematics.passes.onset_sigma, channel_noise_spectrum).

References: a direct evaluation of the Fisher information integral with mpmath for an analytic
pulse and spectrum; the white-noise bound (Parseval) for white noise. Statistical tolerances
come from the Welch estimate's degrees of freedom, not from a machine's results."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from meshphase.signal.crb import crb_delay_std, crb_delay_std_psd, welch_dof
from meshphase.signal.noise_spectrum import MIN_PULSES, NoiseSpectrum, pulse_residual_psd
from meshphase.onsets import Onsets, Template
from meshphase.kinematics.passes import channel_noise_spectrum, onset_sigma
from meshphase.recording import ChannelSpec, Recording

FS = 1000.0
TAU = 0.03            # Gaussian pulse width parameter [s]
SPACING = 2.0         # between pulses [s]


def _gauss(t):
    return np.exp(-0.5 * (t / TAU) ** 2)


def _gauss_derivative(rate=FS, half=0.3):
    t = np.arange(-half, half, 1.0 / rate)
    return -t / TAU ** 2 * _gauss(t)


def _pink_gain(f, fc=10.0, f0=0.5):
    """Power gain of the coloured test noise over white: 1 + fc / (f + f0) [-]."""
    return 1.0 + fc / (np.asarray(f, float) + f0)


def _train(n, sigma, rng, *, coloured=False, amp=1.0):
    """Pulses every SPACING s (times returned) on white or coloured Gaussian noise whose
    one-sided PSD is 2 sigma^2 / FS (times _pink_gain when coloured), by exact circular
    filtering of white noise."""
    w = rng.normal(0.0, sigma, n)
    if coloured:
        spec = np.fft.rfft(w) * np.sqrt(_pink_gain(np.fft.rfftfreq(n, 1.0 / FS)))
        w = np.fft.irfft(spec, n)
    times = np.arange(SPACING, n / FS - SPACING, SPACING) + rng.uniform(-0.1, 0.1, 1)[0]
    t = np.arange(n) / FS
    x = w.copy()
    for tk in times:
        i = int(round(tk * FS))
        sl = slice(max(i - 400, 0), min(i + 400, n))
        x[sl] += amp * _gauss(t[sl] - tk)
    return x, times


def _dof_tolerance(spec: NoiseSpectrum, k: float = 4.0) -> float:
    """k sigma of the bound's relative error from the Welch estimate: each bin's 1/S_hat has
    relative SD sqrt(2 / (nu - 4)) (chi^2_nu), the information sums bins, at worst fully
    correlated, and the bound is its -1/2 power (the 1/M the pulse average takes is
    corrected for: test_residual_psd_unbiased_with_few_pulses)."""
    nu = spec.dof
    return k * 0.5 * math.sqrt(2.0 / (nu - 4.0))


# ---- welch_dof -----------------------------------------------------------------------------

def test_welch_dof_values():
    assert welch_dof(1) == 2.0
    assert welch_dof(10, overlap=0.0) == 20.0
    # half-overlapping Hann segments: nu -> 2K / (1 + 2 * 0.167^2) for many segments
    assert welch_dof(100000) == pytest.approx(2 * 100000 / (1 + 2 * 0.167 ** 2), rel=1e-4)
    assert 2 * 10 / 1.06 < welch_dof(10) < 20


@pytest.mark.parametrize("bad, exc", [(0, ValueError), (-3, ValueError), (2.5, TypeError),
                                      (True, TypeError), ("4", TypeError)])
def test_welch_dof_bad_segments(bad, exc):
    with pytest.raises(exc):
        welch_dof(bad)


def test_welch_dof_bad_overlap():
    with pytest.raises(ValueError, match="overlap"):
        welch_dof(4, overlap=0.75)


# ---- crb_delay_std_psd ---------------------------------------------------------------------

def test_psd_bound_white_equals_white_bound():
    """White PSD 2 sigma^2 / fs -> exactly the white-noise bound (Parseval), also for a
    derivative sampled below the data rate (the template's decimated rate)."""
    sigma = 0.05
    f = np.linspace(0.0, FS / 2, 2049)
    s = np.full(f.size, 2 * sigma ** 2 / FS)
    d = _gauss_derivative()
    assert crb_delay_std_psd(d, FS, f, s) == pytest.approx(crb_delay_std(d, sigma), rel=1e-4)
    dec = 5
    d5 = _gauss_derivative(FS / dec)
    assert crb_delay_std_psd(d5, FS / dec, f, s) == pytest.approx(
        crb_delay_std(d5, sigma) / math.sqrt(dec), rel=1e-4)


def test_psd_bound_matches_mpmath_integral():
    """The bound for an analytic Gaussian pulse in noise of PSD a (1 + fc / (f + f0)) against
    the Fisher integral 4 int_0^inf |2 pi f P(f)|^2 / S(f) df evaluated by mpmath."""
    mpmath = pytest.importorskip("mpmath")
    a = 2 * 0.05 ** 2 / FS
    tau = mpmath.mpf(TAU)

    def integrand(f):
        p = tau * mpmath.sqrt(2 * mpmath.pi) * mpmath.exp(-2 * mpmath.pi ** 2 * f ** 2 * tau ** 2)
        return (2 * mpmath.pi * f * p) ** 2 / (a * (1 + 10 / (f + mpmath.mpf(0.5))))

    info = 4 * mpmath.quad(integrand, [0, 5, 20, 60, mpmath.inf])
    ref = float(1 / mpmath.sqrt(info))
    f = np.linspace(0.0, FS / 2, 20001)
    got = crb_delay_std_psd(_gauss_derivative(half=0.4), FS, f, a * _pink_gain(f))
    assert got == pytest.approx(ref, rel=1e-3)
    # and it exceeds the bound in white noise of the white part alone
    assert got > 1.5 * crb_delay_std(_gauss_derivative(half=0.4), 0.05)


def test_psd_bound_dof_correction():
    f = np.linspace(0.0, FS / 2, 513)
    s = np.full(f.size, 1e-5)
    d = _gauss_derivative()
    exact = crb_delay_std_psd(d, FS, f, s)
    assert crb_delay_std_psd(d, FS, f, s, dof=12.0) == pytest.approx(exact * math.sqrt(12 / 10))


def test_psd_bound_empty_and_no_information():
    f = np.linspace(0.0, FS / 2, 65)
    s = np.ones(f.size)
    assert crb_delay_std_psd([], FS, f, s) == math.inf
    assert crb_delay_std_psd(np.zeros(10), FS, f, s) == math.inf
    assert crb_delay_std_psd(_gauss_derivative(), FS, [], []) == math.inf
    # a spectrum that is zero (no estimate) carries no information rather than infinite
    assert crb_delay_std_psd(_gauss_derivative(), FS, f, np.zeros(f.size)) == math.inf


@pytest.mark.parametrize("kw, match", [
    (dict(derivative=np.ones((2, 3))), "1-D"),
    (dict(derivative=[0.0, np.nan, 1.0]), "finite"),
    (dict(rate=0.0), "rate"),
    (dict(freqs=[0.0, 2.0, 1.0], psd=[1.0, 1.0, 1.0]), "increasing"),
    (dict(freqs=[0.0, 1.0], psd=[1.0]), "one length"),
    (dict(psd=[1.0, np.nan, 1.0]), "NaN"),
    (dict(dof=2.0), "dof"),
    (dict(band_fraction=-1.0), "band_fraction"),
])
def test_psd_bound_bad_input(kw, match):
    args = dict(derivative=_gauss_derivative(), rate=FS, freqs=[0.0, 1.0, 2.0], psd=[1.0, 1.0, 1.0])
    args.update(kw)
    with pytest.raises(ValueError, match=match):
        crb_delay_std_psd(args.pop("derivative"), args.pop("rate"), args.pop("freqs"),
                          args.pop("psd"), **args)


# ---- pulse_residual_psd --------------------------------------------------------------------

def test_residual_psd_white_gives_white_bound():
    """White noise under a pulse train: the bound from the Welch estimate of what the pulses
    leave equals the white-noise bound within the estimate's statistical error."""
    rng = np.random.default_rng(11)
    sigma = 0.05
    x, times = _train(1 << 21, sigma, rng)
    spec = pulse_residual_psd(x, FS, 0.0, times)
    assert spec is not None and spec.n_pulses >= 1000 and spec.nperseg == 1024
    d = _gauss_derivative()
    got = crb_delay_std_psd(d, FS, spec.freqs, spec.psd, dof=spec.dof)
    ref = crb_delay_std(d, sigma)
    assert abs(got / ref - 1.0) < _dof_tolerance(spec)
    assert spec.rms == pytest.approx(sigma, rel=0.02)
    assert spec.n_excluded == 0          # no window of plain noise is taken for a transient


def test_residual_psd_coloured_gives_coloured_bound():
    """Coloured noise: the Welch-based bound follows the exact-PSD bound (within the
    statistical error plus the Hann window's smoothing of 1/f over a 1 Hz bin, which the
    exact PSD averaged over the window's main lobe bounds by a few per cent) and is well
    above the white bound of the same per-sample RMS."""
    rng = np.random.default_rng(12)
    sigma = 0.05
    x, times = _train(1 << 21, sigma, rng, coloured=True)
    spec = pulse_residual_psd(x, FS, 0.0, times)
    d = _gauss_derivative()
    got = crb_delay_std_psd(d, FS, spec.freqs, spec.psd, dof=spec.dof)
    f = np.linspace(0.0, FS / 2, 20001)
    exact = crb_delay_std_psd(d, FS, f, 2 * sigma ** 2 / FS * _pink_gain(f))
    assert abs(got / exact - 1.0) < _dof_tolerance(spec) + 0.05
    assert got > 1.5 * crb_delay_std(d, sigma)
    assert spec.n_excluded == 0


@pytest.mark.parametrize("kind", ["step", "knock"])
def test_residual_psd_leaves_a_transient_out(kind, monkeypatch):
    """A bridge's level step, high-passed by conditioning into a decaying transient (or a
    knock: a short ringing burst), is not noise: left in, the windows it falls in carry
    its energy into the estimate (here the RMS 1.17-1.19x the noise's; on the independent rig
    one step made the sun gauge's timing floor 13x its scatter). The windows above
    TRANSIENT_RATIO times the median residual energy are left out, and the estimate is that
    of the noise alone, within the white test's 2 %."""
    import meshphase.signal.noise_spectrum as ns

    rng = np.random.default_rng(31)
    sigma = 0.05
    x, times = _train(1 << 18, sigma, rng)
    t = np.arange(x.size) / FS
    ts = times[40] + 0.7                # between two pulses
    after = t >= ts
    if kind == "step":
        x[after] += 2.0 * np.exp(-(t[after] - ts) / 0.3)
    else:
        x[after] += 5.0 * np.exp(-(t[after] - ts) / 0.05) * np.sin(2 * np.pi * 40 * (t[after] - ts))
    spec = pulse_residual_psd(x, FS, 0.0, times)
    assert spec is not None and 1 <= spec.n_excluded <= 3
    assert spec.rms == pytest.approx(sigma, rel=0.02)
    assert spec.n_pulses == len([c for c in times if 1.0 <= c <= x.size / FS - 1.0]) - spec.n_excluded
    monkeypatch.setattr(ns, "TRANSIENT_RATIO", np.inf)   # what it was: the transient kept
    kept = pulse_residual_psd(x, FS, 0.0, times)
    assert kept.n_excluded == 0 and kept.rms > 1.1 * sigma


def test_residual_psd_unbiased_with_few_pulses():
    """About ten pulse windows on white noise, 60 realisations: the mean estimate over the
    bins above the first is the white density within 3 % (its sampling SD here ~0.2 %). A
    shape averaged from M windows carries 1/M of each window's noise out of it at every
    frequency, 10 % here, and the estimate is scaled back for it (it was 10 % low before).
    The first bin is not checked: the segment mean each Welch segment loses takes 1/6 of
    white noise's first bin, but conditioned channels are high-passed, where it takes next
    to nothing."""
    rng = np.random.default_rng(21)
    sigma = 0.05
    ratios = []
    for _ in range(60):
        x, times = _train(int(24 * FS), sigma, rng)
        spec = pulse_residual_psd(x, FS, 0.0, times)
        assert spec is not None and 9 <= spec.n_pulses <= 11
        ratios.append(spec.psd[2:-1] / (2 * sigma ** 2 / FS))
    assert abs(float(np.mean(ratios)) - 1.0) < 0.03


def test_residual_psd_too_little():
    rng = np.random.default_rng(3)
    x = rng.normal(size=4000)
    assert pulse_residual_psd(x, FS, 0.0, []) is None
    assert pulse_residual_psd(x, FS, 0.0, [1.0]) is None
    # windows shorter than MIN_NPERSEG
    assert pulse_residual_psd(x, FS, 0.0, np.arange(0.5, 3.5, 0.1)) is None
    # fewer than MIN_PULSES windows
    assert pulse_residual_psd(x, FS, 0.0, [0.6, 1.2, 1.8, 2.4][:MIN_PULSES - 1]) is None
    assert pulse_residual_psd(np.empty(0), FS, 0.0, [0.5, 1.0]) is None


def test_residual_psd_skips_nonfinite_windows_and_settling():
    rng = np.random.default_rng(4)
    x, times = _train(200000, 0.05, rng)
    y = x.copy()
    y[int(10 * FS)] = np.nan
    a, b = pulse_residual_psd(x, FS, 0.0, times), pulse_residual_psd(y, FS, 0.0, times)
    assert b.n_pulses == a.n_pulses - 1
    c = pulse_residual_psd(x, FS, 0.0, times, skip=20.0)
    assert c.n_pulses < a.n_pulses - 8


@pytest.mark.parametrize("kw, exc", [(dict(x=np.ones((3, 3))), ValueError),
                                     (dict(fs=-1.0), ValueError),
                                     (dict(times=np.ones((2, 2))), ValueError),
                                     (dict(t0="0"), TypeError)])
def test_residual_psd_bad_input(kw, exc):
    args = dict(x=np.zeros(1000), fs=FS, t0=0.0, times=[0.1, 0.5])
    args.update(kw)
    with pytest.raises(exc):
        pulse_residual_psd(args["x"], args["fs"], args["t0"], args["times"])


# ---- onset_sigma and channel_noise_spectrum ------------------------------------------------

def _tpl(decimation=1):
    rate = FS / decimation
    t = np.arange(-0.3, 0.3, 1.0 / rate)
    h = _gauss(t)
    pk = float(np.argmax(h))
    return Template(h, FS, decimation, pk, pk - 5, 2.3548 * TAU)


def _ons(times, tpl, amp=1.0):
    t = np.asarray(times, float)
    n = t.size
    return Onsets(t, t * FS, np.ones(n), np.full(n, amp), np.full(n, TAU), np.zeros(n, np.uint8),
                  np.zeros(n, np.int32), (tpl,), FS, 0.0, "g")


def test_onset_sigma_white_spectrum_equals_white():
    sigma = 0.05
    f = np.linspace(0.0, FS / 2, 4097)
    spec = NoiseSpectrum(f, np.full(f.size, 2 * sigma ** 2 / FS), 1e9, 1 << 20, 100, 8192)
    for dec in (1, 4):
        on = _ons([1.0, 3.0], _tpl(dec), amp=2.0)
        np.testing.assert_allclose(onset_sigma(on, sigma, noise=spec), onset_sigma(on, sigma),
                                   rtol=2e-3)


def test_onset_sigma_coloured_is_larger_and_needs_no_rms():
    sigma = 0.05
    f = np.linspace(0.0, FS / 2, 4097)
    spec = NoiseSpectrum(f, 2 * sigma ** 2 / FS * _pink_gain(f), 1e9, 1 << 20, 100, 8192)
    on = _ons([1.0, 3.0], _tpl(), amp=2.0)
    white = onset_sigma(on, sigma)
    col = onset_sigma(on, sigma, noise=spec)
    assert np.all(col > 1.5 * white)
    np.testing.assert_allclose(onset_sigma(on, float("nan"), noise=spec), col)
    # a spectrum without information there falls back on the white bound
    zero = NoiseSpectrum(f, np.zeros(f.size), 1e9, 1 << 20, 100, 8192)
    np.testing.assert_allclose(onset_sigma(on, sigma, noise=zero), white)


def test_onset_sigma_bad_noise():
    with pytest.raises(TypeError, match="NoiseSpectrum"):
        onset_sigma(_ons([1.0], _tpl()), 0.1, noise=np.ones(3))


def test_channel_noise_spectrum():
    rng = np.random.default_rng(5)
    x, times = _train(1 << 18, 0.05, rng)
    rec = Recording(x[:, None], FS, [ChannelSpec("g", kind="sun")])
    on = _ons(times, _tpl())
    spec = channel_noise_spectrum(rec, "g", on)
    assert isinstance(spec, NoiseSpectrum) and spec.n_pulses == len(times) - 1 or spec.n_pulses == len(times)
    assert channel_noise_spectrum(None, "g", on) is None
    assert channel_noise_spectrum(rec, "other", on) is None
    empty = Recording(np.empty((0, 1)), FS, [ChannelSpec("g", kind="sun")])
    assert channel_noise_spectrum(empty, "g", on) is None
    with pytest.raises(TypeError):
        channel_noise_spectrum(rec, 3, on)
    with pytest.raises(TypeError):
        channel_noise_spectrum(rec, "g", times)


# ---- gauge_passes: the floor factor --------------------------------------------------------

def _gauge_case(coloured, sigma=0.05, n=1 << 18, seed=6):
    from meshphase.signal.condition import ChannelQuality

    x, times = _train(n, sigma, np.random.default_rng(seed), coloured=coloured)
    rec = Recording(x[:, None], FS, [ChannelSpec("g", kind="sun")])
    e = np.empty((0, 2), dtype=np.int64)
    q = dataclasses.replace(ChannelQuality("g", FS, 0.0, n, e, e.copy(), e.copy()), noise_rms=sigma)
    return rec, {"g": _ons(times, _tpl())}, {"g": q}


def test_gauge_passes_floor_factor_white_coloured_and_weights_unchanged():
    from meshphase.kinematics.passes import gauge_passes

    for coloured in (False, True):
        rec, ons, quality = _gauge_case(coloured)
        plain, _ = gauge_passes(rec.channels, ons, quality, FS, 0.0)
        (p,), _ = gauge_passes(rec.channels, ons, quality, FS, 0.0, excerpt=rec)
        assert plain[0].floor_factor == 1.0
        # the angle model's weights stay the white bound's
        np.testing.assert_array_equal(p.sigma, plain[0].sigma)
        spec = channel_noise_spectrum(rec, "g", ons["g"], quality["g"])
        f = np.linspace(0.0, FS / 2, 20001)
        gain = _pink_gain(f) if coloured else np.ones(f.size)
        d = np.gradient(_tpl().samples) * FS
        exact = crb_delay_std_psd(d, FS, f, 2 * 0.05 ** 2 / FS * gain) / crb_delay_std(d, 0.05)
        assert abs(p.floor_factor / exact - 1.0) < _dof_tolerance(spec) + (0.05 if coloured else 0.0)


def test_gauge_passes_pulse_misfit_is_not_noise():
    """Noise-free pulses whose shape drifts (a speed ramp stretches them) leave a residual
    far above the per-sample noise: that is misfit, and the floor stays the white bound's."""
    from meshphase.kinematics.passes import NOISE_LIKE_RATIO, gauge_passes

    rng = np.random.default_rng(7)
    n = 1 << 18
    t = np.arange(n) / FS
    times = np.arange(SPACING, n / FS - SPACING, SPACING)
    x = rng.normal(0.0, 1e-6, n)
    for k, tk in enumerate(times):
        width = TAU * (1.0 + 0.3 * k / times.size)
        x += np.exp(-0.5 * ((t - tk) / width) ** 2)
    rec = Recording(x[:, None], FS, [ChannelSpec("g", kind="sun")])
    from meshphase.signal.condition import ChannelQuality

    e = np.empty((0, 2), dtype=np.int64)
    q = dataclasses.replace(ChannelQuality("g", FS, 0.0, n, e, e.copy(), e.copy()), noise_rms=1e-6)
    spec = pulse_residual_psd(x, FS, 0.0, times)
    assert spec.rms > NOISE_LIKE_RATIO * 1e-6
    assert channel_noise_spectrum(rec, "g", _ons(times, _tpl()), q) is None
    (p,), _ = gauge_passes(rec.channels, {"g": _ons(times, _tpl())}, {"g": q}, FS, 0.0, excerpt=rec)
    assert p.floor_factor == 1.0
