"""The step pipeline against analytic answers: bounces, cradle, gas, resting, events."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from physdbg.engine import energies
from physdbg.engine.timeline import ROWS
from physdbg.engine.world import wants_swept_tests
from physdbg.events import (
    BroadPhaseInfo,
    KIND_PAIR,
    KIND_WALL,
    OUTCOME_HIT,
    OUTCOME_MISS,
    STEP_PHASES,
    Contacts,
    StepBegin,
    StepEnd,
    SweptTests,
)
from physdbg.observe import FanOut, ListObserver
from physdbg.api import load_scene

from .conftest import make_state, make_walls, make_world

G = 9.81


# ----------------------------------------------------------------------------- bounce
@pytest.mark.parametrize("dt", [1 / 60, 1 / 7])
def test_bouncing_ball_matches_closed_form_for_ten_bounces(dt):
    """Impact times t_{k+1} = t1[1 + 2e(1-e^k)/(1-e)] and apexes e^(2k)·h0, to 1e-9."""
    e, h0, r = 0.8, 1.0, 0.1
    state = make_state([[0.0, h0 + r, 0.0]], radius=r, restitution=e)
    world, obs = make_world(state, make_walls(([0, 1, 0], 0.0, 1.0)), gravity=(0.0, -G, 0.0))
    while len(obs.contacts) < 11:
        world.step(dt)
    starts = {b.step: b.time for b in obs.step_begins}
    t1 = math.sqrt(2 * h0 / G)
    assert t1 == pytest.approx(0.45152, abs=1e-5)
    for k, contact in enumerate(obs.contacts[:10]):
        expected_time = t1 * (1 + 2 * e * (1 - e**k) / (1 - e))
        impact_time = starts[contact.step] + contact.time_in_step
        assert impact_time == pytest.approx(expected_time, rel=1e-9)
        apex = contact.velocity_a_after[1] ** 2 / (2 * G)  # height climbed above the contact
        assert apex == pytest.approx(e ** (2 * (k + 1)) * h0, rel=1e-9)
        assert contact.kind == KIND_WALL and not contact.resting
        assert contact.point[1] == pytest.approx(0.0, abs=1e-12)
    assert obs.contacts[0].velocity_a_after[1] ** 2 / (2 * G) == pytest.approx(0.64, rel=1e-12)


def test_bounce_scene_comes_to_rest_on_the_floor():
    scene = load_scene("bounce")
    world = scene.build_world()
    for _ in range(scene.steps):
        stats = world.step(scene.dt)
    assert world.state.positions[0, 1] == pytest.approx(0.1, abs=1e-9)
    assert np.all(world.state.velocities == 0.0)
    assert stats.counts.held == 1 and stats.counts.contacts == 0


def test_a_held_contact_that_is_kicked_apart_is_counted_as_released():
    """StepEnd.counts.released (the recording's column too): the held contacts
    a step let go of — here the resting ball's, once it is thrown upwards."""
    scene = load_scene("bounce")
    obs = ListObserver()
    world = scene.build_world(obs)
    for _ in range(scene.steps):
        stats = world.step(scene.dt)
    assert stats.counts.held == 1 and stats.counts.released == 0
    world.state.velocities[0] = (0.0, 3.0, 0.0)
    stats = world.step(scene.dt)
    assert stats.counts.held == 0 and stats.counts.released == 1
    assert obs.events[-1].counts.released == 1
    assert world.step(scene.dt).counts.released == 0


# ----------------------------------------------------------------------------- cradle
def _run_cradle(ordering):
    scene = load_scene("cradle", [f"ordering={ordering}"])
    obs = ListObserver()
    world = scene.build_world(obs)
    after_impact = None
    for _ in range(scene.steps):
        world.step(scene.dt)
        if obs.contacts and after_impact is None:
            after_impact = world.state.copy()
    return world, after_impact, obs


def test_cradle_time_ordering_passes_the_blow_to_the_last_ball():
    world, after_impact, obs = _run_cradle("time")
    for state in (after_impact, world.state):
        np.testing.assert_array_equal(state.velocities[:4], 0.0)
        np.testing.assert_allclose(state.velocities[4], [1.0, 0.0, 0.0], rtol=0, atol=1e-15)
    # all four contacts happened in the impact step, in order down the row, at one instant
    assert [c.order for c in obs.contacts] == [0, 1, 2, 3]
    assert [(c.a, c.other) for c in obs.contacts] == [(0, 1), (1, 2), (2, 3), (3, 4)]
    assert len({c.step for c in obs.contacts}) == 1
    # the resting balls never moved; the last one is where the exact answer puts it
    np.testing.assert_allclose(world.state.positions[1:4, 0], [1.0, 2.0, 3.0], atol=1e-12)
    np.testing.assert_allclose(world.state.positions[0, 0], 0.0, atol=1e-12)
    np.testing.assert_allclose(world.state.positions[4, 0], 4.0 + (3.0 - 0.73), atol=1e-12)


def test_cradle_index_ordering_does_not_and_shows_why():
    world, after_impact, obs = _run_cradle("index")
    # after the impact step a middle ball carries the blow, inside its neighbour
    assert after_impact.velocities[1, 0] == pytest.approx(1.0)
    assert after_impact.velocities[4, 0] == 0.0
    assert np.linalg.norm(after_impact.positions[1] - after_impact.positions[2]) < 1.0 - 1e-3
    # one ball per step afterwards: the contacts are spread over four steps
    assert len({c.step for c in obs.contacts}) == 4
    # and the time lost shows at the end: the last ball lags, the middle ones are displaced
    assert world.state.positions[4, 0] < 4.0 + (3.0 - 0.73) - 2 * (1 / 60)
    assert np.max(np.abs(world.state.positions[1:4, 0] - [1.0, 2.0, 3.0])) > 1e-3


# ----------------------------------------------------------------------------- gas
def test_elastic_gas_conserves_energy_over_ten_thousand_steps():
    scene = load_scene("gas", ["generate.count=27", "steps=10000"])
    world = scene.build_world()
    k0, _, _ = energies(world.state, world.gravity)
    contacts = 0
    worst_overlap = 0.0
    for _ in range(scene.steps):
        stats = world.step(scene.dt)
        contacts += stats.counts.contacts
        worst_overlap = max(worst_overlap, stats.max_overlap)
        assert not stats.warnings
    k1, _, _ = energies(world.state, world.gravity)
    assert contacts > 10_000  # it really is a colliding gas
    assert abs(k1 - k0) / k0 < 1e-10
    assert worst_overlap <= scene.settings.contact_tolerance


# ----------------------------------------------------------------------------- resting
@pytest.mark.parametrize("integrator", ["exact", "verlet", "semi-implicit", "euler"])
def test_resting_sphere_stays_at_its_height_with_bounded_events(integrator):
    r = 0.25
    state = make_state([[0.3, r, -0.2]], radius=r, restitution=0.5)
    world, _ = make_world(state, make_walls(([0, 1, 0], 0.0, 0.5)), observe=False,
                          integrator=integrator, gravity=(0.0, -G, 0.0))
    heights = []
    events = []
    for _ in range(10_000):
        stats = world.step(1 / 60)
        heights.append(world.state.positions[0, 1])
        events.append(stats.counts.contacts)
    assert max(abs(h - r) for h in heights) <= 1e-9
    assert max(events) <= 2
    assert sum(events) <= 4  # it settles once, then costs nothing
    assert np.all(world.state.positions[0, [0, 2]] == [0.3, -0.2])


def test_stacks_and_rows_rest_and_a_dropped_ball_settles():
    scene = load_scene("rest")
    world = scene.build_world()
    start = world.state.positions.copy()
    per_step = []
    for _ in range(scene.steps):
        stats = world.step(scene.dt)
        per_step.append(stats.counts.contacts)
        assert stats.max_overlap <= scene.settings.contact_tolerance
    final = world.state.positions
    np.testing.assert_allclose(final[:6], start[:6], atol=1e-9)  # stack and row unmoved
    assert final[6, 1] == pytest.approx(1.5, abs=1e-9)  # dropped ball rests on the row
    assert np.all(np.abs(world.state.velocities) < 1e-9)
    assert max(per_step) <= 20
    assert sum(per_step[-100:]) == 0  # settled: no events any more
    assert stats.counts.held == 7


def test_event_cap_stops_the_step_and_warns():
    scene = load_scene("cradle", ["max_contacts_per_step=2"])
    obs = ListObserver()
    world = scene.build_world(obs)
    for _ in range(scene.steps):
        world.step(scene.dt)
    caps = [w for w in obs.warnings if w.code == "max_contacts_per_step"]
    assert caps, "the cap must be reported"
    assert max(e.counts.contacts for e in obs.step_ends) == 2


def test_the_contact_and_swept_test_budgets_are_sized_to_the_scene_unless_set(monkeypatch):
    from physdbg.engine import Settings, state

    sized = Settings()
    assert (sized.contact_cap(100), sized.swept_test_budget(100)) == (10_000, 10_000_000)
    assert (sized.contact_cap(100_000), sized.swept_test_budget(100_000)) == (10_000_000, 200_000_000)
    chosen = Settings(max_contacts_per_step=7, max_swept_tests_per_step=9)
    assert (chosen.contact_cap(100_000), chosen.swept_test_budget(100_000)) == (7, 9)
    assert load_scene("rain", ["max_swept_tests_per_step=0"]).settings.max_swept_tests_per_step == 0
    # the world spends the sized budget (made small here: 1 000 tests a sphere, at least 5 000)
    monkeypatch.setattr(state, "MIN_SWEPT_TESTS", 5_000)
    monkeypatch.setattr(state, "SWEPT_TESTS_PER_SPHERE", 1_000)
    for count, budget in ((3, 5_000), (20, 20_000)):
        world = load_scene("gas", ["dt=100", "steps=1", f"generate.count={count}"]).build_world()
        stats = world.step(100.0)  # a long step in a small box: every sphere bounces thousands of times
        assert budget <= stats.counts.swept_tests <= budget + 2 * (count + 6)
        assert stats.warnings[0].message.startswith(f"max_swept_tests_per_step reached ({budget} swept tests)")


# ----------------------------------------------------------------------------- events
def test_events_arrive_in_pipeline_order_with_everything_a_recording_needs():
    scene = load_scene("cradle")
    obs = ListObserver()
    world = scene.build_world(obs)
    for _ in range(50):
        world.step(scene.dt)
    kinds = [type(e) for e in obs.events]
    assert kinds[0] is StepBegin and kinds[-1] is StepEnd
    # per step: StepBegin, BroadPhaseInfo, contacts..., SweptTests, StepEnd
    step44 = [type(e) for e in obs.events if getattr(e, "step", None) == obs.contacts[0].step]
    assert step44 == [StepBegin, BroadPhaseInfo, Contacts, SweptTests, StepEnd]
    batch = [b for b in obs.of_type(Contacts) if b.step == obs.contacts[0].step][0]
    assert len(batch) == 4 and list(batch.a) == [0, 1, 2, 3] and batch.velocity_b_before.shape == (4, 3)
    tests = [t for t in obs.swept_tests if t.step == obs.contacts[0].step][0]
    assert np.count_nonzero(tests.outcome == OUTCOME_HIT) == 4
    assert set(np.unique(tests.kind)) <= {KIND_PAIR, KIND_WALL}
    hits = tests.outcome == OUTCOME_HIT
    assert np.all(np.isfinite(tests.toi[hits]))
    assert np.all(np.isnan(tests.toi[tests.outcome == OUTCOME_MISS]))
    end = obs.step_ends[-1]
    assert end.positions.shape == (5, 3) and end.velocities.shape == (5, 3)
    assert list(end.timings) == list(STEP_PHASES)  # each phase timed, in the order World._phases runs them
    assert set(vars(end.counts)) == {"contacts", "swept_tests", "events", "held", "rapid", "released", "asleep",
                                     "slept", "woken"}
    assert end.kinetic == pytest.approx(0.5)
    contact = obs.contacts[0]
    assert contact.impulse == pytest.approx(1.0)  # j = -(1+1)(1·n)/(1+1), n = -x
    np.testing.assert_allclose(contact.normal, [-1.0, 0.0, 0.0])
    np.testing.assert_allclose(contact.point, [0.5, 0.0, 0.0], atol=1e-12)


def test_observer_does_not_change_the_run():
    scene = load_scene("rain", ["steps=60"])
    watched = scene.build_world(ListObserver())
    alone = scene.build_world()
    for _ in range(scene.steps):
        a = watched.step(scene.dt)
        b = alone.step(scene.dt)
        assert a.state_hash == b.state_hash


@pytest.mark.parametrize("ordering", ["time", "index"])
def test_an_unobserved_step_logs_only_the_tests_that_hit(ordering):
    # The same run, the same count of swept tests; without an observer the test log
    # keeps only the hits (a dense step runs millions of tests, 95 % misses), and they
    # are the observed run's hits, in the same order, with the same outcomes.
    scene = load_scene("rain", ["steps=40", "generate.count=60", f"ordering={ordering}"])
    obs = ListObserver()
    watched = scene.build_world(obs)
    alone = scene.build_world()
    kept = total = 0
    for _ in range(scene.steps):
        a = watched.step(scene.dt)
        b = alone.step(scene.dt)
        assert ((a.state_hash, a.counts.swept_tests, a.counts.contacts)
                == (b.state_hash, b.counts.swept_tests, b.counts.contacts))
        tests = obs.swept_tests[-1]
        assert len(tests.kind) == a.counts.swept_tests
        hit = ~np.isnan(tests.toi)
        rows = int(alone._buf.counters[ROWS])
        assert rows == int(hit.sum())
        np.testing.assert_array_equal(alone._buf.test_int[:rows, 1], tests.a[hit])
        np.testing.assert_array_equal(alone._buf.test_int[:rows, 2], tests.other[hit])
        np.testing.assert_array_equal(alone._buf.test_float[:rows, 1], tests.toi[hit])
        np.testing.assert_array_equal(alone._buf.test_outcome[:rows], tests.outcome[hit])
        kept += rows
        total += b.counts.swept_tests
    assert 0 < kept < total / 2


class _NoTests(ListObserver):
    wants_swept_tests = False


def test_an_observer_that_reads_no_swept_tests_gets_none_and_the_step_logs_only_hits():
    # The audit, the Rerun view and a recording below detail "full" read no SweptTests: the
    # step logs only the hits (as unobserved) and sends every other event; same results.
    scene = load_scene("rain", ["steps=30", "generate.count=60"])
    lean, full = _NoTests(), ListObserver()
    a, b = scene.build_world(lean), scene.build_world(full)
    for _ in range(scene.steps):
        sa, sb = a.step(scene.dt), b.step(scene.dt)
        assert ((sa.state_hash, sa.counts.swept_tests, sa.counts.contacts)
                == (sb.state_hash, sb.counts.swept_tests, sb.counts.contacts))
        rows = int(a._buf.counters[ROWS])
        assert rows == int(np.count_nonzero(~np.isnan(full.swept_tests[-1].toi))) < sb.counts.swept_tests
    assert lean.swept_tests == [] and len(full.swept_tests) == scene.steps
    assert [type(e) for e in lean.events] == [type(e) for e in full.events if not isinstance(e, SweptTests)]
    assert len(lean.contacts) == len(full.contacts) > 0


def test_a_fan_out_wants_swept_tests_when_any_of_its_observers_does():
    assert not FanOut(_NoTests(), _NoTests()).wants_swept_tests
    assert FanOut(_NoTests(), ListObserver()).wants_swept_tests  # one that does not say gets everything
    assert FanOut(FanOut(_NoTests()), FanOut(_NoTests(), ListObserver())).wants_swept_tests
    assert not FanOut(FanOut(_NoTests()), _NoTests()).wants_swept_tests
    assert not wants_swept_tests(None) and wants_swept_tests(ListObserver())


@pytest.mark.parametrize("ordering", ["time", "index"])
def test_a_step_whose_buffers_would_pass_max_memory_is_stopped_like_a_budget(ordering):
    # 200 spheres count 0.82 MB and the buffers start at ~0.32 MB; an observer of the swept
    # tests makes the log grow in the first step. Under 1.2e6 bytes it may not: the step
    # stops with a warning that says what it would have needed and what to set, and the
    # buffers never pass the limit. The suggested limit gives the exact run back.
    def world(*extra):
        scene = load_scene("rain", ["steps=20", "generate.count=200", f"ordering={ordering}", *extra])
        return scene, scene.build_world(ListObserver())

    tight_scene, tight = world("max_memory=1.2e6")
    assert tight_scene.settings.max_memory == 1.2e6
    stopped = []
    for _ in range(tight_scene.steps):
        stats = tight.step(tight_scene.dt)
        stopped += [w.message for w in stats.warnings if w.code == "max_memory"]
        buffers = tight._buf.bytes_after(0, 0, 0)[0]
        assert 200 * 4096 + buffers + sum(a.nbytes for a in tight.held) <= 1.2e6
    assert len(stopped) == tight_scene.steps
    message = stopped[0]
    assert "max_memory reached" in message and "more than max_memory = 1.2e+06 bytes" in message
    assert "the remaining contacts of the step were not resolved" in message
    suggested = message.split("--set max_memory=")[1].split()[0]
    scene, again = world(f"max_memory={suggested}")
    _, default = world()
    for _ in range(scene.steps):
        a, b = again.step(scene.dt), default.step(scene.dt)
        assert a.warnings == b.warnings and a.state_hash == b.state_hash  # index order may overlap: as ever
        assert "max_memory" not in {w.code for w in a.warnings}


def test_an_observer_of_the_swept_tests_counts_their_log_against_max_memory():
    # The same limit holds the hits-only log of a step no observer reads the tests of, and
    # not the full one; the warning then names the lighter recording detail.
    scene = load_scene("rain", ["steps=20", "generate.count=200", "max_memory=1.2e6"])
    lean, full = scene.build_world(_NoTests()), scene.build_world(ListObserver())
    lean_stats = [lean.step(scene.dt) for _ in range(scene.steps)]
    full_stats = [full.step(scene.dt) for _ in range(scene.steps)]
    assert all(not s.warnings for s in lean_stats)
    message = full_stats[0].warnings[0].message
    assert message.startswith("max_memory reached") and "or record below --detail full" in message


def test_events_carry_copies_not_views():
    scene = load_scene("bounce", ["steps=5"])
    obs = ListObserver()
    world = scene.build_world(obs)
    world.step(scene.dt)
    first = obs.step_ends[0].positions.copy()
    world.step(scene.dt)
    np.testing.assert_array_equal(obs.step_ends[0].positions, first)


# ----------------------------------------------------------------------------- determinism
# Pinned: bounce, exact + swept + time, 300 steps of 1/60 s (closed forms, no drag:
# only IEEE +, -, *, /, sqrt). A change to this hash is a change of behaviour.
GOLDEN_BOUNCE_HASH = "8001b275691de3af018776bfb275eecf"


def _final_hash(scene_name, overrides=()):
    scene = load_scene(scene_name, list(overrides))
    world = scene.build_world()
    hashes = [world.step(scene.dt).state_hash for _ in range(scene.steps)]
    return hashes


def test_golden_state_hash_of_bounce():
    assert _final_hash("bounce")[-1] == GOLDEN_BOUNCE_HASH


@pytest.mark.slow
def test_same_scene_gives_bit_identical_hashes_in_another_process():
    here = _final_hash("rain", ["steps=40"])
    code = ("from tests.test_world import _final_hash; "
            "print('\\n'.join(_final_hash('rain', ['steps=40'])))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=__file__.rsplit("/tests/", 1)[0])
    assert out.stdout.split() == here


# ----------------------------------------------------------------------------- dense piles
def _box_rain(count: int, *extra: str):
    """Issue 10's box-rain: r = 0.05 m spheres filling 10 % of a box, e = 0.8, dt = 1/240."""
    side = (count * 4.0 / 3.0 * np.pi * 0.05**3 / 0.1) ** (1.0 / 3.0)
    return load_scene("rain", [f"generate.count={count}", "generate.radius=0.05", f"box.max=[{side},{side},{side}]",
                               "dt=1/240", "steps=240", "generate.restitution=0.8", "box.restitution=0.8", *extra])


def test_box_rain_piles_up_exactly_with_no_step_stopped_by_a_budget():
    """Under the engine's own rules (the rain scene's are tc and sleeping)."""
    scene = _box_rain(1000, "rapid_contact_rule=hold", "sleep_speed=0")
    world = scene.build_world()
    rapid = held = 0
    for _ in range(scene.steps):
        stats = world.step(scene.dt)
        assert not stats.warnings, stats.warnings
        assert stats.max_overlap <= scene.settings.contact_tolerance
        rapid += stats.counts.rapid
        held = stats.counts.held
    assert held > 100  # the first layers lie on the floor, held
    assert rapid > 0  # and the rapid-contact rule acted (reported per step)


def test_box_rain_under_the_tc_rule_is_exact_and_does_not_churn():
    """rapid_contact_rule = tc holds a pressed rapid contact only when it is slow, so an
    impact is not passed through held clusters whose far contacts then come apart: the
    same box-rain, as exact, lets go of (almost) no held contact, where the hold rule lets
    go of hundreds."""
    released = {}
    for rule in ("hold", "tc"):
        scene = _box_rain(1000, f"rapid_contact_rule={rule}", "sleep_speed=0")
        world = scene.build_world()
        released[rule] = rapid = 0
        for _ in range(scene.steps):
            stats = world.step(scene.dt)
            assert not stats.warnings, stats.warnings
            assert stats.max_overlap <= scene.settings.contact_tolerance
            released[rule] += stats.counts.released
            rapid += stats.counts.rapid
        assert rapid > 1000  # the rule acts under both
    assert released["hold"] > 500 and released["tc"] * 50 < released["hold"], released


@pytest.mark.slow
def test_box_rain_comes_entirely_to_rest_under_tc_with_sleeping():
    """Issue 10's "the pile settles, contacts per step bounded": box-rain 1k with
    rapid_contact_rule=tc, sleep_speed=0.1, sleep_time=0.1 is exact at every step and every
    sphere is asleep by step 700 (671 when measured), with no contact left to resolve."""
    scene = _box_rain(1000, "rapid_contact_rule=tc", "sleep_speed=0.1", "sleep_time=0.1", "steps=700")
    world = scene.build_world()
    most = 0
    for _ in range(scene.steps):
        stats = world.step(scene.dt)
        assert not stats.warnings, stats.warnings
        assert stats.max_overlap <= scene.settings.contact_tolerance
        most = max(most, stats.counts.contacts)
    assert stats.counts.asleep == 1000 and (stats.counts.contacts, stats.counts.events, stats.counts.held, stats.kinetic) == (0, 0, 0, 0.0)
    assert most < 20_000  # bounded on the way: the event cap of 1 000 spheres is 20 000


def test_under_the_tc_rule_a_lone_ball_still_comes_to_rest():
    """With the resting rule off, only the rapid rule stops a ball's ever shorter bounces.
    Under tc its rapid contacts close at most g·T/2 < g·rapid_contact_time, so they are
    held, as under hold: the same run to the bit."""
    hashes = {}
    for rule in ("hold", "tc"):
        scene = load_scene("bounce", ["rest_fraction=0", "rapid_contact_time=1e-4", f"rapid_contact_rule={rule}"])
        world = scene.build_world()
        steps = [world.step(scene.dt) for _ in range(scene.steps)]
        assert sum(s.counts.rapid for s in steps) > 0 and steps[-1].counts.held == 1
        assert sum(s.counts.contacts for s in steps[-20:]) == 0  # at rest: no contact is resolved any more
        hashes[rule] = steps[-1].state_hash
    assert hashes["hold"] == hashes["tc"]


def test_the_rapid_contact_rule_can_be_turned_off_and_then_never_acts():
    scene = _box_rain(300, "rapid_contact_time=0", "steps=120")
    world = scene.build_world()
    assert sum(world.step(scene.dt).counts.rapid for _ in range(scene.steps)) == 0


def test_an_unpressed_rapid_contact_is_elastic_so_a_free_row_does_not_collapse():
    # three spheres in a row, nothing pressing them: a hit at c = 0.5 sends contacts down the
    # row at one instant; the second and third are rapid, hence elastic (the TC model)
    state = make_state([[0.0, 0, 0], [0.2, 0, 0], [0.4, 0, 0]], [[1.0, 0, 0], [0, 0, 0], [0, 0, 0]], radius=0.1,
                       restitution=0.5)
    state.positions[0, 0] = -0.5
    world, obs = make_world(state, gravity=(0.0, 0.0, 0.0))
    for _ in range(10):
        world.step(0.1)
    rapid = [c for c in obs.contacts if c.restitution == 1.0]
    assert rapid and all(not c.resting for c in obs.contacts)
    assert sum(s.counts.rapid for s in obs.step_ends) == len(rapid)


def test_an_euler_pair_is_predicted_along_the_straight_lines_after_a_partner_bounced():
    """Euler moves each sphere on the straight line of its anchor velocity, while its
    velocity follows gravity. B bounces off a wall mid-step (its new anchor carries
    v + g·t); A, anchored at the step start, still moves at v_A, not v_A + g·t. Predicting
    the pair with A's velocity as v_A + g·t (the bug hypothesis found: 0.3 mm overlaps)
    misses the touch below; the straight lines give its time exactly."""
    dt = 0.2
    state = make_state([[0.2, 0.5, 0.0], [0.85, 0.5, 0.0]], [[1.0, 0.0, 0.0], [3.0, 0.0, 0.0]], radius=0.1)
    world, obs = make_world(state, make_walls(([-1, 0, 0], -1.0, 1.0)), gravity=(0.0, -G, 0.0),
                            integrator="euler")
    stats = world.step(dt)
    wall, pair = obs.contacts
    assert (wall.kind, wall.a) == (KIND_WALL, 1) and pair.kind == KIND_PAIR
    t_b = 0.05 / 3.0
    assert wall.time_in_step == pytest.approx(t_b, abs=1e-14)
    v_b = np.array([-3.0, -G * t_b, 0.0])  # reflected; Euler's velocity followed gravity until then
    a0, b0 = np.array([0.2, 0.5, 0.0]), np.array([0.9, 0.5, 0.0])
    # |a0 + v_a τ - (b0 + v_b (τ - t_b))| = 0.2: a quadratic in s = τ - t_b
    d0 = a0 + np.array([1.0, 0.0, 0.0]) * t_b - b0
    dv = np.array([1.0, 0.0, 0.0]) - v_b
    qa, qb, qc = dv @ dv, 2 * d0 @ dv, d0 @ d0 - 0.04
    s = (-qb - math.sqrt(qb * qb - 4 * qa * qc)) / (2 * qa)
    assert pair.time_in_step == pytest.approx(t_b + s, abs=1e-12)
    assert stats.max_overlap <= 1e-9 and not stats.warnings


# ----------------------------------------------------------------------------- re-prediction
def test_a_contact_far_from_the_walls_re_predicts_no_wall():
    """After a contact the two spheres are predicted again against each other, and against
    only the walls their swept boxes reach: none, in the middle of a unit box (every wall
    used to be tested again, 12 misses here)."""
    box = make_walls(([1, 0, 0], 0.0, 1.0), ([-1, 0, 0], -1.0, 1.0), ([0, 1, 0], 0.0, 1.0),
                     ([0, -1, 0], -1.0, 1.0), ([0, 0, 1], 0.0, 1.0), ([0, 0, -1], -1.0, 1.0))
    state = make_state([[0.4, 0.5, 0.5], [0.6, 0.5, 0.5]], [[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]], radius=0.05)
    world, obs = make_world(state, box, gravity=(0.0, 0.0, 0.0))
    stats = world.step(0.1)
    assert stats.counts.contacts == 1
    tests = obs.swept_tests[-1]
    # the step-start pair test (a hit) and the pair predicted once after the contact
    assert list(tests.kind) == [KIND_PAIR, KIND_PAIR] and stats.counts.swept_tests == 2
    # elastic, equal masses: they meet at 0.05 s and are back where they started at 0.1 s
    np.testing.assert_allclose(world.state.positions[:, 0], [0.4, 0.6], atol=1e-15)
    np.testing.assert_allclose(world.state.velocities[:, 0], [-1.0, 1.0], atol=1e-15)


def test_a_sphere_sent_out_of_its_box_is_still_stopped_by_a_wall():
    """A contact that sends a sphere beyond its swept box (here: hit at 30 m/s by a heavy
    sphere, towards a wall its box did not reach) tests every wall again, so the wall
    still stops it within the step."""
    box = make_walls(([1, 0, 0], 0.0, 1.0), ([-1, 0, 0], -1.0, 1.0))
    state = make_state([[0.5, 0.5, 0.5], [0.62, 0.5, 0.5]], [[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]], radius=0.05,
                       inverse_mass=[0.001, 1.0])
    state.velocities[0, 0] = 30.0
    world, obs = make_world(state, box, gravity=(0.0, 0.0, 0.0))
    for _ in range(3):
        world.step(0.01)
        assert np.all(world.state.positions[:, 0] >= 0.05 - 1e-12)
        assert np.all(world.state.positions[:, 0] <= 0.95 + 1e-12)
    walls_hit = [c for c in obs.contacts if c.kind == KIND_WALL]
    assert walls_hit and walls_hit[0].a == 1


def test_a_changed_sphere_skips_a_partner_its_new_path_cannot_reach():
    """B is a broad-phase partner of C (their boxes grown to what a contact could reach
    meet), but neither B's path nor, after its contact with A, B's new path has a box that
    meets C's: B is never tested against C."""
    state = make_state([[0.3, 0.5, 0.5], [0.5, 0.5, 0.5], [0.75, 0.5, 0.5]],
                       [[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 0.0]], radius=0.05)
    world, obs = make_world(state, gravity=(0.0, 0.0, 0.0), broad_phase="brute-force")
    stats = world.step(0.1)
    assert stats.counts.contacts == 1
    tests = obs.swept_tests[-1]
    pairs = [(int(a), int(o)) for a, o in zip(tests.a, tests.other)]
    assert [1, 2] in world.last_step.pairs.tolist()  # a broad-phase pair
    # step start: A–B (a hit; B–C's path boxes miss); after the contact A–B once, B–C not at all
    assert pairs == [(0, 1), (0, 1)]
    np.testing.assert_allclose(world.state.positions[:, 0], [0.3, 0.5, 0.75], atol=1e-15)


def test_a_sphere_sent_towards_a_partner_still_meets_it():
    """The partner test keeps what can happen: B, knocked out of its swept box towards C at
    60 m/s, meets C within the step."""
    state = make_state([[0.3, 0.5, 0.5], [0.42, 0.5, 0.5], [0.9, 0.5, 0.5]],
                       [[30.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]], radius=0.05,
                       inverse_mass=[0.001, 1.0, 1.0])
    world, obs = make_world(state, gravity=(0.0, 0.0, 0.0), broad_phase="brute-force")
    world.step(0.01)
    assert [(c.a, c.other) for c in obs.contacts][:2] == [(0, 1), (1, 2)]


def test_after_warm_up_a_run_loads_no_kernel(monkeypatch):
    # warm_up loads every version of every kernel a step calls from Python, so that a run
    # is not charged a cache load (~5 ms each) mid-way: with compiling and loading turned
    # off afterwards, a sleeping rain whose steps have zero, one and many contacts, and a
    # Python re-query (World._refresh_box, rare in a run), still find a version of each.
    # (Not caught here: a contiguous array where the version takes any layout, which numba
    # then converts; Sleepers.end_of_step passes contiguous columns for that reason.)
    import gc

    from physdbg.engine.jit import _OneVersionPerType
    from physdbg.engine.warm import warm_up

    warm_up("grid", sleeping=True)
    kernels = [k for k in gc.get_objects() if isinstance(k, _OneVersionPerType)]
    for k in kernels:
        monkeypatch.setattr(k, "_can_compile", False)
    scene = load_scene("rain", ["steps=40", "generate.count=60", "broad_phase=grid", "rapid_contact_rule=tc",
                                "sleep_speed=0.1", "sleep_time=0.1"])
    world = scene.build_world()
    seen = set()
    for _ in range(scene.steps):
        seen.add(min(world.step(scene.dt).counts.contacts, 2))
        world._refresh_box(world.last_step, 0)
    assert seen == {0, 1, 2} and world.sleepers is not None


# ----------------------------------------------------------------------------- partner search
@pytest.mark.parametrize("name, overrides", [
    ("billiards", ["steps=120"]), ("gas", ["steps=40"]), ("rain", ["steps=150", "sleep_speed=0"]),
    ("highspeed", ["steps=40", "generate.count=800"]), ("funnel", ["steps=150"]),
])
def test_scanning_every_path_box_gives_the_states_listing_partners_gives(name, overrides, monkeypatch):
    """World._choose_partner_search picks a scan of every sphere's path box per
    re-prediction or the partner lists by cost; the states, their hashes and the overlap
    audit are the same bit for bit either way (forced here: every step that may scan does)."""
    import physdbg.engine.world as world_module
    from physdbg.events import BroadPhaseInfo

    runs = {}
    for factor in (0.0, 1e12):  # lists always; a scan wherever one is allowed
        monkeypatch.setattr(world_module, "SCAN_PER_LISTED_PAIR", factor)
        scene = load_scene(name, overrides)
        seen = ListObserver()
        world = scene.build_world(seen)
        ends = [world.step(dt) for dt in scene.step_lengths()]
        scanned = [info.stats["scanned"] for info in seen.of_type(BroadPhaseInfo)]
        runs[factor] = ([e.state_hash for e in ends], [e.max_overlap for e in ends], [e.counts.contacts for e in ends],
                        scanned)
    lists, scans = runs[0.0], runs[1e12]
    assert not any(lists[3]) and sum(scans[3]) > len(scans[3]) // 2  # RELIST_EVERY steps list again
    assert lists[0] == scans[0] and lists[1] == scans[1] and lists[2] == scans[2]


@pytest.mark.slow
def test_highspeed_scans_by_itself_and_lists_again_every_relist_steps():
    """Among 5,000 fast spheres of spread speeds the lists pair each sphere with dozens
    (their boxes grown to their reach), and a step has a few hundred contacts: the world
    scans, from counts alone, and lists again every RELIST_EVERY steps to re-measure."""
    from physdbg.engine.world import RELIST_EVERY
    from physdbg.events import BroadPhaseInfo

    scene = load_scene("highspeed", ["steps=70"])
    seen = ListObserver()
    world = scene.build_world(seen)
    for dt in scene.step_lengths():
        world.step(dt)
    scanned = [info.stats["scanned"] for info in seen.of_type(BroadPhaseInfo)]
    listed = [k for k, s in enumerate(scanned) if not s]  # step k + 1 listed (step_index k at its start)
    assert listed[:1] == [0] and set(range(RELIST_EVERY, 70, RELIST_EVERY)) <= set(listed)
    assert sum(scanned) >= 70 - 2 * len(listed) and len(listed) <= 6


def test_an_overlap_warning_and_the_summary_name_who_overlaps(tmp_path):
    """A ball started 3 cm into a mesh, swept detection: each step's warning, the step's
    record (StepEnd.overlap_with) and the run summary's overlap line name the sphere and the
    triangle, in the scene's numbering."""
    from typer.testing import CliRunner

    from physdbg import api
    from physdbg.cli import app
    from physdbg.events import KIND_MESH

    (tmp_path / "plate.obj").write_text("v -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\nf 1 3 2\nf 1 4 3\n")
    scene = tmp_path / "inside.toml"
    scene.write_text('name = "inside"\ndt = "1/60"\nsteps = 3\ngravity = [0.0, 0.0, 0.0]\n'
                     '[[meshes]]\nname = "plate"\nfile = "plate.obj"\n'
                     '[[particles]]\nposition = [0.5, 2.0, 0.0]\nradius = 0.1\n'
                     '[[particles]]\nposition = [-0.5, 0.07, 0.5]\nradius = 0.1\n')
    ends = []
    api.run(str(scene), observer=type("O", (), {"on_event": lambda self, e: ends.append(e)
                                                if isinstance(e, StepEnd) else None})())
    assert ends[0].overlap_with == (KIND_MESH, 1, 1) and ends[0].max_overlap == pytest.approx(0.03)
    assert ends[0].warnings[0].message.startswith("sphere 1 and mesh 'plate' triangle 1 overlap by 0.03 m")
    out = CliRunner().invoke(app, ["run", str(scene)]).output
    assert "overlap     max 0.03 m  (sphere 1 and mesh 'plate' triangle 1, step 1)" in out, out
    # within the contact tolerance an overlap is rounding, and nobody is named for it
    ramp = CliRunner().invoke(app, ["run", "ramp", "-s", "steps=400"]).output  # 5.55e-17 m, sphere 2 and a triangle
    assert "overlap     max 5.55e-17 m\n" in ramp, ramp
