"""Whether each main gauge's passes come as often as its gear's should.

A gauge on one tooth of the sun sees a pulse each time a planet passes it: N per turn of the
sun relative to the carrier; a gauge on the ring, N per turn of the ring relative to the
carrier. Every mesh of the gearset runs at one mesh frequency f_m, so these rates are
``N f_m / Z_s`` and ``N f_m / Z_r`` whatever the speed: a sun gauge's passes come
``Z_r / Z_s`` times as often as a ring gauge's (3.48 on the seed rig, 25/87/29). Measured
against that, and against the typed speeds when there are some, the pass rates catch what the
phasing's own diagnostics only see as scatter: the sun and ring channels swapped in the scene
(on the independent rig: both gears' phasing 27-29x their floor, flagged only as "not
reliable"), a gauge given the other gear's kind, speeds typed far from the rig's.

:func:`wiring_findings` checks every gauge channel, not only each gear's main one, and
names the channel and the fix: a gauge whose rate is the other gear's (its kind is wrong), two
channels of one kind whose rates disagree (e.g. a glob that mapped the ring gauge as a second
sun gauge: its passes feed the angle model and the phasing scatters), a channel whose passes
come once per carrier turn (the tacho mapped as a gauge). The phasing stage makes each
finding a reason of the gear's phasing being unreliable, so the run's status names it.

The measured rate is one over the median interval between passes, so missing pulses and gaps
(fewer than half the intervals) and unequal planet spacing (intervals within a factor
:data:`RATE_TOLERANCE` of each other) do not move it enough to matter.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["RATE_TOLERANCE", "measured_pass_rate", "expected_pass_rates", "pass_rate_warnings",
           "wiring_findings", "two_level_train", "TWO_LEVEL_SPREAD"]

#: a channel whose samples above and below half its range each spread less than this share of
#: the gap between the two levels, with fewer samples between the levels than this share of
#: those at the high one, is a two-level pulse train (a tacho) [-]: a TTL tacho with 5 mV of
#: noise on 5 V spreads 0.001, a tooth-root pulse train 0.15-0.3 (its tops are round)
TWO_LEVEL_SPREAD = 0.05

#: a measured pass rate within this factor of the expected one agrees with it [-]; the
#: sun's and the ring's rates differ by Z_r / Z_s > 2, so this never accepts the other gear
RATE_TOLERANCE = 1.5


def measured_pass_rate(times) -> float:
    """Passes per second of one gauge [Hz]: one over the median interval; NaN with fewer
    than three finite pass times.

    Parameters
    ----------
    times : array_like
        Pass times [s].
    """
    t = np.asarray(times, dtype=float).ravel()
    t = np.sort(t[np.isfinite(t)])
    if t.size < 3:
        return float("nan")
    dt = float(np.median(np.diff(t)))
    return 1.0 / dt if dt > 0 else float("nan")


def expected_pass_rates(gearset, speeds) -> dict:
    """Passes per second of a gauge on each gear at the typed speeds [Hz]: N |w_sc| / 2 pi
    for the sun, N |w_rc| / 2 pi for the ring; a gear standing still relative to the carrier
    is left out.

    Parameters
    ----------
    gearset : Gearset
    speeds : Speeds or None
        None: no expectation ({}).

    Returns
    -------
    dict of str to float
    """
    if speeds is None:
        return {}
    n = int(gearset.n_planets)
    out = {}
    for gear, w in (("sun", speeds.w_sc), ("ring", speeds.w_rc)):
        rate = n * abs(float(w)) / (2.0 * math.pi)
        if rate > 0 and math.isfinite(rate):
            out[gear] = rate
    return out


def _agrees(measured: float, expected: float) -> bool:
    return abs(math.log(measured / expected)) <= math.log(RATE_TOLERANCE)


def pass_rate_warnings(passes, gearset, speeds=None) -> list[str]:
    """What the main gauges' pass rates say is wrong with the scene: a message per finding,
    none when the rates agree.

    Parameters
    ----------
    passes : sequence of GaugePasses
        The gauges' usable passes (:func:`meshphase.kinematics.passes.gauge_passes`); the main gauge of
        each gear is checked.
    gearset : Gearset
    speeds : Speeds or None
        The typed (or recorded nominal) speeds, for the rate each gear's gauge should have.

    Returns
    -------
    list of str
    """
    if gearset is None or not hasattr(gearset, "z_sun"):
        raise TypeError(f"gearset must be a Gearset, got {type(gearset).__name__}")
    rates, names = {}, {}
    for p in passes:
        if getattr(p, "main", False) and p.gear in ("sun", "ring") and p.gear not in rates:
            r = measured_pass_rate(p.times)
            if math.isfinite(r):
                rates[p.gear], names[p.gear] = r, p.name
    ratio = gearset.z_ring / gearset.z_sun
    out = []
    if len(rates) == 2:
        seen = rates["sun"] / rates["ring"]
        if not _agrees(seen, ratio) and abs(math.log(seen * ratio)) < abs(math.log(seen / ratio)):
            return [f"the sun and ring channels look swapped: the passes of {names['sun']!r} "
                    f"(kind sun) come {seen:.3g}x as often as those of {names['ring']!r} (kind "
                    f"ring), where a sun gauge's come Z_r / Z_s = {ratio:.3g}x as often as a "
                    "ring gauge's at any speed; check the channels' kind in the scene"]
    expected = expected_pass_rates(gearset, speeds)
    off = {g: r / expected[g] for g, r in rates.items() if g in expected and not _agrees(r, expected[g])}
    if len(off) == 2 and abs(math.log(off["sun"] / off["ring"])) < math.log(1.1):
        k = math.sqrt(off["sun"] * off["ring"])
        return [f"the typed speeds look {1.0 / k:.3g}x the rig's: both gauges' passes come "
                f"{k:.3g}x as often as they give (sun {rates['sun']:.4g} Hz for "
                f"{expected['sun']:.4g}, ring {rates['ring']:.4g} Hz for {expected['ring']:.4g}); "
                "the phasing follows the passes, but the held member and the planets' names "
                "rest on the typed speeds"]
    for gear, r in rates.items():
        e = expected.get(gear)
        if e is None or _agrees(r, e):
            continue
        other = "ring" if gear == "sun" else "sun"
        hint = (f"they match a {other} gauge's ({expected[other]:.4g} Hz): is the channel's kind "
                f"{other}?" if other in expected and _agrees(r, expected[other]) else
                "check the typed speeds, the planet count and the channel's kind")
        out.append(f"{gear} gauge {names[gear]!r}: its passes come at {r:.4g} Hz where the "
                   f"typed speeds give {e:.4g} Hz ({gearset.n_planets} planets x the {gear}'s "
                   f"speed relative to the carrier); {hint}")
    return out


def _carrier_rate(speeds, tacho_times) -> float:
    """Carrier turns per second [Hz]: from the tacho's pulses (one per turn), else from the
    speeds; NaN when neither gives one."""
    r = measured_pass_rate(tacho_times) if tacho_times is not None else float("nan")
    if not math.isfinite(r) and speeds is not None:
        r = abs(float(speeds.carrier)) / (2.0 * math.pi)
    return r if r > 0 else float("nan")


def _gear_of_rate(rate: float, expected: dict) -> str | None:
    """The gear whose expected pass rate ``rate`` agrees with, if exactly one."""
    hits = [g for g, e in expected.items() if _agrees(rate, e)]
    return hits[0] if len(hits) == 1 else None


def two_level_train(x) -> tuple[float, float] | None:
    """The (low, high) levels of a two-level pulse train such as a tacho's, or None.

    Parameters
    ----------
    x : array_like, shape (n,)
        Raw samples of one channel [its units]; non-finite ones are ignored.

    Returns
    -------
    (float, float) or None
        The means of the samples below and above half the range [its units] when each group
        spreads less than :data:`TWO_LEVEL_SPREAD` of the gap between them and fewer than
        that share of the high group's samples lie in the middle half of the range; None
        otherwise, or with fewer than 3 samples in either group.
    """
    x = np.asarray(x, dtype=float).ravel()
    x = x[np.isfinite(x)]
    if x.size < 6:
        return None
    # the test is scale-free: work on samples scaled to at most 1 in magnitude, so no sample
    # size (1e300 or subnormal) overflows the range or the spreads
    scale = float(np.max(np.abs(x)))
    if not 0.0 < scale < math.inf:
        return None
    x = x / scale
    lo, hi = float(x.min()), float(x.max())
    if not hi > lo:
        return None
    high = x >= 0.5 * (lo + hi)
    a, b = x[~high], x[high]
    if a.size < 3 or b.size < 3:
        return None
    gap = float(b.mean() - a.mean())
    middle = np.count_nonzero(np.abs(x - 0.5 * (lo + hi)) < 0.25 * (hi - lo))
    if max(float(a.std()), float(b.std())) < TWO_LEVEL_SPREAD * gap and middle < TWO_LEVEL_SPREAD * b.size:
        return float(a.mean()) * scale, float(b.mean()) * scale
    return None


def wiring_findings(passes, gearset, speeds=None, tacho_times=None, pulse_trains=None) -> dict:
    """Gauge channels wired or mapped as the wrong kind, from their own pass rates.

    Parameters
    ----------
    passes : sequence of GaugePasses
        Every gauge channel's usable passes (:func:`meshphase.kinematics.passes.gauge_passes`).
    gearset : Gearset
    speeds : Speeds or None
        Typed (or recorded nominal) speeds: each gear's expected pass rate.
    tacho_times : array_like, optional
        The tacho's pulse times [s] (one per carrier turn).
    pulse_trains : dict of str to (str, float, float), optional
        Gauge channels whose samples are a two-level pulse train (:func:`two_level_train`):
        channel -> (its gear, low level, high level).

    Returns
    -------
    dict of str to list of str
        Gear -> findings, each naming the channel, what its rate says and the fix; empty
        when every gauge's rate agrees with its gear's (or nothing can be said).
    """
    if gearset is None or not hasattr(gearset, "z_sun"):
        raise TypeError(f"gearset must be a Gearset, got {type(gearset).__name__}")
    chans = [(p.name, p.gear, measured_pass_rate(p.times)) for p in passes
             if getattr(p, "gear", None) in ("sun", "ring")]
    chans = [c for c in chans if math.isfinite(c[2])]
    expected = expected_pass_rates(gearset, speeds)
    f_c = _carrier_rate(speeds, tacho_times)
    ratio = gearset.z_ring / gearset.z_sun
    out: dict = {}
    said = set()

    def add(gear, name, text):
        if name not in said:
            said.add(name)
            out.setdefault(gear, []).append(text)

    for name, (gear, lo, hi) in (pulse_trains or {}).items():
        add(gear, name, f"channel {name!r} (kind {gear}) is a two-level pulse train (its samples "
            f"sit at {lo:.4g} and {hi:.4g}), as a tacho's are, not a gauge's pulses: is it the "
            f'tacho? map it with kind = "tacho" and the {gear} gauge\'s channel with kind = "{gear}"')
    for name, gear, r in chans:       # once per carrier turn: the tacho mapped as a gauge
        if math.isfinite(f_c) and _agrees(r, f_c) and not (gear in expected and _agrees(r, expected[gear])):
            add(gear, name, f"channel {name!r} (kind {gear}): its passes come once per carrier turn "
                f"({r:.4g} Hz, the carrier's {f_c:.4g} Hz), as a tacho's do: is it the tacho? "
                f'map it with kind = "tacho" and the {gear} gauge\'s channel with kind = "{gear}"')
    for name, gear, r in chans:       # the other gear's rate
        e = expected.get(gear)
        other = "ring" if gear == "sun" else "sun"
        if e is not None and not _agrees(r, e) and _gear_of_rate(r, expected) == other:
            add(gear, name, f"channel {name!r} (kind {gear}): its passes come at {r:.4g} Hz, a "
                f"{other} gauge's rate ({expected[other]:.4g} Hz at the typed speeds), not a {gear} "
                f"gauge's ({e:.4g} Hz): it is wired or mapped as the wrong gear; give it kind = "
                f'"{other}" in the scene\'s [[channels]]')
    for gear in ("sun", "ring"):       # two channels of one kind that disagree
        mine = [(n, r) for n, g, r in chans if g == gear and n not in said]
        if len(mine) < 2:
            continue
        ref_n, ref_r = max(mine, key=lambda c: sum(_agrees(c[1], o[1]) for o in mine))
        for n, r in mine:
            if n == ref_n or _agrees(r, ref_r):
                continue
            seen = r / ref_r
            hint = ("its rate is a ring gauge's" if _agrees(seen, 1.0 / ratio) else
                    "its rate is a sun gauge's" if _agrees(seen, ratio) else
                    "its rate matches neither gear")
            add(gear, n, f"channels {ref_n!r} and {n!r} are both mapped as {gear} gauges but their "
                f"passes come at {ref_r:.4g} and {r:.4g} Hz ({seen:.3g}x; a sun gauge's come Z_r / "
                f"Z_s = {ratio:.3g}x as often as a ring gauge's): {hint}; map each channel with "
                "its own kind (narrow the glob or regex of the scene's [[channels]])")
    return out
