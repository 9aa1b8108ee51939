"""Typed events the engine reports to its observer.

One step produces, in this order::

    StepBegin
    BroadPhaseInfo             (the structure used this step, its stats and, for BVHs, nodes)
    EngineWarning ...          (zero or more, as they arise)
    Contacts                   (one batch: every contact, in the order they were resolved)
    SweptTests                 (one batch: every candidate the narrow phase tested)
    MeshSearch                 (a scene with meshes: every node of their trees the step's walks visited)
    StepEnd

Every event's ``step`` is the step's number, counted from 1 as the CLI, the recordings
and the viewer count it: step k moves the state of frame k-1 (frame 0 is the scene's
initial state) to frame k. Units: metres, seconds, kilograms; impulses in N·s. Arrays
are float64 unless stated. Events are built only when an observer is attached; arrays in
them are copies the engine will not mutate afterwards, so an observer may keep them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

# Collider kinds: what a contact's partner is (a swept test, a contact and a held contact
# are (kind, a, other): sphere ``a`` against partner ``other`` of that kind). The table,
# one row per kind indexed by its code, is what readers ask (is the partner a sphere that
# moves? what is it called?) instead of testing for a kind; the engine's colliders read the
# same rows (engine/colliders/kinds.py) and add each kind's geometry (engine/colliders/).
class ColliderKindRow(NamedTuple):
    """A row of the registry of collider kinds: what the partner is called in records and
    reports (and, for a kind beyond the wall and the mesh, its scene table's name), its
    module in engine/colliders/ (the geometry, the swept test and what every layer reads
    of the kind: docs/colliders.md) and whether the partner is a sphere that moves and
    takes impulses (its own velocity, version, anchor time and held-contact list); the
    others (a wall, a mesh's triangle) are immovable."""

    name: str
    module: str
    partner_is_sphere: bool


# The registry: one row per kind, in the order of their codes. A kind is its module and
# its row here (then `python physdbg/write_switch.py` writes the switch).
COLLIDER_KINDS = (
    ColliderKindRow("sphere", "sphere", True),
    ColliderKindRow("wall", "plane", False),
    ColliderKindRow("mesh", "mesh", False),
)
KIND_PAIR = 0  # the partner is sphere ``other``
KIND_WALL = 1  # the partner is wall (plane) ``other`` of the scene's walls
KIND_MESH = 2  # the partner is triangle ``other`` of the scene's meshes (numbered across them)
KIND_NAMES = tuple(row.name for row in COLLIDER_KINDS)
PARTNER_IS_SPHERE = tuple(row.partner_is_sphere for row in COLLIDER_KINDS)
_PARTNER_IS_SPHERE = np.array(PARTNER_IS_SPHERE, dtype=bool)


def check_kinds(kind, where: str = "") -> None:
    """Raise RecordingError when a kind code (or array of them) is not in the table: a
    file from a physdbg that knows more kinds, or a damaged one. where: the file."""
    codes = np.asarray(kind)
    if codes.size and (int(codes.min()) < 0 or int(codes.max()) >= len(KIND_NAMES)):
        from .errors import RecordingError

        bad = int(codes.max()) if int(codes.max()) >= len(KIND_NAMES) else int(codes.min())
        raise RecordingError(f"{where + ': ' if where else ''}a contact or swept test of collider kind {bad}, which "
                             f"this physdbg does not know (its kinds: " +
                             ", ".join(f"{code} {name}" for code, name in enumerate(KIND_NAMES)) + ")")


def partner_is_sphere(kind):
    """Whether the partner of a contact of this kind is a sphere (an array of kinds gives
    an array of bools): a row of the table."""
    return _PARTNER_IS_SPHERE[kind]


def partner_words(kind: int, other: int, names) -> str:
    """How reports name a contact's partner: "sphere 4", "wall 'floor'" or "mesh 'ramp'
    triangle 3" (names: the recording's names of the partners, one sequence per kind
    indexed by the partner's number: state.Walls.partner_names)."""
    return f"sphere {other}" if PARTNER_IS_SPHERE[kind] else f"{KIND_NAMES[kind]} {names[kind][other]}"


def overlap_words(parties: tuple[int, int, int] | None, names) -> str:
    """Who overlaps, in words: "spheres 3 and 4", "sphere 3 and mesh 'trough' triangle 1"
    (parties: (kind, sphere, partner) as StepEnd.overlap_with; None: "spheres")."""
    if parties is None:
        return "spheres"
    kind, a, other = parties
    return parties_words(kind, a, other, partner_words(kind, other, names))


def parties_words(kind: int, a: int, other: int, partner_name: str) -> str:
    """"spheres 3 and 4" or "sphere 3 and <partner_name>" (partner_words' name of the partner)."""
    return f"spheres {a} and {other}" if PARTNER_IS_SPHERE[kind] else f"sphere {a} and {partner_name}"


def contact_words(kind: int, a: int, other: int, names) -> str:
    """How reports name a contact in few words: "3–4" (a sphere pair), "3–wall 'floor'"."""
    return f"{a}–{other}" if PARTNER_IS_SPHERE[kind] else f"{a}–{partner_words(kind, other, names)}"

# how a contact was resolved (Contacts.how; the recording's contacts ``how`` column)
HOW_IMPULSE = 0  # the seed's impulse (or reflection), alone
HOW_RESTING = 1  # held by the resting rule, restitution 0
HOW_RAPID = 2  # held by the rapid-contact (TC) rule, restitution 0
HOW_WITH_HELD = 3  # an impulse solved together with the held contacts it reached
HOW_AT_ONE_INSTANT = 4  # an impulse solved together with the sphere's other contacts at that instant

# Outcomes of one swept test (SweptTests.outcome).
OUTCOME_MISS = 0  # no contact before the end of the step
OUTCOME_HIT = 1  # the predicted contact was resolved
OUTCOME_SUPERSEDED = 2  # a contact was predicted, but an earlier one changed a path first
OUTCOME_CAPPED = 3  # predicted, but the per-step contact cap (max_contacts_per_step) stopped the step first
OUTCOME_NAMES = ("miss", "hit", "superseded", "capped")


@dataclass(frozen=True)
class StepBegin:
    """A step is about to run.

    step: the step's number (from 1; module doc); time: simulated time at its start (s);
    dt: its length (s), exactly as used (kept so a real-time run can be repeated).
    """

    step: int
    time: float
    dt: float


@dataclass(frozen=True)
class BroadPhaseInfo:
    """The broad phase of one step: which structure, why, how it did, and its nodes.

    name: e.g. "grid", "bvh-sah"; reason: why it was chosen; stats: numbers such as
    build_seconds, query_seconds, nodes_visited, box_tests, sah_cost, rebuilt, pairs.
    nodes: for BVHs, arrays of length M: lo, hi (M, 3) bounds (m) of the swept boxes;
    left, right, parent (-1 = none); depth; start, count (range in ``order``); order: the
    particle index of each leaf slot. None for structures without nodes.
    """

    step: int
    name: str
    reason: str
    stats: dict
    nodes: dict[str, np.ndarray] | None


@dataclass(frozen=True)
class ContactResolved:
    """One contact (a row of :class:`Contacts`), resolved at ``time_in_step`` seconds after the step began.

    kind: a collider kind (KIND_NAMES): KIND_PAIR (``other`` is particle b) or KIND_WALL
    (``other`` is the wall index).
    order: 0-based position among this step's contacts.
    point: (3,) contact point on the surface of ``a``; normal: (3,) unit, from b (or the
    wall) towards a. impulse: j (N·s) applied along ``normal`` to ``a`` (and -j to b);
    for a wall it is m_a times the change of normal speed (inf for an immovable sphere).
    velocity_*: (3,) m/s just before and after (b's: None for a partner standing still,
    a kinematic mesh's surface velocity at the point). restitution: the combined coefficient
    used; resting: True when the contact was held (restitution 0: the resting rule or
    the rapid-contact rule). closing_speed: normal approach speed before the contact
    (m/s, >= 0). how: HOW_IMPULSE (the seed's impulse alone), HOW_RESTING, HOW_RAPID
    (held by that rule), HOW_WITH_HELD (an impulse solved together with the held
    contacts it reached, which also moved other spheres) or HOW_AT_ONE_INSTANT (an impulse
    solved together with the sphere's other contacts with immovable partners at the same
    instant, and the held contacts they reached: resolve.resolve_at_one_instant). feature: for a mesh's triangle,
    1 + the index in FEATURE_NAMES of where it was touched (face, edge, corner); else 0.
    """

    step: int
    order: int
    time_in_step: float
    kind: int
    a: int
    other: int
    point: np.ndarray
    normal: np.ndarray
    impulse: float
    velocity_a_before: np.ndarray
    velocity_a_after: np.ndarray
    velocity_b_before: np.ndarray | None
    velocity_b_after: np.ndarray | None
    restitution: float
    closing_speed: float
    resting: bool
    how: int = 0
    feature: int = 0


# The contact row: one schema for the compiled loop's buffer, the Contacts event and the
# recording's /physdbg/contacts table (format.py takes this list as it is). Packed, so the
# row is the same bytes whatever the platform's alignment. (name, numpy kind, shape):
CONTACT_FIELDS = [
    ("time_in_step", "<f8", ()), ("kind", "i1", ()), ("how", "i1", ()), ("a", "<i4", ()), ("other", "<i4", ()),
    ("point", "<f8", (3,)), ("normal", "<f8", (3,)), ("impulse", "<f8", ()),
    ("velocity_a_before", "<f8", (3,)), ("velocity_a_after", "<f8", (3,)),
    ("velocity_b_before", "<f8", (3,)), ("velocity_b_after", "<f8", (3,)),
    ("restitution", "<f8", ()), ("closing_speed", "<f8", ()),
    # the feature of a mesh's triangle touched: 0 for any other partner (and in files made
    # before it was kept), else 1 + its index in FEATURE_NAMES
    ("feature", "i1", ()),
]
# a triangle's features (engine/mesh/closest.py's codes): where a sphere touches it
FEATURE_NAMES = ("face", "edge 0-1", "edge 1-2", "edge 2-0", "corner 0", "corner 1", "corner 2")


def feature_words(feature: int) -> str:
    """A contact row's feature in words: "" for none, else "face", "edge 1-2", "corner 0"."""
    return FEATURE_NAMES[feature - 1] if 0 < feature <= len(FEATURE_NAMES) else ""
CONTACT_ROW = np.dtype([(name, kind, shape) if shape else (name, kind) for name, kind, shape in CONTACT_FIELDS])


def _column(name: str):
    return property(lambda self: self.rows[name], doc=f"the ``{name}`` column of ``rows`` (a view)")


@dataclass(frozen=True)
class Contacts:
    """Every contact resolved during one step, in the order they were resolved (row i is
    contact ``order`` i). Box2D-style buffered events: one object per step however many
    contacts, so observing stays cheap.

    rows: (M,) structured array of :data:`CONTACT_ROW`, the very rows the compiled loop
    wrote (a copy). Each field is also an attribute, a view of its column:
    time_in_step: (M,) s; kind: (M,) int8; a, other: (M,) int32; point, normal,
    velocity_a_before, velocity_a_after: (M, 3); velocity_b_before/after: (M, 3), NaN rows
    for walls and fixed meshes, a kinematic mesh's surface velocity at the point; impulse,
    restitution, closing_speed: (M,); how: (M,) int8 HOW_*; feature: (M,) int8 (a mesh
    triangle's face, edge or corner touched: feature_words). resting:
    (M,) bool, derived from ``how`` (held by the resting or the rapid-contact rule).
    Meanings as in :class:`ContactResolved`; ``record(i)`` or iteration gives one contact
    as that type.
    """

    step: int
    rows: np.ndarray

    def __post_init__(self) -> None:
        if self.rows.dtype != CONTACT_ROW:
            raise TypeError(f"Contacts.rows must have dtype CONTACT_ROW, not {self.rows.dtype}")

    time_in_step = _column("time_in_step")
    kind = _column("kind")
    how = _column("how")
    a = _column("a")
    other = _column("other")
    point = _column("point")
    normal = _column("normal")
    impulse = _column("impulse")
    velocity_a_before = _column("velocity_a_before")
    velocity_a_after = _column("velocity_a_after")
    velocity_b_before = _column("velocity_b_before")
    velocity_b_after = _column("velocity_b_after")
    restitution = _column("restitution")
    closing_speed = _column("closing_speed")
    feature = _column("feature")

    @property
    def resting(self) -> np.ndarray:
        """(M,) bool: held with restitution 0 (HOW_RESTING or HOW_RAPID)."""
        return (self.how == HOW_RESTING) | (self.how == HOW_RAPID)

    @classmethod
    def empty(cls, step: int, count: int = 0) -> Contacts:
        """``count`` zeroed rows (to fill column by column: tests, importers)."""
        return cls(step, np.zeros(count, CONTACT_ROW))

    def first(self, count: int) -> Contacts:
        """The first ``count`` contacts (all of them when there are fewer)."""
        return self if len(self) <= count else Contacts(self.step, self.rows[:count])

    def __len__(self) -> int:
        return len(self.rows)

    def record(self, i: int) -> ContactResolved:
        r = self.rows[i]
        # a sphere partner's velocities, or a kinematic mesh's surface's (a fixed one's are NaN)
        moves = PARTNER_IS_SPHERE[int(r["kind"])] or bool(np.isfinite(r["velocity_b_before"]).all())
        how = int(r["how"])
        return ContactResolved(
            self.step, i, float(r["time_in_step"]), int(r["kind"]), int(r["a"]), int(r["other"]),
            r["point"].copy(), r["normal"].copy(), float(r["impulse"]),
            r["velocity_a_before"].copy(), r["velocity_a_after"].copy(),
            r["velocity_b_before"].copy() if moves else None, r["velocity_b_after"].copy() if moves else None,
            float(r["restitution"]), float(r["closing_speed"]), how in (HOW_RESTING, HOW_RAPID), how,
            int(r["feature"]))

    def __iter__(self):
        return (self.record(i) for i in range(len(self)))


class CollisionSums(NamedTuple):
    """What a step's contacts add to the equation of state: virial (J·s), wall_impulse
    (N·s) and collisions (sphere–sphere contacts)."""

    virial: float
    wall_impulse: float
    collisions: int


NO_COLLISIONS = CollisionSums(0.0, 0.0, 0)


def collision_sums(contacts: Contacts, radius: np.ndarray) -> CollisionSums:
    """The sums of a step's contacts: over sphere pairs r_ab · J_a = (r_a + r_b) j (J·s;
    r_ab from b to a at contact, J_a = j n the impulse on a), the impulses on spheres at
    walls (N·s), and the number of sphere–sphere contacts. Over a time T, the collisional
    virial gives PV = N kT + sum / (3 T), the wall impulses P = sum / (area T)."""
    if not len(contacts):
        return NO_COLLISIONS
    pair = partner_is_sphere(contacts.kind)
    wall = contacts.kind == KIND_WALL  # the box's walls: what the pressure on them is measured from
    impulse = np.nan_to_num(contacts.impulse, nan=0.0)
    reach = radius[contacts.a[pair]] + radius[contacts.other[pair]]
    return CollisionSums(float(reach @ impulse[pair]), float(impulse[wall].sum()), int(np.count_nonzero(pair)))


@dataclass(frozen=True)
class SweptTests:
    """Every narrow-phase test run during one step, as parallel arrays of length M.

    kind: (M,) int8 KIND_PAIR / KIND_WALL; a, other: (M,) int32 particle, and particle or
    wall index; start: (M,) time in the step the test started from (s); toi: (M,) predicted
    time of impact in the step (s, NaN when none); outcome: (M,) int8 OUTCOME_*.
    """

    step: int
    kind: np.ndarray
    a: np.ndarray
    other: np.ndarray
    start: np.ndarray
    toi: np.ndarray
    outcome: np.ndarray

    def __len__(self) -> int:
        return len(self.kind)


# outcome of a node visited by a walk of a mesh's tree (MeshSearch.outcome)
SEARCH_MET = 0  # the box met the node's box: the walk went down into it
SEARCH_CULLED = 1  # it did not: the branch ended there
SEARCH_REACHED = 2  # it met a leaf's box: that triangle was tested (unless a held contact)
SEARCH_OUTCOME_NAMES = ("met", "culled", "reached")


@dataclass(frozen=True)
class MeshSearch:
    """Every walk of the meshes' trees (the seed's "search tree that records descent into
    each BVH") in one step of a scene with meshes, as the engine made them.

    A *query* is a box the engine asked every mesh's tree with: each sphere's path box at
    the step's start (``after`` -1), and again each time a contact changed a sphere's path
    (``after``: the row in the step's Contacts of the contact after which it asked).
    query_sphere (J,) int32, query_after (J,) int32, query_lo, query_hi (J, 3) m: the box
    in the world frame (each mesh's walk carries it into the mesh's frame, grown by the
    mesh's motion over the step: engine/colliders/mesh.frame_box).

    A *visit* is one node of one tree visited by one query's walk, in the order walked:
    visit_query (V,) int32 (the query's row), visit_node (V,) int32 (the node: a position in
    the meshes' trees laid out in pre-order one after another, as the recording's mesh-tree
    channel numbers them), visit_outcome (V,) int8 (SEARCH_MET, SEARCH_CULLED,
    SEARCH_REACHED), visit_parent (V,) int32 (the row of the visit it was reached from;
    -1 for a tree's root). Built only for an observer that reads it (``wants_mesh_search``).
    """

    step: int
    query_sphere: np.ndarray
    query_after: np.ndarray
    query_lo: np.ndarray
    query_hi: np.ndarray
    visit_query: np.ndarray
    visit_node: np.ndarray
    visit_outcome: np.ndarray
    visit_parent: np.ndarray

    def __len__(self) -> int:
        return len(self.visit_node)


@dataclass(frozen=True)
class EngineWarning:
    """Something the user should know about a step: code, a stable identifier (a budget's
    setting name, overlap, non-finite, pinned, periodic, max_memory); message, one
    sentence; bodies, the spheres it is about (scene numbering), where it is about some."""

    step: int
    code: str
    message: str
    bodies: tuple[int, ...] = ()


# the step pipeline's phases, in order (engine/world.py runs and times each; StepEnd.timings,
# the run summary's shares and the recording's seconds_* columns are named by these)
STEP_PHASES = ("forces", "broad_phase", "narrow_phase", "resolve", "finish")


@dataclass(frozen=True)
class StepCounts:
    """What one step did, counted (each also a column of the recording's /physdbg/stats).

    contacts: contacts resolved; swept_tests: swept tests run; events: pops of the event
    queue; held: contacts held at the step's end (resting or rapid, resting/); rapid:
    contacts the rapid-contact rule held in the step; released: held contacts let go in
    the step; asleep: spheres asleep at the step's end; slept, woken: spheres that fell
    asleep, woke in the step (sleep.py).
    """

    contacts: int = 0
    swept_tests: int = 0
    events: int = 0
    held: int = 0
    rapid: int = 0
    released: int = 0
    asleep: int = 0
    slept: int = 0
    woken: int = 0


STEP_COUNTS = tuple(StepCounts.__dataclass_fields__)
# counts that say how things are at the step's end (a run reports the last); the others
# say what happened in the step (a run adds them up)
COUNTS_AT_END = ("held", "asleep")


@dataclass(frozen=True)
class StepEnd:
    """A step has finished: the one record of a step, sent to the observer and returned by
    ``World.step`` alike (a recording gives back the same record).

    positions, velocities: (N, 3) state at ``time`` (copies). kinetic, potential: J
    (potential is -m·g_i·x relative to the origin); momentum: (3,) kg·m/s over movable
    particles. counts: StepCounts. max_overlap: deepest sphere–sphere or sphere–wall
    penetration after the step (m, 0 when none). timings: seconds per phase (STEP_PHASES).
    state_hash: hex digest over the exact bytes of positions and velocities. warnings:
    the step's EngineWarning events. asleep: (N,) bool, the spheres asleep at ``time``
    (engine/sleep.py), or None when the run does not let spheres sleep. overlap_with:
    (kind, sphere, partner) of max_overlap, in the scene's numbering (None when nothing
    overlaps, and in a run read back from a recording, which keeps only the depth).
    """

    step: int
    time: float
    dt: float
    positions: np.ndarray
    velocities: np.ndarray
    kinetic: float
    potential: float
    momentum: np.ndarray
    counts: StepCounts
    max_overlap: float
    timings: dict[str, float]
    state_hash: str
    warnings: tuple[EngineWarning, ...] = field(default=())
    asleep: np.ndarray | None = None
    overlap_with: tuple[int, int, int] | None = None


class RunTally:
    """A run's counts, step by step: ``total`` adds up what happened in each step
    (COUNTS_AT_END keep the last step's), ``most`` is the largest of each in one step,
    ``seconds`` the time spent in each phase."""

    def __init__(self):
        self.steps = 0
        self.total = dict.fromkeys(STEP_COUNTS, 0)
        self.most = dict.fromkeys(STEP_COUNTS, 0)
        self.seconds = dict.fromkeys(STEP_PHASES, 0.0)
        self.max_overlap = 0.0
        self.overlap_with = None  # (kind, sphere, partner) of the deepest overlap, where known
        self.overlap_step = 0

    def add(self, end: StepEnd) -> None:
        self.steps += 1
        for name in STEP_COUNTS:
            value = getattr(end.counts, name)
            self.total[name] = value if name in COUNTS_AT_END else self.total[name] + value
            self.most[name] = max(self.most[name], value)
        for name, seconds in end.timings.items():
            self.seconds[name] = self.seconds.get(name, 0.0) + seconds
        if end.max_overlap > self.max_overlap:
            self.max_overlap = end.max_overlap
            self.overlap_with = end.overlap_with
            self.overlap_step = end.step


Event = StepBegin | BroadPhaseInfo | Contacts | SweptTests | MeshSearch | EngineWarning | StepEnd
