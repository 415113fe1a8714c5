"""What the tooth counts and the speeds say about the shafts, in mesh cycles.

:func:`kinematics` gives the mesh cycles per turn of every shaft whose speed ripple the angle
model can follow (:class:`Kinematics`), :func:`shaft_cycles` those of an encoder's shaft,
:func:`held_member` which member is held (from the nominal speeds within what their typed
digits leave open, :func:`typed_resolution`, or from the measured mesh and carrier rates).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .encoder import shaft_of

__all__ = ["Kinematics", "kinematics", "shaft_cycles", "typed_resolution", "held_member"]


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


def shaft_cycles(kin: Kinematics, shaft: str) -> float:
    """Mesh cycles per revolution of an encoder's shaft [mesh cycles].

    Parameters
    ----------
    kin : Kinematics
        Tooth counts and the held member (:func:`kinematics`).
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
        raise TypeError(f"kin must be a Kinematics (meshphase.kinematics.shafts.kinematics), got "
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
