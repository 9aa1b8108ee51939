"""Periodic boundaries: the minimum image of a separation, and positions wrapped into the box.

A periodic axis c has a period L_c > 0 (m) and an origin o_c: a sphere leaving the box
through o_c + L_c comes back in through o_c, and every pair interacts through the image
of its separation that is shortest on that axis (the *minimum image*). ``period`` is a
(3,) array with 0 on axes that are not periodic, so one kernel serves every box.

Why the minimum image is exact here: every separation a step uses (a pair's relative
path from its anchors, a held contact's normal, an overlap) is between spheres whose
swept boxes overlap, and the world refuses a step in which a swept box is half a period
wide or more (``World``): then the true separation of such a pair is under L/2 on
every axis, at every instant of the step, and the minimum image is that separation.
Positions are wrapped once, at the end of each step, so the paths inside a step are
continuous.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .jit import kernel


@njit(cache=True, inline="always")
def image(d, length):
    """The minimum image of one component d (m) of a separation on an axis of period
    ``length`` (m; 0 = not periodic: d unchanged)."""
    if length > 0.0:
        return d - length * math.floor(d / length + 0.5)
    return d


@kernel
def wrap_positions(x, origin, period):
    """Wrap the positions x (N, 3) into [origin, origin + period) on each periodic axis, in place."""
    for c in range(3):
        length = period[c]
        if length > 0.0:
            o = origin[c]
            for i in range(x.shape[0]):
                u = x[i, c] - o
                if u < 0.0 or u >= length:
                    u -= length * math.floor(u / length)
                    if u >= length:  # rounding of a tiny negative u
                        u = 0.0
                    x[i, c] = o + u


def minimum_image(d: np.ndarray, period: np.ndarray) -> np.ndarray:
    """The minimum image of separations d (..., 3) (m) for a (3,) period (0 = not periodic)."""
    period = np.asarray(period, dtype=np.float64)
    if not np.any(period > 0):
        return d
    safe = np.where(period > 0, period, 1.0)
    return np.where(period > 0, d - safe * np.floor(d / safe + 0.5), d)


def unwrap_near(x: np.ndarray, reference: np.ndarray, period: np.ndarray) -> np.ndarray:
    """x (..., 3) moved by whole periods to the image nearest ``reference`` (same shape)."""
    return reference + minimum_image(x - reference, period)
