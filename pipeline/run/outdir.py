"""A run's output folder, written whole or not at all.

:class:`OutputDir` reserves a run's output folder, lets the run fill a staging folder beside
it and swaps that in atomically when the run finishes (nothing of a failed or interrupted run
is left; ``--overwrite`` leaves no stale file and never writes through symbolic links);
:func:`recover_output_dirs` cleans up what a killed writer left beside its folder;
:func:`output_write_errors` names the output path in an OSError of a full disk.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import re
import secrets
import shutil
import socket
import stat
import time
from collections import OrderedDict
from pathlib import Path

# one definition of "this host" and "that writer is gone" for the temp files and the
# output folders (a process under another user counts as alive: not ours to recover)
from ..version import __version__
from ..io import atomic_path
from ..io.atomic import WRITE_FULL, SignalGuard, fsync_path, host_tag, pid_alive
from ..runtime.log import logger

__all__ = ["OutputDir", "output_write_errors", "new_output_dir", "free_output_name",
           "foreign_entries", "recover_output_dirs", "published_path", "remove_partial",
           "read_json_object", "MANIFEST_NAME", "PARTIAL_SUFFIX", "STALE_DIR_AGE"]


@contextlib.contextmanager
def output_write_errors(path):
    """Name the output ``path`` in an OSError of a full disk (ENOSPC, EDQUOT, EFBIG) that
    names no file: Python's buffered writers (``Path.write_text``, pandas) raise it when they
    flush or close, without the file name.

    Parameters
    ----------
    path : str or Path
        The output file or folder the caller writes (as the user named it).
    """
    try:
        yield
    except OSError as exc:
        if exc.errno in WRITE_FULL and exc.filename is None:
            raise OSError(exc.errno, os.strerror(exc.errno), str(path)) from exc
        raise


#: The manifest meshphase writes into every folder it publishes (and into a staging folder
#: while a run fills it): JSON with ``state`` ("staging", "partial" or "complete"),
#: ``target`` (the folder's name), ``files`` (the relative paths of the files written) and,
#: in a staging folder, ``keep`` (worth keeping as ``<target>.partial`` if the run dies).
MANIFEST_NAME = ".meshphase.json"
#: Suffix of the folder that keeps what an unfinished run had done (a campaign's finished
#: recordings, for ``--resume``): ``<output folder>.partial``.
PARTIAL_SUFFIX = ".partial"
#: A staging folder, an old folder set aside or a swap journal of a writer on ANOTHER host
#: (shared file system) is recovered only after this long [s] without change: that writer may
#: still run. On this host a writer's leftovers are recovered as soon as its process is gone.
STALE_DIR_AGE = 7 * 24 * 3600.0
#: the working names of :class:`OutputDir` next to the output folder (short: any legal
#: output name works): ``.mp-<host>-<pid>-<8 hex>.new`` (the staging folder), ``.old`` (the
#: previous folder set aside during the swap) and ``.swap`` (the swap journal)
_WORK_RE = re.compile(r"^\.mp-(?P<host>[0-9a-f]{4})-(?P<pid>[0-9]{1,10})-(?P<tok>[0-9a-f]{8})"
                      r"\.(?P<kind>new|old|swap)$")
# temporary files of meshphase.io.atomic_path (a killed writer's leftovers are no foreign files)
_TEMP_FILE_RE = re.compile(r"^\.mp-[0-9a-f]{4}-[0-9]{1,10}-[0-9a-f]{8}\.partial$")
# what meshphase versions without a manifest wrote into an output folder (any depth; PNGs in
# a ``figures`` folder): such a folder may be replaced by --overwrite too
_LEGACY_NAME_RE = re.compile(r"^(summary\.json|passes_\w+\.csv|load_sharing\.csv|identified_errors\.csv|"
                             r"tilt\.csv|stages\.csv|arrays\.h5|report\.html|demo_scene\.toml|"
                             r"campaign\.json|campaign\.csv|campaign_report\.html)$")
# staging folder -> published folder, for callers that only kept paths (published_path)
_PUBLISHED: "OrderedDict[str, str]" = OrderedDict()




def _work_name(kind: str, token: str) -> str:
    return f".mp-{host_tag()}-{os.getpid()}-{token}.{kind}"


def _fsync_tree(root: Path) -> None:
    """Every file and folder under ``root`` on disk before ``root`` is renamed into place (the
    writers - pandas, h5py, matplotlib - close their files without fsync)."""
    for dirpath, _dirs, files in os.walk(root, topdown=False):
        for name in files:
            p = os.path.join(dirpath, name)
            if stat.S_ISREG(os.lstat(p).st_mode):
                fsync_path(p)
        fsync_path(dirpath, directory=True)


def _write_json_atomic(path: Path, obj) -> None:
    data = json.dumps(obj, indent=1).encode("utf-8")
    with atomic_path(path, overwrite=True) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(data)


def read_json_object(path, max_bytes: int = 64 * 2**20) -> dict | None:
    """The JSON object in the regular file ``path`` (first ``max_bytes`` bytes), or None when
    it is missing, not a regular file (symlinks are not followed), unreadable or not a JSON
    object: a marker or manifest that cannot be trusted counts as absent."""
    try:
        if not stat.S_ISREG(os.lstat(path).st_mode):
            return None
        with open(path, "rb") as fh:
            m = json.loads(fh.read(max_bytes).decode("utf-8"))
    except (OSError, ValueError):
        return None
    return m if isinstance(m, dict) else None


def _read_manifest(folder) -> dict | None:
    return read_json_object(Path(folder) / MANIFEST_NAME)


def _files_under(root: Path) -> list[str]:
    """Relative POSIX paths of the regular files under ``root`` (no manifest, no temp files)."""
    out = []
    for dirpath, _dirs, files in os.walk(root):
        rel = Path(dirpath).relative_to(root)
        for name in files:
            if name == MANIFEST_NAME and rel == Path(".") or _TEMP_FILE_RE.match(name):
                continue
            if stat.S_ISREG(os.lstat(os.path.join(dirpath, name)).st_mode):
                out.append((rel / name).as_posix())
    return sorted(out)


def foreign_entries(folder, *, limit: int = 5) -> list[str]:
    """What in ``folder`` meshphase did not write (so ``--overwrite`` must not delete it).

    A file is meshphase's when the folder's manifest (:data:`MANIFEST_NAME`, written when the
    folder was published) lists it, or - a folder of a meshphase without manifests - when its
    name is one meshphase writes (``summary.json``, ``passes_<gauge>.csv``, ``arrays.h5``,
    ``campaign.json``, ..., PNGs in a ``figures`` folder). Symbolic links, FIFOs, devices and
    sockets are never meshphase's. Symbolic links are not followed.

    Parameters
    ----------
    folder : str or Path
        An existing folder.
    limit : int
        Stop after this many entries.

    Returns
    -------
    list of str
        Relative paths (at most ``limit``), a symbolic link as ``"name (symbolic link to
        TARGET)"``; empty when everything is meshphase's.
    """
    folder = Path(folder)
    manifest = _read_manifest(folder)
    listed = set(manifest.get("files") or []) if manifest is not None else None
    bad: list[str] = []
    for dirpath, dirs, files in os.walk(folder):  # followlinks=False: a linked folder is not entered
        rel_dir = Path(dirpath).relative_to(folder)
        for name in sorted(dirs) + sorted(files):
            p = os.path.join(dirpath, name)
            rel = (rel_dir / name).as_posix()
            try:
                mode = os.lstat(p).st_mode
            except OSError:
                continue
            if stat.S_ISLNK(mode):
                try:
                    bad.append(f"{rel} (symbolic link to {os.readlink(p)})")
                except OSError:
                    bad.append(f"{rel} (symbolic link)")
            elif stat.S_ISDIR(mode):
                continue
            elif not stat.S_ISREG(mode):
                bad.append(f"{rel} (not a regular file)")
            elif rel == MANIFEST_NAME or _TEMP_FILE_RE.match(name):
                continue
            elif listed is not None:
                if rel not in listed:
                    bad.append(rel)
            elif not (_LEGACY_NAME_RE.match(name) or (name.endswith(".png") and rel_dir.name == "figures")):
                bad.append(rel)
            if len(bad) >= limit:
                return bad
    return bad


def _link_error(path: Path) -> FileExistsError:
    try:
        target = f" (to {os.readlink(path)})"
    except OSError:
        target = ""
    return FileExistsError(errno.EEXIST, f"is a symbolic link{target}; meshphase never writes through "
                                         "links: give the folder itself, or remove the link", str(path))


def _identity(path: Path) -> tuple:
    st = os.lstat(path)
    return st.st_dev, st.st_ino, st.st_mtime_ns


def _plain_name(name) -> bool:
    return isinstance(name, str) and name not in ("", ".", "..") and "/" not in name and "\\" not in name \
        and "\0" not in name


def _swap_in(stage: Path, dest: Path, token: str, *, reserved: bool = False, snapshot=None) -> None:
    """Put the finished folder ``stage`` at ``dest`` (a sibling), atomically.

    ``dest`` missing, or reserved by this run (empty): one rename (onto an empty folder,
    allowed by POSIX; it fails when another writer put files there). Otherwise a swap with a
    journal: write ``.mp-...swap`` (target, new, old), rename ``dest`` aside to ``.mp-...old``,
    rename ``stage`` to ``dest``, drop the journal, remove the old folder. A crash at any point
    leaves the old or the new complete folder: at ``dest``, or - between the two renames -
    under its working name, which :func:`recover_output_dirs` puts back (rolling forward).
    """
    parent = dest.parent
    if os.path.islink(dest):
        raise _link_error(dest)
    if not os.path.lexists(dest) or reserved:
        try:
            os.rename(stage, dest)
        except OSError as exc:
            if exc.errno in (errno.ENOTEMPTY, errno.EEXIST):
                raise FileExistsError(errno.EEXIST, "another writer put files into the folder reserved "
                                                    "for this run; nothing replaced", str(dest)) from None
            raise
        fsync_path(parent, directory=True)
        return
    if not os.path.isdir(dest):
        raise NotADirectoryError(errno.ENOTDIR, "exists and is not a folder; nothing replaced", str(dest))
    if snapshot is not None and _identity(dest) != snapshot:
        raise FileExistsError(errno.EEXIST, "was changed by another writer while this run ran; "
                                            "nothing replaced", str(dest))
    journal = parent / _work_name("swap", token)
    aside = parent / _work_name("old", token)
    _write_json_atomic(journal, {"target": dest.name, "new": stage.name, "old": aside.name})
    try:
        os.rename(dest, aside)
        try:
            os.rename(stage, dest)
        except BaseException:
            os.rename(aside, dest)
            raise
        fsync_path(parent, directory=True)
    finally:
        with contextlib.suppress(OSError):
            os.unlink(journal)
    shutil.rmtree(aside, ignore_errors=True)  # a leftover is removed by the next recovery
    fsync_path(parent, directory=True)


def _rename_to_free(stage: Path, base: Path) -> Path:
    """Put the finished folder ``stage`` at the first free one of ``base``, ``base-2``, ...
    (:func:`free_output_name`: another writer may have taken a name while this run ran);
    returns where."""
    for _ in range(100):
        dest = free_output_name(base)
        try:
            os.rename(stage, dest)
        except OSError as exc:
            if exc.errno not in (errno.ENOTEMPTY, errno.EEXIST):
                raise
            continue
        fsync_path(dest.parent, directory=True)
        return dest
    raise FileExistsError(errno.EEXIST, "no free output folder name after 100 tries",  # pragma: no cover
                          str(base))


def _keep_as_partial(stage: Path, dest: Path, token: str) -> None:
    """Put the unfinished ``stage`` at ``dest`` (``<folder>.partial``), replacing an older one
    only when that holds nothing but meshphase's files (it may be a folder of the user's)."""
    if os.path.lexists(dest):
        if os.path.islink(dest) or not os.path.isdir(dest):
            raise FileExistsError(errno.EEXIST, "exists and is not a meshphase folder", str(dest))
        foreign = foreign_entries(dest, limit=1)
        if foreign:
            raise FileExistsError(errno.EEXIST, f"holds {foreign[0]}, not written by meshphase", str(dest))
    _write_json_atomic(stage / MANIFEST_NAME, {**(_read_manifest(stage) or {}), "state": "partial",
                                               "target": dest.name[:-len(PARTIAL_SUFFIX)],
                                               "files": _files_under(stage)})
    _fsync_tree(stage)
    _swap_in(stage, dest, token)


def remove_partial(folder) -> bool:
    """Remove ``<folder>.partial`` when it is meshphase's (its manifest says "partial" and it
    holds nothing else); True when removed."""
    partial = Path(os.path.abspath(folder) + PARTIAL_SUFFIX)
    if os.path.islink(partial) or not partial.is_dir():
        return False
    if (_read_manifest(partial) or {}).get("state") != "partial" or foreign_entries(partial, limit=1):
        return False
    shutil.rmtree(partial, ignore_errors=True)
    return not partial.exists()


def recover_output_dirs(parent) -> list[str]:
    """Finish or undo what writers that died left next to their output folders in ``parent``.

    For each working name of :class:`OutputDir` whose writer is gone (this host: its process
    no longer runs; another host: :data:`STALE_DIR_AGE` without change):

    * a swap journal (``.mp-...swap``): the output folder missing means the writer died
      between its two renames; the new folder (complete: it is renamed only when finished) is
      renamed into place, else the old one back; then the old folder is removed;
    * a staging folder (``.mp-...new``): removed, unless its run marked it worth keeping
      (:meth:`OutputDir.mark_partial`): then it becomes ``<target>.partial`` (replacing an
      older one);
    * an old folder set aside (``.mp-...old``) without journal: the swap had finished;
      removed.

    Called by :class:`OutputDir` before it reserves a folder. Never follows symbolic links,
    never touches other names. Errors (a read-only folder ...) are logged, not raised.

    Parameters
    ----------
    parent : str or Path

    Returns
    -------
    list of str
        One line per action taken.
    """
    parent = Path(parent)
    host, now = host_tag(), time.time()
    try:
        entries = [e for e in os.scandir(parent) if _WORK_RE.match(e.name)]
    except OSError:
        return []
    done: list[str] = []

    def gone(entry) -> bool:
        m = _WORK_RE.match(entry.name)
        if m["host"] == host:
            return int(m["pid"]) != os.getpid() and not pid_alive(int(m["pid"]))
        try:
            return now - entry.stat(follow_symlinks=False).st_mtime > STALE_DIR_AGE
        except OSError:
            return False

    def is_dir(p: Path) -> bool:
        return p.is_dir() and not p.is_symlink()

    dead = [e for e in entries if gone(e)]
    try:
        for e in (e for e in dead if e.name.endswith(".swap")):
            try:
                with open(e.path, "rb") as fh:
                    j = json.loads(fh.read(65536).decode("utf-8"))
                target, new, old = j["target"], j["new"], j["old"]
                if not (_plain_name(target) and _WORK_RE.match(new) and new.endswith(".new")
                        and _WORK_RE.match(old) and old.endswith(".old")):
                    raise ValueError("unexpected names")
            except (OSError, ValueError, KeyError, TypeError) as exc:
                logger.warning("%s: unreadable swap journal left alone (%s)", e.path, exc)
                continue
            t, n, o = parent / target, parent / new, parent / old
            if not os.path.lexists(t):
                if is_dir(n):
                    os.rename(n, t)
                    done.append(f"{t}: finished an interrupted replacement (new folder put in place)")
                elif is_dir(o):
                    os.rename(o, t)
                    done.append(f"{t}: undid an interrupted replacement (old folder put back)")
            if is_dir(o):
                shutil.rmtree(o, ignore_errors=True)
            os.unlink(e.path)
        for e in dead:
            p = Path(e.path)
            if e.name.endswith(".swap") or not is_dir(p):
                continue
            man = _read_manifest(p) if e.name.endswith(".new") else None
            target = (man or {}).get("target")
            if man and man.get("keep") and _plain_name(target):
                dest = parent / (target + PARTIAL_SUFFIX)
                try:
                    _keep_as_partial(p, dest, _WORK_RE.match(e.name)["tok"])
                    done.append(f"{dest}: kept the partial results of a run that died")
                    continue
                except FileExistsError as exc:
                    logger.warning("%s: the partial results of a run that died are dropped: %s", p, exc)
                shutil.rmtree(p, ignore_errors=True)
            else:
                shutil.rmtree(p, ignore_errors=True)
                done.append(f"{p}: removed the working folder of a run that died")
    except OSError as exc:
        logger.warning("%s: could not recover the leftovers of an earlier run: %s", parent, exc)
    for line in done:
        logger.info("%s", line)
    return done


def published_path(path) -> Path:
    """Where a path inside an :class:`OutputDir` staging folder is after publishing (for a
    caller that kept only paths); other paths are returned unchanged."""
    p = Path(path)
    for stage, final in reversed(_PUBLISHED.items()):
        try:
            return Path(final) / p.relative_to(stage)
        except ValueError:
            continue
    return p


def free_output_name(base: Path) -> Path:
    """``base`` if nothing is there (not even a dangling link), else the first free one of
    ``base-2``, ``base-3``, ...; nothing is created."""
    base = Path(base)
    if not os.path.lexists(base):
        return base
    i = 2
    while os.path.lexists(f"{base}-{i}"):
        i += 1
    return Path(f"{base}-{i}")


def new_output_dir(base: Path, *, overwrite: bool = False) -> Path:
    """``base`` if it does not exist (or ``overwrite``), else ``base-2``, ``base-3``, ...:
    a run never overwrites an earlier one unless asked."""
    base = Path(base)
    if overwrite or not base.exists():
        base.mkdir(parents=True, exist_ok=True)
        return base
    out = free_output_name(base)
    out.mkdir(parents=True)
    return out


def _own_stage(p: Path) -> bool:
    """Whether the staging folder ``p`` is this process's: empty (made, no manifest yet) or its
    manifest names this process."""
    try:
        if not os.listdir(p):
            return True
        with open(p / MANIFEST_NAME, encoding="utf-8") as fh:
            return json.load(fh).get("pid") == os.getpid()
    except (OSError, ValueError, AttributeError):
        return False


class OutputDir:
    """A run's output folder, written whole or not at all.

    ``with OutputDir(base, overwrite=...) as out:`` picks the output folder up front
    (``base``, else ``base-2``, ...; with ``overwrite`` an existing ``base``) and creates its
    staging folder beside it, so an unwritable location fails in a second, not after the
    processing. The run writes into ``out.path``: a new, empty staging folder with a short
    name (``.mp-<host>-<pid>-<hex>.new``) - always with ``overwrite`` or ``staged=True``. With
    ``staged=True`` and a new folder nothing is created under the final name until the
    results are complete (a run killed before leaves no empty folder there, and the next run
    gets the same name); should another run have taken it meanwhile, the results go to the
    next free name (:attr:`final` says which). With ``staged=None`` (the default) and a new
    folder, the folder is created (reserved) at once and ``out.path`` is that
    folder itself (callers that return the paths they wrote keep working; it is removed
    whole if the run fails, but a process killed mid-write leaves it half written: give
    ``staged=True`` and map paths with :meth:`published`). When the body returns, every file
    in it is fsync'ed, a manifest (:data:`MANIFEST_NAME`: the files written) is added, and the
    staging folder replaces the output folder atomically (a rename to the new name, or onto
    the empty reserved folder, or - ``overwrite`` (:func:`_swap_in`) - rename the old folder
    aside, rename the new one in, remove the old one; a crash at any point leaves the old or
    the new complete folder). No stale file of an earlier run survives an overwrite.

    While the folder is open, SIGTERM and SIGHUP (at their default action) raise
    ``SystemExit(128 + signum)`` in the main thread, so a terminated run unwinds as an
    interrupted one does (exit 143 for SIGTERM). If the body raises (an error,
    ``KeyboardInterrupt``, that ``SystemExit``), the staging folder is removed and
    the output folder is as before (a reserved folder removed again); after
    :meth:`mark_partial` it is kept as ``<output folder>.partial`` instead. :meth:`discard`
    removes it on request (a run with nothing usable writes nothing).

    Symbolic links: a link at the output path is refused (FileExistsError), never written
    through, in every mode; ``overwrite`` refuses a folder holding a link, a special file or
    any file meshphase did not write (:func:`foreign_entries`: ``meshphase run scene.toml
    --out . --overwrite`` must not delete the scene), and never deletes anything outside the
    folder. What a killed writer left beside its folder is recovered on the next use of the
    same parent folder (:func:`recover_output_dirs`).

    Parameters
    ----------
    base : str or Path
        The output folder.
    overwrite : bool
        Replace ``base`` if it exists (else ``base-2``, ...).
    staged : bool or None
        Write into a staging folder also when the output folder is new (see above).

    Attributes
    ----------
    path : Path
        Where the run writes (after ``__enter__``).
    final : Path
        The output folder the results will have (``base``, ``base-2``, ...).
    partial_path : Path or None
        Where unfinished results were kept (:meth:`mark_partial`), once the run failed.
    """

    def __init__(self, base, *, overwrite: bool = False, staged: bool | None = None):
        if not isinstance(base, (str, os.PathLike)):
            raise TypeError(f"base must be a path (str or Path), got {type(base).__name__} {base!r}")
        if not os.fspath(base):
            raise ValueError(f"base must be a folder path, got an empty path {base!r}")
        if staged is not None and not isinstance(staged, bool):
            raise TypeError(f"staged must be None or a bool, got {type(staged).__name__} {staged!r}")
        # absolute: the staging folder goes into the parent ("." and ".." have none of their own)
        self.base = Path(os.path.abspath(base))
        self.overwrite = bool(overwrite)
        self.staged = staged
        self.path: Path | None = None
        self.final: Path | None = None
        self.partial_path: Path | None = None
        self._token = ""
        self._reserved = False
        self._snapshot = None
        self._keep = False
        self._fresh = False
        self._signals = None
        self._state = "new"

    def __enter__(self) -> "OutputDir":
        # the guard comes first: a SIGTERM between a folder's creation (the reserved name, the
        # staging folder) and the guard would end the process at the default action and
        # leave that folder behind
        self._signals = SignalGuard().__enter__()
        self._making = None
        try:
            return self._open()
        except BaseException:
            # a signal raises SystemExit wherever the main thread is: between the staging
            # folder's mkdir and the code that would remove it on failure, too
            if self._making is not None and self._state != "open" and _own_stage(self._making):
                shutil.rmtree(self._making, ignore_errors=True)
            self._signals.__exit__(None, None, None)
            self._signals = None
            raise

    def _open(self) -> "OutputDir":
        base = self.base
        if os.path.islink(base):
            raise _link_error(base)
        if os.path.lexists(base) and not base.is_dir():
            raise NotADirectoryError(errno.ENOTDIR, "exists and is not a folder", str(base))
        if base.parent.is_dir():
            recover_output_dirs(base.parent)
        if self.overwrite and base.is_dir():
            try:
                cwd = os.getcwd()
            except OSError:
                cwd = None
            if cwd is not None and (cwd == str(base) or cwd.startswith(str(base).rstrip(os.sep) + os.sep)):
                raise ValueError(f"{base}: --overwrite cannot replace the current folder (or one it is "
                                 "in); run from elsewhere or choose another output folder")
            foreign = foreign_entries(base)
            if foreign:
                raise FileExistsError(
                    errno.EEXIST, "--overwrite replaces the whole folder, and it holds "
                    + ", ".join(foreign) + (", ..." if len(foreign) >= 5 else "")
                    + ", not written by meshphase: move that away or choose another output folder",
                    str(base))
            self.final = base
            self._snapshot = _identity(base)
        elif self.staged:
            # the final name appears only when the results are complete (publish): a run
            # killed before leaves no empty folder under it, only its staging folder,
            # which the next run's recover_output_dirs removes
            try:
                os.makedirs(base.parent, exist_ok=True)
            except (FileExistsError, NotADirectoryError):    # a part of the path is a file
                raise NotADirectoryError(errno.ENOTDIR, os.strerror(errno.ENOTDIR), str(base)) from None
            self.final = free_output_name(base)
            self._fresh = True
        else:
            self.final = Path(new_output_dir(base, overwrite=self.overwrite))
            self._reserved = True
        if self.staged is False and not (self._reserved or self._fresh):
            raise ValueError(f"{base}: replacing an existing folder needs a staging folder (staged=False "
                             "applies to a new folder only)")
        if self.staged or not self._reserved:
            try:
                self.path = self._make_stage()
            except BaseException:
                if self._reserved:
                    with contextlib.suppress(OSError):
                        os.rmdir(self.final)
                raise
        else:  # a new folder, filled in place (see the class notes)
            self.path = self.final
        self._state = "open"
        return self

    @property
    def is_staged(self) -> bool:
        """True when the run writes into a staging folder (:attr:`path` is not :attr:`final`)."""
        return self.path is not None and self.path != self.final

    def _make_stage(self) -> Path:
        parent = self.final.parent
        for _ in range(100):
            self._token = secrets.token_hex(4)
            p = parent / _work_name("new", self._token)
            self._making = p                 # named before it exists: __enter__ removes it on any exit
            try:
                os.mkdir(p)
            except FileExistsError:
                self._making = None          # another run's folder (a 32-bit token collision)
                continue
            except OSError as exc:      # the output folder's name, not the working name, in the message
                self._making = None
                raise OSError(exc.errno, exc.strerror, str(self.final)) from None
            break
        else:  # pragma: no cover - 100 collisions of 32 random bits
            raise FileExistsError(errno.EEXIST, "no free staging folder name after 100 tries", str(parent))
        try:
            self._write_stage_manifest(p)
        except BaseException:
            shutil.rmtree(p, ignore_errors=True)
            raise
        return p

    def _write_stage_manifest(self, p: Path) -> None:
        _write_json_atomic(p / MANIFEST_NAME, {"meshphase_output": 1, "state": "staging",
                                               "target": self.final.name, "keep": self._keep,
                                               "pid": os.getpid(), "host": socket.gethostname()})

    def __exit__(self, exc_type, exc, tb) -> bool:
        try:
            if self._state != "open":
                return False
            if exc_type is None:
                try:
                    self.publish()
                except BaseException:
                    self._fail()
                    raise
            else:
                self._fail()
            return False
        finally:
            if self._signals is not None:
                self._signals.__exit__(None, None, None)
                self._signals = None

    def published(self, path) -> Path:
        """Where ``path`` (inside :attr:`path`) is once the folder is published; other paths
        are returned unchanged."""
        p = Path(path)
        if self.path is None:
            return p
        try:
            return self.final / p.relative_to(self.path)
        except ValueError:
            return p

    def mark_partial(self) -> None:
        """The staging folder holds results worth keeping if the run does not finish: then
        it becomes ``<output folder>.partial`` (also when the process is killed: the next
        :func:`recover_output_dirs` of this parent folder does it) instead of being removed."""
        if self._state != "open" or self._keep or not self.is_staged:
            return
        self._keep = True
        self._write_stage_manifest(self.path)

    def _manifest(self, state: str) -> dict:
        return {"meshphase_output": 1, "state": state, "target": self.final.name,
                "meshphase": __version__, "written": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                "files": _files_under(self.path)}

    def publish(self) -> Path:
        """Make the staging folder the output folder (``__exit__`` does this when the body
        returns). Returns :attr:`final`."""
        if self._state != "open":
            raise RuntimeError(f"{self.base}: output folder not open (state {self._state})")
        _fsync_tree(self.path)
        _write_json_atomic(self.path / MANIFEST_NAME, self._manifest("complete"))
        if not self.is_staged:
            self._state = "published"
            return self.final
        if self._fresh:
            self.final = _rename_to_free(self.path, self.base)
        else:
            _swap_in(self.path, self.final, self._token, reserved=self._reserved, snapshot=self._snapshot)
        _PUBLISHED[str(self.path)] = str(self.final)
        while len(_PUBLISHED) > 64:
            _PUBLISHED.popitem(last=False)
        self._state = "published"
        return self.final

    def _fail(self) -> None:
        if self._keep and self.is_staged and self.path.is_dir():
            dest = self.final.with_name(self.final.name + PARTIAL_SUFFIX)
            try:
                _keep_as_partial(self.path, dest, self._token)
            except OSError as exc:
                logger.warning("%s: could not keep the partial results (%s); removed", dest, exc)
            else:
                self.partial_path = dest
                logger.warning("%s: the run did not finish; what it had done is kept in %s",
                               self.final, dest)
                if self._reserved:
                    with contextlib.suppress(OSError):
                        os.rmdir(self.final)
                self._state = "kept"
                return
        self.discard()

    def discard(self) -> None:
        """Drop what this run wrote (the staging folder; the reserved output folder too when
        this run created it); the output folder of an ``overwrite`` stays as it was."""
        if self._state not in ("open",):
            return
        if self.is_staged:
            shutil.rmtree(self.path, ignore_errors=True)
        elif self._reserved and self.path is not None:  # a new folder filled in place: ours whole
            shutil.rmtree(self.path, ignore_errors=True)
        if self._reserved and self.final is not None:
            with contextlib.suppress(OSError):
                os.rmdir(self.final)  # only when empty: never deletes anything else
        self._state = "discarded"
