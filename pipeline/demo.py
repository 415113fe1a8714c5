"""The embedded demo scene: the seed 000 rig, synthetic, with every recording result.

``meshphase demo`` writes this scene next to its outputs (so the run is reproducible with
``meshphase run``) and runs it.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["DEMO_SCENE", "demo_scene_path"]

DEMO_SCENE = """\
# meshphase demo: the seed 000 rig (5120 Hz, sun 18.19 r/min, carrier 1.06 r/min), a synthetic
# recording with noise, drift, hum and Table 2 case 1 shaft hole errors; every recording result.
name = "meshphase demo: seed 000 rig"
results = ["ideal_phasing", "phasing", "load_sharing", "compare", "identify", "tolerance"]

[gearset]
name = "seed 000 rig (Z 25/87/31, 4 planets, ring driven)"
z_sun = 25
z_ring = 87
z_planet = 31
n_planets = 4
carrier_radius_mm = 112.5
face_width_mm = 40
direction = "cw"

[speeds]          # nominal hint [r/min]; the ring is driven at -3.862 r/min (differential)
sun_rpm = 18.19
carrier_rpm = 1.06

[input]
synthetic = "noisy"
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
