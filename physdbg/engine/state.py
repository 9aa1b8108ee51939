"""The world's data: particle state as a structure of arrays, walls, engine settings.

Nothing here knows about files: :mod:`physdbg.scene` builds these from TOML.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np

from .motion import INTEGRATOR_NAMES
from .toi import DETECTION_NAMES

ORDERING_NAMES = ("time", "index")


@dataclass
class Settings:
    """How the engine steps. Units: s, m, m/s, m/s².

    integrator: one of motion.INTEGRATOR_NAMES; detection: one of toi.DETECTION_NAMES;
    samples: k for ``sampled``; ordering: ``time`` or ``index``; gravity: (3,) m/s²;
    drag: d in v·d^t, in (0, 1] (1 = none); restitution_rule: see resolve.py;
    rest_speed: closing speed (m/s) at or below which a contact rests; contact_tolerance:
    allowed overlap / resting gap (m); max_events_per_step: cap on contacts per step.
    """

    integrator: str = "exact"
    detection: str = "swept"
    samples: int = 4
    ordering: str = "time"
    broad_phase: str = "auto"
    gravity: tuple[float, float, float] = (0.0, -9.81, 0.0)
    drag: float = 1.0
    restitution_rule: str = "min"
    rest_speed: float = 1e-3
    contact_tolerance: float = 1e-9
    max_events_per_step: int = 10_000

    @property
    def integrator_code(self) -> int:
        return INTEGRATOR_NAMES.index(self.integrator)

    @property
    def detection_code(self) -> int:
        return DETECTION_NAMES.index(self.detection)


@dataclass
class Walls:
    """W planes n·x = d (arrays of length W; normals (W, 3) unit).

    One-sided walls keep spheres where n·x - d >= r; two-sided walls are thin slabs of
    ``thickness`` centred on the plane that spheres bounce off from either side.
    """

    names: list[str] = field(default_factory=list)
    normals: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    offsets: np.ndarray = field(default_factory=lambda: np.zeros(0))
    restitution: np.ndarray = field(default_factory=lambda: np.zeros(0))
    two_sided: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.bool_))
    thickness: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def __len__(self) -> int:
        return len(self.names)


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


def state_hash(positions: np.ndarray, velocities: np.ndarray) -> str:
    """BLAKE2b-128 hex digest of the exact bytes of positions then velocities (float64, C order)."""
    h = hashlib.blake2b(digest_size=16)
    h.update(np.ascontiguousarray(positions, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(velocities, dtype=np.float64).tobytes())
    return h.hexdigest()


def energies(state: State, gravity: np.ndarray) -> tuple[float, float, np.ndarray]:
    """(kinetic J, potential J, momentum (3,) kg·m/s) over movable particles.

    Potential energy is -m (s_i g)·x_i: zero at the origin, so only its changes mean much.
    """
    movable = state.inverse_mass > 0
    m = 1.0 / state.inverse_mass[movable]
    v = state.velocities[movable]
    kinetic = 0.5 * float(np.sum(m * np.einsum("ij,ij->i", v, v)))
    g = state.gravity_scale[movable, None] * gravity[None, :]
    potential = -float(np.sum(m * np.einsum("ij,ij->i", g, state.positions[movable])))
    momentum = (m[:, None] * v).sum(axis=0) if m.size else np.zeros(3)
    return kinetic, potential, momentum
