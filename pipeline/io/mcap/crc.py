"""CRC-32 of MCAP files: the footer's summary CRC, the DataEnd record's data-section CRC,
and ``crc32_combine`` to fold in a chunk's stored CRC without reading its records."""

from __future__ import annotations

import struct
import zlib
from functools import lru_cache
from pathlib import Path

from ...validate import as_int
from ..base import CorruptFileError
from .layout import CHUNK_HEAD, OP_CHUNK, REC, U64, MAGIC

__all__ = ["crc32_combine"]

_CRC_POLY = 0xEDB88320  # CRC-32 (ISO-HDLC, zlib), reflected

try:  # ISA-L's CRC-32 (same polynomial as zlib, SIMD): ~3x zlib's speed where installed
    from isal.isal_zlib import crc32
except ImportError:  # the default: zlib (releases the GIL for large buffers, as does isal)
    crc32 = zlib.crc32


def _crc_mulmod(a: int, b: int) -> int:
    """a * b modulo the CRC-32 polynomial (reflected bit order, as zlib's multmodp)."""
    m = 1 << 31
    p = 0
    while m:
        if a & m:
            p ^= b
            if not a & (m - 1):
                break
        m >>= 1
        b = (b >> 1) ^ _CRC_POLY if b & 1 else b >> 1
    return p


def _x2n_table() -> list[int]:
    t = [0] * 32
    p = 1 << 30  # x^1
    for k in range(32):
        t[k] = p
        p = _crc_mulmod(p, p)
    return t


_X2N = _x2n_table()  # x^(2^k) mod P


@lru_cache(maxsize=1024)
def _x8n(n: int) -> int:
    """x^(8 n) mod P: the factor that shifts a CRC over n zero bytes."""
    p = 1 << 31  # x^0
    k = 3
    while n:
        if n & 1:
            p = _crc_mulmod(_X2N[k & 31], p)
        n >>= 1
        k += 1
    return p


def crc32_combine(crc1: int, crc2: int, len2: int) -> int:
    """CRC-32 of ``A + B`` from ``crc1 = crc32(A)``, ``crc2 = crc32(B)`` and ``len(B)``.

    The algorithm of zlib's ``crc32_combine`` (not exposed by Python's zlib): shift
    ``crc1`` over ``len2`` bytes by multiplying with x^(8 len2) modulo the polynomial.

    Parameters
    ----------
    crc1, crc2 : int
        CRC-32 values (as ``zlib.crc32`` returns).
    len2 : int
        Length of the second block [B], >= 0.

    Returns
    -------
    int
    """
    len2 = as_int(len2, "len2")
    if len2 < 0:
        raise ValueError(f"len2 must be >= 0, got {len2}")
    return _crc_mulmod(_x8n(len2), crc1 & 0xFFFFFFFF) ^ (crc2 & 0xFFFFFFFF)


_FOOTER = struct.Struct("<BQQQI")  # opcode, length (20), summary_start, summary_offset_start, crc
_OP_FOOTER = 0x02
_OP_DATA_END = 0x0F
_IO_BLOCK = 1 << 22  # bytes CRC'd per read while walking the data section


def check_summary_crc(fh, path: Path) -> tuple[int, int]:
    """Check the footer record and the summary CRC (when not 0) before anything parses the
    summary. Returns (footer offset, summary_start)."""
    fh.seek(0, 2)
    size = fh.tell()
    pos = size - 8 - _FOOTER.size
    fh.seek(pos)
    op, length, summary_start, offset_start, crc = _FOOTER.unpack(fh.read(_FOOTER.size))
    if op != _OP_FOOTER or length != 20:
        raise CorruptFileError(path, f"byte {pos} (footer)", f"no footer record before the closing magic "
                                                            f"(opcode {op:#04x}, length {length})")
    start = summary_start or pos
    if not 8 <= start <= pos or (offset_start and not start <= offset_start <= pos):
        raise CorruptFileError(path, f"byte {pos} (footer)", f"footer points outside the file (summary "
                                                            f"at byte {summary_start}, summary offsets at "
                                                            f"byte {offset_start}, footer at byte {pos})")
    if crc:
        fh.seek(start)
        got = crc32(fh.read(pos - start))
        got = crc32(_FOOTER.pack(op, length, summary_start, offset_start, 0)[:-4], got)
        if got != crc:
            raise CorruptFileError(path, f"bytes [{start}, {pos + 25}) (summary section and footer)",
                                   f"summary CRC32 is {got:#010x}, the footer records {crc:#010x}: the "
                                   f"index, channel or schema records are damaged")
    fh.seek(0)
    return pos, start


def check_data_crc(fh, path: Path, data_end_limit: int) -> bool:
    """Walk the records of the data section and check the DataEnd record's CRC (when not 0).

    The CRC covers bytes [0, start of DataEnd). Uncompressed chunks with a stored CRC are
    not read: their record prefix is CRC'd and the stored CRC of their records combined in
    (:func:`crc32_combine`); a damaged record byte is caught by that chunk's own CRC when it
    is read. Other records (and compressed chunks) are read and CRC'd. Returns True when a
    CRC was checked, False when the file stores none.
    """
    crc = crc32(MAGIC)
    pos = 8
    fh.seek(pos)
    head_size = 9 + CHUNK_HEAD.size
    while True:
        if pos + 9 > data_end_limit:
            raise CorruptFileError(path, f"byte {pos}", f"the data section ends without a DataEnd record "
                                                        f"(records run into the summary at byte {data_end_limit})")
        head = fh.read(9)
        op, length = REC.unpack(head)
        end = pos + 9 + length
        if end > data_end_limit:
            raise CorruptFileError(path, f"byte {pos}", f"record (opcode {op:#04x}) of {length} bytes runs past "
                                                        f"the data section (ends at byte {data_end_limit})")
        if op == _OP_DATA_END:
            if length < 4:
                raise CorruptFileError(path, f"byte {pos}", f"DataEnd record of {length} bytes is too short")
            (stored,) = struct.unpack("<I", fh.read(4))
            if stored and stored != crc:
                raise CorruptFileError(path, f"bytes [0, {pos}) (data section)",
                                       f"data-section CRC32 is {crc:#010x}, the DataEnd record says "
                                       f"{stored:#010x}: a record outside the chunks' records (header, "
                                       f"metadata, chunk headers, message indexes) is damaged")
            return bool(stored)
        crc = crc32(head, crc)
        done = 9
        if op == OP_CHUNK and length >= CHUNK_HEAD.size + 4 + 8:
            fixed = fh.read(CHUNK_HEAD.size)
            _, _, usize, ccrc, clen = CHUNK_HEAD.unpack(fixed)
            if head_size + clen + 8 <= 9 + length:
                rest = fh.read(clen + 8)
                (rlen,) = U64.unpack_from(rest, clen)
                if ccrc and clen == 0 and head_size + clen + 8 + rlen == 9 + length and usize == rlen:
                    crc = crc32(rest, crc32(fixed, crc))
                    crc = crc32_combine(crc, ccrc, rlen)
                    pos = end
                    fh.seek(pos)
                    continue
                crc = crc32(rest, crc32(fixed, crc))
                done = head_size + clen + 8
            else:
                crc = crc32(fixed, crc)
                done = head_size
        left = 9 + length - done
        while left > 0:
            piece = fh.read(min(left, _IO_BLOCK))
            if not piece:
                raise CorruptFileError(path, f"byte {pos}", "record runs past the end of the file")
            crc = crc32(piece, crc)
            left -= len(piece)
        pos = end

