"""Scenes: built-ins, validation messages that name file/field/allowed, overrides, generators."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from physdbg.errors import SceneError, UnknownSceneError
from physdbg import open_recording
from physdbg.api import load_scene
from physdbg.scene import FIELDS, parse_scene
from physdbg.scenes import builtin_descriptions, builtin_names

EXPECTED = {"bounce", "bullet-wall", "cradle", "billiards", "rain", "gas", "rest", "ramp", "highspeed", "funnel"}

MINIMAL = """
dt = 0.01
steps = 3
[[particles]]
position = [0, 1, 0]
radius = 0.1
"""


def test_all_promised_scenes_are_built_in_with_a_description():
    assert EXPECTED <= set(builtin_names())
    for name, description in builtin_descriptions():
        assert description, name


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_every_built_in_scene_validates_and_steps(name):
    scene = load_scene(name)
    assert scene.name == name
    assert scene.steps and scene.steps > 0
    world = scene.build_world()
    for _ in range(3):
        stats = world.step(scene.dt)
        assert not stats.warnings
        assert stats.max_overlap <= scene.settings.contact_tolerance


def test_billiards_has_mixed_masses_and_an_immovable_post():
    scene = load_scene("billiards")
    inverse = scene.state.inverse_mass
    assert np.count_nonzero(inverse == 0) == 1
    assert len(set(inverse[inverse > 0].round(6))) >= 2


@pytest.mark.parametrize("count", [1, 50, 300])
def test_rain_generates_n_spheres_inside_the_box_without_overlap(count):
    scene = load_scene("rain", [f"generate.count={count}"])
    x, r = scene.state.positions, scene.state.radius
    assert len(x) == count
    assert np.all(x - r[:, None] >= 0) and np.all(x + r[:, None] <= 1.0)
    if count > 1:
        d = np.linalg.norm(x[:, None] - x[None], axis=-1) + np.eye(count) * 10
        assert d.min() >= 2 * r[0]
    speeds = np.linalg.norm(scene.state.velocities, axis=1)
    assert np.all((speeds >= 1.8 - 1e-12) & (speeds <= 2.2 + 1e-12))


def test_gas_box_has_the_requested_packing_fraction_and_zero_momentum():
    scene = load_scene("gas", ["generate.packing_fraction=0.3", "generate.count=125"])
    side = scene.walls.offsets[1] * -1  # x+ wall: n = -x, offset = -side
    volume = 125 * 4 / 3 * math.pi * 0.05**3
    assert volume / side**3 == pytest.approx(0.3)
    np.testing.assert_allclose(scene.state.velocities.sum(axis=0), 0.0, atol=1e-12)
    x, r = scene.state.positions, scene.state.radius
    d = np.linalg.norm(x[:, None] - x[None], axis=-1) + np.eye(125) * 10
    assert d.min() >= 2 * r[0]


def test_same_seed_same_scene_other_seed_other_scene():
    a = load_scene("rain", ["seed=3"]).state.positions
    b = load_scene("rain", ["seed=3"]).state.positions
    c = load_scene("rain", ["seed=4"]).state.positions
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_building_a_world_leaves_the_scene_untouched():
    scene = load_scene("bounce")
    before = scene.state.positions.copy()
    world = scene.build_world()
    world.step(0.1)
    np.testing.assert_array_equal(scene.state.positions, before)


# ----------------------------------------------------------------------------- overrides
def test_overrides_reach_settings_tables_and_arrays():
    scene = load_scene("bounce", ["integrator=verlet", "particles.0.radius=0.2", "gravity=[0, -3.7, 0]",
                                  'dt="1/7"', "detection=sampled", "samples=9"])
    assert scene.settings.integrator == "verlet"
    assert scene.state.radius[0] == 0.2
    assert scene.settings.gravity == (0.0, -3.7, 0.0)
    assert scene.dt == 1 / 7
    assert scene.settings.samples == 9


def test_overriding_steps_replaces_duration_and_back():
    assert load_scene("bounce", ["steps=7"]).steps == 7
    scene = load_scene("bullet-wall", ["duration=1.0"])
    assert scene.duration == 1.0 and scene.steps == 10


def test_fraction_dt_and_duration_give_whole_steps():
    scene = load_scene("bounce")
    assert scene.dt == 1 / 60 and scene.steps == 300


@pytest.mark.parametrize("override, field, words", [
    ("integrator=rk4", "integrator", "allowed: euler, semi-implicit, verlet, exact"),
    ("integrater=verlet", "integrater", "did you mean 'integrator'"),
    ("drag=1.5", "drag", "<= 1"),
    ("particles.3.radius=1", "particles.3", "index must be 0..0"),
    ("particles.0.radius=-1", "particles.0.radius", ">= 1e-12"),
    ("particles.0.restitution=2", "particles.0.restitution", "<= 1"),
    ("samples=2.5", "samples", "an integer"),
    ("steps=1e6", "steps", "got 1000000.0, a float; expected an integer >= 1 and <= 1e+12, written without a "
                           "decimal point or exponent (such as 1000000)"),
    ("dt=0", "dt", "seconds > 0"),
    ("dt=fast", "dt", '"real"'),
    ("gravity=[1, 2]", "gravity", "[x, y, z]"),
    ("rapid_contact_time=-1", "rapid_contact_time", ">= 0"),
    ("rapid_contact_rule=elastic", "rapid_contact_rule", "allowed: hold, tc"),
    ("max_contacts_per_step=-1", "max_contacts_per_step", "an integer >= 0"),
    ("mesh_search=dual", "mesh_search", "allowed: auto, walk, together"),
])
def test_bad_overrides_name_the_field_and_what_is_allowed(override, field, words):
    with pytest.raises(SceneError) as info:
        load_scene("bounce", [override])
    message = str(info.value)
    assert "built-in scene 'bounce'" in message
    assert f"field '{field}'" in message
    assert words in message


def test_override_without_equals_is_explained():
    with pytest.raises(SceneError, match="key=value"):
        load_scene("bounce", ["integrator"])


def test_override_error_says_it_came_from_the_command_line():
    with pytest.raises(SceneError, match=r"--set drag=7"):
        load_scene("bounce", ["drag=7"])


# ----------------------------------------------------------------------------- files
def _write(tmp_path, text, name="scene.toml"):
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def test_scene_file_errors_name_the_file_and_field(tmp_path):
    path = _write(tmp_path, MINIMAL + "[[planes]]\nnormal = [0, 0, 0]\n")
    with pytest.raises(SceneError) as info:
        load_scene(path)
    assert str(info.value).startswith(path)
    assert "planes.0.normal" in str(info.value)


def test_unknown_fields_list_what_is_allowed(tmp_path):
    path = _write(tmp_path, MINIMAL.replace("radius", "raduis"))
    with pytest.raises(SceneError) as info:
        load_scene(path)
    assert "particles.0.raduis" in str(info.value)
    assert "did you mean 'particles.0.radius'" in str(info.value)


def test_invalid_toml_is_reported_with_the_file(tmp_path):
    path = _write(tmp_path, "dt = = 3")
    with pytest.raises(SceneError, match="not valid TOML"):
        load_scene(path)


def test_unknown_scene_suggests_the_nearest_name():
    with pytest.raises(UnknownSceneError, match="Did you mean 'bounce'"):
        load_scene("bounse")


def test_unreadable_scene_files_are_errors_not_tracebacks(tmp_path):
    with pytest.raises(UnknownSceneError, match="directory"):
        load_scene(str(tmp_path))
    binary = tmp_path / "binary.toml"
    binary.write_bytes(b"\xff\xfe\x00\x81")
    with pytest.raises(UnknownSceneError, match="cannot read"):
        load_scene(str(binary))


@pytest.mark.parametrize("text, field", [
    ("dt = 0.1\n", "steps"),
    ("steps = 3\n", "dt"),
    ("dt = 0.1\nsteps = 3\nduration = 1.0\n", "duration"),
    (MINIMAL + "[[particles]]\nposition = [0,0,0]\nradius = 1\nmass = 1\ninverse_mass = 1\n", "particles.1.mass"),
    (MINIMAL + "[[particles]]\nposition = [0,0,0]\nradius = 1\ninverse_mass = 0\nvelocity = [1,0,0]\n",
     "particles.1.velocity"),
    (MINIMAL + "[box]\nmin = [0,0,0]\nmax = [1,0,1]\n", "box.max"),
    (MINIMAL + "[generate]\nkind = \"rain\"\ncount = 3\nradius = 0.1\n", "box"),
    (MINIMAL + "[box]\nmin = [0,0,0]\nmax = [1,1,1]\n[generate]\nkind = \"rain\"\ncount = 5000\nradius = 0.1\n",
     "generate.count"),
    (MINIMAL + "[generate]\nkind = \"gas\"\ncount = 3\nradius = 0.1\npacking_fraction = 0.6\n",
     "generate.packing_fraction"),
    (MINIMAL + "[[planes]]\nnormal = [0, 1, 0]\nthickness = 0.1\n", "planes.0.thickness"),
])
def test_inconsistent_scenes_are_rejected_with_the_field(text, field):
    with pytest.raises(SceneError) as info:
        parse_scene(text, "x.toml")
    assert f"field '{field}'" in str(info.value)


def test_every_field_has_a_description():
    for table, fields in FIELDS.items():
        for name, text in fields.items():
            assert text, f"{table}.{name}"


def test_a_misspelt_field_gets_the_likely_fix_not_every_field():
    """A misspelt field listed all 33 top-level fields; now the close match, or where they are."""
    with pytest.raises(SceneError) as info:
        load_scene("bounce", ["restitutoin_rule=min"])
    assert "did you mean 'restitution_rule'? (every field: docs/scenes.md)" in str(info.value)
    assert "allowed:" not in str(info.value)
    with pytest.raises(SceneError) as info:
        load_scene("bounce", ["zzz=1"])
    assert "fields allowed here are listed in docs/scenes.md (tables among them: particles, planes" in str(info.value)
    with pytest.raises(SceneError, match="unknown field; allowed: name, normal, offset, restitution"):
        load_scene("bounce", ["planes.0.zzz=1"])


def test_the_old_name_of_the_contact_budget_is_still_read(tmp_path):
    """max_events_per_step (it counted contacts) is read as max_contacts_per_step: in a
    file, in --set, and in a recording made under the old name; a file with both is refused."""
    text = 'steps = 3\ndt = 0.01\nmax_events_per_step = 7\n[[particles]]\nposition = [0, 0, 0]\nradius = 0.1\n'
    assert parse_scene(text, "old.toml").settings.max_contacts_per_step == 7
    assert parse_scene(text, "old.toml", ["max_events_per_step=9"]).settings.max_contacts_per_step == 9
    assert load_scene("cradle", ["max_events_per_step=2"]).settings.max_contacts_per_step == 2
    with pytest.raises(SceneError) as err:
        parse_scene("max_contacts_per_step = 8\n" + text, "both.toml")
    assert "max_events_per_step is the old name of max_contacts_per_step; give one of them, not both" in str(err.value)
    # the CI goldens were recorded under the old name: read, their settings say the new one
    golden = Path(__file__).resolve().parents[1] / "recordings" / "ci" / "rain.mcap"
    with open_recording(golden) as rec:
        assert "max_contacts_per_step" in rec.meta["settings"] and "max_events_per_step" not in rec.meta["settings"]


def test_each_field_has_one_rule_and_every_engine_setting_is_read():
    """The rules tables (scene.py) and the field descriptions name the same fields, and the
    settings rules cover every Settings field (max_memory is a top-level rule): a new
    setting without a rule fails here, not in a user's scene."""
    import dataclasses

    from physdbg.engine.state import Settings
    from physdbg.scene import (GENERATE_FIELDS, GENERATE_RULES, MESH_FIELDS, MESH_RULES, PARTICLE_FIELDS,
                               PARTICLE_RULES, PLANE_FIELDS, PLANE_RULES, SETTING_RULES, TOP_FIELDS, TOP_RULES)

    assert set(SETTING_RULES) | {"max_memory"} == {f.name for f in dataclasses.fields(Settings)}
    assert set(SETTING_RULES) | set(TOP_RULES) <= set(TOP_FIELDS)
    assert set(PLANE_RULES) | {"name"} == set(PLANE_FIELDS)
    assert set(PARTICLE_RULES) | {"mass", "inverse_mass"} == set(PARTICLE_FIELDS)
    assert set(MESH_RULES) | {"shape", "file", "name", "scale", "pivot"} == set(MESH_FIELDS)
    assert set(GENERATE_RULES) | {"kind", "count", "packing_fraction", "min", "max"} == set(GENERATE_FIELDS)
