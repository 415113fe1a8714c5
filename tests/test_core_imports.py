"""The core never imports matplotlib (DESIGN.md: only meshphase.report may)."""

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
