"""The core never imports matplotlib (only meshphase.report may: docs/architecture.md), and stays light."""

import subprocess
import sys

import pytest


@pytest.mark.parametrize("module", ["meshphase", "meshphase.io", "meshphase.models", "meshphase.cli",
                                    "meshphase.models.gearset", "meshphase.recording"])
def test_core_import_leaves_matplotlib_out(module):
    code = (f"import sys, {module}; "
            "bad = [m for m in sys.modules if m == 'matplotlib' or m.startswith('matplotlib.')]; "
            "print(','.join(bad)); sys.exit(1 if bad else 0)")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert res.returncode == 0, f"{module} imported matplotlib: {res.stdout} {res.stderr}"


def test_cli_version():
    from meshphase.cli import main

    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0


HEAVY = ("scipy", "pandas", "matplotlib", "dask", "distributed", "numba", "h5py", "mcap",
         "nptdms", "jsonschema", "tqdm")


@pytest.mark.parametrize("module", ["meshphase", "meshphase.io", "meshphase.models",
                                    "meshphase.recording"])
def test_core_import_is_light(module):
    # the core (the Recording, the format registry, the model package's face) loads numpy
    # and nothing heavy: formats and solvers import their libraries when first used. The
    # start-up time this buys is measured by the bench, not asserted here.
    code = (f"import sys, {module}; "
            "print(','.join(sorted({m.split('.')[0] for m in sys.modules} & set(sys.argv[1:]))))")
    res = subprocess.run([sys.executable, "-c", code, *HEAVY], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "", f"{module} loaded {res.stdout.strip()}"


@pytest.mark.parametrize("module", ["meshphase.run.stages", "meshphase.cli"])
def test_processing_import_leaves_the_optional_heavy_parts_out(module):
    # what `meshphase process FILE` imports: numba/LLVM (the Monte Carlo kernel), dask (the
    # campaign), matplotlib (the report), pandas (the notebook API) and the synthetic
    # generator load only where they are used
    code = (f"import sys, {module}; "
            "print(','.join(sorted(m for m in {x.split('.')[0] for x in sys.modules} "
            "if m in sys.argv[1:]) + [m for m in sys.modules if m.startswith('meshphase.synthetic')]))")
    res = subprocess.run([sys.executable, "-c", code, "numba", "llvmlite", "dask", "distributed",
                          "matplotlib", "pandas"], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "", f"{module} loaded {res.stdout.strip()}"


STARTUP_HEAVY = ("scipy", "pandas", "matplotlib", "dask", "distributed", "numba", "llvmlite")


@pytest.mark.parametrize("argv", [["--help"], ["info", "{h5}"], ["info", "{h5}", "--no-quality"],
                                  ["convert", "{h5}", "{out}"]])
def test_cli_start_up_loads_no_solver(tmp_path, argv):
    # `meshphase --help`, `info` and `convert` need no stage: the CLI imports the stages (and
    # with them scipy, which scipy.signal pulls scipy.stats into) only for a command that
    # runs one. The start-up this buys is timed by `meshphase bench io`'s start-up rows.
    import numpy as np

    from meshphase.io import write
    from meshphase.recording import Recording

    h5 = tmp_path / "r.h5"
    write(Recording(np.zeros((64, 2)), 5120.0, ["sun_g1", "ring_g1"]), h5)
    args = [a.format(h5=h5, out=tmp_path / "copy.h5") for a in argv]
    code = ("import sys, contextlib, io\n"
            "from meshphase.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            "    try:\n"
            "        rc = main(sys.argv[1].split('|'))\n"
            "    except SystemExit as e:\n"
            "        rc = e.code\n"
            "assert rc == 0, rc\n"
            "print(','.join(sorted({m.split('.')[0] for m in sys.modules} & set(sys.argv[2:]))))")
    res = subprocess.run([sys.executable, "-c", code, "|".join(args), *STARTUP_HEAVY],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "", f"meshphase {' '.join(argv)} loaded {res.stdout.strip()}"


@pytest.mark.parametrize("argv", [["--version"], ["--help"]])
def test_cli_start_up_loads_no_progress_bar_results_or_campaign(argv):
    # tqdm (with importlib.metadata, ~20 ms), the run's result types and the campaign
    # machinery load with the first progress bar, run or campaign, not for every command
    code = ("import sys, contextlib, io\n"
            "from meshphase.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            "    try:\n"
            "        main(sys.argv[1:2])\n"
            "    except SystemExit as e:\n"
            "        assert e.code == 0, e.code\n"
            "print(','.join(m for m in ('tqdm', 'meshphase.run.results', 'meshphase.campaign.runner', "
            "'meshphase.campaign.job') if m in sys.modules))")
    res = subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "", f"meshphase {argv[0]} loaded {res.stdout.strip()}"


def test_processing_import_leaves_scipy_signal_and_stats_out():
    # scipy.signal imports scipy.stats (find_peaks_cwt), 0.5-0.8 s of every start; the
    # processing takes its filter designs, smoother and spectra from meshphase.signal.sos_design,
    # .savgol and .spectral instead (tests/processing/test_dsp_designs.py holds them to scipy)
    code = ("import sys, meshphase.run.stages; "
            "print(','.join(sorted(m for m in sys.modules if m in ('scipy.signal', 'scipy.stats'))))")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "", f"meshphase.run.stages loaded {res.stdout.strip()}"


def test_process_command_loads_only_what_it_needs(tmp_path):
    # the whole `meshphase process FILE` of a file scene, start to finish: no pandas (its
    # tables are written by meshphase.run.table_csv, pandas cost ~0.33 s a run), dask,
    # matplotlib or synthetic generator; and with numba installed no scipy.signal or
    # scipy.stats (the filters run on numba's kernel, meshphase.signal.iir.pick_engine: one of
    # numba and scipy.signal must load, numba's kernel is the faster; without numba the
    # filters need scipy.signal); nor the models of the stages it does not run (bearing
    # moments, tilt, the tolerance Monte Carlo: `meshphase run` a scene for those)
    import importlib.util

    import pandas as pd
    from seed_rig_toml import SEED_RIG_GEARSET

    import meshphase.io
    from meshphase.synthetic import generate

    rec, _ = generate("seed_rig", duration=40.0, seed=5)
    path = meshphase.io.write(rec, tmp_path / "rig.h5")
    gs = tmp_path / "gearset.toml"
    gs.write_text('name = "seed rig gearset"\n' + SEED_RIG_GEARSET, encoding="utf-8")
    bad = ["dask", "distributed", "pandas", "matplotlib", "meshphase.models.bearing",
           "meshphase.models.tilt", "meshphase.models.tolerance", "meshphase.models.tolerance_model"]
    if importlib.util.find_spec("numba") is not None:
        bad += ["scipy.signal", "scipy.stats"]
    code = ("import sys, contextlib, io\n"
            "from meshphase.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            "    rc = main(['-q', 'process', sys.argv[1], '--gearset', sys.argv[2], '--out', sys.argv[3]])\n"
            "assert rc == 0, rc\n"
            "print(','.join(sorted(m for m in sys.modules if m in sys.argv[4:] "
            "or m.startswith('meshphase.synthetic'))))")
    res = subprocess.run([sys.executable, "-c", code, str(path), str(gs), str(tmp_path / "out"), *bad],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr[-3000:]
    assert res.stdout.strip() == "", f"meshphase process loaded {res.stdout.strip()}"
    df = pd.read_csv(tmp_path / "out" / "passes_sun.csv")          # pandas reads what it wrote
    assert len(df) > 10 and df["planet"].dtype.kind == "i" and df["gauge"].eq("sun").all()


def test_process_of_a_missing_file_fails_before_the_stages_load(tmp_path):
    # a mistyped recording path is reported before the stages (scipy, numba) are imported
    gs = tmp_path / "gearset.toml"
    gs.write_text("name = 'x'\n", encoding="utf-8")
    code = ("import sys, contextlib, io\n"
            "from meshphase.cli import main\n"
            "err = io.StringIO()\n"
            "with contextlib.redirect_stderr(err):\n"
            "    rc = main(['-q', 'process', sys.argv[1], '--gearset', sys.argv[2]])\n"
            "assert rc == 1 and 'no such file' in err.getvalue(), (rc, err.getvalue())\n"
            "print(','.join(sorted({m.split('.')[0] for m in sys.modules} & set(sys.argv[3:]))))")
    res = subprocess.run([sys.executable, "-c", code, str(tmp_path / "missing.h5"), str(gs),
                          *STARTUP_HEAVY], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "", f"a failed process loaded {res.stdout.strip()}"


def test_white_noise_synthesis_leaves_scipy_signal_out():
    # the generator's 1/f filter is the only user of scipy.signal (and through it of
    # scipy.stats): a recording without 1/f noise - the demo's - imports neither; one with
    # it does, as before
    code = ("import sys; from meshphase.synthetic import generate; "
            "generate(sys.argv[1], duration=2.0); "
            "print(','.join(m for m in ('scipy.signal', 'scipy.stats') if m in sys.modules))")
    for name, expect in (("rig_ripple1", ""), ("noisy", "scipy.signal,scipy.stats")):
        res = subprocess.run([sys.executable, "-c", code, name], capture_output=True, text=True)
        assert res.returncode == 0, res.stderr
        assert res.stdout.strip() == expect, (name, res.stdout)


def test_a_scene_run_and_its_report_leave_pandas_out(tmp_path):
    # pandas is the Python API's (tables as DataFrames); `run` and the demo write their CSV
    # tables and the HTML report without it
    code = ("import sys; from pathlib import Path; from meshphase.run.demo import DEMO_SCENE; "
            "from meshphase.run.scene import parse_scene; from meshphase.run.stages import run_scene; "
            "from meshphase.run.outputs import write_outputs; "
            "ctx = run_scene(parse_scene(DEMO_SCENE.replace('minutes = 2.0', 'minutes = 0.5'))); "
            "files = write_outputs(ctx, Path(sys.argv[1]), report=True); "
            "assert 'report' in files and ctx.phasing is not None; "
            "print(','.join(m for m in sys.modules if m == 'pandas' or m.startswith('pandas.')))")
    res = subprocess.run([sys.executable, "-c", code, str(tmp_path)], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.strip() == "", res.stdout[:300]
