"""The event calendar (engine/calendar.py) against the time-ordered loop it stands beside.

The calendar keeps each sphere's anchor from its last contact where the time-ordered loop
moves every anchor to each step's end, so the two round differently: their states agree
to rounding at first and then part as a chaotic gas parts any two roundings. What must
hold: the same contacts (pairs, walls, order, outcome) while they agree, states within
rounding of each other, reruns bit for bit, and every step the calendar cannot serve
taken by the time-ordered loop, as if the calendar were not there.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from physdbg.api import load_scene
from physdbg.engine import calendar as event_calendar
from physdbg.engine.reference import ReferenceWorld
from physdbg.engine.state import Settings, State
from physdbg.engine.world import World
from physdbg.errors import StepStopped
from physdbg.events import HOW_WITH_HELD, KIND_MESH, KIND_PAIR, KIND_WALL, Contacts, EngineWarning, StepBegin, StepEnd
from physdbg.errors import SceneError

from .test_reference import MAX_CONTACTS, _box, _scene_with_a_mesh, _v_and_a_corner, scenes


class _Seen:
    """Contacts and step ends, as an observer that reads no swept tests (as the recorder below full)."""

    wants_swept_tests = False
    wants_mesh_search = False

    def __init__(self):
        self.contacts: list[np.ndarray] = []
        self.ends: list[StepEnd] = []
        self.begins: list[int] = []  # each StepBegin's step
        self.warnings: list[EngineWarning] = []  # as the observer got them

    def on_event(self, event):
        if isinstance(event, StepBegin):
            self.begins.append(event.step)
        elif isinstance(event, EngineWarning):
            self.warnings.append(event)
        elif isinstance(event, Contacts):
            self.contacts.append(event.rows.copy())
        elif isinstance(event, StepEnd):
            self.ends.append(event)


def _run(state: State, walls, method: Settings, dt: float, steps: int, loop: str,
         world_class: type = World) -> tuple[World, _Seen]:
    seen = _Seen()
    world = world_class(state.copy(), walls, dataclasses.replace(method, event_loop=loop), seen)
    for _ in range(steps):
        world.step(dt)
    return world, seen


def _in_time_order(rows: np.ndarray, late: float = 0.0) -> np.ndarray:
    """A step's contacts in time order, those at one instant by kind, sphere and partner:
    contacts of different spheres at one instant commute, and the two loops take such a
    tie in their own order (the time-ordered loop in the order it predicted them, the
    calendar by sphere). late (s): contacts of different spheres within it count as at
    one instant (_agree's pressed: one loop may find a contact met again at once that
    much later). A pair's spheres in the order of their numbers: each loop names a pair's
    spheres in its own numbering's order (the time-ordered loop renumbers by space order as
    the spheres move: space_order.py; the calendar keeps its numbering), so a row's a and
    other may be swapped between the loops."""
    rows = rows.copy()
    pair = rows["kind"] == KIND_PAIR
    low, high = np.minimum(rows["a"], rows["other"]), np.maximum(rows["a"], rows["other"])
    rows["a"][pair], rows["other"][pair] = low[pair], high[pair]
    time = rows["time_in_step"]
    if late > 0.0 and len(rows):  # times rounded to a grid of 4·late: ties within it commute
        time = np.floor(time / (4.0 * late))
    return rows[np.lexsort((rows["other"], rows["a"], rows["kind"], time))]


def _agree(step_loop: _Seen, calendar: _Seen, dt: float, steps: int, tolerance: float = 1e-9,
           times: float | None = None, distance: float = 0.0, pressed: tuple[float, float] | None = None,
           corners: np.ndarray | None = None, rtol: float | None = None) -> None:
    """The same contacts in every step, their times (within ``times`` s plus ``distance``
    m over each contact's closing speed, else tolerance·dt), impulses and the states
    within tolerance.

    pressed (acceleration g m/s², the largest mass kg): a contact met again at once under
    gravity (a ball that bounced with restitution 0, held at once) is a root of its gap
    g·t²/2 away: a gap of a rounding, 1e-15 m, is t = 1.4e-8 s at 9.81 m/s² (the loops
    measure it from anchors of their own, rounded differently: one finds the gap 0, the
    other 1e-17 m and the contact 1.4e-9 s later). Given, such a contact may be
    AT_ONCE s later, its closing speed then g·t where the other loop's is 0, its impulse
    that speed times its mass (twice at most, with its restitution), and the states
    apart by g·t over the run.

    corners (T, 3, 3) m, a scene's triangles: a contact may name another triangle in
    the other loop where the two share a corner (and the contact its time, closing speed
    and impulse, as every contact must): a sphere meeting an edge or a corner shared by
    several triangles meets each at one instant, conservative advancement stops within
    its tolerance of that instant for each (toi.triangle_toi_swept), and which one stops
    a hair sooner depends on the anchor the test starts from (seen both ways: the lower
    number in one loop, the higher in the other). rtol: how closely (relatively) impulses
    and velocities agree (tolerance if None): a sphere–triangle contact, found within the
    contact tolerance (1e-9 m) of its instant, has its point and normal, and so its
    impulse and the velocities after it, within about that over the radius (seen: 1e-8)."""
    rtol = tolerance if rtol is None else rtol
    assert len(calendar.contacts) == len(step_loop.contacts) == steps
    late = AT_ONCE if pressed is not None else 0.0
    for step, (a, b) in enumerate(zip(step_loop.contacts, calendar.contacts), start=1):
        if pressed is not None:
            a, b = _meant(a), _meant(b)
        a, b = _in_time_order(a, late), _in_time_order(b, late)
        assert [tuple(r) for r in a[["kind", "a", "how"]]] == [tuple(r) for r in b[["kind", "a", "how"]]], step
        for row_a, row_b in zip(a, b):
            assert row_a["other"] == row_b["other"] or (
                corners is not None and row_a["kind"] == KIND_MESH
                and _share_a_corner(corners[row_a["other"]], corners[row_b["other"]])), (step, row_a, row_b)
        if times is None:
            allowed = np.full(len(a), tolerance * dt)
        else:  # within ``times``, and within ``distance`` (m) travelled at the closing speed
            allowed = times + distance / np.maximum(np.abs(a["closing_speed"]), 1e-3) + late
        assert (np.abs(b["time_in_step"] - a["time_in_step"]) <= allowed).all(), (
            step, b["time_in_step"] - a["time_in_step"], allowed)
        if pressed is None:
            np.testing.assert_allclose(b["impulse"], a["impulse"], rtol=rtol, atol=tolerance)
        else:
            acceleration, mass = pressed
            closing = np.abs(b["closing_speed"] - a["closing_speed"])
            assert (closing <= tolerance + acceleration * allowed).all(), (step, closing)
            assert (np.abs(b["impulse"] - a["impulse"]) <= tolerance + rtol * np.abs(a["impulse"])
                    + 2.0 * mass * closing).all(), (step, b["impulse"] - a["impulse"])
        np.testing.assert_allclose(b["restitution"], a["restitution"], rtol=0, atol=0)
    apart = tolerance + (pressed[0] * late * max(1.0, steps * dt) if pressed is not None else 0.0)
    for a, b in zip(step_loop.ends, calendar.ends):
        np.testing.assert_allclose(b.positions, a.positions, rtol=0, atol=apart)
        np.testing.assert_allclose(b.velocities, a.velocities, rtol=rtol, atol=apart)
        assert b.warnings == a.warnings
    # one step start a step, and the observer saw the warnings the steps report, no more
    assert calendar.begins == step_loop.begins == list(range(1, steps + 1))
    assert [(w.step, w.code) for w in calendar.warnings] == [(w.step, w.code) for w in step_loop.warnings]


def _share_a_corner(p: np.ndarray, q: np.ndarray) -> bool:
    """Whether triangles p and q (3, 3) m have a corner in common."""
    return bool((np.abs(p[:, None, :] - q[None, :, :]).max(axis=2) == 0.0).any())


def _meant(rows: np.ndarray) -> np.ndarray:
    """A step's contacts without those that are roundings: a contact solved with held ones
    (events.HOW_WITH_HELD) closing at a rounding's speed (below 1e-12 m/s; seen: 1.9e-17),
    which one loop's anchors find and the other's, rounded differently, do not."""
    return rows[~((rows["how"] == HOW_WITH_HELD) & (np.abs(rows["closing_speed"]) < 1e-12))]


# how much later than the other loop a contact met again at once may come (_agree's
# pressed): the root of g·t²/2 = 1e-15 m, a rounding of a position near 1 m, at 9.81 m/s²
AT_ONCE = 1.5e-8


@st.composite
def flow_path_scenes(draw):
    """test_reference's random scenes (a few spheres, walls or periodic axes, gravity or
    none, drag or none, restitution below 1 and the rapid-contact rule) on the paths the
    calendar serves, those whose anchor is their flow: exact's under gravity and drag,
    Verlet's parabola without drag, semi-implicit's straight line without forces."""
    state, walls, method, dt = draw(scenes())
    if draw(st.booleans()):  # an immovable sphere, and spheres that fall differently: pairs on curved paths
        state.inverse_mass[0] = 0.0
        state.gravity_scale[:] = draw(st.lists(st.sampled_from([0.0, 0.5, 1.0]), min_size=state.count,
                                               max_size=state.count))
    integrator = draw(st.sampled_from(["exact", "exact", "verlet", "semi-implicit"]))
    if integrator == "verlet":
        method = dataclasses.replace(method, drag=1.0)
    elif integrator == "semi-implicit":
        method = dataclasses.replace(method, gravity=(0.0, 0.0, 0.0), drag=1.0)
    return state, walls, dataclasses.replace(method, integrator=integrator), dt


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(flow_path_scenes())
def test_the_calendar_gives_the_slow_references_contacts_and_states(scene):
    """The slow reference loop's (engine/reference.py, bit for bit the time-ordered loop's:
    test_reference.py), contact for contact (times within 1e-12 s where every pair falls
    alike; see below where not) and state for state, under gravity and drag too, with the
    contacts the resolver holds (a ball coming to rest, a contact met again at once) and
    those it releases: the calendar takes every step."""
    state, walls, method, dt = scene
    steps = 20
    reference, seen_reference = _run(state, walls, method, dt, steps, "step", ReferenceWorld)
    calendar, seen_calendar = _run(state, walls, method, dt, steps, "calendar")
    assert calendar.calendar_steps == steps, calendar.calendar_unfit
    assert reference.calendar_steps == 0
    # Two spheres that fall differently (an immovable one, another gravity scale) meet on a
    # curved relative path, whose root conservative advancement finds to within a contact's
    # tolerance (toi.pair_toi_swept_scalar: at most 500 moves, each safe): from an anchor
    # many steps old it stops elsewhere in that band than from the step's start. Such a
    # contact, and every one after it, agrees within the contact tolerance over its closing
    # speed; every other within 1e-12 s.
    falls = np.asarray(method.gravity)[None, :] * (state.gravity_scale * (state.inverse_mass > 0))[:, None]
    apart = any(method.gravity) and len(np.unique(falls, axis=0)) > 1
    _agree(seen_reference, seen_calendar, dt, steps, times=1e-12, distance=method.contact_tolerance if apart else 0.0)


@st.composite
def settling_scenes(draw, most: int = 10):
    """A few spheres low in a closed box under gravity, slow, their restitutions 0 to 0.5
    (and the walls'), one of them immovable or not: they land, bounce lower, come to
    rest on the floor and on each other, are held (the resting and rapid-contact rules),
    and released where a neighbour knocks them off; with sleeping on or not (sleep.py:
    slow for 0.1 s, they fall asleep, and wake where a neighbour lands on them)."""
    n = draw(st.integers(2, most))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    radius = rng.uniform(0.05, 0.15, n)
    positions: list[np.ndarray] = []
    for r in radius:  # rejection sampling: no overlaps at the start
        for _ in range(1000):
            x = rng.uniform(r, 1.0 - r, 3)
            x[1] = rng.uniform(r, 0.4)  # low in the box: they land within a few steps
            if all(np.linalg.norm(x - y) > r + s for y, s in zip(positions, radius)):
                positions.append(x)
                break
    m = len(positions)
    state = State(np.array(positions), rng.normal(0.0, draw(st.sampled_from([0.0, 0.3, 1.0])), (m, 3)),
                  rng.uniform(0.5, 2.0, m), radius[:m], rng.uniform(0.0, 0.5, m), np.ones(m))
    if draw(st.booleans()):
        state.inverse_mass[0] = 0.0
    integrator = draw(st.sampled_from(["exact", "verlet"]))
    method = Settings(integrator=integrator, gravity=(0.0, -9.81, 0.0),
                      drag=1.0 if integrator == "verlet" else draw(st.sampled_from([1.0, 0.7])),
                      restitution_rule=draw(st.sampled_from(["min", "product"])),
                      rapid_contact_rule=draw(st.sampled_from(["hold", "tc"])),
                      sleep_speed=draw(st.sampled_from([0.0, 0.05, 0.2])), sleep_time=0.1)
    return state, _box(1.0, draw(st.floats(0.0, 0.5))), method, draw(st.sampled_from([1 / 60, 1 / 240]))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow], derandomize=True)
@given(settling_scenes(most=4))
def test_held_contacts_in_the_calendar_are_the_slow_references(scene):
    """Two to four spheres coming to rest (settling_scenes) over 30 steps: the slow
    reference's contacts (the same held, released and solved with held ones) and states,
    every step the calendar's. Held spheres and falling ones meet on curved relative paths
    (within the contact tolerance over the closing speed, as above), and a contact met
    again at once may come a rounding's root later (_agree's pressed).

    Why small and derandomized: in a pile the rounding differences grow from contact to
    contact (the root above feeds the next contact's time) until a contact at the edge of
    a rule (resting, rapid) is judged one way in one loop and the other way in the other
    (seen: a pair closing at 1.4e-6 m/s, 5e-14 s apart in the two loops, rapid in one),
    or a sphere meeting a neighbour and two walls at one instant takes them in its loop's
    order (the time-ordered loop by its heap's rows, the calendar by its predictions),
    whose impulses differ. Measured: 1 of 400 such small scenes over 30 steps parts that
    way, and 4 of 300 of up to ten spheres over 60 steps (docs/space-order.md, "The event
    calendar")."""
    state, walls, method, dt = scene
    steps = 30
    _, seen_reference = _run(state, walls, method, dt, steps, "step", ReferenceWorld)
    calendar, seen_calendar = _run(state, walls, method, dt, steps, "calendar")
    assert calendar.calendar_steps == steps, calendar.calendar_unfit
    heaviest = 1.0 / state.inverse_mass[state.inverse_mass > 0].min()
    _agree(seen_reference, seen_calendar, dt, steps, times=1e-12, distance=method.contact_tolerance,
           pressed=(9.81, heaviest))


@pytest.mark.parametrize("periodic", [False, True])
def test_the_gas_takes_the_same_contacts_until_rounding_parts_the_runs(periodic):
    """The built-in gas (64 spheres, walls or a periodic box): every contact of the first
    40 steps the time-ordered loop's (a few hundred), the states within 1e-9 m."""
    scene = load_scene("gas", [f"box.periodic={str(periodic).lower()}"])
    state, walls = scene.build_world().state, scene.walls
    ordered = _run(state, walls, scene.settings, scene.dt, 40, "step")[1]
    world, seen = _run(state, walls, scene.settings, scene.dt, 40, "calendar")
    assert world.calendar_steps == 40
    assert sum(len(rows) for rows in seen.contacts) > 100
    _agree(ordered, seen, scene.dt, 40)


def test_a_large_gas_agrees_for_its_first_thousand_contacts():
    """1,000 spheres in a periodic box (the benchmark's gas): the calendar's first 1,000
    contacts are the time-ordered loop's, in order, at the same times."""
    scene = load_scene("gas", ["generate.count=1000", "generate.packing_fraction=0.3", "box.periodic=true"])
    state, walls = scene.build_world().state, scene.walls
    rows = []
    for loop in ("step", "calendar"):
        seen = _run(state, walls, scene.settings, scene.dt, 4, loop)[1]
        rows.append(np.concatenate([_in_time_order(r) for r in seen.contacts])[:1000])
    assert len(rows[0]) == len(rows[1]) == 1000
    assert (rows[0][["kind", "a", "other"]] == rows[1][["kind", "a", "other"]]).all()
    np.testing.assert_allclose(rows[1]["time_in_step"], rows[0]["time_in_step"], rtol=0, atol=1e-9 * scene.dt)


def test_reruns_are_bit_identical():
    scene = load_scene("gas", ["box.periodic=true", "event_loop=calendar"])
    hashes = []
    for _ in range(2):
        world = scene.build_world()
        hashes.append([world.step(scene.dt).state_hash for _ in range(50)])
    assert hashes[0] == hashes[1]


def test_a_corner_met_at_one_instant_is_resolved_as_the_time_ordered_loop_does():
    """A sphere aimed at a box's corner meets three walls at one instant, gathered as the
    time-ordered loop gathers them (resolve.resolve_at_one_instant: three perpendicular
    walls are three impulses, in no order that matters), and it comes straight back."""
    state = State(np.array([[0.5, 0.5, 0.5]]), np.array([[1.0, 1.0, 1.0]]), np.ones(1), np.full(1, 0.1),
                  np.ones(1), np.ones(1))
    method = Settings(gravity=(0.0, 0.0, 0.0))
    runs = [_run(state, _box(1.0, 1.0), method, 0.1, 6, loop) for loop in ("step", "calendar")]
    _agree(runs[0][1], runs[1][1], 0.1, 6)
    rows = np.concatenate(runs[1][1].contacts)
    assert len(rows) == 3 and (rows["kind"] == KIND_WALL).all() and len(set(rows["time_in_step"])) == 1
    np.testing.assert_allclose(runs[1][0].state.velocities, [[-1.0, -1.0, -1.0]], atol=1e-12)


def test_where_it_cannot_serve_the_world_steps_as_without_it():
    """Euler's paths, a semi-implicit kick under forces, meshes, ordering = index, an
    observer of the swept tests: every step taken by the time-ordered loop, bit for bit
    the states of a world without the calendar, and the reason kept."""
    for scene_name, extra, reason in (("bounce", ["integrator=euler"], "euler integrator's path starts again"),
                                      ("bounce", ["integrator=semi-implicit"], "kicks every velocity"),
                                      ("paddle", [], "does not take a kinematic mesh"),
                                      ("gas", ["ordering=index"], "time order")):
        scene = load_scene(scene_name, extra)
        state, walls = scene.build_world().state, scene.walls
        a = _run(state, walls, scene.settings, scene.dt, 30, "step")
        b = _run(state, walls, scene.settings, scene.dt, 30, "calendar")
        assert b[0].calendar_steps == 0 and reason in b[0].calendar_unfit
        assert [e.state_hash for e in a[1].ends] == [e.state_hash for e in b[1].ends]
    scene = load_scene("gas", ["event_loop=calendar"])
    world = scene.build_world(_SweptTestsReader())
    world.step(scene.dt)
    assert world.calendar_steps == 0 and "swept tests" in world.calendar_unfit


@pytest.mark.parametrize("name", ["bounce", "rest", "billiards", "cradle", "bullet-wall"])
def test_the_non_chaotic_scenes_take_every_contact_of_the_time_ordered_loop(name):
    """Gravity (bounce), a stack coming to rest (rest: held from the first step), drag
    (billiards), a row of touching spheres (cradle), a fast sphere and a thin wall
    (bullet-wall), over their whole run: the same contacts in
    every step, their times within 1e-9 s and the states within 1e-9 (bullet-wall, which
    has no duration: 100 steps), every step the calendar's. Bounce comes to rest: the
    resolver holds its last bounce, and the ball stays held on the floor."""
    scene = load_scene(name)
    steps = int(round(scene.duration / scene.dt)) if scene.duration else 100
    state, walls = scene.build_world().state, scene.walls
    ordered = _run(state, walls, scene.settings, scene.dt, steps, "step")[1]
    world, seen = _run(state, walls, scene.settings, scene.dt, steps, "calendar")
    # (times within a nanosecond: billiards' collisions among the balls grow the loops'
    # rounding apart, to 1.4e-11 s by its last contacts, 4 s in)
    _agree(ordered, seen, scene.dt, steps, times=1e-9)
    assert world.calendar_steps == steps
    if name in ("bounce", "rest"):
        assert world.held_count > 0


class _SweptTestsReader:
    wants_swept_tests = True

    def on_event(self, event):
        pass


def test_a_state_written_between_steps_counts():
    """A velocity set between steps (a script's kick) is taken: the calendar is made again
    from the state, and the run goes on as a fresh world from that state would."""
    scene = load_scene("gas", ["box.periodic=true", "event_loop=calendar"])
    world = scene.build_world()
    for _ in range(10):
        world.step(scene.dt)
    world.state.velocities[3] = [2.0, -1.0, 0.5]
    fresh = World(world.state.copy(), scene.walls, world.settings)
    fresh.time, fresh.step_index = world.time, world.step_index
    fresh._last_contact[:] = world._last_contact
    assert [world.step(scene.dt).state_hash for _ in range(5)] == [fresh.step(scene.dt).state_hash
                                                                   for _ in range(5)]


def test_the_step_budget_stops_a_step_as_in_the_time_ordered_loop():
    scene = load_scene("gas", ["box.periodic=true", "event_loop=calendar", "max_contacts_per_step=1",
                               "generate.count=300", "generate.packing_fraction=0.3"])
    world = scene.build_world()
    end = world.step(scene.dt)
    assert end.counts.contacts == 1 and [w.code for w in end.warnings] == ["max_contacts_per_step"]
    end = world.step(scene.dt)  # made again from the state the budget left
    assert end.counts.contacts == 1 and world.calendar_steps == 2


def test_a_stop_request_ends_the_step():
    scene = load_scene("gas", ["box.periodic=true", "event_loop=calendar"])
    world = scene.build_world()
    world.step(scene.dt)
    world.request_stop()
    with pytest.raises(StepStopped):
        world.step(scene.dt)


def test_the_setting_is_checked_where_the_scene_gives_it():
    with pytest.raises(SceneError, match="event_loop.*step.*calendar"):
        load_scene("gas", ["event_loop=fast"])


def test_the_run_summary_says_where_the_calendar_served():
    from typer.testing import CliRunner

    from physdbg.cli import app

    served = CliRunner().invoke(app, ["run", "cradle", "-s", "event_loop=calendar"])
    assert served.exit_code == 0, served.output
    assert "event loop  calendar in 180 of 180 steps (docs/space-order.md" in served.output
    held = CliRunner().invoke(app, ["run", "bounce", "-s", "event_loop=calendar"])
    assert held.exit_code == 0, held.output
    assert "event loop  calendar in 300 of 300 steps" in held.output
    not_served = CliRunner().invoke(app, ["run", "bounce", "-s", "event_loop=calendar", "-s", "integrator=euler"])
    assert not_served.exit_code == 0, not_served.output
    assert ("calendar in 0 of 300 steps; the time-ordered loop took the rest, which it cannot serve: the euler "
            "integrator's path starts again" in not_served.output)


def test_a_ball_coming_to_rest_on_the_floor_is_held_as_in_the_time_ordered_loop():
    """A ball thrown at a box's corner, its restitution 0.5: it meets two walls at one
    instant (resolve.resolve_at_one_instant, the path that can write the held store),
    bounces lower on the floor each time and comes to rest there, sliding, held, until it
    meets a wall while held. The same contacts every step (the same held) and the states
    within 1e-9 m of a world without the calendar, one StepBegin a step. (Its numbers are not round: a contact
    exactly at a step's end can fall in either step by a rounding, and a ball thrown from
    0.1 m at 1 m/s meets its wall at the end of a step of 1/60 s.)"""
    state = State(np.array([[0.3, 0.5, 0.3]]), np.array([[-1.1, 0.0, -1.1]]), np.ones(1), np.full(1, 0.1),
                  np.full(1, 0.5), np.ones(1))
    walls, method, dt, steps = _box(1.0, 0.5), Settings(), 1 / 60, 240
    ordered = _run(state, walls, method, dt, steps, "step")[1]
    world, seen = _run(state, walls, method, dt, steps, "calendar")
    _agree(ordered, seen, dt, steps, times=1e-12)
    rows = np.concatenate(seen.contacts)
    first = rows[:2]
    assert (first["kind"] == KIND_WALL).all() and first["time_in_step"][0] == first["time_in_step"][1]
    assert world.held_count > 0 and world.calendar_steps == steps
    assert (rows["how"] != 0).any()  # (held: events.HOW_*)


def test_a_sphere_all_but_at_rest_does_not_leave_its_shell_at_once():
    """A held solve can leave a velocity of 1e-161 m/s: its square times the shell's
    radius squared underflows, and the straight shell exit's root came out 0, so the
    sphere left its shell at the same instant for ever (until the step's event budget).
    The exit is no earlier than the room left at full speed."""
    from physdbg.engine.calendar import shell_exit

    delta = 0.07
    t = shell_exit(0.0, 0.0, 0.0, 0.0, -1.778207e-161, 0.0, 0.0, 0.0, 0.0, delta, False)
    assert t >= delta / 1.778207e-161 * (1 - 1e-12)
    assert shell_exit(0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 0.0, delta, False) == pytest.approx(delta / 2.0)


def test_a_sleeper_woken_by_a_falling_ball_is_as_in_the_time_ordered_loop():
    """Sleeping in the calendar (sleep.py): a ball at rest on the floor falls asleep (an
    immovable obstacle, its path anchored again at the step's end), a second ball falls
    on it, bounces off it as off a wall and wakes it at that step's end (closing faster
    than sleep_speed), and both come to rest and sleep again. The same contacts, the same
    sleepers every step, and states within 1e-9 of the time-ordered loop's; every step the
    calendar's."""
    state = State(np.array([[0.5, 0.1, 0.5], [0.5, 0.7, 0.5]]), np.zeros((2, 3)), np.ones(2), np.full(2, 0.1),
                  np.full(2, 0.3), np.ones(2))
    method = Settings(gravity=(0.0, -9.81, 0.0), sleep_speed=0.05, sleep_time=0.1, contact_tolerance=1e-6)
    walls, dt, steps = _box(1.0, 0.3), 1 / 60, 120
    ordered = _run(state, walls, method, dt, steps, "step")[1]
    world, seen = _run(state, walls, method, dt, steps, "calendar")
    _agree(ordered, seen, dt, steps, times=1e-12, distance=method.contact_tolerance, pressed=(9.81, 1.0))
    assert world.calendar_steps == steps
    asleep = [[end.counts.asleep, end.counts.slept, end.counts.woken] for end in seen.ends]
    assert asleep == [[end.counts.asleep, end.counts.slept, end.counts.woken] for end in ordered.ends]
    woke = [end.step for end in seen.ends if end.counts.woken]
    assert woke and asleep[woke[0] - 2][0] >= 1  # asleep before the ball came down, woken by it
    assert seen.ends[-1].counts.asleep == 2


def test_a_sleeping_worlds_lists_reach_the_support_gap_farther():
    """The sleep rules read the step's pairs (World._sleep), and judge two spheres touching
    up to a gap of sleep.SUPPORT_GAP of their radii: a sphere near its shell's edge may be
    that close to one whose centre is beyond the plain lists' reach. With sleeping on, a
    pair as far apart as the plain reach plus the support gap (less a hair) is listed;
    with it off, not."""
    from physdbg.engine.calendar import SHELL
    from physdbg.engine.sleep import SUPPORT_GAP

    r = 0.1
    apart = 2 * r + 2 * (SHELL - 1) * r + 0.9 * SUPPORT_GAP * 2 * r
    state = State(np.array([[0.3, r, 0.5], [0.3 + apart, r, 0.5]]), np.zeros((2, 3)), np.ones(2), np.full(2, r),
                  np.full(2, 0.5), np.ones(2))
    listed = {}
    for sleep_speed in (0.0, 0.05):
        world = World(state.copy(), _box(1.0, 0.5), Settings(gravity=(0.0, -9.81, 0.0), sleep_speed=sleep_speed,
                                                              event_loop="calendar"))
        world.step(1 / 60)
        assert world.calendar_steps == 1
        listed[sleep_speed] = [tuple(p) for p in world.last_step.pairs]
    assert listed == {0.0: [], 0.05: [(0, 1)]}


@st.composite
def scenes_with_a_fixed_mesh(draw):
    """test_reference's scenes with a mesh (a turned paddle or an icosphere in the middle
    of a 1 m box, up to eight spheres round it), the mesh fixed, on the paths the calendar
    serves (exact's, Verlet's parabola), with gravity or without."""
    return _scene_with_a_mesh(draw(st.integers(0, 2**32 - 1)), draw(st.sampled_from(["paddle", "icosphere"])),
                              draw(st.integers(1, 8)), False, draw(st.floats(0.3, 1.0)),
                              draw(st.sampled_from(["exact", "verlet"])),
                              draw(st.sampled_from([(0.0, 0.0, 0.0), (0.0, -9.81, 0.0)])),
                              draw(st.sampled_from([1 / 60, 1 / 240])))


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow], derandomize=True)
@given(scenes_with_a_fixed_mesh())
def test_a_fixed_mesh_in_the_calendar_is_the_slow_references(scene):
    """The triangles of a fixed mesh are partners the calendar lists for each shell (the
    walk of each mesh's tree with the shell's box) and tests from the anchors: the slow
    reference's contacts (which tests every triangle) and states, every step the
    calendar's. A sphere–triangle root is conservative advancement's, found within the
    contact tolerance (toi.triangle_toi_swept): times agree within it over the closing
    speed. A contact budget as test_reference's (a sphere wedged in a crease chatters).

    Derandomized: over 300 random examples one parted, two triangle contacts 6.1e-10 s
    apart against an allowance of 3.6e-10 (the tolerance over the closing speed), where
    each loop's conservative advancement stopped at its own place in the band."""
    state, walls, method, dt = scene
    method = dataclasses.replace(method, max_contacts_per_step=MAX_CONTACTS)
    steps = 30
    _, seen_reference = _run(state, walls, method, dt, steps, "step", ReferenceWorld)
    calendar, seen_calendar = _run(state, walls, method, dt, steps, "calendar")
    assert calendar.calendar_steps == steps, calendar.calendar_unfit
    _agree(seen_reference, seen_calendar, dt, steps, times=1e-12, distance=method.contact_tolerance,
           pressed=(9.81, 1.0) if any(method.gravity) else None, corners=walls.meshes.corners, rtol=1e-7)


@pytest.mark.parametrize("shuffle", [0, 1, 2])
def test_triangles_met_at_one_instant_are_resolved_as_the_time_ordered_loop_does(shuffle):
    """Balls dropped onto the crease of a V of four triangles (in three orders) meet two
    triangles at one instant, and one thrown into the floor's edge meets two walls: the
    calendar gathers them from the sphere's listed partners as the time-ordered loop does
    from its candidates, and resolves them together. (30 steps: the thrown ball then rolls
    into the wedge between the floor and the V's underside, where the held solve's
    impulses reach 4e5 N·s for a closing speed of 3e-6 m/s, and the loops' 1e-13 s
    roundings come out of it 1.6e-7 apart, relatively.)"""
    state, walls, method, dt = _v_and_a_corner(shuffle)
    steps = 30
    _, ordered = _run(state, walls, method, dt, steps, "step")
    calendar, seen = _run(state, walls, method, dt, steps, "calendar")
    assert calendar.calendar_steps == steps
    assert any(((rows["kind"] == KIND_MESH).sum() >= 2) for rows in seen.contacts)
    _agree(ordered, seen, dt, steps, times=1e-12, distance=method.contact_tolerance, pressed=(9.81, 1.0),
           corners=walls.meshes.corners, rtol=1e-7)


def test_the_built_in_mesh_scenes_run_on_the_calendar(monkeypatch):
    """ramp, funnel and highspeed (fixed meshes: a ramp, a funnel, six walls as slabs of
    triangles) take every step on the calendar, the time-ordered loop's contacts while the
    runs agree: ramp's balls settle and roll (pressed: held contacts met again at once),
    funnel's pour through a hole and highspeed is a dilute gas at 250 m/s, both chaotic,
    compared for their first steps. Each list of immovable partners starts with room for
    one: they grow (GROW_PARTNERS) where a shell reaches more, as where a sphere's shell
    reaches several triangles and walls."""
    monkeypatch.setattr(event_calendar, "FIRST_IMMOVABLE_ROOM", 1)
    for name, steps in (("ramp", 240), ("funnel", 40), ("highspeed", 6)):
        scene = load_scene(name)
        ordered = _run(scene.state, scene.walls, scene.settings, scene.dt, steps, "step")[1]
        world, seen = _run(scene.state, scene.walls, scene.settings, scene.dt, steps, "calendar")
        assert world.calendar_steps == steps, (name, world.calendar_unfit)
        _agree(ordered, seen, scene.dt, steps, times=1e-9, distance=scene.settings.contact_tolerance,
               pressed=(9.81, 1.0 / scene.state.inverse_mass.min()) if any(scene.settings.gravity) else None,
               corners=scene.walls.meshes.corners, rtol=1e-7)
        assert world._calendar.immovables.shape[1] > 1, name


def test_a_dilute_worlds_shells_grow_and_a_piles_come_back_thin():
    """highspeed with 500 spheres (6 m apart at 250 m/s, 0.25 m in radius) leaves a shell
    of the thinnest thickness (0.125 m) about 33 times a step a sphere: after its first
    judgement (calendar.shell_fit, after two steps) the shells are thicker and each
    sphere leaves one about once a step, with the same contacts as the time-ordered loop; rain's spheres leave
    thicker shells while they rain, and thinner ones again once they meet the floor and
    each other more often than they leave them; the gas (packing 0.3) keeps the thinnest.
    A rerun chooses the same thicknesses: bit-identical states."""
    scene = load_scene("highspeed", ["generate.count=500"])
    steps = event_calendar.SHELL_JUDGED_OVER + 4
    ordered = _run(scene.state, scene.walls, scene.settings, scene.dt, steps, "step")[1]
    world, seen = _run(scene.state, scene.walls, scene.settings, scene.dt, steps, "calendar")
    thinnest = event_calendar.thinnest_shell(scene.state.radius)
    assert world._calendar_delta >= 8 * thinnest
    # its last step's events (shells left, contacts, stale predictions): about one a sphere
    # (at the thinnest shell, 16,000)
    assert seen.ends[-1].counts.events < 2 * 500
    _agree(ordered, seen, scene.dt, steps, times=1e-9)
    again = _run(scene.state, scene.walls, scene.settings, scene.dt, steps, "calendar")[1]
    assert [e.state_hash for e in again.ends] == [e.state_hash for e in seen.ends]
    scene = load_scene("rain", ["event_loop=calendar"])
    world = scene.build_world()
    chosen = []
    for _ in range(240):
        world.step(scene.dt)
        if world._calendar_delta is not None and world._calendar_delta not in chosen[-1:]:
            chosen.append(world._calendar_delta)
    thinnest = event_calendar.thinnest_shell(scene.state.radius)
    assert chosen[0] > thinnest and max(chosen) > chosen[-1] >= thinnest, chosen
    scene = load_scene("gas", ["event_loop=calendar", "generate.packing_fraction=0.3", "generate.count=500"])
    world = scene.build_world()
    for _ in range(3 * event_calendar.SHELL_JUDGED_OVER):
        world.step(scene.dt)
    assert world._calendar_delta is None and world._calendar.delta == event_calendar.thinnest_shell(scene.state.radius)
