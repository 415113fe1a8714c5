"""The Dask job of a campaign: one task per recording, watched, one record per recording.

:func:`run_job` takes the cluster :func:`start_cluster` started in the background (or starts
one), submits every recording still to do as one task (:func:`campaign_task`: paths only,
never open handles) and collects one record per recording: the task's own, or a failure when the task was lost
(the worker died more often than Dask retries, the task raised) or ran past its timeout.

A task's timeout (:func:`default_task_timeout`, ``--task-timeout``) counts from the moment
it starts on a worker, which tells the client through a Dask event; past it the task is
failed and its worker ended (:func:`meshphase.campaign.cluster.end_worker`). Workers lost under a
task are seen in the scheduler's "remove-worker" events; Dask retries the task and the
record lists each retry with its cause.
"""

from __future__ import annotations

import contextlib
import functools
import importlib
import itertools
import os
import pickle
import queue
import re
import shutil
import sys
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

from .resume import relocate, write_marker
from .cluster import ClusterStart, end_worker
from ..io import FORMATS, format_of_suffix, get_spec
from ..runtime.log import logger, stderr_is_terminal
from ..runtime.threads import run_threads, threads_limited
from ..validate import as_nonnegative

__all__ = ["Job", "run_job", "start_cluster", "campaign_task", "failed_record", "default_task_timeout",
           "task_limits", "warm_up", "worker_modules", "campaign_modules", "draw_figures", "figure_order",
           "recording_order", "FIGURES_TIMEOUT_S", "TIMEOUT_BASE_S",
           "TIMEOUT_RATE_BPS"]

#: default ``--task-timeout`` of a recording of ``size`` bytes: TIMEOUT_BASE_S +
#: size / TIMEOUT_RATE_BPS seconds (see :func:`default_task_timeout`)
TIMEOUT_BASE_S = 300.0
TIMEOUT_RATE_BPS = 100e3
# worker -> client event when a task starts (its key, worker, pid): start of its timeout
_START_TOPIC = "meshphase-task-start"


# ---------------------------------------------------------------------------- timeouts
def default_task_timeout(size_bytes) -> float:
    """The default ``--task-timeout`` of a recording of ``size_bytes`` bytes [s].

    ``TIMEOUT_BASE_S + size_bytes / TIMEOUT_RATE_BPS``: 300 s plus 10 s per MB. The campaign of
    8 x 2-min noisy seed-rig recordings (HDF5, 15.7 MB each) took 3-6 s per task on a loaded
    2-core machine (about 3-5 MB/s), so the rate of 0.1 MB/s leaves a margin of 30-50 for
    slower machines, compressed files (more samples per byte) and contention, and the 300 s
    the start-up of a cold worker (imports, numba compilation); a 3-h recording of 8 channels
    (about 1.4 GB) gets about 4 h. It exists to end a task that hangs (a read blocked on a
    dead network file system, a deadlock), not to bound slow ones: give ``--task-timeout``
    for a tighter limit.

    Parameters
    ----------
    size_bytes : int or float
        File size [B].

    Returns
    -------
    float
        Timeout [s].
    """
    return TIMEOUT_BASE_S + as_nonnegative(size_bytes, "size_bytes") / TIMEOUT_RATE_BPS


def task_limits(keys: Sequence, task_timeout: float | None) -> dict[int, float | None]:
    """Each recording's timeout [s]: None for none.

    Parameters
    ----------
    keys : sequence of dict or None
        The recordings' keys (:func:`meshphase.campaign.resume.recording_key`: their ``size``);
        None for a recording gone since it was listed.
    task_timeout : float or None
        ``--task-timeout`` [s]: 0 none, None :func:`default_task_timeout` of each size.

    Returns
    -------
    dict
        Recording index -> timeout [s] or None.
    """
    if isinstance(keys, (str, bytes)) or not hasattr(keys, "__len__"):
        raise TypeError(f"keys must be a sequence of recording keys, got {type(keys).__name__}")
    tt = task_timeout
    return {i: (None if tt == 0 else tt if tt is not None
                else default_task_timeout(key["size"] if key else 0))
            for i, key in enumerate(keys)}


# ---------------------------------------------------------------------------- the task
#: No scipy.signal, as in ``process``: the filter designs are meshphase.signal.sos_design's and the
#: filters and onsets take numba's kernels, which :mod:`meshphase.campaign.fork_ready` loads in the fork
#: server (without numba, the server imports scipy.signal instead)
_STACK = ("distributed", "meshphase.campaign.runner", "meshphase.compare.predict", "meshphase.signal.condition", "meshphase.kinematics.loads",
          "meshphase.models.mesh_phasing", "meshphase.onsets", "meshphase.kinematics.phasing", "meshphase.run.stages",
          "meshphase.report.campaign_report")
#: how long the report's figures may take on the cluster before they are drawn here instead [s]
FIGURES_TIMEOUT_S = 300.0


#: what every task imports besides: the scene's schema check and the BLAS thread limit
_EVERY_TASK = ("jsonschema", "threadpoolctl")
#: imported last: importing it does once what each worker's first recording would (validators,
#: BLAS controller, matplotlib on Agg), then freezes the heap (a fork server can only import),
#: so that no forked worker's collection walks, and copies, what the imports made
_FORK_READY = "meshphase.campaign.fork_ready"


def worker_modules(formats=None, synthetic: bool = False) -> tuple[str, ...]:
    """What a worker's tasks import: the processing stack, the task functions, the scene's
    schema check, the reader of each format with the libraries it imports on first use
    (h5py, mcap, npTDMS, pandas: ``read_libraries`` of each format's spec) and the report's
    figures (:func:`draw_figures`), then :mod:`meshphase.campaign.fork_ready` (first uses paid,
    matplotlib imported, the heap frozen before the workers fork); imported once in the fork
    server the local workers start from (:func:`meshphase.campaign.cluster.worker_server`), and by
    :func:`warm_up`.

    Parameters
    ----------
    formats : iterable of str, optional
        The formats of the campaign's recordings (:data:`meshphase.io.FORMATS`); None: all.
    synthetic : bool
        The scene's ``[input]`` names a synthetic scenario: a task parses the scene, and
        that loads the generator's scenario table (:mod:`meshphase.synthetic`).

    Returns
    -------
    tuple of str
        Module names.

    Raises
    ------
    ValueError
        An unknown format.
    """
    formats = FORMATS if formats is None else tuple(dict.fromkeys(formats))
    libs = tuple(lib for name in formats for lib in get_spec(name).read_libraries)
    return (_STACK + _EVERY_TASK + tuple(get_spec(name).module for name in formats)
            + tuple(dict.fromkeys(libs)) + (("meshphase.synthetic",) if synthetic else ())
            + (_FORK_READY,))


def campaign_modules(scene, files) -> tuple[str, ...]:
    """:func:`worker_modules` for a campaign: the formats of ``files`` (by suffix; a file
    whose suffix names no format: every format) and the scene's input.

    Parameters
    ----------
    scene : meshphase.run.scene.Scene
    files : iterable of path-like
        The recordings.

    Returns
    -------
    tuple of str
    """
    formats = [format_of_suffix(f) for f in files]
    synthetic = "synthetic" in (getattr(scene, "input", None) or {})
    return worker_modules(None if None in formats else formats, synthetic)


def warm_up(modules=None) -> int:
    """Import the processing stack in a worker (``modules``, default :func:`worker_modules`;
    so that task wall times measure processing): at once in a worker forked from the warm
    fork server.

    Returns
    -------
    int
        The worker's pid.
    """
    for name in (worker_modules() if modules is None else modules):
        importlib.import_module(name)
    return os.getpid()


def _draw(call) -> bytes:
    # the report's module: imported by the client after the workers' fork server started
    # (meshphase.campaign.runner's module notes), by the workers from the server
    from ..report.campaign_report import figure_png

    make, args, kwargs = call
    return figure_png(make, *args, **kwargs)


def recording_order(todo, keys) -> list[int]:
    """The order a campaign submits its recordings in: the largest file first (``size`` of
    its key, :func:`meshphase.campaign.resume.recording_key`), ties and keyless recordings
    (a file gone since) in ``todo`` order.

    Dask runs a job's tasks about in the order they were submitted. In file order, a long
    recording listed last started when the others were done and ran alone while the other
    workers idled; largest first (the longest-processing-time rule) it starts at once and
    the short ones fill the other workers meanwhile. Size stands for work within a format;
    a campaign of one format (the usual) is ordered by length.

    Parameters
    ----------
    todo : sequence of int
        Indices of the recordings to run.
    keys : sequence of dict or None
        Every recording's key (indexed by the ``todo`` entries).

    Returns
    -------
    list of int
        ``todo``, reordered.

    Raises
    ------
    TypeError
        ``todo`` or ``keys`` is not a sequence.
    """
    if isinstance(todo, (str, bytes)) or not hasattr(todo, "__iter__") \
            or isinstance(keys, (str, bytes)) or not hasattr(keys, "__getitem__"):
        raise TypeError(f"todo and keys must be sequences, got {type(todo).__name__} and "
                        f"{type(keys).__name__}")

    def size(i: int) -> int:
        key = keys[i]
        return int(key.get("size") or 0) if isinstance(key, dict) else 0

    return sorted(todo, key=lambda i: -size(i))


def figure_order(calls: list) -> list[int]:
    """The order :func:`draw_figures` hands figures to the workers: the heaviest first, each
    weighed by the pickled size of its arguments (what it plots), ties in ``calls`` order.

    Parameters
    ----------
    calls : list of (callable, tuple, dict)

    Returns
    -------
    list of int
        Indices into ``calls``.
    """
    def weight(i: int) -> int:
        try:
            return len(pickle.dumps(calls[i][1:], protocol=pickle.HIGHEST_PROTOCOL))
        except Exception:  # noqa: BLE001 - an argument that does not pickle weighs nothing here
            return 0

    return sorted(range(len(calls)), key=lambda i: -weight(i))


def draw_figures(client, calls: list, timeout: float = FIGURES_TIMEOUT_S) -> list[bytes]:
    """The combined report's figures drawn on the cluster's workers, side by side.

    ``draw`` of :func:`meshphase.report.campaign_report.build_campaign_report`: one task per
    figure, the heaviest first (:func:`figure_order`), and only as many at a time as the
    cluster has threads: the next goes to the first worker that is free. (Submitted all at
    once, Dask would place them before any ran, two on each of two workers, and the phasing
    figure, the heaviest, could share a worker with the next heaviest while the other
    worker drew two light ones.) When the cluster does not draw them (a worker lost, no
    worker left, a figure failing, past ``timeout``) they are drawn here instead, one after
    another; with no worker at all, at once rather than after ``timeout``.

    Parameters
    ----------
    client : distributed.Client
    calls : list of (callable, tuple, dict)
        The figures: a figure function, its arguments and keyword arguments.
    timeout : float
        [s]

    Returns
    -------
    list of bytes
        One PNG per call, in order.

    Raises
    ------
    TypeError
        ``calls`` is not a list of (callable, args, kwargs).
    """
    from distributed import wait

    if not isinstance(calls, (list, tuple)) or not all(
            isinstance(c, tuple) and len(c) == 3 and callable(c[0]) for c in calls):
        raise TypeError(f"calls must be a list of (figure function, args, kwargs), got {calls!r}")
    if not calls:
        return []
    futs: dict = {}
    try:
        slots = sum(client.nthreads().values())
        if slots < 1:       # no worker left: do not wait out the timeout for one
            raise RuntimeError("the cluster has no worker")
        todo = iter(figure_order(calls))
        out: list = [None] * len(calls)
        deadline = time.monotonic() + timeout
        for i in itertools.islice(todo, slots):
            futs[client.submit(_draw, calls[i], pure=False)] = i
        running = set(futs)
        while running:
            done, running = wait(list(running), timeout=max(0.0, deadline - time.monotonic()),
                                 return_when="FIRST_COMPLETED")
            for f in done:
                out[futs[f]] = f.result()
                i = next(todo, None)
                if i is not None:
                    g = client.submit(_draw, calls[i], pure=False)
                    futs[g] = i
                    running.add(g)
        return out
    except Exception as exc:  # noqa: BLE001 - the report is drawn here instead
        logger.info("campaign: report figures not drawn on the cluster (%s: %s); drawing them here",
                    type(exc).__name__, exc)
        if futs:
            with contextlib.suppress(Exception):
                client.cancel(list(futs))
        return [_draw(c) for c in calls]


def failed_record(path, name: str, out_dir, error: str) -> dict:
    """The campaign record of a recording whose task gave none (lost, timed out, no dict).

    Parameters
    ----------
    path : str or Path
        The recording.
    name : str
        Its name in the campaign.
    out_dir : str or Path
        Its results folder.
    error : str
        The cause.

    Returns
    -------
    dict
        ``status`` "failed", ``error``, and the keys of :func:`meshphase.campaign.runner.run_recording`'s
        record, empty.
    """
    return {"recording": str(path), "name": name, "out_dir": str(out_dir), "status": "failed",
            "error": error, "format": None, "wall_time_s": float("nan"), "worker": None,
            "timings_s": {}, "stages_ran": [], "stages_failed": {}, "messages": [], "files": {}}


def campaign_task(task: Callable[..., dict], scene_path: str, recording_path: str, out_dir: str,
                  dask_key: str | None = None, done_key: dict | None = None, *,
                  threads: int | None = None, **kw) -> dict:
    """What a campaign worker runs for one recording.

    Tells the client the task started (its timeout counts from here), runs ``task``, and when
    its results are usable (status ok, unreliable or partial) writes the completion marker
    (:func:`meshphase.campaign.resume.write_marker`) last, atomically. Gets paths only, never
    open handles.

    Parameters
    ----------
    task : callable
        ``task(scene_path, recording_path, out_dir, **kw) -> dict``.
    scene_path, recording_path, out_dir : str
    dask_key : str, optional
        The task's key, sent with its start; None: not in a Dask job.
    done_key : dict, optional
        The recording's key for its marker; None: no marker.
    threads : int, optional
        Worker threads of the run (:func:`meshphase.runtime.threads.threads_limited`); None: the
        worker process's own default.
    **kw
        Passed to ``task``.

    Returns
    -------
    dict
        What ``task`` returned (a note added to its ``messages`` when the marker could not
        be written).

    Raises
    ------
    TypeError
        A path is not a string.
    """
    for what, v in (("scene_path", scene_path), ("recording_path", recording_path), ("out_dir", out_dir)):
        if not isinstance(v, str):
            raise TypeError(f"{what} must be a path string (tasks get paths, never handles), got "
                            f"{type(v).__name__}")
    if dask_key is not None:
        try:
            from distributed import get_worker

            w = get_worker()
            w.log_event(_START_TOPIC, {"key": dask_key, "worker": w.address, "pid": os.getpid()})
        except ValueError:  # not in a worker (called directly)
            pass
    if threads is None:
        rec = task(scene_path, recording_path, out_dir, **kw)
    else:
        with threads_limited(threads):
            rec = task(scene_path, recording_path, out_dir, **kw)
    if done_key is not None and isinstance(rec, dict) and rec.get("status") in ("ok", "unreliable", "partial"):
        try:
            write_marker(out_dir, done_key, rec)
        except OSError as exc:
            rec.setdefault("messages", []).append(f"campaign: completion marker not written ({exc}); "
                                                  "--resume will redo this recording")
    return rec


# ---------------------------------------------------------------------------- the job
@dataclass
class Job:
    """The recordings a campaign hands to Dask.

    Attributes
    ----------
    task : callable
        The per-recording function (:func:`campaign_task` wraps it).
    scene_path : str
    files : list of Path
        Every recording of the campaign.
    names : list of str
        Their names.
    rec_dirs : list of Path
        Their results folders (staging).
    keys : list of dict or None
        Their keys (completion markers).
    limits : dict
        Index -> timeout [s] or None (:func:`task_limits`).
    todo : list of int
        Indices of the recordings to run.
    bands : dict or None
        The client's Monte Carlo band, passed to each task.
    recording_report : bool
        Each task also writes its HTML report.
    progress : bool
        A tqdm bar on stderr, when stderr is a terminal.
    final_of : callable
        A staging path -> the path it will have in the finished campaign.
    on_usable : callable
        Called after each recording that did not fail (the campaign folder is worth keeping).
    """

    task: Callable[..., dict]
    scene_path: str
    files: list
    names: list
    rec_dirs: list
    keys: list
    limits: dict
    todo: list
    bands: dict | None
    recording_report: bool
    progress: bool
    final_of: Callable[[Path], str]
    on_usable: Callable[[], None]


def _dask_key(token: str, i: int, name: str) -> str:
    return f"meshphase-{token}-{i}-{re.sub(r'[^A-Za-z0-9_.-]', '_', name)[:40]}"


def _task_threads(cluster_info: dict) -> int | None:
    """Worker threads per recording (:mod:`meshphase.runtime.threads`): on a local cluster the
    recordings already run side by side, one per worker, so each gets its share of this
    machine's cores; None on a remote cluster (each worker's own default)."""
    if not cluster_info.get("local"):
        return None
    return max(1, run_threads() // max(1, int(cluster_info.get("n_workers") or 1)))


def run_job(job: Job, records: dict, *, scheduler: str | None, workers: int | None, dashboard,
            cluster_info: dict, timing: dict, start=None) -> None:
    """Run the recordings ``job.todo`` on the cluster and put one record per recording into
    ``records``: results, failures, timeouts (worker ended) and retries (worker lost).

    Parameters
    ----------
    job : Job
    records : dict
        Index -> record; the records already there (resumed) count as done on the bar.
    scheduler, workers, dashboard
        The cluster (:class:`meshphase.campaign.cluster.ClusterStart`), when ``start`` is None.
    cluster_info : dict
        Filled in: ``dashboard``, ``n_workers``, ``scheduler``.
    timing : dict
        Filled in: ``cluster_start`` (the start's own time, also where it overlapped other
        work), ``cluster_wait`` (the part of it this call waited for) and ``processing``
        (first submit to last result) [s].
    start : meshphase.campaign.cluster.ClusterStart, optional
        A cluster start already under way (:func:`start_cluster`); the caller closes it
        (it may do so in the background while it writes the report). None: started and
        closed here.
    """
    if not isinstance(job, Job) or not isinstance(records, dict):
        raise TypeError(f"job must be a Job and records a dict, got {type(job).__name__} and "
                        f"{type(records).__name__}")
    own = start is None
    if own:
        start = start_cluster(scheduler, workers, dashboard, cluster_info)
    try:
        t = time.perf_counter()
        client = start.client()
        timing["cluster_wait"] = time.perf_counter() - t
        timing["cluster_start"] = start.elapsed_s
        t = time.perf_counter()
        token = uuid.uuid4().hex[:10]  # task keys unique on a shared scheduler
        dkeys = {i: _dask_key(token, i, job.names[i]) for i in job.todo}
        watch = _Watch({k: i for i, k in dkeys.items()})
        with watch.subscribed(client):
            _Collection(client, job, records, watch, dkeys, _task_threads(cluster_info)).run()
        timing["processing"] = time.perf_counter() - t
    finally:
        if own:
            start.close()


def start_cluster(scheduler: str | None, workers: int | None, dashboard, cluster_info: dict,
                  modules: Sequence[str] | None = None):
    """Start a campaign's cluster in the background, its workers warmed up (:func:`warm_up`;
    a local cluster's workers fork from a server that imported ``modules``).

    Parameters
    ----------
    scheduler : str or None
        Address of an existing scheduler; None: a local cluster.
    workers : int or None
        Local worker processes.
    dashboard : None, bool, int or str
    cluster_info : dict
        Filled in when the start ends: ``dashboard``, ``n_workers``, ``scheduler``.
    modules : sequence of str, optional
        What the tasks import (:func:`campaign_modules`); None: :func:`worker_modules` of
        every format.

    Returns
    -------
    meshphase.campaign.cluster.ClusterStart
        ``client()`` waits for it; ``close()`` ends it.
    """
    modules = worker_modules() if modules is None else tuple(modules)
    return ClusterStart(scheduler, workers, dashboard, functools.partial(warm_up, modules), cluster_info,
                        modules)


def _event_message(event):
    return event[1] if isinstance(event, (tuple, list)) and len(event) == 2 else event


class _Watch:
    """What the cluster tells about the job's tasks: when and where each started, and the
    workers lost under them. The handlers run on the client's event loop thread, before the
    collection sees the futures they concern (events and results come on one ordered
    stream)."""

    def __init__(self, index_of: dict):
        self.index_of = index_of
        self.starts: dict[str, list[dict]] = {}
        self.lost: dict[str, list[dict]] = {}
        self.restarted: set = set()  # workers this campaign restarted (after a timeout)

    def on_start(self, event) -> None:
        msg = _event_message(event)
        if isinstance(msg, dict) and msg.get("key") in self.index_of:
            self.starts.setdefault(msg["key"], []).append({"t": time.monotonic(), "worker": msg.get("worker"),
                                                           "pid": msg.get("pid")})

    def on_cluster(self, event) -> None:
        msg = _event_message(event)
        if not isinstance(msg, dict) or msg.get("action") != "remove-worker":
            return
        w = msg.get("worker")
        for k in msg.get("processing-tasks") or ():
            if k not in self.index_of:
                continue
            st = self.starts.get(k) or []
            ran = bool(st) and st[-1]["worker"] == w
            # a worker that dies at once may not have sent the task's start: "held"
            cause = (f"worker {w} (pid {st[-1]['pid']}) was lost while running it" if ran
                     else f"worker {w} was lost while it held the task")
            cause += (" (restarted after another task's timeout)" if w in self.restarted
                      else " (killed, crashed or out of memory)")
            self.lost.setdefault(k, []).append({"cause": cause, "worker": w, "running": ran})

    @contextlib.contextmanager
    def subscribed(self, client):
        client.subscribe_topic(_START_TOPIC, self.on_start)
        client.subscribe_topic("all", self.on_cluster)
        try:
            yield self
        finally:
            # before the client closes: else the scheduler fails to send it the "remove-client"
            # event of topic "all" and logs that as CRITICAL
            for topic in (_START_TOPIC, "all"):
                with contextlib.suppress(Exception):
                    client.unsubscribe_topic(topic)


class _Collection:
    """Submit the job's tasks, then collect a record for each: from its future, or a
    failure when it was lost or timed out."""

    def __init__(self, client, job: Job, records: dict, watch: _Watch, dkeys: dict,
                 threads: int | None = None):
        self.client, self.job, self.records, self.watch, self.dkeys = client, job, records, watch, dkeys
        self.threads = threads          # worker threads per recording (None: the worker's)
        self.pending = set(job.todo)
        self.n_failed = 0
        self.bar = None
        self.done_q: queue.SimpleQueue = queue.SimpleQueue()

    def submit(self) -> dict:
        job = self.job
        todo = recording_order(job.todo, job.keys)       # the largest first
        kw = {"bands": job.bands, "recording_report": job.recording_report,
              "threads": self.threads}
        fn = functools.partial(campaign_task, job.task)
        # one map call = one graph: the tasks form one group, which the scheduler queues
        # (root-ish tasks) when there are more than twice as many as worker threads
        futs = self.client.map(fn, [job.scene_path] * len(todo), [str(job.files[i]) for i in todo],
                               [str(job.rec_dirs[i]) for i in todo], [self.dkeys[i] for i in todo],
                               [job.keys[i] for i in todo], key=[self.dkeys[i] for i in todo],
                               pure=False, **kw)
        for f in futs:
            f.add_done_callback(self.done_q.put)
        return dict(zip(todo, futs))

    def finish(self, i: int, rec) -> None:
        job = self.job
        if not isinstance(rec, dict):
            rec = failed_record(job.files[i], job.names[i], job.rec_dirs[i],
                                f"task returned {type(rec).__name__}, not a dict")
        rec = relocate(rec, job.rec_dirs[i], job.final_of(job.rec_dirs[i]))
        retries = self.watch.lost.get(self.dkeys[i], [])
        rec["retries"] = [r["cause"] for r in retries]
        rec["attempts"] = 1 + len(retries)
        rec["resumed"] = False
        if retries:
            logger.warning("campaign: %s: %s; retried (attempt %d)", job.files[i], retries[-1]["cause"],
                           rec["attempts"])
        self.records[i] = rec
        self.pending.discard(i)
        if rec.get("status") == "failed":
            self.n_failed += 1
        else:
            job.on_usable()
        self.bar.set_postfix_str(f"failed {self.n_failed}")
        self.bar.update(1)

    def record_of(self, f, i: int):
        """The record of recording ``i`` from its done future ``f``."""
        job = self.job
        if f.status == "finished":
            try:
                return f.result()
            except Exception as exc:  # noqa: BLE001 - a result that cannot be fetched
                return failed_record(job.files[i], job.names[i], job.rec_dirs[i],
                                     f"task lost: {type(exc).__name__}: {exc}")
        # the worker died too often (KilledWorker), or the task raised
        exc = f.exception() if f.status == "error" else None
        err = (f"{type(exc).__name__}: {exc}" if exc is not None else f"dask future {f.status}")
        rec = failed_record(job.files[i], job.names[i], job.rec_dirs[i], f"task lost: {err}")
        shutil.rmtree(job.rec_dirs[i], ignore_errors=True)  # whatever it half wrote
        logger.warning("campaign: %s: %s", job.files[i], rec["error"])
        return rec

    def check_timeouts(self, now: float, fut_of: dict) -> None:
        job = self.job
        for i in sorted(self.pending):
            st = self.watch.starts.get(self.dkeys[i])
            if job.limits[i] is None or not st or now - st[-1]["t"] <= job.limits[i]:
                continue
            self.watch.restarted.add(st[-1]["worker"])
            self.finish(i, _timed_out(self.client, fut_of[i], job.files[i], job.names[i], job.rec_dirs[i],
                                      job.limits[i], st[-1]))

    def run(self) -> None:
        from tqdm import tqdm

        fut_of = self.submit()
        index_of = self.watch.index_of
        with tqdm(total=len(self.records) + len(self.job.todo), initial=len(self.records), desc="recordings",
                  unit="rec", disable=not (self.job.progress and stderr_is_terminal()), file=sys.stderr,
                  leave=False) as self.bar:
            next_check = 0.0
            while self.pending:
                try:
                    f = self.done_q.get(timeout=0.5)
                except queue.Empty:
                    f = None
                if f is not None:
                    i = index_of.get(f.key)
                    if i in self.pending:
                        self.finish(i, self.record_of(f, i))
                    f.release()
                now = time.monotonic()
                if now < next_check:
                    continue
                next_check = now + 0.5
                self.check_timeouts(now, fut_of)


def _timed_out(client, fut, path, name, rec_dir, limit, start) -> dict:
    """Fail a task that ran past its timeout: cancel it, end its worker (the only way to stop
    a thread blocked in a read: :func:`meshphase.campaign.cluster.end_worker`), drop what it half
    wrote."""
    client.cancel([fut])
    w, pid = start["worker"], start["pid"]
    how = end_worker(client, w, pid)
    shutil.rmtree(rec_dir, ignore_errors=True)
    rec = failed_record(path, name, rec_dir, f"timeout: no result {limit:.4g} s after the task started "
                                             f"(--task-timeout); its worker {w} (pid {pid}) was {how}")
    rec["timed_out"] = True
    rec["worker"] = w
    logger.warning("campaign: %s: %s", path, rec["error"])
    return rec
