"""Sleeping spheres (engine/sleep.py): who may sleep, when they sleep and wake, what it costs."""

from __future__ import annotations

import numpy as np
import pytest

from physdbg.engine import Settings, World
from physdbg.events import CONTACT_ROW, KIND_PAIR
from physdbg.engine.resting import HELD, held_add, new_held
from physdbg.engine.sleep import SUPPORT_GAP, can_sleep, release_static
from physdbg.errors import SceneError
from physdbg.api import load_scene

from .conftest import make_state, make_walls

G = 9.81
SLEEP = {"sleep_speed": 0.05, "sleep_time": 0.1}


def _world(positions, velocities=None, *, restitution=0.5, radius=0.1, gravity=(0.0, -G, 0.0), **settings):
    state = make_state(positions, velocities, radius=radius, restitution=restitution)
    floor = make_walls(([0, 1, 0], 0.0, restitution))
    return World(state, floor, Settings(gravity=gravity, **{**SLEEP, **settings}))


def test_only_a_sphere_gravity_would_carry_through_the_sleep_speed_quickly_may_sleep():
    """A sphere in free flight is at most v_s fast for v_s/g + v_s/(g - k·v_s) seconds."""
    g = np.array([[0.0, -G, 0.0], [0.0, -G, 0.0], [0.0, 0.0, 0.0], [0.0, -0.01, 0.0]])
    allowed = can_sleep(g, 0.0, 0.05, 0.5)
    assert allowed.tolist() == [True, True, False, False]  # no gravity, or too little, never sleeps
    flight = 2 * 0.05 / G  # 0.0102 s at the top of a flight
    assert can_sleep(g[:1], 0.0, 0.05, 1.01 * flight).tolist() == [True]
    assert can_sleep(g[:1], 0.0, 0.05, 0.99 * flight).tolist() == [False]
    # drag slows the fall: with g <= k·v_s a sphere could drift slower than v_s for ever
    assert can_sleep(g[:1], G / 0.05, 0.05, 100.0).tolist() == [False]


def test_every_pair_the_rules_count_as_touching_is_a_candidate_whatever_the_reach():
    """The rules read the step's candidate pairs; a still sphere's box grows by little more
    than its radius, so two still spheres a hair apart (within SUPPORT_GAP, "touching")
    must still be paired: with sleeping, every box is padded by the touching distance.
    (Before, the broad phase's generous reach usually paired them, and a tighter one
    changed which spheres fell asleep.)"""
    r = 0.1
    gap = 0.8 * SUPPORT_GAP * 2 * r  # touching for the rules, yet far beyond a still sphere's reach
    for sleep_speed, paired in ((0.05, True), (0.0, False)):
        world = _world([[0.0, r, 0.0], [2 * r + gap, r, 0.0]], radius=r, sleep_speed=sleep_speed)
        world.step(1 / 240)
        assert ([0, 1] in world.last_step.pairs.tolist()) is paired


def _step_until(world, counted: str, limit: int):
    """Step (1/60 s) until a step's stats count ``counted`` (slept, woken); returns its stats."""
    for _ in range(limit):
        stats = world.step(1 / 60)
        assert stats.max_overlap <= world.settings.contact_tolerance
        if getattr(stats.counts, counted):
            return stats
    raise AssertionError(f"no step counted {counted} in {limit} steps")


def test_a_dropped_ball_comes_to_rest_then_sleeps_exactly_where_it_lies():
    world = _world([[0.0, 0.6, 0.0]])
    stats = _step_until(world, "slept", 600)
    assert stats.counts.asleep == 1
    lying = world.state.positions.copy()
    assert world.state.velocities.tolist() == [[0.0, 0.0, 0.0]]
    assert lying[0, 1] == pytest.approx(0.1, abs=1e-9)  # on the floor
    for _ in range(60):
        stats = world.step(1 / 60)
        assert (stats.counts.contacts, stats.counts.asleep, stats.counts.slept, stats.counts.woken) == (0, 1, 0, 0)
        assert stats.kinetic == 0.0
    assert np.array_equal(world.state.positions, lying)  # to the bit: no gravity, no motion


def test_sleeping_is_off_by_default_and_then_nothing_sleeps():
    state = make_state([[0.0, 0.6, 0.0]], restitution=0.5)
    world = World(state, make_walls(([0, 1, 0], 0.0, 0.5)), Settings())
    for _ in range(300):
        stats = world.step(1 / 60)
    assert world.sleepers is None and (stats.counts.asleep, stats.counts.slept, stats.counts.woken) == (0, 0, 0)


def test_a_stack_sleeps_from_the_floor_up_and_a_hit_on_its_foot_wakes_it_all():
    """Two balls stacked on the floor fall asleep; a third slides along the (frictionless)
    floor at 6 m/s, too fast to sleep, and hits the bottom one."""
    world = _world([[0.0, 0.1, 0.0], [0.0, 0.3, 0.0], [12.0, 0.1, 0.0]], [[0, 0, 0], [0, 0, 0], [-6.0, 0, 0]])
    stats = _step_until(world, "slept", 60)
    assert world.sleepers.asleep.tolist() == [True, True, False]  # together: the lower one lets the upper sleep
    stats = _step_until(world, "woken", 180)
    # the bottom ball was hit (rule 2) and the one resting on it woke with it (rule 3)
    assert stats.counts.woken == 2 and not world.sleepers.asleep.any()
    # within the step of the impact the sleeper did not move: the ball bounced off it
    assert world.state.velocities[0].tolist() == [0.0, 0.0, 0.0]
    assert world.state.velocities[2, 0] > 0.0


def test_a_ball_on_an_awake_one_does_not_fall_asleep_before_it():
    """Rule 4: the upper ball is slow from the start, but sleeps only once the lower one does."""
    world = _world([[0.0, 0.1, 0.0], [0.0, 0.3, 0.0]])
    world.sleepers.allowed[0] = False  # the lower ball may never sleep
    for _ in range(60):
        stats = world.step(1 / 60)
    assert stats.counts.asleep == 0
    world.sleepers.allowed[0] = True
    for _ in range(30):
        stats = world.step(1 / 60)
    assert stats.counts.asleep == 2


def test_a_slow_ball_in_a_box_without_gravity_never_sleeps():
    world = _world([[0.0, 0.5, 0.0]], [[0.01, 0.0, 0.0]], gravity=(0.0, 0.0, 0.0), restitution=1.0)
    for _ in range(120):
        stats = world.step(1 / 60)
    assert stats.counts.asleep == 0 and world.state.velocities[0, 0] == 0.01


def test_a_held_contact_between_two_immovable_ends_is_released():
    h = new_held(3)
    held_add(h, 0, 0, 1, 0.0, 1.0, 0.0)  # spheres 0 and 1
    held_add(h, 0, 1, 2, 0.0, 1.0, 0.0)  # spheres 1 and 2
    held_add(h, 1, 2, 0, 0.0, 1.0, 0.0)  # sphere 2 and wall 0
    released = release_static(h, np.array([0.0, 1.0, 0.0]))  # sphere 1 can move
    assert released == 1 and int(h.count[HELD]) == 2
    assert sorted((int(h.kind[c]), int(h.a[c]), int(h.other[c])) for c in range(2)) == [(0, 0, 1), (0, 1, 2)]


NARROW_PILE = ["generate.count=100", "box.max=[0.3,1,0.3]", "generate.speed=0", "generate.restitution=0.5",
               "box.restitution=0.5", "rapid_contact_rule=tc", "sleep_speed=0"]  # rain sleeps by itself


def test_without_sleeping_the_narrow_pile_collapses():
    """The pile below, awake: its bed rattles ever faster until the event cap stops a step."""
    scene = load_scene("rain", [*NARROW_PILE, "steps=60"])
    world = scene.build_world()
    codes = set()
    for _ in range(scene.steps):
        codes.update(w.code for w in world.step(scene.dt).warnings)
    assert "max_contacts_per_step" in codes


@pytest.mark.slow
def test_a_pile_falls_asleep_exactly_and_sleeping_never_adds_energy():
    """100 spheres dropped into a narrow box pile up and every one falls asleep: no contact,
    no event, no motion is left, and no step left an overlap or gained energy beyond the
    simultaneous solves' rounding (5e-9 of it in the worst step here)."""
    scene = load_scene("rain", [*NARROW_PILE, "sleep_speed=0.05", "sleep_time=0.1", "steps=240"])
    world = scene.build_world()
    energy = None
    slept = 0
    for _ in range(scene.steps):
        before = energy
        stats = world.step(scene.dt)
        energy = stats.kinetic + stats.potential
        slept += stats.counts.slept
        assert stats.max_overlap <= scene.settings.contact_tolerance and not stats.warnings
        if before is not None:
            assert energy <= before + 1e-7 * abs(before)
    assert slept >= 100 and stats.counts.asleep == 100 and (stats.counts.contacts, stats.counts.events, stats.kinetic) == (0, 0, 0.0)


def test_only_slow_spheres_fall_asleep_and_only_their_kinetic_energy_goes():
    """end_of_step zeroes the velocities of the spheres that fall asleep, each at most v_s
    fast, and touches no other."""
    from physdbg.engine.sleep import Sleepers

    free = np.tile([0.0, -G, 0.0], (4, 1))
    sleepers = Sleepers(free, 0.0, 0.05, 0.1)
    x = np.array([[0.0, 0.1, 0.0], [1.0, 0.1, 0.0], [2.0, 0.1, 0.0], [3.0, 0.1, 0.0]])
    v = np.array([[0.03, 0.0, 0.0], [0.0, 0.049, 0.0], [0.2, 0.0, 0.0], [0.0, 0.0, 0.0]])
    radius = np.full(4, 0.1)
    no_pairs = (np.empty((0, 2), np.int64), np.empty((0, 2), np.int64))
    for _ in range(5):  # 5 steps of 0.02 s: slow for 0.1 s
        before = v.copy()
        fell, woke = sleepers.end_of_step(0.02, x, v, radius, no_pairs, np.zeros(0, CONTACT_ROW))
    assert fell.tolist() == [0, 1, 3] and woke.size == 0
    assert np.array_equal(v[2], before[2]) and not v[[0, 1, 3]].any()
    removed = 0.5 * np.einsum("ij,ij->i", before, before)[fell]
    assert (removed <= 0.5 * 0.05**2).all()
    # a sphere hit while asleep wakes; its slow time starts again
    hit = np.zeros(1, CONTACT_ROW)
    hit["kind"], hit["a"], hit["other"], hit["closing_speed"] = KIND_PAIR, 1, 2, 0.5
    fell, woke = sleepers.end_of_step(0.02, x, v, radius, no_pairs, hit)
    assert woke.tolist() == [1] and fell.size == 0 and sleepers.still[1] == 0.0


def test_a_scene_cannot_sleep_in_a_periodic_box():
    with pytest.raises(SceneError, match="sleep_speed"):
        load_scene("gas", ["sleep_speed=0.1", "box.periodic=true"])


def test_same_scene_with_sleeping_gives_the_same_hashes():
    hashes = []
    for _ in range(2):
        scene = load_scene("rain", ["generate.count=40", "sleep_speed=0.05", "sleep_time=0.1", "steps=200"])
        world = scene.build_world()
        hashes.append([world.step(scene.dt).state_hash for _ in range(scene.steps)])
    assert hashes[0] == hashes[1]


# ----------------------------------------------------------------------------- the rules, slowly
def _reference_rules(sleepers, dt, x, velocities, radius, pair_lists, rows):
    """The sleep rules in plain numpy (sleep.py's module doc, each fixed point reached by
    repeating its rule over every pair until nothing changes): the reference the compiled
    sleep_rules must match. In place on sleepers and velocities; returns (fell, woke)."""
    from physdbg.engine.sleep import SUPPORT_GAP

    asleep = sleepers.asleep
    pairs = np.concatenate(pair_lists)
    fast = (rows["kind"] == KIND_PAIR) & (rows["closing_speed"] > sleepers.sleep_speed)
    a, b = rows["a"][fast].astype(np.int64), rows["other"][fast].astype(np.int64)
    disturbed = np.unique(np.concatenate((a[asleep[a] & ~asleep[b]], b[asleep[b] & ~asleep[a]])))
    i, j = pairs[:, 0], pairs[:, 1]
    d = x[i] - x[j]
    reach = (1.0 + SUPPORT_GAP) * (radius[i] + radius[j])
    near = np.einsum("ij,ij->i", d, d) <= reach * reach
    i, j, d = i[near], j[near], -d[near]
    j_below = np.einsum("ij,ij->i", d, sleepers.down[i]) > 0.0
    i_below = np.einsum("ij,ij->i", -d, sleepers.down[j]) > 0.0
    upper = np.concatenate((i[j_below], j[i_below]))
    lower = np.concatenate((j[j_below], i[i_below]))
    waking = np.zeros_like(asleep)
    waking[disturbed] = True
    while True:
        more = upper[(~asleep[lower] | waking[lower]) & asleep[upper] & ~waking[upper]]
        if more.size == 0:
            break
        waking[more] = True
    woke = np.nonzero(waking)[0]
    asleep[woke] = False
    speed2 = np.einsum("ij,ij->i", velocities, velocities)
    slow = sleepers.allowed & ~asleep & ~waking & (speed2 <= sleepers.sleep_speed ** 2)
    sleepers.still[:] = np.where(slow, sleepers.still + dt, 0.0)
    ready = slow & (sleepers.still >= sleepers.sleep_time)
    while True:
        blocked = upper[ready[upper] & ~(asleep[lower] | ready[lower])]
        if blocked.size == 0:
            break
        ready[blocked] = False
    fell = np.nonzero(ready)[0]
    asleep[fell] = True
    sleepers.still[fell] = 0.0
    velocities[fell] = 0.0
    return fell, woke


def test_the_compiled_rules_match_the_plain_ones_on_a_pile_falling_asleep_and_waking():
    """Every step of a pile falling asleep (and parts of it woken again as it settles):
    the compiled rules (worklists) and the plain ones (repeat until nothing changes) agree
    on who sleeps, who wakes, each sphere's slow time and the zeroed velocities."""
    import copy

    from physdbg.engine.sleep import Sleepers

    scene = load_scene("rain", [*NARROW_PILE, "sleep_speed=0.1", "sleep_time=0.1", "steps=240"])
    world = scene.build_world()
    compiled = Sleepers.end_of_step
    seen = {"fell": 0, "woke": 0, "steps": 0}

    def checked(self, dt, x, velocities, radius, pair_lists, rows, carried=None):
        twin, v = copy.deepcopy(self), velocities.copy()
        fell, woke = compiled(self, dt, x, velocities, radius, pair_lists, rows, carried)
        if carried is not None:  # a carried sphere may not sleep: the plain rules see it as not allowed
            twin.allowed = twin.allowed & ~carried
        want = _reference_rules(twin, dt, x, v, radius, pair_lists, rows)
        assert fell.tolist() == want[0].tolist() and woke.tolist() == want[1].tolist()
        assert np.array_equal(self.asleep, twin.asleep) and np.array_equal(self.still, twin.still)
        assert np.array_equal(velocities, v)
        seen["fell"] += fell.size
        seen["woke"] += woke.size
        seen["steps"] += 1
        return fell, woke

    Sleepers.end_of_step = checked
    try:
        for _ in range(scene.steps):
            world.step(scene.dt)
    finally:
        Sleepers.end_of_step = compiled
    assert seen["steps"] == scene.steps and seen["fell"] > 100 and seen["woke"] > 0, seen
