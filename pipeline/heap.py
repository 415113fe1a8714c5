"""Keep the C heap from growing with the length of a streamed run (glibc only).

Streaming a recording allocates and frees the same few block-sized arrays (a few hundred kB
to tens of MB) thousands of times. glibc serves an allocation above ``M_MMAP_THRESHOLD``
with its own ``mmap`` and returns it to the system when freed, but by default it *raises*
that threshold to the size of every mmapped block freed (up to 32 MiB on 64-bit), so after
the first blocks the arrays come from the heap instead, where freed space is fragmented
and the peak resident memory creeps up with the number of blocks: ``meshphase process`` on
3 h of 8 channels peaked at 724 MB against 542 MB for 10 min.

Two ways out were measured (``meshphase process``, 8 channels, 5120 Hz, idle 2-core machine):

- a low fixed threshold (128 KiB, glibc's starting value; the choice until issue 13): flat
  peaks (``meshphase bench processing``: 389 / 401 / 403 MB at 10 min / 1 h / 3 h), but every
  block array is a fresh mapping whose pages fault in one by one: 1 h took 43 s in the
  bench, 3 h 130 s in one in-process run;
- the heap (threshold fixed at its 32 MiB ceiling) and a daemon thread that hands the heap's
  free pages back to the system every :data:`TRIM_PERIOD` (``malloc_trim(0)``, which since
  glibc 2.8 also releases free pages inside the heap): 417 / 424 / 449 MB, 1 h in 39 s and
  3 h in 86 s (the bench; 89 s in-process). A period of 0.5 s was faster still (3 h: 82 s)
  but let the peak creep (454 MB at 1 h, 512 MB at 3 h). This is what
  :func:`limit_heap_growth` does now.

A value the user set in the documented environment variable ``MALLOC_MMAP_THRESHOLD_`` is
left alone (the trimming still runs). Elsewhere than glibc this does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import sys
import threading

__all__ = ["limit_heap_growth", "heap_trimming", "MMAP_THRESHOLD", "TRIM_PERIOD"]

#: Allocations at or above this size get their own mmap [bytes]: the ceiling glibc's own
#: adaptation would reach, fixed so that it does not move during a run.
MMAP_THRESHOLD = 32 * 2**20
#: Seconds between two hand-backs of the heap's free pages (``malloc_trim(0)``) [s].
TRIM_PERIOD = 0.1
_M_MMAP_THRESHOLD = -3          # <malloc.h>
_done: bool | None = None
_trimmer: threading.Thread | None = None


def _libc():
    """glibc's CDLL, or None (not Linux, no glibc, no mallopt / malloc_trim)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        libc.mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
        libc.mallopt.restype = ctypes.c_int
        libc.malloc_trim.argtypes = (ctypes.c_size_t,)
        libc.malloc_trim.restype = ctypes.c_int
    except (OSError, AttributeError):       # musl and others: no mallopt
        return None
    return libc


def _trim_forever(trim, period: float) -> None:
    # a daemon thread: it ends with the process; malloc_trim takes the arenas' own locks
    event = threading.Event()
    while not event.wait(period):
        trim(0)


def heap_trimming() -> bool:
    """True when this process runs the trimming thread (:func:`limit_heap_growth`)."""
    return _trimmer is not None and _trimmer.is_alive()


def limit_heap_growth(threshold: int = MMAP_THRESHOLD) -> bool:
    """Fix glibc's mmap threshold at ``threshold`` bytes for this process and start the
    thread that returns the heap's free pages every :data:`TRIM_PERIOD` s (once).

    Parameters
    ----------
    threshold : int
        [bytes], 4096 to 32 MiB.

    Returns
    -------
    bool
        True when the threshold is now fixed (by this call, an earlier one or the
        environment) and the heap trimmed; False where there is no glibc.

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
    libc = _libc()
    if libc is None:
        _done = False
        return False
    ok = True
    if "MALLOC_MMAP_THRESHOLD_" not in os.environ:
        ok = bool(libc.mallopt(_M_MMAP_THRESHOLD, int(threshold)))
    global _trimmer
    _trimmer = threading.Thread(target=_trim_forever, args=(libc.malloc_trim, TRIM_PERIOD),
                                name="meshphase-heap-trim", daemon=True)
    _trimmer.start()
    _done = ok
    return _done
