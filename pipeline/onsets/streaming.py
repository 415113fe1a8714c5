"""Onsets of a stream: samples or recording blocks fed one after another, in bounded
memory, with the same result as :func:`~meshphase.onsets.detect_onsets` on the whole."""

from __future__ import annotations

import warnings
from typing import Iterable

import numpy as np

from ..errors import DataQualityWarning
from ..recording import Recording
from ..validate import as_signal
from .engine import BlockEngine
from .options import check_options
from .results import Onsets, empty_onsets
from .runs import time_runs

__all__ = ["OnsetStream", "detect_onsets_stream"]


class OnsetStream:
    """:func:`detect_onsets` on samples fed in consecutive chunks, in bounded memory: the
    matched-filter detector (:class:`meshphase.onsets.detector.OnsetDetector`, registered as
    ``"matched"``).

    Parameters
    ----------
    fs : float
        Sample rate [Hz].
    **kwargs
        As :func:`detect_onsets` (``t0``, ``mesh_freq``, ``flag_runs``, ``gap_runs``,
        ``gap_guard``, ``channel``...), runs in samples from the first sample fed.

    Notes
    -----
    :meth:`feed` keeps references to the arrays it is given (no copy): do not change them
    afterwards. The result of :meth:`finish` is identical to :func:`detect_onsets` on the
    concatenated samples, however they are chunked; about two analysis blocks (2**20
    samples each by default) are held at a time.
    """

    def __init__(self, fs: float, **kwargs):
        self._eng = BlockEngine(check_options(fs, **kwargs))
        self._done = False

    @property
    def n_samples(self) -> int:
        """Samples fed so far [-]."""
        return self._eng.n_fed

    @property
    def block_samples(self) -> int:
        """The analysis block [samples] as estimated from the options before any sample:
        the ``block`` option, or 16 pulse widths from ``mesh_freq`` when that is longer
        (about two blocks are held at a time)."""
        opt = self._eng.opt
        if opt.mesh_width is None:
            return int(opt.block)
        return max(int(opt.block), int(16 * opt.mesh_width))

    def feed(self, x) -> None:
        """Feed the next chunk of samples (1-D, float32 or float64; NaN marks gaps)."""
        if self._done:
            raise RuntimeError("OnsetStream.feed after finish()")
        self._eng.feed(as_signal(x))

    def finish(self) -> Onsets:
        """The onsets of everything fed (call once)."""
        if self._done:
            raise RuntimeError("OnsetStream.finish called twice")
        self._done = True
        return self._eng.finish()


def detect_onsets_stream(blocks: Iterable[Recording], channel: str, *, flag_times=None,
                         gap_times=None, **kwargs) -> Onsets:
    """:func:`detect_onsets` over a stream of recording blocks, in bounded memory.

    Parameters
    ----------
    blocks : iterable of Recording
        Consecutive pieces of one recording (``Recording.blocks``,
        ``meshphase.io.iter_blocks``...), possibly overlapping; samples already seen are
        skipped (by each block's ``t0``), missing samples between blocks become a gap (NaN,
        with a DataQualityWarning).
    channel : str
        Channel name.
    flag_times : array_like, shape (k, 2), optional
        ``[t_start, t_stop)`` time ranges [s] to flag ``FLAG_CLIPPED``.
    gap_times : array_like, shape (k, 2), optional
        ``[t_start, t_stop)`` time ranges [s] that are gaps although finite (dropouts, e.g.
        ``ChannelQuality.runs_time("dropout")``); see ``gap_runs`` of :func:`detect_onsets`.
    **kwargs
        Passed to :func:`detect_onsets` (not ``fs``, ``t0``, ``channel``, ``flag_runs``,
        ``gap_runs``).

    Returns
    -------
    Onsets
        Identical to :func:`detect_onsets` on the concatenated samples; empty (with
        ``fs = nan``) when ``blocks`` is empty.

    Notes
    -----
    Memory holds about two analysis blocks whatever the length of the stream.
    """
    if isinstance(blocks, Recording):
        raise TypeError("blocks must be an iterable of Recording blocks, got a single Recording "
                        "(use detect_onsets_recording)")
    if not isinstance(channel, str):
        raise TypeError(f"channel must be a channel name (str), got {channel!r}")
    for bad in ("fs", "t0", "channel", "flag_runs", "gap_runs"):
        if bad in kwargs:
            raise TypeError(f"detect_onsets_stream takes {bad} from the blocks, not as an argument")
    eng = None
    fs = t0 = None
    missing = 0
    for blk in blocks:
        if not isinstance(blk, Recording):
            raise TypeError(f"blocks must yield Recording objects, got {type(blk).__name__}")
        col = blk.channel(channel)
        if eng is None:
            fs, t0 = blk.fs, blk.t0
            fr = time_runs(flag_times, "flag_times", fs, t0)
            gr = time_runs(gap_times, "gap_times", fs, t0)
            eng = BlockEngine(check_options(fs, t0=t0, channel=channel, flag_runs=fr, gap_runs=gr,
                                            **kwargs))
        elif blk.fs != fs:
            raise ValueError(f"block at t0={blk.t0!r} s has fs={blk.fs!r} Hz, the stream started at {fs!r} Hz")
        pos = (blk.t0 - t0) * fs
        i0 = int(round(pos))
        if abs(pos - i0) > 1e-3:
            raise ValueError(f"block at t0={blk.t0!r} s is off the sample grid of the stream "
                             f"(t0={t0!r} s, fs={fs!r} Hz)")
        if i0 > eng.n_fed:
            missing += i0 - eng.n_fed
            eng.feed(np.full(i0 - eng.n_fed, np.nan))
        skip = eng.n_fed - i0
        if skip < col.size:
            eng.feed(col[skip:])
    if eng is None:
        o = check_options(1.0, channel=channel, **{k: v for k, v in kwargs.items()
                                                   if k in ("reference", "level")})
        return empty_onsets(float("nan"), 0.0, channel, o.reference, o.level)
    if missing:
        warnings.warn(f"channel {channel!r}: {missing} sample(s) missing between stream blocks; "
                      "treated as a gap", DataQualityWarning, stacklevel=2)
    return eng.finish()

