"""The median of finite samples by one single-pivot partition.

``np.median`` partitions around the middle element (two of them for an even count) and the
last one too, which it checks for NaN, and its generic reduction machinery costs on top.
Where the samples are known to be finite (first differences filtered by ``np.isfinite``, the
finite samples of a channel, the onset detector's decimated blocks), one partition around
the middle suffices, with the value ``np.median`` gives. ``meshphase bench processing``
times both on 2 min of a pulse train (the ``np.median`` and ``median_of_finite`` rows of its
throughput table): 1.9, 2.2 and 3.0x faster in three runs of the stop that wrote this.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["MAD_TO_SIGMA", "median_of_finite", "median_and_mad", "sigma_of_differences"]

#: 1 / Phi^-1(3/4): the median absolute deviation of Gaussian samples over their sigma [-]
MAD_TO_SIGMA = 1.482602218505602


def median_of_finite(a: np.ndarray):
    """``np.median(a)`` of a finite, non-empty array, for less.

    Parameters
    ----------
    a : numpy.ndarray
        Finite samples [any unit], of any shape (taken flat, as ``np.median`` without an
        axis). Not checked for NaN: with a NaN the result is meaningless (``np.median``
        gives NaN).

    Returns
    -------
    numpy.floating
        The middle value, or the mean of the two middle values of an even count [unit of
        ``a``], of ``np.median``'s dtype and value (to the sign of a zero, which neither
        orders). float32 and float64 samples take the single partition (the lower middle
        value is the maximum of the part below the upper one); other dtypes (integers,
        float16), whose mean ``np.median`` takes in a wider type, go to ``np.median``.

    Raises
    ------
    ValueError
        When ``a`` is empty.
    """
    a = np.ravel(a)
    n = a.size
    if n == 0:
        raise ValueError("median of an empty array")
    if a.dtype not in (np.float64, np.float32):
        return np.median(a)
    k = n >> 1
    p = np.partition(a, k)
    if n & 1:
        return p[k]
    return (p[:k].max() + p[k]) / 2


def median_and_mad(a: np.ndarray):
    """(median, median absolute deviation from it) of a finite, non-empty array, both by
    :func:`median_of_finite` (``np.median``'s values and dtype); ``MAD_TO_SIGMA * mad`` is
    the robust standard deviation of Gaussian samples [unit of ``a``]."""
    med = median_of_finite(a)
    return med, median_of_finite(np.abs(a - med))


def sigma_of_differences(d: np.ndarray):
    """The robust sigma of white noise from its first differences ``d`` (finite, non-empty):
    ``MAD_TO_SIGMA`` times their median absolute deviation, over sqrt(2) (a difference of
    two samples has sqrt(2) times their sigma) [unit of ``d``]."""
    return MAD_TO_SIGMA * median_and_mad(d)[1] / math.sqrt(2.0)
