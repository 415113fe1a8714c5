"""The stages of a run, each declared once: what it needs, what it gives, where it shows.

:data:`STAGE_REGISTRY` holds one :class:`Stage` per stage, in declaration order (the order
a run lists them). Everything that names stages is derived from it: the scene's stage graph
and result names (:data:`meshphase.run.scene.STAGES`, :data:`meshphase.run.scene.RESULTS`),
the result type each stage records (:data:`meshphase.run.context.RESULT_TYPES`), the exit table from a stage to
the result a scene requests it by (:data:`RESULT_OF_STAGE`), the campaign's split of a
scene's results into client and per-recording ones
(:func:`meshphase.campaign.runner.split_results`), the report's sections
(:func:`report_sections`) and the enum of ``results`` in ``data_schemas/scene.schema.json``
(held to :func:`result_names` by the tests). Each derivation is a function of a registry, so
a registry with one more :class:`Stage` flows through all of them.

The stage's function is bound where it is written, in :mod:`meshphase.run.stages`
(``@runs("name")``, checked against this registry when that module loads): this module stays
light, as the scene validation and the command line's start-up read it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable


__all__ = ["Stage", "STAGE_REGISTRY", "SCOPES", "stage_graph", "result_stages", "result_names",
           "result_of_stage", "report_sections", "client_results",
           "gearset_stages", "recording_stages", "check_registry",
           "RESULT_OF_STAGE", "STAGE_NAMES"]

#: where a stage runs in a campaign: once per recording, or once per scene (on the client)
SCOPES = ("recording", "scene")


@dataclass(frozen=True)
class Stage:
    """One stage of a run, declared once.

    Attributes
    ----------
    name : str
        The stage name (``ctx.<name>`` holds its result).
    needs : tuple of str
        Stages that must have run before it (a DAG; a failed one skips this stage).
    result_type : str or type
        The :class:`meshphase.run.results.StageResult` subclass it records: its name in
        :mod:`meshphase.run.results`, or the class (resolved by
        :func:`meshphase.run.context.result_types`; named, so this module loads no result
        code).
    result : str or None
        The name a scene requests it by in ``results`` (None: only pulled in by others).
    reads : tuple of str
        Stages whose results it reads when they ran, without needing them.
    outputs : tuple of str
        The files of the output folder written from its result.
    report : str or None
        The section of the HTML report its result fills (None: none of its own).
    scope : {"recording", "scene"}
        "recording": runs with each recording (in a campaign, in the worker); "scene": needs
        no recording, runs once per scene (on the campaign's client).
    uses_gearset : bool
        Needs a gearset (the scene's, else the recording's metadata gearset).
    opens_recording : bool
        Opens the scene's recording (it must exist and be readable).
    """

    name: str
    needs: tuple = ()
    result_type: str | type = "StageResult"
    result: str | None = None
    reads: tuple = ()
    outputs: tuple = ()
    report: str | None = None
    scope: str = "recording"
    uses_gearset: bool = False
    opens_recording: bool = False

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name.isidentifier():
            raise ValueError(f"a stage name is an identifier, got {self.name!r}")
        if self.scope not in SCOPES:
            raise ValueError(f"stage {self.name!r}: scope must be one of {SCOPES}, got {self.scope!r}")
        rt = self.result_type
        if not (isinstance(rt, type) or (isinstance(rt, str) and rt.isidentifier())):
            raise TypeError(f"stage {self.name!r}: result_type must be a StageResult subclass or "
                            f"its name, got {rt!r}")
        for key in ("needs", "reads", "outputs"):
            if not isinstance(getattr(self, key), tuple):
                raise TypeError(f"stage {self.name!r}: {key} must be a tuple, got "
                                f"{type(getattr(self, key)).__name__}")


#: every stage, in declaration order (a stage after the stages it needs; the results in the
#: order the scene's documentation lists them)
STAGE_REGISTRY: tuple[Stage, ...] = (
    Stage("ideal", result_type="IdealStage", result="ideal_phasing", report="ideal",
          uses_gearset=True, outputs=("summary.json: ideal",)),
    Stage("load", result_type="LoadStage", report="recording", opens_recording=True,
          outputs=("summary.json: recording",)),
    Stage("condition", needs=("load",), result_type="ConditionStage", report="recording"),
    Stage("onsets", needs=("condition",), result_type="OnsetsStage", report="onsets",
          uses_gearset=True, outputs=("arrays.h5: onsets", "summary.json: onsets")),
    Stage("phasing", needs=("onsets",), result_type="PhasingStage", result="phasing",
          report="phasing", uses_gearset=True,
          outputs=("passes_<gear>.csv", "summary.json: phasing")),
    Stage("load_sharing", needs=("onsets",), reads=("phasing",), result_type="LoadSharingStage",
          result="load_sharing", report="load_sharing", uses_gearset=True,
          outputs=("load_sharing.csv", "summary.json: load_sharing")),
    Stage("centroids", needs=("onsets",), result_type="CentroidsStage", result="centroids",
          report="centroids", outputs=("summary.json: centroids_m",)),
    Stage("compare", needs=("phasing", "ideal"), reads=("identify", "tolerance"),
          result_type="CompareStage", result="compare", uses_gearset=True,
          outputs=("summary.json: compare",)),
    Stage("identify", needs=("phasing",), result_type="IdentifyStage", result="identify",
          report="identify", uses_gearset=True,
          outputs=("identified_errors.csv", "identified_combinations.csv",
                   "summary.json: identify")),
    Stage("tolerance", result_type="ToleranceStage", result="tolerance", scope="scene",
          uses_gearset=True, outputs=("arrays.h5: monte_carlo", "summary.json: tolerance")),
    Stage("bearing_moments", reads=("centroids",), result_type="BearingStage",
          result="bearing_moments", report="bearing_moments", scope="scene",
          outputs=("bearing_moments.csv", "summary.json: bearing_moments")),
    Stage("tilt", result_type="TiltStage", result="tilt", report="tilt", scope="scene",
          outputs=("tilt.csv", "summary.json: tilt")),
)


def check_registry(registry: Iterable[Stage]) -> tuple[Stage, ...]:
    """``registry`` as a tuple, checked: unique names and result names, each stage's
    ``needs`` declared before it (so declaration order is a run order), its ``reads``
    declared.

    Raises
    ------
    TypeError
        An entry is not a :class:`Stage`.
    ValueError
        A name twice, a stage needing one declared after it (or not at all), or reading one
        not declared.
    """
    stages = tuple(registry)
    seen: set = set()
    results: set = set()
    for s in stages:
        if not isinstance(s, Stage):
            raise TypeError(f"a stage registry holds Stage declarations, got {type(s).__name__}")
        if s.name in seen:
            raise ValueError(f"stage {s.name!r} is declared twice")
        late = [d for d in s.needs if d not in seen]
        if late:
            raise ValueError(f"stage {s.name!r} needs {', '.join(late)}, not declared before it")
        if s.result is not None:
            if s.result in results:
                raise ValueError(f"result {s.result!r} is declared by two stages")
            results.add(s.result)
        seen.add(s.name)
    unknown = [(s.name, d) for s in stages for d in s.reads if d not in seen]
    if unknown:
        raise ValueError("stages read stages not declared: "
                         + ", ".join(f"{a} reads {b}" for a, b in unknown))
    return stages


def stage_graph(registry: Iterable[Stage] = STAGE_REGISTRY) -> dict[str, tuple[str, ...]]:
    """stage -> the stages it needs, in declaration order."""
    return {s.name: s.needs for s in check_registry(registry)}


def result_stages(registry: Iterable[Stage] = STAGE_REGISTRY) -> dict[str, tuple[str, ...]]:
    """result name -> the stages that produce it (the scene's ``results`` vocabulary)."""
    return {s.result: (s.name,) for s in check_registry(registry) if s.result is not None}


def result_names(registry: Iterable[Stage] = STAGE_REGISTRY) -> list[str]:
    """The result names a scene may request, in declaration order (the schema's enum)."""
    return list(result_stages(registry))


def result_of_stage(registry: Iterable[Stage] = STAGE_REGISTRY) -> dict[str, str]:
    """stage -> the result name a scene requests it by (the exit table's inverse of
    :func:`result_stages`); stages only pulled in by others are left out."""
    return {s.name: s.result for s in check_registry(registry) if s.result is not None}


def report_sections(registry: Iterable[Stage] = STAGE_REGISTRY) -> dict[str, tuple[str, ...]]:
    """report section -> the stages whose results fill it (stages without a section left
    out)."""
    out: dict = {}
    for s in check_registry(registry):
        if s.report is not None:
            out[s.report] = out.get(s.report, ()) + (s.name,)
    return out


def gearset_stages(registry: Iterable[Stage] = STAGE_REGISTRY) -> frozenset:
    """The stages that need a gearset."""
    return frozenset(s.name for s in check_registry(registry) if s.uses_gearset)


def recording_stages(registry: Iterable[Stage] = STAGE_REGISTRY) -> frozenset:
    """The stages that open the scene's recording."""
    return frozenset(s.name for s in check_registry(registry) if s.opens_recording)


def client_results(results, *, gearset_known: bool, registry: Iterable[Stage] = STAGE_REGISTRY
                   ) -> list[str]:
    """Of the requested ``results``, those a campaign runs once on the client.

    A result runs on the client when its stage is scene-scoped, reads no per-recording result
    that is also requested (bearing moments with measured centroids run with each recording)
    and, when it uses a gearset, the scene has one (``gearset_known``; otherwise each
    recording brings its own).
    """
    stages = check_registry(registry)
    by_result = {s.result: s for s in stages if s.result is not None}
    by_name = {s.name: s for s in stages}
    wanted = {by_result[r].name for r in results if r in by_result}
    out = []
    for r in results:
        s = by_result.get(r)
        if s is None or s.scope != "scene" or (s.uses_gearset and not gearset_known):
            continue
        if any(d in wanted and by_name[d].scope == "recording" for d in s.reads):
            continue
        out.append(r)
    return out


STAGE_NAMES: tuple[str, ...] = tuple(s.name for s in STAGE_REGISTRY)
#: stage -> the result name a scene requests it by
RESULT_OF_STAGE: dict[str, str] = result_of_stage()
