"""The filter designs, Savitzky-Golay smoother and spectral tools that stand in for
scipy.signal on the processing path (meshphase.signal.sos_design, .savgol, .spectral).

Each is held against scipy.signal itself (the tests may import it; the processing does not)
and, where a closed form exists, against that: scipy's own arithmetic is restated step for
step, so the results agree to rounding. Tolerances: 1e-13 of the coefficients' or data's
scale (a few hundred ulps: scipy may sum in another order in a future release, or on
another LAPACK build, without being more right); the Welch estimate, which scipy 1.17
computes through ShortTimeFFT in another order, to 1e-12 of the spectrum's peak.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import signal

from meshphase.signal.savgol import savgol_coeffs, savgol_coeffs_cached, savgol_filter
from meshphase.signal.sos_design import butter_sos, notch_sos, sosfilt_zi
from meshphase.signal.spectral import resample, tukey, welch

FS = 5120.0


def _rel(a, b):
    return np.max(np.abs(np.asarray(a) - b)) / max(np.max(np.abs(b)), 1e-300)


def _gain(sos, f, fs):
    """|H(e^{j 2 pi f / fs})| of the cascade, evaluated directly from the coefficients."""
    z = np.exp(-2j * np.pi * np.atleast_1d(f) / fs)
    h = np.ones_like(z)
    for b0, b1, b2, a0, a1, a2 in sos:
        h *= (b0 + b1 * z + b2 * z * z) / (a0 + a1 * z + a2 * z * z)
    return np.abs(h)


# ---------------------------------------------------------------------------- Butterworth
@settings(max_examples=150, deadline=None)
@given(order=st.integers(1, 12), kind=st.sampled_from(["lowpass", "highpass", "bandpass"]),
       f1=st.floats(0.2, 2400.0), ratio=st.floats(1.05, 10.0))
def test_butter_equals_scipy(order, kind, f1, ratio):
    cut = f1 if kind != "bandpass" else [f1, min(f1 * ratio, 2550.0)]
    mine = butter_sos(order, cut, kind, FS)
    ref = signal.butter(order, cut, btype=kind, fs=FS, output="sos")
    assert mine.shape == ref.shape
    # each section to 1e-13 of its own largest coefficient (a band-pass's sections span
    # decades of gain: the first holds the whole filter's gain)
    scale = np.max(np.abs(ref), axis=1, keepdims=True)
    assert np.all(np.abs(mine - ref) <= 1e-13 * scale)


@pytest.mark.parametrize("order", [1, 2, 3, 4, 7])
def test_butter_corner_is_minus_3_db(order):
    # the defining property, evaluated from the sections without scipy: |H| = 1/sqrt(2) at
    # each corner (bilinear transform pre-warped there), 1 in the pass-band centre
    s = butter_sos(order, 400.0, "lowpass", FS)
    np.testing.assert_allclose(_gain(s, [0.0, 400.0], FS), [1.0, 2 ** -0.5], rtol=1e-12)
    s = butter_sos(order, 400.0, "highpass", FS)
    np.testing.assert_allclose(_gain(s, [FS / 2, 400.0], FS), [1.0, 2 ** -0.5], rtol=1e-12)
    s = butter_sos(order, [100.0, 900.0], "bandpass", FS)
    centre = FS / np.pi * np.arctan(np.sqrt(np.tan(np.pi * 100 / FS) * np.tan(np.pi * 900 / FS)))
    np.testing.assert_allclose(_gain(s, [centre, 100.0, 900.0], FS), [1.0, 2 ** -0.5, 2 ** -0.5],
                               rtol=1e-10)


@pytest.mark.parametrize("args, match", [
    ((0, 100.0, "lowpass", FS), "order"), ((2.0, 100.0, "lowpass", FS), "order"),
    ((True, 100.0, "lowpass", FS), "order"), ((2, 100.0, "bandstop", FS), "kind"),
    ((2, 100.0, "lowpass", 0.0), "fs"), ((2, 100.0, "lowpass", "fast"), "fs"),
    ((2, 2560.0, "lowpass", FS), "cutoff"), ((2, -1.0, "highpass", FS), "cutoff"),
    ((2, float("nan"), "lowpass", FS), "cutoff"), ((2, 100.0, "bandpass", FS), "2 corner"),
    ((2, [100.0, 50.0], "bandpass", FS), "increase"), ((2, [50.0, 100.0], "lowpass", FS), "1 corner"),
    ((2, [], "lowpass", FS), "1 corner"), ((2, "low", "lowpass", FS), "cutoff")])
def test_butter_bad_input(args, match):
    with pytest.raises(ValueError, match=match):
        butter_sos(*args)


# ---------------------------------------------------------------------------- notches
@settings(max_examples=100, deadline=None)
@given(f=st.floats(0.5, 2550.0), q=st.floats(0.5, 1000.0))
def test_notch_equals_scipy(f, q):
    ref = signal.tf2sos(*signal.iirnotch(f, q, fs=FS))
    assert _rel(notch_sos([f], q, FS), ref) <= 1e-13


def test_notch_cascade_removes_each_line():
    s = notch_sos([50.0, 150.0, 250.0], 30.0, FS)
    assert s.shape == (3, 6)
    assert np.all(_gain(s, [50.0, 150.0, 250.0], FS) < 1e-9)     # zeros on the unit circle
    np.testing.assert_allclose(_gain(s, [0.0, FS / 2], FS), 1.0, rtol=1e-12)


@pytest.mark.parametrize("args, match", [
    (([], 30.0, FS), "at least one"), (([50.0], 0.0, FS), "q"), (([50.0], "x", FS), "q"),
    (([2560.0], 30.0, FS), "notch line"), (([0.0], 30.0, FS), "notch line"),
    (([50.0], 30.0, -1.0), "fs"), ((["a"], 30.0, FS), "notch line")])
def test_notch_bad_input(args, match):
    with pytest.raises(ValueError, match=match):
        notch_sos(*args)


# ---------------------------------------------------------------------------- sosfilt_zi
@pytest.mark.parametrize("sos", [butter_sos(4, [10.0, 1500.0], "bandpass", FS),
                                 butter_sos(3, 5.0, "highpass", FS),
                                 notch_sos([50.0, 100.0], 30.0, FS)])
def test_sosfilt_zi_equals_scipy_and_is_a_steady_state(sos):
    zi = sosfilt_zi(sos)
    assert _rel(zi, signal.sosfilt_zi(sos)) <= 1e-12
    # started from zi * x0 on a constant, the filter stays at its DC gain times x0
    y, _ = signal.sosfilt(sos, np.full(50, 2.5), zi=zi * 2.5)
    np.testing.assert_allclose(y, y[0], rtol=0, atol=1e-12 * max(1.0, abs(y[0])))


def test_sosfilt_zi_bad_input():
    for bad in (np.zeros((0, 6)), np.zeros((2, 5)), np.zeros(6), [[1, 0, 0, 2, 0, 0]],
                [[np.nan, 0, 0, 1, 0, 0]]):
        with pytest.raises(ValueError, match="sos"):
            sosfilt_zi(bad)
    with pytest.raises(ValueError, match="pole at z = 1"):
        sosfilt_zi([[1.0, 0.0, 0.0, 1.0, -2.0, 1.0]])          # a double integrator


# ---------------------------------------------------------------------------- Savitzky-Golay
@settings(max_examples=120, deadline=None)
@given(w=st.integers(1, 41), p=st.integers(0, 5), extra=st.integers(0, 60),
       dtype=st.sampled_from([np.float64, np.float32, np.int64]), seed=st.integers(0, 99))
def test_savgol_equals_scipy(w, p, extra, dtype, seed):
    if p >= w:
        p = w - 1
    x = (np.random.default_rng(seed).normal(size=w + extra) * 100).astype(dtype)
    np.testing.assert_allclose(savgol_coeffs(w, p), signal.savgol_coeffs(w, p), rtol=0, atol=1e-13)
    got, ref = savgol_filter(x, w, p), signal.savgol_filter(x, w, p)
    assert got.dtype == ref.dtype
    tol = 1e-5 if dtype == np.float32 else 1e-13
    assert _rel(got, ref) <= tol


def test_savgol_keeps_polynomials():
    # a quadratic smoother reproduces a quadratic everywhere, ends included
    t = np.arange(40.0)
    x = 0.3 * t ** 2 - 2 * t + 5
    np.testing.assert_allclose(savgol_filter(x, 17, 2), x, rtol=1e-12)
    assert abs(savgol_coeffs(17, 2).sum() - 1.0) < 1e-14


@pytest.mark.parametrize("args, match", [
    ((np.ones(10), 0, 0), "window_length"), ((np.ones(10), 5, 5), "polyorder"),
    ((np.ones(10), 5, -1), "polyorder"), ((np.ones(10), 5.0, 2), "window_length"),
    ((np.ones(4), 5, 2), "exceed"), ((np.ones((5, 5)), 5, 2), "1-D"),
    ((np.ones(0), 1, 0), "exceed")])
def test_savgol_bad_input(args, match):
    with pytest.raises(ValueError, match=match):
        savgol_filter(*args)
    if args[1] != 5.0 and isinstance(args[1], int) and not 0 <= args[2] < args[1]:
        with pytest.raises(ValueError):
            savgol_coeffs(args[1], args[2])


def test_savgol_cached_coefficients_are_read_only_and_equal():
    # one cache for the drift baseline and the template features: the same coefficients,
    # computed once, and no caller can change them for the next
    c = savgol_coeffs_cached(17, 2)
    assert c is savgol_coeffs_cached(17, 2)
    np.testing.assert_array_equal(c, savgol_coeffs(17, 2))
    with pytest.raises(ValueError):
        c[0] = 1.0
    assert savgol_coeffs_cached(1, 0).tolist() == [1.0]              # the shortest window
    for bad in ((0, 0), (5, 5), (5, -1)):
        with pytest.raises(ValueError):
            savgol_coeffs_cached(*bad)


# ---------------------------------------------------------------------------- windows, Welch, resample
@pytest.mark.parametrize("m", [0, 1, 2, 3, 16, 17, 64, 101])
@pytest.mark.parametrize("alpha", [0.0, 0.1, 0.5, 0.99, 1.0, 2.0])
def test_tukey_equals_scipy(m, alpha):
    np.testing.assert_allclose(tukey(m, alpha), signal.windows.tukey(m, alpha), rtol=0, atol=1e-15)


def test_tukey_bad_input():
    for m in (-1, 2.5, "8", True):
        with pytest.raises(ValueError, match="m must be"):
            tukey(m)
    with pytest.raises(ValueError, match="alpha"):
        tukey(8, float("nan"))


@pytest.mark.parametrize("nperseg, noverlap", [(16, None), (64, 0), (255, 100), (256, None), (1, 0)])
@pytest.mark.parametrize("detrend", ["constant", False, "linear-callable"])
def test_welch_equals_scipy(nperseg, noverlap, detrend):
    from meshphase.signal.condition import detrend_linear

    det = detrend_linear if detrend == "linear-callable" else detrend
    rng = np.random.default_rng(1)
    n = 5000
    x = rng.normal(size=n) + 3 * np.sin(0.3 * np.arange(n)) + 1e-3 * np.arange(n)
    f, p = welch(x, FS, nperseg, noverlap=noverlap, detrend=det)
    fr, pr = signal.welch(x, FS, nperseg=nperseg, noverlap=noverlap, detrend=det)
    np.testing.assert_array_equal(f, fr)
    assert _rel(p, pr) <= 1e-12


def test_welch_white_noise_level():
    # independent of scipy: unit-variance white noise has a one-sided density 2 / fs
    x = np.random.default_rng(7).normal(size=1 << 18)
    f, p = welch(x, FS, 1024)
    assert abs(np.mean(p[1:-1]) * FS / 2 - 1.0) < 0.01          # 511 bins x 511 segments


@pytest.mark.parametrize("args, kw, match", [
    ((np.ones(10), FS, 16), {}, "nperseg"), ((np.ones(10), FS, 0), {}, "nperseg"),
    ((np.ones((4, 4)), FS, 2), {}, "1-D"), ((np.ones(10), 0.0, 4), {}, "fs"),
    ((np.ones(10), FS, 4), {"noverlap": 4}, "noverlap"), ((np.ones(10), FS, 4), {"detrend": "linear"}, "detrend"),
    ((np.ones(0), FS, 1), {}, "nperseg")])
def test_welch_bad_input(args, kw, match):
    with pytest.raises(ValueError, match=match):
        welch(*args, **kw)


@pytest.mark.parametrize("n", [1, 2, 3, 17, 18, 64])
@pytest.mark.parametrize("factor", [0.5, 1, 2, 3, 32])
def test_resample_equals_scipy(n, factor):
    x = np.random.default_rng(n).normal(size=n)
    num = max(1, int(n * factor))
    np.testing.assert_allclose(resample(x, num), signal.resample(x, num), rtol=0, atol=1e-13)


def test_resample_keeps_band_limited_samples():
    # a band-limited periodic signal upsampled by 4 passes through its old samples
    t = np.arange(32)
    x = np.cos(2 * np.pi * 3 * t / 32) + 0.5 * np.sin(2 * np.pi * 5 * t / 32)
    np.testing.assert_allclose(resample(x, 128)[::4], x, atol=1e-13)


def test_resample_bad_input():
    for x, num in ((np.ones(0), 4), (np.ones((2, 2)), 4), (np.ones(4) + 1j, 8), (np.ones(4), 0),
                   (np.ones(4), 2.5)):
        with pytest.raises(ValueError):
            resample(x, num)
