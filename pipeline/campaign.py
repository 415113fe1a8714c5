"""Campaigns: one scene, many recordings, one Dask job (``meshphase campaign``).

The scene supplies the gearset, channel map, tolerances and the results wanted; each
recording file replaces the scene's ``[input]``. Every recording is one Dask task that gets
*file paths* (scene, recording, output folder), never open handles or arrays, loads the
scene in the worker, runs :func:`pipeline.stages.run_scene` and writes its own results into
``OUT/recordings/<recording name>/`` (:func:`recording_names`; a name space of their own,
so no recording can collide with the campaign's files), its completion marker
(:data:`DONE_NAME`) last. The task returns a small JSON-friendly dict; a recording that
fails (unreadable file, a stage raising, the worker process dying more often than Dask
retries, a task running past its timeout) is reported as failed and the others finish. The
client then writes ``campaign.json``, ``campaign.csv`` and ``campaign_report.html``
(:mod:`pipeline.report.campaign_report`) across all recordings, each atomically; the whole
folder is built beside ``OUT`` and swapped in when finished (:class:`pipeline.exits.OutputDir`).

Faults: a task's timeout (:func:`default_task_timeout`, ``--task-timeout``) counts from the
moment it starts on a worker (the worker tells the client through a Dask event); past it the
task is failed and its worker killed (our LocalCluster: the Nanny starts a new one) or
restarted (another cluster). Workers lost under a task are seen in the scheduler's
"remove-worker" events; Dask retries the task and the campaign records each retry with its
cause. ``--resume`` reuses the recordings whose marker matches their inputs
(:func:`recording_key`) in ``OUT`` and in ``OUT.partial`` (what an unfinished campaign kept).

Results that need no recording are computed once, on the client, not once per recording:
the tolerance Monte Carlo (its 3-sigma phasing band is passed to the tasks, which then
compute the band coverage of their own passes exactly as :func:`pipeline.stages.stage_compare`
does), the tilt solve and the (unmeasured) bearing moments. They go to ``OUT/scene/``.

Cluster: a :class:`distributed.LocalCluster` (:func:`local_cluster`: on 127.0.0.1 only, no
dashboard unless asked) with one single-threaded worker *process* per core by default
(processes, because the stages are numpy/Python code that holds the GIL for long stretches,
and because ``warnings.catch_warnings`` inside :func:`run_scene` is not thread-safe);
``scheduler="tcp://host:8786"`` uses an existing cluster instead, whose workers must have
meshphase installed and see the same paths (a shared file system).

Per-recording HTML reports are off by default (``recording_reports=False``): building one
with its figures took about twice as long as processing a 1-min seed rig recording on the
reference machine (2.8 s vs 1.3 s), and the combined report is the product of a campaign;
``meshphase process`` / ``meshphase run`` give the full single-recording report.
"""

from __future__ import annotations

import contextlib
import copy
import hashlib
import json
import logging
import math
import os
import queue
import re
import shutil
import socket
import stat
import sys
import tempfile
import time
import traceback
import uuid
import warnings
from pathlib import Path
from typing import Callable, Iterable

from .jsonable import to_jsonable
from .log import logger
from .results import phasing_verdict
from .validate import as_positive, as_positive_int, as_regular_file

__all__ = ["run_recording", "run_campaign", "cli_campaign", "collect_recordings",
           "recording_names", "split_results", "campaign_rows", "measure_speedup",
           "phasing_reliability", "campaign_exit_code", "default_task_timeout", "local_cluster",
           "recording_key", "completed_recordings", "SCENE_DIR_NAME", "RECORDINGS_DIR_NAME",
           "DONE_NAME", "STATUSES", "TIMEOUT_BASE_S", "TIMEOUT_RATE_BPS"]

#: sub-folder of the campaign output that holds the scene-level results
SCENE_DIR_NAME = "scene"
#: sub-folder of the campaign output with one folder per recording, ``recordings/<name>/``:
#: names derived from recording files live in their own name space, so they never collide
#: with the campaign's own files and folders
RECORDINGS_DIR_NAME = "recordings"
#: a recording's completion marker, written last and atomically into its folder: the key of
#: its inputs (recording path, size, mtime; scene hash; meshphase version; options) and its
#: campaign record. ``--resume`` skips a recording whose marker's key matches.
DONE_NAME = "done.json"
#: default ``--task-timeout`` of a recording of ``size`` bytes: TIMEOUT_BASE_S +
#: size / TIMEOUT_RATE_BPS seconds (see :func:`default_task_timeout`)
TIMEOUT_BASE_S = 300.0
TIMEOUT_RATE_BPS = 100e3
# worker -> client event when a task starts (its key, worker, pid): start of its timeout
_START_TOPIC = "meshphase-task-start"
_SKIP_SUFFIXES = (".truth.json", ".tdms_index")
#: a recording's status in a campaign, best first (pipeline.exits.run_status)
STATUSES = ("ok", "unreliable", "partial", "failed")


# ---------------------------------------------------------------------------- reliability
def phasing_reliability(ctx) -> dict:
    """Whether each gauge's measured phasing is reliable, and why not.

    The one place that decides it (campaign status, ``process`` / ``run`` status line,
    summary.json; :func:`pipeline.results.phasing_verdict`): ``ctx.phasing.reliability``
    when the phasing stage provides it (``{gauge: {"reliable": bool, "reasons": [str,
    ...]}}``); otherwise the
    ProcessingWarning messages of the run (``ctx.messages``) that say "not reliable",
    attributed to the gauge they name ("sun gauge: ...") or, when they name none, to every
    gauge with a phasing table (to ``"phasing"`` if there is none).

    Parameters
    ----------
    ctx : pipeline.stages.RunContext

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
        raise TypeError(f"ctx must be a RunContext (pipeline.stages.run_scene), got {type(ctx).__name__}")
    return phasing_verdict(ctx.phasing, messages)


# ---------------------------------------------------------------------------- inputs
def _recording_suffixes() -> tuple[str, ...]:
    from .io import FORMATS, get_format

    return tuple(s for f in FORMATS for s in get_format(f).SUFFIXES)


def collect_recordings(inputs: Iterable) -> tuple[list[Path], list[dict]]:
    """The recording files named by ``inputs`` (files or folders), in a stable order.

    A folder contributes every file directly inside it (not recursively) that is a recording
    by content (:func:`pipeline.io.detect_format`) or carries a recording suffix (.h5, .mcap,
    .csv, .tdms, ...: a corrupt recording is kept so that the campaign reports it failed);
    truth sidecars (``*.truth.json``), TDMS index files, hidden files and anything else are
    skipped. A file named explicitly is always taken. Duplicates are dropped.

    Parameters
    ----------
    inputs : iterable of str or Path

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
    from .io import detect_format

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
        for q in sorted(p.iterdir()):
            name = q.name.lower()
            if not q.is_file():
                reason = "not a file"
            elif q.name.startswith("."):
                reason = "hidden file"
            elif name.endswith(_SKIP_SUFFIXES):
                reason = "truth sidecar" if name.endswith(".truth.json") else "TDMS index"
            else:
                try:
                    detect_format(q)
                    reason = None
                except ValueError as exc:  # RecordingFileError is a ValueError
                    reason = None if q.suffix.lower() in suffixes else f"not a recording: {exc}"
            if reason is None:
                files.append(q.resolve())
            else:
                skipped.append({"path": str(q), "reason": reason})
    unique = list(dict.fromkeys(files))
    return unique, skipped


_MAX_NAME_BYTES = 120


def _safe_name(stem: str) -> str:
    """A folder name from a file stem: no leading dot (hidden, and the working names of
    :mod:`pipeline.exits` start with one), never empty, at most 120 bytes (longer: cut, plus
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
    scene : pipeline.scene.Scene

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
    client, worker = [], []
    for r in results:
        if r == "tolerance":
            (client if mc_on_client else worker).append(r)
        elif r == "tilt" or (r == "bearing_moments" and "centroids" not in results):
            client.append(r)
        else:
            worker.append(r)
    if mc_on_client and "tolerance" not in client:
        client.append("tolerance")
    return client, worker, mc_on_client


def _worker_scene(scene, recording: Path, mc_on_client: bool):
    """A copy of ``scene`` reading ``recording``, with the per-recording results only."""
    _, worker, _ = split_results(scene)
    s = copy.copy(scene)
    s.input = {"recording": Path(recording)}
    s.results = worker
    if mc_on_client:
        s.tolerances = None  # the band comes from the client's Monte Carlo
    return s


def _client_scene(scene):
    client, _, _ = split_results(scene)
    s = copy.copy(scene)
    s.input = {}
    s.results = client
    return s


def _bands(mc) -> dict:
    """The phasing band around the ideal per gauge, as :func:`stages.stage_compare` builds it."""
    out = {}
    for gear, ave, dev in (("sun", mc.ave_s, mc.dev_s), ("ring", mc.ave_r, mc.dev_r)):
        lo = ave.bound3[0] - dev.bound3[1] / 2
        hi = ave.bound3[1] + dev.bound3[1] / 2
        out[gear] = {"lo": [float(v) for v in lo], "hi": [float(v) for v in hi]}
    return out


def _apply_bands(ctx, bands: dict) -> None:
    """Band coverage of each gauge's passes, given the client's Monte Carlo band."""
    import numpy as np

    from .compare import band_coverage

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
def _warm_up() -> int:
    """Import the processing stack in a worker (so task wall times measure processing)."""
    import pipeline.compare  # noqa: F401
    import pipeline.condition  # noqa: F401
    import pipeline.io  # noqa: F401
    import pipeline.loads  # noqa: F401
    import pipeline.models.mesh_phasing  # noqa: F401
    import pipeline.onsets  # noqa: F401
    import pipeline.phasing  # noqa: F401
    import pipeline.stages  # noqa: F401
    from pipeline.io import FORMATS, get_format

    for name in FORMATS:  # the readers import h5py, mcap, pandas, npTDMS
        get_format(name)
    return os.getpid()


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
                  recording_report: bool = False) -> dict:
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

    Returns
    -------
    dict
        ``recording``, ``name``, ``out_dir``, ``status`` ("ok"; "unreliable": all computed,
        phasing flagged unreliable; "partial": a result not computed; "failed": nothing
        usable; :func:`pipeline.exits.run_status`), ``error`` (None or the cause(s)),
        ``missing_results`` and ``unreliable`` (as run_status gives them), ``format``,
        ``wall_time_s`` and ``cpu_time_s`` (this process's CPU time) [s], ``worker``,
        ``timings_s``, ``stages_ran``, ``stages_failed``,
        ``messages``, ``files`` and the compact results (``phasing``, ``load_sharing``,
        ``compare``, ``identify``, ``ideal``, ``recording_info`` ... when computed).
    """
    t0, c0 = time.perf_counter(), time.process_time()
    rec_path = Path(recording_path)
    out: dict = {"recording": str(recording_path), "name": Path(out_dir).name, "out_dir": str(out_dir),
                 "status": "failed", "error": None, "format": None, "wall_time_s": float("nan"),
                 "worker": f"{socket.gethostname()}:{os.getpid()}", "timings_s": {},
                 "stages_ran": [], "stages_failed": {}, "messages": [], "files": {}}
    try:
        from .exits import run_status
        from .io import detect_format
        from .scene import load_scene
        from .stages import run_scene, summary_dict, write_outputs

        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                out["format"] = detect_format(rec_path)
            except (ValueError, OSError) as exc:
                out["error"] = f"{type(exc).__name__}: {exc}"
            scene = load_scene(scene_path)
            _, _, mc_on_client = split_results(scene)
            scene = _worker_scene(scene, rec_path, mc_on_client and bands is not None)
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
        out["stages_failed"] = dict(ctx.failed)
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


def _failed_record(path: Path, name: str, out_dir: Path, error: str) -> dict:
    return {"recording": str(path), "name": name, "out_dir": str(out_dir), "status": "failed",
            "error": error, "format": None, "wall_time_s": float("nan"), "worker": None,
            "timings_s": {}, "stages_ran": [], "stages_failed": {}, "messages": [], "files": {}}


# ---------------------------------------------------------------------------- fault handling
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
    from .validate import as_nonnegative

    return TIMEOUT_BASE_S + as_nonnegative(size_bytes, "size_bytes") / TIMEOUT_RATE_BPS


def _sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def recording_key(recording, scene_sha256: str, options: dict | None = None) -> dict:
    """What a recording's results depend on (the key of its completion marker).

    Parameters
    ----------
    recording : str or Path
        The recording file (resolved here).
    scene_sha256 : str
        SHA-256 of the scene file's bytes.
    options : dict, optional
        Campaign options that change the results (``recording_report``).

    Returns
    -------
    dict
        ``recording`` (resolved path), ``size`` [B], ``mtime_ns``, ``scene_sha256``,
        ``meshphase`` (version), ``options``. A recording whose file was rewritten (size or
        mtime changed), or a changed scene, gives a different key.

    Raises
    ------
    OSError
        The file cannot be stat'ed.
    """
    from . import __version__

    if not isinstance(recording, (str, os.PathLike)):
        raise TypeError(f"recording must be a path, got {type(recording).__name__} {recording!r}")
    path = Path(recording).resolve()
    st = os.stat(path)
    return {"recording": str(path), "size": int(st.st_size), "mtime_ns": int(st.st_mtime_ns),
            "scene_sha256": str(scene_sha256), "meshphase": __version__,
            "options": dict(sorted((options or {}).items()))}


def _read_json(path: Path) -> dict | None:
    try:
        if not stat.S_ISREG(os.lstat(path).st_mode):
            return None
        with open(path, "rb") as fh:
            d = json.loads(fh.read(16 * 2**20).decode("utf-8"))
    except (OSError, ValueError):
        return None
    return d if isinstance(d, dict) else None


def _write_atomic(path: Path, write: Callable[[Path], None]) -> None:
    """``write(tmp)`` to a temporary file beside ``path``, fsync, rename (pipeline.io)."""
    from .io import atomic_path

    with atomic_path(path, overwrite=True) as tmp:
        write(tmp)


def _write_text_atomic(path: Path, text: str) -> None:
    _write_atomic(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


def completed_recordings(folder) -> dict[str, tuple[Path, dict]]:
    """The recordings whose results are complete in a campaign folder (its completion markers).

    Parameters
    ----------
    folder : str or Path
        A campaign output folder (or its ``.partial`` twin); missing: empty result.

    Returns
    -------
    dict
        Resolved recording path -> (the recording's results folder, its marker: ``key``
        (:func:`recording_key`) and ``record`` (what the task returned)).
    """
    out: dict[str, tuple[Path, dict]] = {}
    try:
        entries = sorted(os.scandir(Path(folder) / RECORDINGS_DIR_NAME), key=lambda e: e.name)
    except OSError:
        return out
    for e in entries:
        if not e.is_dir(follow_symlinks=False):
            continue
        m = _read_json(Path(e.path) / DONE_NAME)
        if m and isinstance(m.get("key"), dict) and isinstance(m.get("record"), dict):
            out.setdefault(str(m["key"].get("recording")), (Path(e.path), m))
    return out


def _link_or_copy(src, dst) -> None:
    try:
        os.link(src, dst, follow_symlinks=False)
    except OSError:  # no hard links here (FAT, some network file systems), or across devices
        shutil.copy2(src, dst, follow_symlinks=False)


def _relocate(record: dict, old_dir, new_dir) -> dict:
    """``record`` with its ``out_dir`` and ``files`` moved to ``new_dir`` (from the record's
    own ``out_dir``, else ``old_dir``: a marker holds the paths its task wrote, in the
    staging folder of the campaign that made it)."""
    rec = dict(record)
    old_dir = record.get("out_dir") or old_dir

    def move(p):
        try:
            return str(Path(new_dir) / Path(p).relative_to(old_dir))
        except (ValueError, TypeError):
            return p

    rec["out_dir"] = str(new_dir)
    rec["files"] = {k: move(v) for k, v in (record.get("files") or {}).items()}
    return rec


def _campaign_task(task: Callable[..., dict], scene_path: str, recording_path: str, out_dir: str,
                   dask_key: str | None = None, done_key: dict | None = None, **kw) -> dict:
    """What a campaign worker runs for one recording: tell the client the task started (its
    timeout counts from here), run ``task``, and when its results are usable (status ok,
    unreliable or partial) write the completion marker :data:`DONE_NAME` last, atomically.
    Gets paths only, never open handles."""
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
    rec = task(scene_path, recording_path, out_dir, **kw)
    if done_key is not None and isinstance(rec, dict) and rec.get("status") in ("ok", "unreliable", "partial"):
        d = Path(out_dir)
        try:
            d.mkdir(parents=True, exist_ok=True)
            _write_text_atomic(d / DONE_NAME, json.dumps(to_jsonable({"meshphase_done": 1, "key": done_key,
                                                                    "record": rec}), indent=1))
        except OSError as exc:
            rec.setdefault("messages", []).append(f"campaign: completion marker not written ({exc}); "
                                                  "--resume will redo this recording")
    return rec


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


def local_cluster(n_workers: int, *, dashboard=None):
    """The campaign's own Dask cluster: ``n_workers`` single-threaded worker processes.

    Everything listens on the loopback interface only: the scheduler and the workers
    (``host="127.0.0.1"``) and the scheduler's HTTP server, which distributed always starts
    (health and metrics routes) and which serves the dashboard - unauthenticated - when asked
    (``dashboard``); it is off by default. ``worker-saturation = 1.0``: a worker holds only
    the task it runs (inputs are paths, prefetching buys nothing), so when a worker dies or a
    task hangs only that task is concerned.

    Parameters
    ----------
    n_workers : int
    dashboard : None, bool, int or str
        None/False: no dashboard (the HTTP server on 127.0.0.1, a free port). True: the
        dashboard on 127.0.0.1, a free port. A port (8787, ":8787"): on 127.0.0.1 at that
        port. ``host:port``: there, as given (another interface only when named: it has no
        authentication; a warning is logged).

    Returns
    -------
    distributed.LocalCluster
        Its ``dashboard_link`` is the dashboard's address.
    """
    import dask
    from distributed import LocalCluster

    n_workers = as_positive_int(n_workers, "n_workers")
    if dashboard is not None and not isinstance(dashboard, (bool, int, str)):
        raise TypeError(f"dashboard must be None, a bool, a port or 'host:port', got "
                        f"{type(dashboard).__name__} {dashboard!r}")
    on = dashboard is not None and dashboard is not False
    address = _dashboard_address(dashboard) if on else "127.0.0.1:0"
    host = address.rsplit(":", 1)[0].strip("[]")
    if on and host not in ("127.0.0.1", "localhost", "::1"):
        logger.warning("campaign: the Dask dashboard listens on %s without authentication", address)
    # the workers' own distributed logs (a cancelled task, a restart) reach stderr only when
    # our logger is verbose (meshphase -v): the campaign reports those events itself
    quiet = logging.WARNING if logger.isEnabledFor(logging.INFO) else logging.ERROR
    with dask.config.set({"distributed.scheduler.worker-saturation": 1.0}):
        return LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                            host="127.0.0.1", dashboard_address=address, silence_logs=quiet,
                            scheduler_kwargs={"dashboard": on})


# ---------------------------------------------------------------------------- tables
def campaign_rows(records: list[dict]) -> list[dict]:
    """One flat row per recording (the columns of ``campaign.csv``).

    Columns: name, recording, format, status, error, duration_s, wall_time_s, worker,
    attempts (1 + the retries), retries (their causes, "; "-separated), resumed (taken from an
    earlier run by ``--resume``), passes_<gauge>, rms_vs_ideal_<gauge>, rms_vs_model_<gauge>, coverage_<gauge>,
    gamma_mean_<gauge>_p<k>, gamma_std_<gauge>_p<k> [mesh cycles], load_sharing_p<k>,
    load_sharing_se_p<k> [-], identify_rms_after, n_messages, out_dir.

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
            row[f"rms_vs_ideal_{gear}"] = c.get("rms_vs_ideal")
            row[f"rms_vs_model_{gear}"] = c.get("rms_vs_model")
            row[f"coverage_{gear}"] = c.get("coverage")
            for k, v in sorted(((ph or {}).get("per_planet") or {}).items(), key=lambda kv: int(kv[0])):
                row[f"gamma_mean_{gear}_p{k}"] = v.get("mean")
                row[f"gamma_std_{gear}_p{k}"] = v.get("std")
        for ls in r.get("load_sharing") or []:
            row[f"load_sharing_p{ls['planet']}"] = ls.get("load_sharing")
            row[f"load_sharing_se_p{ls['planet']}"] = ls.get("std_error")
        row["identify_rms_after"] = (r.get("identify") or {}).get("rms_after")
        row["n_messages"] = len(r.get("messages") or [])
        row["out_dir"] = r.get("out_dir")
        rows.append(row)
    # one column set and order for every row: fixed columns, then per planet, then the tail
    tail = ["identify_rms_after", "n_messages", "out_dir"]
    keys = list(dict.fromkeys(k for row in rows for k in row))
    fixed = [k for k in keys if not k.startswith(("gamma_", "load_sharing_")) and k not in tail]

    def planet_key(k):
        kind, _, p = k.rpartition("_p")
        return (k.startswith("load_sharing"), kind.split("_")[-1] if k.startswith("gamma") else "",
                int(p), kind)

    per_planet = sorted((k for k in keys if k.startswith(("gamma_", "load_sharing_"))), key=planet_key)
    order = fixed + per_planet + tail
    return [{k: row.get(k) for k in order} for row in rows]


def campaign_exit_code(campaign: dict) -> int:
    """The exit code of ``meshphase campaign`` (table in :mod:`pipeline.exits`).

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
    from .exits import EXIT_ERROR, EXIT_OK, EXIT_PARTIAL

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
def _cores() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not on Linux
        return max(1, os.cpu_count() or 1)


def run_campaign(scene_path, inputs, out_dir=None, *, scheduler: str | None = None,
                 workers: int | None = None, overwrite: bool = False, progress: bool = True,
                 recording_reports: bool = False, task: Callable[..., dict] | None = None,
                 task_timeout: float | None = None, resume: bool = False, dashboard=None) -> dict:
    """Process many recordings with one scene as one Dask job.

    The output folder is written whole or not at all (:class:`pipeline.exits.OutputDir`: a
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
        did not write or symbolic links: :class:`pipeline.exits.OutputDir`).
    progress : bool
        A tqdm progress bar (recordings done) on stderr.
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

    Returns
    -------
    dict
        ``scene``, ``scene_path``, ``out_dir``, ``cluster`` (``scheduler``, ``n_workers``,
        ``local``, ``dashboard``), ``timing_s`` (``total``, ``scene_level``,
        ``cluster_start``, ``processing``, ``report``), ``counts`` (ok / unreliable / partial
        / failed), ``skipped_inputs``, ``scene_level`` (summary of the client-side results or
        None), ``scene_status`` (their :func:`pipeline.exits.run_status`, or None),
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
    from .exits import PARTIAL_SUFFIX, OutputDir, remove_partial
    from .scene import load_scene, plan
    from .validate import as_nonnegative

    if scheduler is not None and not isinstance(scheduler, str):
        raise TypeError(f"scheduler must be an address string like 'tcp://host:8786', got "
                        f"{type(scheduler).__name__} {scheduler!r}")
    if workers is not None:
        workers = as_positive_int(workers, "workers")
        if scheduler is not None:
            raise ValueError(f"workers={workers} applies to the local cluster only; the cluster at "
                             f"{scheduler!r} has its own workers")
    if dashboard is not None and dashboard is not False:
        if not isinstance(dashboard, (bool, int, str)):
            raise TypeError(f"dashboard must be None, a bool, a port or 'host:port', got "
                            f"{type(dashboard).__name__} {dashboard!r}")
        if scheduler is not None:
            raise ValueError(f"dashboard={dashboard!r} applies to the local cluster only; the cluster "
                             f"at {scheduler!r} has its own dashboard")
    if task_timeout is not None:
        task_timeout = as_nonnegative(task_timeout, "task_timeout")
    task = run_recording if task is None else task
    if not callable(task):
        raise TypeError(f"task must be callable, got {type(task).__name__}")
    scene_path = Path(scene_path).resolve()
    scene = load_scene(scene_path)  # FileNotFoundError / SceneError (a ValueError) up front
    if not isinstance(inputs, (str, bytes, os.PathLike)):
        inputs = list(inputs)  # read twice below: a generator would be empty the second time
    files, skipped = collect_recordings(inputs)
    if not files:
        left = [Path(s["path"]).name for s in skipped]
        raise ValueError(f"no recording files found in inputs {[str(i) for i in inputs]!r}"
                         + (f" (left out: {', '.join(left[:8])}{', ...' if len(left) > 8 else ''})"
                            if left else ""))
    client_results, worker_results, mc_on_client = split_results(scene)
    if not worker_results:
        raise ValueError(f"scene {scene_path.name}: results {scene.results} need no recording; "
                         "a campaign needs per-recording results (phasing, load_sharing, compare, "
                         "identify, centroids); use `meshphase run` for this scene")
    plan(_worker_scene(scene, files[0], mc_on_client))  # the worker scene validates here, once
    names = recording_names(files)
    base = Path(out_dir) if out_dir is not None else scene_path.with_name(scene_path.stem + "-campaign")
    partial = base.with_name(base.name + PARTIAL_SUFFIX)
    opts = {"scene_path": str(scene_path), "scene_path_sha256": _sha256_file(scene_path), "client_results": client_results,
            "worker_results": worker_results, "mc_on_client": mc_on_client, "scheduler": scheduler,
            "workers": workers, "progress": progress, "recording_reports": bool(recording_reports),
            "task": task, "t_all": t_all, "task_timeout": task_timeout, "resume": bool(resume),
            "sources": [base, partial] if resume else [], "dashboard": dashboard}
    # the folder is reserved now; the campaign fills a staging folder beside it, swapped in
    # when it finishes; if it raises or is interrupted (Ctrl-C) nothing is left but the
    # recordings it had finished, in <out>.partial (pipeline.exits.OutputDir)
    with OutputDir(base, overwrite=overwrite or resume, staged=True) as guard:
        opts["guard"] = guard
        result = _campaign_body(scene, scene_path, inputs, files, skipped, names, guard.path.resolve(), opts)
    if resume and Path(guard.final) == Path(os.path.abspath(base)):
        remove_partial(base)  # its results are in the campaign now
    return result


def _campaign_body(scene, scene_path, inputs, files, skipped, names, out, opts) -> dict:
    """The campaign after its output folder is reserved (see :func:`run_campaign`); ``out``
    is the staging folder, ``opts["guard"].final`` the folder it will be."""
    from .stages import run_scene, summary_dict, write_outputs

    guard = opts["guard"]
    final = Path(guard.final).resolve()
    client_results, mc_on_client = opts["client_results"], opts["mc_on_client"]
    scheduler = opts["scheduler"]
    timing: dict[str, float] = {}

    def final_of(p) -> str:
        try:
            return str(final / Path(p).relative_to(out))
        except ValueError:
            return str(p)

    # --- scene-level results, once, on the client
    t = time.perf_counter()
    scene_level = None
    scene_status = None
    bands = None
    if client_results:
        from .exits import run_status

        sctx = run_scene(_client_scene(scene))
        scene_status = {k: v for k, v in run_status(sctx).items() if k != "exit_code"}
        sdir = out / SCENE_DIR_NAME
        sdir.mkdir(exist_ok=True)
        write_outputs(sctx, sdir, report=False)
        scene_level = summary_dict(sctx)
        if mc_on_client and "tolerance" in sctx.results:
            bands = _bands(sctx.results["tolerance"])
            scene_level["bands"] = bands
        elif mc_on_client:
            logger.warning("campaign: the tolerance Monte Carlo failed (%s); no band coverage",
                           sctx.failed.get("tolerance"))
    timing["scene_level"] = time.perf_counter() - t

    # --- keys, and the recordings a resumed campaign has done already
    rec_root = out / RECORDINGS_DIR_NAME
    rec_root.mkdir(exist_ok=True)
    rec_dirs = [rec_root / n for n in names]
    options = {"recording_report": opts["recording_reports"]}
    keys: list[dict | None] = []
    for f in files:
        try:
            keys.append(recording_key(f, opts["scene_path_sha256"], options))
        except OSError:
            keys.append(None)  # gone since it was listed: the task reports it
    records: dict[int, dict] = {}
    # (the folder reserved for this campaign is new and empty: no source)
    sources = [str(s) for s in opts["sources"]
               if not Path(s).is_symlink() and (Path(s) / RECORDINGS_DIR_NAME).is_dir()]
    if sources:
        done: dict[str, tuple[Path, dict]] = {}
        for src in sources:
            for path, hit in completed_recordings(src).items():
                done.setdefault(path, hit)
        for i, key in enumerate(keys):
            hit = done.get(key["recording"]) if key else None
            if hit is None or hit[1].get("key") != key:
                continue
            try:
                shutil.copytree(hit[0], rec_dirs[i], symlinks=True, copy_function=_link_or_copy)
            except (OSError, shutil.Error) as exc:
                logger.warning("campaign: %s: cannot reuse the results in %s (%s); redone", files[i],
                               hit[0], exc)
                shutil.rmtree(rec_dirs[i], ignore_errors=True)
                continue
            rec = _relocate(hit[1]["record"], hit[0], final_of(rec_dirs[i]))
            rec.update(name=names[i], resumed=True)
            records[i] = rec
        if records:
            guard.mark_partial()
            logger.info("campaign: %d of %d recordings complete already (--resume)", len(records), len(files))

    # --- per-task timeouts [s] (None: none)
    tt = opts["task_timeout"]
    limits = {}
    for i, key in enumerate(keys):
        limits[i] = (None if tt == 0 else tt if tt is not None
                     else default_task_timeout(key["size"] if key else 0))

    # --- the Dask job
    todo = [i for i in range(len(files)) if i not in records]
    cluster_info = {"scheduler": None, "n_workers": 0, "local": scheduler is None, "dashboard": None}
    timing["cluster_start"] = 0.0
    timing["processing"] = 0.0
    if todo:
        _run_tasks(files, names, rec_dirs, keys, limits, todo, records, bands, cluster_info, timing,
                   opts, final_of)
    recs = [records[i] for i in range(len(files))]
    for r in recs:
        r.setdefault("attempts", 1)
        r.setdefault("retries", [])
        r.setdefault("resumed", False)

    # --- combined outputs, each written atomically
    t = time.perf_counter()
    counts = {s: sum(r.get("status") == s for r in recs) for s in STATUSES}
    result = {"scene": scene.name, "scene_path": str(scene_path), "out_dir": str(final),
              "inputs": [str(i) for i in inputs], "skipped_inputs": skipped,
              "cluster": cluster_info, "results_client": client_results,
              "results_per_recording": opts["worker_results"], "counts": counts, "timing_s": timing,
              "scene_level": scene_level, "scene_status": scene_status,
              "task_timeout": {"mode": "off" if tt == 0 else "size" if tt is None else "fixed",
                               "seconds": tt if tt else None},
              "resume": {"enabled": opts["resume"], "n_resumed": sum(bool(r.get("resumed")) for r in recs),
                         "sources": sources},
              "recordings": recs}
    result["exit_code"] = campaign_exit_code(result)
    import pandas as pd

    csv_path = out / "campaign.csv"
    rows = pd.DataFrame(campaign_rows(recs))
    _write_atomic(csv_path, lambda tmp: rows.to_csv(tmp, index=False))
    from .report.campaign_report import build_campaign_report

    report_path = build_campaign_report(result, out)
    timing["report"] = time.perf_counter() - t
    timing["total"] = time.perf_counter() - opts["t_all"]
    json_path = out / "campaign.json"
    result["files"] = {"campaign.json": final_of(json_path), "campaign.csv": final_of(csv_path),
                       "campaign_report.html": final_of(report_path)}
    _write_text_atomic(json_path, json.dumps(to_jsonable(result), indent=2))
    logger.info("campaign %s: %d ok, %d unreliable, %d partial, %d failed in %.1f s -> %s",
                scene.name, counts["ok"], counts["unreliable"], counts["partial"], counts["failed"],
                timing["total"], final)
    return result


def _dask_key(token: str, i: int, name: str) -> str:
    return f"meshphase-{token}-{i}-{re.sub(r'[^A-Za-z0-9_.-]', '_', name)[:40]}"


def _run_tasks(files, names, rec_dirs, keys, limits, todo, records, bands, cluster_info, timing,
               opts, final_of) -> None:
    """Submit the recordings ``todo`` to the cluster and collect one record per recording into
    ``records``: results, failures, timeouts (worker restarted) and retries (worker lost)."""
    from distributed import Client

    scheduler = opts["scheduler"]
    cluster = None
    t = time.perf_counter()
    # distributed logs cluster life (start, connections, close) at INFO and worker restarts
    # at WARNING; show them only when our own logger is verbose (meshphase -v): the campaign
    # reports lost workers, retries and timeouts itself
    dlog = logging.getLogger("distributed")
    old_level = dlog.level
    if not logger.isEnabledFor(logging.INFO):
        dlog.setLevel(logging.ERROR)
    try:
        if scheduler is None:
            cluster = local_cluster(opts["workers"] or _cores(), dashboard=opts["dashboard"])
            client = Client(cluster)
            if opts["dashboard"] not in (None, False):
                cluster_info["dashboard"] = cluster.dashboard_link
                logger.warning("campaign: Dask dashboard at %s", cluster.dashboard_link)
        else:
            try:
                client = Client(scheduler)
            except OSError as exc:
                raise ValueError(f"scheduler {scheduler!r}: cannot connect: {exc}") from None
        with client:
            try:
                pids = client.run(_warm_up)
            except ImportError as exc:
                raise ValueError(f"the workers of {client.scheduler.address} cannot import "
                                 f"meshphase ({exc}); install it where the workers run") from None
            cluster_info["n_workers"] = len(pids)
            if not pids:
                logger.warning("campaign: the cluster at %s has no workers yet; the tasks wait "
                               "for workers to join", client.scheduler.address)
            cluster_info["scheduler"] = client.scheduler.address
            timing["cluster_start"] = time.perf_counter() - t
            t = time.perf_counter()
            _collect(client, files, names, rec_dirs, keys, limits, todo, records, bands, opts,
                     final_of)
            timing["processing"] = time.perf_counter() - t
    finally:
        if cluster is not None:
            cluster.close()
        dlog.setLevel(old_level)


def _collect(client, files, names, rec_dirs, keys, limits, todo, records, bands, opts, final_of) -> None:
    guard = opts["guard"]
    token = uuid.uuid4().hex[:10]  # task keys unique on a shared scheduler
    dkeys = {i: _dask_key(token, i, names[i]) for i in todo}
    index_of = {k: i for i, k in dkeys.items()}
    starts: dict[str, list[dict]] = {}
    lost: dict[str, list[dict]] = {}
    restarted: set = set()  # workers this campaign restarted (after a timeout)

    # the handlers run on the client's event loop thread, before the loop below sees the
    # futures they concern (events and results come on one ordered stream)
    def on_start(event):
        msg = event[1] if isinstance(event, (tuple, list)) and len(event) == 2 else event
        if isinstance(msg, dict) and msg.get("key") in index_of:
            starts.setdefault(msg["key"], []).append({"t": time.monotonic(), "worker": msg.get("worker"),
                                                      "pid": msg.get("pid")})

    def on_cluster(event):
        msg = event[1] if isinstance(event, (tuple, list)) and len(event) == 2 else event
        if not isinstance(msg, dict) or msg.get("action") != "remove-worker":
            return
        w = msg.get("worker")
        for k in msg.get("processing-tasks") or ():
            if k not in index_of:
                continue
            st = starts.get(k) or []
            ran = bool(st) and st[-1]["worker"] == w
            # a worker that dies at once may not have sent the task's start: "held"
            cause = (f"worker {w} (pid {st[-1]['pid']}) was lost while running it" if ran
                     else f"worker {w} was lost while it held the task")
            cause += (" (restarted after another task's timeout)" if w in restarted
                      else " (killed, crashed or out of memory)")
            lost.setdefault(k, []).append({"cause": cause, "worker": w, "running": ran})

    client.subscribe_topic(_START_TOPIC, on_start)
    client.subscribe_topic("all", on_cluster)
    try:
        _collect_loop(client, files, names, rec_dirs, keys, limits, todo, records, bands, opts,
                      final_of, guard, dkeys, index_of, starts, lost, restarted)
    finally:
        # before the client closes: else the scheduler fails to send it the "remove-client"
        # event of topic "all" and logs that as CRITICAL
        for topic in (_START_TOPIC, "all"):
            with contextlib.suppress(Exception):
                client.unsubscribe_topic(topic)


def _collect_loop(client, files, names, rec_dirs, keys, limits, todo, records, bands, opts,
                  final_of, guard, dkeys, index_of, starts, lost, restarted) -> None:
    import functools

    from tqdm import tqdm

    kw = {"bands": bands, "recording_report": opts["recording_reports"]}
    fn = functools.partial(_campaign_task, opts["task"])
    # one map call = one graph: the tasks form one group, which the scheduler queues
    # (root-ish tasks) when there are more than twice as many as worker threads
    futs = client.map(fn, [opts["scene_path"]] * len(todo), [str(files[i]) for i in todo],
                      [str(rec_dirs[i]) for i in todo], [dkeys[i] for i in todo],
                      [keys[i] for i in todo], key=[dkeys[i] for i in todo], pure=False, **kw)
    fut_of = dict(zip(todo, futs))
    done_q: queue.SimpleQueue = queue.SimpleQueue()
    for f in futs:
        f.add_done_callback(done_q.put)
    pending = set(todo)
    n_failed = 0

    def finish(i: int, rec: dict) -> None:
        nonlocal n_failed
        k = dkeys[i]
        if not isinstance(rec, dict):
            rec = _failed_record(files[i], names[i], rec_dirs[i],
                                 f"task returned {type(rec).__name__}, not a dict")
        rec = _relocate(rec, rec_dirs[i], final_of(rec_dirs[i]))
        retries = lost.get(k, [])
        rec["retries"] = [r["cause"] for r in retries]
        rec["attempts"] = 1 + len(retries)
        rec["resumed"] = False
        if retries:
            logger.warning("campaign: %s: %s; retried (attempt %d)", files[i], retries[-1]["cause"],
                           rec["attempts"])
        records[i] = rec
        pending.discard(i)
        if rec.get("status") == "failed":
            n_failed += 1
        else:
            guard.mark_partial()
        bar.set_postfix_str(f"failed {n_failed}")
        bar.update(1)

    with tqdm(total=len(records) + len(todo), initial=len(records), desc="recordings", unit="rec",
              disable=not opts["progress"], file=sys.stderr, leave=False) as bar:
        next_check = 0.0
        while pending:
            try:
                f = done_q.get(timeout=0.5)
            except queue.Empty:
                f = None
            if f is not None:
                i = index_of.get(f.key)
                if i in pending:
                    if f.status == "finished":
                        try:
                            rec = f.result()
                        except Exception as exc:  # noqa: BLE001 - a result that cannot be fetched
                            rec = _failed_record(files[i], names[i], rec_dirs[i],
                                                 f"task lost: {type(exc).__name__}: {exc}")
                    else:  # the worker died too often (KilledWorker), or the task raised
                        exc = f.exception() if f.status == "error" else None
                        err = (f"{type(exc).__name__}: {exc}" if exc is not None else f"dask future {f.status}")
                        rec = _failed_record(files[i], names[i], rec_dirs[i], f"task lost: {err}")
                        shutil.rmtree(rec_dirs[i], ignore_errors=True)  # whatever it half wrote
                        logger.warning("campaign: %s: %s", files[i], rec["error"])
                    finish(i, rec)
                f.release()
            now = time.monotonic()
            if now < next_check:
                continue
            next_check = now + 0.5
            for i in sorted(pending):
                st = starts.get(dkeys[i])
                if limits[i] is None or not st or now - st[-1]["t"] <= limits[i]:
                    continue
                restarted.add(st[-1]["worker"])
                finish(i, _timed_out(client, fut_of[i], files[i], names[i], rec_dirs[i], limits[i], st[-1]))


def _own_child(pid) -> bool:
    """True when ``pid`` is a process this one started (a worker of our LocalCluster)."""
    import psutil

    try:
        return isinstance(pid, int) and any(c.pid == pid for c in psutil.Process().children(recursive=True))
    except psutil.Error:
        return False


def _timed_out(client, fut, path, name, rec_dir, limit, start) -> dict:
    """Fail a task that ran past its timeout: cancel it, end its worker (the only way to stop
    a thread blocked in a read), drop what it half wrote.

    A worker of our own LocalCluster is killed at once (SIGKILL; its Nanny starts a new one:
    a graceful restart would wait for the blocked thread first); another cluster's worker is
    restarted through the scheduler (which needs a Nanny there)."""
    import signal

    client.cancel([fut])
    w, pid = start["worker"], start["pid"]
    if _own_child(pid):
        try:
            os.kill(pid, getattr(signal, "SIGKILL", signal.SIGTERM))
            how = "killed (its Nanny starts a new one)"
        except OSError as exc:
            how = f"not stopped ({exc}): it may stay busy"
    else:
        try:
            res = client.restart_workers([w], timeout=120, raise_for_error=False)
            state = res.get(w, "?") if isinstance(res, dict) else "?"
        except Exception as exc:  # noqa: BLE001 - the campaign goes on either way
            state = f"{type(exc).__name__}: {exc}"
        how = "restarted" if state == "OK" else f"not restarted ({state}): it may stay busy"
    shutil.rmtree(rec_dir, ignore_errors=True)
    rec = _failed_record(path, name, rec_dir, f"timeout: no result {limit:.4g} s after the task started "
                                              f"(--task-timeout); its worker {w} (pid {pid}) was {how}")
    rec["timed_out"] = True
    rec["worker"] = w
    logger.warning("campaign: %s: %s", path, rec["error"])
    return rec


def cli_campaign(scene_path, inputs: list[str], *, scheduler: str | None = None,
                 workers: int | None = None, out=None, overwrite: bool = False,
                 progress: bool = True, recording_reports: bool = False,
                 task_timeout: float | None = None, resume: bool = False, dashboard=None) -> dict:
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

    Returns
    -------
    dict
        As :func:`run_campaign`.
    """
    return run_campaign(scene_path, list(inputs), out, scheduler=scheduler, workers=workers,
                        overwrite=overwrite, progress=progress, recording_reports=recording_reports,
                        task_timeout=task_timeout, resume=resume, dashboard=dashboard)


# ---------------------------------------------------------------------------- speed-up
def _finite_sum(values) -> float:
    return float(sum(v for v in values if isinstance(v, (int, float)) and math.isfinite(v)))


def measure_speedup(n_recordings: int = 8, minutes: float = 2.0, workers=(1, 2), *,
                    repeats: int = 1, scenario: str = "noisy", scene_path=None, work_dir=None,
                    seed: int = 0, progress: bool = False) -> dict:
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
        Synthetic scenario (:data:`synthetic.SCENARIOS`).
    scene_path : str or Path, optional
        Scene to run (default: the demo scene, :data:`pipeline.demo.DEMO_SCENE`).
    work_dir : str or Path, optional
        Where recordings and outputs go (default: a temporary folder, removed afterwards).
    seed : int
        Seed of the first recording.
    progress : bool

    Returns
    -------
    dict
        ``n_recordings``, ``minutes``, ``cores``, ``runs`` (per worker count: ``workers``,
        ``wall_s`` total incl. cluster start, ``cluster_start_s``, ``processing_s``
        (first submit to last result), ``scene_level_s``, ``report_s``, ``task_sum_s`` and
        ``task_cpu_sum_s`` (sums of the tasks' own wall and CPU times: their ratio shows
        contention for the cores), ``n_ok``, ``n_failed``), ``loadavg`` (the machine's load
        before the first run: other work on the cores distorts the numbers), and
        ``speedup`` / ``processing_speedup`` per worker count relative to the first.
    """
    n_recordings = as_positive_int(n_recordings, "n_recordings")
    minutes = as_positive(minutes, "minutes")
    repeats = as_positive_int(repeats, "repeats")
    if isinstance(workers, (int, str)) or not hasattr(workers, "__iter__"):
        raise TypeError(f"workers must be a sequence of ints, got {workers!r}")
    workers = [as_positive_int(w, "workers") for w in workers]
    if not workers:
        raise ValueError("workers must name at least one worker count, got an empty sequence")
    from synthetic import cli_synth
    from synthetic.scenarios import SCENARIOS

    if scenario not in SCENARIOS:
        raise ValueError(f"scenario must be one of {sorted(SCENARIOS)}, got {scenario!r}")
    tmp = None
    if work_dir is None:
        tmp = tempfile.TemporaryDirectory(prefix="meshphase-speedup-")
        work = Path(tmp.name)
    else:
        work = Path(work_dir)
        work.mkdir(parents=True, exist_ok=True)
    try:
        rec_dir = work / "recordings"
        rec_dir.mkdir(exist_ok=True)
        for k in range(n_recordings):
            p = rec_dir / f"{scenario}_{k:03d}.h5"
            if not p.exists():
                cli_synth(scenario, p, minutes=minutes, seed=seed + k, progress=False)
        if scene_path is None:
            from .demo import DEMO_SCENE

            scene_path = work / "speedup_scene.toml"
            scene_path.write_text(DEMO_SCENE, encoding="utf-8")
        # warm the client up (imports, numba compilation of the Monte Carlo kernel) so that
        # the first timed run does not pay for what the later ones get for free
        import distributed  # noqa: F401

        from .report import campaign_report  # noqa: F401
        from .scene import load_scene
        from .stages import run_scene

        warm = _client_scene(load_scene(scene_path))
        if warm.results:
            run_scene(warm)
        runs = []
        load0 = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
        for rep, w in ((rep, w) for rep in range(repeats) for w in workers):
            res = run_campaign(scene_path, [rec_dir], work / f"campaign-{w}w", workers=w,
                               progress=progress)
            tm = res["timing_s"]
            runs.append({"workers": w, "repeat": rep, "wall_s": tm["total"],
                         "cluster_start_s": tm["cluster_start"],
                         "processing_s": tm["processing"], "scene_level_s": tm["scene_level"],
                         "report_s": tm["report"],
                         "task_sum_s": _finite_sum(r.get("wall_time_s") for r in res["recordings"]),
                         "task_cpu_sum_s": _finite_sum(r.get("cpu_time_s") for r in res["recordings"]),
                         "n_ok": res["counts"]["ok"], "n_failed": res["counts"]["failed"]})
            logger.info("speed-up: %d worker(s): %.1f s total, %.1f s processing", w,
                        tm["total"], tm["processing"])
        best = {w: min(r["wall_s"] for r in runs if r["workers"] == w) for w in workers}
        best_p = {w: min(r["processing_s"] for r in runs if r["workers"] == w) for w in workers}
        ref = workers[0]
        return {"n_recordings": n_recordings, "minutes": minutes, "scenario": scenario,
                "repeats": repeats, "cores": _cores(), "loadavg": list(load0), "runs": runs,
                "best_wall_s": best, "best_processing_s": best_p,
                "speedup": {w: best[ref] / best[w] for w in workers},
                "processing_speedup": {w: best_p[ref] / best_p[w] for w in workers}}
    finally:
        if tmp is not None:
            tmp.cleanup()
