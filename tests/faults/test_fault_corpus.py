"""The fault corpus (``fault_corpus.py``) through the ``meshphase`` command, as a user runs it.

For every case and every command it names, the command must show (issue 10, items 1-3):

* no ``Traceback`` on stdout or stderr;
* an exit code from the documented table (``pipeline/run/exits.py``), one the case accepts, and
  never 0 for a faulty input (a byte flip the reader never sees may exit 0 only when the
  flipped file reads back identical to the original);
* exactly one error line, ``meshphase COMMAND: error: ...``, naming the file (and the key
  and line for scenes); every stderr line starts with ``meshphase COMMAND:`` (no library
  log lines);
* nothing left behind: no output folder or file, no ``.partial`` temporary file;
* no hang: a per-case pytest-timeout (in-process), or a killed child process (cases that
  could hang inside compiled code run as a subprocess);
* under a signal (SIGTERM, SIGKILL then a rerun, Ctrl-C of a campaign): the signal's exit
  code, no traceback, only ``interrupted`` after Ctrl-C, nothing left (the rerun's output
  under its own name).

Each case run is classified (``fault_corpus.OUTCOMES``: clean, silent, traceback, hang, leak,
other) and the session ends with the table by category (``conftest.py``).

Most cases run in-process through :func:`meshphase.cli.main` (fast); a sample runs as the
real command (``python -m meshphase.cli``) to see the real stderr. The default suite runs the
bounded selection; ``-m slow`` runs the sweep (more offsets, seeds and keys).
Known product faults outside the CLI/io scope are ``xfail(strict=True)`` with the file to fix
in the reason (``fault_corpus.py``).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import pytest
from fault_corpus import OUTCOMES, OUTPUTS, Skip, Workspace, build_originals, corpus, outcome_table

import meshphase.io as pio
from meshphase.cli import main
from meshphase.run.exits import EXIT_PARTIAL

REPO = Path(__file__).resolve().parents[2]
DOCUMENTED = {0, 1, 2, 3, 130, 141, 143}   # pipeline/run/exits.py
CASES = corpus()
DEFAULT = [c for c in CASES if not c.slow]
SLOW = [c for c in CASES if c.slow]
#: run as the real command too (stderr as a user sees it); unpatched cases, first command
SUBPROCESS_SAMPLE = ("truncation/mcap/mid-data", "byteflip/tdms/metadata/seed-0",
                     "special/recording/fifo", "scene/toml-syntax-error", "output/parent-is-file")


@pytest.fixture(scope="session")
def originals(tmp_path_factory):
    """The valid recordings and scenes; each command runs once on them first and must exit 0
    (so a case's failure is its fault's, and the lazy imports are paid here, not inside a
    case's timeout); ``process`` exits 3: its phasing and load sharing need more than the
    recordings' 5 s for a pass (an empty requested result is a partial run)."""
    orig = build_originals(tmp_path_factory.mktemp("fault_originals"))
    out = tmp_path_factory.mktemp("fault_clean_runs")
    for fmt, path in orig.recordings.items():
        rc = _quiet_main(["-q", "info", "--no-quality", str(path)])
        assert rc == 0, f"the valid {fmt} recording gives exit {rc}"
    for argv in (["process", str(orig.recordings["tdms"]), "--gearset", str(orig.gearset),
                  "--out", str(out / "p")],
                 ["convert", str(orig.recordings["mcap"]), str(out / "c.h5")],
                 ["run", str(orig.scene), "--out", str(out / "r"), "--no-report"]):
        rc = _quiet_main(["-q", *argv])
        want = EXIT_PARTIAL if argv[0] == "process" else 0
        assert rc == want, f"meshphase {' '.join(argv)} on valid input gives exit {rc}"
    return orig


def _quiet_main(argv) -> int:
    import contextlib
    import io

    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return main(argv)


def _params(cases):
    out = []
    for c in cases:
        marks = [pytest.mark.timeout(c.timeout * max(1, len(c.commands)) + 5, func_only=True)]
        if c.xfail:
            marks.append(pytest.mark.xfail(strict=True, reason=c.xfail))
        if c.slow:
            marks.append(pytest.mark.slow)
        out.append(pytest.param(c, id=c.name, marks=marks))
    return out


# --------------------------------------------------------------------------- running a case
class CaseFault(AssertionError):
    """A requirement a case run did not meet; ``outcome`` says which kind (``OUTCOMES``)."""

    def __init__(self, outcome: str, message: str):
        super().__init__(message)
        self.outcome = outcome


def _require(ok, outcome: str, message: str) -> None:
    if not ok:
        raise CaseFault(outcome, message)


def _build(case, ws) -> dict:
    values = ws.defaults()
    try:
        values.update(case.make(ws))
    except Skip as exc:
        pytest.skip(str(exc))
    return values


def _argv(cmd, values) -> list[str]:
    return ["-q", *(a.format(**values) for a in cmd)]


def _to_stderr(message, category, filename, lineno, file=None, line=None):
    sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))


def _run_inprocess(argv, capsys) -> tuple[int, str, str]:
    capsys.readouterr()
    with warnings.catch_warnings():
        warnings.simplefilter("default")    # warnings are output here, not test errors:
        warnings.showwarning = _to_stderr   # on stderr, where the command's user sees them
        try:
            rc = main(argv)
        except SystemExit as exc:           # argparse: usage errors
            rc = exc.code if isinstance(exc.code, int) else 1
    out, err = capsys.readouterr()
    return rc, out, err


def _run_subprocess(argv, timeout) -> tuple[int, str, str]:
    try:
        r = subprocess.run([sys.executable, "-m", "meshphase.cli", *argv], capture_output=True,
                           text=True, timeout=timeout, cwd=REPO, stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        raise CaseFault("hang", f"meshphase {' '.join(argv)}: no answer after {timeout} s (a hang; the "
                                "process was killed)") from None
    return r.returncode, r.stdout, r.stderr


def _staging(folder: Path) -> bool:
    return folder.is_dir() and any(n.startswith(".mp-") for n in os.listdir(folder))


def _run_signal(case, values) -> None:
    """The first command as the real command, in a session of its own, given ``case.signal``
    once its staging folder exists (SIGINT after 2 s more, to the whole group, as Ctrl-C)."""
    name, rerun = case.signal
    argv = _argv(case.commands[0], values)
    out_dir = Path(values["out"])
    where = f"{case.name}: meshphase {' '.join(argv)}"
    p = subprocess.Popen([sys.executable, "-m", "meshphase.cli", *argv], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, text=True, cwd=REPO,
                         start_new_session=True)
    try:
        deadline = time.monotonic() + case.timeout
        while p.poll() is None and not _staging(out_dir):
            _require(time.monotonic() < deadline, "hang", f"{where}: no staging folder after {case.timeout} s")
            time.sleep(0.02)
        _require(p.poll() is None, "other", f"{where}: finished (exit {p.returncode}) before the signal")
        if name == "SIGINT":
            time.sleep(2.0)                            # the workers under way
            os.killpg(p.pid, signal.SIGINT)
        else:
            p.send_signal(getattr(signal, name))
        try:
            _, err = p.communicate(timeout=case.timeout)
        except subprocess.TimeoutExpired:
            raise CaseFault("hang", f"{where}: no end {case.timeout} s after {name}") from None
    finally:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(p.pid, signal.SIGKILL)          # what is left of the group we started
        p.wait()
    where += f" -> {name}, exit {p.returncode}\nstderr: {err.strip()[:2000]}"
    _require("Traceback" not in err, "traceback", where)
    _require(p.returncode in case.expect, "other", f"expected exit {sorted(case.expect)}; {where}")
    prefix = f"meshphase {argv[1]}: "
    if name == "SIGINT":
        lines = [ln for ln in err.splitlines() if ln.strip()]
        # a campaign says where it kept what it had finished (OUT.partial, for --resume)
        kept = [ln for ln in lines[:-1] if ln.startswith(prefix + "warning: ") and ln.endswith(".partial")]
        _require(lines[-1:] == [prefix + "interrupted"] and len(kept) == len(lines) - 1, "other",
                 f"expected only '{prefix}interrupted' (after where a campaign kept its results); {where}")
    if rerun:
        rc, _, err = _run_subprocess(argv, case.timeout)
        # the rerun ends as the command does on the untouched recording: the corpus's 5-s
        # recording is too short for every pass (partial, outputs written; see the originals)
        want = EXIT_PARTIAL if argv[1] == "process" else 0
        _require(rc == want, "other", f"the rerun gives exit {rc}, expected {want}: {err.strip()[:2000]}; {where}")
        final = Path(case.commands[0][-1].format(**values)).name
        left = sorted(os.listdir(out_dir))
        _require(left == [final], "leak", f"after the rerun {left} in the output folder, expected [{final!r}]; {where}")
    else:
        left = [n for n in os.listdir(out_dir) if not n.endswith(".partial")]   # a campaign's kept results
        _require(not left, "leak", f"{left} left in the output folder; {where}")


def _reads_identical(values) -> bool:
    """The flipped file reads back exactly as the original (samples, specs, metadata; the
    original is read under the same file name, which TDMS puts into the history)."""
    flipped = Path(values["input"])
    ref = flipped.parent / "reference" / flipped.name
    ref.parent.mkdir(exist_ok=True)
    shutil.copyfile(values["original"], ref)
    try:
        return pio.read(flipped) == pio.read(ref)
    except ValueError:
        return False


def _check(case, argv, rc, out, err, values) -> None:
    cmd = argv[1]
    where = f"{case.name}: meshphase {' '.join(argv)} -> exit {rc}\nstderr: {err.strip()[:2000]}"
    _require("Traceback" not in out and "Traceback" not in err, "traceback", where)
    _require(rc in DOCUMENTED, "other", f"undocumented exit code; {where}")
    if rc == 0 and case.may_be_harmless:
        _require(_reads_identical(values), "silent", f"exit 0, but the flipped file reads differently; {where}")
        return
    _require(rc != 0, "silent", f"exit 0 for a faulty input; {where}")
    _require(rc in case.expect, "other", f"expected exit {sorted(case.expect)}; {where}")
    lines = [ln for ln in err.splitlines() if ln.strip()]
    prefix = f"meshphase {cmd}: "
    stray = [ln for ln in lines if not ln.startswith(prefix)]
    _require(not stray, "other", f"stderr lines that are not the command's: {stray[:3]}; {where}")
    if rc == 130:                                            # Ctrl-C: one quiet line
        _require(lines[-1:] == [prefix + "interrupted"], "other", f"expected '{prefix}interrupted'; {where}")
        _nothing_left(values, where)
        return
    errors = [ln for ln in lines if ln.startswith(prefix + "error: ")]
    _require(errors, "silent", f"no error line; {where}")
    _require(len(errors) == 1, "other", f"expected one error line, got {len(errors)}; {where}")
    for key in case.names:
        name = Path(values[key]).name
        _require(name in errors[0], "other", f"the error line does not name {name!r}; {where}")
    for text in case.contains:
        text = text.format(**values)
        _require(text in errors[0], "other", f"the error line does not say {text!r}; {where}")
    if case.max_line is not None:
        _require(len(errors[0]) <= case.max_line, "other", f"an error line of {len(errors[0])} characters; {where}")
    _nothing_left(values, where)


def _nothing_left(values, where) -> None:
    for o in OUTPUTS:
        p = o.format(**values)
        _require(not os.path.lexists(p), "leak", f"{p} left behind by a failed command; {where}")
    out_dir = Path(values["out"])
    if out_dir.is_dir():
        left = [p.name for p in out_dir.iterdir()]
        _require(not left, "leak", f"{left} left in the output folder; {where}")


def _run_case(case, originals, tmp_path, capsys, monkeypatch, *, runner=None, runs=None):
    """Run ``case``; its outcome goes into ``runs`` (a list of (category, outcome))."""
    ws = Workspace(originals, tmp_path)
    outcome = "other"
    try:
        _run_commands(case, ws, capsys, monkeypatch, runner or case.runner)
        outcome = "clean"
    except pytest.skip.Exception:
        outcome = None
        raise
    except CaseFault as exc:
        outcome = exc.outcome
        raise
    except pytest.fail.Exception as exc:          # pytest-timeout's in-process timeout
        outcome = "hang" if "Timeout" in str(exc) else "other"
        raise
    finally:
        for fn in ws.cleanups:
            fn()
        if runs is not None and outcome is not None:
            runs.append((case.category, outcome))


def _run_commands(case, ws, capsys, monkeypatch, runner):
    values = _build(case, ws)
    if case.signal is not None:
        _run_signal(case, values)
        return
    for cmd in case.commands:
        argv = _argv(cmd, values)
        if runner == "subprocess":
            rc, out, err = _run_subprocess(argv, case.timeout)
        else:
            if case.patch is not None:
                case.patch(monkeypatch, values)
            try:
                rc, out, err = _run_inprocess(argv, capsys)
            finally:
                monkeypatch.undo()
        _check(case, argv, rc, out, err, values)
    if case.after is not None:
        case.after(values)


# --------------------------------------------------------------------------- the tests
@pytest.fixture
def runs(pytestconfig):
    """Where the outcomes go for the session's table (``conftest.py``)."""
    return pytestconfig.__dict__.setdefault("_corpus_outcomes", [])


@pytest.mark.parametrize("case", _params(DEFAULT))
def test_fault_case(case, originals, tmp_path, capsys, monkeypatch, runs):
    _run_case(case, originals, tmp_path, capsys, monkeypatch, runs=runs)


@pytest.mark.parametrize("case", _params(SLOW))
def test_fault_case_sweep(case, originals, tmp_path, capsys, monkeypatch, runs):
    _run_case(case, originals, tmp_path, capsys, monkeypatch, runs=runs)


@pytest.mark.parametrize("name", SUBPROCESS_SAMPLE)
@pytest.mark.timeout(120, func_only=True)
def test_fault_case_real_command(name, originals, tmp_path, capsys, monkeypatch):
    """The real command: real exit code, and stderr without tracebacks or library log lines
    (npTDMS logs through ``logging``, which the in-process run does not show)."""
    case = next(c for c in CASES if c.name == name)
    assert case.patch is None and not case.xfail
    case = type(case)(**{**case.__dict__, "commands": case.commands[:1], "timeout": 60.0})
    _run_case(case, originals, tmp_path, capsys, monkeypatch, runner="subprocess")


@pytest.mark.timeout(120, func_only=True)
def test_nptdms_log_lines_become_one_warning_line(originals, tmp_path):
    """npTDMS logs through its own stderr handler (and the root one): the real command shows
    one ``meshphase info: warning: FormatWarning: FILE: npTDMS: ...`` line instead. The file is a TDMS
    whose first lead-in says version 4713 and the others 4712 (harmless: no checksum covers
    it, the samples read the same)."""
    blob = bytearray(originals.blob("tdms"))
    blob[8] ^= 0x01                                     # the version field of the first lead-in
    p = tmp_path / "version.tdms"
    p.write_bytes(bytes(blob))
    rc, out, err = _run_subprocess(["-q", "info", "--no-quality", str(p)], 60)
    assert rc == 0, err
    assert err.splitlines() == [f"meshphase info: warning: FormatWarning: {p}: npTDMS: Segment version "
                                "mismatch, 4712 != 4713"]


@pytest.mark.slow
@pytest.mark.timeout(600, func_only=True)
def test_campaign_over_faulty_recordings(originals, tmp_path):
    """``campaign`` (the real command, one local worker) over a truncated HDF5, an MCAP with a
    flipped CRC and a valid TDMS: exit 3 (some failed), one stderr line naming each failed
    recording, no traceback, no stray log lines; over the two faulty ones only: exit 1."""
    recs = tmp_path / "recs"
    recs.mkdir()
    blob = originals.blob("hdf5")
    (recs / "cut.h5").write_bytes(blob[: len(blob) // 2])
    mcap = bytearray(originals.blob("mcap"))
    lo, hi = originals.regions["mcap"]["checksum"][0]
    mcap[lo] ^= 0x5A
    (recs / "crc.mcap").write_bytes(bytes(mcap))
    scene = tmp_path / "campaign.toml"
    scene.write_text(originals.gearset.read_text().replace('name = "seed rig gearset (fault corpus)"',
                     'name = "campaign"\nresults = ["phasing"]')   # each recording replaces [input]
                     + f'\n[input]\nrecording = "{originals.recordings["tdms"]}"\n', encoding="utf-8")
    for files, want in (((recs / "cut.h5", recs / "crc.mcap", originals.recordings["tdms"]), 3),
                        ((recs / "cut.h5", recs / "crc.mcap"), 1)):
        out = tmp_path / f"camp{want}"
        rc, _, err = _run_subprocess(["-q", "campaign", str(scene), *map(str, files), "--out", str(out),
                                      "--workers", "1"], 400)
        assert rc == want, err
        assert "Traceback" not in err
        lines = [ln for ln in err.splitlines() if ln.strip()]
        assert all(ln.startswith("meshphase campaign: ") for ln in lines), lines
        for bad in ("cut.h5", "crc.mcap"):
            assert len([ln for ln in lines if bad in ln]) == 1, lines


def test_corpus_shape():
    """Every category is there, names are unique, the default selection is bounded and every
    case accepts only documented, non-zero exit codes."""
    cats = {c.category for c in CASES}
    assert cats == {"truncation", "byteflip", "special", "scene", "output", "declared", "signal"}
    assert len({c.name for c in CASES}) == len(CASES)
    assert {c.category for c in DEFAULT} == cats
    assert 100 <= len(DEFAULT) <= 250 and len(SLOW) > 3 * len(DEFAULT)
    for c in CASES:
        # a signal case may expect a death by its signal (SIGKILL: -9 from subprocess)
        assert c.expect and (set(c.expect) <= DOCUMENTED - {0, 2} or c.signal is not None), c.name
        assert c.signal is None or (c.runner == "subprocess" and c.patch is None), c.name
        assert c.commands and all(cmd[0] in ("info", "convert", "process", "run", "campaign")
                                  for cmd in c.commands), c.name
        assert c.runner in ("inprocess", "subprocess"), c.name
        assert c.patch is None or c.runner == "inprocess", c.name
    assert set(SUBPROCESS_SAMPLE) <= {c.name for c in DEFAULT}


def test_outcome_table_counts_by_category():
    table = outcome_table([("declared", "clean"), ("declared", "leak"), ("signal", "hang"), ("x", "clean")])
    rows = {ln.split()[0]: ln.split()[1:] for ln in table.splitlines()[2:]}
    assert table.splitlines()[1].split() == ["category", *OUTCOMES, "total"]
    assert rows == {"declared": ["1", "0", "0", "0", "1", "0", "2"], "signal": ["0", "0", "0", "1", "0", "0", "1"],
                    "x": ["1", "0", "0", "0", "0", "0", "1"], "all": ["2", "0", "0", "1", "1", "0", "4"]}
    empty = outcome_table([]).splitlines()
    assert empty[2].split() == ["all"] + ["0"] * (len(OUTCOMES) + 1)
    with pytest.raises(ValueError, match="'slow' of a 'scene' case"):
        outcome_table([("scene", "slow")])
