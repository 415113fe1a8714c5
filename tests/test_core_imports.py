"""The core never imports matplotlib (DESIGN.md: only meshphase.report may), and stays light."""

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


@pytest.mark.parametrize("module", ["meshphase.stages", "meshphase.cli"])
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
