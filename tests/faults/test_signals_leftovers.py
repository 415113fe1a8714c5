"""Signals and leftovers: a run's output folder appears under its name only when complete,
SIGTERM unwinds (exit 143, nothing left), SIGKILL leaves only a hidden staging folder that
the next run removes, and a campaign's fork server and workers leave Ctrl-C to the command."""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from meshphase.run.outdir import OutputDir, free_output_name

REPO = Path(__file__).resolve().parents[2]


def _py(code: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True,
                          timeout=timeout, cwd=REPO)


def _entries(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


# --------------------------------------------------------------------------- the name appears when complete
def test_staged_output_name_appears_only_when_published(tmp_path):
    base = tmp_path / "pout"
    with OutputDir(base, staged=True) as out:
        (out.path / "summary.json").write_text("{}")
        assert not os.path.lexists(base)                      # no empty folder under the final name
        assert [n for n in _entries(tmp_path) if n.startswith(".mp-")] == [out.path.name]
    assert out.final == base and (base / "summary.json").read_text() == "{}"
    assert _entries(tmp_path) == ["pout"]


def test_staged_output_takes_the_next_name_when_taken_meanwhile(tmp_path):
    base = tmp_path / "pout"
    with OutputDir(base, staged=True) as out:
        (out.path / "a.txt").write_text("mine")
        base.mkdir()
        (base / "other.txt").write_text("another run's")       # another run published first
    assert out.final == tmp_path / "pout-2" and (out.final / "a.txt").read_text() == "mine"
    assert (base / "other.txt").read_text() == "another run's"


def test_free_output_name_empty_and_bad(tmp_path):
    assert free_output_name(tmp_path / "x") == tmp_path / "x"            # nothing there
    (tmp_path / "x").mkdir()
    (tmp_path / "x-2").symlink_to(tmp_path / "gone")                     # a dangling link counts
    assert free_output_name(tmp_path / "x") == tmp_path / "x-3"
    assert not (tmp_path / "x-3").exists()                               # nothing created
    with pytest.raises(TypeError):
        free_output_name(None)


def test_output_under_a_file_is_refused_naming_the_output(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(NotADirectoryError, match="file/out"):
        with OutputDir(blocker / "out", staged=True):
            pass  # pragma: no cover


# --------------------------------------------------------------------------- SIGTERM and SIGKILL
def test_sigterm_inside_output_dir_exits_143_and_leaves_nothing(tmp_path):
    r = _py(f"""
        import os, signal, time
        from meshphase.run.outdir import OutputDir
        with OutputDir({str(tmp_path / 'pout')!r}, staged=True) as out:
            (out.path / "half.csv").write_text("1,2")
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(30)
        """)
    assert r.returncode == 128 + signal.SIGTERM, r.stderr
    assert "Traceback" not in r.stderr
    assert _entries(tmp_path) == []


def test_sigkill_leaves_a_staging_folder_the_next_run_removes(tmp_path):
    r = _py(f"""
        import os, signal
        from meshphase.run.outdir import OutputDir
        with OutputDir({str(tmp_path / 'pout')!r}, staged=True) as out:
            (out.path / "half.csv").write_text("1,2")
            os.kill(os.getpid(), signal.SIGKILL)
        """)
    assert r.returncode == -signal.SIGKILL
    left = _entries(tmp_path)
    assert len(left) == 1 and left[0].startswith(".mp-") and left[0].endswith(".new")   # no 'pout'
    with OutputDir(tmp_path / "pout", staged=True) as out:
        (out.path / "summary.json").write_text("{}")
    assert out.final == tmp_path / "pout"                     # the name, not pout-2
    assert _entries(tmp_path) == ["pout"]


@pytest.mark.timeout(180, func_only=True)
def test_process_command_sigterm_exits_143_and_leaves_nothing(tmp_path):
    """The real command: SIGTERM once its staging folder exists (the run is under way)."""
    from fault_corpus import SEED_RIG_GEARSET

    import meshphase.io as pio
    from meshphase.synthetic import generate

    rec, _ = generate("seed_rig", duration=20.0, seed=0)
    src = pio.write(rec, tmp_path / "rig.h5")
    gear = tmp_path / "gear.toml"
    gear.write_text(SEED_RIG_GEARSET, encoding="utf-8")
    out_parent = tmp_path / "o"
    out_parent.mkdir()
    p = subprocess.Popen([sys.executable, "-m", "meshphase.cli", "-q", "process", str(src), "--gearset", str(gear),
                          "--out", str(out_parent / "pout")], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True, cwd=REPO)
    t_end = time.monotonic() + 120
    while not any(n.startswith(".mp-") for n in _entries(out_parent)) and p.poll() is None:
        assert time.monotonic() < t_end, "no staging folder after 120 s"
        assert not (out_parent / "pout").exists()               # never visible while running
        time.sleep(0.02)
    if p.poll() is not None:                                     # pragma: no cover - a very fast machine
        pytest.skip("the run finished before it could be signalled")
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 128 + signal.SIGTERM, err
    assert "Traceback" not in err
    assert _entries(out_parent) == []


# --------------------------------------------------------------------------- Ctrl-C and the workers
@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="reads /proc")
@pytest.mark.timeout(120, func_only=True)
def test_fork_server_starts_with_sigint_blocked():
    """Started from a thread, as a campaign does: the server (so every worker it forks) has
    SIGINT blocked; the resource tracker ignores it on its own."""
    r = _py("""
        import glob, os, threading
        from meshphase.campaign.cluster import worker_server
        t = threading.Thread(target=worker_server, args=(("json",),)); t.start(); t.join()
        for d in glob.glob("/proc/[0-9]*"):
            try:
                st = open(d + "/status").read()
            except OSError:
                continue
            if f"\\nPPid:\\t{os.getpid()}\\n" in st and "forkserver" in open(d + "/cmdline").read():
                blk = int(next(l for l in st.splitlines() if l.startswith("SigBlk")).split()[1], 16)
                print("server", bool(blk & (1 << (2 - 1))))
        """)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["server", "True"]


@pytest.mark.parametrize("verbose", [False, True])
def test_distributed_is_quiet_from_its_import_unless_verbose(verbose):
    """A campaign's first import of distributed takes its logging config at ERROR (INFO with
    -v), so a cluster closed after the start's quieting ends (an interrupted start) prints no
    INFO lines; the environment variable that does it is gone after the import."""
    r = _py(f"""
        import logging, os, sys
        from meshphase.campaign.cluster import _distributed_config_quiet
        from meshphase.runtime.log import logger
        logger.setLevel(logging.INFO if {verbose} else logging.WARNING)
        with _distributed_config_quiet():
            import distributed
        print(logging.getLogger("distributed").level, "DASK_LOGGING__DISTRIBUTED" in os.environ)
    """)
    assert r.returncode == 0, r.stderr
    level, env = r.stdout.split()
    assert int(level) == (logging.INFO if verbose else logging.ERROR) and env == "False"
