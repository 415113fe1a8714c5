"""meshphase.runtime.threads: worker threads of one run (thread count, order, errors, progress).

``thread_map`` below is one call of a :func:`thread_pool`, as the streamed conditioning makes
per block."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from meshphase.runtime import threads
from meshphase.runtime.threads import ENV_THREADS, MAX_THREADS, run_threads, thread_pool, threads_limited


def thread_map(fn, items, *, threads, progress=None):
    items = list(items)
    with thread_pool(threads, max_items=len(items)) as tmap:
        return tmap(fn, items, progress=progress)


def test_default_is_the_cores_up_to_the_ceiling(monkeypatch):
    monkeypatch.delenv(ENV_THREADS, raising=False)
    n = run_threads()
    assert 1 <= n <= MAX_THREADS
    monkeypatch.setattr(threads, "_available_cores", lambda: 64)
    assert run_threads() == MAX_THREADS
    monkeypatch.setattr(threads, "_available_cores", lambda: 1)
    assert run_threads() == 1


def test_environment_sets_the_count_and_bad_values_are_named(monkeypatch):
    monkeypatch.setenv(ENV_THREADS, "3")
    assert run_threads() == 3
    for bad in ("0", "-2", "two", "1.5"):
        monkeypatch.setenv(ENV_THREADS, bad)
        with pytest.raises(ValueError, match=ENV_THREADS):
            run_threads()


def test_limit_holds_inside_the_block_only(monkeypatch):
    monkeypatch.setenv(ENV_THREADS, "3")
    with threads_limited(1):
        assert run_threads() == 1
        with threads_limited(2):
            assert run_threads() == 2
        assert run_threads() == 1
    assert run_threads() == 3
    for bad in (0, -1, 1.5, True, "2", None):
        with pytest.raises(ValueError):
            with threads_limited(bad):
                pass


def test_empty_input_gives_an_empty_list():
    calls = []
    assert thread_map(lambda x: x, [], threads=2, progress=lambda *a: calls.append(a)) == []
    assert calls == []


def test_bad_thread_count_is_refused():
    for bad in (0, -1, 2.0, True):
        with pytest.raises(ValueError, match="positive integer"):
            thread_map(lambda x: x, [1, 2], threads=bad)


def test_results_keep_the_order_of_the_items_and_run_on_worker_threads():
    names = set()

    def fn(x):
        names.add(threading.current_thread().name)
        return np.linalg.qr(np.full((200, 20), float(x)) + np.eye(200, 20))[1][0, 0]

    items = list(range(9))
    serial = thread_map(fn, items, threads=1)
    assert names == {threading.current_thread().name}
    names.clear()
    seen = []
    par = thread_map(fn, items, threads=3, progress=lambda d, t: seen.append((d, t)))
    assert par == serial                                   # same values, same order
    assert seen == [(i, 9) for i in range(1, 10)]          # in order, in the caller
    assert all(nm.startswith("meshphase") for nm in names)


def test_the_first_failing_item_raises():
    def fn(x):
        if x in (2, 5):
            raise KeyError(x)
        return x

    with pytest.raises(KeyError, match="2"):
        thread_map(fn, range(8), threads=2)
    with pytest.raises(KeyError, match="2"):
        thread_map(fn, range(8), threads=1)


@pytest.mark.parametrize("threads", [1, 3])
def test_start_returns_at_once_and_wait_gives_the_results_in_order(threads):
    # tmap.start: the calls go on while the caller works; wait() gives them in item order,
    # raises the first failing item's exception, and an empty list starts nothing
    gate = threading.Event()
    names = set()

    def fn(x):
        names.add(threading.current_thread().name)
        if threads > 1:
            assert gate.wait(10.0)           # held until the caller has gone on
        return x * x

    with thread_pool(threads) as tmap:
        wait = tmap.start(fn, range(6))
        gate.set()                           # only reached if start did not block
        assert wait() == [x * x for x in range(6)]
        assert tmap.start(fn, [])() == []

        def bad(x):
            if x in (2, 4):
                raise KeyError(x)
            return x

        with pytest.raises(KeyError, match="2"):
            tmap.start(bad, range(6))()
    if threads > 1:
        assert all(nm.startswith("meshphase") for nm in names)
    else:
        assert names == {threading.current_thread().name}


# --------------------------------------------------------------------------- read_ahead
def _blocks(n, log, *, fail_at=None):
    """A reader's block iterator: logs its thread, each block, and its close."""
    log.append(("thread", threading.current_thread().name))
    try:
        for k in range(n):
            if k == fail_at:
                raise OSError(f"read failed at block {k}")
            log.append(("read", k))
            yield k, np.full(4, float(k))
    finally:
        log.append(("closed", None))


@pytest.mark.parametrize("n_threads", [1, 2])
def test_read_ahead_gives_every_item_in_order(n_threads):
    log = []
    with threads_limited(n_threads):
        got = [(k, x.copy()) for k, x in threads.read_ahead(lambda: _blocks(7, log), depth=2)]
    assert [k for k, _ in got] == list(range(7))
    assert all(np.array_equal(x, np.full(4, float(k))) for k, x in got)
    assert log[-1] == ("closed", None)
    reader = log[0][1]
    if n_threads == 1:
        assert reader == threading.current_thread().name        # no thread started
    else:
        assert reader == "meshphase-read"


def test_read_ahead_raises_the_readers_error_after_the_blocks_before_it():
    log = []
    got = []
    with threads_limited(2), pytest.raises(OSError, match="block 3"):
        for k, _ in threads.read_ahead(lambda: _blocks(7, log, fail_at=3)):
            got.append(k)
    assert got == [0, 1, 2]
    assert log[-1] == ("closed", None)


def test_read_ahead_stops_the_reader_when_the_caller_leaves_early():
    log = []
    before = threading.active_count()
    with threads_limited(2):
        for k, _ in threads.read_ahead(lambda: _blocks(1000, log), depth=1):
            if k == 2:
                break
    # the reader is stopped and joined when the loop is left: its iterator closed, at most
    # depth + 1 blocks read beyond the last one taken
    assert log[-1] == ("closed", None)
    assert max(k for what, k in log if what == "read") <= 2 + 2
    assert threading.active_count() == before


def test_read_ahead_empty_and_bad_input():
    with threads_limited(2):
        assert list(threads.read_ahead(lambda: iter(()))) == []
    for bad in (0, -1, 1.5, True, "2"):
        with pytest.raises(ValueError, match="depth"):
            list(threads.read_ahead(lambda: iter(()), depth=bad))
    with threads_limited(2), pytest.raises(TypeError):
        list(threads.read_ahead(lambda: 5))           # not an iterator: raised here


def test_blas_single_thread_holds_blas_to_one_and_keeps_its_controller():
    # one thread inside, the library's own count restored after; the controller (a scan of
    # every loaded library) is kept while no module is imported, made anew after an import
    import importlib
    import sys

    from threadpoolctl import threadpool_info

    from meshphase.runtime import threads

    def blas_threads():
        return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]

    before = blas_threads()
    with threads.blas_single_thread():
        assert all(n == 1 for n in blas_threads())
        first = threads._controller()
    assert blas_threads() == before
    assert threads._controller() is first
    name = "meshphase.tests_fresh_import_probe"
    spec = importlib.machinery.ModuleSpec(name, None)
    sys.modules[name] = importlib.util.module_from_spec(spec)      # the module count moves
    try:
        assert threads._controller() is not first
    finally:
        del sys.modules[name]


def test_hold_blas_single_thread_stays_after_the_call():
    # process-wide and not restored (a fork server's workers inherit it): in a child
    # interpreter, so that this test process keeps its BLAS threads
    import subprocess
    import sys

    code = ("import numpy, threadpoolctl\n"
            "from meshphase.runtime import threads\n"
            "def n():\n"
            "    return [i['num_threads'] for i in threadpoolctl.threadpool_info() if i['user_api'] == 'blas']\n"
            "assert n(), 'no BLAS found'\n"
            "assert threads.hold_blas_single_thread() is None\n"
            "with threads.blas_single_thread():\n"
            "    pass\n"
            "print(n())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         env={**__import__("os").environ, "OPENBLAS_NUM_THREADS": "2"})
    assert out.returncode == 0, out.stderr
    counts = eval(out.stdout.strip())                 # a printed list of ints
    assert counts and all(c == 1 for c in counts)
