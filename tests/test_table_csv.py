"""meshphase.run.table_csv: result tables as CSV without pandas, byte for byte what pandas'
``DataFrame(table).to_csv(path, index=False, na_rep="")`` wrote before (pandas is the
reference here: the files' format is what users' scripts already read)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings, strategies as st

from meshphase.run.table_csv import write_csv

FLOATS = st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=64),
                   st.sampled_from([0.1, 1e-5, 1e16, -0.0, 5e-324, 1.7976931348623157e308]))
TEXT = st.text(alphabet=st.sampled_from(list('ab ,"\'\n;x1')), max_size=6)


def _pandas(table, path, columns=None):
    df = pd.DataFrame(table, columns=columns)
    df.to_csv(path, index=False, na_rep="")
    return path.read_bytes()


# columns of one kind each, as the result tables have them: floats (with NaN and inf),
# integers, integers with a missing one, bools, text, text with a missing one, all missing
KINDS = {
    "float": FLOATS,
    "float_or_none": st.one_of(FLOATS, st.none()),
    "int": st.integers(-10 ** 12, 10 ** 12),
    "np_float": FLOATS.map(np.float64),
    "bool": st.booleans(),
    "text": TEXT,
    "text_or_none": st.one_of(TEXT, st.none()),
}


@settings(max_examples=60, deadline=None)
@given(kinds=st.lists(st.sampled_from(sorted(KINDS)), min_size=1, max_size=5),
       n=st.integers(1, 6), data=st.data())
def test_rows_as_pandas_wrote_them(tmp_path_factory, kinds, n, data):
    tmp = tmp_path_factory.mktemp("csv")
    rows = [{f"c{j}_{k}": data.draw(KINDS[k]) for j, k in enumerate(kinds)} for _ in range(n)]
    ours = write_csv(rows, tmp / "ours.csv").read_bytes()
    assert ours == _pandas(rows, tmp / "ref.csv")


@settings(max_examples=40, deadline=None)
@given(n=st.integers(0, 50), seed=st.integers(0, 2 ** 31 - 1))
def test_columns_as_pandas_wrote_them(tmp_path_factory, n, seed):
    # the passes table: a gauge name for every row, float and integer arrays
    tmp = tmp_path_factory.mktemp("csv")
    rng = np.random.default_rng(seed)
    x = rng.standard_normal(n) * 10.0 ** rng.integers(-12, 12, n)
    x[rng.random(n) < 0.2] = np.nan
    cols = {"gauge": "sun", "time_s": x, "planet": rng.integers(1, 6, n),
            "flag": rng.random(n) < 0.5, "gamma_cycles": rng.random(n)}
    assert write_csv(cols, tmp / "ours.csv").read_bytes() == _pandas(cols, tmp / "ref.csv")


def test_edge_tables(tmp_path):
    cases = [
        ([{"a": 1, "b": None}, {"a": None, "b": 2.5}], None),      # int column with a gap
        ([{"a": True}, {"a": None}], None),                         # bool column with a gap
        ([{"only": float("nan")}], None),                           # one empty field: ""
        ([{"a": 1}, {"b": "x"}], None),                             # keys in order of appearance
        ([], ["stage", "wall_time_s"]),                             # header only
        ([{"stage": "load", "x": 1.0}], ["stage", "wall_time_s"]),  # a column no row holds
    ]
    for i, (rows, columns) in enumerate(cases):
        ours = write_csv(rows, tmp_path / f"o{i}.csv", columns).read_bytes()
        assert ours == _pandas(rows, tmp_path / f"r{i}.csv", columns), rows


def test_empty_and_bad_input(tmp_path):
    assert write_csv({}, tmp_path / "e.csv").read_bytes() == _pandas({}, tmp_path / "e2.csv")
    with pytest.raises(TypeError, match="list of dicts"):
        write_csv([1, 2], tmp_path / "x.csv")
    with pytest.raises(TypeError, match="list of dicts"):
        write_csv("a,b", tmp_path / "x.csv")
    with pytest.raises(ValueError, match="different lengths"):
        write_csv({"a": np.zeros(2), "b": np.zeros(3)}, tmp_path / "x.csv")
    with pytest.raises(FileNotFoundError):
        write_csv([{"a": 1}], tmp_path / "no" / "x.csv")
