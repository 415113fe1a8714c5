"""meshphase.threads: worker threads of one run (thread count, order, errors, progress).

``thread_map`` below is one call of a :func:`thread_pool`, as the streamed conditioning makes
per block."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from meshphase import threads
from meshphase.threads import ENV_THREADS, MAX_THREADS, run_threads, thread_pool, threads_limited


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
