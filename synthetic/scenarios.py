"""Registry of named synthetic scenarios (tests parametrize over :data:`SCENARIOS`).

Each entry is a :class:`Scenario` whose ``config()`` builds a fresh
:class:`~meshphase.synthetic.config.SynthConfig`. ``get_scenario(name)`` returns the config;
``list_scenarios()`` the names.

Gearsets
--------
``table1``
    Seed 000 Table 1 as :func:`meshphase.models.tolerance.table2_case` gives it: Z_s 25,
    Z_r 87, Z_p 29, four equally spaced planets, R_c 112.5 mm, fixed ring, w_s 448,
    w_c 100 rad/s (w_s / w_c = 4.48 = 1 + Z_r / Z_s), clockwise planets. Mesh frequency
    Z_s w_sc / 2 pi = 1385 Hz, so it is sampled at 51.2 kHz (the NI 9234 maximum), 37 samples
    per mesh period. Face width 40 mm (not in the seed; assumed).
``seed_rig``
    The seed's rig runs the sun at 18.19 r/min and the carrier at 1.06 r/min, a ratio of
    17.16. With a fixed ring that needs 1 + Z_r / Z_s = 17.16, which no simple stage with four
    planets can reach: the planets' tip circles must clear each other,
    (Z_s + Z_p) sin(pi / 4) > Z_p + 2, and with Z_r = Z_s + 2 Z_p that caps the fixed-ring
    ratio 2 + 2 Z_p / Z_s below 6.83. So the rig must run as a differential, the ring driven
    too (a reaction motor or a back-to-back loop), and the sun and carrier speeds fix the
    ring speed by Willis: w_r = w_c - (Z_s / Z_r)(w_s - w_c) = -3.862 r/min (counter-rotating).
    Tooth counts: the seed's own Table 1 gearset (the experiment validates that model), with
    the planet count made consistent with the centre distances: Z_s 25, Z_r 87,
    Z_p = (87 - 25) / 2 = 31 (Table 1's 29 cannot mesh with both at one centre distance),
    four equally spaced planets (assemblable: (25 + 87) / 4 = 28), R_c 112.5 mm (module 4 mm
    with a +0.5 mm centre-distance shift), face width 40 mm. Mesh frequency 7.14 Hz
    (T_m = 0.140 s = 717 samples at 5120 Hz); the sun gauge meets a planet every 0.88 s,
    the ring gauge every 3.05 s (relative ring revolution 12.2 s).

``rig`` (the accuracy-matrix family, ``rig_*`` below)
    The seed's Table 1 gearset on a rig as an independent tester ran it: Z_s 25, Z_r 87,
    Z_p 29 (as in Table 1: 29 rather than (87 - 25) / 2 = 31 needs a centre-distance /
    profile shift, which the kinematics do not see), four planets at 90 deg, R_c 112.5 mm,
    face width 40 mm, FIXED ring (w_r = 0 exactly), sun 18.19 r/min, carrier
    18.19 / (1 + 87/25) = 4.0603 r/min (Willis), clockwise planets, 5120 Hz. Mesh frequency
    Z_s w_sc / 2 pi = Z_r w_c / 2 pi = 5.89 Hz (T_m = 0.170 s = 869 samples); the sun gauge
    meets a planet every 1.06 s (relative sun revolution 4.25 s), the ring gauge every 3.69 s
    (one carrier revolution 14.8 s). Table 2 case 1 shaft hole errors (0.2 mm), 20 dB SNR of
    white noise (no 1/f), 50 Hz hum 2 µε, thermal drift 8 µε (T 900 s), 24-bit ADC over
    +-2000 µε, sun + ring gauges and a carrier tacho, 2 min. ``rig_5planets`` uses
    Z 25/85/30 with five equally spaced planets (assemblable: 110 / 5 = 22; tip circles clear:
    55 sin 36 deg = 32.3 > 32), carrier 18.19 / (1 + 85/25) r/min.

Gauges: sun tooth 0 (150 µε nominal, contact ratio 1.6), ring tooth 0 (100 µε, contact ratio
1.8: internal meshes have more overlap), a carrier tacho; the face-width scenarios add gauges
across one sun and one ring tooth. Every scenario's tacho can be removed with
``get_scenario(name).with_(tacho=None)`` and its artefacts replaced with ``artefacts=...``.

Scenarios
---------
``table1_high_speed`` (and ``_ccw``, every speed reversed), ``table2_case1/2/3`` (seed 000
Table 2 errors; case 3 draws one realisation from the tolerance bands with the seed),
``seed_rig`` (case 1 errors, clean), ``noisy``, ``adc16_clipped``, ``speed_ripple``
(``speed_ripple_fast`` as a stress case),
``speed_ramp``, ``gaps``, ``facewidth_offcentre``, ``facewidth_partial``, ``facewidth_tilt``,
``rig_realistic``, ``one_hour`` (generate it with :func:`meshphase.synthetic.generate_blocks`).

The ``rig`` family changes one factor each from ``rig_steady`` (no speed variation):
``rig_ripple1`` / ``rig_ripple3`` (1 % / 3 % speed ripple once per carrier revolution, locked
to the carrier angle), ``rig_ripple_sun`` (1 % once per absolute sun revolution),
``rig_ripple_planet`` (1 % once per planet revolution relative to the carrier: generator
only, it may not be measurable), ``rig_ramp_up`` / ``rig_ramp_down`` (1 % carrier ripple plus
+10 % / -10 % speed over the 2 min, the ramp in time), ``rig_ccw`` (1 % carrier ripple, every
speed reversed, counter-clockwise planets), ``rig_3planets`` (three unequally spaced
assemblable planets at p_n = 0, 36, 75 of 2 pi / 112, i.e. 0, 115.7, 241.1 deg: mixed
phasing; 1 % carrier ripple), ``rig_5planets`` (Z 25/85/30, five equally spaced planets,
1 % carrier ripple). Shaft-locked ripple follows the member's angle
(:class:`meshphase.synthetic.kinematics.ShaftRipple`), so it stays locked to the shaft through a ramp.
``rig_ripple_planet_encoder`` adds a 60-pulse sun-shaft encoder to ``rig_ripple_planet``
(:class:`meshphase.synthetic.config.EncoderConfig`): the encoder sees that ripple.

Adversarial rig conditions (:data:`ADVERSARIAL_SCENARIOS`, tag "adversarial", tagged "rig" too):
conditions where measured phasing was confident and wrong. ``rig_ripple_planet`` above,
``rig_5planets_ripple_planet`` (the same ripple on the five-planet gearset),
``rig_fast_ripple1`` (sun at 120 r/min, 1 % carrier ripple), ``rig_load_ripple`` (every pulse
amplitude +-25 % once per carrier revolution: a torque ripple, :class:`LoadModulation`),
``rig_microstrain`` (gauge channels written in µε) hold processing to ``expect =
"goal_or_flag"`` (:attr:`Scenario.expect`: within the target or flagged unreliable);
``rig_clean`` (rig_steady without artefacts) to the plain goal, with no data-quality warning.

Each entry's ``description`` says what it holds; :func:`describe_scenarios` lists them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

from meshphase.models.gearset import Gearset, Speeds, rpm_to_rad_s
from meshphase.models.tolerance import table2_case

from meshphase.synthetic.config import Artefacts, EncoderConfig, GaugeConfig, LoadModulation, SynthConfig, TachoConfig, TiltSource
from meshphase.synthetic.kinematics import SpeedProfile

__all__ = ["Scenario", "SCENARIOS", "get_scenario", "list_scenarios", "describe_scenarios",
           "register", "table1_gearset", "seed_rig_gearset", "seed_rig_speeds", "rig_gearset",
           "rig_speeds", "RIG_SCENARIOS", "ADVERSARIAL_SCENARIOS", "EXPECTS"]

FACE_WIDTH = 40e-3
SEED_RIG_SUN_RPM = 18.19
SEED_RIG_CARRIER_RPM = 1.06
#: what a scenario's processing must give (:attr:`Scenario.expect`)
EXPECTS = ("goal", "goal_or_flag")


@dataclass(frozen=True)
class Scenario:
    """A named scenario.

    Attributes
    ----------
    name : str
    description : str
    build : callable() -> SynthConfig
    tags : tuple of str
        e.g. "fast" (cheap at its default duration), "long", "noise", "facewidth", "errors",
        "speed" (speed variation), "rig" (the accuracy-matrix family), "adversarial" (a
        condition where measured phasing was once confident and wrong).
    expect : {"goal", "goal_or_flag"}
        What processing must give: "goal", the measured phasing within its accuracy target;
        "goal_or_flag", within the target or flagged unreliable by the run (a condition the
        angle model may not resolve, where a confident wrong answer is the one failure).
    """

    name: str
    description: str
    build: Callable[[], SynthConfig]
    tags: tuple = field(default_factory=tuple)
    expect: str = "goal"

    def __post_init__(self):
        if self.expect not in EXPECTS:
            raise ValueError(f"scenario {self.name!r}: expect must be one of {EXPECTS}, got "
                             f"{self.expect!r}")

    def config(self, **changes) -> SynthConfig:
        """A fresh config (with fields replaced, e.g. ``duration=2.0``)."""
        cfg = self.build()
        return cfg.with_(**changes) if changes else cfg


#: name -> Scenario
SCENARIOS: dict[str, Scenario] = {}


def register(scenario: Scenario) -> Scenario:
    """Add a scenario to the registry (ValueError if the name is taken)."""
    if not isinstance(scenario, Scenario):
        raise TypeError(f"scenario must be a Scenario, got {type(scenario).__name__}")
    if scenario.name in SCENARIOS:
        raise ValueError(f"scenario {scenario.name!r} is already registered")
    SCENARIOS[scenario.name] = scenario
    return scenario


def list_scenarios() -> list[str]:
    """Names of the registered scenarios, sorted."""
    return sorted(SCENARIOS)


def describe_scenarios() -> list[dict]:
    """One row per scenario: ``name``, ``description``, ``tags``, ``fs`` [Hz], ``duration`` [s],
    ``channels`` (for ``meshphase synth --list``)."""
    rows = []
    for name in list_scenarios():
        sc = SCENARIOS[name]
        cfg = sc.config()
        rows.append({"name": name, "description": sc.description, "tags": list(sc.tags),
                     "fs": cfg.fs, "duration": cfg.duration,
                     "channels": [g.name for g in cfg.gauges] + ([cfg.tacho.name] if cfg.tacho else [])})
    return rows


def get_scenario(name: str, **changes) -> SynthConfig:
    """Config of scenario ``name`` (ValueError listing the known names)."""
    if not isinstance(name, str):
        raise TypeError(f"scenario name must be a string, got {type(name).__name__}")
    if name not in SCENARIOS:
        raise ValueError(f"unknown scenario {name!r}; known: {', '.join(list_scenarios())}")
    return SCENARIOS[name].config(**changes)


# ----------------------------------------------------------------------------- building blocks

def table1_gearset() -> tuple[Gearset, Speeds]:
    """Seed 000 Table 1 gearset (face width 40 mm added) and its speeds [rad/s]."""
    g, sp, _ = table2_case(1)
    g = Gearset(g.z_sun, g.z_ring, g.z_planet, g.planet_angles, g.carrier_radius,
                direction=g.direction, name="seed000-table1", face_width=FACE_WIDTH)
    return g, sp


def seed_rig_gearset() -> Gearset:
    """The seed 000 rig as modelled here (see the module docstring for why)."""
    return Gearset.equally_spaced(25, 87, 31, 4, 112.5e-3, direction="cw",
                                  name="seed000-rig (differential, ring driven)",
                                  face_width=FACE_WIDTH)


def seed_rig_speeds(gearset: Gearset | None = None) -> Speeds:
    """Sun 18.19 r/min, carrier 1.06 r/min, ring by Willis (-3.862 r/min) [rad/s]."""
    g = seed_rig_gearset() if gearset is None else gearset
    return Speeds.kinematic(g, rpm_to_rad_s(SEED_RIG_SUN_RPM), rpm_to_rad_s(SEED_RIG_CARRIER_RPM))


def rig_gearset(z_sun: int = 25, z_ring: int = 87, z_planet: int = 29, planet_angles=None, *,
                direction: str = "cw", name: str = "seed000-table1-rig") -> Gearset:
    """The ``rig`` family's gearset: seed 000 Table 1 (Z 25/87/29, R_c 112.5 mm, face width
    40 mm); ``planet_angles`` [rad] default four at 90 deg."""
    if planet_angles is None:
        planet_angles = tuple(i * math.pi / 2.0 for i in range(4))
    return Gearset(z_sun, z_ring, z_planet, tuple(planet_angles), 112.5e-3, direction=direction,
                   name=name, face_width=FACE_WIDTH)


def rig_speeds(gearset: Gearset, sun_rpm: float = SEED_RIG_SUN_RPM, *, reverse: bool = False) -> Speeds:
    """Fixed-ring speeds [rad/s]: sun ``sun_rpm`` [r/min], carrier sun / (1 + Z_r / Z_s), ring
    exactly 0, planet by Willis (``w_p - w_c = -(Z_s / Z_p)(w_s - w_c)``); ``reverse`` turns
    every speed round."""
    sun = rpm_to_rad_s(sun_rpm)
    carrier = sun / (1.0 + gearset.z_ring / gearset.z_sun)
    planet = carrier - gearset.z_sun / gearset.z_planet * (sun - carrier)
    sgn = -1.0 if reverse else 1.0
    return Speeds(sun=sgn * sun, carrier=sgn * carrier, planet=sgn * planet, ring=0.0)


def _gauges(*, facewidth: bool = False) -> tuple:
    out = [GaugeConfig("sun", "sun", tooth=0, amplitude=150e-6, contact_ratio=1.6),
           GaugeConfig("ring", "ring", tooth=0, amplitude=100e-6, contact_ratio=1.8)]
    if facewidth:
        b = FACE_WIDTH
        for i, z in enumerate((-0.4 * b, 0.0, 0.4 * b)):
            out.append(GaugeConfig(f"sun_fw{i + 1}", "sun", tooth=5, face_position=z,
                                   amplitude=150e-6, contact_ratio=1.6))
        for i, z in enumerate((-0.4 * b, -0.2 * b, 0.0, 0.2 * b, 0.4 * b)):
            out.append(GaugeConfig(f"ring_fw{i + 1}", "ring", tooth=10, face_position=z,
                                   amplitude=100e-6, contact_ratio=1.8))
    return tuple(out)


def _table1(name, description, *, errors=None, duration=0.5, **kw) -> SynthConfig:
    g, sp = table1_gearset()
    return SynthConfig(name=name, description=description, gearset=g, speeds=sp, fs=51200.0,
                       duration=duration, gauges=_gauges(), errors=errors, tacho=TachoConfig(),
                       **kw)


def _seed_rig(name, description, *, duration=60.0, errors="case1", gauges=None, **kw) -> SynthConfig:
    g = seed_rig_gearset()
    if errors == "case1":
        errors = table2_case(1)[2]
    return SynthConfig(name=name, description=description, gearset=g, speeds=seed_rig_speeds(g),
                       fs=5120.0, duration=duration, gauges=gauges or _gauges(), errors=errors,
                       tacho=TachoConfig(), **kw)


#: acquisition of the rig family: 20 dB white noise, 50 Hz hum, slow drift, 24-bit ADC
_RIG_ACQ = Artefacts(snr_db=20.0, pink_fraction=0.0, drift_amplitude=8e-6, drift_time_constant=900.0,
                     hum_amplitude=2e-6, hum_frequency=50.0, adc_bits=24, adc_range=2e-3)
#: the rig family's default duration [s]
RIG_DURATION = 120.0


def _rig(name, description, *, speed=None, reverse=False, gearset=None, sun_rpm=SEED_RIG_SUN_RPM,
         **kw) -> SynthConfig:
    g = rig_gearset(direction="ccw" if reverse else "cw") if gearset is None else gearset
    kw = {"gauges": _gauges(), "artefacts": _RIG_ACQ, **kw}
    return SynthConfig(name=name, description=description, gearset=g,
                       speeds=rig_speeds(g, sun_rpm, reverse=reverse), fs=5120.0,
                       duration=RIG_DURATION, errors=table2_case(1)[2],
                       speed=SpeedProfile() if speed is None else speed, tacho=TachoConfig(), **kw)


#: artefacts of a good real rig: 24-bit DAQ, 30 dB SNR with some 1/f, slight drift and hum
_REALISTIC = Artefacts(snr_db=30.0, pink_fraction=0.3, pink_fmin=0.05, drift_amplitude=8e-6,
                       drift_time_constant=900.0, hum_amplitude=2e-6, hum_frequency=50.0,
                       adc_bits=24, adc_range=2e-3)


# ----------------------------------------------------------------------------- the registry

register(Scenario(
    "table1_high_speed",
    "Seed 000 Table 1 gearset at its Table 1 speeds (w_s 448, w_c 100 rad/s, fixed ring), no "
    "errors, 51.2 kHz, sun + ring gauges + carrier tacho; clean.",
    lambda: _table1("table1_high_speed", "Seed 000 Table 1 gearset at high speed, ideal"),
    ("fast",)))

register(Scenario(
    "table1_high_speed_ccw",
    "As table1_high_speed with every speed reversed (counter-clockwise planets): pass order "
    "and phasing signs flip.",
    lambda: (lambda g, sp: SynthConfig(
        name="table1_high_speed_ccw", description="Table 1 gearset, reversed rotation",
        gearset=Gearset(g.z_sun, g.z_ring, g.z_planet, g.planet_angles, g.carrier_radius,
                        direction="ccw", name=g.name, face_width=g.face_width),
        speeds=Speeds(-sp.sun, -sp.carrier, -sp.planet, -sp.ring), fs=51200.0, duration=0.5,
        gauges=_gauges(), tacho=TachoConfig()))(*table1_gearset()),
    ("fast",)))

for _case in (1, 2, 3):
    register(Scenario(
        f"table2_case{_case}",
        f"Seed 000 Table 1 gearset at high speed with Table 2 case {_case} shaft hole errors"
        + (" (normal tolerance bands: one realisation drawn with the seed)" if _case == 3 else "")
        + ", 51.2 kHz, sun + ring gauges + tacho; clean.",
        (lambda c: lambda: _table1(f"table2_case{c}", f"Table 1 gearset, Table 2 case {c} errors",
                                   errors=table2_case(c)[2]))(_case),
        ("fast", "errors")))

register(Scenario(
    "seed_rig",
    "The seed's rig: 5120 Hz, sun 18.19 r/min, carrier 1.06 r/min (ring driven at -3.862 r/min, "
    "Z 25/87/31, 4 planets), Table 2 case 1 errors, sun + ring gauges + tacho, 60 s; clean.",
    lambda: _seed_rig("seed_rig", "Seed 000 rig speeds, case 1 errors"),
    ("fast", "errors")))

register(Scenario(
    "noisy",
    "seed_rig at 20 dB SNR (40 % of the noise power 1/f from 0.05 Hz), thermal drift 20 µε "
    "(T 600 s), 50 Hz hum 5 µε, 24-bit ADC over +-2000 µε, 2 % random gauge gain errors.",
    lambda: _seed_rig("noisy", "seed rig with noise, drift, hum, 24-bit ADC, gain errors",
                      artefacts=Artefacts(snr_db=20.0, pink_fraction=0.4, pink_fmin=0.05,
                                          drift_amplitude=20e-6, drift_time_constant=600.0,
                                          hum_amplitude=5e-6, hum_frequency=50.0, adc_bits=24,
                                          adc_range=2e-3, gain_error_std=0.02)),
    ("fast", "noise")))

register(Scenario(
    "adc16_clipped",
    "seed_rig through a 16-bit ADC whose +-140 µε range clips the sun pulses, 60 Hz hum, "
    "35 dB SNR.",
    lambda: _seed_rig("adc16_clipped", "seed rig, 16-bit ADC clipping the sun gauge",
                      artefacts=Artefacts(snr_db=35.0, hum_amplitude=3e-6, hum_frequency=60.0,
                                          adc_bits=16, adc_range=140e-6)),
    ("fast", "noise")))

register(Scenario(
    "speed_ripple",
    "seed_rig with a slow speed ripple (4 % at 0.01 Hz plus 1.5 % at 0.025 Hz, slow against "
    "the 3.5 s relative sun revolution): engagement times follow the actual rotation angles.",
    lambda: _seed_rig("speed_ripple", "seed rig with speed ripple",
                      speed=SpeedProfile(ripple=((0.04, 0.01, 0.0), (0.015, 0.025, 1.0)))),
    ("fast", "speed")))

register(Scenario(
    "speed_ripple_fast",
    "Stress case: seed_rig with a fast speed ripple (5 % at 0.1 Hz plus 2 % at 0.37 Hz, "
    "comparable with the 3.5 s relative sun revolution), faster than four passes per "
    "revolution can resolve; processing must say so rather than report clean phasing.",
    lambda: _seed_rig("speed_ripple_fast", "seed rig with fast speed ripple",
                      speed=SpeedProfile(ripple=((0.05, 0.1, 0.0), (0.02, 0.37, 1.0)))),
    ("fast", "speed", "stress")))

register(Scenario(
    "speed_ramp",
    "seed_rig with the drive speeding up 20 % over 60 s (ramp 0.33 %/s) plus 1 % ripple at "
    "0.02 Hz.",
    lambda: _seed_rig("speed_ramp", "seed rig with a speed ramp",
                      speed=SpeedProfile(ramp_rate=0.2 / 60.0, ripple=((0.01, 0.02, 0.0),))),
    ("fast", "speed")))

register(Scenario(
    "gaps",
    "seed_rig with acquisition gaps (one per 20 s on average, mean 0.2 s) and single dropped "
    "samples (0.5 per s), NaN in every channel, 30 dB SNR.",
    lambda: _seed_rig("gaps", "seed rig with gaps and dropped samples",
                      artefacts=Artefacts(snr_db=30.0, gap_rate=0.05, gap_length=0.2,
                                          dropout_rate=0.5)),
    ("fast", "gaps")))

register(Scenario(
    "facewidth_offcentre",
    "seed_rig with 3 face-width gauges across sun tooth 5 and 5 across ring tooth 10 "
    "(b = 40 mm), load centroids off centre: Z_S = -2 mm, Z_R = +3, +2.5, +3.5, +3 mm per "
    "planet (linear load), unequal load sharing 1.08/0.95/1.02/0.95.",
    lambda: _seed_rig("facewidth_offcentre", "face-width gauges, off-centre load",
                      gauges=_gauges(facewidth=True), centroid_sun=-2e-3,
                      centroid_ring=(3e-3, 2.5e-3, 3.5e-3, 3e-3),
                      load_sharing=(1.08, 0.95, 1.02, 0.95)),
    ("fast", "facewidth")))

register(Scenario(
    "facewidth_partial",
    "As facewidth_offcentre with the ring load run off the face (Z_R = 9 mm > b/6): partial "
    "contact, triangular load, the gauges at the unloaded end read nothing.",
    lambda: _seed_rig("facewidth_partial", "face-width gauges, partial contact",
                      gauges=_gauges(facewidth=True), centroid_sun=-2e-3, centroid_ring=9e-3),
    ("fast", "facewidth")))

register(Scenario(
    "facewidth_tilt",
    "Face-width gauges with the load centroids from the coupled bearing tilt solve (seed 001 "
    "Case 1 planet geometry, k_t = 8.8e4 N·m/rad, 1378.7 N·m, the gearset's 40 mm face): "
    "Z_S < 0 < Z_R, equal on every planet.",
    lambda: _seed_rig("facewidth_tilt", "face-width gauges, centroids from the tilt solve",
                      gauges=_gauges(facewidth=True), tilt=TiltSource("1", k_tilt=8.8e4)),
    ("fast", "facewidth")))

register(Scenario(
    "rig_realistic",
    "seed_rig with everything a good rig records: 30 dB SNR (30 % 1/f), drift, hum, 24-bit "
    "ADC, 1 % gain errors, 3 % slow speed ripple (0.01 Hz).",
    lambda: _seed_rig("rig_realistic", "seed rig, realistic acquisition",
                      artefacts=Artefacts(**{**_REALISTIC.to_dict(), "hum_harmonics": (1.0, 0.0, 0.25),
                                             "gain_error_std": 0.01}),
                      speed=SpeedProfile(ripple=((0.03, 0.01, 0.0),))),
    ("fast", "noise", "speed")))

register(Scenario(
    "one_hour",
    "One hour of the seed rig with realistic acquisition (30 dB SNR, 1/f, drift, hum, 24-bit): "
    "18.4 MSamples per channel, for benchmarks; written block by block (flat memory).",
    lambda: _seed_rig("one_hour", "one hour of the seed rig, realistic acquisition",
                      duration=3600.0, artefacts=_REALISTIC),
    ("long", "noise", "bench")))


# ----------------------------------------------------------------------------- the rig family

def _ripple(member, amplitude=0.01, ramp=0.0):
    return SpeedProfile.shaft_ripple(member, amplitude, 1, 0.0, ramp_rate=ramp / RIG_DURATION)


#: p_n of the three-planet layout: psi_n = 2 pi p_n / (Z_s + Z_r)
RIG_3PLANETS_P = (0, 36, 75)

_RIG_COMMON = ("seed 000 Table 1 gearset (Z 25/87/29, 4 planets at 90 deg) on a fixed-ring rig, "
               "sun 18.19 r/min, carrier 4.0603 r/min, 5120 Hz, Table 2 case 1 errors, 20 dB "
               "white noise, 50 Hz hum, drift, 24-bit ADC, sun + ring gauges + tacho, 2 min")

_RIG = {
    "rig_steady": ("No speed variation: the reference of the rig family; " + _RIG_COMMON + ".",
                   lambda n, d: _rig(n, d), ("rig",)),
    "rig_ripple1": ("rig_steady with 1 % speed ripple once per carrier revolution (locked to "
                    "the carrier angle).", lambda n, d: _rig(n, d, speed=_ripple("carrier")),
                    ("rig", "speed")),
    "rig_ripple3": ("rig_steady with 3 % speed ripple once per carrier revolution.",
                    lambda n, d: _rig(n, d, speed=_ripple("carrier", 0.03)), ("rig", "speed")),
    "rig_ripple_sun": ("rig_steady with 1 % speed ripple once per absolute sun revolution "
                       "(3.3 s at 18.19 r/min).", lambda n, d: _rig(n, d, speed=_ripple("sun")),
                       ("rig", "speed")),
    "rig_ripple_planet": ("rig_steady with 1 % speed ripple once per planet revolution "
                          "relative to the carrier (4.9 s): processing must meet the target "
                          "or flag the phasing unreliable.",
                          lambda n, d: _rig(n, d, speed=_ripple("planet")),
                          ("rig", "speed", "adversarial")),
    "rig_ramp_up": ("rig_ripple1 plus a +10 % speed change over the 2 min (ramp in time, the "
                    "ripple stays locked to the carrier angle).",
                    lambda n, d: _rig(n, d, speed=_ripple("carrier", ramp=0.10)), ("rig", "speed")),
    "rig_ramp_down": ("rig_ripple1 plus a -10 % speed change over the 2 min.",
                      lambda n, d: _rig(n, d, speed=_ripple("carrier", ramp=-0.10)),
                      ("rig", "speed")),
    "rig_ccw": ("rig_ripple1 with every speed reversed (counter-clockwise planets, direction "
                "'ccw'): pass order and phasing signs flip, the ripple follows the reversed "
                "carrier angle.", lambda n, d: _rig(n, d, speed=_ripple("carrier"), reverse=True),
                ("rig", "speed")),
    "rig_3planets": ("rig_ripple1 with three unequally spaced planets that can be assembled "
                     "(psi_n = 2 pi p_n / 112, p_n = 0, 36, 75: 0, 115.7, 241.1 deg; mixed "
                     "phasing).",
                     lambda n, d: _rig(n, d, speed=_ripple("carrier"), gearset=rig_gearset(
                         planet_angles=tuple(2.0 * math.pi * p / 112 for p in RIG_3PLANETS_P),
                         name="seed000-table1-rig, 3 unequal planets")), ("rig", "speed")),
    "rig_5planets": ("rig_ripple1 on a Z 25/85/30 gearset with five equally spaced planets "
                     "(carrier 18.19 / 4.4 r/min).",
                     lambda n, d: _rig(n, d, speed=_ripple("carrier"), gearset=rig_gearset(
                         25, 85, 30, tuple(2.0 * math.pi * i / 5 for i in range(5)),
                         name="rig 25/85/30, 5 planets")), ("rig", "speed")),
}

#: names of the rig family (the accuracy matrix), in a sensible reading order
RIG_SCENARIOS = tuple(_RIG)

for _name, (_desc, _build, _tags) in _RIG.items():
    register(Scenario(_name, _desc, (lambda n, d, b: lambda: b(n, d))(_name, _desc, _build), _tags,
                      "goal_or_flag" if "adversarial" in _tags else "goal"))


# ----------------------------------------------------------------------------- adversarial rig cases

def _five_planets() -> Gearset:
    return rig_gearset(25, 85, 30, tuple(2.0 * math.pi * i / 5 for i in range(5)),
                       name="rig 25/85/30, 5 planets")


def _units_gauges(units: str) -> tuple:
    return tuple(GaugeConfig(g.name, g.gear, g.tooth, g.face_position, g.amplitude, g.contact_ratio,
                             g.side_lobe, g.skew, units=units) for g in _gauges())


_ADVERSARIAL = {
    "rig_5planets_ripple_planet": (
        "rig_ripple_planet on the Z 25/85/30 gearset with five equally spaced planets: 1 % "
        "speed ripple once per planet revolution relative to the carrier.",
        lambda n, d: _rig(n, d, speed=_ripple("planet"), gearset=_five_planets()),
        ("rig", "speed", "adversarial"), "goal_or_flag"),
    "rig_fast_ripple1": (
        "rig_ripple1 with the sun at 120 r/min (carrier 26.8 r/min, mesh frequency 38.9 Hz, "
        "132 samples per mesh period): 1 % speed ripple once per carrier revolution.",
        lambda n, d: _rig(n, d, speed=_ripple("carrier"), sun_rpm=120.0),
        ("rig", "speed", "adversarial"), "goal_or_flag"),
    "rig_load_ripple": (
        "rig_steady with every pulse amplitude +-25 % once per carrier revolution (a torque "
        "ripple common to every planet, locked to the carrier angle).",
        lambda n, d: _rig(n, d, load_modulation=(LoadModulation(0.25, 1, 0.4),)),
        ("rig", "load", "adversarial"), "goal_or_flag"),
    "rig_microstrain": (
        "rig_steady with the gauge channels written in microstrain (unit string µε, "
        "samples 1e6 x the strain).",
        lambda n, d: _rig(n, d, gauges=_units_gauges("µε")),
        ("rig", "units", "adversarial"), "goal_or_flag"),
    "rig_clean": (
        "rig_steady without any acquisition artefact (no noise, hum, drift or ADC): a clean "
        "slow rig, where no data-quality warning is expected.",
        lambda n, d: _rig(n, d, artefacts=Artefacts()),
        ("rig", "adversarial"), "goal"),
}

#: names of the adversarial rig conditions (the accuracy table of ``meshphase bench processing``)
ADVERSARIAL_SCENARIOS = ("rig_ripple_planet",) + tuple(_ADVERSARIAL)

for _name, (_desc, _build, _tags, _expect) in _ADVERSARIAL.items():
    register(Scenario(_name, _desc, (lambda n, d, b: lambda: b(n, d))(_name, _desc, _build), _tags,
                      _expect))

register(Scenario(
    "rig_ripple_planet_encoder",
    "rig_ripple_planet with a 60-pulse encoder on the sun (input) shaft: it samples the mesh "
    "angle every 25 x 87 / (112 x 60) = 0.32 mesh cycles and sees the planet-rate ripple that "
    "the gauges and the once-per-turn tacho cannot tell from the planets' own terms.",
    lambda: _rig("rig_ripple_planet_encoder", "planet-rate ripple, 60-pulse sun encoder",
                 speed=_ripple("planet")).with_(encoder=EncoderConfig(shaft="input",
                                                                      pulses_per_rev=60)),
    ("rig", "speed", "encoder")))
