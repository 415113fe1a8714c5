"""Identification of the shaft hole position errors from the measured phasing.

:func:`identify_errors` fits the Cartesian offsets of the sun, ring, carrier holes and planets
(:func:`PARAMETER_NAMES`) to the measured phasing of every pass
(:func:`meshphase.compare.pass_model.predict_pass_phasing`, by bounded least squares with an
analytic or finite-difference Jacobian), finds what the data cannot resolve (the rank of the
weighted Jacobian; parameter combinations only, :func:`describe_combination`; records that
would resolve them) and returns an :class:`Identification`; :func:`identification_verdict`
says in words what it can be trusted for.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from ..runtime.lazy import optimize
from .pass_model import (gamma_and_jacobian, gradient_plan, pass_setup, predict_pass_phasing,
                         table_speeds, wrap)
from ..errors import ProcessingWarning
from ..kinematics.pass_table import PassTable, pass_order
from ..models.gearset import Gearset
from ..models.mesh_phasing import ShaftHoleErrors
from ..models.phasing_jacobian import MeshGradientPlan
from ..validate import as_choice, as_positive, as_positive_int

__all__ = ["Identification", "identify_errors", "PARAMETER_NAMES", "describe_combination",
           "identification_verdict", "vector_from_errors", "RECORD_FACTORS", "JACOBIANS"]

TWO_PI = 2.0 * math.pi


#: parameter order of the identification: Cartesian offset components [m]
def PARAMETER_NAMES(n_planets: int) -> list[str]:
    """Names of the identification parameters (Cartesian offsets [m])."""
    names = ["sun_x", "sun_y", "ring_x", "ring_y"]
    for i in range(1, n_planets + 1):
        names += [f"planet{i}_x", f"planet{i}_y"]
    return names


def _errors_from_vector(p: np.ndarray, n: int) -> ShaftHoleErrors:
    xs, ys, xr, yr = p[:4]
    xp, yp = p[4::2], p[5::2]
    return ShaftHoleErrors(e_sun=math.hypot(xs, ys), kappa_sun=math.atan2(ys, xs),
                           e_ring=math.hypot(xr, yr), kappa_ring=math.atan2(yr, xr),
                           e_planet=np.hypot(xp, yp), kappa_planet=np.arctan2(yp, xp))


def vector_from_errors(err: ShaftHoleErrors, n: int) -> np.ndarray:
    """The Cartesian offset parameters of ``err`` in the order of :func:`PARAMETER_NAMES` [m]
    (sun x, y, ring x, y, then each of the ``n`` planets' x, y)."""
    ep = np.broadcast_to(np.asarray(err.e_planet, float), (n,))
    kp = np.broadcast_to(np.asarray(err.kappa_planet, float), (n,))
    v = [float(err.e_sun) * math.cos(float(err.kappa_sun)), float(err.e_sun) * math.sin(float(err.kappa_sun)),
         float(err.e_ring) * math.cos(float(err.kappa_ring)), float(err.e_ring) * math.sin(float(err.kappa_ring))]
    for e, k in zip(ep, kp):
        v += [e * math.cos(k), e * math.sin(k)]
    return np.asarray(v)


@dataclass
class Identification:
    """Shaft hole errors identified from measured phasing by least squares.

    Attributes
    ----------
    errors : ShaftHoleErrors
        The fitted errors used for the model curves: identifiable parameters at their
        estimates, unidentifiable combinations at minimum norm (not an estimate of them).
    table : list of dict
        Per gear: ``gear``, ``e`` [m], ``e_std`` [m], ``e_ci95`` [m, m], ``kappa`` [rad],
        ``kappa_std`` [rad], ``identifiable`` (bool), ``note``.
    parameters : dict
        Cartesian parameters: name -> (estimate [m], std [m], identifiable).
    singular_values : ndarray
        Of the weighted Jacobian (identifiability: near-zero ones are combinations the data
        cannot see).
    rms_before, rms_after : float
        Residual RMS against the ideal and against the fitted model [mesh cycles].
    sigma : float
        Residual standard deviation after the fit [mesh cycles] (scales the covariance).
    n_passes, n_parameters : int
    cost_evaluations : int
        Model evaluations (with the analytic Jacobian each gives the Jacobian too).
    jacobian_evaluations : int
        Jacobians the solver used (``scipy.optimize.OptimizeResult.njev``).
    wall_time : float [s]
    identifiable : bool
        All requested parameters identifiable.
    projector : ndarray, shape (P, P)
        Orthogonal projector onto the identifiable subspace of the Cartesian parameters
        (:data:`PARAMETER_NAMES` order); see :meth:`subspace_error`.
    notes : list of str
    rank : int
        Singular values above ``rcond`` times the largest: the number of combinations the
        data determine.
    rank_note : str
        The rank decision in words (threshold, smallest kept and largest dropped singular
        value, whether the decision is marginal).
    combinations : list of dict
        The determined combinations (:func:`_combinations`), best determined first:
        ``description`` (in words), ``coefficients`` (parameter name -> unit-norm
        coefficient [-]), ``estimate`` [m], ``std`` [m], ``ci95`` [m, m],
        ``relative_singular_value`` [-].
    suggestions : list of dict
        Per gear that is not identifiable: the first extra gauge or longer record that
        would identify it, with its predicted standard error (:func:`_suggestions`).
    """

    errors: ShaftHoleErrors
    table: list
    parameters: dict
    singular_values: np.ndarray
    rms_before: float
    rms_after: float
    sigma: float
    n_passes: int
    n_parameters: int
    cost_evaluations: int
    wall_time: float
    identifiable: bool
    notes: list = field(default_factory=list)
    projector: np.ndarray | None = None
    free: np.ndarray | None = None
    jacobian_evaluations: int = 0
    rank: int = 0
    rank_note: str = ""
    combinations: list = field(default_factory=list)
    suggestions: list = field(default_factory=list)

    def subspace_error(self, true_errors: ShaftHoleErrors) -> float:
        """Distance [m] between the estimate and ``true_errors`` inside the identifiable
        subspace (what the data can tell apart); the check for synthetic truth."""
        if self.projector is None:
            return float("nan")
        n_pl = (self.free.size - 4) // 2
        d = (vector_from_errors(self.errors, n_pl) - vector_from_errors(true_errors, n_pl))[self.free]
        return float(np.linalg.norm(self.projector @ d))

    def true_combinations(self, true_errors: ShaftHoleErrors) -> np.ndarray:
        """Value [m] of each of :attr:`combinations` for ``true_errors`` (synthetic truth):
        what each estimate and its interval should hold."""
        if not isinstance(true_errors, ShaftHoleErrors):
            raise TypeError(f"true_errors must be a ShaftHoleErrors, got {type(true_errors).__name__}")
        if self.free is None or not self.combinations:
            return np.empty(0)
        n_pl = (self.free.size - 4) // 2
        p = vector_from_errors(true_errors, n_pl)
        names = PARAMETER_NAMES(n_pl)
        return np.array([sum(c * p[names.index(nm)] for nm, c in comb["coefficients"].items())
                         for comb in self.combinations])


#: how far the timed pulse feature may sit from the engagement instant [mesh cycles]: the
#: matched filter's timing centre of a skewed tooth-root pulse lies 0.02-0.06 mesh cycles off
#: the middle of the contact (synthetic skew +-0.2, measured), unknown on a real rig
PASS_OFFSET_STD = 0.05


#: Jacobian options of :func:`identify_errors`: closed form, or scipy's finite differences
JACOBIANS = ("analytic", "2-point", "3-point")


def identify_errors(tables, gearset: Gearset, *, gears=("sun", "ring", "planet"),
                    rcond: float = 1e-2, max_nfev: int = 200,
                    pass_offset_std: float = PASS_OFFSET_STD,
                    jac: str = "analytic", suggest: bool = True) -> Identification:
    """Identify shaft hole errors (e, kappa per gear) from measured phasing time series.

    Weighted nonlinear least squares (scipy.optimize.least_squares, trust region) of the
    wrapped residuals gamma_measured - :func:`predict_pass_phasing`, over Cartesian offset
    components (x, y) = e (cos kappa, sin kappa) so that e = 0 is a regular point. The
    weighted Jacobian's SVD decides identifiability: the right singular vectors with
    s > rcond * s_max span what the data determine (the rank), and a parameter whose
    direction lies less than 95 % inside that span is reported as not identifiable (e.g. a
    gear's own offset seen only by a gauge on that gear). A rank-deficient design (at zero
    offsets) is fitted from 0 inside the determined span only, so the flat directions stay
    0 instead of wandering with the noise; the rank is decided again at the solution.
    Confidence intervals: covariance sigma^2 (J^T J)^+ on the identifiable subspace,
    e and kappa by the delta method; 95 % intervals are +-1.96 std. The determined span is
    reported as unit-norm combinations with their estimates and intervals
    (``combinations``), and each offset that is not identifiable gets the first extra gauge
    or longer record that would identify it (``suggestions``, :func:`_suggestions`).

    Parameters
    ----------
    tables : PassTable or sequence of PassTable
        Measured passes of the sun and/or ring gauge.
    gearset : Gearset
    gears : tuple of {"sun", "ring", "planet"}
        Which offsets to fit.
    rcond : float
        Relative singular value threshold for identifiability [-].
    max_nfev : int
        Limit of model evaluations.
    pass_offset_std : float
        Uncertainty of where the timed pulse feature sits relative to the engagement instant
        [mesh cycles]. The offsets turn while the pulse passes, so such a shift rotates every
        identified angle a little; its effect on the parameters (their sensitivity to a
        common shift of all passes, by finite differences) enters their covariance as a
        systematic term. 0: the pass times are taken as the engagement instants.
    jac : {"analytic", "2-point", "3-point"}
        Jacobian of the residuals: closed form (:func:`meshphase.compare.pass_model.pass_phasing_jacobian`; one model
        evaluation gives residuals and Jacobian together), or scipy's finite differences
        (``diff_step`` 1e-6; 1 + P or 1 + 2P evaluations per Jacobian), kept as the
        reference and fallback. Both reach the same solution within the solver's
        tolerances (tests/processing/test_identify_jacobian.py).
    suggest : bool
        Work out what would identify each offset that is not identifiable
        (``suggestions``: the design rows of up to a 64 times longer record, the larger part
        of the cost on a long record). False leaves ``suggestions`` empty.

    Returns
    -------
    Identification
        ``cost_evaluations`` counts model evaluations of every kind (with
        ``jac="analytic"`` each yields the Jacobian too); ``jacobian_evaluations`` the
        Jacobians the solver asked for.
    """
    t_start = time.perf_counter()
    tables, gears = _identify_inputs(tables, gearset, gears)
    rcond = as_positive(rcond, "rcond")
    max_nfev = as_positive_int(max_nfev, "max_nfev")
    jac = as_choice(jac, "jac", JACOBIANS)
    n_pl = gearset.n_planets
    names = PARAMETER_NAMES(n_pl)
    free = np.array([(n.split("_")[0].rstrip("0123456789") in gears) for n in names])
    if not tables:
        warnings.warn("identify_errors: no measured passes; nothing identified",
                      ProcessingWarning, stacklevel=2)
        return Identification(ShaftHoleErrors(), [], {}, np.empty(0), float("nan"), float("nan"),
                              float("nan"), 0, int(free.sum()), 0, 0.0, False,
                              ["no measured passes"])
    fit = _PhasingFit(tables, gearset, free, analytic=jac == "analytic")
    x0 = np.zeros(int(free.sum()))
    # offsets are small against the carrier radius: bound each component to 5 % of R_c so the
    # flat (unidentifiable) directions cannot wander to geometrically impossible layouts
    bound = 0.05 * gearset.carrier_radius / fit.scale
    # the design at zero offsets decides which directions the data determine; a fit over all
    # of them would let noise drive the nearly flat ones to the bounds, and at such offsets
    # the second-order terms bias the determined combinations. So a rank-deficient design is
    # fitted from 0 inside the span of its determined directions (the flat ones stay 0)
    _, s0, Vt0 = np.linalg.svd(_jacobian_at(fit, x0, jac), full_matrices=False)
    keep0 = _kept(s0, rcond)
    njev = 1
    if np.all(keep0):
        sol = _box_fit(fit, x0, jac, max_nfev, bound)
    else:
        sol = _subspace_fit(fit, Vt0[keep0].T, jac, max_nfev, bound)
    njev += int(sol.njev or 0)
    U, s, Vt = np.linalg.svd(sol.jac, full_matrices=False)
    keep = _kept(s, rcond)
    if s.size and keep.sum() != keep0.sum():
        # the rank changed between 0 and the solution: fit again over what is determined there
        if np.all(keep):
            sol = _box_fit(fit, sol.x, jac, max_nfev, bound)
        else:
            sol = _subspace_fit(fit, Vt[keep].T, jac, max_nfev, bound)
        njev += int(sol.njev or 0)
        U, s, Vt = np.linalg.svd(sol.jac, full_matrices=False)
        keep = _kept(s, rcond)
    ident = np.sum(Vt[keep] ** 2, axis=0) > RESOLUTION         # resolution of each parameter
    Vk = Vt[keep].T
    cov_free = fit.covariance(sol, U, s, Vk, keep, pass_offset_std)
    p_hat = np.zeros(len(names))
    # the fitted model is the solution inside the determined subspace (the combinations the
    # data cannot see at 0); only the identifiable parameters are reported as estimates
    est = sol.x * fit.scale
    p_hat[free] = est
    cov = np.zeros((len(names), len(names)))
    fi = np.flatnonzero(free)
    cov[np.ix_(fi, fi)] = cov_free
    r1 = wrap(fit.meas - fit.model(est / fit.scale))
    ok = fit.ok
    ident_full = np.zeros(len(names), bool)
    ident_full[fi] = ident
    params = {nm: (float(p_hat[i]), float(math.sqrt(max(cov[i, i], 0.0))), bool(ident_full[i]))
              for i, nm in enumerate(names) if free[i]}
    rows, notes = _gear_rows(p_hat, cov, free, ident_full, {t.gauge for t in tables}, n_pl)
    combos = _combinations(Vt[keep], s[keep] / s[0] if s.size else s[keep], cov_free,
                           p_hat[free], [nm for nm, f in zip(names, free) if f], gearset)
    s2 = float(np.sum(sol.fun ** 2)) / max(1, int(fit.ok.sum()) - int(keep.sum()))
    sugg = _suggestions(fit, sol, rcond, s2, names, [r["gear"] for r in rows
                                                     if not r["identifiable"]]) if suggest else []
    if not sol.success:
        notes.append(f"least squares stopped: {sol.message}")
    return Identification(
        errors=_errors_from_vector(p_hat, n_pl), table=rows, parameters=params,
        singular_values=s, rms_before=fit.rms_before,
        rms_after=float(np.sqrt(np.mean(r1[ok] ** 2))) if ok.any() else float("nan"),
        sigma=float(np.std(r1[ok])) if ok.any() else float("nan"), n_passes=int(ok.sum()),
        n_parameters=int(free.sum()), cost_evaluations=fit.n_eval,
        jacobian_evaluations=njev,
        wall_time=time.perf_counter() - t_start,
        identifiable=bool(np.all(ident)), notes=notes, projector=Vk @ Vk.T, free=free,
        rank=int(keep.sum()), rank_note=_rank_note(s, keep, rcond), combinations=combos,
        suggestions=sugg)


def _box_fit(fit: "_PhasingFit", x0: np.ndarray, jac: str, max_nfev: int, bound: float) -> "optimize.OptimizeResult":
    """Least squares of :meth:`_PhasingFit.resid` over every free parameter from ``x0``, each
    held to +-``bound`` [scaled parameter units] (trust region reflective; the closed-form
    Jacobian, or forward differences of step 1e-6)."""
    return optimize.least_squares(fit.resid, x0, jac=fit.jac if jac == "analytic" else jac,
                         method="trf", x_scale=1.0, diff_step=1e-6, max_nfev=max_nfev,
                         bounds=(-bound, bound))


def _subspace_fit(fit: "_PhasingFit", basis: np.ndarray, jac: str, max_nfev: int,
                  bound: float = np.inf) -> "optimize.OptimizeResult":
    """Least squares of :meth:`_PhasingFit.resid` over x = ``basis`` c (orthonormal columns:
    the determined directions), started at c = 0, so the directions outside the span stay
    exactly 0. Returns ``x`` (scaled parameters), ``fun``, ``jac`` (the full Jacobian at x,
    closed form or forward differences of step 1e-6), ``njev``, ``success``, ``message``.

    ``bound`` [scaled parameter units] keeps every component of x inside +-bound, as the
    full fit's box does: with orthonormal columns |x_i| <= |x| = |c| <= sqrt(k) max |c_j|,
    so each of the k coordinates c_j is held to bound / sqrt(k) (a geometrically impossible
    layout, e.g. on passes that hold no phasing, can then never be reached)."""
    if basis.shape[1] == 0:        # nothing determined: the parameters stay at 0
        x = np.zeros(basis.shape[0])
        return optimize.OptimizeResult(x=x, fun=fit.resid(x), jac=_jacobian_at(fit, x, jac), njev=1,
                              success=True, message="no determined direction to fit")

    def resid(c):
        return fit.resid(basis @ c)

    def jac_c(c):
        return fit.jac(basis @ c) @ basis

    cb = bound / math.sqrt(basis.shape[1])
    sol = optimize.least_squares(resid, np.zeros(basis.shape[1]), jac=jac_c if fit.analytic else jac,
                        method="trf", x_scale=1.0, diff_step=1e-6, max_nfev=max_nfev,
                        bounds=(-cb, cb))
    x = basis @ sol.x
    return optimize.OptimizeResult(x=x, fun=fit.resid(x), jac=_jacobian_at(fit, x, jac),
                          njev=(sol.njev or 0) + 1, success=sol.success, message=sol.message)


def _jacobian_at(fit: "_PhasingFit", x: np.ndarray, jac: str) -> np.ndarray:
    """Jacobian of :meth:`_PhasingFit.resid` at the scaled parameters ``x``: closed form, or
    forward differences of step 1e-6 (scipy.optimize.approx_fprime)."""
    if fit.analytic:
        return fit.jac(x)
    return np.atleast_2d(optimize.approx_fprime(x, fit.resid, 1e-6)).reshape(fit.meas.size, x.size)


def _kept(s: np.ndarray, rcond: float) -> np.ndarray:
    """Singular values above ``rcond`` times the largest (the rank rule) [bool]."""
    return s > rcond * (s[0] if s.size and s[0] > 0 else 1.0)


#: a singular value within this factor of the rank threshold makes the rank decision marginal
MARGINAL_FACTOR = 2.0


#: coefficients of a combination's description below this are left out of the words [-]
DESCRIBE_MIN = 0.05


#: angular tolerance for naming a direction after a planet or a gear axis [rad]
DESCRIBE_ANGLE = math.radians(5.0)


#: record-length multiples tried by :func:`_suggestions` [-]
RECORD_FACTORS = (2, 4, 8, 16, 32, 64)


#: a parameter counts as identifiable when this share of its direction lies in the span of
#: the kept singular vectors [-] (as in :func:`identify_errors`)
RESOLUTION = 0.95


def _rank_note(s: np.ndarray, keep: np.ndarray, rcond: float) -> str:
    """The rank decision in words: threshold, smallest kept and largest dropped singular
    value relative to the largest, and whether one lies within :data:`MARGINAL_FACTOR` of the
    threshold (then a different rcond, or a little more or less data, changes the rank)."""
    if not s.size or not s[0] > 0:
        return "rank 0: the weighted design is zero (the data see none of the parameters)"
    rel = s / s[0]
    kept, dropped = rel[keep], rel[~keep]
    text = (f"rank {int(keep.sum())} of {s.size}: singular values above rcond = {rcond:.3g} "
            f"of the largest count as determined (")
    text += f"smallest kept {kept.min():.3g}" if kept.size else "none kept"
    text += f", largest dropped {dropped.max():.3g})" if dropped.size else ", none dropped)"
    near = np.any((rel > rcond / MARGINAL_FACTOR) & (rel < rcond * MARGINAL_FACTOR))
    if near:
        text += (f"; the decision is marginal: a singular value lies within a factor "
                 f"{MARGINAL_FACTOR:g} of the threshold")
    return text


def _combinations(vt_keep: np.ndarray, rel_s: np.ndarray, cov_free: np.ndarray,
                  est_free: np.ndarray, names: list, gearset: Gearset) -> list:
    """The combinations of the free Cartesian parameters the data determine: the kept right
    singular vectors of the weighted design (every column scaled alike, so each is a
    unit-norm combination of offsets in metres).

    Each singular vector v gives the estimate v . p [m] and its standard deviation
    sqrt(v^T C v) [m] from the parameters' covariance C (the fit's residual scale and the
    pass-timing systematic term); 95 % interval +-1.96 std. The sign makes the largest
    coefficient positive. Ordered by standard deviation, smallest first.
    """
    out = []
    for v, r in zip(vt_keep, rel_s):
        v = v * math.copysign(1.0, v[int(np.argmax(np.abs(v)))])
        est = float(v @ est_free)
        std = float(math.sqrt(max(float(v @ cov_free @ v), 0.0)))
        out.append({"description": describe_combination(v, names, gearset),
                    "coefficients": {nm: float(c) for nm, c in zip(names, v)},
                    "estimate": est, "std": std, "ci95": [est - 1.96 * std, est + 1.96 * std],
                    "relative_singular_value": float(r)})
    out.sort(key=lambda c: c["std"])
    return out


def describe_combination(coefficients, names, gearset: Gearset) -> str:
    """A combination of Cartesian offset parameters in a rig engineer's words.

    Each gear's pair (x, y) of coefficients is one term: its length times the gear's offset
    along the pair's direction. A sun or ring direction within 5 deg of a planet's line of
    centres at the time origin (psi_n) is named after that planet ("towards planet n"); a
    planet's x is its inward radial (towards the sun), y its tangential direction
    (:class:`~meshphase.models.mesh_phasing.ShaftHoleErrors`). Terms shorter than
    :data:`DESCRIBE_MIN` are left out (and said to be).

    Parameters
    ----------
    coefficients : array_like, shape (P,)
        Coefficients [-] of the parameters ``names``.
    names : list of str
        Parameter names (:func:`PARAMETER_NAMES` entries), as many as coefficients.
    gearset : Gearset
        Planet angles psi_n [rad].

    Returns
    -------
    str
        e.g. "0.71 sun offset towards planet 1 - 0.70 planet 1 radial offset (towards the
        sun)"; "0" for a zero combination.
    """
    c = np.asarray(coefficients, dtype=float)
    names = list(names)
    if c.ndim != 1 or c.size != len(names):
        raise ValueError(f"coefficients must be 1-D with one entry per name ({len(names)}), "
                         f"got shape {c.shape}")
    if not np.all(np.isfinite(c)):
        raise ValueError(f"coefficients must be finite, got {c.tolist()}")
    if not isinstance(gearset, Gearset):
        raise TypeError(f"gearset must be a Gearset, got {type(gearset).__name__}")
    known = set(PARAMETER_NAMES(gearset.n_planets))
    bad = [nm for nm in names if nm not in known]
    if bad:
        raise ValueError(f"unknown parameter name(s) {bad}; expected {sorted(known)}")
    pairs: dict = {}
    for nm, v in zip(names, c):
        gear, axis = nm.rsplit("_", 1)
        pairs.setdefault(gear, [0.0, 0.0])[axis == "y"] = float(v)
    psi = np.asarray(gearset.angles, dtype=float)
    terms, left_out = [], False
    for gear, (a, b) in pairs.items():
        m = math.hypot(a, b)
        if m < DESCRIBE_MIN:
            left_out = left_out or m > 0
            continue
        sign, what = _term_words(gear, math.atan2(b, a), psi)
        terms.append((sign * m, what))
    if not terms:
        return "0"
    terms.sort(key=lambda t: -abs(t[0]))
    text = ""
    for i, (k, what) in enumerate(terms):
        op = ("-" if k < 0 else "") if i == 0 else (" - " if k < 0 else " + ")
        text += f"{op}{abs(k):.2f} {what}"
    return text + (" (+ smaller terms)" if left_out else "")


def _term_words(gear: str, phi: float, psi: np.ndarray) -> tuple[float, str]:
    """(sign, words) of one gear's offset along direction ``phi`` [rad]."""
    def near(target):
        return abs(float(wrap((phi - target) / TWO_PI))) * TWO_PI < DESCRIBE_ANGLE
    if gear in ("sun", "ring"):
        for sign, turn in ((1.0, 0.0), (-1.0, math.pi)):
            for n, p in enumerate(psi, start=1):
                if near(p + turn):
                    return sign, f"{gear} offset towards planet {n}"
        return 1.0, f"{gear} offset along {math.degrees(phi):.0f} deg"
    num = gear[len("planet"):]
    for sign, target, what in ((1.0, 0.0, "radial offset (towards the sun)"),
                               (-1.0, math.pi, "radial offset (towards the sun)"),
                               (1.0, math.pi / 2, "tangential offset"),
                               (-1.0, -math.pi / 2, "tangential offset")):
        if near(target):
            return sign, f"planet {num} {what}"
    return 1.0, f"planet {num} offset at {math.degrees(phi):.0f} deg from its inward radial"


def _schedule_rows(fit: "_PhasingFit", gauge: str, tau_start: float, tau_end: float,
                   weight: float, errors: ShaftHoleErrors) -> tuple[np.ndarray, float]:
    """Weighted design rows (as :meth:`_PhasingFit.jac`) of a ``gauge`` that meets planet 1
    at angle time ``tau_start`` [s] and then every planet of each whole relative revolution
    that starts before ``tau_end`` [s] and fits in it, at the fit's speeds, each pass
    weighted ``weight`` [1/mesh cycles]; and the angle time of the next revolution's planet-1
    pass [s] (where a continuation starts in the same phase)."""
    g = fit.gearset
    sp = next(iter(fit.speeds.values()))
    o = pass_order(g.direction, gauge)
    z = g.z_sun if gauge == "sun" else g.z_ring
    w = abs(sp.w_sc if gauge == "sun" else sp.w_rc)
    psi = np.asarray(g.angles, dtype=float)
    lag = np.mod(o * (psi[1:] - psi[0]), TWO_PI)             # angle from planet 1 to planet n
    n_rev = max(0, int(math.floor((tau_end - tau_start) * w / TWO_PI)))
    nxt = tau_start + TWO_PI * n_rev / w
    if n_rev < 1 or lag.size == 0:
        return np.empty((0, int(fit.free.sum()))), nxt
    tau_1 = np.repeat(tau_start + TWO_PI * np.arange(n_rev) / w, lag.size)
    tau_n = tau_1 + np.tile(lag, n_rev) / w
    planet = np.tile(np.arange(2, g.n_planets + 1), n_rev)
    m = tau_1.size
    plan = MeshGradientPlan(np.concatenate([tau_n, tau_1]),
                            np.concatenate([planet, np.ones(m, dtype=int)]), g, sp, mesh=gauge)
    _, j = plan.evaluate(errors)
    jac = (o * z / TWO_PI) * (j[:m] - j[m:])
    return -weight * jac[:, fit.free] * fit.scale, nxt


def _resolved_std(R: np.ndarray, rcond: float, s2: float, scale: float) -> tuple:
    """(identifiable per column, standard deviation per column [m]) of a weighted design in
    scaled parameters, given by its triangular QR factor ``R`` (same singular values and
    right singular vectors): the rank rule of :func:`identify_errors` and the statistical
    covariance s2 (J^T J)^+ on the kept subspace (NaN where not identifiable)."""
    _, s, Vt = np.linalg.svd(R, full_matrices=False)
    keep = s > rcond * (s[0] if s.size and s[0] > 0 else 1.0)
    ident = np.sum(Vt[keep] ** 2, axis=0) > RESOLUTION
    var = np.sum((Vt[keep] / s[keep, None]) ** 2, axis=0) * s2 * scale ** 2
    return ident, np.where(ident, np.sqrt(var), np.nan)


def _stack_r(*blocks) -> np.ndarray:
    """Triangular QR factor of the design rows ``blocks`` stacked (Householder QR: the
    singular values and right singular vectors of the stack, without its left ones)."""
    return np.linalg.qr(np.vstack(blocks), mode="r")


def _suggestions(fit: "_PhasingFit", sol, rcond: float, s2: float, names: list,
                 blind: list) -> list:
    """For each gear of ``blind``: the first of these additions to the data that makes its
    offset identifiable, with the predicted standard error of its components.

    The options, in order: the main gauge not recorded (sun or ring) over the same record;
    a second gauge on a recorded gear, a quarter of a relative revolution from the first;
    the record 2, 4, ... 64 times as long (every recorded gauge continues). Each adds the
    design rows such passes would give (same model, same speeds, at the fitted errors; an
    added gauge's passes weighted as the median of the recorded gauge of that gear, else of
    all) to the weighted design, and the rank rule of :func:`identify_errors` is applied
    again. The predicted standard error is the statistical one (residual scale ``s2`` of
    this fit), without the pass-timing systematic term. Face-width gauges measure no
    phasing and add no rows, so they are not among the options.

    Returns
    -------
    list of dict
        Per gear: ``option`` (the first that identifies it, None: none does),
        ``predicted_std`` [m] (the larger of its two components'), ``tried`` (the options
        tried up to it), ``record_option``, ``record_factor`` [-], ``record_s`` [s] and
        ``record_predicted_std`` [m] of the shortest longer record that does, ``note``.
    """
    if not blind:
        return []
    ok = fit.ok
    taus = [np.concatenate([st.tau_n[st.ok], st.tau_1[st.ok]]) for st in fit.setups if st is not None]
    taus = np.concatenate(taus) if taus else np.empty(0)
    taus = taus[np.isfinite(taus)]
    if taus.size < 2:
        nan = float("nan")
        return [{"gear": g, "option": None, "predicted_std": nan, "tried": [],
                 "record_option": None, "record_factor": nan, "record_s": nan,
                 "record_predicted_std": nan, "note": f"{g}: no pass times to extend"}
                for g in blind]
    lo, hi = float(taus.min()), float(taus.max())
    errors = fit._errors(sol.x)
    gauges = list(dict.fromkeys(t.gauge for t in fit.tables))
    rows_of = np.concatenate([np.full(len(t), t.gauge) for t in fit.tables])
    w_all = float(np.median(fit.w[ok]))
    weight = {g: float(np.median(fit.w[ok & (rows_of == g)])) if np.any(ok & (rows_of == g))
              else w_all for g in ("sun", "ring")}
    sp = next(iter(fit.speeds.values()))
    base = _stack_r(sol.jac)

    def rows(gauge, a, b):
        return _schedule_rows(fit, gauge, a, b, weight[gauge], errors)

    # each recorded table continues in its own phase: from the revolution after its last
    # planet-1 pass (a gauge started at another phase is a gauge at another angle)
    nxt = []
    for t, st in zip(fit.tables, fit.setups):
        w = abs(sp.w_sc if t.gauge == "sun" else sp.w_rc)
        t1 = st.tau_1[st.ok]
        nxt.append((t.gauge, float(t1.max()) + TWO_PI / w if t1.size else hi))

    def options():
        for gauge in ("sun", "ring"):
            if gauge not in gauges:
                yield (f"add a {gauge} gauge over the same record", 1.0,
                       _stack_r(base, rows(gauge, lo, hi)[0]))
        for gauge in gauges:
            w = abs(sp.w_sc if gauge == "sun" else sp.w_rc)
            t1 = min(b for gg, b in nxt if gg == gauge) - TWO_PI / w
            t1 -= TWO_PI / w * math.floor((t1 - lo) * w / TWO_PI)  # its first revolution
            yield (f"add a second {gauge} gauge a quarter turn from the first", 1.0,
                   _stack_r(base, rows(gauge, t1 + 0.25 * TWO_PI / w, hi)[0]))
        R = base                # the record grows segment by segment: each QR adds only the new
        for f in RECORD_FACTORS:
            end = lo + f * (hi - lo)
            parts = [rows(gauge, start, end) for gauge, start in nxt]
            nxt[:] = [(gauge, p[1]) for (gauge, _), p in zip(nxt, parts)]
            R = _stack_r(R, *[p[0] for p in parts])
            yield f"record {f} times as long ({f * (hi - lo):.0f} s)", float(f), R

    free_names = [nm for nm, fr in zip(names, fit.free) if fr]
    cols = {g: [i for i, nm in enumerate(free_names) if nm.rsplit("_", 1)[0] == g] for g in blind}
    first: dict = {}         # gear -> (option, record factor, predicted std [m], options tried)
    record: dict = {}        # gear -> (option, record factor, predicted std [m]) of the records
    tried = []
    for text, factor, R in options():
        ident, std = _resolved_std(R, rcond, s2, fit.scale)
        tried.append(text)
        for g in blind:
            if np.all(ident[cols[g]]):
                got = (text, factor, float(np.max(std[cols[g]])))
                first.setdefault(g, got + (len(tried),))
                if text.startswith("record"):
                    record.setdefault(g, got)
        if len(record) == len(blind):
            break
    out = []
    nan = float("nan")
    for g in blind:
        text, factor, std, k = first.get(g, (None, nan, nan, len(tried)))
        r_text, r_factor, r_std = record.get(g, (None, nan, nan))
        if text is None:
            note = f"{g}: none of the options tried identifies it ({'; '.join(tried)})"
        else:
            note = f"{g}: {text} identifies it (predicted std {std * 1e3:.3g} mm)"
            if r_text is not None and r_text != text:
                note += f"; so does: {r_text} (predicted std {r_std * 1e3:.3g} mm)"
        out.append({"gear": g, "option": text, "predicted_std": std, "tried": tried[:k],
                    "record_option": r_text, "record_factor": r_factor,
                    "record_s": r_factor * (hi - lo), "record_predicted_std": r_std,
                    "note": note})
    return out


def identification_verdict(identification: Identification | None,
                           member_speeds: dict | None = None) -> str:
    """One paragraph for the top of a report: what the identification can tell, with the key
    numbers, and each member's measured speed.

    Parameters
    ----------
    identification : Identification or None
        None: no identification ran (only the speeds are told).
    member_speeds : dict, optional
        :func:`meshphase.kinematics.member_speeds.member_speeds` (its ``text``).

    Returns
    -------
    str
        Status (every offset identified, some combinations determined, or nothing), the
        phasing residual RMS before and after the fit [mesh cycles], the number of determined
        combinations out of the parameters, the best determined one with its 95 % interval
        [mm], what would identify the rest, and the speeds [r/min].
    """
    if identification is not None and not isinstance(identification, Identification):
        raise TypeError(f"identification must be an Identification or None, got "
                        f"{type(identification).__name__}")
    if member_speeds is not None and not isinstance(member_speeds, dict):
        raise TypeError(f"member_speeds must be a dict (member_speeds()) or None, got "
                        f"{type(member_speeds).__name__}")
    parts = []
    i = identification
    if i is None:
        parts.append("No shaft hole errors were identified (the identify stage did not run).")
    elif i.n_passes == 0:
        parts.append("No shaft hole error can be identified: there are no measured passes.")
    else:
        n_id = sum(bool(r["identifiable"]) for r in i.table)
        status = ("every requested offset is identified" if i.identifiable else
                  f"{n_id} of {len(i.table)} offsets are identified one by one" if n_id else
                  "no single offset is identified")
        parts.append(f"Identification: {status}; the fit lowers the phasing residual RMS from "
                     f"{i.rms_before:.3g} to {i.rms_after:.3g} mesh cycles over {i.n_passes} "
                     f"passes, and the data determine {i.rank} combination(s) of the "
                     f"{i.n_parameters} offset components"
                     + (" (a marginal rank: a singular value lies within a factor "
                        f"{MARGINAL_FACTOR:g} of the threshold)." if "marginal" in i.rank_note
                        else "."))
        if i.combinations:
            c = i.combinations[0]
            parts.append(f"Best determined: {c['description']} = {c['estimate'] * 1e3:.4g} mm "
                         f"(95 % interval {c['ci95'][0] * 1e3:.4g} to {c['ci95'][1] * 1e3:.4g} mm).")
        helped = [sg for sg in i.suggestions if sg["option"] is not None]
        never = [sg["gear"] for sg in i.suggestions if sg["option"] is None]
        by_option: dict = {}
        for sg in helped:
            by_option.setdefault(sg["option"], []).append(sg)
        for option, sgs in by_option.items():
            worst = max(sg["predicted_std"] for sg in sgs)
            text = (f"To identify {', '.join(sg['gear'] for sg in sgs)}: {option} "
                    f"(predicted std up to {worst * 1e3:.3g} mm)")
            rec = {sg["record_option"] for sg in sgs}
            if len(rec) == 1 and None not in rec and option not in rec:
                worst = max(sg["record_predicted_std"] for sg in sgs)
                text += f", or {rec.pop()}"
                turns = abs(member_speeds["carrier"]) / 60.0 * sgs[0]["record_s"] \
                    if member_speeds is not None else float("nan")
                if math.isfinite(turns) and turns > 0:
                    text += f", {turns:.3g} carrier turns"
                text += f" (up to {worst * 1e3:.3g} mm)"
            parts.append(text + ".")
        if never:
            parts.append(f"No extra gauge or longer record tried identifies {', '.join(never)}.")
    if member_speeds is not None:
        parts.append(f"Member speeds: {member_speeds['text']}.")
    return " ".join(parts)


def _identify_inputs(tables, gearset, gears) -> tuple[list, tuple]:
    """:func:`identify_errors`' tables (the non-empty ones) and gears, checked."""
    if isinstance(tables, PassTable):
        tables = [tables]
    tables = list(tables)
    for t in tables:
        if not isinstance(t, PassTable):
            raise TypeError(f"tables must hold PassTable objects, got {type(t).__name__}")
    tables = [t for t in tables if len(t) > 0]
    if not isinstance(gearset, Gearset):
        raise TypeError(f"gearset must be a Gearset, got {type(gearset).__name__}")
    if isinstance(gears, str):
        gears = (gears,)
    gears = tuple(gears)
    bad = set(gears) - {"sun", "ring", "planet"}
    if bad or not gears:
        raise ValueError("gears must be a non-empty selection of 'sun', 'ring', 'planet', got "
                         f"{gears!r}")
    return tables, gears


class _PhasingFit:
    """The weighted residuals of :func:`identify_errors`: measured phasing of the passes of
    ``tables`` against :func:`predict_pass_phasing` with the ``free`` Cartesian offset
    parameters (scaled by ``scale`` [m]); counts the model evaluations. With ``analytic``
    each evaluation also gives the Jacobian (:func:`meshphase.compare.pass_model.pass_phasing_jacobian`), kept for the
    :meth:`jac` call that follows at the same point."""

    def __init__(self, tables: list, gearset: Gearset, free: np.ndarray, *, analytic: bool = False):
        self.tables, self.gearset, self.free = tables, gearset, free
        self.analytic = analytic
        self._last = (None, None)      # (parameter bytes, Jacobian) of the last evaluation
        self.n_pl = gearset.n_planets
        self.speeds = {id(t): table_speeds(t, gearset) for t in tables}
        self.meas = np.concatenate([t.gamma for t in tables])
        unc = np.concatenate([t.uncertainty for t in tables])
        ideal = np.concatenate([predict_pass_phasing(t, gearset, None, speeds=self.speeds[id(t)])
                                for t in tables])
        r0 = wrap(self.meas - ideal)
        self.ok = ok = np.isfinite(r0)
        self.rms_before = float(np.sqrt(np.mean(r0[ok] ** 2))) if ok.any() else float("nan")
        # weights: given per-pass uncertainties, else the scatter of the residual about its mean
        floor = max(1e-6, 0.1 * float(np.nanmedian(unc))) if np.any(np.isfinite(unc)) else 1e-6
        w = 1.0 / np.where(np.isfinite(unc) & (unc > 0), np.maximum(unc, floor), np.nan)
        if not np.any(np.isfinite(w)):
            w = np.ones_like(self.meas)
        self.w = np.where(np.isfinite(w), w, np.nanmedian(w))
        self.scale = 1e-4 * gearset.carrier_radius  # parameter scale ~ a typical offset [m]
        self.n_eval = 0
        # the error-independent part of every model evaluation, prepared once
        self.setups = [pass_setup(t, gearset, None, self.speeds[id(t)], 0.0) for t in tables]
        self.plans = [gradient_plan(s, gearset) if analytic else None for s in self.setups]

    def _predict(self, p_free, pass_offset: float = 0.0) -> np.ndarray:
        err = self._errors(p_free)
        return np.concatenate([predict_pass_phasing(t, self.gearset, err, speeds=self.speeds[id(t)],
                                                    pass_offset=pass_offset)
                               for t in self.tables])

    def _errors(self, p_free) -> ShaftHoleErrors:
        p = np.zeros(self.free.size)
        p[self.free] = p_free * self.scale
        return _errors_from_vector(p, self.n_pl)

    def model(self, p_free) -> np.ndarray:
        """Predicted phasing of every pass [mesh cycles] (one model evaluation)."""
        self.n_eval += 1
        if not self.analytic:
            return self._predict(p_free)
        err = self._errors(p_free)
        parts = [gamma_and_jacobian(s, self.gearset, err, pl)
                 for s, pl in zip(self.setups, self.plans)]
        J = np.concatenate([j for _, j in parts])[:, self.free] * self.scale
        self._last = (np.asarray(p_free, dtype=float).tobytes(), J)
        return np.concatenate([g for g, _ in parts])

    def jac(self, p_free) -> np.ndarray:
        """Jacobian of :meth:`resid` in the scaled free parameters (rows 0 where the
        measurement is not finite); reuses the evaluation at the same point."""
        key = np.asarray(p_free, dtype=float).tobytes()
        if self._last[0] != key:
            self.model(p_free)
        J = -self.w[:, None] * self._last[1]
        return np.where(self.ok[:, None], J, 0.0)

    def resid(self, p_free) -> np.ndarray:
        """Weighted wrapped residuals (0 where the measurement is not finite)."""
        r = wrap(self.meas - self.model(p_free)) * self.w
        return np.where(self.ok, r, 0.0)

    def covariance(self, sol, U, s, Vk, keep, pass_offset_std: float) -> np.ndarray:
        """Covariance of the free parameters [m^2]: sigma^2 (J^T J)^+ on the identifiable
        subspace, plus the systematic term of ``pass_offset_std`` [mesh cycles]."""
        dof = max(1, int(self.ok.sum()) - int(keep.sum()))
        s2 = float(np.sum(sol.fun ** 2)) / dof  # reduced chi-square: rescales the given
        cov_free = s2 * (Vk / s[keep] ** 2) @ Vk.T * self.scale ** 2     # uncertainties
        if pass_offset_std and pass_offset_std > 0 and s.size:
            # systematic part: parameters' response to a common shift of where the passes are
            # timed relative to the engagement (pseudo-inverse of the weighted Jacobian applied
            # to the change of the weighted residuals)
            h = 0.01
            shifted = self._predict(sol.x, pass_offset=h)
            base = self.model(sol.x)
            dr = np.where(self.ok, wrap(shifted - base) * self.w, 0.0) / h   # d(prediction)/d offset
            dp = (Vk / s[keep]) @ (U[:, keep].T @ dr) * self.scale        # d(parameters)/d offset [m]
            cov_free = cov_free + pass_offset_std ** 2 * np.outer(dp, dp)
        return cov_free


def _gear_rows(p_hat: np.ndarray, cov: np.ndarray, free: np.ndarray, ident_full: np.ndarray,
               watched: set, n_pl: int) -> tuple[list, list]:
    """The per-gear table of :class:`Identification` (e, kappa and their uncertainties by
    the delta method) and the notes on what the data cannot see (``watched``: the gauged
    gears)."""
    rows = []
    notes = []
    gear_list = [("sun", 0), ("ring", 2)] + [(f"planet{i + 1}", 4 + 2 * i) for i in range(n_pl)]
    for gear, i in gear_list:
        if not free[i]:
            continue
        x, y = p_hat[i], p_hat[i + 1]
        C = cov[i:i + 2, i:i + 2]
        e = math.hypot(x, y)
        idf = bool(ident_full[i] and ident_full[i + 1])
        if idf and e > 0:
            g = np.array([x, y]) / e
            e_std = float(math.sqrt(max(g @ C @ g, 0.0)))
            gk = np.array([-y, x]) / e ** 2
            k_std = float(math.sqrt(max(gk @ C @ gk, 0.0)))
        else:
            e_std = k_std = float("nan")
        note = ""
        if not idf:
            note = "not identifiable from these data"
            if gear in watched:
                note += f" (a {gear} gauge turns with the {gear} offset and cannot see it)"
            notes.append(f"{gear}: {note}")
        elif e_std > e:
            note = "offset smaller than its uncertainty; angle undefined"
        rows.append({"gear": gear, "e": e if idf else float("nan"), "e_std": e_std,
                     "e_ci95": [e - 1.96 * e_std, e + 1.96 * e_std] if idf else [float("nan")] * 2,
                     "kappa": math.atan2(y, x) if idf and e > 0 else float("nan"),
                     "kappa_std": k_std, "identifiable": idf, "note": note})
    return rows, notes
