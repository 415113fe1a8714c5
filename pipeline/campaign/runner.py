"""Campaigns: one scene, many recordings, one Dask job (``meshphase campaign``).

One module of about 1,000 lines: collecting the inputs, the per-recording task, the scene-level
results and the campaign tables are one flow over the same options; the job's life is in
:mod:`meshphase.campaign.job`, markers in :mod:`~meshphase.campaign.resume`, the cluster in
:mod:`~meshphase.campaign.cluster`.

The scene supplies the gearset, channel map, tolerances and the results wanted; each
recording file replaces the scene's ``[input]``. Every recording is one Dask task that gets
*file paths* (scene, recording, output folder), never open handles or arrays, loads the
scene in the worker, runs :func:`meshphase.run.stages.run_scene` and writes its own results into
``OUT/recordings/<recording name>/`` (:func:`recording_names`; a name space of their own,
so no recording can collide with the campaign's files), its completion marker
(:data:`DONE_NAME`) last. The task returns a small JSON-friendly dict; a recording that
fails (unreadable file, a stage raising, the worker process dying more often than Dask
retries, a task running past its timeout) is reported as failed and the others finish. The
client then writes ``campaign.json``, ``campaign.csv`` and ``campaign_report.html``
(:mod:`meshphase.report.campaign_report`) across all recordings, each atomically; the whole
folder is built beside ``OUT`` and swapped in when finished (:class:`meshphase.run.outdir.OutputDir`).

Faults: a task's timeout (:func:`default_task_timeout`, ``--task-timeout``) counts from the
moment it starts on a worker (the worker tells the client through a Dask event); past it the
task is failed and its worker killed (our LocalCluster: the Nanny starts a new one) or
restarted (another cluster). Workers lost under a task are seen in the scheduler's
"remove-worker" events; Dask retries the task and the campaign records each retry with its
cause (:mod:`meshphase.campaign.job`). ``--resume`` reuses the recordings whose marker
matches their inputs (:func:`recording_key`) in ``OUT`` and in ``OUT.partial`` (what an
unfinished campaign kept; :mod:`meshphase.campaign.resume`).

Results that need no recording are computed once, on the client, not once per recording:
the tolerance Monte Carlo (its 3-sigma phasing band, :meth:`meshphase.models.tolerance.MonteCarloResult.phasing_band`,
is passed to the tasks, which then compute the band coverage of their own passes exactly as
:func:`meshphase.run.stages.stage_compare` does), the tilt solve and the (unmeasured) bearing
moments. They go to ``OUT/scene/``.

Cluster (:mod:`meshphase.campaign.cluster`): a :class:`distributed.LocalCluster` (:func:`local_cluster`:
on 127.0.0.1 only, no dashboard unless asked) with one single-threaded worker *process* per
core by default (processes, because the stages are numpy/Python code that holds the GIL for
long stretches, and because ``warnings.catch_warnings`` inside :func:`run_scene` is not
thread-safe); ``scheduler="tcp://host:8786"`` uses an existing cluster instead, whose
workers must have meshphase installed and see the same paths (a shared file system). The
cluster starts in a background thread while the client runs the scene-level results and
imports what the report needs; the local workers fork from a server that imported the
processing stack once (:func:`meshphase.campaign.cluster.worker_server`), so they start warm. That
server starts first of all, before the scene's checks (:func:`_start_worker_server_early`).
``timing_s`` gives the start's ``cluster_start`` and the part of it
the campaign still waited for (``cluster_wait``). After the last recording the workers draw
the combined report's figures side by side (:func:`meshphase.campaign.job.draw_figures`), then
the cluster closes.

Per-recording HTML reports are off by default (``recording_reports=False``): building one
with its figures took about twice as long as processing a 1-min seed rig recording on the
reference machine (2.8 s vs 1.3 s), and the combined report is the product of a campaign;
``meshphase process`` / ``meshphase run`` give the full single-recording report.
The campaign speed-up benchmark is :func:`meshphase.bench.campaign.measure_speedup`.
"""

from __future__ import annotations

import copy
import functools
import hashlib
import json
import os
import re
import socket
import threading
import time
import tomllib
import traceback
import warnings
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Callable, Iterable

import numpy as np

from .job import (TIMEOUT_BASE_S, TIMEOUT_RATE_BPS, Job, campaign_modules, default_task_timeout,
                  draw_figures, run_job, start_cluster, task_limits)
from .resume import (DONE_NAME, RECORDINGS_DIR_NAME, completed_recordings,
                     recording_key, recording_keys, resume_sources, reuse_completed,
                     sha256_file)
from . import cluster
from .cluster import check_cluster_options, local_cluster, trim_env_is_distributed
from ..io import FORMATS, atomic_path, detect_format, get_spec
from ..runtime.heap import limit_heap_growth
from ..jsonable import to_jsonable
from ..runtime.log import logger
from ..run.context import phasing_verdict
from ..run.declare import client_results
from ..run.exits import EXIT_ERROR, EXIT_OK, EXIT_PARTIAL, run_status
from ..run.outdir import MANIFEST_NAME, PARTIAL_SUFFIX, OutputDir, remove_partial
from ..run.scene import load_scene, plan, with_recording
from ..run.state import failure_texts
from ..run.table_csv import write_csv
from ..validate import as_nonnegative, as_regular_file

__all__ = ["run_recording", "run_campaign", "cli_campaign", "collect_recordings",
           "recording_names", "split_results", "client_scene", "campaign_rows",
           "phasing_reliability", "campaign_exit_code", "default_task_timeout", "local_cluster",
           "recording_key", "completed_recordings", "SCENE_DIR_NAME", "RECORDINGS_DIR_NAME",
           "DONE_NAME", "STATUSES", "TIMEOUT_BASE_S", "TIMEOUT_RATE_BPS"]

#: sub-folder of the campaign output that holds the scene-level results
SCENE_DIR_NAME = "scene"
_SKIP_SUFFIXES = (".truth.json", ".tdms_index")
#: a recording's status in a campaign, best first (meshphase.run.exits.run_status)
STATUSES = ("ok", "unreliable", "partial", "failed")


# ---------------------------------------------------------------------------- reliability
def phasing_reliability(ctx) -> dict:
    """Whether each gauge's measured phasing is reliable, and why not.

    The one place that decides it (campaign status, ``process`` / ``run`` status line,
    summary.json; :func:`meshphase.run.results.phasing_verdict`): ``ctx.phasing.reliability``
    when the phasing stage provides it (``{gauge: {"reliable": bool, "reasons": [str,
    ...]}}``); otherwise the
    ProcessingWarning messages of the run (``ctx.messages``) that say "not reliable",
    attributed to the gauge they name ("sun gauge: ...") or, when they name none, to every
    gauge with a phasing table (to ``"phasing"`` if there is none).

    Parameters
    ----------
    ctx : meshphase.run.stages.RunContext

    Returns
    -------
    dict
        gauge -> ``{"reliable": bool, "reasons": list of str}``; empty when no phasing ran
        and nothing was flagged.

    Raises
    ------
    TypeError
        ``ctx`` has no ``phasing`` result slot or ``messages`` list (not a run context).
    """
    messages = getattr(ctx, "messages", None)
    if not hasattr(ctx, "phasing") or not isinstance(messages, (list, tuple)):
        raise TypeError(f"ctx must be a RunContext (meshphase.run.stages.run_scene), got {type(ctx).__name__}")
    return phasing_verdict(ctx.phasing, messages)


# ---------------------------------------------------------------------------- inputs
def _recording_suffixes() -> tuple[str, ...]:
    return tuple(s for f in FORMATS for s in get_spec(f).suffixes)


def collect_recordings(inputs: Iterable, *, recursive: bool = False) -> tuple[list[Path], list[dict]]:
    """The recording files named by ``inputs`` (files or folders), in a stable order.

    A folder contributes every file directly inside it (with ``recursive``, also inside its
    subfolders, depth first in name order) that is a recording by content
    (:func:`meshphase.io.detect_format`) or carries a recording suffix (.h5, .mcap, .csv,
    .tdms, ...: a corrupt recording is kept so that the campaign reports it failed); truth
    sidecars (``*.truth.json``), TDMS index files, hidden files and anything else are
    skipped. Subfolders are entered only with ``recursive``, and then never a hidden one, a
    symbolic link to a folder (a link could loop) or a folder meshphase wrote (it holds
    ``.meshphase.json``: a run's or a campaign's outputs, whose CSV tables are no
    recordings). A file named explicitly is always taken. Duplicates are dropped.

    Parameters
    ----------
    inputs : iterable of str or Path
    recursive : bool
        Look into subfolders too (``meshphase campaign --recursive``).

    Returns
    -------
    files : list of Path
        Resolved paths, folders' contents sorted by name.
    skipped : list of dict
        ``{"path", "reason"}`` for each folder entry that was left out.

    Raises
    ------
    TypeError
        ``inputs`` is a string (one path: wrap it in a list) or holds a non-path.
    FileNotFoundError
        A named file or folder does not exist.
    ValueError
        A named input is a FIFO, a device or a socket (not a regular file, not a folder).
    """
    if isinstance(inputs, (str, bytes, os.PathLike)):
        raise TypeError(f"inputs must be a list of paths, got a single path {inputs!r}")
    suffixes = _recording_suffixes()
    files: list[Path] = []
    skipped: list[dict] = []
    for item in inputs:
        if not isinstance(item, (str, os.PathLike)):
            raise TypeError(f"inputs must hold paths (str or Path), got {type(item).__name__} {item!r}")
        p = Path(item)
        if not p.exists():
            raise FileNotFoundError(f"{p}: no such recording file or folder")
        if not p.is_dir():
            # a named FIFO or device is refused here, before a worker could block on it
            files.append(as_regular_file(p, "a campaign input").resolve())
            continue
        for q in _folder_files(p, recursive, skipped):
            reason = _not_a_recording(q, suffixes)
            if reason is None:
                files.append(q.resolve())
            else:
                skipped.append({"path": str(q), "reason": reason})
    unique = list(dict.fromkeys(files))
    return unique, skipped


def _folder_files(folder: Path, recursive: bool, skipped: list):
    """The entries of ``folder`` in name order (with ``recursive``, those of its subfolders
    in their place, depth first); the subfolders not entered go to ``skipped``."""
    for q in sorted(folder.iterdir()):
        if not (recursive and q.is_dir()):
            yield q
        elif q.is_symlink():
            skipped.append({"path": str(q), "reason": "symbolic link to a folder (not followed)"})
        elif q.name.startswith("."):
            skipped.append({"path": str(q), "reason": "hidden folder"})
        elif (q / MANIFEST_NAME).exists():
            skipped.append({"path": str(q), "reason": "meshphase output folder"})
        else:
            yield from _folder_files(q, recursive, skipped)


def _not_a_recording(q: Path, suffixes: tuple) -> str | None:
    """Why the folder entry ``q`` is not taken as a recording, or None when it is."""
    name = q.name.lower()
    if not q.is_file():
        return "not a file"
    if q.name.startswith("."):
        return "hidden file"
    if name.endswith(_SKIP_SUFFIXES):
        return "truth sidecar" if name.endswith(".truth.json") else "TDMS index"
    try:
        detect_format(q)
        return None
    except ValueError as exc:  # RecordingFileError is a ValueError
        return None if q.suffix.lower() in suffixes else f"not a recording: {exc}"


_MAX_NAME_BYTES = 120


def _safe_name(stem: str) -> str:
    """A folder name from a file stem: no leading dot (hidden, and the working names of
    :mod:`meshphase.run.exits` start with one), never empty, at most 120 bytes (longer: cut, plus
    a hash of the whole, so room is left for the suffixes that tell names apart)."""
    name = re.sub(r"^\.+", lambda m: "_" * len(m.group()), stem.replace("\0", "")) or "recording"
    raw = name.encode("utf-8", "surrogateescape")
    if len(raw) > _MAX_NAME_BYTES:
        digest = hashlib.blake2s(raw, digest_size=4).hexdigest()
        name = raw[:_MAX_NAME_BYTES - 9].decode("utf-8", "ignore") + "~" + digest
    return name


def recording_names(paths: Iterable) -> list[str]:
    """Unique folder names for ``paths`` (the folders ``recordings/<name>/`` of a campaign).

    The file stem; where stems collide (case-insensitively: a campaign folder may live on a
    case-insensitive file system), the least of ``stem_<suffix>`` (``a.h5``, ``a.csv``),
    ``stem_<parent folder>`` (``a/x.h5``, ``b/x.h5`` -> ``x_a``, ``x_b``) or both that tells
    them apart; then ``-2``, ``-3`` ... Leading dots become ``_``; names longer than 120 bytes
    are cut and get a hash. The names live in their own folder, so no recording name can
    collide with the campaign's own files (``campaign.json``, ``figures``, ``scene`` ...).

    Parameters
    ----------
    paths : iterable of str or Path

    Returns
    -------
    list of str
        One name per path, in order, all distinct (also case-insensitively).

    Raises
    ------
    TypeError
        An entry is not a path.
    """
    paths = [Path(p) for p in paths]
    stems = [_safe_name(p.stem or p.name) for p in paths]
    groups: dict[str, list[int]] = {}
    for i, s in enumerate(stems):
        groups.setdefault(s.casefold(), []).append(i)
    cands = list(stems)
    for members in groups.values():
        if len(members) < 2:
            continue
        suffix = {i: paths[i].suffix.lstrip(".") or "file" for i in members}
        parent = {i: paths[i].parent.name or "root" for i in members}
        for parts in ((suffix,), (parent,), (suffix, parent)):
            trial = {i: _safe_name("_".join([stems[i]] + [part[i] for part in parts])) for i in members}
            if len({t.casefold() for t in trial.values()}) == len(members):
                break
        else:  # nothing tells them apart (one file named twice): the stem, then -2, -3
            trial = {}
        cands = [trial.get(i, c) for i, c in enumerate(cands)]
    names: list[str] = []
    used: set[str] = set()
    for c in cands:
        name, k = c, 2
        while name.casefold() in used:
            name, k = f"{c}-{k}", k + 1
        used.add(name.casefold())
        names.append(name)
    return names


# ---------------------------------------------------------------------------- scene split
def split_results(scene) -> tuple[list[str], list[str], bool]:
    """Which of the scene's results run once on the client and which per recording.

    Parameters
    ----------
    scene : meshphase.run.scene.Scene

    Returns
    -------
    client : list of str
        Results that need no recording (``tolerance`` - also when only pulled in by
        ``compare`` for its band coverage -, ``tilt``, and ``bearing_moments`` unless
        measured centroids are wanted too).
    worker : list of str
        The per-recording results.
    mc_on_client : bool
        True when the tolerance Monte Carlo runs on the client and the tasks get its band.
        It stays in the tasks only when the scene has no ``[gearset]`` (each recording then
        brings its own from its metadata).
    """
    results = list(scene.results)
    mc_wanted = "tolerance" in results or ("compare" in results and scene.tolerances is not None)
    mc_on_client = mc_wanted and scene.gearset is not None
    client = client_results(results, gearset_known=scene.gearset is not None)
    worker = [r for r in results if r not in client]
    if mc_on_client and "tolerance" not in client:
        client.append("tolerance")
    return client, worker, mc_on_client


def _worker_scene(scene, recording: Path, mc_on_client: bool, read_options: dict | None = None):
    """A copy of ``scene`` reading ``recording`` (with ``read_options`` over its tables), with
    the per-recording results only."""
    _, worker, _ = split_results(scene)
    s = copy.copy(scene)
    # the reading options ([input.mcap], [input.csv], [input] fs_Hz) hold for every recording
    s.input = with_recording(scene, Path(recording), read_options)
    s.results = worker
    if mc_on_client:
        s.tolerances = None  # the band comes from the client's Monte Carlo
    return s


def client_scene(scene):
    """A copy of ``scene`` with no ``[input]`` and the results that need no recording only
    (:func:`split_results`): what a campaign runs once, on the client.

    Parameters
    ----------
    scene : meshphase.run.scene.Scene

    Returns
    -------
    meshphase.run.scene.Scene
        Its ``results`` may be empty (nothing to run on the client).

    Raises
    ------
    TypeError
        ``scene`` is not a scene (no ``results``).
    """
    if not hasattr(scene, "results"):
        raise TypeError(f"scene must be a meshphase.run.scene.Scene, got {type(scene).__name__}")
    client, _, _ = split_results(scene)
    s = copy.copy(scene)
    s.input = {}
    s.results = client
    return s


def _bands(mc) -> dict:
    """The phasing band around the ideal per gauge (:meth:`meshphase.models.tolerance.MonteCarloResult.phasing_band`,
    as :func:`stages.stage_compare` builds it), as lists."""
    out = {}
    for gear in ("sun", "ring"):
        lo, hi = mc.phasing_band(gear)
        out[gear] = {"lo": [float(v) for v in lo], "hi": [float(v) for v in hi]}
    return out


def _apply_bands(ctx, bands: dict) -> None:
    """Band coverage of each gauge's passes, given the client's Monte Carlo band."""
    # the processing stack, here and below: not imported by the client before the workers'
    # fork server starts (module notes; ~0.3 s of imports)
    from ..compare.predict import band_coverage

    comp, phasing, ideal = ctx.compare, ctx.phasing, ctx.ideal
    if comp is None or phasing is None or ideal is None:
        return
    for gear, row in comp.by_gear.items():
        if gear not in bands or gear not in phasing.tables:
            continue
        tab = phasing.tables[gear]
        lo, hi = np.asarray(bands[gear]["lo"]), np.asarray(bands[gear]["hi"])
        comp = comp.with_gauge(gear, row.with_band(lo, hi))
        try:
            cov = band_coverage(tab.gamma, tab.planet, ideal.gamma(gear), lo, hi)
            comp = comp.with_gauge(gear, row.with_band(lo, hi, cov))
        except ValueError as exc:
            ctx.messages.append(f"compare: band coverage of the {gear} gauge: {exc}")
    ctx.record("compare", comp)


# ---------------------------------------------------------------------------- the task
def _compact(summary: dict) -> dict:
    """The per-recording numbers the combined report needs, from :func:`summary_dict`."""
    out: dict = {}
    rec = summary.get("recording")
    if rec:
        out["recording_info"] = {"fs_hz": rec.get("fs_hz"), "n_samples": rec.get("n_samples"),
                                 "duration_s": rec.get("duration_s"),
                                 "n_channels": len(rec.get("channels") or [])}
    if "ideal" in summary:
        out["ideal"] = {"gamma_s": summary["ideal"]["gamma_s"], "gamma_r": summary["ideal"]["gamma_r"]}
    if "phasing" in summary:
        out["phasing"] = {g: {"n_passes": v["n_passes"], "per_planet": v["per_planet"]}
                          for g, v in summary["phasing"].items()}
    if summary.get("load_sharing") is not None:
        out["load_sharing"] = summary["load_sharing"]
    if "compare" in summary:
        comp = {}
        for g, c in summary["compare"].items():
            comp[g] = {"rms_vs_ideal": (c.get("vs_ideal") or {}).get("rms"),
                       "rms_vs_model": (c.get("vs_model") or {}).get("rms"),
                       "coverage": (c.get("coverage") or {}).get("inside_fraction"),
                       "rms_vs_truth": (c.get("vs_truth") or {}).get("rms")}
        out["compare"] = comp
    if "identify" in summary:
        i = summary["identify"]
        out["identify"] = {k: i.get(k) for k in ("rms_before", "rms_after", "n_passes", "identifiable")}
    if summary.get("centroids_m"):
        out["centroids_m"] = summary["centroids_m"]
    if "bearing_moments" in summary:
        out["bearing_moments"] = summary["bearing_moments"]
    return out


def run_recording(scene_path: str, recording_path: str, out_dir: str, *, bands: dict | None = None,
                  recording_report: bool = False, read_options: dict | None = None) -> dict:
    """Process one recording of a campaign (the Dask task; also callable directly).

    Loads the scene, replaces its ``[input]`` by the recording, keeps the per-recording
    results (:func:`split_results`), runs them, writes ``summary.json``, the pass CSVs,
    ``stages.csv`` and ``arrays.h5`` (plus ``report.html`` when ``recording_report``) into
    ``out_dir`` and returns a small JSON-friendly dict. It never raises for a bad recording:
    any exception becomes ``status = "failed"`` with its message.

    Parameters
    ----------
    scene_path, recording_path, out_dir : str
        Paths as seen by the worker (created: ``out_dir``).
    bands : dict, optional
        ``{gauge: {"lo": [...], "hi": [...]}}``, the tolerance band of the deviation from the
        ideal phasing per planet [mesh cycles] from the client's Monte Carlo; the band
        coverage of the passes is computed with it.
    recording_report : bool
        Also build this recording's HTML report (slower; see the module notes).
    read_options : dict, optional
        Format options of the recording's reads over the scene's ``[input.*]`` tables
        (``meshphase campaign --topics/--fs/...``: :func:`meshphase.run.scene.with_recording`).

    Returns
    -------
    dict
        ``recording``, ``name``, ``out_dir``, ``status`` ("ok"; "unreliable": all computed,
        phasing flagged unreliable; "partial": a result not computed; "failed": nothing
        usable; :func:`meshphase.run.exits.run_status`), ``error`` (None or the cause(s)),
        ``missing_results`` and ``unreliable`` (as run_status gives them), ``format``,
        ``wall_time_s`` and ``cpu_time_s`` (this process's CPU time) [s], ``worker``,
        ``timings_s``, ``stages_ran``, ``stages_failed``,
        ``messages``, ``files`` and the compact results (``phasing``, ``load_sharing``,
        ``compare``, ``identify``, ``ideal``, ``recording_info`` ... when computed).
    """
    # a worker streams recording after recording (pipeline/runtime/heap.py); a Dask worker's trim
    # threshold in the environment is distributed's, not the user's
    limit_heap_growth(trim_env=not trim_env_is_distributed())
    t0, c0 = time.perf_counter(), time.process_time()
    rec_path = Path(recording_path)
    out: dict = {"recording": str(recording_path), "name": Path(out_dir).name, "out_dir": str(out_dir),
                 "status": "failed", "error": None, "format": None, "wall_time_s": float("nan"),
                 "worker": f"{socket.gethostname()}:{os.getpid()}", "timings_s": {},
                 "stages_ran": [], "stages_failed": {}, "messages": [], "files": {}}
    try:
        from ..run.stages import run_scene, summary_dict, write_outputs  # the processing stack

        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                out["format"] = detect_format(rec_path)
            except (ValueError, OSError) as exc:
                out["error"] = f"{type(exc).__name__}: {exc}"
            scene = load_scene(scene_path, recording_given=True)  # the recording replaces [input]
            _, _, mc_on_client = split_results(scene)
            scene = _worker_scene(scene, rec_path, mc_on_client and bands is not None, read_options)
            ctx = run_scene(scene)
            if bands:
                _apply_bands(ctx, bands)
            d = Path(out_dir)
            d.mkdir(parents=True, exist_ok=True)
            files = write_outputs(ctx, d, report=recording_report)
        out["files"] = {k: str(v) for k, v in files.items()}
        summ = summary_dict(ctx)
        out.update(_compact(summ))
        out["timings_s"] = summ["timings_s"]
        out["stages_ran"] = list(ctx.ran)
        out["stages_failed"] = failure_texts(ctx.failed)
        msgs = list(ctx.messages)
        for w in caught:
            m = f"{w.category.__name__}: {w.message}"
            if not any(m in x for x in msgs):
                msgs.append(m)
        out["messages"] = msgs
        # the same status as `meshphase process` / `run` (summary.json "status")
        st = run_status(ctx)
        out["status"] = st["status"]
        out["missing_results"] = st["missing_results"]
        out["unreliable"] = st["unreliable"]
        if st["status"] == "failed":
            out["error"] = st["error"]
        elif st["status"] == "partial":
            out["error"] = "; ".join(f"{m['result']}: {m['cause']}" for m in st["missing_results"])
        elif st["status"] == "unreliable":
            out["error"] = "; ".join(f"{g} gauge phasing: {'; '.join(r)}"
                                     for g, r in st["unreliable"].items())
        else:
            out["error"] = None
    except Exception as exc:  # noqa: BLE001 - the task must report, never kill the campaign
        out["status"] = "failed"
        out["error"] = f"{type(exc).__name__}: {exc}"
        out["traceback"] = traceback.format_exc(limit=8)
        logger.warning("campaign: %s failed: %s", recording_path, out["error"])
    out["wall_time_s"] = time.perf_counter() - t0
    out["cpu_time_s"] = time.process_time() - c0
    return out


def _write_atomic(path: Path, write: Callable[[Path], None]) -> None:
    """``write(tmp)`` to a temporary file beside ``path``, fsync, rename (meshphase.io)."""
    with atomic_path(path, overwrite=True) as tmp:
        write(tmp)


def _write_text_atomic(path: Path, text: str) -> None:
    _write_atomic(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


# ---------------------------------------------------------------------------- tables
def campaign_rows(records: list[dict]) -> list[dict]:
    """One flat row per recording (the columns of ``campaign.csv``).

    Columns: name, recording, format, status, error, duration_s, wall_time_s, worker,
    attempts (1 + the retries), retries (their causes, "; "-separated), resumed (taken from an
    earlier run by ``--resume``), passes_<gauge>, rms_vs_ideal_<gauge>_cycles,
    rms_vs_model_<gauge>_cycles, coverage_<gauge> (fraction inside the band),
    gamma_mean_<gauge>_p<k>_cycles, gamma_std_<gauge>_p<k>_cycles, load_sharing_p<k>,
    load_sharing_se_p<k> [-], identify_rms_after_cycles, n_messages, out_dir. A column's unit
    is its name's suffix (``_s`` seconds, ``_cycles`` mesh cycles; none: a count, a fraction
    or a text), as in every CSV a run writes (data_schemas/outputs.md).

    Parameters
    ----------
    records : list of dict
        What :func:`run_recording` returns.

    Returns
    -------
    list of dict
    """
    if not isinstance(records, (list, tuple)):
        raise TypeError(f"records must be a list of dicts, got {type(records).__name__}")
    rows = []
    for r in records:
        if not isinstance(r, dict):
            raise TypeError(f"records must hold dicts, got {type(r).__name__} {r!r}")
        info = r.get("recording_info") or {}
        row = {"name": r.get("name"), "recording": r.get("recording"), "format": r.get("format"),
               "status": r.get("status"), "error": r.get("error") or "",
               "duration_s": info.get("duration_s"), "wall_time_s": r.get("wall_time_s"),
               "worker": r.get("worker"), "attempts": r.get("attempts", 1),
               "retries": "; ".join(r.get("retries") or []), "resumed": bool(r.get("resumed"))}
        for gear in ("sun", "ring"):
            ph = (r.get("phasing") or {}).get(gear)
            row[f"passes_{gear}"] = None if ph is None else ph.get("n_passes")
            c = (r.get("compare") or {}).get(gear) or {}
            row[f"rms_vs_ideal_{gear}_cycles"] = c.get("rms_vs_ideal")
            row[f"rms_vs_model_{gear}_cycles"] = c.get("rms_vs_model")
            row[f"coverage_{gear}"] = c.get("coverage")
            for k, v in sorted(((ph or {}).get("per_planet") or {}).items(), key=lambda kv: int(kv[0])):
                row[f"gamma_mean_{gear}_p{k}_cycles"] = v.get("mean")
                row[f"gamma_std_{gear}_p{k}_cycles"] = v.get("std")
        for ls in r.get("load_sharing") or []:
            row[f"load_sharing_p{ls['planet']}"] = ls.get("load_sharing")
            row[f"load_sharing_se_p{ls['planet']}"] = ls.get("std_error")
        row["identify_rms_after_cycles"] = (r.get("identify") or {}).get("rms_after")
        row["n_messages"] = len(r.get("messages") or [])
        row["out_dir"] = r.get("out_dir")
        rows.append(row)
    # one column set and order for every row: fixed columns, then per planet, then the tail
    tail = ["identify_rms_after_cycles", "n_messages", "out_dir"]
    keys = list(dict.fromkeys(k for row in rows for k in row))
    fixed = [k for k in keys if not k.startswith(("gamma_", "load_sharing_")) and k not in tail]

    def planet_key(k):
        kind, _, p = k.removesuffix("_cycles").rpartition("_p")
        return (k.startswith("load_sharing"), kind.split("_")[-1] if k.startswith("gamma") else "",
                int(p), kind)

    per_planet = sorted((k for k in keys if k.startswith(("gamma_", "load_sharing_"))), key=planet_key)
    order = fixed + per_planet + tail
    return [{k: row.get(k) for k in order} for row in rows]


def campaign_exit_code(campaign: dict) -> int:
    """The exit code of ``meshphase campaign`` (table in :mod:`meshphase.run.exits`).

    0 when every recording is "ok" (and the scene-level results, if any, too); 1 when every
    recording failed (nothing usable); 3 otherwise: any recording failed, partial or
    unreliable, or a scene-level result (Monte Carlo, tilt, ...) missing.

    Parameters
    ----------
    campaign : dict
        :func:`run_campaign`'s result (``recordings``, optionally ``scene_status``).

    Returns
    -------
    int
    """
    if not isinstance(campaign, dict) or not isinstance(campaign.get("recordings"), list):
        raise TypeError(f"campaign must be run_campaign's dict with a 'recordings' list, got "
                        f"{type(campaign).__name__}")
    statuses = [r.get("status", "failed") if isinstance(r, dict) else "failed"
                for r in campaign["recordings"]]
    if statuses and all(s == "failed" for s in statuses):
        return EXIT_ERROR
    scene_ok = (campaign.get("scene_status") or {}).get("status", "ok") == "ok"
    return EXIT_OK if scene_ok and all(s == "ok" for s in statuses) else EXIT_PARTIAL


# ---------------------------------------------------------------------------- the campaign
def run_campaign(scene_path, inputs, out_dir=None, *, scheduler: str | None = None,
                 workers: int | None = None, overwrite: bool = False, progress: bool = True,
                 recording_reports: bool = False, task: Callable[..., dict] | None = None,
                 task_timeout: float | None = None, resume: bool = False, dashboard=None,
                 recursive: bool = False) -> dict:
    """Process many recordings with one scene as one Dask job.

    The output folder is written whole or not at all (:class:`meshphase.run.outdir.OutputDir`: a
    staging folder swapped in at the end). Each recording's results go to
    ``recordings/<name>/`` (:func:`recording_names`) with a completion marker written last
    (:data:`DONE_NAME`); ``resume`` reuses the results whose marker matches the recording
    (path, size, mtime), the scene (its SHA-256), the meshphase version and the options, and
    redoes the rest. If the campaign does not finish (an error, Ctrl-C, the process killed)
    after some recordings were done, those are kept in ``<out_dir>.partial`` for ``resume``.

    A task counts its time from the moment it starts on a worker; past its timeout it is
    failed ("timeout: ...", the campaign goes on) and its worker restarted (which needs a
    Nanny: a LocalCluster always has one). A task whose worker dies (killed, crashed, out of
    memory) is retried by Dask on another worker (up to ``distributed.scheduler.allowed-
    failures`` times, 3 by default; then failed with KilledWorker); every retry is recorded
    with its cause (``attempts``, ``retries`` in campaign.json and campaign.csv).

    Parameters
    ----------
    scene_path : str or Path
        Scene TOML; its ``[input]`` is replaced by each recording.
    inputs : list of str or Path
        Recording files and/or folders (:func:`collect_recordings`).
    out_dir : str or Path, optional
        Campaign output folder (default ``<scene stem>-campaign`` next to the scene). An
        existing folder is never overwritten unless ``overwrite`` or ``resume``: ``-2``,
        ``-3`` ... instead.
    scheduler : str, optional
        Address of an existing Dask scheduler (``tcp://host:8786``); its workers need
        meshphase and the same paths. Default: a LocalCluster on this machine
        (:func:`local_cluster`, on 127.0.0.1 only).
    workers : int, optional
        LocalCluster worker processes (one thread each); default one per core.
    overwrite : bool
        Replace ``out_dir`` if it exists (atomically; refused when it holds files meshphase
        did not write or symbolic links: :class:`meshphase.run.outdir.OutputDir`).
    progress : bool
        A tqdm progress bar (recordings done) on stderr, drawn only when stderr is a terminal
        (a cluster job's log file gets the scheduler's dashboard link instead).
    recording_reports : bool
        Also write each recording's HTML report (default False: see the module notes).
    task : callable, optional
        The per-recording function, ``task(scene_path, recording_path, out_dir, **kw) ->
        dict`` (default :func:`run_recording`); must be importable by the workers.
    task_timeout : float, optional
        Seconds a task may run [s]; None: :func:`default_task_timeout` of each recording's
        size; 0: no timeout.
    resume : bool
        Reuse the complete results in ``out_dir`` and ``<out_dir>.partial`` (implies
        replacing ``out_dir``, as ``overwrite``).
    dashboard : None, bool, int or str
        The local cluster's Dask dashboard (:func:`local_cluster`): off by default; True or
        a port: on 127.0.0.1.
    recursive : bool
        Look for recordings in the input folders' subfolders too (:func:`collect_recordings`).

    Returns
    -------
    dict
        ``scene``, ``scene_path``, ``out_dir``, ``cluster`` (``scheduler``, ``n_workers``,
        ``local``, ``dashboard``), ``timing_s`` (``total``, ``scene_level``,
        ``cluster_start`` (in the background, meanwhile the scene-level results run),
        ``cluster_wait`` (what the campaign then still waited for it), ``processing``,
        ``report``) [s], ``counts`` (ok / unreliable / partial
        / failed), ``skipped_inputs``, ``scene_level`` (summary of the client-side results or
        None), ``scene_status`` (their :func:`meshphase.run.exits.run_status`, or None),
        ``task_timeout`` (``mode`` "size" / "fixed" / "off", ``seconds``), ``resume``
        (``enabled``, ``n_resumed``, ``sources``), ``recordings`` (one dict per recording, in
        input order, with ``attempts``, ``retries`` and ``resumed``), ``exit_code``
        (:func:`campaign_exit_code`) and ``files`` (campaign.json, campaign.csv,
        campaign_report.html).

    Raises
    ------
    FileNotFoundError
        The scene, or a named recording / folder, does not exist.
    FileExistsError
        ``out_dir`` is a symbolic link, or (``overwrite`` / ``resume``) holds what meshphase
        did not write.
    ValueError
        No recording found, a bad scene, bad ``workers`` / ``task_timeout``, or an
        unreachable scheduler.
    TypeError
        Arguments of the wrong type.
    """
    t_all = time.perf_counter()
    workers, task_timeout, task = _check_options(scheduler, workers, dashboard, task_timeout, task)
    scene_path = Path(scene_path).resolve()
    if not isinstance(inputs, (str, bytes, os.PathLike)):
        inputs = list(inputs)  # read more than once below: a generator would be empty after
    found = _start_worker_server_early(scene_path, inputs, recursive) if scheduler is None else None
    scene, inputs, files, skipped = _scene_and_recordings(scene_path, inputs, recursive, found)
    client_results, worker_results, mc_on_client = split_results(scene)
    names = recording_names(files)
    base = Path(out_dir) if out_dir is not None else scene_path.with_name(scene_path.stem + "-campaign")
    partial = base.with_name(base.name + PARTIAL_SUFFIX)
    opts = _Options(scene_path=str(scene_path), scene_sha256=sha256_file(scene_path),
                    client_results=client_results, worker_results=worker_results,
                    mc_on_client=mc_on_client, scheduler=scheduler, workers=workers, progress=progress,
                    recording_reports=bool(recording_reports), task=task, t_all=t_all,
                    task_timeout=task_timeout, resume=bool(resume),
                    sources=[base, partial] if resume else [], dashboard=dashboard)
    # the folder is reserved now; the campaign fills a staging folder beside it, swapped in
    # when it finishes; if it raises or is interrupted (Ctrl-C) nothing is left but the
    # recordings it had finished, in <out>.partial (meshphase.run.outdir.OutputDir)
    with OutputDir(base, overwrite=overwrite or resume, staged=True) as guard:
        opts.guard = guard
        result = _campaign_body(scene, scene_path, inputs, files, skipped, names, guard.path.resolve(), opts)
    if resume and Path(guard.final) == Path(os.path.abspath(base)):
        remove_partial(base)  # its results are in the campaign now
    return result


@dataclass
class _Options:
    """A campaign's checked options and what it derived from them up front."""

    scene_path: str
    scene_sha256: str
    client_results: list
    worker_results: list
    mc_on_client: bool
    scheduler: str | None
    workers: int | None
    progress: bool
    recording_reports: bool
    task: Callable[..., dict]
    t_all: float
    task_timeout: float | None
    resume: bool
    sources: list
    dashboard: object
    guard: object = None


def _check_options(scheduler, workers, dashboard, task_timeout, task):
    """(workers, task_timeout, task) checked, before anything is read or started."""
    workers = check_cluster_options(scheduler, workers, dashboard)
    if task_timeout is not None:
        task_timeout = as_nonnegative(task_timeout, "task_timeout")
    task = run_recording if task is None else task
    if not callable(task):
        raise TypeError(f"task must be callable, got {type(task).__name__}")
    return workers, task_timeout, task


def _start_worker_server_early(scene_path: Path, inputs, recursive: bool):
    """Start the local workers' fork server (:func:`meshphase.campaign.cluster.worker_server`, ~2 s
    of imports) in the background now, before the scene is loaded and checked (~0.5 s: its
    gearset check loads scipy) and the output folder reserved, so that the cluster waits
    less for it. Its modules (:func:`meshphase.campaign.job.campaign_modules`) come from the
    recordings' suffixes and a plain read of the scene's ``[input]``; anything that fails
    here is left to the checks that follow, which report it. Returns what
    :func:`collect_recordings` found (for :func:`_scene_and_recordings`), None when it
    failed."""
    try:
        found = collect_recordings(inputs, recursive=recursive)
    except Exception:  # noqa: BLE001 - collected again, and reported, after the scene's checks
        return None
    try:
        with open(scene_path, "rb") as f:
            raw = tomllib.load(f).get("input")
        modules = campaign_modules(SimpleNamespace(input=raw if isinstance(raw, dict) else {}), found[0])
        # what starting the server imports, imported here (an ImportError where the platform
        # has no fork server): the thread then imports nothing while this one goes on
        # importing (the scene's checks load scipy)
        import multiprocessing.popen_forkserver  # noqa: F401
    except Exception:  # noqa: BLE001 - reported by the scene's checks that follow, not here
        return found

    def serve():
        try:
            cluster.worker_server(modules)
        except Exception as exc:  # noqa: BLE001 - the cluster's own start tries again and reports
            logger.debug("campaign: early fork server start failed (%s)", exc)

    threading.Thread(target=serve, name="meshphase-fork-server-start", daemon=True).start()
    return found


def _scene_and_recordings(scene_path: Path, inputs, recursive: bool = False, found=None):
    """(scene, inputs, recording files, skipped entries): the scene loaded, the recordings
    found in ``inputs`` (a path or a list: read more than once; ``found``: what
    :func:`collect_recordings` gave already), and the per-recording scene validated once, up
    front."""
    # FileNotFoundError / SceneError (a ValueError) up front; each recording replaces [input]
    scene = load_scene(scene_path, recording_given=True)
    files, skipped = found if found is not None else collect_recordings(inputs, recursive=recursive)
    if not files:
        left = [Path(s["path"]).name for s in skipped]
        raise ValueError(f"no recording files found in inputs {[str(i) for i in inputs]!r}"
                         + (f" (left out: {', '.join(left[:8])}{', ...' if len(left) > 8 else ''})"
                            if left else ""))
    _, worker_results, mc_on_client = split_results(scene)
    if not worker_results:
        raise ValueError(f"scene {scene_path.name}: results {scene.results} need no recording; "
                         "a campaign needs per-recording results (phasing, load_sharing, compare, "
                         "identify, centroids); use `meshphase run` for this scene")
    plan(_worker_scene(scene, files[0], mc_on_client))  # the worker scene validates here, once
    return scene, inputs, files, skipped


def _final_path(out: Path, final: Path, p) -> str:
    """A path in the staging folder ``out`` -> the path it has once ``out`` is ``final``."""
    try:
        return str(final / Path(p).relative_to(out))
    except ValueError:
        return str(p)


def _campaign_body(scene, scene_path, inputs, files, skipped, names, out, opts: _Options) -> dict:
    """The campaign after its output folder is reserved (see :func:`run_campaign`); ``out``
    is the staging folder, ``opts.guard.final`` the folder it will be.

    The cluster starts in the background (:func:`meshphase.campaign.job.start_cluster`: worker
    processes, their imports) while this process runs the scene-level results and imports
    what the report needs; its workers draw the report's figures, then it closes."""
    guard = opts.guard
    final = Path(guard.final).resolve()
    final_of = functools.partial(_final_path, out, final)
    timing: dict[str, float] = {"cluster_start": 0.0, "cluster_wait": 0.0, "processing": 0.0}
    rec_root = out / RECORDINGS_DIR_NAME
    rec_root.mkdir(exist_ok=True)
    rec_dirs = [rec_root / n for n in names]
    keys = recording_keys(files, opts.scene_sha256, {"recording_report": opts.recording_reports})
    # (the folder reserved for this campaign is new and empty: no source)
    sources = resume_sources(opts.sources)
    records = reuse_completed(sources, keys, rec_dirs, names, final_of) if sources else {}
    if records:
        guard.mark_partial()
        logger.info("campaign: %d of %d recordings complete already (--resume)", len(records), len(files))
    todo = [i for i in range(len(files)) if i not in records]
    cluster_info = {"scheduler": None, "n_workers": 0, "local": opts.scheduler is None, "dashboard": None}
    start = (start_cluster(opts.scheduler, opts.workers, opts.dashboard, cluster_info,
                           campaign_modules(scene, [files[i] for i in todo])) if todo else None)
    try:
        t = time.perf_counter()
        scene_level, scene_status, bands = _scene_level(scene, out, opts)
        timing["scene_level"] = time.perf_counter() - t
        _import_report_modules()  # while the workers start
        if todo:
            job = Job(task=opts.task, scene_path=opts.scene_path, files=files, names=names, rec_dirs=rec_dirs,
                      keys=keys, limits=task_limits(keys, opts.task_timeout), todo=todo, bands=bands,
                      recording_report=opts.recording_reports, progress=opts.progress, final_of=final_of,
                      on_usable=guard.mark_partial)
            run_job(job, records, scheduler=opts.scheduler, workers=opts.workers, dashboard=opts.dashboard,
                    cluster_info=cluster_info, timing=timing, start=start)
        result = _result_dict(scene, scene_path, inputs, skipped, final, cluster_info, timing,
                              scene_level, scene_status, sources, [records[i] for i in range(len(files))],
                              opts)
        # the workers draw the report's figures, then the cluster closes
        _write_campaign_files(result, out, final_of, opts.t_all,
                              closed=start.close if start is not None else None,
                              draw=functools.partial(draw_figures, start.client()) if start is not None else None)
    finally:
        if start is not None:
            start.close()
    return result


def _import_report_modules() -> None:
    """Import what :func:`_write_campaign_files` needs, ahead of time: the report's module,
    without matplotlib (the workers draw the figures)."""
    from ..report import campaign_report  # noqa: F401  (the processing stack: module notes)


def _result_dict(scene, scene_path, inputs, skipped, final, cluster_info, timing, scene_level,
                 scene_status, sources, recs, opts: _Options) -> dict:
    """:func:`run_campaign`'s result, but its ``files``."""
    for r in recs:
        r.setdefault("attempts", 1)
        r.setdefault("retries", [])
        r.setdefault("resumed", False)
    tt = opts.task_timeout
    result = {"scene": scene.name, "scene_path": str(scene_path), "out_dir": str(final),
              "inputs": [str(i) for i in inputs], "skipped_inputs": skipped,
              "cluster": cluster_info, "results_client": opts.client_results,
              "results_per_recording": opts.worker_results,
              "counts": {s: sum(r.get("status") == s for r in recs) for s in STATUSES},
              "timing_s": timing, "scene_level": scene_level, "scene_status": scene_status,
              "task_timeout": {"mode": "off" if tt == 0 else "size" if tt is None else "fixed",
                               "seconds": tt if tt else None},
              "resume": {"enabled": opts.resume, "n_resumed": sum(bool(r.get("resumed")) for r in recs),
                         "sources": sources},
              "recordings": recs}
    result["exit_code"] = campaign_exit_code(result)
    return result


def _scene_level(scene, out: Path, opts: _Options):
    """(summary, run status, bands) of the results that need no recording, run once on the
    client into ``out/scene/``; all None when there are none."""
    if not opts.client_results:
        return None, None, None
    from ..run.stages import run_scene, summary_dict, write_outputs  # the processing stack

    sctx = run_scene(client_scene(scene))
    scene_status = {k: v for k, v in run_status(sctx).items() if k != "exit_code"}
    sdir = out / SCENE_DIR_NAME
    sdir.mkdir(exist_ok=True)
    scene_level = summary_dict(sctx)   # once: it converts the Monte Carlo summaries
    write_outputs(sctx, sdir, report=False, summary=scene_level)
    bands = None
    if opts.mc_on_client and sctx.tolerance is not None:
        bands = _bands(sctx.tolerance.monte_carlo)
        scene_level["bands"] = bands
    elif opts.mc_on_client:
        logger.warning("campaign: the tolerance Monte Carlo failed (%s); no band coverage",
                       sctx.failed.get("tolerance"))
    return scene_level, scene_status, bands


def _write_campaign_files(result: dict, out: Path, final_of, t_all: float,
                          closed: Callable[[], None] | None = None,
                          draw: Callable[[list], list] | None = None) -> None:
    """campaign.csv, campaign_report.html and campaign.json into ``out``, each atomically;
    sets ``result["files"]`` and the ``report`` and ``total`` times. ``draw`` draws the
    report's figures (:func:`meshphase.campaign.job.draw_figures`; None: here); ``closed()``
    (if given) closes the cluster after the report, before the total is taken."""
    from ..report.campaign_report import build_campaign_report  # the processing stack

    timing, counts = result["timing_s"], result["counts"]
    t = time.perf_counter()
    csv_path = out / "campaign.csv"
    rows = campaign_rows(result["recordings"])
    _write_atomic(csv_path, lambda tmp: write_csv(rows, tmp))
    report_path = build_campaign_report(result, out, draw=draw)
    timing["report"] = time.perf_counter() - t
    if closed is not None:
        closed()
    timing["total"] = time.perf_counter() - t_all
    json_path = out / "campaign.json"
    result["files"] = {"campaign.json": final_of(json_path), "campaign.csv": final_of(csv_path),
                       "campaign_report.html": final_of(report_path)}
    _write_text_atomic(json_path, json.dumps(to_jsonable(result), indent=2))
    logger.info("campaign %s: %d ok, %d unreliable, %d partial, %d failed in %.1f s -> %s",
                result["scene"], counts["ok"], counts["unreliable"], counts["partial"], counts["failed"],
                timing["total"], result["out_dir"])


def cli_campaign(scene_path, inputs: list[str], *, scheduler: str | None = None,
                 workers: int | None = None, out=None, overwrite: bool = False,
                 progress: bool = True, recording_reports: bool = False,
                 task_timeout: float | None = None, resume: bool = False, dashboard=None,
                 recursive: bool = False, read_options: dict | None = None) -> dict:
    """``meshphase campaign SCENE DIR...``: :func:`run_campaign` with the CLI's arguments.

    Parameters
    ----------
    scene_path : str
    inputs : list of str
        Recording files and/or folders.
    scheduler : str, optional
        Dask scheduler address (``--scheduler``); default a LocalCluster.
    workers : int, optional
        LocalCluster worker processes (``--workers``); default one per core.
    out : str, optional
        Output folder (``--out``); default ``<scene stem>-campaign`` next to the scene.
    overwrite : bool
    progress : bool
    recording_reports : bool
        ``--recording-reports``: an HTML report per recording too.
    task_timeout : float, optional
        ``--task-timeout`` [s] (0: none; default from each recording's size).
    resume : bool
        ``--resume``: reuse complete results.
    dashboard : None, bool or str
        ``--dashboard [ADDRESS]``.
    recursive : bool
        ``--recursive``: look into the folders' subfolders too.
    read_options : dict, optional
        ``--topics``, ``--fs``, ``--header-row`` ...: format options of every recording's
        reads, over the scene's ``[input.*]`` tables (:func:`run_recording`).

    Returns
    -------
    dict
        As :func:`run_campaign`.
    """
    return run_campaign(scene_path, list(inputs), out, scheduler=scheduler, workers=workers,
                        overwrite=overwrite, progress=progress, recording_reports=recording_reports,
                        task_timeout=task_timeout, resume=resume, dashboard=dashboard,
                        recursive=recursive,
                        task=functools.partial(run_recording, read_options=read_options)
                        if read_options else None)
