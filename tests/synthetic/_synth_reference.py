"""Independent slow references for the synthetic tests (not a test module)."""

import math

import numpy as np

from meshphase.synthetic.kinematics import SpeedProfile, gauge_rates

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




# ----------------------------------------------------------------------------- speed ODE reference

def _member_rate_ref(sp, member):
    """Rate of the angle a shaft-locked ripple follows, from the Speeds fields directly."""
    return {"carrier": sp.carrier, "sun": sp.sun, "ring": sp.ring,
            "planet": sp.planet - sp.carrier}[member]


def ode_tau_ref(profile, sp, t_end, *, rtol=1e-13, atol=1e-14):
    """Angle time tau(t) on [0, t_end] from scipy's DOP853 on the ODE d tau/dt = s(t, tau),
    written out here from the documented definition (math module, no synthetic code).

    The integrated state is the deviation y = tau - G(t) from the closed-form time part
    G(t) = t + r t^2/2 + sum a/(2 pi f) (cos phi - cos(2 pi f t + phi)), so the tolerance
    rtol * |y| acts on a quantity of ~0.5 s instead of tau ~ 600 s: at rtol 1e-12 on tau
    itself DOP853's global error over 10 min reaches ~5e-9 s (measured), more than the 1e-9 s
    claim under test. Returns a vectorised callable tau(t).
    """
    from scipy.integrate import solve_ivp

    r = float(profile.ramp_rate)
    rip = [(float(a), float(f), float(p)) for a, f, p in profile.ripple]
    comps = [(c.amplitude, c.order * _member_rate_ref(sp, c.member), c.phase) for c in profile.shaft]

    def big_g(t):
        return t + 0.5 * r * t * t + sum(a / (2 * math.pi * f) * (math.cos(p) - math.cos(2 * math.pi * f * t + p))
                                         for a, f, p in rip)

    def rhs(t, y):
        tau = big_g(t) + y[0]
        return [sum(b * math.sin(k * tau + p) for b, k, p in comps)]

    sol = solve_ivp(rhs, (0.0, float(t_end)), [0.0], method="DOP853", rtol=rtol, atol=atol,
                    dense_output=True)
    assert sol.success, sol.message

    def tau(t):
        t = np.asarray(t, dtype=float)
        g = np.vectorize(big_g)(t) if t.ndim else big_g(float(t))
        return g + sol.sol(t)[0]
    return tau


def residual_tau_ref(t, gear, n, theta, gs, sp, err, tau_fn):
    """As residual_ref with tau(t) from ``tau_fn`` (e.g. :func:`ode_tau_ref`)."""
    tau = float(tau_fn(t))
    w, _ = gauge_rates(gs, sp, gear)
    x = theta + w * tau - line_angle_ref(tau, gear, n, gs, sp, err)
    return math.remainder(x, TWO_PI)
