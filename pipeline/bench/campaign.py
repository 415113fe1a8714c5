"""Campaign benchmarks: the speed-up over local workers, and the machinery's overhead on a
cluster of separate processes.

:func:`measure_speedup` generates synthetic recordings once, then runs
:func:`meshphase.campaign.runner.run_campaign` on them with each worker count on a fresh
LocalCluster and reports wall times and speed-ups. :func:`measure_overhead` runs a campaign
on a scheduler and workers started as separate processes
(:class:`meshphase.campaign.processes.ProcessCluster`) and the plain ``meshphase process`` of
the same recordings on as many plain processes, and reports the campaign's cost per
recording over the plain processing. Measured, never asserted.
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

__all__ = ["measure_speedup", "measure_overhead", "overhead_lines", "process_scene_text"]


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


# ---------------------------------------------------------------------------- overhead
def process_scene_text() -> str:
    """The demo scene (:data:`meshphase.run.demo.DEMO_SCENE`) asking for what ``meshphase
    process`` computes (:data:`meshphase.run.stages.PROCESS_RESULTS`), without its tolerance
    table (``process`` runs no Monte Carlo): a campaign of it does per recording exactly
    what ``process`` does.

    Returns
    -------
    str
        Scene TOML.
    """
    import re

    from ..run.demo import DEMO_SCENE
    from ..run.stages import PROCESS_RESULTS

    text = DEMO_SCENE.split("\n[tolerances]")[0]
    results = "results = [" + ", ".join(f'"{r}"' for r in PROCESS_RESULTS) + "]"
    return re.sub(r"(?m)^results = .*$", results, text, count=1)


def _plain_warm(modules) -> int:
    """Import in a plain pool process what a campaign's workers import when they connect
    (:func:`meshphase.campaign.job.warm_up`: the processing stack, the first uses of
    :mod:`meshphase.campaign.fork_ready`), not timed; hold it a moment so that every process
    of the pool gets one."""
    import time as _time

    from ..campaign.job import warm_up

    warm_up(modules)
    _time.sleep(0.5)
    return os.getpid()


def _plain_process(args) -> float:
    """``meshphase process`` of one recording (:func:`meshphase.run.stages.process_recording`);
    its wall time [s]."""
    import time as _time

    from ..run.stages import process_recording

    rec, scene, out = args
    t = _time.perf_counter()
    process_recording(rec, scene, out_dir=out, overwrite=True)
    return _time.perf_counter() - t


def _link_recordings(rec_dir: Path, sources: list, n: int) -> None:
    """``n`` recordings in ``rec_dir`` named ``rec_<k>.h5``: hard links to ``sources`` in
    turn (copies where the file system has none). A campaign treats every file as a
    recording of its own."""
    for k in range(n):
        dst = rec_dir / f"rec_{k:03d}.h5"
        if dst.exists():
            continue
        src = sources[k % len(sources)]
        try:
            os.link(src, dst)
        except OSError:
            import shutil

            shutil.copyfile(src, dst)


def measure_overhead(n_recordings: int = 200, minutes: float = 2.0, workers: int = 2, *,
                     distinct: int = 4, scenario: str = "noisy", work_dir=None, seed: int = 0) -> dict:
    """The campaign machinery's cost per recording, on a cluster of separate processes.

    ``distinct`` synthetic recordings of ``scenario`` are generated and linked under
    ``n_recordings`` names. Then, on the same recordings, with :func:`process_scene_text`:

    1. the plain processing: ``meshphase process`` of each recording
       (:func:`meshphase.run.stages.process_recording`) in a pool of ``workers`` plain
       processes, warmed up first (imports), no Dask;
    2. the campaign: ``dask scheduler`` and ``workers`` x ``dask worker`` started as
       processes (:class:`meshphase.campaign.processes.ProcessCluster`; their start is not
       timed: an allocation's, not the campaign's), then
       :func:`meshphase.campaign.runner.run_campaign` with ``scheduler=`` its address, timed
       whole (connection and the workers' warm-up, submission, collection, the combined
       report).

    ``overhead`` is campaign wall over plain wall, less 1: the machinery's extra time per
    recording as a fraction of a recording's plain processing (both spread over the same
    number of processes).

    Parameters
    ----------
    n_recordings : int
    minutes : float
        Length of each recording [min].
    workers : int
        Plain processes, and Dask workers (one thread each).
    distinct : int
        Recordings actually generated (at most ``n_recordings``).
    scenario : str
    work_dir : str or Path, optional
        Default: a temporary folder, removed afterwards.
    seed : int

    Returns
    -------
    dict
        ``n_recordings``, ``minutes``, ``workers``, ``plain_wall_s``, ``campaign_wall_s``,
        ``per_recording_plain_s``, ``per_recording_campaign_s``, ``overhead`` [-],
        ``machinery_overhead`` and ``processing_overhead`` (the campaign's whole wall time,
        and the part while its tasks ran, over the sum of its tasks' own wall times divided
        by ``workers``, less 1: the machinery alone, whatever ``process`` does besides) [-],
        ``campaign_timing_s`` (the campaign's ``timing_s``), ``task_sum_s`` (the campaign
        tasks' own wall times), ``plain_task_sum_s``, ``cluster_start_s`` (the processes'
        start, not in the campaign's time), ``n_failed``, ``loadavg_before`` and
        ``loadavg_after``.

    Raises
    ------
    ValueError
        A count or length not positive, an unknown scenario.
    """
    import concurrent.futures
    import multiprocessing
    import time as _time

    from ..campaign.processes import ProcessCluster

    n_recordings, minutes, _, _ = _check_args(n_recordings, minutes, 1, (1,), scenario)
    workers = as_positive_int(workers, "workers")
    distinct = min(as_positive_int(distinct, "distinct"), n_recordings)
    tmp = tempfile.TemporaryDirectory(prefix="meshphase-overhead-") if work_dir is None else None
    work = Path(tmp.name if tmp is not None else work_dir)
    work.mkdir(parents=True, exist_ok=True)
    try:
        from meshphase.synthetic import cli_synth

        src_dir = work / "generated"
        src_dir.mkdir(exist_ok=True)
        sources = []
        for k in range(distinct):
            p = src_dir / f"{scenario}_{k:03d}.h5"
            if not p.exists():
                cli_synth(scenario, p, minutes=minutes, seed=seed + k, progress=False)
            sources.append(p)
        rec_dir = work / "recordings"
        rec_dir.mkdir(exist_ok=True)
        _link_recordings(rec_dir, sources, n_recordings)
        scene_path = work / "process_scene.toml"
        scene_path.write_text(process_scene_text(), encoding="utf-8")
        recs = sorted(rec_dir.glob("rec_*.h5"))[:n_recordings]
        load0 = list(os.getloadavg()) if hasattr(os, "getloadavg") else None
        plain_out = work / "plain"
        plain_out.mkdir(exist_ok=True)
        ctx = multiprocessing.get_context("forkserver" if "forkserver" in multiprocessing.get_all_start_methods()
                                          else "spawn")
        with concurrent.futures.ProcessPoolExecutor(workers, mp_context=ctx) as pool:
            from ..campaign.job import worker_modules

            list(pool.map(_plain_warm, [worker_modules(["hdf5"])] * workers))
            t = _time.perf_counter()
            plain_times = list(pool.map(_plain_process, [(str(r), str(scene_path), str(plain_out / r.stem))
                                                         for r in recs]))
            plain_wall = _time.perf_counter() - t
        t = _time.perf_counter()
        with ProcessCluster(workers, work_dir=work / "dask") as cl:
            cluster_start = _time.perf_counter() - t
            res = run_campaign(scene_path, [rec_dir], work / "campaign", scheduler=cl.address,
                               progress=False, overwrite=True)
        camp_wall = res["timing_s"]["total"]
        return {"n_recordings": n_recordings, "minutes": minutes, "workers": workers,
                "scenario": scenario, "distinct": distinct,
                "plain_wall_s": plain_wall, "campaign_wall_s": camp_wall,
                "per_recording_plain_s": plain_wall / n_recordings,
                "per_recording_campaign_s": camp_wall / n_recordings,
                "overhead": camp_wall / plain_wall - 1.0,
                "machinery_overhead": _over_tasks(camp_wall, res["recordings"], workers),
                "processing_overhead": _over_tasks(res["timing_s"]["processing"], res["recordings"], workers),
                "campaign_timing_s": res["timing_s"],
                "task_sum_s": _finite_sum(r.get("wall_time_s") for r in res["recordings"]),
                "plain_task_sum_s": _finite_sum(plain_times),
                "cluster_start_s": cluster_start, "n_failed": res["counts"]["failed"],
                "loadavg_before": load0,
                "loadavg_after": list(os.getloadavg()) if hasattr(os, "getloadavg") else None}
    finally:
        if tmp is not None:
            tmp.cleanup()


def _over_tasks(wall: float, records: list, workers: int) -> float:
    """``wall`` over the tasks' own wall times spread over ``workers``, less 1 [-]: what the
    campaign spends beyond its tasks (NaN without task times)."""
    tasks = _finite_sum(r.get("wall_time_s") for r in records)
    return wall * workers / tasks - 1.0 if tasks > 0 else float("nan")


def overhead_lines(res: dict) -> list[str]:
    """What ``meshphase bench campaign`` prints of :func:`measure_overhead`.

    Parameters
    ----------
    res : dict
        :func:`measure_overhead`'s result.

    Returns
    -------
    list of str

    Raises
    ------
    KeyError
        ``res`` lacks one of the keys above.
    """
    load = res.get("loadavg_before") or [float("nan")]
    return [f"campaign overhead on a cluster of processes ({res['n_recordings']} x {res['minutes']:g} min, "
            f"{res['workers']} workers, load before {load[0]:.1f}):",
            f"  plain process {res['plain_wall_s']:7.1f} s ({res['per_recording_plain_s']:.3f} s per recording), "
            f"campaign {res['campaign_wall_s']:7.1f} s ({res['per_recording_campaign_s']:.3f} s per recording)",
            f"  overhead per recording: {100 * res['overhead']:+.1f} % of its plain processing "
            f"(goal < 5 %); {res['n_failed']} failed",
            f"  the campaign over its own tasks' time per worker: {100 * res['machinery_overhead']:+.1f} % "
            f"in all (connection, warm-up, combined report), {100 * res['processing_overhead']:+.1f} % "
            "while the tasks ran"]
