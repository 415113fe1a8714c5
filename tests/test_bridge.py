"""Strain from bridge volts (issue 12 item 5): NI's Wheatstone-bridge strain equations
(meshphase.io.bridge's docstring names the sources) against values worked out by hand, the
volts <-> strain round trip and the small-strain linear limit with hypothesis, the scene's
bridge keys and their SceneErrors, and the conversion in a run (history, null window)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from seed_rig_toml import SEED_RIG_GEARSET as G

import meshphase.io
from meshphase.io.bridge import (BRIDGE_TYPES, BridgeConfig, bridge_history, bridge_recording,
                                 convert_block, initial_volts, null_ratio, ratio_from_strain,
                                 strain_from_ratio, strain_from_volts, strain_spec,
                                 volts_from_strain, window_means)
from meshphase.io.sources import BridgeSource
from meshphase.recording import ChannelSpec, Recording
from meshphase.errors import SceneWarning
from meshphase.run.scene import SceneError, load_scene, parse_scene
from meshphase.run.stream import MemorySource

NU = {"half_I": 0.3, "full_II": 0.3, "full_III": 0.3}


def _cfg(bridge, gf=2.0, ex=5.0, lead=0.0, rg=None, **kw) -> BridgeConfig:
    return BridgeConfig(bridge, gf, ex, poisson=NU.get(bridge), lead_resistance=lead,
                        gauge_resistance=rg, **kw)


# =========================================================================== hand-computed
# One reading for every configuration: GF = 2.0, V_ex = 5 V, V_out = -2.5 mV, V_init = 0,
# so V_r = (V_out - V_init) / V_ex = -0.0025 / 5 = -5e-4 V/V (NI-DAQ Strain_Convert: V_r =
# (strainVolts - V_init) / V_ex). Poisson's ratio 0.3 where used. The equations: NI,
# "Measuring Strain with Strain Gages"; NI SCC-SG Series User Guide, "Strain Equations".
HAND = {
    # -4 V_r / (GF (1 + 2 V_r)) = 2e-3 / (2 x (1 - 1e-3)) = 2e-3 / 1.998
    "quarter_I": 2e-3 / 1.998,                      # 1.001001e-3
    "quarter_II": 2e-3 / 1.998,
    # -4 V_r / (GF ((1 + nu) - 2 V_r (nu - 1))) = 2e-3 / (2 x (1.3 - 2 x -5e-4 x -0.7))
    #   = 2e-3 / (2 x (1.3 - 7e-4)) = 2e-3 / 2.5986
    "half_I": 2e-3 / 2.5986,                        # 7.696452e-4
    # -2 V_r / GF = 1e-3 / 2
    "half_II": 5e-4,
    # -V_r / GF = 5e-4 / 2
    "full_I": 2.5e-4,
    # -2 V_r / (GF (nu + 1)) = 1e-3 / (2 x 1.3) = 1e-3 / 2.6
    "full_II": 1e-3 / 2.6,                          # 3.846154e-4
    # -2 V_r / (GF ((nu + 1) - V_r (nu - 1))) = 1e-3 / (2 x (1.3 - 3.5e-4)) = 1e-3 / 2.5993
    "full_III": 1e-3 / 2.5993,                      # 3.847189e-4
}


@pytest.mark.parametrize("bridge", list(BRIDGE_TYPES))
def test_hand_computed_strain(bridge):
    cfg = _cfg(bridge)
    assert strain_from_volts(-2.5e-3, cfg) == pytest.approx(HAND[bridge], rel=1e-12)
    assert strain_from_ratio(-5e-4, cfg) == pytest.approx(HAND[bridge], rel=1e-12)
    # and back: the volts that strain gives
    assert volts_from_strain(HAND[bridge], cfg) == pytest.approx(-2.5e-3, rel=1e-12)


def test_hand_computed_lead_resistance_and_offset():
    # quarter I with R_L = 1 ohm, R_g = 350 ohm: x (1 + 1/350) = x 351/350
    cfg = _cfg("quarter_I", lead=1.0, rg=350.0)
    assert cfg.lead_factor == pytest.approx(351 / 350)
    assert strain_from_volts(-2.5e-3, cfg) == pytest.approx(2e-3 / 1.998 * 351 / 350, rel=1e-12)
    # an unstrained output of +1 mV: V_r = (-2.5e-3 - 1e-3) / 5 = -7e-4
    # -4 x -7e-4 / (2 x (1 - 1.4e-3)) = 2.8e-3 / 1.9972
    assert strain_from_volts(-2.5e-3, _cfg("quarter_I"), 1e-3) == pytest.approx(2.8e-3 / 1.9972, rel=1e-12)
    # the plain names are the bending forms
    assert _cfg("quarter").bridge == "quarter_I" and _cfg("half").bridge == "half_II"
    assert _cfg("full").bridge == "full_I"


# =========================================================================== properties
_GF = st.floats(0.5, 5.0)
_EX = st.floats(0.5, 10.0)
_NU = st.floats(0.0, 0.49)
_STRAIN = st.floats(-5e-3, 5e-3)


def _any_cfg(bridge, gf, ex, nu, lead, rg):
    uses_nu, has_lead = BRIDGE_TYPES[bridge]
    return BridgeConfig(bridge, gf, ex, poisson=nu if uses_nu else None,
                        lead_resistance=lead if has_lead else 0.0,
                        gauge_resistance=rg if has_lead else None)


@settings(max_examples=200, deadline=None)
@given(st.sampled_from(list(BRIDGE_TYPES)), _GF, _EX, _NU, st.floats(0.0, 10.0),
       st.floats(100.0, 1000.0), st.lists(_STRAIN, min_size=1, max_size=20),
       st.floats(-0.01, 0.01))
def test_round_trip_volts_strain(bridge, gf, ex, nu, lead, rg, strain, v_init):
    cfg = _any_cfg(bridge, gf, ex, nu, lead, rg)
    e = np.array(strain)
    back = strain_from_volts(volts_from_strain(e, cfg, v_init), cfg, v_init)
    np.testing.assert_allclose(back, e, rtol=1e-9, atol=1e-15)


#: sensitivity dV_r/d(strain) at zero strain, over GF / (1 + R_L/R_g) (the equations' slope)
_SLOPE = {"quarter_I": lambda nu: -0.25, "quarter_II": lambda nu: -0.25,
          "half_I": lambda nu: -(1 + nu) / 4, "half_II": lambda nu: -0.5,
          "full_I": lambda nu: -1.0, "full_II": lambda nu: -(1 + nu) / 2,
          "full_III": lambda nu: -(1 + nu) / 2}


@settings(max_examples=200, deadline=None)
@given(st.sampled_from(list(BRIDGE_TYPES)), _GF, _NU, st.floats(0.0, 10.0),
       st.floats(100.0, 1000.0), st.floats(-1e-6, 1e-6))
def test_small_strain_linear_limit(bridge, gf, nu, lead, rg, strain):
    # for |strain| <= 1 microstrain every bridge is linear: V_r = slope GF strain / (1 + R_L/R_g)
    # within a relative GF |strain| (the next term of the series)
    cfg = _any_cfg(bridge, gf, 5.0, nu, lead, rg)
    linear = _SLOPE[bridge](cfg.poisson) * gf * strain / cfg.lead_factor
    assert float(ratio_from_strain(strain, cfg)) == pytest.approx(linear, rel=4 * gf * 1e-6, abs=1e-300)


# =========================================================================== config checks
@pytest.mark.parametrize("kw, match", [
    (dict(bridge="eighth"), "not a known configuration"),
    (dict(gauge_factor=0.0), "gauge factor is > 0"),
    (dict(gauge_factor=-2.0), "gauge factor is > 0"),
    (dict(excitation=0.0), "excitation is > 0"),
    (dict(bridge="half_I"), "needs Poisson's ratio"),
    (dict(poisson=0.3), "does not use Poisson's ratio"),
    (dict(bridge="full_II", poisson=0.7), "0 .. 0.5"),
    (dict(lead_resistance=-1.0), "negative"),
    (dict(lead_resistance=1.0), "gauge_ohm"),
    (dict(bridge="full_I", lead_resistance=1.0, gauge_resistance=350.0), "no lead-resistance term"),
    (dict(lead_resistance=1.0, gauge_resistance=0.0), "resistance is > 0"),
    (dict(null_window=(1.0, 0.5)), "stop after start"),
    (dict(null_window=(0.0,)), "stop after start"),
    (dict(gauge_factor=math.nan), "finite"),
])
def test_config_refuses_bad_values(kw, match):
    args = dict(bridge="quarter_I", gauge_factor=2.0, excitation=5.0)
    args.update(kw)
    with pytest.raises(ValueError, match=match):
        BridgeConfig(**args)


def test_array_functions_empty_and_bad_input():
    cfg = _cfg("quarter_I")
    for f in (strain_from_ratio, ratio_from_strain, strain_from_volts, volts_from_strain):
        out = f(np.array([]), cfg)
        assert out.shape == (0,) and out.dtype == np.float64
        with pytest.raises(TypeError, match="BridgeConfig"):
            f(np.zeros(3), {"bridge": "quarter_I"})
    assert np.isnan(strain_from_volts([np.nan], cfg)[0])
    with pytest.raises(ValueError):
        strain_from_volts([1.0], cfg, v_init=math.inf)
    np.testing.assert_array_equal(strain_from_ratio(np.zeros((2, 3)), cfg), np.zeros((2, 3)))


def test_null_ratio_and_window_means():
    assert null_ratio([1.0, 3.0, np.nan], 4.0) == pytest.approx(0.5)
    with pytest.raises(ValueError, match="no finite sample"):
        null_ratio([], 5.0)
    with pytest.raises(ValueError, match="excitation"):
        null_ratio([1.0], 0.0)
    data = np.column_stack([np.arange(10.0), np.ones(10)])
    blocks = [(0, data[:4]), (4, data[4:])]
    # 10 Hz from t0 = 1 s: window [1.2, 1.5) s is samples 2, 3, 4 -> mean 3
    assert window_means(iter(blocks), 1.0, 10.0, 10, {0: (1.2, 1.5)}) == {0: pytest.approx(3.0)}
    assert window_means(iter(blocks), 1.0, 10.0, 10, {}) == {}
    with pytest.raises(ValueError, match="not inside the recording"):
        window_means(iter(blocks), 1.0, 10.0, 10, {0: (0.0, 0.5)})
    with pytest.raises(ValueError, match="holds no sample"):
        window_means(iter(blocks), 1.0, 10.0, 10, {0: (1.21, 1.22)})


def test_block_helpers_empty_and_bad_input():
    cfg = _cfg("full_I")
    data = np.full((4, 2), -2.5e-3)
    out = convert_block(data, {1: (cfg, 0.0)})
    np.testing.assert_allclose(out[:, 1], 2.5e-4)
    np.testing.assert_array_equal(out[:, 0], data[:, 0])          # untouched, and a copy
    assert convert_block(np.empty((0, 2)), {1: (cfg, 0.0)}).shape == (0, 2)
    with pytest.raises(IndexError):
        convert_block(data, {5: (cfg, 0.0)})
    assert initial_volts(iter([(0, data)]), 0.0, 10.0, 4, {}) == {}
    assert initial_volts(iter([(0, data)]), 0.0, 10.0, 4, {1: cfg}) == {1: 0.0}
    nan = np.full((4, 1), np.nan)
    with pytest.raises(ValueError, match="no finite sample"):
        initial_volts(iter([(0, nan)]), 0.0, 10.0, 4, {0: _cfg("full_I", null_window=(0.0, 0.2))})
    assert bridge_history(["a"], {}, {}) == {}
    h = bridge_history(["a", "b"], {1: cfg}, {1: 1e-3})
    assert h["b"]["v_init_V"] == 1e-3 and h["b"]["initial_ratio_V_per_V"] == pytest.approx(2e-4)
    assert strain_spec(ChannelSpec("x", units="V")).units == "m/m"
    with pytest.raises(TypeError):
        strain_spec({"name": "x"})


def _volts_rec(n=1000, fs=100.0):
    t = np.arange(n) / fs
    strain = 1e-4 * np.sin(2 * np.pi * t) * (t >= 2.0)     # at rest for 2 s
    cfg = _cfg("quarter_I", null_window=(0.0, 2.0))
    volts = volts_from_strain(strain, cfg, v_init=1.5e-3)  # an unbalanced bridge
    rec = Recording(np.column_stack([volts, t]), fs, [ChannelSpec("g", units="V"),
                                                       ChannelSpec("other", units="s")])
    return rec, strain, cfg


def test_bridge_recording_nulls_and_records():
    rec, strain, cfg = _volts_rec()
    out = bridge_recording(rec, {"g": cfg})
    np.testing.assert_allclose(out.channel("g"), strain, atol=1e-12)
    np.testing.assert_array_equal(out.channel("other"), rec.channel("other"))
    assert out.spec("g").units == "m/m" and out.spec("other").units == "s"
    step = out.history[-1]
    assert step["step"] == "bridge_strain" and step["channels"]["g"]["v_init_V"] == pytest.approx(1.5e-3)
    assert step["channels"]["g"]["bridge"] == "quarter_I"
    assert bridge_recording(rec, {}) is rec
    with pytest.raises(TypeError):
        bridge_recording(rec.data, {"g": cfg})
    with pytest.raises(ValueError):
        bridge_recording(rec, {"missing": cfg})
    with pytest.raises(ValueError, match="not inside the recording"):
        bridge_recording(rec, {"g": _cfg("quarter_I", null_window=(5.0, 20.0))})


def test_bridge_source_streams_the_same_as_the_recording():
    rec, strain, cfg = _volts_rec()
    src = BridgeSource(MemorySource(rec), {"g": cfg})
    got = np.concatenate([d for _, d in src.blocks(128)])
    np.testing.assert_allclose(got[:, 0], bridge_recording(rec, {"g": cfg}).channel("g"), rtol=0, atol=0)
    assert src.header.spec("g").units == "m/m" and src.header.history[-1]["step"] == "bridge_strain"
    assert src.label == "recording"
    with pytest.raises(TypeError):
        BridgeSource(MemorySource(rec), {})
    with pytest.raises(TypeError):
        BridgeSource(MemorySource(rec), {"g": "quarter_I"})


# =========================================================================== scenes
B = ('[[channels]]\nname = "sun"\nkind = "sun"\nbridge = "quarter_I"\ngauge_factor = 2.0\n'
     'excitation_V = 5.0\n')


def _bad(extra: str, key: str, match: str, base: str = B):
    text = 'results = ["ideal_phasing"]\n' + G + base + extra
    with pytest.raises(SceneError, match=match) as info:
        parse_scene(text, "/x/s.toml")
    assert info.value.key == key, info.value


@pytest.mark.parametrize("extra, key, match", [
    ("poisson = 0.3\n", "channels.0.poisson", "does not use Poisson"),
    ("lead_ohm = 1.5\n", "channels.0.lead_ohm", "gauge_ohm"),
    ("lead_ohm = -1\n", "channels.0.lead_ohm", "minimum"),
    ("gauge_ohm = 0\n", "channels.0.gauge_ohm", "exclusiveMinimum|less than or equal"),
    ("null_window_s = [2.0, 1.0]\n", "channels.0.null_window_s", "stop after start"),
    ("null_window_s = [2.0]\n", "channels.0.null_window_s", "short|non-empty|items"),
])
def test_scene_bridge_keys_refused(extra, key, match):
    _bad(extra, key, match)


def test_scene_bridge_keys_refused_elsewhere():
    _bad("", "channels.0.gauge_factor", "0", base=B.replace("gauge_factor = 2.0", "gauge_factor = 0"))
    _bad("", "channels.0.excitation_V", "0", base=B.replace("excitation_V = 5.0", "excitation_V = -1"))
    _bad("", "channels.0.bridge", "is not one of", base=B.replace('"quarter_I"', '"eighth"'))
    _bad("", "channels.0.poisson", "needs Poisson", base=B.replace('"quarter_I"', '"half_I"'))
    _bad("", "channels.0.bridge", "needs gauge_factor", base=B.replace("gauge_factor = 2.0\n", ""))
    _bad("", "channels.0.gauge_factor", "give its bridge too",
         base='[[channels]]\nname = "sun"\ngauge_factor = 2.0\n')
    _bad("lead_ohm = 1\ngauge_ohm = 350\n", "channels.0.lead_ohm", "no lead-resistance term",
         base=B.replace('"quarter_I"', '"full_I"'))


def test_scene_bridge_parsed_in_si():
    text = ('results = ["ideal_phasing"]\n' + G + B
            + 'lead_ohm = 0.5\ngauge_ohm = 350\nnull_window_s = [0, 1.5]\n')
    c = parse_scene(text).channels[0]
    assert c["bridge"] == BridgeConfig("quarter_I", 2.0, 5.0, lead_resistance=0.5,
                                       gauge_resistance=350.0, null_window=(0.0, 1.5))
    assert not any(k in c for k in ("gauge_factor", "excitation_V", "lead_ohm", "null_window_s"))


@pytest.fixture(scope="module")
def volts_files(tmp_path_factory):
    """10 s of the seed rig in strain, and the same gauges as quarter-bridge volts (GF 2.1,
    5 V, leads 0.8 ohm on 350 ohm gauges, unbalanced by +1.2 mV), channels named as a rig
    names them."""
    from meshphase.synthetic import generate

    rec, _ = generate("seed_rig", duration=10.0, seed=0)
    d = tmp_path_factory.mktemp("bridge")
    cfg = BridgeConfig("quarter_I", 2.1, 5.0, lead_resistance=0.8, gauge_resistance=350.0)
    volts = rec.data.copy()
    for j in (0, 1):
        volts[:, j] = volts_from_strain(rec.data[:, j], cfg, 1.2e-3)
    names = [ChannelSpec("SG01_sun", units="V"), ChannelSpec("SG02_ring", units="V"),
             ChannelSpec("OPR", kind="tacho", units="V")]
    vpath = meshphase.io.write(Recording(volts, rec.fs, names, meta=rec.meta), d / "volts.h5")
    spath = meshphase.io.write(Recording(rec.data, rec.fs, [ChannelSpec("SG01_sun"),
                                                            ChannelSpec("SG02_ring"),
                                                            ChannelSpec("OPR", kind="tacho")],
                                         meta=rec.meta), d / "strain.h5")
    return Path(vpath), Path(spath), rec


def _scene(tmp_path, rec_path, bridge_keys: str, extra_input: str = "") -> Path:
    gauges = "".join(f'[[channels]]\nname = "SG0{i}_{g}"\nkind = "{g}"\n{bridge_keys}'
                     for i, g in ((1, "sun"), (2, "ring")))
    p = tmp_path / "s.toml"
    p.write_text('results = ["phasing"]\n' + G + gauges
                 + f'[input]\nrecording = "{rec_path}"\n{extra_input}', encoding="utf-8")
    return p


KEYS = ('bridge = "quarter_I"\ngauge_factor = 2.1\nexcitation_V = 5.0\nlead_ohm = 0.8\n'
        'gauge_ohm = 350\nnull_window_s = [0.0, 10.0]\n')


def test_run_on_bridge_volts_matches_the_run_on_strain(volts_files, tmp_path):
    from meshphase.run.outputs import summary_dict
    from meshphase.run.stages import run_scene

    vpath, spath, rec = volts_files
    (tmp_path / "v").mkdir()
    (tmp_path / "s").mkdir()
    v = run_scene(load_scene(_scene(tmp_path / "v", vpath, KEYS)))
    s = run_scene(load_scene(_scene(tmp_path / "s", spath, "")))
    assert v.failed == {} and v.load.recording.spec("SG01_sun").units == "m/m"
    step = next(h for h in v.load.recording.history if h["step"] == "bridge_strain")
    # V_init: the mean output over the null window (here the whole file)
    volts = meshphase.io.read(vpath).channel("SG01_sun")
    assert step["channels"]["SG01_sun"]["v_init_V"] == pytest.approx(volts.mean(), rel=1e-9)
    # the converted samples are the strain up to the constant the null window leaves
    blk = np.concatenate([d for _, d in v.load.stream.blocks(1 << 16)])
    diff = blk[:, 0] - rec.data[:, 0]
    assert np.ptp(diff) < 1e-3 * np.ptp(rec.data[:, 0])
    pv, ps = summary_dict(v)["phasing"], summary_dict(s)["phasing"]
    assert pv.keys() == ps.keys() and pv
    for gear in pv:
        for planet, x in ps[gear]["per_planet"].items():
            if x.get("mean") is not None:
                assert pv[gear]["per_planet"][planet]["mean"] == pytest.approx(x["mean"], abs=1e-4)


def test_null_window_outside_the_analysis_window_and_outside_the_recording(volts_files, tmp_path):
    from meshphase.run.stages import stage_load, RunContext

    vpath, _, _ = volts_files
    keys = KEYS.replace("[0.0, 10.0]", "[0.0, 2.0]")
    ctx = RunContext(load_scene(_scene(tmp_path, vpath, keys, "start_s = 5.0\n")))
    with pytest.warns(SceneWarning, match="OPR"):       # the tacho no entry maps
        load = stage_load(ctx)
    assert load.recording.t0 == pytest.approx(5.0)
    step = next(h for h in load.recording.history if h["step"] == "bridge_strain")
    assert step["channels"]["SG01_sun"]["null_window_s"] == [0.0, 2.0]
    p = _scene(tmp_path, vpath, KEYS.replace("[0.0, 10.0]", "[9.0, 12.0]"))
    with pytest.raises(SceneError) as info:
        load_scene(p)
    assert info.value.key == "channels.0.null_window_s" and "not inside the recording" in str(info.value)
