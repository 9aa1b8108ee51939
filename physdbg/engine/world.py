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
from .motion import EULER, SEMI_IMPLICIT, VERLET, advance_particles, particle_box, swept_boxes
from .resolve import RESTITUTION_RULES, apply_pair_impulse, combine_restitution, pair_impulse, reflect, unit
from .resting import pressed_closing, rests, solve_accelerations
from .state import BUDGETS, NonFiniteState, Settings, State, Walls, energies, first_non_finite, state_hash
from .timeline import (
    CAPPED,
    CF_CLOSING,
    CF_IMPULSE,
    CF_NORMAL,
    CF_POINT,
    CF_RESTITUTION,
    CF_TIME,
    CF_VA_AFTER,
    CF_VA_BEFORE,
    CF_VB_AFTER,
    CF_VB_BEFORE,
    CONTACTS,
    DONE,
    EVENTS,
    GROW,
    PAUSE_RESOLVE,
    REQUERY,
    TEST_BUDGET,
    TESTS,
    Buffers,
    adjacency_from_pairs,
    mark_capped,
    max_overlap,
    predict_into,
    reachable_walls,
    run_time_order,
)



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
        self.held: dict[tuple, np.ndarray | None] = {}
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
        # exact and semi-implicit paths are flows: re-anchoring mid-path changes nothing
        self._anchor_is_flow = self._integrator not in (EULER, VERLET) or (
            self._integrator == VERLET and self._drag == 1.0)
        # straight Euler paths arrive at a rest with about one step of acceleration (resting.py)
        self._rest_step_factor = 1.5 if self._integrator in (EULER, SEMI_IMPLICIT) else 0.0
        self._offsets = np.ascontiguousarray(walls.offsets, dtype=np.float64)
        self._wall_restitution = np.ascontiguousarray(walls.restitution, dtype=np.float64)
        self._buf = Buffers()

    # ------------------------------------------------------------------ helpers
    def _wall_normal_towards(self, i: int, w: int) -> np.ndarray:
        """The wall's normal pointing to the side particle i is on."""
        n = self._normals[w]
        if self._two_sided[w] and float(n @ self.state.positions[i]) - self._offsets[w] < 0.0:
            return -n
        return n.copy()

    def _held_key_normal(self, key: tuple) -> np.ndarray:
        if key[0] == "wall":
            return self.held[key]
        d = self.state.positions[key[1]] - self.state.positions[key[2]]
        return unit(d)

    def _solve_held(self):
        """Accelerations from held contacts; contacts that no longer push are released."""
        while True:
            acc, lam, work = solve_accelerations(self._free_accel, self.state.inverse_mass,
                                                 self.state.positions, self.held)
            self._resting_work += work
            loose = [key for key, value in lam.items() if value <= 0.0]
            if not loose:
                return acc
            for key in loose:
                del self.held[key]

    def _project_held_velocities(self, particles: np.ndarray) -> None:
        """Remove any approach along held contacts from the velocities (in place)."""
        if not self.held:
            return
        projected, _, work = solve_accelerations(self.state.velocities, self.state.inverse_mass,
                                                 self.state.positions, self.held)
        self._resting_work += work
        self.state.velocities[particles] = projected[particles]

    def _held_gap_ok(self, key: tuple) -> bool:
        x = self.state.positions
        tol = self.settings.contact_tolerance
        if key[0] == "wall":
            i, w = key[1], key[2]
            h = float(self._normals[w] @ x[i]) - self._offsets[w]
            gap = (abs(h) if self._two_sided[w] else h) - self._half_thickness[w] - self.state.radius[i]
        else:
            i, j = key[1], key[2]
            gap = float(np.linalg.norm(x[i] - x[j])) - self.state.radius[i] - self.state.radius[j]
        return abs(gap) <= tol

    def _held_particles(self) -> set[int]:
        """Every particle in a held contact."""
        return {i for key in self.held for i in ((key[1], key[2]) if key[0] == "pair" else (key[1],))}

    def _sync_held(self) -> None:
        """Held contacts as the arrays the compiled loop reads (sorted keys, flags)."""
        n = self.state.count
        nw = len(self.walls)
        pairs = sorted(key[1] * n + key[2] for key in self.held if key[0] == "pair")
        walls = sorted(key[1] * nw + key[2] for key in self.held if key[0] == "wall")
        self._held_pairs = np.array(pairs, dtype=np.int64)
        self._held_walls = np.array(walls, dtype=np.int64)
        has = np.zeros(n, dtype=np.bool_)
        has[list(self._held_particles())] = True
        self._has_held = has

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
        for key in [key for key in self.held if not self._held_gap_ok(key)]:
            del self.held[key]
        acc = self._solve_held()
        if self._integrator == SEMI_IMPLICIT:
            damp = 1.0 if self._drag == 1.0 else self._drag ** dt
            v *= damp
            v += acc * dt
            path_accel = np.zeros_like(acc)
        else:
            path_accel = acc.copy()
        sigma = np.zeros(n)
        self._acc = acc
        self._held_members = self._held_particles()
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
        pairs = self.broad_phase.pairs(lo, hi, s.max_pairs_per_step)
        if len(pairs) > s.max_pairs_per_step:
            warn("max_pairs_per_step", _budget_message("max_pairs_per_step", s.max_pairs_per_step))
            pairs = np.empty((0, 2), dtype=np.int64)
        self._lo, self._hi = lo, hi
        self._grown: set[int] = set()
        self._build_adjacency(pairs, n)
        t2 = perf_counter()
        timings["broad_phase"] = t2 - t1
        if obs is not None:
            obs.on_event(self._broad_phase_event(step_no, len(pairs)))

        # -- narrow phase ---------------------------------------------------------
        self._step_no = step_no
        self._dt = dt
        self._version = np.zeros(n, dtype=np.int64)
        buf = self._buf
        buf.reset()
        self._sync_held()
        push = s.ordering == "time"
        self._predict(KIND_PAIR, pairs[:, 0].copy(), pairs[:, 1].copy(), push)
        wall_p, wall_w = reachable_walls(lo, hi, self._normals, self._offsets, self._half_thickness,
                                         self._two_sided)
        self._predict(KIND_WALL, wall_p, wall_w, push)
        t3 = perf_counter()
        timings["narrow_phase"] = t3 - t2

        # -- resolve --------------------------------------------------------------
        budget = self._resolve_in_time_order() if push else self._resolve_in_index_order()
        if budget is not None:
            warn(budget, _budget_message(budget, getattr(s, budget)))
        t4 = perf_counter()
        timings["resolve"] = t4 - t3

        # -- finish -------------------------------------------------------------
        advance_particles(x, v, self._a, sigma, np.arange(n, dtype=np.int64), dt, self._integrator,
                          self._drag, self._k)
        sigma[:] = 0.0
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
        stats = StepStats(step_no, self.time, dt, kinetic, potential, momentum, contacts, tests, events,
                          len(self.held), max_overlap, digest, timings, warnings)
        if obs is not None:
            obs.on_event(self._contacts_event())
            obs.on_event(self._swept_tests_event())
            obs.on_event(StepEnd(step_no, self.time, dt, x.copy(), v.copy(), kinetic, potential,
                                 momentum.copy(),
                                 {"contacts": contacts, "swept_tests": tests, "events": events,
                                  "resting": len(self.held)},
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
        if st.count == 0:
            return
        speed = np.linalg.norm(st.velocities, axis=1) + np.linalg.norm(self._a, axis=1) * dt
        typical = float(np.quantile(speed, 0.99))
        reach = (np.maximum(speed, typical) * dt + st.radius + self.settings.contact_tolerance)[:, None]
        np.minimum(lo, st.positions - reach, out=lo)
        np.maximum(hi, st.positions + reach, out=hi)

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
        found = set(self.broad_phase.query(self._lo, self._hi, self._lo[i], self._hi[i]).tolist())
        # a structure built at step start knows the old boxes: check grown ones directly
        if self._grown:
            grown = np.fromiter(self._grown, dtype=np.int64)
            hit = np.all((self._lo[grown] <= self._hi[i]) & (self._lo[i] <= self._hi[grown]), axis=1)
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
                     self._normals, self._offsets, self._half_thickness, self._two_sided, self._held_pairs,
                     self._held_walls, buf.test_int, buf.test_float, buf.test_outcome,
                     buf.heap_toi, buf.heap_data, buf.counters, push)

    def _predict_for(self, particles: set[int]) -> None:
        """Re-predict everything involving ``particles`` (after their paths changed)."""
        new_pairs = []
        for i in sorted(particles):
            new_pairs += [(min(i, j), max(i, j)) for j in self._refresh_box(i)]
        self._add_partners(new_pairs)
        seen = set()
        pa, pb = [], []
        for i in sorted(particles):
            for j in self._partners(i).tolist():
                key = (i, j) if i < j else (j, i)
                if key not in seen:
                    seen.add(key)
                    pa.append(key[0])
                    pb.append(key[1])
        plist = np.array(sorted(particles), dtype=np.int64)
        nw = len(self.walls)
        self._predict(KIND_PAIR, np.array(pa, dtype=np.int64), np.array(pb, dtype=np.int64), True)
        self._predict(KIND_WALL, np.repeat(plist, nw), np.tile(np.arange(nw, dtype=np.int64), plist.size), True)

    # ------------------------------------------------------------------ policies
    def _resolve_in_time_order(self) -> str | None:
        """The compiled loop, with Python taking the pauses (see timeline.py); returns the
        budget that stopped it (a Settings field name), or None."""
        st = self.state
        s = self.settings
        buf = self._buf
        nw = len(self.walls)
        cap = s.max_events_per_step
        rule = RESTITUTION_RULES.index(s.restitution_rule)
        while True:
            status = run_time_order(
                st.positions, st.velocities, self._a, self._acc, st.radius, st.inverse_mass, st.restitution,
                self._sigma, self._version, self._dt, self._integrator, self._drag, self._k, self._detection,
                s.samples, s.contact_tolerance * 1e-3, s.rest_fraction, self._rest_step_factor, rule,
                self._normals, self._offsets, self._half_thickness, self._two_sided, self._wall_restitution,
                self._held_pairs, self._held_walls, self._has_held, self._adj_start, self._adj, self._lo, self._hi,
                s.contact_tolerance, self._max_degree, cap, s.max_swept_tests_per_step, self._anchor_is_flow,
                buf.heap_toi, buf.heap_data, buf.test_int, buf.test_float, buf.test_outcome, buf.contact_float,
                buf.contact_int, buf.counters, buf.pending_int, buf.pending_float, buf.requery, buf.requery_count)
            if status == DONE:
                return None
            if status == CAPPED:
                return "max_events_per_step"
            if status == TEST_BUDGET:
                return "max_swept_tests_per_step"
            if self._resting_work > s.max_resting_work_per_step:
                mark_capped(self._buf.heap_data, self._buf.test_outcome, self._buf.counters)
                return "max_resting_work_per_step"
            if status == GROW:
                room = 2 * self._max_degree + 2 * nw + 4
                buf.ensure(room, room, 2)
            elif status == PAUSE_RESOLVE:
                kind, a, other, rid = (int(c) for c in buf.pending_int)
                changed, resolved = self._resolve(kind, a, other, float(buf.pending_float[0]))
                buf.test_outcome[rid] = OUTCOME_HIT if resolved else OUTCOME_SUPERSEDED
                self._sync_held()
                if changed:
                    for i in changed:
                        self._version[i] += 1
                    self._predict_for(changed)
            elif status == REQUERY:
                new_pairs = []
                for i in buf.requery[: buf.requery_count[0]].tolist():
                    new_pairs += [(min(i, j), max(i, j)) for j in self._refresh_box(i)]
                self._add_partners(new_pairs)

    def _resolve_in_index_order(self) -> str | None:
        """Every contact predicted at step start, in detection order, nothing re-predicted;
        returns the budget that stopped it (a Settings field name), or None."""
        buf = self._buf
        s = self.settings
        count = int(buf.counters[TESTS])
        toi = buf.test_float[:count, 1]
        for rid in np.nonzero(toi <= self._dt)[0].tolist():
            buf.counters[EVENTS] += 1
            over = ("max_events_per_step" if buf.counters[CONTACTS] >= s.max_events_per_step else
                    "max_resting_work_per_step" if self._resting_work > s.max_resting_work_per_step else None)
            if over is not None:
                hits = np.nonzero(toi <= self._dt)[0]
                buf.test_outcome[hits[hits >= rid]] = OUTCOME_CAPPED
                return over
            kind, a, other = (int(c) for c in buf.test_int[rid])
            at = max(float(toi[rid]), self._sigma[a], self._sigma[other] if kind == KIND_PAIR else 0.0)
            _, resolved = self._resolve(kind, a, other, at)
            buf.test_outcome[rid] = OUTCOME_HIT if resolved else OUTCOME_SUPERSEDED
        return None

    # ------------------------------------------------------------------ one contact
    def _resolve(self, kind: int, a: int, other: int, when: float) -> tuple[set[int], bool]:
        """Resolve one predicted contact at time ``when`` in the step.

        Returns (particles whose paths may have changed, whether a contact was resolved);
        a pair no longer approaching at ``when`` is left alone.
        """
        st = self.state
        x, v, w = st.positions, st.velocities, st.inverse_mass
        involved = np.array([a, other] if kind == KIND_PAIR else [a], dtype=np.int64)
        # integrators that are not a flow (Euler, Verlet with drag) take a new path from a
        # new anchor, so moving the anchor alone obliges a re-prediction
        moved_only = {int(i) for i in involved} if not self._anchor_is_flow else set()
        advance_particles(x, v, self._a, self._sigma, involved, when, self._integrator, self._drag, self._k)
        dt = self._dt
        if kind == KIND_PAIR:
            b = other
            normal = unit(x[a] - x[b])
            closing = -float((v[a] - v[b]) @ normal)
            rel_acc = float((self._acc[a] - self._acc[b]) @ normal)
            restitution = combine_restitution(self.settings.restitution_rule, st.restitution[a], st.restitution[b])
            key = ("pair", min(a, b), max(a, b))
        else:
            b = -1
            normal = self._wall_normal_towards(a, other)
            closing = -float(v[a] @ normal)
            rel_acc = float(self._acc[a] @ normal)
            restitution = combine_restitution(self.settings.restitution_rule, st.restitution[a],
                                              float(self.walls.restitution[other]))
            key = ("wall", a, other)
        accelerating_in = rel_acc < 0.0
        closing = pressed_closing(closing, rel_acc, dt)
        if closing < 0.0 or (closing == 0.0 and not accelerating_in):
            return moved_only, False
        resting = rests(closing, rel_acc, dt, self._rest_step_factor, self.settings.rest_fraction)
        used = 0.0 if resting else restitution
        va_before = v[a].copy()
        vb_before = v[b].copy() if b >= 0 else None
        if kind == KIND_PAIR:
            if w[a] + w[b] == 0.0:
                return moved_only, False
            j = pair_impulse(v[a], v[b], w[a], w[b], normal, used)
            apply_pair_impulse(v, w, a, b, normal, j)
        else:
            v[a] = reflect(v[a], normal, used)
            j = (1.0 + used) * closing / w[a] if w[a] > 0 else math.inf
        changed = {int(i) for i in involved}
        if resting:
            self.held[key] = normal.copy() if kind == KIND_WALL else None
        else:
            for k_ in [k_ for k_ in self.held if k_[1] in changed or (k_[0] == "pair" and k_[2] in changed)]:
                del self.held[k_]
        changed |= self._rebalance_held(when)
        self._record_contact(kind, a, other, when, x[a] - normal * st.radius[a], normal, j, va_before, v[a],
                             vb_before, v[b] if b >= 0 else None, used, closing, resting)
        return changed, True

    def _rebalance_held(self, when: float) -> set[int]:
        """Re-solve held contacts at time ``when``: velocities and accelerations.

        Returns the particles whose velocity or acceleration changed.
        """
        # only particles held now or before can have an acceleration other than free fall
        touched = self._held_particles() | self._held_members
        if not touched:
            return set()
        new_acc = self._solve_held()
        self._held_members = self._held_particles()
        idx = np.array(sorted(touched), dtype=np.int64)
        st = self.state
        advance_particles(st.positions, st.velocities, self._a, self._sigma, idx, when,
                          self._integrator, self._drag, self._k)
        before_v = st.velocities[idx].copy()
        self._project_held_velocities(idx)
        self._acc = new_acc
        if self._integrator != SEMI_IMPLICIT:
            before_a = self._a[idx].copy()
            self._a[idx] = new_acc[idx]
            moved = np.any(self._a[idx] != before_a, axis=1)
        else:
            moved = np.zeros(idx.size, dtype=bool)
        moved |= np.any(st.velocities[idx] != before_v, axis=1)
        if not self._anchor_is_flow:
            moved[:] = True
        return {int(i) for i in idx[moved]}

    def _record_contact(self, kind, a, other, when, point, normal, impulse, va_before, va_after, vb_before,
                        vb_after, restitution, closing, resting) -> None:
        """One row of the contact buffer (the same columns the compiled loop writes)."""
        buf = self._buf
        buf.ensure(0, 0, 1)
        row = int(buf.counters[CONTACTS])
        cf = buf.contact_float[row]
        cf[CF_TIME] = when
        cf[CF_POINT:CF_POINT + 3] = point
        cf[CF_NORMAL:CF_NORMAL + 3] = normal
        cf[CF_IMPULSE] = impulse
        cf[CF_VA_BEFORE:CF_VA_BEFORE + 3] = va_before
        cf[CF_VA_AFTER:CF_VA_AFTER + 3] = va_after
        cf[CF_VB_BEFORE:CF_VB_BEFORE + 3] = vb_before if vb_before is not None else np.nan
        cf[CF_VB_AFTER:CF_VB_AFTER + 3] = vb_after if vb_after is not None else np.nan
        cf[CF_RESTITUTION] = restitution
        cf[CF_CLOSING] = closing
        buf.contact_int[row] = (kind, a, other, int(resting))
        buf.counters[CONTACTS] = row + 1

    def _contacts_event(self) -> Contacts:
        buf = self._buf
        m = int(buf.counters[CONTACTS])
        f = buf.contact_float[:m]
        ints = buf.contact_int[:m]

        def vec(col: int) -> np.ndarray:
            return f[:, col:col + 3].copy()

        return Contacts(self._step_no, f[:, CF_TIME].copy(), ints[:, 0].astype(np.int8), ints[:, 1].astype(np.int32),
                        ints[:, 2].astype(np.int32), vec(CF_POINT), vec(CF_NORMAL), f[:, CF_IMPULSE].copy(),
                        vec(CF_VA_BEFORE), vec(CF_VA_AFTER), vec(CF_VB_BEFORE), vec(CF_VB_AFTER),
                        f[:, CF_RESTITUTION].copy(), f[:, CF_CLOSING].copy(), ints[:, 3].astype(np.bool_))

    # ------------------------------------------------------------------ audit
    def _max_overlap(self) -> float:
        """Deepest penetration (m) among candidate pairs and particle–wall pairs."""
        return float(max_overlap(self.state.positions, self.state.radius, self._pairs, self._normals,
                                 self._offsets, self._half_thickness, self._two_sided,
                                 self.settings.detection != "swept"))

    def _broad_phase_event(self, step_no: int, pair_count: int) -> BroadPhaseInfo:
        bp = self.broad_phase
        stats = dict(getattr(bp, "stats", {}) or {})
        stats.setdefault("pairs", pair_count)
        tree = getattr(bp, "nodes", None)
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
