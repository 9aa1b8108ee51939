"""Rigid motion, the one module: a mesh's pose, a kinematic mesh's motion, its inverse
and the velocity and acceleration of its surface, in numpy (the scene, the analysis and
the views) and in numba (the compiled loop), the two forms tested against each other
(tests/test_rigid_motion.py).

A pose is a position (3,) in m and a rotation (3, 3) whose columns are the local axes in
world coordinates: world = rotation @ local + position. Rotations are given in scenes and
on the command line as angles in degrees about the world's x, then y, then z axis
(R = Rz · Ry · Rx).

A kinematic mesh moves rigidly from run time 0: its pivot P₀ at velocity v, its body
turning at ω (rad/s) about the pivot. A point c of the mesh at run time 0 is at
R(ω t)(c − P₀) + P₀ + v t at run time t (``transform``, ``placed``); a world point x at
time t is at R(−ω t)(x − P₀ − v t) + P₀ in the mesh's frame (``in_body_frame``, the
inverse); the mesh's surface at world point x moves at v + ω × (x − P(t))
(``surface_velocity``) and accelerates at ω × (ω × (x − P(t))) (``surface_acceleration``).
The compiled forms take the motion as one row (9,): the pivot (at the time counted from),
v and ω, and a time τ from then.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..jit import borrowing


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


def turn_quaternion(angular_velocity: np.ndarray, time: float) -> np.ndarray:
    """(4,) x, y, z, w: the quaternion of rotation_about(angular_velocity, time), the turn
    by |ω|·time about ω's direction (what pybullet and MuJoCo take a pose's turn as)."""
    w = np.asarray(angular_velocity, dtype=np.float64).reshape(3)
    speed = float(np.sqrt(w @ w))
    if speed == 0.0 or time == 0.0:
        return np.array([0.0, 0.0, 0.0, 1.0])
    half = 0.5 * speed * time
    return np.concatenate([w / speed * math.sin(half), [math.cos(half)]])


def transform(pivot: np.ndarray, velocity: np.ndarray, angular_velocity: np.ndarray,
              time: float) -> tuple[np.ndarray, np.ndarray]:
    """(rotation (3, 3), translation (3,)) carrying a moving body's run-time-0 points c to
    where they are at run time ``time``: R(ω t)·c + translation (pivot P₀ (3,) m, velocity
    v (3,) m/s, angular velocity ω (3,) rad/s)."""
    turn = rotation_about(angular_velocity, time)
    return turn, np.asarray(pivot, dtype=np.float64) + np.asarray(velocity, dtype=np.float64) * time - turn @ pivot


def placed(points: np.ndarray, pivot: np.ndarray, velocity: np.ndarray, angular_velocity: np.ndarray,
           time: float) -> np.ndarray:
    """(..., 3): a moving body's run-time-0 points where they are at run time ``time``:
    R(ω t)(c − P₀) + P₀ + v t."""
    turn = rotation_about(angular_velocity, time)
    return (points - pivot) @ turn.T + (pivot + velocity * time)


def surface_velocity_at(point: np.ndarray, pivot: np.ndarray, velocity: np.ndarray, angular_velocity: np.ndarray,
                        time: float) -> np.ndarray:
    """(3,) m/s: the velocity at run time ``time`` of a moving body's surface at world
    ``point`` (3,): v + ω × (point − P(time)) (``surface_velocity`` is the compiled form)."""
    arm = np.asarray(point, dtype=np.float64) - (pivot + velocity * time)
    return velocity + np.cross(angular_velocity, arm)


# ------------------------------------------------------------------ compiled forms
# A kinematic mesh moves rigidly: its pivot P at v_m and its body turning at ω about it. In
# the body's frame (the triangle's corners frozen where they were at the step's start) the
# centre is y(τ) = R(-ω·τ)(x - P - v_m·τ) + P, τ the time since the step began.

@borrowing
def turned(z0, z1, z2, k0, k1, k2, c, s):
    """z turned by the angle whose cosine and sine are c, s about the unit axis k (Rodrigues)."""
    kz = k0 * z0 + k1 * z1 + k2 * z2
    return (z0 * c + (k1 * z2 - k2 * z1) * s + k0 * kz * (1.0 - c),
            z1 * c + (k2 * z0 - k0 * z2) * s + k1 * kz * (1.0 - c),
            z2 * c + (k0 * z1 - k1 * z0) * s + k2 * kz * (1.0 - c))


@borrowing
def in_body_frame(p0, p1, p2, e0, e1, e2, motion, tau):
    """(y0, y1, y2, r0, r1, r2): a point p with rate e (m/s) at time ``tau`` s after the step
    began, seen from a mesh moving by ``motion`` (9,): its pivot at the step's start (m),
    its velocity (m/s) and its angular velocity (rad/s); y the point where the mesh was
    at the step's start, r its rate there."""
    z0 = p0 - motion[0] - motion[3] * tau
    z1 = p1 - motion[1] - motion[4] * tau
    z2 = p2 - motion[2] - motion[5] * tau
    w0, w1, w2 = motion[6], motion[7], motion[8]
    # the rate relative to the moving frame, before turning back: z' - ω×z
    q0 = e0 - motion[3] - (w1 * z2 - w2 * z1)
    q1 = e1 - motion[4] - (w2 * z0 - w0 * z2)
    q2 = e2 - motion[5] - (w0 * z1 - w1 * z0)
    speed = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    if speed == 0.0:
        return z0 + motion[0], z1 + motion[1], z2 + motion[2], q0, q1, q2
    c = math.cos(speed * tau)
    s = -math.sin(speed * tau)  # turned back by -|ω|·τ
    k0, k1, k2 = w0 / speed, w1 / speed, w2 / speed
    y0, y1, y2 = turned(z0, z1, z2, k0, k1, k2, c, s)
    r0, r1, r2 = turned(q0, q1, q2, k0, k1, k2, c, s)
    return y0 + motion[0], y1 + motion[1], y2 + motion[2], r0, r1, r2


@borrowing
def turned_with(d0, d1, d2, motion, tau):
    """A direction d fixed in a moving body (``motion`` as in_body_frame's) at τ = 0, as it
    points at ``tau``: d turned by R(ω·τ)."""
    w0, w1, w2 = motion[6], motion[7], motion[8]
    speed = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    if speed == 0.0:
        return d0, d1, d2
    return turned(d0, d1, d2, w0 / speed, w1 / speed, w2 / speed, math.cos(speed * tau), math.sin(speed * tau))


@borrowing
def surface_velocity(q0, q1, q2, motion, tau):
    """(u0, u1, u2) m/s: the velocity at time ``tau`` of the moving mesh's surface point at
    world point q: v_m + ω × (q - pivot(τ))."""
    r0 = q0 - motion[0] - motion[3] * tau
    r1 = q1 - motion[1] - motion[4] * tau
    r2 = q2 - motion[2] - motion[5] * tau
    w0, w1, w2 = motion[6], motion[7], motion[8]
    return (motion[3] + w1 * r2 - w2 * r1, motion[4] + w2 * r0 - w0 * r2, motion[5] + w0 * r1 - w1 * r0)


@borrowing
def surface_acceleration(q0, q1, q2, motion, tau):
    """(a0, a1, a2) m/s²: the acceleration at time ``tau`` of the moving mesh's surface
    point at world point q: ω × (ω × (q - pivot(τ))) (the velocity and ω are constant)."""
    r0 = q0 - motion[0] - motion[3] * tau
    r1 = q1 - motion[1] - motion[4] * tau
    r2 = q2 - motion[2] - motion[5] * tau
    w0, w1, w2 = motion[6], motion[7], motion[8]
    c0, c1, c2 = w1 * r2 - w2 * r1, w2 * r0 - w0 * r2, w0 * r1 - w1 * r0
    return w1 * c2 - w2 * c1, w2 * c0 - w0 * c2, w0 * c1 - w1 * c0



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
