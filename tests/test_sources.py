"""The one recording header, the block-source interface and its sources, the generator
entry point, the truth protocol, and the package's independence of meshphase.synthetic."""

from __future__ import annotations

import ast
import dataclasses
import pkgutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import meshphase
from meshphase.compare.truth import RecordingTruth, tacho_geometry, true_errors
from meshphase.errors import DataQualityWarning
from meshphase.io import write
from meshphase.io.base import RecordingFileError, RecordingInfo
from meshphase.io.sources import (FileSource, GeneratedSource, RecordingGenerator, blocks_ahead,
                                  checked_blocks, generator, register_generator, scenario_config,
                                  scenario_names)
from meshphase.models.mesh_phasing import ShaftHoleErrors
from meshphase.recording import (BlockSource, MemorySource, Recording, RecordingHeader, apply_gains,
                                 history_entry, warn_nonfinite_runs)
from meshphase.run import stream

PIPELINE = Path(meshphase.__file__).parent


def _rec(n=10, dtype=np.float64):
    data = np.arange(n * 2, dtype=dtype).reshape(n, 2)
    return Recording(data, 10.0, ["a", "b"], t0=1.0, meta={"k": 1})


# ----------------------------------------------------------------------------- the header
def test_one_header_type_under_the_old_names():
    assert stream.StreamedRecording is RecordingHeader
    assert issubclass(RecordingInfo, RecordingHeader)
    rec = _rec()
    h = rec.info
    assert (h.fs, h.n_samples, h.names, h.t_end, h.dtype) == (10.0, 10, ["a", "b"], 2.0, np.float64)
    assert h.header() == rec.header()
    assert h.window(1.2, 1.5) == rec.sample_range(1.2, 1.5) == (2, 5)
    assert h.check_channels("b") == ["b"] and h.check_channels(None) == ["a", "b"]
    info = RecordingInfo(path="x.h5", format="hdf5", fs=10.0, n_samples=10, channels=rec.channels)
    assert info.names == ["a", "b"] and "hdf5 file x.h5" in repr(info)
    assert dataclasses.replace(info, history=[{"step": "s"}]).history == [{"step": "s"}]


def test_header_empty_and_bad_input():
    empty = RecordingHeader(10.0, 0)
    assert empty.n_channels == 0 and empty.duration == 0.0 and "0 samples" in repr(empty)
    with pytest.raises(ValueError, match="fs"):
        RecordingHeader(-1.0, 10)
    with pytest.raises(RecordingFileError, match="outside the physical range"):
        RecordingInfo(path="x", format="csv", fs=1e12, n_samples=1, channels=[])
    h = _rec().info
    with pytest.raises(ValueError, match="outside"):
        h.window(100.0, 101.0)
    with pytest.raises(ValueError, match="empty"):
        h.check_channels([])
    with pytest.raises(ValueError, match="no channel"):
        h.check_channels(["c"])
    with pytest.raises(TypeError, match="streamed"):
        h.data


def test_history_entry_empty_and_bad_input():
    e = history_entry("step", x=np.float64(2.5), bad=float("nan"))
    assert e["step"] == "step" and e["x"] == 2.5 and isinstance(e["x"], float) and np.isnan(e["bad"])
    assert set(history_entry("bare")) == {"step", "time"}
    with pytest.raises(TypeError, match="string"):
        history_entry(3)


# ----------------------------------------------------------------------------- sources
def test_memory_source_is_the_recordings_blocks():
    rec = _rec(dtype=np.float32)
    src = rec.source(gains=[(1, 2.0)])
    assert isinstance(src, BlockSource) and src.header.dtype == np.float32
    got = list(checked_blocks(src, 4))
    assert [a for a, _ in got] == [0, 4, 8]
    np.testing.assert_array_equal(np.vstack([d for _, d in got])[:, 1], rec.data[:, 1] * 2)
    np.testing.assert_array_equal(rec.data[:, 1], np.arange(1, 20, 2))   # the caller's untouched
    with blocks_ahead(src, 3) as blocks:
        assert sum(d.shape[0] for _, d in blocks) == 10


def test_sources_empty_and_bad_input(tmp_path):
    empty = Recording(np.empty((0, 2)), 10.0, ["a", "b"])
    assert list(checked_blocks(MemorySource(empty), 4)) == []
    with pytest.raises(TypeError, match="Recording"):
        MemorySource(np.zeros((3, 2)))
    with pytest.raises(TypeError):
        BlockSource()

    class Short(MemorySource):
        def blocks(self, n_block):
            yield 0, self.rec.data[:3]

    with pytest.raises(ValueError, match="the blocks hold 3 samples, the header says 10"):
        list(checked_blocks(Short(_rec(), label="short"), 4))
    with pytest.raises(FileNotFoundError):
        FileSource(tmp_path / "missing.h5")


def test_apply_gains_empty_and_bad_input():
    x = np.ones((3, 2))
    assert apply_gains(x, [], copy=True) is x
    y = apply_gains(x, [(0, 3.0), (0, 2.0)], copy=True)
    assert y[0, 0] == 6.0 and x[0, 0] == 1.0
    assert apply_gains(x, [(1, 5.0)], copy=False) is x and x[0, 1] == 5.0
    with pytest.raises(IndexError):
        apply_gains(x, [(4, 1.0)], copy=True)


def test_file_source_equals_memory_source(tmp_path):
    rec = _rec(n=1000)
    path = write(rec, tmp_path / "r.h5")
    f, m = FileSource(path), rec.source()
    assert f.header.names == m.header.names and f.header.n_samples == m.header.n_samples
    np.testing.assert_array_equal(np.vstack([d for _, d in checked_blocks(f, 128)]),
                                  np.vstack([d for _, d in checked_blocks(m, 128)]))


def test_warn_nonfinite_runs_empty_and_bad_input():
    class Scan:
        nonfinite_runs = np.array([[2, 5]])

    with warnings.catch_warnings(record=True) as wl:
        warnings.simplefilter("always")
        warn_nonfinite_runs("rec", ["a", "b"], {"a": Scan()}, first=10)
        warn_nonfinite_runs("rec", [], {})
    assert len(wl) == 1 and issubclass(wl[0].category, DataQualityWarning)
    assert "rec: channel 'a' has 1 run(s) of NaN/inf samples (3 samples, longest 3, first at sample 12)" \
        in str(wl[0].message)
    with pytest.raises(AttributeError):
        warn_nonfinite_runs("rec", ["a"], {"a": object()})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        MemorySource(_rec()).warn_nonfinite({"a": Scan()})      # off unless asked


def test_generated_source_reads_the_stream_again_for_every_pass():
    gen = generator("synthetic")
    stream_ = gen.stream("seed_rig", duration=2.0, seed=3)
    src = GeneratedSource(stream_, gains=[(0, 2.0)])
    first = np.vstack([d for _, d in checked_blocks(src, 1 << 12)])
    again = np.vstack([d for _, d in checked_blocks(src, 1 << 12)])
    np.testing.assert_array_equal(first, again)
    np.testing.assert_array_equal(first[:, 0], stream_.collect().data[:, 0] * 2.0)
    assert src.label == "synthetic recording" and stream.GeneratorSource is GeneratedSource


# ----------------------------------------------------------------------------- generators
def test_generator_entry_point_and_scenarios():
    gen = generator("synthetic")
    assert isinstance(gen, RecordingGenerator)
    assert "seed_rig" in scenario_names() and scenario_names() == sorted(scenario_names())
    cfg = scenario_config("seed_rig")
    assert cfg.fs > 0 and cfg.gearset.to_dict()["z_sun"] > 0


def test_generators_empty_and_bad_input():
    assert generator("no-such-generator") is None
    assert scenario_names("no-such-generator") == []
    assert scenario_config("seed_rig", "no-such-generator") is None
    assert scenario_config("no-such-scenario") is None
    with pytest.raises(TypeError, match="name"):
        generator(3)
    with pytest.raises(TypeError, match="scenarios"):
        register_generator("x", object())
    with pytest.raises(TypeError, match="non-empty"):
        register_generator("", generator("synthetic"))


# ----------------------------------------------------------------------------- truth
def test_truth_protocol_of_the_generator():
    _, truth = meshphase.synthetic.generate("seed_rig", duration=1.0, seed=2)
    assert isinstance(truth, RecordingTruth)
    te = truth.shaft_hole_errors()
    assert isinstance(te, ShaftHoleErrors) and true_errors(truth).e_sun == te.e_sun
    assert tacho_geometry(truth) == truth.tacho_geometry()

    class Plain:                                         # a truth that is no GroundTruth
        config, events = {}, {}

        def shaft_hole_errors(self):
            return None

        def tacho_geometry(self):
            return 0.5, {"sun": 1.0}

    assert true_errors(Plain()) is None and tacho_geometry(Plain()) == (0.5, {"sun": 1.0})
    with pytest.raises(TypeError, match="synthetic truth"):
        true_errors(object())


# ----------------------------------------------------------------------------- independence
def _package_modules() -> list[str]:
    """Every module of the package but the CLI, the benchmarks and the synthetic rig."""
    out = []
    for m in pkgutil.walk_packages([str(PIPELINE)], prefix="meshphase."):
        name = m.name
        if name == "meshphase.cli" or name.startswith(("meshphase.bench", "meshphase.synthetic",
                                                       "meshphase.data_schemas")):
            continue
        out.append(name)
    return out


def test_the_package_never_imports_synthetic_at_run_time():
    mods = _package_modules()
    assert "meshphase.run.stages" in mods and "meshphase.io.sources" in mods
    code = ("import importlib, sys\n"
            f"for m in {mods!r}:\n"
            "    importlib.import_module(m)\n"
            "bad = sorted(m for m in sys.modules if m.startswith('meshphase.synthetic'))\n"
            "print(bad)\n"
            "sys.exit(1 if bad else 0)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout + out.stderr


def _synthetic_imports(path: Path) -> list[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    found = []
    for node in ast.walk(tree):
        names = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
        found += [f"{path.relative_to(PIPELINE)}:{node.lineno} {n}" for n in names
                  if n == "meshphase.synthetic" or n.startswith("meshphase.synthetic.")]
    return found


def test_no_module_of_the_package_imports_synthetic():
    files = [p for p in PIPELINE.rglob("*.py")
             if p.name != "cli.py" or p.parent != PIPELINE]
    files = [p for p in files if "bench" not in p.relative_to(PIPELINE).parts]
    assert len(files) > 50
    bad = [hit for p in files for hit in _synthetic_imports(p)]
    assert bad == []
    # the check sees an import where there is one
    assert _synthetic_imports(PIPELINE / "cli.py") or _synthetic_imports(PIPELINE / "bench" / "io.py") \
        or any(_synthetic_imports(p) for p in (PIPELINE / "bench").rglob("*.py"))
