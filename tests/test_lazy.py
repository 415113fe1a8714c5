"""meshphase.runtime.lazy: module proxies that import their module on first attribute read."""

import subprocess
import sys

import pytest

from meshphase.runtime.lazy import LazyModule, is_loaded, lazy_module, load_all


def _run(code):
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    return res.stdout.strip()


def test_creating_a_proxy_imports_nothing():
    # a fresh interpreter: neither the proxies of meshphase.runtime.lazy nor a new one load scipy
    out = _run("import sys, meshphase.runtime.lazy as lz; p = lz.lazy_module('scipy.special'); "
               "repr(p); print(sorted(m for m in sys.modules if m == 'scipy' or m.startswith('scipy.')), "
               "lz.is_loaded(p), lz.is_loaded(lz.linalg))")
    assert out == "[] False False"


def test_attribute_read_imports_the_module():
    out = _run("import sys, meshphase.runtime.lazy as lz; f = lz.special.ndtr; "
               "import scipy.special; print('scipy.special' in sys.modules, f is scipy.special.ndtr, "
               "lz.is_loaded(lz.special), 'ndtr' in vars(lz.special), dir(lz.special) == dir(scipy.special))")
    assert out == "True True True True True"


def test_dunder_probes_do_not_import():
    out = _run("import sys, inspect, meshphase.runtime.lazy as lz; inspect.unwrap(lz.optimize); "
               "print(hasattr(lz.optimize, '__path__'), 'scipy.optimize' in sys.modules)")
    assert out == "False False"


def test_a_missing_module_fails_on_first_use_naming_it():
    proxy = lazy_module("meshphase_no_such_module.sub")          # creation does not look it up
    assert not is_loaded(proxy)
    with pytest.raises(ImportError, match="meshphase_no_such_module.sub") as exc:
        proxy.anything
    assert exc.value.name == "meshphase_no_such_module.sub"
    assert not is_loaded(proxy)


def test_a_missing_attribute_is_an_attribute_error():
    proxy = lazy_module("json")
    with pytest.raises(AttributeError):
        proxy.no_such_function
    assert is_loaded(proxy) and proxy.dumps([1]) == "[1]"


def test_repr_says_whether_it_is_loaded():
    proxy = lazy_module("json")
    assert repr(proxy) == "<lazy module 'json' (not loaded)>"
    assert "dumps" in dir(proxy)
    assert repr(proxy) == "<lazy module 'json' (loaded)>"
    assert isinstance(proxy, LazyModule)


@pytest.mark.parametrize("bad", ["", ".relative", None, 3])
def test_empty_or_bad_names_are_refused(bad):
    with pytest.raises(ValueError, match="absolute module name"):
        lazy_module(bad)


def test_load_all_loads_the_processing_modules_and_not_signal_or_stats():
    out = _run("import sys, meshphase.runtime.lazy as lz; lz.load_all(); "
               "print(all(lz.is_loaded(p) for p in lz.PROCESSING_SCIPY), "
               "[m for m in ('scipy.linalg', 'scipy.optimize', 'scipy.signal', 'scipy.stats') if m in sys.modules])")
    assert out == "True ['scipy.linalg', 'scipy.optimize']"


def test_load_all_of_nothing_loads_nothing():
    out = _run("import sys, meshphase.runtime.lazy as lz; lz.load_all(()); "
               "print([m for m in sys.modules if m.startswith('scipy')])")
    assert out == "[]"


def test_load_all_refuses_what_is_not_a_proxy():
    proxy = lazy_module("json")
    with pytest.raises(TypeError, match="LazyModule"):
        load_all([proxy, "scipy.linalg"])
    assert not is_loaded(proxy)                       # checked before anything is loaded


def test_the_proxy_adds_no_public_name_over_the_module():
    # numpy.load stays numpy's: the proxy's own state is asked through is_loaded
    np_proxy = lazy_module("numpy")
    import numpy

    assert np_proxy.load is numpy.load
    assert not [a for a in vars(LazyModule) if not a.startswith("_")]


def test_is_loaded_refuses_what_is_not_a_proxy():
    import json

    with pytest.raises(TypeError, match="LazyModule"):
        is_loaded(json)
    with pytest.raises(TypeError, match="LazyModule"):
        is_loaded(None)
