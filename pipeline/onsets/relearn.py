"""When a learnt template is kept for the next analysis block (``relearn="auto"``).

A template is learnt once per operating point and reused while the pulses still fit it.
Two checks, both on what a block measures anyway:

- **Speed**, before refining: the block's pulse period (coarse maxima, see
  :func:`pulse_period`) against the period of the block the template was learnt in. A pulse
  train at a speed changed by the fraction ``f`` is the template stretched by ``f``, which
  would move the onset feature by about ``f`` times its distance from the pulse centre
  (the larger of ``|ref - peak|`` and half the FWHM). The template is kept while that shift
  stays below ``SHIFT_TOL`` (0.1) of the per-pulse timing bound measured when it was
  learnt, so re-use costs at most a tenth of the timing jitter.
- **Shape**, after refining: the median normalised correlation of the block's unflagged
  pulses may fall below the one measured when the template was learnt by at most
  ``max(NCC_ABS, NCC_REL * (1 - ncc_learnt))`` (0.01, half the misfit: a 10 % load swing
  lowers the SNR enough to move it by a quarter); else the
  block is re-learnt and refined again (a load step that lowers the SNR re-learns too,
  which costs time only).

The timing bound comes from the template and the correlations alone (no noise level
needed): for a window of ``L`` samples, NCC ``c`` and template ``h`` (zero-mean energy
``e0``), the residual noise per sample is ``a^2 e0 (1 - c^2) / (c^2 (L - 2))`` (``a`` the
amplitude), so the Cramer-Rao bound ``sigma / (a sqrt(sum h'^2))`` is
``D sqrt(e0 (1 - c^2) / ((L - 2) c^2 sum h'^2))`` full-rate samples (``D`` the
decimation), independent of the amplitude.

A steady run therefore learns once; a ramp re-learns whenever the speed has moved the
onset by a tenth of its jitter. ``relearn="block"`` (learn in every block) is kept for
comparison, ``relearn="never"`` learns once whatever happens.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..signal.median import median_of_finite
from .template import Template

__all__ = ["TemplateFit", "good_median", "pulse_period", "timing_bound", "SHIFT_TOL", "NCC_ABS",
           "NCC_REL"]

SHIFT_TOL = 0.1      # allowed onset shift from a speed change [timing bounds]
NCC_ABS = 0.01       # allowed drop of the median NCC [-], at least ...
NCC_REL = 0.5        # ... or this fraction of the learnt misfit 1 - NCC


def pulse_period(peaks: np.ndarray) -> float | None:
    """Mean pulse period of a block [decimated samples] from its coarse maxima: the
    least-squares slope of their positions against their period count, each interval
    counted as its nearest multiple of the median interval (a missed pulse counts twice);
    None with fewer than 8 maxima."""
    if peaks.size < 8:
        return None
    dif = np.diff(peaks).astype(np.float64)
    med = float(median_of_finite(dif))
    if not med > 0:
        return None
    c = np.concatenate([[0.0], np.cumsum(np.rint(dif / med))])
    c -= c.mean()
    den = float(c @ c)
    return float(c @ (peaks - peaks.mean())) / den if den > 0 else None


def good_median(ncc: np.ndarray, flags: np.ndarray) -> float:
    """Median NCC of the unflagged pulses (of all when fewer than 3 are unflagged)."""
    good = ncc[flags == 0]
    a = good if good.size >= 3 else ncc
    return float(median_of_finite(a)) if a.size and np.isfinite(a).all() else float(np.median(a))


def timing_bound(tpl: Template, ncc: float) -> float:
    """Per-pulse timing bound [full-rate samples] of pulses correlating ``ncc`` with ``tpl``
    (see the module notes); inf for ``ncc <= 0``, 0 for ``ncc >= 1``."""
    h = tpl.samples
    if not ncc > 0:
        return math.inf
    h0 = h - h.mean()
    e0 = float(h0 @ h0)
    g = float(np.sum(np.gradient(h) ** 2))
    c = min(float(ncc), 1.0)
    if not (g > 0 and h.size > 2):
        return math.inf
    return tpl.decimation * math.sqrt(e0 * (1.0 - c * c) / ((h.size - 2) * c * c * g))


@dataclass(frozen=True)
class TemplateFit:
    """How a learnt template fitted its block: median NCC, pulse period [decimated
    samples] and the largest relative speed change it tolerates [-]."""

    ncc: float
    period: float | None
    speed_tol: float

    @classmethod
    def measure(cls, tpl: Template, ncc: np.ndarray, flags: np.ndarray, period: float | None):
        c = good_median(ncc, flags)
        lever = max(abs(tpl.ref - tpl.peak), 0.5 * tpl.fwhm * tpl.fs / tpl.decimation)
        lever *= tpl.decimation                                   # [full-rate samples]
        tol = SHIFT_TOL * timing_bound(tpl, c) / lever if lever > 0 else 0.0
        return cls(c, period, tol)

    def speed_holds(self, period: float | None) -> bool:
        """Is the block's period within the tolerated change? (Unknown: left to the shape
        check when the template's own period is unknown too, else no.)"""
        if period is None or self.period is None:
            return period is None and self.period is None
        return abs(period / self.period - 1.0) <= self.speed_tol

    def holds(self, ncc: np.ndarray, flags: np.ndarray) -> bool:
        """Do the refined pulses still fit (median NCC within the allowed drop)?"""
        return good_median(ncc, flags) >= self.ncc - max(NCC_ABS, NCC_REL * (1.0 - self.ncc))
