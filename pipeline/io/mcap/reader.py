"""Reading MCAP recordings: the header, a window of samples, or the whole file as a stream
of blocks, from the chunks that the summary's chunk index selects."""

from __future__ import annotations

import copy
from collections import deque
from pathlib import Path
from typing import Iterator

import numpy as np

from ...recording import Recording
from ...validate import as_positive_int
from ..base import RecordingFileError, RecordingInfo, check_allocation
from .chunks import ChunkReader, decode_message, chunk_payloads
from .foreign import foreign_info, read_foreign
from .header import ForeignMcapError, Layout, lib_errors, open_layout
from .layout import MAX_LOG_TIME, MSG_HEAD, OP_MESSAGE, REC, FORMAT_VERSION, HEADER_SIZE

__all__ = ["read_info", "read", "iter_blocks"]

# One message record as written by write(): record header, message header, payload header.
_RECORD_VIEW = np.dtype({
    "names": ["op", "length", "channel", "first", "n", "nch", "code", "version"],
    "formats": ["u1", "<u8", "<u2", "<u8", "<u4", "<u2", "u1", "u1"],
    "offsets": [0, 1, 9, 31, 39, 43, 45, 46],
    "itemsize": 47})


def _uniform_chunk(recs: memoryview, lay: Layout, col: dict, i0: int, i1: int):
    """Fast path of :func:`read` for the chunks :func:`write` produces.

    When the chunk holds only full-size messages of one wanted channel, with contiguous
    sample ranges inside [i0, i1) and valid headers, return (column, first sample, strided
    (messages x samples) view of the samples); otherwise None, and the caller parses the
    chunk message by message (which also reports what is wrong, if anything is).
    """
    size = len(recs)
    if size < 9 + MSG_HEAD.size + HEADER_SIZE:
        return None
    op, length = REC.unpack_from(recs, 0)
    rec_size = 9 + length
    n = lay.block
    if op != OP_MESSAGE or length != MSG_HEAD.size + HEADER_SIZE + n * lay.dtype.itemsize \
            or size % rec_size:
        return None
    k = size // rec_size
    heads = np.ndarray((k,), dtype=_RECORD_VIEW, buffer=recs, strides=(rec_size,))
    cid = int(heads["channel"][0])
    first = int(heads["first"][0])
    if (cid not in col or first < i0 or first + k * n > i1
            or not (np.all(heads["op"] == OP_MESSAGE) and np.all(heads["length"] == length)
                    and np.all(heads["channel"] == cid) and np.all(heads["n"] == n)
                    and np.all(heads["nch"] == 1) and np.all(heads["code"] == lay.code)
                    and np.all(heads["version"] == FORMAT_VERSION)
                    and np.array_equal(heads["first"], first + n * np.arange(k, dtype=np.uint64)))):
        return None
    samples = np.ndarray((k, n), dtype=lay.dtype, buffer=recs, offset=9 + MSG_HEAD.size + HEADER_SIZE,
                         strides=(rec_size, lay.dtype.itemsize))
    return col[cid], first, samples


def _check_tiling(path: Path, name: str, spans: list, i0: int, i1: int) -> None:
    """Samples [i0, i1) of one channel must be covered exactly once by ``spans``."""
    if i1 <= i0:
        return
    if not spans:
        raise RecordingFileError(path, f"channel {name!r}: no message holds samples [{i0}, {i1}) "
                                       f"(messages lost)")
    s = np.asarray(spans, dtype=np.int64)
    s = s[np.argsort(s[:, 0], kind="stable")]
    starts = np.concatenate(([i0], s[:, 1]))
    ends = np.concatenate((s[:, 0], [i1]))
    bad = np.flatnonzero(starts != ends)
    if bad.size:
        k = int(bad[0])
        a, b = int(starts[k]), int(ends[k])
        what = (f"samples [{a}, {b}) are missing" if b > a
                else f"samples [{b}, {a}) are stored twice")
        raise RecordingFileError(path, f"channel {name!r}: {what} (messages lost or duplicated)")


def _names(info: RecordingInfo, channels) -> list:
    """Channel selection; the registry passes [] for a file with no channels at all."""
    if channels is None or (not info.channels and not isinstance(channels, str)
                            and len(list(channels)) == 0):
        return info.names
    return info.check_channels(channels)


def _recording(lay: Layout, data: np.ndarray, names: list, i0: int) -> Recording:
    info = lay.info
    specs = {c.name: c for c in info.channels}
    return Recording(data, info.fs, [specs[n] for n in names], t0=info.t0 + i0 / info.fs,
                     start_datetime=info.start_datetime, meta=copy.deepcopy(info.meta),
                     history=copy.deepcopy(info.history))


def _mapped(path, verify, topics, fs, max_jitter, stamp) -> Recording | None:
    """The whole recording decoded through a mapping (:mod:`.foreign`), or None for
    meshphase's own block layout read without one."""
    if topics is not None:
        return read_foreign(path, topics=topics, fs=fs, max_jitter=max_jitter, stamp=stamp, verify=verify)
    try:
        with open_layout(path, verify):
            pass
    except ForeignMcapError:
        return read_foreign(path, fs=fs, max_jitter=max_jitter, stamp=stamp, verify=verify)
    if fs is not None or max_jitter is not None or stamp is not None:
        raise ValueError(f"{path}: fs, max_jitter and stamp apply to MCAP files of other tools "
                         f"(with topics=); this is a meshphase recording, which carries its own")
    return None


def _part(rec: Recording, names: list, i0: int, i1: int) -> Recording:
    """Samples [i0, i1) of the named channels of a decoded recording, as a new Recording."""
    idx = [rec.index(n) for n in names]
    return Recording(np.array(rec.data[i0:i1, idx], order="F"), rec.fs, [rec.channels[i] for i in idx],
                     t0=rec.t0 + i0 / rec.fs, start_datetime=rec.start_datetime,
                     meta=copy.deepcopy(rec.meta), history=copy.deepcopy(rec.history))


def _window_ns(lay: Layout, i0: int, i1: int) -> tuple[int, int]:
    """Inclusive log-time range [ns] of every message that can hold a sample of [i0, i1)."""
    return lay.log_time(max(0, i0 - lay.block + 1)), lay.log_time(i1 - 1)


def _select_chunks(lay: Layout, ids, start_ns: int, end_ns: int) -> list:
    """Chunk indexes that may hold messages of channel ids ``ids`` with log_time in
    [start_ns, end_ns] (inclusive), in log-time order."""
    out = []
    for ci in lay.summary.chunk_indexes:
        if ci.message_start_time > end_ns or ci.message_end_time < start_ns:
            continue
        if ci.message_index_offsets and not any(i in ci.message_index_offsets for i in ids):
            continue
        out.append(ci)
    out.sort(key=lambda ci: (ci.message_start_time, ci.chunk_start_offset))
    return out


def read_info(path, *, verify: bool = True, topics=None, fs: float | None = None,
              max_jitter: float | None = None, stamp: str | None = None) -> RecordingInfo:
    """Header of an MCAP recording (channels, fs, n_samples, t0, metadata); no samples read.

    Parameters
    ----------
    path : str or Path
    verify : bool
        Check the summary and data-section CRCs (default True; once per file identity).
    topics, fs, max_jitter, stamp
        The mapping of a file written by another tool (:func:`.foreign.read_foreign`): its
        messages are decoded once (kept for the following :func:`read`) to know the length.

    Returns
    -------
    RecordingInfo
        ``extra`` holds ``block`` [samples per message], ``dtype``, ``compression``,
        ``n_chunks``, ``n_messages`` and ``log_time_origin_ns`` [ns].
    """
    rec = _mapped(path, verify, topics, fs, max_jitter, stamp)
    if rec is not None:
        return foreign_info(path, rec)
    with open_layout(path, verify) as (_, _, lay):
        return copy.deepcopy(lay.info)


def read(path, channels=None, i0: int = 0, i1: int | None = None, *,
         verify: bool = True, topics=None, fs: float | None = None,
         max_jitter: float | None = None, stamp: str | None = None) -> Recording:
    """Samples ``i0 <= i < i1`` of the named channels of an MCAP recording.

    Parameters
    ----------
    path : str or Path
    channels : str or sequence of str, optional
        Channel names (all when None), in the order wanted.
    i0, i1 : int
        Sample range [i0, i1) [-]; ``i1=None`` reads to the end.
    verify : bool
        Check the CRCs (default True): summary and data-section CRC once per file, and the
        CRC of every chunk read (computed in a worker thread while the samples are copied).
        False skips them (a damaged chunk then reads as whatever its bytes say).
    topics, fs, max_jitter, stamp
        The mapping of a file written by another tool (:func:`.foreign.read_foreign`, the
        generic decoder path); a file in meshphase's ``foxglove`` layout needs none.

    Returns
    -------
    Recording
        Data in one array allocated once, Fortran order (each channel contiguous); ``t0`` of
        the returned recording is the time of sample ``i0`` [s].

    Notes
    -----
    The chunk index of the summary section (parsed by ``mcap.reader.make_reader``) selects
    the chunks of the wanted channels whose log-time range meets the inclusive range
    ``[log_time(i0 - block + 1), log_time(i1 - 1)]``. Each chunk is read whole into one
    reused buffer (and decompressed); a chunk of full messages of one channel (what
    :func:`write` produces) is copied into the output in one strided copy, any other chunk
    message by message. (Scatter reads straight from the file into the output, saving that
    buffer, measured no faster here: first-touch page faults of the output dominate.)

    Raises
    ------
    CorruptFileError
        A CRC does not match or the file is truncated (the chunk or byte range is named).
    RecordingFileError
        The file is not a meshphase MCAP recording or does not hold what its index says;
        a foreign file without a mapping (the message lists its topics and numeric fields).
    """
    rec = _mapped(path, verify, topics, fs, max_jitter, stamp)
    if rec is not None:
        names = foreign_info(path, rec).check_channels(channels)
        i1 = rec.n_samples if i1 is None else int(i1)
        if not 0 <= int(i0) <= i1 <= rec.n_samples:
            raise ValueError(f"{path}: sample range [{i0}, {i1}) is outside [0, {rec.n_samples}]")
        return _part(rec, names, int(i0), i1)
    with open_layout(path, verify) as (path, fh, lay):
        info = lay.info
        names = _names(info, channels)
        n_total = info.n_samples
        i1 = n_total if i1 is None else int(i1)
        i0 = int(i0)
        if not 0 <= i0 <= i1 <= n_total:
            raise ValueError(f"{path}: sample range [{i0}, {i1}) is outside [0, {n_total}]")
        check_allocation(path, i1 - i0, len(names), lay.dtype.itemsize)
        out = np.empty((i1 - i0, len(names)), dtype=lay.dtype.newbyteorder("="), order="F")
        if i1 > i0 and names:
            col = {lay.channel_ids[n]: c for c, n in enumerate(names)}
            spans: list[list] = [[] for _ in names]
            start_ns, end_ns = _window_ns(lay, i0, i1)
            itemsize = lay.dtype.itemsize
            dtype = lay.dtype
            with lib_errors(path, "reading chunks"), \
                    ChunkReader(fh, path, lay, verify=verify) as chunks:
                for ci in _select_chunks(lay, col, start_ns, end_ns):
                    recs = chunks.records(ci)
                    fast = _uniform_chunk(recs, lay, col, i0, i1)
                    if fast is not None:  # whole chunk in one strided copy
                        c, first, samples = fast
                        m_, n_ = samples.shape
                        out[first - i0:first - i0 + m_ * n_, c].reshape(m_, n_)[...] = samples
                        spans[c].append((first, first + m_ * n_))
                        continue
                    for cid, off, size, _ in chunk_payloads(recs, col, path):
                        c = col[cid]
                        first, n = decode_message(recs, off, size, lay, path, names[c])
                        a = first if first > i0 else i0
                        b = first + n if first + n < i1 else i1
                        if a >= b:
                            continue
                        out[a - i0:b - i0, c] = np.frombuffer(
                            recs, dtype, b - a, off + HEADER_SIZE + (a - first) * itemsize)
                        spans[c].append((a, b))
            for c, name in enumerate(names):
                _check_tiling(path, name, spans[c], i0, i1)
        return _recording(lay, out, names, i0)


def iter_blocks(path, n_block: int, n_overlap: int, channels=None, *,
                verify: bool = True, topics=None, fs: float | None = None,
                max_jitter: float | None = None, stamp: str | None = None) -> Iterator[Recording]:
    """Stream an MCAP recording in blocks of ``n_block`` samples plus ``n_overlap``.

    One pass over the chunks in log-time order; each message's samples are copied at once
    into the block being filled (samples of later blocks that arrive early are kept aside),
    and a block is handed out as soon as every channel has reached its end. Memory stays
    flat however long the recording is: one block plus one chunk group (about
    n_channels x chunk_size, 8 MiB by default). Block k
    covers samples [k n_block, (k + 1) n_block + n_overlap), clipped to the recording. Each
    channel's messages must come in sample order (as :func:`write` stores them).

    Parameters
    ----------
    path : str or Path
    n_block : int
        Samples per block [-], >= 1.
    n_overlap : int
        Extra samples of the following block appended to each block [-], >= 0.
    channels : sequence of str, optional
        Channel names (all when None).
    verify : bool
        Check the CRCs as :func:`read` does (default True); every chunk feeding a block has
        passed its CRC before the block is handed out.
    topics, fs, max_jitter, stamp
        The mapping of a file written by another tool: that file is decoded whole (the
        generic path holds the recording), then handed out block by block.

    Yields
    ------
    Recording
    """
    n_block = as_positive_int(n_block, "n_block")
    if isinstance(n_overlap, bool) or not isinstance(n_overlap, (int, np.integer)) or n_overlap < 0:
        raise ValueError(f"n_overlap must be a non-negative integer, got {n_overlap!r}")
    n_overlap = int(n_overlap)
    rec = _mapped(path, verify, topics, fs, max_jitter, stamp)
    if rec is not None:
        names = foreign_info(path, rec).check_channels(channels)
        for b0 in range(0, rec.n_samples, n_block):
            yield _part(rec, names, b0, min(rec.n_samples, b0 + n_block + n_overlap))
        return
    with open_layout(path, verify) as (path, fh, lay):
        names = _names(lay.info, channels)
        n_total = lay.info.n_samples
        if n_total == 0:
            return
        native = lay.dtype.newbyteorder("=")
        blocks = _Blocks(n_total, n_block, n_overlap, len(names), native)
        if not names:
            for k in range(blocks.n_blocks):
                b0, b1 = blocks.span(k)
                yield _recording(lay, np.empty((b1 - b0, 0), native), names, b0)
            return
        col = {lay.channel_ids[n]: c for c, n in enumerate(names)}
        with lib_errors(path, "streaming chunks"), \
                ChunkReader(fh, path, lay, verify=verify) as chunks:  # samples are copied out at once
            for ci in _select_chunks(lay, col, 0, MAX_LOG_TIME):
                recs = chunks.records(ci)
                for cid, off, size, _ in chunk_payloads(recs, col, path):
                    c = col[cid]
                    first, n = decode_message(recs, off, size, lay, path, names[c])
                    done = blocks.done[c]
                    if first != done:
                        what = "missing" if first > done else "stored twice or out of order"
                        raise RecordingFileError(path, f"channel {names[c]!r}: samples "
                                                       f"[{min(first, done)}, {max(first, done)}) "
                                                       f"are {what}")
                    blocks.add(c, first, np.frombuffer(recs, lay.dtype, n, off + HEADER_SIZE))
                while blocks.full():
                    chunks.finish()  # the chunks feeding this block passed their CRC
                    out, b0 = blocks.take()
                    yield _recording(lay, out, names, b0)
                    del out
                    blocks.advance()
        if blocks.k < blocks.n_blocks:
            c = int(np.argmin(blocks.done))
            raise RecordingFileError(path, f"channel {names[c]!r}: samples [{blocks.done[c]}, {n_total}) "
                                           f"are missing (messages lost)")


class _Blocks:
    """The blocks of :func:`iter_blocks`, filled as each channel's samples arrive in order.

    Only block ``k`` (being filled) is allocated, as ``cur``; samples that later blocks need
    and that arrive early (other channels lag by up to one chunk group) wait in ``later``
    as copies, so the peak is one block plus one chunk group, however long the file.
    """

    def __init__(self, n_total: int, n_block: int, n_overlap: int, n_col: int, dtype: np.dtype):
        self.n_total = n_total
        self.n_block = n_block
        self.n_overlap = n_overlap
        self.n_blocks = -(-n_total // n_block)
        self.dtype = dtype
        self.later = [deque() for _ in range(n_col)]  # per channel: (first sample, samples) >= next block
        self.done = [0] * n_col  # samples [0, done[c]) of channel c have arrived
        self.k = 0  # block being filled
        self.cur = self._start(0)

    def span(self, k: int) -> tuple[int, int]:
        """Samples [b0, b1) of block ``k``."""
        b0 = k * self.n_block
        return b0, min(self.n_total, b0 + self.n_block + self.n_overlap)

    def _start(self, k: int) -> np.ndarray:
        """Block ``k``, with the samples already waiting for it."""
        b0, b1 = self.span(k)
        out = np.empty((b1 - b0, len(self.later)), self.dtype, order="F")
        nxt = b0 + self.n_block  # samples before this are no longer needed by later blocks
        for c, q in enumerate(self.later):
            for first, arr in q:
                a, b = max(first, b0), min(first + arr.size, b1)
                if a < b:
                    out[a - b0:b - b0, c] = arr[a - first:b - first]
            while q and q[0][0] + q[0][1].size <= nxt:
                q.popleft()
            if q and q[0][0] < nxt:
                first, arr = q.popleft()
                q.appendleft((nxt, arr[nxt - first:]))
        return out

    def add(self, c: int, first: int, arr: np.ndarray) -> None:
        """Samples [first, first + arr.size) of column ``c``, the next ones of that channel."""
        b0, b1 = self.span(self.k)
        a, b = max(first, b0), min(first + arr.size, b1)
        if a < b:
            self.cur[a - b0:b - b0, c] = arr[a - first:b - first]
        nxt = b0 + self.n_block
        if first + arr.size > nxt and self.k + 1 < self.n_blocks:
            a = max(first, nxt)
            self.later[c].append((a, arr[a - first:].copy()))
        self.done[c] = first + arr.size

    def full(self) -> bool:
        """True when every channel has reached the end of block ``k``."""
        return self.k < self.n_blocks and min(self.done) >= self.span(self.k)[1]

    def take(self) -> tuple[np.ndarray, int]:
        """Block ``k`` and its first sample; no block is held until :meth:`advance`."""
        out, self.cur = self.cur, None
        return out, self.span(self.k)[0]

    def advance(self) -> None:
        """Start filling the next block (if any)."""
        self.k += 1
        if self.k < self.n_blocks:
            self.cur = self._start(self.k)
