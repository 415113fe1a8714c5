"""What every format module shares: the header type, the file errors, the helpers of the
readers and writers (option and header checks, JSON text, warnings about NaN runs).
Format modules share code through this module and :mod:`meshphase.io.atomic` (atomic
writes; :func:`atomic_path` and :func:`clean_stale_partials` are re-exported here).

A format module (``hdf5``, ``mcap``, ``csv``, ``tdms``) declares itself once, as ``FORMAT``
(a :class:`~meshphase.io.registry.FormatSpec`: name, suffixes, capabilities, options), and
provides

``sniff(head: bytes) -> bool``
    True when the first bytes of a file are this format (content, not suffix).
``read_info(path, *, verify=True, **options) -> RecordingInfo``
    Header only: no samples are read.
``read(path, channels=None, i0=0, i1=None, *, verify=True, **options) -> Recording``
    Samples ``i0 <= i < i1`` of the named channels (all when None); indices already checked
    by the registry. ``verify`` switches the checksum checks of formats that store checksums
    (MCAP CRCs, HDF5 fletcher32); structural checks (truncation, field counts) always run.
``iter_blocks(path, n_block, n_overlap, channels, *, verify=True, **options) -> Iterator[Recording]``
    (optional) A faster streaming path than repeated ``read`` calls.
``write(recording, path, **options) -> None`` (when ``writable``)
    Writes to ``path``, an empty file the registry created for it (see :func:`atomic_path`).
``write_blocks(header, blocks, path, *, dtype, **options) -> None`` (when ``streaming_write``)
    The same from a header and consecutive (k, channels) sample blocks, in flat memory.

Errors: :class:`RecordingFileError` (a ValueError) for a file that is not what it claims to
be; its subclass :class:`CorruptFileError` for a file whose bytes are damaged (checksum
mismatch, truncation, a malformed row), with the position of the damage.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import json
import math
import os
import re
import warnings
from dataclasses import dataclass
from typing import Any, Iterator

import numpy as np

from ..errors import DataQualityWarning, FormatWarning
from ..jsonable import json_default
from ..signal.quality import nonfinite_runs
from ..recording import ChannelSpec, RecordingHeader
from .atomic import STALE_AGE, TEMP_PREFIX, TEMP_SUFFIX, atomic_path, clean_stale_partials
# the one list of clock names (TDMS without waveform timing, HDF5 from other tools, CSV, LVM)
from .timenames import CLOCK_NAMES

__all__ = ["RecordingFileError", "CorruptFileError", "RecordingTooLargeError", "RecordingInfo", "atomic_path",
           "clean_stale_partials", "TEMP_PREFIX", "TEMP_SUFFIX", "STALE_AGE", "check_verify",
           "warn_nonfinite", "dumps_json", "check_start_datetime", "spec_from_dict", "nice_fs",
           "CLOCK_NAMES", "kind_from_name", "clock_timing",
           "regroup_blocks", "recording_read_errors", "physical_memory", "check_allocation",
           "check_fs_range", "FS_RANGE", "ANY_FS_ENV"]


class RecordingFileError(ValueError):
    """A recording file that cannot be read as what it claims to be (truncated, malformed,
    inconsistent). The message starts with the file path and names the problem."""

    def __init__(self, path, problem: str):
        self.path = str(path)
        self.problem = problem
        super().__init__(f"{path}: {problem}")


class CorruptFileError(RecordingFileError):
    """The bytes of a recording file are damaged: a checksum does not match (MCAP CRC32, HDF5
    fletcher32), the file is cut short, or a row is malformed.

    The message is ``"<path>: <position>: <problem>"``; the parts are kept as attributes.

    Attributes
    ----------
    path : str
    position : str
        Where the damage is, in the format's own terms: ``"byte 1234"``,
        ``"chunk 3 at byte 1234"``, ``"line 17 (byte 4096)"``, ``"dataset /channels/x,
        samples [0, 131072)"``.
    problem : str
        What is wrong.
    """

    def __init__(self, path, position: str, problem: str):
        self.position = str(position)
        super().__init__(path, f"{position}: {problem}")
        self.problem = problem


class RecordingTooLargeError(RecordingFileError, MemoryError):
    """The samples asked of a recording file do not fit in memory (also a MemoryError).

    The message names the file, the samples x channels asked and their size in memory, the
    machine's memory when known, and how to read less (a time window, or block by block).

    Attributes
    ----------
    path : str
    n_samples, n_channels : int
        The samples and channels asked.
    available : int or None
        The machine's physical memory [bytes], when the check was made against it.
    """

    def __init__(self, path, n_samples: int, n_channels: int, itemsize: int = 8, *,
                 available: int | None = None):
        self.n_samples, self.n_channels = int(n_samples), int(n_channels)
        self.available = None if available is None else int(available)
        size = self.n_samples * self.n_channels * int(itemsize)
        have = ("" if self.available is None
                else f", more than this machine's {self.available / 1e9:.4g} GB of memory")
        super().__init__(path, f"{self.n_samples} samples x {self.n_channels} channel(s) "
                               f"({size / 1e9:.3g} GB in memory) do not fit in memory{have}; read "
                               "a time window (start=, stop=), fewer channels, or block by block "
                               "(iter_blocks, the streamed commands)")


@dataclass(repr=False)
class RecordingInfo(RecordingHeader):
    """Header of a recording file: a :class:`~meshphase.recording.RecordingHeader` whose
    sample rate is checked as a file's (built with keywords: ``path``, ``format``, ``fs``,
    ``n_samples``, ``channels``, ...).

    Raises
    ------
    RecordingFileError
        ``fs`` is not a finite positive number, or lies outside :data:`FS_RANGE` (see
        :func:`check_fs_range`).
    """

    def __post_init__(self):
        check_fs_range(self.fs, self.path)
        super().__post_init__()


# ---------------------------------------------------------------------------- shared helpers
#: Sample rates [Hz] a recording file may state: from a slow logger to the fastest strain
#: acquisition, with a wide margin either side. A rate outside is refused as a damaged or
#: misread header unless the environment variable :data:`ANY_FS_ENV` is ``1`` (the
#: ``meshphase --any-fs`` option sets it).
FS_RANGE = (1e-3, 1e8)
#: The environment variable that lets any finite positive sample rate through.
ANY_FS_ENV = "MESHPHASE_ANY_FS"


def check_fs_range(fs, path) -> None:
    """Refuse a sample rate ``fs`` [Hz] of the file ``path`` outside :data:`FS_RANGE`
    (unless :data:`ANY_FS_ENV` is ``1``).

    Raises
    ------
    RecordingFileError
        Naming the file, echoing the rate and the range, and how to force it.
    """
    try:
        rate = float(fs)
    except (TypeError, ValueError):
        raise RecordingFileError(path, f"sample rate fs = {fs!r} is not a number") from None
    if not (math.isfinite(rate) and rate > 0):
        raise RecordingFileError(path, f"sample rate fs = {fs!r} Hz is not a finite positive number")
    if not FS_RANGE[0] <= rate <= FS_RANGE[1] and os.environ.get(ANY_FS_ENV, "").strip() != "1":
        raise RecordingFileError(path, f"sample rate fs = {fs!r} Hz is outside the physical range "
                                       f"[{FS_RANGE[0]:g}, {FS_RANGE[1]:g}] Hz (a damaged or misread header?); "
                                       f"if it is right, run with --any-fs ({ANY_FS_ENV}=1)")


def physical_memory() -> int | None:
    """The machine's physical memory [bytes], or None where the OS does not say."""
    try:
        return int(os.sysconf("SC_PHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, ValueError, OSError):
        return None


def check_allocation(path, n_samples: int, n_channels: int, itemsize: int) -> None:
    """Refuse, before allocating, to read ``n_samples`` x ``n_channels`` samples of
    ``itemsize`` [bytes] that the machine's physical memory cannot hold.

    Raises
    ------
    RecordingTooLargeError
        (a MemoryError) Naming the file, the sizes and the memory [GB], and what to do
        instead (a time window, the streamed commands).
    """
    need = int(n_samples) * int(n_channels) * int(itemsize)
    ram = physical_memory()
    if ram is not None and need > ram:
        raise RecordingTooLargeError(path, n_samples, n_channels, itemsize, available=ram)


def check_verify(verify) -> bool:
    """The ``verify`` option of a format's readers, checked: a bool (TypeError otherwise)."""
    if not isinstance(verify, (bool, np.bool_)):
        raise TypeError(f"verify must be a bool, got {verify!r}")
    return bool(verify)


def warn_nonfinite(path, data: np.ndarray, names, i0: int = 0) -> None:
    """Issue one DataQualityWarning per channel holding NaN/inf runs (the data are kept).

    Parameters
    ----------
    path : str or Path
        File the samples came from (named in the message).
    data : ndarray, shape (n_samples, n_channels)
    names : sequence of str
        Channel names, one per column.
    i0 : int
        File sample index of ``data[0]`` (so the message gives file sample indices).
    """
    if data.size == 0:
        return
    for j, name in enumerate(names):
        col = data[:, j]
        # a finite sum proves every sample finite (NaN and inf propagate); only a non-finite
        # sum (or an overflow) pays for the exact scan
        with np.errstate(invalid="ignore", over="ignore"):
            total = np.add.reduce(col, dtype=np.float64)
        if np.isfinite(total):
            continue
        runs = nonfinite_runs(col)
        if not len(runs):  # the sum overflowed; every sample is finite
            continue
        lengths = runs[:, 1] - runs[:, 0]
        first = int(runs[0, 0]) + i0
        warnings.warn(DataQualityWarning(
            f"{path}: channel {name!r} has {len(runs)} run(s) of NaN/inf samples "
            f"({int(lengths.sum())} samples, longest {int(lengths.max())}, first at sample {first}); "
            f"kept in the data"), stacklevel=3)


def _same_json(a: Any, b: Any) -> bool:
    """Equality that treats NaN == NaN and requires equal container types (tuple != list)."""
    if type(a) is not type(b):
        return False
    if isinstance(a, float):
        return a == b or (math.isnan(a) and math.isnan(b))
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same_json(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return len(a) == len(b) and all(_same_json(x, y) for x, y in zip(a, b))
    return a == b


def dumps_json(obj: Any, what: str) -> str:
    """One-line JSON text of ``obj`` (numpy scalars/arrays and datetimes converted).

    Raises TypeError naming ``what`` for values JSON cannot hold; warns (FormatWarning) when
    reading the text back will not give an equal object (tuples become lists, non-string keys
    become strings, numpy values become Python values).
    """
    try:
        text = json.dumps(obj, default=json_default, ensure_ascii=False, allow_nan=True)
    except TypeError as exc:
        raise TypeError(f"{what}: {exc}") from exc
    except ValueError as exc:  # circular reference
        raise ValueError(f"{what}: {exc}") from exc
    if not _same_json(json.loads(text), obj):
        warnings.warn(FormatWarning(
            f"{what} is stored as JSON and will read back changed (tuples become lists, "
            f"non-string keys become strings, numpy values become Python values)"), stacklevel=3)
    return text


def nice_fs(fs_est: float, n: int, span: float, quantum: float = 0.0) -> float:
    """The shortest decimal (<= 12 digits) sample rate whose grid spans ``span`` [s] over ``n``
    samples to within 1 % of a sample interval, plus the resolution ``quantum`` [s] of the
    two times the span is taken from; ``fs_est`` [Hz] to 12 digits otherwise (a time column
    of a CSV or a TDMS file gives its sample rate this way: 5120.0, not 5119.99999)."""
    for digits in range(1, 13):
        cand = float(f"{fs_est:.{digits}g}")
        if cand > 0 and abs((n - 1) / cand - span) <= 0.01 / cand + quantum:
            return cand
    return float(f"{fs_est:.12g}")



_KIND_PATTERNS = (
    ("sun", re.compile(r"^sun", re.I)),
    ("ring", re.compile(r"^ring", re.I)),
    ("facewidth", re.compile(r"^(fw|face)", re.I)),
    ("tacho", re.compile(r"^(tacho|once)", re.I)),
)


def kind_from_name(*names: str) -> str:
    """Channel kind from the first name (channel, then group) matching a pattern, else "other"."""
    for name in names:
        for kind, pat in _KIND_PATTERNS:
            if pat.match(name.strip()):
                return kind
    return "other"


def clock_timing(path, what: str, values: np.ndarray, n_samples: int) -> tuple[float, float, str | None]:
    """(fs [Hz], t0 [s], start_datetime) from a clock: each sample's time in seconds
    (float) or as timestamps (datetime64). fs comes from its first and last time
    (:func:`nice_fs`), and every time is checked against the grid t0 + i/fs to 0.1 sample
    plus the clock's own resolution (float32 seconds: eps x the largest time; timestamps:
    their unit); timestamps give t0 = 0 and start_datetime the first.

    Parameters
    ----------
    path : str or Path
        The file (messages).
    what : str
        The clock, for messages (``"clock channel 'Time'"``).
    values : ndarray, shape (n,)
        [s] or datetime64.
    n_samples : int
        Samples of the recording's channels [-].

    Raises
    ------
    RecordingFileError
        Length not ``n_samples``, fewer than two times, a non-finite time, a span that is not
        positive, or a time off the grid (a dropped, repeated or shifted sample: named).
    """
    t = np.asarray(values).reshape(-1)
    if t.size != n_samples:
        raise RecordingFileError(path, f"{what} has {t.size} values for {n_samples} samples")
    if t.size < 2:
        raise RecordingFileError(path, f"missing or non-positive sample rate: {what} has {t.size} value(s)")
    start = None
    if t.dtype.kind == "M":
        unit = np.datetime_data(t.dtype)[0]
        quantum = float(np.timedelta64(1, unit) / np.timedelta64(1, "ns")) * 1e-9
        t64 = t.astype("datetime64[ns]")
        start = np.datetime_as_string(t64[0].astype("datetime64[us]"), unit="us") + "+00:00"
        t = (t64 - t64[0]).astype(np.int64) * 1e-9
    elif t.dtype.kind in "iuf":
        quantum = float(np.finfo(t.dtype).eps) * float(np.max(np.abs(t))) if t.dtype.kind == "f" else 1.0
        t = t.astype(np.float64)
    else:
        raise RecordingFileError(path, f"{what} holds {t.dtype} values, not times")
    if not np.all(np.isfinite(t)):
        k = int(np.flatnonzero(~np.isfinite(t))[0])
        raise RecordingFileError(path, f"{what}: non-finite time at sample {k}")
    span = float(t[-1] - t[0])
    if not span > 0:
        raise RecordingFileError(path, f"missing or non-positive sample rate: {what} runs from "
                                       f"{float(t[0])!r} to {float(t[-1])!r} s")
    fs = nice_fs((t.size - 1) / span, t.size, span, quantum)
    t0 = 0.0 if start is not None else float(t[0])
    tol = 0.1 / fs + quantum
    off = np.abs(t - (t[0] + np.arange(t.size) / fs))
    if not np.all(off <= tol):
        k = int(np.flatnonzero(~(off <= tol))[0])
        raise RecordingFileError(path, f"non-uniform time in {what} at sample {k}: t = {float(t[k] - t[0])!r} s "
                                       f"after the first, expected {k / fs!r} s on the uniform grid (fs = "
                                       f"{fs!r} Hz, tolerance {tol * fs:.3g} sample): a dropped, repeated or "
                                       f"shifted sample")
    if quantum >= 1.0 / fs:
        warnings.warn(FormatWarning(f"{path}: {what} resolves {quantum:.3g} s, too coarse for 1/fs = "
                                    f"{1.0 / fs:.4g} s: a dropped sample cannot be seen in it"), stacklevel=5)
    return fs, t0, start


def check_start_datetime(value, path) -> str | None:
    """Check an ISO 8601 start time read from a file (None passes)."""
    if value is None:
        return None
    if not isinstance(value, str):
        raise RecordingFileError(path, f"start_datetime must be an ISO 8601 string, got {value!r}")
    try:
        _dt.datetime.fromisoformat(value)
    except ValueError as exc:
        raise RecordingFileError(path, f"start_datetime {value!r} is not ISO 8601") from exc
    return value


def spec_from_dict(d: dict, path, where: str, *, checked: bool = False) -> ChannelSpec:
    """A ChannelSpec from a dict read from a file, checked against channel_spec.schema.json
    (unless ``checked``: already validated as part of a larger schema)."""
    from meshphase.data_schemas import validate

    try:
        if not checked:
            validate(d, "channel_spec", where=where)
        return ChannelSpec.from_dict(d)
    except (ValueError, TypeError) as exc:
        raise RecordingFileError(path, f"bad channel spec: {exc}") from exc


def checked_write_blocks(blocks, nch: int, n: int) -> Iterator[np.ndarray]:
    """Each of ``blocks`` as an array, checked as a streaming writer takes them: (samples,
    ``nch``) each, and ``n`` samples together. ValueError naming the shape, or the count
    (raised after the last block when they hold fewer)."""
    got = 0
    for blk in blocks:
        blk = np.asarray(blk)
        if blk.ndim != 2 or blk.shape[1] != nch:
            raise ValueError(f"blocks must be (samples, {nch}) arrays, got shape {blk.shape}")
        if got + blk.shape[0] > n:
            raise ValueError(f"blocks hold more than the header's n_samples = {n}")
        got += blk.shape[0]
        yield blk
    if got != n:
        raise ValueError(f"blocks hold {got} samples, the header says n_samples = {n}")


def regroup_blocks(blocks, nch: int, n: int, group_len: int, dtype: np.dtype) -> Iterator[tuple[np.ndarray, int]]:
    """The samples of ``blocks`` (each (k, nch), any k) regrouped by a streaming writer:
    (samples, first sample) of consecutive groups of ``group_len`` samples (the last may be
    shorter) from blocks of any length: ``samples`` is (channels, samples) of ``dtype``, a
    buffer re-used for the next group. ValueError when the blocks do not hold ``n`` rows."""
    buf = np.empty((nch, min(group_len, max(n, 1))), dtype=dtype)
    fill = pos = 0
    for blk in blocks:
        blk = np.asarray(blk)
        if blk.ndim != 2 or blk.shape[1] != nch:
            raise ValueError(f"blocks must be (samples, {nch}) arrays, got shape {blk.shape}")
        k = blk.shape[0]
        if pos + fill + k > n:
            raise ValueError(f"blocks hold more than the header's n_samples = {n}")
        i = 0
        while i < k:
            if fill == 0 and k - i >= group_len:
                yield np.ascontiguousarray(blk[i:i + group_len].T, dtype=dtype), pos
                pos += group_len
                i += group_len
                continue
            m = min(group_len - fill, k - i)
            buf[:, fill:fill + m] = blk[i:i + m].T
            fill += m
            i += m
            if fill == group_len:
                yield buf, pos
                pos += group_len
                fill = 0
    if fill:
        yield buf[:, :fill], pos
        pos += fill
    if pos != n:
        raise ValueError(f"blocks hold {pos} samples, the header says n_samples = {n}")


@contextlib.contextmanager
def recording_read_errors(path) -> Iterator[None]:
    """Turn the HDF5 library's errors while reading ``path`` into a RecordingFileError.

    h5py reports HDF5 failures as ``OSError`` without an errno ("Can't synchronously read
    data (filter returned failure during read)"), ``RuntimeError`` ("Special link traversal
    failed (too many links)": a soft-link loop) or ``KeyError`` ("Unable to open object");
    none names the file. OS errors with an errno pass through: unchanged when they carry a
    file name (permission, ...), with ``path`` as their file name when they do not (EIO
    from ``read()``).
    """
    try:
        yield
    except RecordingFileError:
        raise
    except OSError as exc:
        if exc.errno is not None and exc.filename is None:
            # read() errors (EIO from a failing disk or /proc/self/mem) carry no file name
            raise type(exc)(exc.errno, exc.strerror, str(path)) from exc
        if exc.errno is not None or type(exc) is not OSError:  # ours name the file already
            raise
        raise RecordingFileError(path, f"read error, file corrupt? ({exc})") from exc
    except RuntimeError as exc:
        raise RecordingFileError(path, f"read error ({exc})") from exc
    except KeyError as exc:
        raise RecordingFileError(path, f"read error ({exc.args[0] if exc.args else exc})") from exc
