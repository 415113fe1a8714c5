"""meshphase.jsonable: the one JSON conversion (results strict, metadata lossless)."""

import datetime as dt
import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from meshphase.jsonable import json_default, to_jsonable


def test_numpy_paths_dates_and_containers():
    v = {1: (np.float32(0.5), np.int64(3), np.bool_(True)), "p": Path("/a/b"),
         "d": dt.date(2026, 11, 25), "a": np.arange(3), "t": np.datetime64("2026-01-02T03:04:05"),
         "b": b"\xff"}
    out = to_jsonable(v)
    assert out == {"1": [0.5, 3, True], "p": "/a/b", "d": "2026-11-25", "a": [0, 1, 2],
                   "t": "2026-01-02T03:04:05.000000+00:00", "b": "\xff"}
    json.dumps(out, allow_nan=False)


@pytest.mark.parametrize("policy, expect", [("null", None), ("repr", "nan")])
def test_nonfinite_policies(policy, expect):
    assert to_jsonable([np.nan], nonfinite=policy) == [expect]
    assert math.isnan(to_jsonable(np.float64("nan"), nonfinite="keep"))


def test_empty_and_bad_input():
    assert to_jsonable({}) == {} and to_jsonable([]) == [] and to_jsonable(np.array([])) == []
    with pytest.raises(ValueError, match="nonfinite"):
        to_jsonable(1.0, nonfinite="drop")
    with pytest.raises(TypeError, match="object"):
        json.dumps({"x": object()}, default=json_default)


@given(st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=20))
def test_strict_policy_always_gives_strict_json(xs):
    json.dumps(to_jsonable(np.array(xs)), allow_nan=False)
