"""The names a time column or clock channel goes by, in one list for every format.

A text export (CSV, LabVIEW LVM) heads its time column ``Time [s]``, ``Zeit [s]``,
``Temps (s)``, ``t/ms`` or ``Tiempo in s``; a TDMS file or an HDF5 file from another tool
names its clock channel ``Time`` or ``Zeit``. :data:`TIME_NAMES` are the names of a column
of times in seconds (or ms / us, by its units), :data:`STAMP_NAMES` those of a column of
timestamps, :data:`CLOCK_NAMES` both: what a format checks a channel name against.
:func:`time_header` reads a header field as a time column with its units.
"""

from __future__ import annotations

import re

__all__ = ["TIME_NAMES", "STAMP_NAMES", "CLOCK_NAMES", "TIME_UNITS", "time_header", "is_clock_name"]

#: Names (lower case) of a column or channel of times [s, ms or us]: English, German,
#: French, Spanish, Italian, the short ``t``, and what loggers write besides.
TIME_NAMES = ("time", "t", "time_s", "zeit", "temps", "tiempo", "tempo", "relative time")
#: Names (lower case) of a column or channel of timestamps (date and clock time).
STAMP_NAMES = ("timestamp", "time stamp", "datetime", "date/time", "date time", "date_time")
#: Every name of a clock: :data:`TIME_NAMES` then :data:`STAMP_NAMES`.
CLOCK_NAMES = TIME_NAMES + STAMP_NAMES
#: Units a time column may carry, as seconds per unit (``""``: none given, seconds).
TIME_UNITS = {"": 1.0, "s": 1.0, "sec": 1.0, "ms": 1e-3, "msec": 1e-3, "us": 1e-6, "\u00b5s": 1e-6,
              "\u03bcs": 1e-6}

_NUMBERED_RE = re.compile(r"^(?:time|zeit|temps|tiempo|tempo)\s+\d+(?:\s.*)?$", re.I | re.S)
# 'name [u]', 'name (u)', 'name / u', 'name/u', 'name in u'
_UNITS_RE = re.compile(r"^(?P<name>.*?)\s*(?:\[(?P<a>[^\[\]]*)\]|\((?P<b>[^()]*)\)|/\s*(?P<c>[^/\s]+)"
                       r"|\s+in\s+(?P<d>\S+))\s*$", re.S | re.I)


def _time_name(name: str) -> bool:
    """One of :data:`TIME_NAMES`, or a long one followed by a channel number and a
    description (``Zeit  1 - Standard-Messrate``, as catman names its time channels)."""
    return name.lower() in TIME_NAMES or _NUMBERED_RE.match(name) is not None


def is_clock_name(name) -> bool:
    """True when ``name`` (any case, surrounding blanks ignored) is one of :data:`CLOCK_NAMES`."""
    return isinstance(name, str) and name.strip().lower() in CLOCK_NAMES


def time_header(field) -> tuple[str, str, float] | None:
    """``field`` read as the header of a time column: (name, units, seconds per unit), or
    None when it is not one.

    The name is one of :data:`TIME_NAMES` (any case); the units, when given, follow as
    ``[s]``, ``(s)``, ``/s`` or ``in s`` and are one of :data:`TIME_UNITS` (``Zeit [ms]``:
    1e-3 s per unit). A name without units is in seconds.

    Parameters
    ----------
    field : str
        One header field, quotes and blanks around it already removed or not.

    Returns
    -------
    tuple of (str, str, float) or None
    """
    if not isinstance(field, str):
        return None
    text = field.strip().strip('"').strip()
    if _time_name(text):
        return text, "", 1.0
    m = _UNITS_RE.match(text)
    if m is None:
        return None
    name = m.group("name").strip()
    units = next(u for u in (m.group("a"), m.group("b"), m.group("c"), m.group("d")) if u is not None).strip()
    if not _time_name(name) or units.lower() not in TIME_UNITS and units not in TIME_UNITS:
        return None
    return name, units, TIME_UNITS.get(units, TIME_UNITS.get(units.lower()))
