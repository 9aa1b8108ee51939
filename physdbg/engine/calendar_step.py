"""A world's step taken from the event calendar (calendar.py): whether the calendar can
serve a step, and the step it takes.

World inherits these methods (``World.step`` asks ``_calendar_unfit`` each step of a
world with ``event_loop = "calendar"``, and takes the step here where it is None); they
stand apart from world.py as the calendar stands apart from the time-ordered loop
(timeline.py): the step the calendar takes is its own pipeline over the same step
context, sharing the world's begin, close and end of a step.
"""

from __future__ import annotations

from time import perf_counter

import numpy as np

from ..errors import StepStopped
from ..events import HOW_IMPULSE, BroadPhaseInfo, StepEnd
from . import calendar
from .colliders import CALENDAR_TAKES, KIND_NAMES, KINDS, PARTNER_IS_SPHERE, most_partners, partner_count
from .resolve import settle_held
from .resting import HELD, PINNED, STEP_RELEASED, STEP_WORK
from .sleep import SUPPORT_GAP
from .state import budget_message
from .step_context import StepContext, wants_mesh_search, wants_swept_tests
from .timeline import CONTACTS

# the broad phase a calendar step reports (BroadPhaseInfo): its lists stand in for one
CALENDAR_REASON = ("event_loop = calendar: each sphere's neighbours within its shell, listed again only when it "
                   "leaves it (engine/calendar.py)")


class CalendarSteps:
    """World's steps from the event calendar (the world's own state: ``_calendar``,
    ``calendar_steps``, ``calendar_unfit``, set up by World.__init__)."""

    def _calendar_unfit_by_scene(self) -> str | None:
        """Why the scene and settings keep the calendar (calendar.py) out of every step, or
        None: it needs paths whose anchor is their flow (motion.FLOW), the swept,
        time-ordered method and partners of the kinds it takes; the observer is judged
        each step (_calendar_unfit)."""
        s, st = self.settings, self._st
        if s.ordering != "time" or s.detection != "swept":
            return "it resolves contacts in time order from swept tests (ordering = time, detection = swept)"
        if not self._anchor_is_flow:
            return (f"the {s.integrator} integrator's path starts again at every step's end (re-anchoring changes it"
                    f"{' under drag' if self._drag != 1.0 else ''}: engine/motion.py, FLOW)")
        if self._kick_first and (self._drag != 1.0 or np.any(self._free_accel)):
            return f"the {s.integrator} integrator kicks every velocity at each step's start"
        for kind in range(KINDS):
            if not CALENDAR_TAKES[kind] and (PARTNER_IS_SPHERE[kind] or partner_count(kind, self._geometry)):
                return f"it does not take {KIND_NAMES[kind]} partners (colliders.CALENDAR_TAKES)"
        if self._meshes_move:
            return ("it does not take a kinematic mesh (its triangles move into shells whose lists were made "
                    "without them)")
        if calendar.periodic_axes_too_short(self._period, st.radius):
            return "a periodic axis is shorter than three neighbour lists' reach"
        return None

    def _calendar_unfit(self) -> str | None:
        """Why this step cannot use the calendar (None: it can)."""
        if self._calendar_settled_unfit is not None:
            return self._calendar_settled_unfit
        if wants_swept_tests(self.observer):
            return "the observer reads every step's swept tests, which it does not run"
        if self._walks_mesh_trees and wants_mesh_search(self.observer):
            return "the observer reads every step's search of the meshes' trees, which it does not make"
        return None

    def _calendar_step(self, ctx: StepContext) -> StepEnd:
        """One step taken from the event calendar (calendar.py): the held contacts settled
        at its start (the forces phase's rule), its events up to the step's end, then every
        sphere read from its anchor there. The calendar is made afresh when there is none,
        or when the state was written since the last step."""
        st, buf, dt = self._st, self._buf, ctx.dt
        started = perf_counter()
        buf.reset(keep_misses=False)
        self.held.count[STEP_WORK:STEP_RELEASED + 1] = 0  # this step's resting work, whole solves, releases
        cal = self._calendar
        fresh = cal is None or not (np.array_equal(cal.last_x, st.positions)
                                    and np.array_equal(cal.last_v, st.velocities))
        # the forces phase's rule where a contact is held, or was in the last step (one
        # released since leaves its spheres' accelerations to be made again from gravity)
        held_at_start = bool(self.held.count[HELD])
        renewed = self._settle_held_paths(ctx) if held_at_start or (cal is not None and cal.settle_next) else None
        if fresh:
            if renewed is not None:  # the paths the held contacts' solve gave
                x, v, a, acc, _spheres = renewed
            else:
                x, v, a, acc = st.positions, st.velocities, self._free_accel, self._free_accel
            cal = self._calendar = calendar.Calendar(x, v, a, st.radius, self._period, self._period_origin, self.time,
                                                     self._calendar_margin(), most_partners(self._geometry, 0),
                                                     self._calendar_delta)
            np.copyto(cal.acc, acc)
        ctx.path_accel = cal.a
        ctx.timings["forces"] = perf_counter() - started
        particles = cal.paths(st.radius, self._inverse_mass, st.restitution, self._last_contact)
        method = self._loop_method(cal.epoch, dt, ctx.vtol)
        started = perf_counter()
        if fresh:
            cal.build(particles, method, self._geometry, self.held, buf.counters)
        else:
            if renewed is not None:
                x, v, a, acc, spheres = renewed
                cal.renew(spheres, x, v, a, acc, particles, method, self._geometry, self.held, buf.counters)
            cal.expire_skips(particles, method, self._geometry, self.held, buf.counters)
        # the grid, the lists and the first predictions; or the held spheres' new paths and
        # the skips of the last step expired
        ctx.timings["broad_phase"] = perf_counter() - started
        ctx.timings["narrow_phase"] = 0.0  # (no step-wide narrow phase: each event predicts its own)
        started = perf_counter()
        status = self._calendar_events(ctx, cal, particles, method)
        rows = buf.contacts[:int(buf.counters[CONTACTS])]
        rows["time_in_step"] -= cal.now  # the resolver's times are the calendar's (since its epoch)
        cal.settle_next = bool(held_at_start or self.held.count[HELD] or np.any(rows["how"] != HOW_IMPULSE))
        ctx.timings["resolve"] = perf_counter() - started
        started = perf_counter()
        until = cal.now + dt
        cal.positions_at(until, self._integrator, self._drag, self._k, st.positions, st.velocities)
        cal.now = until
        ctx.pairs = cal.pairs()
        ctx.sigma = np.zeros(st.count)
        if ctx.observer is not None:
            ctx.observer.on_event(BroadPhaseInfo(ctx.step, "calendar", CALENDAR_REASON, {"pairs": len(ctx.pairs),
                                                                                        "scanned": False}, None))
        self._close(ctx)
        if status != calendar.DONE:
            self._calendar = None  # what it did not take is past: made afresh from the state next step
        else:
            if ctx.sleep_changed.size:  # fell asleep (immovable, still) or woke: new paths from here
                cal.renew(ctx.sleep_changed, st.positions, st.velocities, self._free_accel, self._free_accel,
                          particles, method, self._geometry, self.held, buf.counters)
            cal.last_x, cal.last_v = st.positions.copy(), st.velocities.copy()  # (the world's numbering)
            cal.tally[2] += 1
            fit = calendar.shell_fit(cal, st.radius, self._period, self._calendar_margin())
            if fit is not None:  # thicker shells for a dilute world, thinner for a dense one: made afresh
                self._calendar_delta = fit
                self._calendar = None
        self.calendar_steps += 1
        ctx.timings["finish"] = perf_counter() - started
        return self._end(ctx)

    def _calendar_margin(self) -> float:
        """How much farther than touching the calendar's lists reach (m): a sleeping world's
        as far as its support rules look (sleep.py), which read the lists as the step's pairs."""
        st = self._st
        return SUPPORT_GAP * 2.0 * float(st.radius.max()) if self.sleepers is not None and st.count else 0.0

    def _calendar_events(self, ctx: StepContext, cal: calendar.Calendar, particles: tuple, method: tuple) -> int:
        """The calendar's events up to the step's end, its buffers grown on demand within
        max_memory; a budget spent is warned of (the step then ends as it stands).
        Returns the calendar's status: DONE, CAPPED, RESTING_BUDGET."""
        st, buf = self._st, self._buf
        until = cal.now + ctx.dt
        cap = self.contact_cap
        while True:
            status = cal.run(until, particles, method, self._geometry, self.held, buf.contacts, buf.counters,
                             buf.changed, cap, calendar.MOST_EVENTS_PER_CONTACT * (cap + st.count), self.resting_budget)
            if status == calendar.GROW_CONTACTS and self._ensure(ctx, 0, 0, calendar.CONTACT_ROOM):
                continue
            if status == calendar.GROW_HELD and self._grow_held(ctx):
                continue
            break
        if status == calendar.STOPPED:
            raise StepStopped(self.step_index + 1)
        if status in (calendar.GROW_CONTACTS, calendar.GROW_HELD):
            ctx.warn("max_memory", self._memory.message(ctx))
            return calendar.CAPPED
        if status == calendar.CAPPED and not ctx.warnings:
            ctx.warn("max_contacts_per_step", budget_message("max_contacts_per_step", cap))
        if status == calendar.RESTING_BUDGET and not ctx.warnings:
            ctx.warn("max_resting_work_per_step", budget_message("max_resting_work_per_step", self.resting_budget))
        return status

    def _settle_held_paths(self, ctx: StepContext) -> tuple:
        """The forces phase's rule for held contacts (resolve.settle_held), from the state at
        the step's start, as the time-ordered loop takes it: released where their gaps
        opened, their accelerations solved, their approach taken out of the velocities.
        Returns (x, v, a, acc, spheres): positions, velocities (N, 3) after the solve, the
        path accelerations and accelerations (N, 3) m/s², and the spheres (int64) whose
        path that changes (a new velocity or acceleration, or a held contact released),
        which the calendar anchors again at the step's start."""
        st, s = self._st, self.settings
        held = self.held
        degree_before = held.deg.copy()
        v = st.velocities.copy()
        a = np.empty_like(st.velocities)
        acc = np.empty_like(st.velocities)
        particles = (st.positions, v, a, acc, st.radius, self._inverse_mass, st.restitution, np.zeros(st.count),
                     self._last_contact)
        method = self._loop_method(self.time, ctx.dt, ctx.vtol)
        if not settle_held(held, particles, method, self._geometry, self._free_accel, s.contact_tolerance,
                           self.resting_budget):
            if held.count[PINNED]:
                ctx.warn("pinned", *self._pinned_warning())
            else:
                ctx.warn("max_resting_work_per_step", budget_message("max_resting_work_per_step", self.resting_budget))
        cal = self._calendar
        previous_a = cal.a if cal is not None else self._free_accel
        spheres = np.flatnonzero((degree_before != held.deg) | np.any(a != previous_a, axis=1)
                                 | np.any(v != st.velocities, axis=1)).astype(np.int64)
        return st.positions, v, a, acc, spheres
