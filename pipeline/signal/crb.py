"""Cramer-Rao bound on the arrival time of a known pulse in Gaussian noise: white
(:func:`crb_delay_std`) or coloured with a known power spectral density
(:func:`crb_delay_std_psd`).

Used to hold the onset detector (:mod:`meshphase.onsets`) against the physical limit, and as
the timing floor of the phasing's reliability judgement (:mod:`meshphase.kinematics.passes`).

Model: samples ``x[n] = A s(t_n - tau) + b + w[n]``, ``w[n]`` white Gaussian with variance
``sigma^2``, pulse shape ``s`` known. The Fisher information of the delay ``tau`` is

    J_tau = (1 / sigma^2) * sum_n (d/dtau A s(t_n - tau))^2 = (1 / sigma^2) * sum_n (A s'(t_n - tau))^2

so any unbiased estimator has ``var(tau_hat) >= sigma^2 / sum_n (A s'(t_n - tau))^2``
(Kay, Fundamentals of Statistical Signal Processing, Vol. I: Estimation Theory, 1993,
eq. 3.14 for a signal in WGN and Example 3.13 "range estimation", whose continuous form is
``var >= 1 / ((E / (N0/2)) F^2)`` with ``F^2`` the mean-square bandwidth; Van Trees,
Detection, Estimation and Modulation Theory, Part I, ch. 2.4 and 6).

When the amplitude ``A`` and the baseline ``b`` are unknown too (they are: amplitudes vary
per planet and with load), the bound on ``tau`` is the ``(tau, tau)`` element of the
inverse 3x3 Fisher matrix with columns ``A s'``, ``s`` and ``1``. For a pulse that starts and
ends at its baseline, ``sum s s' = 0`` and ``sum s' = 0``, so the nuisance parameters cost
nothing and the simple bound holds; :func:`crb_delay_std` computes the full version when
``pulse`` is given.

An estimator using a template learnt from ``M`` noisy pulses (rather than the true shape)
carries roughly ``(1 + 1/M)`` times the variance of this bound.

Coloured noise (:func:`crb_delay_std_psd`): for stationary Gaussian noise of one-sided power
spectral density ``S(f)`` [units^2/Hz] and a record long against the pulse and the noise's
correlation time, the Fisher information of the delay is (Whittle's asymptotic form; Kay 1993,
sec. 3.11 and eq. 3.30 for a signal in coloured noise)

    J_tau = 4 * int_0^inf |2 pi f P(f)|^2 / S(f) df,

``P(f)`` the Fourier transform of the pulse [units s], so ``2 pi f P(f)`` is that of its
time derivative. White noise of variance ``sigma^2`` per sample at rate ``fs`` has
``S = 2 sigma^2 / fs`` and Parseval turns this into ``sum_n (A s'(t_n))^2 / sigma^2``, the
bound above. Noise that is stronger in the pulse's band than its per-sample variance says
(1/f noise under slow pulses) makes the bound larger.
"""

from __future__ import annotations

import math

import numpy as np

from ..validate import as_nonnegative, as_positive

__all__ = ["crb_delay_std", "crb_delay_std_psd", "welch_dof"]


def crb_delay_std(derivative, sigma: float, *, pulse=None) -> np.ndarray | float:
    """Cramer-Rao lower bound on the standard deviation of a pulse delay estimate.

    Parameters
    ----------
    derivative : array_like, shape (..., n)
        ``d/dtau`` of the noise-free pulse ``A s(t_n - tau)`` at the sample instants, i.e.
        ``-A s'(t_n - tau)`` [units per time unit]; the sign does not matter. Leading axes
        index independent pulses. The time unit of the result is the one used here: pass
        the derivative per sample to get the bound in samples, per second for seconds.
    sigma : float
        Standard deviation of the white Gaussian noise per sample [units].
    pulse : array_like, shape (..., n), optional
        The noise-free pulse ``A s(t_n - tau)`` itself [units]; when given, the amplitude
        and baseline are treated as unknown nuisance parameters (3x3 Fisher matrix).

    Returns
    -------
    float or ndarray, shape (...)
        Lower bound on ``std(tau_hat)`` [time unit of ``derivative``]; ``inf`` where the
        pulse carries no information (zero derivative or empty), 0 where ``sigma == 0``.

    Notes
    -----
    ``var(tau_hat) >= sigma^2 / sum_n (ds/dtau)^2`` (Kay 1993, eq. 3.14 / Example 3.13);
    see the module docstring for the nuisance-parameter form.
    """
    sigma = as_nonnegative(sigma, "sigma")
    d = np.asarray(derivative, dtype=np.float64)
    if d.ndim == 0:
        raise ValueError(f"derivative must be at least 1-D (samples on the last axis), got shape {d.shape}")
    if d.size and not np.all(np.isfinite(d)):
        raise ValueError("derivative must be finite")
    if pulse is None:
        info = np.sum(d * d, axis=-1)
    else:
        s = np.asarray(pulse, dtype=np.float64)
        if s.shape != d.shape:
            raise ValueError(f"pulse shape {s.shape} must equal derivative shape {d.shape}")
        if s.size and not np.all(np.isfinite(s)):
            raise ValueError("pulse must be finite")
        one = np.ones_like(d)
        g = np.stack([d, s, one], axis=-1)                       # (..., n, 3)
        j = np.einsum("...ni,...nj->...ij", g, g)                # (..., 3, 3)
        # Schur complement: J_tt - J_tn J_nn^-1 J_nt
        jnn = j[..., 1:, 1:]
        jtn = j[..., 0, 1:]
        det = jnn[..., 0, 0] * jnn[..., 1, 1] - jnn[..., 0, 1] * jnn[..., 1, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = np.stack([np.stack([jnn[..., 1, 1], -jnn[..., 0, 1]], -1),
                            np.stack([-jnn[..., 1, 0], jnn[..., 0, 0]], -1)], -2) / det[..., None, None]
            corr = np.einsum("...i,...ij,...j->...", jtn, inv, jtn)
        info = j[..., 0, 0] - np.where(np.isfinite(corr), corr, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.where(info > 0, sigma / np.sqrt(np.where(info > 0, info, 1.0)), np.inf)
    if sigma == 0.0:
        out = np.where(info > 0, 0.0, np.inf)
    return float(out) if np.ndim(out) == 0 else out


def welch_dof(n_segments: int, overlap: float = 0.5) -> float:
    """Equivalent degrees of freedom of a Welch PSD estimate with a Hann window [-].

    ``nu = 2 K / (1 + 2 rho^2)`` for ``K`` segments overlapping by half, ``rho = 0.167`` the
    correlation of the Hann-windowed periodograms of two half-overlapping segments
    (Welch 1967, IEEE Trans. Audio Electroacoust. 15(2), eq. 13 and Table 1; Percival and
    Walden 1993, sec. 6.17); without overlap ``nu = 2 K``. Each bin of the estimate is then
    ``S(f) chi^2_nu / nu`` distributed.

    Parameters
    ----------
    n_segments : int
        Segments averaged, K >= 1.
    overlap : {0.5, 0.0}
        Fraction of a segment shared with the next.

    Returns
    -------
    float
    """
    if isinstance(n_segments, bool) or not isinstance(n_segments, (int, np.integer)):
        raise TypeError(f"n_segments must be an int, got {type(n_segments).__name__} {n_segments!r}")
    if n_segments < 1:
        raise ValueError(f"n_segments must be >= 1, got {n_segments!r}")
    if overlap not in (0.0, 0.5):
        raise ValueError(f"overlap must be 0.0 or 0.5 (Hann weights known), got {overlap!r}")
    k = int(n_segments)
    if overlap == 0.0 or k == 1:
        return 2.0 * k
    rho = 0.167
    return 2.0 * k / (1.0 + 2.0 * rho * rho * (k - 1) / k)


def crb_delay_std_psd(derivative, rate: float, freqs, psd, *, dof: float | None = None,
                      band_fraction: float = 1e-6) -> float:
    """Cramer-Rao lower bound on the standard deviation of a pulse delay estimate in
    stationary Gaussian noise of a given power spectral density (module docstring).

    Parameters
    ----------
    derivative : array_like, shape (n,)
        ``d/dtau`` of the noise-free pulse at its sample instants [units per time unit], at
        ``rate`` samples per second (the template's rate may be below the data's: the bound
        depends on the pulse's spectrum, not on how it is sampled, as long as it is
        sampled above twice its bandwidth). The time unit is the result's, as in
        :func:`crb_delay_std`.
    rate : float
        Sample rate of ``derivative`` [Hz].
    freqs : array_like, shape (m,)
        Frequencies of the PSD estimate [Hz], increasing, from 0 (a one-sided
        :func:`scipy.signal.welch` grid).
    psd : array_like, shape (m,)
        One-sided noise power spectral density at ``freqs`` [units^2/Hz] (``scaling =
        "density"``), interpolated linearly in between; above ``freqs[-1]`` and where it is
        not positive the pulse is taken to carry no information.
    dof : float, optional
        Equivalent degrees of freedom ``nu`` of the PSD estimate (:func:`welch_dof`): the
        information is multiplied by ``(nu - 2) / nu``, since ``E[1 / S_hat] = nu / (nu - 2)
        / S`` for a ``chi^2_nu`` estimate. None: the PSD is taken as exact.
    band_fraction : float
        Frequencies where the pulse's derivative spectrum ``|D(f)|^2`` is below this
        fraction of its maximum are left out [-]: there the pulse carries no timing
        information and ``S`` of a low-passed channel (the conditioned data) falls to its
        stop band, so their ratio would only measure the template's own noise.

    Returns
    -------
    float
        [time unit of ``derivative``]; ``inf`` when the pulse carries no information in the
        band of ``psd`` (zero derivative, empty input).

    Notes
    -----
    The derivative is zero-padded to at least 4 times its length and the PSD's resolution
    so that the sum over its FFT bins follows ``int |D|^2 / S df``. For ``S = 2 sigma^2 /
    rate_data`` (white) the result equals ``crb_delay_std(derivative, sigma) /
    sqrt(rate_data / rate)`` up to ``band_fraction``.
    """
    d = np.asarray(derivative, dtype=np.float64)
    if d.ndim != 1:
        raise ValueError(f"derivative must be 1-D, got shape {d.shape}")
    if d.size and not np.all(np.isfinite(d)):
        raise ValueError("derivative must be finite")
    rate = as_positive(rate, "rate")
    f = np.asarray(freqs, dtype=np.float64)
    s = np.asarray(psd, dtype=np.float64)
    if f.ndim != 1 or s.shape != f.shape:
        raise ValueError(f"freqs and psd must be 1-D of one length, got shapes {f.shape} and {s.shape}")
    if f.size and not (np.all(np.isfinite(f)) and np.all(np.diff(f) > 0) and f[0] >= 0):
        raise ValueError("freqs must be finite, non-negative and increasing")
    if s.size and np.any(np.isnan(s)):
        raise ValueError("psd must not be NaN")
    if dof is not None:
        dof = as_positive(dof, "dof")
        if dof <= 2.0:
            raise ValueError(f"dof must exceed 2 (1 / S_hat has no mean otherwise), got {dof!r}")
    band_fraction = as_nonnegative(band_fraction, "band_fraction")
    if d.size == 0 or f.size < 2 or not np.any(d):
        return float("inf")
    df_psd = float(np.min(np.diff(f)))
    n = 1 << int(math.ceil(math.log2(max(4 * d.size, 4.0 * rate / df_psd, 2))))
    spec = np.fft.rfft(d, n) / rate                     # D(f) [units], continuous FT
    fk = np.fft.rfftfreq(n, 1.0 / rate)
    p2 = spec.real ** 2 + spec.imag ** 2
    sk = np.interp(fk, f, s, right=np.nan)
    use = (fk > 0) & (sk > 0) & np.isfinite(sk) & (p2 >= band_fraction * float(p2.max()))
    # one-sided sum: the Nyquist bin of an even FFT (a single real bin) counts once
    w = np.where(fk[use] >= 0.5 * rate, 0.5, 1.0)
    info = 4.0 * float(np.sum(w * p2[use] / sk[use])) * (rate / n)
    if dof is not None:
        info *= (dof - 2.0) / dof
    return math.sqrt(1.0 / info) if info > 0 else float("inf")
