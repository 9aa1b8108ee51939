"""check-run's judgements of the run as a whole and of its free flight (a mixin of
departure._Comparison, reading and writing its state): which integrator moved the bodies,
the drag the run applies, an immovable body that moved, the kicks (a velocity change the
forces do not explain) and physdbg's exact local step from the run's state, which every
other judgement compares with."""

from __future__ import annotations

import math

import numpy as np

from ..events import PARTNER_IS_SPHERE
from .departure_records import (Departure, family_of, FIT_SLACK, INTEGRATOR_FITS, integrator_of, Kick, KICK_FRACTION,
                                StepContact)


class FlightJudges:
    """The whole-run judgements and the readings the others use (kicks, local steps)."""

    # ------------------------------------------------------------------ integrator
    def _integrator(self, kicked: np.ndarray) -> dict | None:
        """Which integrator family moved the foreign bodies in their free steps (None when
        nothing accelerates, so every family moves them alike)."""
        r = self.runs
        if len(r.t) < 2 or not np.any(self.acc):
            return None
        free = ~kicked & np.isfinite(r.xf[1:]).all(axis=2) & np.isfinite(r.xf[:-1]).all(axis=2)
        free &= (self.inv > 0)[None, :]
        disp = r.xf[1:] - r.xf[:-1]
        v0, v1 = r.vf[:-1], r.vf[1:]
        if self.estimated:  # only step 1 has a known starting velocity (the scene's)
            free[1:] = False
            v0 = r.vr[:-1]
            v1 = v0 + self.acc[None, :, :] * r.dt[1:, None, None]
        if not free.any():
            return None
        dt = r.dt[1:, None, None]
        residual = {}
        for name, _, (w0, w1) in INTEGRATOR_FITS:
            miss = np.linalg.norm(disp - (w0 * v0 + w1 * v1) * dt, axis=2)[free]
            residual[name] = float(np.sqrt(np.mean(miss ** 2)))
        ranked = sorted(residual, key=residual.get)
        best, second = ranked[0], ranked[1]
        a = float(np.max(np.linalg.norm(self.acc, axis=1)))
        step_error = 0.5 * a * float(np.median(r.dt[1:])) ** 2
        if residual[best] > 0.25 * step_error + FIT_SLACK:
            words = (f"none of the usual integrators fits its free steps (the nearest, {best}, misses by "
                     f"{residual[best]:.3g} m a step on average): forces or drag differ from the scene's")
            return {"name": None, "residual": residual, "differs": True, "sentence": words}
        ours = family_of(self.settings.get("integrator", integrator_of(None)))
        described = dict((n, w) for n, w, _ in INTEGRATOR_FITS)[best]
        differs = best != ours
        sentence = f"your engine moves bodies like {described}"
        if differs:
            sentence += (f"; the scene's integrator ({self.settings.get('integrator')}) is {ours or 'of no family here'}, "
                         f"so in free flight "
                         f"under {a:.3g} m/s² the paths part by {step_error:.3g} m a step (a·dt²/2), growing as "
                         f"they go")
        else:
            sentence += f", the same family as the scene's integrator ({self.settings.get('integrator')})"
        if residual[second] - residual[best] < 1e-3 * step_error:
            sentence += "; its free steps fit two families equally, so this is a guess"
        return {"name": best, "residual": residual, "differs": differs, "sentence": sentence,
                "physdbg": ours, "step_error": step_error}

    # ------------------------------------------------------------------ kicks
    def _kick_sizes(self) -> np.ndarray:
        """(F-1, N) |Δv − the forces' Δv| over each step (estimated velocities: between
        the step's average and the next step's, assigned to the step's end)."""
        r = self.runs
        if self.estimated:
            out = np.zeros((len(r.t) - 1, r.xf.shape[1]))
            if len(r.t) > 2:
                change = r.vf[2:] - r.vf[1:-1] - self.acc[None, :, :] * r.dt[2:, None, None]
                out[:-1] = np.linalg.norm(change, axis=2)
            return np.nan_to_num(out, nan=0.0)
        dt = r.dt[1:, None, None]
        factor = self._decay(dt)
        forces = r.vf[:-1] * (factor - 1.0) + self.acc[None, :, :] * dt
        return np.nan_to_num(np.linalg.norm(r.vf[1:] - r.vf[:-1] - forces, axis=2), nan=0.0)

    def _change_beyond_forces(self, s: int, b: int) -> float:
        """|Δv − the forces' Δv| (m/s) of body b over step s, as _kick_sizes reads it."""
        r = self.runs
        if self.estimated:
            if s + 1 >= len(r.t):
                return 0.0
            change = r.vf[s + 1, b] - r.vf[s, b] - self.acc[b] * r.dt[s + 1]
        else:
            change = r.vf[s, b] - r.vf[s - 1, b] - (r.vf[s - 1, b] * (self._decay(r.dt[s]) - 1.0) + self.acc[b] * r.dt[s])
        return float(np.nan_to_num(np.linalg.norm(change), nan=0.0))

    def _decay(self, dt):
        """Drag's factor on the velocity over steps of dt (s): the scene's d^dt, or, once
        the run was found to apply drag its own way (_measure_drag), the run's, so that
        its drag is not taken for a contact in every step."""
        if self.run_decay is not None:
            return self.run_decay + 0.0 * dt
        return self.drag ** dt if 0.0 < self.drag < 1.0 else 1.0 + 0.0 * dt

    def _measure_drag(self) -> None:
        """The run's velocity decay per step in free flight, against the scene's drag
        v·d^dt (the seed: "incorporate time so drag changes if the frame rate varies"):
        a run that multiplies by d every step (drag-per-step) or not at all (drag-ignored)
        is named once, with the decay it shows, and its kicks are then measured with it."""
        self.run_decay = None
        r = self.runs
        if self.estimated or not 0.0 < self.drag < 1.0 or len(r.t) < 2:
            return
        v0, v1, dt = r.vf[:-1], r.vf[1:], r.dt[1:, None]
        speed2 = np.einsum("fij,fij->fi", v0, v0)
        moving = (self.inv > 0)[None, :] & np.isfinite(speed2) & (speed2 > 0) & np.isfinite(v1).all(axis=2)
        if not moving.any():
            return
        ratio = np.einsum("fij,fij->fi", v1 - self.acc[None, :, :] * dt[:, :, None], v0) / np.where(moving, speed2, 1)
        measured = ratio[moving]
        wanted = np.broadcast_to(self.drag ** dt, ratio.shape)[moving]
        mistakes = (("drag-per-step", np.full(measured.shape, self.drag)), ("drag-ignored", np.ones(measured.shape)))
        fits = {name: float(np.median(np.abs(measured - predicted))) for name, predicted in mistakes}
        if float(np.median(np.abs(measured - wanted))) <= 1e-9:
            return
        name = min(fits, key=fits.get)
        if fits[name] > 1e-9:
            return  # neither mistake: the integrator or the forces (drift, named later)
        self.run_decay = self.drag if name == "drag-per-step" else 1.0
        step = float(np.median(r.dt[1:]))
        k = int(np.flatnonzero(moving.any(axis=1))[0]) + 1
        body = int(np.flatnonzero(moving[k - 1])[0])
        if name == "drag-per-step":
            text = (f"your run multiplies the velocity by {float(np.median(measured)):.6g} every step, the drag "
                    f"d = {self.drag:g} itself; the seed's drag is v·d^t, so a step of {step:.4g} s takes "
                    f"d^dt = {self.drag ** step:.6g}. Drag per step makes the motion depend on the frame rate: "
                    f"at {1 / step:.3g} steps a second the speed falls to {self.drag ** (1 / step):.3g} of itself in "
                    f"one second instead of {self.drag:g}")
            advice = "multiply by d**dt (the time of the step), not by d: v = v * drag ** dt"
        else:
            text = (f"your run keeps the velocity in free flight (a decay of {float(np.median(measured)):.6g} a "
                    f"step) where the scene's drag d = {self.drag:g} takes d^dt = {self.drag ** step:.6g} a step")
            advice = "apply the scene's drag every step: v = v * drag ** dt"
        self.departures.append(Departure(name, k, body, text, advice,
                                         evidence={"measured": float(np.median(measured)), "drag": self.drag,
                                                   "expected": float(self.drag ** step), "dt": step}))

    def _immovable_moved(self) -> None:
        """An immovable sphere (inverse mass 0) that the run moves: named at the step it
        starts to move, with the sphere that hit it there in physdbg's run."""
        r = self.runs
        fixed = np.flatnonzero(self.inv == 0)
        if not len(fixed) or len(r.t) < 2:
            return
        moved = np.linalg.norm(r.xf[:, fixed] - r.xf[:1, fixed], axis=2) > self.atol
        moved |= np.linalg.norm(r.vf[:, fixed], axis=2) > self.atol
        frames, which = np.nonzero(moved)
        if not len(frames):
            return
        k, body = max(int(frames[0]), 1), int(fixed[which[0]])
        speed = float(np.linalg.norm(r.vf[k, body]))
        hit = None
        local = self._local_step(k)
        if local is not None:
            hit = next((c.other if c.a == body else c.a for c in local[2]
                        if PARTNER_IS_SPHERE[c.kind] and body in (c.a, c.other)), None)
        self.departures.append(Departure(
            "immovable-moved", k, body,
            f"sphere {body} is immovable (inverse mass 0 in the scene), yet your run moves it from step {k} on "
            f"({speed:.3g} m/s at its end" + (f", after sphere {hit} hit it" if hit is not None else "") + ")",
            "an immovable body takes no impulse: scale each impulse by the body's inverse mass (0 for an immovable "
            "one), never by a mass of 1 or by 1/m with m = 0", other=hit,
            evidence={"speed": speed, "hit_by": hit}))

    def _kick_thresholds(self) -> np.ndarray:
        r = self.runs
        speed = np.nan_to_num(np.linalg.norm(r.vf[:-1], axis=2))
        return KICK_FRACTION * (speed + np.linalg.norm(self.acc, axis=1)[None, :] * r.dt[1:, None]) + 1e-12

    def _kicks(self, kicked: np.ndarray) -> dict[tuple[int, int], Kick]:
        """{(step, body): the Kick of that body in that step}."""
        r = self.runs
        steps, bodies = np.nonzero(kicked)
        out = {}
        for s0, i in zip(steps.tolist(), bodies.tolist(), strict=True):
            s = s0 + 1
            tau = self._kick_time(s, i)
            out[(s, i)] = Kick(s, i, tau, float(r.t[s - 1] + tau))
        return out

    def _kick_time(self, s: int, i: int) -> float:
        """When in step s body i was kicked (s after the step began): the instant that
        splits the step's displacement between the velocity before and after the kick."""
        r = self.runs
        dt = float(r.dt[s])
        if self.estimated:
            return dt  # the change shows between two step averages: at the frame between them
        fit = (self.integrator or {}).get("name") or "exact"
        a, v0, v1 = self.acc[i], r.vf[s - 1, i], r.vf[s, i]
        disp = r.xf[s, i] - r.xf[s - 1, i]
        if fit == "exact":  # x1 − x0 = v0·τ + aτ²/2 + (v1 − a(dt − τ))(dt − τ) + a(dt − τ)²/2, solved for τ
            along = v0 - v1 + a * dt
            lever = disp - v1 * dt + 0.5 * a * dt * dt
        else:  # a straight path: the velocity after the forces' update, then the kicked one
            _, w1 = dict((n, w) for n, _, w in INTEGRATOR_FITS)[fit]
            along = v0 + w1 * a * dt - v1
            lever = disp - v1 * dt
        size = float(along @ along)
        if not size > 0 or not math.isfinite(size):
            return dt
        return float(np.clip((lever @ along) / size, 0.0, dt))

    # ------------------------------------------------------------------ step by step
    def _local_step(self, s: int, start: tuple[np.ndarray, np.ndarray] | None = None,
                    order: np.ndarray | None = None, **settings):
        """physdbg's exact step s from the foreign state at its start (or ``start``, (x, v)
        (N, 3) each): (x, v, contacts as dicts), with the scene's settings or, given, some of
        them replaced (ordering="index"). order (N,): the world numbers sphere order[k] as k
        (to take a tie in another order); what it returns is in the scene's numbering."""
        import dataclasses

        from ..engine import World
        from ..errors import WorldStuck
        from ..engine.state import State
        from ..events import Contacts
        from ..observe import ListObserver

        r, st = self.runs, self.scene.state
        if start is not None:
            x0, v0 = start
        else:
            x0, v0 = r.xf[s - 1], r.vf[s - 1]
            if self.estimated:  # the velocity at the step's start: the step's average less half the forces' change
                v0 = r.vf[s] - 0.5 * self.acc * float(r.dt[s])
        k = np.arange(st.count) if order is None else np.asarray(order)
        if order is None:  # (the common case: no copies of the constants)
            state = State(np.array(x0), np.array(v0), st.inverse_mass, st.radius, st.restitution, st.gravity_scale)
        else:
            state = State(np.ascontiguousarray(x0[k]), np.ascontiguousarray(v0[k]), st.inverse_mass[k], st.radius[k],
                          st.restitution[k], st.gravity_scale[k])
        seen = ListObserver()
        world = World(state, self.scene.walls, dataclasses.replace(self.scene.settings, **settings) if settings
                      else self.scene.settings, seen)
        world.time = float(r.t[s - 1])
        try:
            world.step(float(r.dt[s]))
        except WorldStuck:
            return None
        if order is None:
            x, v = state.positions, state.velocities
        else:  # back to the scene's numbering
            x, v = np.empty_like(state.positions), np.empty_like(state.velocities)
            x[k], v[k] = state.positions, state.velocities
        out = []
        batches = seen.of_type(Contacts)
        c = batches[0] if batches else None
        resting = c.resting if c is not None else None
        for j in range(len(c) if c is not None else 0):
            kind, a, other = int(c.kind[j]), int(k[c.a[j]]), int(c.other[j])
            other = int(k[other]) if PARTNER_IS_SPHERE[kind] else other
            out.append(StepContact(s, j, kind, a, other, float(c.time_in_step[j]),
                                   float(r.t[s - 1] + c.time_in_step[j]), c.normal[j].copy(),
                                   float(c.restitution[j]), bool(resting[j]), abs(float(c.closing_speed[j])),
                                   c.point[j] + c.normal[j] * self.radius[a]))
        return x, v, out
