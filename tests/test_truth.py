"""What a synthetic truth tells a run (meshphase.compare.truth): the true errors, the generator's tacho
geometry, the measured phasing scored against the true one."""

from __future__ import annotations

import math

import numpy as np
import pytest

from meshphase.compare.predict import truth_comparison
from meshphase.models.mesh_phasing import ShaftHoleErrors
from meshphase.kinematics.phasing import GaugeLabels, PassTable
from meshphase.run.scene import parse_scene
from meshphase.run.stages import run_scene
from meshphase.compare.truth import phasing_vs_truth, tacho_geometry, true_errors
from meshphase.synthetic import generate, get_scenario
from meshphase.synthetic.config import SynthConfig


@pytest.fixture(scope="module")
def seed_truth():
    return generate("seed_rig", duration=2.0, seed=1)[1]


def test_true_errors_of_the_generator(seed_truth):
    te = true_errors(seed_truth)
    assert isinstance(te, ShaftHoleErrors)
    assert float(te.e_sun) == pytest.approx(seed_truth.errors["e_sun"])
    assert true_errors(None) is None


def test_tacho_geometry_of_the_generator(seed_truth):
    cfg = SynthConfig.from_dict(seed_truth.config)
    key, mounts = tacho_geometry(seed_truth)
    assert key == -cfg.tacho_angle()
    assert mounts == {g.name: cfg.tooth_angle(g) for g in cfg.gauges}
    _, no_tacho = generate(get_scenario("seed_rig").with_(tacho=None), duration=1.0, seed=1)
    key, mounts = tacho_geometry(no_tacho)
    assert key is None and set(mounts) == {"sun", "ring"}


def test_phasing_vs_truth_is_the_truth_comparison_of_the_labels_used():
    scene = parse_scene('results = ["phasing"]\n[input]\nsynthetic = "seed_rig"\nminutes = 0.25\n'
                        'seed = 3\n')
    ctx = run_scene(scene)
    truth = ctx.load.truth
    assert ctx.phasing.labels
    for gear, lab in ctx.phasing.labels.items():
        tab = ctx.phasing.tables[gear]
        got = phasing_vs_truth(tab, lab, truth)
        want = truth_comparison(tab, truth, lab.channel, times=lab.times, planets=lab.planet)
        assert got["rms"] == want["rms"] and got["n"] == want["n"] > 0
        assert math.isfinite(got["rms"])


def test_truth_empty_and_bad_input(seed_truth):
    assert phasing_vs_truth(PassTable.empty("sun"), None, seed_truth) is None
    with pytest.raises(TypeError, match="synthetic truth"):
        phasing_vs_truth(PassTable.empty("sun"), None, object())
    with pytest.raises(TypeError, match="GaugeLabels"):
        phasing_vs_truth(PassTable.empty("sun"), ("sun", np.zeros(1)), seed_truth)
    with pytest.raises(TypeError, match="synthetic truth"):
        tacho_geometry(None)
    lab = GaugeLabels("sun", np.empty(0), np.empty(0), None, np.empty(0, int), np.empty(0, int),
                      "first pulse")
    assert phasing_vs_truth(PassTable.empty("sun"), lab, seed_truth) is None
