"""Conditioning of a whole :class:`~meshphase.recording.Recording` in memory.

Thin wrappers over :mod:`meshphase.signal`'s array functions: each picks the channels (by
default every gauge: tachos and encoders are left alone), applies the function per channel,
and returns a new Recording with one history entry (``"condition.filter"``, ...).
:func:`condition_recording` runs the whole chain (quality, hum notch, drift, band limit, SNR)
as a run's ``condition`` stage does; a run streams the recording block by block through the
same block filters (:mod:`meshphase.run.stream`), equal to these to rounding.

Sits above :mod:`meshphase.recording` (it takes and gives Recordings) and
:mod:`meshphase.signal` (the array code it applies).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Sequence

import numpy as np

from .recording import Recording
from .signal import drift as drift_filters
from .signal.condition import (NOTCH_Q, ChannelQuality, HumReport, assess_quality, band_request,
                               check_freq, detect_hum, filter_signal, notch_hum, notch_settle,
                               remove_drift, resolve_band, settle_time)
from .signal.drift import drift_window
from .signal.quality import find_runs, warn_quality
from .signal.snr import estimate_snr
from .validate import as_choice, as_positive

__all__ = ["filter_recording", "remove_drift_recording", "notch_hum_recording",
           "assess_quality_recording", "condition_recording", "Conditioned"]


def _default_channels(rec: Recording, channels) -> list[int]:
    if channels is None:
        return [i for i, c in enumerate(rec.channels) if c.kind not in ("tacho", "encoder")]
    if isinstance(channels, str):
        channels = [channels]
    return [rec.index(c) for c in channels]


def _check_rec(rec) -> None:
    if not isinstance(rec, Recording):
        raise TypeError(f"rec must be a Recording, got {type(rec).__name__}")


def _map_channels(rec: Recording, channels, func) -> tuple[Recording, list[str]]:
    _check_rec(rec)
    idx = _default_channels(rec, channels)
    out = rec.data.copy()
    for i in idx:
        out[:, i] = func(rec.data[:, i])
    return rec.replace_data(out), [rec.channels[i].name for i in idx]


def filter_recording(rec: Recording, *, channels: Sequence[str] | str | None = None,
                     kind: str = "bandpass", low: float | None = None, high: float | None = None,
                     order: int = 4, mesh_freq: float | None = None) -> Recording:
    """:func:`filter_signal` on channels of a recording (default: all but tachos and encoders).

    Returns a new Recording (same specs) with one ``"condition.filter"`` history entry
    naming the corners actually used [Hz].
    """
    _check_rec(rec)
    kind = as_choice(kind, "kind", ("bandpass", "highpass", "lowpass"))
    kind, low, high = resolve_band(rec.fs, kind, low, high, mesh_freq)
    out, names = _map_channels(rec, channels, lambda c: filter_signal(
        c, rec.fs, kind=kind, low=low, high=high, order=order))
    return out.with_history("condition.filter", kind=kind, low_hz=low, high_hz=high,
                            order=order, zero_phase=True, mesh_freq_hz=mesh_freq, channels=names)


def remove_drift_recording(rec: Recording, *, channels: Sequence[str] | str | None = None,
                           method: str = "median", window: float | None = None,
                           mesh_freq: float | None = None,
                           pulse_period: float | None = None) -> Recording:
    """:func:`remove_drift` on channels of a recording (default: all but tachos and encoders).

    Returns a new Recording with one ``"condition.remove_drift"`` history entry.
    """
    _check_rec(rec)
    method = as_choice(method, "method", ("median", "savgol", "highpass"))
    w = drift_window(window, mesh_freq)
    out, names = _map_channels(rec, channels, lambda c: remove_drift(c, rec.fs, method=method,
                                                                     window=w,
                                                                     pulse_period=pulse_period))
    return out.with_history("condition.remove_drift", method=method, window_s=w, channels=names,
                            pulse_period_s=pulse_period)


def _notch_rec(rec: Recording, channels, freqs, mains, q, exclude):
    _check_rec(rec)
    q = as_positive(q, "q")
    idx = _default_channels(rec, channels)
    data = rec.data                     # copied once, when the first channel is notched
    reports: dict[str, HumReport | None] = {}
    for i in idx:
        name = rec.channels[i].name
        if freqs is None:
            rep = detect_hum(rec.data[:, i], rec.fs, mains=mains, exclude=exclude)
            fl = rep.freqs
        else:
            rep = None
            fl = np.asarray([check_freq(f, "freqs", rec.fs) for f in freqs], dtype=np.float64)
        if fl.size:
            if data is rec.data:
                data = rec.data.copy()
            data[:, i] = notch_hum(rec.data[:, i], rec.fs, freqs=fl, q=q)
        reports[name] = rep
    lines = {nm: ([float(f) for f in r.freqs] if r is not None else [float(f) for f in freqs])
             for nm, r in reports.items()}
    out = rec.replace_data(data).with_history("condition.notch_hum", q=q, lines_hz=lines)
    return out, reports


def notch_hum_recording(rec: Recording, *, channels: Sequence[str] | str | None = None,
                        freqs: Sequence[float] | None = None, mains: str | float = "auto",
                        q: float = 30.0, exclude: Sequence[float] = ()) -> Recording:
    """:func:`notch_hum` on channels of a recording (default: all but tachos and encoders).

    Hum is detected per channel when ``freqs`` is None; the history entry
    ``"condition.notch_hum"`` lists the lines notched on each channel [Hz].
    """
    return _notch_rec(rec, channels, freqs, mains, q, exclude)[0]


def assess_quality_recording(rec: Recording, *, channels: Sequence[str] | str | None = None,
                             warn: bool = True, **kwargs) -> dict[str, ChannelQuality]:
    """:func:`assess_quality` per channel (default: all but tachos and encoders), keyed by name."""
    if not isinstance(rec, Recording):
        raise TypeError(f"rec must be a Recording, got {type(rec).__name__}")
    return {rec.channels[i].name: assess_quality(rec.data[:, i], rec.fs, t0=rec.t0,
                                                 name=rec.channels[i].name, warn=warn, **kwargs)
            for i in _default_channels(rec, channels)}


@dataclass
class Conditioned:
    """Result of :func:`condition_recording`.

    Attributes
    ----------
    recording : Recording
        The conditioned recording (history extended by one entry per step).
    quality : dict of str -> ChannelQuality
        Per conditioned channel: gaps, dropouts and clipping from the raw data, SNR after
        hum and drift removal (before any low-pass, which would hide the white noise), hum
        found, filter settling time.
    """

    recording: Recording
    quality: dict = field(default_factory=dict)


def condition_recording(rec: Recording, *, channels: Sequence[str] | str | None = None,
                        mesh_freq: float | None = None, hum: bool = True,
                        drift: str | None = "median", drift_window: float | None = None,
                        lowpass: float | str | None = "auto", highpass: float | None = None,
                        order: int = 4, warn: bool = True, dropouts: str = "nan",
                        pulse_period: float | None = None) -> Conditioned:
    """The default conditioning chain: quality -> (dropouts to NaN) -> hum notch -> drift
    removal -> band limit.

    Parameters
    ----------
    rec : Recording
    channels : names, optional
        Channels to condition (default: all but tachos and encoders); the others pass unchanged.
    mesh_freq : float, optional
        Mesh frequency of the gauged gears [Hz] (defaults of the filters, see the module
        docstring). Sun and ring gauges mesh at different frequencies (ring ~ Z_r w_c vs
        sun ~ Z_s |w_s - w_c|): condition each gear's channels with its own ``mesh_freq``
        (``channels=``) for the best drift window and low-pass.
    hum : bool
        Detect mains hum per channel and notch the lines found.
    drift : {"median", "savgol", "highpass"} or None
        Drift removal method (None: none).
    drift_window : float, optional
        Drift window [s].
    lowpass : float, "auto" or None
        Low-pass corner [Hz]; "auto": ``4 f_m`` when ``mesh_freq`` is given and below
        0.45 fs, else none.
    highpass : float, optional
        Additional zero-phase high-pass corner [Hz] (None: none; the drift removal
        usually suffices).
    order : int
        Butterworth order of the band-limiting filters.
    warn : bool
        Warn (DataQualityWarning) about gaps, dropouts, clipping and low SNR.
    dropouts : {"nan", "keep"}
        "nan": the dropout runs found on the raw data become NaN before any filtering (one
        ``"condition.mask_dropouts"`` history entry when there are any), so that they are
        gaps for every later stage; "keep": leave the samples (the report still lists them;
        pass ``quality=`` to :func:`meshphase.onsets.detect_onsets_recording`).
    pulse_period : float, optional
        Period of the channels' pulse train [s] (one relative revolution of the gauged gear):
        the drift baseline then averages whole periods (:func:`drift_baseline`).

    Returns
    -------
    Conditioned
    """
    if not isinstance(rec, Recording):
        raise TypeError(f"rec must be a Recording, got {type(rec).__name__}")
    if drift is not None:
        as_choice(drift, "drift", ("median", "savgol", "highpass"))
    dropouts = as_choice(dropouts, "dropouts", ("nan", "keep"))
    quality = assess_quality_recording(rec, channels=channels, warn=False, snr=False)
    names = list(quality)
    if not names:
        return Conditioned(rec.with_history("condition", channels=[]), quality)
    out = rec
    masked = {nm: quality[nm].n_dropout_samples for nm in names if len(quality[nm].dropout_runs)}
    if dropouts == "nan" and masked:
        data = rec.data.copy()
        for nm in masked:
            runs = quality[nm].dropout_runs
            marks = np.zeros(rec.n_samples + 1, dtype=np.int64)
            np.add.at(marks, runs[:, 0], 1)
            np.add.at(marks, runs[:, 1], -1)
            data[np.cumsum(marks[:-1]) > 0, rec.index(nm)] = np.nan
        out = rec.replace_data(data).with_history("condition.mask_dropouts", samples=masked)
    settle = 0.0
    if hum:
        out, reports = _notch_rec(out, names, None, "auto", NOTCH_Q, ())
        for nm, r in reports.items():
            quality[nm] = replace(quality[nm], hum=r)
            if r is not None and r.present:
                settle = max(settle, notch_settle(r.freqs, NOTCH_Q))
    if drift is not None:
        out = remove_drift_recording(out, channels=names, method=drift, window=drift_window,
                                     pulse_period=pulse_period,
                                     mesh_freq=mesh_freq)
        if drift == "highpass":
            # (the parameter drift_window hides the function of that name here)
            settle = max(settle, 2.0 * drift_filters.drift_window(drift_window, mesh_freq))
    # SNR on the drift-free, not yet band-limited data: its noise is still the white
    # per-sample noise the peak-power SNR is defined with (a low-pass would hide it)
    for nm in names:
        snr_db, peak, noise = estimate_snr(out.channel(nm))
        quality[nm] = replace(quality[nm], snr_db=snr_db, signal_peak=peak, noise_rms=noise)
    req = band_request(rec.fs, mesh_freq, lowpass, highpass)
    if req is not None:
        kind, low, high = req
        out = filter_recording(out, channels=names, kind=kind, low=low, high=high, order=order)
        settle = max(settle, settle_time(low, high))
    for nm in names:
        q = quality[nm] = replace(quality[nm], settle=settle,
                                  conditioned_gap_runs=find_runs(~np.isfinite(out.channel(nm))))
        if warn:
            warn_quality(q, 6.0)
    out = out.with_history("condition.quality", settle_s=settle,
                           quality={nm: quality[nm].history_entry() for nm in names})
    return Conditioned(out, quality)
