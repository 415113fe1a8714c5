"""Inner loops of the shaft-hole-error phasing model (numpy path and optional numba path).

Private module. Both paths evaluate the same arithmetic, in the same order, on the same
precomputed inputs, so they agree to a few units in the last place (the tests hold them to
1e-12); only the summation order of the time mean differs.

Inputs (all float64):

- ``cs, ss`` / ``cr, sr`` / ``cp, sp`` : cos and sin of the reduced offset rotation angles
  w_sc t, w_rc t, w_pc t on the time grid, shape (n_t,) [-]. They come from
  :func:`meshphase.models.mesh_phasing.rotation_cos_sin`, which reduces w t modulo 2 pi
  exactly, so no large argument ever reaches a trig function here.
- ``cpsi, spsi`` : cos and sin of the nominal planet angles psi_n, shape (N,) [-].
- ``R`` : carrier radius [m].
- per realisation i: ``es, cks, sks`` sun radial error [m] and cos/sin of its angle, shape (S,);
  ``er, ckr, skr`` the ring's; ``ep, ckp, skp`` the planets', shape (S, N).

Geometry (carrier frame, counter-clockwise positive; see mesh_phasing for the derivation):
in the frame of planet n (radial unit vector u_n towards the ideal planet centre, tangential
unit vector t_n = u_n rotated +90 deg) the vector from the actual sun centre to the actual
planet centre is

    v_s = (R - e_p cos th - e_s cos(a_s - psi_n),  -e_p sin th - e_s sin(a_s - psi_n))

with th = w_pc t + kappa_p and a_s = w_sc t + kappa_s (ring: e_r, a_r = w_rc t + kappa_r), and
the angular deviation of the mesh line from the nominal planet angle is delta = atan2(v_t, v_u).
The angles enter only through angle addition of precomputed cos/sin, which is what makes the
inner loop cheap. The numba kernel loops over time innermost with a branch-free atan (Cephes)
so that loop vectorises (libm's atan2 is not vectorised). The kernel also reduces the absolute
(not planet-1-relative) deviations.

Throughput is measured by ``meshphase bench models`` ("Kernel throughput" in
``models_bench.md``: G realisation x time x planet evaluations per second, both meshes, all
eight statistics, one thread and all threads). On the 2-core reference machine it gives
0.065-0.135 G evaluations/s unloaded (0.088 on one thread, 0.135 on both; the numpy path
0.033) and about a tenth of that under a load average of ~13.
"""

from __future__ import annotations

import importlib.util
import os
import time

import numpy as np

from ..runtime.log import logger
from ._kernel_math import atan_cephes  # noqa: F401  (the scalar reference, re-exported)
from ..runtime.numba_cache import import_kernels, numba_cache_dir  # noqa: F401  (numba_cache_dir re-exported)

__all__ = ["HAVE_NUMBA", "deltas_numpy", "stats_numpy", "stats_numba", "resolve_engine",
           "atan_cephes", "numba_cache_dir", "warmup"]

#: numba is optional (extras "fast" and "test"); it is looked for here, imported (with LLVM,
#: ~0.2-0.5 s) only when a Monte Carlo first runs on it (:func:`_numba_kernels`)
HAVE_NUMBA = importlib.util.find_spec("numba") is not None
_NUMBA_ERROR = "numba is not installed"


def _numba_kernels():
    """The numba module of the kernel, imported on first use with the per-user cache set
    (ImportError when numba cannot be imported after all)."""
    global HAVE_NUMBA, _NUMBA_ERROR
    try:
        return import_kernels("meshphase.models._kernels_numba")
    except ImportError as exc:  # pragma: no cover - a broken numba install
        HAVE_NUMBA, _NUMBA_ERROR = False, repr(exc.__cause__ or exc)
        raise

ENGINES = ("auto", "numba", "numpy")
_LOGGED_FALLBACK = False


def resolve_engine(engine: str) -> str:
    """Return ``"numba"`` or ``"numpy"`` for a requested engine.

    ``"auto"`` picks numba when it imports and logs (once, at INFO) when it falls back to the
    numpy path. Asking for ``"numba"`` explicitly without numba is a ValueError.
    """
    global _LOGGED_FALLBACK
    if not isinstance(engine, str):
        raise TypeError(f"engine must be a string, one of {list(ENGINES)}, got {engine!r}")
    if engine not in ENGINES:
        raise ValueError(f"engine must be one of {list(ENGINES)}, got {engine!r}")
    if engine == "numpy":
        return "numpy"
    if HAVE_NUMBA:
        try:
            _numba_kernels()
            return "numba"
        except ImportError:  # pragma: no cover - a broken numba install: as without numba
            pass
    if engine == "numba":
        raise ValueError(f"engine='numba' requested but numba is not importable ({_NUMBA_ERROR})")
    if not _LOGGED_FALLBACK:
        logger.info("numba is not importable (%s): the phasing statistics use the numpy path "
                    "(same numbers, slower)", _NUMBA_ERROR)
        _LOGGED_FALLBACK = True
    return "numpy"


def deltas_numpy(cs, ss, cr, sr, cp, sp, cpsi, spsi, R, es, cks, sks, er, ckr, skr, ep, ckp, skp,
                 *, time_last: bool = False):
    """Angular deviations delta_s, delta_r [rad] of the mesh lines, shape (S, n_t, N), or
    (S, N, n_t) with ``time_last`` (the layout :func:`stats_numpy` reduces along time in).

    ``es ... skr`` have shape (S,), ``ep, ckp, skp`` shape (S, N); the time arrays (n_t,).
    The layout changes only how the arrays broadcast: every element is the same arithmetic.
    """
    all_ = slice(None)
    t_ix = (None, None, all_) if time_last else (None, all_, None)    # time arrays (n_t,)
    n_ix = (None, all_, None) if time_last else (None, None, all_)    # planet arrays (N,)
    sn_ix = (all_, all_, None) if time_last else (all_, None, all_)   # (S, N)
    s_ix = (all_, None, None)                                         # (S,)
    c_t = cs[t_ix]
    s_t = ss[t_ix]
    # sun offset direction a_s = w_sc t + kappa_s (angle addition), S x time
    ca_s = c_t * cks[s_ix] - s_t * sks[s_ix]
    sa_s = s_t * cks[s_ix] + c_t * sks[s_ix]
    c_t = cr[t_ix]
    s_t = sr[t_ix]
    ca_r = c_t * ckr[s_ix] - s_t * skr[s_ix]
    sa_r = s_t * ckr[s_ix] + c_t * skr[s_ix]
    # planet offset angle th = w_pc t + kappa_p, S x time x N
    c_t = cp[t_ix]
    s_t = sp[t_ix]
    ct = c_t * ckp[sn_ix] - s_t * skp[sn_ix]
    st = s_t * ckp[sn_ix] + c_t * skp[sn_ix]
    epb = ep[sn_ix]
    px = R - epb * ct
    py = -(epb * st)
    del ct, st
    cps = cpsi[n_ix]
    sps = spsi[n_ix]
    crel = ca_s * cps + sa_s * sps
    srel = sa_s * cps - ca_s * sps
    esb = es[s_ix]
    d_s = np.arctan2(py - esb * srel, px - esb * crel)
    crel = ca_r * cps + sa_r * sps
    srel = sa_r * cps - ca_r * sps
    erb = er[s_ix]
    d_r = np.arctan2(py - erb * srel, px - erb * crel)
    return d_s, d_r


def stats_numpy(cs, ss, cr, sr, cp, sp, cpsi, spsi, R, es, cks, sks, er, ckr, skr, ep, ckp, skp,
                g_s, g_r, out_ave_s, out_dev_s, out_ave_r, out_dev_r, out_abs=None,
                chunk_elems=1 << 15):
    """Ave and Dev of the phasing deviation per realisation (numpy path), written in place.

    g_s, g_r are the factors that turn an angle difference into mesh cycles
    (+-Z_s / 2 pi, -+Z_r / 2 pi). Output arrays have shape (S, N): relative to planet 1
    (``g (delta_n - delta_1)``) in ``out_*``, and, when ``out_abs`` = (ave_s, dev_s, ave_r,
    dev_r) is given, each mesh's own deviation ``g delta_n`` (absolute, seed 000's
    gamma_jn = Z psi_ejpn / 2 pi less its ideal value). Realisations are processed in chunks
    of about ``chunk_elems`` (S_chunk x N x n_t) elements: the default keeps each of the
    chain's temporary arrays (256 kB) and the chain itself in the processor's caches,
    which runs it faster than chunks of 2^20 elements did, with the same numbers
    (a realisation's arithmetic does not depend on its chunk). Time is the
    contiguous last axis of the deviations (:func:`deltas_numpy` with ``time_last``), so
    the time means, maxima and minima reduce contiguous rows; with time in the middle,
    numpy's reductions ran over rows of N = 3-5 values, several times slower.
    """
    n_s = es.shape[0]
    n_t = cs.shape[0]
    n_p = cpsi.shape[0]
    step = max(1, int(chunk_elems) // max(1, n_t * n_p))
    for a in range(0, n_s, step):
        b = min(n_s, a + step)
        d_s, d_r = deltas_numpy(cs, ss, cr, sr, cp, sp, cpsi, spsi, R, es[a:b], cks[a:b],
                                sks[a:b], er[a:b], ckr[a:b], skr[a:b], ep[a:b], ckp[a:b], skp[a:b],
                                time_last=True)
        for d, g, ave, dev in ((d_s, g_s, out_ave_s, out_dev_s), (d_r, g_r, out_ave_r, out_dev_r)):
            v = g * (d - d[:, :1, :])
            ave[a:b] = v.mean(axis=2)
            dev[a:b] = v.max(axis=2) - v.min(axis=2)
        if out_abs is not None:
            for d, g, ave, dev in ((d_s, g_s, out_abs[0], out_abs[1]),
                                   (d_r, g_r, out_abs[2], out_abs[3])):
                v = g * d
                ave[a:b] = v.mean(axis=2)
                dev[a:b] = v.max(axis=2) - v.min(axis=2)


def stats_numba(cs, ss, cr, sr, cp, sp, cpsi, spsi, R, es, cks, sks, er, ckr, skr, ep, ckp, skp,
                g_s, g_r, out_ave_s, out_dev_s, out_ave_r, out_dev_r, out_abs=None):
    """Same as :func:`stats_numpy`, compiled with numba (parallel over realisations)."""
    if not HAVE_NUMBA:  # pragma: no cover
        raise ValueError("numba is not importable")
    if es.shape[0] == 0 or cs.shape[0] == 0:
        return
    # one compiled signature only: C-contiguous, writable float64 (read-only broadcast views
    # would otherwise compile a second specialisation)
    def req(a):
        return np.require(a, dtype=np.float64, requirements=("C", "W"))

    args = [req(a) for a in (cs, ss, cr, sr, cp, sp, cpsi, spsi)]
    per = [req(a) for a in (es, cks, sks, er, ckr, skr)]
    pl = [req(a) for a in (ep, ckp, skp)]
    if out_abs is None:   # the kernel always writes both; discard the absolute ones
        out_abs = [np.empty_like(out_ave_s) for _ in range(4)]
    _numba_kernels()._stats_numba_kernel(*args, float(R), *per, *pl, float(g_s), float(g_r),
                        out_ave_s, out_dev_s, out_ave_r, out_dev_r, *out_abs)


def warmup() -> dict:
    """Compile the numba kernel once (or load it from the per-user cache) so that the first
    Monte Carlo of a run does not pay for it (``meshphase bench --warmup``).

    Returns
    -------
    dict
        ``engine`` ("numba", or "numpy" when numba is not importable: nothing to compile),
        ``seconds`` [s] the import and compilation took, ``cache_dir`` (None on numpy).
    """
    t = time.perf_counter()
    if resolve_engine("auto") != "numba":
        return {"engine": "numpy", "seconds": 0.0, "cache_dir": None}
    n_t, n_p = 2, 2
    ang = np.linspace(0.0, 1.0, n_t)
    per = [np.full(1, v) for v in (1e-5, 1.0, 0.0, 1e-5, 1.0, 0.0)]
    pl = [np.full((1, n_p), v) for v in (1e-5, 1.0, 0.0)]
    out = [np.empty((1, n_p)) for _ in range(4)]
    stats_numba(np.cos(ang), np.sin(ang), np.cos(ang), np.sin(ang), np.cos(ang), np.sin(ang),
                np.cos([0.0, np.pi]), np.sin([0.0, np.pi]), 0.1, *per, *pl, 1.0, 1.0, *out)
    if not np.all(np.isfinite(out)):   # pragma: no cover - a miscompiled kernel
        raise RuntimeError("the numba kernel gave non-finite statistics on the warm-up case")
    return {"engine": "numba", "seconds": time.perf_counter() - t,
            "cache_dir": os.environ.get("NUMBA_CACHE_DIR", numba_cache_dir())}
