"""Can this planetary gearset be built? Coaxiality and planet tip clearance, in tooth counts.

Assembly itself (which planet angles fit the sun and ring teeth) is
:func:`meshphase.models.mesh_phasing.assembly_check`; this module adds the two other checks a
gearset must pass before any model of it means anything, both module-free (tooth counts and
angles only), so they run on a scene before anything else:

``coaxiality``
    With standard (unshifted) gears the sun-planet and planet-ring centre distances are
    m (Z_s + Z_p) / 2 and m (Z_r - Z_p) / 2; they are one carrier radius only when
    Z_r = Z_s + 2 Z_p. A gearset that breaks this can still be built with profile-shifted
    gears (a centre-distance modification), which the tooth counts cannot tell: a scene must
    declare it (``[gearset] profile_shift = true``).
``tip clearance``
    Neighbouring planets at angles Delta psi apart have centres 2 R_c sin(Delta psi / 2)
    apart and tip circles of diameter m (Z_p + 2) (addendum one module), so they clear each
    other only when (2 R_c / m) sin(Delta psi / 2) > Z_p + 2. For a coaxial gearset
    2 R_c / m = Z_s + Z_p, giving the classical condition for N equally spaced planets
    (Z_s + Z_p) sin(pi / N) > Z_p + 2 (e.g. Lynwander, *Gear Drive Systems*, 1983, ch. 5;
    Mueller's planetary design rules). With profile shift the carrier radius lies between the
    two standard centre distances; their mean, 2 R_c / m ~ (Z_s + Z_r) / 2, is used (equal
    to Z_s + Z_p when coaxial). The addendum of shifted gears is not known from tooth counts,
    so with profile shift this is an estimate.

All counts are integers [-]; angles [rad].
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from ..validate import as_finite_array, as_int, as_positive_int

__all__ = ["coaxiality_error", "tip_clearance", "max_equal_planets", "assemblable_planet_counts",
           "CLEARANCE_ATOL"]

TWO_PI = 2.0 * math.pi
#: tip circles closer than this [modules] count as touching, i.e. colliding (it absorbs the
#: float rounding of angles such as 2 pi k / N at an exact boundary like (Z_s + Z_p) sin(pi/6)
#: = Z_p + 2 for Z_s = Z_p + 4)
CLEARANCE_ATOL = 1e-9


def _counts(z_sun, z_ring, z_planet=None):
    zs = as_positive_int(z_sun, "z_sun")
    zr = as_positive_int(z_ring, "z_ring")
    if zr <= zs:
        raise ValueError(f"z_ring must exceed z_sun, got z_ring={zr}, z_sun={zs}")
    if z_planet is None:
        return zs, zr, None
    return zs, zr, as_positive_int(z_planet, "z_planet")


def coaxiality_error(z_sun: int, z_ring: int, z_planet: int) -> int:
    """Z_r - (Z_s + 2 Z_p) [teeth]: 0 for a coaxial gearset of standard gears.

    Parameters
    ----------
    z_sun, z_ring, z_planet : int
        Tooth counts [-].

    Returns
    -------
    int
        The ring's tooth count minus the one that would make the two centre distances equal
        with standard gears; twice the centre-distance mismatch in modules.
    """
    zs, zr, zp = _counts(z_sun, z_ring, z_planet)
    return zr - (zs + 2 * zp)


def tip_clearance(z_sun: int, z_ring: int, z_planet: int, planet_angles: ArrayLike) -> float:
    """Smallest gap between neighbouring planets' tip circles [modules].

    Parameters
    ----------
    z_sun, z_ring, z_planet : int
        Tooth counts [-].
    planet_angles : array_like
        Planet angles psi_n [rad], any order, shape (N,).

    Returns
    -------
    float
        min over neighbouring pairs of (Z_s + Z_r)/2 sin(Delta psi / 2) - (Z_p + 2): the
        centre distance of the two planets minus one tip diameter, both divided by the module
        (module 4 mm: a margin of 1.0 is 4 mm of clearance). Above ``CLEARANCE_ATOL`` the
        planets clear; at or below it they collide (touching tips included). ``inf`` for a
        single planet (nothing to collide with) and for empty ``planet_angles``.

    Notes
    -----
    See the module docstring; for a coaxial gearset (Z_s + Z_r)/2 = Z_s + Z_p and N equally
    spaced planets this is (Z_s + Z_p) sin(pi / N) - (Z_p + 2).
    """
    zs, zr, zp = _counts(z_sun, z_ring, z_planet)
    psi = np.atleast_1d(as_finite_array(planet_angles, "planet_angles"))
    if psi.ndim != 1:
        raise ValueError(f"planet_angles must be 1-D, got shape {psi.shape}")
    if psi.size < 2:
        return math.inf
    a = np.sort(np.mod(psi, TWO_PI))
    gaps = np.diff(np.append(a, a[0] + TWO_PI))
    # a half-angle of a gap past pi would wrap: sin(gap / 2) stays right for gap in [0, 2 pi]
    return float(0.5 * (zs + zr) * np.sin(0.5 * gaps.min()) - (zp + 2))


def max_equal_planets(z_sun: int, z_ring: int, z_planet: int) -> int:
    """Most equally spaced planets whose tip circles clear each other [-] (>= 1).

    Parameters
    ----------
    z_sun, z_ring, z_planet : int
        Tooth counts [-].
    """
    zs, zr, zp = _counts(z_sun, z_ring, z_planet)
    # sin(pi / N) > (Z_p + 2) / ((Z_s + Z_r) / 2) <=> N < pi / arcsin(ratio)
    ratio = (zp + 2) / (0.5 * (zs + zr))
    if ratio >= 1.0:
        return 1
    n = int(math.floor(math.pi / math.asin(ratio)))
    # the float boundary: step down while the strict inequality fails, up while the next fits
    while n > 1 and not tip_clearance(zs, zr, zp, TWO_PI * np.arange(n) / n) > CLEARANCE_ATOL:
        n -= 1
    while tip_clearance(zs, zr, zp, TWO_PI * np.arange(n + 1) / (n + 1)) > CLEARANCE_ATOL:
        n += 1
    return max(n, 1)


def assemblable_planet_counts(z_sun: int, z_ring: int, z_planet: int | None = None,
                              n_max: int = 64) -> list[int]:
    """Planet counts N that can be assembled equally spaced (N divides Z_s + Z_r) and, when
    ``z_planet`` is given, whose tip circles clear.

    Parameters
    ----------
    z_sun, z_ring : int
        Tooth counts [-].
    z_planet : int, optional
        Planet tooth count [-]; None: the tip clearance is not checked.
    n_max : int
        Largest count listed [-].

    Returns
    -------
    list of int
        Ascending; always starts with 1.
    """
    zs, zr, zp = _counts(z_sun, z_ring, z_planet)
    n_max = as_positive_int(as_int(n_max, "n_max"), "n_max")
    top = n_max if zp is None else min(n_max, max_equal_planets(zs, zr, zp))
    return [n for n in range(1, top + 1) if (zs + zr) % n == 0]
