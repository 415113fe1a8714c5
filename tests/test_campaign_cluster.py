"""A campaign on a cluster as an HPC allocation or a container platform runs one: the
scheduler and the workers are separate processes (``dask scheduler`` / ``dask worker``,
:class:`meshphase.campaign.processes.ProcessCluster`), the campaign reaches them through
``--scheduler``.

Faults as on a real cluster: a worker (with its Nanny) killed with SIGKILL mid-task, whose
task Dask reruns on the other worker (``distributed.scheduler.allowed-failures``: a task is
retried while fewer than that many workers died under it, docs/cluster.md); the client
process killed with SIGKILL mid-run, after which ``--resume`` does the rest and reuses what
was done. The recordings are 10 s of the seed rig, three seeds copied under twelve names (a
campaign treats each file as a recording of its own). The full-size run, 200 x 2 min, is
``meshphase bench campaign``'s overhead row.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from seed_rig_toml import SEED_RIG_GEARSET

import meshphase.io
from meshphase.campaign import runner as cp
from meshphase.campaign.processes import ProcessCluster
from meshphase.run.exits import EXIT_OK, EXIT_PARTIAL

SCENE = ('name = "campaign cluster scene"\nresults = ["phasing"]\n\n' + SEED_RIG_GEARSET
         + '\n[input]\nsynthetic = "seed_rig"\nminutes = 0.1\n')
USABLE = ("ok", "unreliable", "partial")
N_RECORDINGS = 12
VICTIM = "rig05.h5"


@pytest.fixture(scope="module")
def rigs(tmp_path_factory):
    """The scene and twelve 10-s seed-rig recordings (three seeds, copied)."""
    from meshphase.synthetic import generate

    d = tmp_path_factory.mktemp("cluster")
    (d / "scene.toml").write_text(SCENE, encoding="utf-8")
    src = d / "in"
    src.mkdir()
    seeds = []
    for seed in range(3):
        rec, _ = generate("seed_rig", duration=10.0, seed=seed)
        seeds.append(Path(meshphase.io.write(rec, d / f"seed{seed}.h5")))
    for k in range(N_RECORDINGS):
        shutil.copyfile(seeds[k % 3], src / f"rig{k:02d}.h5")
    return d


@pytest.fixture
def cluster(tmp_path):
    """A scheduler and two workers, each its own process; ended after the test. They import
    this module's task as a cluster's workers import installed code: from their path."""
    path = os.pathsep.join([str(Path(__file__).parent), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    with ProcessCluster(2, work_dir=tmp_path / "dask", dashboard=True, env={"PYTHONPATH": path}) as cl:
        yield cl


def _victim_waits(scene_path, recording_path, out_dir, **kw):
    """The real task; on its first run for ``VICTIM`` it first writes its process id beside
    the recording and waits (the test kills its worker meanwhile)."""
    from meshphase.campaign.runner import run_recording

    flag = Path(recording_path + ".pid")
    if Path(recording_path).name == VICTIM and not flag.exists():
        flag.write_text(str(os.getpid()))
        time.sleep(120)
    return run_recording(scene_path, recording_path, out_dir, **kw)


def _pid_of(record: dict) -> int:
    return int(str(record["worker"]).rsplit(":", 1)[1])


def test_worker_killed_on_a_cluster_of_processes_is_rerun_on_the_other(rigs, cluster, tmp_path, capsys):
    """SIGKILL to a worker and its Nanny while it runs a recording: the scheduler sees the
    worker gone, reruns the task on the other worker, the campaign records the retry and
    finishes every recording; the dashboard link is reported, no progress bar is drawn on a
    stderr that is no terminal."""
    out = tmp_path / "camp"
    result: dict = {}

    def run():
        try:
            result["res"] = cp.run_campaign(rigs / "scene.toml", [rigs / "in"], out,
                                            scheduler=cluster.address, progress=True,
                                            task=_victim_waits)
        except BaseException as exc:  # noqa: BLE001 - re-raised by the test below
            result["exc"] = exc

    flag = rigs / "in" / (VICTIM + ".pid")
    flag.unlink(missing_ok=True)
    t = threading.Thread(target=run)
    t.start()
    deadline = time.monotonic() + 180
    while not flag.exists() and t.is_alive() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert flag.exists(), result
    time.sleep(0.2)  # the pid is written whole
    victim_pid = int(flag.read_text())
    i = cluster.worker_of(victim_pid)
    assert i is not None, f"pid {victim_pid} is in no worker's session"
    cluster.kill_worker(i)
    t.join(300)
    assert not t.is_alive() and "exc" not in result, result.get("exc")
    res = result["res"]
    assert len(res["recordings"]) == N_RECORDINGS
    assert all(r["status"] in USABLE for r in res["recordings"]), [r["error"] for r in res["recordings"]]
    by = {Path(r["recording"]).name: r for r in res["recordings"]}
    v = by[VICTIM]
    assert v["attempts"] == 2 and len(v["retries"]) == 1
    assert "was lost while running it (killed, crashed or out of memory)" in v["retries"][0]
    assert _pid_of(v) != victim_pid                     # rerun by the other worker
    survivor = cluster.worker_pids()[1 - i]
    assert survivor is not None and cluster.worker_pids()[i] is None
    # the scheduler's default worker-saturation (1.1) lets a 1-thread worker hold a second
    # task besides the one it runs: that one is retried too, "held", not "running"
    retried = [r for r in res["recordings"] if r["attempts"] > 1]
    assert 1 <= len(retried) <= 2 and all(r["attempts"] == 2 for r in retried)
    killed = v["retries"][0].split()[1]
    assert all(r["retries"][0].startswith(f"worker {killed} ") for r in retried)
    assert res["cluster"]["scheduler"] == cluster.address and not res["cluster"]["local"]
    assert res["cluster"]["dashboard"].startswith("http://127.0.0.1:")
    assert res["exit_code"] in (EXIT_OK, EXIT_PARTIAL)
    err = capsys.readouterr().err
    assert "recordings:" not in err and "rec/s" not in err   # no bar: stderr is no terminal
    saved = json.loads((out / "campaign.json").read_text())
    assert {r["name"]: r["attempts"] for r in saved["recordings"]}["rig05"] == 2


def _markers(parent: Path) -> dict:
    """Completion markers in the staging folders beside ``parent``'s campaign: name -> bytes."""
    return {p.parent.name: p.read_bytes() for p in parent.glob(".mp-*/recordings/*/" + cp.DONE_NAME)}


def test_client_killed_mid_run_then_resume_does_only_the_rest(rigs, cluster, tmp_path):
    """``meshphase campaign --scheduler`` as its own process, killed with SIGKILL (a login
    node's session ended, the job's time up) after a few recordings: the recordings it
    finished are kept (its staging folder becomes OUT.partial when the next run starts), and
    ``--resume`` against the same scheduler runs only the others."""
    out = tmp_path / "camp"
    log = open(tmp_path / "client.log", "wb")
    cmd = [sys.executable, "-c", "import sys; from meshphase.cli import console_main; "
           "sys.exit(console_main())", "campaign", str(rigs / "scene.toml"), str(rigs / "in"),
           "--scheduler", cluster.address, "--out", str(out)]
    proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
                            start_new_session=True)
    try:
        deadline = time.monotonic() + 240
        while len(_markers(tmp_path)) < 3 and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)
        assert proc.poll() is None, (tmp_path / "client.log").read_text()
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait()
        log.close()
    # the scheduler forgets the dead client's tasks; a task already running finishes on its
    # worker and may still write its marker: wait until the markers stop changing
    before, t_still = _markers(tmp_path), time.monotonic()
    while time.monotonic() - t_still < 3.0:
        time.sleep(0.25)
        now = _markers(tmp_path)
        if now != before:
            before, t_still = now, time.monotonic()
    assert 3 <= len(before) < N_RECORDINGS and not out.exists()
    res = cp.run_campaign(rigs / "scene.toml", [rigs / "in"], out, scheduler=cluster.address,
                          resume=True, progress=False)
    by = {r["name"]: r for r in res["recordings"]}
    assert len(by) == N_RECORDINGS and all(r["status"] in USABLE for r in by.values())
    resumed = {n for n, r in by.items() if r["resumed"]}
    assert resumed == set(before), (resumed, set(before))    # the done ones, and only those
    assert res["resume"]["n_resumed"] == len(before)
    for n in resumed:   # reused as they were: the marker is the one the killed run wrote
        assert (out / "recordings" / n / cp.DONE_NAME).read_bytes() == before[n]
    assert res["resume"]["sources"] == [str(out) + ".partial"]
    assert not Path(str(out) + ".partial").exists()           # its results are in the campaign
    assert json.loads((out / "campaign.json").read_text())["counts"]["failed"] == 0


def test_process_cluster_bad_input(tmp_path):
    with pytest.raises(ValueError, match="n_workers"):
        ProcessCluster(0, work_dir=tmp_path)
    with pytest.raises(ValueError, match="start_timeout"):
        ProcessCluster(1, work_dir=tmp_path, start_timeout=-1)
    with pytest.raises(TypeError, match="env"):
        ProcessCluster(1, work_dir=tmp_path, env={"A": 1})
    assert not list(tmp_path.glob("*.log"))            # refused before anything started


def test_process_cluster_that_does_not_start_leaves_no_process(tmp_path):
    """A scheduler given no time to write its file: a RuntimeError naming its log, and the
    process it started is ended again."""
    import psutil

    before = {p.pid for p in psutil.Process().children(recursive=True)}
    with pytest.raises(RuntimeError, match="scheduler.log"):
        ProcessCluster(1, work_dir=tmp_path, start_timeout=0.01)
    left = [p for p in psutil.Process().children(recursive=True) if p.pid not in before]
    assert not [p for p in left if p.is_running() and p.status() != psutil.STATUS_ZOMBIE]
    assert (tmp_path / "scheduler.log").is_file()


def test_process_cluster_kill_worker_bad_index(cluster):
    with pytest.raises(IndexError, match="no worker 5"):
        cluster.kill_worker(5)
    assert cluster.worker_of(os.getpid()) is None      # this process is no worker
    assert all(p is not None for p in cluster.worker_pids())


def test_dashboard_named_only_where_the_scheduler_serves_one(tmp_path):
    """A scheduler started with ``--no-dashboard`` still names its HTTP server "dashboard":
    no link is reported for it."""
    from distributed import Client

    from meshphase.campaign.cluster import scheduler_dashboard

    with ProcessCluster(1, work_dir=tmp_path, dashboard=False) as cl, Client(cl.address) as client:
        assert "dashboard" in client.scheduler_info()["services"]
        assert scheduler_dashboard(client) is None
