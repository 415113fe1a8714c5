"""Safe writes: O_EXCL temporary files with short names, fsync, one winner among concurrent
writers, cleanup on every exit path (exceptions, SIGTERM/SIGINT; SIGKILL's leftover on the
next write), and a clean OSError with nothing left behind when the disk is full."""

from __future__ import annotations

import errno
import multiprocessing as mp
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import meshphase.io as pio
from meshphase.io import atomic
from meshphase.io.atomic import TEMP_SUFFIX, atomic_path, clean_stale_partials
from meshphase.recording import ChannelSpec, Recording

pytestmark = pytest.mark.timeout(120)

FORMATS = [("hdf5", "h5"), ("mcap", "mcap"), ("csv", "csv")]


def _rec(n=2000, n_channels=2, seed=0):
    data = np.random.default_rng(seed).standard_normal((n, n_channels)) * 1e-5
    return Recording(data, 5120.0, [ChannelSpec(name=f"sun_{j}", kind="sun", units="m/m")
                                    for j in range(n_channels)])


def _partials(d):
    return sorted(p.name for p in Path(d).iterdir() if p.name.endswith(TEMP_SUFFIX))


def _temp_name(pid, tag="deadbeef"):
    return f".mp-{atomic.host_tag()}-{pid}-{tag}{TEMP_SUFFIX}"


def _dead_pid():
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


# ---------------------------------------------------------------------------------- names
@pytest.mark.parametrize("fmt, suffix", FORMATS)
def test_longest_legal_output_name_works(tmp_path, fmt, suffix):
    name = "r" * (244 - len(suffix) - 1) + "." + suffix
    assert len(name) == 244
    rec = _rec()
    p = pio.write(rec, tmp_path / name)
    assert pio.read(p) == rec and _partials(tmp_path) == []
    name = "x" * (255 - len(suffix) - 1) + "." + suffix  # NAME_MAX itself
    assert pio.read(pio.write(rec, tmp_path / name)) == rec


def test_temp_file_is_created_exclusively(tmp_path, monkeypatch):
    """A name that exists is never reused (O_EXCL): the next random name is taken."""
    taken = tmp_path / _temp_name(os.getpid(), "00000000")
    taken.write_bytes(b"someone else's")
    tags = iter(["00000000", "00000000", "11111111"])
    monkeypatch.setattr(atomic.secrets, "token_hex", lambda n: next(tags))
    with atomic_path(tmp_path / "out.bin") as tmp:
        assert tmp.name == _temp_name(os.getpid(), "11111111")
        tmp.write_bytes(b"mine")
    assert taken.read_bytes() == b"someone else's"
    assert (tmp_path / "out.bin").read_bytes() == b"mine"


def test_no_free_temp_name_raises(tmp_path, monkeypatch):
    (tmp_path / _temp_name(os.getpid(), "00000000")).write_bytes(b"")
    monkeypatch.setattr(atomic.secrets, "token_hex", lambda n: "00000000")
    with pytest.raises(FileExistsError, match="no free temporary file name"):
        with atomic_path(tmp_path / "out.bin"):
            pass
    assert not (tmp_path / "out.bin").exists()


def test_file_and_directory_are_fsynced(tmp_path, monkeypatch):
    synced = []
    real = os.fsync
    monkeypatch.setattr(atomic.os, "fsync", lambda fd: synced.append(os.readlink(f"/proc/self/fd/{fd}"))
                        or real(fd))
    p = pio.write(_rec(), tmp_path / "s.h5")
    assert synced[0].endswith(TEMP_SUFFIX) and synced[-1] == str(tmp_path)
    assert p.exists() and _partials(tmp_path) == []


def test_temp_replaced_during_write_is_not_published(tmp_path):
    with pytest.raises(OSError, match="removed or replaced during the write"):
        with atomic_path(tmp_path / "out.bin") as tmp:
            tmp.unlink()
            tmp.write_bytes(b"swapped in")
    assert not (tmp_path / "out.bin").exists() and _partials(tmp_path) == []


# ---------------------------------------------------------------------------------- two writers
def _racer(target, text, barrier, results):
    try:
        with atomic_path(target) as tmp:
            tmp.write_text(text)
            barrier.wait(30)  # both have passed the early exists() check and written
        results.put(("ok", text))
    except FileExistsError as exc:
        results.put(("exists", str(exc)))


def test_two_processes_one_output_exactly_one_wins(tmp_path):
    ctx = mp.get_context("fork")
    barrier = ctx.Barrier(2)
    results = ctx.Queue()
    target = tmp_path / "out.txt"
    procs = [ctx.Process(target=_racer, args=(target, t, barrier, results)) for t in ("first", "second")]
    for p in procs:
        p.start()
    got = sorted(results.get(timeout=60) for _ in procs)
    for p in procs:
        p.join(30)
    kinds = [k for k, _ in got]
    assert kinds == ["exists", "ok"]
    winner = next(t for k, t in got if k == "ok")
    assert target.read_text() == winner
    assert "exists (written by another writer while this one ran?); nothing replaced" in got[0][1]
    assert _partials(tmp_path) == []


@pytest.mark.parametrize("fmt, suffix", FORMATS)
def test_two_threads_writing_one_recording_exactly_one_wins(tmp_path, monkeypatch, fmt, suffix):
    barrier = threading.Barrier(2)
    mod = pio.get_format(fmt)
    real = mod.write

    def slow_write(rec, path, **kw):
        real(rec, path, **kw)
        barrier.wait(30)

    monkeypatch.setattr(mod, "write", slow_write)
    target = tmp_path / f"r.{suffix}"
    recs = [_rec(seed=1), _rec(seed=2)]
    out = [None, None]

    def run(i):
        try:
            pio.write(recs[i], target)
            out[i] = "ok"
        except FileExistsError:
            out[i] = "exists"

    threads = [threading.Thread(target=run, args=(i,)) for i in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert sorted(out) == ["exists", "ok"]
    assert pio.read(target) == recs[out.index("ok")]
    assert _partials(tmp_path) == []


def test_overwrite_replaces_atomically(tmp_path):
    target = tmp_path / "r.h5"
    pio.write(_rec(seed=1), target)
    pio.write(_rec(seed=2), target, overwrite=True)
    assert pio.read(target) == _rec(seed=2)
    with pytest.raises(FileExistsError, match="pass overwrite=True"):
        pio.write(_rec(seed=3), target)
    assert _partials(tmp_path) == []


# ---------------------------------------------------------------------------------- leftovers
def test_stale_partials_are_cleaned_and_others_kept(tmp_path):
    now = time.time()
    dead = tmp_path / _temp_name(_dead_pid(), "aaaaaaaa")
    live = tmp_path / _temp_name(os.getppid(), "bbbbbbbb")          # a running process
    old_live = tmp_path / _temp_name(os.getppid(), "cccccccc")
    other_host = tmp_path / ".mp-zzzz-1-dddddddd.partial"            # not our pattern: kept
    foreign_host = tmp_path / f".mp-{'0000' if atomic.host_tag() != '0000' else '1111'}-1-eeeeeeee.partial"
    legacy_old = tmp_path / ".run.h5.k2j4_x9q.partial"
    legacy_new = tmp_path / ".run.h5.abcdefgh.partial"
    unrelated = tmp_path / ".notes.partial"
    for p in (dead, live, old_live, other_host, foreign_host, legacy_old, legacy_new, unrelated):
        p.write_bytes(b"x" * 10)
    for p in (old_live, legacy_old, unrelated):
        os.utime(p, (now - 2 * atomic.STALE_AGE, now - 2 * atomic.STALE_AGE))
    removed = clean_stale_partials(tmp_path)
    assert sorted(p.name for p in removed) == sorted([dead.name, old_live.name, legacy_old.name])
    assert all(p.exists() for p in (live, other_host, foreign_host, legacy_new, unrelated))
    os.utime(foreign_host, (now - 2 * atomic.STALE_AGE,) * 2)  # another host's, by age only
    assert clean_stale_partials(tmp_path) == [foreign_host]
    assert clean_stale_partials(tmp_path / "missing") == []


def test_clean_stale_partials_empty_and_bad_input(tmp_path):
    assert clean_stale_partials(tmp_path) == []
    (tmp_path / _temp_name(os.getppid())).write_bytes(b"")
    assert clean_stale_partials(tmp_path, max_age=0.0, now=time.time() + 1.0) != []  # everything is old
    with pytest.raises(ValueError, match="max_age must be >= 0"):
        clean_stale_partials(tmp_path, max_age=-1.0)
    with pytest.raises(TypeError, match="now"):
        clean_stale_partials(tmp_path, now="today")


_KILLED_WRITER = textwrap.dedent("""
    import sys, time
    from meshphase.io.atomic import atomic_path
    with atomic_path(sys.argv[1]) as tmp:
        tmp.write_bytes(b"x" * 1_000_000)
        print(tmp, flush=True)
        time.sleep(60)
""")


def _start_writer(target, *extra):
    p = subprocess.Popen([sys.executable, "-c", _KILLED_WRITER, str(target), *extra], stdout=subprocess.PIPE,
                         text=True)
    tmp = Path(p.stdout.readline().strip())
    assert tmp.exists() and tmp.stat().st_size == 1_000_000
    return p, tmp


def test_sigkill_leftover_is_removed_by_the_next_write(tmp_path):
    p, tmp = _start_writer(tmp_path / "killed.h5")
    p.kill()
    p.wait(30)
    p.stdout.close()
    assert tmp.exists() and not (tmp_path / "killed.h5").exists()  # what SIGKILL leaves
    pio.write(_rec(), tmp_path / "next.h5")
    assert not tmp.exists() and _partials(tmp_path) == []


# SIGTERM: SystemExit(143); SIGINT: KeyboardInterrupt, after which Python ends itself by SIGINT
@pytest.mark.parametrize("sig, code", [(signal.SIGTERM, 128 + signal.SIGTERM), (signal.SIGINT, -signal.SIGINT)])
def test_sigterm_and_sigint_remove_the_temp_file(tmp_path, sig, code):
    p, tmp = _start_writer(tmp_path / "t.h5")
    p.send_signal(sig)
    rc = p.wait(30)
    p.stdout.close()
    assert rc == code
    assert not tmp.exists() and _partials(tmp_path) == [] and not (tmp_path / "t.h5").exists()


def test_signal_handler_is_restored(tmp_path):
    before = signal.getsignal(signal.SIGTERM)
    with atomic_path(tmp_path / "a") as tmp:
        assert signal.getsignal(signal.SIGTERM) is not before or before is not signal.SIG_DFL
        tmp.write_bytes(b"")
    assert signal.getsignal(signal.SIGTERM) is before


# ---------------------------------------------------------------------------------- disk full
@pytest.mark.parametrize("fmt, suffix", FORMATS)
def test_enospc_in_the_writer_leaves_nothing(tmp_path, monkeypatch, fmt, suffix):
    mod = pio.get_format(fmt)
    real = mod.write

    def full(rec, path, **kw):
        real(rec, path, **kw)  # a partial file exists now
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    monkeypatch.setattr(mod, "write", full)
    with pytest.raises(OSError) as err:
        pio.write(_rec(), tmp_path / f"full.{suffix}")
    assert err.value.errno == errno.ENOSPC
    assert list(tmp_path.iterdir()) == []


def test_enospc_from_fsync_leaves_nothing(tmp_path, monkeypatch):
    """Delayed allocation: the disk-full error may come only when the data are synced."""
    def fsync(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(atomic.os, "fsync", fsync)
    with pytest.raises(OSError) as err:
        pio.write(_rec(), tmp_path / "f.mcap")
    assert err.value.errno == errno.ENOSPC and list(tmp_path.iterdir()) == []


def test_not_enough_space_is_refused_before_writing(tmp_path, monkeypatch):
    real = os.statvfs

    class Tiny:
        def __init__(self, st):
            self.f_bavail, self.f_frsize = 10, st.f_frsize

    monkeypatch.setattr(atomic.os, "statvfs", lambda p: Tiny(real(p)))
    rec = _rec(100_000, 4)
    with pytest.raises(OSError, match=r"not enough free space: the file needs about 3200000 bytes") as err:
        pio.write(rec, tmp_path / "big.h5")
    assert err.value.errno == errno.ENOSPC and list(tmp_path.iterdir()) == []
    pio.write(rec, tmp_path / "big.h5", compression="gzip")  # compressed: size unknown, not refused
    assert pio.read(tmp_path / "big.h5") == rec


# a real, tiny filesystem: HDF5 used to crash the process (exit 139) here
_FULL_DISK = textwrap.dedent("""
    import errno, os, sys
    import numpy as np
    import meshphase.io as pio
    from meshphase.io import atomic
    from meshphase.recording import ChannelSpec, Recording
    fmt, target, preflight = sys.argv[1], sys.argv[2], sys.argv[3] == "1"
    if not preflight:  # make the format's own writer hit ENOSPC
        atomic._check_space = lambda path, size_hint: None
    rec = Recording(np.random.default_rng(0).standard_normal((40_000, 4)), 5120.0,
                    [ChannelSpec(name=f"s{j}", kind="sun", units="m/m") for j in range(4)])
    try:
        pio.write(rec, target)
    except OSError as exc:
        print("errno", exc.errno, type(exc).__name__)
    else:
        print("written")
""")


@pytest.fixture
def tiny_fs(tmp_path):
    d = tmp_path / "tiny"
    d.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(d)], capture_output=True, text=True)
    if r.returncode:
        pytest.skip(f"cannot mount a tmpfs here: {r.stderr.strip()}")
    try:
        yield d
    finally:
        subprocess.run(["umount", str(d)], check=False)


@pytest.mark.parametrize("fmt, suffix, preflight", [(f, s, False) for f, s in FORMATS] + [("hdf5", "h5", True)])
def test_real_full_disk_gives_clean_oserror(tiny_fs, fmt, suffix, preflight):
    """1 MiB tmpfs, 1.28 MB of samples; preflight=False makes the writer itself hit ENOSPC."""
    r = subprocess.run([sys.executable, "-c", _FULL_DISK, fmt, str(tiny_fs / f"out.{suffix}"),
                        "1" if preflight else "0"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]  # no segfault (139), no traceback
    assert r.stdout.strip() == f"errno {errno.ENOSPC} OSError", r.stdout + r.stderr[-2000:]
    assert list(tiny_fs.iterdir()) == []
