"""The io benchmark runs end to end on a tiny recording and reports what it promises.

Only the shape of the report is asserted (files, columns, positive numbers): timings are
measured, never asserted.
"""

from __future__ import annotations

import importlib.util
import json

import numpy as np
import pytest

from meshphase.bench.io import COLUMNS, IO_FORMATS, TARGETS, run_io_bench, strain_recording


def _present():
    return [f for f in IO_FORMATS if importlib.util.find_spec(f"meshphase.io.{f}") is not None]


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    out = tmp_path_factory.mktemp("io_bench")
    res = run_io_bench(out, minutes=0.05, n_channels=3, block_budget_mb=0.2, repeats=1,
                       progress=False, rng=7)
    return out, res


def test_tiny_run_writes_json_and_markdown(tiny):
    out, res = tiny
    js = json.loads((out / "io_bench.json").read_text())
    md = (out / "io_bench.md").read_text()
    assert js["config"]["n_samples"] == round(0.05 * 60 * 5120)
    assert js["config"]["n_channels"] == 3
    assert js["raw"]["prealloc_msps"] > 0 and js["raw"]["np_load_msps"] > 0
    rows = js["rows"]
    assert rows and all(set(r) == set(COLUMNS) for r in rows)
    present = _present()
    assert sorted({r["format"] for r in rows}) == sorted(present)
    assert sorted(s["format"] for s in js["skipped"]) == sorted(set(IO_FORMATS) - set(present))
    if "mcap" in present:
        assert sorted(r["variant"] for r in rows if r["format"] == "mcap") == ["lz4", "none", "zstd"]
    if "tdms" in present:
        # large segments; 512 and 1000 per segment, contiguous and interleaved; 512 with the
        # plan not cached and through npTDMS's read_data; the interleaved ones on numpy rows
        tdms_variants = [r["variant"] for r in rows if r["format"] == "tdms"]
        assert len(tdms_variants) == 9
        assert [v for v in tdms_variants if v.endswith("numpy rows")] == [
            "512 samples/segment, interleaved, numpy rows", "1000 samples/segment, interleaved, numpy rows"]
        warm = js["config"]["tdms_rows_engine"]
        assert warm["engine"] in ("numba", "numpy") and warm["seconds"] >= 0
        assert any("TDMS interleaved rows" in n for n in js["notes"])
    for r in rows:
        for key in ("file_mb", "write_s", "read_s", "read_msps", "ratio_to_raw", "one_channel_msps",
                    "window_msps", "stream_peak_mb_1x", "stream_peak_mb_4x"):
            assert isinstance(r[key], float) and np.isfinite(r[key]) and r[key] > 0, (r["format"], key)
        assert r["exact"] is True  # every format returns the samples that were written
        assert r["target_ratio"] == TARGETS.get(r["format"])
        assert isinstance(r["meets_target"], bool)
        if r["format"] == "csv":
            assert r["pandas_c_msps"] > 0 and r["csv_over_pandas"] > 0
        else:
            assert r["pandas_c_msps"] is None and r["csv_over_pandas"] is None
    # the markdown table has a header, a rule and one line per row
    table = [ln for ln in md.split("\n## ")[0].splitlines() if ln.startswith("|")]
    assert len(table) == 2 + len(rows)
    if "mcap" in present:  # own MCAP layout (fast path) against the generic decoder path
        paths = js["mcap_paths"]
        assert [r["reader"].split(" (")[0] for r in paths][:2] == ["fast path", "generic decoder path"]
        assert all(r["exact"] is True and r["read_msps"] > 0 and r["messages"] > 0 for r in paths)
        assert paths[0]["x_fast"] == 1.0
        assert "## MCAP: own layout (fast path) against the generic decoder path" in md
    assert "read MS/s" in table[0] and "x raw" in table[0] and "stream peak 4x MB" in table[0]
    assert res["files"]["json"].endswith("io_bench.json")
    # the written test files are cleaned up
    assert not [p for p in out.iterdir() if p.is_dir()]


def test_strain_recording_shape_and_randomness():
    a = strain_recording(1000, 3, 5120.0, rng=1)
    b = strain_recording(1000, 3, 5120.0, rng=1)
    c = strain_recording(1000, 3, 5120.0, rng=2)
    assert a.data.shape == (1000, 3) and a.data.dtype == np.float64
    assert np.array_equal(a.data, b.data) and not np.array_equal(a.data, c.data)
    assert 5e-5 < a.data.max() < 2e-4  # pulse peaks ~1e-4 m/m
    assert strain_recording(0, 2).data.shape == (0, 2)  # empty input


@pytest.mark.parametrize("kwargs, exc", [
    ({"formats": ()}, ValueError), ({"formats": ("xls",)}, ValueError),
    ({"formats": ("mcap", "mcap")}, ValueError), ({"minutes": 0.0}, ValueError),
    ({"minutes": "long"}, TypeError), ({"n_channels": 0}, ValueError),
    ({"block_budget_mb": -1.0}, ValueError), ({"repeats": 0}, ValueError),
    ({"minutes": 1e-6}, ValueError)])
def test_bad_arguments(tmp_path, kwargs, exc):
    with pytest.raises(exc):
        run_io_bench(tmp_path, progress=False, **kwargs)
    assert not (tmp_path / "io_bench.json").exists()


def test_strain_recording_bad_input():
    with pytest.raises(ValueError):
        strain_recording(-1, 2)
    with pytest.raises(TypeError):
        strain_recording(10.5, 2)
    with pytest.raises(ValueError):
        strain_recording(10, 0)


def test_cli_bench_io_prints_the_peak_rss_of_convert_and_process(tmp_path, capsys, monkeypatch):
    # `meshphase bench io --rss-minutes` measures convert and process in child processes
    # and prints one line per measurement; only the report's shape is asserted (the numbers
    # are measured: the 10 min / 1 h / 3 h ones are in the io bench's Markdown)
    from meshphase import bench
    from meshphase.bench import io as bio
    from meshphase.cli import main

    real = bio.run_io_bench

    def small(out, **kw):          # a tiny read-throughput part; the RSS lengths as given
        kw.update(minutes=0.02, n_channels=2, formats=("hdf5",), repeats=1, progress=False)
        return real(out, **kw)

    monkeypatch.setattr(bio, "run_io_bench", small)
    assert main(["bench", "io", "--out", str(tmp_path / "b"), "--rss-minutes", "0.05"]) == 0
    out = capsys.readouterr().out.splitlines()
    conv = [ln for ln in out if ln.startswith("convert")]
    proc = [ln for ln in out if ln.startswith("process")]
    assert len(conv) == 2 and len(proc) == 1                   # hdf5 -> mcap -> hdf5; process
    assert all("0.05 min x 8 ch" in ln and "peak RSS" in ln for ln in conv + proc)
    js = json.loads((tmp_path / "b" / "io_bench.json").read_text())
    assert js["process"][0]["peak_rss_mb"] > 0 and js["process"][0]["n_onsets"] > 0
    assert all(js["process"][0][k] > 0 for k in ("read_checked_s", "read_unchecked_s", "read_library_s"))
    md = (tmp_path / "b" / "io_bench.md").read_text()
    assert "meshphase process: peak memory" in md and "meshphase convert: peak memory" in md
    assert bench.rss_summary({}) == []                         # nothing measured: no line


@pytest.mark.parametrize("arg", ["ten", "10,-1", "nan", "10,,60"])
def test_cli_bench_rss_minutes_bad_value_is_a_usage_error(arg, bench_usage_error):
    bench_usage_error(["io", "--rss-minutes", arg], "--rss-minutes")


def test_run_bench_rss_minutes_bad_type(tmp_path):
    from meshphase.bench import run_bench

    with pytest.raises(TypeError, match="rss_minutes"):
        run_bench("io", tmp_path, rss_minutes="10")
    with pytest.raises(ValueError, match="rss_minutes"):
        run_bench("io", tmp_path, rss_minutes=(0.0,))
