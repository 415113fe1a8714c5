"""The angle model's order, chosen from the data.

The model order (spline intervals, ripple harmonics per shaft, amplitude modulation,
planet-term harmonics) is chosen by greedy forward selection on the Bayesian information
criterion (:func:`select_terms`; a candidate term is solved only when an optimistic bound on
its criterion, from one linearised step, could win: the same model for less work); a pass
whose residual is far outside its train's scatter (a mislabelled pulse) is left out, with a
count (:func:`drop_gross_outliers`), and one variance factor per train is estimated from its
residuals (:func:`variance_factors`, leverage-corrected; never below 1 when the timing bound
was given). Nothing depends on rounding: selection needs a BIC gain of at least ``BIC_GAIN``
and the residual variance in the criterion has a floor (the timing bound: residuals inside
it are no evidence for another term), so the same onsets moved by 1e-9 s give the same model.
"""

from __future__ import annotations

import math

import numpy as np

from ..runtime.lazy import linalg
from .angle_design import (RANK_TOL, Design, FitBasis, ModelFit, ModelSpec, column_norms,
                           extend_theta, fit_basis, fix_rate, plausible_rate, rank_keep,
                           solve, spline_basis)
from .shafts import Kinematics
from .trains import PassTrain

__all__ = ["knot_ladder", "unseen_ripples", "ripple_rates", "drop_gross_outliers", "select_terms",
           "variance_factors", "KNOT_LADDER", "BIC_GAIN", "UNSEEN_TOL", "SCREEN_SLACK"]

#: spline interval counts tried, in order
KNOT_LADDER = (1, 2, 3, 4, 6, 8, 11, 16, 22, 32, 45, 64)
#: BIC gain needed to accept a term [-] ("positive evidence", Kass & Raftery 1995)
BIC_GAIN = 2.0


def _min_step(tr: PassTrain) -> float:
    """Smallest mesh-angle step between consecutive planets of a gauge train [mesh cycles]
    (Z times the smallest planet spacing in revolutions)."""
    steps = np.diff(tr.target)[np.diff(tr.position) == 1]
    return float(np.min(steps)) if steps.size else float("inf")


def knot_ladder(d: Design, kin: Kinematics, gauges: list, max_knots) -> list:
    """Spline interval counts tried: knots at least two relative revolutions of the densest
    gauge train apart, at most 64 intervals (or ``max_knots``)."""
    span = d.t_hi - d.t_lo
    rev = min(float(np.ptp(tr.times)) / max(1.0, (tr.target[-1] - tr.target[0]) /
                                             (kin.z_sun if tr.kind == "sun" else kin.z_ring))
              for tr in gauges)
    kmax = int(max(1, min(64, math.floor(span / (2.0 * rev)) if rev > 0 else 1)))
    if max_knots is not None:
        kmax = max(1, min(kmax, int(max_knots)))
    return [k for k in KNOT_LADDER if k <= kmax]


#: a shaft's ripple counts as unseen when the share of its first harmonic that varies within
#: the passes of one planet on one train (and within the tacho's edges) is below this [-]:
#: exactly zero in exact arithmetic (the pass targets are whole turns plus fixed fractions),
#: ~1e-30 in floating point
UNSEEN_TOL = 1e-12


def unseen_ripples(trains, kin: Kinematics) -> list:
    """Shafts whose speed ripple no train can see: (shaft, mesh cycles per turn) pairs.

    A ripple locked to a shaft's angle is seen only where the trains meet that shaft at
    varying angles. A gauge on the held ring meets each planet, and a carrier tacho fires,
    at one carrier angle each: with no other train (the sun gauge dead, clipped or absent)
    a ripple at the carrier's harmonics only adds a constant to each planet's passes, which
    the planets' own offsets take up, and the phasing between planets, A(t_n) - A(t_1),
    carries its difference between their carrier angles unseen (the independent rig's
    ordinary 1 % carrier ripple, ring gauge and tacho alone: 0.14 mesh cycles, 54 x the
    floor, with residuals at the floor). The planet spin is not tried here (its common
    ripple is not fitted by default: :func:`meshphase.kinematics.angles.fit_angle_model`); a shaft that turns less
    than once over the record is left to the drift (as there).

    Parameters
    ----------
    trains : sequence of PassTrain
        The trains the angle model is fitted to (gauges and tacho); trains with fewer than
        two observations are ignored.
    kin : Kinematics

    Returns
    -------
    list of (str, float)
    """
    if not isinstance(kin, Kinematics):
        raise TypeError(f"kin must be a Kinematics, got {type(kin).__name__}")
    use = [tr for tr in trains if isinstance(tr, PassTrain) and len(tr) >= 2]
    gauges = [tr for tr in use if tr.kind in ("sun", "ring")]
    if not gauges:
        return []
    span = max(float(np.ptp(tr.target)) for tr in gauges)
    out = []
    for shaft, period in kin.periods.items():
        if shaft == "planet" or not (period > 0 and span >= period):
            continue
        varying = total = 0.0
        for tr in use:
            c = np.exp(2j * np.pi * np.mod(np.asarray(tr.target, dtype=float), period) / period)
            _, grp = np.unique(np.asarray(tr.planet), return_inverse=True)
            cnt = np.bincount(grp)
            mean = (np.bincount(grp, c.real) + 1j * np.bincount(grp, c.imag)) / cnt
            rep = cnt[grp] >= 2                  # a planet passed once tells nothing either way
            varying += float(np.sum(np.abs(c - mean[grp])[rep] ** 2))
            total += float(np.count_nonzero(rep))
        if total > 0 and varying <= UNSEEN_TOL * total:
            out.append((shaft, float(period)))
    return out


def ripple_rates(d: Design, kin: Kinematics, planet_ripple: bool, notes: list) -> list:
    """Shafts whose speed ripple may be fitted: a shaft must turn at least once over the
    record for its ripple to be told from drift (the others are named in ``notes``)."""
    span = d.t_hi - d.t_lo
    mean_rate = (d.y.max() - d.y.min()) / span if span > 0 else 0.0
    turns = {r: mean_rate * span / P for r, P in kin.periods.items()}
    rates = [r for r in kin.periods if turns[r] >= 1.0 and (planet_ripple or r != "planet")]
    skipped = [r for r in kin.periods if r not in rates and (planet_ripple or r != "planet")]
    if skipped:
        notes.append(f"no ripple terms for {', '.join(skipped)}: fewer than one turn in the record")
    return rates


def drop_gross_outliers(d: Design, use: list, spec: ModelSpec, outlier_k: float) -> ModelFit:
    """The base fit, refitted without gross outliers (at most 3 rounds; ``d.active`` is
    updated): mislabelled pulses are whole planet spacings off."""
    ones = np.ones(len(use))
    fit = solve(d, spec, None, ones)
    for _ in range(3):
        out = np.zeros(d.t.size, bool)
        for q in range(len(use)):
            m = (d.q == q) & d.active
            r = fit.resid[m]
            if r.size < 4:
                continue
            med = np.median(r)
            mad = 1.4826 * np.median(np.abs(r - med))
            lim = max(outlier_k * mad, 1e-9)
            if use[q].kind == "tacho":
                continue
            # mislabels are whole planet spacings off; never call less than 0.3 of the
            # smallest spacing an outlier here (unmodelled ripple can reach ~0.5 cycles)
            step_min = _min_step(use[q])
            if math.isfinite(step_min):
                lim = max(lim, 0.3 * step_min)
            idx = np.flatnonzero(m)
            out[idx[np.abs(r - med) > lim]] = True
        if not out.any():
            break
        d.active &= ~out
        fit = solve(d, spec, None, ones)
    return fit


def select_terms(d: Design, spec: ModelSpec, fit: ModelFit, ladder: list, rates: list,
                  kin: Kinematics, max_harmonics: int, max_planet_harmonics: int, *,
                  screen: bool = True, rejected: list | None = None, reuse: bool = True):
    """Forward selection of the model terms on BIC, weights from the timing bounds alone:
    (spec, fit, selection steps).

    ``screen``: a candidate is solved only when its optimistic BIC (a finer spline's from
    :func:`_spline_bounds`, any other's from :func:`_linear_bound`) could beat the bar set
    by the candidates solved before it (the fit's BIC less the gain needed, or the best
    candidate's), with ``BIC_GAIN`` to spare. Candidates are solved from the lowest bound
    up, so the bar falls fastest. Most of a selection's time went into candidates that do
    not pay for their columns (a 64-interval spline costs as much as ten ripple terms; a
    step that ends the selection solves every candidate only to reject it); screening
    leaves the chosen model unchanged (a test runs the selection both ways).

    ``rejected``: a list that receives the spec of the best candidate of the last step (the
    one that did not gain ``BIC_GAIN``), when one was solved.

    ``reuse``: the screen's bounds take the fit's factorisations, made once per step
    (:func:`meshphase.kinematics.angle_design.fit_basis`): each candidate adds its own
    columns to them (:func:`meshphase.kinematics.angle_design.appended_diagonal`) instead
    of refactorising the whole design. The same bounds and identifiable columns in exact
    arithmetic; ``reuse=False`` factorises each candidate afresh (a test runs both)."""
    ones = np.ones(len(d.trains))
    selection = [(0, spec.describe(), fit.bic())]
    step = 0
    while True:
        step += 1
        cands = []
        # every finer spline is a candidate: a drift the next step cannot follow may still
        # be followed by a finer one (greedy steps of one would stop short)
        for k in (k for k in ladder if k > spec.knots):
            s2 = spec.copy()
            s2.knots = k
            cands.append(s2)
        for r in rates:
            # a common ripple at the planet spin looks, on one gear's gauges, exactly like the
            # same planet term on every planet: it is tried only next to planet terms of that
            # harmonic (and dropped where the data cannot tell the two apart), because every
            # planet's own shaft hole offset is certain to be there and a common planet-rate
            # speed ripple is not
            if r == "planet" and spec.harm[r] >= spec.sig and not _planet_rate_sampled(d, kin):
                continue
            if spec.harm[r] < max_harmonics:
                s2 = spec.copy()
                s2.harm[r] += 1
                cands.append(s2)
            if spec.harm[r] >= 1 and not spec.mod[r]:
                s2 = spec.copy()
                s2.mod[r] = True
                cands.append(s2)
        if kin.planet_period and spec.sig < max_planet_harmonics:
            s2 = spec.copy()
            s2.sig += 1
            cands.append(s2)
        finer = [c.knots for c in cands if c.knots != spec.knots]
        # the fit's factorisations, shared by every candidate's bound of this step
        basis = fit_basis(d, fit) if screen and reuse else None
        spline_bound = _spline_bounds(d, fit, finer, basis) if screen and finer else {}
        n_act = np.count_nonzero(d.active)
        # each candidate's optimistic BIC (-inf: always solved), its start and, where the
        # bound judged it, its identifiable columns there (the solve's own first check)
        bound, start, keep0 = {}, {}, {}
        for i, c in enumerate(cands):
            if d.layout(c)["p"] > n_act - max(4, 0.2 * n_act):
                continue
            if c.knots != spec.knots:
                bound[i] = spline_bound.get(c.knots, -math.inf)
                continue
            start[i] = extend_theta(fit, c, d)
            bound[i], keep0[i] = (_linear_bound(d, fit, c, start[i], basis) if screen
                                  else (-math.inf, None))
        # from the most promising: each BIC solved lowers the bar the others' optimistic
        # BICs must pass
        order = sorted(bound, key=lambda i: bound[i])
        best, best_i = None, -1
        for i in order:
            c = cands[i]
            bar = fit.bic() - BIC_GAIN if best is None else min(fit.bic() - BIC_GAIN, best.bic())
            if bound[i] > bar + BIC_GAIN:
                continue
            if i not in start:
                # a finer spline past its cheap bound: its own linearised step, with its rank
                start[i] = extend_theta(fit, c, d)
                if screen:
                    b, keep0[i] = _linear_bound(d, fit, c, start[i])
                    if b > bar + BIC_GAIN:
                        continue
            th0 = start[i]
            f2 = solve(d, c, th0, ones, max_iter=4, recheck=False, keep=keep0.get(i))
            # lowest BIC; a tie goes to the earlier candidate, as in the order of ``cands``
            if best is None or f2.bic() < best.bic() or (f2.bic() == best.bic() and i < best_i):
                best, best_i = f2, i
        if best is None or best.bic() > fit.bic() - BIC_GAIN:
            if rejected is not None and best is not None:
                rejected.append(best.spec)
            break
        full = solve(d, best.spec, best.theta, ones)
        fit = full if full.bic() <= best.bic() + 1e-9 * abs(best.bic()) else best
        spec = best.spec
        selection.append((step, spec.describe(), fit.bic()))
    return spec, fit, selection


#: A candidate (a finer spline, a ripple, modulation or planet harmonic) is assumed able to
#: lower the misfit by this factor more than its linearised gain (the ripple arguments move
#: with the spline: the gain of the Gauss-Newton iterations is not quite the first step's;
#: tests/processing/test_angles.py checks the bound on every candidate of three records) [-]
SCREEN_SLACK = 1.5


def _spline_bounds(d: Design, fit: ModelFit, knots, basis: FitBasis | None = None) -> dict:
    """Optimistic BIC of each finer spline in ``knots`` [-], from one evaluation at ``fit``.

    The spline with K' intervals can lower the misfit by no more than the union of the
    fitted model's columns and the K' spline's columns could in a linearised step: the
    weighted residual's part outside the span of both. Its rank is at least the union's
    less the spline columns it drops. The bound takes ``SCREEN_SLACK`` times that gain and
    that rank: n ln(max(chi2 / n, floor)) + rank ln n. A spline whose bound is not finite
    gets -inf (it is always solved). ``basis``: ``fit``'s :class:`FitBasis` when already
    made (its evaluation and QR are the ones needed here)."""
    out = {int(k): -math.inf for k in knots}
    if not knots:
        return out
    if basis is None or not np.array_equal(basis.rows, np.flatnonzero(d.active)):
        basis = fit_basis(d, fit, nominal=False)
    if basis is None:
        return out
    rows = basis.rows
    n = rows.size
    chi, r_out, chi_out, fac, Q = basis.chi, basis.r_out, basis.chi_out, basis.fac, basis.q
    sb = fit.lay["blocks"]["spline"]
    kept_spline = int(np.count_nonzero(fit.keep[sb]))
    for k in out:
        N = spline_basis(d.x[rows], k) * fac[:, None]
        nn = column_norms(N)
        N = N[:, nn > 0] / nn[nn > 0]
        for _ in range(2):                         # projected twice: orthogonal to rounding
            N -= Q @ (Q.T @ N)
        # Q2^T r_out by applying the reflectors (LAPACK ormqr), without forming Q2
        rq, R2, _ = linalg.qr_multiply(N, r_out, mode="right", pivoting=True, overwrite_a=True)
        k2 = int(np.count_nonzero(np.abs(np.diag(R2)) > RANK_TOL))
        g = rq[:k2]
        chi_u = max(chi_out - float(g @ g), 0.0)
        chi_opt = max(chi - SCREEN_SLACK * (chi - chi_u), 0.0)
        rank = fit.rank + k2 - kept_spline
        out[k] = n * math.log(max(chi_opt / n, fit.floor)) + rank * math.log(n)
    return out


def _linear_bound(d: Design, fit: ModelFit, spec: ModelSpec, theta0: np.ndarray,
                  basis: FitBasis | None = None):
    """Optimistic BIC of the candidate ``spec`` that extends ``fit`` by terms starting at zero
    (``theta0``, from :func:`extend_theta`) [-], and the identifiable columns there: (bound, keep).

    The candidate's first Gauss-Newton step from ``theta0`` is the least-squares fit of the
    weighted residual by its weighted columns (the fit's and the new ones, evaluated at
    theta0, where the new terms are zero and the model is the fit's). The misfit after that
    step, chi_lin, is one QR away: R_pp^2 of the QR of [A | r]. The bound takes
    ``SCREEN_SLACK`` times that gain (the iterations after the first step add little to
    it: the model is nearly linear in the new terms near zero) and the candidate's own rank
    (the columns :func:`solve` keeps at theta0, returned so the solve need not find them
    again; None where it drops a parameter that is not zero there):
    n ln(max(chi_opt / n, floor)) + rank ln n, as :meth:`ModelFit.bic`. A candidate whose check
    drops a parameter that is not zero at theta0 (its solve starts elsewhere), whose misfit
    is not finite, or with no more rows than columns gets -inf: it is always solved.

    ``basis``: ``fit``'s :class:`FitBasis` (``theta0`` must extend ``fit``). The rank check
    then factorises only the columns after the candidate's shared leading ones, and where
    the candidate keeps every column the fit kept, chi_lin is the residual's part outside
    the basis (``r_out``) less what the candidate's new columns, projected out of the
    basis, take of it: one QR of [N | r] of the new columns, not of the whole design."""
    rows = np.flatnonzero(d.active)
    n = rows.size
    lay = d.layout(spec)
    if basis is not None and not (basis.knots == spec.knots and np.array_equal(basis.rows, rows)):
        basis = None
    keep = rank_keep(d, theta0, lay, spec, rows, basis=basis)
    p = int(np.count_nonzero(keep))
    if np.any(theta0[~keep] != 0.0):
        return -math.inf, None            # the solve zeroes them and starts from there
    if n <= p:
        return -math.inf, keep
    f, J, rate = d.evaluate(theta0, lay, spec, rows)
    w = 1.0 / (d.sig[rows] * fix_rate(rate))
    with np.errstate(over="ignore", invalid="ignore"):
        r = (d.y[rows] - f) * w
        chi = float(r @ r)
    if not (math.isfinite(chi) and plausible_rate(rate)):
        return -math.inf, keep
    names = lay["names"]
    kept = np.flatnonzero(keep)
    new = [j for j in kept if names[j] not in basis.kept] if basis is not None else None
    if basis is not None and len(kept) - len(new) == len(basis.kept) and n > p:
        # the fit's identifiable columns all kept: the union's span is the basis's and the
        # new columns'; [N | r] projected out of the basis, its QR gives the rest
        k = len(new)
        Ab = np.empty((n, k + 1), order="F")
        Ab[:, :k] = J[:, new] * w[:, None]
        cn = column_norms(Ab[:, :k])
        cn[~(cn > 0)] = 1.0
        Ab[:, :k] /= cn
        Ab[:, k] = r
        Q = basis.q
        for _ in range(2):                  # projected twice: orthogonal to rounding
            Ab -= Q @ (Q.T @ Ab)
        qr = linalg.qr(Ab, mode="raw", overwrite_a=True, check_finite=False)[0][0]
        chi_lin = float(qr[k, k]) ** 2
    else:
        Ab = np.empty((n, p + 1), order="F")
        Ab[:, :p] = J[:, keep] * w[:, None]
        cn = column_norms(Ab[:, :p])
        cn[~(cn > 0)] = 1.0
        Ab[:, :p] /= cn
        Ab[:, p] = r
        qr = linalg.qr(Ab, mode="raw", overwrite_a=True, check_finite=False)[0][0]
        chi_lin = float(qr[p, p]) ** 2
    if not math.isfinite(chi_lin):
        return -math.inf, keep
    chi_opt = max(chi - SCREEN_SLACK * max(chi - chi_lin, 0.0), 0.0)
    return n * math.log(max(chi_opt / n, fit.floor)) + p * math.log(n), keep


def variance_factors(d: Design, use: list, spec: ModelSpec, fit: ModelFit, outlier_k: float):
    """Variance factors per train and outliers against the final model, then the final fit:
    (scale, fit). Each round judges every observation afresh: one left out early by a poorer
    model may come back."""
    n_obs = d.t.size
    ones = np.ones(len(use))
    base_active = d.active.copy()
    scale = ones.copy()
    for _ in range(4):
        fit = solve(d, spec, fit.theta, scale, full=True)
        new = scale.copy()
        w = 1.0 / (d.sig * fit.rate)
        for q, tr in enumerate(use):
            m = (d.q == q) & d.active
            if not np.any(m):
                continue
            dof = max(1.0, np.count_nonzero(m) - float(np.sum(fit.lev[m])))
            s = math.sqrt(float(np.sum((fit.resid[m] * w[m]) ** 2)) / dof)
            # a given timing bound is a bound; an unknown one (default sigma) may be far off,
            # but never trusted below 1e-3 of the default (1e-7 of a tacho interval: a
            # synthetic tacho is exact to 1e-13, and weights that far apart make every
            # Gauss-Newton step stiff enough to leave the model's domain)
            new[q] = max(s, 1.0) if tr.sigma_given else max(s, 1e-3)
        out = np.zeros(n_obs, bool)
        for q in range(len(use)):
            m = (d.q == q) & base_active
            lim = outlier_k * new[q] / w[m]
            idx = np.flatnonzero(m)
            out[idx[np.abs(fit.resid[m]) > lim]] = True
        active = base_active & ~out
        if np.array_equal(active, d.active) and np.allclose(new, scale, rtol=1e-3):
            scale = new
            break
        d.active = active
        scale = new
    return scale, solve(d, spec, fit.theta, scale, full=True)


def _planet_rate_sampled(d: Design, kin: Kinematics) -> bool:
    """Whether a train without planet terms (an encoder) observes the mesh angle at least
    four times per planet spin (median step below Z_p / 4 mesh cycles): a common
    planet-rate speed ripple is then seen apart from the planets' own terms, and is tried
    on its own."""
    zp = kin.planet_period
    if not zp:
        return False
    for tr in d.trains:
        if tr.kind == "tacho" and len(tr) > 2 and float(np.median(np.diff(tr.target))) < zp / 4.0:
            return True
    return False
