"""The slow reference for the compiled contact loop: obviously correct, O(N²) per contact.

:class:`ReferenceWorld` is a :class:`~physdbg.engine.world.World` whose time-ordered
resolve phase is a plain Python loop with no broad phase, no event queue, no versions and
no re-query: before every contact it swept-tests *every* pair and every sphere–wall pair
from the current anchors, takes the earliest contact in the step (ties: walls before
pairs, then by sphere and partner index), and resolves it with the same resolver
(resolve.resolve_contact; with the sphere's other contacts with immovable partners at that
instant, resolve.resolve_at_one_instant). Whatever the fast loop gains by remembering predictions,
pruning pairs with swept boxes, invalidating stale ones and pausing for Python, it must
give the same contacts in the same order and the same states; a hypothesis test
(tests/test_reference.py) checks that on small random scenes, as the brute-force broad
phase judges the grid.

It shares with the fast loop only what is not the loop: the swept tests (toi.py), the
resolver and the held-contact solve (resolve.py, resting/) and the step's other phases.
"""

from __future__ import annotations

from ..events import OUTCOME_HIT, OUTCOME_SUPERSEDED
from .colliders import KINDS, PARTNER_IS_SPHERE, every_candidate
from .resolve import AT_ONE_INSTANT_CANDIDATES, OUT_OF_WORK, SAME_INSTANT, SKIPPED
from .step_context import StepContext
from .timeline import CONTACTS, EVENTS, ROWS, TESTS, Buffers, predict_into
from .world import World


class ReferenceWorld(World):
    """A World whose time-ordered resolve phase is the O(N²) reference loop (module doc).

    once_a_step: take each contact (kind, sphere, partner) at most once a step, as an engine
    with a guard against meeting a pair twice in a step does (check-run re-simulates a
    student's step that way to test a mistake that leaves a pair approaching:
    analysis/departure.py, "a mistake re-simulated"); physdbg's own loop has no such guard."""

    once_a_step = False

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._walks_mesh_trees = False  # it tests every triangle: no tree is walked, none reported

    def _resolve_in_time_order(self, ctx: StepContext) -> str | None:
        st = self._st
        every = [(kind, *every_candidate(kind, st.count, self._geometry)) for kind in range(KINDS)]
        particles, method, geometry = self._kernel_groups(ctx)
        scratch = Buffers(st.count, heap=1, tests=max(sum(len(ia) for _, ia, _ in every), 1))
        # a skipped contact is not taken again until a path of its spheres changes: the
        # compiled loop's prediction of it was used up, and only a changed path predicts it anew
        used_up: set[tuple[int, int, int]] = set()
        taken: set[tuple[int, int, int]] = set()  # (once_a_step)
        while True:
            candidates = []
            for kind, ia, ib in every:
                scratch.reset()
                predict_into(kind, ia, ib, particles, method, geometry, self.held, scratch.loop(), False)
                m = int(scratch.counters[ROWS])
                for row in range(m):
                    toi = float(scratch.test_float[row, 1])
                    if toi <= ctx.dt:
                        k, a, other = (int(c) for c in scratch.test_int[row])
                        if (k, a, other) not in used_up and (k, a, other) not in taken:
                            candidates.append((toi, PARTNER_IS_SPHERE[k], a, other, k))
            if not candidates:
                return None
            toi, _, a, other, kind = self._first(candidates)
            self._buf.counters[EVENTS] += 1
            if self._buf.counters[CONTACTS] >= self.contact_cap:
                return "max_contacts_per_step"
            # contacts of the sphere with immovable partners at that instant go together
            # (resolve.resolve_at_one_instant), as the compiled loop gathers them from its queue
            together = [(kind, other)]
            if not PARTNER_IS_SPHERE[kind] and self.settings.detection == "swept":
                until = toi + SAME_INSTANT * ctx.dt
                together += sorted({(k, o) for t, _, i, o, k in candidates
                                    if i == a and not PARTNER_IS_SPHERE[k] and t <= until and (k, o) != (kind, other)})
                together = together[:AT_ONE_INSTANT_CANDIDATES]
            if len(together) > 1:
                status, resolved = self._resolve_at_one_instant(ctx, together, a, toi)
                for (k, o), done in list(zip(together, resolved))[1:]:
                    if done:
                        self._record_outcome(ctx, k, a, o, toi, OUTCOME_HIT)
                if not resolved[0]:
                    status = SKIPPED
            else:
                status = self._resolve_one(ctx, kind, a, other, toi)
            if self.once_a_step:
                taken.update((k, a, o) for k, o in together)
            changed = {int(c) for c in self._buf.changed[1:1 + int(self._buf.changed[0])]}
            if changed:
                used_up = {(k, i, j) for k, i, j in used_up
                           if i not in changed and not (PARTNER_IS_SPHERE[k] and j in changed)}
            if status == SKIPPED and a not in changed and not (PARTNER_IS_SPHERE[kind] and other in changed):
                used_up.add((kind, a, other))  # (a skip that moved an anchor changed the path: predicted anew)
            self._record_outcome(ctx, kind, a, other, toi, OUTCOME_SUPERSEDED if status == SKIPPED else OUTCOME_HIT)
            if status == OUT_OF_WORK:
                return "max_resting_work_per_step"

    @staticmethod
    def _first(candidates: list[tuple]) -> tuple:
        """The contact to resolve next: the earliest (ties: immovable partners such as walls
        first, then by index)."""
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
