"""Geometry shared by :mod:`.mesh_phasing` and :mod:`.tolerance` (spec section 2).

One home for what both modules need: the exact reduction of rotation angles (Cody-Waite
with a Veltkamp-split product), the :class:`ShaftHoleErrors` container and its broadcasting
to (realisations, planets), the bound e_sun + e_planet < R_c, and the argument checks of
:class:`~meshphase.models.gearset.Gearset`, :class:`~meshphase.models.gearset.Speeds` and
the planet rotation direction. The conventions are those of :mod:`.mesh_phasing` (carrier
frame, counter-clockwise phases); the public names are re-exported there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..validate import as_choice, as_finite_array, as_float
from .gearset import DIRECTIONS, Gearset, Speeds

__all__ = [
    "TWO_PI",
    "MAX_PHASE",
    "ShaftHoleErrors",
    "reduce_angle",
    "rotation_angle",
    "rotation_cos_sin",
]

TWO_PI = 2.0 * math.pi
# 2 pi = _C1 + _C2 + _C3 + O(5e-29): _C1 and _C2 carry 20 significant bits each, so n * _C1 and
# n * _C2 are exact for |n| < 2**33 (Cody-Waite reduction).
_C1 = float.fromhex("0x1.921fa00000000p+2")
_C2 = float.fromhex("0x1.5444200000000p-18")
_C3 = float.fromhex("0x1.a308d313198a3p-39")
_INV_TWO_PI = 1.0 / TWO_PI
_SPLIT = 134217729.0  # 2**27 + 1 (Veltkamp)
#: Largest |angle| [rad] that :func:`reduce_angle` / :func:`rotation_angle` reduce exactly.
MAX_PHASE = 5.0e10


# ----------------------------------------------------------------------------- angle reduction

def reduce_angle(x: ArrayLike) -> np.ndarray:
    """Reduce angles modulo 2 pi into [-pi, pi] with ~1 ulp error.

    Parameters
    ----------
    x : array_like
        Angles [rad], finite, ``|x| <= MAX_PHASE`` (5e10 rad).

    Returns
    -------
    numpy.ndarray
        ``x - 2 pi n`` with ``n = round(x / 2 pi)`` [rad], same shape as ``x``.

    Notes
    -----
    Cody-Waite reduction with 2 pi split into three doubles (the first two with 20 significant
    bits, so ``n * C1`` and ``n * C2`` are exact for ``|n| < 2**33``). The subtractions
    ``x - n C1`` and ``(x - n C1) - n C2`` are exact (Sterbenz) and only the last one rounds,
    so the result carries ~1 ulp of pi; ``np.fmod(x, 2 pi)`` would carry ``x * 2.4e-16``.
    """
    x = as_finite_array(x, "x")
    if x.size and np.max(np.abs(x)) > MAX_PHASE:
        raise ValueError(f"x must satisfy |x| <= {MAX_PHASE:g} rad for exact reduction, "
                         f"got max |x| = {float(np.max(np.abs(x))):g}")
    return reduce_unchecked(x)


def reduce_unchecked(x):
    n = np.rint(x * _INV_TWO_PI)
    return ((x - n * _C1) - n * _C2) - n * _C3


def _split(x):
    c = _SPLIT * x
    hi = c - (c - x)
    return hi, x - hi


def rotation_angle(w: float, t: ArrayLike, phase: ArrayLike = 0.0) -> np.ndarray:
    """The angle ``w t + phase`` reduced into [-pi, pi], computed without losing digits.

    Parameters
    ----------
    w : float
        Angular speed [rad/s].
    t : array_like
        Times [s].
    phase : array_like
        Angle added at t = 0 [rad] (broadcast against ``t``).

    Returns
    -------
    numpy.ndarray
        Reduced angle [rad], shape ``broadcast(t, phase)``.

    Notes
    -----
    The product ``w t`` is split error-free (Veltkamp: w = wh + wl, t = th + tl with 26-bit
    halves, so wh th, wh tl, wl th, wl tl are exact doubles) and each partial product is
    reduced on its own with :func:`reduce_angle`; the reduced parts (each in [-pi, pi]) are
    summed and reduced once more. The error is a few ulp of pi (~1e-15 rad) for
    ``|w t| <= MAX_PHASE``, against ``|w t| * 1.1e-16`` for the naive ``np.mod(w * t, 2 pi)``
    (4e-8 rad at w = 350 rad/s, t = 1e6 s).
    """
    w = as_float(w, "w")
    t = as_finite_array(t, "t")
    phase = as_finite_array(phase, "phase")
    if t.size and abs(w) * float(np.max(np.abs(t))) > MAX_PHASE:
        raise ValueError(f"|w t| must be <= {MAX_PHASE:g} rad for exact reduction, got "
                         f"w = {w!r} rad/s and max |t| = {float(np.max(np.abs(t))):g} s; "
                         "shift the time origin")
    if phase.size and np.max(np.abs(phase)) > MAX_PHASE:
        raise ValueError(f"phase must satisfy |phase| <= {MAX_PHASE:g} rad")
    return rotation_angle_unchecked(w, t, phase)


def rotation_angle_unchecked(w, t, phase=0.0):
    if w == 0.0:
        r = np.zeros_like(t)
    else:
        wh, wl = _split(np.float64(w))
        th, tl = _split(t)
        r = reduce_unchecked(reduce_unchecked(wh * th) + reduce_unchecked(wh * tl)
                             + reduce_unchecked(wl * th) + wl * tl)
    if np.ndim(phase) == 0 and float(phase) == 0.0:
        return r
    return reduce_unchecked(r + reduce_unchecked(np.asarray(phase, dtype=float)))


def rotation_cos_sin(w: float, t: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """cos and sin of ``w t`` [-] for times ``t`` [s] at speed ``w`` [rad/s], reduced exactly.

    See :func:`rotation_angle`. Returns two arrays shaped like ``t``.
    """
    r = rotation_angle(w, t)
    return np.cos(r), np.sin(r)


# ----------------------------------------------------------------------------- errors container

def _as_error_field(value, name, *, radial):
    arr = as_finite_array(value, name)
    if radial and arr.size and np.any(arr < 0.0):
        raise ValueError(f"{name} must be >= 0 [m] (a radial size; turn the angle by pi for the "
                         f"opposite direction), got min {float(np.min(arr))!r}")
    if (not radial) and arr.size and np.max(np.abs(arr)) > MAX_PHASE:
        raise ValueError(f"{name} must satisfy |{name}| <= {MAX_PHASE:g} rad")
    return arr


@dataclass(frozen=True, eq=False)
class ShaftHoleErrors:
    """Radial [m] and angular [rad] gear shaft hole position errors.

    Every field broadcasts. Leading dimensions are realisations (e.g. Monte Carlo samples);
    the planet fields carry a trailing planet axis of length ``n_planets`` or 1 (a 0-d planet
    field applies to every planet). To give per-realisation planet errors that are the same
    for every planet, use shape ``(S, 1)``.

    Parameters
    ----------
    e_sun, e_ring : array_like
        Radial offsets of the sun and ring pitch circle centres [m], >= 0.
    kappa_sun, kappa_ring : array_like
        Offset angles at t = 0, from the carrier +x axis (planet 1 direction) [rad].
    e_planet : array_like
        Radial offsets of the planet pitch circle centres [m], >= 0, trailing planet axis.
    kappa_planet : array_like
        Offset angles at t = 0, measured counter-clockwise from the inward radial (the line
        from the ideal planet centre to the sun centre) [rad], trailing planet axis.

    Notes
    -----
    Values must be finite and radial sizes non-negative (ValueError otherwise). The bound
    ``e_sun + e_planet < R_c`` (and ``e_ring + e_planet < R_c``) is checked by the functions
    that know the gearset. Seed 000 Table 2 lists the angles of planet 1 only ("kappa_s1",
    "kappa_p1"); :func:`meshphase.models.tolerance.table2_case` applies them to every planet.
    """

    e_sun: ArrayLike = 0.0
    kappa_sun: ArrayLike = 0.0
    e_ring: ArrayLike = 0.0
    kappa_ring: ArrayLike = 0.0
    e_planet: ArrayLike = 0.0
    kappa_planet: ArrayLike = 0.0

    def __post_init__(self):
        for name in ("e_sun", "e_ring", "e_planet"):
            object.__setattr__(self, name, _as_error_field(getattr(self, name), name, radial=True))
        for name in ("kappa_sun", "kappa_ring", "kappa_planet"):
            object.__setattr__(self, name, _as_error_field(getattr(self, name), name, radial=False))

    @classmethod
    def from_mm_deg(cls, **kwargs) -> "ShaftHoleErrors":
        """Build from engineering units: ``e_*`` in [mm], ``kappa_*`` in [deg]."""
        out = {}
        for k, v in kwargs.items():
            if k.startswith("e_"):
                out[k] = np.asarray(v, dtype=float) * 1e-3
            elif k.startswith("kappa_"):
                out[k] = np.deg2rad(np.asarray(v, dtype=float))
            else:
                raise TypeError(f"unknown field {k!r}")
        return cls(**out)

    @property
    def is_zero(self) -> bool:
        """True when every radial error is exactly zero."""
        return all(not np.any(getattr(self, n)) for n in ("e_sun", "e_ring", "e_planet"))

    def sample_shape(self, n_planets: int) -> tuple[int, ...]:
        """Shape of the realisation (sample) dimensions for a gearset with ``n_planets``."""
        return broadcast_errors(self, n_planets)[0]


@dataclass(frozen=True)
class BroadcastErrors:
    shape: tuple
    es: np.ndarray
    ks: np.ndarray
    er: np.ndarray
    kr: np.ndarray
    ep: np.ndarray
    kp: np.ndarray


def _planet_field(arr, name, n_planets):
    if arr.ndim == 0:
        return arr[None]
    if arr.shape[-1] not in (1, n_planets):
        raise ValueError(f"{name} must have a trailing planet axis of length {n_planets} or 1, "
                         f"got shape {arr.shape}")
    return arr


def broadcast_errors(errors, n_planets):
    if errors is None:
        errors = ShaftHoleErrors()
    if not isinstance(errors, ShaftHoleErrors):
        raise TypeError(f"errors must be a ShaftHoleErrors or None, got {type(errors).__name__}")
    ep = _planet_field(errors.e_planet, "e_planet", n_planets)
    kp = _planet_field(errors.kappa_planet, "kappa_planet", n_planets)
    try:
        shape = np.broadcast_shapes(errors.e_sun.shape, errors.kappa_sun.shape,
                                    errors.e_ring.shape, errors.kappa_ring.shape,
                                    ep.shape[:-1], kp.shape[:-1])
    except ValueError as exc:
        raise ValueError(f"ShaftHoleErrors fields do not broadcast: {exc}") from None
    b = BroadcastErrors(shape=tuple(shape),
                   es=np.broadcast_to(errors.e_sun, shape),
                   ks=np.broadcast_to(errors.kappa_sun, shape),
                   er=np.broadcast_to(errors.e_ring, shape),
                   kr=np.broadcast_to(errors.kappa_ring, shape),
                   ep=np.broadcast_to(ep, shape + (n_planets,)),
                   kp=np.broadcast_to(kp, shape + (n_planets,)))
    return b.shape, b


def check_error_size(b, carrier_radius):
    """e_sun + e_planet < R_c and e_ring + e_planet < R_c (else the centres may coincide)."""
    if b.ep.size == 0:
        return
    ep_max = np.max(b.ep, axis=-1)
    for name, e in (("e_sun", b.es), ("e_ring", b.er)):
        tot = e + ep_max
        if np.any(tot >= carrier_radius):
            worst = float(np.max(tot))
            raise ValueError(f"{name} + e_planet must be < carrier_radius = {carrier_radius!r} m "
                             f"(the actual centres could coincide), got up to {worst!r} m")


# ----------------------------------------------------------------------------- argument checks

def check_gearset(gearset):
    if not isinstance(gearset, Gearset):
        raise TypeError(f"gearset must be a Gearset, got {type(gearset).__name__}")
    return gearset


def check_speeds(speeds):
    if not isinstance(speeds, Speeds):
        raise TypeError(f"speeds must be a Speeds, got {type(speeds).__name__}")
    return speeds


def direction_sign(direction):
    return 1.0 if as_choice(direction, "direction", DIRECTIONS) == "cw" else -1.0


def cos_sin(x):
    r = reduce_unchecked(np.asarray(x, dtype=float))
    return np.cos(r), np.sin(r)
