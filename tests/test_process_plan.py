"""``meshphase process`` plans only what its outputs need (issue 12, item 7): a gearset file
with ``[tolerances]`` and extra results runs no Monte Carlo and no bearing stages unless
``--tolerance`` asks for the Monte Carlo; the stages that ran (``ctx.ran``) say so."""

from __future__ import annotations

import pytest
from seed_rig_toml import SEED_RIG_GEARSET

import meshphase.io
from meshphase.cli import main
from meshphase.run.scene import SceneError
from meshphase.run.stages import PROCESS_RESULTS, process_recording

TOLERANCES = """
[tolerances]
e_sun_mm = 0.2
e_ring_mm = 0.5
e_planet_mm = 0.2
samples = 64
sampler = "random"
seed = 3
"""

BEARING = """
[bearing]
case = "1"
input_torque_Nm = 1378.7
k_tilt_Nm_per_rad = [8.8e4]
c_g_N_per_mm_um = 20.0
"""


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    """30 s of seed_rig as HDF5 (both gauges measured: a clean run is "ok"), a gearset file
    asking for tolerance, bearing moments and tilt (with their tables), and one without
    [tolerances]."""
    from meshphase.synthetic import generate

    d = tmp_path_factory.mktemp("plan")
    rec, _ = generate("seed_rig", duration=30.0, seed=5)
    path = meshphase.io.write(rec, d / "rig.h5")
    full = d / "full.toml"
    full.write_text('name = "rig"\nresults = ["ideal_phasing", "tolerance", "bearing_moments", "tilt"]\n'
                    + SEED_RIG_GEARSET + TOLERANCES + BEARING, encoding="utf-8")
    bare = d / "bare.toml"
    bare.write_text('name = "rig"\n' + SEED_RIG_GEARSET, encoding="utf-8")
    return {"path": path, "full": full, "bare": bare, "dir": d}


def test_process_runs_no_monte_carlo_nor_bearing_stages_by_default(rig):
    ctx, files = process_recording(rig["path"], rig["full"], out_dir=rig["dir"] / "a")
    assert ctx.ran == ["load", "condition", "onsets", "phasing", "load_sharing", "identify",
                       "ideal", "compare"]
    assert "tolerance" not in ctx.failed and ctx.tolerance is None
    assert ctx.scene.results == list(PROCESS_RESULTS)
    assert "arrays" in files and "tilt" not in files and "bearing_moments" not in files


def test_process_tolerance_flag_runs_the_monte_carlo_before_compare(rig):
    ctx, _ = process_recording(rig["path"], rig["full"], out_dir=rig["dir"] / "b", tolerance=True)
    assert "tolerance" in ctx.ran
    assert ctx.ran.index("tolerance") < ctx.ran.index("compare")
    assert not {"bearing_moments", "tilt"} & set(ctx.ran)
    # the comparison carries the band the Monte Carlo gave
    assert all(row.band is not None for row in ctx.compare.by_gear.values())


def test_process_tolerance_flag_without_tolerances_is_a_scene_error(rig):
    with pytest.raises(SceneError, match=r"\[tolerances\]"):
        process_recording(rig["path"], rig["bare"], out_dir=rig["dir"] / "c", tolerance=True)
    assert not (rig["dir"] / "c").exists()


def test_process_command_tolerance_flag(rig, capsys):
    out = rig["dir"] / "d"
    assert main(["-q", "process", str(rig["path"]), "--gearset", str(rig["full"]), "--out", str(out)]) == 0
    stages = capsys.readouterr().out.splitlines()[1]
    assert stages.startswith("stages") and "tolerance" not in stages and "tilt" not in stages
    assert main(["-q", "process", str(rig["path"]), "--gearset", str(rig["bare"]), "--out",
                 str(rig["dir"] / "e"), "--tolerance"]) == 1
    assert "[tolerances]" in capsys.readouterr().err
