"""The pulse template of the matched-filter detector: its samples at the decimated rate and
the features measured on them (peak, onset feature, width)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Template"]


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
