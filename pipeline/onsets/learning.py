"""Template learning: the pulse shape averaged from a recording's own clean pulses, and the
pulse width estimate that sizes it.

Step 3 of the pipeline (see :mod:`meshphase.onsets`): windows around the coarse maxima,
aligned to sub-sample precision against the running template (Fourier shifts) and averaged
with least-squares amplitude weights; baseline 0, tensile peak 1, tapered. Its peak and
level crossings come from :mod:`meshphase.onsets.features`.
"""

from __future__ import annotations

import math

import numpy as np

from ..runtime.lazy import fft as sfft
from ..signal.spectral import tukey
from ..validate import as_choice, as_float, as_positive, as_positive_int, as_signal
from .coarse import coarse_decimated, decimate, decimation_for, fill_nan
from .features import template_features
from .matched import gather_windows, Matcher, sublags, window_baseline
from .template import Template

__all__ = ["learn_template", "estimate_pulse_width", "half_length", "learn_decimated", "refine_width",
           "width_autocorr"]

_HALF_LENGTH = 3.0           # template half-length [FWHM]
_TAPER = 0.2                 # Tukey taper fraction of the template
_AUTOCORR_TO_FWHM = 1.6      # FWHM ~ 1.6 x lag where the autocorrelation halves (raised cosine)
_WIDTH_SAMPLES = 1 << 20     # samples entering the width estimate


def half_length(w_d: float) -> int:
    """Template half-length [samples] for pulses ``w_d`` samples wide (FWHM): 3 FWHM, >= 4."""
    return max(4, int(math.ceil(_HALF_LENGTH * w_d)))


def _normalise(h: np.ndarray) -> np.ndarray | None:
    e = max(1, h.size // 10)
    base = 0.5 * (h[:e].mean() + h[-e:].mean())
    h = h - base
    top = h.max()
    if not top > 0:
        return None
    return (h / top) * tukey(h.size, _TAPER)


def _frac_advance(w: np.ndarray, frac: np.ndarray) -> np.ndarray:
    """Rows advanced by ``frac`` samples, ``out_i[t] = w_i(t + frac_i)`` (band-limited).

    A straight line through each row's end points is removed before the FFT and restored
    after (shifted exactly), so the circular transform sees no jump at the ends.
    """
    n = w.shape[1]
    t = np.arange(n, dtype=np.float64)
    slope = (w[:, -1] - w[:, 0]) / max(n - 1, 1)
    line = w[:, :1] + slope[:, None] * t[None, :]
    r = w - line
    p = sfft.next_fast_len(2 * n)
    spec = sfft.rfft(r, p, axis=1)
    f = np.arange(spec.shape[1]) / p
    out = sfft.irfft(spec * np.exp(2j * np.pi * f[None, :] * frac[:, None]), p, axis=1)[:, :n]
    return out + line + slope[:, None] * frac[:, None]


def learn_decimated(yd: np.ndarray, peaks: np.ndarray, *, fs: float, d: int, w_d: float,
                    reference: str, level: float, polarity: int, max_pulses: int, n_align: int,
                    min_corr: float, max_half: int | None = None) -> Template | None:
    """Learn a template from decimated data ``yd`` around coarse maxima ``peaks``.

    The template spans +-3 FWHM, but never more than half the usual distance between
    pulses (``max_half`` [decimated samples]): a template reaching into the neighbouring
    pulses (planets a few mesh periods apart) learns their tails and times every pulse
    worse (five planets, sun gauge: 1.6x the Cramer-Rao bound before the cap, 1.2x after)."""
    h_half = half_length(w_d)
    if max_half is not None:
        h_half = max(4, min(h_half, int(max_half)))
    k = int(math.ceil(0.5 * w_d)) + 2
    L = 2 * h_half + 1
    start = peaks - h_half - k
    ok = (start >= 0) & (start + L + 2 * k <= yd.size)
    peaks = peaks[ok]
    if peaks.size == 0:
        return None
    if peaks.size > max_pulses:
        peaks = peaks[np.round(np.linspace(0, peaks.size - 1, max_pulses)).astype(np.int64)]
    w, _ = gather_windows(yd, peaks - h_half - k, L + 2 * k)
    w = w - window_baseline(w)[:, None]
    c0 = w[:, k:k + L]
    centre = slice(max(0, h_half - int(w_d)), h_half + int(w_d) + 1)
    a0 = c0[:, centre].max(axis=1)
    if not np.any(a0 > 0):
        return None
    h = _normalise((a0[:, None] * c0).sum(axis=0) / float(a0 @ a0))
    if h is None:
        return None
    u = sublags(w_d)
    n_used = peaks.size
    for _ in range(n_align):
        tpl = Template(h, fs, d, float(h_half), float(h_half), float("nan"))
        mt = Matcher(tpl, k, u)
        lag, cmax, ncc, edge, _, _ = mt.match(w)
        use = (~edge) & (ncc >= min_corr) & (cmax > 0)
        if not use.any():
            return None
        lag, amp = lag[use], cmax[use] / mt.e0
        pos = k + lag                                    # window position of template sample 0
        q = np.floor(pos).astype(np.int64)
        fr = pos - q
        # integer part by gathering, fraction by band-limited advance
        idx = q[:, None] + np.arange(-2, L + 2)[None, :]
        idx = np.clip(idx, 0, w.shape[1] - 1)
        rows = np.take_along_axis(w[use], idx, axis=1)
        al = _frac_advance(rows, fr)[:, 2:2 + L]
        al = al - window_baseline(al)[:, None]
        h_new = _normalise((amp[:, None] * al).sum(axis=0) / float(amp @ amp))
        if h_new is None:
            return None
        h = h_new
        n_used = int(use.sum())
    peak, ref, fwhm = template_features(h, reference, level)
    if not (np.isfinite(peak) and np.isfinite(ref) and np.isfinite(fwhm)):
        return None
    return Template(h, fs, d, peak, ref, fwhm * d / fs, reference, level, n_used, polarity)


def width_autocorr(x: np.ndarray) -> float:
    """Tensile FWHM estimate [samples] from the autocorrelation half-lag.

    The autocorrelation of the (median-removed) signal is evaluated at geometrically spaced
    lags only (one dot product each), and the first lag where it falls below half its
    lag-1 value (lag 0 carries the noise) is interpolated in log-lag. Scaled by 1.6 to the
    FWHM of a raised-cosine pulse; only a starting value for the template-based refinement.
    """
    x = x[:_WIDTH_SAMPLES]
    n = x.size
    if n < 8:
        return 2.0
    step = max(1, n >> 16)
    z = x - float(np.median(x[::step]))
    lags = np.unique(np.round(np.geomspace(1, max(2, n // 4), 48)).astype(np.int64))
    # one dot product per lag, in order, up to the first below half of lag 1's (the only
    # one used): ~12 of the 48 for pulses tens of samples wide
    r = [float(z[:n - lags[0]] @ z[lags[0]:])]
    if not r[0] > 0:
        return 2.0
    j = 0
    for j in range(1, lags.size):
        k = int(lags[j])
        r.append(float(z[:n - k] @ z[k:]))
        if r[-1] < 0.5 * r[0]:
            break
    else:
        return float(max(2.0, _AUTOCORR_TO_FWHM * lags[-1]))
    l0, l1 = math.log(lags[j - 1]), math.log(lags[j])
    fr = (r[j - 1] - 0.5 * r[0]) / (r[j - 1] - r[j])
    return float(max(2.0, _AUTOCORR_TO_FWHM * math.exp(l0 + fr * (l1 - l0))))


def refine_width(seg: np.ndarray, fs: float, w0: float, k_sigma: float, pol: int,
                 decimation: int | None = None) -> tuple[float, Template | None]:
    """Up to three rounds of coarse detection + template learning to pin the FWHM [samples]."""
    w = w0
    tpl = None
    for _ in range(3):
        d = decimation or decimation_for(w)
        yd = decimate(seg, d)
        peaks, *_ = coarse_decimated(yd, w / d, 2.0 * w / d, k_sigma)
        t = learn_decimated(yd, peaks, fs=fs, d=d, w_d=w / d, reference="peak", level=0.5,
                            polarity=pol, max_pulses=128, n_align=1, min_corr=0.3)
        if t is None:
            break
        tpl = t
        w_new = t.fwhm * fs
        done = 0.8 < w_new / w < 1.25
        w = w_new
        if done:
            break
    return float(w), tpl


def estimate_pulse_width(x, fs: float, *, polarity: str = "positive") -> float:
    """Estimate the tensile full width at half maximum of the pulses in ``x`` [s].

    Parameters
    ----------
    x : array_like, shape (n,)
        Conditioned samples of one channel; NaN allowed (bridged by the median).
    fs : float
        Sample rate [Hz].
    polarity : {"positive", "negative"}
        Sign of the tensile peak in ``x``.

    Returns
    -------
    float
        FWHM [s]: the autocorrelation half-lag (first 2**20 samples) scaled to a raised-cosine
        pulse, then refined by the FWHM of a template learnt on those samples (up to three
        rounds). ``2 / fs`` when no pulse structure is found.
    """
    x = as_signal(x)
    fs = as_positive(fs, "fs")
    pol = 1 if as_choice(polarity, "polarity", ("positive", "negative")) == "positive" else -1
    if x.size == 0:
        return 2.0 / fs
    seg = x[:_WIDTH_SAMPLES] * pol
    seg = fill_nan(seg)
    w, _ = refine_width(seg, fs, width_autocorr(seg), 5.0, pol)
    return w / fs


def learn_template(x, fs: float, coarse_idx, *, width: float | None = None,
                   decimation: int | None = None, reference: str = "rise", level: float = 0.5,
                   polarity: str = "positive", max_pulses: int = 256, n_align: int = 2,
                   min_corr: float = 0.5) -> Template:
    """Learn a pulse template from the pulses around ``coarse_idx``.

    Parameters
    ----------
    x : array_like, shape (n,)
        Conditioned samples [data units].
    fs : float
        Sample rate [Hz].
    coarse_idx : array_like of int
        Approximate sample indices of pulse maxima (e.g. ``coarse_peaks(...).index``).
    width : float, optional
        Tensile FWHM [s]; estimated when None.
    decimation : int, optional
        Block-mean decimation (default from the width).
    reference, level
        Onset feature (see :func:`detect_onsets`).
    polarity : {"positive", "negative"}
    max_pulses : int
        At most this many pulses (evenly spread) are averaged.
    n_align : int
        Sub-sample alignment iterations.
    min_corr : float
        Pulses correlating worse with the running template are left out [-].

    Returns
    -------
    Template

    Raises
    ------
    ValueError
        When ``coarse_idx`` is empty or no usable pulse (full window inside ``x``, positive
        correlation) is found.
    """
    arr = as_signal(x)
    fs = as_positive(fs, "fs")
    idx = np.asarray(coarse_idx)
    if idx.dtype.kind not in "iu":
        raise TypeError(f"coarse_idx must be integer sample indices, got dtype {idx.dtype}")
    idx = idx.ravel().astype(np.int64)
    if idx.size == 0:
        raise ValueError("coarse_idx is empty: no pulse to learn a template from")
    reference = as_choice(reference, "reference", ("rise", "peak"))
    level = as_float(level, "level")
    if not 0.0 <= level < 1.0:
        raise ValueError(f"level must be in [0, 1), got {level!r}")
    pol = 1 if as_choice(polarity, "polarity", ("positive", "negative")) == "positive" else -1
    seg = fill_nan(arr.astype(np.float64, copy=False))
    if pol < 0:
        seg = -seg
    w = as_positive(width, "width") * fs if width is not None else refine_width(
        seg, fs, width_autocorr(seg), 5.0, pol, decimation)[0]
    d = decimation_for(w) if decimation is None else as_positive_int(decimation, "decimation")
    yd = decimate(seg, d)
    tpl = learn_decimated(yd, np.sort(idx) // d, fs=fs, d=d, w_d=w / d, reference=reference,
                          level=level, polarity=pol, max_pulses=as_positive_int(max_pulses, "max_pulses"),
                          n_align=as_positive_int(n_align, "n_align"), min_corr=as_float(min_corr, "min_corr"))
    if tpl is None:
        raise ValueError(f"no usable pulse among the {idx.size} coarse indices (windows outside the "
                         "data, or no positive correlation)")
    return tpl

