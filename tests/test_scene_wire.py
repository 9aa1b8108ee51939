"""The view's spheres and arrows written with numpy are the protobuf library's bytes."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from physdbg.record import format as fmt
from physdbg.record.scene_wire import ARROW_COLOR, RESTING_ARROW_COLOR, SphereEntities, arrows, entity_field


def library_bytes(ns, positions, diameters, colors) -> bytes:
    """The same entities built one message at a time by the library (what the view did)."""
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate

    update = SceneUpdate()
    for i, (position, diameter, color) in enumerate(zip(positions.tolist(), diameters.tolist(), colors.tolist())):
        entity = update.entities.add(frame_id=fmt.VIEW_SCENE_FRAME, id=f"sphere {i}")
        entity.timestamp.FromNanoseconds(ns)
        sphere = entity.spheres.add()
        sphere.pose.position.x, sphere.pose.position.y, sphere.pose.position.z = position
        sphere.pose.orientation.w = 1.0
        sphere.size.x = sphere.size.y = sphere.size.z = diameter
        sphere.color.r, sphere.color.g, sphere.color.b, sphere.color.a = color
    return update.SerializeToString()


coordinate = st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=64),
                       st.sampled_from([0.0, -0.0, 1e-300, 5e-324]))


@settings(max_examples=60, deadline=None)
@given(data=st.data(), count=st.integers(0, 40), ns=st.sampled_from([0, 1, 999_999_999, 1_000_000_000,
                                                                      4_166_666_667, 3_600 * 10**9 + 7]))
def test_the_encoder_writes_the_librarys_bytes(data, count, ns):
    positions = np.array(data.draw(st.lists(st.tuples(coordinate, coordinate, coordinate), min_size=count,
                                            max_size=count)), dtype=np.float64).reshape(count, 3)
    diameters = np.array(data.draw(st.lists(st.sampled_from([0.1, 0.0, 2.0, 1e-3]), min_size=count,
                                            max_size=count)))
    colors = np.array(data.draw(st.lists(st.sampled_from([(1.0, 0.5, 0.0, 1.0), (0.0, 0.0, 0.0, 1.0),
                                                          (0.3, 0.4, 0.5, 1.0), (0.0, 0.0, 0.0, 0.0)]),
                                         min_size=count, max_size=count))).reshape(count, 4)
    encoder = SphereEntities(fmt.VIEW_SCENE_FRAME, diameters, colors)
    assert encoder.encode(ns, positions) == library_bytes(ns, positions, diameters, colors)


def test_long_entities_and_new_colours():
    """Ids past "sphere 9999" and every coordinate present make an entity longer than 127
    bytes (a two-byte length); colours set again are the ones written from then on."""
    count = 12_000
    rng = np.random.default_rng(7)
    positions = rng.normal(size=(count, 3))
    positions[::7, 1] = 0.0
    diameters = np.full(count, 0.1)
    colors = np.tile([1.0, 140 / 255.0, 0.0, 1.0], (count, 1))
    encoder = SphereEntities(fmt.VIEW_SCENE_FRAME, diameters, colors)
    assert encoder.encode(123, positions) == library_bytes(123, positions, diameters, colors)
    colors[::3] = (0.4, 0.5, 0.6, 1.0)
    encoder.set_colors(colors)
    assert encoder.encode(5, positions) == library_bytes(5, positions, diameters, colors)


def library_arrows(points, rotations, lengths, resting) -> bytes:
    """The arrows as the view built them with the library, one message each."""
    from foxglove_schemas_protobuf.SceneEntity_pb2 import SceneEntity

    entity = SceneEntity()
    for point, rotation, length, rest in zip(points.tolist(), rotations.tolist(), lengths.tolist(),
                                             resting.tolist()):
        arrow = entity.arrows.add(shaft_length=0.7 * length, head_length=0.3 * length,
                                  shaft_diameter=0.08 * length, head_diameter=0.2 * length)
        arrow.pose.position.x, arrow.pose.position.y, arrow.pose.position.z = point
        q = arrow.pose.orientation
        q.x, q.y, q.z, q.w = rotation
        arrow.color.r, arrow.color.g, arrow.color.b, arrow.color.a = RESTING_ARROW_COLOR if rest else ARROW_COLOR
    return entity.SerializeToString()


@settings(max_examples=60, deadline=None)
@given(data=st.data(), count=st.integers(0, 30))
def test_the_arrows_are_the_librarys_bytes(data, count):
    def column(width):
        return np.array(data.draw(st.lists(st.tuples(*[coordinate] * width), min_size=count, max_size=count)),
                        dtype=np.float64).reshape(count, width)

    points, rotations = column(3), column(4)
    lengths = column(1).reshape(count)
    resting = np.array(data.draw(st.lists(st.booleans(), min_size=count, max_size=count)), dtype=bool)
    assert arrows(points, rotations, lengths, resting) == library_arrows(points, rotations, lengths, resting)


def test_an_entity_field_is_what_the_update_writes_for_it():
    from foxglove_schemas_protobuf.SceneEntity_pb2 import SceneEntity
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate

    entity = SceneEntity(id="contacts", frame_id="scene")
    entity.arrows.add(shaft_length=0.5)
    long = SceneEntity(id="x" * 300)
    update = SceneUpdate()
    update.entities.append(entity)
    update.entities.append(long)
    assert entity_field(entity.SerializeToString()) + entity_field(long.SerializeToString()) == \
        update.SerializeToString()


def test_a_frame_of_the_view_decodes_as_the_scene_it_was_given():
    """The view's frame: an entity per sphere at its centre, the contacts' arrows after them."""
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate

    from physdbg import api
    from physdbg.events import Contacts
    from physdbg.record.foxglove_view import FoxgloveView
    from physdbg.record.header import RecordingHeader

    scene = api.load_scene("cradle")
    view = FoxgloveView(RecordingHeader.from_scene(scene, "contacts"), "contacts")
    positions = scene.build_world().state.positions + 0.25
    contacts = Contacts.empty(1)
    update = SceneUpdate.FromString(view._spheres(42, positions, contacts))
    spheres = [e for e in update.entities if e.id.startswith("sphere ")]
    assert [e.id for e in spheres] == [f"sphere {i}" for i in range(len(positions))]
    assert np.array_equal([[s.spheres[0].pose.position.x, s.spheres[0].pose.position.y,
                            s.spheres[0].pose.position.z] for s in spheres], positions)
    assert all(e.timestamp.ToNanoseconds() == 42 for e in update.entities)
    assert update.entities[-1].id == "contacts" and not len(update.entities[-1].arrows)
