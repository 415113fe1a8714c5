"""The few spectral tools the processing uses: the Tukey window, Welch's power spectral
density and FFT resampling (:func:`scipy.signal.windows.tukey`,
:func:`scipy.signal.welch`, :func:`scipy.signal.resample`).

Restated here so that ``meshphase process`` does not import ``scipy.signal`` (which imports
``scipy.stats``; see :mod:`meshphase.signal.sos_design`). :func:`tukey` and :func:`resample` are
scipy's arithmetic; :func:`welch` is the textbook estimate (segments, detrending, periodic
Hann window, one-sided density scaling, mean over segments), which scipy 1.17 computes
through ``ShortTimeFFT`` in another order: all equal scipy's to rounding
(tests/processing/test_dsp_designs.py: 1e-13 of the scale, 1e-12 for Welch). Frequencies in hertz, densities in data units
squared per hertz.
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

from ..runtime.lazy import fft as sfft
__all__ = ["tukey", "welch", "resample"]


def _check_length(m, name: str) -> int:
    if isinstance(m, bool) or not isinstance(m, (int, np.integer)) or m < 0:
        raise ValueError(f"{name} must be a non-negative integer, got {m!r}")
    return int(m)


def tukey(m: int, alpha: float = 0.5) -> np.ndarray:
    """Symmetric Tukey (tapered cosine) window: ``scipy.signal.windows.tukey(m, alpha)``.

    Parameters
    ----------
    m : int
        Points (>= 0).
    alpha : float
        Fraction of the window inside the cosine tapers [-]: 0 is rectangular, 1 is Hann.

    Returns
    -------
    ndarray of float64, shape (m,)

    Raises
    ------
    ValueError
        A negative or non-integer ``m``, a non-finite ``alpha``.
    """
    m = _check_length(m, "m")
    alpha = float(alpha)
    if not math.isfinite(alpha):
        raise ValueError(f"alpha must be finite, got {alpha!r}")
    if m <= 1 or alpha <= 0:
        return np.ones(m)
    if alpha >= 1.0:
        return _hann_sym(m)
    n = np.arange(0, m, dtype=np.float64)
    width = int(math.floor(alpha * (m - 1) / 2.0))
    n1, n2, n3 = n[0:width + 1], n[width + 1:m - width - 1], n[m - width - 1:]
    w1 = 0.5 * (1 + np.cos(np.pi * (-1 + 2.0 * n1 / alpha / (m - 1))))
    w3 = 0.5 * (1 + np.cos(np.pi * (-2.0 / alpha + 1 + 2.0 * n3 / alpha / (m - 1))))
    return np.concatenate((w1, np.ones(n2.shape), w3))


def _hann_sym(m: int) -> np.ndarray:
    """Symmetric Hann window of ``m`` points, as scipy's general cosine computes it."""
    if m <= 1:
        return np.ones(m)
    fac = np.linspace(-np.pi, np.pi, m)
    w = np.zeros(m)
    for k, a in enumerate((0.5, 0.5)):
        w += a * np.cos(k * fac)
    return w


def _hann_periodic(m: int) -> np.ndarray:
    """Periodic Hann window (the DFT-even one Welch's estimate uses) of ``m`` points."""
    if m <= 1:
        return np.ones(m)
    return _hann_sym(m + 1)[:-1]


def welch(x, fs: float, nperseg: int, *, noverlap: int | None = None,
          detrend: str | Callable = "constant") -> tuple[np.ndarray, np.ndarray]:
    """One-sided power spectral density by Welch's method: ``scipy.signal.welch(x, fs,
    nperseg=nperseg, noverlap=noverlap, detrend=detrend)`` with its defaults otherwise
    (periodic Hann window, ``scaling="density"``, ``average="mean"``).

    Parameters
    ----------
    x : array_like, shape (n,)
        Real samples [any unit]; n >= ``nperseg``.
    fs : float
        Sample rate [Hz].
    nperseg : int
        Samples per segment (>= 1).
    noverlap : int, optional
        Samples shared by consecutive segments (0 <= noverlap < nperseg); default half a
        segment.
    detrend : {"constant", False} or callable
        Remove each segment's mean, nothing, or apply the callable to the
        ``(n_segments, nperseg)`` array of segments (it returns the detrended array).

    Returns
    -------
    f : ndarray, shape (nperseg // 2 + 1,)
        Frequencies [Hz].
    pxx : ndarray, shape (nperseg // 2 + 1,)
        Density [unit^2/Hz].

    Raises
    ------
    ValueError
        ``x`` not 1-D or shorter than a segment, bad ``fs``, ``nperseg``, ``noverlap`` or
        ``detrend``.
    """
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 1:
        raise ValueError(f"x must be 1-D, got shape {x.shape}")
    fs = float(fs)
    if not (fs > 0 and math.isfinite(fs)):
        raise ValueError(f"fs must be a positive, finite sample rate [Hz], got {fs!r}")
    nperseg = _check_length(nperseg, "nperseg")
    if nperseg < 1 or x.size < nperseg:
        raise ValueError(f"nperseg must be >= 1 and at most the samples ({x.size}), got {nperseg}")
    noverlap = nperseg // 2 if noverlap is None else _check_length(noverlap, "noverlap")
    if noverlap >= nperseg:
        raise ValueError(f"noverlap ({noverlap}) must be below nperseg ({nperseg})")
    if detrend == "constant":
        def detrend(seg):
            return seg - seg.mean(axis=-1, keepdims=True)
    elif detrend is False:
        def detrend(seg):
            return seg
    elif not callable(detrend):
        raise ValueError(f"detrend must be 'constant', False or a callable, got {detrend!r}")
    step = nperseg - noverlap
    seg = np.lib.stride_tricks.sliding_window_view(x, nperseg)[::step]
    win = _hann_periodic(nperseg)
    spec = sfft.rfft(win * detrend(seg), n=nperseg, axis=-1)
    p = (spec.real ** 2 + spec.imag ** 2).mean(axis=0) / (fs * (win * win).sum())
    p[1:-1 if nperseg % 2 == 0 else None] *= 2
    return sfft.rfftfreq(nperseg, 1.0 / fs), p


def resample(x, num: int) -> np.ndarray:
    """``x`` resampled to ``num`` samples by its Fourier series: ``scipy.signal.resample(x,
    num)`` for real samples (periodic extension: the ends should come to rest).

    Parameters
    ----------
    x : array_like, shape (n,)
        Real samples [any unit], n >= 1.
    num : int
        Samples wanted (>= 1).

    Returns
    -------
    ndarray of float64, shape (num,)

    Raises
    ------
    ValueError
        ``x`` not 1-D, empty or complex; ``num`` not a positive integer.
    """
    x = np.asarray(x)
    if x.ndim != 1 or x.size == 0 or np.iscomplexobj(x):
        raise ValueError(f"x must be 1-D, real and non-empty, got shape {x.shape}, dtype {x.dtype}")
    num = _check_length(num, "num")
    if num < 1:
        raise ValueError(f"num must be >= 1, got {num}")
    n = x.shape[0]
    m = min(num, n)
    spec = sfft.rfft(x)[:m // 2 + 1]
    if m % 2 == 0 and num != n:
        spec[m // 2] *= 2 if num < n else 0.5
    return sfft.irfft(spec / (n / num), n=num, overwrite_x=True)
