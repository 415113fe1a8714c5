"""Exit status is the truth: one exit-code table (pipeline/run/exits.py, README "Exit status") for
every subcommand, one line per cause on stderr, never a traceback.

The CLI runs in-process through :func:`meshphase.cli.main` (a few cases as a subprocess, to see
the real exit code and that no "Traceback" reaches stderr). Recordings are 30 s of the seed rig:
the shortest that gives both gauges measured passes and load sharing a factor per planet (a
requested result left empty is a partial run, exit 3), still well under a second per run.
"""

from __future__ import annotations

import dataclasses

import errno
import json
import os
import re
import subprocess
import sys
import warnings
from pathlib import Path

import h5py
import numpy as np
import pytest
from seed_rig_toml import SEED_RIG_GEARSET

import meshphase.api.process
import meshphase.io
import meshphase.io.base
import meshphase.run.exits
import meshphase.run.outdir
import meshphase.run.stages
from meshphase import cli
from meshphase.campaign.runner import phasing_reliability
from meshphase.cli import describe_error, main
from meshphase.errors import ProcessingWarning
from meshphase.run.state import FailureKind, RunMessage, StageFailure
from meshphase.run.exits import (EXIT_ERROR, EXIT_INTERRUPTED, EXIT_OK, EXIT_PARTIAL, EXIT_PIPE,
                                 run_status, status_line)
from meshphase.run.outdir import OutputDir
from meshphase.recording import ChannelSpec, Recording
from meshphase.run.stages import STAGE_FUNCTIONS, RunContext
from meshphase.validate import as_regular_file

GEARSET_TOML = 'name = "seed rig gearset"\n' + SEED_RIG_GEARSET
REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    """30 s of the seed rig as HDF5 (channels sun, ring, tacho), its gearset file, and a copy of
    the recording truncated to a third (HDF5 magic intact, body cut off)."""
    from meshphase.synthetic import generate

    d = tmp_path_factory.mktemp("exit_rig")
    rec, _ = generate("seed_rig", duration=30.0, seed=0)
    path = Path(meshphase.io.write(rec, d / "rig.h5"))
    gs = d / "gearset.toml"
    gs.write_text(GEARSET_TOML, encoding="utf-8")
    raw = path.read_bytes()
    cut = d / "cut.h5"
    cut.write_bytes(raw[: len(raw) // 3])
    return {"dir": d, "rec": rec, "path": path, "gearset": gs, "cut": cut}


def _run_cli(*args, env=None, timeout=120, **kw):
    """``python -m meshphase.cli ARGS`` as a subprocess (the real exit code and stderr)."""
    return subprocess.run([sys.executable, "-m", "meshphase.cli", "-q", *map(str, args)],
                          capture_output=True, text=True, timeout=timeout, cwd=REPO, env=env, **kw)


def _entries(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def _cause_lines(err: str) -> list[str]:
    """The stderr lines that are not warnings (``meshphase COMMAND: warning: ...``: a run's
    warnings share stderr with the causes, in the same style)."""
    return [ln for ln in err.splitlines() if ln.strip() and not re.match(r"meshphase \w+: warning: ", ln)]


def _err_lines(capsys) -> list[str]:
    return _cause_lines(capsys.readouterr().err)


# --------------------------------------------------------------------------- 1: input errors
def test_truncated_recording_exits_1_and_writes_nothing(rig, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["-q", "process", str(rig["cut"]), "--gearset", str(rig["gearset"]),
                 "--out", str(out)]) == EXIT_ERROR
    err = _err_lines(capsys)
    assert len(err) == 1                                   # one cause, one line
    assert "cut.h5" in err[0] and "truncated" in err[0] and "cannot load the recording" in err[0]
    assert not out.exists()                                # nothing usable, nothing written


def test_truncated_recording_real_command_has_no_traceback(rig, tmp_path):
    r = _run_cli("process", rig["cut"], "--gearset", rig["gearset"], "--out", tmp_path / "o")
    assert r.returncode == EXIT_ERROR
    assert "Traceback" not in r.stderr and "cut.h5" in r.stderr and "truncated" in r.stderr
    assert not (tmp_path / "o").exists()


def test_channel_typo_in_scene_lists_the_channels_present(rig, tmp_path, capsys):
    gs = tmp_path / "typo.toml"
    gs.write_text(GEARSET_TOML + '\n[[channels]]\nname = "sun_gauge"\nkind = "sun"\n', encoding="utf-8")
    assert main(["-q", "process", str(rig["path"]), "--gearset", str(gs),
                 "--out", str(tmp_path / "o")]) == EXIT_ERROR
    err = _err_lines(capsys)
    assert len(err) == 1
    assert "'sun_gauge'" in err[0] and "is not in the file" in err[0]
    assert "channels present: sun (sun), ring (ring), tacho (tacho)" in err[0]
    assert "did you mean 'sun_gauge' -> 'sun'" in err[0]
    assert not (tmp_path / "o").exists()


def test_run_scene_with_channel_typo_exits_1(rig, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    scene = tmp_path / "typo.toml"
    scene.write_text('results = ["ideal_phasing", "phasing"]\n' + SEED_RIG_GEARSET
                     + f'[input]\nrecording = "{rig["path"]}"\n'
                     + '[[channels]]\nname = "ring_gauge"\nkind = "ring"\n', encoding="utf-8")
    # `ideal` needs no recording and runs: still exit 1, the recording was not read
    assert main(["-q", "run", str(scene), "--no-report"]) == EXIT_ERROR
    err = capsys.readouterr().err
    assert "'ring_gauge'" in err and "sun (sun), ring (ring), tacho (tacho)" in err
    assert not (tmp_path / "typo-meshphase").exists()


def test_recording_without_gauge_channels_exits_1_naming_kinds(rig, tmp_path, capsys):
    rec = rig["rec"]
    specs = [ChannelSpec("ch_a", kind="other"), ChannelSpec("ch_b", kind="other"),
             ChannelSpec("tacho", kind="tacho", units="V")]
    path = meshphase.io.write(Recording(rec.data, rec.fs, specs), tmp_path / "nogauge.h5")
    assert main(["-q", "process", str(path), "--gearset", str(rig["gearset"]),
                 "--out", str(tmp_path / "o")]) == EXIT_ERROR
    err = _err_lines(capsys)
    assert len(err) == 1
    assert "no gauge channel (kind sun, ring or facewidth)" in err[0]
    assert "channels present: ch_a (other), ch_b (other), tacho (tacho)" in err[0]
    assert '[[channels]] name = "ch_a", kind = "sun"' in err[0]       # the mapping to add
    assert not (tmp_path / "o").exists()


def test_plain_csv_without_strain_channels_exits_1(tmp_path, capsys):
    p = tmp_path / "plain.csv"
    p.write_text("time,a,b\n" + "".join(f"{i / 5120!r},{i % 7}.5,{i % 3}.25\n" for i in range(2048)),
                 encoding="utf-8")
    gs = tmp_path / "gs.toml"
    gs.write_text(GEARSET_TOML, encoding="utf-8")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")       # the reader's FormatWarning: no [units] in the header
        rc = main(["-q", "process", str(p), "--gearset", str(gs), "--out", str(tmp_path / "o")])
    assert rc == EXIT_ERROR
    err = capsys.readouterr().err
    assert "no gauge channel" in err and "a (other), b (other)" in err and "[[channels]]" in err
    assert "no measured passes" not in err and not (tmp_path / "o").exists()


def test_hdf5_soft_link_loop_exits_1_naming_the_file(rig, tmp_path, capsys):
    p = tmp_path / "loop.h5"
    p.write_bytes(rig["path"].read_bytes())
    with h5py.File(p, "a") as f:                          # h5py raises RuntimeError on it
        del f["channels/sun"]
        f["channels/sun"] = h5py.SoftLink("/channels/sun2")
        f["channels/sun2"] = h5py.SoftLink("/channels/sun")
    assert main(["-q", "info", str(p)]) == EXIT_ERROR
    err = _err_lines(capsys)
    assert len(err) == 1 and "loop.h5" in err[0] and "too many links" in err[0]


def test_directory_as_input_exits_1(rig, tmp_path, capsys):
    d = tmp_path / "a_folder.h5"
    d.mkdir()
    assert main(["-q", "info", str(d)]) == EXIT_ERROR
    assert "a_folder.h5: is a directory" in capsys.readouterr().err
    assert main(["-q", "process", str(d), "--gearset", str(rig["gearset"])]) == EXIT_ERROR
    assert "is a directory" in capsys.readouterr().err
    assert main(["-q", "process", str(rig["path"]), "--gearset", str(d)]) == EXIT_ERROR
    assert "is a directory; the gearset scene (--gearset) must be a file" in capsys.readouterr().err


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no os.mkfifo on this platform")
def test_fifo_as_input_is_refused_without_opening_it(rig, tmp_path, capsys):
    fifo = tmp_path / "pipe.h5"
    os.mkfifo(fifo)
    # in-process: refused by stat before anything opens it (opening would block: no writer)
    for argv in (["info", str(fifo)], ["convert", str(fifo), str(tmp_path / "x.h5")],
                 ["process", str(fifo), "--gearset", str(rig["gearset"])], ["run", str(fifo)]):
        assert main(["-q", *argv]) == EXIT_ERROR, argv
        err = _err_lines(capsys)
        assert len(err) == 1 and "is a FIFO (named pipe), not a regular file" in err[0], argv
    # the real command: a hang would hit the timeout (subprocess.TimeoutExpired fails the test)
    r = _run_cli("info", fifo, timeout=60)
    assert r.returncode == EXIT_ERROR and "FIFO" in r.stderr and "Traceback" not in r.stderr


# --------------------------------------------------------------------------- 1: OS errors
def test_output_folder_under_a_regular_file_exits_1(rig, tmp_path, capsys):
    blocker = tmp_path / "not_a_folder"
    blocker.write_text("x")
    assert main(["-q", "process", str(rig["path"]), "--gearset", str(rig["gearset"]),
                 "--out", str(blocker / "out")]) == EXIT_ERROR
    err = _err_lines(capsys)
    assert len(err) == 1
    assert "not_a_folder/out: Not a directory" in err[0] and "a part of the path is a file" in err[0]


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() == 0,
                    reason="root ignores permission bits (covered by the ENOTDIR and injected EACCES tests)")
def test_permission_denied_output_folder_exits_1(rig, tmp_path, capsys):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        assert main(["-q", "process", str(rig["path"]), "--gearset", str(rig["gearset"]),
                     "--out", str(locked / "out")]) == EXIT_ERROR
    finally:
        locked.chmod(0o700)
    err = capsys.readouterr().err
    assert "Permission denied" in err and "check the permissions" in err


def test_permission_denied_output_folder_injected_exits_1(rig, tmp_path, monkeypatch, capsys):
    """The EACCES path as root too: no folder can be created in ``locked`` (as mkdir raises it)."""
    real_mkdir = os.mkdir

    def denied(path, *a, **k):
        if os.path.dirname(os.fspath(path)) == str(tmp_path / "locked"):
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), os.fspath(path))
        return real_mkdir(path, *a, **k)

    monkeypatch.setattr(os, "mkdir", denied)
    out = tmp_path / "locked" / "out"
    assert main(["-q", "process", str(rig["path"]), "--gearset", str(rig["gearset"]),
                 "--out", str(out)]) == EXIT_ERROR
    err = _err_lines(capsys)
    assert err == [f"meshphase process: error: {out}: Permission denied (check the permissions of "
                   "the file or folder)"]


def test_output_name_too_long_exits_1(rig, tmp_path, capsys):
    long = tmp_path / ("x" * 300)                     # one name > 255 bytes: ENAMETOOLONG
    assert main(["-q", "process", str(rig["path"]), "--gearset", str(rig["gearset"]),
                 "--out", str(long)]) == EXIT_ERROR
    err = _err_lines(capsys)
    assert len(err) == 1 and "File name too long" in err[0]
    assert main(["-q", "convert", str(rig["path"]), str(tmp_path / ("y" * 300 + ".h5"))]) == EXIT_ERROR
    assert "File name too long" in capsys.readouterr().err
    assert _entries(tmp_path) == []


def test_no_space_left_while_writing_exits_1_and_cleans_up(rig, tmp_path, monkeypatch, capsys):
    def full(ctx, out_dir, **kw):
        (Path(out_dir) / "summary.json").write_text("{")     # half written when the disk fills
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(Path(out_dir) / "arrays.h5"))

    monkeypatch.setattr(meshphase.run.stages, "write_outputs", full)
    out = tmp_path / "o"
    assert main(["-q", "process", str(rig["path"]), "--gearset", str(rig["gearset"]),
                 "--out", str(out)]) == EXIT_ERROR
    err = _err_lines(capsys)
    assert len(err) == 1 and "arrays.h5: No space left on device" in err[0]
    assert not out.exists()                                # no half-written results left


def test_memory_error_exits_1_with_one_line(rig, tmp_path, monkeypatch, capsys):
    def oom(ctx):
        raise MemoryError()

    monkeypatch.setitem(STAGE_FUNCTIONS, "condition", oom)
    assert main(["-q", "process", str(rig["path"]), "--gearset", str(rig["gearset"]),
                 "--out", str(tmp_path / "o")]) == EXIT_ERROR
    err = _err_lines(capsys)
    assert len(err) == 1 and err[0].startswith("meshphase process: error: out of memory")
    assert not (tmp_path / "o").exists()


# --------------------------------------------------------------------------- 3: partial
def test_failed_stage_is_partial_exit_3_with_causes(rig, tmp_path, monkeypatch, capsys):
    def boom(ctx):
        raise ValueError("onset detector exploded")

    monkeypatch.setitem(STAGE_FUNCTIONS, "onsets", boom)
    out = tmp_path / "o"
    assert main(["-q", "process", str(rig["path"]), "--gearset", str(rig["gearset"]),
                 "--out", str(out)]) == EXIT_PARTIAL
    cap = capsys.readouterr()
    assert "status    partial: not computed: phasing, load_sharing, identify, compare" in cap.out
    err = cap.err.splitlines()
    assert len(err) == 4                                    # one line per missing result
    assert all("onsets failed (ValueError: onset detector exploded)" in ln for ln in err)
    summ = json.loads((out / "summary.json").read_text())  # outputs are still written
    assert summ["status"] == "partial"
    missing = {m["result"]: m for m in summ["missing_results"]}
    assert set(missing) == {"phasing", "load_sharing", "identify", "compare"}
    assert missing["phasing"]["stage"] == "phasing"
    assert missing["phasing"]["cause"] == "skipped: onsets failed (ValueError: onset detector exploded)"
    assert "ideal" in summ["stages_ran"]


def test_failed_result_stage_itself_is_partial(rig, tmp_path, monkeypatch, capsys):
    def boom(ctx):
        raise ValueError("planet_count: 0 planets in the file")

    monkeypatch.setitem(STAGE_FUNCTIONS, "load_sharing", boom)
    out = tmp_path / "o"
    assert main(["-q", "process", str(rig["path"]), "--gearset", str(rig["gearset"]),
                 "--out", str(out)]) == EXIT_PARTIAL
    err = _err_lines(capsys)
    assert err == ["meshphase process: partial: load_sharing not computed: ValueError: "
                   "planet_count: 0 planets in the file"]
    summ = json.loads((out / "summary.json").read_text())
    assert summ["status"] == "partial"
    assert summ["missing_results"] == [{"result": "load_sharing", "stage": "load_sharing",
                                        "cause": "ValueError: planet_count: 0 planets in the file"}]


def test_key_error_in_a_stage_is_a_bug_exit_1_not_partial(rig, tmp_path, monkeypatch, capsys):
    # a mistyped key is a bug: it stops the run (one line, nothing written), it is not
    # reported as a result that could not be computed
    def typo(ctx):
        raise KeyError("planet_count")

    monkeypatch.setitem(STAGE_FUNCTIONS, "load_sharing", typo)
    out = tmp_path / "o"
    assert main(["-q", "process", str(rig["path"]), "--gearset", str(rig["gearset"]),
                 "--out", str(out)]) == EXIT_ERROR
    assert _err_lines(capsys) == ["meshphase process: error: missing key 'planet_count'"]
    assert not out.exists()


def test_unreliable_phasing_exits_3_with_status_line(rig, tmp_path, monkeypatch, capsys):
    original = STAGE_FUNCTIONS["phasing"]

    def flagged(ctx):
        original(ctx)
        reason = "sun gauge: the pass train does not follow one smooth speed; phasing not reliable"
        ctx.phasing.reliability["sun"] = {"reliable": False, "reasons": [reason]}
        warnings.warn(reason, ProcessingWarning, stacklevel=2)

    monkeypatch.setitem(STAGE_FUNCTIONS, "phasing", flagged)
    out = tmp_path / "o"
    assert main(["-q", "process", str(rig["path"]), "--gearset", str(rig["gearset"]),
                 "--out", str(out)]) == EXIT_PARTIAL
    cap = capsys.readouterr()
    assert "status    unreliable: phasing of the sun gauge" in cap.out
    assert _cause_lines(cap.err) == [
        "meshphase process: unreliable: sun gauge phasing: sun gauge: the pass train does not "
        "follow one smooth speed; phasing not reliable"]
    # the stage's warning is a stderr line in the same style, not a stdout line
    assert ("meshphase process: warning: phasing: ProcessingWarning: sun gauge: the pass train does "
            "not follow one smooth speed; phasing not reliable") in cap.err.splitlines()
    assert not [ln for ln in cap.out.splitlines() if ln.startswith("warning") or ": warning: " in ln]
    summ = json.loads((out / "summary.json").read_text())
    assert summ["status"] == "unreliable" and summ["missing_results"] == []
    assert summ["phasing_reliability"]["sun"]["reliable"] is False
    assert summ["phasing_reliability"]["ring"]["reliable"] is True


def test_clean_run_exits_0_and_lists_unused_channels(rig, tmp_path, capsys):
    rec = rig["rec"]
    extra = Recording(rec.data[:, [0, 1, 2, 2]], rec.fs,
                      list(rec.channels) + [ChannelSpec("oil_temp", kind="other", units="V")])
    path = meshphase.io.write(extra, tmp_path / "extra.h5")
    out = tmp_path / "o"
    assert main(["-q", "process", str(path), "--gearset", str(rig["gearset"]),
                 "--out", str(out)]) == EXIT_OK
    cap = capsys.readouterr()
    assert "unused    oil_temp (other): channel(s) read but used by no stage" in cap.out
    assert "status    ok" in cap.out and _cause_lines(cap.err) == []
    summ = json.loads((out / "summary.json").read_text())
    assert summ["status"] == "ok" and summ["channels_unused"] == ["oil_temp"]
    assert summ["missing_results"] == []


# --------------------------------------------------------------------------- 130: interrupted
def test_keyboard_interrupt_in_a_stage_exits_130_and_leaves_nothing(rig, tmp_path, monkeypatch, capsys):
    def ctrl_c(ctx):
        raise KeyboardInterrupt

    monkeypatch.setitem(STAGE_FUNCTIONS, "phasing", ctrl_c)
    before = _entries(rig["dir"])
    assert main(["-q", "process", str(rig["path"]), "--gearset", str(rig["gearset"])]) == EXIT_INTERRUPTED
    assert _err_lines(capsys) == ["meshphase process: interrupted"]
    assert _entries(rig["dir"]) == before                  # the reserved rig-meshphase is gone


def test_keyboard_interrupt_while_writing_leaves_the_previous_folder_intact(rig, tmp_path, monkeypatch, capsys):
    """Ctrl-C while an --overwrite run writes: the previous run's folder stays exactly as it was
    (the new one is built beside it and swapped in only when finished); a fresh folder is gone."""
    out = tmp_path / "o"
    assert main(["-q", "process", str(rig["path"]), "--gearset", str(rig["gearset"]),
                 "--out", str(out)]) in (EXIT_OK, EXIT_PARTIAL)
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    real = meshphase.run.stages.write_outputs

    def interrupted(ctx, out_dir, **kw):
        real(ctx, out_dir, **kw)
        raise KeyboardInterrupt

    monkeypatch.setattr(meshphase.run.stages, "write_outputs", interrupted)
    assert main(["-q", "process", str(rig["path"]), "--gearset", str(rig["gearset"]),
                 "--out", str(out), "--overwrite"]) == EXIT_INTERRUPTED
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before
    assert _entries(tmp_path) == ["o"]                    # no staging folder left beside it
    assert main(["-q", "process", str(rig["path"]), "--gearset", str(rig["gearset"]),
                 "--out", str(tmp_path / "fresh")]) == EXIT_INTERRUPTED
    assert not (tmp_path / "fresh").exists()
    assert capsys.readouterr().err.count("interrupted") == 2


def test_overwrite_refuses_a_folder_with_files_meshphase_did_not_write(rig, tmp_path, capsys):
    """--overwrite replaces the whole folder, so one holding a file of the user's is refused
    (exit 1, one line naming it), never emptied."""
    out = tmp_path / "o"
    out.mkdir()
    (out / "earlier.txt").write_text("from the user")
    assert main(["-q", "process", str(rig["path"]), "--gearset", str(rig["gearset"]),
                 "--out", str(out), "--overwrite"]) == EXIT_ERROR
    err = _err_lines(capsys)
    assert len(err) == 1 and "earlier.txt" in err[0] and "not written by meshphase" in err[0]
    assert _entries(out) == ["earlier.txt"]


def test_keyboard_interrupt_in_run_scene_exits_130(tmp_path, monkeypatch, capsys):
    scene = REPO / "examples" / "bearing_moments.toml"

    def ctrl_c(ctx):
        raise KeyboardInterrupt

    monkeypatch.setitem(STAGE_FUNCTIONS, "tilt", ctrl_c)
    out = tmp_path / "bm"
    assert main(["-q", "run", str(scene), "--out", str(out), "--no-report"]) == EXIT_INTERRUPTED
    assert "interrupted" in capsys.readouterr().err and not out.exists()


# --------------------------------------------------------------------------- 141: closed pipe
def test_info_json_into_a_closed_pipe_exits_quietly(rig):
    # the reader closes its end before meshphase writes (imports alone take longer): EPIPE for sure
    p = subprocess.Popen([sys.executable, "-m", "meshphase.cli", "-q", "info", "--json",
                          "--no-quality", str(rig["path"])], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, cwd=REPO)
    p.stdout.close()
    _, err = p.communicate(timeout=120)
    assert p.returncode == EXIT_PIPE
    assert err.decode() == ""                              # no BrokenPipeError, no message


def test_info_json_piped_to_head_has_no_traceback(rig):
    cmd = (f"{sys.executable} -m meshphase.cli -q info --json {rig['path']} | head -c 10; "
           "echo \" rc=${PIPESTATUS[0]}\"")
    r = subprocess.run(["bash", "-c", cmd], capture_output=True, text=True, timeout=120, cwd=REPO)
    # the JSON may fit the pipe buffer before head exits (0) or not (141): both are quiet
    assert r.stdout.startswith("{") and r.stdout.rstrip().endswith(("rc=0", f"rc={EXIT_PIPE}"))
    assert "Traceback" not in r.stderr and "BrokenPipeError" not in r.stderr and r.stderr == ""


# --------------------------------------------------------------------------- --debug
def test_debug_reraises_with_the_traceback(rig, tmp_path, monkeypatch):
    with pytest.raises(IsADirectoryError, match="is a directory"):
        main(["-q", "--debug", "info", str(tmp_path)])
    monkeypatch.setenv("MESHPHASE_DEBUG", "1")
    with pytest.raises(IsADirectoryError):
        main(["-q", "info", str(tmp_path)])
    monkeypatch.setenv("MESHPHASE_DEBUG", "0")
    assert main(["-q", "info", str(tmp_path)]) == EXIT_ERROR


def test_usage_error_is_2():
    with pytest.raises(SystemExit) as e:
        main(["process"])
    assert e.value.code == 2


# --------------------------------------------------------------------------- helpers
def _failure(stage: str, text: str) -> StageFailure:
    """The typed failure a run records for what its text says (test shorthand)."""
    if text.startswith("skipped: needs "):
        return StageFailure.blocked(stage, text[len("skipped: needs "):].split(", "))
    if text.startswith("skipped: "):
        return StageFailure.not_applicable(stage, text[len("skipped: "):])
    exc, reason = text.split(": ", 1)
    return StageFailure(stage, FailureKind.RAISED, reason, exc)


def _ctx(failed=None, ran=None, messages=None, tables=None):
    from meshphase.run.results import PhasingStage
    from meshphase.run.scene import parse_scene

    scene = parse_scene('results = ["tilt"]\n[bearing]\ncase = "1"\nk_tilt_Nm_per_rad = 1e6\n')
    ctx = RunContext(scene)
    ctx.failed, ctx.ran = {k: _failure(k, v) for k, v in (failed or {}).items()}, list(ran or [])
    ctx.messages = list(messages or [])
    if tables is not None:
        ctx.record("phasing", PhasingStage(tables=tables))
    return ctx


def test_run_status_table():
    ok = run_status(_ctx(ran=["tilt"]))
    assert ok == {"status": "ok", "exit_code": 0, "error": None, "missing_results": [], "unreliable": {}}
    assert status_line(ok) == "ok"
    # a benign skip (no face-width gauges) is not a missing result
    benign = run_status(_ctx(ran=["load"], failed={"centroids": "skipped: the recording has no "
                                                                 "face-width gauges"}))
    assert benign["status"] == "ok"
    chain = run_status(_ctx(ran=["load", "ideal"], failed={
        "condition": "ValueError: bad", "onsets": "skipped: needs condition",
        "phasing": "skipped: needs onsets", "compare": "skipped: needs phasing"}))
    assert chain["status"] == "partial" and chain["exit_code"] == 3
    assert [m["result"] for m in chain["missing_results"]] == ["phasing", "compare"]
    assert chain["missing_results"][1]["cause"] == "skipped: condition failed (ValueError: bad)"
    assert status_line(chain) == "partial: not computed: phasing, compare"
    load = run_status(_ctx(ran=["ideal"], failed={"load": "RecordingFileError: x.h5: truncated"}))
    assert load["status"] == "failed" and load["exit_code"] == 1
    assert load["error"] == "cannot load the recording: x.h5: truncated"
    none = run_status(_ctx(failed={"tilt": "ValueError: k"}))
    assert none["status"] == "failed" and none["exit_code"] == 1 and status_line(none) == "failed: tilt: ValueError: k"


def test_run_status_and_status_line_bad_input():
    with pytest.raises(TypeError, match="RunContext"):
        run_status({"failed": {}})
    with pytest.raises(TypeError, match="run_status"):
        status_line("ok")
    with pytest.raises(TypeError, match="run_status"):
        status_line({})


def test_phasing_reliability_prefers_the_stage_key_and_falls_back_to_messages():
    assert phasing_reliability(_ctx()) == {}                         # nothing ran: nothing flagged
    msg = RunMessage("phasing", "ProcessingWarning", "ring gauge: encoder misfit; phasing not reliable",
                     gauge="ring", unreliable=True)
    said = RunMessage("onsets", "DataQualityWarning", "sun gauge: aliased, not reliable", gauge="sun")
    ctx = _ctx(messages=[msg, said],
               tables={"sun": [], "ring": []})
    assert phasing_reliability(ctx) == {
        "sun": {"reliable": True, "reasons": []},                    # DataQualityWarning: not ours
        "ring": {"reliable": False, "reasons": ["ring gauge: encoder misfit; phasing not reliable"]}}
    anon = _ctx(messages=[RunMessage("compare", "ProcessingWarning", "residuals not reliable",
                                     unreliable=True)],
                tables={"sun": []})
    assert phasing_reliability(anon)["sun"]["reliable"] is False
    given = {"sun": {"reliable": False, "reasons": ["from the stage"]}}
    ctx.record("phasing", dataclasses.replace(ctx.phasing, reliability=given))  # the stage's key wins
    assert phasing_reliability(ctx) == given
    with pytest.raises(TypeError, match="RunContext"):
        phasing_reliability(object())


def test_describe_error_one_line_per_kind():
    assert describe_error(OSError(errno.ENOSPC, "No space left on device", "/x/a.h5")) == (
        "/x/a.h5: No space left on device (free some space or write the outputs elsewhere (--out))")
    assert describe_error(ValueError("x.h5: bad\nheader")) == "x.h5: bad header"
    assert describe_error(KeyError("fs")) == "missing key 'fs'"
    assert describe_error(MemoryError()).startswith("out of memory; ")
    assert "unexpected" in describe_error(RuntimeError("boom")) and "--debug" in describe_error(RuntimeError())
    assert describe_error(OSError("Can't read data")) == "Can't read data"   # h5py: no errno


def test_output_dir_bad_input_and_discard(tmp_path):
    with pytest.raises(TypeError, match="base"):
        OutputDir(3)
    with OutputDir(tmp_path / "a") as out:
        (out.path / "f").write_text("x")
        out.discard()
    assert not (tmp_path / "a").exists()
    with pytest.raises(RuntimeError):
        with OutputDir(tmp_path / "b") as out:
            raise RuntimeError("stage bug")
    assert not (tmp_path / "b").exists()


def test_as_regular_file_empty_and_bad_input(tmp_path):
    f = tmp_path / "f.h5"
    f.write_bytes(b"x")
    assert as_regular_file(str(f), "the recording") == f
    with pytest.raises(FileNotFoundError, match="nope.h5"):
        as_regular_file(tmp_path / "nope.h5", "the recording")
    with pytest.raises(ValueError, match="empty path"):
        as_regular_file("", "the recording")
    with pytest.raises(IsADirectoryError, match="is a directory"):
        as_regular_file(tmp_path, "the recording")
    with pytest.raises(TypeError, match="the recording must be a path"):
        as_regular_file(3, "the recording")
    with pytest.raises(NotADirectoryError):
        as_regular_file(f / "sub", "the recording")


# --------------------------------------------------------------------------- smaller boundary fixes
def test_process_takes_a_gearset_file_with_results_but_no_input(rig, tmp_path, capsys):
    # the recording given on the command line replaces [input]: a scene's results need none
    gs = tmp_path / "with_results.toml"
    gs.write_text('name = "rig"\nresults = ["phasing"]\n' + SEED_RIG_GEARSET, encoding="utf-8")
    out = tmp_path / "o"
    assert main(["-q", "process", str(rig["path"]), "--gearset", str(gs), "--out", str(out)]) == EXIT_OK
    assert "need an [input]" not in capsys.readouterr().err
    assert json.loads((out / "summary.json").read_text())["status"] == "ok"
    assert meshphase.api.process.process(rig["path"], gs).status == "ok"         # the API the same
    # a campaign's recordings replace [input] too (its up-front scene check, without a cluster)
    from meshphase.campaign.runner import _scene_and_recordings

    scene, _inputs, files, _skipped = _scene_and_recordings(gs, [str(rig["path"])])
    assert files == [rig["path"].resolve()] and scene.results == ["phasing"]
    # `run` has no recording of its own: there [input] is still required
    assert main(["-q", "run", str(gs), "--out", str(tmp_path / "r")]) == EXIT_ERROR
    assert "need an [input] recording" in capsys.readouterr().err


def test_disk_full_while_writing_the_outputs_names_the_output_folder(rig, tmp_path, monkeypatch, capsys):
    def full(ctx, out_dir, **kw):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))  # a buffered writer's close: no name

    monkeypatch.setattr(meshphase.run.stages, "write_outputs", full)
    out = tmp_path / "results"
    assert main(["-q", "process", str(rig["path"]), "--gearset", str(rig["gearset"]),
                 "--out", str(out)]) == EXIT_ERROR
    err = _err_lines(capsys)
    assert len(err) == 1 and f"{out}: No space left on device" in err[0]
    assert not out.exists()


def test_disk_full_inside_a_writer_names_the_output_file(rig, tmp_path, monkeypatch):
    def full(rec, path, **kw):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(meshphase.io.get_format("mcap"), "write", full)
    with pytest.raises(OSError, match="No space left on device") as exc:
        meshphase.io.write(rig["rec"], tmp_path / "x.mcap", compression="zstd")
    assert exc.value.errno == errno.ENOSPC and exc.value.filename == str(tmp_path / "x.mcap")
    assert _entries(tmp_path) == []                        # the temporary file is gone too


def test_read_only_file_system_is_not_reported_as_full(rig, tmp_path, monkeypatch, capsys):
    real = os.statvfs

    def read_only(path):
        st = real(path)
        return os.statvfs_result((st.f_bsize, st.f_frsize, st.f_blocks, 0, 0, st.f_files,
                                  st.f_ffree, st.f_favail, st.f_flag | os.ST_RDONLY, st.f_namemax))

    monkeypatch.setattr(meshphase.io.base.os, "statvfs", read_only)
    assert main(["-q", "convert", str(rig["path"]), str(tmp_path / "x.h5")]) == EXIT_ERROR
    err = _err_lines(capsys)
    assert len(err) == 1 and "x.h5: Read-only file system" in err[0] and "free space" not in err[0]


def test_overflowing_samples_give_no_raw_numpy_warning():
    from meshphase.signal.condition import detect_hum
    from meshphase.signal.quality import channel_quality

    t = np.arange(10 * 5120) / 5120.0
    x = 1e-4 * np.sin(2 * np.pi * 50.0 * t) + 1e-6 * np.random.default_rng(0).standard_normal(t.size)
    ref = channel_quality(x)["rms"]
    # pytest turns any RuntimeWarning (overflow, invalid value) into an error here
    for scale in (1e300, 1e-310):
        q = channel_quality(x * scale)
        # the RMS is scaled exactly but for rounding: relative 1e-12 is ~1e4 ulp of float64
        # (subnormal samples keep ~14 of their 52 bits: relative 1e-4 there)
        assert q["rms"] == pytest.approx(ref * scale, rel=1e-12 if scale > 1 else 1e-4)
        hum, ref_hum = detect_hum(x * scale, 5120.0), detect_hum(x, 5120.0)
        assert hum.mains == ref_hum.mains == 50.0                      # a ratio test: scale-free
        # the same excess but for the samples' rounding: 1e-9 dB at 1e300; at 1e-310 the
        # noise samples (1e-316) keep a few bits only, 1e-4 dB is far above what that moves
        np.testing.assert_allclose(hum.excess_db, ref_hum.excess_db, rtol=0,
                                   atol=1e-9 if scale > 1 else 1e-4)


def test_output_write_errors_empty_and_bad_input(tmp_path):
    with meshphase.run.outdir.output_write_errors(tmp_path / "o"):     # nothing raised: nothing to do
        pass
    with pytest.raises(OSError) as exc:                             # names no file: the output
        with meshphase.run.outdir.output_write_errors(tmp_path / "o"):
            raise OSError(errno.EDQUOT, os.strerror(errno.EDQUOT))
    assert exc.value.errno == errno.EDQUOT and exc.value.filename == str(tmp_path / "o")
    named = OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), "/elsewhere/f.csv")
    with pytest.raises(OSError) as exc:                             # already named: kept as is
        with meshphase.run.outdir.output_write_errors(tmp_path / "o"):
            raise named
    assert exc.value is named
    with pytest.raises(PermissionError):                            # not a full disk: untouched
        with meshphase.run.outdir.output_write_errors(tmp_path / "o"):
            raise PermissionError(errno.EACCES, "Permission denied")
    with pytest.raises(ValueError, match="not an OSError"):
        with meshphase.run.outdir.output_write_errors(tmp_path / "o"):
            raise ValueError("not an OSError")
