"""Cramer-Rao bound on the arrival time of a known pulse in white Gaussian noise.

Used to hold the onset detector (:mod:`meshphase.onsets`) against the physical limit.

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
"""

from __future__ import annotations

import numpy as np

from .validate import as_nonnegative

__all__ = ["crb_delay_std"]


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
