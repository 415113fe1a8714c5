"""Interleaved TDMS rows read together: the channels read from segments whose raw data are
interleaved (one row of every object per value, ``kTocInterleavedData``) are transposed
into channel-major output, every sample tested for NaN/inf on the way so a finite read needs
no second pass. The runs come from :func:`meshphase.io.tdms_index.scan`.

Two engines (:data:`ENGINES`, :func:`rows_engine`):

* ``numpy``: block after block of whole segments, the rows through an aligned buffer
  (``os.preadv`` into it when ``buf`` carries a descriptor, else a copy from the memory
  map), transposed in one numpy assignment per block and summed while in the cache;
* ``numba``: one compiled pass per run of segments straight from the memory map
  (:mod:`meshphase.io._tdms_rows_numba`), the finiteness test folded into the copy. numpy's
  transposing copy costs about four times a contiguous one, and the buffer copy and the sum
  are passes of their own: on the shared 2-core machine the numba engine read 512- and
  1000-sample interleaved segments at 0.32-0.51x the raw read (medians 0.38 and 0.39 of
  ten runs), the numpy engine at 0.18-0.32x (medians 0.27 and 0.28) (``meshphase bench
  io``, the TDMS rows and their ``numpy rows`` twins, 10 and 60 min).

``auto`` (the default) takes numba only when numba is already loaded in the process (a
Monte Carlo, a dense onset block, a warm-up): loading numba and the kernel took 0.4-1.4 s
(the bench's warm-up), the numba engine saved 0.06-0.2 s per GB read, so loading it for
a read alone would not pay. Non-native byte order, bool data and non-float output take
the numpy engine.
"""

from __future__ import annotations

import importlib.util
import os
import sys
import time

import numpy as np

from ..runtime.numba_cache import import_kernels

__all__ = ["ENGINES", "HAVE_NUMBA", "shared_rows", "row_columns", "read_rows", "rows_engine", "warmup"]

#: engines of :func:`read_rows`'s transposing copy
ENGINES = ("auto", "numba", "numpy")
#: numba is optional (extras "fast" and "test"); looked for here, imported on first use
HAVE_NUMBA = importlib.util.find_spec("numba") is not None


def rows_engine(engine: str = "auto") -> str:
    """The engine :func:`read_rows` takes for ``engine``: ``"numba"`` or ``"numpy"``.

    ``"auto"`` is numba when numba is installed and already loaded in this process (its
    start-up paid by someone else), else numpy; ``"numba"`` without numba is a ValueError.
    """
    if not isinstance(engine, str) or engine not in ENGINES:
        raise ValueError(f"engine must be one of {list(ENGINES)}, got {engine!r}")
    if engine == "numba" and not HAVE_NUMBA:
        raise ValueError("engine='numba' requested but numba is not importable (not installed)")
    if engine == "auto":
        return "numba" if HAVE_NUMBA and "numba" in sys.modules else "numpy"
    return engine


def _kernels():
    """The numba kernel module, imported on first use with the per-user cache set
    (ImportError, naming the cause, when numba cannot be imported after all)."""
    return import_kernels("meshphase.io._tdms_rows_numba")


def warmup() -> dict:
    """Load numba and the rows kernel (compiled once into the per-user cache) for float64
    rows into float64 output, so that the next :func:`read_rows` on ``"auto"`` takes it.

    Returns
    -------
    dict
        ``engine`` ("numba", or "numpy" when numba is not importable: nothing to load) and
        ``seconds`` [s] the import and compilation (or cache load) took.
    """
    t = time.perf_counter()
    if not HAVE_NUMBA:
        return {"engine": "numpy", "seconds": 0.0}
    rows = np.arange(6.0).reshape(1, 3, 2)
    out = np.empty((2, 3))
    _kernels().rows_to_channels(rows, np.array([1, 0], dtype=np.int64), out, 0)
    if not np.array_equal(out, rows[0].T[::-1]):
        raise RuntimeError("the numba rows kernel gave wrong samples")
    return {"engine": "numba", "seconds": time.perf_counter() - t}


def shared_rows(runs_per_channel: list) -> bool:
    """True when :func:`read_rows` can read these channels together: their runs are the same
    interleaved rows (equal boundaries, strides and type, one chunk per segment) and every
    channel lies at a fixed column of them (see :func:`row_columns`)."""
    return row_columns(runs_per_channel) is not None


def row_columns(runs_per_channel: list) -> tuple | None:
    """Byte offset of each channel's column in the shared interleaved rows, counted from the
    leftmost channel read (any order, gaps allowed, each a multiple of the item size), or
    None when the channels' runs are not such rows (:func:`shared_rows`)."""
    first = runs_per_channel[0] if runs_per_channel else None
    if not first:
        return None
    item = first[0].dtype.itemsize
    shape = [(r.start, r.n_seg, r.n_chunks, r.n_values, r.seg_stride, r.value_stride, r.dtype) for r in first]
    if any(r.n_chunks != 1 or r.value_stride <= item or r.value_stride % item for r in first):
        return None
    for runs in runs_per_channel:
        if [(r.start, r.n_seg, r.n_chunks, r.n_values, r.seg_stride, r.value_stride, r.dtype)
                for r in runs] != shape:
            return None
    base = [min(runs[k].offset for runs in runs_per_channel) for k in range(len(first))]
    cols = []
    for runs in runs_per_channel:
        col = runs[0].offset - base[0]
        if any(r.offset - b != col for r, b in zip(runs, base)):
            return None
        cols.append(col)
    if max(cols) + item > first[0].value_stride or any(c % item for c in cols):
        return None
    return tuple(cols)


#: bytes of interleaved rows taken at a time (about the CPU's L2 cache)
_ROW_BLOCK = 1 << 19
#: segments read by one ``os.preadv`` at most (two buffers each; IOV_MAX is 1024 on Linux)
_PREADV_SEGMENTS = 500


def read_rows(buf, runs_per_channel: list, starts: np.ndarray, i0: int, i1: int, out: np.ndarray,
              engine: str = "auto") -> bool:
    """Samples [i0, i1) of channels that are columns of shared interleaved rows
    (:func:`shared_rows`) into ``out`` (n_channels, i1 - i0).

    On the numba engine (:func:`rows_engine`; native byte order, numeric rows, floating-point
    ``out``), one compiled pass per run of segments copies the samples from ``buf`` (the
    memory map) into ``out`` and tests each for finiteness. On the numpy engine, a block of
    whole segments at a time (about ``_ROW_BLOCK`` bytes), the bytes from the
    leftmost channel's value to the rightmost one's in the last row of each segment land
    side by side in an aligned buffer, and one numpy assignment transposes the block into
    ``out`` (one strided copy per channel when the columns are not side by side in order);
    no Python loop runs per segment. When ``buf`` is a :class:`~meshphase.io.tdms_index.FileMap` and ``os.preadv``
    exists, one ``os.preadv`` per block reads the segments' rows into the buffer and their
    lead-ins into a scratch buffer (the kernel copies from the page cache: no page faults
    on the map, which cost most where segments are about a page apart); else the rows are
    copied from ``buf``. The samples just written are summed while they are in the cache.
    Both engines give the same samples bit for bit.

    Parameters
    ----------
    buf : FileMap, mmap or bytes
        The file's bytes.
    runs_per_channel : list of list of Run
        Each channel's runs (:attr:`meshphase.io.tdms_index.Index.runs`).
    starts : ndarray of int64
        First sample of each run [-].
    i0, i1 : int
        Samples read [-].
    out : ndarray, shape (n_channels, i1 - i0)
        Channel-major output (its dtype: the samples are cast as numpy casts).
    engine : {"auto", "numba", "numpy"}
        See :func:`rows_engine`.

    Returns
    -------
    bool
        True when every sample copied is shown finite (``out`` is floating point and, on
        the numpy engine, the sum of every block is finite: a NaN or inf propagates into
        its sum; on the numba engine, every sample tested), so the caller can skip its own
        scan for NaN/inf; False when not shown (a non-finite sample, or a sum that
        overflowed).

    Raises
    ------
    ValueError
        The runs are not shared rows, ``out`` has the wrong shape, ``engine`` is unknown
        (or numba and numba is missing), or the file ends before the rows (a strided view
        or ``os.preadv`` past its end; a TypeError from numpy on the numpy engine's map
        path).
    """
    compiled = rows_engine(engine) == "numba"
    cols = row_columns(runs_per_channel)
    if cols is None:
        raise ValueError("the channels' runs are not shared interleaved rows (see shared_rows)")
    if out.shape != (len(cols), i1 - i0):
        raise ValueError(f"out has shape {out.shape}, expected {(len(cols), i1 - i0)}")
    left = runs_per_channel[cols.index(0)]            # the leftmost column's runs
    finite = out.dtype.kind == "f"
    fd = getattr(buf, "fd", -1) if hasattr(os, "preadv") else -1
    kern = None
    if compiled and finite and left[0].dtype.isnative and left[0].dtype.kind in "iuf":
        kern = _kernels().rows_to_channels
    k = max(0, int(np.searchsorted(starts, i0, side="right")) - 1)
    with np.errstate(over="ignore", invalid="ignore"):
        while k < len(left) and left[k].start < i1:
            q = left[k]
            k += 1
            a, b = max(i0, q.start), min(i1, q.stop)
            if b <= a:
                continue
            if kern is not None:
                shown = _compiled_run(kern, buf, q, cols, a, b, out[:, a - i0:b - i0])
                finite = finite and shown
            else:
                finite = _RowBlocks(buf, fd, q, cols, a, b).copy(out[:, a - i0:b - i0], finite)
    return bool(finite)


def _compiled_run(kern, buf, q, cols: tuple, a: int, b: int, dst: np.ndarray) -> bool:
    """Samples [a, b) of the channels at byte columns ``cols`` of the rows of run ``q`` (the
    leftmost channel's) into ``dst`` by the numba kernel, straight from ``buf``; True when
    every sample written is finite."""
    item, p = q.dtype.itemsize, q.n_values
    s0, s_end = (a - q.start) // p, (b - q.start - 1) // p + 1
    width = max(cols) // item + 1
    offset = q.offset + s0 * q.seg_stride
    end = offset + (s_end - s0 - 1) * q.seg_stride + (p - 1) * q.value_stride + width * item
    if end > len(buf):
        raise ValueError(f"the file ends inside segment rows (they need {end} bytes, it has {len(buf)})")
    src = np.ndarray((s_end - s0, p, width), dtype=q.dtype, buffer=buf, offset=offset,
                     strides=(q.seg_stride, q.value_stride, item))
    idx = np.array(cols, dtype=np.int64) // item
    return bool(kern(src, idx, dst, a - q.start - s0 * p))


class _RowBlocks:
    """Samples [a, b) of the channels at byte columns ``cols`` of the rows of run ``q`` (the
    leftmost channel's), block after block of whole segments through an aligned buffer."""

    def __init__(self, buf, fd: int, q, cols: tuple, a: int, b: int):
        self.buf, self.fd, self.q, self.cols, self.a, self.b = buf, fd, q, cols, a, b
        item, p, row = q.dtype.itemsize, q.n_values, q.value_stride
        self.together = cols == tuple(range(0, len(cols) * item, item))   # side by side, in order
        self.full = p * row                                  # a segment's rows in the buffer
        self.used = (p - 1) * row + max(cols) + item         # ... of which the file holds these
        self.s0, self.s_end = (a - q.start) // p, (b - q.start - 1) // p + 1
        per = max(1, _ROW_BLOCK // self.full)
        if fd >= 0:
            per = min(per, _PREADV_SEGMENTS)
        self.per = min(per, self.s_end - self.s0)
        self.tmp = np.empty(self.per * self.full, dtype=np.uint8)
        self.iov = None
        if fd >= 0:
            mv = memoryview(self.tmp)
            gap = bytearray(max(0, q.seg_stride - self.used))   # the next lead-in (and metadata)
            self.iov = [x for s in range(self.per) for x in (mv[s * self.full:s * self.full + self.used], gap)]

    def _fill(self, g: int, nk: int) -> None:
        """Segments [g, g + nk) of the run into the buffer."""
        q = self.q
        if self.iov is not None:
            want = (nk - 1) * q.seg_stride + self.used
            got = os.preadv(self.fd, self.iov[:2 * nk - 1], q.offset + g * q.seg_stride)
            if got != want:
                raise ValueError(f"the file ends inside segment rows at byte {q.offset + g * q.seg_stride + got}")
            return
        src = np.ndarray((nk, self.used), dtype=np.uint8, buffer=self.buf, offset=q.offset + g * q.seg_stride,
                         strides=(q.seg_stride, 1))
        self.tmp[:nk * self.full].reshape(nk, self.full)[:, :self.used] = src

    def copy(self, out: np.ndarray, finite: bool) -> bool:
        """Transpose the samples into ``out`` (nch, b - a); ``finite`` and-ed with every
        block's sums being finite."""
        q, a, b, p = self.q, self.a, self.b, self.q.n_values
        for g in range(self.s0, self.s_end, self.per):
            nk = min(self.per, self.s_end - g)
            self._fill(g, nk)
            lo = q.start + g * p                             # first sample in the buffer
            c0, c1 = max(a, lo), min(b, lo + nk * p)
            dst = out[:, c0 - a:c1 - a]
            if self.together:                                # one transposing assignment
                rows = np.ndarray((nk * p, len(self.cols)), dtype=q.dtype, buffer=self.tmp,
                                  strides=(q.value_stride, q.dtype.itemsize))
                dst[...] = rows[c0 - lo:c1 - lo].T
            else:                                            # one strided column per channel
                for j, col in enumerate(self.cols):
                    dst[j] = np.ndarray((nk * p,), dtype=q.dtype, buffer=self.tmp, offset=col,
                                        strides=(q.value_stride,))[c0 - lo:c1 - lo]
            if finite:
                finite = bool(np.isfinite(np.add.reduce(dst, axis=1)).all())
        return finite
