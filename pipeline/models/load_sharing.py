"""Planet load sharing from ring-gear root strains (spec section 6).

Source: Ligata, Kahraman & Singh, J. Mech. Des. 130 (2008) 041701. A gauge at the root of
one ring tooth sees one strain pulse per planet pass; the peak of the pulse planet n
produces is proportional to the load that planet carries, so the load-sharing factor of
planet n is its peak strain relative to the mean peak,

    LS_n = N eps_n / sum_i eps_i        (1 = equal sharing; sum_n LS_n = N).
"""

from __future__ import annotations

import warnings

import numpy as np

from ..errors import DataQualityWarning
from ..validate import as_choice, as_int

__all__ = ["load_sharing"]

_NAN_POLICIES = ("raise", "omit")


def load_sharing(peak_strains, axis: int = -1, nan_policy: str = "raise") -> np.ndarray:
    """Planet load-sharing factors LS_n = N eps_n / sum_i eps_i (spec 6).

    Parameters
    ----------
    peak_strains : array_like
        Peak root strain each planet produces at the gauged ring tooth [m/m], as magnitudes
        (>= 0); planets along ``axis``, anything else (passes, gauges, runs) on the other axes.
    axis : int
        Planet axis.
    nan_policy : {"raise", "omit"}
        "raise": any NaN is a ValueError. "omit": a NaN planet (a pass that could not be
        measured) is left out of that slice: N counts the finite planets only, its factor is
        NaN, and a DataQualityWarning says how many were left out. Infinities always raise.

    Returns
    -------
    ndarray
        Load-sharing factors [-], same shape as ``peak_strains`` (empty in, empty out).

    Raises
    ------
    ValueError
        Negative or infinite strains, NaN with nan_policy="raise", a slice whose strains are all
        zero (no load to share) or, with "omit", all NaN.
    TypeError
        Non-numeric input.

    Notes
    -----
    Normalising by the slice mean makes the factor independent of the gauge's calibration
    gain and of the applied torque; it assumes the same gain for every planet's pulse, which
    holds because one gauge sees all planets. Summing to N is the invariant to check.
    """
    if isinstance(peak_strains, (str, bytes)):
        raise TypeError(f"peak_strains must be numeric array_like, got {peak_strains!r}")
    try:
        eps = np.asarray(peak_strains, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"peak_strains must be numeric array_like, got {peak_strains!r}") from exc
    policy = as_choice(nan_policy, "nan_policy", _NAN_POLICIES)
    ax = as_int(axis, "axis")
    if eps.ndim == 0:
        raise ValueError("peak_strains must have at least one dimension (the planet axis), "
                         f"got a scalar {float(eps)!r}")
    if not -eps.ndim <= ax < eps.ndim:
        raise ValueError(f"axis {ax} is out of range for peak_strains with {eps.ndim} dimension(s)")
    if eps.size == 0:
        return np.zeros(eps.shape)
    if np.any(np.isinf(eps)):
        raise ValueError(f"peak_strains must not be infinite, got {int(np.isinf(eps).sum())} "
                         "infinite value(s)")
    nan = np.isnan(eps)
    if nan.any():
        if policy == "raise":
            raise ValueError(f"peak_strains has {int(nan.sum())} NaN value(s); pass "
                             "nan_policy='omit' to leave those planets out")
        warnings.warn(f"load_sharing: {int(nan.sum())} NaN peak strain(s) left out; their "
                      "factors are NaN and N counts the finite planets of each slice",
                      DataQualityWarning, stacklevel=2)
    if np.any(eps[~nan] < 0):
        raise ValueError(f"peak_strains must be >= 0 (magnitudes of the peaks), got min "
                         f"{float(np.min(eps[~nan]))!r}")
    n = np.sum(~nan, axis=ax, keepdims=True)
    total = np.sum(np.where(nan, 0.0, eps), axis=ax, keepdims=True)
    if np.any(n == 0):
        raise ValueError(f"{int(np.sum(n == 0))} slice(s) of peak_strains along axis {ax} hold "
                         "no finite value")
    if np.any(total <= 0):
        raise ValueError(f"{int(np.sum(total <= 0))} slice(s) of peak_strains along axis {ax} "
                         "are all zero: no load to share")
    return np.where(nan, np.nan, n * np.where(nan, 0.0, eps) / total)
