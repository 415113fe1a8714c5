"""Sample runs ``[start, stop)``: gaps and flagged stretches, merged, tested against pulse
windows and onset positions."""

from __future__ import annotations

import numpy as np

from ..signal.condition import ChannelQuality, merge_runs

__all__ = ["runs_overlap", "inside_runs", "check_runs", "time_runs", "quality_options"]


def runs_overlap(a: np.ndarray, b: np.ndarray, runs: np.ndarray) -> np.ndarray:
    """For intervals [a, b): does any of the sorted, disjoint ``runs`` overlap it?"""
    if len(runs) == 0 or a.size == 0:
        return np.zeros(a.size, dtype=bool)
    j = np.searchsorted(runs[:, 0], b, side="left") - 1
    ok = j >= 0
    out = np.zeros(a.size, dtype=bool)
    out[ok] = runs[j[ok], 1] > a[ok]
    return out


def inside_runs(x: np.ndarray, runs: np.ndarray) -> np.ndarray:
    """Is the (fractional) position ``x`` inside one of the sorted, disjoint ``runs``?"""
    if len(runs) == 0 or x.size == 0:
        return np.zeros(x.size, dtype=bool)
    j = np.searchsorted(runs[:, 0], x, side="right") - 1
    ok = j >= 0
    out = np.zeros(x.size, dtype=bool)
    out[ok] = x[ok] < runs[j[ok], 1]
    return out


def check_runs(runs, name: str) -> np.ndarray:
    """``[start, stop)`` integer rows, merged; (0, 2) for None."""
    if runs is None:
        return np.empty((0, 2), dtype=np.int64)
    r = np.asarray(runs)
    if r.dtype.kind not in "iu" or r.ndim != 2 or r.shape[1] != 2:
        raise ValueError(f"{name} must be an integer array of [start, stop) rows, got "
                         f"dtype {r.dtype}, shape {r.shape}")
    return merge_runs(r)


def time_runs(times, name: str, fs: float, t0: float) -> np.ndarray | None:
    """``[t_start, t_stop)`` rows [s] as sample runs ``[ceil((t-t0) fs), ...)`` (None: None)."""
    if times is None:
        return None
    ft = np.asarray(times, dtype=np.float64).reshape(-1, 2)
    if ft.size and not np.all(np.isfinite(ft)):
        raise ValueError(f"{name} must be finite")
    return np.ceil((ft - t0) * fs - 1e-6).astype(np.int64)



def quality_options(quality: ChannelQuality, n_samples: int, fs: float) -> dict:
    """The detector options a channel's quality report gives (:mod:`meshphase.signal.condition`):
    its clipped runs flagged (``flag_runs``), its ``settle`` time as ``gap_guard`` [s] and,
    when it has any, its dropout runs as gaps (``gap_runs``).

    Parameters
    ----------
    quality : ChannelQuality
        The report of the channel the onsets are detected on.
    n_samples : int
        Samples of that channel [-].
    fs : float
        Its sample rate [Hz].

    Returns
    -------
    dict
        ``flag_runs``, ``gap_guard`` and (with dropouts) ``gap_runs``.

    Raises
    ------
    TypeError
        ``quality`` is not a ChannelQuality.
    ValueError
        The report describes another number of samples or another sample rate.
    """
    if not isinstance(quality, ChannelQuality):
        raise TypeError(f"quality must be a ChannelQuality, got {type(quality).__name__}")
    if quality.n_samples != n_samples or quality.fs != fs:
        raise ValueError(f"quality report ({quality.n_samples} samples at {quality.fs} Hz) does "
                         f"not describe this recording ({n_samples} samples at {fs} Hz)")
    out = {"flag_runs": quality.clipped_runs, "gap_guard": quality.settle}
    if len(quality.dropout_runs):
        out["gap_runs"] = quality.dropout_runs
    return out
