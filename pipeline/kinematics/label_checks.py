"""Checks of the planet labels against other evidence: the planets' loads and the gauges on one tooth.

The loads name the sun gauge's planet 1 only when the ring gauge's per-planet loads, divided
by the load variation with the carrier's phase that the sun gauge measures
(:func:`carrier_load_variation`), match the sun's under one labelling clearly
(:func:`load_shift_chi2`, :func:`sun_by_loads`); gauges on one tooth (across its face width)
see each planet at the same instant, which names their planets alike
(:func:`coincident_shift`), and the planets' own shaft hole offsets name them alike on every
gauge (:func:`align_labels`, :func:`meshphase.kinematics.label_shift.label_shift_costs`).
Where the loads and another kind of evidence disagree, the labels are relative and carry a
caution saying why.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..runtime.lazy import interpolate, linalg, special
from .label_shift import label_shift_costs
from .pass_table import nearest_index, pass_order, planet_fractions
from .planet_labels import GaugeLabels, GaugePasses, shift_labels
from .trains import relabel_train
from ..validate import as_finite_array, as_positive_int

__all__ = ["LoadVariation", "carrier_load_variation", "load_shift_chi2", "ring_loads", "sun_by_loads",
           "coincident_shift", "align_labels", "LOAD_VARIATION_ORDERS", "LOAD_SHIFT_MARGIN",
           "LOAD_VARIATION_NOTED", "LOAD_MATCH_QUANTILE", "COINCIDENT_TOL", "COINCIDENT_MIN",
           "COINCIDENT_AGREE"]

TWO_PI = 2.0 * math.pi


def ring_loads(lab: GaugeLabels, n: int):
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
    ``seq[(q + s) % N]`` (what :func:`shift_labels` does).

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
    return interpolate.PchipInterpolator(t, turns, extrapolate=False)


def _chi2_quantile(q: float, dof: int) -> float:
    """The chi-square distribution's ``q`` quantile with ``dof`` degrees of freedom [-]
    (``scipy.stats.chi2.ppf``, from the regularised incomplete gamma function: scipy.stats
    costs a processing run's start half a second)."""
    return float(2.0 * special.gammaincinv(0.5 * dof, q))


def sun_by_loads(p: GaugePasses, pl, pos, raw: tuple, ring: GaugeLabels, gearset,
                  notes: list) -> tuple:
    """The sun gauge's planet 1 from the planets' loads, checked against a load variation
    with the carrier's phase (:func:`carrier_load_variation` on the sun's pulses, the phase
    from the ring gauge's pulses): the ring gauge's per-planet loads divided by that
    variation must match the sun's per-place loads under one cyclic shift clearly
    (:func:`load_shift_chi2`, ``LOAD_SHIFT_MARGIN``, ``LOAD_MATCH_QUANTILE``).

    ``pl``, ``pos`` are the pattern labels with planet 1 the first pulse, ``raw`` the
    (planet, position, decided_by) of the loads as the ring gauge sees them
    (:func:`meshphase.kinematics.planet_labels.assign_planets_by_pattern` with ``reference_amplitudes``). Returns (planet,
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
        new_pl, new_pos = shift_labels(pl, pos, seq, best)
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


#: a gauge's passes are matched to a gauge on the same tooth when they fall within this
#: fraction of the median pass interval of each other [-]
COINCIDENT_TOL = 0.25


#: coincident passes needed, and the share of them that must name the same shift [-]
COINCIDENT_MIN = 8


COINCIDENT_AGREE = 0.9


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


def align_labels(trains, train_of, all_labels, labels, kin, n, notes):
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
            pl, pos = shift_labels(lab.planet, lab.position, seq, shift)
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
