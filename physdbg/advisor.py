"""The advisor: from a scene alone, which methods fail on it and the cheapest safe settings.

What it knows comes from the measured maps and charts (docs/accuracy.md,
docs/stability.md), turned into rules over facts of the scene:

* a **speed bound**: no contact (e <= 1) or drag adds energy, so no sphere can move
  faster than if it held all the scene's kinetic energy plus the potential energy every
  sphere can still lose before it rests on a floor: v <= sqrt(2 E / m_min). Without a
  floor under gravity nothing bounds the fall, and the advisor says it uses an estimate
  (the fastest initial speed plus |g| times the duration). Closing speeds between two
  spheres are at most twice the bound;
* **whether any contact can happen at all**: each sphere stays within bound × duration of
  where it starts, so two spheres whose reachable balls do not meet, and a sphere whose
  ball does not reach a wall, can never touch;
* the **slabs a step must land in**: a discrete test pushes an overlapping sphere out on
  the side its centre is on, so it tunnels once a step carries the centre past a two-sided
  wall's mid-plane (thickness/2 + r) or past another sphere's centre (r_a + r_b relative);
  a one-sided wall is a half-space and cannot be tunnelled.

Rules: the **exact** integrator whenever only gravity and drag act (always, in physdbg:
it is exact at any dt and costs what Euler costs per step); **swept** detection whenever
a contact can happen (discrete and sampled find contacts only after the overlap, at every
speed: the stability maps), **discrete** when none can (no swept tests to pay for);
**time** ordering when a step can hold more than one contact (index ordering resolves a
later contact first: overlaps in the cradle and the gas); the broad phase ``auto`` picks
by size and radius spread (docs/broadphase.md).

A **pile**: under gravity, in a box closed by one-sided walls with a floor against
gravity, spheres with restitution below 1 end in a pile PILE_LAYERS or more layers deep
(their volume at random close packing over the floor). An exact pile never rests by
itself (docs/benchmarks.md): with ``rapid_contact_rule = "hold"`` each impact on it is
solved through its held contacts and the steps slow as it grows (rain of 500: minutes);
with ``"tc"`` its bed rattles ever faster until a budget stops steps; with ``"tc"`` and
sleeping (``sleep_speed``) it falls asleep, exactly, at the price of freezing motion below
``sleep_speed`` (docs/sleeping.md). This is advice on speed and on resting,
read from those measurements; it does not change ``check``'s exit code.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .engine.broadphase import choose_broad_phase
from .engine.motion import EXACT_UNDER, INTEGRATOR_NAMES
from .engine.periodic import minimum_image
from .engine.state import RAPID_CONTACT_TIME
from .engine.toi import DETECTION_NAMES

AUTO = "auto"
CHOSEN = ("integrator", "detection", "ordering")  # what ``auto`` may decide in a scene
PILE_RULES = ("rapid_contact_time", "rapid_contact_rule", "sleep_speed")  # ``auto`` by default: decided by whether a
# pile forms (resolve_pile_rules)
PILE_LAYERS = 1.0  # layers of spheres at rest on the floor from which the rain makes a pile
RANDOM_CLOSE_PACKING = 0.64  # the volume fraction of a settled pile of equal spheres
PILE_REMEDY = {"rapid_contact_rule": "tc", "sleep_speed": 0.1, "sleep_time": 0.1}  # measured on box-rain and rain
PILE_REMEDY_FLAGS = " ".join(f"-s {k}={v}" for k, v in PILE_REMEDY.items())  # as a user types them


@dataclass
class Prediction:
    """What a method will do on the scene: outcome "safe", "inexact", "overlap left" or
    "tunnels", and why in words."""

    setting: str
    value: str
    outcome: str
    why: str


@dataclass
class Advice:
    """recommended: setting -> value; reasons: setting -> why; predictions: per choice;
    facts: what the rules were applied to (speed_bound m/s, dt s, ...)."""

    recommended: dict[str, str]
    reasons: dict[str, str]
    predictions: list[Prediction]
    facts: dict = field(default_factory=dict)

    def fails(self, setting: str, value: str) -> list[Prediction]:
        return [p for p in self.predictions if p.setting == setting and p.value == value and p.outcome != "safe"]


def advise(scene) -> Advice:
    """The advice for a scene (a physdbg.scene.Scene; its own settings are not read, only
    its bodies, walls, forces and time step)."""
    state, walls, s = scene.state, scene.walls, scene.settings
    n = state.count
    movable = state.inverse_mass > 0
    gravity = float(np.linalg.norm(s.gravity))
    duration = scene.duration if scene.duration is not None else (scene.steps or 0) * (scene.dt or 0.0)
    dt = scene.dt if scene.dt is not None else scene.max_dt  # a real-time run's steps are at most max_dt
    bound, bound_why = _speed_bound(state, walls, np.asarray(s.gravity, dtype=float), duration)
    surface = walls.meshes.surface_speeds()  # (M,) m/s: each kinematic mesh's fastest surface point
    if surface.size and surface.max() > 0:
        # a moving mesh does work on what it strikes, every time: no energy bounds a sphere
        bound += 2.0 * float(surface.max())
        bound_why = (f"an estimate, not a bound (a kinematic mesh can add energy at every strike): {bound_why}, plus "
                     f"twice the fastest kinematic mesh surface ({surface.max():.3g} m/s), what one strike adds")
    reach = bound * duration  # how far any sphere can get from where it starts
    r = state.radius
    r_min = float(r.min()) if n else 0.0
    contacts_possible = _contacts_possible(state.positions, r, movable, reach, walls, duration)
    periodic = _periodic_fit(walls, r, bound, dt)
    two_sided = [(f"wall '{name}'", float(t), 0.0) for name, two, t
                 in zip(walls.names, walls.two_sided, walls.thickness, strict=True) if two]
    # a mesh's triangles have no thickness: a centre carried past one by more than a
    # radius is through it, as through a two-sided wall of thickness 0; a kinematic mesh
    # closes on a sphere faster by its own surface speed
    two_sided += [(f"mesh '{name}'", 0.0, float(u)) for name, u in zip(walls.meshes.names, surface, strict=True)]
    several = n >= 3 or (n >= 2 and len(walls) > 0)  # a step can hold more than one contact
    facts = {"particles": n, "walls": len(walls), "meshes": mesh_sizes(walls.meshes),
             "partners": {kind: len(partners) for kind, partners in walls.partners.items()}, "speed_bound": bound, "speed_bound_why": bound_why, "dt": dt, "duration": duration,
             "gravity": gravity, "drag": s.drag, "radius_min": r_min, "radius_max": float(r.max()) if n else 0.0,
             "contacts_possible": contacts_possible, "samples": s.samples, "periodic": periodic,
             "mesh_sweeps": mesh_sweeps(walls.meshes, dt, s.budget("max_swept_tests_per_step", n))}

    predictions: list[Prediction] = []
    # integrators
    forces = "gravity and drag" if s.drag < 1 else "gravity"
    act = "act" if s.drag < 1 else "acts"
    for name, exact_under in zip(INTEGRATOR_NAMES, EXACT_UNDER, strict=True):
        if gravity == 0 and s.drag == 1:
            predictions.append(Prediction("integrator", name, "safe", "no force acts: every integrator is exact"))
        elif exact_under == "gravity and drag" or (exact_under == "gravity" and s.drag == 1):
            predictions.append(Prediction("integrator", name, "safe", f"exact under {forces} at any dt"))
        else:
            predictions.append(Prediction("integrator", name, "inexact",
                                          f"first-order error in flight under {forces} (docs/accuracy.md)"))
    # detection
    for name in DETECTION_NAMES:
        predictions.append(_detection(name, contacts_possible, bound, dt, s.samples, r_min, two_sided, n))
    # ordering
    for name in ("time", "index"):
        if name == "index" and several and contacts_possible:
            predictions.append(Prediction("ordering", name, "overlap left",
                                          "a step can hold several contacts; index order may resolve a later one "
                                          "first (overlaps in the cradle and the gas: docs/accuracy.md)"))
        else:
            predictions.append(Prediction("ordering", name, "safe", "contacts in the order they happen"
                                          if name == "time" else "at most one contact a step can hold"))

    if periodic is not None and not periodic["fits"]:
        predictions.append(Prediction("dt", f"{dt:.6g}", "pairs untested", periodic["why"]))
    geometry = mesh_geometry(scene)  # the meshes' collider group, for both checks
    overlaps = starting_overlaps(scene, geometry)  # a sphere inside another body at the start: overlap left
    facts["start_overlaps"] = overlaps
    facts["notes"] = meshes_out_of_reach(scene) + driven_notes(scene, geometry)  # said, not failed
    if overlaps:
        predictions.append(Prediction("start", "positions", "overlap left", start_words(overlaps)))
    pile = _pile(state, walls, np.asarray(s.gravity, dtype=float))
    facts["pile"] = pile
    if pile is not None:
        predictions += _pile_predictions()

    recommended = {"integrator": "exact"}
    reasons = {"integrator": f"only {forces} {act} on physdbg's spheres: exact at any dt, and no dearer per step "
                             "than Euler (docs/accuracy.md)" if gravity or s.drag < 1 else
               "no force acts; exact is as cheap as any"}
    if contacts_possible:
        recommended["detection"] = "swept"
        reasons["detection"] = (f"contacts can happen (speeds up to {bound:.3g} m/s over {duration:.3g} s): only "
                                "swept tests find them at their time of impact, at every speed and dt "
                                "(docs/stability.md)")
    else:
        recommended["detection"] = "discrete"
        reasons["detection"] = ("no contact can happen: no sphere can reach another, a wall, a mesh or any other partner within the run "
                                f"(at most {reach:.3g} m from where it starts), so no swept test is needed")
    recommended["ordering"] = "time"
    reasons["ordering"] = ("a step can hold several contacts: time order resolves them as they happen"
                           if several and contacts_possible else "time order (the default); nothing to reorder")
    broad, why = choose_broad_phase("auto", r)
    recommended["broad_phase"] = broad
    reasons["broad_phase"] = why
    return Advice(recommended, reasons, predictions, facts)


def _detection(name, contacts_possible, bound, dt, samples, r_min, two_sided, n) -> Prediction:
    if name == "swept":
        return Prediction("detection", name, "safe", "every contact at its time of impact, at any speed and dt")
    if not contacts_possible:
        return Prediction("detection", name, "safe", "no contact can happen in this run")
    per = dt / (samples if name == "sampled" else 1)
    travel = bound * per  # the most a test's interval can carry a centre
    tunnels = [f"{wall} (t/2 + r = {t / 2 + r_min:.3g} m" + (f"; it moves at up to {extra:.3g} m/s itself)" if extra
                                                              else ")")
               for wall, t, extra in two_sided if (bound + extra) * per > t / 2 + r_min]
    if n >= 2 and 2 * travel > 2 * r_min:
        tunnels.append(f"another sphere (r_a + r_b = {2 * r_min:.3g} m at closing speeds up to {2 * bound:.3g} m/s)")
    step = f"{travel:.3g} m a {'sample' if name == 'sampled' else 'step'} at {bound:.3g} m/s"
    if tunnels:
        return Prediction("detection", name, "tunnels", f"can tunnel through {', '.join(tunnels)}: up to {step}")
    return Prediction("detection", name, "overlap left",
                      "finds each contact only after the spheres overlap (docs/stability.md); up to " + step)


def _pile(state, walls, gravity: np.ndarray) -> dict | None:
    """Whether the spheres end in a pile (see module doc): {"layers", "why"}, or None.
    state: anything with (N,) radius, inverse_mass, restitution and gravity_scale (a
    State, a RecordingHeader)."""
    return pile_or_why_not(state, walls, gravity)[0]


def pile_or_why_not(state, walls, gravity: np.ndarray) -> tuple[dict | None, str]:
    """(the pile, "") when the spheres end in one (see module doc), else (None, why not)."""

    movable = (state.inverse_mass > 0) & (state.gravity_scale > 0)
    g = float(np.linalg.norm(gravity))
    box = walls.box()
    if g == 0.0 or not np.any(movable):
        return None, "nothing falls (no gravity, or no sphere it moves)"
    if box is None or walls.periodic:
        return None, "no closed box to pile up in"
    down = gravity / g
    axis = int(np.argmax(np.abs(down)))
    if abs(abs(down[axis]) - 1.0) > 1e-12:  # gravity along no axis of the box: no floor area to speak of
        return None, "gravity points along no axis of the box"
    side = box[1] - box[0]
    floor = float(np.prod(np.delete(side, axis)))
    r = state.radius[movable]
    height = float(np.sum(4.0 / 3.0 * np.pi * r**3)) / RANDOM_CLOSE_PACKING / floor
    layers = height / (2.0 * float(r.mean()))
    if layers < PILE_LAYERS:
        return None, f"the spheres cover {layers:.2g} of a layer on the floor, not a pile"
    e_spheres = float(state.restitution[movable].min())
    e_walls = float(walls.restitution.min()) if len(walls) else 1.0
    if min(e_spheres, e_walls) >= 1.0:  # nothing loses energy: the spheres stay a hot gas, no pile
        return None, "no contact loses energy (restitution 1): the spheres stay a gas"
    return {"layers": layers, "why": (
        f"{int(np.count_nonzero(movable))} spheres settle about {layers:.2g} layers deep on a {floor:.3g} m² floor "
        f"(restitution {min(e_spheres, e_walls):.2g} < 1)")}, ""


def _pile_predictions() -> list[Prediction]:
    """How each rapid-contact rule, with sleeping or not, does on a pile (module doc)."""
    return [
        Prediction("pile", "hold", "churns", "each impact on the pile is solved through the contacts it holds, so "
                                             "the steps slow as it grows (rain of 500: minutes; docs/benchmarks.md)"),
        Prediction("pile", "hold+sleep", "churns", "the pile churns before its spheres are slow long enough to sleep"),
        Prediction("pile", "tc", "collapses", "fast while the rain falls; once the pile has formed, its bed rattles "
                                              "ever faster until a budget stops steps"),
        Prediction("pile", "tc+sleep", "settles", "falls asleep from the floor up, exactly (rain of 500: seconds); "
                                                  "motion slower than sleep_speed is frozen"),
    ]


def _unrested_pile(bodies, walls, gravity, rapid_contact_rule: str, sleep_speed: float) -> tuple[dict, str] | None:
    """(the pile, the settings' choice) when the spheres make a pile that rule and
    sleeping do not let rest; None otherwise. O(N): safe on any scene, unlike advise
    (whose contact test is O(N²))."""
    pile = _pile(bodies, walls, np.asarray(gravity, dtype=float))
    choice = _choice(rapid_contact_rule, sleep_speed)
    return None if pile is None or choice == "tc+sleep" else (pile, choice)


def pile_note(scene) -> str | None:
    """One sentence for a run about to start (physdbg run / record): the scene makes a pile
    that its settings will not let rest, and what would; None otherwise."""
    s = scene.settings
    found = _unrested_pile(scene.state, scene.walls, s.gravity, s.rapid_contact_rule, s.sleep_speed)
    if found is None:
        return None
    pile, choice = found
    outcome = next(p for p in _pile_predictions() if p.value == choice)
    return (f"{pile['why']}, and an exact pile does not rest by itself. Under {choice} it {outcome.outcome}: "
            f"{outcome.why}. To let it rest: {PILE_REMEDY_FLAGS} (physdbg check on this scene says more).")


def pile_hint(header) -> str | None:
    """For advice on a recorded run (the audit): the scene makes a pile its settings do not
    let rest, and what does; None otherwise. header: a RecordingHeader."""
    s = header.meta.get("settings", {})
    found = _unrested_pile(header, header.walls, s.get("gravity", (0.0, 0.0, 0.0)), s.get("rapid_contact_rule", "hold"),
                           float(s.get("sleep_speed", 0.0) or 0.0))
    if found is None:
        return None
    pile, choice = found
    return (f"this scene makes a pile about {pile['layers']:.2g} layers deep, which {choice} does not let rest: "
            f"{PILE_REMEDY_FLAGS} lets it fall asleep (physdbg check)")


def pile_choice(settings) -> str:
    """The ``pile`` prediction a scene's settings pick: its rapid-contact rule, +sleep when on."""
    return _choice(settings.rapid_contact_rule, settings.sleep_speed)


def _choice(rapid_contact_rule: str, sleep_speed: float) -> str:
    return rapid_contact_rule + ("+sleep" if sleep_speed > 0 else "")


def _speed_bound(state, walls, gravity: np.ndarray, duration: float) -> tuple[float, str]:
    """(m/s, how it was found) no sphere can exceed during the run (see module doc)."""
    movable = state.inverse_mass > 0
    if not np.any(movable):
        return 0.0, "nothing can move"
    v = state.velocities[movable]
    mass = 1.0 / state.inverse_mass[movable]
    kinetic = float(np.sum(0.5 * mass * np.sum(v * v, axis=1)))
    g = float(np.linalg.norm(gravity))
    if g == 0.0:
        return float(np.sqrt(2 * kinetic / mass.min())), "energy: all the kinetic energy in the lightest sphere"
    down = gravity / g
    floors = [offset for normal, offset, two in zip(walls.normals, walls.offsets, walls.two_sided, strict=True)
              if not two and normal @ down < -1 + 1e-12]  # a one-sided plane facing up, against gravity
    if not floors:  # nothing bounds the fall: an estimate, not a bound
        fastest = float(np.linalg.norm(v, axis=1).max())
        return fastest + g * duration, "an estimate (no floor under gravity): the fastest start plus |g| × duration"
    floor = max(floors)  # the highest floor: every centre stays at least r above it
    height = -(state.positions[movable] @ down) - (floor + state.radius[movable])  # above where it would rest
    energy = kinetic + float(np.sum(mass * g * np.maximum(height, 0.0)))
    return float(np.sqrt(2 * energy / mass.min())), "energy: all the kinetic and fall energy in the lightest sphere"


def _periodic_fit(walls, r, bound: float, dt: float) -> dict | None:
    """In a periodic box: the widest swept box a step can make (2 r + 2 v dt at the speed
    bound) against half the shortest period, which the minimum image needs (World refuses
    a step otherwise); None without periodic axes."""
    if not walls.periodic:
        return None
    period = float(walls.period[walls.period > 0].min())
    width = 2.0 * (float(r.max()) if len(r) else 0.0) + 2.0 * bound * dt
    axes = ", ".join(a for a, length in zip("xyz", walls.period, strict=True) if length > 0)
    fits = width < 0.5 * period
    why = (f"periodic on {axes}: a step's swept box is at most {width:.3g} m wide, "
           + ("under" if fits else "not under") + f" half the period ({0.5 * period:.3g} m)")
    if not fits:
        longest = (0.5 * period - 2.0 * float(r.max())) / (2.0 * bound) if bound > 0 else math.inf
        why += ("; steps where it is wider test no pairs (their images cannot be told apart): "
                + (f"use dt < {longest:.3g} s" if longest > 0 else "make the box larger"))
    return {"axes": axes, "period": period, "width": width, "fits": fits, "why": why}


def _contacts_possible(x, r, movable, reach, walls, duration: float = 0.0) -> bool:
    """Whether any two spheres, or a sphere and a wall or a mesh, can touch within the run:
    each movable sphere stays within ``reach`` of where it starts (in a periodic box, pairs
    are as near as their nearest images; a mesh is as near as its nearest corner's box)."""
    n = len(r)
    if n == 0:
        return False
    extent = np.where(movable, reach, 0.0) + r
    if n >= 2 and _two_reach_each_other(x, extent, walls):
        return True
    for normal, offset, two, t in zip(walls.normals, walls.offsets, walls.two_sided, walls.thickness, strict=True):
        gap = x @ normal - offset  # signed distance of each centre from the plane
        distance = np.abs(gap) - t / 2 if two else gap  # a one-sided wall is a half-space: behind it is touching
        if np.any(distance <= extent):
            return True
    if walls.meshes.triangles:
        corners = walls.meshes.corners.reshape(-1, 3)
        lo, hi = corners.min(axis=0), corners.max(axis=0)  # the meshes' box: no sphere farther can touch one
        # a kinematic mesh can be anywhere within its turning radius and its drift of where it starts
        meshes = walls.meshes
        spread = float(np.max(meshes.turn_radii() * (np.linalg.norm(meshes.angular_velocity, axis=1) > 0)
                              + np.linalg.norm(meshes.velocity, axis=1) * duration, initial=0.0))
        outside = np.linalg.norm(np.maximum(0.0, np.maximum(lo - spread - x, x - hi - spread)), axis=1)
        if np.any(outside <= extent):
            return True
    return _kind_partners_reached(x, extent, walls)


PAIRS_LOOKED_AT = 1_000_000  # box pairs _two_reach_each_other measures before it says "maybe"


def _two_reach_each_other(x, extent, walls) -> bool:
    """Whether two spheres (centres x (N, 3) m, each within ``extent`` (N,) m of where it
    starts) can touch: the broad phase's grid finds the pairs whose boxes meet, so time
    and memory grow with N and those pairs, never N × N. Past PAIRS_LOOKED_AT pairs of
    boxes, or where a sphere reaches half a periodic box round, the answer is yes (what
    the advisor has not measured it never calls out of reach)."""
    from .engine.broadphase.grid import grid_pairs
    from .engine.broadphase.periodic import images

    period = np.asarray(walls.period, dtype=np.float64)
    periodic = period > 0
    if periodic.any():
        if 2.0 * float(extent.max()) >= float(period[periodic].min()) / 2.0:
            return True
        origin = np.asarray(walls.period_origin, dtype=np.float64)
        x = np.where(periodic, origin + np.mod(x - origin, np.where(periodic, period, 1.0)), x)
        lo, hi, owner = images(x - extent[:, None], x + extent[:, None], origin, period)
    else:
        lo, hi, owner = x - extent[:, None], x + extent[:, None], np.arange(len(x))
    boxes, _, _ = grid_pairs(np.ascontiguousarray(lo), np.ascontiguousarray(hi), 0.0, PAIRS_LOOKED_AT)
    if len(boxes) > PAIRS_LOOKED_AT:
        return True
    a, b = owner[boxes[:, 0]], owner[boxes[:, 1]]
    keep = a != b
    a, b = a[keep], b[keep]
    d = np.linalg.norm(minimum_image(x[a] - x[b], period), axis=1)
    return bool(np.any(d <= extent[a] + extent[b]))


def _kind_partners_reached(x, extent, walls) -> bool:
    """Whether a sphere (centres x (N, 3), each within ``extent`` (N,) m of where it
    starts) can reach a partner of a kind declaring its own fields (a kind beyond the wall
    and the mesh): by the boxes its module's ``reach`` gives, or, for a module that gives
    none, always (what the advisor cannot measure it never calls out of reach)."""
    from .engine.colliders import extra_kinds

    for _code, name, module in extra_kinds():
        partners = walls.partners.get(name)
        if partners is None or not len(partners):
            continue
        if getattr(module, "reach", None) is None:
            return True
        lo, hi = module.reach(partners)  # (P, 3) each
        outside = np.linalg.norm(np.maximum(0.0, np.maximum(lo[None] - x[:, None], x[:, None] - hi[None])), axis=2)
        if np.any(outside <= extent[:, None]):
            return True
    return False


def decide(scene):
    """Decide a loaded scene's "auto" settings in place (resolve_auto) and its meshes'
    auto bounding volumes (resolve_mesh_volumes), and return the scene; scene.auto says
    each decision and why. Deciding twice changes nothing."""
    if scene.settings.undecided():
        scene.auto = resolve_auto(scene)
    if "auto" in scene.walls.meshes.bounding_volume:
        scene.auto = {**scene.auto, **resolve_mesh_volumes(scene)}
    return scene


# What a mesh's walk costs, in node tests of an AABB: a node test with any volume ~10 ns
# (benchmarks/mesh_queries.py's timings), an OBB's ~25 % dearer; each triangle reached is a
# swept sphere–triangle test, about 20 node tests.
VOLUME_NODE_COST = {"aabb": 1.0, "sphere": 1.0, "obb": 1.25}
TRIANGLE_TEST_COST = 20.0
VOLUME_SAMPLES = 256  # boxes a mesh's volumes are counted with


@dataclass(frozen=True)
class Decision:
    """An "auto" setting as decided (scene.auto, RunSummary.auto): its value and why, the
    advisor's words; or ``shared_with``, the setting decided with it whose words say why
    for both (the pile rules are one decision)."""

    value: object
    why: str = ""
    shared_with: str = ""


def resolve_mesh_volumes(scene) -> dict[str, Decision]:
    """Each mesh's ``bounding_volume = "auto"``, decided by counted work (never timed, so
    the same scene decides the same): boxes the size of this scene's sphere paths over a
    step (the median radius, the median speed plus a step of gravity, times dt; grown by
    the mesh's own motion over a step, as the engine grows them) placed at points on its
    triangles (seeded), walked with each volume (colliders/mesh.search_work): node tests
    and triangles reached, weighed by VOLUME_NODE_COST and TRIANGLE_TEST_COST; the least
    wins (AABB on a tie). Returns {"bounding_volume": Decision} when any was auto."""
    from .engine.colliders.mesh import VOLUMES, MeshGeometry, search_work

    meshes, st = scene.walls.meshes, scene.state
    dt = scene.dt if scene.dt is not None else 1.0 / 60.0
    radius = float(np.median(st.radius)) if st.count else 0.1
    speed = float(np.median(np.linalg.norm(st.velocities, axis=1))) if st.count else 0.0
    speed += float(np.linalg.norm(scene.settings.gravity)) * dt
    turn = meshes.turn_radii()
    words, chosen = [], []
    still = np.zeros(len(meshes), dtype=np.bool_)  # each mesh walked where it starts (its motion is in ``half``)
    for k, name in enumerate(meshes.names):
        if meshes.bounding_volume[k] != "auto":
            continue
        mine = meshes.corners[meshes.mesh_of == k]
        rng = np.random.default_rng(k)
        pick = rng.integers(0, len(mine), VOLUME_SAMPLES)
        weights = rng.dirichlet(np.ones(3), VOLUME_SAMPLES)
        points = np.einsum("sc,scd->sd", weights, mine[pick])
        half = (radius + speed * dt + float(np.linalg.norm(meshes.velocity[k])) * dt
                + float(np.linalg.norm(meshes.angular_velocity[k])) * dt * float(turn[k]))
        work = {}
        for volume in VOLUMES:
            group = MeshGeometry.of(scene.walls, np.full(len(meshes), VOLUMES.index(volume)))._replace(moving=still)
            tests, reached = search_work(points - half, points + half, tuple(group), k)
            work[volume] = VOLUME_NODE_COST[volume] * int(tests) + TRIANGLE_TEST_COST * int(reached)
        best = min(work, key=lambda v: (work[v], v != "aabb"))
        meshes.bounding_volume[k] = best
        chosen.append(f"{best} for '{name}'")
        words.append(f"mesh '{name}' {best} (counted work per box: " + ", ".join(
            f"{v} {work[v] / VOLUME_SAMPLES:.0f}" for v in ("aabb", "sphere", "obb")) + ")")
    if not words:
        return {}
    return {"bounding_volume": Decision(", ".join(chosen), "; ".join(words) + f" for {VOLUME_SAMPLES} path-sized "
                                        "boxes on its triangles (docs/meshes.md, \"Bounding volumes\")")}


def resolve_auto(scene) -> dict[str, Decision]:
    """Replace ``auto`` in a scene's settings by the advice; returns setting -> Decision
    for each one decided (empty when none was auto). integrator, detection and ordering
    take ``advise``'s recommendation; rapid_contact_rule and sleep_speed (``auto`` unless
    the scene gives them) take the pile rules (resolve_pile_rules)."""
    decided = resolve_pile_rules(scene)
    asked = [name for name in CHOSEN if getattr(scene.settings, name) == AUTO]
    if not asked:
        return decided
    advice = advise(scene)
    for name in asked:
        setattr(scene.settings, name, advice.recommended[name])
    return {**{name: Decision(advice.recommended[name], advice.reasons[name]) for name in asked}, **decided}


def resolve_pile_rules(scene) -> dict[str, Decision]:
    """``auto`` rapid_contact_time, rapid_contact_rule and sleep_speed: where the spheres
    will make a pile (an exact pile never rests by itself: module doc), the rapid-contact
    rule (RAPID_CONTACT_TIME), the TC rule and sleeping at 0.1 m/s after 0.1 s (PILE_REMEDY,
    measured on box-rain and rain; sleep_time only when the scene does not give it);
    elsewhere the seed's model, no more: no rapid-contact rule (a break shot keeps each
    contact's restitution), held contacts exact, and no sleeping."""
    s = scene.settings
    asked = [name for name in PILE_RULES if getattr(s, name) == AUTO]
    if not asked:
        return {}
    pile, why_not = pile_or_why_not(scene.state, scene.walls, np.asarray(s.gravity, dtype=float))
    if pile is not None:
        values = {name: {**PILE_REMEDY, "rapid_contact_time": RAPID_CONTACT_TIME}[name] for name in asked}
        if "sleep_speed" in asked and "sleep_time" not in scene.raw:
            values["sleep_time"] = PILE_REMEDY["sleep_time"]
        rules = _and([words for name, words in (("rapid_contact_time", "the rapid-contact rule"),
                                                ("rapid_contact_rule", "the TC rule"),
                                                ("sleep_speed", "sleeping")) if name in asked])
        why = (f"{pile['why']}: an exact pile does not rest by itself; {rules} let it fall asleep "
               f"(docs/sleeping.md)")
    else:
        values = {name: {"rapid_contact_time": 0.0, "rapid_contact_rule": "hold", "sleep_speed": 0.0}[name]
                  for name in asked}
        why = f"{why_not}: " + _and([
            words for name, words in (("rapid_contact_time", "no rapid-contact rule (the seed's model: each contact "
                                                              "with its own restitution)"),
                                      ("rapid_contact_rule", "contacts are held exactly"),
                                      ("sleep_speed", "nothing sleeps")) if name in asked])
    for name, value in values.items():
        setattr(s, name, value)
    # one line says why; the others point to it
    first = next(iter(values))
    return {name: Decision(value, why) if name == first else Decision(value, shared_with=first)
            for name, value in values.items()}


def _and(parts: list[str]) -> str:
    """"a", "a and b", "a, b and c"."""
    return ", ".join(parts[:-1]) + (" and " if len(parts) > 1 else "") + parts[-1]


# A kinematic mesh turning more than this in one step sweeps boxes that cover most of its
# turn: every contact near it is tested against most of its triangles, each test in many
# short passes (toi._triangle_toi_swept), so the swept-test budget ends such steps early.
SWEEP_DEGREES_PER_STEP = 90.0


def mesh_sweeps(meshes, dt: float, budget: int) -> list[dict]:
    """The kinematic meshes that turn more than SWEEP_DEGREES_PER_STEP in a step of ``dt``
    s, each {mesh, degrees, triangles, dt_max, why}: what a step can test (``budget``,
    max_swept_tests_per_step as sized) and the dt that keeps the turn within the limit."""
    out = []
    sizes = mesh_sizes(meshes)
    for k, name in enumerate(meshes.names):
        spin = float(np.degrees(np.linalg.norm(meshes.angular_velocity[k])))  # deg/s
        degrees = spin * dt
        if degrees <= SWEEP_DEGREES_PER_STEP:
            continue
        dt_max = SWEEP_DEGREES_PER_STEP / spin
        out.append({"mesh": name, "degrees": degrees, "triangles": sizes[name], "dt_max": dt_max,
                    "why": (f"mesh '{name}' turns {degrees:,.0f}° in a step ({spin:.3g} deg/s, dt {dt:.3g} s): its "
                            f"triangles' swept boxes cover the turn, so each contact near it tests up to all "
                            f"{sizes[name]:,} of them, each in many short passes; a step can test {budget:,.0f} "
                            f"(max_swept_tests_per_step), so its contacts may stop steps early (a warning names the "
                            f"budget); dt ≤ {dt_max:.3g} s keeps it within {SWEEP_DEGREES_PER_STEP:g}° a step")})
    return out


def mesh_sizes(meshes) -> dict[str, int]:
    """Each fixed mesh's name and its number of triangles (state.Meshes)."""
    first = meshes.first
    return {name: int(first[k + 1] - first[k]) for k, name in enumerate(meshes.names)}


# ----------------------------------------------------------------------------- the starting state
START_EXAMPLES = 3  # starting overlaps named in full; the rest counted
START_NOT_PUSHED = ("physdbg does not push bodies apart: it resolves contacts from where they are, so the overlap "
                    "stays until their motions part them, and every step warns")


def mesh_geometry(scene) -> tuple | None:
    """The scene's meshes as the engine's collider group (colliders.mesh.MeshGeometry, as a
    tuple, on the trees of the scene's mesh set), or None without meshes: for the checks below."""
    from .engine.colliders.mesh import MeshGeometry

    return tuple(MeshGeometry.of(scene.walls)) if scene.walls.meshes.triangles else None


def starting_overlaps(scene, geometry: tuple | None = None) -> list[dict]:
    """Every sphere that starts inside another body, deeper than the contact tolerance:
    [{"sphere": i, "partner": "sphere 4" / "wall 'floor'" / "mesh 'trough' triangle 1",
    "depth": m}], each sphere once (its deepest), deepest first. Spheres with spheres by the
    grid broad phase on their own boxes (periodic images included by the minimum image),
    walls by their gaps (colliders.plane.gaps), triangles by the engine's mesh search
    (colliders.mesh.deepest_where) and the partners of a kind that declares its fields by
    the switch's deepest_of_kind, all at run time 0: the engine's own rules. geometry:
    mesh_geometry(scene), if already built."""
    from .engine.broadphase.boxes import NO_LIMIT
    from .engine.broadphase.grid import grid_pairs
    from .engine.colliders.mesh import deepest_where
    from .engine.colliders.plane import gaps
    from .events import KIND_MESH, KIND_WALL, partner_words

    state, walls = scene.state, scene.walls
    x, r = state.positions, state.radius
    tolerance = scene.settings.contact_tolerance
    worst: dict[int, tuple[float, str]] = {}

    def note(i: int, depth: float, partner: str) -> None:
        if depth > tolerance and depth > worst.get(i, (0.0, ""))[0]:
            worst[i] = (float(depth), partner)

    if state.count == 0 or not np.isfinite(x).all():
        return []
    if state.count > 1:
        pairs, _, _ = grid_pairs(x - r[:, None], x + r[:, None], 0.0, NO_LIMIT)
        if len(pairs):
            a, b = pairs[:, 0], pairs[:, 1]
            depth = r[a] + r[b] - np.linalg.norm(minimum_image(x[a] - x[b], walls.period), axis=1)
            for k in np.flatnonzero(depth > tolerance):
                note(int(a[k]), float(depth[k]), f"sphere {int(b[k])}")
                note(int(b[k]), float(depth[k]), f"sphere {int(a[k])}")
    names = walls.partner_names()
    if len(walls.names):
        depth = -gaps(x, r, walls)
        for i, w in zip(*np.nonzero(depth > tolerance)):
            note(int(i), float(depth[i, w]), partner_words(KIND_WALL, int(w), names))
    if walls.meshes.triangles:
        geometry = geometry if geometry is not None else mesh_geometry(scene)
        corners = walls.meshes.corners.reshape(-1, 3)
        near = np.all((x + r[:, None] >= corners.min(axis=0)) & (x - r[:, None] <= corners.max(axis=0)), axis=1)
        for i in np.flatnonzero(near):
            depth, _, t = deepest_where(np.ascontiguousarray(x[i:i + 1], dtype=np.float64),
                                        np.ascontiguousarray(r[i:i + 1], dtype=np.float64), geometry, False)
            note(int(i), float(depth), partner_words(KIND_MESH, int(t), names))
    if any(len(partners) for partners in walls.partners.values()):  # a kind that declares its fields
        from .engine.colliders import deepest_of_kind, extra_kinds, geometry_of

        kinds_geometry, no_pairs = geometry_of(walls), np.zeros((0, 2), dtype=np.int64)
        for code, _name, _module in extra_kinds():  # the engine's own measure, through the switch
            for i in range(state.count):
                depth, _, other = deepest_of_kind(code, np.ascontiguousarray(x[i:i + 1], dtype=np.float64),
                                                  np.ascontiguousarray(r[i:i + 1], dtype=np.float64), no_pairs,
                                                  kinds_geometry, False)
                if other >= 0:
                    note(int(i), float(depth), partner_words(code, int(other), names))
    return [{"sphere": i, "partner": partner, "depth": depth}
            for i, (depth, partner) in sorted(worst.items(), key=lambda item: (-item[1][0], item[0]))]


def start_words(overlaps: list[dict]) -> str:
    """The starting overlaps in one line (starting_overlaps' list, not empty)."""
    def length(metres: float) -> str:  # as the audit writes a depth: mm below a metre
        return f"{metres * 1000:.3g} mm" if abs(metres) < 1 else f"{metres:.3g} m"

    named = "; ".join(f"sphere {o['sphere']} starts {length(o['depth'])} inside {o['partner']}"
                      for o in overlaps[:START_EXAMPLES])
    more = len(overlaps) - START_EXAMPLES
    return named + (f" (and {more} more spheres)" if more > 0 else "") + f"; {START_NOT_PUSHED}"


def meshes_out_of_reach(scene) -> list[str]:
    """A note for each mesh no sphere can reach within the run (each sphere stays within
    the advisor's speed bound × duration of where it starts, and a kinematic mesh within
    its turn radius and drift of where it starts): nothing will touch it."""
    state, walls, s = scene.state, scene.walls, scene.settings
    meshes = walls.meshes
    if not meshes.triangles or state.count == 0:
        return []
    duration = scene.duration if scene.duration is not None else (scene.steps or 0) * (scene.dt or 0.0)
    bound, _ = _speed_bound(state, walls, np.asarray(s.gravity, dtype=float), duration)
    surface = meshes.surface_speeds()
    bound += 2.0 * float(surface.max(initial=0.0))
    movable = state.inverse_mass > 0
    extent = np.where(movable, bound * duration, 0.0) + state.radius
    spread = (meshes.turn_radii() * (np.linalg.norm(meshes.angular_velocity, axis=1) > 0)
              + np.linalg.norm(meshes.velocity, axis=1) * duration)
    notes = []
    for k, name in enumerate(meshes.names):
        corners = meshes.corners[meshes.mesh_of == k].reshape(-1, 3)
        if not len(corners):
            continue
        lo, hi = corners.min(axis=0) - spread[k], corners.max(axis=0) + spread[k]
        away = np.linalg.norm(np.maximum(0.0, np.maximum(lo - state.positions, state.positions - hi)), axis=1)
        gap = away - extent
        if np.all(gap > 0.0):
            i = int(np.argmin(away))
            notes.append(f"mesh '{name}' is out of every sphere's reach in this run: the nearest, sphere {i}, starts "
                         f"{away[i]:.3g} m from it and can travel at most {extent[i] - state.radius[i]:.3g} m "
                         f"({bound:.3g} m/s at most, {duration:.3g} s); nothing will touch it")
    return notes


def driven_notes(scene, geometry: tuple | None = None) -> list[str]:
    """Notes on the kinematic meshes: each one's motion does work on what it strikes (the
    run's energy is not conserved), and each sphere that starts resting on one (within the
    contact tolerance, or a micrometre, of its surface) is carried by it. geometry:
    mesh_geometry(scene), if already built."""
    from .engine.colliders.mesh import deepest_where
    from .events import KIND_MESH, partner_words

    state, walls = scene.state, scene.walls
    meshes = walls.meshes
    if not meshes.triangles or not meshes.moving.any():
        return []
    notes = [f"mesh '{name}' {meshes.motion_words(k)}: its prescribed motion does work on every sphere it strikes, "
             f"so the run's energy is not conserved (the audit judges each contact against the moving surface)"
             for k, name in enumerate(meshes.names) if meshes.moving[k]]
    if state.count and np.isfinite(state.positions).all():
        geometry = geometry if geometry is not None else mesh_geometry(scene)
        names = walls.partner_names()
        near = max(scene.settings.contact_tolerance, 1e-6)
        for i in range(state.count):
            x = np.ascontiguousarray(state.positions[i:i + 1], dtype=np.float64)
            depth, _, t = deepest_where(x, np.ascontiguousarray(state.radius[i:i + 1] + near, dtype=np.float64),
                                        geometry, False)
            if depth > 0.0 and meshes.moving[meshes.mesh_of[t]] and depth <= 2.0 * near:
                notes.append(f"sphere {i} starts resting on {partner_words(KIND_MESH, int(t), names)}, which moves: "
                             "it is carried (a held contact takes the surface's velocity); pressed by it against "
                             "something immovable it is pinned, and the run stops there (docs/meshes.md)")
    return notes
