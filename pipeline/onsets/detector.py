"""Onset detectors chosen by name: the interface every detector implements
(:class:`OnsetDetector`), the registry of detector factories, and detection on a whole
recording channel with any of them.

A detector is a block filter: built from its options for one channel, it is fed the
channel's conditioned samples chunk after chunk (:meth:`OnsetDetector.feed`) and returns
the channel's :class:`~meshphase.onsets.Onsets` when flushed (:meth:`OnsetDetector.finish`).
The onsets carry their timing model (:mod:`meshphase.onsets.timing`): timing centres and
per-onset uncertainties are all the passes and the phasing take from a detector.

A factory is called as ``factory(fs, *, t0, channel, mesh_freq=None, flag_runs=None,
gap_runs=None, gap_guard=0.0)``, the options a run gives every detector (see
:data:`RUN_OPTIONS`; a detector may ignore those it has no use for): sample rate [Hz],
time of the first sample [s], channel name, the gear's mesh frequency [Hz], the
``[start, stop)`` sample runs to flag as clipped and to treat as gaps, and the time [s]
around a gap whose pulses are flagged. The matched filter (:class:`OnsetStream`) is
built in as :data:`DEFAULT_DETECTOR`, ``"matched"``. The names live in
:data:`meshphase.runtime.registry.ONSET_DETECTORS`, which a scene checks its
``[onsets] detector`` against without importing any detector.
"""

from __future__ import annotations

from typing import Callable, Protocol, runtime_checkable

import numpy as np

from ..recording import Recording
from ..runtime.registry import DEFAULT_ONSET_DETECTOR, ONSET_DETECTORS
from .results import Onsets
from .runs import quality_options

__all__ = ["OnsetDetector", "DEFAULT_DETECTOR", "RUN_OPTIONS", "register_detector",
           "unregister_detector", "detector_names", "check_detector", "make_detector",
           "detect_recording", "recording_channel"]

#: the detector a scene uses unless its ``[onsets] detector`` names another: the matched
#: filter, :class:`meshphase.onsets.OnsetStream`
DEFAULT_DETECTOR = DEFAULT_ONSET_DETECTOR

#: the keyword options a run passes every detector factory (besides ``fs``)
RUN_OPTIONS = ("t0", "channel", "mesh_freq", "flag_runs", "gap_runs", "gap_guard")


@runtime_checkable
class OnsetDetector(Protocol):
    """One channel's onset detector: a block filter fed samples, flushed for its onsets."""

    @property
    def n_samples(self) -> int:
        """Samples fed so far [-]."""

    @property
    def block_samples(self) -> int:
        """The largest stretch of samples the detector holds at a time [samples], as
        estimated before any sample (sizes the run's memory estimate)."""

    def feed(self, x) -> None:
        """Take the next chunk of conditioned samples (1-D float; NaN marks gaps)."""

    def finish(self) -> Onsets:
        """The onsets of everything fed (called once)."""


def register_detector(name: str, factory: Callable[..., OnsetDetector], *, replace: bool = False) -> None:
    """Make ``factory`` the detector called ``name`` (scenes choose it by
    ``[onsets] detector = name``).

    Parameters
    ----------
    name : str
        Non-empty detector name.
    factory : callable
        ``factory(fs, **options) -> OnsetDetector`` (the options: see the module notes).
    replace : bool
        Allow replacing an earlier registration (never the built-in ``"matched"``).

    Raises
    ------
    TypeError
        ``name`` is not a string or ``factory`` is not callable.
    ValueError
        ``name`` is empty, names the built-in detector, or is taken (without ``replace``).
    """
    ONSET_DETECTORS.register(name, factory, replace=replace)


def unregister_detector(name: str) -> None:
    """Remove the detector called ``name`` (ValueError for the built-in or an unknown one)."""
    ONSET_DETECTORS.unregister(name)


def detector_names() -> tuple[str, ...]:
    """The registered detector names, sorted."""
    return ONSET_DETECTORS.names()


def check_detector(name) -> str:
    """``name`` when a detector is registered under it, else a ValueError listing the known
    ones (TypeError when it is not a string)."""
    return ONSET_DETECTORS.check(name)


def make_detector(name: str, fs: float, **options) -> OnsetDetector:
    """The detector called ``name`` for one channel sampled at ``fs`` [Hz], built from
    ``options`` (see the module notes).

    Returns
    -------
    OnsetDetector

    Raises
    ------
    ValueError
        Unknown ``name`` (the message lists the known ones), or bad options (the factory's).
    TypeError
        The factory built something that is not an :class:`OnsetDetector`.
    """
    det = ONSET_DETECTORS.factory(name)(fs, **options)
    if not isinstance(det, OnsetDetector):
        raise TypeError(f"onset detector {name!r} built a {type(det).__name__}, not an OnsetDetector "
                        "(feed, finish, n_samples, block_samples)")
    return det


def recording_channel(rec: Recording, channel: str, quality, options: dict, caller: str) -> np.ndarray:
    """The samples of ``channel`` of ``rec``, with the options its quality report gives added to
    ``options`` (in place, where not given): the checks every detection on a whole recording
    channel makes first.

    Raises TypeError for a ``rec`` that is no Recording, a ``channel`` that is no name, or
    ``options`` that give ``fs``, ``t0`` or ``channel`` (the recording's own); KeyError for an
    unknown channel (:meth:`Recording.channel`).
    """
    if not isinstance(rec, Recording):
        raise TypeError(f"rec must be a Recording, got {type(rec).__name__}")
    if not isinstance(channel, str):
        raise TypeError(f"channel must be a channel name (str), got {channel!r}")
    for bad in ("fs", "t0", "channel"):
        if bad in options:
            raise TypeError(f"{caller} takes {bad} from the recording, not as an argument")
    if quality is not None:
        for key, value in quality_options(quality, rec.n_samples, rec.fs).items():
            options.setdefault(key, value)
    return rec.channel(channel)


def detect_recording(rec: Recording, channel: str, *, detector: str = DEFAULT_DETECTOR, quality=None,
                     **options) -> Onsets:
    """The onsets of one channel of a conditioned recording by the detector called
    ``detector``, its samples fed at once.

    Parameters
    ----------
    rec : Recording
        Conditioned recording.
    channel : str
        Channel name.
    detector : str
        Registered detector name (:func:`detector_names`).
    quality : ChannelQuality, optional
        The channel's report from :mod:`meshphase.signal.condition`: its clipped runs are
        flagged, its dropout runs are gaps and its ``settle`` time guards the gaps
        (:func:`meshphase.onsets.runs.quality_options`), unless ``options`` give them.
    **options
        Passed to the factory (not ``fs``, ``t0``, ``channel``).

    Returns
    -------
    Onsets
        For the matched filter identical to
        :func:`~meshphase.onsets.detect_onsets_recording`.
    """
    x = recording_channel(rec, channel, quality, options, "detect_recording")
    det = make_detector(detector, rec.fs, t0=rec.t0, channel=channel, **options)
    det.feed(x)
    return det.finish()
