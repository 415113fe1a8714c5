"""Typed results of the stages a scene runs: one frozen dataclass per stage.

:func:`meshphase.run.stages.run_scene` keeps them in its
:class:`meshphase.run.context.RunContext`, one attribute per stage (``ctx.load``, ``ctx.phasing``, ``ctx.compare``, ...; None for a stage
that did not run); :func:`meshphase.run.stages.summary_dict`, :func:`meshphase.run.stages.write_outputs`,
the HTML report and the run status read them there. Units are SI; phasing in mesh cycles [-].

The dataclasses are frozen (a stage's result is not changed by a later stage: a stage that
revises an earlier result, as the identification relabelling a gauge, returns the revised one
in :meth:`StageResult.supersedes`); the arrays and dicts they hold are not copied.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["StageResult", "LoadStage", "ConditionStage", "OnsetsStage", "PhasingStage",
           "LoadSharingStage", "CentroidsStage", "IdealStage", "ToleranceStage",
           "IdentifyStage", "GaugeComparison", "CompareStage", "BearingStage", "TiltStage"]


@dataclass(frozen=True, kw_only=True)
class StageResult:
    """What every stage result carries.

    Attributes
    ----------
    error_estimate : str
        The stage's error estimate in words (what "error against run time" lists).
    """

    error_estimate: str = ""


    def supersedes(self) -> dict:
        """Results of earlier stages this one revises: stage name -> its new result."""
        return {}


# ----------------------------------------------------------------------------- the recording
@dataclass(frozen=True, kw_only=True)
class LoadStage(StageResult):
    """The recording opened and its raw samples scanned (``load`` stage).

    Attributes
    ----------
    recording : Recording or StreamedRecording
        The recording's header (channels, fs [Hz], t0 [s], metadata); a file's samples are
        not held, the later stages stream them again from ``stream``.
    source : str
        The file path, or ``synthetic:<scenario>``.
    quality : list of dict
        Raw-sample quality per channel (:meth:`meshphase.recording.Recording.quality`).
    truth : meshphase.synthetic.truth.Truth or None
        The generator's truth for a synthetic input.
    true_errors : ShaftHoleErrors or None
        The shaft hole errors of that truth.
    stream : meshphase.run.stream.BlockSource or None
        Where the samples come from for each pass.
    scan : meshphase.run.stream.RawScan or None
        What the scan found (tacho edges, hum windows, quality: one read, :func:`meshphase.run.stream.scan_source`).
    channels_unused : tuple of str
        Channels no planned stage reads.
    pulse_trains : dict of str to (str, float, float)
        Gauge channels whose raw samples are a two-level pulse train, as a tacho's: channel
        -> (gear, low level, high level) (:func:`meshphase.kinematics.pass_rates.two_level_train`).
    """

    recording: Any
    source: str
    quality: list
    truth: Any = None
    true_errors: Any = None
    stream: Any = None
    scan: Any = None
    channels_unused: tuple = ()
    pulse_trains: dict = field(default_factory=dict)


@dataclass(frozen=True, kw_only=True)
class ConditionStage(StageResult):
    """The channels conditioned and the gauges' pulses timed in one streamed pass
    (``condition`` stage).

    Attributes
    ----------
    recording : StreamedRecording or Recording
        The conditioned recording's header.
    quality : dict of str to ChannelQuality
        Per conditioned channel (SNR [dB], hum, conditioned gap runs, noise RMS).
    excerpt : Recording or None
        The first minute of the conditioned channels (for the report's figure).
    onsets : dict of str to Onsets or None
        Onsets per gauge channel found in the pass (None: the onsets stage detects them).
    onset_warnings : list of (category, message)
        The detector's warnings, issued again by the onsets stage.
    timings : dict of str to float
        Seconds spent conditioning and detecting onsets [s].
    memory : dict of str to int
        Memory estimate of the pass [B].
    scan : meshphase.run.stream.RawScan or None
        The raw-sample scan the pass used (the load stage's, or one made here).
    """

    recording: Any
    quality: dict
    excerpt: Any = None
    onsets: dict | None = None
    onset_warnings: list = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    memory: dict = field(default_factory=dict)
    scan: Any = None


@dataclass(frozen=True, kw_only=True)
class OnsetsStage(StageResult):
    """Tooth-engagement onsets of every gauge channel (``onsets`` stage).

    Attributes
    ----------
    by_channel : dict of str to Onsets
        Per gauge channel, in the recording's channel order.
    tacho_times : ndarray or None
        Edge times of the first tacho channel [s].
    encoder_times : dict of str to ndarray
        Rising edge times of each encoder channel [s].
    """

    by_channel: dict
    tacho_times: np.ndarray | None = None
    encoder_times: dict = field(default_factory=dict)


# ----------------------------------------------------------------------------- measured
@dataclass(frozen=True, kw_only=True)
class PhasingStage(StageResult):
    """Measured mesh phasing per gauged gear (``phasing`` stage).

    Attributes
    ----------
    tables : dict of str to PassTable
        Per gear ("sun", "ring"): gamma per pass [-] with uncertainties; an empty table for a
        main gauge without a measurable pass.
    labels : dict of str to GaugeLabels
        Per gear: planet labels of its main gauge's pulses.
    model : AngleModel or None
        The angle model of the whole recording.
    reliability : dict of str to dict or None
        Per gear: ``reliable``, ``reasons``, ``error_estimate`` [-], ``floor`` [-], ...
        (None: not given, the run's messages decide, :func:`phasing_verdict`).
    fixed : {"ring", "sun", None}
        Held member; ``fixed_reason`` says how it was decided.
    fixed_reason : str
    labels_relative : list of str
        Gears whose planet 1 is only the first pulse seen.
    notes : list of str
    result : PhasingResult or None
        The whole measurement (trains, fractions) :func:`meshphase.kinematics.phasing.relabel_gauge`
        recomputes from.
    member_speeds : dict or None
        Every member's measured speed [r/min] and which is held
        (:func:`meshphase.kinematics.member_speeds.member_speeds`); None without an angle model.
    """

    tables: dict
    labels: dict = field(default_factory=dict)
    model: Any = None
    reliability: dict | None = None
    fixed: str | None = None
    fixed_reason: str = ""
    labels_relative: list = field(default_factory=list)
    notes: list = field(default_factory=list)
    result: Any = None
    member_speeds: dict | None = None


    @property
    def assignment(self) -> dict:
        """Per gear: ``shift_decided_by`` (what named planet 1), ``n_unassigned``,
        ``ambiguous`` (planet 1 is only the first pulse seen, or in doubt) and, when planet 1
        is in doubt, ``caution`` (why: :attr:`meshphase.kinematics.phasing.GaugeLabels.caution`)."""
        out = {}
        for k, v in self.labels.items():
            caution = getattr(v, "caution", "")
            out[k] = {"shift_decided_by": v.decided_by, "n_unassigned": v.n_unassigned,
                      "ambiguous": v.decided_by == "first pulse" or bool(caution),
                      **({"caution": caution} if caution else {})}
        return out

    def relabelled(self, gear: str, table, labels) -> "PhasingStage":
        """This result with ``gear``'s table and labels replaced (a gauge relabelled
        cyclically, :func:`meshphase.kinematics.phasing.relabel_gauge`); the gear's labels are then no
        longer relative."""
        tables = {**self.tables, gear: table}
        labs = {**self.labels, gear: labels}
        result = self.result
        if result is not None:
            result = dataclasses.replace(result, tables={**result.tables, gear: table},
                                         labels={**result.labels, gear: labels})
        return dataclasses.replace(self, tables=tables, labels=labs, result=result,
                                   labels_relative=[g for g in self.labels_relative if g != gear])


@dataclass(frozen=True, kw_only=True)
class LoadSharingStage(StageResult):
    """Planet load sharing from the ring gauge's pulse amplitudes (``load_sharing`` stage).

    Attributes
    ----------
    sharing : LoadSharingResult or None
        Factors per planet [-]; None without a ring gauge.
    channel : str or None
        The ring gauge read.
    """

    sharing: Any = None
    channel: str | None = None


@dataclass(frozen=True, kw_only=True)
class CentroidsStage(StageResult):
    """Face-width load centroids (``centroids`` stage).

    Attributes
    ----------
    by_gear : dict of str to CentroidResult or None
        Per gear with face-width gauges: Z [m] and its standard error [m]; None where it has
        fewer than two positioned gauges or no face width.
    """

    by_gear: dict = field(default_factory=dict)


# ----------------------------------------------------------------------------- models
@dataclass(frozen=True, kw_only=True)
class IdealStage(StageResult):
    """Ideal mesh phasing of the gearset (``ideal`` stage, Parker & Lin 2004).

    Attributes
    ----------
    gamma_s, gamma_r : ndarray, shape (N,)
        Sun-planet and ring-planet phasing of each planet relative to planet 1 [-].
    classification : str
        "in-phase", "sequential", "counter-phase" or "mixed".
    assembly : AssemblyCheck
    """

    gamma_s: np.ndarray
    gamma_r: np.ndarray
    classification: str
    assembly: Any = None


    def gamma(self, gear: str) -> np.ndarray:
        """The ideal phasing of ``gear`` ("sun" or "ring") [-]."""
        return self.gamma_s if gear == "sun" else self.gamma_r


@dataclass(frozen=True, kw_only=True)
class ToleranceStage(StageResult):
    """Monte Carlo phasing statistics under the scene's tolerances (``tolerance`` stage).

    Attributes
    ----------
    monte_carlo : MonteCarloResult
    """

    monte_carlo: Any


    def band(self, gear: str) -> tuple[np.ndarray, np.ndarray]:
        """The 3-sigma band of ``gear``'s phasing deviation from the ideal per planet [mesh
        cycles] (:meth:`meshphase.models.tolerance.MonteCarloResult.phasing_band`)."""
        return self.monte_carlo.phasing_band(gear)


@dataclass(frozen=True, kw_only=True)
class IdentifyStage(StageResult):
    """Shaft hole errors identified from the measured phasing (``identify`` stage).

    Attributes
    ----------
    identification : meshphase.compare.predict.Identification
    relabelled : tuple of (str, int)
        Gears whose relative planet labels the identification moved, with the shift [places].
    phasing : PhasingStage or None
        The phasing with those gears relabelled (None: unchanged); it supersedes the phasing
        stage's result.
    """

    identification: Any
    relabelled: tuple = ()
    phasing: PhasingStage | None = None

    def supersedes(self) -> dict:
        return {} if self.phasing is None else {"phasing": self.phasing}


@dataclass(frozen=True, kw_only=True)
class GaugeComparison:
    """One gauge's measured phasing against the models.

    Attributes
    ----------
    ideal : ndarray, shape (n,)
        Ideal phasing at each pass [-].
    model : ndarray, shape (n,) or None
        The identified error model's phasing at each pass [-] (None: no identification).
    vs_ideal, vs_model : dict or None
        :func:`meshphase.compare.predict.residual_stats` of the passes against them [-].
    band : dict or None
        ``lo``, ``hi``: the Monte Carlo 3-sigma band per planet around the ideal [-].
    coverage : dict or None
        :func:`meshphase.compare.predict.band_coverage` of the passes in that band.
    vs_truth : dict or None
        :func:`meshphase.compare.predict.truth_comparison` against the synthetic truth.
    scored_against_truth : bool
        The input had a truth to score against (``vs_truth`` None then: no labels).
    """

    ideal: np.ndarray
    model: np.ndarray | None
    vs_ideal: dict
    vs_model: dict | None
    band: dict | None = None
    coverage: dict | None = None
    vs_truth: dict | None = None
    scored_against_truth: bool = False

    def with_band(self, lo, hi, coverage=None) -> "GaugeComparison":
        """This comparison with the band ``lo``, ``hi`` [-] and, when given, its coverage."""
        return dataclasses.replace(self, band={"lo": lo, "hi": hi},
                                   coverage=self.coverage if coverage is None else coverage)

    def as_dict(self) -> dict:
        """ideal, model, vs_ideal, vs_model, then band and coverage (with a band) and
        vs_truth (when scored)."""
        out = {"ideal": self.ideal, "model": self.model, "vs_ideal": self.vs_ideal,
               "vs_model": self.vs_model}
        if self.band is not None:
            out["band"] = self.band
            if self.coverage is not None:
                out["coverage"] = self.coverage
        if self.scored_against_truth:
            out["vs_truth"] = self.vs_truth
        return out


@dataclass(frozen=True, kw_only=True)
class CompareStage(StageResult):
    """Measured phasing against the ideal, the identified model and the Monte Carlo band
    (``compare`` stage).

    Attributes
    ----------
    by_gear : dict of str to GaugeComparison
        Per gear with a non-empty phasing table, sun first.
    """

    by_gear: dict = field(default_factory=dict)

    def with_gauge(self, gear: str, comparison: GaugeComparison) -> "CompareStage":
        """This result with ``gear``'s comparison replaced."""
        return dataclasses.replace(self, by_gear={**self.by_gear, gear: comparison})


@dataclass(frozen=True, kw_only=True)
class BearingStage(StageResult):
    """Bearing moments of a seed 001 case (``bearing_moments`` stage).

    Attributes
    ----------
    case : SeedCase
    torque : float
        Input torque [N·m].
    concentrated : BearingMoments or DoublePinionMoments
        With the loads at the face centres [N·m].
    with_offsets : BearingMoments or None
        Single pinion: with the scene's centroid offsets z_s, z_r.
    measured : BearingMoments or None
        Single pinion: with the measured centroids (centroids stage).
    """

    case: Any
    torque: float
    concentrated: Any
    with_offsets: Any = None
    measured: Any = None


@dataclass(frozen=True, kw_only=True)
class TiltStage(StageResult):
    """Coupled bearing tilt and load distribution (``tilt`` stage).

    Attributes
    ----------
    case : SeedCase
    torque : float
        Input torque [N·m].
    solutions : list of (float, TiltSolution)
        Per bearing tilt stiffness k_tilt [N·m/rad], its solution.
    """

    case: Any
    torque: float
    solutions: list
