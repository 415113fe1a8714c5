"""Planet needle-bearing moments in single and double pinion planetary gearsets.

Spec section 4; source: seed 001 (J. Mech. Des. 129 (2007), DOI 10.1115/1.2359472; the OCR
text lost its Greek letters, the spec restores them).

Everything here is linear in the input torque and in the centroid offsets of the distributed
mesh loads, so the functions are closed-form and vectorised: the input torque and the offsets
broadcast against each other. SI inside: lengths [m], forces [N], moments [N·m], angles [rad].

Frames and signs (seed Figs. 3-5, checked against its Tables 3-11). Each pinion has its own
frame: origin at the pinion centre, X along the line from the central (sun/ring) axis to the
pinion centre, Z along the pinion axis, Y completing a right-handed frame. The mesh force of
one mesh acts at its operating pitch point, at the axial position Z of the centroid of the
distributed load (0 for a centred pattern). Moments are ``r x F`` summed over the meshes of the
pinion (counter-clockwise positive, seed Table 3). A *line-of-action* (LOA) moment is the
component of the pinion moment that tilts the pinion inside the plane of action of one mesh;
a positive LOA moment pushes the load towards -z (seed, Table 9 text).

Geometry first: :func:`operating_mesh` derives operating pitch radii, pressure and helix angles
from tooth counts and centre distance; :func:`seed_case` builds the seed's Case 1, 2-A and 2-B
from its Tables 1 and 2 with it. Where the spec page and the seed disagree the geometry wins,
and the docstrings say so (Case 2's SP-RP pressure angle, Table 6's radii).

Why one file of over 1,000 lines: it is one closed-form model, the seed's bearing moments,
from one frame and sign convention; the geometry, the single- and double-pinion moments and
the seed's cases share that convention and check each other against the seed's tables, and
split apart each half would have to restate it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..validate import as_choice, as_float, as_positive, as_positive_int
from ._renamed import accept_old_names, renamed_kwargs

__all__ = [
    "SinglePinion",
    "DoublePinion",
    "MeshGeometry",
    "MeshForces",
    "BearingMoments",
    "DoublePinionMoments",
    "SeedCase",
    "operating_mesh",
    "single_pinion_forces",
    "single_pinion_moments",
    "double_pinion_moments",
    "moments_from_offsets",
    "offsets_from_moments",
    "loa_from_moments",
    "double_pinion_offsets_from_moments",
    "sp_sun_moment",
    "rp_ring_moment",
    "worst_case_angles",
    "worst_case_moment",
    "single_equivalent_moment",
    "same_as_single_angle",
    "worst_to_single_ratio",
    "seed_case",
    "SEED_CASES",
]

_HALF_PI = 0.5 * math.pi


# --------------------------------------------------------------------------------------------
# validation helpers (thin wrappers over meshphase.validate)
# --------------------------------------------------------------------------------------------
def _angle(value, name, lo, hi, *, lo_open=True, hi_open=True) -> float:
    """A finite angle [rad] inside (lo, hi) (open or closed ends as flagged)."""
    out = as_float(value, name)
    bad_lo = out <= lo if lo_open else out < lo
    bad_hi = out >= hi if hi_open else out > hi
    if bad_lo or bad_hi:
        lb = "(" if lo_open else "["
        hb = ")" if hi_open else "]"
        raise ValueError(f"{name} must lie in {lb}{lo:.6g}, {hi:.6g}{hb} rad, got {out!r}")
    return out


def real_array(value, name) -> np.ndarray:
    """Float array with only finite entries (TypeError: non-numeric; ValueError: NaN/inf)."""
    if isinstance(value, (str, bytes)):
        raise TypeError(f"{name} must be numeric array_like, got {value!r}")
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be numeric array_like, got {value!r}") from exc
    if arr.size and not np.all(np.isfinite(arr)):
        bad = int(np.count_nonzero(~np.isfinite(arr)))
        raise ValueError(f"{name} must be finite, got {bad} non-finite value(s)")
    return arr


def _torque_array(value, name="input_torque") -> np.ndarray:
    """Input torque array [N·m]: finite and >= 0 (the formulas assume the drive flanks)."""
    arr = real_array(value, name)
    if arr.size and np.any(arr < 0):
        raise ValueError(
            f"{name} must be >= 0 [N·m] (the force directions assume the drive flanks; reverse "
            f"torque loads the other flanks), got min {float(arr.min())!r}")
    return arr


def _mm(value, name) -> float:
    """A length given in [mm], returned in [m] (validated as a finite number)."""
    return as_float(value, name) * 1e-3


def _deg(value, name) -> float:
    """An angle given in [deg], returned in [rad] (validated as a finite number)."""
    return math.radians(as_float(value, name))


def as_scalar(x):
    """A Python float (bool) for a 0-d result, the array itself otherwise."""
    arr = np.asarray(x)
    return arr.item() if arr.ndim == 0 else x


# --------------------------------------------------------------------------------------------
# geometry
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class MeshGeometry:
    """Operating geometry of one gear mesh (output of :func:`operating_mesh`).

    Attributes
    ----------
    r_ref_1, r_ref_2 : float
        Reference pitch radii of gear 1 and gear 2 [m].
    r_w_1, r_w_2 : float
        Operating pitch radii [m].
    pressure_angle : float
        Operating transverse pressure angle alpha_wt [rad].
    helix_angle : float
        Operating helix angle beta_w (at the operating pitch cylinders) [rad].
    transverse_pressure_angle : float
        Reference transverse pressure angle alpha_t [rad].
    center_distance : float
        Operating centre distance [m].
    internal : bool
        True for an internal (ring) mesh, gear 2 being the ring.
    """

    r_ref_1: float
    r_ref_2: float
    r_w_1: float
    r_w_2: float
    pressure_angle: float
    helix_angle: float
    transverse_pressure_angle: float
    center_distance: float
    internal: bool


def operating_mesh(z_1: int, z_2: int, normal_module: float, normal_pressure_angle: float,
                   helix_angle: float, center_distance: float, internal: bool = False
                   ) -> MeshGeometry:
    """Operating pitch radii, pressure angle and helix angle of an involute helical mesh.

    Parameters
    ----------
    z_1, z_2 : int
        Tooth counts [-]; for an internal mesh gear 2 is the ring.
    normal_module : float
        Normal module m_n [m].
    normal_pressure_angle : float
        Normal reference pressure angle alpha_n [rad], in (0, pi/2).
    helix_angle : float
        Reference helix angle beta [rad], in [0, pi/2) (hand does not matter here).
    center_distance : float
        Operating centre distance a_w [m].
    internal : bool
        True for a pinion-ring mesh (reference distance r_2 - r_1).

    Returns
    -------
    MeshGeometry

    Raises
    ------
    ValueError
        Bad values, or a centre distance the involutes cannot reach
        (|a cos(alpha_t) / a_w| > 1).

    Notes
    -----
    Standard involute geometry: r_i = z_i m_n / (2 cos beta), tan alpha_t = tan alpha_n /
    cos beta, a = r_1 + r_2 (external) or r_2 - r_1 (internal), cos alpha_wt = a cos alpha_t /
    a_w, r_wi = r_i cos alpha_t / cos alpha_wt (base radii are fixed), and the helix angle at
    the operating pitch cylinder tan beta_w = tan beta r_wi / r_i (the lead is fixed).

    Applied to the seed's Tables 1 and 2 this reproduces every operating value the seed prints
    (R_SUN 29.805, R_pS 22.141, R_pR 22.510, R_SP-RP 22.23, R_RP-SP 20.52, R_RP-RING 20.68 mm;
    phi 21.30, 23.59, 23.0 deg; beta 21.00, 21.32 deg) and gives the SP-RP operating pressure
    angle the seed does not print: 21.88 deg.
    """
    z1 = as_positive_int(z_1, "z_1")
    z2 = as_positive_int(z_2, "z_2")
    mn = as_positive(normal_module, "normal_module")
    an = _angle(normal_pressure_angle, "normal_pressure_angle", 0.0, _HALF_PI)
    beta = _angle(helix_angle, "helix_angle", 0.0, _HALF_PI, lo_open=False)
    aw = as_positive(center_distance, "center_distance")
    if not isinstance(internal, (bool, np.bool_)):
        raise TypeError(f"internal must be a bool, got {internal!r}")
    if internal and z2 <= z1:
        raise ValueError(f"an internal mesh needs z_2 (ring) > z_1, got z_1={z1}, z_2={z2}")
    r1 = z1 * mn / (2.0 * math.cos(beta))
    r2 = z2 * mn / (2.0 * math.cos(beta))
    at = math.atan(math.tan(an) / math.cos(beta))
    a0 = r2 - r1 if internal else r1 + r2
    c = a0 * math.cos(at) / aw
    if not 0.0 < c < 1.0:
        raise ValueError(
            f"center_distance {aw!r} m cannot be reached by these involutes "
            f"(cos alpha_wt = {c!r}); reference distance is {a0!r} m")
    awt = math.acos(c)
    f = math.cos(at) / c
    return MeshGeometry(r_ref_1=r1, r_ref_2=r2, r_w_1=r1 * f, r_w_2=r2 * f, pressure_angle=awt,
                        helix_angle=math.atan(math.tan(beta) * f), transverse_pressure_angle=at,
                        center_distance=aw, internal=bool(internal))


@dataclass(frozen=True)
class SinglePinion:
    """Single pinion planet (sun - pinion - ring), seed 001 Fig. 3 / Table 1.

    Parameters
    ----------
    r_sun : float
        Operating pitch radius of the sun R_SUN [m].
    r_ps : float
        Operating pitch radius of the pinion at the sun mesh R_pS [m].
    r_pr : float
        Operating pitch radius of the pinion at the ring mesh R_pR [m].
    phi_1, phi_2 : float
        Operating transverse pressure angles at the sun and ring meshes [rad], in (0, pi/2).
    helix_1, helix_2 : float
        Operating helix angles at the sun and ring meshes [rad], in (-pi/2, pi/2) (the seed's
        beta_1, beta_2; named ``helix_*`` as in :class:`DoublePinion`, where the seed's beta is
        an included angle). Positive values give the seed's axial force signs (FzS > 0 > FzR
        for a positive input torque); a negative value flips the axial force of that mesh
        (opposite hand).
    n_planets : int
        Number of planets N sharing the input torque [-].
    face_width : float, optional
        Contact face width b of both meshes [m] (used by :mod:`meshphase.models.tilt`).
    name : str
        Free label.

    Notes
    -----
    Everything is SI; :meth:`from_mm_deg` takes the drawing's units (mm, deg). The old names
    ``beta_1``, ``beta_2`` still work as keywords and attributes, with a
    :class:`~meshphase.errors.DeprecatedNameWarning`.
    """

    r_sun: float
    r_ps: float
    r_pr: float
    phi_1: float
    phi_2: float
    helix_1: float
    helix_2: float
    n_planets: int
    face_width: float | None = None
    name: str = ""

    def __post_init__(self):
        for n in ("r_sun", "r_ps", "r_pr"):
            object.__setattr__(self, n, as_positive(getattr(self, n), n))
        for n in ("phi_1", "phi_2"):
            object.__setattr__(self, n, _angle(getattr(self, n), n, 0.0, _HALF_PI))
        for n in ("helix_1", "helix_2"):
            object.__setattr__(self, n, _angle(getattr(self, n), n, -_HALF_PI, _HALF_PI))
        object.__setattr__(self, "n_planets", as_positive_int(self.n_planets, "n_planets"))
        if self.face_width is not None:
            object.__setattr__(self, "face_width", as_positive(self.face_width, "face_width"))
        if not isinstance(self.name, str):
            raise TypeError(f"name must be a string, got {self.name!r}")

    mesh_names = ("sun", "ring")

    @classmethod
    def from_mm_deg(cls, *, r_sun_mm, r_ps_mm, r_pr_mm, phi_1_deg, phi_2_deg, helix_1_deg,
                    helix_2_deg, n_planets, face_width_mm=None, name="") -> "SinglePinion":
        """Build from a gear drawing's units: radii and face width in [mm], angles in [deg].

        Every argument is keyword-only and carries its unit in its name, so a value in the
        wrong unit cannot slip in silently (see the class for the meaning of each).
        """
        return cls(r_sun=_mm(r_sun_mm, "r_sun_mm"), r_ps=_mm(r_ps_mm, "r_ps_mm"),
                   r_pr=_mm(r_pr_mm, "r_pr_mm"), phi_1=_deg(phi_1_deg, "phi_1_deg"),
                   phi_2=_deg(phi_2_deg, "phi_2_deg"), helix_1=_deg(helix_1_deg, "helix_1_deg"),
                   helix_2=_deg(helix_2_deg, "helix_2_deg"), n_planets=n_planets,
                   face_width=None if face_width_mm is None else _mm(face_width_mm,
                                                                      "face_width_mm"),
                   name=name)


accept_old_names(SinglePinion, {"beta_1": "helix_1", "beta_2": "helix_2"})


@dataclass(frozen=True)
class DoublePinion:
    """Double pinion planet (sun - SP - RP - ring), seed 001 Fig. 5 / Tables 2, 4, 5.

    Parameters
    ----------
    r_sun : float
        Operating pitch radius of the sun at the sun-SP mesh [m].
    r_sp_sun, r_sp_rp : float
        Operating pitch radii of SP at the sun and RP meshes, R_SP-SUN, R_SP-RP [m].
    r_rp_sp, r_rp_ring : float
        Operating pitch radii of RP at the SP and ring meshes, R_RP-SP, R_RP-RING [m].
    included_angle_sp, included_angle_rp : float
        Included angles of the triangle of centres (sun axis, SP, RP) at SP and at RP [rad]
        (the seed's beta and gamma); included_angle_sp in (0, pi], included_angle_rp in
        [0, pi), their sum <= pi. pi and 0 put the meshes of each pinion diametrically
        opposite (seed Case 2-A).
    phi_1, phi_2, phi_3 : float
        Operating transverse pressure angles at the sun-SP, SP-RP and RP-ring meshes [rad].
    helix_1, helix_2, helix_3 : float
        Operating helix angles at the same meshes [rad] (named ``helix_*`` as in
        :class:`SinglePinion`; the seed uses beta for an included angle). Positive values give
        the seed's axial force signs (Table 5: FzSUN > 0, FzRP < 0 on SP; FzSP > 0,
        FzRING < 0 on RP).
    n_planets : int
        Number of SP-RP pinion pairs sharing the input torque [-].
    included_angle_sun : float, optional
        Included angle at the sun axis [rad] (the seed's alpha); derived as
        pi - included_angle_sp - included_angle_rp when omitted, and checked against it
        (1e-3 rad, the seed prints angles to 0.001 deg) when given.
    face_width : float, optional
        Contact face width b of the three meshes [m].
    name : str
        Free label.

    Notes
    -----
    Everything is SI; :meth:`from_mm_deg` takes the drawing's units (mm, deg). The old names
    ``beta``, ``gamma``, ``alpha`` still work as keywords and attributes, with a
    :class:`~meshphase.errors.DeprecatedNameWarning`.
    """

    r_sun: float
    r_sp_sun: float
    r_sp_rp: float
    r_rp_sp: float
    r_rp_ring: float
    included_angle_sp: float
    included_angle_rp: float
    phi_1: float
    phi_2: float
    phi_3: float
    helix_1: float
    helix_2: float
    helix_3: float
    n_planets: int
    included_angle_sun: float | None = None
    face_width: float | None = None
    name: str = ""

    def __post_init__(self):
        for n in ("r_sun", "r_sp_sun", "r_sp_rp", "r_rp_sp", "r_rp_ring"):
            object.__setattr__(self, n, as_positive(getattr(self, n), n))
        sp = _angle(self.included_angle_sp, "included_angle_sp", 0.0, math.pi, hi_open=False)
        rp = _angle(self.included_angle_rp, "included_angle_rp", 0.0, math.pi, lo_open=False)
        if sp + rp > math.pi + 1e-12:
            raise ValueError("included_angle_sp + included_angle_rp must not exceed pi, got "
                             f"included_angle_sp={sp!r}, included_angle_rp={rp!r}")
        object.__setattr__(self, "included_angle_sp", sp)
        object.__setattr__(self, "included_angle_rp", rp)
        sun = max(0.0, math.pi - sp - rp)
        if self.included_angle_sun is not None:
            a = as_float(self.included_angle_sun, "included_angle_sun")
            if abs(a - sun) > 1e-3:
                raise ValueError(
                    "included_angle_sun + included_angle_sp + included_angle_rp (the seed's "
                    "alpha + beta + gamma) must equal pi (triangle of centres), got "
                    f"included_angle_sun={a!r}, included_angle_sp={sp!r}, "
                    f"included_angle_rp={rp!r} (sum {a + sp + rp!r})")
        object.__setattr__(self, "included_angle_sun", sun)
        for n in ("phi_1", "phi_2", "phi_3"):
            object.__setattr__(self, n, _angle(getattr(self, n), n, 0.0, _HALF_PI))
        for n in ("helix_1", "helix_2", "helix_3"):
            object.__setattr__(self, n, _angle(getattr(self, n), n, -_HALF_PI, _HALF_PI))
        object.__setattr__(self, "n_planets", as_positive_int(self.n_planets, "n_planets"))
        if self.face_width is not None:
            object.__setattr__(self, "face_width", as_positive(self.face_width, "face_width"))
        if not isinstance(self.name, str):
            raise TypeError(f"name must be a string, got {self.name!r}")

    mesh_names = ("sun-SP", "SP-RP", "RP-ring")

    @classmethod
    def from_mm_deg(cls, *, r_sun_mm, r_sp_sun_mm, r_sp_rp_mm, r_rp_sp_mm, r_rp_ring_mm,
                    included_angle_sp_deg, included_angle_rp_deg, phi_1_deg, phi_2_deg,
                    phi_3_deg, helix_1_deg, helix_2_deg, helix_3_deg, n_planets,
                    included_angle_sun_deg=None, face_width_mm=None, name="") -> "DoublePinion":
        """Build from a gear drawing's units: radii and face width in [mm], angles in [deg].

        Every argument is keyword-only and carries its unit in its name (see the class for
        the meaning of each).
        """
        opt = {}
        if included_angle_sun_deg is not None:
            opt["included_angle_sun"] = _deg(included_angle_sun_deg, "included_angle_sun_deg")
        if face_width_mm is not None:
            opt["face_width"] = _mm(face_width_mm, "face_width_mm")
        return cls(r_sun=_mm(r_sun_mm, "r_sun_mm"), r_sp_sun=_mm(r_sp_sun_mm, "r_sp_sun_mm"),
                   r_sp_rp=_mm(r_sp_rp_mm, "r_sp_rp_mm"), r_rp_sp=_mm(r_rp_sp_mm, "r_rp_sp_mm"),
                   r_rp_ring=_mm(r_rp_ring_mm, "r_rp_ring_mm"),
                   included_angle_sp=_deg(included_angle_sp_deg, "included_angle_sp_deg"),
                   included_angle_rp=_deg(included_angle_rp_deg, "included_angle_rp_deg"),
                   phi_1=_deg(phi_1_deg, "phi_1_deg"), phi_2=_deg(phi_2_deg, "phi_2_deg"),
                   phi_3=_deg(phi_3_deg, "phi_3_deg"), helix_1=_deg(helix_1_deg, "helix_1_deg"),
                   helix_2=_deg(helix_2_deg, "helix_2_deg"),
                   helix_3=_deg(helix_3_deg, "helix_3_deg"), n_planets=n_planets, name=name,
                   **opt)


accept_old_names(DoublePinion, {"beta": "included_angle_sp", "gamma": "included_angle_rp",
                                "alpha": "included_angle_sun"})


# --------------------------------------------------------------------------------------------
# the common linear layout: mesh sides on pinions, per unit input torque
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class UnitLayout:
    """Per-unit-input-torque description of the mesh forces of one planet.

    A *side* is one mesh seen from one pinion (single pinion: sun, ring; double pinion:
    sp_sun, sp_rp, rp_sp, rp_ring). ``pos`` is the pitch point (x, y) in that pinion's frame
    [m]; ``force`` the force on the pinion (Fx, Fy, Fz) per N·m of input torque [1/m]; ``u`` the
    unit vector whose dot product with the pinion's (Mx, My) is the side's LOA moment.
    """

    sides: tuple
    meshes: tuple
    pinion: np.ndarray       # (S,) pinion index of each side
    mesh: np.ndarray         # (S,) mesh index of each side
    pos: np.ndarray          # (S, 2) [m]
    force: np.ndarray        # (S, 3) [N per N·m]
    u: np.ndarray            # (S, 2) [-]
    n_pinions: int

    @property
    def transverse(self) -> np.ndarray:
        """Transverse force magnitude per side per unit torque [1/m]."""
        return np.hypot(self.force[:, 0], self.force[:, 1])

    def mesh_force(self, basis: str) -> np.ndarray:
        """Per-mesh force per unit torque [1/m]: 'normal' |F|, 'tangential' F_t, 'transverse'."""
        out = np.zeros(len(self.meshes))
        for s, j in enumerate(self.mesh):
            fx, fy, fz = self.force[s]
            if basis == "normal":
                val = math.sqrt(fx * fx + fy * fy + fz * fz)
            elif basis == "transverse":
                val = math.hypot(fx, fy)
            else:  # tangential: component perpendicular to the radius through the pitch point
                px, py = self.pos[s]
                val = abs(px * fy - py * fx) / math.hypot(px, py)
            out[j] = val  # both sides of one mesh carry the same magnitude
        return out

    def side_matrix(self) -> np.ndarray:
        """(2P, S) matrix of the side LOA directions in the stacked (Mx_p, My_p) space."""
        e = np.zeros((2 * self.n_pinions, len(self.sides)))
        for s, p in enumerate(self.pinion):
            e[2 * p:2 * p + 2, s] = self.u[s]
        return e

    def mesh_matrix(self) -> np.ndarray:
        """(2P, J) matrix E: column j sums the LOA directions of the sides of mesh j."""
        es = self.side_matrix()
        e = np.zeros((es.shape[0], len(self.meshes)))
        for s, j in enumerate(self.mesh):
            e[:, j] += es[:, s]
        return e


def _side(pos_xy, f_dir, magnitude, fz):
    """Pack one side: pitch point, transverse force magnitude*direction, axial force."""
    fx, fy = magnitude * f_dir[0], magnitude * f_dir[1]
    return (pos_xy, (fx, fy, fz), (-f_dir[1], f_dir[0]))


def unit_layout(geom) -> UnitLayout:
    """The per-unit-torque layout of a SinglePinion or DoublePinion."""
    if isinstance(geom, SinglePinion):
        ft_s = 1.0 / (geom.n_planets * geom.r_sun)                 # -FyS per N·m
        ft_r = ft_s * geom.r_ps / geom.r_pr                        # -FyR per N·m
        p1, p2 = geom.phi_1, geom.phi_2
        s_sun = _side((-geom.r_ps, 0.0), (math.sin(p1), -math.cos(p1)), ft_s / math.cos(p1),
                      ft_s * math.tan(geom.helix_1))
        s_ring = _side((geom.r_pr, 0.0), (-math.sin(p2), -math.cos(p2)), ft_r / math.cos(p2),
                       -ft_r * math.tan(geom.helix_2))
        sides = (s_sun, s_ring)
        return UnitLayout(sides=("sun", "ring"), meshes=SinglePinion.mesh_names,
                       pinion=np.array([0, 0]), mesh=np.array([0, 1]),
                       pos=np.array([s[0] for s in sides], dtype=float),
                       force=np.array([s[1] for s in sides], dtype=float),
                       u=np.array([s[2] for s in sides], dtype=float), n_pinions=1)
    if isinstance(geom, DoublePinion):
        b, g = geom.included_angle_sp, geom.included_angle_rp
        p1, p2, p3 = geom.phi_1, geom.phi_2, geom.phi_3
        ft1 = 1.0 / (geom.n_planets * geom.r_sun)                  # sun-SP tangential per N·m
        ft2 = ft1 * geom.r_sp_sun / geom.r_sp_rp                   # SP-RP (Mz = 0 on SP)
        ft3 = ft2 * geom.r_rp_sp / geom.r_rp_ring                  # RP-ring (Mz = 0 on RP)
        sides = (
            _side((-geom.r_sp_sun, 0.0), (math.sin(p1), -math.cos(p1)), ft1 / math.cos(p1),
                  ft1 * math.tan(geom.helix_1)),
            _side((-geom.r_sp_rp * math.cos(b), -geom.r_sp_rp * math.sin(b)),
                  (-math.sin(b - p2), math.cos(b - p2)), ft2 / math.cos(p2),
                  -ft2 * math.tan(geom.helix_2)),
            _side((-geom.r_rp_sp * math.cos(g), geom.r_rp_sp * math.sin(g)),
                  (math.sin(g + p2), math.cos(g + p2)), ft2 / math.cos(p2),
                  ft2 * math.tan(geom.helix_2)),
            _side((geom.r_rp_ring, 0.0), (-math.sin(p3), math.cos(p3)), ft3 / math.cos(p3),
                  -ft3 * math.tan(geom.helix_3)),
        )
        return UnitLayout(sides=("sp_sun", "sp_rp", "rp_sp", "rp_ring"),
                       meshes=DoublePinion.mesh_names,
                       pinion=np.array([0, 0, 1, 1]), mesh=np.array([0, 1, 1, 2]),
                       pos=np.array([s[0] for s in sides], dtype=float),
                       force=np.array([s[1] for s in sides], dtype=float),
                       u=np.array([s[2] for s in sides], dtype=float), n_pinions=2)
    raise TypeError(f"geom must be a SinglePinion or DoublePinion, got {type(geom).__name__}")


def _evaluate(lay: UnitLayout, torque: np.ndarray, z: np.ndarray):
    """Forces, per-side moment contributions, pinion moments and LOA moments.

    torque (...) [N·m]; z (..., J) [m], broadcast together. Returns
    forces (..., S, 3), contrib (..., S, 3) = r_s x F_s, m (..., P, 3), loa (..., S).
    """
    torque = np.asarray(torque, dtype=float)
    z = np.asarray(z, dtype=float)
    shape = np.broadcast_shapes(torque.shape, z.shape[:-1])
    torque = np.broadcast_to(torque, shape)
    z = np.broadcast_to(z, shape + (z.shape[-1],))
    forces = torque[..., None, None] * lay.force                          # (..., S, 3)
    zs = z[..., lay.mesh]                                                 # (..., S)
    x, y = lay.pos[:, 0], lay.pos[:, 1]
    fx, fy, fz = forces[..., 0], forces[..., 1], forces[..., 2]
    contrib = np.stack([y * fz - zs * fy, zs * fx - x * fz, x * fy - y * fx], axis=-1)
    onehot = (lay.pinion[None, :] == np.arange(lay.n_pinions)[:, None]).astype(float)  # (P, S)
    m = np.einsum("ps,...sk->...pk", onehot, contrib)                     # (..., P, 3)
    mp = m[..., lay.pinion, :2]                                           # (..., S, 2)
    loa = np.einsum("...sk,sk->...s", mp, lay.u)
    return forces, contrib, m, loa


# --------------------------------------------------------------------------------------------
# results
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class MeshForces:
    """Mesh forces on the pinion(s) of one planet, in each pinion's frame.

    Attributes
    ----------
    sides : tuple of str
        Side names in the order of the last axis (single: 'sun', 'ring'; double: 'sp_sun',
        'sp_rp', 'rp_sp', 'rp_ring').
    fx, fy, fz : ndarray, shape (..., S)
        Radial (X), tangential (Y) and axial (Z) force on the pinion at each side [N].
    """

    sides: tuple
    fx: np.ndarray
    fy: np.ndarray
    fz: np.ndarray

    def side(self, name: str):
        """(fx, fy, fz) of one side [N]."""
        i = self.sides.index(as_choice(name, "name", self.sides))
        return self.fx[..., i], self.fy[..., i], self.fz[..., i]

    @property
    def transverse(self) -> np.ndarray:
        """Transverse force magnitude hypot(fx, fy) per side [N]."""
        return np.hypot(self.fx, self.fy)

    @property
    def normal(self) -> np.ndarray:
        """Total mesh force magnitude |F| per side [N]."""
        return np.sqrt(self.fx ** 2 + self.fy ** 2 + self.fz ** 2)


class _CommonMoments:
    """The names :class:`BearingMoments` and :class:`DoublePinionMoments` share.

    A :class:`~meshphase.models.tilt.TiltSolution` holds either; code that reads these names
    works for both (a single pinion is one pinion with meshes sun and ring; a double pinion
    has pinions SP and RP and meshes sun-SP, SP-RP, RP-ring).

    Attributes
    ----------
    mesh_names : tuple of str
        Mesh order of :attr:`z` (last axis).
    pinion_names : tuple of str
        Pinion order of :attr:`bending`.
    loa_names : tuple of str
        Order of the line-of-action moments in :attr:`loa`: one per mesh side on a pinion
        (single: 'sun', 'ring'; double: 'sp_sun', 'sp_rp', 'rp_sp', 'rp_ring').

    Both also have ``m_loa_sun`` and ``m_loa_ring`` (the LOA moments at the sun and ring
    meshes [N·m]; double pinion: M_SP-SUN and M_RP-RING), ``loa`` (..., len(loa_names))
    [N·m], ``z`` (..., len(mesh_names)) [m] and ``bending`` (..., len(pinion_names), 2),
    the (Mx, My) of each pinion [N·m].
    """

    def _scalar_fields(self, names):
        for n in names:
            object.__setattr__(self, n, as_scalar(getattr(self, n)))

    @property
    def z_sun(self):
        """Load-centroid offset at the sun mesh [m]."""
        return as_scalar(np.asarray(self.z)[..., 0])

    @property
    def z_ring(self):
        """Load-centroid offset at the ring mesh [m]."""
        return as_scalar(np.asarray(self.z)[..., -1])

    def loa_of(self, name: str):
        """One line-of-action moment by its name in :attr:`loa_names` [N·m]."""
        i = self.loa_names.index(as_choice(name, "name", self.loa_names))
        return as_scalar(self.loa[..., i])


@dataclass(frozen=True)
class BearingMoments(_CommonMoments):
    """Forces and moments on a single pinion (seed Tables 3, 7, 8, 9).

    Attributes
    ----------
    mx, my, mz : ndarray
        Net moments Mx-PIN, My-PIN, Mz-PIN on the pinion [N·m] (Mz is 0 by torque balance).
    m_loa_sun, m_loa_ring : ndarray
        Moments causing misalignment in the sun-pinion and ring-pinion planes of action
        [N·m]; positive pushes the load towards -z.
    mx_ld, my_ld : ndarray
        Parts of mx, my due to the load-distribution offsets alone (Table 8's Mx^LD, My^LD)
        [N·m].
    m_loa_sun_ld, m_loa_ring_ld : ndarray
        Parts of the LOA moments due to the offsets alone (Table 9's LD rows) [N·m].
    z_s, z_r : ndarray
        The offsets used [m].
    forces : MeshForces
        The mesh forces (sides 'sun', 'ring') [N].

    Notes
    -----
    Values are Python floats when the inputs were scalars. The names shared with
    :class:`DoublePinionMoments` (``m_loa_sun``, ``m_loa_ring``, ``z``, ``z_sun``,
    ``z_ring``, ``loa``, ``loa_names``, ``loa_of``, ``bending``, ``mesh_names``,
    ``pinion_names``) are listed in ``_CommonMoments``.
    """

    mx: np.ndarray
    my: np.ndarray
    mz: np.ndarray
    m_loa_sun: np.ndarray
    m_loa_ring: np.ndarray
    mx_ld: np.ndarray
    my_ld: np.ndarray
    m_loa_sun_ld: np.ndarray
    m_loa_ring_ld: np.ndarray
    z_s: np.ndarray
    z_r: np.ndarray
    forces: MeshForces

    mesh_names = SinglePinion.mesh_names
    pinion_names = ("pinion",)
    loa_names = ("sun", "ring")

    def __post_init__(self):
        self._scalar_fields(("mx", "my", "mz", "m_loa_sun", "m_loa_ring", "mx_ld", "my_ld",
                             "m_loa_sun_ld", "m_loa_ring_ld", "z_s", "z_r"))

    @property
    def total(self) -> np.ndarray:
        """Magnitude of the bending moment hypot(Mx, My) [N·m]."""
        return as_scalar(np.hypot(self.mx, self.my))

    @property
    def loa(self) -> np.ndarray:
        """LOA moments stacked on a last axis (sun, ring) [N·m]."""
        return np.stack([self.m_loa_sun, self.m_loa_ring], axis=-1)

    @property
    def z(self) -> np.ndarray:
        """Offsets stacked on a last axis (sun, ring) [m]."""
        return np.stack([self.z_s, self.z_r], axis=-1)

    @property
    def bending(self) -> np.ndarray:
        """Pinion bending moments (Mx, My), shape (..., 1, 2) [N·m]."""
        return np.stack([self.mx, self.my], axis=-1)[..., None, :]


@dataclass(frozen=True)
class DoublePinionMoments(_CommonMoments):
    """Forces and moments on the SP and RP pinions (seed Tables 4, 5, 11).

    Attributes
    ----------
    mx_sp, my_sp, mx_rp, my_rp : ndarray
        Net moments on SP and RP in their own frames [N·m].
    mz_sp, mz_rp : ndarray
        Net moments about the pinion axes [N·m] (0 by torque balance).
    m_sp_sun, m_sp_rp, m_rp_sp, m_rp_ring : ndarray
        LOA moments (seed M_SP-SUN, M_SP-RP, M_RP-SP, M_RP-RING) [N·m]; positive pushes the
        load towards -z.
    contributions : dict
        Table 5's rows: force name ('FzSUN', 'FzRP', 'FzSP', 'FzRING') -> (Mx, My) of that
        side's full mesh force [N·m] (with centred loads only the axial force contributes).
    z : ndarray, shape (..., 3)
        Offsets used for the sun-SP, SP-RP and RP-ring meshes [m].
    forces : MeshForces
        Mesh forces (sides 'sp_sun', 'sp_rp' in the SP frame; 'rp_sp', 'rp_ring' in RP's) [N].

    Notes
    -----
    Values are Python floats when the inputs were scalars. ``m_loa_sun`` (= ``m_sp_sun``),
    ``m_loa_ring`` (= ``m_rp_ring``), ``z_sun``, ``z_ring``, ``loa_names``, ``loa_of``,
    ``bending``, ``mesh_names`` and ``pinion_names`` are the names shared with
    :class:`BearingMoments`.
    """

    mx_sp: np.ndarray
    my_sp: np.ndarray
    mx_rp: np.ndarray
    my_rp: np.ndarray
    m_sp_sun: np.ndarray
    m_sp_rp: np.ndarray
    m_rp_sp: np.ndarray
    m_rp_ring: np.ndarray
    mz_sp: np.ndarray
    mz_rp: np.ndarray
    contributions: dict = field(compare=False)
    z: np.ndarray = field(compare=False, default=None)
    forces: MeshForces = field(compare=False, default=None)

    mesh_names = DoublePinion.mesh_names
    pinion_names = ("SP", "RP")
    loa_names = ("sp_sun", "sp_rp", "rp_sp", "rp_ring")

    def __post_init__(self):
        self._scalar_fields(("mx_sp", "my_sp", "mx_rp", "my_rp", "m_sp_sun", "m_sp_rp",
                             "m_rp_sp", "m_rp_ring", "mz_sp", "mz_rp"))
        if isinstance(self.contributions, dict):
            object.__setattr__(self, "contributions", {
                k: tuple(as_scalar(v) for v in pair) for k, pair in self.contributions.items()})

    @property
    def m_loa_sun(self):
        """LOA moment at the sun mesh, M_SP-SUN [N·m] (same name as the single pinion's)."""
        return self.m_sp_sun

    @property
    def m_loa_ring(self):
        """LOA moment at the ring mesh, M_RP-RING [N·m] (same name as the single pinion's)."""
        return self.m_rp_ring

    @property
    def bending(self) -> np.ndarray:
        """Pinion bending moments (Mx, My) of SP and RP, shape (..., 2, 2) [N·m]."""
        return np.stack([np.stack([self.mx_sp, self.my_sp], axis=-1),
                         np.stack([self.mx_rp, self.my_rp], axis=-1)], axis=-2)

    @property
    def total_sp(self) -> np.ndarray:
        """Bending moment magnitude on SP hypot(Mx_SP, My_SP) [N·m]."""
        return as_scalar(np.hypot(self.mx_sp, self.my_sp))

    @property
    def total_rp(self) -> np.ndarray:
        """Bending moment magnitude on RP [N·m]."""
        return as_scalar(np.hypot(self.mx_rp, self.my_rp))

    @property
    def loa(self) -> np.ndarray:
        """The four LOA moments on a last axis, seed Table 11 order [N·m]."""
        return np.stack([self.m_sp_sun, self.m_sp_rp, self.m_rp_sp, self.m_rp_ring], axis=-1)


# --------------------------------------------------------------------------------------------
# forward models
# --------------------------------------------------------------------------------------------
def _check_geom(geom, cls):
    if not isinstance(geom, cls):
        raise TypeError(f"geom must be a {cls.__name__}, got {type(geom).__name__}")


def single_pinion_forces(geom: SinglePinion, input_torque) -> MeshForces:
    """Mesh forces on a single pinion (seed 001, Case 1 force list under Table 3).

    Parameters
    ----------
    geom : SinglePinion
        Pinion geometry.
    input_torque : array_like
        Sun input torque T_in [N·m], >= 0; shared by ``geom.n_planets`` planets.

    Returns
    -------
    MeshForces
        Sides ('sun', 'ring'), arrays shaped like ``input_torque`` plus a last axis of 2 [N].

    Notes
    -----
    Per mesh T = T_in / N; FyS = -T / R_SUN, FyR = -(T / R_SUN)(R_pS / R_pR) (torque balance of
    the pinion, Mz = 0), FxS = -FyS tan(phi_1), FxR = FyR tan(phi_2) (separating forces),
    FzS = -FyS tan(beta_1), FzR = FyR tan(beta_2).
    """
    _check_geom(geom, SinglePinion)
    t = _torque_array(input_torque)
    forces, _, _, _ = _evaluate(unit_layout(geom), t, np.zeros(t.shape + (2,)))
    return MeshForces(("sun", "ring"), forces[..., 0], forces[..., 1], forces[..., 2])


def single_pinion_moments(geom: SinglePinion, input_torque, z_s=0.0, z_r=0.0) -> BearingMoments:
    """Bearing and line-of-action moments on a single pinion (spec 4; seed Tables 3, 7-9).

    Parameters
    ----------
    geom : SinglePinion
        Pinion geometry.
    input_torque : array_like
        Sun input torque T_in [N·m], >= 0.
    z_s, z_r : array_like
        Axial offsets Z_S, Z_R of the centroids of the distributed loads at the sun and ring
        meshes [m] (0 = centred pattern). All three inputs broadcast together.

    Returns
    -------
    BearingMoments

    Notes
    -----
    With the forces of :func:`single_pinion_forces` acting at (x, y, z) = (-R_pS, 0, Z_S) and
    (R_pR, 0, Z_R) in the pinion frame, M = sum r x F gives (seed Table 7)

        Mx = -(FyS Z_S + FyR Z_R)
        My = (FzS R_pS - FzR R_pR) + (FxS Z_S + FxR Z_R)      Mz = 0

    and the moments tilting the pinion in the two planes of action (seed Fig. 4)

        M_LOA,sun  = Mx cos(phi_1) + My sin(phi_1)
        M_LOA,ring = Mx cos(phi_2) - My sin(phi_2).

    The LOA direction of a mesh is (-f_y, f_x) for the unit transverse force direction f on the
    pinion: a tilt theta about that direction changes the mesh approach by -theta z along the
    face width, so a positive LOA moment pushes the load towards -z, as the seed states.
    """
    _check_geom(geom, SinglePinion)
    t = _torque_array(input_torque)
    zs = real_array(z_s, "z_s")
    zr = real_array(z_r, "z_r")
    zs, zr = np.broadcast_arrays(zs, zr)
    z = np.stack([zs, zr], axis=-1)
    lay = unit_layout(geom)
    forces, _, m, loa = _evaluate(lay, t, z)
    _, _, m0, loa0 = _evaluate(lay, t, np.zeros_like(z))
    shape = m.shape[:-2]
    return BearingMoments(
        mx=m[..., 0, 0], my=m[..., 0, 1], mz=m[..., 0, 2],
        m_loa_sun=loa[..., 0], m_loa_ring=loa[..., 1],
        mx_ld=m[..., 0, 0] - m0[..., 0, 0], my_ld=m[..., 0, 1] - m0[..., 0, 1],
        m_loa_sun_ld=loa[..., 0] - loa0[..., 0], m_loa_ring_ld=loa[..., 1] - loa0[..., 1],
        z_s=np.broadcast_to(zs, shape), z_r=np.broadcast_to(zr, shape),
        forces=MeshForces(("sun", "ring"), forces[..., 0], forces[..., 1], forces[..., 2]))


def double_pinion_moments(geom: DoublePinion, input_torque, z_sun=0.0, z_mid=0.0,
                          z_ring=0.0) -> DoublePinionMoments:
    """Bearing and LOA moments on the SP and RP pinions (spec 4; seed Tables 4, 5, 11).

    Parameters
    ----------
    geom : DoublePinion
        Double pinion geometry.
    input_torque : array_like
        Sun input torque T_in [N·m], >= 0.
    z_sun, z_mid, z_ring : array_like
        Load-centroid offsets at the sun-SP, SP-RP and RP-ring meshes [m] (the SP-RP contact
        is one load pattern shared by both pinions). All inputs broadcast together.

    Returns
    -------
    DoublePinionMoments

    Notes
    -----
    The pitch points sit at (-R_SP-SUN, 0) and R_SP-RP(-cos beta, -sin beta) in the SP frame,
    R_RP-SP(-cos gamma, sin gamma) and (R_RP-RING, 0) in the RP frame. With centred loads,
    M = sum r x F reproduces the seed's Table 4:

        Mx_SP = -F_zRP R_SP-RP sin(beta)     My_SP = F_zSUN R_SP-SUN + F_zRP R_SP-RP cos(beta)
        Mx_RP =  F_zSP R_RP-SP sin(gamma)    My_RP = F_zSP R_RP-SP cos(gamma) - F_zRING R_RP-RING

    and the LOA directions (-f_y, f_x) of the four sides reproduce the seed's LOA formulas

        M_SP-SUN  =  Mx_SP cos(phi_1)         + My_SP sin(phi_1)
        M_SP-RP   = -Mx_SP cos(beta - phi_2)  - My_SP sin(beta - phi_2)
        M_RP-SP   = -Mx_RP cos(gamma + phi_2) + My_RP sin(gamma + phi_2)
        M_RP-RING = -Mx_RP cos(phi_3)         - My_RP sin(phi_3).

    The tangential forces follow from Mz = 0 on each pinion (F_t2 = F_t1 R_SP-SUN / R_SP-RP,
    F_t3 = F_t2 R_RP-SP / R_RP-RING); the axial force F_t tan(helix) is then the same at every
    mesh (5919 N in the seed's cases, as it says). The force on RP at the SP-RP mesh is minus
    the force on SP, turned into the RP frame; the RP-SP LOA direction is then minus the SP-RP
    one in a common frame, so the SP-RP mesh sees the *relative* tilt of the two pinions
    (seed: "net differential moment ... only 11 N m" = M_SP-RP + M_RP-SP).

    beta = pi, gamma = 0 reduces SP to the single pinion of Table 3 (Case 2-A). RP's frame is
    the mirror image of a single pinion's (its flanks are loaded the other way), hence the
    opposite sign of its Mx terms in the LOA formulas.

    Offsets add ``Z (-F_y, F_x) = Z |F_T| u`` to the pinion moment of each side; the seed only
    analyses them for the single pinion, the generalisation is the same r x F.
    """
    _check_geom(geom, DoublePinion)
    t = _torque_array(input_torque)
    a = real_array(z_sun, "z_sun")
    b = real_array(z_mid, "z_mid")
    c = real_array(z_ring, "z_ring")
    a, b, c = np.broadcast_arrays(a, b, c)
    z = np.stack([a, b, c], axis=-1)
    lay = unit_layout(geom)
    forces, contrib, m, loa = _evaluate(lay, t, z)
    names = ("FzSUN", "FzRP", "FzSP", "FzRING")
    contributions = {n: (contrib[..., s, 0], contrib[..., s, 1]) for s, n in enumerate(names)}
    shape = m.shape[:-2]
    return DoublePinionMoments(
        mx_sp=m[..., 0, 0], my_sp=m[..., 0, 1], mx_rp=m[..., 1, 0], my_rp=m[..., 1, 1],
        m_sp_sun=loa[..., 0], m_sp_rp=loa[..., 1], m_rp_sp=loa[..., 2], m_rp_ring=loa[..., 3],
        mz_sp=m[..., 0, 2], mz_rp=m[..., 1, 2], contributions=contributions,
        z=np.broadcast_to(z, shape + (3,)),
        forces=MeshForces(lay.sides, forces[..., 0], forces[..., 1], forces[..., 2]))


# --------------------------------------------------------------------------------------------
# inverse use
# --------------------------------------------------------------------------------------------
def offset_system(geom):
    """m = m0 + A z with A per unit torque: returns (m0 per unit torque (2P,), A (2P, J))."""
    lay = unit_layout(geom)
    j = len(lay.meshes)
    _, _, m0, _ = _evaluate(lay, np.ones(()), np.zeros(j))
    a = np.zeros((2 * lay.n_pinions, j))
    for k in range(j):
        e = np.zeros(j)
        e[k] = 1.0
        _, _, mk, _ = _evaluate(lay, np.ones(()), e)
        a[:, k] = (mk[:, :2] - m0[:, :2]).ravel()
    return m0[:, :2].ravel(), a


def moments_from_offsets(geom: SinglePinion, input_torque, z_s, z_r):
    """Net pinion moments (Mx, My) from load-centroid offsets (forward of the inverse pair).

    Parameters
    ----------
    geom : SinglePinion
        Pinion geometry.
    input_torque : array_like
        Sun input torque [N·m], >= 0.
    z_s, z_r : array_like
        Offsets of the load centroids at the sun and ring meshes [m].

    Returns
    -------
    mx, my : ndarray
        Mx-PIN and My-PIN [N·m] (same as :func:`single_pinion_moments`).
    """
    res = single_pinion_moments(geom, input_torque, z_s, z_r)
    return res.mx, res.my


def offsets_from_moments(geom: SinglePinion, input_torque, mx, my):
    """Load-centroid offsets (Z_S, Z_R) that produce given pinion moments (spec 4, inverse).

    Parameters
    ----------
    geom : SinglePinion
        Pinion geometry.
    input_torque : array_like
        Sun input torque [N·m], > 0.
    mx, my : array_like
        Measured or simulated Mx-PIN, My-PIN [N·m]. All inputs broadcast together.

    Returns
    -------
    z_s, z_r : ndarray
        Offsets [m].

    Raises
    ------
    ValueError
        Non-finite inputs, or a zero torque (the offsets are then undetermined).

    Notes
    -----
    Solves the 2x2 linear system of seed Table 7,

        Mx           = -(FyS Z_S + FyR Z_R)
        My - My(0)   =  FxS Z_S + FxR Z_R,

    whose determinant FyR FxS - FyS FxR = -(T/R_SUN)^2 (R_pS/R_pR)(tan phi_1 + tan phi_2) never
    vanishes for positive pressure angles. This is how the seed's Table 10 "Computed" Z_S,
    Z_R follow from GSAM's moments.
    """
    _check_geom(geom, SinglePinion)
    t = _torque_array(input_torque)
    if t.size and np.any(t == 0):
        raise ValueError("input_torque must be > 0 to recover offsets (no load, no centroid)")
    mx = real_array(mx, "mx")
    my = real_array(my, "my")
    m0, a = offset_system(geom)
    t, mx, my = np.broadcast_arrays(t, mx, my)
    rhs = np.stack([mx, my], axis=-1) / np.where(t == 0, 1.0, t)[..., None] - m0
    z = np.linalg.solve(a, rhs[..., None])[..., 0] if rhs.size else np.zeros(rhs.shape)
    return as_scalar(z[..., 0]), as_scalar(z[..., 1])


def loa_from_moments(geom: SinglePinion, mx, my):
    """Line-of-action moments of a single pinion from given (e.g. measured) Mx, My.

    Parameters
    ----------
    geom : SinglePinion
        Pinion geometry (only the pressure angles enter).
    mx, my : array_like
        Net pinion moments Mx-PIN, My-PIN [N·m]; broadcast together.

    Returns
    -------
    m_loa_sun, m_loa_ring : ndarray
        Mx cos(phi_1) + My sin(phi_1) and Mx cos(phi_2) - My sin(phi_2) [N·m] (seed Fig. 4);
        seed Table 10 gets its M_LOA columns from GSAM's Mx, My this way.
    """
    _check_geom(geom, SinglePinion)
    mx = real_array(mx, "mx")
    my = real_array(my, "my")
    u = unit_layout(geom).u
    return as_scalar(mx * u[0, 0] + my * u[0, 1]), as_scalar(mx * u[1, 0] + my * u[1, 1])


def double_pinion_offsets_from_moments(geom: DoublePinion, input_torque, mx_sp, my_sp, mx_rp,
                                       my_rp):
    """Offsets (Z_sun, Z_mid, Z_ring) from the four pinion moments, by least squares.

    Parameters
    ----------
    geom : DoublePinion
        Geometry.
    input_torque : array_like
        Sun input torque [N·m], > 0.
    mx_sp, my_sp, mx_rp, my_rp : array_like
        Net moments on SP and RP in their frames [N·m]. All inputs broadcast together.

    Returns
    -------
    z_sun, z_mid, z_ring : ndarray
        Offsets at the sun-SP, SP-RP and RP-ring meshes [m].

    Notes
    -----
    Four moments, three offsets (the SP-RP pattern is shared by both pinions): the system is
    solved in the least-squares sense, exactly when the moments come from
    :func:`double_pinion_moments`.
    """
    _check_geom(geom, DoublePinion)
    t = _torque_array(input_torque)
    if t.size and np.any(t == 0):
        raise ValueError("input_torque must be > 0 to recover offsets (no load, no centroid)")
    arrs = [real_array(v, n) for v, n in ((mx_sp, "mx_sp"), (my_sp, "my_sp"),
                                           (mx_rp, "mx_rp"), (my_rp, "my_rp"))]
    m0, a = offset_system(geom)
    t, *arrs = np.broadcast_arrays(t, *arrs)
    rhs = np.stack(arrs, axis=-1) / np.where(t == 0, 1.0, t)[..., None] - m0
    pinv = np.linalg.pinv(a)
    z = rhs @ pinv.T
    return as_scalar(z[..., 0]), as_scalar(z[..., 1]), as_scalar(z[..., 2])


# --------------------------------------------------------------------------------------------
# parametric study (seed Fig. 6 and Table 6)
# --------------------------------------------------------------------------------------------
def _pressure_array(phi, name="phi") -> np.ndarray:
    arr = real_array(phi, name)
    if arr.size and np.any((arr <= 0) | (arr >= _HALF_PI)):
        raise ValueError(f"{name} must lie in (0, pi/2) rad, got range "
                         f"[{float(arr.min())!r}, {float(arr.max())!r}]")
    return arr


def _radius_pair(r_mesh, r_inter):
    rm = real_array(r_mesh, "r_mesh")
    if rm.size and np.any(rm <= 0):
        raise ValueError(f"r_mesh must be > 0 [m], got min {float(rm.min())!r}")
    if r_inter is None:
        return rm, rm
    ri = real_array(r_inter, "r_inter")
    if ri.size and np.any(ri <= 0):
        raise ValueError(f"r_inter must be > 0 [m], got min {float(ri.min())!r}")
    return rm, ri


@renamed_kwargs({"beta": "included_angle_sp"})
def sp_sun_moment(axial_force, r_mesh, phi, included_angle_sp, r_inter=None):
    """Sun-SP misaligning moment as a function of the included angle at SP (seed Fig. 6a).

    Parameters
    ----------
    axial_force : array_like
        Axial force magnitude F_A = F_zSUN = -F_zRP [N].
    r_mesh : array_like
        Pitch radius of SP at the sun mesh R_SP-SUN [m].
    phi : array_like
        Transverse pressure angle, taken equal at both SP meshes [rad], in (0, pi/2).
    included_angle_sp : array_like
        Included angle at SP, the seed's beta [rad] (old keyword ``beta``: deprecated).
    r_inter : array_like, optional
        Pitch radius of SP at the RP mesh R_SP-RP [m]; defaults to ``r_mesh`` (the seed's
        R_SP-RP ~ R_SP-SUN = R_SP approximation).

    Returns
    -------
    ndarray
        M_SP-SUN [N·m].

    Notes
    -----
    Substituting F_zSUN = -F_zRP = F_A and phi_1 = phi_2 = phi in the Table 4 moments gives
    M_SP-SUN = F_A [R_SP-RP sin(beta - phi) + R_SP-SUN sin(phi)], the seed's
    F_A R_SP (sin(beta - phi) + sin(phi)) when the radii are equal; beta = pi is the single
    pinion, F_A (R_SP-SUN + R_SP-RP) sin(phi).
    """
    fa = real_array(axial_force, "axial_force")
    rm, ri = _radius_pair(r_mesh, r_inter)
    p = _pressure_array(phi)
    b = real_array(included_angle_sp, "included_angle_sp")
    return as_scalar(fa * (ri * np.sin(b - p) + rm * np.sin(p)))


@renamed_kwargs({"gamma": "included_angle_rp"})
def rp_ring_moment(axial_force, r_mesh, phi, included_angle_rp, r_inter=None):
    """RP-ring misaligning moment as a function of the included angle at RP (seed Fig. 6b).

    Parameters
    ----------
    axial_force : array_like
        Axial force magnitude F_A = F_zRING = -F_zSP [N].
    r_mesh : array_like
        Pitch radius of RP at the ring mesh R_RP-RING [m].
    phi : array_like
        Transverse pressure angle, taken equal at both RP meshes [rad].
    included_angle_rp : array_like
        Included angle at RP, the seed's gamma [rad] (old keyword ``gamma``: deprecated).
    r_inter : array_like, optional
        Pitch radius of RP at the SP mesh R_RP-SP [m]; defaults to ``r_mesh``.

    Returns
    -------
    ndarray
        |M_RP-RING| [N·m] for the parametric sign convention of the seed.

    Notes
    -----
    M_RP-RING = F_A [R_RP-SP sin(gamma + phi) + R_RP-RING sin(phi)] (seed: F_A R_RP
    (sin(gamma + phi) + sin(phi))); gamma = 0 is the single pinion.
    """
    fa = real_array(axial_force, "axial_force")
    rm, ri = _radius_pair(r_mesh, r_inter)
    p = _pressure_array(phi)
    g = real_array(included_angle_rp, "included_angle_rp")
    return as_scalar(fa * (ri * np.sin(g + p) + rm * np.sin(p)))


def worst_case_angles(phi):
    """Included angles of the largest misaligning moments (seed Table 6).

    Parameters
    ----------
    phi : array_like
        Transverse pressure angle [rad], in (0, pi/2).

    Returns
    -------
    included_angle_sp_worst, included_angle_rp_worst : ndarray or float
        The seed's beta = pi/2 + phi (sun-SP mesh) and gamma = pi/2 - phi (RP-ring mesh)
        [rad], where
        d M / d beta = F_A R cos(beta - phi) = 0 and d M / d gamma = F_A R cos(gamma + phi) = 0.
    """
    p = _pressure_array(phi)
    return as_scalar(_HALF_PI + p), as_scalar(_HALF_PI - p)


def worst_case_moment(axial_force, r_mesh, phi, r_inter=None):
    """Largest misaligning moment over the included angle (seed Table 6, first column).

    Parameters
    ----------
    axial_force : array_like
        Axial force magnitude F_A [N].
    r_mesh : array_like
        Pinion pitch radius at the sun (or ring) mesh [m].
    phi : array_like
        Transverse pressure angle [rad].
    r_inter : array_like, optional
        Pinion pitch radius at the pinion-pinion mesh [m]; defaults to ``r_mesh``.

    Returns
    -------
    ndarray
        F_A (R_inter + R_mesh sin(phi)) [N·m]; the seed's F_A R_SP (1 + sin(phi)) for equal
        radii. Same expression for both the sun-SP (beta = pi/2 + phi) and the RP-ring
        (gamma = pi/2 - phi) meshes.

    Notes
    -----
    Seed disagreement: the printed column (167, 178, 189, 199 N·m at 15-30 deg) is not the
    equal-radius formula of its heading (that gives 165, 176, 186, 197 with F_A = 5919 N,
    R_SP = 22.141 mm). It is this two-radius expression with F_A = 5919 N, R_mesh = 22.141 mm
    and R_inter = 22.510 mm, i.e. the Case 1 pinion's sun and ring radii (the same values the
    seed's Case 2-A copied from Case 1).
    """
    fa = real_array(axial_force, "axial_force")
    rm, ri = _radius_pair(r_mesh, r_inter)
    p = _pressure_array(phi)
    return as_scalar(fa * (ri + rm * np.sin(p)))


def single_equivalent_moment(axial_force, r_mesh, phi, r_inter=None):
    """Misaligning moment of the equivalent single pinion (seed Table 6, second column).

    Parameters
    ----------
    axial_force : array_like
        Axial force magnitude F_A [N].
    r_mesh : array_like
        Pinion pitch radius at the sun (or ring) mesh [m].
    phi : array_like
        Transverse pressure angle [rad].
    r_inter : array_like, optional
        Pitch radius at the other mesh [m]; defaults to ``r_mesh``.

    Returns
    -------
    ndarray
        F_A (R_mesh + R_inter) sin(phi) [N·m] (beta = pi or gamma = 0), the seed's
        2 F_A R sin(phi) for equal radii.
    """
    fa = real_array(axial_force, "axial_force")
    rm, ri = _radius_pair(r_mesh, r_inter)
    p = _pressure_array(phi)
    return as_scalar(fa * (rm + ri) * np.sin(p))


def same_as_single_angle(phi, mesh: str = "sp_sun"):
    """Included angle giving the same misaligning moment as the single pinion (seed Table 6).

    Parameters
    ----------
    phi : array_like
        Transverse pressure angle [rad].
    mesh : {"sp_sun", "rp_ring"}
        Which mesh: sun-SP (included angle at SP, the seed's beta) or RP-ring (included
        angle at RP, the seed's gamma).

    Returns
    -------
    ndarray
        sp_sun: beta = 2 phi (sin(beta - phi) = sin(pi - phi)); rp_ring: gamma = pi - 2 phi
        (sin(gamma + phi) = sin(phi)), which the seed notes is not feasible for
        gamma < pi/2 with phi < pi/4 [rad].
    """
    p = _pressure_array(phi)
    mesh = as_choice(mesh, "mesh", ("sp_sun", "rp_ring"))
    return as_scalar(2.0 * p if mesh == "sp_sun" else math.pi - 2.0 * p)


def worst_to_single_ratio(phi, r_mesh=1.0, r_inter=None):
    """Ratio of the worst-case to the equivalent single pinion moment (seed Table 6).

    Parameters
    ----------
    phi : array_like
        Transverse pressure angle [rad].
    r_mesh : array_like
        Pinion pitch radius at the sun/ring mesh [m] (only the ratio to ``r_inter`` matters).
    r_inter : array_like, optional
        Pitch radius at the pinion-pinion mesh [m]; defaults to ``r_mesh``.

    Returns
    -------
    ndarray
        (R_inter + R_mesh sin(phi)) / ((R_mesh + R_inter) sin(phi)) [-]; the seed's
        (1 + sin(phi)) / (2 sin(phi)) for equal radii (1.88 at 21.3 deg, 1.78 at 23 deg, as the
        seed quotes with its Fig. 6).
    """
    rm, ri = _radius_pair(r_mesh, r_inter)
    p = _pressure_array(phi)
    return as_scalar((ri + rm * np.sin(p)) / ((rm + ri) * np.sin(p)))


# --------------------------------------------------------------------------------------------
# seed cases
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SeedCase:
    """One of the seed's worked cases.

    Attributes
    ----------
    name : str
        Case label ('1', '2-A', '2-B').
    geometry : SinglePinion or DoublePinion
        Geometry derived from the seed's gear data.
    input_torque : float
        Sun input torque [N·m].
    source : str
        Where the data come from.
    """

    name: str
    geometry: object
    input_torque: float
    source: str


_MM = 1e-3
_DEG = math.pi / 180.0
#: Gear data of seed 001 Tables 1 and 2 (SI).
_SEED_GEAR = dict(normal_module=1.59 * _MM, normal_pressure_angle=20.0 * _DEG,
                  helix_angle=21.0 * _DEG, input_torque=1378.7, n_planets=3,
                  face_width_pinion=29.00 * _MM)
SEED_CASES = ("1", "2-A", "2-B")


def _triangle_angles(a_os: float, a_sr: float, a_or: float):
    """Included angles (alpha at the sun axis, beta at SP, gamma at RP) from the 3 distances."""
    alpha = math.acos((a_os ** 2 + a_or ** 2 - a_sr ** 2) / (2 * a_os * a_or))
    beta = math.acos((a_os ** 2 + a_sr ** 2 - a_or ** 2) / (2 * a_os * a_sr))
    return alpha, beta, math.pi - alpha - beta


def seed_case(name: str) -> SeedCase:
    """Geometry and input torque of a seed 001 case, derived from its gear tables.

    Parameters
    ----------
    name : {"1", "2-A", "2-B"}
        Case 1: single pinion (Table 1: sun 35, pinion 26, ring 86 teeth, m_n 1.59 mm,
        alpha_n 20 deg, helix 21 deg, centre distance 51.945 mm, 3 pinions, 1378.7 N·m into
        the sun, carrier reaction). Case 2-B: double pinion (Table 2: sun 35, SP 26, RP 24,
        ring 92; centre distances 51.945, 42.750, 58.600 mm). Case 2-A: Case 2 with the meshes
        180 deg apart (beta = pi, gamma = 0).

    Returns
    -------
    SeedCase

    Notes
    -----
    Operating radii and angles come from :func:`operating_mesh`; the included angles of
    Case 2-B from the triangle of centre distances (45.002, 75.768, 59.230 deg, as printed).
    Face width: the pinions' 29.00 mm, the narrower member of every mesh.

    Spec disagreement: the spec page takes phi_2 = phi_1 = 21.3 deg for Case 2; the geometry
    gives 21.88 deg at the SP-RP mesh, which reproduces the seed's Table 5 RP-SP moment (166;
    21.3 deg gives 164.8) and Case 2-A's RP-SP value (91; 21.3 deg gives 88.6).

    Seed inconsistency: for Case 2-A the seed's SP rows are Case 1's values copied (it says
    so: R_SP-RP = 22.510 mm and phi = 23.59 deg of the Case 1 ring mesh); this geometry uses
    Case 2's own SP-RP radius and angle, so its SP rows differ from the printed ones.
    """
    name = as_choice(name, "name", SEED_CASES)
    g = _SEED_GEAR
    common = dict(normal_module=g["normal_module"],
                  normal_pressure_angle=g["normal_pressure_angle"], helix_angle=g["helix_angle"])
    if name == "1":
        sun = operating_mesh(35, 26, center_distance=51.945 * _MM, **common)
        ring = operating_mesh(26, 86, center_distance=51.945 * _MM, internal=True, **common)
        geom = SinglePinion(r_sun=sun.r_w_1, r_ps=sun.r_w_2, r_pr=ring.r_w_1,
                            phi_1=sun.pressure_angle, phi_2=ring.pressure_angle,
                            helix_1=sun.helix_angle, helix_2=ring.helix_angle,
                            n_planets=g["n_planets"], face_width=g["face_width_pinion"],
                            name="seed 001 Case 1")
        return SeedCase("1", geom, g["input_torque"], "seed 001 Table 1")
    sun = operating_mesh(35, 26, center_distance=51.945 * _MM, **common)
    mid = operating_mesh(26, 24, center_distance=42.750 * _MM, **common)
    ring = operating_mesh(24, 92, center_distance=58.600 * _MM, internal=True, **common)
    if name == "2-B":
        alpha, beta, gamma = _triangle_angles(51.945, 42.750, 58.600)
        label, source = "seed 001 Case 2-B", "seed 001 Table 2 and Table 5 text"
    else:
        alpha, beta, gamma = 0.0, math.pi, 0.0
        label = "seed 001 Case 2-A"
        source = "seed 001 Table 5 text (Case 2 with meshes 180 deg apart)"
    geom = DoublePinion(r_sun=sun.r_w_1, r_sp_sun=sun.r_w_2, r_sp_rp=mid.r_w_1,
                        r_rp_sp=mid.r_w_2, r_rp_ring=ring.r_w_1, included_angle_sp=beta,
                        included_angle_rp=gamma, included_angle_sun=alpha,
                        phi_1=sun.pressure_angle, phi_2=mid.pressure_angle,
                        phi_3=ring.pressure_angle, helix_1=sun.helix_angle,
                        helix_2=mid.helix_angle, helix_3=ring.helix_angle,
                        n_planets=g["n_planets"], face_width=g["face_width_pinion"], name=label)
    return SeedCase(name, geom, g["input_torque"], source)
