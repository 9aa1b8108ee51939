"""Pressure and temperature from the collisions of a recorded run: an equation of state
read off a recording.

Each step's statistics hold the collisional virial W = Σ r_ab·J_a over its sphere–sphere
contacts (J·s) and the sum of the impulses at walls (N·s). Over the steps averaged, of
total time T, with kinetic energy K (time-averaged) of N moving spheres (kT = 2K/3N):

* **from the collisions**: Z = PV/(NkT) = 1 + ΣW / (2 ∫K dt) — the virial theorem for
  impulsive forces; it needs no walls and no volume;
* **from the walls** (scenes whose walls close a box): P = Σ wall impulses / (A T) with A
  the box's inside area, and Z = PV/(NkT) with V the box's volume.

The error bars are the standard error of the mean over BLOCKS consecutive blocks of steps
(collisions correlate over a few mean free times; blocks much longer than that are
independent). With walls, the density next to them differs from the bulk, so Z from the
collisions of a small walled gas is not quite the bulk's; a periodic box (``[box]
periodic = true``) has no walls and gives the bulk's (docs/pressure.md, the EOS table).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..events import NO_COLLISIONS, CollisionSums, collision_sums  # noqa: F401 (the step's sums, kept with the contacts)

BLOCKS = 10


def carnahan_starling(phi: float) -> float:
    """Z of the hard-sphere fluid at packing fraction phi (Carnahan & Starling 1969)."""
    return (1 + phi + phi * phi - phi**3) / (1 - phi) ** 3


def contact_value(phi: float) -> float:
    """g(σ), the pair distribution at contact, from Carnahan–Starling: Z - 1 = 4 phi g(σ)."""
    return (1 - phi / 2) / (1 - phi) ** 3


def enskog_collision_rate(phi: float, diameter: float, kT: float, mass: float) -> float:
    """Collisions per sphere per second in a hard-sphere fluid (Enskog): 4 n σ² g(σ)
    sqrt(π kT / m), with n = 6 phi / (π σ³) and g(σ) from Carnahan–Starling (1/s)."""
    density = 6 * phi / (math.pi * diameter**3)
    return 4 * density * diameter**2 * contact_value(phi) * math.sqrt(math.pi * kT / mass)


@dataclass
class EquationOfState:
    """What a run's collisions say. z_virial, z_virial_error: from the collisions; z_wall,
    z_wall_error: from the walls (None without a closed box); kT: J, time-averaged;
    packing_fraction: sphere volume / box volume (None without a box); z_carnahan_starling
    at that packing fraction (equal radii only); steps: (first, last) averaged over;
    collision_rate, collision_rate_error: sphere–sphere collisions per sphere per second;
    collision_rate_enskog: Enskog's at that packing fraction and kT (equal spheres only)."""

    z_virial: float
    z_virial_error: float
    z_wall: float | None
    z_wall_error: float | None
    kT: float
    packing_fraction: float | None
    z_carnahan_starling: float | None
    steps: tuple[int, int]
    collision_rate: float | None = None
    collision_rate_error: float | None = None
    collision_rate_enskog: float | None = None


def equation_of_state(rec, skip: float = 0.5) -> EquationOfState:
    """Z of a recording (physdbg.Recording) over its steps after the first ``skip`` fraction
    (the gas forgets how it was set up)."""
    first = max(1, int(rec.steps * skip) + 1)
    stats = rec.stats(first)
    if len(stats) < BLOCKS:
        raise ValueError(f"{len(stats)} steps to average; an equation of state needs at least {BLOCKS}")
    header = rec.header
    movable = header.inverse_mass > 0
    n = int(np.count_nonzero(movable))
    dt, kinetic = stats["dt"], stats["kinetic"]
    blocks = np.array_split(np.arange(len(stats)), BLOCKS)

    still = next((b for b in blocks if not (kinetic[b] * dt[b]).sum() > 0), None)
    if still is not None:  # e.g. a pile that fell asleep: no temperature to divide by
        raise ValueError(f"nothing moves in steps {first + int(still[0])}..{first + int(still[-1])}: "
                         f"no temperature, so no equation of state")

    def mean_and_error(values: np.ndarray) -> tuple[float, float]:
        return float(values.mean()), float(values.std(ddof=1) / math.sqrt(len(values)))

    z_blocks = np.array([1 + stats["virial"][b].sum() / (2 * (kinetic[b] * dt[b]).sum()) for b in blocks])
    z_virial, z_virial_error = mean_and_error(z_blocks)
    kT = float((2 * kinetic * dt).sum() / (3 * n * dt.sum()))
    box = header.walls.box()
    z_wall = z_wall_error = phi = z_cs = None
    if box is not None:
        side = box[1] - box[0]
        volume = float(np.prod(side))
        phi = float((4 / 3) * math.pi * np.sum(header.radius[movable] ** 3) / volume)
        if np.ptp(header.radius) == 0:
            z_cs = carnahan_starling(phi)
    if box is not None and not header.walls.periodic:
        area = 2 * float(side[0] * side[1] + side[1] * side[2] + side[0] * side[2])
        # P = wall impulses / (area × time); N kT = 2/3 of the time-averaged kinetic energy
        wall_blocks = np.array([(stats["wall_impulse"][b].sum() / (area * dt[b].sum())) * volume
                                / ((2 / 3) * (kinetic[b] * dt[b]).sum() / dt[b].sum()) for b in blocks])
        z_wall, z_wall_error = mean_and_error(wall_blocks)
    rate_blocks = np.array([2 * stats["collisions"][b].sum() / (n * dt[b].sum()) for b in blocks])
    rate, rate_error = mean_and_error(rate_blocks)
    enskog = None
    if z_cs is not None and np.ptp(header.inverse_mass[movable]) == 0:
        enskog = enskog_collision_rate(phi, 2 * float(header.radius[0]), kT, 1 / float(header.inverse_mass[movable][0]))
    return EquationOfState(z_virial, z_virial_error, z_wall, z_wall_error, kT, phi, z_cs, (first, rec.steps),
                           rate, rate_error, enskog)
