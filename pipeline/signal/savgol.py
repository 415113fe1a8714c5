"""Savitzky-Golay smoothing: :func:`scipy.signal.savgol_coeffs` and
:func:`scipy.signal.savgol_filter` (``mode="interp"``, no derivative) for 1-d data.

Restated here so that ``meshphase process`` does not import ``scipy.signal`` (which imports
``scipy.stats``; see :mod:`meshphase.signal.sos_design`). The arithmetic is scipy's step for step
(the same least-squares solver, :func:`scipy.linalg.lstsq`, the same convolution,
:func:`scipy.ndimage.convolve1d`, the same scaled polynomial fits of the ends), so the
results are scipy's to rounding (tests/processing/test_dsp_designs.py: 1e-13 of the data's
scale, as another LAPACK build may order its sums differently).
"""

from __future__ import annotations

import functools

import numpy as np

from ..runtime.lazy import linalg, ndimage
__all__ = ["savgol_coeffs", "savgol_coeffs_cached", "savgol_filter"]


def _check(window_length, polyorder) -> tuple[int, int]:
    for name, v in (("window_length", window_length), ("polyorder", polyorder)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
            raise ValueError(f"{name} must be an integer, got {v!r}")
    window_length, polyorder = int(window_length), int(polyorder)
    if window_length < 1:
        raise ValueError(f"window_length must be >= 1, got {window_length}")
    if not 0 <= polyorder < window_length:
        raise ValueError(f"polyorder must be >= 0 and below window_length ({window_length}), "
                         f"got {polyorder}")
    return window_length, polyorder


def savgol_coeffs(window_length: int, polyorder: int) -> np.ndarray:
    """Convolution coefficients of the least-squares polynomial smoother.

    Parameters
    ----------
    window_length : int
        Samples in the window (>= 1); an even length centres between two samples.
    polyorder : int
        Degree of the local polynomial, below ``window_length``.

    Returns
    -------
    ndarray of float64, shape (window_length,)
        For :func:`scipy.ndimage.convolve1d`; they sum to 1.

    Raises
    ------
    ValueError
        A non-integer or out-of-range ``window_length`` or ``polyorder``.
    """
    window_length, polyorder = _check(window_length, polyorder)
    halflen, rem = divmod(window_length, 2)
    pos = halflen if rem else halflen - 0.5
    x = np.arange(-pos, window_length - pos, dtype=np.float64)[::-1]
    a = x ** np.arange(polyorder + 1, dtype=np.float64).reshape(-1, 1)
    y = np.zeros(polyorder + 1)
    y[0] = 1.0
    return linalg.lstsq(a, y, cond=np.finfo(np.float64).eps * max(a.shape))[0]


@functools.lru_cache(maxsize=64)
def savgol_coeffs_cached(window_length: int, polyorder: int) -> np.ndarray:
    """:func:`savgol_coeffs`, computed once per (``window_length``, ``polyorder``) and
    returned read-only (the streamed drift baseline and the onsets' template features ask
    for the same few windows block after block).

    Raises
    ------
    ValueError
        As :func:`savgol_coeffs` (nothing is cached then).
    """
    c = savgol_coeffs(window_length, polyorder)
    c.flags.writeable = False
    return c


def _fit_edge(x: np.ndarray, y: np.ndarray, start: int, stop: int, i0: int, i1: int,
              polyorder: int) -> None:
    """``y[i0:i1]`` from the polynomial fitted to ``x[start:stop]`` (columns scaled to unit
    norm before the solve, as :func:`numpy.polyfit` and scipy do)."""
    t = np.arange(0, stop - start, dtype=x.dtype)
    lhs = t[:, None] ** np.arange(polyorder + 1, dtype=t.dtype)[::-1][None, :]
    scale = np.sqrt(np.sum(lhs * lhs, axis=0))
    lhs /= scale
    c = linalg.lstsq(lhs, x[start:stop].reshape(-1, 1), cond=t.shape[0] * np.finfo(t.dtype).eps)[0]
    c = (c.T / scale).T
    i = np.arange(i0 - start, i1 - start, dtype=c.dtype).reshape(-1, 1)
    v = np.zeros_like(i)
    for j in range(c.shape[0]):
        v = v * i + c[j, ...]
    y[i0:i1] = v.reshape(-1)


def savgol_filter(x, window_length: int, polyorder: int) -> np.ndarray:
    """Smoothed ``x``: ``scipy.signal.savgol_filter(x, window_length, polyorder)``.

    Inside, the convolution with :func:`savgol_coeffs`; in the ``window_length // 2``
    samples at each end, the polynomial fitted to the first (last) ``window_length``
    samples, evaluated there (scipy's ``mode="interp"``).

    Parameters
    ----------
    x : array_like, shape (n,)
        Samples [any unit]; float32 stays float32, anything else becomes float64.
    window_length : int
        Odd or even window (>= 1, <= n) [samples].
    polyorder : int
        Degree of the local polynomial, below ``window_length``.

    Returns
    -------
    ndarray, shape (n,)

    Raises
    ------
    ValueError
        ``x`` not 1-D, ``window_length`` longer than ``x``, bad ``window_length`` or
        ``polyorder``.
    """
    window_length, polyorder = _check(window_length, polyorder)
    x = np.asarray(x)
    if x.dtype not in (np.float64, np.float32):
        x = x.astype(np.float64)
    if x.ndim != 1:
        raise ValueError(f"x must be 1-D, got shape {x.shape}")
    n = x.shape[0]
    if window_length > n:
        raise ValueError(f"window_length ({window_length}) must not exceed the samples ({n})")
    y = ndimage.convolve1d(x, savgol_coeffs_cached(window_length, polyorder), mode="constant")
    half = window_length // 2
    _fit_edge(x, y, 0, window_length, 0, half, polyorder)
    _fit_edge(x, y, n - window_length, n, n - half, n, polyorder)
    return y
