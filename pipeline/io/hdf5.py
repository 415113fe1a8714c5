"""HDF5: the native archive of meshphase recordings (h5py).

One module of about 1,000 lines on purpose: the reader, the block reader and the writer of one
layout share its checks, constants and chunk arithmetic; split, they would pass private names
between the halves.

Layout (version 1; full description in ``data_schemas/hdf5_layout.md``, schema in
``data_schemas/hdf5_layout.schema.json``)::

    /                       attrs: meshphase_format="recording", format_version=1, fs [Hz],
                                   t0 [s], n_samples, dtype, channel_order (names, column order),
                                   start_datetime (ISO 8601, only when known),
                                   meta (JSON object text), history (JSON array text),
                                   created_by, file_id (random UUID of this write)
    /channels/<name>        one 1-D dataset per channel (channel-major), float32 or float64
                            as in the Recording, chunked (default 131072 samples = 1 MiB of
                            float64), fletcher32 checksum per chunk (default on), optional
                            gzip/lzf compression; attrs: the ChannelSpec
                            fields (name, kind, units, gain, gear, tooth, face_position,
                            description), None fields left out

Channel names are stored in the ``name`` attribute; the dataset name is the channel name with
``%`` and ``/`` percent-encoded (and a name ``.`` written ``%2E``) so any Unicode name works.

A file written by another tool (no ``meshphase_format`` root attribute) is read as it is
laid out: its numeric datasets of the longest length are the channels, a 1-D dataset one
channel, a 2-D one of any channel count one channel per column (or row: the samples axis is
the longer one unless an attribute says otherwise), an N-D one one channel per index over
its other axes (``name[i,j]``); the rate from ``fs=``, a clock dataset or a rate / interval
attribute (:func:`_foreign_header`; ``data_schemas/hdf5_layout.md``, "HDF5 files written by
other tools").

Reading allocates the output once, as a channel-major (Fortran-ordered) samples x channels
array, and fills each column with ``Dataset.read_direct``: one channel or one time window is
read without reading the rest. Samples round-trip bit-exactly (NaN payloads included), as do
every ChannelSpec field, ``meta``, ``history``, ``t0``, ``fs`` and ``start_datetime``.

Format options of :func:`write`: ``compression`` (None | "gzip" | "lzf", default None),
``compression_opts`` (gzip level 0-9, default 4), ``shuffle`` (default True when compressed),
``chunk_samples`` (samples per chunk, default 131072), ``fletcher32`` (default True).

Integrity: files are written in the HDF5 1.10 file format (``libver=("v110", "v110")``:
superblock, object headers, attributes and the chunk index carry checksums that HDF5 checks
when it reads them) with a fletcher32 checksum on every sample chunk, which HDF5 checks on
every read of that chunk. A mismatch raises :class:`~meshphase.io.base.CorruptFileError`
naming the file, the dataset, the sample range of the chunk and its byte offset. A chunk
never written has no checksum to check (HDF5 reads it as zeros): the chunk index is
compared with the declared length when the header is read (:func:`_check_written`), and a
missing chunk is a CorruptFileError naming the channel and its time range; so is a declared
length of 1e12 samples with nothing stored, before anything is allocated.
``read(..., verify=False)`` reads chunks stored with fletcher32 as the only filter without
checking the checksum (to salvage the undamaged samples of a damaged file, or to read again
what a checked pass of the same run has read: :class:`meshphase.io.sources.FileSource`), with
``os.preadv`` at the chunks' byte offsets; chunks with
compression are always checked (h5py exposes no switch to skip it). Files are written with
no chunk cache (``rdcc_nbytes=0``), so a failed write (ENOSPC) leaves no dirty chunk for
HDF5 to flush while closing: the write raises a clean OSError.
"""

from __future__ import annotations

import contextlib
import copy
import errno
import json
import math
import os
import re
import uuid
import warnings
import zlib
from collections import OrderedDict
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from ..errors import FormatWarning
from ..jsonable import to_jsonable
from ..runtime.log import logger
from ..recording import ChannelSpec, Recording
from ..validate import as_choice, as_int, as_positive, as_positive_int
from .base import (CLOCK_NAMES, CorruptFileError, RecordingFileError, RecordingInfo, check_start_datetime,
                   check_allocation, check_verify, clock_timing, dumps_json, kind_from_name,
                   regroup_blocks, spec_from_dict, warn_nonfinite)
from .registry import FormatSpec
from ..version import __version__

__all__ = ["NAME", "FORMAT", "FORMAT_VERSION", "DEFAULT_CHUNK_SAMPLES", "sniff",
           "read_info", "read", "write", "write_blocks", "iter_blocks"]

NAME = "hdf5"
#: The format's declaration in the registry (:mod:`meshphase.io.registry`).
FORMAT = FormatSpec(
    name=NAME, module=__name__, suffixes=(".h5", ".hdf5", ".hdf", ".he5"),
    writable=True, streaming_write=True, random_access=True, checksums=True, rate_option=True,
    read_options={"fs": float},
    write_options={"compression": str, "compression_opts": int, "shuffle": bool, "chunk_samples": int,
                   "fletcher32": bool},
    read_libraries=("h5py",),
    description="native archive: chunked, fletcher32 checksums, windows read in place")
#: Layout version written by :func:`write`; readers refuse newer versions.
FORMAT_VERSION = 1
#: Samples per chunk (131072 float64 samples = 1 MiB, the HDF5 default chunk-cache size).
DEFAULT_CHUNK_SAMPLES = 131072

#: HDF5 file-format versions written (lowest, highest): 1.10, the first with checksums on
#: every metadata object that a recording uses (readable by HDF5 >= 1.10).
LIBVER = ("v110", "v110")

_MAGIC = b"\x89HDF\r\n\x1a\n"
_USERBLOCK_OFFSETS = (0, 512, 1024, 2048)
_GROUP = "channels"


# ---------------------------------------------------------------------------- helpers
def loads_json(text: Any, path, what: str, kind: type):
    """Parse JSON text read from a file; RecordingFileError naming the file and ``what``."""
    if isinstance(text, bytes):
        text = text.decode("utf-8", errors="replace")
    if not isinstance(text, str):
        raise RecordingFileError(path, f"{what} must be JSON text, got {type(text).__name__}")
    try:
        value = json.loads(text)
    except json.JSONDecodeError as exc:
        raise RecordingFileError(path, f"{what} is not valid JSON ({exc})") from exc
    if not isinstance(value, kind):
        raise RecordingFileError(path, f"{what} must be a JSON {'object' if kind is dict else 'array'}, "
                                       f"got {type(value).__name__}")
    return value


def _plain(v: Any) -> Any:
    """HDF5 attribute value -> JSON-like Python value."""
    if isinstance(v, bytes):
        return v.decode("utf-8", errors="replace")
    if isinstance(v, np.ndarray):
        return [_plain(x) for x in v.tolist()] if v.ndim else _plain(v.item())
    if isinstance(v, (np.bool_,)):
        return bool(v)
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, np.floating):
        return float(v)
    if isinstance(v, list):
        return [_plain(x) for x in v]
    return v


# ---------------------------------------------------------------------------- names
def dataset_name(channel: str) -> str:
    """HDF5 link name of a channel's dataset (``%`` and ``/`` percent-encoded)."""
    out = channel.replace("%", "%25").replace("/", "%2F")
    return "%2E" if out == "." else out


# ---------------------------------------------------------------------------- sniff
#: user-block text of a MATLAB 7.3 MAT-file (HDF5 inside, read by :mod:`meshphase.io.matlab`)
_MATLAB_TEXT = b"MATLAB 7.3 MAT-file"


def sniff(head: bytes) -> bool:
    """True when ``head`` carries the HDF5 signature at offset 0, 512, 1024 or 2048, and its
    user block is not a MATLAB 7.3 MAT-file's header (that file is the ``matlab`` format's)."""
    if head.startswith(_MATLAB_TEXT):
        return False
    return any(head[o:o + 8] == _MAGIC for o in _USERBLOCK_OFFSETS)


# ---------------------------------------------------------------------------- reading
def _open(path):
    import h5py

    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file")
    try:
        # rdcc_nbytes=0: no chunk cache, so uncompressed chunks go straight into the output buffer
        return h5py.File(path, "r", rdcc_nbytes=0)
    except OSError as exc:
        size = path.stat().st_size
        raise CorruptFileError(path, f"file of {size} bytes", f"cannot open as HDF5: truncated or corrupt "
                                                              f"file ({exc})") from exc


# what h5py raises for damaged metadata (checksum, bad address) read after opening
_H5_ERRORS = (OSError, KeyError, RuntimeError, ValueError, TypeError)


class _MetaErrors:
    """Turn h5py errors while reading metadata (attributes, groups) into CorruptFileError."""

    def __init__(self, path):
        self.path = path

    def __enter__(self):
        return self

    def __exit__(self, typ, exc, tb):
        if exc is None or isinstance(exc, RecordingFileError) or not isinstance(exc, _H5_ERRORS):
            return False
        if isinstance(exc, (ValueError, TypeError)) and "checksum" not in str(exc):
            return False
        raise CorruptFileError(self.path, "HDF5 metadata (header, attributes or index)",
                               f"cannot be read: {type(exc).__name__}: {exc}") from exc


_HEADER_CACHE: "OrderedDict[tuple, tuple]" = OrderedDict()
_HEADER_CACHE_SIZE = 64


def _cache_key(f, path) -> tuple | None:
    """Key identifying this exact file content, or None (no caching) for files without a
    ``file_id`` (a random UUID our writer stores at every write, so a file rewritten at the
    same path never hits a stale entry; size and mtime guard against in-place edits)."""
    file_id = _plain(f.attrs.get("file_id"))
    if not isinstance(file_id, str):
        return None
    st = os.stat(path)
    return (os.path.realpath(path), file_id, st.st_size, st.st_mtime_ns)


def _header(f, path, fs_opt=None) -> tuple[dict, list, list]:
    """Validated header of an open file: (root attrs, channel specs, datasets in column order).

    Parsed headers are cached (see :func:`_cache_key`): the registry reads the header for
    ``read_info`` and again for ``read``, and each HDF5 attribute costs ~40 us to read. A
    file another tool wrote (no ``meshphase_format``) is read as :func:`_foreign_header`
    finds it; ``fs_opt`` [Hz] gives or overrides its sample rate.
    """
    with _MetaErrors(path):
        if "meshphase_format" not in f.attrs:
            st = os.stat(path)
            key = ("foreign", os.path.realpath(path), st.st_size, st.st_mtime_ns, fs_opt)
            hit = _HEADER_CACHE.get(key)
            if hit is None:       # parsed (and warned about) once per file content
                hit = _cache_put(key, _foreign_header(f, path, fs_opt))
            attrs, specs, where = hit
            return (copy.deepcopy(attrs), list(specs),
                    [f[p] if col is None else _Column(f[p], col, axis) for p, col, axis in where])
        attrs, specs, dsets = _header_checked(f, path)
        if fs_opt is not None and abs(float(fs_opt) - attrs["fs"]) > 1e-9 * attrs["fs"]:
            warnings.warn(FormatWarning(f"{path}: fs={fs_opt!r} Hz given overrides the file's {attrs['fs']!r} Hz"),
                          stacklevel=4)
            attrs["fs"] = float(fs_opt)
        return attrs, specs, dsets


def _cache_put(key: tuple, hit: tuple) -> tuple:
    """``hit`` into the header cache under ``key``, the oldest entries out past its size."""
    _HEADER_CACHE[key] = hit
    while len(_HEADER_CACHE) > _HEADER_CACHE_SIZE:
        _HEADER_CACHE.popitem(last=False)
    return hit


def _header_checked(f, path) -> tuple[dict, list, list]:
    key = _cache_key(f, path)
    hit = _HEADER_CACHE.get(key) if key is not None else None
    if hit is None:
        hit = _parse_header(f, path)
        if key is not None:
            _cache_put(key, hit)
    else:
        _HEADER_CACHE.move_to_end(key)
    attrs, specs, keys = hit
    attrs = dict(attrs, meta=copy.deepcopy(attrs["meta"]), history=copy.deepcopy(attrs["history"]))
    group = f[_GROUP]
    return attrs, list(specs), [group[k] for k in keys]


#: attributes (any case) stating a sample rate [Hz] in HDF5 files of other tools
_RATE_ATTRS = ("fs", "fs_hz", "sample_rate", "sampling_rate", "samplerate", "sampling_frequency",
               "sample_rate_hz", "rate")
#: attributes (any case) stating a sample interval [s]
_INTERVAL_ATTRS = ("dt", "sample_interval", "wf_increment", "increment", "time_step")


def _stated_rate(objs, path, where: str) -> float | None:
    """The sample rate [Hz] an attribute of the first of ``objs`` (a dataset, then its groups
    up to the root) states: a rate (:data:`_RATE_ATTRS`) or an interval
    (:data:`_INTERVAL_ATTRS`); None when none does."""
    for obj in objs:
        low = {str(k).lower(): k for k in obj.attrs.keys()}
        for names, invert in ((_RATE_ATTRS, False), (_INTERVAL_ATTRS, True)):
            for a in names:
                if a in low:
                    v = _plain(obj.attrs[low[a]])
                    if isinstance(v, list) and len(v) == 1:
                        v = v[0]
                    if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
                        raise RecordingFileError(path, f"{where}: attribute {low[a]} = {v!r} of {obj.name} is "
                                                       f"not a positive {'interval' if invert else 'rate'}")
                    return 1.0 / float(v) if invert else float(v)
    return None


#: attributes (any case) of a 2-D dataset naming its channels
_NAMES_ATTRS = ("channels", "channel_names", "names", "columns", "labels")
#: attributes (any case) of a 2-D or N-D dataset giving its samples axis (0-based, in the
#: dataset's own axis order as h5py and numpy show it)
_AXIS_ATTRS = ("time_axis", "sample_axis", "samples_axis")
#: a dataset of channels read at a time is read in pieces of at most this many bytes
_PIECE_BYTES = 64 * 2 ** 20


class _Column:
    """One channel of a 2-D or N-D dataset (samples along ``axis``; ``col`` the index over
    the other axes: an int for a 2-D dataset, a tuple for N-D), read like a 1-D dataset:
    through h5py's selection, never the raw-chunk path (``chunks`` None)."""

    chunks = None
    fletcher32 = False

    def __init__(self, ds, col, axis: int):
        self.ds, self.axis = ds, int(axis)
        self.col = tuple(int(c) for c in col) if isinstance(col, (tuple, list)) else int(col)
        idx = self.col if isinstance(self.col, tuple) else (self.col,)
        other = tuple(d for k, d in enumerate(ds.shape) if k != self.axis)
        #: the column's index into the other axes flattened in C order
        self.flat = int(np.ravel_multi_index(idx, other))
        self.name = f"{ds.name}[{','.join(map(str, idx))}]"
        self.dtype, self.attrs, self.parent = ds.dtype, ds.attrs, ds.parent
        self.shape = (ds.shape[self.axis],)
        self.compression = ds.compression

    def _sel(self, source):
        idx = list(self.col) if isinstance(self.col, tuple) else [self.col]
        idx.insert(self.axis, source)
        return tuple(idx)

    def read_direct(self, dest, source=np.s_[:]):
        self.ds.read_direct(dest, self._sel(source))

    def __getitem__(self, key):
        return self.ds[self._sel(np.s_[:] if key == () else key)]


def _samples_axis(ds, path) -> int | None:
    """The samples axis of a 2-D or N-D dataset: an axis attribute (:data:`_AXIS_ATTRS`),
    else (2-D) the axis other than the one a names attribute's count matches, else the
    longest axis; None when two axes tie for longest (ambiguous)."""
    low = {str(a).lower(): a for a in ds.attrs.keys()}
    for a in _AXIS_ATTRS:
        if a in low:
            v = _plain(ds.attrs[low[a]])
            if isinstance(v, list) and len(v) == 1:
                v = v[0]
            if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v < ds.ndim:
                raise RecordingFileError(path, f"attribute {low[a]} = {v!r} of dataset {ds.name} (shape "
                                               f"{ds.shape}) is not an axis 0 to {ds.ndim - 1}")
            return v
    if ds.ndim == 2:
        for a in _NAMES_ATTRS:
            if a in low:
                v = _plain(ds.attrs[low[a]])
                k = len(v.split(",")) if isinstance(v, str) else len(v) if isinstance(v, list) else -1
                match = [ax for ax in (0, 1) if ds.shape[ax] == k]
                if len(match) == 1:
                    return 1 - match[0]
    longest = max(ds.shape)
    if list(ds.shape).count(longest) > 1:
        return None
    return int(np.argmax(ds.shape))


def _column_names(ds, k: int, base: str) -> list[str]:
    """Names of a 2-D dataset's ``k`` channels: a names attribute (:data:`_NAMES_ATTRS`) of
    ``k`` strings, else ``<base>_<i>``."""
    low = {str(a).lower(): a for a in ds.attrs.keys()}
    for a in _NAMES_ATTRS:
        if a in low:
            v = _plain(ds.attrs[low[a]])
            if isinstance(v, str):
                v = [t.strip() for t in v.split(",")]
            if isinstance(v, list) and len(v) == k and all(isinstance(t, str) and t for t in v):
                return v
    return [f"{base}_{i}" for i in range(k)]


def _foreign_header(f, path, fs_opt) -> tuple[dict, tuple, tuple]:
    """Header of an HDF5 file another tool wrote: its numeric datasets of the longest length
    are the channels (shorter ones skipped with a FormatWarning): a 1-D dataset is one
    channel; a 2-D one, of any size, one channel per index of its other axis (the samples
    axis by :func:`_samples_axis`: an axis attribute, else the axis other than the one a
    names attribute counts, else the longer; named by a names attribute, else
    ``<dataset>_<i>``); an N-D one one channel per index over the axes other than the samples
    axis (``<dataset>[i,j]``, C order); a dataset whose two longest axes tie at the longest
    length found is refused as ambiguous. Channels are named by their link names (full paths
    where those repeat), kind from the name as for TDMS, units from a ``units`` / ``unit``
    attribute (a list: one per column of a 2-D dataset). The rate: ``fs_opt``, else a clock
    dataset or column (:data:`CLOCK_NAMES`; not a channel), else a rate or interval attribute
    on the datasets or their groups (:data:`_RATE_ATTRS`, :data:`_INTERVAL_ATTRS`); all
    stating one must agree. Returns (attrs, specs, (dataset path, column or None, samples
    axis) per channel)."""
    import h5py

    found = []                                         # (dataset or column, name)
    ambiguous = []                                     # (dataset, length of its tied axes)

    def visit(name, obj):
        if not isinstance(obj, h5py.Dataset) or obj.dtype.kind not in "biuf" or 0 in obj.shape or not obj.ndim:
            return
        base = obj.name.rsplit("/", 1)[-1]
        if obj.ndim == 1:
            found.append((obj, base))
            return
        axis = _samples_axis(obj, path)
        if axis is None:
            ambiguous.append((obj, max(obj.shape)))
            return
        other = tuple(d for k, d in enumerate(obj.shape) if k != axis)
        if obj.ndim == 2:
            found.extend((_Column(obj, i, axis), nm) for i, nm in enumerate(_column_names(obj, other[0], base)))
        else:
            found.extend((_Column(obj, idx, axis), f"{base}[{','.join(map(str, idx))}]")
                         for idx in np.ndindex(*other))

    f.visititems(visit)
    longest = max([ds.shape[0] for ds, _ in found] + [0])
    tied = [(ds, m) for ds, m in ambiguous if m >= longest]
    if tied:
        ds, m = tied[0]
        raise RecordingFileError(path, f"dataset {ds.name} of shape {ds.shape}: two axes of {m} values, so "
                                       "which is the samples axis is ambiguous; give it an attribute "
                                       f"{_AXIS_ATTRS[0]} (the samples axis, 0-based){' or a names attribute' if ds.ndim == 2 else ''}")
    if not found:
        raise RecordingFileError(path, "an HDF5 file but not a meshphase recording (root attribute "
                                       "meshphase_format='recording' missing), and it holds no 1-D numeric "
                                       "dataset (nor a 2-D or N-D one) to read as channels")
    n = max(ds.shape[0] for ds, _ in found)
    skipped = sorted({ds.name for ds, _ in found if ds.shape[0] != n} | {ds.name for ds, _ in ambiguous})
    if skipped:
        warnings.warn(FormatWarning(f"{path}: skipped dataset(s) {skipped}: shorter than the channels "
                                    f"({n} samples)"), stacklevel=4)
    chans = [ds for ds, _ in found if ds.shape[0] == n]
    base = [nm for ds, nm in found if ds.shape[0] == n]
    clock = None
    if fs_opt is None and len(chans) > 1:
        clock = next((i for i, b in enumerate(base) if b.strip().lower() in CLOCK_NAMES), None)
    start = None
    t0 = 0.0
    if clock is not None:
        ds = chans.pop(clock)
        base.pop(clock)
        fs, t0, start = clock_timing(path, f"clock dataset {ds.name!r}", ds[()], n)
    elif fs_opt is not None:
        fs = float(fs_opt)
    else:
        rates = {}
        for ds in chans:
            parents, g = [ds], ds.parent
            while True:
                parents.append(g)
                if g.name == "/":
                    break
                g = g.parent
            rates[ds.name] = _stated_rate(parents, path, "sample rate")
        given = {k: v for k, v in rates.items() if v is not None}
        if not given:
            raise RecordingFileError(path, "an HDF5 file of another tool with no sample rate: no clock dataset "
                                           f"(named {', '.join(CLOCK_NAMES[:3])}, ...) and no rate attribute "
                                           f"({', '.join(_RATE_ATTRS[:3])}, ... or an interval dt, ...); give the "
                                           "rate: [input] fs_Hz in a scene, fs= to meshphase.io.read")
        vals = list(given.values())
        if max(vals) - min(vals) > 1e-9 * max(vals):
            raise RecordingFileError(path, f"datasets state different sample rates {given}")
        fs = vals[0]
    names = base if len(set(base)) == len(base) else [
        ds.name.lstrip("/") if isinstance(ds, h5py.Dataset) else f"{ds.ds.name.lstrip('/')}/{b}"
        for ds, b in zip(chans, base)]
    specs = []
    unit_attrs: dict = {}                              # dataset name -> its units attribute (read once)
    for name, ds in zip(names, chans):
        key = ds.ds.name if isinstance(ds, _Column) else ds.name
        if key not in unit_attrs:
            unit_attrs[key] = next((_plain(ds.attrs[k]) for k in ds.attrs.keys()
                                    if str(k).lower() in ("units", "unit", "unit_string")), "")
        units = unit_attrs[key]
        if isinstance(units, list) and isinstance(ds, _Column):
            units = units[ds.col] if isinstance(ds.col, int) and ds.col < len(units) else ""
        try:
            specs.append(ChannelSpec(name=name, kind=kind_from_name(name.rsplit("/", 1)[-1],
                                                                    ds.parent.name.strip("/")),
                                     units=units if isinstance(units, str) else ""))
        except (ValueError, TypeError) as exc:
            raise RecordingFileError(path, f"dataset {ds.name!r}: {exc}") from exc
    checked = set()
    for nm, ds in zip(names, chans):
        whole = ds.ds if isinstance(ds, _Column) else ds
        if whole.name not in checked:
            checked.add(whole.name)
            _check_written(path, whole, nm, fs, ds.axis if isinstance(ds, _Column) else 0)
    dtypes = {ds.dtype for ds in chans}
    dtype = "float32" if dtypes == {np.dtype(np.float32)} else "float64"
    root = {str(k): _plain(v) for k, v in f.attrs.items()}
    attrs = {"fs": fs, "t0": t0, "n_samples": n, "dtype": dtype, "start_datetime": start,
             "format_version": None, "created_by": root.get("created_by"), "file_id": None,
             "meta": {"hdf5": {"root": _jsonable_attrs(root), "datasets": _datasets_meta(names, chans)}},
             "history": [{"step": "read_hdf5", "file": Path(path).name, "layout": "other tool",
                          "datasets": {nm: ds.name for nm, ds in zip(names, chans)},
                          "fs_from": "given" if fs_opt is not None else "clock" if clock is not None else "attribute"}]}
    return attrs, tuple(specs), tuple((ds.name, None, 0) if isinstance(ds, h5py.Dataset)
                                      else (ds.ds.name, ds.col, ds.axis) for ds in chans)


def _datasets_meta(names, chans) -> dict:
    """The attributes of the datasets read: by channel name for a 1-D dataset, once by the
    dataset's path (without the leading ``/``) for a 2-D or N-D one."""
    out = {}
    for nm, ds in zip(names, chans):
        key = ds.ds.name.lstrip("/") if isinstance(ds, _Column) else nm
        if key not in out:
            out[key] = _jsonable_attrs({str(k): _plain(v) for k, v in ds.attrs.items()})
    return out


def _stored_chunk_offsets(ds) -> np.ndarray:
    """Offsets (in elements, one row per dimension) of the chunks of ``ds`` that are stored:
    read from the chunk index (metadata, no samples), by ``chunk_iter`` where h5py has it
    (one pass over the index), else chunk by chunk through ``get_chunk_info``."""
    offs: list = []
    if hasattr(ds.id, "chunk_iter"):
        ds.id.chunk_iter(lambda info: offs.append(info.chunk_offset))
    else:
        offs = [ds.id.get_chunk_info(i).chunk_offset for i in range(ds.id.get_num_chunks())]
    return np.array(offs, dtype=np.int64).reshape(-1, ds.ndim).T


def _check_written(path, ds, name: str, fs: float, axis: int = 0) -> None:
    """Raise when samples of the channel ``name`` (dataset ``ds``, samples along ``axis``)
    were never written.

    HDF5 gives its fill value (zero) for a chunk that is not stored, and no checksum is
    checked for it: the chunk index is compared with the declared shape. A chunk is
    allocated as a whole, so the check costs a look at the index (``get_num_chunks``: no
    sample is read); only a file with missing chunks pays a pass over the index to name
    their time range. A contiguous dataset must have the storage its shape declares; a
    virtual or external one is not checked (its samples live in other files). A chunk that
    was written in part is stored whole: its unwritten samples (the fill value) are beyond
    what the index can show.

    Raises
    ------
    CorruptFileError
        Naming the channel, the dataset, the first unwritten sample range [samples] and its
        time range [s], and how many chunks are missing.
    """
    n = int(ds.shape[axis]) if ds.ndim else 0
    if n == 0 or ds.is_virtual or ds.external:
        return
    where = f"channel {name!r} (dataset {ds.name})"
    if ds.chunks is None:
        want = int(ds.size) * ds.dtype.itemsize
        got = int(ds.id.get_storage_size())
        if got < want:
            raise CorruptFileError(path, where, f"{got} of the {want} bytes its {n} samples need are stored: "
                                                "the samples were never written (HDF5 reads them as zeros)")
        return
    grid = [-(-int(s) // int(c)) for s, c in zip(ds.shape, ds.chunks)]
    total = math.prod(grid)
    if ds.id.get_num_chunks() >= total:
        return
    c = int(ds.chunks[axis])
    rows = _stored_chunk_offsets(ds)[axis] // c
    done, count = np.unique(rows, return_counts=True)
    done = done[count >= total // grid[axis]]           # rows with every chunk across them stored
    gap = np.flatnonzero(done != np.arange(done.size))
    first = int(gap[0]) if gap.size else int(done.size)
    after = done[done > first]
    last = int(after[0]) - 1 if after.size else grid[axis] - 1
    a, b = first * c, min(n, (last + 1) * c)
    raise CorruptFileError(
        path, f"{where}, samples [{a}, {b}) ({a / fs:.6g} s to {b / fs:.6g} s)",
        f"never written: {total - rows.size} of its {total} chunks are missing from the file "
        f"(HDF5 would read them as zeros); the file is incomplete")


def _jsonable_attrs(d: dict) -> dict:
    """Attributes as strict JSON values (:func:`meshphase.jsonable.to_jsonable`; non-finite
    numbers as their text, anything it leaves alone (object references) as text)."""
    out = to_jsonable(d, nonfinite="repr")
    return {k: v if v is None or isinstance(v, (str, int, float, bool, list, dict)) else str(v)
            for k, v in out.items()}


def _parse_header(f, path) -> tuple[dict, tuple, tuple]:
    import h5py
    from meshphase.data_schemas import validate

    attrs = {k: _plain(v) for k, v in f.attrs.items()}
    for key in ("meta", "history"):
        crc = attrs.pop(f"{key}_crc32", None)
        text = attrs.get(key)
        if crc is not None and isinstance(text, str) and zlib.crc32(text.encode("utf-8")) != crc:
            raise CorruptFileError(path, f"root attribute {key}",
                                   f"CRC32 mismatch: the {len(text)}-character text is damaged "
                                   f"(or was edited without updating {key}_crc32)")
    if attrs.get("meshphase_format") != "recording":
        raise RecordingFileError(path, "an HDF5 file but not a meshphase recording "
                                       "(root attribute meshphase_format='recording' missing)")
    version = attrs.get("format_version")
    if isinstance(version, int) and version > FORMAT_VERSION:
        raise RecordingFileError(path, f"written with HDF5 layout version {version}; this reader knows "
                                       f"versions up to {FORMAT_VERSION}")
    fs = attrs.get("fs")
    if isinstance(fs, bool) or not isinstance(fs, (int, float)) or not (math.isfinite(fs) and fs > 0):
        raise RecordingFileError(path, f"missing or non-positive sample rate (root attribute fs = {fs!r})")
    order = attrs.get("channel_order")
    if isinstance(order, str):
        order = [order]
        attrs["channel_order"] = order
    if isinstance(order, list):
        dup = sorted({n for n in order if order.count(n) > 1})
        if dup:
            raise RecordingFileError(path, f"duplicate channel name(s) {dup} in channel_order")
    group = f.get(_GROUP)
    if not isinstance(group, h5py.Group):
        raise RecordingFileError(path, f"group /{_GROUP} missing")
    dsets = {}
    for key, ds in group.items():
        if not isinstance(ds, h5py.Dataset):
            raise RecordingFileError(path, f"/{_GROUP}/{key} is not a dataset")
        dsets[key] = {"shape": list(ds.shape), "dtype": str(ds.dtype),
                      "attrs": {k: _plain(v) for k, v in ds.attrs.items()}}
    try:
        validate({"attrs": attrs, "channels": dsets}, "hdf5_layout")
    except ValueError as exc:
        raise RecordingFileError(path, f"bad header: {exc}") from exc
    n = attrs["n_samples"]
    keys = [dataset_name(name) for name in order]
    missing = [name for name, k in zip(order, keys) if k not in dsets]
    if missing:
        raise RecordingFileError(path, f"channel(s) {missing} listed in channel_order have no dataset in /{_GROUP}")
    extra = sorted(set(dsets) - set(keys))
    if extra:
        raise RecordingFileError(path, f"dataset(s) {extra} in /{_GROUP} are not listed in channel_order")
    lengths = {name: dsets[k]["shape"][0] for name, k in zip(order, keys)}
    if any(v != n for v in lengths.values()):
        raise RecordingFileError(path, f"channels of unequal length (n_samples = {n}): {lengths}")
    dtypes = {dsets[k]["dtype"] for k in keys}
    if len(dtypes) > 1:
        raise RecordingFileError(path, f"channels have mixed dtypes {sorted(dtypes)}")
    declared = attrs.get("dtype")
    if declared is not None and dtypes and dtypes != {declared}:
        raise RecordingFileError(path, f"root attribute dtype = {declared!r} but the channels are {sorted(dtypes)}")
    attrs["dtype"] = dtypes.pop() if dtypes else (declared or "float64")
    specs = []
    for name, k in zip(order, keys):
        d = dsets[k]["attrs"]
        if d.get("name") != name:
            raise RecordingFileError(path, f"dataset /{_GROUP}/{k} has name attribute {d.get('name')!r}, "
                                           f"expected {name!r}")
        specs.append(spec_from_dict(d, path, f"/{_GROUP}/{k}", checked=True))
        _check_written(path, group[k], name, float(fs))
    attrs["meta"] = loads_json(attrs["meta"], path, "root attribute meta", dict)
    attrs["history"] = loads_json(attrs["history"], path, "root attribute history", list)
    attrs["start_datetime"] = check_start_datetime(attrs.get("start_datetime"), path)
    return attrs, tuple(specs), tuple(keys)


def read_info(path, *, fs: float | None = None, verify: bool = True) -> RecordingInfo:
    """Header of an HDF5 recording (root and channel attributes; no samples are read).

    ``verify`` is accepted for the registry's uniform options; the metadata checksums of
    the HDF5 format are always checked by HDF5.

    Raises
    ------
    CorruptFileError
        Truncated file, damaged metadata (checksum mismatch).
    RecordingFileError
        Not a meshphase recording, header not matching
        ``hdf5_layout.schema.json``, missing or non-positive sample rate, channels of unequal
        length, duplicate channel names.
    """
    check_verify(verify)
    with _open(path) as f, _MetaErrors(path):
        attrs, specs, dsets = _header(f, path, _fs_option(fs))
        extra = {"format_version": attrs["format_version"],
                 "dtype": attrs["dtype"],
                 "chunks": dsets[0].chunks if dsets else None,
                 "compression": dsets[0].compression if dsets else None,
                 "fletcher32": bool(dsets[0].fletcher32) if dsets else None,
                 "created_by": attrs.get("created_by"), "file_id": attrs.get("file_id")}
    return RecordingInfo(path=str(path), format=NAME, fs=float(attrs["fs"]), n_samples=int(attrs["n_samples"]),
                         channels=specs, t0=float(attrs["t0"]), start_datetime=attrs["start_datetime"],
                         meta=attrs["meta"], history=attrs["history"], extra=extra)


def _fs_option(fs) -> float | None:
    return None if fs is None else as_positive(fs, "fs")


def _unverified_ok(ds) -> bool:
    """True when the chunks of ``ds`` can be read raw with the checksum skipped: fletcher32
    is its only filter."""
    return bool(ds.chunks and ds.fletcher32 and ds.compression is None and not ds.shuffle
                and not ds.scaleoffset)


def _read_raw_chunks(ds, out: np.ndarray, i0: int, i1: int, chunks: "_ChunkReader | None" = None) -> None:
    """Samples [i0, i1) of a fletcher32-only dataset into ``out``, checksums not checked:
    by ``chunks`` (:class:`_ChunkReader`, ``os.preadv`` at the chunks' byte offsets) where
    it can, else chunk by chunk through h5py's ``read_direct_chunk`` (the library path)."""
    c = ds.chunks[0]
    dtype = ds.dtype
    for c0 in range((i0 // c) * c, i1, c):
        a, b = max(i0, c0), min(i1, c0 + c)
        if chunks is not None and chunks.read(ds, c0, a, b, out[a - i0:b - i0]):
            continue
        try:
            _, raw = ds.id.read_direct_chunk((c0,))
        except RuntimeError:                   # never written: HDF5 gives its fill value
            if ds.id.get_chunk_info_by_coord((c0,)).byte_offset is not None:
                raise
            ds.read_direct(out[a - i0:b - i0], np.s_[a:b])
            continue
        out[a - i0:b - i0] = np.frombuffer(raw, dtype, b - a, (a - c0) * dtype.itemsize)


class _ChunkReader:
    """Stored chunks of fletcher32-only datasets read at their byte offsets with one
    ``os.preadv`` each, straight into the output (h5py's ``read_direct_chunk``, the library
    path, returns a new bytes object per chunk, copied again). The offsets come from h5py's public
    ``get_chunk_info_by_coord`` (HDF5 >= 1.10.5), once per chunk; the samples of a stored
    chunk are its first bytes, the checksum follows them.

    ``read`` returns False (the caller takes the library path) where os.preadv, the chunk
    index query or an allocated chunk is missing, or the output's dtype is not the stored
    one (a byte-order conversion).
    """

    def __init__(self, path):
        self.fd = os.open(path, os.O_RDONLY) if hasattr(os, "preadv") else -1
        self.where: dict = {}

    def close(self) -> None:
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def _locate(self, ds, c0: int):
        key = (ds.name, c0)
        if key not in self.where:
            try:
                info = ds.id.get_chunk_info_by_coord((c0,))
                self.where[key] = (None if info.byte_offset is None
                                   else (int(info.byte_offset), int(info.size)))
            except (AttributeError, RuntimeError, ValueError, OSError):
                self.where[key] = None
        return self.where[key]

    def read(self, ds, c0: int, a: int, b: int, out: np.ndarray) -> bool:
        """Samples [a, b) of the chunk starting at sample ``c0`` of ``ds`` into ``out``."""
        if self.fd < 0 or out.dtype != ds.dtype or not out.flags.c_contiguous:
            return False
        loc = self._locate(ds, c0)
        item = ds.dtype.itemsize
        if loc is None or (b - c0) * item > loc[1]:
            return False
        want = (b - a) * item
        got = os.preadv(self.fd, [memoryview(out).cast("B")], loc[0] + (a - c0) * item)
        if got != want:
            raise OSError(f"the file ends inside the chunk at byte {loc[0]} ({got} of {want} bytes read)")
        return True


def _locate_bad_chunk(f, path, ds, name: str, i0: int, i1: int, exc: BaseException):
    """CorruptFileError for the first chunk of [i0, i1) of ``ds`` that fails to read."""
    problem = (f"fletcher32 checksum mismatch: the stored samples are damaged ({exc})"
               if ds.fletcher32 else f"cannot read the samples: {exc}")
    where = f"dataset {ds.name} (channel {name!r})"
    if ds.chunks:
        c = ds.chunks[0]
        tmp = np.empty(c, dtype=ds.dtype)
        for c0 in range((i0 // c) * c, i1, c):
            c1 = min(c0 + c, ds.shape[0])
            try:
                ds.read_direct(tmp[:c1 - c0], np.s_[c0:c1])
            except OSError:
                try:
                    off = ds.id.get_chunk_info_by_coord((c0,)).byte_offset
                    at = f" at byte {off}" if off is not None else ""
                except (OSError, RuntimeError, ValueError):
                    at = ""
                return CorruptFileError(path, f"{where}, samples [{c0}, {c1}) (chunk {c0 // c}{at})", problem)
    return CorruptFileError(path, f"{where}, samples [{i0}, {i1})", problem)


def _read_open(f, path, attrs, specs, dsets, names, i0, i1, verify: bool = True,
               chunks: "_ChunkReader | None" = None) -> Recording:
    by_name = {s.name: (s, d) for s, d in zip(specs, dsets)}
    sel = [by_name[nm] for nm in names]
    dtype = np.dtype(attrs["dtype"])
    n = i1 - i0
    check_allocation(path, n, len(sel), dtype.itemsize)
    buf = np.empty((len(sel), n), dtype=dtype)  # channel-major; data = buf.T (Fortran order)
    if n:
        source = np.s_[i0:i1]
        columns: dict = {}                              # 2-D / N-D dataset -> [(j, column)]
        for j, (spec, ds) in enumerate(sel):
            if isinstance(ds, _Column):
                columns.setdefault(ds.ds.name, []).append((j, ds))
        for group in columns.values():
            if len(group) > 1:
                _read_columns(f, path, group, buf, i0, i1, [sel[j][0].name for j, _ in group])
        for j, (spec, ds) in enumerate(sel):
            if isinstance(ds, _Column) and len(columns[ds.ds.name]) > 1:
                continue
            try:
                if not verify and _unverified_ok(ds):
                    _read_raw_chunks(ds, buf[j], i0, i1, chunks)
                else:
                    ds.read_direct(buf[j], source)
            except (OSError, RuntimeError) as exc:
                raise _locate_bad_chunk(f, path, ds, spec.name, i0, i1, exc) from exc
    data = buf.T
    warn_nonfinite(path, data, names, i0)
    fs = float(attrs["fs"])
    return Recording(data, fs, [s for s, _ in sel], t0=float(attrs["t0"]) + i0 / fs,
                     start_datetime=attrs["start_datetime"], meta=attrs["meta"], history=attrs["history"])


def _read_columns(f, path, group: list, buf: np.ndarray, i0: int, i1: int, names: list) -> None:
    """Samples [i0, i1) of several channels of one 2-D or N-D dataset (``group``: (row of
    ``buf``, column)) into ``buf``: the dataset's slab of the window read once, in pieces of
    at most :data:`_PIECE_BYTES`, each column copied out of it."""
    ds, axis = group[0][1].ds, group[0][1].axis
    row = math.prod(d for k, d in enumerate(ds.shape) if k != axis) * ds.dtype.itemsize
    step = max(1, _PIECE_BYTES // max(row, 1))
    flats = np.array([c.flat for _, c in group])
    rows = np.array([j for j, _ in group])
    for a in range(i0, i1, step):
        b = min(i1, a + step)
        sel = tuple(slice(a, b) if k == axis else slice(None) for k in range(ds.ndim))
        try:
            piece = ds[sel]
        except (OSError, RuntimeError) as exc:
            raise _locate_bad_chunk(f, path, group[0][1], names[0], a, b, exc) from exc
        piece = np.moveaxis(piece, axis, 0).reshape(b - a, -1)
        buf[rows, a - i0:b - i0] = piece[:, flats].T


def _check_range(path, n_samples, i0, i1):
    i0 = as_int(i0, "i0")
    i1 = n_samples if i1 is None else as_int(i1, "i1")
    if not 0 <= i0 <= i1 <= n_samples:
        raise ValueError(f"{path}: sample range [{i0}, {i1}) outside the recording's [0, {n_samples})")
    return i0, i1


def _names(path, specs, channels) -> list[str]:
    if not specs:  # a recording without channels: only the empty selection exists
        return []
    info = RecordingInfo(path=str(path), format=NAME, fs=1.0, n_samples=0, channels=specs)
    return info.check_channels(channels)


def read(path, channels=None, i0: int = 0, i1: int | None = None, *, fs: float | None = None,
         verify: bool = True) -> Recording:
    """Samples ``i0 <= i < i1`` of the named channels (all when None) of an HDF5 recording.

    Parameters
    ----------
    path : str or Path
    channels : str or sequence of str, optional
        Channel names, in the order wanted.
    i0, i1 : int
        Sample range [i0, i1) (default: all).
    verify : bool
        Check the fletcher32 checksum of every chunk read (default True). False reads the
        chunks of fletcher32-only datasets raw, unchecked (compressed ones stay checked).

    Returns
    -------
    Recording
        Data are a Fortran-ordered (channel-major) samples x channels array of the file's
        dtype; ``t0`` is shifted to the first sample read.

    Raises
    ------
    CorruptFileError
        A chunk's checksum does not match (dataset, sample range and byte offset named),
        the file is truncated, or its metadata are damaged.
    """
    verify = check_verify(verify)
    with _open(path) as f:
        attrs, specs, dsets = _header(f, path, _fs_option(fs))
        names = _names(path, specs, channels)
        i0, i1 = _check_range(path, int(attrs["n_samples"]), i0, i1)
        with _ChunkReader(path) if not verify else contextlib.nullcontext() as chunks:
            return _read_open(f, path, attrs, specs, dsets, names, i0, i1, verify, chunks)


def iter_blocks(path, n_block: int, n_overlap: int, channels=None, *, fs: float | None = None,
                verify: bool = True) -> Iterator[Recording]:
    """Blocks of ``n_block`` samples plus ``n_overlap`` following samples, file kept open.

    Block k covers samples [k n_block, (k + 1) n_block + n_overlap), clipped to the recording.
    ``verify`` as in :func:`read`.
    """
    verify = check_verify(verify)
    n_block = as_positive_int(n_block, "n_block")
    n_overlap = as_int(n_overlap, "n_overlap")
    if n_overlap < 0:
        raise ValueError(f"n_overlap must be >= 0, got {n_overlap}")
    with _open(path) as f:
        attrs, specs, dsets = _header(f, path, _fs_option(fs))
        names = _names(path, specs, channels)
        n = int(attrs["n_samples"])
        with _ChunkReader(path) if not verify else contextlib.nullcontext() as chunks:
            for i0 in range(0, n, n_block):
                yield _read_open(f, path, attrs, specs, dsets, names, i0,
                                 min(n, i0 + n_block + n_overlap), verify, chunks)


# ---------------------------------------------------------------------------- writing
def write(recording: Recording, path, *, compression: str | None = None, compression_opts: int | None = None,
          shuffle: bool | None = None, chunk_samples: int = DEFAULT_CHUNK_SAMPLES,
          fletcher32: bool = True) -> None:
    """Write ``recording`` to a new HDF5 file at ``path`` (the registry makes it atomic).

    Parameters
    ----------
    recording : Recording
    path : str or Path
    compression : {None, "gzip", "lzf"}
        Per-dataset compression (default None: fastest reads; gzip saves only 10-24 % on
        noisy strain and reads at ~0.04 GS/s).
    compression_opts : int, optional
        gzip level 0-9 (default 4); not allowed with lzf or None.
    shuffle : bool, optional
        Byte-shuffle filter; default True when compressed, False otherwise.
    chunk_samples : int
        Samples per chunk [-] (default 131072).
    fletcher32 : bool
        Store a fletcher32 checksum with every chunk (default True; 4 bytes per chunk,
        checked by HDF5 on every read).

    Raises
    ------
    OSError
        From the filesystem (e.g. ENOSPC); the HDF5 file is closed before it propagates.
    """
    if not isinstance(recording, Recording):
        raise TypeError(f"recording must be a Recording, got {type(recording).__name__}")
    write_blocks(recording, [recording.data], path, dtype=recording.data.dtype,
                 compression=compression, compression_opts=compression_opts, shuffle=shuffle,
                 chunk_samples=chunk_samples, fletcher32=fletcher32)


def write_blocks(header, blocks, path, *, dtype="float64", compression: str | None = None,
                 compression_opts: int | None = None, shuffle: bool | None = None,
                 chunk_samples: int = DEFAULT_CHUNK_SAMPLES, fletcher32: bool = True) -> None:
    """Write a recording given as a header and consecutive blocks of samples (streaming).

    Parameters
    ----------
    header : Recording, RecordingInfo or alike
        ``fs``, ``t0``, ``n_samples``, ``channels``, ``start_datetime``, ``meta``,
        ``history`` of the recording (its samples, if any, are not read).
    blocks : iterable of ndarray, shape (k, n_channels)
        The samples, in order; together exactly ``header.n_samples`` rows. Cast to ``dtype``.
    path : str or Path
    dtype : {"float32", "float64"}
        Sample type stored.
    compression, compression_opts, shuffle, chunk_samples, fletcher32
        As :func:`write`.

    Notes
    -----
    Samples are written chunk-aligned (one chunk of every channel is buffered), so memory
    stays at one block plus one chunk per channel whatever the length.
    """
    import h5py

    if compression is not None:
        as_choice(compression, "compression", ("gzip", "lzf"))
    if compression_opts is not None:
        if compression != "gzip":
            raise ValueError(f"compression_opts is only for compression='gzip', got compression={compression!r}")
        compression_opts = as_int(compression_opts, "compression_opts")
        if not 0 <= compression_opts <= 9:
            raise ValueError(f"compression_opts must be a gzip level 0-9, got {compression_opts}")
    elif compression == "gzip":
        compression_opts = 4
    if shuffle is None:
        shuffle = compression is not None
    elif not isinstance(shuffle, (bool, np.bool_)):
        raise TypeError(f"shuffle must be a bool, got {shuffle!r}")
    chunk_samples = as_positive_int(chunk_samples, "chunk_samples")
    if not isinstance(fletcher32, (bool, np.bool_)):
        raise TypeError(f"fletcher32 must be a bool, got {fletcher32!r}")
    dtype = np.dtype(dtype)
    if dtype not in (np.float32, np.float64):
        raise TypeError(f"dtype must be float32 or float64, got {dtype}")
    meta = dumps_json(header.meta, "recording meta")
    history = dumps_json(header.history, "recording history")
    n = int(header.n_samples)
    # rdcc_nbytes=0: chunks go straight to the file, so a failing write (ENOSPC) leaves no
    # dirty chunk cache that HDF5 would flush again on close (which crashed the process)
    f = h5py.File(path, "w", track_order=False, libver=LIBVER, rdcc_nbytes=0)
    try:
        dsets = _write_open(f, header, dtype, meta, history, chunk_samples, compression,
                            compression_opts, shuffle, fletcher32)
        _write_samples(dsets, blocks, n, dtype, min(n, chunk_samples) if n else 1)
    except BaseException as exc:
        _close_after_failure(f, path)
        err = _as_oserror(exc, path) if isinstance(exc, (OSError, RuntimeError)) else exc
        if err is exc:
            raise
        raise err from exc
    try:
        f.close()
    except (OSError, RuntimeError) as exc:  # the final flush failed (disk full)
        _close_after_failure(f, path)
        err = _as_oserror(exc, path)
        if err is exc:
            raise
        raise err from exc
    logger.debug("wrote %s: %d x %d samples, compression=%s", path, n, len(dsets), compression)


def _write_open(f, header, dtype, meta: str, history: str, chunk_samples: int, compression,
                compression_opts, shuffle: bool, fletcher32: bool) -> list:
    """Write the header of the new, open HDF5 file ``f`` and create one dataset per channel
    (see :func:`write_blocks`); returns the datasets in column order."""
    n = int(header.n_samples)
    names = [c.name for c in header.channels]
    f.attrs["meshphase_format"] = _fixed_text("recording")
    f.attrs["format_version"] = np.int64(FORMAT_VERSION)
    f.attrs["fs"] = np.float64(header.fs)
    f.attrs["t0"] = np.float64(header.t0)
    f.attrs["n_samples"] = np.int64(n)
    f.attrs["dtype"] = _fixed_text(str(np.dtype(dtype)))
    if header.start_datetime is not None:
        f.attrs["start_datetime"] = _fixed_text(header.start_datetime)
    f.attrs["channel_order"] = _fixed_text(names)
    for key, text in (("meta", meta), ("history", history)):
        f.attrs[key] = _fixed_text(text)
        b = text.encode("utf-8")
        if len(b) > DENSE_ATTR_BYTES:
            # too large for the checksummed object header: its CRC32 goes there instead
            f.attrs[f"{key}_crc32"] = np.int64(zlib.crc32(b))
    f.attrs["created_by"] = _fixed_text(f"meshphase {_version_string()}")
    f.attrs["file_id"] = _fixed_text(str(uuid.uuid4()))
    group = f.create_group(_GROUP)
    kw = {}
    if n:
        kw["chunks"] = (min(n, chunk_samples),)
        if compression is not None:
            kw.update(compression=compression, compression_opts=compression_opts)
        if shuffle:
            kw["shuffle"] = True
        if fletcher32:
            kw["fletcher32"] = True
    dsets = []
    for spec in header.channels:
        ds = group.create_dataset(dataset_name(spec.name), shape=(n,), dtype=dtype, **kw)
        for key, value in spec.to_dict().items():
            if value is None:
                continue
            if isinstance(value, float):
                value = np.float64(value)
            elif isinstance(value, int):
                value = np.int64(value)
            elif isinstance(value, str):
                value = _fixed_text(value)
            ds.attrs[key] = value
        dsets.append(ds)
    return dsets


#: text attributes longer than this [bytes] leave the object header (HDF5 dense storage)
DENSE_ATTR_BYTES = 60_000


def _fixed_text(value):
    """A text attribute value stored as fixed-length UTF-8 (a str, or a list of str).

    Fixed-length strings live in the object header, which HDF5 1.10 checksums on every read,
    so a damaged letter is an error; variable-length strings would live in the global heap,
    which HDF5 does not checksum (a flipped byte would read back as a different, valid
    text). Attributes over 64 KiB go to HDF5's dense storage, which is not checksummed
    either: for ``meta``/``history`` text that large, :func:`write_blocks` stores its CRC32
    as an integer attribute (``meta_crc32``, ``history_crc32``), checked on read. Files whose
    attributes were edited later with variable-length strings (h5py's default) still read.
    """
    import h5py

    if isinstance(value, str):
        b = value.encode("utf-8")
        return np.array(b, dtype=h5py.string_dtype("utf-8", max(len(b), 1)))
    enc = [v.encode("utf-8") for v in value]
    return np.array(enc, dtype=h5py.string_dtype("utf-8", max([len(b) for b in enc] + [1])))


def _write_samples(dsets: list, blocks, n: int, dtype, cs: int) -> None:
    """Write consecutive blocks into the datasets, one chunk (``cs`` samples) at a time."""
    for group, pos in regroup_blocks(blocks, len(dsets), n, cs, dtype):
        m = group.shape[1]
        for j, ds in enumerate(dsets):
            ds.write_direct(np.ascontiguousarray(group[j]), dest_sel=np.s_[pos:pos + m])


_ERRNO_RE = re.compile(r"errno = (\d+)")


def _as_oserror(exc: BaseException, path) -> OSError:
    """An OSError for an HDF5 write failure (h5py raises RuntimeError from some flushes)."""
    if isinstance(exc, OSError) and exc.errno is not None:
        return exc
    m = _ERRNO_RE.search(str(exc))
    code = int(m.group(1)) if m else errno.EIO
    return OSError(code, f"{os.strerror(code)}: writing HDF5 file {path} failed ({str(exc).splitlines()[0]})",
                   str(path))


def _close_after_failure(f, path) -> None:
    """Close an h5py file whose write failed; HDF5 may fail to flush while closing (ENOSPC),
    so try twice and then leave it (the caller removes the file)."""
    for _ in range(2):
        try:
            if f.id.valid:
                f.close()
            return
        except Exception as exc:  # HDF5 raises OSError/RuntimeError while flushing to a full disk
            logger.debug("closing %s after a failed write: %s", path, exc)


def _version_string() -> str:
    return str(__version__)
