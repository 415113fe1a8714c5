"""The angle model of a long recording, fitted in overlapping windows and stitched (array code).

:func:`meshphase.kinematics.angles.fit_angle_model` holds a dense Jacobian of every observation times
every candidate column while it chooses the model order: its memory and time grow with the
number of passes (about 6 kB and 6 ms per observation on the seed rig's eight trains). A
recording of hours would make the angle fit the largest allocation of a run. Here the record
is cut into windows of at most ``max_obs`` observations (cores of equal observation count),
each window is fitted on its core plus two *margins* on either side, and the windows' mesh
angles are joined into one continuous A(t):

* margin ``h`` = the longest relative revolution of any gauge train [s] (the time from a
  planet-1 pass to the last planet of its revolution is below it, so every phasing pair
  whose midpoint lies in a core lies inside that window's fitted span);
* window k is fitted on ``[core_lo - 2 h, core_hi + 2 h]``;
* at a core boundary b the two windows' angles are blended over ``[b - h, b + h]`` with a
  raised-cosine weight, after adding to the later window the constant that makes the two
  agree on average there (their origins differ by the fit's constants). A(t) and dA/dt are
  continuous; the stitch misfit (RMS of the two windows' difference over the blend) is kept
  per boundary: it is the windows' own disagreement and sits at the level of their
  ``difference_std``.

Every model order is chosen per window from that window's data (a long record's drift
needs more spline intervals than one window's); per-pass phasing, uncertainties, residuals
and outlier flags come from the window whose core holds the pass (or the pair's midpoint).
A record of at most ``max_obs`` observations is fitted whole, exactly as
:func:`~meshphase.kinematics.angles.fit_angle_model` does. Memory of the fit is then bounded by
``max_obs`` whatever the length, and the time is linear in the record's length.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from .angles import AngleModel, TrainFit, fit_angle_model
from .shafts import Kinematics
from .trains import PassTrain, slice_train
from ..runtime.threads import thread_pool

__all__ = ["fit_angle_windows", "WindowedAngleModel", "WINDOW_OBS"]

#: Observations per window above which a record is fitted in windows [-]: about 40 MB of
#: the fit's working memory on eight trains (a 1-h seed-rig record holds ~13 000).
WINDOW_OBS = 6000
#: Cores shorter than this many margins are not split further [-].
MIN_CORE_MARGINS = 8.0
#: Points per blend on which the window constants are matched [-].
_STITCH_POINTS = 33


@dataclass
class WindowedAngleModel(AngleModel):
    """An :class:`~meshphase.kinematics.angles.AngleModel` made of windowed fits (module notes).

    Attributes (beyond AngleModel's)
    --------------------------------
    windows : list of AngleModel
        The fits, in time order.
    bounds : ndarray, shape (K - 1,)
        Core boundaries [s].
    margin : float
        Blend half-width h [s].
    constants : ndarray, shape (K,)
        Constant added to each window's A(t) [mesh cycles] (0 for the first).
    stitch_rms : ndarray, shape (K - 1,)
        RMS difference of neighbouring windows over each blend, after the constant [mesh
        cycles].
    """

    windows: list = field(default_factory=list)
    bounds: np.ndarray = field(default_factory=lambda: np.empty(0))
    margin: float = 0.0
    constants: np.ndarray = field(default_factory=lambda: np.zeros(1))
    stitch_rms: np.ndarray = field(default_factory=lambda: np.empty(0))
    _slices: list = field(default_factory=list, repr=False)
    _lengths: dict = field(default_factory=dict, repr=False)

    # ------------------------------------------------------------------ A(t), dA/dt
    def _eval(self, t, rate: bool) -> np.ndarray:
        t = np.atleast_1d(np.asarray(t, dtype=float))
        k = np.searchsorted(self.bounds, t, side="right")
        out = np.empty(t.shape)
        for j, w in enumerate(self.windows):
            m = k == j
            if np.any(m):
                out[m] = w.mesh_rate(t[m]) if rate else w.mesh_angle(t[m]) + self.constants[j]
        h = self.margin
        for j, b in enumerate(self.bounds):
            m = np.abs(t - b) < h
            if not np.any(m):
                continue
            tb = t[m]
            u = (tb - (b - h)) / (2.0 * h)
            wgt = 0.5 - 0.5 * np.cos(np.pi * u)
            lo, hi = self.windows[j], self.windows[j + 1]
            a_lo = lo.mesh_angle(tb) + self.constants[j]
            a_hi = hi.mesh_angle(tb) + self.constants[j + 1]
            if rate:
                dw = 0.5 * np.pi * np.sin(np.pi * u) / (2.0 * h)
                out[m] = (1.0 - wgt) * lo.mesh_rate(tb) + wgt * hi.mesh_rate(tb) + dw * (a_hi - a_lo)
            else:
                out[m] = (1.0 - wgt) * a_lo + wgt * a_hi
        return out

    def mesh_angle(self, t) -> np.ndarray:
        """Mesh angle A(t) [mesh cycles] at times ``t`` [s] (continuous across windows)."""
        return self._eval(t, False)

    def mesh_rate(self, t) -> np.ndarray:
        """Mesh frequency dA/dt [cycles/s] at times ``t`` [s]."""
        return self._eval(t, True)

    def difference_std(self, t_a, t_b) -> np.ndarray:
        """Standard deviation of A(t_a) - A(t_b) [mesh cycles], from the window whose core
        holds the pair's midpoint."""
        ta = np.atleast_1d(np.asarray(t_a, dtype=float))
        tb = np.atleast_1d(np.asarray(t_b, dtype=float))
        k = np.searchsorted(self.bounds, 0.5 * (ta + tb), side="right")
        out = np.empty(ta.shape)
        for j, w in enumerate(self.windows):
            m = k == j
            if np.any(m):
                out[m] = w.difference_std(ta[m], tb[m])
        return out

    def choice_spread(self, t_a, t_b, *, tolerance: float = 0.0) -> tuple[np.ndarray, list]:
        """:meth:`~meshphase.kinematics.angles.AngleModel.choice_spread` from the window whose core
        holds each pair's midpoint; a competitor named alike in several windows is reported
        once, its ``rms`` over all their pairs, its ``delta_bic`` and ``weight`` the most
        telling (lowest BIC difference, highest weight)."""
        ta = np.atleast_1d(np.asarray(t_a, dtype=float))
        tb = np.atleast_1d(np.asarray(t_b, dtype=float))
        if ta.shape != tb.shape:
            raise ValueError(f"t_a and t_b must have one shape, got {ta.shape} and {tb.shape}")
        k = np.searchsorted(self.bounds, 0.5 * (ta + tb), side="right")
        out = np.zeros(ta.shape)
        merged: dict = {}
        for j, w in enumerate(self.windows):
            m = k == j
            if not np.any(m):
                continue
            out[m], info = w.choice_spread(ta[m], tb[m], tolerance=tolerance)
            for c in info:
                key = (c["words"], c["versus"], c["inseparable"])
                if key not in merged:
                    merged[key] = dict(c, rms=c["rms"] ** 2 * c["n"])
                    continue
                e = merged[key]
                e["rms"] += c["rms"] ** 2 * c["n"]
                e["n"] += c["n"]
                e["delta_bic"] = min(e["delta_bic"], c["delta_bic"])
                e["weight"] = max(e["weight"], c["weight"])
                e["counted"] = e["counted"] or c["counted"]
        info = []
        for e in merged.values():
            e["rms"] = math.sqrt(e["rms"] / e["n"]) if e["n"] else float("nan")
            info.append(e)
        return out, info

    # ------------------------------------------------------------------ per-train views
    def _core(self, j: int, t: np.ndarray) -> np.ndarray:
        lo = self.bounds[j - 1] if j > 0 else -np.inf
        hi = self.bounds[j] if j < self.bounds.size else np.inf
        return (t >= lo) & (t < hi)

    def residuals(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """(times [s], residuals [mesh cycles]) of train ``name``, each from its core's window."""
        if name not in self._lengths:
            raise KeyError(f"no train {name!r}")
        ts, rs = [], []
        for j, w in enumerate(self.windows):
            try:
                tt, rr = w.residuals(name)
            except KeyError:
                continue
            c = self._core(j, tt)
            ts.append(tt[c])
            rs.append(rr[c])
        return (np.concatenate(ts), np.concatenate(rs)) if ts else (np.empty(0), np.empty(0))

    def outlier_mask(self, name: str) -> np.ndarray:
        """True for the observations of train ``name`` left out as outliers (by the window
        whose core holds each)."""
        if name not in self._lengths:
            raise KeyError(f"no train {name!r}")
        out = np.zeros(self._lengths[name], bool)
        for j, w in enumerate(self.windows):
            sl = self._slices[j].get(name)
            if sl is None:
                continue
            i0, times = sl
            try:
                m = w.outlier_mask(name)
            except KeyError:
                continue
            c = self._core(j, times)
            idx = np.flatnonzero(c) + i0
            out[idx] = m[c]
        return out

    def summary(self) -> dict:
        """JSON-friendly diagnostics, with one entry per window."""
        s = super().summary()
        s["windows"] = [{"t_span_s": list(w.t_span), "terms": w.terms, "rank": w.rank,
                         "n_parameters": w.n_parameters, "residual_rms_cycles": w.residual_rms,
                         "converged": w.converged} for w in self.windows]
        s["stitch_rms_cycles"] = [float(x) for x in self.stitch_rms]
        s["margin_s"] = self.margin
        return s


def _revolution(tr: PassTrain, n_planets: int) -> float:
    """Longest relative revolution of a gauge train [s]: the longest span of one
    revolution's passes (planet 1 opens it; positions // N count revolutions)."""
    if len(tr) < 2:
        return 0.0
    rev = np.floor_divide(tr.position, n_planets)
    starts = np.flatnonzero(np.diff(rev, prepend=rev[0] - 1))
    first = tr.times[starts]
    nxt = np.append(first[1:], tr.times[-1])
    # a revolution's passes lie between its first pass and the next revolution's first
    span = float(np.max(nxt - first)) if first.size > 1 else float(np.ptp(tr.times))
    return span


def _plan(trains: list, n_planets: int, max_obs: int) -> tuple[np.ndarray, float]:
    """Core boundaries [s] and margin h [s]; no boundaries when one window suffices."""
    n_obs = sum(len(tr) for tr in trains)
    gauges = [tr for tr in trains if tr.kind in ("sun", "ring")]
    h = max(_revolution(tr, n_planets) for tr in gauges)
    t = np.sort(np.concatenate([tr.times for tr in trains]))
    span = float(t[-1] - t[0])
    if n_obs <= max_obs or h <= 0:
        return np.empty(0), h
    # cores of equal observation count, each small enough that core + margins <= max_obs
    per_s = n_obs / span if span > 0 else float("inf")
    core_obs = max_obs - 4.0 * h * per_s
    if core_obs <= 0:
        return np.empty(0), h
    k = math.ceil(n_obs / core_obs)
    k = min(k, int(span // (MIN_CORE_MARGINS * h)))
    if k < 2:
        return np.empty(0), h
    idx = np.round(np.arange(1, k) * (t.size / k)).astype(int)
    return t[idx], h


def fit_angle_windows(trains, kin: Kinematics, n_planets: int, *, max_obs: int = WINDOW_OBS,
                      progress=None, **kwargs) -> AngleModel:
    """The mesh angle of a recording of any length in bounded memory (module notes).

    Parameters
    ----------
    trains, kin, n_planets
        As :func:`meshphase.kinematics.angles.fit_angle_model`.
    max_obs : int
        Observations above which the record is fitted in windows [-] (default
        :data:`WINDOW_OBS`).
    progress : callable, optional
        ``progress(done, total)`` after each window.
    **kwargs
        Passed to :func:`~meshphase.kinematics.angles.fit_angle_model` for every window.

    Returns
    -------
    AngleModel
        The whole-record fit when it holds at most ``max_obs`` observations (or is too short
        to split), else a :class:`WindowedAngleModel`.

    Raises
    ------
    TypeError, ValueError
        As :func:`~meshphase.kinematics.angles.fit_angle_model`; ``max_obs`` not a positive integer.
    """
    if isinstance(max_obs, bool) or not isinstance(max_obs, (int, np.integer)) or max_obs < 100:
        raise ValueError(f"max_obs must be an integer >= 100, got {max_obs!r}")
    trains = list(trains)
    if any(not isinstance(tr, PassTrain) for tr in trains):
        return fit_angle_model(trains, kin, n_planets, **kwargs)   # raises its TypeError
    usable = [tr for tr in trains if len(tr) >= 2]
    if not any(tr.kind in ("sun", "ring") for tr in usable) or int(n_planets) < 1:
        return fit_angle_model(trains, kin, n_planets, **kwargs)   # raises its ValueError
    bounds, h = _plan(usable, int(n_planets), int(max_obs))
    if bounds.size == 0:
        return fit_angle_model(trains, kin, n_planets, **kwargs)
    return _fit_windows(usable, kin, int(n_planets), bounds, h, progress, kwargs)


def _fit_windows(trains, kin, n, bounds, h, progress, kwargs) -> WindowedAngleModel:
    t0 = time.perf_counter()
    edges = np.concatenate([[-np.inf], bounds, [np.inf]])
    jobs, slices = [], []
    for j in range(edges.size - 1):
        lo, hi = edges[j] - 2.0 * h, edges[j + 1] + 2.0 * h
        subs, sl = [], {}
        for tr in trains:
            s, i0 = slice_train(tr, lo, hi)
            if len(s) >= 2:
                subs.append(s)
                sl[tr.name] = (i0, s.times)
        jobs.append((j, lo, hi, subs))
        slices.append(sl)

    # side by side on the run's threads (meshphase.runtime.threads): the fits' heavy steps (QR,
    # matrix products, array arithmetic on thousands of rows) release the GIL
    def fit(job):
        j, lo, hi, subs = job
        try:
            return fit_angle_model(subs, kin, n, **kwargs)
        except ValueError as exc:
            raise ValueError(f"angle model window {j + 1} of {edges.size - 1} "
                             f"([{max(lo, trains[0].times[0]):.1f}, {hi:.1f}] s): {exc}") from exc

    with thread_pool(max_items=len(jobs)) as tmap:
        windows = tmap(fit, jobs, progress=progress)
    consts = np.zeros(len(windows))
    stitch = np.empty(bounds.size)
    for j, b in enumerate(bounds):
        g = np.linspace(b - h, b + h, _STITCH_POINTS)
        diff = windows[j].mesh_angle(g) + consts[j] - windows[j + 1].mesh_angle(g)
        consts[j + 1] = float(np.mean(diff))
        stitch[j] = float(np.sqrt(np.mean((diff - consts[j + 1]) ** 2)))
    return _assemble(trains, windows, slices, bounds, h, consts, stitch, time.perf_counter() - t0)


def _combined_fits(model: WindowedAngleModel, trains) -> list:
    fits = []
    for tr in trains:
        n = n_out = 0
        s2 = r2 = lag_w = lag_n = 0.0
        for j, w in enumerate(model.windows):
            sl = model._slices[j].get(tr.name)
            if sl is None:
                continue
            try:
                f = w.train(tr.name)
                tt, rr = w.residuals(tr.name)
                om = w.outlier_mask(tr.name)
            except KeyError:
                continue
            c = model._core(j, sl[1])
            nk = int(np.count_nonzero(c & ~om))
            n += nk
            n_out += int(np.count_nonzero(c & om))
            s2 += nk * f.scale ** 2
            cr = model._core(j, tt)
            r2 += float(np.sum(rr[cr & ~om] ** 2))
            if math.isfinite(f.lag1):
                lag_w += nk * f.lag1
                lag_n += nk
        if n + n_out == 0:
            continue
        fits.append(TrainFit(tr.name, tr.kind, n, n_out,
                             math.sqrt(s2 / n) if n else float("nan"),
                             math.sqrt(r2 / n) if n else float("nan"),
                             lag_w / lag_n if lag_n else float("nan")))
    return fits


def _combined_offsets(windows) -> dict:
    acc: dict = {}
    for w in windows:
        for name, per in w.offsets.items():
            for p, (v, s) in per.items():
                acc.setdefault(name, {}).setdefault(p, []).append((v, s))
    out = {}
    for name, per in acc.items():
        out[name] = {}
        for p, vals in per.items():
            v = np.array([x[0] for x in vals])
            s = np.array([x[1] for x in vals])
            ok = np.isfinite(s) & (s > 0)
            if np.any(ok):
                wgt = 1.0 / s[ok] ** 2
                out[name][p] = (float(np.sum(wgt * v[ok]) / np.sum(wgt)), float(1.0 / math.sqrt(np.sum(wgt))))
            else:
                out[name][p] = (float(np.mean(v)), float("nan"))
    return out


def _assemble(trains, windows, slices, bounds, h, consts, stitch, wall) -> WindowedAngleModel:
    terms = {}
    for w in windows:
        terms[w.terms] = terms.get(w.terms, 0) + 1
    span = (min(w.t_span[0] for w in windows), max(w.t_span[1] for w in windows))
    notes = [f"angle model fitted in {len(windows)} overlapping windows of about "
             f"{(span[1] - span[0]) / len(windows):.0f} s (blend +/-{h:.1f} s; stitch misfit "
             f"RMS up to {float(np.max(stitch)):.2e} mesh cycles)"]
    for w in windows:
        notes.extend(x for x in w.notes if x not in notes)
    dropped = sorted({d for w in windows for d in w.dropped})
    model = WindowedAngleModel(
        t_span=span, terms=f"{len(windows)} windows: " + "; ".join(
            f"{t} (x{c})" if c > 1 else t for t, c in terms.items()),
        rank=max(w.rank for w in windows), n_parameters=max(w.n_parameters for w in windows),
        dropped=dropped, trains=[], residual_rms=float("nan"),
        selection=[(j, w.terms, w.selection[-1][2] if w.selection else float("nan"))
                   for j, w in enumerate(windows)],
        notes=notes, wall_time=wall, iterations=sum(w.iterations for w in windows),
        converged=all(w.converged for w in windows), offsets=_combined_offsets(windows),
        windows=windows, bounds=np.asarray(bounds, dtype=float), margin=float(h),
        constants=consts, stitch_rms=stitch, _slices=slices,
        _lengths={tr.name: len(tr) for tr in trains})
    model.trains = _combined_fits(model, trains)
    nn = sum(t.n for t in model.trains if math.isfinite(t.rms))
    if nn:
        model.residual_rms = math.sqrt(sum(t.n * t.rms ** 2 for t in model.trains
                                           if math.isfinite(t.rms)) / nn)
    return model
