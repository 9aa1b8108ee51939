"""The pure core: state arrays, integrators, swept tests, broad phase, resolution, stepping.

Imports numpy and numba only (and the standard library's math, hashlib, heapq; and
physdbg.kernel_cache, which points numba's cache at this version's folder first);
knows nothing of files or viewers. Results leave through typed events
(:mod:`physdbg.events`) handed to an observer.
"""

from ..kernel_cache import use as _use_kernel_cache

_use_kernel_cache()  # before the first kernel is defined: numba places each one's cache then

from .broadphase import BROAD_PHASE_NAMES, BruteForce, choose_broad_phase, make_broad_phase  # noqa: E402
from .motion import INTEGRATOR_NAMES  # noqa: E402
from .resolve import RESTITUTION_RULES, combine_restitution  # noqa: E402
from .resting import RAPID_RULES  # noqa: E402
from .state import (  # noqa: E402
    BUDGETS, ORDERING_NAMES, SIZED_BUDGETS, NonFiniteState, Settings, State, Walls, energies, state_hash)
from .toi import DETECTION_NAMES  # noqa: E402
from .warm import warm_up  # noqa: E402
from .world import World  # noqa: E402

__all__ = [
    "BROAD_PHASE_NAMES", "BUDGETS", "BruteForce", "choose_broad_phase", "DETECTION_NAMES", "INTEGRATOR_NAMES", "ORDERING_NAMES",
    "NonFiniteState", "RAPID_RULES", "RESTITUTION_RULES", "SIZED_BUDGETS", "Settings", "State", "Walls", "World",
    "combine_restitution", "energies", "make_broad_phase", "state_hash", "warm_up",
]
