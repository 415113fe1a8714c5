"""Independent slow references for the synthetic tests (not a test module)."""

import math

import numpy as np

from synthetic.kinematics import SpeedProfile, gauge_rates

TWO_PI = 2 * math.pi


def tau_ref(profile: SpeedProfile, t: float) -> float:
    """int_0^t s dt' by 24-point Gauss-Legendre on 0.25 s pieces (independent of tau())."""
    if t == 0:
        return 0.0
    x, w = np.polynomial.legendre.leggauss(24)
    n = max(1, math.ceil(abs(t) / 0.25))
    edges = np.linspace(0.0, t, n + 1)
    a, b = edges[:-1, None], edges[1:, None]
    pts = 0.5 * (b - a) * x[None, :] + 0.5 * (b + a)
    return float(np.sum(0.5 * (b - a) * w[None, :] * profile.factor(pts)))


def line_angle_ref(tau, gear, n, gs, sp, err):
    """Direction of (actual planet n centre - actual gear centre) from the rotation angles,
    written out from mesh_phasing's documented conventions (scalar, math module)."""
    psi = gs.planet_angles[n]
    u = (math.cos(psi), math.sin(psi))
    tn = (-math.sin(psi), math.cos(psi))
    if err is None:
        return psi
    ep = float(np.broadcast_to(err.e_planet, (gs.n_planets,))[n])
    kp = float(np.broadcast_to(err.kappa_planet, (gs.n_planets,))[n])
    th = sp.w_pc * tau + kp
    px = gs.carrier_radius * u[0] - ep * (math.cos(th) * u[0] + math.sin(th) * tn[0])
    py = gs.carrier_radius * u[1] - ep * (math.cos(th) * u[1] + math.sin(th) * tn[1])
    if gear == "sun":
        e, a = float(err.e_sun), sp.w_sc * tau + float(err.kappa_sun)
    else:
        e, a = float(err.e_ring), sp.w_rc * tau + float(err.kappa_ring)
    return math.atan2(py - e * math.sin(a), px - e * math.cos(a))


def residual_ref(t, gear, n, theta, gs, sp, err, prof):
    """Wrapped angle between the gauged tooth and the line of centres at time t [rad]."""
    tau = tau_ref(prof, t)
    w, _ = gauge_rates(gs, sp, gear)
    x = theta + w * tau - line_angle_ref(tau, gear, n, gs, sp, err)
    return math.remainder(x, TWO_PI)


