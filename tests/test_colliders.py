"""The collider kinds (engine/colliders): the table, and each kind's geometry judged by
the others' view of it: the swept test, the gap, the deepest overlap, the candidates."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, event, given, settings
from hypothesis import strategies as st

from physdbg.engine.colliders import (
    KIND_NAMES,
    KINDS,
    PARTNER_IS_SPHERE,
    contact_gap,
    deepest_overlap,
    every_candidate,
    geometry_of,
    max_overlap,
    narrow_candidates,
    partner_restitution,
    partner_sphere,
    time_of_impact,
)
from physdbg.engine.motion import EULER, EXACT, VERLET, advance_particle
from physdbg.engine.state import Walls
from physdbg.engine.toi import SWEPT
from physdbg.events import KIND_PAIR, KIND_WALL

coordinate = st.floats(-1.0, 1.0, allow_nan=False)
vector = st.tuples(coordinate, coordinate, coordinate).map(np.array)


def _walls(normal: np.ndarray, offset: float, two_sided: bool, thickness: float) -> tuple:
    unit = normal / np.linalg.norm(normal)
    return geometry_of(Walls(["w"], unit[None, :], np.array([offset]), np.array([0.7]), np.array([two_sided]),
                             np.array([thickness])))


def test_the_table_names_each_kind_and_which_partners_move():
    assert KINDS == len(KIND_NAMES) == len(PARTNER_IS_SPHERE) == 3
    assert KIND_NAMES[KIND_PAIR] == "sphere" and KIND_NAMES[KIND_WALL] == "wall"
    assert partner_sphere(KIND_PAIR, 7) == 7  # a sphere partner is sphere 7 ...
    assert partner_sphere(KIND_WALL, 7) == -1  # ... wall 7 is immovable
    walls = _walls(np.array([0.0, 1.0, 0.0]), 0.0, False, 0.0)
    restitution = np.array([0.2, 0.9])
    assert partner_restitution(KIND_PAIR, 1, restitution, walls) == 0.9
    assert partner_restitution(KIND_WALL, 0, restitution, walls) == 0.7


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.filter_too_much])
@given(kind=st.sampled_from([KIND_PAIR, KIND_WALL]), integrator=st.sampled_from([EULER, EXACT, VERLET]),
       xa=vector, xb=vector, va=vector.map(lambda v: 4.0 * v), vb=vector.map(lambda v: 4.0 * v),
       gravity=vector.map(lambda g: 10.0 * g), normal=vector, offset=coordinate, two_sided=st.booleans(),
       radius=st.floats(0.02, 0.3), aim=st.floats(0.5, 4.0))
@pytest.mark.slow
def test_each_kind_s_gap_closes_at_its_time_of_impact(kind, integrator, xa, xb, va, vb, gravity, normal, offset,
                                                      two_sided, radius, aim):
    """Advance to the predicted time of impact on the method's path: the kind's own gap is
    zero there (sphere 0 is aimed at its partner, plus a random velocity)."""
    assume(np.linalg.norm(normal) > 0.1)
    walls = _walls(normal, offset, two_sided, 0.04 if two_sided else 0.0)
    unit = walls[KIND_WALL][0][0]
    height = unit @ xa - offset
    if kind == KIND_PAIR:
        va = va + aim * (xb - xa)
    else:
        if height < 0.0 and not two_sided:  # a one-sided wall keeps spheres on its normal's side
            xa = xa - 2.0 * height * unit
            height = -height
        va = va - aim * np.sign(height) * unit
    x = np.array([xa, xb])
    v = np.array([va, vb])
    a = np.array([gravity, gravity * 0.5])
    r = np.array([radius, 0.7 * radius])
    sigma = np.zeros(2)
    other = 1 if kind == KIND_PAIR else 0
    gap0 = contact_gap(kind, x, v, a, r, 0, other, walls)[0]
    assume(gap0 > 1e-3)
    start, t, _work = time_of_impact(kind, 0, other, x, v, a, r, sigma, 1.0, integrator, 0.0, SWEPT, 1, 1e-12, walls)
    assert start == 0.0
    assume(t <= 1.0)
    event(f"{KIND_NAMES[kind]} hit")
    for i in range(2):
        advance_particle(x, v, a, sigma, i, t, integrator, 1.0, 0.0)
    gap = contact_gap(kind, x, v, a, r, 0, other, walls)[0]
    assert abs(gap) <= 1e-7, (KIND_NAMES[kind], t, gap)


@settings(max_examples=200, deadline=None)
@given(points=st.lists(vector, min_size=2, max_size=6), normal=vector, offset=coordinate, two_sided=st.booleans(),
       radius=st.floats(0.05, 0.6))
def test_the_deepest_overlap_is_the_largest_negative_gap_and_no_overlap_is_pruned(points, normal, offset, two_sided,
                                                                                  radius):
    """max_overlap (the finish phase's audit) against every kind's contact_gap over every
    candidate; and the narrow phase's candidates for boxes x ± r hold every overlap."""
    assume(np.linalg.norm(normal) > 0.1)
    walls = _walls(normal, offset, two_sided, 0.04 if two_sided else 0.0)
    x = np.array(points)
    n = len(x)
    r = np.full(n, radius)
    zeros = np.zeros((n, 3))
    pairs = np.column_stack(every_candidate(KIND_PAIR, n, walls))
    deepest = 0.0
    for kind in range(KINDS):
        a, other = every_candidate(kind, n, walls)
        gaps = [contact_gap(kind, x, zeros, zeros, r, i, j, walls)[0] for i, j in zip(a, other)]
        deepest = max([deepest] + [-g for g in gaps])
        near_a, near_other = narrow_candidates(kind, pairs, x - r[:, None], x + r[:, None], walls)
        kept = set(zip(near_a.tolist(), near_other.tolist()))
        for i, j, g in zip(a.tolist(), other.tolist(), gaps):
            if g <= 0.0:
                assert (i, j) in kept, (KIND_NAMES[kind], i, j, g)
    assert math.isclose(max_overlap(x, r, pairs, walls, False), deepest, rel_tol=0.0, abs_tol=1e-12)
    depth, kind, a, other = deepest_overlap(x, r, pairs, walls, False)  # and who: the parties of that gap
    assert depth == max_overlap(x, r, pairs, walls, False)
    if depth > 0.0:
        assert math.isclose(-contact_gap(kind, x, zeros, zeros, r, a, other, walls)[0], depth, abs_tol=1e-12)
    else:
        assert (kind, a, other) == (-1, -1, -1)


# ----------------------------------------------------------------------------- meshes (KIND_MESH)
def _mesh_walls(shape: str = "icosphere", position=(0.0, 0.0, 0.0), degrees=(0.0, 0.0, 0.0), restitution=0.6):
    from physdbg.engine.mesh import Pose
    from physdbg.engine.state import Meshes
    from physdbg.meshes import load_mesh

    mesh = load_mesh(shape, hull=False)
    corners = Pose.of(position, degrees).apply(mesh.vertices)[mesh.faces]
    return Walls([], np.zeros((0, 3)), np.zeros(0), np.zeros(0), np.zeros(0, dtype=np.bool_), np.zeros(0),
                 meshes=Meshes([shape], np.array([restitution]), corners, np.zeros(len(corners), dtype=np.int64),
                               [f"shape {shape}"]))


def test_a_mesh_is_a_kind_of_immovable_partner_with_its_mesh_restitution():
    from physdbg.events import KIND_MESH

    assert KIND_NAMES[KIND_MESH] == "mesh" and not PARTNER_IS_SPHERE[KIND_MESH] and partner_sphere(KIND_MESH, 5) == -1
    geometry = geometry_of(_mesh_walls(restitution=0.6))
    assert partner_restitution(KIND_MESH, 7, np.ones(3), geometry) == 0.6


@settings(max_examples=60, deadline=None)
@given(lo=st.tuples(*[st.floats(-0.8, 0.8)] * 3), size=st.tuples(*[st.floats(0.0, 0.6)] * 3))
def test_the_stackless_walk_finds_exactly_the_triangles_a_box_meets(lo, size):
    from physdbg.engine.colliders import mesh
    from physdbg.events import KIND_MESH

    walls = _mesh_walls("icosphere", degrees=(10, 20, 30))
    geometry = geometry_of(walls)
    box_lo = np.array([lo])
    box_hi = box_lo + np.array([size])
    a, t = narrow_candidates(KIND_MESH, np.zeros((0, 2), dtype=np.int64), box_lo, box_hi, geometry)
    corners = walls.meshes.corners
    brute = np.flatnonzero(np.all(corners.min(axis=1) <= box_hi, axis=1) & np.all(corners.max(axis=1) >= box_lo, axis=1))
    assert sorted(t.tolist()) == brute.tolist() and set(a.tolist()) <= {0}
    out = np.empty((len(corners), 2), dtype=np.int64)
    assert mesh.partners_of(0, box_lo, box_hi, geometry[KIND_MESH], out) == len(brute)


def test_a_sphere_meets_a_mesh_at_the_swept_time_with_the_normal_from_the_closest_point():
    from physdbg.events import KIND_MESH

    geometry = geometry_of(_mesh_walls("paddle"))  # a 1 × 0.2 × 0.05 m plate at the origin
    x = np.array([[0.2, 0.0, 1.0]])
    v = np.array([[0.0, 0.0, -10.0]])
    a = np.zeros((1, 3))
    radius = np.array([0.1])
    found = []
    triangles = len(geometry[KIND_MESH][0])  # 68: the plate's long sides in 8 pieces
    for t in range(triangles):
        start, when, _work = time_of_impact(KIND_MESH, 0, t, x, v, a, radius, np.zeros(1), 1.0, EULER, 0.0, SWEPT, 4, 1e-12,
                                     geometry)
        found.append(when)
    first = min(found)
    assert first == pytest.approx((1.0 - 0.025 - 0.1) / 10.0, abs=1e-12)  # the top face, at z = 0.025
    touched = found.index(first)
    at = x + v * first
    gap, n0, n1, n2, renewed = contact_gap(KIND_MESH, at, v, a, radius, 0, touched, geometry)
    assert abs(gap) < 1e-12 and renewed and (n0, n1, n2) == pytest.approx((0.0, 0.0, 1.0))
    # past the plate's edge, the normal turns with the closest point (an edge contact)
    beside = np.array([[0.6, 0.0, 0.1]])
    best = min(range(triangles), key=lambda t: contact_gap(KIND_MESH, beside, v, a, radius, 0, t, geometry)[0])
    gap, n0, n1, n2, _ = contact_gap(KIND_MESH, beside, v, a, radius, 0, best, geometry)
    assert n0 > 0.5 and n2 > 0.5
    assert max_overlap(at - [[0.0, 0.0, 0.01]], radius, np.zeros((0, 2), dtype=np.int64), geometry, False) == \
        pytest.approx(0.01, abs=1e-12)


# ----------------------------------------------------------------------------- the written switch
def test_the_switch_is_what_its_generator_writes_from_the_registry():
    """colliders/switch.py is written by physdbg/write_switch.py from events.COLLIDER_KINDS and
    each kind module's SWITCH: the file in the tree is exactly what it writes now (edit
    the kinds' modules or the registry, then run the script; never the file)."""
    from physdbg import write_switch
    from physdbg.events import COLLIDER_KINDS

    assert write_switch.SWITCH_FILE.read_text() == write_switch.switch_source(), \
        "switch.py is not what write_switch.py writes: run python physdbg/write_switch.py"
    assert write_switch.read_registry() == [(row.name, row.module) for row in COLLIDER_KINDS]
    from physdbg.engine.colliders import switch

    assert switch.WRITTEN_FOR == tuple(row.module for row in COLLIDER_KINDS)


def test_a_kind_module_the_switch_cannot_be_written_from_is_refused_saying_what_is_wrong(tmp_path):
    from physdbg import write_switch
    from physdbg.write_switch import switch_source

    registry = [("sphere", "sphere"), ("capsule", "capsule")]
    (tmp_path / "sphere.py").write_text((write_switch.HERE / "sphere.py").read_text())
    with pytest.raises(ValueError, match="lists kind 'capsule' in module 'capsule', but there is no "
                                                "engine/colliders/capsule.py"):
        switch_source(registry, tmp_path)
    (tmp_path / "capsule.py").write_text("def normal(x, ia, other, group):\n    pass\n")
    with pytest.raises(ValueError, match="capsule.py: no SWITCH table"):
        switch_source(registry, tmp_path)
    (tmp_path / "capsule.py").write_text("def normal(x, ia, other, group):\n    pass\nSWITCH = {'contact_normal': "
                                         "'normal(x, ia, other, group)'}\n")
    with pytest.raises(ValueError, match="SWITCH has no entry for 'time_of_impact'"):
        switch_source(registry, tmp_path)
    full = dict.fromkeys((f.name for f in write_switch.FUNCTIONS), "0")
    for entry, problem in (({"contact_normal": "turned(x, ia, other, group)"},
                            "calls turned, which the module neither defines nor imports"),
                           ({"contact_normal": "normal(x, ia, other, velocity)"},
                            "reads velocity, which is not one of the function's parameters"),
                           ({"contact_colour": "0"}, "SWITCH names contact_colour, which the switch does not have")):
        (tmp_path / "capsule.py").write_text(f"def normal(x, ia, other, group):\n    pass\nSWITCH = {dict(full, **entry)!r}\n")
        with pytest.raises(ValueError, match=problem):
            switch_source(registry, tmp_path)
    (tmp_path / "capsule.py").write_text(f"def normal(x, ia, other, group):\n    pass\nSWITCH = "
                                         f"{dict(full, contact_normal='normal(x, ia, other, group)')!r}\n")
    written = switch_source(registry, tmp_path)
    assert "    if kind == 1:  # capsule\n        return capsule.normal(x, ia, other, geometry[1])" in written
    assert 'WRITTEN_FOR = ("sphere", "capsule")' in written
