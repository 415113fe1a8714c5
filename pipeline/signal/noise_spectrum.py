"""The noise power spectrum of a conditioned gauge channel, from what the pulses leave.

The timing floor of the phasing (:func:`meshphase.kinematics.passes.onset_sigma`) is the Cramer-Rao
bound of each pulse's arrival time (:mod:`meshphase.signal.crb`). In white noise the channel's
per-sample noise RMS is all it needs; 1/f noise, drift left over after conditioning or
vibration under the slow pulses of a low-speed rig put more noise into the pulses' band than
that RMS says, and the white bound is then optimistic. :func:`pulse_residual_psd` estimates
the spectrum that bound needs from the conditioned samples the run keeps (the excerpt of the
condition stage, the first minute): each pulse's window, one inter-pulse spacing long and
centred on its onset, less the pulse shape fitted to it by least squares, and one Welch
estimate (:func:`meshphase.signal.spectral.welch`, scipy.signal.welch's: Hann window, half overlap) of those residual windows
laid end to end.

The pulse shape is the synchronous average of the windows at full rate (amplitude-weighted,
aligned on the onsets to the nearest sample), so it carries the pulse's tails and the
neighbouring pulses' flanks that the detector's shorter, tapered template leaves out; each
window gets its own least-squares fit of that shape, its shift and its stretch (the detector's
amplitudes alone, fitted over the template's span, leave tens of times the white noise level
in the pulses' band; a speed change stretches the pulses). The fit takes the noise component
along those three shapes out of each window, a fraction ``g(f) = sum_j |U_j(f)|^2 / W`` of the
noise at frequency ``f`` (``U_j`` the DFTs of the orthonormal shapes over the ``W``-sample
window): the estimate is divided by ``1 - g``. The averaged shape carries ``1 / M`` of every
window's noise (``M`` windows), and fitting it takes that share out of each window at every
frequency (with the windows weighted by their amplitudes, exactly ``1 / M`` on average): the
estimate is divided by ``1 - 1 / M`` too. That is 6 % of the power for the 16 ring pulses of
a seed-rig minute; left in, it made the ring gauge's timing floor optimistic on the
independent rig's recordings (tests/independent).

What the fit cannot follow stays in the residual as if it were noise: on noise-free or very
clean data that misfit dominates, and :func:`meshphase.kinematics.passes.channel_noise_spectrum` refuses
a residual far above the channel's per-sample noise RMS.

A window holding a transient (a level step of the bridge, a knock, a cable jerk) is not
noise either: its residual energy is that of the transient, and one step of twice the pulse
height in the first minute made the sun gauge's timing floor 13x what its passes scattered
(independent rig, ``ripple1_carrier``). The residual energies of noise windows sit within a
factor of two of their median (0.6-1.7 on the same preset, coloured noise); a window above
:data:`TRANSIENT_RATIO` times the median is left out, the pulse shape is averaged again
without it, and the estimate counts what it left out (``n_excluded``). On clean data (40-60
dB) the residual is no longer noise but the fit's misfit (a first pulse shaped a little
differently, the conditioning's baseline settling, a speed ripple's stretch), which
can exceed ten times the median while being a millionth of the pulse: such a window is left
out too but counted as misfit (``n_misfit``), not as a transient, unless its excess reaches
:data:`TRANSIENT_PULSE_SHARE` of a pulse's energy (a step or a knock in the recording does).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .crb import welch_dof
from .spectral import welch
from ..validate import as_float, as_positive

__all__ = ["NoiseSpectrum", "pulse_residual_psd"]

#: fewest Welch segments an estimate is made from (fewer: none); 8 half-overlapping Hann
#: segments give nu ~ 15 degrees of freedom, a bin's relative error ~ 0.37 and the bound's
#: (the information sums many bins) well below that
MIN_SEGMENTS = 8

#: fewest pulse windows the pulse shape is averaged from [-]
MIN_PULSES = 4

#: shortest Welch segment [samples]
MIN_NPERSEG = 256

#: a pulse window whose residual energy exceeds this many times the median window's holds a
#: transient, not noise, and is left out of the estimate [-] (noise windows: 0.6-1.7)
TRANSIENT_RATIO = 10.0

#: a window left out holds a transient (a step, a knock: something in the recording) when its
#: residual energy exceeds the median's by at least this share of a pulse's energy [-]; below,
#: the excess is the pulse fit's misfit, which clean data show above their noise (the first
#: pulse of a 60-dB recording: 12x the median residual, 4e-6 of the pulse's energy), and the
#: window is left out without a warning. At 20 dB any window over TRANSIENT_RATIO passes it.
TRANSIENT_PULSE_SHARE = 1e-2

#: rounds of leaving windows out and averaging the pulse shape again [-]
_SCREEN_ROUNDS = 3


@dataclass(frozen=True, eq=False)
class NoiseSpectrum:
    """A one-sided noise power spectral density estimate.

    Attributes
    ----------
    freqs : ndarray, shape (m,)
        [Hz], from 0 to the Nyquist frequency.
    psd : ndarray, shape (m,)
        [units^2/Hz] (Welch, ``scaling="density"``).
    dof : float
        Equivalent degrees of freedom of each bin [-] (:func:`meshphase.signal.crb.welch_dof`).
    n_samples : int
        Samples the estimate used [-].
    n_pulses : int
        Pulse windows they came from [-].
    nperseg : int
        Welch segment length [samples].
    n_excluded : int
        Pulse windows left out as transients (:data:`TRANSIENT_RATIO`,
        :data:`TRANSIENT_PULSE_SHARE`) [-].
    n_misfit : int
        Pulse windows left out whose excess is the pulse fit's misfit, not a transient [-].
    """

    freqs: np.ndarray
    psd: np.ndarray
    dof: float
    n_samples: int
    n_pulses: int
    nperseg: int
    n_excluded: int = 0
    n_misfit: int = 0

    @property
    def rms(self) -> float:
        """RMS of the noise the spectrum integrates to [units]."""
        df = float(self.freqs[1] - self.freqs[0]) if self.freqs.size > 1 else 0.0
        return math.sqrt(float(np.sum(self.psd)) * df)


def pulse_residual_psd(x, fs: float, t0: float, times, *, skip: float = 0.0) -> NoiseSpectrum | None:
    """Welch estimate of a conditioned channel's noise from what its pulses leave (module
    docstring).

    Parameters
    ----------
    x : array_like, shape (n,)
        The conditioned channel [units].
    fs : float
        Sample rate [Hz].
    t0 : float
        Time of ``x[0]`` [s].
    times : array_like, shape (k,)
        The channel's onset times [s] (:attr:`meshphase.onsets.Onsets.times`, increasing);
        those whose window leaves ``x`` or meets a non-finite sample are not used.
    skip : float
        Time at the start of ``x`` to leave out [s] (filters settling).

    Returns
    -------
    NoiseSpectrum or None
        None with fewer than :data:`MIN_PULSES` usable windows or :data:`MIN_SEGMENTS`
        Welch segments of at least :data:`MIN_NPERSEG` samples.
    """
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 1:
        raise ValueError(f"x must be 1-D, got shape {x.shape}")
    fs = as_positive(fs, "fs")
    t0 = as_float(t0, "t0")
    skip = as_float(skip, "skip")
    t = np.asarray(times, dtype=np.float64)
    if t.ndim != 1:
        raise ValueError(f"times must be 1-D, got shape {t.shape}")
    t = t[np.isfinite(t)]
    if t.size < 2:
        return None
    c = np.rint((t - t0) * fs).astype(np.int64)
    step = np.diff(c)
    half = int(np.median(step[step > 0])) // 2 if np.any(step > 0) else 0
    if 2 * half < MIN_NPERSEG:
        return None
    c = c[(c - half >= max(0, int(math.ceil(skip * fs)))) & (c + half <= x.size)]
    idx = c[:, None] + np.arange(-half, half)[None, :]
    w = x[idx] if c.size else np.empty((0, 2 * half))
    w = w[np.all(np.isfinite(w), axis=1)]
    if len(w) < MIN_PULSES:
        return None
    basis, r, n_out, n_misfit = _screened_fit(w)
    if basis is None or len(r) < MIN_PULSES:
        return None
    w_used = len(r)
    r = r.ravel()
    nperseg = 1 << int(math.floor(math.log2(2 * half)))
    n_seg = (r.size - nperseg) // (nperseg // 2) + 1
    if n_seg < MIN_SEGMENTS:
        return None
    f, p = welch(r, fs, nperseg, noverlap=nperseg // 2, detrend="constant")
    g = np.sum(np.abs(np.fft.rfft(basis, axis=1)) ** 2, axis=0) / basis.shape[1]
    fg = np.fft.rfftfreq(basis.shape[1], 1.0 / fs)      # share of the noise the fit took
    p = p / (1.0 - np.clip(np.interp(f, fg, g), 0.0, 0.5))
    p = p / (1.0 - 1.0 / w_used)                       # the average's share (module notes)
    return NoiseSpectrum(f, p, welch_dof(int(n_seg)), int(r.size), int(w_used), int(nperseg),
                         int(n_out), int(n_misfit))


def _screened_fit(w: np.ndarray):
    """(basis, residual windows, transients, misfits): each window less its least-squares fit
    of the pulse basis, the windows whose residual energy exceeds
    :data:`TRANSIENT_RATIO` times the median left out and the basis averaged again without
    them, until none is left out (at most :data:`_SCREEN_ROUNDS` rounds); of those left out,
    the transients (excess of at least :data:`TRANSIENT_PULSE_SHARE` of a pulse's energy) and
    the misfits (less); basis None when the average is zero."""
    keep = np.ones(len(w), dtype=bool)
    e = med = None
    for _ in range(_SCREEN_ROUNDS):
        basis = _pulse_basis(w[keep])
        if basis is None:
            return None, w[:0], 0, 0
        r = w - (w @ basis.T) @ basis
        e = np.einsum("ij,ij->i", r, r)
        med = float(np.median(e[keep]))
        new = e <= TRANSIENT_RATIO * med if med > 0 else np.ones(len(w), dtype=bool)
        if np.array_equal(new, keep) or np.count_nonzero(new) < MIN_PULSES:
            break
        keep = new
    fit = w - r
    ep = float(np.median(np.einsum("ij,ij->i", fit[keep], fit[keep])))
    big = ~keep & (e - med >= TRANSIENT_PULSE_SHARE * ep)
    return basis, r[keep], int(np.count_nonzero(big)), int(np.count_nonzero(~keep & ~big))


def _pulse_basis(w: np.ndarray) -> np.ndarray | None:
    """Orthonormal rows spanning what a window's pulse may do: the pulse shape (the
    windows' average, each weighted by its projection on the plain average), its shift
    (time derivative) and its stretch (time times derivative, about the window's centre);
    None when the average is zero."""
    m = w.mean(axis=0)
    nm = float(np.linalg.norm(m))
    if not nm > 0:
        return None
    h = (w @ (m / nm)) @ w
    dh = np.gradient(h)
    u = np.arange(h.size) - 0.5 * (h.size - 1)
    q, r = np.linalg.qr(np.stack([h, dh, u * dh], axis=1))
    keep = np.abs(np.diag(r)) > 1e-12 * max(float(np.abs(r[0, 0])), 1e-300)
    return q[:, keep].T if keep[0] else None
