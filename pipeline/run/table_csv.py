"""Result tables as CSV without pandas (array code).

``meshphase process`` writes a handful of small tables (the passes, load sharing, the
identified errors, the stage timings); pandas' ``to_csv`` wrote them, and importing pandas
for that cost about 0.33 s of every run (a tenth of a 2-min ``process``). This writer gives
the same bytes as ``pandas.DataFrame(rows).to_csv(path, index=False, na_rep="")`` for the
tables meshphase writes (tests/test_table_csv.py compares the two on generated tables):

* a column of bools is written ``True`` / ``False``; of integers, as integers; of numbers
  with a missing value or a float among them, as floats (an integer as ``3.0``), in the
  shortest form that reads back exactly (numpy's, as pandas does), NaN as an empty field;
* any other column value by value: missing (None, NaN) as an empty field, others as ``str``;
* the columns in the order of their first appearance among the rows (a row without one
  has it missing); the csv module's minimal quoting; lines end with ``os.linesep``.
"""

from __future__ import annotations

import csv
import math
import numbers
import os
from pathlib import Path

import numpy as np

__all__ = ["write_csv"]


def write_csv(table, path, columns=None) -> Path:
    """Write ``table`` as CSV to ``path``.

    Parameters
    ----------
    table : list of dict or dict
        Rows (dicts, column name -> value), or columns (name -> 1-D array or a scalar
        repeated on every row).
    path : str or Path
    columns : sequence of str, optional
        The columns, in order (default: as they first appear). A name no row holds is
        written empty.

    Returns
    -------
    Path

    Raises
    ------
    TypeError
        ``table`` neither a list of dicts nor a dict.
    ValueError
        Columns of different lengths.
    """
    path = Path(path)
    names, cols, n = _columns(table, columns)
    text = [_format(c) for c in cols]
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh, lineterminator=os.linesep)
        w.writerow(names)
        w.writerows(zip(*text) if text else [[] for _ in range(n)])
    return path


def _columns(table, columns) -> tuple[list, list, int]:
    """(names, column values, row count) of rows or columns."""
    if isinstance(table, dict):
        lengths = {k: np.shape(v)[0] for k, v in table.items() if np.ndim(v) == 1}
        if len(set(lengths.values())) > 1:
            raise ValueError(f"columns of different lengths: {lengths}")
        n = next(iter(lengths.values()), 1 if table else 0)
        names = list(columns) if columns is not None else list(table)
        cols = []
        for k in names:
            v = table.get(k)
            cols.append(v if np.ndim(v) == 1 else [v] * n)
        return names, cols, n
    if not isinstance(table, (list, tuple)) or any(not isinstance(r, dict) for r in table):
        raise TypeError(f"table must be a list of dicts or a dict of columns, got {type(table).__name__}")
    if columns is not None:
        names = list(columns)
    else:
        names = list(dict.fromkeys(k for r in table for k in r))
    return names, [[r.get(k) for r in table] for k in names], len(table)


def _missing(v) -> bool:
    return v is None or (isinstance(v, (float, np.floating)) and math.isnan(v))


def _format(col) -> list:
    """One column as strings (pandas' inference, see the module notes)."""
    if isinstance(col, np.ndarray):
        if col.dtype.kind == "f":
            s = col.astype(str)
            s[np.isnan(col)] = ""
            return s.tolist()
        if col.dtype.kind in "iub":
            return col.astype(str).tolist()
        col = col.tolist()
    vals = list(col)
    if vals and all(isinstance(v, (bool, np.bool_)) for v in vals):
        return ["True" if v else "False" for v in vals]
    numeric = [v for v in vals if not _missing(v)]
    if numeric and len(numeric) == len(vals) and all(
            isinstance(v, (numbers.Integral, np.integer)) and not isinstance(v, (bool, np.bool_))
            for v in vals):
        return [str(int(v)) for v in vals]
    if all(_missing(v) or (isinstance(v, (numbers.Real, np.number))
                           and not isinstance(v, (bool, np.bool_))) for v in vals):
        a = np.array([np.nan if _missing(v) else v for v in vals], dtype=np.float64)
        s = a.astype(str)
        s[np.isnan(a)] = ""
        return s.tolist()
    return ["" if _missing(v) else str(v) for v in vals]
