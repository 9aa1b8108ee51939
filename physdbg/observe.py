"""Observers: whoever listens to the engine.

The engine holds at most one observer and calls ``observer.on_event(event)`` for each
typed event of :mod:`physdbg.events`. Recorders, summaries and tests are observers;
:class:`FanOut` hands every event to several of them.

An observer that does not read ``SweptTests`` (every swept test of a step, misses
included: tens of millions in a dense step) says so with ``wants_swept_tests = False``;
the world then neither logs the misses nor sends the event (engine.world.wants_swept_tests);
so does one that does not read ``MeshSearch`` (every walk of the meshes' trees) with
``wants_mesh_search = False``. One that does not say gets every event.
"""

from __future__ import annotations

from typing import Protocol

from .events import ContactResolved, Contacts, EngineWarning, Event, StepBegin, StepEnd, SweptTests


class Observer(Protocol):
    def on_event(self, event: Event) -> None: ...
    # optional: wants_swept_tests, wants_mesh_search: bool (True when absent)


class FanOut:
    """Passes each event to every observer, in the order given."""

    def __init__(self, *observers: Observer):
        self.observers = [o for o in observers if o is not None]

    @property
    def wants_swept_tests(self) -> bool:
        """Whether any of the observers reads SweptTests (True for one that does not say)."""
        return any(getattr(o, "wants_swept_tests", True) for o in self.observers)

    @property
    def wants_mesh_search(self) -> bool:
        """Whether any of the observers reads MeshSearch (True for one that does not say)."""
        return any(getattr(o, "wants_mesh_search", True) for o in self.observers)

    def on_event(self, event: Event) -> None:
        for observer in self.observers:
            observer.on_event(event)


class ListObserver:
    """Keeps every event, grouped by type; for tests and small scripts."""

    def __init__(self) -> None:
        self.events: list[Event] = []

    def on_event(self, event: Event) -> None:
        self.events.append(event)

    def of_type(self, kind: type) -> list:
        return [e for e in self.events if isinstance(e, kind)]

    @property
    def contacts(self) -> list[ContactResolved]:
        """Every contact of every step, one record each (from the Contacts batches)."""
        return [record for batch in self.of_type(Contacts) for record in batch]

    @property
    def step_ends(self) -> list[StepEnd]:
        return self.of_type(StepEnd)

    @property
    def step_begins(self) -> list[StepBegin]:
        return self.of_type(StepBegin)

    @property
    def swept_tests(self) -> list[SweptTests]:
        return self.of_type(SweptTests)

    @property
    def warnings(self) -> list[EngineWarning]:
        return self.of_type(EngineWarning)
