"""Tooth-root strain gauges: pulse shape, face-width load weighting and pulse rendering.

A strain gauge in the root fillet of a gear tooth sees one pulse per engagement of that
tooth with a planet. This module holds the shape of that pulse, the weighting of gauges
placed across the face width by the load distribution (spec section 7), and the vectorised
renderer that scatters one pulse per engagement event into a sample buffer.

Pulse shape
-----------
A tooth-root pulse is a function of the gauged gear's rotation angle relative to the carrier,
not of time: the tooth bends while a planet rolls across it, over a fixed angle. The pulse
variable is the angle turned since the engagement, in mesh periods::

    u = Z |w_rel| (tau(t) - tau_e) / (2 pi)

(``Z`` the tooth count of the gauged gear, ``w_rel`` its nominal speed relative to the
carrier [rad/s], ``tau`` the angle time of :mod:`meshphase.synthetic.kinematics`, ``tau_e`` that of the
engagement). So the pulse stretches and shrinks with the local speed, also within one pulse:
a pulse lasts ``2 * half`` mesh periods of angle, ``2 * half * T_m`` [s] at a steady local
mesh period ``T_m = 2 pi / (Z |w_rel| s)``. At constant speed this is ``u = (t - t_e) / T_m``.
The engagement instant is the instant the gauged tooth's centre line crosses the line of
centres of the actual gear centre and the actual planet centre, i.e. the middle of the
tooth's contact with that planet (see :mod:`meshphase.synthetic.kinematics`).

The tooth carries load while ``|u| < eps / 2`` (``eps`` the contact ratio): a single-contact
plateau of half-width ``a = eps/2 - r`` and, at each end, a double-contact zone of width
``r = eps - 1`` (clipped to [0.15, eps/2]; the lower clip stands for the elastic extension
of the contact by tooth deflection, which keeps the pulse smooth at eps -> 1). The load
fraction follows a raised cosine across each double-contact zone::

    L(u) = 1                                         |u| <= a
         = (1 + cos(pi (|u| - a) / r)) / 2           a < |u| < eps / 2
         = 0                                         otherwise

The root bending strain is load times moment arm; the contact point moves along the flank
during the engagement (root to tip on a driving gear, tip to root on a driven one), which we
model as a linear arm factor ``1 + skew * u / (eps / 2)``. The fillet of the gauged tooth is
compressed while the neighbouring teeth (one mesh period earlier and later) carry load, so
the strain reads::

    g(u) = L(u) (1 + skew * 2 u / eps)
    p(u) = g(u) - side_lobe * (g(u - 1) + g(u + 1)),      normalised to max p = 1

a tensile peak while the tooth carries load, with a compressive lobe before and after it.
The pulse support is ``|u| < 1 + eps / 2`` [mesh periods of angle].

Rendering
---------
:func:`render_pulses` scatters pulses whose variable is linear in time (constant speed).
:func:`angle_pulse_map` gives, per engagement, the first sample of its support and a
polynomial in the sample offset that reproduces the table coordinate ``u(t_i)`` to a
verified tolerance (1e-9 mesh periods by default: the degree is raised until the fit matches
the exact ``tau(t)`` at interleaved check points); :func:`render_angle_pulses` scatters
them. Both evaluate only the samples near each event, and a sample gets the same value bit
for bit however the recording is cut into blocks.

Face-width weighting (spec section 7)
-------------------------------------
The line load across the face width ``b`` with centroid offset ``Z`` is
``w(z) = (F / b)(1 + 12 Z z / b^2)`` while that stays non-negative (``|Z| <= b / 6``).
Beyond, the contact runs off the face (spec section 5, partial contact): the load is
triangular, zero at ``z0`` and largest at the loaded edge, with contact length
``L_c = 3 (b/2 - |Z|)`` so that its centroid is ``Z`` and its integral ``F``. A gauge at
``z`` reads ``w(z) / (F / b)`` times its nominal amplitude. Both shapes are those of the
section 5 model in :mod:`meshphase.models.tilt` (``load_intensity``), which is what
:func:`face_load_factor` evaluates.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from meshphase.models.tilt import load_intensity, tilt_from_centroid
from meshphase.validate import as_finite_array, as_float, as_nonnegative, as_positive

__all__ = ["pulse_shape", "pulse_support", "pulse_peak_offset", "face_load_factor",
           "PulseTable", "render_pulses", "render_box", "AnglePulses", "angle_pulse_map",
           "render_angle_pulses"]

_MIN_RAMP = 0.15
_TABLE_POINTS = 1 << 15


def _check_shape(contact_ratio, side_lobe, skew):
    eps = as_float(contact_ratio, "contact_ratio")
    if not 1.0 <= eps <= 3.0:
        raise ValueError(f"contact_ratio must be in [1, 3], got {eps!r}")
    beta = as_nonnegative(side_lobe, "side_lobe")
    if beta >= 1.0:
        raise ValueError(f"side_lobe must be in [0, 1), got {beta!r}")
    sk = as_float(skew, "skew")
    if abs(sk) >= 1.0:
        raise ValueError(f"skew must be in (-1, 1), got {sk!r}")
    return eps, beta, sk


def _load(u, eps, skew):
    half = 0.5 * eps
    r = min(max(eps - 1.0, _MIN_RAMP), half)
    a = half - r
    au = np.abs(u)
    lf = np.where(au <= a, 1.0, 0.5 * (1.0 + np.cos(np.pi * np.clip((au - a) / r, 0.0, 1.0))))
    lf = np.where(au < half, lf, 0.0)
    return lf * (1.0 + skew * u / half)


def _raw_shape(u, eps, beta, skew):
    return _load(u, eps, skew) - beta * (_load(u - 1.0, eps, skew) + _load(u + 1.0, eps, skew))


def _norm(eps, beta, skew) -> float:
    # the maximum lies on the tensile lobe |u| < eps/2: dense grid + parabolic refinement
    u = np.linspace(-0.5 * eps, 0.5 * eps, 20001)
    p = _raw_shape(u, eps, beta, skew)
    i = int(np.argmax(p))
    if 0 < i < u.size - 1:
        y0, y1, y2 = p[i - 1], p[i], p[i + 1]
        den = y0 - 2.0 * y1 + y2
        if den < 0.0:
            return float(y1 - 0.125 * (y2 - y0) ** 2 / den)
    return float(p[i])


def pulse_support(contact_ratio: float) -> float:
    """Half-width of the pulse support [mesh periods]: ``1 + contact_ratio / 2``.

    Parameters
    ----------
    contact_ratio : float
        Transverse contact ratio eps [-], in [1, 3].
    """
    eps, _, _ = _check_shape(contact_ratio, 0.0, 0.0)
    return 1.0 + 0.5 * eps


def pulse_shape(u, contact_ratio: float = 1.6, side_lobe: float = 0.3, skew: float = 0.0) -> np.ndarray:
    """Normalised tooth-root strain pulse p(u) [-] (peak 1), see the module docstring.

    Parameters
    ----------
    u : array_like
        Angle turned since the engagement, in mesh periods [-] (at constant speed: time from
        the engagement instant in mesh periods).
    contact_ratio : float
        Contact ratio eps [-]: the tooth carries load for ``eps`` mesh periods.
    side_lobe : float
        Depth of the compressive lobes relative to the tensile peak before normalisation
        [-], in [0, 1).
    skew : float
        Moment-arm asymmetry [-], in (-1, 1): > 0 peaks late (contact moving root -> tip,
        a driving gear), < 0 peaks early (a driven gear).

    Returns
    -------
    ndarray
        p(u), same shape as ``u``; 0 outside ``|u| < 1 + eps/2``.
    """
    eps, beta, sk = _check_shape(contact_ratio, side_lobe, skew)
    uu = np.asarray(u, dtype=np.float64)
    if uu.size and not np.all(np.isfinite(uu)):
        raise ValueError("u must be finite")
    return _raw_shape(uu, eps, beta, sk) / _norm(eps, beta, sk)


def pulse_peak_offset(contact_ratio: float = 1.6, side_lobe: float = 0.3, skew: float = 0.0) -> float:
    """Position of the pulse maximum after the engagement [mesh periods of angle].

    A detector that reports the pulse peak sees the truth engagement shifted by this constant
    angle: ``peak_offset * 2 pi / Z`` [rad] of the gauged gear relative to the carrier, i.e.
    ``tau_e + peak_offset * T`` in angle time (``T = 2 pi / (Z |w_rel|)``), about
    ``peak_offset`` local mesh periods in time.
    """
    return _peak_offset(*_check_shape(contact_ratio, side_lobe, skew))


@functools.lru_cache(maxsize=64)
def _peak_offset(eps: float, beta: float, sk: float) -> float:
    u = np.linspace(-0.5 * eps, 0.5 * eps, 200001)
    return float(u[int(np.argmax(_raw_shape(u, eps, beta, sk)))])


def face_load_factor(z, centroid, face_width: float) -> np.ndarray:
    """Local line load w(z) relative to the mean load F / b [-] (spec sections 5 and 7).

    Parameters
    ----------
    z : array_like
        Axial positions across the face, from the face centre [m]; |z| <= b / 2.
    centroid : array_like
        Load centroid offset Z [m], |Z| < b / 2; broadcasts against ``z``.
    face_width : float
        Face width b [m].

    Returns
    -------
    ndarray
        ``w(z) / (F / b)``: linear ``1 + 12 Z z / b^2`` for ``|Z| <= b / 6``, the partial-
        contact triangle of length ``3 (b/2 - |Z|)`` at the loaded end beyond (zero over the
        unloaded part of the face). Its mean over the face is 1 and its centroid is ``Z``.

    Notes
    -----
    Evaluated with the section 5 model of :mod:`meshphase.models.tilt`: the misalignment that
    puts the centroid at Z (``tilt_from_centroid``) and the load pattern it gives
    (``load_intensity``), with a unit force; the shape does not depend on the force or the
    mesh stiffness.
    """
    b = as_positive(face_width, "face_width")
    zz = as_finite_array(z, "z")
    zc = as_finite_array(centroid, "centroid")
    if zz.size and np.any(np.abs(zz) > 0.5 * b * (1 + 1e-12)):
        raise ValueError(f"z must lie within the face, |z| <= b/2 = {0.5 * b!r} m, got max |z| "
                         f"{float(np.max(np.abs(zz)))!r}")
    if zc.size and np.any(np.abs(zc) >= 0.5 * b):
        raise ValueError(f"centroid must satisfy |Z| < b/2 = {0.5 * b!r} m, got max |Z| "
                         f"{float(np.max(np.abs(zc)))!r}")
    zz, zc = np.broadcast_arrays(zz, zc)
    if zz.size == 0:
        return np.zeros(zz.shape)
    theta = tilt_from_centroid(zc, 1.0, b)
    return np.asarray(load_intensity(np.clip(zz, -0.5 * b, 0.5 * b), 1.0, theta, b) * b, dtype=np.float64)


@functools.lru_cache(maxsize=32)
def _table(eps: float, beta: float, sk: float, n: int):
    u = np.linspace(-(1.0 + 0.5 * eps), 1.0 + 0.5 * eps, n)
    p = pulse_shape(u, eps, beta, sk)
    p[0] = p[-1] = 0.0
    u.flags.writeable = False
    p.flags.writeable = False
    return u, p


class PulseTable:
    """Tabulated pulse shape for fast evaluation by linear interpolation.

    Parameters
    ----------
    contact_ratio, side_lobe, skew : float
        Shape parameters of :func:`pulse_shape`.
    n : int
        Table points over the support (default 32768: interpolation error < 1e-7 of peak).
    """

    def __init__(self, contact_ratio: float = 1.6, side_lobe: float = 0.3, skew: float = 0.0,
                 n: int = _TABLE_POINTS):
        eps, beta, sk = _check_shape(contact_ratio, side_lobe, skew)
        self.contact_ratio, self.side_lobe, self.skew = eps, beta, sk
        self.half = 1.0 + 0.5 * eps
        n = int(n)
        self.u, self.p = _table(eps, beta, sk, n)
        #: table points per mesh period [1/mesh period]
        self.scale = (n - 1) / (2.0 * self.half)
        # value and slope per table cell; one extra zero cell catches x beyond the support
        self._val = np.concatenate([self.p, [0.0]])
        self._slope = np.concatenate([np.diff(self.p), [0.0, 0.0]])
        self._last = n

    def __call__(self, u) -> np.ndarray:
        return np.interp(u, self.u, self.p, left=0.0, right=0.0)

    def lookup(self, x: np.ndarray) -> np.ndarray:
        """Shape at table coordinates ``x = (u + half) * scale`` (x >= 0), linear interpolation."""
        i = x.astype(np.intp)
        np.minimum(i, self._last, out=i)
        f = x - i
        f *= self._slope[i]
        f += self._val[i]
        return f


def render_pulses(out, i0: int, positions, periods, amplitudes, table: PulseTable, *,
                  max_elems: int = 1 << 15) -> None:
    """Add one pulse per event into ``out`` (in place), evaluating only nearby samples.

    Parameters
    ----------
    out : ndarray, shape (n,)
        Buffer holding absolute samples ``i0 <= i < i0 + n`` of the recording.
    i0 : int
        Absolute index of ``out[0]`` [-].
    positions : array_like, shape (m,)
        Engagement instants in absolute samples, ``(t_e - t_first) * fs`` [samples].
    periods : array_like, shape (m,)
        Local mesh periods in samples, ``T_m * fs`` [samples].
    amplitudes : array_like, shape (m,)
        Peak strains [m/m]; events whose support misses the buffer add nothing.
    table : PulseTable
        Pulse shape.
    max_elems : int
        Bound on the temporary (events x support) work arrays.

    Notes
    -----
    Sample ``i`` gets ``A p((i - P) / T)`` from every event; the work is proportional to the
    number of pulse samples, not events x samples, and overlapping pulses add
    (``np.add.at``). The table coordinate of sample ``first_e + k`` is ``k a_e + c_e`` with
    ``a_e``, ``c_e`` computed from the event alone, so a sample gets the same value bit for
    bit however the recording is cut into blocks.
    """
    n = out.shape[0]
    pos = np.asarray(positions, dtype=np.float64)
    if n == 0 or pos.size == 0:
        return
    tp = np.asarray(periods, dtype=np.float64)
    amp = np.asarray(amplitudes, dtype=np.float64)
    hw = table.half * tp                             # half support [samples]
    keep = (pos + hw >= i0) & (pos - hw < i0 + n)
    if not np.all(keep):
        pos, hw, tp, amp = pos[keep], hw[keep], tp[keep], amp[keep]
    if pos.size == 0:
        return
    m = int(math.ceil(2.0 * float(hw.max()))) + 2
    first = np.floor(pos - hw).astype(np.int64) + 1   # absolute index of the first sample
    slope = table.scale / tp                          # table points per sample
    c0 = (first - pos) * slope + table.half * table.scale
    k = np.arange(m, dtype=np.float64)
    kj = np.arange(m, dtype=np.int64)
    step = max(1, max_elems // m)
    # events in position order, samples in order within an event: every sample sums its
    # contributions in the same order whatever the block boundaries
    for a in range(0, pos.size, step):
        b = min(pos.size, a + step)
        x = k[None, :] * slope[a:b, None]
        x += c0[a:b, None]
        val = table.lookup(x)
        val *= amp[a:b, None]
        j = (first[a:b] - i0)[:, None] + kj[None, :]
        fa = first[a:b]
        if fa.min() >= i0 and fa.max() + m <= i0 + n:
            np.add.at(out, j.ravel(), val.ravel())
        else:
            ok = (j >= 0) & (j < n)
            np.add.at(out, j[ok], val[ok])


# ----------------------------------------------------------------------------- pulses in angle

#: Polynomial degrees tried by :func:`angle_pulse_map`, lowest first.
_DEGREES = tuple(range(1, 17))


@dataclass(frozen=True, eq=False)
class AnglePulses:
    """Where each pulse's samples lie and how to find their pulse variable.

    Sample ``first[e] + k`` (``0 <= k < count[e]``) of event ``e`` reads the pulse table at
    the table coordinate ``x = sum_j coef[e, j] y^(degree - j)`` (Horner order, highest power
    first) with ``y = 2 k / (width - 1) - 1``; ``x = (u + half) * scale`` with ``u`` the
    angle since the engagement in mesh periods (module docstring). The polynomial holds on
    the whole window ``0 <= k < width``; beyond ``count[e]`` the pulse is zero.

    Attributes
    ----------
    first : ndarray of int64, shape (m,)
        Absolute index of the first sample inside each event's support [-] (sorted as the
        events).
    count : ndarray of int64, shape (m,)
        Samples inside each event's support [-].
    width : int
        Length of the common window the polynomials are fitted on [samples] (the longest
        support plus one).
    coef : ndarray, shape (m, degree + 1)
        Polynomial coefficients of the table coordinate in ``y`` [table points].
    degree : int
        Polynomial degree [-].
    fit_error : float
        Largest deviation of the polynomial from the exact pulse variable at the check
        points [mesh periods].
    """

    first: np.ndarray
    count: np.ndarray
    width: int
    coef: np.ndarray
    degree: int
    fit_error: float

    def __len__(self) -> int:
        return int(self.first.size)


@functools.lru_cache(maxsize=32)
def _fit_matrices(d: int):
    nodes = np.cos(np.pi * (np.arange(d + 1) + 0.5) / (d + 1))     # Chebyshev, first kind
    check = np.cos(np.pi * np.arange(d + 2) / (d + 1))              # interleaved, with +-1
    vander = np.polynomial.chebyshev.chebvander(nodes, d)
    to_mono = np.zeros((d + 1, d + 1))
    for k in range(d + 1):
        e = np.zeros(d + 1)
        e[k] = 1.0
        p = np.polynomial.chebyshev.cheb2poly(e)
        to_mono[: p.size, k] = p
    # node values -> monomial coefficients, highest power first
    fit = (to_mono @ np.linalg.inv(vander))[::-1]
    for a in (nodes, check, fit):
        a.flags.writeable = False
    return nodes, check, fit


def _horner(coef, y):
    x = coef[:, 0:1] * y[None, :]
    x += coef[:, 1:2]
    for j in range(2, coef.shape[1]):
        x *= y[None, :]
        x += coef[:, j:j + 1]
    return x


def angle_pulse_map(tau_e, mesh_angle: float, tau_of, time_of, fs: float, table: PulseTable, *,
                    tol: float = 1e-9, max_degree: int = 16) -> AnglePulses:
    """Sample windows and pulse-variable polynomials of pulses that last a fixed angle.

    Parameters
    ----------
    tau_e : array_like, shape (m,)
        Angle times of the engagements [s], sorted.
    mesh_angle : float
        One mesh period of angle in angle time, ``2 pi / (Z |w_rel|)`` [s].
    tau_of : callable
        ``tau_of(t)``: angle time [s] at times t [s] from the first sample (vectorised).
    time_of : callable
        ``time_of(tau)``: its inverse [s].
    fs : float
        Sample rate [Hz]; sample i sits at t = i / fs.
    table : PulseTable
        Pulse shape (its ``half`` and ``scale``).
    tol : float
        Largest allowed deviation of the polynomial from the exact pulse variable
        [mesh periods] (plus the rounding floor of ``tau_of(t) - tau_e``, 64 ulp of tau).
    max_degree : int
        Highest polynomial degree tried; ValueError beyond.

    Returns
    -------
    AnglePulses
        Empty (width 0) when there is no event.

    Notes
    -----
    Per event, the support ``|u| < half`` is mapped to times with ``time_of`` (so its samples
    are exactly those inside the angle support); the table coordinate is interpolated at
    Chebyshev points of the sample window and checked against ``tau_of`` at the interleaved
    points and the window ends; the lowest degree that meets ``tol`` on every event is used.
    The speed changes slowly against one pulse (a ripple period spans many mesh periods), so
    degrees of 2-8 are typical, and 1 at constant speed.
    """
    if not isinstance(table, PulseTable):
        raise TypeError(f"table must be a PulseTable, got {type(table).__name__}")
    tau_e = as_finite_array(tau_e, "tau_e", ndim=1)
    T = as_positive(mesh_angle, "mesh_angle")
    fs = as_positive(fs, "fs")
    tol = as_positive(tol, "tol")
    max_degree = int(max_degree)
    if not callable(tau_of) or not callable(time_of):
        raise TypeError("tau_of and time_of must be callables (e.g. SpeedClock.tau, .time_of)")
    if tau_e.size == 0:
        return AnglePulses(np.empty(0, np.int64), np.empty(0, np.int64), 0, np.empty((0, 2)), 1, 0.0)
    half, scale = table.half, table.scale
    t_lo = np.asarray(time_of(tau_e - half * T), dtype=np.float64)
    t_hi = np.asarray(time_of(tau_e + half * T), dtype=np.float64)
    first = np.floor(t_lo * fs).astype(np.int64) + 1
    last = np.ceil(t_hi * fs).astype(np.int64) - 1
    count = np.maximum(last - first + 1, 0)
    width = max(2, int(np.max(count)) + 1)
    span = 0.5 * (width - 1)                         # k = (y + 1) * span
    floor = 64.0 * np.finfo(float).eps * (float(np.max(np.abs(tau_e))) + half * T) / T
    fb = first.astype(np.float64)

    def exact(y):
        t = (fb[:, None] + (y[None, :] + 1.0) * span) / fs
        tau = np.asarray(tau_of(t.ravel()), dtype=np.float64).reshape(t.shape)
        return ((tau - tau_e[:, None]) / T + half) * scale

    worst = math.inf
    for d in _DEGREES:
        if d > max_degree:
            break
        nodes, check, fit = _fit_matrices(d)
        coef = exact(nodes) @ fit.T
        err = float(np.max(np.abs(_horner(coef, check) - exact(check)))) / scale
        worst = err
        if err <= tol + floor:
            return AnglePulses(first, count, width, np.ascontiguousarray(coef), d, err)
    raise ValueError(f"the speed changes too fast within one pulse: no polynomial of degree <= "
                     f"{max_degree} follows the pulse variable to {tol!r} mesh periods (best "
                     f"{worst!r}); lower the ripple frequency or raise max_degree")


def render_angle_pulses(out, i0: int, pulses: AnglePulses, amplitudes, table: PulseTable, *,
                        max_elems: int = 1 << 15) -> None:
    """Add the pulses of :func:`angle_pulse_map` into ``out`` (in place).

    Parameters
    ----------
    out : ndarray, shape (n,)
        Buffer holding absolute samples ``i0 <= i < i0 + n``.
    i0 : int
        Absolute index of ``out[0]`` [-].
    pulses : AnglePulses
        Windows and polynomials (a subset of events may be given by slicing its arrays into
        a new AnglePulses).
    amplitudes : array_like, shape (m,)
        Peak strains [m/m].
    table : PulseTable
        The table the map was made for.
    max_elems : int
        Bound on the temporary (events x width) work arrays.

    Notes
    -----
    The value of sample ``first[e] + k`` depends on the event and k only (``y[k]`` is the same
    number in every call), and events add in their order, so the result is the same bit for
    bit however the recording is cut into blocks. Only ``max(count) + 1`` samples per event
    of the events in the buffer are evaluated.
    """
    n = out.shape[0]
    if not isinstance(pulses, AnglePulses):
        raise TypeError(f"pulses must be an AnglePulses, got {type(pulses).__name__}")
    first = pulses.first
    if n == 0 or first.size == 0:
        return
    amp = np.asarray(amplitudes, dtype=np.float64)
    if amp.shape != first.shape:
        raise ValueError(f"amplitudes must have one value per event ({first.size}), got shape "
                         f"{amp.shape}")
    count = pulses.count
    keep = (first < i0 + n) & (first + count > i0)
    coef = pulses.coef
    if not np.all(keep):
        first, count, coef, amp = first[keep], count[keep], coef[keep], amp[keep]
    if first.size == 0:
        return
    m = min(pulses.width, int(count.max()) + 1)
    y = np.arange(m, dtype=np.float64) * (2.0 / (pulses.width - 1)) - 1.0
    kj = np.arange(m, dtype=np.int64)
    step = max(1, max_elems // m)
    for a in range(0, first.size, step):
        b = min(first.size, a + step)
        x = _horner(coef[a:b], y)
        np.maximum(x, 0.0, out=x)
        val = table.lookup(x)
        val *= amp[a:b, None]
        fa = first[a:b]
        j = (fa - i0)[:, None] + kj[None, :]
        if fa.min() >= i0 and fa.max() + m <= i0 + n:
            np.add.at(out, j.ravel(), val.ravel())
        else:
            ok = (j >= 0) & (j < n)
            np.add.at(out, j[ok], val[ok])


def render_box(out, i0: int, starts, stops, level: float) -> None:
    """Add rectangular pulses of height ``level`` over [start, stop) into ``out`` (in place).

    Parameters
    ----------
    out : ndarray, shape (n,)
        Buffer holding absolute samples ``i0 <= i < i0 + n``.
    i0 : int
        Absolute index of ``out[0]``.
    starts, stops : array_like, shape (m,)
        Rising and falling edges in absolute samples [samples] (stop > start).
    level : float
        Pulse height (e.g. [V]).

    Notes
    -----
    Each sample reads the fraction of its cell ``[i - 1/2, i + 1/2)`` that the pulse covers,
    so the edges carry their sub-sample position (an ideal integrating front end).
    """
    n = out.shape[0]
    a = np.asarray(starts, dtype=np.float64)
    b = np.asarray(stops, dtype=np.float64)
    if n == 0 or a.size == 0:
        return
    keep = (b > i0 - 0.5) & (a < i0 + n - 0.5)
    a, b = a[keep], b[keep]
    if a.size == 0:
        return
    # cumulative high time H(x) = sum clip(x - a, 0, b - a); sample i gets H(i+1/2) - H(i-1/2)
    ia = np.floor(a + 0.5).astype(np.int64)          # cell holding the rising edge
    ib = np.floor(b + 0.5).astype(np.int64)          # cell holding the falling edge
    full_lo = ia + 1
    full_hi = ib                                     # samples full_lo .. full_hi - 1 are fully high
    diff = np.zeros(n + 1)
    lo = np.clip(full_lo - i0, 0, n)
    hi = np.clip(full_hi - i0, 0, n)
    ok = hi > lo
    np.add.at(diff, lo[ok], level)
    np.add.at(diff, hi[ok], -level)
    acc = np.cumsum(diff[:n])
    same = ia == ib
    cov_a = np.where(same, b - a, (ia + 0.5) - a)
    cov_b = np.where(same, 0.0, b - (ib - 0.5))
    for idx, cov in ((ia, cov_a), (ib, cov_b)):
        j = idx - i0
        m = (j >= 0) & (j < n) & (cov > 0)
        np.add.at(acc, j[m], level * cov[m])
    out += acc
