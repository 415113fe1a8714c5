"""Campaign faults: a hung task, a worker killed mid-task, a rerun, hostile recording names,
the local cluster's network exposure, and failures while the combined outputs are written.

The recordings are 10 s of the seed rig (``meshphase.synthetic.generate``, ``meshphase.io.write``). Most
runs use a light task (reads the recording's header, writes a summary; shipped to the workers
by value) on a 1-worker LocalCluster: what is tested is the campaign's machinery, not the
processing. The resume test runs the real task. Timeouts are a few seconds: the hung task
sleeps for 10 minutes, so a campaign that did not time it out would fail the test by its
length, not pass it by luck.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import re
import shutil
import signal
import socket
import sys
import time
from pathlib import Path

import pytest
from seed_rig_toml import SEED_RIG_GEARSET

import meshphase.io
from meshphase.campaign import runner as cp
from meshphase.campaign import cluster as cluster_mod
from meshphase.campaign.job import campaign_task
from meshphase.cli import build_parser
from meshphase.run.exits import EXIT_OK, EXIT_PARTIAL
from meshphase.run.outdir import MANIFEST_NAME, PARTIAL_SUFFIX

SCENE = ('name = "campaign fault scene"\nresults = ["phasing"]\n\n' + SEED_RIG_GEARSET
         + '\n[input]\nsynthetic = "seed_rig"\nminutes = 0.1\n')
#: statuses with results (the completion marker is written): "unreliable" is a verdict on the
#: phasing of a 10-s recording, not a failure of the campaign machinery tested here
USABLE = ("ok", "unreliable", "partial")


@pytest.fixture(scope="module")
def rigs(tmp_path_factory):
    """The scene and 10-s seed-rig recordings under hostile names: ``campaign.json.h5`` and
    ``figures.h5`` (the campaign's own names), ``a/x.h5`` and ``b/x.h5`` (one stem, two
    folders), ``hang.h5`` (the light task hangs on it), and two distinct ones for resume."""
    from meshphase.synthetic import generate

    d = tmp_path_factory.mktemp("faults")
    (d / "scene.toml").write_text(SCENE, encoding="utf-8")
    rec, _ = generate("seed_rig", duration=10.0, seed=0)
    src = Path(meshphase.io.write(rec, d / "rig0.h5"))
    rec1, _ = generate("seed_rig", duration=10.0, seed=1)
    meshphase.io.write(rec1, d / "rig1.h5")
    for rel in ("campaign.json.h5", "figures.h5", "a/x.h5", "b/x.h5", "hang.h5", "victim.h5"):
        (d / rel).parent.mkdir(exist_ok=True)
        shutil.copyfile(src, d / rel)
    return d


@pytest.fixture(scope="module")
def cluster():
    """The campaign's own kind of cluster (:func:`meshphase.campaign.runner.local_cluster`: 1 worker
    under a Nanny, loopback only, no dashboard), shared through its address (one cluster start
    for the module; the campaign starting its own is tested in test_campaign.py)."""
    with cp.local_cluster(1) as cl:
        yield cl


@contextlib.contextmanager
def _tasks_by_value():
    """The workers cannot import this test module: ship its task functions by value."""
    import cloudpickle

    cloudpickle.register_pickle_by_value(sys.modules[__name__])
    try:
        yield
    finally:
        cloudpickle.unregister_pickle_by_value(sys.modules[__name__])


def _light_task(scene_path, recording_path, out_dir, **kw):
    """Reads the recording's header from its path and writes a summary: the campaign's
    machinery without the processing time. Hangs on ``hang.h5`` (a read blocked on a dead
    file server)."""
    from meshphase.io import read_info

    if Path(recording_path).name == "hang.h5":
        time.sleep(600)
    info = read_info(recording_path)
    d = Path(out_dir)
    d.mkdir(parents=True, exist_ok=True)
    (d / "summary.json").write_text(json.dumps({"n_samples": info.n_samples}))
    return {"recording": recording_path, "name": d.name, "out_dir": out_dir, "status": "ok",
            "error": None, "format": "hdf5", "wall_time_s": 0.0,
            "worker": f"{socket.gethostname()}:{os.getpid()}",
            "files": {"summary": str(d / "summary.json")}, "messages": []}


def _dies_once(scene_path, recording_path, out_dir, **kw):
    """The worker process is killed (as by the OOM killer) the first time it runs
    ``victim.h5``; the retry succeeds. The flag file beside the recording says "died once"."""
    flag = Path(recording_path + ".died")
    if Path(recording_path).name == "victim.h5" and not flag.exists():
        flag.touch()
        time.sleep(0.5)  # the task's start reaches the client first (else: "held", not "running")
        os.kill(os.getpid(), signal.SIGKILL)
    return _light_task(scene_path, recording_path, out_dir, **kw)


# ---------------------------------------------------------------------------- Dask runs
def test_hung_task_times_out_and_hostile_names_never_collide(rigs, cluster, tmp_path):
    """A task that hangs is failed "timeout" after --task-timeout, its worker restarted, the
    others finish, the campaign exits 3. Recordings named like the campaign's own files, or
    with one stem in two folders, get their own folders under recordings/."""
    files = [rigs / "hang.h5", rigs / "campaign.json.h5", rigs / "figures.h5", rigs / "a" / "x.h5",
             rigs / "b" / "x.h5"]
    out = tmp_path / "camp"
    t0 = time.monotonic()
    with _tasks_by_value():
        res = cp.run_campaign(rigs / "scene.toml", files, out, scheduler=cluster.scheduler_address,
                              progress=False, task=_light_task, task_timeout=3)
    assert time.monotonic() - t0 < 300  # nowhere near the 600 s the task sleeps
    by = {r["recording"]: r for r in res["recordings"]}
    hung = by[str(rigs / "hang.h5")]
    assert hung["status"] == "failed" and hung["error"].startswith("timeout: no result 3 s after")
    assert "was killed (its Nanny starts a new one)" in hung["error"] and hung["timed_out"]
    assert not (out / "recordings" / "hang").exists()  # nothing half written is left
    assert all(by[str(f)]["status"] == "ok" for f in files[1:]), {k: v["error"] for k, v in by.items()}
    assert res["exit_code"] == EXIT_PARTIAL and res["counts"]["failed"] == 1
    assert res["task_timeout"] == {"mode": "fixed", "seconds": 3.0}
    # names: the campaign's own files stay its own
    assert [by[str(f)]["name"] for f in files] == ["hang", "campaign.json", "figures", "x_a", "x_b"]
    assert sorted(p.name for p in (out / "recordings").iterdir()) == ["campaign.json", "figures", "x_a", "x_b"]
    for name in ("campaign.json", "figures", "x_a", "x_b"):
        assert (out / "recordings" / name / "summary.json").is_file()
        assert (out / "recordings" / name / cp.DONE_NAME).is_file()
    saved = json.loads((out / "campaign.json").read_text())
    assert len(saved["recordings"]) == 5 and saved["exit_code"] == EXIT_PARTIAL
    assert all(p.suffix == ".png" for p in (out / "figures").iterdir())
    assert Path(by[str(rigs / "figures.h5")]["files"]["summary"]) == out.resolve() / "recordings" / "figures" / "summary.json"
    csv = (out / "campaign.csv").read_text().splitlines()
    assert len(csv) == 6 and "attempts" in csv[0].split(",") and "retries" in csv[0].split(",")
    html = (out / "campaign_report.html").read_text()
    assert "href='recordings/campaign.json/summary.json'" in html and "timeout" in html
    assert sorted(os.listdir(tmp_path)) == ["camp"]  # no staging folder left beside it


@pytest.mark.slow
def test_hung_task_on_a_cluster_not_ours_restarts_its_worker(rigs, cluster, tmp_path, monkeypatch):
    """A worker that is not a child of this process (another machine's) is restarted through
    the scheduler (its Nanny waits for the blocked thread, then kills it): the same outcome."""
    monkeypatch.setattr(cluster_mod, "own_child", lambda pid: False)
    with _tasks_by_value():
        res = cp.run_campaign(rigs / "scene.toml", [rigs / "hang.h5", rigs / "rig0.h5"], tmp_path / "c",
                              scheduler=cluster.scheduler_address, progress=False, task=_light_task,
                              task_timeout=2)
    hung, good = res["recordings"]
    assert hung["status"] == "failed" and hung["error"].startswith("timeout: no result 2 s after")
    assert hung["error"].endswith("was restarted") and good["status"] == "ok"
    assert res["exit_code"] == EXIT_PARTIAL


def test_worker_killed_mid_task_is_retried_and_the_retry_recorded(rigs, cluster, tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    for name in ("victim.h5", "rig0.h5"):
        shutil.copyfile(rigs / name, src / name)
    out = tmp_path / "camp"
    with _tasks_by_value():
        res = cp.run_campaign(rigs / "scene.toml", [src], out, scheduler=cluster.scheduler_address,
                              progress=False, task=_dies_once)
    by = {Path(r["recording"]).name: r for r in res["recordings"]}
    v = by["victim.h5"]
    assert v["status"] == "ok" and v["attempts"] == 2 and len(v["retries"]) == 1
    assert "was lost while running it (killed, crashed or out of memory)" in v["retries"][0]
    assert by["rig0.h5"]["attempts"] == 1 and by["rig0.h5"]["retries"] == []
    assert res["exit_code"] == EXIT_OK
    saved = {r["name"]: r for r in json.loads((out / "campaign.json").read_text())["recordings"]}
    assert saved["victim"]["attempts"] == 2 and "killed" in saved["victim"]["retries"][0]
    rows = (out / "campaign.csv").read_text().splitlines()
    head = rows[0].split(",")
    victim = next(r for r in rows[1:] if r.startswith("victim,"))
    assert victim.split(",")[head.index("attempts")] == "2"
    assert "Retries" in (out / "campaign_report.html").read_text()


def test_resume_skips_complete_redoes_changed_and_keeps_an_unfinished_run(rigs, cluster, tmp_path,
                                                                          monkeypatch):
    """The real task. A rerun with --resume reuses both recordings (no cluster is even
    started); a rewritten recording is redone; a campaign that does not finish keeps what it
    had in OUT.partial, which the next --resume uses; a write failing with ENOSPC leaves the
    previous campaign folder as it was."""
    from meshphase.synthetic import generate

    src = tmp_path / "in"
    src.mkdir()
    for name in ("rig0.h5", "rig1.h5"):
        shutil.copyfile(rigs / name, src / name)
    scene = rigs / "scene.toml"
    out = tmp_path / "camp"
    sched = cluster.scheduler_address
    r1 = cp.run_campaign(scene, [src], out, scheduler=sched, progress=False)
    assert [r["status"] in USABLE for r in r1["recordings"]] == [True, True], r1["recordings"]
    first = {r["name"]: r for r in r1["recordings"]}
    # everything complete: nothing to do, no cluster
    r2 = cp.run_campaign(scene, [src], out, resume=True, progress=False)
    assert r2["resume"]["n_resumed"] == 2 and r2["cluster"]["n_workers"] == 0
    assert Path(r2["out_dir"]) == out.resolve()  # replaced in place, not out-2
    for r in r2["recordings"]:
        assert r["resumed"] and r["phasing"] == first[r["name"]]["phasing"]
        assert Path(r["files"]["summary"]).is_file() and Path(r["out_dir"]).parent == out.resolve() / "recordings"
    # one input rewritten: only that one is redone
    other, _ = generate("seed_rig", duration=10.0, seed=7)
    meshphase.io.write(other, src / "rig1.h5", overwrite=True)
    r3 = cp.run_campaign(scene, [src], out, resume=True, scheduler=sched, progress=False)
    by = {r["name"]: r for r in r3["recordings"]}
    assert by["rig0"]["resumed"] and not by["rig1"]["resumed"] and by["rig1"]["status"] in USABLE
    marker = json.loads((out / "recordings" / "rig1" / cp.DONE_NAME).read_text())
    assert marker["key"]["size"] == (src / "rig1.h5").stat().st_size
    # interrupted after the recordings are done: OUT stays as it was, OUT.partial keeps them
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    import meshphase.report.campaign_report as crep

    def ctrl_c(*a, **k):
        raise KeyboardInterrupt

    with monkeypatch.context() as m:
        m.setattr(crep, "build_campaign_report", ctrl_c)
        with pytest.raises(KeyboardInterrupt):
            cp.run_campaign(scene, [src], out, resume=True, progress=False)
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before
    partial = tmp_path / ("camp" + PARTIAL_SUFFIX)
    assert (partial / "recordings" / "rig0" / cp.DONE_NAME).is_file()
    # the disk fills while campaign.json is written: the previous folder is untouched
    def full(path, text):
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    with monkeypatch.context() as m:
        m.setattr(cp, "_write_text_atomic", full)
        with pytest.raises(OSError, match="No space left"):
            cp.run_campaign(scene, [src], out, resume=True, progress=False)
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before
    assert not any(p.name.endswith(".new") for p in tmp_path.iterdir())
    # the campaign folder lost: --resume takes the finished recordings from OUT.partial
    shutil.rmtree(out)
    r4 = cp.run_campaign(scene, [src], out, resume=True, progress=False)
    assert r4["resume"]["n_resumed"] == 2 and r4["cluster"]["n_workers"] == 0
    assert r4["resume"]["sources"] == [str(partial)]
    assert not partial.exists()  # its results are in the campaign now
    assert json.loads((out / MANIFEST_NAME).read_text())["state"] == "complete"
    assert sorted(os.listdir(tmp_path)) == ["camp", "in"]


def _listening(proc) -> set:
    import psutil

    addrs = set()
    for p in [proc] + proc.children(recursive=True):
        with contextlib.suppress(psutil.Error):
            addrs |= {c.laddr.ip for c in p.net_connections(kind="inet") if c.status == psutil.CONN_LISTEN}
    return addrs


def test_local_cluster_listens_on_loopback_only(cluster):
    """The campaign's LocalCluster: scheduler, workers, nannies and the scheduler's HTTP server
    (the dashboard's, off by default) all listen on 127.0.0.1 - and nothing else in this
    process tree listens elsewhere."""
    import psutil

    assert cluster.scheduler_address.startswith("tcp://127.0.0.1:")
    assert cluster.dashboard_link.startswith("http://127.0.0.1:")
    assert _listening(psutil.Process()) == {"127.0.0.1"}


def _monitoring(dask_worker) -> tuple:
    """(profiling?, tick interval [ms], system-monitor interval [ms]) of a worker or Nanny."""
    pcs = dask_worker.periodic_callbacks
    return "profile" in pcs, pcs["tick"].callback_time, pcs["monitor"].callback_time


def _ms(key: str) -> float:
    import dask
    from dask.utils import parse_timedelta

    return parse_timedelta(dask.config.get(key), default="ms") * 1000


def test_monitoring_only_as_fine_as_a_dashboard_needs():
    """Without a dashboard nothing shows the workers' stack samples or the fine-grained
    loop and system metrics: the workers' profiler (every 10 ms on every task thread) is
    off and every server's loop ticks every 0.5 s and samples the system every 2 s - also
    a worker its Nanny restarted (after a timeout), and the scheduler and Nannies in this
    process; with a dashboard, the configured values (distributed's 20 ms and 500 ms by
    default) and the profiler on. (Clusters of its own: the module's shared one is not
    restarted under the tests after this one, which count its worker; a restarted worker
    can shut itself down instead, dask/distributed#6494, and one CI run lost it so.)"""
    from distributed import Client

    quiet = (False, 500.0, 2000.0)
    with _tasks_by_value(), cp.local_cluster(1) as cl, Client(cl.scheduler_address) as client:
        assert list(client.run(_monitoring).values()) == [quiet]
        assert list(client.run(_monitoring, nanny=True).values()) == [quiet]
        client.restart_workers(list(client.scheduler_info()["workers"]))
        assert list(client.run(_monitoring).values()) == [quiet]
        assert _monitoring(cl.scheduler)[1:] == quiet[1:]
    default = (True, _ms("distributed.admin.tick.interval"), _ms("distributed.admin.system-monitor.interval"))
    assert default[1:] != quiet[1:]
    with _tasks_by_value(), cp.local_cluster(1, dashboard=True) as cl, Client(cl) as client:
        assert list(client.run(_monitoring).values()) == [default]
        assert _monitoring(cl.scheduler)[1:] == default[1:]


def test_figures_drawn_on_the_cluster_heaviest_first_come_back_in_order(cluster):
    """draw_figures hands the workers the heaviest figure first, one at a time per worker
    thread, and returns each figure's PNG at its own place: the same bytes as drawn here."""
    from distributed import Client

    from meshphase.campaign.job import draw_figures, figure_order
    from meshphase.report import campaign_report as crep

    names = [f"rec{i}" for i in range(12)]
    calls = [(crep.wall_times_across_recordings, (names[:2], [1.0, 2.0]), {}),
             (crep.wall_times_across_recordings, (names, [float(i) for i in range(12)]), {}),
             (crep.load_sharing_across_recordings, (names[:3], [[1.0, 0.9, 1.1]] * 3), {})]
    assert figure_order(calls) == [1, 2, 0]
    with Client(cluster.scheduler_address) as client:
        # drawn on the worker (a cluster without one draws them here, tested below)
        assert len(client.scheduler_info()["workers"]) == 1
        pngs = draw_figures(client, calls)
    assert pngs == [crep.figure_png(m, *a, **k) for m, a, k in calls]


def test_figures_drawn_here_at_once_when_the_cluster_has_no_worker():
    from distributed import Client, LocalCluster

    from meshphase.campaign.job import draw_figures
    from meshphase.report import campaign_report as crep

    calls = [(crep.wall_times_across_recordings, (["a", "b"], [1.0, 2.0]), {})]
    with LocalCluster(n_workers=0, processes=False, dashboard_address=None) as cl, Client(cl) as client:
        t = time.perf_counter()
        pngs = draw_figures(client, calls, timeout=60.0)
        assert time.perf_counter() - t < 30.0
    assert pngs == [crep.figure_png(m, *a, **k) for m, a, k in calls]


def test_figure_order_empty_ties_and_unpicklable():
    from meshphase.campaign.job import figure_order

    f = (lambda: None)
    assert figure_order([]) == []
    assert figure_order([(f, (1,), {}), (f, (2,), {})]) == [0, 1]          # ties: as given
    assert figure_order([(f, (lambda: 0,), {}), (f, ([0.0] * 50,), {})]) == [1, 0]


def test_open_client_joins_a_cluster_and_warms_its_workers(cluster):
    info = {}
    with cluster_mod.open_client(cluster.scheduler_address, None, None, os.getpid, info) as client:
        assert client.scheduler.address == cluster.scheduler_address
    # the cluster serves no dashboard: its page answers 404 and no link is named, unless the
    # page could not be asked at all within the check's time (a loaded machine), when the
    # scheduler's advertised address is named, as documented for an unreachable page
    link = info.pop("dashboard", None)
    assert link is None or re.fullmatch(r"http://127\.0\.0\.1:\d+/status", link), link
    assert info == {"n_workers": 1, "scheduler": cluster.scheduler_address}
    with pytest.raises(ValueError, match="cannot import meshphase"):
        with cluster_mod.open_client(cluster.scheduler_address, None, None, _no_meshphase, {}):
            pass


def _no_meshphase():
    """Shipped by reference: the workers cannot import this test module (as a worker
    without meshphase cannot import the warm-up), and if they could, it raises the same."""
    raise ImportError("No module named 'meshphase'")


def test_dashboard_addresses_and_bad_input():
    assert cluster_mod._dashboard_address(True) == "127.0.0.1:0"
    assert cluster_mod._dashboard_address("8787") == "127.0.0.1:8787"
    assert cluster_mod._dashboard_address(":8787") == "127.0.0.1:8787"  # distributed: all interfaces
    assert cluster_mod._dashboard_address("10.0.0.5:8787") == "10.0.0.5:8787"  # named: as given
    with pytest.raises(TypeError, match="dashboard"):
        cp.local_cluster(1, dashboard=1.5)
    with pytest.raises(ValueError, match="n_workers"):
        cp.local_cluster(0)


def test_campaign_option_errors_before_any_cluster(rigs, tmp_path):
    rec = [rigs / "rig0.h5"]
    with pytest.raises(ValueError, match="task_timeout"):
        cp.run_campaign(rigs / "scene.toml", rec, tmp_path / "o", task_timeout=-1)
    with pytest.raises(ValueError, match="local cluster only"):
        cp.run_campaign(rigs / "scene.toml", rec, tmp_path / "o", dashboard=True,
                        scheduler="tcp://127.0.0.1:1")
    with pytest.raises(TypeError, match="dashboard"):
        cp.run_campaign(rigs / "scene.toml", rec, tmp_path / "o", dashboard=[1])
    link = tmp_path / "link"
    link.symlink_to(tmp_path / "elsewhere")
    with pytest.raises(FileExistsError, match="symbolic link"):
        cp.run_campaign(rigs / "scene.toml", rec, link, resume=True)
    assert sorted(os.listdir(tmp_path)) == ["link"]


def test_cli_campaign_options_parse():
    p = build_parser()
    a = p.parse_args(["campaign", "s.toml", "d", "--task-timeout", "90", "--resume", "--dashboard"])
    assert a.task_timeout == 90.0 and a.resume and a.dashboard == "127.0.0.1:0"
    a = p.parse_args(["campaign", "s.toml", "d"])
    assert a.task_timeout is None and not a.resume and a.dashboard is None
    for bad in ("-1", "nan", "inf", "soon"):
        with pytest.raises(SystemExit) as e:
            p.parse_args(["campaign", "s.toml", "d", "--task-timeout", bad])
        assert e.value.code == 2


# ---------------------------------------------------------------------------- pieces
def test_default_task_timeout_grows_with_size():
    assert cp.default_task_timeout(0) == cp.TIMEOUT_BASE_S
    # a 2-min, 15.7-MB recording processes in 3-6 s here; its limit is minutes
    assert 400 < cp.default_task_timeout(15.7e6) < 600
    assert cp.default_task_timeout(1.4e9) > 3600
    with pytest.raises(ValueError, match="size_bytes"):
        cp.default_task_timeout(-1)


def test_recording_key_changes_with_the_file_and_the_scene(tmp_path):
    f = tmp_path / "r.h5"
    f.write_bytes(b"1234")
    k = cp.recording_key(f, "aa", {"recording_report": False})
    assert k["size"] == 4 and k["recording"] == str(f.resolve())
    assert cp.recording_key(f, "aa", {"recording_report": False}) == k
    assert cp.recording_key(f, "bb", {"recording_report": False}) != k
    assert cp.recording_key(f, "aa", {"recording_report": True}) != k
    os.utime(f, ns=(k["mtime_ns"] + 10**9, k["mtime_ns"] + 10**9))
    assert cp.recording_key(f, "aa", {"recording_report": False}) != k
    with pytest.raises(FileNotFoundError):
        cp.recording_key(tmp_path / "missing.h5", "aa")
    with pytest.raises(TypeError, match="recording"):
        cp.recording_key(3, "aa")


def test_completed_recordings_empty_and_malformed(tmp_path):
    assert cp.completed_recordings(tmp_path / "missing") == {}
    d = tmp_path / "recordings" / "a"
    d.mkdir(parents=True)
    (d / cp.DONE_NAME).write_text("{not json")
    (tmp_path / "recordings" / "b").mkdir()
    (tmp_path / "recordings" / "b" / cp.DONE_NAME).write_text(json.dumps({"key": {"recording": "/r.h5"},
                                                                           "record": {"status": "ok"}}))
    (tmp_path / "recordings" / "c").symlink_to(tmp_path / "recordings" / "b")
    done = cp.completed_recordings(tmp_path)
    assert list(done) == ["/r.h5"] and done["/r.h5"][0].name == "b"


def test_recording_names_hostile_cases():
    names = cp.recording_names(["/d/a/x.h5", "/d/b/x.h5", "/d/a/X.csv", "/d/campaign.json.h5",
                                "/d/..h5", "/d/.hidden.h5", "/d/" + "é" * 200 + ".h5"])
    assert names[:4] == ["x_h5_a", "x_h5_b", "X_csv_a", "campaign.json"]
    assert names[4] == "_" and names[5] == "_hidden"
    assert len(names[6].encode()) <= 120 and "~" in names[6]
    assert len({n.casefold() for n in names}) == len(names)
    assert cp.recording_names(["/a/x.h5", "/b/x.h5"]) == ["x_a", "x_b"]
    assert cp.recording_names(["/a/x.h5", "/a/x.h5"]) == ["x", "x-2"]


def test_task_takes_paths_only_and_writes_no_marker_for_a_failure(tmp_path):
    with open(os.devnull) as handle, pytest.raises(TypeError, match="recording_path must be a path string"):
        campaign_task(_light_task, "s.toml", handle, str(tmp_path / "o"))
    failed = {"status": "failed", "error": "boom"}
    rec = campaign_task(lambda *a, **k: dict(failed), "s.toml", "r.h5", str(tmp_path / "o"),
                            None, {"recording": "r.h5"})
    assert rec == failed and not (tmp_path / "o").exists()
    ok = campaign_task(lambda *a, **k: {"status": "ok", "messages": []}, "s.toml", "r.h5",
                           str(tmp_path / "o"), None, {"recording": "r.h5"})
    marker = json.loads((tmp_path / "o" / cp.DONE_NAME).read_text())
    assert marker["key"] == {"recording": "r.h5"} and marker["record"] == ok


def test_task_runs_with_its_share_of_the_threads_and_refuses_a_bad_count(tmp_path, monkeypatch):
    # a local cluster's workers share this machine's cores: each recording's run is held to
    # the share run_job hands it (meshphase.runtime.threads), and only inside the task
    from meshphase.runtime.threads import ENV_THREADS, run_threads

    monkeypatch.setenv(ENV_THREADS, "4")
    seen = []

    def task(*a, **k):
        seen.append(run_threads())
        return {"status": "failed", "error": "x"}

    campaign_task(task, "s.toml", "r.h5", str(tmp_path / "o"), threads=2)
    campaign_task(task, "s.toml", "r.h5", str(tmp_path / "o"))
    assert seen == [2, 4] and run_threads() == 4
    with pytest.raises(ValueError, match="positive integer"):
        campaign_task(task, "s.toml", "r.h5", str(tmp_path / "o"), threads=0)
