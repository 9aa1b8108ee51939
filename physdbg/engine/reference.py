"""The slow reference for the compiled contact loop: obviously correct, O(N²) per contact.

:class:`ReferenceWorld` is a :class:`~physdbg.engine.world.World` whose time-ordered
resolve phase is a plain Python loop with no broad phase, no event queue, no versions and
no re-query: before every contact it swept-tests *every* pair and every sphere–wall pair
from the current anchors, takes the earliest contact in the step (ties: walls before
pairs, then by sphere and partner index), and resolves it with the same resolver
(resolve.resolve_contact). Whatever the fast loop gains by remembering predictions,
pruning pairs with swept boxes, invalidating stale ones and pausing for Python, it must
give the same contacts in the same order and the same states; a hypothesis test
(tests/test_reference.py) checks that on small random scenes, as the brute-force broad
phase judges the grid.

It shares with the fast loop only what is not the loop: the swept tests (toi.py), the
resolver and the held-contact solve (resolve.py, resting.py) and the step's other phases.
"""

from __future__ import annotations

import numpy as np

from ..events import KIND_PAIR, KIND_WALL, OUTCOME_HIT, OUTCOME_SUPERSEDED
from .resolve import OUT_OF_WORK, SKIPPED
from .step_context import StepContext
from .timeline import CONTACTS, EVENTS, ROWS, TESTS, Buffers, predict_into
from .world import World


class ReferenceWorld(World):
    """A World whose time-ordered resolve phase is the O(N²) reference loop (module doc)."""

    def _resolve_in_time_order(self, ctx: StepContext) -> str | None:
        st = self.state
        s = self.settings
        n = st.count
        nw = len(self.walls)
        pair_a, pair_b = np.triu_indices(n, 1)
        pair_a = pair_a.astype(np.int64)
        pair_b = pair_b.astype(np.int64)
        wall_p = np.repeat(np.arange(n, dtype=np.int64), nw)
        wall_w = np.tile(np.arange(nw, dtype=np.int64), n)
        scratch = Buffers(n, heap=1, tests=max(len(pair_a) + len(wall_p), 1))
        while True:
            candidates = []
            for kind, ia, ib in ((KIND_WALL, wall_p, wall_w), (KIND_PAIR, pair_a, pair_b)):
                scratch.reset()
                predict_into(kind, ia, ib, st.positions, st.velocities, ctx.path_accel, st.radius, ctx.sigma,
                             ctx.version, ctx.dt, self._integrator, self._k, self._detection, s.samples,
                             s.contact_tolerance * 1e-3, self._normals, self._offsets, self._half_thickness,
                             self._two_sided, self._period, self.held, scratch.test_int, scratch.test_float,
                             scratch.test_outcome, scratch.heap_toi, scratch.heap_data, scratch.counters, False)
                m = int(scratch.counters[ROWS])
                for row in range(m):
                    toi = float(scratch.test_float[row, 1])
                    if toi <= ctx.dt:
                        k, a, other = (int(c) for c in scratch.test_int[row])
                        candidates.append((toi, 0 if k == KIND_WALL else 1, a, other, k))
            if not candidates:
                return None
            toi, _, a, other, kind = self._first(candidates)
            self._buf.counters[EVENTS] += 1
            if self._buf.counters[CONTACTS] >= self.event_cap:
                return "max_events_per_step"
            status = self._resolve_one(ctx, kind, a, other, toi)
            self._record_outcome(ctx, kind, a, other, toi, OUTCOME_SUPERSEDED if status == SKIPPED else OUTCOME_HIT)
            if status == OUT_OF_WORK:
                return "max_resting_work_per_step"

    @staticmethod
    def _first(candidates: list[tuple]) -> tuple:
        """The contact to resolve next: the earliest (ties: walls first, then by index)."""
        return min(candidates)

    def _record_outcome(self, ctx: StepContext, kind: int, a: int, other: int, toi: float, outcome: int) -> None:
        """Log the contact as a swept test (the reference keeps only those it acted on)."""
        buf = self._buf
        buf.ensure(0, 1, 0)
        row = int(buf.counters[ROWS])
        buf.test_int[row] = (kind, a, other)
        buf.test_float[row] = (ctx.sigma[a], toi)
        buf.test_outcome[row] = outcome
        buf.counters[ROWS] = row + 1
        buf.counters[TESTS] += 1
