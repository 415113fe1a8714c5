"""End to end: every synthetic scenario through ``run_scene``, held against its truth (issue 5,
item 6), and bad inputs that must give clear warnings and partial results.

Each registry scenario (:data:`meshphase.synthetic.SCENARIOS`) is generated with seed 3 and processed by
``meshphase.run.stages.run_scene`` (phasing, load sharing, compare, identify, centroids). The run's
own truth comparison (``ctx.compare.by_gear[gear].vs_truth``: the measured phasing with the
onsets labelled as the truth labels them) must lie within the tolerance of the table below;
load sharing, face-width centroids and identified shaft hole errors are checked against the
truth the generator wrote. A new scenario without a row here fails
``test_every_registry_scenario_has_an_expectation``.

Measured (regression values: this machine, seed 3, 1 min of 5120 Hz unless noted; Table 1
scenarios at their own 0.5 s of 51.2 kHz; the joint angle model of pipeline/kinematics/angles.py) and the
tolerances set (about 3x, RMS of the measured phasing against the truth [mesh cycles]; "max"
tolerances are 4x the RMS ones). The rig family (seed 000 teeth on the seed's rig, ripple,
ramps, 3/5 planets, with and without tacho) has its own matrix in tests/test_phasing_accuracy.py:

=======================  =================  =================  ==================================
scenario                 sun RMS / tol      ring RMS / tol     what limits it
=======================  =================  =================  ==================================
table1_high_speed(_ccw)  6.9e-5 / 2e-4      4.3e-5 / 2.5e-4    sub-sample timing of noise-free
table2_case1/2/3         6.8-7.0e-5         1.1-3.8e-5         pulses at 37 samples per mesh period
seed_rig, facewidth_*    5.3-5.5e-5 / 1e-4  4.6-4.7e-5 / 1.5e-4  sub-sample timing (~1e-4 FWHM)
speed_ramp               1.1e-4 / 3e-4      1.2e-4 / 3.5e-4    the spline following the ramp
speed_ripple             8.9e-5 / 3e-4      6.7e-5 / 3e-4      the 4 % 0.01 Hz ripple is smooth
                                                               speed: the spline takes it
rig_realistic            3.5e-3 / 9e-3      4.5e-3 / 3e-2      onset jitter at 30 dB (30 % 1/f)
noisy                    1.2e-2 / 3e-2      9.9e-3 / 7e-2      onset jitter at 20 dB, 40 % of it
                                                               1/f
adc16_clipped            none (clipped)     1.2e-3 / 5e-3      every sun pulse clips at 140 µε and
                                                               is flagged: the ring runs alone
gaps                     7.5e-4 / 1e-2      none (flagged)     sun: the passes the dropout flags
                                                               leave; ring: < 8 clean pulses, no
                                                               template (warned)
speed_ripple_fast        0.30 (stress)      0.27 (stress)      ripple faster than the passes: the
                                                               failure must show
one_hour (slow, 60 min)  2.8e-3 / 9e-3      3.9e-3 / 1.2e-2    onset jitter at 30 dB
=======================  =================  =================  ==================================

Load sharing: clean scenarios exact to < 5e-6 (tolerance 1e-4, facewidth_offcentre's unequal
1.08/0.95/1.02/0.95 included); noisy 0.7-1.9e-2 with a std error 1.2-1.6e-2 (tolerance 4e-2).
Centroids (facewidth_offcentre): Z_S -2.000 mm exactly, Z_R +3.034 mm against the pass-weighted
truth (sum LS Z / sum LS over the passes seen) 3.034 mm (tolerance 0.01 mm) and the planet mean
3.009 mm (tolerance 0.15 mm: 5/4/5/5 passes per planet in a minute); facewidth_tilt -5.106 /
+5.334 mm exactly.

Identification: ``subspace_error`` of the truth (mapped into our planet numbering) divided by the
norm of the projected truth. Clean scenarios measured 0.095-0.105 with the pass times at the
onset feature (leading half-amplitude point, 0.43 mesh periods before the engagement: every
offset's phase read w_jc * 0.06 s late), 0.054-0.072 with them at the template's tensile peak
(which leans 0.21 / -0.12 mesh periods off the middle of the contact on these skewed pulses),
0.02-0.03 at the middle of the lobe and 0.01 with the truth's own offset. That part is a bias,
not noise; with the pass times at the template's timing centre it is held below 0.05 by
``test_identification_has_no_onset_offset_bias``. Tolerance 0.25. Noise-limited scenarios are
checked against the fit's own uncertainty instead (|estimate - truth| / std <= 4 per
identifiable parameter; measured <= 2.3 over seeds 1-5 for noisy, rig_realistic, speed_ripple).

Known bugs are strict xfails (they fail loudly once fixed, so the marker comes off). None is
left: the "gaps" scenario's labels (the pattern period of a sparse pass train), table2_case3
identification (sun and ring planet numberings chosen independently), the onset-offset bias of
the identified errors and a minute of Table 1 at 51.2 kHz were fixed with the joint angle
model and the pass times at the template's timing centre, as were a dead gauge without a
warning, a missing planet that took a second one with it, a revolution-long NaN gap that
collapsed the onset threshold, the partial-contact ring centroid, NaN without a warning, and
no warning for speed_ripple_fast: plain tests now.

Bad inputs go the recording-file route (HDF5 written with ``meshphase.io.write``, a scene with
``[input] recording``), as a user's file would.
"""

from __future__ import annotations

import functools
import json
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

import meshphase.io
from meshphase.compare.identify import vector_from_errors
from meshphase.compare.predict import PARAMETER_NAMES, truth_comparison, wrap
from meshphase.errors import ProcessingWarning
from meshphase.models.mesh_phasing import ShaftHoleErrors
from meshphase.run.scene import SceneError, load_scene, parse_scene
from meshphase.run.stages import RunContext, run_scene, summary_dict
from meshphase.synthetic import SCENARIOS, generate, list_scenarios

SEED = 3
RESULTS = '["phasing", "load_sharing", "compare", "identify", "centroids"]'
CENTROIDS_SKIPPED = "skipped: the recording has no face-width gauges"

# ----------------------------------------------------------------------------- expectations

@dataclass(frozen=True)
class Expect:
    """What a scenario must give.

    minutes : run length (None: the scenario's own duration).
    sun, ring : RMS tolerance of the measured phasing against the truth [mesh cycles]; None:
        no table expected for that gauge (and a warning saying why).
    load_sharing : max |LS - truth| [-]; None: NaN factors with a warning expected.
    ident : ("ratio", tol) subspace error / projected truth; ("z", k) every identifiable
        parameter within k of its own std; ("zero", tol [m]) no errors in the truth: the
        projected estimate stays below tol; ("fails",) the stress case.
    min_passes : fraction of the truth's passes each expected table keeps.
    xfail : test key -> reason (strict xfail).
    """

    minutes: float | None
    sun: float | None
    ring: float | None
    load_sharing: float | None
    ident: tuple
    min_passes: float = 0.8
    xfail: dict = field(default_factory=dict)


_T1 = dict(minutes=None, sun=2e-4, ring=2.5e-4, load_sharing=1e-4)
_RIG = dict(minutes=1.0, sun=1e-4, ring=1.5e-4, load_sharing=1e-4)
EXPECT: dict[str, Expect] = {
    # no errors: projected estimate 11.6 µm (cw) / 0.9 µm (ccw) measured; the cw ring reads
    # 1.9e-4 cycles against the ideal through the sun encoder of 28 relative revolutions
    "table1_high_speed": Expect(**_T1, ident=("zero", 25e-6)),
    "table1_high_speed_ccw": Expect(**_T1, ident=("zero", 25e-6)),
    "table2_case1": Expect(**_T1, ident=("ratio", 0.25)),
    "table2_case2": Expect(**_T1, ident=("ratio", 0.25)),
    "table2_case3": Expect(**_T1, ident=("ratio", 0.25)),
    "seed_rig": Expect(**_RIG, ident=("ratio", 0.25)),
    "facewidth_offcentre": Expect(**_RIG, ident=("ratio", 0.25)),
    "facewidth_partial": Expect(**_RIG, ident=("ratio", 0.25)),
    "facewidth_tilt": Expect(**_RIG, ident=("ratio", 0.25)),
    "speed_ramp": Expect(1.0, 3e-4, 3.5e-4, 1e-2, ("ratio", 0.25)),
    "speed_ripple": Expect(1.0, 3e-4, 3e-4, 6e-3, ("z", 4.0)),
    "rig_realistic": Expect(1.0, 9e-3, 3e-2, 2e-2, ("z", 4.0)),
    "noisy": Expect(1.0, 3e-2, 7e-2, 4e-2, ("z", 4.0)),
    "adc16_clipped": Expect(1.0, None, 5e-3, 2e-3, ("ratio", 0.25)),
    # gaps: with the fix the sun keeps 20 of ~50 passes at 3.3e-3 and identifies to 0.35-0.38
    "gaps": Expect(1.0, 1e-2, None, None, ("ratio", 0.6), min_passes=0.3),
    "speed_ripple_fast": Expect(1.0, None, None, 1e-2, ("fails",)),
    "one_hour": Expect(None, 9e-3, 1.2e-2, 2e-3, ("ratio", 0.25)),
}
SLOW = {"one_hour"}
STRESS = {"speed_ripple_fast"}
FACEWIDTH = sorted(n for n in EXPECT if n.startswith("facewidth_"))


def _params(key: str, names) -> list:
    """Scenario names as pytest params: one_hour slow, known bugs strict xfails."""
    out = []
    for n in names:
        marks = []
        if n in SLOW:
            marks.append(pytest.mark.slow)
        if key in EXPECT[n].xfail:
            marks.append(pytest.mark.xfail(strict=True, reason=EXPECT[n].xfail[key]))
        out.append(pytest.param(n, marks=marks, id=n))
    return out


ALL = sorted(EXPECT)
ACCURATE = [n for n in ALL if n not in STRESS]


# ----------------------------------------------------------------------------- runs
def _scene_text(name: str, minutes: float | None, results: str = RESULTS) -> str:
    dur = "" if minutes is None else f"minutes = {minutes}\n"
    return (f'name = "e2e {name}"\nresults = {results}\n[input]\nsynthetic = "{name}"\n'
            f"{dur}seed = {SEED}\n")


@functools.lru_cache(maxsize=None)
def synthetic_run(name: str) -> RunContext:
    """One run per scenario for the whole module (our warnings land in ctx.messages)."""
    return run_scene(parse_scene(_scene_text(name, EXPECT[name].minutes)))


def _nearest(sorted_t: np.ndarray, t: np.ndarray) -> np.ndarray:
    j = np.clip(np.searchsorted(sorted_t, t), 1, sorted_t.size - 1)
    return np.where(np.abs(sorted_t[j - 1] - t) < np.abs(sorted_t[j] - t), j - 1, j)


def truth_labels(ctx: RunContext, truth, gear: str):
    """(times, our 0-based labels, the truth's 0-based labels, onset-to-engagement offset [s])
    of the onsets a gauge's phasing used."""
    lab = ctx.phasing.labels[gear]
    ch, times, pl = lab.channel, lab.times, lab.planet
    et = np.asarray(truth.events[ch].time)
    off = float(np.median(times - et[_nearest(et, times)]))
    tl = np.asarray(truth.events[ch].planet)[_nearest(et, times - off)] - 1
    return np.asarray(times), np.asarray(pl), tl, off


def label_map(ctx: RunContext, truth, gear: str, n: int = 4):
    """Our planet q is the truth's planet m[q] (0-based); purity = share of the labelled
    onsets that follow that one map (1: a consistent relabelling)."""
    _, pl, tl, _ = truth_labels(ctx, truth, gear)
    m = np.array([np.bincount(tl[pl == q], minlength=n).argmax() if np.any(pl == q) else -1
                  for q in range(n)])
    lab = pl >= 0
    purity = float(np.mean(tl[lab] == m[pl[lab]])) if lab.any() else float("nan")
    return m, purity


def mapped_true_errors(ctx: RunContext, truth, gearset) -> ShaftHoleErrors:
    """The true shaft hole errors in our planet numbering (the sun gauge's, which the fit's
    planet 1 follows): planet errors permuted, sun/ring phases turned by our planet 1's angle."""
    te = ctx.load.true_errors
    tabs = ctx.phasing.tables
    gear = "sun" if len(tabs.get("sun", ())) else "ring"
    m, purity = label_map(ctx, truth, gear, gearset.n_planets)
    if purity < 1.0 or np.any(m < 0) or len(set(m.tolist())) != m.size:
        return te  # no consistent relabelling: compare as labelled (and let the test fail)
    n = gearset.n_planets
    ep = np.broadcast_to(np.asarray(te.e_planet, float), (n,))[m]
    kp = np.broadcast_to(np.asarray(te.kappa_planet, float), (n,))[m]
    rot = float(gearset.angles[m[0]])
    return ShaftHoleErrors(e_sun=float(te.e_sun), kappa_sun=float(te.kappa_sun) - rot,
                           e_ring=float(te.e_ring), kappa_ring=float(te.kappa_ring) - rot,
                           e_planet=np.array(ep), kappa_planet=np.array(kp))


def _ident_ratio(ident, errors: ShaftHoleErrors) -> float:
    n = (ident.free.size - 4) // 2
    proj = np.linalg.norm(ident.projector @ vector_from_errors(errors, n)[ident.free])
    return ident.subspace_error(errors) / proj


def _messages(ctx: RunContext, *words: str) -> list[str]:
    return [m for m in ctx.messages if all(w in m for w in words)]


# ============================================================================ the registry
def test_every_registry_scenario_has_an_expectation():
    # the "rig" family (seed 000 Table 1 teeth on the seed's rig, held ring) has its own
    # accuracy matrix in tests/test_phasing_accuracy.py
    rig = {n for n, sc in SCENARIOS.items() if "rig" in sc.tags}
    assert rig and set(EXPECT) == set(list_scenarios()) - rig == set(SCENARIOS) - rig


def test_truth_helpers_agree_with_the_runs_own_truth_comparison():
    """The label helpers used below (truth labels from the nearest engagement) reproduce the
    run's own label_match; the truth-labelled rebuild reproduces vs_truth exactly."""
    ctx = synthetic_run("seed_rig")
    truth = ctx.load.truth
    g = ctx.gearset
    for gear in ("sun", "ring"):
        times, pl, tl, off = truth_labels(ctx, truth, gear)
        vt = ctx.compare.by_gear[gear].vs_truth
        assert off == pytest.approx(vt["onset_offset_s"], abs=1e-12)
        assert float(np.mean(tl[pl >= 0] == pl[pl >= 0])) == pytest.approx(vt["label_match"])
        err = truth_phasing_error(ctx, truth, gear, g)
        assert err["rms"] == pytest.approx(vt["rms"], rel=1e-9)
        assert err["n"] == vt["n"]


# ============================================================================ per scenario
@pytest.mark.parametrize("name", _params("stages", ALL))
def test_every_requested_stage_runs(name):
    ctx = synthetic_run(name)
    fw = any(c.kind == "facewidth" for c in ctx.load.recording.channels)
    expected_failed = {} if fw else {"centroids": CENTROIDS_SKIPPED}
    assert {k: str(v) for k, v in ctx.failed.items()} == expected_failed
    for stage in ("load", "condition", "onsets", "phasing", "load_sharing", "identify", "compare"):
        assert stage in ctx.ran
    assert ("centroids" in ctx.ran) == fw


@pytest.mark.parametrize("name", _params("phasing", ACCURATE))
def test_phasing_matches_truth(name):
    exp = EXPECT[name]
    ctx = synthetic_run(name)
    truth = ctx.load.truth
    tables = ctx.phasing.tables
    for gear, tol in (("sun", exp.sun), ("ring", exp.ring)):
        if tol is None:
            # no phasing for this gauge: it must be empty (not a number) and a warning says why
            assert len(tables.get(gear, ())) == 0, gear
            assert gear not in ctx.compare.by_gear or ctx.compare.by_gear[gear].vs_truth is None
            assert any(f"'{gear}'" in m for m in ctx.messages), (gear, ctx.messages)
            continue
        vt = ctx.compare.by_gear[gear].vs_truth
        n_truth = len(truth.gamma_table(ctx.phasing.labels[gear].channel).time)
        assert vt["n"] >= exp.min_passes * n_truth, (gear, vt["n"], n_truth)
        assert vt["rms"] <= tol, (gear, vt)
        assert vt["max_abs"] <= 4 * tol, (gear, vt)
        # the table's own numbers are finite where given
        t = tables[gear]
        assert np.all(np.isfinite(t.gamma)) and np.all((t.gamma >= 0) & (t.gamma < 1))


@pytest.mark.parametrize("name", _params("labels", ACCURATE))
def test_planet_labels_are_a_consistent_relabelling_of_the_truth(name):
    # which pulse is planet 1 is not observable for a symmetric layout without a reference,
    # but within a gauge the labels must follow one map: every onset of our planet q belongs
    # to the same true planet
    ctx = synthetic_run(name)
    truth = ctx.load.truth
    for gear, t in ctx.phasing.tables.items():
        if not len(t):
            continue
        m, purity = label_map(ctx, truth, gear)
        assert purity == 1.0, (gear, m, purity)
        assert sorted(m.tolist()) == [0, 1, 2, 3], (gear, m)


def test_unequal_load_sharing_fixes_the_sun_labels():
    # facewidth_offcentre: loads 1.08/0.95/1.02/0.95, so the sun labels come from matching the
    # ring's per-planet amplitudes and must agree with the ring's numbering; the ring's first
    # pulse is planet 1 in this generator (ring gauge tooth at pi/8), so both equal the truth
    ctx = synthetic_run("facewidth_offcentre")
    truth = ctx.load.truth
    cmp = ctx.compare.by_gear
    assert ctx.phasing.assignment["sun"]["shift_decided_by"] == "amplitude"
    assert np.array_equal(label_map(ctx, truth, "sun")[0], label_map(ctx, truth, "ring")[0])
    assert cmp["sun"].vs_truth["label_match"] == 1.0
    assert cmp["ring"].vs_truth["label_match"] == 1.0
    assert not _messages(ctx, "sun gauge: which pulse is planet 1")


@pytest.mark.parametrize("name", _params("load_sharing", ALL))
def test_load_sharing_matches_truth(name):
    exp = EXPECT[name]
    ctx = synthetic_run(name)
    truth = ctx.load.truth
    ls = ctx.load_sharing.sharing
    if exp.load_sharing is None:
        # no ring pulses: NaN factors, said so, never a number
        assert np.all(np.isnan(ls.factors)) and np.all(ls.n_passes == 0)
        assert _messages(ctx, "load_sharing: ProcessingWarning", "no pulse from planet(s)")
        return
    m, purity = label_map(ctx, truth, "ring")
    assert purity == 1.0
    want = np.asarray(truth.load_sharing)[m]
    assert np.all(np.isfinite(ls.factors)) and np.all(np.isfinite(ls.std_error))
    assert np.max(np.abs(ls.factors - want)) <= exp.load_sharing, (ls.factors, want)
    assert np.sum(ls.factors) == pytest.approx(ls.factors.size, rel=1e-12)
    assert np.all(ls.n_passes >= 2)


@pytest.mark.parametrize("name", _params("identify", [n for n in ALL if n not in STRESS]))
def test_identified_errors_recover_the_truth(name):
    kind = EXPECT[name].ident
    ctx = synthetic_run(name)
    truth = ctx.load.truth
    ident = ctx.identify.identification
    g = ctx.gearset
    assert ident.n_passes > 0 and math.isfinite(ident.rms_after)
    assert ident.rms_after <= ident.rms_before
    if kind[0] == "zero":
        # no errors in the truth: the projected estimate stays at the encoder's resolution
        n = (ident.free.size - 4) // 2
        est = np.linalg.norm(ident.projector @ vector_from_errors(ident.errors, n)[ident.free])
        assert est <= kind[1], est
        return
    true = mapped_true_errors(ctx, truth, g)
    if kind[0] == "ratio":
        assert _ident_ratio(ident, true) <= kind[1]
    else:
        # noise-limited: each identifiable parameter within k of its own standard deviation
        vt = dict(zip(PARAMETER_NAMES(g.n_planets), vector_from_errors(true, g.n_planets)))
        z = [(est - vt[k]) / std for k, (est, std, ok) in ident.parameters.items() if ok]
        assert len(z) >= 4, ident.parameters
        assert np.all(np.isfinite(z)) and np.max(np.abs(z)) <= kind[1], z


BIAS_FREE = ["seed_rig", "table2_case1", "table2_case2", "facewidth_offcentre"]


@pytest.mark.parametrize("name", BIAS_FREE)
def test_identification_has_no_onset_offset_bias(name):
    ctx = synthetic_run(name)
    truth = ctx.load.truth
    assert _ident_ratio(ctx.identify.identification, mapped_true_errors(ctx, truth, ctx.gearset)) <= 0.05


@pytest.mark.parametrize("name", _params("centroids", FACEWIDTH))
def test_sun_centroid_matches_truth(name):
    # noise-free linear load across three gauges: exact up to rounding (1 µm tolerance)
    ctx = synthetic_run(name)
    truth = ctx.load.truth
    c = ctx.centroids.by_gear["sun"]
    assert c.shape == "linear" and c.contact_fraction == 1.0
    assert c.centroid == pytest.approx(float(np.mean(truth.centroid_sun)), abs=1e-6)
    assert np.ptp(truth.centroid_sun) == 0.0


def _pass_weighted_ring_centroid(ctx, truth) -> float:
    """sum LS_n Z_n / sum LS_n over the ring face-width passes the run used (their planets
    from the truth): what a centroid from the mean gauge readings measures."""
    ons = ctx.onsets.by_channel
    fw = [c.name for c in ctx.load.recording.channels
          if c.kind == "facewidth" and c.gear == "ring"]
    best = max(fw, key=lambda c: int(np.count_nonzero(ons[c].good)))
    t = ons[best].times[ons[best].good]
    et = np.asarray(truth.events[best].time)
    p = np.asarray(truth.events[best].planet)[_nearest(et, t)] - 1
    ls, z = np.asarray(truth.load_sharing), np.asarray(truth.centroid_ring)
    return float(np.sum(ls[p] * z[p]) / np.sum(ls[p]))


@pytest.mark.parametrize("name", ["facewidth_offcentre", "facewidth_tilt"])
def test_ring_centroid_matches_truth(name):
    ctx = synthetic_run(name)
    truth = ctx.load.truth
    c = ctx.centroids.by_gear["ring"]
    assert c.shape == "linear" and c.contact_fraction == 1.0
    # against the planets the passes came from: 2e-4 mm measured (pulse sampling), 0.01 mm
    assert c.centroid == pytest.approx(_pass_weighted_ring_centroid(ctx, truth), abs=1e-5)
    # against the load-weighted planet mean: the pass mix (5/4/5/5 in a minute) moves it
    ls, z = np.asarray(truth.load_sharing), np.asarray(truth.centroid_ring)
    assert c.centroid == pytest.approx(float(np.sum(ls * z) / np.sum(ls)), abs=1.5e-4)
    assert math.isfinite(c.std_error) and c.std_error < 0.5e-3


def test_partial_contact_ring_centroid_matches_truth():
    # regression: stage_centroids timed every pass by the first ring face-width gauge, which
    # reads nothing at the unloaded end of a partial contact: no rows, centroid NaN (shape
    # 'none') and no warning
    ctx = synthetic_run("facewidth_partial")
    truth = ctx.load.truth
    c = ctx.centroids.by_gear["ring"]
    assert c.shape == "partial"
    assert c.centroid == pytest.approx(float(np.mean(truth.centroid_ring)), abs=5e-5)
    # triangle centroid b/2 - L/3 = 9 mm with b = 40 mm: loaded length 33 mm of 40
    assert c.contact_fraction == pytest.approx(3 * (20e-3 - 9e-3) / 40e-3, abs=0.01)


@pytest.mark.parametrize("name", [n for n in ALL if n not in FACEWIDTH and n not in SLOW])
def test_no_centroid_work_without_facewidth_gauges(name):
    ctx = synthetic_run(name)
    assert ctx.centroids is None
    assert str(ctx.failed.get("centroids")) == CENTROIDS_SKIPPED and ctx.failed["centroids"].benign


@pytest.mark.parametrize("name", FACEWIDTH)
def test_centroids_are_numbers_for_every_gear(name):
    # every gear with face-width gauges gets a finite centroid with a finite std error, or
    # (a failure) a warning naming the gear: never a silent NaN
    ctx = synthetic_run(name)
    assert set(ctx.centroids.by_gear) == {"sun", "ring"}
    for gear, c in ctx.centroids.by_gear.items():
        if c is None or not math.isfinite(c.centroid):
            assert any(gear in m and "centroid" in m for m in ctx.messages), (gear, ctx.messages)
        else:
            assert math.isfinite(c.std_error) and 0.0 < c.contact_fraction <= 1.0


def test_a_minute_of_table1_stays_accurate():
    # table2_case1 at 1 min instead of its 0.5 s: 3 MSamples per channel, ~10 s to run
    ctx = run_scene(parse_scene(_scene_text("table2_case1", 1.0)))
    truth = ctx.load.truth
    assert not _messages(ctx, "fit no planet") and not _messages(ctx, "not reliable")
    for gear in ("sun", "ring"):
        assert label_map(ctx, truth, gear)[1] == 1.0
        assert ctx.compare.by_gear[gear].vs_truth["rms"] <= 5e-4
        assert ctx.compare.by_gear[gear].vs_model["rms"] <= 5e-4
    true = mapped_true_errors(ctx, truth, ctx.gearset)
    assert _ident_ratio(ctx.identify.identification, true) <= 0.25


# ----------------------------------------------------------------------------- stress case
def test_fast_ripple_failure_is_visible():
    # speed_ripple_fast: 5 % at 0.1 Hz + 2 % at 0.37 Hz against a 3.5 s relative sun
    # revolution. The phasing really is wrong (~0.3 cycles RMS against the truth), so what the
    # run must not do is present it as clean: the residual against the identified model
    # stays at the same size (0.19-0.25 measured) instead of the 1e-4 of a clean run, and
    # the fit does not absorb it (rms_after > 0.1).
    ctx = synthetic_run("speed_ripple_fast")
    cmp = ctx.compare.by_gear
    clean = synthetic_run("speed_ripple")
    for gear in ("sun", "ring"):
        assert cmp[gear].vs_truth["rms"] > 0.1
        assert cmp[gear].vs_model["rms"] > 0.1
        assert cmp[gear].vs_model["rms"] > 5 * clean.compare.by_gear[gear].vs_model["rms"]
    ident = ctx.identify.identification
    assert ident.rms_after > 0.1
    assert ident.rms_after > 5 * clean.identify.identification.rms_after


def test_fast_ripple_is_warned_about():
    # fixed: stage_phasing warns when the encoder misfit exceeds 0.01 mesh cycles
    ctx = synthetic_run("speed_ripple_fast")
    known = ("cannot be told from the pattern",)
    assert [m for m in ctx.messages
            if m.split(":")[0] in ("phasing", "identify", "compare")
            and "ProcessingWarning" in m and not any(k in m for k in known)]


# ============================================================================ bad inputs
GEARSET = """[gearset]
name = "seed rig"
z_sun = {z_sun}
z_ring = {z_ring}
z_planet = 31
n_planets = 4
carrier_radius_mm = 112.5
face_width_mm = 40
direction = "cw"
profile_shift = {profile_shift}
"""


@pytest.fixture(scope="module")
def rig():
    """One minute of the clean seed rig and its truth, to spoil in various ways."""
    return generate("seed_rig", duration=60.0, seed=SEED)


def run_file(tmp_path: Path, rec, *, z_sun: int = 25, z_ring: int = 87) -> RunContext:
    """Write ``rec`` as HDF5 and process it through a scene file, as a user would (tooth counts
    other than the file's 25/87/31 are declared profile shifted, so that they pass the scene's
    coaxiality check and reach the processing)."""
    meshphase.io.write(rec, tmp_path / "rec.h5")
    shift = "false" if (z_sun, z_ring) == (25, 87) else "true"
    text = (f'name = "bad input"\nresults = {RESULTS}\n'
            + GEARSET.format(z_sun=z_sun, z_ring=z_ring, profile_shift=shift)
            + '[input]\nrecording = "rec.h5"\n')
    (tmp_path / "scene.toml").write_text(text, encoding="utf-8")
    return run_scene(load_scene(tmp_path / "scene.toml"))


def truth_phasing_error(ctx: RunContext, truth, gear: str, g=None) -> dict:
    """Phasing error against the truth for a run without it (a file): every measured pass
    against the true mesh angle turned between its two pulses
    (:func:`meshphase.compare.predict.truth_comparison`)."""
    lab, table = ctx.phasing.labels[gear], ctx.phasing.tables[gear]
    out = truth_comparison(table, truth, lab.channel, times=lab.times, planets=lab.planet)
    out["table"] = table
    return out


def _json_has_no_nan(ctx: RunContext) -> None:
    # the machine-readable summary never carries NaN as a number (null instead)
    json.dumps(summary_dict(ctx), allow_nan=False)


@pytest.mark.parametrize("kind", ["zeros", "noise"])
def test_recording_without_pulses_gives_warnings_and_no_numbers(tmp_path, rig, kind):
    rec, _ = rig
    data = rec.data.copy()
    gauges = [rec.index("sun"), rec.index("ring")]
    if kind == "zeros":
        data[:, gauges] = 0.0
    else:
        data[:, gauges] = np.random.default_rng(1).normal(0.0, 5e-6, (rec.n_samples, 2))
    ctx = run_file(tmp_path, rec.replace_data(data))
    # nothing crashed: every stage ran or was skipped with a reason
    assert set(ctx.failed) <= {"centroids"}
    tables = ctx.phasing.tables
    assert all(len(t) == 0 for t in tables.values())
    assert ctx.compare.by_gear == {}
    ls = ctx.load_sharing.sharing
    assert np.all(np.isnan(ls.factors)) and np.all(ls.n_passes == 0)
    assert _messages(ctx, "load_sharing: ProcessingWarning", "no pulse from planet(s) [1, 2, 3, 4]")
    ident = ctx.identify.identification
    assert ident.n_passes == 0 and math.isnan(ident.rms_after) and not ident.identifiable
    assert _messages(ctx, "identify: ProcessingWarning", "no measured passes")
    if kind == "noise":
        assert _messages(ctx, "condition: DataQualityWarning", "'sun'", "low SNR")
        assert _messages(ctx, "condition: DataQualityWarning", "'ring'", "low SNR")
    _json_has_no_nan(ctx)


def test_dead_gauge_is_named_in_a_warning(tmp_path, rig):
    # one dead gauge (the sun's): the ring's results go on, and a warning from the stage that
    # found nothing names the sun gauge (before the fix: only an empty table, note 'no onsets')
    rec, truth = rig
    data = rec.data.copy()
    data[:, rec.index("sun")] = 0.0
    ctx = run_file(tmp_path, rec.replace_data(data))
    assert set(ctx.failed) <= {"centroids"}
    assert len(ctx.phasing.tables["sun"]) == 0
    assert [m for m in ctx.messages if m.startswith(("onsets:", "phasing:"))
            and "Warning" in m and "sun" in m and "planet 1 cannot be told" not in m]
    assert len(ctx.phasing.tables["ring"]) > 0
    assert set(ctx.compare.by_gear) == {"ring"}
    # the ring alone (its own encoder, 12 passes): 1.6e-3 against the truth as in adc16_clipped
    assert truth_phasing_error(ctx, truth, "ring", _gearset_of(rec))["rms"] <= 5e-3
    _json_has_no_nan(ctx)


def _remove_planet_pulses(rec, truth, channel: str, planet: int):
    """Zero a gauge's pulses from one planet: every truth engagement of that planet +-
    the pulse half-support (support mesh periods of this gauge) [s]."""
    sp = rec.meta["speeds_nominal"]
    g = _gearset_of(rec)
    w = abs(sp["ring"] - sp["carrier"]) if channel == "ring" else abs(sp["sun"] - sp["carrier"])
    z = g.z_ring if channel == "ring" else g.z_sun
    half = truth.pulse[channel]["support"] * 2 * math.pi / (z * w)
    t = rec.t0 + np.arange(rec.n_samples) / rec.fs
    ev = truth.events[channel]
    mask = np.zeros(rec.n_samples, bool)
    for te in np.asarray(ev.time)[np.asarray(ev.planet) == planet]:
        mask |= np.abs(t - te) <= half
    data = rec.data.copy()
    data[mask, rec.index(channel)] = 0.0
    return rec.replace_data(data), int(np.count_nonzero(np.asarray(ev.planet) == planet))


def _gearset_of(rec):
    from meshphase.models.gearset import Gearset

    return Gearset.from_dict(rec.meta["gearset"])


def test_missing_planet_is_warned_and_the_others_are_given(tmp_path, rig):
    rec, truth = rig
    spoilt, n_removed = _remove_planet_pulses(rec, truth, "ring", 3)
    assert n_removed >= 4
    ctx = run_file(tmp_path, spoilt)
    assert set(ctx.failed) <= {"centroids"}
    ls = ctx.load_sharing.sharing
    # planet 3 is named; every factor is either a finite number from >= 2 passes or NaN with
    # no pass behind it (never a NaN or a number presented the other way round)
    msgs = _messages(ctx, "load_sharing: ProcessingWarning", "no pulse from planet(s)")
    assert msgs and "3" in msgs[0].split("planet(s)")[1].split("]")[0]
    assert np.isnan(ls.factors[2]) and ls.n_passes[2] == 0
    seen = ls.n_passes > 0
    assert np.all(np.isfinite(ls.factors[seen])) and np.all(np.isnan(ls.factors[~seen]))
    assert ls.factors[seen] == pytest.approx(np.ones(seen.sum()), abs=1e-4)
    # the sun gauge is untouched and as accurate as on the clean file
    g = _gearset_of(rec)
    assert truth_phasing_error(ctx, truth, "sun", g)["rms"] <= 1e-4
    # the ring phasing that is given is right
    assert len(ctx.phasing.tables["ring"]) > 0
    assert truth_phasing_error(ctx, truth, "ring", g)["rms"] <= 5e-4
    _json_has_no_nan(ctx)


def test_missing_planet_costs_only_that_planet(tmp_path, rig):
    # regression: with one planet's pulses gone every N-step span of the ring train was 1.25
    # revolutions, the pattern period followed it and planet 2's pulses were dropped as well
    # ('7 pulse(s) fit no planet'; load sharing for planets 1 and 4 only)
    rec, truth = rig
    spoilt, _ = _remove_planet_pulses(rec, truth, "ring", 3)
    ctx = run_file(tmp_path, spoilt)
    ls = ctx.load_sharing.sharing
    assert ls.n_passes.tolist()[:2] + ls.n_passes.tolist()[3:] == [5, 5, 5]
    assert not _messages(ctx, "fit no planet")


def test_wrong_tooth_counts_blow_up_the_residuals(tmp_path, rig):
    """A gearset that does not belong to the file. What shows it (documented here):

    * the angle model cannot tie the sun and the ring pass trains together (one mesh angle
      drives both only with the right tooth counts): each train's passes scatter 300x to
      140000x beyond their timing bound (measured for z_sun 29 and z_ring 91; 1.0 with the
      right counts) and both gauges' phasing is flagged "not reliable", with that reason;
    * z_sun 24 (Z_s + Z_r = 111 cannot be assembled with 4 equally spaced planets) is refused
      by the scene before anything runs; z_sun 29 and z_ring 91 (assemblable: 116 = 4 x 29;
      declared profile shifted, else the scene refuses them as not coaxial) give the above;
    * the residuals against the identified model are >= 30x those with the right counts.
    """
    rec, _ = rig
    for sub in ("right", "z24", "z29", "z91"):
        (tmp_path / sub).mkdir()
    right = run_file(tmp_path / "right", rec)
    base = {gear: right.compare.by_gear[gear].vs_model["rms"] for gear in ("sun", "ring")}
    assert base["sun"] < 2e-4 and base["ring"] < 5e-4
    assert all(r["reliable"] for r in right.phasing.reliability.values())
    with pytest.raises(SceneError, match=r"\[gearset.n_planets\] 4 equally spaced planets cannot be assembled"):
        run_file(tmp_path / "z24", rec, z_sun=24)
    z29 = run_file(tmp_path / "z29", rec, z_sun=29)
    z91 = run_file(tmp_path / "z91", rec, z_ring=91)
    for ctx in (z29, z91):
        assert set(ctx.failed) <= {"centroids"}
        model = ctx.phasing.model
        assert min(t.scale for t in model.trains) > 30
        for gear in ("sun", "ring"):
            rel = ctx.phasing.reliability[gear]
            assert not rel["reliable"] and any("beyond their timing bound" in r for r in rel["reasons"])
            assert _messages(ctx, f"{gear} gauge: phasing not reliable")
        assert ctx.compare.by_gear["ring"].vs_model["rms"] > 30 * base["ring"]
        assert ctx.identify.identification.rms_after > 30 * right.identify.identification.rms_after


GAP = (20.0, 33.0)   # [s]: longer than a relative ring revolution (12.2 s), ~4 sun ones


def _with_gap(rec):
    t = rec.t0 + np.arange(rec.n_samples) / rec.fs
    data = rec.data.copy()
    data[(t >= GAP[0]) & (t < GAP[1]), :] = np.nan
    return rec.replace_data(data)


@pytest.fixture(scope="module")
def gap_run(rig, tmp_path_factory):
    rec, truth = rig
    return run_file(tmp_path_factory.mktemp("gap"), _with_gap(rec)), truth


def test_gap_across_a_revolution_gives_no_onset_inside_and_finite_results(gap_run):
    ctx, truth = gap_run
    assert set(ctx.failed) <= {"centroids"}
    for ch in ("sun", "ring"):
        assert _messages(ctx, "DataQualityWarning", f"'{ch}'", "non-finite")
        o = ctx.onsets.by_channel[ch]
        assert not np.any((o.times >= GAP[0]) & (o.times < GAP[1])), ch
    given = {g: t for g, t in ctx.phasing.tables.items() if len(t)}
    assert given, "no phasing at all"
    for gear, t in given.items():
        assert np.all(np.isfinite(t.gamma)) and np.all(np.isfinite(t.time))
        # passes across the gap: the missing reference passes are bridged (or passes dropped),
        # and the table says so
        assert any("bridged" in n or "dropped" in n for n in t.notes), t.notes
        assert not np.any((t.time >= GAP[0]) & (t.time < GAP[1]))
        assert math.isfinite(ctx.compare.by_gear[gear].vs_ideal["rms"])
    ls = ctx.load_sharing.sharing
    assert np.all(np.isfinite(ls.factors))
    _json_has_no_nan(ctx)


def test_gap_across_a_revolution_keeps_the_accuracy(gap_run):
    # regression: the onset detector filled the 13 s gap with one constant and took the noise
    # from all samples, the MAD (and the threshold) collapsed and 7 of the 54 sun pulses
    # outside the gap were found; the ring, left on its own encoder, came out 0.29 cycles off
    ctx, truth = gap_run
    g = ctx.gearset
    et = np.asarray(truth.events["sun"].time)
    outside = np.count_nonzero((et < GAP[0] - 1.0) | (et > GAP[1] + 1.0))
    assert len(ctx.onsets.by_channel["sun"]) >= 0.9 * outside
    # with the fixes: sun 1.2e-3 (36 passes, 4 revolutions bridged), ring 2e-3
    assert truth_phasing_error(ctx, truth, "sun", g)["rms"] <= 5e-3
    assert truth_phasing_error(ctx, truth, "ring", g)["rms"] <= 1e-2
