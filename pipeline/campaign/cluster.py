"""The Dask cluster a campaign runs on: its own, or one it joins; and ending a stuck worker.

:func:`local_cluster` starts the campaign's own :class:`distributed.LocalCluster` (on
127.0.0.1 only, no dashboard unless asked, one single-threaded worker *process* per core by
default: the stages are numpy/Python code that holds the GIL for long stretches, and
``warnings.catch_warnings`` in :func:`meshphase.run.stages.run_scene` is not thread-safe).
:func:`open_client` gives a client on that cluster or on an existing scheduler
(``tcp://host:8786``, whose workers must have meshphase installed and see the same paths),
with the workers warmed up, and closes what it started. :func:`end_worker` ends a worker
whose task ran past its timeout (the only way to stop a thread blocked in a read).

Worker start-up: a spawned worker is a fresh interpreter that imports distributed, then the
processing stack (scipy.linalg, .interpolate and .optimize, the readers),
every worker at every campaign, all at the same time and while the client computes the
scene-level results. Where the platform has one, :func:`worker_server` starts Python's fork
server (:mod:`multiprocessing`, start method "forkserver") once per process with those
modules imported, and the local cluster forks its workers from it: they start already warm,
and one import replaces one per worker (``meshphase bench campaign`` reports the server's
start, ``worker_server_s``, and each campaign's ``cluster_start_s``). The fork server is a single-threaded
process of its own, so the workers inherit neither this process's threads and locks nor its
signal handlers, warning filters or heap settings (what plain "fork" would bring along). It
lives until this process ends; a campaign started later in the same process (the benchmark's
repeats, a notebook) finds it running. A worker the Nanny restarts (after a timeout) is
spawned as before.

``distributed`` is imported inside the functions: it is a heavy dependency that only a
campaign needs.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import threading
import time
from typing import Callable, Iterator, Sequence

from ..runtime.log import logger
from ..validate import as_positive_int

__all__ = ["local_cluster", "open_client", "ClusterStart", "check_cluster_options", "cores", "own_child",
           "end_worker", "worker_server", "trim_env_is_distributed", "scheduler_dashboard"]

_server_lock = threading.Lock()
_server_modules: tuple | None = None  # what the fork server this module started imported


def cores() -> int:
    """The cores this process may run on (at least 1): the default number of local workers.

    Returns
    -------
    int
    """
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not on Linux
        return max(1, os.cpu_count() or 1)


def _check_dashboard(dashboard) -> None:
    if not isinstance(dashboard, (bool, int, str)):
        raise TypeError(f"dashboard must be None, a bool, a port or 'host:port', got "
                        f"{type(dashboard).__name__} {dashboard!r}")


def check_cluster_options(scheduler, workers, dashboard) -> int | None:
    """Check a campaign's cluster options before anything starts.

    Parameters
    ----------
    scheduler : str or None
        Address of an existing scheduler; None: a local cluster.
    workers : int or None
        Local worker processes.
    dashboard : None, bool, int or str
        The local cluster's dashboard (:func:`local_cluster`).

    Returns
    -------
    int or None
        ``workers``, checked.

    Raises
    ------
    TypeError
        ``scheduler`` is not a string, ``dashboard`` of a wrong type.
    ValueError
        ``workers`` not a positive integer, or ``workers`` / ``dashboard`` given together
        with ``scheduler`` (they apply to the local cluster only).
    """
    if scheduler is not None and not isinstance(scheduler, str):
        raise TypeError(f"scheduler must be an address string like 'tcp://host:8786', got "
                        f"{type(scheduler).__name__} {scheduler!r}")
    if workers is not None:
        workers = as_positive_int(workers, "workers")
        if scheduler is not None:
            raise ValueError(f"workers={workers} applies to the local cluster only; the cluster at "
                             f"{scheduler!r} has its own workers")
    if dashboard is not None and dashboard is not False:
        _check_dashboard(dashboard)
        if scheduler is not None:
            raise ValueError(f"dashboard={dashboard!r} applies to the local cluster only; the cluster "
                             f"at {scheduler!r} has its own dashboard")
    return workers


def _dashboard_address(dashboard) -> str:
    """``--dashboard`` value -> the HTTP address: loopback unless a host is named."""
    text = "" if dashboard is True else str(dashboard).strip()
    if not text:
        return "127.0.0.1:0"
    if text.isdigit():
        return f"127.0.0.1:{text}"
    if text.startswith(":"):  # ":8787" means all interfaces to distributed; here loopback
        return "127.0.0.1" + text
    return text


def _check_modules(modules) -> tuple:
    if isinstance(modules, str) or not hasattr(modules, "__iter__"):
        raise TypeError(f"modules must be a sequence of module names, got {type(modules).__name__} {modules!r}")
    modules = tuple(modules)
    for m in modules:
        if not isinstance(m, str) or not m.strip():
            raise TypeError(f"modules must hold module names (non-empty str), got {m!r}")
    return modules


@contextlib.contextmanager
def _sigint_blocked() -> Iterator[None]:
    """SIGINT blocked in this thread while the body runs (processes it starts inherit the
    mask); a Ctrl-C that came meanwhile is delivered when it ends."""
    import signal

    if not hasattr(signal, "pthread_sigmask"):    # pragma: no cover - not on POSIX
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def worker_server(modules: Sequence[str]) -> float | None:
    """Start this process's fork server with ``modules`` imported, once (see the module notes).

    Processes started with the "forkserver" method (:mod:`multiprocessing`) are forked from
    it, so they start with ``modules`` imported. The first call starts the server and waits
    for it (its imports); later calls return at once. A module that fails to import there is
    skipped (multiprocessing's rule): the workers then import it themselves.

    Parameters
    ----------
    modules : sequence of str
        Module names to import in the server (``()``: none).

    Returns
    -------
    float or None
        Seconds this call waited for the server to start [s] (0.0 when it was running
        already); None where the platform has no fork server (Windows): the workers spawn.

    Raises
    ------
    TypeError
        ``modules`` is not a sequence of non-empty strings.
    """
    import multiprocessing

    global _server_modules
    modules = _check_modules(modules)
    if "forkserver" not in multiprocessing.get_all_start_methods():
        return None
    with _server_lock:
        if _server_modules is not None:
            return 0.0
        t = time.perf_counter()
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(list(modules))
        # the server, and every worker it forks, starts with SIGINT blocked: a Ctrl-C at the
        # terminal (sent to the whole process group) is this process's to handle (it closes
        # the cluster and prints "interrupted"), not a KeyboardInterrupt traceback from the
        # server's imports or a worker's task. The resource tracker first: starting it
        # unblocks SIGINT in the calling thread.
        from multiprocessing import forkserver, resource_tracker

        resource_tracker.ensure_running()
        with _sigint_blocked():
            forkserver.ensure_running()
        # starting any process starts the server (with the preload above); os.getpid is
        # a harmless target the child can unpickle without importing anything of ours
        p = ctx.Process(target=os.getpid, name="meshphase-fork-server-start", daemon=True)
        p.start()
        p.join()
        _server_modules = modules
        return time.perf_counter() - t


#: Without a dashboard: the event loops' health tick (distributed's default 20 ms; a loop
#: blocked past ``distributed.admin.tick.limit``, 3 s, is still reported) and the system
#: metrics, which only the dashboard plots (default 500 ms), at a coarser pitch. The memory
#: limits keep their own monitor (``distributed.worker.memory.monitor-interval``, 100 ms).
_QUIET_MONITORS = {"distributed.admin.tick.interval": "500ms",
                   "distributed.admin.system-monitor.interval": "2s"}


def _pre_spawn_environ() -> dict:
    """``distributed.nanny.pre-spawn-environ`` as configured now (a copy; {} when unset):
    what a Nanny writes into its worker's environment, and into this process's, before it
    starts the worker."""
    import dask

    return dict(dask.config.get("distributed.nanny.pre-spawn-environ", None) or {})


def _worker_environ() -> dict:
    """What a Nanny sets in its worker's environment before the worker starts
    (``distributed.nanny.pre-spawn-environ``), but ``MALLOC_TRIM_THRESHOLD_``.

    distributed sets it to 64 KiB to hand freed memory back early. In a worker forked from
    the fork server it reaches ``os.environ`` only, after glibc read its settings, and there
    :func:`meshphase.runtime.heap.limit_heap_growth` took it for the user's own choice and left the
    trim threshold at glibc's 128 KiB while fixing the mmap threshold: every free at the top
    of the heap handed pages back that the next block faulted in again, recording after
    recording (the task CPU of ``meshphase bench campaign`` shows the difference; a remote
    worker's tasks see the value from their Nanny, :func:`trim_env_is_distributed`). Left out,
    the workers keep the heap as ``process`` does (``pipeline/runtime/heap.py``); a value the user
    set in the environment still reaches them and is still left alone.
    """
    env = _pre_spawn_environ()
    env.pop("MALLOC_TRIM_THRESHOLD_", None)
    return env


def trim_env_is_distributed() -> bool:
    """True in a Dask worker whose ``MALLOC_TRIM_THRESHOLD_`` is the one its Nanny set from
    ``distributed.nanny.pre-spawn-environ`` (distributed's 64 KiB unless configured), not a
    user's: a campaign task then keeps meshphase's heap policy
    (:func:`meshphase.runtime.heap.limit_heap_growth` with ``trim_env=False``). False outside a
    worker, without the variable, or with another value.
    """
    value = os.environ.get("MALLOC_TRIM_THRESHOLD_")
    if value is None or "distributed" not in sys.modules:
        return False
    try:
        from distributed import get_worker

        get_worker()
    except ValueError:                       # not in a worker's task
        return False
    env = _pre_spawn_environ()
    return "MALLOC_TRIM_THRESHOLD_" in env and str(env["MALLOC_TRIM_THRESHOLD_"]) == value.strip()


def local_cluster(n_workers: int, *, dashboard=None, worker_modules: Sequence[str] | None = None):
    """The campaign's own Dask cluster: ``n_workers`` single-threaded worker processes.

    Everything listens on the loopback interface only: the scheduler and the workers
    (``host="127.0.0.1"``) and the scheduler's HTTP server, which distributed always starts
    (health and metrics routes) and which serves the dashboard - unauthenticated - when asked
    (``dashboard``); it is off by default. ``worker-saturation = 1.0``: a worker holds only
    the task it runs (inputs are paths, prefetching buys nothing), so when a worker dies or a
    task hangs only that task is concerned. Without a dashboard the workers' statistical
    profiler is off (``distributed.worker.profile.enabled``): it samples every task thread's
    stack every 10 ms for the dashboard's profile page, CPU time taken from the campaign's
    tasks; and every server's event loop wakes less often (:data:`_QUIET_MONITORS`): each
    wake-up of a worker's loop takes the GIL from its task thread, and the scheduler's and
    the Nannies' loops share the cores with the workers.

    Parameters
    ----------
    n_workers : int
    dashboard : None, bool, int or str
        None/False: no dashboard (the HTTP server on 127.0.0.1, a free port). True: the
        dashboard on 127.0.0.1, a free port. A port (8787, ":8787"): on 127.0.0.1 at that
        port. ``host:port``: there, as given (another interface only when named: it has no
        authentication; a warning is logged).
    worker_modules : sequence of str, optional
        The modules the workers' tasks need: imported once in the fork server
        (:func:`worker_server`), from which the workers are then forked, warm. None: the
        workers are spawned (fresh interpreters), as where there is no fork server.

    Returns
    -------
    distributed.LocalCluster
        Its ``dashboard_link`` is the dashboard's address.
    """
    import dask
    from distributed import LocalCluster

    n_workers = as_positive_int(n_workers, "n_workers")
    server = None if worker_modules is None else worker_server(worker_modules)
    if dashboard is not None:
        _check_dashboard(dashboard)
    on = dashboard is not None and dashboard is not False
    address = _dashboard_address(dashboard) if on else "127.0.0.1:0"
    host = address.rsplit(":", 1)[0].strip("[]")
    if on and host not in ("127.0.0.1", "localhost", "::1"):
        logger.warning("campaign: the Dask dashboard listens on %s without authentication", address)
    # the workers' own distributed logs (a cancelled task, a restart) reach stderr only when
    # our logger is verbose (meshphase -v): the campaign reports those events itself
    quiet = logging.WARNING if logger.isEnabledFor(logging.INFO) else logging.ERROR
    # what only the dashboard shows (the docstring): the workers' profiler, and the event
    # loops' tick and system metrics at a finer pitch than a campaign needs. Read when each
    # server (scheduler, Nannies here; workers in their processes) is created, so the
    # workers get theirs from their Nanny, which hands them to a worker it restarts too:
    # the config of the block below is gone by then
    monitor = {} if on else _QUIET_MONITORS
    workers_config = {"distributed.worker.profile.enabled": on, **monitor}
    config = {"distributed.scheduler.worker-saturation": 1.0, **monitor,
              "distributed.nanny.pre-spawn-environ": _worker_environ()}
    if server is not None:
        # read when a Nanny starts its worker: the initial workers fork from the server; a
        # worker restarted later (after a timeout) is spawned, as by default
        config["distributed.worker.multiprocessing-method"] = "forkserver"
    with dask.config.set(config):
        return LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                            host="127.0.0.1", dashboard_address=address, silence_logs=quiet,
                            scheduler_kwargs={"dashboard": on}, config=workers_config)


@contextlib.contextmanager
def _distributed_config_quiet() -> Iterator[None]:
    """While distributed is first imported: its logging config at ERROR unless our own logger
    is verbose (dask reads ``DASK_LOGGING__DISTRIBUTED`` from the environment at import), so
    the level :func:`_quiet_distributed` later restores is ERROR too: a cluster closed after
    that restore (a campaign interrupted while its cluster starts) logs nothing at INFO. A
    user's own setting of the variable, or an earlier import, is left as it is."""
    key = "DASK_LOGGING__DISTRIBUTED"
    set_here = ("distributed" not in sys.modules and key not in os.environ
                and not logger.isEnabledFor(logging.INFO))
    if set_here:
        os.environ[key] = "error"
    try:
        yield
    finally:
        if set_here:
            os.environ.pop(key, None)


@contextlib.contextmanager
def _quiet_distributed() -> Iterator[None]:
    """distributed logs cluster life (start, connections, close) at INFO and worker restarts
    at WARNING; show them only when our own logger is verbose (meshphase -v): the campaign
    reports lost workers, retries and timeouts itself."""
    dlog = logging.getLogger("distributed")
    old_level = dlog.level
    if not logger.isEnabledFor(logging.INFO):
        dlog.setLevel(logging.ERROR)
    try:
        yield
    finally:
        dlog.setLevel(old_level)


def _connect(scheduler, workers, dashboard, info: dict, worker_modules=None):
    """(client, cluster): a new local cluster (``scheduler`` None, its workers forked warm
    when ``worker_modules`` are given) or the one at ``scheduler`` (cluster None)."""
    from distributed import Client

    if scheduler is not None:
        try:
            client = Client(scheduler)
        except OSError as exc:
            raise ValueError(f"scheduler {scheduler!r}: cannot connect: {exc}") from None
        # a cluster job's output is a log file, not a terminal (no progress bar): the
        # scheduler's dashboard shows the tasks as they run
        link = scheduler_dashboard(client)
        if link is not None:
            info["dashboard"] = link
            logger.warning("campaign: the scheduler's Dask dashboard: %s", link)
        return client, None
    cluster = local_cluster(workers or cores(), dashboard=dashboard, worker_modules=worker_modules)
    try:
        client = Client(cluster)
    except BaseException:
        cluster.close()
        raise
    if dashboard not in (None, False):
        info["dashboard"] = cluster.dashboard_link
        logger.warning("campaign: Dask dashboard at %s", cluster.dashboard_link)
    return client, cluster


def scheduler_dashboard(client) -> str | None:
    """The address of the dashboard of the scheduler ``client`` is connected to, with the
    host of the address the client reached the scheduler at (the one that works from here);
    None when the scheduler has none.

    A scheduler names its HTTP server (health, metrics) a "dashboard" service whether or
    not it serves the dashboard (``dask scheduler --no-dashboard`` too); the dashboard's page
    is asked for once (at most 5 s, also for a scheduler slowed by a loaded machine): a 404
    means there is none. A page that cannot be reached from here (a firewall; an SSH tunnel
    would reach it) is still named.

    Parameters
    ----------
    client : distributed.Client

    Returns
    -------
    str or None
        ``http://HOST:PORT/status``.
    """
    try:
        services = client.scheduler_info().get("services") or {}
    except Exception:  # noqa: BLE001 - a link is a courtesy; the campaign goes on without it
        return None
    if "dashboard" not in services:
        return None
    try:
        link = str(client.dashboard_link)
    except Exception:  # noqa: BLE001 - as above
        return None
    import urllib.error
    import urllib.request

    try:
        with urllib.request.urlopen(link, timeout=5.0):
            pass
    except urllib.error.HTTPError as exc:
        if exc.code == 404:
            return None
    except (OSError, ValueError):       # unreachable from here: named all the same
        pass
    return link


class ClusterStart:
    """A Dask client on the campaign's own local cluster or on the one at ``scheduler``,
    started in a background thread, its workers warmed up, so that the client can do other
    work (the scene-level results) meanwhile; :meth:`client` waits for it, :meth:`close`
    closes the client and the local cluster it started.

    Parameters
    ----------
    scheduler : str or None
        Address of an existing scheduler; None: a :func:`local_cluster`.
    workers : int or None
        Local worker processes (default :func:`cores`).
    dashboard : None, bool, int or str
        The local cluster's dashboard (:func:`local_cluster`).
    warm_up : callable
        Run once on every worker (``client.run``): imports what the tasks need; returns the
        worker's pid.
    info : dict
        Filled in: ``dashboard`` (its link, when asked), ``n_workers``, ``scheduler`` (the
        address).
    worker_modules : sequence of str, optional
        What the tasks need, imported once in the fork server the local cluster's workers
        are forked from (:func:`local_cluster`); None: they are spawned.

    Attributes
    ----------
    elapsed_s : float or None
        Time the start took [s] (connect, cluster start, warm-up); None until it ended.

    Raises
    ------
    TypeError
        ``warm_up`` not callable or ``info`` not a dict.
    """

    def __init__(self, scheduler: str | None, workers: int | None, dashboard, warm_up: Callable[[], int],
                 info: dict, worker_modules: Sequence[str] | None = None):
        if not callable(warm_up) or not isinstance(info, dict):
            raise TypeError(f"warm_up must be callable and info a dict, got {type(warm_up).__name__} and "
                            f"{type(info).__name__}")
        if worker_modules is not None:
            worker_modules = _check_modules(worker_modules)
        self._args = (scheduler, workers, dashboard, warm_up, info, worker_modules)
        self._environ: dict = {}
        self._client = self._cluster = self._error = None
        self._closer = None
        self.elapsed_s: float | None = None
        self._quiet = contextlib.ExitStack()
        self._t0 = time.perf_counter()
        self._thread = threading.Thread(target=self._start, name="meshphase-cluster-start", daemon=True)
        self._thread.start()

    def _start(self) -> None:
        scheduler, workers, dashboard, warm_up, info, worker_modules = self._args
        try:
            # importing distributed sets its loggers' levels from its config (INFO): quieted
            # before that, a command's first campaign printed ~30 lines of cluster life
            with _distributed_config_quiet():
                import distributed  # noqa: F401

            self._quiet.enter_context(_quiet_distributed())
            # a local cluster's Nannies write their pre-spawn variables into this process's
            # environment (distributed's way to hand them to a spawned worker): put back on close
            if scheduler is None:
                self._environ = _spawn_environ_now()
            self._client, self._cluster = _connect(scheduler, workers, dashboard, info, worker_modules)
            try:
                pids = self._client.run(warm_up)
            except ImportError as exc:
                raise ValueError(f"the workers of {self._client.scheduler.address} cannot import "
                                 f"meshphase ({exc}); install it where the workers run") from None
            info["n_workers"] = len(pids)
            if not pids:
                logger.warning("campaign: the cluster at %s has no workers yet; the tasks wait "
                               "for workers to join", self._client.scheduler.address)
            info["scheduler"] = self._client.scheduler.address
        except BaseException as exc:  # noqa: BLE001 - handed to the thread that waits for it
            self._error = exc
        finally:
            self.elapsed_s = time.perf_counter() - self._t0

    def client(self):
        """Wait for the start and return the client.

        Returns
        -------
        distributed.Client

        Raises
        ------
        ValueError
            The scheduler cannot be reached, or its workers cannot import meshphase.
        Exception
            Whatever else the start raised.
        """
        self._thread.join()
        if self._error is not None:
            raise self._error
        return self._client

    def close(self, wait: bool = True) -> None:
        """Close the client and the local cluster (after the start has ended).

        Parameters
        ----------
        wait : bool
            False: close in a background thread (the caller goes on, e.g. writes the
            report) and call ``close()`` again later to wait for it.
        """
        if self._closer is None:
            self._closer = threading.Thread(target=self._close, name="meshphase-cluster-close", daemon=True)
            self._closer.start()
        if wait:
            self._closer.join()
            self._quiet.close()

    def _close(self) -> None:
        self._thread.join()
        try:
            if self._client is not None:
                self._client.close()
        finally:
            try:
                if self._cluster is not None:
                    self._cluster.close()
            finally:
                _restore_environ(self._environ)


def _spawn_environ_now() -> dict:
    """This process's values (None: unset) of the variables a Nanny writes into it before it
    spawns a worker: ``distributed.nanny.pre-spawn-environ`` (OMP_NUM_THREADS=1 and the like)
    and PYTHONHASHSEED, which it sets when unset. Left there, a notebook that ran a campaign
    started its later subprocesses with one BLAS thread."""
    keys = set(_pre_spawn_environ()) | {"PYTHONHASHSEED"}
    return {k: os.environ.get(k) for k in keys}


def _restore_environ(before: dict) -> None:
    """Put back the values :func:`_spawn_environ_now` took (None: unset)."""
    for k, v in before.items():
        if v is None:
            os.environ.pop(k, None)
        else:
            os.environ[k] = v


@contextlib.contextmanager
def open_client(scheduler: str | None, workers: int | None, dashboard, warm_up: Callable[[], int],
                info: dict, worker_modules: Sequence[str] | None = None) -> Iterator:
    """A Dask client on the campaign's own local cluster or on the one at ``scheduler``, its
    workers warmed up; closes the client, and the local cluster it started, on exit.

    :class:`ClusterStart` (whose parameters these are), waited for at once.

    Yields
    ------
    distributed.Client

    Raises
    ------
    ValueError
        The scheduler cannot be reached, or its workers cannot import meshphase.
    TypeError
        ``warm_up`` not callable or ``info`` not a dict.
    """
    start = ClusterStart(scheduler, workers, dashboard, warm_up, info, worker_modules)
    try:
        yield start.client()
    finally:
        start.close()


def own_child(pid) -> bool:
    """True when ``pid`` is a process this one started (a worker of our LocalCluster).

    Parameters
    ----------
    pid : int

    Returns
    -------
    bool
        False for anything else, also for a non-integer.
    """
    import psutil

    try:
        return isinstance(pid, int) and any(c.pid == pid for c in psutil.Process().children(recursive=True))
    except psutil.Error:
        return False


def end_worker(client, worker: str, pid) -> str:
    """End the worker ``worker`` (process ``pid``) whose task ran past its timeout.

    A worker of our own LocalCluster is killed at once (SIGKILL; its Nanny starts a new one:
    a graceful restart would wait for the blocked thread first); another cluster's worker is
    restarted through the scheduler (which needs a Nanny there).

    Parameters
    ----------
    client : distributed.Client
    worker : str
        The worker's address.
    pid : int
        Its process id, as it told the client.

    Returns
    -------
    str
        How it went, to follow "its worker ... was": "killed (its Nanny starts a new one)",
        "restarted", or "not stopped (...)" / "not restarted (...)" with the cause.
    """
    import signal

    if own_child(pid):
        try:
            os.kill(pid, getattr(signal, "SIGKILL", signal.SIGTERM))
            return "killed (its Nanny starts a new one)"
        except OSError as exc:
            return f"not stopped ({exc}): it may stay busy"
    try:
        res = client.restart_workers([worker], timeout=120, raise_for_error=False)
        state = res.get(worker, "?") if isinstance(res, dict) else "?"
    except Exception as exc:  # noqa: BLE001 - the campaign goes on either way
        state = f"{type(exc).__name__}: {exc}"
    return "restarted" if state == "OK" else f"not restarted ({state}): it may stay busy"
