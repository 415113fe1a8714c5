"""The seed 000 rig's [gearset] and [speeds] tables as scene TOML, shared by the scene, CLI
and campaign tests (the same gearset the demo scene and the seed_rig scenario use)."""

SEED_RIG_GEARSET = """\
[gearset]
name = "seed 000 rig"
z_sun = 25
z_ring = 87
z_planet = 31
n_planets = 4
carrier_radius_mm = 112.5
face_width_mm = 40
direction = "cw"

[speeds]
sun_rpm = 18.19
carrier_rpm = 1.06
"""
