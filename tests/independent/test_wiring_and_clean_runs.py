"""meshphase on the independent rig's recordings remapped wrongly in the scene: the run's
status names the channel and the fix (not "the passes scatter"); clean steady-rig recordings
(high SNR, several seeds) raise no data-quality warning of a transient; a TDMS in microstrain
gives the load sharing of the same rig in m/m."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from meshphase.run.exits import run_status
from meshphase.run.scene import parse_scene
from meshphase.run.stages import run_scene
from . import rig as R
from .test_meshphase_on_rig import scene_text


@pytest.fixture(scope="module")
def steady(tmp_path_factory):
    """(path, truth) of a 1-min steady-rig TDMS (sun 18.19 r/min, ring held)."""
    p = tmp_path_factory.mktemp("wiring") / "steady.tdms"
    truth = R.write_rig_tdms(R.Rig(R.make_rig_config(minutes=1.0, seed=2)), p)
    return p, truth


def _remapped(steady, *entries: str, speeds: bool = True):
    p, truth = steady
    head = scene_text(truth, p, geometry=False).split("[[channels]]")[0]
    if not speeds:
        head = head.replace(head[head.index("[speeds]"):head.index("[input]")], "")
    text = head + "".join(f"[[channels]]\n{e}\n" for e in entries)
    ctx = run_scene(parse_scene(text, p.with_suffix(".toml")))
    return ctx, run_status(ctx)


def _names(steady):
    return {c["kind"]: c["name"] for c in steady[1].channels}


def test_right_mapping_is_ok(steady):
    n = _names(steady)
    ctx, st = _remapped(steady, f'name = "{n["sun"]}"\nkind = "sun"',
                        f'name = "{n["ring"]}"\nkind = "ring"', f'name = "{n["tacho"]}"\nkind = "tacho"')
    assert st["status"] == "ok", st
    assert not [m for m in ctx.messages if "wrong gear" in m or "pulse train" in m]


@pytest.mark.parametrize("speeds", [True, False])
def test_both_gauges_mapped_as_sun_by_a_glob_are_named(steady, speeds):
    n = _names(steady)
    ctx, st = _remapped(steady, 'name = "SG_*"\nkind = "sun"', f'name = "{n["tacho"]}"\nkind = "tacho"',
                        speeds=speeds)
    assert st["status"] == "unreliable" and st["exit_code"] == 3
    cause = st["unreliable"]["sun"][0]                      # the first reason is the wiring
    assert repr(n["ring"]) in cause and "kind" in cause and "scatter" not in cause


def test_the_tacho_mapped_as_a_gauge_is_named(steady):
    n = _names(steady)
    # its unit (V) already stops a gauge at the door, naming the tacho as a possibility
    ctx, st = _remapped(steady, f'name = "{n["sun"]}"\nkind = "sun"', f'name = "{n["tacho"]}"\nkind = "ring"',
                        f'name = "{n["ring"]}"\nkind = "other"')
    assert st["status"] == "failed" and repr(n["tacho"]) in st["error"] and 'kind = "tacho"' in st["error"]
    # given a strain unit, its samples are still two levels: named as the ring's cause
    ctx, st = _remapped(steady, f'name = "{n["sun"]}"\nkind = "sun"',
                        f'name = "{n["tacho"]}"\nkind = "ring"\nunits = "m/m"',
                        f'name = "{n["ring"]}"\nkind = "other"')
    # no ring pass either: the ring result is missing (partial, exit 3), its cause the wiring
    assert st["status"] == "partial" and st["exit_code"] == 3, st
    cause = [m["cause"] for m in st["missing_results"] if m["cause"].startswith("ring gauge")][0]
    assert repr(n["tacho"]) in cause and "two-level pulse train" in cause and 'kind = "tacho"' in cause


@pytest.mark.parametrize("snr_db, seed", [(20.0, 1), (40.0, 2), (60.0, 1), (60.0, 2), (60.0, 3)])
def test_a_clean_steady_recording_holds_no_transient(snr_db, seed, tmp_path):
    # 60 dB, seed 2 warned "5 of 19 pulse windows hold a transient" on the ring gauge: the
    # windows of flagged onsets (no pulse at their centre) and the first pulse's misfit
    # (4e-6 of its energy) were taken for transients
    p = tmp_path / "clean.tdms"
    truth = R.write_rig_tdms(R.Rig(R.make_rig_config(minutes=1.0, seed=seed, snr_db=snr_db)), p)
    ctx = run_scene(parse_scene(scene_text(truth, p), p.with_suffix(".toml")))
    assert ctx.failed == {}
    assert not [m for m in ctx.messages if "transient" in m], ctx.messages


def test_a_tdms_in_microstrain_gives_the_load_sharing_in_m_per_m(steady, tmp_path):
    p, truth = steady
    ue = tmp_path / "ue.tdms"
    R.write_rig_tdms(R.Rig(R.RigConfig.from_dict(truth.config)), ue, gauge_unit="µε")
    out = {}
    for path in (p, ue):
        text = scene_text(truth, path).replace('results = ["phasing", "compare"]',
                                               'results = ["phasing", "load_sharing"]')
        ctx = run_scene(parse_scene(text, Path(path).with_suffix(".toml")))
        out[path] = np.array([r["mean_amplitude"] for r in ctx.load_sharing.sharing.to_rows()])
    assert np.all(np.isfinite(out[p])) and np.all(out[p] < 1e-3)    # strain, not microstrain
    # the same rig, its samples written x 1e6 and read x 1e-6: equal to float rounding
    np.testing.assert_allclose(out[ue], out[p], rtol=1e-9)


def test_gauge_unit_bad_input(tmp_path):
    rig = R.Rig(R.make_rig_config(minutes=0.05, seed=1))
    with pytest.raises(ValueError, match="gauge_unit"):
        R.write_rig_tdms(rig, tmp_path / "x.tdms", gauge_unit="kPa")
