"""Block sources of recordings that are not in memory, and the generators behind them.

Every source is a :class:`meshphase.recording.BlockSource` (a ``header`` and
``blocks(n_block)``); the memory source is :class:`meshphase.recording.MemorySource`. Here:

- :class:`FileSource`: a file of any :mod:`meshphase.io` format (or a time window of it),
  read block by block through its format module;
- :class:`GeneratedSource`: a generated recording (a stream of blocks), generated again for
  every pass;
- :class:`BridgeSource`: another source whose bridge channels come out in strain
  (:mod:`meshphase.io.bridge`).

:func:`checked_blocks` and :func:`blocks_ahead` read a source's blocks checked to be
consecutive, the latter reading the next one on a thread of its own.

Generators of recordings (the synthetic rig of :mod:`meshphase.synthetic`) plug in through
the entry-point group :data:`GENERATOR_GROUP` (or :func:`register_generator`): the package
itself never imports them. :func:`generator` finds one by name, :func:`scenario_names` and
:func:`scenario_config` ask it about its named scenarios.
"""

from __future__ import annotations

import contextlib
import importlib.metadata
import os
import warnings
from pathlib import Path
from typing import Any, Iterator, Protocol, runtime_checkable

import numpy as np

from ..errors import DataQualityWarning
from . import detect_format, get_spec
from .base import CorruptFileError, recording_read_errors
from .bridge import BridgeConfig, bridge_history, convert_block, initial_volts, strain_spec
from ..recording import BlockSource, RecordingHeader, apply_gains, warn_nonfinite_runs
from ..runtime.threads import read_ahead

__all__ = ["FileSource", "GeneratedSource", "BridgeSource", "checked_blocks", "blocks_ahead",
           "RecordingGenerator", "GENERATOR_GROUP", "register_generator", "generator",
           "scenario_names", "scenario_config", "StreamedRecording", "GeneratorSource"]


# ============================================================================ files
class FileSource(BlockSource):
    """A recording file (any format of :mod:`meshphase.io`), or a time window of it.

    Parameters
    ----------
    path : str or Path
    start, stop : float, optional
        Time window [s] on the recording's axis (as :func:`meshphase.io.read`).
    channels : sequence of ChannelSpec, optional
        Specs replacing the file's (channel overrides).
    gains : list of (int, float), optional
        (column, factor) applied to the samples, in order.
    format : str, optional
    options : dict, optional
        Format options of every read (e.g. an MCAP mapping: ``topics``, ``fs``).
    """


    def __init__(self, path, *, start: float | None = None, stop: float | None = None,
                 channels=None, gains: list | None = None, format: str | None = None,
                 options: dict | None = None):
        self.path = Path(path)
        self.fmt = format or detect_format(self.path)
        self.spec = get_spec(self.fmt)
        self.mod = self.spec.load()
        self.options = dict(options or {})
        info = self.mod.read_info(self.path, **self.options)
        self.info = info
        self.names = info.names
        if start is None and stop is None:
            self.i0, self.i1 = 0, info.n_samples
        else:
            self.i0, self.i1 = info.window(start, stop)
        dtype = np.dtype(np.float64)            # until the first block says otherwise
        self.gains = list(gains or [])
        self.header = RecordingHeader(info.fs, self.i1 - self.i0,
                                      list(channels) if channels is not None else list(info.channels),
                                      info.t0 + self.i0 / info.fs, info.start_datetime, info.meta,
                                      info.history, dtype)
        self._dtype_known = False
        self._seen: set = set()
        self._verified: tuple | None = None     # the file's signature after a checked pass

    @property
    def label(self) -> str:
        """The file's path."""
        return str(self.path)

    def blocks(self, n_block: int):
        """The window's consecutive blocks, read errors turned into the file errors of
        :func:`meshphase.io.base.recording_read_errors`."""
        with recording_read_errors(self.path):
            opts, unchecked, sig = self._pass_options()
            yield from self._read(n_block, opts)
            self._pass_done(unchecked, sig)

    def _read(self, n_block: int, opts: dict):
        i0, i1 = self.i0, self.i1
        if i0 == 0 and i1 == self.info.n_samples and hasattr(self.mod, "iter_blocks"):
            for blk in self._quiet(self.mod.iter_blocks(self.path, n_block, 0, self.names, **opts)):
                a = int(round((blk.t0 - self.info.t0) * self.info.fs))
                self._note_dtype(blk.data)
                yield a, apply_gains(blk.data, self.gains, copy=False)
            return
        if self.spec.random_access or not hasattr(self.mod, "iter_blocks"):
            reads = (self.mod.read(self.path, self.names, a, min(i1, a + n_block), **opts)
                     for a in range(i0, i1, n_block))
            for blk in self._quiet(reads):
                self._note_dtype(blk.data)
                a = int(round((blk.t0 - self.info.t0) * self.info.fs))
                yield a - i0, apply_gains(blk.data, self.gains, copy=False)
            return
        # other formats stream from the start: skip to the window, stop after it
        pos = 0
        for blk in self._quiet(self.mod.iter_blocks(self.path, n_block, 0, self.names, **opts)):
            a, b = pos, pos + blk.n_samples
            pos = b
            if b <= i0:
                continue
            if a >= i1:
                break
            data = blk.data[max(a, i0) - a:min(b, i1) - a]
            self._note_dtype(data)
            yield max(a, i0) - i0, apply_gains(data, self.gains, copy=True)

    def _signature(self) -> tuple:
        st = os.stat(self.path)
        return (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns)

    def _pass_options(self) -> tuple[dict, bool, tuple | None]:
        """Format options of the next pass over the file, whether it skips the checksums,
        and the file's signature now.

        A file with checksums (HDF5 fletcher32, MCAP CRC32: a format whose spec declares
        ``checksums``) has
        them checked in the first whole pass (they cost about as much as the rest of the
        read). A later pass of the same source over the file, unchanged since (device,
        inode, size and modification time as before and after the checked pass), reads it
        again unchecked (``verify=False``); ``verify`` given in the options is obeyed in
        every pass."""
        if not self.spec.checksums or "verify" in self.options:
            return self.options, False, None
        sig = self._signature()
        if self._verified is not None and sig == self._verified:
            return dict(self.options, verify=False), True, sig
        self._verified = None
        return self.options, False, sig

    def _pass_done(self, unchecked: bool, sig: tuple | None) -> None:
        """After a whole pass: an unchecked one must have read the file as checked
        (CorruptFileError if it changed meanwhile); a checked one over an unchanged file
        lets the next passes skip the checksums."""
        if sig is None:
            return
        end = self._signature()
        if unchecked and end != self._verified:
            raise CorruptFileError(self.path, "the whole file", "it changed while it was being read "
                                   "again (size or modification time): read it anew")
        if not unchecked and end == sig:
            self._verified = sig

    def _quiet(self, it):
        """The blocks of ``it``; the readers' per-block NaN/inf warnings are dropped
        (:meth:`warn_nonfinite` issues one per channel for the whole window instead), any
        other warning is issued once."""
        it = iter(it)
        try:
            while True:
                with warnings.catch_warnings(record=True) as wl:
                    warnings.simplefilter("always")
                    try:
                        blk = next(it)
                    except StopIteration:
                        return
                for w in wl:
                    text = str(w.message)
                    if issubclass(w.category, DataQualityWarning) and "NaN/inf samples" in text:
                        continue
                    if text not in self._seen:
                        self._seen.add(text)
                        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
                yield blk
        finally:
            close = getattr(it, "close", None)
            if close is not None:
                close()

    def warn_nonfinite(self, results: dict) -> None:
        """One DataQualityWarning per channel with NaN/inf runs, as :func:`meshphase.io.read`
        of the whole window issues it (``results``: the ScanResults by channel)."""
        warn_nonfinite_runs(str(self.path), self.names, results, self.i0)

    def _note_dtype(self, data: np.ndarray) -> None:
        if not self._dtype_known:
            self.header.dtype = data.dtype
            self._dtype_known = True



# ============================================================================ generated
class GeneratedSource(BlockSource):
    """A generated recording, generated block by block again for every pass (the generator
    is deterministic: the same samples each time).

    Parameters
    ----------
    stream : iterable of Recording
        A stream of a :class:`RecordingGenerator` (:meth:`RecordingGenerator.stream`): it has
        ``fs``, ``n_samples``, ``channels``, ``t0``, ``start_datetime``, ``meta``,
        ``history`` and ``dtype``, and iterating it gives consecutive Recording blocks (of
        its own length).
    channels : sequence of ChannelSpec, optional
        Specs replacing the stream's (channel overrides).
    gains : list of (int, float), optional
        (column, factor) applied to the samples, in order.
    label : str
        What the source is called in messages.
    """

    def __init__(self, stream, channels=None, gains: list | None = None, *,
                 label: str = "synthetic recording"):
        self.stream = stream
        self.gains = list(gains or [])
        self.header = RecordingHeader(stream.fs, stream.n_samples,
                                      list(channels) if channels is not None else list(stream.channels),
                                      stream.t0, stream.start_datetime, stream.meta,
                                      stream.history, stream.dtype)
        self._label = str(label)

    @property
    def label(self) -> str:
        """What the source is called in messages."""
        return self._label

    def blocks(self, n_block: int):
        """The stream's blocks (its own length; ``n_block`` is not used), gains applied."""
        pos = 0
        for blk in self.stream:
            yield pos, apply_gains(blk.data, self.gains, copy=False)
            pos += blk.n_samples


#: The header of a streamed recording: :class:`meshphase.recording.RecordingHeader`.
StreamedRecording = RecordingHeader
#: :class:`GeneratedSource` under its other name.
GeneratorSource = GeneratedSource


# ============================================================================ converted
class BridgeSource(BlockSource):
    """A block source whose bridge channels come out in strain [m/m]: the wrapped source's
    blocks converted as they are read (:func:`meshphase.io.bridge.convert_block`).

    V_init of each channel with a null window is read once, when this source is made, from
    ``null_source`` (the whole recording, so that a window outside an analysis window
    ``start_s``/``stop_s`` still reads, :func:`meshphase.io.bridge.initial_volts`); every
    other attribute is the wrapped source's.

    Parameters
    ----------
    source : BlockSource
        Bridge channels in volts [V] (gains applied).
    configs : dict of str to BridgeConfig
        Channel name -> its bridge.
    null_source : BlockSource, optional
        The whole recording, for the null windows (default ``source``).
    """

    def __init__(self, source: BlockSource, configs: dict, null_source: BlockSource | None = None):
        h = source.header
        self.source = source
        bad = [n for n, c in configs.items() if not isinstance(c, BridgeConfig)]
        if bad or not configs:
            raise TypeError(f"configs must map channel names to BridgeConfig, got {configs!r}")
        cols = {h.index(name): c for name, c in configs.items()}
        ns = source if null_source is None else null_source
        nh = ns.header
        self.v_init = initial_volts(ns.blocks(1 << 16), nh.t0, nh.fs, nh.n_samples, cols)
        self.conversions = {j: (c, self.v_init[j]) for j, c in cols.items()}
        specs = [strain_spec(s) if j in cols else s for j, s in enumerate(h.channels)]
        self._header = RecordingHeader(h.fs, h.n_samples, specs, h.t0, h.start_datetime, h.meta,
                                       h.history, h.dtype).with_history(
            "bridge_strain", channels=bridge_history(h.names, cols, self.v_init))

    @property
    def header(self) -> RecordingHeader:
        """The wrapped source's header with the bridge channels in "m/m" and the
        ``bridge_strain`` step in its history (its dtype follows the wrapped source's)."""
        self._header.dtype = self.source.header.dtype
        return self._header

    @property
    def label(self) -> str:
        """The wrapped source's label."""
        return self.source.label

    def __getattr__(self, name):
        if name == "source":   # not set yet (copy, pickle): no recursion
            raise AttributeError(name)
        return getattr(self.source, name)  # warn_nonfinite, fmt, path ... of the wrapped source

    def blocks(self, n_block: int):
        """The wrapped source's blocks, bridge columns in strain [m/m]."""
        for a, data in self.source.blocks(n_block):
            yield a, convert_block(data, self.conversions)


# ============================================================================ reading
def checked_blocks(source: BlockSource, n_block: int) -> Iterator[tuple[int, np.ndarray]]:
    """The source's non-empty blocks, checked to be consecutive, of the header's channel
    count and to cover the recording (ValueError naming the source otherwise).

    Parameters
    ----------
    source : BlockSource
    n_block : int
        Samples per block asked of the source [-].
    """
    pos = 0
    n = source.header.n_samples
    nc = source.header.n_channels
    for a, data in source.blocks(n_block):
        if a != pos:
            raise ValueError(f"{source.label}: block at sample {a}, expected {pos}")
        if data.ndim != 2 or data.shape[1] != nc:
            raise ValueError(f"{source.label}: block of shape {data.shape}, expected (k, {nc})")
        pos += data.shape[0]
        if data.shape[0]:
            yield a, data
    if pos != n:
        raise ValueError(f"{source.label}: the blocks hold {pos} samples, the header says {n}")


def blocks_ahead(source: BlockSource, n_block: int):
    """:func:`checked_blocks`, the next block read on a thread of its own while the caller
    works on this one (:func:`meshphase.runtime.threads.read_ahead`), as a context manager:
    leaving it, whatever way, stops the reader and closes its file."""
    return contextlib.closing(read_ahead(lambda: checked_blocks(source, n_block)))


# ============================================================================ generators
#: The entry-point group through which a package provides a :class:`RecordingGenerator`
#: (name: the generator's name, e.g. ``synthetic``; value: ``module:object``).
GENERATOR_GROUP = "meshphase.sources"

_GENERATORS: dict[str, Any] = {}


@runtime_checkable
class RecordingGenerator(Protocol):
    """What a generator of recordings provides (the synthetic rig's is
    :data:`meshphase.synthetic.source.GENERATOR`)."""

    def scenarios(self) -> list[str]:
        """The names of its scenarios."""

    def scenario(self, name: str) -> Any:
        """The configuration of scenario ``name``: ``fs`` [Hz], ``duration`` [s], ``gauges``,
        ``tacho`` (or None) and ``gearset`` (with ``to_dict()``); no samples generated."""

    def stream(self, scenario_or_config, *, duration: float | None, seed: int) -> Any:
        """A deterministic stream of the recording (see :class:`GeneratedSource`) with
        ``collect()`` (the whole Recording), ``names``, ``truth`` and ``block_samples``."""


def register_generator(name: str, gen: RecordingGenerator) -> None:
    """Make ``gen`` the generator called ``name`` (it wins over an entry point of that name).

    Raises
    ------
    TypeError
        ``name`` is no non-empty string, or ``gen`` lacks a method of
        :class:`RecordingGenerator`.
    """
    if not isinstance(name, str) or not name:
        raise TypeError(f"a generator's name must be a non-empty string, got {name!r}")
    if not isinstance(gen, RecordingGenerator):
        raise TypeError(f"generator {name!r} must have scenarios(), scenario(name) and "
                        f"stream(...), got {type(gen).__name__}")
    _GENERATORS[name] = gen


def generator(name: str) -> RecordingGenerator | None:
    """The generator called ``name``: registered, else loaded from the installed entry point
    of :data:`GENERATOR_GROUP` (once); None when there is none."""
    if not isinstance(name, str):
        raise TypeError(f"a generator's name must be a string, got {type(name).__name__}")
    if name not in _GENERATORS:
        found = [ep for ep in importlib.metadata.entry_points(group=GENERATOR_GROUP) if ep.name == name]
        if not found:
            return None
        register_generator(name, found[0].load())
    return _GENERATORS[name]


def scenario_names(name: str = "synthetic") -> list[str]:
    """The scenario names of generator ``name``, sorted; empty when it is not installed."""
    gen = generator(name)
    return sorted(gen.scenarios()) if gen is not None else []


def scenario_config(scenario: str, name: str = "synthetic") -> Any:
    """The configuration of ``scenario`` of generator ``name`` (no samples generated), or
    None when the generator is not installed or has no such scenario."""
    gen = generator(name)
    if gen is None or scenario not in gen.scenarios():
        return None
    return gen.scenario(scenario)
