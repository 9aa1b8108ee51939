"""Spheres against fixed meshes in whole runs: scenes that name meshes, the `ramp` scene,
thin mesh walls at speed, tunnelling named by triangle, and recordings that keep meshes."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
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
    assert seen.rows[0][0] == 3  # 24.99 m away at 10 m a step: the touch falls in the third step
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


def test_balls_in_the_ramps_crease_never_gain_energy_and_stop_touching_without_sleeping():
    """Sleeping off, the balls lie in the crease for the run's second half: held on both
    faces, none may gain energy from one step to the next (a held contact kept while the
    ball left its face pushed it up the other: a rocking that never decayed, 6–8 contacts a
    step), and the contacts die out (docs/meshes.md "In a crease")."""
    scene = api.load_scene("ramp", ["sleep_speed=0"])
    world = scene.build_world()
    energy, contacts = [], []
    for dt in scene.step_lengths():
        end = world.step(dt)
        x, v = world.state.positions, world.state.velocities
        energy.append(0.5 * (v * v).sum(axis=1) - x @ np.asarray(scene.settings.gravity))
        contacts.append(end.counts.contacts)
    half = len(energy) // 2
    rise = np.diff(np.array(energy[half:]), axis=0)
    assert rise.max() < 0.0, rise.max()  # drag takes a little every step, contacts never give
    assert sum(contacts[-300:]) < 10 and end.counts.held == 6  # each ball on both faces


@pytest.mark.slow
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
    ('shape = "ramp"\nbounding_volume = "obbb"', "meshes.0.bounding_volume",
     "got 'obbb'; did you mean 'obb'? allowed: auto, aabb, sphere, obb"),
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


# ----------------------------------------------------------------------------- kinematic meshes
class _MeshContacts:
    def __init__(self):
        self.rows = []

    def on_event(self, event):
        if isinstance(event, Contacts):
            for i in np.flatnonzero(event.kind == KIND_MESH):
                self.rows.append((event.step, event.time_in_step[i], event.a[i], event.point[i].copy(),
                                  event.normal[i].copy(), event.velocity_a_before[i].copy(),
                                  event.velocity_a_after[i].copy(), event.velocity_b_before[i].copy(),
                                  event.restitution[i]))


def test_the_paddle_strikes_every_ball_and_its_surface_velocity_enters_each_impulse():
    """Every ball is struck; at each strike the recorded surface velocity is the paddle's
    own, ω × (point - pivot), computed here from the scene, and the impulse reverses the
    normal velocity *relative to that surface* by the restitution used."""
    scene = api.load_scene("paddle")
    meshes = scene.walls.meshes
    assert meshes.moving.tolist() == [True]
    seen = _MeshContacts()
    world = scene.build_world(seen)
    for dt in scene.step_lengths():
        end = world.step(dt)
    assert {int(a) for _s, _t, a, *_ in seen.rows} == set(range(scene.state.count))
    spin, pivot = meshes.angular_velocity[0], meshes.pivot[0]
    for step, when, _a, point, normal, before, after, surface, e in seen.rows:
        assert np.allclose(surface, np.cross(spin, point - pivot), rtol=1e-9, atol=1e-9)
        closing = -(before - surface) @ normal
        assert closing > 0
        assert (after - surface) @ normal == pytest.approx(e * closing, rel=1e-9, abs=1e-9)
    assert end.max_overlap <= scene.settings.contact_tolerance


def test_a_moving_mesh_sweeps_a_resting_ball_away_at_twice_its_surface_speed(tmp_path):
    """A wall of triangles sliding at 3 m/s into a ball at rest (no gravity, e = 1): the
    ball leaves at 6 m/s, the seed's impulse against a partner of infinite mass that
    moves; the contact is found at the instant the gap closes."""
    scene = tmp_path / "push.toml"
    scene.write_text('dt = 0.01\nsteps = 20\ngravity = [0.0, 0.0, 0.0]\n'
                     '[[meshes]]\nshape = "box"\nscale = [0.1, 1.0, 1.0]\nposition = [-0.5, 0.0, 0.0]\n'
                     'velocity = [3.0, 0.0, 0.0]\n'
                     '[[particles]]\nposition = [0.0, 0.0, 0.0]\nradius = 0.1\n')
    loaded = api.load_scene(str(scene))
    seen = _MeshContacts()
    world = loaded.build_world(seen)
    for dt in loaded.step_lengths():
        world.step(dt)
    assert len(seen.rows) == 1
    step, when, *_ = seen.rows[0]
    # the box's face (x = -0.45) meets the ball (x = -0.1) after 0.35 m at 3 m/s
    assert (step - 1) * 0.01 + when == pytest.approx(0.35 / 3.0, rel=1e-9)  # step k starts at (k-1)·dt
    assert world.state.velocities[0] == pytest.approx([6.0, 0.0, 0.0], rel=1e-12)


def test_a_discrete_paddle_run_is_tunnelling_by_the_paddle_named_by_explain(tmp_path):
    recorded = tmp_path / "paddle.mcap"
    done = runner.invoke(app, ["record", "paddle", "-s", "detection=discrete", "-s", "duration=0.3", "-o",
                               str(recorded), "--no-rrd"])
    assert done.exit_code == 0, done.output
    explained = runner.invoke(app, ["explain", str(recorded), "--json", "--all"])
    findings = [f for f in json.loads(explained.output)["findings"] if f["kind"] == "tunnelling"]
    assert findings
    first = findings[0]
    assert first["message"].startswith(f"mesh 'paddle' triangle {first['evidence']['triangle']} (turns at 1080 "
                                       f"deg/s (3 rev/s) about [0, 0.12, 0]) swept through sphere "
                                       f"{first['particles'][0]} with no contact")
    assert first["advice"].startswith("use detection = swept")
    swept = runner.invoke(app, ["run", "paddle", "-s", "duration=0.3"])
    assert swept.exit_code == 0 and "audit       clean" in swept.output, swept.output
    assert "meshes      'paddle' turns at 1080 deg/s (3 rev/s) about [0, 0.12, 0]" in swept.output


def test_a_kinematic_mesh_recording_keeps_its_motion_and_replays_bit_for_bit(tmp_path):
    recorded = tmp_path / "paddle.mcap"
    done = runner.invoke(app, ["record", "paddle", "-s", "duration=0.5", "-o", str(recorded), "--no-rrd"])
    assert done.exit_code == 0, done.output
    assert runner.invoke(app, ["replay", str(recorded), "--verify"]).exit_code == 0
    from physdbg import open_recording

    with open_recording(recorded) as rec:
        meshes = rec.header.walls.meshes
        scene = api.load_scene("paddle").walls.meshes
        assert np.array_equal(meshes.angular_velocity, scene.angular_velocity)
        assert np.array_equal(meshes.pivot, scene.pivot) and np.array_equal(meshes.corners, scene.corners)
    assert runner.invoke(app, ["diff", str(recorded), str(recorded)]).exit_code == 0
    # the Foxglove view poses the paddle every frame where it is (3 rev/s: 18 degrees a step)
    from mcap_protobuf.decoder import DecoderFactory
    from mcap.reader import make_reader

    with open(recorded, "rb") as f:
        poses = [e.triangles[0].pose for _, _, _, message in make_reader(f, decoder_factories=[DecoderFactory()])
                 .iter_decoded_messages(topics=["/view/scene"]) for e in message.entities if e.id == "mesh paddle"]
    assert len(poses) == 31  # the first frame and each of 30 steps
    turn = 2 * np.degrees(np.arccos(np.clip([p.orientation.w for p in poses], -1, 1)))
    assert turn[0] == 0.0 and turn[1] == pytest.approx(18.0)


def test_a_box_carried_into_a_moving_mesh_s_frame_finds_every_triangle_it_meets_in_the_step():
    """colliders/mesh.frame_box: a mesh's tree is never refitted; a world box asked of it is
    carried into its run-time-0 frame and grown by the motion over the step. Every triangle
    that meets the world box at any sampled instant of the step is found, for the
    paddle turning 18 degrees a step, a faster drifting one, and one past a half turn a step."""
    from physdbg.engine.colliders.mesh import MeshGeometry, place, reachable
    from physdbg.engine.state import Meshes, Walls

    scene = api.load_scene("paddle")
    paddle = scene.walls.meshes
    fast = Meshes(paddle.names, paddle.restitution, paddle.corners, paddle.mesh_of, paddle.sources, [],
                  np.array([[0.7, 0.0, -0.4]]), paddle.angular_velocity * 4, paddle.pivot)
    spinning = Meshes(paddle.names, paddle.restitution, paddle.corners, paddle.mesh_of, paddle.sources, [],
                      None, paddle.angular_velocity * 12, paddle.pivot)  # 216 degrees a step: past a half turn
    rng = np.random.default_rng(11)
    for meshes in (paddle, fast, spinning):
        group = tuple(MeshGeometry.of(Walls(meshes=meshes)))
        dt, start = 1 / 60, 0.3
        assert place(group, meshes, start, dt) == 1
        centre = rng.uniform(-1.6, 1.6, (300, 3)) * [1, 0.1, 1] + [0, 0.12, 0]
        size = rng.uniform(0.0, 0.1, (300, 3))
        lo, hi = centre - size, centre + size
        sphere, triangle = reachable(lo, hi, group)
        found = set(zip(sphere.tolist(), triangle.tolist()))
        # points of each triangle (corners, edges, inside): one in a box means the triangle meets it
        weights = np.array([(a, b, 6 - a - b) for a in range(7) for b in range(7 - a)]) / 6.0
        for tau in np.linspace(0.0, dt, 13):
            points = np.einsum("pc,tcx->tpx", weights, meshes.placed(start + tau)[0])  # (T, P, 3)
            inside = np.all((points[None] >= lo[:, None, None]) & (points[None] <= hi[:, None, None]), axis=3)
            assert set(zip(*np.nonzero(inside.any(axis=2)))) <= found, tau


def test_the_tree_the_views_draw_is_the_tree_the_engine_walks():
    """Each mesh's tree is built once, by the scene's mesh set (engine/mesh/mesh_set.py):
    its pre-order layout is each mesh's tree (MeshTree, the one the Rerun view draws by
    level and volume) node for node (the same boxes, the same triangle at each leaf, the
    same depths and parents), and the engine's collider group walks the set's own arrays."""
    from physdbg.engine.colliders.mesh import MeshGeometry

    for name in ("funnel", "paddle", "ramp"):
        scene = api.load_scene(name)
        meshes = scene.walls.meshes
        trees = meshes.mesh_set
        assert meshes.mesh_set is trees  # built once, kept
        for k, tree in enumerate(trees.trees):
            nodes, order, depth, stack = tree.nodes, [], [], [(int(tree.nodes.root), 0)]
            while stack:
                q, d = stack.pop()
                order.append(q)
                depth.append(d)
                if nodes.left[q] >= 0:
                    stack += [(int(nodes.right[q]), d + 1), (int(nodes.left[q]), d + 1)]
            mine = trees.nodes_of(k)
            assert np.array_equal(trees.box_lo[mine], nodes.lo[order])
            assert np.array_equal(trees.box_hi[mine], nodes.hi[order])
            drawn = [tree.leaf_triangle(q) + int(meshes.first[k]) if nodes.left[q] < 0 else -1 for q in order]
            assert trees.leaf_triangle[mine].tolist() == drawn
            assert trees.depth[mine].tolist() == depth and np.all(trees.node_mesh[mine] == k)
            inner = mine[trees.leaf_triangle[mine] < 0]
            assert np.all(trees.parent[inner + 1] == inner) and np.all(trees.parent[trees.skip[inner + 1]] == inner)
        group = MeshGeometry.of(scene.walls)
        assert group.box_lo is trees.box_lo and group.leaf_triangle is trees.leaf_triangle
        assert group.corners is not meshes.corners  # each group's placement is its own


def test_a_recording_builds_each_mesh_tree_once(tmp_path, monkeypatch):
    """`physdbg record funnel` with the Rerun view, the Foxglove view and the audit on builds
    each of the scene's mesh trees once (its mesh set), not once per reader (the kernels'
    warm-up walks a two-triangle mesh of its own)."""
    from physdbg.engine.mesh import mesh_set

    built = []
    real = mesh_set.build_mesh_tree
    monkeypatch.setattr(mesh_set, "build_mesh_tree", lambda vertices, *a, **k: built.append(len(vertices))
                        or real(vertices, *a, **k))
    meshes = api.load_scene("funnel").walls.meshes
    sizes = [3 * int(np.count_nonzero(meshes.mesh_of == k)) for k in range(len(meshes))]
    built.clear()
    done = runner.invoke(app, ["record", "funnel", "-o", str(tmp_path / "f.mcap"), "--detail", "full",
                               "-s", "duration=0.1"])
    assert done.exit_code == 0, done.output
    assert (tmp_path / "f.rrd").exists() and "Foxglove view channels written" in done.output
    assert sizes and all(size > 6 for size in sizes)
    assert [size for size in built if size > 6] == sizes


def test_the_reference_descent_reaches_exactly_the_triangles_whose_boxes_meet():
    """mesh_view.search (the reference walk, a stack in Python, that the recorded search is
    checked against) on the engine's own tree finds exactly the triangles whose boxes meet
    a sphere's box carried into the mesh's frame (brute force), and its search tree links every visited pair
    to the pair it descended from."""
    from physdbg.record import mesh_view

    scene = api.load_scene("paddle")
    meshes = scene.walls.meshes
    rng = np.random.default_rng(5)
    x0 = rng.uniform(-1.5, 1.5, (40, 3)) * [1, 0.1, 1] + [0, 0.1, 0]
    x1 = x0 + rng.normal(0, 0.2, (40, 3))
    radius = np.full(40, 0.1)
    lo, hi = mesh_view.path_boxes(x0, x1, radius)
    found = mesh_view.search(meshes, lo, hi, 0.1, 1 / 60)
    from physdbg.engine.colliders.mesh import MeshGeometry, frame_box, place

    group = tuple(MeshGeometry.of(scene.walls))
    place(group, meshes, 0.1, 1 / 60)
    trees = meshes.mesh_set
    box_lo, box_hi, leaf = trees.box_lo, trees.box_hi, trees.leaf_triangle
    leaves = np.flatnonzero(leaf >= 0)
    carried = np.array([frame_box(0, *lo[k], *hi[k], group) for k in range(len(lo))])  # the paddle's frame
    lo, hi = carried[:, :3], carried[:, 3:]
    meets = np.all((lo[:, None] <= box_hi[leaves][None]) & (box_lo[leaves][None] <= hi[:, None]), axis=2)
    assert found.triangles.tolist() == sorted(set(leaf[leaves][np.any(meets, axis=0)].tolist()))
    assert found.spheres.tolist() == np.flatnonzero(meets.any(axis=1)).tolist()
    visits = found.visits
    assert np.all(visits[visits[:, 3] >= 0, 3] < np.flatnonzero(visits[:, 3] >= 0))  # parents come first
    assert np.all(visits[visits[:, 3] >= 0][:, 0] == visits[visits[visits[:, 3] >= 0, 3], 0])  # same sphere
    assert len(mesh_view.tree_layout(visits)) == len(visits)


def _record(tmp_path, name, detail, *overrides):
    path = tmp_path / f"{name}-{detail}.mcap"
    done = runner.invoke(app, ["record", name, "-o", str(path), "--no-rrd", "--detail", detail,
                               *[part for o in overrides for part in ("-s", o)]])
    assert done.exit_code == 0, done.output
    return path


@pytest.mark.parametrize("name", ["paddle", "funnel"])
def test_every_step_s_search_of_the_meshes_trees_is_recorded_as_the_engine_walked_it(tmp_path, name):
    """At --detail full every step's walks of the meshes' BVHs are in the file: the trees
    are the engine's (node for node), each recorded walk is the reference walk of its box
    (mesh_view.search, a Python stack walk) visit for visit, and every triangle the engine
    swept-tested was reached by a walk of that sphere: the search drawn is the one made."""
    from physdbg.record import mesh_view
    from physdbg.record.reader import open_recording

    recording = open_recording(_record(tmp_path, name, "full", "duration=0.25"))
    meshes = recording.header.walls.meshes
    tree = recording.mesh_tree()
    for column, values in mesh_view.tree_table(meshes.mesh_set).items():
        assert np.array_equal(tree[column], values), column
    leaf = meshes.mesh_set.leaf_triangle
    walks = later = 0
    for events in recording.iter_step_events():
        begin, search = events[0], next(e for e in events if e.__class__.__name__ == "MeshSearch")
        tests = next(e for e in events if e.__class__.__name__ == "SweptTests")
        assert len(search.query_sphere) >= recording.header.count  # every sphere's path box, then re-asks
        assert np.all(search.query_after[:recording.header.count] == -1)
        later += int(np.count_nonzero(search.query_after >= 0))
        reference = mesh_view.search(meshes, search.query_lo, search.query_hi, begin.time, begin.dt)
        recorded = np.stack([search.visit_query, search.visit_node, search.visit_outcome, search.visit_parent], 1)
        assert np.array_equal(recorded, reference.visits)
        reached = set(zip(search.query_sphere[search.visit_query[search.visit_outcome == 2]].tolist(),
                          leaf[search.visit_node[search.visit_outcome == 2]].tolist()))
        mine = tests.kind == KIND_MESH
        assert set(zip(tests.a[mine].tolist(), tests.other[mine].tolist())) <= reached
        walks += len(search.query_sphere)
    assert walks > 0 and later > 0  # some paths a contact changed asked again


def test_detail_contacts_keeps_the_walks_that_led_to_a_contact(tmp_path):
    """--detail contacts keeps, of each step's search, the visits from a root down to each
    triangle the step had a contact with: a subset of the whole search, every kept visit's
    parent kept, and a reached triangle for every contact on a mesh."""
    from physdbg.record.reader import open_recording

    full = open_recording(_record(tmp_path, "paddle", "full", "duration=0.25"))
    kept = open_recording(_record(tmp_path, "paddle", "contacts", "duration=0.25"))
    leaf = full.mesh_tree()["triangle"]
    contacts_on_mesh = 0
    for k in range(1, full.steps + 1):
        whole, part, contacts = full.mesh_search(k), kept.mesh_search(k), kept.contacts(k)
        whole_rows = set(zip(whole.query_sphere[whole.visit_query].tolist(), whole.query_after[whole.visit_query].tolist(),
                             whole.visit_node.tolist(), whole.visit_outcome.tolist()))
        part_rows = set(zip(part.query_sphere[part.visit_query].tolist(), part.query_after[part.visit_query].tolist(),
                            part.visit_node.tolist(), part.visit_outcome.tolist()))
        assert part_rows <= whole_rows
        assert np.all((part.visit_parent == -1) | (part.visit_parent < np.arange(len(part))))
        assert not np.any(part.visit_outcome == 1)  # a culled node leads nowhere
        reached = set(zip(part.query_sphere[part.visit_query[part.visit_outcome == 2]].tolist(),
                          leaf[part.visit_node[part.visit_outcome == 2]].tolist()))
        on_mesh = contacts.kind == KIND_MESH
        contacts_on_mesh += int(np.count_nonzero(on_mesh))
        assert set(zip(contacts.a[on_mesh].tolist(), contacts.other[on_mesh].tolist())) == reached
    assert contacts_on_mesh > 0


def test_a_recording_without_a_search_says_why(tmp_path):
    from physdbg.errors import RecordingError
    from physdbg.record.reader import open_recording

    state = open_recording(_record(tmp_path, "paddle", "state", "duration=0.05"))
    with pytest.raises(RecordingError, match="recorded with --detail state; it needs --detail contacts or full"):
        state.mesh_search(1)
    assert state.mesh_tree() is None
    spheres = open_recording(_record(tmp_path, "billiards", "full", "steps=2"))
    with pytest.raises(RecordingError, match="no mesh search recorded \\(the scene has no meshes\\)"):
        spheres.mesh_search(1)


@pytest.mark.parametrize("peer", ["pybullet", "mujoco"])
def test_a_peer_moves_a_kinematic_mesh_as_its_users_would_and_the_ball_rides_the_elevator(tmp_path, peer,
                                                                                         monkeypatch):
    """record-peer sets up a kinematic mesh as each peer's users do (pybullet: a fixed-base
    multibody whose pose and velocity are set before each step; MuJoCo: a mocap body posed
    before each step) and says so; on the elevator the peer's ball rides the platform up
    (0.75 m in 1.5 s), within a few millimetres of physdbg's."""
    from physdbg.peers import DEFAULT_SETUPS, run_peer

    # a slab 2 m square and 0.1 m thick, its top at y = 0 (MuJoCo collides with a mesh's convex
    # hull and refuses a flat one)
    monkeypatch.setitem(CARRIERS, "slab-elevator", ('shape = "box"\nscale = [2.0, 0.1, 2.0]\n'
                                                    'position = [0.0, -0.05, 0.0]\nvelocity = [0.0, 0.5, 0.0]',
                                                    CARRIERS["elevator"][1]))
    path = _carrier_scene(tmp_path, "slab-elevator")
    scene = api.load_scene(path)
    run, notes = run_peer(peer, scene, DEFAULT_SETUPS[peer])
    assert ("kinematic mesh a fixed-base multibody" if peer == "pybullet" else "kinematic mesh a mocap body") in notes[0]
    world = scene.build_world()
    for dt in scene.step_lengths():
        world.step(dt)
    ours = world.state.positions[0]
    theirs = run.positions[-1, 0]
    platform = 0.5 * run.times[-1]
    assert abs(ours[1] - (platform + 0.1)) < 1e-9
    assert abs(theirs[1] - ours[1]) < 0.02, (theirs, ours)
    out = tmp_path / f"{peer}.mcap"
    done = runner.invoke(app, ["record-peer", peer, path, "-o", str(out)])
    assert done.exit_code == 0, done.output


def test_a_kinematic_mesh_passing_into_another_is_a_mesh_overlap_finding_at_the_instant_they_meet(tmp_path):
    """A 2 m paddle turning at 180 deg/s about z meets a post whose near corner is at
    (0.05, 0.75): its side (0.1 m from its axis) reaches the corner when it has turned
    atan2(0.75, 0.05) - asin(0.1 / |corner|), at 0.436 s; the audit names both meshes and
    the instant, to a millionth of a step."""
    scene = tmp_path / "crash.toml"
    scene.write_text('dt = 0.01\nduration = 1.0\ngravity = [0.0, 0.0, 0.0]\n'
                     '[[meshes]]\nname = "paddle"\nshape = "paddle"\nscale = [2.0, 1.0, 1.0]\n'
                     'angular_velocity = [0.0, 0.0, 180.0]\n'
                     '[[meshes]]\nname = "post"\nshape = "box"\nscale = [0.1, 0.1, 0.5]\nposition = [0.0, 0.8, 0.0]\n'
                     '[[particles]]\nposition = [0.0, -0.6, 0.0]\nradius = 0.05\n')
    recorded = tmp_path / "crash.mcap"
    assert runner.invoke(app, ["record", str(scene), "-o", str(recorded), "--no-rrd"]).exit_code == 0
    explained = runner.invoke(app, ["explain", str(recorded), "--json", "--all"])
    assert explained.exit_code == 1, explained.output
    overlaps = [f for f in json.loads(explained.output)["findings"] if f["kind"] == "mesh-overlap"]
    assert len(overlaps) == 1 and overlaps[0]["step"] == 44
    corner = np.hypot(0.05, 0.75)
    expected = (np.arctan2(0.75, 0.05) - np.arcsin(0.1 / corner)) / np.pi
    assert overlaps[0]["evidence"]["time"] == pytest.approx(expected, abs=1e-7)
    assert overlaps[0]["evidence"]["meshes"] == ["paddle", "post"]
    assert overlaps[0]["message"].startswith("meshes 'paddle' and 'post' pass into each other from t = 0.436")
    # apart all run long (the post moved out of the sweep): clean, and the summary says it looked
    scene.write_text(scene.read_text().replace("[0.0, 0.8, 0.0]", "[0.0, 1.3, 0.0]"))
    clean = runner.invoke(app, ["run", str(scene)])
    assert clean.exit_code == 0
    assert "audit       clean (no tunnelling, overlap, out-of-order contact, energy gain or collapse, and no meshes " \
           "passing into each other or pinning a sphere)" in clean.output


@pytest.mark.parametrize("where, part", [((0.3, -0.2), "face"), ((1.0, 0.4), "edge"), ((1.0, 1.0), "corner")])
def test_a_contact_with_a_mesh_records_the_face_edge_or_corner_it_touched(tmp_path, where, part):
    """A ball falling straight onto the 2 m plate (two triangles) over its face, over its
    outer edge x = 1, or over its corner (1, 1): the contact row's feature, and the event
    log's words."""
    from physdbg.events import feature_words
    from physdbg.record.view import describe_contacts

    (tmp_path / "plate.obj").write_text(PLATE)
    scene = tmp_path / "drop.toml"
    scene.write_text(f'dt = 0.01\nsteps = 10\ngravity = [0.0, 0.0, 0.0]\n[[meshes]]\nname = "plate"\nfile = "plate.obj"\n'
                     f'[[particles]]\nposition = [{where[0]}, {where[1]}, 0.5]\nvelocity = [0.0, 0.0, -10.0]\n'
                     f'radius = 0.1\n')
    loaded = api.load_scene(str(scene))
    rows = []

    class Keep:
        def on_event(self, event):
            if isinstance(event, Contacts) and len(event):
                rows.append(event)

    world = loaded.build_world(Keep())
    for dt in loaded.step_lengths():
        world.step(dt)
    first = rows[0]
    assert first.kind[0] == KIND_MESH
    assert feature_words(int(first.feature[0])).startswith(part)
    line = describe_contacts(1, first, 0.01, loaded.walls.partner_names())[0][0]
    assert f"hit mesh 'plate' triangle {int(first.other[0])} ({feature_words(int(first.feature[0]))})" in line


# ------------------------------------------------------------------ resting on moving meshes
FLOOR = "v -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\nf 1 3 2\nf 1 4 3\n"  # a 2 m square, face up (+y)
CARRIERS = {
    # a platform rising at 0.5 m/s, the ball dropped onto it from 3 mm
    "elevator": ("file = \"floor.obj\"\nvelocity = [0.0, 0.5, 0.0]", (0.3, 0.103, 0.2)),
    # a 6 m plate tilting at 5 degrees a second about the x axis, the ball off its axis: it slides
    # down the plate as it tilts, across the diagonal between its two triangles
    "tilting": ("file = \"floor.obj\"\nscale = [3.0, 1.0, 3.0]\nangular_velocity = [5.0, 0.0, 0.0]",
                (0.3, 0.1, 0.2)),
    # a wedge 6 m long moving sideways (along x, away from the ball sliding down its slope)
    "moving-ramp": ("shape = \"ramp\"\nrotation = [-90.0, 0.0, 0.0]\nscale = [3.0, 1.0, 3.0]\nvelocity = [0.3, 0.0, 0.0]",
                    (1.6, 1.3, 0.0)),
}


def _carrier_scene(tmp_path, name: str, extra: str = "") -> str:
    (tmp_path / "floor.obj").write_text(FLOOR)
    mesh, (x, y, z) = CARRIERS[name]
    scene = tmp_path / f"{name}.toml"
    scene.write_text(f"""
name = "{name}"
dt = "1/60"
duration = 1.5
gravity = [0.0, -9.81, 0.0]

[[meshes]]
name = "carrier"
{mesh}
restitution = 0.5

[[particles]]
position = [{x}, {y}, {z}]
radius = 0.1
restitution = 0.5
{extra}""")
    return str(scene)


class _Ends:
    """Each step's end: (step, contacts, held, the ball's gap to the mesh's surface (m), warnings)."""

    def __init__(self, scene):
        self.scene, self.rows = scene, []

    def on_event(self, event):
        from physdbg.engine.mesh.closest import closest_on_triangle
        from physdbg.events import StepEnd

        if isinstance(event, StepEnd):
            corners = np.asarray(self.scene.walls.meshes.placed(event.time)[0]).reshape(-1, 3, 3)
            x = event.positions[0]
            gap = min(np.linalg.norm(x - np.array(closest_on_triangle(*x, *c.reshape(9))[:3])) for c in corners) \
                - self.scene.state.radius[0]
            self.rows.append((event.step, event.counts.contacts, event.counts.held, gap, event.warnings))
            self.velocity = event.velocities[0].copy()


@pytest.mark.parametrize("name", sorted(CARRIERS))
def test_a_ball_rides_an_elevator_a_tilting_plate_and_a_moving_ramp_on_the_surface_at_every_step_end(tmp_path, name):
    """Resting on a moving mesh (issue: a ball on a rising platform once took 720 000 contacts
    in 120 steps and sank 4 cm into it): once it rests, the ball's gap to the moving surface
    is within the contact tolerance at every step's end, it takes at most 2 contacts a step,
    and the run has no warning and a clean audit."""
    scene = api.load_scene(_carrier_scene(tmp_path, name))
    ends = _Ends(scene)
    summary = api.run(scene, observer=ends)
    rows = ends.rows
    resting = next(k for k, row in enumerate(rows) if row[2] >= 1)  # the first step it ends held
    assert resting < 20, rows[:20]
    tolerance = scene.settings.contact_tolerance
    after = rows[resting:]
    assert all(abs(gap) <= tolerance for _, _, _, gap, _ in after), max(abs(r[3]) for r in after)
    assert max(contacts for _, contacts, _, _, _ in after[1:]) <= 2  # the steps after it came to rest
    assert all(held >= 1 for _, _, held, _, _ in after)
    assert not any(warnings for *_, warnings in rows)
    assert not summary.finding_counts, summary.finding_counts
    if name == "elevator":  # carried up at the platform's speed
        assert abs(ends.velocity[1] - 0.5) < 1e-9


def test_a_ball_pinned_by_the_elevator_against_a_ceiling_is_one_finding_and_the_run_ends_there(tmp_path):
    """A ball the elevator presses into a fixed ceiling cannot be saved: the motion is
    prescribed, the ceiling immovable. One finding names both, the run ends with that step
    (no budget storm: each step of a held-solve storm spent 10 million updates), and the
    recording up to it is kept."""
    ceiling = "\n[[planes]]\nname = \"ceiling\"\nnormal = [0.0, -1.0, 0.0]\noffset = -0.5\n"
    scene = _carrier_scene(tmp_path, "elevator", ceiling)
    ran = runner.invoke(app, ["run", scene])
    assert ran.exit_code == 3, ran.output
    assert "sphere 0 is pinned between mesh 'carrier' triangle" in ran.output
    assert "and wall 'ceiling'" in ran.output and "a prescribed motion cannot be stopped" in ran.output
    recording = tmp_path / "pinned.mcap"
    recorded = runner.invoke(app, ["record", scene, "-o", str(recording), "--no-rrd"])
    assert recorded.exit_code == 3 and "is readable and holds steps 1..36" in recorded.output, recorded.output
    explained = runner.invoke(app, ["explain", str(recording), "--json"])
    findings = json.loads(explained.output)["findings"]
    assert [f["kind"] for f in findings] == ["pinned"], findings
    assert findings[0]["step"] == 36 and findings[0]["particles"] == [0]
    assert "wall 'ceiling'" in findings[0]["message"] and "mesh 'carrier'" in findings[0]["message"]


def test_a_held_contact_s_surface_motion_is_the_second_derivative_of_its_gap():
    """colliders/mesh.normal_motion: a sphere whose acceleration along the normal equals
    the returned surface acceleration keeps g'' = 0 against a turning, moving plate
    (checked by differences of the gap along the sphere's own path), and its velocity
    along the normal equals the returned speed when g' = 0."""
    from physdbg.engine.colliders import geometry_of, partner_normal_motion
    from physdbg.engine.mesh.closest import closest_on_triangle
    from physdbg.engine.state import Meshes, Walls
    from physdbg.engine.mesh.rigid_motion import in_body_frame

    corners = np.array([[[-1.0, 0.0, -1.0], [1.0, 0.0, 1.0], [1.0, 0.0, -1.0]]])
    meshes = Meshes(["plate"], np.array([0.5]), corners, np.zeros(1, dtype=np.int64), ["test"],
                    velocity=[(0.2, 0.3, -0.1)], angular_velocity=[(0.4, -0.7, 0.5)], pivot=[(0.1, -0.2, 0.3)])
    geometry = geometry_of(Walls(meshes=meshes))
    motion = geometry[KIND_MESH][8][0]
    radius = np.array([0.1])

    def gap(x, t):  # in the plate's frame at run time 0 (where its corners are)
        y = in_body_frame(*x, 0.0, 0.0, 0.0, motion, t)[:3]
        return np.linalg.norm(np.array(y) - np.array(closest_on_triangle(*y, *corners[0].reshape(9))[:3])) - radius[0]

    x0 = np.array([[0.3, 0.1, -0.4]])
    n = np.array([0.0, 1.0, 0.0])
    sigma = np.zeros(1)
    v_any = np.array([[0.7, 0.0, -0.2]])
    speed, _ = partner_normal_motion(KIND_MESH, x0, v_any, sigma, radius, 0, 0, *n, geometry)
    v = v_any + (speed - v_any[0] @ n) * n  # g' = 0
    _, acc_n = partner_normal_motion(KIND_MESH, x0, v, sigma, radius, 0, 0, *n, geometry)
    a = np.array([1.3, acc_n, 0.6])  # a·n = the surface's
    h = 1e-4
    path = [x0[0] + v[0] * t + 0.5 * a * t * t for t in (-h, 0.0, h)]
    g = [gap(p, t) for p, t in zip(path, (-h, 0.0, h), strict=True)]
    assert abs(g[1]) < 1e-12
    assert abs((g[2] - g[0]) / (2 * h)) < 1e-8  # g' = 0
    assert abs((g[2] - 2 * g[1] + g[0]) / h**2) < 1e-5  # g'' = 0


SWEEPER = """
name = "sweeper"
dt = "1/120"
duration = 2.5
gravity = [0.0, -9.81, 0.0]
sleep_speed = 0.1
sleep_time = 0.1

[[planes]]
name = "floor"
normal = [0.0, 1.0, 0.0]
offset = 0.0

[[meshes]]
name = "pusher"
shape = "box"
scale = [0.2, 0.4, 1.0]
position = [-1.5, 0.25, 0.0]
velocity = [1.0, 0.0, 0.0]
restitution = 0.5

[[particles]]
position = [0.0, 0.1, 0.0]
radius = 0.1
restitution = 0.5
"""


def test_a_moving_mesh_wakes_a_sleeping_sphere_before_it_reaches_it(tmp_path, monkeypatch):
    """A ball asleep on the floor, a slab sliding at 1 m/s into it: the ball is woken the
    step the slab's box over the step reaches it (World._wake_where_meshes_move) and
    leaves at (1 + e)·1 m/s = 1.5 m/s, the audit clean. Without the rule the slab passed
    through it (a sleeper is immovable, and two immovable partners' contact is skipped)."""
    from physdbg.engine.world import World

    path = tmp_path / "sweeper.toml"
    path.write_text(SWEEPER)
    summary = api.run(str(path))
    assert summary.woken == 1 and summary.finding_counts == {}
    scene = api.load_scene(str(path))
    world = scene.build_world()
    ends = [world.step(dt) for dt in scene.step_lengths()]
    assert ends[100].counts.asleep == 1  # asleep long before the slab comes
    assert np.allclose(world.state.velocities[0], [1.5, 0.0, 0.0], atol=1e-12)
    monkeypatch.setattr(World, "_wake_where_meshes_move", lambda self, ctx: None)
    world = scene.build_world()
    for dt in scene.step_lengths():
        world.step(dt)
    assert np.array_equal(world.state.positions[0], [0.0, 0.1, 0.0])  # passed through


# ------------------------------------------------------------------ bounding volumes
def _triangle_meets_box(tri: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> bool:
    """Exact triangle–box overlap by separating axes (Akenine-Möller): the box's 3 axes,
    the triangle's normal and the 9 crosses of its edges with the box's axes."""
    centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    v = tri - centre
    edges = [v[1] - v[0], v[2] - v[1], v[0] - v[2]]
    axes = [*np.eye(3), np.cross(edges[0], edges[1])] + [np.cross(e, a) for e in edges for a in np.eye(3)]
    for axis in axes:
        if not np.any(axis):
            continue
        p = v @ axis
        r = half @ np.abs(axis)
        if p.min() > r or p.max() < -r:
            return False
    return True


@settings(max_examples=120, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), count=st.integers(1, 40), builder=st.sampled_from(["median", "mean", "sah", "lbvh"]),
       volume=st.sampled_from(["aabb", "sphere", "obb"]))
@pytest.mark.slow
def test_the_walk_finds_what_a_brute_force_finds_with_every_volume_and_builder(seed, count, builder, volume):
    """colliders.mesh's walk (search_visits, the walk the contact loop makes) with any
    volume over a tree by any builder reaches exactly the triangles whose every node on the
    way down meets the box (the reference test of each, mesh_view._meets), and every
    triangle that meets the box (exact, by separating axes) is among them."""
    from physdbg.engine.colliders.mesh import MeshGeometry, search_visits
    from physdbg.engine.mesh.mesh_set import MeshSet
    from physdbg.engine.state import Meshes, Walls
    from physdbg.record.mesh_view import _meets

    rng = np.random.default_rng(seed)
    corners = rng.uniform(-1, 1, (count, 3, 3))
    corners[:, 1:] = corners[:, :1] + rng.normal(0, 0.4, (count, 2, 3))  # triangles of various sizes
    meshes = Meshes(["m"], np.array([1.0]), corners, np.zeros(count, dtype=np.int64), ["test"],
                    bounding_volume=[volume])
    trees = MeshSet(meshes, builder)
    group = tuple(MeshGeometry.of(Walls(meshes=meshes), trees=trees))
    box_lo, box_hi, leaf, parent = trees.box_lo, trees.box_hi, trees.leaf_triangle, trees.parent
    node_sphere, node_obb = trees.node_sphere, trees.node_obb
    centres = rng.uniform(-1.5, 1.5, (8, 3))
    halves = rng.uniform(0.0, 0.8, (8, 3))
    query, node, outcome, _ = search_visits(centres - halves, centres + halves, group)
    for j in range(8):
        lo, hi = centres[j] - halves[j], centres[j] + halves[j]
        found = set(leaf[node[(query == j) & (outcome == 2)]].tolist())
        brute = set()
        for q in np.flatnonzero(leaf >= 0):
            up, ok = q, True
            while up >= 0 and ok:
                ok = _meets(volume, lo, hi, up, box_lo, box_hi, node_sphere, node_obb)
                up = parent[up]
            if ok:
                brute.add(int(leaf[q]))
        assert found == brute
        touching = {t for t in range(count) if _triangle_meets_box(corners[t], lo, hi)}
        assert touching <= found


@pytest.mark.parametrize("name", ["funnel", "paddle", "ramp"])
def test_every_bounding_volume_gives_the_same_run(name):
    """The walked volume changes which triangles are swept-tested, never a contact: the
    states are the same bit for bit with AABB, sphere and OBB (and auto's choice is one of
    them, said in scene.auto)."""
    hashes = {}
    for volume in ("aabb", "sphere", "obb"):
        scene = api.load_scene(name, ["steps=90"])
        assert "bounding_volume" in scene.auto and all(v in ("aabb", "sphere", "obb")
                                                       for v in scene.walls.meshes.bounding_volume)
        scene.walls.meshes.bounding_volume[:] = [volume] * len(scene.walls.meshes.names)
        world = scene.build_world()
        hashes[volume] = [world.step(dt).state_hash for dt in scene.step_lengths()]
    assert hashes["aabb"] == hashes["sphere"] == hashes["obb"]


# ------------------------------------------------------------------ the simultaneous descent
@settings(max_examples=120, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), meshes=st.integers(1, 3), spheres=st.integers(0, 60),
       builder=st.sampled_from(["median", "mean", "sah", "lbvh"]), volume=st.sampled_from(["aabb", "sphere", "obb"]),
       moving=st.booleans())
@pytest.mark.slow
def test_the_simultaneous_descent_finds_what_a_walk_per_sphere_finds(seed, meshes, spheres, builder, volume, moving):
    """colliders.mesh.reachable_together (the spheres' tree and each mesh's descended
    together) gives the candidates of a walk per sphere (reachable: the triangles whose
    every node on the way down meets the path box), in the same order, for every volume and
    builder, fixed and moving meshes; and every triangle that meets a box (exact, by
    separating axes) is among them."""
    from physdbg.engine.colliders.mesh import MeshGeometry, place, reachable, reachable_together
    from physdbg.engine.mesh.mesh_set import MeshSet
    from physdbg.engine.state import Meshes, Walls

    rng = np.random.default_rng(seed)
    sizes = rng.integers(1, 40, meshes)
    corners = rng.uniform(-1, 1, (int(sizes.sum()), 3, 3))
    corners[:, 1:] = corners[:, :1] + rng.normal(0, 0.4, (len(corners), 2, 3))
    mesh_of = np.repeat(np.arange(meshes), sizes)
    velocity = rng.normal(0, 1.0, (meshes, 3)) if moving else None
    spin = rng.normal(0, 3.0, (meshes, 3)) if moving else None
    group_of = Meshes([f"m{k}" for k in range(meshes)], np.ones(meshes), corners, mesh_of,
                      [f"test {k}" for k in range(meshes)], velocity=velocity, angular_velocity=spin,
                      pivot=rng.uniform(-0.5, 0.5, (meshes, 3)), bounding_volume=[volume] * meshes)
    group = tuple(MeshGeometry.of(Walls(meshes=group_of), trees=MeshSet(group_of, builder)))
    if moving:
        place(group, group_of, 0.3, 1 / 60)  # placed for a step, as a run does
    centres = rng.uniform(-1.5, 1.5, (spheres, 3))
    halves = rng.uniform(0.0, 0.5, (spheres, 3))
    lo, hi = centres - halves, centres + halves
    walked = reachable(lo, hi, group)
    together = reachable_together(lo, hi, group)
    assert np.array_equal(walked[0], together[0]) and np.array_equal(walked[1], together[1])
    if not moving:
        found = set(zip(together[0].tolist(), together[1].tolist()))
        assert {(i, t) for i in range(spheres) for t in range(len(corners))
                if _triangle_meets_box(corners[t], lo[i], hi[i])} <= found


@pytest.mark.parametrize("name", ["funnel", "paddle"])
def test_each_mesh_search_gives_the_same_run_and_auto_says_which_it_took(name):
    """mesh_search = walk, together or auto: the same candidates, so the same states bit for
    bit; the run summary says in how many steps the descent was simultaneous."""
    hashes, summaries = {}, {}
    for method in ("walk", "together", "auto"):
        scene = api.load_scene(name, ["steps=40", f"mesh_search={method}"])
        world = scene.build_world()
        hashes[method] = [world.step(dt).state_hash for dt in scene.step_lengths()]
        summaries[method] = world.together_steps
    assert hashes["walk"] == hashes["together"] == hashes["auto"]
    assert summaries["walk"] == 0 and summaries["together"] == 40
    # auto counted both at steps 0 and 32: here a walk per sphere is less work
    assert summaries["auto"] == 0
    result = CliRunner().invoke(app, ["run", name, "--set", "steps=40", "--set", "mesh_search=together"])
    assert result.exit_code == 0, result.output
    assert "searched by the simultaneous descent in 40 of 40 steps" in result.output


@pytest.mark.parametrize("speed", [50.0, 80.0, 130.0, 300.0])
def test_a_discrete_sphere_ending_a_step_deep_in_a_closed_box_makes_one_contact_or_tunnels_never_a_storm(speed):
    """A 0.2 m sphere at 1.05 m from a 1 m box's centre, 0.01 s steps: at 50 m/s it ends
    the first step 5 cm short of the face, overlapping it, and bounces off (one contact);
    at 80 and 130 m/s its centre ends inside the box, past a face: it went through, the
    audit names the tunnelling, and no face bounces it back and forth; at 300 m/s it
    passes the box whole. Before the discrete test was one contact per mesh, a centre
    between two faces approached one, then the other, up to the contact budget."""
    scene = parse_scene('dt = 0.01\nsteps = 4\ngravity = [0.0, 0.0, 0.0]\ndetection = "discrete"\n'
                        '[[meshes]]\nname = "block"\nshape = "box"\n'
                        f'[[particles]]\nposition = [-1.05, 0.0, 0.0]\nvelocity = [{speed}, 0.0, 0.0]\n'
                        'radius = 0.2\n', "deep.toml")
    result = api.run(scene)
    assert not result.warnings and "budget" not in result.finding_counts
    assert "collapse" not in result.finding_counts
    if speed == 50.0:
        assert result.contacts == 1 and "tunnelling" not in result.finding_counts
        assert result.momentum_end[0] == pytest.approx(-result.momentum_start[0])  # bounced off the near face
    else:
        assert result.contacts == 0 and result.finding_counts["tunnelling"] >= 1
        assert result.momentum_end == result.momentum_start  # through, untouched


FIVE_MESHES = """dt = "1/60"
steps = 3
gravity = [0.0, -9.81, 0.0]
detection = "{detection}"
max_memory = 1e8
[[meshes]]
name = "room"
shape = "box"
scale = 4.0
[[meshes]]
name = "spinner"
shape = "icosphere"
scale = 0.8
angular_velocity = [0.0, 100000.0, 20000.0]
[[meshes]]
name = "tet"
file = "tet.obj"
position = [1.0, -1.5, 0.5]
[[meshes]]
name = "turning tet"
file = "tet.obj"
position = [-1.5, -1.0, -1.0]
angular_velocity = [30000.0, 0.0, 0.0]
[[meshes]]
name = "ball"
shape = "icosphere"
scale = 0.5
position = [-1.0, 1.0, 1.0]
[generate]
kind = "rain"
count = 150
radius = 0.08
min = [-1.9, -1.9, -1.9]
max = [1.9, 1.9, 1.9]
speed = 2.0
"""


@pytest.mark.parametrize("detection", ["swept", "discrete"])
def test_five_meshes_one_spinning_at_a_hundred_thousand_degrees_a_second_stay_within_their_memory(tmp_path,
                                                                                                  detection):
    """A closed room, two icospheres (one turning 283 rev/s) and two tetrahedra (one turning
    83 rev/s) among 150 spheres: the fuzzed scene whose peak memory grew by about 1.1 GB in
    3 steps at the contact budget. The run's allocations (numpy's, traced) peak within its
    max_memory (100 MB), and it takes its 3 steps."""
    import tracemalloc

    (tmp_path / "tet.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n")
    (tmp_path / "five.toml").write_text(FIVE_MESHES.format(detection=detection))
    scene = api.load_scene(str(tmp_path / "five.toml"))
    tracemalloc.start()
    try:
        result = api.run(scene)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert result.steps == 3 and "max_memory" not in result.warning_counts
    assert peak < 1e8, f"{peak / 1e6:.0f} MB"


def test_a_discrete_sphere_in_a_crease_meets_both_faces(tmp_path):
    """A floor and a wall of one mesh meeting at a right angle, a 0.2 m sphere ending its
    first step 0.15 m from each: both faces are contacts (their directions to the centre
    are not opposed, as two walls are not), and it leaves the crease the way it came; only
    faces on both sides of the centre (inside a thin part of a mesh) are one contact."""
    (tmp_path / "crease.obj").write_text("v 0 0 -1\nv 2 0 -1\nv 2 0 1\nv 0 0 1\nv 0 2 -1\nv 0 2 1\n"
                                         "f 1 2 3\nf 1 3 4\nf 1 4 6\nf 1 6 5\n")
    (tmp_path / "crease.toml").write_text('dt = 0.01\nsteps = 1\ngravity = [0.0, 0.0, 0.0]\ndetection = "discrete"\n'
                                          '[[meshes]]\nname = "crease"\nfile = "crease.obj"\n'
                                          '[[particles]]\nposition = [0.5, 0.5, 0.0]\nvelocity = [-35.0, -35.0, 0.0]\n'
                                          'radius = 0.2\n')
    result = api.run(str(tmp_path / "crease.toml"))
    assert result.contacts == 2 and not result.warnings
    assert result.momentum_end[:2] == pytest.approx([35.0, 35.0])
