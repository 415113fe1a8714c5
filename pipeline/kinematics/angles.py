"""One kinematic angle model for a whole recording (the "angles" step of the flow: onsets -> angles -> phasing).

Array code: pass trains (onset times with their planet labels and pass-order positions) in,
a fitted :class:`AngleModel` out. No Recording, no files.

The mesh angle
--------------
Every mesh of a simple planetary gearset runs at the same mesh frequency, whatever member is
held: Z_s |w_sc| = Z_r |w_rc| = Z_p |w_pc| (Willis). So one angle describes the whole gear
train: the *mesh angle* ``A(t)`` [mesh cycles], the number of mesh cycles since an origin,
increasing with time in either sense of rotation. A gauge on sun tooth j meets planet n when
the sun, relative to the carrier, has turned to the planet's direction, i.e. at

    A = Z_s (k + f_n) + c + d_n + h_n          (sun gauge, relative revolution k)        (1)

with ``f_n`` the planet's fraction of a revolution in the gauge's pass order
(:func:`meshphase.kinematics.pass_table.planet_fractions`), ``c`` a constant of the gauge (which tooth, which
pulse feature is timed), ``d_n`` planet n's phasing deviation from the ideal (the quantity of
interest) and ``h_n`` its time-varying part (a planet's own shaft hole offset turns with the
planet and moves its passes: terms periodic in the planet's spin, Z_p mesh cycles per turn).
A ring gauge obeys (1) with Z_r; a carrier once-per-revolution tacho, when a member is held,
fires at A = P_c k + c_T with P_c = Z_r (ring held) or Z_s (sun held) mesh cycles per carrier
revolution; a shaft encoder of p pulses per turn fires at A = (P_shaft / p) k + c_E
(:func:`meshphase.kinematics.trains.encoder_train`, P_shaft from :func:`meshphase.kinematics.shafts.shaft_cycles`). Measured phasing is then the
mesh angle turned between two passes,
gamma_n = frac(A(t_n) - A(t_1)) (spec section 3; at constant speed frac((t_n - t_1) / T)).

The model
---------
The rig's speed is never assumed; ``A(t)`` is estimated from every pass train at once::

    A(t) = S(t) + sum_rho sum_m (a + a' x) cos(2 pi m S / P_rho) + (b + b' x) sin(...)       (2)

``S`` a cubic B-spline in time (slow drift, ramps), the sums the speed ripple locked to the
shaft angles present (carrier, sun, ring, planet spin: P_rho mesh cycles per turn of that
shaft, from the tooth counts; drive and eccentricity ripple follow the shaft angle, so the
terms are periodic in angle, and a periodic-in-angle speed gives exactly such a series in the
smooth angle S), optionally with amplitudes changing linearly in the scaled time x in [-1, 1]
(a relative ripple under a ramp). The per-train constants, per-planet offsets d and planet
terms h of (1) are separate parameters: a speed change moves every pass of every gauge
together, an offset moves only one planet's passes of one gauge, and the two are told apart
by their different sampling of the shaft angles. A term that the data cannot tell apart
from others (a column in the span of earlier columns, e.g. the planet-spin term at a ring
gauge when Z_r / Z_p is an integer: the planet shows the same tooth at every ring pass) is
dropped with a note; the effective rank is reported.

The fit (:func:`fit_angle_model`) builds the design of every train
(:mod:`meshphase.kinematics.angle_design`, weighted Gauss-Newton), chooses the model order
from the data (:mod:`meshphase.kinematics.angle_selection`, BIC), refits the models that
explain the passes about as well (:mod:`meshphase.kinematics.angle_choice`) and returns an
:class:`AngleModel`: the mesh angle, its rate, its uncertainty and the spread over the
competing models. The pass trains are :mod:`meshphase.kinematics.trains`, the shaft periods
:mod:`meshphase.kinematics.shafts`.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from ..errors import ProcessingWarning
from .angle_choice import INSEPARABLE_RIPPLE, model_competitors
from .angle_design import Design, ModelFit, ModelSpec
from .angle_selection import (drop_gross_outliers, knot_ladder, ripple_rates, select_terms,
                              variance_factors)
from .shafts import Kinematics, held_member, typed_resolution  # noqa: F401 (run/ imports them here)
from .trains import PassTrain

__all__ = ["AngleModel", "TrainFit", "fit_angle_model", "held_member", "typed_resolution"]


@dataclass
class TrainFit:
    """Fit diagnostics of one train.

    Attributes
    ----------
    name, kind : str
    n, n_outliers : int
        Observations used and left out (residual beyond 6 times the train's scatter).
    scale : float
        Variance factor: residual scatter / timing bound [-] (leverage-corrected).
    rms : float
        Residual RMS [mesh cycles].
    lag1 : float
        Lag-1 autocorrelation of the normalised residuals per planet, averaged [-] (near 0
        for a model that follows the speed; near 1 for systematic misfit).
    """

    name: str
    kind: str
    n: int
    n_outliers: int
    scale: float
    rms: float
    lag1: float


@dataclass
class AngleModel:
    """The fitted mesh angle of a recording (module notes) and its diagnostics.

    Use :meth:`mesh_angle` / :meth:`mesh_rate` for A(t) and dA/dt, :meth:`difference_std`
    for the model's own uncertainty of A(t_a) - A(t_b), :meth:`train` for a train's
    diagnostics, ``offsets`` for the per-planet phasing deviations the fit estimated.

    Attributes
    ----------
    t_span : tuple of float
        First and last observation time [s] (the model is fitted there; outside it is
        extrapolated).
    terms : str
        The selected model order, in words.
    rank, n_parameters : int
        Effective rank and columns of the final design.
    dropped : list of str
        Columns the data could not tell apart from earlier ones.
    trains : list of TrainFit
    residual_rms : float
        Weighted-average residual RMS over all trains [mesh cycles].
    selection : list of tuple
        (step, terms, BIC) of the forward selection.
    notes : list of str
    wall_time : float [s]
    competitors : list of Competitor
        Models that explain the passes about as well as the chosen one (module notes,
        "Model choice"); their spread is :meth:`choice_spread`.
    """

    t_span: tuple
    terms: str
    rank: int
    n_parameters: int
    dropped: list
    trains: list
    residual_rms: float
    selection: list
    notes: list
    wall_time: float
    iterations: int
    converged: bool
    offsets: dict = field(default_factory=dict)
    _design: Design = field(default=None, repr=False)
    _fit: ModelFit = field(default=None, repr=False)
    competitors: list = field(default_factory=list)
    _choice_ref: ModelFit = field(default=None, repr=False)

    def mesh_angle(self, t) -> np.ndarray:
        """Mesh angle A(t) [mesh cycles] at times ``t`` [s]."""
        return self._design.a_part(self._fit.theta, self._fit.lay, self._fit.spec, t)[0]

    def mesh_rate(self, t) -> np.ndarray:
        """Mesh frequency dA/dt [cycles/s] at times ``t`` [s]."""
        return self._design.a_part(self._fit.theta, self._fit.lay, self._fit.spec, t)[1]

    def difference_std(self, t_a, t_b) -> np.ndarray:
        """Standard deviation of A(t_a) - A(t_b) from the fit's covariance [mesh cycles]."""
        f = self._fit
        ga = self._design.a_part(f.theta, f.lay, f.spec, t_a)[2][:, f.keep]
        gb = self._design.a_part(f.theta, f.lay, f.spec, t_b)[2][:, f.keep]
        g = ga - gb
        return np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", g, f.cov, g), 0.0))

    def choice_spread(self, t_a, t_b, *, tolerance: float = 0.0) -> tuple[np.ndarray, list]:
        """How far the competing models (``competitors``) move A(t_a) - A(t_b).

        Parameters
        ----------
        t_a, t_b : array_like, shape (n,)
            Pass times [s].
        tolerance : float
            An inseparable competitor whose difference from the chosen model is at most this
            (RMS over the pairs) [mesh cycles], or at most what a common ripple of
            ``INSEPARABLE_RIPPLE`` at the planet spin rate can do, is reported but not
            counted: the chosen model (planet terms, which every planet's own shaft hole
            offset is certain to give) stands for it.

        Returns
        -------
        spread : ndarray, shape (n,)
            One-sigma model-choice uncertainty of A(t_a) - A(t_b) [mesh cycles]: the
            posterior-weighted second moment of the competitors' values about the chosen
            model's, plus the whole difference to a counted competitor the data cannot tell
            from the chosen model at all (its weight is not the data's to give), taken over
            every phase of the common term the two split differently (the move and its
            quarter turn in quadrature).
        info : list of dict
            Per competitor: ``words``, ``versus``, ``terms``, ``delta_bic`` [-], ``weight``
            [-], ``inseparable``, ``counted``, ``ripple_bound`` [mesh cycles], ``rms`` (RMS
            over the pairs of its difference from the chosen model [mesh cycles]) and ``n``.

        Raises
        ------
        ValueError
            ``t_a`` and ``t_b`` of different shapes; a negative or NaN ``tolerance``.
        """
        ta = np.atleast_1d(np.asarray(t_a, dtype=float))
        tb = np.atleast_1d(np.asarray(t_b, dtype=float))
        if ta.shape != tb.shape:
            raise ValueError(f"t_a and t_b must have one shape, got {ta.shape} and {tb.shape}")
        tolerance = float(tolerance)
        if not tolerance >= 0.0:
            raise ValueError(f"tolerance must be >= 0 [mesh cycles], got {tolerance!r}")
        if not self.competitors or ta.size == 0:
            return np.zeros(ta.shape), []
        d = self._design

        def turned(f):
            return d.a_part(f.theta, f.lay, f.spec, ta)[0] - d.a_part(f.theta, f.lay, f.spec, tb)[0]

        base = turned(self._choice_ref)
        var = np.zeros(ta.shape)
        whole = np.zeros(ta.shape)
        info = []
        for c in self.competitors:
            dl = turned(c.fit) - base
            if c.turned is not None:
                # every phase of the common term: the move and its quarter turn together
                dl = np.hypot(dl, turned(c.turned) - base)
            rms = float(np.sqrt(np.mean(dl ** 2)))
            least = tolerance
            if math.isfinite(c.ripple_bound):
                least = max(least, INSEPARABLE_RIPPLE / 0.01 * c.ripple_bound)
            counted = not c.inseparable or rms > least
            if c.inseparable and counted:
                np.maximum(whole, dl ** 2, out=whole)
            elif not c.inseparable:
                var += c.weight * dl ** 2
            info.append({"words": c.words, "versus": c.versus, "terms": c.terms,
                         "delta_bic": c.delta_bic, "weight": c.weight,
                         "inseparable": c.inseparable, "counted": counted,
                         "ripple_bound": c.ripple_bound, "rms": rms, "n": int(ta.size)})
        return np.sqrt(var + whole), info

    def train(self, name: str) -> TrainFit:
        """Diagnostics of the train called ``name`` (KeyError naming the trains)."""
        for tr in self.trains:
            if tr.name == name:
                return tr
        raise KeyError(f"no train {name!r}; trains: {[t.name for t in self.trains]}")

    def scale_of(self, name: str) -> float:
        """Variance factor of train ``name`` [-] (1 when unknown)."""
        try:
            return float(self.train(name).scale)
        except KeyError:
            return 1.0

    def residuals(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """(times [s], residuals [mesh cycles]) of train ``name``'s observations."""
        d = self._design
        for q, tr in enumerate(d.trains):
            if tr.name == name:
                m = d.q == q
                return d.t[m], self._fit.resid[m]
        raise KeyError(f"no train {name!r}")

    def outlier_mask(self, name: str) -> np.ndarray:
        """True for the observations of train ``name`` left out as outliers."""
        d = self._design
        for q, tr in enumerate(d.trains):
            if tr.name == name:
                return ~d.active[d.q == q]
        raise KeyError(f"no train {name!r}")

    def summary(self) -> dict:
        """JSON-friendly diagnostics."""
        return {"terms": self.terms, "rank": self.rank, "n_parameters": self.n_parameters,
                "dropped": list(self.dropped), "residual_rms_cycles": self.residual_rms,
                "iterations": self.iterations, "converged": self.converged,
                "t_span_s": list(self.t_span), "wall_time_s": self.wall_time,
                "trains": [vars(t) for t in self.trains], "notes": list(self.notes),
                "selection": [{"step": s, "terms": m, "bic": b} for s, m, b in self.selection],
                "competitors": [{"explanation": c.words, "versus": c.versus, "terms": c.terms,
                                 "delta_bic": c.delta_bic, "weight": c.weight,
                                 "inseparable": c.inseparable} for c in self.competitors]}


def _dropped_notes(d: Design, lay: dict, keep: np.ndarray) -> tuple[list, list]:
    names = [nm for nm, k in zip(lay["names"], keep) if not k]
    notes = []
    if not names:
        return names, notes
    kin = d.kin
    spin = [nm for nm in names if "spin term" in nm]
    rest = [nm for nm in names if "spin term" not in nm]
    if spin:
        why = []
        for tr in d.trains:
            if tr.kind in ("sun", "ring") and kin.z_planet:
                z = kin.z_sun if tr.kind == "sun" else kin.z_ring
                if z % kin.z_planet == 0:
                    why.append(f"{tr.name}: Z/Z_p = {z}/{kin.z_planet} = {z // kin.z_planet} is an "
                               "integer, the planet shows the same tooth at every pass")
        notes.append(f"{len(spin)} planet spin term(s) not identifiable and dropped"
                     + (f": {'; '.join(why)}" if why else ""))
    if rest:
        notes.append(f"not identifiable and dropped: {', '.join(rest)}")
    return names, notes


def _lag1(resid: np.ndarray, pl: np.ndarray) -> float:
    vals = []
    for n in np.unique(pl):
        r = resid[pl == n]
        if r.size >= 6 and np.std(r) > 0:
            r = r - r.mean()
            vals.append(float(np.sum(r[1:] * r[:-1]) / np.sum(r * r)))
    return float(np.mean(vals)) if vals else float("nan")


def fit_angle_model(trains, kin: Kinematics, n_planets: int, *, max_harmonics: int = 4,
                    max_planet_harmonics: int = 2, outlier_k: float = 6.0,
                    max_knots: int | None = None, planet_ripple: bool = False) -> AngleModel:
    """Fit the mesh angle A(t) to every pass train and tacho at once (module notes).

    Parameters
    ----------
    trains : sequence of PassTrain
        Gauge trains (:func:`meshphase.kinematics.trains.gauge_train`) and at most one tacho (:func:`meshphase.kinematics.trains.tacho_train`);
        trains with fewer than 2 observations are ignored.
    kin : Kinematics
        Shaft periods and the held member (:func:`meshphase.kinematics.shafts.kinematics`).
    n_planets : int
        Number of planets N [-].
    max_harmonics : int
        Highest harmonic of each shaft ripple tried [-].
    max_planet_harmonics : int
        Highest harmonic of the planet spin terms tried [-].
    outlier_k : float
        Observations whose residual exceeds this many times the train's robust scatter are
        left out [-].
    max_knots : int, optional
        Cap on the spline intervals (default: knots at least two relative revolutions of the
        densest gauge train apart, at most 64 intervals).
    planet_ripple : bool
        Also try a common speed ripple at the planet spin rate. Off by default: on one
        gear's gauges it is the same as an equal term on every planet (each planet's own
        offset is certain to be there, a common planet-rate speed ripple is not), and only
        the two gears together over a long record tell them apart; tried on shorter records
        it takes up what the planets' own terms should (a 30-s seed-rig ramp: 4.7e-3 mesh
        cycles of error with it, 1e-4 without). Where a train without planet terms samples
        the planet spin (an encoder, :func:`meshphase.kinematics.trains.encoder_train`) the ripple is seen apart from
        the planets' terms and, when on, is tried on its own.

    Returns
    -------
    AngleModel

    Raises
    ------
    TypeError
        Trains that are not PassTrain, kin not Kinematics.
    ValueError
        No gauge train with at least 2 passes; n_planets < 1.
    """
    t_start = time.perf_counter()
    use = _usable_trains(trains, kin, n_planets)
    gauges = [tr for tr in use if tr.kind in ("sun", "ring")]
    notes: list[str] = []
    d = Design(use, kin, int(n_planets))
    ladder = knot_ladder(d, kin, gauges, max_knots)
    rates = ripple_rates(d, kin, planet_ripple, notes)
    spec = ModelSpec(knots=ladder[0], harm={r: 0 for r in rates}, mod={r: False for r in rates})
    # 1. base fit and gross outliers (mislabelled pulses are whole planet spacings off)
    fit = drop_gross_outliers(d, use, spec, outlier_k)
    # 2. forward selection on BIC (weights from the timing bounds alone)
    rejected: list = []
    spec, fit, selection = select_terms(d, spec, fit, ladder, rates, kin, max_harmonics,
                                         max_planet_harmonics, rejected=rejected)
    # 3. variance factors per train, outliers against the final model, final fit
    scale, fit = variance_factors(d, use, spec, fit, outlier_k)
    # 4. the models that explain the passes about as well (their spread joins the phasing's
    # uncertainty)
    choice_ref, competitors = model_competitors(d, spec, fit, rejected, kin)
    dropped, dnotes = _dropped_notes(d, fit.lay, fit.keep)
    notes.extend(dnotes)
    tfits = _train_fits(d, use, fit, scale, notes)
    act = d.active
    d.release()
    wall = time.perf_counter() - t_start
    if not fit.converged:
        warnings.warn(f"angle model: Gauss-Newton did not converge in {fit.iterations} iterations "
                      "(speed ripple too strong for its series?)", ProcessingWarning, stacklevel=2)
    return AngleModel(
        t_span=(d.t_lo, d.t_hi), terms=spec.describe(), rank=fit.rank,
        n_parameters=fit.lay["p"], dropped=dropped, trains=tfits,
        residual_rms=float(np.sqrt(np.mean(fit.resid[act] ** 2))) if act.any() else float("nan"),
        selection=selection, notes=notes, wall_time=wall, iterations=fit.iterations,
        converged=fit.converged, offsets=_offsets(use, fit), _design=d, _fit=fit,
        competitors=competitors, _choice_ref=choice_ref)


def _usable_trains(trains, kin, n_planets) -> list:
    """The trains the fit uses (2 or more observations), checked: the gauge with most passes
    first (its constant is the spline's), then the tacho."""
    if not isinstance(kin, Kinematics):
        raise TypeError(f"kin must be a Kinematics (meshphase.kinematics.shafts.kinematics), got {type(kin).__name__}")
    trains = list(trains)
    for tr in trains:
        if not isinstance(tr, PassTrain):
            raise TypeError(f"trains must hold PassTrain objects, got {type(tr).__name__}")
    if int(n_planets) < 1:
        raise ValueError(f"n_planets must be >= 1, got {n_planets!r}")
    use = [tr for tr in trains if len(tr) >= 2]
    gauges = [tr for tr in use if tr.kind in ("sun", "ring")]
    if not gauges:
        raise ValueError("fit_angle_model needs at least one gauge train with 2 or more passes")
    names = [tr.name for tr in use]
    if len(set(names)) != len(names):
        raise ValueError(f"train names must be unique, got {names}")
    return sorted(gauges, key=lambda tr: -len(tr)) + [tr for tr in use if tr.kind == "tacho"]


def _train_fits(d: Design, use: list, fit: ModelFit, scale: np.ndarray, notes: list) -> list:
    """One :class:`TrainFit` per train (outliers left out are named in ``notes``)."""
    tfits = []
    w = 1.0 / (d.sig * fit.rate)
    for q, tr in enumerate(use):
        m = d.q == q
        act = m & d.active
        r = fit.resid[act]
        tfits.append(TrainFit(tr.name, tr.kind, int(np.count_nonzero(act)),
                              int(np.count_nonzero(m & ~d.active)), float(scale[q]),
                              float(np.sqrt(np.mean(r ** 2))) if r.size else float("nan"),
                              _lag1(fit.resid[act] * w[act], d.pl[act])))
        if tfits[-1].n_outliers:
            notes.append(f"{tr.name}: {tfits[-1].n_outliers} observation(s) far off the model "
                         "(mislabelled or spurious pulses) left out")
    return tfits


def _offsets(use: list, fit: ModelFit) -> dict:
    """Per train and planet: the fitted offset and its standard deviation [mesh cycles]."""
    offsets = {}
    ob = fit.lay["blocks"]["off"]
    kept_idx = np.cumsum(fit.keep) - 1
    for q, n in zip(*np.nonzero(fit.lay["off_table"] >= 0)):
        col = ob.start + int(fit.lay["off_table"][q, n])
        n = int(n)
        std = float(math.sqrt(max(fit.cov[kept_idx[col], kept_idx[col]], 0.0))) if fit.keep[col] else float("nan")
        offsets.setdefault(use[q].name, {})[n] = (float(fit.theta[col]), std)
    return offsets
