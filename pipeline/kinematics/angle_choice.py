"""Model choice: the models that explain the passes about as well as the chosen one.

The selected order is one choice among models that may explain the passes about as well.
The neighbours of the chosen model (one step less of each term taken, the best term turned
down, a common speed ripple at the planet spin rate) are refitted; each within ``BIC_CLOSE``
of the chosen BIC (or below it) is a :class:`Competitor` with its posterior weight, and the
weighted spread of the phasing over them joins the uncertainty
(:meth:`meshphase.kinematics.angles.AngleModel.choice_spread`), so nothing rests on a BIC
gain of 2 alone. A common planet-rate ripple and equal terms on every planet can be the very
same columns over the trains fitted (a gauge on a gear whose Z / Z_p is an integer, a carrier
tacho: every pass meets each planet at one spin angle); a rank test in both orders finds that
from the data, the two explanations are kept as an inseparable pair, and a train that meets
the planet spin at other angles (a shaft encoder) makes the columns independent, which
clears the pair.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from .angle_design import Design, ModelFit, ModelSpec, extend_theta, rank_keep, solve
from .angle_selection import ripple_rates
from .shafts import Kinematics

__all__ = ["Competitor", "model_competitors", "BIC_CLOSE", "INSEPARABLE_RIPPLE"]


@dataclass
class Competitor:
    """A model of the same passes that explains them about as well as the chosen one.

    Attributes
    ----------
    words : str
        What it explains the passes by, in a rig engineer's words.
    versus : str
        What the chosen model explains them by instead.
    terms : str
        Its model order, as :attr:`meshphase.kinematics.angles.AngleModel.terms` gives the chosen one's.
    delta_bic : float
        Its BIC less the chosen model's [-] (weights from the timing bounds alone, as in the
        selection; negative: the data prefer it).
    weight : float
        Its posterior weight [-] (exp(-BIC / 2), normalised over the chosen model and its
        competitors); NaN when ``inseparable``.
    inseparable : bool
        The trains fitted cannot tell it from the chosen model at all: its extra column lies
        in the span of the chosen model's columns (the fit is the same, the angle is not).
    ripple_bound : float
        For a speed ripple at the planet spin rate: how far every 1 % of it can move a
        phasing value [mesh cycles] (P / (100 pi), P mesh cycles per planet turn); else NaN.
    fit : ModelFit
        Its fit, on the chosen model's design.
    turned : ModelFit or None
        For an inseparable competitor: its move away from the chosen model turned a quarter
        period in phase (every phase of the common term the two split differently); else None.
    """

    words: str
    versus: str
    terms: str
    delta_bic: float
    weight: float
    inseparable: bool
    ripple_bound: float = float("nan")
    fit: ModelFit = field(default=None, repr=False)
    turned: ModelFit = field(default=None, repr=False)


#: a competing model within this BIC of the chosen one (posterior weight at least exp(-3),
#: 5 % of the chosen model's: below "positive evidence" against it, Kass & Raftery 1995,
#: counted twice over) joins the phasing's uncertainty [-]
BIC_CLOSE = 6.0


#: a common term at the planet spin period that the trains cannot place (ripple or planet
#: terms) stays with the planet terms while it moves the phasing by no more than a common
#: speed ripple of this relative amplitude at the planet spin rate could [-]: ordinary shaft
#: hole offsets reach about that (the seed rig's 0.2 mm of Table 2 case 1 on every planet:
#: 0.005-0.010 mesh cycles, 0.1 % of ripple's worth; a 1 % planet-rate ripple: 0.05-0.08)
INSEPARABLE_RIPPLE = 0.002


_SHAFT_WORDS = {"carrier": "carrier", "sun": "sun", "ring": "ring", "planet": "planet spin"}


def _order_words(spec: ModelSpec, base: ModelSpec) -> str:
    """What ``spec`` explains the passes by where it differs from ``base``, in words."""
    parts = []
    if spec.knots != base.knots:
        parts.append(f"a speed drift of {spec.knots} spline interval(s) (not {base.knots})")
    for r in [r for r in _SHAFT_WORDS if r in spec.harm or r in base.harm]:
        h, h0 = spec.harm.get(r, 0), base.harm.get(r, 0)
        w = _SHAFT_WORDS[r]
        if h > h0:
            parts.append(f"a speed ripple at the {w} rate to harmonic {h}"
                         + (f" (not {h0})" if h0 else ""))
        elif h < h0:
            parts.append(f"the speed ripple at the {w} rate to harmonic {h} only (not {h0})"
                         if h else f"no speed ripple at the {w} rate")
        elif h and spec.mod.get(r, False) != base.mod.get(r, False):
            parts.append(f"a {w}-rate ripple whose size changes over the record"
                         if spec.mod.get(r) else f"a {w}-rate ripple of constant size")
    if spec.sig > base.sig:
        parts.append(f"planet shaft-hole errors to harmonic {spec.sig}")
    elif spec.sig < base.sig:
        parts.append(f"planet shaft-hole errors to harmonic {spec.sig} only" if spec.sig
                     else "no planet shaft-hole errors")
    return " and ".join(parts) or spec.describe()


def _quarter_turn(th0: np.ndarray, fit: ModelFit) -> np.ndarray:
    """``fit``'s parameters with its move away from ``th0`` (same layout) turned a quarter
    period in phase in every ripple and planet-term harmonic (each (cos, sin) pair (a, b)
    becomes (-b, a)), the other parameters at ``th0``.

    Moving a common term from the planet terms into a ripple at the same period is a move
    along the columns' common direction, for either phase of that term: the quarter-turned
    move is as invisible to the data as the move itself, and the two together span every
    phase of a common term of that size."""
    out = th0.copy()
    dl = fit.theta - th0
    for key, sl in fit.lay["blocks"].items():
        if key.startswith(("rip:", "mod:")) or key == "sig":
            pairs = dl[sl].reshape(-1, 2)
            out[sl] = th0[sl] + np.column_stack([-pairs[:, 1], pairs[:, 0]]).ravel()
    return out


def model_competitors(d: Design, spec: ModelSpec, fit: ModelFit, rejected: list,
                 kin: Kinematics) -> tuple[ModelFit, list]:
    """The chosen model refitted with the selection's weights (timing bounds alone), and the
    models that explain the passes about as well: (reference fit, list of Competitor).

    Tried: one step less of each term the selection took (a ripple harmonic, its amplitude
    modulation, a planet-term harmonic), the best term it turned down, and a common speed
    ripple at the planet spin rate next to the planet terms. The last is judged by rank
    first: where its columns lie in the span of the planet terms over the trains actually
    fitted (the two rank orders of :attr:`ModelSpec.first` keep different columns), the data
    cannot tell a common planet-rate ripple from equal terms on every planet, and both
    explanations are kept as inseparable competitors; a train that sees the ripple apart
    from the planets (a shaft encoder) makes the columns independent and the test clears.
    Every other competitor counts when its BIC is within ``BIC_CLOSE`` of the chosen one's
    (or below it), with its posterior weight.
    """
    ones = np.ones(len(d.trains))
    rows = np.flatnonzero(d.active)
    ref = solve(d, spec, fit.theta, ones, keep=fit.keep, recheck=False)
    versus = f"the chosen model ({spec.describe()})"
    cands: list = []
    for r, h in spec.harm.items():
        if h:
            s2 = spec.copy()
            s2.harm[r] = h - 1
            s2.mod[r] = s2.mod.get(r, False) and h > 1
            cands.append(s2)
            if spec.mod.get(r) and h > 1:
                s3 = spec.copy()
                s3.mod[r] = False
                cands.append(s3)
    if spec.sig:
        s2 = spec.copy()
        s2.sig -= 1
        cands.append(s2)
    cands.extend(rejected)
    found: list = []
    bound = float("nan")
    if kin.planet_period and "planet" in ripple_rates(d, kin, True, []):
        bound = 0.01 * float(kin.planet_period) / math.pi
        s_r = spec.copy()
        s_r.harm["planet"] = max(spec.harm.get("planet", 0), spec.sig, 1)
        s_r.mod.setdefault("planet", False)
        s_r.first = "ripple"
        s_p = s_r.copy()
        s_p.first = "planet"
        th = extend_theta(ref, s_r, d)
        k_r = rank_keep(d, th, d.layout(s_r), s_r, rows)
        k_p = rank_keep(d, th, d.layout(s_p), s_p, rows)
        if not np.array_equal(k_r, k_p):
            # both ends of the split; the one that moves the angle from the chosen model is
            # the competitor (the other is the chosen model itself, the same columns kept)
            pair = []
            for s2, k2, words, vs in ((s_r, k_r, "a common speed ripple at the planet spin rate",
                                       "equal shaft-hole errors on every planet"),
                                      (s_p, k_p, "equal shaft-hole errors on every planet",
                                       "a common speed ripple at the planet spin rate")):
                f2 = solve(d, s2, np.where(k2, th, 0.0), ones, keep=k2, recheck=False)
                moved = (d.a_part(f2.theta, f2.lay, s2, d.t)[0]
                         - d.a_part(ref.theta, ref.lay, spec, d.t)[0])
                pair.append((float(np.ptp(moved)),
                             Competitor(words, vs, s2.describe(), f2.bic() - ref.bic(),
                                        float("nan"), True, bound, f2,
                                        replace(f2, theta=_quarter_turn(th, f2)))))
            found.append(max(pair, key=lambda x: x[0])[1])
        elif s_r.harm["planet"] != spec.harm.get("planet", 0):
            cands.append(s_r)
    seen = set()
    weighed = []
    for c in cands:
        key = (c.knots, tuple(sorted(c.harm.items())), tuple(sorted(c.mod.items())), c.sig)
        if key in seen:
            continue
        seen.add(key)
        # a ripple column that only duplicates the planet terms (a carrier harmonic at the
        # planet spin period) is the inseparable pair's business, not a second opinion here
        c = c.copy()
        c.first = "planet"
        f2 = solve(d, c, extend_theta(ref, c, d), ones)
        db = f2.bic() - ref.bic()
        if db <= BIC_CLOSE:
            planet = c.harm.get("planet", 0) > spec.harm.get("planet", 0)
            weighed.append(Competitor(_order_words(c, spec), versus, c.describe(), db,
                                      float("nan"), False, bound if planet else float("nan"), f2))
    if weighed:
        dbs = np.array([0.0] + [c.delta_bic for c in weighed])
        w = np.exp(-0.5 * (dbs - dbs.min()))
        w /= w.sum()
        for c, wi in zip(weighed, w[1:]):
            c.weight = float(wi)
    return ref, found + weighed
