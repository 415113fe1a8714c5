"""What onset detection returns: the pulse template, coarse maxima, onsets and their flags."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Template", "CoarsePeaks", "Onsets", "FLAG_GAP", "FLAG_CLIPPED", "FLAG_LOW_CORR",
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
class Template:
    """A pulse template learnt from a recording (or given).

    Attributes
    ----------
    samples : ndarray of float64, shape (L,)
        Pulse shape at the decimated rate ``fs / decimation``, baseline 0, tensile peak 1,
        polarity-corrected (tension positive), Tukey-tapered at its ends.
    fs : float
        Sample rate of the recording [Hz].
    decimation : int
        Block-mean decimation factor D of the template samples [-].
    peak : float
        Position of the tensile maximum [template samples].
    ref : float
        Position of the onset feature [template samples].
    fwhm : float
        Full width at half maximum of the tensile lobe [s].
    reference : str
        "rise" or "peak" (see :mod:`meshphase.onsets`).
    level : float
        Level of the "rise" feature, fraction of the peak height [-].
    n_pulses : int
        Pulses averaged [-].
    polarity : int
        +1 when tension reads positive in the data, -1 otherwise.
    """

    samples: np.ndarray
    fs: float
    decimation: int
    peak: float
    ref: float
    fwhm: float
    reference: str = "rise"
    level: float = 0.5
    n_pulses: int = 0
    polarity: int = 1

    @property
    def rate(self) -> float:
        """Sample rate of the template samples, fs / decimation [Hz]."""
        return self.fs / self.decimation

    @property
    def ref_after_peak(self) -> float:
        """Time from the tensile peak to the onset feature [s] (negative for "rise")."""
        return (self.ref - self.peak) / self.rate

    def to_dict(self) -> dict:
        """JSON-friendly dict."""
        return {"samples": self.samples.tolist(), "fs": self.fs, "decimation": self.decimation,
                "peak": self.peak, "ref": self.ref, "fwhm": self.fwhm,
                "reference": self.reference, "level": self.level, "n_pulses": self.n_pulses,
                "polarity": self.polarity}


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
    """Engagement onsets of one channel, with per-onset quality.

    Attributes
    ----------
    times : ndarray of float64, shape (n,)
        Onset times [s] on the recording's time axis (``t0 + index / fs``), increasing.
    index : ndarray of float64, shape (n,)
        Fractional sample index of each onset, relative to the first sample [samples].
    corr : ndarray of float64, shape (n,)
        Normalised correlation of the pulse with the template [-], in [-1, 1].
    amplitude : ndarray of float64, shape (n,)
        Fitted tensile peak above baseline, signed, in data units (e.g. strain [m/m]).
    width : ndarray of float64, shape (n,)
        Tensile full width at half maximum measured on the pulse [s] (noisy at low SNR).
    flags : ndarray of uint8, shape (n,)
        Bit mask of ``FLAG_*`` values; 0 for a clean onset.
    template_id : ndarray of int32, shape (n,)
        Index into ``templates`` of the template that timed each onset.
    templates : tuple of Template
        Templates in use, one per analysis block that had pulses (repeated objects when a
        block re-used an earlier one).
    fs : float
        Sample rate [Hz].
    t0 : float
        Time of sample 0 [s].
    channel : str or None
    reference : str
    level : float
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

    def __post_init__(self):
        n = self.times.size
        for name in ("index", "corr", "amplitude", "width", "flags", "template_id"):
            if getattr(self, name).shape != (n,):
                raise ValueError(f"Onsets.{name} must have shape ({n},), got {getattr(self, name).shape}")

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
                      self.fs, self.t0, self.channel, self.reference, self.level)

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


def empty_onsets(fs, t0, channel, reference, level, templates=()) -> Onsets:
    """:class:`Onsets` with no onset (every array empty) of a channel sampled at ``fs`` [Hz]
    from ``t0`` [s], with the detector's timing ``reference`` and ``level`` and its
    ``templates``: the one return type of a detector that found nothing."""
    f = np.empty(0, dtype=np.float64)
    return Onsets(f, f.copy(), f.copy(), f.copy(), f.copy(), np.empty(0, dtype=np.uint8),
                  np.empty(0, dtype=np.int32), tuple(templates), fs, t0, channel, reference, level)

