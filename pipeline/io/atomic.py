"""Atomic file writes: a temporary file beside the target, fsync'ed, then published.

:func:`atomic_path` yields a new empty temporary file ``.mp-<host>-<pid>-<8 hex>.partial``
next to the output and publishes it (hard link, or rename with ``overwrite``) when the
writer's body returns; on every failure the temporary file is removed and the output is
untouched. :func:`clean_stale_partials` removes the temporary files of writers that died.
The helpers :func:`host_tag`, :func:`pid_alive`, :class:`SignalGuard` and
:data:`WRITE_FULL` are shared with the other writers of temporary files (the run's output
folder).
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import os
import re
import secrets
import signal
import socket
import stat
import threading
import time
from pathlib import Path

from ..runtime.log import logger
from ..validate import as_float, as_nonnegative

__all__ = ["atomic_path", "clean_stale_partials", "TEMP_PREFIX", "TEMP_SUFFIX", "STALE_AGE", "WRITE_FULL",
           "host_tag", "pid_alive", "SignalGuard", "fsync_path"]

#: Temporary files are named ``.mp-<host>-<pid>-<8 hex>.partial`` (at most 33 characters,
#: so any legal output name works): ``host`` is 4 hex digits of a hash of the host name and
#: ``pid`` the writing process, so a later write can tell a dead writer's leftover.
TEMP_PREFIX = ".mp-"
TEMP_SUFFIX = ".partial"
#: A ``.partial`` file not modified for this long [s] is stale whoever wrote it (a writer
#: on another host, a reused PID, a writer of an older meshphase).
STALE_AGE = 3600.0
_TEMP_RE = re.compile(r"^\.mp-(?P<host>[0-9a-f]{4})-(?P<pid>[0-9]{1,10})-[0-9a-f]{8}\.partial$")
# temporary names of meshphase <= 0.1 (tempfile.mkstemp(prefix=".<name>.", suffix=".partial"))
_LEGACY_RE = re.compile(r"^\..+\.[a-z0-9_]{8}\.partial$")
# link() is refused by filesystems without hard links (FAT, some FUSE/SMB mounts)
_NO_LINK = {errno.EPERM, errno.EOPNOTSUPP, errno.ENOTSUP, errno.EMLINK, errno.ENOSYS, errno.EACCES}
# fsync of a directory is refused by some filesystems; the data are already synced then
_NO_FSYNC = {errno.EINVAL, errno.EBADF, errno.EACCES, errno.EPERM, errno.EISDIR, errno.ENOTSUP,
             errno.EROFS}
#: Signals that would end the process without unwinding; while a temporary file is open in
#: the main thread they raise SystemExit(128 + signum) instead, so the file is removed.
_GUARDED_SIGNALS = tuple(getattr(signal, n) for n in ("SIGTERM", "SIGHUP") if hasattr(signal, n))


def host_tag() -> str:
    """Four hex digits of a hash of this host's name: the ``<host>`` of temporary names."""
    return hashlib.blake2s(socket.gethostname().encode("utf-8", "replace"), digest_size=2).hexdigest()


def pid_alive(pid: int) -> bool:
    """Whether process ``pid`` runs on this host (True when it cannot tell: keep its files)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, OSError):
        return True  # exists under another user (or cannot tell): keep its file
    return True


def clean_stale_partials(directory, *, max_age: float = STALE_AGE, now: float | None = None) -> list[Path]:
    """Remove temporary files of writers that died (SIGKILL, power loss) from ``directory``.

    A ``.mp-<host>-<pid>-<hex>.partial`` file is stale when it was made on this host by a
    process that no longer runs, or when it was not modified for ``max_age`` seconds (a
    writer on another host, a reused PID). Files of older meshphase versions
    (``.<name>.<8 chars>.partial``) are removed by age only. Anything else is never touched.
    Called by :func:`atomic_path` on every write, so a killed writer's leftover is removed
    by the next write to the same directory.

    Parameters
    ----------
    directory : str or Path
    max_age : float
        Age [s] after which any matching file is stale (default :data:`STALE_AGE`).
    now : float, optional
        Current time [s since the epoch] (default ``time.time()``).

    Returns
    -------
    list of Path
        The files removed.
    """
    directory = Path(directory)
    max_age = as_nonnegative(max_age, "max_age")
    now = time.time() if now is None else as_float(now, "now")
    host = host_tag()
    removed = []
    try:
        entries = list(os.scandir(directory))
    except OSError:
        return removed
    for entry in entries:
        name = entry.name
        if not name.endswith(TEMP_SUFFIX) or not name.startswith("."):
            continue
        m = _TEMP_RE.match(name)
        if m is None and not _LEGACY_RE.match(name):
            continue
        try:
            st = entry.stat(follow_symlinks=False)
        except OSError:
            continue
        if not stat.S_ISREG(st.st_mode):
            continue
        old = now - st.st_mtime > max_age
        dead = (m is not None and m["host"] == host and int(m["pid"]) != os.getpid()
                and not pid_alive(int(m["pid"])))
        if not (old or dead):
            continue
        try:
            os.unlink(entry.path)
        except OSError as exc:
            logger.debug("could not remove stale temporary file %s: %s", entry.path, exc)
            continue
        logger.info("removed stale temporary file %s (%s)", entry.path,
                    "writer process gone" if dead else f"not modified for {now - st.st_mtime:.0f} s")
        removed.append(Path(entry.path))
    return removed


def _create_temp(directory: Path) -> tuple[Path, int]:
    """Create a new empty temporary file with O_EXCL in ``directory``; (path, fd)."""
    host = host_tag()
    flags = os.O_CREAT | os.O_EXCL | os.O_WRONLY | getattr(os, "O_CLOEXEC", 0)
    for _ in range(100):
        tmp = directory / f"{TEMP_PREFIX}{host}-{os.getpid()}-{secrets.token_hex(4)}{TEMP_SUFFIX}"
        try:
            return tmp, os.open(tmp, flags, 0o666)
        except FileExistsError:
            continue
    raise FileExistsError(errno.EEXIST, f"{directory}: no free temporary file name after 100 tries")


def fsync_path(path, *, directory: bool = False) -> None:
    """fsync a file (opened read-only: enough on Linux) or a folder; refusals of the file
    system (some refuse fsync on folders, read-only descriptors or read-only mounts) are not
    errors."""
    flags = os.O_RDONLY | getattr(os, "O_CLOEXEC", 0) | (getattr(os, "O_DIRECTORY", 0) if directory else 0)
    try:
        fd = os.open(path, flags)
    except OSError as exc:
        if exc.errno in _NO_FSYNC:
            return
        raise
    try:
        os.fsync(fd)
    except OSError as exc:
        if exc.errno not in _NO_FSYNC:
            raise
    finally:
        os.close(fd)


#: errno of a write that failed for want of room: disk full, quota, file too large
WRITE_FULL = {errno.ENOSPC, errno.EDQUOT, errno.EFBIG}


def _check_space(path: Path, size_hint: int | None) -> None:
    """OSError(EROFS) naming ``path`` on a read-only file system, OSError(ENOSPC) when it has
    less free space than ``size_hint`` [B]; nothing when statvfs cannot tell."""
    try:
        st = os.statvfs(path.parent)
    except (OSError, AttributeError):
        return
    if getattr(st, "f_flag", 0) & getattr(os, "ST_RDONLY", 0):
        # read-only: no free space to report (statvfs counts blocks all the same)
        raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(path))
    if not size_hint:
        return
    free = st.f_bavail * st.f_frsize
    if free < size_hint:
        raise OSError(errno.ENOSPC, f"{path}: not enough free space: the file needs about "
                                    f"{size_hint} bytes, {free} bytes are free on {path.parent}")


def _publish(tmp: Path, path: Path, overwrite: bool) -> None:
    """Move the finished temporary file onto ``path``: atomically, and refusing an existing
    ``path`` unless ``overwrite`` (a hard link cannot replace, unlike rename)."""
    if overwrite:
        os.replace(tmp, path)
        return
    try:
        os.link(tmp, path)
    except FileExistsError:
        raise FileExistsError(errno.EEXIST, f"{path}: exists (written by another writer while this one "
                                            f"ran?); nothing replaced; pass overwrite=True to replace it",
                              str(path)) from None
    except OSError as exc:
        if exc.errno not in _NO_LINK:
            raise
        # no hard links on this filesystem: check, then rename (a race with another writer
        # finishing in between is possible here, and only here)
        if os.path.lexists(path):
            raise FileExistsError(errno.EEXIST, f"{path}: exists; pass overwrite=True to replace it",
                                  str(path)) from None
        os.rename(tmp, path)
        return
    os.unlink(tmp)


class SignalGuard:
    """While active in the main thread, SIGTERM/SIGHUP raise SystemExit(128 + signum) where
    they would have killed the process, so ``finally`` blocks run and temporary files go.
    Only signals still at their default action are taken over; handlers are restored."""

    def __init__(self):
        self.saved = {}

    def __enter__(self):
        if threading.current_thread() is not threading.main_thread():
            return self
        for sig in _GUARDED_SIGNALS:
            try:
                if signal.getsignal(sig) is signal.SIG_DFL:
                    signal.signal(sig, self._raise)
                    self.saved[sig] = signal.SIG_DFL
            except (ValueError, OSError):  # not allowed here
                continue
        return self

    @staticmethod
    def _raise(signum, frame):
        raise SystemExit(128 + signum)

    def __exit__(self, *exc):
        for sig, handler in self.saved.items():
            with contextlib.suppress(ValueError, OSError):
                signal.signal(sig, handler)
        self.saved.clear()
        return False


def _name_max(directory: Path) -> int:
    try:
        return int(os.pathconf(directory, "PC_NAME_MAX"))
    except (OSError, ValueError, AttributeError):
        return 255


def _check_target(path: Path, directory: Path, overwrite: bool) -> None:
    """Refuse an output ``path`` before anything is written: its folder must be a folder,
    its name must fit, and an existing entry is replaced only when it is a regular file (or
    a symbolic link: the link itself is replaced, never written through) and ``overwrite``.
    The errors carry ``path`` as their file name; their text does not repeat it."""
    try:
        st_dir = os.stat(directory)
    except FileNotFoundError:
        raise FileNotFoundError(errno.ENOENT, f"folder {directory} does not exist", str(path)) from None
    except OSError as exc:   # ENOTDIR (a part of the path is a file), ELOOP, EACCES, ENAMETOOLONG
        raise type(exc)(exc.errno, exc.strerror, str(path)) from None
    if not stat.S_ISDIR(st_dir.st_mode):
        raise NotADirectoryError(errno.ENOTDIR, f"{directory} is a file, not a folder", str(path))
    n, n_max = len(os.fsencode(path.name)), _name_max(directory)
    if n > n_max:
        raise OSError(errno.ENAMETOOLONG, f"{os.strerror(errno.ENAMETOOLONG)}: the name has {n} bytes, "
                                          f"the file system allows {n_max}", str(path))
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return
    if stat.S_ISDIR(st.st_mode) or (stat.S_ISLNK(st.st_mode) and path.is_dir()):
        raise IsADirectoryError(errno.EISDIR, "is a directory", str(path))
    if not overwrite:
        raise FileExistsError(errno.EEXIST, "exists; pass overwrite=True to replace it", str(path))
    if not (stat.S_ISREG(st.st_mode) or stat.S_ISLNK(st.st_mode)):
        kind = ("a FIFO (named pipe)" if stat.S_ISFIFO(st.st_mode) else
                "a device" if stat.S_ISCHR(st.st_mode) or stat.S_ISBLK(st.st_mode) else
                "a socket" if stat.S_ISSOCK(st.st_mode) else "not a regular file")
        raise FileExistsError(errno.EEXIST, f"is {kind}; overwrite replaces regular files only, "
                                            "nothing replaced", str(path))


@contextlib.contextmanager
def atomic_path(path, *, overwrite: bool = False, size_hint: int | None = None):
    """Yield a new empty temporary file next to ``path``; on success publish it as ``path``.

    1. Stale temporary files of dead writers in the target directory are removed
       (:func:`clean_stale_partials`).
    2. The temporary file ``.mp-<host>-<pid>-<8 hex>.partial`` is created with
       ``O_CREAT | O_EXCL`` in the target directory (short name: any legal output name
       works) and yielded as a Path; the caller's writer opens it by name and writes.
    3. When the body returns: the file is fsync'ed, checked to be still the file created in
       2, and published: ``overwrite=False`` hard-links it to ``path``, which fails with
       FileExistsError when ``path`` exists by then (two writers to one output: exactly one
       wins, the other's data are dropped); ``overwrite=True`` renames it over ``path``
       (atomic). Then the directory is fsync'ed.

    On every failure (an exception, KeyboardInterrupt, SIGTERM or SIGHUP in the main thread,
    which raise SystemExit(143) / SystemExit(129) here) the temporary file is removed and
    ``path`` is untouched. After SIGKILL or a power loss the temporary file stays until the
    next write to the same directory removes it.

    Parameters
    ----------
    path : str or Path
        Output file.
    overwrite : bool
        Replace an existing ``path`` (default False: FileExistsError, checked before writing
        and again, atomically, when publishing).
    size_hint : int, optional
        Expected file size [B]; OSError(ENOSPC) before anything is written when the
        filesystem has less free space.

    Raises
    ------
    FileExistsError
        ``path`` exists and not ``overwrite``; or, with ``overwrite``, ``path`` is a FIFO,
        device or socket (overwrite replaces regular files, and a symbolic link itself).
    FileNotFoundError
        The directory of ``path`` does not exist.
    NotADirectoryError
        The directory of ``path`` is a file (or a part of its path is).
    IsADirectoryError
        ``path`` is a directory.
    OSError
        ENAMETOOLONG (the name is longer than the file system allows), ELOOP, EACCES, EROFS
        (a read-only file system; checked before anything is written); from the filesystem
        while writing (ENOSPC: disk full, EDQUOT, EFBIG), with nothing left behind. Every
        error carries ``path`` as its file name.
    """
    path = Path(path)
    directory = path.parent
    _check_target(path, directory, overwrite)
    clean_stale_partials(directory)
    _check_space(path, size_hint)
    with SignalGuard():
        tmp, fd = _create_temp(directory)
        try:
            created = os.fstat(fd)
            try:
                yield tmp
                os.fsync(fd)
            except OSError as exc:
                if exc.errno not in WRITE_FULL or exc.filename == str(path):
                    raise
                # the writer's error names the temporary file, or nothing (h5py, mcap): the
                # file the caller asked for is the one to name
                raise OSError(exc.errno, os.strerror(exc.errno), str(path)) from exc
            try:
                now = os.lstat(tmp)
            except FileNotFoundError:
                now = None
            if now is None or (now.st_dev, now.st_ino) != (created.st_dev, created.st_ino) \
                    or not stat.S_ISREG(now.st_mode):
                raise OSError(errno.ESTALE, f"{tmp}: the temporary file was removed or replaced during "
                                            f"the write; {path} not written")
            os.close(fd)
            fd = -1
            _publish(tmp, path, overwrite)
            tmp = None
            fsync_path(directory, directory=True)
        finally:
            if fd >= 0:
                os.close(fd)
            if tmp is not None:
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(tmp)
