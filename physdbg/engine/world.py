"""The world and its step: a named pipeline of phases, each timed.

``World.step(dt)`` runs::

    forces        held contacts -> accelerations; semi-implicit velocity update
    broad_phase   swept box of each path over the step -> candidate pairs
    narrow_phase  swept test of every candidate pair and particle–wall pair
    resolve       contacts taken in the order of the policy:
                    time  - earliest first; advance the particles to it, change their
                            velocities, re-predict only them, repeat (no lost time);
                    index - every contact predicted at step start, resolved in
                            detection order, nothing re-predicted (the naive engine,
                            kept on purpose so its failures can be shown)
    finish        advance every particle to the end of the step; audit overlaps;
                  energies, momentum and the state hash

Each particle carries an *anchor*: its position and velocity at a time sigma inside the
step, from which :mod:`motion` gives its path. Resolving a contact at time t advances the
anchors of the particles involved to t, so the rest of their step runs over exactly the
remaining time. Events go to ``observer.on_event``; with no observer, building them
costs one branch per step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from time import perf_counter

import numpy as np

from ..events import (
    BroadPhaseInfo,
    KIND_PAIR,
    KIND_WALL,
    OUTCOME_CAPPED,
    OUTCOME_HIT,
    OUTCOME_SUPERSEDED,
    Contacts,
    EngineWarning,
    StepBegin,
    StepEnd,
    SweptTests,
)
from .broadphase import choose_broad_phase, make_broad_phase
from .broadphase.boxes import boxes_meet
from .broadphase.periodic import PeriodicBroadPhase
from .motion import (
    FLOW,
    KICK_AT_STEP_START,
    REST_STEP_FACTOR,
    advance_particles,
    grow_to_reach,
    particle_box,
    swept_boxes,
)
from .periodic import wrap_positions
from .resolve import (
    OUT_OF_WORK,
    RESTITUTION_RULES,
    SKIPPED,
    resolve_contact,
    settle_held,
)
from .resting import grow_held, held_room, new_held
from .state import BUDGETS, NonFiniteState, Settings, State, Walls, energies, first_non_finite, state_hash
from .timeline import (
    CAPPED,
    CONTACTS,
    DONE,
    EVENTS,
    GROW,
    GROW_HELD,
    RAPID,
    REQUERY,
    RESTING_BUDGET,
    TEST_BUDGET,
    TESTS,
    Buffers,
    adjacency_from_pairs,
    max_overlap,
    predict_into,
    reachable_walls,
    run_time_order,
)

# Updates of the held-contact solves smaller than this (relative to the largest free
# acceleration, at least 1 m/s², and for velocities to that acceleration times dt) wake
# no neighbours: they are rounding.
SOLVE_TOLERANCE = 1e-12


@dataclass
class StepStats:
    """What one step reports whether or not anyone observes it."""

    step: int
    time: float
    dt: float
    kinetic: float
    potential: float
    momentum: np.ndarray
    contacts: int
    swept_tests: int
    events: int
    held: int
    rapid: int
    max_overlap: float
    state_hash: str
    timings: dict[str, float]
    warnings: list[EngineWarning]


class World:
    """Particles, walls and settings, stepped in place.

    state: the particles (its arrays are updated by ``step``); walls: the planes;
    settings: methods and tolerances; observer: anything with ``on_event(event)``.
    """

    def __init__(self, state: State, walls: Walls, settings: Settings, observer=None):
        bad = first_non_finite(state.positions, state.velocities)
        if bad is not None:
            raise ValueError(f"the initial {bad[1]} of sphere {bad[0]} is NaN or infinite")
        self.state = state
        self.walls = walls
        self.settings = settings
        self.observer = observer
        self.step_index = 0
        self.time = 0.0
        chosen, self.broad_phase_reason = choose_broad_phase(settings.broad_phase, state.radius)
        self.broad_phase = make_broad_phase(chosen)
        self.held = new_held(state.count)
        self._last_contact = np.full(state.count, -math.inf)
        self._integrator = settings.integrator_code
        self._detection = settings.detection_code
        self._drag = float(settings.drag)
        self._k = -math.log(self._drag)
        gravity = np.asarray(settings.gravity, dtype=np.float64)
        self.gravity = gravity
        movable = state.inverse_mass > 0
        state.velocities[~movable] = 0.0
        self._free_accel = np.ascontiguousarray(
            (state.gravity_scale * movable)[:, None] * gravity[None, :])
        self._half_thickness = np.ascontiguousarray(walls.thickness * 0.5, dtype=np.float64)
        self._two_sided = np.ascontiguousarray(walls.two_sided, dtype=np.bool_)
        self._normals = np.ascontiguousarray(walls.normals, dtype=np.float64).reshape(-1, 3)
        # the integrator's traits (motion.py's table): no branch on which integrator it is
        self._anchor_is_flow = FLOW[self._integrator][self._drag != 1.0]
        self._rest_step_factor = REST_STEP_FACTOR[self._integrator]
        self._kick_first = KICK_AT_STEP_START[self._integrator]
        self._accel_scale = max(1.0, float(np.abs(self._free_accel).max())) if state.count else 1.0
        self._atol = SOLVE_TOLERANCE * self._accel_scale
        self._vtol = self._atol  # set per step: SOLVE_TOLERANCE·(acceleration scale)·dt
        self._acc = np.zeros((state.count, 3))
        self._offsets = np.ascontiguousarray(walls.offsets, dtype=np.float64)
        self._wall_restitution = np.ascontiguousarray(walls.restitution, dtype=np.float64)
        self._period = np.ascontiguousarray(walls.period, dtype=np.float64)
        self._period_origin = np.ascontiguousarray(walls.period_origin, dtype=np.float64)
        self._periodic = walls.periodic
        if self._periodic:
            wrap_positions(state.positions, self._period_origin, self._period)
            self.broad_phase = PeriodicBroadPhase(self.broad_phase, self._period_origin, self._period)
        self._buf = Buffers(state.count)
        self.event_cap = settings.event_cap(state.count)

    @property
    def held_count(self) -> int:
        """How many contacts are held (resting or rapid, resting.py)."""
        return int(self.held.count[0])

    # ------------------------------------------------------------------ the step
    def step(self, dt: float) -> StepStats:
        """Advance the world by ``dt`` seconds and report what happened.

        Raises NonFiniteState (after reporting the step) when a position or velocity
        became NaN or infinite: the world cannot go on from there.
        """
        if isinstance(dt, bool) or not isinstance(dt, (int, float, np.floating)) or not 0.0 < dt < math.inf:
            raise ValueError(f"World.step needs dt, a positive finite number of seconds; got {dt!r} (a scene with "
                             f'dt = "real" gives each step\'s length through Scene.step_lengths())')
        dt = float(dt)
        st = self.state
        s = self.settings
        obs = self.observer
        n = st.count
        step_no = self.step_index
        if obs is not None:
            obs.on_event(StepBegin(step_no, self.time, dt))
        timings: dict[str, float] = {}
        warnings: list[EngineWarning] = []
        self._resting_work = 0
        x, v = st.positions, st.velocities

        def warn(code: str, message: str) -> None:
            warnings.append(EngineWarning(step_no, code, message))
            if obs is not None:
                obs.on_event(warnings[-1])

        # -- forces ---------------------------------------------------------------
        t0 = perf_counter()
        self.held.count[2] = 0  # the resting work of this step
        # a velocity residue of vtol moves a sphere vtol·dt in a step: SOLVE_TOLERANCE·a·dt²
        self._vtol = SOLVE_TOLERANCE * self._accel_scale * dt
        acc = self._acc
        path_accel = np.empty_like(acc)
        sigma = np.zeros(n)
        if not settle_held(self.held, x, v, path_accel, acc, self._free_accel, st.radius, st.inverse_mass, sigma, dt,
                           self._integrator, self._drag, self._k, self._kick_first, self._normals,
                           self._offsets, self._half_thickness, self._two_sided, self._period, s.contact_tolerance,
                           s.max_resting_work_per_step, self._vtol, self._atol,
                           dt * (self._rest_step_factor + s.rest_fraction)):
            warn("max_resting_work_per_step", _budget_message("max_resting_work_per_step",
                                                              s.max_resting_work_per_step))
        self._a = path_accel
        self._sigma = sigma
        t1 = perf_counter()
        timings["forces"] = t1 - t0

        # -- broad phase --------------------------------------------------------
        lo = np.empty((n, 3))
        hi = np.empty((n, 3))
        swept_boxes(x, v, path_accel, st.radius, sigma, dt, self._integrator, self._k,
                    s.contact_tolerance, lo, hi)
        self._add_reach(lo, hi, dt)
        too_wide = self._too_wide_for_the_period(lo, hi)
        if too_wide:
            warn("periodic", too_wide)
            pairs = np.empty((0, 2), dtype=np.int64)
        else:
            pairs = self.broad_phase.pairs(lo, hi, s.max_pairs_per_step)
        if len(pairs) > s.max_pairs_per_step:
            warn("max_pairs_per_step", _budget_message("max_pairs_per_step", s.max_pairs_per_step))
            pairs = np.empty((0, 2), dtype=np.int64)
        self._lo, self._hi = lo, hi
        self._grown: set[int] = set()
        self._too_wide_mid_step: str | None = None  # a box grown mid-step past half a period (periodic)
        self._build_adjacency(pairs, n)
        t2 = perf_counter()
        timings["broad_phase"] = t2 - t1
        if obs is not None:
            obs.on_event(self._broad_phase_event(step_no, len(pairs)))

        # -- narrow phase ---------------------------------------------------------
        self._step_no = step_no
        self._dt = dt
        self._version = np.zeros(n, dtype=np.int64)
        self._run_time = self.time
        buf = self._buf
        buf.reset()
        push = s.ordering == "time"
        self._predict(KIND_PAIR, pairs[:, 0].copy(), pairs[:, 1].copy(), push)
        wall_p, wall_w = reachable_walls(lo, hi, self._normals, self._offsets, self._half_thickness,
                                         self._two_sided)
        self._predict(KIND_WALL, wall_p, wall_w, push)
        t3 = perf_counter()
        timings["narrow_phase"] = t3 - t2

        # -- resolve --------------------------------------------------------------
        budget = self._resolve_in_time_order() if push else self._resolve_in_index_order()
        if self._too_wide_mid_step and not any(w.code == "periodic" for w in warnings):
            warn("periodic", self._too_wide_mid_step)
        if budget is not None and not any(w.code == budget for w in warnings):
            warn(budget, _budget_message(budget, self.event_cap if budget == "max_events_per_step"
                                         else getattr(s, budget)))
        t4 = perf_counter()
        timings["resolve"] = t4 - t3

        # -- finish -------------------------------------------------------------
        advance_particles(x, v, self._a, sigma, np.arange(n, dtype=np.int64), dt, self._integrator,
                          self._drag, self._k)
        sigma[:] = 0.0
        if self._periodic:  # the paths were continuous through the step; the state is in the box
            wrap_positions(x, self._period_origin, self._period)
        max_overlap = self._max_overlap()
        if s.detection == "swept" and max_overlap > s.contact_tolerance and not warnings:
            warn("overlap", f"spheres overlap by {max_overlap:.3g} m, more than the contact tolerance "
                            f"{s.contact_tolerance:g} m")
        non_finite = first_non_finite(x, v)
        if non_finite is not None:
            failure = NonFiniteState(step_no, *non_finite)
            warn("non-finite", str(failure))
        kinetic, potential, momentum = energies(st, self.gravity)
        digest = state_hash(x, v)
        self.time += dt
        self.step_index += 1
        t5 = perf_counter()
        timings["finish"] = t5 - t4
        contacts = int(buf.counters[CONTACTS])
        tests = int(buf.counters[TESTS])
        events = int(buf.counters[EVENTS])
        rapid = int(buf.counters[RAPID])
        stats = StepStats(step_no, self.time, dt, kinetic, potential, momentum, contacts, tests, events,
                          self.held_count, rapid, max_overlap, digest, timings, warnings)
        if obs is not None:
            obs.on_event(self._contacts_event())
            obs.on_event(self._swept_tests_event())
            obs.on_event(StepEnd(step_no, self.time, dt, x.copy(), v.copy(), kinetic, potential,
                                 momentum.copy(),
                                 {"contacts": contacts, "swept_tests": tests, "events": events,
                                  "resting": self.held_count, "rapid": rapid},
                                 max_overlap, dict(timings), digest, tuple(w.message for w in warnings)))
        if non_finite is not None:
            raise failure
        return stats

    # ------------------------------------------------------------------ candidates
    def _build_adjacency(self, pairs: np.ndarray, n: int) -> None:
        """CSR lists of each particle's broad-phase partners (pairs must be sorted)."""
        self._adj_start, self._adj = adjacency_from_pairs(np.ascontiguousarray(pairs, dtype=np.int64), n)
        self._max_degree = int(np.diff(self._adj_start).max()) if n else 0
        self._pairs = pairs

    def _add_reach(self, lo: np.ndarray, hi: np.ndarray, dt: float) -> None:
        """Grow each swept box to the cube a sphere could reach this step at a typical speed.

        A contact turns a path, so a box around the old path alone would send nearly every
        particle back to the broad phase after its first contact. The cube x ± (reach + r)
        with reach = max(own speed, the scene's 99th-percentile speed) · dt (speed counting
        one step of acceleration) holds any path that does not outrun it; the rare one that
        does is queried again (timeline.REQUERY). In place on lo, hi (N, 3).
        """
        st = self.state
        # compiled (motion.grow_to_reach): np.quantile alone was a third of a small step
        grow_to_reach(st.positions, st.velocities, self._a, st.radius, dt, self.settings.contact_tolerance, lo, hi)

    def _too_wide_for_the_period(self, lo: np.ndarray, hi: np.ndarray,
                                 consequence: str = "sphere–sphere contacts were not tested in this step"
                                 ) -> str | None:
        """Why this step's swept boxes (N, 3) break the minimum image, or None.

        The minimum image is the true separation of every pair whose boxes overlap only
        while each box is narrower than half the period (periodic.py); a step whose
        box is wider would test the wrong images, so its pairs are not tested at all.
        """
        if not self._periodic or lo.shape[0] == 0:
            return None
        width = (hi - lo).max(axis=0)
        bad = np.nonzero((self._period > 0) & (width >= 0.5 * self._period))[0]
        if not bad.size:
            return None
        axis = int(bad[0])
        return (f"a sphere's swept box is {width[axis]:.3g} m wide on periodic axis {'xyz'[axis]}, at least half "
                f"the period {self._period[axis]:g} m: pairs cannot be told apart from their images, so "
                f"{consequence}; make the box larger or dt shorter")

    def _partners(self, i: int) -> np.ndarray:
        return self._adj[self._adj_start[i]:self._adj_start[i + 1]]

    def _refresh_box(self, i: int) -> list[int]:
        """Grow i's swept box to hold its new path; return partners it did not have."""
        st = self.state
        lo = np.empty(3)
        hi = np.empty(3)
        particle_box(st.positions, st.velocities, self._a, st.radius, self._sigma, i, self._dt, self._integrator,
                     self._k, self.settings.contact_tolerance, lo, hi)
        if np.all(lo >= self._lo[i]) and np.all(hi <= self._hi[i]):
            return []
        self._lo[i] = np.minimum(self._lo[i], lo)
        self._hi[i] = np.maximum(self._hi[i], hi)
        if self._periodic and self._too_wide_mid_step is None:
            self._too_wide_mid_step = self._too_wide_for_the_period(
                self._lo[i:i + 1], self._hi[i:i + 1], f"sphere {i}'s later contacts in this step (after a contact "
                                                      f"sent it out of its box) may have met the wrong image")
        found = set(self.broad_phase.query(self._lo, self._hi, self._lo[i], self._hi[i]).tolist())
        # a structure built at step start knows the old boxes: check grown ones directly
        if self._grown:
            grown = np.fromiter(self._grown, dtype=np.int64)
            hit = boxes_meet(self._lo[grown], self._hi[grown], self._lo[i], self._hi[i], self._period)
            found.update(grown[hit].tolist())
        self._grown.add(i)
        known = set(self._partners(i).tolist())
        return sorted(j for j in found if j != i and j not in known)

    def _add_partners(self, new_pairs: list[tuple[int, int]]) -> None:
        """Add broad-phase pairs found mid-step, and predict them."""
        if not new_pairs:
            return
        extra = np.array(sorted(set(new_pairs)), dtype=np.int64).reshape(-1, 2)
        merged = np.concatenate((self._pairs, extra))
        merged = merged[np.lexsort((merged[:, 1], merged[:, 0]))]
        self._build_adjacency(merged, self.state.count)
        self._predict(KIND_PAIR, extra[:, 0].copy(), extra[:, 1].copy(), True)

    # ------------------------------------------------------------------ narrow phase
    def _predict(self, kind: int, ia: np.ndarray, ib: np.ndarray, push: bool) -> None:
        """Swept-test candidates (kind, ia[m], ib[m]) into the buffers (held ones skipped)."""
        if ia.size == 0:
            return
        st = self.state
        s = self.settings
        buf = self._buf
        buf.ensure(ia.size, ia.size, 0)
        predict_into(kind, ia, ib, st.positions, st.velocities, self._a, st.radius, self._sigma, self._version,
                     self._dt, self._integrator, self._k, self._detection, s.samples, s.contact_tolerance * 1e-3,
                     self._normals, self._offsets, self._half_thickness, self._two_sided, self._period, self.held,
                     buf.test_int, buf.test_float, buf.test_outcome, buf.heap_toi, buf.heap_data, buf.counters, push)

    # ------------------------------------------------------------------ policies
    def _resolve_in_time_order(self) -> str | None:
        """The compiled loop, with Python taking the pauses (see timeline.py); returns the
        budget that stopped it (a Settings field name), or None."""
        st = self.state
        s = self.settings
        buf = self._buf
        nw = len(self.walls)
        rule = RESTITUTION_RULES.index(s.restitution_rule)
        while True:
            status = run_time_order(
                st.positions, st.velocities, self._a, self._acc, st.radius, st.inverse_mass, st.restitution,
                self._sigma, self._version, self._last_contact, self._run_time, self._dt, self._integrator,
                self._drag, self._k, self._detection, s.samples, s.contact_tolerance * 1e-3, s.rest_fraction,
                self._rest_step_factor, rule, s.rapid_contact_time, self._normals, self._offsets,
                self._half_thickness, self._two_sided, self._wall_restitution, self._period, self.held,
                self._adj_start, self._adj, self._lo, self._hi, s.contact_tolerance, self._max_degree, self.event_cap,
                s.max_swept_tests_per_step, s.max_resting_work_per_step, self._anchor_is_flow,
                not self._kick_first, self._vtol, self._atol, buf.heap_toi, buf.heap_data,
                buf.test_int, buf.test_float, buf.test_outcome, buf.contacts, buf.counters,
                buf.pending, buf.changed, buf.batch_mark, buf.requery, buf.requery_count)
            if status == DONE:
                return None
            if status == CAPPED:
                return "max_events_per_step"
            if status == TEST_BUDGET:
                return "max_swept_tests_per_step"
            if status == RESTING_BUDGET:
                return "max_resting_work_per_step"
            if status == GROW:
                room = 2 * self._max_degree + 2 * nw + 4
                buf.ensure(room, room, 2)
            elif status == GROW_HELD:
                self.held = grow_held(self.held)
            elif status == REQUERY:
                new_pairs = []
                for i in buf.requery[: buf.requery_count[0]].tolist():
                    new_pairs += [(min(i, j), max(i, j)) for j in self._refresh_box(i)]
                self._add_partners(new_pairs)

    def _resolve_in_index_order(self) -> str | None:
        """Every contact predicted at step start, in detection order, nothing re-predicted;
        returns the budget that stopped it (a Settings field name), or None."""
        buf = self._buf
        count = int(buf.counters[TESTS])
        toi = buf.test_float[:count, 1]
        hits = np.nonzero(toi <= self._dt)[0]
        for rid in hits.tolist():
            buf.counters[EVENTS] += 1
            if buf.counters[CONTACTS] >= self.event_cap:
                buf.test_outcome[hits[hits >= rid]] = OUTCOME_CAPPED
                return "max_events_per_step"
            kind, a, other = (int(c) for c in buf.test_int[rid])
            at = max(float(toi[rid]), self._sigma[a], self._sigma[other] if kind == KIND_PAIR else 0.0)
            status = self._resolve(kind, a, other, at)
            buf.test_outcome[rid] = OUTCOME_SUPERSEDED if status == SKIPPED else OUTCOME_HIT
            if status == OUT_OF_WORK:
                buf.test_outcome[hits[hits > rid]] = OUTCOME_CAPPED
                return "max_resting_work_per_step"
        return None

    # ------------------------------------------------------------------ one contact
    def _resolve(self, kind: int, a: int, other: int, when: float) -> int:
        """Resolve one predicted contact at time ``when`` in the step (resolve.resolve_contact);
        returns its status (SKIPPED, RESOLVED or OUT_OF_WORK)."""
        st = self.state
        s = self.settings
        buf = self._buf
        buf.ensure(0, 0, 1)
        while not held_room(self.held, a, other if kind == KIND_PAIR else -1):
            self.held = grow_held(self.held)
        return resolve_contact(kind, a, other, when, self._run_time, st.positions, st.velocities, self._a, self._acc,
                               st.radius, st.inverse_mass, st.restitution, self._sigma, self._last_contact, self._dt,
                               self._integrator, self._drag, self._k, self._anchor_is_flow,
                               not self._kick_first, s.rest_fraction, self._rest_step_factor,
                               RESTITUTION_RULES.index(s.restitution_rule), s.rapid_contact_time, self._normals,
                               self._offsets, self._two_sided, self._wall_restitution, self._period, self.held,
                               buf.contacts, buf.counters, CONTACTS, RAPID, buf.changed,
                               s.max_resting_work_per_step, self._vtol, self._atol)

    def _contacts_event(self) -> Contacts:
        return Contacts(self._step_no, self._buf.contacts[:int(self._buf.counters[CONTACTS])].copy())

    # ------------------------------------------------------------------ audit
    def _max_overlap(self) -> float:
        """Deepest penetration (m) among candidate pairs and particle–wall pairs."""
        return float(max_overlap(self.state.positions, self.state.radius, self._pairs, self._normals,
                                 self._offsets, self._half_thickness, self._two_sided, self._period,
                                 self.settings.detection != "swept"))

    def _broad_phase_event(self, step_no: int, pair_count: int) -> BroadPhaseInfo:
        bp = self.broad_phase
        stats = dict(bp.stats)
        stats.setdefault("pairs", pair_count)
        tree = bp.nodes
        nodes = None
        if tree is not None:
            nodes = {name: getattr(tree, name).copy() for name in
                     ("lo", "hi", "left", "right", "parent", "depth", "start", "count", "order")}
        return BroadPhaseInfo(step_no, bp.name, self.broad_phase_reason, stats, nodes)

    def _swept_tests_event(self) -> SweptTests:
        buf = self._buf
        count = int(buf.counters[TESTS])
        toi = buf.test_float[:count, 1].copy()
        return SweptTests(self._step_no, buf.test_int[:count, 0].astype(np.int8),
                          buf.test_int[:count, 1].astype(np.int32), buf.test_int[:count, 2].astype(np.int32),
                          buf.test_float[:count, 0].copy(), np.where(toi <= self._dt, toi, np.nan),
                          buf.test_outcome[:count].copy())

def _budget_message(budget: str, value: int) -> str:
    """What a warning says when a budget stopped a step: which, what happened, what to change."""
    counts, consequence = BUDGETS[budget]
    return (f"{budget} reached ({value} {counts}); {consequence}; raise it with --set {budget}=N "
            f"if the scene really needs more")


def warm_up(broad_phase: str | None = None) -> float:
    """Compile (or load from numba's cache) every kernel a step uses; returns seconds taken.

    Runs a two-sphere, one-wall world for one step with contacts, so the first real step
    is not charged with compilation. The kernels take the integrator and detection as
    arguments, so one run compiles every method. broad_phase: also compile this one.
    """
    started = perf_counter()
    if broad_phase is not None and broad_phase != "brute-force":
        boxes = np.random.default_rng(0).uniform(0.0, 1.0, (8, 3))
        make_broad_phase(broad_phase).pairs(boxes, boxes + 0.3)
    state = State(np.array([[0.0, 0.3, 0.0], [0.5, 0.3, 0.0]]), np.array([[1.0, -1.0, 0.0], [-1.0, 0.0, 0.0]]),
                  np.ones(2), np.full(2, 0.1), np.ones(2), np.ones(2))
    walls = Walls(["floor"], np.array([[0.0, 1.0, 0.0]]), np.zeros(1), np.ones(1), np.zeros(1, dtype=np.bool_),
                  np.zeros(1))
    for detection in ("swept", "sampled"):
        World(state.copy(), walls, Settings(detection=detection)).step(0.5)
    return perf_counter() - started
