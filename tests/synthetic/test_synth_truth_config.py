"""GroundTruth sidecar round trip and SynthConfig validation."""

import json

import numpy as np
import pytest

from meshphase.models.gearset import Gearset, Speeds
from meshphase.models.mesh_phasing import ShaftHoleErrors
from meshphase.synthetic import (Artefacts, GaugeConfig, GroundTruth, SynthConfig, TachoConfig, generate,
                                 get_scenario, list_scenarios, truth_path_for)
from meshphase.synthetic.config import TiltSource, errors_from_dict, errors_to_dict
from meshphase.synthetic.truth import TRUTH_FORMAT


# ----------------------------------------------------------------------------- truth

def test_truth_json_round_trip_is_exact(tmp_path):
    rec, truth = generate("rig_realistic", duration=13.0, seed=4)
    p = truth.write(tmp_path / "x.truth.json")
    back = GroundTruth.read(p)
    assert back == truth
    assert np.array_equal(back.events["sun"].time, truth.events["sun"].time)
    assert back.events["sun"].planet.dtype == np.int64
    assert back.gaps.shape == (0, 2)
    d = json.loads(p.read_text())
    assert d["format"] == TRUTH_FORMAT and d["seed"] == 4
    assert "middle of the tooth's contact" in d["engagement_definition"]
    with pytest.raises(FileExistsError):
        truth.write(p)
    truth.write(p, overwrite=True)


def test_truth_read_from_recording_path_and_bad_format(tmp_path):
    _, truth = generate("seed_rig", duration=2.0, seed=1)
    rec_path = tmp_path / "r.h5"
    truth.write(truth_path_for(rec_path))
    assert truth_path_for(rec_path).name == "r.h5.truth.json"
    assert GroundTruth.read(rec_path).seed == 1
    bad = tmp_path / "bad.truth.json"
    bad.write_text(json.dumps({"format": "other"}))
    with pytest.raises(ValueError, match="not a meshphase synthetic truth"):
        GroundTruth.read(bad)


def test_truth_gamma_table_and_empty_planet():
    _, truth = generate("table1_high_speed", duration=0.2, seed=1)
    p = truth.gamma_table("sun")
    assert set(np.unique(p.planet)) == {2, 3, 4}
    assert len(p.for_planet(7)) == 0
    with pytest.raises(ValueError, match="channels"):
        truth.gamma_table("nope")


# ----------------------------------------------------------------------------- config

@pytest.mark.parametrize("name", list_scenarios())
def test_config_dict_round_trip(name):
    cfg = get_scenario(name)
    d = json.loads(json.dumps(cfg.to_dict()))
    back = SynthConfig.from_dict(d)
    assert back.to_dict() == cfg.to_dict()


def test_errors_dict_round_trip():
    e = ShaftHoleErrors(e_sun=1e-4, kappa_sun=0.1, e_ring=2e-4, kappa_ring=0.2,
                        e_planet=[1e-4, 2e-4, 3e-4], kappa_planet=[0.1, 0.2, 0.3])
    back = errors_from_dict(errors_to_dict(e))
    assert np.array_equal(back.e_planet, e.e_planet) and float(back.kappa_ring) == 0.2
    assert errors_to_dict(None) is None and errors_from_dict(None) is None
    with pytest.raises(TypeError):
        errors_to_dict("big")
    with pytest.raises(ValueError, match="unknown errors type"):
        errors_from_dict({"type": "Other"})


def _base(**kw):
    g = Gearset.equally_spaced(25, 87, 31, 4, 0.1125, direction="cw", face_width=0.04)
    sp = Speeds.kinematic(g, 10.0, 1.0)
    d = dict(name="t", gearset=g, speeds=sp, fs=5120.0, duration=1.0,
             gauges=(GaugeConfig("sun", "sun"),))
    d.update(kw)
    return SynthConfig(**d)


@pytest.mark.parametrize("kw, exc, match", [
    (dict(fs=0.0), ValueError, "fs"),
    (dict(duration=-1.0), ValueError, "duration"),
    (dict(gauges=("sun",)), TypeError, "GaugeConfig"),
    (dict(gauges=()), ValueError, "at least one"),
    (dict(gauges=(GaugeConfig("a", "sun"), GaugeConfig("a", "ring"))), ValueError, "duplicate"),
    (dict(tacho=TachoConfig("sun")), ValueError, "duplicate"),
    (dict(load_sharing=(1.2, 1.0, 1.0, 1.0)), ValueError, "average 1"),
    (dict(load_sharing=(1.0, 1.0)), ValueError, "one value per planet"),
    (dict(centroid_ring=0.03), ValueError, "b/2"),
    (dict(errors="big"), TypeError, "errors"),
    (dict(errors=ShaftHoleErrors(e_sun=[1e-4, 2e-4])), ValueError, "one realisation"),
    (dict(dtype="int16"), ValueError, "dtype"),
    (dict(speed="fast"), TypeError, "SpeedProfile"),
    (dict(artefacts={}), TypeError, "Artefacts"),
    (dict(tilt=TiltSource(), centroid_sun=0.001), ValueError, "not both"),
    (dict(gauges=(GaugeConfig("s", "sun", tooth=25),)), ValueError, "does not exist"),
    (dict(artefacts=Artefacts(gain_error={"ring": 0.1})), ValueError, "unknown gauge"),
])
def test_config_bad_input(kw, exc, match):
    with pytest.raises(exc, match=match):
        _base(**kw)


def test_config_direction_must_match_speeds():
    g = Gearset.equally_spaced(25, 87, 31, 4, 0.1125, direction="ccw")
    with pytest.raises(ValueError, match="direction"):
        SynthConfig("t", g, Speeds.kinematic(g, 10.0, 1.0), 5120.0, 1.0, (GaugeConfig("s", "sun"),))
    with pytest.raises(ValueError, match="w_sc"):
        SynthConfig("t", g, Speeds(1.0, 1.0, 1.0, 1.0), 5120.0, 1.0, (GaugeConfig("s", "sun"),))


def test_config_face_width_needed():
    g = Gearset.equally_spaced(25, 87, 31, 4, 0.1125, direction="cw")
    with pytest.raises(ValueError, match="face_width"):
        SynthConfig("t", g, Speeds.kinematic(g, 10.0, 1.0), 5120.0, 1.0,
                    (GaugeConfig("fw", "ring", face_position=0.0),))


@pytest.mark.parametrize("kw, exc", [
    (dict(name=""), ValueError), (dict(gear="planet"), ValueError), (dict(tooth=-1), ValueError),
    (dict(amplitude=0.0), ValueError), (dict(contact_ratio=0.5), ValueError),
    (dict(side_lobe=1.0), ValueError), (dict(skew=1.0), ValueError),
    (dict(face_position="mid"), TypeError), (dict(tooth="one"), TypeError),
    (dict(tooth=1.5), ValueError),
])
def test_gauge_config_bad_input(kw, exc):
    d = dict(name="g", gear="sun")
    d.update(kw)
    with pytest.raises(exc):
        GaugeConfig(**d)


def test_gauge_config_defaults():
    assert GaugeConfig("s", "sun").skew == 0.2 and GaugeConfig("r", "ring").skew == -0.2
    assert GaugeConfig("f", "ring", face_position=0.01).kind == "facewidth"


@pytest.mark.parametrize("kw, exc", [
    (dict(snr_db="high"), TypeError), (dict(pink_fraction=2.0), ValueError),
    (dict(adc_bits=16), ValueError), (dict(adc_bits=64, adc_range=1.0), ValueError),
    (dict(clip_level=-1.0), ValueError), (dict(gap_rate=-1.0), ValueError),
    (dict(gain_error=-1.0), ValueError), (dict(gain_error={"a": -2.0}), ValueError),
    (dict(hum_frequency=0.0), ValueError),
])
def test_artefacts_bad_input(kw, exc):
    with pytest.raises(exc):
        Artefacts(**kw)


def test_artefacts_off_by_default():
    assert not Artefacts().any
    assert Artefacts(snr_db=20.0).any and Artefacts(gap_rate=0.1).any


def test_tacho_and_tilt_bad_input():
    with pytest.raises(ValueError, match="width"):
        TachoConfig(width=0.6)
    with pytest.raises(ValueError, match="level"):
        TachoConfig(level=0.0)
    with pytest.raises(ValueError, match="k_tilt"):
        TiltSource(k_tilt=0.0)
    with pytest.raises(ValueError):
        TiltSource(case="3")


def test_tilt_source_gives_seed001_signs():
    """Seed 001 Table 10 signs: Z_S < 0 < Z_R (the tilt solve; magnitudes are its business)."""
    _, truth = generate("facewidth_tilt", duration=2.0, seed=1)
    assert np.all(truth.centroid_sun < 0) and np.all(truth.centroid_ring > 0)
    assert truth.extra["tilt_solution"]["converged"]
