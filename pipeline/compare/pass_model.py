"""The models' phasing at each measured pass, and its derivative in the shaft hole offsets.

What a gauge measures
---------------------
A gauged sun tooth meets planet n when its direction about the actual sun centre equals the
line of centres psi_es,n (meshphase.synthetic.kinematics gives the same condition), so between the
planet-1 pass (angle time tau_1) and the planet-n pass (tau_n) the tooth turns

    lag_n = psi_es,n(tau_n) - psi_es,1(tau_1)        (mod 2 pi, in the gear's sense)

and the measured phasing is gamma_n = frac(o Z lag_n / 2 pi) with o = +-1 the gauge's
sense of rotation (:func:`meshphase.kinematics.pass_table.pass_order`). The model therefore has to be
evaluated at the two engagement instants, not at one common time as in seed 000's
gamma(t): :func:`predict_pass_phasing` does that, on the pulse-train encoder angle of each
pass (so speed drift does not accumulate into the offset angles).

One consequence is physical and worth knowing: a gear's own shaft hole offset turns with
the gauged tooth, so a gauge on that gear meets every planet with the offset in the same
place, and its phasing is blind to it (exactly, in the absence of planet errors). The sun
gauge cannot see e_sun, the ring gauge cannot see e_ring; planet offsets are seen by both.
:func:`meshphase.compare.identify.identify_errors` reports such parameters as not identifiable from the data at hand
instead of returning a number.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from ..errors import ProcessingWarning
from ..kinematics.pass_table import PassTable, pass_order
from ..models.gearset import Gearset, Speeds
from ..models.mesh_phasing import ShaftHoleErrors, mesh_angle_deviations
from ..models.phasing_jacobian import MeshGradientPlan, n_offset_parameters
from ..validate import as_positive

__all__ = ["wrap", "relative_speeds", "table_speeds", "predict_pass_phasing", "pass_phasing_jacobian",
           "PassSetup", "pass_setup", "gamma_of", "gradient_plan", "gamma_and_jacobian"]

TWO_PI = 2.0 * math.pi


def wrap(x):
    """Wrap mesh-cycle differences into [-0.5, 0.5) [-]."""
    x = np.asarray(x, dtype=float)
    return x - np.floor(x + 0.5)


def relative_speeds(gearset: Gearset, gauge: str, w_gauge: float) -> Speeds:
    """Speeds relative to the carrier implied by one gauge's measured relative speed.

    The model needs only speeds relative to the carrier, and those are tied by the tooth
    counts whatever the input/output arrangement (Willis): w_pc = -(Z_s / Z_p) w_sc,
    w_rc = -(Z_s / Z_r) w_sc. Returned with carrier = 0.

    Parameters
    ----------
    gearset : Gearset
        Needs z_planet > 0 for the planet offsets to turn (0: planet offsets frozen, warned).
    gauge : {"sun", "ring"}
    w_gauge : float
        Magnitude of the gauged member's speed relative to the carrier [rad/s].
    """
    w = as_positive(w_gauge, "w_gauge")
    o = pass_order(gearset.direction, gauge)
    w_sc = o * w if gauge == "sun" else -o * w * gearset.z_ring / gearset.z_sun
    if gearset.z_planet > 0:
        w_pc = -w_sc * gearset.z_sun / gearset.z_planet
    else:
        warnings.warn("gearset.z_planet is 0: planet offsets are modelled as not turning",
                      ProcessingWarning, stacklevel=2)
        w_pc = 0.0
    w_rc = -w_sc * gearset.z_sun / gearset.z_ring
    return Speeds(sun=w_sc, carrier=0.0, planet=w_pc, ring=w_rc)


def _angle_zero_time(table: PassTable) -> float:
    """Time [s] at which the table's encoder angle is 0: its first reference pass.

    ``table.origin`` is documented as that instant, but a ring table driven by the sun's
    encoder (:class:`meshphase.kinematics.phasing.ScaledEncoder`) reports the start of the overlap of the
    two encoders there, which is later than its first reference pass whenever the sun's
    first planet-1 pass comes after the ring's; the angles still count from the ring's first
    reference pass. Both encoders keep their reference times in ``full_t``, so take the
    instant from there when the table carries its encoder.
    """
    full_t = getattr(table.encoder, "full_t", None)
    if full_t is not None and np.size(full_t) and math.isfinite(float(full_t[0])):
        return float(full_t[0])
    return float(table.origin)


def _angle_to_origin(table: PassTable, w: float, t0: float) -> float:
    """Angle [rad] the gauged member turned from the time origin to ``t0``, where the encoder
    angle is 0. The time origin is ``table.time_origin`` (the recording's first sample when
    set by the pipeline, else t = 0), so a recording starting at t0 = 1e6 s needs no
    extrapolation over 1e6 s and the identified kappa are the offsets' phases at its start.

    The offsets' phases kappa are fixed at the time origin and turn with the members' actual rotation,
    so the model's time variable must be (angle since t = 0) / w. The encoder counts angle
    from its first reference pass on; the part before it (less than one relative revolution
    when the record starts with the planet-1 pass) has to be extrapolated. When the table
    carries its encoder, the encoder's own smooth angle is extrapolated (for a ring table
    driven by the sun's encoder, the sun's angle times the ratio). Otherwise the passes of
    the first two relative revolutions give it: a least-squares polynomial of the angle
    against time constrained through the reference pass (t0, 0) (quadratic with four or more
    passes, so a ramp is followed; linear otherwise), evaluated at t = 0. Falls back to
    ``w * t0`` without usable passes.

    Using the record's mean speed for the whole of it (w_mean * t0) shifts every offset
    phase by (w_mean - w_0) t0: under a speed ramp of 5e-3 /s over 30 s that moved the
    model phasing by ~5e-3 mesh cycles (Table 1 gearset at 5 % speed, e = 0.2 mm).
    """
    origin = float(getattr(table, "time_origin", 0.0) or 0.0)
    if t0 == origin:
        return 0.0
    enc = table.encoder
    ends = np.array([origin, t0])
    if callable(getattr(enc, "angle", None)):
        a = np.asarray(enc.angle(ends), dtype=float)
        if np.all(np.isfinite(a)):
            return float(a[1] - a[0])
    src = getattr(enc, "source", None)
    if callable(getattr(src, "angle", None)) and math.isfinite(getattr(enc, "ratio", float("nan"))):
        a = np.asarray(src.angle(ends), dtype=float)
        if np.all(np.isfinite(a)):
            return float(enc.ratio * (a[1] - a[0]))
    ok = np.isfinite(table.time) & np.isfinite(table.angle)
    span = t0 - origin
    if np.count_nonzero(ok) == 0:
        return w * span
    rev = table.revolution[ok]
    near = rev <= rev.min() + 1
    dt = table.time[ok][near] - t0
    a = table.angle[ok][near]
    good = dt != 0
    dt, a = dt[good], a[good]
    if dt.size == 0:
        return w * span
    # the angle is 0 at t0 by definition: fit a(t) = c1 (t - t0) [+ c2 (t - t0)^2] through it
    cols = [dt, dt * dt] if dt.size >= 4 else [dt]
    coef = np.linalg.lstsq(np.stack(cols, axis=1), a, rcond=None)[0]
    return float(sum(c * (span ** (i + 1)) * (-1) ** i for i, c in enumerate(coef)))


def _angle_times(table: PassTable, w: float) -> tuple[np.ndarray, np.ndarray]:
    """Angle time of each pass and of its planet-1 reference pass [s] from the encoder.

    Angle time here is (angle of the gauged member since t = 0) / w, w the speed the model
    turns the offsets at, so that every offset sits at its actual phase at each pass whatever
    the speed did in between (see :func:`_angle_to_origin`).
    """
    if np.all(np.isfinite(table.angle)) and math.isfinite(table.origin):
        a0 = _angle_to_origin(table, w, _angle_zero_time(table))
        tau_n = (a0 + table.angle) / w
        tau_1 = (a0 + TWO_PI * table.revolution) / w
    else:
        tau_n = table.time
        tau_1 = np.where(np.isfinite(table.ref_time), table.ref_time, np.nan)
    return tau_n, tau_1


def table_speeds(table: PassTable, gearset: Gearset) -> Speeds:
    """Relative speeds from a table's encoder (mean slope), else from its mesh periods."""
    z = gearset.z_sun if table.gauge == "sun" else gearset.z_ring
    w = table.mean_speed()
    if not math.isfinite(w):
        # no encoder angles: the local speed the mesh periods carry
        per = np.asarray(table.mesh_period, dtype=float)
        per = per[np.isfinite(per) & (per > 0)]
        w = TWO_PI / (z * float(np.median(per))) if per.size else float("nan")
    if not math.isfinite(w) or w <= 0:
        raise ValueError(f"{table.gauge} table: cannot measure the gauge speed from "
                         f"{len(table)} pass(es)")
    return relative_speeds(gearset, table.gauge, w)


def predict_pass_phasing(table: PassTable, gearset: Gearset, errors: ShaftHoleErrors | None,
                         *, speeds: Speeds | None = None, pass_offset: float = 0.0) -> np.ndarray:
    """Model phasing at each measured pass of ``table`` [-], in [0, 1).

    Parameters
    ----------
    table : PassTable
        Measured passes (sun or ring gauge) with their encoder angles.
    gearset : Gearset
    errors : ShaftHoleErrors or None
        One realisation; None gives the ideal phasing.
    speeds : Speeds, optional
        Relative speeds; default from the table's own mean speed (:func:`relative_speeds`).
    pass_offset : float
        Where the timed pulse feature sits after the engagement instant [mesh cycles]: the
        model is evaluated that much earlier in angle (0: the pass time is the engagement).

    Returns
    -------
    gamma : ndarray, shape (n_passes,)
        frac(o Z (psi_n(tau_n) - psi_1(tau_1)) / 2 pi); NaN where the reference pass is
        unknown.

    Raises
    ------
    TypeError
        ``table``, ``gearset``, ``errors`` or ``speeds`` of the wrong type.
    ValueError
        A gauge other than sun/ring, errors with sample dimensions, planet numbers the
        gearset does not have, no measurable gauge speed.

    Notes
    -----
    The offsets turn with the members' actual rotation from their phases kappa at t = 0, so
    the model runs on angle time tau = (angle of the gauged member since t = 0) / w: the
    encoder angle of the pass plus the angle turned before the encoder's origin
    (:func:`_angle_to_origin`). Without encoder angles the wall-clock times of the pass and
    of its reference pass are used (exact at constant speed only). Accuracy against exact
    engagements (tests/processing/test_compare.py): <= 1e-5 cycles with the true angles,
    the residual being second order in e / R_c.
    """
    setup = pass_setup(table, gearset, errors, speeds, pass_offset)
    if setup is None:
        return np.empty(0)
    out = np.full(len(table), np.nan)
    if not np.any(setup.ok):
        return out
    ok, sp, idx = setup.ok, setup.speeds, setup.index
    if errors is None or errors.is_zero:
        d_n = np.zeros(np.count_nonzero(ok))
        d_1 = d_n
    else:
        # deviations of each pass's own planet at its own time, and of planet 1 at tau_1
        which = 0 if setup.mesh == "sun" else 1
        dn = mesh_angle_deviations(setup.tau_n[ok], gearset, sp, errors)[which]
        d1 = mesh_angle_deviations(setup.tau_1[ok], gearset, sp, errors)[which]
        rows = np.arange(dn.shape[-2])
        d_n = dn[..., rows, idx[ok]]
        d_1 = d1[..., rows, 0]
    out[ok] = gamma_of(setup, gearset, d_n - d_1)
    return out


def pass_phasing_jacobian(table: PassTable, gearset: Gearset, errors: ShaftHoleErrors | None,
                          *, speeds: Speeds | None = None,
                          pass_offset: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Model phasing at each measured pass and its derivative in the Cartesian offsets.

    Parameters
    ----------
    table, gearset, errors, speeds, pass_offset
        As :func:`predict_pass_phasing`.

    Returns
    -------
    gamma : ndarray, shape (n_passes,)
        Equal (bit for bit) to :func:`predict_pass_phasing` [-].
    jac : ndarray, shape (n_passes, 4 + 2 N)
        d gamma / d p [mesh cycles / m], p the Cartesian offsets in :func:`meshphase.compare.identify.PARAMETER_NAMES`
        order; NaN rows where the reference pass is unknown.

    Raises
    ------
    TypeError, ValueError
        As :func:`predict_pass_phasing`.

    Notes
    -----
    gamma = frac(o Z (psi_n - psi_1 + delta_n(tau_n) - delta_1(tau_1)) / 2 pi), so away from
    the wrap d gamma / d p = o Z (d delta_n / dp - d delta_1 / dp) / 2 pi with the closed-form
    gradients of :func:`meshphase.models.phasing_jacobian.mesh_angle_gradient`.
    """
    setup = pass_setup(table, gearset, errors, speeds, pass_offset)
    n_par = n_offset_parameters(gearset.n_planets)
    if setup is None:
        return np.empty(0), np.empty((0, n_par))
    return gamma_and_jacobian(setup, gearset, errors)


@dataclass(frozen=True)
class PassSetup:
    """What the model needs of a pass table besides the errors: the gauge's sense ``o`` and
    tooth count ``z``, the mesh, the relative speeds, the angle times [s] of each pass and of
    its reference pass, the 0-based planet index and which rows have both times."""

    o: float
    z: int
    mesh: str
    speeds: Speeds
    tau_n: np.ndarray
    tau_1: np.ndarray
    index: np.ndarray
    ok: np.ndarray


def pass_setup(table, gearset, errors, speeds, pass_offset) -> PassSetup | None:
    """The checked, error-independent part of :func:`predict_pass_phasing` (None: no passes)."""
    if not isinstance(table, PassTable):
        raise TypeError(f"table must be a PassTable, got {type(table).__name__}")
    if not isinstance(gearset, Gearset):
        raise TypeError(f"gearset must be a Gearset, got {type(gearset).__name__}")
    if errors is not None and not isinstance(errors, ShaftHoleErrors):
        raise TypeError(f"errors must be a ShaftHoleErrors or None, got {type(errors).__name__}")
    if speeds is not None and not isinstance(speeds, Speeds):
        raise TypeError(f"speeds must be a Speeds or None, got {type(speeds).__name__}")
    if len(table) == 0:
        return None
    gauge = table.gauge
    o = pass_order(gearset.direction, gauge)  # ValueError for a gauge other than sun/ring
    z = gearset.z_sun if gauge == "sun" else gearset.z_ring
    if errors is not None and errors.sample_shape(gearset.n_planets) != ():
        raise ValueError("errors must be one realisation (no sample dimensions), got sample "
                         f"shape {errors.sample_shape(gearset.n_planets)}")
    planet = np.asarray(table.planet)
    if planet.min() < 1 or planet.max() > gearset.n_planets:
        raise ValueError(f"table.planet must lie in [1, {gearset.n_planets}] (the gearset's "
                         f"planets), got [{planet.min()}, {planet.max()}]")
    sp = table_speeds(table, gearset) if speeds is None else speeds
    w_gauge = abs(sp.w_sc if gauge == "sun" else sp.w_rc)
    if not w_gauge > 0:
        raise ValueError(f"speeds: the {gauge} must turn relative to the carrier, got "
                         f"{'w_sc' if gauge == 'sun' else 'w_rc'} = 0")
    tau_n, tau_1 = _angle_times(table, w_gauge)
    if pass_offset:
        back = TWO_PI * float(pass_offset) / (z * w_gauge)     # [s] of angle time
        tau_n, tau_1 = tau_n - back, tau_1 - back
    idx = table.planet - 1
    ok = np.isfinite(tau_1) & np.isfinite(tau_n)
    return PassSetup(o, z, gauge, sp, tau_n, tau_1, idx, ok)


def gamma_of(setup: PassSetup, gearset: Gearset, d_lag: np.ndarray) -> np.ndarray:
    """frac(o Z lag / 2 pi) of the rows ``setup.ok``, lag = psi_n - psi_1 + ``d_lag`` [rad]."""
    psi = gearset.angles
    lag = (psi[setup.index[setup.ok]] - psi[0]) + d_lag
    g = (setup.o * setup.z * lag / TWO_PI) % 1.0
    return np.where(g >= 1.0, 0.0, g)  # x % 1.0 rounds to 1.0 for x = -tiny


def gradient_plan(setup: PassSetup, gearset: Gearset) -> MeshGradientPlan:
    """The rotations of the rows ``setup.ok``, prepared once
    (:class:`~meshphase.models.phasing_jacobian.MeshGradientPlan`): the passes' own planets
    at their times, followed by planet 1 at the reference times."""
    ok = setup.ok
    return MeshGradientPlan(np.concatenate([setup.tau_n[ok], setup.tau_1[ok]]),
                            np.concatenate([setup.index[ok] + 1,
                                            np.ones(np.count_nonzero(ok), dtype=np.intp)]),
                            gearset, setup.speeds, mesh=setup.mesh)


def gamma_and_jacobian(setup: PassSetup, gearset: Gearset, errors,
                        plan: MeshGradientPlan | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`pass_phasing_jacobian` on a prepared table (``plan``: its
    :func:`gradient_plan`, made here when not given)."""
    n = setup.ok.size
    gamma = np.full(n, np.nan)
    jac = np.full((n, n_offset_parameters(gearset.n_planets)), np.nan)
    ok = setup.ok
    if not np.any(ok):
        return gamma, jac
    d, j = (gradient_plan(setup, gearset) if plan is None else plan).evaluate(errors)
    m = np.count_nonzero(ok)
    if errors is None or errors.is_zero:     # as predict_pass_phasing: exactly the ideal
        d = np.zeros(2 * m)
    gamma[ok] = gamma_of(setup, gearset, d[:m] - d[m:])
    jac[ok] = (setup.o * setup.z / TWO_PI) * (j[:m] - j[m:])
    return gamma, jac
