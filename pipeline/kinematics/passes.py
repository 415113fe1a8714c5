"""Pass selection: which of a gauge's onsets its phasing uses, when each pass happened and
how well it is timed.

The onset detector (:mod:`meshphase.onsets`) times every pulse of a gauge channel; the phasing
(:mod:`meshphase.kinematics.phasing`) wants passes: the usable pulses (:func:`usable_onsets`: clean, or
flagged only for a gap that conditioning bridged), each at its template's timing centre (a
fixed angle of the gauged gear, :func:`pass_times`), with a timing bound (:func:`onset_sigma`,
the Cramer-Rao bound of :func:`meshphase.signal.crb.crb_delay_std` in white noise of the channel's
RMS, with a resolution floor) that weights the pass in the angle model, and the factor by
which the bound in the channel's noise spectrum exceeds it (:func:`channel_noise_spectrum`,
:func:`meshphase.signal.crb.crb_delay_std_psd`): the timing floor the phasing's reliability is
judged against.
:func:`gauge_passes` does that for every gauge of a recording; :func:`gap_intervals_of`
gives the gaps the phasing must not bridge.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from meshphase.signal.crb import crb_delay_std, crb_delay_std_psd
from meshphase.errors import DataQualityWarning, ProcessingWarning
from meshphase.signal.noise_spectrum import TRANSIENT_RATIO, NoiseSpectrum, pulse_residual_psd
from meshphase.onsets import FLAG_GAP, FLAG_TEMPLATE, Onsets, Template
from meshphase.kinematics.phasing import GaugePasses
from meshphase.recording import GAUGE_KINDS
from meshphase.validate import as_positive

__all__ = ["ONSET_RESOLUTION", "timing_centre", "centre_shifts", "pass_times", "usable_onsets",
           "conditioned_gap_runs", "gap_intervals_of", "onset_sigma", "channel_noise_spectrum",
           "NOISE_LIKE_RATIO", "gauge_passes"]

#: finest onset timing claimed on noise-free data, as a fraction of the pulse's FWHM [-]
ONSET_RESOLUTION = 1e-4

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


def timing_centre(template: Template) -> float:
    """The point of a template the matched filter follows when the pulse stretches
    [template samples]: the centroid of its squared slope, sum(u h'(u)^2) / sum(h'(u)^2).

    A tooth-root pulse lasts a fixed angle, so at another speed it is the template stretched
    in time by s about the engagement; the correlation peak then moves by (s - 1) times that
    centroid's distance from the engagement (d lag / d s = int u h'^2 / int h'^2, implicit
    differentiation of the correlation maximum). The onset the detector reports is that
    centroid plus a template-fixed (time-fixed) offset, so only the centroid sits at a fixed
    angle of the gauged gear under speed ripple.

    Parameters
    ----------
    template : meshphase.onsets.Template
        With at least two samples.

    Returns
    -------
    float
        The centre [template samples]; the template's peak when it has no slope.
    """
    if not isinstance(template, Template):
        raise TypeError(f"template must be a Template (meshphase.onsets), got {type(template).__name__}")
    h = np.asarray(template.samples, dtype=float)
    if h.ndim != 1 or h.size < 2:
        raise ValueError(f"template.samples must be 1-D with at least 2 samples, got shape {h.shape}")
    d = np.gradient(h)
    e = d * d
    tot = float(e.sum())
    if not tot > 0:
        return float(template.peak)
    return float(np.sum(np.arange(h.size) * e) / tot)


def pass_times(onsets: Onsets) -> np.ndarray:
    """Onset times moved to their template's timing centre [s] (:func:`timing_centre`): a
    fixed angle of the gauged gear whatever the local speed, near the middle of the tooth's
    contact, i.e. the engagement instant, on every gauge alike.

    The move is measured once, on the template learnt from the most pulses, and scaled to
    every other template by their FWHM ratio (:func:`centre_shifts`). Onsets without
    templates, and a shift that would break the increasing order, keep their times.
    """
    on = _as_onsets(onsets)
    if not len(on) or not on.templates:
        return on.times
    shift = centre_shifts(on.templates)
    tid = np.clip(on.template_id, 0, shift.size - 1)
    out = on.times + np.where(on.template_id >= 0, shift[tid], 0.0)
    # keep the order strictly increasing (templates may differ between blocks)
    return out if np.all(np.diff(out) > 0) else on.times


def centre_shifts(templates) -> np.ndarray:
    """Per template: from its onset feature to its timing centre [s] (what
    :func:`pass_times` adds to an onset timed with it).

    The centre is a centroid weighted by the squared slope and by the distance from the
    centre, so a template's own noise moves it many times more than it moves the onsets
    timed with it: on the independent rig's ring gauge (tests/independent) two templates
    learnt from some fifty pulses each put it several times farther apart than their onsets
    of the same pulses, and every pass after the relearn moved by more than the timing
    floor (a step the angle model read as scatter). So the centre is taken from one template, the one
    learnt from the most pulses (its noise is then one constant offset of the gauge's
    passes, which the angle model's per-gauge constant takes up), and carried to the others
    by their FWHM ratio: a pulse lasting a fixed angle stretches as a whole with the speed,
    and a template is re-learnt when the speed changes.

    Parameters
    ----------
    templates : sequence of meshphase.onsets.Template

    Returns
    -------
    ndarray, shape (len(templates),)
        [s]; a template whose FWHM is not a positive finite number keeps its own centre.
    """
    tps = list(templates)
    for tp in tps:
        if not isinstance(tp, Template):
            raise TypeError(f"templates must hold Template objects, got {type(tp).__name__}")
    own = np.array([(timing_centre(tp) - tp.ref) / tp.rate for tp in tps], dtype=float)
    if own.size < 2:
        return own
    fw = np.array([tp.fwhm for tp in tps], dtype=float)
    ok = np.isfinite(fw) & (fw > 0)
    if not ok.any():
        return own
    k = max(np.flatnonzero(ok), key=lambda i: tps[i].n_pulses)
    return np.where(ok, own[k] * fw / fw[k], own)


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
    """Per-onset timing uncertainty [s]: the Cramer-Rao bound for the learnt template at the
    fitted amplitude, in the conditioned channel's noise.

    In white noise of the channel's per-sample RMS (:func:`meshphase.signal.crb.crb_delay_std`,
    Kay 1993 eq. 3.14); the onset tests hold the detector within ~1.1x of it. With its noise
    spectrum (``noise``, :func:`channel_noise_spectrum`) it is the bound in coloured Gaussian
    noise instead (:func:`meshphase.signal.crb.crb_delay_std_psd`, Kay 1993 sec. 3.11): 1/f noise
    under slow pulses (the seed rig's 650-sample pulses, 30 % of the noise power 1/f from
    0.05 Hz) makes it ~4.5x the white bound, and the passes scatter by that much; where it
    gives no finite bound the white one stands. The two agree for white noise (within the
    spectrum estimate's error).

    It never claims better than the detector resolves a noise-free pulse: its sub-sample
    interpolation leaves an error that repeats with the pulse's position on the sample grid,
    ~1e-4 of the pulse's FWHM (noise-free seed rig at 5120 Hz, FWHM 650 samples: 6.6 us sun,
    4.1 us ring RMS; Table 1 at 51.2 kHz, FWHM 34 samples: 0.004 sample), so
    :data:`ONSET_RESOLUTION` times the template's FWHM is a floor.

    Parameters
    ----------
    onsets : meshphase.onsets.Onsets
    noise_rms : float
        RMS of the conditioned channel's noise per sample [data units]; not a positive
        finite float (and no ``noise``): the floor alone.
    noise : NoiseSpectrum, optional
        The channel's noise spectrum [data units^2/Hz].

    Returns
    -------
    ndarray, shape (n,)
        [s]; NaN for an onset without a template (and where the bound is not finite).
    """
    on = _as_onsets(onsets)
    if noise is not None and not isinstance(noise, NoiseSpectrum):
        raise TypeError(f"noise must be a NoiseSpectrum or None, got {type(noise).__name__}")
    out = np.full(len(on), np.nan)
    if not len(on) or not on.templates:
        return out
    tid = np.clip(on.template_id, 0, len(on.templates) - 1)
    has = on.template_id >= 0
    floor = np.array([ONSET_RESOLUTION * tp.fwhm for tp in on.templates])[tid]
    floor = np.where(has, floor, np.nan)
    white = isinstance(noise_rms, float) and math.isfinite(noise_rms) and noise_rms > 0
    if not white and noise is None:
        return floor
    # the bound of each template at unit amplitude [s]
    unit = np.array([_unit_bound(tp, noise_rms if white else float("nan"), noise)
                     for tp in on.templates])
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.where(has, unit[tid], np.nan) / np.abs(on.amplitude)
    out = np.fmax(out, floor)
    return np.where(np.isfinite(out), out, np.nan)


def _unit_bound(tp: Template, noise_rms: float, noise: NoiseSpectrum | None = None) -> float:
    """Cramer-Rao bound [s] of a unit-amplitude pulse of template ``tp``: in the noise
    spectrum ``noise`` when given and finite there, else in white noise of RMS
    ``noise_rms`` per original sample (NaN for a template that is not finite)."""
    d = np.gradient(np.asarray(tp.samples, dtype=float)) * tp.rate   # [1/s], peak 1
    if not np.all(np.isfinite(d)):
        return float("nan")
    if noise is not None:
        b = crb_delay_std_psd(d, tp.rate, noise.freqs, noise.psd, dof=noise.dof)
        if math.isfinite(b):
            return b
    if not (math.isfinite(noise_rms) and noise_rms > 0):
        return float("nan")
    # the template is sampled at fs / decimation: its information sums decimation times over
    return float(crb_delay_std(d, noise_rms)) / math.sqrt(tp.decimation)


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
