"""Which cyclic relabelling of a train names the planets as the reference trains do.

A planet's own shaft hole offset moves its passes on every gauge alike (the planet terms of
the angle model are shared by the gauges), so when the planets' offsets differ, only the
relabelling that names the same physical planet alike on both gauges fits:
:func:`label_shift_costs` fits each of the N shifts with a fixed small model and returns
their misfits.
"""

from __future__ import annotations

import numpy as np

from .angle_design import Design, ModelSpec, extend_theta, solve
from .shafts import Kinematics
from .trains import PassTrain, relabel_train, slice_train
from ..runtime.threads import thread_pool
from ..validate import as_positive_int

__all__ = ["label_shift_costs", "SHIFT_OBS"]


#: Observations above which :func:`label_shift_costs` fits only the central time window of
#: the record holding this many [-]: hundreds of passes per train decide a relabelling, and
#: the cost of the N fits then stays bounded in the record's length (a 1-h seed-rig record
#: holds ~13 000 gauge passes).
SHIFT_OBS = 6000


def _central_window(trains: list, max_obs: int) -> list:
    """``trains`` cut to the central time window holding at most ``max_obs`` observations."""
    n_obs = sum(len(tr) for tr in trains)
    if n_obs <= max_obs:
        return trains
    t = np.sort(np.concatenate([tr.times for tr in trains]))
    i0 = (t.size - max_obs) // 2
    lo, hi = t[i0], t[i0 + max_obs - 1]
    return [slice_train(tr, lo, np.nextafter(hi, np.inf))[0] for tr in trains]


def label_shift_costs(reference, train: PassTrain, fractions, kin: Kinematics,
                      n_planets: int, *, max_obs: int = SHIFT_OBS) -> np.ndarray:
    """Misfit of each cyclic relabelling of ``train`` against ``reference`` trains whose
    labels are taken as they are.

    A planet's own shaft hole offset moves its passes on every gauge alike (the planet terms
    of the model are shared by the gauges), so when the planets' offsets differ, only the
    relabelling that names the same physical planet alike on both gauges fits. Each shift is
    fitted with a fixed small model (cubic spline, first ripple harmonic of every shaft that
    turns, first planet term) and scored by its weighted chi-square. A record of more than
    ``max_obs`` observations is fitted on its central time window of ``max_obs`` (every
    train cut alike), so that the cost stays bounded in the record's length. The shifts
    after the first that fits start from its parameters and go side by side on the run's
    threads (:func:`meshphase.runtime.threads.thread_pool`): the same costs as one after another.

    Returns
    -------
    ndarray, shape (N,)
        chi-square per pass-order shift 0..N-1 [-] (inf where the fit failed).
    """
    max_obs = as_positive_int(max_obs, "max_obs")
    refs = [r for r in reference if len(r) >= 2]
    n = int(n_planets)
    out = np.full(n, np.inf)
    if not refs or len(train) < 2 or not kin.planet_period:
        return out
    *refs, train = _central_window(refs + [train], max_obs)
    refs = [r for r in refs if len(r) >= 2]
    if not refs or len(train) < 2:
        return out

    def shift_fit(s, first):
        trs = refs + [relabel_train(train, s, fractions, n)]
        d = Design(trs, kin, n)
        span = d.t_hi - d.t_lo
        mean_rate = (d.y.max() - d.y.min()) / span if span > 0 else 0.0
        harm = {r: (1 if mean_rate * span / P >= 1.0 else 0) for r, P in kin.periods.items()}
        harm["planet"] = 0
        spec = ModelSpec(knots=1, harm=harm, mod={r: False for r in kin.periods}, sig=1)
        ones = np.ones(len(trs))
        if first is not None and d.layout(spec)["names"] == first.lay["names"]:
            # the same columns (a relabelling can change which planets a short train
            # holds, and with them its offsets and planet terms: then it starts afresh)
            th0 = _relabelled_start(d, spec, first.theta, len(trs) - 1)
        else:
            base = solve(d, ModelSpec(knots=1, harm={r: 0 for r in kin.periods},
                                   mod={r: False for r in kin.periods}), None, ones)
            th0 = extend_theta(base, spec, d)
        return solve(d, spec, th0, ones)

    # the shifts in order until one fits; that fit is the start of every later shift, whose
    # fits then share nothing and go side by side on the run's threads (QR and the large
    # array steps release the GIL): the same fits, in any order, as one after another
    first = None
    s = 0
    while s < n and first is None:
        fit = shift_fit(s, None)
        if np.isfinite(fit.chi2):
            out[s] = fit.chi2
            first = fit
        s += 1
    rest = list(range(s, n))
    if first is not None and rest:
        with thread_pool(max_items=len(rest)) as tmap:
            fits = tmap(lambda k: shift_fit(k, first), rest)
        for k, fit in zip(rest, fits):
            if np.isfinite(fit.chi2):
                out[k] = fit.chi2
    return out


def _relabelled_start(d: Design, spec: ModelSpec, theta: np.ndarray, q: int) -> np.ndarray:
    """Start parameters for train ``q`` relabelled: another shift's fitted ``theta`` with
    that train's constant and offsets moved by its per-planet mean residual.

    A cyclic relabelling moves each planet's targets by a constant (a planet spacing and
    whole revolutions), so the shared terms (spline, ripple, the other trains' planet terms)
    of a neighbouring shift's fit are a start a few iterations from this shift's optimum,
    once the train's own constants take up the move."""
    lay = d.layout(spec)
    th = np.array(theta, dtype=float)
    f, _, _ = d.evaluate(th, lay, spec, jac=False)
    r = d.y - f
    m = d.q == q
    if not np.any(m):
        return th
    pl = d.pl[m]
    mean = {int(k): float(np.mean(r[m][pl == k])) for k in np.unique(pl)}
    ref = d.ref[q]
    c0 = mean.get(ref, 0.0)
    if q > 0:
        th[lay["blocks"]["const"].start + q - 1] += c0
    ob = lay["blocks"]["off"].start
    for k, v in mean.items():
        col = int(lay["off_table"][q, k])
        if col >= 0:
            th[ob + col] += v - c0
    return th
