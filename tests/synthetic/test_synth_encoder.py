"""The synthetic generator's encoder channel (EncoderConfig), the rig_ripple_planet_encoder
scenario measured end to end, and encoder channel specs through every writer and reader."""

import numpy as np
import pytest

import meshphase.io as mio
from meshphase.bench.phasing import TARGET_ABS, TARGET_FLOOR_RATIO
from meshphase.compare.predict import truth_comparison
from meshphase.kinematics.encoder import clean_edges, edge_times
from meshphase.run.scene import Scene
from meshphase.run.stages import run_scene
from meshphase.synthetic import EncoderConfig, SynthConfig, generate, get_scenario
from meshphase.synthetic.tdms_export import write_tdms


def _short(encoder: EncoderConfig, seconds: float = 20.0) -> SynthConfig:
    return get_scenario("rig_ripple_planet_encoder").with_(duration=seconds, encoder=encoder)


def test_encoder_config_defaults_and_round_trip():
    cfg = get_scenario("rig_ripple_planet_encoder")
    assert cfg.encoder == EncoderConfig(shaft="input", pulses_per_rev=60)
    assert cfg.encoder.member == "sun"
    assert SynthConfig.from_dict(cfg.to_dict()).encoder == cfg.encoder


@pytest.mark.parametrize("kw, match", [
    ({"shaft": "planet"}, "encoder shaft must be one of"),
    ({"pulses_per_rev": 0}, "pulses_per_rev must be a positive integer, got 0"),
    ({"pulses_per_rev": 2.5}, "whole number"),
    ({"duty": 0.0}, r"duty must be in \(0, 1\), got 0.0"),
    ({"missing": 1.0}, r"missing must be in \[0, 1\), got 1.0"),
    ({"extra": -0.1}, "extra must be >= 0"),
    ({"glitch": 0.3}, r"glitch must be in \(0, 0.2\], got 0.3"),
    ({"name": " "}, "encoder name must be a non-empty string"),
])
def test_encoder_config_bad_input(kw, match):
    with pytest.raises(ValueError, match=match):
        EncoderConfig(**kw)


def test_an_encoder_on_a_held_shaft_or_clashing_name_is_refused():
    cfg = get_scenario("rig_ripple_planet_encoder")
    with pytest.raises(ValueError, match="the ring shaft does not turn"):
        cfg.with_(encoder=EncoderConfig(shaft="ring"))
    with pytest.raises(ValueError, match=r"duplicate channel name\(s\) \['tacho'\]"):
        cfg.with_(encoder=EncoderConfig(name="tacho"))
    with pytest.raises(TypeError, match="EncoderConfig"):
        cfg.with_(encoder=("sun", 60))


def test_encoder_edges_match_the_truth_to_a_tenth_of_a_sample():
    rec, truth = generate(_short(EncoderConfig(shaft="input", pulses_per_rev=60)), seed=3)
    spec = rec.channels[-1]
    assert (spec.kind, spec.shaft, spec.pulses_per_rev) == ("encoder", "input", 60)
    enc = truth.extra["encoder"]
    te = np.asarray(enc["rising_edges"])
    got = edge_times(rec.data[:, -1], rec.fs, t0=rec.t0)
    assert got.size == te.size == 364
    # the integrating front end puts each edge's sub-sample position in its edge sample;
    # linear interpolation at the half level is then off by c + 1/(2c) - 3/2 samples (c the
    # covered share of the edge's cell), at most 0.086 at c = 1/sqrt(2)
    assert np.max(np.abs(got - te)) * rec.fs < 0.09


def test_missing_pulses_and_glitches_are_counted_against_the_truth():
    ec = EncoderConfig(shaft="input", pulses_per_rev=60, missing=0.02, extra=0.02)
    rec, truth = generate(_short(ec), seed=4)
    enc = truth.extra["encoder"]
    n_true = len(enc["rising_edges"])
    c = clean_edges(edge_times(rec.data[:, -1], rec.fs, t0=rec.t0))
    assert len(enc["missing"]) > 0 and len(enc["glitch_edges"]) > 0     # the draw holds both
    assert c.n_missing == len(enc["missing"])
    assert c.n_extra == len(enc["glitch_edges"])
    # every kept edge is a true one, with its true pulse count
    kept = np.setdiff1d(np.arange(n_true), enc["missing"])
    assert np.array_equal(c.count, kept - kept[0])
    assert np.max(np.abs(c.times - np.asarray(enc["rising_edges"])[kept])) * rec.fs < 0.09


def test_the_encoder_scenario_meets_the_phasing_target_through_missing_pulses_and_glitches():
    # rig_ripple_planet: 1 % common ripple at the planets' spin rate, which the gauges and the
    # once-per-turn tacho take for equal planet terms (seed 11 without the encoder: sun /
    # ring 29 / 18 x the floor). The 60-pulse input-shaft encoder, here with 1 % of its
    # pulses missing and 1 % glitches, brings both to the target (seed 11: sun 0.94, ring
    # 1.02 x the floor, as with a clean encoder) with RMS(err / sigma) ~1
    cfg = get_scenario("rig_ripple_planet_encoder")
    cfg = cfg.with_(encoder=EncoderConfig(shaft="input", pulses_per_rev=60, missing=0.01,
                                          extra=0.01))
    scene = Scene(path=None, name="encoder", results=["phasing"],
                  input={"synthetic": cfg.name, "minutes": 2.0, "seed": 11, "config": cfg})
    ctx = run_scene(scene)
    assert not [m for m in ctx.messages if "not reliable" in m], ctx.messages
    ph, truth = ctx.phasing, ctx.load.truth
    assert set(ph.tables) == {"sun", "ring"}
    for gear, tab in ph.tables.items():
        lab = ph.labels[gear]
        tc = truth_comparison(tab, truth, lab.channel, times=lab.times, planets=lab.planet)
        target = max(TARGET_ABS, TARGET_FLOOR_RATIO * tc["floor_rms"])
        assert tc["n"] >= 20 and tc["rms"] <= target, (gear, tc["rms"], tc["floor_rms"])
        # 84 sun / 24 ring passes: RMS(z) of honest sigmas lies within 0.6-1.5 there
        assert 0.6 <= tc["z_rms"] <= 1.5, (gear, tc["z_rms"])
    assert "planet ripple" in ph.model.terms
    enc = truth.extra["encoder"]
    assert len(enc["missing"]) > 5 and len(enc["glitch_edges"]) > 5      # the draw holds both
    note = next(n for n in ph.notes if n.startswith("encoder encoder (input shaft, 60 pulses"))
    assert (f"{len(enc['glitch_edges'])} extra dropped, {len(enc['missing'])} missing counted"
            in note), note
    # the counts reach the run's messages (report, summary) and the stage's estimate
    assert [m for m in ctx.messages if "DataQualityWarning: encoder encoder: "
            f"{len(enc['glitch_edges'])} extra edge(s) dropped" in m], ctx.messages
    counts = note.rsplit(": ", 1)[-1]                 # "2167 edges, 19 extra dropped, ..."
    assert f"encoder encoder: {counts}" in ctx.error_estimates["phasing"]


@pytest.mark.parametrize("suffix", [".h5", ".mcap", ".csv", ".tdms"])
def test_encoder_channel_spec_survives_every_format(tmp_path, suffix):
    rec, _ = generate(_short(EncoderConfig(shaft="carrier", pulses_per_rev=36), seconds=1.0),
                      seed=1)
    path = tmp_path / f"rec{suffix}"
    if suffix == ".tdms":
        write_tdms(rec, path)               # the generator's NI TDMS export
    else:
        mio.write(rec, path)
    back = mio.read(path)
    spec = back.channels[-1]
    assert (spec.kind, spec.shaft, spec.pulses_per_rev) == ("encoder", "carrier", 36)
