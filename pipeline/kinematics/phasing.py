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

Speed. The rig's speed is never assumed. Z_j lag_n / 2 pi is the mesh angle turned between
the two passes, and the mesh angle A(t) of the whole gear train is fitted to every pass train
and the tacho at once (:mod:`meshphase.kinematics.angles`: smooth drift plus ripple locked to the shaft
angles, per-planet offsets and planet-spin terms told apart by how they sample the shafts),
so gamma_n = frac(A(t_n) - A(t_1)) (:func:`phasing_from_model`). Each pass carries the
one-sigma uncertainty of its two onsets' timing and of the model.

Labels. Which pulse is which planet comes from the pass pattern
(:func:`assign_planets_by_pattern`: the fractions of a revolution between consecutive
planets); which one is planet 1 from unequal spacing, from a carrier tacho for a gauge on
the held member (:func:`assign_planets_by_tacho`, geometry in ``data_schemas/scene.md``), or
from the planets' loads; otherwise the labels are relative to the first pulse. The loads name
the sun gauge's planet 1 only when the ring gauge's per-planet loads, divided by the load
variation with the carrier's phase that the sun gauge measures
(:func:`carrier_load_variation`), match the sun's under one labelling clearly
(:func:`load_shift_chi2`); where the loads and another kind of evidence disagree, the labels
are relative and carry a caution saying why. A scene may fix a gauge's planet 1 outright
(``label_shifts`` of :func:`measure_phasing`).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy import linalg, special
from scipy.interpolate import PchipInterpolator

from meshphase.kinematics.angle_windows import fit_angle_windows
from meshphase.kinematics.angle_selection import unseen_ripples
from meshphase.kinematics.angles import AngleModel
from meshphase.kinematics.label_shift import label_shift_costs
from meshphase.kinematics.shafts import Kinematics, held_member, kinematics, shaft_cycles
from meshphase.kinematics.trains import (PassTrain, encoder_train, gauge_train, mesh_cycles_per_carrier_turn,
                                         relabel_train, revolution_numbers, tacho_train)
from meshphase.kinematics.encoder import MAX_GAP_PULSES, clean_edges, split_at_gaps
from meshphase.errors import DataQualityWarning, ProcessingWarning
from meshphase.validate import as_finite_array, as_positive_int

__all__ = [
    "PassTable",
    "pass_order",
    "planet_fractions",
    "revolution_numbers",
    "GaugeEncoder",
    "assign_planets_by_pattern",
    "assign_planets_by_tacho",
    "TachoRelabel",
    "relabel_by_tacho",
    "phasing_from_model",
    "measured_phasing",
    "GaugePasses",
    "GaugeLabels",
    "PhasingResult",
    "measure_phasing",
    "relabel_gauge",
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
        One-sigma uncertainty of gamma [-]: the two onsets' timing (bound times the train's
        fitted variance factor) and the angle model's covariance, combined.
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
    timing_floor : ndarray, shape (n,)
        What the two onsets' timing bounds alone allow [-]: A'(t_n) sigma_n and A'(t_1)
        sigma_1 combined (NaN without timing bounds); from :func:`measure_phasing` with
        the bounds in the gauge's noise spectrum (``sigma`` times
        :attr:`GaugePasses.floor_factor`), the floor the reliability is judged against.
    model_sigma : ndarray, shape (n,)
        The angle model's own one-sigma uncertainty of A(t_n) - A(t_1) [-].
    choice_sigma : ndarray, shape (n,)
        The part of ``uncertainty`` from the choice of angle model [-]
        (:meth:`meshphase.kinematics.angles.AngleModel.choice_spread`; zeros where no competing model
        explains the passes about as well).
    competitors : list of dict
        The competing angle models behind ``choice_sigma`` (``choice_spread``'s ``info``).
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
    timing_floor: np.ndarray = None
    model_sigma: np.ndarray = None
    choice_sigma: np.ndarray = None
    competitors: list = field(default_factory=list)

    def __post_init__(self):
        n = np.asarray(self.time).size
        for name in ("ref_time", "angle", "timing_floor", "model_sigma"):
            if getattr(self, name) is None:
                setattr(self, name, np.full(n, np.nan))

    def __len__(self) -> int:
        return int(self.time.size)

    @classmethod
    def empty(cls, gauge: str, notes=None) -> "PassTable":
        z = np.empty(0)
        return cls(gauge, z, np.empty(0, int), np.empty(0, int), z.copy(), z.copy(), z.copy(),
                   z.copy(), z.copy(), list(notes or []))

    def columns(self) -> dict:
        """The table's columns, name -> array (``gauge``: the gauge's name, one for all rows):
        gauge, time_s, planet, revolution, gamma, uncertainty, mesh_period_s, ref_time_s,
        angle_rad, timing_floor, model_sigma (units as the attributes')."""
        return {"gauge": self.gauge, "time_s": self.time, "planet": self.planet,
                "revolution": self.revolution, "gamma": self.gamma,
                "uncertainty": self.uncertainty, "mesh_period_s": self.mesh_period,
                "ref_time_s": self.ref_time, "angle_rad": self.angle,
                "timing_floor": self.timing_floor, "model_sigma": self.model_sigma}

    def to_dataframe(self):
        """pandas DataFrame of :meth:`columns`."""
        import pandas as pd

        return pd.DataFrame(self.columns())

    def for_planet(self, n: int) -> "PassTable":
        """Rows of planet ``n`` (1-based)."""
        m = self.planet == n
        return PassTable(self.gauge, self.time[m], self.planet[m], self.revolution[m],
                         self.gamma[m], self.uncertainty[m], self.mesh_period[m],
                         self.ref_time[m], self.angle[m], list(self.notes), self.origin,
                         self.encoder, self.time_origin, self.timing_floor[m],
                         self.model_sigma[m])

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
    the ring-gauge load sharing per planet) when given. That pattern is taken as it is given:
    a ring gauge's loads carry any load variation with the carrier's phase, which
    :func:`measure_phasing` removes (:func:`carrier_load_variation`) before it trusts them.

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
        ``n_unassigned``, ``period`` (median relative revolution [s]), ``position``
        (int array: cumulative pass-order position of each onset, revolution
        ``position // N`` and place ``position % N``; meaningful where planet >= 0).
    """
    t = as_finite_array(times, "times", ndim=1)
    frac = planet_fractions(planet_angles, order)
    n = frac.size
    info = {"shift_decided_by": "given", "ambiguous": False, "n_unassigned": 0, "period": float("nan"),
            "position": np.empty(0, dtype=np.int64)}
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
        info["position"] = np.arange(t.size, dtype=np.int64)
        return np.zeros(t.size, dtype=int), info
    q_first = int(np.flatnonzero(seq == first)[0])
    if t.size < n + 1:
        # too few onsets to estimate a period: label consecutively from `first`
        info["ambiguous"] = True
        info["position"] = q_first + np.arange(t.size, dtype=np.int64)
        return seq[(q_first + np.arange(t.size)) % n], info
    gap_period, period = _revolution_period(t, n, fs, step, q_first, tol * spacing)
    info["period"] = period
    gaps = np.diff(t) / gap_period
    symmetric = bool(np.allclose(step, step[0], atol=1e-9))
    if symmetric:
        pos, ok, _ = _walk(gaps, fs, q_first, tol * spacing)
        info["ambiguous"] = True
        if reference_amplitudes is not None and amplitudes is not None:
            got = _amplitude_shift(amplitudes, reference_amplitudes, pos, ok, seq, t.size)
            if got is not None:
                best, info["ambiguous"] = got
                info["shift_decided_by"] = "amplitude"
                pos = pos + (best - q_first) % n
    else:
        walks = {q0: _walk(gaps, fs, q0, tol * spacing) for q0 in range(n)}
        q0 = min(walks, key=lambda q: (np.count_nonzero(~walks[q][1]), walks[q][2]))
        pos, ok, _ = walks[q0]
        info["shift_decided_by"] = "pattern"
    planet = np.where(ok, seq[pos % n], -1)
    info["position"] = pos
    info["n_unassigned"] = int(np.count_nonzero(~ok))
    return planet, info


def _revolution_period(t: np.ndarray, n: int, fs: np.ndarray, step: np.ndarray, q_first: int,
                       tol: float) -> tuple[np.ndarray, float]:
    """The local relative revolution period at each gap of the onset times ``t`` [s] and its
    median [s], for :func:`assign_planets_by_pattern`.

    The median of N-step intervals (robust to a missing pulse), taken locally (a running
    median over ~2 revolutions) so speed ramps are followed. If a planet is missing
    altogether, N - 1 (or fewer) pulses make a revolution: the candidate step counts are
    tried and the one whose gaps fit the planet pattern (fractions ``fs`` in pass order,
    gaps ``step`` between them) best is kept; a symmetric layout also tries the planet step
    of sparse trains (:func:`_step_periods`).
    """
    best = None
    cands = [k for k in range(n, max(1, n - 2), -1) if t.size >= k + 2]
    symmetric_steps = bool(np.allclose(step, step[0], atol=1e-9))
    for k in cands + (["steps"] if symmetric_steps and t.size >= 3 else []):
        got = _step_periods(t, n) if k == "steps" else _gap_periods(t, k)
        if got is None:
            continue
        gp, per = got
        probe = _walk(np.diff(t) / gp, fs, q_first, tol)
        score = (np.count_nonzero(~probe[1]), probe[2])
        if best is None or score < best[0]:
            best = (score, gp, per)
        if score[0] == 0:
            break
    return best[1], best[2]


def _gap_periods(t: np.ndarray, k: int) -> tuple[np.ndarray, float]:
    """Revolution period [s] at each gap of ``t`` when ``k`` pulses make a revolution: the
    running median (over 2 k + 1) of the k-step spans, and their median."""
    mid = 0.5 * (t[1:] + t[:-1])
    spans = t[k:] - t[:-k]
    w = min(spans.size, 2 * k + 1)
    if spans.size >= w >= 3:
        pad = np.pad(spans, (w // 2, w - 1 - w // 2), mode="edge")
        local = np.median(np.lib.stride_tricks.sliding_window_view(pad, w), axis=1)
        return np.interp(mid, 0.5 * (t[k:] + t[:-k]), local), float(np.median(spans))
    return np.full(t.size - 1, float(np.median(spans))), float(np.median(spans))


def _step_periods(t: np.ndarray, n: int) -> tuple[np.ndarray, float] | None:
    """Equal spacing, sparse trains (pulses lost to dropouts): every gap between
    consecutive pulses is a whole number of planet steps, so the step is the local median
    of gap / round(gap / step), started from the short gaps (single steps) and refined
    twice; the period is N steps. None when the short gaps are not positive."""
    g = np.diff(t)
    s = float(np.quantile(g, 0.2))
    if not s > 0:
        return None
    loc = np.full(g.size, s)
    for _ in range(3):
        m = np.maximum(1.0, np.rint(g / loc))
        est = g / m
        w = min(est.size, 4 * n + 1)
        if w >= 3:
            pad = np.pad(est, (w // 2, w - 1 - w // 2), mode="edge")
            loc = np.median(np.lib.stride_tricks.sliding_window_view(pad, w), axis=1)
        else:
            loc = np.full(g.size, float(np.median(est)))
    return n * loc, float(n * np.median(loc))


def _amplitude_shift(amplitudes, reference_amplitudes, pos, ok, seq, m: int):
    """(shift, ambiguous) of a symmetric layout's labels from the pulse amplitudes: the
    cyclic shift whose planets' expected amplitudes (``reference_amplitudes``) correlate
    best with the mean amplitude per pass-order place; ambiguous when the next best is
    within 0.2. None when a place has no pulse or either pattern is flat."""
    n = seq.size
    a = as_finite_array(amplitudes, "amplitudes", ndim=1)
    ref = as_finite_array(reference_amplitudes, "reference_amplitudes", ndim=1)
    if a.size != m or ref.size != n:
        raise ValueError(f"amplitudes must have one value per onset ({m}) and "
                         f"reference_amplitudes one per planet ({n})")
    mean_a = np.array([np.mean(a[ok & (pos == q)]) if np.any(ok & (pos == q)) else np.nan
                       for q in range(n)])
    if not (np.all(np.isfinite(mean_a)) and np.ptp(ref) > 0 and np.ptp(mean_a) > 0):
        return None
    scores = np.array([np.corrcoef(mean_a, ref[seq[(np.arange(n) + s) % n]])[0, 1]
                       for s in range(n)])
    best = int(np.argmax(scores))
    return best, bool(scores[best] - np.sort(scores)[-2] < 0.2)
#: gaps whose moves :func:`_walk` works out at once (its tables hold this many x N x (N + 1)
#: values: memory bounded whatever the recording's length) [-]
_WALK_CHUNK = 4096


def _walk(gaps: np.ndarray, fs: np.ndarray, q0: int, tol: float):
    """Positions in pass order of a pulse train whose first pulse is at position ``q0``.

    Each gap [relative revolutions] advances the position by the number of planet steps
    whose fractions fit it best; a gap that fits no step within ``tol`` marks the pulse
    unassigned. Returns (positions, ok mask, summed mismatch); a position's place in the
    pass order is position mod N.

    The walk is sequential only through the place p mod N the previous gap left it at, so
    the moves of ``_WALK_CHUNK`` gaps at a time are worked out for each of the N places at
    once, and the place before each gap follows by composing those moves (pointer doubling:
    log2 of the chunk gathers). The mismatch is summed in gap order, as a loop over the
    gaps would (the same result to the bit, tested against that loop).
    """
    n = fs.size
    gaps = np.asarray(gaps, dtype=np.float64)
    m = gaps.size
    pos = np.empty(m + 1, dtype=np.int64)
    ok = np.ones(m + 1, dtype=bool)
    pos[0] = q0
    if m == 0:
        return pos, ok, 0.0
    if not np.all(np.isfinite(gaps)):
        raise ValueError("gaps must be finite")
    fs_closed = np.concatenate([fs, [1.0]])
    place = np.arange(n)
    p, s, total = int(q0), int(q0) % n, 0.0
    for c0 in range(0, m, _WALK_CHUNK):
        g = gaps[c0:c0 + _WALK_CHUNK]
        k = g.size
        target = fs[None, :] + g[:, None]                     # (k, N): gap i from place s
        whole = np.floor(target)
        rest = target - whole
        dist = np.abs(fs_closed[None, None, :] - rest[:, :, None])   # (k, N, N + 1)
        q = np.argmin(dist, axis=2)                           # first of equals, as a loop
        miss = np.take_along_axis(dist, q[:, :, None], axis=2)[:, :, 0]
        adv = whole.astype(np.int64) * n + q - place[None, :]
        bad = (adv <= 0) | (miss > tol)
        adv = np.where(bad, np.maximum(adv, 1), adv)
        # the place after gap i from each place, composed with every move before it in the
        # chunk: the place after gap i from the chunk's first place
        comp = (place[None, :] + adv) % n
        d = 1
        while d < k:
            comp[d:] = np.take_along_axis(comp[d:], comp[:-d], axis=1)
            d *= 2
        before = np.empty(k, dtype=np.int64)
        before[0] = s
        before[1:] = comp[:-1, s]
        i = np.arange(k)
        pos[c0 + 1:c0 + k + 1] = p + np.cumsum(adv[i, before])
        ok[c0 + 1:c0 + k + 1] = ~bad[i, before]
        total = float(np.cumsum(np.concatenate([[total], miss[i, before]]))[-1])
        p, s = int(pos[c0 + k]), int(comp[-1, s])
    return pos, ok, total


class GaugeEncoder:
    """The relative angle of one gauged gear, read off the recording's :class:`AngleModel`.

    ``angle(t) = 2 pi (A(t) - A(origin)) / Z`` [rad]: the angle the gauged gear has turned
    relative to the carrier since its first reference (planet-1) pass, in its own sense of
    rotation. :mod:`meshphase.compare.predict` runs the models on it.

    Attributes
    ----------
    model : AngleModel
    z : int
        Tooth count of the gauged gear [-].
    full_t : ndarray
        Planet-1 pass time of each revolution from the first one with a reference pass [s]
        (NaN where that pass is missing).
    k0 : int
        Revolution number of ``full_t[0]``.
    """

    def __init__(self, model: AngleModel, z: int, full_t: np.ndarray, k0: int):
        self.model = model
        self.z = int(z)
        self.full_t = np.asarray(full_t, dtype=float)
        self.k0 = int(k0)
        self._a0 = float(model.mesh_angle(self.full_t[:1])[0])
        self.t_first, self.t_last = (float(x) for x in model.t_span)

    def angle(self, t) -> np.ndarray:
        """Relative angle of the gauged gear since its first reference pass [rad]."""
        return TWO_PI * (self.model.mesh_angle(t) - self._a0) / self.z

    def rates(self, t):
        """Relative angular speed [rad/s] and (not modelled separately) 0 acceleration."""
        w = TWO_PI * self.model.mesh_rate(t) / self.z
        return w, np.zeros_like(w)

    def knot_time_or_nan(self) -> np.ndarray:
        return self.full_t.copy()


def assign_planets_by_tacho(times, tacho_times, planet_angles, gauge_angle: float, order: int,
                            *, key_angle: float = 0.0, tol: float = 0.25) -> np.ndarray:
    """Planet index of each pass of a gauge on the HELD member from a carrier tacho.

    Geometry (``data_schemas/scene.md`` has the figure): ground angles are counted
    counter-clockwise from the tacho probe; planet n sits at carrier-frame angle psi_n
    (planet 1 at 0); the tacho key sits at carrier-frame angle ``key_angle`` and the edge
    fires when the key passes the probe, i.e. when the carrier angle theta_c = -key_angle
    (mod 2 pi). A gauge on the held member at ground angle ``gauge_angle`` meets planet n when
    theta_c + psi_n = gauge_angle (mod 2 pi). theta_c(t) between edges comes from the edges
    (shape-preserving cubic through them); speed ripple of several percent moves it by far
    less than a planet spacing.

    Parameters
    ----------
    times : array_like, shape (m,)
        Pass times [s].
    tacho_times : array_like, shape (r,)
        Tacho edge times [s] (>= 2).
    planet_angles : array_like, shape (N,)
        psi_n [rad].
    gauge_angle : float
        Ground angle of the gauged tooth of the held member [rad].
    order : {+1, -1}
        Sense of the carrier's rotation (+1: counter-clockwise).
    key_angle : float
        Carrier-frame angle of the tacho key relative to planet 1 [rad].
    tol : float
        Largest accepted angular mismatch as a fraction of the smallest planet spacing [-];
        passes further off are labelled -1 (unassigned).

    Returns
    -------
    planet : ndarray of int, shape (m,)
        0-based planet index, -1 when unassigned (outside the tacho span or no planet near).
    """
    t = as_finite_array(times, "times", ndim=1)
    tach = as_finite_array(tacho_times, "tacho_times", ndim=1)
    psi = as_finite_array(planet_angles, "planet_angles", ndim=1, allow_empty=False)
    if order not in (1, -1):
        raise ValueError(f"order must be +1 or -1, got {order!r}")
    out = np.full(t.size, -1, dtype=int)
    if t.size == 0:
        return out
    if tach.size < 2:
        raise ValueError(f"assign_planets_by_tacho needs >= 2 tacho pulses, got {tach.size}")
    k = revolution_numbers(tach)
    theta = PchipInterpolator(tach, -float(key_angle) + TWO_PI * k * order, extrapolate=False)(t)
    ok = np.isfinite(theta)
    # ground angle of planet n: theta_c + psi_n; match against the gauge angle
    d = (gauge_angle - theta[ok, None] - psi[None, :] + math.pi) % TWO_PI - math.pi
    best = np.argmin(np.abs(d), axis=1)
    spacing = np.min(np.diff(np.sort(np.concatenate([psi % TWO_PI, [psi[0] % TWO_PI + TWO_PI]]))))
    good = np.abs(d[np.arange(best.size), best]) <= tol * spacing
    idx = np.flatnonzero(ok)
    out[idx[good]] = best[good]
    return out


@dataclass(frozen=True, eq=False)
class TachoRelabel:
    """A gauge's pattern labels after a carrier tacho's vote on planet 1
    (:func:`relabel_by_tacho`).

    Attributes
    ----------
    planet : ndarray of int, shape (m,)
        0-based planet per pulse, -1 unassigned (moved only when ``accepted``).
    position : ndarray of int, shape (m,)
        Pass-order position per pulse (moved with ``planet``).
    shift : int
        Places along the pass order the tacho's majority moves planet 1 by (-1: no pulse
        was labelled by both).
    agree : int
        Pulses whose tacho label agrees with that shift.
    compared : int
        Pulses labelled both by the pattern and by the tacho.
    accepted : bool
        At least the asked share of the compared pulses agree: the labels moved.
    """

    planet: np.ndarray
    position: np.ndarray
    shift: int
    agree: int
    compared: int
    accepted: bool


def relabel_by_tacho(times, planet, position, tacho_times, planet_angles, gauge_angle: float, *,
                     pass_order: int, carrier_sense: int, key_angle: float = 0.0,
                     agreement: float = 0.8) -> TachoRelabel:
    """Name planet 1 of a held-member gauge's pattern labels with a carrier tacho.

    The pass pattern (:func:`assign_planets_by_pattern`) labels the pulses up to a cyclic
    shift along the pass order; the tacho (:func:`assign_planets_by_tacho`) labels each pulse
    absolutely but loosely. Every pulse labelled by both votes for the shift between the two
    labels; the majority shift is taken when at least ``agreement`` of the votes agree.

    Parameters
    ----------
    times : array_like, shape (m,)
        Pass times [s], increasing.
    planet : array_like of int, shape (m,)
        0-based pattern label per pulse, -1 unassigned.
    position : array_like of int, shape (m,)
        Pass-order position per pulse (``info["position"]`` of the pattern labelling).
    tacho_times : array_like, shape (r,)
        Carrier tacho edges [s] (>= 2 when ``times`` is not empty).
    planet_angles : array_like, shape (N,)
        psi_n [rad].
    gauge_angle : float
        Ground angle of the gauged tooth of the held member [rad].
    pass_order : {+1, -1}
        Sense in which the gauge meets the planets (:func:`pass_order`).
    carrier_sense : {+1, -1}
        Sense of the carrier's rotation (+1: counter-clockwise).
    key_angle : float
        Carrier-frame angle of the tacho key from planet 1 [rad].
    agreement : float
        Share of the compared pulses that must agree, in (0, 1] [-].

    Returns
    -------
    TachoRelabel
    """
    t = as_finite_array(times, "times", ndim=1)
    pl = np.asarray(planet)
    pos = np.asarray(position)
    if pl.shape != t.shape or pos.shape != t.shape:
        raise ValueError(f"planet and position must have the shape of times {t.shape}, got "
                         f"{pl.shape} and {pos.shape}")
    if not 0.0 < float(agreement) <= 1.0:
        raise ValueError(f"agreement must lie in (0, 1], got {agreement!r}")
    psi = as_finite_array(planet_angles, "planet_angles", ndim=1, allow_empty=False)
    n = psi.size
    seq = np.argsort(planet_fractions(psi, pass_order), kind="stable")
    tl = assign_planets_by_tacho(t, tacho_times, psi, gauge_angle, carrier_sense,
                                 key_angle=key_angle)
    both = (tl >= 0) & (pl >= 0)
    if not np.any(both):
        return TachoRelabel(pl, pos, -1, 0, 0, False)
    place = np.empty(n, dtype=np.int64)
    place[seq] = np.arange(n)
    votes = np.bincount(np.mod(place[tl[both]] - place[pl[both]], n), minlength=n)
    best = int(np.argmax(votes))
    agree, compared = int(votes[best]), int(both.sum())
    if votes[best] >= agreement * both.sum():
        new_pl, new_pos = _shift_labels(pl, pos, seq, best)
        return TachoRelabel(new_pl, new_pos, best, agree, compared, True)
    return TachoRelabel(pl, pos, best, agree, compared, False)


def _gap_between(t_a: np.ndarray, t_b: np.ndarray, gaps) -> np.ndarray:
    """True where a gap interval [g0, g1) lies (partly) between t_a and t_b."""
    out = np.zeros(t_a.size, bool)
    if gaps is None:
        return out
    g = np.asarray(gaps, dtype=float).reshape(-1, 2)
    if g.size == 0 or t_a.size == 0:
        return out
    lo = np.minimum(t_a, t_b)
    hi = np.maximum(t_a, t_b)
    g = g[np.argsort(g[:, 0])]
    # any gap starting before hi whose end is after lo
    j = np.searchsorted(g[:, 0], hi, side="left")
    end_max = np.maximum.accumulate(g[:, 1])
    has = j > 0
    out[has] = end_max[j[has] - 1] > lo[has]
    return out


def phasing_from_model(model: AngleModel, train: PassTrain, z_gear: int, n_planets: int, *,
                       gauge: str, gaps=None) -> PassTable:
    """Measured phasing per pass of one gauge train from the recording's angle model.

    gamma = frac(A(t_n) - A(t_1)) with t_1 the planet-1 pass opening the same revolution of
    the same gauge (module notes; A in mesh cycles). Each row's ``uncertainty`` is the
    one-sigma combination of the two onsets' timing (their bound times the train's variance
    factor, which is >= 1), the angle model's own uncertainty of A(t_n) - A(t_1) and the
    spread of that difference over the competing models that explain the passes about as
    well (``choice_sigma``, :meth:`meshphase.kinematics.angles.AngleModel.choice_spread`);
    ``timing_floor`` is the part the two timing bounds alone set.

    Parameters
    ----------
    model : AngleModel
        From :func:`meshphase.kinematics.angle_windows.fit_angle_windows` (``train`` among its trains).
    train : PassTrain
        The gauge's passes (:func:`meshphase.kinematics.trains.gauge_train`).
    z_gear : int
        Tooth count of the gauged gear [-].
    n_planets : int
        N [-].
    gauge : {"sun", "ring"}
        Label carried into the table.
    gaps : array_like, shape (k, 2), optional
        Gap intervals [s] of the recording: a pass whose planet-1 reference lies across a gap
        longer than the train's median interval between passes (less data than anywhere
        else in the record) is dropped, never bridged silently; the count goes into the
        notes. Shorter gaps (dropped samples) take no more angle on trust than the ordinary
        interval between two passes does.

    Returns
    -------
    PassTable
    """
    if not isinstance(model, AngleModel):
        raise TypeError(f"model must be an AngleModel, got {type(model).__name__}")
    if not isinstance(train, PassTrain):
        raise TypeError(f"train must be a PassTrain, got {type(train).__name__}")
    z = as_positive_int(z_gear, "z_gear")
    n = as_positive_int(n_planets, "n_planets")
    notes: list[str] = []
    if len(train) == 0:
        return PassTable.empty(gauge, ["no passes"])
    try:
        out_mask = model.outlier_mask(train.name)
        scale = model.scale_of(train.name)
    except KeyError:
        out_mask = np.zeros(len(train), bool)
        scale = 1.0
    t, pl, pos, sig = train.times, train.planet, train.position, train.sigma
    good = ~out_mask
    rev = np.floor_divide(pos, n)
    r0 = int(rev[good].min())
    nrev = int(rev[good].max()) - r0 + 1
    ref_t = np.full(nrev, np.nan)
    ref_s = np.full(nrev, np.nan)
    one = good & (pl == 0)
    ref_t[rev[one] - r0] = t[one]
    ref_s[rev[one] - r0] = sig[one]
    if np.count_nonzero(np.isfinite(ref_t)) == 0:
        msg = f"{gauge} gauge: no planet-1 pass; phasing relative to planet 1 cannot be measured"
        warnings.warn(msg, ProcessingWarning, stacklevel=2)
        return PassTable.empty(gauge, [msg])
    first = int(np.flatnonzero(np.isfinite(ref_t))[0])
    ref_t, ref_s = ref_t[first:], ref_s[first:]
    r0 += first
    rows = np.flatnonzero(good & (pl > 0) & (rev >= r0))
    ri = rev[rows] - r0
    t1 = ref_t[ri]
    s1 = ref_s[ri]
    missing = ~np.isfinite(t1)
    across = np.zeros(rows.size, bool)
    if gaps is not None and t.size > 1:
        g = np.asarray(gaps, dtype=float).reshape(-1, 2)
        g = g[(g[:, 1] - g[:, 0]) >= float(np.median(np.diff(t)))]
        across[~missing] = _gap_between(t[rows][~missing], t1[~missing], g)
    if np.any(missing):
        notes.append(f"{int(missing.sum())} pass(es) without the planet-1 pass of their "
                     "revolution dropped")
    if np.any(across):
        notes.append(f"{int(across.sum())} pass(es) whose planet-1 reference lies across a gap "
                     "dropped")
    if np.any(out_mask):
        notes.append(f"{int(out_mask.sum())} pass(es) far off the angle model left out")
    keep = ~missing & ~across
    rows, t1, s1, ri = rows[keep], t1[keep], s1[keep], ri[keep]
    tn = t[rows]
    an = model.mesh_angle(tn)
    a1 = model.mesh_angle(t1)
    fn = model.mesh_rate(tn)
    f1 = model.mesh_rate(t1)
    gamma = np.mod(an - a1, 1.0)
    gamma = np.where(gamma >= 1.0, 0.0, gamma)
    floor = np.hypot(fn * sig[rows], f1 * s1) if train.sigma_given else np.full(rows.size, np.nan)
    timing = scale * np.hypot(fn * sig[rows], f1 * s1)
    model_sd = model.difference_std(tn, t1) if rows.size else np.empty(0)
    # two explanations the data cannot tell apart (a common planet-rate ripple, equal planet
    # terms) may share the common term in any split: D, the difference over every phase of
    # that term, is the size of the whole move; with the split unknown (a share uniform in
    # [0, 1], a phase uniform), the chosen end is off by D / sqrt(6), RMS. That counts once
    # it passes what the reliability rule lets an estimated error reach (UNRELIABLE_RATIO x
    # the timing floor), and then the whole D joins the uncertainty (the far end is not
    # ruled out); below it, or below what a small common ripple could do
    # (:data:`meshphase.kinematics.angle_choice.INSEPARABLE_RIPPLE`), the chosen explanation stands and a
    # note names the other
    tol = (UNRELIABLE_RATIO * INSEPARABLE_SHARE * float(np.sqrt(np.mean(floor ** 2)))
           if rows.size else 0.0)
    choice_sd, competitors = model.choice_spread(tn, t1,
                                                 tolerance=tol if math.isfinite(tol) else 0.0)
    for c in competitors:
        if c["inseparable"] and not c["counted"] and c["rms"] > 0.0:
            notes.append(f"{c['words']} and {c['versus']} explain the passes equally well; "
                         f"their phasing differs by {c['rms']:.2g} mesh cycles (RMS), too little "
                         f"to matter (under {UNRELIABLE_RATIO * INSEPARABLE_SHARE:.1f}x the timing "
                         "floor, or within what ordinary shaft-hole errors give): "
                         f"{c['versus']} kept"
                         + (f" (every 1 % of speed ripple at the planet spin rate can move the "
                            f"phasing by up to {c['ripple_bound']:.2g} mesh cycles)"
                            if math.isfinite(c["ripple_bound"]) else ""))
    unc = np.hypot(np.hypot(timing, model_sd), choice_sd)
    a_ref = float(model.mesh_angle(ref_t[:1])[0])
    enc = GaugeEncoder(model, z, ref_t, r0)
    tab = PassTable(gauge, tn, pl[rows].astype(int) + 1, ri, gamma, unc, 1.0 / fn, t1,
                    TWO_PI * (an - a_ref) / z, notes, float(ref_t[0]))
    tab.encoder = enc
    tab.timing_floor = floor
    tab.model_sigma = model_sd
    tab.choice_sigma = choice_sd
    tab.competitors = competitors
    return tab


def measured_phasing(times, planets, z_gear: int, n_planets: int, *, gauge: str = "sun",
                     sigma_t=None, reference_times=None, z_planet: int = 0,
                     positions=None, planet_angles=None, direction: str | None = None) -> PassTable:
    """Phasing per pass of ONE gauge's labelled onsets, with an angle model fitted to them.

    The convenience path for a single pass train (the pipeline fits every gauge and the tacho
    together: :func:`meshphase.kinematics.angle_windows.fit_angle_windows`, :func:`phasing_from_model`). The
    gauged member's angle comes from the train itself (every planet's passes, each at its own
    offset, plus planet-spin terms when ``z_planet`` is given), never from nominal speed.

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
        Which gear carries the gauge.
    sigma_t : float or array_like, optional
        One-sigma onset timing uncertainty [s] (the timing bound), scalar or per onset.
    reference_times : array_like, optional
        Once-per-relative-revolution reference times of this gauge's member [s] (a carrier
        tacho for a gauge on a held ring): an extra angle train, Z_gear mesh cycles apart.
    z_planet : int
        Planet tooth count [-] (0: no planet-spin terms).
    positions : array_like of int, optional
        Pass-order positions (:func:`assign_planets_by_pattern` ``info["position"]``);
        default: counted from the labels (consecutive onsets of one revolution).
    planet_angles : array_like, optional
        psi_n [rad] (default equally spaced) and ``direction`` ("cw"/"ccw") fix the pass
        order; ``direction`` None: the order the labels follow in time.

    Returns
    -------
    PassTable
        Rows for planets 2..N (planet 1 is the reference, gamma = 0 by definition).
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
    if sigma_t is not None:
        sig = np.broadcast_to(np.asarray(sigma_t, dtype=float), t.shape).astype(float)
        if np.any(sig < 0):
            raise ValueError("sigma_t must be >= 0")
    else:
        sig = None
    if t.size == 0:
        return PassTable.empty(gauge, ["no onsets"])
    ok = lab >= 0
    if np.count_nonzero(lab[ok] == 0) < 2:
        msg = (f"{gauge} gauge: fewer than two reference passes ({np.count_nonzero(lab == 0)}); "
               "no relative revolution can be measured")
        warnings.warn(msg, ProcessingWarning, stacklevel=2)
        return PassTable.empty(gauge, [msg])
    if positions is not None:
        if planet_angles is None:
            raise ValueError("positions need planet_angles (and direction) to fix the pass order")
        psi = as_finite_array(planet_angles, "planet_angles", ndim=1, allow_empty=False)
        frac = planet_fractions(psi, pass_order(direction or "cw", gauge))
        pos = np.asarray(positions)[ok]
    else:
        frac, pos = _positions_from_labels(t[ok], lab[ok], n)
    tr = gauge_train(gauge, gauge, t[ok], lab[ok].astype(int), pos.astype(np.int64), frac, z,
                     sigma=None if sig is None else sig[ok])
    trains = [tr]
    if reference_times is not None:
        ref = as_finite_array(reference_times, "reference_times", ndim=1)
        if ref.size >= 2:
            trains.append(tacho_train(ref, float(z)))
    # a lone train knows no shaft ratios but the planet spin (a turn of its own member
    # relative to the carrier is no ripple rate: at the passes it equals the offsets)
    zp = int(z_planet or 0)
    kin = Kinematics(z, z, zp, None, {"planet": float(zp)} if zp > 0 else {}, None)
    model = fit_angle_windows(trains, kin, n)
    tab = phasing_from_model(model, tr, z, n, gauge=gauge)
    tab.notes = list(model.notes) + tab.notes
    return tab


def _positions_from_labels(t: np.ndarray, lab: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Fractions of a revolution per planet and pass-order positions of labelled passes.

    The planet-1 passes count relative revolutions (:func:`revolution_numbers` bridges a
    missing one); every pass gets the revolution count interpolated at its time, whose
    integer part is its revolution and whose fractional part, averaged per planet, is that
    planet's place in the revolution. No planet angles are needed: the angle model's
    per-planet offsets absorb any constant error of the fractions.
    """
    one = lab == 0
    t1 = t[one]
    k1 = revolution_numbers(t1).astype(float)
    slope0 = (k1[1] - k1[0]) / (t1[1] - t1[0])
    slope1 = (k1[-1] - k1[-2]) / (t1[-1] - t1[-2])
    r = np.interp(t, t1, k1)
    r = np.where(t < t1[0], k1[0] + (t - t1[0]) * slope0, r)
    r = np.where(t > t1[-1], k1[-1] + (t - t1[-1]) * slope1, r)
    r = np.where(one, np.rint(r), r)
    k = np.floor(r + 1e-9)
    frac = np.zeros(n)
    for q in range(1, n):
        m = lab == q
        if np.any(m):
            frac[q] = float(np.median(r[m] - k[m]))
        else:
            frac[q] = q / n
    seq = np.argsort(frac, kind="stable")
    place = np.empty(n, dtype=np.int64)
    place[seq] = np.arange(n)
    pos = k.astype(np.int64) * n + place[lab]
    return frac, pos


# ----------------------------------------------------------------------------- the whole recording
@dataclass(frozen=True)
class GaugePasses:
    """The usable pulses of one gauge channel, as the phasing needs them.

    Attributes
    ----------
    name : str
        Channel name.
    gear : {"sun", "ring"}
        Gear carrying the gauge.
    times : ndarray
        Pass times [s], strictly increasing (a fixed feature of each pulse).
    amplitude : ndarray
        Pulse amplitudes [channel units] (planet loads).
    sigma : ndarray or None
        Timing bound of each pass [s].
    main : bool
        The gauge whose passes make the gear's phasing table (others only inform the angle).
    floor_factor : float
        How much the timing bound in the channel's noise spectrum exceeds ``sigma`` (the
        white-noise bound) [-] (:func:`meshphase.kinematics.passes.gauge_passes`): the phasing table's
        ``timing_floor`` and the reliability judgement use ``sigma`` times it, the angle
        model weights the passes by ``sigma`` alone (1: white noise, or no spectrum).
    tooth : int or None
        Index of the gauged tooth on its gear [-] (the channel's ``tooth``), None when not
        known: gauges on one tooth (across its face width) see each planet at the same
        instant, which names their planets alike (:func:`coincident_shift`).
    """

    name: str
    gear: str
    times: np.ndarray
    amplitude: np.ndarray
    sigma: np.ndarray | None = None
    main: bool = True
    floor_factor: float = 1.0
    tooth: int | None = None


@dataclass
class GaugeLabels:
    """Planet labels of one gauge's pulses.

    Attributes
    ----------
    channel : str
    times, amplitude, sigma : ndarray
        As in :class:`GaugePasses`.
    planet : ndarray of int
        0-based planet per pulse, -1 unassigned.
    position : ndarray of int
        Pass-order position per pulse (revolution ``position // N``).
    decided_by : str
        What named planet 1: "tacho", "pattern" (unequal spacing), "amplitude" (planet
        loads), "scene" (the scene's ``[labels]``) or "first pulse" (relative labels).
    n_unassigned : int
    caution : str
        Why planet 1 of these labels is in doubt (two kinds of evidence disagree, or a load
        pattern a carrier-rate load variation explains); empty when nothing is in doubt. Labels
        with a caution count as relative.
    """

    channel: str
    times: np.ndarray
    amplitude: np.ndarray
    sigma: np.ndarray | None
    planet: np.ndarray
    position: np.ndarray
    decided_by: str
    n_unassigned: int = 0
    caution: str = ""


@dataclass
class PhasingResult:
    """Measured phasing of a recording.

    Attributes
    ----------
    tables : dict of str to PassTable
        Per gear ("sun", "ring"): passes of its main gauge.
    labels : dict of str to GaugeLabels
        Per gear: labels of its main gauge.
    model : AngleModel or None
        The angle model of the whole recording.
    fixed : {"ring", "sun", None}
        The held member used; ``fixed_reason`` says how it was decided.
    reliability : dict of str to dict
        Per gear: ``reliable`` (bool), ``reasons`` (list of str), ``error_estimate`` (RMS of
        the per-pass uncertainty [-]), ``floor`` (RMS of the timing floor [-]: the
        Cramer-Rao bound in the gauge's noise spectrum where it has one) and
        ``floor_factor`` (that floor over the white-noise bound's [-]).
    labels_relative : list of str
        Gears whose planet 1 is only the first pulse seen (no absolute reference).
    notes : list of str
    trains : dict of str to PassTrain
        The angle trains by channel (what :func:`relabel_gauge` recomputes from).
    fractions : dict of str to ndarray
        Each channel's planet fractions in pass order [-].
    gaps : ndarray or None
        Gap intervals used [s].
    """

    tables: dict
    labels: dict
    model: AngleModel | None
    fixed: str | None
    fixed_reason: str
    reliability: dict
    labels_relative: list
    notes: list = field(default_factory=list)
    trains: dict = field(default_factory=dict)
    fractions: dict = field(default_factory=dict)
    gaps: np.ndarray | None = None


def relabel_gauge(result: PhasingResult, gear: str, shift: int, gearset) -> tuple:
    """(PassTable, GaugeLabels) of ``gear``'s main gauge with planet 1 moved ``shift`` places
    along its pass order, recomputed from the same angle model (a cyclic relabelling of a
    symmetric layout: what :func:`meshphase.run.stages.stage_identify` tries when a gauge's labels
    are only relative)."""
    lab = result.labels[gear]
    tr = result.trains[lab.channel]
    frac = result.fractions[lab.channel]
    n = gearset.n_planets
    new_tr = relabel_train(tr, shift, frac, n)
    z = gearset.z_sun if gear == "sun" else gearset.z_ring
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ProcessingWarning)
        tab = phasing_from_model(result.model, new_tr, z, n, gauge=gear, gaps=result.gaps)
    tab.time_origin = result.tables[gear].time_origin if gear in result.tables else 0.0
    seq = np.argsort(frac, kind="stable")
    pl, pos = _shift_labels(lab.planet, lab.position, seq, shift)
    new_lab = GaugeLabels(lab.channel, lab.times, lab.amplitude, lab.sigma, pl, pos,
                          lab.decided_by, lab.n_unassigned)
    return tab, new_lab


def _ring_loads(lab: GaugeLabels, n: int):
    """Mean |amplitude| per planet and whether their spread exceeds 5x its standard error
    (only then can the loads tell the sun's planets apart)."""
    a = np.abs(lab.amplitude)
    mean = np.full(n, np.nan)
    se = np.full(n, np.nan)
    for q in range(n):
        x = a[lab.planet == q]
        if x.size >= 2:
            mean[q] = x.mean()
            se[q] = x.std(ddof=1) / math.sqrt(x.size)
    if not np.all(np.isfinite(mean)):
        return None
    ls = n * mean / mean.sum()
    spread = float(np.max(np.abs(ls - 1.0)))
    noise = float(np.max(n * se / mean.sum()))
    return mean if spread > 5.0 * noise else None


#: orders of the load variation fitted against the carrier's phase (once and twice per turn
#: of the carrier relative to the ring gauge) [-]
LOAD_VARIATION_ORDERS = (1, 2)
#: chi-square by which every other cyclic shift must match two load patterns worse than the
#: best for the loads to name planet 1 (a 5-sigma step for one choice among N) [-]
LOAD_SHIFT_MARGIN = 25.0
#: a load variation with the carrier's phase gets a note from this half peak-to-peak swing on
#: (and beyond chance): the 1 %-3 % carrier-rate speed ripples of the rig presets move pulse
#: amplitudes by up to 1 %, measurably but far below the load differences that name planets [-]
LOAD_VARIATION_NOTED = 0.02
#: the best shift's chi-square must lie below this quantile of chi-square with N - 1 degrees
#: of freedom, else the two gauges' load patterns match under no labelling [-]
LOAD_MATCH_QUANTILE = 0.999


@dataclass(frozen=True)
class LoadVariation:
    """A gauge's pulse amplitudes split into per-planet loads and a variation locked to the
    carrier's phase (:func:`carrier_load_variation`):

        ln|a_i| = c[place_i] + sum_m (alpha_m cos(m phi_i) + beta_m sin(m phi_i))

    Attributes
    ----------
    log_loads : ndarray, shape (N,)
        c per pass-order place [ln of the amplitude unit].
    log_loads_se : ndarray, shape (N,)
        Their standard errors [-].
    coef : ndarray, shape (2 K,)
        alpha_1, beta_1, alpha_2, beta_2, ... [-].
    cov : ndarray, shape (2 K, 2 K)
        Their covariance [-].
    orders : tuple of int
        The K orders m [-].
    n_pulses : int
        Pulses fitted.
    """

    log_loads: np.ndarray
    log_loads_se: np.ndarray
    coef: np.ndarray
    cov: np.ndarray
    orders: tuple
    n_pulses: int

    def _basis(self, phase) -> np.ndarray:
        ph = np.asarray(phase, dtype=np.float64)[..., None] * np.asarray(self.orders)
        return np.stack([np.cos(ph), np.sin(ph)], axis=-1).reshape(*ph.shape[:-1],
                                                                    2 * len(self.orders))

    def log_factor(self, phase) -> tuple[np.ndarray, np.ndarray]:
        """ln of the amplitude factor [-] at carrier phases ``phase`` [rad], and its standard
        error [-]."""
        b = self._basis(phase)
        return b @ self.coef, np.sqrt(np.einsum("...i,ij,...j->...", b, self.cov, b))

    @property
    def swing(self) -> float:
        """Half the peak-to-peak amplitude factor over one turn [-] (0.25: +-25 %)."""
        f = np.exp(self.log_factor(np.linspace(0.0, TWO_PI, 361))[0])
        return float(0.5 * np.ptp(f) / np.mean(f))

    @property
    def chi2(self) -> float:
        """Wald statistic of the variation against none [-] (chi-square with 2 K degrees of
        freedom when there is none)."""
        return float(self.coef @ linalg.lstsq(self.cov, self.coef, check_finite=False)[0])


def carrier_load_variation(phase, amplitudes, place, n_places: int, *,
                           orders=LOAD_VARIATION_ORDERS) -> LoadVariation | None:
    """Per-planet loads and the load variation with the carrier's phase, from the pulses of a
    gauge that meets every planet at every carrier phase (the sun gauge when the ring is
    held).

    A once-per-carrier-turn torque ripple scales every planet's pulses by one function of the
    carrier angle. A gauge on the held member meets each planet at one carrier angle only, so
    its per-planet amplitudes are the loads times that function there; a gauge that meets the
    planets at every carrier angle measures both apart: ln|a| is fitted (least squares by
    SVD) as a constant per place plus a Fourier series of ``orders`` in the phase.

    Parameters
    ----------
    phase : array_like, shape (m,)
        Carrier phase at each pulse [rad] (any fixed origin).
    amplitudes : array_like, shape (m,)
        Pulse amplitudes [channel units], non-zero.
    place : array_like of int, shape (m,)
        Pass-order place 0..N-1 of each pulse (the cyclic labelling does not matter).
    n_places : int
        N, the planets [-].
    orders : sequence of int
        Orders m of the variation [-].

    Returns
    -------
    LoadVariation or None
        None when the pulses cannot separate the two: fewer than two pulses in a place, fewer
        than twice as many pulses as parameters, or phases that do not spread over a turn.
    """
    ph = as_finite_array(phase, "phase", ndim=1)
    a = np.abs(as_finite_array(amplitudes, "amplitudes", ndim=1))
    q = np.asarray(place)
    n = as_positive_int(n_places, "n_places")
    ords = tuple(as_positive_int(m, "orders") for m in np.atleast_1d(orders))
    if a.shape != ph.shape or q.shape != ph.shape:
        raise ValueError(f"phase, amplitudes and place must have one value per pulse, got shapes "
                         f"{ph.shape}, {a.shape} and {q.shape}")
    if not ords:
        raise ValueError("orders must name at least one order, got none")
    if q.size and (not np.issubdtype(q.dtype, np.integer) or q.min() < 0 or q.max() >= n):
        raise ValueError(f"place must hold integers 0..{n - 1}, got {np.unique(q)[:8]!r}")
    if np.any(a == 0):
        raise ValueError(f"amplitudes must be non-zero (their log is fitted), got "
                         f"{np.count_nonzero(a == 0)} zero(s)")
    k = 2 * len(ords)
    if ph.size < 2 * (n + k) or np.any(np.bincount(q, minlength=n) < 2):
        return None
    X = np.concatenate([np.eye(n)[q], np.zeros((ph.size, k))], axis=1)
    lv = LoadVariation(np.zeros(n), np.zeros(n), np.zeros(k), np.eye(k), ords, int(ph.size))
    X[:, n:] = lv._basis(ph)
    U, sv, Vt = linalg.svd(X, full_matrices=False, check_finite=False)
    if sv[-1] <= 1e-6 * sv[0]:
        return None
    y = np.log(a)
    beta = Vt.T @ ((U.T @ y) / sv)
    resid = y - X @ beta
    s2 = float(resid @ resid) / (ph.size - n - k)
    cov = s2 * (Vt.T / sv ** 2) @ Vt
    se = np.sqrt(np.diag(cov))
    return LoadVariation(beta[:n], se[:n], beta[n:], cov[n:, n:], ords, int(ph.size))


def load_shift_chi2(loads, loads_se, reference, reference_se, seq) -> np.ndarray:
    """How well a gauge's per-place loads match a reference gauge's per-planet loads under
    each cyclic labelling: chi-square per shift s, place q taken as planet
    ``seq[(q + s) % N]`` (what :func:`_shift_labels` does).

    Both patterns are logs of loads (any gauge's scale: a common offset is fitted per
    shift, weighted by the summed variances).

    Parameters
    ----------
    loads, loads_se : array_like, shape (N,)
        ln load per pass-order place and its standard error [-].
    reference, reference_se : array_like, shape (N,)
        ln load per planet (0-based) and its standard error [-].
    seq : array_like of int, shape (N,)
        Planets in pass order (``argsort`` of :func:`planet_fractions`).

    Returns
    -------
    ndarray, shape (N,)
        chi-square of each shift [-] (N - 1 degrees of freedom).
    """
    c = as_finite_array(loads, "loads", ndim=1)
    cs = as_finite_array(loads_se, "loads_se", ndim=1)
    r = as_finite_array(reference, "reference", ndim=1)
    rs = as_finite_array(reference_se, "reference_se", ndim=1)
    sq = np.asarray(seq)
    n = c.size
    if not (cs.size == r.size == rs.size == sq.size == n):
        raise ValueError(f"loads, loads_se, reference, reference_se and seq must have one value "
                         f"per planet, got sizes {[c.size, cs.size, r.size, rs.size, sq.size]}")
    if n and (np.any(cs <= 0) or np.any(rs <= 0)):
        raise ValueError(f"standard errors must be positive, got loads_se {cs!r}, "
                         f"reference_se {rs!r}")
    if n and not np.array_equal(np.sort(sq), np.arange(n)):
        raise ValueError(f"seq must be a permutation of 0..{n - 1}, got {sq!r}")
    idx = sq[(np.arange(n)[None, :] + np.arange(n)[:, None]) % n] if n else np.zeros((0, 0), int)
    d = c[None, :] - r[idx]                          # (shift, place)
    w = 1.0 / (cs[None, :] ** 2 + rs[idx] ** 2)
    mean = np.sum(w * d, axis=1, keepdims=True) / np.sum(w, axis=1, keepdims=True) if n else d
    return np.sum(w * (d - mean) ** 2, axis=1)


def _shift_labels(planet, position, seq, shift):
    """Relabel cyclically in pass order by ``shift`` places (planet 1 moves)."""
    n = seq.size
    pos = position + shift
    return np.where(planet >= 0, seq[np.mod(pos, n)], -1), pos


def measure_phasing(passes, gearset, *, fixed=None, fixed_reason: str = "",
                    tacho_times=None, key_angle: float | None = None, mounts=None,
                    speeds=None, gaps=None, carrier_sense: int | None = None,
                    check_held: bool = False, speeds_resolution=None,
                    label_shifts=None, encoders=None) -> PhasingResult:
    """Label every gauge's pulses, fit one angle model to all of them and the tacho, and
    measure the phasing of each gear's main gauge.

    Parameters
    ----------
    passes : sequence of GaugePasses
        Every sun, ring and face-width gauge with its usable pulses.
    gearset : Gearset
    fixed : {"ring", "sun", None}
        Held member (:func:`meshphase.kinematics.shafts.held_member`); ``fixed_reason`` says why.
    tacho_times : array_like, optional
        Carrier tacho edges [s]: an angle train when a member is held, and planet 1 of the
        held member's gauge when ``key_angle`` and that gauge's ``mounts`` entry are known.
    key_angle : float, optional
        Carrier-frame angle of the tacho key from planet 1 [rad].
    mounts : dict of str to float, optional
        Ground angle of each gauge on the held member [rad], from the tacho probe.
    speeds : Speeds, optional
        Nominal speeds (shaft ratios of a differential; the carrier's sense).
    gaps : array_like, shape (k, 2), optional
        Gap intervals [s]: a pass whose reference lies across one is dropped.
    carrier_sense : {+1, -1}, optional
        Sense of the carrier's rotation (default from the direction and the held member).
    check_held : bool
        Decide the held member again from the data (mesh cycles per carrier turn measured
        between tacho edges, :func:`meshphase.kinematics.trains.mesh_cycles_per_carrier_turn`) together
        with ``speeds`` and their typed ``speeds_resolution``
        (:func:`meshphase.kinematics.shafts.held_member`); ``fixed`` is then only the starting guess.
    label_shifts : dict of str to int, optional
        Per gear ("sun", "ring"): planet 1 of its main gauge is this many places along the
        pass order from its first pulse [-] (the scene's ``[labels]``); what the data say
        otherwise is then only a note.
    encoders : sequence of tuple, optional
        Shaft encoders as angle trains, each ``(name, shaft, pulses_per_rev, edge times [s],
        edge sigma [s] or None)`` (shaft "sun", "input", "carrier" or "ring"; edges from
        :func:`meshphase.kinematics.encoder.edge_times`); used when a member is held.

    Returns
    -------
    PhasingResult
    """
    n = gearset.n_planets
    notes: list[str] = []
    passes = [p for p in passes if isinstance(p, GaugePasses)]
    mounts = dict(mounts or {})
    tach = None if tacho_times is None else np.asarray(tacho_times, dtype=float)
    if check_held and tach is not None and tach.size >= 2 and passes:
        fixed, fixed_reason = _held_from_data(passes, gearset, tach, speeds, speeds_resolution,
                                              (fixed, fixed_reason))
    if carrier_sense is None:
        # clockwise planets: the sun turns counter-clockwise relative to the carrier; with
        # the ring held the carrier turns with the sun (ccw), with the sun held against it
        cw = gearset.direction == "cw"
        carrier_sense = (1 if cw else -1) * (1 if fixed != "sun" else -1)
    held = _HeldGauges(fixed, tach, key_angle, mounts, carrier_sense)
    labels, all_labels, relative = _label_gauges(passes, gearset, held, notes,
                                                 dict(label_shifts or {}))
    trains, train_of = _gauge_trains(all_labels, gearset)
    # one angle model from every train (and the tacho when a member is held)
    kin = kinematics(gearset.z_sun, gearset.z_ring, gearset.z_planet, fixed=fixed, speeds=speeds)
    # the planet terms are shared by every gauge, so every gauge must name the same physical
    # planet alike: align the relatively labelled gauges to the absolute ones (or to the
    # largest), by the planets' own offsets where they differ enough to tell
    symmetric = bool(np.allclose(np.diff(np.sort(planet_fractions(gearset.angles, 1))), 1.0 / n,
                                 atol=1e-9))
    if symmetric and n > 1 and kin.planet_period and len(train_of) > 1:
        trains, train_of = _align_labels(trains, train_of, all_labels, labels, kin, n, notes)
        relative = [gear for gear, lab in labels.items()
                    if lab.decided_by == "first pulse" or lab.caution]
    if fixed is not None and tach is not None and tach.size >= 2 and kin.tacho_cycles:
        trains.append(tacho_train(tach, kin.tacho_cycles))
    elif tach is not None and tach.size >= 2 and fixed is None:
        notes.append("differential rig: the carrier tacho does not fix the mesh angle (no held "
                     "member); it is not used")
    n_before = len(trains)
    trains += _encoder_trains(encoders, kin, notes)
    model = None
    tables: dict = {}
    reliability: dict = {}
    if any(tr.kind in ("sun", "ring") and len(tr) >= 2 for tr in trains):
        # an encoder samples the mesh angle many times per planet spin: a common speed
        # ripple at the planet rate is then told from the planets' own terms and is tried
        extra = {"planet_ripple": True} if len(trains) > n_before else {}
        model = fit_angle_windows(trains, kin, n, **extra)
        notes.extend(model.notes)
        unseen = unseen_ripples(trains, kin)
        for shaft, _ in unseen:
            notes.append(f"a speed ripple locked to the {shaft} angle is not seen by "
                         f"{' and '.join(tr.name for tr in trains)}: they meet the {shaft} at "
                         "fixed angles only")
        factors = {p.name: float(getattr(p, "floor_factor", 1.0)) for p in passes}
        tables, reliability = _gear_tables(model, labels, train_of, gearset, gaps, factors,
                                           unseen)
    return PhasingResult(tables, labels, model, fixed, fixed_reason, reliability, relative, notes,
                         dict(train_of), {nm: v[1] for nm, v in all_labels.items()},
                         None if gaps is None else np.asarray(gaps, dtype=float))


def _encoder_trains(encoders, kin: Kinematics, notes: list) -> list:
    """Angle trains of the encoders (:func:`meshphase.kinematics.trains.encoder_train`), their edges
    cleaned (:func:`meshphase.kinematics.encoder.clean_edges`, counts in ``notes``); an encoder that
    cannot observe the mesh angle (a differential, a held shaft) is named in ``notes``."""
    out = []
    for name, shaft, ppr, times, sigma in encoders or ():
        ppr = as_positive_int(ppr, f"encoder {name!r} pulses_per_rev")
        if kin.fixed is None:
            notes.append(f"differential rig: encoder {name} on the {shaft} shaft does not fix the "
                         "mesh angle (no held member); it is not used")
            continue
        try:
            per_rev = shaft_cycles(kin, shaft)
        except ValueError as exc:
            notes.append(f"encoder {name}: {exc}; it is not used")
            continue
        edges = clean_edges(np.asarray(times, dtype=float))
        pieces = split_at_gaps(edges)
        notes.append(f"encoder {name} ({shaft} shaft, {ppr} pulses per turn, "
                     f"{per_rev / ppr:.4g} mesh cycles per pulse): {edges.summary()}"
                     + (f"; counted anew after {len(pieces) - 1} gap(s) of more than "
                        f"{MAX_GAP_PULSES} pulses" if len(pieces) > 1 else ""))
        if edges.n_extra or edges.n_missing:
            warnings.warn(f"encoder {name}: {edges.n_extra} extra edge(s) dropped (glitches), "
                          f"{edges.n_missing} missing edge(s) counted", DataQualityWarning,
                          stacklevel=3)
        for q, piece in enumerate(pieces):
            if len(piece) >= 2:
                out.append(encoder_train(piece, per_rev / ppr, sigma=sigma,
                                         name=name if q == 0 else f"{name} [{q + 1}]"))
    return out


def _held_from_data(passes, gearset, tach: np.ndarray, speeds, resolution, given: tuple) -> tuple:
    """(held member, reason) from the data: mesh cycles per carrier turn, counted over one
    tacho interval on the busiest gauge's pass pattern (which pulse is planet 1 does not
    matter for a count), with the nominal ``speeds`` (:func:`meshphase.kinematics.shafts.held_member`);
    ``given`` when the count cannot be made."""
    psi = gearset.angles
    p0 = max(passes, key=lambda p: p.times.size)
    o0 = pass_order(gearset.direction, p0.gear)
    pl0, inf0 = assign_planets_by_pattern(p0.times, psi, o0)
    ok0 = pl0 >= 0
    if np.count_nonzero(ok0) < 2:
        return given
    z0 = gearset.z_sun if p0.gear == "sun" else gearset.z_ring
    tr0 = gauge_train(p0.name, p0.gear, p0.times[ok0], pl0[ok0].astype(int),
                      inf0["position"][ok0].astype(np.int64), planet_fractions(psi, o0), z0)
    ratio = mesh_cycles_per_carrier_turn(tr0, tach)
    if not math.isfinite(ratio):
        return given
    return held_member(gearset.z_sun, gearset.z_ring, speeds, resolution=resolution,
                       mesh_rate=ratio, carrier_rate=1.0)


@dataclass(frozen=True)
class _HeldGauges:
    """What names planet 1 of a gauge on the held member: the held member, the tacho edges
    [s], the key's carrier-frame angle [rad], the gauges' ground angles [rad] and the
    carrier's sense (+1 counter-clockwise)."""

    fixed: str | None
    tacho: np.ndarray | None
    key_angle: float | None
    mounts: dict
    carrier_sense: int

    def applies(self, p: GaugePasses, planet: np.ndarray) -> bool:
        return (p.gear == self.fixed and p.name in self.mounts and self.key_angle is not None
                and self.tacho is not None and self.tacho.size >= 2 and bool(np.any(planet >= 0)))


def _label_gauges(passes, gearset, held: _HeldGauges, notes: list,
                  shifts: dict | None = None) -> tuple[dict, dict, list]:
    """Planet labels of every gauge, ring gauges first (their loads may name the sun's
    planets): by the pass pattern, then by the tacho for a gauge on the held member; a main
    gauge whose gear has an entry in ``shifts`` takes planet 1 from it (:func:`_pinned`).

    Returns (labels of each gear's main gauge, {channel: (labels, fractions, passes)} of
    every gauge, gears whose labels are relative)."""
    psi = gearset.angles
    n = gearset.n_planets
    labels: dict = {}
    all_labels: dict = {}
    relative: list = []
    ring_load = None
    for p in sorted(passes, key=lambda p: (p.gear != "ring", not p.main)):
        order = pass_order(gearset.direction, p.gear)
        frac = planet_fractions(psi, order)
        ref = ring_load if (p.gear == "sun" and p.main) else None
        pl, inf = assign_planets_by_pattern(p.times, psi, order, amplitudes=np.abs(p.amplitude),
                                            reference_amplitudes=ref)
        pos = inf["position"]
        decided = {"pattern": "pattern", "amplitude": "amplitude"}.get(inf["shift_decided_by"],
                                                                         "first pulse")
        if inf.get("ambiguous"):
            decided = "first pulse"
        caution = ""
        if ref is not None or (p.gear == "sun" and p.main and "ring" in labels):
            # the loads as the ring gauge sees them against the sun's once the load variation
            # with the carrier's phase is divided out
            pl0, inf0 = assign_planets_by_pattern(p.times, psi, order)
            pl, pos, decided, caution = _sun_by_loads(p, pl0, inf0["position"],
                                                      (pl, pos, decided), labels["ring"],
                                                      gearset, notes)
        if held.applies(p, pl):
            vote = relabel_by_tacho(p.times, pl, pos, held.tacho, psi, held.mounts[p.name],
                                    pass_order=order, carrier_sense=held.carrier_sense,
                                    key_angle=held.key_angle)
            pl, pos = vote.planet, vote.position
            if vote.accepted:
                decided, caution = "tacho", ""
            elif vote.compared:
                notes.append(f"{p.name}: the tacho and the pass pattern disagree on planet 1 "
                             f"({vote.agree} of {vote.compared} passes agree); labels "
                             "left relative")
        if p.main and p.gear not in labels and p.gear in (shifts or {}):
            pl, pos, decided, caution = _pinned(p, pl, pos, decided, shifts[p.gear], gearset,
                                                notes)
        lab = GaugeLabels(p.name, p.times, p.amplitude, p.sigma, pl, pos, decided,
                          int(inf.get("n_unassigned", 0)), caution)
        all_labels[p.name] = (lab, frac, p)
        if p.main and p.gear not in labels:
            labels[p.gear] = lab
            if decided == "first pulse" or caution:
                relative.append(p.gear)
            if p.gear == "ring" and np.any(pl >= 0):
                ring_load = _ring_loads(lab, n)
    return labels, all_labels, relative


def _pinned(p: GaugePasses, pl, pos, decided: str, shift: int, gearset, notes: list) -> tuple:
    """(planet, position, "scene", "") of a main gauge whose planet 1 the scene fixes
    ``shift`` places along its pass order from its first pulse; a note when the labels the
    data gave (``pl``, ``pos``, named by ``decided``) put planet 1 elsewhere."""
    n = gearset.n_planets
    order = pass_order(gearset.direction, p.gear)
    seq = np.argsort(planet_fractions(gearset.angles, order), kind="stable")
    pl0, inf0 = assign_planets_by_pattern(p.times, gearset.angles, order)
    new_pl, new_pos = _shift_labels(pl0, inf0["position"], seq, int(shift) % n)
    ok = (new_pl >= 0) & (pl >= 0)
    if decided != "first pulse" and np.any(ok):
        d = int(np.mod(pos[ok][0] - new_pos[ok][0], n))
        if d:
            by = {"amplitude": "loads", "pattern": "pass pattern"}.get(decided, decided)
            notes.append(f"{p.name}: the scene's {p.gear}_shift = {shift} puts planet 1 {d} "
                         f"place(s) from where the {by} name(s) it; the scene's is used")
    return new_pl, new_pos, "scene", ""


def _ring_clock(lab: GaugeLabels, gearset):
    """Turns of the carrier relative to the ring gauge [-] as a function of time [s]: the
    ring gauge's labelled pulses at their pass-order positions (revolution plus the planet's
    fraction), joined by a shape-preserving cubic (NaN outside them); None with fewer than
    three labelled pulses."""
    n = gearset.n_planets
    ok = lab.planet >= 0
    if np.count_nonzero(ok) < 3:
        return None
    fs = np.sort(planet_fractions(gearset.angles, pass_order(gearset.direction, "ring")))
    pos = lab.position[ok].astype(np.int64)
    turns = pos // n + fs[pos % n]
    t = lab.times[ok]
    if np.any(np.diff(turns) <= 0):
        return None
    return PchipInterpolator(t, turns, extrapolate=False)



def _chi2_quantile(q: float, dof: int) -> float:
    """The chi-square distribution's ``q`` quantile with ``dof`` degrees of freedom [-]
    (``scipy.stats.chi2.ppf``, from the regularised incomplete gamma function: scipy.stats
    costs a processing run's start half a second)."""
    return float(2.0 * special.gammaincinv(0.5 * dof, q))

def _sun_by_loads(p: GaugePasses, pl, pos, raw: tuple, ring: GaugeLabels, gearset,
                  notes: list) -> tuple:
    """The sun gauge's planet 1 from the planets' loads, checked against a load variation
    with the carrier's phase (:func:`carrier_load_variation` on the sun's pulses, the phase
    from the ring gauge's pulses): the ring gauge's per-planet loads divided by that
    variation must match the sun's per-place loads under one cyclic shift clearly
    (:func:`load_shift_chi2`, ``LOAD_SHIFT_MARGIN``, ``LOAD_MATCH_QUANTILE``).

    ``pl``, ``pos`` are the pattern labels with planet 1 the first pulse, ``raw`` the
    (planet, position, decided_by) of the loads as the ring gauge sees them
    (:func:`assign_planets_by_pattern` with ``reference_amplitudes``). Returns (planet,
    position, decided_by, caution): the labels moved to the clear shift ("amplitude"), else
    ``raw`` when it did not use the loads, else relative ("first pulse") with a caution
    naming why the ring gauge's loads do not name the sun's planet 1."""
    n = gearset.n_planets
    if n < 2 or raw[2] not in ("amplitude", "first pulse"):
        return (*raw, "")
    seq = np.argsort(planet_fractions(gearset.angles, pass_order(gearset.direction, "sun")),
                     kind="stable")
    ok = pl >= 0
    clock = _ring_clock(ring, gearset)
    lv = cnt = None
    if clock is not None:
        ph = TWO_PI * clock(p.times[ok])
        use = np.isfinite(ph) & (np.abs(p.amplitude[ok]) > 0)
        lv = carrier_load_variation(ph[use], p.amplitude[ok][use], np.mod(pos[ok][use], n), n)
    if lv is not None:
        rk = ring.planet >= 0
        lf, lf_se = lv.log_factor(TWO_PI * clock(ring.times[rk]))
        ra = np.abs(ring.amplitude[rk])
        keep = np.isfinite(lf) & (ra > 0)
        y, lf_se, rpl = np.log(ra[keep]) - lf[keep], lf_se[keep], ring.planet[rk][keep]
        cnt = np.bincount(rpl, minlength=n)
    if lv is None or np.any(cnt < 2):
        if raw[2] != "amplitude":
            return (*raw, "")
        cause = ("the ring gauge's per-planet loads name planet 1 of the sun gauge, but the sun "
                 "gauge's pulses cannot measure the load variation with the carrier's phase "
                 "those loads may hold; planet 1 is the first pulse seen")
        notes.append(f"{p.name}: {cause}")
        return pl, pos, "first pulse", cause
    mean = np.bincount(rpl, y, n) / cnt
    var = np.bincount(rpl, (y - mean[rpl]) ** 2, n) / np.maximum(cnt - 1, 1)
    fse = np.sqrt(np.bincount(rpl, lf_se ** 2, n) / cnt)
    rse = np.maximum(np.sqrt(var / cnt + fse ** 2), 1e-12)
    chi2 = load_shift_chi2(lv.log_loads, np.maximum(lv.log_loads_se, 1e-12), mean, rse, seq)
    order = np.argsort(chi2, kind="stable")
    best, next_ = int(order[0]), float(chi2[order[1]])
    limit = _chi2_quantile(LOAD_MATCH_QUANTILE, n - 1)
    clear = bool(next_ - chi2[best] > LOAD_SHIFT_MARGIN and chi2[best] < limit)
    swing = f"+-{100 * lv.swing:.0f} %"
    fit = f"chi-square {chi2[best]:.1f} vs {next_:.1f} next, {n - 1} degrees of freedom"
    raw_shift = int(np.mod(raw[1][ok][0] - pos[ok][0], n)) if np.any(ok) else 0
    if lv.swing >= LOAD_VARIATION_NOTED and lv.chi2 > _chi2_quantile(LOAD_MATCH_QUANTILE, lv.coef.size):
        notes.append(f"{p.name}: a load variation of {swing} with the carrier's phase (Wald "
                     f"chi-square {lv.chi2:.0f}, {lv.coef.size} degrees of freedom): a ring gauge "
                     "meets each planet at one carrier phase, so its per-planet amplitudes, and a "
                     "load sharing from them, carry it")
    if clear:
        new_pl, new_pos = _shift_labels(pl, pos, seq, best)
        if raw[2] == "amplitude" and raw_shift != best:
            notes.append(f"{p.name}: planet 1 named by the loads once divided by the load "
                         f"variation of {swing} with the carrier's phase the sun gauge measures "
                         f"({fit}); the ring gauge's loads as seen name it "
                         f"{(raw_shift - best) % n} place(s) on")
        return new_pl, new_pos, "amplitude", ""
    if raw[2] != "amplitude":
        return (*raw, "")
    how = ("match the sun gauge's under no labelling" if chi2[best] >= limit
           else "do not tell the planets apart")
    cause = (f"the ring gauge's per-planet loads name planet 1 of the sun gauge, but divided by "
             f"the load variation of {swing} with the carrier's phase that the sun gauge "
             f"measures they {how} ({fit}); planet 1 is the first pulse seen")
    notes.append(f"{p.name}: {cause}")
    return pl, pos, "first pulse", cause


def _gauge_trains(all_labels: dict, gearset) -> tuple[list, dict]:
    """The angle train of every gauge with two or more labelled passes
    (:func:`meshphase.kinematics.trains.gauge_train`), as a list and by channel."""
    trains, train_of = [], {}
    for name, (lab, frac, p) in all_labels.items():
        ok = lab.planet >= 0
        if np.count_nonzero(ok) < 2:
            continue
        z = gearset.z_sun if p.gear == "sun" else gearset.z_ring
        sig = None if p.sigma is None else np.asarray(p.sigma)[ok]
        tr = gauge_train(name, p.gear, p.times[ok], lab.planet[ok].astype(int),
                         lab.position[ok].astype(np.int64), frac, z, sigma=sig,
                         order=pass_order(gearset.direction, p.gear))
        trains.append(tr)
        train_of[name] = tr
    return trains, train_of


def _gear_tables(model: AngleModel, labels: dict, train_of: dict, gearset, gaps,
                 factors=None, unseen=()) -> tuple[dict, dict]:
    """Per gear with a main-gauge train: its phasing table from the angle model
    (:func:`phasing_from_model`), its timing floor times the gauge's floor factor (``factors``
    by channel, :attr:`GaugePasses.floor_factor`: both passes of a row are the gauge's), and
    its reliability (:func:`_reliability`)."""
    n = gearset.n_planets
    tables: dict = {}
    reliability: dict = {}
    for gear, lab in labels.items():
        tr = train_of.get(lab.channel)
        if tr is None:
            continue
        z = gearset.z_sun if gear == "sun" else gearset.z_ring
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ProcessingWarning)
            tab = phasing_from_model(model, tr, z, n, gauge=gear, gaps=gaps)
        factor = (factors or {}).get(lab.channel, 1.0)
        if tab.timing_floor is not None and factor != 1.0:
            tab.timing_floor = tab.timing_floor * factor
        tables[gear] = tab
        reliability[gear] = {**_reliability(model, tr, tab, unseen), "floor_factor": float(factor)}
    return tables, reliability


#: a gauge's passes are matched to a gauge on the same tooth when they fall within this
#: fraction of the median pass interval of each other [-]
COINCIDENT_TOL = 0.25
#: coincident passes needed, and the share of them that must name the same shift [-]
COINCIDENT_MIN = 8
COINCIDENT_AGREE = 0.9


def nearest_index(sorted_times: np.ndarray, t) -> np.ndarray:
    """Index of the entry of ``sorted_times`` (increasing, at least two) nearest each of
    ``t`` (a tie goes to the later one)."""
    u = np.asarray(sorted_times, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)
    k = np.clip(np.searchsorted(u, t), 1, u.size - 1)
    return np.where(np.abs(u[k - 1] - t) < np.abs(u[k] - t), k - 1, k)


def coincident_shift(train, reference, n_planets: int) -> tuple[int | None, int, int]:
    """The cyclic relabelling of ``train`` (:func:`meshphase.kinematics.trains.relabel_train`) that
    gives its passes the planets of the ``reference`` train's passes at the same instants.

    Two gauges on one tooth (across its face width) meet each planet at the same time, so a
    pass of one within ``COINCIDENT_TOL`` of the median pass interval of a pass of the other
    is the same planet's, and their pass-order positions differ by the relabelling sought
    (mod ``n_planets``). Gauges on different teeth must not be compared so: a tooth one
    planet spacing further on is passed at the same instants by the next planet.

    Returns
    -------
    (shift, agree, compared) : (int or None, int, int)
        The shift 0..N-1 named by at least ``COINCIDENT_AGREE`` of the ``compared``
        coincident passes (``agree`` of them), or None (fewer than ``COINCIDENT_MIN``
        coincident passes, or no clear majority).
    """
    n = as_positive_int(n_planets, "n_planets")
    t = np.asarray(train.times, dtype=np.float64)
    u = np.asarray(reference.times, dtype=np.float64)
    if t.size == 0 or u.size < 2:
        return None, 0, 0
    k = nearest_index(u, t)
    tol = COINCIDENT_TOL * float(np.median(np.diff(u)))
    ok = np.abs(u[k] - t) <= tol
    compared = int(np.count_nonzero(ok))
    if compared < COINCIDENT_MIN:
        return None, 0, compared
    d = np.mod(np.asarray(reference.position)[k[ok]] - np.asarray(train.position)[ok], n)
    votes = np.bincount(d.astype(np.int64), minlength=n)
    shift = int(np.argmax(votes))
    agree = int(votes[shift])
    if agree < COINCIDENT_AGREE * compared:
        return None, agree, compared
    return shift, agree, compared


def _same_tooth_ref(p, refs, all_labels):
    """The first reference gauge on the same gear and tooth as passes ``p``, or None."""
    if p.tooth is None:
        return None
    for r in refs:
        q = all_labels[r][2]
        if q.gear == p.gear and q.tooth is not None and q.tooth == p.tooth:
            return r
    return None


def _align_labels(trains, train_of, all_labels, labels, kin, n, notes):
    """Relabel relatively labelled gauge trains cyclically so that their planet numbers name
    the same planets as the reference trains'. A gauge on the same tooth as a reference
    gauge takes the shift its coincident passes name (:func:`coincident_shift`). Otherwise
    the shifts are fitted (:func:`meshphase.kinematics.label_shift.label_shift_costs`), and one is taken
    only when its misfit stands clearly apart (the next best is worse by more than 25 times
    the fit's variance per observation); else the planets' offsets look alike, nothing is
    changed and a note says so."""
    absolute = [nm for nm in train_of
                if all_labels[nm][0].decided_by in ("tacho", "pattern", "scene")]
    rel = [nm for nm in train_of if nm not in absolute]
    if not rel:
        return trains, train_of
    refs = absolute or [max(rel, key=lambda nm: len(train_of[nm]))]
    ref_kind = "absolute" if absolute else "relative"
    todo = [nm for nm in rel if nm not in refs]
    for nm in sorted(todo, key=lambda nm: -len(train_of[nm])):
        lab, frac, p = all_labels[nm]
        tr = train_of[nm]
        twin = _same_tooth_ref(p, refs, all_labels)
        shift = None
        if twin is not None:
            shift, agree, compared = coincident_shift(tr, train_of[twin], n)
            if shift is None:
                notes.append(f"{nm}: its passes and those of {twin} (the same tooth) do not "
                             f"coincide clearly ({agree} of {compared} name one planet); the "
                             "planets' offsets decide instead")
        same_tooth = shift is not None
        if same_tooth:
            by = [twin]
            why = f"the same tooth: {agree} of {compared} passes coincide"
        else:
            costs = label_shift_costs([train_of[r] for r in refs], tr, frac, kin, n)
            if not np.all(np.isfinite(costs)):
                continue
            order = np.argsort(costs)
            best, second = float(costs[order[0]]), float(costs[order[1]])
            n_obs = sum(len(train_of[r]) for r in refs) + len(tr)
            var = max(best / max(n_obs, 1), 1e-300)
            if second - best <= 25.0 * var:
                notes.append(f"{nm}: the planets' own offsets look too alike to tell which of "
                             f"its pulses is which planet from the {', '.join(refs)} gauge(s)")
                refs.append(nm)
                continue
            shift = int(order[0])
            by = list(refs)
            why = f"the planets' own offsets: misfit {best:.3g} vs {second:.3g} next"
            if shift and lab.decided_by == "amplitude" and ref_kind == "absolute":
                lab.caution = _disagreement(p, lab, [all_labels[r] for r in refs], shift, n, why)
                notes.append(f"{nm}: {lab.caution}")
        if shift:
            new = relabel_train(tr, shift, frac, n)
            train_of[nm] = new
            trains = [new if t.name == nm else t for t in trains]
            seq = np.argsort(frac, kind="stable")
            pl, pos = _shift_labels(lab.planet, lab.position, seq, shift)
            lab.planet, lab.position = pl, pos
        if same_tooth:
            # as absolute as the twin's own labels
            if all_labels[twin][0].decided_by != "first pulse":
                lab.decided_by = f"same tooth (as {twin})"
        elif ref_kind == "absolute" and not lab.caution:
            lab.decided_by = f"planet offsets (as {', '.join(refs)})"
        notes.append(f"{nm}: planet labels aligned with the {', '.join(by)} gauge(s) by "
                     f"shift {shift} ({why})")
        refs.append(nm)
    return trains, train_of


def _disagreement(p: GaugePasses, lab: GaugeLabels, refs: list, shift: int, n: int,
                  why: str) -> str:
    """The caution of a gauge whose load-pattern labels the planets' own offsets move
    ``shift`` places from the reference gauges' (``refs``: (labels, fractions, passes))."""
    places = min(shift, n - shift)
    count = "one planet" if places == 1 else f"{places} planets"
    by = " and ".join(f"the {q.gear}'s by {r.decided_by}" for r, _, q in refs)
    return (f"the {p.gear}'s labels by load pattern and {by} disagree by {count}: {why} name "
            f"planet 1 {shift} place(s) on along the {p.gear} gauge's pass order; the labels "
            "follow the offsets")


#: the "not reliable" rule: the per-pass error the model's own diagnostics predict, against
#: the timing floor; a train's residual autocorrelation above this means systematic misfit
UNRELIABLE_RATIO = 3.0
UNRELIABLE_LAG1 = 0.6
#: the whole move between two explanations the data cannot tell apart over its RMS expected
#: share, sqrt(6): a split uniform in [0, 1] (1/3 of the square) of a term of uniform phase
#: (1/2 of it) [-]
INSEPARABLE_SHARE = math.sqrt(6.0)


def _choice_reasons(competitors, floor: float, est: float) -> list:
    """Reasons of :func:`_reliability` from the competing angle models of a gear's passes
    (:attr:`PassTable.competitors`), in words: each counted inseparable one, and, when the
    estimated error ``est`` with the model choice in it passes ``UNRELIABLE_RATIO`` times the
    timing ``floor`` (the one rule of the verdict), each weighed one that moves the phasing
    by more than the floor [mesh cycles] (RMS over the passes)."""
    out = []
    known = math.isfinite(floor) and floor > 0
    weighed = known and math.isfinite(est) and est > UNRELIABLE_RATIO * floor
    named = set()
    for c in competitors:
        if c["inseparable"]:
            # counted ones only (above the floor and what hole errors give); without timing
            # bounds there is no floor to set against, and the count alone decides
            if not (c.get("counted", True) and (c["rms"] > floor or not known)):
                continue
        elif not (weighed and c["rms"] > floor):
            continue
        if c["inseparable"]:
            pair = frozenset((c["words"], c["versus"]))
            if pair in named:
                continue
            named.add(pair)
            bound = c.get("ripple_bound", float("nan"))
            out.append(f"{c['words']} and {c['versus']} explain these passes equally well (the "
                       "gauges, and tacho if any, see them as one and the same term) and their "
                       f"phasing differs by {c['rms']:.2g} mesh cycles (RMS over the passes"
                       + (f", {c['rms'] / floor:.0f}x the timing floor" if known else "")
                       + "); the uncertainty includes that difference"
                       + (f"; every 1 % of speed ripple at the planet spin rate can move the "
                          f"phasing by up to {bound:.2g} mesh cycles"
                          if math.isfinite(bound) else "")
                       + "; a shaft encoder on the sun (input) shaft would tell them apart")
        else:
            how = ("explains these passes about as well as" if c["delta_bic"] >= 0
                   else "explains these passes better than")
            out.append(f"{c['words']} {how} {c['versus']} (BIC difference "
                       f"{c['delta_bic']:+.1f}, posterior weight {c['weight']:.2f}) and their "
                       f"phasing differs by {c['rms']:.2g} mesh cycles (RMS over the passes, "
                       f"{c['rms'] / floor:.1f}x the timing floor); the uncertainty includes "
                       "that spread")
    return out


def _reliability(model: AngleModel, train: PassTrain, tab: PassTable, unseen=()) -> dict:
    """Whether a gear's phasing can be trusted, from the model's own residual diagnostics and
    what its trains can see (``unseen``: :func:`meshphase.kinematics.angle_selection.unseen_ripples`)."""
    reasons = []
    for shaft, period in unseen:
        # a relative ripple a moves A by a P / (2 pi) mesh cycles at most, and the phasing
        # between two planets (A at two carrier angles) by twice that
        reasons.append(f"a speed ripple locked to the {shaft} angle is not seen by the gauges "
                       f"and tacho (they meet the {shaft} at fixed angles only): the phasing "
                       f"assumes the {shaft} turns evenly, and every 1 % of such ripple (an "
                       f"ordinary drive's) can move it by up to {0.01 * period / math.pi:.2g} "
                       "mesh cycles")
    fit = model.train(train.name)
    est = float(np.sqrt(np.mean(tab.uncertainty ** 2))) if len(tab) else float("nan")
    floor = float(np.sqrt(np.mean(tab.timing_floor ** 2))) if len(tab) else float("nan")
    choice = tab.choice_sigma if tab.choice_sigma is not None else np.zeros(len(tab))
    reasons.extend(_choice_reasons(tab.competitors, floor, est))
    # the scatter test judges the chosen model's own uncertainty (the model choice is above)
    within = float(np.sqrt(np.mean(np.maximum(tab.uncertainty ** 2 - choice ** 2, 0.0)))) \
        if len(tab) else float("nan")
    if math.isfinite(floor) and floor > 0 and within > UNRELIABLE_RATIO * floor:
        reasons.append(f"the passes scatter {fit.scale:.1f}x beyond their timing bound: "
                       f"estimated error {within:.2e} cycles is {within / floor:.1f}x the floor "
                       f"{floor:.2e}")
    if math.isfinite(fit.lag1) and fit.lag1 > UNRELIABLE_LAG1 and fit.n >= 20:
        reasons.append(f"residuals follow each other (lag-1 correlation {fit.lag1:.2f}): the "
                       "speed varies in a way the angle model does not follow")
    if not model.converged:
        reasons.append("the angle model did not converge")
    if fit.n and fit.n_outliers > 0.1 * (fit.n + fit.n_outliers):
        reasons.append(f"{fit.n_outliers} of {fit.n + fit.n_outliers} passes far off the model "
                       "(mislabelled or spurious pulses)")
    if len(tab) == 0:
        reasons.append("no pass could be measured")
    return {"reliable": not reasons, "reasons": reasons, "error_estimate": est, "floor": floor,
            "scale": fit.scale, "lag1": fit.lag1}
