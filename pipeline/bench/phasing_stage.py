"""The phasing stage's time and share of ``meshphase process``, and the run's fixed cost.

The 8-channel benchmark recording (:func:`meshphase.bench.rss.bench_config`) of each length
is written once, then ``meshphase process`` runs on every length in fresh interpreters
(:func:`meshphase.bench.rss.run_child`), the lengths interleaved ``repeats`` times so that
other work on a shared machine spreads over all of them. Per length: the run's wall time
(interpreter start to exit) and the phasing stage's time [s], min and median over the
repeats, and the stage's share of the run (median of the per-run ratios). The fixed cost per
run is the wall time extrapolated linearly to a recording of no length from the two
shortest lengths' medians, 2 t(a) - t(2a) when the second is twice the first: the start-up,
the imports and every cost that does not grow with the samples. The machine's load average
is recorded beside the figures. Measured, never asserted.
"""

from __future__ import annotations

import os
import shutil
import statistics
from pathlib import Path

from ..runtime.log import logger
from ..validate import as_positive, as_positive_int

__all__ = ["PHASING_COLUMNS", "PHASING_MINUTES", "phasing_stage_rows", "fixed_cost",
           "phasing_markdown"]

#: Columns of the phasing-stage table.
PHASING_COLUMNS = ("minutes", "repeats", "wall_min_s", "wall_median_s", "phasing_min_s",
                   "phasing_median_s", "phasing_share", "status")
#: Recording lengths [min] of the default table: the two short ones give the fixed cost.
PHASING_MINUTES = (2.0, 4.0, 60.0)


def phasing_stage_rows(work, minutes=PHASING_MINUTES, repeats: int = 3, *, seed: int = 1) -> list:
    """Wall time of ``meshphase process`` and of its phasing stage per recording length.

    Parameters
    ----------
    work : path-like
        Working folder (created; the recordings and outputs are removed again).
    minutes : sequence of float
        Recording lengths [min] (positive).
    repeats : int
        Runs per length (>= 1), interleaved over the lengths.
    seed : int
        Seed of the generated recordings.

    Returns
    -------
    list of dict
        Rows with the keys :data:`PHASING_COLUMNS`, in the order of ``minutes``; empty when
        ``minutes`` is.
    """
    from .rss import BENCH_GEARSET, run_child

    minutes = [float(as_positive(m, "minutes")) for m in minutes]
    repeats = as_positive_int(repeats, "repeats")
    if not minutes:
        return []
    work = Path(work)
    work.mkdir(parents=True, exist_ok=True)
    gearset = work / "gearset.toml"
    gearset.write_text(BENCH_GEARSET, encoding="utf-8")
    paths = {}
    try:
        for m in minutes:
            paths[m] = work / f"phasing_{m:g}.h5"
            run_child("write_job", path=str(paths[m]), minutes=m, seed=seed)
        run_child("import_job")                  # the bytecode written, as a user's first run
        runs = {m: [] for m in minutes}
        for _ in range(repeats):
            for m in minutes:
                r = run_child("process_job", path=str(paths[m]), gearset=str(gearset),
                              out_dir=str(work / f"out_{m:g}"))
                runs[m].append((r["wall_s"], r["timings"].get("phasing", float("nan")), r["status"]))
                shutil.rmtree(work / f"out_{m:g}", ignore_errors=True)
                logger.info("phasing bench: %g min: %.2f s, phasing %.2f s", m, r["wall_s"],
                            runs[m][-1][1])
    finally:
        for p in paths.values():
            p.unlink(missing_ok=True)
    rows = []
    for m in minutes:
        wall = [w for w, _, _ in runs[m]]
        ph = [p for _, p, _ in runs[m]]
        rows.append({"minutes": m, "repeats": repeats, "wall_min_s": min(wall),
                     "wall_median_s": statistics.median(wall), "phasing_min_s": min(ph),
                     "phasing_median_s": statistics.median(ph),
                     "phasing_share": statistics.median(p / w for w, p, _ in runs[m]),
                     "status": ",".join(sorted({s for _, _, s in runs[m]}))})
    return rows


def fixed_cost(rows) -> float:
    """Wall time of a run extrapolated linearly to a recording of no length [s], from the
    median wall times of the two shortest lengths in ``rows``; NaN with fewer than two
    lengths."""
    rows = sorted(rows, key=lambda r: r["minutes"])
    if len(rows) < 2 or rows[0]["minutes"] == rows[1]["minutes"]:
        return float("nan")
    (a, ta), (b, tb) = [(r["minutes"], r["wall_median_s"]) for r in rows[:2]]
    return ta - a * (tb - ta) / (b - a)


def phasing_markdown(rows) -> str:
    """The table of :func:`phasing_stage_rows` and the fixed cost, as Markdown."""
    lines = ["| " + " | ".join(PHASING_COLUMNS) + " |", "|" + "---|" * len(PHASING_COLUMNS)]
    for r in rows:
        lines.append("| " + " | ".join(f"{r[c]:.3g}" if isinstance(r[c], float) else str(r[c])
                                       for c in PHASING_COLUMNS) + " |")
    load = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
    lines += ["", f"fixed cost per run (wall time extrapolated to no length): "
                  f"{fixed_cost(rows):.3f} s; load average at the end {load[0]:.2f} "
                  f"on {os.cpu_count()} cores"]
    return "\n".join(lines) + "\n"
