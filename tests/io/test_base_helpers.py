"""The helpers that the format modules share through meshphase.io.base."""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import numpy as np
import pytest

from meshphase.errors import DataQualityWarning, FormatWarning
from meshphase.io.base import (RecordingFileError, check_start_datetime, check_verify, dumps_json,
                               spec_from_dict, warn_nonfinite)
from meshphase.recording import ChannelSpec


def _imported_modules(path: Path, package: str) -> set[str]:
    """Absolute names of the modules a source file imports (``from X import y`` gives X and X.y)."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = package.split(".")[:len(package.split(".")) - node.level + 1] if node.level else []
            mod = ".".join(base + ([node.module] if node.module else []))
            out.add(mod)
            out.update(f"{mod}.{a.name}" for a in node.names)
    return out


@pytest.mark.parametrize("name", ["hdf5", "mcap", "csv", "tdms"])
def test_format_modules_share_helpers_only_through_base(name):
    # no format module imports another: what they share lives in io/base.py
    mod = importlib.import_module(f"meshphase.io.{name}")
    path = Path(mod.__file__)
    files = sorted(path.parent.glob("*.py")) if path.name == "__init__.py" else [path]
    package = mod.__name__ if path.name == "__init__.py" else "meshphase.io"
    others = {f"meshphase.io.{o}" for o in ("hdf5", "mcap", "csv", "tdms") if o != name}
    for f in files:
        bad = {m for m in _imported_modules(f, package) if m in others or m.rsplit(".", 1)[0] in others}
        assert not bad, f"{f.name} imports {sorted(bad)}"


@pytest.mark.parametrize("value", [True, False, np.bool_(True)])
def test_check_verify_takes_bools(value):
    assert check_verify(value) is bool(value)


@pytest.mark.parametrize("value", [None, 1, "yes", []])
def test_check_verify_refuses_other_values(value):
    with pytest.raises(TypeError, match="verify must be a bool"):
        check_verify(value)


def test_warn_nonfinite_is_quiet_on_empty_and_finite_data(recwarn):
    warn_nonfinite("f.h5", np.empty((0, 2)), ["a", "b"])
    warn_nonfinite("f.h5", np.ones((5, 1)), ["a"])
    warn_nonfinite("f.h5", np.full((3, 1), 1e308), ["a"])  # the sum overflows, the samples are finite
    assert not recwarn.list


def test_warn_nonfinite_names_the_channel_and_file_sample():
    data = np.ones((10, 2))
    data[4:6, 1] = np.nan
    with pytest.warns(DataQualityWarning, match=r"f\.h5: channel 'b' has 1 run.*2 samples.*first at sample 104"):
        warn_nonfinite("f.h5", data, ["a", "b"], i0=100)


def test_dumps_json_round_trips_and_warns_when_it_cannot():
    assert dumps_json({}, "meta") == "{}" and dumps_json([], "history") == "[]"
    assert dumps_json({"x": [1, 2.5, "ü"]}, "meta") == '{"x": [1, 2.5, "ü"]}'
    with pytest.warns(FormatWarning, match="tuples become lists"):
        dumps_json({"x": (1, 2)}, "meta")


def test_dumps_json_names_what_cannot_be_stored():
    with pytest.raises(TypeError, match="^recording meta: "):
        dumps_json({"x": object()}, "recording meta")
    loop: list = []
    loop.append(loop)
    with pytest.raises(ValueError, match="^recording history: "):
        dumps_json(loop, "recording history")


def test_check_start_datetime():
    assert check_start_datetime(None, "f.csv") is None
    assert check_start_datetime("2024-05-01T10:00:00+00:00", "f.csv") == "2024-05-01T10:00:00+00:00"
    with pytest.raises(RecordingFileError, match="not ISO 8601"):
        check_start_datetime("", "f.csv")
    with pytest.raises(RecordingFileError, match="must be an ISO 8601 string"):
        check_start_datetime(20240501, "f.csv")


def test_spec_from_dict():
    d = ChannelSpec("a", kind="sun", units="V").to_dict()
    assert spec_from_dict(d, "f.csv", "channels[0]") == ChannelSpec("a", kind="sun", units="V")
    with pytest.raises(RecordingFileError, match="f.csv: bad channel spec"):
        spec_from_dict({}, "f.csv", "channels[0]")
    with pytest.raises(RecordingFileError, match="bad channel spec"):
        spec_from_dict(dict(d, kind="strain"), "f.csv", "channels[0]")
