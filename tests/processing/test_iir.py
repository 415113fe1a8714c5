"""meshphase.signal.iir: zero-phase filtering by second-order sections, scipy's or numba's.

The numba kernel does scipy's operations (scipy.signal.sosfilt's transposed direct form II)
in scipy's order for every section, two sections per sweep. Asserted: equal to
scipy.signal.sosfiltfilt to 1e-12 of the signal's amplitude. On x86-64 the two are equal bit
for bit (no fused multiply-adds on either side: measured, and checked by ``meshphase bench
processing``); the tolerance leaves room for a scipy build whose compiler contracts a
multiply and an add into one rounding (aarch64), a difference of an ulp per operation in a
stable filter (poles inside the unit circle: it does not grow).
"""

import sys
import threading

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import signal

from meshphase.signal import iir

numba_only = pytest.mark.skipif(not iir.HAVE_NUMBA, reason="numba is not installed")
FS = 5120.0


def _filters():
    """The conditioning's filters and the odd section counts the sweeps pair up."""
    notch = np.concatenate([signal.tf2sos(*signal.iirnotch(f, 30.0, fs=FS)) for f in (50.0, 100.0, 150.0)])
    return {
        "lowpass4": signal.butter(4, 28.6, fs=FS, output="sos"),
        "bandpass4": signal.butter(4, [0.36, 28.6], btype="bandpass", fs=FS, output="sos"),
        "highpass2": signal.butter(2, 0.36, btype="highpass", fs=FS, output="sos"),
        "lowpass1": signal.butter(1, 100.0, fs=FS, output="sos"),
        "lowpass5": signal.butter(5, 300.0, fs=FS, output="sos"),
        "notch3": notch,
    }


def _close(a, b, x):
    scale = max(float(np.max(np.abs(x))), 1.0)
    np.testing.assert_allclose(a, b, rtol=0.0, atol=1e-12 * scale)


@numba_only
@pytest.mark.parametrize("name", sorted(_filters()))
@pytest.mark.parametrize("n", [2, 50, 4097, 300_000])
def test_numba_equals_scipy_sosfiltfilt(name, n):
    sos = _filters()[name]
    rng = np.random.default_rng(n)
    x = rng.standard_normal(n) + 3.0 + np.linspace(0.0, 5.0, n)     # offset and drift: the ends matter
    for padlen in sorted({0, 1, 3 * (2 * len(sos) + 1), n - 1}):
        if padlen >= n:
            continue
        ref = signal.sosfiltfilt(sos, x, padlen=padlen)
        got = iir.sosfiltfilt(sos, x, padlen=padlen, engine="numba")
        assert got.shape == (n,) and got.dtype == np.float64
        _close(got, ref, x)


@numba_only
@settings(max_examples=60, deadline=None)
@given(n=st.integers(1, 400), order=st.integers(1, 6), wn=st.floats(0.001, 0.45),
       padlen=st.integers(0, 60), seed=st.integers(0, 2 ** 32 - 1), amp=st.floats(1e-6, 1e6))
def test_numba_equals_scipy_property(n, order, wn, padlen, seed, amp):
    if padlen >= n:
        padlen = n - 1
    sos = signal.butter(order, wn, output="sos")
    x = amp * np.random.default_rng(seed).standard_normal(n)
    _close(iir.sosfiltfilt(sos, x, padlen=padlen, engine="numba"),
           signal.sosfiltfilt(sos, x, padlen=padlen), x)


def test_scipy_engine_is_scipy_and_input_is_left_alone():
    sos = _filters()["lowpass4"]
    x = np.random.default_rng(1).standard_normal(1000)
    keep = x.copy()
    assert np.array_equal(iir.sosfiltfilt(sos, x, padlen=15, engine="scipy"),
                          signal.sosfiltfilt(sos, x, padlen=15))
    if iir.HAVE_NUMBA:
        iir.sosfiltfilt(sos, x, padlen=15, engine="numba")
    assert np.array_equal(x, keep)


@numba_only
def test_non_finite_samples_spread_as_in_scipy():
    sos = _filters()["lowpass4"]
    x = np.random.default_rng(2).standard_normal(200)
    x[120] = np.nan
    a = iir.sosfiltfilt(sos, x, padlen=15, engine="numba")
    b = signal.sosfiltfilt(sos, x, padlen=15)
    assert np.array_equal(np.isnan(a), np.isnan(b)) and np.isnan(a).all()


@numba_only
def test_kernel_runs_side_by_side_on_threads():
    """nogil: the channels' chains filter on worker threads; each result is the serial one."""
    sos = _filters()["notch3"]
    xs = [np.random.default_rng(k).standard_normal(200_000) for k in range(4)]
    serial = [iir.sosfiltfilt(sos, x, padlen=21, engine="numba") for x in xs]
    got = [None] * len(xs)

    def run(k):
        got[k] = iir.sosfiltfilt(sos, xs[k], padlen=21, engine="numba")

    ts = [threading.Thread(target=run, args=(k,)) for k in range(len(xs))]
    for t in ts:
        t.start()
    for t in ts:
        t.join()
    assert all(np.array_equal(a, b) for a, b in zip(got, serial))


def test_pick_engine_rule(monkeypatch):
    assert iir.pick_engine("scipy", 10 ** 12) == "scipy"
    monkeypatch.setattr(iir, "HAVE_NUMBA", False)
    assert iir.pick_engine("auto", 10 ** 12) == "scipy"
    with pytest.raises(ValueError, match="not importable"):
        iir.pick_engine("numba")
    monkeypatch.setattr(iir, "HAVE_NUMBA", True)
    # the kernel module stands in (its import is not what this rule is about, and numba
    # must not be imported afresh while it is out of sys.modules)
    monkeypatch.setattr(iir, "_kernels", lambda: object())
    monkeypatch.delitem(sys.modules, "numba", raising=False)
    monkeypatch.setitem(sys.modules, "scipy.signal", sys.modules.get("scipy.signal", object()))
    assert iir.pick_engine("auto", iir.NUMBA_SAMPLES - 1) == "scipy"      # numba's import would not pay
    assert iir.pick_engine("auto", iir.NUMBA_SAMPLES) == "numba"
    assert iir.pick_engine("numba", 0) == "numba"
    monkeypatch.delitem(sys.modules, "scipy.signal")     # one of the two must load: numba's is faster
    assert iir.pick_engine("auto", 0) == "numba"
    monkeypatch.setitem(sys.modules, "scipy.signal", object())
    monkeypatch.setitem(sys.modules, "numba", object())                   # loaded already: free
    assert iir.pick_engine("auto", 0) == "numba"


@pytest.mark.parametrize("engine", ["fast", None, 1, "NUMBA"])
def test_pick_engine_bad_input(engine):
    with pytest.raises(ValueError, match="engine must be one of"):
        iir.pick_engine(engine)


@pytest.mark.parametrize("engine", ["scipy"] + (["numba"] if iir.HAVE_NUMBA else []))
def test_sosfiltfilt_empty_and_bad_input(engine):
    sos = _filters()["lowpass4"]
    x = np.arange(100.0)
    with pytest.raises(ValueError, match="longer than padlen"):
        iir.sosfiltfilt(sos, np.empty(0), padlen=0, engine=engine)
    with pytest.raises(ValueError, match="longer than padlen"):
        iir.sosfiltfilt(sos, x[:15], padlen=15, engine=engine)
    with pytest.raises(ValueError, match="padlen must be >= 0"):
        iir.sosfiltfilt(sos, x, padlen=-1, engine=engine)
    with pytest.raises(ValueError, match="1-D"):
        iir.sosfiltfilt(sos, np.ones((10, 2)), padlen=3, engine=engine)
    with pytest.raises(ValueError, match=r"shape \(n_sections, 6\)"):
        iir.sosfiltfilt(sos[:, :5], x, padlen=3, engine=engine)
    with pytest.raises(ValueError, match=r"shape \(n_sections, 6\)"):
        iir.sosfiltfilt(np.empty((0, 6)), x, padlen=3, engine=engine)
    bad = sos.copy()
    bad[0, 3] = 2.0
    with pytest.raises(ValueError, match="a0"):
        iir.sosfiltfilt(bad, x, padlen=3, engine=engine)
    bad[0, 3], bad[1, 4] = 1.0, np.nan
    with pytest.raises(ValueError, match="finite"):
        iir.sosfiltfilt(bad, x, padlen=3, engine=engine)


def test_warmup_loads_and_checks_the_kernel():
    w = iir.warmup()
    assert w["engine"] == ("numba" if iir.HAVE_NUMBA else "scipy")
    assert w["seconds"] >= 0.0


def test_warmup_without_the_check_loads_no_scipy_signal():
    # a campaign's fork server loads the kernel alone (meshphase.campaign.fork_ready)
    import subprocess
    import sys

    code = ("import sys\nfrom meshphase.signal import iir\nw = iir.warmup(check=False)\n"
            "print(w['engine'], w['seconds'] >= 0, 'scipy.signal' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["numba" if iir.HAVE_NUMBA else "scipy", "True", "False"]


@numba_only
@pytest.mark.parametrize("pair", [("lowpass4", "notch3"), ("bandpass4", "bandpass4"),
                                  ("lowpass5", "lowpass5"), ("lowpass1", "lowpass1")])
@pytest.mark.parametrize("n", [2, 777, 300_000])
def test_pair_equals_two_single_calls(pair, n):
    """Two channels in one sweep: each channel's operations are those of its own call, so
    the numbers are the same bit for bit (on every machine: one kernel, one compiler)."""
    fs = _filters()
    sa, sb = fs[pair[0]], fs[pair[1]]
    if sa.shape != sb.shape:
        sb = np.concatenate([sb, sb])[:len(sa)]          # equal section counts
    rng = np.random.default_rng(n)
    xa, xb = rng.standard_normal(n) + 2.0, 1e3 * rng.standard_normal(n)
    padlen = min(3 * (2 * len(sa) + 1), n - 1)
    ya, yb = iir.sosfiltfilt_pair(sa, xa, sb, xb, padlen=padlen)
    assert np.array_equal(ya, iir.sosfiltfilt(sa, xa, padlen=padlen, engine="numba"))
    assert np.array_equal(yb, iir.sosfiltfilt(sb, xb, padlen=padlen, engine="numba"))
    _close(ya, signal.sosfiltfilt(sa, xa, padlen=padlen), xa)


@numba_only
def test_pair_empty_and_bad_input():
    sos = _filters()["lowpass4"]
    x = np.arange(100.0)
    with pytest.raises(ValueError, match="longer than padlen"):
        iir.sosfiltfilt_pair(sos, np.empty(0), sos, np.empty(0), padlen=0)
    with pytest.raises(ValueError, match="equal length"):
        iir.sosfiltfilt_pair(sos, x, sos, x[:-1], padlen=3)
    with pytest.raises(ValueError, match="equal length"):
        iir.sosfiltfilt_pair(sos, x, sos, np.ones((100, 1)), padlen=3)
    with pytest.raises(ValueError, match="equal shapes"):
        iir.sosfiltfilt_pair(sos, x, sos[:1], x, padlen=3)
    with pytest.raises(ValueError, match="padlen must be >= 0"):
        iir.sosfiltfilt_pair(sos, x, sos, x, padlen=-2)
    with pytest.raises(ValueError, match="a0"):
        iir.sosfiltfilt_pair(sos, x, sos * 2.0, x, padlen=3)


def test_pair_needs_numba(monkeypatch):
    monkeypatch.setattr(iir, "HAVE_NUMBA", False)
    sos = _filters()["lowpass4"]
    with pytest.raises(ValueError, match="not importable"):
        iir.sosfiltfilt_pair(sos, np.arange(50.0), sos, np.arange(50.0), padlen=3)


@pytest.mark.parametrize("cuts", [[], [1], [5, 6, 90], [0, 0, 50]])
def test_extended_joins_pieces_as_one_array(cuts):
    """A stream's pieces joined straight into the kernel's buffer: the same buffer as the
    joined array's, with scipy's odd extension at both ends (2 x[0] - x[k], numpy's odd
    reflection)."""
    x = np.random.default_rng(3).standard_normal(120)
    pieces = np.split(x, cuts)
    for padlen in (0, 1, 15, 119):
        got = iir.extended(pieces, padlen)
        assert np.array_equal(got, np.pad(x, padlen, mode="reflect", reflect_type="odd"))


def test_extended_empty():
    assert iir.extended([], 0).size == 0


def test_numba_installed_but_broken_falls_back_to_scipy(monkeypatch, caplog):
    """numba found but its import fails (a broken install): "auto" filters on scipy and
    says so once; "numba" is refused with the cause."""
    def broken(name):
        raise ImportError(f"{name} does not import (boom)")

    monkeypatch.setattr(iir, "HAVE_NUMBA", True)
    monkeypatch.setattr(iir, "_NUMBA_ERROR", iir._NUMBA_ERROR)
    monkeypatch.setattr(iir, "import_kernels", broken)
    with caplog.at_level("WARNING", logger="meshphase"):
        assert iir.pick_engine("auto", 10 ** 12) == "scipy"
    assert "numba does not import" in caplog.text and not iir.HAVE_NUMBA
    with pytest.raises(ValueError, match="boom"):
        iir.pick_engine("numba")
    sos = _filters()["lowpass4"]
    x = np.random.default_rng(5).standard_normal(500)
    assert np.array_equal(iir.sosfiltfilt(sos, x, padlen=15),
                          signal.sosfiltfilt(sos, x, padlen=15))
