"""Start-up time of the ``meshphase`` command and of the imports behind it.

Each row runs a fresh interpreter ``repeats`` times and reports the median wall time and the
number of modules loaded; ``python -c pass`` is the floor the others stand on. Measured,
never asserted (tests/test_core_imports.py holds which modules each command loads).

The interpreters write and reuse bytecode (``.pyc``) as a user's do from their second run
on: ``PYTHONDONTWRITEBYTECODE`` is cleared for them (:func:`meshphase.bench.rss.child_env`)
and every case runs once, untimed, before the timed runs. The development machine's
environment sets that variable, and the figures of earlier stops (README) include compiling
meshphase's sources at every start.
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from ..validate import as_positive_int

__all__ = ["STARTUP_COLUMNS", "EXIT_COLUMNS", "startup_rows", "exit_rows"]

#: Columns of the start-up table: the whole process [s] (median, min, max), the modules
#: loaded, the median over ``python -c pass`` [s], and ``ready_s``: the median from the start
#: to the end of the case's code, the imports (or the command) done, before the
#: interpreter's exit (whose cost :func:`exit_rows` measures) [s].
STARTUP_COLUMNS = ("what", "median_s", "min_s", "max_s", "modules", "over_python_s", "ready_s")
#: Columns of the exit table: from the last ``atexit`` handler to the process reaped [s], the
#: objects the collector tracked at the end of the command and the collection
#: :func:`meshphase.cli.console_main` runs before it freezes them [s].
EXIT_COLUMNS = ("what", "median_s", "min_s", "max_s", "objects", "collect_s")

# the wall clock when the case's code is done (before the interpreter's exit), then the modules
_COUNT = ("import sys, time; print(repr(time.time()), file=sys.stderr); "
          "print(len(sys.modules), file=sys.stderr)")


def _cases(h5: Path) -> list:
    """(label, python -c code) per row; the CLI rows call ``main`` as the console script does."""
    def cli(argv):
        return (f"import sys; from meshphase.cli import main; rc = main({argv!r}); "
                f"{_COUNT}; sys.exit(rc)")

    return [("python -c pass", _COUNT),
            ("import meshphase", f"import meshphase; {_COUNT}"),
            ("meshphase --version", "import sys\nfrom meshphase.cli import main\n"
                                    "try:\n    main(['--version'])\nexcept SystemExit:\n    pass\n"
                                    + _COUNT),
            ("meshphase info FILE.h5 --no-quality", cli(["info", str(h5), "--no-quality"])),
            ("meshphase info FILE.h5", cli(["info", str(h5)])),
            ("import meshphase.run.stages (what process loads)", f"import meshphase.run.stages; {_COUNT}"),
            # what the filters' scipy engine adds (process takes numba's kernel instead when
            # numba is installed: meshphase.signal.iir.pick_engine)
            ("import meshphase.run.stages, scipy.signal", f"import meshphase.run.stages, scipy.signal; {_COUNT}"),
            # what process loads at its first filter where numba is installed (its kernel's
            # engine, meshphase.signal.iir.pick_engine, for a recording of NUMBA_SAMPLES or more)
            ("import meshphase.run.stages, numba", f"import meshphase.run.stages, numba; {_COUNT}"),
            # what process loaded while pandas wrote its CSV tables (meshphase.run.table_csv now)
            ("import meshphase.run.stages, pandas", f"import meshphase.run.stages, pandas; {_COUNT}")]


def _timed_runs(make_cases, repeats: int, what: str):
    """Run each case in fresh interpreters: one untimed round (it writes the bytecode), then
    ``repeats`` timed rounds, the cases interleaved so that other work on the machine spreads
    over all of them.

    ``make_cases(h5)`` gives ``(label, argv)`` pairs (argv after ``python``), ``h5`` a
    one-second recording of two gauges in the runs' working folder (the file's size does
    not matter, the imports do). Returns the cases and, per label, one ``(started, elapsed,
    reaped, stdout, stderr)`` per timed run: wall clock at the start [s since the epoch],
    the run's wall time [s], wall clock once it was reaped [s since the epoch].
    """
    repeats = as_positive_int(repeats, "repeats")
    import numpy as np

    from ..io import write
    from ..recording import Recording
    from .rss import child_env

    with tempfile.TemporaryDirectory(prefix=f"meshphase-{what}-") as tmp:
        h5 = Path(tmp) / f"{what}.h5"
        write(Recording(np.zeros((5120, 2)), 5120.0, ["sun_g1", "ring_g1"]), h5)
        cases = make_cases(h5)
        runs = {label: [] for label, _ in cases}
        env = child_env()
        for k in range(repeats + 1):
            for label, argv in cases:
                t, started = time.perf_counter(), time.time()
                res = subprocess.run([sys.executable, *argv], capture_output=True, text=True, cwd=tmp,
                                     env=env)
                elapsed, reaped = time.perf_counter() - t, time.time()
                if res.returncode != 0:
                    raise RuntimeError(f"{what} case {label!r} failed:\n{res.stderr[-2000:]}")
                if k:
                    runs[label].append((started, elapsed, reaped, res.stdout, res.stderr))
    return cases, runs


def startup_rows(repeats: int = 5) -> list:
    """Median wall time [s] of each start-up case over ``repeats`` fresh interpreters.

    Parameters
    ----------
    repeats : int
        Runs per case (>= 1); the cases are interleaved so that other work on the machine
        spreads over all of them.

    Returns
    -------
    list of dict
        Rows with the keys :data:`STARTUP_COLUMNS`; ``over_python_s`` is the median minus the
        ``python -c pass`` median (what meshphase itself costs).
    """
    cases, runs = _timed_runs(lambda h5: [(label, ["-c", code]) for label, code in _cases(h5)],
                              repeats, "start-up")
    rows = []
    for label, _ in cases:
        times = [elapsed for _, elapsed, _, _, _ in runs[label]]
        # the code's last two stderr lines: the wall clock when it was done, the modules
        done = [err.strip().splitlines()[-2:] for _, _, _, _, err in runs[label]]
        rows.append({"what": label, "median_s": statistics.median(times), "min_s": min(times),
                     "max_s": max(times), "modules": int(done[-1][1]),
                     "ready_s": statistics.median(float(d[0]) - r[0] for d, r in zip(done, runs[label]))})
    base = rows[0]["median_s"]
    for r in rows:
        r["over_python_s"] = r["median_s"] - base
    return [{c: r[c] for c in STARTUP_COLUMNS} for r in rows]


def _exit_code(frozen: bool) -> str:
    """``python -c`` code: the campaign workers' stack imported, ``meshphase info FILE``
    (argv[1]), then the interpreter's exit as it is or as :func:`meshphase.cli.console_main`
    leaves it (one collection, timed, then the heap frozen). Prints the tracked objects and
    the collection's time; the last ``atexit`` handler prints the wall clock."""
    tail = ("t = time.perf_counter(); gc.collect(); c = time.perf_counter() - t; gc.freeze()\n" if frozen
            else "c = float('nan')\n")
    return ("import atexit, contextlib, gc, importlib, io, sys, time\n"
            "from meshphase.campaign.job import _FORK_READY, worker_modules\n"
            "for m in worker_modules():\n"
            "    if m != _FORK_READY:      # the workers' fork server freezes; a command does not\n"
            "        importlib.import_module(m)\n"
            "from meshphase.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            "    assert main(['info', sys.argv[1]]) == 0\n"
            "n = len(gc.get_objects())\n" + tail +
            "print(n, c)\n"
            "atexit.register(lambda: print(repr(time.time()), flush=True))\n")


def exit_rows(repeats: int = 5) -> list:
    """Median time [s] from a command's last ``atexit`` handler to its process reaped: the
    interpreter's own finalization, with the campaign workers' stack loaded (dask,
    matplotlib, pandas, h5py, scipy), as it is and after :func:`meshphase.cli.console_main`'s
    collection and :func:`gc.freeze`.

    Parameters
    ----------
    repeats : int
        Fresh interpreters per case (>= 1), the cases interleaved, after one untimed round.

    Returns
    -------
    list of dict
        Rows with the keys :data:`EXIT_COLUMNS`.
    """
    import math

    cases, runs = _timed_runs(
        lambda h5: [("exit as the interpreter does it", ["-c", _exit_code(False), str(h5)]),
                    ("exit after console_main's collection and gc.freeze", ["-c", _exit_code(True), str(h5)])],
        repeats, "exit")
    rows = []
    for label, _ in cases:
        # stdout's last two lines: the objects and the collection's time, then the wall clock
        # in the last atexit handler
        got = [(out.strip().splitlines()[-2].split(), reaped - float(out.strip().splitlines()[-1]))
               for _, _, reaped, out, _ in runs[label]]
        ends = [e for _, e in got]
        collect = [float(c) for (_, c), _ in got]
        rows.append({"what": label, "median_s": statistics.median(ends), "min_s": min(ends),
                     "max_s": max(ends), "objects": int(got[-1][0][0]),
                     "collect_s": (statistics.median(collect) if all(map(math.isfinite, collect))
                                   else float("nan"))})
    return rows
