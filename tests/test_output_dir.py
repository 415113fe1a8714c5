"""The output-folder guard (meshphase.run.outdir.OutputDir): written whole or not at all.

``--overwrite`` builds the new folder beside the old one and swaps it in (rename aside, rename
in, remove the old one; a journal makes a crash between the renames recoverable), never writes
through a symbolic link, never deletes anything outside the folder and refuses a folder that
holds files meshphase did not write. No cluster, no processing: plain files, so the module
runs in about a second. Crashes are real processes killed with SIGKILL, or the working names a
killed writer leaves, made by hand with the PID of a process that has exited.
"""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import meshphase.run.outdir as ex
from meshphase.run.outdir import (MANIFEST_NAME, PARTIAL_SUFFIX, OutputDir, foreign_entries,
                                  published_path, recover_output_dirs)


def _tree(folder: Path) -> dict[str, bytes]:
    """Every regular file under ``folder`` (relative path -> bytes); links are not followed."""
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and not p.is_symlink()}


def _publish(base: Path, files: dict[str, str], **kw) -> Path:
    with OutputDir(base, staged=True, **kw) as out:
        for rel, text in files.items():
            p = out.path / rel
            p.parent.mkdir(parents=True, exist_ok=True)
            p.write_text(text)
    return out.final


def _dead_pid() -> int:
    """The PID of a process that has exited (reaped): what a killed writer leaves behind."""
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def _work(parent: Path, pid: int, token: str, kind: str) -> Path:
    return parent / f".mp-{ex.host_tag()}-{pid}-{token}.{kind}"


# ---------------------------------------------------------------------------- the swap
def test_overwrite_swaps_the_whole_folder_no_stale_file(tmp_path):
    base = tmp_path / "out"
    _publish(base, {"summary.json": "old", "report.html": "old page", "figures/a.png": "png"})
    assert json.loads((base / MANIFEST_NAME).read_text())["files"] == ["figures/a.png", "report.html",
                                                                        "summary.json"]
    with OutputDir(base, overwrite=True) as out:
        assert out.path != base and out.path.parent == tmp_path and len(out.path.name) < 40
        (out.path / "summary.json").write_text("new")
        assert (base / "report.html").read_text() == "old page"  # untouched while the run runs
    assert out.final == base
    assert _tree(base) == {MANIFEST_NAME: (base / MANIFEST_NAME).read_bytes(), "summary.json": b"new"}
    assert sorted(os.listdir(tmp_path)) == ["out"]  # no staging or old folder left
    assert out.published(out.path / "summary.json") == base / "summary.json"
    assert published_path(out.path / "summary.json") == base / "summary.json"
    assert published_path(tmp_path / "elsewhere") == tmp_path / "elsewhere"


def test_new_folder_never_overwritten_and_staged_fresh_folder(tmp_path):
    base = tmp_path / "out"
    _publish(base, {"a.txt": "1"})
    second = _publish(base, {"a.txt": "2"})
    assert second == tmp_path / "out-2" and (base / "a.txt").read_text() == "1"
    # the default for a new folder (staged=None): filled in place, as before
    with OutputDir(tmp_path / "inplace") as out:
        assert out.path == out.final == tmp_path / "inplace" and not out.is_staged
        (out.path / "summary.json").write_text("{}")
    assert "summary.json" in json.loads((tmp_path / "inplace" / MANIFEST_NAME).read_text())["files"]


def test_failure_mid_write_leaves_the_previous_folder_intact(tmp_path):
    base = tmp_path / "out"
    _publish(base, {"summary.json": "old", "sub/x.csv": "1,2"})
    before = _tree(base)
    for exc in (OSError(errno.ENOSPC, "No space left on device"), KeyboardInterrupt()):
        with pytest.raises(type(exc)):
            with OutputDir(base, overwrite=True) as out:
                (out.path / "summary.json").write_text("{")  # half written when it fails
                raise exc
        assert _tree(base) == before
        assert sorted(os.listdir(tmp_path)) == ["out"]


def test_failure_during_the_swap_rolls_back(tmp_path, monkeypatch):
    """The rename of the new folder into place fails (after the old one was set aside): the
    old one is put back, nothing else is left."""
    base = tmp_path / "out"
    _publish(base, {"summary.json": "old"})
    before = _tree(base)
    real = os.rename

    def failing(src, dst, *a, **k):
        if str(src).endswith(".new") and Path(dst) == base:
            raise OSError(errno.EIO, "Input/output error", str(dst))
        return real(src, dst, *a, **k)

    monkeypatch.setattr(ex.os, "rename", failing)
    with pytest.raises(OSError, match="Input/output"):
        with OutputDir(base, overwrite=True) as out:
            (out.path / "summary.json").write_text("new")
    assert _tree(base) == before
    assert sorted(os.listdir(tmp_path)) == ["out"]


def test_discard_and_reserved_folder(tmp_path):
    with OutputDir(tmp_path / "a", staged=True) as out:
        (out.path / "f").write_text("x")
        out.discard()
    assert os.listdir(tmp_path) == []
    base = _publish(tmp_path / "b", {"f": "1"})
    with OutputDir(base, overwrite=True) as out:
        out.discard()  # a run with nothing usable: the previous results stay
    assert (base / "f").read_text() == "1" and sorted(os.listdir(tmp_path)) == ["b"]


# ---------------------------------------------------------------------------- links
def test_symlinked_output_folder_is_refused_in_every_mode(tmp_path):
    real = _publish(tmp_path / "real", {"summary.json": "theirs"})
    link = tmp_path / "link"
    link.symlink_to(real, target_is_directory=True)
    dangling = tmp_path / "dangling"
    dangling.symlink_to(tmp_path / "nowhere")
    for path in (link, dangling):
        for kw in ({}, {"overwrite": True}, {"overwrite": True, "staged": True}):
            with pytest.raises(FileExistsError, match="symbolic link.*never writes through"):
                with OutputDir(path, **kw):
                    pass
    assert (real / "summary.json").read_text() == "theirs"
    assert not (tmp_path / "nowhere").exists()
    assert sorted(os.listdir(tmp_path)) == ["dangling", "link", "real"]


def test_symlink_inside_the_folder_is_refused_never_written_through(tmp_path):
    base = _publish(tmp_path / "out", {"report.html": "old"})
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    (base / "summary.json").symlink_to(victim)
    with pytest.raises(FileExistsError, match=r"summary\.json \(symbolic link to .*victim\.txt\)"):
        with OutputDir(base, overwrite=True) as out:
            (out.path / "summary.json").write_text("new")
    assert victim.read_text() == "precious"
    assert (base / "summary.json").is_symlink() and (base / "report.html").read_text() == "old"
    # a linked sub-folder is not entered either
    (base / "summary.json").unlink()
    (base / "figures").symlink_to(tmp_path, target_is_directory=True)
    assert foreign_entries(base) == [f"figures (symbolic link to {tmp_path})"]


def test_overwrite_refuses_foreign_files_and_a_file_at_the_path(tmp_path):
    base = tmp_path / "out"
    base.mkdir()
    (base / "recording.h5").write_bytes(b"\x89HDF")  # e.g. --out . --overwrite next to the data
    with pytest.raises(FileExistsError, match=r"holds recording\.h5.*not written by meshphase"):
        with OutputDir(base, overwrite=True):
            pass
    assert os.listdir(base) == ["recording.h5"] and sorted(os.listdir(tmp_path)) == ["out"]
    f = tmp_path / "file"
    f.write_text("x")
    with pytest.raises(NotADirectoryError, match="not a folder"):
        with OutputDir(f, overwrite=True):
            pass


def test_foreign_entries_legacy_folder_empty_and_fifo(tmp_path):
    """A folder written before manifests existed may be replaced when it holds only names
    meshphase writes; an empty folder too; a FIFO never."""
    legacy = tmp_path / "legacy"
    (legacy / "figures").mkdir(parents=True)
    (legacy / "run1").mkdir()
    for rel in ("summary.json", "passes_sun.csv", "arrays.h5", "report.html", "figures/x.png",
                "run1/summary.json", "campaign.json"):
        (legacy / rel).write_text("x")
    assert foreign_entries(legacy) == []
    (legacy / "notes.txt").write_text("mine")
    assert foreign_entries(legacy) == ["notes.txt"]
    empty = tmp_path / "empty"
    empty.mkdir()
    assert foreign_entries(empty) == []
    os.mkfifo(empty / "pipe")
    assert foreign_entries(empty) == ["pipe (not a regular file)"]


def test_output_dir_bad_input():
    with pytest.raises(TypeError, match="base"):
        OutputDir(3)
    with pytest.raises(ValueError, match="empty path"):
        OutputDir("")
    with pytest.raises(TypeError, match="staged"):
        OutputDir("x", staged="yes")


def test_staged_false_cannot_replace(tmp_path):
    base = _publish(tmp_path / "out", {"f": "1"})
    with pytest.raises(ValueError, match="staging folder"):
        with OutputDir(base, overwrite=True, staged=False):
            pass
    assert (base / "f").read_text() == "1"


# ---------------------------------------------------------------------------- crashes
@pytest.mark.parametrize("moment", ["before_renames", "between_renames", "after_renames"])
def test_crash_during_the_swap_recovers_old_or_new_complete_folder(tmp_path, moment):
    """What a writer killed at each point of the swap leaves is put right by the next run in
    the same folder: the old or the new folder, complete, never a mix."""
    pid, tok = _dead_pid(), "0123abcd"
    base = _publish(tmp_path / "out", {"summary.json": "old"})
    new = _work(tmp_path, pid, tok, "new")
    new.mkdir()
    (new / "summary.json").write_text("new")
    (new / MANIFEST_NAME).write_text(json.dumps({"state": "complete", "target": "out",
                                                 "files": ["summary.json"]}))
    old = _work(tmp_path, pid, tok, "old")
    journal = _work(tmp_path, pid, tok, "swap")
    if moment != "after_renames":
        journal.write_text(json.dumps({"target": "out", "new": new.name, "old": old.name}))
    if moment in ("between_renames", "after_renames"):
        os.rename(base, old)
    if moment == "after_renames":
        os.rename(new, base)
    done = recover_output_dirs(tmp_path)
    assert sorted(os.listdir(tmp_path)) == ["out"] and done
    expect = "old" if moment == "before_renames" else "new"
    assert (base / "summary.json").read_text() == expect


def test_recovery_leaves_live_writers_and_other_names_alone(tmp_path):
    live = _work(tmp_path, os.getppid(), "00000000", "new")  # our parent process runs
    live.mkdir()
    other = tmp_path / ".mp-something-else"
    other.mkdir()
    bad_journal = _work(tmp_path, _dead_pid(), "11111111", "swap")
    bad_journal.write_text(json.dumps({"target": "../escape", "new": "x", "old": "y"}))
    assert recover_output_dirs(tmp_path) == []
    assert live.is_dir() and other.is_dir() and bad_journal.exists()  # refused, logged
    assert recover_output_dirs(tmp_path / "missing") == []


_KILLED_WRITER = textwrap.dedent("""
    import os, signal, sys
    from meshphase.run.outdir import OutputDir
    base, keep = sys.argv[1], sys.argv[2] == "keep"
    with OutputDir(base, overwrite=True, staged=True) as out:
        (out.path / "summary.json").write_text("half")
        if keep:
            out.mark_partial()
        os.kill(os.getpid(), signal.SIGKILL)
""")


@pytest.mark.parametrize("keep", [False, True])
def test_writer_killed_mid_write(tmp_path, keep):
    """SIGKILL while the new folder is written: the old one is intact; the next run in the
    same parent folder removes the staging folder, or - marked worth keeping - makes it
    ``<folder>.partial``."""
    base = _publish(tmp_path / "out", {"summary.json": "old"})
    before = _tree(base)
    r = subprocess.run([sys.executable, "-c", _KILLED_WRITER, str(base), "keep" if keep else "no"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == -signal.SIGKILL, r.stderr
    assert _tree(base) == before
    assert len(os.listdir(tmp_path)) == 2  # out + the dead writer's staging folder
    with OutputDir(tmp_path / "other", staged=True):
        pass
    partial = tmp_path / ("out" + PARTIAL_SUFFIX)
    expected = ["other", "out"] + (["out" + PARTIAL_SUFFIX] if keep else [])
    assert sorted(os.listdir(tmp_path)) == sorted(expected)
    if keep:
        assert (partial / "summary.json").read_text() == "half"
        assert json.loads((partial / MANIFEST_NAME).read_text())["state"] == "partial"


def test_mark_partial_keeps_an_unfinished_run(tmp_path):
    base = _publish(tmp_path / "out", {"summary.json": "old"})
    with pytest.raises(KeyboardInterrupt):
        with OutputDir(base, overwrite=True) as out:
            (out.path / "done.json").write_text("1")
            out.mark_partial()
            raise KeyboardInterrupt
    assert out.partial_path == tmp_path / ("out" + PARTIAL_SUFFIX)
    assert (out.partial_path / "done.json").read_text() == "1"
    assert (base / "summary.json").read_text() == "old"
    # a second unfinished run replaces the older partial folder
    with pytest.raises(RuntimeError):
        with OutputDir(base, overwrite=True) as out:
            (out.path / "done.json").write_text("2")
            out.mark_partial()
            raise RuntimeError("boom")
    assert (out.partial_path / "done.json").read_text() == "2"
    assert sorted(os.listdir(tmp_path)) == ["out", "out" + PARTIAL_SUFFIX]


def test_a_users_partial_folder_is_never_replaced(tmp_path, caplog):
    base = _publish(tmp_path / "out", {"summary.json": "old"})
    mine = tmp_path / ("out" + PARTIAL_SUFFIX)
    mine.mkdir()
    (mine / "notes.txt").write_text("the user's")
    with pytest.raises(KeyboardInterrupt):
        with OutputDir(base, overwrite=True) as out:
            (out.path / "done.json").write_text("1")
            out.mark_partial()
            raise KeyboardInterrupt
    assert out.partial_path is None and "could not keep the partial results" in caplog.text
    assert _tree(mine) == {"notes.txt": b"the user's"}
    assert sorted(os.listdir(tmp_path)) == ["out", "out" + PARTIAL_SUFFIX]
    assert not ex.remove_partial(base) and mine.is_dir()  # not meshphase's: left alone


def test_relative_paths_and_the_current_folder(tmp_path, monkeypatch):
    base = _publish(tmp_path / "out", {"summary.json": "old"})
    monkeypatch.chdir(tmp_path)
    with OutputDir("out", overwrite=True) as out:  # relative: the staging folder is a sibling
        assert out.final == base and out.path.parent == tmp_path
        (out.path / "summary.json").write_text("new")
    assert (base / "summary.json").read_text() == "new"
    monkeypatch.chdir(base)
    for path in (".", str(base)):
        with pytest.raises(ValueError, match="cannot replace the current folder"):
            with OutputDir(path, overwrite=True):
                pass
    assert (base / "summary.json").read_text() == "new" and sorted(os.listdir(tmp_path)) == ["out"]


def test_a_signal_right_after_the_staging_mkdir_leaves_no_folder(tmp_path, monkeypatch):
    # SIGTERM raises SystemExit wherever the main thread is; the window between the staging
    # folder's mkdir and the code that removes it on failure was open (a loaded machine's
    # signal landed there and left .mp-*.new behind)
    real = os.mkdir

    def mkdir_then_signal(p, *a, **k):
        real(p, *a, **k)
        raise SystemExit(143)

    monkeypatch.setattr(ex.os, "mkdir", mkdir_then_signal)
    with pytest.raises(SystemExit):
        with ex.OutputDir(tmp_path / "out", staged=True):
            pass
    monkeypatch.undo()
    assert sorted(os.listdir(tmp_path)) == []


def test_a_colliding_staging_name_of_another_run_is_never_removed(tmp_path):
    other = tmp_path / ".mp-0000-1-00000000.new"
    other.mkdir()
    (other / ex.MANIFEST_NAME).write_text('{"pid": 1}')
    assert not ex._own_stage(other)
    mine = tmp_path / "mine"
    mine.mkdir()
    assert ex._own_stage(mine)
    assert not ex._own_stage(tmp_path / "missing")
