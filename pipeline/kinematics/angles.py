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
(:func:`meshphase.kinematics.phasing.planet_fractions`), ``c`` a constant of the gauge (which tooth, which
pulse feature is timed), ``d_n`` planet n's phasing deviation from the ideal (the quantity of
interest) and ``h_n`` its time-varying part (a planet's own shaft hole offset turns with the
planet and moves its passes: terms periodic in the planet's spin, Z_p mesh cycles per turn).
A ring gauge obeys (1) with Z_r; a carrier once-per-revolution tacho, when a member is held,
fires at A = P_c k + c_T with P_c = Z_r (ring held) or Z_s (sun held) mesh cycles per carrier
revolution; a shaft encoder of p pulses per turn fires at A = (P_shaft / p) k + c_E
(:func:`encoder_train`, P_shaft from :func:`shaft_cycles`). Measured phasing is then the
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

Estimation: weighted Gauss-Newton on (2) (the ripple arguments depend on S), each step a
least-squares solve of the column-scaled weighted Jacobian by Householder QR (never the
normal equations; rank-revealing QR where a column has become dependent), halved while it
raises the misfit, and an iteration whose full step moves no prediction by the convergence
tolerance ends there (such a step is rounding). Weights 1 / (sigma_t A'(t)) from each
onset's timing bound, with one variance factor per train estimated from its residuals
(leverage-corrected; never below 1 when the timing bound was given). The model order (spline intervals, ripple harmonics per shaft,
amplitude modulation, planet-term harmonics) is chosen from the data by greedy forward
selection on the Bayesian information criterion (a candidate term is solved only when an
optimistic bound on its criterion, from one linearised step, could win: the same model for
less work); a pass whose residual is far outside its train's scatter (a mislabelled pulse)
is left out, with a count. Nothing depends on rounding:
selection needs a BIC gain of at least 2 and the residual variance in the criterion has a
floor (the timing bound: residuals inside it are no evidence for another term), so the same
onsets moved by 1e-9 s give the same model.

Model choice
------------
The selected order is one choice among models that may explain the passes about as well.
The neighbours of the chosen model (one step less of each term taken, the best term turned
down, a common speed ripple at the planet spin rate) are refitted; each within ``BIC_CLOSE``
of the chosen BIC (or below it) is a :class:`Competitor` with its posterior weight, and the
weighted spread of the phasing over them joins the uncertainty
(:meth:`AngleModel.choice_spread`), so nothing rests on a BIC gain of 2 alone. A common
planet-rate ripple and equal terms on every planet can be the very same columns over the
trains fitted (a gauge on a gear whose Z / Z_p is an integer, a carrier tacho: every pass
meets each planet at one spin angle); a rank test in both orders finds that from the data,
the two explanations are kept as an inseparable pair, and a train that meets the planet spin
at other angles (a shaft encoder) makes the columns independent, which clears the pair.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import linalg
from scipy.interpolate import BSpline

from meshphase.signal.median import median_of_finite
from meshphase.kinematics.encoder import EncoderEdges, shaft_of
from meshphase.errors import ProcessingWarning
from meshphase.runtime.threads import thread_pool
from meshphase.validate import as_finite_array, as_positive, as_positive_int

__all__ = ["PassTrain", "Kinematics", "AngleModel", "gauge_train", "tacho_train",
           "kinematics", "fit_angle_model", "revolution_numbers", "held_member",
           "typed_resolution", "relabel_train", "label_shift_costs", "slice_train",
           "mesh_cycles_per_carrier_turn", "unseen_ripples", "SHIFT_OBS", "Competitor"]

TWO_PI = 2.0 * math.pi
#: spline interval counts tried, in order
KNOT_LADDER = (1, 2, 3, 4, 6, 8, 11, 16, 22, 32, 45, 64)
#: columns whose share outside the span of earlier columns is below this are dropped [-]
RANK_TOL = 1e-7
#: BIC gain needed to accept a term [-] ("positive evidence", Kass & Raftery 1995)
BIC_GAIN = 2.0
#: floor of the mean squared weighted residual in the criterion [-] when no timing bound was
#: given (noise-free data); with bounds the floor is 1
CHI2_FLOOR = 1e-8


# ----------------------------------------------------------------------------- inputs
@dataclass(frozen=True)
class PassTrain:
    """One train of angle observations: a gauge's passes or the tacho's edges.

    Attributes
    ----------
    name : str
        Channel name (or "tacho").
    kind : {"sun", "ring", "tacho"}
        "tacho": a shaft pulse train (a carrier tacho or an encoder, :func:`encoder_train`):
        a constant of its own, no planet terms.
    times : ndarray, shape (m,)
        Observation times [s], strictly increasing.
    sigma : ndarray, shape (m,)
        One-sigma timing uncertainty of each observation [s] (> 0).
    target : ndarray, shape (m,)
        Mesh angle of each observation up to the train's constant and the planet terms
        [mesh cycles]: Z (k + f_n) for a gauge, P_c k for a tacho.
    planet : ndarray of int, shape (m,)
        0-based planet of each gauge pass; -1 for a tacho.
    position : ndarray of int, shape (m,)
        Pass-order position counted from the train's first pass (gauges; revolution
        k = position // N, planet 1 opens each revolution).
    sigma_given : bool
        True when ``sigma`` is a timing bound (the train's variance factor is then >= 1).
    z : int
        Tooth count of the gauged gear (0 for a tacho) [-].
    order : {+1, -1}
        Sense in which the gauge meets the planets (:func:`meshphase.kinematics.phasing.pass_order`):
        a planet's carrier-frame angle shift d psi moves its passes by
        ``order * z * d psi / 2 pi`` mesh cycles.
    """

    name: str
    kind: str
    times: np.ndarray
    sigma: np.ndarray
    target: np.ndarray
    planet: np.ndarray
    position: np.ndarray
    sigma_given: bool = True
    z: int = 0
    order: int = 1

    def __len__(self) -> int:
        return int(self.times.size)


def slice_train(train: PassTrain, lo: float, hi: float) -> tuple[PassTrain, int]:
    """The observations of ``train`` with ``lo <= time < hi`` [s], and the index of the first.

    Labels, positions and targets are kept as they are (a slice of the train, not a new
    train counted from its own first pass).
    """
    if not isinstance(train, PassTrain):
        raise TypeError(f"train must be a PassTrain, got {type(train).__name__}")
    lo, hi = float(lo), float(hi)
    if math.isnan(lo) or math.isnan(hi):
        raise ValueError(f"lo and hi must be numbers, got {lo!r}, {hi!r}")
    i0, i1 = np.searchsorted(train.times, [lo, hi], side="left")
    s = slice(int(i0), int(max(i0, i1)))
    return replace(train, times=train.times[s], sigma=train.sigma[s], target=train.target[s],
                   planet=train.planet[s], position=train.position[s]), int(i0)


def _check_times(times, name: str) -> np.ndarray:
    t = as_finite_array(times, name, ndim=1)
    if t.size > 1 and np.any(np.diff(t) <= 0):
        raise ValueError(f"{name} must be strictly increasing")
    return t


def _sigma(sigma, n: int, default: float) -> tuple[np.ndarray, bool]:
    if sigma is None:
        return np.full(n, default), False
    s = np.broadcast_to(np.asarray(sigma, dtype=float), (n,)).astype(float)
    bad = ~np.isfinite(s) | (s <= 0)
    if np.all(bad) and n:
        return np.full(n, default), False
    if np.any(bad):
        s[bad] = np.median(s[~bad])
    return s, True


def gauge_train(name: str, gear: str, times, planet, position, fractions, z_gear: int, *,
                sigma=None, order: int = 1) -> PassTrain:
    """A gauge's pass train for :func:`fit_angle_model`.

    Parameters
    ----------
    name : str
        Channel name.
    gear : {"sun", "ring"}
        Gear carrying the gauge.
    times : array_like, shape (m,)
        Pass times [s], strictly increasing.
    planet : array_like of int, shape (m,)
        0-based planet per pass (>= 0: pass unassigned pulses separately, not here).
    position : array_like of int, shape (m,)
        Pass-order position of each pass (:func:`meshphase.kinematics.phasing.assign_planets_by_pattern`
        ``info["position"]``): consecutive planets differ by 1, a revolution by N.
    fractions : array_like, shape (N,)
        Fraction of a revolution from planet 1 to planet n in pass order [-]
        (:func:`meshphase.kinematics.phasing.planet_fractions`).
    z_gear : int
        Tooth count of the gauged gear [-].
    sigma : float or array_like, optional
        Timing uncertainty per pass [s] (the onset timing bound). None: unknown (the
        train's scatter sets it).
    order : {+1, -1}
        The gauge's pass order (:func:`meshphase.kinematics.phasing.pass_order`), which sets the sign
        with which a planet's own angle shift moves its passes.
    """
    if order not in (1, -1):
        raise ValueError(f"order must be +1 or -1, got {order!r}")
    if gear not in ("sun", "ring"):
        raise ValueError(f"gear must be 'sun' or 'ring', got {gear!r}")
    t = _check_times(times, "times")
    pl = np.asarray(planet)
    pos = np.asarray(position)
    if pl.shape != t.shape or pos.shape != t.shape:
        raise ValueError(f"planet {pl.shape} and position {pos.shape} must have the shape of "
                         f"times {t.shape}")
    if t.size and (not np.issubdtype(pl.dtype, np.integer) or not np.issubdtype(pos.dtype, np.integer)):
        raise TypeError("planet and position must be integer arrays")
    f = as_finite_array(fractions, "fractions", ndim=1, allow_empty=False)
    n = f.size
    if t.size and (pl.min() < 0 or pl.max() >= n):
        raise ValueError(f"planet must lie in [0, {n - 1}], got [{pl.min()}, {pl.max()}]")
    z = int(z_gear)
    if z <= 0:
        raise ValueError(f"z_gear must be a positive integer, got {z_gear!r}")
    seq = np.argsort(f, kind="stable")
    fs = f[seq]
    if t.size and np.any(seq[pos % n] != pl):
        raise ValueError("position and planet disagree: position % N must be the planet's place "
                         "in pass order")
    target = z * (np.floor_divide(pos, n) + fs[pos % n])
    dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    s, given = _sigma(sigma, t.size, 1e-3 * dt)
    return PassTrain(name, gear, t, s, target.astype(float), pl.astype(int), pos.astype(int), given,
                     z, int(order))


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


def tacho_train(times, cycles_per_rev: float, *, sigma=None, name: str = "tacho") -> PassTrain:
    """The carrier tacho's rising edges as an angle train (A = P_c k + c_T).

    Parameters
    ----------
    times : array_like, shape (m,)
        Edge times [s], strictly increasing.
    cycles_per_rev : float
        Mesh cycles per carrier revolution P_c [-] (Z_r with the ring held, Z_s with the sun
        held; :attr:`Kinematics.tacho_cycles`).
    sigma : float or array_like, optional
        Edge timing uncertainty [s]; None: the train's scatter sets it.
    """
    t = _check_times(times, "times")
    p = float(cycles_per_rev)
    if not (math.isfinite(p) and p > 0):
        raise ValueError(f"cycles_per_rev must be a positive number, got {cycles_per_rev!r}")
    k = revolution_numbers(t) if t.size else np.empty(0, int)
    dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    s, given = _sigma(sigma, t.size, 1e-4 * dt)
    return PassTrain(name, "tacho", t, s, p * k.astype(float), np.full(t.size, -1),
                     k.astype(int), given)


@dataclass(frozen=True)
class Kinematics:
    """What the tooth counts say about the shafts, in mesh cycles.

    Attributes
    ----------
    z_sun, z_ring, z_planet : int
        Tooth counts (z_planet 0 when unknown: no planet-spin terms).
    fixed : {"ring", "sun", None}
        The held member (None: a differential, both driven).
    periods : dict of str to float
        Mesh cycles per turn of each shaft whose speed ripple can be modelled [-]
        ("carrier", "sun", "ring": absolute turns; "planet": spin relative to the carrier).
    tacho_cycles : float or None
        Mesh cycles per carrier revolution when a member is held (the tacho then measures the
        mesh angle); None for a differential.
    """

    z_sun: int
    z_ring: int
    z_planet: int
    fixed: str | None
    periods: dict
    tacho_cycles: float | None

    @property
    def planet_period(self) -> float | None:
        """Mesh cycles per planet spin relative to the carrier, Z_p [-] (None if unknown)."""
        return float(self.z_planet) if self.z_planet > 0 else None


def kinematics(z_sun: int, z_ring: int, z_planet: int = 0, *, fixed: str | None = "ring",
               speeds=None) -> Kinematics:
    """Shaft periods in mesh cycles from the tooth counts and the held member.

    Parameters
    ----------
    z_sun, z_ring, z_planet : int
        Tooth counts [-] (z_planet 0: unknown).
    fixed : {"ring", "sun", None}
        Held member; None for a differential (then ``speeds`` give the shaft ratios).
    speeds : meshphase.models.gearset.Speeds, optional
        Nominal speeds [rad/s]; used only for a differential (ratios of shaft speeds to the
        mesh frequency). Without them a differential gets no shaft-ripple terms.

    Notes
    -----
    Ring held: a carrier turn is Z_r mesh cycles, a sun turn Z_s Z_r / (Z_s + Z_r); sun held:
    a carrier turn is Z_s, a ring turn Z_s Z_r / (Z_s + Z_r). A planet turns once relative to
    the carrier every Z_p mesh cycles in every arrangement.
    """
    zs, zr, zp = int(z_sun), int(z_ring), int(z_planet or 0)
    if zs <= 0 or zr <= 0 or zp < 0:
        raise ValueError(f"tooth counts must be positive, got z_sun={z_sun!r}, z_ring={z_ring!r}, "
                         f"z_planet={z_planet!r}")
    if fixed not in ("ring", "sun", None):
        raise ValueError(f"fixed must be 'ring', 'sun' or None, got {fixed!r}")
    periods: dict = {}
    tacho = None
    if fixed == "ring":
        periods = {"carrier": float(zr), "sun": zs * zr / (zs + zr)}
        tacho = float(zr)
    elif fixed == "sun":
        periods = {"carrier": float(zs), "ring": zs * zr / (zs + zr)}
        tacho = float(zs)
    elif speeds is not None:
        w_sc = abs(speeds.sun - speeds.carrier)
        if w_sc > 0:
            for name in ("carrier", "sun", "ring"):
                w = abs(getattr(speeds, name))
                if w > 1e-9 * w_sc:
                    periods[name] = zs * w_sc / w
    if zp > 0:
        periods["planet"] = float(zp)
    return Kinematics(zs, zr, zp, fixed, periods, tacho)


# ----------------------------------------------------------------------------- the model
@dataclass
class _Spec:
    knots: int = 1
    harm: dict = field(default_factory=dict)      # rate -> highest harmonic
    mod: dict = field(default_factory=dict)       # rate -> amplitude modulation on/off
    sig: int = 0                                  # planet-term harmonics
    # rank order between the planet terms and a ripple at the planet-spin period where the
    # data cannot tell them apart: "" the default (carrier, sun and ring ripple before the
    # planet terms, the planet-rate ripple after), "planet" the planet terms before every
    # ripple, "ripple" every ripple before the planet terms
    first: str = ""

    def copy(self) -> "_Spec":
        return _Spec(self.knots, dict(self.harm), dict(self.mod), self.sig, self.first)

    def describe(self) -> str:
        parts = [f"spline {self.knots} interval(s)"]
        for r, h in self.harm.items():
            if h:
                parts.append(f"{r} ripple x{h}" + (" (modulated)" if self.mod.get(r) else ""))
        if self.sig:
            parts.append(f"planet terms x{self.sig}")
        return ", ".join(parts)


def _basis(x: np.ndarray, K: int, nu: int = 0) -> np.ndarray:
    """Uniform cubic B-spline basis on [-1, 1] with K intervals (knots continued past both
    ends, so polynomials up to degree 3 are in the span), value or derivative ``nu``."""
    h = 2.0 / K
    kk = -1.0 + h * np.arange(-3, K + 4)
    nb = K + 3
    spl = BSpline(kk, np.eye(nb), 3, extrapolate=True)
    return spl(x, nu) if x.size else np.zeros((0, nb))


class _Design:
    """Observations of all trains, stacked, and the column layout of one model spec."""

    def __init__(self, trains: list[PassTrain], kin: Kinematics, n_planets: int):
        self.trains = trains
        self.kin = kin
        self.N = n_planets
        self.t = np.concatenate([tr.times for tr in trains])
        self.y = np.concatenate([tr.target for tr in trains])
        self.sig = np.concatenate([tr.sigma for tr in trains])
        self.q = np.concatenate([np.full(len(tr), i) for i, tr in enumerate(trains)])
        self.pl = np.concatenate([tr.planet for tr in trains])
        # mesh cycles per radian of a planet's carrier-frame angle shift, per row (0: tacho)
        self.ps = np.concatenate([np.full(len(tr), tr.order * tr.z / TWO_PI if tr.kind != "tacho" else 0.0)
                                  for tr in trains])
        self.t_lo, self.t_hi = float(self.t.min()), float(self.t.max())
        self.t_mid = 0.5 * (self.t_lo + self.t_hi)
        self.half = max(0.5 * (self.t_hi - self.t_lo), 1e-12)
        self.x = (self.t - self.t_mid) / self.half
        self.active = np.ones(self.t.size, bool)      # False: left out as an outlier
        # spline bases at every observation, per (intervals, derivative): the iterations of a
        # fit evaluate the same rows again and again (a few recent entries are kept)
        self._bases: dict = {}
        self._layouts: dict = {}
        # reference planet of each gauge train: planet 1 when present, else the lowest
        self.ref = []
        for tr in trains:
            if tr.kind == "tacho" or not len(tr):
                self.ref.append(-1)
            else:
                present = np.unique(tr.planet)
                self.ref.append(0 if 0 in present else int(present[0]))

    def x_of(self, t: np.ndarray) -> np.ndarray:
        return (np.asarray(t, dtype=float) - self.t_mid) / self.half

    #: spline bases kept by :meth:`basis_rows` (a window of 6000 observations and 64
    #: intervals: 3 MB each)
    _BASES_KEPT = 4

    def basis_rows(self, K: int, nu: int, rows: np.ndarray) -> np.ndarray:
        """The spline basis (``nu``: 0 value, 1 derivative per second) at observations
        ``rows``: evaluated once at every observation and kept, then gathered."""
        key = (int(K), int(nu))
        full = self._bases.pop(key, None)
        if full is None:
            full = _basis(self.x, K, nu)
            if nu:
                full /= self.half ** nu
        self._bases[key] = full                      # most recently used last
        while len(self._bases) > self._BASES_KEPT:
            del self._bases[next(iter(self._bases))]
        rows = np.asarray(rows)
        if rows.size == full.shape[0] and np.array_equal(rows, np.arange(rows.size)):
            return full                              # every row, in order: no gather
        return full[rows]

    def release(self) -> None:
        """Drop the kept spline bases and layouts (a fitted model keeps its design; a
        layout holds three index arrays of the observations' length)."""
        self._bases.clear()
        self._layouts.clear()

    def layout(self, spec: _Spec) -> dict:
        """Parameter blocks of ``spec``: name -> slice, column names, priorities, and the
        (train, planet) -> column tables of the offsets and planet terms (made once per spec
        and design; read-only)."""
        key = (spec.knots, tuple(sorted(spec.harm.items())), tuple(sorted(spec.mod.items())),
               spec.sig, spec.first)
        lay = self._layouts.get(key)
        if lay is None:
            lay = self._layouts[key] = self._layout(spec)
        return lay

    def _layout(self, spec: _Spec) -> dict:
        names, prio = [], []
        blocks = {}
        i = 0

        def add(key, cols, p):
            nonlocal i
            blocks[key] = slice(i, i + len(cols))
            names.extend(cols)
            prio.extend(p if isinstance(p, list) else [p] * len(cols))
            i += len(cols)

        add("spline", [f"spline[{j}]" for j in range(spec.knots + 3)], 0)
        for r in self.kin.periods:
            h = spec.harm.get(r, 0)
            if h:
                # a common ripple at the planet spin is what identical planet terms on every
                # planet would look like: where the data cannot tell them apart, the planet
                # terms (always present, from the planets' own shaft hole offsets) are kept
                # so is a harmonic of another shaft's ripple at a period of the planet spin
                # (the carrier's third on Z_r / Z_p = 3): the planet terms go first there too
                k = np.arange(1, h + 1) * (self.kin.planet_period or 0.0) / self.kin.periods[r]
                spin = (r == "planet") | ((k > 0) & (np.abs(k - np.round(k)) < 1e-9))
                pr = [6 if sp else 3 for sp in spin for _ in range(2)]
                if spec.first:
                    pr = [6 if spec.first == "planet" else 3] * (2 * h)
                add(f"rip:{r}", [f"{r} ripple {c}{m}" for m in range(1, h + 1) for c in ("cos", "sin")], pr)
                if spec.mod.get(r):
                    add(f"mod:{r}", [f"{r} ripple x*{c}{m}" for m in range(1, h + 1)
                                     for c in ("cos", "sin")], [x + 1 for x in pr])
        add("const", [f"{tr.name}: constant" for q, tr in enumerate(self.trains) if q > 0], 1)
        T = len(self.trains)
        off_table = np.full((T, self.N), -1, dtype=np.int64)
        offs = []
        for q, tr in enumerate(self.trains):
            if tr.kind == "tacho":
                continue
            for n in np.unique(tr.planet):
                if n != self.ref[q]:
                    off_table[q, n] = len(offs)
                    offs.append(f"{tr.name}: planet {n + 1} offset")
        add("off", offs, 2)
        # planet terms: one set per planet, shared by every gauge (a planet's own shaft hole
        # offset turns the line of centres of its sun and its ring mesh alike, to first order
        # in e / R_c: d psi_n(t) [rad]), each gauge seeing it scaled by order * Z / 2 pi
        sig_index = np.full(self.N, -1, dtype=np.int64)
        sigs = []
        if spec.sig and self.kin.planet_period:
            for n in np.unique(self.pl[self.pl >= 0]):
                sig_index[n] = len(sigs)
                sigs += [f"planet {n + 1} spin term {c}{m}"
                         for m in range(1, spec.sig + 1) for c in ("cos", "sin")]
        add("sig", sigs, 5)
        # the gauges time their passes at features that sit a (small, gauge-specific) angle
        # off the engagement; the planet terms turn with the planet, so each gauge after the
        # first carries that angle as a phase lag of the planet terms [mesh cycles]
        lag_index = np.full(T, -1, dtype=np.int64)
        lags = []
        if sigs:
            gauges = [q for q, tr in enumerate(self.trains) if tr.kind != "tacho"]
            for q in gauges[1:]:
                lag_index[q] = len(lags)
                lags.append(f"{self.trains[q].name}: planet-term lag")
        add("lag", lags, 5)
        pl = np.maximum(self.pl, 0)
        return {"blocks": blocks, "names": names, "priority": np.asarray(prio), "p": i,
                "off_table": off_table, "sig_index": sig_index, "lag_index": lag_index,
                "li": lag_index[self.q],
                "oi": np.where(self.pl >= 0, off_table[self.q, pl], -1),
                "si": np.where((self.pl >= 0) & (self.ps != 0), sig_index[pl], -1)}

    # ------------------------------------------------------------------ evaluation
    def _ripple(self, theta, lay, spec, A, x):
        """R(A, x), dR/dA, dR/dx at mesh angles A and scaled times x; and the columns
        dR/dtheta (one array per ripple block, in layout order)."""
        R = np.zeros(A.size)
        RA = np.zeros(A.size)
        Rx = np.zeros(A.size)
        cols = []
        for r, P in self.kin.periods.items():
            h = spec.harm.get(r, 0)
            if not h:
                continue
            m = np.arange(1, h + 1)
            ph = TWO_PI * np.mod(np.outer(A, m / P), 1.0)             # (n, h), reduced
            c, sn = np.cos(ph), np.sin(ph)
            trig = np.empty((A.size, 2 * h))
            trig[:, 0::2], trig[:, 1::2] = c, sn
            dtrig = np.empty_like(trig)                               # d trig / dA
            dtrig[:, 0::2] = -sn * (TWO_PI * m / P)
            dtrig[:, 1::2] = c * (TWO_PI * m / P)
            a = theta[lay["blocks"][f"rip:{r}"]]
            R += trig @ a
            RA += dtrig @ a
            cols.append(trig)
            if spec.mod.get(r):
                am = theta[lay["blocks"][f"mod:{r}"]]
                R += x * (trig @ am)
                RA += x * (dtrig @ am)
                Rx += trig @ am
                cols.append(trig * x[:, None])
        return R, RA, Rx, cols

    def _common(self, theta, lay, spec, x, A_fixed=None, rows=None):
        """Solve A = S(t) + R(A, x) (Newton from A = S) at scaled times x.

        Returns A, dA/dt, the columns dA/dtheta restricted to spline and ripple blocks (as a
        dense (n, p) array with zeros elsewhere) and dR/dA. With ``A_fixed`` the columns are
        evaluated at those angles instead of the solved ones. ``rows``: x are the scaled
        times of these observations (their spline bases are kept between calls)."""
        if rows is None:
            B = _basis(x, spec.knots)
            dB = _basis(x, spec.knots, 1) / self.half
        else:
            B = self.basis_rows(spec.knots, 0, rows)
            dB = self.basis_rows(spec.knots, 1, rows)
        beta = theta[lay["blocks"]["spline"]]
        S = B @ beta
        dS = dB @ beta
        A = S.copy() if A_fixed is None else np.asarray(A_fixed, dtype=float)
        if A_fixed is None and any(spec.harm.get(r, 0) for r in self.kin.periods):
            scale = max(1.0, float(np.max(np.abs(S))) if S.size else 1.0)
            for _ in range(30):
                R, RA, _, _ = self._ripple(theta, lay, spec, A, x)
                F = A - S - R
                A = A - F / (1.0 - RA)
                if not F.size or float(np.max(np.abs(F))) <= 4 * np.finfo(float).eps * scale:
                    break
        R, RA, Rx, cols = self._ripple(theta, lay, spec, A, x)
        den = 1.0 - RA if A_fixed is None else np.ones(A.size)
        G = np.zeros((x.size, lay["p"]))
        np.divide(B, den[:, None], out=G[:, lay["blocks"]["spline"]])
        c = 0
        for key, sl in lay["blocks"].items():
            if key.startswith("rip:") or key.startswith("mod:"):
                np.divide(cols[c], den[:, None], out=G[:, sl])
                c += 1
        rate = (dS + Rx / self.half) / den
        return A, rate, G, RA

    def evaluate(self, theta, lay, spec, rows=None, *, jac=True, nominal=False):
        """Model value f, Jacobian J (rows x p), and the observation's angle rate [cycles/s].

        ``nominal``: the first-order (structural) design instead: columns evaluated at the
        angles the observations put A at (target minus the train's constant, offset and
        planet term), without the slope factors (1 + h') / (1 - R'). Those angles are exactly
        periodic where the geometry makes them so (a planet meeting a ring gauge at the same
        spin angle every time), so structural dependence between columns is exact, not
        blurred by residuals or by second-order coupling of ripple and planet terms (which no
        real record resolves); used to judge identifiability.
        """
        idx = np.arange(self.t.size) if rows is None else rows
        x = self.x[idx]
        q = self.q[idx]
        n = idx.size
        cb = lay["blocks"]["const"]
        ob = lay["blocks"]["off"]
        th_c = theta[cb]
        th_o = theta[ob]
        has_c = q > 0
        oi = lay["oi"][idx]
        train_terms = np.zeros(n)
        if th_c.size:
            train_terms += np.where(has_c, th_c[np.maximum(q - 1, 0)], 0.0)
        if th_o.size:
            train_terms += np.where(oi >= 0, th_o[np.maximum(oi, 0)], 0.0)
        if nominal:
            # the angle the observation names: its target less its train's constant and
            # offset, exactly periodic wherever the geometry is (the planet terms, a few
            # 1e-3 cycles, and the residuals are left out on purpose)
            A, rate, G, _ = self._common(theta, lay, spec, x,
                                         A_fixed=self.y[idx] - train_terms, rows=idx)
        else:
            A, rate, G, _ = self._common(theta, lay, spec, x, rows=idx)
        f = A + train_terms
        # planet terms, periodic in the planet's spin: functions of the mesh angle A
        sb = lay["blocks"]["sig"]
        hA = np.zeros(n)
        sig_cols = None
        hA_lag = np.zeros(n)
        lb = lay["blocks"]["lag"]
        li = lay["li"][idx]
        lag = np.zeros(n)
        if lb.stop > lb.start:
            has = li >= 0
            lag[has] = theta[lb][li[has]]
        if sb.stop > sb.start:
            P = self.kin.planet_period
            m = np.arange(1, spec.sig + 1)
            ph = TWO_PI * np.mod(np.outer(A - lag, m / P), 1.0)
            trig = np.empty((n, 2 * spec.sig))
            trig[:, 0::2], trig[:, 1::2] = np.cos(ph), np.sin(ph)
            dtrig = np.empty_like(trig)
            dtrig[:, 0::2] = -np.sin(ph) * (TWO_PI * m / P)
            dtrig[:, 1::2] = np.cos(ph) * (TWO_PI * m / P)
            si = lay["si"][idx]
            ps = self.ps[idx]
            th_s = theta[sb]
            w = 2 * spec.sig
            ok = si >= 0
            if np.any(ok):
                gather = th_s[si[ok, None] + np.arange(w)[None, :]]
                f[ok] += ps[ok] * np.sum(gather * trig[ok], axis=1)
                hA[ok] = ps[ok] * np.sum(gather * dtrig[ok], axis=1)
            sig_cols = (si, trig * ps[:, None])
        hA_lag = hA.copy()
        if nominal:
            hA = np.zeros(n)
        obs_rate = rate * (1.0 + hA)
        if not jac:
            return f, None, obs_rate
        J = G                              # _common's own array: scaled in place
        J *= (1.0 + hA)[:, None]
        if cb.stop > cb.start:
            J[np.flatnonzero(has_c), cb.start + q[has_c] - 1] = 1.0
        if ob.stop > ob.start:
            k = np.flatnonzero(oi >= 0)
            J[k, ob.start + oi[k]] = 1.0
        if sig_cols is not None:
            si, trig = sig_cols
            k = np.flatnonzero(si >= 0)
            w = trig.shape[1]
            J[k[:, None], sb.start + si[k][:, None] + np.arange(w)[None, :]] = trig[k]
        if lb.stop > lb.start:
            k = np.flatnonzero((li >= 0) & (lay["si"][idx] >= 0))
            J[k, lb.start + li[k]] = -hA_lag[k]
        return f, J, obs_rate

    def a_part(self, theta, lay, spec, t):
        """A(t), dA/dt and dA/dtheta (the common angle only, no train terms) at times t."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        A, rate, G, _ = self._common(theta, lay, spec, self.x_of(t))
        return A, rate, G


def _rank_keep(d: "_Design", theta, lay, spec, rows) -> np.ndarray:
    """Identifiable columns: the Jacobian at the nominal angles, weighted by the timing bounds
    alone (a train's variance factor must not decide what is identifiable)."""
    _, J, rate = d.evaluate(theta, lay, spec, rows, nominal=True)
    w = 1.0 / (d.sig[rows] * _fix_rate(rate))
    return _independent_columns(J * w[:, None], lay["priority"])


def _fix_rate(rate: np.ndarray) -> np.ndarray:
    """Angle rates with non-finite or non-positive entries (a model not yet fitted) replaced
    by the median of the good ones (1 when there is none) [cycles/s]."""
    ok = np.isfinite(rate) & (rate > 0)
    if np.all(ok):
        return rate
    return np.where(ok, rate, float(np.median(rate[ok])) if np.any(ok) else 1.0)


#: mesh-angle rates within one fit stay within this factor of their median [-]: a model
#: beyond it has left the implicit angle equation's domain (a step to dR/dA near 1)
RATE_SPREAD = 100.0


def _plausible_rate(rate: np.ndarray) -> bool:
    """Whether every mesh-angle rate is finite, positive and within ``RATE_SPREAD`` of the
    median (a recording that speeds up 100-fold is split by operating point, not fitted)."""
    rate = np.asarray(rate, dtype=np.float64)
    if rate.size == 0:
        return True
    if not (np.all(np.isfinite(rate)) and np.all(rate > 0)):
        return False
    med = float(median_of_finite(rate))             # finite, checked above
    return bool(np.all(rate <= RATE_SPREAD * med) and np.all(rate >= med / RATE_SPREAD))


def _column_norms(A: np.ndarray) -> np.ndarray:
    """Euclidean norm of each column, without overflow when entries are huge (a near-exact
    observation, such as a synthetic tacho, carries weights where squares pass 1e308)."""
    A = np.asarray(A, dtype=np.float64)
    if A.size == 0:
        return np.zeros(A.shape[1] if A.ndim == 2 else 0)
    amax = np.maximum(np.max(A, axis=0), -np.min(A, axis=0))     # max |A|, no |A| copy
    safe = np.where(amax > 0, amax, 1.0)
    # np.linalg.norm(A / safe, axis=0) to the bit, squared in place (without its temporaries
    # and dispatch, which cost more than the sum itself on the fits' tall designs)
    T = A / safe
    np.multiply(T, T, out=T)
    return np.where(amax > 0, amax * np.sqrt(np.add.reduce(T, axis=0)), 0.0)


def _independent_columns(Jw: np.ndarray, priority: np.ndarray, tol: float = RANK_TOL) -> np.ndarray:
    """Columns kept, in priority order (then left to right): a column whose part outside the
    span of the columns kept before it is below ``tol`` of its norm is dropped.

    Householder QR without pivoting on the unit-norm columns in priority order gives, in
    |R_jj|, each column's distance to the span of the ones before it. The first column
    below ``tol`` is dropped and the QR repeated (a dependent column would otherwise steer
    the later reflections), until none is."""
    p = Jw.shape[1]
    order = np.lexsort((np.arange(p), priority))
    norms = _column_norms(Jw)
    cand = [j for j in order if norms[j] > 0]
    while cand:
        A = Jw[:, cand] / norms[cand]
        # geqrf's packed result: R is its upper triangle (mode "r" would copy it out whole)
        qr = linalg.qr(A, mode="raw", overwrite_a=True, check_finite=False)[0][0]
        d = np.abs(np.diag(qr))
        small = np.flatnonzero(d < tol)
        if small.size == 0:
            break
        # clear-cut dependence (far below tol) is dropped at once; a borderline column one
        # at a time, since a dependent column steers the later reflections
        clear = small[d[small] < 1e-3 * tol]
        drop = clear if clear.size else small[:1]
        for i in sorted(drop.tolist(), reverse=True):
            del cand[int(i)]
    keep = np.zeros(p, bool)
    keep[cand] = True
    return keep


@dataclass
class _Fit:
    spec: _Spec
    lay: dict
    theta: np.ndarray
    keep: np.ndarray
    chi2: float
    n: int
    rank: int
    iterations: int
    converged: bool
    resid: np.ndarray = None        # [mesh cycles], all rows (outliers too)
    rate: np.ndarray = None         # [cycles/s]
    cov: np.ndarray = None          # kept-parameter covariance (scaled)
    lev: np.ndarray = None          # leverages of the active rows

    floor: float = CHI2_FLOOR

    def bic(self) -> float:
        """n ln(max(chi2 / n, floor)) + rank ln n. With timing bounds given the floor is 1:
        residuals already inside the bounds are no evidence for another term."""
        n = max(self.n, 1)
        return n * math.log(max(self.chi2 / n, self.floor)) + self.rank * math.log(n)


def _conv_tol(d: _Design, rows: np.ndarray, rate: np.ndarray) -> float:
    """With timing bounds, a step that moves no prediction by 1e-3 of its own bound changes
    nothing that matters: that move is the convergence tolerance [mesh cycles] (0 without);
    ``rate``: the angle rates at ``rows`` at the start [cycles/s]."""
    if not all(tr.sigma_given for tr in d.trains):
        return 0.0
    r0 = _fix_rate(rate)
    if np.all(np.isfinite(r0)) and np.any(r0 != 1.0):
        return 1e-3 * float(np.min(d.sig[rows] * r0))
    return 0.0


#: a Gauss-Newton step is solved by unpivoted QR while every |R_jj| of the unit-norm columns
#: is above this [-]; below it (a column the converged point made dependent) by gelsy,
#: rank-revealing
STEP_QR_TOL = 1e-10


def _gn_step(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Least-squares solution of A x ~ b for the unit-norm columns of a Gauss-Newton design.

    Householder QR of [A | b] (LAPACK geqrf through :func:`scipy.linalg.qr`): its last
    column holds Q^T b, so x solves R x = (Q^T b)[:p]. geqrf releases the GIL (gelsy does
    not), so fits on several threads overlap. The columns were screened for independence
    (:func:`_independent_columns`); where one has become dependent at this point (an |R_jj|
    below ``STEP_QR_TOL``) the step falls back to gelsy's rank-revealing solution."""
    n, p = A.shape
    if p == 0:
        return np.zeros(0)
    if n > p:
        Ab = np.empty((n, p + 1), order="F")
        Ab[:, :p] = A
        Ab[:, p] = b
        qr, _ = linalg.qr(Ab, mode="raw", overwrite_a=True, check_finite=False)[0]
        d = np.abs(np.diag(qr[:p, :p]))
        if np.all(np.isfinite(qr[:p, :p + 1])) and np.min(d) > STEP_QR_TOL * np.max(d):
            return linalg.solve_triangular(qr[:p, :p], qr[:p, p], check_finite=False)
    return linalg.lstsq(A, b, lapack_driver="gelsy", check_finite=False)[0]


def _solve(d: _Design, spec: _Spec, theta0: np.ndarray | None, scale: np.ndarray, *,
           max_iter: int = 12, tol: float = 1e-10, full: bool = False,
           recheck: bool = True, keep: np.ndarray | None = None) -> _Fit:
    """Weighted Gauss-Newton for one spec; ``scale`` is the per-train variance factor.
    ``keep``: the identifiable columns at ``theta0`` when already known (what the first
    check would find; every parameter it drops must be zero in ``theta0``)."""
    lay = d.layout(spec)
    p = lay["p"]
    theta = np.zeros(p) if theta0 is None else theta0.copy()
    rows = np.flatnonzero(d.active)
    conv = False
    it = 0
    budget = max_iter
    rechecked = not recheck
    last = {}     # the latest evaluation: _finish reuses it when every row is active

    def weighted(theta_):
        f_, J_, rate_ = d.evaluate(theta_, lay, spec, rows)
        last.update(theta=theta_, f=f_, J=J_, rate=rate_)
        w_ = 1.0 / (d.sig[rows] * _fix_rate(rate_) * scale[d.q[rows]])
        r_ = d.y[rows] - f_
        # a trial step can throw the implicit angle equation near its singular point (rates
        # past 1e190): such a point is no candidate, never a floating-point overflow
        with np.errstate(over="ignore", invalid="ignore"):
            chi_ = float(np.sum((r_ * w_) ** 2))
        if not (math.isfinite(chi_) and _plausible_rate(rate_)):
            chi_ = math.inf
        return f_, J_, w_, r_, chi_

    f, J, w, r, chi = weighted(theta)
    conv_tol = _conv_tol(d, rows, last["rate"])
    while it < budget:
        it += 1
        if keep is None:
            keep = _rank_keep(d, theta, lay, spec, rows)
            if not np.all(keep):
                # unidentifiable parameters sit at zero (minimum norm), not at stale values
                theta[~keep] = 0.0
                f, J, w, r, chi = weighted(theta)
        A = J[:, keep] * w[:, None]
        cn = _column_norms(A)
        cn[~(cn > 0)] = 1.0
        step = _gn_step(A / cn, r * w) / cn
        # the largest move of a prediction the full step makes, to first order [mesh cycles]
        pred = float(np.max(np.abs(J[:, keep] @ step))) if step.size else 0.0
        tol_it = max(tol, conv_tol, 64 * np.finfo(float).eps * float(np.max(np.abs(d.y))))
        # Gauss-Newton with step halving: never accept a step that raises the misfit
        lam = 1.0
        at_theta = dict(last)
        for _ in range(12):
            trial = theta.copy()
            trial[keep] += lam * step
            ft, Jt, wt, rt, chit = weighted(trial)
            if chit <= chi * (1.0 + 1e-12) or not np.isfinite(chi):
                break
            if pred <= tol_it:
                # a step that moves no prediction by the tolerance is rounding: where it
                # raises the misfit, halving it only repeats the evaluation (up to 12 times
                # per converged solve); the iteration stands where it is, converged
                lam = 0.0
                trial, ft, Jt, wt, rt, chit = theta, f, J, w, r, chi
                last.clear()
                last.update(at_theta)
                break
            lam *= 0.5
        change = lam * pred
        theta, f, J, w, r, chi = trial, ft, Jt, wt, rt, chit
        if change <= tol_it:
            if rechecked:
                conv = True
                break
            # identifiability is judged where the columns are evaluated: check it again at
            # the converged point (a start far off can make dependent columns look apart)
            rechecked = True
            k2 = _rank_keep(d, theta, lay, spec, rows)
            if np.array_equal(k2, keep):
                conv = True
                break
            keep = k2
            theta[~keep] = 0.0
            f, J, w, r, chi = weighted(theta)
            budget = it + max_iter   # a fresh allowance from the new start
    if full and not rechecked:
        # the iteration limit came first: the identifiability check at the end still decides
        k2 = _rank_keep(d, theta, lay, spec, rows)
        if not np.array_equal(k2, keep):
            keep = k2
            theta[~keep] = 0.0
            return _solve(d, spec, theta, scale, max_iter=max_iter, tol=tol, full=full,
                          recheck=False) if max_iter > 1 else _solve(d, spec, theta, scale,
                                                                       max_iter=2, full=full)
    same = rows.size == d.t.size and last.get("theta") is theta
    return _finish(d, spec, lay, theta, keep, scale, rows, it, conv, full,
                   (last["f"], last["J"], last["rate"]) if same else None)


def _finish(d: _Design, spec: _Spec, lay: dict, theta: np.ndarray, keep: np.ndarray,
            scale: np.ndarray, rows: np.ndarray, it: int, conv: bool, full: bool,
            at_theta=None) -> _Fit:
    """The :class:`_Fit` of converged parameters: residuals and rates at every observation,
    the weighted misfit and, with ``full``, the covariance and the leverages. ``at_theta``:
    (f, J, rate) already evaluated at ``theta`` on every observation, or None."""
    if at_theta is None:
        f, J, rate = d.evaluate(theta, lay, spec, np.arange(d.t.size), jac=full)
    else:
        f, J, rate = at_theta
    resid = d.y - f
    rate = _fix_rate(rate)
    w_all = 1.0 / (d.sig * rate * scale[d.q])
    chi2 = float(np.sum((resid[rows] * w_all[rows]) ** 2))
    fit = _Fit(spec, lay, theta, keep, chi2, rows.size, int(keep.sum()), it, conv, resid, rate)
    fit.floor = 1.0 if all(tr.sigma_given for tr in d.trains) else CHI2_FLOOR
    if full:
        A = (J[rows] * w_all[rows, None])[:, keep]
        cn = _column_norms(A)
        cn[~(cn > 0)] = 1.0
        # covariance from the SVD of the (column-scaled) weighted design: R's diagonal from
        # an unpivoted QR can sit above any tolerance while R^-1 still overflows (110 passes
        # at 51.2 kHz: entries past 1e154); the singular values say it. A direction that
        # became dependent at the converged point has unbounded variance, which the
        # truncated pseudo-inverse reports as the smallest-norm split
        U, sv, Vt = linalg.svd(A / cn, full_matrices=False, check_finite=False)
        use = sv > RANK_TOL * (sv[0] if sv.size else 0.0)
        Vs = Vt[use].T / sv[use]
        C = (Vs @ Vs.T) / np.outer(cn, cn)
        fit.cov = C
        lev = np.zeros(d.t.size)
        lev[rows] = np.sum(U[:, use] ** 2, axis=1)
        fit.lev = lev
    return fit


# ----------------------------------------------------------------------------- results
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
class Competitor:
    """A model of the same passes that explains them about as well as the chosen one.

    Attributes
    ----------
    words : str
        What it explains the passes by, in a rig engineer's words.
    versus : str
        What the chosen model explains them by instead.
    terms : str
        Its model order, as :attr:`AngleModel.terms` gives the chosen one's.
    delta_bic : float
        Its BIC less the chosen model's [-] (weights from the timing bounds alone, as in the
        selection; negative: the data prefer it).
    weight : float
        Its posterior weight [-] (exp(-BIC / 2), normalised over the chosen model and its
        competitors); NaN when ``inseparable``.
    inseparable : bool
        The trains fitted cannot tell it from the chosen model at all: its extra column lies
        in the span of the chosen model's columns (the fit is the same, the angle is not).
    ripple_bound : float
        For a speed ripple at the planet spin rate: how far every 1 % of it can move a
        phasing value [mesh cycles] (P / (100 pi), P mesh cycles per planet turn); else NaN.
    """

    words: str
    versus: str
    terms: str
    delta_bic: float
    weight: float
    inseparable: bool
    ripple_bound: float = float("nan")
    _fit: "_Fit" = field(default=None, repr=False)
    # an inseparable competitor's move turned a quarter period in phase (:func:`_quarter_turn`)
    _turned: "_Fit" = field(default=None, repr=False)


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
    _design: _Design = field(default=None, repr=False)
    _fit: _Fit = field(default=None, repr=False)
    competitors: list = field(default_factory=list)
    _choice_ref: _Fit = field(default=None, repr=False)

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
            dl = turned(c._fit) - base
            if c._turned is not None:
                # every phase of the common term: the move and its quarter turn together
                dl = np.hypot(dl, turned(c._turned) - base)
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


def _dropped_notes(d: _Design, lay: dict, keep: np.ndarray) -> tuple[list, list]:
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


def _min_step(tr: PassTrain) -> float:
    """Smallest mesh-angle step between consecutive planets of a gauge train [mesh cycles]
    (Z times the smallest planet spacing in revolutions)."""
    steps = np.diff(tr.target)[np.diff(tr.position) == 1]
    return float(np.min(steps)) if steps.size else float("inf")


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
        Gauge trains (:func:`gauge_train`) and at most one tacho (:func:`tacho_train`);
        trains with fewer than 2 observations are ignored.
    kin : Kinematics
        Shaft periods and the held member (:func:`kinematics`).
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
        the planet spin (an encoder, :func:`encoder_train`) the ripple is seen apart from
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
    d = _Design(use, kin, int(n_planets))
    ladder = _knot_ladder(d, kin, gauges, max_knots)
    rates = _ripple_rates(d, kin, planet_ripple, notes)
    spec = _Spec(knots=ladder[0], harm={r: 0 for r in rates}, mod={r: False for r in rates})
    # 1. base fit and gross outliers (mislabelled pulses are whole planet spacings off)
    fit = _drop_gross_outliers(d, use, spec, outlier_k)
    # 2. forward selection on BIC (weights from the timing bounds alone)
    rejected: list = []
    spec, fit, selection = _select_terms(d, spec, fit, ladder, rates, kin, max_harmonics,
                                         max_planet_harmonics, rejected=rejected)
    # 3. variance factors per train, outliers against the final model, final fit
    scale, fit = _variance_factors(d, use, spec, fit, outlier_k)
    # 4. the models that explain the passes about as well (their spread joins the phasing's
    # uncertainty)
    choice_ref, competitors = _competitors(d, spec, fit, rejected, kin)
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
        raise TypeError(f"kin must be a Kinematics (meshphase.kinematics.angles.kinematics), got {type(kin).__name__}")
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


def _knot_ladder(d: _Design, kin: Kinematics, gauges: list, max_knots) -> list:
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
    ripple is not fitted by default: :func:`fit_angle_model`); a shaft that turns less
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


def _ripple_rates(d: _Design, kin: Kinematics, planet_ripple: bool, notes: list) -> list:
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


def _drop_gross_outliers(d: _Design, use: list, spec: _Spec, outlier_k: float) -> _Fit:
    """The base fit, refitted without gross outliers (at most 3 rounds; ``d.active`` is
    updated): mislabelled pulses are whole planet spacings off."""
    ones = np.ones(len(use))
    fit = _solve(d, spec, None, ones)
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
        fit = _solve(d, spec, None, ones)
    return fit


def _select_terms(d: _Design, spec: _Spec, fit: _Fit, ladder: list, rates: list,
                  kin: Kinematics, max_harmonics: int, max_planet_harmonics: int, *,
                  screen: bool = True, rejected: list | None = None):
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
    one that did not gain ``BIC_GAIN``), when one was solved."""
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
        spline_bound = _spline_bounds(d, fit, finer) if screen and finer else {}
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
            start[i] = _extend(fit, c, d)
            bound[i], keep0[i] = (_linear_bound(d, fit, c, start[i]) if screen
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
                start[i] = _extend(fit, c, d)
                if screen:
                    b, keep0[i] = _linear_bound(d, fit, c, start[i])
                    if b > bar + BIC_GAIN:
                        continue
            th0 = start[i]
            f2 = _solve(d, c, th0, ones, max_iter=4, recheck=False, keep=keep0.get(i))
            # lowest BIC; a tie goes to the earlier candidate, as in the order of ``cands``
            if best is None or f2.bic() < best.bic() or (f2.bic() == best.bic() and i < best_i):
                best, best_i = f2, i
        if best is None or best.bic() > fit.bic() - BIC_GAIN:
            if rejected is not None and best is not None:
                rejected.append(best.spec)
            break
        full = _solve(d, best.spec, best.theta, ones)
        fit = full if full.bic() <= best.bic() + 1e-9 * abs(best.bic()) else best
        spec = best.spec
        selection.append((step, spec.describe(), fit.bic()))
    return spec, fit, selection


#: A candidate (a finer spline, a ripple, modulation or planet harmonic) is assumed able to
#: lower the misfit by this factor more than its linearised gain (the ripple arguments move
#: with the spline: the gain of the Gauss-Newton iterations is not quite the first step's;
#: tests/processing/test_angles.py checks the bound on every candidate of three records) [-]
SCREEN_SLACK = 1.5


def _spline_bounds(d: _Design, fit: _Fit, knots) -> dict:
    """Optimistic BIC of each finer spline in ``knots`` [-], from one evaluation at ``fit``.

    The spline with K' intervals can lower the misfit by no more than the union of the
    fitted model's columns and the K' spline's columns could in a linearised step: the
    weighted residual's part outside the span of both. Its rank is at least the union's
    less the spline columns it drops. The bound takes ``SCREEN_SLACK`` times that gain and
    that rank: n ln(max(chi2 / n, floor)) + rank ln n. A spline whose bound is not finite
    gets -inf (it is always solved)."""
    rows = np.flatnonzero(d.active)
    n = rows.size
    out = {int(k): -math.inf for k in knots}
    if n == 0 or not knots:
        return out
    f, J, rate = d.evaluate(fit.theta, fit.lay, fit.spec, rows)
    w = 1.0 / (d.sig[rows] * _fix_rate(rate))
    with np.errstate(over="ignore", invalid="ignore"):
        r = (d.y[rows] - f) * w
        chi = float(r @ r)
    if not math.isfinite(chi):
        return out
    sb = fit.lay["blocks"]["spline"]
    # the spline columns are B(x) (1 + h') / (1 - R'): B-splines sum to 1, so the row sums
    # of the fitted spline's columns are the factor every spline's columns share
    fac = J[:, sb].sum(axis=1) * w
    Ac = (J * w[:, None])[:, fit.keep]
    cn = _column_norms(Ac)
    cn[~(cn > 0)] = 1.0
    Q = linalg.qr(Ac / cn, mode="economic", check_finite=False)[0]
    r_out = r - Q @ (Q.T @ r)
    chi_out = float(r_out @ r_out)
    kept_spline = int(np.count_nonzero(fit.keep[sb]))
    for k in out:
        N = _basis(d.x[rows], k) * fac[:, None]
        nn = _column_norms(N)
        N = N[:, nn > 0] / nn[nn > 0]
        for _ in range(2):                         # projected twice: orthogonal to rounding
            N -= Q @ (Q.T @ N)
        Q2, R2, _ = linalg.qr(N, mode="economic", pivoting=True, check_finite=False)
        k2 = int(np.count_nonzero(np.abs(np.diag(R2)) > RANK_TOL))
        g = Q2[:, :k2].T @ r_out
        chi_u = max(chi_out - float(g @ g), 0.0)
        chi_opt = max(chi - SCREEN_SLACK * (chi - chi_u), 0.0)
        rank = fit.rank + k2 - kept_spline
        out[k] = n * math.log(max(chi_opt / n, fit.floor)) + rank * math.log(n)
    return out


def _linear_bound(d: _Design, fit: _Fit, spec: _Spec, theta0: np.ndarray):
    """Optimistic BIC of the candidate ``spec`` that extends ``fit`` by terms starting at zero
    (``theta0``, from :func:`_extend`) [-], and the identifiable columns there: (bound, keep).

    The candidate's first Gauss-Newton step from ``theta0`` is the least-squares fit of the
    weighted residual by its weighted columns (the fit's and the new ones, evaluated at
    theta0, where the new terms are zero and the model is the fit's). The misfit after that
    step, chi_lin, is one QR away: R_pp^2 of the QR of [A | r]. The bound takes
    ``SCREEN_SLACK`` times that gain (the iterations after the first step add little to
    it: the model is nearly linear in the new terms near zero) and the candidate's own rank
    (the columns :func:`_solve` keeps at theta0, returned so the solve need not find them
    again; None where it drops a parameter that is not zero there):
    n ln(max(chi_opt / n, floor)) + rank ln n, as :meth:`_Fit.bic`. A candidate whose check
    drops a parameter that is not zero at theta0 (its solve starts elsewhere), whose misfit
    is not finite, or with no more rows than columns gets -inf: it is always solved."""
    rows = np.flatnonzero(d.active)
    n = rows.size
    lay = d.layout(spec)
    keep = _rank_keep(d, theta0, lay, spec, rows)
    p = int(np.count_nonzero(keep))
    if np.any(theta0[~keep] != 0.0):
        return -math.inf, None            # the solve zeroes them and starts from there
    if n <= p:
        return -math.inf, keep
    f, J, rate = d.evaluate(theta0, lay, spec, rows)
    w = 1.0 / (d.sig[rows] * _fix_rate(rate))
    with np.errstate(over="ignore", invalid="ignore"):
        r = (d.y[rows] - f) * w
        chi = float(r @ r)
    if not (math.isfinite(chi) and _plausible_rate(rate)):
        return -math.inf, keep
    Ab = np.empty((n, p + 1), order="F")
    Ab[:, :p] = J[:, keep] * w[:, None]
    cn = _column_norms(Ab[:, :p])
    cn[~(cn > 0)] = 1.0
    Ab[:, :p] /= cn
    Ab[:, p] = r
    qr = linalg.qr(Ab, mode="raw", overwrite_a=True, check_finite=False)[0][0]
    chi_lin = float(qr[p, p]) ** 2
    if not math.isfinite(chi_lin):
        return -math.inf, keep
    chi_opt = max(chi - SCREEN_SLACK * max(chi - chi_lin, 0.0), 0.0)
    return n * math.log(max(chi_opt / n, fit.floor)) + p * math.log(n), keep


def _variance_factors(d: _Design, use: list, spec: _Spec, fit: _Fit, outlier_k: float):
    """Variance factors per train and outliers against the final model, then the final fit:
    (scale, fit). Each round judges every observation afresh: one left out early by a poorer
    model may come back."""
    n_obs = d.t.size
    ones = np.ones(len(use))
    base_active = d.active.copy()
    scale = ones.copy()
    for _ in range(4):
        fit = _solve(d, spec, fit.theta, scale, full=True)
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
    return scale, _solve(d, spec, fit.theta, scale, full=True)


#: a competing model within this BIC of the chosen one (posterior weight at least exp(-3),
#: 5 % of the chosen model's: below "positive evidence" against it, Kass & Raftery 1995,
#: counted twice over) joins the phasing's uncertainty [-]
BIC_CLOSE = 6.0

#: a common term at the planet spin period that the trains cannot place (ripple or planet
#: terms) stays with the planet terms while it moves the phasing by no more than a common
#: speed ripple of this relative amplitude at the planet spin rate could [-]: ordinary shaft
#: hole offsets reach about that (the seed rig's 0.2 mm of Table 2 case 1 on every planet:
#: 0.005-0.010 mesh cycles, 0.1 % of ripple's worth; a 1 % planet-rate ripple: 0.05-0.08)
INSEPARABLE_RIPPLE = 0.002

_SHAFT_WORDS = {"carrier": "carrier", "sun": "sun", "ring": "ring", "planet": "planet spin"}


def _order_words(spec: _Spec, base: _Spec) -> str:
    """What ``spec`` explains the passes by where it differs from ``base``, in words."""
    parts = []
    if spec.knots != base.knots:
        parts.append(f"a speed drift of {spec.knots} spline interval(s) (not {base.knots})")
    for r in [r for r in _SHAFT_WORDS if r in spec.harm or r in base.harm]:
        h, h0 = spec.harm.get(r, 0), base.harm.get(r, 0)
        w = _SHAFT_WORDS[r]
        if h > h0:
            parts.append(f"a speed ripple at the {w} rate to harmonic {h}"
                         + (f" (not {h0})" if h0 else ""))
        elif h < h0:
            parts.append(f"the speed ripple at the {w} rate to harmonic {h} only (not {h0})"
                         if h else f"no speed ripple at the {w} rate")
        elif h and spec.mod.get(r, False) != base.mod.get(r, False):
            parts.append(f"a {w}-rate ripple whose size changes over the record"
                         if spec.mod.get(r) else f"a {w}-rate ripple of constant size")
    if spec.sig > base.sig:
        parts.append(f"planet shaft-hole errors to harmonic {spec.sig}")
    elif spec.sig < base.sig:
        parts.append(f"planet shaft-hole errors to harmonic {spec.sig} only" if spec.sig
                     else "no planet shaft-hole errors")
    return " and ".join(parts) or spec.describe()


def _quarter_turn(th0: np.ndarray, fit: _Fit) -> np.ndarray:
    """``fit``'s parameters with its move away from ``th0`` (same layout) turned a quarter
    period in phase in every ripple and planet-term harmonic (each (cos, sin) pair (a, b)
    becomes (-b, a)), the other parameters at ``th0``.

    Moving a common term from the planet terms into a ripple at the same period is a move
    along the columns' common direction, for either phase of that term: the quarter-turned
    move is as invisible to the data as the move itself, and the two together span every
    phase of a common term of that size."""
    out = th0.copy()
    dl = fit.theta - th0
    for key, sl in fit.lay["blocks"].items():
        if key.startswith(("rip:", "mod:")) or key == "sig":
            pairs = dl[sl].reshape(-1, 2)
            out[sl] = th0[sl] + np.column_stack([-pairs[:, 1], pairs[:, 0]]).ravel()
    return out


def _competitors(d: _Design, spec: _Spec, fit: _Fit, rejected: list,
                 kin: Kinematics) -> tuple[_Fit, list]:
    """The chosen model refitted with the selection's weights (timing bounds alone), and the
    models that explain the passes about as well: (reference fit, list of Competitor).

    Tried: one step less of each term the selection took (a ripple harmonic, its amplitude
    modulation, a planet-term harmonic), the best term it turned down, and a common speed
    ripple at the planet spin rate next to the planet terms. The last is judged by rank
    first: where its columns lie in the span of the planet terms over the trains actually
    fitted (the two rank orders of :attr:`_Spec.first` keep different columns), the data
    cannot tell a common planet-rate ripple from equal terms on every planet, and both
    explanations are kept as inseparable competitors; a train that sees the ripple apart
    from the planets (a shaft encoder) makes the columns independent and the test clears.
    Every other competitor counts when its BIC is within ``BIC_CLOSE`` of the chosen one's
    (or below it), with its posterior weight.
    """
    ones = np.ones(len(d.trains))
    rows = np.flatnonzero(d.active)
    ref = _solve(d, spec, fit.theta, ones, keep=fit.keep, recheck=False)
    versus = f"the chosen model ({spec.describe()})"
    cands: list = []
    for r, h in spec.harm.items():
        if h:
            s2 = spec.copy()
            s2.harm[r] = h - 1
            s2.mod[r] = s2.mod.get(r, False) and h > 1
            cands.append(s2)
            if spec.mod.get(r) and h > 1:
                s3 = spec.copy()
                s3.mod[r] = False
                cands.append(s3)
    if spec.sig:
        s2 = spec.copy()
        s2.sig -= 1
        cands.append(s2)
    cands.extend(rejected)
    found: list = []
    bound = float("nan")
    if kin.planet_period and "planet" in _ripple_rates(d, kin, True, []):
        bound = 0.01 * float(kin.planet_period) / math.pi
        s_r = spec.copy()
        s_r.harm["planet"] = max(spec.harm.get("planet", 0), spec.sig, 1)
        s_r.mod.setdefault("planet", False)
        s_r.first = "ripple"
        s_p = s_r.copy()
        s_p.first = "planet"
        th = _extend(ref, s_r, d)
        k_r = _rank_keep(d, th, d.layout(s_r), s_r, rows)
        k_p = _rank_keep(d, th, d.layout(s_p), s_p, rows)
        if not np.array_equal(k_r, k_p):
            # both ends of the split; the one that moves the angle from the chosen model is
            # the competitor (the other is the chosen model itself, the same columns kept)
            pair = []
            for s2, k2, words, vs in ((s_r, k_r, "a common speed ripple at the planet spin rate",
                                       "equal shaft-hole errors on every planet"),
                                      (s_p, k_p, "equal shaft-hole errors on every planet",
                                       "a common speed ripple at the planet spin rate")):
                f2 = _solve(d, s2, np.where(k2, th, 0.0), ones, keep=k2, recheck=False)
                moved = (d.a_part(f2.theta, f2.lay, s2, d.t)[0]
                         - d.a_part(ref.theta, ref.lay, spec, d.t)[0])
                pair.append((float(np.ptp(moved)),
                             Competitor(words, vs, s2.describe(), f2.bic() - ref.bic(),
                                        float("nan"), True, bound, f2,
                                        replace(f2, theta=_quarter_turn(th, f2)))))
            found.append(max(pair, key=lambda x: x[0])[1])
        elif s_r.harm["planet"] != spec.harm.get("planet", 0):
            cands.append(s_r)
    seen = set()
    weighed = []
    for c in cands:
        key = (c.knots, tuple(sorted(c.harm.items())), tuple(sorted(c.mod.items())), c.sig)
        if key in seen:
            continue
        seen.add(key)
        # a ripple column that only duplicates the planet terms (a carrier harmonic at the
        # planet spin period) is the inseparable pair's business, not a second opinion here
        c = c.copy()
        c.first = "planet"
        f2 = _solve(d, c, _extend(ref, c, d), ones)
        db = f2.bic() - ref.bic()
        if db <= BIC_CLOSE:
            planet = c.harm.get("planet", 0) > spec.harm.get("planet", 0)
            weighed.append(Competitor(_order_words(c, spec), versus, c.describe(), db,
                                      float("nan"), False, bound if planet else float("nan"), f2))
    if weighed:
        dbs = np.array([0.0] + [c.delta_bic for c in weighed])
        w = np.exp(-0.5 * (dbs - dbs.min()))
        w /= w.sum()
        for c, wi in zip(weighed, w[1:]):
            c.weight = float(wi)
    return ref, found + weighed


def _train_fits(d: _Design, use: list, fit: _Fit, scale: np.ndarray, notes: list) -> list:
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


def _offsets(use: list, fit: _Fit) -> dict:
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


def _extend(fit: _Fit, spec: _Spec, d: _Design) -> np.ndarray:
    """Parameters of ``fit`` mapped onto the layout of ``spec`` (new terms start at 0; a
    finer spline starts from the old one's least-squares projection)."""
    new = d.layout(spec)
    th = np.zeros(new["p"])
    old = fit.lay
    for key, sl in old["blocks"].items():
        if key == "spline":
            continue
        if key in new["blocks"]:
            ns = new["blocks"][key]
            k = min(sl.stop - sl.start, ns.stop - ns.start)
            if key.startswith("rip:") or key.startswith("mod:"):
                # harmonic pairs keep their place
                th[ns.start:ns.start + k] = fit.theta[sl.start:sl.start + k]
            elif key == "sig":
                # per (train, planet) groups of 2 * sig columns
                w_old = 2 * fit.spec.sig
                w_new = 2 * spec.sig
                if w_old and w_new:
                    g = (sl.stop - sl.start) // w_old
                    w = min(w_old, w_new)            # fewer harmonics: the lower ones kept
                    for i in range(g):
                        th[ns.start + i * w_new: ns.start + i * w_new + w] = \
                            fit.theta[sl.start + i * w_old: sl.start + i * w_old + w]
            else:
                th[ns.start:ns.start + k] = fit.theta[sl.start:sl.start + k]
    sb = new["blocks"]["spline"]
    if spec.knots == fit.spec.knots:
        th[sb] = fit.theta[old["blocks"]["spline"]]
    else:
        xs = np.linspace(-1.0, 1.0, 8 * (spec.knots + 3))
        s_old = _basis(xs, fit.spec.knots) @ fit.theta[old["blocks"]["spline"]]
        th[sb] = linalg.lstsq(_basis(xs, spec.knots), s_old, check_finite=False)[0]
    return th


def typed_resolution(value: float) -> float:
    """Half a unit in the last digit of a number as a person typed it [same unit].

    ``4.06`` -> 0.005, ``18.19`` -> 0.005, ``100.0`` -> 0.05, ``4`` -> 0.5, ``1e-3`` -> 5e-4: the
    uncertainty a typed nominal value carries (Python keeps the shortest repr that round
    trips, which is the typed text for typed numbers)."""
    if isinstance(value, bool):
        raise TypeError(f"value must be a number, got {value!r}")
    if isinstance(value, (int, np.integer)):
        return 0.5
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"value must be finite, got {value!r}")
    text = repr(abs(v)).lower()
    mant, _, exp = text.partition("e")
    decimals = len(mant.split(".")[1]) if "." in mant else 0
    if "." in mant and mant.split(".")[1] == "0":
        decimals = 1 if not exp else 0
    e = int(exp) if exp else 0
    return 0.5 * 10.0 ** (e - decimals)


def held_member(z_sun: int, z_ring: int, speeds=None, *, resolution=None,
                mesh_rate: float | None = None, carrier_rate: float | None = None,
                rel_tol: float = 1e-3) -> tuple[str | None, str]:
    """Which member is held (its speed is zero within what is known about it).

    Parameters
    ----------
    z_sun, z_ring : int
        Tooth counts [-].
    speeds : Speeds, optional
        Nominal speeds [rad/s] (ring from Willis when the user typed sun and carrier).
    resolution : dict, optional
        Uncertainty of the typed sun and carrier speeds {"sun": [rad/s], "carrier": [rad/s]}
        (:func:`typed_resolution` of what was typed, converted); the ring's uncertainty
        follows by Willis. None: the speeds are exact (then |w| <= 1e-9 of the largest speed
        counts as zero).
    mesh_rate, carrier_rate : float, optional
        Measured mesh frequency [cycles/s] and carrier revolutions per second [1/s] (from the
        pass trains and a carrier tacho): a held ring gives mesh/carrier = Z_r, a held sun
        Z_s, within ``rel_tol``. When given they decide, and a contradiction with the speeds
        is reported in the reason.

    Returns
    -------
    fixed : {"ring", "sun", None}
    reason : str
        How it was decided, for the summary.

    Notes
    -----
    No speed is ever compared with an exact zero: a user types the carrier of a held-ring
    rig as 4.06 r/min, which with sun 18.19 r/min gives a Willis ring speed of -3.4e-4 r/min,
    far inside the +-7.9e-3 r/min the two typed values leave open.
    """
    from_speeds = None
    why = ""
    if speeds is not None:
        zs, zr = float(z_sun), float(z_ring)
        if resolution is None:
            scale = max(abs(speeds.sun), abs(speeds.carrier), abs(speeds.ring), 1e-300)
            d_ring = d_sun = d_carrier = 1e-9 * scale
        else:
            ds = float(resolution.get("sun", 0.0))
            dc = float(resolution.get("carrier", 0.0))
            d_ring = (1.0 + zs / zr) * dc + (zs / zr) * ds
            d_sun = ds
            d_carrier = dc
        if abs(speeds.ring) <= d_ring:
            from_speeds = "ring"
            why = f"ring speed {speeds.ring:.3g} rad/s is zero within +-{d_ring:.2g} rad/s"
        elif abs(speeds.sun) <= d_sun:
            from_speeds = "sun"
            why = f"sun speed {speeds.sun:.3g} rad/s is zero within +-{d_sun:.2g} rad/s"
        elif abs(speeds.carrier) <= d_carrier:
            why = (f"carrier speed {speeds.carrier:.3g} rad/s is zero within +-{d_carrier:.2g} "
                   "rad/s: a held carrier (star arrangement), measured like a differential "
                   "(no held ring or sun for a tacho to name planets on)")
        else:
            why = "no member's speed is zero: a differential (both driven)"
    if mesh_rate is not None and carrier_rate is not None and carrier_rate > 0 and mesh_rate > 0:
        ratio = mesh_rate / carrier_rate
        if not math.isfinite(ratio):
            return from_speeds, why or "no speeds: treated as a differential"
        data = None
        for name, z in (("ring", z_ring), ("sun", z_sun)):
            if abs(ratio / z - 1.0) <= rel_tol:
                data = name
        dwhy = (f"measured mesh/carrier frequency ratio {ratio:.5g} "
                + (f"= Z_{'r' if data == 'ring' else 's'}" if data else
                   f"matches neither Z_r = {z_ring} nor Z_s = {z_sun}"))
        if speeds is not None and data != from_speeds:
            return data, (f"{dwhy}; the nominal speeds said "
                          f"{from_speeds or 'a differential'} ({why}): the data decide")
        return data, dwhy + (f"; {why}" if why else "")
    return from_speeds, why or "no speeds: treated as a differential"


def relabel_train(train: PassTrain, shift: int, fractions, n_planets: int) -> PassTrain:
    """The same passes with planet 1 moved ``shift`` places along the pass order (every
    label and position with it): the N cyclic relabellings of a symmetric layout."""
    f = as_finite_array(fractions, "fractions", ndim=1, allow_empty=False)
    n = int(n_planets)
    seq = np.argsort(f, kind="stable")
    pos = train.position + int(shift)
    pl = seq[np.mod(pos, n)]
    target = train.z * (np.floor_divide(pos, n) + np.sort(f)[np.mod(pos, n)])
    return PassTrain(train.name, train.kind, train.times, train.sigma, target.astype(float),
                     pl.astype(int), pos.astype(int), train.sigma_given, train.z, train.order)


#: Observations above which :func:`label_shift_costs` fits only the central time window of
#: the record holding this many [-]: hundreds of passes per train decide a relabelling, and
#: the cost of the N fits then stays bounded in the record's length (a 1-h seed-rig record
#: holds ~13 000 gauge passes).
SHIFT_OBS = 6000


def _central_window(trains: list, max_obs: int) -> list:
    """``trains`` cut to the central time window holding at most ``max_obs`` observations."""
    n_obs = sum(len(tr) for tr in trains)
    if n_obs <= max_obs:
        return trains
    t = np.sort(np.concatenate([tr.times for tr in trains]))
    i0 = (t.size - max_obs) // 2
    lo, hi = t[i0], t[i0 + max_obs - 1]
    return [slice_train(tr, lo, np.nextafter(hi, np.inf))[0] for tr in trains]


def label_shift_costs(reference, train: PassTrain, fractions, kin: Kinematics,
                      n_planets: int, *, max_obs: int = SHIFT_OBS) -> np.ndarray:
    """Misfit of each cyclic relabelling of ``train`` against ``reference`` trains whose
    labels are taken as they are.

    A planet's own shaft hole offset moves its passes on every gauge alike (the planet terms
    of the model are shared by the gauges), so when the planets' offsets differ, only the
    relabelling that names the same physical planet alike on both gauges fits. Each shift is
    fitted with a fixed small model (cubic spline, first ripple harmonic of every shaft that
    turns, first planet term) and scored by its weighted chi-square. A record of more than
    ``max_obs`` observations is fitted on its central time window of ``max_obs`` (every
    train cut alike), so that the cost stays bounded in the record's length. The shifts
    after the first that fits start from its parameters and go side by side on the run's
    threads (:func:`meshphase.runtime.threads.thread_pool`): the same costs as one after another.

    Returns
    -------
    ndarray, shape (N,)
        chi-square per pass-order shift 0..N-1 [-] (inf where the fit failed).
    """
    max_obs = as_positive_int(max_obs, "max_obs")
    refs = [r for r in reference if len(r) >= 2]
    n = int(n_planets)
    out = np.full(n, np.inf)
    if not refs or len(train) < 2 or not kin.planet_period:
        return out
    *refs, train = _central_window(refs + [train], max_obs)
    refs = [r for r in refs if len(r) >= 2]
    if not refs or len(train) < 2:
        return out

    def shift_fit(s, first):
        trs = refs + [relabel_train(train, s, fractions, n)]
        d = _Design(trs, kin, n)
        span = d.t_hi - d.t_lo
        mean_rate = (d.y.max() - d.y.min()) / span if span > 0 else 0.0
        harm = {r: (1 if mean_rate * span / P >= 1.0 else 0) for r, P in kin.periods.items()}
        harm["planet"] = 0
        spec = _Spec(knots=1, harm=harm, mod={r: False for r in kin.periods}, sig=1)
        ones = np.ones(len(trs))
        if first is not None and d.layout(spec)["names"] == first.lay["names"]:
            # the same columns (a relabelling can change which planets a short train
            # holds, and with them its offsets and planet terms: then it starts afresh)
            th0 = _relabelled_start(d, spec, first.theta, len(trs) - 1)
        else:
            base = _solve(d, _Spec(knots=1, harm={r: 0 for r in kin.periods},
                                   mod={r: False for r in kin.periods}), None, ones)
            th0 = _extend(base, spec, d)
        return _solve(d, spec, th0, ones)

    # the shifts in order until one fits; that fit is the start of every later shift, whose
    # fits then share nothing and go side by side on the run's threads (QR and the large
    # array steps release the GIL): the same fits, in any order, as one after another
    first = None
    s = 0
    while s < n and first is None:
        fit = shift_fit(s, None)
        if np.isfinite(fit.chi2):
            out[s] = fit.chi2
            first = fit
        s += 1
    rest = list(range(s, n))
    if first is not None and rest:
        with thread_pool(max_items=len(rest)) as tmap:
            fits = tmap(lambda k: shift_fit(k, first), rest)
        for k, fit in zip(rest, fits):
            if np.isfinite(fit.chi2):
                out[k] = fit.chi2
    return out


def _relabelled_start(d: _Design, spec: _Spec, theta: np.ndarray, q: int) -> np.ndarray:
    """Start parameters for train ``q`` relabelled: another shift's fitted ``theta`` with
    that train's constant and offsets moved by its per-planet mean residual.

    A cyclic relabelling moves each planet's targets by a constant (a planet spacing and
    whole revolutions), so the shared terms (spline, ripple, the other trains' planet terms)
    of a neighbouring shift's fit are a start a few iterations from this shift's optimum,
    once the train's own constants take up the move."""
    lay = d.layout(spec)
    th = np.array(theta, dtype=float)
    f, _, _ = d.evaluate(th, lay, spec, jac=False)
    r = d.y - f
    m = d.q == q
    if not np.any(m):
        return th
    pl = d.pl[m]
    mean = {int(k): float(np.mean(r[m][pl == k])) for k in np.unique(pl)}
    ref = d.ref[q]
    c0 = mean.get(ref, 0.0)
    if q > 0:
        th[lay["blocks"]["const"].start + q - 1] += c0
    ob = lay["blocks"]["off"].start
    for k, v in mean.items():
        col = int(lay["off_table"][q, k])
        if col >= 0:
            th[ob + col] += v - c0
    return th


def mesh_cycles_per_carrier_turn(train: PassTrain, tacho_times) -> float:
    """Measured mesh cycles per carrier revolution between the first and last tacho edge.

    The gauge train's mesh angle (its targets, piecewise linear between passes) is read at
    the first and the last edge inside its span; the edges count whole carrier turns
    (:func:`revolution_numbers`). Both counts cover the same interval, so a ramp or ripple
    cancels; the error is the linear interpolation between two passes at each end (a
    fraction of the speed variation within one pass interval). A held ring gives Z_r, a held
    sun Z_s (:func:`held_member`). NaN when fewer than two edges fall inside the train.
    """
    if not isinstance(train, PassTrain):
        raise TypeError(f"train must be a PassTrain, got {type(train).__name__}")
    t = _check_times(tacho_times, "tacho_times")
    if len(train) < 2 or t.size < 2:
        return float("nan")
    k = revolution_numbers(t)
    inside = (t >= train.times[0]) & (t <= train.times[-1])
    if np.count_nonzero(inside) < 2:
        return float("nan")
    ta, tb = t[inside][0], t[inside][-1]
    ka, kb = k[inside][0], k[inside][-1]
    if kb == ka:
        return float("nan")
    a = np.interp([ta, tb], train.times, train.target)
    return float((a[1] - a[0]) / (kb - ka))


# ----------------------------------------------------------------------------- encoders
__all__ += ["shaft_cycles", "encoder_train"]


def shaft_cycles(kin: Kinematics, shaft: str) -> float:
    """Mesh cycles per revolution of an encoder's shaft [mesh cycles].

    Parameters
    ----------
    kin : Kinematics
        Tooth counts and the held member (:func:`meshphase.kinematics.angles.kinematics`).
    shaft : {"sun", "input", "carrier", "ring"}

    Returns
    -------
    float
        Ring held: carrier Z_r, sun Z_s Z_r / (Z_s + Z_r); sun held: carrier Z_s, ring
        Z_s Z_r / (Z_s + Z_r); a differential: from its nominal speeds.

    Raises
    ------
    ValueError
        The shaft is the held member (it does not turn), or a differential without speeds.
    """
    if not isinstance(kin, Kinematics):
        raise TypeError(f"kin must be a Kinematics (meshphase.kinematics.angles.kinematics), got "
                        f"{type(kin).__name__}")
    member = shaft_of(shaft)
    if member == kin.fixed:
        raise ValueError(f"encoder on the {shaft} shaft: the {member} is held, its encoder "
                         "does not turn")
    p = kin.periods.get(member)
    if p is None:
        raise ValueError(f"encoder on the {shaft} shaft: mesh cycles per {member} turn are not "
                         f"known (held member {kin.fixed!r}; a differential needs its speeds)")
    return float(p)


def encoder_train(edges: EncoderEdges, cycles_per_pulse: float, *, sigma=None,
                  name: str = "encoder") -> PassTrain:
    """An encoder's cleaned edges as an angle train (A = cycles_per_pulse k + c).

    Parameters
    ----------
    edges : EncoderEdges
        From :func:`meshphase.kinematics.encoder.clean_edges`.
    cycles_per_pulse : float
        Mesh cycles per pulse [mesh cycles]: :func:`shaft_cycles` / pulses per revolution.
    sigma : float or array_like, optional
        Edge timing uncertainty [s] (e.g. :func:`meshphase.kinematics.encoder.edge_timing_sigma`); None: the train's
        scatter sets it.
    name : str
        The channel's name (unique among the trains of a fit).

    Returns
    -------
    PassTrain
        Kind ``"tacho"``: a constant of its own, no planet terms.
    """
    if not isinstance(edges, EncoderEdges):
        raise TypeError(f"edges must be EncoderEdges (meshphase.kinematics.encoder.clean_edges), got "
                        f"{type(edges).__name__}")
    p = as_positive(cycles_per_pulse, "cycles_per_pulse")
    if not isinstance(name, str) or not name:
        raise ValueError(f"name must be a non-empty string, got {name!r}")
    t = _check_times(edges.times, "edges.times")
    k = np.asarray(edges.count, dtype=np.int64)
    if k.shape != t.shape:
        raise ValueError(f"edges.count {k.shape} must have the shape of edges.times {t.shape}")
    if k.size > 1 and np.any(np.diff(k) < 1):
        raise ValueError("edges.count must increase by at least 1 from edge to edge")
    dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    s, given = _sigma(sigma, t.size, 1e-4 * dt)
    return PassTrain(name, "tacho", t, s, p * k.astype(float), np.full(t.size, -1), k, given)


def _planet_rate_sampled(d: _Design, kin: Kinematics) -> bool:
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

