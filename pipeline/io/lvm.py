"""NI LabVIEW Measurement files (``.lvm``): the text files LabVIEW's "Write To Measurement
File" Express VI writes. Read-only.

Layout (NI, "Specification for the LabVIEW Measurement File (.lvm)"; full mapping in
``data_schemas/lvm.md``)::

    LabVIEW Measurement
    Writer_Version  2
    Separator       Tab
    Decimal_Separator  .
    Multi_Headings  Yes
    X_Columns       One
    Time_Pref       Relative
    Date            2026/11/28
    Time            10:00:00.000
    ***End_of_Header***

    Channels        2
    Samples         5120    5120
    Date            2026/11/28      2026/11/28
    Time            10:00:00.000    10:00:00.000
    Y_Unit_Label    um/m    um/m
    X_Dimension     Time    Time
    X0              0.0000000000000000E+0   0.0000000000000000E+0
    Delta_X         1.953125E-4     1.953125E-4
    ***End_of_Header***
    X_Value sun     ring    Comment
    0.000000        -10.2   3.1
    ...

* The file header (up to the first ``***End_of_Header***``) gives the separator (``Tab`` or
  ``Comma``), the decimal mark (``Decimal_Separator``, "." when absent), ``X_Columns``
  (``No``: no x values, the column is left empty; ``One``: one x column first; ``Multi``:
  an x column before every channel) and ``Multi_Headings``. Its tags are kept in
  ``meta["lvm"]["file"]``.
* Each segment (one call of the Express VI) has a header (``Channels``, ``Samples``,
  ``Date``, ``Time``, ``Y_Unit_Label``, ``X_Dimension``, ``X0``, ``Delta_X``, one value per
  column), then the column-heading line (``X_Value``, the channel names, ``Comment``), then
  the rows. With ``Multi_Headings`` ``No`` rows of later calls follow without a header.
  Segments after the first must hold the same channels, units and ``Delta_X`` and continue
  the first in time (the Date/Time plus X0 of each segment one sample after the last of the
  one before, to half a sample); the recording is their concatenation. Segment headers are
  kept in ``meta["lvm"]["segments"]``.
* Channels: names from the column-heading line, units from ``Y_Unit_Label`` (empty when
  absent), kind ``"other"`` (a scene maps them). fs = 1 / ``Delta_X``, the shortest decimal
  rate that prints as the file's ``Delta_X``; with an x column, from its first and last
  value instead (checked against ``Delta_X``), and every x value is checked against the grid
  t0 + i / fs. t0 = ``X0`` [s]; start_datetime = the first segment's ``Date`` and ``Time``
  (the file header's when the segment has none; LabVIEW writes local time, no offset). A
  ``Time_Pref`` ``Absolute`` ``X0`` of 1e8 s or more is a LabVIEW timestamp (seconds since
  1904-01-01 UTC): it gives start_datetime, and t0 = 0.
* Errors name the file and the line: no ``LabVIEW Measurement`` first line, no
  ``***End_of_Header***``, an unknown ``Separator`` or ``X_Columns``, a segment without
  the column headings, a row with fewer fields than the channels need, a file that does
  not end with a newline (cut short), a ``Multi_Headings`` segment whose rows are not its
  ``Samples`` (truncated), segments that disagree or do not continue one another.

The rows are parsed with pandas' C engine, one segment at a time; a read parses the whole
file (a text format for modest sizes, as NI says), and :func:`iter_blocks` parses it once.
"""

from __future__ import annotations

import datetime as _dt
import os
import warnings
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import numpy as np

from ..errors import FormatWarning
from ..recording import ChannelSpec, Recording
from ..validate import as_int, as_positive_int
from .base import CorruptFileError, RecordingFileError, RecordingInfo, check_verify, nice_fs, warn_nonfinite
from .registry import FormatSpec

__all__ = ["NAME", "FORMAT", "MAGIC", "END_OF_HEADER", "sniff", "read_info", "read", "iter_blocks"]

NAME = "lvm"
#: The format's declaration in the registry (:mod:`meshphase.io.registry`).
FORMAT = FormatSpec(name=NAME, module=__name__, suffixes=(".lvm",), read_libraries=("pandas",),
                    description="NI LabVIEW Measurement File (text; read-only)")
#: The first line of every LVM file.
MAGIC = "LabVIEW Measurement"
#: The tag that ends the file header and each segment header.
END_OF_HEADER = "***End_of_Header***"
#: A Time_Pref Absolute X0 this large [s] is a LabVIEW timestamp (since 1904-01-01 UTC).
_ABSOLUTE_X0 = 1e8
_LABVIEW_EPOCH = _dt.datetime(1904, 1, 1, tzinfo=_dt.timezone.utc)
#: segments continue one another to this many sample intervals [-]
_CONTINUITY = 0.5
#: x values sit on the grid to this many sample intervals plus their printed step [-]
_X_TOLERANCE = 0.1


def sniff(head: bytes) -> bool:
    """True when the first line is ``LabVIEW Measurement`` (a UTF-8 byte-order mark allowed)."""
    if head.startswith(b"\xef\xbb\xbf"):
        head = head[3:]
    return head.startswith(MAGIC.encode())


# ---------------------------------------------------------------------------- structure
@dataclass
class _Segment:
    line: int                        # 1-based line of its "Channels" tag
    header: dict                     # tag -> values (one per column after the tag)
    names: list
    runs: list = field(default_factory=list)   # (0-based first line, rows) of its rows
    rows: int = 0


@dataclass
class _Layout:
    info: RecordingInfo
    sep: str
    decimal: str
    encoding: str
    width: int                       # fields of the column-heading line
    cols: list                       # channel columns
    xcol: int | None                 # the x column of the first channel (None: X_Columns No)
    segments: list
    x_quantum: float = 0.0


def _err(path, line: int, problem: str) -> RecordingFileError:
    return RecordingFileError(path, f"line {line}: {problem}")


def _number(path, line: int, text: str, decimal: str, what: str) -> float:
    t = text.strip()
    try:
        return float(t.replace(decimal, ".") if decimal != "." else t)
    except ValueError:
        raise _err(path, line, f"{what} {text!r} is not a number") from None


def _split(line: str, sep: str | None) -> list[str]:
    if sep is None:        # the file header, before its Separator tag is known
        sep = "\t" if "\t" in line else ","
    return line.split(sep)


def _blank(line: str, sep: str) -> bool:
    return not line.replace(sep, "").strip()


def _start(path, line: int, date: str, time: str, decimal: str) -> _dt.datetime | None:
    """A segment's or the file's Date (``YYYY/MM/DD``) and Time (``HH:MM:SS.fff...``)."""
    date, time = date.strip(), time.strip()
    if not date or not time:
        return None
    try:
        y, m, d = (int(v) for v in date.split("/"))
        hms = time.replace(",", ".")        # LVM 1 files print the clock in the locale's mark
        hh, mm, ss = hms.split(":")
        sec = float(ss)
        whole = int(sec)
        return _dt.datetime(y, m, d, int(hh), int(mm), whole) + _dt.timedelta(seconds=sec - whole)
    except ValueError:
        raise _err(path, line, f"Date {date!r} / Time {time!r} is not YYYY/MM/DD and HH:MM:SS") from None


def _printed_step(text: str) -> float:
    """The step a number is printed to (``3.906250E-5``: 1e-11, ``0.000977``: 1e-6)."""
    t = text.strip().lower().lstrip("+-")
    mant, _, exp = t.partition("e")
    mark = next((c for c in ".," if c in mant), None)
    dec = len(mant) - mant.index(mark) - 1 if mark else 0
    return 10.0 ** (-dec + (int(exp) if exp else 0))


def _rate(dx: float, step: float) -> float:
    """The shortest decimal rate [Hz] whose interval prints as ``dx`` [s] to ``step``."""
    est = 1.0 / dx
    for digits in range(1, 13):
        cand = float(f"{est:.{digits}g}")
        if cand > 0 and abs(1.0 / cand - dx) <= step / 2:
            return cand
    return float(f"{est:.12g}")


def _layout(path) -> _Layout:
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file")
    raw = path.read_bytes()
    if not raw:
        raise RecordingFileError(path, "file is empty (0 bytes)")
    if raw.startswith(b"\xef\xbb\xbf"):
        raw = raw[3:]
    try:
        text, encoding = raw.decode("utf-8"), "utf-8"
    except UnicodeDecodeError:
        text, encoding = raw.decode("latin-1"), "latin-1"
    if not text.endswith("\n"):
        tail = text[-40:]
        raise CorruptFileError(path, f"byte {len(raw)} (end of file)",
                               f"truncated: the last line does not end with a newline (it ends with {tail!r})")
    lines = text.split("\n")[:-1]
    lines = [ln[:-1] if ln.endswith("\r") else ln for ln in lines]
    if not lines[0].startswith(MAGIC):
        raise _err(path, 1, f"not a LabVIEW Measurement file (first line {lines[0][:40]!r})")
    # ---- file header
    fhead, i = {}, 1
    while i < len(lines) and _split(lines[i], None)[0].strip() != END_OF_HEADER:
        f = _split(lines[i], None)
        if f[0].strip():
            fhead[f[0].strip()] = f[1].strip() if len(f) > 1 else ""
        i += 1
    if i == len(lines):
        raise _err(path, len(lines), f"the file header has no {END_OF_HEADER} line")
    seps = {"tab": "\t", "comma": ","}
    sep = seps.get(fhead.get("Separator", "Tab").strip().lower())
    if sep is None:
        raise _err(path, 1, f"Separator {fhead.get('Separator')!r} is neither Tab nor Comma")
    decimal = fhead.get("Decimal_Separator", ".") or "."
    if decimal not in (".", ","):
        raise RecordingFileError(path, f"Decimal_Separator {decimal!r} is neither '.' nor ','")
    if decimal == sep:
        raise RecordingFileError(path, "Separator Comma with Decimal_Separator ',': the numbers cannot be told apart")
    xmode = fhead.get("X_Columns", "One").strip().lower()
    if xmode not in ("no", "one", "multi"):
        raise RecordingFileError(path, f"X_Columns {fhead.get('X_Columns')!r} is not No, One or Multi")
    multi_headings = fhead.get("Multi_Headings", "Yes").strip().lower() != "no"
    # ---- segments
    segments: list[_Segment] = []
    i += 1
    n = len(lines)
    while i < n:
        if _blank(lines[i], sep):
            i += 1
            continue
        first = lines[i].split(sep)[0].strip()
        if first != "Channels":
            if segments and not multi_headings:       # the rows of a later call, without a header
                start = i
                while i < n and not _blank(lines[i], sep) and lines[i].split(sep)[0].strip() != "Channels":
                    i += 1
                segments[-1].runs.append((start, i - start))
                segments[-1].rows += i - start
                continue
            raise _err(path, i + 1, f"expected a segment header (Channels ...), got {lines[i][:60]!r}")
        at = i
        header, special = {}, []
        while i < n and lines[i].split(sep)[0].strip() != END_OF_HEADER:
            f = lines[i].split(sep)
            tag = f[0].strip()
            if tag == "***Start_Special***" or special and special[-1] != "***End_Special***":
                special.append(lines[i])
            elif tag:
                header[tag] = [v.strip() for v in f[1:]]
            i += 1
        if i == n:
            raise _err(path, at + 1, f"the segment header has no {END_OF_HEADER} line")
        i += 1
        if i == n or lines[i].split(sep)[0].strip() != "X_Value":
            raise _err(path, i + 1, "expected the column headings (X_Value, the channel names, Comment) after "
                                    "the segment header")
        names = [v.strip() for v in lines[i].split(sep)]
        seg = _Segment(line=at + 1, header=header, names=names)
        if special:
            seg.header["special"] = special
        i += 1
        start = i
        while i < n and not _blank(lines[i], sep):
            i += 1
        seg.runs.append((start, i - start))
        seg.rows = i - start
        segments.append(seg)
    if not segments:
        raise RecordingFileError(path, "no segment (Channels ... ***End_of_Header***) after the file header")
    return _describe(path, lines, fhead, segments, sep, decimal, encoding, xmode, multi_headings)


def _describe(path, lines, fhead, segments, sep, decimal, encoding, xmode, multi_headings) -> _Layout:
    first = segments[0]
    try:
        nch = int(first.header.get("Channels", [""])[0])
    except ValueError:
        raise _err(path, first.line, f"Channels {first.header.get('Channels')!r} is not a count") from None
    cols = [1 + 2 * j for j in range(nch)] if xmode == "multi" else [1 + j for j in range(nch)]
    xcol = None if xmode == "no" else 0
    need = cols[-1] + 1 if cols else 1
    names_line = first.runs[0][0]       # the heading is the line before the first row
    if len(first.names) < need:
        raise _err(path, names_line, f"the column headings hold {len(first.names)} field(s), {nch} channel(s) "
                                     f"with X_Columns {xmode.capitalize()} need {need}")

    def per_channel(seg, tag):
        vals = seg.header.get(tag, [])
        return [vals[c - 1] if c - 1 < len(vals) else "" for c in cols]

    names = [first.names[c] for c in cols]
    units = per_channel(first, "Y_Unit_Label")
    dxs = per_channel(first, "Delta_X")
    if not dxs or any(not d for d in dxs):
        raise _err(path, first.line, "Delta_X missing (the sample interval of every channel)")
    dx_vals = {_number(path, first.line, d, decimal, "Delta_X") for d in dxs}
    if len(dx_vals) > 1:
        raise _err(path, first.line, f"channels of different Delta_X {sorted(dx_vals)}: one recording needs one rate")
    dx = dx_vals.pop()
    if not dx > 0:
        raise _err(path, first.line, f"Delta_X {dxs[0]!r} is not a positive interval")
    step = _printed_step(dxs[0])
    fs = _rate(dx, step)
    x0s = per_channel(first, "X0")
    x0 = _number(path, first.line, x0s[0], decimal, "X0") if x0s and x0s[0] else 0.0
    # ---- every segment: the same channels, rows, continuity
    starts = []
    for k, seg in enumerate(segments):
        if k:
            got = [seg.names[c] if c < len(seg.names) else "" for c in cols]
            if got != names or per_channel(seg, "Y_Unit_Label") != units:
                raise _err(path, seg.line, f"segment {k + 1} holds channels {got} "
                                           f"{per_channel(seg, 'Y_Unit_Label')}, segment 1 {names} {units}: one "
                                           f"recording needs the same channels in every segment")
            dk = {_number(path, seg.line, d, decimal, "Delta_X") for d in per_channel(seg, "Delta_X") if d}
            if dk != {dx}:
                raise _err(path, seg.line, f"segment {k + 1} has Delta_X {sorted(dk)}, segment 1 {dx!r}")
        samples = {v for v in per_channel(seg, "Samples") if v}
        if len(samples) > 1:
            raise _err(path, seg.line, f"channels of unequal length (Samples {sorted(samples)})")
        if multi_headings and samples and int(samples.pop()) != seg.rows:
            want = int(per_channel(seg, "Samples")[0])
            end = seg.runs[-1][0] + seg.runs[-1][1]
            raise CorruptFileError(path, f"line {end} (segment {k + 1})",
                                   f"Samples says {want} rows, the segment holds {seg.rows}"
                                   + (" (truncated)" if seg.rows < want else ""))
        for r0, m in seg.runs:
            for j in range(r0, r0 + m):
                if lines[j].count(sep) + 1 < need:
                    raise CorruptFileError(path, f"line {j + 1}", f"{lines[j].count(sep) + 1} field(s), the "
                                                                  f"{nch} channel(s) need {need}: malformed row")
        sx0 = per_channel(seg, "X0")
        seg_x0 = _number(path, seg.line, sx0[0], decimal, "X0") if sx0 and sx0[0] else 0.0
        d, t = per_channel(seg, "Date"), per_channel(seg, "Time")
        when = _start(path, seg.line, d[0] if d else "", t[0] if t else "", decimal)
        starts.append((when, seg_x0))
    total = sum(s.rows for s in segments)
    for k in range(1, len(segments)):
        (w0, a), (w1, b) = starts[k - 1], starts[k]
        gap = b - a + ((w1 - w0).total_seconds() if w0 is not None and w1 is not None else 0.0)
        want = segments[k - 1].rows / fs
        if abs(gap - want) > _CONTINUITY / fs:
            raise _err(path, segments[k].line, f"segment {k + 1} starts {gap!r} s after segment {k}, whose "
                                               f"{segments[k - 1].rows} samples take {want!r} s at fs = {fs!r} Hz: "
                                               f"the segments are not one continuous recording")
    # ---- time origin
    when = starts[0][0]
    if when is None:
        when = _start(path, 1, fhead.get("Date", ""), fhead.get("Time", ""), decimal)
    t0 = x0
    if fhead.get("Time_Pref", "").strip().lower() == "absolute" and x0 >= _ABSOLUTE_X0:
        when, t0 = _LABVIEW_EPOCH + _dt.timedelta(seconds=x0), 0.0
    start = None if when is None else when.isoformat()
    # ---- an x column gives fs more closely than Delta_X's printed digits
    x_quantum = 0.0
    if xcol is not None and total >= 2:
        r_first = segments[0].runs[0][0]
        last_seg = next(s for s in reversed(segments) if s.rows)
        r_last = last_seg.runs[-1][0] + last_seg.runs[-1][1] - 1
        xa, xb = lines[r_first].split(sep)[xcol], lines[r_last].split(sep)[xcol]
        if xa.strip() and xb.strip() and len(segments) == 1:
            x_quantum = max(_printed_step(xa), _printed_step(xb)) if "e" not in (xa + xb).lower() else 0.0
            va = _number(path, r_first + 1, xa, decimal, "X_Value")
            vb = _number(path, r_last + 1, xb, decimal, "X_Value")
            span = vb - va
            if span > 0:
                fx = nice_fs((total - 1) / span, total, span, x_quantum)
                if abs(1.0 / fx - dx) <= step / 2 + 1e-12 * dx:
                    fs = fx
    elif step / 2 > 1e-6 * dx:
        warnings.warn(FormatWarning(f"{path}: Delta_X {dxs[0]!r} is printed to {step:.3g} s: fs = {fs!r} Hz is "
                                    f"known to {step / 2 / dx:.2g} of itself only (no x column to pin it)"),
                      stacklevel=4)
    specs = []
    for nm, un in zip(names, units):
        try:
            specs.append(ChannelSpec(name=nm, kind="other", units=un))
        except (ValueError, TypeError) as exc:
            raise _err(path, names_line, f"bad channel column {nm!r}: {exc}") from exc
    if len(set(names)) != len(names):
        raise _err(path, names_line, f"duplicate channel name(s) in the column headings {names}")
    meta = {"lvm": {"file": fhead, "segments": [s.header for s in segments]}}
    info = RecordingInfo(path=str(path), format=NAME, fs=fs, n_samples=total, channels=specs, t0=float(t0),
                         start_datetime=start, meta=meta,
                         extra={"segments": len(segments), "x_columns": xmode.capitalize(), "dtype": "float64",
                                "encoding": encoding})
    return _Layout(info=info, sep=sep, decimal=decimal, encoding=encoding, width=max(len(first.names), need) + 1,
                   cols=cols, xcol=xcol, segments=segments, x_quantum=x_quantum)


_CACHE: "OrderedDict[tuple, _Layout]" = OrderedDict()
_CACHE_MAX = 8


def _cached_layout(path) -> _Layout:
    st = os.stat(path)
    key = (os.path.realpath(path), st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns)
    hit = _CACHE.get(key)
    if hit is None:
        hit = _layout(path)
        _CACHE[key] = hit
        while len(_CACHE) > _CACHE_MAX:
            _CACHE.popitem(last=False)
    _CACHE.move_to_end(key)
    return hit


# ---------------------------------------------------------------------------- reading
def read_info(path, *, verify: bool = True) -> RecordingInfo:
    """Header of an LVM file: channels, fs, n_samples, t0, start_datetime, the headers in
    ``meta["lvm"]``. The whole structure is checked (see the module notes); ``verify`` is
    accepted for the registry's uniform options (LVM stores no checksum)."""
    check_verify(verify)
    if not Path(path).exists():
        raise FileNotFoundError(f"{path}: no such file")
    return _cached_layout(path).info


def _samples(path, lay: _Layout) -> tuple[np.ndarray, np.ndarray | None]:
    """Every row's samples (n, channels) and x values (None without an x column)."""
    import pandas as pd

    use = list(lay.cols) + ([lay.xcol] if lay.xcol is not None else [])
    parts, xs = [], []
    for seg in lay.segments:
        for r0, m in seg.runs:
            if not m:
                continue
            try:
                # no usecols: rows of fewer fields than the headings (no comment, X_Columns No)
                # are filled with NaN, which usecols refuses
                df = pd.read_csv(path, sep=lay.sep, header=None, names=list(range(lay.width)),
                                 skiprows=r0, nrows=m, decimal=lay.decimal, engine="c", skip_blank_lines=False,
                                 dtype={c: np.float64 for c in use}, encoding=lay.encoding)
            except (ValueError, pd.errors.ParserError) as exc:
                raise RecordingFileError(path, f"rows from line {r0 + 1}: {exc}") from exc
            if len(df) != m:
                raise CorruptFileError(path, f"line {r0 + 1}", f"{len(df)} rows parsed, {m} expected")
            parts.append(df[lay.cols].to_numpy(dtype=np.float64))
            if lay.xcol is not None:
                xs.append(df[lay.xcol].to_numpy(dtype=np.float64))
    nch = len(lay.cols)
    data = np.concatenate(parts) if parts else np.empty((0, nch))
    x = np.concatenate(xs) if xs else None
    return np.asfortranarray(data), x


def _check_x(path, lay: _Layout, x: np.ndarray | None) -> None:
    """x values (One/Multi) on the grid x0 + i / fs, per segment; NaN x (an empty field) is
    not checked."""
    if x is None or lay.info.extra["segments"] != 1 or not x.size:
        return
    fs = lay.info.fs
    ok = np.isfinite(x)
    if not ok.any():
        return
    i = np.arange(x.size)
    x0 = x[ok][0] - i[ok][0] / fs
    off = np.abs(x - (x0 + i / fs))
    tol = _X_TOLERANCE / fs + lay.x_quantum
    bad = ok & ~(off <= tol)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        line = lay.segments[0].runs[0][0] + k + 1
        raise RecordingFileError(path, f"non-uniform time at line {line} (sample {k}): X_Value {float(x[k])!r} s, "
                                       f"expected {float(x0 + k / fs)!r} s on the grid (fs = {fs!r} Hz)")


def _all(path, channels):
    lay = _cached_layout(path)
    info = lay.info
    names = info.check_channels(channels) if info.names else []
    data, x = _samples(path, lay)
    _check_x(path, lay, x)
    idx = [info.names.index(n) for n in names]
    return info, names, np.asfortranarray(data[:, idx])


def _recording(info: RecordingInfo, data, names, i0: int) -> Recording:
    by_name = {c.name: c for c in info.channels}
    return Recording(data, info.fs, [by_name[n] for n in names], t0=info.t0 + i0 / info.fs,
                     start_datetime=info.start_datetime, meta=info.meta, history=info.history)


def read(path, channels=None, i0: int = 0, i1: int | None = None, *, verify: bool = True) -> Recording:
    """Rows ``i0 <= i < i1`` of the named channels (all when None) of an LVM file.

    Raises
    ------
    CorruptFileError
        A file cut short, a malformed row, a segment with fewer rows than its Samples.
    RecordingFileError
        Bad headers, segments that disagree, non-numeric values, x values off the grid.
    """
    check_verify(verify)
    info, names, data = _all(path, channels)
    n = info.n_samples
    i0 = as_int(i0, "i0")
    i1 = n if i1 is None else as_int(i1, "i1")
    if not 0 <= i0 <= i1 <= n:
        raise ValueError(f"{path}: sample range [{i0}, {i1}) outside the recording's [0, {n})")
    block = np.asfortranarray(data[i0:i1])
    warn_nonfinite(path, block, names, i0)
    return _recording(info, block, names, i0)


def iter_blocks(path, n_block: int, n_overlap: int, channels=None, *,
                verify: bool = True) -> Iterator[Recording]:
    """Blocks of ``n_block`` rows plus ``n_overlap`` following rows; the file is parsed once."""
    n_block = as_positive_int(n_block, "n_block")
    n_overlap = as_int(n_overlap, "n_overlap")
    if n_overlap < 0:
        raise ValueError(f"n_overlap must be >= 0, got {n_overlap}")
    check_verify(verify)
    info, names, data = _all(path, channels)
    for i0 in range(0, info.n_samples, n_block):
        block = np.asfortranarray(data[i0:min(info.n_samples, i0 + n_block + n_overlap)])
        warn_nonfinite(path, block, names, i0)
        yield _recording(info, block, names, i0)
