"""MATLAB MAT-files (v5/v6/v7 and v7.3), read-only: the arrays a lab's MATLAB script saved,
as the channels of a recording.

Versions, told apart by content (the first bytes, :func:`sniff`):

* **v5** (``save -v6``, ``save -v7``, the default): a 128-byte header whose text starts
  ``MATLAB 5.0 MAT-file``; read whole through ``scipy.io.loadmat`` (compressed variables
  included). The last file read stays loaded (up to :data:`KEEP_BYTES` of arrays), so the
  windows of a streamed run do not load it again.
* **v7.3** (``save -v7.3``): an HDF5 file with a 512-byte user block whose text starts
  ``MATLAB 7.3 MAT-file``; read through h5py, lazily: :func:`read_info` reads the arrays'
  classes and sizes, the scalars and texts (rate, names, units) and a time vector (to check
  it), never a channel's samples; :func:`read` and :func:`iter_blocks` read only the window's
  slice of each channel. MATLAB stores an ``m x n`` array as an HDF5 dataset of shape
  ``(n, m)`` (column-major), a struct as a group, a cell array as object references into
  ``/#refs#``, text as UTF-16 code units (class ``char``).
* **v4** (``save -v4``): recognised and refused, saying how to save it again.

Layouts (``data_schemas/matlab.md`` has the full rules and examples):

a. **One variable per channel**: numeric vectors of the longest common length are the
   channels, named by their variable names; a time vector (:data:`TIME_NAMES`) or a rate
   scalar (:data:`RATE_NAMES`; an interval :data:`INTERVAL_NAMES`) gives the rate.
b. **One matrix** (samples x channels or channels x samples) with a names text
   (:data:`NAMES_VARS`: a cellstr or a char matrix) whose count picks the channel axis
   (without names: the longer axis is the samples, channels ``<var>_1``, ``<var>_2``, ...;
   a square matrix is ambiguous and refused). A names entry that is a time name makes its
   column the time vector. A ``units`` text of as many entries gives the units.
c. **Structs**: a struct's numeric vector fields are channels as in (a), with its ``fs`` /
   ``dt`` / time fields and a ``units`` struct (``data.units.sun_T3 = 'ue'``); structs nested
   one level deeper too (``rec.strain.sun_T3``); and a **struct per channel** (a field
   :data:`VALUE_FIELDS` holding the samples, with its own ``fs`` / ``dt`` / time vector and
   ``units``: DEWESoft and nCode exports), named by the struct.

A rate is looked up from the channel outward: the channel's own struct, then each struct
around it, then the file's top level; the first that holds a time vector of the channels'
length (checked against the uniform grid as CSV and TDMS clocks are:
:func:`meshphase.io.base.clock_timing`, 0.1 sample plus the clock's resolution) or a rate
or interval scalar gives it; every channel's rate must agree. ``fs=`` (a scene's
``[input] fs_Hz``) gives the rate of a file that has neither (it wins over the file's with a
FormatWarning, and no time vector is read then). A file whose layout none of these fits is
refused with a :class:`~meshphase.io.base.RecordingFileError` listing its variables with
their sizes and classes.
"""

from __future__ import annotations

import copy
import math
import os
import struct
import warnings
import zlib
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np

from ..errors import FormatWarning
from ..recording import ChannelSpec, Recording
from ..runtime.lazy import io as scipy_io
from ..validate import as_int, as_positive, as_positive_int
from .base import (CLOCK_NAMES, CorruptFileError, RecordingFileError, RecordingInfo, check_allocation,
                   check_verify, clock_timing, kind_from_name, warn_nonfinite)
from .registry import FormatSpec

__all__ = ["NAME", "FORMAT", "TIME_NAMES", "RATE_NAMES", "INTERVAL_NAMES", "NAMES_VARS", "UNITS_VARS",
           "VALUE_FIELDS", "KEEP_BYTES", "sniff", "mat_version", "read_info", "read", "iter_blocks"]

NAME = "matlab"
#: The format's declaration in the registry (:mod:`meshphase.io.registry`).
FORMAT = FormatSpec(
    name=NAME, module=__name__, suffixes=(".mat",), random_access=True, rate_option=True,
    read_options={"fs": float}, read_libraries=("scipy.io", "h5py"),
    description="MATLAB MAT-file v5/v7 (scipy) and v7.3 (HDF5, windows read in place); read-only")

#: names (any case) of a time vector [s]: the shared clock names of the TDMS and HDF5 readers
#: (:data:`meshphase.io.base.CLOCK_NAMES`) and the spellings of MATLAB scripts
TIME_NAMES = CLOCK_NAMES + ("tvec", "time_vec", "time_vector", "timevector", "t_s")
#: names (any case) of a scalar sample rate [Hz]
RATE_NAMES = ("fs", "fs_hz", "sample_rate", "samplerate", "sampling_rate", "samplingrate",
              "sampling_frequency", "sample_rate_hz", "srate", "rate")
#: names (any case) of a scalar sample interval [s]
INTERVAL_NAMES = ("dt", "ts", "sample_interval", "sampleinterval", "increment", "time_step", "timestep")
#: names (any case) of the text (cellstr or char matrix) naming the channels of a matrix
NAMES_VARS = ("channel_names", "channelnames", "names", "channels", "labels", "chan_names", "signals")
#: names (any case) of the units: a text of one entry per matrix channel, a struct of one
#: field per channel, or a text field of a channel's own struct
UNITS_VARS = ("units", "unit", "channel_units", "eng_units")
#: fields (any case) of a struct per channel that hold its samples
VALUE_FIELDS = ("values", "data", "y", "signal", "samples", "value")
#: v5 files: the arrays of the last file read are kept while they hold at most this [bytes]
KEEP_BYTES = 256 * 2 ** 20

_V5_TEXT = b"MATLAB 5.0 MAT-file"
_V73_TEXT = b"MATLAB 7.3 MAT-file"
_NUMERIC = {"double": "float64", "single": "float32", "int8": "int8", "uint8": "uint8", "int16": "int16",
            "uint16": "uint16", "int32": "int32", "uint32": "uint32", "int64": "int64", "uint64": "uint64"}
_CLASS_OF_DTYPE = {np.dtype(v): k for k, v in _NUMERIC.items()}
_SKIP_ROOT = ("#refs#", "#subsystem#")


# ---------------------------------------------------------------------------- sniff
def _v4_header(head: bytes) -> bool:
    """True when ``head`` starts with a MATLAB v4 matrix header: type MOPT (IEEE little- or
    big-endian machine digit, O = 0, precision 0-5, type 0-2), sizes >= 0, imaginary flag 0
    or 1, and a NUL-terminated ASCII name of 1-63 characters."""
    if len(head) < 21:
        return False
    for order, machine in (("<", 0), (">", 1)):
        mopt, rows, cols, imagf, namlen = struct.unpack(order + "5i", head[:20])
        m, o, p, t = mopt // 1000, mopt // 100 % 10, mopt // 10 % 10, mopt % 10
        if not (0 <= mopt < 2000 and m == machine and o == 0 and p <= 5 and t <= 2):
            continue
        if rows < 0 or cols < 0 or imagf not in (0, 1) or not 2 <= namlen <= 64 or len(head) < 20 + namlen:
            continue
        name = head[20:20 + namlen]
        if name[-1:] == b"\0" and name[:-1].isascii() and name[:-1].decode("ascii").isidentifier():
            return True
    return False


def mat_version(head: bytes) -> str | None:
    """The MAT-file version ``head`` (a file's first bytes) starts: ``"5"`` (v5/v6/v7),
    ``"7.3"``, ``"4"``, or None for no MAT-file."""
    if head.startswith(_V73_TEXT):
        return "7.3"
    if head.startswith(_V5_TEXT):
        return "5"
    if _v4_header(head):
        return "4"
    return None


def sniff(head: bytes) -> bool:
    """True when ``head`` starts a MATLAB MAT-file (v5 or v7.3 header text, or a v4 matrix
    header, which reading refuses by name)."""
    return mat_version(head) is not None


# ---------------------------------------------------------------------------- arrays
class _Array:
    """One MATLAB array of a file: its path (``data.sun_T3``), MATLAB class and size; the
    values are read on demand."""

    def __init__(self, path: str, mclass: str, shape: tuple):
        self.path, self.mclass, self.shape = path, mclass, tuple(int(d) for d in shape)

    @property
    def numeric(self) -> bool:
        return self.mclass in _NUMERIC

    @property
    def size(self) -> int:
        return math.prod(self.shape)

    @property
    def is_scalar(self) -> bool:
        return self.numeric and self.size == 1

    @property
    def is_vector(self) -> bool:
        return self.numeric and self.size >= 2 and sum(d > 1 for d in self.shape) == 1

    @property
    def is_matrix(self) -> bool:
        return self.numeric and len(self.shape) == 2 and min(self.shape) > 1

    @property
    def length(self) -> int:
        return max(self.shape) if self.shape else 1

    def describe(self) -> str:
        return f"{self.path} ({'x'.join(map(str, self.shape))} {self.mclass})"

    def scalar(self) -> float:
        return float(self.vector(0, 1)[0])

    def whole(self) -> np.ndarray:
        """A vector's values, all of them."""
        return self.vector(0, self.length)


class _V5Array(_Array):
    """An array loaded by ``scipy.io.loadmat(simplify_cells=True)``: vectors come 1-D."""

    def __init__(self, path: str, value):
        self.value = value
        if isinstance(value, str):
            mclass, shape = "char", (1, len(value))
        elif isinstance(value, (bool, np.bool_)):
            mclass, shape = "logical", (1, 1)
        elif isinstance(value, (int, float, np.integer, np.floating)):
            self.value = np.asarray(value)
            mclass, shape = _CLASS_OF_DTYPE.get(self.value.dtype, "double"), (1, 1)
            if self.value.dtype not in _CLASS_OF_DTYPE:
                self.value = self.value.astype(np.float64)
        elif isinstance(value, np.ndarray):
            shape = value.shape if value.ndim else (1, 1)
            if value.dtype in _CLASS_OF_DTYPE:
                mclass = _CLASS_OF_DTYPE[value.dtype]
            elif value.dtype.kind == "b":
                mclass = "logical"
            elif value.dtype.kind == "c":
                mclass = "complex"
            elif value.dtype.kind == "U":
                mclass = "char"
            elif value.dtype.kind == "O":
                mclass = "struct array" if any(isinstance(v, dict) for v in value.ravel()) else "cell"
            else:
                mclass = str(value.dtype)
        elif isinstance(value, list):
            mclass = "struct array" if any(isinstance(v, dict) for v in value) else "cell"
            shape = (1, len(value))
        else:
            mclass, shape = type(value).__name__, (1, 1)
        super().__init__(path, mclass, shape)

    def text(self):
        v = self.value
        if self.mclass == "char":
            if isinstance(v, str):
                return v
            rows = [str(r).rstrip() for r in np.atleast_1d(v).ravel()]
            return rows[0] if len(rows) == 1 else rows
        if self.mclass == "cell":
            items = list(np.ravel(np.asarray(v, dtype=object))) if not isinstance(v, list) else v
            if items and all(isinstance(x, str) for x in items):
                return [x for x in items]
        return None

    def vector(self, i0: int, i1: int) -> np.ndarray:
        return np.asarray(self.value).reshape(-1)[i0:i1]

    def column(self, axis: int, j: int, i0: int, i1: int) -> np.ndarray:
        return self.value[i0:i1, j] if axis == 0 else self.value[j, i0:i1]


def _h5_text(attr) -> str:
    if isinstance(attr, bytes):
        return attr.decode("ascii", errors="replace")
    if isinstance(attr, np.ndarray):
        return "".join(_h5_text(x) for x in attr.ravel())
    return str(attr)


class _H5Array(_Array):
    """A dataset of a v7.3 file, read through h5py in MATLAB's orientation (the HDF5 shape
    reversed)."""

    def __init__(self, path: str, ds):
        self.ds = ds
        attrs = ds.attrs
        mclass = _h5_text(attrs["MATLAB_class"]) if "MATLAB_class" in attrs else ""
        dt = ds.dtype
        if dt.kind == "O" or (dt.kind == "V" and dt.names is None):
            mclass = mclass if mclass == "cell" else (mclass or "reference")
        elif dt.names is not None:
            mclass = "complex"
        elif not mclass:
            mclass = _CLASS_OF_DTYPE.get(dt, str(dt))
        if mclass == "string" or "MATLAB_object_decode" in attrs:
            mclass = f"{mclass or 'object'} object"
        shape = tuple(reversed(ds.shape))
        if "MATLAB_empty" in attrs and np.any(np.asarray(attrs["MATLAB_empty"])):
            shape = (0, 0)             # the dataset holds the empty array's size, not values
        super().__init__(path, mclass, shape)

    def _char(self, ds) -> str | list:
        if "MATLAB_empty" in ds.attrs or 0 in ds.shape:
            return ""
        codes = np.asarray(ds[()])
        if codes.ndim < 2 or codes.shape[1] == 1:
            return "".join(map(chr, codes.ravel()))
        rows = ["".join(map(chr, codes[:, i])).rstrip() for i in range(codes.shape[1])]
        return rows[0] if len(rows) == 1 else rows

    def text(self):
        if self.mclass == "char":
            return self._char(self.ds)
        if self.mclass == "cell" and self.size:
            out = []
            f = self.ds.file
            for ref in np.asarray(self.ds[()]).ravel():
                item = f[ref]
                if _h5_text(item.attrs.get("MATLAB_class", b"")) != "char":
                    return None
                t = self._char(item)
                if not isinstance(t, str):
                    return None
                out.append(t)
            return out
        return None

    def vector(self, i0: int, i1: int) -> np.ndarray:
        ax = next((k for k, d in enumerate(self.ds.shape) if d > 1), 0)
        sel = tuple(slice(i0, i1) if k == ax else 0 for k in range(self.ds.ndim))
        return np.asarray(self.ds[sel]).reshape(-1)

    def column(self, axis: int, j: int, i0: int, i1: int) -> np.ndarray:
        h = 1 - axis                               # MATLAB axis a is HDF5 axis ndim - 1 - a
        sel = (slice(i0, i1), j) if h == 0 else (j, slice(i0, i1))
        return np.asarray(self.ds[sel])


# ---------------------------------------------------------------------------- trees
def _v5_tree(value: dict, prefix: str) -> dict:
    out = {}
    for k, v in value.items():
        if k.startswith("__"):
            continue
        p = f"{prefix}{k}"
        out[k] = _v5_tree(v, p + ".") if isinstance(v, dict) else _V5Array(p, v)
    return out


def _h5_tree(group, prefix: str, depth: int = 0) -> dict:
    import h5py

    out = {}
    for k in group.keys():
        if depth == 0 and k in _SKIP_ROOT:
            continue
        obj = group.get(k)
        p = f"{prefix}{k}"
        if isinstance(obj, h5py.Group):
            cls = _h5_text(obj.attrs["MATLAB_class"]) if "MATLAB_class" in obj.attrs else "struct"
            if cls == "struct" and depth < 3:
                out[k] = _h5_tree(obj, p + ".", depth + 1)
            else:
                out[k] = _Array(p, cls if cls != "struct" else "struct (too deep)", (1, 1))
        elif isinstance(obj, h5py.Dataset):
            out[k] = _H5Array(p, obj)
    return out


def _inventory(tree: dict, limit: int = 40) -> str:
    """The variables of a file as text: ``t (1x10240 double), data (struct: fs (1x1 double),
    ...)``."""
    parts = []
    for k, v in tree.items():
        if len(parts) >= limit:
            parts.append("...")
            break
        parts.append(f"{k} (struct: {_inventory(v, limit)})" if isinstance(v, dict)
                     else f"{k} ({'x'.join(map(str, v.shape))} {v.mclass})")
    return ", ".join(parts) if parts else "no variables"


# ---------------------------------------------------------------------------- layout
@dataclass(frozen=True)
class _Source:
    """Where one channel's samples are: the array's path in the tree (a tuple of names) and,
    for a matrix, the samples axis (MATLAB's) and the column."""

    keys: tuple
    axis: int = -1
    col: int = -1


@dataclass
class _Layout:
    fs: float
    t0: float
    start: str | None
    n: int
    dtype: str
    specs: tuple
    sources: tuple
    meta: dict
    history: list


def _low(name: str) -> str:
    return name.strip().lower()


def _node(tree: dict, keys: tuple):
    node = tree
    for k in keys:
        node = node[k]
    return node


def _text_list(arr) -> list | None:
    t = arr.text() if isinstance(arr, _Array) else None
    if isinstance(t, str):
        t = [s.strip() for s in t.split(",")] if "," in t else [t]
    return t


def _value_field(node: dict) -> str | None:
    by_low = {_low(k): k for k in node}
    for f in VALUE_FIELDS:
        k = by_low.get(f)
        if k is not None and isinstance(node[k], _Array) and node[k].is_vector:
            return k
    return None


@dataclass
class _Chan:
    keys: tuple            # path of the samples' array
    name_keys: tuple       # path naming the channel (the struct of a struct per channel)
    array: _Array
    own: dict | None       # the channel's own struct (struct per channel)


def _collect(tree: dict):
    """Channels (numeric vectors and structs per channel), matrices, and what is not read."""
    chans, matrices, skipped = [], [], []

    def visit(scope: dict, prefix: tuple, depth: int):
        for name, node in scope.items():
            p = prefix + (name,)
            low = _low(name)
            if isinstance(node, dict):
                vf = _value_field(node)
                if vf is not None:
                    chans.append(_Chan(p + (vf,), p, node[vf], node))
                elif depth < 3:
                    visit(node, p, depth + 1)
                continue
            if node.is_vector and low not in TIME_NAMES:
                chans.append(_Chan(p, p, node, None))
            elif node.is_matrix:
                matrices.append((p, node))
            elif node.numeric and node.size > 1 and not (node.is_vector and low in TIME_NAMES):
                skipped.append(node)

    visit(tree, (), 1)
    return chans, matrices, skipped


def _scope_rate(scope: dict, n: int, path, fs_opt):
    """(kind, value) the scope states for channels of ``n`` samples: ("clock", array) for a
    time vector of length n, ("rate", fs) for a rate or interval scalar, None."""
    clock = rate = None
    for k, v in scope.items():
        if not isinstance(v, _Array):
            continue
        low = _low(k)
        if v.is_vector and low in TIME_NAMES and v.length == n and clock is None:
            clock = v
        elif v.is_scalar and (low in RATE_NAMES or low in INTERVAL_NAMES) and rate is None:
            x = v.scalar()
            if not (math.isfinite(x) and x > 0):
                raise RecordingFileError(path, f"variable {v.path} = {x!r} is not a positive "
                                               f"{'interval' if low in INTERVAL_NAMES else 'rate'}")
            rate = (1.0 / x if low in INTERVAL_NAMES else x, v.path)
    if clock is not None and fs_opt is None:
        return ("clock", clock, rate)
    if rate is not None:
        return ("rate", rate, None)
    if clock is not None:
        return ("clock", clock, None)
    return None


def _units_from(scope: dict, name: str) -> str | None:
    """A channel's unit from a ``units`` struct of ``scope`` (one field per channel)."""
    for k, v in scope.items():
        if _low(k) in UNITS_VARS and isinstance(v, dict):
            u = next((w for kk, w in v.items() if kk == name), None)
            t = u.text() if isinstance(u, _Array) else None
            if isinstance(t, str):
                return t.strip()
    return None


def _own_units(own: dict) -> str | None:
    for k, v in own.items():
        if _low(k) in UNITS_VARS and isinstance(v, _Array):
            t = v.text()
            if isinstance(t, str):
                return t.strip()
    return None


def _matrix_layout(tree, path, p, m: _Array):
    """(sources, names, units, clock column or None) of the one matrix ``m`` at ``p``."""
    scope = _node(tree, p[:-1])
    names = units = None
    for k, v in scope.items():
        if isinstance(v, _Array) and _low(k) in NAMES_VARS and names is None:
            names = _text_list(v)
            if names is None and not v.numeric:
                raise RecordingFileError(path, f"{v.describe()} names the channels of {m.describe()} but "
                                               "holds no text meshphase can read (MATLAB string arrays are "
                                               "opaque objects: save the names as a cellstr, cellstr(names))")
    rows, cols = m.shape
    if names is not None:
        match = [ax for ax in (0, 1) if m.shape[ax] == len(names)]
        if len(match) == 2:
            raise RecordingFileError(path, f"{m.describe()} is square: its {len(names)} names do not tell "
                                           "the channel axis from the samples axis")
        if not match:
            raise RecordingFileError(path, f"{len(names)} channel names for {m.describe()}: the count matches "
                                           "neither axis")
        axis = 1 - match[0]
    else:
        if rows == cols:
            raise RecordingFileError(path, f"{m.describe()} is square and no names text ({', '.join(NAMES_VARS[:3])}"
                                           ", ...) tells the channel axis from the samples axis; save it "
                                           "with channel names, or as one vector per channel")
        axis = 0 if rows > cols else 1
        names = [f"{p[-1]}_{i + 1}" for i in range(m.shape[1 - axis])]
    for k, v in scope.items():
        if isinstance(v, _Array) and _low(k) in UNITS_VARS:
            t = _text_list(v)
            if t is not None and len(t) == len(names):
                units = t
    units = units or [""] * len(names)
    clock = next((j for j, nm in enumerate(names) if _low(nm) in TIME_NAMES), None)
    return [_Source(p, axis, j) for j in range(len(names))], names, units, clock


def _rate_for(tree, path, keys: tuple, own: dict | None, n: int, fs_opt, memo: dict):
    """The first rate statement from a channel outward: its own struct, then each scope up
    (``memo``: the statements of the scopes already looked at, by identity)."""
    scopes = ([own] if own is not None else []) + [_node(tree, keys[:i]) for i in range(len(keys) - 1, -1, -1)]
    for scope in scopes:
        if id(scope) not in memo:
            memo[id(scope)] = _scope_rate(scope, n, path, fs_opt)
        if memo[id(scope)] is not None:
            return memo[id(scope)]
    return None


def _layout(tree: dict, path, fs_opt, version: str, header_text: str) -> _Layout:
    chans, matrices, skipped = _collect(tree)
    clock_col = None
    if chans:
        n = max(c.array.length for c in chans)
        short = sorted(c.array.path for c in chans if c.array.length != n)
        short += sorted(a.path for a in skipped)
        chans = [c for c in chans if c.array.length == n]
        if matrices:
            short += [m.describe() for _, m in matrices]
        if short:
            warnings.warn(FormatWarning(f"{path}: not read as channels (of {n} samples): {short}"), stacklevel=5)
        sources = [_Source(c.keys) for c in chans]
        name_keys = [c.name_keys for c in chans]
        base = [k[-1] for k in name_keys]
        names = base if len(set(base)) == len(base) else [".".join(k) for k in name_keys]
        units = []
        for c, nk in zip(chans, name_keys):
            u = _own_units(c.own) if c.own is not None else None
            if u is None:
                for i in range(len(nk) - 1, -1, -1):
                    u = _units_from(_node(tree, nk[:i]), nk[-1])
                    if u is not None:
                        break
            units.append(u or "")
        arrays = [c.array for c in chans]
        rate_keys = [(c.name_keys, c.own) for c in chans]
        layout = "struct per channel" if any(c.own is not None for c in chans) else (
            "vectors in structs" if any(len(c.keys) > 1 for c in chans) else "one variable per channel")
    elif len(matrices) == 1:
        p, m = matrices[0]
        sources, names, units, clock_col = _matrix_layout(tree, path, p, m)
        n = m.shape[sources[0].axis]
        arrays = [m] * len(sources)
        rate_keys = [(p, None)]
        layout = "matrix"
    elif matrices:
        raise RecordingFileError(path, f"several matrices and no channel vectors: "
                                       f"{', '.join(m.describe() for _, m in matrices)}; meshphase reads one "
                                       "matrix (samples x channels) per file, or one vector per channel. "
                                       f"Variables: {_inventory(tree)}")
    else:
        raise RecordingFileError(path, f"no channels found in this MATLAB {version} MAT-file: no numeric "
                                       "vectors of equal length (one per channel), no matrix with channel "
                                       f"names, no struct per channel. Variables: {_inventory(tree)}")
    # the rate
    fs = t0 = None
    start = None
    fs_from = "given" if fs_opt is not None else None
    if clock_col is not None:
        m = arrays[0]
        src = sources.pop(clock_col)
        what = f"time column {names.pop(clock_col)!r} of {m.path}"
        units.pop(clock_col)
        arrays.pop(clock_col)
        if fs_opt is None:
            fs, t0, start = clock_timing(path, what, m.column(src.axis, src.col, 0, n), n)
            fs_from = what
    stated, memo = {}, {}
    if fs is None:
        for keys, own in rate_keys:
            r = _rate_for(tree, path, keys, own, n, fs_opt, memo)
            if r is None:
                continue
            kind, val, also = r
            if kind == "clock":
                if val.path not in stated:
                    f_, t_, s_ = clock_timing(path, f"time vector {val.path!r}", val.whole(), n)
                    if also is not None and abs(also[0] - f_) > 1e-6 * f_:
                        raise RecordingFileError(path, f"time vector {val.path!r} gives {f_!r} Hz, "
                                                       f"{also[1]} says {also[0]!r} Hz")
                    stated[val.path] = (f_, t_, s_)
            else:
                stated[val[1]] = (val[0], 0.0, None)
        if stated:
            vals = list(stated.values())
            fss = [v[0] for v in vals]
            if max(fss) - min(fss) > 1e-9 * max(fss):
                raise RecordingFileError(path, f"channels state different sample rates: "
                                               f"{ {k: v[0] for k, v in stated.items()} } Hz")
            t0s = [v[1] for v in vals]
            if max(t0s) - min(t0s) > 0.5 / fss[0]:
                raise RecordingFileError(path, f"time vectors start at different times: "
                                               f"{ {k: v[1] for k, v in stated.items()} } s")
        if fs_opt is not None:
            if stated and abs(next(iter(stated.values()))[0] - fs_opt) > 1e-9 * fs_opt:
                warnings.warn(FormatWarning(f"{path}: fs={fs_opt!r} Hz given overrides the file's "
                                            f"{next(iter(stated.values()))[0]!r} Hz"), stacklevel=5)
            fs, t0 = float(fs_opt), 0.0
        elif stated:
            fs, t0, start = next(iter(stated.values()))
            fs_from = next(iter(stated))
        else:
            raise RecordingFileError(path, f"a MATLAB MAT-file with no sample rate: no time vector (named "
                                           f"{', '.join(TIME_NAMES[:4])}, ...) of {n} values and no rate "
                                           f"({', '.join(RATE_NAMES[:4])}, ...) or interval (dt, Ts) scalar "
                                           "beside the channels; give the rate: [input] fs_Hz in a scene, "
                                           "fs= to meshphase.io.read")
    elif fs_opt is not None:
        fs, t0 = float(fs_opt), 0.0
    specs = []
    seen = set()
    for name, u in zip(names, units):
        if name in seen:
            raise RecordingFileError(path, f"channel name {name!r} repeats")
        seen.add(name)
        try:
            specs.append(ChannelSpec(name=name, kind=kind_from_name(name.rsplit(".", 1)[-1]), units=u))
        except (ValueError, TypeError) as exc:
            raise RecordingFileError(path, f"channel {name!r}: {exc}") from exc
    dtype = "float32" if arrays and all(a.mclass == "single" for a in arrays) else "float64"
    where = {nm: (a.path if s.axis < 0 else f"{a.path}(:,{s.col + 1})" if s.axis == 0
                  else f"{a.path}({s.col + 1},:)") for nm, a, s in zip(names, arrays, sources)}
    meta = {"matlab": {"version": version, "header": header_text, "layout": layout}}
    history = [{"step": "read_matlab", "file": Path(path).name, "version": version, "layout": layout,
                "variables": where, "fs_from": fs_from}]
    return _Layout(float(fs), float(t0), start, int(n), dtype, tuple(specs), tuple(sources), meta, history)


# ---------------------------------------------------------------------------- opening
_LAYOUTS: "OrderedDict[tuple, _Layout]" = OrderedDict()
_LAYOUTS_SIZE = 64
_V5_LAST: list = []            # [(key, tree, header text)] of the last v5 file read


def _key(path) -> tuple:
    st = os.stat(path)
    return (os.path.realpath(path), st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns)


class _Open:
    """A MAT-file opened for reading: its version, header text and tree of arrays (a v7.3
    file's HDF5 file stays open until the context ends)."""

    def __init__(self, path):
        self.path = Path(path)
        self.h5 = None

    def __enter__(self):
        path = self.path
        if not path.exists():
            raise FileNotFoundError(f"{path}: no such file")
        with open(path, "rb") as fh:
            head = fh.read(128)
        self.version = mat_version(head)
        if self.version is None:
            raise RecordingFileError(path, f"not a MATLAB MAT-file (first bytes {head[:20]!r})")
        if self.version == "4":
            raise RecordingFileError(path, "a MATLAB v4 MAT-file (save -v4): meshphase reads MAT-files v5/v6/v7 "
                                           "and v7.3; save it again with save(file, ..., '-v7') or '-v7.3'")
        self.header = head[:116].rstrip(b"\0 ").decode("latin-1")
        self.key = _key(path)
        if self.version == "7.3":
            self._open_h5()
        else:
            self._load_v5()
        return self

    def _open_h5(self):
        import h5py

        try:
            self.h5 = h5py.File(self.path, "r")
        except OSError as exc:
            raise CorruptFileError(self.path, f"file of {self.path.stat().st_size} bytes",
                                   f"a MATLAB 7.3 header but cannot be opened as HDF5: truncated or "
                                   f"corrupt ({exc})") from exc
        try:
            self.tree = _h5_tree(self.h5, "")
        except (OSError, KeyError, RuntimeError, ValueError) as exc:
            self.h5.close()
            raise CorruptFileError(self.path, "HDF5 metadata", f"cannot be read: {type(exc).__name__}: {exc}") from exc

    def _load_v5(self):
        if _V5_LAST and _V5_LAST[0][0] == self.key:
            self.tree = _V5_LAST[0][1]
            return
        _V5_LAST.clear()
        try:
            raw = scipy_io.loadmat(self.path, simplify_cells=True)
        except NotImplementedError as exc:
            raise RecordingFileError(self.path, f"cannot be read as a MAT-file v5: {exc}") from exc
        except (ValueError, TypeError, OSError, EOFError, zlib.error, IndexError, KeyError,
                scipy_io.matlab.MatReadError) as exc:
            raise CorruptFileError(self.path, f"file of {self.path.stat().st_size} bytes",
                                   f"a MATLAB 5.0 header but the variables cannot be read: truncated or "
                                   f"corrupt ({type(exc).__name__}: {exc})") from exc
        self.tree = _v5_tree(raw, "")
        held = sum(a.value.nbytes for a in _leaves(self.tree) if isinstance(a.value, np.ndarray))
        if held <= KEEP_BYTES:
            _V5_LAST.append((self.key, self.tree))

    def __exit__(self, *exc):
        if self.h5 is not None:
            self.h5.close()
            self.h5 = None

    def layout(self, fs_opt) -> _Layout:
        key = self.key + (fs_opt,)
        hit = _LAYOUTS.get(key)
        if hit is None:
            hit = _layout(self.tree, self.path, fs_opt, self.version, self.header)
            _LAYOUTS[key] = hit
            while len(_LAYOUTS) > _LAYOUTS_SIZE:
                _LAYOUTS.popitem(last=False)
        else:
            _LAYOUTS.move_to_end(key)
        return hit

    def samples(self, src: _Source, i0: int, i1: int) -> np.ndarray:
        arr = _node(self.tree, src.keys)
        try:
            return arr.vector(i0, i1) if src.axis < 0 else arr.column(src.axis, src.col, i0, i1)
        except (OSError, RuntimeError) as exc:
            raise CorruptFileError(self.path, f"variable {arr.path}, samples [{i0}, {i1})",
                                   f"cannot be read: {exc}") from exc


def _leaves(tree: dict):
    for v in tree.values():
        if isinstance(v, dict):
            yield from _leaves(v)
        else:
            yield v


# ---------------------------------------------------------------------------- reading
def _fs_option(fs) -> float | None:
    return None if fs is None else as_positive(fs, "fs")


def read_info(path, *, fs: float | None = None, verify: bool = True) -> RecordingInfo:
    """Header of a MAT-file: channels, rate, length (a v7.3 file: no channel sample read).

    Parameters
    ----------
    path : str or Path
    fs : float, optional
        Sample rate [Hz] of a file that states none (wins over the file's, with a warning).
    verify : bool
        Accepted for the registry's uniform options (MAT-files store no checksums).

    Raises
    ------
    RecordingFileError
        A v4 file, no recognised layout (the message lists the variables with their sizes),
        no sample rate, a time vector off the uniform grid, rates that disagree.
    CorruptFileError
        A truncated or damaged file.
    """
    check_verify(verify)
    with _Open(path) as mf:
        lay = mf.layout(_fs_option(fs))
    return RecordingInfo(path=str(path), format=NAME, fs=lay.fs, n_samples=lay.n, channels=list(lay.specs),
                         t0=lay.t0, start_datetime=lay.start, meta=copy.deepcopy(lay.meta),
                         history=copy.deepcopy(lay.history),
                         extra={"mat_version": mf.version, "dtype": lay.dtype})


def _select(path, lay: _Layout, channels) -> list[int]:
    if not lay.specs:
        return []
    info = RecordingInfo(path=str(path), format=NAME, fs=1.0, n_samples=0, channels=list(lay.specs))
    names = info.check_channels(channels)
    index = {s.name: i for i, s in enumerate(lay.specs)}
    return [index[nm] for nm in names]


def _check_range(path, n, i0, i1) -> tuple[int, int]:
    i0 = as_int(i0, "i0")
    i1 = n if i1 is None else as_int(i1, "i1")
    if not 0 <= i0 <= i1 <= n:
        raise ValueError(f"{path}: sample range [{i0}, {i1}) outside the recording's [0, {n})")
    return i0, i1


def _read_open(mf: _Open, lay: _Layout, sel: list[int], i0: int, i1: int) -> Recording:
    dtype = np.dtype(lay.dtype)
    check_allocation(mf.path, i1 - i0, len(sel), dtype.itemsize)
    buf = np.empty((len(sel), i1 - i0), dtype=dtype)        # channel-major; data = buf.T
    if i1 > i0:
        for j, k in enumerate(sel):
            buf[j] = mf.samples(lay.sources[k], i0, i1)
    data = buf.T
    names = [lay.specs[k].name for k in sel]
    warn_nonfinite(mf.path, data, names, i0)
    return Recording(data, lay.fs, [lay.specs[k] for k in sel], t0=lay.t0 + i0 / lay.fs,
                     start_datetime=lay.start, meta=copy.deepcopy(lay.meta), history=copy.deepcopy(lay.history))


def read(path, channels=None, i0: int = 0, i1: int | None = None, *, fs: float | None = None,
         verify: bool = True) -> Recording:
    """Samples ``i0 <= i < i1`` of the named channels (all when None) of a MAT-file.

    A v7.3 file reads only that slice of each channel's dataset; a v5 file is loaded whole
    (kept for the next read while it holds at most :data:`KEEP_BYTES`).

    Parameters
    ----------
    path : str or Path
    channels : str or sequence of str, optional
    i0, i1 : int
        Sample range [i0, i1) (default: all).
    fs : float, optional
        As :func:`read_info`.
    verify : bool
        As :func:`read_info`.

    Returns
    -------
    Recording
        float32 when every channel is class ``single``, else float64 (integer classes are
        converted); ``t0`` shifted to the first sample read.
    """
    check_verify(verify)
    with _Open(path) as mf:
        lay = mf.layout(_fs_option(fs))
        sel = _select(path, lay, channels)
        i0, i1 = _check_range(path, lay.n, i0, i1)
        return _read_open(mf, lay, sel, i0, i1)


def iter_blocks(path, n_block: int, n_overlap: int, channels=None, *, fs: float | None = None,
                verify: bool = True) -> Iterator[Recording]:
    """Blocks of ``n_block`` samples plus ``n_overlap`` following samples, file kept open.

    Block k covers samples [k n_block, (k + 1) n_block + n_overlap), clipped to the recording.
    """
    check_verify(verify)
    n_block = as_positive_int(n_block, "n_block")
    n_overlap = as_int(n_overlap, "n_overlap")
    if n_overlap < 0:
        raise ValueError(f"n_overlap must be >= 0, got {n_overlap}")
    with _Open(path) as mf:
        lay = mf.layout(_fs_option(fs))
        sel = _select(path, lay, channels)
        for a in range(0, lay.n, n_block):
            yield _read_open(mf, lay, sel, a, min(lay.n, a + n_block + n_overlap))
