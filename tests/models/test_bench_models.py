"""Smoke test of the Monte Carlo error-vs-runtime benchmark (meshphase.bench.models).

Timings are measured, never asserted: only the files, the table layout and the sanity of the
errors are checked.
"""

import json
import math

import pytest

from meshphase.bench.models import TABLE_COLUMNS, _interp_crossover, _sobol_count, run_models_bench


def test_quick_bench_writes_table_json_and_figure(tmp_path):
    res = run_models_bench(tmp_path, quick=True, rng=1)
    for name in ("models_bench.json", "models_bench.md", "models_bench.png"):
        assert (tmp_path / name).is_file() and (tmp_path / name).stat().st_size > 0
    md = (tmp_path / "models_bench.md").read_text().splitlines()
    header = next(line for line in md if line.startswith("| sampler"))
    assert [c.strip() for c in header.strip("|").split("|")] == list(TABLE_COLUMNS)
    data = json.loads((tmp_path / "models_bench.json").read_text())
    assert {r["sampler"] for r in data["rows"]} == {"random", "sobol"}
    assert len(data["rows"]) == 4
    for r in data["rows"]:
        assert set(TABLE_COLUMNS) <= set(r)
        assert r["wall_time_s"] > 0
        assert 0 < r["err_moments"] < 5 and 0 < r["err_quantile"] < 5
        if r["sampler"] == "sobol":
            assert r["n_samples"] in (64, 256)          # 8 replicates x 2**m
    assert data["reference"]["n_samples"] == 4096
    # with a fixed ring and the default window the ring offset turns exactly once: Ave_rn has
    # no spread and its metrics are skipped, not divided by zero
    assert "mean_ave_r" in data["reference"]["skipped_metrics"]
    assert data["meta"]["window"]["name"] == "slowest-offset"
    assert "err_max" in data["crossover"]["metrics"]
    assert res["files"]["figure"].endswith("models_bench.png")
    tp = data["meta"]["kernel_throughput"]
    assert tp["one_thread"] > 0 and tp["all_threads"] > 0 and tp["numpy"] > 0
    assert any("the numpy path (no numba" in line for line in md)


def test_bench_helpers():
    assert _sobol_count(100000, 8) == 131072 and _sobol_count(64, 8) == 64
    assert _sobol_count(1, 8) == 8
    # log-log interpolation between (100, 1.0) and (10000, 0.01): 0.1 is reached at n = 1000
    assert _interp_crossover([100, 10000], [1.0, 0.01], 0.1) == pytest.approx(1000)
    assert _interp_crossover([100, 10000], [1.0, 0.5], 0.1) != _interp_crossover([1], [1], 2)
    assert math.isnan(_interp_crossover([100, 10000], [1.0, 0.5], 0.1))
    assert _interp_crossover([], [], 0.1) != _interp_crossover([], [], 0.1)   # nan when empty


def test_bench_bad_inputs(tmp_path):
    with pytest.raises(ValueError):
        run_models_bench(tmp_path, samplers=("halton",), quick=True)
    with pytest.raises(ValueError):
        run_models_bench(tmp_path, window="forever", quick=True)
    with pytest.raises(ValueError):
        run_models_bench(tmp_path, sample_counts=(0,), n_repeats=1, reference_samples=64,
                         figure=False)
