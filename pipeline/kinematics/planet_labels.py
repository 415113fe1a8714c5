"""Which pulse is which planet: the planet labels of a gauge's passes.

Labels. Which pulse is which planet comes from the pass pattern
(:func:`assign_planets_by_pattern`: the fractions of a revolution between consecutive
planets); which one is planet 1 from unequal spacing, from a carrier tacho for a gauge on
the held member (:func:`assign_planets_by_tacho`, geometry in ``data_schemas/scene.md``), or
from the planets' loads; otherwise the labels are relative to the first pulse. The checks of
the labels against each other (loads, gauges on one tooth) are
:mod:`meshphase.kinematics.label_checks`.

A gauge's usable pulses are a :class:`GaugePasses`, its labels a :class:`GaugeLabels`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..runtime.lazy import interpolate
from .pass_table import planet_fractions
from .trains import revolution_numbers
from ..validate import as_finite_array

__all__ = ["GaugePasses", "GaugeLabels", "assign_planets_by_pattern", "assign_planets_by_tacho",
           "TachoRelabel", "relabel_by_tacho", "shift_labels"]

TWO_PI = 2.0 * math.pi


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
    :func:`meshphase.kinematics.phasing.measure_phasing` removes (:func:`meshphase.kinematics.label_checks.carrier_load_variation`) before it trusts them.

    Parameters
    ----------
    times : array_like, shape (m,)
        Sorted onset times [s].
    planet_angles : array_like, shape (N,)
        psi_n [rad].
    order : {+1, -1}
        From :func:`meshphase.kinematics.pass_table.pass_order`.
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
    theta = interpolate.PchipInterpolator(tach, -float(key_angle) + TWO_PI * k * order, extrapolate=False)(t)
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
        Sense in which the gauge meets the planets (:func:`meshphase.kinematics.pass_table.pass_order`).
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
        new_pl, new_pos = shift_labels(pl, pos, seq, best)
        return TachoRelabel(new_pl, new_pos, best, agree, compared, True)
    return TachoRelabel(pl, pos, best, agree, compared, False)


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
        instant, which names their planets alike (:func:`meshphase.kinematics.label_checks.coincident_shift`).
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


def shift_labels(planet, position, seq, shift):
    """Relabel cyclically in pass order by ``shift`` places (planet 1 moves)."""
    n = seq.size
    pos = position + shift
    return np.where(planet >= 0, seq[np.mod(pos, n)], -1), pos
