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
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Any

from ...recording import CHANNEL_KINDS, ChannelSpec

__all__ = ["TopicField", "parse_topics", "parse_field_path", "format_field_path", "STAMP_SOURCES"]

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
