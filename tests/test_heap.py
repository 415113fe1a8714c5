"""meshphase.runtime.heap: glibc's mmap threshold fixed for streamed runs."""

import subprocess
import sys

import pytest

from meshphase.runtime.heap import limit_heap_growth


def test_bad_threshold():
    for bad in (0, 4095, 2**26, 1.5, True, "128k", None):
        with pytest.raises(ValueError, match="threshold"):
            limit_heap_growth(bad)


def _child(code: str, env=None) -> str:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True, env=env).stdout.strip()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc only")
def test_threshold_fixed_once_in_a_fresh_process():
    # a fresh interpreter: the first call sets it, the second reports the same answer; on a
    # glibc system mallopt accepts the value (returns 1)
    out = _child("from meshphase.runtime.heap import limit_heap_growth as f; print(f(), f())")
    a, b = out.split()
    assert a == b
    import platform
    if platform.libc_ver()[0] == "glibc":
        assert a == "True"


def test_environment_setting_is_left_alone():
    import os
    env = dict(os.environ, MALLOC_MMAP_THRESHOLD_="262144")
    out = _child("from meshphase.runtime.heap import limit_heap_growth as f; print(f())", env=env)
    assert out == "True"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc only")
def test_trimming_thread_runs_after_the_first_call():
    # the heap's free pages go back to the system from a daemon thread (pipeline/runtime/heap.py):
    # none before the call, one after it, and a second call starts no other
    code = ("import threading, time\n"
            "from meshphase.runtime.heap import heap_trimming, limit_heap_growth\n"
            "before = heap_trimming()\n"
            "a = limit_heap_growth(); b = limit_heap_growth(); time.sleep(0.6)\n"
            "n = sum(t.name == 'meshphase-heap-trim' for t in threading.enumerate())\n"
            "print(before, a, heap_trimming(), n)")
    import platform
    before, a, trimming, n = _child(code).split()
    assert before == "False"
    if platform.libc_ver()[0] == "glibc":
        assert (a, trimming, n) == ("True", "True", "1")


def test_trim_step_hands_back_only_after_the_slack(monkeypatch):
    from meshphase.runtime import heap

    seq = iter([100, 100, 150, 90, 400, 120, None, 130])   # resident set per look [bytes]
    monkeypatch.setattr(heap, "_rss_bytes", lambda: next(seq))
    calls = []
    trim = calls.append
    floor = heap._trim_step(trim, None, 200)          # first look: trim, floor after it
    assert calls == [0] and floor == 100
    floor = heap._trim_step(trim, floor, 200)         # 150: within the slack
    assert calls == [0] and floor == 100
    floor = heap._trim_step(trim, floor, 200)         # 90: a lower floor
    assert calls == [0] and floor == 90
    floor = heap._trim_step(trim, floor, 200)         # 400 > 90 + 200: trim
    assert calls == [0, 0] and floor == 120
    floor = heap._trim_step(trim, floor, 200)         # unreadable: trim anyway
    assert calls == [0, 0, 0] and floor == 130
    assert heap.TRIM_SLACK > 0 and heap.TRIM_PERIOD > 0


_FAULTS = ("import resource, sys\n"
           "import numpy as np\n"
           "from meshphase.runtime.heap import limit_heap_growth\n"
           "limit_heap_growth(trim_env=sys.argv[1] == '1')\n"
           "def faults():\n"
           "    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt\n"
           "b = np.ones(2**18)\n"
           "del b\n"
           "a = faults()\n"
           "for _ in range(40):\n"
           "    b = np.ones(2**18)        # 2 MiB from the heap, freed at its top\n"
           "    del b\n"
           "print(faults() - a)\n")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc only")
def test_trim_env_false_fixes_a_trim_threshold_the_environment_set():
    # distributed's 64 KiB in a Dask worker's environment (meshphase.campaign.cluster.trim_env_is_distributed):
    # left alone, every 2-MiB array freed at the heap's top is handed back and faulted in
    # again (512 pages each); with trim_env=False the threshold is fixed at 64 MiB and the
    # heap keeps the pages. The counts are the kernel's, not timings
    import os
    import platform

    if platform.libc_ver()[0] != "glibc":
        pytest.skip("glibc only")
    env = dict(os.environ, MALLOC_TRIM_THRESHOLD_="65536")
    left = int(subprocess.run([sys.executable, "-c", _FAULTS, "1"], capture_output=True, text=True,
                              check=True, env=env).stdout)
    fixed = int(subprocess.run([sys.executable, "-c", _FAULTS, "0"], capture_output=True, text=True,
                               check=True, env=env).stdout)
    assert left > 40 * 256              # at least half the pages of every array, every time
    assert fixed < 2 * 512              # about one array's pages at most
