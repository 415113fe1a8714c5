"""The numba build of the Monte Carlo kernel (:func:`meshphase.models._kernels.stats_numba`).

Imported only when a Monte Carlo runs on the numba engine, so that importing the models (and
processing a recording) does not load numba and LLVM. Compiled functions are cached
(``cache=True``) in the per-user directory :func:`meshphase.runtime.numba_cache.numba_cache_dir`
names unless ``NUMBA_CACHE_DIR`` is set (``meshphase bench --warmup`` fills it).
"""

from __future__ import annotations

import numba as _numba
import numpy as np

from ._kernel_math import atan_cephes, mean_range

_atan = _numba.njit(inline="always", cache=True)(atan_cephes)
_mean_range = _numba.njit(inline="always", cache=True)(mean_range)

@_numba.njit(parallel=True, cache=True, fastmath=False, nogil=True)
def _stats_numba_kernel(cs, ss, cr, sr, cp, sp, cpsi, spsi, R, es, cks, sks, er, ckr, skr,
                        ep, ckp, skp, g_s, g_r, out_ave_s, out_dev_s, out_ave_r,
                        out_dev_r, abs_ave_s, abs_dev_s, abs_ave_r,
                        abs_dev_r):  # pragma: no cover - compiled
    n_s = es.shape[0]
    n_t = cs.shape[0]
    n_p = cpsi.shape[0]
    for i in _numba.prange(n_s):
        cas = np.empty(n_t)
        sas = np.empty(n_t)
        car = np.empty(n_t)
        sar = np.empty(n_t)
        d1s = np.empty(n_t)
        d1r = np.empty(n_t)
        vs = np.empty(n_t)
        vr = np.empty(n_t)
        ws = np.empty(n_t)
        wr = np.empty(n_t)
        a1 = cks[i]
        b1 = sks[i]
        a2 = ckr[i]
        b2 = skr[i]
        for k in range(n_t):
            cas[k] = cs[k] * a1 - ss[k] * b1
            sas[k] = ss[k] * a1 + cs[k] * b1
            car[k] = cr[k] * a2 - sr[k] * b2
            sar[k] = sr[k] * a2 + cr[k] * b2
        esi = es[i]
        eri = er[i]
        for n in range(n_p):
            c_k = ckp[i, n]
            s_k = skp[i, n]
            e = ep[i, n]
            cps = cpsi[n]
            sps = spsi[n]
            for k in range(n_t):
                ct = cp[k] * c_k - sp[k] * s_k
                st = sp[k] * c_k + cp[k] * s_k
                px = R - e * ct
                py = -(e * st)
                crel = cas[k] * cps + sas[k] * sps
                srel = sas[k] * cps - cas[k] * sps
                # x > 0 (e_s + e_p < R_c), so atan2(y, x) = atan(y / x)
                d_s = _atan((py - esi * srel) / (px - esi * crel))
                crel = car[k] * cps + sar[k] * sps
                srel = sar[k] * cps - car[k] * sps
                d_r = _atan((py - eri * srel) / (px - eri * crel))
                if n == 0:
                    d1s[k] = d_s
                    d1r[k] = d_r
                vs[k] = g_s * (d_s - d1s[k])
                vr[k] = g_r * (d_r - d1r[k])
                ws[k] = g_s * d_s
                wr[k] = g_r * d_r
            out_ave_s[i, n], out_dev_s[i, n] = _mean_range(vs)
            out_ave_r[i, n], out_dev_r[i, n] = _mean_range(vr)
            abs_ave_s[i, n], abs_dev_s[i, n] = _mean_range(ws)
            abs_ave_r[i, n], abs_dev_r[i, n] = _mean_range(wr)
