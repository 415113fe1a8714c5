"""The numba build of :mod:`meshphase.signal.iir`'s second-order-section recursion.

Imported only when :func:`meshphase.signal.iir.sosfiltfilt` takes the numba engine, so that
importing the conditioning (and filtering a short recording) does not load numba and LLVM.
Compiled with ``cache=True`` into the per-user directory
:func:`meshphase.runtime.numba_cache.numba_cache_dir` names (``meshphase bench --warmup`` fills it),
``nogil``: the channels' chains filter side by side on threads.

The arithmetic is that of :func:`scipy.signal.sosfilt` (transposed direct form II), in its
order, each section's statement for statement; ``fastmath`` stays off, so nothing is fused
or reassociated. What differs is the order of the loops: scipy runs every section for one
sample before the next sample, with the section states in memory; here two sections go
together through all the samples with their four states in registers. A section's output
depends only on its input sequence and its own state, so the outputs are the same numbers;
the two sections' recursions are independent chains the processor overlaps, which is where
the speed comes from (a single section's recursion is latency-bound).
"""

from __future__ import annotations

import numba as _numba


@_numba.njit(cache=True, nogil=True)
def _pair(sos, s, x, z, reverse):  # pragma: no cover - compiled
    """Sections ``s`` and ``s + 1`` of ``sos`` run over ``x`` in place (backwards with
    ``reverse``), from and into the states ``z[s]``, ``z[s + 1]``."""
    b10, b11, b12, a11, a12 = sos[s, 0], sos[s, 1], sos[s, 2], sos[s, 4], sos[s, 5]
    b20, b21, b22, a21, a22 = (sos[s + 1, 0], sos[s + 1, 1], sos[s + 1, 2], sos[s + 1, 4],
                               sos[s + 1, 5])
    z10, z11, z20, z21 = z[s, 0], z[s, 1], z[s + 1, 0], z[s + 1, 1]
    n = x.shape[0]
    for k in range(n):
        i = n - 1 - k if reverse else k
        xc = x[i]
        y1 = b10 * xc + z10
        z10 = b11 * xc - a11 * y1 + z11
        z11 = b12 * xc - a12 * y1
        y2 = b20 * y1 + z20
        z20 = b21 * y1 - a21 * y2 + z21
        z21 = b22 * y1 - a22 * y2
        x[i] = y2
    z[s, 0], z[s, 1], z[s + 1, 0], z[s + 1, 1] = z10, z11, z20, z21


@_numba.njit(cache=True, nogil=True)
def _single(sos, s, x, z, reverse):  # pragma: no cover - compiled
    """Section ``s`` alone (the last of an odd count), as :func:`_pair`."""
    b0, b1, b2, a1, a2 = sos[s, 0], sos[s, 1], sos[s, 2], sos[s, 4], sos[s, 5]
    z0, z1 = z[s, 0], z[s, 1]
    n = x.shape[0]
    for k in range(n):
        i = n - 1 - k if reverse else k
        xc = x[i]
        y = b0 * xc + z0
        z0 = b1 * xc - a1 * y + z1
        z1 = b2 * xc - a2 * y
        x[i] = y
    z[s, 0], z[s, 1] = z0, z1


@_numba.njit(cache=True, nogil=True)
def cascade(sos, x, z, reverse):  # pragma: no cover - compiled
    """Every section of ``sos`` (shape (n_sections, 6), a0 = 1) over the float64 samples
    ``x`` in place, forwards or (``reverse``) backwards; ``z`` (n_sections, 2): the initial
    states in, the final states out."""
    n_sec = sos.shape[0]
    s = 0
    while s + 1 < n_sec:
        _pair(sos, s, x, z, reverse)
        s += 2
    if s < n_sec:
        _single(sos, s, x, z, reverse)


@_numba.njit(cache=True, nogil=True)
def _pair2(sa, sb, s, xa, xb, za, zb, reverse):  # pragma: no cover - compiled
    """Sections ``s`` and ``s + 1`` of ``sa`` over ``xa`` and of ``sb`` over ``xb`` (of
    equal length) in one sweep, as :func:`_pair` does each: four independent recursions."""
    a10, a11, a12, a14, a15 = sa[s, 0], sa[s, 1], sa[s, 2], sa[s, 4], sa[s, 5]
    a20, a21, a22, a24, a25 = sa[s + 1, 0], sa[s + 1, 1], sa[s + 1, 2], sa[s + 1, 4], sa[s + 1, 5]
    b10, b11, b12, b14, b15 = sb[s, 0], sb[s, 1], sb[s, 2], sb[s, 4], sb[s, 5]
    b20, b21, b22, b24, b25 = sb[s + 1, 0], sb[s + 1, 1], sb[s + 1, 2], sb[s + 1, 4], sb[s + 1, 5]
    p10, p11, p20, p21 = za[s, 0], za[s, 1], za[s + 1, 0], za[s + 1, 1]
    q10, q11, q20, q21 = zb[s, 0], zb[s, 1], zb[s + 1, 0], zb[s + 1, 1]
    n = xa.shape[0]
    for k in range(n):
        i = n - 1 - k if reverse else k
        u = xa[i]
        v = xb[i]
        y1 = a10 * u + p10
        p10 = a11 * u - a14 * y1 + p11
        p11 = a12 * u - a15 * y1
        w1 = b10 * v + q10
        q10 = b11 * v - b14 * w1 + q11
        q11 = b12 * v - b15 * w1
        y2 = a20 * y1 + p20
        p20 = a21 * y1 - a24 * y2 + p21
        p21 = a22 * y1 - a25 * y2
        w2 = b20 * w1 + q20
        q20 = b21 * w1 - b24 * w2 + q21
        q21 = b22 * w1 - b25 * w2
        xa[i] = y2
        xb[i] = w2
    za[s, 0], za[s, 1], za[s + 1, 0], za[s + 1, 1] = p10, p11, p20, p21
    zb[s, 0], zb[s, 1], zb[s + 1, 0], zb[s + 1, 1] = q10, q11, q20, q21


@_numba.njit(cache=True, nogil=True)
def cascade2(sa, sb, xa, xb, za, zb, reverse):  # pragma: no cover - compiled
    """:func:`cascade` of two channels at once: ``sa`` over ``xa`` and ``sb`` over ``xb``,
    of equal length and equal section count, two sections of each per sweep."""
    n_sec = sa.shape[0]
    s = 0
    while s + 1 < n_sec:
        _pair2(sa, sb, s, xa, xb, za, zb, reverse)
        s += 2
    if s < n_sec:
        _single(sa, s, xa, za, reverse)
        _single(sb, s, xb, zb, reverse)
