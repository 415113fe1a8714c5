"""Keep the C heap from growing with the length of a streamed run (glibc only).

Streaming a recording allocates and frees the same few block-sized arrays (a few hundred kB
to tens of MB) thousands of times. glibc serves an allocation above ``M_MMAP_THRESHOLD``
with its own ``mmap`` and returns it to the system when freed, but by default it *raises*
that threshold to the size of every mmapped block freed (up to 32 MiB on 64-bit), so after
the first blocks the arrays come from the heap instead, where freed space is fragmented
and the peak resident memory creeps up with the number of blocks: ``meshphase process`` on
3 h of 8 channels peaked at 724 MB against 542 MB for 10 min. Setting the threshold
explicitly (``mallopt(M_MMAP_THRESHOLD, 128 KiB)``, glibc's own starting value) turns that
adaptation off, and the same 3-h run peaked at 464 MB (`meshphase bench io` measures it).

Same effect as the documented environment variable ``MALLOC_MMAP_THRESHOLD_=131072``; a
value the user set there is left alone. Elsewhere than glibc this does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import sys

__all__ = ["limit_heap_growth", "MMAP_THRESHOLD"]

#: Allocations at or above this size get their own mmap [bytes] (glibc's default start).
MMAP_THRESHOLD = 128 * 1024
_M_MMAP_THRESHOLD = -3          # <malloc.h>
_done: bool | None = None


def limit_heap_growth(threshold: int = MMAP_THRESHOLD) -> bool:
    """Fix glibc's mmap threshold at ``threshold`` bytes for this process (once).

    Parameters
    ----------
    threshold : int
        [bytes], 4096 to 32 MiB.

    Returns
    -------
    bool
        True when the threshold is now fixed (by this call, an earlier one or the
        environment); False where there is no glibc.

    Raises
    ------
    ValueError
        ``threshold`` outside [4096, 32 MiB].
    """
    global _done
    if isinstance(threshold, bool) or not isinstance(threshold, int) \
            or not 4096 <= threshold <= 32 * 2**20:
        raise ValueError(f"threshold must be an int in [4096, 33554432] bytes, got {threshold!r}")
    if _done is not None:
        return _done
    if "MALLOC_MMAP_THRESHOLD_" in os.environ:
        _done = True
        return True
    if not sys.platform.startswith("linux"):
        _done = False
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):       # musl and others: no mallopt
        _done = False
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    _done = bool(mallopt(_M_MMAP_THRESHOLD, int(threshold)))
    return _done
