"""The world and its step: a named pipeline of phases, each timed.

Why one module of this size: it is the step pipeline over one step context, each phase
a method with the Python side of the time-ordered loop it drives; the calendar's step
(calendar_step.py) and the world's use of its meshes (mesh_steps.py) stand apart.

``World.step(dt)`` runs::

    forces        held contacts -> accelerations; semi-implicit velocity update
    broad_phase   swept box of each path over the step -> candidate pairs
    narrow_phase  swept test of every candidate pair and particle–wall pair whose path boxes meet
    resolve       contacts taken in the order of the policy:
                    time  - earliest first; advance the particles to it, change their
                            velocities, re-predict only them, repeat (no lost time);
                    index - every contact predicted at step start, resolved in
                            detection order, nothing re-predicted (the naive engine,
                            kept on purpose so its failures can be shown)
    finish        advance every particle to the end of the step; audit overlaps;
                  energies, momentum and the state hash

Each phase is a method over one :class:`~.step_context.StepContext`, which holds what
lives for the step (the path accelerations, the swept boxes, the candidate pairs, the
warnings, the timings); the world keeps only what lasts the run.

Each particle carries an *anchor*: its position and velocity at a time sigma inside the
step, from which :mod:`motion` gives its path. Resolving a contact at time t advances the
anchors of the particles involved to t, so the rest of their step runs over exactly the
remaining time. Events go to ``observer.on_event``; with no observer, building them
costs one branch per step. The step's swept tests (``SweptTests``: every test, misses
included) are logged and sent only to an observer that reads them (see
``wants_swept_tests``): the tests of a dense step run to tens of millions.
"""

from __future__ import annotations

import math
from time import perf_counter

import numpy as np

from ..events import (
    KIND_MESH,
    KIND_PAIR,
    OUTCOME_CAPPED,
    OUTCOME_HIT,
    OUTCOME_SUPERSEDED,
    BroadPhaseInfo,
    Contacts,
    StepBegin,
    StepCounts,
    StepEnd,
    SweptTests,
    overlap_words,
    partner_words,
)
from . import calendar
from .calendar_step import CalendarSteps
from .mesh_steps import MeshSteps
from .broadphase import choose_broad_phase, make_broad_phase
from .broadphase.boxes import boxes_meet
from .broadphase.periodic import PeriodicBroadPhase
from .colliders import KINDS, PARTNER_IS_SPHERE, deepest_overlap, geometry_of, narrow_candidates
from .jit import records
from .kernel_args import LoopBudgets, LoopCandidates, LoopMethod, LoopParticles
from .memory import MemoryBudget
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
    keep_on_moving_partners,
    resolve_at_one_instant,
    resolve_contact,
    settle_held,
)
from .resting import (HELD, PINNED, PINNED_CONTACTS, RAPID_RULES, STEP_RELEASED, STEP_WORK, grow_held, held_room,
                      new_held, renumber_held)
from .resting.store import STOP
from ..errors import PinnedSphere, StepStopped
from .sleep import SUPPORT_GAP, Sleepers, release_static, split_sleeping
from .space_order import RENUMBER_EVERY, Numbering, chosen_order, inverse_permutation, morton_order
from .state import (STATE_FIELDS, NonFiniteState, Settings, State, Walls, energies, first_non_finite,
                    budget_message, state_hash)
from .step_context import StepContext, wants_mesh_search, wants_swept_tests
from .timeline import (
    CAPPED,
    CONTACT_ROOM,
    CONTACTS,
    DONE,
    EVENTS,
    GROW,
    GROW_HELD,
    RAPID,
    REQUERY,
    RESTING_BUDGET,
    STOPPED,
    TEST_BUDGET,
    ROWS,
    TESTS,
    Buffers,
    adjacency_from_pairs,
    mark_capped,
    merge_sorted_pairs,
    predict_into,
    prediction_room,
    run_time_order,
)

# Partner lists against a scan (World._choose_partner_search): a listed pair costs about
# this many box tests of a scan (measured on highspeed and box-rain: ~70 ns a pair through
# the grid, the adjacency and the paths' filter, ~2 ns a box scanned); and how often a
# world that scans lists again, to know what the lists would hold.
SCAN_PER_LISTED_PAIR = 35.0
RELIST_EVERY = 32

# Updates of the held-contact solves smaller than this (relative to the largest free
# acceleration, at least 1 m/s², and for velocities to that acceleration times dt) wake
# no neighbours: they are rounding.
SOLVE_TOLERANCE = 1e-12
# the settings a world takes in the middle of a run (World.retune: a fork of a recording,
# docs/recording.md "Forking a recording"): those each step reads afresh, and the
# integrator and detection, whose traits retune derives again. The others shape what the
# world built (its numbering, broad phase, sleepers, budgets, the forces' arrays).
RETUNABLE_SETTINGS = ("detection", "integrator", "samples", "restitution_rule", "rapid_contact_time",
                      "rapid_contact_rule", "rest_fraction")


class World(MeshSteps, CalendarSteps):
    """Particles, walls and settings, stepped in place.

    state: the particles (its positions and velocities are updated in place by ``step``,
    and what is written to them between steps counts); walls: the planes; settings:
    methods and tolerances; observer: anything with ``on_event(event)``, and optionally
    ``wants_swept_tests`` (see the function of that name).

    A large world numbers the spheres its own way (``settings.space_order``,
    space_order.py): ``numbering`` translates (None: the scene's numbering). ``state``,
    the events and the stats are always in the scene's numbering; what is inside
    (``held``, ``sleepers``, ``last_step``) is in the world's, which it renews every
    RENUMBER_EVERY steps.
    """

    def __init__(self, state: State, walls: Walls, settings: Settings, observer=None):
        if settings.undecided():
            raise ValueError(f"{', '.join(settings.undecided())} still 'auto': decide it before building a World "
                             f"(physdbg.advisor.decide(scene), or load with physdbg.api.load_scene)")
        bad = first_non_finite(state.positions, state.velocities)
        if bad is not None:
            raise ValueError(f"the initial {bad[1]} of sphere {bad[0]} is NaN or infinite")
        self.state = state
        self.walls = walls
        self.settings = settings
        self.observer = observer
        self.step_index = 0
        self._memory = MemoryBudget(settings.max_memory, state.count)
        self.time = 0.0
        movable = state.inverse_mass > 0
        state.velocities[~movable] = 0.0
        # the colliders' geometry is built once; only a kinematic mesh's arrays are
        # rewritten in place, at each step's start (_place_meshes)
        self._geometry = geometry_of(walls)
        self._meshes_move = bool(walls.meshes.moving.any())
        self._walks_mesh_trees = len(walls.meshes) > 0  # MeshSearch events (the reference loop walks none)
        self._period = np.ascontiguousarray(walls.period, dtype=np.float64).reshape(3)
        self._period_origin = np.ascontiguousarray(walls.period_origin, dtype=np.float64)
        self._periodic = walls.periodic
        if self._periodic:
            wrap_positions(state.positions, self._period_origin, self._period)
        # the world's own numbering (space_order.py): self._st is the particles in it, and
        # is self.state itself when it is the scene's
        self.numbering: Numbering | None = None
        self._st = state
        if chosen_order(settings.space_order, state.count, settings.ordering) == "morton":
            self.numbering = Numbering(morton_order(state.positions))
            self._st = State(*(self.numbering.inward(getattr(state, name)) for name in STATE_FIELDS))
            movable = self._st.inverse_mass > 0
        st = self._st
        chosen, self.broad_phase_reason = choose_broad_phase(settings.broad_phase, st.radius)
        self.broad_phase = make_broad_phase(chosen)
        self.held = new_held(st.count)
        self._last_contact = np.full(st.count, -math.inf)
        self._integrator = settings.integrator_code
        self._detection = settings.detection_code
        self._drag = float(settings.drag)
        self._k = -math.log(self._drag)
        gravity = np.asarray(settings.gravity, dtype=np.float64)
        self.gravity = gravity
        self._free_accel = np.ascontiguousarray(
            (st.gravity_scale * movable)[:, None] * gravity[None, :])
        # the integrator's traits (motion.py's table): no branch on which integrator it is
        self._anchor_is_flow = FLOW[self._integrator][self._drag != 1.0]
        self._rest_step_factor = REST_STEP_FACTOR[self._integrator]
        self._kick_first = KICK_AT_STEP_START[self._integrator]
        self._accel_scale = max(1.0, float(np.abs(self._free_accel).max())) if st.count else 1.0
        self._atol = SOLVE_TOLERANCE * self._accel_scale
        self._acc = np.zeros((st.count, 3))
        if self._periodic:
            self.broad_phase = PeriodicBroadPhase(self.broad_phase, self._period_origin, self._period)
        self._buf = Buffers(state.count)
        # a re-query the loop can answer itself (timeline.grow_unpartnered) without a pause
        self._scan_boxes = bool(self.broad_phase.query_scans_boxes) and not self._periodic
        # partner lists or a scan per re-prediction (_choose_partner_search): what the last
        # step with lists paired per sphere, and the re-predictions of the last step
        self._listed_pairs_per_sphere = 0.0
        self._last_contacts = 0
        self.scanned_steps = 0  # steps whose re-predictions scanned every path box
        # a walk per sphere or the simultaneous descent (_choose_mesh_search): the last
        # counted work of each (node tests of a walk), and the steps that descended together
        self._search_work: tuple[float, float] | None = None
        self.together_steps = 0
        # sleeping (sleep.py): the step reads these, not state.inverse_mass and the free
        # accelerations, so a sleeping sphere is immovable and feels no gravity
        self._inverse_mass = st.inverse_mass
        self._free_accel_awake = self._free_accel
        self.sleepers: Sleepers | None = None
        if settings.sleep_speed > 0:
            if self._periodic:
                raise ValueError("sleep_speed > 0 needs a scene without periodic walls (sleep.py)")
            self.sleepers = Sleepers(self._free_accel, self._k, settings.sleep_speed, settings.sleep_time)
            self._inverse_mass = st.inverse_mass.copy()
            self._free_accel = self._free_accel.copy()
        # every swept box is padded by this (m) beyond the sphere: the contact tolerance, and
        # with sleeping the sleep rules' touching distance, so every pair they count as
        # touching at a step's end is one of the step's candidate pairs whatever the reach
        self._box_margin = settings.contact_tolerance
        if self.sleepers is not None and st.count:
            self._box_margin += SUPPORT_GAP * float(st.radius.max())
        self.contact_cap = settings.contact_cap(state.count)
        self.resting_budget = settings.budget("max_resting_work_per_step", state.count)
        self._stop_asked = False  # request_stop
        self.last_step: StepContext | None = None  # the context of the latest step (for inspection)
        # the event calendar (settings.event_loop = "calendar"): kept across the steps it
        # serves; the steps it served, and why the last one it could not serve could not
        self._calendar: calendar.Calendar | None = None
        self._calendar_settled_unfit = self._calendar_unfit_by_scene()
        self.calendar_steps = 0
        self._calendar_delta: float | None = None  # the calendar's shell thickness (m; calendar.shell_fit)
        self.calendar_unfit: str | None = None

    def asleep(self) -> np.ndarray | None:
        """(N,) bool in the scene's numbering: the spheres asleep now (sleep.py), or None
        when the world does not sleep. (``self.sleepers`` is in the world's own numbering.)"""
        if self.sleepers is None:
            return None
        if self.numbering is None:
            return self.sleepers.asleep.copy()
        return self.numbering.outward(self.sleepers.asleep)

    def scene_sphere(self, index: int) -> int:
        """The scene's number of the world's sphere ``index`` (space_order.py)."""
        return index if self.numbering is None else self.numbering.sphere(index)

    @property
    def held_count(self) -> int:
        """How many contacts are held (resting or rapid, resting/)."""
        return int(self.held.count[HELD])

    # ------------------------------------------------------------------ the step
    def step(self, dt: float) -> StepEnd:
        """Advance the world by ``dt`` seconds and report what happened (the StepEnd the
        observer also gets).

        Raises NonFiniteState (after reporting the step) when a position or velocity
        became NaN or infinite, PinnedSphere when a moving mesh pins a sphere against
        something immovable (resting.pinned_by): the world cannot go on from there.
        """
        self._stop_if_asked()
        dt = _checked_step_length(dt)
        if self.settings.event_loop == "calendar":
            self.calendar_unfit = self._calendar_unfit()
            if self.calendar_unfit is None:
                return self._calendar_step(self._begin(dt, renumber=False))
            self._calendar = None  # the time-ordered loop changes the paths: the calendar is out of date
        ctx = self._begin(dt)
        for name, phase in self._phases():
            self._timed(ctx, name, phase)
            self._stop_if_asked()
            if name == "broad_phase" and ctx.observer is not None:  # reported outside its timing
                ctx.observer.on_event(self._broad_phase_event(ctx))
            if name == "resolve" and ctx.search_start is not None:  # while the meshes are placed for the step
                ctx.mesh_search = self._mesh_search_event(ctx)
        return self._end(ctx)

    def _phases(self) -> tuple:
        """The step's phases in order, each (its name in events.STEP_PHASES, the method that runs it)."""
        return (("forces", self._forces), ("broad_phase", self._broad_phase), ("narrow_phase", self._narrow_phase),
                ("resolve", self._resolve), ("finish", self._finish))

    def retune(self, changes: dict) -> None:
        """Change settings between two steps (RETUNABLE_SETTINGS, by name: the value as a
        scene gives it): what the world carries (positions, velocities, held contacts,
        sleep, the rapid-contact times, its numbering) stays; the integrator's and the
        detection's codes and traits are derived again, and the event calendar, which
        predicted with the old ones, starts afresh. ValueError for any other setting."""
        unknown = sorted(set(changes) - set(RETUNABLE_SETTINGS))
        if unknown:
            raise ValueError(f"{', '.join(unknown)} cannot change in the middle of a run; these can: "
                             f"{', '.join(RETUNABLE_SETTINGS)}")
        for name, value in changes.items():
            setattr(self.settings, name, value)
        self._integrator = self.settings.integrator_code
        self._detection = self.settings.detection_code
        self._anchor_is_flow = FLOW[self._integrator][self._drag != 1.0]
        self._rest_step_factor = REST_STEP_FACTOR[self._integrator]
        self._kick_first = KICK_AT_STEP_START[self._integrator]
        self._calendar = None
        self._calendar_settled_unfit = self._calendar_unfit_by_scene()

    def request_stop(self) -> None:
        """Ask the world to stop: the step under way ends at once, half done and
        unreported, with StepStopped (so does every later step). Safe from any thread and
        from a signal handler: it sets one integer that the compiled event loop and the
        held-contact solves read as they go (kernels release the GIL: jit.py), and Python
        checks between phases."""
        self._stop_asked = True
        self.held.count[STOP] = 1

    def _stop_if_asked(self) -> None:
        if self._stop_asked:
            raise StepStopped(self.step_index + 1)

    def _begin(self, dt: float, renumber: bool = True) -> StepContext:
        # a velocity residue of vtol moves a sphere vtol·dt in a step: SOLVE_TOLERANCE·a·dt²
        ctx = StepContext(self.step_index + 1, dt, self.time, SOLVE_TOLERANCE * self._accel_scale * dt, self.observer)
        self.last_step = ctx
        self._place_meshes(self.time, dt)
        if self.numbering is not None:  # World.state is the world: what was written to it counts
            self.numbering.inward(self.state.positions, out=self._st.positions)
            self.numbering.inward(self.state.velocities, out=self._st.velocities)
            if renumber and self._renumber_due():
                self._renumber()
        if ctx.observer is not None:
            ctx.observer.on_event(StepBegin(ctx.step, ctx.run_time, dt))
        return ctx

    def _renumber_due(self) -> bool:
        """Whether this step renumbers the spheres (space_order.py: every RENUMBER_EVERY steps)."""
        return self.numbering is not None and bool(self.step_index) and self.step_index % RENUMBER_EVERY == 0

    @staticmethod
    def _timed(ctx: StepContext, name: str, phase) -> None:
        started = perf_counter()
        phase(ctx)
        ctx.timings[name] = perf_counter() - started

    def _forces(self, ctx: StepContext) -> None:
        """Held contacts -> the accelerations the paths follow (resolve.settle_held), once
        the sleepers a moving mesh may reach are woken (_wake_where_meshes_move)."""
        self._wake_where_meshes_move(ctx)
        s, n = self.settings, self._st.count
        self.held.count[STEP_WORK:STEP_RELEASED + 1] = 0  # this step's resting work, whole solves, releases
        ctx.path_accel = np.empty_like(self._acc)
        ctx.sigma = np.zeros(n)
        particles, method, geometry = self._kernel_groups(ctx)
        if not settle_held(self.held, particles, method, geometry, self._free_accel, s.contact_tolerance,
                           self.resting_budget):
            if self.held.count[PINNED]:
                ctx.warn("pinned", *self._pinned_warning())
            else:
                ctx.warn("max_resting_work_per_step",
                         budget_message("max_resting_work_per_step", self.resting_budget))

    def _broad_phase(self, ctx: StepContext) -> None:
        """Each path's swept box over the step, grown to its reach -> candidate pairs (or,
        where a scan per re-prediction costs less than the lists, the pairs of the paths'
        own boxes: _choose_partner_search)."""
        st, s, n = self._st, self.settings, self._st.count
        ctx.lo = np.empty((n, 3))
        ctx.hi = np.empty((n, 3))
        swept_boxes(st.positions, st.velocities, ctx.path_accel, st.radius, ctx.sigma, ctx.dt, self._integrator,
                    self._k, self._box_margin, ctx.lo, ctx.hi)
        ctx.path_lo, ctx.path_hi = ctx.lo.copy(), ctx.hi.copy()
        ctx.scan_partners = self._choose_partner_search()
        self.scanned_steps += int(ctx.scan_partners)
        if not ctx.scan_partners:
            self._add_reach(ctx)
        too_wide = self._too_wide_for_the_period(ctx.lo, ctx.hi)
        if too_wide:
            ctx.warn("periodic", too_wide)
            pairs = np.empty((0, 2), dtype=np.int64)
        else:
            pairs = self.broad_phase.pairs(ctx.lo, ctx.hi, s.max_pairs_per_step)
        if len(pairs) > s.max_pairs_per_step:
            ctx.warn("max_pairs_per_step", budget_message("max_pairs_per_step", s.max_pairs_per_step))
            pairs = np.empty((0, 2), dtype=np.int64)
        if self.sleepers is not None and len(pairs):  # two sleeping spheres cannot meet
            pairs, ctx.sleeping_pairs = split_sleeping(np.ascontiguousarray(pairs, dtype=np.int64),
                                                       self.sleepers.asleep)
        self._build_adjacency(ctx, pairs)
        if ctx.scan_partners:
            ctx.max_degree = max(n - 1, 0)  # a scan may find every other sphere
        elif n:
            self._listed_pairs_per_sphere = len(pairs) / n

    def _choose_partner_search(self) -> bool:
        """Whether this step's re-predictions scan every sphere's path box instead of
        listing each sphere's partners at the step's start (sphere.partners_of): the same
        contacts and states either way, bit for bit, and the cheaper one is chosen from
        counts, never from times. The lists cost about SCAN_PER_LISTED_PAIR box tests per
        pair (grid, adjacency and the paths' filter); a scan costs one per sphere per
        re-prediction, about two per contact. Lists win in a pile (box-rain: thousands of
        contacts a step, a few pairs a sphere); a scan among fast spheres whose speeds
        vary, whose boxes grown to their reach overlap by the dozen (highspeed: 70 pairs a
        sphere, 350 contacts a step among 5,000). Only with the grid (a stateless broad
        phase), no periodic axis and no sleeping; every RELIST_EVERY steps lists again, to
        measure what the lists would hold."""
        n = self._st.count
        if not self._scan_boxes or self.sleepers is not None or self.settings.ordering != "time" or n < 2:
            return False
        if self.step_index % RELIST_EVERY == 0 or self._listed_pairs_per_sphere == 0.0:
            return False
        scan = 2.0 * self._last_contacts * n
        return scan < SCAN_PER_LISTED_PAIR * self._listed_pairs_per_sphere * n

    def _narrow_phase(self, ctx: StepContext) -> None:
        """The swept test of every candidate of every collider kind whose path boxes meet:
        the broad phase's pairs, the walls each path reaches (colliders.narrow_candidates).
        The broad phase paired the boxes grown to what a sphere could reach after a contact;
        until a contact changes a path, only the path's own box can meet anything, and a
        changed path is tested again against every partner of the grown box (timeline)."""
        # an unobserved step logs only the tests that hit (Buffers.reset)
        log_queries = self._walks_mesh_trees and wants_mesh_search(ctx.observer)
        self._buf.reset(keep_misses=wants_swept_tests(ctx.observer), log_queries=log_queries)
        if log_queries:  # every sphere's path box asks the meshes' trees (colliders.narrow_candidates)
            ctx.search_start = (ctx.path_lo.copy(), ctx.path_hi.copy())
        push = self.settings.ordering == "time"
        for kind in range(KINDS):  # in the kinds' order: ties in the queue break by test
            if kind == KIND_MESH and self._walks_mesh_trees:
                ia, other = self._mesh_candidates(ctx)
            else:
                ia, other = narrow_candidates(kind, ctx.pairs, ctx.path_lo, ctx.path_hi, self._geometry)
            self._predict(ctx, kind, ia, other, push)

    def _resolve(self, ctx: StepContext) -> None:
        """The contacts, in the order of the policy (``settings.ordering``); none once a
        sphere is pinned (the forces phase found it: the step ends as it stands)."""
        if self.held.count[PINNED]:
            return
        s = self.settings
        budget = self._resolve_in_time_order(ctx) if s.ordering == "time" else self._resolve_in_index_order(ctx)
        if ctx.too_wide_mid_step and not ctx.warned("periodic"):
            ctx.warn("periodic", ctx.too_wide_mid_step)
        if budget == "max_resting_work_per_step" and self.held.count[PINNED]:
            if not ctx.warned("pinned"):
                ctx.warn("pinned", *self._pinned_warning())
        elif budget == "max_memory" and not ctx.warned(budget):
            ctx.warn(budget, self._memory.message(ctx))
        elif budget is not None and not ctx.warned(budget):
            ctx.warn(budget, budget_message(budget, s.budget(budget, self._st.count)))

    def _finish(self, ctx: StepContext) -> None:
        """Every sphere to the end of the step; the overlap audit, energies and state hash."""
        st, s, n = self._st, self.settings, self._st.count
        x, v = st.positions, st.velocities
        advance_particles(x, v, ctx.path_accel, ctx.sigma, np.arange(n, dtype=np.int64), ctx.dt, self._integrator,
                          self._drag, self._k)
        ctx.sigma[:] = 0.0
        self._close(ctx)

    def _close(self, ctx: StepContext) -> None:
        """The step's end, every sphere at it: wrapped into a periodic box, the overlap
        audit, the sleep rules, energies and the state hash (both event loops)."""
        st, s = self._st, self.settings
        x, v = st.positions, st.velocities
        if self._periodic:  # the paths were continuous through the step; the state is in the box
            wrap_positions(x, self._period_origin, self._period)
        self._place_meshes(self.time + ctx.dt, 0.0)  # the audit sees the meshes where the spheres are
        if self._meshes_move and self.held.count[HELD]:  # held spheres end the step on a moving surface
            keep_on_moving_partners(self.held, x, v, ctx.path_accel, st.radius, ctx.sigma, self._inverse_mass, self._geometry,
                                    s.contact_tolerance)
        ctx.max_overlap, ctx.overlap_with = self._max_overlap(ctx)
        if s.detection == "swept" and ctx.max_overlap > s.contact_tolerance and not ctx.warnings:
            who = ctx.overlap_with
            ctx.warn("overlap", f"{overlap_words(who, self.walls.partner_names())} overlap by "
                                f"{ctx.max_overlap:.3g} m, more than the contact tolerance {s.contact_tolerance:g} m",
                     () if who is None else (who[1], who[2]) if PARTNER_IS_SPHERE[who[0]] else (who[1],))
        if self.sleepers is not None:
            self._sleep(ctx)
        if self.numbering is not None:  # what leaves the world is in the scene's numbering
            self.numbering.outward(x, out=self.state.positions)
            self.numbering.outward(v, out=self.state.velocities)
            x, v = self.state.positions, self.state.velocities
        ctx.non_finite = first_non_finite(x, v)
        if ctx.non_finite is not None:
            ctx.warn("non-finite", str(NonFiniteState(ctx.step, *ctx.non_finite)), (ctx.non_finite[0],))
        ctx.kinetic, ctx.potential, ctx.momentum = energies(self.state, self.gravity)
        ctx.state_hash = state_hash(x, v)
        self.time += ctx.dt
        self.step_index += 1

    def _sleep(self, ctx: StepContext) -> None:
        """The sleep rules at the step's end (sleep.py): wake the disturbed, freeze the slow."""
        st, sleepers = self._st, self.sleepers
        rows = self._buf.contacts[:int(self._buf.counters[CONTACTS])]
        pair_lists = (np.ascontiguousarray(ctx.pairs, dtype=np.int64),
                      np.ascontiguousarray(ctx.sleeping_pairs, dtype=np.int64))
        fell, woke = sleepers.end_of_step(ctx.dt, st.positions, st.velocities, st.radius, pair_lists, rows,
                                          self._carried())
        self._inverse_mass[woke] = st.inverse_mass[woke]
        self._free_accel[woke] = self._free_accel_awake[woke]
        self._inverse_mass[fell] = 0.0
        self._free_accel[fell] = 0.0
        if fell.size:
            release_static(self.held, self._inverse_mass)
        ctx.slept = int(fell.size)
        ctx.woken += int(woke.size)
        ctx.sleep_changed = np.concatenate([fell, woke]).astype(np.int64)

    def _end(self, ctx: StepContext) -> StepEnd:
        """The step's record, after its closing events; raises NonFiniteState or PinnedSphere after reporting."""
        buf = self._buf
        self._last_contacts = int(buf.counters[CONTACTS])
        counts = StepCounts(contacts=int(buf.counters[CONTACTS]), swept_tests=int(buf.counters[TESTS]),
                            events=int(buf.counters[EVENTS]), held=self.held_count, rapid=int(buf.counters[RAPID]),
                            released=int(self.held.count[STEP_RELEASED]),
                            asleep=self.sleepers.count if self.sleepers is not None else 0,
                            slept=ctx.slept, woken=ctx.woken)
        end = StepEnd(ctx.step, self.time, ctx.dt, self.state.positions.copy(), self.state.velocities.copy(),
                      ctx.kinetic, ctx.potential, ctx.momentum.copy(), counts, ctx.max_overlap, dict(ctx.timings),
                      ctx.state_hash, tuple(ctx.warnings), self.asleep(), ctx.overlap_with)
        obs = ctx.observer
        if obs is not None:
            obs.on_event(self._contacts_event(ctx))
            if wants_swept_tests(obs):
                obs.on_event(self._swept_tests_event(ctx))
            if ctx.mesh_search is not None:
                obs.on_event(ctx.mesh_search)
            obs.on_event(end)
        if ctx.non_finite is not None:
            raise NonFiniteState(ctx.step, *ctx.non_finite)
        if self.held.count[PINNED]:
            raise PinnedSphere(ctx.step, self._pinned_warning()[0])
        return end

    def _pinned_warning(self) -> tuple[str, tuple[int]]:
        """The pinned sphere and its two partners (resting.pinned_by), as reports name them,
        and the sphere (scene numbering): a "pinned" warning's message and bodies."""
        count = self.held.count
        names = self.walls.partner_names()
        sphere = self.scene_sphere(int(count[PINNED]) - 1)
        first, second = (partner_words(int(count[PINNED_CONTACTS + 2 * e]), int(count[PINNED_CONTACTS + 2 * e + 1]),
                                       names) for e in range(2))
        return f"sphere {sphere} is pinned between {first} and {second}, which close on it from opposite sides", (sphere,)

    def _renumber(self) -> None:
        """Number the spheres in Morton order of where they are now (space_order.py): every
        array that outlives a step is permuted, the held contacts and the sleepers too."""
        old_of_new = morton_order(self._st.positions)
        new_of_old = inverse_permutation(old_of_new)
        moved: dict[int, np.ndarray] = {}  # by id: an array held under two names stays one array

        def move(rows: np.ndarray) -> np.ndarray:
            if id(rows) not in moved:
                moved[id(rows)] = np.take(rows, old_of_new, axis=0)
            return moved[id(rows)]

        st = self._st
        for name in STATE_FIELDS:
            setattr(st, name, move(getattr(st, name)))
        self._inverse_mass, self._free_accel, self._free_accel_awake, self._acc, self._last_contact = (
            move(rows) for rows in (self._inverse_mass, self._free_accel, self._free_accel_awake, self._acc,
                                    self._last_contact))
        if self.sleepers is not None:
            self.sleepers.renumber(old_of_new)
        renumber_held(self.held, old_of_new, new_of_old)
        self._buf.renumber(old_of_new)
        self.broad_phase.renumbered()
        self.numbering = Numbering(self.numbering.inner_to_scene[old_of_new])

    def _loop_method(self, run_time: float, dt: float, vtol: float) -> tuple:
        """kernel_args.LoopMethod of a step (or of the calendar: run_time its epoch), as a plain tuple."""
        s = self.settings
        return tuple(LoopMethod(run_time, dt, self._integrator, self._drag, self._k, self._detection, s.samples,
                                s.contact_tolerance * 1e-3, s.rest_fraction, self._rest_step_factor,
                                RESTITUTION_RULES.index(s.restitution_rule), s.rapid_contact_time,
                                RAPID_RULES.index(s.rapid_contact_rule), self._anchor_is_flow,
                                not self._kick_first, vtol, self._atol))

    # ------------------------------------------------------------------ candidates
    @staticmethod
    def _build_adjacency(ctx: StepContext, pairs: np.ndarray) -> None:
        """CSR lists of each particle's broad-phase partners (pairs must be sorted)."""
        n = ctx.sigma.shape[0]
        ctx.adj_start, ctx.adj = adjacency_from_pairs(np.ascontiguousarray(pairs, dtype=np.int64), n)
        ctx.max_degree = int(np.diff(ctx.adj_start).max()) if n else 0
        ctx.pairs = pairs

    def _add_reach(self, ctx: StepContext) -> None:
        """Grow each swept box to the cube a sphere could reach this step at a typical speed.

        A contact turns a path, so a box around the old path alone would send nearly every
        particle back to the broad phase after its first contact. The cube x ± (reach + r)
        with reach = max(own speed, min(the scene's 99th-percentile speed, the fastest
        sphere nearby)) · dt (speed counting one step of acceleration; "nearby":
        motion.nearby_fastest) holds any path that does not outrun it; the rare one that
        does is queried again (timeline.REQUERY). In place on ctx.lo, ctx.hi (N, 3).
        """
        st = self._st
        # compiled (motion.grow_to_reach): np.quantile alone was a third of a small step
        grow_to_reach(st.positions, st.velocities, ctx.path_accel, st.radius, ctx.dt, self._box_margin,
                      ctx.lo, ctx.hi)

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

    def _refresh_box(self, ctx: StepContext, i: int) -> list[int]:
        """Grow i's swept box to hold its new path; return partners it did not have."""
        st = self._st
        lo = np.empty(3)
        hi = np.empty(3)
        particle_box(st.positions, st.velocities, ctx.path_accel, st.radius, ctx.sigma, i, ctx.dt, self._integrator,
                     self._k, self._box_margin, lo, hi)
        if np.all(lo >= ctx.lo[i]) and np.all(hi <= ctx.hi[i]):
            return []
        ctx.lo[i] = np.minimum(ctx.lo[i], lo)
        ctx.hi[i] = np.maximum(ctx.hi[i], hi)
        if self._periodic and ctx.too_wide_mid_step is None:
            ctx.too_wide_mid_step = self._too_wide_for_the_period(
                ctx.lo[i:i + 1], ctx.hi[i:i + 1],
                f"sphere {self.scene_sphere(i)}'s later contacts in this step (after a contact sent it out of its "
                f"box) may have met the wrong image")
        found = set(self.broad_phase.query(ctx.lo, ctx.hi, ctx.lo[i], ctx.hi[i]).tolist())
        # a structure built at step start knows the old boxes: check grown ones directly
        if ctx.grown:
            grown = np.fromiter(ctx.grown, dtype=np.int64)
            hit = boxes_meet(ctx.lo[grown], ctx.hi[grown], ctx.lo[i], ctx.hi[i], self._period)
            found.update(grown[hit].tolist())
        ctx.grown.add(i)
        known = set(ctx.partners(i).tolist())
        return sorted(j for j in found if j != i and j not in known)

    def _add_partners(self, ctx: StepContext, new_pairs: list[tuple[int, int]]) -> None:
        """Add broad-phase pairs found mid-step, and predict them."""
        if not new_pairs:
            return
        extra = np.array(sorted(set(new_pairs)), dtype=np.int64).reshape(-1, 2)
        # new_pairs holds no known partner (_refresh_box), so the two lists are disjoint
        self._build_adjacency(ctx, merge_sorted_pairs(np.ascontiguousarray(ctx.pairs, dtype=np.int64), extra))
        self._predict(ctx, KIND_PAIR, extra[:, 0].copy(), extra[:, 1].copy(), True)

    # ------------------------------------------------------------------ narrow phase
    def _predict(self, ctx: StepContext, kind: int, ia: np.ndarray, ib: np.ndarray, push: bool) -> None:
        """Swept-test candidates (kind, ia[m], ib[m]) into the buffers (held ones skipped);
        none if the buffers cannot grow for them within max_memory (ctx.out_of_memory)."""
        if ia.size == 0:
            return
        if ctx.out_of_memory or not self._ensure(ctx, ia.size, ia.size, 0):
            return  # the step stops before resolving anything more (_resolve)
        particles, method, geometry = self._kernel_groups(ctx)
        predict_into(kind, ia, ib, particles, method, geometry, self.held, self._buf.loop(), push)

    # ------------------------------------------------------------------ policies
    def _resolve_in_time_order(self, ctx: StepContext) -> str | None:
        """The compiled loop, with Python taking the pauses (see timeline.py); returns the
        budget that stopped it (a Settings field name), or None."""
        s = self.settings
        buf = self._buf
        particles, method, geometry = self._kernel_groups(ctx)
        budgets = tuple(LoopBudgets(self.contact_cap, s.swept_test_budget(self._st.count),
                                    self.resting_budget))
        while True:
            if ctx.out_of_memory:  # the narrow phase, or a re-query's predictions, did not fit
                mark_capped(buf.heap_data, buf.test_outcome, buf.counters)
                return "max_memory"
            # the held store, the adjacency and the buffers are replaced when they grow
            candidates = tuple(LoopCandidates(ctx.adj_start, ctx.adj, ctx.lo, ctx.hi, self._box_margin,
                                              ctx.max_degree, ctx.path_lo, ctx.path_hi, self._scan_boxes,
                                              ctx.scan_partners))
            status = run_time_order(particles, method, geometry, self.held, candidates, budgets, buf.loop())
            if status == DONE:
                return None
            if status == CAPPED:
                return "max_contacts_per_step"
            if status == TEST_BUDGET:
                return "max_swept_tests_per_step"
            if status == RESTING_BUDGET:
                return "max_resting_work_per_step"
            if status == STOPPED:
                return None  # World.step raises StepStopped after this phase
            if status == GROW:
                room = prediction_room(geometry, ctx.max_degree)
                self._ensure(ctx, room, room, CONTACT_ROOM)
            elif status == GROW_HELD:
                self._grow_held(ctx)
            elif status == REQUERY:
                new_pairs = []
                for i in buf.requery[: buf.requery_count[0]].tolist():
                    new_pairs += [(min(i, j), max(i, j)) for j in self._refresh_box(ctx, i)]
                self._add_partners(ctx, new_pairs)

    def _resolve_in_index_order(self, ctx: StepContext) -> str | None:
        """Every contact predicted at step start, in detection order, nothing re-predicted;
        returns the budget that stopped it (a Settings field name), or None."""
        buf = self._buf
        count = int(buf.counters[ROWS])
        toi = buf.test_float[:count, 1]
        hits = np.nonzero(toi <= ctx.dt)[0]
        if ctx.out_of_memory:  # the narrow phase did not fit: nothing is resolved
            buf.test_outcome[hits] = OUTCOME_CAPPED
            return "max_memory"
        for rid in hits.tolist():
            buf.counters[EVENTS] += 1
            if buf.counters[CONTACTS] >= self.contact_cap:
                buf.test_outcome[hits[hits >= rid]] = OUTCOME_CAPPED
                return "max_contacts_per_step"
            kind, a, other = (int(c) for c in buf.test_int[rid])
            if not self._ensure(ctx, 0, 0, 1) or not self._held_room(ctx, a, other if PARTNER_IS_SPHERE[kind] else -1):
                buf.test_outcome[hits[hits >= rid]] = OUTCOME_CAPPED
                return "max_memory"
            at = max(float(toi[rid]), ctx.sigma[a], ctx.sigma[other] if PARTNER_IS_SPHERE[kind] else 0.0)
            status = self._resolve_one(ctx, kind, a, other, at)
            buf.test_outcome[rid] = OUTCOME_SUPERSEDED if status == SKIPPED else OUTCOME_HIT
            if status == OUT_OF_WORK:
                buf.test_outcome[hits[hits > rid]] = OUTCOME_CAPPED
                return "max_resting_work_per_step"
        return None

    # ------------------------------------------------------------------ memory
    def _ensure(self, ctx: StepContext, heap_room: int, test_room: int, contact_room: int) -> bool:
        """Grow the loop's buffers for this much more within max_memory (memory.py)."""
        return self._memory.ensure(ctx, self._buf, self.held, heap_room, test_room, contact_room)

    def _grow_held(self, ctx: StepContext) -> bool:
        """Grow the held-contact store within max_memory (memory.py); False if it would not fit."""
        grown = self._memory.grow_held(ctx, self._buf, self.held)
        if grown is None:
            return False
        self.held = grown
        if self._stop_asked:  # asked while the store was being copied
            self.held.count[STOP] = 1
        return True

    def _held_room(self, ctx: StepContext, a: int, b: int) -> bool:
        """Room in the held store for a contact of a (and sphere b, or -1), grown if need
        be within max_memory."""
        while not held_room(self.held, a, b):
            if not self._grow_held(ctx):
                return False
        return True

    # ------------------------------------------------------------------ one contact
    def _resolve_one(self, ctx: StepContext, kind: int, a: int, other: int, when: float) -> int:
        """Resolve one predicted contact at time ``when`` in the step (resolve.resolve_contact);
        returns its status (SKIPPED, RESOLVED or OUT_OF_WORK)."""
        buf = self._buf
        buf.ensure(0, 0, 1)
        while not held_room(self.held, a, other if PARTNER_IS_SPHERE[kind] else -1):
            self.held = grow_held(self.held)
        particles, method, geometry = self._kernel_groups(ctx)
        return resolve_contact(kind, a, other, when, particles, method, geometry, self.held, records(buf.contacts),
                               buf.counters, CONTACTS, RAPID, buf.changed, self.resting_budget)

    def _resolve_at_one_instant(self, ctx: StepContext, contacts: list[tuple[int, int]], a: int,
                                when: float) -> tuple[int, list[bool]]:
        """Resolve sphere a's contacts (kind, partner) with immovable partners at one
        instant, ``when`` in the step, together (resolve.resolve_at_one_instant; the first
        is the one taken from the queue); returns its status and which were resolved."""
        buf = self._buf
        buf.ensure(0, 0, CONTACT_ROOM)
        while not held_room(self.held, a, -1):
            self.held = grow_held(self.held)
        particles, method, geometry = self._kernel_groups(ctx)
        kinds = np.array([k for k, _ in contacts], dtype=np.int64)
        others = np.array([o for _, o in contacts], dtype=np.int64)
        resolved = np.zeros(len(contacts), dtype=np.int64)
        status = resolve_at_one_instant(kinds, others, len(contacts), a, when, particles, method, geometry, self.held,
                                        records(buf.contacts), buf.counters, CONTACTS, RAPID, buf.changed,
                                        self.resting_budget, resolved)
        return int(status), [bool(r) for r in resolved]

    def _kernel_groups(self, ctx: StepContext) -> tuple[tuple, tuple, tuple]:
        """The step's arrays and settings as the compiled loop and resolver take them:
        kernel_args' LoopParticles and LoopMethod, as plain tuples, and the colliders'
        geometry. Built once a step, in the forces phase (the index-ordered policy asks for
        them at every contact): none of their arrays is replaced after the forces phase
        makes the path accelerations and anchor times."""
        if ctx.kernel_groups is None:
            ctx.kernel_groups = self._build_kernel_groups(ctx)
        return ctx.kernel_groups

    def _build_kernel_groups(self, ctx: StepContext) -> tuple[tuple, tuple, tuple]:
        st = self._st
        particles = LoopParticles(st.positions, st.velocities, ctx.path_accel, self._acc, st.radius, self._inverse_mass,
                                  st.restitution, ctx.sigma, self._last_contact)
        return tuple(particles), self._loop_method(ctx.run_time, ctx.dt, ctx.vtol), self._geometry

    # ------------------------------------------------------------------ events
    def _contacts_event(self, ctx: StepContext) -> Contacts:
        rows = self._buf.contacts[:int(self._buf.counters[CONTACTS])].copy()
        if self.numbering is not None:  # a pair's a may then be the larger number
            rows["other"] = self.numbering.partners(rows["kind"], rows["other"])
            rows["a"] = self.numbering.spheres(rows["a"])
        return Contacts(ctx.step, rows)

    def _max_overlap(self, ctx: StepContext) -> tuple[float, tuple[int, int, int] | None]:
        """Deepest penetration (m) among candidate pairs and particle–wall pairs (after a
        step that scanned, the pairs whose spheres' boxes meet at its end: the step's
        pairs are those of the paths at its start), and its parties (kind, sphere, partner)
        in the scene's numbering (None when nothing overlaps)."""
        st = self._st
        pairs = ctx.pairs
        if ctx.scan_partners:
            r = st.radius[:, None]
            pairs = self.broad_phase.pairs(st.positions - r, st.positions + r)
        depth, kind, a, other = deepest_overlap(st.positions, st.radius, pairs, self._geometry,
                                                self.settings.detection != "swept")
        if kind < 0:
            return depth, None
        if self.numbering is not None:
            a = int(self.numbering.spheres(np.array([a]))[0])
            other = int(self.numbering.partners(np.array([kind]), np.array([other]))[0])
        if PARTNER_IS_SPHERE[kind] and other < a:
            a, other = other, a
        return depth, (kind, a, other)

    def _broad_phase_event(self, ctx: StepContext) -> BroadPhaseInfo:
        bp = self.broad_phase
        stats = dict(bp.stats)
        stats.setdefault("pairs", len(ctx.pairs))
        stats["scanned"] = bool(ctx.scan_partners)
        if ctx.mesh_search_method:  # how the triangles were searched (a scene with meshes)
            stats["mesh_search"] = ctx.mesh_search_method
        tree = bp.nodes
        nodes = None
        if tree is not None:
            nodes = {name: getattr(tree, name).copy() for name in
                     ("lo", "hi", "left", "right", "parent", "depth", "start", "count", "order")}
            if self.numbering is not None:
                nodes["order"] = self.numbering.spheres(nodes["order"])
        return BroadPhaseInfo(ctx.step, bp.name, self.broad_phase_reason, stats, nodes)

    def _swept_tests_event(self, ctx: StepContext) -> SweptTests:
        buf = self._buf
        count = int(buf.counters[ROWS])  # every test: an observed step logs them all
        toi = buf.test_float[:count, 1].copy()
        kind, a, other = buf.test_int[:count, 0], buf.test_int[:count, 1], buf.test_int[:count, 2]
        if self.numbering is not None:
            a, other = self.numbering.spheres(a), self.numbering.partners(kind, other)
        return SweptTests(ctx.step, kind.astype(np.int8), a.astype(np.int32), other.astype(np.int32),
                          buf.test_float[:count, 0].copy(), np.where(toi <= ctx.dt, toi, np.nan),
                          buf.test_outcome[:count].copy())


def _checked_step_length(dt) -> float:
    if isinstance(dt, bool) or not isinstance(dt, (int, float, np.floating)) or not 0.0 < dt < math.inf:
        raise ValueError(f"World.step needs dt, a positive finite number of seconds; got {dt!r} (a scene with "
                         f'dt = "real" gives each step\'s length through Scene.step_lengths())')
    return float(dt)
