"""What a synthetic recording's truth tells a run (:mod:`synthetic`: the generator keeps it).

The true shaft hole errors (:func:`true_errors`, for the identification's check), the tacho
geometry the generator used when neither the scene nor the file states it
(:func:`tacho_geometry`), and the measured phasing scored pass by pass against the true one
(:func:`phasing_vs_truth`). A recording from a file has no truth: the run never needs one.
"""

from __future__ import annotations

from meshphase.compare.predict import truth_comparison
from meshphase.kinematics.phasing import GaugeLabels, PassTable

__all__ = ["true_errors", "tacho_geometry", "phasing_vs_truth"]


def _check_truth(truth) -> None:
    if truth is None or not hasattr(truth, "config"):
        raise TypeError(f"truth must be a synthetic truth (meshphase.synthetic.generate), got {type(truth).__name__}")


def true_errors(truth):
    """The shaft hole errors the generator put in (ShaftHoleErrors), None when its truth
    has none (a scenario without errors) or there is no truth."""
    if truth is None or getattr(truth, "errors", None) is None:
        return None
    if isinstance(truth.errors, dict):
        from meshphase.synthetic.config import errors_from_dict  # the generator: optional for the core

        return errors_from_dict(truth.errors)
    return truth.errors


def tacho_geometry(truth) -> tuple:
    """(key angle [rad] or None, {gauge channel: ground angle [rad]}) of the generator.

    Its key reaches the probe at carrier angle ``cfg.tacho_angle()``, so the edge fires at
    theta_c = -key_angle; a held member's gauge sits still, its direction at t = 0 is its
    ground angle. The key angle is None without a tacho in the configuration.
    """
    _check_truth(truth)
    from meshphase.synthetic.config import SynthConfig  # the generator: optional for the core

    cfg = SynthConfig.from_dict(truth.config)
    key = -cfg.tacho_angle() if cfg.tacho is not None else None
    return key, {g.name: cfg.tooth_angle(g) for g in cfg.gauges}


def phasing_vs_truth(table: PassTable, labels: GaugeLabels | None, truth) -> dict | None:
    """A gauge's measured phasing against the truth, pass by pass
    (:func:`meshphase.compare.predict.truth_comparison` with the labels the phasing used); None
    without labels."""
    _check_truth(truth)
    if labels is None:
        return None
    if not isinstance(labels, GaugeLabels):
        raise TypeError(f"labels must be GaugeLabels (meshphase.kinematics.phasing), got {type(labels).__name__}")
    return truth_comparison(table, truth, labels.channel, times=labels.times, planets=labels.planet)
