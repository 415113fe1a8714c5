"""Closed-form derivatives of the mesh-line deviations with respect to the shaft hole errors.

The identification (:func:`meshphase.compare.identify_errors`) fits the Cartesian offset
components p = (sun_x, sun_y, ring_x, ring_y, planet1_x, planet1_y, ...) [m], with
(x, y) = e (cos kappa, sin kappa) in the conventions of :class:`ShaftHoleErrors` (planet
kappa from the inward radial). In the frame of planet n (u_n radial, t_n tangential) the
vector from the actual sun centre to the actual planet centre is
(:mod:`meshphase.models.mesh_phasing`)

    v_u = R_c - e_p cos(th) - e_s cos(a_s - psi_n),   v_t = -e_p sin(th) - e_s sin(a_s - psi_n)

with th = w_pc t + kappa_p and a_s = w_sc t + kappa_s. Expanding the angle sums, e cos(w t +
kappa) = x cos(w t) - y sin(w t) and e sin(w t + kappa) = x sin(w t) + y cos(w t), so v is
*affine* in p: with (c, s) = (cos, sin)(w_sc t - psi_n) for the sun and (c_p, s_p) =
(cos, sin)(w_pc t) for the planet,

    dv_u/dx = -c,  dv_u/dy = s,  dv_t/dx = -s,  dv_t/dy = -c      (and likewise with c_p, s_p)

and the deviation delta = atan2(v_t, v_u) has the gradient

    d delta = (v_u dv_t - v_t dv_u) / |v|^2,   |v| = hypot(v_u, v_t),

i.e. d delta/dx = (v_t c - v_u s) / |v|^2 and d delta/dy = -(v_u c + v_t s) / |v|^2. The
ring mesh is the same with the ring's offset and w_rc. Only the meshing gear's (x, y) and the
planet's own (x, y) enter a row; the other columns are exactly 0. The formula is regular at
e = 0 (|v| = R_c) and, since e_s + e_p < R_c keeps v_u > 0, |v| never vanishes; no
square root of a difference appears. The rotation angles w t are reduced exactly
(:func:`meshphase.models.mesh_phasing.rotation_angle`), so long times cost no accuracy.

Tests (tests/models/test_phasing_jacobian.py) hold the gradient to central finite
differences and to an mpmath reference (50 digits) at zero errors, one planet and errors
near the R_c bound.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ..validate import as_choice
from ._geometry import cos_sin, rotation_angle_unchecked
from .gearset import Gearset, Speeds
from .mesh_phasing import ShaftHoleErrors, _prepare

__all__ = ["MESHES", "mesh_angle_gradient", "n_offset_parameters"]

#: The two meshes of a planet: with the sun and with the ring.
MESHES = ("sun", "ring")


def n_offset_parameters(n_planets: int) -> int:
    """Number of Cartesian offset parameters of a gearset with ``n_planets`` [-]: 4 + 2 N."""
    return 4 + 2 * int(n_planets)


def mesh_angle_gradient(t: ArrayLike, planet: ArrayLike, gearset: Gearset, speeds: Speeds,
                        errors: ShaftHoleErrors | None = None, *,
                        mesh: str = "sun") -> tuple[np.ndarray, np.ndarray]:
    """Deviation of one planet's mesh line per time and its gradient in the offsets.

    Parameters
    ----------
    t : array_like
        Times [s], scalar or 1-D, shape (n,).
    planet : array_like of int
        1-based planet number per time, shape (n,) or scalar (broadcast).
    gearset : Gearset
        Planet angles psi_n [rad], carrier radius R_c [m].
    speeds : Speeds
        Speeds [rad/s]; offsets turn at ``w_sc``, ``w_pc``, ``w_rc``.
    errors : ShaftHoleErrors, optional
        One realisation (no sample dimensions); None means no errors.
    mesh : {"sun", "ring"}
        Which mesh line.

    Returns
    -------
    delta : numpy.ndarray, shape (n,)
        psi_e,n(t) - psi_n [rad] of the given planet, equal (bit for bit) to the matching
        entry of :func:`meshphase.models.mesh_phasing.mesh_angle_deviations`.
    grad : numpy.ndarray, shape (n, 4 + 2 N)
        d delta / d p [rad/m], p the Cartesian offsets in the order of
        :func:`meshphase.compare.PARAMETER_NAMES`: (sun_x, sun_y, ring_x, ring_y,
        planet1_x, planet1_y, ...). Columns other than the meshing gear's and the planet's
        own are 0.

    Raises
    ------
    TypeError
        Wrong types of ``gearset``, ``speeds`` or ``errors``.
    ValueError
        Errors with sample dimensions or beyond the R_c bound, planet numbers out of range,
        ``t`` and ``planet`` of different lengths, an unknown ``mesh``.
    """
    mesh = as_choice(mesh, "mesh", MESHES)
    g, sp, t, shape, b = _prepare(t, gearset, speeds, errors)
    if shape != ():
        raise ValueError(f"errors must be one realisation (no sample dimensions), got sample "
                         f"shape {shape}")
    n_p = g.n_planets
    pl = np.asarray(planet)
    if pl.size and not np.issubdtype(pl.dtype, np.integer):
        raise ValueError(f"planet must hold integer planet numbers, got dtype {pl.dtype}")
    pl = np.broadcast_to(pl, t.shape) if pl.ndim == 0 else pl
    if pl.shape != t.shape:
        raise ValueError(f"planet {pl.shape} must have the shape of t {t.shape}")
    if pl.size and (pl.min() < 1 or pl.max() > n_p):
        raise ValueError(f"planet must lie in [1, {n_p}], got [{pl.min()}, {pl.max()}]")
    idx = pl.astype(np.intp) - 1
    grad = np.zeros((t.size, n_offset_parameters(n_p)))
    if t.size == 0:
        return np.empty(0), grad
    if mesh == "sun":
        w, e, kappa, col = sp.w_sc, float(b.es), float(b.ks), 0
    else:
        w, e, kappa, col = sp.w_rc, float(b.er), float(b.kr), 2
    vu, vt, c, s, cp, spl = _centre_vector(t, idx, g, sp, w, e, kappa, b.ep, b.kp)
    h2 = np.hypot(vu, vt) ** 2
    rows = np.arange(t.size)
    grad[:, col] = (vt * c - vu * s) / h2
    grad[:, col + 1] = -(vu * c + vt * s) / h2
    grad[rows, 4 + 2 * idx] = (vt * cp - vu * spl) / h2
    grad[rows, 5 + 2 * idx] = -(vu * cp + vt * spl) / h2
    return np.arctan2(vt, vu), grad


def _centre_vector(t, idx, g, sp, w, e, kappa, ep_all, kp_all):
    """v = O_pan - O_ga in the frame of each row's planet (same operations, in the same
    order, as :func:`meshphase.models._kernels.deltas_numpy`, so atan2(v_t, v_u) is the
    model's delta bit for bit), and the rotation cos/sin the gradient needs: (c, s) of
    w t - psi_n and (c_p, s_p) of w_pc t."""
    psi = g.angles[idx]
    cps, sps = np.cos(psi), np.sin(psi)
    r = rotation_angle_unchecked(w, t)
    cw, sw = np.cos(r), np.sin(r)
    ck, sk = cos_sin(kappa)
    ca = cw * ck - sw * sk
    sa = sw * ck + cw * sk
    r = rotation_angle_unchecked(sp.w_pc, t)
    cp, spl = np.cos(r), np.sin(r)
    ckp, skp = cos_sin(np.asarray(kp_all, dtype=float)[idx])
    ep = np.asarray(ep_all, dtype=float)[idx]
    px = g.carrier_radius - ep * (cp * ckp - spl * skp)
    py = -(ep * (spl * ckp + cp * skp))
    crel = ca * cps + sa * sps
    srel = sa * cps - ca * sps
    vu = px - e * crel
    vt = py - e * srel
    c = cw * cps + sw * sps        # cos(w t - psi_n)
    s = sw * cps - cw * sps        # sin(w t - psi_n)
    return vu, vt, c, s, cp, spl
