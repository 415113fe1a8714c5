"""Whether a gear's measured phasing can be trusted, and why not.

The verdict (:func:`phasing_reliability`) sets the per-pass error the angle model's own
diagnostics predict against the timing floor (``UNRELIABLE_RATIO``), and names the ripples
the trains cannot see, a train's systematic misfit (``UNRELIABLE_LAG1``), a fit that did not
converge, passes left out, and the competing angle models whose phasing differs by more than
the floor (:func:`choice_reasons`).
"""

from __future__ import annotations

import math

import numpy as np

from .angles import AngleModel
from .trains import PassTrain

__all__ = ["phasing_reliability", "choice_reasons", "UNRELIABLE_RATIO", "UNRELIABLE_LAG1",
           "INSEPARABLE_SHARE"]


#: the "not reliable" rule: the per-pass error the model's own diagnostics predict, against
#: the timing floor; a train's residual autocorrelation above this means systematic misfit
UNRELIABLE_RATIO = 3.0


UNRELIABLE_LAG1 = 0.6


#: the whole move between two explanations the data cannot tell apart over its RMS expected
#: share, sqrt(6): a split uniform in [0, 1] (1/3 of the square) of a term of uniform phase
#: (1/2 of it) [-]
INSEPARABLE_SHARE = math.sqrt(6.0)


def choice_reasons(competitors, floor: float, est: float) -> list:
    """Reasons of :func:`phasing_reliability` from the competing angle models of a gear's passes
    (:attr:`meshphase.kinematics.pass_table.PassTable.competitors`), in words: each counted inseparable one, and, when the
    estimated error ``est`` with the model choice in it passes ``UNRELIABLE_RATIO`` times the
    timing ``floor`` (the one rule of the verdict), each weighed one that moves the phasing
    by more than the floor [mesh cycles] (RMS over the passes)."""
    out = []
    known = math.isfinite(floor) and floor > 0
    weighed = known and math.isfinite(est) and est > UNRELIABLE_RATIO * floor
    named = set()
    for c in competitors:
        if c["inseparable"]:
            # counted ones only (above the floor and what hole errors give); without timing
            # bounds there is no floor to set against, and the count alone decides
            if not (c.get("counted", True) and (c["rms"] > floor or not known)):
                continue
        elif not (weighed and c["rms"] > floor):
            continue
        if c["inseparable"]:
            pair = frozenset((c["words"], c["versus"]))
            if pair in named:
                continue
            named.add(pair)
            bound = c.get("ripple_bound", float("nan"))
            out.append(f"{c['words']} and {c['versus']} explain these passes equally well (the "
                       "gauges, and tacho if any, see them as one and the same term) and their "
                       f"phasing differs by {c['rms']:.2g} mesh cycles (RMS over the passes"
                       + (f", {c['rms'] / floor:.0f}x the timing floor" if known else "")
                       + "); the uncertainty includes that difference"
                       + (f"; every 1 % of speed ripple at the planet spin rate can move the "
                          f"phasing by up to {bound:.2g} mesh cycles"
                          if math.isfinite(bound) else "")
                       + "; a shaft encoder on the sun (input) shaft would tell them apart")
        else:
            how = ("explains these passes about as well as" if c["delta_bic"] >= 0
                   else "explains these passes better than")
            out.append(f"{c['words']} {how} {c['versus']} (BIC difference "
                       f"{c['delta_bic']:+.1f}, posterior weight {c['weight']:.2f}) and their "
                       f"phasing differs by {c['rms']:.2g} mesh cycles (RMS over the passes, "
                       f"{c['rms'] / floor:.1f}x the timing floor); the uncertainty includes "
                       "that spread")
    return out


def phasing_reliability(model: AngleModel, train: PassTrain, tab, unseen=()) -> dict:
    """Whether a gear's phasing can be trusted, from the model's own residual diagnostics and
    what its trains can see.

    Parameters
    ----------
    model : AngleModel
        The recording's fitted angle model.
    train : PassTrain
        The gear's main gauge train (one of the model's trains).
    tab : meshphase.kinematics.pass_table.PassTable
        The gear's phasing read off ``model`` (its ``uncertainty``, ``timing_floor``,
        ``choice_sigma`` and ``competitors``).
    unseen : sequence of (str, float)
        Shafts whose speed ripple the trains cannot see and their mesh cycles per turn
        (:func:`meshphase.kinematics.angle_selection.unseen_ripples`).

    Returns
    -------
    dict
        ``reliable`` (bool), ``reasons`` (list of str, empty when reliable),
        ``error_estimate`` and ``floor`` (RMS estimated error and timing floor [mesh
        cycles]), the train's ``scale`` [-] and ``lag1`` [-].

    Raises
    ------
    KeyError
        ``train`` is not one of the model's trains.
    """
    reasons = []
    for shaft, period in unseen:
        # a relative ripple a moves A by a P / (2 pi) mesh cycles at most, and the phasing
        # between two planets (A at two carrier angles) by twice that
        reasons.append(f"a speed ripple locked to the {shaft} angle is not seen by the gauges "
                       f"and tacho (they meet the {shaft} at fixed angles only): the phasing "
                       f"assumes the {shaft} turns evenly, and every 1 % of such ripple (an "
                       f"ordinary drive's) can move it by up to {0.01 * period / math.pi:.2g} "
                       "mesh cycles")
    fit = model.train(train.name)
    est = float(np.sqrt(np.mean(tab.uncertainty ** 2))) if len(tab) else float("nan")
    floor = float(np.sqrt(np.mean(tab.timing_floor ** 2))) if len(tab) else float("nan")
    choice = tab.choice_sigma if tab.choice_sigma is not None else np.zeros(len(tab))
    reasons.extend(choice_reasons(tab.competitors, floor, est))
    # the scatter test judges the chosen model's own uncertainty (the model choice is above)
    within = float(np.sqrt(np.mean(np.maximum(tab.uncertainty ** 2 - choice ** 2, 0.0)))) \
        if len(tab) else float("nan")
    if math.isfinite(floor) and floor > 0 and within > UNRELIABLE_RATIO * floor:
        reasons.append(f"the passes scatter {fit.scale:.1f}x beyond their timing bound: "
                       f"estimated error {within:.2e} cycles is {within / floor:.1f}x the floor "
                       f"{floor:.2e}")
    if math.isfinite(fit.lag1) and fit.lag1 > UNRELIABLE_LAG1 and fit.n >= 20:
        reasons.append(f"residuals follow each other (lag-1 correlation {fit.lag1:.2f}): the "
                       "speed varies in a way the angle model does not follow")
    if not model.converged:
        reasons.append("the angle model did not converge")
    if fit.n and fit.n_outliers > 0.1 * (fit.n + fit.n_outliers):
        reasons.append(f"{fit.n_outliers} of {fit.n + fit.n_outliers} passes far off the model "
                       "(mislabelled or spurious pulses)")
    if len(tab) == 0:
        reasons.append("no pass could be measured")
    return {"reliable": not reasons, "reasons": reasons, "error_estimate": est, "floor": floor,
            "scale": fit.scale, "lag1": fit.lag1}
