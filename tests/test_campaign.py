"""`meshphase campaign`: many recordings, one scene, one Dask job.

The recordings are generated in code (20 s of the seed rig, a few MB each) in three formats,
plus a truncated HDF5 file that must be reported as failed while the others finish. The Dask
runs use real worker processes (LocalCluster, processes=True): one run lets the campaign
start its own cluster (the default path), the others share one module-scoped cluster through
its scheduler address (the ``--scheduler`` path). Numbers compared between recordings are
regression values of our own pipeline, not paper values.
"""

from __future__ import annotations

import importlib.util
import json
import os
import sys
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pytest
from seed_rig_toml import SEED_RIG_GEARSET
from hypothesis import given, settings
from hypothesis import strategies as st

from meshphase.campaign import runner as cp
from meshphase.report import campaign_report as crep
from meshphase.run.scene import load_scene

SCENE = """\
name = "campaign test scene"
results = ["ideal_phasing", "phasing", "load_sharing", "compare", "tolerance"]

""" + SEED_RIG_GEARSET + """
[input]
synthetic = "seed_rig"
minutes = 0.1

[tolerances]
e_sun_mm = 0.2
e_ring_mm = 0.5
e_planet_mm = 0.2
samples = 512
sampler = "sobol"
"""

GOOD = ("rig_a.h5", "rig_b.csv", "rig_c.mcap")


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    """Scene + a folder with 3 good recordings (hdf5, csv, mcap; truth sidecars beside
    them) and one truncated HDF5 file."""
    from meshphase.synthetic import cli_synth

    root = tmp_path_factory.mktemp("campaign")
    scene = root / "scene.toml"
    scene.write_text(SCENE)
    rec = root / "recordings"
    rec.mkdir()
    for k, name in enumerate(GOOD):
        cli_synth("seed_rig", rec / name, minutes=40 / 60, seed=10 + k, progress=False)
    raw = (rec / "rig_a.h5").read_bytes()
    (rec / "broken.h5").write_bytes(raw[: len(raw) // 3])  # HDF5 magic intact, body cut off
    return {"root": root, "scene": scene, "recordings": rec}


@pytest.fixture(scope="module")
def cluster():
    """One LocalCluster (2 single-threaded worker processes) shared through its address.

    ``allowed-failures = 0``: a task whose worker dies is not retried on another worker (the
    default retries 3 times, each costing a worker restart), so the worker-death test is
    quick; ``worker-saturation = 1.0`` (as the campaign's own cluster): no task waits queued on
    the dying worker, where it would count as a failure too. ``dashboard_address=
    "127.0.0.1:0"``: the scheduler's HTTP server always starts; on a free port it never warns
    "Port 8787 is already in use" (a UserWarning, an error here) when another cluster runs on
    this machine, and on loopback only (":0" would listen on all interfaces).
    """
    import dask
    from distributed import LocalCluster

    with dask.config.set({"distributed.scheduler.allowed-failures": 0,
                          "distributed.scheduler.worker-saturation": 1.0}):
        cl = LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                          dashboard_address="127.0.0.1:0")
    yield cl
    cl.close()


# ---------------------------------------------------------------------------- the task
def test_run_recording_good_and_corrupt_in_process(data, tmp_path):
    """The task itself, no Dask: results for a good file, a failure (with the reader's
    message) for a truncated one, JSON-friendly either way, band coverage from given bands."""
    bands = {"sun": {"lo": [-0.05] * 4, "hi": [0.05] * 4}, "ring": {"lo": [-0.05] * 4, "hi": [0.05] * 4}}
    good = cp.run_recording(str(data["scene"]), str(data["recordings"] / "rig_a.h5"),
                            str(tmp_path / "a"), bands=bands)
    assert good["status"] == "ok", good["error"]
    assert good["format"] == "hdf5"
    assert good["phasing"]["sun"]["n_passes"] > 0
    assert good["compare"]["sun"]["coverage"] == pytest.approx(1.0)  # +-0.05 cycles holds all passes
    assert "tolerance" not in good["stages_ran"]  # the Monte Carlo is the client's job
    assert (tmp_path / "a" / "summary.json").is_file() and not (tmp_path / "a" / "report.html").exists()
    json.dumps(good, allow_nan=True)
    bad = cp.run_recording(str(data["scene"]), str(data["recordings"] / "broken.h5"), str(tmp_path / "b"))
    assert bad["status"] == "failed"
    assert "broken.h5" in bad["error"] and "HDF5" in bad["error"]
    json.dumps(bad, allow_nan=True)
    missing = cp.run_recording(str(data["scene"]), str(tmp_path / "nope.h5"), str(tmp_path / "c"))
    assert missing["status"] == "failed" and "nope.h5" in missing["error"]
    noscene = cp.run_recording(str(tmp_path / "no_scene.toml"), str(data["recordings"] / "rig_a.h5"),
                               str(tmp_path / "d"))
    assert noscene["status"] == "failed" and "FileNotFoundError" in noscene["error"]


# ---------------------------------------------------------------------------- Dask runs
def test_campaign_default_local_cluster(data, tmp_path, capsys, monkeypatch):
    """The default path: the campaign starts a 2-process LocalCluster, every good recording
    has results, the truncated one is failed with its message, the combined outputs name all.
    The progress bar is drawn when stderr is a terminal (here: said to be one)."""
    from meshphase.campaign import job as job_mod

    monkeypatch.setattr(job_mod, "stderr_is_terminal", lambda: True)
    out = tmp_path / "camp"
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)   # the bar is drawn on a terminal only
    res = cp.cli_campaign(str(data["scene"]), [str(data["recordings"])], workers=2, out=str(out),
                          progress=True)
    assert "recordings" in capsys.readouterr().err  # the tqdm bar went to stderr
    by = {Path(r["recording"]).name: r for r in res["recordings"]}
    assert set(by) == set(GOOD) | {"broken.h5"}  # sidecars (*.truth.json) were skipped
    assert {Path(s["path"]).name for s in res["skipped_inputs"]} == {g + ".truth.json" for g in GOOD}
    for name in GOOD:
        r = by[name]
        assert r["status"] == "ok", r["error"]
        assert r["phasing"]["sun"]["per_planet"], name
        assert r["compare"]["sun"]["coverage"] is not None  # band from the client's Monte Carlo
        assert (out / "recordings" / r["name"] / "summary.json").is_file()
        assert (out / "recordings" / r["name"] / cp.DONE_NAME).is_file()  # complete: marker written
    assert {by[n]["format"] for n in GOOD} == {"hdf5", "csv", "mcap"}
    # the same signal in three formats (different seeds): regression check that they agree
    # to well within the pass-to-pass scatter of 1e-2 cycles
    means = [by[n]["phasing"]["sun"]["per_planet"]["3"]["mean"] for n in GOOD]
    assert np.ptp(means) < 1e-2
    assert by["broken.h5"]["status"] == "failed"
    assert "broken.h5" in by["broken.h5"]["error"] and "truncated" in by["broken.h5"]["error"]
    assert res["counts"] == {"ok": 3, "unreliable": 0, "partial": 0, "failed": 1}
    assert res["cluster"]["local"] and res["cluster"]["n_workers"] == 2
    assert len({r["worker"] for r in res["recordings"]}) == 2  # both processes did work
    assert res["results_client"] == ["tolerance"]
    assert (out / "scene" / "summary.json").is_file()
    saved = json.loads((out / "campaign.json").read_text())
    assert [r["name"] for r in saved["recordings"]] == [r["name"] for r in res["recordings"]]
    csv = (out / "campaign.csv").read_text().splitlines()
    assert len(csv) == 5 and csv[0].startswith("name,recording,format,status,error")
    html = (out / "campaign_report.html").read_text()
    for r in res["recordings"]:
        assert r["name"] in html
    assert "truncated" in html and "Phasing per planet" in html


# columns that tell where and how fast a recording ran, not what it gave
_RUN_COLUMNS = ("wall_time_s", "worker", "out_dir")


def test_one_and_two_workers_give_the_same_results(data, tmp_path):
    """The cluster starting in the background (meanwhile the scene-level Monte Carlo runs)
    and closing while the report is written changes no result: campaign.csv, each
    recording's tables and the scene-level outputs are the same with 1 and 2 workers."""
    import pandas as pd

    outs, res = {}, {}
    for w in (1, 2):
        outs[w] = tmp_path / f"camp-{w}w"
        res[w] = cp.run_campaign(data["scene"], [data["recordings"]], outs[w], workers=w, progress=False)
        assert res[w]["cluster"]["n_workers"] == w
        tm = res[w]["timing_s"]
        assert {"cluster_start", "cluster_wait", "scene_level", "processing", "report", "total"} <= set(tm)
        assert 0.0 <= tm["cluster_wait"] <= tm["cluster_start"] + 1e-6 and tm["total"] >= tm["processing"]
    csv1, csv2 = (pd.read_csv(outs[w] / "campaign.csv").drop(columns=list(_RUN_COLUMNS)) for w in (1, 2))
    pd.testing.assert_frame_equal(csv1, csv2)
    assert csv1["status"].tolist().count("ok") == len(GOOD)
    for r in res[1]["recordings"]:
        tables = sorted(p.name for p in (outs[1] / "recordings" / r["name"]).glob("*.csv"))
        assert tables == sorted(p.name for p in (outs[2] / "recordings" / r["name"]).glob("*.csv"))
        for name in set(tables) - {"stages.csv"}:  # stages.csv: the stages' wall times
            assert ((outs[1] / "recordings" / r["name"] / name).read_bytes()
                    == (outs[2] / "recordings" / r["name"] / name).read_bytes()), (r["name"], name)
    s1, s2 = (json.loads((outs[w] / "scene" / "summary.json").read_text()) for w in (1, 2))
    s1["tolerance"].pop("wall_time"), s2["tolerance"].pop("wall_time")
    assert s1["tolerance"] == s2["tolerance"]
    assert sorted(p.name for p in (outs[1] / "figures").iterdir()) == sorted(
        p.name for p in (outs[2] / "figures").iterdir())


def _die_on_rig_b(scene_path, recording_path, out_dir, **kw):
    """A task whose worker process dies on one recording (as a segfault or the OOM killer would)."""
    if Path(recording_path).name == "rig_b.csv":
        os._exit(3)
    return cp.run_recording(scene_path, recording_path, out_dir, **kw)


def test_campaign_on_existing_scheduler_dying_worker_and_no_overwrite(data, cluster, tmp_path):
    """``--scheduler ADDRESS``: an existing cluster is used and left running.

    A worker process dying under one recording fails that recording only. Five tasks on 2
    worker threads are more than twice the threads, so the scheduler queues them and a worker
    holds only the task it runs (fewer are assigned eagerly, and a task waiting on the dying
    worker would count as killed too; with the default allowed-failures = 3 it would be
    retried instead, at the cost of worker restarts). A second run into the same folder goes
    to ``-2`` and leaves the first untouched.
    """
    import cloudpickle

    files = [data["recordings"] / n for n in GOOD]
    for k, src in enumerate(files[::2]):  # two more recordings: copies under other names
        dst = tmp_path / f"copy_{k}{src.suffix}"
        dst.write_bytes(src.read_bytes())
        files.append(dst)
    out = tmp_path / "camp"
    # the workers cannot import this test module: ship the task function by value
    cloudpickle.register_pickle_by_value(sys.modules[__name__])
    try:
        r1 = cp.run_campaign(data["scene"], files, out, scheduler=cluster.scheduler_address,
                             progress=False, task=_die_on_rig_b)
    finally:
        cloudpickle.unregister_pickle_by_value(sys.modules[__name__])
    by = {Path(r["recording"]).name: r for r in r1["recordings"]}
    assert by["rig_b.csv"]["status"] == "failed"
    assert "KilledWorker" in by["rig_b.csv"]["error"]
    assert all(by[f.name]["status"] == "ok" for f in files if f.name != "rig_b.csv"), \
        {k: v["error"] for k, v in by.items()}
    assert "rig_b" in (out / "campaign_report.html").read_text()
    assert not r1["cluster"]["local"] and r1["cluster"]["scheduler"] == cluster.scheduler_address
    first = (out / "campaign.json").read_bytes()
    r2 = cp.run_campaign(data["scene"], [files[0], data["recordings"] / "broken.h5"], out,
                         scheduler=cluster.scheduler_address, progress=False)
    assert Path(r1["out_dir"]) == out.resolve()
    assert Path(r2["out_dir"]) == Path(f"{out}-2").resolve()
    assert (out / "campaign.json").read_bytes() == first
    assert r2["counts"] == {"ok": 1, "unreliable": 0, "partial": 0, "failed": 1}
    assert cluster.status.name == "running"  # not ours to close


def _phasing_only_scene(folder: Path) -> Path:
    """The test scene asking for phasing only, no Monte Carlo (quick; statuses are the point)."""
    scene = folder / "phasing_only.toml"
    scene.write_text(SCENE.replace('["ideal_phasing", "phasing", "load_sharing", "compare", "tolerance"]',
                                   '["phasing"]').split("[tolerances]")[0])
    return scene


def test_campaign_cli_exit_codes(data, cluster, tmp_path, capsys):
    """`meshphase campaign`: any recording failed -> exit 3 (the table lists all, the failed one
    with its cause on stderr); every recording failed -> exit 1 (nothing usable)."""
    from meshphase.cli import main

    rec = data["recordings"]
    out = tmp_path / "camp"
    scene = _phasing_only_scene(tmp_path)
    rc = main(["-q", "campaign", str(scene), str(rec / "rig_a.h5"), str(rec / "broken.h5"),
               "--scheduler", cluster.scheduler_address, "--out", str(out)])
    cap = capsys.readouterr()
    assert rc == 3
    assert "1 ok, 0 unreliable, 0 partial, 1 failed" in cap.out
    assert "failed     broken" in cap.out
    err = cap.err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("meshphase campaign: failed: ")
    assert "broken.h5: cannot load the recording" in err[0]
    assert "truncated" in err[0]
    rows = (out / "campaign.csv").read_text().splitlines()
    assert len(rows) == 3 and {r.split(",")[0] for r in rows[1:]} == {"rig_a", "broken"}
    assert json.loads((out / "campaign.json").read_text())["exit_code"] == 3
    rc = main(["-q", "campaign", str(scene), str(rec / "broken.h5"),
               "--scheduler", cluster.scheduler_address, "--out", str(tmp_path / "all_bad")])
    assert rc == 1 and "0 ok, 0 unreliable, 0 partial, 1 failed" in capsys.readouterr().out
    # exit 1, and the folder is written all the same (the exit table says so): the causes
    summ = json.loads((tmp_path / "all_bad" / "campaign.json").read_text())
    assert summ["exit_code"] == 1 and [r["status"] for r in summ["recordings"]] == ["failed"]
    assert "truncated" in summ["recordings"][0]["error"]


def test_run_recording_unreliable_phasing_is_not_ok(data, tmp_path, monkeypatch):
    """A recording whose phasing the run flags unreliable is "unreliable" (exit 3), not "ok"."""
    import warnings

    from meshphase.errors import ProcessingWarning
    from meshphase.run.stages import STAGE_FUNCTIONS

    original = STAGE_FUNCTIONS["phasing"]

    def flagged(ctx):
        original(ctx)
        reason = "sun gauge: encoder misfit 3e-2 mesh cycles; phasing not reliable"
        ctx.phasing.reliability["sun"] = {"reliable": False, "reasons": [reason]}
        warnings.warn(reason, ProcessingWarning, stacklevel=2)

    monkeypatch.setitem(STAGE_FUNCTIONS, "phasing", flagged)
    r = cp.run_recording(str(_phasing_only_scene(tmp_path)), str(data["recordings"] / "rig_a.h5"),
                         str(tmp_path / "a"))
    assert r["status"] == "unreliable"
    assert r["unreliable"] == {"sun": ["sun gauge: encoder misfit 3e-2 mesh cycles; phasing not reliable"]}
    assert "sun gauge phasing" in r["error"] and r["missing_results"] == []
    assert json.loads((tmp_path / "a" / "summary.json").read_text())["status"] == "unreliable"
    assert cp.campaign_exit_code({"recordings": [r]}) == 3
    assert cp.campaign_rows([r])[0]["status"] == "unreliable"


def test_campaign_interrupted_exits_130_and_leaves_no_folder(data, tmp_path, monkeypatch, capsys):
    """Ctrl-C during a campaign: exit 130, the campaign folder it had reserved is removed."""
    from meshphase.cli import main

    def ctrl_c(scene, scene_path, inputs, files, skipped, names, out, *rest):
        (out / "campaign.csv").write_text("half written")
        raise KeyboardInterrupt

    monkeypatch.setattr(cp, "_campaign_body", ctrl_c)
    out = tmp_path / "camp"
    assert main(["-q", "campaign", str(data["scene"]), str(data["recordings"] / "rig_a.h5"),
                 "--out", str(out)]) == 130
    assert capsys.readouterr().err.strip() == "meshphase campaign: interrupted"
    assert not out.exists()


def test_campaign_exit_code_table_empty_and_bad():
    assert cp.campaign_exit_code({"recordings": []}) == 0
    assert cp.campaign_exit_code({"recordings": [{"status": "ok"}, {"status": "ok"}]}) == 0
    assert cp.campaign_exit_code({"recordings": [{"status": "ok"}, {"status": "partial"}]}) == 3
    assert cp.campaign_exit_code({"recordings": [{"status": "ok"}, {"status": "failed"}]}) == 3
    assert cp.campaign_exit_code({"recordings": [{"status": "failed"}, {"status": "failed"}]}) == 1
    # a scene-level result (the Monte Carlo) missing makes the campaign partial too
    assert cp.campaign_exit_code({"recordings": [{"status": "ok"}],
                                  "scene_status": {"status": "partial"}}) == 3
    with pytest.raises(TypeError, match="recordings"):
        cp.campaign_exit_code([])
    with pytest.raises(TypeError, match="recordings"):
        cp.campaign_exit_code({"recordings": "x"})


# ---------------------------------------------------------------------------- inputs, errors
def test_collect_recordings_rules(tmp_path):
    d = tmp_path / "in"
    d.mkdir()
    (d / "odd_name.dat").write_bytes(b"\x89HDF\r\n\x1a\n" + b"\0" * 64)  # HDF5 by content
    (d / "garbage.csv").write_bytes(b"\x00\x01\x02 not text")  # corrupt, kept by suffix
    (d / "notes.txt").write_text("hello")
    (d / "x.h5.truth.json").write_text("{}")
    (d / ".hidden.h5").write_bytes(b"\x89HDF\r\n\x1a\n")
    (d / "sub").mkdir()
    extra = tmp_path / "explicit.xyz"
    extra.write_text("not a recording, but named explicitly")
    files, skipped = cp.collect_recordings([d, extra, d / "garbage.csv"])
    assert [f.name for f in files] == ["garbage.csv", "odd_name.dat", "explicit.xyz"]  # no duplicate
    reasons = {Path(s["path"]).name: s["reason"] for s in skipped}
    assert reasons[".hidden.h5"] == "hidden file" and reasons["x.h5.truth.json"] == "truth sidecar"
    assert reasons["sub"] == "not a file" and reasons["notes.txt"].startswith("not a recording")
    assert cp.collect_recordings([]) == ([], [])
    with pytest.raises(TypeError, match="single path"):
        cp.collect_recordings(str(d))
    with pytest.raises(TypeError, match="inputs must hold paths"):
        cp.collect_recordings([3])
    with pytest.raises(FileNotFoundError, match="missing"):
        cp.collect_recordings([tmp_path / "missing"])


@settings(max_examples=80, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(["a", "b", "scene", "rig"]),
                          st.sampled_from([".h5", ".csv", ".mcap", ""]),
                          st.sampled_from(["x", "y"])), max_size=12))
def test_recording_names_unique(items):
    paths = [Path("/d") / folder / (stem + suf) for stem, suf, folder in items]
    names = cp.recording_names(paths)
    assert len(names) == len(paths)
    # distinct also case-insensitively; "scene" is fine: the names live in recordings/
    assert len({n.casefold() for n in names}) == len(names)
    for n, p in zip(names, paths):
        assert n.startswith(p.stem)


def test_recording_names_empty_and_bad():
    assert cp.recording_names([]) == []
    assert cp.recording_names(["/x/a.h5", "/y/a.csv", "/z/b.h5"]) == ["a_h5", "a_csv", "b"]
    with pytest.raises(TypeError):
        cp.recording_names([3.5])


def test_split_results(data, tmp_path):
    scene = load_scene(data["scene"])
    client, worker, mc = cp.split_results(scene)
    assert client == ["tolerance"] and "tolerance" not in worker and "compare" in worker and mc
    # compare alone still pulls the Monte Carlo (for band coverage): run once, on the client
    p = tmp_path / "s.toml"
    p.write_text(SCENE.replace('"compare", "tolerance"]', '"compare"]'))
    client, worker, mc = cp.split_results(load_scene(p))
    assert client == ["tolerance"] and mc
    # without tolerances nothing runs on the client
    p.write_text(SCENE.replace('"compare", "tolerance"]', '"compare"]').split("[tolerances]")[0])
    client, worker, mc = cp.split_results(load_scene(p))
    assert client == [] and not mc and worker == ["ideal_phasing", "phasing", "load_sharing", "compare"]


def test_campaign_bad_and_empty_inputs_fail_before_any_cluster(data, tmp_path):
    scene, rec = data["scene"], [data["recordings"] / "rig_a.h5"]
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(ValueError, match="no recording files"):
        cp.run_campaign(scene, [], tmp_path / "o")
    with pytest.raises(ValueError, match="no recording files"):
        cp.run_campaign(scene, [empty], tmp_path / "o")
    with pytest.raises(ValueError, match="workers"):
        cp.run_campaign(scene, rec, tmp_path / "o", workers=0)
    with pytest.raises(TypeError, match="workers"):
        cp.run_campaign(scene, rec, tmp_path / "o", workers="2")
    with pytest.raises(ValueError, match="local cluster only"):
        cp.run_campaign(scene, rec, tmp_path / "o", workers=2, scheduler="tcp://127.0.0.1:1")
    with pytest.raises(TypeError, match="scheduler"):
        cp.run_campaign(scene, rec, tmp_path / "o", scheduler=8786)
    with pytest.raises(TypeError, match="task"):
        cp.run_campaign(scene, rec, tmp_path / "o", task="run_recording")
    with pytest.raises(FileNotFoundError, match="no_scene"):
        cp.run_campaign(tmp_path / "no_scene.toml", rec, tmp_path / "o")
    with pytest.raises(FileNotFoundError, match="gone.h5"):
        cp.run_campaign(scene, [tmp_path / "gone.h5"], tmp_path / "o")
    only_mc = tmp_path / "mc.toml"
    only_mc.write_text(SCENE.replace('["ideal_phasing", "phasing", "load_sharing", "compare", "tolerance"]',
                                     '["tolerance"]'))
    with pytest.raises(ValueError, match="need no recording"):
        cp.run_campaign(only_mc, rec, tmp_path / "o")
    assert not (tmp_path / "o").exists()  # nothing was created by a refused campaign


def test_campaign_rows_empty_bad_and_columns():
    assert cp.campaign_rows([]) == []
    with pytest.raises(TypeError):
        cp.campaign_rows({"name": "x"})
    with pytest.raises(TypeError):
        cp.campaign_rows(["x"])
    rows = cp.campaign_rows([
        {"name": "a", "status": "failed", "error": "boom"},
        {"name": "b", "status": "ok", "phasing": {"sun": {"n_passes": 3, "per_planet": {
            "2": {"n": 3, "mean": 0.25, "std": 0.01}}}},
         "load_sharing": [{"planet": 1, "load_sharing": 1.01, "std_error": 0.002}]}])
    assert list(rows[0]) == list(rows[1])  # one column set for the CSV
    assert rows[1]["gamma_mean_sun_p2_cycles"] == 0.25 and rows[0]["gamma_mean_sun_p2_cycles"] is None
    assert rows[1]["load_sharing_p1"] == 1.01 and rows[0]["error"] == "boom"
    # units in the names, as in every CSV of a run; the per-planet columns sort by planet
    assert {"duration_s", "wall_time_s", "rms_vs_ideal_sun_cycles", "rms_vs_model_ring_cycles"} <= set(rows[0])
    assert list(rows[0])[-3:] == ["identify_rms_after_cycles", "n_messages", "out_dir"]


# ---------------------------------------------------------------------------- report
def test_campaign_report_empty_and_bad(tmp_path):
    p = crep.build_campaign_report({"scene": "s", "recordings": []}, tmp_path)
    assert "No recordings" in p.read_text()
    with pytest.raises(TypeError, match="campaign"):
        crep.build_campaign_report([], tmp_path)
    with pytest.raises(TypeError, match="recordings"):
        crep.build_campaign_report({"recordings": ["x"]}, tmp_path)
    with pytest.raises(FileNotFoundError):
        crep.build_campaign_report({"recordings": []}, tmp_path / "missing")


def test_campaign_report_from_records(tmp_path):
    recs = [{"name": "r<1>", "recording": "/x/r1.h5", "out_dir": str(tmp_path / "r1"), "status": "ok",
             "format": "hdf5", "wall_time_s": 1.5, "worker": "w:1", "files": {"summary": "s"},
             "ideal": {"gamma_s": [0, 0.25], "gamma_r": [0, 0.5]},
             "phasing": {"sun": {"n_passes": 4, "per_planet": {"2": {"n": 2, "mean": 0.26, "std": 0.01}}}},
             "load_sharing": [{"planet": 1, "load_sharing": 1.02, "std_error": 0.01},
                              {"planet": 2, "load_sharing": 0.98, "std_error": 0.01}],
             "compare": {"sun": {"rms_vs_ideal": 0.01, "rms_vs_model": 0.005, "coverage": 0.9}},
             "messages": ["phasing: ProcessingWarning: ambiguous"]},
            {"name": "r2", "recording": "/x/r2.h5", "out_dir": "o", "status": "failed",
             "error": "load: RecordingFileError: truncated", "wall_time_s": float("nan")}]
    html = crep.build_campaign_report({"scene": "s", "recordings": recs, "timing_s": {"processing": 2.0}},
                                      tmp_path).read_text()
    assert "r&lt;1&gt;" in html and "truncated" in html and "90.0%" in html
    assert "1.0200 ± 1.0e-02" in html and "ProcessingWarning" in html
    assert sorted(q.name for q in (tmp_path / "figures").iterdir()) == [
        "load_sharing_across_recordings.png", "phasing_across_recordings.png", "residual_rms.png",
        "wall_times.png"]


@pytest.mark.parametrize("fn, args", [
    (crep.phasing_across_recordings, ([], {})),
    (crep.load_sharing_across_recordings, ([], [])),
    (crep.residual_rms_across_recordings, ([], {})),
    (crep.wall_times_across_recordings, ([], [])),
])
def test_figures_empty(fn, args):
    fig = fn(*args)
    assert "no " in " ".join(t.get_text() for ax in fig.axes for t in ax.texts)
    plt.close(fig)


@pytest.mark.parametrize("fn, args, exc", [
    (crep.phasing_across_recordings, (["a", "b"], {"sun": {"2": ([0.25], [0.01])}}), ValueError),
    (crep.phasing_across_recordings, ("ab", {}), TypeError),
    (crep.load_sharing_across_recordings, (["a"], [[1.0], [1.0]]), ValueError),
    (crep.load_sharing_across_recordings, (["a"], [[1.0, 1.0]], [[0.1]]), ValueError),
    (crep.residual_rms_across_recordings, (["a"], [0.1]), TypeError),
    (crep.residual_rms_across_recordings, (["a"], {"sun": [0.1, 0.2]}), ValueError),
    (crep.wall_times_across_recordings, (["a"], [1.0, 2.0]), ValueError),
    (crep.wall_times_across_recordings, (["a"], [1.0], ["ok", "ok"]), ValueError),
])
def test_figures_bad_input(fn, args, exc):
    with pytest.raises(exc):
        fn(*args)
    plt.close("all")


@pytest.mark.parametrize("fn, args", [
    (crep.phasing_across_recordings, (["a", "b"], {"sun": {"2": ([0.0, 0.01], [0.02, 0.02]),
                                                          "3": ([0.01, -0.01], [0.02, 0.03])}})),
    (crep.load_sharing_across_recordings, (["a", "b"], [[1.0, 1.02], [0.98, 1.0]])),
    (crep.residual_rms_across_recordings, (["a", "b"], {"sun": [1e-3, 2e-3], "ring": [3e-3, 1e-3]})),
])
def test_figure_legends_sit_outside_the_axes(fn, args):
    # right of the axes, as the run report's legends: a legend inside could hide a point
    fig = fn(*args)
    fig.canvas.draw()
    legends = [(ax, ax.get_legend()) for ax in fig.axes if ax.get_legend() is not None]
    assert len(legends) == 1           # the phasing panels share one legend of the planets
    for ax, leg in legends:
        assert leg.get_window_extent().x0 >= ax.get_window_extent().x1
    plt.close(fig)


def test_phasing_figure_one_legend_of_every_planet_and_shared_recordings_axis():
    names = ["a", "b", "c"]
    ph = {"sun": {"2": ([0.0, 0.01, 0.0], [0.02] * 3)},
          "ring": {"3": ([0.01, -0.01, 0.0], [0.02] * 3), "2": ([0.0, 0.0, 0.0], [0.01] * 3)}}
    fig = crep.phasing_across_recordings(names, ph)
    top, bottom = fig.axes
    assert [t.get_text() for t in top.get_legend().get_texts()] == ["planet 2", "planet 3"]
    assert bottom.get_legend() is None
    fig.canvas.draw()
    assert [t.get_text() for t in bottom.get_xticklabels()] == names
    assert not any(t.get_visible() and t.get_text() for t in top.get_xticklabels())
    plt.close(fig)


def test_figures_shorten_long_recording_names_and_lay_them_out(recwarn):
    # names of 80 characters: tight_layout gave up on them with a warning; the axes show
    # each name's head and tail, which the layout fits
    long = [f"rec_{i}_" + "x" * 80 + f"_end{i}" for i in range(6)]
    fig = crep.load_sharing_across_recordings(long, [[1.0, 1.01]] * 6)
    labels = [t.get_text() for t in fig.axes[0].get_xticklabels()]
    assert all(len(t) == crep.TICK_NAME_CHARS and "…" in t for t in labels)
    assert labels[0].startswith("rec_0_x") and labels[0].endswith("_end0")
    plt.close(fig)
    for make, args in [(crep.wall_times_across_recordings, (long, [1.0] * 6)),
                       (crep.residual_rms_across_recordings, (long, {"sun": [1e-3] * 6}))]:
        png = crep.figure_png(make, *args)
        assert png[:8] == b"\x89PNG\r\n\x1a\n"
    assert not [w for w in recwarn if "layout" in str(w.message).lower()]


def test_figure_png_empty_and_bad():
    png = crep.figure_png(crep.wall_times_across_recordings, [], [])
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(TypeError, match="figure function"):
        crep.figure_png("wall_times")
    with pytest.raises(TypeError, match="not a figure"):
        crep.figure_png(lambda: 3)


def test_campaign_report_drawn_elsewhere_is_the_same_page(tmp_path):
    """``draw`` gets one call per figure, in page order, and its PNGs take their places: the
    page equals the one drawn here (but for its time stamp); a wrong answer is refused."""
    import re

    recs = [{"name": f"r{k}", "status": "ok", "wall_time_s": 1.0 + k,
             "load_sharing": [{"planet": 1, "load_sharing": 1.0, "std_error": 0.01}]} for k in range(3)]
    camp = {"scene": "s", "recordings": recs}
    seen = []

    def draw(calls):
        seen.extend(m.__name__ for m, _, _ in calls)
        return [crep.figure_png(m, *a, **k) for m, a, k in calls]

    here, there = tmp_path / "here", tmp_path / "there"
    here.mkdir(), there.mkdir()
    stamp = re.compile(r"generated [0-9: -]+UTC")
    page = stamp.sub("", crep.build_campaign_report(camp, here).read_text())
    assert stamp.sub("", crep.build_campaign_report(camp, there, draw=draw).read_text()) == page
    assert seen == ["wall_times_across_recordings", "load_sharing_across_recordings"]
    assert sorted(p.name for p in (there / "figures").iterdir()) == sorted(
        p.name for p in (here / "figures").iterdir())
    with pytest.raises(TypeError, match="one PNG"):
        crep.build_campaign_report(camp, there, draw=lambda calls: [b"x"])


def test_local_workers_start_warm_from_the_fork_server():
    """The campaign's local workers are forked from the fork server (their parent is not
    this process) with the processing stack imported before any warm-up ran, numba's
    kernels loaded: their filters and onsets take numba, as ``process`` does."""
    from distributed import Client

    from meshphase.campaign import cluster as cluster_mod
    from meshphase.campaign.job import worker_modules

    if cluster_mod.worker_server(worker_modules()) is None:
        pytest.skip("no fork server on this platform: the workers spawn")
    with cluster_mod.local_cluster(1, worker_modules=worker_modules()) as cl, Client(cl) as client:
        # a lambda travels by value (the workers cannot import this test module)
        warm = client.run(lambda: "meshphase.run.stages" in sys.modules)
        assert list(warm.values()) == [True]
        engines = client.run(lambda: (__import__("meshphase.signal.iir", fromlist=["_"]).pick_engine(),
                                      __import__("meshphase.onsets.fastpath", fromlist=["_"]).dense("auto", 1)))
        numba = importlib.util.find_spec("numba") is not None
        assert list(engines.values()) == [("numba" if numba else "scipy", numba)]
        # distributed's 64-KiB MALLOC_TRIM_THRESHOLD_ for its workers is left out: in a forked
        # worker it reached os.environ only, and meshphase.runtime.heap then left glibc's trim threshold
        # at 128 KiB. A worker has the value of the fork server it forked from (the environment
        # of the process that started the server, where a user's own value would be); this
        # process's own may differ, as a Nanny sets its pre-spawn variables here too
        def trim_values():
            parent = open(f"/proc/{os.getppid()}/environ", "rb").read().split(b"\0")
            there = [v.split(b"=", 1)[1].decode() for v in parent if v.startswith(b"MALLOC_TRIM_THRESHOLD_=")]
            return os.environ.get("MALLOC_TRIM_THRESHOLD_"), (there or [None])[-1]

        if os.path.exists("/proc/self/environ"):
            for here, server in client.run(trim_values).values():
                assert here == server
        assert os.getpid() not in client.run(os.getppid).values()
