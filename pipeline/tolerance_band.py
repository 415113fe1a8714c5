"""The tolerance band of the measured phasing: where each planet's deviation from the ideal
phasing may lie under the scene's tolerances, from the tolerance Monte Carlo.

One definition for the ``compare`` stage (band coverage of one recording's passes) and for a
campaign (the band computed once on the client, passed to every recording's task).
"""

from __future__ import annotations

__all__ = ["phasing_band", "GAUGES"]

#: gauges with a band: the sun gear's and the ring gear's
GAUGES = ("sun", "ring")


def phasing_band(mc, gear: str) -> tuple:
    """The 3-sigma band of ``gear``'s phasing deviation from the ideal, per planet [mesh cycles].

    ``(Ave bound3 low - Dev bound3 high / 2, Ave bound3 high + Dev bound3 high / 2)``: the
    3-sigma range of the planets' mean phasing, widened by half the 3-sigma upper bound of
    their pass-to-pass deviation on either side.

    Parameters
    ----------
    mc : pipeline.models.tolerance.MonteCarloResult
        The tolerance Monte Carlo (its ``ave_s``, ``dev_s``, ``ave_r``, ``dev_r`` statistics).
    gear : {"sun", "ring"}
        The gauged gear.

    Returns
    -------
    (lo, hi) : tuple of numpy.ndarray
        Lower and upper band edge per planet [mesh cycles].

    Raises
    ------
    ValueError
        ``gear`` is not "sun" or "ring".
    TypeError
        ``mc`` holds no Monte Carlo statistics.
    """
    if gear not in GAUGES:
        raise ValueError(f"gear must be one of {GAUGES}, got {gear!r}")
    try:
        ave, dev = (mc.ave_s, mc.dev_s) if gear == "sun" else (mc.ave_r, mc.dev_r)
    except AttributeError:
        raise TypeError(f"mc must be a tolerance Monte Carlo result (ave_s, dev_s, ave_r, dev_r), got "
                        f"{type(mc).__name__}") from None
    return ave.bound3[0] - dev.bound3[1] / 2, ave.bound3[1] + dev.bound3[1] / 2
