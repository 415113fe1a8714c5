"""The accuracy table of ``meshphase bench processing --accuracy`` (meshphase.bench.conditions):
its files, columns and row logic on one short row; numbers are measured, never asserted."""

import csv
import json

import pytest

from meshphase.bench.conditions import (CONDITION_COLUMNS, CONDITIONS, FLAGGED_Z_MAX, Condition,
                                        condition_rows, conditions_markdown)
from meshphase.bench.phasing import TARGET_ABS, TARGET_FLOOR_RATIO
from meshphase.cli import main
from meshphase.synthetic.scenarios import SCENARIOS


def test_accuracy_flag_runs_only_the_table(tmp_path, capsys):
    out = tmp_path / "b"
    assert main(["bench", "processing", "--accuracy", "--quick", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "| " + " | ".join(CONDITION_COLUMNS) + " |" in text
    assert "Pooled over" in text and "RMS(error/sigma)" in text
    assert sorted(p.name for p in out.iterdir()) == ["conditions.csv", "conditions.json",
                                                     "conditions.md"]
    data = json.loads((out / "conditions.json").read_text(encoding="utf-8"))
    rows = data["rows"]
    assert {r["gauge"] for r in rows} == {"sun", "ring"}
    for r in rows:
        assert tuple(r) == CONDITION_COLUMNS and r["scenario"] == "rig_ripple_planet"
        assert r["n"] > 0
        assert r["target"] == pytest.approx(max(TARGET_ABS, TARGET_FLOOR_RATIO * r["floor"]))
        assert r["within_target"] == (r["rms"] <= r["target"])
        assert r["verdict"] == "ok" or r["verdict"].startswith("unreliable: ")
        flagged = r["verdict"] != "ok" and r["z_rms"] <= FLAGGED_Z_MAX
        assert r["meets"] == (r["within_target"] or flagged)
        assert 0.0 <= r["coverage95"] <= 1.0 and r["z_rms"] > 0
    pooled = data["pooled"]
    assert pooled["n"] == sum(r["n"] for r in rows) and pooled["n_rows"] == len(rows)
    assert pooled["n_ok"] == sum(r["meets"] for r in rows)
    with open(out / "conditions.csv", newline="", encoding="utf-8") as fh:
        table = list(csv.reader(fh))
    assert tuple(table[0]) == CONDITION_COLUMNS and len(table) == len(rows) + 1
    assert (out / "conditions.md").read_text(encoding="utf-8") in text


def test_accuracy_flag_belongs_to_processing(tmp_path, capsys):
    out = tmp_path / "b"
    assert main(["bench", "io", "--accuracy", "--out", str(out)]) != 0
    assert "--accuracy" in capsys.readouterr().err
    assert not out.exists()


def test_conditions_cover_the_issue_rows():
    assert all(c.scenario in SCENARIOS for c in CONDITIONS)
    by = {c.scenario: c for c in CONDITIONS}
    assert len(by["rig_ripple_planet"].seeds) == 3 and len(by["rig_fast_ripple1"].seeds) == 3
    glob = [c for c in CONDITIONS if c.channels]
    assert len(glob) == 1 and dict(glob[0].channels[0])["kind"] == "sun"
    assert Condition("x", "rig_clean").case.snr_db is None      # the scenario's own artefacts


def test_condition_empty_and_bad_inputs():
    assert condition_rows([]) == []
    md = conditions_markdown([])
    assert md.startswith("| " + " | ".join(CONDITION_COLUMNS)) and "Pooled over 0 passes" in md
    with pytest.raises(TypeError, match="Condition"):
        condition_rows(["rig_steady"])
    with pytest.raises(ValueError, match=r"seeds must be .* got \(\)"):
        Condition("x", "rig_steady", seeds=())
    with pytest.raises(ValueError, match=r"seeds must be .* got \(-1,\)"):
        Condition("x", "rig_steady", seeds=(-1,))
    with pytest.raises(ValueError, match="'x' minutes must be > 0, got 0"):
        Condition("x", "rig_steady", minutes=0)
    with pytest.raises(ValueError, match="'x' seed must be a whole number, got 1.5"):
        Condition("x", "rig_steady", seeds=(1.5,))
    with pytest.raises(ValueError, match="name"):
        Condition("", "rig_steady")
