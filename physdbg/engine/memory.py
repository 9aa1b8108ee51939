"""The memory budget of a world (``Settings.max_memory``), checked before anything grows.

What counts: the particles' own memory (BYTES_PER_PARTICLE each), the held-contact
store, the step's growable buffers (event queue, swept-test log, contact rows) and the
copies the step's events take of them (the contact rows for any observer, the test log
twice for one that reads the swept tests: the event's copy and its encoding). A growth
that would pass the limit is not made: the step records what it would have needed
(``StepContext.out_of_memory``, bytes) and stops like a budget, with the warning
``message`` writes.
"""

from __future__ import annotations

from .resting import grow_held
from .state import BYTES_PER_PARTICLE
from .step_context import StepContext, wants_swept_tests


class MemoryBudget:
    """max_memory (bytes) for a world of ``spheres`` spheres."""

    def __init__(self, limit: float, spheres: int):
        self.limit = limit
        self.spheres = spheres
        self.particle_bytes = spheres * BYTES_PER_PARTICLE

    def fits(self, ctx: StepContext, need: int) -> bool:
        """Whether the particles' own memory and ``need`` more bytes stay within the limit;
        if not, ctx.out_of_memory keeps the largest total asked for."""
        need += self.particle_bytes
        if need > self.limit:
            ctx.out_of_memory = max(ctx.out_of_memory, need)
            return False
        return True

    @staticmethod
    def buffer_bytes(ctx: StepContext, buffers, heap_room: int, test_room: int, contact_room: int) -> int:
        """The loop's buffers (timeline.Buffers) after growing by these rooms, and the
        copies the step's events will take of them: the contact rows for any observer, the
        test log for one that reads the swept tests (bytes)."""
        total, log, rows = buffers.bytes_after(heap_room, test_room, contact_room)
        # an observer of the swept tests holds the event's copy of the log and, recording
        # it, an encoding of about the same size (rain 2000 at --detail full with its
        # budgets raised peaked at 6.5 GB under max_memory = 4e9 counting the copy once)
        return (total + (rows if ctx.observer is not None else 0)
                + (2 * log if wants_swept_tests(ctx.observer) else 0))

    def ensure(self, ctx: StepContext, buffers, held, heap_room: int, test_room: int, contact_room: int) -> bool:
        """Grow the loop's buffers for this much more (Buffers.ensure), unless that would
        take the particles, the held contacts, the buffers and the events' copies of them
        past the limit: then nothing is allocated, ctx.out_of_memory holds what it would
        have needed (bytes), and False."""
        if not self.fits(ctx, _nbytes(held) + self.buffer_bytes(ctx, buffers, heap_room, test_room, contact_room)):
            return False
        buffers.ensure(heap_room, test_room, contact_room)
        return True

    def grow_held(self, ctx: StepContext, buffers, held):
        """The held-contact store grown (resting.grow_held: at most twice its size), or
        None (ctx.out_of_memory set) if that would not fit."""
        if not self.fits(ctx, 2 * _nbytes(held) + self.buffer_bytes(ctx, buffers, 0, 0, 0)):
            return None
        return grow_held(held)

    def message(self, ctx: StepContext) -> str:
        """What the warning says when the limit stopped a step."""
        logging = (" or record below --detail full (an observer of the swept tests keeps every test, misses "
                   "included)" if wants_swept_tests(ctx.observer) else "")
        return (f"max_memory reached: this step's buffers (event queue, swept-test log, contacts, held contacts) "
                f"would have taken the run to about {_bytes(ctx.out_of_memory)}, more than max_memory = "
                f"{self.limit:.3g} bytes (the {self.spheres} particles count ~{BYTES_PER_PARTICLE // 1024} KiB "
                f"each); the remaining contacts of the step were not resolved; raise it with --set "
                f"max_memory={max(ctx.out_of_memory * 1.5, self.limit * 2):.2g}{logging}")


def _bytes(count: float) -> str:
    """A size for a message: 950 kB, 1.26 MB, 4.1 GB (powers of 1000, as max_memory is given)."""
    for unit, size in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if count >= size:
            return f"{count / size:.3g} {unit}"
    return f"{count:.0f} bytes"


def _nbytes(arrays) -> int:
    return sum(a.nbytes for a in arrays)
