"""check-run's judgements of one contact or one chain of contacts (a mixin of
departure._Comparison): a contact missed, tunnelling, a late bounce, the energy at a
contact (and which impulse mistake gives it), a reflection of the whole velocity or a
wrong normal, an impulse loop, a bounce that skips the rest of the step, a chain
resolved out of order, an extra contact, drift in free flight."""

from __future__ import annotations

import dataclasses
import math
import sys

import numpy as np

from ..events import KIND_MESH, KIND_WALL, PARTNER_IS_SPHERE
from .departure_records import (_body_count, _Lone, _no_geometry, bodies_of, Departure, integrator_of, Kick,
                                RESTING_SPEED_STEPS, RUNAWAY, StepContact, TIME_TOLERANCE)
from .restitution_mistakes import restitution_mistake, RESTITUTION_TOLERANCE
from .tunnel_words import why_tunnelled


class ContactJudges:
    """The judgements of one contact (_judge_one) or one chain (_judge_chain) of a step."""

    def _slow(self, c: StepContact, s: int) -> bool:
        """Not judged one by one: a contact closing slower than the forces' speed over
        RESTING_SPEED_STEPS steps (a resting contact, whose handling differs between engines
        by design), or one at the very start of a step right after the foreign run kicked
        the body (the aftermath of that kick, already judged)."""
        if c.tau <= TIME_TOLERANCE * float(self.runs.dt[s]) and any(
                getattr(self.kicks.get((k, b)), "matched", None) for b in self._bodies(c) for k in (s - 1, s)):
            return True
        return self._resting_speed(c, s)

    def _resting_speed(self, c: StepContact, s: int) -> bool:
        """Contact c closes slower than the speed the forces give its spheres in
        RESTING_SPEED_STEPS steps (a resting contact)."""
        a = max(float(np.linalg.norm(self.acc[b])) for b in self._bodies(c))
        return a > 0 and c.closing < RESTING_SPEED_STEPS * a * float(self.runs.dt[s])

    @staticmethod
    def _bodies(c: StepContact) -> tuple[int, ...]:
        return bodies_of(c.kind, c.a, c.other)

    def _kick_for(self, c: StepContact) -> Kick | None:
        """The foreign kick of contact c: on its sphere (or the other sphere of a pair), in
        its step or the next."""
        for s in (c.step, c.step + 1):
            for b in self._bodies(c):
                k = self.kicks.get((s, b))
                if k is not None and not k.matched and self.inv[b] > 0:
                    return k
        return None

    def _judge_one(self, c: StepContact) -> None:
        r, kicks = self.runs, self.kicks
        if self._runaway(c):
            return
        kick = self._kick_for(c)
        s, dt = c.step, float(r.dt[c.step])
        if kick is None:
            crossing = self._crossing(c)
            if crossing is not None:
                self._tunnelled(c, crossing)
            elif not any(self.kicked[s - 1, b] for b in self._bodies(c) if self.inv[b] > 0):
                # (a change the forces do not explain that another contact took is a change all
                # the same: then nothing the frames show is missing, and nothing is said)
                change = max(self._change_beyond_forces(s, b) for b in self._bodies(c) if self.inv[b] > 0)
                self._add("missed-contact", s, c, f"{self._subject(c)}: physdbg, stepping from the same state, "
                                                  f"touches {self._what(c)} at t = {c.time:.6g} s "
                                                  f"({c.tau / dt:.2f}·dt); your run shows no change of velocity "
                                                  f"in that step beyond the forces' ({change:.3g} m/s)",
                          "look for contacts along each step's whole path; a contact within the step that your "
                          "engine did not see changes everything after it",
                          {"time": c.time, "velocity_change": change})
            return
        for b in self._bodies(c):
            k = kicks.get((kick.step, b))
            if k is not None:
                k.matched = True
        # how well a kick's instant is known: TIME_TOLERANCE, plus the part of the step's velocity
        # change that the forces make, since when the engine applied them is not known
        i, k = kick.body, kick.step + (1 if self.estimated else 0)  # estimated: between two averages
        change = float(np.linalg.norm(r.vf[min(k, len(r.t) - 1), i] - r.vf[k - 1, i]))
        slack = float(np.linalg.norm(self.acc[i])) * dt / change if change > 0 else 0.0
        if self._skipped_rest(c):
            self._judge_energy(c, kick, quiet_if_late=True)
            return
        late = abs(kick.time - c.time) > (TIME_TOLERANCE + slack) * dt
        if late:
            self._late(c, kick)
        self._judge_energy(c, kick, quiet_if_late=late)

    def _runaway(self, c: StepContact) -> bool:
        """The contact's bodies leave its step still approaching, at RUNAWAY times their
        speed or more, or with NaN or infinite velocities: what an impulse of the wrong sign
        does in an engine that looks again at once (the pair, pushed together at (2 + e)
        times its closing speed, meets again at the same instant, and again, until the
        numbers overflow). Named impulse-loop, with the meetings it takes to reach the
        run's speed; True when named."""
        r = self.runs
        s, bodies = c.step, self._bodies(c)
        if any(self.inv[b] == 0 for b in bodies) and len(bodies) == 1:
            return False
        dt = float(r.dt[s])
        start = max(float(np.linalg.norm(r.vf[s - 1, b])) for b in bodies) + float(np.linalg.norm(self.acc[bodies[0]])) * dt
        after = r.vf[s, c.a] - (r.vf[s, c.other] if PARTNER_IS_SPHERE[c.kind] else 0.0)
        normal_after = float(after @ c.normal)
        blown = not math.isfinite(normal_after)
        if not blown and not (normal_after < 0 and -normal_after >= RUNAWAY * max(start, c.closing, 1e-12)):
            return False
        e, closing = c.restitution, max(c.closing, 1e-300)
        factor = 2.0 + e
        if blown:
            outcome = "with NaN or infinite velocities"
            meetings = math.log(sys.float_info.max / closing) / math.log(factor)
            reached = f"passes the largest float after about {meetings:.0f} meetings"
        else:
            outcome = f"still approaching at {-normal_after:.3g} m/s"
            meetings = math.log(-normal_after / closing) / math.log(factor)
            reached = f"gets there after about {meetings:.0f} meetings"
        self._add("impulse-loop", s, c,
                  f"{self._both(c)}: they met at {closing:.3g} m/s at {c.tau / dt:.2f}·dt into step {s} and "
                  f"left the step {outcome}. An impulse of the wrong sign does this in an engine that looks for the "
                  f"next contact at once: it pushes the pair together at (2 + e) = {factor:.3g} times their closing "
                  f"speed, so they meet again at the same instant, and again: their speed {reached}",
                  "the impulse points the wrong way: j = −(1 + e)·(v_rel·n)/(1/m_a + 1/m_b) pushes a along n (from b "
                  "towards a) and b against it. A bound on the contacts of a step (physdbg's max_contacts_per_step) "
                  "turns such a loop into an error instead of NaN",
                  {"closing_speed": closing, "factor": factor, "meetings": meetings,
                   "speed_after": None if blown else -normal_after})
        for k in (s, s + 1):
            for b in bodies:
                if (k, b) in self.kicks:
                    self.kicks[(k, b)].matched = True
        return True

    def _skipped_rest(self, c: StepContact) -> bool:
        """The run left sphere a where it touched for the rest of the step: its position at
        the step's end is physdbg's centre at the touch (the seed moves a body on after a
        bounce for the time the step has left)."""
        r = self.runs
        s, a = c.step, c.a
        dt = float(r.dt[s])
        if c.tau >= (1.0 - TIME_TOLERANCE) * dt or self.inv[a] == 0:
            return False
        centre = c.centre
        if np.linalg.norm(r.xf[s, a] - centre) > self.atol + self.rtol * float(np.linalg.norm(centre)):
            return False
        left = dt - c.tau
        self._add("skipped-rest", s, c,
                  f"{self._subject(c)} touched {self._what(c)} at {c.tau / dt:.2f}·dt into step {s} and stayed "
                  f"there for the rest of the step ({left:.3g} s, {left / dt:.2f}·dt); physdbg moves it on with its "
                  f"new velocity, to {float(np.linalg.norm(r.xf[s, a] - self._end_of(s)[a])):.3g} m from where your "
                  f"run left it",
                  "after resolving a contact at time τ into the step, move the body on with its new velocity for the "
                  "time left (dt − τ), and look for further contacts in that time", {"tau": c.tau, "left": left})
        return True

    def _end_of(self, s: int) -> np.ndarray:
        """physdbg's positions (N, 3) at the end of step s taken from the run's own start."""
        local = self._local_step(s)
        return local[0] if local is not None else np.full_like(self.runs.xf[s], np.nan)

    def _late(self, c: StepContact, kick: Kick) -> None:
        r = self.runs
        s, a = kick.step, kick.body
        dt = float(r.dt[c.step])
        x = r.xf[s - 1, a] + (r.xf[s, a] - r.xf[s - 1, a]) * (kick.tau / float(r.dt[s]))
        depth = -self._gap(c, a, x, s, kick.tau)
        shift = kick.time - c.time
        fraction = kick.tau / float(r.dt[s])
        where = (f"at the end of step {s}" if fraction >= 1 - TIME_TOLERANCE else
                 f"at the start of step {s}" if fraction <= TIME_TOLERANCE else f"{fraction:.2f}·dt into step {s}")
        text = (f"{self._subject(c)} bounced off {self._what(c)} at t = {kick.time:.6g} s ({where}), "
                f"{abs(shift) * 1000:.3g} ms ({abs(shift) / dt:.2f}·dt) {'after' if shift > 0 else 'before'} the "
                f"exact time of impact t = {c.time:.6g} s")
        if depth > 0:
            text += f", when it was already {depth * 1000:.3g} mm inside"
            advice = ("your engine tests for contact where each step ends (discrete detection) and bounces there, "
                      "late and from inside: find the time of impact within the step (solve |x + v·t − c| = r for "
                      "t, the swept test) and bounce at that instant")
        elif shift < 0:
            advice = ("the bounce came before the bodies touched: check the contact distance (the sum of the radii) "
                      "and that contacts are tested where the body is, not ahead of it")
        else:
            advice = ("the bounce came after the touch but before an overlap showed: find the time of impact "
                      "within the step (the swept test) instead of testing at sampled instants")
        self._add("bounce-time", c.step, c, text, advice, {"physdbg_time": c.time, "time": kick.time,
                                                                "shift": shift, "depth": max(depth, 0.0)})

    def _judge_energy(self, c: StepContact, kick: Kick, quiet_if_late: bool) -> None:
        """Compare the contact's outgoing normal speed with the restitution's. After a late
        bounce, only a clear error is reported (below 0 or above 1): the speeds of a body
        bounced from inside are not the exact contact's."""
        r = self.runs
        s = kick.step
        tau, dt = kick.tau, float(r.dt[s])
        n = c.normal
        # a soft contact (MuJoCo's) spreads its impulse over steps: the contact lasts while the
        # kicks go on, and its outcome is the velocity after the last of them
        end = s

        def normal_speed(k):
            v = r.vf[k, c.a] - (r.vf[k, c.other] if PARTNER_IS_SPHERE[c.kind] else 0.0)
            return float(v @ n)

        def pushing_apart(k):  # step k's kick pushes the bodies apart while they touch or approach
            gap = self._gap(c, c.a, r.xf[k - 1, c.a], k, 0.0)
            return normal_speed(k) > normal_speed(k - 1) and (gap <= 0.0 or normal_speed(k - 1) < 0.0)

        while (not self.estimated and pushing_apart(s) and end + 1 < len(r.t)
               and any((end + 1, b) in self.kicks for b in self._bodies(c)) and pushing_apart(end + 1)):
            end += 1
            for b in self._bodies(c):
                if (end, b) in self.kicks:
                    self.kicks[(end, b)].matched = True

        def readings(i, last=None):
            """(velocity just before, just after) the contact, as each way of applying the
            forces around it would have them; which one the engine used is not known.
            last: the step whose end is "after" (default: the contact's last step)."""
            last = end if last is None else last
            length = float(r.t[last] - r.t[s - 1])
            if self.estimated:  # the kick is at the step's end, between its average and the next step's
                if last + 1 >= len(r.t):
                    return []
                return [(r.vf[s, i] + 0.5 * self.acc[i] * dt,
                         r.vf[last + 1, i] - 0.5 * self.acc[i] * float(r.dt[last + 1]))]
            v0, v1, a = r.vf[s - 1, i], r.vf[last, i], self.acc[i]
            return [(v0 + a * tau, v1 - a * (length - tau)), (v0 + a * dt, v1 - a * (length - dt)),
                    (v0, v1 - a * length)]

        want = c.restitution

        def effective(last=None):
            """(|e − want|, e, normal speed before, after) of each reading of the contact."""
            out = []
            pair = PARTNER_IS_SPHERE[c.kind]
            for (before_a, after_a), other in zip(readings(c.a, last),
                                                  readings(c.other, last) if pair else [(0.0, 0.0)] * 3):
                before, after = (before_a - other[0]) @ n, (after_a - other[1]) @ n
                if math.isfinite(before) and math.isfinite(after) and before < 0:
                    out.append((abs(-after / before - want), -after / before, before, after))
            return out

        options = effective()
        if not options:
            return
        _, e, before, after = min(options)  # the reading kindest to the run: report only what none explains
        mistake = restitution_mistake(e, want)
        if mistake is None and end > s:  # a mistake shows whole in the contact's own step, before what it leads to
            first = effective(s)
            if first and restitution_mistake(min(first)[1], want) is not None:
                _, e, before, after = min(first)
                mistake = restitution_mistake(e, want)
        # the direction of the push, over the contact's own step (a wrong normal impulse
        # that leaves the bodies approaching makes more contacts in the steps after)
        if self._judge_tangent(c, lambda i: readings(i, s)) and mistake is None:
            return
        if abs(e - want) <= RESTITUTION_TOLERANCE + 1e-3 * want or (quiet_if_late and 0.0 <= e <= 1.0):
            return
        if mistake is not None:
            code, words, advice = mistake
            self._add(code, c.step, c,
                      f"{self._both(c)}: "
                      + (f"they met at {abs(before):.3g} m/s and {'still approach' if after < 0 else 'part'}"
                         if PARTNER_IS_SPHERE[c.kind] else
                         f"it met {self._what(c)} at {abs(before):.3g} m/s and "
                         f"{'still approaches it' if after < 0 else 'leaves'}")
                      + f" at {abs(after):.3g} m/s after the contact, an "
                      f"effective restitution of {e:.3g} where physdbg applies e = {want:g}: {words}", advice,
                      {"restitution": e, "expected": want, "speed_in": abs(before), "speed_out": abs(after)})
            return
        if e < -1.0:
            text = (f"{self._both(c)}: after the contact they still approach, at {abs(after):.3g} m/s where they "
                    f"met at {abs(before):.3g} m/s (an effective restitution of {e:.2f}; the scene's is {want:g}): "
                    f"energy gained")
            advice = ("the impulse points the wrong way: j = −(1 + e)·(v_rel·n)/(1/m_a + 1/m_b) pushes a along n "
                      "(from b towards a) and b against it; check its sign and the normal's direction")
        elif e < 0:
            text = (f"{self._both(c)}: after the contact they still approach, at {abs(after):.3g} m/s where they "
                    f"met at {abs(before):.3g} m/s (an effective restitution of {e:.2f}; the scene's is {want:g}): "
                    f"the impulse points the right way but is too small to part them")
            advice = ("j = −(1 + e)·(v_rel·n)/(1/m_a + 1/m_b) must take away the whole closing speed (the 1) and "
                      "give back e of it reversed: check both terms of (1 + e) and the masses")
        else:
            gained = e > 1.0
            verdict = ("energy gained at the contact" if gained else
                       "more energy kept than that restitution allows" if e > want else
                       "more energy lost than that restitution takes")
            text = (f"{self._subject(c)}: the contact with {self._what(c)} sent it off at {abs(after):.3g} m/s for "
                    f"{abs(before):.3g} m/s coming in, an effective restitution of {e:.3g} where physdbg applies "
                    f"{want:g}: {verdict}")
            advice = ("restitution above 1 adds energy: check the impulse and the restitution of both bodies"
                      if gained else
                      "check the restitution your engine was given and how it combines two bodies' (physdbg's "
                      f"rule here: restitution_rule = {self.settings.get('restitution_rule', 'min')})")
        self._add("contact-energy", c.step, c, text, advice,
                  {"restitution": e, "expected": want, "speed_in": abs(before), "speed_out": abs(after)})

    def _judge_tangent(self, c: StepContact, readings) -> bool:
        """A frictionless contact pushes along its normal only, so each sphere keeps its
        velocity across the normal (its tangential part). A run that changes it either
        reflected the whole velocity (tangent-reversed: the seed's R = Ri − 2N(Ri·N) turns
        only the normal part) or pushed along another direction (wrong-normal). True when
        one was named."""
        n = c.normal
        for i in self._bodies(c):
            if self.inv[i] == 0:
                continue
            best = None
            for before, after in readings(i):
                t0, t1 = before - (before @ n) * n, after - (after @ n) * n
                change = float(np.linalg.norm(t1 - t0))
                if math.isfinite(change) and (best is None or change < best[0]):
                    best = (change, before, after, t0, t1)
            if best is None:
                continue
            change, before, after, t0, t1 = best
            scale = float(np.linalg.norm(before)) + float(np.linalg.norm(self.acc[i])) * float(self.runs.dt[c.step])
            if change <= RESTITUTION_TOLERANCE * scale + self.atol:
                continue
            c_i = dataclasses.replace(c, a=i, other=c.other if i == c.a else c.a) if PARTNER_IS_SPHERE[c.kind] else c
            size0, size1 = float(np.linalg.norm(t0)), float(np.linalg.norm(t1))
            if size0 > 0 and size1 > 0 and float(t0 @ t1) < -0.9 * size0 * size1:
                self._add("tangent-reversed", c.step, c_i,
                          f"{self._subject(c_i)}: the contact with {self._what(c_i)} reversed its velocity along the "
                          f"surface too, from {size0:.3g} m/s to {size1:.3g} m/s the other way; a frictionless "
                          f"contact keeps that part and turns only the part along the normal",
                          "reflect only the normal part: v − (1 + e)(v·n)n (the seed's R = Ri − 2N(Ri·N) for e = "
                          "1), not −e·v", {"tangential_before": size0, "tangential_after": -size1})
            else:
                kick = after - before
                along = abs(float(kick @ n)) / max(float(np.linalg.norm(kick)), 1e-300)
                angle = math.degrees(math.acos(min(1.0, along)))
                self._add("wrong-normal", c.step, c_i,
                          f"{self._subject(c_i)}: the contact with {self._what(c_i)} pushed it {angle:.3g}° away from "
                          f"the normal at the touch, changing its velocity across the normal by {change:.3g} m/s "
                          f"(a frictionless contact changes only the part along the normal)",
                          "push along the normal at the time of impact: for two spheres the line of centres, "
                          "n = (x_a − x_b)/|x_a − x_b| at the touch, not the direction of their velocities",
                          {"angle_degrees": angle, "tangential_change": change})
            return True
        return False

    def _judge_chain(self, s: int, group: list[StepContact], v_local: np.ndarray) -> None:
        """Contacts of one step that share bodies: the group's outcome as a whole."""
        r = self.runs
        bodies = sorted({b for c in group for b in self._bodies(c) if self.inv[b] > 0})
        for b in bodies:
            for k in (s, s + 1):
                if (k, b) in self.kicks:
                    self.kicks[(k, b)].matched = True
        idx = np.array(bodies)
        vf, vr = r.vf[s, idx], v_local[idx]
        gap = np.linalg.norm(vf - vr, axis=1)
        if not np.any(gap > self.atol + self.rtol * np.linalg.norm(vr, axis=1)):
            return  # the chain's outcome is physdbg's; what differs is where the bodies are (drift)
        # what the run's own frames say of the chain: momentum and energy at the step's end
        # against its start carried over the step by the forces and drag alone, over the
        # chain's spheres and every other sphere the run kicked in the step (where the run's
        # contacts took momentum)
        members = np.array(sorted(set(bodies) | set(self._changed_near(s, bodies))))
        mass = 1.0 / self.inv[members]
        dt = float(r.dt[s])
        start = r.vf[s - 1, members] * float(self._decay(dt)) + self.acc[members] * dt
        end = r.vf[s, members]
        momentum_0, momentum_1 = (mass[:, None] * start).sum(axis=0), (mass[:, None] * end).sum(axis=0)
        energy_0, energy_1 = (0.5 * float(mass @ (start * start).sum(axis=1)),
                              0.5 * float(mass @ (end * end).sum(axis=1)))
        energy_r = 0.5 * float((1.0 / self.inv[idx]) @ (vr * vr).sum(axis=1))
        # slack for how the forces and drag were applied around the contacts (not known)
        forces = float(np.sum(mass * (np.linalg.norm(self.acc[members], axis=1) * dt
                                      + np.linalg.norm(r.vf[s - 1, members], axis=1) * abs(1.0 - self._decay(dt)))))
        scale = max(float(np.sum(mass * np.linalg.norm(end, axis=1))), float(np.sum(mass * np.linalg.norm(start, axis=1))),
                    1e-300)
        momentum_off = float(np.linalg.norm(momentum_1 - momentum_0))
        walls = self._may_touch_a_wall(s, members)  # a wall or a mesh takes momentum: not compared then
        kept = walls or momentum_off <= 1e-3 * scale + forces
        speed = max(float(np.max(np.linalg.norm(end, axis=1))), float(np.max(np.linalg.norm(start, axis=1))))
        energy_slack = 1e-3 * max(energy_0, 1e-300) + forces * (speed + forces / float(mass.min()))
        gained = energy_1 > energy_0 + energy_slack
        order = ", then ".join(f"{self._pair_words(c)} at {c.tau / dt:.2f}·dt" for c in group[:6])
        worst = int(idx[int(np.argmax(gap))])
        spheres = ", ".join(map(str, members.tolist()[:12])) + (" …" if len(members) > 12 else "")
        evidence = {"bodies": bodies, "momentum_bodies": members.tolist(),
                    "physdbg_order": [[c.a, c.other, c.kind] for c in group],
                    "energy_before": energy_0, "energy": energy_1, "physdbg_energy": energy_r,
                    "momentum_before": momentum_0.tolist(), "momentum": momentum_1.tolist(),
                    "momentum_off": momentum_off, "momentum_kept": kept, "forces_slack": forces, "walls": walls}
        first = group[0]
        if gained:
            self._add("contact-energy", s, first,
                      f"in the chain {order}, your run's spheres {spheres} leave step {s} with {energy_1:.4g} J of "
                      f"kinetic energy where they had {energy_0:.4g} J (the step's start, carried by the forces and "
                      f"drag alone): energy gained (physdbg's leave with {energy_r:.4g} J)",
                      "check each impulse's sign and that restitution is at most 1", evidence)
        elif kept:
            self._add("collision-order", s, first,
                      f"physdbg resolves {order}; your run gives sphere {worst} a velocity {gap.max():.3g} m/s "
                      f"away, with " + (
                          "no energy gained; with a wall within reach, momentum is not compared, so this is the same "
                          "contacts in another order (or all at once), or an impulse a wall does not explain"
                          if walls else
                          "momentum kept and no energy gained: the same contacts in another order (or all at once)"),
                      "resolve contacts one at a time in the order they happen (earliest time of impact first), "
                      "looking again for new contacts after each: a chain of touching spheres passes its impulse "
                      "along only in that order", evidence)
        else:
            self._add("contact-energy", s, first,
                      f"in the chain {order}, momentum is not kept: your run's spheres {spheres} change their total "
                      f"momentum by {momentum_off:.3g} N·s in step {s} (from {float(np.linalg.norm(momentum_0)):.4g} "
                      f"to {float(np.linalg.norm(momentum_1)):.4g} N·s), where the forces and drag account for at most "
                      f"{forces:.3g} N·s",
                      "apply each impulse to both bodies, equal and opposite, scaled by their inverse masses",
                      evidence)

    def _changed_near(self, s: int, chain: list[int]) -> list[int]:
        """Spheres outside ``chain`` whose velocity the run changed in step s beyond the
        forces (and the tolerance) and that came within reach of a chain sphere (the sum of
        the radii plus both spheres' travel in the step): where the run's chain may have
        taken momentum that physdbg's did not."""
        r = self.runs
        travel = np.linalg.norm(r.xf[s] - r.xf[s - 1], axis=1)
        near = []
        for b in np.flatnonzero(self.inv > 0).tolist():
            if b in chain or not (self._change_beyond_forces(s, b)
                                  > self.atol + self.rtol * float(np.linalg.norm(r.vf[s, b]))):
                continue
            for k in (s - 1, s):
                gaps = (np.linalg.norm(r.xf[k, chain] - r.xf[k, b], axis=1) - self.radius[chain] - self.radius[b]
                        - travel[chain] - travel[b])
                if np.any(np.nan_to_num(gaps, nan=-1.0) <= self.atol):
                    near.append(b)
                    break
        return near

    def _may_touch_a_wall(self, s: int, members: np.ndarray) -> bool:
        """Whether any of spheres ``members`` may have touched a wall or a mesh in step s of
        the run: a plane within its radius plus the step's travel at the step's start or end
        (a scene with meshes: always, not measured here)."""
        if len(self.walls.meshes.corners):
            return True
        if not len(self.walls):
            return False
        r = self.runs
        from ..engine.colliders.plane import gaps

        reach = np.linalg.norm(r.xf[s, members] - r.xf[s - 1, members], axis=1)
        for k in (s - 1, s):
            g = gaps(np.ascontiguousarray(r.xf[k, members], dtype=np.float64), self.radius[members], self.walls)
            if np.any(np.nan_to_num(g, nan=-1.0) <= reach[:, None] + self.atol):
                return True
        return False

    def _extra(self, kick: Kick) -> None:
        r = self.runs
        s, i = kick.step, kick.body
        size = float(np.linalg.norm(r.vf[s, i] - r.vf[s - 1, i]))
        self._add("extra-contact", s, _Lone(i),
                  f"sphere {i} changed velocity by {size:.3g} m/s at t ≈ {kick.time:.6g} s; physdbg, stepping "
                  f"from the same state, touches nothing in that step",
                  "a contact physdbg does not see: a test that fires too early or against the wrong body, or a "
                  "body that was already inside another (look at the step before)", {"change": size})

    def _drift(self, drift: dict[int, list[int]]) -> None:
        """Free steps that end elsewhere: one departure for all bodies, with the counts."""
        if not drift or self.run_decay is not None:  # the run's own drag, named already, is why
            return
        integrator = self.integrator or {}
        b = min(drift, key=lambda i: (drift[i][0], i))
        steps = sorted({k for ks in drift.values() for k in ks})
        who = f"sphere {b} drifts" if len(drift) == 1 else f"{len(drift)} spheres (sphere {b} first) drift"
        text = (f"{who} in free flight ({len(steps)} step{'s' if len(steps) != 1 else ''} with no contact "
                f"end{'s' if len(steps) == 1 else ''} elsewhere than physdbg's from the "
                f"same start)")
        if integrator.get("differs") and integrator.get("name"):
            text += ": the integrator"
            advice = (f"integrate as the scene says (integrator = {self.settings.get('integrator')}), or set the "
                      f"scene's integrator to your engine's to compare the contacts alone")
        else:
            advice = (f"check gravity ({self.settings.get('gravity')} m/s²), drag ({self.drag:g}) and the gravity "
                      f"scale against the scene's")
        self.departures.append(Departure("drift", steps[0], b, text, advice,
                                         evidence={"steps": len(steps), "bodies": sorted(drift)}))

    # ------------------------------------------------------------------ crossings
    def _crossings_in(self, s: int):
        if not hasattr(self, "_checker"):
            from .tunnel import StepChecker

            settings = dict(self.settings)
            settings["integrator"] = integrator_of((self.integrator or {}).get("name"))
            self._checker = StepChecker(self.radius, self.inv, self.rr.header.gravity_scale, self.walls, settings)
        r = self.runs
        if not (np.isfinite(r.xf[s]).all() and np.isfinite(r.xf[s - 1]).all()):
            return []
        return self._checker.check(r.xf[s - 1], r.vf[s - 1], r.xf[s], float(r.dt[s]), None, float(r.t[s - 1]))

    def _crossing(self, c: StepContact):
        """The foreign crossing of contact c's bodies in its step or the next, or None."""
        for s in (c.step, c.step + 1):
            if s >= len(self.runs.t):
                break
            for x in self._crossings_in(s):
                if x.kind == c.kind and {x.a, x.other} == ({c.a, c.other} if PARTNER_IS_SPHERE[c.kind]
                                                              else {x.a, c.other}) and x.a in self._bodies(c):
                    return s, x
        return None

    def _tunnelled(self, c: StepContact, crossing) -> None:
        r = self.runs
        s, x = crossing
        a, dt = c.a, float(r.dt[c.step])
        speed = float(np.linalg.norm(r.vf[s - 1, a]))
        if PARTNER_IS_SPHERE[c.kind]:
            room = 2 * float(self.radius[a] + self.radius[c.other])
            what = f"more than the two spheres' diameters ({room:.3g} m)"
        elif c.kind == KIND_WALL:
            room = float(self.walls.thickness[c.other]) + 2 * float(self.radius[a])
            what = f"more than the wall's thickness plus the sphere's diameter ({room:.3g} m)"
        elif c.kind == KIND_MESH:
            room = 2 * float(self.radius[a])
            what = f"more than the sphere's diameter ({room:.3g} m: a mesh's triangle has no thickness)"
        else:
            raise _no_geometry(c.kind)
        text = (f"{self._subject(c)} went through {self._what(c)} with no contact; physdbg's swept test, from the "
                f"same state, finds the touch at t = {c.time:.6g} s ({c.tau / dt:.2f}·dt) and bounces it back")
        advice = why_tunnelled(self.settings, [], foreign=True).advice
        carried = speed * float(r.dt[s])
        inside = -self._gap(c, a, r.xf[s - 1, a], s, 0.0)
        if inside > self.settings.get("contact_tolerance", 0.0) and PARTNER_IS_SPHERE[c.kind]:
            text += f"; it was already {inside * 1000:.3g} mm inside at the step's start"
            advice = ("it started the step inside the other sphere, after a contact resolved late or with the wrong "
                      "impulse: fix that first (see the departure before this one)")
        elif carried > room:
            text += f". At {speed:.3g} m/s a step of {float(r.dt[s]):.3g} s carries it {carried:.3g} m, {what}"
            advice += f" (steps under {room / max(speed, 1e-300):.3g} s here)"
        self._add("tunnelling", s, c, text, advice, {"physdbg_time": c.time, "speed": speed, "depth": x.depth})

    def _non_finite(self) -> None:
        r = self.runs
        bad = ~(np.isfinite(r.xf).all(axis=2) & np.isfinite(r.vf).all(axis=2))
        frames, bodies = np.nonzero(bad)
        if len(frames):
            k, i = int(frames[0]), int(bodies[0])
            self._add("non-finite", k, _Lone(i),
                      f"sphere {i}'s {'position' if not np.isfinite(r.xf[k, i]).all() else 'velocity'} is NaN or "
                      f"infinite from t = {r.t[k]:.6g} s ({_body_count(int(bad[k].sum()))} then)",
                      "look at the step before: a division by a zero distance (two centres at one point) or a "
                      "zero mass is the usual start", {"frame": k})

    # ------------------------------------------------------------------ words
    def _gap(self, c: StepContact, a: int, x: np.ndarray, s: int, tau: float) -> float:
        """Distance from contact (m; negative inside) of body a at x, the other body where
        the foreign run had it at that instant."""
        r = self.runs
        if c.kind == KIND_WALL:
            from ..engine.colliders.plane import gaps

            return float(gaps(np.asarray(x, dtype=np.float64).reshape(1, 3), self.radius[a:a + 1], self.walls)[0, c.other])
        if c.kind == KIND_MESH:
            from ..engine.mesh.closest import closest_on_triangle

            meshes = self.walls.meshes
            corners = meshes.corners[c.other]
            if meshes.moving[meshes.mesh_of[c.other]]:  # a kinematic mesh, where it was then
                corners = meshes.placed(float(r.t[s - 1]) + tau)[0][c.other]
            q = np.array(closest_on_triangle(*(float(v) for v in x), *corners.ravel())[:3])
            return float(np.linalg.norm(x - q)) - float(self.radius[a])
        if not PARTNER_IS_SPHERE[c.kind]:
            raise _no_geometry(c.kind)
        b = c.other if a == c.a else c.a
        xb = r.xf[s - 1, b] + (r.xf[s, b] - r.xf[s - 1, b]) * (tau / float(r.dt[s]))
        return float(np.linalg.norm(x - xb)) - float(self.radius[a] + self.radius[b])
