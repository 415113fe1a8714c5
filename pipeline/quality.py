"""Array functions for data-quality flags: runs of NaN/inf, clipped runs, gaps.

Numpy in, numpy out; no Recording here (see :meth:`pipeline.Recording.quality`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["find_runs", "nonfinite_runs", "clipped_runs", "channel_quality"]


def find_runs(mask) -> np.ndarray:
    """Start and stop indices of the runs of True in a 1-D boolean mask.

    Parameters
    ----------
    mask : array_like of bool, shape (n,)

    Returns
    -------
    runs : ndarray of int64, shape (n_runs, 2)
        ``[start, stop)`` sample indices of each run, in order; shape (0, 2) when none.
    """
    m = np.asarray(mask, dtype=bool)
    if m.ndim != 1:
        raise ValueError(f"mask must be 1-D, got shape {m.shape}")
    if m.size == 0:
        return np.empty((0, 2), dtype=np.int64)
    d = np.diff(m.view(np.int8), prepend=np.int8(0), append=np.int8(0))
    starts = np.flatnonzero(d == 1)
    stops = np.flatnonzero(d == -1)
    return np.stack([starts, stops], axis=1).astype(np.int64)


def nonfinite_runs(x) -> np.ndarray:
    """Runs of NaN or +-inf samples in a 1-D array, as ``[start, stop)`` rows."""
    x = np.asarray(x)
    if x.ndim != 1:
        raise ValueError(f"x must be 1-D, got shape {x.shape}")
    return find_runs(~np.isfinite(x))


def clipped_runs(x, *, min_run: int = 3, rtol: float = 0.0) -> np.ndarray:
    """Runs of at least ``min_run`` consecutive samples sitting at the channel's extreme value.

    A converter that saturates holds its full-scale value; a run of identical samples equal to
    the channel maximum (or minimum) is flagged. ``rtol`` widens "equal" relative to the
    channel range.

    Returns
    -------
    runs : ndarray of int64, shape (n_runs, 2)
    """
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 1:
        raise ValueError(f"x must be 1-D, got shape {x.shape}")
    if min_run < 2:
        raise ValueError(f"min_run must be >= 2, got {min_run!r}")
    finite = np.isfinite(x)
    if not finite.any():
        return np.empty((0, 2), dtype=np.int64)
    hi = np.max(x[finite])
    lo = np.min(x[finite])
    if hi == lo:
        return np.empty((0, 2), dtype=np.int64)
    tol = rtol * (hi - lo)
    at_rail = (x >= hi - tol) | (x <= lo + tol)
    runs = find_runs(at_rail)
    return runs[(runs[:, 1] - runs[:, 0]) >= min_run]


def channel_quality(x) -> dict:
    """Summary of one channel: counts and runs of non-finite and clipped samples, range.

    Returns
    -------
    dict
        ``n_samples``, ``n_nonfinite``, ``nonfinite_runs`` (list of [start, stop)),
        ``longest_nonfinite_run``, ``n_clipped_runs``, ``clipped_runs``, ``min``, ``max``,
        ``rms`` (of finite samples; NaN when none is finite).
    """
    x = np.asarray(x)
    nf = nonfinite_runs(x)
    cl = clipped_runs(x)
    finite = x[np.isfinite(x)]
    return {
        "n_samples": int(x.size),
        "n_nonfinite": int((nf[:, 1] - nf[:, 0]).sum()),
        "nonfinite_runs": nf.tolist(),
        "longest_nonfinite_run": int((nf[:, 1] - nf[:, 0]).max()) if len(nf) else 0,
        "n_clipped_runs": int(len(cl)),
        "clipped_runs": cl.tolist(),
        "min": float(finite.min()) if finite.size else float("nan"),
        "max": float(finite.max()) if finite.size else float("nan"),
        "rms": float(np.sqrt(np.mean(np.square(finite, dtype=np.float64)))) if finite.size else float("nan"),
    }
