"""Swept tests: exact time of impact, first root only, and the tunnelling of the others."""

from __future__ import annotations


import math

import numpy as np
import pytest
from hypothesis import assume, event, given, settings
from hypothesis import strategies as st

from physdbg.engine.motion import EULER, EXACT, SEMI_IMPLICIT, VERLET, path_coefficients
from physdbg.engine.toi import (
    INF,
    pair_toi_sampled,
    pair_toi_swept,
    wall_toi_sampled,
    wall_toi_swept,
)
from physdbg.api import load_scene

coord = st.floats(-3.0, 3.0, allow_nan=False)
vec = st.tuples(coord, coord, coord).map(np.array)


@st.composite
def approach(draw, scale=1.0):
    """(dx, dv): relative position and a velocity aimed roughly back along -dx, so that
    hits and misses (and near misses) are all common."""
    dx = draw(vec) * scale
    aim = draw(st.floats(0.0, 3.0))
    wobble = draw(vec) * draw(st.sampled_from([0.0, 0.1, 0.5, 1.0]))
    return dx, -dx * aim + wobble


def _relative_path(dx, dv, da, integrator, k, tau):
    p1, p2, _ = path_coefficients(integrator, k, tau)
    return dx + dv * p1 + da * p2


# ----------------------------------------------------------------------------- the seed's quadratic
@settings(max_examples=500, deadline=None)
@given(relative=approach(), radius_sum=st.floats(0.05, 1.0), horizon=st.floats(0.01, 5.0))
def test_straight_paths_touch_exactly_when_they_come_within_the_radii_sum(relative, radius_sum, horizon):
    dx, dv = relative
    assume(np.linalg.norm(dx) > radius_sum * (1 + 1e-6))
    vv = float(dv @ dv)
    s_closest = 0.0 if vv == 0 else min(max(-float(dx @ dv) / vv, 0.0), horizon)
    closest = float(np.linalg.norm(dx + dv * s_closest))
    assume(abs(closest - radius_sum) > 1e-7 * radius_sum)  # not a graze at the edge of rounding
    t = pair_toi_swept(dx, dv, np.zeros(3), radius_sum, EULER, 0.0, horizon, 1e-12)
    if closest > radius_sum:
        event("no contact")
        assert t == INF
        return
    event("contact")
    assert 0.0 <= t <= s_closest + 1e-12
    assert np.linalg.norm(dx + dv * t) == pytest.approx(radius_sum, rel=1e-9)
    # the first time: before it the spheres were apart all along
    for s in np.linspace(0.0, t, 50)[:-1]:
        assert np.linalg.norm(dx + dv * s) > radius_sum * (1 - 1e-9)


def test_touching_pairs_are_a_contact_only_while_approaching():
    dx = np.array([1.0, 0.0, 0.0])
    assert pair_toi_swept(dx, np.array([-1.0, 0.0, 0.0]), np.zeros(3), 1.0, EULER, 0.0, 1.0, 0.0) == 0.0
    assert pair_toi_swept(dx, np.array([1.0, 0.0, 0.0]), np.zeros(3), 1.0, EULER, 0.0, 1.0, 0.0) == INF
    # overlapping and separating: left alone so it can leave
    assert pair_toi_swept(0.5 * dx, np.array([1.0, 0.0, 0.0]), np.zeros(3), 1.0, EULER, 0.0, 1.0, 0.0) == INF


# ----------------------------------------------------------------------------- curved paths
def _sampled_first_contact(dx, dv, da, radius_sum, integrator, k, horizon, samples=4001):
    taus = np.linspace(0.0, horizon, samples)
    gaps = np.array([np.linalg.norm(_relative_path(dx, dv, da, integrator, k, s)) for s in taus]) - radius_sum
    return taus, gaps


@settings(max_examples=300, deadline=None)
@given(relative=approach(scale=0.4), da=vec.map(lambda a: a * 2.0), radius_sum=st.floats(0.05, 1.0),
       horizon=st.floats(0.01, 2.0), integrator=st.sampled_from([VERLET, EXACT]),
       k=st.sampled_from([0.0, 0.3, 2.0]))
@pytest.mark.slow
def test_curved_paths_first_contact_matches_dense_sampling(relative, da, radius_sum, horizon, integrator, k):
    """Unequal accelerations (a falling sphere and a resting one): never skip the first root."""
    dx, dv = relative
    k = k if integrator == EXACT else 0.0
    assume(np.linalg.norm(dx) > radius_sum * 1.001)
    taus, gaps = _sampled_first_contact(dx, dv, da, radius_sum, integrator, k, horizon)
    spacing = taus[1] - taus[0]
    lipschitz = float(np.linalg.norm(dv) + np.linalg.norm(da) * horizon + 1e-12)
    margin = 2 * lipschitz * spacing
    t = pair_toi_swept(dx, dv, da, radius_sum, integrator, k, horizon, 1e-12)
    if gaps.min() > margin:
        event("no contact")
        assert t == INF  # clearly never touch
        return
    below = np.nonzero(gaps < -margin)[0]
    assume(below.size > 0)  # clearly touch (grazes within the sampling margin are skipped)
    event("contact")
    first_below = taus[below[0]]
    assert t <= first_below + 1e-12
    gap_t = np.linalg.norm(_relative_path(dx, dv, da, integrator, k, t)) - radius_sum
    assert abs(gap_t) <= 1e-9 * max(1.0, radius_sum)
    before = taus < t - spacing
    assert np.all(gaps[before] > -margin)


# ----------------------------------------------------------------------------- walls
@settings(max_examples=500, deadline=None)
@given(g0=st.floats(1e-3, 2.0), p=st.floats(-10.0, 10.0), q=st.floats(-20.0, 20.0),
       horizon=st.floats(0.01, 2.0), integrator=st.sampled_from([EULER, SEMI_IMPLICIT, VERLET, EXACT]),
       k=st.sampled_from([0.0, 0.5, 3.0]))
def test_wall_first_inward_crossing_matches_dense_sampling(g0, p, q, horizon, integrator, k):
    k = k if integrator == EXACT else 0.0
    q_eff = 0.0 if integrator in (EULER, SEMI_IMPLICIT) else q
    taus = np.linspace(0.0, horizon, 4001)
    gaps = np.array([g0 + p * c[0] + q_eff * c[1] for c in (path_coefficients(integrator, k, s) for s in taus)])
    spacing = taus[1] - taus[0]
    margin = 2 * (abs(p) + abs(q_eff) * horizon) * spacing + 1e-12
    t = wall_toi_swept(g0, p, q, integrator, k, horizon)
    if gaps.min() > margin:
        event("no contact")
        assert t == INF
        return
    below = np.nonzero(gaps < -margin)[0]
    assume(below.size > 0)
    event("contact")
    assert t <= taus[below[0]] + 1e-12
    c1, c2, _ = path_coefficients(integrator, k, t)
    assert abs(g0 + p * c1 + q_eff * c2) <= 1e-9 * max(1.0, g0)
    assert np.all(gaps[taus < t - spacing] > -margin)


def test_the_seeds_sphere_plane_formula_for_straight_paths():
    """t = (r - ((n·C) - d)) / (n·v) for a sphere approaching a plane."""
    n_dot_c, d, r, n_dot_v = 2.5, 0.5, 0.25, -3.0
    t = wall_toi_swept(n_dot_c - d - r, n_dot_v, 0.0, EULER, 0.0, 10.0)
    assert t == (r - (n_dot_c - d)) / n_dot_v


def test_ball_thrown_up_from_the_floor_comes_back_at_two_v_over_g():
    # touching, moving away, pulled back: the next contact is the landing, not "now"
    t = wall_toi_swept(0.0, 3.0, -9.81, EXACT, 0.0, 2.0)
    assert t == pytest.approx(2 * 3.0 / 9.81, rel=1e-14)
    assert wall_toi_swept(0.0, 3.0, -9.81, EXACT, 0.0, 0.5) == INF


# ----------------------------------------------------------------------------- tunnelling
def _thin_wall(detection):
    scene = load_scene("bullet-wall", [f"detection={detection}", "steps=1"])
    world = scene.build_world()
    world.step(0.1)
    return world.state.positions[0], world.state.velocities[0]


def test_thin_wall_swept_reflects_with_no_lost_time():
    """r = 0.1 at +100 m/s from x = 0, wall at x = 1, e = 1, one step of 0.1 s."""
    position, velocity = _thin_wall("swept")
    np.testing.assert_allclose(position, [-8.2, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(velocity, [-100.0, 0.0, 0.0], atol=1e-12)


@pytest.mark.parametrize("detection", ["discrete", "sampled"])
def test_thin_wall_discrete_and_sampled_tunnel(detection):
    position, velocity = _thin_wall(detection)
    assert position[0] == pytest.approx(10.0)  # straight through the wall
    assert velocity[0] == 100.0


@pytest.mark.parametrize("detection", ["discrete", "sampled"])
def test_a_sample_past_a_thin_wall_is_logged_as_a_miss_not_a_found_contact(detection):
    from physdbg.events import OUTCOME_MISS
    from physdbg.observe import ListObserver

    scene = load_scene("bullet-wall", [f"detection={detection}"])
    events = ListObserver()
    world = scene.build_world(events)
    world.step(scene.dt)
    tests = events.swept_tests[0]
    assert list(tests.outcome) == [OUTCOME_MISS] and np.isnan(tests.toi[0])
    # ...while a sample inside the slab is a contact: a slow sphere is caught
    assert wall_toi_sampled(0.05, -1.0, 0.0, EULER, 0.0, 0.1, 1, 0.2) == 0.1
    assert wall_toi_sampled(0.05, -10.0, 0.0, EULER, 0.0, 0.1, 1, 0.2) == INF


def test_sampled_detection_catches_what_falls_between_its_samples_only_if_slow():
    # a wall 0.3 m ahead; 4 samples over 1 s: at 1 m/s it is caught at a sample...
    assert wall_toi_sampled(0.3, -1.0, 0.0, EULER, 0.0, 1.0, 4, INF) == 0.5
    # ...and a sphere pair crossing between samples is missed (the seed's case c)
    dx = np.array([-1.0, 0.0, 0.0])
    assert pair_toi_sampled(dx, np.array([2.6, 0.0, 0.0]), np.zeros(3), 0.2, EULER, 0.0, 1.0, 4) == INF
    assert pair_toi_swept(dx, np.array([2.6, 0.0, 0.0]), np.zeros(3), 0.2, EULER, 0.0, 1.0, 0.0) < 1.0


# ----------------------------------------------------------------------------- sphere–triangle
def _closest_distances(points, tri):
    """Distance (K,) from points (K, 3) to a triangle tri (3, 3), or to one triangle each
    (K, 3, 3): the nearest of its three edges and, where the point's foot on the plane lies
    inside, its face. Plain numpy over all K at once, apart from the engine's closest point
    (which test_the_closest_point_of_a_triangle_is_closer_than_any_sampled_point_of_it holds)."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    tri = np.broadcast_to(np.asarray(tri, dtype=float), (len(points), 3, 3))
    corners = tri[:, 0], tri[:, 1], tri[:, 2]
    edges = list(zip(corners, corners[1:] + corners[:1]))

    def dot(u, w):
        return np.einsum("ki,ki->k", u, w)

    nearest = np.full(len(points), np.inf)
    for p, q in edges:
        along = np.clip(dot(points - p, q - p) / dot(q - p, q - p), 0.0, 1.0)
        nearest = np.minimum(nearest, np.linalg.norm(points - (p + along[:, None] * (q - p)), axis=1))
    normal = np.cross(corners[1] - corners[0], corners[2] - corners[0])
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    height = dot(points - corners[0], normal)
    foot = points - height[:, None] * normal
    inside = np.logical_and.reduce([dot(np.cross(q - p, foot - p), normal) >= 0.0 for p, q in edges])
    return np.where(inside, np.minimum(np.abs(height), nearest), nearest)


def _center_at(x, v, a, integrator, t):
    """The sphere's centre (3,) at local time t (s), or (T, 3) at times t (T,)."""
    from physdbg.engine.motion import STRAIGHT_PATH

    times = np.atleast_1d(t)
    p1, p2 = np.array([path_coefficients(integrator, 0.0, s)[:2] for s in times]).T
    centers = x + v * p1[:, None] + (0.0 if STRAIGHT_PATH[integrator] else 1.0) * a * p2[:, None]
    return centers if np.ndim(t) else centers[0]


def test_the_closest_point_of_a_triangle_is_closer_than_any_sampled_point_of_it():
    from physdbg.engine.mesh.closest import FACE, FEATURE_NAMES, closest_on_triangle

    rng = np.random.default_rng(3)
    weights = rng.dirichlet((1, 1, 1), 3000)  # points spread over the triangle
    seen = set()
    for _ in range(300):
        tri = rng.uniform(-1, 1, (3, 3))
        p = rng.uniform(-2, 2, 3)
        *q, feature = closest_on_triangle(*p, *tri.ravel())
        seen.add(FEATURE_NAMES[feature])
        best = np.min(np.linalg.norm(weights @ tri - p, axis=1))
        assert np.linalg.norm(p - np.array(q)) <= best + 1e-12
    assert len(seen) == 7 and FEATURE_NAMES[FACE] == "face"  # every feature is met


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), integrator=st.sampled_from([EULER, VERLET, EXACT]),
       speed=st.floats(0.5, 40.0), radius=st.floats(0.02, 0.5))
@pytest.mark.slow
def test_sphere_triangle_time_of_impact_against_fine_sampling(seed, integrator, speed, radius):
    """The swept time of impact lies between the last sampled instant clear of the
    triangle and the first touching one (10,000 samples), is a real touch, and none is
    missed: every sample before it is clear."""
    from physdbg.engine.toi import triangle_toi_swept

    rng = np.random.default_rng(seed)
    tri = rng.uniform(-1, 1, (3, 3))
    assume(np.linalg.norm(np.cross(tri[1] - tri[0], tri[2] - tri[0])) > 0.05)
    x = rng.uniform(-3, 3, 3)
    assume(_closest_distances(x[None], tri)[0] > radius + 1e-6)
    target = rng.dirichlet((1, 1, 1)) @ tri + rng.normal(0, 0.3, 3)  # mostly at the triangle, some misses
    v = (target - x) / np.linalg.norm(target - x) * speed
    a = np.array([0.0, 0.0, -9.81])
    horizon = 0.4
    t, feature, _passes = triangle_toi_swept(*x, *v, *a, radius, tri, integrator, 0.0, horizon, 1e-10)
    times = np.linspace(0.0, horizon, 10_001)
    gaps = _closest_distances(_center_at(x, v, a, integrator, times), tri) - radius
    inside = np.nonzero(gaps <= 0.0)[0]
    if len(inside):
        first = inside[0]
        assert feature >= 0 and times[first - 1] - 1e-9 <= t <= times[first] + 1e-9
    if t != math.inf:
        assert 0 <= feature <= 6
        assert _closest_distances(_center_at(x, v, a, integrator, t)[None], tri)[0] - radius <= 1e-8
        assert np.all(gaps[times < t - 1e-9] > -1e-9)
    else:
        assert len(inside) == 0


def _moving_corners(tri, motion, tau):
    """A moving triangle's corners (3, 3) at tau (s), or (T, 3, 3) at taus (T,):
    R(w·tau)(c - P) + P + v·tau (motion: P, v, w), R by Rodrigues' formula, written here
    over all taus at once (rigid_motion.rotation_about takes one tau; tests/test_rigid_motion.py
    holds the engine's turns to it), and apart from the engine's own."""
    pivot, velocity, spin = motion[:3], motion[3:6], motion[6:]
    taus = np.atleast_1d(tau)
    speed = np.linalg.norm(spin)
    k = np.cross(np.eye(3), spin / speed)  # the cross-product matrix of the axis
    angle = (speed * taus)[:, None, None]
    turns = np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)
    corners = (tri - pivot) @ turns.transpose(0, 2, 1) + pivot + velocity * taus[:, None, None]
    return corners if np.ndim(tau) else corners[0]


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), integrator=st.sampled_from([EULER, VERLET, EXACT]),
       pace=st.floats(0.0, 2.0), spin=st.floats(0.5, 60.0), radius=st.floats(0.02, 0.3),
       tau0=st.floats(0.0, 0.05))
@pytest.mark.slow
def test_sphere_against_a_rotating_triangle_against_fine_sampling(seed, integrator, pace, spin, radius, tau0):
    """A triangle turning (up to 60 rad/s) about a pivot and sliding: the swept time of
    impact lies between the last clear sample and the first touching one of 10,000 (the
    triangle placed at each sample by the closed form, independently of the engine's
    frame change), is a touch, and no earlier touch is missed; also from an anchor tau0
    into the step (the triangle has moved on by then)."""
    from physdbg.engine.toi import moving_triangle_toi_swept

    rng = np.random.default_rng(seed)
    tri = rng.uniform(-1, 1, (3, 3))
    assume(np.linalg.norm(np.cross(tri[1] - tri[0], tri[2] - tri[0])) > 0.05)
    axis = rng.normal(size=3)
    motion = np.concatenate([rng.uniform(-0.5, 0.5, 3), rng.normal(0, 2.0, 3), axis / np.linalg.norm(axis) * spin])
    horizon = 0.25
    # aimed at where the triangle will be at some instant of the horizon, arriving about
    # then (pace 1: just then), from up to 1.5 m away: touches, grazes and misses all common
    meet = rng.uniform(0.02, horizon)
    target = rng.dirichlet((1, 1, 1)) @ _moving_corners(tri, motion, tau0 + meet) + rng.normal(0, 0.1, 3)
    away = rng.normal(size=3)
    x = target + away / np.linalg.norm(away) * rng.uniform(0.3, 1.5)
    assume(_closest_distances(x[None], _moving_corners(tri, motion, tau0))[0] > radius + 1e-6)
    v = (target - x) / meet * (0.7 + 0.3 * pace)
    a = np.array([0.0, 0.0, -9.81])
    t, feature, _passes = moving_triangle_toi_swept(*x, *v, *a, radius, tri, motion, tau0, integrator, 0.0, horizon, 1e-10)
    times = np.linspace(0.0, horizon, 10_001)
    gaps = _closest_distances(_center_at(x, v, a, integrator, times), _moving_corners(tri, motion, tau0 + times)) - radius
    inside = np.nonzero(gaps <= 0.0)[0]
    event("touches" if len(inside) else "misses")
    if len(inside):
        first = inside[0]
        assert feature >= 0 and times[first - 1] - 1e-9 <= t <= times[first] + 1e-9
    if t != math.inf:
        assert 0 <= feature <= 6
        at = _closest_distances(_center_at(x, v, a, integrator, t)[None], _moving_corners(tri, motion, tau0 + t))
        assert at[0] - radius <= 1e-7
        assert np.all(gaps[times < t - 1e-9] > -1e-9)
    else:
        assert len(inside) == 0


def test_a_paddle_sweeping_a_resting_ball_is_caught_by_the_swept_test_and_missed_by_the_discrete_one():
    """A plate turning at 30 rad/s sweeps 0.3 m at 1 m from its axis in a 0.01 s step:
    the swept test finds the touch of a ball at rest in its way (at the time the plate's
    face reaches it), the discrete test, looking only at the step's end, misses it."""
    from physdbg.engine.toi import moving_triangle_toi_sampled, moving_triangle_toi_swept

    # a triangle of the plate x in [0, 1.2], z = 0 (y up to 0.2), turning about +y
    tri = np.array([[0.0, 0.0, 0.0], [1.2, 0.0, 0.0], [1.2, 0.2, 0.0]])
    motion = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 30.0, 0.0])
    ball = np.array([1.0, 0.1, -0.15])  # in the plate's way: R_y turns +x towards -z
    radius = 0.05
    t, _, _ = moving_triangle_toi_swept(*ball, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, radius, tri, motion, 0.0, EULER, 0.0,
                                     0.01, 1e-12)
    # the face (z = 0 in the plate) reaches the ball's near side when its angle is asin(0.05 / |arm|)
    # short of the ball's own angle atan2(0.15, 1.0), the arm being the ball's distance from the axis
    arm = math.hypot(1.0, 0.15)
    expected = (math.atan2(0.15, 1.0) - math.asin(radius / arm)) / 30.0
    assert t == pytest.approx(expected, rel=1e-9)
    missed, *_ = moving_triangle_toi_sampled(*ball, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, radius, tri, motion, 0.0, EULER,
                                            0.0, 0.01, 1)
    assert missed == INF


def test_a_sphere_falling_on_a_triangle_touches_its_face_edge_or_corner_as_aimed():
    from physdbg.engine.mesh.closest import CORNER_0, EDGE_0, FACE
    from physdbg.engine.toi import triangle_toi_sampled, triangle_toi_swept

    tri = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    down = (0.0, 0.0, -2.0)
    for start, expected, feature in (((0.25, 0.25, 1.0), 0.45, FACE), ((0.5, -0.05, 1.0), None, EDGE_0),
                                     ((-0.05, -0.05, 1.0), None, CORNER_0)):
        t, found, _ = triangle_toi_swept(*start, *down, 0.0, 0.0, 0.0, 0.1, tri, EULER, 0.0, 1.0, 1e-12)
        assert found == feature
        if expected is not None:
            assert t == pytest.approx(expected, abs=1e-12)  # (1 − 0.1) / 2 m/s
    # discrete: one sample at the end of the step; a fast sphere passes through unseen
    t, found, *_ = triangle_toi_sampled(0.25, 0.25, 1.0, 0.0, 0.0, -20.0, 0.0, 0.0, 0.0, 0.1, tri, EULER, 0.0, 0.1, 1)
    assert t == math.inf and found == -1
    t, found, _ = triangle_toi_swept(0.25, 0.25, 1.0, 0.0, 0.0, -20.0, 0.0, 0.0, 0.0, 0.1, tri, EULER, 0.0, 0.1, 1e-12)
    assert t == pytest.approx(0.045, abs=1e-12) and found == FACE
