"""Second-order-section designs of the conditioning's filters: Butterworth band-, high- and
low-pass, mains notches, and the sections' steady-state initial conditions.

These are :func:`scipy.signal.butter` (``output="sos"``), :func:`scipy.signal.iirnotch` with
:func:`scipy.signal.tf2sos`, and :func:`scipy.signal.sosfilt_zi`, restated for the three
designs the pipeline uses so that ``meshphase process`` does not import ``scipy.signal``:
that package imports ``scipy.stats`` (through ``find_peaks_cwt``), and the two cost a
noticeable part of every run's start (``meshphase bench processing``, start-up table: the
``import meshphase.run.stages, scipy.signal`` row against the row above it; README.md) for a
few closed-form designs. The Butterworth path is scipy's own, step for step (analogue
prototype, frequency transform, bilinear transform with pre-warping, scipy's
``zpk2sos(pairing="nearest")`` pairing and ordering; scipy 1.17, BSD-3-Clause), so the
sections are scipy's to rounding (tests/processing/test_dsp_designs.py compares them across orders
1-12 and the whole usable band). The notch biquad is written in its normalised form
as scipy writes it, then taken through its roots into a section as ``tf2sos`` does.

Frequencies are in hertz at a sample rate ``fs`` [Hz]; every design is checked and raises
ValueError with the offending value.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["butter_sos", "notch_sos", "sosfilt_zi"]

_KINDS = ("lowpass", "highpass", "bandpass")


def _positive(v, what: str) -> float:
    """``v`` as a positive, finite float; ValueError naming ``what`` otherwise."""
    try:
        f = float(v)
    except (TypeError, ValueError):
        f = float("nan")
    if not (f > 0 and math.isfinite(f)):
        raise ValueError(f"{what} must be positive and finite, got {v!r}")
    return f


def _check_fs(fs) -> float:
    return _positive(fs, "fs (the sample rate [Hz])")


def _check_corner(f, fs: float, what: str) -> float:
    try:
        f = float(f)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be a frequency [Hz], got {f!r}") from None
    if not 0.0 < f < 0.5 * fs:
        raise ValueError(f"{what} must lie strictly between 0 and fs/2 = {0.5 * fs!r} Hz, got {f!r}")
    return f


def _cplxreal(z: np.ndarray, tol: float = 100 * np.finfo(np.float64).eps):
    """Complex values with positive imaginary part (one of each conjugate pair, sorted by
    real part) and the real values (sorted): scipy's ``_cplxreal`` for one 1-d array."""
    z = np.atleast_1d(np.asarray(z, dtype=np.complex128))
    if z.size == 0:
        return z, z.real
    z = z[np.lexsort((abs(z.imag), z.real))]
    real = abs(z.imag) <= tol * abs(z)
    zr = z[real].real
    if real.all():
        return np.array([], dtype=np.complex128), zr
    z = z[~real]
    zp = z[z.imag > 0]
    zn = z[z.imag < 0]
    if len(zp) != len(zn):
        raise ValueError("a complex root has no matching conjugate")
    same_real = np.diff(zp.real) <= tol * abs(zp[:-1])
    diffs = np.diff(np.concatenate(([0], same_real, [0])))
    for start, stop in zip(np.nonzero(diffs > 0)[0], np.nonzero(diffs < 0)[0] + 1):
        for chunk in (zp[start:stop], zn[start:stop]):
            chunk[...] = chunk[np.lexsort([abs(chunk.imag)])]
    if np.any(abs(zp - zn.conj()) > tol * abs(zn)):
        raise ValueError("a complex root has no matching conjugate")
    return (zp + zn.conj()) / 2, zr


def _nearest(fro: np.ndarray, to: complex, which: str) -> int:
    """Index in ``fro`` of the value nearest ``to`` among the real, complex or any."""
    order = np.argsort(np.abs(fro - to))
    if which == "any":
        return int(order[0])
    mask = np.isreal(fro[order])
    if which == "complex":
        mask = ~mask
    return int(order[np.nonzero(mask)[0][0]])


def _section(z, p) -> np.ndarray:
    """One section [b0 b1 b2 1 a1 a2] with unit gain from up to two zeros and poles."""
    sos = np.zeros(6)
    b = np.real(np.poly(z)) if len(z) else np.ones(1)
    a = np.real(np.poly(p)) if len(p) else np.ones(1)
    sos[3 - len(b):3] = b
    sos[6 - len(a):6] = a
    return sos


def _zpk2sos(z: np.ndarray, p: np.ndarray, k: float) -> np.ndarray:
    """Sections of a digital filter given by zeros, poles and gain: scipy's ``zpk2sos``
    with ``pairing="nearest"``. The poles nearest the unit circle go into the last
    section, each pole pair takes the zeros nearest it, the gain goes into the first."""
    p = np.concatenate((p, np.zeros(max(len(z) - len(p), 0))))
    z = np.concatenate((z, np.zeros(max(len(p) - len(z), 0))))
    n_sections = (max(len(p), len(z)) + 1) // 2
    if len(p) % 2 == 1:
        p = np.concatenate((p, [0.0]))
        z = np.concatenate((z, [0.0]))
    z = np.concatenate(_cplxreal(z))
    p = np.concatenate(_cplxreal(p))

    def idx_worst(q):
        return int(np.argmin(np.abs(1 - np.abs(q))))

    sos = np.zeros((n_sections, 6))
    for si in range(n_sections - 1, -1, -1):
        i1 = idx_worst(p)
        p1 = p[i1]
        p = np.delete(p, i1)
        if np.isreal(p1) and np.isreal(p).sum() == 0:
            iz = _nearest(z, p1, "real")
            z1 = z[iz]
            z = np.delete(z, iz)
            sos[si] = _section([z1, 0], [p1, 0])
        elif (len(p) + 1 == len(z) and not np.isreal(p1) and np.isreal(p).sum() == 1
              and np.isreal(z).sum() == 1):
            iz = _nearest(z, p1, "complex")
            z1 = z[iz]
            z = np.delete(z, iz)
            sos[si] = _section([z1, z1.conj()], [p1, p1.conj()])
        else:
            if np.isreal(p1):
                real_idx = np.flatnonzero(np.isreal(p))
                i2 = int(real_idx[idx_worst(p[real_idx])])
                p2 = p[i2]
                p = np.delete(p, i2)
            else:
                p2 = p1.conj()
            if len(z):
                iz = _nearest(z, p1, "any")
                z1 = z[iz]
                z = np.delete(z, iz)
                if not np.isreal(z1):
                    sos[si] = _section([z1, z1.conj()], [p1, p2])
                elif len(z):
                    iz = _nearest(z, p1, "real")
                    z2 = z[iz]
                    z = np.delete(z, iz)
                    sos[si] = _section([z1, z2], [p1, p2])
                else:
                    sos[si] = _section([z1], [p1, p2])
            else:
                sos[si] = _section([], [p1, p2])
    sos[0][:3] *= k
    return sos


def butter_sos(order: int, cutoff, kind: str, fs: float) -> np.ndarray:
    """Digital Butterworth filter as second-order sections:
    ``scipy.signal.butter(order, cutoff, btype=kind, fs=fs, output="sos")``.

    Parameters
    ----------
    order : int
        Filter order (>= 1); a band-pass has twice as many poles.
    cutoff : float or (float, float)
        The -3 dB corner [Hz] (low- and high-pass) or the two corners, low then high
        [Hz] (band-pass); each strictly between 0 and ``fs / 2``.
    kind : {"lowpass", "highpass", "bandpass"}
    fs : float
        Sample rate [Hz].

    Returns
    -------
    sos : ndarray, shape (n_sections, 6)
        Rows [b0 b1 b2 1 a1 a2]; ``ceil(order / 2)`` rows (low-/high-pass) or ``order``
        rows (band-pass).

    Raises
    ------
    ValueError
        A non-positive or non-integer order, an unknown kind, corners outside (0, fs/2)
        or not increasing, the wrong number of corners for ``kind``.
    """
    if isinstance(order, bool) or not isinstance(order, (int, np.integer)) or order < 1:
        raise ValueError(f"order must be a positive integer, got {order!r}")
    order = int(order)
    if kind not in _KINDS:
        raise ValueError(f"kind must be one of {list(_KINDS)}, got {kind!r}")
    fs = _check_fs(fs)
    corners = np.atleast_1d(np.asarray(cutoff, dtype=object))
    want = 2 if kind == "bandpass" else 1
    if corners.ndim != 1 or corners.size != want:
        raise ValueError(f"a {kind} needs {want} corner frequenc{'ies' if want == 2 else 'y'} "
                         f"[Hz], got {cutoff!r}")
    wn = np.array([_check_corner(f, fs, "cutoff") for f in corners]) / (fs / 2)
    if want == 2 and not wn[0] < wn[1]:
        raise ValueError(f"the band's corners must increase, got {cutoff!r}")
    # analogue prototype: poles on the left half of the unit circle, no zeros, unit gain
    m = np.arange(-order + 1, order, 2, dtype=np.float64)
    p = -np.exp(1j * np.pi * m / (2 * order))
    z = np.empty(0, dtype=np.complex128)
    k = 1.0
    warped = 2 * 2.0 * np.tan(np.pi * wn / 2.0)      # pre-warped corners (fs = 2 convention)
    degree = len(p) - len(z)
    if kind == "lowpass":
        wo = float(warped[0])
        z, p, k = wo * z, wo * p, k * wo ** degree
    elif kind == "highpass":
        wo = float(warped[0])
        k = k * np.real(np.prod(-z) / np.prod(-p))
        z = np.concatenate((wo / z, np.zeros(degree)))
        p = wo / p
    else:
        bw = float(warped[1] - warped[0])
        wo = float(np.sqrt(warped[0] * warped[1]))
        z_lp = (z * bw / 2).astype(np.complex128)
        p_lp = (p * bw / 2).astype(np.complex128)
        z = np.concatenate((z_lp + np.sqrt(z_lp ** 2 - wo ** 2), z_lp - np.sqrt(z_lp ** 2 - wo ** 2),
                            np.zeros(degree)))
        p = np.concatenate((p_lp + np.sqrt(p_lp ** 2 - wo ** 2), p_lp - np.sqrt(p_lp ** 2 - wo ** 2)))
        k = k * bw ** degree
    # bilinear transform at fs = 2
    fs2 = 4.0
    degree = len(p) - len(z)
    k = k * np.real(np.prod(fs2 - z) / np.prod(fs2 - p))
    z = np.concatenate(((fs2 + z) / (fs2 - z), -np.ones(degree)))
    p = (fs2 + p) / (fs2 - p)
    return _zpk2sos(z, p, float(k))


def notch_sos(freqs, q: float, fs: float) -> np.ndarray:
    """Cascade of mains notches, one biquad per line: ``scipy.signal.tf2sos(
    *scipy.signal.iirnotch(f, q, fs=fs))`` stacked over ``freqs``.

    Each biquad has unit gain away from its line, a zero pair on the unit circle at the
    line and a -3 dB width of ``f / q``.

    Parameters
    ----------
    freqs : sequence of float
        Lines to remove [Hz], each strictly between 0 and ``fs / 2``.
    q : float
        Quality factor (> 0) [-].
    fs : float
        Sample rate [Hz].

    Returns
    -------
    sos : ndarray, shape (len(freqs), 6)

    Raises
    ------
    ValueError
        No line, a line outside (0, fs/2), a non-positive ``q`` or ``fs``.
    """
    fs = _check_fs(fs)
    q = _positive(q, "q (the quality factor)")
    freqs = [_check_corner(f, fs, "a notch line") for f in np.atleast_1d(np.asarray(freqs, dtype=object))]
    if not freqs:
        raise ValueError("notch_sos needs at least one line [Hz], got none")
    rows = []
    for f in freqs:
        w0 = 2 * f / fs
        beta = math.tan(w0 / q * math.pi / 2.0)
        gain = 1.0 / (1.0 + beta)
        c = math.cos(w0 * math.pi)
        b = np.array([gain, -2.0 * gain * c, gain])
        a = np.array([1.0, -2.0 * gain * c, 2.0 * gain - 1.0])
        # tf2sos: zeros of the monic numerator, poles, gain b0 (the coefficients to rounding)
        rows.append(_zpk2sos(np.roots(b / b[0]), np.roots(a), float(b[0])))
    return np.concatenate(rows)


def sosfilt_zi(sos) -> np.ndarray:
    """Initial conditions of each section for the step response's steady state:
    ``scipy.signal.sosfilt_zi(sos)``.

    Parameters
    ----------
    sos : array_like, shape (n_sections, 6)
        Sections with a0 = 1 (column 3) and no pole at z = 1.

    Returns
    -------
    zi : ndarray, shape (n_sections, 2)
        Scaled by the DC gain of the sections before each, as scipy does: ``zi * x[0]``
        starts a filter on a constant ``x[0]`` in its steady state.

    Raises
    ------
    ValueError
        ``sos`` not of shape (n, 6) with n >= 1, a0 not 1, not finite, or a section with a
        pole at z = 1 (no steady state).
    """
    sos = np.asarray(sos, dtype=np.float64)
    if sos.ndim != 2 or sos.shape[1] != 6 or sos.shape[0] == 0:
        raise ValueError(f"sos must have shape (n_sections, 6) with n_sections >= 1, got {sos.shape}")
    if not np.all(np.isfinite(sos)) or not np.all(sos[:, 3] == 1.0):
        raise ValueError("sos must be finite with a0 (column 3) = 1 in every section")
    zi = np.empty((sos.shape[0], 2))
    scale = 1.0
    for i, (b0, b1, b2, _, a1, a2) in enumerate(sos):
        # (I - A^T) zi = b[1:] - a[1:] b0, A the companion matrix of [1, a1, a2]
        m = np.array([[1.0 + a1, -1.0], [a2, 1.0]])
        try:
            zi[i] = scale * np.linalg.solve(m, np.array([b1 - a1 * b0, b2 - a2 * b0]))
        except np.linalg.LinAlgError:
            raise ValueError(f"section {i} has a pole at z = 1: no steady state") from None
        scale *= (b0 + b1 + b2) / (1.0 + a1 + a2)
    return zi
