"""Readers and writers: one module per format, declared to the format registry.

``read(path, channels=None, start=None, stop=None)`` and ``write(recording, path,
format=None)``. The format is recognised by content (magic bytes), the suffix only breaks
ties for text formats; an unknown format raises ValueError listing the supported ones.

Formats (:data:`FORMATS`, from :mod:`meshphase.io.registry`): ``hdf5`` (native archive),
``mcap``, ``tdms`` (NI), ``lvm`` (NI LabVIEW text, read-only), ``csv``, and any registered with :func:`register_format` or the
``meshphase.formats`` entry points. Each format module declares its
:class:`~meshphase.io.registry.FormatSpec` once; detection, the suffix table, the command
line's ``--format`` choices and the per-format options derive from the specs.

Integrity: every read checks what the format lets it check (``data_schemas/*.md`` say what,
per format): MCAP chunk, data-section and summary CRC32s, HDF5 fletcher32 checksums of the
sample chunks, CSV and TDMS structure (truncation, malformed final row, field counts). A
damaged file raises :class:`CorruptFileError` (a :class:`RecordingFileError`, so a
ValueError) naming the file, the position and the problem. ``verify=False`` (a format
option of :func:`read`, :func:`read_info` and :func:`iter_blocks`) skips the checksum
checks (MCAP, HDF5); structural checks always run.

Writes are atomic and safe: see :func:`~meshphase.io.atomic.atomic_path`.

Imports: the package root helpers (recording, validate, errors), :mod:`meshphase.runtime`
and :mod:`meshphase.signal` (quality); never a format library at import time (a format
module is imported when the registry first needs it).
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterator

import numpy as np

from ..recording import Recording
from ..validate import as_nonnegative, as_positive, as_regular_file
from .atomic import atomic_path, clean_stale_partials
from .base import CorruptFileError, RecordingFileError, RecordingInfo, RecordingTooLargeError
from .registry import (FormatChoices, FormatSpec, format_names, format_of_suffix, get_format, get_spec,
                       register_format, sniff_order, unregister_format, writable_formats)

__all__ = ["read", "write", "write_blocks", "convert", "read_info", "iter_blocks", "detect_format", "FORMATS",
           "RecordingFileError", "CorruptFileError", "RecordingTooLargeError", "RecordingInfo",
           "get_format", "get_spec", "FormatSpec", "FormatChoices", "register_format", "unregister_format",
           "format_names", "format_of_suffix", "writable_formats", "format_for_write", "atomic_path",
           "clean_stale_partials"]

_SNIFF_BYTES = 4096


def __getattr__(name: str):
    # FORMATS follows the registry: a format registered later is in it too
    if name == "FORMATS":
        return format_names()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def detect_format(path) -> str:
    """Name of the format of the file at ``path``, from its first bytes.

    The formats are asked in the registry's order (:func:`~meshphase.io.registry.sniff_order`:
    formats with magic bytes first, delimited text last). The file position of an open
    file object is never touched: the path is opened anew, after
    :func:`~meshphase.validate.as_regular_file` checked it (its exceptions:
    FileNotFoundError, IsADirectoryError, NotRegularFileError for a FIFO, device or socket,
    OSError for a symbolic-link loop ...). Raises :class:`RecordingFileError` when the file
    is empty or no format recognises the content (the message lists the supported ones).
    """
    path = as_regular_file(path, "the recording")
    try:
        with open(path, "rb") as fh:
            head = fh.read(_SNIFF_BYTES)
    except OSError as exc:
        if exc.filename is not None or exc.errno is None:
            raise
        # read() errors (EIO, EINVAL: /proc/self/mem, a failing disk) carry no file name
        raise type(exc)(exc.errno, exc.strerror, str(path)) from exc
    if not head:
        raise RecordingFileError(path, "file is empty (0 bytes)")
    for spec in sniff_order():
        if spec.load().sniff(head):
            return spec.name
    raise RecordingFileError(path, f"unknown format (first bytes {head[:8]!r}); supported "
                                   f"formats: {', '.join(format_names())}")


def format_for_write(path, format: str | None = None) -> str:
    """The writable format to write ``path`` in: ``format``, else the one of its suffix.

    Raises ValueError for an unknown or read-only format, and for a suffix no writable
    format claims (the message lists the writable formats).
    """
    path = Path(path)
    if format is not None:
        if not get_spec(format).writable:
            raise ValueError(f"format {format!r} is read-only here; writable formats: "
                             f"{', '.join(writable_formats())}")
        return format
    name = format_of_suffix(path)
    if name is not None:
        if not get_spec(name).writable:
            raise ValueError(f"{path}: format {name!r} is read-only here; writable formats: "
                             f"{', '.join(writable_formats())}")
        return name
    raise ValueError(f"{path}: cannot tell the format from suffix {path.suffix.lower()!r}; pass format= "
                     f"one of {', '.join(writable_formats())}")


def read_info(path, format: str | None = None, **options) -> RecordingInfo:
    """Header of a recording file (channels, fs, n_samples, t0, metadata) without samples.

    ``options`` go to the format module (e.g. ``fs=`` and ``raw=`` for TDMS, ``verify=False``
    to skip checksum checks). The path is checked as :func:`read` checks it."""
    path = as_regular_file(path, "the recording")
    name = format or detect_format(path)
    return get_format(name).read_info(path, **options)


def read(path, channels=None, start: float | None = None, stop: float | None = None, *,
         format: str | None = None, **options) -> Recording:
    """Read a recording file, or a time window / channel subset of it.

    Parameters
    ----------
    path : str or Path
    channels : str or sequence of str, optional
        Channel names to read (all when None), in the order given.
    start, stop : float, optional
        Half-open time window [start, stop) [s] on the recording's own time axis
        (``t0 + i / fs``); ValueError when it lies outside the recording.
    format : str, optional
        Skip detection and use this format.
    **options
        Format options: every format takes ``verify`` (default True: check the stored
        checksums, MCAP CRC32 and HDF5 fletcher32; False skips them, structural checks
        still run); TDMS also ``fs=`` when the file has no ``wf_increment`` and ``raw=True``
        to keep unscaled values; MCAP written by other tools ``topics=`` (the mapping of
        topic fields onto channels, e.g. ``{"sun_T3": "/rig/strain:gauges.sun_T3"}``),
        ``fs=``, ``max_jitter=`` [s] and ``stamp=`` (``data_schemas/mcap.md``). An unknown
        option raises TypeError.

    Raises
    ------
    FileNotFoundError, IsADirectoryError, NotRegularFileError, OSError
        The path is no regular file (checked by ``os.stat`` before anything opens it, as
        the ``meshphase`` command checks it: a FIFO never blocks), or the file system
        refused it (a symbolic-link loop, permission ...); see :mod:`meshphase.errors`.
    CorruptFileError
        The file is damaged (checksum mismatch, truncated, malformed row); the message
        names the file, the position and the problem.
    RecordingTooLargeError
        The samples asked do not fit in memory (a RecordingFileError and a MemoryError).
    RecordingFileError
        The file is empty, of no known format, not a recording of the detected format, or
        inconsistent.

    Returns
    -------
    Recording
    """
    path = as_regular_file(path, "the recording")
    name = format or detect_format(path)
    mod = get_format(name)
    info = mod.read_info(path, **options)
    names = info.check_channels(channels)
    i0, i1 = (0, info.n_samples) if start is None and stop is None else info.window(start, stop)
    try:
        return mod.read(path, names, i0, i1, **options)
    except MemoryError as exc:
        if isinstance(exc, RecordingTooLargeError):
            raise
        raise RecordingTooLargeError(path, i1 - i0, len(names)) from exc


def iter_blocks(path, block: float, overlap: float = 0.0, channels=None, *,
                format: str | None = None, **options) -> Iterator[Recording]:
    """Stream a recording file in blocks of ``block`` seconds plus ``overlap`` seconds.

    Memory stays flat: only one block (plus overlap) is held at a time. Block k covers
    samples [k n, (k + 1) n + n_overlap), the same as :meth:`Recording.blocks` gives in memory.
    The path is checked as :func:`read` checks it.
    """
    path = as_regular_file(path, "the recording")
    name = format or detect_format(path)
    mod = get_format(name)
    info = mod.read_info(path, **options)
    names = info.check_channels(channels)
    n_block = max(1, int(round(as_positive(block, "block") * info.fs)))
    n_ovl = int(round(as_nonnegative(overlap, "overlap") * info.fs))
    if hasattr(mod, "iter_blocks"):
        yield from mod.iter_blocks(path, n_block, n_ovl, names, **options)
        return
    for i0 in range(0, info.n_samples, n_block):
        yield mod.read(path, names, i0, min(info.n_samples, i0 + n_block + n_ovl), **options)


def write(recording: Recording, path, format: str | None = None, *, overwrite: bool = False,
          **options) -> Path:
    """Write ``recording`` to ``path`` atomically (temporary file, then rename).

    Parameters
    ----------
    recording : Recording
    path : str or Path
    format : str, optional
        One of the writable formats; from the suffix when None.
    overwrite : bool
        Replace an existing file (default False: FileExistsError).
    **options
        Format options (e.g. ``compression="gzip"`` for HDF5, ``block=5120`` for MCAP,
        ``layout="foxglove"`` for MCAP that Foxglove plots).

    Returns
    -------
    Path
        The written path.

    Raises
    ------
    FileExistsError
        ``path`` exists (also when another writer published it while this one wrote) and
        not ``overwrite``.
    OSError
        From the filesystem, e.g. ENOSPC (disk full): raised before writing when the free
        space is clearly too small, else when the write fails; nothing is left behind.

    Notes
    -----
    The file is written to a temporary ``.mp-*.partial`` file in the same directory
    (created with O_EXCL), fsync'ed and then published (see
    :func:`~meshphase.io.base.atomic_path`); a reader never sees a partial file under
    ``path``.
    """
    if not isinstance(recording, Recording):
        raise TypeError(f"recording must be a Recording, got {type(recording).__name__}")
    path = Path(path)
    name = format_for_write(path, format)
    mod = get_format(name)
    with atomic_path(path, overwrite=overwrite, size_hint=_size_hint(recording, name, options)) as tmp:
        mod.write(recording, tmp, **options)
    return path


def write_blocks(header, blocks, path, format: str | None = None, *, dtype="float64",
                 overwrite: bool = False, **options) -> Path:
    """Write a recording given as a header and consecutive blocks of samples, atomically.

    The streaming form of :func:`write` (``meshphase convert``, ``meshphase synth``): memory
    holds one block plus the writer's own buffer (one chunk per channel for HDF5, one chunk
    group for MCAP, ``chunk_rows`` rows for CSV), whatever the length; the file is the same
    as :func:`write` makes of the same samples.

    Parameters
    ----------
    header : Recording, RecordingInfo or alike
        ``fs``, ``t0``, ``n_samples``, ``channels``, ``start_datetime``, ``meta``,
        ``history`` of the recording.
    blocks : iterable of ndarray, shape (k, n_channels)
        The samples, in order; together exactly ``header.n_samples`` rows (ValueError
        otherwise, and nothing is written).
    path : str or Path
    format : str, optional
        One of the writable formats; from the suffix when None.
    dtype : {"float32", "float64"}
        Sample type stored.
    overwrite : bool
        Replace an existing file (default False: FileExistsError).
    **options
        Format options, as :func:`write`.

    Returns
    -------
    Path
    """
    path = Path(path)
    name = format_for_write(path, format)
    if not get_spec(name).streaming_write:
        raise ValueError(f"{path}: format {name!r} is not written block by block; write() the whole "
                         f"recording, or use one of {', '.join(n for n in format_names() if get_spec(n).streaming_write)}")
    mod = get_format(name)
    for attr in ("fs", "t0", "n_samples", "channels", "meta", "history"):
        if not hasattr(header, attr):
            raise TypeError(f"header must have fs, t0, n_samples, channels, meta and history "
                            f"(a Recording or RecordingInfo), got {type(header).__name__} without {attr}")
    dtype = np.dtype(dtype)
    if dtype not in (np.float32, np.float64):
        raise TypeError(f"dtype must be float32 or float64, got {dtype}")
    hint = _hint(int(header.n_samples), len(header.channels), dtype.itemsize, name, options)
    with atomic_path(path, overwrite=overwrite, size_hint=hint) as tmp:
        mod.write_blocks(header, blocks, tmp, dtype=dtype, **options)
    return path


def _size_hint(recording: Recording, name: str, options: dict) -> int | None:
    """A lower bound of the written file's size [B] (None when compressed: unknown)."""
    return _hint(recording.n_samples, recording.n_channels, recording.data.dtype.itemsize,
                 name, options)


def _hint(n: int, nc: int, itemsize: int, name: str, options: dict) -> int | None:
    if options.get("compression") not in (None, "none") or options.get("layout") == "foxglove":
        return None  # compressed (the foxglove layout is zstd by default): size unknown
    if name == "csv":  # at least one digit and one separator per value
        return 2 * n * (nc + 1)
    return int(n * nc * itemsize)


# convert streams through the functions above (read_info, iter_blocks, write_blocks)
from .convert import convert  # noqa: E402
