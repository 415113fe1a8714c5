"""Pass trains: the angle observations the angle model is fitted to.

A :class:`PassTrain` holds one gauge's passes (onset times, planet labels, pass-order
positions and the mesh angle each pass sits at, eq. (1) of :mod:`meshphase.kinematics.angles`)
or a tacho's or an encoder's edges (whole turns of a shaft in mesh cycles). The builders
check their inputs (:func:`gauge_train`, :func:`tacho_train`, :func:`encoder_train`), count
the revolutions of a once-per-turn train with missed edges (:func:`revolution_numbers`), cut
a train to a time window (:func:`slice_train`), move its planet labels cyclically
(:func:`relabel_train`) and read the measured mesh cycles per carrier turn
(:func:`mesh_cycles_per_carrier_turn`). Array code: no fit, no Recording, no files.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from .encoder import EncoderEdges
from ..validate import as_finite_array, as_positive

__all__ = ["PassTrain", "slice_train", "gauge_train", "revolution_numbers", "tacho_train",
           "relabel_train", "mesh_cycles_per_carrier_turn", "encoder_train"]


@dataclass(frozen=True)
class PassTrain:
    """One train of angle observations: a gauge's passes or the tacho's edges.

    Attributes
    ----------
    name : str
        Channel name (or "tacho").
    kind : {"sun", "ring", "tacho"}
        "tacho": a shaft pulse train (a carrier tacho or an encoder, :func:`encoder_train`):
        a constant of its own, no planet terms.
    times : ndarray, shape (m,)
        Observation times [s], strictly increasing.
    sigma : ndarray, shape (m,)
        One-sigma timing uncertainty of each observation [s] (> 0).
    target : ndarray, shape (m,)
        Mesh angle of each observation up to the train's constant and the planet terms
        [mesh cycles]: Z (k + f_n) for a gauge, P_c k for a tacho.
    planet : ndarray of int, shape (m,)
        0-based planet of each gauge pass; -1 for a tacho.
    position : ndarray of int, shape (m,)
        Pass-order position counted from the train's first pass (gauges; revolution
        k = position // N, planet 1 opens each revolution).
    sigma_given : bool
        True when ``sigma`` is a timing bound (the train's variance factor is then >= 1).
    z : int
        Tooth count of the gauged gear (0 for a tacho) [-].
    order : {+1, -1}
        Sense in which the gauge meets the planets (:func:`meshphase.kinematics.pass_table.pass_order`):
        a planet's carrier-frame angle shift d psi moves its passes by
        ``order * z * d psi / 2 pi`` mesh cycles.
    """

    name: str
    kind: str
    times: np.ndarray
    sigma: np.ndarray
    target: np.ndarray
    planet: np.ndarray
    position: np.ndarray
    sigma_given: bool = True
    z: int = 0
    order: int = 1

    def __len__(self) -> int:
        return int(self.times.size)


def slice_train(train: PassTrain, lo: float, hi: float) -> tuple[PassTrain, int]:
    """The observations of ``train`` with ``lo <= time < hi`` [s], and the index of the first.

    Labels, positions and targets are kept as they are (a slice of the train, not a new
    train counted from its own first pass).
    """
    if not isinstance(train, PassTrain):
        raise TypeError(f"train must be a PassTrain, got {type(train).__name__}")
    lo, hi = float(lo), float(hi)
    if math.isnan(lo) or math.isnan(hi):
        raise ValueError(f"lo and hi must be numbers, got {lo!r}, {hi!r}")
    i0, i1 = np.searchsorted(train.times, [lo, hi], side="left")
    s = slice(int(i0), int(max(i0, i1)))
    return replace(train, times=train.times[s], sigma=train.sigma[s], target=train.target[s],
                   planet=train.planet[s], position=train.position[s]), int(i0)


def _check_times(times, name: str) -> np.ndarray:
    t = as_finite_array(times, name, ndim=1)
    if t.size > 1 and np.any(np.diff(t) <= 0):
        raise ValueError(f"{name} must be strictly increasing")
    return t


def _sigma(sigma, n: int, default: float) -> tuple[np.ndarray, bool]:
    if sigma is None:
        return np.full(n, default), False
    s = np.broadcast_to(np.asarray(sigma, dtype=float), (n,)).astype(float)
    bad = ~np.isfinite(s) | (s <= 0)
    if np.all(bad) and n:
        return np.full(n, default), False
    if np.any(bad):
        s[bad] = np.median(s[~bad])
    return s, True


def gauge_train(name: str, gear: str, times, planet, position, fractions, z_gear: int, *,
                sigma=None, order: int = 1) -> PassTrain:
    """A gauge's pass train for :func:`meshphase.kinematics.angles.fit_angle_model`.

    Parameters
    ----------
    name : str
        Channel name.
    gear : {"sun", "ring"}
        Gear carrying the gauge.
    times : array_like, shape (m,)
        Pass times [s], strictly increasing.
    planet : array_like of int, shape (m,)
        0-based planet per pass (>= 0: pass unassigned pulses separately, not here).
    position : array_like of int, shape (m,)
        Pass-order position of each pass (:func:`meshphase.kinematics.planet_labels.assign_planets_by_pattern`
        ``info["position"]``): consecutive planets differ by 1, a revolution by N.
    fractions : array_like, shape (N,)
        Fraction of a revolution from planet 1 to planet n in pass order [-]
        (:func:`meshphase.kinematics.pass_table.planet_fractions`).
    z_gear : int
        Tooth count of the gauged gear [-].
    sigma : float or array_like, optional
        Timing uncertainty per pass [s] (the onset timing bound). None: unknown (the
        train's scatter sets it).
    order : {+1, -1}
        The gauge's pass order (:func:`meshphase.kinematics.pass_table.pass_order`), which sets the sign
        with which a planet's own angle shift moves its passes.
    """
    if order not in (1, -1):
        raise ValueError(f"order must be +1 or -1, got {order!r}")
    if gear not in ("sun", "ring"):
        raise ValueError(f"gear must be 'sun' or 'ring', got {gear!r}")
    t = _check_times(times, "times")
    pl = np.asarray(planet)
    pos = np.asarray(position)
    if pl.shape != t.shape or pos.shape != t.shape:
        raise ValueError(f"planet {pl.shape} and position {pos.shape} must have the shape of "
                         f"times {t.shape}")
    if t.size and (not np.issubdtype(pl.dtype, np.integer) or not np.issubdtype(pos.dtype, np.integer)):
        raise TypeError("planet and position must be integer arrays")
    f = as_finite_array(fractions, "fractions", ndim=1, allow_empty=False)
    n = f.size
    if t.size and (pl.min() < 0 or pl.max() >= n):
        raise ValueError(f"planet must lie in [0, {n - 1}], got [{pl.min()}, {pl.max()}]")
    z = int(z_gear)
    if z <= 0:
        raise ValueError(f"z_gear must be a positive integer, got {z_gear!r}")
    seq = np.argsort(f, kind="stable")
    fs = f[seq]
    if t.size and np.any(seq[pos % n] != pl):
        raise ValueError("position and planet disagree: position % N must be the planet's place "
                         "in pass order")
    target = z * (np.floor_divide(pos, n) + fs[pos % n])
    dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    s, given = _sigma(sigma, t.size, 1e-3 * dt)
    return PassTrain(name, gear, t, s, target.astype(float), pl.astype(int), pos.astype(int), given,
                     z, int(order))


def revolution_numbers(ref_times, *, tol: float = 0.5) -> np.ndarray:
    """Revolution count k of each once-per-revolution reference time, allowing for missed ones.

    A reference pulse missing (gap, dropout) shows as an interval about twice the local period;
    k then steps by the rounded ratio, so the angle knots stay right.

    Parameters
    ----------
    ref_times : array_like, shape (m,)
        Sorted reference times [s] (planet-1 passes or tacho pulses).
    tol : float
        Largest accepted distance of an interval ratio from an integer [-].

    Returns
    -------
    k : ndarray of int, shape (m,)
        k[0] = 0, non-decreasing steps of >= 1.
    """
    t = as_finite_array(ref_times, "ref_times", ndim=1)
    if t.size == 0:
        return np.empty(0, dtype=int)
    if t.size == 1:
        return np.zeros(1, dtype=int)
    d = np.diff(t)
    if np.any(d <= 0):
        raise ValueError("ref_times must be strictly increasing")
    # local period: running median of the intervals (robust to single missed pulses)
    # local period: running median of the intervals over 15 (robust to a few missed pulses,
    # follows slow speed change); short trains use their global median
    w = 15
    if d.size < w:
        local = np.full(d.size, np.median(d))
    else:
        pad = np.pad(d, (w // 2, w - 1 - w // 2), mode="reflect")
        local = np.median(np.lib.stride_tricks.sliding_window_view(pad, w), axis=1)
    ratio = d / local
    steps = np.maximum(1, np.rint(ratio)).astype(int)
    return np.concatenate([[0], np.cumsum(steps)])


def tacho_train(times, cycles_per_rev: float, *, sigma=None, name: str = "tacho") -> PassTrain:
    """The carrier tacho's rising edges as an angle train (A = P_c k + c_T).

    Parameters
    ----------
    times : array_like, shape (m,)
        Edge times [s], strictly increasing.
    cycles_per_rev : float
        Mesh cycles per carrier revolution P_c [-] (Z_r with the ring held, Z_s with the sun
        held; :attr:`meshphase.kinematics.shafts.Kinematics.tacho_cycles`).
    sigma : float or array_like, optional
        Edge timing uncertainty [s]; None: the train's scatter sets it.
    """
    t = _check_times(times, "times")
    p = float(cycles_per_rev)
    if not (math.isfinite(p) and p > 0):
        raise ValueError(f"cycles_per_rev must be a positive number, got {cycles_per_rev!r}")
    k = revolution_numbers(t) if t.size else np.empty(0, int)
    dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    s, given = _sigma(sigma, t.size, 1e-4 * dt)
    return PassTrain(name, "tacho", t, s, p * k.astype(float), np.full(t.size, -1),
                     k.astype(int), given)


def relabel_train(train: PassTrain, shift: int, fractions, n_planets: int) -> PassTrain:
    """The same passes with planet 1 moved ``shift`` places along the pass order (every
    label and position with it): the N cyclic relabellings of a symmetric layout."""
    f = as_finite_array(fractions, "fractions", ndim=1, allow_empty=False)
    n = int(n_planets)
    seq = np.argsort(f, kind="stable")
    pos = train.position + int(shift)
    pl = seq[np.mod(pos, n)]
    target = train.z * (np.floor_divide(pos, n) + np.sort(f)[np.mod(pos, n)])
    return PassTrain(train.name, train.kind, train.times, train.sigma, target.astype(float),
                     pl.astype(int), pos.astype(int), train.sigma_given, train.z, train.order)


def mesh_cycles_per_carrier_turn(train: PassTrain, tacho_times) -> float:
    """Measured mesh cycles per carrier revolution between the first and last tacho edge.

    The gauge train's mesh angle (its targets, piecewise linear between passes) is read at
    the first and the last edge inside its span; the edges count whole carrier turns
    (:func:`revolution_numbers`). Both counts cover the same interval, so a ramp or ripple
    cancels; the error is the linear interpolation between two passes at each end (a
    fraction of the speed variation within one pass interval). A held ring gives Z_r, a held
    sun Z_s (:func:`meshphase.kinematics.shafts.held_member`). NaN when fewer than two edges fall inside the train.
    """
    if not isinstance(train, PassTrain):
        raise TypeError(f"train must be a PassTrain, got {type(train).__name__}")
    t = _check_times(tacho_times, "tacho_times")
    if len(train) < 2 or t.size < 2:
        return float("nan")
    k = revolution_numbers(t)
    inside = (t >= train.times[0]) & (t <= train.times[-1])
    if np.count_nonzero(inside) < 2:
        return float("nan")
    ta, tb = t[inside][0], t[inside][-1]
    ka, kb = k[inside][0], k[inside][-1]
    if kb == ka:
        return float("nan")
    a = np.interp([ta, tb], train.times, train.target)
    return float((a[1] - a[0]) / (kb - ka))


def encoder_train(edges: EncoderEdges, cycles_per_pulse: float, *, sigma=None,
                  name: str = "encoder") -> PassTrain:
    """An encoder's cleaned edges as an angle train (A = cycles_per_pulse k + c).

    Parameters
    ----------
    edges : EncoderEdges
        From :func:`meshphase.kinematics.encoder.clean_edges`.
    cycles_per_pulse : float
        Mesh cycles per pulse [mesh cycles]: :func:`meshphase.kinematics.shafts.shaft_cycles` / pulses per revolution.
    sigma : float or array_like, optional
        Edge timing uncertainty [s] (e.g. :func:`meshphase.kinematics.encoder.edge_timing_sigma`); None: the train's
        scatter sets it.
    name : str
        The channel's name (unique among the trains of a fit).

    Returns
    -------
    PassTrain
        Kind ``"tacho"``: a constant of its own, no planet terms.
    """
    if not isinstance(edges, EncoderEdges):
        raise TypeError(f"edges must be EncoderEdges (meshphase.kinematics.encoder.clean_edges), got "
                        f"{type(edges).__name__}")
    p = as_positive(cycles_per_pulse, "cycles_per_pulse")
    if not isinstance(name, str) or not name:
        raise ValueError(f"name must be a non-empty string, got {name!r}")
    t = _check_times(edges.times, "edges.times")
    k = np.asarray(edges.count, dtype=np.int64)
    if k.shape != t.shape:
        raise ValueError(f"edges.count {k.shape} must have the shape of edges.times {t.shape}")
    if k.size > 1 and np.any(np.diff(k) < 1):
        raise ValueError("edges.count must increase by at least 1 from edge to edge")
    dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    s, given = _sigma(sigma, t.size, 1e-4 * dt)
    return PassTrain(name, "tacho", t, s, p * k.astype(float), np.full(t.size, -1), k, given)
