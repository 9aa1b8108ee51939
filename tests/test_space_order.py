"""The world's own numbering (space_order.py): invisible from outside, the same physics."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from physdbg import api
from physdbg.analysis import diff
from physdbg.engine import world as world_module
from physdbg.engine.space_order import SPACE_ORDER_MIN, Numbering, chosen_order, morton_keys, morton_order
from physdbg.engine.state import NonFiniteState, Settings, State, Walls
from physdbg.engine.world import World
from physdbg.errors import SceneError
from physdbg.events import KIND_PAIR, BroadPhaseInfo, Contacts, StepEnd, SweptTests
from physdbg.api import load_scene


class Collect:
    def __init__(self):
        self.events = []

    def on_event(self, event):
        self.events.append(event)

    def of(self, kind):
        return [e for e in self.events if isinstance(e, kind)]


def _run(scene, space_order, steps=None, observer=None, **changes):
    world = World(scene.state.copy(), scene.walls,
                  dataclasses.replace(scene.settings, space_order=space_order, **changes), observer)
    stats = [world.step(scene.dt) for _ in range(steps or scene.steps)]
    return world, stats


# ----------------------------------------------------------------------------- keys and choice
def test_morton_keys_follow_the_z_curve_of_a_cube():
    corners = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], dtype=float)
    keys = morton_keys(corners, bits=1)
    assert keys.tolist() == list(range(8))  # x the lowest bit, then y, then z
    assert np.all(np.diff(morton_keys(corners)) > 0)  # the same order at 10 bits an axis
    shuffled = corners[[5, 2, 7, 0, 3, 6, 1, 4]]
    assert shuffled[morton_order(shuffled)].tolist() == corners.tolist()
    assert morton_keys(np.zeros((0, 3))).shape == (0,)
    assert morton_keys(np.ones((3, 3))).tolist() == [0, 0, 0]  # all in one place: no division by zero


def test_auto_orders_only_large_time_ordered_worlds():
    assert chosen_order("auto", SPACE_ORDER_MIN - 1, "time") == "given"
    assert chosen_order("auto", SPACE_ORDER_MIN, "time") == "morton"
    assert chosen_order("auto", SPACE_ORDER_MIN, "index") == "given"  # index order reads as the scene's
    assert chosen_order("morton", 2, "index") == "morton" and chosen_order("given", 10**6, "time") == "given"
    with pytest.raises(ValueError, match="space_order must be one of auto, given, morton, not 'z'"):
        chosen_order("z", 10, "time")


def test_a_numbering_moves_rows_both_ways_and_keeps_wall_indices():
    numbering = Numbering(np.array([2, 0, 3, 1]))
    scene_rows = np.array([[0.0], [10.0], [20.0], [30.0]])
    inner = numbering.inward(scene_rows)
    assert inner[:, 0].tolist() == [20.0, 0.0, 30.0, 10.0]
    assert numbering.outward(inner).tolist() == scene_rows.tolist()
    back = np.empty_like(scene_rows)
    numbering.outward(inner, out=back)
    again = np.empty_like(inner)
    numbering.inward(back, out=again)
    assert back.tolist() == scene_rows.tolist() and again.tolist() == inner.tolist()
    kinds = np.array([KIND_PAIR, 1, KIND_PAIR])
    assert numbering.partners(kinds, np.array([0, 0, 3])).tolist() == [2, 0, 1]  # the wall stays wall 0
    assert numbering.sphere(2) == 3 and numbering.spheres(np.array([1, 3], dtype=np.int32)).dtype == np.int32


def test_a_scene_names_the_field_and_the_choices_for_a_wrong_space_order():
    with pytest.raises(SceneError) as caught:
        load_scene("gas", ["space_order=z"])
    assert "space_order" in str(caught.value) and "auto, given, morton" in str(caught.value)
    assert load_scene("gas", ["space_order=morton"]).settings.space_order == "morton"


# the pile rules (auto picks them for rain from about 350 spheres; 300 is given them here)
PILE = ["rapid_contact_time=1e-4", "rapid_contact_rule=tc", "sleep_speed=0.1", "sleep_time=0.1"]


# ----------------------------------------------------------------------------- the same physics
@pytest.mark.parametrize("scene, overrides, steps", [
    ("gas", ["generate.count=300"], 100),  # e = 1, free flight and pair contacts only
    ("rain", ["generate.count=300", *PILE], 200),  # held contacts, the rapid-contact rule, sleeping: until the pile
    ("billiards", [], None),
])
def test_the_world_in_morton_order_reports_what_it_does_in_the_scenes(scene, overrides, steps):
    """The same hashes every step, the same contacts, the same sleepers, all in the
    scene's numbering (the numbering inside is not the identity)."""
    sc = load_scene(scene, overrides)
    seen = {order: Collect() for order in ("given", "morton")}
    worlds = {order: _run(sc, order, steps, seen[order]) for order in seen}
    morton = worlds["morton"][0]
    assert not np.array_equal(morton.numbering.inner_to_scene, np.arange(sc.state.count))
    assert [s.state_hash for s in worlds["given"][1]] == [s.state_hash for s in worlds["morton"][1]]
    assert worlds["given"][0].state.positions.tobytes() == morton.state.positions.tobytes()
    for a, b in zip(seen["given"].of(Contacts), seen["morton"].of(Contacts), strict=True):
        # the same contacts at the same times (contacts at one time, of different spheres,
        # may come in another order), a pair's two spheres perhaps named the other way round
        assert _contacts(a) == _contacts(b)
    for a, b in zip(seen["given"].of(StepEnd), seen["morton"].of(StepEnd), strict=True):
        assert a.positions.tobytes() == b.positions.tobytes()
        assert (a.asleep is None) == (b.asleep is None) and (a.asleep is None or a.asleep.tolist() == b.asleep.tolist())
    if scene == "rain":
        assert any(e.asleep.any() for e in seen["morton"].of(StepEnd))


def test_a_pile_in_morton_order_differs_only_in_its_last_bits():
    """A settling pile's held clusters are solved sphere by sphere in the world's numbering,
    so from some step on (221 of rain-300's 240) the two runs differ in the last bits of a
    cluster's solve: the same contacts, held contacts and sleepers every step, both exact,
    the places within 1e-7 m."""
    sc = load_scene("rain", ["generate.count=300", *PILE])
    (given_world, given_stats), (world, stats) = _run(sc, "given"), _run(sc, "morton")
    assert [(s.counts.contacts, s.counts.held, s.counts.asleep, s.warnings) for s in given_stats] == \
        [(s.counts.contacts, s.counts.held, s.counts.asleep, s.warnings) for s in stats]
    assert max(s.max_overlap for s in stats) <= sc.settings.contact_tolerance
    assert np.abs(given_world.state.positions - world.state.positions).max() < 1e-7
    _, again = _run(sc, "morton")  # and a run in the world's numbering is as deterministic as any
    assert [s.state_hash for s in again] == [s.state_hash for s in stats]


def test_a_pile_renumbered_at_random_every_step_keeps_its_held_contacts_and_sleepers(monkeypatch):
    """The held contacts (pairs turned over when their ends swap), the sleepers, the warm
    start and the loop's marks all follow the spheres through a renumbering: a pile
    renumbered at random before every step runs as the scene's numbering does, to the
    same counts every step and the same places within rounding."""
    sc = load_scene("rain", ["generate.count=300", *PILE])
    given_world, given_stats = _run(sc, "given")
    rng = np.random.default_rng(1)
    monkeypatch.setattr(world_module, "morton_order", lambda positions: rng.permutation(len(positions)))
    monkeypatch.setattr(world_module, "RENUMBER_EVERY", 1)
    world, stats = _run(sc, "morton")
    def seen(s):
        c = s.counts
        return c.contacts, c.held, c.rapid, c.asleep, c.slept, c.woken, s.warnings

    assert [seen(s) for s in given_stats] == [seen(s) for s in stats]
    assert max(s.counts.held for s in stats) > 100 and stats[-1].counts.asleep > 0
    assert np.abs(given_world.state.positions - world.state.positions).max() < 1e-12


def _contacts(event: Contacts) -> list[tuple]:
    r = event.rows
    pair = r["kind"] == KIND_PAIR
    low = np.where(pair, np.minimum(r["a"], r["other"]), r["a"])
    high = np.where(pair, np.maximum(r["a"], r["other"]), r["other"])
    return sorted(zip(r["time_in_step"].tolist(), r["kind"].tolist(), low.tolist(), high.tolist(),
                      np.abs(r["impulse"]).tolist(), strict=True))


def test_swept_tests_and_bvh_leaves_name_the_scenes_spheres():
    sc = load_scene("gas", ["generate.count=200", "broad_phase=bvh-sah"])
    seen = Collect()
    _run(sc, "morton", 5, seen)
    ends = seen.of(StepEnd)
    for info, start in zip(seen.of(BroadPhaseInfo)[1:], ends, strict=False):
        nodes = info.nodes
        for node in np.nonzero(nodes["left"] < 0)[0]:  # a leaf's box holds its spheres at the step's start
            spheres = nodes["order"][nodes["start"][node]:nodes["start"][node] + nodes["count"][node]]
            inside = (start.positions[spheres] >= nodes["lo"][node] - 1e-12) & \
                     (start.positions[spheres] <= nodes["hi"][node] + 1e-12)
            assert inside.all()
    given = Collect()
    _run(sc, "given", 5, given)
    for a, b in zip(given.of(SweptTests), seen.of(SweptTests), strict=True):
        assert _tests(a) == _tests(b) and len(a.a) > 0


def _tests(swept: SweptTests) -> list[tuple]:
    """The swept tests as a sorted list of (kind, sphere, partner), a pair's lower number first."""
    pair = swept.kind == KIND_PAIR
    low = np.where(pair, np.minimum(swept.a, swept.other), swept.a)
    high = np.where(pair, np.maximum(swept.a, swept.other), swept.other)
    return sorted(zip(swept.kind.tolist(), low.tolist(), high.tolist(), strict=True))


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), count=st.integers(2, 40))
def test_any_numbering_gives_the_same_run(seed, count):
    """Whatever permutations the world takes, at the start and renumbering every 5
    steps, a random gas runs to the same states."""
    rng = np.random.default_rng(seed)
    sc = load_scene("gas", [f"generate.count={count}", f"seed={seed % 1000}", "steps=20"])
    _, given_stats = _run(sc, "given")
    taken = []

    def any_order(positions):
        taken.append(rng.permutation(len(positions)))
        return taken[-1]

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(world_module, "morton_order", any_order)
        patch.setattr(world_module, "RENUMBER_EVERY", 5)
        world, morton_stats = _run(sc, "morton")
    assert len(taken) == 4  # at the start, and before steps 5, 10 and 15
    composed = np.arange(count)
    for permutation in taken:
        composed = composed[permutation]
    assert world.numbering.inner_to_scene.tolist() == composed.tolist()
    assert [s.state_hash for s in given_stats] == [s.state_hash for s in morton_stats]


@pytest.mark.parametrize("broad_phase", ["bvh-sah", "grid"])
def test_a_periodic_gas_renumbered_often_runs_the_same(monkeypatch, broad_phase):
    """Through the periodic broad phase (images of the boxes) and a BVH kept from step to
    step by index, renumbering every 3 steps changes nothing."""
    sc = load_scene("gas", ["generate.count=150", "box.periodic=true", f"broad_phase={broad_phase}", "steps=40"])
    assert sc.walls.periodic
    _, given_stats = _run(sc, "given")
    monkeypatch.setattr(world_module, "RENUMBER_EVERY", 3)
    _, stats = _run(sc, "morton")
    assert [s.state_hash for s in given_stats] == [s.state_hash for s in stats]
    assert sum(s.counts.contacts for s in stats) > 0


def test_the_cradle_reversed_resolves_its_chain_the_same_way(monkeypatch):
    """Contacts that touch at once (the cradle's chain) come out the same numbered backwards."""
    sc = load_scene("cradle")
    monkeypatch.setattr(world_module, "morton_order", lambda positions: np.arange(len(positions))[::-1].copy())
    _, given_stats = _run(sc, "given")
    _, reversed_stats = _run(sc, "morton")
    assert [s.state_hash for s in given_stats] == [s.state_hash for s in reversed_stats]


# ----------------------------------------------------------------------------- the boundary
def test_world_state_is_the_world_in_the_scenes_numbering_and_writes_to_it_count():
    sc = load_scene("gas", ["generate.count=100"])
    given_world, _ = _run(sc, "given", 3)
    world, _ = _run(sc, "morton", 3)
    assert world.state.velocities.tobytes() == given_world.state.velocities.tobytes()
    for w in (given_world, world):  # a kick between steps, written to World.state
        w.state.velocities[17] += [5.0, 0.0, 0.0]
    assert given_world.step(sc.dt).state_hash == world.step(sc.dt).state_hash


def test_a_non_finite_sphere_is_named_by_its_scene_number():
    state = State(np.array([[20.0, 0, 0], [0.0, 0, 0], [10.0, 0, 0]]), np.zeros((3, 3)), np.ones(3),
                  np.full(3, 0.1), np.ones(3), np.ones(3))
    walls = Walls([], np.zeros((0, 3)), np.zeros(0), np.zeros(0), np.zeros(0, dtype=np.bool_), np.zeros(0))
    world = World(state, walls, Settings(space_order="morton", gravity=(0.0, 0.0, 0.0)))
    assert world.numbering.inner_to_scene.tolist() == [1, 2, 0]  # scene sphere 1 is the world's 0
    world.state.velocities[1] = [np.inf, 0.0, 0.0]
    with pytest.raises(NonFiniteState) as caught:
        world.step(0.01)
    assert caught.value.particle == 1


def test_a_large_world_keeps_a_morton_numbering_by_default_and_a_diff_says_it_cannot_change_much(tmp_path):
    big = load_scene("gas", [f"generate.count={SPACE_ORDER_MIN}", "steps=2"])
    assert World(big.state.copy(), big.walls, big.settings).numbering is not None
    small = ["generate.count=200", "steps=30"]
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    api.record("gas", small, mcap_path=str(a), rrd=False, detail="contacts")
    api.record("gas", [*small, "space_order=morton"], mcap_path=str(b), rrd=False, detail="contacts")
    report = diff(a, b)
    assert report.equivalent and report.exit_code == 0
    difference = next(s for s in report.settings if s.name == "space_order")
    assert (difference.a, difference.b) == ("auto", "morton") and "numbering" in difference.note
    # auto means the scene's numbering below SPACE_ORDER_MIN: no difference to report
    c = tmp_path / "c.mcap"
    api.record("gas", [*small, "space_order=given"], mcap_path=str(c), rrd=False, detail="contacts")
    assert not [s for s in diff(a, c).settings if s.name == "space_order"]
