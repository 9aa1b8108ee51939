"""check-run's explanations of a whole step (a mixin of departure._Comparison): where
every step ends where physdbg's does and the runs still part (chaos, sleeping), and
what may explain a step that ends elsewhere before its contacts are judged one by one
(departure.STEP_EXPLANATIONS, in its order): physdbg's own modelling rule, a tie, index
order, an impulse mistake along a chain."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..events import PARTNER_IS_SPHERE
from .departure_records import (_chains, _changed_contacts, Departure, FirstDeparture, MISTAKE_MISSES, OWN_RULES,
                                RESTING_SPEED_STEPS, SLEEPING_RULE, StepContact, TIE_SPHERES)
from .restitution_mistakes import MISTAKE_SPHERES, RESTITUTION_MISTAKES, RESTITUTION_TOLERANCE, step_with_mistake


class StepJudges:
    """What explains a whole step (departure.STEP_EXPLANATIONS) or a run that parts with no step departing."""

    def _no_step_departs(self, first: FirstDeparture) -> None:
        """Every step, taken from the run's own state, ends where physdbg's does, yet the
        runs part: chaos when the gap between them grows at a finite-time Lyapunov exponent
        (align.Growth.judge_chaos: steady exponential growth over e-folds while spheres
        collide), else unexplained."""
        from .align import fit_growth

        r = self.runs
        frames = np.arange(first.step, len(r.t))
        gaps = np.linalg.norm(r.xf[frames] - r.xr[frames], axis=2)
        gaps = np.where(np.isfinite(gaps).all(axis=1), gaps.max(axis=1), np.inf)
        movable = self.inv > 0
        radius = float(self.radius[movable].min()) if movable.any() else float(self.radius.min())
        growth = fit_growth(frames, r.t[frames], gaps, radius, first.step, float(r.t[first.step]),
                            float(r.dt[first.step]))
        collisions = self.rr.stats(first.step)["collisions"] if self.rr.frames > first.step else np.zeros(0)
        growth.judge_chaos(bool(np.any(collisions > 0)))
        steps = "every step, taken from your run's own state at its start, ends where physdbg's exact step does"
        if growth.chaotic:
            self.departures.append(Departure(
                "chaos", first.step, first.body,
                f"{steps} (within the tolerance), and the runs part because differences below it grow: "
                f"{growth.sentence()}",
                "nothing your engine does in a step differs from physdbg's beyond the tolerance: to compare a chaotic "
                "scene for longer, give it the scene's step lengths exactly, or compare with a looser --atol",
                evidence={"lyapunov": growth.rate, "efolds": growth.efolds}))
        else:
            self.departures.append(Departure(
                "unexplained", first.step, first.body,
                f"{steps} (within the tolerance), yet the runs part, and not as chaos does ({growth.sentence()}): "
                f"physdbg cannot say why",
                "small differences in every step add up: check that the run's steps are the scene's (dt = "
                f"{float(np.median(r.dt[1:])):.6g} s), and its forces and drag, to the last digit",
                evidence={"growth": growth.as_dict()}))

    def _slept(self, first: FirstDeparture) -> bool:
        """Every step ends where the run's does, yet the runs part where physdbg's sleeping
        rule froze a sphere (at rest in the reference, with spheres asleep in that step)
        that the run keeps moving: named own-rule, as OWN_RULES are (SLEEPING_RULE;
        check-run then compares against physdbg without sleeping)."""
        speed = float(self.settings.get("sleep_speed") or 0.0)
        r, k, b = self.runs, first.step, first.body
        if speed <= 0 or k < 1 or np.any(r.vr[k, b]) or not np.any(r.vf[k, b]):
            return False
        asleep = self.rr.stats(k, k + 1)["asleep"] if self.rr.frames > k else np.zeros(0)
        if not (len(asleep) and asleep[0] > 0):
            return False
        since = k
        while since > 1 and not np.any(r.vr[since - 1, b]):
            since -= 1
        code, setting, value, name = SLEEPING_RULE
        moving = float(np.linalg.norm(r.vf[k, b]))
        did = (f"put sphere {b} to sleep (frozen from step {since}, once slower than sleep_speed = {speed:g} m/s for "
               f"sleep_time = {float(self.settings.get('sleep_time') or 0.0):g} s), where your run keeps it moving "
               f"({moving:.3g} m/s at step {k})")
        flag = f"-s {setting}={value:g}"
        self.departures.append(Departure(
            "own-rule", k, b,
            f"physdbg's {name} {did}; every step taken from your run's state ends where your run's does: the seed's "
            f"model has no sleeping, so this is physdbg's modelling, not a mistake of your engine",
            f"nothing to change in your engine; compare with {flag} to check the rest of the run against physdbg "
            f"without sleeping (check-run does this itself)",
            evidence={"rule": code, "setting": setting, "value": value, "name": name, "contacts": [], "said": did}))
        return True

    def _own_rule(self, s: int, contacts: list[StepContact], off: np.ndarray) -> bool:
        """The run's step s is physdbg's step taken without one of its own modelling rules
        (OWN_RULES): named own-rule, with what the rule did to which contact. Tried where a
        step with contacts ends elsewhere, for each rule the reference has on."""
        if not contacts:
            return False
        r = self.runs
        for code, setting, value, name in OWN_RULES:
            if self.settings.get(setting, value) == value:
                continue
            alternative = self._local_step(s, **{setting: value})
            if alternative is None or self._beyond(r.xf[s], r.vf[s], alternative[0], alternative[1]).any():
                continue
            changed = _changed_contacts(contacts, alternative[2])
            did = self._rule_did(code, *changed[0], contacts) if changed else f"changed the contacts of step {s}"
            if len(changed) > 1:
                did += f", and {len(changed) - 1} more contact{'s' if len(changed) > 2 else ''} of the step"
            body = int(np.flatnonzero(off)[0])
            flag = f"-s {setting}={value:g}"
            pairs = [[c.a, c.other, c.kind] for c, _ in changed]
            self.departures.append(Departure(
                "own-rule", s, changed[0][0].a if changed else body,
                f"physdbg's {name} {did}; without the rule ({flag}) physdbg's step {s}, taken from your run's "
                f"state, ends where your run's does: the seed's model has no such rule, so this is physdbg's "
                f"modelling, not a mistake of your engine",
                f"nothing to change in your engine for this step; compare with {flag} to check the rest of the run "
                f"against physdbg without the rule (check-run does this itself)",
                other=changed[0][0].other if changed and PARTNER_IS_SPHERE[changed[0][0].kind] else None,
                evidence={"rule": code, "setting": setting, "value": value, "name": name, "contacts": pairs,
                          "said": did}))
            return True
        return False

    def _ties_in(self, contacts: list[StepContact], dt: float) -> list[list[StepContact]]:
        """The step's ties: groups of contacts at one instant (within SAME_INSTANT of the
        step) that share a sphere, in physdbg's order."""
        from ..engine.resolve import SAME_INSTANT

        groups: list[list[StepContact]] = []
        for c in contacts:
            if groups and abs(c.tau - groups[-1][0].tau) <= SAME_INSTANT * dt:
                groups[-1].append(c)
            else:
                groups.append([c])
        return [g for g in groups if len(g) > 1 and any(
            set(self._bodies(c)) & set(self._bodies(d)) for i, c in enumerate(g) for d in g[i + 1:])]

    def _tie_orders(self, s: int, contacts: list[StepContact]):
        """Each (tie, order, the local step) of step s taken from the run's state with a tie's
        spheres numbered in another order (``_local_step``'s order)."""
        import itertools

        n = self.scene.state.count
        for tie in self._ties_in(contacts, float(self.runs.dt[s])):
            spheres = sorted({b for c in tie for b in self._bodies(c)})
            renumbered = (itertools.permutations(spheres) if len(spheres) <= TIE_SPHERES
                          else [tuple(reversed(spheres))])
            for numbering in renumbered:
                if list(numbering) == spheres:
                    continue
                order = np.arange(n)
                order[spheres] = numbering
                step = self._local_step(s, order=order, space_order="given")
                if step is not None:
                    yield tie, order, step

    def _tie(self, s: int, contacts: list[StepContact], off: np.ndarray) -> bool:
        """The run's step s is physdbg's step with contacts at one instant taken in another
        order (a tie: ``_ties_in``): named tie, with both orders. Tried where a step of
        several contacts ends elsewhere."""
        if len(contacts) < 2:
            return False
        from ..engine.resolve import SAME_INSTANT

        r = self.runs
        for tie, order, (x, v, taken) in self._tie_orders(s, contacts):
            if self._beyond(r.xf[s], r.vf[s], x, v).any():
                continue
            instant = [c for c in taken if abs(c.tau - tie[0].tau) <= SAME_INSTANT * float(r.dt[s])]
            ours = [self._listed(c) for c in tie]
            theirs = [self._listed(c) for c in instant] or ours
            if theirs == ours:
                continue  # the same order, and yet the run's step: not a tie's doing
            tied = " and ".join(self._sequence([c]) for c in dict.fromkeys(map(tuple, ours)))
            said = (f"in step {s} the contacts {tied} happen at one instant (t = {tie[0].time:.6g} s) and your "
                    f"run takes {self._sequence(theirs[:1])} first")
            self.departures.append(Departure(
                "tie", s, tie[0].a,
                f"{said}: physdbg takes {self._sequence(ours)}; your run {self._sequence(theirs)}. Taken in your run's "
                f"order, physdbg's step {s} from your run's state ends where your run's does. Which of two contacts at one instant "
                f"goes first is not the model's to say (each is the earliest), so this is a tie, not a mistake",
                "nothing to change in your engine: either order is right. (Runs that take ties in one order compare "
                "bit for bit; physdbg takes them in the order its tests found them.)",
                other=tie[0].other if PARTNER_IS_SPHERE[tie[0].kind] else None,
                evidence={"time": tie[0].time, "physdbg_order": ours, "run_order": theirs,
                          "numbering": order.tolist(), "said": said}))
            return True
        return False

    def _tie_parts(self, first: FirstDeparture) -> bool:
        """Where the runs first part at a tie (``_tie``), the reference goes on from physdbg's
        step taken in the run's order (``_continue_reference``): True when it did."""
        s = first.step
        local = self._local_step(s) if s >= 1 else None
        if local is None:
            return False
        x, v, contacts = local
        off = self._beyond(self.runs.xf[s], self.runs.vf[s], x, v)
        if not off.any():
            return False  # the step itself ends where physdbg's does: no tie parted them
        found = len(self.departures)
        if not self._tie(s, contacts, off):
            return False
        tie = self.departures.pop(found)
        self.ties.append(tie)
        self._continue_reference(s, np.asarray(tie.evidence["numbering"]))
        return True

    def _continue_reference(self, s: int, order: np.ndarray) -> None:
        """Replace physdbg's reference from frame s on: its step s from its own state,
        taken in ``order`` (a tie in the run's order), then every later step from there, in
        one world as a run takes them."""
        import dataclasses

        from ..engine import World
        from ..engine.state import State
        from ..errors import WorldStuck  # (a NaN or infinity is one too: NonFiniteState)

        r, st = self.runs, self.scene.state
        step = self._local_step(s, (r.xr[s - 1], r.vr[s - 1]), order, space_order="given")
        if step is None:
            r.xr[s:], r.vr[s:] = np.nan, np.nan
            return
        r.xr[s], r.vr[s] = step[0], step[1]
        state = State(step[0].copy(), step[1].copy(), st.inverse_mass, st.radius, st.restitution, st.gravity_scale)
        world = World(state, self.scene.walls, dataclasses.replace(self.scene.settings))
        world.time = float(r.t[s])
        for k in range(s + 1, len(r.t)):
            try:
                world.step(float(r.dt[k]))
            except WorldStuck:
                r.xr[k:], r.vr[k:] = np.nan, np.nan
                return
            r.xr[k], r.vr[k] = state.positions, state.velocities

    def _rule_did(self, code: str, c: StepContact, other: StepContact | None, contacts: list[StepContact]) -> str:
        """What rule ``code`` did to contact c of a step (other: the same contact without the
        rule), in words: "made the contact 2–3 in step 22 elastic (16 µs after ...)"."""
        what = f"the contact {self._pair_words(c)} in step {c.step}"
        if code == "rapid-contact":
            earlier = [d for d in contacts if d.index < c.index and set(self._bodies(d)) & set(self._bodies(c))]
            when = ""
            if earlier:
                d = earlier[-1]
                when = (f" ({(c.tau - d.tau) * 1e6:.3g} µs after {self._pair_words(d)}, within "
                        f"rapid_contact_time = {self.settings.get('rapid_contact_time'):g} s)")
            if c.resting:
                return f"held {what}{when}"
            e = "elastic" if c.restitution == 1.0 else f"e = {c.restitution:g}"
            want = f" instead of e = {other.restitution:g}" if other is not None else ""
            return f"made {what} {e}{want}{when}"
        return f"held {what} as resting" if c.resting else f"changed {what}"

    def _index_ordered(self, s: int, contacts: list[StepContact], off: np.ndarray) -> bool:
        """The run's step s is physdbg's step taken with ordering = index (the contacts
        predicted at the step's start resolved in index order, none looked for after): named
        index-order. Tried where a step of several contacts ends elsewhere."""
        if len(contacts) < 2 or self.settings.get("ordering", "time") == "index":
            return False
        r = self.runs
        alternative = self._local_step(s, ordering="index")
        if alternative is None or self._beyond(r.xf[s], r.vf[s], alternative[0], alternative[1]).any():
            return False
        body = int(np.flatnonzero(off)[0])
        dt = float(r.dt[s])
        order = ", then ".join(f"{self._pair_words(c)} at {c.tau / dt:.2f}·dt" for c in contacts[:6])
        indexed = [c for c in (alternative[2] or [])]
        self.departures.append(Departure(
            "index-order", s, body,
            f"physdbg resolves {order}{' …' if len(contacts) > 6 else ''}; your run ends step {s} exactly where "
            f"physdbg does when it resolves only the contacts predicted at the step's start, in index order "
            f"(ordering = index: {len(indexed)} contact{'s' if len(indexed) != 1 else ''}), so a contact that an "
            f"earlier one creates within the step is never looked for",
            "resolve contacts one at a time in time order (earliest time of impact first), and look again for new "
            "contacts after each: a chain of touching spheres passes its impulse along only that way",
            evidence={"physdbg_order": [[c.a, c.other, c.kind] for c in contacts],
                      "index_order": [[c.a, c.other, c.kind] for c in indexed]}))
        return True

    def _resting(self, c: StepContact, b: int, x: np.ndarray) -> None:
        """Sphere b ends step c.step elsewhere than physdbg's step, whose only contact of b
        is resting or slow (_slow: not judged one by one, as engines hold such contacts
        their own ways): named resting, with where the run left b. x: physdbg's positions
        (N, 3) at the step's end."""
        r = self.runs
        s = c.step
        b_c = dataclasses.replace(c, a=b, other=c.a if b == c.other else c.other) if PARTNER_IS_SPHERE[c.kind] else c
        apart = float(np.linalg.norm(r.xf[s, b] - x[b]))
        gap = self._gap(b_c, b, r.xf[s, b], s, float(r.dt[s]))
        inside = f", {-gap * 1000:.3g} mm inside {self._what(b_c)}" if gap < -self.atol else ""
        slow = (f"a slow contact with {self._what(b_c)} (closing at {c.closing:.3g} m/s, slower than the forces "
                f"give in {RESTING_SPEED_STEPS:g} steps), which it {'holds' if c.resting else 'resolves'}"
                if self._resting_speed(c, s) else
                f"a contact with {self._what(b_c)} (closing at {c.closing:.3g} m/s) that it holds (its resting or "
                f"rapid-contact rule)")
        self._add("resting", s, b_c,
                  f"sphere {b}: physdbg's step {s}, taken from your run's state, has {slow}; your run ends "
                  f"the step with sphere {b} {apart * 1000:.3g} mm from where physdbg's does{inside}",
                  "slow and resting contacts are held in different ways by different engines, and are not judged "
                  "one by one; a body that sinks into what it rests on needs a contact that acts at zero closing "
                  "speed (an overlap tested where each step ends, or a held resting contact)",
                  {"time": c.time, "apart": apart, "gap": gap, "held": bool(c.resting)})

    def _mistaken_chain(self, s: int, contacts: list[StepContact], off: np.ndarray) -> bool:
        """The run's step s is physdbg's step from the run's state with every sphere pair's
        impulse made with one of RESTITUTION_MISTAKES, each contact once a step
        (restitution_mistakes.step_with_mistake): named that mistake. Tried where a chain of
        moving contacts (one step's contacts sharing spheres) ends elsewhere, in scenes of up
        to MISTAKE_SPHERES spheres: there the speeds around each contact are not in the run's
        frames, so the mistake that reproduces the step is named rather than the chain's
        symptoms (a single contact's effective restitution is read off it: _judge_energy)."""
        moving = [c for c in contacts if not (c.resting or self._slow(c, s))]
        chains = [g for g in _chains(moving) if len(g) > 1 and any(PARTNER_IS_SPHERE[c.kind] for c in g)]
        if not chains or self.scene.state.count > MISTAKE_SPHERES or self.mistake_misses >= MISTAKE_MISSES:
            return False
        r = self.runs
        right = np.asarray(self.scene.state.restitution, dtype=float)
        # the mistake found in an earlier step first; after MISTAKE_MISSES chains that none
        # reproduced, the run makes none of them and they are not tried again
        for code, predicted, words, advice in sorted(RESTITUTION_MISTAKES, key=lambda m: m[0] != self.mistake_found):
            if all(abs(predicted(float(e)) - e) <= 2 * RESTITUTION_TOLERANCE for e in right):
                continue  # the same as the scene's own restitution here (e² for e = 1)
            # each contact once a step (an engine's guard), and, for a mistake that parts the
            # pair (an effective restitution of 0 or more), also without the guard
            guards = (True, False) if min(predicted(float(e)) for e in right) >= 0 else (True,)
            for once in guards:
                stepped = step_with_mistake(self.scene, r.xf[s - 1], r.vf[s - 1], float(r.t[s - 1]),
                                            float(r.dt[s]), predicted, once)
                if stepped is not None and not self._beyond(r.xf[s], r.vf[s], *stepped).any():
                    break
            else:
                continue
            chain = chains[0]
            first = next(c for c in chain if PARTNER_IS_SPHERE[c.kind])
            want = float(first.restitution)
            dt = float(r.dt[s])
            order = ", then ".join(f"{self._pair_words(c)} at {c.tau / dt:.2f}·dt" for c in chain[:6])
            bodies = sorted({b for g in chains for c in g for b in self._bodies(c)})
            self._add(code, s, first,
                      f"in the chain {order}{' …' if len(chain) > 6 else ''}, your run's step {s} is physdbg's step "
                      f"from your run's state with each sphere's restitution replaced by the mistake's effective "
                      f"restitution ({predicted(want):.3g} for {self._pair_words(first)}, where physdbg applies "
                      f"e = {want:g}){', each contact once' if once else ''}: {predicted(want):.3g} = {words}", advice,
                      {"restitution": predicted(want), "expected": want, "bodies": bodies,
                       "physdbg_order": [[c.a, c.other, c.kind] for c in chain], "reproduced": True})
            self.mistake_found = code
            return True
        self.mistake_misses += self.mistake_found is None
        return False
