"""A world's questions about its meshes in a step: where the kinematic ones are, which
sleepers they may reach, how the step's spheres search the trees, who rides a moving
surface, and what the step's search was (the MeshSearch event).

World inherits these methods (as it inherits the calendar's step, calendar_step.py): they
stand apart from world.py as the meshes stand apart from the step's pipeline, which asks
them at its phases (``_begin`` and ``_close`` place the meshes, ``_forces`` wakes the
sleepers, ``_narrow_phase`` asks for the candidates, ``_sleep`` who is carried, ``step``
for the search). What a mesh is and how its tree is walked is the collider kind's
(colliders/mesh.py) and the scene's mesh set's (mesh/mesh_set.py); this is the world's
use of them in a step.
"""

from __future__ import annotations

import numpy as np

from ..events import KIND_MESH, MeshSearch
from .colliders import mesh_search, narrow_candidates
from .colliders.mesh import place, reachable_together, walk_tests
from .resting import HELD
from .step_context import StepContext
from .timeline import MESH_QUERIES

# A walk per sphere against the simultaneous descent (World._choose_mesh_search), in node
# tests of a walk (~10 ns each, stackless and in pre-order): a pair of nodes of the descent
# costs about TOGETHER_PAIR_COST of them (~60 ns: a stack and two trees), and the tree of
# the path boxes TOGETHER_BOX_COST a box (~350 ns: an LBVH build); measured by
# benchmarks/mesh_queries.py --together. Both are counted again every RECHOOSE_SEARCH_EVERY steps.
TOGETHER_PAIR_COST = 6.0
TOGETHER_BOX_COST = 30.0
RECHOOSE_SEARCH_EVERY = 32


class MeshSteps:
    """The world's mesh methods (module doc); World is the only class that inherits them."""

    def _place_meshes(self, time: float, span: float) -> None:
        """Kinematic meshes where they are at run time ``time``, and their frames for the
        next ``span`` s (colliders/mesh.place); nothing when none moves."""
        if self._meshes_move:
            place(self._geometry[KIND_MESH], self.walls.meshes, time, span)

    def _wake_where_meshes_move(self, ctx: StepContext) -> None:
        """Wake the sleeping spheres a kinematic mesh may reach in this step, before anything
        moves: asleep, a sphere is immovable, and a contact between two immovable partners
        is skipped, so the mesh would pass through it. Which: those whose box (grown by the
        contact tolerance) a moving mesh's tree reaches with the box carried into its frame
        over the step (colliders/mesh.frame_box: the candidates its swept tests would get)."""
        if self.sleepers is None or not self._meshes_move or not self.sleepers.count:
            return
        st = self._st
        asleep = np.flatnonzero(self.sleepers.asleep)
        reach = (st.radius[asleep] + self.settings.contact_tolerance)[:, None]
        x = st.positions[asleep]
        spheres, triangles = narrow_candidates(KIND_MESH, ctx.pairs, x - reach, x + reach, self._geometry)
        woke = np.unique(asleep[spheres[self.walls.meshes.mesh_set.on_moving_mesh(triangles)]])
        if woke.size:
            self.sleepers.wake(woke)
            self._inverse_mass[woke] = st.inverse_mass[woke]
            self._free_accel[woke] = self._free_accel_awake[woke]
            ctx.woken += int(woke.size)

    def _mesh_candidates(self, ctx: StepContext) -> tuple[np.ndarray, np.ndarray]:
        """The step's sphere–triangle candidates, by a walk of each mesh's tree per sphere
        or by the simultaneous descent (``settings.mesh_search``; auto: _choose_mesh_search).
        Both give the same candidates in the same order, so the same states bit for bit."""
        together = self._choose_mesh_search(ctx)
        chosen = together is not False
        self.together_steps += int(chosen)
        ctx.mesh_search_method = "together" if chosen else "walk"
        if isinstance(together, tuple):  # counted this step: the descent's candidates are at hand
            return together
        return narrow_candidates(KIND_MESH, ctx.pairs, ctx.path_lo, ctx.path_hi, self._geometry, chosen)

    def _choose_mesh_search(self, ctx: StepContext):
        """Whether this step's spheres are searched against the meshes by the simultaneous
        descent: ``settings.mesh_search``, or under auto the one of less counted work (never
        timed, so a run chooses the same every time): every RECHOOSE_SEARCH_EVERY steps both
        are counted (colliders/mesh.walk_tests; reachable_together's tests, weighed by
        TOGETHER_PAIR_COST, and TOGETHER_BOX_COST a path box), and the steps between keep
        the choice. On a counting step that chose the descent, its candidates (a tuple)."""
        method = self.settings.mesh_search
        if method != "auto":
            return method == "together"
        if self._search_work is not None and self.step_index % RECHOOSE_SEARCH_EVERY != 0:
            walk, together = self._search_work
            return together < walk
        group = self._geometry[KIND_MESH]
        walk = float(walk_tests(ctx.path_lo, ctx.path_hi, group))
        ia, other, tests = reachable_together(ctx.path_lo, ctx.path_hi, group)
        boxes = self._st.count * self.walls.meshes.mesh_set.trees_per_box()
        together = TOGETHER_PAIR_COST * tests + TOGETHER_BOX_COST * boxes
        self._search_work = (walk, together)
        return (ia, other) if together < walk else False

    def _carried(self) -> np.ndarray | None:
        """(N,) bool: the spheres held on a kinematic mesh (a moving surface carries them,
        so they may not sleep: asleep, a sphere is immovable and the mesh would pass
        through it); None when no mesh moves."""
        if not self._meshes_move:
            return None
        held = int(self.held.count[HELD])
        kind, a, other = self.held.kind[:held], self.held.a[:held], self.held.other[:held]
        on_mesh = kind == KIND_MESH
        moving = np.zeros(held, dtype=bool)
        moving[on_mesh] = self.walls.meshes.mesh_set.on_moving_mesh(other[on_mesh])
        carried = np.zeros(self._st.count, dtype=bool)
        carried[a[moving]] = True
        return carried

    def _mesh_search_event(self, ctx: StepContext) -> MeshSearch:
        """The step's walks of the meshes' trees: the path boxes asked at step start and
        those the contact loop logged (timeline's mesh_queries), each walked again by the
        engine's own walk (colliders.mesh_search) with the meshes placed for the step."""
        buf = self._buf
        logged = buf.mesh_queries[:int(buf.counters[MESH_QUERIES])]
        lo0, hi0 = ctx.search_start
        n = lo0.shape[0]
        sphere = np.concatenate([np.arange(n, dtype=np.int64), logged[:, 0].astype(np.int64)])
        after = np.concatenate([np.full(n, -1, dtype=np.int64), logged[:, 1].astype(np.int64)])
        lo = np.concatenate([lo0, logged[:, 2:5]])
        hi = np.concatenate([hi0, logged[:, 5:8]])
        query, node, outcome, parent = mesh_search(lo, hi, self._geometry)
        if self.numbering is not None:
            sphere = self.numbering.spheres(sphere)
        return MeshSearch(ctx.step, sphere.astype(np.int32), after.astype(np.int32), lo, hi, query.astype(np.int32),
                          node.astype(np.int32), outcome.astype(np.int8), parent.astype(np.int32))
