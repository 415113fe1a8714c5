"""Worker threads of one run: the channels' conditioning chains side by side.

The streamed conditioning (:func:`meshphase.run.stream.condition_stream`) filters each block of
every channel through that channel's own chain (notch, drift, band-pass): chains that share
nothing, whose work is scipy's zero-phase filters and numpy array arithmetic, which release
the GIL, so threads run them on separate cores. Each chain runs whole on one thread per
block, so the samples are bit-identical to the serial ones whatever the thread count. While
the workers filter a block, the calling thread takes the block before through the onset
detectors (``tmap.start``, :func:`thread_pool`), which before left the second core idle
through the onsets. ``meshphase bench processing`` (its process rows carry the thread count
and the CPU time beside the wall time) against ``MESHPHASE_THREADS=1 meshphase bench
processing`` compares the two.

The angle model of a long record is fitted in windows (:mod:`meshphase.kinematics.angle_windows`), and
the windows go side by side on these threads too, as do the planet-label alignment's
relabellings after the first (:func:`meshphase.kinematics.label_shift.label_shift_costs`). Each fit's
Gauss-Newton steps are solved by Householder QR (LAPACK geqrf, which releases the GIL;
gelsy, used before, held it, as do the SVD and the small array steps that remain), so two
threads gain less than two cores.

Each streamed pass reads the recording's next block on a thread of its own while it works on
this one (:func:`read_ahead`: h5py's reads and ``os.preadv`` release the GIL): the 1-h bench
record's quality scans took 1.7-2.0 s instead of 2.2-2.6 s (``meshphase bench processing``,
the 1-h row's ``load_s``, with and without the read-ahead).

A run holds the BLAS library's own thread pool to one thread (:func:`blas_single_thread`,
threadpoolctl). The least squares here are tall and narrow (thousands of rows, tens of
columns), where OpenBLAS's threads gain little on an idle machine and lose badly on a busy
one: with the other core taken (a campaign's other worker, a second job) they spin against
it, and a 10-min run's phasing took several times as long in our runs.

Thread count: :func:`run_threads` (``MESHPHASE_THREADS`` in the environment, else the cores
this process may use, at most :data:`MAX_THREADS`). A campaign on a local cluster gives each
recording its share, cores // workers (:func:`threads_limited`).
"""

from __future__ import annotations

import os
import sys
from contextlib import contextmanager

__all__ = ["run_threads", "threads_limited", "thread_pool", "blas_single_thread",
           "hold_blas_single_thread", "read_ahead",
           "MAX_THREADS", "ENV_THREADS"]

#: Default ceiling on worker threads [-] (one channel's chain each, a few MB per block).
MAX_THREADS = 4
#: Environment variable that sets the thread count (a positive integer).
ENV_THREADS = "MESHPHASE_THREADS"

_limit: int | None = None

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


#: (len(sys.modules) when made, threadpoolctl.ThreadpoolController) of this process, or None
_blas_controller: tuple | None = None


def _controller():
    """threadpoolctl's view of the loaded thread-pool libraries, kept while no module was
    imported since it was made (only an import loads a new BLAS). Making one looks through
    every loaded shared library, which :func:`threadpoolctl.threadpool_limits` does at every
    call."""
    global _blas_controller
    n = len(sys.modules)
    if _blas_controller is None or _blas_controller[0] != n:
        from threadpoolctl import ThreadpoolController

        _blas_controller = (n, ThreadpoolController())
    return _blas_controller[1]


@contextmanager
def blas_single_thread():
    """Hold every loaded BLAS library (OpenBLAS, MKL, BLIS) to one thread inside the block
    (module notes); process-wide, restored on exit."""
    with _controller().limit(limits=1, user_api="blas"):
        yield


def hold_blas_single_thread() -> None:
    """Hold every loaded BLAS library to one thread from now on, process-wide, not restored.

    A campaign's fork server (:mod:`meshphase.campaign.fork_ready`): its workers inherit the limit.
    OpenBLAS ends its thread pool at a fork and starts it again on the child's first call,
    so each worker's first recording started (and spun) two BLAS threads; with the limit
    there is no pool to start. Each run holds BLAS to one thread anyway (module notes).
    """
    _controller().limit(limits=1, user_api="blas")


@contextmanager
def thread_pool(threads: int | None = None, *, max_items: int | None = None):
    """A pool of worker threads for many calls (one block of a stream after another):
    yields ``tmap(fn, items, progress=None) -> list``, ``[fn(x) for x in items]`` on the
    pool's threads, in the order of ``items``; ``progress(done, total)`` is called in the
    calling thread as results arrive, and the first exception raised by ``fn`` (in item
    order) is raised in the caller. ``tmap.start(fn, items)`` starts the same calls and
    returns at once a ``wait() -> list`` that waits for them (the caller works meanwhile);
    with one thread the calls are made by ``start`` itself.

    Parameters
    ----------
    threads : int, optional
        Thread count [-] (default :func:`run_threads`); 1 runs every call in the caller.
    max_items : int, optional
        The most items one call will get: no more threads than that are started.

    Raises
    ------
    ValueError
        ``threads`` not a positive integer.
    """
    n = run_threads() if threads is None else threads
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ValueError(f"threads must be a positive integer, got {n!r}")
    if max_items is not None:
        n = max(1, min(n, int(max_items)))

    def serial(fn, items, progress=None):
        items = list(items)
        out = []
        for x in items:
            out.append(fn(x))
            if progress is not None:
                progress(len(out), len(items))
        return out

    def serial_start(fn, items):
        out = serial(fn, items)
        return lambda: out

    if n == 1:
        serial.start = serial_start
        with blas_single_thread():
            yield serial
        return
    from concurrent.futures import ThreadPoolExecutor

    with blas_single_thread(), ThreadPoolExecutor(max_workers=n, thread_name_prefix="meshphase") as ex:

        def tmap(fn, items, progress=None):
            items = list(items)
            if len(items) <= 1:
                return serial(fn, items, progress)
            out = []
            for r in ex.map(fn, items):
                out.append(r)
                if progress is not None:
                    progress(len(out), len(items))
            return out

        def start(fn, items):
            items = list(items)
            futures = [ex.submit(fn, x) for x in items]
            return lambda: [f.result() for f in futures]

        tmap.start = start
        yield tmap


def read_ahead(make_items, *, depth: int = 1):
    """The items of the iterator ``make_items()`` returns, produced on a thread of their own
    up to ``depth`` ahead of the caller: a file's next block is read while the caller works
    on this one (h5py's reads and ``os.preadv`` release the GIL). The iterator is created,
    run and closed on that thread; its exceptions are raised here, in order, and leaving the
    loop early (a break, an exception) stops it and waits for it to close (its file with it).
    With :func:`run_threads` at 1 the items are produced here, one by one.

    Parameters
    ----------
    make_items : callable
        Returns the iterator (called on the reading thread).
    depth : int
        Items read ahead at most [-] (each a block in memory).

    Returns
    -------
    generator
        The items; closing it (``contextlib.closing``) stops the reader at once.

    Raises
    ------
    ValueError
        ``depth`` not a positive integer.
    """
    if isinstance(depth, bool) or not isinstance(depth, int) or depth < 1:
        raise ValueError(f"depth must be a positive integer, got {depth!r}")
    if run_threads() == 1:
        return _read_here(make_items)
    return _read_ahead(make_items, depth)


def _read_here(make_items):
    """:func:`read_ahead` on one thread: the items made here, one by one."""
    yield from make_items()


def _read_ahead(make_items, depth: int):
    """:func:`read_ahead`'s generator on the reading thread (``depth`` checked)."""
    import queue
    import threading

    q: queue.Queue = queue.Queue(maxsize=depth)
    stop = threading.Event()

    def put(msg) -> bool:
        while not stop.is_set():
            try:
                q.put(msg, timeout=0.05)
                return True
            except queue.Full:
                continue
        return False

    def produce():
        try:
            it = make_items()
            try:
                for item in it:
                    if not put(("item", item)):
                        return
            finally:
                close = getattr(it, "close", None)
                if close is not None:
                    close()
        except BaseException as exc:          # handed to the caller, raised there
            put(("error", exc))
            return
        put(("done", None))

    t = threading.Thread(target=produce, name="meshphase-read", daemon=True)
    t.start()
    try:
        while True:
            kind, value = q.get()
            if kind == "item":
                yield value
            elif kind == "error":
                raise value
            else:
                return
    finally:
        stop.set()
        t.join()
