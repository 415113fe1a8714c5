"""The chunk reader: one chunk's uncompressed records read into reused buffers, its CRC
checked in a worker thread, and the messages and payload headers in it."""

from __future__ import annotations

import os
import struct
from pathlib import Path

import numpy as np

from ..base import CorruptFileError, RecordingFileError
from .crc import crc32
from .header import LIB_ERRORS, Layout
from .layout import (CHUNK_HEAD, HEADER, MAX_RECORD, MSG_HEAD, OP_CHUNK, OP_MESSAGE, REC, U64,
                     FORMAT_VERSION, HEADER_SIZE)

__all__: list[str] = ["read_message_index"]

_OP_MESSAGE_INDEX = 0x07
_INDEX_HEAD = struct.Struct("<BQHI")  # opcode, record length, channel id, entries byte length

_CRC_ASYNC_MIN = 1 << 16  # chunks at least this large [B] get their CRC in the worker thread


class ChunkReader:
    """Reads the uncompressed records of one chunk given its ChunkIndex (summary section).

    The file bytes go into two buffers used in turn: the returned view is valid until the
    next call but one (callers copy the samples out at once). With ``verify``, the CRC32 of
    each chunk's uncompressed records is computed in a worker thread (zlib releases the GIL)
    while the caller copies the samples and reads the next chunk; :meth:`finish` waits for
    it. Use as a context manager: on leaving, the last CRC is checked, and a CRC mismatch
    takes precedence over an error raised while parsing the damaged chunk.
    """

    def __init__(self, fh, path: Path, lay: Layout | None = None, *, verify: bool = True):
        self.fh = fh
        self.file_size = os.fstat(fh.fileno()).st_size
        self.path = path
        self.lay = lay
        self.verify = verify
        self.bufs = [bytearray(0), bytearray(0)]
        self.turn = 0
        self.pending = None  # (future, chunk index, stored crc, n bytes)
        self._pending_turn = -1  # buffer the pending CRC reads (-1: none of ours)
        self.pool = None
        self._zstd = None
        self._numbers = None

    def __enter__(self):
        return self

    def __exit__(self, typ, exc, tb):
        try:
            if exc is None:
                self.finish()
            else:
                try:
                    self.finish()
                except CorruptFileError as crc_error:
                    if isinstance(exc, (RecordingFileError,) + LIB_ERRORS):
                        raise crc_error from exc
        finally:
            if self.pool is not None:
                self.pool.shutdown(wait=True)
                self.pool = None
        return False

    def _where(self, ci) -> str:
        if self.lay is not None:
            if self._numbers is None:
                self._numbers = {c.chunk_start_offset: k for k, c in enumerate(self.lay.summary.chunk_indexes)}
            k = self._numbers.get(ci.chunk_start_offset)
            if k is not None:
                return f"chunk {k} at byte {ci.chunk_start_offset}"
        return f"chunk at byte {ci.chunk_start_offset}"

    def _bad(self, ci, problem: str):
        return CorruptFileError(self.path, self._where(ci), problem)

    def _crc_error(self, ci, got: int, want: int, nbytes: int):
        names = []
        if self.lay is not None:
            by_id = {v: k for k, v in self.lay.channel_ids.items()}
            names = [by_id[i] for i in (ci.message_index_offsets or {}) if i in by_id]
        return self._bad(ci, f"CRC32 of its {nbytes} uncompressed record bytes is {got:#010x}, the chunk "
                             f"records {want:#010x}: the chunk is damaged (channel(s) {names}, log time "
                             f"[{ci.message_start_time}, {ci.message_end_time}] ns)")

    def finish(self) -> None:
        """Wait for the pending CRC and raise CorruptFileError when it does not match."""
        if self.pending is None:
            return
        fut, ci, want, nbytes = self.pending
        self.pending = None
        self._pending_turn = -1
        got = fut.result()
        if got != want:
            raise self._crc_error(ci, got, want, nbytes)

    def _check_crc(self, ci, data, want: int, turn: int) -> None:
        """Check (or start checking) the CRC of ``data``, which lives in buffer ``turn``
        (-1: in its own object)."""
        if len(data) < _CRC_ASYNC_MIN:
            got = crc32(data)
            if got != want:
                raise self._crc_error(ci, got, want, len(data))
            return
        if self.pool is None:
            from concurrent.futures import ThreadPoolExecutor

            self.pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="meshphase-crc")
        self.finish()  # one CRC in flight at a time
        self.pending = (self.pool.submit(crc32, data), ci, want, len(data))
        self._pending_turn = turn

    def records(self, ci) -> memoryview:
        size = int(ci.chunk_length)
        if ci.chunk_start_offset + size > self.file_size:
            raise self._bad(ci, f"the chunk index says {size} bytes, past the end of the "
                                f"{self.file_size}-byte file")
        self.fh.seek(ci.chunk_start_offset)
        if self.pending is not None and self._pending_turn == self.turn:
            self.finish()  # the pending CRC still reads this buffer
        buf = self.bufs[self.turn]
        if len(buf) < size:
            buf = self.bufs[self.turn] = bytearray(size)
        mv = memoryview(buf)[:size]
        got = self.fh.readinto(mv)
        if got != size:
            raise self._bad(ci, f"only {got} of {size} bytes present (file truncated)")
        if size < 9 + CHUNK_HEAD.size + 8:
            raise self._bad(ci, f"{size} bytes is too short for a chunk record")
        op, length = REC.unpack_from(mv, 0)
        if op != OP_CHUNK or 9 + length != size:
            raise self._bad(ci, f"the chunk index points at a record with opcode {op:#04x} and "
                                f"length {length}, not a {size}-byte chunk")
        _, _, usize, crc, clen = CHUNK_HEAD.unpack_from(mv, 9)
        pos = 9 + CHUNK_HEAD.size
        comp = bytes(mv[pos:pos + clen]).decode("utf-8", "replace")
        pos += clen
        if pos + 8 > size:
            raise self._bad(ci, "chunk header runs past the record")
        (rlen,) = U64.unpack_from(mv, pos)
        pos += 8
        if pos + rlen != size:
            raise self._bad(ci, f"records length {rlen} does not fit the {size}-byte record")
        data = mv[pos:pos + rlen]
        if usize > MAX_RECORD:
            raise self._bad(ci, f"claims {usize} bytes uncompressed, more than {MAX_RECORD}")
        try:
            if comp == "":
                pass
            elif comp == "lz4":
                import lz4.frame

                data = memoryview(lz4.frame.decompress(data))
            elif comp == "zstd":
                if self._zstd is None:
                    import zstandard

                    self._zstd = zstandard.ZstdDecompressor()
                data = memoryview(self._zstd.decompress(data, max_output_size=usize))
            else:
                raise self._bad(ci, f"unsupported compression {comp!r} (supported: none, lz4, zstd)")
        except RecordingFileError:
            raise
        except LIB_ERRORS as exc:
            raise self._bad(ci, f"{comp} data do not decompress ({type(exc).__name__}: {exc}): the chunk "
                                f"is damaged") from exc
        if len(data) != usize:
            raise self._bad(ci, f"decompressed to {len(data)} bytes, the chunk says {usize}")
        if self.verify and crc:
            self._check_crc(ci, data, crc, self.turn if comp == "" else -1)
        self.turn ^= 1
        return data


def chunk_payloads(recs: memoryview, ids, path: Path):
    """(channel id, payload offset, payload length, log_time) of the messages of the wanted
    channel ids in the uncompressed records of one chunk, in file order."""
    q = 0
    end = len(recs)
    while q < end:
        if q + 9 > end:
            raise RecordingFileError(path, "record header runs past the end of its chunk")
        op, length = REC.unpack_from(recs, q)
        nxt = q + 9 + length
        if nxt > end:
            raise RecordingFileError(path, f"record of {length} bytes runs past the end of its chunk")
        if op == OP_MESSAGE:
            if length < MSG_HEAD.size:
                raise RecordingFileError(path, f"message record of {length} bytes is too short")
            cid, _, log_time, _ = MSG_HEAD.unpack_from(recs, q + 9)
            if cid in ids:
                yield cid, q + 9 + MSG_HEAD.size, length - MSG_HEAD.size, log_time
        q = nxt


def decode_message(buf, off: int, size: int, lay: Layout, path: Path, name: str) -> tuple[int, int]:
    """Check one payload header; return (first_sample, n_samples)."""
    if size < HEADER_SIZE:
        raise RecordingFileError(path, f"channel {name!r}: message payload of {size} bytes is "
                                       f"shorter than the {HEADER_SIZE}-byte header")
    first, n, nch, code, version = HEADER.unpack_from(buf, off)
    if version != FORMAT_VERSION or nch != 1 or code != lay.code:
        raise RecordingFileError(path, f"channel {name!r}: message header (version {version}, "
                                       f"n_channels {nch}, dtype code {code}) does not match the "
                                       f"layout (version {FORMAT_VERSION}, 1 channel, code {lay.code})")
    if size != HEADER_SIZE + n * lay.dtype.itemsize or n > lay.block or n == 0:
        raise RecordingFileError(path, f"channel {name!r}: message at sample {first} claims {n} "
                                       f"samples in {size - HEADER_SIZE} payload bytes "
                                       f"(block {lay.block}, {lay.dtype.itemsize} B/sample)")
    if first + n > lay.info.n_samples:
        raise RecordingFileError(path, f"channel {name!r}: message holds samples [{first}, {first + n}) "
                                       f"beyond n_samples = {lay.info.n_samples}")
    return first, n



def read_message_index(fh, path: Path, offset: int, cid: int) -> np.ndarray | None:
    """The entries of the MessageIndex record at byte ``offset`` of the file (a chunk index's
    ``message_index_offsets[cid]``): an (n, 2) uint64 array of (log_time [ns], offset of the
    message record in the chunk's uncompressed records [B]), in the file's order; None when
    the bytes there are not a MessageIndex record of channel ``cid``.

    Raises
    ------
    RecordingFileError
        The record runs past the end of the file.
    """
    fh.seek(offset)
    head = fh.read(_INDEX_HEAD.size)
    if len(head) < _INDEX_HEAD.size:
        raise RecordingFileError(path, f"message index at byte {offset} runs past the end of the file")
    op, length, ch, nbytes = _INDEX_HEAD.unpack(head)
    if op != _OP_MESSAGE_INDEX or ch != cid or nbytes % 16 or 2 + 4 + nbytes != length:
        return None
    raw = fh.read(nbytes)
    if len(raw) != nbytes:
        raise RecordingFileError(path, f"message index at byte {offset} runs past the end of the file")
    return np.frombuffer(raw, dtype="<u8").reshape(-1, 2)
