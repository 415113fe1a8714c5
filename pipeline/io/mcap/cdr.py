"""ROS 2 CDR messages decoded many at a time: the message definition (``ros2msg`` schema
text, https://mcap.dev/spec/registry#ros2msg) is parsed into fields, and the byte position of
each wanted field is computed for every message of a chunk at once with numpy (strings and
sequences before it shift it message by message), so a field's values come out of one
gather instead of one Python object per message.

The rules are those of ``mcap_ros2``'s decoder, which stays the reference (:mod:`.bulk`
checks the first and last message of every chunk against it): XCDR1 little-endian payloads
(encapsulation ``00 01``), alignment of an n-byte primitive to n bytes counted from the end
of the 4-byte encapsulation header, strings as a uint32 length and that many bytes, sequences
as a uint32 count then the elements (aligned only when there is one), an empty message type
as one byte, ``builtin_interfaces/Time`` and ``Duration`` as two uint32 unless the schema
defines them. Anything else (big-endian payloads, ``wstring``, a sequence of structs whose
length varies between messages, a field after a ``bool`` array's target...) raises
:class:`Unsupported`, and the caller decodes message by message.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

__all__ = ["Unsupported", "MsgField", "parse_msgdefs", "CdrBatch", "PRIMITIVES"]

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
