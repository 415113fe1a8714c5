"""Tests of the independent reference rig (tests/independent/rig.py).

Reference values: Parker & Lin (2004) ideal phasing as restated in meshphase.models.mesh_phasing;
closed forms derived in the test docstrings. Recordings are kept to seconds so the module runs
in a few seconds.
"""

from __future__ import annotations

import ast
import json
import math
import struct
import sys
from pathlib import Path

import numpy as np
import pytest
from nptdms import TdmsFile
from scipy.integrate import quad

from . import rig as R

TWO_PI = 2.0 * math.pi
FS = 5120.0


def circ(a, b):
    """Circular distance between phasings in cycles [-] (0.9999999999 is next to 0)."""
    d = np.mod(np.asarray(a) - np.asarray(b), 1.0)
    return np.minimum(d, 1.0 - d)


def small_config(**kw):
    """A short, fast recording config (seconds, not minutes)."""
    base = dict(minutes=kw.pop("minutes", 4.0 / 60.0))
    base.update(kw)
    return R.make_rig_config(**base)


GEARSETS = {
    "4eq_25_87_29": R.Gearset.equally_spaced(25, 87, 29, 4),
    "5eq_25_85_30": R.Gearset.equally_spaced(25, 85, 30, 5, carrier_radius=0.110),
    "3unequal_assemblable": R.Gearset.from_assembly_positions(25, 87, 29, (0, 37, 75)),
    "3arbitrary": R.Gearset(25, 87, 29, (0.0, 1.7, 3.9)),
}


# ----------------------------------------------------------------------------- independence
def test_imports_nothing_from_pipeline_or_synthetic():
    src = Path(R.__file__).read_text()
    roots = set()
    for node in ast.walk(ast.parse(src)):
        if isinstance(node, ast.Import):
            roots |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            assert node.level == 0, "no relative imports"
            roots.add(node.module.split(".")[0])
    allowed = {"numpy", "scipy", "nptdms"} | set(sys.stdlib_module_names)
    assert roots <= allowed, roots - allowed
    assert not roots & {"pipeline", "synthetic", "meshphase"}


# ----------------------------------------------------------------------------- kinematics
@pytest.mark.parametrize("fixed,kw", [("ring", {"sun_rpm": 18.19}), ("sun", {"carrier_rpm": 4.0}),
                                      ("carrier", {"sun_rpm": -7.0})])
def test_kinematic_relations(fixed, kw):
    """Willis: Z_s theta_sc = -Z_r theta_rc = -Z_p theta_pc; absolute = carrier + relative; fixed = 0."""
    g = GEARSETS["4eq_25_87_29"]
    k = R.nominal_kinematics(g, fixed, **kw)
    m = R.Motion(k, R.SpeedProfile(((0.02, 1.0, "planet", 0.3),), 0.1, 10.0), -1.0, 11.0)
    t = np.linspace(-1, 11, 301)
    a = {mem: m.angle(mem, t) for mem in R.MEMBERS}
    scale = np.abs(a["sun_rel"]).max() * g.z_sun
    # identities hold to rounding of the ratio products (a few ulp of the largest angle)
    tol = 1e-13 * scale
    np.testing.assert_allclose(g.z_sun * a["sun_rel"], -g.z_ring * a["ring_rel"], rtol=0, atol=tol)
    np.testing.assert_allclose(g.z_sun * a["sun_rel"], -g.z_planet * a["planet"], rtol=0, atol=tol)
    np.testing.assert_allclose(a["sun"], a["carrier"] + a["sun_rel"], rtol=0, atol=tol)
    np.testing.assert_allclose(a["ring"], a["carrier"] + a["ring_rel"], rtol=0, atol=tol)
    assert np.all(a[fixed] == 0.0)
    given, rpm = next(iter(kw.items()))
    assert k.rpm(given.removesuffix("_rpm")) == pytest.approx(rpm, rel=1e-15)


def test_carrier_speed_exact_vs_scene():
    """Fixed ring: n_c = n_s Z_s / (Z_s + Z_r) exactly; a scene would say 4.06 r/min."""
    k = R.nominal_kinematics(GEARSETS["4eq_25_87_29"], sun_rpm=18.19)
    assert k.rpm("carrier") == pytest.approx(18.19 * 25 / 112, rel=1e-15)
    assert round(k.rpm("carrier"), 2) == 4.06
    assert k.planet_rotation == "cw"
    assert R.nominal_kinematics(GEARSETS["4eq_25_87_29"], sun_rpm=-18.19).planet_rotation == "ccw"


def test_ramp_matches_closed_form():
    """No ripple: theta_c = w0 (t + r (t^2/(2T) - t/2)) on [0, T], linear outside.

    DOP853 (order 8) integrates a quadratic exactly; what remains is rounding, a few ulp of
    the largest angle (~10 rad) -> 1e-13 rad.
    """
    k = R.nominal_kinematics(GEARSETS["4eq_25_87_29"], sun_rpm=18.19)
    T, r = 20.0, 0.3
    m = R.integrate_motion(k, R.SpeedProfile((), r, T), -2.0, T + 2.0)
    t = np.linspace(-2.0, T + 2.0, 4001)
    w0 = k.speed("carrier")
    tc = np.clip(t, 0, T)
    closed = (w0 * (tc + r * (tc ** 2 / (2 * T) - tc / 2)) + w0 * (1 + r / 2) * np.maximum(t - T, 0)
              + w0 * (1 - r / 2) * np.minimum(t, 0))
    np.testing.assert_allclose(m.theta_ref(t), closed, rtol=0, atol=1e-13)
    np.testing.assert_allclose(m.rate("carrier", t), w0 * (1 + r * (tc / T - 0.5)), rtol=1e-14)


@pytest.mark.parametrize("member,order,amp", [("carrier", 1.0, 0.03), ("sun", 2.0, 0.02), ("planet", 1.0, 0.01)])
def test_ripple_matches_quadrature(member, order, amp):
    """Shaft-locked ripple without ramp is separable: t(theta) = int dtheta / theta_dot(theta).

    quad of that integral is an independent path to the same motion. Tolerance 1e-9 rad over
    35 rad (3e-11 relative): the global error of a DOP853 run at rtol 1e-12 over a few hundred
    steps (observed ~5e-11 rad).
    """
    k = R.nominal_kinematics(GEARSETS["4eq_25_87_29"], sun_rpm=18.19)
    m = R.Motion(k, R.SpeedProfile(((amp, order, member, 0.4),), 0.0, 100.0), 0.0, 100.0)
    w0, kk = k.speed("carrier"), k.ratio(member)
    for th in np.linspace(0.5, 35.0, 8):
        tq, _ = quad(lambda x: 1.0 / (w0 * (1 + amp * np.sin(order * kk * x + 0.4))), 0.0, th,
                     epsabs=1e-13, epsrel=1e-13, limit=1000)
        assert abs(m.theta_ref(np.array([tq]))[0] - th) < 1e-9


# ----------------------------------------------------------------------------- truth phasing
@pytest.mark.parametrize("name", list(GEARSETS))
@pytest.mark.parametrize("sun_rpm", [18.19, -18.19])
def test_truth_equals_parker_when_steady_and_error_free(name, sun_rpm):
    """Spec section 1: gamma_sn = frac(+Z_s psi/2pi), gamma_rn = frac(-Z_r psi/2pi) (cw; ccw flips).

    Tolerance 1e-9 cycles: the engagement roots are solved to 1e-13 s, i.e. ~1e-12 mesh
    cycles; the rest is rounding of angles of a few hundred rad.
    """
    g = GEARSETS[name]
    k = R.nominal_kinematics(g, sun_rpm=sun_rpm)
    m = R.Motion(k, R.SpeedProfile(), 0.0, 40.0)
    ps, pr = R.parker_phasing(g, k.planet_rotation)
    for gear, ideal, a0 in (("sun", ps, 0.3), ("ring", pr, 1.0)):
        t, p = R.engagement_instants(m, R.HoleErrors(), gear, a0, 0.0, 40.0)
        passes = R.pass_truth(m, gear, t, p)
        assert len(passes) >= 1
        for ps_ in passes:
            assert circ(ps_["gamma"], ideal).max() < 1e-9
    if g.is_assemblable():
        assert circ(ps, pr).max() < 1e-12  # spec section 1 invariant


@pytest.mark.parametrize("preset", list(R.PRESETS))
def test_presets_truth(preset):
    """Every preset builds; error-free presets keep Parker's phasing in the truth under ripple,
    ramp, either sense and any SNR (phasing is geometry: speed changes move instants, not
    gamma); the shaft-hole preset departs from it."""
    cfg = R.preset_config(preset, minutes=30.0 / 60.0)  # one complete ring pass in either sense
    rig = R.Rig(cfg)
    truth = rig.truth()
    ps, pr = np.array(truth.parker["sun"]), np.array(truth.parker["ring"])
    assert len(truth.passes["SG_sun_T3"]) >= 3 and len(truth.passes["SG_ring_T1"]) >= 1
    dev = max(circ(p["gamma"], ps if ch.startswith("SG_sun") else pr).max()
              for ch, pl in truth.passes.items() for p in pl)
    if preset == "hole_errors_case1":
        assert dev > 1e-3
    else:
        assert dev < 1e-9
    assert (truth.tacho is None) == (not cfg.tacho)


def test_engagements_satisfy_geometry_with_errors_ripple_and_ramp():
    """At each instant the tooth direction equals arg(O_pan - O_ja) to < 1e-10 rad.

    brentq's xtol of 1e-13 s is < 1e-12 rad at these speeds; 1e-10 leaves room for rounding
    of angles of ~100 rad.
    """
    g = GEARSETS["4eq_25_87_29"]
    err = R.HoleErrors(e_sun=1e-3, kappa_sun=0.07, e_ring=1e-3, kappa_ring=1.05,
                       e_planet=(1e-3, 0.5e-3, 0.8e-3, 0.2e-3), kappa_planet=(0.35, 1.0, -2.0, 3.0))
    k = R.nominal_kinematics(g, sun_rpm=18.19)
    prof = R.SpeedProfile(((0.03, 1.0, "carrier", 0.2), (0.01, 1.0, "planet", 1.1)), 0.1, 40.0)
    m = R.Motion(k, prof, 0.0, 40.0)
    for gear, a0 in (("sun", 0.3), ("ring", 1.0)):
        t, p = R.engagement_instants(m, err, gear, a0, 0.0, 40.0)
        assert t.size > 4
        assert np.abs(R.engagement_residual(m, err, gear, a0, t, p)).max() < 1e-10
        # instants in one pass come planet after planet in the gear's sense
        passes = R.pass_truth(m, gear, t, p)
        assert passes
        ideal = R.parker_phasing(g, "cw")[0 if gear == "sun" else 1]
        dev = max(circ(q["gamma"], ideal).max() for q in passes)
        # 1 mm offsets on R_c = 112.5 mm turn the lines of centres by ~1e-2 rad -> Z/2pi * that
        assert 1e-3 < dev < 0.2


def test_line_of_centres_matches_seed_planet_formula():
    """Planet error only: the seed's dpsi_epn = arcsin(e sin b / |O_si O_pan|), with
    |O_si O_pan| = sqrt(R^2 + e^2 - 2 R e cos b), is this geometry with b = pi - beta."""
    g = GEARSETS["4eq_25_87_29"]
    k = R.nominal_kinematics(g, sun_rpm=18.19)
    m = R.Motion(k, R.SpeedProfile(), 0.0, 10.0)
    e = (2e-3, 1e-3, 0.5e-3, 3e-3)
    kap = (0.2, 1.0, 2.5, -1.0)
    err = R.HoleErrors(e_planet=e, kappa_planet=kap)
    t = np.linspace(0, 10, 101)
    for n in range(4):
        beta = kap[n] + m.angle("planet", t)
        b = math.pi - beta
        dist = np.sqrt(g.carrier_radius ** 2 + e[n] ** 2 - 2 * g.carrier_radius * e[n] * np.cos(b))
        seed = np.arcsin(e[n] * np.sin(b) / dist)
        got = R.line_of_centres(m, err, "sun", n, t) - g.planet_angles[n]
        np.testing.assert_allclose(got, seed, rtol=0, atol=1e-15)


# ----------------------------------------------------------------------------- signals
def test_pulse_shape():
    u = np.linspace(-3, 3, 60001)
    p = R.pulse_shape(u)
    assert p.max() == pytest.approx(1.0, abs=1e-12)
    assert u[p.argmax()] == pytest.approx(0.12, abs=1e-4)  # peak slightly after engagement
    lo, hi = R.PULSE_SUPPORT
    assert np.all(p[(u < lo) | (u > hi)] == 0)
    assert p.min() < -0.2  # compressive side lobes
    pos = u[p > 0]
    # tensile lobe 1.6 mesh cycles; the trailing compressive lobe overlaps its last 0.05 cycles
    assert 1.55 < pos.max() - pos.min() <= 1.6
    assert R.pulse_shape(np.zeros(0)).shape == (0,)
    with pytest.raises(ValueError):
        R.pulse_shape("abc")


def test_pulse_width_scales_with_inverse_local_speed():
    """The half-maximum width of the tensile lobe is 0.8 mesh cycles of angle, so in time it is
    0.8 / f_mesh. With a linear ramp the mean mesh rate over the window equals the rate at the
    window's midpoint exactly; linear interpolation of the half-max crossings (~900 samples per
    mesh cycle) is good to << 1e-3."""
    cfg = small_config(minutes=20 / 60, ramp=0.6, snr_db=None, hum=0.0, drift=0.0, tacho=False,
                       ring_gauge=False)
    rig = R.Rig(cfg)
    t = np.arange(rig.n_samples) / FS
    x = rig.clean_gauge("sun", t)
    te, p = rig.engagements("sun")
    widths, rates = [], []
    for tk, pk in zip(te, p):
        i = int(round(tk * FS))
        if i < 2000 or i > rig.n_samples - 2000:
            continue
        seg = slice(i - 2000, i + 2000)
        xs, ts = x[seg], t[seg]
        half = 0.5 * xs.max()
        above = np.flatnonzero(xs > half)
        a, b = above[0], above[-1]
        ta = np.interp(half, xs[a - 1:a + 1], ts[a - 1:a + 1])
        tb = np.interp(-half, -xs[b:b + 2], ts[b:b + 2])
        widths.append(tb - ta)
        f_mesh = abs(rig.motion.rate("sun_rel", np.array([(ta + tb) / 2]))[0]) * 25 / TWO_PI
        rates.append(f_mesh)
    widths, rates = np.array(widths), np.array(rates)
    assert widths.max() / widths.min() > 1.3  # the ramp really changes the width
    np.testing.assert_allclose(widths * rates, 0.8, rtol=1e-3)


def test_noise_level_matches_snr():
    """Noise rms = peak / 10^(snr/20); ~61k samples give the rms to 0.3 % (1 sigma), 3 % is 10 sigma."""
    cfg = small_config(minutes=12 / 60, snr_db=20.0, hum=0.0, drift=0.0, load_sharing=(1.2, 1.0, 0.9, 0.9))
    rig = R.Rig(cfg)
    t = np.arange(rig.n_samples) / FS
    data = np.concatenate([d["SG_sun_T3"] for _, _, d in rig.iter_blocks(4096)])
    noise = data - rig.clean_gauge("sun", t)
    peak = cfg.sun_peak * 1.2  # the largest pulse: planet 1, factor 1.2
    assert np.sqrt(np.mean(noise ** 2)) == pytest.approx(peak / 10.0, rel=0.03)
    assert R.Rig(cfg).truth().load_sharing == pytest.approx([1.2, 1.0, 0.9, 0.9], rel=1e-15)


def test_blocks_do_not_change_values():
    rig = R.Rig(small_config(minutes=3 / 60, adc_bits=24))
    a = {k: np.concatenate([d[k] for _, _, d in rig.iter_blocks(512)]) for k in ("SG_sun_T3", "Tacho OPR")}
    b = {k: np.concatenate([d[k] for _, _, d in rig.iter_blocks(1000, render_samples=3000)])
         for k in ("SG_sun_T3", "Tacho OPR")}
    for k in a:
        np.testing.assert_array_equal(a[k], b[k])


@pytest.mark.parametrize("sun_rpm", [18.19, -18.19])
def test_tacho_edges(sun_rpm):
    """Rising edges sit where the absolute carrier angle = edge angle (mod 2 pi); the sampled
    TTL channel goes high on the first sample at or after each edge."""
    cfg = small_config(minutes=40 / 60, sun_rpm=sun_rpm, tacho_noise=0.0)
    rig = R.Rig(cfg)
    te = rig.tacho_edges
    assert te.size >= 2  # 40 s at 4.06 r/min: one carrier revolution takes 14.8 s
    th = rig.motion.angle("carrier", te)
    assert np.abs(R._wrap(th - cfg.tacho_edge_angle)).max() < 1e-10
    x = np.concatenate([d["Tacho OPR"] for _, _, d in rig.iter_blocks(8192)])
    rises = np.flatnonzero((x[1:] > 2.5) & (x[:-1] < 2.5)) + 1
    np.testing.assert_array_equal(rises, np.ceil(te * FS).astype(int))
    truth = rig.truth()
    assert truth.tacho["ring_gauge_angle_from_tacho"] == pytest.approx(
        (cfg.ring_gauge_angle - cfg.tacho_edge_angle) % TWO_PI)
    # the key passes the pick-up (ground angle 0) at each edge
    key_ground = rig.motion.angle("carrier", te) + truth.tacho["key_carrier_angle"]
    assert np.abs(R._wrap(key_ground)).max() < 1e-10


# ----------------------------------------------------------------------------- TDMS + sidecar
def _lead_ins(path):
    """Walk the TDMS segment lead-ins (28 bytes: tag, ToC, version, next offset, raw offset)."""
    out = []
    with open(path, "rb") as f:
        size = Path(path).stat().st_size
        pos = 0
        while pos < size:
            f.seek(pos)
            tag, toc, ver, nxt, raw = struct.unpack("<4siiQQ", f.read(28))
            out.append((tag, toc, ver))
            pos += 28 + nxt
    return out


@pytest.mark.parametrize("seg", [1000, 512])
def test_tdms_round_trip(tmp_path, seg):
    path = tmp_path / "rig.tdms"
    truth = R.make_preset_tdms(path, "ripple1_carrier", minutes=3 / 60, samples_per_segment=seg)
    n = int(3 * FS)
    f = TdmsFile.read(path)
    (grp,) = f.groups()
    assert grp.name == "Rig"
    names = [c.name for c in grp.channels()]
    assert names == ["SG_sun_T3", "SG_ring_T1", "Tacho OPR"]
    rig = R.Rig(R.RigConfig.from_dict(truth.config))  # the sidecar config rebuilds the rig
    expect = {k: np.concatenate([d[k] for _, _, d in rig.iter_blocks(seg)]) for k in names}
    for c in grp.channels():
        assert c.properties["wf_increment"] == 1.0 / FS
        assert c.properties["wf_start_time"] == np.datetime64("2024-03-12T09:41:27.250000", "us")
        assert c.properties["wf_samples"] == seg
        assert c.properties["unit_string"] == ("V" if c.name.startswith("Tacho") else "Strain")
        assert len(c) == n and c.dtype == np.float64
        np.testing.assert_array_equal(c[:], expect[c.name])  # float64 written and read bit for bit
    segs = _lead_ins(path)
    assert len(segs) == math.ceil(n / seg) == truth.tdms["segments"]
    assert all(s[0] == b"TDSm" for s in segs)
    assert all(s[1] & (1 << 5) == 0 for s in segs)  # kTocInterleavedData never set
    with TdmsFile.open(path) as fo:
        assert sum(1 for _ in fo.data_chunks()) == len(segs)


@pytest.mark.parametrize("bits,dtype", [(16, np.int16), (24, np.int32)])
def test_tdms_int_storage_with_ni_scaling(tmp_path, bits, dtype):
    path = tmp_path / "q.tdms"
    truth = R.make_rig_tdms(path, minutes=2 / 60, adc_bits=bits, storage="int")
    rig = R.Rig(R.RigConfig.from_dict(truth.config))
    f = TdmsFile.read(path)
    for c in f["Rig"].channels():
        raw = c.read_data(scaled=False)
        assert raw.dtype == dtype
        counts = np.concatenate([d[c.name] for _, _, d in rig.iter_blocks(1000, counts=True)])
        np.testing.assert_array_equal(raw, counts)
        np.testing.assert_array_equal(c[:], counts * rig.lsb(c.name))  # same float64 product
        phys = np.concatenate([d[c.name] for _, _, d in rig.iter_blocks(1000)])
        np.testing.assert_array_equal(c[:], phys)


def test_sidecar_round_trip(tmp_path):
    path = tmp_path / "a.tdms"
    truth = R.make_rig_tdms(path, minutes=20 / 60, ripple=[(0.01, 1, "carrier", 0.0)], ramp=0.1,
                            errors={"e_sun": 0.2e-3, "kappa_sun": 0.07})
    assert R.truth_path(path) == tmp_path / "a.truth.json"
    for p in (path, R.truth_path(path)):
        back = R.read_truth(p)
        assert back == truth
    assert back.file == "a.tdms"
    ch = "SG_ring_T1"
    assert back.engagements[ch]["planet"][:4] == [1, 4, 3, 2]  # ring turns cw relative to the carrier
    # the truth's config rebuilds the same rig: identical instants
    rig = R.Rig(R.RigConfig.from_dict(back.config))
    t, _ = rig.engagements("sun")
    assert t.tolist() == back.engagements["SG_sun_T3"]["t"]
    doc = json.loads(R.truth_path(path).read_text())
    assert doc["speeds"]["carrier_rpm_scene"] == 4.06


def test_no_tacho_file_layout(tmp_path):
    """What an NI reader needs: one wf_increment, one start time, a length per channel."""
    path = tmp_path / "b.tdms"
    R.make_rig_tdms(path, minutes=1 / 60, tacho=False)
    f = TdmsFile.read(path)
    chans = f["Rig"].channels()
    assert len(chans) == 2
    assert {c.properties["wf_increment"] for c in chans} == {1 / FS}
    assert {len(c) for c in chans} == {5120}


# ----------------------------------------------------------------------------- bad / empty inputs
def test_gearset_bad_inputs():
    with pytest.raises(ValueError, match="planet_angles"):
        R.Gearset(25, 87, 29, ())
    with pytest.raises(TypeError, match="z_sun"):
        R.Gearset("25", 87, 29, (0.0,))
    with pytest.raises(ValueError, match="planet 1"):
        R.Gearset(25, 87, 29, (0.1, 1.0))
    with pytest.raises(ValueError, match="increase"):
        R.Gearset(25, 87, 29, (0.0, 2.0, 1.0))
    with pytest.raises(ValueError, match="z_ring"):
        R.Gearset(87, 25, 29, (0.0,))
    with pytest.raises(ValueError, match="n_planets"):
        R.Gearset.equally_spaced(25, 87, 29, 0)
    with pytest.raises(ValueError, match="positions"):
        R.Gearset.from_assembly_positions(25, 87, 29, (0, 112))
    with pytest.raises(TypeError, match="positions"):
        R.Gearset.from_assembly_positions(25, 87, 29, "0 28")
    with pytest.raises(ValueError, match="planet_angles"):
        R.Gearset.from_assembly_positions(25, 87, 29, ())


def test_kinematics_and_profile_bad_inputs():
    g = GEARSETS["4eq_25_87_29"]
    with pytest.raises(ValueError, match="exactly one"):
        R.nominal_kinematics(g)
    with pytest.raises(ValueError, match="fixed member"):
        R.nominal_kinematics(g, "ring", ring_rpm=3.0)
    with pytest.raises(ValueError, match="fixed"):
        R.nominal_kinematics(g, "planet", sun_rpm=3.0)
    with pytest.raises(TypeError, match="sun_rpm"):
        R.nominal_kinematics(g, sun_rpm="fast")
    with pytest.raises(ValueError, match="member"):
        R.RippleTerm(0.01, 1, "shaft")
    with pytest.raises(TypeError, match="amplitude"):
        R.RippleTerm("1%")
    with pytest.raises(ValueError, match="sum of ripple"):
        R.SpeedProfile(((0.3, 1, "carrier"), (0.3, 1, "sun")))
    with pytest.raises(ValueError, match="ramp"):
        R.SpeedProfile((), 1.0)
    with pytest.raises(TypeError, match="ripple"):
        R.SpeedProfile("carrier")
    assert R.SpeedProfile(()).ripple == ()
    k = R.nominal_kinematics(g, sun_rpm=18.19)
    with pytest.raises(ValueError, match="t_start"):
        R.Motion(k, R.SpeedProfile(), 1.0, 2.0)
    with pytest.raises(ValueError, match="does not turn"):
        R.Motion(k, R.SpeedProfile(((0.01, 1, "ring"),)), 0.0, 2.0)
    m = R.Motion(k, R.SpeedProfile(), 0.0, 2.0)
    assert m.theta_ref(np.zeros(0)).shape == (0,)
    with pytest.raises(ValueError, match="outside"):
        m.theta_ref(np.array([3.0]))
    with pytest.raises(TypeError, match="kinematics"):
        R.integrate_motion(None, R.SpeedProfile(), 0.0, 1.0)


def test_geometry_and_truth_bad_and_empty_inputs():
    g = GEARSETS["4eq_25_87_29"]
    k = R.nominal_kinematics(g, sun_rpm=18.19)
    m = R.Motion(k, R.SpeedProfile(), 0.0, 20.0)
    e0 = R.HoleErrors()
    with pytest.raises(ValueError, match="e_sun"):
        R.HoleErrors(e_sun=-1e-3)
    with pytest.raises(ValueError, match="kappa_planet"):
        R.HoleErrors(e_planet=(1e-3,), kappa_planet=(0.1, 0.2))
    with pytest.raises(ValueError, match="too large"):
        R.HoleErrors(e_sun=0.05, e_planet=(0.02,) * 4).check(g)
    with pytest.raises(TypeError, match="errors"):
        R.HoleErrors.coerce(3.0)
    with pytest.raises(ValueError, match="gear"):
        R.line_of_centres(m, e0, "planet", 0, [1.0])
    with pytest.raises(ValueError, match="planet index"):
        R.line_of_centres(m, e0, "sun", 4, [1.0])
    with pytest.raises(ValueError, match="window"):
        R.engagement_instants(m, e0, "sun", 0.3, 0.0, 30.0)
    t, p = R.engagement_instants(m, e0, "sun", 0.3, 0.0, 0.01)  # too short to meet a planet
    assert t.size == 0 and p.size == 0 and p.dtype == np.int64
    assert R.engagement_residual(m, e0, "sun", 0.3, [], []).shape == (0,)
    with pytest.raises(ValueError, match="same shape"):
        R.engagement_residual(m, e0, "sun", 0.3, [1.0, 2.0], [1])
    with pytest.raises(ValueError, match="planets must be"):
        R.engagement_residual(m, e0, "sun", 0.3, [1.0], [0])
    assert R.pass_truth(m, "sun", [], []) == []
    with pytest.raises(ValueError, match="sorted"):
        R.pass_truth(m, "sun", [2.0, 1.0], [1, 2])
    with pytest.raises(ValueError, match="planet_rotation"):
        R.parker_phasing(g, "left")
    with pytest.raises(TypeError, match="Gearset"):
        R.parker_phasing((25, 87, 29), "cw")


def test_rig_and_writer_bad_and_empty_inputs(tmp_path):
    with pytest.raises(ValueError, match="minutes"):
        R.make_rig_config(minutes=0)
    with pytest.raises(TypeError, match="minutes"):
        R.make_rig_config(minutes="1")
    with pytest.raises(ValueError, match="adc_bits"):
        small_config(adc_bits=12)
    with pytest.raises(ValueError, match="tacho"):
        small_config(fixed="carrier", sun_rpm=10.0)
    with pytest.raises(ValueError, match="load_sharing"):
        small_config(load_sharing=(1.0, 1.0))
    with pytest.raises(TypeError, match="ripple"):
        small_config(ripple="1%")
    with pytest.raises(ValueError, match="name"):
        R.preset_config("windy", minutes=1)
    with pytest.raises(TypeError, match="config"):
        R.Rig({"minutes": 1})
    rig = R.Rig(small_config(minutes=1 / 60))
    assert rig.clean_gauge("sun", np.zeros(0)).shape == (0,)
    with pytest.raises(ValueError, match="increase"):
        rig.clean_gauge("sun", [0.2, 0.1])
    with pytest.raises(ValueError, match="block"):
        next(rig.iter_blocks(0))
    with pytest.raises(ValueError, match="counts"):
        next(rig.iter_blocks(100, counts=True))
    with pytest.raises(ValueError, match="interleaved"):
        R.write_rig_tdms(rig, tmp_path / "x.tdms", interleaved=True)
    with pytest.raises(ValueError, match="adc_bits"):
        R.write_rig_tdms(rig, tmp_path / "x.tdms", storage="int")
    with pytest.raises(TypeError, match="path"):
        R.write_rig_tdms(rig, 3)
    with pytest.raises(TypeError, match="rig"):
        R.write_rig_tdms(None, tmp_path / "x.tdms")
    with pytest.raises(ValueError, match="no tacho"):
        R.Rig(small_config(minutes=1 / 60, tacho=False)).clean_tacho([0.0])
    with pytest.raises(TypeError, match="tdms_path"):
        R.truth_path(3)
    with pytest.raises(TypeError, match="path"):
        R.read_truth(None)
    with pytest.raises(ValueError, match="keys"):
        R.RigTruth.from_json("{}")
    with pytest.raises(TypeError, match="text"):
        R.RigTruth.from_json(b"{}")
    with pytest.raises(TypeError, match="mapping"):
        R.RigConfig.from_dict([])


def test_small_api_bad_inputs():
    g = GEARSETS["4eq_25_87_29"]
    k = R.nominal_kinematics(g, sun_rpm=18.19)
    with pytest.raises(ValueError, match="member"):
        k.coef("shaft")
    with pytest.raises(ValueError, match="mesh_rate"):
        R.Kinematics(g, "ring", 0.0)
    with pytest.raises(TypeError, match="ripple term"):
        R.RippleTerm.coerce(0.01)
    assert R.RippleTerm.coerce({"amplitude": 0.01}).member == "carrier"
    assert R.HoleErrors.coerce(None) == R.HoleErrors()
    rig = R.Rig(small_config(minutes=1 / 60, ring_gauge=False))
    t, p = rig.engagements("sun")
    assert t.size == p.size
    with pytest.raises(ValueError, match="gear"):
        rig.engagements("ring")  # not recorded
    with pytest.raises(ValueError, match="adc_bits"):
        rig.lsb("SG_sun_T3")
    rq = R.Rig(small_config(minutes=1 / 60, adc_bits=16))
    with pytest.raises(ValueError, match="no channel"):
        rq.lsb("SG_planet")
    assert rq.lsb("SG_sun_T3") == 2 * 2e-3 / 2 ** 16


def test_encoder_edges_sit_at_equal_shaft_angles():
    # rising edge k where the shaft has turned (a0 + 2 pi k / ppr), in its sense of rotation,
    # with the planet-rate ripple on: the edges' shaft angles are whole pulses to root tolerance
    cfg = R.make_rig_config(minutes=0.25, ripple=((0.01, 1.0, "planet", 0.0),),
                            encoder=("sun", 60), encoder_edge_angle=0.2)
    rig = R.Rig(cfg)
    te = rig.encoder_edges
    pulses = 60 * (rig.motion.angle("sun", te) - 0.2) / (2 * math.pi)
    assert np.max(np.abs(pulses - np.rint(pulses))) < 1e-9
    assert np.all(np.diff(np.rint(pulses)) == 1)             # none skipped
    turns = abs(rig.kinematics.rpm("sun")) * 0.25
    assert te.size == pytest.approx(60 * turns, abs=2)
    truth = rig.truth()
    assert truth.encoder["rising_edges"] == te.tolist() and truth.encoder["pulses_per_rev"] == 60
    assert [c["kind"] for c in truth.channels][-1] == "encoder"
    # the rendered channel is high from each edge for half a pulse
    t = np.arange(rig.n_samples) / cfg.fs
    x = rig._encoder_from_ref(rig.motion.theta_ref(t))
    assert set(np.unique(x)) == {0.0, cfg.encoder_high}
    assert np.mean(x > 0) == pytest.approx(0.5, abs=0.01)
    assert R.RigTruth.from_json(truth.to_json()).encoder == json.loads(truth.to_json())["encoder"]


@pytest.mark.parametrize("kw, err, match", [
    ({"encoder": ("ring", 60)}, ValueError, "held ring does not turn"),
    ({"encoder": ("planet", 60)}, ValueError, "encoder shaft"),
    ({"encoder": ("sun", 0)}, ValueError, "encoder pulses per revolution"),
    ({"encoder": "sun"}, TypeError, r"encoder must be \(shaft, pulses per revolution\)"),
    ({"encoder": ("sun", 60), "encoder_duty": 1.0}, ValueError, r"encoder_duty must be in \(0, 1\)"),
])
def test_encoder_config_errors(kw, err, match):
    with pytest.raises(err, match=match):
        R.make_rig_config(minutes=0.1, **kw)
