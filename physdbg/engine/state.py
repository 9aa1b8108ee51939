"""The world's data: particle state as a structure of arrays, walls, engine settings.

Nothing here knows about files: :mod:`physdbg.scene` builds these from TOML.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field

import numpy as np

from ..events import KIND_NAMES
from .jit import kernel
from .motion import INTEGRATOR_NAMES
from .toi import DETECTION_NAMES
from ..errors import NonFiniteState  # noqa: F401 (raised here; every exception lives in errors.py)

ORDERING_NAMES = ("time", "index")

# the default contact budget of a step (Settings.contact_cap), and of swept tests
# (Settings.swept_test_budget). A settling bed under the rain scene's rules rattles before
# it sleeps: `physdbg run rain -s generate.count=10000 -s generate.radius=0.02` (dt 1/120)
# needs up to 62 contacts and 1 280 swept tests a sphere in a step: under 20 and 400 every
# step from step 49 on was stopped and spheres were left 6 mm inside each other; under
# these it is exact and asleep by step 185 (docs/benchmarks.md, "Budgets")
MIN_CONTACT_CAP = 10_000
CONTACTS_PER_SPHERE = 100
MIN_SWEPT_TESTS = 10_000_000
SWEPT_TESTS_PER_SPHERE = 2_000

# Estimated bytes of memory per particle while stepping, before the step's growable buffers
# (state, swept boxes, candidate pairs, the per-sphere arrays of the loop): what a scene is
# refused by before it starts (scene.py) and what World.step counts besides its buffers
# when it holds them to max_memory. Box-rain peaks at ~1.7 KiB at 10k and ~1 KiB at 100k
# (peak RSS over the start); twice that leaves room.
BYTES_PER_PARTICLE = 4096
DEFAULT_MAX_MEMORY = 4e9

# The held-contact solve's budget of a step (Settings.max_resting_work_per_step = 0, sized):
# with rapid_contact_rule = "hold" the jammed steps of `physdbg run rain -s
# generate.count=500 -s rapid_contact_rule=hold -s sleep_speed=0` need up to 2.5·10⁸
# updates (5·10⁵ a sphere); with today's defaults (TC rule and sleeping in a pile) 23,000.
# A fixed 10⁹ let 20 spheres at 10⁶ m/s spend 10 s a step in hopeless solves (~10 ns an
# update); sized, they get 2·10⁷ (0.2 s), and no scene more than 10⁹ (docs/benchmarks.md, "Budgets").
MIN_RESTING_WORK = 10_000_000
RESTING_WORK_PER_SPHERE = 1_000_000
MAX_RESTING_WORK = 1_000_000_000

# The budgets whose 0 (their default) means "sized to the scene's sphere count" (budget_value).
SIZED_BUDGETS = ("max_contacts_per_step", "max_swept_tests_per_step", "max_resting_work_per_step")

# settings renamed (old name -> name now): a scene or recording made before still says the
# old one, which is read as the new (max_events_per_step counted contacts, not events)
RENAMED_SETTINGS = {"max_events_per_step": "max_contacts_per_step"}

# The work budgets of one step (Settings fields), each with what it counts and what
# happens to the rest of the step when it is reached.
BUDGETS = {
    "max_contacts_per_step": ("contacts resolved", "the remaining contacts of the step were not resolved"),
    "max_pairs_per_step": ("broad-phase candidate pairs",
                           "sphere–sphere contacts were not tested in this step (spheres may pass through "
                           "or overlap each other); usually dt is too long for the speeds, or spheres overlap"),
    "max_swept_tests_per_step": ("swept tests", "the remaining contacts of the step were not resolved"),
    "max_resting_work_per_step": ("held-contact solve updates",
                                  "the remaining contacts of the step were not resolved"),
}


def budget_message(budget: str, value: int) -> str:
    """What a warning says when a budget stopped a step: which, what happened, what to change."""
    counts, consequence = BUDGETS[budget]
    return (f"{budget} reached ({value} {counts}); {consequence}; raise it with --set {budget}=N "
            f"if the scene really needs more")


# Settings.event_loop's choices
EVENT_LOOP_NAMES = ("step", "calendar")
# settings a scene may give as "auto": the advisor (physdbg.advisor.decide) replaces each by
# a value before a World is built; the engine itself never decides
AUTO_SETTINGS = ("integrator", "detection", "ordering", "rapid_contact_time", "rapid_contact_rule", "sleep_speed")
# the rapid-contact rule's window (s) where it is on: a pile forms (advisor.resolve_pile_rules)
# or a scene gives it; a tenth of a millisecond holds a sphere squeezed between two
RAPID_CONTACT_TIME = 1e-4


@dataclass
class Settings:
    """How the engine steps. Units: s, m, m/s, m/s².

    integrator: one of motion.INTEGRATOR_NAMES; detection: one of toi.DETECTION_NAMES;
    samples: k for ``sampled``; ordering: ``time`` or ``index``; gravity: (3,) m/s²;
    drag: d in v·d^t, in (0, 1] (1 = none); restitution_rule: see resolve.py;
    rest_fraction: a pressed contact rests when its closing speed is at most this fraction
    of |a_n|·dt (resting/); rapid_contact_time: a contact with restitution < 1 this soon
    (s) after either sphere's previous one is held like a resting one if something presses
    it, else elastic (resting/, 0 = off); rapid_contact_rule: "hold" holds such a pressed
    contact at any speed, "tc" only a slow one (resting.rapid_holds);
    contact_tolerance: allowed overlap / resting gap (m); sleep_speed: a sphere at most
    this fast (m/s) for sleep_time (s) falls asleep, immovable until disturbed (sleep.py;
    0 = off, the default); space_order: the world's own numbering of the spheres,
    "auto", "given" or "morton" (space_order.py: only speed and the order of work that
    is otherwise a tie depend on it; everything the world reports is in the scene's
    numbering); mesh_search: how each step's candidates against the meshes are found,
    "walk" (one walk of each mesh's tree per sphere), "together" (the spheres' tree and
    each mesh's descended together) or "auto" (the world picks each step by counted work:
    World._choose_mesh_search); the same candidates, so the same states, either way.
    event_loop: "step" (every step boxes, pairs and predicts its paths again: timeline.py)
    or "calendar" (predictions kept across steps where paths are straight between
    contacts: calendar.py; the world says in which steps it could not, and why).

    max_memory (bytes): the particles' own memory (BYTES_PER_PARTICLE each) and the step's
    growable buffers (event queue, swept-test log, contact rows, held contacts) may not
    pass it; a step whose buffers would is stopped like a budget (warning "max_memory").
    Budgets bound the work of one step (see BUDGETS); when one is reached the step still
    finishes, and a warning names the budget. max_contacts_per_step = 0 and
    max_swept_tests_per_step = 0 (the defaults) are sized to the scene: see ``contact_cap``
    and ``swept_test_budget``.
    """

    integrator: str = "exact"
    detection: str = "swept"
    samples: int = 4
    ordering: str = "time"
    broad_phase: str = "auto"
    gravity: tuple[float, float, float] = (0.0, -9.81, 0.0)
    drag: float = 1.0
    restitution_rule: str = "min"
    rest_fraction: float = 0.01
    rapid_contact_time: float = RAPID_CONTACT_TIME
    rapid_contact_rule: str = "hold"
    contact_tolerance: float = 1e-9
    sleep_speed: float = 0.0
    sleep_time: float = 0.5
    max_contacts_per_step: int = 0
    max_pairs_per_step: int = 10_000_000
    max_swept_tests_per_step: int = 0
    max_resting_work_per_step: int = 0  # sized: MIN_RESTING_WORK .. MAX_RESTING_WORK, per sphere
    max_memory: float = DEFAULT_MAX_MEMORY
    space_order: str = "auto"
    mesh_search: str = "auto"
    event_loop: str = "step"

    def contact_cap(self, spheres: int) -> int:
        """The contact budget of one step for this many spheres: max_contacts_per_step, or
        when it is 0, max(MIN_CONTACT_CAP, CONTACTS_PER_SPHERE × spheres) — a settling pile
        of N spheres legitimately resolves a few contacts per sphere in a step, so a fixed
        cap that suits 100 spheres stops every step of a pile of 10 000."""
        return self.budget("max_contacts_per_step", spheres)

    def swept_test_budget(self, spheres: int) -> int:
        """The swept-test budget of one step for this many spheres: max_swept_tests_per_step,
        or when it is 0, max(MIN_SWEPT_TESTS, SWEPT_TESTS_PER_SPHERE × spheres) (the same
        reason as contact_cap)."""
        return self.budget("max_swept_tests_per_step", spheres)

    def budget(self, name: str, spheres: int) -> int:
        """The value budget ``name`` (a BUDGETS key) takes in a world of this many spheres."""
        return budget_value(name, getattr(self, name), spheres)

    def undecided(self) -> list[str]:
        """The settings still "auto" (AUTO_SETTINGS): a World refuses them."""
        return [name for name in AUTO_SETTINGS if getattr(self, name) == "auto"]

    @property
    def integrator_code(self) -> int:
        return INTEGRATOR_NAMES.index(self.integrator)

    @property
    def detection_code(self) -> int:
        return DETECTION_NAMES.index(self.detection)


@dataclass
class Meshes:
    """Triangle meshes, in the world frame (the immovable partners of kind mesh).

    names (M,) and restitution (M,) per mesh; corners (T, 3, 3) m: every triangle's
    corners as rows at run time 0, the meshes' triangles one after another; mesh_of (T,)
    int64: whose each is; first (M + 1,) int64: where each mesh's triangles start (and the
    end); sources (M,): the file or "shape NAME" each came from; notes: what loading them
    left out (degenerate triangles, by line), for the run summary.

    A mesh may move by a prescribed rigid motion (it is kinematic: immovable by any
    contact, the seed's inverse mass 0, but carried along): velocity (M, 3) m/s, the
    pivot's, and angular_velocity (M, 3) rad/s about its pivot (M, 3) m (where the pivot
    is at run time 0). At run time t a corner c is at R(ω·t)(c - pivot) + pivot + v·t
    (``placed``): the closed form, so a pose never accumulates rounding.

    bounding_volume (M,): the volume each mesh's tree is walked with ("aabb", "sphere",
    "obb"; "auto" until the advisor decides: ``volumes``); none: "aabb" for every mesh.
    """

    names: list[str] = field(default_factory=list)
    restitution: np.ndarray = field(default_factory=lambda: np.zeros(0))
    corners: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 3)))
    mesh_of: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    sources: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    velocity: np.ndarray | None = None
    angular_velocity: np.ndarray | None = None
    pivot: np.ndarray | None = None
    bounding_volume: list[str] | None = None
    _mesh_set: object = field(default=None, init=False, repr=False, compare=False)  # mesh_set, once built

    def __post_init__(self) -> None:
        self.corners = np.ascontiguousarray(self.corners, dtype=np.float64).reshape(-1, 3, 3)
        self.mesh_of = np.ascontiguousarray(self.mesh_of, dtype=np.int64).reshape(-1)
        self.restitution = np.ascontiguousarray(self.restitution, dtype=np.float64).reshape(-1)
        m = len(self.names)
        for name in ("velocity", "angular_velocity", "pivot"):
            value = getattr(self, name)
            value = np.zeros((m, 3)) if value is None else np.asarray(value, dtype=np.float64).reshape(m, 3)
            setattr(self, name, np.ascontiguousarray(value))
        if self.bounding_volume is None:
            self.bounding_volume = ["aabb"] * m

    @property
    def mesh_set(self):
        """Every mesh's tree (engine/mesh/mesh_set.MeshSet), built at the first ask and kept:
        the one build of the trees that the engine, the advisor, the audit, the recording
        and the views all read (the corners at run time 0 never change)."""
        if self._mesh_set is None:
            from .mesh.mesh_set import MeshSet

            self._mesh_set = MeshSet(self)
        return self._mesh_set

    def volumes(self) -> list[str]:
        """Each mesh's walked volume; ValueError while one is still "auto" (a World needs
        the advisor's choice: advisor.decide)."""
        if "auto" in self.bounding_volume:
            raise ValueError("a mesh's bounding_volume is still auto: decide it first (physdbg.advisor.decide, "
                             "which api.load_scene calls)")
        return list(self.bounding_volume)

    @property
    def moving(self) -> np.ndarray:
        """(M,) bool: the meshes with a prescribed motion (kinematic)."""
        return np.any(self.velocity != 0.0, axis=1) | np.any(self.angular_velocity != 0.0, axis=1)

    def rotations(self, time: float) -> np.ndarray:
        """(M, 3, 3): each mesh's turn R(ω·time) since run time 0 (mesh.rigid_motion)."""
        from .mesh.rigid_motion import rotation_about

        return np.stack([rotation_about(w, time) for w in self.angular_velocity]) if len(self) else np.zeros((0, 3, 3))

    def placed(self, time: float) -> tuple[np.ndarray, np.ndarray]:
        """(corners (T, 3, 3), pivots (M, 3)) m at run time ``time`` s (the closed form of
        the class doc, mesh.rigid_motion.placed; a fixed mesh's corners are its own, bit for bit)."""
        from .mesh.rigid_motion import placed

        corners = self.corners.copy()
        pivots = self.pivot + self.velocity * time
        for k in np.nonzero(self.moving)[0]:
            rows = self.mesh_of == k
            corners[rows] = placed(self.corners[rows], self.pivot[k], self.velocity[k], self.angular_velocity[k], time)
        return corners, pivots

    def surface_velocity(self, k: int, point, time: float) -> np.ndarray:
        """(3,) m/s: the velocity at run time ``time`` of mesh k's surface at world
        ``point`` (3,): v + ω × (point - pivot(time)) (mesh.rigid_motion)."""
        from .mesh.rigid_motion import surface_velocity_at

        return surface_velocity_at(point, self.pivot[k], self.velocity[k], self.angular_velocity[k], time)

    def transform(self, k: int, time: float) -> tuple[np.ndarray, np.ndarray]:
        """(rotation (3, 3), translation (3,)) that carries mesh k's run-time-0 corners c
        to where they are at ``time``: R·c + translation (the views' per-step transform)."""
        from .mesh.rigid_motion import transform

        return transform(self.pivot[k], self.velocity[k], self.angular_velocity[k], time)

    def turn_radii(self) -> np.ndarray:
        """(M,) m: how far each mesh's farthest corner is from its pivot at run time 0."""
        out = np.zeros(len(self))
        for k in range(len(self)):
            rows = self.corners[self.mesh_of == k].reshape(-1, 3)
            if len(rows):
                out[k] = float(np.linalg.norm(rows - self.pivot[k], axis=1).max())
        return out

    def surface_speeds(self) -> np.ndarray:
        """(M,) m/s: the fastest any point of each mesh moves, |v| + |ω|·(its turn radius)
        (0 for a fixed mesh)."""
        return np.linalg.norm(self.velocity, axis=1) + np.linalg.norm(self.angular_velocity, axis=1) * self.turn_radii()

    def motion_words(self, k: int) -> str:
        """How mesh k moves, as the run summary says it ("" when fixed)."""
        if not self.moving[k]:
            return ""
        parts = []
        if np.any(self.velocity[k]):
            parts.append(f"moves at {np.linalg.norm(self.velocity[k]):.3g} m/s")
        if np.any(self.angular_velocity[k]):
            spin = np.linalg.norm(self.angular_velocity[k])
            parts.append(f"turns at {np.degrees(spin):.4g} deg/s ({spin / (2 * np.pi):.3g} rev/s) about "
                         f"[{', '.join(f'{q:g}' for q in self.pivot[k])}]")
        return " and ".join(parts)

    def __len__(self) -> int:
        return len(self.names)

    @property
    def triangles(self) -> int:
        return int(self.corners.shape[0])

    @property
    def first(self) -> np.ndarray:
        """(M + 1,) int64: where each mesh's triangles start in ``corners`` (and the end)."""
        return np.searchsorted(self.mesh_of, np.arange(len(self.names) + 1)).astype(np.int64)

    def triangle_words(self, t: int) -> str:
        """A triangle as reports name it: "'ramp' triangle 3" (its number in its own mesh)."""
        mesh = int(self.mesh_of[t])
        return f"'{self.names[mesh]}' triangle {t - int(self.first[mesh])}"


class _Numbered:
    """A kind's partners named by number alone ("#3"): a kind with no names of its own."""

    def __getitem__(self, other: int) -> str:
        return f"#{int(other)}"


class _TriangleNames:
    """Meshes.triangle_words as a sequence (partner_names' entry for kind mesh)."""

    def __init__(self, meshes: Meshes):
        self._meshes = meshes

    def __getitem__(self, t: int) -> str:
        return self._meshes.triangle_words(int(t))

    def __len__(self) -> int:
        return self._meshes.triangles


@dataclass
class Partners:
    """The partners of one collider kind whose module declares its scene fields (FIELDS:
    a kind beyond the sphere, the wall and the mesh; docs/colliders.md): their names and
    one array per declared field, one row per partner (float64, shape (P, *field.shape))."""

    names: list[str] = field(default_factory=list)
    fields: dict[str, np.ndarray] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.names)

    @classmethod
    def empty(cls, declared) -> Partners:
        """No partners, with every declared field (kinds.Field rows) as an empty array."""
        return cls([], {f.name: np.zeros((0, *f.shape)) for f in declared})


@dataclass
class Walls:
    """The immovable geometry: W planes n·x = d (arrays of length W; normals (W, 3) unit)
    and the fixed meshes (``meshes``, a Meshes).

    One-sided walls keep spheres where n·x - d >= r; two-sided walls are thin slabs of
    ``thickness`` centred on the plane that spheres bounce off from either side.

    period, period_origin: (3,) m: an axis with period L > 0 is periodic, spheres leaving
    [origin, origin + L) come back on the other side and pairs meet through the minimum
    image (periodic.py); 0 = not periodic. No wall's normal may have a component along
    a periodic axis.
    """

    names: list[str] = field(default_factory=list)
    normals: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    offsets: np.ndarray = field(default_factory=lambda: np.zeros(0))
    restitution: np.ndarray = field(default_factory=lambda: np.zeros(0))
    two_sided: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.bool_))
    thickness: np.ndarray = field(default_factory=lambda: np.zeros(0))
    period: np.ndarray = field(default_factory=lambda: np.zeros(3))
    period_origin: np.ndarray = field(default_factory=lambda: np.zeros(3))
    meshes: Meshes = field(default_factory=Meshes)
    # the partners of each kind whose module declares scene fields, by the kind's name
    # (events.COLLIDER_KINDS); a kind with none is absent
    partners: dict[str, Partners] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.period = np.ascontiguousarray(self.period, dtype=np.float64).reshape(3)
        self.period_origin = np.ascontiguousarray(self.period_origin, dtype=np.float64).reshape(3)

    def __len__(self) -> int:
        return len(self.names)

    def partner_names(self) -> tuple:
        """How reports name each kind's partners, one sequence per kind in the kinds' order
        (events.partner_words): the walls' quoted names, the meshes' triangles ("'ramp'
        triangle 3"), and numbers ("#3") for a kind without names (spheres are named by
        events.partner_words itself)."""
        named = {"wall": [f"'{name}'" for name in self.names], "mesh": _TriangleNames(self.meshes),
                 **{kind: [f"'{name}'" for name in partners.names] for kind, partners in self.partners.items()}}
        return tuple(named.get(kind, _Numbered()) for kind in KIND_NAMES)

    @property
    def periodic(self) -> bool:
        """Is any axis periodic?"""
        return bool(np.any(self.period > 0))

    def box(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(lo, hi) (3,) m of the axis-aligned box on each axis periodic or closed by
        one-sided walls, one facing in on each side, or None."""
        lo, hi = np.full(3, np.nan), np.full(3, np.nan)
        periodic = self.period > 0
        lo[periodic] = self.period_origin[periodic]
        hi[periodic] = self.period_origin[periodic] + self.period[periodic]
        for normal, offset, two in zip(self.normals, self.offsets, self.two_sided, strict=True):
            axis = int(np.argmax(np.abs(normal)))
            if two or abs(abs(normal[axis]) - 1) > 1e-12:
                continue
            if normal[axis] > 0:
                lo[axis] = offset
            else:
                hi[axis] = -offset
        if np.any(np.isnan(lo)) or np.any(np.isnan(hi)) or np.any(hi <= lo):
            return None
        return lo, hi


# State's per-sphere arrays, in its order
STATE_FIELDS = ("positions", "velocities", "inverse_mass", "radius", "restitution", "gravity_scale")


@dataclass
class State:
    """Particles as arrays. positions, velocities: (N, 3) m, m/s; inverse_mass: (N,) 1/kg
    (0 = immovable); radius: (N,) m; restitution: (N,); gravity_scale: (N,)."""

    positions: np.ndarray
    velocities: np.ndarray
    inverse_mass: np.ndarray
    radius: np.ndarray
    restitution: np.ndarray
    gravity_scale: np.ndarray

    def __post_init__(self) -> None:
        self.positions = np.ascontiguousarray(self.positions, dtype=np.float64).reshape(-1, 3)
        self.velocities = np.ascontiguousarray(self.velocities, dtype=np.float64).reshape(-1, 3)
        for name in ("inverse_mass", "radius", "restitution", "gravity_scale"):
            setattr(self, name, np.ascontiguousarray(getattr(self, name), dtype=np.float64).reshape(-1))

    @property
    def count(self) -> int:
        return self.positions.shape[0]

    def copy(self) -> "State":
        return State(self.positions.copy(), self.velocities.copy(), self.inverse_mass.copy(),
                     self.radius.copy(), self.restitution.copy(), self.gravity_scale.copy())





def first_non_finite(positions: np.ndarray, velocities: np.ndarray) -> tuple[int, str, int] | None:
    """(first particle, "position" or "velocity", how many) whose state is not finite, or None."""
    # fast path, every step: a sum is finite when no entry is NaN or infinite (or, with
    # finite entries that overflow the sum, the exact check below finds nothing); compiled,
    # one pass: 2 µs at 1 000 particles (numpy's two sums: 15 µs within a step)
    if _sum_is_finite(np.ascontiguousarray(positions, dtype=np.float64),
                      np.ascontiguousarray(velocities, dtype=np.float64)):
        return None
    bad_x = ~np.isfinite(positions).all(axis=1)
    bad_v = ~np.isfinite(velocities).all(axis=1)
    bad = bad_x | bad_v
    if not bad.any():
        return None
    first = int(np.argmax(bad))
    return first, "position" if bad_x[first] else "velocity", int(bad.sum())


@kernel
def _sum_is_finite(x, v):
    """Is the sum of every entry of x and v (N, 3) finite?"""
    total = 0.0
    for i in range(x.shape[0]):
        total += x[i, 0] + x[i, 1] + x[i, 2] + v[i, 0] + v[i, 1] + v[i, 2]
    return math.isfinite(total)


def state_hash(positions: np.ndarray, velocities: np.ndarray) -> str:
    """BLAKE2b-128 hex digest of the exact bytes of positions then velocities (float64, C order)."""
    h = hashlib.blake2b(digest_size=16)
    h.update(np.ascontiguousarray(positions, dtype=np.float64).data)  # the buffer itself, not a copy of it
    h.update(np.ascontiguousarray(velocities, dtype=np.float64).data)
    return h.hexdigest()


def energies(state: State, gravity: np.ndarray) -> tuple[float, float, np.ndarray]:
    """(kinetic J, potential J, momentum (3,) kg·m/s) over movable particles.

    Potential energy is -m (s_i g)·x_i: zero at the origin, so only its changes mean much.
    """
    g = np.asarray(gravity, dtype=np.float64)
    kinetic, potential, p0, p1, p2 = _energy_sums(state.positions, state.velocities, state.inverse_mass,
                                                  state.gravity_scale, g[0], g[1], g[2])
    return kinetic, potential, np.array([p0, p1, p2])


@kernel
def _energy_sums(x, v, inverse_mass, gravity_scale, g0, g1, g2):
    """energies' sums in one compiled pass over the particles (every step computes them:
    numpy's dot products took 55 µs of a step at 1 000 particles). Summed in index order
    (numba does not reorder float additions without fastmath), so a run's energies are
    deterministic like its states."""
    kinetic = 0.0
    potential = 0.0
    p0 = 0.0
    p1 = 0.0
    p2 = 0.0
    for i in range(x.shape[0]):
        w = inverse_mass[i]
        if w > 0.0:
            m = 1.0 / w
            kinetic += m * (v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1] + v[i, 2] * v[i, 2])
            potential += m * gravity_scale[i] * (x[i, 0] * g0 + x[i, 1] * g1 + x[i, 2] * g2)
            p0 += m * v[i, 0]
            p1 += m * v[i, 1]
            p2 += m * v[i, 2]
    return 0.5 * kinetic, -potential, p0, p1, p2


def budget_value(name: str, value: int | None, spheres: int) -> int:
    """What budget ``name`` (a BUDGETS key) set to ``value`` is for this many spheres: the
    value, or for a budget of SIZED_BUDGETS set to 0 (or None), max(at least, per sphere ×
    spheres) (the resting work also at most MAX_RESTING_WORK). What a world spends and
    what the audit reports."""
    if value or name not in SIZED_BUDGETS:
        return int(value or 0)
    if name == "max_resting_work_per_step":
        return min(MAX_RESTING_WORK, max(MIN_RESTING_WORK, RESTING_WORK_PER_SPHERE * spheres))
    least, per_sphere = ((MIN_CONTACT_CAP, CONTACTS_PER_SPHERE) if name == "max_contacts_per_step"
                         else (MIN_SWEPT_TESTS, SWEPT_TESTS_PER_SPHERE))
    return max(least, per_sphere * spheres)
