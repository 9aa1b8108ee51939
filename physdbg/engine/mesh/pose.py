"""A mesh's pose: where its local frame sits in the world (a rigid transform).

A pose is a position (3,) in m and a rotation (3, 3) whose columns are the local axes in
world coordinates: world = rotation @ local + position. Rotations are given in scenes and
on the command line as angles in degrees about the world's x, then y, then z axis
(R = Rz · Ry · Rx).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


def rotation_from_degrees(angles: np.ndarray | tuple[float, float, float]) -> np.ndarray:
    """(3, 3) rotation for angles (3,) in degrees about x, then y, then z (R = Rz·Ry·Rx)."""
    ax, ay, az = np.radians(np.asarray(angles, dtype=np.float64))
    cx, sx, cy, sy, cz, sz = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az), np.sin(az)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cx, -sx], [0.0, sx, cx]])
    ry = np.array([[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]])
    rz = np.array([[cz, -sz, 0.0], [sz, cz, 0.0], [0.0, 0.0, 1.0]])
    return rz @ ry @ rx


def rotation_about(angular_velocity: np.ndarray, time: float) -> np.ndarray:
    """(3, 3) rotation by |ω|·time radians about ω's direction (Rodrigues), for an angular
    velocity ω (3,) rad/s; the identity when ω = 0."""
    w = np.asarray(angular_velocity, dtype=np.float64).reshape(3)
    speed = float(np.sqrt(w @ w))
    if speed == 0.0 or time == 0.0:
        return np.eye(3)
    axis = w / speed
    angle = speed * time
    cross = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + np.sin(angle) * cross + (1.0 - np.cos(angle)) * (cross @ cross)


@dataclass(frozen=True)
class Pose:
    """Rigid transform: ``position`` (3,) m, ``rotation`` (3, 3) (columns: local axes in the world)."""

    position: np.ndarray = field(default_factory=lambda: np.zeros(3))
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))

    @classmethod
    def of(cls, position=(0.0, 0.0, 0.0), degrees=(0.0, 0.0, 0.0)) -> "Pose":
        """Pose at ``position`` (3,) m turned by ``degrees`` (3,) about x, y, z."""
        return cls(np.asarray(position, dtype=np.float64).reshape(3), rotation_from_degrees(degrees))

    def apply(self, points: np.ndarray) -> np.ndarray:
        """World coordinates (N, 3) of local points (N, 3)."""
        return np.ascontiguousarray(points @ self.rotation.T + self.position)

    @property
    def is_identity(self) -> bool:
        return bool(np.all(self.position == 0.0) and np.all(self.rotation == np.eye(3)))
