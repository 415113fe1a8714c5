"""Planet labels on an independent-rig TDMS file with a +-25 % load variation once per carrier
turn (the tester's seed 000 rig: ring held, tacho geometry given, equal planet loads), run
through a scene as a user runs it: the ring gauge's per-planet loads differ through the
variation alone, so they must not name the sun's planet 1; the run says so (summary,
assignment, warning), and a scene's ``[labels] sun_shift`` pins the labels.
"""

import re

import numpy as np
import pytest

from meshphase.run.outputs import summary_dict
from meshphase.kinematics.pass_table import pass_order, planet_fractions
from meshphase.run.scene import parse_scene
from meshphase.run.stages import run_scene
from . import rig as R
from .test_meshphase_on_rig import _errors, make, per_pass_errors, scene_text


@pytest.fixture(scope="module")
def modulated(tmp_path_factory):
    p = tmp_path_factory.mktemp("labels") / "torque_ripple.tdms"
    kw = dict(minutes=2.0, seed=5, load_modulation=((0.25, 1, 0.0),))
    R.write_rig_tdms(R.Rig(R.make_rig_config(errors=_errors(4), **kw)), p)
    return p, R.read_truth(R.truth_path(p))


def _run(p, truth, extra=""):
    scene = p.with_name(p.stem + f"{len(extra)}.toml")
    scene.write_text(scene_text(truth, p) + extra, encoding="utf-8")
    return run_scene(parse_scene(scene.read_text(encoding="utf-8"), scene))


def test_a_carrier_rate_load_variation_leaves_the_sun_labels_in_doubt_and_says_why(modulated):
    p, truth = modulated
    gains = np.asarray(truth.engagements["SG_ring_T1"]["gain"])
    assert np.ptp(gains) > 0.3       # the ring gauge's pulses differ by the variation
    ctx = _run(p, truth)
    a = ctx.phasing.assignment
    assert a["ring"]["shift_decided_by"] == "tacho" and not a["ring"]["ambiguous"]
    assert per_pass_errors(ctx, truth, "ring")["labels"] == 1.0
    assert a["sun"]["ambiguous"] and "load variation of +-2" in a["sun"]["caution"]
    said = summary_dict(ctx)["phasing_labels"]
    assert said.startswith("planet labels of the sun gauge in doubt: the ring gauge's "
                           "per-planet loads name planet 1"), said
    assert any("sun gauge: planet labels in doubt" in m for m in ctx.messages), ctx.messages
    # the sun gauge measures the variation: +-25 % in truth; 84 pulses at 20 dB give it to
    # about 1 %, so +-3 % is three standard errors
    swing = [int(m.group(1)) for n in ctx.phasing.notes
             if (m := re.search(r"a load variation of \+-(\d+) %", n))]
    assert swing and all(22 <= x <= 28 for x in swing), ctx.phasing.notes
    # never a confident wrong answer: labels taken as absolute are the truth's
    for gear in ("sun", "ring"):
        if not a[gear]["ambiguous"]:
            assert per_pass_errors(ctx, truth, gear)["labels"] == 1.0


def test_the_scene_pins_the_sun_labels(modulated):
    p, truth = modulated
    ctx = _run(p, truth)
    lab = ctx.phasing.labels["sun"]
    et = np.asarray(truth.engagements["SG_sun_T3"]["t"])
    planet = np.asarray(truth.engagements["SG_sun_T3"]["planet"]) - 1
    t = lab.times[lab.planet >= 0]
    near = np.abs(et[None, :] - t[:, None]).argmin(axis=1)
    off = float(np.median(t - et[near]))         # onset feature vs engagement instant
    true_first = planet[np.abs(et - (t[0] - off)).argmin()]
    # the shift that moves the first labelled pulse's planet onto the truth's
    psi = np.asarray(R.RigConfig.from_dict(truth.config).gearset.planet_angles)
    seq = np.argsort(planet_fractions(psi, pass_order("cw", "sun")), kind="stable")
    place = np.empty(seq.size, int)
    place[seq] = np.arange(seq.size)
    k = int((place[true_first] - place[lab.planet[lab.planet >= 0][0]]) % seq.size)
    ctx = _run(p, truth, f"[labels]\nsun_shift = {k}\n")
    assert ctx.phasing.assignment["sun"] == {"shift_decided_by": "scene", "n_unassigned": 0,
                                             "ambiguous": False}
    assert per_pass_errors(ctx, truth, "sun")["labels"] == 1.0
    assert summary_dict(ctx)["phasing_labels"] == "planet labels absolute"


def test_the_rig_load_modulation_is_the_pulse_gain_and_checks_its_terms():
    cfg = R.make_rig_config(minutes=0.2, seed=0, snr_db=None,
                            load_modulation=((0.25, 1, 0.5), (0.05, 2, 0.0)))
    rig = R.Rig(cfg)
    t, _ = rig.engagements("ring")
    th = rig.motion.angle("carrier", t)
    want = 1 + 0.25 * np.cos(th + 0.5) + 0.05 * np.cos(2 * th)
    np.testing.assert_allclose(rig.truth().engagements["SG_ring_T1"]["gain"], want, rtol=1e-12)
    back = R.RigConfig.from_dict(cfg.to_dict())
    assert back.load_modulation == ((0.25, 1, 0.5), (0.05, 2, 0.0))
    assert "gain" not in R.Rig(R.make_rig_config(minutes=0.2, seed=0)).truth().engagements[
        "SG_ring_T1"]                            # no variation: the truth as it was
    for bad, words in ((((0.6, 1, 0.0), (0.5, 2, 0.0)), "sum below 1"),
                       (((0.2, 1),), "terms must be"), ("0.2", "sequence")):
        with pytest.raises((ValueError, TypeError), match=words):
            R.make_rig_config(minutes=0.2, load_modulation=bad)


def test_a_speed_ripple_preset_is_labelled_as_it_was(tmp_path):
    # a 3 % carrier-rate speed ripple moves the pulse amplitudes by about 1 % with the
    # carrier's phase: measurable, below what gets a note, and it changes no label
    p, truth = make(tmp_path, "ripple3_carrier")
    ctx = _run(p, truth)
    a = ctx.phasing.assignment
    assert a["ring"] == {"shift_decided_by": "tacho", "n_unassigned": 0, "ambiguous": False}
    assert a["sun"] == {"shift_decided_by": "first pulse", "n_unassigned": 0, "ambiguous": True}
    assert not any("load variation" in n for n in ctx.phasing.notes), ctx.phasing.notes
