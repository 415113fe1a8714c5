"""The ``meshphase`` command: run / process / demo write results without overwriting earlier
ones, the report carries its sections, bad input exits 1 naming the file (exit table in
pipeline/run/exits.py; more in test_exit_status.py); info, convert and
synth on small generated files (issue 6, item 3).

Most tests call :func:`meshphase.cli.main` in-process (no interpreter start-up); one runs the
module as a subprocess to check the real exit code.
"""

from __future__ import annotations

import base64
import io as _io
import json
import re
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from seed_rig_toml import SEED_RIG_GEARSET

import meshphase.io
from meshphase.cli import main
from meshphase.recording import ChannelSpec, Recording

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"

GEARSET_TOML = 'name = "seed rig gearset"\n' + SEED_RIG_GEARSET


def _sections(html: str) -> dict:
    """Report section title -> its HTML."""
    out = {}
    for m in re.finditer(r'<section id="[^"]+"><h2>(.*?)</h2>(.*?)</section>', html, re.S):
        out[m.group(1)] = m.group(2)
    return out


def _table_rows(fragment: str) -> list[list[str]]:
    """Cells of every table row in an HTML fragment (tags stripped)."""
    rows = []
    for tr in re.findall(r"<tr>(.*?)</tr>", fragment, re.S):
        rows.append([re.sub(r"<[^>]+>", "", c) for c in re.findall(r"<t[dh][^>]*>(.*?)</t[dh]>", tr, re.S)])
    return rows


def _embedded_pngs(html: str) -> list[bytes]:
    return [base64.b64decode(b) for b in re.findall(r'src="data:image/png;base64,([^"]+)"', html)]


def _assert_png_not_blank(png: bytes) -> None:
    from PIL import Image

    img = np.asarray(Image.open(_io.BytesIO(png)).convert("L"), dtype=float)
    assert img.shape[0] > 50 and img.shape[1] > 50
    assert img.std() > 5.0          # a figure with axes, lines, text: not one flat colour


# --------------------------------------------------------------------------- bad input
def test_run_bad_scene_exits_1_naming_file_key_and_line(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    p = tmp_path / "bad.toml"
    p.write_text('results = ["bearing_moments"]\n[bearing]\ncase = "1"\ntorque = 5\n', encoding="utf-8")
    assert main(["-q", "run", str(p)]) == 1
    err = capsys.readouterr().err
    assert str(p) in err and "line 4" in err and "bearing.torque" in err
    assert not (tmp_path / "bad-meshphase").exists()     # nothing written for a scene that failed


def test_run_missing_scene_exits_1(tmp_path, capsys):
    p = tmp_path / "missing.toml"
    assert main(["-q", "run", str(p)]) == 1
    assert str(p) in capsys.readouterr().err


def test_run_scene_with_missing_recording_exits_1(tmp_path, capsys):
    p = tmp_path / "rec.toml"
    p.write_text('results = ["phasing"]\n' + GEARSET_TOML.split("name =", 1)[1].split("\n", 1)[1]
                 + '[input]\nrecording = "no_such.h5"\n', encoding="utf-8")
    assert main(["-q", "run", str(p)]) == 1
    err = capsys.readouterr().err
    assert "no_such.h5" in err and "input.recording" in err


def test_process_missing_recording_exits_1(tmp_path, capsys):
    gs = tmp_path / "gs.toml"
    gs.write_text(GEARSET_TOML, encoding="utf-8")
    assert main(["-q", "process", str(tmp_path / "none.h5"), "--gearset", str(gs)]) == 1
    assert "none.h5" in capsys.readouterr().err


def test_exit_code_of_the_real_command(tmp_path):
    p = tmp_path / "syntax.toml"
    p.write_text('results = ["phasing"\n', encoding="utf-8")
    r = subprocess.run([sys.executable, "-m", "meshphase.cli", "-q", "run", str(p)],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 1                     # a bad scene: input error (2 is usage only)
    assert str(p) in r.stderr and "TOML syntax error" in r.stderr
    assert "Traceback" not in r.stderr


# --------------------------------------------------------------------------- run
def test_run_never_overwrites_unless_asked(tmp_path, capsys, monkeypatch):
    scene = tmp_path / "scenes" / "bearing.toml"
    scene.parent.mkdir()
    scene.write_text((EXAMPLES / "bearing_moments.toml").read_text(encoding="utf-8"), encoding="utf-8")
    monkeypatch.chdir(tmp_path)
    assert main(["-q", "run", str(scene)]) == 0
    first = tmp_path / "bearing-meshphase"       # in the current directory, not beside the scene
    assert [p.name for p in scene.parent.iterdir()] == ["bearing.toml"]
    summary = (first / "summary.json").read_text()
    out = capsys.readouterr().out
    assert "bearing_moments" in out and "report" in out
    # the second and third runs skip the report (figures are the slow part; not needed here)
    assert main(["-q", "run", str(scene), "--no-report"]) == 0
    second = tmp_path / "bearing-meshphase-2"
    assert second.is_dir()
    assert (first / "summary.json").read_text() == summary
    html = (first / "report.html").read_text(encoding="utf-8")
    names = {p.name for p in first.iterdir()}
    assert {"summary.json", "tilt.csv", "stages.csv", "arrays.h5", "report.html", "figures"} <= names
    assert main(["-q", "run", str(scene), "--overwrite", "--no-report"]) == 0
    assert not (tmp_path / "bearing-meshphase-3").exists()
    assert {"summary.json", "tilt.csv", "stages.csv", "arrays.h5"} <= {p.name for p in second.iterdir()}
    # --overwrite replaced the folder: no report.html / figures of the earlier run beside the new summary
    names = {p.name for p in first.iterdir()}
    assert {"summary.json", "tilt.csv", "stages.csv", "arrays.h5"} <= names
    assert not names & {"report.html", "figures"}
    sec = _sections(html)
    bm = next(v for k, v in sec.items() if k.startswith("Bearing moments"))
    # the model's moments with seed 001 Table 10 (GSAM) side by side
    assert "GSAM GA" in bm and "Table 10" in bm
    tilt = sec["Coupled bearing tilt / load distribution"]
    assert "GSAM My" in tilt
    rows = _table_rows(sec["Error against run time"])
    assert [r[0] for r in rows[1:]] == ["bearing_moments", "tilt"]
    assert json.loads(summary)["stages_ran"] == ["bearing_moments", "tilt"]


def test_run_no_report_and_out_option(tmp_path):
    scene = EXAMPLES / "bearing_double_pinion.toml"
    out = tmp_path / "dp"
    assert main(["-q", "run", str(scene), "--out", str(out), "--no-report"]) == 0
    assert (out / "summary.json").is_file() and not (out / "report.html").exists()


@pytest.fixture(scope="module")
def rig_cli_run(tmp_path_factory):
    """``meshphase run`` on the rig-validation example (0.5 min of seed_rig, 256 MC samples)."""
    d = tmp_path_factory.mktemp("cli_rig")
    text = (EXAMPLES / "rig_validation.toml").read_text(encoding="utf-8")
    text = text.replace("minutes = 1.0", "minutes = 0.5").replace("samples = 4096", "samples = 256")
    scene = d / "rig.toml"
    scene.write_text(text, encoding="utf-8")
    rc = main(["-q", "run", str(scene), "--out", str(d / "rig-out")])
    return rc, d / "rig-out"


def test_run_rig_scene_writes_everything(rig_cli_run):
    rc, out = rig_cli_run
    assert rc == 0
    names = {p.name for p in out.iterdir()}
    assert {"summary.json", "passes_sun.csv", "passes_ring.csv", "load_sharing.csv",
            "identified_errors.csv", "stages.csv", "arrays.h5", "report.html", "figures"} <= names
    with h5py.File(out / "arrays.h5", "r") as f:
        assert set(f["onsets"]) == {"sun", "ring"}
        assert f["onsets/sun/times"].shape[0] > 10
    figs = sorted(p.name for p in (out / "figures").glob("*.png"))
    assert {"onsets_sun.png", "onsets_ring.png", "phasing.png", "residuals.png",
            "load_sharing.png", "stage_times.png"} <= set(figs)
    # seed_rig is clean: no quality chart of zeros, a sentence instead
    assert "quality.png" not in figs
    assert "No non-finite samples and no clipped runs" in (out / "report.html").read_text(encoding="utf-8")


def test_rig_report_sections(rig_cli_run):
    _, out = rig_cli_run
    html = (out / "report.html").read_text(encoding="utf-8")
    sec = _sections(html)
    for title in ("Summary", "Recording and its quality", "Engagement onsets",
                  "Measured phasing against the models", "Identified shaft hole errors",
                  "Error against run time"):
        assert title in sec, title
    assert any(t.startswith("Planet load sharing") for t in sec)
    phasing = sec["Measured phasing against the models"]
    assert "Monte Carlo 3σ band" in phasing and "inside MC 3σ band" in phasing
    assert "Residual histograms" in phasing
    # no bearing results asked for (base64 image data can spell anything: look at the text)
    assert "GSAM" not in re.sub(r"data:image/png;base64,[A-Za-z0-9+/=]+", "", html)
    summary = json.loads((out / "summary.json").read_text())
    rows = _table_rows(sec["Error against run time"])
    assert rows[0][:3] == ["stage", "wall time [s]", "error estimate"]
    by_stage = {r[0]: r for r in rows[1:]}
    assert list(by_stage) == summary["stages_ran"]
    for stage, r in by_stage.items():
        assert float(r[1]) >= 0.0, stage               # a wall time
        assert r[2].strip(), stage                     # and an error estimate
        assert r[3] == "ran"


def test_rig_report_figures_are_not_empty(rig_cli_run):
    _, out = rig_cli_run
    pngs = _embedded_pngs((out / "report.html").read_text(encoding="utf-8"))
    assert len(pngs) == len(list((out / "figures").glob("*.png")))
    for png in pngs:
        _assert_png_not_blank(png)


# --------------------------------------------------------------------------- process
def test_process_writes_in_the_current_directory(tmp_path, capsys, monkeypatch):
    from meshphase.synthetic import generate

    # 40 s: a shorter noise-free record cannot fit the planets' own offsets apart from the
    # speed (too few passes) and is, rightly, flagged unreliable against its tiny floor
    rec, _ = generate("seed_rig", duration=40.0, seed=5)
    path = Path(meshphase.io.write(rec, tmp_path / "rig.h5"))
    gs = tmp_path / "gearset.toml"
    gs.write_text(GEARSET_TOML, encoding="utf-8")
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    before = sorted(p.name for p in tmp_path.iterdir())
    assert main(["-q", "process", str(path), "--gearset", str(gs)]) == 0
    out = capsys.readouterr().out
    assert "sun phasing" in out and "load sharing planet 1" in out and "RMS residual" in out
    assert sorted(p.name for p in tmp_path.iterdir()) == before    # nothing beside the recording
    assert [p.name for p in work.iterdir()] == ["rig-meshphase"]
    assert (work / "rig-meshphase" / "summary.json").is_file()
    assert main(["-q", "process", str(path), "--gearset", str(gs)]) == 0
    assert (work / "rig-meshphase-2" / "summary.json").is_file()


# --------------------------------------------------------------------------- info / convert / synth
def _small_recording(n: int = 3000) -> Recording:
    rng = np.random.default_rng(3)
    data = rng.standard_normal((n, 3)) * np.array([1e-5, 3e-6, 1.0])
    data[0, 0] = -0.0
    data[5, 1] = np.nextafter(1e-6, 1.0)            # last-digit values must survive
    specs = [ChannelSpec("sun", kind="sun", gear="sun", tooth=0),
             ChannelSpec("ring", kind="ring", gear="ring", tooth=2),
             ChannelSpec("tacho", kind="tacho", units="V")]
    return Recording(data, 5120.0, specs, t0=1.25, start_datetime="2025-03-04T05:06:07+00:00")


def test_info_text_and_json(tmp_path, capsys):
    p = Path(meshphase.io.write(_small_recording(), tmp_path / "small.h5"))
    assert main(["-q", "info", str(p)]) == 0
    out = capsys.readouterr().out
    assert "hdf5" in out and "5120 Hz" in out and "3000" in out
    for name in ("sun", "ring", "tacho"):
        assert re.search(rf"^\s+{name}\s", out, re.M)
    assert main(["-q", "info", str(p), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["format"] == "hdf5" and info["n_samples"] == 3000 and info["fs_hz"] == 5120.0
    assert info["t0_s"] == 1.25
    assert [c["name"] for c in info["channels"]] == ["sun", "ring", "tacho"]
    assert "quality" not in info            # the header only, by default: no sample scan
    assert main(["-q", "info", str(p), "--json", "--quality"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["quality"]["sun"]["n_nonfinite"] == 0


def test_info_missing_and_unknown_files(tmp_path, capsys):
    assert main(["-q", "info", str(tmp_path / "nope.h5")]) == 1
    assert "nope.h5" in capsys.readouterr().err
    junk = tmp_path / "junk.bin"
    junk.write_bytes(b"\x00\x01 not a recording")
    assert main(["-q", "info", str(junk)]) == 1
    assert "junk.bin" in capsys.readouterr().err


def test_convert_round_trip_is_bit_exact(tmp_path, capsys):
    rec = _small_recording()
    h5 = Path(meshphase.io.write(rec, tmp_path / "a.h5"))
    csv = tmp_path / "b.csv"
    back = tmp_path / "c.h5"
    assert main(["-q", "convert", str(h5), str(csv)]) == 0
    assert main(["-q", "convert", str(csv), str(back)]) == 0
    assert meshphase.io.detect_format(csv) == "csv"
    out = meshphase.io.read(back)
    assert out.data.shape == rec.data.shape
    # bit-exact: compare the raw float64 bit patterns (keeps -0.0 and the last ulp)
    np.testing.assert_array_equal(out.data.astype(np.float64).view(np.int64),
                                  rec.data.view(np.int64))
    assert out.fs == rec.fs and out.t0 == rec.t0
    assert [c.name for c in out.channels] == ["sun", "ring", "tacho"]
    assert [c.kind for c in out.channels] == ["sun", "ring", "tacho"]
    assert any(h.get("step") == "convert" for h in out.history)
    # the output exists now: converting onto it again is refused (exit 1), unless asked
    assert main(["-q", "convert", str(csv), str(back)]) == 1
    assert "c.h5" in capsys.readouterr().err
    assert main(["-q", "convert", str(csv), str(back), "--overwrite"]) == 0


def test_synth_list_and_usage(capsys):
    assert main(["synth", "--list"]) == 0
    out = capsys.readouterr().out
    assert re.search(r"^seed_rig\s+5120 Hz", out, re.M)
    assert "facewidth_offcentre" in out
    assert main(["synth"]) == 2
    assert "usage: meshphase synth" in capsys.readouterr().err


# --------------------------------------------------------------------------- demo
def test_demo_runs_quickly_and_writes_the_report(tmp_path, capsys):
    t = time.perf_counter()
    rc = main(["-q", "demo", "--out", str(tmp_path / "demo")])
    wall = time.perf_counter() - t
    out = capsys.readouterr().out
    with capsys.disabled():
        print(f"\n[meshphase demo] {wall:.1f} s wall (in-process, imports already loaded)")
    assert rc == 0
    assert wall < 120.0                      # issue: "under a minute"; 2x slack for a loaded CI
    d = tmp_path / "demo"
    assert (d / "report.html").is_file() and (d / "demo_scene.toml").is_file()
    assert "demo finished in" in out
    # a gauge whose planet labels are only relative says so beside its label match with
    # the truth (the demo's sun gauge: planet 1 is the first pulse seen)
    summary = json.loads((d / "summary.json").read_text(encoding="utf-8"))
    said = summary.get("phasing_labels") or ""
    relative = set(re.findall(r"\b(sun|ring)\b", said.split(" are relative")[0])) \
        if " are relative" in said else set()
    lines = [ln for ln in out.splitlines() if ": RMS residual vs model" in ln and "vs truth" in ln]
    assert lines
    for line in lines:
        gear = line.split(":")[0]
        assert ("labels relative, as truth" in line) == (gear in relative), (line, said)
    sec = _sections((d / "report.html").read_text(encoding="utf-8"))
    assert "Measured phasing against the models" in sec and "Error against run time" in sec
    # the scene written next to the outputs reproduces the run with `meshphase run`
    from meshphase.run.scene import load_scene

    assert load_scene(d / "demo_scene.toml").input["synthetic"] == "rig_ripple1"


def test_the_console_script_freezes_the_heap_after_main(tmp_path):
    # the installed `meshphase` (and `python -m meshphase.cli`) is console_main: main's exit
    # code, then one collection and the heap frozen, so that the interpreter's exit does not
    # walk it again; main itself (called by tests, notebooks) leaves the collector alone
    import tomllib

    root = Path(__file__).resolve().parents[1]
    scripts = tomllib.loads((root / "pyproject.toml").read_text())["project"]["scripts"]
    assert scripts == {"meshphase": "meshphase.cli:console_main"}
    code = ("import gc, sys\n"
            "from meshphase.cli import console_main, main\n"
            "rc_main = main(['info', sys.argv[1]])\n"
            "frozen_after_main = gc.get_freeze_count()\n"
            "rc = console_main(['info', sys.argv[1]])\n"
            "print(rc_main, rc, frozen_after_main, gc.get_freeze_count() > 0)")
    res = subprocess.run([sys.executable, "-c", code, str(tmp_path / "missing.h5")], capture_output=True,
                         text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert res.stdout.split() == ["1", "1", "0", "True"]        # a missing file: exit 1, both ways
    res = subprocess.run([sys.executable, "-m", "meshphase.cli", "info", str(tmp_path / "missing.h5")],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 1 and "error" in res.stderr
