"""TDMS segment index read from the file itself, and samples read by computed byte offsets.

The layout follows NI's published TDMS file format ("TDMS File Format Internal Structure"):
every segment is a 28-byte lead-in (tag ``TDSm``, ToC mask, version, next-segment offset,
raw-data offset), then, when the ToC has ``kTocMetaData``, the metadata (objects with their
raw data index and properties), then the raw data: chunks of every object with data in the
object order, each chunk holding ``number_values`` values per object (contiguous per object,
or one row of all objects per value when ``kTocInterleavedData`` is set). A segment without
``kTocNewObjList`` updates and extends the previous object list; one without
``kTocMetaData`` repeats the previous layout; raw data index ``0`` means "as in the
previous segment" and ``0xFFFFFFFF`` "no data here".

:func:`scan` walks every segment once, checks its lead-in (a cut or damaged structure raises
:class:`CorruptFileError` naming the segment and byte offset) and, for plain numeric data
(any endianness, interleaved or not), records where each channel's samples lie. Segments
with identical metadata share one parsed layout, and runs of segments with the same layout
at a constant spacing become one strided array, so a file of many small segments (NI-DAQmx
logging writes 512 or 1000 samples per segment) is read with a few numpy copies instead of
one call per segment. DAQmx raw data, strings and unknown types leave ``Index.unsupported``
set: the caller then reads through npTDMS's public ``read_data``.
"""

from __future__ import annotations

import hashlib
import mmap
import os
import struct
from dataclasses import dataclass, field

import numpy as np

from .base import CorruptFileError, RecordingFileError
from .tdms_rows import read_rows, row_columns, shared_rows  # the interleaved rows reader (names kept here)

__all__ = ["Index", "Run", "FileMap", "scan", "read_runs", "shared_rows", "row_columns", "read_rows", "open_map",
           "count_index_segments"]

LEAD_IN = 28
TOC_META = 1 << 1
TOC_RAW = 1 << 3
TOC_INTERLEAVED = 1 << 5
TOC_BIG_ENDIAN = 1 << 6
TOC_DAQMX = 1 << 7
TOC_NEW_OBJ_LIST = 1 << 2
INCOMPLETE = 0xFFFFFFFFFFFFFFFF
_NO_DATA = 0xFFFFFFFF
_SAME_AS_BEFORE = 0x00000000
_DAQMX_INDEX = (0x69120000, 0x69130000)

#: TDMS data type code -> numpy dtype (without byte order) of the numeric types read here
NUMERIC = {1: "i1", 2: "i2", 3: "i4", 4: "i8", 5: "u1", 6: "u2", 7: "u4", 8: "u8", 9: "f4", 10: "f8",
           0x19: "f4", 0x1A: "f8", 0x21: "b1"}
#: byte size of the other fixed-size types (data not read here, but it takes room in a chunk)
_OTHER_SIZE = {11: 16, 0x1B: 16, 0x44: 16, 0x08000C: 8, 0x10000D: 16}
#: byte size of a property value by type code (strings are length-prefixed)
_PROP_SIZE = {1: 1, 2: 2, 3: 4, 4: 8, 5: 1, 6: 2, 7: 4, 8: 8, 9: 4, 10: 8, 11: 16, 0x19: 4, 0x1A: 8,
              0x1B: 16, 0x21: 1, 0x44: 16, 0x08000C: 8, 0x10000D: 16}
_STRING = 0x20


@dataclass(frozen=True)
class Run:
    """Samples ``[start, start + n_seg * n_chunks * n_values)`` of one channel: a strided
    array of shape (n_seg, n_chunks, n_values) at byte ``offset`` with byte strides
    (seg_stride, chunk_stride, value_stride) and dtype ``dtype``."""

    start: int
    offset: int
    n_seg: int
    n_chunks: int
    n_values: int
    seg_stride: int
    chunk_stride: int
    value_stride: int
    dtype: np.dtype

    @property
    def per_seg(self) -> int:
        return self.n_chunks * self.n_values

    @property
    def stop(self) -> int:
        return self.start + self.n_seg * self.per_seg


@dataclass
class Index:
    """What :func:`scan` found: segment count, digest of lead-ins and metadata, and, when the
    data are plain numeric, per channel path its runs, sample count and stored dtype."""

    n_segments: int
    digest: bytes
    runs: dict = field(default_factory=dict)        # path -> [Run]
    lengths: dict = field(default_factory=dict)     # path -> int
    dtypes: dict = field(default_factory=dict)      # path -> np.dtype (with byte order)
    unsupported: str | None = None                  # why the runs cannot be used
    partial: str | None = None                      # first segment holding a partial chunk

    def starts(self, path) -> np.ndarray:
        return np.fromiter((r.start for r in self.runs[path]), dtype=np.int64)


@dataclass(frozen=True)
class _Layout:
    """Data layout of a segment: per object with data (path, dtype or None, byte offset in a
    chunk (plain) or row (interleaved), values per chunk); chunk size [B]; interleaved."""

    objs: tuple
    chunk: int
    interleaved: bool
    unsupported: str | None = None


class _Unsupported(Exception):
    pass


def _read_string(meta: bytes, pos: int, endian: str) -> tuple[str, int]:
    (n,) = struct.unpack_from(endian + "I", meta, pos)
    pos += 4
    if pos + n > len(meta):
        raise _Unsupported("a string runs past the metadata")
    return meta[pos:pos + n].decode("utf-8", "replace"), pos + n


def _parse_meta(meta: bytes, endian: str, state: tuple, known: dict) -> tuple[tuple, bool]:
    """The object list after this metadata: ``state`` is the previous list as a tuple of
    (path, type code, n_values, total bytes, has_data); ``known`` maps every path seen to its
    last raw data index (type code, n_values, total bytes). Returns (new list, whether the
    result depends on ``known`` beyond ``state``). Raises _Unsupported for DAQmx data."""
    pos = 0
    (n_obj,) = struct.unpack_from(endian + "I", meta, pos)
    pos += 4
    if n_obj > len(meta):
        raise _Unsupported(f"object count {n_obj} larger than the metadata")
    entries = []
    outside = False
    in_state = {e[0]: e for e in state}
    for _ in range(n_obj):
        path, pos = _read_string(meta, pos, endian)
        (idx,) = struct.unpack_from(endian + "I", meta, pos)
        pos += 4
        if idx == _NO_DATA:
            prev = in_state.get(path) or known.get(path)
            entries.append((path, *(prev[1:4] if prev else (None, 0, 0)), False))
        elif idx == _SAME_AS_BEFORE:
            prev = in_state.get(path)
            if prev is None or prev[1] is None:
                prev = known.get(path)
                outside = True
            if prev is None or prev[1] is None:
                raise _Unsupported(f"object {path!r} reuses a raw data index it never had")
            entries.append((path, prev[1], prev[2], prev[3], True))
        elif idx in _DAQMX_INDEX:
            raise _Unsupported("DAQmx raw data")
        else:
            code, dim, nv = struct.unpack_from(endian + "IIQ", meta, pos)
            total = struct.unpack_from(endian + "Q", meta, pos + 16)[0] if code == _STRING else 0
            if idx < 20:
                raise _Unsupported(f"object {path!r} has a raw data index of {idx} bytes")
            pos += idx - 4                  # the index length counts its own 4 bytes
            if dim != 1:
                raise _Unsupported(f"object {path!r} has array dimension {dim}")
            entries.append((path, code, nv, total, True))
        (n_props,) = struct.unpack_from(endian + "I", meta, pos)
        pos += 4
        for _ in range(n_props):
            _, pos = _read_string(meta, pos, endian)
            (ptype,) = struct.unpack_from(endian + "I", meta, pos)
            pos += 4
            if ptype == _STRING:
                _, pos = _read_string(meta, pos, endian)
            elif ptype in _PROP_SIZE:
                pos += _PROP_SIZE[ptype]
            else:
                raise _Unsupported(f"property type {ptype:#x}")
        if pos > len(meta):
            raise _Unsupported("metadata runs past its segment")
    return tuple(entries), outside


def _merge(state: tuple, entries: tuple, new_list: bool) -> tuple:
    if new_list:
        return entries
    order = {e[0]: i for i, e in enumerate(state)}
    out = list(state)
    for e in entries:
        if e[0] in order:
            out[order[e[0]]] = e
        else:
            order[e[0]] = len(out)
            out.append(e)
    return tuple(out)


def _layout(state: tuple, toc: int) -> _Layout:
    endian = ">" if toc & TOC_BIG_ENDIAN else "<"
    interleaved = bool(toc & TOC_INTERLEAVED)
    objs, off, why = [], 0, None
    counts = set()
    for path, code, nv, total, has_data in state:
        if not has_data or not nv:
            continue
        if code in NUMERIC:
            dt = np.dtype(endian + NUMERIC[code]) if NUMERIC[code] != "b1" else np.dtype(np.bool_)
            size = dt.itemsize
        else:
            dt = None
            size = _OTHER_SIZE.get(code)
            if code == _STRING and not interleaved:
                size = None
            if size is None and code != _STRING:
                why = why or f"object {path!r} has data type {code:#x}"
        objs.append((path, dt, off, nv))
        counts.add(nv)
        if code == _STRING:
            if interleaved:
                why = why or "interleaved string data"
            off += total
        else:
            off += size if interleaved else size * nv
    if interleaved and len(counts) > 1:
        why = why or "interleaved objects with different value counts"
    chunk = off * (next(iter(counts)) if interleaved and counts else 1)
    return _Layout(tuple(objs), chunk, interleaved, why)


def scan(path, mm=None) -> Index:
    """Walk the segments of a TDMS data file once.

    Parameters
    ----------
    path : str or Path
        The file (named in errors; opened and mapped here unless ``mm`` is given).
    mm : mmap, optional
        The file's memory map, when the caller keeps one open to read the samples through it
        next: the pages the walk maps in are then not faulted in a second time.

    Raises
    ------
    RecordingFileError
        Empty file.
    CorruptFileError
        A lead-in cut short or without the tag, a next-segment offset never written or past
        the end of the file, a raw-data offset beyond its segment.
    """
    if mm is not None and len(mm):
        return _Scan(path, mm, len(mm)).run()
    size = os.path.getsize(path)
    if size == 0:
        raise RecordingFileError(path, "file is empty (0 bytes)")
    with open(path, "rb") as fh, open_map(fh) as own:
        return _Scan(path, own, size).run()


def count_index_segments(path) -> int:
    """Segments listed by a ``.tdms_index`` file (lead-ins tagged ``TDSh``, each followed by
    its metadata only); -1 when the file is not a well-formed index."""
    with open(path, "rb") as fh:
        data = fh.read()
    n, pos = 0, 0
    while pos < len(data):
        if len(data) - pos < LEAD_IN or data[pos:pos + 4] != b"TDSh":
            return -1
        (toc,) = struct.unpack_from("<I", data, pos + 4)
        endian = ">" if toc & TOC_BIG_ENDIAN else "<"
        (raw_off,) = struct.unpack_from(endian + "Q", data, pos + 20)
        pos += LEAD_IN + raw_off
        n += 1
    return n if pos == len(data) else -1


class FileMap(mmap.mmap):
    """A read-only memory map that knows the descriptor of its open file (``fd``), so that
    :func:`read_rows` can read rows with ``os.preadv`` instead of through the map."""

    fd: int = -1


def open_map(fh) -> FileMap:
    """Read-only memory map of an open file (non-empty), with the file's descriptor as
    ``.fd`` (valid while ``fh`` is open)."""
    mm = FileMap(fh.fileno(), 0, access=mmap.ACCESS_READ)
    mm.fd = fh.fileno()
    return mm


class _Scan:
    """One pass over the segments; see :func:`scan`."""

    tag = b"TDSm"

    def __init__(self, path, mm, size: int):
        self.path, self.mm, self.size = path, mm, size
        self.digest = hashlib.blake2b(digest_size=16)
        self.digest.update(struct.pack("<Q", size))
        self.index = Index(0, b"")
        self.state: tuple = ()
        self.known: dict = {}
        self.memo: dict = {}
        self.layouts: dict = {}    # (state, flags) -> _Layout
        self.flags: dict = {}      # id(_Layout) -> its ToC flags
        self.layout: _Layout | None = None
        # the open run: [layout, n_chunks, first data position, spacing, n_seg]
        self.run_: list | None = None
        self.done: dict = {}   # path -> samples so far

    def run(self) -> Index:
        n, pos, mm, size = 0, 0, self.mm, self.size
        unpack = struct.unpack_from
        while pos < size:
            where = f"segment {n} at byte {pos}"
            if size - pos < LEAD_IN:
                raise CorruptFileError(self.path, where, f"truncated: incomplete lead-in "
                                                         f"({size - pos} of {LEAD_IN} bytes)")
            if mm[pos:pos + 4] != self.tag:
                raise CorruptFileError(self.path, where, f"corrupt: the lead-in does not start with "
                                                         f"{self.tag!r} (found {mm[pos:pos + 4]!r})")
            (toc,) = unpack("<I", mm, pos + 4)
            endian = ">" if toc & TOC_BIG_ENDIAN else "<"
            _version, next_off, raw_off = unpack(endian + "IQQ", mm, pos + 8)
            if next_off == INCOMPLETE:
                raise CorruptFileError(self.path, where, "truncated: the segment was never finished "
                                                         "(next-segment offset unset; the writer stopped mid-segment)")
            if raw_off > next_off:
                raise CorruptFileError(self.path, where, f"corrupt: raw-data offset {raw_off} beyond the "
                                                         f"segment length {next_off}")
            nxt = pos + LEAD_IN + next_off
            if nxt > size:
                raise CorruptFileError(self.path, where, f"truncated: the segment needs {nxt} bytes, the "
                                                         f"file has {size}")
            meta = mm[pos + LEAD_IN:pos + LEAD_IN + raw_off] if raw_off else b""
            self.digest.update(mm[pos:pos + LEAD_IN])
            self.digest.update(meta)
            steady = True
            if self.index.unsupported is None:
                try:
                    steady = self._segment(where, toc, meta, pos + LEAD_IN + raw_off, next_off - raw_off,
                                           LEAD_IN + next_off)
                except (_Unsupported, struct.error) as exc:
                    self.index.unsupported = f"{where}: {exc}"
            pos = nxt
            n += 1
            if steady and pos < size:
                m = self._repeats(pos - LEAD_IN - next_off, LEAD_IN + next_off, LEAD_IN + raw_off)
                if m:
                    self._extend(m, LEAD_IN + next_off)
                    self.digest.update(b"repeated %d" % m)
                    pos += m * (LEAD_IN + next_off)
                    n += m
        self._close_run()
        self.index.n_segments = n
        self.index.digest = self.digest.digest()
        return self.index

    def _repeats(self, pos: int, length: int, head: int) -> int:
        """How many segments right after the one at ``pos`` (``length`` bytes) repeat its
        lead-in and metadata (its first ``head`` bytes) exactly, back to back."""
        k_max = (self.size - pos) // length - 1
        if k_max <= 0:
            return 0
        first = np.frombuffer(self.mm, dtype=np.uint8, count=head, offset=pos)
        m, step = 0, 16
        while m < k_max:
            k = min(step, k_max - m)
            rows = np.ndarray((k, head), dtype=np.uint8, buffer=self.mm, offset=pos + (m + 1) * length,
                              strides=(length, 1))
            same = (rows == first).all(axis=1)
            if not same.all():
                return m + int(np.argmin(same))
            m += k
            step *= 16
        return m

    def _extend(self, m: int, seg_len: int) -> None:
        """The last segment (``seg_len`` bytes), repeated ``m`` more times back to back."""
        r = self.run_
        if self.index.unsupported is None and r is not None:
            if r[4] == 1:
                r[3] = seg_len
            r[4] += m

    def _segment(self, where: str, toc: int, meta: bytes, data_pos: int, data_len: int, seg_len: int) -> bool:
        """Add one segment; True when an exact repeat of it right after would continue the
        open run (same object list after it, its data the run's last segment)."""
        before = self.state
        if toc & TOC_DAQMX:
            raise _Unsupported("DAQmx raw data")
        if toc & TOC_META:
            key = (self.state, toc & (TOC_NEW_OBJ_LIST | TOC_BIG_ENDIAN | TOC_INTERLEAVED), meta)
            hit = self.memo.get(key)
            if hit is None:
                endian = ">" if toc & TOC_BIG_ENDIAN else "<"
                entries, outside = _parse_meta(meta, endian, self.state, self.known)
                state = _merge(self.state, entries, bool(toc & TOC_NEW_OBJ_LIST))
                for e in entries:
                    if e[4]:
                        self.known[e[0]] = e
                hit = (state, self._layout_of(state, toc))
                if not outside:
                    self.memo[key] = hit
            else:
                for e in hit[0]:
                    if e[4]:
                        self.known[e[0]] = e
            self.state, self.layout = hit
        elif self.layout is None or (toc & (TOC_BIG_ENDIAN | TOC_INTERLEAVED)) != self._flags(self.layout):
            self.layout = self._layout_of(self.state, toc)
        lay = self.layout
        steady = self.state == before
        if not toc & TOC_RAW or lay.chunk == 0 or data_len == 0:
            return False
        if lay.unsupported:
            raise _Unsupported(lay.unsupported)
        n_chunks, rest = divmod(data_len, lay.chunk)
        if rest and self.index.partial is None:
            self.index.partial = (f"{where}: truncated or corrupt: the segment holds a partial chunk of data "
                                  f"({data_len} bytes of data, chunks of {lay.chunk} bytes)")
        if n_chunks == 0:
            return False
        r = self.run_
        if r is not None and r[0] is lay and r[1] == n_chunks and (
                (r[4] == 1) or data_pos - r[2] == r[3] * r[4]):
            if r[4] == 1:
                r[3] = data_pos - r[2]
            r[4] += 1
        else:
            self._close_run()
            self.run_ = r = [lay, n_chunks, data_pos, 0, 1]
        # a repeat lies one segment length further on: it continues the run when the
        # spacing is still open (one segment) or equals the segment length
        return steady and (r[4] == 1 or r[3] == seg_len)

    def _flags(self, lay: _Layout) -> int:
        return self.flags[id(lay)]

    def _layout_of(self, state: tuple, toc: int) -> _Layout:
        flags = toc & (TOC_BIG_ENDIAN | TOC_INTERLEAVED)
        key = (state, flags)
        lay = self.layouts.get(key)
        if lay is None:
            lay = self.layouts[key] = _layout(state, toc)
            self.flags[id(lay)] = flags
        return lay

    def _close_run(self) -> None:
        r = self.run_
        if r is None:
            return
        self.run_ = None
        lay, n_chunks, first, spacing, n_seg = r
        idx = self.index
        if lay.interleaved:
            nv_rows = lay.objs[0][3] * n_chunks
            row = lay.chunk // lay.objs[0][3]
        for path, dt, off, nv in lay.objs:
            if dt is None:
                continue
            start = self.done.get(path, 0)
            if lay.interleaved:
                run = Run(start, first + off, n_seg, 1, nv_rows, spacing, 0, row, dt)
            else:
                run = Run(start, first + off, n_seg, n_chunks, nv, spacing, lay.chunk, dt.itemsize, dt)
            idx.runs.setdefault(path, []).append(run)
            self.done[path] = run.stop
            idx.lengths[path] = run.stop
            old = idx.dtypes.setdefault(path, dt)
            if old != dt and idx.unsupported is None:
                idx.unsupported = f"channel {path!r} changes its data type from {old} to {dt}"


def read_runs(buf, runs: list, starts: np.ndarray, i0: int, i1: int, dest: np.ndarray) -> None:
    """Copy samples [i0, i1) of one channel (its ``runs``, whose starts are ``starts``) from
    the buffer ``buf`` (the file's bytes) into ``dest`` (length i1 - i0), converting to
    ``dest.dtype``."""
    k = max(0, int(np.searchsorted(starts, i0, side="right")) - 1)
    while k < len(runs) and runs[k].start < i1:
        r = runs[k]
        k += 1
        a, b = max(i0, r.start), min(i1, r.stop)
        if b <= a:
            continue
        view = np.ndarray((r.n_seg, r.n_chunks, r.n_values), dtype=r.dtype, buffer=buf, offset=r.offset,
                          strides=(r.seg_stride, r.chunk_stride, r.value_stride))
        p = r.per_seg
        s0, s1 = divmod(a - r.start, p)
        e0, e1 = divmod(b - r.start, p)
        out = dest[a - i0:b - i0]
        if s0 == e0:                                  # inside one segment
            out[:] = view[s0].reshape(-1)[s1:e1]
            continue
        pos = 0
        if s1:                                        # the tail of the first segment
            out[:p - s1] = view[s0].reshape(-1)[s1:]
            pos, s0 = p - s1, s0 + 1
        if e0 > s0:                                   # whole segments
            n = (e0 - s0) * p
            out[pos:pos + n].reshape(e0 - s0, r.n_chunks, r.n_values)[...] = view[s0:e0]
            pos += n
        if e1:                                        # the head of the last one
            out[pos:] = view[e0].reshape(-1)[:e1]
