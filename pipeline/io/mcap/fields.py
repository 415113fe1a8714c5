"""Fields of decoded MCAP messages (dicts from JSON, protobuf messages, ROS 2 objects): the
value at a field path, numbers and arrays of numbers as samples, time stamps, and the list of
a message's numeric fields. Shared by the per-message decoder path (:mod:`.foreign`) and the
per-chunk one (:mod:`.bulk`), which must agree value for value."""

from __future__ import annotations

import math

import numpy as np

from .mapping import format_field_path

__all__ = ["FieldError", "get_field", "is_number", "as_values", "stamp_ns", "numeric_fields"]

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
