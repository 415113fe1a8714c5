"""meshphase.bench.phasing_stage: the phasing stage's time and share, the fixed cost per run."""

from __future__ import annotations

import math

import pytest

from meshphase.bench.phasing_stage import (PHASING_COLUMNS, fixed_cost, phasing_markdown,
                                           phasing_stage_rows)


def test_fixed_cost_extrapolates_the_two_shortest_lengths_to_none():
    rows = [{"minutes": 60.0, "wall_median_s": 30.0}, {"minutes": 4.0, "wall_median_s": 3.0},
            {"minutes": 2.0, "wall_median_s": 2.0}]
    assert fixed_cost(rows) == pytest.approx(1.0)          # 2 t(2) - t(4)
    assert math.isnan(fixed_cost(rows[:1]))
    assert math.isnan(fixed_cost([]))


def test_empty_and_bad_input(tmp_path):
    assert phasing_stage_rows(tmp_path, ()) == []
    with pytest.raises(ValueError):
        phasing_stage_rows(tmp_path, (-1.0,))
    with pytest.raises(ValueError):
        phasing_stage_rows(tmp_path, (1.0,), repeats=0)


def test_a_short_run_times_the_phasing_stage(tmp_path):
    rows = phasing_stage_rows(tmp_path / "w", (0.1, 0.2), repeats=1)
    assert [r["minutes"] for r in rows] == [0.1, 0.2]
    for r in rows:
        assert set(r) == set(PHASING_COLUMNS)
        assert 0.0 < r["phasing_min_s"] < r["wall_min_s"]
        assert 0.0 < r["phasing_share"] < 1.0
    assert not list((tmp_path / "w").glob("*.h5"))          # the recordings removed again
    md = phasing_markdown(rows)
    assert "fixed cost per run" in md and md.count("\n|") == 3
