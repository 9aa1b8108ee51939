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

import heapq
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
    OUTCOME_MISS,
    OUTCOME_SUPERSEDED,
    ContactResolved,
    EngineWarning,
    StepBegin,
    StepEnd,
    SweptTests,
)
from .broadphase import choose_broad_phase, make_broad_phase
from .motion import EULER, SEMI_IMPLICIT, VERLET, advance_particles, swept_boxes
from .resolve import apply_pair_impulse, combine_restitution, pair_impulse, reflect, unit
from .resting import solve_accelerations
from .state import Settings, State, Walls, energies, state_hash
from .toi import INF, predict_pairs, predict_walls

_EMPTY_I = np.empty(0, dtype=np.int64)


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
    warnings: list[str]


class World:
    """Particles, walls and settings, stepped in place.

    state: the particles (its arrays are updated by ``step``); walls: the planes;
    settings: methods and tolerances; observer: anything with ``on_event(event)``.
    """

    def __init__(self, state: State, walls: Walls, settings: Settings, observer=None):
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
        self._offsets = np.ascontiguousarray(walls.offsets, dtype=np.float64)

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

    def _rest_threshold(self, accel_along_normal: float, dt: float) -> float:
        """Closing speed (m/s) at or below which a contact rests (see resting.py)."""
        extra = abs(accel_along_normal) * dt * 1.5 if self._integrator in (EULER, SEMI_IMPLICIT) else 0.0
        return self.settings.rest_speed + extra

    def _solve_held(self):
        """Accelerations from held contacts; contacts that no longer push are released."""
        while True:
            acc, lam = solve_accelerations(self._free_accel, self.state.inverse_mass,
                                           self.state.positions, self.held)
            loose = [key for key, value in lam.items() if value <= 0.0]
            if not loose:
                return acc
            for key in loose:
                del self.held[key]

    def _project_held_velocities(self, particles: np.ndarray) -> None:
        """Remove any approach along held contacts from the velocities (in place)."""
        if not self.held:
            return
        projected, _ = solve_accelerations(self.state.velocities, self.state.inverse_mass,
                                           self.state.positions, self.held)
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

    # ------------------------------------------------------------------ the step
    def step(self, dt: float) -> StepStats:
        """Advance the world by ``dt`` seconds and report what happened."""
        if not dt > 0.0 or not math.isfinite(dt):
            raise ValueError(f"dt must be a positive finite number of seconds, got {dt!r}")
        st = self.state
        s = self.settings
        obs = self.observer
        n = st.count
        step_no = self.step_index
        if obs is not None:
            obs.on_event(StepBegin(step_no, self.time, dt))
        timings: dict[str, float] = {}
        warnings: list[str] = []
        x, v = st.positions, st.velocities

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
        self._acc_differs_from_free = bool(self.held)
        self._a = path_accel
        self._sigma = sigma
        t1 = perf_counter()
        timings["forces"] = t1 - t0

        # -- broad phase --------------------------------------------------------
        lo = np.empty((n, 3))
        hi = np.empty((n, 3))
        swept_boxes(x, v, path_accel, st.radius, sigma, dt, self._integrator, self._k,
                    s.contact_tolerance, lo, hi)
        pairs = self.broad_phase.pairs(lo, hi)
        self._lo, self._hi = lo, hi
        self._grown: set[int] = set()
        self._build_adjacency(pairs, n)
        t2 = perf_counter()
        timings["broad_phase"] = t2 - t1
        if obs is not None:
            obs.on_event(self._broad_phase_event(step_no, len(pairs)))

        # -- narrow phase + resolve ----------------------------------------------
        self._tests: list[tuple] = []
        self._test_count = 0
        self._outcome: dict[int, int] = {}
        self._contacts = 0
        self._events = 0
        self._contact_order = 0
        self._step_no = step_no
        self._dt = dt
        self._version = np.zeros(n, dtype=np.int64)
        self._heap: list = []
        all_particles = np.arange(n, dtype=np.int64)
        wall_ids = np.arange(len(self.walls), dtype=np.int64)
        predictions = self._predict(pairs[:, 0].copy(), pairs[:, 1].copy(),
                                    np.repeat(all_particles, len(wall_ids)),
                                    np.tile(wall_ids, n))
        t3 = perf_counter()
        timings["narrow_phase"] = t3 - t2
        if s.ordering == "time":
            capped = self._resolve_in_time_order(predictions)
        else:
            capped = self._resolve_in_index_order(predictions)
        if capped:
            msg = (f"step {step_no}: event cap of {s.max_events_per_step} contacts reached; "
                   f"remaining contacts in this step were not resolved")
            warnings.append(msg)
            if obs is not None:
                obs.on_event(EngineWarning(step_no, "event-cap", msg))
        t4 = perf_counter()
        timings["resolve"] = t4 - t3

        # -- finish -------------------------------------------------------------
        advance_particles(x, v, self._a, sigma, all_particles, dt, self._integrator, self._drag, self._k)
        sigma[:] = 0.0
        max_overlap = self._max_overlap()
        if s.detection == "swept" and max_overlap > s.contact_tolerance and not capped:
            msg = (f"step {step_no}: spheres overlap by {max_overlap:.3g} m, more than the "
                   f"contact tolerance {s.contact_tolerance:g} m")
            warnings.append(msg)
            if obs is not None:
                obs.on_event(EngineWarning(step_no, "overlap", msg))
        kinetic, potential, momentum = energies(st, self.gravity)
        digest = state_hash(x, v)
        self.time += dt
        self.step_index += 1
        t5 = perf_counter()
        timings["finish"] = t5 - t4
        stats = StepStats(step_no, self.time, dt, kinetic, potential, momentum, self._contacts,
                          self._test_count, self._events, len(self.held), max_overlap, digest,
                          timings, warnings)
        if obs is not None:
            obs.on_event(self._swept_tests_event())
            obs.on_event(StepEnd(step_no, self.time, dt, x.copy(), v.copy(), kinetic, potential,
                                 momentum.copy(),
                                 {"contacts": self._contacts, "swept_tests": self._test_count,
                                  "events": self._events, "resting": len(self.held)},
                                 max_overlap, dict(timings), digest, tuple(warnings)))
        return stats

    # ------------------------------------------------------------------ candidates
    def _build_adjacency(self, pairs: np.ndarray, n: int) -> None:
        """CSR lists of each particle's broad-phase partners (+ later additions)."""
        if pairs.size:
            both = np.concatenate((pairs, pairs[:, ::-1]))
            order = np.lexsort((both[:, 1], both[:, 0]))
            both = both[order]
            self._adj_start = np.searchsorted(both[:, 0], np.arange(n + 1))
            self._adj = both[:, 1].copy()
        else:
            self._adj_start = np.zeros(n + 1, dtype=np.int64)
            self._adj = _EMPTY_I
        self._adj_extra: dict[int, set[int]] = {}
        self._pairs = pairs

    def _partners(self, i: int) -> np.ndarray:
        base = self._adj[self._adj_start[i]:self._adj_start[i + 1]]
        extra = self._adj_extra.get(i)
        if extra:
            return np.union1d(base, np.fromiter(extra, dtype=np.int64))
        return base

    def _refresh_box(self, i: int) -> None:
        """If i's new path leaves its swept box, grow the box and ask the broad phase again."""
        st = self.state
        lo = np.empty((1, 3))
        hi = np.empty((1, 3))
        idx = np.array([i])
        swept_boxes(st.positions[idx], st.velocities[idx], self._a[idx], st.radius[idx],
                    self._sigma[idx], self._dt, self._integrator, self._k,
                    self.settings.contact_tolerance, lo, hi)
        if np.all(lo[0] >= self._lo[i]) and np.all(hi[0] <= self._hi[i]):
            return
        self._lo[i] = np.minimum(self._lo[i], lo[0])
        self._hi[i] = np.maximum(self._hi[i], hi[0])
        found = set(self.broad_phase.query(self._lo, self._hi, self._lo[i], self._hi[i]).tolist())
        # a structure built at step start knows the old boxes: check grown ones directly
        for j in self._grown:
            if np.all(self._lo[j] <= self._hi[i]) and np.all(self._lo[i] <= self._hi[j]):
                found.add(j)
        self._grown.add(i)
        known = set(self._partners(i).tolist())
        for j in sorted(found):
            if j != i and j not in known:
                self._adj_extra.setdefault(i, set()).add(j)
                self._adj_extra.setdefault(j, set()).add(i)

    # ------------------------------------------------------------------ narrow phase
    def _predict(self, pa, pb, wp, ww):
        """Swept-test pairs (pa[m], pb[m]) and particle–wall pairs (wp[m], ww[m]).

        Held contacts are skipped (they touch by definition). Returns a list of
        (record id, toi, kind, a, other) for every finite prediction within the step.
        """
        st = self.state
        s = self.settings
        if self.held and pa.size:
            keep = np.array([("pair", int(i), int(j)) not in self.held for i, j in zip(pa, pb)], dtype=bool)
            pa, pb = pa[keep], pb[keep]
        if self.held and wp.size:
            keep = np.array([("wall", int(i), int(w)) not in self.held for i, w in zip(wp, ww)], dtype=bool)
            wp, ww = wp[keep], ww[keep]
        out = []
        dt = self._dt
        for kind, ia, ib in ((KIND_PAIR, pa, pb), (KIND_WALL, wp, ww)):
            m = ia.size
            if m == 0:
                continue
            start = np.empty(m)
            toi = np.empty(m)
            if kind == KIND_PAIR:
                predict_pairs(ia, ib, st.positions, st.velocities, self._a, st.radius, self._sigma,
                              dt, self._integrator, self._k, self._detection, s.samples,
                              s.contact_tolerance * 1e-3, start, toi)
            else:
                predict_walls(ia, ib, st.positions, st.velocities, self._a, st.radius, self._sigma,
                              dt, self._normals, self._offsets, self._half_thickness, self._two_sided,
                              self._integrator, self._k, self._detection, s.samples, start, toi)
            base = self._test_count
            self._test_count += m
            self._tests.append((kind, ia, ib, start, toi))
            hit = np.nonzero(toi <= dt)[0]
            for h in hit.tolist():
                out.append((base + h, float(toi[h]), kind, int(ia[h]), int(ib[h])))
        return out

    def _predict_for(self, particles: set[int]):
        """Re-predict everything involving ``particles`` (after their paths changed)."""
        for i in particles:
            self._refresh_box(i)
        seen = set()
        pa, pb = [], []
        for i in sorted(particles):
            for j in self._partners(i).tolist():
                key = (i, j) if i < j else (j, i)
                if key not in seen:
                    seen.add(key)
                    pa.append(key[0])
                    pb.append(key[1])
        plist = sorted(particles)
        nw = len(self.walls)
        return self._predict(np.array(pa, dtype=np.int64), np.array(pb, dtype=np.int64),
                             np.repeat(np.array(plist, dtype=np.int64), nw),
                             np.tile(np.arange(nw, dtype=np.int64), len(plist)))

    # ------------------------------------------------------------------ policies
    def _push(self, predictions) -> None:
        ver = self._version
        for rid, toi, kind, a, other in predictions:
            vb = ver[other] if kind == KIND_PAIR else 0
            heapq.heappush(self._heap, (toi, rid, kind, a, other, ver[a], vb))

    def _resolve_in_time_order(self, predictions) -> bool:
        self._push(predictions)
        heap = self._heap
        cap = self.settings.max_events_per_step
        while heap:
            toi, rid, kind, a, other, va, vb = heapq.heappop(heap)
            self._events += 1
            if self._version[a] != va or (kind == KIND_PAIR and self._version[other] != vb):
                self._outcome[rid] = OUTCOME_SUPERSEDED
                continue
            if self._contacts >= cap:
                self._outcome[rid] = OUTCOME_CAPPED
                for entry in heap:
                    self._outcome[entry[1]] = OUTCOME_CAPPED
                heap.clear()
                return True
            changed, resolved = self._resolve(kind, a, other, toi)
            self._outcome[rid] = OUTCOME_HIT if resolved else OUTCOME_SUPERSEDED
            if not changed:
                continue
            for i in changed:
                self._version[i] += 1
            self._push(self._predict_for(changed))
        return False

    def _resolve_in_index_order(self, predictions) -> bool:
        # detection order: the order the swept tests ran (pairs by index, then walls)
        predictions.sort(key=lambda p: p[0])
        cap = self.settings.max_events_per_step
        for n_done, (rid, toi, kind, a, other) in enumerate(predictions):
            self._events += 1
            if self._contacts >= cap:
                for rest in predictions[n_done:]:
                    self._outcome[rest[0]] = OUTCOME_CAPPED
                return True
            at = max(toi, self._sigma[a], self._sigma[other] if kind == KIND_PAIR else 0.0)
            _, resolved = self._resolve(kind, a, other, at)
            self._outcome[rid] = OUTCOME_HIT if resolved else OUTCOME_SUPERSEDED
        return False

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
        if closing < 0.0 or (closing == 0.0 and not accelerating_in):
            return moved_only, False
        resting = closing <= self._rest_threshold(rel_acc, dt)
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
        self._contacts += 1
        if self.observer is not None:
            point = x[a] - normal * st.radius[a]
            self.observer.on_event(ContactResolved(
                self._step_no, self._contact_order, when, kind, a, other, point.copy(), normal.copy(),
                float(j), va_before, v[a].copy(), vb_before, v[b].copy() if b >= 0 else None,
                float(used), float(closing), bool(resting)))
        self._contact_order += 1
        return changed, True

    def _rebalance_held(self, when: float) -> set[int]:
        """Re-solve held contacts at time ``when``: velocities and accelerations.

        Returns the particles whose velocity or acceleration changed.
        """
        members = set()
        for key in self.held:
            members.add(key[1])
            if key[0] == "pair":
                members.add(key[2])
        old_acc = self._acc
        if not self.held and not self._acc_differs_from_free:
            return set()
        new_acc = self._solve_held()
        self._acc_differs_from_free = bool(self.held)
        touched = members | set(np.nonzero(np.any(new_acc != old_acc, axis=1))[0].tolist())
        if not touched:
            self._acc = new_acc
            return set()
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

    # ------------------------------------------------------------------ audit
    def _max_overlap(self) -> float:
        """Deepest penetration (m) among candidate pairs and particle–wall pairs."""
        st = self.state
        x, r = st.positions, st.radius
        worst = 0.0
        pairs = self._pairs
        if pairs.size:
            d = np.linalg.norm(x[pairs[:, 0]] - x[pairs[:, 1]], axis=1)
            worst = max(worst, float(np.max(r[pairs[:, 0]] + r[pairs[:, 1]] - d)))
        for (i, js) in self._adj_extra.items():
            for j in js:
                worst = max(worst, float(r[i] + r[j] - np.linalg.norm(x[i] - x[j])))
        if len(self.walls) and st.count:
            h = x @ self._normals.T - self._offsets[None, :]
            h = np.where(self._two_sided[None, :], np.abs(h), h)
            pen = self._half_thickness[None, :] + r[:, None] - h
            if self.settings.detection != "swept":
                # thin walls that a sphere tunnelled through are not "overlapping" them
                pen = np.where(self._two_sided[None, :] & (pen > r[:, None]), 0.0, pen)
            worst = max(worst, float(pen.max()))
        return max(worst, 0.0)

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
        if self._tests:
            kind = np.concatenate([np.full(t[1].size, t[0], dtype=np.int8) for t in self._tests])
            a = np.concatenate([t[1] for t in self._tests]).astype(np.int32)
            other = np.concatenate([t[2] for t in self._tests]).astype(np.int32)
            start = np.concatenate([t[3] for t in self._tests])
            toi = np.concatenate([t[4] for t in self._tests])
        else:
            kind = np.zeros(0, dtype=np.int8)
            a = other = np.zeros(0, dtype=np.int32)
            start = toi = np.zeros(0)
        outcome = np.full(kind.size, OUTCOME_MISS, dtype=np.int8)
        for rid, code in self._outcome.items():
            outcome[rid] = code
        toi = np.where(toi <= self._dt, toi, np.nan)
        return SweptTests(self._step_no, kind, a, other, start, toi, outcome)


def warm_up() -> float:
    """Compile (or load from numba's cache) every kernel a step uses; returns seconds taken.

    Runs a two-sphere, one-wall world for one step with contacts, so the first real step
    is not charged with compilation. The kernels take the integrator and detection as
    arguments, so one run compiles every method.
    """
    started = perf_counter()
    state = State(np.array([[0.0, 0.3, 0.0], [0.5, 0.3, 0.0]]), np.array([[1.0, -1.0, 0.0], [-1.0, 0.0, 0.0]]),
                  np.ones(2), np.full(2, 0.1), np.ones(2), np.ones(2))
    walls = Walls(["floor"], np.array([[0.0, 1.0, 0.0]]), np.zeros(1), np.ones(1), np.zeros(1, dtype=np.bool_),
                  np.zeros(1))
    for detection in ("swept", "sampled"):
        World(state.copy(), walls, Settings(detection=detection)).step(0.5)
    return perf_counter() - started
