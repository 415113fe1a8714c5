"""The identification rows of the processing benchmark (meshphase.bench.processing):
columns and counts only; times are measured, never asserted."""

import pytest

from meshphase.bench.processing import IDENTIFY_COLUMNS, PROCESS_COLUMNS, identify_rows


def test_identify_rows_columns_and_counts():
    rows = identify_rows((1.0,))
    assert [r["jac"] for r in rows] == ["2-point", "analytic"]
    for r in rows:
        assert set(IDENTIFY_COLUMNS) <= set(r)
        assert r["n_passes"] > 0 and r["evaluations"] >= r["jacobians"] > 0
    # the same data: the fits agree, the closed form needs fewer evaluations
    assert rows[1]["rms_after"] == pytest.approx(rows[0]["rms_after"], rel=1e-3)
    assert rows[1]["evaluations"] < rows[0]["evaluations"]
    assert {"identify_s", "identify_share"} <= set(PROCESS_COLUMNS)


def test_identify_rows_empty_and_bad():
    assert identify_rows(()) == []
    with pytest.raises(ValueError, match="minutes"):
        identify_rows((0.0,))
    with pytest.raises(ValueError, match="jac"):
        identify_rows((1.0,), jacs=("exact",))
