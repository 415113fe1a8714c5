"""The onset stage's optional numba path for dense pulse trains, and the rule choosing it.

At one pulse every ~15 samples the numpy path spends its time in per-pulse array steps
(a BLAS product on short rows, argmax, gathers, a dozen element-wise passes over ~70 000
pulses per block) and in the coarse stage's run bookkeeping (``flatnonzero``, ``diff``,
``cumsum``, ``reduceat`` over every sample above the threshold). The numba kernels
(:mod:`meshphase.onsets._numba_kernels`) do each in one pass:

- :func:`run_maxima`: the coarse maxima of the runs above the threshold, equal to the
  numpy path's bit for bit (comparisons and indices only);
- :func:`refine_pulses`: correlation at the (sub-)lags, parabolic peak, NCC, width,
  index, amplitude and flags per pulse, equal to the numpy path to rounding (the
  correlations are the same BLAS product, 32 windows at a time; the NCC and baseline sums
  are added in sample order, where numpy's BLAS and einsum add them in their own).

Rule (``engine="auto"``, the default): the numba path serves a block when numba is
importable and either already loaded in this process (as in ``process``, whose filters run
on numba's kernel: :func:`meshphase.signal.iir.pick_engine`) or the block is dense: it can hold at
least ``DENSE_PULSES`` pulses at the minimum spacing (coarse stage) or has at least
``DENSE_PULSES`` pulses to refine (refinement). With numba loaded, loading the onset
kernels from the cache costs little (``meshphase bench --warmup`` prints it) and the
kernels are also the faster on sparse blocks (the throughput table's auto rows against
the ``engine=numpy`` rows); without it, sparse blocks (pulses tens of samples wide or
more) keep the numpy path, which does not load numba for them. ``engine="numba"`` uses
the kernels for every block, ``engine="numpy"`` never. ``meshphase bench processing``
measures both engines per scenario.
"""

from __future__ import annotations

import importlib.util
import sys
import time

import numpy as np

from ..runtime.numba_cache import import_kernels

__all__ = ["ENGINES", "HAVE_NUMBA", "DENSE_PULSES", "check_engine", "dense", "run_maxima",
           "refine_pulses", "warmup"]

ENGINES = ("auto", "numba", "numpy")
#: numba is optional (extras "fast" and "test"); looked for here, imported on first use
HAVE_NUMBA = importlib.util.find_spec("numba") is not None
#: pulses per analysis block from which ``engine="auto"`` takes the numba path [-]
DENSE_PULSES = 16384
_NUMBA_ERROR = "numba is not installed"


def _kernels():
    """The numba kernel module, imported on first use with the per-user cache set
    (ImportError when numba cannot be imported after all)."""
    global HAVE_NUMBA, _NUMBA_ERROR
    try:
        return import_kernels("meshphase.onsets._numba_kernels")
    except ImportError as exc:  # pragma: no cover - a broken numba install
        HAVE_NUMBA, _NUMBA_ERROR = False, repr(exc.__cause__ or exc)
        raise


def check_engine(engine) -> str:
    """``engine`` checked: one of ``ENGINES``; ``"numba"`` without numba is a ValueError."""
    if not isinstance(engine, str) or engine not in ENGINES:
        raise ValueError(f"engine must be one of {list(ENGINES)}, got {engine!r}")
    if engine == "numba" and not HAVE_NUMBA:
        raise ValueError(f"engine='numba' requested but numba is not importable ({_NUMBA_ERROR})")
    return engine


def dense(engine: str, n_pulses: float) -> bool:
    """Does a block with (at most) ``n_pulses`` pulses take the numba path (``engine``
    checked by :func:`check_engine`)?"""
    if engine == "numpy":
        return False
    if engine == "numba":
        return True
    return HAVE_NUMBA and ("numba" in sys.modules or n_pulses >= DENSE_PULSES)


def run_maxima(ys: np.ndarray, thr: float, gap: int, long_len: float) -> np.ndarray:
    """First maximum of every run above ``thr`` [sample indices of ``ys``], int64.

    Parameters
    ----------
    ys : ndarray of float64, shape (n,)
        Smoothed (decimated) samples [data units].
    thr : float
        Threshold [data units].
    gap : int
        Samples above the threshold at most this far apart form one run [samples].
    long_len : float
        A run spanning more than this is split at every break [samples].
    """
    ys = np.asarray(ys)
    if ys.ndim != 1:
        raise ValueError(f"ys must be 1-D, got shape {ys.shape}")
    if ys.size == 0:
        return np.empty(0, dtype=np.int64)
    return _kernels()._run_maxima(np.ascontiguousarray(ys, dtype=np.float64), float(thr),
                                  int(gap), float(long_len))


def refine_pulses(yd: np.ndarray, peaks: np.ndarray, anchor: int, k: int, u: int,
                  t_all: np.ndarray, e0: float, tensile: np.ndarray, n_base: int, lo: int,
                  d: int, ref: float, width_unit: float, min_corr: float, base_flags: int,
                  flag_edge: int, flag_low: int):
    """The refinement of every pulse at ``peaks`` in one compiled pass.

    Parameters as :class:`meshphase.onsets.matched.Matcher` holds them (``t_all`` shape
    ``(L + 2k, ncol)``, ``tensile`` the template's tensile sample indices, ``n_base`` the
    samples at each window end that make the baseline); ``lo`` and ``d`` place the block,
    ``ref`` is the template's onset feature [decimated samples], ``width_unit`` ``d / fs``
    [s].

    Returns
    -------
    tuple of ndarray
        index [full-rate samples], amplitude [data units], NCC [-], width [s], flags
        (uint8) and the first full-rate sample of each pulse window (int64).
    """
    t_all = np.asarray(t_all)
    if t_all.ndim != 2 or t_all.shape[0] < 2 * k + 1 or np.asarray(yd).ndim != 1:
        raise ValueError(f"t_all must be (L + 2k, ncol) with L >= 1 and yd 1-D, got t_all "
                         f"{t_all.shape}, k={k}, yd {np.shape(yd)}")
    n = peaks.size
    out = (np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n, dtype=np.uint8),
           np.empty(n, dtype=np.int64))
    if n:
        _kernels()._refine_pulses(
            np.ascontiguousarray(yd, dtype=np.float64), np.ascontiguousarray(peaks, dtype=np.int64),
            int(anchor), int(k), int(u), np.ascontiguousarray(t_all, dtype=np.float64), float(e0),
            np.ascontiguousarray(tensile, dtype=np.int64), int(n_base), int(lo), int(d), float(ref),
            float(width_unit), float(min_corr), np.uint8(base_flags), np.uint8(flag_edge),
            np.uint8(flag_low), *out)
    return out


def warmup() -> dict:
    """Compile the onset kernels once (or load them from the per-user cache), so that the
    first dense block of a run does not pay for it (``meshphase bench --warmup``).

    Returns
    -------
    dict
        ``engine`` ("numba", or "numpy" when numba is not importable: nothing to compile)
        and ``seconds`` [s] the import and compilation took.
    """
    t = time.perf_counter()
    if not HAVE_NUMBA:
        return {"engine": "numpy", "seconds": 0.0}
    ys = np.array([0.0, 2.0, 1.0, 0.0, 3.0, 0.0])
    peaks = run_maxima(ys, 0.5, 1, 3.0)
    t_all = np.eye(3)
    refine_pulses(ys, peaks, 0, 1, 1, t_all, 1.0, np.array([0]), 1, 0, 1, 0.0, 1.0, 0.5, 0, 1, 2)
    return {"engine": "numba", "seconds": time.perf_counter() - t}
