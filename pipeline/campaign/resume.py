"""Completion markers of a campaign's recordings, and ``--resume`` from them.

A recording's results folder ``recordings/<name>/`` gets its completion marker
(:data:`DONE_NAME`) last and atomically (:func:`write_marker`): the key of its inputs
(:func:`recording_key`: recording path, size, mtime; scene hash; meshphase version; options)
and its campaign record. ``--resume`` reuses a recording whose marker's key matches
(:func:`completed_recordings`, :func:`reuse_completed`), from the campaign folder and from
the ``.partial`` folder an unfinished campaign kept (:func:`resume_sources`).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from pathlib import Path
from typing import Callable, Sequence

from ..io import atomic_path
from ..run.outdir import read_json_object
from ..jsonable import to_jsonable
from ..runtime.log import logger
from ..version import __version__

__all__ = ["RECORDINGS_DIR_NAME", "DONE_NAME", "sha256_file", "recording_key", "recording_keys",
           "completed_recordings", "resume_sources", "reuse_completed", "relocate",
           "write_marker"]

#: sub-folder of the campaign output with one folder per recording, ``recordings/<name>/``:
#: names derived from recording files live in their own name space, so they never collide
#: with the campaign's own files and folders
RECORDINGS_DIR_NAME = "recordings"
#: a recording's completion marker, written last and atomically into its folder: the key of
#: its inputs (recording path, size, mtime; scene hash; meshphase version; options) and its
#: campaign record. ``--resume`` skips a recording whose marker's key matches.
DONE_NAME = "done.json"


def sha256_file(path) -> str:
    """SHA-256 of a file's bytes (the scene's, in a recording's key), hex digits.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    str

    Raises
    ------
    OSError
        The file cannot be read.
    """
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

    if not isinstance(recording, (str, os.PathLike)):
        raise TypeError(f"recording must be a path, got {type(recording).__name__} {recording!r}")
    path = Path(recording).resolve()
    st = os.stat(path)
    return {"recording": str(path), "size": int(st.st_size), "mtime_ns": int(st.st_mtime_ns),
            "scene_sha256": str(scene_sha256), "meshphase": __version__,
            "options": dict(sorted((options or {}).items()))}


def recording_keys(files: Sequence, scene_sha256: str, options: dict | None = None) -> list[dict | None]:
    """:func:`recording_key` of each file; None for a file gone since it was listed (its
    task then reports it).

    Parameters
    ----------
    files : sequence of str or Path
    scene_sha256 : str
    options : dict, optional

    Returns
    -------
    list of dict or None
        One entry per file, in order.
    """
    if isinstance(files, (str, bytes, os.PathLike)):
        raise TypeError(f"files must be a list of paths, got a single path {files!r}")
    keys: list[dict | None] = []
    for f in files:
        try:
            keys.append(recording_key(f, scene_sha256, options))
        except OSError:
            keys.append(None)  # gone since it was listed: the task reports it
    return keys


def write_marker(out_dir, done_key: dict, record: dict) -> None:
    """Write a recording's completion marker :data:`DONE_NAME` into ``out_dir`` (created),
    atomically: ``{"meshphase_done": 1, "key": done_key, "record": record}``.

    Parameters
    ----------
    out_dir : str or Path
        The recording's results folder.
    done_key : dict
        Its :func:`recording_key`.
    record : dict
        What its task returned.

    Raises
    ------
    TypeError
        ``done_key`` or ``record`` is not a dict.
    OSError
        The folder or the file cannot be written.
    """
    if not isinstance(done_key, dict) or not isinstance(record, dict):
        raise TypeError(f"done_key and record must be dicts, got {type(done_key).__name__} and "
                        f"{type(record).__name__}")
    d = Path(out_dir)
    d.mkdir(parents=True, exist_ok=True)
    text = json.dumps(to_jsonable({"meshphase_done": 1, "key": done_key, "record": record}), indent=1)
    with atomic_path(d / DONE_NAME, overwrite=True) as tmp:
        tmp.write_text(text, encoding="utf-8")


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
        m = read_json_object(Path(e.path) / DONE_NAME, 16 * 2**20)
        if m and isinstance(m.get("key"), dict) and isinstance(m.get("record"), dict):
            out.setdefault(str(m["key"].get("recording")), (Path(e.path), m))
    return out


def relocate(record: dict, old_dir, new_dir) -> dict:
    """``record`` with its ``out_dir`` and ``files`` moved to ``new_dir``.

    From the record's own ``out_dir``, else ``old_dir``: a marker holds the paths its task
    wrote, in the staging folder of the campaign that made it. Paths outside that folder
    stay as they are.

    Parameters
    ----------
    record : dict
        A recording's campaign record (:func:`meshphase.campaign.runner.run_recording`).
    old_dir, new_dir : str or Path

    Returns
    -------
    dict
        A shallow copy with ``out_dir`` and ``files`` rewritten.

    Raises
    ------
    TypeError
        ``record`` is not a dict.
    """
    if not isinstance(record, dict):
        raise TypeError(f"record must be a dict, got {type(record).__name__}")
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


def resume_sources(candidates: Sequence) -> list[str]:
    """The folders ``--resume`` may take results from: those of ``candidates`` (the campaign
    folder and its ``.partial`` twin) that hold a recordings folder and are no symbolic link.

    Parameters
    ----------
    candidates : sequence of str or Path

    Returns
    -------
    list of str
    """
    if isinstance(candidates, (str, bytes, os.PathLike)):
        raise TypeError(f"candidates must be a list of folders, got a single path {candidates!r}")
    return [str(s) for s in candidates
            if not Path(s).is_symlink() and (Path(s) / RECORDINGS_DIR_NAME).is_dir()]


def _link_or_copy(src, dst) -> None:
    try:
        os.link(src, dst, follow_symlinks=False)
    except OSError:  # no hard links here (FAT, some network file systems), or across devices
        shutil.copy2(src, dst, follow_symlinks=False)


def reuse_completed(sources: Sequence, keys: Sequence, rec_dirs: Sequence, names: Sequence,
                    final_of: Callable[[Path], str]) -> dict[int, dict]:
    """Take the complete results of recordings whose marker matches their key from
    ``sources``: their folders are hard-linked (else copied) to ``rec_dirs``.

    Parameters
    ----------
    sources : sequence of str or Path
        Folders to reuse results from (:func:`resume_sources`), first hit wins.
    keys : sequence of dict or None
        Each recording's :func:`recording_key` (None: not reused).
    rec_dirs : sequence of Path
        Each recording's results folder in this campaign (staging).
    names : sequence of str
        Each recording's name.
    final_of : callable
        A path in the staging folder -> the path it will have in the finished campaign.

    Returns
    -------
    dict
        Recording index -> its record (relocated, ``name`` set, ``resumed`` True).
    """
    if not (len(keys) == len(rec_dirs) == len(names)):
        raise ValueError(f"keys, rec_dirs and names must have one entry per recording, got "
                         f"{len(keys)}, {len(rec_dirs)}, {len(names)}")
    done: dict[str, tuple[Path, dict]] = {}
    for src in sources:
        for path, hit in completed_recordings(src).items():
            done.setdefault(path, hit)
    records: dict[int, dict] = {}
    for i, key in enumerate(keys):
        hit = done.get(key["recording"]) if key else None
        if hit is None or hit[1].get("key") != key:
            continue
        try:
            shutil.copytree(hit[0], rec_dirs[i], symlinks=True, copy_function=_link_or_copy)
        except (OSError, shutil.Error) as exc:
            logger.warning("campaign: %s: cannot reuse the results in %s (%s); redone", key["recording"],
                           hit[0], exc)
            shutil.rmtree(rec_dirs[i], ignore_errors=True)
            continue
        rec = relocate(hit[1]["record"], hit[0], final_of(rec_dirs[i]))
        rec.update(name=names[i], resumed=True)
        records[i] = rec
    return records
