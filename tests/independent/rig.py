"""Independent reference rig: planetary-gear strain recordings with their exact truth, as NI TDMS.

Why this exists
---------------
meshphase's own generator (``synthetic/``) is written by the same people as the pipeline and
may share its blind spots (an outside tester with a third-party generator found the measured
phasing 20-50x off under an ordinary 1 % drive ripple). This module is a second, independent
implementation of the physics the models restate (ideal phasing, the shaft-hole error
model, the engagement condition; docs/method.md) and of the seed 000 gearset. It imports
nothing from ``pipeline`` or ``synthetic`` -- only numpy, scipy, nptdms and the standard
library -- and deliberately solves things another way:

* the rig's motion is **integrated numerically** (``scipy.integrate.solve_ivp``, DOP853,
  ``rtol = atol = 1e-12``, dense output), never taken from a closed form;
* engagement instants are **roots of a geometric condition** found with
  ``scipy.optimize.brentq`` (``xtol = 1e-13`` s), bracketed on a grid of the integrated angle;
* the truth phasing is counted in **mesh cycles of integrated angle**, not in time;
* pulses are functions of the gauged gear's **angle** since engagement (they stretch with the
  local speed), with a shape of our own (:func:`pulse_shape`);
* files are written block by block through npTDMS's public writer, in NI-DAQmx-like segments.

Conventions (SI inside: m, rad, s, strain in m/m)
-------------------------------------------------
*Frames.* Angles are counter-clockwise (ccw) positive. The carrier frame turns with the
carrier; planet ``n`` (1-based in files and truth, 0-based in arrays) sits at carrier angle
``psi_n`` with ``psi_1 = 0``, numbered ccw (``0 = psi_1 < psi_2 < ... < 2 pi``). At ``t = 0``
every member angle is 0, so the carrier and ground frames coincide at the first sample.

*Kinematics.* With one member fixed, every angle is proportional to the mesh angle
``Phi = Z_s theta_sc = -Z_r theta_rc = -Z_p theta_pc`` (relative to the carrier; sun-planet is
an external mesh, planet-ring an internal one). Ring fixed (default):
``theta_sc = (Z_r/Z_s) theta_c``, ``theta_s = theta_c + theta_sc``,
``theta_pc = -(Z_r/Z_p) theta_c``, ``theta_rc = -theta_c``. :class:`Kinematics` holds the
coefficients ``d theta_member / d Phi``; members are ``"carrier"``, ``"sun"``, ``"ring"``
(absolute angles), ``"sun_rel"``, ``"ring_rel"`` and ``"planet"`` (planet spin relative to the
carrier). ``dPhi/dt > 0`` means clockwise planets (Parker's "clockwise" case); a negative
speed gives counter-clockwise planets.

*Speed model.* The reference member is the carrier (the sun when the carrier is fixed)::

    d theta_ref / dt = w_ref0 * g(t) * (1 + sum_j a_j sin(m_j theta_member_j(t) + phi_j))

``g(t) = 1 + ramp (t / T - 1/2)`` on ``[0, T]`` (``T`` the record length; constant outside),
so ``ramp`` is the total relative speed change over the record and the record-average factor
is 1. Ripple terms are locked to a shaft angle (drive and eccentricity ripple follow the
shaft): order ``m_j`` per revolution of ``member_j``. The ODE is integrated piecewise
(``[0, T]``, after ``T``, and backwards before 0 for pulses that straddle the first sample).

*Shaft-hole errors* (spec section 2, :class:`HoleErrors`). Each offset turns with its body
relative to the carrier, as 2-D vectors (complex numbers) in the carrier frame::

    O_sa  = e_s exp(i (kappa_s + theta_sc))                     actual sun centre
    O_ra  = e_r exp(i (kappa_r + theta_rc))                     actual ring centre
    O_pan = R_c exp(i psi_n) + e_pn exp(i (psi_n + kappa_pn + theta_pc))

``kappa_s``, ``kappa_r`` are measured from the carrier x axis (planet 1's direction),
``kappa_pn`` from planet n's outward radial line, all ccw at ``t = 0``. The sun-mesh line of
centres points along ``arg(O_pan - O_sa)``, the ring-mesh one along ``arg(O_pan - O_ra)``.
Relation to the seed's scalar formulas: with ``beta = kappa_pn + theta_pc`` the seed's
``|O_si O_pan|`` and ``dpsi_epn`` are this geometry with the seed angle ``w_pc t + kappa_pn``
equal to ``pi - beta`` (the seed measures it from the inward line, clockwise); the seed's
per-planet sun error ``e_sn`` is here one sun offset seen by every planet.

*Engagement.* A gauge at the root of a sun tooth (carrier-frame angle ``a_s0`` at ``t = 0``)
meets planet n when the tooth's direction about the actual sun centre, ``a_s0 + theta_sc(t)``,
equals ``arg(O_pan - O_sa)`` (mod 2 pi); a ring tooth gauge at ground angle ``a_r0`` likewise
with ``a_r0 + theta_rc(t)`` and ``O_ra``. That instant is the middle of the tooth's contact
(the tooth on the line of centres); it is what the truth calls the engagement instant.

*Truth phasing per pass.* A pass of gauge j starts at planet 1's engagement ``t_1`` and runs
one relative revolution (to planet 1's next engagement); planet n's instant ``t_n`` is its
engagement inside the pass. ``gamma_jn = frac(Z_j |theta_jc(t_n) - theta_jc(t_1)| / 2 pi)``:
the mesh cycles the gauged gear turned relative to the carrier between meeting planet 1 and
planet n, counted forward in time. Error-free and steady this equals Parker's ideal
(:func:`parker_phasing`; ``gamma_sn = frac(+Z_s psi_n / 2 pi)``,
``gamma_rn = frac(-Z_r psi_n / 2 pi)`` for clockwise planets, both signs flipped for ccw).
Values are in [0, 1); compare them circularly (0.9999999999 is 0).

*Pulses.* ``u`` = mesh cycles turned by the gauged gear relative to the carrier since the
engagement (``u = Z_j |theta_jc(t) - theta_jc(t_e)| / 2 pi``, signed positive after it),
evaluated through the integrated angle at every sample; strain = peak * LS_n *
:func:`pulse_shape` (u). So a pulse lasts a fixed angle, and its length in samples scales
with 1 / local speed.

*Tacho.* A carrier once-per-revolution TTL channel (0 / 5 V): high while
``s (theta_c - theta_edge) mod 2 pi < key_width`` (``s`` the carrier's sense of rotation), so
its rising edge is where the absolute carrier angle equals ``theta_edge`` (mod 2 pi) in
either sense. Geometry, in the ground frame of ``t = 0``: with the pick-up at ground angle 0,
the key sits on the carrier at ``-theta_edge`` relative to planet 1 (reported as
``key_carrier_angle``); at a rising edge planet 1 sits at ground angle ``theta_edge``; the ring gauge sits at ground angle ``a_r0``; so measured from
planet 1's position at the tacho mark (meshphase's ``gauge_angle`` convention) the ring gauge
is at ``a_r0 - theta_edge`` (reported as ``ring_gauge_angle_from_tacho``).

*Speeds a user types.* The rig's carrier speed follows from the fixed ring exactly,
``n_c = n_s Z_s / (Z_s + Z_r)`` = 18.19 * 25 / 112 = 4.0603 r/min for the seed's rig; a user's
scene file will say 4.06 r/min (what the outside tester did). The truth holds both:
``speeds["carrier_rpm"]`` (exact) and ``speeds["carrier_rpm_scene"]`` (rounded to 2 decimals).
(The seed's text says "carrier 1.06 r/min", inconsistent with 18.19 r/min and 25/87 teeth;
4.06 follows from the geometry.)

NI TDMS output (:func:`write_rig_tdms`)
---------------------------------------
One group (default ``"Rig"``), channels named like a rig would (``"SG_sun_T3"``,
``"SG_ring_T1"``, ``"Tacho OPR"``), properties ``wf_increment = 1/fs``, ``wf_start_time``
(numpy datetime64, UTC, microseconds), ``wf_start_offset = 0``, ``wf_samples`` (samples per
channel per segment, as a LabVIEW waveform write sets it -- *not* the channel length),
``wf_xname``, ``wf_xunit_string``, ``unit_string`` (``"Strain"`` / ``"V"``),
``NI_ChannelName``, ``NI_UnitDescription``. Properties are written once, in the first
segment, as NI loggers do. With ``storage="int"`` the quantised ADC counts are stored as
int16 (16 bit) or int32 (24 bit) with an NI linear scale (``NI_Number_Of_Scales = 1``,
``NI_Scale[0]_Scale_Type = "Linear"``, slope = 1 LSB, intercept 0, input source raw).

What npTDMS's public writer (``TdmsWriter.write_segment``) can and cannot do, so what the
files are: every segment is written with the table of contents
``kTocMetaData | kTocRawData | kTocNewObjList`` and a full object list with a raw-data index
per channel (NI-DAQmx reuses the previous object list and writes only raw data after the
first segment); channel data are always **non-interleaved** (``interleaved=True`` is refused
with ValueError); DAQmx raw data (``kTocDAQmxRawData`` with format-changing scalers) cannot be
written. Segment size is free (1000 samples per channel per segment by default, 512 works).

Streaming: the motion (a dense ODE solution of a few hundred polynomial pieces), the
engagement instants and one render chunk (8192 samples per channel by default, in whole
segments) are all that is held; 10 min x 3 channels at 5120 Hz never holds the recording.

Presets (:data:`PRESETS`, :func:`make_preset_tdms`)
---------------------------------------------------
Seed rig 25/87/29, 4 equally spaced planets, ring fixed, sun 18.19 r/min, 20 dB, tacho on,
unless the row says otherwise. "1 % ripple" is ``a = 0.01`` once per carrier revolution.

============================  ====================================================
``steady``                    no ripple, no ramp
``ripple1_carrier``           1 % carrier-rate ripple
``ripple3_carrier``           3 % carrier-rate ripple
``ripple1_ramp10``            1 % ripple + 10 % ramp up over the record
``five_planets_ripple1``      Z 25/85/30, 5 planets (R_c 110 mm), 1 % ripple
``ripple1_sun``               1 % ripple once per sun revolution (instead of carrier)
``ramp_down``                 1 % ripple + 10 % ramp down
``ccw``                       1 % ripple, sun at -18.19 r/min (counter-clockwise planets)
``unequal3``                  1 % ripple, 3 planets at assembly positions p = 0, 37, 75
``no_tacho``                  1 % ripple, no tacho channel
``snr10``                     1 % ripple, 10 dB
``hole_errors_case1``         seed 000 Table 2 case 1 errors (0.2 mm; 4, 60, 20 deg), steady
``planet_ripple1_encoder``    1 % ripple at the planet spin rate, 60-pulse sun-shaft encoder
============================  ====================================================

The first five are the outside tester's table. Without shaft-hole errors the truth phasing
of every pass is Parker's ideal whatever the ripple or ramp (phasing is geometry; speed
changes move the instants, not gamma), so any deviation a pipeline reports on those
presets is the pipeline's error.

Public API
----------
:class:`Gearset`, :class:`Kinematics` / :func:`nominal_kinematics`, :class:`RippleTerm`,
:class:`SpeedProfile`, :class:`Motion` / :func:`integrate_motion`, :class:`HoleErrors`,
:func:`line_of_centres`, :func:`engagement_instants`, :func:`engagement_residual`,
:func:`pass_truth`, :func:`parker_phasing`, :func:`pulse_shape`, :class:`RigConfig`,
:class:`Rig`, :class:`RigTruth`, :func:`write_rig_tdms`, :func:`make_rig_config`,
:func:`make_rig_tdms`, :data:`PRESETS`, :func:`preset_config`, :func:`make_preset_tdms`,
:func:`truth_path`, :func:`read_truth`.

Example
-------
>>> truth = make_preset_tdms("rec.tdms", "ripple1_carrier", minutes=2)   # doctest: +SKIP
>>> truth.passes["SG_sun_T3"][0]["gamma"]                                 # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses
import json
import math
import numbers
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, Sequence

import numpy as np
from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

__all__ = [
    "Gearset", "Kinematics", "nominal_kinematics", "RippleTerm", "SpeedProfile", "Motion",
    "integrate_motion", "HoleErrors", "line_of_centres", "engagement_instants",
    "engagement_residual", "pass_truth", "parker_phasing", "pulse_shape", "PULSE_SUPPORT",
    "RigConfig", "Rig", "RigTruth", "write_rig_tdms", "make_rig_config", "make_rig_tdms", "PRESETS",
    "preset_config", "make_preset_tdms", "truth_path", "read_truth", "MEMBERS", "FIXED_MEMBERS",
]

TWO_PI = 2.0 * math.pi
RPM = TWO_PI / 60.0  #: 1 r/min in rad/s
MEMBERS = ("carrier", "sun", "ring", "sun_rel", "ring_rel", "planet")
FIXED_MEMBERS = ("ring", "sun", "carrier")
ODE_RTOL = 1e-12
ODE_ATOL = 1e-12  # [rad]
ROOT_XTOL = 1e-13  # [s]


# ----------------------------------------------------------------------------- validation
def _real(name: str, v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, numbers.Real):
        raise TypeError(f"{name} must be a real number, got {type(v).__name__} {v!r}")
    f = float(v)
    if not math.isfinite(f):
        raise ValueError(f"{name} must be finite, got {v!r}")
    return f


def _positive(name: str, v: Any) -> float:
    f = _real(name, v)
    if f <= 0:
        raise ValueError(f"{name} must be > 0, got {v!r}")
    return f


def _nonneg(name: str, v: Any) -> float:
    f = _real(name, v)
    if f < 0:
        raise ValueError(f"{name} must be >= 0, got {v!r}")
    return f


def _int(name: str, v: Any, minimum: int | None = None) -> int:
    if isinstance(v, bool) or not isinstance(v, numbers.Integral):
        raise TypeError(f"{name} must be an integer, got {type(v).__name__} {v!r}")
    i = int(v)
    if minimum is not None and i < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {v!r}")
    return i


def _choice(name: str, v: Any, options: Sequence[str]) -> str:
    if not isinstance(v, str):
        raise TypeError(f"{name} must be a string, one of {list(options)}, got {type(v).__name__} {v!r}")
    if v not in options:
        raise ValueError(f"{name} must be one of {list(options)}, got {v!r}")
    return v


def _real_tuple(name: str, v: Any) -> tuple[float, ...]:
    if isinstance(v, (str, bytes)) or not isinstance(v, (Sequence, np.ndarray)):
        raise TypeError(f"{name} must be a sequence of numbers, got {type(v).__name__} {v!r}")
    return tuple(_real(f"{name}[{i}]", x) for i, x in enumerate(v))


def _wrap(x):
    """Angle(s) wrapped to [-pi, pi) [rad]."""
    return np.mod(np.asarray(x, dtype=float) + math.pi, TWO_PI) - math.pi


# ----------------------------------------------------------------------------- gearset
@dataclass(frozen=True)
class Gearset:
    """Tooth counts and planet layout of a single-pinion planetary gearset.

    Parameters
    ----------
    z_sun, z_ring, z_planet : int
        Tooth counts Z_s, Z_r, Z_p [-].
    planet_angles : sequence of float
        Planet angles psi_n in the carrier frame [rad], ccw positive, planet 1 first at 0,
        strictly increasing below 2 pi.
    carrier_radius : float
        Carrier radius R_c [m] (sun-to-planet centre distance); only the shaft-hole error
        geometry uses it. Default 0.1125 m (seed 000, Table 1).
    """

    z_sun: int
    z_ring: int
    z_planet: int
    planet_angles: tuple[float, ...]
    carrier_radius: float = 0.1125

    def __post_init__(self):
        for k in ("z_sun", "z_ring", "z_planet"):
            object.__setattr__(self, k, _int(k, getattr(self, k), minimum=3))
        if self.z_ring <= self.z_sun:
            raise ValueError(f"z_ring must exceed z_sun, got z_ring={self.z_ring!r}, z_sun={self.z_sun!r}")
        psi = _real_tuple("planet_angles", self.planet_angles)
        if not psi:
            raise ValueError("planet_angles must hold at least one planet, got an empty sequence")
        if psi[0] != 0.0:
            raise ValueError(f"planet_angles[0] (planet 1) must be 0, got {psi[0]!r}")
        if any(b <= a for a, b in zip(psi, psi[1:])) or psi[-1] >= TWO_PI:
            raise ValueError(f"planet_angles must increase strictly within [0, 2 pi), got {psi!r}")
        object.__setattr__(self, "planet_angles", psi)
        object.__setattr__(self, "carrier_radius", _positive("carrier_radius", self.carrier_radius))

    @classmethod
    def equally_spaced(cls, z_sun: int, z_ring: int, z_planet: int, n_planets: int,
                       carrier_radius: float = 0.1125) -> "Gearset":
        """Gearset with ``n_planets`` planets at ``psi_n = 2 pi (n-1) / N`` [rad]."""
        n = _int("n_planets", n_planets, minimum=1)
        return cls(z_sun, z_ring, z_planet, tuple(TWO_PI * k / n for k in range(n)), carrier_radius)

    @classmethod
    def from_assembly_positions(cls, z_sun: int, z_ring: int, z_planet: int, positions: Sequence[int],
                                carrier_radius: float = 0.1125) -> "Gearset":
        """Gearset with planets at assemblable angles ``psi_n = 2 pi p_n / (Z_s + Z_r)`` [rad].

        ``positions`` are the integers p_n (p_1 = 0), strictly increasing below Z_s + Z_r.
        """
        if isinstance(positions, (str, bytes)) or not isinstance(positions, (Sequence, np.ndarray)):
            raise TypeError(f"positions must be a sequence of integers, got {type(positions).__name__} {positions!r}")
        p = [_int(f"positions[{i}]", x) for i, x in enumerate(positions)]
        zs, zr = _int("z_sun", z_sun, 3), _int("z_ring", z_ring, 3)
        if p and (p[-1] >= zs + zr):
            raise ValueError(f"positions must be < Z_s + Z_r = {zs + zr}, got {p!r}")
        return cls(zs, zr, z_planet, tuple(TWO_PI * k / (zs + zr) for k in p), carrier_radius)

    @property
    def n_planets(self) -> int:
        """Number of planets N [-]."""
        return len(self.planet_angles)

    def is_assemblable(self, tol: float = 1e-9) -> bool:
        """True when every ``(Z_s + Z_r) psi_n / 2 pi`` is an integer (within ``tol``) [-]."""
        x = np.asarray(self.planet_angles) * (self.z_sun + self.z_ring) / TWO_PI
        return bool(np.all(np.abs(x - np.round(x)) <= tol))


# ----------------------------------------------------------------------------- kinematics
@dataclass(frozen=True)
class Kinematics:
    """Rigid kinematics of a planetary gearset with one member fixed.

    Every angle is ``coef(member) * Phi`` with the mesh angle ``Phi = Z_s theta_sc``.

    Parameters
    ----------
    gearset : Gearset
    fixed : {"ring", "sun", "carrier"}
        The member held still.
    mesh_rate : float
        Nominal d Phi / dt [rad/s] (``2 pi`` times the mesh frequency; sign = sense:
        positive for clockwise planets).
    """

    gearset: Gearset
    fixed: str
    mesh_rate: float

    def __post_init__(self):
        if not isinstance(self.gearset, Gearset):
            raise TypeError(f"gearset must be a Gearset, got {type(self.gearset).__name__}")
        _choice("fixed", self.fixed, FIXED_MEMBERS)
        r = _real("mesh_rate", self.mesh_rate)
        if r == 0.0:
            raise ValueError("mesh_rate must be non-zero (the rig must turn), got 0")
        object.__setattr__(self, "mesh_rate", r)

    def coef(self, member: str) -> float:
        """d theta_member / d Phi [-] for a member of :data:`MEMBERS`."""
        _choice("member", member, MEMBERS)
        g = self.gearset
        c_car = {"ring": 1.0 / g.z_ring, "sun": -1.0 / g.z_sun, "carrier": 0.0}[self.fixed]
        return {
            "sun_rel": 1.0 / g.z_sun,
            "ring_rel": -1.0 / g.z_ring,
            "planet": -1.0 / g.z_planet,
            "carrier": c_car,
            "sun": 0.0 if self.fixed == "sun" else c_car + 1.0 / g.z_sun,
            "ring": 0.0 if self.fixed == "ring" else c_car - 1.0 / g.z_ring,
        }[member]

    @property
    def reference(self) -> str:
        """The integrated member: the carrier, or the sun when the carrier is fixed."""
        return "sun" if self.fixed == "carrier" else "carrier"

    def ratio(self, member: str) -> float:
        """d theta_member / d theta_ref [-] (exactly 1.0 for the reference itself)."""
        if member == self.reference:
            return 1.0
        return self.coef(member) / self.coef(self.reference)

    def speed(self, member: str) -> float:
        """Nominal angular speed of a member [rad/s]."""
        return self.coef(member) * self.mesh_rate

    def rpm(self, member: str) -> float:
        """Nominal speed of a member [r/min]."""
        return self.speed(member) / RPM

    @property
    def sense(self) -> int:
        """+1 when Phi increases (clockwise planets), -1 otherwise."""
        return 1 if self.mesh_rate > 0 else -1

    @property
    def planet_rotation(self) -> str:
        """``"cw"`` or ``"ccw"``: the planets' sense of rotation (Parker's sign convention)."""
        return "cw" if self.sense > 0 else "ccw"

    @property
    def mesh_frequency(self) -> float:
        """Nominal mesh frequency |d Phi/dt| / 2 pi [Hz]."""
        return abs(self.mesh_rate) / TWO_PI


def nominal_kinematics(gearset: Gearset, fixed: str = "ring", *, sun_rpm: float | None = None,
                       carrier_rpm: float | None = None, ring_rpm: float | None = None) -> Kinematics:
    """Kinematics from one nominal absolute speed.

    Parameters
    ----------
    gearset : Gearset
    fixed : {"ring", "sun", "carrier"}
    sun_rpm, carrier_rpm, ring_rpm : float, optional
        Exactly one, for a member that is not fixed [r/min]; sign = sense (ccw positive).

    Returns
    -------
    Kinematics
    """
    given = {m: v for m, v in (("sun", sun_rpm), ("carrier", carrier_rpm), ("ring", ring_rpm)) if v is not None}
    if len(given) != 1:
        raise ValueError(f"give exactly one of sun_rpm, carrier_rpm, ring_rpm, got {sorted(given) or 'none'}")
    (member, rpm), = given.items()
    rpm = _real(f"{member}_rpm", rpm)
    _choice("fixed", fixed, FIXED_MEMBERS)
    if member == fixed:
        raise ValueError(f"{member}_rpm given for the fixed member ({fixed!r}); give a turning member's speed")
    probe = Kinematics(gearset, fixed, 1.0)
    return Kinematics(gearset, fixed, rpm * RPM / probe.coef(member))


# ----------------------------------------------------------------------------- speed model
@dataclass(frozen=True)
class RippleTerm:
    """One speed-ripple term ``a sin(m theta_member + phi)`` locked to a shaft angle.

    Parameters
    ----------
    amplitude : float
        a [-] (0.01 = 1 %).
    order : float
        m [per revolution of the member] (> 0; 1 = once per revolution).
    member : str
        One of :data:`MEMBERS` (not a fixed one).
    phase : float
        phi [rad].
    """

    amplitude: float
    order: float = 1.0
    member: str = "carrier"
    phase: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "amplitude", _real("amplitude", self.amplitude))
        object.__setattr__(self, "order", _positive("order", self.order))
        _choice("member", self.member, MEMBERS)
        object.__setattr__(self, "phase", _real("phase", self.phase))

    @classmethod
    def coerce(cls, v: Any) -> "RippleTerm":
        """A RippleTerm from itself, a mapping, or a tuple ``(amplitude, order, member[, phase])``."""
        if isinstance(v, cls):
            return v
        if isinstance(v, Mapping):
            return cls(**v)
        if isinstance(v, (tuple, list)):
            return cls(*v)
        raise TypeError(f"ripple term must be a RippleTerm, mapping or tuple, got {type(v).__name__} {v!r}")


@dataclass(frozen=True)
class SpeedProfile:
    """Slow ramp and shaft-locked ripple of the drive speed.

    Parameters
    ----------
    ripple : sequence of RippleTerm
        Ripple terms; sum of |a_j| must stay <= 0.5 (the speed never reverses).
    ramp : float
        Total relative speed change over ``[0, ramp_duration]`` [-], centred: ``g(t) = 1 +
        ramp (t / ramp_duration - 1/2)``, held constant outside; |ramp| < 1.
    ramp_duration : float
        T [s], normally the record length.
    """

    ripple: tuple[RippleTerm, ...] = ()
    ramp: float = 0.0
    ramp_duration: float = 1.0

    def __post_init__(self):
        if isinstance(self.ripple, (str, bytes)) or not isinstance(self.ripple, (Sequence, np.ndarray)):
            raise TypeError(f"ripple must be a sequence of ripple terms, got {type(self.ripple).__name__}")
        terms = tuple(RippleTerm.coerce(r) for r in self.ripple)
        if sum(abs(r.amplitude) for r in terms) > 0.5:
            raise ValueError(f"sum of ripple amplitudes must be <= 0.5, got {[r.amplitude for r in terms]!r}")
        object.__setattr__(self, "ripple", terms)
        r = _real("ramp", self.ramp)
        if abs(r) >= 1.0:
            raise ValueError(f"|ramp| must be < 1, got {self.ramp!r}")
        object.__setattr__(self, "ramp", r)
        object.__setattr__(self, "ramp_duration", _positive("ramp_duration", self.ramp_duration))

    def ramp_factor(self, t):
        """g(t) [-] (array in, array out)."""
        tc = np.clip(np.asarray(t, dtype=float), 0.0, self.ramp_duration)
        return 1.0 + self.ramp * (tc / self.ramp_duration - 0.5)


class Motion:
    """The rig's integrated motion: theta_ref(t) from the speed ODE, every other angle by kinematics.

    Integrated with ``solve_ivp`` (DOP853, rtol = atol = 1e-12, dense output) in pieces:
    ``[0, ramp_duration]`` and on to ``t_end`` forwards, ``[0, t_start]`` backwards, so the
    ramp's kinks sit on piece boundaries and ``theta_ref(0) = 0`` exactly. ``max_step`` is a
    quarter of the shortest nominal ripple period, so no ripple cycle is stepped over.

    Parameters
    ----------
    kinematics : Kinematics
    profile : SpeedProfile
    t_start, t_end : float
        Time span covered [s], ``t_start <= 0 < t_end``.
    """

    def __init__(self, kinematics: Kinematics, profile: SpeedProfile, t_start: float, t_end: float):
        if not isinstance(kinematics, Kinematics):
            raise TypeError(f"kinematics must be a Kinematics, got {type(kinematics).__name__}")
        if not isinstance(profile, SpeedProfile):
            raise TypeError(f"profile must be a SpeedProfile, got {type(profile).__name__}")
        t_start, t_end = _real("t_start", t_start), _real("t_end", t_end)
        if not (t_start <= 0.0 < t_end):
            raise ValueError(f"need t_start <= 0 < t_end, got t_start={t_start!r}, t_end={t_end!r}")
        self.kinematics, self.profile = kinematics, profile
        self.t_start, self.t_end = t_start, t_end
        kin = kinematics
        for r in profile.ripple:
            if kin.coef(r.member) == 0.0:
                raise ValueError(f"ripple member {r.member!r} does not turn (fixed {kin.fixed!r})")
        self.w_ref0 = kin.speed(kin.reference)  # [rad/s]
        a = np.array([r.amplitude for r in profile.ripple])
        mk = np.array([r.order * kin.ratio(r.member) for r in profile.ripple])
        ph = np.array([r.phase for r in profile.ripple])
        self._ripple = (a, mk, ph)
        if a.size:
            periods = TWO_PI / np.abs(mk * self.w_ref0)
            max_step = float(periods.min()) / 4.0
        else:
            max_step = np.inf
        self.max_step = max_step

        def rhs(t, y):
            return self.w_ref0 * self.profile.ramp_factor(t) * (1.0 + np.sum(a * np.sin(mk * y[0] + ph)))

        self._rhs = rhs
        T = profile.ramp_duration
        fwd_knots = [0.0] + ([T] if T < t_end else []) + [t_end]
        pieces = []
        y0 = 0.0
        for ta, tb in zip(fwd_knots, fwd_knots[1:]):
            sol = self._solve(ta, tb, y0)
            pieces.append((ta, tb, sol))
            y0 = float(sol.y[0, -1])
        back = []
        if t_start < 0.0:
            back.append((t_start, 0.0, self._solve(0.0, t_start, 0.0)))
        self._pieces = back + pieces
        self._lo = np.array([p[0] for p in self._pieces])
        self.n_steps = int(sum(p[2].t.size - 1 for p in self._pieces))

    def _solve(self, ta, tb, y0):
        sol = solve_ivp(self._rhs, (ta, tb), [y0], method="DOP853", rtol=ODE_RTOL, atol=ODE_ATOL,
                        dense_output=True, max_step=self.max_step)
        if not sol.success:
            raise RuntimeError(f"speed ODE failed on [{ta}, {tb}] s: {sol.message}")
        return sol

    def theta_ref(self, t) -> np.ndarray:
        """Integrated angle of the reference member [rad] at times t [s] (array in, array out)."""
        t = np.asarray(t, dtype=float)
        if t.size and (t.min() < self.t_start or t.max() > self.t_end):
            raise ValueError(f"t outside the integrated span [{self.t_start}, {self.t_end}] s: "
                             f"[{t.min()}, {t.max()}]")
        flat = t.ravel()
        if len(self._pieces) == 1:
            return _eval_dense(self._pieces[0][2].sol, flat).reshape(t.shape)
        out = np.empty_like(flat)
        idx = np.clip(np.searchsorted(self._lo, flat, side="right") - 1, 0, len(self._pieces) - 1)
        for k in np.unique(idx):
            m = idx == k
            out[m] = _eval_dense(self._pieces[k][2].sol, flat[m])
        return out.reshape(t.shape)

    def angle(self, member: str, t) -> np.ndarray:
        """Angle of a member (see :data:`MEMBERS`) [rad] at times t [s]."""
        return self.kinematics.ratio(member) * self.theta_ref(t)

    def mesh_cycles(self, t) -> np.ndarray:
        """Mesh cycles turned since t = 0, counted positive forward in time [-]:
        ``|Phi(t)| / 2 pi`` signed by the sense, = Z_s |theta_sc| / 2 pi = Z_r |theta_rc| / 2 pi."""
        kin = self.kinematics
        return (kin.sense / kin.coef(kin.reference) / TWO_PI) * self.theta_ref(t)

    def rate(self, member: str, t) -> np.ndarray:
        """Angular speed of a member [rad/s] at times t [s] (the ODE right-hand side)."""
        t = np.asarray(t, dtype=float)
        th = self.theta_ref(t)
        a, mk, ph = self._ripple
        rip = 1.0 + np.sum(a[:, None] * np.sin(mk[:, None] * th.ravel()[None, :] + ph[:, None]), axis=0)
        w = self.w_ref0 * self.profile.ramp_factor(t.ravel()) * rip
        return self.kinematics.ratio(member) * w.reshape(t.shape)


def _eval_dense(sol, t: np.ndarray) -> np.ndarray:
    """Evaluate a solve_ivp OdeSolution (1 state) at 1-D times t.

    Same segment choice as ``OdeSolution.__call__`` (the segment whose step ends at t, lower
    index first), but grouped with numpy: ``OdeSolution.__call__`` walks the points one by one
    in Python (``itertools.groupby``), ~0.3 us per point, which dominated block rendering.
    Uses only the public ``ts`` / ``interpolants`` of OdeSolution and DenseOutput.__call__.
    """
    ts = sol.ts
    n = len(sol.interpolants)
    asc = ts[-1] >= ts[0]
    seg = np.searchsorted(ts if asc else ts[::-1], t, side="left" if asc else "right") - 1
    np.clip(seg, 0, n - 1, out=seg)
    if not asc:
        seg = n - 1 - seg
    if t.size and seg.min() == seg.max():
        return sol.interpolants[int(seg[0])](t)[0]
    out = np.empty(t.shape)
    for k in np.unique(seg):
        m = seg == k
        out[m] = sol.interpolants[int(k)](t[m])[0]
    return out


def integrate_motion(kinematics: Kinematics, profile: SpeedProfile, t_start: float, t_end: float) -> Motion:
    """Integrate the speed model; see :class:`Motion`."""
    return Motion(kinematics, profile, t_start, t_end)


# ----------------------------------------------------------------------------- geometry
@dataclass(frozen=True)
class HoleErrors:
    """Shaft-hole position errors (spec section 2): radial e [m], angular kappa [rad].

    Parameters
    ----------
    e_sun, kappa_sun : float
        Sun centre offset and its direction from the carrier x axis at t = 0.
    e_ring, kappa_ring : float
        Ring centre offset and direction.
    e_planet, kappa_planet : sequence of float
        Per planet offset and direction from that planet's outward radial line; empty means
        zero for every planet.
    """

    e_sun: float = 0.0
    kappa_sun: float = 0.0
    e_ring: float = 0.0
    kappa_ring: float = 0.0
    e_planet: tuple[float, ...] = ()
    kappa_planet: tuple[float, ...] = ()

    def __post_init__(self):
        for k in ("e_sun", "e_ring"):
            object.__setattr__(self, k, _nonneg(k, getattr(self, k)))
        for k in ("kappa_sun", "kappa_ring"):
            object.__setattr__(self, k, _real(k, getattr(self, k)))
        ep, kp = _real_tuple("e_planet", self.e_planet), _real_tuple("kappa_planet", self.kappa_planet)
        if any(e < 0 for e in ep):
            raise ValueError(f"e_planet must be >= 0, got {ep!r}")
        if kp and len(kp) != len(ep):
            raise ValueError(f"kappa_planet must match e_planet in length, got {len(kp)} and {len(ep)}")
        object.__setattr__(self, "e_planet", ep)
        object.__setattr__(self, "kappa_planet", kp)

    @classmethod
    def coerce(cls, v: Any) -> "HoleErrors":
        """HoleErrors from itself, None (no errors) or a mapping of its fields."""
        if v is None:
            return cls()
        if isinstance(v, cls):
            return v
        if isinstance(v, Mapping):
            return cls(**v)
        raise TypeError(f"errors must be HoleErrors, a mapping or None, got {type(v).__name__} {v!r}")

    def planet_arrays(self, n_planets: int) -> tuple[np.ndarray, np.ndarray]:
        """(e_p [m], kappa_p [rad]) arrays of length n_planets."""
        if not self.e_planet:
            return np.zeros(n_planets), np.zeros(n_planets)
        if len(self.e_planet) != n_planets:
            raise ValueError(f"e_planet has {len(self.e_planet)} entries for {n_planets} planets")
        kp = self.kappa_planet or (0.0,) * n_planets
        return np.array(self.e_planet), np.array(kp)

    def check(self, gearset: Gearset) -> None:
        """ValueError when the offsets are too large for the line-of-centres construction."""
        ep, _ = self.planet_arrays(gearset.n_planets)
        worst = max(self.e_sun, self.e_ring) + (ep.max() if ep.size else 0.0)
        if worst >= 0.5 * gearset.carrier_radius:
            raise ValueError(f"shaft-hole errors too large: e_sun/e_ring + e_planet = {worst!r} m must stay "
                             f"below half the carrier radius {gearset.carrier_radius!r} m")


_GAUGED = {"sun": "sun_rel", "ring": "ring_rel"}


def line_of_centres(motion: Motion, errors: HoleErrors, gear: str, planet: int, t) -> np.ndarray:
    """Direction of the line of centres arg(O_pan - O_ja) in the carrier frame [rad].

    Returned as ``psi_n + delta`` with ``delta`` in (-pi/2, pi/2), i.e. continuous in t.

    Parameters
    ----------
    motion : Motion
    errors : HoleErrors
    gear : {"sun", "ring"}
        Which mesh: sun-planet (O_sa) or ring-planet (O_ra).
    planet : int
        0-based planet index.
    t : array_like
        Times [s].
    """
    _choice("gear", gear, tuple(_GAUGED))
    g = motion.kinematics.gearset
    n = _int("planet", planet, 0)
    if n >= g.n_planets:
        raise ValueError(f"planet index must be < {g.n_planets}, got {planet!r}")
    return _loc_from_ref(motion.kinematics, errors, gear, n, motion.theta_ref(t))


def _loc_from_ref(kin: Kinematics, errors: HoleErrors, gear: str, n: int, th_ref: np.ndarray) -> np.ndarray:
    """:func:`line_of_centres` from the reference angle [rad] (one ODE evaluation for all angles)."""
    g = kin.gearset
    ep, kp = errors.planet_arrays(g.n_planets)
    psi = g.planet_angles[n]
    th_j = kin.ratio(_GAUGED[gear]) * th_ref
    e_j, k_j = (errors.e_sun, errors.kappa_sun) if gear == "sun" else (errors.e_ring, errors.kappa_ring)
    # (O_pan - O_ja) rotated by -psi_n, built in the rotated frame (no cancellation near psi_n)
    if ep[n] != 0.0:
        bp = kp[n] + kin.ratio("planet") * th_ref
        x = g.carrier_radius + ep[n] * np.cos(bp)
        y = ep[n] * np.sin(bp)
    else:
        x = np.full(np.shape(th_j), g.carrier_radius)
        y = np.zeros(np.shape(th_j))
    if e_j != 0.0:
        bj = k_j + th_j - psi
        x = x - e_j * np.cos(bj)
        y = y - e_j * np.sin(bj)
    return psi + np.arctan2(y, x)


def _level_crossings(D: Callable[[np.ndarray], np.ndarray], t0: float, t1: float, dt: float,
                     xtol: float = ROOT_XTOL) -> tuple[np.ndarray, np.ndarray]:
    """Times in (t0, t1] where an increasing D(t) crosses a level 2 pi k, and the k's."""
    n = max(2, int(math.ceil((t1 - t0) / dt)) + 1)
    grid = np.linspace(t0, t1, n)
    d = D(grid)
    if np.any(np.diff(d) <= 0.0):
        raise ValueError("the engagement condition is not monotone in time (speed reversal, or shaft-hole "
                         "errors turning the line of centres faster than the gear)")
    klo = np.floor(d[:-1] / TWO_PI)
    khi = np.floor(d[1:] / TWO_PI)
    if np.any(khi - klo > 1):
        raise RuntimeError("bracketing grid too coarse: more than one crossing per interval")
    times, ks = [], []
    for i in np.flatnonzero(khi > klo):
        k = khi[i]
        f = lambda s, k=k: float(D(np.array([s]))[0]) - TWO_PI * k  # noqa: E731
        a, b = grid[i], grid[i + 1]
        fa, fb = f(a), f(b)
        if fb == 0.0:
            root = b
        elif fa * fb > 0.0:  # vector and scalar evaluation disagree by rounding at a grid node
            root = a if abs(fa) < abs(fb) else b
        else:
            root = brentq(f, a, b, xtol=xtol, maxiter=200)
        times.append(root)
        ks.append(int(k))
    return np.array(times, dtype=float), np.array(ks, dtype=np.int64)


def _bracket_step(motion: Motion, member: str, t0: float, t1: float) -> float:
    """Grid step [s] over which the gauged angle turns < pi/4 (with a margin)."""
    w = abs(motion.kinematics.speed(member))
    a = sum(abs(r.amplitude) for r in motion.profile.ripple)
    gmax = 1.0 + abs(motion.profile.ramp) / 2.0
    return min((math.pi / 4.0) / (1.5 * w * gmax * (1.0 + a)), max(t1 - t0, 1e-9) / 2.0)


def engagement_instants(motion: Motion, errors: HoleErrors, gear: str, tooth_angle0: float,
                        t0: float, t1: float) -> tuple[np.ndarray, np.ndarray]:
    """Engagement instants of a gauged tooth with every planet, from the geometric condition.

    Solves ``a0 + theta_jc(t) = arg(O_pan(t) - O_ja(t))  (mod 2 pi)`` for each planet n with
    brentq (xtol 1e-13 s), bracketed on a grid of the integrated angle.

    Parameters
    ----------
    motion : Motion
    errors : HoleErrors
    gear : {"sun", "ring"}
    tooth_angle0 : float
        a0: the gauged tooth's carrier-frame angle at t = 0 [rad] (for the ring = its
        ground angle, since the frames coincide at t = 0).
    t0, t1 : float
        Search window (t0, t1] [s], inside the motion's span.

    Returns
    -------
    times : ndarray of float
        Engagement instants [s], sorted (empty when none).
    planets : ndarray of int
        1-based planet number of each instant.
    """
    _choice("gear", gear, tuple(_GAUGED))
    a0 = _real("tooth_angle0", tooth_angle0)
    t0, t1 = _real("t0", t0), _real("t1", t1)
    if not (motion.t_start <= t0 < t1 <= motion.t_end):
        raise ValueError(f"window ({t0}, {t1}] s must lie in the motion span [{motion.t_start}, {motion.t_end}]")
    errors.check(motion.kinematics.gearset)
    member = _GAUGED[gear]
    s = 1.0 if motion.kinematics.speed(member) > 0 else -1.0
    dt = _bracket_step(motion, member, t0, t1)
    all_t, all_p = [], []
    kin = motion.kinematics
    ratio = kin.ratio(member)
    for n in range(kin.gearset.n_planets):
        def D(t, n=n):
            th = motion.theta_ref(t)
            return s * (a0 + ratio * th - _loc_from_ref(kin, errors, gear, n, th))
        tn, _ = _level_crossings(D, t0, t1, dt)
        all_t.append(tn)
        all_p.append(np.full(tn.size, n + 1, dtype=np.int64))
    t = np.concatenate(all_t)
    p = np.concatenate(all_p)
    order = np.argsort(t, kind="stable")
    return t[order], p[order]


def engagement_residual(motion: Motion, errors: HoleErrors, gear: str, tooth_angle0: float,
                        times, planets) -> np.ndarray:
    """Wrapped residual ``a0 + theta_jc(t) - arg(O_pan - O_ja)`` [rad] at given instants.

    ``planets`` are 1-based. Computed from the full carrier-frame vectors with atan2 (not the
    rotated form :func:`line_of_centres` uses), as an independent check.
    """
    _choice("gear", gear, tuple(_GAUGED))
    t = np.asarray(times, dtype=float)
    p = np.asarray(planets, dtype=np.int64)
    if t.shape != p.shape:
        raise ValueError(f"times and planets must have the same shape, got {t.shape} and {p.shape}")
    g = motion.kinematics.gearset
    if p.size and (p.min() < 1 or p.max() > g.n_planets):
        raise ValueError(f"planets must be 1..{g.n_planets}, got {np.unique(p)!r}")
    ep, kp = errors.planet_arrays(g.n_planets)
    psi = np.asarray(g.planet_angles)[p - 1] if p.size else np.zeros(0)
    th_j = motion.angle(_GAUGED[gear], t)
    th_p = motion.angle("planet", t)
    o_p = g.carrier_radius * np.exp(1j * psi) + (ep[p - 1] * np.exp(1j * (psi + kp[p - 1] + th_p)) if p.size else 0)
    e_j, k_j = (errors.e_sun, errors.kappa_sun) if gear == "sun" else (errors.e_ring, errors.kappa_ring)
    o_j = e_j * np.exp(1j * (k_j + th_j))
    d = o_p - o_j
    return _wrap(_real("tooth_angle0", tooth_angle0) + th_j - np.arctan2(d.imag, d.real))


def pass_truth(motion: Motion, gear: str, times, planets) -> list[dict]:
    """Truth phasing per pass from engagement instants.

    Parameters
    ----------
    motion : Motion
    gear : {"sun", "ring"}
    times, planets : array_like
        Sorted engagement instants [s] and their 1-based planets (from
        :func:`engagement_instants`, restricted to the record).

    Returns
    -------
    list of dict
        One per complete pass: ``t_planet1`` [s], ``t_pass`` (mean of the pass's instants) [s],
        ``t`` (instant of planet 1..N) [s], ``gamma`` (planet 1..N, planet 1 = 0) [-]. A pass
        the record cuts short is left out.
    """
    _choice("gear", gear, tuple(_GAUGED))
    t = np.asarray(times, dtype=float)
    p = np.asarray(planets, dtype=np.int64)
    if t.ndim != 1 or t.shape != p.shape:
        raise ValueError(f"times and planets must be 1-D of equal length, got {t.shape} and {p.shape}")
    if t.size and np.any(np.diff(t) < 0):
        raise ValueError("times must be sorted")
    g = motion.kinematics.gearset
    z = g.z_sun if gear == "sun" else g.z_ring
    n = g.n_planets
    theta = motion.angle(_GAUGED[gear], t) if t.size else np.zeros(0)
    starts = np.flatnonzero(p == 1)
    out = []
    for a, i in enumerate(starts):
        end = starts[a + 1] if a + 1 < starts.size else t.size
        pl = p[i + 1:end]
        if a + 1 == starts.size and pl.size < n - 1:
            break  # cut short by the end of the record
        if sorted(pl.tolist()) != list(range(2, n + 1)):
            raise RuntimeError(f"pass at t={t[i]!r} s sees planets {pl.tolist()}, expected each of 2..{n} once")
        tn = np.empty(n)
        tn[0] = t[i]
        tn[pl - 1] = t[i + 1:end]
        th = np.empty(n)
        th[0] = theta[i]
        th[pl - 1] = theta[i + 1:end]
        cyc = z * np.abs(th - th[0]) / TWO_PI
        gamma = cyc - np.floor(cyc)
        out.append({"t_planet1": float(tn[0]), "t_pass": float(tn.mean()),
                    "t": tn.tolist(), "gamma": gamma.tolist()})
    return out


def parker_phasing(gearset: Gearset, planet_rotation: str = "cw") -> tuple[np.ndarray, np.ndarray]:
    """Parker & Lin's ideal phasing (spec section 1): (gamma_s, gamma_r) per planet [-].

    ``gamma_sn = frac(+Z_s psi_n / 2 pi)``, ``gamma_rn = frac(-Z_r psi_n / 2 pi)`` for
    clockwise planets; counter-clockwise flips both signs.
    """
    if not isinstance(gearset, Gearset):
        raise TypeError(f"gearset must be a Gearset, got {type(gearset).__name__}")
    s = 1.0 if _choice("planet_rotation", planet_rotation, ("cw", "ccw")) == "cw" else -1.0
    psi = np.asarray(gearset.planet_angles)
    xs = s * gearset.z_sun * psi / TWO_PI
    xr = -s * gearset.z_ring * psi / TWO_PI
    return xs - np.floor(xs), xr - np.floor(xr)


# ----------------------------------------------------------------------------- pulse shape
#: (first, last) mesh cycle of the pulse's support, relative to the engagement instant.
PULSE_SUPPORT = (-1.65, 1.70)
_TENSILE = (-0.75, 0.12, 0.85)  # start, peak, end [mesh cycles]: 1.6 cycles, peak after engagement
_LOBES = ((-1.20, 0.45, 0.16), (1.25, 0.45, 0.24))  # (centre, half width, depth) [cycles, cycles, -]


def pulse_shape(u) -> np.ndarray:
    """Tooth-root strain pulse vs mesh cycles since engagement, normalised to a peak of 1 [-].

    An asymmetric tensile lobe 1.6 mesh cycles long (sin^2 rise from u = -0.75 to the peak at
    u = +0.12, cos^2 fall to u = 0.85: the peak comes slightly after the tooth crosses the
    line of centres) and two compressive raised-cosine side lobes from the neighbouring
    teeth (depth 0.16 centred at u = -1.20, depth 0.24 centred at u = +1.25, half width 0.45).
    Zero outside :data:`PULSE_SUPPORT`. Deliberately not the shape ``synthetic/`` uses.

    Parameters
    ----------
    u : array_like
        Mesh cycles of the gauged gear (relative to the carrier) since engagement [-].
    """
    u = np.asarray(u, dtype=float)
    a, pk, b = _TENSILE
    out = np.zeros_like(u)
    rise = (u >= a) & (u <= pk)
    fall = (u > pk) & (u <= b)
    out[rise] = np.sin(0.5 * math.pi * (u[rise] - a) / (pk - a)) ** 2
    out[fall] = np.cos(0.5 * math.pi * (u[fall] - pk) / (b - pk)) ** 2
    for c, h, depth in _LOBES:
        m = np.abs(u - c) < h
        out[m] -= depth * 0.5 * (1.0 + np.cos(math.pi * (u[m] - c) / h))
    return out


# ----------------------------------------------------------------------------- rig config
@dataclass(frozen=True)
class RigConfig:
    """Everything that defines one recording (SI units).

    Parameters
    ----------
    gearset : Gearset
    duration : float
        Record length [s] (the sample count is ``round(duration * fs)``).
    fixed : {"ring", "sun", "carrier"}
    speed_member : {"sun", "carrier", "ring"}
        Whose nominal speed ``speed_rpm`` gives.
    speed_rpm : float
        Nominal absolute speed of ``speed_member`` [r/min]; sign = sense.
    ripple : sequence of RippleTerm
    ramp : float
        Total relative speed change over the record [-] (centred, see :class:`SpeedProfile`).
    errors : HoleErrors
    load_sharing : sequence of float or None
        Pulse amplitude factor per planet [-] (None: all 1). The truth reports
        ``LS_n = N f_n / sum f``.
    load_modulation : sequence of (float, int, float)
        Terms ``(a, m, phase)`` [-, -, rad] of a load variation locked to the carrier angle
        (a torque ripple): every pulse's amplitude times ``1 + sum a cos(m theta_c + phase)``,
        theta_c the absolute carrier angle at its engagement [rad]; the truth gives each
        engagement's factor (``engagements[channel]["gain"]``). Empty: none.
    fs : float
        Sample rate [Hz].
    sun_gauge, ring_gauge : bool
        Which gauge channels to record.
    sun_tooth, ring_tooth : int
        Tooth numbers (labels in channel names).
    sun_tooth_angle0 : float
        Sun gauge tooth's carrier-frame angle at t = 0 [rad].
    ring_gauge_angle : float
        Ring gauge tooth's ground angle (= carrier-frame angle at t = 0) [rad].
    sun_peak, ring_peak : float
        Pulse peak for LS = 1 [strain, m/m].
    snr_db : float or None
        20 log10(largest pulse peak / noise rms) per gauge channel [dB]; None: no noise.
    hum : float
        50 Hz mains hum amplitude as a fraction of the channel's pulse peak [-].
    hum_hz : float
        Mains frequency [Hz].
    drift : float
        Thermal drift amplitude as a fraction of the pulse peak [-]:
        ``drift * peak * sign * (1 - exp(-t / drift_tau))``.
    drift_tau : float
        Thermal time constant [s].
    adc_bits : {None, 16, 24}
        Quantise to this many bits over +-adc_range (gauges) / +-tacho_range (tacho).
    adc_range : float
        Gauge ADC full scale [strain].
    tacho : bool
        Record the carrier once-per-revolution channel.
    tacho_edge_angle : float
        Absolute carrier angle of the rising edge [rad].
    tacho_key_width : float
        Carrier angle over which the TTL level is high [rad].
    tacho_high : float
        TTL high level [V].
    tacho_noise : float
        Tacho noise rms [V].
    tacho_range : float
        Tacho ADC full scale [V].
    encoder : (str, int) or None
        A shaft encoder channel: (shaft, pulses per revolution), shaft "sun", "carrier" or
        "ring" (a turning one); None: no encoder.
    encoder_edge_angle : float
        Absolute shaft angle of the encoder's rising edge 0 [rad]; edge k fires at
        ``encoder_edge_angle + 2 pi k / pulses`` (in the shaft's sense of rotation).
    encoder_duty : float
        Fraction of a pulse period at the high level [-].
    encoder_high : float
        Encoder high level [V] (TTL).
    encoder_noise : float
        Encoder noise rms [V].
    start_time : str
        ISO 8601 UTC start of the first sample (written as ``wf_start_time``).
    group : str
        TDMS group name.
    seed : int or None
        Root of all randomness (numpy SeedSequence entropy); None draws fresh entropy,
        which the truth then records.
    """

    gearset: Gearset
    duration: float
    fixed: str = "ring"
    speed_member: str = "sun"
    speed_rpm: float = 18.19
    ripple: tuple[RippleTerm, ...] = ()
    ramp: float = 0.0
    errors: HoleErrors = field(default_factory=HoleErrors)
    load_sharing: tuple[float, ...] | None = None
    load_modulation: tuple[tuple[float, int, float], ...] = ()
    fs: float = 5120.0
    sun_gauge: bool = True
    ring_gauge: bool = True
    sun_tooth: int = 3
    ring_tooth: int = 1
    sun_tooth_angle0: float = 0.3
    ring_gauge_angle: float = 1.0
    sun_peak: float = 420e-6
    ring_peak: float = 260e-6
    snr_db: float | None = 20.0
    hum: float = 0.03
    hum_hz: float = 50.0
    drift: float = 0.10
    drift_tau: float = 180.0
    adc_bits: int | None = None
    adc_range: float = 2e-3
    tacho: bool = True
    tacho_edge_angle: float = 0.5
    tacho_key_width: float = math.radians(5.0)
    tacho_high: float = 5.0
    tacho_noise: float = 0.005
    tacho_range: float = 10.0
    encoder: tuple | None = None
    encoder_edge_angle: float = 0.0
    encoder_duty: float = 0.5
    encoder_high: float = 5.0
    encoder_noise: float = 0.005
    start_time: str = "2024-03-12T09:41:27.250000"
    group: str = "Rig"
    seed: int | None = 0

    def __post_init__(self):
        if not isinstance(self.gearset, Gearset):
            raise TypeError(f"gearset must be a Gearset, got {type(self.gearset).__name__}")
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731
        set_("duration", _positive("duration", self.duration))
        _choice("fixed", self.fixed, FIXED_MEMBERS)
        _choice("speed_member", self.speed_member, ("sun", "carrier", "ring"))
        set_("speed_rpm", _real("speed_rpm", self.speed_rpm))
        if self.speed_rpm == 0.0:
            raise ValueError("speed_rpm must be non-zero, got 0")
        if isinstance(self.ripple, (str, bytes)) or not isinstance(self.ripple, (Sequence, np.ndarray)):
            raise TypeError(f"ripple must be a sequence of ripple terms, got {type(self.ripple).__name__}")
        set_("ripple", tuple(RippleTerm.coerce(r) for r in self.ripple))
        set_("ramp", _real("ramp", self.ramp))
        set_("errors", HoleErrors.coerce(self.errors))
        self.errors.check(self.gearset)
        if self.load_sharing is not None:
            ls = _real_tuple("load_sharing", self.load_sharing)
            if len(ls) != self.gearset.n_planets or any(x <= 0 for x in ls):
                raise ValueError(f"load_sharing needs {self.gearset.n_planets} positive factors, got {ls!r}")
            set_("load_sharing", ls)
        set_("load_modulation", _load_modulation(self.load_modulation))
        set_("fs", _positive("fs", self.fs))
        for k in ("sun_gauge", "ring_gauge", "tacho"):
            if not isinstance(getattr(self, k), (bool, np.bool_)):
                raise TypeError(f"{k} must be a bool, got {getattr(self, k)!r}")
            set_(k, bool(getattr(self, k)))
        if not (self.sun_gauge or self.ring_gauge):
            raise ValueError("at least one of sun_gauge, ring_gauge must be True")
        set_("sun_tooth", _int("sun_tooth", self.sun_tooth, 1))
        set_("ring_tooth", _int("ring_tooth", self.ring_tooth, 1))
        for k in ("sun_tooth_angle0", "ring_gauge_angle", "tacho_edge_angle"):
            set_(k, _real(k, getattr(self, k)))
        for k in ("sun_peak", "ring_peak", "hum_hz", "drift_tau", "adc_range", "tacho_key_width",
                  "tacho_high", "tacho_range"):
            set_(k, _positive(k, getattr(self, k)))
        for k in ("hum", "drift", "tacho_noise"):
            set_(k, _nonneg(k, getattr(self, k)))
        if self.snr_db is not None:
            set_("snr_db", _real("snr_db", self.snr_db))
        if self.adc_bits is not None and _int("adc_bits", self.adc_bits) not in (16, 24):
            raise ValueError(f"adc_bits must be None, 16 or 24, got {self.adc_bits!r}")
        if self.tacho_key_width >= math.pi:
            raise ValueError(f"tacho_key_width must be < pi rad, got {self.tacho_key_width!r}")
        if self.encoder is not None:
            if isinstance(self.encoder, (str, bytes)) or len(self.encoder) != 2:
                raise TypeError(f"encoder must be (shaft, pulses per revolution), got {self.encoder!r}")
            shaft = _choice("encoder shaft", self.encoder[0], ("sun", "carrier", "ring"))
            if shaft == self.fixed:
                raise ValueError(f"encoder on the held {shaft} does not turn (fixed={self.fixed!r})")
            set_("encoder", (shaft, _int("encoder pulses per revolution", self.encoder[1], 1)))
        set_("encoder_edge_angle", _real("encoder_edge_angle", self.encoder_edge_angle))
        set_("encoder_duty", _positive("encoder_duty", self.encoder_duty))
        if self.encoder_duty >= 1.0:
            raise ValueError(f"encoder_duty must be in (0, 1), got {self.encoder_duty!r}")
        set_("encoder_high", _positive("encoder_high", self.encoder_high))
        set_("encoder_noise", _nonneg("encoder_noise", self.encoder_noise))
        if self.tacho and self.fixed == "carrier":
            raise ValueError("a carrier tacho needs a turning carrier; fixed='carrier' requires tacho=False")
        if not isinstance(self.start_time, str):
            raise TypeError(f"start_time must be an ISO 8601 string, got {type(self.start_time).__name__}")
        try:
            np.datetime64(self.start_time, "us")
        except ValueError as exc:
            raise ValueError(f"start_time is not ISO 8601: {self.start_time!r}") from exc
        if not isinstance(self.group, str) or not self.group:
            raise ValueError(f"group must be a non-empty string, got {self.group!r}")
        if self.seed is not None:
            set_("seed", _int("seed", self.seed, 0))
        SpeedProfile(self.ripple, self.ramp, self.duration)  # validates amplitudes and ramp
        if round(self.duration * self.fs) < 2:
            raise ValueError(f"duration * fs must give >= 2 samples, got duration={self.duration!r}, fs={self.fs!r}")

    def to_dict(self) -> dict:
        """JSON-friendly dict (tuples as lists); :meth:`from_dict` inverts it."""
        return _jsonable(dataclasses.asdict(self))

    @classmethod
    def from_dict(cls, d: Mapping) -> "RigConfig":
        """Rebuild from :meth:`to_dict` output (e.g. the truth sidecar's ``config``)."""
        if not isinstance(d, Mapping):
            raise TypeError(f"config must be a mapping, got {type(d).__name__}")
        d = dict(d)
        g = dict(d.pop("gearset"))
        g["planet_angles"] = tuple(g["planet_angles"])
        d["ripple"] = tuple(RippleTerm(**r) for r in d.get("ripple", ()))
        d["errors"] = HoleErrors(**d.get("errors", {}))
        if d.get("load_sharing") is not None:
            d["load_sharing"] = tuple(d["load_sharing"])
        d["load_modulation"] = tuple(tuple(x) for x in d.get("load_modulation", ()))
        if d.get("encoder") is not None:
            d["encoder"] = tuple(d["encoder"])
        return cls(Gearset(**g), **d)


def _load_modulation(v: Any) -> tuple[tuple[float, int, float], ...]:
    """Validated ``load_modulation`` terms (a, m, phase): |a| summed below 1 (amplitudes stay
    positive), m a positive integer."""
    if isinstance(v, (str, bytes)) or not isinstance(v, (Sequence, np.ndarray)):
        raise TypeError(f"load_modulation must be a sequence of (a, m, phase), got {v!r}")
    terms = []
    for term in v:
        if isinstance(term, (str, bytes)) or not isinstance(term, (Sequence, np.ndarray)) or len(term) != 3:
            raise ValueError(f"load_modulation terms must be (a, m, phase), got {term!r}")
        terms.append((_real("load_modulation a", term[0]), _int("load_modulation m", term[1], 1),
                      _real("load_modulation phase", term[2])))
    if sum(abs(a) for a, _, _ in terms) >= 1.0:
        raise ValueError(f"load_modulation amplitudes must sum below 1, got {v!r}")
    return tuple(terms)


def _jsonable(v: Any) -> Any:
    if isinstance(v, Mapping):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, np.ndarray):
        return [_jsonable(x) for x in v.tolist()]
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (numbers.Integral,)):
        return int(v)
    if isinstance(v, numbers.Real):
        return float(v)
    return v


# ----------------------------------------------------------------------------- truth
@dataclass
class RigTruth:
    """Ground truth of one recording (the JSON sidecar's content; JSON-native fields).

    Attributes
    ----------
    file : str or None
        The TDMS file name (None before writing).
    config : dict
        :meth:`RigConfig.to_dict` (rebuild with :meth:`RigConfig.from_dict`).
    seed_entropy : int
        The SeedSequence entropy actually used (reproduces a ``seed=None`` run).
    fs : float
        [Hz]. ``n_samples``: per channel. ``duration``: n_samples / fs [s].
    start_time : str
        ISO 8601 UTC of sample 0.
    speeds : dict
        Nominal speeds [r/min and rad/s], ``carrier_rpm`` exact vs ``carrier_rpm_scene``
        (what a user types), mesh frequency [Hz], planet rotation.
    channels : list of dict
        name, kind (sun/ring/tacho), tooth, angle, unit, peak, noise rms.
    engagements : dict
        channel -> {"gear", "t" [s], "planet" (1-based)}, instants inside the record, and
        "gain" (each pulse's amplitude factor [-]) when there is a ``load_modulation``.
    passes : dict
        channel -> list of per-pass dicts (see :func:`pass_truth`).
    parker : dict
        Ideal phasing per planet {"sun": [...], "ring": [...], "planet_rotation"}.
    load_sharing : list of float
        ``N f_n / sum f`` [-].
    tacho : dict or None
        Rising-edge times [s] and the key geometry [rad].
    pulse : dict
        Pulse model description.
    tdms : dict or None
        Layout written: samples per segment, segments, storage.
    encoder : dict or None
        The encoder channel: name, shaft, pulses per revolution and its rising-edge times [s].
    """

    file: str | None
    config: dict
    seed_entropy: int
    fs: float
    n_samples: int
    duration: float
    start_time: str
    speeds: dict
    channels: list
    engagements: dict
    passes: dict
    parker: dict
    load_sharing: list
    tacho: dict | None
    pulse: dict
    tdms: dict | None = None
    encoder: dict | None = None

    def to_json(self) -> str:
        """JSON text (floats round-trip exactly)."""
        return json.dumps(_jsonable(dataclasses.asdict(self)), indent=1)

    @classmethod
    def from_json(cls, text: str) -> "RigTruth":
        """Inverse of :meth:`to_json`."""
        if not isinstance(text, str):
            raise TypeError(f"text must be a str, got {type(text).__name__}")
        d = json.loads(text)
        if not isinstance(d, dict):
            raise ValueError("truth JSON must hold an object")
        names = {f.name for f in dataclasses.fields(cls)}
        if "encoder" not in d:                       # written before the encoder field
            d["encoder"] = None
        if set(d) != names:
            raise ValueError(f"truth JSON keys differ from RigTruth fields: {sorted(set(d) ^ names)}")
        return cls(**d)


def truth_path(tdms_path: str | Path) -> Path:
    """Sidecar path next to a TDMS file: ``rec.tdms`` -> ``rec.truth.json``."""
    if not isinstance(tdms_path, (str, Path)):
        raise TypeError(f"tdms_path must be str or Path, got {type(tdms_path).__name__}")
    p = Path(tdms_path)
    if not p.name:
        raise ValueError(f"tdms_path has no file name: {tdms_path!r}")
    return p.with_name(p.stem + ".truth.json")


def read_truth(path: str | Path) -> RigTruth:
    """Read a truth sidecar (give the ``.truth.json`` or the ``.tdms`` path)."""
    if not isinstance(path, (str, Path)):
        raise TypeError(f"path must be str or Path, got {type(path).__name__}")
    p = Path(path)
    if p.suffix.lower() == ".tdms":
        p = truth_path(p)
    return RigTruth.from_json(p.read_text())


# ----------------------------------------------------------------------------- the rig
@dataclass(frozen=True)
class _Channel:
    name: str
    kind: str  # "sun" | "ring" | "tacho"
    unit: str
    peak: float  # largest pulse peak [strain] (tacho: high level [V])
    noise_rms: float
    full_scale: float


class Rig:
    """A configured rig: motion, engagement instants, tacho edges, and block rendering.

    Parameters
    ----------
    config : RigConfig
    """

    def __init__(self, config: RigConfig):
        if not isinstance(config, RigConfig):
            raise TypeError(f"config must be a RigConfig, got {type(config).__name__}")
        c = self.config = config
        g = c.gearset
        self.n_samples = int(round(c.duration * c.fs))
        self.t_last = (self.n_samples - 1) / c.fs
        self.kinematics = nominal_kinematics(g, c.fixed, **{f"{c.speed_member}_rpm": c.speed_rpm})
        self.profile = SpeedProfile(c.ripple, c.ramp, self.n_samples / c.fs)
        # pad so pulses straddling the record ends are complete: 3 mesh cycles at the slowest speed
        slow = (1.0 - abs(c.ramp) / 2.0) * (1.0 - sum(abs(r.amplitude) for r in c.ripple))
        pad = 3.0 / (self.kinematics.mesh_frequency * slow)
        self.motion = Motion(self.kinematics, self.profile, -pad, self.t_last + pad)
        f = np.ones(g.n_planets) if c.load_sharing is None else np.asarray(c.load_sharing)
        self.amp_factor = f
        self.load_sharing = g.n_planets * f / f.sum()
        # engagements over the padded span (rendering) and inside the record (truth)
        self._eng: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._gain: dict[str, np.ndarray] = {}
        self.channels: list[_Channel] = []
        gauges = [("sun", c.sun_gauge, c.sun_tooth, c.sun_tooth_angle0, c.sun_peak),
                  ("ring", c.ring_gauge, c.ring_tooth, c.ring_gauge_angle, c.ring_peak)]
        for gear, on, tooth, a0, peak in gauges:
            if not on:
                continue
            t, p = engagement_instants(self.motion, c.errors, gear, a0, self.motion.t_start, self.motion.t_end)
            self._eng[gear] = (t, p, self.motion.mesh_cycles(t))
            self._gain[gear] = f[p - 1] * self.load_factor(t)
            top = peak * f.max() * (1.0 + sum(abs(a) for a, _, _ in c.load_modulation))
            noise = 0.0 if c.snr_db is None else top / 10.0 ** (c.snr_db / 20.0)
            self.channels.append(_Channel(f"SG_{gear}_T{tooth}", gear, "Strain", peak, noise, c.adc_range))
        if c.tacho:
            self.channels.append(_Channel("Tacho OPR", "tacho", "V", c.tacho_high, c.tacho_noise, c.tacho_range))
            s = 1.0 if self.kinematics.speed("carrier") > 0 else -1.0
            D = lambda t: s * (self.motion.angle("carrier", t) - c.tacho_edge_angle)  # noqa: E731
            dt = _bracket_step(self.motion, "carrier", 0.0, self.t_last)
            te, _ = _level_crossings(D, 0.0, self.t_last, dt)
            if D(np.array([0.0]))[0] % TWO_PI == 0.0:
                te = np.concatenate([[0.0], te])
            self.tacho_edges = te
        else:
            self.tacho_edges = np.zeros(0)
        self.encoder_edges = np.zeros(0)
        if c.encoder is not None:
            shaft, ppr = c.encoder
            self.channels.append(_Channel(f"Encoder {shaft} {ppr}", "encoder", "V", c.encoder_high,
                                          c.encoder_noise, c.tacho_range))
            s = 1.0 if self.kinematics.speed(shaft) > 0 else -1.0
            D = lambda t: s * ppr * (self.motion.angle(shaft, t) - c.encoder_edge_angle)  # noqa: E731
            dt = _bracket_step(self.motion, shaft, 0.0, self.t_last) / ppr
            te, _ = _level_crossings(D, 0.0, self.t_last, dt)
            if D(np.array([0.0]))[0] % TWO_PI == 0.0:
                te = np.concatenate([[0.0], te])
            self.encoder_edges = te
        # randomness: one child SeedSequence per channel (streams independent of block size)
        if c.seed is None:
            ss = np.random.SeedSequence()
        else:
            ss = np.random.SeedSequence(c.seed)
        self.seed_entropy = int(ss.entropy)
        kids = ss.spawn(len(self.channels) + 1)
        self._noise_seeds = kids[:-1]
        r = np.random.default_rng(kids[-1])
        self._hum_phase = r.uniform(0.0, TWO_PI, len(self.channels))
        self._drift_sign = r.choice([-1.0, 1.0], len(self.channels))

    def load_factor(self, t) -> np.ndarray:
        """The carrier-angle load variation ``1 + sum a cos(m theta_c + phase)`` [-] at times t [s]
        (ones without ``load_modulation``)."""
        t = np.asarray(t, dtype=float)
        out = np.ones(t.shape)
        if self.config.load_modulation:
            th = self.motion.angle("carrier", t)
            for a, m, ph in self.config.load_modulation:
                out = out + a * np.cos(m * th + ph)
        return out

    # ------------------------------------------------------------------ truth
    def engagements(self, gear: str) -> tuple[np.ndarray, np.ndarray]:
        """Engagement instants [s] and 1-based planets of a gauge, inside the record [0, t_last]."""
        _choice("gear", gear, tuple(self._eng))
        t, p, _ = self._eng[gear]
        m = (t >= 0.0) & (t <= self.t_last)
        return t[m], p[m]

    def truth(self, tdms: dict | None = None, file: str | None = None) -> RigTruth:
        """The :class:`RigTruth` of this rig (``tdms``: layout written, if any)."""
        c, kin, g = self.config, self.kinematics, self.config.gearset
        ps, pr = parker_phasing(g, kin.planet_rotation)
        eng, passes = {}, {}
        for ch in self.channels:
            if ch.kind in ("tacho", "encoder"):
                continue
            t, p = self.engagements(ch.kind)
            eng[ch.name] = {"gear": ch.kind, "t": t.tolist(), "planet": p.tolist()}
            if c.load_modulation:
                eng[ch.name]["gain"] = (self.amp_factor[p - 1] * self.load_factor(t)).tolist()
            passes[ch.name] = pass_truth(self.motion, ch.kind, t, p)
        car = kin.rpm("carrier")
        speeds = {
            "fixed": c.fixed, "planet_rotation": kin.planet_rotation,
            "sun_rpm": kin.rpm("sun"), "carrier_rpm": car, "ring_rpm": kin.rpm("ring"),
            "carrier_rpm_scene": round(car, 2), "sun_rpm_scene": round(kin.rpm("sun"), 2),
            "sun_rel_rad_s": kin.speed("sun_rel"), "ring_rel_rad_s": kin.speed("ring_rel"),
            "planet_rel_rad_s": kin.speed("planet"), "carrier_rad_s": kin.speed("carrier"),
            "mesh_frequency_hz": kin.mesh_frequency,
            "note": "nominal (record-average) speeds; carrier_rpm is exact from the fixed member, "
                    "carrier_rpm_scene is what a user would type",
        }
        tacho = None
        if c.tacho:
            tacho = {
                "channel": "Tacho OPR", "rising_edges": self.tacho_edges.tolist(),
                "edge_carrier_angle": c.tacho_edge_angle, "key_width": c.tacho_key_width,
                "key_carrier_angle": float(np.mod(-c.tacho_edge_angle, TWO_PI)),
                "pickup_ground_angle": 0.0,
                "ring_gauge_ground_angle": c.ring_gauge_angle,
                "ring_gauge_angle_from_tacho": float(np.mod(c.ring_gauge_angle - c.tacho_edge_angle, TWO_PI)),
                "sun_tooth_carrier_angle0": c.sun_tooth_angle0,
                "geometry": "rising edge when the absolute carrier angle equals edge_carrier_angle (mod 2 pi), "
                            "i.e. when the key (at key_carrier_angle ccw from planet 1 on the carrier) passes "
                            "the pick-up at ground angle 0; "
                            "then planet 1 is at ground angle edge_carrier_angle; the ring gauge tooth is at "
                            "ground angle ring_gauge_ground_angle, i.e. ring_gauge_angle_from_tacho ccw from "
                            "planet 1's position at the tacho mark. Carrier and ground frames coincide at t=0.",
            }
        pulse = {"shape": "independent.rig.pulse_shape", "support_mesh_cycles": list(PULSE_SUPPORT),
                 "tensile_start_peak_end": list(_TENSILE), "side_lobes_centre_halfwidth_depth": [list(x) for x in _LOBES],
                 "argument": "mesh cycles of the gauged gear relative to the carrier since engagement "
                             "(integrated angle): the pulse lasts a fixed angle",
                 "engagement": "tooth on the line of centres arg(O_pan - O_ja) (middle of contact)"}
        return RigTruth(
            file=file, config=c.to_dict(), seed_entropy=self.seed_entropy, fs=c.fs,
            n_samples=self.n_samples, duration=self.n_samples / c.fs, start_time=c.start_time,
            speeds=speeds,
            channels=[{"name": ch.name, "kind": ch.kind, "unit": ch.unit, "peak": ch.peak,
                       "noise_rms": ch.noise_rms,
                       "tooth": (c.sun_tooth if ch.kind == "sun" else c.ring_tooth if ch.kind == "ring" else None),
                       "angle": (c.sun_tooth_angle0 if ch.kind == "sun" else
                                 c.ring_gauge_angle if ch.kind == "ring" else
                                 c.encoder_edge_angle if ch.kind == "encoder" else c.tacho_edge_angle)}
                      for ch in self.channels],
            engagements=eng, passes=passes,
            parker={"sun": ps.tolist(), "ring": pr.tolist(), "planet_rotation": kin.planet_rotation},
            load_sharing=self.load_sharing.tolist(), tacho=tacho, pulse=pulse, tdms=tdms,
            encoder=None if c.encoder is None else {
                "channel": next(ch.name for ch in self.channels if ch.kind == "encoder"),
                "shaft": c.encoder[0], "pulses_per_rev": c.encoder[1],
                "edge_shaft_angle": c.encoder_edge_angle, "rising_edges": self.encoder_edges.tolist(),
                "geometry": "rising edge k when the absolute shaft angle, in its sense of rotation, equals "
                            "edge_shaft_angle + 2 pi k / pulses_per_rev"},
        )

    # ------------------------------------------------------------------ signals
    def clean_gauge(self, gear: str, t) -> np.ndarray:
        """Noise-free gauge strain [strain] at increasing sample times t [s] (sum of pulses)."""
        _choice("gear", gear, tuple(self._eng))
        t = np.asarray(t, dtype=float)
        if t.ndim != 1:
            raise ValueError(f"t must be 1-D, got shape {t.shape}")
        if t.size and np.any(np.diff(t) <= 0):
            raise ValueError("t must increase strictly")
        return self._gauge_from_cycles(gear, self.motion.mesh_cycles(t))

    def _gauge_from_cycles(self, gear: str, M: np.ndarray) -> np.ndarray:
        x = np.zeros(M.shape)
        if M.size == 0:
            return x
        _, p, Me = self._eng[gear]
        gain = self._gain[gear]
        peak = self.config.sun_peak if gear == "sun" else self.config.ring_peak
        lo_u, hi_u = PULSE_SUPPORT
        k0 = np.searchsorted(Me, M[0] - hi_u, side="left")
        k1 = np.searchsorted(Me, M[-1] - lo_u, side="right")
        for k in range(k0, k1):
            a = np.searchsorted(M, Me[k] + lo_u, side="left")
            b = np.searchsorted(M, Me[k] + hi_u, side="right")
            if b > a:
                x[a:b] += peak * gain[k] * pulse_shape(M[a:b] - Me[k])
        return x

    def clean_tacho(self, t) -> np.ndarray:
        """Noise-free TTL tacho level [V] at times t [s]."""
        if not self.config.tacho:
            raise ValueError("this rig has no tacho (tacho=False)")
        return self._tacho_from_ref(self.motion.theta_ref(t))

    def _tacho_from_ref(self, th_ref: np.ndarray) -> np.ndarray:
        c = self.config
        s = 1.0 if self.kinematics.speed("carrier") > 0 else -1.0
        ph = np.mod(s * (self.kinematics.ratio("carrier") * th_ref - c.tacho_edge_angle), TWO_PI)
        return np.where(ph < c.tacho_key_width, c.tacho_high, 0.0)

    def _encoder_from_ref(self, th_ref: np.ndarray) -> np.ndarray:
        c = self.config
        shaft, ppr = c.encoder
        s = 1.0 if self.kinematics.speed(shaft) > 0 else -1.0
        ph = np.mod(s * ppr * (self.kinematics.ratio(shaft) * th_ref - c.encoder_edge_angle) / TWO_PI, 1.0)
        return np.where(ph < c.encoder_duty, c.encoder_high, 0.0)

    def iter_blocks(self, block: int, *, counts: bool = False,
                    render_samples: int = 8192) -> Iterator[tuple[int, int, dict[str, np.ndarray]]]:
        """Render the recording block by block.

        Parameters
        ----------
        block : int
            Samples per channel per yielded block.
        counts : bool
            Yield the quantised ADC counts (int16 for 16 bit, int32 for 24 bit) instead of
            physical values; needs ``adc_bits``.
        render_samples : int
            Samples rendered at once (rounded to whole blocks, at least one): one ODE
            evaluation per render chunk. Memory holds one chunk.

        Yields
        ------
        (i0, i1, {channel name: samples})
            Sample range [i0, i1) and float64 values [strain or V] (or integer counts). The
            values depend neither on ``block`` nor on ``render_samples`` (one random stream
            per channel, drawn in order).
        """
        block = _int("block", block, 1)
        render_samples = _int("render_samples", render_samples, 1)
        chunk = block * max(1, render_samples // block)
        c = self.config
        if counts and c.adc_bits is None:
            raise ValueError("counts=True needs adc_bits (16 or 24)")
        rngs = [np.random.default_rng(s) for s in self._noise_seeds]
        kin = self.kinematics
        M_per_ref = kin.sense / kin.coef(kin.reference) / TWO_PI
        for c0 in range(0, self.n_samples, chunk):
            c1 = min(c0 + chunk, self.n_samples)
            t = np.arange(c0, c1, dtype=float) / c.fs
            th = self.motion.theta_ref(t)
            M = M_per_ref * th
            out = {}
            for j, ch in enumerate(self.channels):
                if ch.kind == "tacho":
                    x = self._tacho_from_ref(th)
                    x = x + ch.noise_rms * rngs[j].standard_normal(t.size)
                elif ch.kind == "encoder":
                    x = self._encoder_from_ref(th)
                    x = x + ch.noise_rms * rngs[j].standard_normal(t.size)
                else:
                    x = self._gauge_from_cycles(ch.kind, M)
                    if ch.noise_rms > 0:
                        x = x + ch.noise_rms * rngs[j].standard_normal(t.size)
                    x = x + c.hum * ch.peak * np.sin(TWO_PI * c.hum_hz * t + self._hum_phase[j])
                    x = x + c.drift * ch.peak * self._drift_sign[j] * -np.expm1(-t / c.drift_tau)
                if c.adc_bits is not None:
                    q, lsb = self._quantise(x, ch.full_scale)
                    x = q if counts else q * lsb
                out[ch.name] = x
            for i0 in range(c0, c1, block):
                i1 = min(i0 + block, c1)
                yield i0, i1, {k: v[i0 - c0:i1 - c0] for k, v in out.items()}

    def _quantise(self, x, full_scale):
        bits = self.config.adc_bits
        lsb = 2.0 * full_scale / 2 ** bits
        q = np.clip(np.round(x / lsb), -(2 ** (bits - 1)), 2 ** (bits - 1) - 1)
        return q.astype(np.int16 if bits == 16 else np.int32), lsb

    def lsb(self, name: str) -> float:
        """ADC step of a channel [strain or V] (needs adc_bits)."""
        if self.config.adc_bits is None:
            raise ValueError("no quantisation configured (adc_bits=None)")
        ch = {c.name: c for c in self.channels}.get(name)
        if ch is None:
            raise ValueError(f"no channel {name!r}; have {[c.name for c in self.channels]}")
        return 2.0 * ch.full_scale / 2 ** self.config.adc_bits


# ----------------------------------------------------------------------------- TDMS
#: gauge unit strings write_rig_tdms writes -> stored value per m/m
_GAUGE_UNITS = {"Strain": 1.0, "µε": 1e6}


def write_rig_tdms(rig: Rig, path: str | Path, *, samples_per_segment: int = 1000, interleaved: bool = False,
                   storage: str = "float64", write_truth: bool = True,
                   gauge_unit: str = "Strain") -> RigTruth:
    """Stream a rig's recording to an NI-style TDMS file, segment by segment, plus its truth.

    Parameters
    ----------
    rig : Rig
    path : str or Path
        Output ``.tdms`` file (overwritten).
    samples_per_segment : int
        Samples per channel per segment (NI-DAQmx logs e.g. 1000; 512 works too).
    interleaved : bool
        Must be False: npTDMS's public writer only writes non-interleaved segments.
    storage : {"float64", "int"}
        float64 physical values, or quantised ADC counts (int16 / int32 for 16 / 24 bit) with
        an NI linear scale (needs ``adc_bits``).
    write_truth : bool
        Also write the JSON sidecar (:func:`truth_path`).
    gauge_unit : {"Strain", "µε"}
        ``unit_string`` of the strain gauges: "Strain" (m/m, NI's name) or "µε" (the samples
        written x 1e6, as a DAQ set to microstrain logs them); float64 storage only.

    Returns
    -------
    RigTruth
    """
    _choice("gauge_unit", gauge_unit, tuple(_GAUGE_UNITS))
    if not isinstance(rig, Rig):
        raise TypeError(f"rig must be a Rig, got {type(rig).__name__}")
    if not isinstance(path, (str, Path)):
        raise TypeError(f"path must be str or Path, got {type(path).__name__}")
    path = Path(path)
    nseg = _int("samples_per_segment", samples_per_segment, 1)
    if not isinstance(interleaved, (bool, np.bool_)):
        raise TypeError(f"interleaved must be a bool, got {interleaved!r}")
    if interleaved:
        raise ValueError("interleaved=True is not possible: npTDMS's public TdmsWriter writes "
                         "non-interleaved segments only")
    _choice("storage", storage, ("float64", "int"))
    c = rig.config
    if storage == "int" and c.adc_bits is None:
        raise ValueError("storage='int' needs adc_bits (16 or 24)")
    if storage == "int" and gauge_unit != "Strain":
        raise ValueError(f"gauge_unit={gauge_unit!r} needs storage='float64'")
    per_unit = {ch.name: _GAUGE_UNITS[gauge_unit] if ch.unit == "Strain" else 1.0
                for ch in rig.channels}
    start = np.datetime64(c.start_time, "us")
    props = {}
    for ch in rig.channels:
        p = {
            "NI_ChannelName": ch.name,
            "unit_string": gauge_unit if ch.unit == "Strain" else ch.unit,
            "NI_UnitDescription": "Strain" if ch.unit == "Strain" else "Volts",
            "wf_increment": 1.0 / c.fs,
            "wf_start_time": start,
            "wf_start_offset": 0.0,
            "wf_samples": nseg,
            "wf_xname": "Time",
            "wf_xunit_string": "s",
            "description": ("carrier once-per-revolution tacho (TTL)" if ch.kind == "tacho"
                            else f"{c.encoder[0]} shaft encoder, {c.encoder[1]} pulses per revolution (TTL)"
                            if ch.kind == "encoder"
                            else f"tooth-root strain gauge, {ch.kind} tooth "
                                 f"{c.sun_tooth if ch.kind == 'sun' else c.ring_tooth}"),
        }
        if storage == "int":
            p.update({
                "NI_Scaling_Status": "unscaled",
                "NI_Number_Of_Scales": 1,
                "NI_Scale[0]_Scale_Type": "Linear",
                "NI_Scale[0]_Linear_Slope": rig.lsb(ch.name),
                "NI_Scale[0]_Linear_Y_Intercept": 0.0,
                "NI_Scale[0]_Linear_Input_Source": np.uint32(0xFFFFFFFF),
            })
        props[ch.name] = p
    root_props = {"name": path.stem, "author": "independent rig generator (tests/independent/rig.py)",
                  "description": "planetary gear rig: tooth-root strain and carrier tacho", "datetime": start}
    n_written = 0
    with TdmsWriter(str(path)) as w:
        for i0, _, data in rig.iter_blocks(nseg, counts=(storage == "int")):
            objs = []
            if i0 == 0:
                objs += [RootObject(root_props), GroupObject(c.group, {"description": "strain gauges and tacho"})]
            for ch in rig.channels:
                x = data[ch.name] if per_unit[ch.name] == 1.0 else data[ch.name] * per_unit[ch.name]
                objs.append(ChannelObject(c.group, ch.name, x, props[ch.name] if i0 == 0 else None))
            w.write_segment(objs)
            n_written += 1
    truth = rig.truth(tdms={"samples_per_segment": nseg, "segments": n_written, "storage": storage,
                            "interleaved": False, "group": c.group,
                            "toc": "kTocMetaData|kTocRawData|kTocNewObjList in every segment"},
                      file=path.name)
    if write_truth:
        truth_path(path).write_text(truth.to_json())
    return truth


def _planets(planets: Any, z: Sequence[int], carrier_radius: float) -> Gearset:
    if isinstance(z, (str, bytes)) or not isinstance(z, (Sequence, np.ndarray)) or len(z) != 3:
        raise TypeError(f"z must be (Z_s, Z_r, Z_p), got {z!r}")
    if isinstance(planets, numbers.Integral) and not isinstance(planets, bool):
        return Gearset.equally_spaced(*z, planets, carrier_radius)
    if isinstance(planets, Mapping) and "positions" in planets:
        return Gearset.from_assembly_positions(*z, planets["positions"], carrier_radius)
    return Gearset(*z, planet_angles=_real_tuple("planets", planets), carrier_radius=carrier_radius)


def make_rig_config(*, minutes: float, ripple: Sequence = (), ramp: float = 0.0, planets: Any = 4,
                    z: Sequence[int] = (25, 87, 29), fixed: str = "ring", sun_rpm: float | None = 18.19,
                    carrier_rpm: float | None = None, snr_db: float | None = 20.0, tacho: bool = True,
                    seed: int | None = 0, errors: Any = None, load_sharing: Sequence[float] | None = None,
                    carrier_radius: float = 0.1125, fs: float = 5120.0, **options) -> RigConfig:
    """A :class:`RigConfig` from engineering-style keywords (what :func:`make_rig_tdms` takes).

    Parameters
    ----------
    minutes : float
        Record length [min].
    ripple : sequence
        Ripple terms (RippleTerm, mapping or ``(amplitude, order, member[, phase])``).
    ramp : float
        Relative speed change over the record [-] (0.1 = +10 %, centred on nominal).
    planets : int, sequence of float, or {"positions": [p_n]}
        N equally spaced planets, planet angles [rad], or assembly positions p_n
        (``psi_n = 2 pi p_n / (Z_s + Z_r)``).
    z : (int, int, int)
        (Z_s, Z_r, Z_p).
    fixed : {"ring", "sun", "carrier"}
    sun_rpm, carrier_rpm : float or None
        Nominal speed of the sun or of the carrier [r/min] (``carrier_rpm`` wins when both
        are given). Negative: the other sense (ccw planets).
    snr_db : float or None
        Gauge SNR [dB]; None: no noise.
    tacho : bool
    seed : int or None
    errors : HoleErrors, mapping or None
        Shaft-hole errors [m, rad].
    load_sharing : sequence of float or None
    carrier_radius : float
        [m].
    fs : float
        [Hz].
    **options
        Any other :class:`RigConfig` field (e.g. ``adc_bits``, ``hum``, ``drift``,
        ``sun_tooth_angle0``, ``ring_gauge_angle``, ``tacho_edge_angle``, ``start_time``).
    """
    m = _positive("minutes", minutes)
    gs = _planets(planets, z, carrier_radius)
    if carrier_rpm is not None:
        member, rpm = "carrier", carrier_rpm
    elif sun_rpm is not None:
        member, rpm = "sun", sun_rpm
    else:
        raise ValueError("give sun_rpm or carrier_rpm")
    if isinstance(ripple, (str, bytes)) or not isinstance(ripple, (Sequence, np.ndarray)):
        raise TypeError(f"ripple must be a sequence of ripple terms, got {type(ripple).__name__}")
    return RigConfig(gearset=gs, duration=60.0 * m, fixed=fixed, speed_member=member, speed_rpm=rpm,
                     ripple=tuple(ripple), ramp=ramp, errors=HoleErrors.coerce(errors),
                     load_sharing=None if load_sharing is None else tuple(load_sharing),
                     fs=fs, snr_db=snr_db, tacho=tacho, seed=seed, **options)


def make_rig_tdms(path: str | Path, *, minutes: float, samples_per_segment: int = 1000,
                  interleaved: bool = False, storage: str = "float64", **config) -> RigTruth:
    """Generate one rig recording as NI-style TDMS plus its truth sidecar.

    Parameters
    ----------
    path : str or Path
        Output ``.tdms`` file; the truth goes to :func:`truth_path` (path).
    minutes : float
        Record length [min].
    samples_per_segment, interleaved, storage
        See :func:`write_rig_tdms`.
    **config
        Keywords of :func:`make_rig_config`: ``ripple``, ``ramp``, ``planets``,
        ``z=(25, 87, 29)``, ``fixed="ring"``, ``sun_rpm=18.19``, ``carrier_rpm``,
        ``snr_db=20``, ``tacho=True``, ``seed=0``, ``errors``, ``load_sharing``, and any
        :class:`RigConfig` field.

    Returns
    -------
    RigTruth
    """
    cfg = make_rig_config(minutes=minutes, **config)
    return write_rig_tdms(Rig(cfg), path, samples_per_segment=samples_per_segment, interleaved=interleaved,
                          storage=storage)


_R1 = ((0.01, 1.0, "carrier", 0.0),)
_DEG = math.pi / 180.0

#: Named scenarios. The first five match the outside tester's table; the rest are variants of
#: the ordinary 1 % carrier-rate drive ripple (``_R1``). Values are keyword arguments of
#: :func:`make_rig_tdms`.
PRESETS: dict[str, dict] = {
    # outside tester's table
    "steady": {},
    "ripple1_carrier": {"ripple": _R1},
    "ripple3_carrier": {"ripple": ((0.03, 1.0, "carrier", 0.0),)},
    "ripple1_ramp10": {"ripple": _R1, "ramp": 0.10},
    "five_planets_ripple1": {"z": (25, 85, 30), "planets": 5, "ripple": _R1, "carrier_radius": 0.110},
    # further cases
    "ripple1_sun": {"ripple": ((0.01, 1.0, "sun", 0.0),)},
    "ramp_down": {"ripple": _R1, "ramp": -0.10},
    "ccw": {"ripple": _R1, "sun_rpm": -18.19},
    "unequal3": {"ripple": _R1, "planets": {"positions": (0, 37, 75)}},
    "no_tacho": {"ripple": _R1, "tacho": False},
    "snr10": {"ripple": _R1, "snr_db": 10.0},
    "hole_errors_case1": {"errors": {"e_sun": 0.2e-3, "kappa_sun": 4 * _DEG, "e_ring": 0.2e-3,
                                     "kappa_ring": 60 * _DEG, "e_planet": (0.2e-3,) * 4,
                                     "kappa_planet": (20 * _DEG,) * 4}},
    "planet_ripple1_encoder": {"ripple": ((0.01, 1.0, "planet", 0.0),), "encoder": ("sun", 60)},
}


def preset_config(name: str, *, minutes: float, **overrides) -> RigConfig:
    """:func:`make_rig_config` of a named :data:`PRESETS` entry (``overrides`` win)."""
    _choice("name", name, tuple(PRESETS))
    return make_rig_config(minutes=minutes, **{**PRESETS[name], **overrides})


def make_preset_tdms(path: str | Path, name: str, *, minutes: float, samples_per_segment: int = 1000,
                     storage: str = "float64", **overrides) -> RigTruth:
    """:func:`make_rig_tdms` with a named :data:`PRESETS` entry (``overrides`` win)."""
    return write_rig_tdms(Rig(preset_config(name, minutes=minutes, **overrides)), path,
                          samples_per_segment=samples_per_segment, storage=storage)
