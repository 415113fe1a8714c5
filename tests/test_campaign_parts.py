"""The pieces a campaign is built from, without a cluster: the tolerance band, the client's
scene, task timeouts and records, completion markers and --resume reuse, the cluster options
and ending a stuck worker (with stand-ins for the Dask client)."""

from __future__ import annotations

import hashlib
import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from seed_rig_toml import SEED_RIG_GEARSET

from meshphase.campaign import runner as cp
from meshphase.campaign import job as cj
from meshphase.campaign import resume as cr
from meshphase.campaign import cluster
from meshphase.run.scene import load_scene
from meshphase.models.tolerance import MonteCarloResult


# ---------------------------------------------------------------------------- the band
def _mc(n_planets: int):
    def stat(lo, hi):
        return SimpleNamespace(bound3=np.array([np.full(n_planets, lo), np.full(n_planets, hi)]))

    mc = SimpleNamespace(ave_s=stat(-0.1, 0.2), dev_s=stat(0.0, 0.04),
                         ave_r=stat(-0.3, 0.3), dev_r=stat(0.0, 0.1))
    mc.phasing_band = lambda gear: MonteCarloResult.phasing_band(mc, gear)
    return mc


def phasing_band(mc, gear):
    return mc.phasing_band(gear)


def test_phasing_band_widens_the_mean_band_by_half_the_deviation():
    lo, hi = phasing_band(_mc(4), "sun")
    np.testing.assert_allclose(lo, [-0.12] * 4)
    np.testing.assert_allclose(hi, [0.22] * 4)
    lo, hi = phasing_band(_mc(4), "ring")
    np.testing.assert_allclose(hi - lo, [0.7] * 4)
    assert cp._bands(_mc(3)) == {"sun": {"lo": pytest.approx([-0.12] * 3), "hi": pytest.approx([0.22] * 3)},
                                 "ring": {"lo": pytest.approx([-0.35] * 3), "hi": pytest.approx([0.35] * 3)}}


def test_phasing_band_empty_and_bad():
    lo, hi = phasing_band(_mc(0), "sun")
    assert lo.shape == hi.shape == (0,)
    with pytest.raises(ValueError, match="gear"):
        phasing_band(_mc(4), "planet")


# ---------------------------------------------------------------------------- scenes
SCENE = ('name = "parts"\nresults = ["phasing", "tolerance"]\n\n' + SEED_RIG_GEARSET
         + '\n[input]\nsynthetic = "seed_rig"\nminutes = 0.1\n\n[tolerances]\ne_sun_mm = 0.2\n'
         'e_ring_mm = 0.5\ne_planet_mm = 0.2\nsamples = 64\n')


def test_client_scene_keeps_the_client_results_only(tmp_path):
    (tmp_path / "s.toml").write_text(SCENE)
    scene = load_scene(tmp_path / "s.toml")
    c = cp.client_scene(scene)
    assert c.results == ["tolerance"] and c.input == {} and scene.results == ["phasing", "tolerance"]
    (tmp_path / "p.toml").write_text(SCENE.replace('"phasing", "tolerance"', '"phasing"'))
    assert cp.client_scene(load_scene(tmp_path / "p.toml")).results == []  # nothing on the client
    with pytest.raises(TypeError, match="Scene"):
        cp.client_scene({"results": []})


# ---------------------------------------------------------------------------- the job's pieces
def test_task_limits_per_recording():
    keys = [{"size": 0}, None, {"size": 15.7e6}]
    assert cj.task_limits(keys, 0) == {0: None, 1: None, 2: None}
    assert cj.task_limits(keys, 7.5) == {0: 7.5, 1: 7.5, 2: 7.5}
    by_size = cj.task_limits(keys, None)
    assert by_size[0] == by_size[1] == cj.TIMEOUT_BASE_S and by_size[2] == cj.default_task_timeout(15.7e6)
    assert cj.task_limits([], None) == {}
    with pytest.raises(TypeError, match="keys"):
        cj.task_limits(3, None)
    with pytest.raises(TypeError, match="keys"):
        cj.task_limits("abc", None)


def test_failed_record_has_the_task_record_keys():
    rec = cj.failed_record(Path("/r/a.h5"), "a", Path("/o/a"), "boom")
    assert rec["status"] == "failed" and rec["error"] == "boom" and rec["recording"] == "/r/a.h5"
    assert rec["out_dir"] == "/o/a" and rec["files"] == {} and np.isnan(rec["wall_time_s"])
    assert cj.failed_record("", "", "", "")["recording"] == ""


def test_warm_up_returns_this_process_id():
    # a list without meshphase.campaign.fork_ready: the default list would freeze this test process
    assert cj.warm_up(("json", "meshphase.campaign.runner")) == os.getpid()


def test_run_job_bad_input():
    with pytest.raises(TypeError, match="Job"):
        cj.run_job({}, {}, scheduler=None, workers=None, dashboard=None, cluster_info={}, timing={})


# ---------------------------------------------------------------------------- markers, resume
def test_sha256_file_empty_and_missing(tmp_path):
    (tmp_path / "e").write_bytes(b"")
    assert cr.sha256_file(tmp_path / "e") == hashlib.sha256(b"").hexdigest()
    with pytest.raises(FileNotFoundError):
        cr.sha256_file(tmp_path / "missing")


def test_recording_keys_empty_gone_and_bad(tmp_path):
    (tmp_path / "a.h5").write_bytes(b"12")
    keys = cr.recording_keys([tmp_path / "a.h5", tmp_path / "gone.h5"], "ff", {"recording_report": False})
    assert keys[0] == cr.recording_key(tmp_path / "a.h5", "ff", {"recording_report": False})
    assert keys[1] is None
    assert cr.recording_keys([], "ff") == []
    with pytest.raises(TypeError, match="list of paths"):
        cr.recording_keys(str(tmp_path / "a.h5"), "ff")


def test_write_marker_round_trip_and_bad(tmp_path):
    cr.write_marker(tmp_path / "r", {"recording": "/x.h5"}, {"status": "ok", "gamma": np.float64(0.5)})
    assert cr.completed_recordings(tmp_path) == {}  # not under recordings/
    cr.write_marker(tmp_path / cr.RECORDINGS_DIR_NAME / "x", {"recording": "/x.h5"}, {})
    (path, marker), = cr.completed_recordings(tmp_path).values()
    assert path.name == "x" and marker == {"meshphase_done": 1, "key": {"recording": "/x.h5"}, "record": {}}
    assert json.loads((tmp_path / "r" / cr.DONE_NAME).read_text())["record"]["gamma"] == 0.5
    with pytest.raises(TypeError, match="dicts"):
        cr.write_marker(tmp_path / "r", None, {})


def test_relocate_empty_and_bad():
    rec = cr.relocate({"out_dir": "/a/s", "files": {"summary": "/a/s/summary.json", "x": "/else/y"}},
                      "/ignored", "/b/s")
    assert rec == {"out_dir": "/b/s", "files": {"summary": "/b/s/summary.json", "x": "/else/y"}}
    assert cr.relocate({}, "/a", "/b") == {"out_dir": "/b", "files": {}}
    with pytest.raises(TypeError, match="record"):
        cr.relocate(None, "/a", "/b")


def test_resume_sources_skip_missing_and_linked(tmp_path):
    (tmp_path / "camp" / cr.RECORDINGS_DIR_NAME).mkdir(parents=True)
    (tmp_path / "link").symlink_to(tmp_path / "camp")
    (tmp_path / "bare").mkdir()
    found = cr.resume_sources([tmp_path / "camp", tmp_path / "link", tmp_path / "bare", tmp_path / "no"])
    assert found == [str(tmp_path / "camp")]
    assert cr.resume_sources([]) == []
    with pytest.raises(TypeError, match="list of folders"):
        cr.resume_sources(str(tmp_path))


def test_reuse_completed_takes_matching_markers_only(tmp_path):
    rec_file = tmp_path / "a.h5"
    rec_file.write_bytes(b"abc")
    key = cr.recording_key(rec_file, "ff")
    old = tmp_path / "old" / cr.RECORDINGS_DIR_NAME / "a"
    old.mkdir(parents=True)
    (old / "summary.json").write_text("{}")
    cr.write_marker(old, key, {"status": "ok", "out_dir": str(old), "files": {"summary": str(old / "summary.json")}})
    new = tmp_path / "new"
    got = cr.reuse_completed([tmp_path / "old"], [key, None], [new / "a", new / "b"], ["a", "b"],
                             lambda p: str(Path("/final") / Path(p).name))
    assert list(got) == [0] and got[0]["resumed"] and got[0]["name"] == "a"
    assert got[0]["files"]["summary"] == "/final/a/summary.json" and (new / "a" / "summary.json").is_file()
    stale = dict(key, size=99)
    assert cr.reuse_completed([tmp_path / "old"], [stale], [tmp_path / "n2"], ["a"], str) == {}
    assert cr.reuse_completed([], [], [], [], str) == {}
    with pytest.raises(ValueError, match="one entry per recording"):
        cr.reuse_completed([], [key], [], ["a"], str)


# ---------------------------------------------------------------------------- the cluster
def test_cores_is_at_least_one():
    assert isinstance(cluster.cores(), int) and cluster.cores() >= 1


def test_check_cluster_options_empty_and_bad():
    assert cluster.check_cluster_options(None, None, None) is None
    assert cluster.check_cluster_options(None, 3, True) == 3
    assert cluster.check_cluster_options("tcp://h:8786", None, False) is None
    with pytest.raises(TypeError, match="scheduler"):
        cluster.check_cluster_options(8786, None, None)
    with pytest.raises(ValueError, match="workers"):
        cluster.check_cluster_options(None, 0, None)
    with pytest.raises(ValueError, match="local cluster only"):
        cluster.check_cluster_options("tcp://h:8786", 2, None)
    with pytest.raises(TypeError, match="dashboard"):
        cluster.check_cluster_options(None, None, 1.5)


def test_open_client_bad_input():
    with pytest.raises(TypeError, match="warm_up"):
        with cluster.open_client(None, 1, None, "not callable", {}):
            pass
    with pytest.raises(TypeError, match="info"):
        with cluster.open_client(None, 1, None, os.getpid, None):
            pass


def test_own_child_only_for_our_children():
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        assert cluster.own_child(proc.pid)
    finally:
        proc.kill()
        proc.wait()
    assert not cluster.own_child(os.getpid()) and not cluster.own_child(None)
    assert not cluster.own_child("123")


class _Client:
    """Stands in for distributed.Client.restart_workers."""

    def __init__(self, answer):
        self.answer, self.asked = answer, []

    def restart_workers(self, workers, timeout, raise_for_error):
        self.asked.append((workers, timeout, raise_for_error))
        if isinstance(self.answer, Exception):
            raise self.answer
        return self.answer


def test_end_worker_kills_our_child_and_restarts_another():
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    assert cluster.end_worker(None, "tcp://127.0.0.1:1", proc.pid) == "killed (its Nanny starts a new one)"
    assert proc.wait(timeout=10) != 0
    ok = _Client({"tcp://w:1": "OK"})
    assert cluster.end_worker(ok, "tcp://w:1", None) == "restarted"
    assert ok.asked == [(["tcp://w:1"], 120, False)]
    assert (cluster.end_worker(_Client({}), "tcp://w:1", None)
            == "not restarted (?): it may stay busy")
    assert (cluster.end_worker(_Client(RuntimeError("no nanny")), "tcp://w:1", os.getpid())
            == "not restarted (RuntimeError: no nanny): it may stay busy")


def test_cluster_start_bad_input():
    with pytest.raises(TypeError, match="warm_up"):
        cluster.ClusterStart(None, 1, None, "not callable", {})
    with pytest.raises(TypeError, match="info"):
        cluster.ClusterStart(None, 1, None, os.getpid, None)


def test_cluster_start_error_reaches_the_waiting_thread(monkeypatch):
    """A start that fails in its thread raises where the client is asked for, and closes
    cleanly (nothing was started); the distributed log level is restored."""
    import logging

    def no_cluster(scheduler, workers, dashboard, info, worker_modules=None):
        raise ValueError(f"scheduler {scheduler!r}: cannot connect: refused")

    import distributed  # noqa: F401 - its import sets its own log levels; the start then quiets them

    monkeypatch.setattr(cluster, "_connect", no_cluster)
    level = logging.getLogger("distributed").level
    start = cluster.ClusterStart("tcp://127.0.0.1:1", None, None, os.getpid, {})
    with pytest.raises(ValueError, match="cannot connect"):
        start.client()
    start.close(wait=False)
    start.close()
    assert start.elapsed_s is not None and start.elapsed_s >= 0.0
    assert logging.getLogger("distributed").level == level


def test_start_cluster_bad_input():
    with pytest.raises(TypeError, match="info"):
        cj.start_cluster(None, 1, None, None)


def _fresh(code: str, *argv, timeout: float = 120) -> str:
    """``code`` run by a fresh interpreter (``argv`` after it): its stdout, once it exited 0."""
    out = subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True, timeout=timeout)
    assert out.returncode == 0, out.stderr
    return out.stdout


# ---------------------------------------------------------------------------- warm workers
def test_worker_server_empty_and_bad():
    """In a fresh interpreter (the server is started once per process): the first call
    starts it, the next finds it running; bad module lists are refused before anything."""
    code = ("from meshphase.campaign.cluster import worker_server\n"
            "if __name__ == '__main__':\n"
            "    first = worker_server(())\n"
            "    print(first is None or first >= 0.0, worker_server(['json']) in (None, 0.0))\n")
    stdout = _fresh(code)
    assert stdout.split() == ["True", "True"]
    for bad in ("meshphase.run.stages", [1], [""], None):
        with pytest.raises(TypeError, match="modules"):
            cluster.worker_server(bad)
    with pytest.raises(TypeError, match="modules"):
        cluster.ClusterStart(None, 1, None, os.getpid, {}, worker_modules="meshphase")


def test_worker_modules_are_importable_and_name_every_reader():
    from meshphase.io import FORMATS

    mods = cj.worker_modules()
    assert {f"meshphase.io.{f}" for f in FORMATS} <= set(mods) and "meshphase.run.stages" in mods
    # in a fresh interpreter: warm_up freezes the heap of the process it runs in (a worker)
    code = ("import os, sys\n"
            "import meshphase.campaign.job as cj\n"
            "assert cj.warm_up() == os.getpid()\n"
            "print(all(m in sys.modules for m in cj.worker_modules()))")
    stdout = _fresh(code, timeout=300)
    assert stdout.split() == ["True"]


def test_the_fork_server_readies_and_freezes_its_heap_last():
    # the fork server imports worker_modules() in order: the last one pays the first uses a
    # worker's first recording would (validators, the BLAS controller), then collects and
    # freezes the heap, so that the workers' collections never walk (and copy) what the
    # imports made
    for mods in (cj.worker_modules(), cj.worker_modules([]), cj.worker_modules(["csv"], True)):
        assert mods[-1] == "meshphase.campaign.fork_ready" and mods.count(mods[-1]) == 1
    code = ("import gc\n"
            "before = gc.get_freeze_count()\n"
            "import meshphase.campaign.fork_ready as fh\n"
            "from meshphase.runtime import threads\n"
            "kept = threads._blas_controller is not None and threads._controller() is threads._blas_controller[1]\n"
            "import sys, threadpoolctl\n"
            "k = fh.KERNELS\n"
            "one = all(i['num_threads'] == 1 for i in threadpoolctl.threadpool_info() if i['user_api'] == 'blas')\n"
            "print(before, fh.FROZEN_OBJECTS > 10_000, gc.get_freeze_count() > 10_000, fh.FIRST_USE_S > 0, kept and one,"
            " k['filters'], k['onsets'], k['seconds'] >= 0, 'scipy.signal' in sys.modules)")
    stdout = _fresh(code)
    # BLAS held to one thread for good (no forked worker starts its pool), numba's kernels
    # loaded (the workers' filters and onsets take them), no scipy.signal (without numba:
    # scipy.signal, the filters' engine then)
    numba = importlib.util.find_spec("numba") is not None
    assert stdout.split() == ["0", "True", "True", "True", "True", "numba" if numba else "scipy",
                              "numba" if numba else "numpy", "True", "False" if numba else "True"]


def test_the_fork_server_starts_when_its_first_uses_fail():
    # a full temporary disk (the recording written there fails): the import goes on, the
    # heap is frozen, and the workers pay the first uses themselves
    code = ("import errno, gc\n"
            "import meshphase.io\n"
            "def full(*a, **k):\n"
            "    raise OSError(errno.ENOSPC, 'No space left on device')\n"
            "meshphase.io.write = full\n"
            "import meshphase.campaign.fork_ready as fh\n"
            "print(fh.FIRST_USE_S != fh.FIRST_USE_S, gc.get_freeze_count() > 10_000)")
    stdout = _fresh(code)
    assert stdout.split() == ["True", "True"]


def test_worker_modules_follow_the_formats_and_the_input():
    hdf5 = cj.worker_modules(["hdf5"])
    assert {"meshphase.io.hdf5", "h5py", "jsonschema", "threadpoolctl", "meshphase.run.stages"} <= set(hdf5)
    assert not {"pandas", "nptdms", "meshphase.io.csv", "meshphase.synthetic"} & set(hdf5)
    assert {"meshphase.io.csv", "pandas", "meshphase.synthetic"} <= set(cj.worker_modules(["csv"], True))
    assert cj.worker_modules(["tdms", "tdms"]).count("nptdms") == 1
    assert "meshphase.io.hdf5" not in cj.worker_modules([])           # no recording: no reader
    with pytest.raises(ValueError, match="unknown format"):
        cj.worker_modules(["xls"])


def test_campaign_modules_read_the_suffixes_and_the_scene(tmp_path):
    scene = SimpleNamespace(input={})
    assert cj.campaign_modules(scene, [tmp_path / "a.H5", "b.hdf5"]) == cj.worker_modules(["hdf5"])
    # a suffix no format claims (a file named on the command line): every reader
    assert cj.campaign_modules(scene, ["a.h5", "b.dat"]) == cj.worker_modules()
    synth = SimpleNamespace(input={"synthetic": "noisy"})
    assert "meshphase.synthetic" in cj.campaign_modules(synth, ["a.tdms"])
    assert cj.campaign_modules(SimpleNamespace(), []) == cj.worker_modules([])


def test_the_fork_server_starts_before_the_scene_is_checked(tmp_path, monkeypatch):
    # run_campaign starts the local workers' fork server in the background before the
    # scene's checks (which import scipy), with the modules the campaign's tasks import
    import threading

    started, done = [], threading.Event()

    def fake_server(modules):
        started.append(tuple(modules))
        done.set()
        return 0.0

    monkeypatch.setattr(cluster, "worker_server", fake_server)
    (tmp_path / "a.tdms").write_bytes(b"")
    scene = tmp_path / "s.toml"
    scene.write_text('results = ["phasing"]\n[input]\nsynthetic = "noisy"\n', encoding="utf-8")
    found = cp._start_worker_server_early(scene, [str(tmp_path)], False)
    assert found == cp.collect_recordings([str(tmp_path)])       # handed on: not walked twice
    assert done.wait(10.0)
    assert started == [cj.campaign_modules(SimpleNamespace(input={"synthetic": "noisy"}),
                                           [tmp_path / "a.tdms"])]
    # what cannot be read is left to the checks that follow: no start, no error here
    started.clear()
    done.clear()
    assert cp._start_worker_server_early(tmp_path / "missing.toml", [str(tmp_path)], False) is not None
    scene.write_text("results = [", encoding="utf-8")
    assert cp._start_worker_server_early(scene, [str(tmp_path)], False) is not None
    assert cp._start_worker_server_early(tmp_path / "s.toml", [str(tmp_path / "nothing")], False) is None
    assert not done.wait(0.5) and started == []


@pytest.mark.parametrize("synthetic_input", [False, True])
def test_a_campaign_task_imports_nothing_its_fork_server_lacks(tmp_path, synthetic_input):
    # the local workers fork from a server that imported campaign_modules(): a task that
    # imported more would pay it in every worker's first task (h5py, jsonschema and
    # threadpoolctl did)
    import meshphase.io
    from meshphase.synthetic import generate

    rec, _ = generate("seed_rig", duration=30.0, seed=3)  # both gauges measured: status ok
    path = meshphase.io.write(rec, tmp_path / "rig.h5")
    scene = tmp_path / "scene.toml"
    scene.write_text('name = "w"\nresults = ["phasing", "compare"]\n'
                     + ('[input]\nsynthetic = "seed_rig"\nminutes = 0.5\n' if synthetic_input
                        else '[input]\nrecording = "rig.h5"\n')
                     + SEED_RIG_GEARSET, encoding="utf-8")
    code = ("import sys, importlib\n"
            "from meshphase.campaign.job import campaign_modules\n"
            "from meshphase.run.scene import load_scene\n"
            "for m in campaign_modules(load_scene(sys.argv[1]), [sys.argv[2]]):\n"
            "    importlib.import_module(m)\n"
            "before = set(sys.modules)\n"
            "from meshphase.campaign.runner import run_recording\n"
            "r = run_recording(sys.argv[1], sys.argv[2], sys.argv[3])\n"
            "assert r['status'] in ('ok', 'unreliable'), r\n"
            "print(','.join(sorted(set(sys.modules) - before)))")
    res = subprocess.run([sys.executable, "-c", code, str(scene), str(path), str(tmp_path / "out")],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.strip() == "", f"the task imported {res.stdout.strip()}"


class _GoneClient:
    """A client whose cluster is gone: every submit fails."""

    def submit(self, *a, **k):
        raise OSError("no workers")


def test_draw_figures_empty_bad_and_drawn_here_without_a_cluster():
    from meshphase.report import campaign_report as crep

    assert cj.draw_figures(None, []) == []
    with pytest.raises(TypeError, match="calls"):
        cj.draw_figures(None, "wall_times")
    with pytest.raises(TypeError, match="calls"):
        cj.draw_figures(None, [("not callable", (), {})])
    pngs = cj.draw_figures(_GoneClient(), [(crep.wall_times_across_recordings, (["a"], [1.0]), {})])
    assert len(pngs) == 1 and pngs[0][:4] == b"\x89PNG"


def test_the_campaign_client_assembles_its_report_without_matplotlib_or_pandas(tmp_path):
    # the workers draw the figures (their fork server imported matplotlib), campaign.csv is
    # meshphase.run.table_csv's: the client's report imports neither library (~0.5 s of CPU
    # that its start would otherwise spend beside the fork server's imports)
    code = """
import json, sys
from pathlib import Path
from meshphase.campaign import runner as cp
from meshphase.report.campaign_report import build_campaign_report
from meshphase.run.table_csv import write_csv
cp._import_report_modules()
recs = [{"name": "r1", "recording": "/x/r1.h5", "out_dir": "o1", "status": "ok", "format": "hdf5",
         "wall_time_s": 1.5, "worker": "w:1", "files": {},
         "ideal": {"gamma_s": [0, 0.25], "gamma_r": [0, 0.5]},
         "phasing": {"sun": {"n_passes": 4, "per_planet": {"2": {"n": 2, "mean": 0.26, "std": 0.01}}}},
         "load_sharing": [{"planet": 1, "load_sharing": 1.02, "std_error": 0.01}]},
        {"name": "r2", "recording": "/x/r2.h5", "out_dir": "o2", "status": "failed", "error": "boom",
         "wall_time_s": float("nan")}]
out = Path(sys.argv[1])
drawn = []
def draw(calls):
    drawn.extend(calls)
    return [b"\\x89PNG not drawn here"] * len(calls)
build_campaign_report({"scene": "s", "recordings": recs}, out, draw=draw)
write_csv(cp.campaign_rows(recs), out / "campaign.csv")
print(len(drawn), "matplotlib" in sys.modules, "pandas" in sys.modules)
"""
    stdout = _fresh(code, str(tmp_path))
    n, mpl, pd_ = stdout.split()
    assert int(n) >= 3 and (mpl, pd_) == ("False", "False")
    assert (tmp_path / "campaign_report.html").is_file() and (tmp_path / "campaign.csv").is_file()


def test_campaign_command_keeps_distributed_quiet(tmp_path):
    """``meshphase campaign`` in a fresh process: distributed is first imported in the
    cluster's start thread, and its import sets its loggers to INFO from its config; quieted
    before that, the command printed ~30 lines of cluster life (scheduler at, nanny start,
    close-stream, ...) on stderr. Only with -v now."""
    import meshphase.io
    from meshphase.synthetic import generate

    rec, _ = generate("seed_rig", duration=20.0, seed=4)
    recs = tmp_path / "recs"
    recs.mkdir()
    meshphase.io.write(rec, recs / "a.h5")
    scene = tmp_path / "scene.toml"
    scene.write_text('name = "q"\nresults = ["phasing"]\n[input]\nrecording = "recs/a.h5"\n' + SEED_RIG_GEARSET,
                     encoding="utf-8")
    argv = [sys.executable, "-m", "meshphase.cli", "-q", "campaign", str(scene), str(recs), "--workers", "1"]
    res = subprocess.run(argv + ["--out", str(tmp_path / "o1")], capture_output=True, text=True, timeout=300)
    assert res.returncode in (0, 3), res.stderr[-2000:]
    assert "distributed." not in res.stderr, res.stderr[:2000]
    res = subprocess.run(argv[:3] + ["-v"] + argv[3:] + ["--out", str(tmp_path / "o2")], capture_output=True,
                         text=True, timeout=300)
    assert "distributed.scheduler" in res.stderr


def test_worker_environ_leaves_out_the_trim_threshold_alone():
    import dask

    with dask.config.set({"distributed.nanny.pre-spawn-environ": {"MALLOC_TRIM_THRESHOLD_": 65536,
                                                                   "OMP_NUM_THREADS": 1}}):
        assert cluster._worker_environ() == {"OMP_NUM_THREADS": 1}
    with dask.config.set({"distributed.nanny.pre-spawn-environ": None}):
        assert cluster._worker_environ() == {}
    with dask.config.set({"distributed.nanny.pre-spawn-environ": {}}):
        assert cluster._worker_environ() == {}


def test_trim_env_is_distributed_only_in_a_worker_with_distributeds_value(monkeypatch):
    # outside a worker: whatever the environment says, the user's
    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "65536")
    assert cluster.trim_env_is_distributed() is False
    monkeypatch.delenv("MALLOC_TRIM_THRESHOLD_")
    assert cluster.trim_env_is_distributed() is False


def test_trim_env_is_distributed_in_workers():
    # a plain LocalCluster's spawned worker has its Nanny's 64 KiB (distributed's default
    # pre-spawn-environ): a campaign task there keeps meshphase's heap policy; the campaign's
    # own local cluster leaves the variable out (nothing to tell)
    import dask
    from distributed import Client, LocalCluster

    saved = dict(os.environ)          # a Nanny sets its pre-spawn variables here too
    try:
        with dask.config.set({"distributed.nanny.pre-spawn-environ": {"MALLOC_TRIM_THRESHOLD_": 65536}}), \
                LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None,
                             host="127.0.0.1") as cl, Client(cl) as client:
            assert client.submit(cluster.trim_env_is_distributed, pure=False).result() is True

            # another value in the worker's environment is taken for the user's
            def other():
                os.environ["MALLOC_TRIM_THRESHOLD_"] = "1048576"
                return cluster.trim_env_is_distributed()

            assert client.submit(other, pure=False).result() is False
    finally:
        os.environ.clear()
        os.environ.update(saved)


def test_the_fork_server_without_numba_loads_scipys_filters():
    # numba is optional: the fork server then loads scipy.signal, the filters' engine, once
    # for all its workers
    code = ("import sys\n"
            "import meshphase.signal.iir as iir, meshphase.onsets.fastpath as fp\n"
            "iir.HAVE_NUMBA = fp.HAVE_NUMBA = False\n"
            "import meshphase.campaign.fork_ready as fh\n"
            "k = fh.KERNELS\n"
            "print(k['filters'], k['onsets'], 'scipy.signal' in sys.modules, 'numba' in sys.modules)")
    assert _fresh(code).split() == ["scipy", "numpy", "True", "False"]


def test_cluster_start_puts_the_nannies_environment_back(tmp_path):
    # a Nanny writes its pre-spawn variables (OMP_NUM_THREADS=1, ...) into the process that
    # starts it; a campaign's cluster puts them back when it closes
    import dask

    keys = set(dask.config.get("distributed.nanny.pre-spawn-environ", None) or {}) | {"PYTHONHASHSEED"}
    before = {k: os.environ.get(k) for k in keys}
    info: dict = {}
    start = cluster.ClusterStart(None, 1, None, os.getpid, info)
    try:
        start.client()
        assert info["n_workers"] == 1
    finally:
        start.close()
    assert {k: os.environ.get(k) for k in keys} == before


def test_restore_environ_sets_and_unsets(monkeypatch):
    monkeypatch.setenv("MESHPHASE_TEST_A", "changed")
    monkeypatch.setenv("MESHPHASE_TEST_B", "set by a nanny")
    cluster._restore_environ({"MESHPHASE_TEST_A": "1", "MESHPHASE_TEST_B": None})
    assert os.environ["MESHPHASE_TEST_A"] == "1" and "MESHPHASE_TEST_B" not in os.environ
    cluster._restore_environ({})                      # nothing taken: nothing changed
    assert os.environ["MESHPHASE_TEST_A"] == "1"


def test_recording_order_largest_first_ties_and_gone_files_in_order():
    keys = [{"size": 10}, None, {"size": 300}, {"size": 10}, {"size": 0}, {"size": 300}]
    assert cj.recording_order([0, 1, 2, 3, 4, 5], keys) == [2, 5, 0, 3, 1, 4]
    assert cj.recording_order([3, 0, 1], keys) == [3, 0, 1]           # a resumed campaign's rest
    assert cj.recording_order([], keys) == []
    with pytest.raises(TypeError, match="sequences"):
        cj.recording_order("012", keys)
    with pytest.raises(TypeError, match="sequences"):
        cj.recording_order([0], 5)
