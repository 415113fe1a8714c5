"""meshphase on recordings it did not make: NI-style TDMS files from the independent reference
rig (tests/independent/rig.py, which shares no code with pipeline/ or synthetic/), processed as
a user would, through a scene file with the speeds typed as a user types them (sun 18.19 r/min,
carrier 4.06 r/min: the held ring's Willis speed is then -3.4e-4 r/min, not 0).

What is checked, against the generator's own truth (integrated angles, brentq engagements):
the per-pass phasing error of both gauges against the target of the measured-phasing issue
(<= max(2e-3, 1.3 x the timing floor) mesh cycles); the ring gauge's planet 1 named by the
tacho; the held member found; no "not reliable" warning; the same file read as TDMS and as CSV
(meshphase convert) gives the same phasing to 1e-7 cycles. The default suite runs the steady,
1 % and 3 % carrier-ripple presets (2 min each); ``-m slow`` every preset.

The target is a claim about the expected RMS error, and a 2-min recording holds few passes: 21
on the ring gauge (7 carrier turns, 3 passes each), whose passes of one turn share their
planet-1 reference pulse. Their sample RMS spreads by about +-25 % around the expected one
(seed 5 of the ``ccw`` preset: 1.47 x the floor on the ring, 1.13 on 10 minutes of the same
preset; 8-10 minute records of ``steady`` and ``ccw`` over 19 more seeds: ring 0.86-1.24,
mean 1.04, sun 0.94-1.18, mean 1.05). So the target is asserted where a sample can carry it:
on the passes of all presets of a run pooled (:func:`test_pooled_error_within_target`), and
each preset must not reject it (its RMS within the target times the 99.9 % chi-square
allowance for its passes' degrees of freedom, :func:`allowance`): a preset 2x off fails, a
preset drawn unlucky does not.
"""

import math
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from meshphase.run.scene import parse_scene
from meshphase.run.stages import run_scene
from . import rig as R

DEG = math.pi / 180.0
TARGET_ABS, TARGET_RATIO = 2e-3, 1.3


def _errors(n):
    # seed 000 Table 2 case 1: 0.2 mm on every gear, the angles of the table
    return {"e_sun": 0.2e-3, "kappa_sun": 4 * DEG, "e_ring": 0.2e-3, "kappa_ring": 60 * DEG,
            "e_planet": (0.2e-3,) * n, "kappa_planet": (20 * DEG,) * n}


def scene_text(truth: R.RigTruth, path: Path, *, geometry: bool = True) -> str:
    cfg = R.RigConfig.from_dict(truth.config)
    g = cfg.gearset
    sp = truth.speeds
    names = {c["kind"]: c["name"] for c in truth.channels}
    ang = ", ".join(f"{a / DEG:.12g}" for a in g.planet_angles)
    text = f'''name = "independent rig"
results = ["phasing", "compare"]
[gearset]
z_sun = {g.z_sun}
z_ring = {g.z_ring}
z_planet = {g.z_planet}
planet_angles_deg = [{ang}]
carrier_radius_mm = {g.carrier_radius * 1e3}
direction = "{sp.get("planet_rotation", "cw")}"
profile_shift = {"true" if g.z_ring != g.z_sun + 2 * g.z_planet else "false"}
[speeds]
sun_rpm = {sp["sun_rpm"]}
carrier_rpm = {sp["carrier_rpm_scene"]}
[input]
recording = "{path}"
[[channels]]
name = "{names["sun"]}"
kind = "sun"
[[channels]]
name = "{names["ring"]}"
kind = "ring"
'''
    if geometry and truth.tacho:
        text += f"mount_angle_deg = {cfg.ring_gauge_angle / DEG!r}\n"
    if "tacho" in names:
        text += f'[[channels]]\nname = "{names["tacho"]}"\nkind = "tacho"\n'
        if geometry:
            text += f"[tacho]\nkey_angle_deg = {truth.tacho['key_carrier_angle'] / DEG!r}\n"
    if truth.encoder:
        # a [[channels]] table after [tacho] would belong to it: encoder entries go first
        enc = (f'[[channels]]\nname = "{truth.encoder["channel"]}"\nkind = "encoder"\n'
               f'shaft = "{truth.encoder["shaft"]}"\npulses_per_rev = {truth.encoder["pulses_per_rev"]}\n')
        text = text.replace("[[channels]]\n", enc + "[[channels]]\n", 1)
    return text


def per_pass_errors(ctx, truth: R.RigTruth, gear: str) -> dict:
    """Every measured pass against the true mesh angle turned between its two pulses."""
    cfg = R.RigConfig.from_dict(truth.config)
    rig = R.Rig(cfg)
    names = {c["kind"]: c["name"] for c in truth.channels}
    tab = ctx.phasing.tables[gear]
    eng = truth.engagements[names[gear]]
    et, epl = np.asarray(eng["t"]), np.asarray(eng["planet"])

    def nearest(x):
        j = np.clip(np.searchsorted(et, x), 1, et.size - 1)
        return np.where(np.abs(et[j - 1] - x) < np.abs(et[j] - x), j - 1, j)

    off = float(np.median(tab.time - et[nearest(tab.time)]))
    i_n, i_1 = nearest(tab.time - off), nearest(tab.ref_time - off)
    z = cfg.gearset.z_sun if gear == "sun" else cfg.gearset.z_ring
    th = rig.motion.angle("sun_rel" if gear == "sun" else "ring_rel", et)
    true = np.mod(z * np.abs(th[i_n] - th[i_1]) / (2 * math.pi), 1.0)
    err = (tab.gamma - true + 0.5) % 1.0 - 0.5
    floor = float(np.sqrt(np.mean(tab.timing_floor ** 2)))
    return {"rms": float(np.sqrt(np.mean(err ** 2))), "floor": floor, "n": err.size,
            "labels": float(np.mean(epl[i_n] == tab.planet)), "z": err / tab.uncertainty}


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    return tmp_path_factory.mktemp("indep")


def make(files: Path, preset: str, minutes: float = 2.0, seed: int = 5):
    p = files / f"{preset}.tdms"
    cfg = R.preset_config(preset, minutes=minutes, seed=seed)
    if not p.exists():
        R.make_preset_tdms(p, preset, minutes=minutes, seed=seed,
                           errors=_errors(cfg.gearset.n_planets))
    return p, R.read_truth(R.truth_path(p))


def run(files: Path, preset: str, **kw):
    p, truth = make(files, preset, **kw)
    scene = files / f"{preset}.toml"
    scene.write_text(scene_text(truth, p), encoding="utf-8")
    return run_scene(parse_scene(scene.read_text(encoding="utf-8"), scene)), truth


def max_phasing_difference(a, b) -> float:
    """Largest difference [mesh cycles] between two runs' phasing of the same passes, over
    both gears (wrapped to [-0.5, 0.5)); the runs must have the same, non-empty pass tables."""
    worst = 0.0
    for gear in ("sun", "ring"):
        ta, tb = a.phasing.tables[gear], b.phasing.tables[gear]
        assert len(ta) == len(tb) > 0, (gear, len(ta), len(tb))
        d = (ta.gamma - tb.gamma + 0.5) % 1.0 - 0.5
        worst = max(worst, float(np.max(np.abs(d))))
    return worst


def differs_from_the_tdms(files: Path, truth: R.RigTruth, path: Path, fs_hz: float | None = None) -> float:
    """:func:`max_phasing_difference` of the ``ripple1_carrier`` recording written again as
    ``path`` (another format or layout; the scene gives ``[input] fs_Hz`` when ``fs_hz``)
    from the rig's own TDMS file."""
    text = scene_text(truth, path)
    if fs_hz is not None:
        text = text.replace("[input]\n", f"[input]\nfs_Hz = {fs_hz!r}\n")
    ctx = run_scene(parse_scene(text, path.with_suffix(".toml")))
    base, _ = run(files, "ripple1_carrier")
    return max_phasing_difference(base, ctx)


def allowance(n: int, n_planets: int, p: float = 0.999) -> float:
    """How far the RMS of ``n`` per-pass errors may exceed their expected RMS by chance at
    level ``p`` [-]: sqrt(chi2_p(nu) / nu). A turn's N - 1 passes share the planet-1 pulse
    (errors e_n - e_1: covariance 2 on the diagonal, 1 off it, eigenvalues N and 1), so their
    squares sum to N chi2_1 + (N - 2) chi2_1: nu = 4 (N - 1) / (N + 2) per turn, by
    Satterthwaite (2 of 3 for four planets)."""
    nu = max(n * 4.0 / (n_planets + 2), 1.0)
    return math.sqrt(float(stats.chi2.ppf(p, nu)) / nu)


def check(ctx, truth) -> dict:
    """The checks of one preset; returns its per-gear errors (``per_pass_errors`` plus the
    squared sums the pooled test adds up)."""
    assert not ctx.failed, ctx.failed
    assert not [m for m in ctx.messages if "not reliable" in m], ctx.messages
    out = {}
    n_planets = R.RigConfig.from_dict(truth.config).gearset.n_planets
    for gear in ("sun", "ring"):
        e = per_pass_errors(ctx, truth, gear)
        assert e["n"] >= 15
        # inside the envelope the choice of angle model adds less than 10 % to the sigma
        # (the chosen fit itself is the same with or without its competitors)
        tab = ctx.phasing.tables[gear]
        own = np.sqrt(np.maximum(tab.uncertainty ** 2 - tab.choice_sigma ** 2, 0.0))
        assert np.sqrt(np.mean(tab.uncertainty ** 2)) <= 1.1 * np.sqrt(np.mean(own ** 2)), gear
        target = max(TARGET_ABS, TARGET_RATIO * e["floor"])
        assert e["rms"] <= target * allowance(e["n"], n_planets), (gear, e["rms"], e["floor"])
        out[gear] = e
    ph = ctx.phasing
    assert ph.fixed == "ring"
    if truth.tacho:
        assert ph.assignment["ring"]["shift_decided_by"] == "tacho"
        assert out["ring"]["labels"] == 1.0
    return out


_OUTCOMES: dict = {}


def outcome(files: Path, preset: str) -> dict:
    """:func:`check` of a preset, run once per module (the per-preset and pooled tests share it)."""
    if preset not in _OUTCOMES:
        ctx, truth = run(files, preset)
        if truth.encoder:
            _ENCODER_RUN[preset] = (ctx, truth)       # its own test looks at the encoder
        _OUTCOMES[preset] = check(ctx, truth)
    return _OUTCOMES[preset]


def pooled(outs) -> dict:
    """Per gear: RMS error and RMS floor over every pass of ``outs`` [mesh cycles]."""
    res = {}
    for gear in ("sun", "ring"):
        n = sum(o[gear]["n"] for o in outs)
        err2 = sum(o[gear]["rms"] ** 2 * o[gear]["n"] for o in outs)
        fl2 = sum(o[gear]["floor"] ** 2 * o[gear]["n"] for o in outs)
        res[gear] = {"n": n, "rms": math.sqrt(err2 / n), "floor": math.sqrt(fl2 / n)}
    return res


FAST = ["steady", "ripple1_carrier", "ripple3_carrier"]


@pytest.mark.parametrize("preset", FAST)
def test_independent_rig_recordings_are_measured_right(files, preset):
    outcome(files, preset)


SLOW = [p for p in R.PRESETS if p not in FAST]


@pytest.mark.slow
@pytest.mark.parametrize("preset", SLOW)
def test_independent_rig_every_preset(files, preset):
    outcome(files, preset)


@pytest.mark.parametrize("presets", [pytest.param(FAST, id="default"),
                                     pytest.param(SLOW, id="every-other", marks=pytest.mark.slow)])
def test_pooled_error_within_target(files, presets):
    # the measured-phasing target on every pass of the presets together (module docstring):
    # 252 sun and 72 ring passes by default, 754 and 213 in the slow set; pooled today:
    # 1.02 and 1.07 x the floor by default, 1.04 and 1.07 in the slow set
    for gear, e in pooled([outcome(files, p) for p in presets]).items():
        assert e["rms"] <= max(TARGET_ABS, TARGET_RATIO * e["floor"]), (gear, e)


@pytest.mark.parametrize("n_planets, turns", [(4, 7), (4, 28), (3, 8), (5, 8)])
def test_allowance_matches_simulated_passes(n_planets, turns):
    # the allowance's premise, simulated: per turn, N - 1 passes e_n - e_1 of unit-variance
    # onset errors; the 99.9 % point of their mean square over its expectation (2) is
    # allowance^2 to the Satterthwaite approximation's accuracy (a few % of the square here)
    rng = np.random.default_rng(0)
    e = rng.standard_normal((200_000, turns, n_planets))
    d = e[:, :, 1:] - e[:, :, :1]
    ms = np.mean(d.reshape(len(d), -1) ** 2, axis=1) / 2.0
    q = float(np.quantile(ms, 0.999))
    a2 = allowance(turns * (n_planets - 1), n_planets) ** 2
    assert abs(a2 / q - 1.0) < 0.06, (a2, q)


def test_ring_gauge_and_tacho_alone_flag_the_carrier_ripple_they_cannot_see(files, tmp_path):
    # the sun gauge left out (dead, clipped or never fitted): the held ring's gauge and the
    # carrier tacho meet the carrier at fixed angles only, so the ordinary 1 % carrier ripple
    # is invisible to them and moves the ring's phasing by ~0.14 mesh cycles (54 x the floor
    # on this preset) with residuals at the floor; the run must say the phasing is not
    # reliable, and why
    p, truth = make(files, "ripple1_carrier")
    text = scene_text(truth, p)
    sun = next(c["name"] for c in truth.channels if c["kind"] == "sun")
    text = text.replace(f'[[channels]]\nname = "{sun}"\nkind = "sun"\n', "")
    assert sun not in text
    scene = tmp_path / "ring_only.toml"
    scene.write_text(text, encoding="utf-8")
    ctx = run_scene(parse_scene(text, scene))
    e = per_pass_errors(ctx, truth, "ring")
    assert e["rms"] > 10 * e["floor"]                   # the error the warning is about
    rel = ctx.phasing.reliability["ring"]
    assert not rel["reliable"]
    assert any("carrier angle is not seen" in r for r in rel["reasons"])
    assert [m for m in ctx.messages if "ring gauge: phasing not reliable" in m]


def test_compressive_gauges_give_the_same_phasing(files, tmp_path):
    # gauges on the compressive fillet (or bridges wired the other way round) record the
    # pulses upside down: here both gauges through gain = -1. Timed as positive pulses they
    # were timed on the side lobes (ring 2.3-2.6 x its floor, no warning); the sign is now
    # found from the data, and the phasing is that of the upright recording
    p, truth = make(files, "ripple1_carrier")
    text = scene_text(truth, p)
    out = {}
    for label, t in (("upright", text),
                     ("inverted", text.replace('kind = "sun"\n', 'kind = "sun"\ngain = -1\n')
                                      .replace('kind = "ring"\n', 'kind = "ring"\ngain = -1\n'))):
        scene = tmp_path / f"{label}.toml"
        scene.write_text(t, encoding="utf-8")
        out[label] = run_scene(parse_scene(t, scene))
    assert text.count("gain = -1") == 0
    assert max_phasing_difference(out["upright"], out["inverted"]) < 1e-9
    ons = out["inverted"].onsets.by_channel
    assert all(np.all(o.amplitude < 0) for o in ons.values() if len(o))
    assert not [m for m in out["inverted"].messages if "not reliable" in m]
    note = out["inverted"].onsets.error_estimate
    assert "negative (compressive) pulses on" in note and all(nm in note for nm in ons)
    assert "negative" not in out["upright"].onsets.error_estimate


def test_swapped_gauge_channels_are_named(files, tmp_path):
    # the sun's and the ring's channel given each other's kind: both gears' phasing is then
    # 27-29x its floor, which the reliability check sees only as scatter; the pass rates
    # (a sun gauge's come Z_r / Z_s = 3.48x as often as a ring gauge's) name the cause
    p, truth = make(files, "ripple1_carrier")
    names = {c["kind"]: c["name"] for c in truth.channels}
    text = (scene_text(truth, p).replace(f'name = "{names["sun"]}"', "name = \"@\"")
            .replace(f'name = "{names["ring"]}"', f'name = "{names["sun"]}"')
            .replace("name = \"@\"", f'name = "{names["ring"]}"'))
    ctx = run_scene(parse_scene(text, tmp_path / "swapped.toml"))
    swapped = [m for m in ctx.messages if "look swapped" in m]
    assert len(swapped) == 1 and f"'{names['ring']}' (kind sun)" in swapped[0]
    ok, _ = run(files, "ripple1_carrier")
    assert not [m for m in ok.messages if "swapped" in m or "passes come" in m]


def _sun_stepped(files: Path, tmp_path: Path, at: float):
    """(run, truth, sun channel) of ``ripple1_carrier`` with the sun gauge's level stepped by
    twice its pulse height at ``at`` [s]."""
    import meshphase.io as mio
    from meshphase.recording import Recording

    p, truth = make(files, "ripple1_carrier")
    rec = mio.read(p)
    sun = next(c["name"] for c in truth.channels if c["kind"] == "sun")
    d = np.array(rec.data, dtype=float)
    i = rec.names.index(sun)
    d[int(at * rec.fs):, i] += 2.0 * np.percentile(np.abs(d[:, i]), 99.9)
    stepped = tmp_path / f"step{at:g}.h5"
    mio.write(Recording(d, rec.fs, rec.channels, t0=rec.t0, start_datetime=rec.start_datetime,
                        meta=rec.meta), stepped)
    text = scene_text(truth, p).replace(str(p), str(stepped))
    return run_scene(parse_scene(text, stepped.with_suffix(".toml"))), truth, sun


def test_level_step_mid_record_is_named(files, tmp_path):
    # the same step at 90 s, after the noise spectrum's minute: the drift baseline ramps
    # across the 4.2-s block that holds it, a few pulses there are lost or timed off, and
    # the sun gauge was flagged 'not reliable' with nothing to say why; the step is named
    ctx, _, sun = _sun_stepped(files, tmp_path, 90.0)
    said = [m for m in ctx.messages if "the baseline steps by" in m and sun in m]
    assert len(said) == 1
    t = float(said[0].split("near t = ")[1].split(" s")[0])
    assert abs(t - 90.0) < 4.3                          # within the block that holds it
    base, _ = run(files, "ripple1_carrier")
    assert not [m for m in base.messages if "baseline steps" in m]


def test_level_step_in_the_first_minute_does_not_inflate_the_floor(files, tmp_path):
    # a bridge's level step of twice the pulse height at 20 s on the sun gauge: conditioning
    # leaves a decaying transient, which the noise spectrum (from the first minute) took for
    # noise: the sun's timing floor was 13x what its passes scattered (3.8e-2 cycles against
    # 2.9e-3), with no warning, and the reliability check then measures scatter against a
    # floor that large. The windows with the transient are now left out, and named
    ctx, truth, sun = _sun_stepped(files, tmp_path, 20.0)
    base, _ = run(files, "ripple1_carrier")
    e, e0 = per_pass_errors(ctx, truth, "sun"), per_pass_errors(base, truth, "sun")
    assert e["floor"] < 1.3 * e0["floor"]               # 13x before
    assert e["rms"] < 1.3 * e["floor"]                  # and the passes are as good
    assert [m for m in ctx.messages if "hold a transient" in m and sun in m]
    assert not [m for m in base.messages if "hold a transient" in m]


def test_tdms_and_csv_of_one_recording_give_the_same_phasing(files, tmp_path):
    # the same samples through two formats: the CSV's time column and the TDMS waveform
    # timing differ by rounding (~1e-9 s); nothing in the phasing may depend on it
    import meshphase.io as pio

    p, truth = make(files, "ripple1_carrier")
    rec = pio.read(p)
    csv = tmp_path / "same.csv"
    pio.write(rec, csv)
    out = {}
    for label, path in (("tdms", p), ("csv", csv)):
        scene = tmp_path / f"{label}.toml"
        scene.write_text(scene_text(truth, path), encoding="utf-8")
        out[label] = run_scene(parse_scene(scene.read_text(encoding="utf-8"), scene))
    assert max_phasing_difference(out["tdms"], out["csv"]) < 1e-7


def test_a_labview_spreadsheet_file_gives_the_same_phasing(files, tmp_path):
    # the recording as LabVIEW's 'Write To Spreadsheet File' on a decimal-comma PC writes
    # it: tab-separated, '1,234560E-5', time to 0.1 ms ('%.4f': up to 0.26 sample off the
    # grid at 5120 Hz). It was 'unknown format'; now it reads, and the phasing is the
    # TDMS file's to what 7 significant digits leave
    import meshphase.io as pio

    p, truth = make(files, "ripple1_carrier")
    rec = pio.read(p)
    t = rec.t0 + np.arange(rec.n_samples) / rec.fs
    cols = [np.char.mod("%.4f", t)] + [np.char.mod("%.6E", rec.data[:, j]) for j in range(rec.n_channels)]
    rows = np.char.replace(np.char.add(np.char.add(cols[0], "\t"), cols[1]), ".", ",")
    for c in cols[2:]:
        rows = np.char.add(np.char.add(rows, "\t"), np.char.replace(c, ".", ","))
    header = "\t".join(["Time [s]"] + [f"{c.name} [{c.units}]" for c in rec.channels])
    lv = tmp_path / "labview.csv"
    lv.write_text(header + "\n" + "\n".join(rows.tolist()) + "\n", encoding="utf-8")
    out = {}
    for label, path in (("tdms", p), ("labview", lv)):
        scene = tmp_path / f"{label}.toml"
        scene.write_text(scene_text(truth, path), encoding="utf-8")
        out[label] = run_scene(parse_scene(scene.read_text(encoding="utf-8"), scene))
    assert max_phasing_difference(out["tdms"], out["labview"]) < 1e-7   # 5e-9 measured; floor ~2.6e-3


@pytest.mark.parametrize("timing", ["clock channel", "scene fs_Hz"])
def test_a_tdms_file_without_waveform_timing_gives_the_same_phasing(files, tmp_path, timing):
    # DIAdem, LabVIEW's 'Write to Measurement File' without waveforms or a script write the
    # channels with no wf_increment: the file was 'missing or non-positive sample rate'
    # from the CLI. A Time channel beside them, or [input] fs_Hz in the scene, gives the rate
    from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

    import meshphase.io as pio

    p, truth = make(files, "ripple1_carrier")
    rec = pio.read(p)
    objs = [RootObject(), GroupObject("Log")]
    if timing == "clock channel":
        objs.append(ChannelObject("Log", "Time", np.arange(rec.n_samples) / rec.fs))
    objs += [ChannelObject("Log", c.name, rec.data[:, j].copy(), properties={"unit_string": c.units})
             for j, c in enumerate(rec.channels)]
    plain = tmp_path / "plain.tdms"
    with TdmsWriter(str(plain)) as w:
        w.write_segment(objs)
    assert differs_from_the_tdms(files, truth, plain, rec.fs if timing == "scene fs_Hz" else None) < 1e-9


@pytest.mark.parametrize("rate", ["attribute", "scene fs_Hz"])
def test_an_hdf5_file_of_another_tool_gives_the_same_phasing(files, tmp_path, rate):
    # an h5py script's file: one dataset per channel under a group, the rate as an
    # attribute (or nowhere: the scene gives it); it was 'not a meshphase recording'
    import h5py

    import meshphase.io as pio

    p, truth = make(files, "ripple1_carrier")
    rec = pio.read(p)
    other = tmp_path / "script.h5"
    with h5py.File(other, "w") as f:
        g = f.create_group("daq")
        if rate == "attribute":
            g.attrs["sample_rate"] = rec.fs
        for j, c in enumerate(rec.channels):
            g[c.name] = rec.data[:, j]
    assert differs_from_the_tdms(files, truth, other, rec.fs if rate == "scene fs_Hz" else None) < 1e-9


def test_sun_encoder_sees_the_planet_rate_ripple(files):
    # a 1 % common speed ripple at the planets' spin rate: with Z_r / Z_p an integer it is, at
    # the gauges and the once-per-turn tacho, the same function of time as equal planet
    # terms on every planet (without an encoder: sun / ring 0.056 / 0.064 mesh cycles on
    # seed 5, RMS(err/sigma) ~20). A 60-pulse sun-shaft encoder samples the mesh angle every
    # 0.32 mesh cycles and sees it: the measured-phasing target with honest sigma
    # (seeds 1, 2, 3, 5: sun 0.82-1.07, ring 0.89-1.21 x the floor; RMS(err/sigma) 0.77-1.11)
    res = outcome(files, "planet_ripple1_encoder")
    ctx, truth = _ENCODER_RUN["planet_ripple1_encoder"]
    for gear, e in res.items():
        # RMS(err/sigma) is ~1 where sigma is honest; the band is the 99.9 % chi-square
        # allowance of the passes' degrees of freedom each way
        a = allowance(e["n"], 4)
        assert 1.0 / a <= float(np.sqrt(np.mean(e["z"] ** 2))) <= a, (gear, e)
    assert "planet ripple" in ctx.phasing.model.terms
    name = truth.encoder["channel"]
    assert any(f"encoder {name}" in n and "0 extra dropped, 0 missing counted" in n
               for n in ctx.phasing.notes), ctx.phasing.notes
    # edges timed to a fraction of a sample: a sharp (TTL) edge crossed between two samples
    # is uniform within one sample period, RMS 1 / sqrt(12) = 0.29 of a sample
    got = ctx.onsets.encoder_times[name]
    true = np.asarray(truth.encoder["rising_edges"])
    true = true[true > 0.0]                  # an edge at sample 0 has no sample before it
    assert got.size == true.size
    err = (got - true) * truth.fs
    assert abs(float(np.mean(err))) < 0.1
    assert 0.25 < float(np.std(err)) < 0.33


_ENCODER_RUN: dict = {}


# The tester's conditions outside the envelope (seed 000 rig unless said, 2 min, seed 5):
# per gear, the phasing must be within the target, or the run must say 'unreliable' (exit
# 3), name the cause, and carry a sigma that covers the error (RMS(error / sigma) <= 1.5).
OUTSIDE = {
    # a 1 % common speed ripple at the planets' spin rate: with Z_r / Z_p = 3 the same columns
    # as equal planet terms (0.055 / 0.064 cycles, 20x the floor, 'ok' at RMS(err/sigma) 20)
    "planet_ripple": ({"ripple": ((0.01, 1.0, "planet", 0.0),)}, "planet spin rate"),
    # the same on 25 / 85 / 30 with 5 planets: the ripple explains the passes far better
    "planet_ripple_five": ({"z": (25, 85, 30), "planets": 5, "carrier_radius": 0.110,
                            "ripple": ((0.01, 1.0, "planet", 0.0),)}, "planet spin rate"),
    # a fast rig (sun 120 r/min) under the ordinary 1 % carrier ripple
    "fast_carrier_ripple": ({"sun_rpm": 120.0, "ripple": ((0.01, 1.0, "carrier", 0.0),)}, ""),
}


@pytest.mark.parametrize("row", list(OUTSIDE))
def test_outside_the_envelope_the_answer_is_right_or_flagged(files, row):
    from meshphase.run.exits import run_status

    kw, cause = OUTSIDE[row]
    p = files / f"{row}.tdms"
    n_planets = kw.get("planets", 4)
    if not p.exists():
        R.write_rig_tdms(R.Rig(R.make_rig_config(minutes=2.0, seed=5, errors=_errors(n_planets),
                                                 **kw)), p)
    truth = R.read_truth(R.truth_path(p))
    scene = p.with_suffix(".toml")
    scene.write_text(scene_text(truth, p), encoding="utf-8")
    ctx = run_scene(parse_scene(scene.read_text(encoding="utf-8"), scene))
    assert not ctx.failed, ctx.failed
    status = run_status(ctx)
    for gear in ("sun", "ring"):
        e = per_pass_errors(ctx, truth, gear)
        if e["rms"] <= max(TARGET_ABS, TARGET_RATIO * e["floor"]) * allowance(e["n"], n_planets):
            continue
        rel = ctx.phasing.reliability[gear]
        assert not rel["reliable"], (gear, e["rms"], e["floor"])
        assert status["status"] == "unreliable" and status["exit_code"] == 3
        assert gear in status["unreliable"]
        assert any(cause in r for r in rel["reasons"]), rel["reasons"]
        # 1.5: the calibration target for a flagged value (the sigma covers the
        # explanations the data cannot rule out, not the truth's exact share of them)
        assert float(np.sqrt(np.mean(e["z"] ** 2))) <= 1.5, (gear, e["rms"])
