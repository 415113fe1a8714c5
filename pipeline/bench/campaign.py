"""Campaign speed-up: the same campaign timed with different numbers of local workers.

:func:`measure_speedup` generates synthetic recordings once, then runs
:func:`meshphase.campaign.runner.run_campaign` on them with each worker count on a fresh
LocalCluster and reports wall times and speed-ups. Measured, never asserted.
"""

from __future__ import annotations

import math
import os
import statistics
import tempfile
from pathlib import Path

from ..campaign.runner import client_scene, collect_recordings, run_campaign
from ..campaign.job import campaign_modules
from ..campaign.cluster import cores, worker_server
from ..runtime.log import logger
from ..validate import as_positive, as_positive_int

__all__ = ["measure_speedup"]


def _finite_sum(values) -> float:
    return float(sum(v for v in values if isinstance(v, (int, float)) and math.isfinite(v)))


def _check_args(n_recordings, minutes, repeats, workers, scenario):
    n_recordings = as_positive_int(n_recordings, "n_recordings")
    minutes = as_positive(minutes, "minutes")
    repeats = as_positive_int(repeats, "repeats")
    if isinstance(workers, (int, str)) or not hasattr(workers, "__iter__"):
        raise TypeError(f"workers must be a sequence of ints, got {workers!r}")
    workers = [as_positive_int(w, "workers") for w in workers]
    if not workers:
        raise ValueError("workers must name at least one worker count, got an empty sequence")
    from meshphase.synthetic.scenarios import SCENARIOS

    if scenario not in SCENARIOS:
        raise ValueError(f"scenario must be one of {sorted(SCENARIOS)}, got {scenario!r}")
    return n_recordings, minutes, repeats, workers


def _prepare(work: Path, n_recordings: int, minutes: float, scenario: str, seed: int, scene_path):
    """Generate the recordings (those missing) and the scene; warm the client up. Returns
    (recordings folder, scene path, seconds the workers' fork server took to start or None)."""
    from meshphase.synthetic import cli_synth

    rec_dir = work / "recordings"
    rec_dir.mkdir(exist_ok=True)
    for k in range(n_recordings):
        p = rec_dir / f"{scenario}_{k:03d}.h5"
        if not p.exists():
            cli_synth(scenario, p, minutes=minutes, seed=seed + k, progress=False)
    if scene_path is None:
        from ..run.demo import DEMO_SCENE

        scene_path = work / "speedup_scene.toml"
        scene_path.write_text(DEMO_SCENE, encoding="utf-8")
    # warm the client up (imports, numba compilation of the Monte Carlo kernel) so that
    # the first timed run does not pay for what the later ones get for free
    import distributed  # noqa: F401

    from ..report import campaign_report  # noqa: F401
    from ..run.scene import load_scene
    from ..run.stages import run_scene

    scene = load_scene(scene_path)
    warm = client_scene(scene)
    if warm.results:
        run_scene(warm)
    # the workers' fork server is started once per process (meshphase.campaign.cluster.worker_server):
    # started here, with what the campaign would give it, every timed run finds it running,
    # the first one as much as the others
    server_s = worker_server(campaign_modules(scene, collect_recordings([rec_dir])[0]))
    return rec_dir, scene_path, server_s


def _paired(runs: list, workers: list, key: str = "wall_s") -> dict:
    """Per worker count, the speed-ups of each repeat's own pair: the reference count's run
    of a repeat against this count's run of the same repeat (the two ran one after the
    other, so a slow spell of the machine that spans both cancels). ``{w: {"pairs": [...],
    "median": ...}}``; only counts other than the reference (the first)."""
    ref = workers[0]
    by = {(r["repeat"], r["workers"]): r[key] for r in runs}
    reps = sorted({r["repeat"] for r in runs})
    out = {}
    for w in workers[1:]:
        pairs = [by[(k, ref)] / by[(k, w)] for k in reps
                 if (k, ref) in by and (k, w) in by and by[(k, w)] > 0]
        out[w] = {"pairs": pairs, "median": statistics.median(pairs) if pairs else float("nan")}
    return out


def _timed_run(scene_path, rec_dir: Path, out: Path, w: int, rep: int, progress: bool) -> dict:
    """One timed campaign with ``w`` workers: its row of ``runs``."""
    res = run_campaign(scene_path, [rec_dir], out, workers=w, progress=progress)
    tm = res["timing_s"]
    row = {"workers": w, "repeat": rep, "wall_s": tm["total"],
           "cluster_start_s": tm["cluster_start"], "cluster_wait_s": tm.get("cluster_wait", 0.0),
           "processing_s": tm["processing"], "scene_level_s": tm["scene_level"],
           "report_s": tm["report"],
           "task_sum_s": _finite_sum(r.get("wall_time_s") for r in res["recordings"]),
           "task_cpu_sum_s": _finite_sum(r.get("cpu_time_s") for r in res["recordings"]),
           "n_ok": res["counts"]["ok"], "n_failed": res["counts"]["failed"],
           "loadavg_after": list(os.getloadavg()) if hasattr(os, "getloadavg") else None}
    logger.info("speed-up: %d worker(s): %.1f s total, %.1f s processing", w,
                tm["total"], tm["processing"])
    return row


def measure_speedup(n_recordings: int = 8, minutes: float = 2.0, workers=(1, 2), *,
                    repeats: int = 1, scenario: str = "noisy", scene_path=None, work_dir=None,
                    seed: int = 0, progress: bool = False, threads: int = 1) -> dict:
    """Time the same campaign with different numbers of local worker processes.

    ``n_recordings`` synthetic recordings of ``scenario`` (HDF5, seeds ``seed`` ...) are
    generated once, then the campaign runs once per entry of ``workers`` on a fresh
    LocalCluster (one single-threaded process per worker), each into its own folder; with
    ``repeats`` > 1 the worker counts are interleaved (1, 2, 1, 2, ...) and the speed-ups
    use the shortest time per worker count (other work on the machine only ever adds time).

    Parameters
    ----------
    n_recordings : int
        Recordings in the campaign.
    minutes : float
        Length of each recording [min].
    workers : sequence of int
        Worker counts to time; the first is the reference of the speed-ups.
    repeats : int
        Timed runs per worker count.
    scenario : str
        Synthetic scenario (:data:`meshphase.synthetic.SCENARIOS`).
    scene_path : str or Path, optional
        Scene to run (default: the demo scene, :data:`meshphase.run.demo.DEMO_SCENE`).
    work_dir : str or Path, optional
        Where recordings and outputs go (default: a temporary folder, removed afterwards).
    seed : int
        Seed of the first recording.
    progress : bool
    threads : int
        Worker threads of each recording's run (:mod:`meshphase.runtime.threads`) [-]. The default 1
        measures the campaign's own scaling over workers; a ``meshphase campaign`` command
        gives each recording its share of the cores instead (all of them with 1 worker),
        which makes the 1-worker run faster and the ratio smaller.

    Returns
    -------
    dict
        ``n_recordings``, ``minutes``, ``cores``, ``runs`` (per worker count: ``workers``,
        ``wall_s`` total incl. cluster start, ``cluster_start_s`` (in the background, while the
        scene-level results run), ``cluster_wait_s`` (what the campaign still waited for it),
        ``processing_s``
        (first submit to last result), ``scene_level_s``, ``report_s``, ``task_sum_s`` and
        ``task_cpu_sum_s`` (sums of the tasks' own wall and CPU times: their ratio shows
        contention for the cores), ``n_ok``, ``n_failed``, ``loadavg_after`` (the machine's
        load averages after the run)), ``loadavg`` (the machine's load
        before the first run: other work on the cores distorts the numbers),
        ``worker_server_s`` (the start of the workers' fork server, once, before the timed
        runs: a ``meshphase campaign`` command pays it in the background while its scene-level
        results run; None where there is none), and
        ``speedup`` / ``processing_speedup`` per worker count relative to the first (best
        times), and ``paired_speedup`` / ``paired_processing_speedup`` (per worker count but
        the first: ``pairs``, each repeat's reference run over this count's run of the same
        repeat, and their ``median``; less sensitive than the best times to a slow spell of
        the machine that hits one worker count's runs more than the other's), and
        ``task_cpu_ratio`` per worker count (the median of the runs' task CPU sums over the
        first count's: 1 when the workers do not slow each other; NaN without CPU times).
    """
    n_recordings, minutes, repeats, workers = _check_args(n_recordings, minutes, repeats, workers,
                                                          scenario)
    tmp = None
    if work_dir is None:
        tmp = tempfile.TemporaryDirectory(prefix="meshphase-speedup-")
        work = Path(tmp.name)
    else:
        work = Path(work_dir)
        work.mkdir(parents=True, exist_ok=True)
    try:
        rec_dir, scene_path, server_s = _prepare(work, n_recordings, minutes, scenario, seed, scene_path)
        load0 = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
        from ..runtime.threads import threads_limited

        with threads_limited(as_positive_int(threads, "threads")):
            runs = [_timed_run(scene_path, rec_dir, work / f"campaign-{w}w", w, rep, progress)
                    for rep in range(repeats) for w in workers]
        best = {w: min(r["wall_s"] for r in runs if r["workers"] == w) for w in workers}
        cpu = {w: statistics.median(r["task_cpu_sum_s"] for r in runs if r["workers"] == w)
               for w in workers}
        best_p = {w: min(r["processing_s"] for r in runs if r["workers"] == w) for w in workers}
        ref = workers[0]
        return {"n_recordings": n_recordings, "minutes": minutes, "scenario": scenario,
                "repeats": repeats, "threads": threads, "cores": cores(),
                "loadavg": list(load0), "runs": runs,
                "worker_server_s": server_s,
                "best_wall_s": best, "best_processing_s": best_p,
                "speedup": {w: best[ref] / best[w] for w in workers},
                "processing_speedup": {w: best_p[ref] / best_p[w] for w in workers},
                "paired_speedup": _paired(runs, workers),
                "paired_processing_speedup": _paired(runs, workers, "processing_s"),
                # the same recordings: more CPU on more workers is the cores slowing each
                # other (shared caches, memory, a host's other guests), which no scheduling
                # removes
                "task_cpu_ratio": {w: cpu[w] / cpu[ref] if cpu[ref] > 0 else float("nan")
                                   for w in workers}}
    finally:
        if tmp is not None:
            tmp.cleanup()
