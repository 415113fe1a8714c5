"""meshphase.bench.startup: the start-up rows are measured, their shape and ordering held."""

import pytest

from meshphase.bench.startup import EXIT_COLUMNS, STARTUP_COLUMNS, exit_rows, startup_rows


def test_startup_rows_measure_each_case():
    rows = startup_rows(1)
    assert [r["what"] for r in rows][0] == "python -c pass"
    for r in rows:
        assert set(r) == set(STARTUP_COLUMNS)
        assert 0.0 < r["min_s"] <= r["median_s"] <= r["max_s"]
        assert 0.0 < r["ready_s"] <= r["max_s"]          # the code ends before the process does
    mods = {r["what"]: r["modules"] for r in rows}
    # the module counts are what the rows claim: the interpreter loads least, the stages most
    assert mods["python -c pass"] < mods["import meshphase"] < mods["meshphase --version"]
    assert mods["meshphase --version"] < mods["import meshphase.run.stages (what process loads)"]
    # the row beside it adds pandas, which process no longer loads (meshphase.run.table_csv)
    assert mods["import meshphase.run.stages (what process loads)"] < mods["import meshphase.run.stages, pandas"]


@pytest.mark.parametrize("bad, exc", [(0, ValueError), (-2, ValueError), ("3", TypeError),
                                      (None, TypeError), (2.5, ValueError)])
def test_startup_rows_reject_bad_repeats(bad, exc):
    with pytest.raises(exc):
        startup_rows(bad)
    with pytest.raises(exc):
        exit_rows(bad)


def test_exit_rows_measure_both_exits():
    # measured, not asserted: the rows' shape, and that both cases saw the same stack
    rows = exit_rows(1)
    assert [r["what"] for r in rows] == ["exit as the interpreter does it",
                                         "exit after console_main's collection and gc.freeze"]
    for r in rows:
        assert set(r) == set(EXIT_COLUMNS) and 0.0 < r["min_s"] <= r["median_s"] <= r["max_s"]
    assert rows[0]["objects"] > 50_000 and abs(rows[1]["objects"] - rows[0]["objects"]) < 0.05 * rows[0]["objects"]
    assert rows[1]["collect_s"] > 0.0 and rows[0]["collect_s"] != rows[0]["collect_s"]   # NaN: no collection
