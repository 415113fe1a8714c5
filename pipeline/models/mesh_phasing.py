"""Ideal and time-varying mesh phasing of a simple planetary gearset (spec sections 1 and 2).

Ideal phasing follows Parker & Lin, "Mesh phasing relationships in planetary and epicyclic
gears", ASME J. Mech. Des. 126 (2004) 365-370. The time-varying phasing under gear shaft hole
position errors follows seed 000 (``/work/shared/seeds/000_*.txt``), restated in vector form:
the actual centres of sun, ring and planets are placed as 2-D vectors in the carrier frame and
the mesh-line angles are taken with ``atan2``, distances with ``hypot``.

Conventions (all SI; angles counter-clockwise positive in the carrier frame)
-------------------------------------------------------------------------
Carrier frame: origin at the ideal sun (= ideal ring) centre, x axis through planet 1 when
psi_1 = 0. Planet n sits nominally at R_c u_n, u_n = (cos psi_n, sin psi_n); t_n is u_n rotated
by +90 deg. Every error is a radial size ``e >= 0`` [m] and an angle ``kappa`` [rad] that fix
the offset vector of the gear's pitch circle centre at t = 0; the offset then turns with the
body that carries it, at that body's speed relative to the carrier (``Speeds.w_sc``,
``w_pc``, ``w_rc``, counter-clockwise positive):

=========  ===============================================  ============================
member     offset direction at time t (carrier frame)        kappa measured from
=========  ===============================================  ============================
sun        a_s(t) = w_sc t + kappa_sun                      the +x axis (planet 1)
ring       a_r(t) = w_rc t + kappa_ring                     the +x axis (planet 1)
planet n   psi_n + pi + th_n(t), th_n = w_pc t + kappa_pn   the inward radial -u_n
=========  ===============================================  ============================

so the actual centres are O_sa = e_s (cos a_s, sin a_s), O_ra = e_r (cos a_r, sin a_r) and
O_pan = R_c u_n - e_p (cos th u_n + sin th t_n). With this convention the seed's distance
|O_si O_pan| = sqrt(R_c^2 + e_p^2 - 2 R_c e_p cos(w_pc t + kappa_p)) holds exactly. The seed's
angles (dpsi_epn = arcsin(e_p sin(w_pc t + kappa)/|O_si O_pan|), Delta_sn, varsigma_spn) come
out of the same triangle with the offset phase measured *clockwise* (the seed draws clockwise
planet rotation): seed(w, kappa) == this module(-w, -kappa), exactly, for dpsi_epn and for
the full angle psi_espn = psi_pn + dpsi_epn + varsigma_spn (tests/models/test_mesh_phasing.py
shows both). We keep counter-clockwise phases so that an offset turns in the same sense as
the body carrying it.

Phasing: with s = +1 for clockwise planet rotation (``direction="cw"``) and -1 otherwise,
gamma_sn = frac(s Z_s (psi_es,n - psi_es,1) / 2 pi) and gamma_rn = frac(-s Z_r (psi_er,n -
psi_er,1) / 2 pi), where psi_es,n = arg(O_pan - O_sa) and psi_er,n = arg(O_pan - O_ra).

Long times: offset angles w t are reduced modulo 2 pi with an error-free product (Veltkamp
split) and a three-part 2 pi (Cody-Waite), so the phase error stays ~1e-15 rad for |w t| up to
5e10 rad (e.g. t = 1e6 s at 5e4 rad/s). The inputs are taken as exact binary numbers: the
conditioning of the problem itself (a 1-ulp change of t = 1e6 s moves a 350 rad/s offset by
4e-8 rad) belongs to the data, not to this code.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..errors import ModelWarning
from ..validate import as_finite_array, as_float, as_int, as_positive_int
from ._geometry import (MAX_PHASE, TWO_PI, ShaftHoleErrors, broadcast_errors, check_error_size,
                        check_gearset, check_speeds, cos_sin, direction_sign, reduce_angle,
                        rotation_angle, rotation_angle_unchecked, rotation_cos_sin)
from ._kernels import deltas_numpy
from .gearset import Gearset, Speeds

__all__ = [
    "ShaftHoleErrors",
    "AssemblyCheck",
    "ideal_phasing",
    "ideal_phasing_angles",
    "assembly_check",
    "classify_phasing",
    "harmonic_excitation",
    "modal_excitation",
    "centre_positions",
    "mesh_angles",
    "mesh_angle_deviations",
    "time_varying_phasing",
    "phasing_deviation",
    "reduce_angle",
    "rotation_angle",
    "rotation_cos_sin",
    "MAX_PHASE",
    "SNAP_CYCLES",
]

#: Phasing values closer than this to a whole number of mesh cycles [-] are returned as 0.
SNAP_CYCLES = 1e-9


# ----------------------------------------------------------------------------- helpers

def _frac_cycles(x):
    """frac(x) into [0, 1), values within SNAP_CYCLES of an integer set to 0."""
    x = np.asarray(x, dtype=float)
    r = np.rint(x)
    out = x - np.floor(x)
    snap = np.abs(x - r) <= SNAP_CYCLES
    out = np.where(snap, 0.0, out)
    return np.where(out >= 1.0, 0.0, out)


def _times(t):
    t = as_finite_array(t, "t")
    if t.ndim > 1:
        raise ValueError(f"t must be a scalar or 1-D array of times [s], got shape {t.shape}")
    return np.atleast_1d(t)


# ----------------------------------------------------------------------------- section 1: ideal

def ideal_phasing_angles(z_sun: int, z_ring: int, planet_angles: ArrayLike,
                         direction: str = "cw") -> tuple[np.ndarray, np.ndarray]:
    """Ideal sun-planet and ring-planet mesh phasing for given tooth counts and planet angles.

    Parameters
    ----------
    z_sun, z_ring : int
        Sun and ring tooth counts Z_s, Z_r [-], positive, Z_r > Z_s.
    planet_angles : array_like
        Planet angles psi_n [rad], counter-clockwise, planet 1 first; shape (..., N).
    direction : {"cw", "ccw"}
        Planet rotation direction; "ccw" flips both signs.

    Returns
    -------
    gamma_s, gamma_r : numpy.ndarray
        Mesh phasing relative to planet 1 [-] (fractions of one mesh cycle, in [0, 1)),
        shape of ``planet_angles``. Values within ``SNAP_CYCLES`` (1e-9) of a whole cycle are
        returned as exactly 0 (angles such as 2 pi k / N carry rounding error).

    Notes
    -----
    Parker & Lin (2004), eq. for clockwise planet rotation:
    gamma_sn = frac(+Z_s (psi_n - psi_1) / 2 pi), gamma_rn = frac(-Z_r (psi_n - psi_1) / 2 pi):
    the sun turns by psi_n relative to mesh 1 before its teeth present the same phase to
    planet n, which is Z_s psi_n / 2 pi mesh cycles; the ring meshes from the outside, hence
    the opposite sign. For an assemblable layout (psi_n = 2 pi p_n / (Z_s + Z_r)) the two are
    equal modulo 1.
    """
    z_sun = as_positive_int(z_sun, "z_sun")
    z_ring = as_positive_int(z_ring, "z_ring")
    if z_ring <= z_sun:
        raise ValueError(f"z_ring must exceed z_sun, got z_ring={z_ring}, z_sun={z_sun}")
    sign = direction_sign(direction)
    psi = as_finite_array(planet_angles, "planet_angles")
    if psi.ndim == 0:
        psi = psi[None]
    if psi.shape[-1] == 0:
        return np.zeros(psi.shape), np.zeros(psi.shape)
    return _ideal_from_psi(psi, z_sun, z_ring, sign)


def _ideal_from_psi(psi, z_sun, z_ring, sign):
    rel = psi - psi[..., :1]
    return (_frac_cycles((sign * z_sun) * rel / TWO_PI),
            _frac_cycles((-sign * z_ring) * rel / TWO_PI))


def ideal_phasing(gearset: Gearset) -> tuple[np.ndarray, np.ndarray]:
    """Ideal mesh phasing of a gearset, relative to planet 1, using ``gearset.direction``.

    Parameters
    ----------
    gearset : Gearset
        Tooth counts, planet angles psi_n [rad] and planet rotation direction.

    Returns
    -------
    gamma_s, gamma_r : numpy.ndarray
        Shape (n_planets,), in [0, 1) [-]; see :func:`ideal_phasing_angles` (Parker & Lin 2004).
    """
    g = check_gearset(gearset)
    return _ideal_from_psi(g.angles, g.z_sun, g.z_ring, direction_sign(g.direction))


@dataclass(frozen=True, eq=False)
class AssemblyCheck:
    """Result of :func:`assembly_check`.

    Attributes
    ----------
    z_sum : int
        Z_s + Z_r [-].
    p : numpy.ndarray
        Nearest integer p_n with psi_n - psi_1 ~ 2 pi p_n / (Z_s + Z_r) [-], shape (N,).
    assemblable : numpy.ndarray
        Per planet, whether |psi_n - psi_1 - 2 pi p_n / (Z_s + Z_r)| <= atol (bool, shape (N,)).
    nearest_angles : numpy.ndarray
        Nearest assemblable planet angles psi_1 + 2 pi p_n / (Z_s + Z_r) [rad], shape (N,).
    angle_error : numpy.ndarray
        psi_n - nearest_angles [rad], shape (N,).
    """

    z_sum: int
    p: np.ndarray
    assemblable: np.ndarray
    nearest_angles: np.ndarray
    angle_error: np.ndarray

    @property
    def all_assemblable(self) -> bool:
        """True when every planet can be assembled at its angle."""
        return bool(np.all(self.assemblable))


def assembly_check(gearset, z_ring: int | None = None, planet_angles: ArrayLike | None = None,
                   *, atol: float = 1e-9) -> AssemblyCheck:
    """Which planet angles can be assembled, and the nearest assemblable layout.

    Parameters
    ----------
    gearset : Gearset or int
        A :class:`Gearset`, or the sun tooth count Z_s [-] (then give ``z_ring`` and
        ``planet_angles`` too).
    z_ring : int, optional
        Ring tooth count Z_r [-] (only with an integer first argument).
    planet_angles : array_like, optional
        Planet angles psi_n [rad], shape (N,) (only with an integer first argument).
    atol : float
        Angular tolerance [rad] for "assemblable" (default 1e-9 rad, i.e. float rounding of
        angles such as 2 pi k / N).

    Returns
    -------
    AssemblyCheck

    Notes
    -----
    With the sun and ring teeth meshing planet 1, planet n fits only where the sun and ring
    tooth patterns, seen from psi_n, are in the same relative position, i.e. when
    (Z_s + Z_r)(psi_n - psi_1) / 2 pi is an integer p_n (Parker & Lin 2004, section 2). The
    nearest assemblable angle rounds p_n. Planets are not checked for overlap.
    """
    if isinstance(gearset, Gearset):
        if z_ring is not None or planet_angles is not None:
            raise TypeError("give either a Gearset or (z_sun, z_ring, planet_angles), not both")
        z_sun, z_ring, psi = gearset.z_sun, gearset.z_ring, gearset.angles
    else:
        if z_ring is None or planet_angles is None:
            raise TypeError("assembly_check needs a Gearset or z_sun, z_ring and planet_angles")
        z_sun = as_positive_int(gearset, "z_sun")
        z_ring = as_positive_int(z_ring, "z_ring")
        if z_ring <= z_sun:
            raise ValueError(f"z_ring must exceed z_sun, got z_ring={z_ring}, z_sun={z_sun}")
        psi = as_finite_array(planet_angles, "planet_angles")
        if psi.ndim != 1:
            psi = np.atleast_1d(psi)
            if psi.ndim != 1:
                raise ValueError(f"planet_angles must be 1-D, got shape {psi.shape}")
    atol = as_float(atol, "atol")
    if atol < 0:
        raise ValueError(f"atol must be >= 0 [rad], got {atol!r}")
    z_sum = int(z_sun) + int(z_ring)
    if psi.size == 0:
        e = np.zeros(0)
        return AssemblyCheck(z_sum, np.zeros(0, dtype=np.int64), np.zeros(0, dtype=bool), e, e)
    rel = psi - psi[0]
    step = TWO_PI / z_sum
    p = np.rint(rel / step)
    nearest = psi[0] + p * step
    err = psi - nearest
    return AssemblyCheck(z_sum, p.astype(np.int64), np.abs(err) <= atol, nearest, err)


def _equally_spaced(psi, atol):
    n = psi.size
    rel = np.sort(np.mod(psi - psi[0], TWO_PI))
    ideal = TWO_PI * np.arange(n) / n
    d = np.abs(rel - ideal)
    d = np.minimum(d, TWO_PI - d)
    return bool(np.all(d <= atol))


def classify_phasing(gearset: Gearset, *, atol: float = 1e-9) -> str:
    """Phasing class of a gearset: "in-phase", "sequential", "counter-phase" or "mixed".

    Parameters
    ----------
    gearset : Gearset
        Tooth counts and planet angles psi_n [rad].
    atol : float
        Angular tolerance [rad] for "equally spaced".

    Returns
    -------
    str
        For N equally spaced planets with k = Z_s mod N: k = 0 "in-phase"; k = 1 or N - 1
        "sequential"; otherwise "counter-phase". Unequal spacing gives "mixed". One planet is
        "in-phase".

    Warns
    -----
    ModelWarning
        When the planets are equally spaced but Z_s + Z_r is not a multiple of N (the layout
        cannot be assembled; the class is then that of the sun meshes only).

    Notes
    -----
    Parker & Lin (2004): for equally spaced planets gamma_sn = frac(Z_s (n - 1) / N), so the
    meshes are all in phase when N divides Z_s and step by 1/N (sequentially phased) when
    Z_s = +-1 mod N. With N | Z_s + Z_r, Z_r = -Z_s mod N, so the ring gives the same class.
    For N = 2, k = 1 = N - 1 is reported "sequential" (the two meshes are half a cycle apart).
    """
    g = check_gearset(gearset)
    atol = as_float(atol, "atol")
    n = g.n_planets
    if n == 1:
        return "in-phase"
    if not _equally_spaced(g.angles, atol):
        return "mixed"
    if (g.z_sun + g.z_ring) % n != 0:
        warnings.warn(f"classify_phasing: {n} equally spaced planets cannot be assembled with "
                      f"Z_s + Z_r = {g.z_sun + g.z_ring} (not a multiple of {n}); classifying "
                      "by the sun meshes", ModelWarning, stacklevel=2)
    k = g.z_sun % n
    if k == 0:
        return "in-phase"
    if k in (1, n - 1):
        return "sequential"
    return "counter-phase"


def _harmonics(harmonics):
    h = np.atleast_1d(np.asarray(harmonics))
    if h.ndim != 1:
        raise ValueError(f"harmonics must be 1-D, got shape {h.shape}")
    out = [as_int(x.item() if hasattr(x, "item") else x, "harmonics") for x in h]
    if any(x < 1 for x in out):
        raise ValueError(f"harmonics must be positive integers, got {out!r}")
    return out


def modal_excitation(gearset: Gearset, harmonics: ArrayLike) -> dict[str, np.ndarray]:
    """Normalised modal excitation sums of the sun-planet mesh harmonics (any planet spacing).

    Parameters
    ----------
    gearset : Gearset
        Tooth counts, planet angles psi_n [rad], direction.
    harmonics : array_like of int
        Mesh harmonic orders l >= 1 [-].

    Returns
    -------
    dict
        ``"rotational"``: |sum_n exp(-i 2 pi l gamma_sn)| / N; ``"translational"``:
        max over +-1 of |sum_n exp(-i (2 pi l gamma_sn -+ psi_n))| / N; each shape (L,) [-].
        Zero means the harmonic cannot excite that mode family.

    Notes
    -----
    The l-th harmonic of mesh n is F_l exp(i l (w_m t - 2 pi gamma_sn)). Its net torque on the
    central members is proportional to the first sum and its net transverse force (components
    along u_n) to the second (Parker & Lin 2004). For equally spaced planets these reduce to
    Parker's rule used by :func:`harmonic_excitation`.
    """
    g = check_gearset(gearset)
    hs = np.asarray(_harmonics(harmonics), dtype=float)
    gamma_s, _ = ideal_phasing(g)
    n = g.n_planets
    ph = TWO_PI * np.outer(hs, gamma_s)
    rot = np.abs(np.exp(-1j * ph).sum(axis=1)) / n
    psi = g.angles - g.angles[0]
    tr = np.maximum(np.abs(np.exp(-1j * (ph - psi)).sum(axis=1)),
                    np.abs(np.exp(-1j * (ph + psi)).sum(axis=1))) / n
    return {"rotational": rot, "translational": tr}


def harmonic_excitation(gearset: Gearset, harmonics: ArrayLike, *,
                        atol: float = 1e-9) -> dict[int, str]:
    """Which mode family each sun-planet mesh harmonic excites (Parker's rule).

    Parameters
    ----------
    gearset : Gearset
        Equally spaced planets (psi_n = psi_1 + 2 pi (n - 1) / N [rad]).
    harmonics : array_like of int
        Mesh harmonic orders l >= 1 [-].
    atol : float
        Angular tolerance [rad] for "equally spaced".

    Returns
    -------
    dict of int to str
        For each l: "rotational" if l Z_s / N is an integer, else "translational" if
        (l Z_s +- 1) / N is an integer, else "planet" (only planet modes are excited).
        Empty dict for no harmonics.

    Raises
    ------
    ValueError
        For unequally spaced planets (the rule does not hold; use :func:`modal_excitation`).

    Notes
    -----
    Parker & Lin (2004): with gamma_sn = Z_s (n - 1) / N the sums of :func:`modal_excitation`
    are N or 0; the rotational one is N exactly when N | l Z_s and the translational one when
    N | l Z_s -+ 1. The rules are tested in that order (for N = 1 everything is "rotational").
    """
    g = check_gearset(gearset)
    hs = _harmonics(harmonics)
    atol = as_float(atol, "atol")
    n = g.n_planets
    if n > 1 and not _equally_spaced(g.angles, atol):
        raise ValueError("gearset: Parker's harmonic rule needs equally spaced planets, got "
                         f"planet_angles={g.planet_angles!r}; use modal_excitation() instead")
    out = {}
    for l in hs:
        lz = l * g.z_sun
        if lz % n == 0:
            out[l] = "rotational"
        elif (lz + 1) % n == 0 or (lz - 1) % n == 0:
            out[l] = "translational"
        else:
            out[l] = "planet"
    return out


# ----------------------------------------------------------------------------- section 2: errors

def prepare_inputs(t, gearset, speeds, errors):
    """Checked inputs of the phasing models: (gearset, speeds, times [s], the errors' batch
    shape, the errors broadcast to every planet); ValueError or TypeError as the public
    models raise on a bad gearset, speeds, times or error size, or a phase past MAX_PHASE."""
    g = check_gearset(gearset)
    sp = check_speeds(speeds)
    t = _times(t)
    shape, b = broadcast_errors(errors, g.n_planets)
    check_error_size(b, g.carrier_radius)
    if t.size:
        tmax = float(np.max(np.abs(t)))
        for name, w in (("w_sc", sp.w_sc), ("w_pc", sp.w_pc), ("w_rc", sp.w_rc)):
            if abs(w) * tmax > MAX_PHASE:
                raise ValueError(f"|{name} t| must be <= {MAX_PHASE:g} rad, got {name} = {w!r} "
                                 f"rad/s and max |t| = {tmax:g} s; shift the time origin")
    return g, sp, t, shape, b




def _deltas(t, g, sp, shape, b):
    """delta_s, delta_r [rad], shape (*shape, n_t, N)."""
    grid = []
    for w in (sp.w_sc, sp.w_rc, sp.w_pc):
        r = rotation_angle_unchecked(w, t)
        grid += [np.cos(r), np.sin(r)]
    psi = g.angles
    n_p = psi.size
    flat = int(np.prod(shape, dtype=np.int64))
    cks, sks = cos_sin(b.ks.reshape(flat))
    ckr, skr = cos_sin(b.kr.reshape(flat))
    ckp, skp = cos_sin(b.kp.reshape(flat, n_p))
    d_s, d_r = deltas_numpy(*grid, np.cos(psi), np.sin(psi), g.carrier_radius,
                            np.ascontiguousarray(b.es.reshape(flat)), cks, sks,
                            np.ascontiguousarray(b.er.reshape(flat)), ckr, skr,
                            np.ascontiguousarray(b.ep.reshape(flat, n_p)), ckp, skp)
    out_shape = tuple(shape) + (t.size, n_p)
    return d_s.reshape(out_shape), d_r.reshape(out_shape)


def centre_positions(t: ArrayLike, gearset: Gearset, speeds: Speeds,
                     errors: ShaftHoleErrors | None = None) -> dict[str, np.ndarray]:
    """Actual pitch circle centres of sun, ring and planets in the carrier frame.

    Parameters
    ----------
    t : array_like
        Times [s], scalar or 1-D, shape (n_t,).
    gearset : Gearset
        Planet angles psi_n [rad] and carrier radius R_c [m].
    speeds : Speeds
        Absolute speeds [rad/s]; the offsets turn at ``w_sc``, ``w_pc``, ``w_rc``.
    errors : ShaftHoleErrors, optional
        Position errors (sample dims S); None means none.

    Returns
    -------
    dict
        ``"sun"``: O_sa, shape (*S, n_t, 2) [m]; ``"ring"``: O_ra, shape (*S, n_t, 2) [m];
        ``"planets"``: O_pan, shape (*S, n_t, N, 2) [m]; ``"planets_ideal"``: R_c u_n,
        shape (N, 2) [m]. Last axis (x, y).

    Notes
    -----
    O_sa = e_s (cos a_s, sin a_s), O_ra = e_r (cos a_r, sin a_r),
    O_pan = R_c u_n - e_p (cos th u_n + sin th t_n) with a_s = w_sc t + kappa_s,
    a_r = w_rc t + kappa_r, th = w_pc t + kappa_pn (module docstring). Then
    |O_pan| = sqrt(R_c^2 + e_p^2 - 2 R_c e_p cos th), the seed's |O_si O_pan|.
    """
    g, sp, t, shape, b = prepare_inputs(t, gearset, speeds, errors)
    sl = (Ellipsis, None)
    a_s = rotation_angle_unchecked(sp.w_sc, t, b.ks[sl])
    a_r = rotation_angle_unchecked(sp.w_rc, t, b.kr[sl])
    th = rotation_angle_unchecked(sp.w_pc, t[:, None], b.kp[..., None, :])
    sun = b.es[sl][..., None] * np.stack([np.cos(a_s), np.sin(a_s)], axis=-1)
    ring = b.er[sl][..., None] * np.stack([np.cos(a_r), np.sin(a_r)], axis=-1)
    psi = g.angles
    u = np.stack([np.cos(psi), np.sin(psi)], axis=-1)        # (N, 2)
    tn = np.stack([-np.sin(psi), np.cos(psi)], axis=-1)
    ep = b.ep[..., None, :, None]
    planets = (g.carrier_radius * u - ep * (np.cos(th)[..., None] * u
                                            + np.sin(th)[..., None] * tn))
    return {"sun": sun, "ring": ring, "planets": planets, "planets_ideal": g.carrier_radius * u}


def mesh_angles(t: ArrayLike, gearset: Gearset, speeds: Speeds,
                errors: ShaftHoleErrors | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Directions of the sun-planet and ring-planet lines of centres under position errors.

    Parameters
    ----------
    t : array_like
        Times [s], scalar or 1-D, shape (n_t,).
    gearset : Gearset
        Planet angles psi_n [rad], carrier radius R_c [m].
    speeds : Speeds
        Absolute speeds [rad/s].
    errors : ShaftHoleErrors, optional
        Position errors with sample dims S; None gives the ideal angles exactly.

    Returns
    -------
    psi_es, psi_er : numpy.ndarray
        arg(O_pan - O_sa) and arg(O_pan - O_ra) [rad], shape (*S, n_t, N), as psi_n + delta
        with delta in (-pi/2, pi/2) (not reduced to [-pi, pi), so that no errors give psi_n
        bit for bit).

    Notes
    -----
    Seed 000 writes psi_espn = psi_pn + dpsi_epn + varsigma_spn with two law-of-cosines /
    arcsin steps. Here the vector v = O_pan - O_sa is expressed in the frame of planet n
    (u_n, t_n) directly,

        v = (R_c - e_p cos th - e_s cos(a_s - psi_n), -e_p sin th - e_s sin(a_s - psi_n)),

    and delta = atan2(v_t, v_u). This is the same angle (dpsi_epn + varsigma_spn, with the
    seed's phases read clockwise) without an arcsin domain problem and without the
    cancellation of sqrt(R^2 + e^2 - 2 R e cos) for e -> 0 or e -> R. Requires
    e_s + e_p < R_c so that v_u > 0. Accuracy against an mpmath reference: |delta error| <=
    1e-12 (e_s + e_p) / R_c for e / R_c in [1e-12, 0.99] and |t| <= 1e6 s (tests; measured
    worst 1.4e-15). Memory: the full (*S, n_t, N) broadcast with ~10 temporaries; for many
    realisations use :func:`meshphase.models.tolerance.phasing_statistics`, which batches.
    """
    g, sp, t, shape, b = prepare_inputs(t, gearset, speeds, errors)
    d_s, d_r = _deltas(t, g, sp, shape, b)
    psi = g.angles
    return psi + d_s, psi + d_r


def mesh_angle_deviations(t: ArrayLike, gearset: Gearset, speeds: Speeds,
                          errors: ShaftHoleErrors | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Angular deviations of the mesh lines from the nominal planet angles.

    Parameters
    ----------
    t : array_like
        Times [s], scalar or 1-D, shape (n_t,).
    gearset : Gearset
        Planet angles psi_n [rad], carrier radius R_c [m].
    speeds : Speeds
        Absolute speeds [rad/s].
    errors : ShaftHoleErrors, optional
        Position errors with sample dims S; None gives exactly 0.

    Returns
    -------
    delta_s, delta_r : numpy.ndarray
        psi_es,n - psi_n and psi_er,n - psi_n [rad], shape (*S, n_t, N), computed directly
        (not as a difference of large angles), so they keep full relative accuracy for
        errors down to e / R_c = 1e-12.

    Notes
    -----
    delta = atan2(v_t, v_u) with v the sun-to-planet (ring-to-planet) centre vector in the
    frame of planet n (see :func:`mesh_angles`); in seed 000's notation
    delta_s = dpsi_epn + varsigma_spn.
    """
    g, sp, t, shape, b = prepare_inputs(t, gearset, speeds, errors)
    return _deltas(t, g, sp, shape, b)


def time_varying_phasing(t: ArrayLike, gearset: Gearset, speeds: Speeds,
                         errors: ShaftHoleErrors | None = None, *,
                         relative_to_first: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Time-varying mesh phasing gamma_s(t), gamma_r(t) under shaft hole position errors.

    Parameters
    ----------
    t : array_like
        Times [s], scalar or 1-D, shape (n_t,).
    gearset : Gearset
        Tooth counts, planet angles psi_n [rad], carrier radius R_c [m], direction.
    speeds : Speeds
        Absolute speeds [rad/s].
    errors : ShaftHoleErrors, optional
        Position errors with sample dims S; None (or all-zero errors) returns exactly
        :func:`ideal_phasing`, broadcast.
    relative_to_first : bool
        Phasing relative to planet 1 (default). False gives the phase of each mesh line
        relative to the carrier +x axis, frac(s Z_s psi_es,n / 2 pi).

    Returns
    -------
    gamma_s, gamma_r : numpy.ndarray
        Fractions of a mesh cycle in [0, 1) [-], shape (*S, n_t, N).

    Notes
    -----
    Seed 000: gamma_sn = Z_s psi_espn / 2 pi, gamma_rn = -Z_r psi_erpn / 2 pi for clockwise
    planets (signs flipped for counter-clockwise), with the mesh-line angles of
    :func:`mesh_angles`; relative to planet 1 the angle difference
    (psi_n - psi_1) + (delta_n - delta_1) is used, which reproduces the ideal value exactly
    when every delta is zero.
    """
    g, sp, t, shape, b = prepare_inputs(t, gearset, speeds, errors)
    d_s, d_r = _deltas(t, g, sp, shape, b)
    sign = direction_sign(g.direction)
    psi = g.angles
    if relative_to_first and psi.size:
        rel = psi - psi[:1]
        d_s = d_s - d_s[..., :1]
        d_r = d_r - d_r[..., :1]
    else:
        rel = psi
    gs = _frac_cycles((sign * g.z_sun) * (rel + d_s) / TWO_PI)
    gr = _frac_cycles((-sign * g.z_ring) * (rel + d_r) / TWO_PI)
    return gs, gr


def phasing_deviation(t: ArrayLike, gearset: Gearset, speeds: Speeds,
                      errors: ShaftHoleErrors | None = None, *,
                      wrap: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Deviation of the time-varying phasing from the ideal phasing, in mesh cycles.

    Parameters
    ----------
    t : array_like
        Times [s], scalar or 1-D, shape (n_t,).
    gearset : Gearset
        Tooth counts, planet angles psi_n [rad], carrier radius R_c [m], direction.
    speeds : Speeds
        Absolute speeds [rad/s].
    errors : ShaftHoleErrors, optional
        Position errors with sample dims S (None: zero deviation).
    wrap : bool
        Wrap into [-0.5, 0.5) (default). With ``wrap=False`` the continuous deviation
        s Z_s (delta_n - delta_1) / 2 pi is returned; the two agree whenever its magnitude
        is below 0.5, and the continuous one is what Ave / Dev
        (:func:`meshphase.models.tolerance.phasing_statistics`) are computed on, so that a
        deviation crossing +-0.5 does not fold.

    Returns
    -------
    dev_s, dev_r : numpy.ndarray
        gamma(t) - gamma_ideal [-], shape (*S, n_t, N); planet 1 is identically 0.

    Notes
    -----
    gamma_sn(t) - gamma_sn,ideal = s Z_s (delta_s,n - delta_s,1) / 2 pi (mod 1) and
    gamma_rn(t) - gamma_rn,ideal = -s Z_r (delta_r,n - delta_r,1) / 2 pi (mod 1) with the
    deltas of :func:`mesh_angles` (seed 000; Ave_jn and Dev_jn are taken on this quantity).
    """
    g, sp, t, shape, b = prepare_inputs(t, gearset, speeds, errors)
    d_s, d_r = _deltas(t, g, sp, shape, b)
    sign = direction_sign(g.direction)
    if d_s.shape[-1]:
        d_s = d_s - d_s[..., :1]
        d_r = d_r - d_r[..., :1]
    v_s = (sign * g.z_sun / TWO_PI) * d_s
    v_r = (-sign * g.z_ring / TWO_PI) * d_r
    if wrap:
        v_s = v_s - np.floor(v_s + 0.5)
        v_r = v_r - np.floor(v_r + 0.5)
    return v_s, v_r

