"""Peer engines: run a physdbg scene in pybullet or MuJoCo from the same initial state and
return the run as a foreign trajectory (record/foreign.py), so ``check-run``, ``diff`` and
``explain`` compare it with physdbg's exact run.

The scene is translated, not tuned: spheres keep their radius, mass and restitution; planes
become static planes (two-sided walls thin boxes of the wall's thickness); gravity and
drag carry over; friction is off (physdbg has none). What each engine then does with
contacts — pybullet's impulse solver with its restitution threshold, MuJoCo's soft
contacts — is what the comparison shows. Each adapter says what it set in ``notes``.

Both engines are optional extras (``pip install 'physdbg[peers]'``); a missing one is a
clear error naming the extra.
"""

from __future__ import annotations

import math
import os
from contextlib import contextmanager

import numpy as np

from .errors import PhysdbgError
from .record.foreign import ForeignRun

PEERS = ("pybullet", "mujoco")
WALL_EXTENT = 1000.0  # m: half-size of a thin wall's box, standing in for an infinite plane
MAX_PEER_BODY_STEPS = 20_000_000  # bodies × steps a peer run may take
CONTACT_STEPS = 4  # MuJoCo: a soft contact lasts this many steps (shorter is stiffer and less stable)


class PeerError(PhysdbgError):
    """A peer engine that is missing or cannot run the scene."""


@contextmanager
def _quiet_stdout():
    """pybullet prints its build time from C on import; keep the user's terminal clean."""
    import sys

    import ctypes

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


def run_peer(name: str, scene) -> tuple[ForeignRun, list[str]]:
    """Run ``scene`` (a physdbg Scene with a fixed dt) in peer ``name``: (run, notes)."""
    if name not in PEERS:
        raise PeerError(f"unknown peer {name!r}; choose one of {', '.join(PEERS)}")
    if scene.dt is None:
        raise PeerError(f"scene '{scene.name}' has dt = \"real\"; a peer run needs a fixed dt (--set dt=1/60)")
    if scene.walls.periodic:
        raise PeerError(f"scene '{scene.name}' has a periodic box, which {name} has no counterpart for; "
                        f"record-peer translates closed boxes and planes only")
    if scene.state.count * scene.steps > MAX_PEER_BODY_STEPS:
        bodies = "1 body" if scene.state.count == 1 else f"{scene.state.count} bodies"
        raise PeerError(f"{bodies} × {scene.steps} steps is more than a peer run may take "
                        f"({MAX_PEER_BODY_STEPS:,}); shorten the scene (--set steps=N)")
    return (_pybullet if name == "pybullet" else _mujoco)(scene)


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


def _pybullet(scene) -> tuple[ForeignRun, list[str]]:
    pb = _need("pybullet")
    st, walls, settings = scene.state, scene.walls, scene.settings
    client = pb.connect(pb.DIRECT)
    try:
        pb.setGravity(*settings.gravity, physicsClientId=client)
        pb.setTimeStep(scene.dt, physicsClientId=client)
        for normal, offset, thickness, two_sided, e in zip(walls.normals, walls.offsets, walls.thickness,
                                                             walls.two_sided, walls.restitution, strict=True):
            if two_sided:
                shape = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=[WALL_EXTENT, WALL_EXTENT,
                                                                          max(float(thickness) / 2, 1e-6)],
                                                physicsClientId=client)
            else:
                shape = pb.createCollisionShape(pb.GEOM_PLANE, physicsClientId=client)
            wall = pb.createMultiBody(0, shape, basePosition=(normal * offset).tolist(),
                                      baseOrientation=_plane_quaternion(normal), physicsClientId=client)
            pb.changeDynamics(wall, -1, restitution=float(e), lateralFriction=0.0, physicsClientId=client)
        bodies = []
        for x, v, inv, r, e in zip(st.positions, st.velocities, st.inverse_mass, st.radius, st.restitution,
                                   strict=True):
            shape = pb.createCollisionShape(pb.GEOM_SPHERE, radius=float(r), physicsClientId=client)
            body = pb.createMultiBody(1.0 / inv if inv > 0 else 0.0, shape, basePosition=x.tolist(),
                                      physicsClientId=client)
            pb.resetBaseVelocity(body, v.tolist(), [0.0, 0.0, 0.0], physicsClientId=client)
            # linear damping multiplies v by (1 − damping)^dt each step: physdbg's drag d^t
            pb.changeDynamics(body, -1, restitution=float(e), lateralFriction=0.0, rollingFriction=0.0,
                              spinningFriction=0.0, linearDamping=1.0 - float(settings.drag), angularDamping=0.0,
                              physicsClientId=client)
            bodies.append(body)
        n = len(bodies)
        xs, vs = np.empty((scene.steps + 1, n, 3)), np.empty((scene.steps + 1, n, 3))
        xs[0], vs[0] = st.positions, st.velocities
        for k in range(1, scene.steps + 1):
            pb.stepSimulation(physicsClientId=client)
            for i, body in enumerate(bodies):
                xs[k, i] = pb.getBasePositionAndOrientation(body, physicsClientId=client)[0]
                vs[k, i] = pb.getBaseVelocity(body, physicsClientId=client)[0]
        version = pb.getAPIVersion(physicsClientId=client)
    finally:
        pb.disconnect(client)
    notes = [f"pybullet (API {version}): one stepSimulation per step of {scene.dt:g} s; restitution per body and "
             f"wall (pybullet multiplies the two); friction off; linearDamping = 1 − drag"]
    return ForeignRun(_times(scene), xs, vs, f"pybullet:{scene.name}", "pybullet"), notes


def _mujoco(scene) -> tuple[ForeignRun, list[str]]:
    mujoco = _need("mujoco")
    st, walls, settings = scene.state, scene.walls, scene.settings
    dt = scene.dt

    def solref(e: float) -> str:
        """A spring–damper contact (MuJoCo's direct form: −stiffness −damping, per unit mass)
        that lasts CONTACT_STEPS steps and returns e of the closing speed: a damped spring
        does so when ζ = −ln e / √(π² + ln² e)."""
        e = min(max(e, 1e-6), 1.0)
        zeta = -math.log(e) / math.sqrt(math.pi ** 2 + math.log(e) ** 2)
        omega = math.pi / (CONTACT_STEPS * dt) / math.sqrt(1.0 - zeta ** 2)
        return f'solref="{-omega * omega!r} {-2.0 * zeta * omega!r}" solimp="0.99 0.99 0.001"'

    def fmt(vec) -> str:
        return " ".join(repr(float(c)) for c in vec)

    geoms = []
    for k, (normal, offset, thickness, two_sided, e) in enumerate(zip(
            walls.normals, walls.offsets, walls.thickness, walls.two_sided, walls.restitution, strict=True)):
        kind = (f'type="box" size="{WALL_EXTENT} {WALL_EXTENT} {max(float(thickness) / 2, 1e-6)!r}"' if two_sided
                else 'type="plane" size="0 0 1"')
        geoms.append(f'<geom name="wall{k}" {kind} pos="{fmt(normal * offset)}" zaxis="{fmt(normal)}" condim="1" '
                     f'{solref(float(e))}/>')
    damping = -math.log(settings.drag) if 0.0 < settings.drag < 1.0 else 0.0
    movable = []
    for i, (x, inv, r, e) in enumerate(zip(st.positions, st.inverse_mass, st.radius, st.restitution, strict=True)):
        geom = f'type="sphere" size="{float(r)!r}" condim="1" {solref(float(e))}'
        if inv > 0:
            mass = 1.0 / float(inv)
            geoms.append(f'<body name="b{i}" pos="{fmt(x)}"><joint type="free" damping="{damping * mass!r}"/>'
                         f'<geom {geom} mass="{mass!r}"/></body>')
            movable.append(i)
        else:
            geoms.append(f'<geom name="s{i}" pos="{fmt(x)}" {geom}/>')
    xml = (f'<mujoco><option timestep="{dt!r}" gravity="{fmt(settings.gravity)}"/>'
           f'<worldbody>{"".join(geoms)}</worldbody></mujoco>')
    try:
        model = mujoco.MjModel.from_xml_string(xml)
    except ValueError as err:
        raise PeerError(f"MuJoCo refused the translated scene: {err}") from None
    data = mujoco.MjData(model)
    for j, i in enumerate(movable):
        data.qvel[6 * j:6 * j + 3] = st.velocities[i]
    n = st.count
    xs, vs = np.empty((scene.steps + 1, n, 3)), np.empty((scene.steps + 1, n, 3))
    xs[:], vs[:] = st.positions, st.velocities
    for k in range(1, scene.steps + 1):
        mujoco.mj_step(model, data)
        for j, i in enumerate(movable):
            xs[k, i] = data.qpos[7 * j:7 * j + 3]
            vs[k, i] = data.qvel[6 * j:6 * j + 3]
    notes = [f"MuJoCo {mujoco.__version__}: one mj_step per step of {dt:g} s (its default integrator); soft "
             f"spring–damper contacts lasting {CONTACT_STEPS} steps, damped to return each geom's restitution "
             f"(MuJoCo mixes two geoms' solref by averaging); frictionless (condim 1); drag as free-joint damping"]
    return ForeignRun(_times(scene), xs, vs, f"mujoco:{scene.name}", "mujoco"), notes


__all__ = ["PEERS", "PeerError", "run_peer"]
