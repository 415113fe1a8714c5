"""Block filters: the one interface of every conditioning step, and a channel's chain of them.

A block filter takes a signal of known length in consecutive blocks: ``push(block)``
returns the output that is final so far (possibly nothing, possibly more than the block
when look-ahead was waiting), ``flush()`` the rest once the signal has ended; the outputs
joined are the step's output for the whole signal, whatever the blocks. The steps:
:class:`meshphase.signal.zero_phase.ZeroPhase` (band limit, hum notches, the high-pass
drift removal), :class:`meshphase.signal.drift.DriftFilter` and :class:`Identity`; the
:class:`meshphase.signal.snr.SnrTap` watches the samples between two of them.
:func:`run_whole` pushes a whole signal through one (the whole-array functions of
:mod:`meshphase.signal.condition` are that), :class:`ConditioningChain` strings a channel's
steps together and :func:`push_chains` advances one or two chains by a block.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from .zero_phase import ZeroPhase, push_pair

__all__ = ["BlockFilter", "Identity", "ConditioningChain", "run_whole", "push_chains"]


class BlockFilter(Protocol):
    """What every conditioning step offers."""

    def push(self, x: np.ndarray) -> np.ndarray:
        """The next samples; returns the output final so far."""

    def flush(self) -> np.ndarray:
        """The output not yet returned, once the signal has ended."""


class Identity:
    """The block filter that passes every sample on at once (a step left out)."""

    def push(self, x: np.ndarray) -> np.ndarray:
        """``x`` itself."""
        return x

    def flush(self) -> np.ndarray:
        """Nothing: nothing is held."""
        return np.empty(0)


def run_whole(filt: BlockFilter, x: np.ndarray) -> np.ndarray:
    """The output of block filter ``filt`` for the whole signal ``x`` pushed at once."""
    y = filt.push(x)
    tail = filt.flush()
    return np.concatenate([y, tail]) if tail.size else y


class ConditioningChain:
    """A channel's conditioning: dropouts to NaN -> notch -> drift -> (SNR tap) -> band
    limit, each step a block filter; :func:`push_chains` pushes one or two chains and
    returns the newly final conditioned samples.

    Parameters
    ----------
    n : int
        Samples of the channel [-].
    dropouts : ndarray of int, shape (k, 2), or None
        ``[start, stop)`` runs set to NaN before anything else.
    notch : ZeroPhase or None
        Hum notches.
    drift : block filter
        Drift removal (:class:`Identity` for none).
    snr : SnrTap
        Sees the drift-free samples.
    band : ZeroPhase or None
        Band limit.
    dtype : numpy dtype
        Sample type of the recording: a float32 recording holds each step's result as
        float32 (as the whole-array path does, writing every step back into the
        recording's array), and the samples between the steps stay float32 arrays (half
        the bytes to hold and move; each filter reads them into its float64 window, the
        same numbers as the float64 copies of float32 values it held before).
    """

    def __init__(self, n: int, *, dropouts: np.ndarray | None, notch: ZeroPhase | None,
                 drift, snr, band: ZeroPhase | None, dtype=np.float64):
        self.n = n
        self.dropouts = dropouts if dropouts is not None and len(dropouts) else None
        self.notch, self.drift, self.snr, self.band = notch, drift, snr, band
        self.pos = 0
        self.round = np.dtype(dtype) == np.float32

    def _rounded(self, x: np.ndarray) -> np.ndarray:
        """A step's float64 result rounded to float32 on a float32 recording (kept as
        float32: the values the float64 copy of the rounded samples holds)."""
        return x.astype(np.float32) if self.round and x.size else x

    def _mask(self, x: np.ndarray) -> np.ndarray:
        if self.dropouts is None:
            return x
        a, b = self.pos, self.pos + x.size
        r = self.dropouts
        i = np.searchsorted(r[:, 1], a, side="right")
        j = np.searchsorted(r[:, 0], b, side="left")
        if j > i:
            x = x.copy()
            for s0, s1 in r[i:j]:
                x[max(s0, a) - a:min(s1, b) - a] = np.nan
        return x


def _live(st) -> bool:
    return not (st is None or isinstance(st, Identity))


def _stage(sts, xs: list, finals: list) -> list:
    """One stage of one or two chains (``sts``: that stage of each, None where a chain has
    none) pushed their samples ``xs``, flushed where the chain is final; the outputs (the
    input where a chain has no such stage). Two filters go through
    :func:`meshphase.signal.zero_phase.push_pair`."""
    out = list(xs)
    live = [i for i, st in enumerate(sts) if _live(st)]
    if (len(live) == 2 and all(isinstance(sts[i], ZeroPhase) and xs[i].size for i in live)):
        out[0], out[1] = push_pair(sts[0], xs[0], sts[1], xs[1])
    else:
        for i in live:
            out[i] = sts[i].push(xs[i]) if xs[i].size else np.empty(0)
    for i in live:
        if finals[i]:
            tail = sts[i].flush()
            out[i] = np.concatenate([out[i], tail]) if tail.size else out[i]
    return out


def push_chains(chains, xs) -> list:
    """Each of ``chains`` (one, or two filtered side by side:
    :func:`meshphase.signal.zero_phase.push_pair`) pushed its next samples ``xs``; the newly
    final conditioned samples of each."""
    xs = [c._mask(x) for c, x in zip(chains, xs)]
    for c, x in zip(chains, xs):
        c.pos += x.size
    finals = [c.pos >= c.n for c in chains]
    for attr in ("notch", "drift"):
        sts = [getattr(c, attr) for c in chains]
        ys = _stage(sts, xs, finals)
        xs = [c._rounded(y) if _live(st) else y for c, st, y in zip(chains, sts, ys)]
    for c, x in zip(chains, xs):
        if x.size:
            # the tap's differences are float64 arithmetic (float32 samples widened, exactly)
            c.snr.add(x if x.dtype == np.float64 else x.astype(np.float64))
    sts = [c.band for c in chains]
    ys = _stage(sts, xs, finals)
    return [c._rounded(y) if _live(st) else y for c, st, y in zip(chains, sts, ys)]
