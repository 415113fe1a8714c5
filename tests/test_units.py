"""Gauge units checked when a recording is loaded (meshphase.io.units): each spelling's factor to
m/m, bridge ratios and volts with a bridge entry, an unknown unit named with its channel, a
missing one warned once, the scene's units winning over the file's, and one recording in
microstrain through every reader (HDF5 native and foreign, MCAP, CSV with and without a units
row, TDMS) giving the load sharing of the same recording in m/m."""

from __future__ import annotations

import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from seed_rig_toml import SEED_RIG_GEARSET as G

import meshphase.io
from meshphase.io.bridge import BridgeConfig, ratio_from_strain
from meshphase.errors import FormatWarning
from meshphase.recording import ChannelSpec, Recording
from meshphase.run.scene import parse_scene
from meshphase.run.stages import run_scene
from meshphase.io.units import UnitError, gauge_unit_gains, parse_unit


# ----------------------------------------------------------------------------- parse_unit
@pytest.mark.parametrize("text, what, factor", [
    ("m/m", "strain", 1.0), ("Strain", "strain", 1.0), ("strain", "strain", 1.0),
    ("µε", "strain", 1e-6), ("με", "strain", 1e-6), ("ue", "strain", 1e-6),
    ("uE", "strain", 1e-6), ("microstrain", "strain", 1e-6), ("µm/m", "strain", 1e-6),
    ("um/m", "strain", 1e-6), (" µm / m ", "strain", 1e-6), ("mm/m", "strain", 1e-3),
    ("%", "strain", 1e-2), ("percent", "strain", 1e-2),
    # outside the table: pint
    ("micrometer / meter", "strain", 1e-6), ("millistrain", "strain", 1e-3), ("ppm", "strain", 1e-6),
    ("mV/V", "ratio", 1e-3), ("V/V", "ratio", 1.0), ("µV/V", "ratio", 1e-6),
    ("millivolt / volt", "ratio", 1e-3),
    ("V", "volt", 1.0), ("mV", "volt", 1e-3), ("kV", "volt", 1e3),
])
def test_each_spelling_has_its_factor(text, what, factor):
    got = parse_unit(text)
    assert got[0] == what
    assert got[1] == pytest.approx(factor, rel=1e-12)     # exact decimal prefixes


@pytest.mark.parametrize("text", ["Pa", "raw", "count", "rad", "s", "N", "no such unit", "m/m/2"])
def test_a_unit_that_is_not_strain_nor_volts_is_none(text):
    assert parse_unit(text) is None


def test_parse_unit_empty_and_bad_input():
    assert parse_unit("") == ("", 1.0)
    assert parse_unit("   ") == ("", 1.0)
    with pytest.raises(TypeError, match="unit must be a string"):
        parse_unit(None)
    with pytest.raises(TypeError, match="unit must be a string"):
        parse_unit(1e-6)


def test_the_table_keeps_pint_out_of_the_common_spellings():
    # meshphase info / convert start-up: the common spellings never import pint
    code = ("import sys; from meshphase.io.units import parse_unit; "
            "[parse_unit(u) for u in ('m/m', 'µε', 'ue', 'mm/m', '%', 'mV/V', 'V', 'Strain', '')]; "
            "print('pint' in sys.modules)")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "False"


# ----------------------------------------------------------------------------- gauge_unit_gains
def _specs(*units, kinds=("sun", "ring", "tacho")):
    return [ChannelSpec(f"c{i}", kind=k, units=u) for i, (k, u) in enumerate(zip(kinds, units))]


def test_gauge_gains_convert_gauges_and_keep_other_channels():
    specs, gains, conv = gauge_unit_gains(_specs("µε", "mm/m", "V"))
    assert [s.units for s in specs] == ["m/m", "m/m", "V"]       # the tacho keeps its volts
    assert gains == [(0, pytest.approx(1e-6)), (1, pytest.approx(1e-3))]
    assert conv["c0"] == {"units": "µε", "factor": pytest.approx(1e-6), "to": "m/m"}
    assert "c2" not in conv


def test_gauge_gains_empty_and_bad_input():
    assert gauge_unit_gains([]) == ([], [], {})
    specs, gains, conv = gauge_unit_gains(_specs("m/m", "m/m", "V"))
    assert gains == [] and conv == {}
    with pytest.raises(TypeError, match="ChannelSpecs"):
        gauge_unit_gains(["sun"])


@pytest.mark.parametrize("unit", ["Pa", "raw", "counts"])
def test_an_unknown_gauge_unit_names_the_channel_and_the_unit(unit):
    with pytest.raises(UnitError) as exc:
        gauge_unit_gains(_specs("m/m", unit, "V"), source="rig.tdms")
    msg = str(exc.value)
    assert "rig.tdms" in msg and "'c1'" in msg and repr(unit) in msg and 'units = "µm/m"' in msg


@pytest.mark.parametrize("unit, what", [("mV/V", "output ratio"), ("V", "voltage")])
def test_volts_on_a_gauge_without_a_bridge_ask_for_it(unit, what):
    with pytest.raises(UnitError, match=f"'c0' is in '{unit}', a bridge's {what}.*bridge, gauge_factor"):
        gauge_unit_gains(_specs(unit, "m/m", "V"))


def test_a_missing_unit_is_m_per_m_with_one_warning_naming_the_channels():
    with pytest.warns(FormatWarning) as rec:
        specs, gains, conv = gauge_unit_gains(_specs("", " ", "V"), source="x.csv")
    assert len(rec) == 1
    msg = str(rec[0].message)
    assert "x.csv" in msg and "'c0'" in msg and "'c1'" in msg and "m/m" in msg
    assert gains == [] and [s.units for s in specs] == ["m/m", "m/m", "V"]
    assert conv == {}          # nothing to convert: taken as m/m, said by the warning


def test_a_bridge_ratio_becomes_volts_for_the_bridge():
    cfg = BridgeConfig("full_I", 2.0, 5.0)
    specs = [ChannelSpec("g", kind="sun", units="m/m")]      # the mapped spec says m/m
    out, gains, conv = gauge_unit_gains(specs, {"g": cfg}, raw_units={"g": "mV/V"})
    # mV/V x 1e-3 -> V/V, x the 5 V excitation -> V: the bridge divides by it again
    assert gains == [(0, pytest.approx(5e-3, rel=1e-12))] and conv["g"]["to"] == "V"
    out, gains, _ = gauge_unit_gains(specs, {"g": cfg}, raw_units={"g": "mV"})
    assert gains == [(0, pytest.approx(1e-3, rel=1e-12))]
    with pytest.raises(UnitError, match="bridge channel 'g' has the unit 'µε'"):
        gauge_unit_gains(specs, {"g": cfg}, raw_units={"g": "µε"})


# ----------------------------------------------------------------------------- runs
@pytest.fixture(scope="module")
def seed_rec():
    from meshphase.synthetic import generate

    rec, _ = generate("seed_rig", duration=30.0, seed=0)   # 30 s: every planet's ring pass
    return rec


def _with_units(rec: Recording, units: str, scale: float) -> Recording:
    """The seed recording with its gauges (columns 0, 1) in ``units``, samples x ``scale``."""
    d = np.array(rec.data, dtype=np.float64)
    d[:, :2] *= scale
    specs = [ChannelSpec("SG01_sun", units=units), ChannelSpec("SG02_ring", units=units),
             ChannelSpec("OPR", kind="tacho", units="V")]
    return Recording(d, rec.fs, specs, meta=rec.meta)


def _run(path: Path, tmp_path: Path, extra: str = "", bridge: str = "", tail: str = ""):
    gauges = "".join(f'[[channels]]\nname = "SG0{i}_{g}"\nkind = "{g}"\n{extra}{bridge}'
                     for i, g in ((1, "sun"), (2, "ring")))
    text = ('results = ["phasing", "load_sharing"]\n' + G + gauges
            + '[[channels]]\nname = "OPR"\nkind = "tacho"\n' + f'[input]\nrecording = "{path}"\n'
            + tail)
    return run_scene(parse_scene(text, tmp_path / "s.toml"))


def _amplitudes(ctx) -> np.ndarray:
    assert ctx.failed == {}, ctx.failed
    a = np.array([r["mean_amplitude"] for r in ctx.load_sharing.sharing.to_rows()])
    assert a.size == 4 and np.all(np.isfinite(a)), a
    return a


def _write_tdms(rec: Recording, path: Path) -> Path:
    from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

    with TdmsWriter(str(path)) as w:
        objs = [RootObject({}), GroupObject("rig", {})]
        for j, c in enumerate(rec.channels):
            objs.append(ChannelObject("rig", c.name, np.ascontiguousarray(rec.data[:, j]),
                                      {"unit_string": c.units, "wf_increment": 1.0 / rec.fs,
                                       "wf_start_offset": 0.0}))
        w.write_segment(objs)
    return path


def _write_csv_units_row(rec: Recording, path: Path) -> Path:
    """A DIAdem-style CSV: names on the first line, units on the second."""
    t = np.arange(rec.n_samples) / rec.fs
    with open(path, "w", encoding="utf-8") as fh:
        fh.write("time," + ",".join(rec.names) + "\n")
        fh.write("s," + ",".join(c.units for c in rec.channels) + "\n")
        np.savetxt(fh, np.column_stack([t, rec.data]), delimiter=",", fmt="%.17g")
    return path


@pytest.fixture(scope="module")
def ref_amplitudes(seed_rec, tmp_path_factory):
    """Mean pulse amplitude per planet [m/m] of the seed recording stored in m/m."""
    d = tmp_path_factory.mktemp("ref")
    return _amplitudes(_run(meshphase.io.write(_with_units(seed_rec, "m/m", 1.0), d / "ref.h5"), d))


def _write_foreign_hdf5(rec: Recording, path: Path) -> Path:
    """An h5py script's file: one 1-D dataset per channel with a ``units`` attribute and the
    rate as a root ``fs`` attribute."""
    import h5py

    with h5py.File(path, "w") as f:
        f.attrs["fs"] = rec.fs
        for j, c in enumerate(rec.channels):
            f.create_dataset(c.name, data=rec.data[:, j]).attrs["units"] = c.units
    return path


WRITERS = {"hdf5": lambda rec, p: meshphase.io.write(rec, p.with_suffix(".h5")),
           "mcap": lambda rec, p: meshphase.io.write(rec, p.with_suffix(".mcap")),
           "csv": lambda rec, p: meshphase.io.write(rec, p.with_suffix(".csv")),
           "csv units row": lambda rec, p: _write_csv_units_row(rec, p.with_suffix(".csv")),
           "tdms": lambda rec, p: _write_tdms(rec, p.with_suffix(".tdms")),
           "foreign hdf5": lambda rec, p: _write_foreign_hdf5(rec, p.with_suffix(".h5"))}


@pytest.mark.parametrize("fmt", list(WRITERS))
def test_one_recording_in_microstrain_through_every_reader(fmt, seed_rec, ref_amplitudes, tmp_path):
    path = WRITERS[fmt](_with_units(seed_rec, "µε", 1e6), tmp_path / "ue")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FormatWarning)    # the foreign files' own notes
        ctx = _run(path, tmp_path)
    # the same samples x 1e6 x 1e-6 (two roundings): the m/m file's amplitudes to float
    # rounding, not 1e6 times them
    np.testing.assert_allclose(_amplitudes(ctx), ref_amplitudes, rtol=1e-9)
    step = next(h for h in ctx.load.recording.history if h["step"] == "units_to_si")
    assert step["channels"]["SG01_sun"] == {"units": "µε", "factor": 1e-6, "to": "m/m"}
    assert ctx.load.recording.spec("SG01_sun").units == "m/m"
    assert ctx.load.recording.spec("OPR").units == "V"              # the tacho as it was


def test_a_foreign_mcap_mapped_in_microstrain(seed_rec, ref_amplitudes, tmp_path):
    import json

    from mcap.writer import Writer

    ue = _with_units(seed_rec, "µε", 1e6)
    path, per = tmp_path / "daq.mcap", 512
    with open(path, "wb") as fh:                 # one JSON topic per channel, 512 samples a message
        w = Writer(fh)
        w.start(profile="", library="a DAQ logger")
        sid = w.register_schema("daq.Block", "jsonschema", b'{"type": "object"}')
        cids = [w.register_channel(f"/daq/{n}", "json", sid) for n in ue.names]
        for a in range(0, ue.n_samples, per):
            t = 1_750_000_000_000_000_000 + (a * 10**9) // int(ue.fs)
            for j, cid in enumerate(cids):
                w.add_message(cid, t, json.dumps({"values": ue.data[a:a + per, j].tolist()}).encode(), t)
        w.finish()
    mapping = "[input.mcap]\nfs_Hz = 5120.0\n" + "".join(
        f'[[input.mcap.channels]]\nname = "{c.name}"\ntopic = "/daq/{c.name}"\nfield = "values"\n'
        f'units = "{c.units}"\n' for c in ue.channels)
    ctx = _run(path, tmp_path, tail=mapping)
    # JSON keeps every digit (repr round trip): the m/m amplitudes to float rounding
    np.testing.assert_allclose(_amplitudes(ctx), ref_amplitudes, rtol=1e-9)


def test_the_scene_units_win_over_the_file(seed_rec, ref_amplitudes, tmp_path):
    ref = ref_amplitudes
    # samples in microstrain, the file saying m/m: the scene's units put it right
    wrong = meshphase.io.write(_with_units(seed_rec, "m/m", 1e6), tmp_path / "wrong.h5")
    np.testing.assert_allclose(_amplitudes(_run(wrong, tmp_path, 'units = "µε"\n')), ref, rtol=1e-9)
    assert np.all(_amplitudes(_run(wrong, tmp_path)) > 1e5 * ref)    # without: the file's word


def test_an_unknown_unit_fails_the_load_naming_channel_and_unit(seed_rec, tmp_path):
    path = meshphase.io.write(_with_units(seed_rec, "kPa", 1.0), tmp_path / "kpa.h5")
    ctx = _run(path, tmp_path)
    assert "SG01_sun" in str(ctx.failed["load"]) and "'kPa'" in str(ctx.failed["load"])
    assert ctx.phasing is None


def test_a_missing_unit_is_taken_as_m_per_m_with_one_message(seed_rec, ref_amplitudes, tmp_path):
    ref = ref_amplitudes
    ctx = _run(meshphase.io.write(_with_units(seed_rec, "", 1.0), tmp_path / "none.h5"), tmp_path)
    np.testing.assert_allclose(_amplitudes(ctx), ref, rtol=1e-12)
    said = [m for m in ctx.messages if "carry no unit" in m]
    assert len(said) == 1 and "'SG01_sun'" in said[0] and "'SG02_ring'" in said[0]


def test_a_bridge_ratio_in_mv_per_v_with_a_bridge_entry(seed_rec, ref_amplitudes, tmp_path):
    ref = ref_amplitudes
    cfg = BridgeConfig("full_I", 2.0, 5.0)
    rec = _with_units(seed_rec, "mV/V", 1.0)
    d = rec.data.copy()
    d[:, :2] = ratio_from_strain(seed_rec.data[:, :2], cfg) * 1e3       # V/V -> mV/V
    path = meshphase.io.write(Recording(d, rec.fs, rec.channels, meta=rec.meta), tmp_path / "mvv.h5")
    ctx = _run(path, tmp_path, bridge='bridge = "full_I"\ngauge_factor = 2.0\nexcitation_V = 5.0\n')
    # full_I is linear (strain = -V_r / GF): the round trip is exact to rounding
    np.testing.assert_allclose(_amplitudes(ctx), ref, rtol=1e-9)
    assert ctx.load.recording.spec("SG01_sun").units == "m/m"
    # without the bridge entry the ratio is refused, naming the channel
    assert "SG01_sun" in str(_run(path, tmp_path).failed["load"])


def test_scene_refuses_an_unknown_gauge_unit_at_parse_time(tmp_path):
    # the scene's own units key is checked as the scene is read (line and key named), not
    # when the recording is loaded; a non-gauge channel keeps whatever unit it states
    from meshphase.run.scene import SceneError, parse_scene

    base = ('results = ["ideal_phasing"]\n[gearset]\nz_sun = 25\nz_ring = 87\nz_planet = 29\n'
            'n_planets = 4\ncarrier_radius_mm = 112.5\nprofile_shift = true\n')
    with pytest.raises(SceneError, match=r"channels.*units.*unknown unit 'furlong'"):
        parse_scene(base + '[[channels]]\nname = "sun"\nkind = "sun"\nunits = "furlong"\n',
                    tmp_path / "s.toml")
    parse_scene(base + '[[channels]]\nname = "speed"\nkind = "other"\nunits = "rpm"\n',
                tmp_path / "s.toml")
    parse_scene(base + '[[channels]]\nname = "sun"\nkind = "sun"\nunits = "µε"\n', tmp_path / "s.toml")
