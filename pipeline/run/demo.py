"""The embedded demo scene: seed 000 Table 1 teeth on the seed's rig with the ordinary 1 %
drive ripple, synthetic, with every recording result.

``meshphase demo`` writes this scene next to its outputs (so the run is reproducible with
``meshphase run``) and runs it.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["DEMO_SCENE", "demo_scene_path"]

DEMO_SCENE = """\
# meshphase demo: seed 000 Table 1 teeth on the seed's rig (5120 Hz, sun 18.19 r/min, ring held,
# so the carrier turns at 18.19 x 25/112 = 4.06 r/min), the ordinary 1 % drive ripple at the
# carrier rate, 20 dB white noise, 50 Hz hum, drift, Table 2 case 1 shaft hole errors and a
# carrier tacho; a synthetic recording with known truth; every recording result.
name = "meshphase demo: seed 000 gearset on the seed's rig, 1 % drive ripple"
results = ["ideal_phasing", "phasing", "load_sharing", "compare", "identify", "tolerance"]

[gearset]
name = "seed 000 Table 1 (Z 25/87/29, 4 planets, ring held)"
z_sun = 25
z_ring = 87
z_planet = 29
n_planets = 4
carrier_radius_mm = 112.5
face_width_mm = 40
direction = "cw"
profile_shift = true   # 25 + 2 x 29 = 83, not 87: the seed's gearset needs shifted profiles

[speeds]          # nominal, as typed [r/min]: the ring is held (Willis gives -3.4e-4 r/min,
sun_rpm = 18.19   # zero within what two values typed to 0.01 r/min can tell)
carrier_rpm = 4.06

[input]
synthetic = "rig_ripple1"
minutes = 2.0
seed = 2026

[tolerances]      # +-3 sigma bands [mm], angles uniform
e_sun_mm = 0.2
e_ring_mm = 0.2
e_planet_mm = 0.2
samples = 8192
sampler = "sobol"
seed = 1
"""


def demo_scene_path(out_dir) -> Path:
    """Write the demo scene into ``out_dir`` and return its path."""
    p = Path(out_dir) / "demo_scene.toml"
    p.write_text(DEMO_SCENE, encoding="utf-8")
    return p
