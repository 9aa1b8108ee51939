"""Peer engines: a physdbg scene built in pybullet or MuJoCo, from the same initial state,
the way their own users would set it up for the same physics; stepped for ``record-peer``
(a trajectory, record/foreign.py, that ``check-run``, ``diff`` and ``explain`` compare with
physdbg's exact run) and for the benchmarks (``benchmarks/box_rain.py``, ``physdbg bench
engines``), from this one module so the two never disagree.

The physics is physdbg's and nothing more: spheres keep their radius and mass; planes
become static planes (two-sided walls thin boxes of the wall's thickness); gravity and
drag carry over; **no friction** (physdbg's spheres have none) and no damping beyond the
scene's drag. Restitution is translated into each engine's own terms: pybullet multiplies
the two bodies' restitution, so each gets √e where the scene's e is one for all (the
scene's "min" rule otherwise: the notes say so); MuJoCo's contacts are soft, so each geom
gets a spring–damper that lasts CONTACT_STEPS steps and returns e of the closing speed.
What each engine then does — pybullet's impulse solver, MuJoCo's soft contacts — is what
the comparison shows. A ``PeerSetup`` names the solver settings: the benchmarks try each
engine's honest variants and keep the fastest (docs/benchmarks.md, "The peers").

Both engines are optional extras (``pip install 'physdbg[peers]'``); a missing one is a
clear error naming the extra.
"""

from __future__ import annotations

import math
import os
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from .errors import PeerError
from .record.foreign import ForeignRun

PEERS = ("pybullet", "mujoco")
WALL_EXTENT = 1000.0  # m: half-size of a thin wall's box, standing in for an infinite plane
MAX_PEER_BODY_STEPS = 20_000_000  # bodies × steps a peer run may take
CONTACT_STEPS = 4  # MuJoCo: a soft contact lasts this many steps (shorter is stiffer and less stable)
MUJOCO_SOLVERS = ("PGS", "CG", "Newton")





@dataclass(frozen=True)
class PeerSetup:
    """One way to set a peer up. engine: "pybullet" or "mujoco"; for MuJoCo: solver (PGS,
    CG or Newton), iterations, speculative (MuJoCo 4's speculative contacts, its continuous
    collision), sleep (MuJoCo 4's sleeping islands), midphase (its BVH midphase, on by
    default). pybullet keeps its own defaults (its solver, its sleeping); ccd turns on its
    continuous collision for the spheres (a swept sphere of 0.9 of each radius), each
    sphere then a rigid body (useMaximalCoordinates), the only kind Bullet's CCD acts on."""

    engine: str
    solver: str = "Newton"
    iterations: int = 100
    speculative: bool = False
    sleep: bool = False
    midphase: bool = True
    ccd: bool = False

    @property
    def label(self) -> str:
        if self.engine == "pybullet":
            return "pybullet +ccd" if self.ccd else "pybullet"
        flags = "".join(f" +{name}" for name in ("speculative", "sleep") if getattr(self, name))
        return f"mujoco {self.solver}-{self.iterations}{flags}{'' if self.midphase else ' -midphase'}"


# MuJoCo's own defaults (Newton, 100 iterations), frictionless: record-peer's setting, as a
# user would start; the benchmarks measure the other variants beside it
DEFAULT_SETUPS = {"pybullet": PeerSetup("pybullet"), "mujoco": PeerSetup("mujoco")}


@contextmanager
def _quiet_stdout():
    """pybullet prints its build time from C on import; keep the user's terminal clean."""
    import ctypes
    import sys

    sys.stdout.flush()
    sys.stderr.flush()
    saved, saved_err = os.dup(1), os.dup(2)
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 1)
            os.dup2(null.fileno(), 2)
            try:
                yield
            finally:
                ctypes.CDLL(None).fflush(None)  # C's buffered printf, before stdout comes back
    finally:
        os.dup2(saved, 1)
        os.dup2(saved_err, 2)
        os.close(saved)
        os.close(saved_err)


def _need(module: str):
    import importlib

    try:
        with _quiet_stdout():
            return importlib.import_module(module)
    except ImportError:
        raise PeerError(f"{module} is not installed: pip install 'physdbg[peers]' (or pip install {module})") from None


def available(engine: str) -> bool:
    """Whether the peer can be imported here."""
    try:
        _need(engine)
    except PeerError:
        return False
    return True


def check_scene(name: str, scene) -> None:
    """PeerError when the peer cannot run the scene (a real-time dt, a periodic box, too
    long)."""
    if name not in PEERS:
        raise PeerError(f"unknown peer {name!r}; choose one of {', '.join(PEERS)}")
    if scene.dt is None:
        raise PeerError(f"scene '{scene.name}' has dt = \"real\"; a peer run needs a fixed dt (--set dt=1/60)")
    if scene.walls.periodic:
        raise PeerError(f"scene '{scene.name}' has a periodic box, which {name} has no counterpart for; "
                        f"record-peer translates closed boxes and planes only")
    for kind, partners in scene.walls.partners.items():
        if len(partners):
            raise PeerError(f"scene '{scene.name}' has {kind} partners (a collider kind of physdbg's own), which "
                            f"record-peer does not translate for {name}: it translates spheres, planes and meshes")
    if scene.state.count * scene.steps > MAX_PEER_BODY_STEPS:
        bodies = "1 body" if scene.state.count == 1 else f"{scene.state.count} bodies"
        raise PeerError(f"{bodies} × {scene.steps} steps is more than a peer run may take "
                        f"({MAX_PEER_BODY_STEPS:,}); shorten the scene (--set steps=N)")


class PeerWorld:
    """A scene built in a peer: step() advances one scene step; positions() and
    velocities() are (N, 3) in the scene's order (immovable spheres where they started);
    notes say what the translation set; close() frees the engine."""

    notes: list[str]

    def step(self) -> None:
        raise NotImplementedError

    def positions(self) -> np.ndarray:
        raise NotImplementedError

    def velocities(self) -> np.ndarray:
        raise NotImplementedError

    def close(self) -> None:
        pass


def build(scene, setup: PeerSetup) -> PeerWorld:
    """The scene in the peer ``setup.engine`` (see the module doc)."""
    check_scene(setup.engine, scene)
    return (_Pybullet if setup.engine == "pybullet" else _Mujoco)(scene, setup)


def run_peer(name: str, scene, setup: PeerSetup | None = None) -> tuple[ForeignRun, list[str]]:
    """Run ``scene`` (a physdbg Scene with a fixed dt) in peer ``name``: (run, notes)."""
    check_scene(name, scene)
    world = build(scene, setup or DEFAULT_SETUPS[name])
    try:
        n = scene.state.count
        xs, vs = np.empty((scene.steps + 1, n, 3)), np.empty((scene.steps + 1, n, 3))
        xs[0], vs[0] = scene.state.positions, scene.state.velocities
        for k in range(1, scene.steps + 1):
            world.step()
            xs[k], vs[k] = world.positions(), world.velocities()
    finally:
        world.close()
    return ForeignRun(_times(scene), xs, vs, f"{name}:{scene.name}", name), world.notes


def _times(scene) -> np.ndarray:
    """Frame times as physdbg's world sums them (time += dt), so frames align exactly."""
    times = np.empty(scene.steps + 1)
    t = 0.0
    times[0] = 0.0
    for k in range(1, scene.steps + 1):
        t += scene.dt
        times[k] = t
    return times


def _plane_quaternion(normal: np.ndarray) -> list[float]:
    """(x, y, z, w) turning +z onto ``normal``."""
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, normal)
    s = float(np.linalg.norm(axis))
    if s < 1e-12:
        return [0.0, 0.0, 0.0, 1.0] if normal[2] > 0 else [1.0, 0.0, 0.0, 0.0]
    angle = math.atan2(s, float(z @ normal))
    axis = axis / s
    return [*(axis * math.sin(angle / 2)).tolist(), math.cos(angle / 2)]


def _restitution_factors(scene) -> tuple[np.ndarray, np.ndarray, np.ndarray, str]:
    """pybullet's restitution for each sphere, wall and mesh, whose products give the
    scene's: √e each where every body has the same e; otherwise each its own (pybullet's
    product, not the scene's rule, then decides: said in the notes)."""
    spheres, walls, meshes = scene.state.restitution, scene.walls.restitution, scene.walls.meshes.restitution
    every = np.concatenate([spheres, walls, meshes])
    if len(every) and np.all(every == every[0]):
        root = math.sqrt(float(every[0]))
        return (np.full(len(spheres), root), np.full(len(walls), root), np.full(len(meshes), root),
                f"√e = {root:.6g} on every body (e = {every[0]:g})")
    return spheres.copy(), walls.copy(), meshes.copy(), "each body its own e (pybullet multiplies two bodies' e; " \
                                                        f"the scene's rule is {scene.settings.restitution_rule})"


class _Pybullet(PeerWorld):
    def __init__(self, scene, setup: PeerSetup):
        pb = self.pb = _need("pybullet")
        st, walls, settings = scene.state, scene.walls, scene.settings
        e_spheres, e_walls, e_meshes, restitution_words = _restitution_factors(scene)
        self.client = client = pb.connect(pb.DIRECT)
        pb.setGravity(*settings.gravity, physicsClientId=client)
        pb.setTimeStep(scene.dt, physicsClientId=client)
        for normal, offset, thickness, two_sided, e in zip(walls.normals, walls.offsets, walls.thickness,
                                                             walls.two_sided, e_walls, strict=True):
            if two_sided:
                shape = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=[WALL_EXTENT, WALL_EXTENT,
                                                                          max(float(thickness) / 2, 1e-6)],
                                                physicsClientId=client)
            else:
                shape = pb.createCollisionShape(pb.GEOM_PLANE, physicsClientId=client)
            wall = pb.createMultiBody(0, shape, basePosition=(normal * offset).tolist(),
                                      baseOrientation=_plane_quaternion(normal), physicsClientId=client)
            pb.changeDynamics(wall, -1, restitution=float(e), lateralFriction=0.0, rollingFriction=0.0,
                              spinningFriction=0.0, physicsClientId=client)
        meshes = self.meshes = walls.meshes
        self.time, self.dt, self.kinematic = 0.0, scene.dt, []
        for k in range(len(meshes)):  # each mesh a triangle mesh of mass 0 with its base at its pivot
            corners = meshes.corners[meshes.mesh_of == k].reshape(-1, 3) - meshes.pivot[k]
            shape = pb.createCollisionShape(pb.GEOM_MESH, vertices=corners.tolist(),
                                            indices=list(range(len(corners))), physicsClientId=client)
            # a kinematic one a multibody whose base pose and velocity are set before each step
            # (a fixed base takes no impulse, and its velocity enters the contacts; a rigid
            # body of mass 0 ignores a velocity set so, and a ball falls through it)
            mesh = pb.createMultiBody(0, shape, basePosition=meshes.pivot[k].tolist(), physicsClientId=client)
            pb.changeDynamics(mesh, -1, restitution=float(e_meshes[k]), lateralFriction=0.0, rollingFriction=0.0,
                              spinningFriction=0.0, physicsClientId=client)
            if meshes.moving[k]:
                self.kinematic.append((k, mesh))
        shapes: dict[float, int] = {}
        self.bodies = []
        for x, v, inv, r, e in zip(st.positions, st.velocities, st.inverse_mass, st.radius, e_spheres, strict=True):
            if float(r) not in shapes:
                shapes[float(r)] = pb.createCollisionShape(pb.GEOM_SPHERE, radius=float(r), physicsClientId=client)
            # with CCD each sphere is a rigid body (maximal coordinates): Bullet's continuous
            # collision acts on a btRigidBody only; createMultiBody's default, a btMultiBody,
            # ignores ccdSweptSphereRadius (and clamps its speed to 100 m/s)
            body = pb.createMultiBody(1.0 / inv if inv > 0 else 0.0, shapes[float(r)], basePosition=x.tolist(),
                                      useMaximalCoordinates=setup.ccd, physicsClientId=client)
            pb.resetBaseVelocity(body, v.tolist(), [0.0, 0.0, 0.0], physicsClientId=client)
            # linear damping multiplies v by (1 − damping)^dt each step: physdbg's drag d^t
            pb.changeDynamics(body, -1, restitution=float(e), lateralFriction=0.0, rollingFriction=0.0,
                              spinningFriction=0.0, linearDamping=1.0 - float(settings.drag), angularDamping=0.0,
                              physicsClientId=client)
            if setup.ccd:
                pb.changeDynamics(body, -1, ccdSweptSphereRadius=0.9 * float(r), physicsClientId=client)
            self.bodies.append(body)
        version = pb.getAPIVersion(physicsClientId=client)
        self.notes = [f"pybullet (API {version}): one stepSimulation per step of {scene.dt:g} s, its default solver "
                      f"and sleeping; restitution {restitution_words}; friction off; linearDamping = 1 − drag, "
                      f"angularDamping 0" + ("; continuous collision on (each sphere a rigid body, useMaximalCoordinates, "
                                               "ccdSweptSphereRadius 0.9 r)" if setup.ccd
                                             else "")
                      + ("; each fixed mesh a static triangle mesh" if len(meshes) > len(self.kinematic) else "")
                      + ("; each kinematic mesh a fixed-base multibody whose pose (where the mesh is at the step's "
                         "start) and velocity are set before each step" if self.kinematic else "")]

    def step(self) -> None:
        from .engine.mesh.rigid_motion import turn_quaternion

        meshes = self.meshes
        for k, mesh in self.kinematic:
            pivot = meshes.pivot[k] + meshes.velocity[k] * self.time
            self.pb.resetBasePositionAndOrientation(mesh, pivot.tolist(),
                                                    turn_quaternion(meshes.angular_velocity[k], self.time).tolist(),
                                                    physicsClientId=self.client)
            self.pb.resetBaseVelocity(mesh, meshes.velocity[k].tolist(), meshes.angular_velocity[k].tolist(),
                                      physicsClientId=self.client)
        self.pb.stepSimulation(physicsClientId=self.client)
        self.time += self.dt

    def positions(self) -> np.ndarray:
        return np.array([self.pb.getBasePositionAndOrientation(b, physicsClientId=self.client)[0]
                         for b in self.bodies]).reshape(-1, 3)

    def velocities(self) -> np.ndarray:
        return np.array([self.pb.getBaseVelocity(b, physicsClientId=self.client)[0]
                         for b in self.bodies]).reshape(-1, 3)

    def close(self) -> None:
        if self.client is not None:
            self.pb.disconnect(self.client)
            self.client = None


class _Mujoco(PeerWorld):
    def __init__(self, scene, setup: PeerSetup):
        mujoco = self.mujoco = _need("mujoco")
        if setup.solver not in MUJOCO_SOLVERS:
            raise PeerError(f"MuJoCo has no solver {setup.solver!r}; choose one of {', '.join(MUJOCO_SOLVERS)}")
        st, walls, settings = scene.state, scene.walls, scene.settings
        dt = scene.dt

        def solref(e: float) -> str:
            """A spring–damper contact (MuJoCo's direct form: −stiffness −damping, per unit
            mass) that lasts CONTACT_STEPS steps and returns e of the closing speed: a damped
            spring does so when ζ = −ln e / √(π² + ln² e)."""
            e = min(max(e, 1e-6), 1.0)
            zeta = -math.log(e) / math.sqrt(math.pi ** 2 + math.log(e) ** 2)
            omega = math.pi / (CONTACT_STEPS * dt) / math.sqrt(1.0 - zeta ** 2)
            return f'solref="{-omega * omega!r} {-2.0 * zeta * omega!r}" solimp="0.99 0.99 0.001"'

        def fmt(vec) -> str:
            return " ".join(repr(float(c)) for c in vec)

        geoms = []
        for k, (normal, offset, thickness, two_sided, e) in enumerate(zip(
                walls.normals, walls.offsets, walls.thickness, walls.two_sided, walls.restitution, strict=True)):
            kind = (f'type="box" size="{WALL_EXTENT} {WALL_EXTENT} {max(float(thickness) / 2, 1e-6)!r}"'
                    if two_sided else 'type="plane" size="0 0 1"')
            geoms.append(f'<geom name="wall{k}" {kind} pos="{fmt(normal * offset)}" zaxis="{fmt(normal)}" condim="1" '
                         f'{solref(float(e))}/>')
        meshes = self.meshes = walls.meshes
        self.time, self.kinematic = 0.0, [k for k in range(len(meshes)) if meshes.moving[k]]
        assets = []
        for k in range(len(meshes)):  # MuJoCo collides with a mesh's convex hull: exact for a box-shaped slab
            corners = meshes.corners[meshes.mesh_of == k].reshape(-1, 3) - meshes.pivot[k]
            assets.append(f'<mesh name="mesh{k}" vertex="{fmt(corners.ravel())}"/>')
            geom = f'<geom name="meshgeom{k}" type="mesh" mesh="mesh{k}" condim="1" {solref(float(meshes.restitution[k]))}/>'
            # a kinematic mesh a mocap body (MuJoCo's way to move a body by hand), posed before each step
            geoms.append(f'<body name="mesh{k}" pos="{fmt(meshes.pivot[k])}"'
                         f'{" mocap=" + chr(34) + "true" + chr(34) if meshes.moving[k] else ""}>{geom}</body>')
        damping = -math.log(settings.drag) if 0.0 < settings.drag < 1.0 else 0.0
        self.movable = []
        for i, (x, inv, r, e) in enumerate(zip(st.positions, st.inverse_mass, st.radius, st.restitution,
                                               strict=True)):
            geom = f'type="sphere" size="{float(r)!r}" condim="1" {solref(float(e))}'
            if inv > 0:
                mass = 1.0 / float(inv)
                geoms.append(f'<body name="b{i}" pos="{fmt(x)}"><joint type="free" damping="{damping * mass!r}"/>'
                             f'<geom {geom} mass="{mass!r}"/></body>')
                self.movable.append(i)
            else:
                geoms.append(f'<geom name="s{i}" pos="{fmt(x)}" {geom}/>')
        flags = [f'{name}="enable"' for name in ("speculative", "sleep") if getattr(setup, name)]
        if not setup.midphase:
            flags.append('midphase="disable"')
        memory = max(64, 400 * st.count // 1000)  # MB: the default arena is too small for thousands of free bodies
        xml = (f'<mujoco><size memory="{memory}M"/>' + (f'<asset>{"".join(assets)}</asset>' if assets else '')
               + f'<option timestep="{dt!r}" gravity="{fmt(settings.gravity)}" '
               f'solver="{setup.solver}" iterations="{setup.iterations}"><flag {" ".join(flags)}/></option>'
               f'<worldbody>{"".join(geoms)}</worldbody></mujoco>')
        try:
            self.model = mujoco.MjModel.from_xml_string(xml)
        except ValueError as err:
            raise PeerError(f"MuJoCo refused the translated scene: {err}") from None
        self.data = mujoco.MjData(self.model)
        for j, i in enumerate(self.movable):
            self.data.qvel[6 * j:6 * j + 3] = st.velocities[i]
        self.start = st.positions.copy()
        self.index = np.array(self.movable, dtype=np.int64)
        self.notes = [f"MuJoCo {mujoco.__version__}: one mj_step per step of {dt:g} s, solver {setup.solver} with "
                      f"{setup.iterations} iterations" + "".join(f", {name} on" for name in ("speculative", "sleep")
                                                                 if getattr(setup, name))
                      + f"; soft spring–damper contacts lasting {CONTACT_STEPS} steps, damped to return each geom's "
                        f"restitution (MuJoCo mixes two geoms' solref by averaging); frictionless (condim 1); drag as "
                        f"free-joint damping" + ("; each mesh as its convex hull (MuJoCo's meshes are convex)"
                                                 if len(meshes) else "")
                      + ("; each kinematic mesh a mocap body posed where the mesh is at the step's start before each "
                         "step (MuJoCo gives a mocap body no velocity: its contacts push by their depth)"
                         if self.kinematic else "")]

    def step(self) -> None:
        from .engine.mesh.rigid_motion import turn_quaternion

        meshes = self.meshes
        for j, k in enumerate(self.kinematic):  # mocap bodies are numbered in the order of the bodies
            self.data.mocap_pos[j] = meshes.pivot[k] + meshes.velocity[k] * self.time
            x, y, z, w = turn_quaternion(meshes.angular_velocity[k], self.time)
            self.data.mocap_quat[j] = (w, x, y, z)  # MuJoCo's quaternions are w first
        self.mujoco.mj_step(self.model, self.data)
        self.time += self.model.opt.timestep

    def positions(self) -> np.ndarray:
        out = self.start.copy()
        out[self.index] = self.data.qpos.reshape(-1, 7)[:, :3]
        return out

    def velocities(self) -> np.ndarray:
        out = np.zeros_like(self.start)
        out[self.index] = self.data.qvel.reshape(-1, 6)[:, :3]
        return out


__all__ = ["DEFAULT_SETUPS", "MUJOCO_SOLVERS", "PEERS", "PeerError", "PeerSetup", "PeerWorld", "available", "build",
           "check_scene", "run_peer"]
