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

__all__ = ["STARTUP_COLUMNS", "startup_rows"]

#: Columns of the start-up table.
STARTUP_COLUMNS = ("what", "median_s", "min_s", "max_s", "modules", "over_python_s")

_COUNT = "import sys; print(len(sys.modules), file=sys.stderr)"


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
            ("import meshphase.stages (what process loads)", f"import meshphase.stages; {_COUNT}"),
            # what the filters' scipy engine adds (process takes numba's kernel instead when
            # numba is installed: meshphase.iir.pick_engine)
            ("import meshphase.stages, scipy.signal", f"import meshphase.stages, scipy.signal; {_COUNT}"),
            # what process loaded while pandas wrote its CSV tables (meshphase.table_csv now)
            ("import meshphase.stages, pandas", f"import meshphase.stages, pandas; {_COUNT}")]


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
    repeats = as_positive_int(repeats, "repeats")
    import numpy as np

    from ..io import write
    from ..recording import Recording
    from .rss import child_env

    with tempfile.TemporaryDirectory(prefix="meshphase-startup-") as tmp:
        h5 = Path(tmp) / "startup.h5"
        # one second of two gauges: the file's size does not matter, the imports do
        write(Recording(np.zeros((5120, 2)), 5120.0, ["sun_g1", "ring_g1"]), h5)
        cases = _cases(h5)
        times = {label: [] for label, _ in cases}
        modules = {}
        env = child_env()
        for k in range(repeats + 1):              # the first round writes the bytecode
            for label, code in cases:
                t = time.perf_counter()
                res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                     cwd=tmp, env=env)
                if k:
                    times[label].append(time.perf_counter() - t)
                if res.returncode != 0:
                    raise RuntimeError(f"start-up case {label!r} failed:\n{res.stderr[-2000:]}")
                modules[label] = int(res.stderr.strip().splitlines()[-1])
    base = statistics.median(times[cases[0][0]])
    return [{"what": label, "median_s": statistics.median(times[label]),
             "min_s": min(times[label]), "max_s": max(times[label]), "modules": modules[label],
             "over_python_s": statistics.median(times[label]) - base} for label, _ in cases]
