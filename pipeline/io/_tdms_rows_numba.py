"""The numba build of the interleaved TDMS rows' transposing copy (:mod:`meshphase.io.tdms_rows`).

Imported only when :func:`meshphase.io.tdms_rows.read_rows` takes its numba engine (numba
already loaded in the process, or asked for), so reading a TDMS file does not load numba and
LLVM by itself. Compiled functions are cached (``cache=True``) in the per-user directory
:func:`meshphase.runtime.numba_cache.numba_cache_dir` names unless ``NUMBA_CACHE_DIR`` is set.
``fastmath`` stays off: it would let the compiler assume no NaN or inf, and the finiteness
test must see them.
"""

from __future__ import annotations

import math

import numba as _numba


@_numba.njit(cache=True, nogil=True)
def rows_to_channels(src, cols, dst, j0):  # pragma: no cover - compiled
    """Transpose interleaved rows into channel-major output in one pass, testing every
    sample written for finiteness on the way.

    Parameters
    ----------
    src : ndarray, shape (n_seg, n_values, width)
        The rows of whole segments (any strides, native byte order): ``src[s, i, c]`` is
        item ``c`` of row ``i`` of segment ``s``.
    cols : ndarray of int64, shape (n_channels,)
        Item column of each output channel in a row (any order, gaps allowed, each below
        ``width``).
    dst : ndarray of float, shape (n_channels, n)
        Output; row ``j`` receives column ``cols[j]`` of the rows from row ``j0`` of the
        first segment on, ``n`` rows in all (cast to ``dst``'s type as numpy casts).
    j0 : int
        First row read in the first segment [-].

    Returns
    -------
    bool
        True when every value written (as ``dst`` holds it) is finite.
    """
    in_order = True          # side by side in order: no column look-up (LLVM takes the
    for j in range(cols.size):   # test out of the loop; measured faster than looking up)
        in_order = in_order and cols[j] == j
    n_seg, p = src.shape[0], src.shape[1]
    nc, n = dst.shape[0], dst.shape[1]
    ok = True
    k = 0
    for s in range(n_seg):
        i0 = j0 if s == 0 else 0
        i1 = min(p, i0 + n - k)
        for i in range(i0, i1):
            for j in range(nc):
                w = dst.dtype.type(src[s, i, j if in_order else cols[j]])
                dst[j, k] = w
                ok &= math.isfinite(w)
            k += 1
        if k >= n:
            break
    return ok
