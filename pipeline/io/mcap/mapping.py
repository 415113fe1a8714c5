"""The mapping of an MCAP file written by another tool onto recording channels: which topic
and which field of its messages feed each channel (``data_schemas/mcap.md``, "Reading MCAP
written by other tools").

A mapping is a list of :class:`TopicField` entries, built by :func:`parse_topics` from what a
user writes (a scene's ``[[input.mcap.channels]]``, or ``meshphase.io.read(path,
topics=...)``): either ``{"sun_T3": "/rig/strain:gauges.sun_T3"}`` (channel name ->
``"TOPIC:FIELD"``) or a list of tables ``{"name": ..., "topic": ..., "field": ..., "kind":
..., "units": ..., "scale": ..., "stamp": ...}``.

Field paths: dotted keys with integer indexes and quoted keys, e.g. ``gauges.sun_T3``,
``data[3]``, ``channels["sun.1"]``, ``header.stamp``.

The fields of decoded messages (dicts from JSON, protobuf messages, ROS 2 objects) are read
here too: the value at a path (:func:`get_field`), numbers and arrays of numbers as samples
(:func:`as_values`), time stamps (:func:`stamp_ns`) and the list of a message's numeric fields
(:func:`numeric_fields`), shared by the per-message decoder path (:mod:`.foreign`) and the
per-chunk one (:mod:`.bulk`), which must agree value for value.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ...recording import CHANNEL_KINDS, ChannelSpec

__all__ = ["TopicField", "parse_topics", "parse_field_path", "format_field_path", "STAMP_SOURCES",
           "FieldError", "get_field", "is_number", "as_values", "stamp_ns", "numeric_fields"]

#: Stamps taken from the MCAP message record rather than from a field of the message.
STAMP_SOURCES = ("log_time", "publish_time")

_SPEC_KEYS = ("kind", "units", "gear", "tooth", "face_position", "description")
_ENTRY_KEYS = {"name", "topic", "field", "scale", "stamp"} | set(_SPEC_KEYS)
_TOKEN = re.compile(r"""\s*(?:
      (?P<key>[A-Za-z_][A-Za-z0-9_]*)          # bare key
    | \[\s*(?P<index>-?\d+)\s*\]               # [3]
    | \[\s*"(?P<qkey>(?:[^"\\]|\\.)*)"\s*\]    # ["key with . or spaces"]
    | (?P<dot>\.)
    )""", re.VERBOSE)


def parse_field_path(text: str, what: str = "field") -> tuple:
    """A field path as a tuple of keys (str) and indexes (int).

    Parameters
    ----------
    text : str
        E.g. ``"gauges.sun_T3"``, ``"data[3]"``, ``'channels["sun.1"]'``.
    what : str
        Name used in error messages.

    Returns
    -------
    tuple of (str or int)

    Raises
    ------
    ValueError
        Empty or malformed path (the position is named).
    """
    if not isinstance(text, str):
        raise TypeError(f"{what} must be a string field path like 'gauges.sun_T3', got {text!r}")
    parts: list = []
    pos, expect_key = 0, True
    s = text.strip()
    if not s:
        raise ValueError(f"{what} is empty: give a field path like 'gauges.sun_T3' or 'data[3]'")
    while pos < len(s):
        m = _TOKEN.match(s, pos)
        if m is None or m.end() == pos:
            raise ValueError(f"{what} {text!r}: cannot parse at character {pos + 1} ({s[pos:]!r}); "
                             "use dotted keys, [index] and [\"quoted key\"]")
        if m.group("dot"):
            if expect_key:
                raise ValueError(f"{what} {text!r}: a '.' at character {pos + 1} without a key before it")
            expect_key = True
        elif m.group("key") is not None:
            if not expect_key:
                raise ValueError(f"{what} {text!r}: key {m.group('key')!r} needs a '.' before it")
            parts.append(m.group("key"))
            expect_key = False
        elif m.group("index") is not None:
            if not parts:
                raise ValueError(f"{what} {text!r}: an [index] needs a field before it")
            parts.append(int(m.group("index")))
            expect_key = False
        else:
            parts.append(re.sub(r"\\(.)", r"\1", m.group("qkey")))
            expect_key = False
        pos = m.end()
    if expect_key:
        raise ValueError(f"{what} {text!r}: ends with '.'")
    return tuple(parts)


def format_field_path(path: tuple) -> str:
    """The text of a field path tuple (inverse of :func:`parse_field_path`)."""
    out = ""
    for p in path:
        if isinstance(p, int):
            out += f"[{p}]"
        elif re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", p):
            out += ("." if out else "") + p
        else:
            out += '["' + p.replace("\\", "\\\\").replace('"', '\\"') + '"]'
    return out


@dataclass(frozen=True)
class TopicField:
    """One recording channel fed by one field of the messages of one MCAP topic.

    Attributes
    ----------
    spec : ChannelSpec
        The channel (name, kind, units of the values after ``scale``...).
    topic : str
        MCAP topic (channel topic) whose messages hold the field.
    path : tuple
        Field path (keys and indexes) to a number (one sample per message) or to an array of
        numbers (consecutive samples, the first at the message's stamp).
    scale : float
        Factor applied to the decoded values to give SI values in ``spec.units`` [-].
    stamp : str or tuple
        ``"log_time"`` (default), ``"publish_time"``, or the field path of a time stamp in
        the message (``{sec, nsec|nanosec}`` or ``{seconds, nanos}`` struct; an integer is
        [ns], a float [s]).
    missing_is_nan : bool
        A message without the field holds NaN (the ``foxglove`` layout leaves NaN and inf
        out) instead of being an error.
    """

    spec: ChannelSpec
    topic: str
    path: tuple
    scale: float = 1.0
    stamp: Any = "log_time"
    missing_is_nan: bool = False

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def field(self) -> str:
        return format_field_path(self.path)

    def stamp_text(self) -> str:
        return self.stamp if isinstance(self.stamp, str) else format_field_path(self.stamp)


def _stamp(value, where: str):
    if value is None:
        return "log_time"
    if isinstance(value, tuple):
        return value
    if not isinstance(value, str):
        raise TypeError(f"{where}: stamp must be 'log_time', 'publish_time' or a field path, got {value!r}")
    return value if value in STAMP_SOURCES else parse_field_path(value, f"{where}: stamp")


def _entry(raw, where: str, default_stamp) -> TopicField:
    if isinstance(raw, TopicField):
        return raw
    if not isinstance(raw, dict):
        raise TypeError(f"{where}: a mapping entry must be a table with name, topic and field, "
                        f"got {type(raw).__name__}")
    unknown = sorted(set(raw) - _ENTRY_KEYS)
    if unknown:
        raise ValueError(f"{where}: unknown key(s) {unknown}; known: {sorted(_ENTRY_KEYS)}")
    for k in ("name", "topic", "field"):
        if k not in raw:
            raise ValueError(f"{where}: {k!r} is missing (an entry needs name, topic and field)")
        if not isinstance(raw[k], str) or not raw[k].strip():
            raise ValueError(f"{where}: {k} must be a non-empty string, got {raw[k]!r}")
    kind = raw.get("kind", "other")
    if kind not in CHANNEL_KINDS:
        raise ValueError(f"{where}: kind must be one of {CHANNEL_KINDS}, got {kind!r}")
    scale = raw.get("scale", 1.0)
    if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not math.isfinite(scale) \
            or scale == 0:
        raise ValueError(f"{where}: scale must be a finite non-zero number, got {scale!r}")
    spec_kw = {k: raw[k] for k in _SPEC_KEYS if k in raw}
    try:
        spec = ChannelSpec(name=raw["name"], **spec_kw)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {exc}") from None
    return TopicField(spec=spec, topic=raw["topic"], path=parse_field_path(raw["field"], f"{where}: field"),
                      scale=float(scale), stamp=_stamp(raw.get("stamp", default_stamp), where))


def parse_topics(topics, *, stamp=None) -> list[TopicField]:
    """The mapping of topics and fields onto channels, checked.

    Parameters
    ----------
    topics : dict or list
        ``{channel name: "TOPIC:FIELD"}`` (the last ``:`` splits topic and field; other
        channel attributes default: kind "other", units "m/m"), or ``{channel name:
        {"topic": ..., "field": ..., ...}}``, or a list of tables each with ``name``,
        ``topic``, ``field`` and optionally ``kind``, ``units``, ``gear``, ``tooth``,
        ``face_position``, ``description``, ``scale`` (values x scale are SI in ``units``)
        and ``stamp``.
    stamp : str, optional
        Default ``stamp`` of every entry: ``"log_time"`` (when None), ``"publish_time"`` or a
        field path.

    Returns
    -------
    list of TopicField

    Raises
    ------
    ValueError
        Empty mapping, duplicate channel names, a malformed entry (named).
    TypeError
        ``topics`` of another type.
    """
    if isinstance(topics, dict):
        entries = []
        for name, val in topics.items():
            if isinstance(val, str):
                topic, sep, fld = val.rpartition(":")
                if not sep or not topic or not fld:
                    raise ValueError(f"topics[{name!r}] = {val!r}: write 'TOPIC:FIELD', e.g. "
                                     f"'/rig/strain:gauges.sun_T3'")
                entries.append({"name": name, "topic": topic, "field": fld})
            elif isinstance(val, dict):
                entries.append({"name": name, **val})
            else:
                raise TypeError(f"topics[{name!r}] must be 'TOPIC:FIELD' or a table, got {val!r}")
    elif isinstance(topics, (list, tuple)):
        entries = list(topics)
    else:
        raise TypeError(f"topics must be a dict {{channel: 'TOPIC:FIELD'}} or a list of tables "
                        f"(name, topic, field), got {type(topics).__name__}")
    if not entries:
        raise ValueError("topics is empty: map at least one channel, e.g. "
                         "{'sun_T3': '/rig/strain:gauges.sun_T3'}")
    out = [_entry(e, f"topics[{i}]" if not isinstance(topics, dict) else f"topics[{e['name']!r}]", stamp)
           for i, e in enumerate(entries)]
    seen: dict = {}
    for e in out:
        if e.name in seen:
            raise ValueError(f"channel {e.name!r} is mapped twice")
        seen[e.name] = e
    return out


def mapping_key(entries: list[TopicField]) -> tuple:
    """A hashable key of a mapping (for caches)."""
    return tuple((e.spec, e.topic, e.path, e.scale, e.stamp, e.missing_is_nan) for e in entries)


@dataclass
class TopicSummary:
    """What a foreign MCAP file holds on one topic (for the listing of a missing mapping)."""

    topic: str
    schema: str
    schema_encoding: str
    message_encoding: str
    messages: int | None
    fields: list = field(default_factory=list)  # (path text, "number" or "array[n]")


# -- fields of decoded messages ----------------------------------------------------------

_MAX_LISTED_FIELDS = 40


class FieldError(LookupError):
    """A field path that a decoded message does not hold; the text is the path up to the
    first missing part."""


def get_field(obj, path: tuple):
    """The value at ``path`` in a decoded message (dict, protobuf message, ROS 2 object)."""
    for i, p in enumerate(path):
        try:
            if isinstance(p, int):
                obj = obj[p]
            elif isinstance(obj, dict):
                obj = obj[p]
            else:
                obj = getattr(obj, p)
        except (KeyError, IndexError, AttributeError, TypeError):
            where = format_field_path(path[:i + 1])
            raise FieldError(where) from None
    return obj


def is_number(x) -> bool:
    """True for an int or float (Python or numpy), False for a bool and anything else."""
    return isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, (bool, np.bool_))


def as_values(x):
    """A float (one sample) or a 1-D float64 array (samples), or None when not numeric.
    JSON null reads as NaN."""
    if is_number(x):
        return float(x)
    if x is None:
        return math.nan
    if isinstance(x, (str, bytes, dict)):
        return None
    if isinstance(x, np.ndarray) or hasattr(x, "__len__"):
        try:
            arr = np.asarray(x)
        except (TypeError, ValueError):
            return None
        if arr.ndim == 1 and arr.dtype.kind in "iuf":
            return arr.astype(np.float64)
        if arr.ndim == 1 and arr.dtype.kind == "O":  # JSON nulls among the numbers
            items = arr.tolist()
            if all(is_number(v) or v is None for v in items):
                return np.array([math.nan if v is None else v for v in items], dtype=np.float64)
    return None


def stamp_ns(stamp, msg, decoded, where: str) -> int:
    """The time stamp [ns] of one message: ``stamp`` is ``"log_time"`` or ``"publish_time"``
    (of the MCAP message record ``msg``) or the field path of a ``{sec, nsec}``, ``{sec,
    nanosec}`` or ``{seconds, nanos}`` struct, an integer [ns] or a float [s] in the decoded
    message; ValueError naming ``where`` otherwise."""
    if stamp == "log_time":
        return int(msg.log_time)
    if stamp == "publish_time":
        return int(msg.publish_time)
    try:
        v = get_field(decoded, stamp)
    except FieldError as exc:
        raise ValueError(f"{where}: stamp field {format_field_path(stamp)!r} not found "
                         f"(at {exc})") from None
    for sec, nsec in (("sec", "nsec"), ("sec", "nanosec"), ("seconds", "nanos")):
        try:
            s, ns = (v[sec], v[nsec]) if isinstance(v, dict) else (getattr(v, sec), getattr(v, nsec))
        except (KeyError, AttributeError, TypeError):
            continue
        return int(s) * 1_000_000_000 + int(ns)
    if is_number(v) and math.isfinite(float(v)):
        return int(v) if isinstance(v, (int, np.integer)) else int(round(float(v) * 1e9))
    raise ValueError(f"{where}: stamp field {format_field_path(stamp)!r} is {v!r}; a stamp is "
                     f"{{sec, nsec}}, {{sec, nanosec}}, {{seconds, nanos}}, an integer [ns] or a float [s]")


def numeric_fields(obj, prefix: tuple, out: list, depth: int = 0) -> None:
    """Append to ``out`` the numeric fields of a decoded message (dict, protobuf message,
    ROS 2 object) below ``prefix``, as (field path text, ``"number"`` or ``"array[n]"``);
    at most 40 fields, 8 levels deep, arrays of arrays by their first element."""
    if len(out) >= _MAX_LISTED_FIELDS or depth > 8:
        return
    v = as_values(obj) if prefix else None
    if isinstance(v, float):
        out.append((format_field_path(prefix), "number"))
        return
    if isinstance(v, np.ndarray):
        if v.size:
            out.append((format_field_path(prefix), f"array[{v.size}]"))
        return
    if isinstance(obj, dict):
        items = list(obj.items())
    elif hasattr(obj, "DESCRIPTOR") and hasattr(obj.DESCRIPTOR, "fields"):  # protobuf
        items = [(f.name, getattr(obj, f.name)) for f in obj.DESCRIPTOR.fields]
    elif hasattr(obj, "__slots__"):  # mcap_ros2's message classes
        items = [(k, getattr(obj, k)) for k in obj.__slots__ if not k.startswith("_")]
    elif isinstance(obj, (list, tuple)) and obj:
        items = [(0, obj[0])]
    else:
        return
    for k, val in items:
        numeric_fields(val, prefix + (k,), out, depth + 1)
