"""Signal conditioning of tooth-root strain channels, and the per-channel quality report.

Array functions at the bottom (numpy in, numpy out, sample rate ``fs`` in [Hz]) and thin
:class:`~meshphase.recording.Recording` wrappers that convert, apply per channel and append
one entry to the recording's history. The filters are the block filters of
:mod:`meshphase.signal.zero_phase` and :mod:`meshphase.signal.drift`, pushed the whole array
(:func:`meshphase.signal.blocks.run_whole`): the streamed stages run the same ones block by
block.

Steps
-----
``filter_signal``
    Zero-phase Butterworth band-, high- or low-pass (:func:`meshphase.signal.sos_design.butter_sos`,
    scipy.signal.butter's sections, run by :func:`meshphase.signal.iir.sosfiltfilt`).
``remove_drift``
    Slow (thermal) drift removal: a robust moving-median baseline computed on block medians
    (default), a Savitzky-Golay baseline on block medians, or a zero-phase high-pass.
``notch_hum``
    Mains hum (50/60 Hz and harmonics) notches (scipy.signal.iirnotch's biquads, zero-phase),
    applied only to the lines :func:`detect_hum` finds above the local noise floor.
``assess_quality``
    Gaps (non-finite runs), NaN runs, DAQ dropout runs (exact zeros or a held value),
    clipped runs (at the rails, or plateaus at any level) and an SNR estimate, as a
    :class:`ChannelQuality` that the onset stage respects (pulses overlapping a gap, a
    dropout or a clipped run are flagged, no onset is placed inside a gap or a dropout).
    :func:`gap_intervals` lists a channel's gaps and dropouts in seconds.

Dropouts and clipped plateaus
-----------------------------
A DAQ that drops samples may write exact zeros or hold its last sample instead of NaN; an
ADC or amplifier stage may saturate below the nominal full scale, or on one polarity only.
:func:`meshphase.signal.flat_runs.flat_runs` finds both on the raw data, with a run-length threshold
from the channel's own statistics (a quantised quiet channel repeats values by chance) and
tells them apart by where the flat run sits: a clip bounds a pulse extreme and is entered
steeply, a dropout sits at 0 or at a value the signal passes through (see that module's
docstring for the rule). :func:`condition_recording` sets dropout samples to NaN before
filtering (``dropouts="nan"``): the filters then neither ring on the dropout's steps nor
treat fake samples as data, and every later stage sees an ordinary gap.

Defaults relative to the mesh frequency
---------------------------------------
With the mesh frequency ``f_m`` [Hz] known (``mesh_freq``), a tooth-root pulse lasts about
the contact ratio (1.4-1.8) times the mesh period and carries its energy below ~3 ``f_m``;
consecutive pulses of one gauge are several mesh periods apart. The defaults are

- high-pass corner ``f_m / 20``: a time constant of ~20 mesh periods, an order of magnitude
  longer than a pulse, so the pulse shape is kept and only slow drift is removed;
- low-pass corner ``4 f_m`` when that is below ``0.45 fs``; otherwise no low-pass (pulses a
  few samples wide, mesh frequency near Nyquist: keep the whole band);
- drift-removal window 20 mesh periods (> 10 pulse lengths, so the moving median follows the
  baseline, not the pulses).

Without ``f_m``: high-pass corner 0.05 Hz, no low-pass, drift window 10 s.

NaN handling
------------
Filtering never smears NaN: interior non-finite runs of at most ``fill_max`` samples are
bridged by linear interpolation for the filter, longer runs split the signal into segments
filtered independently, and every sample that was non-finite on input is NaN on output
(mask back). Segments too short for the filter's edge padding come out NaN, with a
:class:`~meshphase.errors.DataQualityWarning`.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import replace
from typing import Sequence

import numpy as np

from ..errors import ProcessingWarning
from ..runtime.log import logger
from .blocks import run_whole
from .drift import (DEFAULT_DRIFT_WINDOW_S, STEP_SPREADS, DriftFilter, drift_baseline,
                    drift_window, level_steps)
from .quality import (DROPOUT_MIN_RUN, FALSE_ALARM, ChannelQuality, ChannelScan, HumReport,
                      find_runs, merge_runs, quality_from_scan, warn_quality)
from .snr import estimate_noise, estimate_snr
from .sos_design import butter_sos, notch_sos
from .spectral import welch
from .zero_phase import ZeroPhase
from ..validate import as_signal, as_choice, as_float, as_nonnegative, as_positive, as_positive_int

__all__ = [
    "ChannelQuality", "HumReport", "band_request",
    "default_band", "design_filter", "design_notch", "filter_signal", "remove_drift", "drift_baseline",
    "level_steps", "STEP_SPREADS",
    "detect_hum", "notch_hum", "assess_quality", "estimate_noise", "estimate_snr",
    "merge_runs", "gap_intervals",
    "check_freq", "resolve_band", "hum_nperseg", "detrend_linear", "band_limit", "settle_time", "notch_settle", "drift_highpass",
    "DEFAULT_HIGHPASS_HZ", "DEFAULT_DRIFT_WINDOW_S", "NOTCH_Q",
]

#: High-pass corner used when the mesh frequency is unknown [Hz].
DEFAULT_HIGHPASS_HZ = 0.05
#: High-pass corner as a fraction of the mesh frequency [-].
HIGHPASS_FRACTION = 1.0 / 20.0
#: Low-pass corner as a multiple of the mesh frequency [-].
LOWPASS_MULTIPLE = 4.0
#: Highest corner frequency allowed, as a fraction of fs [-].
MAX_CORNER_FRACTION = 0.45
#: Quality factor of the hum notches of the conditioning chain [-].
NOTCH_Q = 30.0


# ====================================================================== small helpers
def _as_signal(x, name: str = "x") -> np.ndarray:
    """1-D float64 view/copy of ``x``; NaN/inf allowed (they are data-quality findings)."""
    return as_signal(x, name, float64=True)


def check_freq(value, name: str, fs: float) -> float:
    """``value`` [Hz] checked positive and below Nyquist ``fs / 2`` (``name`` in messages)."""
    f = as_positive(value, name)
    if f >= 0.5 * fs:
        raise ValueError(f"{name} must be below Nyquist fs/2 = {0.5 * fs!r} Hz, got {f!r}")
    return f


# ====================================================================== filtering
def default_band(fs: float, mesh_freq: float | None = None) -> tuple[float | None, float | None]:
    """Default (high-pass corner, low-pass corner) [Hz] for a strain channel.

    Parameters
    ----------
    fs : float
        Sample rate [Hz].
    mesh_freq : float, optional
        Mesh frequency f_m of the gauged gear [Hz].

    Returns
    -------
    (low, high) : tuple
        ``low = f_m / 20`` (``DEFAULT_HIGHPASS_HZ`` without ``f_m``); ``high = 4 f_m`` when
        below ``0.45 fs``, else None (no low-pass). See the module docstring for the reasons.
    """
    fs = as_positive(fs, "fs")
    if mesh_freq is None:
        return (min(DEFAULT_HIGHPASS_HZ, 0.25 * fs), None)
    fm = as_positive(mesh_freq, "mesh_freq")
    low = HIGHPASS_FRACTION * fm
    if low >= MAX_CORNER_FRACTION * fs:
        raise ValueError(f"mesh_freq {fm!r} Hz is too high for fs {fs!r} Hz: the default "
                         f"high-pass corner f_m/20 = {low!r} Hz exceeds 0.45 fs")
    high = LOWPASS_MULTIPLE * fm
    return (low, high if high < MAX_CORNER_FRACTION * fs else None)


def design_filter(fs: float, *, kind: str = "bandpass", low: float | None = None,
                  high: float | None = None, order: int = 4) -> np.ndarray:
    """Butterworth second-order sections for :func:`filter_signal`.

    Parameters
    ----------
    fs : float
        Sample rate [Hz].
    kind : {"bandpass", "highpass", "lowpass"}
    low : float, optional
        High-pass corner [Hz] (bandpass, highpass).
    high : float, optional
        Low-pass corner [Hz] (bandpass, lowpass).
    order : int
        Butterworth order of the one-way filter (zero-phase filtering doubles it).

    Returns
    -------
    sos : ndarray, shape (n_sections, 6)
    """
    fs = as_positive(fs, "fs")
    kind = as_choice(kind, "kind", ("bandpass", "highpass", "lowpass"))
    order = as_positive_int(order, "order")
    if order > 12:
        raise ValueError(f"order must be <= 12, got {order!r}")
    if kind in ("bandpass", "highpass"):
        if low is None:
            raise ValueError(f"kind={kind!r} needs the high-pass corner low [Hz], got None")
        low = check_freq(low, "low", fs)
    if kind in ("bandpass", "lowpass"):
        if high is None:
            raise ValueError(f"kind={kind!r} needs the low-pass corner high [Hz], got None")
        high = check_freq(high, "high", fs)
    if kind == "bandpass":
        if not low < high:
            raise ValueError(f"low ({low!r} Hz) must be below high ({high!r} Hz)")
        return butter_sos(order, [low, high], "bandpass", fs)
    if kind == "highpass":
        return butter_sos(order, low, "highpass", fs)
    return butter_sos(order, high, "lowpass", fs)


def resolve_band(fs, kind, low, high, mesh_freq):
    """(kind, low, high) [Hz] that :func:`filter_signal` designs for a request: missing
    corners from :func:`default_band`; a bandpass without a usable low-pass corner becomes
    a high-pass (logged)."""
    d_low, d_high = default_band(fs, mesh_freq)
    if kind == "bandpass":
        low = d_low if low is None else low
        high = d_high if high is None else high
        if high is None:
            logger.info("bandpass: no low-pass corner (mesh frequency unknown or near Nyquist); "
                        "high-pass only at %.4g Hz", low)
            return "highpass", low, None
        return kind, low, high
    if kind == "highpass":
        return kind, (d_low if low is None else low), None
    if high is None:
        if d_high is None:
            raise ValueError("kind='lowpass' needs high [Hz] or a mesh_freq whose default corner "
                             f"4 f_m lies below 0.45 fs; got high=None, mesh_freq={mesh_freq!r}")
        high = d_high
    return kind, None, high


def settle_time(low: float | None, high: float | None) -> float:
    """Heuristic settling time [s] of a zero-phase filter: 2 / (lowest corner)."""
    corners = [f for f in (low, high) if f is not None]
    return 2.0 / min(corners) if corners else 0.0


def band_request(fs: float, mesh_freq, lowpass, highpass) -> tuple[str, float | None, float | None] | None:
    """(kind, low, high) of :func:`meshphase.conditioning.condition_recording`'s band limit as it asks
    :func:`~meshphase.conditioning.filter_recording` for it, or None (no band limit)."""
    low = None if highpass is None else check_freq(highpass, "highpass", fs)
    if isinstance(lowpass, str):
        as_choice(lowpass, "lowpass", ("auto",))
        high = default_band(fs, mesh_freq)[1] if mesh_freq is not None else None
    elif lowpass is None:
        high = None
    else:
        high = check_freq(lowpass, "lowpass", fs)
    if low is None and high is None:
        return None
    kind = "bandpass" if (low is not None and high is not None) else (
        "highpass" if low is not None else "lowpass")
    return kind, low, high


def band_limit(fs: float, mesh_freq: float | None, lowpass, highpass: float | None,
               order: int = 4) -> tuple | None:
    """The band limit of :func:`condition_recording`, as its filter runs it.

    Parameters
    ----------
    fs : float
        Sample rate [Hz].
    mesh_freq : float or None
        Mesh frequency [Hz] (the ``"auto"`` low-pass corner).
    lowpass, highpass, order
        As :func:`condition_recording`.

    Returns
    -------
    (kind, low, high, sos) or None
        Filter kind, corners [Hz] and second-order sections; None when there is no band
        limit.
    """
    req = band_request(fs, mesh_freq, lowpass, highpass)
    if req is None:
        return None
    kind, low, high = resolve_band(fs, *req, None)          # filter_recording resolves,
    kind, low, high = resolve_band(fs, kind, low, high, None)   # filter_signal again
    return kind, low, high, design_filter(fs, kind=kind, low=low, high=high, order=order)


def notch_settle(freqs, q: float = NOTCH_Q) -> float:
    """Ringing time [s] of hum notches of quality ``q`` at ``freqs`` [Hz]: a notch rings for
    ~q / (pi f) seconds, twice that for the lowest line; 0 without lines."""
    f = np.asarray(freqs, dtype=np.float64)
    return 2.0 * q / (math.pi * float(np.min(f))) if f.size else 0.0


def drift_highpass(fs: float, window: float, order: int = 2) -> np.ndarray:
    """Second-order sections of the ``method="highpass"`` drift removal: a Butterworth
    high-pass of corner ``min(1 / window, fs / 4)`` [Hz] (``window`` [s], ``fs`` [Hz])."""
    window = as_positive(window, "window")
    return design_filter(fs, kind="highpass", low=min(1.0 / window, 0.25 * fs), order=order)


def _zero_phase(x: np.ndarray, sos: np.ndarray, *, what: str, fill_max: int) -> np.ndarray:
    """The :class:`~meshphase.signal.zero_phase.ZeroPhase` block filter pushed the whole of
    ``x``, warning about the stretches too short for it."""
    return run_whole(ZeroPhase(sos, x.size, what=what, fill_max=fill_max, engine="auto",
                               warn=True), x)


def filter_signal(x, fs: float, *, kind: str = "bandpass", low: float | None = None,
                  high: float | None = None, order: int = 4, mesh_freq: float | None = None,
                  fill_max: int = 8) -> np.ndarray:
    """Zero-phase Butterworth filtering that leaves gaps as NaN.

    Parameters
    ----------
    x : array_like, shape (n,)
        Samples of one channel [any unit]; NaN/inf mark gaps.
    fs : float
        Sample rate [Hz].
    kind : {"bandpass", "highpass", "lowpass"}
        Filter type. "bandpass" without a usable low-pass corner degrades to a high-pass
        (logged).
    low, high : float, optional
        High-pass and low-pass corners [Hz]; default from :func:`default_band`.
    order : int
        One-way Butterworth order (the zero-phase result has twice the attenuation slope).
    mesh_freq : float, optional
        Mesh frequency of the gauged gear [Hz], for the defaults.
    fill_max : int
        Interior gaps up to this many samples are bridged for the filter (and NaN again on
        output); longer gaps split the signal.

    Returns
    -------
    y : ndarray of float64, shape (n,)

    Notes
    -----
    :func:`scipy.signal.sosfiltfilt` runs the filter forwards and backwards: no phase shift
    (the pulse timing is untouched) and squared magnitude response (through
    :func:`meshphase.signal.iir.sosfiltfilt`, which takes the same arithmetic compiled by numba
    for a long channel).
    """
    x = _as_signal(x)
    fs = as_positive(fs, "fs")
    fill_max = int(as_nonnegative(fill_max, "fill_max"))
    kind = as_choice(kind, "kind", ("bandpass", "highpass", "lowpass"))
    kind, low, high = resolve_band(fs, kind, low, high, mesh_freq)
    sos = design_filter(fs, kind=kind, low=low, high=high, order=order)
    return _zero_phase(x, sos, what=f"filter_signal({kind})", fill_max=fill_max)


# ====================================================================== drift
def remove_drift(x, fs: float, *, method: str = "median", window: float | None = None,
                 mesh_freq: float | None = None, order: int = 2, fill_max: int = 8,
                 pulse_period: float | None = None) -> np.ndarray:
    """Remove slow (thermal) drift from a strain channel.

    Parameters
    ----------
    x : array_like, shape (n,)
        Samples [any unit]; NaN/inf stay NaN.
    fs : float
        Sample rate [Hz].
    method : {"median", "savgol", "highpass"}
        "median" (default) and "savgol" subtract :func:`drift_baseline`; "highpass" is a
        zero-phase Butterworth high-pass of corner ``1 / window`` and order ``order``.
    window : float, optional
        Baseline window [s] (see :func:`drift_baseline`).
    mesh_freq : float, optional
        Mesh frequency [Hz] for the default window.
    order : int
        High-pass order (method "highpass" only).
    fill_max : int
        Gap bridging of the high-pass (see :func:`filter_signal`).
    pulse_period : float, optional
        Period of the pulse train [s] (see :func:`drift_baseline`).

    Returns
    -------
    y : ndarray of float64, shape (n,)

    Notes
    -----
    The block-median + moving-median baseline costs a fraction of a pass over the data
    (each block median uses at most 33 strided samples), is robust to the sparse tooth pulses and follows a linear
    trend exactly; it is the default because a high-pass corner low enough to keep long
    pulses intact (0.05 Hz at the seed rig's ring gauge) needs very long filter settling.
    """
    x = _as_signal(x)
    fs = as_positive(fs, "fs")
    method = as_choice(method, "method", ("median", "savgol", "highpass"))
    w = drift_window(window, mesh_freq)
    if method == "highpass":
        return _zero_phase(x, drift_highpass(fs, w, order), what="filter_signal(highpass)",
                           fill_max=int(as_nonnegative(fill_max, "fill_max")))
    if x.size == 0:
        return np.empty(0)
    return run_whole(DriftFilter(x.size, fs, method=method, window=w, pulse_period=pulse_period), x)


# ====================================================================== mains hum
def hum_nperseg(n: int, fs: float) -> int:
    """Welch segment length of the hum search: about 4 s (a power of two), at most ``n``."""
    return int(min(n, 2 ** math.ceil(math.log2(4.0 * fs))))


def detrend_linear(seg: np.ndarray) -> np.ndarray:
    """Each row of ``seg`` (segments along the last axis) less its least-squares line.

    The line is the projection on the orthonormal pair ``1 / sqrt(n)`` and the centred,
    normalised sample index: two matrix-vector products for every segment at once.
    ``scipy.signal.detrend(seg, type="linear")`` gives the same to rounding (4e-15
    relative in a 120-s PSD of the hum search; the tests allow 1e-9 and 1e-12 of the
    segments' scale) by a least-squares solve per segment, with which the whole ``welch``
    of 120 s took 1.6-2.1x as long (``meshphase bench processing``, throughput table, the
    two ``welch detrend=`` rows).
    """
    n = seg.shape[-1]
    if n == 0:
        return seg.copy()
    if n == 1:
        return np.zeros_like(seg)
    t = np.arange(n) - 0.5 * (n - 1)
    t /= np.sqrt(t @ t)
    return seg - seg.mean(axis=-1, keepdims=True) - (seg @ t)[..., None] * t


def _fill_nonfinite(x: np.ndarray) -> np.ndarray:
    bad = ~np.isfinite(x)
    if not bad.any():
        return x
    good = np.flatnonzero(~bad)
    if good.size == 0:
        return np.zeros_like(x)
    out = x.copy()
    idx = np.flatnonzero(bad)
    out[idx] = np.interp(idx, good, x[good])
    return out


def detect_hum(x, fs: float, *, mains: str | float = "auto", n_harmonics: int = 5,
               threshold_db: float = 10.0, max_seconds: float = 120.0,
               exclude: Sequence[float] = ()) -> HumReport:
    """Find mains hum lines (50/60 Hz and harmonics) standing above the noise floor.

    Parameters
    ----------
    x : array_like, shape (n,)
        Samples [any unit]; non-finite samples are bridged by interpolation for the
        spectrum.
    fs : float
        Sample rate [Hz].
    mains : {"auto", 50, 60}
        Mains family to look for; "auto" examines both and keeps the stronger.
    n_harmonics : int
        Harmonics examined (1 = fundamental only), capped at 0.45 fs.
    threshold_db : float
        A line is hum when its Welch PSD peak (within +-0.5 Hz) exceeds the median PSD of
        its neighbourhood (1.5-6 Hz away) by this much [dB].
    max_seconds : float
        Only the first ``max_seconds`` of ``x`` are analysed [s] (hum is stationary; this
        bounds the cost on long recordings).
    exclude : sequence of float
        Frequencies [Hz] not to treat as hum (e.g. known mesh harmonics); candidates within
        1 Hz of one are skipped.

    Returns
    -------
    HumReport

    Notes
    -----
    Welch PSD with segments of about 4 s (0.25 Hz resolution) and linear detrending. A mesh
    harmonic that happens to sit on a mains line is indistinguishable from hum by this test:
    pass it in ``exclude``.
    """
    x = _as_signal(x)
    fs = as_positive(fs, "fs")
    if isinstance(mains, str):
        as_choice(mains, "mains", ("auto",))
        families = (50.0, 60.0)
    else:
        m = as_float(mains, "mains")
        if m not in (50.0, 60.0):
            raise ValueError(f"mains must be 'auto', 50 or 60 [Hz], got {mains!r}")
        families = (m,)
    n_harmonics = as_positive_int(n_harmonics, "n_harmonics")
    threshold_db = as_float(threshold_db, "threshold_db")
    max_seconds = as_positive(max_seconds, "max_seconds")
    excl = np.asarray([as_float(f, "exclude") for f in exclude], dtype=np.float64)

    cands = {f0: np.array([k * f0 for k in range(1, n_harmonics + 1)
                           if k * f0 < MAX_CORNER_FRACTION * fs]) for f0 in families}
    all_c = np.unique(np.concatenate(list(cands.values()))) if cands else np.empty(0)
    n_use = min(x.size, int(max_seconds * fs))
    xs = x[:n_use]
    n_finite = int(np.count_nonzero(np.isfinite(xs)))
    if n_finite < 2.0 * fs or all_c.size == 0:
        return HumReport(None, np.empty(0), all_c, np.full(all_c.size, np.nan), threshold_db,
                         checked=False)
    xs = _fill_nonfinite(xs)
    # the test is a ratio of PSD values: scaled to a largest magnitude of 1, samples of any
    # size (1e300, subnormal) give it without overflow or underflow in the squares
    peak_abs = float(np.max(np.abs(xs)))
    if peak_abs > 0.0:
        xs = xs / peak_abs
    nper = hum_nperseg(xs.size, fs)
    f, p = welch(xs, fs, nper, detrend=detrend_linear)
    df = f[1] - f[0]

    def excess(fc: float) -> float:
        if excl.size and np.min(np.abs(excl - fc)) < 1.0:
            return float("nan")
        near = np.abs(f - fc) <= max(0.5, 0.51 * df)
        ring = (np.abs(f - fc) >= max(1.5, 2 * df)) & (np.abs(f - fc) <= max(6.0, 8 * df))
        if not near.any() or ring.sum() < 3:
            return float("nan")
        floor = np.median(p[ring])
        peak = np.max(p[near])
        if floor <= 0:
            return float("inf") if peak > 0 else float("nan")
        return float(10.0 * np.log10(peak / floor))

    ex = {fc: excess(fc) for fc in all_c}
    best, best_key = None, None
    for f0, c in cands.items():
        e = np.array([ex[fc] for fc in c])
        present = np.nan_to_num(e, nan=-np.inf) >= threshold_db
        if not present.any():
            continue
        key = (bool(present[0]), int(present.sum()), float(np.nansum(np.where(present, e, 0.0))))
        if best_key is None or key > best_key:
            best, best_key = f0, key
    freqs = np.empty(0)
    if best is not None:
        c = cands[best]
        e = np.array([ex[fc] for fc in c])
        freqs = c[np.nan_to_num(e, nan=-np.inf) >= threshold_db]
    return HumReport(best, freqs, all_c, np.array([ex[fc] for fc in all_c]), threshold_db)


def notch_hum(x, fs: float, *, freqs: Sequence[float] | None = None, mains: str | float = "auto",
              q: float = 30.0, threshold_db: float = 10.0, exclude: Sequence[float] = (),
              fill_max: int = 8) -> np.ndarray:
    """Zero-phase notches at mains hum lines.

    Parameters
    ----------
    x : array_like, shape (n,)
        Samples [any unit]; NaN/inf stay NaN.
    fs : float
        Sample rate [Hz].
    freqs : sequence of float, optional
        Lines to notch [Hz]; default: those :func:`detect_hum` finds (nothing is filtered
        when no hum is present; an empty sequence also filters nothing).
    mains, threshold_db, exclude
        Passed to :func:`detect_hum` when ``freqs`` is None.
    q : float
        Quality factor of each notch, f / bandwidth(-3 dB) [-].
    fill_max : int
        Gap bridging (see :func:`filter_signal`).

    Returns
    -------
    y : ndarray of float64, shape (n,)

    Notes
    -----
    Each line is a :func:`scipy.signal.iirnotch` biquad (:func:`meshphase.signal.sos_design.notch_sos`);
    all are cascaded as second-order sections and applied forwards and backwards
    (:func:`meshphase.signal.iir.sosfiltfilt`, scipy.signal.sosfiltfilt's arithmetic).
    """
    x = _as_signal(x)
    fs = as_positive(fs, "fs")
    q = as_positive(q, "q")
    if freqs is None:
        rep = detect_hum(x, fs, mains=mains, threshold_db=threshold_db, exclude=exclude)
        if not rep.checked and x.size:
            warnings.warn(f"notch_hum: only {x.size / fs:.3g} s of data, too short to detect mains "
                          "hum; no notch applied (pass freqs to force one)", ProcessingWarning,
                          stacklevel=2)
        fl = rep.freqs
    else:
        fl = np.asarray([check_freq(f, "freqs", fs) for f in freqs], dtype=np.float64)
    if fl.size == 0 or x.size == 0:
        return x.copy()
    fill_max = int(as_nonnegative(fill_max, "fill_max"))
    return _zero_phase(x, design_notch(fl, fs, q), what="notch_hum", fill_max=fill_max)


def design_notch(freqs, fs: float, q: float = 30.0) -> np.ndarray:
    """Second-order sections of :func:`notch_hum`'s filter: one :func:`scipy.signal.iirnotch`
    biquad per line in ``freqs`` [Hz] (quality factor ``q`` [-]) at sample rate ``fs`` [Hz],
    cascaded; shape (len(freqs), 6)."""
    return notch_sos(freqs, q, fs)


# ====================================================================== quality
def gap_intervals(quality_or_mask, fs: float | None = None, t0: float | None = None) -> np.ndarray:
    """Gap intervals of a channel in seconds: non-finite gaps and dropout runs together.

    Parameters
    ----------
    quality_or_mask : ChannelQuality, or array_like of shape (n,)
        A channel's quality report (its ``gap_runs`` and ``dropout_runs``); or a boolean
        mask, True for every sample lost; or the samples of a conditioned channel (float),
        whose non-finite samples are the gaps (dropouts are NaN there after
        :func:`condition_recording`).
    fs : float, optional
        Sample rate [Hz]; required for a mask or samples, taken from a report (and checked
        against it when given).
    t0 : float, optional
        Time of sample 0 [s]; default 0 for a mask or samples, the report's own ``t0`` for a
        report (checked against it when given).

    Returns
    -------
    ndarray of float64, shape (k, 2)
        ``[t_start, t_stop)`` per gap, sorted, disjoint, merged when touching:
        ``t_start = t0 + i_start / fs`` is the time of the first lost sample, ``t_stop =
        t0 + i_stop / fs`` that of the first good sample after it (the end of the
        recording for a trailing gap). A reference time ``t`` lies in a gap when
        ``t_start <= t < t_stop``; shape (0, 2) when there is none.
    """
    if isinstance(quality_or_mask, ChannelQuality):
        q = quality_or_mask
        if fs is not None and as_positive(fs, "fs") != q.fs:
            raise ValueError(f"fs {fs!r} Hz contradicts the quality report's {q.fs!r} Hz")
        if t0 is not None and as_float(t0, "t0") != q.t0:
            raise ValueError(f"t0 {t0!r} s contradicts the quality report's {q.t0!r} s")
        return q.gap_intervals()
    if isinstance(quality_or_mask, (str, bytes, dict)) or quality_or_mask is None:
        raise TypeError("quality_or_mask must be a ChannelQuality, a boolean mask or the "
                        f"samples of a channel, got {type(quality_or_mask).__name__}")
    arr = np.asarray(quality_or_mask)
    if arr.dtype.kind not in "bf":
        raise TypeError(f"quality_or_mask must be a ChannelQuality, a boolean mask or float "
                        f"samples, got an array of dtype {arr.dtype}")
    if arr.ndim != 1:
        raise ValueError(f"quality_or_mask must be 1-D (one channel), got shape {arr.shape}")
    if fs is None:
        raise ValueError("fs [Hz] is required with a mask or samples, got None")
    fs = as_positive(fs, "fs")
    t0 = 0.0 if t0 is None else as_float(t0, "t0")
    runs = find_runs(arr if arr.dtype.kind == "b" else ~np.isfinite(arr))
    return t0 + runs.astype(np.float64) / fs


def assess_quality(x, fs: float, *, t0: float = 0.0, name: str = "", clip_min_run: int = 3,
                   clip_rtol: float = 0.0, snr: bool = True, warn: bool = True,
                   snr_warn_db: float = 6.0, detect_flat: bool = True,
                   dropout_min_run: int = DROPOUT_MIN_RUN,
                   false_alarm: float = FALSE_ALARM) -> ChannelQuality:
    """Quality report of one channel: gaps, NaN runs, dropouts, clipped runs, SNR.

    Parameters
    ----------
    x : array_like, shape (n,)
        Samples [any unit]; assess clipping on raw (unfiltered) data.
    fs : float
        Sample rate [Hz].
    t0 : float
        Time of the first sample [s].
    name : str
        Channel name for messages.
    clip_min_run, clip_rtol
        See :func:`meshphase.signal.quality.clipped_runs`; ``clip_min_run`` is also the shortest
        clipped plateau at other levels [samples].
    snr : bool
        Estimate the SNR (:func:`estimate_snr`); meaningful on drift-free data.
    warn : bool
        Issue a :class:`~meshphase.errors.DataQualityWarning` when gaps, dropouts or clipped
        runs are found, or the SNR is below ``snr_warn_db``.
    snr_warn_db : float
        SNR below which to warn [dB].
    detect_flat : bool
        Look for dropout runs and clipped plateaus at any level
        (:func:`meshphase.signal.flat_runs.flat_runs`); False: non-finite gaps and rail clipping only.
        Meant for analogue (strain) channels, not pulse trains.
    dropout_min_run : int
        Floor of the dropout run-length threshold [samples], >= 2 (the threshold itself
        comes from the channel's statistics).
    false_alarm : float
        Expected number of chance runs over the channel at the threshold [-], in (0, 1).

    Returns
    -------
    ChannelQuality
    """
    x = _as_signal(x)
    fs = as_positive(fs, "fs")
    t0 = as_float(t0, "t0")
    if not isinstance(name, str):
        raise TypeError(f"name must be a string, got {name!r}")
    clip_min_run = as_positive_int(clip_min_run, "clip_min_run")
    if clip_min_run < 2:
        raise ValueError(f"clip_min_run must be >= 2, got {clip_min_run!r}")
    clip_rtol = as_nonnegative(clip_rtol, "clip_rtol")
    if not isinstance(detect_flat, (bool, np.bool_)):
        raise TypeError(f"detect_flat must be a bool, got {type(detect_flat).__name__} {detect_flat!r}")
    dropout_min_run = as_positive_int(dropout_min_run, "dropout_min_run")
    if dropout_min_run < 2:
        raise ValueError(f"dropout_min_run must be >= 2, got {dropout_min_run!r}")
    false_alarm = as_positive(false_alarm, "false_alarm")
    if not false_alarm < 1.0:
        raise ValueError(f"false_alarm must be in (0, 1), got {false_alarm!r}")
    if x.size == 0:
        e = np.empty((0, 2), dtype=np.int64)
        return ChannelQuality(name, fs, t0, 0, e, e.copy(), e.copy())
    scan = ChannelScan(x.size, flat=bool(detect_flat), rail_min_run=clip_min_run,
                       rail_rtol=clip_rtol, false_alarm=false_alarm, min_run=dropout_min_run,
                       clip_min_run=clip_min_run)
    scan.feed1(x)
    scan.end1()
    scan.feed2(x)
    rep = quality_from_scan(scan.result(), name, fs, t0)
    if snr:
        snr_db, peak, noise = estimate_snr(x)
        rep = replace(rep, snr_db=snr_db, signal_peak=peak, noise_rms=noise)
    if warn:
        warn_quality(rep, snr_warn_db)
    return rep
