"""CSV: a time column plus one column per channel (pandas C engine).

One module of about 1,000 lines on purpose: the header parser, the time-grid checks, the block
reader and the writer follow one layout and share its rules; split, they would pass private
names between the halves.

File layout (full description in ``data_schemas/csv_header.md``)::

    # meshphase {"format": "meshphase-csv", "format_version": 1, "fs": 5120.0, "t0": 0.0, ...}
    time [s],sun_1 [m/m],ring_1 [m/m]
    0.0,1.234e-05,-2.5e-06
    0.0001953125,1.3e-05,NaN

* Line 1 (our own files only): ``# meshphase `` and one line of JSON holding what the columns
  cannot: format version, fs [Hz], t0 [s], n_samples, dtype, start_datetime, the full channel
  specs, meta and history. Other lines starting with ``#`` before the header are ignored.
* Header: ``time [s]`` then ``<name> [<units>]`` per channel (csv-quoted when needed).
* Rows: time = t0 + i / fs, then the samples. float64 is written with the shortest repr that
  round-trips, float32 with ``%.9g`` (bit-exact through float64 parsing); NaN as ``NaN``, +-inf as
  ``inf``/``-inf``. Our own files round-trip bit-exactly (NaN payloads excepted).

A plain CSV without the preamble (e.g. from a spreadsheet) reads too: kinds default to
``"other"``, units come from the ``[...]`` of each header field (empty, with a FormatWarning,
when missing), t0 is the first time value and fs is inferred from the first and last time and
the row count (the shortest decimal fs that fits the time span to 1 % of a sample). The time
column may be headed ``time``, ``t`` or ``time_s`` with units ``s``, ``ms`` or ``us``. Its
fields may be separated by commas, semicolons or tabs (the one the header line holds most
of: LabVIEW's spreadsheet files are tab-separated, a spreadsheet in a decimal-comma locale
writes ``;``), and with ``;`` or tabs the numbers may carry a decimal comma. Times printed to
fewer digits than the sample interval needs (``%.4f`` at 5120 Hz: up to 0.26 sample off the
grid) are checked to within their printed step (rounded or truncated). The time column may
also hold ISO 8601 timestamps (``2026-11-28 10:00:00.000195``, headed ``time``, ``timestamp``
or ``datetime``; an offset such as ``+01:00`` or ``Z`` is allowed): the recording then starts
at t0 = 0 and ``start_datetime`` is the first row's timestamp.

Every row read is checked against the uniform grid t0 + i / fs: a time that does not increase
raises RecordingFileError "non-monotonic time at line L"; a step between rows more than
2 x :data:`TIME_TOLERANCE` sample intervals from 1 / fs, or a time more than
:data:`TIME_TOLERANCE` sample intervals off the grid, raises "non-uniform time at line L".

Structure (every file, once per file identity, one vectorised pass over the bytes; raises
:class:`~meshphase.io.base.CorruptFileError` with the line number and byte offset):

* the file ends with a newline: a last line without one was cut short (a number cut
  mid-token, "-7.85" of "-7.85e-11", is recognisable only this way, or by a missing field);
* every data line holds exactly as many commas as the header has fields minus one (lines
  end with "\n" or "\r\n"; data fields are never quoted);
* blank lines only at the end (plain CSVs), none in our own files;
* our own files hold exactly the preamble's n_samples rows (fewer: "truncated").

A plain CSV cut exactly after a newline is a shorter valid file: nothing can tell.
"""

from __future__ import annotations

import codecs
import csv as _csv
import io
import json
import math
import os
import re
import warnings
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import numpy as np

from ..errors import FormatWarning
from ..recording import ChannelSpec, Recording
from ..validate import as_int, as_positive_int
from .base import (CorruptFileError, RecordingFileError, RecordingInfo, check_start_datetime, check_verify,
                   checked_write_blocks, dumps_json, nice_fs, spec_from_dict, warn_nonfinite)
from .registry import FormatSpec
from .timenames import CLOCK_NAMES, time_header

__all__ = ["NAME", "FORMAT", "FORMAT_VERSION", "TIME_TOLERANCE", "sniff", "read_info",
           "read", "write", "write_blocks", "iter_blocks", "MAX_CHANNELS", "MAX_HEADER_LINE"]

NAME = "csv"
#: The format's declaration in the registry (:mod:`meshphase.io.registry`).
FORMAT = FormatSpec(
    name=NAME, module=__name__, suffixes=(".csv",), writable=True, streaming_write=True, catch_all=True,
    read_options={"header_row": int, "skip_rows": int, "fs": float, "decimal": str, "delimiter": str},
    write_options={"chunk_rows": int}, read_libraries=("pandas",),
    description="delimited text with a time column (ours with a JSON preamble)")
#: Version of the preamble written by :func:`write`.
FORMAT_VERSION = 1
#: Largest allowed distance of a time value from the uniform grid t0 + i / fs, in sample
#: intervals [-]. 0.1 accepts times rounded to 1 us at 51.2 kHz and still catches any dropped,
#: repeated or shifted sample.
TIME_TOLERANCE = 0.1

#: Most channel columns a CSV header may have: a header of more is refused before any
#: column is parsed further (a bad export or a transposed table, not a recording).
MAX_CHANNELS = 1024
#: Longest preamble, comment or header line read [bytes] (a preamble holds the channel specs
#: and the history; a header of MAX_CHANNELS long names fits many times over).
MAX_HEADER_LINE = 16 * 1024 ** 2
#: Column names a FormatWarning lists before summarising the rest as a count.
_LISTED = 5

_TAG = "# meshphase "
#: field separators a plain CSV may use, in order of preference on a tie
_SEPARATORS = ("\t", ";", ",")
#: data rows whose time field's printed digits give the time column's resolution
_QUANTUM_ROWS = 64
#: units a timestamp column may carry
_STAMP_UNITS = ("", "utc", "local")
_CLOCK_RE = re.compile(r"\d{1,2}:\d{2}:\d{2}(?:[.,](\d+))?")
#: Field separators the ``delimiter`` option may name.
DELIMITERS = (",", ";", "\t", "|")
#: lines of a plain CSV searched for its header (the metadata block above it included)
_LOOK_LINES = 500
#: longest field of a units line under the header [characters]
_UNIT_CHARS = 24
#: lines a "no header found" message quotes
_SHOWN_LINES = 5
_FIELD_RE = re.compile(r"^(?P<name>.*?)\s*\[(?P<units>[^\[\]]*)\]\s*$", re.S)
_PREAMBLE_KEYS = {"format", "format_version", "fs", "t0", "n_samples", "dtype", "start_datetime",
                  "channels", "meta", "history"}


# ---------------------------------------------------------------------------- sniff
def sniff(head: bytes) -> bool:
    """True when ``head`` is text (no control characters but tab and line ends) in which a
    non-comment line holds a comma, a semicolon or a tab: the header may sit below a
    metadata block whose first lines hold none (a title line, a free-text comment)."""
    if not head or b"\x00" in head:
        return False
    if head.startswith(codecs.BOM_UTF8):
        head = head[len(codecs.BOM_UTF8):]
    if head.startswith(_TAG.encode() + b"{"):
        return True
    try:
        text = codecs.getincrementaldecoder("utf-8")().decode(head, final=False)
    except UnicodeDecodeError:
        text = head.decode("latin-1")
    if any(ord(c) < 32 and c not in "\t\r\n" for c in text):
        return False
    for line in text.splitlines():
        s = line.strip()
        if s and not s.startswith("#") and any(c in s for c in _SEPARATORS):
            return True
    return False


# ---------------------------------------------------------------------------- header
@dataclass
class _Head:
    n_head: int                      # lines before the first data row (preamble, comments, header)
    preamble: dict | None
    fields: list[str]                # header fields (time first)
    names: list[str]
    units: list[str]
    time_scale: float
    encoding: str
    ends_with_newline: bool
    size: int
    data_offset: int = 0             # byte offset of the first data row
    specs: list[ChannelSpec] = field(default_factory=list)
    sep: str = ","                   # field separator
    decimal: str = "."               # decimal mark of the numbers
    time_quantum: float = 0.0        # resolution the times are printed to [s] (0: full)
    epoch: str | None = None         # first row's ISO 8601 timestamp (a timestamp column)
    timed: bool = True               # the first column is the time (else fs was given)
    meta: dict = field(default_factory=dict)   # the metadata block above the header
    fs: float | None = None          # the fs option [Hz]


def _separator(header: str) -> str:
    """The field separator of a plain CSV: the one of :data:`_SEPARATORS` its header line
    holds most of (a comma on a tie with none)."""
    counts = {c: header.count(c) for c in _SEPARATORS}
    best = max(_SEPARATORS, key=lambda c: (counts[c], -_SEPARATORS.index(c)))
    return best if counts[best] else ","


def _units_row(fh, sep: str, n_header: int) -> list[str] | None:
    """The units of a plain CSV whose header line is followed by a line of units (``s,m/m,V``,
    as DIAdem and catman exports write): the fields of that line when it has the header's
    ``n_header`` fields and none of them is a number or a timestamp (``fh`` then after it),
    else None (``fh`` where it was)."""
    at = fh.tell()
    raw = fh.readline(MAX_HEADER_LINE + 1)
    try:
        line = raw.decode("utf-8")
    except UnicodeDecodeError:
        line = raw.decode("latin-1")
    line = line.rstrip("\r\n")
    fields = [f.strip().strip('"').strip("[]").strip() for f in line.split(sep)]

    def numeric(f: str) -> bool:
        try:
            float(f.replace(",", "."))
            return True
        except ValueError:
            return False

    if (not raw.endswith(b"\n") or len(fields) != n_header or not line.strip()
            or any(numeric(f) for f in fields if f) or _stamp(fields[0]) is not None
            or not all(_unit_like(f) for f in fields)):
        fh.seek(at)
        return None
    return fields


def _unit_like(text: str) -> bool:
    """A field of a units line: a short token without blanks or brackets (``m/m``, ``µm/m``,
    ``V``, ``s``, ``°C``), or empty."""
    return len(text) <= _UNIT_CHARS and not any(c.isspace() or c in "[]()" for c in text)


def _time_token(line: str, sep: str) -> str:
    return line.split(sep, 1)[0].strip().strip('"')


def _decimals(token: str) -> int | None:
    """Digits after the decimal mark of a plainly printed number; None for an exponent form
    (its resolution is not in the digits) or no number."""
    t = token.strip().lstrip("+-")
    if not t or "e" in t.lower() or not t.replace(".", "", 1).replace(",", "", 1).isdigit():
        return None
    for mark in (".", ","):
        if mark in t:
            return len(t) - t.index(mark) - 1
    return 0


def _stamp(token: str) -> str | None:
    """``token`` as a normalised ISO 8601 timestamp when it is one, else None."""
    import datetime as _dt

    if ":" not in token or "-" not in token:
        return None
    try:
        return _dt.datetime.fromisoformat(token).isoformat()
    except ValueError:
        return None


def _stamp_seconds(tokens, epoch: str) -> np.ndarray:
    """Seconds from ``epoch`` of ISO 8601 timestamps (offsets honoured; timestamps without
    one are taken as in the epoch's zone) [s]; NaN where one does not parse."""
    import pandas as pd

    t = pd.to_datetime(pd.Series(np.asarray(tokens, dtype=object)), format="ISO8601", utc=True,
                       errors="coerce")
    t0 = pd.to_datetime(pd.Series([epoch]), format="ISO8601", utc=True)
    return ((t - t0.iloc[0]).dt.total_seconds()).to_numpy(dtype=np.float64, na_value=np.nan)


def _dialect(fh, sep: str) -> tuple[str, float, str | None]:
    """(decimal mark, printed time resolution in the time column's units, first row's
    timestamp when the time column holds ISO 8601 timestamps) of a plain CSV's data rows
    (``fh`` at the first data row; left there)."""
    at = fh.tell()
    rows = []
    for _ in range(_QUANTUM_ROWS):
        raw = fh.readline()
        if not raw or not raw.strip():
            break
        rows.append(raw.decode("latin-1").rstrip("\r\n"))
    fh.seek(at)
    tokens = [_time_token(r, sep) for r in rows]
    epoch = _stamp(tokens[0]) if tokens else None
    rest = [r.split(sep, 1)[1] if sep in r else "" for r in rows] if epoch else rows
    decimal = "," if sep != "," and any("," in r for r in rest) else "."
    if epoch:
        clocks = [_CLOCK_RE.search(tk) for tk in tokens]
        digits = [len(m.group(1) or "") if m else None for m in clocks]
    else:
        digits = [_decimals(tk) for tk in tokens]
    quantum = 0.0
    if rows and all(d is not None for d in digits):
        quantum = 10.0 ** -max(digits)
    return decimal, quantum, epoch


def _split_field(text: str) -> tuple[str, str | None]:
    m = _FIELD_RE.match(text)
    if m is None:
        return text.strip(), None
    return m.group("name").strip(), m.group("units").strip()


def _header_field(name: str, units: str) -> str:
    return f"{name} [{units}]"


@dataclass(frozen=True)
class _Options:
    """The layout options of a plain CSV (see :func:`read_info`), checked."""
    header_row: int | None = None    # 1-based line of the column names
    fs: float | None = None          # sample rate [Hz] of a file without a time column
    decimal: str | None = None
    delimiter: str | None = None


def _options(header_row=None, skip_rows=None, fs=None, decimal=None, delimiter=None) -> _Options:
    """The read options checked: ``header_row`` (1-based) and ``skip_rows`` (lines before
    the header) name the same line, ``fs`` [Hz] is finite and positive, ``decimal`` is
    ``.`` or ``,``, ``delimiter`` one of :data:`DELIMITERS` (``"tab"`` for a tab)."""
    if header_row is not None:
        header_row = as_positive_int(header_row, "header_row")
    if skip_rows is not None:
        skip_rows = as_int(skip_rows, "skip_rows")
        if skip_rows < 0:
            raise ValueError(f"skip_rows must be >= 0 (lines before the header), got {skip_rows}")
        if header_row is not None and header_row != skip_rows + 1:
            raise ValueError(f"header_row = {header_row} and skip_rows = {skip_rows} name different header "
                             f"lines ({header_row} and {skip_rows + 1}); give one of them")
        header_row = skip_rows + 1
    if fs is not None:
        if isinstance(fs, bool) or not isinstance(fs, (int, float, np.integer, np.floating)) \
                or not (math.isfinite(float(fs)) and float(fs) > 0):
            raise ValueError(f"fs must be a finite positive sample rate [Hz], got {fs!r}")
        fs = float(fs)
    if decimal is not None and decimal not in (".", ","):
        raise ValueError(f"decimal must be '.' or ',', got {decimal!r}")
    if delimiter is not None:
        if isinstance(delimiter, str) and delimiter.lower() == "tab":
            delimiter = "\t"
        if delimiter not in DELIMITERS:
            raise ValueError(f"delimiter must be one of {', '.join(repr(d) for d in DELIMITERS)} or 'tab', "
                             f"got {delimiter!r}")
        if delimiter == decimal:
            raise ValueError(f"delimiter and decimal are both {delimiter!r}: the numbers could not be told apart")
    return _Options(header_row=header_row, fs=fs, decimal=decimal, delimiter=delimiter)


def _decode(raw: bytes) -> tuple[str, str]:
    try:
        return raw.decode("utf-8"), "utf-8"
    except UnicodeDecodeError:
        return raw.decode("latin-1"), "latin-1"


class _Lines:
    """The first lines of a file, read as they are asked for: (start offset, end offset,
    text without the line end, encoding, ends with a newline) each."""

    def __init__(self, path, fh):
        self.path, self.fh, self.items, self.eof = path, fh, [], False

    def get(self, k: int):
        while len(self.items) <= k and not self.eof:
            at = self.fh.tell()
            raw = self.fh.readline(MAX_HEADER_LINE + 1)
            if not raw:
                self.eof = True
                break
            if len(raw) > MAX_HEADER_LINE:
                raise RecordingFileError(self.path, f"line {len(self.items) + 1} (byte {at}) is longer than "
                                                    f"{MAX_HEADER_LINE} bytes: not a preamble or header line of "
                                                    "a recording")
            body = raw[len(codecs.BOM_UTF8):] if not self.items and raw.startswith(codecs.BOM_UTF8) else raw
            text, enc = _decode(body)
            self.items.append((at, self.fh.tell(), text.rstrip("\r\n"), enc, raw.endswith(b"\n")))
        return self.items[k] if k < len(self.items) else None

    def text(self, k: int) -> str | None:
        item = self.get(k)
        return None if item is None else item[2]


def _numeric(token: str) -> bool:
    """A number as a plain CSV prints one (decimal point or comma, NaN, inf), or empty."""
    t = token.strip().strip('"').strip()
    if not t:
        return True
    try:
        float(t.replace(",", ".", 1) if t.count(",") == 1 and "." not in t else t)
        return True
    except ValueError:
        return False


def _fields(line: str, sep: str) -> list[str]:
    return next(_csv.reader([line], delimiter=sep)) if line else [""]


def _time_like(field: str) -> bool:
    """A header field that names the time column (any units: checked later)."""
    return time_header(field) is not None or _split_field(field)[0].lower() in CLOCK_NAMES


def _data_row(line: str | None, sep: str, n: int, stamp_first: bool = True) -> bool | None:
    """True when ``line`` is a row of ``n`` numbers (the first may be a timestamp); False
    for a row of numbers with another field count; None when it is no row of numbers."""
    if line is None or not line.strip():
        return None
    fields = line.split(sep)
    first_ok = _numeric(fields[0]) or (stamp_first and _stamp(fields[0].strip().strip('"')) is not None)
    if not first_ok or not all(_numeric(f) for f in fields[1:]) or not any(f.strip() for f in fields):
        return None
    return len(fields) == n


def _units_line(line: str | None, sep: str, n: int) -> bool:
    if line is None or not line.strip():
        return False
    fields = [f.strip().strip('"').strip("[]").strip() for f in line.split(sep)]
    return (len(fields) == n and not any(_numeric(f) for f in fields if f)
            and _stamp(fields[0]) is None and all(_unit_like(f) for f in fields))


def _header_at(lines: _Lines, k: int, sep: str, fs_given: bool) -> bool:
    """True when line ``k`` (0-based) is a plain CSV's header: its first field names the
    time (or, with ``fs`` given, no field is a number), and the next line, or the one after
    a units line, is a row of as many numbers, or only blank lines follow. Raises
    CorruptFileError when a time header is followed by a row of numbers of another count."""
    text = lines.text(k)
    if text is None or not text.strip() or text.startswith("#"):
        return False
    fields = _fields(text, sep)
    timed = _time_like(fields[0])
    if not timed and not (fs_given and not any(_numeric(f) for f in fields)):
        return False
    n = len(fields)
    nxt = lines.text(k + 1)
    row = _data_row(nxt, sep, n)
    if row is None and _units_line(nxt, sep, n):
        nxt_k = k + 2
        row = _data_row(lines.text(nxt_k), sep, n)
    else:
        nxt_k = k + 1
    if row:
        return True
    if row is False and timed:
        at, _, line, _, _ = lines.get(nxt_k)
        got = len(line.split(sep))
        raise CorruptFileError(lines.path, f"line {nxt_k + 1} (byte {at})",
                               f"{got} field(s), the header (line {k + 1}) has {n}: malformed row")
    if row is None:
        j = k + 1
        while lines.text(j) is not None and not lines.text(j).strip():
            j += 1
        return lines.text(j) is None       # a header with no rows
    return False


def _find_header(path, lines: _Lines, opts: _Options) -> tuple[int, str]:
    """(0-based line of the header, field separator) of a plain CSV."""
    def sep_of(k):
        return opts.delimiter or _separator(lines.text(k))

    if opts.header_row is not None:
        k = opts.header_row - 1
        if lines.get(k) is None:
            raise RecordingFileError(path, f"header_row = {opts.header_row} is past the end of the file "
                                           f"({len(lines.items)} lines)")
        return k, sep_of(k)
    looked = []
    for k in range(_LOOK_LINES):
        text = lines.text(k)
        if text is None:
            break
        if text.strip() and not text.startswith("#"):
            looked.append(k)
            if _header_at(lines, k, sep_of(k), opts.fs is not None):
                return k, sep_of(k)
    # no header by the rules: the first line over a row of as many numbers is taken, and its
    # first column is then refused with the reason
    for k in looked:
        sep = sep_of(k)
        n = len(_fields(lines.text(k), sep))
        nxt = lines.text(k + 1)
        if _data_row(nxt, sep, n) or (_units_line(nxt, sep, n) and _data_row(lines.text(k + 2), sep, n)):
            return k, sep
    last = lines.items[-1] if lines.items else None
    if last is not None and not last[4]:
        raise CorruptFileError(path, f"line {len(lines.items)} (byte {last[0]})",
                               "truncated: the file ends inside the preamble or header line (no newline)")
    if not looked:
        raise RecordingFileError(path, "no header line (only comments or blank lines)")
    shown = "; ".join(f"line {k + 1}: {lines.text(k)[:60]!r}" for k in looked[:_SHOWN_LINES])
    raise RecordingFileError(path, f"no header found in the first {len(lines.items)} line(s) ({shown}"
                                   f"{'; ...' if len(looked) > _SHOWN_LINES else ''}): a header names the "
                                   f"time column first (Time, Zeit, Temps, t ... [s]) and is followed by "
                                   f"rows of as many numbers; give header_row= (its line number), or fs= "
                                   f"[Hz] when the file has no time column")


def _metadata(lines: list[str], sep: str) -> dict:
    """The lines above a plain CSV's header as ``{"metadata": {key: value}, "lines": [...]}``:
    ``key<sep>value`` -> value, ``key<sep>v1<sep>v2...`` -> [v1, v2, ...], ``key: value``
    -> value; any other line (and a repeated key) kept as it is in ``lines``."""
    md, raw = {}, []
    for line in lines:
        fields = [f.strip() for f in _fields(line, sep)]
        while fields and not fields[-1]:
            fields.pop()
        key = fields[0] if fields else ""
        if len(fields) == 1 and re.match(r"^[^:=]*[A-Za-z][^:=]*[:=]", key):
            key, value = (s.strip() for s in re.split(r"[:=]", key, maxsplit=1))
            fields = [key, value] if value else [key]
        key = key.rstrip(":").strip()
        if len(fields) >= 2 and key and key not in md:
            md[key] = fields[1] if len(fields) == 2 else fields[1:]
        else:
            raw.append(line)
    return {"metadata": md, "lines": raw}


def _read_head(path, opts: _Options = _Options()) -> _Head:
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file")
    size = path.stat().st_size
    if size == 0:
        raise RecordingFileError(path, "file is empty (0 bytes)")
    with open(path, "rb") as fh:
        lines = _Lines(path, fh)
        first = lines.text(0)
        preamble = None
        if first is not None and first.startswith(_TAG):
            if not lines.get(0)[4]:
                raise CorruptFileError(path, "line 1 (byte 0)",
                                       "truncated: the file ends inside the preamble or header line (no newline)")
            try:
                preamble = json.loads(first[len(_TAG):])
            except json.JSONDecodeError as exc:
                raise RecordingFileError(path, f"line 1: meshphase preamble is not valid JSON ({exc})") from exc
            if not isinstance(preamble, dict):
                raise RecordingFileError(path, "line 1: meshphase preamble must be a JSON object")
            k = 1
            while lines.text(k) is not None and (lines.text(k).startswith("#") or not lines.text(k).strip()):
                k += 1
            if lines.get(k) is None:
                raise CorruptFileError(path, f"byte {size} (end of file)", "truncated: the file ends after "
                                                                           "the preamble, before the header line")
            sep = ","
        else:
            k, sep = _find_header(path, lines, opts)
        at, end, header, encoding, newline = lines.get(k)
        if not newline:
            raise CorruptFileError(path, f"line {k + 1} (byte {at})",
                                   "truncated: the file ends inside the preamble or header line (no newline)")
        above = [] if preamble is not None else [
            lines.text(j) for j in range(k) if lines.text(j).strip() and not lines.text(j).startswith("#")]
        n_head = k + 1
        data_offset = end
        fh.seek(data_offset)
        fields = next(_csv.reader([header], delimiter=sep))
        if len(fields) - 1 > MAX_CHANNELS:
            raise RecordingFileError(path, f"line {n_head}: header of {len(fields) - 1} channel columns, more than "
                                           f"the {MAX_CHANNELS} a recording may have (MAX_CHANNELS)")
        units_row, decimal, quantum, epoch = None, ".", 0.0, None
        if preamble is None:
            units_row = _units_row(fh, sep, len(fields))
            if units_row is not None:
                n_head += 1
                data_offset = fh.tell()
            decimal, quantum, epoch = _dialect(fh, sep)
            if opts.decimal is not None:
                decimal = opts.decimal
        fh.seek(max(0, size - 1))
        ends_with_newline = fh.read(1) == b"\n"
    if encoding != "utf-8":
        warnings.warn(FormatWarning(f"{path}: header is not UTF-8; decoded as latin-1"), stacklevel=3)
    if decimal == sep:
        raise RecordingFileError(path, f"decimal mark and field separator are both {sep!r}")
    timed = preamble is not None or opts.fs is None or _time_like(fields[0])
    c0 = 1 if timed else 0
    if len(fields) < 1 + c0 and not (preamble is not None and preamble.get("channels") == []):
        raise RecordingFileError(path, f"line {n_head}: header {header[:80]!r} has no channel columns "
                                       f"(expected 'time [s],<name> [<units>],...')")
    if units_row is not None:          # 'time,sun,ring' then 's,m/m,m/m'
        fields = [f if _split_field(f)[1] is not None or not u else _header_field(f.strip(), u)
                  for f, u in zip(fields, units_row)]
    scale = 1.0
    if timed:
        th = time_header(fields[0])
        tname, tunits = _split_field(fields[0])
        if epoch is not None:
            if tname.lower() not in CLOCK_NAMES or (tunits or "").lower() not in _STAMP_UNITS:
                raise RecordingFileError(path, f"line {n_head}: first column holds timestamps ({epoch}); it must be "
                                               f"headed 'time', 'timestamp' or 'datetime' (units none, UTC or "
                                               f"local), got {fields[0]!r}")
        elif th is None:
            raise RecordingFileError(path, f"line {n_head}: first column must be the time, headed 'time [s]' "
                                           f"(or Zeit, Temps, Tiempo, Tempo, t; units s, ms or us) or holding ISO "
                                           f"8601 timestamps, got {fields[0]!r}; a file without a time column "
                                           f"reads with fs= (its sample rate [Hz]), a header further down with "
                                           f"header_row=")
        else:
            scale = th[2]
    names, units = [], []
    for f in fields[c0:]:
        nm, un = _split_field(f)
        names.append(nm)
        units.append(un)
    meta = {}
    if above:
        meta = {"csv": {"header_row": k + 1, **_metadata(above, sep)}}
    return _Head(n_head=n_head, preamble=preamble, fields=fields, names=names, units=units,
                 time_scale=scale, encoding=encoding,
                 ends_with_newline=ends_with_newline, size=size, data_offset=data_offset,
                 sep=sep, decimal=decimal, time_quantum=quantum * scale,
                 epoch=epoch, timed=timed, meta=meta, fs=opts.fs)


def _duplicates(names) -> list[str]:
    seen, dup = set(), set()
    for n in names:
        (dup if n in seen else seen).add(n)
    return sorted(dup)


def _check_preamble(path, head: _Head) -> RecordingInfo:
    p = head.preamble
    if p.get("format") != "meshphase-csv":
        raise RecordingFileError(path, f"line 1: preamble format must be 'meshphase-csv', got {p.get('format')!r}")
    version = p.get("format_version")
    if not isinstance(version, int) or isinstance(version, bool) or version < 1:
        raise RecordingFileError(path, f"line 1: preamble format_version must be a positive integer, got {version!r}")
    if version > FORMAT_VERSION:
        raise RecordingFileError(path, f"written with CSV preamble version {version}; this reader knows "
                                       f"versions up to {FORMAT_VERSION}")
    unknown = sorted(set(p) - _PREAMBLE_KEYS)
    if unknown:
        warnings.warn(FormatWarning(f"{path}: ignored unknown preamble key(s) {unknown}"), stacklevel=3)
    fs = p.get("fs")
    if isinstance(fs, bool) or not isinstance(fs, (int, float)) or not (math.isfinite(fs) and fs > 0):
        raise RecordingFileError(path, f"missing or non-positive sample rate (preamble fs = {fs!r})")
    t0 = p.get("t0", 0.0)
    if isinstance(t0, bool) or not isinstance(t0, (int, float)) or not math.isfinite(t0):
        raise RecordingFileError(path, f"line 1: preamble t0 must be a finite number, got {t0!r}")
    n = p.get("n_samples")
    if isinstance(n, bool) or not isinstance(n, int) or n < 0:
        raise RecordingFileError(path, f"line 1: preamble n_samples must be a non-negative integer, got {n!r}")
    dtype = p.get("dtype", "float64")
    if dtype not in ("float32", "float64"):
        raise RecordingFileError(path, f"line 1: preamble dtype must be 'float32' or 'float64', got {dtype!r}")
    chans = p.get("channels")
    if not isinstance(chans, list) or not all(isinstance(c, dict) for c in chans):
        raise RecordingFileError(path, "line 1: preamble channels must be a list of channel specs")
    dup = _duplicates([c.get("name") for c in chans])
    if dup:
        raise RecordingFileError(path, f"duplicate channel name(s) {dup} in the preamble")
    specs = [spec_from_dict(c, path, f"line 1: preamble channels[{i}]") for i, c in enumerate(chans)]
    meta = p.get("meta", {})
    if not isinstance(meta, dict):
        raise RecordingFileError(path, f"line 1: preamble meta must be a JSON object, got {type(meta).__name__}")
    history = p.get("history", [])
    if not isinstance(history, list):
        raise RecordingFileError(path, f"line 1: preamble history must be a JSON array, got {type(history).__name__}")
    start = check_start_datetime(p.get("start_datetime"), path)
    expected = [_header_field(s.name, s.units) for s in specs]
    if head.fields[1:] != expected:
        raise RecordingFileError(path, f"line {head.n_head}: header columns {head.fields[1:]} do not match the "
                                       f"preamble's channels {expected}")
    if head.time_scale != 1.0:
        raise RecordingFileError(path, f"line {head.n_head}: time column must be in seconds in a meshphase CSV")
    if not head.ends_with_newline:
        raise CorruptFileError(path, f"byte {head.size} (end of file)",
                               "truncated: the file does not end with a newline (last row cut short)")
    head.specs = specs
    return RecordingInfo(path=str(path), format=NAME, fs=float(fs), n_samples=n, channels=specs, t0=float(t0),
                         start_datetime=start, meta=meta, history=history,
                         extra={"format_version": version, "dtype": dtype, "preamble": True,
                                "header_lines": head.n_head, "encoding": head.encoding})


def _plain_info(path, head: _Head) -> RecordingInfo:
    """Header of a CSV without preamble: count rows, read first and last time, infer fs."""
    dup = _duplicates(head.names)
    if dup:
        raise RecordingFileError(path, f"line {head.n_head}: duplicate channel name(s) {dup} in the header")
    empty = [i + 1 + int(head.timed) for i, n in enumerate(head.names) if not n]
    if empty:
        raise RecordingFileError(path, f"line {head.n_head}: header column(s) {empty} have no name")
    no_units = [n for n, u in zip(head.names, head.units) if u is None]
    if no_units:
        more = f" and {len(no_units) - _LISTED} more" if len(no_units) > _LISTED else ""
        warnings.warn(FormatWarning(f"{path}: header column(s) {no_units[:_LISTED]}{more} carry no '[units]'; "
                                    "units left empty"), stacklevel=3)
    specs = []
    for n, u in zip(head.names, head.units):
        try:
            specs.append(ChannelSpec(name=n, kind="other", units=u or ""))
        except (ValueError, TypeError) as exc:
            raise RecordingFileError(path, f"line {head.n_head}: bad channel column {n!r}: {exc}") from exc
    head.specs = specs
    n, first, last = _scan(path, head)
    extra = {"format_version": None, "dtype": "float64", "preamble": False, "header_lines": head.n_head,
             "encoding": head.encoding, "time_column": head.timed}
    if not head.timed:                 # the rate given: the rows are the grid from t0 = 0
        return RecordingInfo(path=str(path), format=NAME, fs=head.fs, n_samples=n, channels=specs, t0=0.0,
                             meta=head.meta, extra=extra)
    if n < 2 and head.fs is not None:
        t0 = _parse_time(path, first, head.n_head + 1, head) * head.time_scale if n else 0.0
        start = None
        if head.epoch is not None:
            t0, start = 0.0, head.epoch
        return RecordingInfo(path=str(path), format=NAME, fs=head.fs, n_samples=n, channels=specs, t0=float(t0),
                             start_datetime=start, meta=head.meta, extra=extra)
    if n < 2:
        raise RecordingFileError(path, f"missing or non-positive sample rate: cannot infer it from {n} data row(s) "
                                       f"(need at least 2)")
    t_first = _parse_time(path, first, head.n_head + 1, head) * head.time_scale
    t_last = _parse_time(path, last, head.n_head + n, head) * head.time_scale
    span = t_last - t_first
    if not span > 0:
        raise RecordingFileError(path, f"missing or non-positive sample rate: time runs from {t_first!r} s to "
                                       f"{t_last!r} s over {n} rows (non-monotonic time)")
    fs = nice_fs((n - 1) / span, n, span, head.time_quantum)
    if head.fs is not None:
        # the time column and the given rate must tell the same grid
        if abs((n - 1) / head.fs - span) > TIME_TOLERANCE / head.fs + head.time_quantum:
            raise RecordingFileError(path, f"fs = {head.fs!r} Hz given, but the time column spans {span!r} s over "
                                           f"{n} rows: {fs!r} Hz")
        fs = head.fs
    start = None
    if head.epoch is not None:
        t_first, start = 0.0, head.epoch
    if _rounding(head, fs) >= 1.0 / fs:
        warnings.warn(FormatWarning(
            f"{path}: the time column is printed to {head.time_quantum:.3g} s, too coarse for the "
            f"sample interval 1/fs = {1.0 / fs:.4g} s: a dropped or repeated sample cannot be seen "
            f"in it; the rows are taken as the uniform grid t0 + i/fs"), stacklevel=3)
    return RecordingInfo(path=str(path), format=NAME, fs=fs, n_samples=n, channels=specs, t0=float(t_first),
                         start_datetime=start, meta=head.meta, extra=extra)


def _rounding(head: _Head, fs: float) -> float:
    """How far the printing may have moved a time [s]: the step the times are printed to
    (loggers round or truncate), 0 when the sample interval is a whole number of those steps
    (the grid then prints exactly)."""
    q = head.time_quantum
    if q > 0:
        k = 1.0 / (fs * q)                     # sample interval in printed steps
        if abs(k - round(k)) <= 1e-6 * max(1.0, k):
            return 0.0
    return q


def _parse_time(path, line: bytes, lineno: int, head: _Head | None = None) -> float:
    sep, decimal = (head.sep, head.decimal) if head is not None else (",", ".")
    first = _time_token(line.decode("latin-1").strip(), sep)
    if head is not None and head.epoch is not None:
        v = float(_stamp_seconds([first], head.epoch)[0])
        if not math.isfinite(v):
            raise RecordingFileError(path, f"line {lineno}: time {first!r} is not an ISO 8601 timestamp")
        return v
    try:
        v = float(first.replace(decimal, ".") if decimal != "." else first)
    except ValueError as exc:
        raise RecordingFileError(path, f"line {lineno}: time {first!r} is not a number") from exc
    if not math.isfinite(v):
        raise RecordingFileError(path, f"line {lineno}: time {first!r} is not finite")
    return v


_SCAN_BLOCK = 1 << 22  # bytes per step of the structure scan
# structure scans of the last few files: identity -> (n rows, first row, last row)
_SCANS: "OrderedDict[tuple, tuple[int, bytes, bytes]]" = OrderedDict()
_SCANS_MAX = 16


def _scan(path, head: _Head) -> tuple[int, bytes, bytes]:
    """Check the structure of the data lines (see the module notes); return the number of
    data rows (trailing blank lines excluded), the first and the last data row. Cached by
    file identity (device, inode, size, mtime)."""
    st = os.stat(path)
    key = (os.path.realpath(path), st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, head.data_offset,
           len(head.fields))
    hit = _SCANS.get(key)
    if hit is not None:
        _SCANS.move_to_end(key)
        return hit
    out = _scan_structure(path, head)
    _SCANS[key] = out
    while len(_SCANS) > _SCANS_MAX:
        _SCANS.popitem(last=False)
    return out


def _scan_structure(path, head: _Head) -> tuple[int, bytes, bytes]:
    """The structure scan of :func:`_scan`, uncached: the data lines read in blocks of
    ``_SCAN_BLOCK`` bytes (see :class:`_RowScan`), then the file's end checked."""
    scan = _RowScan(path, head)
    buf = bytearray(_SCAN_BLOCK)
    with open(path, "rb", buffering=0) as fh:
        fh.seek(scan.pos)
        while True:
            k = fh.readinto(buf)
            if not k:
                break
            scan.feed(np.frombuffer(buf, np.uint8, k))
        size = scan.pos
        if scan.line_start < size:
            fh.seek(max(scan.line_start, size - 40))
            tail = fh.read(40)
            raise scan.bad_line(scan.line, scan.line_start,
                                f"truncated: the last line does not end with a newline: the file was "
                                f"cut mid-row (it ends with {tail.decode('latin-1')!r}; if the file is "
                                f"complete, add a final newline)")
        first = last = b""
        if scan.n_rows:
            fh.seek(head.data_offset)
            first = fh.readline()
            fh.seek(scan.last_span[0])
            last = fh.read(scan.last_span[1] - scan.last_span[0])
    return scan.n_rows, first, last


class _RowScan:
    """Counts the data rows of a CSV block by block (vectorised over each block's lines) and
    raises CorruptFileError at the first malformed row (wrong field count) or misplaced
    blank line; a line may span blocks."""

    def __init__(self, path, head: _Head):
        self.path = path
        self.expected = len(head.fields) - 1   # separators per data line
        self.sep = ord(head.sep)
        self.own = head.preamble is not None
        self.pos = head.data_offset            # file offset of the next block
        self.line = head.n_head + 1            # file line number of the next line to end
        self.line_start = self.pos             # its byte offset
        self.carry = 0                         # commas seen so far in that line
        self.prev_byte = -1                    # last byte of the previous block
        self.blank_from = None                 # (line, offset) of the first blank line of a trailing run
        self.n_rows = 0
        self.last_span = None                  # (start, end) of the last non-blank line

    def bad_line(self, ln, off, problem) -> CorruptFileError:
        return CorruptFileError(self.path, f"line {ln} (byte {off})", problem)

    def feed(self, a: np.ndarray) -> None:
        """Scan the next block ``a`` of the file (bytes as uint8)."""
        k = a.size
        nl = np.flatnonzero(a == 10)
        if not nl.size:
            self.carry += int(np.count_nonzero(a == self.sep))
            self.prev_byte = int(a[-1])
            self.pos += k
            return
        cm = np.flatnonzero(a == self.sep)
        before = np.searchsorted(cm, nl)
        counts = np.diff(before, prepend=0)
        counts[0] += self.carry
        self.carry = int(cm.size - before[-1])
        starts = np.empty_like(nl)
        starts[0] = self.line_start - self.pos
        starts[1:] = nl[:-1] + 1
        lengths = nl - starts
        # byte before each newline ('\r' of a CRLF blank line), from the previous block if needed
        cr = np.where(nl > 0, a[np.maximum(nl - 1, 0)], self.prev_byte) == 13
        blank = (counts == 0) & ((lengths == 0) | ((lengths == 1) & cr))
        rows = ~blank
        self._check(counts, starts, blank, rows)
        self.n_rows += int(rows.sum())
        if rows.any():
            j = int(np.flatnonzero(rows)[-1])
            self.last_span = (self.pos + int(starts[j]), self.pos + int(nl[j]))
        if blank[-1]:
            if self.blank_from is None:
                run = np.flatnonzero(~blank)
                i = int(run[-1]) + 1 if run.size else 0
                self.blank_from = (self.line + i, self.pos + int(starts[i]))
        else:
            self.blank_from = None
        self.line += nl.size
        self.line_start = self.pos + int(nl[-1]) + 1
        self.prev_byte = int(a[-1])
        self.pos += k

    def _check(self, counts, starts, blank, rows) -> None:
        """Raise at the first problem among the lines of a block (field ``counts`` - 1,
        ``starts`` in the block, ``blank`` and data ``rows`` masks)."""
        if self.blank_from is not None and rows.any():  # a blank run of earlier blocks, then a row
            ln, off = self.blank_from
            raise self.bad_line(ln, off, "blank line inside the data rows")
        wrong = (counts != self.expected) & rows
        problems = []  # (index in block, message): the first one in the file is reported
        if wrong.any():
            i = int(np.argmax(wrong))
            problems.append((i, f"{int(counts[i]) + 1} field(s), the header has {self.expected + 1}: "
                                f"malformed row"))
        if blank.any():
            i = int(np.argmax(blank))
            if self.own:
                problems.append((i, "blank line in a meshphase CSV (none are written)"))
            elif rows[i:].any():
                problems.append((i, "blank line inside the data rows"))
        if problems:
            i, problem = min(problems)
            raise self.bad_line(self.line + i, self.pos + int(starts[i]), problem)


def read_info(path, *, verify: bool = True, header_row: int | None = None, skip_rows: int | None = None,
              fs: float | None = None, decimal: str | None = None, delimiter: str | None = None) -> RecordingInfo:
    """Header of a CSV recording.

    Our own files: preamble and header line only (and the final newline). Plain CSVs: also
    the structure scan (see the module notes), which counts the rows, and the first and last
    time value to infer fs (no samples are parsed). ``verify`` is accepted for the
    registry's uniform options: CSV stores no checksum, the structure is always checked.

    Parameters
    ----------
    path : str or Path
    verify : bool
    header_row : int, optional
        1-based line number of the column-name line (as an editor and the error messages
        count); found by content when None (see the module notes).
    skip_rows : int, optional
        Lines before the header (``header_row = skip_rows + 1``; both given must agree).
    fs : float, optional
        Sample rate [Hz] of a file without a time column (its first column is then a
        channel and t0 = 0). With a time column it must agree with the times.
    decimal : {".", ","}, optional
        Decimal mark of the numbers (detected when None).
    delimiter : {",", ";", "\\t", "|"}, optional
        Field separator (``"tab"`` names a tab; detected from the header line when None).

    The layout options are not used with our own files (the preamble states the layout);
    ``fs`` must then equal the preamble's.

    Raises
    ------
    RecordingFileError
        No header found (the message quotes the first lines looked at), ``header_row`` past
        the end of the file, no time column and no ``fs``, bad time column.
    CorruptFileError
        A row with another field count than the header, a truncated file.
    ValueError, TypeError
        Bad option values.
    """
    check_verify(verify)
    opts = _options(header_row, skip_rows, fs, decimal, delimiter)
    head = _read_head(path, opts)
    if head.preamble is not None:
        info = _check_preamble(path, head)
        if opts.fs is not None and abs(opts.fs - info.fs) > 1e-9 * info.fs:
            raise RecordingFileError(path, f"fs = {opts.fs!r} Hz given, the preamble says {info.fs!r} Hz")
        return info
    return _plain_info(path, head)


# ---------------------------------------------------------------------------- reading
def _parse(path, head: _Head, cols: list[int], dtype, skip: int, nrows: int | None, **kw):
    """pandas C engine on rows skip... (nrows of them, or to the end when None).

    Options are kept to the minimum (no usecols unless a subset is asked for, one dtype when
    the file has one) because each costs parse time.
    """
    import pandas as pd

    ncols = len(head.fields)
    c0 = int(head.timed)
    opts = {}
    if len(cols) != ncols - c0:
        opts["usecols"] = [0] * c0 + [c + c0 for c in cols]
    if head.epoch is not None:
        opts["dtype"] = {0: str, **{c + 1: dtype for c in cols}}
    elif not head.timed:
        opts["dtype"] = dtype
    else:
        opts["dtype"] = np.float64 if dtype == np.float64 else {0: np.float64, **{c + 1: dtype for c in cols}}
    if nrows is not None:
        opts["nrows"] = nrows
    if head.decimal != ".":
        opts["decimal"] = head.decimal
    if head.encoding != "utf-8":
        # only when needed: an explicit encoding routes pandas through a slower decoding reader
        # (UTF-8 is its default; measured 1.6x slower parse with encoding="utf-8" given)
        opts["encoding"] = head.encoding
    try:
        return pd.read_csv(path, sep=head.sep, header=None, names=list(range(ncols)), skiprows=skip, engine="c",
                           skip_blank_lines=False, **opts, **kw)
    except pd.errors.EmptyDataError:
        return None
    except pd.errors.ParserError as exc:
        raise RecordingFileError(path, f"malformed rows: {exc}") from exc
    except UnicodeDecodeError as exc:
        raise RecordingFileError(path, f"not UTF-8 text ({exc})") from exc
    except ValueError as exc:
        where = _locate_bad(path, skip, nrows, head)
        raise RecordingFileError(path, f"non-numeric value in the data rows: {exc}{where}") from exc


def _locate_bad(path, skip: int, nrows: int, head: _Head) -> str:
    """Line number of the first unparseable value (slow path, only after an error)."""
    import pandas as pd

    try:
        df = pd.read_csv(path, sep=head.sep, header=None, skiprows=skip, nrows=nrows, dtype=str,
                         keep_default_na=False, skip_blank_lines=False)
    except (ValueError, pd.errors.ParserError):
        return ""
    for col in df.columns[1:] if head.epoch is not None else df.columns:
        s = df[col]
        if head.decimal != ".":
            s = s.str.replace(head.decimal, ".", regex=False)
        num = pd.to_numeric(s.where(~s.isin(["NaN", "nan", ""]), "nan"), errors="coerce")
        bad = num.isna() & ~s.isin(["NaN", "nan", ""])
        if bad.any():
            i = int(np.flatnonzero(bad.to_numpy())[0])
            return f" (first at line {skip + i + 1}, column {int(col) + 1}: {s.iloc[i]!r})"
    return ""


def _frame_arrays(df, dtype, head: _Head) -> tuple[np.ndarray | None, np.ndarray]:
    if not head.timed:
        t = None
    elif head.epoch is not None:
        t = _stamp_seconds(df[0].to_numpy(dtype=object), head.epoch)
    else:
        t = np.asarray(df[0].to_numpy(dtype=np.float64))
    data = df.iloc[:, int(head.timed):].to_numpy(dtype=dtype)
    if not data.flags.writeable:
        # pandas (copy-on-write) hands out a read-only view of its block; the DataFrame is dropped
        # right after, so the block becomes ours alone.
        data.flags.writeable = True
    return t, data


def _check_time(path, head: _Head, info: RecordingInfo, t: np.ndarray, row0: int) -> None:
    """Raise RecordingFileError naming the line when ``t`` (rows row0...) leaves the grid
    (``t`` None: no time column, nothing to check)."""
    if t is None or t.size == 0:
        return
    if head.time_scale != 1.0:
        t = t * head.time_scale
    bad = ~np.isfinite(t)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise RecordingFileError(path, f"missing or non-finite time at line {head.n_head + row0 + k + 1}")
    # how far a row's time may sit from the grid t0 + i/fs [s]: TIME_TOLERANCE sample
    # intervals, plus what printing the times may have moved them
    moved = _rounding(head, info.fs)
    tol = TIME_TOLERANCE / info.fs + moved
    if t.size > 1:
        d = np.diff(t)
        # times printed coarser than a sample interval repeat: they must not go back
        rising = d >= 0 if moved >= 1.0 / info.fs else d > 0
        if not rising.all():
            k = int(np.flatnonzero(~rising)[0]) + 1
            raise RecordingFileError(path, f"non-monotonic time at line {head.n_head + row0 + k + 1} (data row "
                                           f"{row0 + k}): t = {float(t[k])!r} s after {float(t[k - 1])!r} s")
        # a step far from 1/fs (dropped, repeated or shifted sample) is reported where it happens
        d -= 1.0 / info.fs
        np.abs(d, out=d)
        if not (d <= 2 * tol).all():
            k = int(np.flatnonzero(~(d <= 2 * tol))[0]) + 1
            raise RecordingFileError(path, f"non-uniform time at line {head.n_head + row0 + k + 1} (data row "
                                           f"{row0 + k}): step {float(t[k] - t[k - 1])!r} s from the previous row, "
                                           f"expected 1/fs = {1.0 / info.fs!r} s (fs = {info.fs!r} Hz, tolerance "
                                           f"{2 * tol * info.fs:.3g} sample)")
    expected = np.arange(row0, row0 + t.size, dtype=np.float64)
    expected /= info.fs
    expected += info.t0
    expected -= t
    np.abs(expected, out=expected)
    if not (expected <= tol).all():
        k = int(np.flatnonzero(~(expected <= tol))[0])
        want = info.t0 + (row0 + k) / info.fs
        raise RecordingFileError(path, f"non-uniform time at line {head.n_head + row0 + k + 1} (data row {row0 + k}): "
                                       f"t = {float(t[k])!r} s, expected {want!r} s on the uniform grid "
                                       f"t0 + i/fs (fs = {info.fs!r} Hz, tolerance {tol * info.fs:.3g} sample)")


def _setup(path, channels, opts: _Options):
    head = _read_head(path, opts)
    if head.preamble is not None:
        info = _check_preamble(path, head)
        rows, _, _ = _scan(path, head)
        if rows < info.n_samples:
            raise CorruptFileError(path, f"byte {head.size} (end of file)",
                                   f"truncated: {rows} data rows, the preamble says n_samples = {info.n_samples}")
        if rows > info.n_samples:
            raise RecordingFileError(path, f"more data rows than the preamble's n_samples = {info.n_samples} "
                                           f"({rows} rows)")
        if opts.fs is not None and abs(opts.fs - info.fs) > 1e-9 * info.fs:
            raise RecordingFileError(path, f"fs = {opts.fs!r} Hz given, the preamble says {info.fs!r} Hz")
    else:
        info = _plain_info(path, head)
    names = info.check_channels(channels) if info.names else []
    index = {n: i for i, n in enumerate(info.names)}
    wanted = [index[n] for n in names]
    cols = sorted(wanted)
    at = {w: i for i, w in enumerate(cols)}
    perm = [at[w] for w in wanted]
    dtype = np.dtype(info.extra["dtype"])
    return head, info, names, cols, perm, dtype


def _recording(info: RecordingInfo, data, names, i0: int) -> Recording:
    by_name = {c.name: c for c in info.channels}
    return Recording(data, info.fs, [by_name[n] for n in names], t0=info.t0 + i0 / info.fs,
                     start_datetime=info.start_datetime, meta=info.meta, history=info.history)


def read(path, channels=None, i0: int = 0, i1: int | None = None, *, verify: bool = True,
         header_row: int | None = None, skip_rows: int | None = None, fs: float | None = None,
         decimal: str | None = None, delimiter: str | None = None) -> Recording:
    """Rows ``i0 <= i < i1`` of the named channels (all when None) of a CSV recording.

    The structure of the whole file is checked once (final newline, field count of every
    line, row count of our own files; see the module notes), and the time column against
    the uniform grid t0 + i / fs for every row read. ``verify`` and the layout options
    (``header_row``, ``skip_rows``, ``fs``, ``decimal``, ``delimiter``) as in
    :func:`read_info`.

    Raises
    ------
    CorruptFileError
        Truncated file or malformed row (line number and byte offset named).
    RecordingFileError
        Bad header or preamble, non-numeric values, time off the grid.

    Returns
    -------
    Recording
        float32 when the preamble says so, else float64; Fortran-ordered (channel-major).
    """
    check_verify(verify)
    opts = _options(header_row, skip_rows, fs, decimal, delimiter)
    head, info, names, cols, perm, dtype = _setup(path, channels, opts)
    n = info.n_samples
    i0 = as_int(i0, "i0")
    i1 = n if i1 is None else as_int(i1, "i1")
    if not 0 <= i0 <= i1 <= n:
        raise ValueError(f"{path}: sample range [{i0}, {i1}) outside the recording's [0, {n})")
    m = i1 - i0
    if m == 0:
        data = np.empty((0, len(cols)), dtype=dtype)
        return _recording(info, data[:, perm], names, i0)
    own = head.preamble is not None
    # a read up to the last row parses to the end of the file (cheaper than nrows, and a
    # surplus row shows that the file and its preamble disagree)
    df = _parse(path, head, cols, dtype, head.n_head + i0, None if i1 == n else m)
    got = 0 if df is None else len(df)
    if got < m:
        raise RecordingFileError(path, f"truncated: expected {m} data rows from row {i0}, found {got}"
                                       + (f" (preamble n_samples = {n})" if own else ""))
    if got > m:
        if own:
            raise RecordingFileError(path, f"more data rows than the preamble's n_samples = {n}")
        df = df.iloc[:m]  # trailing blank lines of a plain CSV
    t, data = _frame_arrays(df, dtype, head)
    del df
    _check_time(path, head, info, t, i0)
    if perm != sorted(perm):
        data = np.asfortranarray(data[:, perm])
    warn_nonfinite(path, data, names, i0)
    return _recording(info, data, names, i0)


def iter_blocks(path, n_block: int, n_overlap: int, channels=None, *, verify: bool = True,
                header_row: int | None = None, skip_rows: int | None = None, fs: float | None = None,
                decimal: str | None = None, delimiter: str | None = None) -> Iterator[Recording]:
    """Blocks of ``n_block`` rows plus ``n_overlap`` following rows, parsed in one pass.

    The structure is checked first, as in :func:`read`; the layout options as in
    :func:`read_info`.

    Block k covers rows [k n_block, (k + 1) n_block + n_overlap), clipped to the recording;
    each row is parsed once (pandas ``chunksize``), so the cost is one read of the file.
    """
    import pandas as pd

    n_block = as_positive_int(n_block, "n_block")
    n_overlap = as_int(n_overlap, "n_overlap")
    if n_overlap < 0:
        raise ValueError(f"n_overlap must be >= 0, got {n_overlap}")
    check_verify(verify)
    opts = _options(header_row, skip_rows, fs, decimal, delimiter)
    head, info, names, cols, perm, dtype = _setup(path, channels, opts)
    n = info.n_samples
    if n == 0:
        return
    own = head.preamble is not None
    reader = _parse(path, head, cols, dtype, head.n_head, None if own else n, chunksize=n_block)
    if reader is None:
        raise RecordingFileError(path, f"truncated: expected {n} data rows, found 0")
    pending: list[np.ndarray] = []      # row arrays not yet fully emitted, in order
    pending_rows = 0
    start = 0                            # file row index of pending[0][0]
    parsed = 0
    with reader:
        chunks = iter(reader)
        exhausted = False
        while start < n:
            while not exhausted and pending_rows < min(n - start, n_block + n_overlap):
                try:
                    df = next(chunks)
                except StopIteration:
                    exhausted = True
                    break
                except pd.errors.ParserError as exc:
                    raise RecordingFileError(path, f"malformed rows: {exc}") from exc
                except ValueError as exc:
                    raise RecordingFileError(path, f"non-numeric value in the data rows: {exc}") from exc
                t, data = _frame_arrays(df, dtype, head)
                del df
                if parsed + len(data) > n:
                    raise RecordingFileError(path, f"more data rows than the preamble's n_samples = {n}")
                _check_time(path, head, info, t, parsed)
                parsed += len(data)
                pending.append(data)
                pending_rows += len(data)
            if pending_rows < min(n - start, n_block + n_overlap):
                raise RecordingFileError(path, f"truncated: expected {n} data rows, found {parsed}"
                                               + (f" (preamble n_samples = {n})" if own else ""))
            want = min(n - start, n_block + n_overlap)
            block = np.concatenate(pending, axis=0)[:want] if len(pending) > 1 else pending[0][:want]
            block = np.asfortranarray(block[:, perm])
            warn_nonfinite(path, block, names, start)
            yield _recording(info, block, names, start)
            # drop the rows before the next block start
            drop = min(n_block, pending_rows)
            while drop and pending:
                if len(pending[0]) <= drop:
                    drop -= len(pending[0])
                    pending_rows -= len(pending[0])
                    pending.pop(0)
                else:
                    pending[0] = pending[0][drop:]
                    pending_rows -= drop
                    drop = 0
            start += n_block
        if own:
            try:
                next(chunks)
            except StopIteration:
                pass
            else:
                raise RecordingFileError(path, f"more data rows than the preamble's n_samples = {n}")


# ---------------------------------------------------------------------------- writing
def _format_block(times: np.ndarray, data: np.ndarray) -> str:
    import pandas as pd

    if data.dtype == np.float32:
        # %.9g: 9 significant digits identify every float32, and parsing them as float64 then
        # rounding to float32 never meets a tie (the digits sit far from the midpoints)
        df = pd.DataFrame(data, copy=False)
        df.insert(0, "t", times.astype(str))
        return df.to_csv(header=False, index=False, float_format="%.9g", na_rep="NaN", lineterminator="\n")
    df = pd.DataFrame(np.column_stack([times, data]), copy=False)
    # float64: pandas' default formatting is the shortest repr that round-trips
    return df.to_csv(header=False, index=False, na_rep="NaN", lineterminator="\n")


def write(recording: Recording, path, *, chunk_rows: int = 65536) -> None:
    """Write ``recording`` as a meshphase CSV (preamble, header, rows) to ``path``.

    Parameters
    ----------
    recording : Recording
    path : str or Path
    chunk_rows : int
        Rows formatted per step [-] (memory stays bounded for long recordings).
    """
    if not isinstance(recording, Recording):
        raise TypeError(f"recording must be a Recording, got {type(recording).__name__}")
    write_blocks(recording, [recording.data], path, dtype=recording.data.dtype,
                 chunk_rows=chunk_rows)


def write_blocks(header, blocks, path, *, dtype="float64", chunk_rows: int = 65536) -> None:
    """Write a recording given as a header and consecutive blocks of samples (streaming).

    Parameters
    ----------
    header : Recording, RecordingInfo or alike
        ``fs``, ``t0``, ``n_samples``, ``channels``, ``start_datetime``, ``meta``,
        ``history`` (samples, if any, not read).
    blocks : iterable of ndarray, shape (k, n_channels)
        The samples, in order; together exactly ``header.n_samples`` rows.
    path : str or Path
    dtype : {"float32", "float64"}
        Sample type (named in the preamble, decides the number format).
    chunk_rows : int
        Rows formatted per step [-].
    """
    chunk_rows = as_positive_int(chunk_rows, "chunk_rows")
    dtype = np.dtype(dtype)
    if dtype not in (np.float32, np.float64):
        raise TypeError(f"dtype must be float32 or float64, got {dtype}")
    for spec in header.channels:
        if any(c in spec.name + spec.units for c in "\r\n"):
            raise ValueError(f"channel {spec.name!r}: a line break in a channel name or units cannot go in a "
                             f"CSV header")
    n = int(header.n_samples)
    fs = float(header.fs)
    t_end = header.t0 + n / fs
    span = max(abs(header.t0), abs(t_end))
    if np.spacing(span) > 0.01 / fs:
        raise ValueError(f"t0 = {header.t0!r} s is too large for a CSV time column at fs = {fs!r} Hz: "
                         f"float64 times near {span:.6g} s are {np.spacing(span):.3g} s apart, more than 1 % of a "
                         f"sample; shift t0 (e.g. keep the wall-clock time in start_datetime)")
    preamble = {"format": "meshphase-csv", "format_version": FORMAT_VERSION, "fs": fs,
                "t0": header.t0, "n_samples": n, "dtype": str(dtype),
                "start_datetime": header.start_datetime,
                "channels": [c.to_dict() for c in header.channels],
                "meta": header.meta, "history": header.history}
    text = dumps_json(preamble, "recording metadata (CSV preamble)")
    out = io.StringIO()
    _csv.writer(out, lineterminator="\n").writerow(
        ["time [s]"] + [_header_field(c.name, c.units) for c in header.channels])
    nc = len(header.channels)
    pos = 0
    with open(path, "w", encoding="utf-8", newline="") as fh:
        fh.write(_TAG + text + "\n")
        fh.write(out.getvalue())
        for blk in checked_write_blocks(blocks, nc, n):
            blk = blk.astype(dtype, copy=False)
            for i0 in range(0, blk.shape[0], chunk_rows):
                i1 = min(blk.shape[0], i0 + chunk_rows)
                times = header.t0 + np.arange(pos + i0, pos + i1, dtype=np.float64) / fs
                fh.write(_format_block(times, blk[i0:i1]))
            pos += blk.shape[0]
