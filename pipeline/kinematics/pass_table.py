"""The measured phasing of each pass, read off the angle model (spec section 3).

Array functions: pass trains and the fitted angle model in, a :class:`PassTable` of per-pass
phasing out (:func:`phasing_from_model`; :func:`measured_phasing` for one gauge's onset times
on their own). No Recording, no files.

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
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

from ..errors import ProcessingWarning
from .angle_windows import fit_angle_windows
from .angles import AngleModel
from .reliability import INSEPARABLE_SHARE, UNRELIABLE_RATIO
from .shafts import Kinematics
from .trains import PassTrain, gauge_train, revolution_numbers, tacho_train
from ..validate import as_finite_array, as_positive_int

__all__ = ["PassTable", "pass_order", "planet_fractions", "GaugeEncoder", "phasing_from_model",
           "measured_phasing", "nearest_index"]

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
        sigma_1 combined (NaN without timing bounds); from :func:`meshphase.kinematics.phasing.measure_phasing` with
        the bounds in the gauge's noise spectrum (``sigma`` times
        :attr:`meshphase.kinematics.planet_labels.GaugePasses.floor_factor`), the floor the reliability is judged against.
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
        Pass-order positions (:func:`meshphase.kinematics.planet_labels.assign_planets_by_pattern` ``info["position"]``);
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


def nearest_index(sorted_times: np.ndarray, t) -> np.ndarray:
    """Index of the entry of ``sorted_times`` (increasing, at least two) nearest each of
    ``t`` (a tie goes to the later one)."""
    u = np.asarray(sorted_times, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)
    k = np.clip(np.searchsorted(u, t), 1, u.size - 1)
    return np.where(np.abs(u[k - 1] - t) < np.abs(u[k] - t), k - 1, k)
