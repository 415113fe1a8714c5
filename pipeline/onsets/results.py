"""What onset detection returns: coarse maxima, onsets with their flags and their timing
model (the one result type of every detector, :mod:`meshphase.onsets.detector`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..signal.noise_spectrum import NoiseSpectrum
from .timing import OnsetTiming, TemplateTiming

__all__ = ["CoarsePeaks", "Onsets", "FLAG_GAP", "FLAG_CLIPPED", "FLAG_LOW_CORR",
           "FLAG_EDGE", "FLAG_TEMPLATE", "FLAG_NAMES", "empty_onsets"]

#: The pulse window overlaps (or lies within ``gap_guard`` of) a gap: non-finite samples or
#: a ``gap_runs`` range (a DAQ dropout from the quality report).
FLAG_GAP = 1
#: The pulse window overlaps a flagged run (clipping at a rail or a plateau at any level,
#: from the quality report).
FLAG_CLIPPED = 2
#: Normalised correlation with the template below ``min_corr``.
FLAG_LOW_CORR = 4
#: The pulse window runs past the data, or the correlation peak sits on the search limit.
FLAG_EDGE = 8
#: The block's template is a fallback (learnt from fewer than ``min_template_pulses`` pulses
#: or re-used from an earlier block).
FLAG_TEMPLATE = 16
FLAG_NAMES = {FLAG_GAP: "gap", FLAG_CLIPPED: "clipped", FLAG_LOW_CORR: "low_corr",
              FLAG_EDGE: "edge", FLAG_TEMPLATE: "template"}


@dataclass(frozen=True, eq=False)
class CoarsePeaks:
    """Coarse pulse maxima (:func:`coarse_peaks`).

    Attributes
    ----------
    index : ndarray of int64
        Full-rate sample index of each smoothed maximum (relative to the first sample).
    height : ndarray of float64
        Smoothed height above the median, polarity-corrected [data units].
    threshold : float
        Detection threshold above the median [data units].
    noise : float
        Robust noise level of the smoothed signal [data units].
    decimation : int
        Decimation used [-].
    """

    index: np.ndarray
    height: np.ndarray
    threshold: float
    noise: float
    decimation: int

    def __len__(self) -> int:
        return int(self.index.size)


@dataclass(frozen=True, eq=False)
class Onsets:
    """Engagement onsets of one channel, with per-onset quality and timing: what every onset
    detector returns, and all the passes and the phasing read of it (:attr:`centres`,
    :meth:`sigma`, ``amplitude``, ``width``, ``flags``).

    Attributes
    ----------
    times : ndarray of float64, shape (n,)
        Onset times [s] on the recording's time axis (``t0 + index / fs``), increasing.
    index : ndarray of float64, shape (n,)
        Fractional sample index of each onset, relative to the first sample [samples].
    corr : ndarray of float64, shape (n,)
        Normalised correlation of the pulse with the detector's pulse model [-], in [-1, 1]
        (NaN for a detector without one).
    amplitude : ndarray of float64, shape (n,)
        Fitted tensile peak above baseline, signed, in data units (e.g. strain [m/m]).
    width : ndarray of float64, shape (n,)
        Tensile full width at half maximum measured on the pulse [s] (noisy at low SNR).
    flags : ndarray of uint8, shape (n,)
        Bit mask of ``FLAG_*`` values; 0 for a clean onset.
    template_id : ndarray of int32, shape (n,)
        Index into ``templates`` of the template that timed each onset (matched filter;
        -1 for a detector without templates).
    templates : tuple of Template
        Templates in use, one per analysis block that had pulses (repeated objects when a
        block re-used an earlier one); empty for a detector without templates.
    fs : float
        Sample rate [Hz].
    t0 : float
        Time of sample 0 [s].
    channel : str or None
    reference : str
    level : float
    polarity : int
        Sign of the pulses' main lobe in the data: +1 tensile, -1 compressive, 0 unknown
        (no pulse found).
    timing : OnsetTiming
        The per-onset timing model (:mod:`meshphase.onsets.timing`); default the matched
        filter's, from ``templates``, ``template_id`` and ``amplitude``.
    """

    times: np.ndarray
    index: np.ndarray
    corr: np.ndarray
    amplitude: np.ndarray
    width: np.ndarray
    flags: np.ndarray
    template_id: np.ndarray
    templates: tuple = ()
    fs: float = float("nan")
    t0: float = 0.0
    channel: str | None = None
    reference: str = "rise"
    level: float = 0.5
    polarity: int = 0
    timing: OnsetTiming | None = None

    def __post_init__(self):
        n = self.times.size
        for name in ("index", "corr", "amplitude", "width", "flags", "template_id"):
            if getattr(self, name).shape != (n,):
                raise ValueError(f"Onsets.{name} must have shape ({n},), got {getattr(self, name).shape}")
        if self.timing is None:
            object.__setattr__(self, "timing", TemplateTiming(tuple(self.templates), self.template_id,
                                                              self.amplitude))
        elif not isinstance(self.timing, OnsetTiming):
            raise TypeError(f"Onsets.timing must be an OnsetTiming, got {type(self.timing).__name__}")
        if len(self.timing) != n:
            raise ValueError(f"Onsets.timing describes {len(self.timing)} onsets, not {n}")

    def __len__(self) -> int:
        return int(self.times.size)

    @property
    def good(self) -> np.ndarray:
        """Boolean mask of onsets without any flag."""
        return self.flags == 0

    def has_flag(self, flag: int) -> np.ndarray:
        """Boolean mask of onsets carrying ``flag`` (one of the ``FLAG_*`` values)."""
        return (self.flags & np.uint8(flag)) != 0

    def select(self, mask) -> "Onsets":
        """Onsets where ``mask`` (boolean or integer index array) selects."""
        m = np.asarray(mask)
        return Onsets(self.times[m], self.index[m], self.corr[m], self.amplitude[m],
                      self.width[m], self.flags[m], self.template_id[m], self.templates,
                      self.fs, self.t0, self.channel, self.reference, self.level,
                      self.polarity, self.timing.select(m))

    @property
    def centres(self) -> np.ndarray:
        """Onset times moved to their timing centres [s] (``timing.centre_shifts``): for the
        matched filter a fixed angle of the gauged gear whatever the local speed, near the
        middle of the tooth's contact, i.e. the engagement instant, on every gauge alike
        (:func:`meshphase.onsets.timing.centre_shifts`). Shifts that would break the
        increasing order are not applied: the onset times themselves are returned then, as
        when no onset moves."""
        shift = self.timing.centre_shifts()
        if not np.any(shift):                 # no onset moves (no templates, say)
            return self.times
        out = self.times + shift
        # keep the order strictly increasing (templates may differ between blocks)
        return out if np.all(np.diff(out) > 0) else self.times

    def sigma(self, noise_rms: float, noise: NoiseSpectrum | None = None) -> np.ndarray:
        """Per-onset timing uncertainty [s], shape (n,), in the channel's noise: per-sample
        RMS ``noise_rms`` [data units] and, where the timing model uses it, the noise
        spectrum ``noise`` (see ``timing.sigma``); NaN where unknown."""
        return self.timing.sigma(noise_rms, noise)

    def flag_counts(self) -> dict:
        """Number of onsets carrying each flag, by flag name."""
        return {name: int(np.count_nonzero(self.flags & np.uint8(f))) for f, name in FLAG_NAMES.items()}

    def summary(self) -> dict:
        """Counts and medians, JSON-friendly."""
        def med(a):
            return float(np.median(a)) if a.size else None
        return {"channel": self.channel, "n": len(self), "n_good": int(self.good.sum()),
                "flags": self.flag_counts(), "median_corr": med(self.corr),
                "median_amplitude": med(self.amplitude), "median_width_s": med(self.width),
                "n_templates": len(self.templates), "reference": self.reference,
                "level": self.level}


def empty_onsets(fs, t0, channel, reference, level, templates=(), timing: OnsetTiming | None = None) -> Onsets:
    """:class:`Onsets` with no onset (every array empty) of a channel sampled at ``fs`` [Hz]
    from ``t0`` [s], with the detector's timing ``reference`` and ``level``, its
    ``templates`` and its (empty) ``timing`` model (default the matched filter's): the one
    return type of a detector that found nothing."""
    f = np.empty(0, dtype=np.float64)
    return Onsets(f, f.copy(), f.copy(), f.copy(), f.copy(), np.empty(0, dtype=np.uint8),
                  np.empty(0, dtype=np.int32), tuple(templates), fs, t0, channel, reference, level,
                  0, timing)

