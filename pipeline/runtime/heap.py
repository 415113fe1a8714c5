"""Keep the C heap from growing with the length of a streamed run (glibc only).

Streaming a recording allocates and frees the same few block-sized arrays (a few hundred kB
to tens of MB) thousands of times. glibc serves an allocation above ``M_MMAP_THRESHOLD``
with its own ``mmap`` and returns it to the system when freed, but by default it *raises*
that threshold to the size of every mmapped block freed (up to 32 MiB on 64-bit), so after
the first blocks the arrays come from the heap instead, where freed space is fragmented
and the peak resident memory creeps up with the number of blocks: ``meshphase process`` on
3 h of 8 channels peaked at 724 MB against 542 MB for 10 min.

Two ways out were measured (``meshphase process``, 8 channels, 5120 Hz, idle 2-core machine):

- a low fixed threshold (128 KiB, glibc's starting value): flat
  peaks (``meshphase bench processing``: 389 / 401 / 403 MB at 10 min / 1 h / 3 h), but every
  block array is a fresh mapping whose pages fault in one by one: 1 h took 43 s in the
  bench, 3 h 130 s in one in-process run;
- the heap (threshold fixed at its 32 MiB ceiling) and a daemon thread that hands the heap's
  free pages back to the system every :data:`TRIM_PERIOD` (``malloc_trim(0)``, which since
  glibc 2.8 also releases free pages inside the heap): 417 / 424 / 449 MB, 1 h in 39 s and
  3 h in 86 s (the bench; 89 s in-process). A period of 0.5 s was faster still (3 h: 82 s)
  but let the peak creep (454 MB at 1 h, 512 MB at 3 h).

The second is what :func:`limit_heap_growth` does, with two changes. Fixing the mmap threshold also stops glibc from raising the trim threshold
with it, which stayed at 128 KiB: every free at the top of the heap handed pages back that
the next allocation faulted in again (the phasing stage of a 1-h run: 8.5-9.9 s against
6.1-6.5 s). The trim threshold is now fixed at twice the mmap threshold, as glibc's own
adaptation sets it. And a hand-back at every tick returned the pages of the block arrays
just freed, which the next block faulted in anew: the heap is now trimmed when the resident
set has grown by :data:`TRIM_SLACK` (256 MiB) since the last trim. ``meshphase bench
processing`` (process rows, two runs on the idle machine): 10 min 6.8-7.8 s / 510-543 MB,
1 h 16.7-18.3 s / 561-575 MB, 3 h 43.8-44.8 s / 591-625 MB, 12 h (one run) 158.5 s / 688
MB (the same day with the old policy: 1 h 22.9-25.1 s, 474 MB): faster, at a peak that
grows with length, under the 1 GB budget.
In-process runs of 1 h, old policy with the trim threshold fixed / 64 MiB slack / 256 MiB
slack: 21.6-25.5 s, 473-480 MB / 20.2-21.6 s, 472-488 MB / 17.0-18.3 s, 545-569 MB; no
trimming at all: 16.8-19.8 s, 529-696 MB.

Values the user set in the documented environment variables ``MALLOC_MMAP_THRESHOLD_`` and
``MALLOC_TRIM_THRESHOLD_`` are left alone (the trimming still runs). A campaign's local
workers do not get distributed's own ``MALLOC_TRIM_THRESHOLD_`` (:mod:`meshphase.campaign.cluster`),
which would pass for the user's here, and a task on any Dask worker whose value is
distributed's own fixes the trim threshold all the same (``trim_env``): left at 64 KiB with
the mmap threshold fixed, every recording faulted its block arrays in anew. Elsewhere than
glibc this does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import sys
import threading

__all__ = ["limit_heap_growth", "heap_trimming", "MMAP_THRESHOLD", "TRIM_PERIOD", "TRIM_SLACK"]

#: Allocations at or above this size get their own mmap [bytes]: the ceiling glibc's own
#: adaptation would reach, fixed so that it does not move during a run.
MMAP_THRESHOLD = 32 * 2**20
#: Seconds between two looks at the resident set [s]; the heap's free pages are handed back
#: (``malloc_trim(0)``) when it has grown by :data:`TRIM_SLACK` since the last hand-back.
TRIM_PERIOD = 0.1
#: Growth of the resident set since the last hand-back that triggers the next [bytes].
TRIM_SLACK = 256 * 2**20
_M_MMAP_THRESHOLD = -3          # <malloc.h>
_M_TRIM_THRESHOLD = -1
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


def _rss_bytes() -> int | None:
    """This process's resident set [bytes] (/proc/self/statm), None where unreadable."""
    try:
        with open("/proc/self/statm", "rb") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return None


def _trim_forever(trim, period: float, slack: int) -> None:
    # a daemon thread: it ends with the process; malloc_trim takes the arenas' own locks.
    # The heap is trimmed when the resident set has grown by ``slack`` since the last trim
    # (or fell below it: the new floor), not at every tick: a trim hands back the pages of
    # the block arrays just freed, which the next block then faults in anew
    event = threading.Event()
    floor = None
    while not event.wait(period):
        floor = _trim_step(trim, floor, slack)


def _trim_step(trim, floor: int | None, slack: int) -> int | None:
    """One look at the resident set: ``trim(0)`` when it is unknown, or more than ``slack``
    [bytes] above ``floor`` (the resident set after the last trim, None before the first);
    returns the new floor."""
    rss = _rss_bytes()
    if rss is None or floor is None or rss > floor + slack:
        trim(0)
        return _rss_bytes()
    return min(floor, rss)


def heap_trimming() -> bool:
    """True when this process runs the trimming thread (:func:`limit_heap_growth`)."""
    return _trimmer is not None and _trimmer.is_alive()


def limit_heap_growth(threshold: int = MMAP_THRESHOLD, *, trim_env: bool = True) -> bool:
    """Fix glibc's mmap threshold at ``threshold`` bytes (and its trim threshold at twice
    that) for this process and start the thread that returns the heap's free pages when the
    resident set has grown by :data:`TRIM_SLACK` (looked at every :data:`TRIM_PERIOD` s)
    (once).

    Parameters
    ----------
    threshold : int
        [bytes], 4096 to 32 MiB.
    trim_env : bool
        Leave the trim threshold alone when ``MALLOC_TRIM_THRESHOLD_`` is in the environment
        (the user's choice). False: fix it all the same (a Dask worker's environment holds
        distributed's own value there, :func:`meshphase.campaign.cluster.trim_env_is_distributed`).

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
    if not trim_env or "MALLOC_TRIM_THRESHOLD_" not in os.environ:
        # fixing the mmap threshold also stops glibc from raising the trim threshold with
        # it (to twice the mmap threshold): left at 128 KiB, every free at the heap's top
        # handed pages back that the next allocation faulted in again
        ok = bool(libc.mallopt(_M_TRIM_THRESHOLD, 2 * int(threshold))) and ok
    global _trimmer
    _trimmer = threading.Thread(target=_trim_forever, args=(libc.malloc_trim, TRIM_PERIOD, TRIM_SLACK),
                                name="meshphase-heap-trim", daemon=True)
    _trimmer.start()
    _done = ok
    return _done
