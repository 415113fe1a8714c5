"""The tolerance model's parts: statistics names, observation windows, the time grid of the
kernel, tolerance bands and their sampling map, and the Monte Carlo result types.

Shared by the plain Monte Carlo (:mod:`.tolerance`), the linearised model
(:mod:`.tolerance_linear`) and the control-variate estimator (:mod:`.tolerance_cv`), which
import it and not each other; :mod:`.tolerance` re-exports every public name (conventions in
its docstring).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np

from ..runtime.lazy import special
from ..validate import (as_choice, as_finite_array, as_float, as_int, as_nonnegative,
                        as_positive, as_positive_int)
from . import _kernels
from .gearset import Speeds
from ._geometry import (MAX_PHASE, TWO_PI, check_gearset, check_speeds, cos_sin,
                        direction_sign, rotation_angle_unchecked)

__all__ = [
    "ObservationWindow", "observation_window", "default_n_times", "time_grid", "PhasingStats",
    "ToleranceBand", "Tolerances", "StatSummary", "MonteCarloResult", "STATISTICS",
    "ABSOLUTE_STATISTICS", "ALL_STATISTICS", "WINDOW_KINDS", "SAMPLERS", "METHODS",
    "DEFAULT_QUANTILES",
]

#: Statistics relative to planet 1 (planet 1 is 0 by construction).
STATISTICS = ("ave_s", "dev_s", "ave_r", "dev_r")
#: The same statistics of each mesh's own (absolute) phasing deviation, seed 000's gamma_jn.
ABSOLUTE_STATISTICS = ("ave_s_abs", "dev_s_abs", "ave_r_abs", "dev_r_abs")
ALL_STATISTICS = STATISTICS + ABSOLUTE_STATISTICS
WINDOW_KINDS = ("slowest-offset", "fastest-offset", "common-period")
SAMPLERS = ("random", "sobol")
#: Estimators of :func:`monte_carlo`.
METHODS = ("plain", "cv")
#: Quantile levels reported by default; the first and last are the two-sided 3-sigma levels
#: Phi(-3) and Phi(3) of a normal distribution.
DEFAULT_QUANTILES = (float(special.ndtr(-3.0)), 0.025, 0.5, 0.975, float(special.ndtr(3.0)))
#: the two 3-sigma levels of the normal distribution [-]
P3_LO = float(special.ndtr(-3.0))
P3_HI = float(special.ndtr(3.0))


# ----------------------------------------------------------------------------- window

@dataclass(frozen=True)
class ObservationWindow:
    """Observation window [t0, t0 + duration] of the phasing statistics.

    Parameters
    ----------
    t0 : float
        Start time [s].
    duration : float
        Window length T [s], > 0.
    name : str
        Label used in reports (e.g. "slowest-offset").
    """

    t0: float
    duration: float
    name: str = "custom"

    def __post_init__(self):
        object.__setattr__(self, "t0", as_float(self.t0, "window t0"))
        object.__setattr__(self, "duration", as_positive(self.duration, "window duration"))
        if not isinstance(self.name, str):
            raise TypeError(f"window name must be a string, got {self.name!r}")

    def to_dict(self) -> dict:
        return {"t0": self.t0, "duration": self.duration, "name": self.name}

    def __str__(self) -> str:
        return f"{self.name} window [{self.t0:g}, {self.t0 + self.duration:g}] s"


def offset_speeds(speeds):
    """The rotation speeds [rad/s] of sun, planet and ring relative to the carrier, by gear name."""
    return {"sun": speeds.w_sc, "planet": speeds.w_pc, "ring": speeds.w_rc}


def observation_window(speeds: Speeds, kind: str = "slowest-offset", *, t0: float = 0.0,
                       max_revolutions: int = 1000) -> ObservationWindow:
    """A named observation window for the phasing statistics.

    Parameters
    ----------
    speeds : Speeds
        Absolute speeds [rad/s]; the offsets turn at w_sc, w_pc, w_rc relative to the carrier.
    kind : {"slowest-offset", "fastest-offset", "common-period"}
        "slowest-offset" (default): T = 2 pi / min |w| over the turning offsets, so every
        offset completes at least one relative revolution (for a fixed ring the ring offset,
        turning at carrier speed, sets T). "fastest-offset": one revolution of the fastest
        offset. "common-period": the shortest T in which every offset completes a whole
        number of revolutions (speed ratios read as fractions with denominators up to
        ``max_revolutions``); first-order terms of the deviation then average out exactly.
    t0 : float
        Window start [s].
    max_revolutions : int
        Largest number of revolutions of the slowest offset for "common-period" [-].

    Returns
    -------
    ObservationWindow

    Raises
    ------
    ValueError
        When no offset turns (all relative speeds zero) or no common period exists within
        ``max_revolutions``.
    """
    sp = check_speeds(speeds)
    kind = as_choice(kind, "kind", WINDOW_KINDS)
    t0 = as_float(t0, "t0")
    max_rev = as_positive_int(max_revolutions, "max_revolutions")
    ws = [abs(w) for w in offset_speeds(sp).values() if w != 0.0]
    if not ws:
        raise ValueError("speeds: no offset turns relative to the carrier "
                         f"(w_sc = w_pc = w_rc = 0), got {sp!r}; give the window explicitly")
    w_min, w_max = min(ws), max(ws)
    if kind == "slowest-offset":
        return ObservationWindow(t0, TWO_PI / w_min, kind)
    if kind == "fastest-offset":
        return ObservationWindow(t0, TWO_PI / w_max, kind)
    m = 1
    for w in ws:
        r = w / w_min
        fr = Fraction(r).limit_denominator(max_rev)
        if abs(float(fr) - r) > 1e-9 * r:
            raise ValueError(f"speeds: no common period within {max_rev} revolutions of the "
                             f"slowest offset (speed ratio {r!r})")
        m = m * fr.denominator // math.gcd(m, fr.denominator)
    if m > max_rev:
        raise ValueError(f"speeds: the common period needs {m} > max_revolutions = {max_rev} "
                         "revolutions of the slowest offset")
    return ObservationWindow(t0, m * TWO_PI / w_min, kind)


def as_window(window, speeds):
    """An :class:`ObservationWindow` from a window or its dict (ValueError/TypeError naming it)."""
    if isinstance(window, ObservationWindow):
        return window
    if isinstance(window, str):
        return observation_window(speeds, window)
    if isinstance(window, (tuple, list)) and len(window) == 2:
        return ObservationWindow(window[0], window[1], "custom")
    raise TypeError("window must be an ObservationWindow, a (t0, T) tuple [s] or one of "
                    f"{list(WINDOW_KINDS)}, got {window!r}")


def default_n_times(speeds: Speeds, window, *, points_per_rev: int = 64,
                    min_points: int = 16) -> int:
    """Number of time samples that resolve the fastest offset rotation over a window.

    Parameters
    ----------
    speeds : Speeds
        Absolute speeds [rad/s].
    window : ObservationWindow or (t0, T) tuple [s] or window kind
        Observation window.
    points_per_rev : int
        Samples per revolution of the fastest offset [-] (64: Dev of a sinusoid low by at most
        0.12 %).
    min_points : int
        Lower bound [-].

    Returns
    -------
    int
        ``max(min_points, ceil(points_per_rev T max|w| / 2 pi))``.
    """
    sp = check_speeds(speeds)
    win = as_window(window, sp)
    ppr = as_positive_int(points_per_rev, "points_per_rev")
    mp = as_positive_int(min_points, "min_points")
    w_max = max(abs(w) for w in offset_speeds(sp).values())
    revs = win.duration * w_max / TWO_PI
    return max(mp, int(math.ceil(ppr * revs - 1e-9)))


def time_grid(window, n_times: int) -> np.ndarray:
    """The time grid t_k = t0 + k T / n_times, k = 0 .. n_times - 1 [s]."""
    if not isinstance(window, ObservationWindow):
        if isinstance(window, (tuple, list)) and len(window) == 2:
            window = ObservationWindow(window[0], window[1])
        else:
            raise TypeError(f"window must be an ObservationWindow or (t0, T) tuple, got {window!r}")
    n = as_positive_int(n_times, "n_times")
    return window.t0 + window.duration * (np.arange(n, dtype=float) / n)


# ----------------------------------------------------------------------------- per realisation

@dataclass(frozen=True, eq=False)
class PhasingStats:
    """Ave and Dev of the phasing deviation per realisation (:func:`phasing_statistics`).

    Attributes
    ----------
    ave_s, dev_s, ave_r, dev_r : numpy.ndarray
        Time mean and max - min over the window of gamma_jn(t) - gamma_jn,ideal [-]
        (mesh cycles), phasing relative to planet 1, shape (*S, N); planet 1 is 0.
    window : ObservationWindow
        The observation window.
    n_times : int
        Number of time samples on the window [-].
    engine : str
        "numba" or "numpy".
    ave_s_abs, dev_s_abs, ave_r_abs, dev_r_abs : numpy.ndarray
        The same for each mesh's own (absolute) phase, seed 000's
        gamma_sn = s Z_s psi_espn / 2 pi and gamma_rn = -s Z_r psi_erpn / 2 pi less their
        ideal values: s Z_s delta_s,n / 2 pi and -s Z_r delta_r,n / 2 pi [-], shape (*S, N);
        planet 1 has its own values. The relative ones are their differences to planet 1
        as functions of time (Ave_rel,n = Ave_abs,n - Ave_abs,1 exactly; Dev is not additive).
    """

    ave_s: np.ndarray
    dev_s: np.ndarray
    ave_r: np.ndarray
    dev_r: np.ndarray
    window: ObservationWindow
    n_times: int
    engine: str
    ave_s_abs: np.ndarray = None
    dev_s_abs: np.ndarray = None
    ave_r_abs: np.ndarray = None
    dev_r_abs: np.ndarray = None


class RotationGrid:
    """Precomputed cos/sin of the offset rotations on a time grid and of the planet angles."""

    def __init__(self, gearset, speeds, window, n_times):
        self.t = time_grid(window, n_times)
        tmax = float(np.max(np.abs(self.t)))
        arrays = []
        for name, w in (("w_sc", speeds.w_sc), ("w_rc", speeds.w_rc), ("w_pc", speeds.w_pc)):
            if abs(w) * tmax > MAX_PHASE:
                raise ValueError(f"|{name} t| must be <= {MAX_PHASE:g} rad over the window, got "
                                 f"{name} = {w!r} rad/s, max |t| = {tmax:g} s; shift the window")
            r = rotation_angle_unchecked(w, self.t)
            arrays += [np.cos(r), np.sin(r)]
        self.arrays = arrays
        psi = gearset.angles
        self.cpsi = np.cos(psi)
        self.spsi = np.sin(psi)
        self.R = gearset.carrier_radius
        sign = direction_sign(gearset.direction)
        self.g_s = sign * gearset.z_sun / TWO_PI
        self.g_r = -sign * gearset.z_ring / TWO_PI
        self.n_planets = psi.size

    def run(self, es, ks, er, kr, ep, kp, engine):
        """Stats for flat realisations: es.. (S,), ep, kp (S, N).

        Returns 8 arrays (S, N): ave_s, dev_s, ave_r, dev_r relative to planet 1, then the
        same four absolute (each mesh's own deviation), the order of :data:`ALL_STATISTICS`.
        """
        n_s = es.shape[0]
        outs = [np.empty((n_s, self.n_planets)) for _ in range(8)]
        if n_s == 0:
            return outs
        cks, sks = cos_sin(ks)
        ckr, skr = cos_sin(kr)
        ckp, skp = cos_sin(kp)
        fn = _kernels.stats_numba if engine == "numba" else _kernels.stats_numpy
        fn(*self.arrays, self.cpsi, self.spsi, self.R,
           np.ascontiguousarray(es, dtype=float), cks, sks,
           np.ascontiguousarray(er, dtype=float), ckr, skr,
           np.ascontiguousarray(ep, dtype=float), np.ascontiguousarray(ckp),
           np.ascontiguousarray(skp), self.g_s, self.g_r, *outs[:4], out_abs=outs[4:])
        return outs


def resolve_n_times(speeds, window, n_times, points_per_rev):
    """Time points of a tolerance run: ``n_times`` checked (>= 2), or the default for
    ``points_per_rev`` points per relative revolution over ``window`` when None [-]."""
    if n_times is None:
        return default_n_times(speeds, window, points_per_rev=points_per_rev)
    n = as_positive_int(n_times, "n_times")
    if n < 2:
        raise ValueError(f"n_times must be >= 2 (Dev is a max - min), got {n}")
    return n


# ----------------------------------------------------------------------------- tolerances

@dataclass(frozen=True)
class ToleranceBand:
    """Distribution of one error parameter.

    Parameters
    ----------
    mean : float
        Mean (centre) [m] for radial errors, [rad] for angles.
    band : float
        Half-width of the tolerance band [m] or [rad], >= 0. "normal": the band is +-3 sigma
        (seed 000: "3 sigma principle"), sigma = band / 3. "uniform": values uniform on
        [mean - band, mean + band]. ``band = 0`` is a fixed (given) value.
    distribution : {"normal", "uniform"}
        Distribution family.

    Notes
    -----
    A sampled radial error below zero is the same offset pointing the other way: the Monte
    Carlo stores |e| and turns the angle by pi.
    """

    mean: float = 0.0
    band: float = 0.0
    distribution: str = "normal"

    def __post_init__(self):
        object.__setattr__(self, "mean", as_float(self.mean, "mean"))
        object.__setattr__(self, "band", as_nonnegative(self.band, "band"))
        object.__setattr__(self, "distribution",
                           as_choice(self.distribution, "distribution", ("normal", "uniform")))

    @classmethod
    def fixed(cls, value: float) -> "ToleranceBand":
        """A given (deterministic) value [m] or [rad]."""
        return cls(value, 0.0)

    @classmethod
    def full_circle(cls) -> "ToleranceBand":
        """An angle uniform on [0, 2 pi) [rad]."""
        return cls(math.pi, math.pi, "uniform")

    @property
    def sigma(self) -> float:
        """Standard deviation [m] or [rad]."""
        return self.band / 3.0 if self.distribution == "normal" else self.band / math.sqrt(3.0)

    @property
    def is_random(self) -> bool:
        return self.band > 0.0

    def ppf(self, u: np.ndarray) -> np.ndarray:
        """Map uniform numbers u in [0, 1) to values of this distribution (inverse CDF)."""
        if self.band == 0.0:
            return np.full(np.shape(u), self.mean)
        if self.distribution == "uniform":
            return self.mean - self.band + 2.0 * self.band * u
        # u = 0 (probability 2**-53 for random, possible for Sobol) would give -inf: keep the
        # inverse CDF finite (|z| <= 8.2 sigma; 1 - 2**-53 is the largest double below 1)
        uc = np.clip(u, 2.0 ** -53, 1.0 - 2.0 ** -53)
        return self.mean + self.sigma * special.ndtri(uc)

    def to_dict(self) -> dict:
        return {"mean": self.mean, "band": self.band, "distribution": self.distribution}


#: the shaft-hole error fields of a tolerance set, in sampling order
ERROR_FIELDS = ("e_sun", "kappa_sun", "e_ring", "kappa_ring", "e_planet", "kappa_planet")


def as_band(value, name):
    """A :class:`ToleranceBand` from a band, a number [m] or a (low, high) pair [m]."""
    if isinstance(value, ToleranceBand):
        return value
    if isinstance(value, str):
        if value == "uniform":
            return ToleranceBand.full_circle()
        raise ValueError(f"{name} must be a ToleranceBand, a number or 'uniform', got {value!r}")
    return ToleranceBand.fixed(as_float(value, name))


@dataclass(frozen=True)
class Tolerances:
    """Tolerance bands of the six error parameters (planet bands apply to each planet).

    Parameters
    ----------
    e_sun, e_ring, e_planet : ToleranceBand or float
        Radial errors [m]; a float is a fixed value.
    kappa_sun, kappa_ring, kappa_planet : ToleranceBand or float or "uniform"
        Angles [rad] (conventions of :class:`ShaftHoleErrors`); "uniform" draws on [0, 2 pi).

    Notes
    -----
    Every planet draws its own e_planet and kappa_planet independently from the same band.
    """

    e_sun: ToleranceBand = field(default_factory=ToleranceBand)
    kappa_sun: ToleranceBand = field(default_factory=ToleranceBand)
    e_ring: ToleranceBand = field(default_factory=ToleranceBand)
    kappa_ring: ToleranceBand = field(default_factory=ToleranceBand)
    e_planet: ToleranceBand = field(default_factory=ToleranceBand)
    kappa_planet: ToleranceBand = field(default_factory=ToleranceBand)

    def __post_init__(self):
        for name in ERROR_FIELDS:
            object.__setattr__(self, name, as_band(getattr(self, name), name))

    def to_dict(self) -> dict:
        return {name: getattr(self, name).to_dict() for name in ERROR_FIELDS}

    def columns(self, n_planets: int) -> list[tuple[str, int | None, ToleranceBand]]:
        """The parameters in sampling order: (field, planet index or None, band)."""
        cols = [(name, None, getattr(self, name)) for name in ERROR_FIELDS[:4]]
        for n in range(n_planets):
            cols.append(("e_planet", n, self.e_planet))
            cols.append(("kappa_planet", n, self.kappa_planet))
        return cols

    def n_random(self, n_planets: int) -> int:
        """Number of random dimensions (bands > 0) for ``n_planets`` planets [-]."""
        return sum(1 for _, _, b in self.columns(n_planets) if b.is_random)

    def check(self, carrier_radius: float) -> None:
        """Reject bands that reach the carrier radius [m] (ValueError)."""
        for name in ("e_sun", "e_ring", "e_planet"):
            b = getattr(self, name)
            if abs(b.mean) + b.band >= carrier_radius:
                raise ValueError(f"{name}: |mean| + band = {abs(b.mean) + b.band!r} m must be < "
                                 f"carrier_radius = {carrier_radius!r} m")


def map_samples(u, tol, n_planets):
    """Unit-cube points u (B, d) -> flat error arrays (es, ks, er, kr, ep, kp)."""
    rand = [band for _, _, band in tol.columns(n_planets) if band.is_random]
    values = np.empty(u.shape[:1] + (len(rand),))
    for j, band in enumerate(rand):
        values[:, j] = band.ppf(u[:, j])
    return map_values(values, tol, n_planets)


def map_values(values, tol, n_planets):
    """Values (B, d) of the random parameters (sampling order, signed radial errors [m],
    angles [rad]) -> flat error arrays (es, ks, er, kr, ep, kp), fixed parameters at their
    means, negative radial errors as |e| with the angle turned by pi."""
    bsz = values.shape[0]
    vals = {}
    j = 0
    pl = {"e_planet": np.empty((bsz, n_planets)), "kappa_planet": np.empty((bsz, n_planets))}
    for name, n, band in tol.columns(n_planets):
        if band.is_random:
            v = np.array(values[:, j], dtype=float)
            j += 1
        else:
            v = np.full(bsz, band.mean)
        if n is None:
            vals[name] = v
        else:
            pl[name][:, n] = v
    es, ks = vals["e_sun"], vals["kappa_sun"]
    er, kr = vals["e_ring"], vals["kappa_ring"]
    ep, kp = pl["e_planet"], pl["kappa_planet"]
    for e, k in ((es, ks), (er, kr), (ep, kp)):
        neg = e < 0.0
        if np.any(neg):
            e[neg] = -e[neg]
            k[neg] = k[neg] + math.pi
    return es, ks, er, kr, ep, kp


# ----------------------------------------------------------------------------- Monte Carlo result

@dataclass(eq=False)
class StatSummary:
    """Distribution summary of one statistic (e.g. Dev_sn) over the Monte Carlo samples.

    All arrays have a trailing planet axis (N,); values in mesh cycles [-].

    Attributes
    ----------
    mean, std : numpy.ndarray
        Sample mean and standard deviation (ddof = 1), shape (N,).
    quantile_levels : numpy.ndarray
        Probability levels, shape (Q,).
    quantiles : numpy.ndarray
        Sample quantiles, shape (Q, N).
    bound3 : numpy.ndarray
        3-sigma bounds as the quantiles at Phi(-3) = 0.135 % and Phi(3) = 99.865 %, shape (2, N)
        (distribution-free; the seed's "3 sigma confidence interval").
    mean_pm_3std : numpy.ndarray
        mean -+ 3 std, shape (2, N) (equals bound3 for a normal distribution).
    hist_counts, hist_edges : numpy.ndarray
        Histogram per planet, shapes (N, bins) and (N, bins + 1).
    se_mean, se_std : numpy.ndarray
        Standard errors of mean and std, shape (N,).
    se_quantiles : numpy.ndarray
        Standard errors of the quantiles, shape (Q, N).
    se_bound3 : numpy.ndarray
        Standard errors of bound3, shape (2, N).

    Notes
    -----
    Standard errors come from R independent replicates (independent random streams, or
    independently scrambled Sobol sequences: randomised QMC): SE = std over replicates of the
    statistic / sqrt(R). For the extreme quantiles this is conservative when a replicate is
    small. NaN when R < 2.
    """

    mean: np.ndarray
    std: np.ndarray
    quantile_levels: np.ndarray
    quantiles: np.ndarray
    bound3: np.ndarray
    mean_pm_3std: np.ndarray
    hist_counts: np.ndarray
    hist_edges: np.ndarray
    se_mean: np.ndarray
    se_std: np.ndarray
    se_quantiles: np.ndarray
    se_bound3: np.ndarray

    def to_dict(self) -> dict:
        return {k: np.asarray(getattr(self, k)).tolist() for k in self.__dataclass_fields__}


@dataclass(eq=False)
class MonteCarloResult:
    """Tolerance Monte Carlo of the phasing statistics (:func:`monte_carlo`).

    Attributes
    ----------
    ave_s, dev_s, ave_r, dev_r : StatSummary
        Distributions of Ave_sn, Dev_sn, Ave_rn, Dev_rn over the samples [-], phasing
        relative to planet 1 (planet 1 is 0).
    ave_s_abs, dev_s_abs, ave_r_abs, dev_r_abs : StatSummary
        The same for each mesh's own (absolute) phasing, as seed 000 defines gamma_jn
        (see :class:`PhasingStats`); planet 1 has its own distribution.
    n_samples : int
        Number of error realisations [-].
    sampler : str
        "random" (pseudo-random) or "sobol" (scrambled Sobol, randomised QMC).
    window : ObservationWindow
        Observation window of Ave / Dev.
    n_times : int
        Time samples on the window [-].
    replicates : int
        Independent replicates used for the standard errors [-].
    engine : str
        "numba" or "numpy".
    wall_time : float
        Wall-clock time of the run [s].
    tolerances : Tolerances
        The bands sampled.
    samples : dict or None
        Per-sample arrays {"ave_s", ..., "dev_r_abs"} (:data:`ALL_STATISTICS`) of shape
        (n_samples, N) when kept.
    exact_quantiles : bool
        False when the quantiles and histograms come from the bounded-memory fine histograms.
    method : str
        "plain" (every summary from the samples) or "cv" (control variate about the
        linearised model, :mod:`meshphase.models.tolerance_cv`).
    n_evaluations : int or None
        Full-model evaluations of a "cv" run (paired points plus tail directions) [-];
        None for "plain" (equal to ``n_samples``).
    """

    ave_s: StatSummary
    dev_s: StatSummary
    ave_r: StatSummary
    dev_r: StatSummary
    n_samples: int
    sampler: str
    window: ObservationWindow
    n_times: int
    replicates: int
    engine: str
    wall_time: float
    tolerances: Tolerances
    samples: dict | None = None
    exact_quantiles: bool = True
    ave_s_abs: StatSummary | None = None
    dev_s_abs: StatSummary | None = None
    ave_r_abs: StatSummary | None = None
    dev_r_abs: StatSummary | None = None
    method: str = "plain"
    n_evaluations: int | None = None

    def stat(self, name: str) -> StatSummary:
        """The summary of ``name`` in :data:`ALL_STATISTICS` ("ave_s" ... "dev_r_abs")."""
        return getattr(self, as_choice(name, "name", ALL_STATISTICS))

    def phasing_band(self, gear: str) -> tuple[np.ndarray, np.ndarray]:
        """The band of planet-1-relative phasing that the tolerances allow for a gauge on
        ``gear`` ("sun" or "ring"), per planet [mesh cycles]: Ave's 3-sigma bounds widened
        by half of Dev's upper bound, ``lo = Ave.bound3[0] - Dev.bound3[1] / 2``,
        ``hi = Ave.bound3[1] + Dev.bound3[1] / 2`` (what measured passes are checked
        against, :func:`meshphase.compare.predict.band_coverage`).

        Returns
        -------
        lo, hi : numpy.ndarray
            Shape (N,) each.
        """
        gear = as_choice(gear, "gear", ("sun", "ring"))
        ave, dev = (self.ave_s, self.dev_s) if gear == "sun" else (self.ave_r, self.dev_r)
        return ave.bound3[0] - dev.bound3[1] / 2, ave.bound3[1] + dev.bound3[1] / 2

    def to_dict(self, include_samples: bool = False) -> dict:
        """JSON-friendly dict (per-sample arrays only with ``include_samples``)."""
        out = {
            "n_samples": self.n_samples, "sampler": self.sampler, "window": self.window.to_dict(),
            "n_times": self.n_times, "replicates": self.replicates, "engine": self.engine,
            "wall_time": self.wall_time, "tolerances": self.tolerances.to_dict(),
            "exact_quantiles": self.exact_quantiles, "method": self.method,
            "n_evaluations": (self.n_samples if self.n_evaluations is None
                              else self.n_evaluations),
        }
        for s in ALL_STATISTICS:
            if getattr(self, s) is not None:
                out[s] = getattr(self, s).to_dict()
        if include_samples and self.samples is not None:
            out["samples"] = {k: v.tolist() for k, v in self.samples.items()}
        return out


def nan_summary(n_p, levels, bins):
    """The Monte Carlo summary arrays of ``n_p`` planets filled with NaN (no finite sample)."""
    nan = np.full(n_p, np.nan)
    q = np.full((levels.size, n_p), np.nan)
    two = np.full((2, n_p), np.nan)
    return StatSummary(nan, nan.copy(), levels, q, two, two.copy(),
                       np.zeros((n_p, bins), dtype=np.int64), np.full((n_p, bins + 1), np.nan),
                       nan.copy(), nan.copy(), q.copy(), two.copy())


def case_inputs(gearset, speeds, tolerances, window):
    """Checked (gearset, speeds, window) of a tolerance run; the bands checked against R_c."""
    g = check_gearset(gearset)
    sp = check_speeds(speeds)
    if not isinstance(tolerances, Tolerances):
        raise TypeError(f"tolerances must be a Tolerances, got {type(tolerances).__name__}")
    tolerances.check(g.carrier_radius)
    return g, sp, as_window(window, sp)


def mc_inputs(gearset, speeds, tolerances, window, n_samples, sampler, n_times, batch_size,
               replicates, bins, quantile_levels, max_memory, engine, progress, points_per_rev):
    """Validate the arguments of :func:`monte_carlo` (ValueError / TypeError naming them)."""
    g, sp, win = case_inputs(gearset, speeds, tolerances, window)
    n = as_int(n_samples, "n_samples")
    if n < 0:
        raise ValueError(f"n_samples must be >= 0, got {n}")
    sampler = as_choice(sampler, "sampler", SAMPLERS)
    n_t = resolve_n_times(sp, win, n_times, points_per_rev)
    bs = as_positive_int(batch_size, "batch_size")
    reps = as_positive_int(replicates, "replicates")
    bins = as_positive_int(bins, "bins")
    levels = as_finite_array(quantile_levels, "quantile_levels", ndim=1)
    if levels.size and (np.any(levels <= 0) or np.any(levels >= 1)):
        raise ValueError(f"quantile_levels must lie in (0, 1), got {levels.tolist()}")
    max_memory = as_nonnegative(max_memory, "max_memory")
    eng = _kernels.resolve_engine(engine)
    if progress is not None and not callable(progress):
        raise TypeError(f"progress must be callable or None, got {progress!r}")
    return g, sp, win, n, sampler, n_t, bs, reps, bins, levels, max_memory, eng
