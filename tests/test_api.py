"""meshphase.read / meshphase.process / Result: the tables equal the typed stage results they
come from, the summary, the output files, and clear errors for empty and bad input."""

import errno
import json
import math
import os
import subprocess
import sys
import warnings

import numpy as np
import pandas as pd
import pytest

import meshphase
from meshphase.run.demo import demo_scene_path
import meshphase.io
import meshphase.io.sources
from meshphase.errors import NotRegularFileError
from meshphase.io import RecordingFileError, RecordingTooLargeError, write
from meshphase.api.result import Result
from meshphase.recording import ChannelSpec, Recording
from meshphase.run.context import RunContext
from meshphase.run.scene import Scene


@pytest.fixture(scope="module")
def synthetic():
    """1 min of the demo's rig (a recording in memory)."""
    from meshphase.synthetic import generate

    rec, truth = generate("rig_ripple1", duration=60.0, seed=1)
    return rec


@pytest.fixture(scope="module")
def scene_path(tmp_path_factory):
    return demo_scene_path(tmp_path_factory.mktemp("scene"))


@pytest.fixture(scope="module")
def res(synthetic, scene_path):
    """The demo scene (tolerances, so a Monte Carlo band) on the recording in memory."""
    return meshphase.process(synthetic, scene_path, tolerance=True)


@pytest.fixture(scope="module")
def rig_file(synthetic, tmp_path_factory):
    return write(synthetic, tmp_path_factory.mktemp("rec") / "rig.h5")


# ----------------------------------------------------------------------------- import
def test_import_meshphase_stays_light():
    code = ("import sys, meshphase; "
            "heavy = [m for m in ('pandas', 'matplotlib', 'scipy', 'meshphase.run.stages', "
            "'meshphase.api.process') if m in sys.modules]; print(heavy); sys.exit(1 if heavy else 0)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr


def test_public_names():
    from meshphase import io
    from meshphase.api import process as api

    assert meshphase.read is io.read
    assert meshphase.process is api.process
    assert meshphase.Result is Result
    assert meshphase.Recording is Recording
    assert {"read", "process", "Result", "Recording"} <= set(meshphase.__all__)
    assert {"read", "process", "Result"} <= set(dir(meshphase))
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        meshphase.nope  # noqa: B018


# ----------------------------------------------------------------------------- read
def test_read_gives_the_recording(synthetic, rig_file):
    rec = meshphase.read(rig_file)
    assert rec.names == synthetic.names
    np.testing.assert_array_equal(rec.data, synthetic.data)
    part = meshphase.read(rig_file, channels=["sun"], start=1.0, stop=2.0)
    assert part.names == ["sun"] and part.n_samples == int(synthetic.fs)


def test_read_empty_and_bad_input(tmp_path, rig_file):
    empty = tmp_path / "empty.h5"
    empty.write_bytes(b"")
    with pytest.raises(RecordingFileError, match="empty"):
        meshphase.read(empty)
    with pytest.raises(FileNotFoundError):
        meshphase.read(tmp_path / "missing.h5")
    with pytest.raises(TypeError):
        meshphase.read(42)
    with pytest.raises(TypeError):
        meshphase.read(rig_file, not_an_option=True)


# ------------------------------------------------------------- the same path checks as the CLI
@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no os.mkfifo on this platform")
def test_read_and_process_refuse_a_fifo_without_opening_it(tmp_path, scene_path):
    fifo = tmp_path / "pipe.h5"
    os.mkfifo(fifo)
    # refused by os.stat: opening it would block (no writer), the test would hang
    for call in (meshphase.read, meshphase.io.read_info, meshphase.io.detect_format,
                 lambda p: next(meshphase.io.iter_blocks(p, 1.0)),
                 lambda p: meshphase.io.read(p, format="hdf5"),
                 lambda p: meshphase.process(p, scene_path)):
        with pytest.raises(NotRegularFileError, match="pipe.h5: is a FIFO") as exc:
            call(fifo)
        assert isinstance(exc.value, ValueError) and exc.value.path == str(fifo)


def test_read_and_process_raise_the_same_for_a_folder_and_a_link_loop(tmp_path, scene_path):
    folder = tmp_path / "folder.h5"
    folder.mkdir()
    loop = tmp_path / "loop.h5"
    loop.symlink_to(loop)
    for call in (meshphase.read, lambda p: meshphase.process(p, scene_path)):
        with pytest.raises(IsADirectoryError, match="folder.h5: is a directory"):
            call(folder)
        with pytest.raises(OSError, match="symbolic links") as exc:   # not "no such file"
            call(loop)
        assert exc.value.errno == errno.ELOOP and exc.value.filename == str(loop)
        assert not isinstance(exc.value, FileNotFoundError)


def test_read_too_large_for_memory_names_the_file_and_size(rig_file, monkeypatch):
    def no_memory(*args, **kwargs):
        raise MemoryError()

    monkeypatch.setattr(meshphase.io.get_format("hdf5"), "read", no_memory)
    with pytest.raises(RecordingTooLargeError, match=r"rig\.h5: 307200 samples x 3 channel\(s\) "
                                                     r"\(0\.00737 GB in memory\)") as exc:
        meshphase.read(rig_file)
    assert isinstance(exc.value, MemoryError) and isinstance(exc.value, RecordingFileError)
    assert (exc.value.n_samples, exc.value.n_channels) == (307200, 3)


def test_recording_too_large_error_empty_and_bad_input():
    assert "0 samples x 0 channel(s) (0 GB in memory)" in str(RecordingTooLargeError("x.h5", 0, 0))
    with pytest.raises(ValueError):
        RecordingTooLargeError("x.h5", "many", 3)


def test_not_regular_file_error_keeps_path_and_kind():
    e = NotRegularFileError("/dev/x", "a character device", "the recording")
    assert (e.path, e.kind) == ("/dev/x", "a character device") and "/dev/x: is a character device" in str(e)
    with pytest.raises(TypeError):
        NotRegularFileError("/dev/x")


# ----------------------------------------------------------------------------- process
def test_process_runs_the_cli_stages(res):
    ctx = res.context
    assert isinstance(ctx, RunContext)
    assert res.status == "ok"
    for stage in ("load", "condition", "onsets", "phasing", "load_sharing", "ideal", "identify",
                  "tolerance", "compare"):
        assert stage in ctx.ran
    assert ctx.load.source == "<Recording in memory>"
    assert ctx.load.stream is None       # the result keeps no source of the caller's samples


def test_process_runs_the_monte_carlo_only_when_asked(rig_file, scene_path):
    # as `meshphase process`: the scene's [tolerances] are set aside unless tolerance=True
    r = meshphase.process(rig_file, scene_path)
    assert "tolerance" not in r.context.ran and r.context.scene.tolerances is None
    assert "compare" in r.context.ran
    with pytest.raises(TypeError, match="tolerance"):
        meshphase.process(rig_file, scene_path, tolerance="yes")


def test_process_file_equals_memory(res, synthetic, rig_file, scene_path, monkeypatch):
    """A Recording in memory is streamed from its own samples (no file written) and gives
    bit for bit the tables of the same recording processed from a file."""
    from_file = meshphase.process(rig_file, scene_path)
    assert from_file.context.load.source == str(rig_file.resolve())

    def no_file(*args, **kwargs):
        raise AssertionError("processing a Recording in memory wrote or read a file")

    monkeypatch.setattr(meshphase.io, "write", no_file)
    monkeypatch.setattr(meshphase.io.sources.FileSource, "__init__", no_file)
    in_memory = meshphase.process(synthetic, scene_path)
    for gear, t in from_file.context.phasing.tables.items():
        m = in_memory.context.phasing.tables[gear]
        for col in ("time", "ref_time", "gamma", "uncertainty", "planet"):
            np.testing.assert_array_equal(getattr(m, col), getattr(t, col))
        np.testing.assert_array_equal(res.context.phasing.tables[gear].gamma, t.gamma)
    for name in ("phasing", "passes", "load_sharing", "comparison"):
        pd.testing.assert_frame_equal(getattr(in_memory, name), getattr(from_file, name),
                                      check_exact=True)
    assert in_memory.context.ran == from_file.context.ran
    said = [m.replace(str(rig_file.resolve()), "<Recording in memory>")
            for m in from_file.context.messages]
    assert in_memory.context.messages == said


def test_process_default_gearset_from_metadata_and_window(rig_file, synthetic):
    seen = []
    r = meshphase.process(rig_file, start=0.0, stop=30.0, results=["phasing"],
                          progress=lambda stage, i, n: seen.append(stage))
    ctx = r.context
    assert seen == ctx.ran + ["done"]
    assert ctx.gearset.z_sun == synthetic.meta["gearset"]["z_sun"]
    assert ctx.load.recording.duration == pytest.approx(30.0)
    assert ctx.scene.results == ["phasing"]
    assert "compare" not in ctx.ran and "tolerance" not in ctx.ran
    assert r.comparison.empty and list(r.comparison.columns)[0] == "gauge"
    assert r.passes["time_s"].max() < 30.0


def test_process_empty_recording(synthetic):
    empty = Recording(np.empty((0, 3)), 5120.0, synthetic.channels, meta=synthetic.meta)
    with pytest.raises(ValueError, match="empty"):
        meshphase.process(empty)


def test_process_bad_input(synthetic, scene_path, tmp_path):
    with pytest.raises(TypeError, match="recording must be"):
        meshphase.process(42, scene_path)
    with pytest.raises(TypeError, match="recording must be"):
        meshphase.process(synthetic.data, scene_path)
    with pytest.raises(FileNotFoundError):
        meshphase.process(tmp_path / "missing.h5", scene_path)
    with pytest.raises(TypeError, match="gearset must be"):
        meshphase.process(synthetic, 42)
    with pytest.raises(TypeError, match="not both"):
        meshphase.process(synthetic, scene_path, scene=scene_path)
    with pytest.raises(ValueError, match="unknown result"):
        meshphase.process(synthetic, scene_path, results=["phasing", "nope"])
    with pytest.raises(ValueError, match="results is empty"):
        meshphase.process(synthetic, scene_path, results=[])
    with pytest.raises(TypeError, match="start must be"):
        meshphase.process(synthetic, scene_path, start="0")
    with pytest.raises(ValueError, match="outside the recording"):
        meshphase.process(synthetic, scene_path, start=100.0, stop=200.0)
    with pytest.raises(TypeError, match="progress must be"):
        meshphase.process(synthetic, scene_path, progress="yes")


def test_process_without_a_gearset_says_so(synthetic):
    bare = Recording(synthetic.data[:5120], synthetic.fs, synthetic.channels)  # no metadata
    with pytest.raises(ValueError, match="needs a gearset"):
        meshphase.process(bare)


def test_process_with_nothing_usable_raises_with_the_cause(synthetic):
    others = Recording(synthetic.data[:51200], synthetic.fs,
                       [ChannelSpec(n, kind="other") for n in synthetic.names], meta=synthetic.meta)
    with pytest.raises(meshphase.ProcessingFailed, match="no gauge channel") as exc:
        meshphase.process(others)
    assert "meshphase-" not in str(exc.value)    # the temporary file is not named
    assert isinstance(exc.value.context, RunContext)
    assert isinstance(exc.value, ValueError)


# ----------------------------------------------------------------------------- tables
def test_passes_equal_the_phasing_tables(res):
    ctx, df = res.context, res.passes
    assert list(df.columns[:6]) == ["gauge", "time_s", "planet", "revolution", "gamma_cycles",
                                    "uncertainty_cycles"]
    for gear, t in ctx.phasing.tables.items():
        d = df[df["gauge"] == gear]
        assert len(d) == len(t) > 0
        np.testing.assert_array_equal(d["time_s"], t.time)
        np.testing.assert_array_equal(d["planet"], t.planet)
        np.testing.assert_array_equal(d["gamma_cycles"], t.gamma)
        np.testing.assert_array_equal(d["uncertainty_cycles"], t.uncertainty)
        np.testing.assert_array_equal(d["mesh_period_s"], t.mesh_period)
        cmp = ctx.compare.by_gear[gear]
        np.testing.assert_array_equal(d["gamma_ideal_cycles"], cmp.ideal)
        np.testing.assert_array_equal(d["gamma_model_cycles"], cmp.model)
        r = d["residual_model_cycles"].to_numpy()
        assert np.all(np.abs(r) < 0.5)
        np.testing.assert_allclose(np.sqrt(np.mean(r ** 2)), cmp.vs_model["rms"], rtol=1e-12)


def test_phasing_equals_table_summary_and_comparison(res):
    ctx, df = res.context, res.phasing
    assert {"gamma_mean_cycles", "gamma_std_cycles", "gamma_ideal_cycles", "gamma_model_cycles",
            "residual_model_rms_cycles", "band_dev_lo_cycles"} <= set(df.columns)
    for gear, t in ctx.phasing.tables.items():
        cmp = ctx.compare.by_gear[gear]
        lo, hi = ctx.tolerance.band(gear)
        for planet, s in t.summary().items():
            row = df[(df["gauge"] == gear) & (df["planet"] == planet)].iloc[0]
            assert row["n_passes"] == s["n"]
            assert row["gamma_mean_cycles"] == s["mean"] and row["gamma_std_cycles"] == s["std"]
            assert row["gamma_ideal_cycles"] == ctx.ideal.gamma(gear)[planet - 1]
            assert row["residual_model_rms_cycles"] == cmp.vs_model["per_planet"][planet]["rms"]
            assert row["residual_ideal_mean_cycles"] == cmp.vs_ideal["per_planet"][planet]["mean"]
            assert row["band_dev_lo_cycles"] == lo[planet - 1]
            assert row["band_dev_hi_cycles"] == hi[planet - 1]
            assert abs(row["gamma_model_cycles"] - row["gamma_mean_cycles"]) < 0.01


def test_load_sharing_and_comparison_equal_the_stage_results(res):
    ctx = res.context
    ls = ctx.load_sharing.sharing
    df = res.load_sharing
    assert list(df.columns) == ["planet", "load_sharing", "std_error", "n_passes",
                                "mean_amplitude_strain"]
    np.testing.assert_array_equal(df["load_sharing"], ls.factors)
    np.testing.assert_array_equal(df["std_error"], ls.std_error)
    np.testing.assert_array_equal(df["n_passes"], ls.n_passes)
    np.testing.assert_array_equal(df["mean_amplitude_strain"], ls.mean_amplitude)
    cmp = res.comparison
    assert "rms_cycles" in cmp.columns and "coverage" in cmp.columns
    for gear, c in ctx.compare.by_gear.items():
        for ref, stats in (("ideal", c.vs_ideal), ("model", c.vs_model)):
            row = cmp[(cmp["gauge"] == gear) & (cmp["reference"] == ref)].iloc[0]
            assert row["rms_cycles"] == stats["rms"] and row["n_passes"] == stats["n"]
            assert row["std_cycles"] == stats["std"]
            assert row["coverage"] == c.coverage["inside_fraction"]


def test_identification_equals_the_table_in_m_and_rad(res):
    table = res.context.identify.identification.table
    df = res.identification
    assert list(df.columns[:9]) == ["gear", "e_m", "e_std_m", "e_ci95_lo_m", "e_ci95_hi_m",
                                    "kappa_rad", "kappa_std_rad", "identifiable", "note"]
    assert list(df["gear"]) == [r["gear"] for r in table]
    np.testing.assert_array_equal(df["e_m"], [r["e"] for r in table])
    np.testing.assert_array_equal(df["kappa_rad"], [r["kappa"] for r in table])
    np.testing.assert_array_equal(df["identifiable"], [r["identifiable"] for r in table])


def test_centroids_empty_without_facewidth_gauges(res):
    df = res.centroids
    assert df.empty and list(df.columns) == ["gear", "centroid_m", "std_error_m",
                                             "contact_fraction", "shape", "residual_rms_strain"]
    assert df.attrs["units"]["centroid_m"] == "m"


def test_tables_are_the_csv_files_columns_and_values(res, tmp_path):
    """The DataFrames a notebook sees and the CSV files a run writes: one name, one unit."""
    files = res.write(tmp_path / "out", report=False)
    for gear in res.context.phasing.tables:
        csv = pd.read_csv(files[f"passes_{gear}"])
        df = res.passes
        d = df[df["gauge"] == gear].reset_index(drop=True)
        assert list(d.columns[:len(csv.columns)]) == list(csv.columns)
        pd.testing.assert_frame_equal(pd.DataFrame(d[list(csv.columns)]), csv, check_exact=True)
    for table, name in (("load_sharing", "load_sharing"), ("identification", "identified_errors")):
        df = getattr(res, table)
        csv = pd.read_csv(files[name], keep_default_na=False, na_values=[""])
        assert list(df.columns) == list(csv.columns), table
        assert df.attrs["file"] == f"{name}.csv"
        for c in df.columns:
            if pd.api.types.is_float_dtype(df[c]):
                np.testing.assert_array_equal(df[c].to_numpy(), csv[c].to_numpy(), err_msg=c)
            else:
                assert df[c].astype(str).tolist() == csv[c].astype(str).tolist(), c


def test_every_column_of_every_table_has_a_unit(res):
    for name in ("passes", "phasing", "load_sharing", "comparison", "identification", "centroids"):
        df = getattr(res, name)
        units = df.attrs["units"]
        assert list(units) == list(df.columns), name
        assert df.attrs["table"] == name and df.attrs["description"], name
        for c, u in units.items():      # a number has a unit ("1": a count or ratio), a label none
            numeric = pd.api.types.is_numeric_dtype(df[c]) and not pd.api.types.is_bool_dtype(df[c])
            assert df.empty or (u != "") == numeric, (name, c, u)
    assert res.passes.attrs["units"]["gamma_cycles"] == "cycles"
    assert res.passes.attrs["units"]["time_s"] == "s"
    assert res.load_sharing.attrs["units"]["mean_amplitude_strain"] == "strain"
    assert res.identification.attrs["units"]["e_m"] == "m"
    assert res.identification.attrs["units"]["kappa_rad"] == "rad"
    assert res.load_sharing.attrs["units"]["load_sharing"] == "1"


def test_old_column_names_answer_with_a_future_warning_in_the_old_unit(res):
    df = res.identification
    with pytest.warns(FutureWarning, match="'e_um' is now 'e_m' \\[m\\]"):
        e_um = df["e_um"]
    np.testing.assert_allclose(e_um, df["e_m"] * 1e6, rtol=1e-15)
    assert e_um.name == "e_um"
    with pytest.warns(FutureWarning, match="'kappa_deg' is now 'kappa_rad'"):
        np.testing.assert_allclose(df.kappa_deg, np.degrees(df["kappa_rad"]), rtol=1e-15)
    p = res.passes
    with pytest.warns(FutureWarning, match="'phasing_cycles' is now 'gamma_cycles'"):
        np.testing.assert_array_equal(p["phasing_cycles"], p["gamma_cycles"])
    with pytest.warns(FutureWarning, match="'sigma_cycles' is now 'uncertainty_cycles'"):
        sub = p[["gauge", "sigma_cycles"]]
    assert list(sub.columns) == ["gauge", "sigma_cycles"]
    np.testing.assert_array_equal(sub["sigma_cycles"], p["uncertainty_cycles"])
    with pytest.warns(FutureWarning, match="mean_amplitude_ustrain"):
        np.testing.assert_allclose(res.load_sharing["mean_amplitude_ustrain"],
                                   res.load_sharing["mean_amplitude_strain"] * 1e6, rtol=1e-15)
    with pytest.warns(FutureWarning, match="'mean_cycles' is now 'gamma_mean_cycles'"):
        res.phasing["mean_cycles"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res.comparison["mean_cycles"]         # a current column of this table: no warning
        p["gamma_cycles"]
    with pytest.raises(KeyError):
        p["no_such_column"]


def test_old_column_names_survive_common_operations(res):
    import pickle

    p = res.passes
    derived = {"mask": p[p["planet"] == 2], "head": p.head(3), "sort": p.sort_values("time_s"),
               "copy": p.copy(), "query": p.query("planet == 2"), "assign": p.assign(x=1.0),
               "reset_index": p.reset_index(), "dropna": p.dropna(subset=["gamma_cycles"]),
               "concat": pd.concat([p, p]), "merge": p.merge(p[["time_s"]], on="time_s"),
               "pickle": pickle.loads(pickle.dumps(p)), "loc": p.loc[p["planet"] == 1]}
    for op, d in derived.items():
        assert isinstance(d, type(p)), op
        assert d.attrs["units"]["gamma_cycles"] == "cycles", op
        with pytest.warns(FutureWarning, match="phasing_cycles"):
            np.testing.assert_array_equal(d["phasing_cycles"], d["gamma_cycles"], err_msg=op)


def test_summary(res):
    s = res.summary()
    ctx = res.context
    assert s["status"] == "ok" and s["error"] is None
    assert s["duration_s"] == pytest.approx(60.0) and s["fs_hz"] == 5120.0
    assert s["passes_sun"] == len(ctx.phasing.tables["sun"])
    assert s["reliable_sun"] is True
    assert s["error_estimate_sun_cycles"] == ctx.phasing.reliability["sun"]["error_estimate"]
    assert s["rms_vs_model_ring_cycles"] == ctx.compare.by_gear["ring"].vs_model["rms"]
    assert s["load_sharing_max_dev"] == pytest.approx(
        np.max(np.abs(ctx.load_sharing.sharing.factors - 1)))
    assert s["identify_rms_after_cycles"] == ctx.identify.identification.rms_after
    json.dumps(s)                                  # plain values only
    assert not any(k.startswith(("sun_", "ring_")) for k in s)


def test_summary_old_keys_answer_with_a_future_warning(res):
    s = res.summary()
    with pytest.warns(FutureWarning, match="'sun_passes' is now 'passes_sun'"):
        assert s["sun_passes"] == s["passes_sun"]
    with pytest.warns(FutureWarning, match="'ring_sigma_cycles' is now 'error_estimate_ring_cycles'"):
        assert s.get("ring_sigma_cycles") == s["error_estimate_ring_cycles"]
    assert "sun_passes" not in s and s.get("nope", 3) == 3
    with pytest.raises(KeyError):
        s["nope"]
    with pytest.raises(KeyError):
        Result(_empty_ctx()).summary()["sun_passes"]      # no gauge: no key, old or new


def test_repr(res):
    assert repr(res).startswith("Result(ok, <Recording in memory>; ")


def test_write_outputs(res, tmp_path):
    files = res.write(tmp_path / "out", report=False)
    assert files["summary"] == tmp_path / "out" / "summary.json"
    summary = json.loads(files["summary"].read_text())
    assert summary["status"] == "ok"
    assert summary["recording"]["source"] == "<Recording in memory>"
    assert (tmp_path / "out" / "passes_sun.csv").is_file()
    again = res.write(tmp_path / "out", report=False)       # kept: a new folder beside it
    assert again["summary"].parent == tmp_path / "out-2"


def test_write_outputs_takes_the_callers_summary(res, tmp_path):
    from meshphase.run.outputs import summary_dict, write_outputs

    given = summary_dict(res.context)
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    write_outputs(res.context, tmp_path / "a", report=False)
    write_outputs(res.context, tmp_path / "b", report=False, summary=given)
    assert (tmp_path / "a" / "summary.json").read_text() == (tmp_path / "b" / "summary.json").read_text()
    with pytest.raises(TypeError, match="summary must be"):
        write_outputs(res.context, tmp_path / "b", report=False, summary=[given])


def test_write_bad_input(res, tmp_path):
    with pytest.raises(TypeError, match="folder must be a path"):
        res.write(42)
    with pytest.raises(ValueError, match="empty path"):
        res.write("")


# ----------------------------------------------------------------------------- Result alone
def _empty_ctx():
    return RunContext(Scene(path=None, name="empty", results=[]))


def test_result_of_an_empty_run_has_empty_tables():
    r = Result(_empty_ctx())
    for name in ("passes", "phasing", "load_sharing", "comparison", "identification", "centroids"):
        df = getattr(r, name)
        assert df.empty and len(df.columns) > 2, name
    s = r.summary()
    assert s["status"] == r.status and "passes_sun" not in s and "load_sharing_max_dev" not in s
    assert f"meshphase result: {r.status}" in r._repr_html_()


def test_result_bad_input():
    with pytest.raises(TypeError, match="RunContext"):
        Result({"phasing": {}})
    with pytest.raises(TypeError, match="RunContext"):
        Result(None)
