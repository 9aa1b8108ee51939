"""Scenes are data: TOML files validated into a :class:`Scene`.

A scene is a built-in name (``physdbg scenes`` lists them) or a path to a ``.toml`` file.
Every field is documented in docs/scenes.md; :data:`FIELDS` is the source of truth.
Any field can be overridden before validation with ``key=value`` strings, where the key
is a dotted path (``integrator``, ``generate.count``, ``particles.0.radius``) and the
value is a TOML value (bare words are taken as strings).

Every mistake raises :class:`~physdbg.errors.SceneError` naming the file, the field and
what is allowed.

Why one module of this size: it is the scene format, read and written — its field table,
the rules each field is read by, the cross-field checks, the generators that fill a box,
and ``scene_table`` that writes a scene back as a table of the same fields — kept in one
place so that a field is added, documented and checked once.
"""

from __future__ import annotations

import copy
import dataclasses
import difflib
import math
import re
import sys
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np

from .limits import MAX_INTEGER, MAX_MAGNITUDE, MIN_AREA, MIN_SCALE  # the range of every number (limits.py)
from .engine import (
    BROAD_PHASE_NAMES,
    BUDGETS,
    DETECTION_NAMES,
    INTEGRATOR_NAMES,
    ORDERING_NAMES,
    RAPID_RULES,
    RESTITUTION_RULES,
    SIZED_BUDGETS,
    Settings,
    State,
    Walls,
    World,
)
from .engine.periodic import wrap_positions
from .engine.colliders.mesh import MESH_SEARCH_NAMES
from .engine.space_order import RENUMBER_EVERY, SPACE_ORDER_MIN, SPACE_ORDER_NAMES
from .engine.state import BYTES_PER_PARTICLE, DEFAULT_MAX_MEMORY, EVENT_LOOP_NAMES, RENAMED_SETTINGS, Meshes
from .errors import SceneError, UnknownSceneError
from .scenes import builtin_names, builtin_text

# ----------------------------------------------------------------------------- schema
TOP_FIELDS = {
    "name": "scene name (text)",
    "description": "one line shown by `physdbg scenes` (text)",
    "dt": 'time step: seconds > 0, a fraction such as "1/60", or "real" (wall-clock time per step)',
    "max_dt": "with dt = \"real\": longest step allowed, seconds > 0 (default 0.05)",
    "steps": "number of steps, integer >= 1 (give steps or duration)",
    "duration": "simulated seconds > 0 (give steps or duration)",
    "seed": "random seed for generated initial conditions, integer >= 0",
    "method": "auto: integrator, detection and ordering not given are all auto (the advisor decides: physdbg check)",
    "integrator": "one of " + ", ".join(INTEGRATOR_NAMES) + ", or auto (the advisor decides: physdbg check)",
    "detection": "one of " + ", ".join(DETECTION_NAMES) + ", or auto",
    "samples": "samples along each path for detection = \"sampled\", integer >= 1",
    "ordering": "one of " + ", ".join(ORDERING_NAMES) + ", or auto",
    "broad_phase": "one of " + ", ".join(BROAD_PHASE_NAMES) + " (auto picks by size: docs/broadphase.md)",
    "gravity": "gravity vector [x, y, z] in m/s²",
    "drag": "drag d in v·d^t, 0 < d <= 1 (1 = none)",
    "restitution_rule": "how two restitutions combine: one of " + ", ".join(RESTITUTION_RULES),
    "rest_fraction": ("a pressed contact rests when its closing speed is at most this fraction of |a_n|·dt, "
                      "the speed its pressing acceleration adds in one step (0 to 1, default 0.01)"),
    "rapid_contact_time": ("a contact with restitution < 1 within this many seconds of either sphere's previous "
                           "contact is held like a resting one if something presses it, and elastic if not (the TC "
                           "model against inelastic collapse), seconds >= 0, 0 = off, or auto (the default: 1e-4 where the "
                           "spheres will make a pile, off elsewhere; physdbg check says which)"),
    "rapid_contact_rule": ("what the rapid-contact rule does with a pressed contact: hold (hold it at any speed: "
                           "a pile settles sooner but passes each impact through its held contacts), tc (hold it "
                           "only if it closes no faster than its press adds in rapid_contact_time, else elastic: a "
                           "dense pile is much faster and never churns, but keeps rattling), or auto (the default: "
                           "tc where the spheres will make a pile, hold elsewhere; physdbg check says which)"),
    "contact_tolerance": "allowed overlap and resting gap, metres > 0",
    "sleep_speed": ("a sphere at most this fast (m/s) at the end of every step for sleep_time falls asleep: "
                    "immovable until something hits it faster or what it rests on wakes (a settled pile then "
                    "costs nothing), m/s >= 0, 0 = off, or auto (the default: 0.1 where the spheres will make a "
                    "pile, with sleep_time 0.1 unless given; 0 elsewhere); not with periodic walls"),
    "sleep_time": "how long a sphere must stay slow to fall asleep, seconds > 0 (default 0.5; 0.1 when "
                  "sleep_speed = auto picks sleeping)",
    "max_contacts_per_step": ("budget: contacts resolved in one step, integer >= 0 (default 0 = sized to the scene: "
                            "max(10000, 100 per sphere))"),
    "max_pairs_per_step": "budget: broad-phase candidate pairs in one step, integer >= 1 (default 10000000)",
    "max_swept_tests_per_step": ("budget: swept tests in one step, integer >= 0 (default 0 = sized to the scene: "
                                 "max(10000000, 2000 per sphere)); a test against a moving mesh's triangle counts "
                                 "each pass of its advancement (up to 500), so a fast spin's step stays bounded"),
    "max_resting_work_per_step": ("budget: held-contact solve updates in one step, integer >= 0 (default 0 = "
                                  "sized to the scene: 1000000 per sphere, from 10000000 to 1000000000)"),
    "max_memory": ("the most memory a run may use, bytes (default 4e9): a scene whose particles need more (about "
                   "4 KiB each) is refused, and a step whose buffers (event queue, swept-test log, contacts) would "
                   "grow past it is stopped like a budget"),
    "space_order": ("the engine's own numbering of the spheres, for speed: auto (the default: Morton order from "
                    f"{SPACE_ORDER_MIN} spheres up under ordering = time), given (the scene's) or morton (along a "
                    f"Z-curve of their places, renewed every {RENUMBER_EVERY} steps); every event, state and "
                    "recording stays in the scene's numbering"),
    "mesh_search": ("how each step's path boxes are searched against the meshes' trees: auto (the default: the "
                    "one with less counted work, chosen again every 32 steps), walk (one walk of each mesh's tree per "
                    "sphere) or together (a tree of the path boxes descended together with each mesh's tree); the "
                    "same candidates and states either way"),
    "event_loop": ("how contacts are found between steps: step (the default: each step boxes, pairs and predicts "
                   "every path again) or calendar (predictions kept across steps, each sphere's neighbours in a shell "
                   "around it; under gravity and drag with the exact integrator, not with euler, meshes, sleeping "
                   "or a held contact; elsewhere the world steps as with step, and the run summary says why)"),
    "max_particle_steps": "refuse a run of more particle-steps (particles × steps) than this (default 1e10)",
    "particles": "array of [[particles]] tables",
    "planes": "array of [[planes]] tables",
    "meshes": "array of [[meshes]] tables: fixed triangle meshes (docs/meshes.md)",
    "box": "[box] table: axis-aligned container, closed by walls or periodic on the axes box.periodic names",
    "generate": "[generate] table: generated particles",
}
PARTICLE_FIELDS = {
    "position": "[x, y, z] in m",
    "velocity": "[x, y, z] in m/s (default [0, 0, 0]; must be zero when immovable)",
    "radius": "metres > 0",
    "mass": "kg > 0 (or give inverse_mass)",
    "inverse_mass": "1/kg: 0 = immovable, else 1e-12 to 1e12 (a mass within mass's bounds)",
    "restitution": "0 <= e <= 1 (default 1)",
    "gravity_scale": "multiplies gravity for this particle (default 1)",
}
PLANE_FIELDS = {
    "name": "text shown in events (default plane<k>)",
    "normal": "[x, y, z], non-zero; spheres are kept on the side it points to",
    "offset": "d in n·x = d (m), with n the normalised normal",
    "restitution": "0 <= e <= 1 (default 1)",
    "two_sided": "true for a thin wall spheres bounce off from either side (default false)",
    "thickness": "thickness of a two-sided wall, metres >= 0 (default 0)",
}
MESH_FIELDS = {
    "name": "text shown in events (default mesh<k>)",
    "shape": "a built-in shape: box, ramp, funnel, box-with-hole, paddle or icosphere (or give file)",
    "file": "an .obj or .stl file, relative to the scene file's folder (or give shape)",
    "position": "[x, y, z] in m: where the mesh's origin goes (default [0, 0, 0])",
    "rotation": "[x, y, z] in degrees: turned about the world's x, then y, then z axis (default [0, 0, 0])",
    "scale": ("multiplies the mesh's size: a number, or [x, y, z] along the mesh's own axes, each from 1e-12 to 1e12 "
              "(default 1); the scaled mesh must stay within ±1e12 m and keep its triangles whole"),
    "restitution": "0 <= e <= 1 (default 1)",
    "velocity": "[x, y, z] in m/s: a kinematic mesh's constant velocity (default [0, 0, 0]: fixed)",
    "angular_velocity": "[x, y, z] in degrees per second: a kinematic mesh turns at this rate about its pivot "
                        "(default [0, 0, 0])",
    "pivot": "[x, y, z] in m: the point the mesh turns about at time 0 (default: its position)",
    "bounding_volume": ("the volume its BVH's nodes are tested with: auto (the least counted work for this mesh and "
                        "this scene's spheres), aabb, sphere or obb (default auto)"),
}
BOUNDING_VOLUMES = ("auto", "aabb", "sphere", "obb")
BOX_FIELDS = {
    "min": "[x, y, z] lower corner (m)",
    "max": "[x, y, z] upper corner (m), larger than min on every axis",
    "restitution": "0 <= e <= 1 for all six walls (default 1)",
    "periodic": ("true, false, or [x, y, z] of true/false: the periodic axes, which get no walls (a sphere "
                 "leaving comes back on the other side; default false)"),
}
GENERATE_FIELDS = {
    "kind": 'one of "rain" (in the [box]) or "gas" (makes its own box)',
    "count": "number of particles, integer >= 0",
    "radius": "metres > 0",
    "mass": "kg > 0 (default 1)",
    "restitution": "0 <= e <= 1 (default 1)",
    "speed": "typical speed, m/s >= 0 (rain: each speed within ±10 % of it; gas: rms speed)",
    "packing_fraction": "gas only: sphere volume / box volume, 0 < phi <= 0.45",
    "min": "rain only: [x, y, z] lower corner of the region to fill (default: the [box]'s; with min and max "
           "no [box] is needed, e.g. inside walls made of meshes)",
    "max": "rain only: [x, y, z] upper corner of the region to fill (default: the [box]'s)",
}
FIELDS = {"scene": TOP_FIELDS, "particles": PARTICLE_FIELDS, "planes": PLANE_FIELDS, "meshes": MESH_FIELDS,
          "box": BOX_FIELDS, "generate": GENERATE_FIELDS}

# Fields that were renamed: the hint an old scene file gets.
RENAMED = {"rest_speed": "rest_speed (an absolute m/s) was replaced by rest_fraction, which scales with the scene"}

_SETTINGS_DEFAULTS = Settings()

DEFAULT_MAX_PARTICLE_STEPS = 1e10
MAX_SCENE_BYTES = 64 * 2**20  # a scene file is text: larger ones are made with [generate]
MAX_NESTING = 6
MAX_SAMPLES = 1000  # samples along a path per swept test (detection = "sampled")  # table > array of tables > table > vector is 4 deep


@dataclass
class Scene:
    """A validated scene: everything needed to build a World and to repeat a run.

    dt: seconds, or None for real elapsed time; steps: how many steps to run (None in
    real-time mode with a duration: run until that much time has passed).
    """

    name: str
    description: str
    source: str
    settings: Settings
    dt: float | None
    max_dt: float
    steps: int | None
    duration: float | None
    seed: int
    state: State
    walls: Walls
    raw: dict[str, Any] = field(repr=False)
    overrides: tuple[str, ...] = ()  # the --set KEY=VALUE strings applied to the scene file
    auto: dict = field(default_factory=dict)  # setting -> advisor.Decision, once the advisor decided them


    def build_world(self, observer=None) -> World:
        """A fresh World on a copy of the initial state (the scene itself never changes)."""
        return World(self.state.copy(), self.walls, self.settings, observer)

    def step_lengths(self, dts=None):
        """Each step's dt (s), in order, for a loop ``for dt in scene.step_lengths(): world.step(dt)``.

        dts: exactly these step lengths (to repeat a run). Otherwise the scene's dt for
        ``steps`` steps; with dt = "real", the wall-clock time since the previous step
        (at least 1 µs, at most max_dt), until ``steps`` steps or ``duration`` seconds.
        """
        if dts is not None:
            yield from (float(d) for d in dts)
            return
        if self.dt is not None:
            for _ in range(self.steps):
                yield self.dt
            return
        import time

        taken, simulated, last = 0, 0.0, time.perf_counter()
        while (taken < self.steps) if self.steps is not None else (simulated < self.duration):
            now = time.perf_counter()
            dt = min(max(now - last, 1e-6), self.max_dt)
            last = now
            taken += 1
            simulated += dt
            yield dt


# ----------------------------------------------------------------------------- loading
def read_scene_text(scene: str) -> tuple[str, str]:
    """(TOML text, source label) for a built-in name or a file path."""
    if scene in builtin_names():
        return builtin_text(scene), f"built-in scene '{scene}'"
    path = Path(scene)
    if not path.exists():
        close = difflib.get_close_matches(scene, builtin_names(), n=1)
        hint = f" Did you mean '{close[0]}'?" if close else ""
        raise UnknownSceneError(
            f"no built-in scene or file called '{scene}'.{hint} Built-in scenes: "
            + ", ".join(builtin_names()))
    if path.is_dir():
        raise UnknownSceneError(f"{scene}: is a directory; give a .toml scene file")
    try:
        if not path.is_file():
            raise UnknownSceneError(f"{scene}: not a regular file; give a .toml scene file")
        if path.stat().st_size > MAX_SCENE_BYTES:
            raise UnknownSceneError(f"{scene}: {path.stat().st_size} bytes is more than a scene file may be "
                                    f"({MAX_SCENE_BYTES // 2**20} MiB); make many particles with [generate]")
        return path.read_text(encoding="utf-8"), str(path)
    except (OSError, UnicodeDecodeError) as err:
        raise UnknownSceneError(f"{scene}: cannot read the file ({err})") from None


def read_scene(scene: str, overrides: list[str] | tuple[str, ...] = ()) -> Scene:
    """Load a built-in scene or a TOML file, apply ``key=value`` overrides, validate.
    Settings given as "auto" stay so: ``physdbg.api.load_scene`` reads and decides them."""
    text, source = read_scene_text(scene)
    return parse_scene(text, source, overrides)


# Strings and comments of TOML text (so the dots inside them are not counted as a key's),
# then a run of text between TOML's delimiters holding more dots than any scene key has.
_TOML_STRINGS_AND_COMMENTS = re.compile(r'"""[\s\S]*?"""|\'\'\'[\s\S]*?\'\'\'|"(?:[^"\\\n]|\\.)*"|\'[^\'\n]*\'|#[^\n]*')
# (anchored at a run's start, so each run is scanned once: linear time on any text)
_DEEP_KEY = re.compile(r"(?<![^=,{}\[\]\n])(?:[^=,{}\[\]\n.]*\.){%d}" % (MAX_NESTING + 2))


def _set_aside(match: re.Match) -> str:
    """A string as "" (its lines kept, so line numbers stay), a comment as nothing."""
    found = match.group()
    return "\n" * found.count("\n") if found.startswith("#") else '""' + "\n" * found.count("\n")


def _check_key_depth(text: str, source: str) -> None:
    """Refuse a dotted key deeper than any scene field *before* TOML parses it: Python's
    parser keeps every prefix of a dotted key, so a key 100,000 parts deep takes tens of
    GB. A value never has more than one dot in a row of text between TOML's delimiters
    (1.5, 07:32:00.5), and a scene key has at most MAX_NESTING parts; strings and comments
    are set aside first. Linear in the text, by regular expressions."""
    bare = _TOML_STRINGS_AND_COMMENTS.sub(_set_aside, text)
    found = _DEEP_KEY.search(bare)
    if found is not None:
        line = bare.count("\n", 0, found.start()) + 1
        raise SceneError(source, "", f"a dotted key on line {line} has more parts than any scene field "
                                     f"(at most {MAX_NESTING}): not read")


def parse_scene(text: str, source: str = "<scene>", overrides=()) -> Scene:
    """Validate TOML ``text`` (from ``source``) after applying overrides."""
    _check_key_depth(text, source)
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise SceneError(source, "", f"not valid TOML: {err}") from None
    except RecursionError:
        raise SceneError(source, "", f"nested more deeply than a scene can be ({MAX_NESTING} levels)") from None
    except ValueError as err:  # an integer of more digits than Python converts (sys.get_int_max_str_digits)
        raise SceneError(source, "", f"a number of more than {sys.get_int_max_str_digits()} digits: "
                                     f"not read (a scene's numbers are at most {MAX_MAGNITUDE:g})") from None
    raw = _renamed(raw, source)
    origins: dict[str, str] = {}
    for item in overrides:
        _apply_override(raw, item, source)
        key = item.split("=", 1)[0].strip()
        origins[RENAMED_SETTINGS.get(key, key)] = item
    _check_nesting(raw, source)
    scene = _validate(raw, source, origins)
    scene.overrides = tuple(overrides)
    return scene


def scene_from_dict(raw: dict, source: str, meshes: Meshes | None = None, overrides=()) -> Scene:
    """Validate an already-parsed scene table (the one kept in a recording, or a scene
    object a JavaScript engine's trace carries), after applying ``key=value`` overrides.
    meshes: the scene's meshes as recorded (state.Meshes), used instead of reading its
    [[meshes]] again (a recording keeps its triangles; the files may be gone)."""
    if not isinstance(raw, dict):
        raise SceneError(source, "", f"the scene is not a table (got {type(raw).__name__})")
    _check_nesting(raw, source)
    raw = _renamed(copy.deepcopy(raw), source)
    origins: dict[str, str] = {}
    for item in overrides:
        _apply_override(raw, item, source)
        key = item.split("=", 1)[0].strip()
        origins[RENAMED_SETTINGS.get(key, key)] = item
    scene = _validate(raw, source, origins, meshes)
    scene.overrides = tuple(overrides)
    return scene


# the settings a sphere scene's table always states (scene_table), whatever their values
_STATED_SETTINGS = ("integrator", "detection", "ordering", "gravity", "drag", "restitution_rule")


def scene_table(scene: Scene) -> dict:
    """The scene as an explicit table of its own fields (what a TOML scene holds, each
    value stated): dt (s) and steps as numbers, every sphere of ``[[particles]]`` (a
    [generate] made, each listed) with its position, velocity, radius, mass (or
    inverse_mass = 0: immovable), restitution and gravity_scale, and every wall as a
    ``[[planes]]`` entry (a closed [box] as its six planes), the settings that differ from
    the defaults and those in _STATED_SETTINGS. ``scene_from_dict`` reads it back to the
    same scene. For a sphere scene with a fixed dt only: meshes, periodic boxes and the
    partners of another collider kind are refused (SceneError), as a table of spheres and
    planes cannot hold them."""
    if len(scene.walls.meshes.corners):
        raise SceneError(scene.source, "meshes", "a scene with meshes is written whole only as TOML "
                                                 "(--format toml); as a table of spheres and planes it has no meshes")
    for kind, partners in scene.walls.partners.items():
        if len(partners):
            raise SceneError(scene.source, kind, f"a scene with {kind} partners is written whole only as TOML "
                                                 f"(--format toml); as a table of spheres and planes it has none")
    if scene.walls.periodic:
        raise SceneError(scene.source, "box.periodic", "a periodic box has no planes to write; the scene is written "
                                                       "whole only as TOML (--format toml)")
    if scene.dt is None:
        raise SceneError(scene.source, "dt", 'dt = "real" has no fixed step to write; give the scene a dt')
    st, walls, settings = scene.state, scene.walls, scene.settings
    table: dict[str, Any] = {"name": scene.name}
    if scene.description:
        table["description"] = scene.description
    table["dt"] = float(scene.dt)
    table["steps"] = int(scene.steps)
    defaults = dataclasses.asdict(_SETTINGS_DEFAULTS)
    for key in SETTING_RULES:
        value = getattr(settings, key)
        if key in _STATED_SETTINGS or value != defaults[key]:
            table[key] = list(value) if isinstance(value, tuple) else value
    if settings.max_memory != _SETTINGS_DEFAULTS.max_memory:
        table["max_memory"] = settings.max_memory
    particles = []
    for i in range(st.count):
        sphere: dict[str, Any] = {"position": st.positions[i].tolist(), "velocity": st.velocities[i].tolist(),
                                  "radius": float(st.radius[i])}
        if st.inverse_mass[i] > 0:
            sphere["mass"] = 1.0 / float(st.inverse_mass[i])
        else:
            sphere["inverse_mass"] = 0.0
        sphere["restitution"] = float(st.restitution[i])
        if st.gravity_scale[i] != 1.0:
            sphere["gravity_scale"] = float(st.gravity_scale[i])
        particles.append(sphere)
    table["particles"] = particles
    planes = []
    for k, name in enumerate(walls.names):
        plane: dict[str, Any] = {"name": name, "normal": walls.normals[k].tolist(),
                                 "offset": float(walls.offsets[k]), "restitution": float(walls.restitution[k])}
        if walls.two_sided[k]:
            plane["two_sided"] = True
            plane["thickness"] = float(walls.thickness[k])
        planes.append(plane)
    if planes:
        table["planes"] = planes
    return table


def _renamed(raw: dict, source: str) -> dict:
    """The scene table with each setting's old name (state.RENAMED_SETTINGS) read as its
    name now; a table that gives both is refused."""
    for old, new in RENAMED_SETTINGS.items():
        if old in raw:
            if new in raw:
                raise SceneError(source, old, f"{old} is the old name of {new}; give one of them, not both")
            raw = {(new if key == old else key): value for key, value in raw.items()}
    return raw


def _check_nesting(raw: dict, source: str) -> None:
    """Refuse structures nested deeper than any scene field (walked without recursion)."""
    stack: list[tuple[Any, str, int]] = [(raw, "", 0)]
    while stack:
        node, where, depth = stack.pop()
        if depth > MAX_NESTING:
            raise SceneError(source, where, f"nested more deeply than any scene field ({MAX_NESTING} levels)")
        if isinstance(node, dict):
            stack.extend((value, f"{where}.{key}" if where else str(key), depth + 1) for key, value in node.items())
        elif isinstance(node, list):
            stack.extend((value, f"{where}.{k}", depth + 1) for k, value in enumerate(node))


def _parse_value(text: str) -> Any:
    if _DEEP_KEY.search(_TOML_STRINGS_AND_COMMENTS.sub(_set_aside, text)):
        return text  # a dotted key deeper than any field: kept as text, refused by validation
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except (tomllib.TOMLDecodeError, ValueError):  # ValueError: an integer of over 4,300 digits
        return text
    except RecursionError:
        return None  # reported by the nesting check, which names the field


def _apply_override(raw: dict, item: str, source: str) -> None:
    if "=" not in item:
        raise SceneError(source, item, "an override must look like key=value, e.g. integrator=verlet")
    key, text = (part.strip() for part in item.split("=", 1))
    if not key:
        raise SceneError(source, item, "an override needs a field name before '='")
    key = RENAMED_SETTINGS.get(key, key)
    parts = key.split(".")
    if key in ("steps", "duration"):
        # the run length is given one way: overriding one replaces the other
        raw.pop("duration" if key == "steps" else "steps", None)
    node: Any = raw
    for depth, part in enumerate(parts):
        if not isinstance(node, (dict, list)):
            # a dotted key that walks on past a value (dt.x = 1): nothing there to set
            raise SceneError(source, key, f"--set {item}: '{'.'.join(parts[:depth])}' is a value ({node!r}), "
                                          f"not a table or array, so it has no field '{part}'")
        if depth == len(parts) - 1:
            break
        here = ".".join(parts[:depth + 1])
        if isinstance(node, list):
            if not part.isdigit() or int(part) >= len(node):
                raise SceneError(source, here, f"--set {item}: index must be 0..{len(node) - 1}")
            node = node[int(part)]
        else:
            if part not in node:
                if part in ("box", "generate"):
                    node[part] = {}
                else:
                    raise SceneError(source, here, f"--set {item}: the scene has no '{here}'")
            node = node[part]
    last = parts[-1]
    if isinstance(node, list):
        if not last.isdigit() or int(last) >= len(node):
            raise SceneError(source, key, f"--set {item}: index must be 0..{len(node) - 1}")
        node[int(last)] = _parse_value(text)
    else:
        node[last] = _parse_value(text)


# ----------------------------------------------------------------------------- validation
MAX_FIELDS_LISTED = 12  # an unknown field's message lists the allowed ones up to this many


def _some_fields(allowed: dict) -> str:
    """The tables among the allowed names, or the first few (what a newcomer looks for)."""
    tables = [name for name in allowed if name in ("box", "generate", "particles", "planes", "meshes")]
    return "tables among them: " + ", ".join(tables) if tables else "among them " + ", ".join(list(allowed)[:5])


class _Checker:
    """Small helpers that raise SceneError with the file, the field and what is allowed."""

    def __init__(self, source: str, origins: dict[str, str]):
        self.source = source
        self.origins = origins

    def fail(self, name: str, problem: str):
        origin = self.origins.get(name)
        if origin:
            problem = f"{problem} (set on the command line: --set {_clip(origin, 80)})"
        raise SceneError(self.source, name, problem)

    def known(self, table: dict, allowed: dict, prefix: str, docs: str = "docs/scenes.md") -> None:
        for key in table:
            if key not in allowed:
                if key in RENAMED:
                    self.fail(prefix + key, RENAMED[key])
                close = difflib.get_close_matches(str(key), list(allowed), n=1)
                if close:  # the likely fix, not a wall of every field
                    self.fail(prefix + key, f"unknown field; did you mean '{prefix}{close[0]}'? (every field: "
                                            f"{docs})")
                if len(allowed) <= MAX_FIELDS_LISTED:
                    self.fail(prefix + key, f"unknown field; allowed: {', '.join(allowed)}")
                self.fail(prefix + key, f"unknown field; the {len(allowed)} fields allowed here are listed in "
                                        f"docs/scenes.md ({_some_fields(allowed)})")

    def number(self, table, key, name, *, default=None, lo=None, hi=None, lo_open=False, integer=False,
               scale=False):
        """A number in range. Floats are finite and at most MAX_MAGNITUDE in size; integers at
        most MAX_INTEGER unless ``hi`` says; ``scale``: a length, mass or time something is
        divided by, so at least MIN_SCALE."""
        if scale:
            lo, lo_open = MIN_SCALE, False
        if hi is None:
            hi = MAX_INTEGER if integer else MAX_MAGNITUDE
        if lo is None and not integer:
            lo = -MAX_MAGNITUDE
        if key not in table:
            if default is None:
                self.fail(name, "is required: " + self._what(lo, hi, lo_open, integer))
            return default
        value = table[key]
        number = isinstance(value, (int, float)) and not isinstance(value, bool)
        # compare before converting: an integer too big for a float is out of range, not an overflow
        in_range = number and (not isinstance(value, float) or math.isfinite(value)) and (
            lo is None or (value > lo if lo_open else value >= lo)) and value <= hi
        expected = self._what(lo, hi, lo_open, integer)
        if integer and in_range and isinstance(value, float) and value.is_integer():
            # 1e6 and 100.0 are floats in TOML: say so, or "got 1e+12; expected <= 1e+12" reads as a
            # riddle (out of range, the range alone is said: its integer would be refused too)
            self.fail(name, f"got {_short(value)}, a float; expected {expected}, written without a decimal "
                            f"point or exponent (such as {int(value)})")
        if not in_range or (integer and not isinstance(value, int)):
            self.fail(name, f"got {_short(value)}; expected {expected}")
        return int(value) if integer else float(value)

    @staticmethod
    def _what(lo, hi, lo_open, integer):
        kind = "an integer" if integer else "a number"
        if lo is not None and hi is not None:
            return f"{kind} {'>' if lo_open else '>='} {lo:g} and <= {hi:g}"
        if lo is not None:
            return f"{kind} {'>' if lo_open else '>='} {lo:g}"
        return kind

    def vector(self, table, key, name, default=None):
        """[x, y, z], each finite and at most MAX_MAGNITUDE in size."""
        if key not in table:
            if default is None:
                self.fail(name, "is required: [x, y, z] (three numbers)")
            return np.array(default, dtype=np.float64)
        value = table[key]
        if (not isinstance(value, list) or len(value) != 3
                or any(isinstance(c, bool) or not isinstance(c, (int, float)) for c in value)
                or any(not (-MAX_MAGNITUDE <= c <= MAX_MAGNITUDE) for c in value)):
            self.fail(name, f"got {_short(value)}; expected [x, y, z] (three numbers, each between "
                            f"-{MAX_MAGNITUDE:g} and {MAX_MAGNITUDE:g})")
        return np.array(value, dtype=np.float64)

    def choice(self, table, key, name, options, default):
        value = table.get(key, default)
        if value not in options:
            close = difflib.get_close_matches(str(value), list(options), n=1)
            hint = f"did you mean '{close[0]}'? " if close else ""
            self.fail(name, f"got {_short(value)}; {hint}allowed: {', '.join(options)}")
        return value

    def boolean(self, table, key, name, default):
        value = table.get(key, default)
        if not isinstance(value, bool):
            self.fail(name, f"got {_short(value)}; expected true or false")
        return value

    def text(self, table, key, name, default):
        value = table.get(key, default)
        if not isinstance(value, str):
            self.fail(name, f"got {_short(value)}; expected text")
        return value

    def table(self, raw, key, name):
        value = raw.get(key, {})
        if not isinstance(value, dict):
            self.fail(name, f"expected a [{key}] table")
        return value

    def tables(self, raw, key, name):
        value = raw.get(key, [])
        if not isinstance(value, list) or not all(isinstance(t, dict) for t in value):
            self.fail(name, f"expected an array of [[{key}]] tables")
        return value


STEP_LENGTH_RANGE = f"between {MIN_SCALE:g} and {MAX_MAGNITUDE:g} s"  # what any dt a user gives may be


def step_length(value: Any) -> float | None:
    """A step's length (s) from a number or a number's text (a fraction such as "1/60"),
    or None when it is neither or outside STEP_LENGTH_RANGE: the one rule for every dt a
    user gives (a scene's ``dt``, each line of ``--dts``). Text is compared exactly, so
    "1e400" does not overflow."""
    if isinstance(value, str):
        try:
            exact = Fraction(value.strip())
        except (ValueError, ZeroDivisionError):
            return None
        return float(exact) if MIN_SCALE <= exact <= MAX_MAGNITUDE else None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not MIN_SCALE <= value <= MAX_MAGNITUDE:
        return None
    return float(value)


def _dt(c: _Checker, dt_raw: Any) -> float | None:
    """The time step (s) from a number, a fraction such as "1/60" (step_length), or "real" (None)."""
    if dt_raw is None:
        c.fail("dt", "is required: " + TOP_FIELDS["dt"])
    if dt_raw == "real":
        return None
    dt = step_length(dt_raw)
    if dt is None:
        c.fail("dt", f"got {_short(dt_raw)}; expected {TOP_FIELDS['dt']}, {STEP_LENGTH_RANGE}")
    return dt


def _short(value: Any, limit: int = 60) -> str:
    """repr of a value for a message, cut short (a 100-digit integer, a huge array)."""
    return _clip(repr(value), limit)


def _clip(text: str, limit: int) -> str:
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _meshes(c: _Checker, raw: dict, max_memory: float) -> Meshes:
    """The scene's [[meshes]], loaded (physdbg.meshes) and posed in the world."""
    from .engine.mesh import Pose
    from .errors import MeshError
    from .meshes import load_mesh

    names, restitution, corners, mesh_of, sources, notes = [], [], [], [], [], []
    velocity, angular_velocity, pivot, volumes = [], [], [], []
    folder = Path(c.source).parent if Path(c.source).is_file() else Path.cwd()
    for k, table in enumerate(c.tables(raw, "meshes", "meshes")):
        p = f"meshes.{k}."
        c.known(table, MESH_FIELDS, p)
        if ("shape" in table) == ("file" in table):
            c.fail(p + "shape", "give shape (a built-in shape) or file (an .obj or .stl file), not both or neither")
        if "shape" in table:
            from .meshes import SHAPES

            spec = c.choice(table, "shape", p + "shape", tuple(SHAPES), None)
        else:
            spec = str(folder / c.text(table, "file", p + "file", ""))
        name = c.text(table, "name", p + "name", f"mesh{k}")
        m = _read(c, table, p, MESH_RULES)
        position, rotation = m["position"], m["rotation"]
        if isinstance(table.get("scale"), list):
            scale = c.vector(table, "scale", p + "scale")
            if not np.all(scale >= MIN_SCALE):
                c.fail(p + "scale", f"got {scale.tolist()}; each of [x, y, z] must be between {MIN_SCALE:g} and "
                                    f"{MAX_MAGNITUDE:g}")
        else:
            scale = c.number(table, "scale", p + "scale", default=1.0, scale=True)
        restitution.append(m["restitution"])
        velocity.append(m["velocity"])
        angular_velocity.append(np.radians(m["angular_velocity"]))
        pivot.append(c.vector(table, "pivot", p + "pivot", tuple(position)))  # by default the mesh's position
        volumes.append(m["bounding_volume"])
        try:
            mesh = load_mesh(spec, name, max_memory=max_memory, hull=False)
        except MeshError as err:
            c.fail(p + ("shape" if "shape" in table else "file"), str(err))
        if mesh.skipped:
            notes.append(mesh.skipped_words())
        scaled = mesh.vertices * scale
        _check_scaled_mesh(c, p, mesh, scaled, scale)
        placed = Pose.of(position, rotation).apply(scaled)
        if not np.all(np.abs(placed) <= MAX_MAGNITUDE):
            c.fail(p + "position", f"the mesh reaches {np.abs(placed).max():.3g} m from the origin where it is placed; "
                                   f"every coordinate must be within ±{MAX_MAGNITUDE:g} m")
        corners.append(placed[mesh.faces])
        mesh_of.append(np.full(mesh.triangles, k, dtype=np.int64))
        names.append(name)
        sources.append(mesh.source)
    if not names:
        return Meshes()
    return Meshes(names, np.array(restitution), np.concatenate(corners), np.concatenate(mesh_of), sources, notes,
                  np.array(velocity), np.array(angular_velocity), np.array(pivot), volumes)


def _check_scaled_mesh(c: _Checker, p: str, mesh, scaled: np.ndarray, scale) -> None:
    """A scale that carries a mesh past the range of a coordinate, or flattens a triangle
    the file gives whole (below limits.MIN_AREA, or the mesh's own degenerate ratio),
    names the field: the engine would divide by such a triangle's normal."""
    from .meshes import degenerate

    reach = float(np.abs(scaled).max())
    if reach > MAX_MAGNITUDE:
        c.fail(p + "scale", f"scales the mesh to {reach:.3g} m from its origin; every coordinate must be within "
                            f"±{MAX_MAGNITUDE:g} m")
    flattened, _ = degenerate(scaled, mesh.faces)
    if flattened.any():
        first = int(np.argmax(flattened))
        c.fail(p + "scale", f"got {np.asarray(scale).tolist()}: it makes {int(flattened.sum()):,} of the mesh's "
                            f"triangles degenerate (the first is triangle {first} of {mesh.source}), too thin or "
                            f"smaller than {MIN_AREA:g} m² for a normal; scale each axis so that the "
                            f"triangles keep their shape")


# ----------------------------------------------------------------------------- rules
# What each field of a table may be, once: a rule reads its field through _Checker (which
# names the file, the field and what is allowed). ``default`` None means required, or, for
# an engine setting, the engine's own default (Settings); ``optional`` leaves a missing
# field None; ``auto`` lets a field be "auto" (the advisor decides: physdbg.advisor).
@dataclass(frozen=True)
class _Number:
    lo: float | None = None
    hi: float | None = None
    integer: bool = False
    scale: bool = False  # a length, mass or time something is divided by: at least MIN_SCALE
    default: Any = None
    optional: bool = False
    auto: bool = False

    def read(self, c: _Checker, table: dict, key: str, name: str, default: Any) -> Any:
        if (self.optional and key not in table) or (self.auto and table.get(key, "auto") == "auto"):
            return "auto" if self.auto else None
        return c.number(table, key, name, default=default, lo=self.lo, hi=self.hi, integer=self.integer,
                        scale=self.scale)


@dataclass(frozen=True)
class _Choice:
    # the allowed names, looked up at each read: they are the engine's own tables (a name
    # added to one, e.g. motion.INTEGRATOR_NAMES, is allowed with no change here)
    options: Callable[[], tuple[str, ...]]
    default: Any = None

    def read(self, c: _Checker, table: dict, key: str, name: str, default: Any) -> Any:
        return c.choice(table, key, name, self.options(), default)


@dataclass(frozen=True)
class _Vector:
    default: Any = None

    def read(self, c: _Checker, table: dict, key: str, name: str, default: Any) -> Any:
        return c.vector(table, key, name, default)


@dataclass(frozen=True)
class _Flag:
    default: Any = None

    def read(self, c: _Checker, table: dict, key: str, name: str, default: Any) -> Any:
        return c.boolean(table, key, name, default)


# the top-level fields read as they are (dt, the tables and the engine settings have their own)
TOP_RULES = {
    "max_dt": _Number(scale=True, default=0.05),
    "steps": _Number(lo=1, integer=True, optional=True),
    "duration": _Number(scale=True, optional=True),
    "seed": _Number(lo=0, hi=2**64 - 1, integer=True, default=0),
    "max_memory": _Number(lo=1, hi=1e18, default=DEFAULT_MAX_MEMORY),
    "max_particle_steps": _Number(lo=1, hi=1e18, default=DEFAULT_MAX_PARTICLE_STEPS),
    "method": _Choice(lambda: ("auto", "given"), default="given"),
}
# the engine's settings (Settings fields but max_memory, which TOP_RULES reads first)
SETTING_RULES = {
    "integrator": _Choice(lambda: (*INTEGRATOR_NAMES, "auto")),
    "detection": _Choice(lambda: (*DETECTION_NAMES, "auto")),
    "samples": _Number(lo=1, hi=MAX_SAMPLES, integer=True),
    "ordering": _Choice(lambda: (*ORDERING_NAMES, "auto")),
    "broad_phase": _Choice(lambda: BROAD_PHASE_NAMES),
    "gravity": _Vector(),
    "drag": _Number(hi=1, scale=True),
    "restitution_rule": _Choice(lambda: RESTITUTION_RULES),
    "rest_fraction": _Number(lo=0, hi=1),
    "rapid_contact_time": _Number(lo=0, auto=True),
    "rapid_contact_rule": _Choice(lambda: (*RAPID_RULES, "auto"), default="auto"),
    "contact_tolerance": _Number(scale=True),
    "sleep_speed": _Number(lo=0, auto=True),
    "sleep_time": _Number(scale=True),
    **{budget: _Number(lo=0 if budget in SIZED_BUDGETS else 1, integer=True) for budget in BUDGETS},
    "space_order": _Choice(lambda: SPACE_ORDER_NAMES),
    "mesh_search": _Choice(lambda: MESH_SEARCH_NAMES),
    "event_loop": _Choice(lambda: EVENT_LOOP_NAMES),
}
# [[planes]] (name's default is the plane's number: plane0, plane1, ...)
PLANE_RULES = {
    "normal": _Vector(),
    "offset": _Number(default=0.0),
    "restitution": _Number(lo=0, hi=1, default=1.0),
    "two_sided": _Flag(default=False),
    "thickness": _Number(lo=0, default=0.0),
}
# [[particles]] (mass and inverse_mass, one or the other, are read apart)
PARTICLE_RULES = {
    "position": _Vector(),
    "velocity": _Vector(default=[0.0, 0.0, 0.0]),
    "radius": _Number(scale=True),
    "restitution": _Number(lo=0, hi=1, default=1.0),
    "gravity_scale": _Number(default=1.0),
}


# [[meshes]] (shape or file, name, scale, which is a number or [x, y, z], and pivot, whose
# default is the mesh's position, are read apart)
MESH_RULES = {
    "position": _Vector(default=(0.0, 0.0, 0.0)),
    "rotation": _Vector(default=(0.0, 0.0, 0.0)),
    "restitution": _Number(lo=0, hi=1, default=1.0),
    "velocity": _Vector(default=(0.0, 0.0, 0.0)),
    "angular_velocity": _Vector(default=(0.0, 0.0, 0.0)),
    "bounding_volume": _Choice(lambda: BOUNDING_VOLUMES, default="auto"),
}
# [generate] (kind, count, packing_fraction, min and max depend on the kind: read apart)
GENERATE_RULES = {
    "radius": _Number(scale=True),
    "mass": _Number(scale=True, default=1.0),
    "restitution": _Number(lo=0, hi=1, default=1.0),
    "speed": _Number(lo=0, default=1.0),
}


def _read(c: _Checker, table: dict, prefix: str, rules: dict, defaults: dict | None = None) -> dict:
    """Every field of ``rules`` from ``table`` (its fields named ``prefix`` + key), in the
    rules' order; defaults: a default for a rule that has none of its own."""
    return {key: rule.read(c, table, key, prefix + key,
                           rule.default if rule.default is not None else (defaults or {}).get(key))
            for key, rule in rules.items()}


def _kind_tables() -> dict:
    """The scene's top-level tables of the collider kinds whose modules declare their
    fields (colliders.extra_kinds): name -> what the table is."""
    from .engine.colliders import extra_kinds

    return {name: f"array of [[{name}]] tables: partners of the collider kind '{name}' (docs/colliders.md)"
            for _code, name, _module in extra_kinds()}


def _kind_partners(c: _Checker, raw: dict) -> dict:
    """The [[<kind>]] tables of each collider kind whose module declares its fields
    (colliders.kinds.Field), as state.Partners by the kind's name (a kind with no table
    is absent)."""
    from .engine.colliders import extra_kinds
    from .engine.state import Partners

    out = {}
    for _code, kind, module in extra_kinds():
        tables = c.tables(raw, kind, kind)
        if not tables:
            continue
        allowed = {"name": f"text shown in events (default {kind}<k>)", **{f.name: f.meaning for f in module.FIELDS}}
        names, values = [], {f.name: [] for f in module.FIELDS}
        for k, table in enumerate(tables):
            p = f"{kind}.{k}."
            c.known(table, allowed, p, f"the kind's FIELDS in engine/colliders/{module.__name__.rsplit('.', 1)[1]}.py")
            names.append(c.text(table, "name", p + "name", f"{kind}{k}"))
            for f in module.FIELDS:
                if f.shape == ():
                    values[f.name].append(c.number(table, f.name, p + f.name, default=f.default, lo=f.lo, hi=f.hi,
                                                   lo_open=f.lo_open))
                else:
                    default = None if f.default is None else np.asarray(f.default, dtype=np.float64)
                    values[f.name].append(c.vector(table, f.name, p + f.name, default=default))
        out[kind] = Partners(names, {f.name: np.array(values[f.name], dtype=np.float64).reshape(-1, *f.shape)
                                     for f in module.FIELDS})
    return out


def _validate(raw: dict, source: str, origins: dict[str, str], meshes: Meshes | None = None) -> Scene:
    c = _Checker(source, origins)
    c.known(raw, {**TOP_FIELDS, **_kind_tables()}, "")
    name = c.text(raw, "name", "name", Path(source).stem if source.endswith(".toml") else "scene")
    description = c.text(raw, "description", "description", "")

    # time
    dt = _dt(c, raw.get("dt"))
    top = _read(c, raw, "", TOP_RULES)
    max_dt, steps, duration, seed = top["max_dt"], top["steps"], top["duration"], top["seed"]
    max_memory, max_particle_steps = top["max_memory"], top["max_particle_steps"]
    if steps is None and duration is None:
        c.fail("steps", "give steps (an integer >= 1) or duration (seconds > 0)")
    if steps is not None and duration is not None:
        c.fail("duration", "give steps or duration, not both")
    if steps is None and dt is not None:
        steps = max(1, math.ceil(duration / dt - 1e-9))  # both within range: finite

    d = _SETTINGS_DEFAULTS
    if top["method"] == "auto":
        d = dataclasses.replace(d, integrator="auto", detection="auto", ordering="auto")
    values = _read(c, raw, "", SETTING_RULES, dataclasses.asdict(d))
    values["gravity"] = tuple(values["gravity"].tolist())
    settings = Settings(**values, max_memory=max_memory)

    # walls
    names, normals, offsets, rest, two, thick = [], [], [], [], [], []
    for k, plane in enumerate(c.tables(raw, "planes", "planes")):
        p = f"planes.{k}."
        c.known(plane, PLANE_FIELDS, p)
        v = _read(c, plane, p, PLANE_RULES)
        normal = v["normal"]
        biggest = float(np.max(np.abs(normal)))
        if biggest == 0.0:
            c.fail(p + "normal", "must not be [0, 0, 0]")
        normal = normal / biggest  # first, so that squaring neither overflows nor underflows
        names.append(c.text(plane, "name", p + "name", f"plane{k}"))
        normals.append(normal / float(np.linalg.norm(normal)))
        offsets.append(v["offset"])
        rest.append(v["restitution"])
        two.append(v["two_sided"])
        thick.append(v["thickness"])
        if thick[-1] > 0 and not two[-1]:
            c.fail(p + "thickness", "only a two-sided wall has a thickness; set two_sided = true")
    box = c.table(raw, "box", "box")
    box_lo = box_hi = None
    periodic = np.zeros(3, dtype=bool)
    gas = isinstance(raw.get("generate"), dict) and raw["generate"].get("kind") == "gas"
    if box:
        c.known(box, BOX_FIELDS, "box.")
        periodic = _periodic_axes(c, box)
        e_box = c.number(box, "restitution", "box.restitution", default=1.0, lo=0, hi=1)
        if gas:
            for key in ("min", "max"):
                if key in box:
                    c.fail(f"box.{key}", 'generate.kind = "gas" makes its own box from packing_fraction; a [box] '
                                         'with a gas sets only periodic and restitution')
        else:
            box_lo = c.vector(box, "min", "box.min")
            box_hi = c.vector(box, "max", "box.max")
            if not np.all(box_hi > box_lo):
                c.fail("box.max", f"got {box_hi.tolist()}; must exceed box.min {box_lo.tolist()} on every axis")
    for k, normal in enumerate(normals):
        across = np.nonzero(periodic & (np.abs(normal) > 0))[0]
        if across.size:
            c.fail(f"planes.{k}.normal", f"got {normal.tolist()}; axis {'xyz'[int(across[0])]} is periodic "
                                         f"(box.periodic), so a plane's normal must have no component along it")

    # particles
    pos, vel, inv, rad, res, gs = [], [], [], [], [], []
    for k, part in enumerate(c.tables(raw, "particles", "particles")):
        p = f"particles.{k}."
        c.known(part, PARTICLE_FIELDS, p)
        v = _read(c, part, p, PARTICLE_RULES)
        pos.append(v["position"])
        vel.append(v["velocity"])
        rad.append(v["radius"])
        if "mass" in part and "inverse_mass" in part:
            c.fail(p + "mass", "give mass or inverse_mass, not both")
        if "inverse_mass" in part:
            inv.append(c.number(part, "inverse_mass", p + "inverse_mass", lo=0))
            if 0.0 < inv[-1] < 1.0 / MAX_MAGNITUDE:  # a mass past mass's own bound: its momentum overflows
                c.fail(p + "inverse_mass", f"got {inv[-1]:g}; expected 0 (immovable) or a number >= "
                                           f"{1.0 / MAX_MAGNITUDE:g} and <= {MAX_MAGNITUDE:g}")
        else:
            inv.append(1.0 / c.number(part, "mass", p + "mass", default=1.0, scale=True))
        if inv[-1] == 0.0 and np.any(vel[-1] != 0.0):
            c.fail(p + "velocity", "an immovable particle (inverse_mass = 0) must have velocity [0, 0, 0]")
        res.append(v["restitution"])
        gs.append(v["gravity_scale"])

    gen = c.table(raw, "generate", "generate")
    if gen:
        c.known(gen, GENERATE_FIELDS, "generate.")
        kind = c.choice(gen, "kind", "generate.kind", ("rain", "gas"), None)
    count = c.number(gen, "count", "generate.count", lo=0, integer=True) if gen else 0
    _check_resources(c, len(pos) + count, steps, max_memory, max_particle_steps)
    if gen:
        g = _generate(c, gen, kind, count, seed, box_lo, box_hi)
        if kind == "gas":
            box_lo, box_hi, e_gas = g.pop("box")
            e_box = e_box if box else e_gas
        pos += list(g["position"])
        vel += list(g["velocity"])
        rad += list(g["radius"])
        inv += list(g["inverse_mass"])
        res += list(g["restitution"])
        gs += [1.0] * len(g["radius"])
    period = np.zeros(3)
    if box_lo is not None:
        period = np.where(periodic, box_hi - box_lo, 0.0)
        smallest = 8.0 * max(rad, default=0.0)
        for axis in np.nonzero(periodic)[0]:
            if period[axis] < smallest:
                c.fail("box.periodic", f"the box is {period[axis]:g} m on periodic axis {'xyz'[axis]}, less than "
                                       f"4 diameters of the largest sphere ({smallest:g} m): a sphere would meet "
                                       f"its own image; make the box larger on that axis")
        for axis, label in enumerate("xyz"):
            if periodic[axis]:
                continue
            for sign, lim in ((1.0, box_lo), (-1.0, box_hi)):
                n = np.zeros(3)
                n[axis] = sign
                names.append(f"{label}{'-' if sign > 0 else '+'}")
                normals.append(n)
                offsets.append(sign * lim[axis])
                rest.append(e_box)
                two.append(False)
                thick.append(0.0)

    state = State(np.array(pos, dtype=np.float64).reshape(-1, 3), np.array(vel, dtype=np.float64).reshape(-1, 3),
                  np.array(inv), np.array(rad), np.array(res), np.array(gs))
    walls = Walls(names, np.array(normals, dtype=np.float64).reshape(-1, 3), np.array(offsets, dtype=np.float64),
                  np.array(rest, dtype=np.float64), np.array(two, dtype=np.bool_), np.array(thick, dtype=np.float64),
                  period, box_lo if box_lo is not None else np.zeros(3),
                  meshes if meshes is not None else _meshes(c, raw, max_memory), _kind_partners(c, raw))
    if len(walls.meshes) and walls.periodic:
        c.fail("meshes", "a scene with meshes has no periodic axis (box.periodic): a mesh is not repeated")
    if walls.periodic and settings.sleep_speed != "auto" and settings.sleep_speed > 0:
        c.fail("sleep_speed", f"got {settings.sleep_speed:g}; sleeping needs a box with no periodic axis "
                              f"(box.periodic): leave sleep_speed at 0 here")
    if walls.periodic:  # a sphere placed outside the box on a periodic axis is the same sphere inside it
        wrap_positions(state.positions, walls.period_origin, walls.period)
    # "auto" settings stay "auto" here: the advisor decides them (physdbg.advisor.decide),
    # and physdbg.api.load_scene reads and decides in one call
    return Scene(name, description, source, settings, dt, max_dt, steps, duration, seed, state, walls, raw)


def _periodic_axes(c: _Checker, box: dict) -> np.ndarray:
    """box.periodic as (3,) bool: true (every axis), false, or [x, y, z] of true/false."""
    value = box.get("periodic", False)
    if isinstance(value, bool):
        return np.full(3, value)
    if isinstance(value, list) and len(value) == 3 and all(isinstance(v, bool) for v in value):
        return np.array(value, dtype=bool)
    c.fail("box.periodic", f"got {_short(value)}; expected true, false or [x, y, z] of true/false "
                           f"(e.g. [true, true, false])")


def _check_resources(c: _Checker, particles: int, steps: int | None, max_memory: float,
                     max_particle_steps: float) -> None:
    """Refuse, before anything is allocated, a scene too big for the limits (max_memory,
    max_particle_steps), saying the estimate and how to raise the limit."""
    memory = particles * BYTES_PER_PARTICLE
    if memory > max_memory:
        c.fail("max_memory", f"{particles} particles need about {memory / 2**30:.3g} GiB while stepping "
                             f"(~{BYTES_PER_PARTICLE // 1024} KiB each), more than max_memory = {max_memory:.3g} "
                             f"bytes; use fewer particles or raise the limit, e.g. --set max_memory={memory * 1.5:.2g}")
    work = max(particles, 1) * (steps or 0)
    if work > max_particle_steps:
        c.fail("max_particle_steps", f"{steps} steps × {particles} particles = {work:.3g} particle-steps, more than "
                                     f"max_particle_steps = {max_particle_steps:.3g}; shorten the run (steps, "
                                     f"duration, dt) or raise the limit, e.g. --set max_particle_steps={work * 1.5:.2g}")


def _generate(c: _Checker, gen: dict, kind: str, count: int, seed: int, box_lo, box_hi) -> dict:
    """Particles for ``[generate]``, on randomly chosen cells of a jittered lattice, so none
    overlap and a gas starts uniform (cells are drawn without building the lattice)."""
    g = _read(c, gen, "generate.", GENERATE_RULES)
    radius, mass, restitution, speed = g["radius"], g["mass"], g["restitution"], g["speed"]
    rng = np.random.default_rng(seed)
    out: dict[str, Any] = {}
    if kind == "gas":
        for key in ("min", "max"):
            if key in gen:
                c.fail(f"generate.{key}", 'only for kind = "rain" (a gas makes its own box)')
        phi = c.number(gen, "packing_fraction", "generate.packing_fraction", lo=0, hi=0.45, lo_open=True)
        if count == 0:
            c.fail("generate.count", "a gas needs at least one particle (it sizes the box)")
        side = _gas_side(count, radius, phi)
        if not side <= MAX_MAGNITUDE:  # inf (or NaN) when phi is near the smallest float
            least = count * 4.0 / 3.0 * math.pi * radius**3 / MAX_MAGNITUDE**3
            c.fail("generate.packing_fraction", f"got {phi:g}: the box would be {side:.3g} m on a side, more than "
                                                f"{MAX_MAGNITUDE:g} m; give at least {least:.3g}")
        box_lo, box_hi = np.zeros(3), np.full(3, side)
        out["box"] = (box_lo, box_hi, restitution)
        velocities = rng.normal(size=(count, 3))
        velocities -= velocities.mean(axis=0) if count > 1 else 0.0
        rms = math.sqrt(float(np.mean(np.sum(velocities**2, axis=1)))) or 1.0
        velocities *= speed / rms
    else:
        if "packing_fraction" in gen:
            c.fail("generate.packing_fraction", "only for kind = \"gas\"")
        if ("min" in gen) != ("max" in gen):
            c.fail("generate.min" if "min" not in gen else "generate.max", "give both min and max, or neither")
        if "min" in gen:
            box_lo, box_hi = c.vector(gen, "min", "generate.min"), c.vector(gen, "max", "generate.max")
            if not np.all(box_hi > box_lo):
                c.fail("generate.max", f"got {box_hi.tolist()}; must exceed generate.min {box_lo.tolist()} on every "
                                       f"axis")
        if box_lo is None:
            c.fail("box", "generate.kind = \"rain\" fills the [box] (or the region generate.min, generate.max); "
                          "add a [box] table")
        directions = rng.normal(size=(count, 3))
        directions /= np.maximum(np.linalg.norm(directions, axis=1, keepdims=True), 1e-300)
        velocities = directions * (speed * (1.0 + 0.1 * rng.uniform(-1.0, 1.0, size=(count, 1))))
    per_axis = _lattice(box_lo, box_hi, radius)
    room = math.prod(per_axis)
    if room < count:
        c.fail("generate.count", _fit_advice(kind, count, radius, box_lo, box_hi, room))
    # cells at least 2r (+1 %) apart inside the box, drawn at random (uniform, no corner block)
    chosen = np.stack(np.unravel_index(rng.choice(room, size=count, replace=False), per_axis), axis=-1)
    shape = np.array(per_axis)
    inner_lo = box_lo + radius
    inner_hi = box_hi - radius
    extent = inner_hi - inner_lo
    step = np.where(shape > 1, extent / np.maximum(shape - 1, 1), 0.0)
    centre = np.where(shape > 1, inner_lo + chosen * step, 0.5 * (inner_lo + inner_hi))
    slack = np.maximum(step - 2.0 * radius, 0.0) * 0.45
    # neighbours differ by one cell on some axis, so they stay >= step - 2*slack >= 2r
    # apart there; clipping to the box moves other axes only along their own cell row
    positions = np.clip(centre + rng.uniform(-1.0, 1.0, size=centre.shape) * slack, inner_lo, inner_hi)
    out.update(position=positions, velocity=velocities, radius=np.full(count, radius),
               inverse_mass=np.full(count, 1.0 / mass), restitution=np.full(count, restitution))
    return out


LATTICE_SPACING = 2.02  # lattice cells are this many radii apart (2r + 1 %)
MAX_CELLS_PER_AXIS = 2**20  # more cells than particles can ever need; keeps indices in int64


def _lattice(box_lo, box_hi, radius: float) -> tuple[int, ...]:
    """Lattice cells per axis for spheres of ``radius`` inside the box (0s if none fit)."""
    extent = (np.asarray(box_hi) - np.asarray(box_lo)) - 2.0 * radius
    if np.any(extent < 0):
        return (0, 0, 0)
    return tuple(min(int(e // (LATTICE_SPACING * radius)) + 1, MAX_CELLS_PER_AXIS) for e in extent.tolist())


def _gas_side(count: int, radius: float, phi: float) -> float:
    """Side (m) of the cubic box that ``count`` spheres fill to packing fraction ``phi``."""
    return (count * 4.0 / 3.0 * math.pi * radius**3 / phi) ** (1.0 / 3.0)


def _largest(fits, lo: float, hi: float) -> float:
    """The largest x in [lo, hi] with fits(x), for fits true at lo and monotone (bisection)."""
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if fits(mid) else (lo, mid)
    return lo


def _round_sig(value: float, up: bool, digits: int = 3) -> float:
    """value rounded to ``digits`` significant digits, up or down (advice that must hold)."""
    if value == 0.0:
        return 0.0
    unit = 10.0 ** (math.floor(math.log10(abs(value))) - digits + 1)
    return (math.ceil(value / unit) if up else math.floor(value / unit)) * unit


def _fit_advice(kind: str, count: int, radius: float, box_lo, box_hi, room: int) -> str:
    """What to set, and to what, when ``count`` spheres do not fit."""
    said = f"{count} spheres of radius {radius:g} m do not fit (room for {room} spaced {LATTICE_SPACING}r apart)"
    if kind == "gas":
        phi = _largest(lambda p: math.prod(_lattice(np.zeros(3), np.full(3, _gas_side(count, radius, p)),
                                                    radius)) >= count, 1e-9, 0.45)
        return f"{said}; set generate.packing_fraction to at most {math.floor(phi * 1000) / 1000:g}"
    size = np.asarray(box_hi) - np.asarray(box_lo)
    fits_radius = _round_sig(_largest(lambda r: math.prod(_lattice(box_lo, box_hi, r)) >= count, 0.0, radius), False)
    scale = 1.0 / _largest(lambda f: f > 0 and math.prod(_lattice(box_lo, box_lo + size / f, radius)) >= count,
                           0.0, 1.0)
    bigger = [_round_sig(v, True) for v in (np.asarray(box_lo) + size * scale).tolist()]
    return (f"{said} in the box; set generate.radius to at most {fits_radius:g}, or make the box "
            f"{_round_sig(scale, True):g}x larger on each axis (box.max = {bigger} with box.min = {np.asarray(box_lo).tolist()})")
