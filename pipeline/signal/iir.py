"""Zero-phase filtering by second-order sections: :func:`scipy.signal.sosfiltfilt`, or the
same arithmetic compiled by numba, two sections per sweep.

The conditioning's filters (hum notches, band limit, high-pass drift removal) are cascades
of one or two biquads run forwards and backwards over every sample of every conditioned
channel: the largest single cost of ``meshphase process``. scipy's loop runs all sections
for one sample before the next, its section states in memory; one section's recursion is
a chain of dependent multiplies and adds, so the loop is bound by that chain's latency
(~6 ns per section and sample here). :mod:`meshphase.signal._iir_numba` runs two sections together
through the samples, their states in registers: two independent chains the processor
overlaps, with the same operations in the same order for every section, so the same
numbers; :func:`sosfiltfilt_pair` runs two channels so in one sweep (four chains). In
``meshphase bench processing``'s iir rows (which also check that they agree with scipy):
one channel ~1.6x scipy's rate, two channels side by side ~2.4x.

Engines (``engine``): ``"scipy"``; ``"numba"`` (ValueError when numba is not importable);
``"auto"`` (the default) takes numba when it is importable and it is already loaded in
this process, or ``scipy.signal`` is not (the filter designs are :mod:`meshphase.signal.sos_design`'s,
so one of the two must be loaded for the filters: their loads cost about the same, numba's
import and kernel as ``meshphase bench --warmup`` prints them (numba's import on the first
kernel's line) against the start-up table's ``scipy.signal`` row of ``meshphase bench
processing``, and numba's kernel is the faster), or the job is at least ``NUMBA_SAMPLES``
samples, all channels together (``work``): below that, with ``scipy.signal`` loaded
already, loading numba costs more than it saves.

Padding, initial conditions and the result are those of ``scipy.signal.sosfiltfilt(sos, x,
padlen=padlen)`` (odd extension, steady-state initial conditions scaled by the first and
last values).
"""

from __future__ import annotations

import importlib.util
import sys
import threading
import time

import numpy as np

from ..runtime.lazy import signal as scipy_signal
from ..runtime.log import logger
from ..runtime.numba_cache import import_kernels
from .sos_design import butter_sos, sosfilt_zi

__all__ = ["ENGINES", "HAVE_NUMBA", "NUMBA_SAMPLES", "pick_engine", "padlen_for",
           "sosfiltfilt", "sosfiltfilt_pair", "extended", "filter_extended",
           "filter_extended_pair", "warmup"]

#: engines of :func:`sosfiltfilt`
ENGINES = ("auto", "numba", "scipy")
#: numba is optional (extras "fast" and "test"); looked for here, imported on first use
HAVE_NUMBA = importlib.util.find_spec("numba") is not None
_NUMBA_ERROR = "numba is not installed"
#: samples of a job (all its channels) from which ``engine="auto"`` loads numba [-]: about
#: where the filters' time saved (the two engines' rates in ``meshphase bench processing``'s
#: iir rows, two filters per conditioned channel, on the run's threads) pays for loading
#: numba and the kernel (``meshphase bench --warmup`` prints that time): ~19 min of 7
#: conditioned channels at 5120 Hz, set from paired runs of ``process`` with either engine
#: (the commit that set it gives them)
NUMBA_SAMPLES = 40_000_000

_ZI: dict = {}
_ZI_LOCK = threading.Lock()


def pick_engine(engine: str = "auto", work: int = 0) -> str:
    """The engine :func:`sosfiltfilt` takes: ``"numba"`` or ``"scipy"``.

    Parameters
    ----------
    engine : {"auto", "numba", "scipy"}
    work : int
        Samples of the whole job, all channels together [-] (``"auto"`` only).

    Raises
    ------
    ValueError
        An unknown engine, or ``"numba"`` when numba is not importable (``"auto"`` then
        takes scipy).
    """
    if not isinstance(engine, str) or engine not in ENGINES:
        raise ValueError(f"engine must be one of {list(ENGINES)}, got {engine!r}")
    if engine == "scipy":
        return "scipy"
    if engine == "auto" and not (HAVE_NUMBA and ("numba" in sys.modules
                                                 or "scipy.signal" not in sys.modules
                                                 or work >= NUMBA_SAMPLES)):
        return "scipy"
    if HAVE_NUMBA and _kernels() is not None:
        return "numba"
    if engine == "auto":
        return "scipy"                   # numba installed but broken: logged by _kernels
    raise ValueError(f"engine='numba' requested but numba is not importable ({_NUMBA_ERROR})")


def _kernels():
    """The numba kernel module, imported on first use with the per-user cache set; None
    (logged once, and numba taken for absent from then on) when numba is installed but
    does not import."""
    global HAVE_NUMBA, _NUMBA_ERROR
    try:
        return import_kernels("meshphase.signal._iir_numba")
    except ImportError as exc:
        HAVE_NUMBA, _NUMBA_ERROR = False, repr(exc.__cause__ or exc)
        logger.warning("numba does not import (%s): the filters run on scipy", _NUMBA_ERROR)
        return None


def _zi(sos: np.ndarray) -> np.ndarray:
    """``scipy.signal.sosfilt_zi(sos)``, computed once per filter."""
    key = sos.tobytes()
    zi = _ZI.get(key)
    if zi is None:
        zi = sosfilt_zi(sos)
        with _ZI_LOCK:
            if len(_ZI) > 64:
                _ZI.clear()
            _ZI[key] = zi
    return zi


def _check_sos(sos) -> np.ndarray:
    sos = np.ascontiguousarray(sos, dtype=np.float64)
    if sos.ndim != 2 or sos.shape[1] != 6 or sos.shape[0] == 0:
        raise ValueError(f"sos must have shape (n_sections, 6), got {sos.shape}")
    if not np.all(sos[:, 3] == 1.0):
        raise ValueError("sos[:, 3] (a0 of every section) must be 1")
    if not np.all(np.isfinite(sos)):
        raise ValueError("sos must be finite")
    return sos


def padlen_for(sos) -> int:
    """The odd extension the conditioning's zero-phase filters use at each end [-]:
    ``3 * (2 * n_sections + 1)``, scipy's default for sections without zero coefficients."""
    return 3 * (2 * len(sos) + 1)


def _check_padlen(padlen, n: int) -> int:
    """``padlen`` as an int, checked against ``n`` samples (scipy's rule: n > padlen)."""
    padlen = int(padlen)
    if padlen < 0:
        raise ValueError(f"padlen must be >= 0, got {padlen}")
    if n <= padlen:
        raise ValueError(f"x must be longer than padlen ({padlen}), got {n} samples")
    return padlen


def sosfiltfilt(sos, x, *, padlen: int, engine: str = "auto") -> np.ndarray:
    """Zero-phase filtering of one channel: ``scipy.signal.sosfiltfilt(sos, x,
    padlen=padlen)``.

    Parameters
    ----------
    sos : array_like, shape (n_sections, 6)
        Second-order sections (a0 = 1 in column 3).
    x : array_like, shape (n,)
        Samples [any unit]; n > ``padlen``.
    padlen : int
        Samples of odd extension at each end [-].
    engine : {"auto", "numba", "scipy"}
        See the module notes; ``"auto"`` here weighs this call's samples alone.

    Returns
    -------
    y : ndarray of float64, shape (n,)

    Raises
    ------
    ValueError
        ``sos`` not of shape (n_sections, 6) with a0 = 1, ``x`` not 1-D or not longer than
        ``padlen``, ``padlen`` negative, an unknown engine.
    """
    sos = _check_sos(sos)
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 1:
        raise ValueError(f"x must be 1-D, got shape {x.shape}")
    padlen = _check_padlen(padlen, x.size)
    if pick_engine(engine, x.size) == "scipy":
        return scipy_signal.sosfiltfilt(sos, x, padlen=padlen)
    return filter_extended(sos, extended([x], padlen), padlen)


def extended(pieces, padlen: int) -> np.ndarray:
    """The samples of ``pieces`` (1-D arrays, in order) with scipy's odd extension by
    ``padlen`` at each end, in one new float64 buffer: what :func:`filter_extended` filters
    in place (joining a stream's pieces here saves a copy of the window)."""
    n = sum(p.size for p in pieces)
    ext = np.empty(n + 2 * padlen)
    pos = padlen
    for p in pieces:
        ext[pos:pos + p.size] = p
        pos += p.size
    x = ext[padlen:padlen + n]
    if padlen:
        ext[:padlen] = 2 * x[0] - x[padlen:0:-1]
        ext[padlen + n:] = 2 * x[-1] - x[-2:-(padlen + 2):-1]
    return ext


def filter_extended(sos: np.ndarray, ext: np.ndarray, padlen: int) -> np.ndarray:
    """The numba engine's two sweeps over ``ext`` (from :func:`extended`, overwritten):
    the filtered samples, a view of ``ext`` without its extensions. ``sos`` as checked by
    :func:`sosfiltfilt`."""
    k = _kernels()
    zi = _zi(sos)
    k.cascade(sos, ext, zi * ext[0], False)
    k.cascade(sos, ext, zi * ext[-1], True)
    return ext[padlen:ext.size - padlen]


def filter_extended_pair(sos_a: np.ndarray, ea: np.ndarray, sos_b: np.ndarray, eb: np.ndarray,
                         padlen: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`filter_extended` of two channels in one sweep (equal lengths and section
    counts, see :func:`sosfiltfilt_pair`)."""
    k = _kernels()
    za, zb = _zi(sos_a), _zi(sos_b)
    k.cascade2(sos_a, sos_b, ea, eb, za * ea[0], zb * eb[0], False)
    k.cascade2(sos_a, sos_b, ea, eb, za * ea[-1], zb * eb[-1], True)
    return ea[padlen:ea.size - padlen], eb[padlen:eb.size - padlen]


def sosfiltfilt_pair(sos_a, xa, sos_b, xb, *, padlen: int) -> tuple[np.ndarray, np.ndarray]:
    """Two channels filtered in one sweep on the numba engine: ``(sosfiltfilt(sos_a, xa),
    sosfiltfilt(sos_b, xb))``, the same numbers as two calls.

    One channel's two-section recursion leaves the core waiting on its latency about half
    the time; two channels side by side fill it (four independent recursions per sample).

    Parameters
    ----------
    sos_a, sos_b : array_like, shape (n_sections, 6)
        The two filters (equal section counts).
    xa, xb : array_like, shape (n,)
        The two channels' samples (equal lengths, n > ``padlen``).
    padlen : int
        As :func:`sosfiltfilt`, for both.

    Returns
    -------
    ya, yb : ndarray of float64, shape (n,)

    Raises
    ------
    ValueError
        As :func:`sosfiltfilt`; unequal lengths or section counts; numba not importable.
    """
    sos_a, sos_b = _check_sos(sos_a), _check_sos(sos_b)
    if sos_a.shape != sos_b.shape:
        raise ValueError(f"sos_a and sos_b must have equal shapes, got {sos_a.shape} and "
                         f"{sos_b.shape}")
    xa, xb = np.asarray(xa, dtype=np.float64), np.asarray(xb, dtype=np.float64)
    if xa.ndim != 1 or xb.ndim != 1 or xa.size != xb.size:
        raise ValueError(f"xa and xb must be 1-D of equal length, got shapes {xa.shape} and "
                         f"{xb.shape}")
    padlen = _check_padlen(padlen, xa.size)
    pick_engine("numba")
    return filter_extended_pair(sos_a, extended([xa], padlen), sos_b, extended([xb], padlen),
                                padlen)


def warmup(check: bool = True) -> dict:
    """Load numba and the filter kernel (compiled once into the per-user cache), and check
    it against scipy (``meshphase bench --warmup``).

    Parameters
    ----------
    check : bool
        Compare the kernel with scipy.signal (imports it); False: load only (a campaign's
        fork server, :mod:`meshphase.campaign.fork_ready`, whose workers need no scipy.signal).

    Returns
    -------
    dict
        ``engine`` ("numba", or "scipy" when numba is not importable: nothing to load) and
        ``seconds`` [s] numba's import (when not loaded yet) and the kernel's compilation
        or cache load took; the check against scipy.signal (its import included) is not
        timed.
    """
    if not HAVE_NUMBA:
        return {"engine": "scipy", "seconds": 0.0}
    x = np.sin(np.arange(64.0))
    sos = butter_sos(3, 0.2, "lowpass", 2.0)         # two sections and a single one
    t = time.perf_counter()
    y = sosfiltfilt(sos, x, padlen=9, engine="numba")
    ya, yb = sosfiltfilt_pair(sos, x, sos, -x, padlen=9)
    seconds = time.perf_counter() - t
    if not check:
        return {"engine": "numba", "seconds": seconds}
    ref = scipy_signal.sosfiltfilt(sos, x, padlen=9)
    if not (np.allclose(y, ref, rtol=0.0, atol=1e-12) and np.array_equal(ya, y)
            and np.array_equal(yb, -y)):
        raise RuntimeError("the numba filter kernel disagrees with scipy.signal.sosfiltfilt")
    return {"engine": "numba", "seconds": seconds}
