"""What every format module shares: the header type, the file error, atomic writes.

A format module (``hdf5``, ``mcap``, ``csv``, ``tdms``) provides

``NAME`` (str), ``SUFFIXES`` (tuple of lower-case suffixes), ``CAN_WRITE`` (bool),
``sniff(head: bytes) -> bool``
    True when the first bytes of a file are this format (content, not suffix).
``read_info(path) -> RecordingInfo``
    Header only: no samples are read.
``read(path, channels=None, i0=0, i1=None) -> Recording``
    Samples ``i0 <= i < i1`` of the named channels (all when None); indices already checked
    by the registry.
``write(recording, path, **options) -> None`` (when ``CAN_WRITE``)
    Writes straight to ``path``; the registry wraps it in a temporary file and a rename.
``iter_blocks(path, n_block, n_overlap, channels) -> Iterator[Recording]`` (optional)
    A faster streaming path than repeated ``read`` calls.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from ..recording import ChannelSpec, sample_index

__all__ = ["RecordingInfo", "RecordingFileError", "atomic_path"]


class RecordingFileError(ValueError):
    """A recording file that cannot be read as what it claims to be (truncated, malformed,
    inconsistent). The message starts with the file path and names the problem."""

    def __init__(self, path, problem: str):
        self.path = str(path)
        self.problem = problem
        super().__init__(f"{path}: {problem}")


@dataclass
class RecordingInfo:
    """Header of a recording file: everything but the samples.

    Attributes
    ----------
    path : str
    format : str
    fs : float
        Sample rate [Hz].
    n_samples : int
    channels : list of ChannelSpec
    t0 : float
        Time of the first sample [s].
    start_datetime : str or None
    meta : dict
    history : list
    extra : dict
        Format-specific details (layout, compression, segment count...).
    """

    path: str
    format: str
    fs: float
    n_samples: int
    channels: list[ChannelSpec]
    t0: float = 0.0
    start_datetime: str | None = None
    meta: dict = field(default_factory=dict)
    history: list = field(default_factory=list)
    extra: dict = field(default_factory=dict)

    @property
    def duration(self) -> float:
        """Duration [s]."""
        return self.n_samples / self.fs

    @property
    def names(self) -> list[str]:
        return [c.name for c in self.channels]

    def window(self, start: float | None, stop: float | None) -> tuple[int, int]:
        """Sample range [i0, i1) of the time window [start, stop) [s]; RecordingFileError-free
        ValueError naming the file when the window lies outside the recording."""
        t_end = self.t0 + self.duration
        t_start = self.t0 if start is None else float(start)
        t_stop = t_end if stop is None else float(stop)
        if t_stop <= t_start:
            raise ValueError(f"{self.path}: empty or reversed window [{t_start!r}, {t_stop!r}) s")
        if t_start >= t_end or t_stop <= self.t0:
            raise ValueError(f"{self.path}: window [{t_start!r}, {t_stop!r}) s lies outside the "
                             f"recording [{self.t0!r}, {t_end!r}) s")
        i0 = sample_index(t_start, self.t0, self.fs, self.n_samples)
        i1 = sample_index(t_stop, self.t0, self.fs, self.n_samples)
        return i0, max(i0, i1)

    def check_channels(self, channels) -> list[str]:
        """Normalise a channel selection (None, a name, or names) and check it exists."""
        if channels is None:
            return self.names
        if isinstance(channels, str):
            channels = [channels]
        channels = list(channels)
        if not channels:
            raise ValueError(f"{self.path}: channel selection is empty")
        missing = [c for c in channels if c not in self.names]
        if missing:
            raise ValueError(f"{self.path}: no channel(s) {missing}; the file has {self.names}")
        if len(set(channels)) != len(channels):
            raise ValueError(f"{self.path}: channel selection repeats a channel: {channels}")
        return channels


@contextlib.contextmanager
def atomic_path(path, *, overwrite: bool = False):
    """Yield a temporary path next to ``path``; on success rename it onto ``path``.

    Nothing is left at ``path`` if the body raises (the temporary file is removed), so a
    crash never leaves a half-written recording under the target name. An existing ``path``
    raises FileExistsError unless ``overwrite``.
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path}: exists; pass overwrite=True to replace it")
    if not path.parent.exists():
        raise FileNotFoundError(f"{path}: directory {path.parent} does not exist")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".partial", dir=path.parent)
    os.close(fd)
    os.unlink(tmp)  # writers (h5py, TdmsWriter) want to create the file themselves
    tmp = Path(tmp)
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise
