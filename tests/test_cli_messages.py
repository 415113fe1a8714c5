"""What the command prints (issue 12, item 7): one message style on stderr
(``meshphase COMMAND: LEVEL: TEXT``) for errors, run warnings, Python warnings and log
records; output commands survive a reader that closes the pipe early; help texts say what
the commands do; ``synth --list`` lists the scenarios."""

from __future__ import annotations

import argparse
import logging
import re
import subprocess
import sys
from pathlib import Path

import pytest

from meshphase.cli import build_parser, main
from meshphase.run.exits import EXIT_PIPE
from meshphase.runtime.log import MessageFormatter, message_line
from meshphase.synthetic import list_scenarios

REPO = Path(__file__).resolve().parents[1]
STYLE = re.compile(r"^meshphase( \w+)?: (error|warning|info|debug|partial|unreliable|interrupted|failed)(: .+)?$")


# --------------------------------------------------------------------------- message_line
def test_message_line_one_style_on_one_line():
    assert message_line("process", "warning", "phasing: ProcessingWarning: a\n  b") == (
        "meshphase process: warning: phasing: ProcessingWarning: a b")
    assert message_line("", "error", "x") == "meshphase: error: x"
    assert STYLE.match(message_line("info", "error", "bad file"))


def test_message_line_empty_text_ends_after_the_level():
    assert message_line("process", "interrupted", "") == "meshphase process: interrupted"
    assert message_line("process", "interrupted", "  \n ") == "meshphase process: interrupted"


def test_message_line_bad_input():
    with pytest.raises(TypeError, match="strings"):
        message_line(None, "warning", "x")
    with pytest.raises(TypeError, match="strings"):
        message_line("run", 3, "x")
    with pytest.raises(ValueError, match="level"):
        message_line("run", " ", "x")


# --------------------------------------------------------------------------- log formatter
def _record(name, level, msg, *args, exc_info=None):
    return logging.LogRecord(name, level, __file__, 1, msg, args, exc_info)


def test_formatter_lines_match_the_style():
    f = MessageFormatter("campaign")
    assert f.format(_record("meshphase", logging.WARNING, "campaign: %s failed: %s", "a.h5", "boom")) == (
        "meshphase campaign: warning: a.h5 failed: boom")       # no "campaign: campaign:"
    assert f.format(_record("meshphase.io", logging.INFO, "wrote %s", "x")) == "meshphase campaign: info: wrote x"
    assert f.format(_record("distributed.scheduler", logging.ERROR, "lost")) == (
        "meshphase campaign: error: distributed.scheduler: lost")


def test_formatter_keeps_a_traceback_for_debug():
    try:
        raise ValueError("inner")
    except ValueError:
        rec = _record("meshphase", logging.DEBUG, "stage %s traceback", "load", exc_info=sys.exc_info())
    text = MessageFormatter("run").format(rec)
    first, *rest = text.splitlines()
    assert first == "meshphase run: debug: stage load traceback"
    assert rest[0].startswith("Traceback") and "ValueError: inner" in rest[-1]


def test_formatter_empty_message_and_bad_input():
    assert MessageFormatter("").format(_record("meshphase", logging.WARNING, "")) == "meshphase: warning"
    with pytest.raises(TypeError, match="command"):
        MessageFormatter(None)


# --------------------------------------------------------------------------- the command
def _cli(*args, timeout=300):
    return subprocess.run([sys.executable, "-m", "meshphase.cli", *args], capture_output=True,
                          text=True, timeout=timeout, cwd=REPO)


def test_log_records_and_warnings_of_a_command_share_the_style(tmp_path):
    r = _cli("-q", "-v", "synth", "seed_rig", str(tmp_path / "x.csv"), "--minutes", "0.02", "--seed", "1")
    assert r.returncode == 0, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert lines and all(STYLE.match(ln) for ln in lines), lines
    assert any(ln.startswith("meshphase synth: info: ") for ln in lines)
    assert "WARNING" not in r.stderr and "INFO meshphase" not in r.stderr
    # the CSV reader announces the missing [units] of a plain CSV: a warning line, same style
    plain = tmp_path / "plain.csv"
    plain.write_text("time,sun\n0,1\n0.001,2\n0.002,3\n", encoding="utf-8")
    r = _cli("-q", "info", "--no-quality", str(plain))
    warn = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert all(STYLE.match(ln) for ln in warn), warn


def test_run_warnings_go_to_stderr_in_the_style(tmp_path, capsys):
    from meshphase.synthetic import generate
    from seed_rig_toml import SEED_RIG_GEARSET

    import meshphase.io

    rec, _ = generate("gaps", duration=15.0, seed=2)    # NaN runs: DataQualityWarnings
    path = meshphase.io.write(rec, tmp_path / "gaps.h5")
    gs = tmp_path / "gs.toml"
    gs.write_text('name = "rig"\n' + SEED_RIG_GEARSET, encoding="utf-8")
    main(["-q", "process", str(path), "--gearset", str(gs), "--out", str(tmp_path / "o")])
    cap = capsys.readouterr()
    assert not [ln for ln in cap.out.splitlines() if ln.startswith("warning") or ": warning: " in ln]
    warns = [ln for ln in cap.err.splitlines() if ": warning: " in ln]
    assert warns and all(STYLE.match(ln) for ln in cap.err.splitlines() if ln.strip())
    assert any(ln.startswith("meshphase process: warning: load: DataQualityWarning: ") for ln in warns)


# --------------------------------------------------------------------------- closed pipe
@pytest.mark.parametrize("args", [["synth", "--list"], ["synth"]])
def test_output_into_a_closed_pipe_exits_141_quietly(args):
    # the reader is gone before meshphase writes (imports alone take longer): EPIPE for sure
    p = subprocess.Popen([sys.executable, "-m", "meshphase.cli", "-q", *args], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, cwd=REPO)
    p.stdout.close()
    _, err = p.communicate(timeout=120)
    assert p.returncode == EXIT_PIPE and err.decode() == ""


def test_help_into_a_closed_pipe_has_no_traceback():
    # argparse writes --help itself and ignores the closed pipe: exit 0, nothing on stderr
    p = subprocess.Popen([sys.executable, "-m", "meshphase.cli", "process", "--help"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=REPO)
    p.stdout.close()
    _, err = p.communicate(timeout=120)
    assert p.returncode in (0, EXIT_PIPE) and err.decode() == ""


def test_synth_list_piped_to_head_one_line():
    r = subprocess.run(["bash", "-c", f"{sys.executable} -m meshphase.cli synth --list | head -1; "
                        "echo \"rc=${PIPESTATUS[0]}\""], capture_output=True, text=True, timeout=120,
                       cwd=REPO)
    first, rc = r.stdout.splitlines()
    assert first.split()[0] == list_scenarios()[0]
    assert rc in ("rc=0", f"rc={EXIT_PIPE}") and r.stderr == ""


# --------------------------------------------------------------------------- help texts
def _subparsers():
    p = build_parser()
    return next(a for a in p._actions if isinstance(a, argparse._SubParsersAction)).choices


def test_every_option_of_every_subcommand_has_help():
    for name, sp in _subparsers().items():
        for a in sp._actions:
            if a.option_strings:
                assert a.help, f"meshphase {name} {a.option_strings[0]}: no help text"


def test_output_folder_help_names_the_folder_really_used(tmp_path):
    helps = {name: sp.format_help() for name, sp in _subparsers().items()}
    assert "FILE-meshphase" not in helps["process"] and "STEM-meshphase" in helps["process"]
    assert "--tolerance" in helps["process"]
    assert "STEM-meshphase" in helps["run"] and "current directory" in helps["run"]


def test_synth_list_names_every_scenario_without_python_calls(capsys):
    assert main(["synth", "--list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [ln.split()[0] for ln in lines] == list_scenarios()
    for ln in lines:
        name, _fs, hz, _dur, s, description = ln.split(maxsplit=5)
        assert (hz, s) == ("Hz", "s") and description
        assert not re.search(r"\w\(|generate_blocks|describe_scenarios|list_scenarios", description), ln


def test_synth_without_arguments_lists_and_exits_2(capsys):
    assert main(["synth"]) == 2
    cap = capsys.readouterr()
    assert len(cap.out.splitlines()) == len(list_scenarios())
    assert cap.err.splitlines()[-1] == ("meshphase synth: error: SCENARIO and OUT are required "
                                        "(the scenarios are listed above)")


def test_convert_to_csv_refuses_compression_in_one_line(tmp_path, capsys):
    src = tmp_path / "a.csv"
    src.write_text("time,sun\n0,1\n0.001,2\n", encoding="utf-8")
    assert main(["-q", "convert", str(src), str(tmp_path / "b.csv"), "--compression", "gzip"]) == 1
    err = capsys.readouterr().err.splitlines()
    assert err[-1] == ("meshphase convert: error: --compression gzip: CSV is written uncompressed "
                       "(compression is for hdf5 and mcap)")
    assert not (tmp_path / "b.csv").exists()
