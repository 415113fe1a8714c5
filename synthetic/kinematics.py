"""Rotation angles under speed fluctuation and the exact engagement times of gauged teeth.

Speed profile
-------------
The rig runs at nominal speeds ``Speeds`` (sun, carrier, planet, ring) [rad/s] times a common
speed factor ``s(t)`` [-]::

    s(t) = 1 + r t + sum_i a_i sin(2 pi f_i t + phi_i)

(``r`` a ramp rate [1/s], ``a_i, f_i, phi_i`` slow ripple components; t from the first
sample). One factor for every member is what a rigid gear train imposes: all speeds are tied
by the tooth counts (Willis), so torsional wind-up aside, a speed change of the drive moves
every member in proportion. Every rotation angle is then ``w tau(t)`` with the *angle time*

    tau(t) = int_0^t s dt' = t + r t^2 / 2 + sum_i a_i / (2 pi f_i) (cos phi_i - cos(2 pi f_i t + phi_i))

so the actual relative rotation angles are ``w_sc tau``, ``w_pc tau``, ``w_rc tau``. The
shaft-hole-error geometry of :func:`pipeline.models.mesh_phasing.mesh_angles`, which turns
each offset by ``w t``, is therefore evaluated at ``tau`` instead of ``t``: that *is* the
geometry as a function of the actual rotation angles, with no second implementation of it
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
with that planet. The strain pulse (:mod:`synthetic.gauges`) is defined relative to it.

The equation is solved per event in angle time: from the ideal root
``tau_0 = (psi_n + 2 pi k - theta) / w`` by a chord (Newton) iteration on the reduced angle
residual, with the slope ``w - dpsi/dtau`` estimated once by central differences; the error
terms turn slowly (|dpsi/dtau| << |w|) so a few iterations reach ~1e-15 relative. The
wall-clock time follows by inverting ``tau(t)`` with Newton's method.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pipeline.models.gearset import Gearset, Speeds
from pipeline.models.mesh_phasing import ShaftHoleErrors, mesh_angles, rotation_angle
from pipeline.validate import as_float, as_nonnegative

__all__ = ["SpeedProfile", "EngagementEvents", "engagement_events", "event_times_for_angles",
           "gauge_rates"]

TWO_PI = 2.0 * math.pi
_CHUNK = 50_000


def _reduce(x):
    return x - TWO_PI * np.rint(x / TWO_PI)


@dataclass(frozen=True)
class SpeedProfile:
    """Common speed factor ``s(t) = 1 + ramp_rate t + sum a_i sin(2 pi f_i t + phi_i)`` [-].

    Parameters
    ----------
    ramp_rate : float
        Linear speed change per second, relative to nominal [1/s] (0.001 = +0.1 %/s).
    ripple : tuple of (amplitude, frequency, phase)
        Slow speed ripple components: relative amplitude a_i [-], frequency f_i [Hz] (> 0),
        phase phi_i [rad].
    """

    ramp_rate: float = 0.0
    ripple: tuple = ()

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

    @property
    def is_constant(self) -> bool:
        """True when s(t) = 1 (no ramp, no ripple)."""
        return self.ramp_rate == 0.0 and all(a == 0.0 for a, _, _ in self.ripple)

    def check(self, duration: float) -> None:
        """ValueError unless s(t) > 0 on [0, duration] (a conservative bound)."""
        low = 1.0 + min(0.0, self.ramp_rate * float(duration)) - sum(a for a, _, _ in self.ripple)
        if low <= 0.05:
            raise ValueError(f"speed profile may reach s(t) <= 0.05 within {duration!r} s "
                             f"(ramp_rate={self.ramp_rate!r} 1/s, ripple={self.ripple!r}); the "
                             "rig would stop or reverse")

    def factor(self, t) -> np.ndarray:
        """Speed factor s(t) [-] at times t [s] from the first sample."""
        t = np.asarray(t, dtype=np.float64)
        s = 1.0 + self.ramp_rate * t
        for a, f, ph in self.ripple:
            if a:
                s = s + a * np.sin(TWO_PI * np.mod(f * t, 1.0) + ph)
        return s

    def tau(self, t) -> np.ndarray:
        """Angle time tau(t) = int_0^t s dt' [s]."""
        t = np.asarray(t, dtype=np.float64)
        out = t + 0.5 * self.ramp_rate * t * t
        for a, f, ph in self.ripple:
            if a:
                out = out + a / (TWO_PI * f) * (math.cos(ph) - np.cos(TWO_PI * np.mod(f * t, 1.0) + ph))
        return out

    def time_of(self, tau) -> np.ndarray:
        """Inverse of :meth:`tau`: times t [s] with tau(t) = ``tau`` (Newton, ~1 ulp)."""
        tau = np.asarray(tau, dtype=np.float64)
        if self.is_constant or tau.size == 0:
            return tau.copy()
        r = self.ramp_rate
        # start from the ramp-only solution, then Newton on the full tau(t)
        if r != 0.0:
            disc = np.maximum(1.0 + 2.0 * r * tau, 0.0)
            t = 2.0 * tau / (1.0 + np.sqrt(disc))
        else:
            t = tau.copy()
        for _ in range(60):
            dt = (self.tau(t) - tau) / self.factor(t)
            t = t - dt
            if np.all(np.abs(dt) <= 4e-16 * np.maximum(1.0, np.abs(t))):
                break
        else:
            raise ValueError("could not invert the speed profile tau(t) (speed factor too close to 0?)")
        return t

    def to_dict(self) -> dict:
        return {"ramp_rate": self.ramp_rate,
                "ripple": [{"amplitude": a, "frequency": f, "phase": p} for a, f, p in self.ripple]}

    @classmethod
    def from_dict(cls, d: dict) -> "SpeedProfile":
        return cls(ramp_rate=d.get("ramp_rate", 0.0), ripple=tuple(d.get("ripple", ())))


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
        Local mesh period ``2 pi / (Z |w| s(t))`` at the engagement [s].
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
    profile : SpeedProfile, optional
        Speed fluctuation (None: constant nominal speed).
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
    profile = SpeedProfile() if profile is None else profile
    if not isinstance(profile, SpeedProfile):
        raise TypeError(f"profile must be a SpeedProfile or None, got {type(profile).__name__}")
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
    tau_a, tau_b = (float(x) for x in profile.tau(np.array([t_start, t_stop])))
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
    t = profile.time_of(tau)
    order = np.argsort(t, kind="stable")
    t, tau, pidx, k = t[order], tau[order], pidx[order], k[order]
    period = TWO_PI / (z * abs(w) * profile.factor(t))
    return EngagementEvents(time=t, tau=tau, planet=pidx + 1, revolution=k, mesh_period=period)


def event_times_for_angles(w: float, angle0: float, t_start: float, t_stop: float, *,
                           width: float = 0.0, profile: SpeedProfile | None = None
                           ) -> tuple[np.ndarray, np.ndarray]:
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
        Extra rotation after the pass [rev], >= 0.
    profile : SpeedProfile, optional

    Returns
    -------
    start, stop : ndarray
        Times [s] of the pass and of the end of the mark, sorted.
    """
    profile = SpeedProfile() if profile is None else profile
    w = as_float(w, "w")
    if w == 0.0:
        e = np.empty(0)
        return e, e.copy()
    width = as_nonnegative(width, "width")
    tau_a, tau_b = (float(x) for x in profile.tau(np.array([as_float(t_start, "t_start"),
                                                            as_float(t_stop, "t_stop")])))
    lo, hi = sorted((w * tau_a, w * tau_b))
    sgn = 1.0 if w > 0 else -1.0
    m = np.arange(math.floor((lo - angle0) / TWO_PI) - 1, math.ceil((hi - angle0) / TWO_PI) + 2)
    tau0 = (angle0 + TWO_PI * m) / w
    tau1 = (angle0 + sgn * TWO_PI * width + TWO_PI * m) / w
    keep = (tau0 >= tau_a) & (tau0 < tau_b)
    tau0, tau1 = np.sort(tau0[keep]), np.sort(tau1[keep])
    return profile.time_of(tau0), profile.time_of(tau1)
