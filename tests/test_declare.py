"""The stage registry (meshphase.run.declare) and the typed run state (meshphase.run.state):
every table that names stages is derived from the one declaration per stage."""

from __future__ import annotations

import dataclasses
import pickle

import pytest

from meshphase.data_schemas import load_schema
from meshphase.report.validation import SECTION_KEYS
from meshphase.run.context import RESULT_TYPES, result_types
from meshphase.run.declare import (RESULT_OF_STAGE, STAGE_REGISTRY, Stage, check_registry,
                                   client_results, report_sections, result_names, result_of_stage,
                                   result_stages, stage_graph)
from meshphase.run.exits import RESULT_OF_STAGE as EXIT_TABLE
from meshphase.run.results import StageResult, TiltStage
from meshphase.run.scene import RESULTS, STAGES
from meshphase.run.state import FailureKind, RunMessage, StageFailure, flagged_warning
from meshphase.run.stages import STAGE_FUNCTIONS


def test_schema_enum_is_the_declared_results():
    enum = load_schema("scene")["properties"]["results"]["items"]["enum"]
    assert enum == result_names() == list(RESULTS)


def test_scene_exit_table_and_functions_follow_the_registry():
    names = [s.name for s in STAGE_REGISTRY]
    assert list(STAGES) == list(RESULT_TYPES) == list(STAGE_FUNCTIONS) == names
    assert EXIT_TABLE is RESULT_OF_STAGE and RESULT_OF_STAGE == {v[0]: k for k, v in RESULTS.items()}
    assert set(report_sections()) == set(SECTION_KEYS)


def test_adding_a_result_is_one_descriptor():
    @dataclasses.dataclass(frozen=True, kw_only=True)
    class WearStage(StageResult):
        depth: float = 0.0

    wear = Stage("wear", needs=("tilt",), result_type=WearStage, result="wear", report="wear",
                 scope="scene")
    reg = STAGE_REGISTRY + (wear,)
    assert stage_graph(reg)["wear"] == ("tilt",)
    assert result_stages(reg)["wear"] == ("wear",) and result_names(reg)[-1] == "wear"
    assert result_of_stage(reg)["wear"] == "wear"
    assert result_types(reg)["wear"] is WearStage and result_types(reg)["tilt"] is TiltStage
    assert report_sections(reg)["wear"] == ("wear",)
    assert client_results(["phasing", "wear"], gearset_known=False, registry=reg) == ["wear"]
    assert "wear" not in RESULTS                    # the real registry is untouched


def test_campaign_split_rules():
    assert client_results([], gearset_known=True) == []
    assert client_results(["tolerance", "tilt", "bearing_moments"], gearset_known=True) == [
        "tolerance", "tilt", "bearing_moments"]
    assert client_results(["tolerance"], gearset_known=False) == []          # each recording's gearset
    assert client_results(["bearing_moments", "centroids"], gearset_known=True) == []  # measured
    assert client_results(["no_such"], gearset_known=True) == []


def test_registry_bad_input():
    assert check_registry(()) == ()
    with pytest.raises(ValueError, match="twice"):
        check_registry(STAGE_REGISTRY + (STAGE_REGISTRY[0],))
    with pytest.raises(ValueError, match="not declared"):
        check_registry((Stage("x", needs=("y",), result_type=TiltStage),))
    with pytest.raises(ValueError, match="x reads y"):
        check_registry((Stage("x", reads=("y",), result_type=TiltStage),))
    with pytest.raises(ValueError, match="two stages"):
        check_registry((Stage("a", result="r", result_type=TiltStage),
                        Stage("b", result="r", result_type=TiltStage)))
    with pytest.raises(TypeError, match="Stage"):
        check_registry(("load",))
    with pytest.raises(ValueError, match="scope"):
        Stage("x", scope="cluster")
    with pytest.raises(TypeError, match="StageResult"):
        Stage("x", result_type=3)
    with pytest.raises(TypeError, match="StageResult"):
        result_types((Stage("x", result_type=dict),))
    with pytest.raises(TypeError, match="StageResult"):
        result_types((Stage("x", result_type="NoSuchStage"),))
    with pytest.raises(TypeError, match="tuple"):
        Stage("x", needs=["load"])
    with pytest.raises(ValueError, match="identifier"):
        Stage("not a name")


def test_stage_failure_texts_and_kinds():
    raised = StageFailure.raised("tilt", ValueError("k out of range"))
    assert str(raised) == "ValueError: k out of range" and raised.exception == "ValueError"
    blocked = StageFailure.blocked("phasing", ["onsets", "condition"])
    assert str(blocked) == "skipped: needs onsets, condition" and not blocked.benign
    skip = StageFailure.not_applicable("centroids", "the recording has no face-width gauges")
    assert str(skip) == "skipped: the recording has no face-width gauges" and skip.benign
    assert str(raised.replace_text("k", "K")) == "ValueError: K out of range"
    assert str(StageFailure("x", FailureKind.RAISED)) == ""                      # empty reason
    with pytest.raises(TypeError, match="FailureKind"):
        StageFailure("x", "raised")
    with pytest.raises(ValueError, match="names what blocked"):
        StageFailure.blocked("x", [])


def test_run_message_fields_and_text():
    m = RunMessage.of_warning("phasing", flagged_warning(UserWarning, "ring gauge (R): no pass",
                                                        unreliable=True), UserWarning)
    assert m == "phasing: UserWarning: ring gauge (R): no pass"
    assert (m.stage, m.category, m.gauge, m.unreliable, m.detail) == (
        "phasing", "UserWarning", "ring", True, "no pass")
    back = pickle.loads(pickle.dumps(m))
    assert back == m and back.gauge == "ring" and back.unreliable
    plain = RunMessage("x", "W", "")
    assert plain == "x: W: " and plain.gauge is None and plain.detail == ""
    with pytest.raises(TypeError, match="stage"):
        RunMessage(1, "W", "t")
    with pytest.raises(TypeError, match="Warning subclass"):
        flagged_warning(ValueError, "t")
