"""Planet load sharing and face-width load centroids from measured pulse amplitudes.

Array functions (spec sections 6 and 7); the bearing moments that follow from the centroids
are :func:`meshphase.models.bearing.moments_from_offsets`.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from ..runtime.lazy import optimize
from ..errors import ProcessingWarning
from ..models.load_sharing import load_sharing
from ..validate import as_finite_array, as_float, as_positive, as_positive_int

#: relative slack on |s| b / 2 <= 1 (full contact) for rounding of fitted slopes [-]
_FULL_CONTACT_TOL = 1e-12

__all__ = ["LoadSharingResult", "load_sharing_from_amplitudes", "CentroidResult",
           "facewidth_centroid", "facewidth_readings", "centroid_of_shape"]


@dataclass
class LoadSharingResult:
    """Planet load-sharing factors LS_n = N eps_n / sum eps_i [-] (1 = equal sharing).

    Attributes
    ----------
    factors : ndarray, shape (N,)
        From the per-planet mean peak strain.
    std_error : ndarray, shape (N,)
        Standard error of each factor from the pass-to-pass scatter [-].
    n_passes : ndarray of int, shape (N,)
    mean_amplitude : ndarray, shape (N,)
        Mean pulse amplitude per planet [strain].
    """

    factors: np.ndarray
    std_error: np.ndarray
    n_passes: np.ndarray
    mean_amplitude: np.ndarray

    def to_rows(self) -> list[dict]:
        return [{"planet": i + 1, "load_sharing": float(f), "std_error": float(s),
                 "n_passes": int(n), "mean_amplitude": float(a)}
                for i, (f, s, n, a) in enumerate(zip(self.factors, self.std_error,
                                                     self.n_passes, self.mean_amplitude))]


def load_sharing_from_amplitudes(amplitudes, planets, n_planets: int) -> LoadSharingResult:
    """Load sharing per planet from the peak strains one ring gauge sees (Ligata et al. 2008).

    Parameters
    ----------
    amplitudes : array_like, shape (m,)
        Peak strain of each pulse [strain], > 0.
    planets : array_like of int, shape (m,)
        1-based planet per pulse (0 or negative: unassigned, ignored).
    n_planets : int
        N [-].

    Returns
    -------
    LoadSharingResult
        NaN factors (with a ProcessingWarning) for planets that have no pulse; NaN standard
        errors when a planet seen has a single pulse (no scatter to estimate).

    Raises
    ------
    ValueError
        Shape mismatch, planet numbers above ``n_planets``, negative amplitudes of assigned
        pulses, a planet whose mean amplitude is 0.
    TypeError
        Non-integer planet numbers.

    Notes
    -----
    LS_n = N mean(eps_n) / sum_i mean(eps_i). The standard error follows from the scatter of
    eps_n by first-order propagation (the sum's own scatter is included).
    """
    a = as_finite_array(amplitudes, "amplitudes", ndim=1)
    p = np.asarray(planets)
    if p.shape != a.shape:
        raise ValueError(f"planets {p.shape} must match amplitudes {a.shape}")
    if p.size and not np.issubdtype(p.dtype, np.integer):
        raise TypeError(f"planets must be integers (1-based planet numbers), got dtype {p.dtype}")
    n = as_positive_int(n_planets, "n_planets")
    if p.size and (p.max() > n):
        raise ValueError(f"planets must be <= n_planets = {n}, got {p.max()}")
    assigned = p > 0
    if np.any(a[assigned] < 0):
        raise ValueError("pulse amplitudes must be >= 0 (peak strain magnitudes), got "
                         f"{int(np.count_nonzero(a[assigned] < 0))} negative value(s), min "
                         f"{float(a[assigned].min())!r}")
    mean = np.full(n, np.nan)
    sem = np.full(n, np.nan)
    cnt = np.zeros(n, dtype=int)
    for q in range(1, n + 1):
        x = a[p == q]
        cnt[q - 1] = x.size
        if x.size:
            mean[q - 1] = x.mean()
            sem[q - 1] = x.std(ddof=1) / math.sqrt(x.size) if x.size > 1 else np.nan
    if np.any(cnt == 0):
        missing = (np.flatnonzero(cnt == 0) + 1).tolist()
        warnings.warn(f"load sharing: no pulse from planet(s) {missing}; their factor is NaN and "
                      "the others are normalised over the planets seen", ProcessingWarning,
                      stacklevel=2)
    if not np.any(cnt):
        return LoadSharingResult(np.full(n, np.nan), np.full(n, np.nan), cnt, mean)
    if np.any(mean[cnt > 0] <= 0):
        raise ValueError("every planet's mean pulse amplitude must be > 0 (peak strain) to share "
                         f"load, got {mean.tolist()}")
    seen = cnt > 0
    ls = np.full(n, np.nan)
    # normalised over the planets seen: their factors sum to their count
    ls[seen] = load_sharing(mean[seen])
    total = mean[seen].sum()
    se = np.full(n, np.nan)
    for i in np.flatnonzero(seen):
        # d LS_i / d m_j = k (delta_ij / S - m_i / S^2), k = number seen
        g = -seen.sum() * mean[i] / total ** 2 * np.ones(seen.sum())
        g[np.flatnonzero(np.flatnonzero(seen) == i)[0]] += seen.sum() / total
        # a planet seen once has no scatter to estimate: the factors' std error is unknown
        # (NaN), not zero, since every factor depends on every planet's mean
        s = sem[seen]
        se[i] = float(np.sqrt(np.sum((g * s) ** 2)))
    return LoadSharingResult(ls, se, cnt, mean)


def centroid_of_shape(slope_ratio: float, face_width: float) -> tuple[float, float]:
    """Centroid [m] and contact fraction [-] of the load shape w(z) ~ max(0, 1 - s z) on
    z in [-b/2, b/2] (spec section 5's shape, s = theta / delta [1/m])."""
    b = as_positive(face_width, "face_width")
    s = as_float(slope_ratio, "slope_ratio")
    if abs(s) * b / 2 <= 1.0 + _FULL_CONTACT_TOL:
        # full contact: linear w = 1 - s z, centroid = -s b^2 / 12 (continuous with the
        # triangle below at |s| b / 2 = 1, so rounding across the boundary does not matter
        # for the centroid; the tolerance keeps the label and fraction from flickering)
        return -s * b * b / 12.0, 1.0
    # partial: contact from the loaded edge to z0 = 1 / s (triangle)
    edge = -b / 2 if s > 0 else b / 2
    z0 = 1.0 / s
    lo, hi = sorted((edge, z0))
    # w = 1 - s z is linear on [lo, hi] and 0 at z0: a triangle's centroid is a third from
    # its base (the loaded edge)
    return edge + (z0 - edge) / 3.0, (hi - lo) / b


@dataclass
class CentroidResult:
    """Face-width load centroid Z [m] from gauges across the face.

    Attributes
    ----------
    centroid : float
        Z [m] from the face centre (positive towards +z).
    std_error : float
        From the fit residuals / pass scatter [m].
    contact_fraction : float
        Loaded share of the face width [-] (1: full contact).
    shape : str
        "linear" (full contact) or "partial" (section 5 triangle).
    residual_rms : float
        RMS misfit of the gauge readings [same units as the readings].
    """

    centroid: float
    std_error: float
    contact_fraction: float
    shape: str
    residual_rms: float


def facewidth_centroid(readings, positions, face_width: float, gains=None) -> CentroidResult:
    """Load centroid across the face width from two or more face-width gauge readings.

    Parameters
    ----------
    readings : array_like, shape (G,) or (m, G)
        Peak strain of each gauge [strain] (one row per pass, or one mean reading).
    positions : array_like, shape (G,)
        Axial gauge positions from the face centre [m].
    face_width : float
        b [m].
    gains : array_like, shape (G,), optional
        Calibration gain per gauge (readings are divided by it).

    Returns
    -------
    CentroidResult
        All NaN (shape "none") for zero rows, shape (0, G). Rows with a non-finite reading
        are left out with a ProcessingWarning.

    Raises
    ------
    ValueError
        Fewer than two gauges, coinciding positions, positions off the face, readings not
        one column per gauge, zero gains, no finite row, a non-positive mean load.

    Notes
    -----
    Spec section 7: readings ~ w(z_i). For full contact w(z) = (F / b)(1 + 12 Z z / b^2), a
    straight line a + c z through the readings gives Z = c b^2 / (12 a). When the line
    reaches zero inside the face (a gauge reads ~0), the section 5 shape A max(0, 1 - s z)
    is fitted instead and Z is its triangle centroid. With several passes the fit uses the
    per-gauge mean and the standard error comes from the per-pass centroids.
    """
    r = np.asarray(readings, dtype=float)
    z = as_finite_array(positions, "positions", ndim=1)
    b = as_positive(face_width, "face_width")
    if r.ndim == 1:
        r = r[None, :]
    if r.ndim != 2 or r.shape[1] != z.size:
        raise ValueError(f"readings must have one column per gauge ({z.size}), got shape {r.shape}")
    if z.size < 2:
        raise ValueError(f"a centroid needs at least two face-width gauges, got {z.size}")
    if np.ptp(z) == 0:
        raise ValueError("face-width gauge positions must differ")
    if np.any(np.abs(z) > b / 2 * (1 + 1e-9)):
        raise ValueError(f"gauge positions must lie on the face [-b/2, b/2] = [{-b / 2}, {b / 2}] m, got {z.tolist()}")
    if gains is not None:
        g = as_finite_array(gains, "gains", ndim=1)
        if g.size != z.size or np.any(g == 0):
            raise ValueError("gains must be one non-zero value per gauge")
        r = r / g
    if r.shape[0] == 0:
        return CentroidResult(float("nan"), float("nan"), float("nan"), "none", float("nan"))
    finite = np.all(np.isfinite(r), axis=1)
    if not np.any(finite):
        raise ValueError("every face-width reading row has a non-finite value")
    if not np.all(finite):
        warnings.warn(f"facewidth_centroid: {int(np.count_nonzero(~finite))} of {r.shape[0]} "
                      "reading row(s) with a non-finite value left out", ProcessingWarning,
                      stacklevel=2)
        r = r[finite]

    def one(y):
        c, a = np.polyfit(z, y, 1)
        if a <= 0:
            raise ValueError("face-width readings do not describe a positive load (mean <= 0)")
        s = -c / a
        resid = y - (a + c * z)
        if abs(s) * b / 2 <= 1.0 + _FULL_CONTACT_TOL or z.size < 3:
            zc, frac = centroid_of_shape(s, b)
            return zc, frac, "linear" if frac == 1.0 else "partial", float(np.sqrt(np.mean(resid ** 2)))
        # partial contact: fit A max(0, 1 - s z)
        fun = lambda p: p[0] * np.maximum(0.0, 1.0 - p[1] * z) - y
        sol = optimize.least_squares(fun, [a, s])
        zc, frac = centroid_of_shape(sol.x[1], b)
        return (zc, frac, "linear" if frac == 1.0 else "partial",
                float(np.sqrt(np.mean(sol.fun ** 2))))

    zc, frac, shape, rms = one(r.mean(axis=0))
    if r.shape[0] > 1:
        per = np.array([one(row)[0] for row in r])
        se = float(per.std(ddof=1) / math.sqrt(per.size))
    else:
        se = float("nan")
    return CentroidResult(float(zc), se, float(frac), shape, rms)


def facewidth_readings(times, amplitudes, good, widths, fs: float) -> np.ndarray:
    """Per pass, the peak strain each face-width gauge of one gear reads [strain], for
    :func:`facewidth_centroid`.

    The passes are timed on the gauge that sees the most load (most clean pulses, then the
    largest median amplitude): with partial contact the gauges at the unloaded end of the
    face read nothing. For each of its clean pulses, every gauge reads the |amplitude| of its
    pulse nearest in time when that lies within the reference gauge's median pulse width
    (at least one sample), else 0 (no pulse: unloaded there).

    Parameters
    ----------
    times, amplitudes, good, widths : sequence of G array_like
        Per gauge: onset times [s], signed pulse amplitudes [strain], the clean-pulse mask
        and the pulse widths [s] (the fields of :class:`meshphase.onsets.Onsets`).
    fs : float
        Sample rate [Hz].

    Returns
    -------
    ndarray, shape (m, G)
        One row per clean pulse of the reference gauge; rows with a non-finite reading are
        left out. Shape (0, G) when the reference gauge has no clean pulse.
    """
    fs = as_positive(fs, "fs")
    gauges = [(np.asarray(t, dtype=float), np.asarray(a, dtype=float), np.asarray(g, dtype=bool),
               np.asarray(w, dtype=float)) for t, a, g, w in zip(times, amplitudes, good, widths)]
    if not (len(gauges) == len(times) == len(amplitudes) == len(good) == len(widths)):
        raise ValueError("times, amplitudes, good and widths need one entry per gauge, got "
                         f"{len(times)}, {len(amplitudes)}, {len(good)} and {len(widths)}")
    for k, (t, a, g, w) in enumerate(gauges):
        if not (t.ndim == 1 and a.shape == g.shape == w.shape == t.shape):
            raise ValueError(f"gauge {k}: times, amplitudes, good and widths must be 1-D of one "
                             f"length, got shapes {t.shape}, {a.shape}, {g.shape}, {w.shape}")
    if not gauges:
        return np.empty((0, 0))
    ref_t, ref_a, ref_g, ref_w = max(gauges, key=lambda o: (
        int(o[2].sum()), float(np.nanmedian(np.abs(o[1]))) if o[0].size else 0.0))
    rows = []
    for t0 in ref_t[ref_g]:
        row = []
        for t, a, _, _ in gauges:
            if t.size == 0:
                row.append(0.0)  # no pulse at all on this gauge: unloaded end of the face
                continue
            j = int(np.argmin(np.abs(t - t0)))
            width = float(np.nanmedian(ref_w)) if ref_t.size else 0.0
            row.append(abs(a[j]) if abs(t[j] - t0) < max(width, 1 / fs) else 0.0)
        rows.append(row)
    readings = np.asarray(rows, dtype=float).reshape(-1, len(gauges))
    return readings[np.all(np.isfinite(readings), axis=1)]
