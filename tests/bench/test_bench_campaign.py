"""The campaign speed-up benchmark (:func:`meshphase.bench.campaign.measure_speedup`): the
same campaign timed with 1 and 2 local workers. Measured, never asserted: the smoke run only
checks the table's shape."""

from __future__ import annotations

import pytest

from meshphase.bench.campaign import measure_speedup


def test_measure_speedup_lives_in_bench_only():
    # a benchmark: meshphase.campaign.runner does not reach up into bench/ for it
    from meshphase.campaign import runner as campaign

    assert not hasattr(campaign, "measure_speedup")


def test_measure_speedup_bad_input():
    with pytest.raises(ValueError, match="n_recordings"):
        measure_speedup(n_recordings=0)
    with pytest.raises(ValueError, match="minutes"):
        measure_speedup(minutes=-1)
    with pytest.raises(ValueError, match="workers"):
        measure_speedup(workers=())
    with pytest.raises(TypeError, match="workers"):
        measure_speedup(workers=2)
    with pytest.raises(ValueError, match="repeats"):
        measure_speedup(repeats=0)
    with pytest.raises(ValueError, match="scenario"):
        measure_speedup(scenario="no_such_scenario")


@pytest.mark.bench
def test_measure_speedup_smoke(tmp_path):
    res = measure_speedup(n_recordings=2, minutes=0.25, workers=(1, 2), work_dir=tmp_path)
    assert [r["workers"] for r in res["runs"]] == [1, 2]
    assert res["best_wall_s"][1] == res["runs"][0]["wall_s"]
    # (the noisy scenario's phasing may be flagged unreliable: not ok, but not failed)
    assert all(r["n_failed"] == 0 for r in res["runs"])
    phases = {"cluster_start_s", "cluster_wait_s", "scene_level_s", "processing_s", "report_s"}
    assert all(phases <= set(r) and r["cluster_wait_s"] <= r["cluster_start_s"] + 1e-6 for r in res["runs"])
    assert res["speedup"][1] == pytest.approx(1.0) and res["speedup"][2] > 0
    # one repeat: one pair, and it is the ratio of the best times
    assert res["paired_speedup"][2]["pairs"] == pytest.approx([res["speedup"][2]])


@pytest.mark.bench
def test_cli_bench_campaign_quick(tmp_path, capsys):
    # `meshphase bench campaign --quick`: both worker counts timed, the JSON written
    import json

    from meshphase.cli import main

    assert main(["bench", "campaign", "--quick", "--repeats", "2", "--out", str(tmp_path)]) == 0
    text = capsys.readouterr().out
    assert "1 worker(s)" in text and "2 worker(s)" in text and "speed-up 2 vs 1 worker" in text
    assert "each repeat's 1-worker run over its 2-worker run" in text
    assert "task CPU, two workers over one" in text
    assert "without fork_ready:" in text and "with fork_ready:" in text   # the first-figure rows
    res = json.loads((tmp_path / "campaign_bench.json").read_text())
    assert {r["case"] for r in res["first_figure"]} == {"without fork_ready", "with fork_ready"}
    assert res["task_cpu_ratio"]["1"] == 1.0 and res["task_cpu_ratio"]["2"] > 0
    assert [r["workers"] for r in res["runs"]] == [1, 2, 1, 2]
    assert len(res["paired_speedup"]["2"]["pairs"]) == 2
    assert all(r["n_failed"] == 0 for r in res["runs"])
    assert "campaign overhead on a cluster of processes (6 x 0.5 min, 2 workers" in text
    assert "overhead per recording:" in text
    ov = res["overhead"]
    assert ov["n_recordings"] == 6 and ov["n_failed"] == 0 and ov["campaign_wall_s"] > 0


def test_process_scene_asks_for_what_process_computes(tmp_path):
    """The overhead bench's scene: the demo scene's gearset and channels, the results of
    ``meshphase process`` (:data:`meshphase.run.stages.PROCESS_RESULTS`), no Monte Carlo."""
    from meshphase.bench.campaign import process_scene_text
    from meshphase.run.scene import load_scene
    from meshphase.run.stages import PROCESS_RESULTS

    p = tmp_path / "s.toml"
    p.write_text(process_scene_text())
    scene = load_scene(p)
    assert list(scene.results) == list(PROCESS_RESULTS) and scene.tolerances is None
    assert scene.gearset is not None


def test_overhead_lines_and_bad_input():
    from meshphase.bench.campaign import measure_overhead, overhead_lines

    res = {"n_recordings": 200, "minutes": 2.0, "workers": 2, "loadavg_before": [1.5, 1, 1],
           "plain_wall_s": 200.0, "campaign_wall_s": 206.0, "per_recording_plain_s": 1.0,
           "per_recording_campaign_s": 1.03, "overhead": 0.03, "n_failed": 0,
           "machinery_overhead": 0.04, "processing_overhead": 0.01}
    lines = overhead_lines(res)
    assert "200 x 2 min, 2 workers, load before 1.5" in lines[0]
    assert "+3.0 % of its plain processing" in lines[2]
    assert "+4.0 % in all" in lines[3] and "+1.0 % while the tasks ran" in lines[3]
    with pytest.raises(KeyError):
        overhead_lines({})
    with pytest.raises(ValueError, match="n_recordings"):
        measure_overhead(0)
    with pytest.raises(ValueError, match="workers"):
        measure_overhead(2, 0.1, 0)
    with pytest.raises(ValueError, match="scenario"):
        measure_overhead(2, 0.1, 2, scenario="no_such_scenario")


@pytest.mark.bench
def test_measure_overhead_smoke(tmp_path):
    from meshphase.bench.campaign import measure_overhead

    res = measure_overhead(3, 0.25, 2, distinct=1, work_dir=tmp_path)
    assert res["n_failed"] == 0 and res["plain_wall_s"] > 0
    assert res["overhead"] == pytest.approx(res["campaign_wall_s"] / res["plain_wall_s"] - 1)
    # the whole campaign takes longer than the part while its tasks ran
    assert res["machinery_overhead"] > res["processing_overhead"]
    assert len(list((tmp_path / "recordings").glob("rec_*.h5"))) == 3
    assert len(list((tmp_path / "campaign" / "recordings").iterdir())) == 3


def test_paired_speedups_pair_each_repeats_runs():
    # each repeat's 1-worker wall over its own 2-worker wall; a repeat missing a run is left out
    from meshphase.bench.campaign import _paired

    runs = [{"repeat": 0, "workers": 1, "wall_s": 12.0, "processing_s": 8.0},
            {"repeat": 0, "workers": 2, "wall_s": 6.0, "processing_s": 4.0},
            {"repeat": 1, "workers": 1, "wall_s": 15.0, "processing_s": 9.0},   # a slow spell:
            {"repeat": 1, "workers": 2, "wall_s": 10.0, "processing_s": 6.0},   # both runs slow
            {"repeat": 2, "workers": 1, "wall_s": 11.0, "processing_s": 7.0},
            {"repeat": 2, "workers": 2, "wall_s": 5.5, "processing_s": 3.5},
            {"repeat": 3, "workers": 1, "wall_s": 9.0, "processing_s": 6.0}]
    got = _paired(runs, [1, 2])
    assert list(got) == [2]
    assert got[2]["pairs"] == pytest.approx([2.0, 1.5, 2.0])
    assert got[2]["median"] == pytest.approx(2.0)
    assert _paired(runs, [1, 2], "processing_s")[2]["pairs"] == pytest.approx([2.0, 1.5, 2.0])
    assert _paired(runs, [1]) == {}
    empty = _paired([], [1, 2])[2]
    assert empty["pairs"] == [] and empty["median"] != empty["median"]   # NaN: no pair


@pytest.mark.parametrize("arg", ["0", "-1", "two", "1.5"])
def test_cli_bench_campaign_rejects_bad_repeats(arg, bench_usage_error):
    # argparse refuses before anything is generated or timed
    bench_usage_error(["campaign", "--repeats", arg], "--repeats")
