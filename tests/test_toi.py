"""Swept tests: exact time of impact, first root only, and the tunnelling of the others."""

from __future__ import annotations


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
