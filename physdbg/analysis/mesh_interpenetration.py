"""Meshes that pass through each other: a scene whose prescribed motions interpenetrate.

A kinematic mesh moves whatever it meets (its motion is prescribed, state.Meshes), so two
meshes whose motions carry one into the other are a bug in the scene: no contact between
meshes is ever resolved, and a sphere caught between them is crushed. At each step's end
the audit searches every pair of meshes of which at least one moves with the seed's
two-tree descent (engine/mesh/descent.py, OBBs: they move and turn without a refit), both
posed where they are then. A pair found meeting that was apart at the step's start is
bisected in time to the first instant it meets (to a millionth of the step) and named with
the first triangle pair that meets then; a pair meeting at run time 0 is named at once.

Not seen: a pass that begins and ends inside one step (both ends apart), and fixed meshes
that touch each other by design (two ramps meeting in a valley) are not searched at all.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

BISECTIONS = 20  # halvings of the step: the first meeting instant to 1e-6 of dt


@dataclass
class MeshMeeting:
    """Meshes ``first`` and ``second`` (indices) meet from run time ``time`` s; ``triangles``
    (2,): the first meeting pair then (each numbered in its own mesh); ``point`` (3,) m: a
    corner of the first's triangle there."""

    first: int
    second: int
    time: float
    triangles: tuple[int, int]
    point: np.ndarray


class MeshOverlaps:
    """The pairs of meshes to watch (module doc) and which of them met at the last check."""

    def __init__(self, meshes):
        self.meshes = meshes
        moving = meshes.moving
        self.pairs = [(i, j) for i in range(len(meshes)) for j in range(i + 1, len(meshes)) if moving[i] or moving[j]]
        self._meeting: set[tuple[int, int]] = set()
        self._started = False

    def _search(self, i: int, j: int, time: float):
        from ..engine.mesh.descent import descend
        from ..engine.mesh.rigid_motion import Pose

        trees = self.meshes.mesh_set.trees  # the scene's, built once
        poses = []
        for k in (i, j):
            turn, shift = self.meshes.transform(k, time)
            poses.append(Pose(shift, turn))
        return descend(trees[i], poses[0], trees[j], poses[1], "obb", hull=False)

    def step(self, start: float, end: float) -> list[MeshMeeting]:
        """The pairs that begin to meet in the step from run time ``start`` to ``end`` s (and,
        at the first step, those meeting already at ``start``)."""
        found = []
        meeting = set()
        for i, j in self.pairs:
            if not self._started and self._search(i, j, start).meet:
                meeting.add((i, j))
                found.append(self._meeting_at(i, j, start))
                continue
            if not self._search(i, j, end).meet:
                continue
            meeting.add((i, j))
            if (i, j) in self._meeting:
                continue
            lo, hi = start, end  # apart at lo, meeting at hi
            for _ in range(BISECTIONS):
                mid = 0.5 * (lo + hi)
                if self._search(i, j, mid).meet:
                    hi = mid
                else:
                    lo = mid
            found.append(self._meeting_at(i, j, hi))
        self._started = True
        self._meeting = meeting
        return found

    def _meeting_at(self, i: int, j: int, time: float) -> MeshMeeting:
        pair = self._search(i, j, time).pairs[0]
        corners = self.meshes.placed(time)[0][self.meshes.mesh_of == i]
        return MeshMeeting(i, j, time, (int(pair[0]), int(pair[1])), corners[int(pair[0]), 0].copy())
