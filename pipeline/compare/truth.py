"""What a generated recording's truth tells a run, through the :class:`RecordingTruth` protocol.

A generator (:mod:`meshphase.synthetic`: its ``GroundTruth``) keeps the truth of what it
generated; a run asks it for the true shaft hole errors (:func:`true_errors`, for the
identification's check), the tacho geometry the generator used when neither the scene nor
the file states it (:func:`tacho_geometry`), and scores the measured phasing pass by pass
against the true one (:func:`phasing_vs_truth`). A recording from a file has no truth: the
run never needs one.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

from .predict import truth_comparison
from ..kinematics.phasing import GaugeLabels, PassTable
from ..models.mesh_phasing import ShaftHoleErrors

__all__ = ["RecordingTruth", "true_errors", "tacho_geometry", "phasing_vs_truth"]


@runtime_checkable
class RecordingTruth(Protocol):
    """What a comparison needs of a generated recording's truth.

    Attributes
    ----------
    config : dict
        The generator's configuration: at least ``gearset`` (``z_sun``, ``z_ring``) and
        ``speeds`` (the :class:`meshphase.models.gearset.Speeds` fields).
    events : dict
        Per gauge channel its engagements: ``time`` [s], ``tau`` (angle time) [s] and
        ``planet`` (1-based) arrays (:func:`meshphase.compare.predict.truth_comparison`).
    """

    config: dict
    events: dict

    def shaft_hole_errors(self) -> ShaftHoleErrors | None:
        """The shaft hole errors the generator put in, None without."""

    def tacho_geometry(self) -> tuple:
        """(key angle [rad] or None without a tacho, {gauge channel: ground angle [rad]})."""


def _check_truth(truth) -> None:
    if not isinstance(truth, RecordingTruth):
        raise TypeError(f"truth must be a synthetic truth (a RecordingTruth, e.g. of "
                        f"meshphase.synthetic.generate), got {type(truth).__name__}")


def true_errors(truth: RecordingTruth | None) -> ShaftHoleErrors | None:
    """The shaft hole errors the generator put in, None when its truth has none (a scenario
    without errors) or there is no truth (``truth`` None)."""
    if truth is None:
        return None
    _check_truth(truth)
    return truth.shaft_hole_errors()


def tacho_geometry(truth: RecordingTruth) -> tuple:
    """(key angle [rad] or None, {gauge channel: ground angle [rad]}) of the generator.

    Its key reaches the probe at the carrier angle of the tacho, so the edge fires at
    theta_c = -key_angle; a held member's gauge sits still, its direction at t = 0 is its
    ground angle. The key angle is None without a tacho in the configuration.
    """
    _check_truth(truth)
    return truth.tacho_geometry()


def phasing_vs_truth(table: PassTable, labels: GaugeLabels | None, truth: RecordingTruth) -> dict | None:
    """A gauge's measured phasing against the truth, pass by pass
    (:func:`meshphase.compare.predict.truth_comparison` with the labels the phasing used); None
    without labels."""
    _check_truth(truth)
    if labels is None:
        return None
    if not isinstance(labels, GaugeLabels):
        raise TypeError(f"labels must be GaugeLabels (meshphase.kinematics.phasing), got {type(labels).__name__}")
    return truth_comparison(table, truth, labels.channel, times=labels.times, planets=labels.planet)
