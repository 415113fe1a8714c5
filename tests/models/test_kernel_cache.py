"""The numba kernel's cache is per user, and `meshphase bench --warmup` fills it."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from meshphase.models import _kernels


def test_cache_dir_is_per_user_unless_set(monkeypatch, tmp_path):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert _kernels.numba_cache_dir() == str(tmp_path / "xdg" / "meshphase" / "numba")
    monkeypatch.delenv("XDG_CACHE_HOME")
    assert _kernels.numba_cache_dir() == os.path.join(os.path.expanduser("~"), ".cache",
                                                      "meshphase", "numba")
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "mine"))
    assert _kernels.numba_cache_dir() == str(tmp_path / "mine")    # the user's choice wins


@pytest.mark.skipif(not _kernels.HAVE_NUMBA, reason="numba not installed")
def test_warmup_compiles_into_the_cache(tmp_path):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    res = subprocess.run([sys.executable, "-m", "meshphase.cli", "bench", "--warmup"], env=env,
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    assert "numba kernel ready" in res.stdout and str(tmp_path / "cache") in res.stdout
    assert "onset kernels ready" in res.stdout and "TDMS rows kernel ready" in res.stdout
    assert "filter kernel ready" in res.stdout
    cached = [f for _, _, fs in os.walk(tmp_path / "cache") for f in fs]
    assert any(f.endswith(".nbi") for f in cached) and any(f.endswith(".nbc") for f in cached)


def test_warmup_without_numba_needs_nothing(monkeypatch):
    monkeypatch.setattr(_kernels, "HAVE_NUMBA", False)
    assert _kernels.warmup() == {"engine": "numpy", "seconds": 0.0, "cache_dir": None}


def test_import_kernels_bad_input_and_the_shared_cache(monkeypatch, tmp_path):
    # one home for the cache directory and the first-use import of every numba kernel
    # module (the Monte Carlo's and the onsets'): a module that does not import is an
    # ImportError naming the cause, and an empty name is refused alike
    from meshphase.runtime import numba_cache
    from meshphase.models import _kernels

    assert _kernels.numba_cache_dir is numba_cache.numba_cache_dir
    with pytest.raises(ImportError, match="does not import"):
        numba_cache.import_kernels("meshphase.no_such_kernels")
    with pytest.raises(ImportError, match="does not import"):
        numba_cache.import_kernels("")
