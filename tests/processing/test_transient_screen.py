"""The noise spectrum's transient screen on clean data (meshphase.signal.noise_spectrum): a window
left out for the pulse fit's misfit is not called a transient, a step in the recording still
is; flagged onsets' windows are not pulse windows (meshphase.kinematics.passes.channel_noise_spectrum)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from meshphase.errors import DataQualityWarning
from meshphase.signal.noise_spectrum import TRANSIENT_PULSE_SHARE, TRANSIENT_RATIO, pulse_residual_psd
from meshphase.onsets import FLAG_EDGE, FLAG_LOW_CORR, FLAG_TEMPLATE, Onsets
from meshphase.kinematics.passes import channel_noise_spectrum
from meshphase.recording import Recording

FS = 1000.0
TAU = 0.03            # Gaussian pulse width parameter [s]
SPACING = 2.0         # between pulses [s]


def _clean_train(sigma=1e-6, n=1 << 16, seed=3):
    """Unit Gaussian pulses every SPACING s on white noise of RMS ``sigma`` (60 dB and more
    below the pulse: clean data)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / FS
    times = np.arange(SPACING, n / FS - SPACING, SPACING)
    x = rng.normal(0.0, sigma, n)
    for tk in times:
        x += np.exp(-0.5 * ((t - tk) / TAU) ** 2)
    return x, t, times


def test_a_misfit_far_below_the_pulse_is_left_out_but_no_transient():
    x, t, times = _clean_train()
    # the first pulse with a shoulder of 1e-3 its height 4 widths after it (no shift, stretch
    # or gain of the pulse makes it): 1e-6 of a pulse's energy, 2.6e4 x the noise's
    x += 1e-3 * np.exp(-0.5 * ((t - times[0] - 4 * TAU) / TAU) ** 2)
    spec = pulse_residual_psd(x, FS, 0.0, times)
    assert spec is not None
    assert spec.n_misfit >= 1 and spec.n_excluded == 0


def test_a_step_in_clean_data_is_still_a_transient():
    x, t, times = _clean_train()
    x[t >= times[5] + 0.7] += 2.0 * np.exp(-(t[t >= times[5] + 0.7] - times[5] - 0.7) / 0.3)
    spec = pulse_residual_psd(x, FS, 0.0, times)
    assert spec is not None and spec.n_excluded >= 1
    # its excess is a pulse's energy many times over, far past the share that names it
    assert TRANSIENT_PULSE_SHARE < 1.0 and TRANSIENT_RATIO > 1.0


def _onsets(times, flags):
    n = len(times)
    t = np.asarray(times, float)
    return Onsets(times=t, index=np.rint(t * FS).astype(np.int64), corr=np.ones(n),
                  amplitude=np.ones(n), width=np.full(n, TAU), flags=np.asarray(flags, np.uint8),
                  template_id=np.zeros(n, np.int64), fs=FS)


def test_flagged_onsets_windows_are_not_pulse_windows():
    x, t, times = _clean_train()
    # spurious onsets half-way between pulses, flagged by the detector (low correlation, edge)
    spurious = times[:-1] + 0.5 * SPACING
    all_t = np.sort(np.r_[times, spurious])
    flags = np.where(np.isin(all_t, spurious), FLAG_LOW_CORR | FLAG_EDGE, 0)
    flags[1] |= FLAG_TEMPLATE               # a fallback template's onset is a clean pulse
    rec = Recording(x, FS, ["g"])
    with warnings.catch_warnings():
        warnings.simplefilter("error", DataQualityWarning)      # no transient said
        spec = channel_noise_spectrum(rec, "g", _onsets(all_t, flags))
    ref = channel_noise_spectrum(rec, "g", _onsets(times, np.zeros(times.size)))
    assert spec is not None and spec.n_pulses == ref.n_pulses
    assert spec.rms == pytest.approx(ref.rms, rel=1e-12)


def test_empty_onsets_give_no_spectrum():
    x, _, _ = _clean_train(n=1 << 12)
    assert channel_noise_spectrum(Recording(x, FS, ["g"]), "g", _onsets([], [])) is None
