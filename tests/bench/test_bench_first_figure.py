"""meshphase.bench.first_figure: the rows are measured (never asserted), their shape held."""

import pytest

from meshphase.bench.first_figure import FIRST_FIGURE_COLUMNS, first_figure_rows


def test_first_figure_rows_measure_each_figure_in_both_cases():
    rows = first_figure_rows(1)
    assert [r["case"] for r in rows] == ["without fork_ready"] * 4 + ["with fork_ready"] * 4
    assert [r["figure"] for r in rows[:4]] == ["phasing", "load_sharing", "residual_rms", "wall_times"]
    for r in rows:
        assert set(r) == set(FIRST_FIGURE_COLUMNS) and r["second_s"] > 0.0
        assert r["min_excess_s"] <= r["first_excess_s"] <= r["max_excess_s"]


@pytest.mark.parametrize("bad, exc", [(0, ValueError), ("2", TypeError), (None, TypeError)])
def test_first_figure_rows_reject_bad_repeats(bad, exc):
    with pytest.raises(exc):
        first_figure_rows(bad)
