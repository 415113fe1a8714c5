"""Sample runs ``[start, stop)``: gaps and flagged stretches, merged, tested against pulse
windows and onset positions."""

from __future__ import annotations

import numpy as np

from meshphase.signal.condition import merge_runs

__all__: list[str] = []


def _runs_overlap(a: np.ndarray, b: np.ndarray, runs: np.ndarray) -> np.ndarray:
    """For intervals [a, b): does any of the sorted, disjoint ``runs`` overlap it?"""
    if len(runs) == 0 or a.size == 0:
        return np.zeros(a.size, dtype=bool)
    j = np.searchsorted(runs[:, 0], b, side="left") - 1
    ok = j >= 0
    out = np.zeros(a.size, dtype=bool)
    out[ok] = runs[j[ok], 1] > a[ok]
    return out


def _inside_runs(x: np.ndarray, runs: np.ndarray) -> np.ndarray:
    """Is the (fractional) position ``x`` inside one of the sorted, disjoint ``runs``?"""
    if len(runs) == 0 or x.size == 0:
        return np.zeros(x.size, dtype=bool)
    j = np.searchsorted(runs[:, 0], x, side="right") - 1
    ok = j >= 0
    out = np.zeros(x.size, dtype=bool)
    out[ok] = x[ok] < runs[j[ok], 1]
    return out


def _check_runs(runs, name: str) -> np.ndarray:
    """``[start, stop)`` integer rows, merged; (0, 2) for None."""
    if runs is None:
        return np.empty((0, 2), dtype=np.int64)
    r = np.asarray(runs)
    if r.dtype.kind not in "iu" or r.ndim != 2 or r.shape[1] != 2:
        raise ValueError(f"{name} must be an integer array of [start, stop) rows, got "
                         f"dtype {r.dtype}, shape {r.shape}")
    return merge_runs(r)


def _time_runs(times, name: str, fs: float, t0: float) -> np.ndarray | None:
    """``[t_start, t_stop)`` rows [s] as sample runs ``[ceil((t-t0) fs), ...)`` (None: None)."""
    if times is None:
        return None
    ft = np.asarray(times, dtype=np.float64).reshape(-1, 2)
    if ft.size and not np.all(np.isfinite(ft)):
        raise ValueError(f"{name} must be finite")
    return np.ceil((ft - t0) * fs - 1e-6).astype(np.int64)

