"""Measured mesh phasing from engagement onsets (spec section 3).

Array functions: onset times in, per-pass phasing out. No Recording, no files.

A gauge at one sun tooth root meets every planet once per revolution of the sun relative to
the carrier; a gauge at one ring tooth root meets every planet once per revolution of the
ring relative to the carrier (one carrier revolution for a fixed ring). Between meeting
planet 1 and meeting planet n the gauged member turns, relative to the carrier, by the angle
``lag_n`` (0 <= lag_n < 2 pi, in its own direction of rotation), so

    gamma_jn = frac( Z_j * lag_n / (2 pi) )                                          (1)

with Z_j the tooth count of the gauged gear. At constant speed lag_n = |w_jc| (t_n - t_1)
and (1) is spec section 3's gamma = frac((t_n - t_1) / T_j), T_j = 2 pi / (Z_j |w_jc|).

Notes
-----
Sign convention. With t_n - t_1 counted forward in time from the planet-1 pass to the next
pass of planet n, (1) reproduces spec section 1 for both gears and both rotation directions:
for clockwise planets (w_sc > 0, w_rc < 0) the sun tooth meets planet n after turning
psi_n, giving frac(+Z_s psi_n / 2 pi), and the ring tooth (turning clockwise relative to
the carrier) meets it after turning 2 pi - psi_n, giving frac(-Z_r psi_n / 2 pi). Spec
section 3 writes the ring case as frac(-(t_n - t_1) / T_r); that holds when t_n - t_1 is
counted backwards from planet n to planet 1; we follow the geometry (and the tests check
the measured value against section 1 on both gears and both directions).

Speed drift. The rig's speed is never assumed: the relative angle of the gauged member is
rebuilt from the pulse train itself. Every pass of planet 1 marks one more relative
revolution, so the knots (t_1k, 2 pi k) define the angle Theta(t) of the gauged member;
a shape-preserving cubic (scipy PchipInterpolator) through them gives Theta between knots
and lag_n = Theta(t_n) - 2 pi k. This is exact for constant speed and for a linear ramp to
second order, and follows slow ripple. A carrier once-per-revolution tacho gives the same
knots for a ring gauge (the ring turns once per carrier revolution relative to the carrier).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import PchipInterpolator

from .errors import ProcessingWarning
from .validate import as_finite_array, as_positive_int

__all__ = [
    "PassTable",
    "pass_order",
    "planet_fractions",
    "revolution_numbers",
    "RevolutionEncoder",
    "ScaledEncoder",
    "assign_planets_by_pattern",
    "assign_planets_by_tacho",
    "measured_phasing",
]

TWO_PI = 2.0 * math.pi


@dataclass
class PassTable:
    """Measured phasing per pass: one row per assigned onset of planets 2..N.

    Attributes
    ----------
    gauge : str
        "sun" or "ring".
    time : ndarray, shape (n,)
        Onset time of planet n's pass [s].
    planet : ndarray of int, shape (n,)
        Planet number n (1-based, as in the papers).
    revolution : ndarray of int, shape (n,)
        Relative revolution k the pass belongs to (counted from the first planet-1 pass).
    gamma : ndarray, shape (n,)
        Measured phasing gamma_jn [-] in [0, 1) (fraction of one mesh cycle).
    uncertainty : ndarray, shape (n,)
        One-sigma uncertainty of gamma [-] propagated from the onset timing uncertainty
        (NaN when no timing uncertainty was given).
    mesh_period : ndarray, shape (n,)
        Local mesh period T_j at the pass [s] (from the pulse train, not nominal speed).
    ref_time : ndarray, shape (n,)
        Time of the planet-1 pass that the phasing is taken against [s] (NaN when that pass
        is missing and the revolution was bridged).
    angle : ndarray, shape (n,)
        Relative angle turned by the gauged member since the first reference pass, at the
        pass [rad] (the pulse-train "encoder"; lets models run on the actual angle). The
        planet-1 pass of revolution k sits at angle 2 pi k.
    origin : float
        Time of the first reference pass, where ``angle`` is 0 [s].
    time_origin : float
        Time at which model offset phases (kappa) are referred [s]; the pipeline sets the
        recording's first-sample time (default 0).
    """

    gauge: str
    time: np.ndarray
    planet: np.ndarray
    revolution: np.ndarray
    gamma: np.ndarray
    uncertainty: np.ndarray
    mesh_period: np.ndarray
    ref_time: np.ndarray = None
    angle: np.ndarray = None
    notes: list = field(default_factory=list)
    origin: float = float("nan")
    encoder: object = field(default=None, repr=False, compare=False)
    time_origin: float = 0.0

    def __post_init__(self):
        n = np.asarray(self.time).size
        if self.ref_time is None:
            self.ref_time = np.full(n, np.nan)
        if self.angle is None:
            self.angle = np.full(n, np.nan)

    def __len__(self) -> int:
        return int(self.time.size)

    @classmethod
    def empty(cls, gauge: str, notes=None) -> "PassTable":
        z = np.empty(0)
        return cls(gauge, z, np.empty(0, int), np.empty(0, int), z.copy(), z.copy(), z.copy(),
                   z.copy(), z.copy(), list(notes or []))

    def to_dataframe(self):
        """pandas DataFrame with columns time_s, planet, revolution, gamma, uncertainty,
        mesh_period_s, gauge."""
        import pandas as pd

        return pd.DataFrame({
            "gauge": self.gauge, "time_s": self.time, "planet": self.planet,
            "revolution": self.revolution, "gamma": self.gamma,
            "uncertainty": self.uncertainty, "mesh_period_s": self.mesh_period,
            "ref_time_s": self.ref_time, "angle_rad": self.angle,
        })

    def for_planet(self, n: int) -> "PassTable":
        """Rows of planet ``n`` (1-based)."""
        m = self.planet == n
        return PassTable(self.gauge, self.time[m], self.planet[m], self.revolution[m],
                         self.gamma[m], self.uncertainty[m], self.mesh_period[m],
                         self.ref_time[m], self.angle[m], list(self.notes), self.origin,
                         self.encoder, self.time_origin)

    def mean_speed(self) -> float:
        """Mean relative speed of the gauged member from the encoder angle, |w_jc| [rad/s]
        (least-squares slope of angle against time; NaN with fewer than two passes)."""
        ok = np.isfinite(self.angle)
        if np.count_nonzero(ok) < 2 or np.ptp(self.time[ok]) == 0:
            return float("nan")
        return float(abs(np.polyfit(self.time[ok], self.angle[ok], 1)[0]))

    def summary(self) -> dict:
        """Per planet: count, circular mean of gamma, circular std, max - min of the deviation
        from the circular mean [-]."""
        out = {}
        for n in np.unique(self.planet):
            g = self.gamma[self.planet == n]
            z = np.exp(1j * TWO_PI * g)
            mean = (np.angle(z.mean()) / TWO_PI) % 1.0
            dev = (g - mean + 0.5) % 1.0 - 0.5
            out[int(n)] = {"n": int(g.size), "mean": float(mean), "std": float(dev.std()),
                           "range": float(dev.max() - dev.min()) if g.size else float("nan")}
        return out


def pass_order(direction: str, gauge: str) -> int:
    """Sense in which a gauge meets the planets: +1 in increasing planet angle, -1 decreasing.

    For clockwise planets the sun turns counter-clockwise relative to the carrier (+1) and the
    ring clockwise (-1); counter-clockwise planets flip both.
    """
    if gauge not in ("sun", "ring"):
        raise ValueError(f"gauge must be 'sun' or 'ring', got {gauge!r}")
    if direction not in ("cw", "ccw"):
        raise ValueError(f"direction must be 'cw' or 'ccw', got {direction!r}")
    s = 1 if gauge == "sun" else -1
    return s if direction == "cw" else -s


def planet_fractions(planet_angles, order: int) -> np.ndarray:
    """Fraction of a relative revolution [-] from meeting planet 1 to meeting planet n.

    Parameters
    ----------
    planet_angles : array_like, shape (N,)
        Planet angles psi_n [rad] (planet 1 first).
    order : {+1, -1}
        From :func:`pass_order`.
    """
    psi = as_finite_array(planet_angles, "planet_angles", ndim=1, allow_empty=False)
    if order not in (1, -1):
        raise ValueError(f"order must be +1 or -1, got {order!r}")
    return ((order * (psi - psi[0])) / TWO_PI) % 1.0


def revolution_numbers(ref_times, *, tol: float = 0.5) -> np.ndarray:
    """Revolution count k of each once-per-revolution reference time, allowing for missed ones.

    A reference pulse missing (gap, dropout) shows as an interval about twice the local period;
    k then steps by the rounded ratio, so the angle knots stay right.

    Parameters
    ----------
    ref_times : array_like, shape (m,)
        Sorted reference times [s] (planet-1 passes or tacho pulses).
    tol : float
        Largest accepted distance of an interval ratio from an integer [-].

    Returns
    -------
    k : ndarray of int, shape (m,)
        k[0] = 0, non-decreasing steps of >= 1.
    """
    t = as_finite_array(ref_times, "ref_times", ndim=1)
    if t.size == 0:
        return np.empty(0, dtype=int)
    if t.size == 1:
        return np.zeros(1, dtype=int)
    d = np.diff(t)
    if np.any(d <= 0):
        raise ValueError("ref_times must be strictly increasing")
    # local period: running median of the intervals (robust to single missed pulses)
    # local period: running median of the intervals over 15 (robust to a few missed pulses,
    # follows slow speed change); short trains use their global median
    w = 15
    if d.size < w:
        local = np.full(d.size, np.median(d))
    else:
        pad = np.pad(d, (w // 2, w - 1 - w // 2), mode="reflect")
        local = np.median(np.lib.stride_tricks.sliding_window_view(pad, w), axis=1)
    ratio = d / local
    steps = np.maximum(1, np.rint(ratio)).astype(int)
    return np.concatenate([[0], np.cumsum(steps)])


def assign_planets_by_tacho(times, tacho_times, planet_angles, gauge_angle: float, order: int,
                            *, tol: float = 0.25) -> np.ndarray:
    """Planet index of each ring-gauge onset from a carrier once-per-revolution tacho.

    The tacho fires when the carrier angle is 0 (planet 1 at ground angle psi_1). A ring gauge
    at ground angle ``gauge_angle`` [rad] meets planet n when theta_c(t) + psi_n = gauge_angle
    (mod 2 pi); theta_c(t) comes from the tacho knots (pchip, as in :func:`measured_phasing`).

    Parameters
    ----------
    times : array_like, shape (m,)
        Onset times [s].
    tacho_times : array_like, shape (r,)
        Tacho pulse times [s] (>= 2).
    planet_angles : array_like, shape (N,)
        psi_n [rad].
    gauge_angle : float
        Ground angle of the gauged ring tooth [rad], measured like psi_n from the tacho mark.
    order : {+1, -1}
        Sense of the carrier relative to the ring (+1: the carrier turns counter-clockwise).
    tol : float
        Largest accepted angular mismatch as a fraction of the smallest planet spacing [-];
        onsets further off are labelled -1 (unassigned).

    Returns
    -------
    planet : ndarray of int, shape (m,)
        0-based planet index, -1 when unassigned (outside the tacho span or no planet near).
    """
    t = as_finite_array(times, "times", ndim=1)
    tach = as_finite_array(tacho_times, "tacho_times", ndim=1)
    psi = as_finite_array(planet_angles, "planet_angles", ndim=1, allow_empty=False)
    out = np.full(t.size, -1, dtype=int)
    if t.size == 0:
        return out
    if tach.size < 2:
        raise ValueError(f"assign_planets_by_tacho needs >= 2 tacho pulses, got {tach.size}")
    k = revolution_numbers(tach)
    theta = PchipInterpolator(tach, TWO_PI * k * order, extrapolate=False)(t)
    ok = np.isfinite(theta)
    # ground angle of planet n: theta_c + psi_n; match against the gauge angle
    d = (gauge_angle - theta[ok, None] - psi[None, :] + math.pi) % TWO_PI - math.pi
    best = np.argmin(np.abs(d), axis=1)
    spacing = np.min(np.diff(np.sort(np.concatenate([psi % TWO_PI, [psi[0] % TWO_PI + TWO_PI]]))))
    good = np.abs(d[np.arange(best.size), best]) <= tol * spacing
    idx = np.flatnonzero(ok)
    out[idx[good]] = best[good]
    return out


def assign_planets_by_pattern(times, planet_angles, order: int, *, first: int = 0,
                              amplitudes=None, reference_amplitudes=None,
                              tol: float = 0.3) -> tuple[np.ndarray, dict]:
    """Label a gauge's onsets with planets from the pass pattern alone (no tacho).

    Consecutive onsets are separated by the fraction of a relative revolution between
    consecutive planets in pass order (:func:`planet_fractions`); the relative revolution
    period is estimated locally from the train itself. Missing pulses are detected from the
    gap they leave and skipped. Which onset is planet 1 (the cyclic shift) is taken from
    ``first`` when the layout is symmetric, or chosen as the shift whose labels best match
    the fractions (unequal spacing), or the amplitude pattern (``reference_amplitudes``, e.g.
    the ring-gauge load sharing per planet) when given.

    Parameters
    ----------
    times : array_like, shape (m,)
        Sorted onset times [s].
    planet_angles : array_like, shape (N,)
        psi_n [rad].
    order : {+1, -1}
        From :func:`pass_order`.
    first : int
        0-based planet index of the first onset when nothing else decides.
    amplitudes : array_like, shape (m,), optional
        Pulse amplitudes of these onsets.
    reference_amplitudes : array_like, shape (N,), optional
        Expected relative amplitude per planet (0-based order).
    tol : float
        Largest accepted mismatch of a gap, in units of the smallest planet spacing [-].

    Returns
    -------
    planet : ndarray of int, shape (m,)
        0-based planet index per onset, -1 where unassigned.
    info : dict
        ``shift_decided_by`` ("pattern", "amplitude", "given"), ``ambiguous`` (bool),
        ``n_unassigned``, ``period`` (median relative revolution [s]).
    """
    t = as_finite_array(times, "times", ndim=1)
    frac = planet_fractions(planet_angles, order)
    n = frac.size
    info = {"shift_decided_by": "given", "ambiguous": False, "n_unassigned": 0, "period": float("nan")}
    if t.size == 0:
        return np.empty(0, dtype=int), info
    if np.any(np.diff(t) <= 0):
        raise ValueError("times must be strictly increasing")
    # planets in pass order and the fraction of a revolution between consecutive ones
    seq = np.argsort(frac, kind="stable")
    fs = frac[seq]
    step = np.diff(np.concatenate([fs, [1.0]]))  # gap after seq[i] to seq[i+1]
    spacing = float(step.min())
    if n == 1:
        info["period"] = float(np.median(np.diff(t))) if t.size > 1 else float("nan")
        return np.zeros(t.size, dtype=int), info
    q_first = int(np.flatnonzero(seq == first)[0])
    if t.size < n + 1:
        # too few onsets to estimate a period: label consecutively from `first`
        info["ambiguous"] = True
        return seq[(q_first + np.arange(t.size)) % n], info
    # relative revolution period: median of N-step intervals (robust to a missing pulse),
    # taken locally (a running median over ~2 revolutions) so speed ramps are followed. If a
    # planet is missing altogether, N - 1 (or fewer) pulses make a revolution: the candidate
    # step counts are tried and the one whose gaps fit the planet pattern best is kept.
    mid = 0.5 * (t[1:] + t[:-1])

    def gap_periods(k):
        spans = t[k:] - t[:-k]
        w = min(spans.size, 2 * k + 1)
        if spans.size >= w >= 3:
            pad = np.pad(spans, (w // 2, w - 1 - w // 2), mode="edge")
            local = np.median(np.lib.stride_tricks.sliding_window_view(pad, w), axis=1)
            return np.interp(mid, 0.5 * (t[k:] + t[:-k]), local), float(np.median(spans))
        return np.full(t.size - 1, float(np.median(spans))), float(np.median(spans))

    best = None
    for k in range(n, max(1, n - 2), -1):
        if t.size < k + 2:
            continue
        gp, per = gap_periods(k)
        probe = _walk(np.diff(t) / gp, fs, q_first, tol * spacing)
        score = (np.count_nonzero(~probe[1]), probe[2])
        if best is None or score < best[0]:
            best = (score, gp, per)
        if score[0] == 0:
            break
    gap_period, period = best[1], best[2]
    info["period"] = period
    gaps = np.diff(t) / gap_period
    symmetric = bool(np.allclose(step, step[0], atol=1e-9))
    starts = [q_first] if symmetric else list(range(n))
    walks = {q0: _walk(gaps, fs, q0, tol * spacing) for q0 in starts}
    if symmetric:
        q0 = q_first
        pos, ok, _ = walks[q0]
        info["ambiguous"] = True
        if reference_amplitudes is not None and amplitudes is not None:
            a = as_finite_array(amplitudes, "amplitudes", ndim=1)
            ref = as_finite_array(reference_amplitudes, "reference_amplitudes", ndim=1)
            if a.size != t.size or ref.size != n:
                raise ValueError(f"amplitudes must have one value per onset ({t.size}) and "
                                 f"reference_amplitudes one per planet ({n})")
            mean_a = np.array([np.mean(a[ok & (pos == q)]) if np.any(ok & (pos == q)) else np.nan
                               for q in range(n)])
            if np.all(np.isfinite(mean_a)) and np.ptp(ref) > 0 and np.ptp(mean_a) > 0:
                scores = np.array([np.corrcoef(mean_a, ref[seq[(np.arange(n) + s) % n]])[0, 1]
                                   for s in range(n)])
                best = int(np.argmax(scores))
                info["shift_decided_by"] = "amplitude"
                info["ambiguous"] = bool(scores[best] - np.sort(scores)[-2] < 0.2)
                pos = (pos + best - q0) % n
    else:
        q0 = min(starts, key=lambda q: (np.count_nonzero(~walks[q][1]), walks[q][2]))
        pos, ok, _ = walks[q0]
        info["shift_decided_by"] = "pattern"
    planet = np.where(ok, seq[pos], -1)
    info["n_unassigned"] = int(np.count_nonzero(~ok))
    return planet, info


def _walk(gaps: np.ndarray, fs: np.ndarray, q0: int, tol: float):
    """Positions in pass order of a pulse train whose first pulse is at position ``q0``.

    Each gap [relative revolutions] advances the position by the number of planet steps
    whose fractions fit it best; a gap that fits no step within ``tol`` marks the pulse
    unassigned. Returns (positions mod N, ok mask, summed mismatch).
    """
    n = fs.size
    fs_closed = np.concatenate([fs, [1.0]])
    pos = np.empty(gaps.size + 1, dtype=np.int64)
    ok = np.ones(gaps.size + 1, dtype=bool)
    p = q0
    pos[0] = p
    total = 0.0
    for i, g in enumerate(gaps, start=1):
        target = fs[p % n] + g
        whole = math.floor(target)
        rest = target - whole
        q = int(np.argmin(np.abs(fs_closed - rest)))
        miss = abs(fs_closed[q] - rest)
        total += miss
        adv = whole * n + q - (p % n)
        if adv <= 0 or miss > tol:
            ok[i] = False
            adv = max(1, adv)
        p += adv
        pos[i] = p
    return pos % n, ok, total


class RevolutionEncoder:
    """Relative angle of a gauged member from once-per-revolution pass trains.

    The reference passes (planet 1, or a tacho) mark whole relative revolutions k: knots
    (t_k, 2 pi k). Their times are not exactly one revolution apart when the reference planet
    has its own shaft hole error (each pass moves by that planet's angular deviation, ~e/R_c),
    so the angle is not forced through the knots: a smooth Theta(t) is fitted to them, a cubic
    smoothing spline (scipy make_smoothing_spline) whose smoothing is chosen by generalised
    cross-validation (a quadratic for fewer than 8 passes). The other planets' pass trains,
    each at its own unknown constant angle offset, join the fit (offsets estimated, then one
    refit), so N times more passes average the jitter. Exact for constant speed and a linear
    ramp; follows speed ripple down to a few relative revolutions per period.

    The phasing of a pass at t_n is then taken from Theta(t_n) - Theta(t_1k) with t_1k the
    measured reference pass of its revolution, so at constant speed lag_n = w (t_n - t_1k)
    exactly (spec section 3: gamma = frac(dt / T)).

    Parameters
    ----------
    knot_times : ndarray, shape (m,)
        Reference times [s], strictly increasing, m >= 2.
    k : ndarray of int, shape (m,)
        Their revolution numbers (:func:`revolution_numbers`), gaps allowed.
    extra_trains : list of ndarray, optional
        Pass times of other planets (each strictly increasing, once per revolution).
    lam : float, optional
        Weight of the third-difference roughness penalty (default 1e-2 with ``harmonic``,
        1.0 without).
    harmonic : float, optional
        Rotation of a planet's shaft hole offset per radian of the gauged member's relative
        angle, w_pc / w_jc [-] (-Z_s / Z_p for a sun gauge, Z_r / Z_p for a ring gauge): each
        train gets a cos/sin term at that rate so planet eccentricity is not read as speed.
    knot_spacing : float, optional
        Spline knot spacing [revolutions] (default 1 with ``harmonic``, 4 without).
    """

    def __init__(self, knot_times, k, extra_trains=None, lam: float | None = None,
                 harmonic: float | None = None, knot_spacing: float | None = None):
        kt = np.asarray(knot_times, dtype=float)
        k = np.asarray(k, dtype=int)
        self.k0 = int(k[0])
        full_k = np.arange(k[0], k[-1] + 1)
        # revolutions whose reference pass is missing get an interpolated reference time
        self.full_t = np.interp(full_k, k, kt)
        self._known = np.zeros(full_k.size, bool)
        self._known[k - k[0]] = True
        self.t_first = float(self.full_t[0])
        self.t_last = float(self.full_t[-1])
        # with the eccentricity harmonic modelled the spline may be supple (a knot per
        # revolution); without it, it must be stiff enough not to follow the planets' jitter
        # (which repeats every few revolutions): knots four revolutions apart, more penalty
        if knot_spacing is None:
            knot_spacing = 1.0 if harmonic else 4.0
        if lam is None:
            lam = 1e-2 if harmonic else 1.0
        self.lam = lam
        self.knot_spacing = float(knot_spacing)
        self.residual_rms = float("nan")
        # every train (planet 1 first, then the others): times, revolution numbers, planet
        trains = [(kt, k - k[0])]
        for tq in (extra_trains or []):
            tq = np.asarray(tq, dtype=float)
            inside = (tq >= self.t_first) & (tq <= self.t_last)
            if np.count_nonzero(inside) >= 2:
                trains.append((tq[inside], revolution_numbers(tq[inside])))
        self.harmonic = harmonic
        tt = np.concatenate([x[0] for x in trains])
        base = np.concatenate([TWO_PI * x[1] for x in trains])
        which = np.concatenate([np.full(x[0].size, i) for i, x in enumerate(trains)])
        self._fit_joint(tt, base, which, len(trains))

    def _fit_joint(self, t, y, which, n_trains):
        """One penalised least-squares solve (P-spline, Eilers & Marx 1996) of

            y_i = S(t_i) + c_q + a_q cos(h S(t_i)) + b_q sin(h S(t_i))   (train q of pass i)

        S a cubic B-spline (knots one revolution apart, third-difference penalty so that a
        steady ramp is free), c_q the constant angle offset of each train (0 for planet 1:
        its passes fix the origin) and the harmonic at the planet-offset rotation ratio h,
        which is how a planet's own shaft hole error moves its passes; it turns with the
        planet, so it cannot be mistaken for a change of speed. The harmonic's argument uses
        the previous iterate of S (two Gauss-Newton-like rounds; S is known to ~1e-3 rad after
        the first).
        """
        from scipy import sparse
        from scipy.interpolate import BSpline
        from scipy.sparse.linalg import spsolve

        o = np.argsort(t, kind="stable")
        t, y, which = t[o], y[o], which[o]
        self._t0 = float(t[0])
        span = float(t[-1] - t[0])
        n_rev = max(1.0, (y.max() - y.min()) / TWO_PI)
        P = span / n_rev if span > 0 else 1.0
        self._P = P
        x = (t - self._t0) / P                           # [revolutions]
        n_int = max(1, int(math.ceil(x[-1] / self.knot_spacing)))
        if t.size < 4 * (n_int + 3) // 3 + 3 * n_trains or t.size < 8:
            n_int = 1
        edges = np.linspace(0.0, x[-1] if x[-1] > 0 else 1.0, n_int + 1)
        hk = edges[1] - edges[0]
        # equally spaced knots running past both ends (not clamped): then polynomials up to
        # degree 2 have zero third differences of their coefficients, i.e. no penalty
        kk = np.concatenate([edges[0] - hk * np.arange(3, 0, -1), edges, edges[-1] + hk * np.arange(1, 4)])
        B = BSpline.design_matrix(np.clip(x, edges[0], edges[-1]), kk, 3).tocsc()
        nb = B.shape[1]
        D = sparse.diags([-1.0, 3.0, -3.0, 1.0], [0, 1, 2, 3], shape=(max(0, nb - 3), nb))
        lam = self.lam
        P_pen = lam * (D.T @ D)
        s_prev = y.copy()
        for _ in range(2 if self.harmonic else 1):
            cols = [B]
            for q in range(1, n_trains):
                cols.append(sparse.csc_matrix((which == q).astype(float)[:, None]))
            if self.harmonic:
                for q in range(n_trains):
                    m = (which == q).astype(float)
                    if np.count_nonzero(m) >= 6:
                        cols.append(sparse.csc_matrix((m * np.cos(self.harmonic * s_prev))[:, None]))
                        cols.append(sparse.csc_matrix((m * np.sin(self.harmonic * s_prev))[:, None]))
            A = sparse.hstack(cols, format="csc")
            pen = sparse.block_diag([P_pen, sparse.csc_matrix((A.shape[1] - nb, A.shape[1] - nb))],
                                    format="csc")
            # normal equations are banded + a few dense columns: a sparse direct solve stays
            # linear in the number of revolutions (6600 revolutions solve in well under 1 s)
            M = (A.T @ A + pen).tocsc()
            sol = spsolve(M, A.T @ y)
            if not np.all(np.isfinite(sol)):
                sol = np.linalg.lstsq(M.toarray(), A.T @ y, rcond=None)[0]
            self._spline = BSpline(kk, sol[:nb], 3, extrapolate=True)
            s_prev = self._spline(x)
        self._lin = np.zeros(1)
        self.residual_rms = float(np.sqrt(np.mean((A @ sol - y) ** 2)))

    def _eval(self, t, nu: int = 0):
        t = np.asarray(t, dtype=float)
        if self._spline is not None:
            x = (t - self._t0) / self._P
            return self._spline(x, nu) / self._P ** nu
        p = np.polyder(self._poly, nu) if nu else self._poly
        return np.polyval(p, t - self._t0)

    def angle(self, t):
        """Smooth relative angle Theta(t) [rad] (0 near the first reference pass)."""
        return self._eval(t)

    def rates(self, t):
        """Local angular speed [rad/s] and acceleration [rad/s^2] at times ``t``."""
        return self._eval(t, 1), self._eval(t, 2)

    def lag(self, t):
        """Revolution k, angle turned since that revolution's reference pass [rad] and the
        local angular speed [rad/s] at times ``t`` (inside [t_first, t_last))."""
        t = np.asarray(t, dtype=float)
        j = np.clip(np.searchsorted(self.full_t, t, side="right") - 1, 0, self.full_t.size - 2)
        lag = self._eval(t) - self._eval(self.full_t[j])
        return j + self.k0, lag, np.abs(self._eval(t, 1))

    def knot_time_or_nan(self) -> np.ndarray:
        """Reference time per revolution (NaN where the pass was missing)."""
        return np.where(self._known, self.full_t, np.nan)


class ScaledEncoder:
    """An encoder of one member driven by another member's encoder through a fixed ratio.

    The relative speeds of sun, planets and ring are tied by the tooth counts
    (w_rc = -(Z_s / Z_r) w_sc), so the sun gauge's dense, finely timed pass train measures the
    ring's relative angle too: angle_ring = ratio * angle_sun. The ring gauge's own planet-1
    passes still fix which revolution a pass belongs to and the reference instant t_1.

    Parameters
    ----------
    knot_times, k : ndarray
        This member's reference passes and revolution numbers.
    source : RevolutionEncoder
        The driving encoder (must cover the span of interest).
    ratio : float
        |relative speed of this member| / |relative speed of the source member| [-].
    """

    def __init__(self, knot_times, k, source: "RevolutionEncoder", ratio: float):
        kt = np.asarray(knot_times, dtype=float)
        k = np.asarray(k, dtype=int)
        self.k0 = int(k[0])
        full_k = np.arange(k[0], k[-1] + 1)
        self.full_t = np.interp(full_k, k, kt)
        self._known = np.zeros(full_k.size, bool)
        self._known[k - k[0]] = True
        self.source = source
        self.ratio = float(ratio)
        self.t_first = max(float(self.full_t[0]), source.t_first)
        self.t_last = min(float(self.full_t[-1]), source.t_last)

    def lag(self, t):
        t = np.asarray(t, dtype=float)
        j = np.clip(np.searchsorted(self.full_t, t, side="right") - 1, 0, self.full_t.size - 2)
        t_k = self.full_t[j]
        lag = self.ratio * (self.source.angle(t) - self.source.angle(t_k))
        speed = self.ratio * self.source.rates(t)[0]
        return j + self.k0, lag, np.abs(speed)

    def knot_time_or_nan(self) -> np.ndarray:
        return np.where(self._known, self.full_t, np.nan)


def measured_phasing(times, planets, z_gear: int, n_planets: int, *, gauge: str = "sun",
                     sigma_t=None, reference_times=None, encoder=None,
                     encoder_ratio: float = 1.0, planet_ratio: float | None = None) -> PassTable:
    """Phasing gamma_jn per pass from labelled onset times (equation (1) of the module notes).

    Parameters
    ----------
    times : array_like, shape (m,)
        Sorted onset times [s].
    planets : array_like of int, shape (m,)
        0-based planet index per onset, -1 for unassigned (ignored).
    z_gear : int
        Tooth count of the gauged gear, Z_s or Z_r [-].
    n_planets : int
        Number of planets N [-].
    gauge : {"sun", "ring"}
        Label carried into the table.
    sigma_t : float or array_like, optional
        One-sigma onset timing uncertainty [s], scalar or per onset.
    reference_times : array_like, optional
        Once-per-relative-revolution reference times [s] to use as angle knots instead of the
        planet-1 passes (e.g. a carrier tacho for a ring gauge). Phasing is still taken
        relative to planet 1: gamma_n = frac(Z (lag_n - lag_1) / 2 pi), lag_1 from the same
        revolution.

    encoder : RevolutionEncoder, optional
        Encoder of another member (e.g. ``sun_table.encoder`` for a ring gauge) that drives
        this member's angle through ``encoder_ratio`` (:class:`ScaledEncoder`): a denser,
        finer speed measurement than this gauge's own once-per-revolution passes.
    encoder_ratio : float
        |w of this member| / |w of the encoder's member| relative to the carrier [-]
        (Z_s / Z_r for a ring gauge driven by the sun encoder).
    planet_ratio : float, optional
        w_pc / w_jc, the planets' rotation per radian of this member's relative angle [-]
        (Z_s / Z_p for a sun gauge, Z_r / Z_p for a ring gauge; the sign does not matter):
        lets the speed encoder tell planet eccentricity from speed change
        (:class:`RevolutionEncoder`). None: not modelled.

    Returns
    -------
    PassTable
        Rows for planets 2..N (planet 1 is the reference, gamma = 0 by definition), each with
        the revolution it belongs to, the local mesh period and the propagated uncertainty.
    """
    t = as_finite_array(times, "times", ndim=1)
    lab = np.asarray(planets)
    if lab.shape != t.shape:
        raise ValueError(f"planets must have the shape of times {t.shape}, got {lab.shape}")
    if lab.size and not np.issubdtype(lab.dtype, np.integer):
        raise TypeError(f"planets must be integers, got dtype {lab.dtype}")
    z = as_positive_int(z_gear, "z_gear")
    n = as_positive_int(n_planets, "n_planets")
    if gauge not in ("sun", "ring"):
        raise ValueError(f"gauge must be 'sun' or 'ring', got {gauge!r}")
    if lab.size and (lab.max() >= n or lab.min() < -1):
        raise ValueError(f"planets must lie in [-1, {n - 1}], got range [{lab.min()}, {lab.max()}]")
    if t.size and np.any(np.diff(t) < 0):
        raise ValueError("times must be sorted in increasing order")
    if sigma_t is None:
        sig = np.full(t.size, np.nan)
    else:
        sig = np.broadcast_to(np.asarray(sigma_t, dtype=float), t.shape).astype(float)
        if np.any(sig < 0):
            raise ValueError("sigma_t must be >= 0")
    if t.size == 0:
        return PassTable.empty(gauge, ["no onsets"])
    notes = []
    use_ref = reference_times is not None
    if use_ref:
        knots_t = as_finite_array(reference_times, "reference_times", ndim=1)
        knot_sig = np.zeros(knots_t.size)
    else:
        first = lab == 0
        knots_t = t[first]
        knot_sig = sig[first]
    if knots_t.size < 2:
        msg = (f"{gauge} gauge: fewer than two reference passes ({knots_t.size}); no relative "
               "revolution can be measured")
        warnings.warn(msg, ProcessingWarning, stacklevel=2)
        return PassTable.empty(gauge, [msg])
    k = revolution_numbers(knots_t)
    if k[-1] != knots_t.size - 1:
        notes.append(f"{int(k[-1] - knots_t.size + 1)} missing reference pass(es) bridged")
    if encoder is not None and not use_ref:
        enc = ScaledEncoder(knots_t, k, encoder, encoder_ratio)
        if not enc.t_last > enc.t_first:
            msg = f"{gauge} gauge: the driving encoder does not overlap this gauge's passes"
            warnings.warn(msg, ProcessingWarning, stacklevel=2)
            return PassTable.empty(gauge, [msg])
    else:
        # every planet's own passes are a once-per-revolution encoder of the same member
        others = [] if use_ref else [t[lab == q] for q in range(1, n)]
        enc = RevolutionEncoder(knots_t, k, extra_trains=[x for x in others if x.size >= 2],
                                harmonic=planet_ratio)
    inside = (t >= enc.t_first) & (t < enc.t_last)
    tt = np.where(inside, t, enc.t_first)
    rev, lag, omega = enc.lag(tt)
    th = TWO_PI * rev + lag
    if use_ref:
        # lag of planet 1 per revolution, subtracted from every planet of that revolution
        m1 = inside & (lab == 0)
        t1 = np.full(int(k[-1]) + 1, np.nan)
        t1[rev[m1]] = t[m1]
        lag1 = np.full(int(k[-1]) + 1, np.nan)
        lag1[rev[m1]] = lag[m1]
        sig1 = np.full(int(k[-1]) + 1, np.nan)
        sig1[rev[m1]] = sig[m1]
        rel = lag - lag1[rev]
        sig_ref = sig1[rev]
    else:
        rel = lag
        t1 = enc.knot_time_or_nan()
        # the planet-1 pass of the revolution carries its own timing error
        kpos = np.clip(np.searchsorted(knots_t, t, side="right") - 1, 0, knots_t.size - 1)
        sig_ref = knot_sig[kpos]
    keep = inside & (lab > 0) & np.isfinite(rel)
    n_out = int(np.count_nonzero((lab > 0) & ~inside))
    if n_out:
        notes.append(f"{n_out} pass(es) outside the reference span dropped")
    rel = rel[keep]
    gamma = (z * rel / TWO_PI) % 1.0
    gamma = np.where(gamma >= 1.0, 0.0, gamma)
    om = omega[keep]
    mesh_period = TWO_PI / (z * om)
    unc = z * om / TWO_PI * np.hypot(sig[keep], sig_ref[keep])
    rk = rev[keep]
    out = PassTable(gauge, t[keep], lab[keep] + 1, rk, gamma, unc, mesh_period,
                    t1[np.clip(rk - enc.k0, 0, t1.size - 1)], th[keep], notes, float(enc.full_t[0]))
    out.encoder = enc
    return out
