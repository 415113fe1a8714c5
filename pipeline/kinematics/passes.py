"""Pass selection: which of a gauge's onsets its phasing uses, when each pass happened and
how well it is timed.

The onset detector (:mod:`meshphase.onsets`) times every pulse of a gauge channel; the phasing
(:mod:`meshphase.kinematics.phasing`) wants passes: the usable pulses (:func:`usable_onsets`: clean, or
flagged only for a gap that conditioning bridged), each at its timing centre (a fixed angle
of the gauged gear, :func:`pass_times`), with a timing bound (:func:`onset_sigma`, in white
noise of the channel's RMS) that weights the pass in the angle model, and the factor by
which the bound in the channel's noise spectrum exceeds it (:func:`channel_noise_spectrum`):
the timing floor the phasing's reliability is judged against. Centres and bounds are the
detector's (the timing model its onsets carry, :mod:`meshphase.onsets.timing`): this module
works with any onset detector.
:func:`gauge_passes` does that for every gauge of a recording; :func:`gap_intervals_of`
gives the gaps the phasing must not bridge.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from ..errors import DataQualityWarning, ProcessingWarning
from ..signal.noise_spectrum import TRANSIENT_RATIO, NoiseSpectrum, pulse_residual_psd
from ..onsets import FLAG_GAP, FLAG_TEMPLATE, Onsets
from .phasing import GaugePasses
from ..recording import GAUGE_KINDS
from ..validate import as_positive

__all__ = ["pass_times", "usable_onsets",
           "conditioned_gap_runs", "gap_intervals_of", "onset_sigma", "channel_noise_spectrum",
           "NOISE_LIKE_RATIO", "gauge_passes"]

#: a residual (what the pulses leave, :func:`channel_noise_spectrum`) whose RMS exceeds this
#: many times the channel's per-sample noise RMS is taken for pulse misfit, not noise [-]: a
#: noise-free synthetic speed ramp leaves 150x (sun) to 7e4x (ring), while 30 dB of noise
#: with 30 % of it 1/f leaves 0.4x and white noise 0.1x (both low-passed by conditioning);
#: noise 99 % 1/f would stay below it
NOISE_LIKE_RATIO = 10.0



def _as_onsets(on) -> Onsets:
    if not isinstance(on, Onsets):
        raise TypeError(f"onsets must be an Onsets (meshphase.onsets), got {type(on).__name__}")
    return on


def pass_times(onsets: Onsets) -> np.ndarray:
    """Onset times moved to their timing centres [s] (:attr:`meshphase.onsets.Onsets.centres`,
    from the detector's timing model): a fixed angle of the gauged gear whatever the local
    speed, on every gauge alike. Shifts that would break the increasing order are not
    applied."""
    return _as_onsets(onsets).centres


def usable_onsets(onsets: Onsets, gap_runs, fs: float, t0: float) -> np.ndarray:
    """Onsets to measure phasing with: the clean ones, plus those flagged only for a gap that
    conditioning bridged (a few dropped samples, see condition.filter_signal's ``fill_max``):
    the conditioned signal is finite over the whole pulse, so the timing is not affected.

    Parameters
    ----------
    onsets : meshphase.onsets.Onsets
    gap_runs : array_like of int, shape (k, 2), or None
        The ``[start, stop)`` sample runs where the conditioned channel is not finite
        (:func:`conditioned_gap_runs`), sorted; None: none known.
    fs : float
        Sample rate [Hz].
    t0 : float
        Time of sample 0 [s].

    Returns
    -------
    ndarray of bool, shape (n,)
        A pulse flagged only for a gap is usable when no run meets ``[i - 2 h, i + 2 h)``
        around its onset sample ``i``, ``h`` its half width (at least 2 samples).
    """
    on = _as_onsets(onsets)
    fs = as_positive(fs, "fs")
    ok = on.good.copy()
    gap_only = on.flags == np.uint8(FLAG_GAP)
    if not np.any(gap_only):
        return ok
    r = np.empty((0, 2), dtype=np.int64) if gap_runs is None else \
        np.asarray(gap_runs, dtype=np.int64).reshape(-1, 2)
    if not len(r):
        return ok | gap_only
    half = np.maximum(2, np.ceil(np.nan_to_num(on.width, nan=0.0) * fs)).astype(np.int64)
    i = np.rint((on.times - t0) * fs).astype(np.int64)
    a, b = i - 2 * half, i + 2 * half
    j = np.searchsorted(r[:, 1], a, side="right")          # first run ending after a
    hit = (j < len(r)) & (r[np.minimum(j, len(r) - 1), 0] < b) & (b > a)
    return ok | (gap_only & ~hit)


def conditioned_gap_runs(quality):
    """The ``[start, stop)`` sample runs where a conditioned channel is not finite, from its
    quality report (:class:`meshphase.signal.condition.ChannelQuality`): its conditioned gap runs,
    else its gaps and dropouts; None without a report."""
    if quality is None:
        return None
    runs = getattr(quality, "conditioned_gap_runs", None)
    return quality.all_gap_runs() if runs is None else runs


def gap_intervals_of(quality: dict) -> np.ndarray:
    """Gap intervals [s] of the conditioned gauge channels: every channel's NaN runs and
    dropouts, channel after channel (not merged).

    Parameters
    ----------
    quality : dict of str to ChannelQuality
        Per conditioned channel.

    Returns
    -------
    ndarray, shape (k, 2)
        ``[start, stop)`` times [s].
    """
    if not isinstance(quality, dict):
        raise TypeError(f"quality must be a dict of channel quality reports, got {type(quality).__name__}")
    out = []
    for q in quality.values():
        for attr in ("gap_runs", "dropout_runs"):
            runs = getattr(q, attr, None)
            if runs is not None and np.size(runs):
                r = np.asarray(runs, dtype=float).reshape(-1, 2)
                out.append(q.t0 + r / q.fs)
    return np.concatenate(out) if out else np.empty((0, 2))


def onset_sigma(onsets: Onsets, noise_rms: float, *, noise: NoiseSpectrum | None = None) -> np.ndarray:
    """Per-onset timing uncertainty [s] in the conditioned channel's noise, from the timing
    model the detector's onsets carry (:meth:`meshphase.onsets.Onsets.sigma`; the matched
    filter's: :meth:`meshphase.onsets.timing.TemplateTiming.sigma`, the Cramer-Rao bound at
    the fitted amplitude with a resolution floor).

    Parameters
    ----------
    onsets : meshphase.onsets.Onsets
    noise_rms : float
        RMS of the conditioned channel's noise per sample [data units]; not a positive
        finite float (and no ``noise``): the floor alone.
    noise : NoiseSpectrum, optional
        The channel's noise spectrum [data units^2/Hz] (:func:`channel_noise_spectrum`), for
        a timing model that uses it.

    Returns
    -------
    ndarray, shape (n,)
        [s]; NaN where the bound is unknown.
    """
    on = _as_onsets(onsets)
    if noise is not None and not isinstance(noise, NoiseSpectrum):
        raise TypeError(f"noise must be a NoiseSpectrum or None, got {type(noise).__name__}")
    return on.sigma(noise_rms, noise)


def channel_noise_spectrum(excerpt, name: str, onsets: Onsets, quality=None) -> NoiseSpectrum | None:
    """The noise spectrum of a conditioned gauge channel for :func:`onset_sigma`
    (:func:`meshphase.signal.noise_spectrum.pulse_residual_psd`): one Welch estimate per channel,
    from the conditioned samples a run keeps (the condition stage's excerpt, its first
    minute), after the filters settled. A residual above :data:`NOISE_LIKE_RATIO` times the
    channel's per-sample noise RMS is pulse misfit, not noise: no spectrum then. Pulse windows
    holding a transient are left out of the estimate, with a DataQualityWarning.

    Parameters
    ----------
    excerpt : Recording or None
        Conditioned channels.
    name : str
        The channel.
    onsets : meshphase.onsets.Onsets
        Its onsets.
    quality : ChannelQuality, optional
        Its quality report (``settle`` [s], ``noise_rms`` [data units]).

    Returns
    -------
    NoiseSpectrum or None
        None without an excerpt, without the channel in it, with too few pulses or
        samples, or with a residual that is not noise-like.
    """
    on = _as_onsets(onsets)
    if not isinstance(name, str):
        raise TypeError(f"name must be a channel name (str), got {type(name).__name__}")
    if excerpt is None or name not in excerpt.names or excerpt.n_samples == 0:
        return None
    skip = float(getattr(quality, "settle", 0.0) or 0.0)
    # the windows of pulses only: a flagged onset (low correlation, at an edge, a gap or a
    # clipped run) need not hold one, and its window is then the pulse's misplaced flanks,
    # which on clean data are thousands of times the noise and were taken for transients
    clean = on.times[(np.asarray(on.flags) | FLAG_TEMPLATE) == FLAG_TEMPLATE]
    spec = pulse_residual_psd(excerpt.channel(name), excerpt.fs, excerpt.t0, clean, skip=skip)
    if spec is not None and spec.n_excluded:
        warnings.warn(f"channel {name!r}: {spec.n_excluded} of {spec.n_excluded + spec.n_pulses} "
                      "pulse windows in the first minute hold a transient (a level step of the "
                      "bridge, a knock: residual energy over "
                      f"{TRANSIENT_RATIO:g}x the others'); left out of its noise spectrum",
                      DataQualityWarning, stacklevel=3)
    rms = float(getattr(quality, "noise_rms", float("nan")))
    if spec is not None and math.isfinite(rms) and spec.rms > NOISE_LIKE_RATIO * rms:
        return None
    return spec


def gauge_passes(channels, onsets: dict, quality: dict, fs: float, t0: float, *,
                 excerpt=None) -> tuple[list, dict]:
    """The passes of every gauge channel, as the phasing needs them.

    Parameters
    ----------
    channels : sequence of ChannelSpec
        The recording's channels; sun, ring and face-width gauges with onsets are used.
    onsets : dict of str to Onsets
        Per gauge channel.
    quality : dict of str to ChannelQuality
        Per conditioned channel (gap runs, noise RMS).
    fs : float
        Sample rate [Hz].
    t0 : float
        Time of sample 0 [s].
    excerpt : Recording, optional
        Conditioned samples of the gauges (the condition stage's excerpt): each gauge's
        ``floor_factor`` is then the ratio of its timing bounds in its noise spectrum
        (:func:`channel_noise_spectrum`) to those in white noise of its RMS, else 1.

    Returns
    -------
    passes : list of GaugePasses
        Each gauge with a usable pulse: pass times [s], amplitudes, timing bounds [s] (None
        when no pass has one), the floor factor; ``main`` for the first sun and the first
        ring gauge.
    mains : dict of str to str
        Gear -> its main gauge channel (also when it has no usable pulse: then a
        ProcessingWarning says so).
    """
    if not isinstance(onsets, dict) or not isinstance(quality, dict):
        raise TypeError("onsets and quality must be dicts by channel name")
    fs = as_positive(fs, "fs")
    passes: list = []
    mains: dict = {}
    for c in channels:
        if c.kind not in GAUGE_KINDS or c.name not in onsets:
            continue
        gear = c.gear if c.gear in ("sun", "ring") else (c.kind if c.kind in ("sun", "ring") else "sun")
        on = onsets[c.name]
        q = quality.get(c.name)
        # a pulse's window is checked against the runs where the conditioned channel is not
        # finite (its quality report: the conditioned samples are streamed, not kept)
        ok = usable_onsets(on, conditioned_gap_runs(q), fs, t0)
        times, amp = pass_times(on)[ok], on.amplitude[ok]
        rms = getattr(q, "noise_rms", float("nan"))
        sig = onset_sigma(on, rms)[ok]
        factor = _floor_factor(sig, on, ok, rms, channel_noise_spectrum(excerpt, c.name, on, q))
        main = c.kind in ("sun", "ring") and gear not in mains
        if main:
            mains[gear] = c.name
            if times.size == 0:
                warnings.warn(f"{gear} gauge ({c.name}): no usable pulse ({len(on)} onset(s), all "
                              "flagged or none found): dead gauge, wrong channel or no load; no "
                              "phasing from it", ProcessingWarning, stacklevel=3)
        if times.size:
            passes.append(GaugePasses(c.name, gear, times, amp,
                                      sig if np.any(np.isfinite(sig)) else None, main, factor,
                                      tooth=c.tooth))
    return passes, mains


def _floor_factor(sig: np.ndarray, on: Onsets, ok: np.ndarray, rms, spec) -> float:
    """Median over the usable passes of their timing bound in the noise spectrum ``spec``
    over their white bound ``sig`` [-]; 1 without a spectrum or a finite ratio."""
    if spec is None or not np.any(np.isfinite(sig)):
        return 1.0
    with np.errstate(divide="ignore", invalid="ignore"):
        r = onset_sigma(on, rms, noise=spec)[ok] / sig
    r = r[np.isfinite(r) & (r > 0)]
    return float(np.median(r)) if r.size else 1.0
