"""What a campaign worker's first figure of the combined report costs over its second.

A campaign's local workers fork from a server that imported
:func:`meshphase.campaign.job.worker_modules`; the last of them, :mod:`meshphase.campaign.fork_ready`,
freezes the heap. Each case here is a fresh interpreter that imports that list
without that module (``without fork_ready``: no frozen heap, no figure drawn before the
fork) or with it (``with fork_ready``), then forks one child per draw:
the child draws one figure of the combined report twice, as a worker does after its
recordings, and reports both times (a JSON line in a results file). Measured, never asserted.
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from ..validate import as_positive_int

__all__ = ["FIRST_FIGURE_COLUMNS", "first_figure_rows"]

#: Columns of the table: per case and figure, the median of first minus second draw [s] and
#: the median second draw [s].
FIRST_FIGURE_COLUMNS = ("case", "figure", "first_excess_s", "min_excess_s", "max_excess_s", "second_s")

_CODE = """
import importlib, json, os, sys, time
from meshphase.campaign.job import worker_modules, _FORK_READY
frozen, repeats, results = sys.argv[1] == "with fork_ready", int(sys.argv[2]), sys.argv[3]
for m in worker_modules():          # every reader, as a campaign over mixed formats
    if frozen or m != _FORK_READY:
        importlib.import_module(m)
from meshphase.report import campaign_report as cr
cr.pyplot()                         # matplotlib on Agg in both cases (fork_ready imports it too)
n, planets = 8, ["1", "2", "3", "4"]
names = [f"rec_{i:03d}" for i in range(n)]
ph = {g: {p: ([0.01 * i for i in range(n)], [0.002] * n) for p in planets} for g in ("sun", "ring")}
ideal = {g: {p: 0.25 * int(p) for p in planets} for g in ("sun", "ring")}
calls = {"phasing": (cr.phasing_across_recordings, (names, ph, ideal)),
         "load_sharing": (cr.load_sharing_across_recordings, (names, [[1.0, 1.01, 0.99, 1.0]] * n,
                                                              [[0.01] * 4] * n)),
         "residual_rms": (cr.residual_rms_across_recordings, (names, {"sun": [0.01] * n, "ring": [0.02] * n})),
         "wall_times": (cr.wall_times_across_recordings, (names, [0.4] * n, ["ok"] * (n - 1) + ["failed"]))}
for _ in range(repeats):
    for name, (make, args) in calls.items():
        r, w = os.pipe()
        pid = os.fork()
        if pid == 0:
            os.close(r)
            t = time.perf_counter(); cr.figure_png(make, *args); t1 = time.perf_counter() - t
            t = time.perf_counter(); cr.figure_png(make, *args); t2 = time.perf_counter() - t
            os.write(w, json.dumps([name, t1, t2]).encode())
            os._exit(0)
        os.close(w)
        with os.fdopen(r) as f, open(results, "a", encoding="utf-8") as out:
            out.write(f.read() + "\\n")
        os.waitpid(pid, 0)
"""


def first_figure_rows(repeats: int = 6) -> list:
    """The first figure's excess over the second in a forked worker, without and with
    :mod:`meshphase.campaign.fork_ready` (its frozen heap and the small figure it draws).

    Parameters
    ----------
    repeats : int
        Forked children per case and figure (>= 1).

    Returns
    -------
    list of dict
        Rows with the keys :data:`FIRST_FIGURE_COLUMNS`, the case without fork_ready first; empty
        where this platform cannot fork (no ``os.fork``: no fork server either).
    """
    import os

    repeats = as_positive_int(repeats, "repeats")
    if not hasattr(os, "fork"):
        return []
    from .rss import child_env

    rows = []
    for case in ("without fork_ready", "with fork_ready"):
        with tempfile.TemporaryDirectory(prefix="meshphase-first-figure-") as tmp:
            results = Path(tmp) / "draws.jsonl"
            res = subprocess.run([sys.executable, "-c", _CODE, case, str(repeats), str(results)],
                                 capture_output=True, text=True, env=child_env())
            if res.returncode != 0:
                raise RuntimeError(f"first-figure case {case!r} failed:\n{res.stderr[-2000:]}")
            lines = results.read_text(encoding="utf-8").splitlines()
        got: dict = {}
        for line in lines:
            if not line.strip():
                continue
            name, t1, t2 = json.loads(line)
            got.setdefault(name, []).append((t1 - t2, t2))
        for name, v in got.items():
            ex = [e for e, _ in v]
            rows.append({"case": case, "figure": name, "first_excess_s": statistics.median(ex),
                         "min_excess_s": min(ex), "max_excess_s": max(ex),
                         "second_s": statistics.median(s for _, s in v)})
    return rows
