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

The measured rate is one over the median interval between passes, so missing pulses and gaps
(fewer than half the intervals) and unequal planet spacing (intervals within a factor
:data:`RATE_TOLERANCE` of each other) do not move it enough to matter.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["RATE_TOLERANCE", "measured_pass_rate", "expected_pass_rates", "pass_rate_warnings"]

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
        The gauges' usable passes (:func:`meshphase.passes.gauge_passes`); the main gauge of
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
