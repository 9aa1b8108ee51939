"""The pure core: state arrays, integrators, swept tests, broad phase, resolution, stepping.

Imports numpy and numba only (and the standard library's math, hashlib, heapq);
knows nothing of files or viewers. Results leave through typed events
(:mod:`physdbg.events`) handed to an observer.
"""

from .broadphase import BROAD_PHASE_NAMES, BruteForce, choose_broad_phase, make_broad_phase
from .motion import INTEGRATOR_NAMES
from .resolve import RESTITUTION_RULES, combine_restitution
from .resting import RAPID_RULES
from .state import BUDGETS, ORDERING_NAMES, SIZED_BUDGETS, NonFiniteState, Settings, State, Walls, energies, state_hash
from .toi import DETECTION_NAMES
from .warm import warm_up
from .world import World

__all__ = [
    "BROAD_PHASE_NAMES", "BUDGETS", "BruteForce", "choose_broad_phase", "DETECTION_NAMES", "INTEGRATOR_NAMES", "ORDERING_NAMES",
    "NonFiniteState", "RAPID_RULES", "RESTITUTION_RULES", "SIZED_BUDGETS", "Settings", "State", "Walls", "World",
    "combine_restitution", "energies", "make_broad_phase", "state_hash", "warm_up",
]
