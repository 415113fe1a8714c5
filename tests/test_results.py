"""Typed stage results (meshphase.run.results) and the run context that holds them: one frozen
dataclass per stage, the phasing verdict."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest

from meshphase.kinematics.phasing import GaugeLabels, PassTable, PhasingResult
from meshphase.run.context import RESULT_TYPES, phasing_verdict
from meshphase.run.results import (CompareStage, GaugeComparison, IdentifyStage, LoadSharingStage,
                                   PhasingStage, StageResult, ToleranceStage)
from meshphase.run.state import RunMessage
from meshphase.run.scene import STAGES, parse_scene
from meshphase.run.stages import STAGE_FUNCTIONS, RunContext


def _labels(channel="r", decided="pattern", n_unassigned=0) -> GaugeLabels:
    t = np.array([0.1, 0.2, 0.3])
    return GaugeLabels(channel, t, np.ones(3), None, np.array([0, 1, 2]), np.arange(3),
                       decided, n_unassigned)


def _phasing(**kw) -> PhasingStage:
    tab = PassTable.empty("ring")
    res = PhasingResult({"ring": tab}, {"ring": _labels()}, None, None, "", {}, ["ring"])
    args = dict(tables={"ring": tab}, labels={"ring": _labels(decided="first pulse")},
                reliability={}, labels_relative=["ring"], result=res)
    args.update(kw)
    return PhasingStage(**args)


def _ctx() -> RunContext:
    return RunContext(parse_scene('results = ["tilt"]\n[bearing]\ncase = "1"\nk_tilt_Nm_per_rad = 1e6\n'))


def test_one_result_type_per_stage_and_frozen():
    assert set(RESULT_TYPES) == set(STAGES) == set(STAGE_FUNCTIONS)
    assert all(issubclass(c, StageResult) for c in RESULT_TYPES.values())
    ph = _phasing()
    with pytest.raises(dataclasses.FrozenInstanceError):
        ph.tables = {}


def test_phasing_assignment_and_relabelled():
    ph = _phasing()
    assert ph.assignment == {"ring": {"shift_decided_by": "first pulse", "n_unassigned": 0,
                                      "ambiguous": True}}
    tab = PassTable.empty("ring", ["moved"])
    new = ph.relabelled("ring", tab, _labels(decided="identification"))
    assert new.tables["ring"] is tab and new.result.tables["ring"] is tab
    assert new.labels_relative == [] and ph.labels_relative == ["ring"]   # the old one stays
    assert new.assignment["ring"] == {"shift_decided_by": "identification", "n_unassigned": 0,
                                      "ambiguous": False}


def test_gauge_comparison_keys_follow_what_was_computed():
    row = GaugeComparison(ideal=np.zeros(2), model=None, vs_ideal={"rms": 0.0}, vs_model=None)
    assert list(row.as_dict()) == ["ideal", "model", "vs_ideal", "vs_model"]
    banded = row.with_band(np.zeros(3), np.ones(3), {"inside_fraction": 1.0})
    assert list(banded.as_dict()) == ["ideal", "model", "vs_ideal", "vs_model", "band", "coverage"]
    scored = dataclasses.replace(row, scored_against_truth=True)
    assert scored.as_dict()["vs_truth"] is None
    cmp = CompareStage(by_gear={"sun": row})
    assert cmp.with_gauge("sun", banded).by_gear["sun"] is banded and cmp.by_gear["sun"] is row


def test_tolerance_band_is_ave_bound3_widened_by_half_the_upper_dev():
    stat = lambda lo, hi: SimpleNamespace(bound3=(np.array(lo), np.array(hi)))  # noqa: E731
    mc = SimpleNamespace(ave_s=stat([-0.1], [0.2]), dev_s=stat([0.0], [0.4]),
                         ave_r=stat([-1.0], [1.0]), dev_r=stat([0.0], [2.0]))
    from meshphase.models.tolerance import MonteCarloResult

    mc.phasing_band = lambda gear: MonteCarloResult.phasing_band(mc, gear)
    lo, hi = ToleranceStage(monte_carlo=mc).band("sun")
    np.testing.assert_allclose([lo[0], hi[0]], [-0.3, 0.4])
    lo, hi = ToleranceStage(monte_carlo=mc).band("ring")
    np.testing.assert_allclose([lo[0], hi[0]], [-2.0, 2.0])


def test_run_context_records_typed_results():
    ctx = _ctx()
    assert ctx.phasing is None and ctx.result("phasing") is None
    ph = _phasing(error_estimate="3 passes")
    assert ctx.record("phasing", ph) is ph
    assert ctx.phasing is ph and ctx.result("phasing") is ph
    assert ctx.error_estimates == {"phasing": "3 passes"}
    # a stage that revises an earlier result: its revision replaces it
    revised = ph.relabelled("ring", PassTable.empty("ring"), _labels(decided="identification"))
    ctx.record("identify", IdentifyStage(identification=SimpleNamespace(), phasing=revised))
    assert ctx.phasing is revised
    # results are typed only: no dict-shaped view to write around them
    assert not hasattr(ctx, "results")
    with pytest.raises(AttributeError):
        ctx.phasing = ph


def test_run_context_bad_input():
    ctx = _ctx()
    with pytest.raises(TypeError, match="PhasingStage"):
        ctx.record("phasing", {"tables": {}})
    with pytest.raises(TypeError, match="PhasingStage"):
        ctx.record("phasing", LoadSharingStage())
    with pytest.raises(KeyError):
        ctx.result("phasnig")                            # a mistyped stage is a bug


def test_phasing_verdict_given_or_from_messages():
    assert phasing_verdict(None, []) == {}
    flag = RunMessage("phasing", "ProcessingWarning", "not reliable", unreliable=True)
    assert phasing_verdict(_phasing(reliability={}), [flag]) == {}
    ph = _phasing(reliability=None)
    msgs = [RunMessage("phasing", "ProcessingWarning", "ring gauge: encoder misfit; phasing not reliable",
                       gauge="ring", unreliable=True)]
    assert phasing_verdict(ph, msgs) == {"ring": {"reliable": False, "reasons": [
        "ring gauge: encoder misfit; phasing not reliable"]}}
    assert phasing_verdict(None, [RunMessage("x", "ProcessingWarning", "not reliable", unreliable=True)]) == {
        "phasing": {"reliable": False, "reasons": ["not reliable"]}}
    # the text is never read: an unflagged message that says "not reliable" flags nothing
    assert phasing_verdict(None, ["x: ProcessingWarning: not reliable",
                                  RunMessage("x", "ProcessingWarning", "not reliable")]) == {}
    with pytest.raises(TypeError, match="PhasingStage"):
        phasing_verdict({"tables": {}}, [])
    with pytest.raises(TypeError, match="messages"):
        phasing_verdict(None, "not reliable")
