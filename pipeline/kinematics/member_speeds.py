"""Every member's measured speed: sun, carrier, ring and planet spin.

The fitted angle model gives the mean mesh frequency f_m [cycles/s] over the record; the
tooth counts turn it into the speeds relative to the carrier (Willis):

    |w_s - w_c| = 2 pi f_m / Z_s,   w_r - w_c = -(Z_s / Z_r)(w_s - w_c),
    w_p - w_c = -(Z_s / Z_p)(w_s - w_c).

One more fact fixes the carrier: a held ring (w_c = -(w_r - w_c)), a held sun
(w_c = -(w_s - w_c)), else the carrier tacho's count of turns per second or, without a tacho,
the nominal ratio of carrier to sun-relative speed. The sense of the sun relative to the
carrier is the nominal speeds', else the gearset's direction
(:func:`meshphase.kinematics.pass_table.pass_order`, as :func:`meshphase.compare.pass_model.relative_speeds`).
"""

from __future__ import annotations

import math

import numpy as np

from .trains import revolution_numbers
from ..models.gearset import Gearset, Speeds
from .pass_table import pass_order
from ..validate import as_positive

__all__ = ["member_speeds", "mean_mesh_rate", "tacho_rate"]

TWO_PI = 2.0 * math.pi
#: [rad/s] -> [r/min]
RPM = 60.0 / TWO_PI


def mean_mesh_rate(model) -> float:
    """Mean mesh frequency [cycles/s] of a fitted angle model over its span: the mesh angle
    it turned between its first and last observation over the time between them.

    Parameters
    ----------
    model : meshphase.kinematics.angles.AngleModel
        Anything with ``t_span`` (first, last time [s]) and ``mesh_angle(t)`` [mesh cycles].

    Returns
    -------
    float
        NaN for a model spanning no time.
    """
    span = getattr(model, "t_span", None)
    if span is None or not callable(getattr(model, "mesh_angle", None)):
        raise TypeError(f"model must be a fitted angle model (t_span, mesh_angle), got "
                        f"{type(model).__name__}")
    t0, t1 = (float(x) for x in span)
    if not (math.isfinite(t0) and math.isfinite(t1)) or t1 <= t0:
        return float("nan")
    a = np.asarray(model.mesh_angle(np.array([t0, t1])), dtype=float)
    return float(abs(a[1] - a[0]) / (t1 - t0))


def tacho_rate(tacho_times) -> float:
    """Carrier revolutions per second [1/s] between the first and last once-per-turn tacho
    edge (missed edges counted by :func:`meshphase.kinematics.trains.revolution_numbers`); NaN with
    fewer than two edges."""
    if tacho_times is None:
        return float("nan")
    t = np.asarray(tacho_times, dtype=float)
    if t.ndim != 1:
        raise ValueError(f"tacho_times must be 1-D, got shape {t.shape}")
    if t.size < 2:
        return float("nan")
    k = revolution_numbers(t)
    return float((k[-1] - k[0]) / (t[-1] - t[0]))


def member_speeds(gearset: Gearset, mesh_rate: float, *, fixed: str | None,
                  speeds: Speeds | None = None, carrier_rate: float | None = None) -> dict:
    """Each member's speed from the measured mesh frequency [r/min].

    Parameters
    ----------
    gearset : Gearset
        Tooth counts Z_s, Z_r, Z_p [-] (Z_p = 0: no planet spin) and direction.
    mesh_rate : float
        Measured mean mesh frequency [cycles/s] (:func:`mean_mesh_rate`).
    fixed : {"ring", "sun", None}
        The held member (:func:`meshphase.kinematics.shafts.held_member`).
    speeds : Speeds, optional
        Nominal speeds [rad/s]: the senses, and a differential's carrier ratio when no tacho
        rate is given.
    carrier_rate : float, optional
        Measured carrier revolutions per second [1/s] (:func:`tacho_rate`); used when no
        member is held.

    Returns
    -------
    dict
        ``sun``, ``carrier``, ``ring``, ``planet`` (absolute spin), ``planet_relative``
        (spin relative to the carrier) [r/min], counter-clockwise positive, NaN where unknown;
        ``mesh_rate_hz`` [cycles/s]; ``held`` (the held member or None); ``carrier_from``
        (how the carrier was found); ``text`` (one sentence).

    Raises
    ------
    TypeError
        ``gearset`` or ``speeds`` of the wrong type.
    ValueError
        ``mesh_rate`` not a positive number, ``fixed`` not one of the choices.
    """
    if not isinstance(gearset, Gearset):
        raise TypeError(f"gearset must be a Gearset, got {type(gearset).__name__}")
    if speeds is not None and not isinstance(speeds, Speeds):
        raise TypeError(f"speeds must be a Speeds or None, got {type(speeds).__name__}")
    if fixed not in ("ring", "sun", None):
        raise ValueError(f"fixed must be 'ring', 'sun' or None, got {fixed!r}")
    f_m = as_positive(mesh_rate, "mesh_rate")
    zs, zr, zp = float(gearset.z_sun), float(gearset.z_ring), float(gearset.z_planet)
    sense = pass_order(gearset.direction, "sun")
    if speeds is not None and speeds.w_sc != 0:
        sense = math.copysign(1.0, speeds.w_sc)
    w_sc = sense * TWO_PI * f_m / zs
    w_rc = -w_sc * zs / zr
    w_pc = -w_sc * zs / zp if zp > 0 else float("nan")
    rate = float("nan") if carrier_rate is None else float(carrier_rate)
    if fixed == "ring":
        w_c, how = -w_rc, "ring held"
    elif fixed == "sun":
        w_c, how = -w_sc, "sun held"
    elif math.isfinite(rate) and rate > 0:
        c_sense = math.copysign(1.0, speeds.carrier) if speeds is not None and speeds.carrier else sense
        w_c = c_sense * TWO_PI * rate
        how = "carrier tacho" + ("" if speeds is not None and speeds.carrier else
                                 " (sense taken as the sun's: no nominal speeds)")
    elif speeds is not None and speeds.w_sc != 0:
        w_c, how = w_sc * speeds.carrier / speeds.w_sc, "nominal carrier / sun-relative ratio"
    else:
        w_c, how = float("nan"), "unknown: no member held, no tacho, no nominal speeds"
    out = {"sun": (w_c + w_sc) * RPM, "carrier": w_c * RPM, "ring": (w_c + w_rc) * RPM,
           "planet": (w_c + w_pc) * RPM, "planet_relative": w_pc * RPM,
           "mesh_rate_hz": f_m, "held": fixed, "carrier_from": how}
    out["text"] = _speeds_text(out)
    return out


def _speeds_text(sp: dict) -> str:
    """One sentence: every member's speed and which one is held."""
    def r(x):
        return "unknown" if not math.isfinite(x) else f"{x:.4g} r/min"
    held = sp["held"]
    if held is not None:
        head = f"{held} held"
    elif sp["carrier"] == 0.0 and math.isfinite(sp["ring"]):
        head = f"carrier held (a star arrangement): the ring turns at {r(sp['ring'])}"
    elif math.isfinite(sp["ring"]):
        head = f"none held: the ring turns at {r(sp['ring'])}"
    else:
        head = "none held"
    return (f"{head}; sun {r(sp['sun'])}, carrier {r(sp['carrier'])}, ring {r(sp['ring'])}, "
            f"planet spin {r(sp['planet_relative'])} relative to the carrier "
            f"({r(sp['planet'])} absolute); mesh frequency {sp['mesh_rate_hz']:.5g} Hz "
            f"(carrier from: {sp['carrier_from']})")
