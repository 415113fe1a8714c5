"""Closed-form derivatives of the mesh-line deviations with respect to the shaft hole errors.

The identification (:func:`meshphase.compare.identify.identify_errors`) fits the Cartesian offset
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
from ._geometry import broadcast_errors, check_error_size, cos_sin, rotation_angle_unchecked
from .gearset import Gearset, Speeds
from .mesh_phasing import ShaftHoleErrors, prepare_inputs

__all__ = ["MESHES", "MeshGradientPlan", "mesh_angle_gradient", "n_offset_parameters"]

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
        :func:`meshphase.compare.identify.PARAMETER_NAMES`: (sun_x, sun_y, ring_x, ring_y,
        planet1_x, planet1_y, ...). Columns other than the meshing gear's and the planet's
        own are 0.

    Raises
    ------
    TypeError
        Wrong types of ``gearset``, ``speeds`` or ``errors``.
    ValueError
        Errors with sample dimensions or beyond the R_c bound, planet numbers out of range,
        ``t`` and ``planet`` of different lengths, an unknown ``mesh``.

    See Also
    --------
    MeshGradientPlan : the same evaluation split into its error-independent part (the
        rotations, computed once) and the part each error vector needs; what an iterative
        fit over fixed times uses.
    """
    return MeshGradientPlan(t, planet, gearset, speeds, mesh=mesh).evaluate(errors)


class MeshGradientPlan:
    """:func:`mesh_angle_gradient` at fixed times and planets, for many error vectors.

    The rotations of a row (cos and sin of w t - psi_n, w t and w_pc t, reduced exactly) do
    not depend on the errors; the plan computes them once, and :meth:`evaluate` does only the
    arithmetic that does (a few products per row, no trigonometric function of the times).
    :func:`mesh_angle_gradient` is a plan evaluated once, so the two agree bit for bit.

    Parameters
    ----------
    t, planet, gearset, speeds, mesh
        As :func:`mesh_angle_gradient`.

    Raises
    ------
    TypeError, ValueError
        As :func:`mesh_angle_gradient` for the arguments given here.
    """

    __slots__ = ("mesh", "n_planets", "carrier_radius", "idx", "_rot")

    def __init__(self, t: ArrayLike, planet: ArrayLike, gearset: Gearset, speeds: Speeds, *,
                 mesh: str = "sun"):
        mesh = as_choice(mesh, "mesh", MESHES)
        g, sp, t, _, _ = prepare_inputs(t, gearset, speeds, None)
        n_p = g.n_planets
        pl = np.asarray(planet)
        if pl.size and not np.issubdtype(pl.dtype, np.integer):
            raise ValueError(f"planet must hold integer planet numbers, got dtype {pl.dtype}")
        pl = np.broadcast_to(pl, t.shape) if pl.ndim == 0 else pl
        if pl.shape != t.shape:
            raise ValueError(f"planet {pl.shape} must have the shape of t {t.shape}")
        if pl.size and (pl.min() < 1 or pl.max() > n_p):
            raise ValueError(f"planet must lie in [1, {n_p}], got [{pl.min()}, {pl.max()}]")
        self.mesh, self.n_planets, self.carrier_radius = mesh, n_p, g.carrier_radius
        self.idx = pl.astype(np.intp) - 1
        w = sp.w_sc if mesh == "sun" else sp.w_rc
        self._rot = _rotations(t, self.idx, g, sp, w) if t.size else None

    def __len__(self) -> int:
        return self.idx.size

    def evaluate(self, errors: ShaftHoleErrors | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Deviation and gradient for ``errors``, as :func:`mesh_angle_gradient`.

        Parameters
        ----------
        errors : ShaftHoleErrors, optional
            One realisation; None means no errors.

        Returns
        -------
        delta : numpy.ndarray, shape (n,)
            [rad].
        grad : numpy.ndarray, shape (n, 4 + 2 N)
            [rad/m].

        Raises
        ------
        TypeError
            ``errors`` not a ShaftHoleErrors.
        ValueError
            Errors with sample dimensions, or beyond the R_c bound.
        """
        shape, b = broadcast_errors(errors, self.n_planets)
        check_error_size(b, self.carrier_radius)
        if shape != ():
            raise ValueError(f"errors must be one realisation (no sample dimensions), got "
                             f"sample shape {shape}")
        n_p, idx = self.n_planets, self.idx
        grad = np.zeros((idx.size, n_offset_parameters(n_p)))
        if self._rot is None:
            return np.empty(0), grad
        if self.mesh == "sun":
            e, kappa, col = float(b.es), float(b.ks), 0
        else:
            e, kappa, col = float(b.er), float(b.kr), 2
        vu, vt, c, s, cp, spl = _centre_vector(self._rot, idx, self.carrier_radius, e, kappa,
                                               b.ep, b.kp)
        h2 = np.hypot(vu, vt) ** 2
        rows = np.arange(idx.size)
        grad[:, col] = (vt * c - vu * s) / h2
        grad[:, col + 1] = -(vu * c + vt * s) / h2
        grad[rows, 4 + 2 * idx] = (vt * cp - vu * spl) / h2
        grad[rows, 5 + 2 * idx] = -(vu * cp + vt * spl) / h2
        return np.arctan2(vt, vu), grad


def _rotations(t, idx, g, sp, w):
    """The error-independent rotations of each row: (cos, sin) of psi_n, of w t and of w_pc
    t, and (c, s) = (cos, sin)(w t - psi_n)."""
    psi = g.angles[idx]
    cps, sps = np.cos(psi), np.sin(psi)
    r = rotation_angle_unchecked(w, t)
    cw, sw = np.cos(r), np.sin(r)
    r = rotation_angle_unchecked(sp.w_pc, t)
    cp, spl = np.cos(r), np.sin(r)
    c = cw * cps + sw * sps        # cos(w t - psi_n)
    s = sw * cps - cw * sps        # sin(w t - psi_n)
    return cps, sps, cw, sw, cp, spl, c, s


def _centre_vector(rot, idx, carrier_radius, e, kappa, ep_all, kp_all):
    """v = O_pan - O_ga in the frame of each row's planet (same operations, in the same
    order, as :func:`meshphase.models._kernels.deltas_numpy`, so atan2(v_t, v_u) is the
    model's delta bit for bit), and the rotation cos/sin the gradient needs: (c, s) of
    w t - psi_n and (c_p, s_p) of w_pc t (``rot``: :func:`_rotations`)."""
    cps, sps, cw, sw, cp, spl, c, s = rot
    ck, sk = cos_sin(kappa)
    ca = cw * ck - sw * sk
    sa = sw * ck + cw * sk
    ckp, skp = cos_sin(np.asarray(kp_all, dtype=float)[idx])
    ep = np.asarray(ep_all, dtype=float)[idx]
    px = carrier_radius - ep * (cp * ckp - spl * skp)
    py = -(ep * (spl * ckp + cp * skp))
    crel = ca * cps + sa * sps
    srel = sa * cps - ca * sps
    vu = px - e * crel
    vt = py - e * srel
    return vu, vt, c, s, cp, spl
