"""Spheres against fixed meshes in whole runs: scenes that name meshes, the `ramp` scene,
thin mesh walls at speed, tunnelling named by triangle, and recordings that keep meshes."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from physdbg import api
from physdbg.cli import app
from physdbg.errors import SceneError
from physdbg.events import KIND_MESH, Contacts
from physdbg.scene import parse_scene

runner = CliRunner()

PLATE = "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nf 1 2 3\nf 1 3 4\n"  # a 2 m square of no thickness


def _plate_scene(tmp_path, detection: str, speed: float, steps: int = 6) -> str:
    (tmp_path / "plate.obj").write_text(PLATE)
    scene = tmp_path / "plate.toml"
    scene.write_text(f"""
name = "plate"
dt = 0.01
steps = {steps}
detection = "{detection}"
gravity = [0.0, 0.0, 0.0]

[[meshes]]
name = "plate"
file = "plate.obj"

[[particles]]
position = [0.1, 0.2, 25.0]
velocity = [0.0, 0.0, {-speed}]
radius = 0.01
""")
    return str(scene)


class _Contacts:
    def __init__(self):
        self.rows = []

    def on_event(self, event):
        if isinstance(event, Contacts):
            self.rows += [(event.step, int(k), int(o)) for k, o in zip(event.kind, event.other, strict=True)]


def test_a_swept_sphere_at_1000_radii_a_step_never_passes_a_plate_of_no_thickness(tmp_path):
    seen = _Contacts()
    scene = api.load_scene(_plate_scene(tmp_path, "swept", 1000.0))  # 10 m a step, 1000 radii
    world = scene.build_world(seen)
    for dt in scene.step_lengths():
        world.step(dt)
    assert [(k, other) for _, k, other in seen.rows] in ([(KIND_MESH, 0)], [(KIND_MESH, 1)])
    assert seen.rows[0][0] == 2  # 24.99 m away at 10 m a step: the touch falls in the third step (events count from 0)
    assert world.state.positions[0, 2] > 0 and world.state.velocities[0, 2] == pytest.approx(1000.0)


def test_a_discrete_run_passes_the_plate_and_explain_names_the_triangle_and_step(tmp_path):
    recorded = tmp_path / "discrete.mcap"
    done = runner.invoke(app, ["record", _plate_scene(tmp_path, "discrete", 1000.0), "-o", str(recorded), "--no-rrd"])
    assert done.exit_code == 0, done.output
    explained = runner.invoke(app, ["explain", str(recorded)])
    assert explained.exit_code == 1, explained.output
    assert "sphere 0 went through mesh 'plate' triangle 0 with no contact" in explained.output \
        or "sphere 0 went through mesh 'plate' triangle 1 with no contact" in explained.output
    assert "step 3" in explained.output and "use detection = swept" in explained.output


def test_the_ramp_scene_comes_to_rest_on_its_meshes_within_the_contact_tolerance():
    scene = api.load_scene("ramp")
    world = scene.build_world()
    ends = [world.step(dt) for dt in scene.step_lengths()]
    end = ends[-1]
    # at rest: all three asleep in the valley, no contact for the last second
    assert end.counts.asleep == 3 and np.all(world.state.velocities == 0.0)
    assert all(e.counts.contacts == 0 for e in ends[-240:])
    assert end.max_overlap <= scene.settings.contact_tolerance
    # each ball rests in the valley, on both ramps: centre at r / cos(slope) above the crease
    slope = np.arctan(0.5 / 2.0)
    assert np.allclose(world.state.positions[:, 1], 0.1 / np.cos(slope), atol=1e-4)
    assert np.allclose(world.state.positions[:, 0], 0.0, atol=1e-3)


def test_a_recording_keeps_its_meshes_and_replays_bit_for_bit(tmp_path):
    recorded = tmp_path / "ramp.mcap"
    done = runner.invoke(app, ["record", "ramp", "-s", "duration=2", "-o", str(recorded), "--no-rrd",
                               "--detail", "contacts"])
    assert done.exit_code == 0, done.output
    assert "2 meshes (left 8, right 8 triangles)" in done.output
    info = runner.invoke(app, ["info", str(recorded)])
    assert info.exit_code == 0 and "2 meshes (left 8, right 8 triangles)" in info.output
    replay = runner.invoke(app, ["replay", str(recorded), "--verify"])
    assert replay.exit_code == 0, replay.output
    from physdbg import open_recording

    with open_recording(recorded) as rec:
        meshes = rec.header.walls.meshes
        assert meshes.names == ["left", "right"] and meshes.triangles == 16
        assert np.array_equal(meshes.corners, api.load_scene("ramp").walls.meshes.corners)
        hits = [k for k in range(1, rec.frames) if (rec.contacts(k).kind == KIND_MESH).any()]
        assert hits
        assert runner.invoke(app, ["diff", str(recorded), str(recorded)]).exit_code == 0


@pytest.mark.parametrize("table, field, message", [
    ('name = "m"', "meshes.0.shape", "give shape (a built-in shape) or file (an .obj or .stl file), not both or "
                                      "neither"),
    ('shape = "teapot"', "meshes.0.shape", "got 'teapot'; allowed: box, ramp, funnel, box-with-hole, paddle, icosphere"),
    ('file = "missing.obj"', "meshes.0.file", "missing.obj: no such file"),
    ('shape = "ramp"\nscale = 0', "meshes.0.scale", "0"),
    ('shape = "ramp"\ncolour = 3', "meshes.0.colour", "unknown field"),
])
def test_a_wrong_mesh_field_names_the_file_the_field_and_what_is_allowed(table, field, message):
    with pytest.raises(SceneError) as caught:
        parse_scene(f"dt = 0.01\nsteps = 1\n[[meshes]]\n{table}\n", "bad.toml")
    text = str(caught.value)
    assert text.startswith("bad.toml") and field in text and message in text, text


def test_check_predicts_tunnelling_through_a_thin_mesh_and_sends_it_to_swept_detection(tmp_path):
    done = runner.invoke(app, ["check", _plate_scene(tmp_path, "discrete", 1000.0)])
    assert done.exit_code == 1, done.output
    assert "1 mesh (plate 2 triangles)" in done.output and "contacts can happen" in done.output
    assert "can tunnel through mesh 'plate' (t/2 + r = 0.01 m): up to 10 m a step at 1e+03 m/s" in done.output
    assert "recommended integrator=exact detection=swept" in done.output


def test_the_foxglove_view_carries_each_mesh_as_a_triangle_list(tmp_path):
    from mcap_protobuf.decoder import DecoderFactory
    from mcap.reader import make_reader

    recorded = tmp_path / "ramp.mcap"
    done = runner.invoke(app, ["record", "ramp", "-s", "duration=0.1", "-o", str(recorded), "--no-rrd"])
    assert done.exit_code == 0, done.output
    with open(recorded, "rb") as f:
        first = next(message for _, _, _, message in make_reader(f, decoder_factories=[DecoderFactory()])
                     .iter_decoded_messages(topics=["/view/scene"]))
    meshes = {e.id: e for e in first.entities if e.id.startswith("mesh ")}
    assert set(meshes) == {"mesh left", "mesh right"}
    assert [len(t.points) for t in meshes["mesh left"].triangles] == [8 * 3]


def _closed_room(detection: str, count: int = 200, speed: float = 250.0) -> str:
    """A 10 m cube of triangles of no thickness (the shape box, scaled), ``count`` spheres
    of r = 5 cm inside at ``speed`` m/s in random directions (after Jolt's HighSpeed test)."""
    rng = np.random.default_rng(11)
    directions = rng.normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    lines = [f'dt = "1/60"\nsteps = 120\ndetection = "{detection}"\ngravity = [0.0, 0.0, 0.0]\n',
             '[[meshes]]\nname = "room"\nshape = "box"\nscale = [10.0, 10.0, 10.0]\n']
    for k in range(count):
        x = ((k % 8) - 3.5, ((k // 8) % 8) - 3.5, (k // 64) * 1.1 - 3.5)  # a lattice 1 m apart
        v = directions[k] * speed
        lines.append(f"[[particles]]\nposition = [{x[0]}, {x[1]}, {x[2]}]\nvelocity = [{v[0]}, {v[1]}, {v[2]}]\n"
                     "radius = 0.05\n")
    return "\n".join(lines)


def _escapes(detection: str) -> tuple[int, int]:
    """(spheres that ended a step outside the room, contacts with the room) over the run."""
    from physdbg.advisor import decide

    scene = decide(parse_scene(_closed_room(detection), "room.toml"))
    seen = _Contacts()
    world = scene.build_world(seen)
    out = np.zeros(scene.state.count, dtype=bool)
    for dt in scene.step_lengths():
        world.step(dt)
        out |= np.abs(world.state.positions).max(axis=1) > 5.0
    return int(out.sum()), sum(1 for _, kind, _ in seen.rows if kind == KIND_MESH)


def test_no_sphere_leaves_a_closed_mesh_room_at_250_m_s_in_swept_mode_and_many_do_in_discrete():
    """83 radii a step against walls of no thickness: the swept tests keep all 200 in for
    2 s (about 70 bounces each off the room's triangles: 500 m of path, 6.7 m between walls on
    average in a cube); discrete tests lose most."""
    escaped, bounces = _escapes("swept")
    assert escaped == 0 and bounces > 200 * 60
    escaped, _ = _escapes("discrete")
    assert escaped > 150


def test_highspeed_keeps_every_sphere_in_swept_mode_and_explain_names_each_escape_of_a_discrete_run(tmp_path):
    """The built-in scene at a tenth of its spheres and a fifth of its time (the whole
    scene: 0 of 5,000 escape over 10 s, docs/meshes.md)."""
    small = ["generate.count=500", "duration=2"]
    scene = api.load_scene("highspeed", small)
    world = scene.build_world()
    out = np.zeros(scene.state.count, dtype=bool)
    for dt in scene.step_lengths():
        world.step(dt)
        out |= np.abs(world.state.positions).max(axis=1) > 50.0
    assert not out.any()
    recorded = tmp_path / "discrete.mcap"
    done = runner.invoke(app, ["record", "highspeed", "-s", "generate.count=100", "-s", "duration=0.5", "-s",
                               "detection=discrete", "-o", str(recorded), "--no-rrd"])
    assert done.exit_code == 0, done.output
    explained = runner.invoke(app, ["explain", str(recorded), "--json", "--all"])
    findings = [f for f in json.loads(explained.output)["findings"] if f["kind"] == "tunnelling"]
    assert len({f["particles"][0] for f in findings}) > 90  # nearly every sphere, each named once at least
    first = findings[0]
    mesh, triangle = first["evidence"]["mesh"], first["evidence"]["triangle"]
    assert first["message"].startswith(f"sphere {first['particles'][0]} went through mesh '{mesh}' triangle "
                                       f"{triangle} with no contact")
    assert 0 <= triangle < 12 and first["advice"].startswith("use detection = swept")


def test_the_funnel_scene_pours_every_sphere_through_the_spout_with_a_clean_audit():
    done = runner.invoke(app, ["run", "funnel", "-s", "generate.count=60", "-s", "duration=2"])
    assert done.exit_code == 0, done.output
    assert "1 mesh (funnel 48 triangles)" in done.output and "audit       clean" in done.output
    scene = api.load_scene("funnel", ["generate.count=60", "duration=2"])
    world = scene.build_world()
    for dt in scene.step_lengths():
        end = world.step(dt)
    assert np.all(world.state.positions[:, 1] < 1.0)  # all below the spout, on the floor
    assert end.max_overlap <= scene.settings.contact_tolerance


def test_a_scene_s_degenerate_triangles_are_named_in_the_run_summary_not_as_a_python_warning(tmp_path):
    (tmp_path / "flat.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nf 1 2 3\nf 1 2 4\n")
    scene = tmp_path / "s.toml"
    scene.write_text('dt = 0.01\nsteps = 2\n[[meshes]]\nfile = "flat.obj"\n[[particles]]\n'
                     'position = [0.2, 0.2, 1.0]\nradius = 0.1\n')
    done = runner.invoke(app, ["run", str(scene)])
    assert done.exit_code == 0 and "Warning" not in done.output, done.output
    assert "meshes      " + str(tmp_path / "flat.obj") + ": skipped 1 degenerate triangle(s): line 6 (zero area)" \
        in done.output
