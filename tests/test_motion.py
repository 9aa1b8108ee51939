"""Integrators and drag against their closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from physdbg.engine.motion import EXACT, VERLET, _quantile_99, path_coefficients, velocity_coefficients

from .conftest import make_state, make_world

G = 9.81


def _fall(integrator, dt=0.01, steps=100, drag=1.0, velocity=(0.0, 0.0, 0.0), dts=None):
    state = make_state([[0.0, 0.0, 0.0]], [velocity])
    world, _ = make_world(state, observe=False, integrator=integrator, gravity=(0.0, -G, 0.0), drag=drag)
    for step_dt in dts if dts is not None else [dt] * steps:
        world.step(step_dt)
    return world.state.positions[0].copy(), world.state.velocities[0].copy(), world.time


@pytest.mark.parametrize("integrator, error_cm", [
    ("euler", +4.905), ("semi-implicit", -4.905), ("verlet", 0.0), ("exact", 0.0)])
def test_position_error_under_gravity_after_one_second(integrator, error_cm):
    position, velocity, t = _fall(integrator)
    exact = -0.5 * G * t * t
    assert (position[1] - exact) * 100 == pytest.approx(error_cm, abs=1e-9)
    assert velocity[1] == pytest.approx(-G * t, rel=1e-12)  # all four get the velocity right


def test_explicit_euler_is_exactly_the_seeds_update():
    """P_new = P_old + v t (old velocity), v_new = v d^t + a t."""
    d, dt = 0.9, 0.05
    v0 = np.array([1.0, 2.0, -3.0])
    position, velocity, _ = _fall("euler", dt=dt, steps=1, drag=d, velocity=tuple(v0))
    np.testing.assert_array_equal(position, v0 * dt)
    np.testing.assert_allclose(velocity, v0 * d**dt + np.array([0.0, -G, 0.0]) * dt, rtol=1e-15)


@pytest.mark.parametrize("integrator", ["euler", "semi-implicit", "verlet", "exact"])
def test_drag_alone_decays_as_d_to_the_t_whatever_the_frame_rate(integrator):
    """v(t) = v0 d^t: the seed's frame-rate independent drag, with uneven steps too."""
    d = 0.5
    rng = np.random.default_rng(3)
    dts = rng.uniform(0.001, 0.05, size=60)
    state = make_state([[0.0, 0.0, 0.0]], [[2.0, -1.0, 0.5]])
    world, _ = make_world(state, observe=False, integrator=integrator, gravity=(0.0, 0.0, 0.0), drag=d)
    for dt in dts:
        world.step(float(dt))
    np.testing.assert_allclose(world.state.velocities[0], np.array([2.0, -1.0, 0.5]) * d ** dts.sum(), rtol=1e-12)


@pytest.mark.parametrize("dt", [1 / 240, 1 / 60, 1 / 7, 0.5])
def test_exact_integrator_follows_the_closed_form_with_drag_and_gravity(dt):
    """dv/dt = g - k v, k = -ln d:  v = v0 e^(-kt) + g(1-e^(-kt))/k, x = ∫v, for any dt."""
    d = 0.3
    k = -math.log(d)
    v0 = np.array([3.0, 4.0, 0.0])
    g = np.array([0.0, -G, 0.0])
    steps = int(round(2.0 / dt))
    position, velocity, t = _fall("exact", dt=dt, steps=steps, drag=d, velocity=tuple(v0))
    decay = math.exp(-k * t)
    expected_v = v0 * decay + g * (1 - decay) / k
    expected_x = v0 * (1 - decay) / k + g / k * (t - (1 - decay) / k)
    np.testing.assert_allclose(velocity, expected_v, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(position, expected_x, rtol=1e-12, atol=1e-12)


@settings(max_examples=200, deadline=None)
@given(k=st.floats(0.0, 50.0), tau=st.floats(0.0, 2.0))
def test_path_coefficients_are_the_closed_form_everywhere(k, tau):
    """phi1 = (1-e^(-k tau))/k, phi2 = (tau - phi1)/k, and their k -> 0 limits."""
    p1, p2, dp1 = path_coefficients(EXACT, k, tau)
    if k * tau < 1e-6:
        assert p1 == pytest.approx(tau, rel=1e-5, abs=1e-300)
        assert p2 == pytest.approx(0.5 * tau * tau, rel=1e-5, abs=1e-300)
    else:
        ref1 = -math.expm1(-k * tau) / k
        # tau - phi1 in high precision via the series tail when k tau is small
        assert p1 == pytest.approx(ref1, rel=1e-14)
        if k * tau > 0.1:
            assert p2 == pytest.approx((tau - ref1) / k, rel=1e-12)
    assert dp1 == pytest.approx(math.exp(-k * tau), rel=1e-15)
    assert p2 >= 0.0 and p1 <= tau + 1e-300


def test_verlet_path_is_the_parabola_and_velocity_has_the_seeds_drag():
    assert path_coefficients(VERLET, 0.0, 0.3) == (0.3, 0.5 * 0.3 * 0.3, 1.0)
    damp, gain = velocity_coefficients(VERLET, 0.5, math.log(2.0), 2.0)
    assert damp == 0.25 and gain == 2.0


def _nearby_fastest_reference(x, speed, radius, typical, dt):
    """motion.nearby_fastest in plain numpy: the fastest speed in each sphere's 3 x 3 x 3
    block of cells (side 2 max r + 2 typical dt), or typical where there is no grid."""
    n = len(x)
    cell = 2.0 * radius.max() + 2.0 * typical * dt
    span = x.max(axis=0) - x.min(axis=0)
    if not (np.isfinite(typical) and cell > 0 and np.all(span < 1e6 * cell)):
        return np.full(n, typical)
    dims = (span / cell).astype(np.int64) + 1
    if np.prod(dims) > 8 * n + 4096:
        return np.full(n, typical)
    index = np.minimum(((x - x.min(axis=0)) / cell).astype(np.int64), dims - 1)
    in_cell = np.zeros(tuple(dims))
    np.maximum.at(in_cell, tuple(index.T), np.where(np.isnan(speed), np.inf, speed))
    padded = np.pad(in_cell, 1)
    block = np.max([padded[tuple(index[:, c] + 1 + d[c] for c in range(3))]
                    for d in np.ndindex(3, 3, 3) for d in [np.array(d) - 1]], axis=0)
    return block


def test_the_compiled_reach_is_the_numpy_rule_to_the_bit():
    """World._add_reach's boxes (motion.grow_to_reach) equal the rule written in numpy
    (the 99th-percentile speed by np.quantile, the nearby fastest by the reference above),
    bit for bit, for many sizes and with a NaN velocity (NaN boxes either way)."""
    from physdbg.engine.motion import grow_to_reach

    rng = np.random.default_rng(7)
    for n in (1, 2, 3, 50, 99, 100, 101, 1000, 10_000):
        for nan in (False, True):
            x, v, a = rng.normal(size=(n, 3)), rng.normal(size=(n, 3)) * 3, rng.normal(size=(n, 3))
            if n == 10_000:  # many equal speeds: ties at the order statistics
                v, a = np.round(v), np.zeros((n, 3))
            if nan:
                v[n // 2, 1] = np.nan
            radius, dt, margin = rng.uniform(0.01, 0.1, n), 1 / 60, 1e-9
            lo0, hi0 = x - rng.uniform(0, 0.5, (n, 3)), x + rng.uniform(0, 0.5, (n, 3))
            speed = np.linalg.norm(v, axis=1) + np.linalg.norm(a, axis=1) * dt
            typical = float(np.quantile(speed, 0.99))
            others = np.minimum(_nearby_fastest_reference(x, speed, radius, typical, dt), typical)
            reach = (np.maximum(speed, others) * dt + radius + margin)[:, None]
            want_lo, want_hi = np.minimum(lo0, x - reach), np.maximum(hi0, x + reach)
            lo, hi = lo0.copy(), hi0.copy()
            grow_to_reach(x, v, a, radius, dt, margin, lo, hi)
            np.testing.assert_array_equal(lo, want_lo)
            np.testing.assert_array_equal(hi, want_hi)


def test_a_sphere_far_from_fast_ones_keeps_a_small_box_and_one_near_them_a_large_one():
    """The reach counts only the speeds that could meet a sphere in the step: a still pile
    far below a falling layer is grown by its own speed, the pile's top next to it by the
    layer's (motion.nearby_fastest)."""
    from physdbg.engine.motion import grow_to_reach, nearby_fastest

    lattice = np.stack(np.meshgrid(*[np.arange(10) * 0.1] * 3, indexing="ij"), -1).reshape(-1, 3)
    pile = lattice  # z up to 0.9
    rain = lattice[lattice[:, 2] == 0.0] + [0.0, 0.0, 1.0]  # one layer at z = 1
    x = np.concatenate((pile, rain))
    v = np.zeros_like(x)
    v[len(pile):, 2] = -10.0  # the rain falls at 10 m/s; the pile is still
    radius, dt = np.full(len(x), 0.05), 1 / 240
    speed = np.linalg.norm(v, axis=1)
    nearby = nearby_fastest(x, speed, radius, 10.0, dt)
    assert np.all(nearby[len(pile):] == 10.0)
    bottom, top = pile[:, 2] < 0.35, pile[:, 2] > 0.85
    assert np.all(nearby[:len(pile)][bottom] == 0.0) and np.all(nearby[:len(pile)][top] == 10.0)
    lo, hi = x.copy(), x.copy()
    grow_to_reach(x, v, np.zeros_like(x), radius, dt, 0.0, lo, hi)
    width = (hi - lo)[:, 0]
    np.testing.assert_allclose(width[:len(pile)][bottom], 2 * 0.05)
    np.testing.assert_allclose(width[:len(pile)][top], 2 * (0.05 + 10.0 * dt))
    np.testing.assert_array_equal(nearby_fastest(x, speed, radius, np.nan, dt), np.full(len(x), np.nan))


@settings(max_examples=200, deadline=None)
@given(st.sampled_from(["euler", "semi-implicit", "verlet", "exact"]), st.sampled_from([0.0, 0.7]),
       st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3), st.lists(st.floats(-20.0, 20.0), min_size=3, max_size=3),
       st.floats(0.0, 0.01))
@pytest.mark.slow
def test_particle_box_holds_the_path_and_its_extremes(integrator, k, velocity, acceleration, anchor):
    """The box of a path from its anchor to the step's end holds every point of the path
    (sampled densely) and is no larger than its extremes (the closed-form parabola vertex
    and the bisection for drag paths agree with sampling)."""
    from physdbg.engine.motion import INTEGRATOR_NAMES, particle_box

    code = INTEGRATOR_NAMES.index(integrator)
    x = np.array([[0.1, 0.2, 0.3]])
    v = np.array([velocity])
    a = np.array([acceleration])
    step_end = 0.02
    lo = np.empty(3)
    hi = np.empty(3)
    particle_box(x, v, a, np.array([0.05]), np.array([anchor]), 0, step_end, code, k, 1e-9, lo, hi)
    taus = np.linspace(0.0, step_end - anchor, 4001)
    points = np.array([x[0] + v[0] * p1 + a[0] * p2 for p1, p2, _ in (path_coefficients(code, k, t) for t in taus)])
    pad = 0.05 + 1e-9
    assert np.all(points.min(axis=0) - pad >= lo - 1e-15) and np.all(points.max(axis=0) + pad <= hi + 1e-15)
    # tight: within what 4 000 samples can miss of a path this short
    assert np.all(lo >= points.min(axis=0) - pad - 1e-7) and np.all(hi <= points.max(axis=0) + pad + 1e-7)


@settings(max_examples=300, deadline=None)
@given(n=st.integers(1, 3000), seed=st.integers(0, 2**32 - 1), levels=st.sampled_from([2, 5, 0]),
       order=st.sampled_from(["as drawn", "ascending", "descending"]))
def test_the_99th_percentile_speed_is_numpys_to_the_bit(n, seed, levels, order):
    """The grown boxes' typical speed (motion._quantile_99) is np.quantile(·, 0.99) exactly,
    with ties (speeds drawn from a few levels) and sorted input (the selection's worst
    case) included; a NaN gives NaN."""
    rng = np.random.default_rng(seed)
    speeds = rng.integers(0, levels, n) * 1.5 if levels else rng.exponential(3.0, n)
    if order != "as drawn":
        speeds = np.sort(speeds)[:: 1 if order == "ascending" else -1].copy()
    assert _quantile_99(speeds) == np.quantile(speeds, 0.99)
    speeds[n // 2] = np.nan
    assert math.isnan(_quantile_99(speeds))
