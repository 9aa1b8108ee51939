"""Contact resolution: the seed's impulse and wall reflection, with restitution.

Sphere–sphere (the seed)::

    n = (p_a - p_b) / |p_a - p_b|
    j = -(1 + c) ((v_a - v_b)·n) / (1/m_a + 1/m_b)
    v_a' = v_a + j n / m_a        v_b' = v_b - j n / m_b

with inverse masses w = 1/m (0 = immovable, so a post takes any impulse unmoved).

Sphere–wall: the seed's reflection R_r = R_i - 2N(R_i·N) with restitution c,
v' = v - (1 + c)(v·n) n (c = 1 is exactly the seed's mirror).

Restitution of a contact combines the two coefficients by the scene's
``restitution_rule``: ``min`` (default: a pair is as bouncy as its less bouncy member),
``max``, ``product`` or ``mean``.
"""

from __future__ import annotations

import math

import numpy as np

RESTITUTION_RULES = ("min", "max", "product", "mean")


def combine_restitution(rule: str, e_a: float, e_b: float) -> float:
    """The restitution of a contact between two materials (see module doc)."""
    if rule == "min":
        return min(e_a, e_b)
    if rule == "max":
        return max(e_a, e_b)
    if rule == "product":
        return e_a * e_b
    if rule == "mean":
        return 0.5 * (e_a + e_b)
    raise ValueError(f"unknown restitution rule {rule!r}")


def pair_impulse(v_a: np.ndarray, v_b: np.ndarray, w_a: float, w_b: float, normal: np.ndarray,
                 restitution: float) -> float:
    """Scalar impulse j (N·s) along ``normal`` (unit, from b to a); 0 unless approaching.

    v_a, v_b: (3,) velocities (m/s); w_a, w_b: inverse masses (1/kg).
    """
    closing = float(np.dot(v_a - v_b, normal))
    if closing >= 0.0 or w_a + w_b == 0.0:
        return 0.0
    return -(1.0 + restitution) * closing / (w_a + w_b)


def apply_pair_impulse(v: np.ndarray, inverse_mass: np.ndarray, a: int, b: int,
                       normal: np.ndarray, j: float) -> None:
    """v_a += j n w_a, v_b -= j n w_b, in place on the (N, 3) velocity array."""
    v[a] += (j * inverse_mass[a]) * normal
    v[b] -= (j * inverse_mass[b]) * normal


def reflect(v: np.ndarray, normal: np.ndarray, restitution: float) -> np.ndarray:
    """The seed's wall reflection with restitution: v - (1 + c)(v·n) n, if approaching."""
    vn = float(np.dot(v, normal))
    if vn >= 0.0:
        return v.copy()
    return v - (1.0 + restitution) * vn * normal


def unit(vector: np.ndarray) -> np.ndarray:
    """vector / |vector|; a zero vector gives +x (coincident centres need some normal)."""
    length = math.sqrt(float(np.dot(vector, vector)))
    if length == 0.0:
        return np.array([1.0, 0.0, 0.0])
    return vector / length
