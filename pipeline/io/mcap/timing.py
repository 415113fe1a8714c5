"""Time stamps of messages holding samples -> one uniform sample grid (sample rate and the
time of the first sample), or a clear error when the stamps are not uniform."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["Grid", "fit_grid"]


class Grid(NamedTuple):
    """A uniform sample grid fitted to message stamps."""

    fs: float  # sample rate [Hz]
    origin_ns: int  # time of the first sample [ns], on the stamps' clock
    n_samples: int
    max_residual: float  # largest |stamp - grid time| of a message's first sample [s]


def fit_grid(stamps_ns, counts, *, fs: float | None = None, max_jitter: float | None = None,
             what: str = "topic") -> Grid:
    """Fit ``t = origin + sample_index / fs`` to the stamps of consecutive messages.

    Message k holds ``counts[k]`` consecutive samples, the first at ``stamps_ns[k]``; sample
    indexes run on from message to message (``s_k = counts[0] + ... + counts[k-1]``).

    Parameters
    ----------
    stamps_ns : array of int, shape (m,)
        Stamp of each message's first sample [ns], in message order.
    counts : array of int, shape (m,)
        Samples per message [-] (all 1 for a scalar per message).
    fs : float, optional
        Sample rate [Hz]; derived from the stamps (least squares) when None (needs two
        messages).
    max_jitter : float, optional
        Largest allowed distance of a stamp from the fitted grid [s]; half a sample period
        when None.
    what : str
        Named in error messages.

    Returns
    -------
    Grid

    Raises
    ------
    ValueError
        No messages, one message and no ``fs``, stamps that do not advance, or stamps off a
        uniform grid by more than ``max_jitter`` (lost messages, jitter, a varying rate):
        the message names the worst message, its distance and the range of sample spacings
        the stamps imply.
    """
    t = np.asarray(stamps_ns, dtype=np.int64)
    c = np.asarray(counts, dtype=np.int64)
    if t.ndim != 1 or t.shape != c.shape:
        raise ValueError(f"{what}: stamps and counts must be 1-D of one length, got {t.shape} and {c.shape}")
    if t.size == 0:
        raise ValueError(f"{what}: no messages, so no samples")
    if np.any(c < 0):
        raise ValueError(f"{what}: negative sample counts")
    n = int(c.sum())
    if n == 0:
        raise ValueError(f"{what}: the messages hold no samples (empty arrays)")
    s = np.concatenate(([0], np.cumsum(c)[:-1])).astype(np.float64)
    d = (t - t[0]).astype(np.float64) * 1e-9  # [s] from the first stamp
    if fs is None:
        if t.size < 2 or s[-1] == 0:
            raise ValueError(f"{what}: one message with samples cannot give a sample rate; "
                             f"give fs (the sample rate [Hz])")
        ds = s - s.mean()
        slope = float(np.dot(ds, d - d.mean()) / np.dot(ds, ds))
        if not slope > 0:
            raise ValueError(f"{what}: the stamps do not advance ({_steps(d, c)}); they cannot "
                             f"give a sample rate")
        fs = 1.0 / slope
    fs = float(fs)
    if not (np.isfinite(fs) and fs > 0):
        raise ValueError(f"fs must be finite and > 0, got {fs!r}")
    tol = 0.5 / fs if max_jitter is None else float(max_jitter)
    if not (np.isfinite(tol) and tol >= 0):
        raise ValueError(f"max_jitter must be finite and >= 0 [s], got {max_jitter!r}")
    b = float(np.mean(d - s / fs))
    r = d - (b + s / fs)
    k = int(np.argmax(np.abs(r))) if r.size else 0
    worst = float(abs(r[k])) if r.size else 0.0
    if worst > tol:
        raise ValueError(
            f"{what}: timestamps are irregular: message {k} (stamp {int(t[k])} ns) is "
            f"{worst * 1e3:.6g} ms off a uniform grid of fs = {fs:.10g} Hz (allowed: "
            f"{tol * 1e3:.6g} ms = max_jitter); {_steps(d, c)}. Lost or late messages, "
            f"receive-time jitter or a varying rate: map a header stamp field (stamp=...), "
            f"raise max_jitter, or resample the data first")
    return Grid(fs=fs, origin_ns=int(t[0]) + int(round(b * 1e9)), n_samples=n, max_residual=worst)


def _steps(d: np.ndarray, c: np.ndarray) -> str:
    """The range of sample spacings the stamps imply, as text."""
    if d.size < 2:
        return "one message"
    with np.errstate(divide="ignore", invalid="ignore"):
        per = np.diff(d) / np.where(c[:-1] > 0, c[:-1], 1)
    return (f"sample spacing from the stamps ranges {per.min() * 1e3:.6g} .. {per.max() * 1e3:.6g} ms "
            f"over {d.size} messages")
