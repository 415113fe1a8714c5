"""Messages of one topic decoded many at a time with numpy (:mod:`.bulk` uses them):

**ROS 2 CDR.** The message definition (``ros2msg`` schema text,
https://mcap.dev/spec/registry#ros2msg) is parsed into fields, and the byte position of each
wanted field is computed for every message of a chunk at once with numpy (strings and
sequences before it shift it message by message), so a field's values come out of one
gather instead of one Python object per message.

The rules are those of ``mcap_ros2``'s decoder, which stays the reference (:mod:`.bulk`
checks the first and last message of every chunk against it): XCDR1 little-endian payloads
(encapsulation ``00 01``), alignment of an n-byte primitive to n bytes counted from the end
of the 4-byte encapsulation header, strings as a uint32 length and that many bytes, sequences
as a uint32 count then the elements (aligned only when there is one), an empty message type
as one byte, ``builtin_interfaces/Time`` and ``Duration`` as two uint32 unless the schema
defines them. Anything else (big-endian payloads, ``wstring``, a sequence of structs whose
length varies between messages, a ``bool`` or a string as the wanted field...) raises
:class:`Unsupported`, and the caller decodes message by message.

**JSON.** For the common case of a logger writing the same message shape over and over with only the numbers changing (``{"value": 0.25}``, ``{"stamp":
{"sec": .., "nsec": ..}, "gauges": [..]}``).

The payloads of a chunk are scanned with numpy: a number token starts with ``-`` or a digit
right after ``:``, ``[``, ``,`` or white space and runs over ``0-9 + - . e E``. When every
message has the same number of tokens and the same bytes between them (its *skeleton*), the
messages differ only in their numbers: the first message with token k replaced by the
integer ``1000000 + k`` is parsed by :func:`json.loads` once, which tells which token (or run
of tokens, for an array) a field path names, and that token's text is converted for every
message at once. Otherwise :class:`Unsupported` is raised and the caller parses the messages
with :func:`json.loads`.

Number text to float64 is exact (the same double as Python's ``float`` of the text, which is
what ``json.loads`` gives): a mantissa of up to 19 significant digits M and a decimal exponent
e are read; ``M * 10**e`` is one correctly rounded float64 operation when M <= 2**53 and |e|
<= 22, else one correctly rounded operation in 64-bit-mantissa long double (|e| <= 27), whose
rounding to float64 is exact unless it lands exactly on a midpoint between two doubles; the
remaining tokens (longer mantissas, larger exponents, midpoints, a platform without x87 long
double) go through Python's ``float``. A JSON integer becomes ``float(int)`` (so ``-0`` is
+0.0, as ``json.loads`` gives 0).
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

__all__ = ["Unsupported", "MsgField", "parse_msgdefs", "CdrBatch", "PRIMITIVES", "JsonBatch", "parse_numbers",
           "token_matrix"]

#: Primitive ROS 2 types: numpy dtype (little-endian) and size [B].
PRIMITIVES = {"bool": "u1", "byte": "u1", "char": "i1", "int8": "i1", "uint8": "u1", "int16": "<i2",
              "uint16": "<u2", "int32": "<i4", "uint32": "<u4", "int64": "<i8", "uint64": "<u8",
              "float32": "<f4", "float64": "<f8"}
_SIZES = {k: np.dtype(v).itemsize for k, v in PRIMITIVES.items()}
_STRINGS = ("string", "wstring")
_FIELD = re.compile(r"^(?P<type>[A-Za-z_][A-Za-z0-9_/]*)(?:<=\d+)?(?P<array>\[(?:<=)?(?P<size>\d*)\])?$")
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


class Unsupported(Exception):
    """The messages cannot be decoded in bulk here; decode them one by one."""


@dataclass(frozen=True)
class MsgField:
    """One field of a message definition.

    Attributes
    ----------
    name : str
    base : str
        A primitive type (:data:`PRIMITIVES`), ``string``/``wstring``, or ``pkg/Type``.
    array : str or None
        None (one value), ``"fixed"`` (``size`` values) or ``"seq"`` (a uint32 count first).
    size : int or None
        Length of a fixed array.
    """

    name: str
    base: str
    array: str | None = None
    size: int | None = None


def _parse_one(pkg: str, text: str) -> list[MsgField]:
    fields = []
    for raw in text.replace("\t", " ").splitlines():
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        typ, _, rest = line.partition(" ")
        rest = rest.lstrip()
        if not rest:
            raise Unsupported(f"cannot read the field line {raw!r}")
        if "=" in rest:
            continue  # a constant: not serialized
        name = rest.partition(" ")[0]
        m = _FIELD.match(typ)
        if m is None or not _NAME.match(name):
            raise Unsupported(f"cannot read the field line {raw!r}")
        base = m.group("type")
        if base not in PRIMITIVES and base not in _STRINGS:
            segs = base.split("/")
            if len(segs) == 1:
                base = f"{pkg}/{base}"
            elif len(segs) != 2:
                raise Unsupported(f"type {base!r}")
        array = None
        size = None
        if m.group("array"):
            if m.group("size") and "<=" not in m.group("array"):
                array, size = "fixed", int(m.group("size"))
            else:
                array = "seq"
        fields.append(MsgField(name, base, array, size))
    return fields


def parse_msgdefs(schema_name: str, text: str) -> dict[str, list[MsgField]]:
    """The message types of a ``ros2msg`` schema: ``{"pkg/Type": [MsgField, ...]}``, the
    schema's own type under ``schema_name`` too.

    Raises
    ------
    Unsupported
        A line this parser does not read (the caller decodes message by message).
    """
    time = [MsgField("sec", "uint32"), MsgField("nanosec", "uint32")]
    defs: dict[str, list[MsgField]] = {"builtin_interfaces/Time": time, "builtin_interfaces/Duration": time}
    text = "\n".join(s for s in text.splitlines() if s.strip())
    name = schema_name
    for section in re.split(r"^={3,}$", text, flags=re.MULTILINE):
        section = section.strip()
        m = re.match(r"^MSG:\s+(\S+)$", section, flags=re.MULTILINE)
        if m:
            name = m.group(1)
            section = re.sub(r"^MSG:\s+(\S+)$", "", section, flags=re.MULTILINE)
        pkg, short = name.split("/")[0], name.split("/")[-1]
        fields = _parse_one(pkg, section)
        defs[name] = fields
        defs[f"{pkg}/{short}"] = fields
    if schema_name not in defs:
        raise Unsupported(f"schema {schema_name!r} not defined in its text")
    return defs


def _align(rel: np.ndarray, size: int) -> np.ndarray:
    return rel if size == 1 else rel + (-rel % size)


class CdrBatch:
    """The payloads of many CDR messages of one type, in one byte buffer.

    Parameters
    ----------
    buf : ndarray of uint8
        Bytes holding the payloads.
    start, length : ndarray of int64
        Offset of each payload in ``buf`` and its length [B].
    defs : dict
        :func:`parse_msgdefs` of the messages' schema.
    root : str
        The messages' type (schema name).
    """

    def __init__(self, buf: np.ndarray, start: np.ndarray, length: np.ndarray, defs: dict, root: str):
        if np.any(length < 4):
            raise Unsupported("payload shorter than the CDR header")
        if np.any(buf[start] != 0) or np.any(buf[start + 1] != 1):
            raise Unsupported("not little-endian XCDR1 (encapsulation 00 01)")
        self.buf = buf
        self.base = start + 4
        self.blen = length - 4
        self.defs = defs
        self.root = root

    def _read(self, rel: np.ndarray, kind: str) -> np.ndarray:
        size = _SIZES[kind]
        if np.any(rel + size > self.blen):
            raise Unsupported("a field runs past the end of its message")
        pos = self.base + rel
        if size == 1:
            return self.buf[pos].view(PRIMITIVES[kind])
        raw = self.buf[pos[:, None] + np.arange(size)]
        return raw.view(PRIMITIVES[kind]).reshape(-1)

    def _struct(self, base: str) -> list[MsgField]:
        fields = self.defs.get(base)
        if fields is None:
            raise Unsupported(f"message type {base!r} not defined")
        return fields

    def locate(self, paths: list[tuple]) -> dict:
        """Where each field path is, for every message.

        Parameters
        ----------
        paths : list of tuple
            Field paths (keys and integer indexes).

        Returns
        -------
        dict
            path -> ``("scalar", kind, rel)`` (one primitive per message at offset ``rel``
            from the end of the CDR header), ``("array", kind, rel, count)`` (``count``
            primitives from ``rel``) or ``("struct", type name, rel)``.
        """
        want = {tuple(p) for p in paths}
        found: dict = {}
        rel = np.zeros(self.base.size, dtype=np.int64)
        self._walk(self.root, (), rel, want, found)
        missing = want - set(found)
        if missing:
            raise Unsupported(f"field(s) {sorted(map(str, missing))} not in the message type")
        return found

    def _prim_array(self, f: MsgField, rel: np.ndarray):
        """(rel of the first element, count, rel after the array) of a primitive array."""
        if f.array == "fixed":
            count = np.full(rel.size, f.size, dtype=np.int64)
        else:
            rel = _align(rel, 4)
            count = self._read(rel, "uint32").astype(np.int64)
            rel = rel + 4
        if f.base in _STRINGS:
            raise Unsupported("array of strings")
        size = _SIZES[f.base]
        first = rel if f.base in ("uint8", "byte") else np.where(count > 0, _align(rel, size), rel)
        return first, count, first + count * size

    def _walk(self, typ: str, prefix: tuple, rel: np.ndarray, want: set, found: dict) -> np.ndarray:
        """Advance ``rel`` over one message of type ``typ`` (fields under ``prefix``)."""
        fields = self._struct(typ)
        if not fields:
            return rel + 1  # an empty type is one uint8
        for f in fields:
            if len(found) == len(want):
                return rel
            path = prefix + (f.name,)
            inside = [w for w in want if w[:len(path)] == path and w not in found]
            if f.base in _STRINGS and f.array is None:
                if inside:
                    raise Unsupported(f"{f.name}: a string")
                if f.base == "wstring":
                    raise Unsupported("wstring")
                rel = _align(rel, 4)
                rel = rel + 4 + self._read(rel, "uint32").astype(np.int64)
            elif f.base in PRIMITIVES and f.array is None:
                rel = _align(rel, _SIZES[f.base])
                if path in want:
                    found[path] = ("scalar", f.base, rel)
                rel = rel + _SIZES[f.base]
            elif f.base in PRIMITIVES or f.base in _STRINGS:
                first, count, after = self._prim_array(f, rel)
                for w in inside:
                    if w == path:
                        found[w] = ("array", f.base, first, count)
                    elif len(w) == len(path) + 1 and isinstance(w[-1], int):
                        i = count + w[-1] if w[-1] < 0 else np.full(count.size, w[-1], dtype=np.int64)
                        if np.any((i < 0) | (i >= count)):
                            raise Unsupported(f"{f.name}: index {w[-1]} outside the array")
                        found[w] = ("scalar", f.base, first + i * _SIZES[f.base])
                    else:
                        raise Unsupported(f"{f.name}: no field below a primitive array")
                rel = after
            elif f.array is None:
                if path in want:
                    found[path] = ("struct", f.base, rel)
                rel = self._walk(f.base, path, rel, want, found)
            else:
                if f.array == "fixed":
                    n = f.size
                else:
                    rel = _align(rel, 4)
                    counts = self._read(rel, "uint32")
                    rel = rel + 4
                    n = int(counts[0]) if counts.size else 0
                    if np.any(counts != n):
                        raise Unsupported(f"{f.name}: sequence of structs of varying length")
                if any(len(w) > len(path) and isinstance(w[len(path)], int) and w[len(path)] < 0
                       for w in inside) or path in want:
                    raise Unsupported(f"{f.name}: a struct array as a whole or from its end")
                for k in range(n):
                    rel = self._walk(f.base, path + (k,), rel, want, found)
        return rel

    def values(self, kind: str, rel: np.ndarray) -> np.ndarray:
        """The primitives of type ``kind`` at ``rel`` (one per message), as read."""
        return self._read(rel, kind)

    def array_values(self, kind: str, first: np.ndarray, count: np.ndarray) -> np.ndarray:
        """All elements of a primitive array of every message, concatenated, as read."""
        size = _SIZES[kind]
        total = int(count.sum())
        if np.any(first + count * size > self.blen):
            raise Unsupported("an array runs past the end of its message")
        starts = np.repeat(self.base + first - np.concatenate(([0], np.cumsum(count)[:-1])) * size, count)
        pos = starts + np.arange(total, dtype=np.int64) * size
        if size == 1:
            return self.buf[pos].view(PRIMITIVES[kind])
        return self.buf[pos[:, None] + np.arange(size)].view(PRIMITIVES[kind]).reshape(-1)


# -- JSON ------------------------------------------------------------------------------------

_LUT_NUM = np.zeros(256, dtype=bool)
_LUT_NUM[list(b"0123456789+-.eE")] = True
_LUT_START = np.zeros(256, dtype=bool)
_LUT_START[list(b"0123456789-")] = True
_LUT_DELIM = np.zeros(256, dtype=bool)
_LUT_DELIM[list(b":[, \t\r\n")] = True

_PROBE = 1_000_000


def token_matrix(buf: np.ndarray, start: np.ndarray, length: np.ndarray) -> np.ndarray:
    """(n, max length) uint8 of the byte strings buf[start:start+length], zero-padded."""
    w = int(length.max()) if length.size else 0
    out = np.zeros((start.size, w), dtype=np.uint8)
    if w == 0:
        return out
    whole = start + w <= buf.size
    out[whole] = sliding_window_view(buf, w)[start[whole]]
    for i in np.flatnonzero(~whole):  # near the end of the buffer
        part = buf[start[i]:start[i] + w]
        out[i, :part.size] = part
    out[np.arange(w) >= length[:, None]] = 0
    return out


def _is_digit(c: np.ndarray) -> np.ndarray:
    return np.subtract(c, 48, dtype=np.uint8) < 10


def parse_numbers(mat: np.ndarray, length: np.ndarray):
    """JSON number texts to float64, exactly as ``json.loads`` then ``float``.

    Parameters
    ----------
    mat : ndarray of uint8, shape (n, w)
        One number text per row, zero-padded.
    length : ndarray of int64
        Text lengths [B].

    Returns
    -------
    values : ndarray of float64
    is_int : ndarray of bool
        The text is a JSON integer (no fraction, no exponent).
    mantissa : ndarray of uint64
        The magnitude of an integer text (0 for other texts; saturated at the uint64 maximum
        for an integer of more than 18 digits).

    Raises
    ------
    Unsupported
        A text that is not a JSON number (the caller parses the messages one by one, and
        :func:`json.loads` names the problem).
    """
    n, w = mat.shape
    if w == 0 or np.any(length <= 0):
        raise Unsupported("an empty number")
    mat = np.ascontiguousarray(mat)
    texts = mat.view(f"S{w}").reshape(n)
    # numpy's bytes-to-float cast parses as Python's float() does (correctly rounded) and
    # refuses what float() refuses ("1e", "--1", "1-2", "1e5e5", any letter but e/E ...).
    # JSON refuses more than float() (RFC 8259, section 6): a leading "+", a leading zero
    # before a digit, a dot without digits on both sides; those are checked here.
    try:
        values = texts.astype(np.float64)
    except ValueError:
        raise Unsupported("a token is not a JSON number") from None
    rows = np.arange(n)
    neg = mat[:, 0] == ord("-")
    i0 = neg.astype(np.int64)
    first = mat[rows, np.minimum(i0, w - 1)]
    second = mat[rows, np.minimum(i0 + 1, w - 1)]
    dot = mat == ord(".")
    has_dot = dot.any(axis=1)
    dpos = dot.argmax(axis=1)
    before = mat[rows, np.maximum(dpos - 1, 0)]
    after = mat[rows, np.minimum(dpos + 1, w - 1)]
    ok = (_is_digit(first)                                                # no "+", ".5", "-.5", "e5"
          & ~((first == ord("0")) & (i0 + 1 < length) & _is_digit(second))   # no "01", "-00"
          & (~has_dot | (_is_digit(before) & (dpos > i0) & (dpos + 1 < length) & _is_digit(after))))
    if not ok.all():
        raise Unsupported("a token is not a JSON number")
    is_int = ~has_dot & ~((mat == ord("e")) | (mat == ord("E"))).any(axis=1)
    values[is_int & (values == 0)] = 0.0               # json.loads("-0") is the integer 0
    m = np.zeros(n, dtype=np.uint64)
    small = is_int & (length - i0 <= 18)
    if small.any():
        m[small] = np.abs(texts[small].astype(np.int64)).astype(np.uint64)
    m[is_int & ~small] = np.iinfo(np.uint64).max       # more than 18 digits: saturated
    return values, is_int, m


def _number_chars(buf: np.ndarray) -> np.ndarray:
    """Mask of the bytes ``0-9 + - . e E`` (comparisons: faster than a table lookup)."""
    out = np.subtract(buf, 48, dtype=np.uint8) < 10
    for c in b"+-.eE":
        out |= buf == c
    return out


class JsonBatch:
    """The JSON payloads of a chunk's messages of one channel, tokenized together.

    Parameters
    ----------
    buf : ndarray of uint8
        The chunk's uncompressed records.
    start, length : ndarray of int64
        Offsets of the payloads in ``buf`` (ascending, not overlapping) and their lengths [B].

    Raises
    ------
    Unsupported
        The messages do not all have the first one's skeleton.
    """

    def __init__(self, buf: np.ndarray, start: np.ndarray, length: np.ndarray):
        n = start.size
        if n == 0 or np.any(length <= 0):
            raise Unsupported("empty payload")
        if start[0] == 0:
            raise Unsupported("payload at the start of the buffer")
        end = start + length
        # runs of number characters, broken where a payload starts: a run begins where a
        # number character follows another byte (or a payload starts with one) and ends
        # where one is followed by another byte (or by a payload's first byte)
        num = _number_chars(buf)
        first_of = np.zeros(buf.size + 1, dtype=bool)
        first_of[start] = True
        begins = num.copy()
        begins[1:] &= ~num[:-1]
        begins[start] |= num[start]
        ends = num.copy()
        ends[:-1] &= ~num[1:]
        ends[start - 1] |= num[start - 1] & num[start]
        rs = np.flatnonzero(begins)
        re_ = np.flatnonzero(ends) + 1
        # a token: a run starting with - or a digit after a delimiter or at a payload's start
        tok = _LUT_START[buf[rs]] & (_LUT_DELIM[buf[rs - 1]] | first_of[rs])
        ts, te = rs[tok], re_[tok]
        msg = np.searchsorted(start, ts, side="right") - 1
        inside = (msg >= 0) & (ts < end[np.maximum(msg, 0)])
        ts, te, msg = ts[inside], te[inside], msg[inside]
        if np.any(te > end[msg]):
            raise Unsupported("a number runs past the end of its message")
        counts = np.bincount(msg, minlength=n)
        k = int(counts[0])
        if np.any(counts != k):
            raise Unsupported("messages with different numbers of numbers")
        ts, te = ts.reshape(n, k), te.reshape(n, k)
        # the skeleton: the bytes between the numbers, the same in every message
        seg_start = np.concatenate((start[:, None], te), axis=1)
        seg_len = np.concatenate((ts, end[:, None]), axis=1) - seg_start
        if np.any(seg_len != seg_len[0]):
            raise Unsupported("messages of different shapes")
        for j, size in enumerate(seg_len[0].tolist()):
            if size:
                rows = sliding_window_view(buf, size)[seg_start[:, j]]
                if np.count_nonzero(rows != rows[0]):
                    raise Unsupported("messages of different shapes")
        self.buf, self.n, self.k = buf, n, k
        self.tok_start, self.tok_len = ts, te - ts
        first = bytearray()
        pos = int(start[0])
        for j in range(k):
            first += buf[pos:ts[0, j]].tobytes() + str(_PROBE + j).encode()
            pos = int(te[0, j])
        first += buf[pos:end[0]].tobytes()
        try:
            self.probe = json.loads(first.decode("utf-8"))
        except (ValueError, UnicodeDecodeError):
            raise Unsupported("the first message is not JSON") from None

    def token(self, value) -> int | None:
        """The token index a probed value stands for (None: not a number token)."""
        if type(value) is int and _PROBE <= value < _PROBE + self.k:
            return value - _PROBE
        return None

    def numbers(self, j: int):
        """(values float64, is_int, mantissa) of token ``j`` of every message (:func:`parse_numbers`)."""
        return parse_numbers(token_matrix(self.buf, self.tok_start[:, j], self.tok_len[:, j]), self.tok_len[:, j])
