"""A Dask cluster of separate processes: a scheduler and workers started as commands, as a
batch allocation or a container platform starts them.

:class:`ProcessCluster` runs ``python -m dask scheduler`` (the ``dask scheduler`` command)
and one ``python -m dask worker`` per worker (``dask worker``, each under its own Nanny, one
thread), all on 127.0.0.1, the scheduler at a free port the operating system chooses; the
workers find it through the scheduler file it writes (``--scheduler-file``, the way
dask-jobqueue's and dask-mpi's jobs meet their scheduler on a shared file system). Each
worker runs in a session of its own, so :meth:`ProcessCluster.kill_worker` ends it and its
Nanny together with SIGKILL, as a node that fails or a job the batch system kills: Dask
reruns the tasks it held on the other workers (``distributed.scheduler.allowed-failures``
applies: ``docs/cluster.md``).

What a campaign does on such a cluster is the same as on any other scheduler
(``meshphase campaign --scheduler ADDRESS``): the tests of a campaign on a real cluster and
``meshphase bench campaign``'s overhead run use this class. ``distributed`` is imported
inside the methods.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from ..validate import as_positive, as_positive_int

__all__ = ["ProcessCluster"]


def _kill_group(proc: subprocess.Popen, sig: int) -> None:
    """Send ``sig`` to the session ``proc`` leads (it was started with a session of its own)."""
    if proc.poll() is not None:
        return
    try:
        os.killpg(proc.pid, sig)
    except ProcessLookupError:
        pass


class ProcessCluster:
    """A Dask scheduler and ``n_workers`` workers, each started as a separate process.

    Parameters
    ----------
    n_workers : int
        Worker processes (``dask worker --nworkers 1 --nthreads 1`` each).
    work_dir : str or Path, optional
        Where the scheduler file, the workers' local folders and the logs
        (``scheduler.log``, ``worker-<i>.log``) go; default a temporary folder, removed on
        :meth:`close`.
    dashboard : bool
        Serve the scheduler's dashboard (``--dashboard``; False: ``--no-dashboard``). Its
        HTTP server listens on 127.0.0.1 at a free port either way
        (``--dashboard-address 127.0.0.1:0``).
    start_timeout : float
        Seconds to wait for the scheduler and every worker [s].
    env : dict, optional
        Extra environment variables of every process (``DASK_...`` configuration, say).

    Attributes
    ----------
    address : str
        The scheduler's address (``tcp://127.0.0.1:PORT``).
    scheduler_file : Path
    workers : list of subprocess.Popen
        One per worker (the ``dask worker`` command: the Nanny, which starts the worker).

    Raises
    ------
    ValueError
        ``n_workers`` or ``start_timeout`` not positive.
    TypeError
        ``env`` not a dict of strings.
    RuntimeError
        The scheduler or a worker did not start within ``start_timeout`` (its log is named).
    """

    def __init__(self, n_workers: int, *, work_dir=None, dashboard: bool = False,
                 start_timeout: float = 120.0, env: dict | None = None):
        self.n_workers = as_positive_int(n_workers, "n_workers")
        self.start_timeout = as_positive(start_timeout, "start_timeout")
        if env is not None and not (isinstance(env, dict) and all(
                isinstance(k, str) and isinstance(v, str) for k, v in env.items())):
            raise TypeError(f"env must be a dict of str -> str, got {env!r}")
        self._tmp = tempfile.TemporaryDirectory(prefix="meshphase-dask-") if work_dir is None else None
        self.work_dir = Path(self._tmp.name if self._tmp is not None else work_dir)
        self.work_dir.mkdir(parents=True, exist_ok=True)
        self.dashboard = bool(dashboard)
        self._env = {**os.environ, **(env or {})}
        self.scheduler_file = self.work_dir / "scheduler.json"
        self.scheduler: subprocess.Popen | None = None
        self.workers: list[subprocess.Popen] = []
        self.address: str | None = None
        self._logs: list = []
        try:
            self._start()
        except BaseException:
            self.close()
            raise

    # ------------------------------------------------------------------ start
    def _popen(self, args: list, log_name: str) -> subprocess.Popen:
        log = open(self.work_dir / log_name, "wb")
        self._logs.append(log)
        return subprocess.Popen([sys.executable, "-m", "dask", *args], stdin=subprocess.DEVNULL,
                                stdout=log, stderr=subprocess.STDOUT, env=self._env,
                                cwd=self.work_dir, start_new_session=True)

    def _start(self) -> None:
        t_end = time.monotonic() + self.start_timeout

        def remaining() -> float:
            return max(0.1, t_end - time.monotonic())

        self.scheduler_file.unlink(missing_ok=True)
        # the scheduler's HTTP server (health, metrics; the dashboard when asked) listens
        # whether or not there is a dashboard: on loopback, at a free port
        dash = ["--dashboard-address", "127.0.0.1:0"] + ([] if self.dashboard else ["--no-dashboard"])
        self.scheduler = self._popen(["scheduler", "--host", "127.0.0.1", "--port", "0",
                                      "--scheduler-file", str(self.scheduler_file), *dash], "scheduler.log")
        self.address = self._wait_for_scheduler(remaining())
        for i in range(self.n_workers):
            self.workers.append(self._popen(self._worker_args(i), f"worker-{i}.log"))
        self.wait_for_workers(self.n_workers, timeout=remaining())

    def _worker_args(self, i: int) -> list:
        return ["worker", "--scheduler-file", str(self.scheduler_file), "--nworkers", "1",
                "--nthreads", "1", "--host", "127.0.0.1", "--no-dashboard", "--name", f"w{i}",
                "--local-directory", str(self.work_dir / f"w{i}"), "--death-timeout", "60"]

    def _wait_for_scheduler(self, timeout: float) -> str:
        log = self.work_dir / "scheduler.log"
        t_end = time.monotonic() + timeout
        while time.monotonic() < t_end:
            if self.scheduler.poll() is not None:
                raise RuntimeError(f"dask scheduler exited with {self.scheduler.returncode} at start; "
                                   f"see {log}")
            try:
                info = json.loads(self.scheduler_file.read_text())
                return str(info["address"])
            except (OSError, ValueError, KeyError):
                time.sleep(0.1)
        raise RuntimeError(f"dask scheduler not up after {self.start_timeout:g} s (no {self.scheduler_file}); "
                           f"see {log}")

    def wait_for_workers(self, n: int, timeout: float = 120.0) -> None:
        """Wait until ``n`` workers are connected to the scheduler.

        Parameters
        ----------
        n : int
        timeout : float
            [s]

        Raises
        ------
        RuntimeError
            Fewer than ``n`` after ``timeout`` (a worker's log is named).
        """
        from distributed import Client

        n = as_positive_int(n, "n")
        with Client(self.address, timeout=f"{max(timeout, 1.0)}s") as client:
            try:
                client.wait_for_workers(n, timeout=timeout)
            except TimeoutError:
                raise RuntimeError(f"{len(client.scheduler_info()['workers'])} of {n} dask "
                                   f"workers connected after {timeout:.3g} s; see "
                                   f"{self.work_dir / 'worker-0.log'}") from None

    # ------------------------------------------------------------------ use
    @property
    def dashboard_link(self) -> str | None:
        """The scheduler's dashboard address (``http://127.0.0.1:PORT/status``), None without."""
        if not self.dashboard or self.address is None:
            return None
        from distributed import Client

        with Client(self.address) as client:
            return client.dashboard_link

    def worker_pids(self) -> list[int | None]:
        """The process id of each worker (its ``dask worker`` command); None once it ended."""
        return [p.pid if p.poll() is None else None for p in self.workers]

    def worker_of(self, pid: int) -> int | None:
        """The index of the worker whose session holds process ``pid`` (a task's worker
        process, a child of the Nanny), None for none."""
        try:
            group = os.getpgid(pid)
        except (ProcessLookupError, TypeError):
            return None
        for i, p in enumerate(self.workers):
            if p.pid == group and p.poll() is None:
                return i
        return None

    def kill_worker(self, i: int) -> None:
        """End worker ``i`` and its Nanny at once (SIGKILL to its session), as a failed node.

        Parameters
        ----------
        i : int
            Index into :attr:`workers`.

        Raises
        ------
        IndexError
            No such worker.
        """
        if not isinstance(i, int) or not 0 <= i < len(self.workers):
            raise IndexError(f"no worker {i!r}: this cluster has {len(self.workers)}")
        _kill_group(self.workers[i], signal.SIGKILL)
        self.workers[i].wait()

    # ------------------------------------------------------------------ end
    def close(self) -> None:
        """End the workers, then the scheduler (SIGTERM, then SIGKILL after 10 s); remove the
        temporary folder if this cluster made it."""
        procs = [p for p in [*self.workers, self.scheduler] if p is not None]
        for p in procs:
            _kill_group(p, signal.SIGTERM)
        t_end = time.monotonic() + 10.0
        for p in procs:
            try:
                p.wait(timeout=max(0.1, t_end - time.monotonic()))
            except subprocess.TimeoutExpired:
                _kill_group(p, signal.SIGKILL)
                p.wait()
        for log in self._logs:
            log.close()
        self._logs = []
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None

    def __enter__(self) -> "ProcessCluster":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
