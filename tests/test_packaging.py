"""The distribution installs one import package, ``meshphase`` (issue 12 item 1).

The repository keeps its folders pipeline/, synthetic/ and data_schemas/; pyproject.toml maps
them under ``meshphase`` with setuptools' ``package-dir``. These tests check the mapping from
both ends: the package list names every folder that is a package, and a wheel built from the
checkout, installed in a fresh venv, imports from outside the checkout and puts nothing but
``meshphase`` (and its dist-info) at the top of site-packages.
"""

from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
import tomllib
import zipfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
MAPPING = {"meshphase": "pipeline", "meshphase.synthetic": "synthetic",
           "meshphase.data_schemas": "data_schemas"}


def _pyproject() -> dict:
    return tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))


def _folder_packages() -> set[str]:
    """Every package folder of the checkout, named as it installs."""
    out = set()
    for name, folder in MAPPING.items():
        base = REPO / folder
        for init in base.rglob("__init__.py"):
            rel = init.parent.relative_to(base).parts
            if "__pycache__" not in rel:
                out.add(".".join((name, *rel)))
    return out


def test_package_list_names_every_package_folder():
    st = _pyproject()["tool"]["setuptools"]
    assert st["package-dir"] == MAPPING
    assert set(st["packages"]) == _folder_packages()


def test_py_typed_marker_ships_with_the_package():
    # PEP 561: an empty marker beside meshphase/__init__.py, listed as package data (the
    # wheel test below checks the built wheel holds it)
    import meshphase

    marker = Path(meshphase.__file__).parent / "py.typed"
    assert marker.is_file() and marker.read_bytes() == b""
    assert "py.typed" in _pyproject()["tool"]["setuptools"]["package-data"]["meshphase"]


def test_installed_import_name_is_meshphase_only(tmp_path):
    # from outside the checkout (pytest puts the repository root on sys.path, where the
    # folders themselves would import): this install gives meshphase, and only meshphase
    code = ("import importlib.util as u, meshphase; print(meshphase.__file__); "
            "print([m for m in ('pipeline', 'synthetic', 'data_schemas') if u.find_spec(m)])")
    out = subprocess.run([sys.executable, "-I", "-c", code], check=True, capture_output=True,
                         text=True, cwd=tmp_path, timeout=300).stdout.splitlines()
    assert Path(out[0]).resolve().parent == REPO / "pipeline"
    assert out[1] == "[]"


def _build_wheel(dest: Path) -> Path:
    """The wheel of the checkout. Without build isolation when this interpreter's setuptools
    can build wheels itself (>= 70.1; no network), else pip fetches the build backend."""
    cmd = [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(dest), str(REPO)]
    try:
        import setuptools

        major, minor = (int(x) for x in setuptools.__version__.split(".")[:2])
        if (major, minor) >= (70, 1):
            cmd.insert(4, "--no-build-isolation")
    except ImportError:
        pass
    subprocess.run(cmd, check=True, capture_output=True, text=True, timeout=600,
                   cwd=dest)
    (wheel,) = dest.glob("meshphase-*.whl")
    return wheel


def test_wheel_installs_one_top_level_package(tmp_path):
    wheel = _build_wheel(tmp_path)
    with zipfile.ZipFile(wheel) as z:
        tops = {n.split("/")[0] for n in z.namelist()}
        names = set(z.namelist())
    assert tops == {"meshphase", wheel.name.split("-")[0] + "-" + wheel.name.split("-")[1]
                    + ".dist-info"}
    # data files ship with their package
    assert "meshphase/data_schemas/scene.schema.json" in names
    assert "meshphase/synthetic/generate.py" in names
    # the PEP 561 marker: type checkers read the package's annotations
    assert "meshphase/py.typed" in names

    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=300)
    bindir = venv / ("Scripts" if os.name == "nt" else "bin")
    py = bindir / "python"
    site = Path(subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                               check=True, capture_output=True, text=True).stdout.strip())
    before = set(p.name for p in site.iterdir())
    subprocess.run([str(py), "-m", "pip", "install", "-q", "--no-deps", "--no-index", str(wheel)],
                   check=True, capture_output=True, text=True, timeout=300)
    added = set(p.name for p in site.iterdir()) - before
    assert {a for a in added if not a.endswith(".dist-info")} == {"meshphase"}
    # the dependencies come from this interpreter's site-packages (path only: its .pth files,
    # among them an editable meshphase's finder, are not processed from a .pth entry)
    (site / "_deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n", encoding="utf-8")
    code = ("import meshphase, meshphase.synthetic, meshphase.data_schemas as ds, sys; "
            "from meshphase.io import read; from meshphase.synthetic import generate; "
            "print(meshphase.__file__); print(ds.SCHEMA_DIR / 'scene.schema.json'); "
            "print(sorted(m for m in sys.modules if m.split('.')[0] in "
            "('pipeline', 'synthetic', 'data_schemas')))")
    out = subprocess.run([str(py), "-I", "-c", code], check=True, capture_output=True,
                         text=True, cwd=tmp_path, timeout=300).stdout.splitlines()
    assert Path(out[0]).is_relative_to(site)
    assert Path(out[1]).is_file()
    assert out[2] == "[]"
    ver = subprocess.run([str(bindir / "meshphase"), "--version"], capture_output=True,
                         text=True, cwd=tmp_path, timeout=300)
    assert ver.returncode == 0 and "meshphase" in ver.stdout + ver.stderr

