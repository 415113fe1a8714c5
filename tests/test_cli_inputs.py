"""The command line's input options (one set for info, convert, process, run, campaign),
the scene's reading tables, ``info`` on an MCAP file of another tool, ``--quality``, global
flags in both positions, progress bars, shell completion, ``python -m meshphase`` and the
output folders under the current directory.

The MCAP files of another tool are written with the mcap project's own ``Writer`` (JSON
message encoding), whose record layout is the MCAP specification's, https://mcap.dev/spec;
the JSON channel encoding is the registry's ``json``,
https://mcap.dev/spec/registry#message-encodings.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from mcap.writer import Writer

import meshphase
import meshphase.io as pio
from meshphase import cli
from meshphase.cli import build_parser, main, parse_topics_arg
from meshphase.io.registry import unregister_format
from meshphase.recording import ChannelSpec, Recording
from meshphase.run.scene import (SceneError, output_folder, parse_scene, read_options,
                                 with_recording)
from meshphase.signal.quality import channel_quality

T0_NS = 1_790_000_000_000_000_000
GEARSET = ('[gearset]\nz_sun = 25\nz_ring = 87\nz_planet = 31\nn_planets = 4\ncarrier_radius_mm = 112.5\n'
           'face_width_mm = 40\ndirection = "cw"\n[speeds]\nsun_rpm = 18.19\ncarrier_rpm = 1.06\n')
MCAP_TABLES = ('[input.mcap]\nfs_Hz = 5120.0\n'
               '[[input.mcap.channels]]\nname = "sun"\ntopic = "/rig/strain"\nfield = "sun"\nkind = "sun"\n'
               '[[input.mcap.channels]]\nname = "ring"\ntopic = "/rig/strain"\nfield = "ring"\nkind = "ring"\n'
               '[[input.mcap.channels]]\nname = "tacho"\ntopic = "/rig/strain"\nfield = "tacho"\n'
               'kind = "tacho"\nunits = "V"\n')


def _foreign_mcap(path: Path, rec: Recording, per_message: int = 512) -> Path:
    """``rec`` as another tool's JSON MCAP: one message per ``per_message`` samples on
    /rig/strain with an array field per channel (consecutive samples, the first at the
    message's log time), and a slow /rig/status topic."""
    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start(profile="", library="test")
        sid = w.register_schema("rig.Strain", "jsonschema", b'{"type": "object"}')
        cid = w.register_channel("/rig/strain", "json", sid)
        other = w.register_channel("/rig/status", "json", 0)
        for k, a in enumerate(range(0, rec.n_samples - per_message + 1, per_message)):
            t = T0_NS + round(a * 1e9 / rec.fs)
            msg = {c.name: rec.data[a:a + per_message, j].tolist() for j, c in enumerate(rec.channels)}
            w.add_message(cid, t, json.dumps(msg).encode(), t)
            if k % 10 == 0:
                w.add_message(other, t, b'{"ok": true, "temp": 21.5}', t)
        w.finish()
    return path


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    """40 s of seed_rig as HDF5 (with its metadata gearset) and as a foreign JSON MCAP."""
    from meshphase.synthetic import generate

    d = tmp_path_factory.mktemp("inputs")
    rec, _ = generate("seed_rig", duration=40.0, seed=5)
    h5 = Path(pio.write(rec, d / "rig.h5"))
    mc = _foreign_mcap(d / "ros.mcap", rec)
    return {"dir": d, "rec": rec, "h5": h5, "mcap": mc}


# --------------------------------------------------------------------------- foreign MCAP
def test_info_lists_the_topics_of_a_foreign_mcap(rig, capsys):
    assert main(["-q", "info", str(rig["mcap"])]) == 0
    out = capsys.readouterr().out
    assert "/rig/strain: schema rig.Strain (jsonschema), messages json" in out
    assert "numeric fields: sun [512], ring [512], tacho [512]" in out
    assert "/rig/status" in out and "--topics" in out
    assert main(["-q", "info", str(rig["mcap"]), "--json"]) == 0
    js = json.loads(capsys.readouterr().out)
    strain = next(t for t in js["topics"] if t["topic"] == "/rig/strain")
    assert strain["message_count"] == 400 and abs(strain["rate_Hz"] - 10.0) < 1e-6
    assert js["foreign"] is True and js["format"] == "mcap"


def test_info_convert_and_process_read_a_foreign_mcap_with_the_scene_tables(rig, tmp_path, capsys,
                                                                            monkeypatch):
    scene = tmp_path / "gearset.toml"
    scene.write_text(GEARSET + MCAP_TABLES, encoding="utf-8")   # [input.mcap] without recording
    assert main(["-q", "info", str(rig["mcap"]), "--scene", str(scene), "--json"]) == 0
    js = json.loads(capsys.readouterr().out)
    assert js["n_samples"] == 400 * 512 and js["fs_hz"] == 5120.0
    assert [r["kind"] for r in js["channel_map"]["rows"]] == ["sun", "ring", "tacho"]
    out = tmp_path / "ros.h5"
    assert main(["-q", "convert", str(rig["mcap"]), str(out), "--scene", str(scene)]) == 0
    back = pio.read(out)
    np.testing.assert_array_equal(back.data, rig["rec"].data[:400 * 512])
    monkeypatch.chdir(tmp_path)
    rc = main(["-q", "process", str(rig["mcap"]), "--gearset", str(scene)])
    err = capsys.readouterr().err
    assert rc in (0, 3), err                       # read and processed: not the no-mapping error
    assert "[[input.mcap.channels]]" not in err
    assert (tmp_path / "ros-meshphase" / "summary.json").is_file()


def test_topics_flag_maps_a_foreign_mcap(rig, tmp_path, capsys):
    out = tmp_path / "sun.h5"
    assert main(["-q", "convert", str(rig["mcap"]), str(out), "--topics",
                 "sun=/rig/strain:sun", "--topics", "ring=/rig/strain:ring", "--fs", "5120"]) == 0
    back = pio.read(out)
    assert back.names == ["sun", "ring"] and back.fs == 5120.0
    np.testing.assert_array_equal(back.data[:, 1], rig["rec"].data[:400 * 512, 1])


def test_parse_topics_arg_pairs_json_empty_and_bad():
    assert parse_topics_arg(["a=/t:x, b=/t:y[2]"]) == {"a": "/t:x", "b": "/t:y[2]"}
    assert parse_topics_arg(['{"a": "/t:x"}', "b=/t:y"]) == {"a": "/t:x", "b": "/t:y"}
    tables = parse_topics_arg(['[{"name": "a", "topic": "/t", "field": "x", "scale": 1e-6}]', "b=/t:y"])
    assert tables == [{"name": "a", "topic": "/t", "field": "x", "scale": 1e-6},
                      {"name": "b", "topic": "/t", "field": "y"}]
    with pytest.raises(ValueError, match="NAME=TOPIC:FIELD"):
        parse_topics_arg([])
    with pytest.raises(ValueError, match="no NAME=TOPIC:FIELD pair"):
        parse_topics_arg(["sun"])
    with pytest.raises(ValueError, match="mapped twice"):
        parse_topics_arg(["a=/t:x", "a=/t:y"])
    with pytest.raises(ValueError, match="not valid JSON"):
        parse_topics_arg(["{a"])


# --------------------------------------------------------------------------- option checks
def test_an_option_the_format_does_not_take_is_refused_naming_it(rig, capsys):
    for cmd in (["info", str(rig["h5"])], ["convert", str(rig["h5"]), str(rig["dir"] / "x.mcap")],
                ["process", str(rig["h5"])]):
        assert main(["-q", *cmd, "--header-row", "2"]) == 1
        err = capsys.readouterr().err
        assert "takes no read option 'header_row'" in err and "--header-row" in err
        assert "the hdf5 reader's options: fs" in err
    assert not (rig["dir"] / "x.mcap").exists()


TEXT_PLUGIN = textwrap.dedent('''
    """A test text format taking the delimited-text reader options."""
    import numpy as np

    from meshphase.io.base import RecordingInfo, check_verify
    from meshphase.io.registry import FormatSpec
    from meshphase.recording import ChannelSpec, Recording

    FORMAT = FormatSpec(name="semitext", module=__name__, suffixes=(".stx",), rate_option=True,
                        read_options={"header_row": int, "skip_rows": int, "fs": float,
                                      "decimal": str, "delimiter": str},
                        description="test: text with a preamble")

    def sniff(head):
        return head.startswith(b"#STX")

    def _rows(path, header_row, skip_rows, decimal, delimiter):
        with open(path, encoding="utf-8") as fh:
            lines = fh.read().splitlines()[1 + (skip_rows or 0):]
        names = lines[(header_row or 1) - 1].split(delimiter or ",")   # a line number, from 1
        rows = [[float(v.replace(decimal or ".", ".")) for v in ln.split(delimiter or ",")]
                for ln in lines[(header_row or 1):]]
        return names, np.array(rows)

    def read_info(path, *, verify=True, header_row=None, skip_rows=None, fs=None, decimal=None,
                  delimiter=None):
        check_verify(verify)
        names, rows = _rows(path, header_row, skip_rows, decimal, delimiter)
        return RecordingInfo(path=str(path), format="semitext", fs=fs or 1.0, n_samples=len(rows),
                             channels=[ChannelSpec(n) for n in names], t0=0.0, start_datetime=None,
                             meta={"options": [header_row, skip_rows, fs, decimal, delimiter]},
                             history=[])

    def read(path, channels=None, i0=0, i1=None, *, verify=True, **opts):
        info = read_info(path, **opts)
        _, rows = _rows(path, opts.get("header_row"), opts.get("skip_rows"), opts.get("decimal"),
                        opts.get("delimiter"))
        cols = [info.names.index(n) for n in (channels or info.names)]
        return Recording(rows[i0:i1][:, cols], info.fs, [info.channels[c] for c in cols],
                         t0=i0 / info.fs, meta=info.meta)
''')


@pytest.fixture
def semitext(tmp_path, monkeypatch):
    (tmp_path / "semitext_fmt.py").write_text(TEXT_PLUGIN, encoding="utf-8")
    monkeypatch.syspath_prepend(str(tmp_path))
    import importlib

    mod = importlib.import_module("semitext_fmt")
    pio.register_format(mod.FORMAT)
    path = tmp_path / "daq.stx"
    path.write_text("#STX\nDAQ export\nsecond line\nsun;ring\n1,5;2,0\n3,0;4,25\n", encoding="utf-8")
    yield path
    unregister_format("semitext")
    sys.modules.pop("semitext_fmt", None)


def test_text_options_reach_the_reader_from_flags_and_from_the_scene(semitext, tmp_path, capsys):
    flags = ["--skip-rows", "2", "--header-row", "1", "--decimal", ",", "--delimiter", ";", "--fs", "100"]
    with pytest.raises(SystemExit):                      # a line number counts from 1
        main(["-q", "info", str(semitext), "--header-row", "0"])
    capsys.readouterr()
    assert main(["-q", "info", str(semitext), "--json", *flags]) == 0
    js = json.loads(capsys.readouterr().out)
    assert js["meta"]["options"] == [1, 2, 100.0, ",", ";"]
    assert [c["name"] for c in js["channels"]] == ["sun", "ring"] and js["fs_hz"] == 100.0
    scene = tmp_path / "s.toml"
    scene.write_text(GEARSET + '[input]\nfs_Hz = 50.0\n[input.csv]\nskip_rows = 2\ndecimal = ","\n'
                     'delimiter = ";"\n', encoding="utf-8")
    assert main(["-q", "info", str(semitext), "--json", "--scene", str(scene), "--fs", "200"]) == 0
    js = json.loads(capsys.readouterr().out)
    assert js["meta"]["options"] == [None, 2, 200.0, ",", ";"]     # the flag over the table
    assert main(["-q", "info", str(semitext), "--quality", "--json", *flags]) == 0
    q = json.loads(capsys.readouterr().out)["quality"]
    assert q["sun"]["min"] == 1.5 and q["ring"]["max"] == 4.25


def test_scene_csv_table_is_checked_and_becomes_read_options(tmp_path, rig):
    sc = parse_scene('results = ["phasing"]\n' + GEARSET + '[input.csv]\nheader_row = 3\ndecimal = ","\n',
                     tmp_path / "s.toml", recording_given=True)
    assert read_options(sc) == {"header_row": 3, "decimal": ","}
    inp = with_recording(sc, rig["h5"], {"fs": 10.0})
    assert inp["recording"] == rig["h5"] and inp["csv"] == {"header_row": 3, "decimal": ","}
    assert read_options(type(sc)(path=None, name="x", results=[], input=inp)) == {
        "header_row": 3, "decimal": ",", "fs": 10.0}
    with pytest.raises(SceneError, match=r"input.csv.header_row.*hdf5 file, which takes no header_row"):
        parse_scene('results = ["phasing"]\n' + GEARSET + f'[input]\nrecording = "{rig["h5"]}"\n'
                    '[input.csv]\nheader_row = 3\n', tmp_path / "s.toml")
    with pytest.raises(SceneError, match="give \\[input\\] recording"):
        parse_scene('results = ["phasing"]\n' + GEARSET + '[input.csv]\nskip_rows = 1\n', tmp_path / "s.toml")
    with pytest.raises(SceneError, match="input.csv.decimal"):
        parse_scene('results = ["phasing"]\n' + GEARSET + '[input.csv]\ndecimal = ",,"\n', tmp_path / "s.toml",
                    recording_given=True)
    with pytest.raises(SceneError, match="both ','"):
        parse_scene('results = ["phasing"]\n' + GEARSET + '[input.csv]\ndecimal = ","\ndelimiter = ","\n',
                    tmp_path / "s.toml", recording_given=True)
    with pytest.raises(TypeError, match="options must be a dict"):
        with_recording(sc, rig["h5"], ["fs"])
    with pytest.raises(TypeError, match="scene must be a Scene"):
        with_recording({}, rig["h5"])


def test_campaign_worker_scene_keeps_the_tables_and_takes_the_flags(tmp_path, rig):
    from meshphase.campaign.runner import _worker_scene

    sc = parse_scene('results = ["phasing"]\n' + GEARSET + MCAP_TABLES, tmp_path / "s.toml",
                     recording_given=True)
    ws = _worker_scene(sc, rig["mcap"], False, {"max_jitter": 1e-4})
    assert ws.input["recording"] == rig["mcap"] and read_options(ws)["max_jitter"] == 1e-4
    assert len(read_options(ws)["topics"]) == 3


# --------------------------------------------------------------------------- info --quality
def test_quality_scan_in_one_pass_equals_the_whole_channel_summary(tmp_path, capsys, monkeypatch):
    rng = np.random.default_rng(1)
    x = rng.standard_normal((5000, 2))
    x[100:110, 0] = np.nan
    x[1023:1026, 0] = np.inf             # across a block boundary (blocks of 1024 below)
    x[2040:2050, 1] = x[:, 1].max() + 1  # the clipped rail, across a boundary
    x[4000:4004, 1] = x[:, 1].min() - 1
    rec = Recording(x, 1000.0, [ChannelSpec("a"), ChannelSpec("b")])
    p = Path(pio.write(rec, tmp_path / "q.h5"))
    monkeypatch.setattr(cli, "QUALITY_BLOCK", 1024)
    assert main(["-q", "info", str(p), "--quality", "--json"]) == 0
    q = json.loads(capsys.readouterr().out)["quality"]
    for j, name in enumerate("ab"):
        ref = channel_quality(x[:, j])
        assert q[name]["n_nonfinite"] == ref["n_nonfinite"]
        assert q[name]["nonfinite_runs"] == len(ref["nonfinite_runs"])
        assert q[name]["min"] == ref["min"] and q[name]["max"] == ref["max"]
    assert q["a"]["nonfinite_runs"] == 2 and q["b"]["clipped_runs"] == 2


def test_info_default_reads_no_samples(rig, capsys, monkeypatch):
    def boom(*a, **k):
        raise AssertionError("info read samples without --quality")

    monkeypatch.setattr(cli, "iter_blocks", boom)
    assert main(["-q", "info", str(rig["h5"])]) == 0
    assert "not scanned (--quality" in capsys.readouterr().out
    assert main(["-q", "info", str(rig["h5"]), "--no-quality"]) == 0      # the old name still works


# --------------------------------------------------------------------------- process gearset
def test_process_takes_the_gearset_of_the_file_and_says_so(rig, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    rc = main(["-q", "process", str(rig["h5"])])
    err = capsys.readouterr().err
    assert rc in (0, 3)
    assert "meshphase process: info: gearset: from the file's metadata (Z 25/87/31, 4 planets)" in err
    assert (tmp_path / "rig-meshphase" / "summary.json").is_file()


def test_process_without_any_gearset_names_both_ways(tmp_path, capsys):
    p = Path(pio.write(Recording(np.zeros((100, 1)), 100.0, [ChannelSpec("sun", kind="sun")]),
                       tmp_path / "plain.h5"))
    assert main(["-q", "process", str(p), "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err
    assert "--gearset" in err and "--scene" in err and "metadata carries none" in err
    assert not (tmp_path / "o").exists()


# --------------------------------------------------------------------------- layout
def test_convert_layout_foxglove_and_refused_elsewhere(rig, tmp_path, capsys):
    out = tmp_path / "fox.mcap"
    assert main(["-q", "convert", str(rig["h5"]), str(out), "--layout", "foxglove"]) == 0
    assert any(t["message_encoding"] == "json" for t in pio.mcap.describe_topics(out))
    assert main(["-q", "convert", str(rig["h5"]), str(tmp_path / "x.h5"), "--layout", "foxglove"]) == 1
    assert "a hdf5 file has no layouts" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        build_parser().parse_args(["convert", "a", "b.mcap", "--layout", "nope"])


# --------------------------------------------------------------------------- global flags
@pytest.mark.parametrize("argv", [["-q", "-v", "info", "f"], ["info", "f", "-q", "-v"],
                                  ["-v", "info", "-q", "f"]])
def test_global_flags_before_and_after_the_subcommand(argv):
    args = cli._merge_globals(build_parser().parse_args(argv))
    assert args.quiet is True and args.verbose == 1 and args.command == "info"
    assert not any(k.startswith("after_") for k in vars(args))


def test_verbose_counts_add_up_and_any_fs_after(rig):
    args = cli._merge_globals(build_parser().parse_args(["-v", "info", str(rig["h5"]), "-v",
                                                         "--any-fs", "--debug"]))
    assert args.verbose == 2 and args.any_fs and args.debug
    args = cli._merge_globals(build_parser().parse_args(["info", "f"]))
    assert args.verbose == 0 and not args.quiet and not args.any_fs


def test_python_dash_m_meshphase_runs_the_command():
    r = subprocess.run([sys.executable, "-m", "meshphase", "--version"], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0 and r.stdout.startswith("meshphase ")
    r = subprocess.run([sys.executable, "-m", "meshphase", "info"], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 2 and "usage: meshphase info" in r.stderr


# --------------------------------------------------------------------------- progress bars
def test_no_bar_when_stderr_is_not_a_terminal(rig, tmp_path, capsys, monkeypatch):
    assert main(["convert", str(rig["h5"]), str(tmp_path / "a.csv")]) == 0
    assert capsys.readouterr().err == ""            # a log file gets no bar lines

    class Tty:
        def isatty(self):
            return True

    class Pipe:
        def isatty(self):
            return False

    ns = build_parser().parse_args(["info", "f"])
    monkeypatch.setattr(sys, "stderr", Tty())
    assert cli._bars(ns) is True
    ns.quiet = True
    assert cli._bars(ns) is False
    ns.quiet = False
    monkeypatch.setattr(sys, "stderr", Pipe())
    assert cli._bars(ns) is False


# --------------------------------------------------------------------------- completion
def _complete(line: str) -> list[str]:
    """argcomplete's documented test approach: ``COMP_LINE`` / ``COMP_POINT`` and
    ``_ARGCOMPLETE=1`` in the environment of the command, the completions read from its output
    fd 8 (https://kislyuk.github.io/argcomplete/, "Debugging"; in a subprocess, since
    argcomplete takes fds 8 and 9 of the process it runs in)."""
    env = dict(os.environ, _ARGCOMPLETE="1", _ARGCOMPLETE_IFS="\013", COMP_LINE=line,
               COMP_POINT=str(len(line)), _ARGCOMPLETE_SUPPRESS_SPACE="1")
    r = subprocess.run(["bash", "-c", f'"{sys.executable}" -m meshphase 8>&1 9>/dev/null'], env=env,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    return [c.strip() for c in r.stdout.split("\013")]


def test_completion_of_commands_options_formats_and_scenarios():
    assert {"info", "convert", "process", "run", "campaign", "completion"} <= set(_complete("meshphase "))
    assert {"--topics", "--header-row", "--skip-rows", "--fs", "--decimal", "--delimiter",
            "--scene", "--quality", "--quiet", "--any-fs"} <= set(_complete("meshphase info --"))
    assert {"hdf5", "mcap", "csv", "tdms"} <= set(_complete("meshphase convert a b --format "))
    assert _complete("meshphase convert a b --layout f") == ["foxglove"]
    assert "seed_rig" in _complete("meshphase synth seed")


def test_completion_command_prints_the_activation_code(capsys):
    assert main(["completion", "bash"]) == 0
    out = capsys.readouterr().out
    assert "complete " in out and "meshphase" in out and "_ARGCOMPLETE" in out
    assert main(["completion", "zsh"]) == 0
    assert "#compdef meshphase" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        build_parser().parse_args(["completion", "cmd.exe"])


# --------------------------------------------------------------------------- output folders
def test_output_folder_is_relative_to_the_current_directory(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert output_folder("res") == tmp_path / "res"
    assert output_folder(tmp_path / "abs") == tmp_path / "abs"
    with pytest.raises(ValueError, match="folder path"):
        output_folder("")
    with pytest.raises(ValueError, match="folder path"):
        output_folder(3)
    sc = parse_scene('output = "there"\nresults = ["ideal_phasing"]\n' + GEARSET,
                     tmp_path / "scenes" / "s.toml")
    assert sc.output == tmp_path / "there"


def test_flags_on_a_scene_without_a_recording_are_refused(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    scene = tmp_path / "ideal.toml"
    scene.write_text('results = ["ideal_phasing"]\n' + GEARSET, encoding="utf-8")
    assert main(["-q", "run", str(scene), "--fs", "100"]) == 1
    err = capsys.readouterr().err
    assert "--fs: the scene" in err and "reads no recording" in err
    assert not (tmp_path / "ideal-meshphase").exists()
