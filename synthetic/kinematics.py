"""Rotation angles under speed fluctuation and the exact engagement times of gauged teeth.

Speed profile
-------------
The rig runs at nominal speeds ``Speeds`` (sun, carrier, planet, ring) [rad/s] times a common
speed factor ``s`` [-]. One factor for every member is what a rigid gear train imposes: all
speeds are tied by the tooth counts (Willis), so torsional wind-up aside, a speed change of
the drive moves every member in proportion. Every rotation angle is then ``w tau(t)`` with
the *angle time* ``tau`` [s], ``d tau / dt = s``, ``tau(0) = 0`` (t from the first sample), so
the actual relative rotation angles are ``w_sc tau``, ``w_pc tau``, ``w_rc tau``.

The factor has a part that is a function of time and a part that is periodic in the angle of
a shaft::

    s(t, tau) = 1 + r t + sum_i a_i sin(2 pi f_i t + phi_i)            (time: ramp, ripple [Hz])
                + sum_j b_j sin(m_j theta_j(tau) + phi_j)               (shaft-locked ripple)

``r`` a ramp rate [1/s]; ``a_i, f_i, phi_i`` slow ripple components at fixed frequencies;
``b_j, m_j, phi_j`` ripple locked to the rotation angle ``theta_j = w_j tau`` of a member
(:class:`ShaftRipple`): the carrier, sun or ring at its absolute speed ``w_j`` (carrier,
sun, ring of :class:`~meshphase.models.gearset.Speeds`), or the planet's spin relative to the
carrier, ``w_pc``. Shaft-locked ripple is the physics of drive and eccentricity ripple: it
repeats once per ``1 / m_j`` turn of the shaft, so it follows the shaft when the speed ramps,
and it follows the member's actual angle in either sense of rotation (``w_j < 0`` turns
``theta_j`` backwards). Note that the mean speed over one ripple period of a shaft-locked
component alone is ``sqrt(1 - b^2)`` (``dt = d tau / (1 + b sin)``), not 1: 1.25e-4 below
nominal at b = 5 %.

Without shaft-locked components ``tau`` has the closed form

    tau(t) = t + r t^2 / 2 + sum_i a_i / (2 pi f_i) (cos phi_i - cos(2 pi f_i t + phi_i))

and the inverse ``t(tau)`` follows by Newton's method (~1 ulp). With them, ``d tau / dt =
s(t, tau)`` is an ODE, solved by :class:`SpeedClock` with spectral collocation on panels: on
each panel of at most one period of the fastest component (and at most
:data:`PANEL_MAX` s) ``tau`` is the polynomial of degree 33 whose derivative interpolates
``s(t, tau)`` at 33 Chebyshev-Lobatto points (an implicit Runge-Kutta method of collocation
type, solved by Newton's method with the exact Jacobian). The interpolation error of a
sinusoid over one period at 33 points is ~1e-29 of its amplitude, so the solution is exact to
rounding; the panel starts are summed with compensation (error ~ulp(tau) over any number of
panels). The polynomial is also the dense output: ``tau(t)`` anywhere by Clenshaw summation,
``t(tau)`` by Newton's method on it. Panels are built lazily outward from t = 0 in both
directions (negative times are the margins before the first sample), always in the same
sequence, so the result does not depend on the order of the requests. The test suite holds
it against ``scipy.integrate.solve_ivp`` (DOP853) on the ODE itself.

The shaft-hole-error geometry of :func:`meshphase.models.mesh_phasing.mesh_angles`, which
turns each offset by ``w t``, is therefore evaluated at ``tau`` instead of ``t``: that *is*
the geometry as a function of the actual rotation angles, with no second implementation of it
(the tests check that the engagement angles hold at the actual angles, integrated
numerically). A ring that is driven independently of the sun (a differential) with its own
fluctuation is outside this model.

Engagement of a gauged tooth
----------------------------
A gauge on sun tooth ``j`` sits, in the carrier frame, at the direction
``theta_j + w_sc tau`` about the actual sun centre (the body turns about its bearing axis,
which moves every direction fixed to it by the same angle; ``theta_j = sun_angle0 + 2 pi j /
Z_s`` its direction at t = 0). It meets planet n when that direction equals the direction of
the line of centres ``psi_es,n(tau) = arg(O_pan - O_sa)``::

    theta_j + w_sc tau - psi_es,n(tau) = 2 pi k,      k integer

so per sun revolution relative to the carrier it meets all N planets, in increasing planet
angle when w_sc > 0 and decreasing when w_sc < 0. A gauge on ring tooth ``j`` is the same
with ``w_rc`` (= -w_c for a fixed ring: each planet passes once per carrier revolution) and
``psi_er,n = arg(O_pan - O_ra)``.

**Truth engagement time**: the instant the gauged tooth's centre line crosses the line of
centres (actual gear centre -> actual planet centre), i.e. the middle of the tooth's contact
with that planet. The strain pulse (:mod:`meshphase.synthetic.gauges`) is defined relative to it, in
the angle of the gauged gear.

The equation is solved per event in angle time: from the ideal root
``tau_0 = (psi_n + 2 pi k - theta) / w`` by a chord (Newton) iteration on the reduced angle
residual, with the slope ``w - dpsi/dtau`` estimated once by central differences; the error
terms turn slowly (|dpsi/dtau| << |w|) so a few iterations reach ~1e-15 relative. The
wall-clock time follows from the speed clock's inverse ``t(tau)``. Engagements, the tacho
(:func:`event_times_for_angles`) and the truth all use one :class:`SpeedClock`.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass

import numpy as np
from numpy.polynomial import chebyshev as _cheb

from meshphase.models.gearset import Gearset, Speeds
from meshphase.models.mesh_phasing import ShaftHoleErrors, mesh_angles, rotation_angle
from meshphase.validate import as_choice, as_float, as_int, as_nonnegative

__all__ = ["SpeedProfile", "ShaftRipple", "SpeedClock", "MEMBERS", "member_rate",
           "EngagementEvents", "engagement_events", "event_times_for_angles", "gauge_rates",
           "S_MIN", "PANEL_MAX"]

TWO_PI = 2.0 * math.pi
_CHUNK = 50_000
#: Lowest speed factor a profile may reach [-] (below it the rig would stop or reverse).
S_MIN = 0.05
#: Members whose rotation angle a shaft-locked ripple can follow.
MEMBERS = ("carrier", "sun", "planet", "ring")
#: Longest collocation panel of :class:`SpeedClock` [s].
PANEL_MAX = 16.0


def _reduce(x):
    return x - TWO_PI * np.rint(x / TWO_PI)


def member_rate(speeds: Speeds, member: str) -> float:
    """Nominal rate [rad/s] of the angle a shaft-locked ripple follows.

    Parameters
    ----------
    speeds : Speeds
        Nominal absolute speeds [rad/s].
    member : {"carrier", "sun", "planet", "ring"}
        "carrier", "sun", "ring": the member's absolute speed; "planet": the planet's spin
        relative to the carrier, ``w_pc = w_p - w_c`` (the angle its bearing and its teeth
        turn through against the carrier).
    """
    if not isinstance(speeds, Speeds):
        raise TypeError(f"speeds must be a Speeds, got {type(speeds).__name__}")
    as_choice(member, "member", MEMBERS)
    if member == "planet":
        return speeds.w_pc
    return float(getattr(speeds, member))


@dataclass(frozen=True)
class ShaftRipple:
    """One speed ripple component locked to a member's rotation angle.

    Adds ``amplitude * sin(order * theta + phase)`` to the speed factor, with ``theta =
    w tau`` the member's rotation angle [rad] (``w`` from :func:`member_rate`: the absolute
    angle of the carrier, sun or ring; for "planet" the planet's spin relative to the
    carrier, ``w_pc tau``). ``theta`` follows the member's actual angle in either sense of
    rotation and through any ramp.

    Parameters
    ----------
    member : {"carrier", "sun", "planet", "ring"}
        The member whose angle the ripple follows; it must turn (w != 0) when bound to
        speeds.
    amplitude : float
        Relative amplitude b [-], >= 0 (typically <= 0.05; the whole profile must keep
        s > 0.05).
    order : int
        Harmonic order m [-] of the member's rotation, >= 1.
    phase : float
        Phase phi [rad] at theta = 0.
    """

    member: str
    amplitude: float
    order: int = 1
    phase: float = 0.0

    def __post_init__(self):
        as_choice(self.member, "shaft ripple member", MEMBERS)
        a = as_float(self.amplitude, "shaft ripple amplitude")
        if a < 0.0:
            raise ValueError(f"shaft ripple amplitude must be >= 0 (a relative speed "
                             f"amplitude [-]), got {a!r}")
        if a >= 1.0 - S_MIN:
            raise ValueError(f"shaft ripple amplitude must be < {1.0 - S_MIN!r} so that the speed "
                             f"factor s stays > {S_MIN} (the rig would stop or reverse), got {a!r}")
        object.__setattr__(self, "amplitude", a)
        m = as_int(self.order, "shaft ripple order")
        if m < 1:
            raise ValueError(f"shaft ripple order must be an integer >= 1 (harmonic of the "
                             f"member's rotation), got {m!r}")
        object.__setattr__(self, "order", m)
        object.__setattr__(self, "phase", as_float(self.phase, "shaft ripple phase"))

    def rate(self, speeds: Speeds) -> float:
        """Nominal rate of theta [rad/s] (:func:`member_rate`)."""
        return member_rate(speeds, self.member)

    def to_dict(self) -> dict:
        return {"member": self.member, "amplitude": self.amplitude, "order": self.order,
                "phase": self.phase}

    @classmethod
    def from_dict(cls, d) -> "ShaftRipple":
        """From a dict (keys of :meth:`to_dict`), a ShaftRipple, or a tuple
        ``(member, amplitude[, order[, phase]])``."""
        if isinstance(d, ShaftRipple):
            return d
        if isinstance(d, dict):
            unknown = sorted(set(d) - {"member", "amplitude", "order", "phase"})
            if unknown:
                raise ValueError(f"shaft ripple: unknown key(s) {unknown}; expected member, "
                                 "amplitude, order, phase")
            if "member" not in d or "amplitude" not in d:
                raise ValueError(f"shaft ripple needs 'member' and 'amplitude', got {d!r}")
            return cls(**d)
        if isinstance(d, (tuple, list)) and 2 <= len(d) <= 4:
            return cls(*d)
        raise TypeError("a shaft ripple must be a ShaftRipple, a dict or (member, amplitude[, "
                        f"order[, phase]]), got {d!r}")


@dataclass(frozen=True)
class SpeedProfile:
    """Speed factor ``s(t, tau) = 1 + r t + sum a_i sin(2 pi f_i t + phi_i)
    + sum b_j sin(m_j theta_j + phi_j)`` [-] (see the module docstring).

    Parameters
    ----------
    ramp_rate : float
        Linear speed change per second, relative to nominal [1/s] (0.001 = +0.1 %/s).
    ripple : tuple of (amplitude, frequency, phase)
        Speed ripple at fixed frequencies: relative amplitude a_i [-], frequency f_i [Hz]
        (> 0), phase phi_i [rad].
    shaft : tuple of ShaftRipple
        Speed ripple locked to a member's rotation angle (:class:`ShaftRipple`, or dicts /
        tuples ``(member, amplitude[, order[, phase]])``). A profile with shaft-locked
        components needs the nominal speeds to be evaluated: :meth:`clock`.

    Notes
    -----
    The amplitudes together must leave ``1 - sum a_i - sum b_j > 0.05`` (ValueError
    otherwise); :meth:`check` adds the ramp over a given duration.
    """

    ramp_rate: float = 0.0
    ripple: tuple = ()
    shaft: tuple = ()

    def __post_init__(self):
        object.__setattr__(self, "ramp_rate", as_float(self.ramp_rate, "ramp_rate"))
        rip = []
        for i, comp in enumerate(self.ripple):
            if isinstance(comp, dict):
                comp = (comp["amplitude"], comp["frequency"], comp.get("phase", 0.0))
            try:
                a, f, ph = comp
            except (TypeError, ValueError):
                raise TypeError(f"ripple[{i}] must be (amplitude, frequency [Hz], phase [rad]), got {comp!r}") from None
            a = as_nonnegative(a, f"ripple[{i}] amplitude")
            f = as_float(f, f"ripple[{i}] frequency")
            if f <= 0:
                raise ValueError(f"ripple[{i}] frequency must be > 0 Hz, got {f!r}")
            rip.append((a, f, as_float(ph, f"ripple[{i}] phase")))
        object.__setattr__(self, "ripple", tuple(rip))
        if isinstance(self.shaft, (ShaftRipple, dict)):
            raise TypeError("shaft must be a sequence of shaft ripple components, got a single "
                            f"{type(self.shaft).__name__}; wrap it in a tuple")
        try:
            comps = tuple(self.shaft)
        except TypeError:
            raise TypeError(f"shaft must be a sequence of ShaftRipple, got {self.shaft!r}") from None
        object.__setattr__(self, "shaft", tuple(ShaftRipple.from_dict(c) for c in comps))
        total = self.ripple_amplitude
        if 1.0 - total <= S_MIN:
            raise ValueError(f"ripple amplitudes sum to {total!r}: the speed factor s may fall to "
                             f"<= {S_MIN} (the rig would stop or reverse); ripple={self.ripple!r}, "
                             f"shaft={[c.to_dict() for c in self.shaft]!r}")

    # ------------------------------------------------------------------ construction
    @classmethod
    def shaft_ripple(cls, member: str, amplitude: float, order: int = 1, phase: float = 0.0, *,
                     ramp_rate: float = 0.0, ripple: tuple = ()) -> "SpeedProfile":
        """A profile with one shaft-locked ripple component (plus an optional ramp and
        fixed-frequency ripple): ``amplitude * sin(order * theta_member + phase)``.

        Parameters
        ----------
        member : {"carrier", "sun", "planet", "ring"}
            Member whose angle the ripple follows (:class:`ShaftRipple`).
        amplitude : float
            Relative amplitude [-].
        order : int
            Harmonic of the member's rotation [-], >= 1.
        phase : float
            Phase at theta = 0 [rad].
        ramp_rate : float
            Linear speed change [1/s].
        ripple : tuple
            Fixed-frequency ripple components (see the class).
        """
        return cls(ramp_rate=ramp_rate, ripple=ripple,
                   shaft=(ShaftRipple(member, amplitude, order, phase),))

    # ------------------------------------------------------------------ properties
    @property
    def ripple_amplitude(self) -> float:
        """Sum of all ripple amplitudes, fixed-frequency and shaft-locked [-]."""
        return sum(a for a, _, _ in self.ripple) + sum(c.amplitude for c in self.shaft)

    @property
    def has_shaft(self) -> bool:
        """True when a shaft-locked component has a non-zero amplitude (s depends on tau)."""
        return any(c.amplitude != 0.0 for c in self.shaft)

    @property
    def is_constant(self) -> bool:
        """True when s = 1 (no ramp, no ripple)."""
        return (self.ramp_rate == 0.0 and all(a == 0.0 for a, _, _ in self.ripple)
                and not self.has_shaft)

    def bounds(self, duration: float) -> tuple[float, float]:
        """Conservative bounds (s_lo, s_hi) [-] of the speed factor on [0, duration] [s]."""
        d = as_float(duration, "duration")
        amp = self.ripple_amplitude
        ramp = self.ramp_rate * d
        return 1.0 + min(0.0, ramp) - amp, 1.0 + max(0.0, ramp) + amp

    def check(self, duration: float) -> None:
        """ValueError unless s > 0.05 on [0, duration] (a conservative bound)."""
        low = self.bounds(duration)[0]
        if low <= S_MIN:
            raise ValueError(f"speed profile may reach s <= {S_MIN} within {duration!r} s "
                             f"(ramp_rate={self.ramp_rate!r} 1/s, ripple={self.ripple!r}, "
                             f"shaft={[c.to_dict() for c in self.shaft]!r}); the rig would stop "
                             "or reverse")

    # ------------------------------------------------------------------ the time part
    def _time_factor(self, t):
        s = 1.0 + self.ramp_rate * t
        for a, f, ph in self.ripple:
            if a:
                s = s + a * np.sin(TWO_PI * np.mod(f * t, 1.0) + ph)
        return s

    def _time_tau(self, t):
        out = t + 0.5 * self.ramp_rate * t * t
        for a, f, ph in self.ripple:
            if a:
                out = out + a / (TWO_PI * f) * (math.cos(ph) - np.cos(TWO_PI * np.mod(f * t, 1.0) + ph))
        return out

    def _time_inverse(self, tau):
        r = self.ramp_rate
        # start from the ramp-only solution, then Newton on the full tau(t)
        if r != 0.0:
            disc = np.maximum(1.0 + 2.0 * r * tau, 0.0)
            t = 2.0 * tau / (1.0 + np.sqrt(disc))
        else:
            t = tau.copy()
        # converged when the step is within the rounding of tau(t) itself: a few ulps of its
        # largest term (t, the ramp's r t^2 / 2, each ripple's a / (2 pi f)); a bound on t
        # alone (2 ulps) is never met when those rounding errors exceed it
        spread = sum(2.0 * abs(a) / (TWO_PI * f) for a, f, _ in self.ripple if a)
        for _ in range(60):
            dt = (self._time_tau(t) - tau) / self._time_factor(t)
            t = t - dt
            tol = 8.0 * np.finfo(float).eps * (1.0 + np.abs(t) + 0.5 * abs(r) * t * t + spread)
            if np.all(np.abs(dt) <= tol):
                break
        else:
            raise ValueError("could not invert the speed profile tau(t) (speed factor too close to 0?)")
        return t

    def _need_speeds(self, speeds, what):
        if speeds is None:
            raise ValueError(f"{what}: this profile has shaft-locked ripple, so s depends on the "
                             "rotation angle; pass speeds= (the nominal Speeds) or use "
                             "profile.clock(speeds)")
        return self.clock(speeds)

    # ------------------------------------------------------------------ evaluation
    def factor(self, t, speeds: Speeds | None = None) -> np.ndarray:
        """Speed factor s(t, tau(t)) [-] at times t [s] from the first sample.

        ``speeds`` (nominal Speeds) is needed when the profile has shaft-locked ripple;
        repeated calls should keep one :meth:`clock` instead.
        """
        if self.has_shaft:
            return self._need_speeds(speeds, "factor").factor(t)
        return self._time_factor(np.asarray(t, dtype=np.float64))

    def tau(self, t, speeds: Speeds | None = None) -> np.ndarray:
        """Angle time tau(t) = int_0^t s dt' [s] (``speeds`` as for :meth:`factor`)."""
        if self.has_shaft:
            return self._need_speeds(speeds, "tau").tau(t)
        return self._time_tau(np.asarray(t, dtype=np.float64))

    def time_of(self, tau, speeds: Speeds | None = None) -> np.ndarray:
        """Inverse of :meth:`tau`: times t [s] with tau(t) = ``tau`` (Newton, ~1 ulp)."""
        if self.has_shaft:
            return self._need_speeds(speeds, "time_of").time_of(tau)
        tau = np.asarray(tau, dtype=np.float64)
        if self.is_constant or tau.size == 0:
            return tau.copy()
        return self._time_inverse(tau)

    def clock(self, speeds: Speeds) -> "SpeedClock":
        """This profile bound to nominal speeds: s(t), tau(t) and t(tau) (:class:`SpeedClock`)."""
        return SpeedClock(self, speeds)

    # ------------------------------------------------------------------ serialisation
    def to_dict(self) -> dict:
        return {"ramp_rate": self.ramp_rate,
                "ripple": [{"amplitude": a, "frequency": f, "phase": p} for a, f, p in self.ripple],
                "shaft": [c.to_dict() for c in self.shaft]}

    @classmethod
    def from_dict(cls, d: dict) -> "SpeedProfile":
        if not isinstance(d, dict):
            raise TypeError(f"a speed profile dict is needed, got {type(d).__name__}")
        unknown = sorted(set(d) - {"ramp_rate", "ripple", "shaft"})
        if unknown:
            raise ValueError(f"speed profile: unknown key(s) {unknown}; expected ramp_rate, "
                             "ripple, shaft")
        return cls(ramp_rate=d.get("ramp_rate", 0.0), ripple=tuple(d.get("ripple", ())),
                   shaft=tuple(d.get("shaft", ())))


# ----------------------------------------------------------------------------- the clock

#: Degree of the interpolant of s on a panel (N + 1 Chebyshev-Lobatto points).
_N = 32


def _collocation_matrices(n: int):
    x = -np.cos(np.pi * np.arange(n + 1) / n)             # ascending, x[0] = -1, x[n] = 1
    vinv = np.linalg.inv(_cheb.chebvander(x, n))           # node values -> coefficients
    integ = np.zeros((n + 2, n + 1))
    for k in range(n + 1):
        e = np.zeros(n + 1)
        e[k] = 1.0
        integ[:, k] = _cheb.chebint(e, lbnd=-1.0)          # antiderivative, 0 at x = -1
    q = integ @ vinv                                       # f at nodes -> coeffs of int f
    s = _cheb.chebvander(x, n + 1) @ q                     # f at nodes -> int f at nodes
    return x, q, s


_X, _Q, _S = _collocation_matrices(_N)
_EYE = np.eye(_N + 1)


def _two_sum(a: float, b: float) -> tuple[float, float]:
    s = a + b
    bb = s - a
    return s, (a - (s - bb)) + (b - bb)


class SpeedClock:
    """A :class:`SpeedProfile` bound to nominal speeds: ``s(t, tau)``, ``tau(t)``, ``t(tau)``.

    Without shaft-locked components every method is the profile's closed form (bit for bit).
    With them, ``d tau / dt = s(t, tau)`` is solved by spectral collocation on panels (module
    docstring), built lazily outward from t = 0 as requests reach further.

    Parameters
    ----------
    profile : SpeedProfile
    speeds : Speeds
        Nominal absolute speeds [rad/s]; give the rates of the shaft-locked components.

    Attributes
    ----------
    profile : SpeedProfile
    speeds : Speeds
    rates : tuple of float
        Nominal rate [rad/s] of each shaft-locked component's angle.
    """

    def __init__(self, profile: SpeedProfile, speeds: Speeds):
        if not isinstance(profile, SpeedProfile):
            raise TypeError(f"profile must be a SpeedProfile, got {type(profile).__name__}")
        if not isinstance(speeds, Speeds):
            raise TypeError(f"speeds must be a Speeds, got {type(speeds).__name__}")
        self.profile = profile
        self.speeds = speeds
        comps = [c for c in profile.shaft if c.amplitude != 0.0]
        rates = []
        for c in comps:
            w = c.rate(speeds)
            if w == 0.0:
                raise ValueError(f"shaft ripple on the {c.member!r}: that member does not turn at "
                                 f"these speeds (rate 0 rad/s), so its angle cannot carry a ripple")
            rates.append(w)
        self.rates = tuple(rates)
        self._comps = tuple((c.amplitude, c.order * w, c.phase) for c, w in zip(comps, rates))
        self._shaft = bool(comps)
        self._lock = threading.Lock()
        if self._shaft:
            amp = profile.ripple_amplitude
            self._amp = amp
            self._omega_t = max((TWO_PI * f for a, f, _ in profile.ripple if a), default=0.0)
            self._omega_a = max(abs(k) for _, k, _ in self._comps)
            # panels: forward [0, t1], [t1, t2], ...; backward [0, -t1'], ...
            self._fwd = []       # (t_a, h, tau_hi, tau_lo, coeffs)
            self._bwd = []
            self._arrays = None

    # ------------------------------------------------------------------ s(t, tau)
    @property
    def is_constant(self) -> bool:
        """True when s = 1."""
        return self.profile.is_constant

    @property
    def has_shaft(self) -> bool:
        """True when s depends on tau (shaft-locked ripple)."""
        return self._shaft

    def _angle_part(self, tau):
        h = 0.0
        for b, k, ph in self._comps:
            h = h + b * np.sin(k * tau + ph)
        return h

    def _angle_slope(self, tau):
        d = 0.0
        for b, k, ph in self._comps:
            d = d + (b * k) * np.cos(k * tau + ph)
        return d

    def rate(self, t, tau) -> np.ndarray:
        """The speed factor ``s(t, tau)`` [-] at times t [s] and angle times tau [s]
        (broadcast): the right-hand side of ``d tau / dt = s``."""
        t = np.asarray(t, dtype=np.float64)
        s = self.profile._time_factor(t)
        if self._shaft:
            s = s + self._angle_part(np.asarray(tau, dtype=np.float64))
        return np.asarray(s, dtype=np.float64)

    # ------------------------------------------------------------------ panels
    def _panel_length(self, t_a: float) -> float:
        s_hi = 1.0 + abs(self.profile.ramp_rate) * (abs(t_a) + PANEL_MAX) + self._amp
        omega = max(self._omega_t, self._omega_a * s_hi)
        return min(PANEL_MAX, TWO_PI / omega)

    def _solve_panel(self, t_a: float, hi: float, lo: float, h: float):
        """Coefficients of tau - tau_a on [t_a, t_a + h] (x = -1 at t_a; h may be < 0)."""
        tn = t_a + 0.5 * h * (_X + 1.0)
        gt = self.profile._time_factor(tn)
        tau_a = hi + lo
        y = (tn - t_a) * float(self.rate(t_a, tau_a))
        half = 0.5 * h
        for _ in range(40):
            tau = tau_a + y
            f = gt + self._angle_part(tau)
            res = y - half * (_S @ f)
            jac = _EYE - half * _S * self._angle_slope(tau)[None, :]
            d = np.linalg.solve(jac, res)
            y = y - d
            if float(np.max(np.abs(d))) <= 1e-14 * abs(h):
                break
        else:
            raise ValueError(f"speed clock: the collocation did not converge on the panel at "
                             f"t = {t_a!r} s (speed factor too close to 0?)")
        f = gt + self._angle_part(tau_a + y)
        return half * (_Q @ f)

    def _extend(self, t_min: float, t_max: float, tau_min: float, tau_max: float) -> None:
        with self._lock:
            changed = False
            if not self._fwd:
                h = self._panel_length(0.0)
                self._fwd.append((0.0, h, 0.0, 0.0, self._solve_panel(0.0, 0.0, 0.0, h)))
                changed = True
            for panels, sign, done in ((self._fwd, 1.0, lambda t, tau: t >= t_max and tau >= tau_max),
                                       (self._bwd, -1.0, lambda t, tau: t <= t_min and tau <= tau_min)):
                if panels:
                    t_a, h, hi, lo, c = panels[-1]
                    t_end = t_a + h
                    hi, lo = _two_sum(hi, lo + float(np.sum(c)))
                else:
                    t_end, hi, lo = 0.0, 0.0, 0.0
                while not done(t_end, hi + lo):
                    h = sign * self._panel_length(t_end)
                    c = self._solve_panel(t_end, hi, lo, h)
                    panels.append((t_end, h, hi, lo, c))
                    changed = True
                    t_end = t_end + h
                    hi, lo = _two_sum(hi, lo + float(np.sum(c)))
            if changed or self._arrays is None:
                self._build_arrays()

    def _build_arrays(self) -> None:
        rows = self._bwd[::-1] + self._fwd
        if not rows:
            self._arrays = None
            return
        t_a = np.array([r[0] for r in rows])
        h = np.array([r[1] for r in rows])
        hi = np.array([r[2] for r in rows])
        lo = np.array([r[3] for r in rows])
        coef = np.array([r[4] for r in rows])
        end = coef.sum(axis=1)                    # tau(t_a + h) - tau_a
        t_lo = np.minimum(t_a, t_a + h)
        t_hi = np.maximum(t_a, t_a + h)
        tau_lo = np.where(h > 0, hi + lo, (hi + lo) + end)
        tau_hi = np.where(h > 0, (hi + lo) + end, hi + lo)
        self._arrays = dict(t_a=t_a, h=h, hi=hi, lo=lo, coef=coef, t_lo=t_lo, t_hi=t_hi,
                            tau_lo=tau_lo, tau_hi=tau_hi)

    def _covered(self):
        a = self._arrays
        if a is None:
            return 0.0, 0.0, 0.0, 0.0
        return float(a["t_lo"][0]), float(a["t_hi"][-1]), float(a["tau_lo"][0]), float(a["tau_hi"][-1])

    @property
    def n_panels(self) -> int:
        """Collocation panels built so far (0 without shaft-locked ripple)."""
        return (len(self._fwd) + len(self._bwd)) if self._shaft else 0

    def _eval(self, t: np.ndarray) -> np.ndarray:
        a = self._arrays
        p = np.clip(np.searchsorted(a["t_lo"], t, side="right") - 1, 0, a["t_lo"].size - 1)
        out = np.empty(t.shape)
        for s in range(0, t.size, 8192):
            e = min(t.size, s + 8192)
            pp = p[s:e]
            x = 2.0 * (t[s:e] - a["t_a"][pp]) / a["h"][pp] - 1.0
            c = a["coef"][pp]                      # (m, N + 2)
            # Clenshaw for sum c_k T_k(x)
            b1 = np.zeros(e - s)
            b2 = np.zeros(e - s)
            x2 = 2.0 * x
            for k in range(c.shape[1] - 1, 0, -1):
                b1, b2 = c[:, k] + x2 * b1 - b2, b1
            y = c[:, 0] + x * b1 - b2
            out[s:e] = a["hi"][pp] + (a["lo"][pp] + y)
        return out

    # ------------------------------------------------------------------ tau, t
    def tau(self, t) -> np.ndarray:
        """Angle time tau(t) [s] at times t [s] from the first sample."""
        if not self._shaft:
            return self.profile.tau(t)
        t = np.asarray(t, dtype=np.float64)
        if t.size == 0:
            return np.empty(t.shape)
        if not np.all(np.isfinite(t)):
            raise ValueError("t must be finite")
        t_min, t_max = float(np.min(t)), float(np.max(t))
        c = self._covered()
        if self._arrays is None or t_min < c[0] or t_max > c[1]:
            self._extend(t_min, t_max, math.inf, -math.inf)
        flat = t.reshape(-1)
        return self._eval(flat).reshape(t.shape)

    def factor(self, t) -> np.ndarray:
        """Speed factor s(t, tau(t)) [-] at times t [s]."""
        if not self._shaft:
            return self.profile.factor(t)
        t = np.asarray(t, dtype=np.float64)
        return self.rate(t, self.tau(t))

    def time_of(self, tau) -> np.ndarray:
        """Times t [s] with tau(t) = ``tau`` (Newton on the dense solution, ~1 ulp)."""
        if not self._shaft:
            return self.profile.time_of(tau)
        tau = np.asarray(tau, dtype=np.float64)
        if tau.size == 0:
            return np.empty(tau.shape)
        if not np.all(np.isfinite(tau)):
            raise ValueError("tau must be finite")
        q_min, q_max = float(np.min(tau)), float(np.max(tau))
        c = self._covered()
        if self._arrays is None or q_min < c[2] or q_max > c[3]:
            self._extend(math.inf, -math.inf, q_min, q_max)
        a = self._arrays
        flat = tau.reshape(-1)
        p = np.clip(np.searchsorted(a["tau_lo"], flat, side="right") - 1, 0, a["tau_lo"].size - 1)
        frac = (flat - a["tau_lo"][p]) / (a["tau_hi"][p] - a["tau_lo"][p])
        t = a["t_lo"][p] + frac * (a["t_hi"][p] - a["t_lo"][p])
        # rounding floor of tau(t): a few ulp of t and of the panel's polynomial (~ eps |h|)
        scale = 16.0 * np.finfo(float).eps * np.maximum(np.abs(a["h"][p]), 1.0)
        for _ in range(60):
            cur = self._eval(t)
            dt = (cur - flat) / self.rate(t, cur)
            t = t - dt
            if np.all(np.abs(dt) <= np.maximum(scale, 4e-16 * np.abs(t))):
                break
        else:
            raise ValueError("could not invert the speed clock tau(t) (speed factor too close to 0?)")
        return t.reshape(tau.shape)


def _as_clock(profile, speeds: Speeds) -> SpeedClock:
    """A SpeedClock from None, a SpeedProfile or a SpeedClock (whose speeds must match)."""
    if profile is None:
        return SpeedClock(SpeedProfile(), speeds)
    if isinstance(profile, SpeedClock):
        if profile.speeds != speeds:
            raise ValueError(f"the speed clock was bound to speeds {profile.speeds!r}, not "
                             f"{speeds!r}")
        return profile
    if isinstance(profile, SpeedProfile):
        return SpeedClock(profile, speeds)
    raise TypeError(f"profile must be a SpeedProfile, a SpeedClock or None, got "
                    f"{type(profile).__name__}")


def gauge_rates(gearset: Gearset, speeds: Speeds, gear: str) -> tuple[float, int]:
    """Relative speed [rad/s] of the gauged gear to the carrier and its tooth count [-].

    ``gear`` is "sun" (w_sc, Z_s) or "ring" (w_rc, Z_r). The gauge meets each planet once per
    ``2 pi / |w|`` and its mesh period is ``2 pi / (Z |w|)`` [s].
    """
    if gear == "sun":
        return speeds.w_sc, gearset.z_sun
    if gear == "ring":
        return speeds.w_rc, gearset.z_ring
    raise ValueError(f"gear must be 'sun' or 'ring', got {gear!r}")


@dataclass
class EngagementEvents:
    """Engagements of one gauged tooth with the planets, sorted by time.

    Attributes
    ----------
    time : ndarray, shape (m,)
        Engagement instants [s] from the first sample (truth definition: the tooth's centre
        line crosses the line of centres).
    tau : ndarray, shape (m,)
        Angle time of the engagement [s] (rotation angles are ``w tau``).
    planet : ndarray of int, shape (m,)
        Planet number n, 1-based (planet 1 = ``gearset.planet_angles[0]``).
    revolution : ndarray of int, shape (m,)
        Integer k of the engagement equation (relative revolutions of the gauged gear).
    mesh_period : ndarray, shape (m,)
        Local mesh period ``2 pi / (Z |w| s)`` at the engagement [s] (s at the engagement's
        t and tau).
    """

    time: np.ndarray
    tau: np.ndarray
    planet: np.ndarray
    revolution: np.ndarray
    mesh_period: np.ndarray

    def __len__(self) -> int:
        return int(self.time.size)

    @classmethod
    def empty(cls) -> "EngagementEvents":
        z = np.empty(0)
        return cls(z, z.copy(), np.empty(0, np.int64), np.empty(0, np.int64), z.copy())


def _psi_planet(tau, planet_idx, gearset, speeds, errors, which):
    """psi_es (which=0) or psi_er (which=1) of each event's own planet at angle times tau."""
    out = np.empty(tau.shape)
    for a in range(0, tau.size, _CHUNK):
        b = min(tau.size, a + _CHUNK)
        ang = mesh_angles(tau[a:b], gearset, speeds, errors)[which]
        out[a:b] = ang[np.arange(b - a), planet_idx[a:b]]
    return out


def engagement_events(gearset: Gearset, speeds: Speeds, gear: str, tooth_angle: float,
                      t_start: float, t_stop: float, *, errors: ShaftHoleErrors | None = None,
                      profile: SpeedProfile | None = None, tol: float = 1e-15,
                      max_iter: int = 40) -> EngagementEvents:
    """Exact engagement times of a gauged sun or ring tooth with every planet.

    Parameters
    ----------
    gearset : Gearset
        Tooth counts, planet angles psi_n [rad], carrier radius [m].
    speeds : Speeds
        Nominal absolute speeds [rad/s] (the speed factor s(t) multiplies them).
    gear : {"sun", "ring"}
        The gauged gear.
    tooth_angle : float
        Direction of the gauged tooth's centre line about the gear's pitch centre at t = 0,
        in the carrier frame [rad].
    t_start, t_stop : float
        Half-open window [t_start, t_stop) of times from the first sample [s].
    errors : ShaftHoleErrors, optional
        One realisation of the shaft hole position errors (no sample dimensions).
    profile : SpeedProfile or SpeedClock, optional
        Speed fluctuation (None: constant nominal speed); a SpeedClock must be bound to
        ``speeds``.
    tol : float
        Relative tolerance of the angle-time iteration [-].
    max_iter : int
        Iteration limit; ValueError if it is reached.

    Returns
    -------
    EngagementEvents
        Sorted by time; empty when the gear does not turn relative to the carrier or the
        window is empty.
    """
    if not isinstance(gearset, Gearset):
        raise TypeError(f"gearset must be a Gearset, got {type(gearset).__name__}")
    if not isinstance(speeds, Speeds):
        raise TypeError(f"speeds must be a Speeds, got {type(speeds).__name__}")
    if errors is not None and not isinstance(errors, ShaftHoleErrors):
        raise TypeError(f"errors must be a ShaftHoleErrors or None, got {type(errors).__name__}")
    clock = _as_clock(profile, speeds)
    w, z = gauge_rates(gearset, speeds, gear)
    theta = as_float(tooth_angle, "tooth_angle")
    t_start = as_float(t_start, "t_start")
    t_stop = as_float(t_stop, "t_stop")
    if t_stop <= t_start or w == 0.0:
        return EngagementEvents.empty()
    if errors is not None and errors.sample_shape(gearset.n_planets) != ():
        raise ValueError(f"errors must be one realisation (no sample dimensions), got sample "
                         f"shape {errors.sample_shape(gearset.n_planets)}")
    use_err = errors is not None and not errors.is_zero
    which = 0 if gear == "sun" else 1
    tau_a, tau_b = (float(x) for x in clock.tau(np.array([t_start, t_stop])))
    psi = gearset.angles
    n_p = psi.size
    # bound on the angle deviation of the line of centres: asin((e_g + e_p) / R_c) < pi/2
    margin = 0.0
    if use_err:
        e_tot = (float(np.max(errors.e_sun if gear == "sun" else errors.e_ring))
                 + float(np.max(errors.e_planet)))
        margin = math.asin(min(1.0, e_tot / gearset.carrier_radius)) + 1e-9
    # candidate k per planet: tau0 = (psi_n + 2 pi k - theta) / w within the window +- margin
    lo = min(w * tau_a, w * tau_b) + theta - margin
    hi = max(w * tau_a, w * tau_b) + theta + margin
    ks, ps = [], []
    for n in range(n_p):
        k0 = math.floor((lo - psi[n]) / TWO_PI)
        k1 = math.ceil((hi - psi[n]) / TWO_PI)
        k = np.arange(k0, k1 + 1, dtype=np.int64)
        ks.append(k)
        ps.append(np.full(k.size, n, dtype=np.int64))
    k = np.concatenate(ks)
    pidx = np.concatenate(ps)
    target = psi[pidx] + TWO_PI * k - theta          # unreduced angle w tau0
    tau = target / w
    if use_err:
        # chord iteration on r(tau) = reduce(theta + w tau - psi_n(tau)), slope w - psi'
        h = 1e-6 * TWO_PI / abs(w)
        dpsi = (_psi_planet(tau + h, pidx, gearset, speeds, errors, which)
                - _psi_planet(tau - h, pidx, gearset, speeds, errors, which)) / (2.0 * h)
        slope = w - dpsi
        if np.any(np.abs(dpsi) >= 0.5 * abs(w)):
            raise ValueError(f"shaft hole errors too large for the {gear} gauge: the line of "
                             "centres turns at more than half the gear's relative speed, so "
                             "engagements are not unique per revolution")
        for it in range(max_iter):
            rot = rotation_angle(w, tau, theta)           # reduced theta + w tau
            r = _reduce(rot - _psi_planet(tau, pidx, gearset, speeds, errors, which))
            step = r / slope
            tau = tau - step
            if np.all(np.abs(step) <= tol * np.maximum(np.abs(tau), TWO_PI / abs(w))):
                break
        else:
            raise ValueError(f"engagement iteration did not converge in {max_iter} iterations "
                             f"(largest step {float(np.max(np.abs(step)))!r} s)")
    keep = (tau >= tau_a) & (tau < tau_b)
    tau, pidx, k = tau[keep], pidx[keep], k[keep]
    t = clock.time_of(tau)
    order = np.argsort(t, kind="stable")
    t, tau, pidx, k = t[order], tau[order], pidx[order], k[order]
    period = TWO_PI / (z * abs(w) * clock.rate(t, tau))
    return EngagementEvents(time=t, tau=tau, planet=pidx + 1, revolution=k, mesh_period=period)


def event_times_for_angles(w: float, angle0: float, t_start: float, t_stop: float, *,
                           width: float = 0.0, profile: SpeedProfile | SpeedClock | None = None,
                           speeds: Speeds | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Times at which a member turning at ``w s(t)`` passes ``angle0`` (mod 2 pi), and when it
    has turned a further ``width`` revolutions past it.

    Used for the once-per-revolution tacho (the carrier's absolute angle ``w_c tau``).

    Parameters
    ----------
    w : float
        Nominal speed [rad/s] (non-zero).
    angle0 : float
        Angle of the mark [rad].
    t_start, t_stop : float
        Window of times from the first sample [s]; passes with start in the window are kept.
    width : float
        Extra rotation after the pass [rev], >= 0: the mark spans a fixed angle, so its
        duration follows the local speed.
    profile : SpeedProfile or SpeedClock, optional
        Speed fluctuation (None: constant speed).
    speeds : Speeds, optional
        Nominal speeds, needed to bind a profile with shaft-locked ripple (a SpeedClock
        carries its own).

    Returns
    -------
    start, stop : ndarray
        Times [s] of the pass and of the end of the mark, sorted.
    """
    if isinstance(profile, SpeedClock):
        clock = profile
    elif profile is None or isinstance(profile, SpeedProfile):
        profile = SpeedProfile() if profile is None else profile
        if profile.has_shaft:
            if speeds is None:
                raise ValueError("event_times_for_angles: the profile has shaft-locked ripple; "
                                 "pass speeds= (the nominal Speeds) or a SpeedClock")
            clock = SpeedClock(profile, speeds)
        else:
            clock = SpeedClock(profile, Speeds(0.0, 0.0, 0.0) if speeds is None else speeds)
    else:
        raise TypeError(f"profile must be a SpeedProfile, a SpeedClock or None, got "
                        f"{type(profile).__name__}")
    w = as_float(w, "w")
    if w == 0.0:
        e = np.empty(0)
        return e, e.copy()
    width = as_nonnegative(width, "width")
    tau_a, tau_b = (float(x) for x in clock.tau(np.array([as_float(t_start, "t_start"),
                                                          as_float(t_stop, "t_stop")])))
    lo, hi = sorted((w * tau_a, w * tau_b))
    sgn = 1.0 if w > 0 else -1.0
    m = np.arange(math.floor((lo - angle0) / TWO_PI) - 1, math.ceil((hi - angle0) / TWO_PI) + 2)
    tau0 = (angle0 + TWO_PI * m) / w
    tau1 = (angle0 + sgn * TWO_PI * width + TWO_PI * m) / w
    keep = (tau0 >= tau_a) & (tau0 < tau_b)
    tau0, tau1 = np.sort(tau0[keep]), np.sort(tau1[keep])
    return clock.time_of(tau0), clock.time_of(tau1)
