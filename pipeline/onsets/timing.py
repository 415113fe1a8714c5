"""How well each onset is timed, and where its pass is: the timing model a detector's onsets
carry (:class:`OnsetTiming`), and the matched filter's (:class:`TemplateTiming`).

The passes (:mod:`meshphase.kinematics.passes`) need two things of every onset: its timing
centre (a fixed angle of the gauged gear whatever the local speed, so passes of different
gauges compare) and its timing uncertainty in the channel's noise (which weights the pass in
the angle model). The noise is measured by the conditioning, after the detector ran, so a
detector's onsets carry a timing model that turns a noise level into per-onset
uncertainties, rather than the numbers themselves.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from ..signal.crb import crb_delay_std, crb_delay_std_psd
from ..signal.noise_spectrum import NoiseSpectrum
from .template import Template

__all__ = ["OnsetTiming", "TemplateTiming", "ONSET_RESOLUTION", "timing_centre", "centre_shifts",
           "unit_bound"]

#: finest onset timing the matched filter claims on noise-free data, as a fraction of the
#: pulse's FWHM [-]
ONSET_RESOLUTION = 1e-4


@runtime_checkable
class OnsetTiming(Protocol):
    """The per-onset timing of one channel's onsets, as a detector reports it.

    An implementation holds whatever per-onset data it needs (one entry per onset, in the
    onsets' order) and selects it along with the onsets (:meth:`select`).
    """

    def __len__(self) -> int:
        """Onsets described [-]."""

    def centre_shifts(self) -> np.ndarray:
        """Per onset: the time from the reported onset to its timing centre [s] (0 where
        the onset is its own centre), shape (n,)."""

    def sigma(self, noise_rms: float, noise: NoiseSpectrum | None = None) -> np.ndarray:
        """Per-onset timing uncertainty [s], shape (n,), in noise of per-sample RMS
        ``noise_rms`` [data units] (not a positive finite float: unknown) or, where the
        model uses it, of spectrum ``noise``; NaN where unknown."""

    def select(self, mask) -> "OnsetTiming":
        """The timing of the onsets ``mask`` selects (boolean or integer index array)."""


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


def centre_shifts(templates) -> np.ndarray:
    """Per template: from its onset feature to its timing centre [s] (what an onset timed
    with it moves by to its pass time).

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


@dataclass(frozen=True, eq=False)
class TemplateTiming:
    """The matched filter's timing model: every onset timed with one of ``templates`` at
    its fitted ``amplitude``.

    Attributes
    ----------
    templates : tuple of Template
        The templates in use.
    template_id : ndarray of int32, shape (n,)
        Per onset, the index into ``templates`` of the template that timed it (negative:
        none).
    amplitude : ndarray of float64, shape (n,)
        Per onset, the fitted tensile peak above baseline [data units], signed.
    """

    templates: tuple
    template_id: np.ndarray
    amplitude: np.ndarray

    def __post_init__(self):
        if np.shape(self.template_id) != np.shape(self.amplitude) or np.ndim(self.amplitude) != 1:
            raise ValueError(f"template_id and amplitude must be 1-D of one length, got shapes "
                             f"{np.shape(self.template_id)} and {np.shape(self.amplitude)}")

    def __len__(self) -> int:
        return int(np.size(self.amplitude))

    def select(self, mask) -> "TemplateTiming":
        """The timing of the onsets ``mask`` selects."""
        m = np.asarray(mask)
        return TemplateTiming(self.templates, self.template_id[m], self.amplitude[m])

    def centre_shifts(self) -> np.ndarray:
        """Per onset: its template's shift from the onset feature to the timing centre [s]
        (:func:`centre_shifts`); 0 for an onset without a template."""
        if not len(self) or not self.templates:
            return np.zeros(len(self))
        shift = centre_shifts(self.templates)
        tid = np.clip(self.template_id, 0, shift.size - 1)
        return np.where(self.template_id >= 0, shift[tid], 0.0)

    def sigma(self, noise_rms: float, noise: NoiseSpectrum | None = None) -> np.ndarray:
        """Per-onset timing uncertainty [s]: the Cramer-Rao bound for the template at the
        fitted amplitude, in the conditioned channel's noise.

        In white noise of the channel's per-sample RMS (:func:`meshphase.signal.crb.crb_delay_std`,
        Kay 1993 eq. 3.14); the onset tests hold the detector within ~1.1x of it. With its
        noise spectrum (``noise``) it is the bound in coloured Gaussian noise instead
        (:func:`meshphase.signal.crb.crb_delay_std_psd`, Kay 1993 sec. 3.11): 1/f noise under
        slow pulses (the seed rig's 650-sample pulses, 30 % of the noise power 1/f from
        0.05 Hz) makes it ~4.5x the white bound, and the passes scatter by that much; where
        it gives no finite bound the white one stands. The two agree for white noise
        (within the spectrum estimate's error).

        It never claims better than the detector resolves a noise-free pulse: its
        sub-sample interpolation leaves an error that repeats with the pulse's position on
        the sample grid, ~1e-4 of the pulse's FWHM (noise-free seed rig at 5120 Hz, FWHM 650
        samples: 6.6 us sun, 4.1 us ring RMS; Table 1 at 51.2 kHz, FWHM 34 samples: 0.004
        sample), so :data:`ONSET_RESOLUTION` times the template's FWHM is a floor.

        Parameters
        ----------
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
        out = np.full(len(self), np.nan)
        if not len(self) or not self.templates:
            return out
        tid = np.clip(self.template_id, 0, len(self.templates) - 1)
        has = self.template_id >= 0
        floor = np.array([ONSET_RESOLUTION * tp.fwhm for tp in self.templates])[tid]
        floor = np.where(has, floor, np.nan)
        white = isinstance(noise_rms, float) and math.isfinite(noise_rms) and noise_rms > 0
        if not white and noise is None:
            return floor
        # the bound of each template at unit amplitude [s]
        unit = np.array([unit_bound(tp, noise_rms if white else float("nan"), noise)
                         for tp in self.templates])
        with np.errstate(divide="ignore", invalid="ignore"):
            out = np.where(has, unit[tid], np.nan) / np.abs(self.amplitude)
        out = np.fmax(out, floor)
        return np.where(np.isfinite(out), out, np.nan)


def unit_bound(tp: Template, noise_rms: float, noise: NoiseSpectrum | None = None) -> float:
    """Cramer-Rao bound [s] of a unit-amplitude pulse of template ``tp``: in the noise
    spectrum ``noise`` when given and finite there, else in white noise of RMS
    ``noise_rms`` per original sample [data units] (NaN for a template that is not finite,
    or without either noise).

    Parameters
    ----------
    tp : Template
    noise_rms : float
        [data units]
    noise : NoiseSpectrum, optional

    Returns
    -------
    float
        [s]
    """
    if not isinstance(tp, Template):
        raise TypeError(f"tp must be a Template, got {type(tp).__name__}")
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
