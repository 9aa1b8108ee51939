"""Tunnelling found after the fact: did a recorded step carry a sphere through a wall or
through another sphere without a contact?

The check runs the engine's own exact swept test over the recorded states, not over a
re-simulation: each particle's path through step k is rebuilt from the state at frame
k-1 and the contacts of the step (each contact is an anchor: the centre there and the
velocity after it), along the integrator's own path. The recording does not hold every
change of a path: a contact solved with held contacts (``how`` = 3, or one that is held)
also moves the other spheres of the cluster, which have no row of their own, and the
resting solve changes held spheres' accelerations. So a piece of a rebuilt path, from one
anchor to the next, is checked only where the recording pins its far end: it must arrive
at the next contact's centre with that contact's velocity before it, or at the step's end
position. A piece that does not (something unrecorded changed the path on the way) is
left out of the pair test, which is therefore conservative: it reports no crossing that
the recorded states do not show. (Checking only where each path *ends* is not enough: in
a pile a sphere's path can be moved by cluster solves early in a step and still end on a
recorded contact, and its rebuilt path then ran through a neighbour it never came near;
`physdbg run rain -s generate.count=500` reported six such false tunnellings.)

* Two-sided (thin) walls: the centre is on the other side at the end of the step and no
  contact with that wall was resolved: it went through (true for any path).
* One-sided walls: the centre ends more than a radius behind the plane with no contact.
* Mesh triangles (two-sided, no thickness): the centre's straight path from the step's
  start to its end passes through a triangle, and the sphere resolved no contact with
  that mesh in the step (a sphere that bounced off the mesh is not checked: conservative),
  nor was deflected on the way by another contact (a contact before the step's end and
  an end more than half a radius from where its flight alone would have taken it: it did
  not take that path, and is not checked either). A kinematic mesh's triangles are met in its own frame, where
  its turn bends the path: the path is followed there in pieces over which it turns little.
* Sphere pairs: the swept test on the rebuilt paths finds a touch while approaching,
  no contact between the two was resolved, and they go on to overlap by more than the
  tolerance (a graze within rounding is not a crossing).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from ..engine.broadphase.boxes import NO_LIMIT
from ..engine.broadphase.grid import grid_pairs
from ..engine.motion import KICK_AT_STEP_START, STRAIGHT_PATH, path_coefficients, velocity_coefficients
from ..engine.periodic import unwrap_near
from ..engine.toi import INF, pair_toi_swept_scalar
from ..events import CONTACT_ROW, HOW_IMPULSE, KIND_MESH, KIND_PAIR, KIND_WALL, Contacts

DEPTH_SAMPLES = 32  # instants at which a touched pair's overlap is measured after the touch


def sorted_unique(values: np.ndarray) -> np.ndarray:
    """np.unique of a 1-d integer array (sorted, each value once), by a sort: numpy 2's
    np.unique hashes first, ~0.7 ms for the 5,500 contacts of a box-rain 10k step where
    this takes ~0.12."""
    ordered = np.sort(values)
    if len(ordered) < 2:
        return ordered
    keep = np.empty(len(ordered), dtype=bool)
    keep[0] = True
    np.not_equal(ordered[1:], ordered[:-1], out=keep[1:])
    return ordered[keep]


@dataclass(frozen=True)
class Crossing:
    """One crossing in a step: kind KIND_WALL (other = wall index), KIND_MESH (other =
    triangle) or KIND_PAIR (other = sphere); time: s after the step began (for walls and
    meshes: NaN, the instant is not known); depth: how far into the other sphere it went
    (m; for walls and triangles the distance past the plane); where: the point the
    centre's straight path crossed a triangle and feature the triangle's part it crossed
    (events.FEATURE_NAMES index: its face, or an edge or a corner where it crossed on one;
    meshes only, else -1)."""

    kind: int
    a: int
    other: int
    time: float
    depth: float
    where: tuple[float, float, float] | None = None
    feature: int = -1


@njit(cache=True, inline="always")
def _state_at(anchor_t, anchor_x, anchor_v, row, acc, i, t, integrator, drag, k):
    """Position and velocity of particle i at time t from anchor ``row``, as six floats
    (x, y, z, vx, vy, vz): the one place the checker evaluates a rebuilt path."""
    tau = t - anchor_t[row]
    p1, p2, _ = path_coefficients(integrator, k, tau)
    v0, v1 = velocity_coefficients(integrator, drag, k, tau)
    return (anchor_x[row, 0] + anchor_v[row, 0] * p1 + acc[i, 0] * p2,
            anchor_x[row, 1] + anchor_v[row, 1] * p1 + acc[i, 1] * p2,
            anchor_x[row, 2] + anchor_v[row, 2] * p1 + acc[i, 2] * p2,
            anchor_v[row, 0] * v0 + acc[i, 0] * v1, anchor_v[row, 1] * v0 + acc[i, 1] * v1,
            anchor_v[row, 2] * v0 + acc[i, 2] * v1)


@njit(cache=True)
def _at(anchor_t, anchor_x, anchor_v, row, acc, i, t, integrator, drag, k, out):
    """_state_at into out (6,)."""
    out[0], out[1], out[2], out[3], out[4], out[5] = _state_at(anchor_t, anchor_x, anchor_v, row, acc, i, t,
                                                               integrator, drag, k)


@njit(cache=True, inline="always")
def _piece_start(anchor_t, anchor_x, anchor_v, row, acc, i, t, integrator, drag, k):
    """_state_at where a pinned piece of the pair test begins: the anchor itself when t is
    its time (most pieces start at one; a pinned anchor is finite, so these are the numbers
    the path gives there). Inlined, returning scalars: the pair test's walk ran about 1.5
    times slower through _at's output array."""
    if t == anchor_t[row]:
        return (anchor_x[row, 0], anchor_x[row, 1], anchor_x[row, 2], anchor_v[row, 0], anchor_v[row, 1],
                anchor_v[row, 2])
    return _state_at(anchor_t, anchor_x, anchor_v, row, acc, i, t, integrator, drag, k)


@njit(cache=True)
def _wall_crossings(x0, x1, normals, offsets, two_sided, radius):
    """Spheres whose centre went through a wall in the step, from x0 to x1 (N, 3), as rows
    (sphere, wall, |h1|) of a (K, 3) float64 array in (sphere, wall) order; h = n·x - d is
    the centre's signed distance from wall n·x = d (normals (W, 3), offsets (W,)). A
    two-sided wall: h changed sign, neither end on the plane (a NaN end counts as through,
    as numpy's sign comparison had it); a one-sided wall: from h >= 0 to beyond a radius
    behind it. (Was (N, W) numpy, ~1.7 ms a step at 10 000 spheres; n·x is summed in axis
    order here, where the matrix product's order was the BLAS library's.)"""
    rows = []
    for i in range(x0.shape[0]):
        for w in range(normals.shape[0]):
            h0 = normals[w, 0] * x0[i, 0] + normals[w, 1] * x0[i, 1] + normals[w, 2] * x0[i, 2] - offsets[w]
            h1 = normals[w, 0] * x1[i, 0] + normals[w, 1] * x1[i, 1] + normals[w, 2] * x1[i, 2] - offsets[w]
            if two_sided[w]:
                through = _sign(h0) != _sign(h1) and h0 != 0.0 and h1 != 0.0
            else:
                through = h0 >= 0.0 and h1 < -radius[i]
            if through:
                rows.append((float(i), float(w), abs(h1)))
    out = np.empty((len(rows), 3))
    for r in range(len(rows)):
        out[r, 0] = rows[r][0]
        out[r, 1] = rows[r][1]
        out[r, 2] = rows[r][2]
    return out


@njit(cache=True, inline="always")
def _sign(h):
    """np.sign of a float: -1, 0 or 1, NaN for NaN."""
    if h != h:
        return h
    return 1.0 if h > 0.0 else (-1.0 if h < 0.0 else 0.0)


@njit(cache=True)
def pair_crossings(anchor_start, anchor_t, anchor_x, anchor_v, pinned, acc, radius, pairs, contacted,
                   dt, integrator, drag, k, tolerance):
    """Pairs that touch along their rebuilt paths with no contact resolved between them.

    anchor_start: (N+1,) CSR offsets of each particle's anchors (time-sorted rows of
    anchor_t (s), anchor_x, anchor_v (M, 3)); pinned: (M,) bool, whether the piece of path
    from each anchor to the next is pinned by the recording (module doc; other pieces are
    not tested); acc: (N, 3) path accelerations; pairs: (P, 2) the candidate pairs i < j
    (those whose path boxes meet); contacted: sorted keys i*N+j (i<j) of pairs with a
    contact this step. Returns (i, j, time, depth) rows as (K, 4) float64.
    """
    n = radius.shape[0]
    found = np.empty((0, 4))
    rows = []
    si = np.empty(6)
    sj = np.empty(6)
    for m in range(pairs.shape[0]):
        i = pairs[m, 0]
        j = pairs[m, 1]
        key = i * n + j
        pos = np.searchsorted(contacted, key)
        if pos < contacted.shape[0] and contacted[pos] == key:
            continue
        # walk the instants where either path has a kink (both anchor lists are sorted
        # by time): the paths are smooth between them
        big_r = radius[i] + radius[j]
        pi = anchor_start[i]
        pj = anchor_start[j]
        ei = anchor_start[i + 1]
        ej = anchor_start[j + 1]
        t0 = 0.0
        while t0 < dt:
            # the anchors in force at t0, and the next kink after it
            while pi + 1 < ei and anchor_t[pi + 1] <= t0:
                pi += 1
            while pj + 1 < ej and anchor_t[pj + 1] <= t0:
                pj += 1
            t1 = dt
            if pi + 1 < ei:
                t1 = min(t1, anchor_t[pi + 1])
            if pj + 1 < ej:
                t1 = min(t1, anchor_t[pj + 1])
            ri = pi
            rj = pj
            if not (pinned[ri] and pinned[rj]):
                t0 = t1
                continue
            a0, a1, a2, a3, a4, a5 = _piece_start(anchor_t, anchor_x, anchor_v, ri, acc, i, t0, integrator, drag, k)
            b0, b1, b2, b3, b4, b5 = _piece_start(anchor_t, anchor_x, anchor_v, rj, acc, j, t0, integrator, drag, k)
            toi = pair_toi_swept_scalar(a0 - b0, a1 - b1, a2 - b2, a3 - b3, a4 - b4,
                                        a5 - b5, acc[i, 0] - acc[j, 0], acc[i, 1] - acc[j, 1],
                                        acc[i, 2] - acc[j, 2], big_r, integrator, k, t1 - t0, tolerance)
            if toi == INF:
                t0 = t1
                continue
            # how deep does it go before the interval ends?
            deepest = 0.0
            for q in range(DEPTH_SAMPLES + 1):
                t = t0 + toi + (t1 - t0 - toi) * q / DEPTH_SAMPLES
                _at(anchor_t, anchor_x, anchor_v, ri, acc, i, t, integrator, drag, k, si)
                _at(anchor_t, anchor_x, anchor_v, rj, acc, j, t, integrator, drag, k, sj)
                d = math.sqrt((si[0] - sj[0]) ** 2 + (si[1] - sj[1]) ** 2 + (si[2] - sj[2]) ** 2)
                deepest = max(deepest, big_r - d)
            if deepest > tolerance:
                rows.append((float(i), float(j), t0 + toi, deepest))
                break
            t0 = t1
    if len(rows):
        found = np.empty((len(rows), 4))
        for r in range(len(rows)):
            found[r, 0] = rows[r][0]
            found[r, 1] = rows[r][1]
            found[r, 2] = rows[r][2]
            found[r, 3] = rows[r][3]
    return found


def _crossed_feature(point: np.ndarray, corners: np.ndarray, tolerance: float = 1e-9) -> int:
    """Which part of a triangle (corners (3, 3)) a point on it lies on: its face, or an edge
    or a corner within ``tolerance`` of the triangle's size (events.FEATURE_NAMES order)."""
    size = float(np.linalg.norm(corners.max(axis=0) - corners.min(axis=0)))
    near_corner = np.linalg.norm(corners - point, axis=1) <= tolerance * size
    if near_corner.any():
        return 4 + int(np.argmax(near_corner))
    for edge, (p, q) in enumerate(((0, 1), (1, 2), (2, 0))):
        along = corners[q] - corners[p]
        s = float(np.clip((point - corners[p]) @ along / (along @ along), 0.0, 1.0))
        if np.linalg.norm(corners[p] + s * along - point) <= tolerance * size:
            return 1 + edge
    return 0


# the most a kinematic mesh turns over one piece of a path the audit follows in its frame
# (rad): a straight piece there stands for an arc whose sagitta is under 0.02 % of its
# distance from the axis; and the most pieces a step's path is cut into
TURN_PER_PIECE = math.radians(2.0)
MOST_PIECES = 720


def _in_mesh_frame(meshes, k: int, x0: np.ndarray, x1: np.ndarray, time: float, dt: float):
    """(spheres (K,), triangles (K,), start (K, 3), end (K, 3), final (K, 3)): the centres'
    straight paths from the step's start (x0, run time ``time``) to its end (x1, ``time +
    dt``) seen from kinematic mesh k where it was at run time 0, cut into pieces over each
    of which the mesh turns at most TURN_PER_PIECE (one piece for a mesh that only slides:
    in its frame the path stays straight), each piece paired with each of k's triangles
    whose box its box meets; final: where the piece's sphere ends the step, in that frame.
    A mesh turning a fair part of a revolution in a step bends the path in its frame: the
    chord from start to end would cut through a spinning body the sphere flew past. Only
    the spheres whose path's box comes within the mesh's reach over the step are followed.
    A mesh turning more than MOST_PIECES × TURN_PER_PIECE in a step is followed in
    MOST_PIECES pieces."""
    own = np.flatnonzero(meshes.mesh_of == k)
    corners = meshes.corners[own]
    c_lo, c_hi = corners.min(axis=1), corners.max(axis=1)
    turn = float(np.linalg.norm(meshes.angular_velocity[k])) * dt
    pieces = int(min(MOST_PIECES, max(1, math.ceil(turn / TURN_PER_PIECE))))
    # where the mesh can be during the step: its turning ball about its pivot, carried along
    reach = meshes.turn_radii()[k]
    pivot = meshes.pivot[k] + meshes.velocity[k] * time  # where its pivot is at the step's start
    drift = np.asarray(meshes.velocity[k], dtype=np.float64) * dt
    lo = pivot + np.minimum(drift, 0.0) - reach
    hi = pivot + np.maximum(drift, 0.0) + reach
    near = np.flatnonzero(((np.minimum(x0, x1) <= hi) & (np.maximum(x0, x1) >= lo)).all(axis=1))
    empty = np.zeros((0, 3))
    if not len(near):
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), empty, empty, empty
    a, b = x0[near], x1[near]
    seen = []
    for j in range(pieces + 1):
        f = j / pieces
        rotation, shift = meshes.transform(k, time + f * dt)
        seen.append(((a + (b - a) * f) - shift) @ rotation)  # R^T (x - shift), row by row
    out = []
    for j in range(pieces):
        start, end = seen[j], seen[j + 1]
        lo, hi = np.minimum(start, end), np.maximum(start, end)
        meets = ((lo[:, None, :] <= c_hi[None]) & (hi[:, None, :] >= c_lo[None])).all(axis=2)
        spheres, which = np.nonzero(meets)
        out.append((near[spheres], own[which], start[spheres], end[spheres], seen[-1][spheres]))
    return tuple(np.concatenate([piece[q] for piece in out]) for q in range(5))


def _segments_through_triangles(start: np.ndarray, end: np.ndarray, corners: np.ndarray, final: np.ndarray):
    """Which segments start→end (K, 3) pass through triangle corners (K, 3, 3) (Möller–
    Trumbore, the triangle's edges included): (hit (K,) bool, the crossing point (K, 3),
    how far ``final`` (K, 3: where the sphere ends the step) lies from the triangle's
    plane (K,) m)."""
    d = end - start
    e1 = corners[:, 1] - corners[:, 0]
    e2 = corners[:, 2] - corners[:, 0]
    h = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, h)
    ok = np.abs(det) > 1e-300
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = start - corners[:, 0]
    u = inv * np.einsum("ij,ij->i", s, h)
    q = np.cross(s, e1)
    v = inv * np.einsum("ij,ij->i", d, q)
    t = inv * np.einsum("ij,ij->i", e2, q)
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0) & (t <= 1)
    normal = np.cross(e1, e2)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    past = np.abs(np.einsum("ij,ij->i", final - corners[:, 0], normal))
    return hit, start + t[:, None] * d, past


class StepChecker:
    """Finds crossings in recorded steps of one run.

    radius, inverse_mass, gravity_scale: (N,); walls: engine Walls; settings: the
    recorded settings dict (integrator, drag, gravity, contact_tolerance).
    """

    def __init__(self, radius, inverse_mass, gravity_scale, walls, settings: dict):
        from ..engine.motion import INTEGRATOR_NAMES

        self.radius = np.asarray(radius, dtype=np.float64)
        self.n = len(self.radius)
        self.walls = walls
        name = settings.get("integrator", "exact")
        if name not in INTEGRATOR_NAMES:
            from ..errors import RecordingError

            raise RecordingError(f"the run's integrator '{name}' is not one this physdbg has "
                                 f"({', '.join(INTEGRATOR_NAMES)}): a recording from a newer physdbg?")
        self.integrator = INTEGRATOR_NAMES.index(name)
        self.drag = float(settings.get("drag", 1.0))
        self.k = -math.log(self.drag) if 0.0 < self.drag < 1.0 else 0.0
        gravity = np.asarray(settings.get("gravity", (0.0, 0.0, 0.0)), dtype=np.float64)
        movable = np.asarray(inverse_mass) > 0
        self.gravity_acc = np.where(movable[:, None], np.asarray(gravity_scale)[:, None] * gravity[None, :], 0.0)
        self.path_acc = np.zeros_like(self.gravity_acc) if STRAIGHT_PATH[self.integrator] \
            else self.gravity_acc
        self.path_acc_size = np.linalg.norm(self.path_acc, axis=1)  # (N,) m/s², the same every step
        self.tolerance = max(float(settings.get("contact_tolerance", 1e-9)), 0.0)
        self.two_sided = np.asarray(walls.two_sided, dtype=bool)
        self._mesh_geometry = None  # the engine's mesh group, built at the first step with meshes
        self.half_thickness = 0.5 * np.asarray(walls.thickness, dtype=np.float64)
        # pieces of path (anchor to anchor) seen, and those the recording pins (_pinned)
        self.pieces = 0
        self.pinned_pieces = 0

    def check(self, x0, v0, x1, dt: float, contacts, time: float | None = None,
              pairs: bool = True) -> list[Crossing]:
        """Crossings in one step from frame state (x0, v0) to positions x1 (all (N, 3));
        contacts: the step's Contacts (None when not recorded); time: the run time (s) at
        the step's start, where the kinematic meshes are (None: they are not checked);
        pairs: False leaves out the pair test (spheres through spheres: the audit's cost,
        which a live audit of physdbg's own exact steps takes from the engine's tests).

        In a periodic box the engine wraps each end position into the box and records a
        pair contact's point next to sphere a, whichever image of b it met: every position
        is first moved by whole periods next to where its sphere began the step (a step
        carries no sphere half a period), so each sphere's path is continuous. Pairs that
        meet across a periodic face are not tested (the check stays conservative).
        """
        if self.walls.periodic:
            x1 = unwrap_near(x1, x0, self.walls.period)
        out = self._walls(x0, x1, contacts)
        if self.walls.meshes.triangles:
            out += self._meshes(x0, v0, x1, contacts, time, dt)
        if self.n > 1 and pairs:
            out += self._pairs(x0, v0, x1, dt, contacts)
        return out

    def _walls(self, x0, x1, contacts) -> list[Crossing]:
        walls = self.walls
        if not len(walls):
            return []
        found = _wall_crossings(np.ascontiguousarray(x0, dtype=np.float64), np.ascontiguousarray(x1, dtype=np.float64),
                                np.ascontiguousarray(walls.normals, dtype=np.float64),
                                np.ascontiguousarray(walls.offsets, dtype=np.float64), self.two_sided, self.radius)
        if not len(found):
            return []
        touched = set()
        if contacts is not None:
            wall = contacts.kind == KIND_WALL
            touched = set(zip(contacts.a[wall].tolist(), contacts.other[wall].tolist(), strict=True))
        out = []
        for i, w, depth in found.tolist():
            if (int(i), int(w)) not in touched:
                out.append(Crossing(KIND_WALL, int(i), int(w), math.nan, depth))
        return out

    def _meshes(self, x0, v0, x1, contacts, time, dt) -> list[Crossing]:
        """Spheres whose centre's straight path through the step passes through a triangle
        of a mesh they resolved no contact with (module doc). A kinematic mesh is checked
        in its own frame, where a turning mesh bends the path: followed there in pieces
        over which the mesh turns little (_in_mesh_frame)."""
        from ..engine.colliders import mesh

        meshes = self.walls.meshes
        if self._mesh_geometry is None:
            self._mesh_geometry = tuple(mesh.MeshGeometry.of(self.walls))
        x0 = np.ascontiguousarray(x0, dtype=np.float64)
        x1 = np.ascontiguousarray(x1, dtype=np.float64)
        sphere, triangle = mesh.reachable(np.minimum(x0, x1), np.maximum(x0, x1), self._mesh_geometry)
        moving = meshes.moving
        mesh_of = meshes.mesh_of
        start, end = x0[sphere], x1[sphere]
        if moving.any():
            fixed = ~moving[mesh_of[triangle]]
            sphere, triangle, start, end = sphere[fixed], triangle[fixed], start[fixed], end[fixed]
        final = end
        if moving.any() and time is not None:
            more = [_in_mesh_frame(meshes, k, x0, x1, time, dt) for k in np.flatnonzero(moving)]
            sphere = np.concatenate([sphere] + [m[0] for m in more])
            triangle = np.concatenate([triangle] + [m[1] for m in more])
            start = np.concatenate([start] + [m[2] for m in more])
            final = np.concatenate([end] + [m[4] for m in more])
            end = np.concatenate([end] + [m[3] for m in more])
        if not len(sphere):
            return []
        corners = meshes.corners[triangle]  # (K, 3, 3), at run time 0 (a moving mesh's frame)
        hit, where, past = _segments_through_triangles(start, end, corners, final)
        if not hit.any():
            return []
        features = np.full(len(hit), -1, dtype=np.int64)
        for k in np.flatnonzero(hit):  # the part of the triangle crossed (in the mesh's frame)
            features[k] = _crossed_feature(where[k], corners[k])
        for k in np.flatnonzero(moving[mesh_of[triangle]] & hit):  # back to the world, where the step ends
            turn, shift = meshes.transform(int(mesh_of[triangle[k]]), time + dt)
            where[k] = turn @ where[k] + shift
        touched, deflected = set(), set()
        if contacts is not None:
            on_mesh = contacts.kind == KIND_MESH
            touched = set(zip(contacts.a[on_mesh].tolist(), mesh_of[contacts.other[on_mesh]].tolist(), strict=True))
            # a sphere a contact deflected before the step's end did not take the straight
            # path from its start to its end (a bounce off the floor beside a block has a
            # chord through the block): not checked where its end is more than half a radius
            # from where its flight alone would have taken it (a ball rolling on a floor,
            # held there, still is)
            early = contacts.time_in_step < dt * (1.0 - 1e-9)
            touched_early = set(contacts.a[early].tolist())
            touched_early |= set(contacts.other[early & (contacts.kind == KIND_PAIR)].tolist())
            if touched_early:
                who = np.fromiter(touched_early, dtype=np.int64)
                flight = x0[who] + v0[who] * dt + 0.5 * self.gravity_acc[who] * dt * dt
                off = np.linalg.norm(x1[who] - flight, axis=1) > 0.5 * self.radius[who]
                deflected = set(who[off].tolist())
        out, seen = [], set()
        for k in np.flatnonzero(hit).tolist():
            i, t = int(sphere[k]), int(triangle[k])
            if (i, int(mesh_of[t])) in touched or i in deflected or i in seen:
                continue
            seen.add(i)
            out.append(Crossing(KIND_MESH, i, t, math.nan, float(past[k]), tuple(float(q) for q in where[k]),
                                int(features[k])))
        return out

    def _pairs(self, x0, v0, x1, dt, contacts) -> list[Crossing]:
        n = self.n
        radius = self.radius
        v_start = v0
        if KICK_AT_STEP_START[self.integrator]:  # the step's kick comes first, then straight lines
            v_start = v0 * (self.drag ** dt if self.drag != 1.0 else 1.0) + self.gravity_acc * dt
        # anchors: who (sphere), when (s into the step), where (centre), speed (velocity
        # after), before (velocity just before: how the piece leading here must arrive)
        # the step's start, then one per contact (sphere a), then one per pair contact
        # (sphere b); contacts at one instant (a cradle's blow) are anchors in the order they
        # were resolved (order_key)
        who = [np.arange(n)]
        when = [np.zeros(n)]
        order_key = [np.full(n, -1, dtype=np.int64)]
        no_rows = np.empty((0, 3))
        centre_a = after_a = before_a = centre_b = after_b = before_b = no_rows
        contacted = np.zeros(0, dtype=np.int64)
        if contacts is not None and len(contacts):
            a = contacts.a.astype(np.int64)
            centre_a = contacts.point + contacts.normal * radius[a][:, None]
            after_a, before_a = contacts.velocity_a_after, contacts.velocity_a_before
            who.append(a)
            when.append(contacts.time_in_step)
            order_key.append(np.arange(len(contacts), dtype=np.int64))
            pair = contacts.kind == KIND_PAIR
            b = contacts.other[pair].astype(np.int64)
            centre_b = contacts.point[pair] - contacts.normal[pair] * radius[b][:, None]
            after_b, before_b = contacts.velocity_b_after[pair], contacts.velocity_b_before[pair]
            who.append(b)
            when.append(contacts.time_in_step[pair])
            order_key.append(np.flatnonzero(pair).astype(np.int64))
            contacted = sorted_unique(np.minimum(a[pair], b) * n + np.maximum(a[pair], b))
        who = np.concatenate(who)
        when = np.concatenate(when)
        order_key = np.concatenate(order_key)
        if np.isnan(when).any():  # not from physdbg's engine: numpy's order puts NaN last
            order = np.lexsort((order_key, when, who))
            start = np.zeros(n + 1, dtype=np.int64)
            np.cumsum(np.bincount(who, minlength=n), out=start[1:])
        else:
            order, start = _anchor_order(who, when, order_key, n)
        who, when = who[order], when[order]
        # (M, 3) rows straight into their order: concatenating them and then gathering
        # made two fresh copies of each, ~10 ms a step at 100 000 spheres
        where, speed, before = _ordered_anchors(order, *(np.ascontiguousarray(rows, dtype=np.float64) for rows in
                                                         (x0, v_start, centre_a, after_a, before_a, centre_b,
                                                          after_b, before_b)))
        if self.walls.periodic:
            where = unwrap_near(where, x0[who], self.walls.period)
        pinned = self._pinned(who, when, where, speed, before, start, x1, dt)
        self.pieces += len(pinned)
        self.pinned_pieces += int(pinned.sum())
        checked = np.zeros(n, dtype=bool)
        checked[who[pinned]] = True
        if not checked.any():
            return []
        # boxes: every anchor and the end, padded by the radius and the most a path can bow
        lo = np.minimum(x0, x1)
        hi = np.maximum(x0, x1)
        if np.isnan(where).any():  # NaN spreads through the box, as it always has
            np.minimum.at(lo, who, where)
            np.maximum.at(hi, who, where)
        else:
            _widen_to_anchors(who, np.ascontiguousarray(where), lo, hi)
        bow = 0.125 * (self.path_acc_size + self.k * np.abs(speed).max(initial=0.0)) * dt * dt
        pad = (radius + bow + self.tolerance)[:, None]
        # the boxes that meet, by the engine's uniform grid (a sort and sweep along x took
        # 21 ms a step at 10 000 spheres, twice the engine's step: each box met ~400 in x)
        pairs = grid_pairs(np.ascontiguousarray(lo - pad), np.ascontiguousarray(hi + pad), 0.0, NO_LIMIT)[0]
        pairs = np.ascontiguousarray(pairs[checked[pairs[:, 0]] & checked[pairs[:, 1]]])
        found = pair_crossings(start, when, np.ascontiguousarray(where), np.ascontiguousarray(speed), pinned,
                               np.ascontiguousarray(self.path_acc), radius, pairs, contacted, dt, self.integrator,
                               self.drag, self.k, max(self.tolerance, 1e-12))
        depth_floor = 1e-6 * radius
        return [Crossing(KIND_PAIR, int(i), int(j), float(t), float(d)) for i, j, t, d in found
                if d > max(depth_floor[int(i)], depth_floor[int(j)], self.tolerance)]

    def _pinned(self, who, when, where, speed, before, start, x1, dt) -> np.ndarray:
        """(M,) bool: whether the piece of path from each anchor to the next (the last:
        to the step's end) arrives where the recording says, in position and, at a contact,
        in velocity (module doc). Anchors as in _pairs, sorted by sphere then time.

        The slack is far below the depth a crossing must reach to be reported: a path
        whose unrecorded change stays within it moves by no more than the slack.
        """
        pinned = np.empty(len(who), dtype=bool)
        _pinned_kernel(who, when, np.ascontiguousarray(where), np.ascontiguousarray(speed),
                       np.ascontiguousarray(before), start, np.ascontiguousarray(x1), dt,
                       np.ascontiguousarray(self.path_acc), self.radius, self.tolerance, self.integrator, self.drag,
                       self.k, pinned)
        return pinned


@njit(cache=True)
def _pinned_kernel(who, when, where, speed, before, start, x1, dt, acc, radius, tolerance, integrator, drag, k,
                   pinned):
    """StepChecker._pinned in one compiled pass (its numpy took ~4 ms a step at 10 000
    spheres), written as numpy wrote it: the piece from anchor r runs to the next anchor
    (its time, centre, and velocity before it) or, for a sphere's last, to the step's end
    (dt, x1 (N, 3), no velocity); rebuilt along the path, it must arrive within a slack of
    1e-6 radius + 10 tolerance + 1e-12 |target| (a NaN anywhere fails it), and its
    velocity within slack / dt + 1e-12 |velocity| (none to match passes). pinned: (M,) out."""
    m = who.shape[0]
    is_last = np.zeros(m, dtype=np.bool_)
    for i in range(start.shape[0] - 1):
        is_last[start[i + 1] - 1] = True
    got = np.empty(6)
    for r in range(m):
        last = is_last[r]
        i = who[r]
        _at(when, where, speed, r, acc, i, dt if last else when[r + 1], integrator, drag, k, got)
        x_err = 0.0
        v_err = 0.0
        target_size = 0.0
        speed_size = 0.0
        for c in range(3):
            target = x1[i, c] if last else where[r + 1, c]
            arrived = before[r + 1, c] if not last else np.nan
            x_err += (got[c] - target) * (got[c] - target)
            v_err += (got[3 + c] - arrived) * (got[3 + c] - arrived)
            target_size = _max_with_nan(target_size, abs(target), c)
            speed_size = _max_with_nan(speed_size, abs(got[3 + c]), c)
        slack = 1e-6 * radius[i] + 10.0 * tolerance + 1e-12 * target_size
        v_slack = slack / dt + 1e-12 * speed_size
        v_err = math.sqrt(v_err)
        pinned[r] = math.sqrt(x_err) <= slack and (v_err != v_err or v_err <= v_slack)


@njit(cache=True, inline="always")
def _max_with_nan(so_far, value, c):
    """numpy's max over a row, one element c at a time: the first is taken as it is, and a
    NaN anywhere is the answer."""
    if c == 0 or value != value:
        return value
    if so_far != so_far or so_far >= value:
        return so_far
    return value


def warm_up() -> None:
    """Compile (or load from numba's cache) the checker's kernels: a cold cache takes
    ~11 s here, which an audited run would otherwise charge to its first step
    (precompile.compile_kernels runs this, on its helper process when it has one). The
    step checked is written out, not run, so this compiles nothing of the engine's: two
    spheres 1 m apart closing at 2 m/s along x meet head on at 0.4 s and swap velocities;
    every piece of their paths is pinned, so the pair sweep runs."""
    from ..engine.warm import warm_up_world

    state, walls = warm_up_world()  # (their radii, masses and the floor; the states are below)
    x0 = np.array([[-0.5, 0.3, 0.0], [0.5, 0.3, 0.0]])
    v0 = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    x1 = np.array([[-0.2, 0.3, 0.0], [0.2, 0.3, 0.0]])
    rows = np.zeros(1, dtype=CONTACT_ROW)
    rows[0] = (0.4, KIND_PAIR, HOW_IMPULSE, 0, 1, (0.0, 0.3, 0.0), (-1.0, 0.0, 0.0), 2.0, v0[0], v0[1], v0[1], v0[0],
               1.0, 2.0, 0)
    checker = StepChecker(state.radius, state.inverse_mass, state.gravity_scale, walls,
                          {"integrator": "exact", "drag": 1.0, "gravity": (0.0, 0.0, 0.0), "contact_tolerance": 1e-9})
    checker.check(x0, v0, x1, 0.5, Contacts(0, rows))
    assert checker.pinned_pieces == 4  # the sweep ran (it runs only over pinned pieces)


@njit(cache=True)
def _anchor_order(who, when, order_key, n):
    """The anchors' rows sorted by (who, when, order_key), as np.lexsort((order_key, when,
    who)) gives them (stable; when holds no NaN), and each sphere's first row: (order (M,),
    start (N+1,)). A counting sort by sphere keeps the given order; each sphere's few
    anchors, already nearly in time order, are then insertion-sorted. (lexsort and
    np.minimum.at were most of the audit's own time in a dense step: ~17 of 63 ms.)"""
    m = who.shape[0]
    start = np.zeros(n + 1, dtype=np.int64)
    for r in range(m):
        start[who[r] + 1] += 1
    for i in range(n):
        start[i + 1] += start[i]
    fill = start[:-1].copy()
    order = np.empty(m, dtype=np.int64)
    for r in range(m):
        order[fill[who[r]]] = r
        fill[who[r]] += 1
    for i in range(n):
        for p in range(start[i] + 1, start[i + 1]):
            r = order[p]
            q = p - 1
            while q >= start[i] and (when[order[q]] > when[r]
                                     or (when[order[q]] == when[r] and order_key[order[q]] > order_key[r])):
                order[q + 1] = order[q]
                q -= 1
            order[q + 1] = r
    return order, start


@njit(cache=True)
def _ordered_anchors(order, x0, v_start, centre_a, after_a, before_a, centre_b, after_b, before_b):
    """The anchors' centres, velocities after and velocities before (each (M, 3)) in
    ``order`` (M,), which numbers them as StepChecker._pairs lists them: the N spheres at
    the step's start (x0, v_start; no velocity before: NaN), then sphere a of each contact
    (centre_a, after_a, before_a), then sphere b of each pair contact (centre_b, ...)."""
    n = x0.shape[0]
    with_a = n + centre_a.shape[0]
    m = order.shape[0]
    where = np.empty((m, 3))
    speed = np.empty((m, 3))
    before = np.empty((m, 3))
    for r in range(m):
        s = order[r]
        for c in range(3):
            if s < n:
                where[r, c] = x0[s, c]
                speed[r, c] = v_start[s, c]
                before[r, c] = np.nan
            elif s < with_a:
                where[r, c] = centre_a[s - n, c]
                speed[r, c] = after_a[s - n, c]
                before[r, c] = before_a[s - n, c]
            else:
                where[r, c] = centre_b[s - with_a, c]
                speed[r, c] = after_b[s - with_a, c]
                before[r, c] = before_b[s - with_a, c]
    return where, speed, before


@njit(cache=True)
def _widen_to_anchors(who, where, lo, hi):
    """Grow each sphere's box lo, hi (N, 3) to hold its anchors' centres where (M, 3)."""
    for r in range(who.shape[0]):
        i = who[r]
        for c in range(3):
            if where[r, c] < lo[i, c]:
                lo[i, c] = where[r, c]
            if where[r, c] > hi[i, c]:
                hi[i, c] = where[r, c]

