"""Tunnelling found after the fact (analysis/tunnel.py): crossings where the recording pins
the paths, none where something unrecorded moved them."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from physdbg.analysis.tunnel import (
    StepChecker,
    _anchor_order,
    _at,
    _pinned_kernel,
    _wall_crossings,
    _widen_to_anchors,
)
from physdbg.cli import app
from physdbg.engine.state import Walls
from physdbg.events import CONTACT_ROW, KIND_PAIR, KIND_WALL, Contacts
from physdbg.api import load_scene

R = 0.1


def _floor() -> Walls:
    return Walls(names=["floor"], normals=np.array([[0.0, 1.0, 0.0]]), offsets=np.array([-R]),
                 restitution=np.ones(1), two_sided=np.zeros(1, dtype=bool), thickness=np.zeros(1))


def _wall_contact(time: float, centre, before, after) -> Contacts:
    """One contact of sphere 0 with the floor, at ``time`` s into the step."""
    rows = np.zeros(1, dtype=CONTACT_ROW)
    rows["time_in_step"] = time
    rows["kind"] = KIND_WALL
    rows["a"], rows["other"] = 0, 0
    rows["normal"] = (0.0, 1.0, 0.0)
    rows["point"] = np.asarray(centre) - np.array([0.0, R, 0.0])
    rows["velocity_a_before"], rows["velocity_a_after"] = before, after
    rows["velocity_b_before"] = rows["velocity_b_after"] = np.nan
    rows["restitution"] = 1.0
    return Contacts(step=0, rows=rows)


# Sphere 0 starts at the origin at 1 m/s towards sphere 1, which rests 0.35 m away (they
# would touch at x = 0.15, t = 0.15 s); at t = 0.5 s sphere 0 touches the floor and leaves
# at -1 m/s. Sphere 2 is far away.
X0 = np.array([[0.0, 0.0, 0.0], [0.35, 0.0, 0.0], [5.0, 5.0, 5.0]])
V0 = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])


def _checker() -> StepChecker:
    return StepChecker(np.full(3, R), np.ones(3), np.ones(3), _floor(), {"gravity": (0.0, 0.0, 0.0)})


def test_a_recorded_path_through_a_sphere_is_a_crossing():
    # the recording pins it: at 0.5 s sphere 0 is at x = 0.5 (it went through sphere 1)
    contact = _wall_contact(0.5, (0.5, 0.0, 0.0), before=(1.0, 0.0, 0.0), after=(-1.0, 0.0, 0.0))
    checker = _checker()
    found = checker.check(X0, V0, np.array([[0.0, 0.0, 0.0], X0[1], X0[2]]), 1.0, contact)
    assert [(c.kind, c.a, c.other) for c in found] == [(KIND_PAIR, 0, 1)]
    assert found[0].time == pytest.approx(0.15)
    assert checker.pinned_pieces == checker.pieces == 4  # spheres 1 and 2: one piece each; sphere 0: two


def test_a_path_moved_by_something_unrecorded_is_not_accused():
    """What a held-cluster solve does: sphere 0 was stopped at t = 0.1 s (x = 0.1) by a
    solve in which it had no contact row of its own, then touched the floor at 0.5 s from
    rest. Rebuilt from the step's start alone, its path would run through sphere 1; the
    recording says it arrived at the floor contact at x = 0.1 and at rest, so that piece is
    not pinned and not tested. The piece after the contact is pinned (it ends where the
    step's end says) and is tested: it passes nothing."""
    contact = _wall_contact(0.5, (0.1, 0.0, 0.0), before=(0.0, 0.0, 0.0), after=(-1.0, 0.0, 0.0))
    checker = _checker()
    assert checker.check(X0, V0, np.array([[-0.4, 0.0, 0.0], X0[1], X0[2]]), 1.0, contact) == []
    assert (checker.pieces, checker.pinned_pieces) == (4, 3)
    # arriving at the right place is not enough: with sphere 1 out of the way, a contact
    # whose velocity before is the rebuilt one pins the piece, any other does not
    away = X0 + np.array([[0.0, 0.0, 0.0], [0.0, 3.0, 0.0], [0.0, 0.0, 0.0]])
    for before, pinned in (((1.0, 0.0, 0.0), 4), ((0.2, 0.0, 0.0), 3)):
        contact = _wall_contact(0.5, (0.5, 0.0, 0.0), before=before, after=(-1.0, 0.0, 0.0))
        checker = _checker()
        assert checker.check(away, V0, np.array([[0.0, 0.0, 0.0], away[1], away[2]]), 1.0, contact) == []
        assert (checker.pieces, checker.pinned_pieces) == (4, pinned)


@pytest.mark.parametrize("integrator", ["exact", "euler", "semi-implicit", "verlet"])
def test_every_piece_of_the_cradle_is_pinned(integrator):
    """Where no held contact moves spheres behind the recording's back, the check loses
    nothing: every piece of every path is tested, also the four contacts of the blow at one
    instant (anchors in the order they were resolved)."""
    scene = load_scene("cradle", [f"integrator={integrator}"])
    world = scene.build_world()
    seen = []
    world.observer = type("Grab", (), {"on_event": lambda self, e: seen.append(e)})()
    s = world.settings
    checker = StepChecker(world.state.radius, world.state.inverse_mass, world.state.gravity_scale, world.walls,
                          {"integrator": s.integrator, "drag": s.drag, "gravity": tuple(s.gravity),
                           "contact_tolerance": s.contact_tolerance})
    for dt in scene.step_lengths(None):
        x0, v0 = world.state.positions.copy(), world.state.velocities.copy()
        seen.clear()
        world.step(dt)
        contacts = next((e for e in seen if isinstance(e, Contacts)), None)
        assert checker.check(x0, v0, world.state.positions.copy(), dt, contacts) == []
    assert checker.pieces > scene.steps * len(world.state.radius)
    assert checker.pinned_pieces == checker.pieces


def test_a_dense_pile_is_not_accused_of_tunnelling():
    """In the 500-sphere rain the audit used to report six tunnellings from step 167 on
    ("spheres 342 and 472 passed into each other ... 2.86e-07 m deep"). The slow reference
    loop, stepping the same state with every sphere's path logged, gives the same contacts
    and states to the bit, and along those paths the two spheres never come closer than
    0.06 m + 6e-12 m: sphere 342 had been moved by held-cluster solves it had no row in."""
    result = CliRunner().invoke(app, ["run", "rain", "-s", "generate.count=500", "-s", "duration=1.4"])
    assert result.exit_code == 0, result.output
    assert "audit       clean" in result.output, result.output


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 12), st.data())
def test_the_anchors_are_ordered_and_boxed_as_numpy_would(n, data):
    # The audit's compiled anchor order and boxes against np.lexsort and np.minimum.at,
    # with ties in time (a cradle's blow) and contacts resolved out of time order.
    m = data.draw(st.integers(0, 40))
    who = np.concatenate([np.arange(n), np.array(data.draw(st.lists(st.integers(0, n - 1), min_size=m, max_size=m)),
                                                 dtype=np.int64)])
    times = st.sampled_from([0.0, 0.25, 0.5, 1e-300, 0.5 + 1e-16, 1.0])
    when = np.concatenate([np.zeros(n), np.array(data.draw(st.lists(times, min_size=m, max_size=m)))])
    order_key = np.concatenate([np.full(n, -1), np.array(data.draw(st.permutations(range(m))), dtype=np.int64)])
    order, start = _anchor_order(who, when, order_key, n)
    np.testing.assert_array_equal(order, np.lexsort((order_key, when, who)))
    np.testing.assert_array_equal(start, np.concatenate([[0], np.cumsum(np.bincount(who, minlength=n))]))
    where = np.random.default_rng(m).normal(size=(len(who), 3))
    lo, hi = np.full((n, 3), 0.1), np.full((n, 3), 0.2)
    lo_np, hi_np = lo.copy(), hi.copy()
    np.minimum.at(lo_np, who, where)
    np.maximum.at(hi_np, who, where)
    _widen_to_anchors(who, where, lo, hi)
    np.testing.assert_array_equal(lo, lo_np)
    np.testing.assert_array_equal(hi, hi_np)


def _pinned_by_numpy(who, when, where, speed, before, start, x1, dt, acc, radius, tolerance, integrator, drag, k):
    """StepChecker._pinned as numpy wrote it before it was compiled: the reference."""
    m = len(who)
    is_last = np.zeros(m, dtype=bool)
    is_last[start[1:] - 1] = True
    target_t = np.where(is_last, dt, np.roll(when, -1))
    target_x = np.where(is_last[:, None], x1[who], np.roll(where, -1, axis=0))
    target_v = np.where(is_last[:, None], np.nan, np.roll(before, -1, axis=0))
    got = np.empty((m, 6))
    for r in range(m):
        _at(when, where, speed, r, acc, who[r], target_t[r], integrator, drag, k, got[r])
    slack = 1e-6 * radius[who] + 10.0 * tolerance + 1e-12 * np.abs(target_x).max(axis=1)
    x_ok = np.linalg.norm(got[:, :3] - target_x, axis=1) <= slack
    v_slack = slack / dt + 1e-12 * np.abs(got[:, 3:]).max(axis=1)
    v_err = np.linalg.norm(got[:, 3:] - target_v, axis=1)
    return x_ok & (np.isnan(v_err) | (v_err <= v_slack))


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.sampled_from([(0, 1.0), (0, 0.9), (1, 1.0), (2, 1.0)]))
def test_the_compiled_pinning_rule_answers_as_numpy_did(seed, method):
    """The compiled _pinned_kernel against the numpy it replaced, piece by piece: random
    anchors (1-3 a sphere), some pieces made to arrive exactly where the next anchor (or
    the step's end) is, some nudged within or past the slack, some NaN."""
    integrator, drag = method
    k = -np.log(drag)
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 6))
    counts = rng.integers(1, 4, n)
    start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    m = int(start[-1])
    who = np.repeat(np.arange(n), counts).astype(np.int64)
    dt = 0.01
    when = np.concatenate([np.sort(rng.uniform(0, dt, c)) * (np.arange(c) > 0) for c in counts])
    where = rng.normal(size=(m, 3))
    speed = rng.normal(size=(m, 3))
    before = rng.normal(size=(m, 3))
    acc = rng.normal(size=(n, 3)) * 9.81
    radius = rng.uniform(0.01, 0.1, n)
    x1 = rng.normal(size=(n, 3))
    got = np.empty(6)
    for r in range(m):  # make pieces arrive: exactly, within the slack, past it
        last = r + 1 == m or who[r + 1] != who[r]
        if rng.random() < 0.6:
            _at(when, where, speed, r, acc, who[r], dt if last else when[r + 1], integrator, drag, k, got)
            nudge = rng.choice([0.0, 1e-9, 1e-3])
            if last:
                x1[who[r]] = got[:3] + nudge
            else:
                where[r + 1] = got[:3] + nudge
                before[r + 1] = got[3:] + rng.choice([0.0, 1e-9, 1e-1])
    for a in (where, speed, before, x1):
        if rng.random() < 0.2:
            a[rng.integers(len(a)), rng.integers(3)] = np.nan
    tolerance = float(rng.choice([0.0, 1e-9]))
    compiled = np.empty(m, dtype=bool)
    _pinned_kernel(who, when, where, speed, before, start, x1, dt, acc, radius, tolerance, integrator, drag, k,
                   compiled)
    expected = _pinned_by_numpy(who, when, where, speed, before, start, x1, dt, acc, radius, tolerance, integrator,
                                drag, k)
    assert compiled.tolist() == expected.tolist()


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_the_compiled_wall_check_answers_as_numpy_did(seed):
    """_wall_crossings against the (N, W) numpy it replaced: one- and two-sided walls,
    centres that cross, stop on the plane, stay; some NaN."""
    rng = np.random.default_rng(seed)
    n, w = int(rng.integers(1, 30)), int(rng.integers(1, 5))
    normals = rng.normal(size=(w, 3))
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    normals[rng.random(w) < 0.5] = np.eye(3)[rng.integers(3)]  # axis walls: ends exactly on them
    offsets = rng.choice([0.0, 0.5, -0.25], w)
    two_sided = rng.random(w) < 0.5
    radius = rng.uniform(0.01, 0.3, n)
    x0 = rng.choice([-1.0, -0.25, 0.0, 0.5, 1.0], (n, 3)) + rng.normal(size=(n, 3)) * (rng.random((n, 1)) < 0.5)
    x1 = rng.choice([-1.0, -0.25, 0.0, 0.5, 1.0], (n, 3)) + rng.normal(size=(n, 3)) * (rng.random((n, 1)) < 0.5)
    for a in (x0, x1):
        if rng.random() < 0.3:
            a[rng.integers(n), rng.integers(3)] = np.nan
    def signed_distance(x):  # n·x - d summed in axis order, as the kernel sums it
        return (x[:, 0:1] * normals[:, 0] + x[:, 1:2] * normals[:, 1]) + x[:, 2:3] * normals[:, 2] - offsets[None, :]

    h0, h1 = signed_distance(x0), signed_distance(x1)
    through = np.where(two_sided[None, :], (np.sign(h0) != np.sign(h1)) & (h0 != 0) & (h1 != 0),
                       (h0 >= 0) & (h1 < -radius[:, None]))
    expected = [(float(i), float(j), float(abs(h1[i, j]))) for i, j in zip(*np.nonzero(through), strict=True)]
    got = [tuple(row) for row in _wall_crossings(x0, x1, normals, offsets, two_sided, radius).tolist()]
    assert np.array_equal(np.array(got).reshape(-1, 3), np.array(expected).reshape(-1, 3), equal_nan=True)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(-(2**62), 2**62), max_size=60))
def test_sorted_unique_is_numpys_unique(values):
    from physdbg.analysis.tunnel import sorted_unique

    keys = np.array(values, dtype=np.int64)
    got, want = sorted_unique(keys), np.unique(keys)
    assert got.dtype == want.dtype and np.array_equal(got, want)


SPINNER = """dt = "1/60"
steps = 1
gravity = [0.0, 0.0, 0.0]
[[meshes]]
name = "spinner"
shape = "icosphere"
scale = 0.8
angular_velocity = [0.0, {spin}, 0.0]
[[particles]]
position = [1.06025976, 0.86174387, 0.52550031]
velocity = [{vx}, -58.4898854, 8.56370078]
radius = 0.08
"""


@pytest.mark.parametrize("spin", [5000.0, 20000.0])
def test_a_sphere_flying_past_a_spinning_mesh_is_not_accused_of_going_through_it(spin):
    """A ball of 0.4 m turning 0.23 or 0.93 of a revolution in the step, and a sphere that
    passes 0.25 m from its surface at 109 m/s: seen from the spinning mesh, the chord from
    the sphere's start to its end cuts through the ball (the audit said "swept through
    sphere 0 with no contact ... please report it"); the path, followed in pieces over
    which the mesh turns 2 degrees, does not."""
    from physdbg import api
    from physdbg.scene import parse_scene

    result = api.run(parse_scene(SPINNER.format(spin=spin, vx=-91.56575969), "spinner.toml"))
    assert result.contacts == 0 and result.finding_counts == {}, result.findings
    # aimed at the ball's centre instead, it is struck: the swept test finds the touch
    struck = api.run(parse_scene(SPINNER.format(spin=spin, vx=-91.56575969).replace(
        "velocity = [-91.56575969, -58.4898854, 8.56370078]", "velocity = [-63.6, -51.7, -31.5]"), "spinner.toml"))
    assert struck.contacts >= 1 and "tunnelling" not in struck.finding_counts, struck.findings


def test_a_sphere_through_a_turning_mesh_away_from_the_origin_is_named():
    """A plate turning slowly about its own centre at x = 5 m, a sphere crossing it at
    100 m/s with a discrete test: the audit names the tunnelling (the turning mesh's
    reach is measured about its own pivot, wherever that is)."""
    from physdbg import api
    from physdbg.scene import parse_scene

    scene = parse_scene('dt = 0.01\nsteps = 3\ngravity = [0.0, 0.0, 0.0]\ndetection = "discrete"\n'
                        '[[meshes]]\nname = "plate"\nshape = "box"\nscale = [0.02, 2.0, 2.0]\n'
                        'position = [5.0, 0.0, 0.0]\nangular_velocity = [10.0, 0.0, 0.0]\n'
                        '[[particles]]\nposition = [4.5, 0.1, 0.1]\nvelocity = [100.0, 0.0, 0.0]\nradius = 0.05\n',
                        "plate.toml")
    result = api.run(scene)
    assert result.contacts == 0 and result.finding_counts.get("tunnelling", 0) >= 1, result.findings
    assert "mesh 'plate'" in result.findings[0].message
