"""Runs of samples: ``[start, stop)`` index rows of a boolean mask or of equal samples,
whole arrays and fed in consecutive pieces alike, and their set algebra (merge, containment).

Numpy in, numpy out. The pieces' forms (:class:`RunTracker`, :class:`EqualRuns`) give the
runs of the whole array whatever the pieces.
"""

from __future__ import annotations

import numpy as np

__all__ = ["find_runs", "nonfinite_runs", "merge_runs", "outside_runs", "equal_runs",
           "RunTracker", "EqualRuns", "as_samples", "as_count"]


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


def merge_runs(runs) -> np.ndarray:
    """Sort ``[start, stop)`` rows and merge overlapping or touching ones.

    Parameters
    ----------
    runs : array_like of int, shape (k, 2)
        ``[start, stop)`` sample indices [-], in any order.

    Returns
    -------
    ndarray of int64, shape (m, 2)
        Sorted, disjoint, non-touching rows; shape (0, 2) when ``runs`` is empty.
    """
    r = np.asarray(runs)
    if r.size and r.dtype.kind not in "iuf":
        raise TypeError(f"runs must be integer [start, stop) rows, got dtype {r.dtype}")
    if r.size and (r.ndim != 2 or r.shape[1] != 2):
        raise ValueError(f"runs must have shape (k, 2), got {r.shape}")
    r = r.astype(np.int64).reshape(-1, 2)
    if len(r) == 0:
        return np.empty((0, 2), dtype=np.int64)
    r = r[np.argsort(r[:, 0], kind="stable")]
    ends = np.maximum.accumulate(r[:, 1])
    new = np.ones(len(r), dtype=bool)
    new[1:] = r[1:, 0] > ends[:-1]
    starts = r[new, 0]
    stops = np.maximum.reduceat(r[:, 1], np.flatnonzero(new))
    return np.stack([starts, stops], axis=1)


def _as_runs(runs, name: str) -> np.ndarray:
    r = np.asarray(runs)
    if r.size == 0:
        return np.empty((0, 2), dtype=np.int64)
    if r.dtype.kind not in "iu":
        raise TypeError(f"{name} must be integer [start, stop) rows, got dtype {r.dtype}")
    if r.ndim != 2 or r.shape[1] != 2:
        raise ValueError(f"{name} must have shape (k, 2), got {r.shape}")
    return r.astype(np.int64)


def outside_runs(runs, cover) -> np.ndarray:
    """The rows of ``runs`` not contained in one row of ``cover`` (both ``[start, stop)``;
    ``cover`` sorted and disjoint), e.g. rail runs that are really dropouts at the rail."""
    r, c = _as_runs(runs, "runs"), _as_runs(cover, "cover")
    if len(r) == 0 or len(c) == 0:
        return r
    j = np.searchsorted(c[:, 0], r[:, 0], side="right") - 1
    inside = (j >= 0) & (r[:, 1] <= c[np.maximum(j, 0), 1])
    return r[~inside]


def as_samples(x, name: str = "x") -> np.ndarray:
    """``x`` as a 1-D float64 array (numeric or boolean input; TypeError, ValueError
    otherwise); NaN/inf kept."""
    arr = np.asarray(x)
    if arr.dtype.kind not in "fiub":
        raise TypeError(f"{name} must be a numeric array, got dtype {arr.dtype}")
    if arr.ndim != 1:
        raise ValueError(f"{name} must be 1-D, got shape {arr.shape}")
    return arr.astype(np.float64, copy=False)


def as_count(value, name: str, lowest: int) -> int:
    """``value`` as an int of at least ``lowest`` (TypeError for a bool or non-integer,
    ValueError below ``lowest``; ``name`` in messages)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be an integer, got {type(value).__name__} {value!r}")
    if int(value) < lowest:
        raise ValueError(f"{name} must be >= {lowest}, got {value!r}")
    return int(value)


def _equal_pairs(x: np.ndarray) -> np.ndarray:
    """Indices ``i`` with ``x[i+1] == x[i]``, both finite (``inf == inf`` excluded)."""
    if x.size < 2:
        return np.empty(0, dtype=np.int64)
    eq = x[1:] == x[:-1]
    idx = np.flatnonzero(eq)
    if idx.size:
        idx = idx[np.isfinite(x[idx])]
    return idx


def _runs_from_pairs(idx: np.ndarray) -> np.ndarray:
    """Sample runs ``[start, stop)`` from sorted equal-pair indices (pair i joins i, i+1)."""
    if idx.size == 0:
        return np.empty((0, 2), dtype=np.int64)
    new = np.ones(idx.size, dtype=bool)
    new[1:] = np.diff(idx) > 1
    starts = idx[new]
    last = np.ones(idx.size, dtype=bool)
    last[:-1] = new[1:]
    stops = idx[last] + 2
    return np.stack([starts, stops], axis=1).astype(np.int64)


def equal_runs(x, *, min_run: int = 2) -> np.ndarray:
    """Runs of at least ``min_run`` consecutive, exactly equal, finite samples.

    Parameters
    ----------
    x : array_like, shape (n,)
        Samples [any unit]; NaN/inf break runs.
    min_run : int
        Shortest run reported [samples], >= 2.

    Returns
    -------
    runs : ndarray of int64, shape (k, 2)
        ``[start, stop)`` of each maximal run, in order.
    """
    x = as_samples(x)
    min_run = as_count(min_run, "min_run", 2)
    runs = _runs_from_pairs(_equal_pairs(x))
    return runs[(runs[:, 1] - runs[:, 0]) >= min_run]


class RunTracker:
    """Runs of True of a boolean mask fed in consecutive pieces, merged across pieces
    (:func:`find_runs` of the whole mask): :meth:`add` the next piece, :meth:`runs` the
    ``[start, stop)`` rows so far."""

    def __init__(self):
        self.done: list[np.ndarray] = []
        self.open: int | None = None      # start of a run that touches the last piece's end
        self.n = 0

    def add(self, mask: np.ndarray) -> None:
        """The next piece of the boolean mask."""
        m = mask.size
        if m == 0:
            return
        if not mask.any():
            if self.open is not None:
                self.done.append(np.array([[self.open, self.n]], dtype=np.int64))
                self.open = None
            self.n += m
            return
        r = find_runs(mask) + self.n
        if self.open is not None:
            if r[0, 0] == self.n:
                r[0, 0] = self.open
            else:
                self.done.append(np.array([[self.open, self.n]], dtype=np.int64))
            self.open = None
        if r[-1, 1] == self.n + m:
            self.open = int(r[-1, 0])
            r = r[:-1]
        if len(r):
            self.done.append(r)
        self.n += m

    def skip(self, m: int) -> None:
        """The next piece: ``m`` samples all False (what :meth:`add` of such a mask does)."""
        if m <= 0:
            return
        if self.open is not None:
            self.done.append(np.array([[self.open, self.n]], dtype=np.int64))
            self.open = None
        self.n += int(m)

    def runs(self) -> np.ndarray:
        """The runs of every piece fed, shape (k, 2)."""
        out = list(self.done)
        if self.open is not None:
            out.append(np.array([[self.open, self.n]], dtype=np.int64))
        return np.concatenate(out).astype(np.int64) if out else np.empty((0, 2), dtype=np.int64)


class EqualRuns:
    """Maximal runs of equal finite samples (>= 2) of a channel fed in consecutive pieces."""

    def __init__(self):
        self.n = 0
        self.last = None                   # last sample of the previous piece
        self.open: tuple | None = None     # (start, value) of a run touching that sample
        self.n_pairs = 0

    def add(self, x: np.ndarray):
        """Feed the next piece; returns (starts, stops, values) of the runs it completed."""
        m = x.size
        if m == 0:
            return np.empty(0, np.int64), np.empty(0, np.int64), np.empty(0)
        pos = self.n
        idx = _equal_pairs(x) + pos                       # pairs (i, i + 1) inside the piece
        if self.last is not None and self.last == x[0] and np.isfinite(self.last):
            idx = np.concatenate(([pos - 1], idx))        # the pair across the boundary
        self.n_pairs += idx.size
        runs = _runs_from_pairs(idx)
        starts, stops = runs[:, 0], runs[:, 1]
        values = x[np.maximum(starts - pos, 0)]
        if starts.size and starts[0] == pos - 1:
            values[0] = self.last
        if self.open is not None:
            a0, v0 = self.open
            if starts.size and starts[0] == pos - 1:
                starts[0] = a0
            else:
                starts = np.concatenate(([a0], starts))
                stops = np.concatenate(([pos], stops))
                values = np.concatenate(([v0], values))
            self.open = None
        end = pos + m
        if starts.size and stops[-1] == end:
            self.open = (int(starts[-1]), values[-1])
            starts, stops, values = starts[:-1], stops[:-1], values[:-1]
        self.n = end
        self.last = x[-1]
        return starts, stops, values

    def finish(self):
        """(starts, stops, values) of the run still open at the end (if any)."""
        if self.open is None:
            return np.empty(0, np.int64), np.empty(0, np.int64), np.empty(0)
        a0, v0 = self.open
        self.open = None
        return np.array([a0], np.int64), np.array([self.n], np.int64), np.array([v0])
