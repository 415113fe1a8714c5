"""Measured phasing against the models: residual statistics, Monte Carlo band coverage and
the comparison with a synthetic recording's truth.

The models' phasing at each pass is :mod:`meshphase.compare.pass_model`, the identification
of the shaft hole errors :mod:`meshphase.compare.identify`; their public names are imported
here too (:func:`predict_pass_phasing`, :func:`wrap`, :func:`identify_errors`,
:class:`Identification`, ...), for the callers that take them from this module.
"""

from __future__ import annotations

import math

import numpy as np

from .identify import (PARAMETER_NAMES, RECORD_FACTORS, Identification, describe_combination,
                       identification_verdict, identify_errors)
from .pass_model import pass_phasing_jacobian, predict_pass_phasing, relative_speeds, wrap
from ..kinematics.pass_table import PassTable, nearest_index
from ..models.gearset import Speeds

__all__ = ["truth_comparison", "residual_stats", "band_coverage", "relative_speeds", "predict_pass_phasing",
           "pass_phasing_jacobian", "wrap", "Identification", "identify_errors", "PARAMETER_NAMES",
           "RECORD_FACTORS", "describe_combination", "identification_verdict"]

TWO_PI = 2.0 * math.pi


def residual_stats(measured, predicted, planets=None) -> dict:
    """Residual statistics of measured - predicted phasing [mesh cycles].

    Returns
    -------
    dict
        ``n``, ``mean``, ``rms``, ``max_abs``, ``std`` overall and ``per_planet`` (same keys).
    """
    m = np.asarray(measured, dtype=float)
    p = np.asarray(predicted, dtype=float)
    if m.shape != p.shape:
        raise ValueError(f"measured {m.shape} and predicted {p.shape} must have the same shape")
    r = wrap(m - p)
    ok = np.isfinite(r)

    def stats(x):
        if x.size == 0:
            return {"n": 0, "mean": float("nan"), "rms": float("nan"), "max_abs": float("nan"),
                    "std": float("nan")}
        return {"n": int(x.size), "mean": float(x.mean()), "rms": float(np.sqrt(np.mean(x ** 2))),
                "max_abs": float(np.max(np.abs(x))), "std": float(x.std())}

    out = stats(r[ok])
    if planets is not None:
        pl = np.asarray(planets)
        if pl.shape != m.shape:
            raise ValueError(f"planets {pl.shape} must have the shape of measured {m.shape}")
        out["per_planet"] = {int(n): stats(r[ok & (pl == n)]) for n in np.unique(pl)}
    return out


def band_coverage(measured, planets, ideal, band_lo, band_hi) -> dict:
    """Which passes fall outside a phasing band around the ideal value.

    Parameters
    ----------
    measured : array_like, shape (m,)
        Measured gamma [-].
    planets : array_like of int, shape (m,)
        1-based planet per pass.
    ideal : array_like, shape (N,)
        Ideal gamma per planet [-].
    band_lo, band_hi : array_like, shape (N,)
        Band of the deviation from ideal per planet [-] (e.g. Monte Carlo 3-sigma bounds of
        the smallest and largest deviation over the window).

    Returns
    -------
    dict
        ``inside_fraction``, ``outside_index`` (row indices), ``per_planet`` fractions.
    """
    m = np.asarray(measured, dtype=float)
    pl = np.asarray(planets, dtype=int)
    if m.shape != pl.shape:
        raise ValueError(f"measured {m.shape} and planets {pl.shape} must have the same shape")
    ideal = np.asarray(ideal, dtype=float)
    lo = np.asarray(band_lo, dtype=float)
    hi = np.asarray(band_hi, dtype=float)
    if ideal.ndim != 1 or lo.shape != ideal.shape or hi.shape != ideal.shape:
        raise ValueError(f"ideal {ideal.shape}, band_lo {lo.shape} and band_hi {hi.shape} must be "
                         "1-D with one value per planet")
    if m.size == 0:
        return {"inside_fraction": float("nan"), "outside_index": [], "per_planet": {}}
    if pl.min() < 1 or pl.max() > ideal.size:
        raise ValueError(f"planets must lie in [1, {ideal.size}], got [{pl.min()}, {pl.max()}]")
    # passes without a measured value are neither inside nor outside: left out of the counts
    fin = np.isfinite(m)
    dev = wrap(m - ideal[pl - 1])
    inside = (dev >= lo[pl - 1]) & (dev <= hi[pl - 1])

    def frac(mask):
        return float(inside[mask].mean()) if np.any(mask) else float("nan")

    return {"inside_fraction": frac(fin),
            "outside_index": np.flatnonzero(fin & ~inside).tolist(),
            "per_planet": {int(n): frac(fin & (pl == n)) for n in np.unique(pl)}}


def truth_comparison(table: PassTable, truth, channel: str, *, times=None, planets=None) -> dict | None:
    """Measured phasing of ``table`` against a synthetic recording's truth, pass by pass.

    Each measured row compares two pulses (the planet-n pass and its planet-1 reference);
    both are matched to the truth's engagements of ``channel`` (after removing the median
    offset of the timed pulse feature from the engagement instant) and the true phasing of
    exactly that pair is the mesh angle the gear turned between them,
    ``Z |w| (tau_n - tau_1) / 2 pi`` with tau the truth's angle time (``meshphase.synthetic.truth``).
    So the error is the measurement's own, whatever the planet labels.

    Parameters
    ----------
    table : PassTable
    truth : meshphase.synthetic.truth.GroundTruth
        Anything with ``events[channel]`` (``time``, ``tau``, ``planet``) and ``config``
        (``gearset``, ``speeds``).
    channel : str
        The gauge channel the table was measured on.
    times, planets : array_like, optional
        Every labelled pulse of the channel [s] and its 0-based planet (-1 unassigned): gives
        ``label_match``, the share of labels equal to the truth's.

    Returns
    -------
    dict or None
        ``n``, ``rms``, ``max_abs`` [cycles]; ``z_rms`` (RMS of error / uncertainty) and
        ``coverage95`` (share within 1.96 sigma); ``floor_rms`` (RMS timing floor [cycles]);
        ``label_match``; ``onset_offset_s``; ``errors`` (per row [cycles]). None when the
        truth has no engagements for the channel or the table is empty.
    """
    if not isinstance(table, PassTable):
        raise TypeError(f"table must be a PassTable, got {type(table).__name__}")
    events = getattr(truth, "events", None)
    if not isinstance(events, dict) or channel not in events or not len(table):
        return None
    ev = events[channel]
    et = np.asarray(ev.time, dtype=float)
    if et.size < 2:
        return None

    ref_times = table.time if times is None else np.asarray(times, dtype=float)
    off = float(np.median(ref_times - et[nearest_index(et, ref_times)]))
    match = float("nan")
    if times is not None and planets is not None:
        pl = np.asarray(planets)
        true_lab = np.asarray(ev.planet)[nearest_index(et, ref_times - off)] - 1
        ok = pl >= 0
        match = float(np.mean(true_lab[ok] == pl[ok])) if np.any(ok) else float("nan")
    g = truth.config["gearset"]
    sp = Speeds(**truth.config["speeds"])
    z = g["z_sun"] if table.gauge == "sun" else g["z_ring"]
    w = abs(sp.w_sc if table.gauge == "sun" else sp.w_rc)
    tau = np.asarray(ev.tau, dtype=float)
    i_n = nearest_index(et, table.time - off)
    i_1 = nearest_index(et, table.ref_time - off)
    true = np.mod(z * w * (tau[i_n] - tau[i_1]) / TWO_PI, 1.0)
    err = wrap(table.gamma - true)
    sig = np.asarray(table.uncertainty, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        zs = err / sig
    fin = np.isfinite(zs)
    floor = np.asarray(table.timing_floor, dtype=float)
    ff = floor[np.isfinite(floor)]
    return {"n": int(err.size), "rms": float(np.sqrt(np.mean(err ** 2))),
            "max_abs": float(np.max(np.abs(err))), "label_match": match,
            "onset_offset_s": off,
            "z_rms": float(np.sqrt(np.mean(zs[fin] ** 2))) if fin.any() else float("nan"),
            "coverage95": float(np.mean(np.abs(zs[fin]) <= 1.96)) if fin.any() else float("nan"),
            "floor_rms": float(np.sqrt(np.mean(ff ** 2))) if ff.size else float("nan"),
            "errors": err}
