"""Impulses and reflections: the 1-D formulas, immovable posts, and conservation laws."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from physdbg.engine.resolve import combine_restitution, seed_impulse
from physdbg.engine.resting import push_along

from .conftest import make_state, make_walls, make_world


def _head_on(m_a, m_b, u_a, u_b, e):
    inverse = [1.0 / m_a, 0.0 if m_b == np.inf else 1.0 / m_b]
    state = make_state([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]], [[u_a, 0, 0], [u_b, 0, 0]],
                       radius=0.25, inverse_mass=inverse, restitution=e)
    world, obs = make_world(state, gravity=(0.0, 0.0, 0.0))
    for _ in range(20):
        world.step(0.1)
    # one collision; with e = 0 the pair then moves on touching, and rounding may give
    # another contact with a closing speed of order 1e-16 right after, which the
    # rapid-contact rule holds (it changes nothing measurable); the collision itself is
    # an impulse, not held
    collisions = [c for c in obs.contacts if c.closing_speed > 1e-12]
    assert len(collisions) == 1
    assert not collisions[0].resting
    return world.state.velocities[:, 0], collisions[0]


@pytest.mark.parametrize("e", [0.0, 0.5, 1.0])
@pytest.mark.parametrize("m_a, m_b, u_a, u_b", [(1.0, 3.0, 2.0, -1.0), (5.0, 0.5, 1.5, 0.0), (2.0, 2.0, 1.0, -3.0)])
def test_head_on_collision_matches_the_one_dimensional_formulas(m_a, m_b, u_a, u_b, e):
    v, contact = _head_on(m_a, m_b, u_a, u_b, e)
    total = m_a * u_a + m_b * u_b
    expect_a = (total + m_b * e * (u_b - u_a)) / (m_a + m_b)
    expect_b = (total + m_a * e * (u_a - u_b)) / (m_a + m_b)
    assert v[0] == pytest.approx(expect_a, rel=1e-12, abs=1e-12)
    assert v[1] == pytest.approx(expect_b, rel=1e-12, abs=1e-12)
    # the reported impulse is the seed's j = -(1+c)((va-vb)·n)/(1/ma+1/mb), n from b to a
    j = -(1 + e) * ((u_a - u_b) * -1.0) / (1 / m_a + 1 / m_b)
    assert contact.impulse == pytest.approx(j, rel=1e-12)
    assert contact.restitution == e


@pytest.mark.parametrize("e", [0.0, 0.5, 1.0])
def test_ball_against_an_immovable_post_bounces_with_minus_e_u(e):
    v, contact = _head_on(2.0, np.inf, 3.0, 0.0, e)
    assert v[0] == pytest.approx(-e * 3.0, abs=1e-12)
    assert v[1] == 0.0


def unit(vector):
    return vector / np.linalg.norm(vector)


def reflect(velocity, normal, restitution):
    """The wall reflection as the engine applies it: the seed's impulse against w_b = 0."""
    v = velocity.reshape(1, 3).copy()
    closing = -float(velocity @ normal)
    if closing > 0.0:
        push_along(v, np.ones(1), 0, -1, *normal, seed_impulse(closing, restitution, 1.0))
    return v[0]


def test_wall_reflection_is_the_seeds_mirror_when_e_is_one():
    n = unit(np.array([1.0, 1.0, 0.0]))
    incoming = np.array([-2.0, -1.0, 0.5])
    np.testing.assert_allclose(reflect(incoming, n, 1.0), incoming - 2 * n * (incoming @ n))
    np.testing.assert_allclose(reflect(incoming, n, 0.0) @ n, 0.0, atol=1e-15)
    leaving = -incoming
    np.testing.assert_array_equal(reflect(leaving, n, 1.0), leaving)  # not approaching: untouched


def test_restitution_rules_combine_as_documented():
    assert combine_restitution("min", 0.8, 0.5) == 0.5
    assert combine_restitution("max", 0.8, 0.5) == 0.8
    assert combine_restitution("product", 0.8, 0.5) == pytest.approx(0.4)
    assert combine_restitution("mean", 0.8, 0.5) == pytest.approx(0.65)


def test_wall_restitution_combines_with_the_particle():
    state = make_state([[0.0, 1.0, 0.0]], [[0.0, -2.0, 0.0]], radius=0.1, restitution=0.9)
    walls = make_walls(([0, 1, 0], 0.0, 0.5))
    world, obs = make_world(state, walls, gravity=(0.0, 0.0, 0.0), restitution_rule="product")
    world.step(1.0)
    assert obs.contacts[0].restitution == pytest.approx(0.45)
    assert world.state.velocities[0, 1] == pytest.approx(0.9)


finite = st.floats(-10.0, 10.0, allow_nan=False)
velocity = st.tuples(finite, finite, finite).map(np.array)
inverse_mass = st.one_of(st.just(0.0), st.floats(0.05, 20.0))


@settings(max_examples=400, deadline=None)
@given(v_a=velocity, v_b=velocity, w_a=st.floats(0.05, 20.0), w_b=inverse_mass,
       direction=velocity, c=st.floats(0.0, 1.0))
def test_impulses_conserve_momentum_and_never_add_energy(v_a, v_b, w_a, w_b, direction, c):
    if np.linalg.norm(direction) < 1e-6:
        direction = np.array([1.0, 0.0, 0.0])
    n = unit(direction)
    if w_b == 0.0:
        v_b = np.zeros(3)  # immovable means at rest in physdbg (scenes reject anything else)
    v = np.array([v_a, v_b], dtype=float)
    w = np.array([w_a, w_b])
    closing = -float((v[0] - v[1]) @ n)
    j = seed_impulse(closing, c, w_a + w_b) if closing > 0.0 else 0.0
    before = v.copy()
    push_along(v, w, 0, 1, *n, j)
    assert j >= 0.0
    m_a = 1.0 / w_a
    kinetic = lambda vel: 0.5 * m_a * vel[0] @ vel[0] + (0.5 / w_b * vel[1] @ vel[1] if w_b > 0 else 0.0)
    scale = 1.0 + kinetic(before)
    assert kinetic(v) <= kinetic(before) + 1e-12 * scale
    if w_b > 0:
        momentum = lambda vel: m_a * vel[0] + vel[1] / w_b
        np.testing.assert_allclose(momentum(v), momentum(before), atol=1e-9 * scale)
    else:
        np.testing.assert_array_equal(v[1], before[1])  # the immovable one never moves
    closing_before = (before[0] - before[1]) @ n
    if closing_before < 0:
        # the seed's rule: separating velocity after = -c · before
        assert (v[0] - v[1]) @ n == pytest.approx(-c * closing_before, abs=1e-9 * scale)
