"""Worker threads of one run: independent fits of the phasing stage side by side.

The angle model of a long recording is fitted in windows (:mod:`meshphase.angle_windows`) and
the planet labels of each gauge are aligned by fitting every cyclic relabelling
(:func:`meshphase.angles.label_shift_costs`): fits that share nothing. Their work is numpy
array arithmetic and LAPACK least squares, which release the GIL, so threads run them on
separate cores. Each fit is deterministic and runs whole on one thread, so the results are
bit-identical to the serial ones whatever the thread count.

While threads run, the BLAS library's own thread pool is held to one thread
(threadpoolctl): two fits each asking OpenBLAS for every core would oversubscribe them.

Thread count: :func:`run_threads` (``MESHPHASE_THREADS`` in the environment, else the cores
this process may use, at most :data:`MAX_THREADS`). A campaign already runs one recording
per worker process and sets 1 there (:func:`threads_limited`).
"""

from __future__ import annotations

import os
from contextlib import contextmanager
from typing import Callable, Iterable, TypeVar

__all__ = ["run_threads", "threads_limited", "thread_map", "MAX_THREADS", "ENV_THREADS"]

#: Default ceiling on worker threads [-]: a window fit holds about 40 MB (angle_windows).
MAX_THREADS = 4
#: Environment variable that sets the thread count (a positive integer).
ENV_THREADS = "MESHPHASE_THREADS"

_limit: int | None = None

T = TypeVar("T")
R = TypeVar("R")


def _available_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):          # not on Linux
        return os.cpu_count() or 1


def run_threads() -> int:
    """Worker threads a run may use [-].

    Returns
    -------
    int
        The limit set by :func:`threads_limited` if one is active, else ``MESHPHASE_THREADS``,
        else the cores this process may run on, at most :data:`MAX_THREADS`.

    Raises
    ------
    ValueError
        ``MESHPHASE_THREADS`` set to anything but a positive integer.
    """
    if _limit is not None:
        return _limit
    env = os.environ.get(ENV_THREADS, "").strip()
    if env:
        try:
            n = int(env)
        except ValueError:
            n = 0
        if n < 1:
            raise ValueError(f"{ENV_THREADS} must be a positive integer, got {env!r}")
        return n
    return max(1, min(MAX_THREADS, _available_cores()))


@contextmanager
def threads_limited(n: int):
    """Hold :func:`run_threads` at ``n`` inside the block (process-wide).

    Raises
    ------
    ValueError
        ``n`` not a positive integer.
    """
    global _limit
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ValueError(f"threads must be a positive integer, got {n!r}")
    before = _limit
    _limit = n
    try:
        yield
    finally:
        _limit = before


def thread_map(fn: Callable[[T], R], items: Iterable[T], *, threads: int | None = None,
               progress: Callable[[int, int], None] | None = None) -> list[R]:
    """``[fn(x) for x in items]``, on up to ``threads`` threads (default :func:`run_threads`).

    Parameters
    ----------
    fn : callable
        Applied to each item; must not depend on the order the items run in.
    items : iterable
    threads : int, optional
        Thread count [-]; 1 runs in the calling thread.
    progress : callable, optional
        ``progress(done, total)`` in the calling thread, as results arrive in order.

    Returns
    -------
    list
        The results in the order of ``items``. The first exception raised by ``fn`` (in
        item order) is raised here.
    """
    items = list(items)
    n = run_threads() if threads is None else threads
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ValueError(f"threads must be a positive integer, got {n!r}")
    total = len(items)
    out = []
    if n == 1 or total <= 1:
        for x in items:
            out.append(fn(x))
            if progress is not None:
                progress(len(out), total)
        return out
    from concurrent.futures import ThreadPoolExecutor

    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"), \
            ThreadPoolExecutor(max_workers=min(n, total), thread_name_prefix="meshphase") as ex:
        for r in ex.map(fn, items):
            out.append(r)
            if progress is not None:
                progress(len(out), total)
    return out
