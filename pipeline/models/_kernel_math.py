"""Scalar building blocks of the Monte Carlo kernel, written so that numba compiles them
(:mod:`meshphase.models._kernels_numba`) and Python runs them as the reference the tests hold
the compiled kernel to.

Their own module, below both kernel modules: :mod:`._kernels` (which imports the numba build
lazily) and :mod:`._kernels_numba` (which compiles these) both import from here.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["atan_cephes", "mean_range"]

# Cephes atan (S. L. Moshier), rational approximation on |x| <= 0.66 with two argument
# reductions, written branch-free (selects) so that the time loop vectorises: <= 1 ulp
# against libm on 1e7 random arguments over 1e-5 .. 1e4 (measured); libm's atan2 is not
# vectorised.
_T3P8 = 2.41421356237309504880      # tan(3 pi / 8)
_MOREBITS = 6.123233995736765886130e-17
_PIO2 = np.pi / 2
_PIO4 = np.pi / 4
_P = (-8.750608600031904122785e-1, -1.615753718733365076637e1, -7.500855792314704667340e1,
      -1.228866684490136173410e2, -6.485021904942025371773e1)
_Q = (2.485846490142306297962e1, 1.650270098316988542046e2, 4.328810604912902668951e2,
      4.853903996359136964868e2, 1.945506571482613964425e2)


def atan_cephes(x):
    """Scalar atan(x) [rad] with the branch-free Cephes algorithm (reference for the kernel)."""
    a = abs(x)
    big = a > _T3P8
    mid = a > 0.66
    n1 = 0.0 if big else 1.0
    n0 = 1.0 if mid else 0.0
    d1 = 1.0 if mid else 0.0
    d0 = 0.0 if big else 1.0
    # big: -1/a, mid: (a - 1)/(a + 1), small: a / 1 (exact), with a single division
    xr = (a * n1 - n0) / (a * d1 + d0)
    y0 = _PIO2 if big else (_PIO4 if mid else 0.0)
    mb = _MOREBITS if big else (0.5 * _MOREBITS if mid else 0.0)
    z = xr * xr
    p = (((_P[0] * z + _P[1]) * z + _P[2]) * z + _P[3]) * z + _P[4]
    q = ((((z + _Q[0]) * z + _Q[1]) * z + _Q[2]) * z + _Q[3]) * z + _Q[4]
    r = xr * (z * p / q) + xr
    r = y0 + (r + mb)
    return math.copysign(r, x)


def mean_range(v):
    """(sum / n, max - min) of a 1-D array in one pass (the kernel's reduction, as Python)."""
    sm = 0.0
    mn = np.inf
    mx = -np.inf
    for k in range(v.shape[0]):
        x = v[k]
        sm += x
        mn = min(mn, x)
        mx = max(mx, x)
    return sm / v.shape[0], mx - mn
