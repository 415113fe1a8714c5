"""The scene's ``[labels]`` table: a gear's planet 1 fixed as a shift along its pass order
(data_schemas/scene.md, "Fixing planet 1 in the scene"), checked before anything runs."""

import pytest
from seed_rig_toml import SEED_RIG_GEARSET

from meshphase.run.scene import SceneError, parse_scene, scene_schema_errors

BASE = 'results = ["ideal_phasing"]\n' + SEED_RIG_GEARSET


def test_labels_shifts_are_read():
    scene = parse_scene(BASE + "[labels]\nsun_shift = 1\nring_shift = 0\n")
    assert scene.labels == {"sun": 1, "ring": 0}
    assert parse_scene(BASE).labels == {}                       # no table: nothing pinned


def test_an_empty_labels_table_pins_nothing():
    assert parse_scene(BASE + "[labels]\n").labels == {}


@pytest.mark.parametrize("text, key, words", [
    ("sun_shift = 4", "labels.sun_shift", "below the number of planets (4)"),   # 4 planets
    ("ring_shift = -1", "labels.ring_shift", "minimum"),
    ("sun_shift = 1.5", "labels.sun_shift", "integer"),
    ("sun_shfit = 1", "labels.sun_shfit", "unknown key 'sun_shfit'"),
])
def test_bad_labels_name_the_key_and_the_line(text, key, words):
    full = BASE + "[labels]\n" + text + "\n"
    with pytest.raises(SceneError) as info:
        parse_scene(full, "/data/s.toml")
    e = info.value
    assert e.key == key and words in str(e), str(e)
    assert e.line == full.splitlines().index(text) + 1


def test_the_schema_knows_the_labels_table():
    assert scene_schema_errors({"labels": {"sun_shift": 2}}) == []
    bad = scene_schema_errors({"labels": {"sun_shift": "2", "other": 1}})
    assert len(bad) == 2
