"""Gearset geometry and operating speeds shared by every model.

All values are SI: lengths [m], angles [rad], speeds [rad/s]. Scene files and reports may
speak mm, deg and r/min; they convert once, at the boundary, with the helpers at the bottom
of this module.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..validate import as_choice, as_float, as_positive, as_positive_int

__all__ = ["Gearset", "Speeds", "rpm_to_rad_s", "rad_s_to_rpm", "DIRECTIONS"]

DIRECTIONS = ("cw", "ccw")


def rpm_to_rad_s(rpm: float) -> float:
    """Convert a speed in [r/min] to [rad/s]."""
    return float(rpm) * 2.0 * math.pi / 60.0


def rad_s_to_rpm(w: float) -> float:
    """Convert a speed in [rad/s] to [r/min]."""
    return float(w) * 60.0 / (2.0 * math.pi)


@dataclass(frozen=True)
class Gearset:
    """A simple planetary gearset (sun, N planets on a carrier, ring).

    Parameters
    ----------
    z_sun, z_ring, z_planet : int
        Tooth counts [-]. ``z_planet`` may be 0 when unknown (it only enters planet speed).
    planet_angles : tuple of float
        Planet centre angles psi_n in the carrier frame [rad], counter-clockwise positive,
        planet 1 first (conventionally at 0).
    carrier_radius : float
        Carrier radius R_c, sun centre to planet centre [m].
    direction : {"cw", "ccw"}
        Planet rotation direction that fixes the sign convention of the phasing
        (spec section 1: clockwise gives gamma_sn = +Z_s psi_n / 2 pi).
    name : str
        Free label used in reports.
    face_width : float, optional
        Face width b [m] (needed by the face-width / tilt models only).
    """

    z_sun: int
    z_ring: int
    z_planet: int
    planet_angles: tuple[float, ...]
    carrier_radius: float
    direction: str = "cw"
    name: str = ""
    face_width: float | None = None
    meta: dict = field(default_factory=dict, compare=False, hash=False)

    def __post_init__(self):
        object.__setattr__(self, "z_sun", as_positive_int(self.z_sun, "z_sun"))
        object.__setattr__(self, "z_ring", as_positive_int(self.z_ring, "z_ring"))
        zp = self.z_planet
        if zp is None:
            zp = 0
        zp = int(zp) if not isinstance(zp, bool) else zp
        if isinstance(zp, bool) or zp < 0:
            raise ValueError(f"z_planet must be a non-negative integer, got {self.z_planet!r}")
        object.__setattr__(self, "z_planet", zp)
        if self.z_ring <= self.z_sun:
            raise ValueError(f"z_ring must exceed z_sun, got z_ring={self.z_ring}, z_sun={self.z_sun}")
        try:
            angles = tuple(float(a) for a in np.atleast_1d(np.asarray(self.planet_angles, dtype=float)))
        except (TypeError, ValueError) as exc:
            raise TypeError(f"planet_angles must be a sequence of angles [rad], got {self.planet_angles!r}") from exc
        if len(angles) == 0:
            raise ValueError("planet_angles must hold at least one planet angle [rad], got none")
        if not all(math.isfinite(a) for a in angles):
            raise ValueError(f"planet_angles must be finite, got {angles!r}")
        object.__setattr__(self, "planet_angles", angles)
        object.__setattr__(self, "carrier_radius", as_positive(self.carrier_radius, "carrier_radius"))
        object.__setattr__(self, "direction", as_choice(self.direction, "direction", DIRECTIONS))
        if self.face_width is not None:
            object.__setattr__(self, "face_width", as_positive(self.face_width, "face_width"))

    @classmethod
    def equally_spaced(cls, z_sun: int, z_ring: int, z_planet: int, n_planets: int,
                       carrier_radius: float, **kwargs) -> "Gearset":
        """Gearset with ``n_planets`` planets at psi_n = 2 pi (n - 1) / N [rad]."""
        n = as_positive_int(n_planets, "n_planets")
        angles = tuple(2.0 * math.pi * k / n for k in range(n))
        return cls(z_sun, z_ring, z_planet, angles, carrier_radius, **kwargs)

    @property
    def n_planets(self) -> int:
        """Number of planets N [-]."""
        return len(self.planet_angles)

    @property
    def angles(self) -> np.ndarray:
        """Planet angles psi_n as an array [rad]."""
        return np.asarray(self.planet_angles, dtype=float)

    @property
    def ratio_fixed_ring(self) -> float:
        """Sun-to-carrier speed ratio with the ring held, 1 + Z_r / Z_s [-]."""
        return 1.0 + self.z_ring / self.z_sun

    def to_dict(self) -> dict:
        """JSON-friendly dict (SI units)."""
        return {
            "z_sun": self.z_sun, "z_ring": self.z_ring, "z_planet": self.z_planet,
            "planet_angles": list(self.planet_angles), "carrier_radius": self.carrier_radius,
            "direction": self.direction, "name": self.name, "face_width": self.face_width,
        }

    @classmethod
    def from_dict(cls, d: dict) -> "Gearset":
        """Inverse of :meth:`to_dict`."""
        keys = ("z_sun", "z_ring", "z_planet", "planet_angles", "carrier_radius", "direction",
                "name", "face_width")
        return cls(**{k: d[k] for k in keys if k in d})


@dataclass(frozen=True)
class Speeds:
    """Absolute angular speeds of the members [rad/s], counter-clockwise positive.

    Parameters
    ----------
    sun, carrier : float
        Sun and carrier speeds [rad/s].
    planet : float
        Absolute planet speed [rad/s] (about its own axis, in the ground frame).
    ring : float
        Ring speed [rad/s]; 0 for a fixed ring.
    """

    sun: float
    carrier: float
    planet: float
    ring: float = 0.0

    def __post_init__(self):
        for name in ("sun", "carrier", "planet", "ring"):
            object.__setattr__(self, name, as_float(getattr(self, name), name))

    @classmethod
    def kinematic(cls, gearset: Gearset, sun: float, carrier: float) -> "Speeds":
        """Speeds consistent with the tooth counts (Willis), given sun and carrier [rad/s].

        w_r - w_c = -(Z_s / Z_r)(w_s - w_c) and w_p - w_c = -(Z_s / Z_p)(w_s - w_c).
        Needs ``gearset.z_planet > 0``.
        """
        sun = as_float(sun, "sun")
        carrier = as_float(carrier, "carrier")
        if gearset.z_planet <= 0:
            raise ValueError("Speeds.kinematic needs gearset.z_planet > 0, got 0")
        ring = carrier - gearset.z_sun / gearset.z_ring * (sun - carrier)
        planet = carrier - gearset.z_sun / gearset.z_planet * (sun - carrier)
        return cls(sun=sun, carrier=carrier, planet=planet, ring=ring)

    @property
    def w_sc(self) -> float:
        """Sun speed relative to the carrier, w_s - w_c [rad/s]."""
        return self.sun - self.carrier

    @property
    def w_pc(self) -> float:
        """Planet speed relative to the carrier, w_p - w_c [rad/s]."""
        return self.planet - self.carrier

    @property
    def w_rc(self) -> float:
        """Ring speed relative to the carrier, w_r - w_c [rad/s] (-w_c for a fixed ring)."""
        return self.ring - self.carrier

    def to_dict(self) -> dict:
        return {"sun": self.sun, "carrier": self.carrier, "planet": self.planet, "ring": self.ring}
